//! The library of candidate effects: named, parametric additions to the
//! current model, each with its sensitivity (∂ measured triple / ∂ parameter
//! for every observation row).
//!
//! Parameters are in display units (µm, µrad, µrad/(N·m), kg, µm/W, …) so
//! fitted values print without conversion. Sensitivities are in mm per
//! display unit. Effects the machine file can express are evaluated by
//! forward-predicting a modified copy of the machine (central or one-sided
//! differences; every such effect is linear or nearly linear in its
//! parameter); the others are analytic additions (a row covariate times the
//! derivative of the prediction with respect to a length or angle).

use nalgebra::{DMatrix, UnitQuaternion, Vector3};
use serde::Serialize;

use crate::calibrate::forward::{self, tool_length};
use crate::calibrate::observations::{MeasuredKind, Observation, Pose};
use crate::error::{Error, Result};
use crate::machine::Machine;
use crate::machine::robot::{DhField as RobotDh, Robot, RobotParam};
use crate::machine::tool::{AxisKind, LocationParam, MachineTool, ToolParam};
use crate::machine::yaml_write::{self, Edit};

/// Axis and error-direction letters in slot order.
pub const LETTERS: [char; 6] = ['X', 'Y', 'Z', 'A', 'B', 'C'];

/// Robot DH length/angle fields a candidate can change.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum DhField {
    /// Joint zero offset θ (µrad).
    Theta,
    /// Link length a (µm).
    A,
    /// Link offset d (µm).
    D,
    /// Link twist α (µrad).
    Alpha,
}

/// What a candidate changes (internal description of its mechanism).
#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    /// Robot: a DH parameter of joint `0..6` of the actual model.
    Dh(usize, DhField),
    /// Robot: compliance of joint `0..6` (µrad/(N·m)).
    Compliance(usize),
    /// Robot: TCP offset in the flange frame (µm, 3 parameters).
    Tcp,
    /// Robot: measurement-frame translation along base x/y/z (µm).
    BaseTrans(usize),
    /// Robot: measurement-frame rotation about base x/y/z (µrad).
    BaseRot(usize),
    /// Robot: payload mass error (kg) at the tool load's centre of gravity
    /// (a file without `tool_load` gets one at the TCP).
    Payload,
    /// Robot: thermal growth of a DH length with a joint's power (µm/W),
    /// Paper B linearised: Δp = g·P.
    Thermal {
        /// Joint of the DH length.
        joint: usize,
        /// `DhField::A` or `DhField::D`.
        field: DhField,
        /// Joint whose motor power drives the growth.
        power: usize,
    },
    /// Robot: backlash of a joint (µrad): the joint stops b/2 short of the
    /// side it came from, θ − dir·b/2 (reverse − forward = b, as the
    /// machine-tool reversal).
    RobotBacklash(usize),
    /// Machine tool: a location error key of an axis (or of the spindle,
    /// `axis = None`), in µrad or µm.
    Location {
        /// Axis name in the file (`None` = spindle).
        axis: Option<char>,
        /// The YAML key, e.g. `EC0Y_urad`.
        key: String,
    },
    /// Machine tool: a component error table term `p·u^power`, with
    /// `u = (q − mid)/half` over the axis travel (p = value at the + end).
    Component {
        /// Axis name.
        axis: char,
        /// The YAML key, e.g. `EXX_um`.
        key: String,
        /// 1 = linear, 2 = quadratic.
        power: i32,
    },
    /// Machine tool: backlash of an axis = offset of the reverse column of
    /// its own-direction table (µm or µrad).
    AxisBacklash {
        /// Axis name.
        axis: char,
        /// The own-direction key, e.g. `EXX_um`.
        key: String,
    },
    /// Machine tool: compliance of a linear axis slot 0..3 (µm/N) against
    /// the row force along it.
    AxisStiffness(usize),
    /// Machine tool: spindle growth along the tool with time (µm/h).
    SpindleTime,
    /// Machine tool: spindle growth along the tool with power (µm/kW).
    SpindlePower,
    /// Machine tool: tool length error (µm).
    ToolLength,
}

/// One candidate effect.
#[derive(Debug, Clone, Serialize)]
pub struct Effect {
    /// Short unique name, e.g. `joint2_compliance`.
    pub name: String,
    /// Plain-words description.
    pub description: String,
    /// Parameter names with their unit, e.g. `dc2 [µrad/(N·m)]`.
    pub params: Vec<String>,
    /// How `--write-model` can record it (`None`: it can).
    pub not_writable: Option<String>,
    /// Mechanism.
    #[serde(skip)]
    pub action: Action,
}

/// Families of the library, for `--list-effects` without a machine.
pub const FAMILIES: &[(&str, &str)] = &[
    (
        "robot",
        "jointN_compliance — compliance of joint N, µrad/(N·m)",
    ),
    ("robot", "jointN_zero — zero offset of joint N, µrad"),
    (
        "robot",
        "jointN_a / jointN_d / jointN_alpha — DH length, offset, twist error, µm or µrad",
    ),
    (
        "robot",
        "tcp_offset — tool-centre-point offset in the flange frame, 3 × µm",
    ),
    (
        "robot",
        "base_x/y/z, base_rx/ry/rz — measurement (base) frame translation µm / rotation µrad",
    ),
    ("robot", "payload_mass — payload mass error, kg"),
    (
        "robot",
        "thermal_jointN_a|d_pJ — Paper B growth of a DH length with joint J power, µm/W",
    ),
    (
        "robot",
        "jointN_backlash — backlash of joint N from dirN, µrad: the joint stops b/2 short of the side it came from (θ − dirN·b/2)",
    ),
    (
        "machine tool",
        "E??_lin / E??_quad — component error p·u or p·u², u = (q − mid)/half-travel, p at the + end (with the location errors: the 21 geometric errors)",
    ),
    (
        "machine tool",
        "E?0?_urad / _mm — location (squareness, rotary axis, spindle) errors",
    ),
    (
        "machine tool",
        "X_backlash … — reversal (backlash) per axis from dirX…",
    ),
    (
        "machine tool",
        "X_stiffness … — compliance per linear axis against the force column, µm/N",
    ),
    (
        "machine tool",
        "spindle_growth_time / spindle_growth_power — spindle thermal growth, µm/h, µm/kW",
    ),
    ("machine tool", "tool_length — tool length error, µm"),
];

