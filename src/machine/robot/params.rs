//! Parameters of a robot as data: a typed id for each value a calibration
//! identifies or a study varies (the actual DH parameters, the joint
//! stiffnesses, the thermal terms, the tool centre point), and [`Robot::with_params`], which gives
//! the robot with some of them set and validated again exactly as if the
//! file had held those values. A fit's inner loop sets its trial values
//! through [`Robot::trial_with_params`] instead (`calib.rs`), checked once
//! at the edge.
//!
//! Values are in the unit of their key in the robot file (mm, degrees,
//! N·m/rad, 1/W, min); `machines/README.md` documents the keys.

use crate::error::{Error, Located, Result};

use super::Robot;
use super::raw::{RawFrame, RawLoad, RawRobot};

/// A field of one row of the DH table.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DhField {
    /// `a_mm`.
    A,
    /// `alpha_deg`.
    Alpha,
    /// `d_mm`.
    D,
    /// `theta_offset_deg`.
    ThetaOffset,
}

/// A coefficient of one thermal term.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ThermalField {
    /// `lb_mm`.
    Lb,
    /// `ub_mm`.
    Ub,
    /// `ts_per_w`.
    Ts,
}

/// One parameter of a robot's model.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RobotParam {
    /// A field of row `joint` (0..6) of the `actual` DH table (a file
    /// without `actual` starts from a copy of `nominal`).
    Dh {
        /// DH row, 0-based.
        joint: usize,
        /// Which field.
        field: DhField,
    },
    /// `k_nm_per_rad[joint]`.
    JointStiffness {
        /// Joint, 0-based.
        joint: usize,
    },
    /// A coefficient of `thermal.terms[term]`.
    Thermal {
        /// Index of the term in the file.
        term: usize,
        /// Which coefficient.
        field: ThermalField,
    },
    /// `thermal.time_constant_min`.
    ThermalTimeConstant,
    /// `flange_to_tool.x_mm`, `y_mm`, `z_mm` (`axis` 0..3): the tool
    /// centre point in the flange frame (a file without `flange_to_tool`
    /// starts from the flange itself).
    ToolOffset {
        /// Flange axis x, y, z (0..3).
        axis: usize,
    },
    /// `tool_load.mass_kg` (a file without `tool_load` starts from a
    /// massless load at the tool centre point).
    PayloadMass,
}

impl RobotParam {
    /// The key path of the value in the robot file (`actual[1].a_mm`, …).
    pub fn path(&self) -> String {
        match *self {
            RobotParam::Dh { joint, field } => {
                let key = match field {
                    DhField::A => "a_mm",
                    DhField::Alpha => "alpha_deg",
                    DhField::D => "d_mm",
                    DhField::ThetaOffset => "theta_offset_deg",
                };
                format!("actual[{joint}].{key}")
            }
            RobotParam::JointStiffness { joint } => format!("k_nm_per_rad[{joint}]"),
            RobotParam::Thermal { term, field } => {
                let key = match field {
                    ThermalField::Lb => "lb_mm",
                    ThermalField::Ub => "ub_mm",
                    ThermalField::Ts => "ts_per_w",
                };
                format!("thermal.terms[{term}].{key}")
            }
            RobotParam::ThermalTimeConstant => "thermal.time_constant_min".into(),
            RobotParam::ToolOffset { axis } => {
                let key = ["x_mm", "y_mm", "z_mm"].get(axis).copied().unwrap_or("?");
                format!("flange_to_tool.{key}")
            }
            RobotParam::PayloadMass => "tool_load.mass_kg".into(),
        }
    }
}

impl Robot {
    /// The robot with each parameter of `edits` set to its value (in the
    /// unit of its key), validated again as a robot file holding those
    /// values would be: a value out of range or implausible is the same
    /// error, naming its key path. A parameter the file does not have (a
    /// thermal term or section it lacks, a row past the sixth) is an error
    /// too.
    ///
    /// The other values are the file's: trial values set with
    /// [`Robot::trial_with_params`] are not carried over.
    /// The reconfiguration setting is kept.
    pub fn with_params(&self, edits: &[(RobotParam, f64)]) -> Result<Self> {
        let mut raw = (*self.d.raw).clone();
        for &(p, v) in edits {
            set(&mut raw, p, v).map_err(|m| self.param_error(&p.path(), &m))?;
        }
        let mut r =
            Robot::validate(raw).map_err(|inv| self.param_error(&inv.path, &inv.message))?;
        r.d.allow_reconfiguration = self.d.allow_reconfiguration;
        Ok(r)
    }

