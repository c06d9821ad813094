//! Parameters of a machine tool as data: a typed id for each value of the
//! error model a calibration identifies or a study varies (component error
//! table values, location errors, stiffness, thermal growth), and
//! [`MachineTool::with_params`], which gives the model with some of them
//! set and validated again exactly as if the file had held those values.
//!
//! Values are in the unit of their key in the machine file (µm, µrad, mm,
//! N/µm, µm/kW, ppm/kW, min); `machines/README.md` documents the keys.

use crate::error::{Error, Located, Result};

use super::MachineTool;
use super::raw::{RawGridValues, RawMachineTool, RawSpindle, RawTable};

const LETTERS: [char; 6] = ['X', 'Y', 'Z', 'A', 'B', 'C'];

/// A location error of an axis: which of its keys.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum LocationParam {
    /// Offset along X, Y, Z (0..3) of a rotary axis' line, mm
    /// (`EX0B_mm`, …).
    Offset(usize),
    /// Orientation about X, Y, Z (0..3), µrad (`EC0Y_urad`, `EA0Z_urad`, …).
    Angle(usize),
    /// Zero-angle error of a rotary axis, µrad (`EB0B_urad`, …).
    Zero,
}

/// One parameter of a machine tool's model.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ToolParam {
    /// Node `node` of the component error table of the axis in slot
    /// `axis` (0..6 = X Y Z A B C) for the error along or about `error`
    /// (0..3 translations X Y Z in µm, 3..6 rotations A B C in µrad): the
    /// forward column, or the reverse one. The table must be in the file.
    Component {
        /// Axis slot.
        axis: usize,
        /// Error direction 0..6.
        error: usize,
        /// Table node (index into its positions).
        node: usize,
        /// Forward (true) or reverse column.
        forward: bool,
    },
    /// A location error of the axis in slot `axis`.
    Location {
        /// Axis slot.
        axis: usize,
        /// Which location error.
        error: LocationParam,
    },
    /// `stiffness.k_n_per_um` for direction `dir` (0..3) and load sign:
    /// the one value, or the grid value at `cell` (`[iz, iy, ix]`), N/µm.
    Stiffness {
        /// Direction X, Y, Z (0..3).
        dir: usize,
        /// Load in + (true) or − direction.
        positive: bool,
        /// Grid cell, `None` for a uniform value.
        cell: Option<[usize; 3]>,
    },
    /// A location error of the spindle (`spindle.location_errors`:
    /// `EX0S_mm`, `EY0S_mm`, `EA0S_urad`, `EB0S_urad`).
    SpindleLocation {
        /// Which location error (an offset or an orientation).
        error: LocationParam,
    },
    /// `thermal.spindle.growth_um_per_kw`.
    SpindleGrowth,
    /// `thermal.spindle.time_constant_min`.
    SpindleTimeConstant,
    /// `thermal.axes.<axis>.scale_ppm_per_kw` of the axis in slot `axis`.
    AxisScale {
        /// Axis slot.
        axis: usize,
    },
    /// `thermal.axes.<axis>.time_constant_min` of the axis in slot `axis`.
    AxisTimeConstant {
        /// Axis slot.
        axis: usize,
    },
}

impl ToolParam {
    /// The key path of the value in the machine file
    /// (`axes[X].component_errors.EYX_um.forward[3]`, …).
    pub fn path(&self) -> String {
        let letter = |s: usize| LETTERS.get(s).copied().unwrap_or('?');
        match *self {
            ToolParam::Component {
                axis,
                error,
                node,
                forward,
            } => format!(
                "axes[{}].component_errors.{}.{}[{node}]",
                letter(axis),
                component_key(axis, error),
                if forward { "forward" } else { "reverse" }
            ),
            ToolParam::Location { axis, error } => format!(
                "axes[{}].location_errors.{}",
                letter(axis),
                location_key(axis, error)
            ),
            ToolParam::Stiffness { dir, positive, .. } => format!(
                "stiffness.k_n_per_um.{}_{}",
                letter(dir).to_ascii_lowercase(),
                if positive { "pos" } else { "neg" }
            ),
            ToolParam::SpindleLocation { error } => {
                format!("spindle.location_errors.{}", spindle_key(error))
            }
            ToolParam::SpindleGrowth => "thermal.spindle.growth_um_per_kw".into(),
            ToolParam::SpindleTimeConstant => "thermal.spindle.time_constant_min".into(),
            ToolParam::AxisScale { axis } => {
                format!("thermal.axes.{}.scale_ppm_per_kw", letter(axis))
            }
            ToolParam::AxisTimeConstant { axis } => {
                format!("thermal.axes.{}.time_constant_min", letter(axis))
            }
        }
    }
}