const NOT_THERMAL_TIME: &str = "the thermal section is driven by power (rows at the steady state of spindle_w / pX_w); a growth with time alone has no key: measure the spindle power, or calibrate the time constant; not written";
const NOT_FRAME: &str = "observations are in the robot base frame: a frame offset is a registration error of the measurement set-up, not a machine parameter; not written";
/// Why a TCP offset found in a deviation file is not written.
pub const NOT_TCP_DEVIATION: &str = "in a deviation file the commanded point is the controller's, with the tool it was told (`flange_to_tool`): writing the real tool there would move the commanded point as well; measure the tool (TCP calibration) and update the tool data; not written";
const NOT_ROBOT_BACKLASH: &str = "the robot file has no joint backlash key; not written";
const NOT_TOOL_LENGTH: &str = "the tool table holds the length the controller compensates, so editing it changes nothing in the model: re-measure the tool (its offset) instead; not written";
const NOT_STIFFNESS: &str = "the file has no `stiffness:` section (a new one would need all six directions and load signs, which one compliance does not give); not written";

/// Builds the candidate library for a machine and the columns its rows carry.
pub fn library(machine: &Machine, rows: &[Observation]) -> Vec<Effect> {
    match machine {
        Machine::Robot(_) => robot_library(rows),
        Machine::Tool(t) => tool_library(t, rows),
    }
}

fn eff(name: String, description: String, params: Vec<String>, action: Action) -> Effect {
    Effect {
        name,
        description,
        params,
        not_writable: None,
        action,
    }
}

fn robot_library(rows: &[Observation]) -> Vec<Effect> {
    let has_power = |j: usize| {
        rows.iter().any(|r| match &r.pose {
            Pose::Robot(rp) => rp.p_w.get(j).copied().flatten().is_some(),
            Pose::Tool(_) => false,
        })
    };
    let has_dir = |j: usize| {
        rows.iter().any(|r| match &r.pose {
            Pose::Robot(rp) => rp.dir.get(j).copied().flatten().is_some(),
            Pose::Tool(_) => false,
        })
    };
    let mut out = Vec::new();
    for i in 0..6 {
        let n = i + 1;
        out.push(eff(
            format!("joint{n}_compliance"),
            format!("joint {n} is more compliant than the model (torsional compliance added)"),
            vec![format!("dc{n} [µrad/(N·m)]")],
            Action::Compliance(i),
        ));
    }
    for i in 0..6 {
        let n = i + 1;
        out.push(eff(
            format!("joint{n}_zero"),
            format!("zero offset of joint {n}"),
            vec![format!("dtheta{n} [µrad]")],
            Action::Dh(i, DhField::Theta),
        ));
    }
    for i in 0..6 {
        let n = i + 1;
        for (f, s, w, u) in [
            (DhField::A, "a", "length", "µm"),
            (DhField::D, "d", "offset", "µm"),
            (DhField::Alpha, "alpha", "twist", "µrad"),
        ] {
            out.push(eff(
                format!("joint{n}_{s}"),
                format!("DH {w} {s}{n} error"),
                vec![format!("d{s}{n} [{u}]")],
                Action::Dh(i, f),
            ));
        }
    }
    out.push(eff(
        "tcp_offset".into(),
        "tool-centre-point offset (flange frame)".into(),
        vec!["dx [µm]".into(), "dy [µm]".into(), "dz [µm]".into()],
        Action::Tcp,
    ));
    for (j, c) in ['x', 'y', 'z'].iter().enumerate() {
        let mut e = eff(
            format!("base_{c}"),
            format!("measurement frame shifted along base {c}"),
            vec![format!("t{c} [µm]")],
            Action::BaseTrans(j),
        );
        e.not_writable = Some(NOT_FRAME.into());
        out.push(e);
    }
    for (j, c) in ['x', 'y', 'z'].iter().enumerate() {
        let mut e = eff(
            format!("base_r{c}"),
            format!("measurement frame rotated about base {c}"),
            vec![format!("r{c} [µrad]")],
            Action::BaseRot(j),
        );
        e.not_writable = Some(NOT_FRAME.into());
        out.push(e);
    }
    out.push(eff(
        "payload_mass".into(),
        "payload mass differs from the tool load in the file".into(),
        vec!["dm [kg]".into()],
        Action::Payload,
    ));
    // Paper B couplings (a2 ← P1, P2; d4 ← P1, P2, P3; a3 ← P2, P3), written
    // generically: every a and d of joints 1..6 (every DH length a motor's
    // heat can grow, the base column's d1 and a1 included) with the power
    // of every joint whose power the rows carry.
    for i in 0usize..6 {
        for (f, s) in [(DhField::A, "a"), (DhField::D, "d")] {
            for p in 0usize..6 {
                if !has_power(p) {
                    continue;
                }
                let e = eff(
                    format!("thermal_joint{}_{s}_p{}", i + 1, p + 1),
                    format!(
                        "thermal growth of DH {s}{} with the power of joint {} (Paper B, linearised)",
                        i + 1,
                        p + 1
                    ),
                    vec![format!("g [µm/W]")],
                    Action::Thermal {
                        joint: i,
                        field: f,
                        power: p,
                    },
                );
                out.push(e);
            }
        }
    }
    for i in 0..6 {
        if has_dir(i) {
            let mut e = eff(
                format!("joint{}_backlash", i + 1),
                format!(
                    "backlash of joint {} (last-motion sign dir{})",
                    i + 1,
                    i + 1
                ),
                vec![format!("b{} [µrad]", i + 1)],
                Action::RobotBacklash(i),
            );
            e.not_writable = Some(NOT_ROBOT_BACKLASH.into());
            out.push(e);
        }
    }
    out
}

/// Location-error keys the machine file allows for an axis (machines/README.md).
fn location_keys(slot: usize) -> Vec<String> {
    let a = LETTERS.get(slot).copied().unwrap_or('X');
    let mut keys = Vec::new();
    if slot < 3 {
        for r in 0..3 {
            if r != slot {
                keys.push(format!("E{}0{a}_urad", LETTERS[r + 3]));
            }
        }
    } else {
        let own = slot - 3;
        keys.push(format!("E{a}0{a}_urad"));
        for r in 0..3 {
            if r != own {
                keys.push(format!("E{}0{a}_mm", LETTERS[r]));
                keys.push(format!("E{}0{a}_urad", LETTERS[r + 3]));
            }
        }
    }
    keys
}