    /// The value of a parameter as the file gives it (in the unit of its
    /// key; a DH field of a file without `actual` is the nominal one, a
    /// missing `flange_to_tool` or `tool_load` gives 0); `None` for a value
    /// the file does not have.
    pub fn param_value(&self, p: RobotParam) -> Option<f64> {
        let raw = &*self.d.raw;
        match p {
            RobotParam::Dh { joint, field } => {
                let row = raw.actual.as_ref().unwrap_or(&raw.nominal).get(joint)?;
                Some(match field {
                    DhField::A => row.a_mm,
                    DhField::Alpha => row.alpha_deg,
                    DhField::D => row.d_mm,
                    DhField::ThetaOffset => row.theta_offset_deg,
                })
            }
            RobotParam::JointStiffness { joint } => raw.k_nm_per_rad.get(joint).copied(),
            RobotParam::Thermal { term, field } => {
                let t = raw.thermal.as_ref()?.terms.get(term)?;
                Some(match field {
                    ThermalField::Lb => t.lb_mm,
                    ThermalField::Ub => t.ub_mm,
                    ThermalField::Ts => t.ts_per_w,
                })
            }
            RobotParam::ThermalTimeConstant => Some(raw.thermal.as_ref()?.time_constant_min),
            RobotParam::ToolOffset { axis } => {
                let f = raw.flange_to_tool.as_ref();
                match axis {
                    0 => Some(f.map_or(0.0, |f| f.x_mm)),
                    1 => Some(f.map_or(0.0, |f| f.y_mm)),
                    2 => Some(f.map_or(0.0, |f| f.z_mm)),
                    _ => None,
                }
            }
            RobotParam::PayloadMass => Some(raw.tool_load.as_ref().map_or(0.0, |l| l.mass_kg)),
        }
    }

    fn param_error(&self, path: &str, message: &str) -> Error {
        Error::Machine(Located::whole_file(
            format!("robot `{}`", self.d.name),
            format!("{path}: {message} (a parameter set by value)"),
        ))
    }
}