/// The file key of a component error table (`EYX_um`, `EAX_urad`).
pub(crate) fn component_key(axis: usize, error: usize) -> String {
    let l = |s: usize| LETTERS.get(s).copied().unwrap_or('?');
    let unit = if error < 3 { "um" } else { "urad" };
    format!("E{}{}_{unit}", l(error), l(axis))
}

/// The file key of a spindle location error (`EX0S_mm`, `EA0S_urad`).
pub(crate) fn spindle_key(error: LocationParam) -> String {
    let l = |s: usize| LETTERS.get(s).copied().unwrap_or('?');
    match error {
        LocationParam::Offset(t) => format!("E{}0S_mm", l(t)),
        LocationParam::Angle(r) => format!("E{}0S_urad", l(r + 3)),
        LocationParam::Zero => "E?0S_urad".into(),
    }
}

/// The file key of a location error (`EC0Y_urad`, `EX0B_mm`, `EB0B_urad`).
pub(crate) fn location_key(axis: usize, error: LocationParam) -> String {
    let l = |s: usize| LETTERS.get(s).copied().unwrap_or('?');
    match error {
        LocationParam::Offset(t) => format!("E{}0{}_mm", l(t), l(axis)),
        LocationParam::Angle(r) => format!("E{}0{}_urad", l(r + 3), l(axis)),
        LocationParam::Zero => format!("E{}0{}_urad", l(axis), l(axis)),
    }
}

impl MachineTool {
    /// The model with each parameter of `edits` set to its value (in the
    /// unit of its key), validated again as a machine file holding those
    /// values would be: a value out of range is the same error, naming its
    /// key path. A parameter the file does not have (a component table or
    /// stiffness or thermal section it lacks, a node past the table's end)
    /// is an error too; location errors may be set whether or not the file
    /// writes them.
    pub fn with_params(&self, edits: &[(ToolParam, f64)]) -> Result<Self> {
        let mut raw = (*self.raw).clone();
        for &(p, v) in edits {
            set(&mut raw, p, v).map_err(|m| self.param_error(&p.path(), &m))?;
        }
        super::load::validate(raw).map_err(|inv| self.param_error(&inv.path, &inv.message))
    }

    /// [`MachineTool::with_params`] without the plausibility check, for the
    /// trial steps of a fit, whose intermediate values may leave the
    /// plausible range on the way to the answer: the fit's result is
    /// checked once, at the edge (the calibrated file read back). Ranges,
    /// order and presence are still checked.
    pub fn trial_with_params(&self, edits: &[(ToolParam, f64)]) -> Result<Self> {
        let mut raw = (*self.raw).clone();
        for &(p, v) in edits {
            set(&mut raw, p, v).map_err(|m| self.param_error(&p.path(), &m))?;
        }
        super::load::validate_with(raw, super::load::Plausibility::Unchecked)
            .map_err(|inv| self.param_error(&inv.path, &inv.message))
    }