fn tool_library(t: &crate::machine::tool::MachineTool, rows: &[Observation]) -> Vec<Effect> {
    let tool_rows = || {
        rows.iter().filter_map(|r| match &r.pose {
            Pose::Tool(tp) => Some((r, tp)),
            Pose::Robot(_) => None,
        })
    };
    let mut out = Vec::new();
    for ax in t.axes() {
        let a = LETTERS.get(ax.slot).copied().unwrap_or('X');
        for key in location_keys(ax.slot) {
            let kind = if key.starts_with(&format!("E{a}0")) {
                "zero-angle".to_string()
            } else if ax.slot < 3 {
                "squareness / orientation".to_string()
            } else {
                "location".to_string()
            };
            let unit = if key.ends_with("_mm") { "µm" } else { "µrad" };
            out.push(eff(
                key.trim_end_matches("_urad")
                    .trim_end_matches("_mm")
                    .to_string(),
                format!("{kind} error {key} of axis {a}"),
                vec![format!("{key} [{unit}]")],
                Action::Location { axis: Some(a), key },
            ));
        }
        for (d, dl) in LETTERS.iter().enumerate() {
            let key = format!("E{dl}{a}_{}", if d < 3 { "um" } else { "urad" });
            let unit = if d < 3 { "µm" } else { "µrad" };
            let what = match (d == ax.slot, d < 3) {
                (true, _) => "positioning",
                (false, true) => "straightness",
                (false, false) => "angular",
            };
            for power in [1, 2] {
                // A straightness error linear in position is a squareness
                // (location) error by definition (ISO 230-1 reference line).
                if power == 1 && d < 3 && d != ax.slot && ax.kind == AxisKind::Linear {
                    continue;
                }
                let shape = if power == 1 { "linear" } else { "quadratic" };
                let stem = key.trim_end_matches("_urad").trim_end_matches("_um");
                out.push(eff(
                    format!("{stem}_{}", if power == 1 { "lin" } else { "quad" }),
                    format!("{what} error {stem} of axis {a}, {shape} in position"),
                    vec![format!("{stem} at + end of travel [{unit}]")],
                    Action::Component {
                        axis: a,
                        key: key.clone(),
                        power,
                    },
                ));
            }
        }
        let own = format!(
            "E{a}{a}_{}",
            if ax.kind == AxisKind::Linear {
                "um"
            } else {
                "urad"
            }
        );
        let has_dir = tool_rows().any(|(_, tp)| tp.dir.get(ax.slot).copied().flatten().is_some());
        if has_dir {
            out.push(eff(
                format!("{a}_backlash"),
                format!("backlash (reversal error) of axis {a}"),
                vec![format!(
                    "b{a} [{}]",
                    if ax.kind == AxisKind::Linear {
                        "µm"
                    } else {
                        "µrad"
                    }
                )],
                Action::AxisBacklash { axis: a, key: own },
            ));
        }
        if ax.slot < 3 && tool_rows().any(|(r, _)| r.force_n[ax.slot] != 0.0) {
            let mut e = eff(
                format!("{a}_stiffness"),
                format!("axis {a} yields under the force along it"),
                vec![format!("c{a} [µm/N]")],
                Action::AxisStiffness(ax.slot),
            );
            if t.stiffness().is_none() {
                e.not_writable = Some(NOT_STIFFNESS.into());
            }
            out.push(e);
        }
    }
    for key in ["EX0S_mm", "EY0S_mm", "EA0S_urad", "EB0S_urad"] {
        let unit = if key.ends_with("_mm") { "µm" } else { "µrad" };
        out.push(eff(
            key.trim_end_matches("_urad")
                .trim_end_matches("_mm")
                .to_string(),
            format!("spindle location error {key}"),
            vec![format!("{key} [{unit}]")],
            Action::Location {
                axis: None,
                key: key.to_string(),
            },
        ));
    }
    if tool_rows().any(|(r, _)| r.t_s.is_some()) {
        let mut e = eff(
            "spindle_growth_time".into(),
            "spindle thermal growth along the tool with time (linearised)".into(),
            vec!["g [µm/h]".into()],
            Action::SpindleTime,
        );
        e.not_writable = Some(NOT_THERMAL_TIME.into());
        out.push(e);
    }
    if tool_rows().any(|(_, tp)| tp.spindle_w.is_some()) {
        out.push(eff(
            "spindle_growth_power".into(),
            "spindle thermal growth along the tool with spindle power (steady state)".into(),
            vec!["g [µm/kW]".into()],
            Action::SpindlePower,
        ));
    }
    let mut e = eff(
        "tool_length".into(),
        "tool length error".into(),
        vec!["dL [µm]".into()],
        Action::ToolLength,
    );
    e.not_writable = Some(NOT_TOOL_LENGTH.into());
    out.push(e);
    out
}

/// What sensitivities are computed against.
pub struct Context<'a> {
    /// The current model.
    pub machine: &'a Machine,
    /// Its machine file's text (machine-tool tables are varied through it).
    pub text: &'a str,
    /// Position or deviation files.
    pub kind: MeasuredKind,
    /// Name of the observation file for errors.
    pub file: &'a str,
}

/// Step of the numeric differences, display units (µm, µrad, µrad/(N·m), kg).
const STEP: f64 = 10.0;
/// Compliance step, µrad/(N·m).
const COMPLIANCE_STEP: f64 = 0.1;
/// Payload step, kg.
const MASS_STEP: f64 = 0.5;

/// Slots of a row in a pose sensitivity ([`pose_sensitivity`]): the
/// measured triple (mm per display unit), then the rotation vector of the
/// measured frame's orientation (rad per display unit).
pub const SLOTS: usize = 6;

/// The measured triple and the orientation of the measured frame (robots)
/// predicted by `m` for every row.
type Predictions = Vec<(Vector3<f64>, Option<UnitQuaternion<f64>>)>;

fn predict_all(m: &Machine, rows: &[Observation], ctx: &Context) -> Result<Predictions> {
    rows.iter()
        .map(|r| forward::predict(m, r, ctx.file).map(|p| (p.measured(ctx.kind), p.attained_rot)))
        .collect()
}

/// Simulated measured triples of the current model, mm.
pub fn simulate(ctx: &Context, rows: &[Observation]) -> Result<Vec<Vector3<f64>>> {
    Ok(predict_all(ctx.machine, rows, ctx)?
        .into_iter()
        .map(|p| p.0)
        .collect())
}

