//! Predicted process force of a robot (`process_force:` section), using the
//! machine-independent force models of [`crate::process`] as the force part
//! of a wrench at the tool centre point:
//!
//! * `constant` — a fixed wrench on feed moves (tool, work-object, base or
//!   feed frame);
//! * `milling` — the mechanistic mean forces of [`crate::process::Milling`],
//!   feed per tooth from the move's TCP speed and the spindle speed;
//! * `drilling` — the thrust of [`crate::process::Drilling`] along the tool
//!   axis from the feed per revolution `f_rev = v_tcp · 60 / rpm`;
//! * `table` — per-move forces from a CSV keyed by line
//!   ([`crate::process::ForceTable`], given per run).
//!
//! Which moves cut or drill is decided per move with [`plunge_direction`],
//! [`travel_direction`] and the methods of [`ProcessForce`]; depth, width
//! and spindle speed can be changed from a point of a program on by a
//! `! POSTPROC MILLING …` comment line in it, which arrives here as a
//! [`CutSettings`].

use nalgebra::Vector3;

use super::Robot;
use super::raw::{RawForceFrame, RawForceModel, RawProcessForce, RawWrench, RawWrenchFrame};
use crate::error::{Invalid, Result};
use crate::process::CutSettings;
use crate::process::{self, CutState, Drilling, Frame, Milling, MillingCache, Wrench, WrenchFrame};

/// Default largest feed per revolution still taken as drilling, mm/rev: a
/// faster move along the tool axis is positioning in air.
pub const DEFAULT_MAX_FEED_MM_PER_REV: f64 = 0.5;
/// Default angle between a move and the tool axis for it to count as a
/// plunge or a retract, degrees.
pub const DEFAULT_AXIS_TOLERANCE_DEG: f64 = 3.0;
/// Default number of flutes (a twist drill has two).
pub const DEFAULT_FLUTES: u32 = 2;

pub use crate::process::ForceModel;

/// The validated `process_force:` section.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProcessForce {
    /// The model.
    pub model: ForceModel,
    /// Spindle speed, rev/min (required for drilling and milling).
    pub spindle_rpm: Option<f64>,
    /// Cutting edges of the tool (tooth-passing frequency = rpm·flutes/60).
    pub flutes: u32,
    /// Largest angle between a move and the tool axis for a plunge, rad.
    pub axis_tolerance_rad: f64,
}

impl ProcessForce {
    /// The same model with spindle speed `rpm` when given.
    pub fn with_rpm(&self, rpm: Option<f64>) -> ProcessForce {
        ProcessForce {
            spindle_rpm: rpm.or(self.spindle_rpm),
            ..*self
        }
    }

    /// Drilling thrust (N) at TCP speed `v_tcp_mm_per_s`, or `None` when the
    /// model is not drilling or the feed per revolution is above the
    /// drilling limit (positioning in air).
    pub fn drilling_thrust_n(&self, v_tcp_mm_per_s: f64) -> Option<f64> {
        let ForceModel::Drilling {
            drill,
            max_feed_mm_per_rev,
        } = self.model
        else {
            return None;
        };
        let rpm = self.spindle_rpm?;
        let f_rev = v_tcp_mm_per_s * 60.0 / rpm;
        (f_rev > 0.0 && f_rev <= max_feed_mm_per_rev).then(|| drill.thrust_n(f_rev))
    }

    /// The wrench on the robot of a drilling plunge at `v_tcp_mm_per_s`: the
    /// workpiece pushes the drill back along the PROGRAMMED tool axis,
    /// `F = −thrust · z_tool`, with `z_tool` the target's tool z axis in the
    /// robot base frame (the hole is drilled along the programmed axis; the
    /// arm's own small orientation error does not turn the thrust). The
    /// wrench is in the base frame.
    pub fn drilling_wrench(&self, v_tcp_mm_per_s: f64, z_tool: &Vector3<f64>) -> Option<Wrench> {
        self.drilling_thrust_n(v_tcp_mm_per_s)
            .map(|f| Wrench::force(-f * z_tool, WrenchFrame::Base))
    }

