//! The one writer of machine files: a list of typed edits ([`Edit`]) —
//! values of the model by parameter id ([`ToolParam`], [`RobotParam`]) and
//! the few structural changes identification makes (a whole component
//! table, a new thermal term or spindle entry, the measurement frame, the
//! calibration record, a new section under a key path) — applied to the
//! file's lossless syntax tree ([`tree`]), the one the loader reads
//! ([`super::yaml::Source::read`]). Every comment, the key order and every
//! byte the edits do not touch are kept, in every layout the loader reads:
//! flow lists and maps on one line (the bundled files), block lists
//! (`- 1.0` on separate lines), block maps, sequence items level with
//! their key, everything in flow style, quoted keys, comments between
//! items. New keys and sections are written in the style of the mapping
//! they go into ([`NewValue`]): block lines in the bundled files, flow
//! text in a flow file.
//!
//! A model value is written exactly: the shortest decimal that reads back as
//! the same `f64` (`150.05`, `0.000001`, `3.0`), so the model read from the
//! written file equals [`crate::machine::tool::MachineTool::with_params`] or
//! [`crate::machine::robot::Robot::with_params`] of the same edits. The
//! resolution a value is written with is the caller's choice: it rounds the
//! value first ([`round_to`], [`round_sig`]). Every edited model value is
//! read back from the result.
//!
//! Writing a new section: [`Edit::Section`] sets the value at a key path
//! (`covariance.stiffness`, `axes[X].component_errors.EXX_um`), replacing
//! it whole or adding it with the mappings missing on the way, with an
//! optional comment above a new key:
//!
//! ```
//! use postproc::machine::yaml_write::{Edit, NewValue, apply};
//! let text = "kind: robot\nname: R   # kept\n";
//! let rows = NewValue::Rows(vec!["[1.0, 0.0]".into(), "[0.0, 1.0]".into()]);
//! let edit = Edit::Section {
//!     path: "covariance.stiffness".into(),
//!     value: NewValue::Map(vec![
//!         ("parameters".into(), NewValue::Text("[k1, k2]".into())),
//!         ("rows".into(), rows),
//!     ]),
//!     comment: "Covariance of the fit.".into(),
//! };
//! let out = apply(text, "r.yaml", "postproc calibrate", &[edit]).unwrap();
//! assert_eq!(
//!     out,
//!     "kind: robot\nname: R   # kept\n# Covariance of the fit.\ncovariance:\n  stiffness:\n    parameters: [k1, k2]\n    rows:\n      - [1.0, 0.0]\n      - [0.0, 1.0]\n"
//! );
//! ```
//!
//! The few layouts the writer does not write (aliases, tags) are refused
//! when the file is loaded ([`super::yaml::Source::read`]), never after a
//! fit.

use super::robot::RobotParam;
use super::status::Calibration;
use super::tool::ToolParam;
use crate::error::{Error, Result};

/// Axis and error-direction letters in slot order.
const LETTERS: [char; 6] = ['X', 'Y', 'Z', 'A', 'B', 'C'];

/// One change of a machine file.
#[derive(Debug, Clone, PartialEq)]
pub enum Edit {
    /// A value of a machine tool's model, in the unit of its key. A
    /// location error is added (with its section) when the file lacks it;
    /// component tables are written whole ([`Edit::ComponentTable`]).
    Tool(ToolParam, f64),
    /// A value of a robot's model, in the unit of its key. A DH edit in a
    /// file without `actual` adds the section (a copy of `nominal`) after
    /// the `nominal` rows.
    Robot(RobotParam, f64),
    /// A machine-tool component error table (positions and both columns,
    /// in the file's units), replaced or added with its section.
    ComponentTable {
        /// Axis slot 0..6.
        axis: usize,
        /// Error direction 0..6 (X Y Z translations, A B C rotations).
        error: usize,
        /// `positions_mm` (`positions_deg` for a rotary axis A, B, C).
        positions: Vec<f64>,
        /// `forward`.
        forward: Vec<f64>,
        /// `reverse`.
        reverse: Vec<f64>,
    },
    /// A new robot thermal term, appended to `thermal.terms` (a new
    /// `thermal:` section with `time_constant_min` when the file has none,
    /// preceded by `comment`).
    ThermalTerm {
        /// The term.
        term: ThermalTermText,
        /// `time_constant_min` of a new section.
        time_constant_min: f64,
        /// Comment line above a new section (empty: none).
        comment: String,
    },
    /// The robot's `thermal.rated_power_w` (the section must exist):
    /// replaced, or added after `time_constant_min` preceded by the
    /// comment line `comment` (empty: none).
    RatedPower {
        /// Highest mean motor power of a joint, W.
        watts: f64,
        /// Comment line above a new key.
        comment: String,
    },
    /// A new machine-tool `thermal.spindle` entry with
    /// `idle_w_per_rpm: 0.0` (in the `thermal:` section, or a new one),
    /// preceded by `comment`.
    Spindle {
        /// `growth_um_per_kw`.
        growth_um_per_kw: f64,
        /// `time_constant_min`.
        time_constant_min: f64,
        /// Comment line above the entry (empty: none).
        comment: String,
    },
    /// The top-level `measurement_frame` (the instrument's pose in the
    /// machine's reference frame; not part of the model), written with
    /// 0.1 µm and 10⁻⁶ degree resolution.
    MeasurementFrame {
        /// Translation, mm.
        xyz_mm: [f64; 3],
        /// Roll, pitch, yaw, degrees.
        rpy_deg: [f64; 3],
    },
    /// `status: calibrated` and one more entry of `calibrations`
    /// (the comment after the old `status` word goes with it).
    Calibrated(Calibration),
    /// A comment line `# …` added at the end of the file's leading comment
    /// block (after the comment lines added before it).
    HeaderComment(String),
    /// The value at the key path `path` (`thermal.spindle`,
    /// `axes[X].component_errors`, `covariance.kinematics`): replaced whole
    /// when the file has it, else added with the mappings missing on the
    /// way, after the last key of the mapping it goes into. `value` is
    /// written in the style of that mapping ([`NewValue`]); `comment`, when
    /// not empty, goes on comment lines above a new key (one `# ` line per
    /// line of it).
    Section {
        /// Key path of the value, keys joined by `.`, list items as `[n]`
        /// or `[name]` (the item whose `name` is that).
        path: String,
        /// The value.
        value: NewValue,
        /// Comment above a new key (empty: none).
        comment: String,
    },
}