/// Sets one parameter in the raw file; the message says why it cannot.
fn set(raw: &mut RawRobot, p: RobotParam, v: f64) -> std::result::Result<(), String> {
    match p {
        RobotParam::Dh { joint, field } => {
            let nominal = &raw.nominal;
            let actual = raw.actual.get_or_insert_with(|| nominal.clone());
            let row = actual
                .get_mut(joint)
                .ok_or_else(|| "no such DH row".to_string())?;
            match field {
                DhField::A => row.a_mm = v,
                DhField::Alpha => row.alpha_deg = v,
                DhField::D => row.d_mm = v,
                DhField::ThetaOffset => row.theta_offset_deg = v,
            }
        }
        RobotParam::JointStiffness { joint } => {
            *raw.k_nm_per_rad
                .get_mut(joint)
                .ok_or_else(|| "no such joint".to_string())? = v;
        }
        RobotParam::Thermal { term, field } => {
            let t = raw
                .thermal
                .as_mut()
                .and_then(|t| t.terms.get_mut(term))
                .ok_or_else(|| "the file has no such thermal term".to_string())?;
            match field {
                ThermalField::Lb => t.lb_mm = v,
                ThermalField::Ub => t.ub_mm = v,
                ThermalField::Ts => t.ts_per_w = v,
            }
        }
        RobotParam::ThermalTimeConstant => {
            raw.thermal
                .as_mut()
                .ok_or_else(|| "the file has no `thermal` section".to_string())?
                .time_constant_min = v;
        }
        RobotParam::ToolOffset { axis } => {
            let f = raw.flange_to_tool.get_or_insert(RawFrame {
                x_mm: 0.0,
                y_mm: 0.0,
                z_mm: 0.0,
                quaternion: None,
                rpy_deg: None,
            });
            match axis {
                0 => f.x_mm = v,
                1 => f.y_mm = v,
                2 => f.z_mm = v,
                _ => return Err("no such axis".into()),
            }
        }
        RobotParam::PayloadMass => {
            let tcp = raw
                .flange_to_tool
                .as_ref()
                .map_or([0.0; 3], |f| [f.x_mm, f.y_mm, f.z_mm]);
            raw.tool_load
                .get_or_insert(RawLoad {
                    mass_kg: 0.0,
                    cog_mm: tcp,
                })
                .mass_kg = v;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn text() -> String {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/machines/abb-irb1600.yaml");
        std::fs::read_to_string(path).expect("bundled file")
    }

    fn load(t: &str) -> Robot {
        Robot::from_yaml_str(t, "r.yaml").expect("valid")
    }

    #[test]
    fn set_values_equal_the_file_with_those_values() {
        let t = text();
        let r = load(&t)
            .with_params(&[
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
                    90.5,
                ),
                (RobotParam::JointStiffness { joint: 2 }, 150000.0),
                (
                    RobotParam::Thermal {
                        term: 1,
                        field: ThermalField::Ts,
                    },
                    0.025,
                ),
                (RobotParam::ThermalTimeConstant, 40.0),
            ])
            .expect("valid");
        let edited = t
            .replace("a_mm: 149.95,", "a_mm: 150.05,")
            .replace("alpha_deg: 90.03,", "alpha_deg: 90.5,")
            .replace("140940.0", "150000.0")
            .replace(
                "joint: 2, lb_mm: 0.12, ub_mm: 0.12, ts_per_w: 0.020",
                "joint: 2, lb_mm: 0.12, ub_mm: 0.12, ts_per_w: 0.025",
            )
            .replace("time_constant_min: 30", "time_constant_min: 40");
        assert_ne!(edited, t);
        assert_eq!(format!("{r:?}"), format!("{:?}", load(&edited)));
    }

    #[test]
    fn values_are_validated_again_and_missing_parameters_refused() {
        let r = load(&text());
        let far = RobotParam::Dh {
            joint: 2,
            field: DhField::A,
        };
        // 10 mm from the nominal length: beyond the plausibility limit.
        let e = r.with_params(&[(far, 710.0)]).expect_err("implausible");
        assert_eq!(e.kind(), crate::error::ErrorKind::Machine);
        assert!(e.to_string().contains("actual[2]"), "{e}");
        let soft = RobotParam::JointStiffness { joint: 0 };
        let e = r.with_params(&[(soft, -1.0)]).expect_err("negative");
        assert!(e.to_string().contains("k_nm_per_rad[0]"), "{e}");
        for p in [
            RobotParam::Dh {
                joint: 6,
                field: DhField::D,
            },
            RobotParam::Thermal {
                term: 99,
                field: ThermalField::Lb,
            },
        ] {
            let e = r.with_params(&[(p, 1.0)]).expect_err("not in the file");
            assert_eq!(e.kind(), crate::error::ErrorKind::Machine, "{p:?}");
            assert!(e.to_string().contains(&p.path()), "{e}");
        }
    }

    /// `param_value` reads what `with_params` set; a payload set on a
    /// file without `tool_load` sits at the tool centre point.
    #[test]
    fn param_value_reads_the_values_set() {
        let r = load(&text());
        let params = [
            (
                RobotParam::Dh {
                    joint: 2,
                    field: DhField::D,
                },
                0.05,
            ),
            (RobotParam::JointStiffness { joint: 5 }, 20000.0),
            (RobotParam::ToolOffset { axis: 0 }, 1.5),
            (RobotParam::PayloadMass, 6.5),
            (RobotParam::ThermalTimeConstant, 35.0),
        ];
        let set = r.with_params(&params).expect("valid");
        for (p, v) in params {
            assert_eq!(set.param_value(p), Some(v), "{p:?}");
        }
        let bare: String = text()
            .lines()
            .filter(|l| !l.starts_with("tool_load:"))
            .map(|l| format!("{l}\n"))
            .collect();
        let r = load(&bare);
        assert_eq!(r.param_value(RobotParam::PayloadMass), Some(0.0));
        let set = r
            .with_params(&[(RobotParam::PayloadMass, 2.0)])
            .expect("valid");
        let payload = set.tool_load().expect("a load");
        assert_eq!(payload.mass_kg, 2.0);
        assert_eq!(payload.com_mm, set.flange_to_tool().translation.vector);
    }
}