/// Central difference of the predictions of two machine variants.
fn diff_column(
    plus: &Machine,
    minus: &Machine,
    h2: f64,
    rows: &[Observation],
    ctx: &Context,
    out: &mut DMatrix<f64>,
    col: usize,
) -> Result<()> {
    let a = predict_all(plus, rows, ctx)?;
    let b = predict_all(minus, rows, ctx)?;
    for (i, (pa, pb)) in a.iter().zip(&b).enumerate() {
        let turn = match (pa.1, pb.1) {
            (Some(qa), Some(qb)) => (qa * qb.inverse()).scaled_axis(),
            _ => Vector3::zeros(),
        };
        for c in 0..3 {
            out[(SLOTS * i + c, col)] = (pa.0[c] - pb.0[c]) / h2;
            out[(SLOTS * i + 3 + c, col)] = turn[c] / h2;
        }
    }
    Ok(())
}

/// Robot with `add` (in the unit of the parameter's key) added to the
/// file's value of `p`, through [`Robot::with_params`].
fn robot_added(r: &Robot, p: RobotParam, add: f64) -> Result<Robot> {
    let old = r
        .param_value(p)
        .ok_or_else(|| Error::Internal(format!("validated robot file without {}", p.path())))?;
    r.with_params(&[(p, old + add)])
}

/// The robot parameter of a candidate's DH field, and `v` display units
/// (µm, µrad) in the unit of its key (mm, degrees).
pub fn dh_param(joint: usize, f: DhField, v: f64) -> (RobotParam, f64) {
    let (field, add) = match f {
        DhField::Theta => (RobotDh::ThetaOffset, (v * 1e-6).to_degrees()),
        DhField::Alpha => (RobotDh::Alpha, (v * 1e-6).to_degrees()),
        DhField::A => (RobotDh::A, v * 1e-3),
        DhField::D => (RobotDh::D, v * 1e-3),
    };
    (RobotParam::Dh { joint, field }, add)
}

fn robot_dh(r: &Robot, joint: usize, f: DhField, v: f64) -> Result<Machine> {
    let (p, add) = dh_param(joint, f, v);
    robot_added(r, p, add).map(Machine::Robot)
}

/// Robot with joint `joint`'s compliance raised by `dc` µrad/(N·m).
pub fn robot_compliance(r: &Robot, joint: usize, dc: f64) -> Result<Robot> {
    let p = RobotParam::JointStiffness { joint };
    let k = r
        .param_value(p)
        .ok_or_else(|| Error::Internal(format!("validated robot file without {}", p.path())))?;
    // c [rad/(N·m)] = 1/k; dc µrad/(N·m) = dc·1e-6 rad/(N·m).
    r.with_params(&[(p, 1.0 / (1.0 / k + dc * 1e-6))])
}

/// Robot with the TCP moved by `d` µm in the flange frame.
pub fn robot_tcp(r: &Robot, d: Vector3<f64>) -> Result<Robot> {
    let mut edits = Vec::with_capacity(3);
    for axis in 0..3 {
        let p = RobotParam::ToolOffset { axis };
        let old = r.param_value(p).unwrap_or(0.0);
        edits.push((p, old + d[axis] * 1e-3));
    }
    r.with_params(&edits)
}

/// Robot with the payload mass changed by `dm` kg.
pub fn robot_payload(r: &Robot, dm: f64) -> Result<Robot> {
    robot_added(r, RobotParam::PayloadMass, dm)
}

fn robot_row_value(
    row: &Observation,
    f: impl Fn(&crate::calibrate::observations::RobotPose) -> Option<f64>,
) -> f64 {
    match &row.pose {
        Pose::Robot(rp) => f(rp).unwrap_or(0.0),
        Pose::Tool(_) => 0.0,
    }
}

/// The column of a robot joint's backlash `b`: the joint stops b/2 short
/// of the side it came from (the machine-tool reversal `reverse = forward
/// + b`): moving up (dir +1) it lags by −b/2, moving down by +b/2.
fn robot_backlash_column(
    r: &Robot,
    j: usize,
    rows: &[Observation],
    ctx: &Context,
    s: &mut DMatrix<f64>,
) -> Result<()> {
    let t = DhField::Theta;
    diff_column(
        &robot_dh(r, j, t, STEP)?,
        &robot_dh(r, j, t, -STEP)?,
        2.0 * STEP,
        rows,
        ctx,
        s,
        0,
    )?;
    for (i, row) in rows.iter().enumerate() {
        let d = robot_row_value(row, |rp| rp.dir.get(j).copied().flatten().map(f64::from));
        let half = if d > 0.0 {
            -0.5
        } else if d < 0.0 {
            0.5
        } else {
            0.0
        };
        for c in 0..SLOTS {
            s[(SLOTS * i + c, 0)] *= half;
        }
    }
    Ok(())
}

/// The column of a tool (or spindle) longer than the controller knows:
/// ΔL puts the tip ΔL further along −(tool direction), ∂tip/∂ΔL = −dir,
/// 1e-3 mm per µm; scaled by the hours (spindle growth with time) or the
/// kW (with power) of each row.
fn tool_length_column(
    t: &crate::machine::tool::MachineTool,
    action: &Action,
    rows: &[Observation],
    s: &mut DMatrix<f64>,
) {
    for (i, row) in rows.iter().enumerate() {
        let Pose::Tool(tp) = &row.pose else { continue };
        let cmd = tp.axes();
        let len = tool_length(t, tp);
        let dp = -t.geometric(&cmd, &tp.dirs(), len).dir * 1e-3;
        let scale = match action {
            Action::SpindleTime => row.t_s.unwrap_or(0.0) / 3600.0,
            Action::SpindlePower => tp.spindle_w.unwrap_or(0.0) / 1000.0,
            _ => 1.0,
        };
        for c in 0..3 {
            s[(SLOTS * i + c, 0)] = dp[c] * scale;
        }
    }
}

/// Sensitivity matrix of the measured triples (3·rows × parameters), mm per
/// display unit: the position slots of [`pose_sensitivity`].
pub fn sensitivity(effect: &Effect, ctx: &Context, rows: &[Observation]) -> Result<DMatrix<f64>> {
    let s = pose_sensitivity(effect, ctx, rows)?;
    let idx: Vec<usize> = (0..rows.len())
        .flat_map(|i| [SLOTS * i, SLOTS * i + 1, SLOTS * i + 2])
        .collect();
    Ok(s.select_rows(idx.iter()))
}