/// A value the writer adds to a machine file, written in the style of the
/// mapping it goes into: block lines under a block mapping (the layout of
/// the bundled files: `key:` and its entries one level deeper, a list of
/// rows as `- row` lines), flow text in a flow mapping (`key: { a: 1.0 }`,
/// `key: [row, row]`).
#[derive(Debug, Clone, PartialEq)]
pub enum NewValue {
    /// A scalar or a flow collection, as its text (`1.5`, `[1.0, 2.0]`,
    /// `{ x_mm: 0.0 }`): one line in either style.
    Text(String),
    /// A list of rows, each a flow text (`{ a_mm: 0.0, d_mm: 1.0 }`).
    Rows(Vec<String>),
    /// A mapping, its keys in order.
    Map(Vec<(String, NewValue)>),
}

impl NewValue {
    /// The value as flow text.
    pub fn flow(&self) -> String {
        match self {
            NewValue::Text(t) => t.clone(),
            NewValue::Rows(r) => format!("[{}]", r.join(", ")),
            NewValue::Map(m) if m.is_empty() => "{}".into(),
            NewValue::Map(m) => {
                let pairs: Vec<String> = m
                    .iter()
                    .map(|(k, v)| format!("{k}: {}", v.flow()))
                    .collect();
                format!("{{ {} }}", pairs.join(", "))
            }
        }
    }

    /// The lines of `key: value` in block style at indentation `indent`.
    fn block(&self, key: &str, indent: &str, out: &mut Vec<String>) {
        match self {
            NewValue::Rows(r) if !r.is_empty() => {
                out.push(format!("{indent}{key}:"));
                out.extend(r.iter().map(|row| format!("{indent}  - {row}")));
            }
            NewValue::Map(m) if !m.is_empty() => {
                out.push(format!("{indent}{key}:"));
                let deeper = format!("{indent}  ");
                for (k, v) in m {
                    v.block(k, &deeper, out);
                }
            }
            _ => out.push(format!("{indent}{key}: {}", self.flow())),
        }
    }
}

/// One Paper B thermal term as written in a robot file.
#[derive(Debug, Clone, PartialEq)]
pub struct ThermalTermText {
    /// DH length, `a1..a6` / `d1..d6`.
    pub parameter: String,
    /// Joint whose power drives it, 1..6.
    pub joint: usize,
    /// `lb_mm`.
    pub lb_mm: f64,
    /// `ub_mm`.
    pub ub_mm: f64,
    /// `ts_per_w`.
    pub ts_per_w: f64,
}

mod tree;

pub(crate) use tree::set_status;

/// Applies `edits` in order to the machine file `text` (named `file` in
/// errors) on its syntax tree ([`tree`]). `by` names the program in the
/// comment above a section it adds (`# Identified by `…`.`). Every comment
/// and every byte the edits do not touch are kept. An edited model value
/// that does not read back as written is an error; a result that is not a
/// valid machine file is returned, and the caller, which reads it back as
/// the machine it writes, reports why.
pub fn apply(text: &str, file: &str, by: &str, edits: &[Edit]) -> Result<String> {
    let out = tree::apply(text, file, by, edits)?;
    if reads_back(&out, edits) == ReadBack::Wrong {
        return Err(edit_err(
            file,
            "an edited value does not read back as written; the layout of its key cannot be edited",
        ));
    }
    Ok(out)
}

/// What an edited text reads back as.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ReadBack {
    /// A valid machine with every edited model value as written.
    Values,
    /// A valid machine with an edited value that differs.
    Wrong,
    /// Not a valid machine file (the caller reports why).
    Invalid,
}

