//! Forward model of one observation row: where a machine file says the
//! measured point is for the row's commanded pose, load and state.
//!
//! This is the single definition of "simulated" shared by `simulate` (which
//! writes it, plus noise, into the measured columns), `calibrate` (which fits
//! parameters so it matches the measurements) and `diagnose` (which studies
//! measured − simulated).
//!
//! Frames and conventions:
//! - Robot rows: positions in the robot base frame. The joints are the
//!   controller's `q1…q6`; the real arm has the actual DH parameters and its
//!   joints yield under the gravity torques of the links and the tool load and
//!   under the row's external wrench (`fx_n…`, `mx_nm…`) applied at the wrench
//!   point: `Δθ = Kθ⁻¹ (τ_g + J_WPᵀ W)`. The measured point (`mp_*`, default
//!   the tool centre point) is then carried by the deflected flange. The
//!   commanded position is the measured point on the nominal model without
//!   any load. A row with joint motor powers (`p1_w…p6_w`, missing ones 0 W)
//!   has the actual DH lengths grown by the machine file's `thermal` terms
//!   at those powers (Paper B, thermal steady state); a row without powers
//!   uses the actual DH lengths as they are.
//! - Machine-tool rows: positions in the machine's workpiece frame as the
//!   kinematic chain returns them (equal to the commanded axis position when
//!   the machine is error-free). The attained position is the tool tip of the
//!   geometric model for the row's axes, last-motion signs and tool length
//!   (default: the lowest-numbered tool of the machine file's tool table, or
//!   the gauge line when the table is empty). The prediction is the G-code
//!   path's own ([`crate::predict::ToolPredictor`], machines/README.md,
//!   *Process effects*) with every switched effect at gain 1:
//!   - a row force (`fx_n…`, the force on the tool from the workpiece, N)
//!     deflects the tip through the machine file's `stiffness:` map at the
//!     commanded X, Y, Z: attained += F/k per axis;
//!   - a row with spindle or feed-drive powers (`spindle_w`, `pX_w`, `pY_w`,
//!     `pZ_w`; missing ones 0 W) is at the thermal STEADY STATE of those
//!     mean powers: the machine file's `thermal:` section grows the spindle
//!     by `growth_um_per_kw · P_s` (the tip moves that far against the
//!     tool axis) and scales each axis by `scale_ppm_per_kw · P_i`.
//!     The measured `spindle_w` is the whole spindle power (no
//!     `idle_w_per_rpm · spindle_rpm` is added), and `t_s` alone does not
//!     drive the thermal model (a row without powers is cold).

use nalgebra::{Point3, UnitQuaternion, Vector3, Vector6};

use crate::error::{Error, Located, Result};
use crate::machine::Machine;
use crate::machine::robot::{DhGrowth, Model, Robot, Trial};
use crate::machine::tool::thermal::Powers;
use crate::machine::tool::{MachineTool, ThermalState};
use crate::predict::{
    Effect, EffectSet, MoveContext, ThermalInput, ToolPredictor, Wrench, WrenchFrame,
};

use super::observations::{
    MeasuredKind, ObsKind, Observation, Observations, Pose, RobotPose, ToolPose,
};

/// Commanded and predicted attained position of the measured point of a row.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Predicted {
    /// Where the controller believes the measured point is, mm.
    pub commanded_mm: Vector3<f64>,
    /// Where the model says the measured point really is, mm.
    pub attained_mm: Vector3<f64>,
    /// Orientation of the measured frame the model predicts (robot: the
    /// deflected flange carrying the tool frame's rotation); `None` for a
    /// machine tool.
    pub attained_rot: Option<UnitQuaternion<f64>>,
}

impl Predicted {
    /// Attained − commanded, mm.
    pub fn deviation_mm(&self) -> Vector3<f64> {
        self.attained_mm - self.commanded_mm
    }