/// Sensitivity matrix of the measured triples and of the orientation of the
/// measured frame ([`SLOTS`]·rows × parameters): per row the triple (mm per
/// display unit), then the rotation vector of `varied · current⁻¹` (rad per
/// display unit; zero for a machine whose model gives no orientation).
pub fn pose_sensitivity(
    effect: &Effect,
    ctx: &Context,
    rows: &[Observation],
) -> Result<DMatrix<f64>> {
    let n = rows.len();
    let k = effect.params.len();
    let mut s = DMatrix::zeros(SLOTS * n, k);
    match (&effect.action, ctx.machine) {
        (Action::Dh(j, f), Machine::Robot(r)) => {
            diff_column(
                &robot_dh(r, *j, *f, STEP)?,
                &robot_dh(r, *j, *f, -STEP)?,
                2.0 * STEP,
                rows,
                ctx,
                &mut s,
                0,
            )?;
        }
        (Action::Compliance(j), Machine::Robot(r)) => {
            let plus = Machine::Robot(robot_compliance(r, *j, COMPLIANCE_STEP)?);
            diff_column(&plus, ctx.machine, COMPLIANCE_STEP, rows, ctx, &mut s, 0)?;
        }
        (Action::Tcp, Machine::Robot(r)) => {
            // The real tool differs from the one the controller was told:
            // only the attained point moves; the commanded point (the
            // nominal model with the controller's tool) stays, so the column
            // is the same for positions and deviations.
            let attained = Context {
                kind: MeasuredKind::Position,
                ..*ctx
            };
            for c in 0..3 {
                let mut d = Vector3::zeros();
                d[c] = STEP;
                let p = Machine::Robot(robot_tcp(r, d)?);
                let m = Machine::Robot(robot_tcp(r, -d)?);
                diff_column(&p, &m, 2.0 * STEP, rows, &attained, &mut s, c)?;
            }
        }
        (Action::Payload, Machine::Robot(r)) => {
            // The deflection is linear in the mass: a file without (or with
            // a light) tool load is differenced forward from its own mass,
            // the load added at the TCP as `with_params` adds it.
            let p = Machine::Robot(robot_payload(r, MASS_STEP)?);
            let light = r.param_value(RobotParam::PayloadMass).unwrap_or(0.0) < MASS_STEP;
            if light {
                diff_column(&p, ctx.machine, MASS_STEP, rows, ctx, &mut s, 0)?;
            } else {
                let m = Machine::Robot(robot_payload(r, -MASS_STEP)?);
                diff_column(&p, &m, 2.0 * MASS_STEP, rows, ctx, &mut s, 0)?;
            }
        }
        (Action::BaseTrans(c), Machine::Robot(_)) => {
            for i in 0..n {
                s[(SLOTS * i + c, 0)] = 1e-3;
            }
        }
        (Action::BaseRot(c), Machine::Robot(_)) => {
            let att: Vec<Vector3<f64>> = rows
                .iter()
                .map(|r| forward::predict(ctx.machine, r, ctx.file).map(|p| p.attained_mm))
                .collect::<Result<_>>()?;
            let mut axis = Vector3::zeros();
            axis[*c] = 1e-6;
            for (i, p) in att.iter().enumerate() {
                let v = axis.cross(p);
                for r in 0..3 {
                    s[(SLOTS * i + r, 0)] = v[r];
                    // The measured frame turns with the measurement frame.
                    s[(SLOTS * i + 3 + r, 0)] = axis[r];
                }
            }
        }
        (
            Action::Thermal {
                joint,
                field,
                power,
            },
            Machine::Robot(r),
        ) => {
            diff_column(
                &robot_dh(r, *joint, *field, STEP)?,
                &robot_dh(r, *joint, *field, -STEP)?,
                2.0 * STEP,
                rows,
                ctx,
                &mut s,
                0,
            )?;
            for (i, row) in rows.iter().enumerate() {
                let p = robot_row_value(row, |rp| rp.p_w.get(*power).copied().flatten());
                for c in 0..SLOTS {
                    s[(SLOTS * i + c, 0)] *= p;
                }
            }
        }
        (Action::RobotBacklash(j), Machine::Robot(r)) => {
            robot_backlash_column(r, *j, rows, ctx, &mut s)?;
        }
        (
            Action::Location { .. } | Action::Component { .. } | Action::AxisBacklash { .. },
            Machine::Tool(_),
        ) => {
            let plus = tool_variant(ctx.text, &effect.action, STEP, ctx.machine)?;
            diff_column(&plus, ctx.machine, STEP, rows, ctx, &mut s, 0)?;
        }
        (Action::AxisStiffness(slot), Machine::Tool(_)) => {
            for (i, row) in rows.iter().enumerate() {
                s[(SLOTS * i + slot, 0)] = row.force_n[*slot] * 1e-3;
            }
        }
        (Action::SpindleTime | Action::SpindlePower | Action::ToolLength, Machine::Tool(t)) => {
            tool_length_column(t, &effect.action, rows, &mut s);
        }
        _ => {
            // The library offers each machine kind its own effects.
            return Err(Error::Internal(format!(
                "effect `{}` does not apply to this kind of machine",
                effect.name
            )));
        }
    }
    Ok(s)
}

// ---------------------------------------------------------------------------
// Machine-tool effects as edits of the file's values
// ---------------------------------------------------------------------------

fn interp(pos: &[f64], val: &[f64], q: f64) -> f64 {
    let (Some(&first), Some(&last)) = (pos.first(), pos.last()) else {
        return 0.0;
    };
    if q <= first {
        return val.first().copied().unwrap_or(0.0);
    }
    if q >= last {
        return val.last().copied().unwrap_or(0.0);
    }
    for w in 0..pos.len().saturating_sub(1) {
        let (p0, p1) = (pos[w], pos[w + 1]);
        if q >= p0 && q <= p1 {
            let (v0, v1) = (
                val.get(w).copied().unwrap_or(0.0),
                val.get(w + 1).copied().unwrap_or(0.0),
            );
            return if p1 > p0 {
                v0 + (q - p0) / (p1 - p0) * (v1 - v0)
            } else {
                v0
            };
        }
    }
    0.0
}

/// Number of table positions a new component table gets over the travel.
const GRID: usize = 21;

/// Distance under which two table positions are one, mm or degrees.
const SAME_POSITION: f64 = 1e-9;