    /// The value of a parameter as the file gives it (in the unit of its
    /// key): a location error the file does not write is 0; `None` for a
    /// value the file does not have (a missing table, section or node).
    pub fn param_value(&self, p: ToolParam) -> Option<f64> {
        let raw = &*self.raw;
        let axis = |slot: usize| {
            let name = LETTERS.get(slot)?.to_string();
            raw.axes.iter().find(|a| a.name == name)
        };
        match p {
            ToolParam::Component {
                axis: a,
                error,
                node,
                forward,
            } => {
                let t = axis(a)?.component_errors.get(&component_key(a, error))?;
                let col = match (&t.reverse, forward) {
                    (Some(r), false) => r,
                    _ => &t.forward,
                };
                col.get(node).copied()
            }
            ToolParam::Location { axis: a, error } => Some(
                axis(a)?
                    .location_errors
                    .get(&location_key(a, error))
                    .copied()
                    .unwrap_or(0.0),
            ),
            ToolParam::SpindleLocation { error } => Some(
                raw.spindle
                    .as_ref()
                    .and_then(|s| s.location_errors.get(&spindle_key(error)).copied())
                    .unwrap_or(0.0),
            ),
            ToolParam::Stiffness {
                dir,
                positive,
                cell,
            } => {
                let values = stiffness_values(raw, dir, positive)?;
                match (values, cell) {
                    (RawGridValues::Uniform(u), None) => Some(*u),
                    (RawGridValues::Grid(g), Some([iz, iy, ix])) => {
                        g.get(iz)?.get(iy)?.get(ix).copied()
                    }
                    _ => None,
                }
            }
            ToolParam::SpindleGrowth | ToolParam::SpindleTimeConstant => {
                let s = raw.thermal.as_ref()?.spindle.as_ref()?;
                Some(if p == ToolParam::SpindleGrowth {
                    s.growth_um_per_kw
                } else {
                    s.time_constant_min
                })
            }
            ToolParam::AxisScale { axis: a } | ToolParam::AxisTimeConstant { axis: a } => {
                let t = raw
                    .thermal
                    .as_ref()?
                    .axes
                    .get(&LETTERS.get(a)?.to_string())?;
                Some(if matches!(p, ToolParam::AxisScale { .. }) {
                    t.scale_ppm_per_kw
                } else {
                    t.time_constant_min
                })
            }
        }
    }

    /// The stiffness parameters of direction `dir` (0..3) and load sign in
    /// the file: the one uniform value, or every grid cell.
    pub fn stiffness_params(&self, dir: usize, positive: bool) -> Vec<ToolParam> {
        let p = |cell| ToolParam::Stiffness {
            dir,
            positive,
            cell,
        };
        match stiffness_values(&self.raw, dir, positive) {
            None => Vec::new(),
            Some(RawGridValues::Uniform(_)) => vec![p(None)],
            Some(RawGridValues::Grid(g)) => {
                let mut out = Vec::new();
                for (iz, plane) in g.iter().enumerate() {
                    for (iy, row) in plane.iter().enumerate() {
                        for ix in 0..row.len() {
                            out.push(p(Some([iz, iy, ix])));
                        }
                    }
                }
                out
            }
        }
    }

    /// The component error table of the axis in slot `axis` for error
    /// direction `error` as the file gives it: positions (mm or degrees),
    /// forward and reverse columns (the forward one when the file has no
    /// reverse); `None` when the file has no such table.
    pub fn component_table(&self, axis: usize, error: usize) -> Option<[Vec<f64>; 3]> {
        let name = LETTERS.get(axis)?.to_string();
        let a = self.raw.axes.iter().find(|a| a.name == name)?;
        let t = a.component_errors.get(&component_key(axis, error))?;
        let pos = t.positions_mm.clone().or_else(|| t.positions_deg.clone())?;
        let rev = t.reverse.clone().unwrap_or_else(|| t.forward.clone());
        Some([pos, t.forward.clone(), rev])
    }

    fn param_error(&self, path: &str, message: &str) -> Error {
        Error::Machine(Located::whole_file(
            format!("machine `{}`", self.name),
            format!("{path}: {message} (a parameter set by value)"),
        ))
    }
}

/// The stiffness values of direction `dir` and load sign in the file.
fn stiffness_values(raw: &RawMachineTool, dir: usize, positive: bool) -> Option<&RawGridValues> {
    let k = &raw.stiffness.as_ref()?.k_n_per_um;
    Some(match (dir, positive) {
        (0, true) => &k.x_pos,
        (0, false) => &k.x_neg,
        (1, true) => &k.y_pos,
        (1, false) => &k.y_neg,
        (2, true) => &k.z_pos,
        (2, false) => &k.z_neg,
        _ => return None,
    })
}