    /// Mean milling force on the tool (N, in the frame of `travel` and
    /// `z_tool`) of a feed move travelling along `travel` with the TCP
    /// frame's z axis `z_tool` (pointing out of the tool, into the work) at
    /// `v_tcp_mm_per_s`, with the depth, width and spindle speed of `set`
    /// over the model's. The feed frame is the one of [`crate::process`]:
    /// axial = −`z_tool`. `None` when the model is not milling or nothing is
    /// cut (no spindle speed, no travel, travel along the tool axis).
    pub fn milling_force(
        &self,
        travel: &Vector3<f64>,
        z_tool: &Vector3<f64>,
        v_tcp_mm_per_s: f64,
        set: &CutSettings,
        cache: &mut MillingCache,
    ) -> Option<process::ProcessLoad> {
        let ForceModel::Milling(m) = self.model else {
            return None;
        };
        let state = CutState {
            line: 0,
            cutting: true,
            drilling: false,
            feed_dir: travel.try_normalize(1e-9)?,
            tool_axis: -z_tool,
            feed_mm_min: v_tcp_mm_per_s * 60.0,
            spindle_rpm: set.spindle_rpm.or(self.spindle_rpm)?,
            depth_mm: set.depth_mm,
            width_mm: set.width_mm,
        };
        let load = ForceModel::Milling(m).load(&state, cache, None);
        (load.tooth_hz > 0.0).then_some(load)
    }

    /// Tooth-passing frequency, Hz, when a spindle speed is given.
    pub fn excitation_hz(&self) -> Option<f64> {
        self.spindle_rpm.map(|r| r * f64::from(self.flutes) / 60.0)
    }

    pub(crate) fn from_raw(r: &RawProcessForce) -> Result<Self, Invalid> {
        let model_name = match r.model {
            RawForceModel::Constant => "constant",
            RawForceModel::Milling => "milling",
            RawForceModel::Drilling => "drilling",
            RawForceModel::Table => {
                return Err(Invalid::new(
                    format!("{P}.model"),
                    "a force table is given per run with --force-table FILE",
                ));
            }
        };
        let spindle_rpm = positive("spindle_rpm", r.spindle_rpm)?;
        let tol_deg = positive("axis_tolerance_deg", r.axis_tolerance_deg)?
            .unwrap_or(DEFAULT_AXIS_TOLERANCE_DEG);
        let flutes = r.flutes.unwrap_or(DEFAULT_FLUTES);
        if flutes == 0 || flutes > 64 {
            return Err(Invalid::new(
                format!("{P}.flutes"),
                format!("`{flutes}` flutes is outside 1..64"),
            ));
        }
        refuse_other_keys(r, model_name)?;
        let model = match r.model {
            RawForceModel::Constant => constant_model(r)?,
            RawForceModel::Milling => milling_model(r, flutes)?,
            // (`table` was refused above.)
            RawForceModel::Drilling | RawForceModel::Table => drilling_model(r, model_name)?,
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
                    RawWrenchFrame::Tool => Frame::Tool,
                    RawWrenchFrame::Base => Frame::Base,
                },
            },
            spindle_rpm: None,
            flutes: DEFAULT_FLUTES,
            axis_tolerance_rad: DEFAULT_AXIS_TOLERANCE_DEG.to_radians(),
        })
    }
}

/// The key of `process_force:` in machine files.
const P: &str = "process_force";

/// An optional value that must be positive when given.
fn positive(k: &str, v: Option<f64>) -> Result<Option<f64>, Invalid> {
    match v {
        Some(x) if !x.is_finite() || x <= 0.0 => Err(Invalid::new(
            format!("{P}.{k}"),
            format!("`{x}` must be a positive number"),
        )),
        other => Ok(other),
    }
}

/// A positive value that model `model_name` needs.
fn need(k: &str, v: Option<f64>, model_name: &str) -> Result<f64, Invalid> {
    positive(k, v)?.ok_or_else(|| Invalid::new(P, format!("model `{model_name}` needs `{k}`")))
}