/// The component table `error` of the axis in `slot` with
/// `f(q) = (forward add, reverse add)` added, its positions merged with a
/// grid over the travel: the edit that writes it.
fn table_edit(
    t: &MachineTool,
    slot: usize,
    error: usize,
    f: impl Fn(f64) -> (f64, f64),
) -> Result<Edit> {
    let ax = t.axis(slot).ok_or_else(|| {
        Error::Internal(format!(
            "effect of axis `{}`, which the machine file does not have",
            LETTERS.get(slot).copied().unwrap_or('?')
        ))
    })?;
    let (lo, hi) = ax.travel;
    let [old_pos, old_f, old_r] =
        t.component_table(slot, error)
            .unwrap_or([Vec::new(), Vec::new(), Vec::new()]);
    let mut pos: Vec<f64> = (0..GRID)
        .map(|i| lo + (hi - lo) * i as f64 / (GRID - 1) as f64)
        .chain(old_pos.iter().copied())
        .collect();
    pos.sort_by(f64::total_cmp);
    pos.dedup_by(|a, b| (*a - *b).abs() < SAME_POSITION);
    let mut fw = Vec::with_capacity(pos.len());
    let mut rv = Vec::with_capacity(pos.len());
    for &q in &pos {
        let (df, dr) = f(q);
        fw.push(round9(interp(&old_pos, &old_f, q) + df));
        rv.push(round9(interp(&old_pos, &old_r, q) + dr));
    }
    Ok(Edit::ComponentTable {
        axis: slot,
        error,
        positions: pos.iter().map(|q| round9(*q)).collect(),
        forward: fw,
        reverse: rv,
    })
}

/// Slot of an axis letter, error direction of a table key (`EXX_um` → 0).
pub(super) fn slot_of(c: char) -> Result<usize> {
    LETTERS
        .iter()
        .position(|l| *l == c)
        .ok_or_else(|| Error::Internal(format!("no axis or direction `{c}`")))
}

/// The parameter of a location-error key (`EC0Y_urad`, `EX0B_mm`,
/// `EB0B_urad`) of the axis `axis` (`None`: the spindle).
pub(super) fn location_param(axis: Option<char>, key: &str) -> Result<ToolParam> {
    let r = key
        .chars()
        .nth(1)
        .ok_or_else(|| Error::Internal(format!("location key `{key}`")))?;
    let r = slot_of(r)?;
    let error = match axis {
        Some(a) if slot_of(a)? == r => LocationParam::Zero,
        _ if key.ends_with("_mm") => LocationParam::Offset(r),
        _ => LocationParam::Angle(r.saturating_sub(3)),
    };
    Ok(match axis {
        Some(a) => ToolParam::Location {
            axis: slot_of(a)?,
            error,
        },
        None => ToolParam::SpindleLocation { error },
    })
}

/// The stiffness values of direction `slot` (both load signs) with the
/// compliance `c` µm/N added: `k' = 1/(1/k + c)` at every grid node.
fn stiffness_edits(t: &MachineTool, slot: usize, c: f64) -> Result<Vec<Edit>> {
    let mut out = Vec::new();
    for positive in [true, false] {
        let params = t.stiffness_params(slot, positive);
        if params.is_empty() {
            // Without the section the effect is marked not writable.
            return Err(Error::Internal(
                "stiffness effect written to a file without `stiffness.k_n_per_um`".into(),
            ));
        }
        for p in params {
            let k = t
                .param_value(p)
                .ok_or_else(|| Error::Internal(format!("validated file without {}", p.path())))?;
            let new = 1.0 / (1.0 / k + c);
            if !(new.is_finite() && new > 0.0) {
                return Err(Error::Data(format!(
                    "the fitted compliance {c} µm/N makes the stiffness {k} N/µm non-positive: \
                     the data ask for a stiffer axis than any the file can hold"
                )));
            }
            out.push(Edit::Tool(p, round9(new)));
        }
    }
    Ok(out)
}

/// Rounds to 9 significant decimals so written files stay readable.
pub fn round9(x: f64) -> f64 {
    (x * 1e9).round() / 1e9
}

/// The edits of the machine-tool file that add `value` (display units) of
/// a machine-file-expressible effect to the file's values.
pub fn tool_edits(action: &Action, value: f64, t: &MachineTool) -> Result<Vec<Edit>> {
    match action {
        Action::Location { axis, key } => {
            let p = location_param(*axis, key)?;
            let add = if key.ends_with("_mm") {
                value * 1e-3
            } else {
                value
            };
            let old = t.param_value(p).unwrap_or(0.0);
            Ok(vec![Edit::Tool(p, round9(old + add))])
        }
        Action::Component { axis, key, power } => {
            let slot = slot_of(*axis)?;
            let (lo, hi) = t.axis(slot).map_or((0.0, 0.0), |a| a.travel);
            let mid = 0.5 * (lo + hi);
            let half = (0.5 * (hi - lo)).max(SAME_POSITION);
            let error = slot_of(key.chars().nth(1).unwrap_or('?'))?;
            let e = table_edit(t, slot, error, |q| {
                let v = value * ((q - mid) / half).powi(*power);
                (v, v)
            })?;
            Ok(vec![e])
        }
        Action::AxisBacklash { axis, key } => {
            let slot = slot_of(*axis)?;
            let error = slot_of(key.chars().nth(1).unwrap_or('?'))?;
            Ok(vec![table_edit(t, slot, error, |_| (0.0, value))?])
        }
        Action::AxisStiffness(slot) => {
            if *slot >= 3 {
                return Err(Error::Internal("stiffness effect of a rotary axis".into()));
            }
            stiffness_edits(t, *slot, value)
        }
        _ => Err(Error::Internal(
            "this effect is not expressed through the machine-tool file".into(),
        )),
    }
}