    /// The triple a file with `kind` stores for this row.
    pub fn measured(&self, kind: MeasuredKind) -> Vector3<f64> {
        match kind {
            MeasuredKind::Position => self.attained_mm,
            MeasuredKind::Deviation => self.deviation_mm(),
        }
    }
}

/// Checks that the observations were taken on the kind of machine given.
pub fn check_kind(machine: &Machine, obs: &Observations, file: &str) -> Result<()> {
    let ok = matches!(
        (machine, obs.kind),
        (Machine::Robot(_), ObsKind::Robot) | (Machine::Tool(_), ObsKind::MachineTool)
    );
    if ok {
        Ok(())
    } else {
        let (m, o) = match obs.kind {
            ObsKind::Robot => ("a machine tool", "robot joint columns (q1_deg…)"),
            ObsKind::MachineTool => ("a robot", "machine-tool axis columns (X_mm…)"),
        };
        Err(Error::Usage(format!(
            "{file}: the observations have {o} but the machine file describes {m}"
        )))
    }
}

/// Which effects a prediction includes (all by default): geometric (the
/// actual DH parameters / the error tables), static (gravity sag and the
/// row's wrench / the row's force through the stiffness map) and thermal
/// (the row's powers through the `thermal` terms).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Switches {
    /// Geometric errors.
    pub geometric: bool,
    /// Deflection under gravity and loads.
    pub static_: bool,
    /// Thermal growth at the row's powers.
    pub thermal: bool,
}

impl Default for Switches {
    fn default() -> Self {
        Switches {
            geometric: true,
            static_: true,
            thermal: true,
        }
    }
}

/// Predicts one row. `file` names the observation file in errors.
pub fn predict(machine: &Machine, row: &Observation, file: &str) -> Result<Predicted> {
    predict_with(machine, row, file, Switches::default())
}

/// [`predict`] with only the effects `sw` switched on.
pub fn predict_with(
    machine: &Machine,
    row: &Observation,
    file: &str,
    sw: Switches,
) -> Result<Predicted> {
    let p = match (machine, &row.pose) {
        (Machine::Robot(r), Pose::Robot(rp)) if sw == Switches::default() => {
            predict_robot(r, row, rp, true)
        }
        (Machine::Robot(r), Pose::Robot(rp)) => {
            let r = if sw.geometric {
                r.clone()
            } else {
                r.trial_with_params(&[Trial::Actual(*r.params(Model::Nominal))])
            };
            let p = predict_robot(&r, row, rp, sw.static_);
            if sw.thermal {
                p
            } else {
                predict_robot_at(&r, row, rp, sw.static_)
            }
        }
        (Machine::Tool(t), Pose::Tool(tp)) => predict_tool(t, row, tp, sw),
        _ => {
            return Err(Error::Usage(format!(
                "{file}: row `{}` does not match the kind of machine file",
                row.id
            )));
        }
    };
    if p.attained_mm
        .iter()
        .chain(p.commanded_mm.iter())
        .all(|v| v.is_finite())
    {
        Ok(p)
    } else {
        Err(Error::Input(Located {
            file: file.to_string(),
            line: row.line,
            column: 1,
            message: format!("row `{}`: the model gives a non-finite position", row.id),
        }))
    }
}

/// The measured point of a robot row in the flange frame.
pub fn measured_point(robot: &Robot, rp: &RobotPose) -> Vector3<f64> {
    rp.mp_mm
        .unwrap_or_else(|| robot.flange_to_tool().translation.vector)
}

/// The wrench point of a robot row in the flange frame.
pub fn wrench_point(robot: &Robot, rp: &RobotPose) -> Vector3<f64> {
    rp.wp_mm
        .unwrap_or_else(|| robot.flange_to_tool().translation.vector)
}

/// Joint angles of a robot row, rad.
pub fn joints_rad(rp: &RobotPose) -> [f64; 6] {
    rp.q_deg.map(f64::to_radians)
}