/// A milling value within lo..=hi; `None` → `default` (or an error).
fn within(k: &str, v: Option<f64>, lo: f64, hi: f64, default: Option<f64>) -> Result<f64, Invalid> {
    match v {
        Some(x) if !x.is_finite() || x < lo || x > hi => Err(Invalid::new(
            format!("{P}.{k}"),
            format!("`{x}` is outside {lo}..{hi}"),
        )),
        Some(x) => Ok(x),
        None => default.ok_or_else(|| Invalid::new(P, format!("model `milling` needs `{k}`"))),
    }
}

/// Refuses the keys of another model: they are mistakes, not options.
fn refuse_other_keys(r: &RawProcessForce, model_name: &str) -> Result<(), Invalid> {
    let given: [(&str, bool); 16] = [
        ("force_n", r.force_n.is_some()),
        ("moment_nm", r.moment_nm.is_some()),
        ("frame", r.frame.is_some()),
        (
            "thrust_coefficient_n_per_mm2",
            r.thrust_coefficient_n_per_mm2.is_some(),
        ),
        ("drill_diameter_mm", r.drill_diameter_mm.is_some()),
        ("max_feed_mm_per_rev", r.max_feed_mm_per_rev.is_some()),
        ("axis_tolerance_deg", r.axis_tolerance_deg.is_some()),
        ("kt_n_per_mm2", r.kt_n_per_mm2.is_some()),
        ("kr_n_per_mm2", r.kr_n_per_mm2.is_some()),
        ("ka_n_per_mm2", r.ka_n_per_mm2.is_some()),
        ("kte_n_per_mm", r.kte_n_per_mm.is_some()),
        ("kre_n_per_mm", r.kre_n_per_mm.is_some()),
        ("kae_n_per_mm", r.kae_n_per_mm.is_some()),
        ("tool_diameter_mm", r.tool_diameter_mm.is_some()),
        ("axial_depth_mm", r.axial_depth_mm.is_some()),
        ("radial_width_mm", r.radial_width_mm.is_some()),
    ];
    let allowed: &[&str] = match r.model {
        RawForceModel::Constant => &["force_n", "moment_nm", "frame"],
        RawForceModel::Drilling => &[
            "thrust_coefficient_n_per_mm2",
            "drill_diameter_mm",
            "max_feed_mm_per_rev",
            "axis_tolerance_deg",
        ],
        RawForceModel::Table => &[],
        RawForceModel::Milling => &[
            "kt_n_per_mm2",
            "kr_n_per_mm2",
            "ka_n_per_mm2",
            "kte_n_per_mm",
            "kre_n_per_mm",
            "kae_n_per_mm",
            "tool_diameter_mm",
            "axial_depth_mm",
            "radial_width_mm",
        ],
    };
    if let Some((k, _)) = given
        .iter()
        .find(|(k, present)| *present && !allowed.contains(k))
    {
        return Err(Invalid::new(
            format!("{P}.{k}"),
            format!("`{k}` does not apply to model `{model_name}`"),
        ));
    }
    Ok(())
}

/// Model `constant`: a force and moment in a chosen frame.
fn constant_model(r: &RawProcessForce) -> Result<ForceModel, Invalid> {
    let f = r
        .force_n
        .ok_or_else(|| Invalid::new(P, "model `constant` needs `force_n: [x, y, z]`"))?;
    let m = r.moment_nm.unwrap_or([0.0; 3]);
    if f.iter().chain(&m).any(|v| !v.is_finite()) {
        return Err(Invalid::new(
            format!("{P}.force_n"),
            "force and moment must be finite numbers",
        ));
    }
    Ok(ForceModel::Constant {
        force_n: Vector3::from(f),
        moment_nmm: Vector3::from(m) * 1000.0,
        frame: match r.frame.unwrap_or(RawForceFrame::Tool) {
            RawForceFrame::Tool => Frame::Tool,
            RawForceFrame::Workpiece => Frame::Workpiece,
            RawForceFrame::Base => Frame::Base,
            RawForceFrame::Feed => Frame::Feed,
        },
    })
}