fn reads_back(text: &str, edits: &[Edit]) -> ReadBack {
    let Ok(m) = super::Machine::from_yaml_str(text, "(edited file)") else {
        return ReadBack::Invalid;
    };
    let mut last: Vec<(Option<f64>, f64)> = Vec::new();
    let mut robot: Vec<RobotParam> = Vec::new();
    let mut tool: Vec<ToolParam> = Vec::new();
    for e in edits {
        match (e, &m) {
            (Edit::Robot(p, v), super::Machine::Robot(r)) => {
                if let Some(i) = robot.iter().position(|q| q == p) {
                    last[i].1 = *v;
                } else {
                    robot.push(*p);
                    last.push((r.param_value(*p), *v));
                }
            }
            (Edit::Tool(p, v), super::Machine::Tool(t)) => {
                if let Some(i) = tool.iter().position(|q| q == p) {
                    last[robot.len() + i].1 = *v;
                } else {
                    tool.push(*p);
                    last.push((t.param_value(*p), *v));
                }
            }
            _ => {}
        }
    }
    if last.iter().all(|(got, want)| *got == Some(*want)) {
        ReadBack::Values
    } else {
        ReadBack::Wrong
    }
}

// ---------------------------------------------------------------------------
// Numbers
// ---------------------------------------------------------------------------

/// `v` written exactly: the shortest decimal that reads back as `v`, with
/// one decimal at least so that it reads as a float (`-0` is `0.0`).
pub fn number(v: f64) -> String {
    let v = if v == 0.0 { 0.0 } else { v };
    let s = format!("{v}");
    if s.contains(['.', 'e', 'E', 'N', 'i']) {
        s
    } else {
        format!("{s}.0")
    }
}

/// `v` rounded to `decimals` decimals (the value a file written with that
/// resolution holds).
pub fn round_to(v: f64, decimals: usize) -> f64 {
    format!("{v:.decimals$}").parse().unwrap_or(v)
}

/// `v` rounded to six significant digits (a small coefficient such as
/// `ts_per_w = 1e-6`); 0 for 0 or a non-finite value.
pub fn round_sig(v: f64) -> f64 {
    if v == 0.0 || !v.is_finite() {
        return 0.0;
    }
    let digits = (5 - v.abs().log10().floor() as i64).clamp(1, 15) as usize;
    round_to(v, digits)
}

/// `v` with at most `decimals` decimals, trailing zeros removed (one
/// decimal kept): [`number`] of [`round_to`].
pub fn fmt_value(v: f64, decimals: usize) -> String {
    number(round_to(v, decimals))
}

fn edit_err(file: &str, msg: impl Into<String>) -> Error {
    Error::Usage(format!(
        "{file}: cannot write the calibrated values: {}",
        msg.into()
    ))
}