/// Sets one parameter in the raw file; the message says why it cannot.
fn set(raw: &mut RawMachineTool, p: ToolParam, v: f64) -> std::result::Result<(), String> {
    match p {
        ToolParam::Component {
            axis,
            error,
            node,
            forward,
        } => {
            let key = component_key(axis, error);
            let table = raw_axis(raw, axis)?
                .component_errors
                .get_mut(&key)
                .ok_or_else(|| "the file has no such table".to_string())?;
            set_table(table, node, forward, v)
        }
        ToolParam::Location { axis, error } => {
            let key = location_key(axis, error);
            raw_axis(raw, axis)?.location_errors.insert(key, v);
            Ok(())
        }
        ToolParam::Stiffness {
            dir,
            positive,
            cell,
        } => {
            let s = raw
                .stiffness
                .as_mut()
                .ok_or_else(|| "the file has no `stiffness` section".to_string())?;
            let k = &mut s.k_n_per_um;
            let values = match (dir, positive) {
                (0, true) => &mut k.x_pos,
                (0, false) => &mut k.x_neg,
                (1, true) => &mut k.y_pos,
                (1, false) => &mut k.y_neg,
                (2, true) => &mut k.z_pos,
                (2, false) => &mut k.z_neg,
                _ => return Err("no such direction".into()),
            };
            match (values, cell) {
                (RawGridValues::Uniform(u), None) => *u = v,
                (RawGridValues::Grid(g), Some([iz, iy, ix])) => {
                    *g.get_mut(iz)
                        .and_then(|r| r.get_mut(iy))
                        .and_then(|r| r.get_mut(ix))
                        .ok_or_else(|| "no such grid cell".to_string())? = v;
                }
                (RawGridValues::Uniform(_), Some(_)) => {
                    return Err("the value is one number, not a grid".into());
                }
                (RawGridValues::Grid(_), None) => {
                    return Err("the value is a grid: give its cell".into());
                }
            }
            Ok(())
        }
        ToolParam::SpindleLocation { error } => {
            if error == LocationParam::Zero {
                return Err("the spindle has no zero-angle error".into());
            }
            raw.spindle
                .get_or_insert_with(|| RawSpindle {
                    location_errors: Default::default(),
                })
                .location_errors
                .insert(spindle_key(error), v);
            Ok(())
        }
        ToolParam::SpindleGrowth | ToolParam::SpindleTimeConstant => {
            let s = raw
                .thermal
                .as_mut()
                .and_then(|t| t.spindle.as_mut())
                .ok_or_else(|| "the file has no `thermal.spindle` section".to_string())?;
            if p == ToolParam::SpindleGrowth {
                s.growth_um_per_kw = v;
            } else {
                s.time_constant_min = v;
            }
            Ok(())
        }
        ToolParam::AxisScale { axis } | ToolParam::AxisTimeConstant { axis } => {
            let name = LETTERS
                .get(axis)
                .ok_or_else(|| "no such axis".to_string())?
                .to_string();
            let a = raw
                .thermal
                .as_mut()
                .and_then(|t| t.axes.get_mut(&name))
                .ok_or_else(|| "the file has no such thermal axis".to_string())?;
            if matches!(p, ToolParam::AxisScale { .. }) {
                a.scale_ppm_per_kw = v;
            } else {
                a.time_constant_min = v;
            }
            Ok(())
        }
    }
}

/// The raw axis in `slot`.
fn raw_axis(
    raw: &mut RawMachineTool,
    slot: usize,
) -> std::result::Result<&mut super::raw::RawAxis, String> {
    let letter = LETTERS
        .get(slot)
        .ok_or_else(|| "no such axis".to_string())?
        .to_string();
    raw.axes
        .iter_mut()
        .find(|a| a.name == letter)
        .ok_or_else(|| "the machine has no such axis".to_string())
}