/// Model `milling`: cutting coefficients, tool and engagement.
fn milling_model(r: &RawProcessForce, flutes: u32) -> Result<ForceModel, Invalid> {
    need("spindle_rpm", r.spindle_rpm, "milling")?;
    if r.flutes.is_none() {
        return Err(Invalid::new(P, "model `milling` needs `flutes`"));
    }
    let d = within("tool_diameter_mm", r.tool_diameter_mm, 0.01, 1000.0, None)?;
    Ok(ForceModel::Milling(Milling {
        kt_n_per_mm2: within("kt_n_per_mm2", r.kt_n_per_mm2, 0.0, 1e5, None)?,
        kr_n_per_mm2: within("kr_n_per_mm2", r.kr_n_per_mm2, 0.0, 1e5, None)?,
        ka_n_per_mm2: within("ka_n_per_mm2", r.ka_n_per_mm2, 0.0, 1e5, Some(0.0))?,
        kte_n_per_mm: within("kte_n_per_mm", r.kte_n_per_mm, 0.0, 1e6, Some(0.0))?,
        kre_n_per_mm: within("kre_n_per_mm", r.kre_n_per_mm, 0.0, 1e6, Some(0.0))?,
        kae_n_per_mm: within("kae_n_per_mm", r.kae_n_per_mm, 0.0, 1e6, Some(0.0))?,
        tool_diameter_mm: d,
        flutes,
        axial_depth_mm: within("axial_depth_mm", r.axial_depth_mm, 0.0, 1000.0, None)?,
        radial_width_mm: within("radial_width_mm", r.radial_width_mm, 0.0, d, None)?,
    }))
}

/// Model `drilling`: thrust from the feed per revolution.
fn drilling_model(r: &RawProcessForce, model_name: &str) -> Result<ForceModel, Invalid> {
    need("spindle_rpm", r.spindle_rpm, model_name)?;
    Ok(ForceModel::Drilling {
        drill: Drilling {
            thrust_coefficient_n_per_mm2: need(
                "thrust_coefficient_n_per_mm2",
                r.thrust_coefficient_n_per_mm2,
                model_name,
            )?,
            drill_diameter_mm: need("drill_diameter_mm", r.drill_diameter_mm, model_name)?,
        },
        max_feed_mm_per_rev: positive("max_feed_mm_per_rev", r.max_feed_mm_per_rev)?
            .unwrap_or(DEFAULT_MAX_FEED_MM_PER_REV),
    })
}

/// The wrench the process stage applies without a per-move one: a constant
/// force in the tool or base frame; none for the other models and frames.
pub(crate) fn default_wrench(pf: Option<&ProcessForce>) -> Option<Wrench> {
    match pf.map(|f| f.model) {
        Some(ForceModel::Constant {
            force_n,
            moment_nmm,
            frame: frame @ (Frame::Tool | Frame::Base),
        }) => Some(Wrench {
            force_n,
            moment_nmm,
            frame: if frame == Frame::Tool {
                WrenchFrame::Tool
            } else {
                WrenchFrame::Base
            },
        }),
        _ => None,
    }
}

/// A constant force (or moment) `v` given in the feed frame, turned into the
/// frame of `travel` and `z_tool` (see [`Frame::Feed`]); one definition
/// with the machine-tool side ([`crate::process::ForceModel::Constant`]).
pub fn feed_frame_vector(
    v: &Vector3<f64>,
    travel: &Vector3<f64>,
    z_tool: &Vector3<f64>,
) -> Vector3<f64> {
    let state = CutState {
        line: 0,
        cutting: true,
        drilling: false,
        feed_dir: *travel,
        tool_axis: -z_tool,
        feed_mm_min: 0.0,
        spindle_rpm: 0.0,
        depth_mm: None,
        width_mm: None,
    };
    ForceModel::constant(*v, Frame::Feed)
        .load(&state, &mut MillingCache::default(), None)
        .force_n
}

