//! Predicted process force of a robot (`process_force:` section): a constant
//! wrench on feed moves, or a drilling thrust along the tool axis from the
//! feed per revolution, `F = K · (D/2) · f_rev` with `f_rev = v_tcp · 60 /
//! rpm`. Which moves drill is decided by the RAPID pipeline with
//! [`plunge_direction`] and [`ProcessForce::drilling_wrench`].

use nalgebra::Vector3;

use super::raw::{RawForceFrame, RawForceModel, RawProcessForce, RawWrench, RawWrenchFrame};
use super::{ProcessWrench, Robot};
use crate::error::Invalid;

/// Default largest feed per revolution still taken as drilling, mm/rev: a
/// faster move along the tool axis is positioning in air.
pub const DEFAULT_MAX_FEED_MM_PER_REV: f64 = 0.5;
/// Default angle between a move and the tool axis for it to count as a
/// plunge or a retract, degrees.
pub const DEFAULT_AXIS_TOLERANCE_DEG: f64 = 3.0;
/// Default number of flutes (a twist drill has two).
pub const DEFAULT_FLUTES: u32 = 2;

/// Frame a constant force is given in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ForceFrame {
    /// The tool (TCP) frame.
    Tool,
    /// The work object frame of each move.
    Workpiece,
    /// The robot base frame.
    Base,
}

/// Which force model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ForceModel {
    /// A constant wrench on every feed move (MoveL, MoveC).
    Constant {
        /// Force, N.
        force_n: Vector3<f64>,
        /// Moment, N·mm.
        moment_nmm: Vector3<f64>,
        /// Frame of force and moment.
        frame: ForceFrame,
    },
    /// Drilling thrust along the tool axis on plunge moves.
    Drilling {
        /// Specific thrust `K`, N/mm².
        thrust_coefficient_n_per_mm2: f64,
        /// Drill diameter `D`, mm.
        drill_diameter_mm: f64,
        /// Largest feed per revolution taken as drilling, mm/rev.
        max_feed_mm_per_rev: f64,
    },
}

/// The validated `process_force:` section.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProcessForce {
    /// The model.
    pub model: ForceModel,
    /// Spindle speed, rev/min (required for drilling).
    pub spindle_rpm: Option<f64>,
    /// Cutting edges of the tool (tooth-passing frequency = rpm·flutes/60).
    pub flutes: u32,
    /// Largest angle between a move and the tool axis for a plunge, rad.
    pub axis_tolerance_rad: f64,
}

impl ProcessForce {
    /// Drilling thrust (N) at TCP speed `v_tcp_mm_per_s`, or `None` when the
    /// model is not drilling or the feed per revolution is above the
    /// drilling limit (positioning in air).
    pub fn drilling_thrust_n(&self, v_tcp_mm_per_s: f64) -> Option<f64> {
        let ForceModel::Drilling {
            thrust_coefficient_n_per_mm2: k,
            drill_diameter_mm: d,
            max_feed_mm_per_rev,
        } = self.model
        else {
            return None;
        };
        let rpm = self.spindle_rpm?;
        let f_rev = v_tcp_mm_per_s * 60.0 / rpm;
        (f_rev > 0.0 && f_rev <= max_feed_mm_per_rev).then(|| k * d / 2.0 * f_rev)
    }

    /// The wrench on the robot of a drilling plunge at `v_tcp_mm_per_s`: the
    /// workpiece pushes the drill back, `F = −thrust · z_tool` (tool frame).
    pub fn drilling_wrench(&self, v_tcp_mm_per_s: f64) -> Option<ProcessWrench> {
        self.drilling_thrust_n(v_tcp_mm_per_s)
            .map(|f| ProcessWrench {
                force_n: Vector3::new(0.0, 0.0, -f),
                moment_nmm: Vector3::zeros(),
                in_tool_frame: true,
            })
    }

    /// Tooth-passing frequency, Hz, when a spindle speed is given.
    pub fn excitation_hz(&self) -> Option<f64> {
        self.spindle_rpm.map(|r| r * f64::from(self.flutes) / 60.0)
    }