/// External wrench of a row, robot base frame, `[F (N); M (N·mm)]`.
pub fn row_wrench(row: &Observation) -> Vector6<f64> {
    let mut w = Vector6::zeros();
    w.fixed_rows_mut::<3>(0).copy_from(&row.force_n);
    w.fixed_rows_mut::<3>(3)
        .copy_from(&(row.moment_nm * 1000.0));
    w
}

fn predict_robot(robot: &Robot, row: &Observation, rp: &RobotPose, loads: bool) -> Predicted {
    if rp.p_w.iter().any(Option::is_some) && robot.thermal().is_some() {
        let hot = robot.at_joint_power(&rp.p_w.map(|p| p.unwrap_or(0.0)));
        return predict_robot_at(&hot, row, rp, loads);
    }
    predict_robot_at(robot, row, rp, loads)
}

/// Predicts a robot row with the actual DH lengths grown by `growth` (mm,
/// `[Δa, Δd]` per row) INSTEAD of the machine file's thermal terms: the
/// forward model of a thermal calibration, whose trial terms give the
/// growth. `file` names the observation file in errors.
pub fn predict_robot_with_growth(
    robot: &Robot,
    row: &Observation,
    growth: &DhGrowth,
    file: &str,
) -> Result<Predicted> {
    let Pose::Robot(rp) = &row.pose else {
        return Err(Error::Usage(format!(
            "{file}: row `{}` is not a robot row",
            row.id
        )));
    };
    let mut p = *robot.params(Model::Actual);
    for (j, g) in p.joints.iter_mut().zip(growth) {
        j.a_mm += g[0];
        j.d_mm += g[1];
    }
    let grown = robot.trial_with_params(&[Trial::Actual(p)]);
    let out = predict_robot_at(&grown, row, rp, true);
    if out
        .attained_mm
        .iter()
        .chain(out.commanded_mm.iter())
        .all(|v| v.is_finite())
    {
        Ok(out)
    } else {
        Err(Error::Input(Located {
            file: file.to_string(),
            line: row.line,
            column: 1,
            message: format!("row `{}`: the model gives a non-finite position", row.id),
        }))
    }
}

fn predict_robot_at(robot: &Robot, row: &Observation, rp: &RobotPose, loads: bool) -> Predicted {
    let q = joints_rad(rp);
    let mp = Point3::from(measured_point(robot, rp));
    let wp = wrench_point(robot, rp);
    let tau = if loads {
        robot.gravity_torques(Model::Actual, &q)
            + robot.wrench_torques(Model::Actual, &q, &wp, &row_wrench(row))
    } else {
        Default::default()
    };
    let flange = robot.deflected_flange(Model::Actual, &q, &tau);
    let attained = flange * mp;
    let commanded = robot.flange_pose(Model::Nominal, &q) * mp;
    Predicted {
        commanded_mm: commanded.coords,
        attained_mm: attained.coords,
        attained_rot: Some(flange.rotation * robot.flange_to_tool().rotation),
    }
}

/// Tool length of a machine-tool row, mm.
pub fn tool_length(tool: &MachineTool, tp: &ToolPose) -> f64 {
    tp.tool_mm
        .or_else(|| tool.tools().next().map(|(_, l)| l))
        .unwrap_or(0.0)
}

/// Mean heat-source powers of a machine-tool row (spindle, X, Y, Z drives),
/// W; `None` when the row gives none of them (a cold row).
pub fn tool_powers(tp: &ToolPose) -> Option<Powers> {
    let given = tp.spindle_w.is_some() || tp.p_w.iter().take(3).any(Option::is_some);
    given.then(|| {
        let p = |i: usize| tp.p_w.get(i).copied().flatten().unwrap_or(0.0);
        [tp.spindle_w.unwrap_or(0.0), p(0), p(1), p(2)]
    })
}