/// A machine-tool variant with one effect's parameter set to `value`: a
/// location error through [`MachineTool::with_params`]; a component table,
/// whose positions change, through the file written with it
/// ([`yaml_write`]) and read back.
pub fn tool_variant(text: &str, action: &Action, value: f64, m: &Machine) -> Result<Machine> {
    let Machine::Tool(t) = m else {
        return Err(Error::Internal("a machine-tool variant of a robot".into()));
    };
    let edits = tool_edits(action, value, t)?;
    let params: Option<Vec<(ToolParam, f64)>> = edits
        .iter()
        .map(|e| match e {
            Edit::Tool(p, v) => Some((*p, *v)),
            _ => None,
        })
        .collect();
    match params {
        Some(p) => Ok(Machine::Tool(t.with_params(&p)?)),
        None => {
            let written =
                yaml_write::apply(text, "(diagnose variant)", "postproc diagnose", &edits)?;
            Machine::from_yaml_str(&written, "(diagnose variant)")
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calibrate::observations::{RobotPose, ToolPose};
    use crate::machine::robot::Model;
    use approx::assert_abs_diff_eq;
    use nalgebra::Vector6;

    /// Sensitivity tolerance for exact (table/linear) effects, mm per unit.
    const EXACT_TOL: f64 = 1e-9;
    /// Tolerance where the model's own small angles (≤ 100 µrad) enter, mm per unit.
    const SMALL_ANGLE_TOL: f64 = 2e-7;
    /// Relative tolerance of a first-order (small-deflection) comparison.
    const FIRST_ORDER_REL_TOL: f64 = 1e-2;

    fn load(rel: &str) -> (Machine, String) {
        let path = format!("{}/{rel}", env!("CARGO_MANIFEST_DIR"));
        let text = std::fs::read_to_string(&path).expect("machine file");
        let m = Machine::from_yaml_str(&text, &path).expect("valid");
        (m, text)
    }

    fn robot_row(q_deg: [f64; 6], f: Vector3<f64>, dir: i8) -> Observation {
        Observation {
            orientation: None,
            line: 0,
            id: "r".into(),
            t_s: None,
            measured_mm: Vector3::zeros(),
            force_n: f,
            moment_nm: Vector3::zeros(),
            ambient_c: None,
            pose: Pose::Robot(RobotPose {
                q_deg,
                mp_mm: None,
                wp_mm: None,
                p_w: [Some(100.0); 6],
                dir: [Some(dir); 6],
            }),
        }
    }

    fn tool_row(xyz: [f64; 3], dir: i8, t_s: f64) -> Observation {
        Observation {
            orientation: None,
            line: 0,
            id: "t".into(),
            t_s: Some(t_s),
            measured_mm: Vector3::zeros(),
            force_n: Vector3::new(100.0, 0.0, 0.0),
            moment_nm: Vector3::zeros(),
            ambient_c: None,
            pose: Pose::Tool(ToolPose {
                xyz_mm: Vector3::from(xyz),
                abc_deg: [None; 3],
                dir: [Some(dir), Some(dir), Some(dir), None, None, None],
                tool_mm: None,
                spindle_rpm: None,
                spindle_w: Some(2000.0),
                p_w: [None; 6],
            }),
        }
    }

    fn find<'a>(lib: &'a [Effect], name: &str) -> &'a Effect {
        lib.iter()
            .find(|e| e.name == name)
            .expect("effect in library")
    }

    /// Compliance column = J_MP[:, j] · τ_j · 1e-9 (mm per µrad/(N·m)):
    /// the joint yields by Δθ_j = dc·τ_j; the statics module's linear
    /// point deflection with a torque vector e_j·k_j·τ_j·1e-9 gives exactly
    /// J_MP e_j τ_j 1e-9. The deflected-FK difference agrees to first order
    /// (≈0.1 % from the ≈1 mrad deflection already present).
    #[test]
    fn robot_compliance_column_matches_statics() {
        let (m, v) = load("machines/abb-irb1600.yaml");
        let Machine::Robot(r) = &m else {
            panic!("robot")
        };
        let row = robot_row(
            [10.0, 20.0, -15.0, 30.0, 40.0, 50.0],
            Vector3::new(0.0, 0.0, -200.0),
            1,
        );
        let ctx = Context {
            machine: &m,
            text: &v,
            kind: MeasuredKind::Position,
            file: "t",
        };
        let lib = library(&m, std::slice::from_ref(&row));
        for j in 0..6 {
            let s = sensitivity(
                find(&lib, &format!("joint{}_compliance", j + 1)),
                &ctx,
                std::slice::from_ref(&row),
            )
            .unwrap();
            let Pose::Robot(rp) = &row.pose else { panic!() };
            let q = forward::joints_rad(rp);
            let tcp = r.flange_to_tool().translation.vector;
            let tau = r.gravity_torques(Model::Actual, &q)
                + r.wrench_torques(Model::Actual, &q, &tcp, &forward::row_wrench(&row));
            let k = r.k_nm_per_rad()[j] * 1000.0;
            let mut t = Vector6::zeros();
            t[j] = k * tau[j] * 1e-9;
            let want = r.point_deflection(Model::Actual, &q, &tcp, &t);
            let tol = FIRST_ORDER_REL_TOL * want.fixed_rows::<3>(0).norm() + EXACT_TOL;
            for c in 0..3 {
                assert_abs_diff_eq!(s[(c, 0)], want[c], epsilon = tol);
            }
        }
    }

    /// Rotation of the frame about z by 1 µrad moves p by (−p_y, p_x, 0)·1e-6;
    /// a translation of 1 µm along x moves it by (1e-3, 0, 0) mm.
    #[test]
    fn robot_frame_columns_by_hand() {
        let (m, v) = load("machines/abb-irb1600.yaml");
        let row = robot_row([30.0, 10.0, 0.0, 0.0, 20.0, 0.0], Vector3::zeros(), 1);
        let rows = std::slice::from_ref(&row);
        let ctx = Context {
            machine: &m,
            text: &v,
            kind: MeasuredKind::Position,
            file: "t",
        };
        let lib = library(&m, rows);
        let p = forward::predict(&m, &row, "t").unwrap().attained_mm;
        let s = sensitivity(find(&lib, "base_rz"), &ctx, rows).unwrap();
        assert_abs_diff_eq!(s[(0, 0)], -p.y * 1e-6, epsilon = EXACT_TOL);
        assert_abs_diff_eq!(s[(1, 0)], p.x * 1e-6, epsilon = EXACT_TOL);
        assert_abs_diff_eq!(s[(2, 0)], 0.0, epsilon = EXACT_TOL);
        let s = sensitivity(find(&lib, "base_x"), &ctx, rows).unwrap();
        assert_abs_diff_eq!(s[(0, 0)], 1e-3, epsilon = EXACT_TOL);
    }

    /// The joint-1 zero offset rotates the arm about the base z axis (the
    /// joint-1 axis of the modified-DH IRB 1600 is base z through the
    /// origin): its column equals the base_rz column to first order.
    #[test]
    fn joint1_zero_equals_base_rz() {
        let (m, v) = load("machines/abb-irb1600.yaml");
        let row = robot_row([30.0, 10.0, 5.0, 20.0, 20.0, 10.0], Vector3::zeros(), 1);
        let rows = std::slice::from_ref(&row);
        let ctx = Context {
            machine: &m,
            text: &v,
            kind: MeasuredKind::Position,
            file: "t",
        };
        let lib = library(&m, rows);
        let a = sensitivity(find(&lib, "joint1_zero"), &ctx, rows).unwrap();
        let b = sensitivity(find(&lib, "base_rz"), &ctx, rows).unwrap();
        for c in 0..3 {
            assert_abs_diff_eq!(a[(c, 0)], b[(c, 0)], epsilon = EXACT_TOL);
        }
    }

    /// Machine-tool columns by hand (machines/README.md sign conventions):
    /// - X backlash (reverse column of EXX + b): (1e-3, 0, 0) mm/µm for a
    ///   row moving in −x, zero for +x (X is first in the chain, untilted);
    /// - squareness EC0Y: x error −ε·y → −y·1e-6 mm/µrad;
    /// - EXX quadratic: p·u², u = (x − 500)/500: at x = 750, 0.25e-3 mm/µm;
    /// - tool length: the tip moves along −z (tool direction) 1e-3 mm/µm;
    ///   spindle growth with time = that × t/3600, with power × P/1000;
    /// - X stiffness: F_x · 1e-3 mm per µm/N.
    #[test]
    fn tool_columns_by_hand() {
        let (m, v) = load("machines/afm-r1000.yaml");
        let rows = [
            tool_row([750.0, 300.0, 200.0], -1, 7200.0),
            tool_row([750.0, 300.0, 200.0], 1, 7200.0),
        ];
        let ctx = Context {
            machine: &m,
            text: &v,
            kind: MeasuredKind::Position,
            file: "t",
        };
        let lib = library(&m, &rows);
        let s = sensitivity(find(&lib, "X_backlash"), &ctx, &rows).unwrap();
        assert_abs_diff_eq!(s[(0, 0)], 1e-3, epsilon = EXACT_TOL);
        assert_abs_diff_eq!(s[(1, 0)], 0.0, epsilon = EXACT_TOL);
        assert_abs_diff_eq!(s[(3, 0)], 0.0, epsilon = EXACT_TOL);
        let s = sensitivity(find(&lib, "EC0Y"), &ctx, &rows).unwrap();
        assert_abs_diff_eq!(s[(0, 0)], -300.0e-6, epsilon = SMALL_ANGLE_TOL);
        let s = sensitivity(find(&lib, "EXX_quad"), &ctx, &rows).unwrap();
        assert_abs_diff_eq!(s[(0, 0)], 0.25e-3, epsilon = EXACT_TOL);
        let s = sensitivity(find(&lib, "tool_length"), &ctx, &rows).unwrap();
        assert_abs_diff_eq!(s[(2, 0)], -1e-3, epsilon = SMALL_ANGLE_TOL);
        let st = sensitivity(find(&lib, "spindle_growth_time"), &ctx, &rows).unwrap();
        assert_abs_diff_eq!(st[(2, 0)], 2.0 * s[(2, 0)], epsilon = EXACT_TOL);
        let sp = sensitivity(find(&lib, "spindle_growth_power"), &ctx, &rows).unwrap();
        assert_abs_diff_eq!(sp[(2, 0)], 2.0 * s[(2, 0)], epsilon = EXACT_TOL);
        let sk = sensitivity(find(&lib, "X_stiffness"), &ctx, &rows).unwrap();
        assert_abs_diff_eq!(sk[(0, 0)], 0.1, epsilon = EXACT_TOL);
    }

    /// Robot backlash by the machine-tool convention: a joint moving up
    /// (dir +1) stops b/2 short, θ − b/2; moving down θ + b/2. Its column
    /// is −½ (dir +1) or +½ (dir −1) times the joint-zero column.
    #[test]
    fn robot_backlash_stops_short_of_the_side_it_came_from() {
        let (m, v) = load("machines/abb-irb1600.yaml");
        let rows = [
            robot_row([10.0, 20.0, -15.0, 30.0, 40.0, 50.0], Vector3::zeros(), 1),
            robot_row([10.0, 20.0, -15.0, 30.0, 40.0, 50.0], Vector3::zeros(), -1),
        ];
        let ctx = Context {
            machine: &m,
            text: &v,
            kind: MeasuredKind::Position,
            file: "t",
        };
        let lib = library(&m, &rows);
        for j in 1..=6 {
            let b = sensitivity(find(&lib, &format!("joint{j}_backlash")), &ctx, &rows).unwrap();
            let z = sensitivity(find(&lib, &format!("joint{j}_zero")), &ctx, &rows).unwrap();
            for c in 0..3 {
                assert_abs_diff_eq!(b[(c, 0)], -0.5 * z[(c, 0)], epsilon = EXACT_TOL);
                assert_abs_diff_eq!(b[(3 + c, 0)], 0.5 * z[(3 + c, 0)], epsilon = EXACT_TOL);
            }
        }
    }

    /// Every DH length of joints 1..6 (d1 and a1 included) has a thermal
    /// candidate with every joint's power: 12 × 6 = 72; the column of d1
    /// with joint 3's power is the d1 column times p3_w (here 100 W).
    #[test]
    fn thermal_candidates_cover_every_length_and_power() {
        let (m, v) = load("machines/abb-irb1600.yaml");
        let rows = [robot_row(
            [10.0, 20.0, -15.0, 30.0, 40.0, 50.0],
            Vector3::zeros(),
            1,
        )];
        let lib = library(&m, &rows);
        let thermal: Vec<&Effect> = lib
            .iter()
            .filter(|e| matches!(e.action, Action::Thermal { .. }))
            .collect();
        assert_eq!(thermal.len(), 72);
        for j in 1..=6 {
            for f in ["a", "d"] {
                for p in 1..=6 {
                    find(&lib, &format!("thermal_joint{j}_{f}_p{p}"));
                }
            }
        }
        let ctx = Context {
            machine: &m,
            text: &v,
            kind: MeasuredKind::Position,
            file: "t",
        };
        let t = sensitivity(find(&lib, "thermal_joint1_d_p3"), &ctx, &rows).unwrap();
        let d = sensitivity(find(&lib, "joint1_d"), &ctx, &rows).unwrap();
        for c in 0..3 {
            assert_abs_diff_eq!(t[(c, 0)], 100.0 * d[(c, 0)], epsilon = EXACT_TOL);
        }
    }

    /// Linear straightness is not offered (it is squareness by definition).
    #[test]
    fn no_linear_straightness() {
        let (m, _) = load("machines/afm-r1000.yaml");
        let lib = library(&m, &[tool_row([0.0; 3], 1, 0.0)]);
        assert!(lib.iter().all(|e| e.name != "EYX_lin"));
        assert!(lib.iter().any(|e| e.name == "EYX_quad"));
        assert!(lib.iter().any(|e| e.name == "EXX_lin"));
    }
}