/// Sets node `node` of a table column. A table without `reverse` has one
/// curve for both directions: a forward edit changes it for both; a
/// reverse edit first gives the table its own copy of `forward` as the
/// reverse column, so that the forward one keeps its values.
fn set_table(
    t: &mut RawTable,
    node: usize,
    forward: bool,
    v: f64,
) -> std::result::Result<(), String> {
    let col = if forward {
        &mut t.forward
    } else {
        t.reverse.get_or_insert_with(|| t.forward.clone())
    };
    *col.get_mut(node)
        .ok_or_else(|| "no such table node".to_string())? = v;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const BASE: &str = "kind: machine_tool
name: T
axes:
  - name: Y
    type: linear
    side: workpiece
    travel_mm: [0, 400]
    rapid_mm_per_min: 20000
    location_errors:
      EC0Y_urad: 12.5
  - name: X
    type: linear
    side: tool
    travel_mm: [0, 500]
    rapid_mm_per_min: 20000
    component_errors:
      EXX_um: { positions_mm: [0, 250, 500], forward: [0, 1.5, 3.0] }
      EYX_um: { positions_mm: [0, 250, 500], forward: [0, 0.5, 1.0], reverse: [0, 0.25, 0.5] }
  - name: Z
    type: linear
    side: tool
    travel_mm: [-300, 0]
    rapid_mm_per_min: 15000
stiffness:
  k_n_per_um: { x_pos: 20, x_neg: 20, y_pos: 25, y_neg: 25, z_pos: 40, z_neg: 40 }
thermal:
  spindle: { growth_um_per_kw: 8, time_constant_min: 20 }
  axes:
    X: { scale_ppm_per_kw: 3, time_constant_min: 30 }
";

    fn base() -> MachineTool {
        MachineTool::from_yaml_str(BASE, "t.yaml").expect("valid")
    }

    /// Every value the model holds about its error model, for comparing
    /// two models.
    fn model_text(m: &MachineTool) -> String {
        format!(
            "{:?}\n{:?}\n{:?}\n{:?}",
            m.axes(),
            m.stiffness(),
            m.thermal(),
            m.is_error_free()
        )
    }

    #[test]
    fn setting_table_values_equals_the_file_with_those_values() {
        let m = base()
            .with_params(&[
                (
                    ToolParam::Component {
                        axis: 0,
                        error: 1,
                        node: 2,
                        forward: true,
                    },
                    1.75,
                ),
                (
                    ToolParam::Component {
                        axis: 0,
                        error: 0,
                        node: 1,
                        forward: false,
                    },
                    -2.25,
                ),
            ])
            .expect("valid");
        let t = BASE
            .replace(
                "forward: [0, 0.5, 1.0], reverse",
                "forward: [0, 0.5, 1.75], reverse",
            )
            .replace(
                "forward: [0, 1.5, 3.0] }",
                "forward: [0, 1.5, 3.0], reverse: [0, -2.25, 3.0] }",
            );
        let f = MachineTool::from_yaml_str(&t, "t.yaml").expect("valid");
        assert_eq!(model_text(&m), model_text(&f));
    }

    /// A table given by `forward` only is one curve for both directions:
    /// a forward edit changes both and adds no reversal error.
    #[test]
    fn a_forward_edit_of_a_one_column_table_keeps_one_curve() {
        let m = base()
            .with_params(&[(
                ToolParam::Component {
                    axis: 0,
                    error: 0,
                    node: 1,
                    forward: true,
                },
                2.0,
            )])
            .expect("valid");
        let t = BASE.replace("forward: [0, 1.5, 3.0] }", "forward: [0, 2.0, 3.0] }");
        let f = MachineTool::from_yaml_str(&t, "t.yaml").expect("valid");
        assert_eq!(model_text(&m), model_text(&f));
    }

    #[test]
    fn setting_location_errors_equals_the_file_with_those_values() {
        let sq = |axis, r| ToolParam::Location {
            axis,
            error: LocationParam::Angle(r),
        };
        let m = base()
            .with_params(&[(sq(1, 2), -7.25), (sq(2, 0), 3.5)])
            .expect("valid");
        let t = BASE.replace("EC0Y_urad: 12.5", "EC0Y_urad: -7.25").replace(
            "rapid_mm_per_min: 15000\n",
            "rapid_mm_per_min: 15000\n    location_errors:\n      EA0Z_urad: 3.5\n",
        );
        let f = MachineTool::from_yaml_str(&t, "t.yaml").expect("valid");
        assert_eq!(model_text(&m), model_text(&f));
        assert!(!model_text(&m).contains("12.5"));
    }

    #[test]
    fn stiffness_and_thermal_values_are_set() {
        let m = base()
            .with_params(&[
                (
                    ToolParam::Stiffness {
                        dir: 1,
                        positive: false,
                        cell: None,
                    },
                    30.0,
                ),
                (ToolParam::SpindleGrowth, 9.5),
                (ToolParam::AxisTimeConstant { axis: 0 }, 45.0),
            ])
            .expect("valid");
        let t = BASE
            .replace("y_neg: 25", "y_neg: 30")
            .replace("growth_um_per_kw: 8", "growth_um_per_kw: 9.5")
            .replace("time_constant_min: 30", "time_constant_min: 45");
        let f = MachineTool::from_yaml_str(&t, "t.yaml").expect("valid");
        assert_eq!(model_text(&m), model_text(&f));
    }

    #[test]
    fn a_trial_step_skips_only_the_plausibility_check() {
        let m = base();
        // 500 µm/kW is beyond the plausible ±200 µm/kW, not a hard limit.
        let edit = [(ToolParam::SpindleGrowth, 500.0)];
        let e = m.with_params(&edit).expect_err("implausible");
        assert!(e.to_string().contains("growth_um_per_kw"), "{e}");
        let t = m.trial_with_params(&edit).expect("a trial step");
        assert_eq!(t.param_value(ToolParam::SpindleGrowth), Some(500.0));
        let big = ToolParam::Component {
            axis: 0,
            error: 0,
            node: 0,
            forward: true,
        };
        let e = m
            .trial_with_params(&[(big, 5000.0)])
            .expect_err("beyond 1 mm");
        assert!(e.to_string().contains("EXX_um"), "{e}");
    }

    #[test]
    fn values_are_validated_again_and_missing_parameters_refused() {
        let m = base();
        let big = ToolParam::Component {
            axis: 0,
            error: 0,
            node: 0,
            forward: true,
        };
        let e = m.with_params(&[(big, 5000.0)]).expect_err("beyond 1 mm");
        assert_eq!(e.kind(), crate::error::ErrorKind::Machine);
        assert!(e.to_string().contains("EXX_um"), "{e}");
        for p in [
            ToolParam::Component {
                axis: 0,
                error: 2,
                node: 0,
                forward: true,
            },
            ToolParam::Component {
                axis: 0,
                error: 0,
                node: 3,
                forward: true,
            },
            ToolParam::Stiffness {
                dir: 0,
                positive: true,
                cell: Some([0, 0, 0]),
            },
            ToolParam::AxisScale { axis: 1 },
            ToolParam::Location {
                axis: 4,
                error: LocationParam::Zero,
            },
        ] {
            let e = m.with_params(&[(p, 1.0)]).expect_err("not in the file");
            assert_eq!(e.kind(), crate::error::ErrorKind::Machine, "{p:?}");
            assert!(e.to_string().contains(&p.path()), "{e}");
        }
        // An orientation a linear axis does not have is refused by the
        // same check as in a file.
        let own = ToolParam::Location {
            axis: 0,
            error: LocationParam::Angle(0),
        };
        let e = m.with_params(&[(own, 1.0)]).expect_err("EA0X is not a key");
        assert!(e.to_string().contains("EA0X_urad"), "{e}");
    }

    /// `param_value` reads what `with_params` set, and the file's values
    /// otherwise (a location error the file does not write is 0).
    #[test]
    fn param_value_reads_the_values_set() {
        let m = base();
        let sq = ToolParam::Location {
            axis: 1,
            error: LocationParam::Angle(2),
        };
        assert_eq!(m.param_value(sq), Some(12.5));
        let absent = ToolParam::Location {
            axis: 2,
            error: LocationParam::Angle(0),
        };
        assert_eq!(m.param_value(absent), Some(0.0));
        let params = [
            (sq, -3.0),
            (
                ToolParam::Component {
                    axis: 0,
                    error: 1,
                    node: 1,
                    forward: false,
                },
                0.75,
            ),
            (
                ToolParam::SpindleLocation {
                    error: LocationParam::Offset(0),
                },
                0.01,
            ),
            (ToolParam::SpindleGrowth, 9.0),
            (ToolParam::AxisScale { axis: 0 }, 4.0),
        ];
        let set = m.with_params(&params).expect("valid");
        for (p, v) in params {
            assert_eq!(set.param_value(p), Some(v), "{p:?}");
        }
        assert_eq!(m.stiffness_params(0, true).len(), 1);
        assert_eq!(
            m.component_table(0, 0),
            Some([
                vec![0.0, 250.0, 500.0],
                vec![0.0, 1.5, 3.0],
                vec![0.0, 1.5, 3.0]
            ])
        );
    }
}