/// Direction of travel at the end `p1` of a move from `p0`: along the line
/// for a straight move, the tangent of the circle through `p0`, `via`, `p1`
/// at `p1` for a circular one (the chord when the three points are on a
/// line). Not normalised; zero for a move shorter than 1 µm.
pub fn travel_direction(
    p0: &Vector3<f64>,
    via: Option<&Vector3<f64>>,
    p1: &Vector3<f64>,
) -> Vector3<f64> {
    const MIN_MOVE_MM: f64 = 1e-3;
    let chord = p1 - p0;
    if chord.norm() < MIN_MOVE_MM {
        return Vector3::zeros();
    }
    let Some(b) = via else {
        return chord;
    };
    let u = b - p0;
    let v = p1 - p0;
    let w = u.cross(&v);
    let w2 = w.norm_squared();
    if w2 < 1e-12 * u.norm_squared() * v.norm_squared() || w2 == 0.0 {
        return chord;
    }
    // Circumcentre of the three points.
    let c = p0 + (v.cross(&w) * u.norm_squared() + w.cross(&u) * v.norm_squared()) / (2.0 * w2);
    w.cross(&(p1 - c))
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

    /// The same robot with another process-force model (`None`: no process
    /// force), as the command line's `--force` sets it.
    pub fn with_process_force(&self, pf: Option<ProcessForce>) -> Robot {
        let mut r = self.clone();
        r.d.process_force = pf;
        r
    }
}