/// A machine-tool row by the G-code path's predictor
/// ([`ToolPredictor::evaluate`]): the switched effects at gain 1, the row's
/// force, and the thermal state of the row's powers held for ever.
fn predict_tool(tool: &MachineTool, row: &Observation, tp: &ToolPose, sw: Switches) -> Predicted {
    let on = |b: bool| if b { 1.0 } else { 0.0 };
    let effects = EffectSet::default()
        .with_gain(Effect::Geometric, on(sw.geometric))
        .with_gain(Effect::Static, on(sw.static_))
        .with_gain(Effect::Thermal, on(sw.thermal))
        .with_gain(Effect::Dynamic, 0.0);
    let thermal = match (tool.thermal(), tool_powers(tp)) {
        (Some(t), Some(p)) => t.warm_up(&p, f64::INFINITY),
        _ => ThermalState::default(),
    };
    let ctx = MoveContext {
        wrench: Some(Wrench::force(row.force_n, WrenchFrame::Workpiece)),
        thermal: ThermalInput::Tool(thermal),
        ..MoveContext::default()
    };
    let predictor = ToolPredictor::new(tool, effects).with_context(ctx);
    let (_, attained, nominal) = predictor.evaluate(&tp.axes(), &tp.dirs(), tool_length(tool, tp));
    Predicted {
        commanded_mm: nominal.pos,
        attained_mm: attained.pos,
        attained_rot: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    const POS_TOL_MM: f64 = 1e-9;

    fn irb1600() -> Machine {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/machines/abb-irb1600.yaml");
        Machine::load(std::path::Path::new(path)).expect("machine file loads")
    }

    fn robot_row(q_deg: [f64; 6], force_n: Vector3<f64>) -> Observation {
        Observation {
            orientation: None,
            line: 0,
            id: "r".into(),
            t_s: None,
            measured_mm: Vector3::zeros(),
            force_n,
            moment_nm: Vector3::zeros(),
            ambient_c: None,
            pose: Pose::Robot(RobotPose {
                q_deg,
                mp_mm: Some(Vector3::zeros()),
                wp_mm: Some(Vector3::zeros()),
                p_w: [None; 6],
                dir: [None; 6],
            }),
        }
    }

    /// At all joints zero the nominal IRB 1600 flange is at (815, 0, 1186.5)
    /// mm (docs/physics.md: 150 + 600 + 65 in front, 486.5 + 700 above).
    #[test]
    fn robot_commanded_is_nominal_flange() {
        let m = irb1600();
        let p = predict(&m, &robot_row([0.0; 6], Vector3::zeros()), "t").unwrap();
        assert_abs_diff_eq!(
            p.commanded_mm,
            Vector3::new(815.0, 0.0, 1186.5),
            epsilon = 1e-6
        );
    }

    /// A force changes the attained position by J_MP Kθ⁻¹ J_WPᵀ W to first
    /// order (the statics module's small-deflection formula, an independent
    /// path from the deflected forward kinematics used here).
    #[test]
    fn robot_force_deflection_is_linear_statics() {
        let Machine::Robot(r) = irb1600() else {
            panic!("robot file")
        };
        let m = Machine::Robot(r.clone());
        let q_deg = [10.0, 20.0, -15.0, 30.0, 40.0, 50.0];
        let f = Vector3::new(0.0, 0.0, -335.0);
        let a0 = predict(&m, &robot_row(q_deg, Vector3::zeros()), "t").unwrap();
        let a1 = predict(&m, &robot_row(q_deg, f), "t").unwrap();
        let q = q_deg.map(f64::to_radians);
        let mut w = Vector6::zeros();
        w.fixed_rows_mut::<3>(0).copy_from(&f);
        let tau = r.wrench_torques(Model::Actual, &q, &Vector3::zeros(), &w);
        let lin = r.point_deflection(Model::Actual, &q, &Vector3::zeros(), &tau);
        let got = a1.attained_mm - a0.attained_mm;
        // Second-order terms of a ≈1 mm deflection over a ≈1 m arm are ≈1 µm.
        assert_abs_diff_eq!(got, lin.fixed_rows::<3>(0).into_owned(), epsilon = 5e-3);
        assert!(got.norm() > 0.1, "a 335 N load deflects the arm noticeably");
        assert_abs_diff_eq!(a1.commanded_mm, a0.commanded_mm, epsilon = POS_TOL_MM);
    }

    /// Measured joint powers grow the DH lengths (Paper B). At all joints
    /// zero the IRB 1600 flange sits at x = a2 + d4 + d6, z = d1 + a3
    /// (mDH), so the attained point moves by
    /// (Δa2 + Δd4, 0, Δa3) between a row at 0 W and a row at the Paper B
    /// top powers; the gravity sag barely changes for a 0.1 mm longer arm.
    /// The example calibration's joint-angle and twist errors (about a
    /// milliradian) tilt the growth directions: ≈ 0.3 mm × 1 mrad = 0.3 µm,
    /// hence the 1 µm tolerance.
    #[test]
    fn robot_powers_grow_the_arm() {
        let Machine::Robot(r) = irb1600() else {
            panic!("robot file")
        };
        let m = Machine::Robot(r.clone());
        let with_power = |p: [f64; 6]| {
            let mut row = robot_row([0.0; 6], Vector3::zeros());
            if let Pose::Robot(rp) = &mut row.pose {
                rp.p_w = p.map(Some);
            }
            predict(&m, &row, "t").unwrap()
        };
        let p_hot = [126.0, 112.0, 38.0, 0.0, 0.0, 0.0];
        let cold = with_power([0.0; 6]);
        let hot = with_power(p_hot);
        let g0 = r.thermal_growth_mm(&[0.0; 6]);
        let g1 = r.thermal_growth_mm(&p_hot);
        // DhGrowth rows are joints 1..6, columns [Δa, Δd].
        let da2 = g1[1][0] - g0[1][0];
        let da3 = g1[2][0] - g0[2][0];
        let dd4 = g1[3][1] - g0[3][1];
        assert!(da2.abs() > 1e-3, "the file has an a2 term");
        let moved = hot.attained_mm - cold.attained_mm;
        const GROWTH_TOL_MM: f64 = 1e-3;
        assert_abs_diff_eq!(
            moved,
            Vector3::new(da2 + dd4, 0.0, da3),
            epsilon = GROWTH_TOL_MM
        );
    }

    fn error_free_yaml() -> String {
        let mut yaml = String::from("kind: machine_tool\nname: t\naxes:\n");
        for (axis, side) in [("X", "workpiece"), ("Y", "workpiece"), ("Z", "tool")] {
            yaml.push_str(&format!(
                "  - name: {axis}\n    type: linear\n    side: {side}\n    travel_mm: [-500, 500]\n    rapid_mm_per_min: 20000\n"
            ));
        }
        yaml
    }

    fn tool_row(
        xyz: [f64; 3],
        force_n: Vector3<f64>,
        spindle_w: Option<f64>,
        px_w: Option<f64>,
    ) -> Observation {
        Observation {
            orientation: None,
            line: 0,
            id: "p".into(),
            t_s: Some(3600.0),
            measured_mm: Vector3::zeros(),
            force_n,
            moment_nm: Vector3::zeros(),
            ambient_c: None,
            pose: Pose::Tool(ToolPose {
                xyz_mm: Vector3::from(xyz),
                abc_deg: [None; 3],
                dir: [None; 6],
                tool_mm: Some(100.0),
                spindle_rpm: Some(8000.0),
                spindle_w,
                p_w: [px_w, None, None, None, None, None],
            }),
        }
    }

    /// Stiffness and steady-state thermal growth on an otherwise error-free
    /// three-axis machine (tool axis +Z, tip → spindle):
    /// - force (200, 0, −120) N against k_x+ = 20 and k_z− = 24 N/µm:
    ///   +10 µm in x, −5 µm in z (attained = programmed + F/k);
    /// - spindle 2000 W at 3 µm/kW: 6 µm growth, the tip moves 6 µm along −z;
    /// - X drive 500 W at 60 ppm/kW: 30 ppm of X = 400 mm = +12 µm in x.
    ///
    /// Together (22, 0, −11) µm; each alone as listed; `t_s` and
    /// `spindle_rpm` alone change nothing (a row without powers is cold).
    #[test]
    fn tool_force_and_thermal_steady_state() {
        let mut yaml = error_free_yaml();
        yaml.push_str(
            "stiffness:\n  k_n_per_um: { x_pos: 20.0, x_neg: 21.0, y_pos: 15.0, y_neg: 16.0, z_pos: 28.0, z_neg: 24.0 }\n\
             thermal:\n  spindle: { idle_w_per_rpm: 0.2, growth_um_per_kw: 3.0, time_constant_min: 25.0 }\n\
             \x20 axes:\n    X: { scale_ppm_per_kw: 60.0, time_constant_min: 40.0, friction_n: 300.0 }\n",
        );
        let m = Machine::from_yaml_str(&yaml, "t.yaml").expect("machine file");
        let f = Vector3::new(200.0, 0.0, -120.0);
        let dev = |row: Observation| predict(&m, &row, "t").unwrap().deviation_mm();
        let xyz = [400.0, 50.0, -30.0];
        assert_abs_diff_eq!(
            dev(tool_row(xyz, f, None, None)),
            Vector3::new(0.010, 0.0, -0.005),
            epsilon = POS_TOL_MM
        );
        assert_abs_diff_eq!(
            dev(tool_row(xyz, Vector3::zeros(), Some(2000.0), None)),
            Vector3::new(0.0, 0.0, -0.006),
            epsilon = POS_TOL_MM
        );
        assert_abs_diff_eq!(
            dev(tool_row(xyz, Vector3::zeros(), None, Some(500.0))),
            Vector3::new(0.012, 0.0, 0.0),
            epsilon = POS_TOL_MM
        );
        assert_abs_diff_eq!(
            dev(tool_row(xyz, f, Some(2000.0), Some(500.0))),
            Vector3::new(0.022, 0.0, -0.011),
            epsilon = POS_TOL_MM
        );
        assert_abs_diff_eq!(
            dev(tool_row(xyz, Vector3::zeros(), None, None)),
            Vector3::zeros(),
            epsilon = POS_TOL_MM
        );
        // The commanded point is the nominal tip, whatever the loads.
        let p = predict(&m, &tool_row(xyz, f, Some(2000.0), Some(500.0)), "t").unwrap();
        assert_abs_diff_eq!(
            p.commanded_mm,
            Vector3::new(400.0, 50.0, -30.0),
            epsilon = POS_TOL_MM
        );
    }

    /// An error-free machine tool attains its commanded position.
    #[test]
    fn error_free_tool_attains_command() {
        let m = Machine::from_yaml_str(&error_free_yaml(), "t.yaml").expect("machine file");
        let row = Observation {
            orientation: None,
            line: 0,
            id: "p".into(),
            t_s: None,
            measured_mm: Vector3::zeros(),
            force_n: Vector3::zeros(),
            moment_nm: Vector3::zeros(),
            ambient_c: None,
            pose: Pose::Tool(ToolPose {
                xyz_mm: Vector3::new(10.0, 20.0, 30.0),
                abc_deg: [None; 3],
                dir: [None; 6],
                tool_mm: Some(100.0),
                spindle_rpm: None,
                spindle_w: None,
                p_w: [None; 6],
            }),
        };
        let p = predict(&m, &row, "t").unwrap();
        assert_abs_diff_eq!(p.deviation_mm(), Vector3::zeros(), epsilon = POS_TOL_MM);
    }
}