    pub(crate) fn from_raw(r: &RawProcessForce) -> Result<Self, Invalid> {
        let p = "process_force";
        let positive = |k: &str, v: Option<f64>| -> Result<Option<f64>, Invalid> {
            match v {
                Some(x) if !x.is_finite() || x <= 0.0 => Err(Invalid::new(
                    format!("{p}.{k}"),
                    format!("`{x}` must be a positive number"),
                )),
                other => Ok(other),
            }
        };
        let need = |k: &str, v: Option<f64>| -> Result<f64, Invalid> {
            positive(k, v)?.ok_or_else(|| Invalid::new(p, format!("model `drilling` needs `{k}`")))
        };
        let spindle_rpm = positive("spindle_rpm", r.spindle_rpm)?;
        let tol_deg = positive("axis_tolerance_deg", r.axis_tolerance_deg)?
            .unwrap_or(DEFAULT_AXIS_TOLERANCE_DEG);
        let flutes = r.flutes.unwrap_or(DEFAULT_FLUTES);
        if flutes == 0 {
            return Err(Invalid::new(format!("{p}.flutes"), "must be at least 1"));
        }
        // Keys of the other model are mistakes, not options.
        let stray: &[(&str, bool)] = match r.model {
            RawForceModel::Constant => &[
                (
                    "thrust_coefficient_n_per_mm2",
                    r.thrust_coefficient_n_per_mm2.is_some(),
                ),
                ("drill_diameter_mm", r.drill_diameter_mm.is_some()),
                ("max_feed_mm_per_rev", r.max_feed_mm_per_rev.is_some()),
                ("axis_tolerance_deg", r.axis_tolerance_deg.is_some()),
            ],
            RawForceModel::Drilling => &[
                ("force_n", r.force_n.is_some()),
                ("moment_nm", r.moment_nm.is_some()),
                ("frame", r.frame.is_some()),
            ],
        };
        if let Some((k, _)) = stray.iter().find(|(_, given)| *given) {
            let model = match r.model {
                RawForceModel::Constant => "constant",
                RawForceModel::Drilling => "drilling",
            };
            return Err(Invalid::new(
                format!("{p}.{k}"),
                format!("`{k}` does not apply to model `{model}`"),
            ));
        }
        let model = match r.model {
            RawForceModel::Constant => {
                let f = r.force_n.ok_or_else(|| {
                    Invalid::new(p, "model `constant` needs `force_n: [x, y, z]`")
                })?;
                let m = r.moment_nm.unwrap_or([0.0; 3]);
                if f.iter().chain(&m).any(|v| !v.is_finite()) {
                    return Err(Invalid::new(
                        format!("{p}.force_n"),
                        "force and moment must be finite numbers",
                    ));
                }
                ForceModel::Constant {
                    force_n: Vector3::from(f),
                    moment_nmm: Vector3::from(m) * 1000.0,
                    frame: match r.frame.unwrap_or(RawForceFrame::Tool) {
                        RawForceFrame::Tool => ForceFrame::Tool,
                        RawForceFrame::Workpiece => ForceFrame::Workpiece,
                        RawForceFrame::Base => ForceFrame::Base,
                    },
                }
            }
            RawForceModel::Drilling => {
                need("spindle_rpm", r.spindle_rpm)?;
                ForceModel::Drilling {
                    thrust_coefficient_n_per_mm2: need(
                        "thrust_coefficient_n_per_mm2",
                        r.thrust_coefficient_n_per_mm2,
                    )?,
                    drill_diameter_mm: need("drill_diameter_mm", r.drill_diameter_mm)?,
                    max_feed_mm_per_rev: positive("max_feed_mm_per_rev", r.max_feed_mm_per_rev)?
                        .unwrap_or(DEFAULT_MAX_FEED_MM_PER_REV),
                }
            }
        };
        Ok(ProcessForce {
            model,
            spindle_rpm,
            flutes,
            axis_tolerance_rad: tol_deg.to_radians(),
        })
    }

    /// The legacy `process_wrench:` key as a constant process force.
    pub(crate) fn from_wrench(w: &RawWrench) -> Result<Self, Invalid> {
        if w.force_n.iter().chain(&w.moment_nm).any(|v| !v.is_finite()) {
            return Err(Invalid::new(
                "process_wrench.force_n",
                "force and moment must be finite numbers",
            ));
        }
        Ok(ProcessForce {
            model: ForceModel::Constant {
                force_n: Vector3::from(w.force_n),
                moment_nmm: Vector3::from(w.moment_nm) * 1000.0,
                frame: match w.frame {
                    RawWrenchFrame::Tool => ForceFrame::Tool,
                    RawWrenchFrame::Base => ForceFrame::Base,
                },
            },
            spindle_rpm: None,
            flutes: DEFAULT_FLUTES,
            axis_tolerance_rad: DEFAULT_AXIS_TOLERANCE_DEG.to_radians(),
        })
    }
}

/// Direction of a straight move relative to the tool axis `z_tool` (unit):
/// `Some(true)` for a plunge (along +z, into the work), `Some(false)` for a
/// retract (along −z), `None` otherwise or for a move shorter than 1 µm.
pub fn plunge_direction(
    displacement: &Vector3<f64>,
    z_tool: &Vector3<f64>,
    tolerance_rad: f64,
) -> Option<bool> {
    const MIN_MOVE_MM: f64 = 1e-3;
    let n = displacement.norm();
    if n < MIN_MOVE_MM {
        return None;
    }
    let c = displacement.dot(z_tool) / n;
    if c >= tolerance_rad.cos() {
        Some(true)
    } else if c <= -tolerance_rad.cos() {
        Some(false)
    } else {
        None
    }
}

impl Robot {
    /// The process-force model of the file (`process_force:`, or the legacy
    /// `process_wrench:` as a constant force).
    pub fn process_force(&self) -> Option<&ProcessForce> {
        self.d.process_force.as_ref()
    }

    /// The same robot with `wrench` as the wrench the process stage applies
    /// (`None`: no process load).
    pub fn with_process_wrench(&self, wrench: Option<ProcessWrench>) -> Robot {
        let mut r = self.clone();
        r.d.process_wrench = wrench;
        r
    }
}