impl ProcessForce {
    /// The model `table` (per-move forces of a run's force table,
    /// work-object frame), keeping the spindle speed and flutes of `old`
    /// (the file's model) for the vibration report.
    pub fn table(old: Option<&ProcessForce>) -> ProcessForce {
        ProcessForce {
            model: ForceModel::Table,
            spindle_rpm: old.and_then(|p| p.spindle_rpm),
            flutes: old.map_or(DEFAULT_FLUTES, |p| p.flutes),
            axis_tolerance_rad: DEFAULT_AXIS_TOLERANCE_DEG.to_radians(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    const FORCE_TOL_N: f64 = 1e-9;

    fn milling() -> ProcessForce {
        ProcessForce {
            model: ForceModel::Milling(Milling {
                kt_n_per_mm2: 2000.0,
                kr_n_per_mm2: 800.0,
                ka_n_per_mm2: 0.0,
                kte_n_per_mm: 0.0,
                kre_n_per_mm: 0.0,
                kae_n_per_mm: 0.0,
                tool_diameter_mm: 10.0,
                flutes: 2,
                axial_depth_mm: 2.0,
                radial_width_mm: 10.0,
            }),
            spindle_rpm: Some(1000.0),
            flutes: 2,
            axis_tolerance_rad: DEFAULT_AXIS_TOLERANCE_DEG.to_radians(),
        }
    }

    #[test]
    fn milling_force_is_the_machine_tool_slot() {
        // tests/effects.rs: slot, a = 2 mm, N = 2, c = 400/(1000·2) = 0.2 mm
        // (v_tcp = 400/60 mm/s): tangential −160 N, normal 400 N. Travel +X,
        // TCP z = −Z (tool down): axial = +Z, normal = Z × X = +Y.
        let pf = milling();
        let mut cache = MillingCache::default();
        let set = CutSettings::default();
        let l = pf
            .milling_force(
                &Vector3::x(),
                &-Vector3::z(),
                400.0 / 60.0,
                &set,
                &mut cache,
            )
            .expect("cuts");
        assert_abs_diff_eq!(
            l.force_n,
            Vector3::new(-160.0, 400.0, 0.0),
            epsilon = FORCE_TOL_N
        );
        // Tooth passing 1000·2/60 Hz, as `excitation_hz`.
        assert_abs_diff_eq!(
            l.tooth_hz,
            pf.excitation_hz().expect("rpm"),
            epsilon = FORCE_TOL_N
        );
        // A directive doubling the speed halves c: −80, 200 N.
        let fast = CutSettings {
            spindle_rpm: Some(2000.0),
            ..set
        };
        let l = pf
            .milling_force(
                &Vector3::x(),
                &-Vector3::z(),
                400.0 / 60.0,
                &fast,
                &mut cache,
            )
            .expect("cuts");
        assert_abs_diff_eq!(
            l.force_n,
            Vector3::new(-80.0, 200.0, 0.0),
            epsilon = FORCE_TOL_N
        );
        // Along the tool axis (plunge) and without travel nothing is cut.
        let z = -Vector3::z();
        assert!(pf.milling_force(&z, &z, 5.0, &set, &mut cache).is_none());
        assert!(
            pf.milling_force(&Vector3::zeros(), &z, 5.0, &set, &mut cache)
                .is_none()
        );
        // Other models have no milling force.
        let drill = ProcessForce {
            model: ForceModel::Table,
            ..pf
        };
        assert!(
            drill
                .milling_force(&Vector3::x(), &z, 5.0, &set, &mut cache)
                .is_none()
        );
    }

    #[test]
    fn feed_frame_vector_turns_with_travel_and_tool() {
        // Travel +Y, TCP z = −Z: x = +Y, z = +Z, y = Z × Y = −X:
        // (1, 2, 3) → (−2, 1, 3).
        let v = feed_frame_vector(&Vector3::new(1.0, 2.0, 3.0), &Vector3::y(), &-Vector3::z());
        assert_abs_diff_eq!(v, Vector3::new(-2.0, 1.0, 3.0), epsilon = FORCE_TOL_N);
    }

    #[test]
    fn drilling_thrust_is_the_process_model() {
        // K·(D/2)·f_rev = 450·3.4·(4·60/3000) = 122.4 N, as
        // process::Drilling::thrust_n; a directive RPM of 6000 halves it.
        let pf = ProcessForce {
            model: ForceModel::Drilling {
                drill: Drilling {
                    thrust_coefficient_n_per_mm2: 450.0,
                    drill_diameter_mm: 6.8,
                },
                max_feed_mm_per_rev: DEFAULT_MAX_FEED_MM_PER_REV,
            },
            spindle_rpm: Some(3000.0),
            flutes: 2,
            axis_tolerance_rad: DEFAULT_AXIS_TOLERANCE_DEG.to_radians(),
        };
        assert_abs_diff_eq!(
            pf.drilling_thrust_n(4.0).expect("drills"),
            122.4,
            epsilon = FORCE_TOL_N
        );
        assert_abs_diff_eq!(
            pf.with_rpm(Some(6000.0))
                .drilling_thrust_n(4.0)
                .expect("drills"),
            61.2,
            epsilon = FORCE_TOL_N
        );
        assert_eq!(pf.with_rpm(None), pf);
    }

    /// The thrust pushes back along the programmed tool axis: at the actual
    /// arm (whose DH errors tilt its tool axis by ≈ 1 mrad against the
    /// nominal one) the base-frame force is still −thrust · z_programmed.
    #[test]
    fn drilling_thrust_acts_along_the_programmed_tool_axis() {
        use crate::machine::robot::Model;
        let pf = ProcessForce {
            model: ForceModel::Drilling {
                drill: Drilling {
                    thrust_coefficient_n_per_mm2: 450.0,
                    drill_diameter_mm: 6.8,
                },
                max_feed_mm_per_rev: DEFAULT_MAX_FEED_MM_PER_REV,
            },
            spindle_rpm: Some(3000.0),
            flutes: 2,
            axis_tolerance_rad: DEFAULT_AXIS_TOLERANCE_DEG.to_radians(),
        };
        let r = crate::machine::robot::test_irb1600();
        let q = [0.3, 0.2, -0.1, 0.4, 1.2, -0.5];
        let tool = |m: Model| (r.flange_pose(m, &q) * r.flange_to_tool()).rotation * Vector3::z();
        let z_prog = tool(Model::Nominal);
        // The actual arm's tool axis differs (the test means something).
        assert!((tool(Model::Actual) - z_prog).norm() > 1e-5);
        let w = pf.drilling_wrench(4.0, &z_prog).expect("drills");
        let base = r.process_wrench_base(Model::Actual, &q, Some(&w));
        let want = -122.4 * z_prog;
        for c in 0..3 {
            assert_abs_diff_eq!(base[c], want[c], epsilon = FORCE_TOL_N);
            assert_abs_diff_eq!(base[3 + c], 0.0, epsilon = FORCE_TOL_N);
        }
    }
}