fn term_flow(t: &ThermalTermText) -> String {
    format!(
        "{{ parameter: {}, joint: {}, lb_mm: {}, ub_mm: {}, ts_per_w: {} }}",
        t.parameter,
        t.joint,
        number(t.lb_mm),
        number(t.ub_mm),
        number(t.ts_per_w)
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::machine::Machine;
    use crate::machine::robot::Robot;
    use crate::machine::robot::{DhField, ThermalField};
    use crate::machine::tool::LocationParam;
    use crate::machine::tool::MachineTool;

    fn bundled(name: &str) -> String {
        let path = format!("{}/machines/{name}", env!("CARGO_MANIFEST_DIR"));
        std::fs::read_to_string(path).expect("bundled file")
    }

    fn robot(text: &str) -> Robot {
        match Machine::from_yaml_str(text, "r.yaml").expect("valid") {
            Machine::Robot(r) => r,
            Machine::Tool(_) => panic!("robot file"),
        }
    }

    fn tool(text: &str) -> MachineTool {
        match Machine::from_yaml_str(text, "t.yaml").expect("valid") {
            Machine::Tool(t) => t,
            Machine::Robot(_) => panic!("machine-tool file"),
        }
    }

    /// The lines of `b` that differ from those of `a` (same line count).
    fn changed(a: &str, b: &str) -> Vec<String> {
        assert_eq!(a.lines().count(), b.lines().count(), "{b}");
        a.lines()
            .zip(b.lines())
            .filter(|(x, y)| x != y)
            .map(|(_, y)| y.to_string())
            .collect()
    }

    #[test]
    fn numbers_are_written_exactly_and_read_back_equal() {
        assert_eq!(number(2.0), "2.0");
        assert_eq!(number(-0.0), "0.0");
        assert_eq!(number(1e-6), "0.000001");
        assert_eq!(fmt_value(1.23456, 3), "1.235");
        assert_eq!(fmt_value(-0.00001, 3), "0.0");
        assert_eq!(fmt_value(0.0123456789, 7), "0.0123457");
        assert_eq!(round_sig(0.0123456789), 0.0123457);
        for v in [150.05, 0.1 + 0.2, -1.0 / 3.0, 123_529.721, 1e-9] {
            assert_eq!(number(v).parse::<f64>().ok(), Some(v));
        }
    }

    /// Robot edits of every kind on the bundled IRB 1600 file: only the
    /// edited values change (comments and other bytes kept), and the robot
    /// read back equals `with_params` of the same edits.
    #[test]
    fn robot_file_read_back_equals_with_params() {
        let text = bundled("abb-irb1600.yaml");
        let edits = [
            (
                RobotParam::Dh {
                    joint: 1,
                    field: DhField::A,
                },
                150.05,
            ),
            (
                RobotParam::Dh {
                    joint: 4,
                    field: DhField::Alpha,
                },
                90.031_25,
            ),
            (RobotParam::JointStiffness { joint: 2 }, 123_529.721),
            (
                RobotParam::Thermal {
                    term: 1,
                    field: ThermalField::Ts,
                },
                0.0123457,
            ),
            (RobotParam::ThermalTimeConstant, 42.5),
            (RobotParam::ToolOffset { axis: 2 }, 150.25),
        ];
        let typed: Vec<Edit> = edits.iter().map(|&(p, v)| Edit::Robot(p, v)).collect();
        let out = apply(&text, "r.yaml", "test", &typed).expect("written");
        let lines = changed(&text, &out);
        assert_eq!(lines.len(), 6, "{lines:?}");
        assert!(out.contains("# Paper C Table 6"), "comments kept");
        assert!(out.contains("k_nm_per_rad: [270990.0, 430040.0, 123529.721,"));
        let want = robot(&text).with_params(&edits).expect("valid");
        assert_eq!(format!("{:?}", robot(&out)), format!("{want:?}"));
    }

    /// A DH edit in a file without `actual` adds the section as a copy of
    /// `nominal` after its rows; the robot read back equals `with_params`.
    #[test]
    fn actual_section_is_added_from_nominal() {
        let text = bundled("abb-irb1600.yaml");
        let start = text.find("\nactual:").expect("actual section") + 1;
        let end = start
            + text[start..]
                .match_indices("\n")
                .nth(6)
                .map(|(i, _)| i + 1)
                .expect("six rows");
        let bare = format!("{}{}", &text[..start], &text[end..]);
        assert!(!bare.contains("\nactual:"));
        let p = RobotParam::Dh {
            joint: 0,
            field: DhField::D,
        };
        let out = apply(&bare, "r.yaml", "postproc test", &[Edit::Robot(p, 486.5)]).unwrap();
        assert!(out.contains("# Identified by `postproc test`.\nactual:\n  - { a_mm: "));
        let want = robot(&bare).with_params(&[(p, 486.5)]).expect("valid");
        assert_eq!(format!("{:?}", robot(&out)), format!("{want:?}"));
    }

    /// Machine-tool edits on the bundled AFM R1000 file: a location error
    /// replaced and one added, the spindle growth and a stiffness value;
    /// the model read back equals `with_params` of the same edits.
    #[test]
    fn tool_file_read_back_equals_with_params() {
        let text = bundled("afm-r1000.yaml");
        let sq = |axis, r| ToolParam::Location {
            axis,
            error: LocationParam::Angle(r),
        };
        let edits = [
            (sq(1, 2), 75.25),
            (sq(2, 0), -3.5),
            (ToolParam::SpindleGrowth, 11.0),
        ];
        let typed: Vec<Edit> = edits.iter().map(|&(p, v)| Edit::Tool(p, v)).collect();
        let out = apply(&text, "t.yaml", "test", &typed).expect("written");
        assert!(out.contains("      EC0Y_urad: 75.25"));
        assert!(
            out.contains("# Structure: X is carried by Y"),
            "comments kept"
        );
        let want = tool(&text).with_params(&edits).expect("valid");
        let read = tool(&out);
        assert_eq!(
            format!(
                "{:?}{:?}{:?}",
                read.axes(),
                read.stiffness(),
                read.thermal()
            ),
            format!(
                "{:?}{:?}{:?}",
                want.axes(),
                want.stiffness(),
                want.thermal()
            )
        );
    }

    /// Uniform stiffness values and thermal axis values of a small file,
    /// in a flow map and in block style.
    #[test]
    fn stiffness_and_thermal_axes_read_back_equal_with_params() {
        let text = "kind: machine_tool
name: T
axes:
  - name: Y
    type: linear
    side: workpiece
    travel_mm: [0, 400]
    rapid_mm_per_min: 20000
  - name: X
    type: linear
    side: tool
    travel_mm: [0, 500]
    rapid_mm_per_min: 20000
  - name: Z
    type: linear
    side: tool
    travel_mm: [-300, 0]
    rapid_mm_per_min: 15000
stiffness:
  k_n_per_um: { x_pos: 20, x_neg: 20, y_pos: 25, y_neg: 25, z_pos: 40, z_neg: 40 }  # flow
thermal:
  spindle: { growth_um_per_kw: 8, time_constant_min: 20 }
  axes:
    X: { scale_ppm_per_kw: 3, time_constant_min: 30 }
";
        let edits = [
            (
                ToolParam::Stiffness {
                    dir: 1,
                    positive: false,
                    cell: None,
                },
                30.5,
            ),
            (ToolParam::SpindleTimeConstant, 22.0),
            (ToolParam::AxisTimeConstant { axis: 0 }, 45.0),
        ];
        let typed: Vec<Edit> = edits.iter().map(|&(p, v)| Edit::Tool(p, v)).collect();
        let out = apply(text, "t.yaml", "test", &typed).expect("written");
        assert_eq!(changed(text, &out).len(), 3);
        assert!(out.contains("z_neg: 40 }  # flow"));
        let want = tool(text).with_params(&edits).expect("valid");
        let read = tool(&out);
        assert_eq!(
            format!("{:?}{:?}", read.stiffness(), read.thermal()),
            format!("{:?}{:?}", want.stiffness(), want.thermal())
        );
        let block = text.replace(
            "  k_n_per_um: { x_pos: 20, x_neg: 20, y_pos: 25, y_neg: 25, z_pos: 40, z_neg: 40 }  # flow\n",
            "  k_n_per_um:\n    x_pos: 20\n    x_neg: 20\n    y_pos: 25\n    y_neg: 25  # block\n    z_pos: 40\n    z_neg: 40\n",
        );
        let out = apply(&block, "t.yaml", "test", &typed[..1]).expect("written");
        assert!(out.contains("    y_neg: 30.5  # block\n"), "{out}");
        let read = tool(&out);
        assert_eq!(
            format!("{:?}", read.stiffness()),
            format!("{:?}", want.stiffness())
        );
    }

    /// A payload and a TCP on a robot file without `tool_load` and
    /// `flange_to_tool`: the keys are added, and the robot read back equals
    /// `with_params` (the new load at the TCP).
    #[test]
    fn payload_and_tcp_added_read_back_equal_with_params() {
        let text = bundled("abb-irb1600.yaml");
        let with_tcp = text
            .lines()
            .filter(|l| !l.starts_with("tool_load:"))
            .map(|l| format!("{l}\n"))
            .collect::<String>();
        let edits = [(RobotParam::PayloadMass, 7.5)];
        let out = apply(&with_tcp, "r.yaml", "t", &[Edit::Robot(edits[0].0, 7.5)]).unwrap();
        assert!(out.ends_with("tool_load: { mass_kg: 7.5, cog_mm: [0.0, 0.0, 150.0] }\n"));
        let want = robot(&with_tcp).with_params(&edits).expect("valid");
        assert_eq!(format!("{:?}", robot(&out)), format!("{want:?}"));
        let bare = with_tcp
            .lines()
            .filter(|l| !l.starts_with("flange_to_tool:"))
            .map(|l| format!("{l}\n"))
            .collect::<String>();
        let edits = [(RobotParam::ToolOffset { axis: 2 }, 120.0)];
        let out = apply(&bare, "r.yaml", "t", &[Edit::Robot(edits[0].0, 120.0)]).unwrap();
        assert!(out.ends_with("flange_to_tool: { x_mm: 0.0, y_mm: 0.0, z_mm: 120.0 }\n"));
        let want = robot(&bare).with_params(&edits).expect("valid");
        assert_eq!(format!("{:?}", robot(&out)), format!("{want:?}"));
    }

    /// A stiffness grid cell and spindle location errors (one replaced, one
    /// added): only those numbers change, and the model read back equals
    /// `with_params`.
    #[test]
    fn grid_cells_and_spindle_errors_read_back_equal_with_params() {
        let text = bundled("afm-r1000.yaml");
        let cell = ToolParam::Stiffness {
            dir: 0,
            positive: false,
            cell: Some([1, 1, 2]),
        };
        let out = apply(&text, "t.yaml", "t", &[Edit::Tool(cell, 18.25)]).unwrap();
        assert_eq!(
            changed(&text, &out),
            vec!["      - [[20.0, 22.0, 20.0], [19.0, 21.0, 18.25]]".to_string()]
        );
        let want = tool(&text).with_params(&[(cell, 18.25)]).expect("valid");
        assert_eq!(
            format!("{:?}", tool(&out).stiffness()),
            format!("{:?}", want.stiffness())
        );
        let text = bundled("five-axis-ac.yaml");
        let edits = [
            (
                ToolParam::SpindleLocation {
                    error: LocationParam::Angle(0),
                },
                11.5,
            ),
            (
                ToolParam::SpindleLocation {
                    error: LocationParam::Offset(1),
                },
                0.02,
            ),
        ];
        let typed: Vec<Edit> = edits.iter().map(|&(p, v)| Edit::Tool(p, v)).collect();
        let out = apply(&text, "t.yaml", "t", &typed).unwrap();
        assert!(
            out.contains("spindle:\n  location_errors:\n    EY0S_mm: 0.02\n    EA0S_urad: 11.5\n")
        );
        let want = tool(&text).with_params(&edits).expect("valid");
        let read = tool(&out);
        assert_eq!(
            format!("{:?}", read.spindle_errors()),
            format!("{:?}", want.spindle_errors())
        );
    }

    /// Header comments go after the leading comment block, in order.
    #[test]
    fn header_comments_follow_the_leading_comments() {
        let text = "# a\n\n# b\nkind: robot\n# c\n";
        let out = apply(
            text,
            "f",
            "t",
            &[
                Edit::HeaderComment("one".into()),
                Edit::HeaderComment("two".into()),
            ],
        )
        .unwrap();
        assert_eq!(out, "# a\n\n# b\n# one\n# two\nkind: robot\n# c\n");
    }

    #[test]
    fn lists_maps_and_frames_are_edited_in_place() {
        let text = "# c\nk_nm_per_rad: [1.0, 2.0]  # keep\nflange_to_tool: { x_mm: 0.0, y_mm: 0.0, z_mm: 150.0, quaternion: [1.0, 0.0, 0.0, 0.0] }\n";
        let k = |joint, v| Edit::Robot(RobotParam::JointStiffness { joint }, v);
        let t = apply(text, "f", "t", &[k(0, 3.5), k(1, 4.0)]).unwrap();
        assert_eq!(t.lines().nth(1), Some("k_nm_per_rad: [3.5, 4.0]  # keep"));
        let tcp = |axis, v| Edit::Robot(RobotParam::ToolOffset { axis }, v);
        let t = apply(&t, "f", "t", &[tcp(0, 0.1), tcp(1, -0.2), tcp(2, 150.25)]).unwrap();
        assert_eq!(
            t.lines().nth(2),
            Some(
                "flange_to_tool: { x_mm: 0.1, y_mm: -0.2, z_mm: 150.25, quaternion: [1.0, 0.0, 0.0, 0.0] }"
            )
        );
        assert!(apply(text, "f", "t", &[k(5, 1.0)]).is_err());
        let frame = Edit::MeasurementFrame {
            xyz_mm: [1.0, 2.00004, -3.0],
            rpy_deg: [0.0, 0.1234567, 0.0],
        };
        let t = apply(&t, "f", "t", std::slice::from_ref(&frame)).unwrap();
        assert!(t.ends_with(
            "Not part of the model.\nmeasurement_frame: { x_mm: 1.0, y_mm: 2.0, z_mm: -3.0, rpy_deg: [0.0, 0.123457, 0.0] }\n"
        ));
        let again = apply(&t, "f", "t", &[frame]).unwrap();
        assert_eq!(again, t, "an existing frame line is replaced");
    }

    #[test]
    fn thermal_terms_set_and_added() {
        let text = "kind: robot\nthermal:\n  time_constant_min: 30  # c\n  terms:\n    - { parameter: a2, joint: 1, lb_mm: 0.10, ub_mm: 0.10, ts_per_w: 0.015 }  # J1\n    - { parameter: a2, joint: 2, lb_mm: 0.12, ub_mm: 0.12, ts_per_w: 0.020 }\nmodal: []\n";
        let f = |term, field, v| Edit::Robot(RobotParam::Thermal { term, field }, v);
        let t = apply(
            text,
            "f",
            "t",
            &[
                f(1, ThermalField::Lb, 0.25),
                f(1, ThermalField::Ub, 0.2),
                f(1, ThermalField::Ts, 0.0123457),
                Edit::Robot(RobotParam::ThermalTimeConstant, 45.0),
            ],
        )
        .unwrap();
        assert_eq!(
            t.lines().nth(5),
            Some("    - { parameter: a2, joint: 2, lb_mm: 0.25, ub_mm: 0.2, ts_per_w: 0.0123457 }")
        );
        assert_eq!(t.lines().nth(2), Some("  time_constant_min: 45.0  # c"));
        assert!(t.contains("ts_per_w: 0.015 }  # J1"));
        assert!(apply(text, "f", "t", &[f(2, ThermalField::Lb, 0.0)]).is_err());
        let term = ThermalTermText {
            parameter: "a3".into(),
            joint: 2,
            lb_mm: 300.0,
            ub_mm: 300.0,
            ts_per_w: 1e-6,
        };
        let add = |comment: &str| Edit::ThermalTerm {
            term: term.clone(),
            time_constant_min: 30.0,
            comment: comment.into(),
        };
        let t = apply(text, "f", "t", &[add("")]).unwrap();
        assert_eq!(
            t.lines().nth(6),
            Some(
                "    - { parameter: a3, joint: 2, lb_mm: 300.0, ub_mm: 300.0, ts_per_w: 0.000001 }"
            )
        );
        assert_eq!(t.lines().nth(7), Some("modal: []"));
        let t = apply("kind: robot\n", "f", "t", &[add("assumed")]).unwrap();
        assert_eq!(
            t,
            "kind: robot\n# assumed\nthermal:\n  time_constant_min: 30.0\n  terms:\n    - { parameter: a3, joint: 2, lb_mm: 300.0, ub_mm: 300.0, ts_per_w: 0.000001 }\n"
        );
    }

    #[test]
    fn spindle_growth_set_and_added() {
        let text = "kind: machine_tool\nthermal:\n  spindle: { idle_w_per_rpm: 0.2, growth_um_per_kw: 3.0, time_constant_min: 25.0 }\n";
        let t = apply(
            text,
            "f",
            "t",
            &[Edit::Tool(ToolParam::SpindleGrowth, 7.25)],
        )
        .unwrap();
        assert_eq!(
            t.lines().nth(2),
            Some(
                "  spindle: { idle_w_per_rpm: 0.2, growth_um_per_kw: 7.25, time_constant_min: 25.0 }"
            )
        );
        let add = Edit::Spindle {
            growth_um_per_kw: 5.0,
            time_constant_min: 30.0,
            comment: String::new(),
        };
        assert!(apply(text, "f", "t", std::slice::from_ref(&add)).is_err());
        let t = apply("kind: machine_tool\n", "f", "t", std::slice::from_ref(&add)).unwrap();
        assert_eq!(
            t,
            "kind: machine_tool\nthermal:\n  spindle: { idle_w_per_rpm: 0.0, growth_um_per_kw: 5.0, time_constant_min: 30.0 }\n"
        );
        let t = apply(
            "kind: machine_tool\nthermal:\n  axes:\n    X: { scale_ppm_per_kw: 1.0, time_constant_min: 9.0, friction_n: 1.0 }\n",
            "f",
            "t",
            &[add, Edit::Tool(ToolParam::AxisScale { axis: 0 }, 2.5)],
        )
        .unwrap();
        assert_eq!(
            t,
            "kind: machine_tool\nthermal:\n  spindle: { idle_w_per_rpm: 0.0, growth_um_per_kw: 5.0, time_constant_min: 30.0 }\n  axes:\n    X: { scale_ppm_per_kw: 2.5, time_constant_min: 9.0, friction_n: 1.0 }\n"
        );
    }

    #[test]
    fn machine_tool_tables_and_location_errors() {
        let text = "kind: machine_tool\naxes:\n  - name: X\n    type: linear\n    component_errors:\n      EBX_urad:\n        forward: [1.0]\n  - name: Y\n    type: linear\n    location_errors:\n      EC0Y_urad: 35.0  # sq\n# end\ntools: {}\n";
        let table = |axis, error, p: &[f64], f: &[f64], r: &[f64]| Edit::ComponentTable {
            axis,
            error,
            positions: p.to_vec(),
            forward: f.to_vec(),
            reverse: r.to_vec(),
        };
        let loc = |axis, r, v| {
            Edit::Tool(
                ToolParam::Location {
                    axis,
                    error: LocationParam::Angle(r),
                },
                v,
            )
        };
        let t = apply(
            text,
            "f",
            "t",
            &[
                table(0, 0, &[0.0, 100.0], &[0.0, 2.5], &[1.0, 3.0]),
                table(1, 1, &[0.0], &[0.0], &[0.5]),
                loc(1, 2, -12.5),
                loc(0, 1, 3.0),
            ],
        )
        .unwrap();
        let want = "kind: machine_tool\naxes:\n  - name: X\n    type: linear\n    component_errors:\n      EXX_um:\n        positions_mm: [0.0, 100.0]\n        forward: [0.0, 2.5]\n        reverse: [1.0, 3.0]\n      EBX_urad:\n        forward: [1.0]\n    location_errors:\n      EB0X_urad: 3.0\n  - name: Y\n    type: linear\n    location_errors:\n      EC0Y_urad: -12.5  # sq\n    component_errors:\n      EYY_um:\n        positions_mm: [0.0]\n        forward: [0.0]\n        reverse: [0.5]\n# end\ntools: {}\n";
        assert_eq!(t, want);
        let q = table(3, 3, &[], &[], &[]);
        assert!(apply(text, "f", "t", &[q]).is_err());
        let node = ToolParam::Component {
            axis: 0,
            error: 0,
            node: 0,
            forward: true,
        };
        assert!(apply(text, "f", "t", &[Edit::Tool(node, 1.0)]).is_err());
    }

    /// The edits a calibration or a diagnosis writes, one at a time, on a
    /// machine file of either kind: every value the file has, moved a
    /// little, and each structural edit.
    fn writes_of(m: &Machine) -> Vec<Edit> {
        let mut out = Vec::new();
        match m {
            Machine::Robot(r) => {
                let fields = [DhField::A, DhField::Alpha, DhField::D, DhField::ThetaOffset];
                let mut params: Vec<RobotParam> = (0..6)
                    .flat_map(|joint| fields.map(|field| RobotParam::Dh { joint, field }))
                    .collect();
                params.extend((0..6).map(|joint| RobotParam::JointStiffness { joint }));
                params.extend((0..3).map(|axis| RobotParam::ToolOffset { axis }));
                for term in 0..3 {
                    for field in [ThermalField::Lb, ThermalField::Ub, ThermalField::Ts] {
                        params.push(RobotParam::Thermal { term, field });
                    }
                }
                params.extend([RobotParam::ThermalTimeConstant, RobotParam::PayloadMass]);
                for p in params {
                    if let Some(v) = r.param_value(p) {
                        out.push(Edit::Robot(p, round_sig(v * 1.001 + 0.0625)));
                    }
                }
                out.push(Edit::ThermalTerm {
                    term: ThermalTermText {
                        parameter: "a2".into(),
                        joint: 2,
                        lb_mm: 0.01,
                        ub_mm: 0.25,
                        ts_per_w: 0.002,
                    },
                    time_constant_min: 45.0,
                    comment: "Identified by `postproc calibrate thermal`.".into(),
                });
                if r.param_value(RobotParam::ThermalTimeConstant).is_some() {
                    out.push(Edit::RatedPower {
                        watts: 812.5,
                        comment: "Highest mean motor power of a joint.".into(),
                    });
                }
            }
            Machine::Tool(t) => {
                let mut params = Vec::new();
                for axis in 0..6 {
                    for error in 0..6 {
                        for node in 0..3 {
                            for forward in [true, false] {
                                params.push(ToolParam::Component {
                                    axis,
                                    error,
                                    node,
                                    forward,
                                });
                            }
                        }
                    }
                    for k in 0..3 {
                        params.extend([
                            ToolParam::Location {
                                axis,
                                error: LocationParam::Offset(k),
                            },
                            ToolParam::Location {
                                axis,
                                error: LocationParam::Angle(k),
                            },
                        ]);
                    }
                    params.extend([
                        ToolParam::AxisScale { axis },
                        ToolParam::AxisTimeConstant { axis },
                    ]);
                }
                for k in 0..3 {
                    params.extend([
                        ToolParam::SpindleLocation {
                            error: LocationParam::Offset(k),
                        },
                        ToolParam::SpindleLocation {
                            error: LocationParam::Angle(k),
                        },
                    ]);
                }
                for dir in 0..3 {
                    for positive in [true, false] {
                        params.push(ToolParam::Stiffness {
                            dir,
                            positive,
                            cell: None,
                        });
                    }
                }
                params.extend([ToolParam::SpindleGrowth, ToolParam::SpindleTimeConstant]);
                for p in params {
                    if let Some(v) = t.param_value(p) {
                        out.push(Edit::Tool(p, round_sig(v * 1.001 + 0.0625)));
                    }
                }
                out.push(Edit::ComponentTable {
                    axis: 0,
                    error: 1,
                    positions: vec![-100.0, 0.0, 100.0],
                    forward: vec![-1.5, 0.0, 2.25],
                    reverse: vec![-1.0, 0.5, 2.0],
                });
                out.push(Edit::Spindle {
                    growth_um_per_kw: 7.5,
                    time_constant_min: 30.0,
                    comment: "Identified by `postproc calibrate thermal`.".into(),
                });
            }
        }
        out.push(Edit::MeasurementFrame {
            xyz_mm: [1.25, -2.5, 0.125],
            rpy_deg: [0.01, -0.02, 0.5],
        });
        out.push(Edit::Calibrated(Calibration {
            date: "2026-01-02".into(),
            kind: "geometry".into(),
            observations: "obs.csv".into(),
            observations_sha256: "0".repeat(64),
            rows: 12,
            fit_rms_mm: 0.0125,
        }));
        out.push(Edit::HeaderComment("Calibrated by a test.".into()));
        out
    }

    /// Whether a line holds a flow map inside a flow map (`{ a: { … } }`):
    /// a section written in flow style where the bundled files have block
    /// lines.
    fn nested_flow_map(line: &str) -> bool {
        let mut depth = 0;
        for c in line.split(" #").next().unwrap_or("").chars() {
            match c {
                '{' if depth > 0 => return true,
                '{' => depth += 1,
                '}' => depth -= 1,
                _ => {}
            }
        }
        false
    }

    /// On every bundled machine file, each edit a calibration or a
    /// diagnosis writes succeeds (but a second spindle entry and a table
    /// node alone), keeps every
    /// comment line, reads back (or is a model the loader refuses), and adds its sections in the block style
    /// of the bundled files: no added line holds a flow map inside a flow
    /// map, and every added `key:` line opens deeper lines. The exact
    /// bytes of each kind of new section are fixed by the tests above.
    #[test]
    fn the_writer_adds_sections_in_the_block_style_of_the_bundled_files() {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/machines");
        let mut names: Vec<String> = std::fs::read_dir(dir)
            .expect("machines/")
            .filter_map(|e| e.ok()?.file_name().into_string().ok())
            .filter(|n| n.ends_with(".yaml"))
            .collect();
        names.sort();
        assert!(names.len() > 20, "{names:?}");
        let (mut written, mut bad) = (0, Vec::new());
        for name in &names {
            let text = bundled(name);
            let m = Machine::from_yaml_str(&text, name).expect("bundled file loads");
            let old: std::collections::BTreeSet<&str> = text.lines().collect();
            for edit in writes_of(&m) {
                let edits = std::slice::from_ref(&edit);
                let out = match apply(&text, name, "postproc test", edits) {
                    Ok(out) => out,
                    Err(e)
                        if matches!(edit, Edit::Spindle { .. }) && text.contains("  spindle:") =>
                    {
                        assert!(e.to_string().contains("already"), "{e}");
                        continue;
                    }
                    Err(e) if matches!(edit, Edit::Tool(ToolParam::Component { .. }, _)) => {
                        // A table node alone is refused: tables are written whole.
                        assert!(e.to_string().contains("written whole"), "{e}");
                        continue;
                    }
                    Err(e) => {
                        bad.push(format!("{name} {edit:?}: {e}"));
                        continue;
                    }
                };
                written += 1;
                // Invalid: a value the loader refuses (an offset of the
                // reference axis), written as asked.
                if reads_back(&out, edits) == ReadBack::Wrong {
                    bad.push(format!("{name} {edit:?}: does not read back"));
                }
                for l in text.lines().filter(|l| l.trim_start().starts_with('#')) {
                    if !out.contains(l) {
                        bad.push(format!("{name} {edit:?}: comment `{l}` lost"));
                    }
                }
                let lines: Vec<&str> = out.lines().collect();
                for (i, l) in lines.iter().enumerate() {
                    if old.contains(l) {
                        continue;
                    }
                    let deeper =
                        |n: &str| n.len() - n.trim_start().len() > l.len() - l.trim_start().len();
                    let opens = l.trim_end().ends_with(':') && !l.trim_start().starts_with('#');
                    if nested_flow_map(l) || (opens && !lines.get(i + 1).is_some_and(|n| deeper(n)))
                    {
                        bad.push(format!("{name} {edit:?}: line `{l}`"));
                    }
                }
            }
        }
        assert!(written > 500, "{written} edits written");
        assert!(bad.is_empty(), "{}:\n{}", bad.len(), bad.join("\n"));
    }
}
