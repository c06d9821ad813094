//! 6R industrial robot model: machine-file loading and validation, DH
//! kinematics (nominal = controller, actual = calibrated), inverse kinematics
//! with ABB confdata, joint-stiffness statics and compensation of targets.
//!
//! Conventions (internal): mm, rad, N, N·mm, kg. Poses are `Isometry3<f64>`.
//! - Robot base frame: frame 0 of the DH chain. World frame: the frame the
//!   optional `base` is given in (`world_T_base`). TCP poses passed to and
//!   returned by [`Robot`] are in the world frame: `world_T_tcp =
//!   base · flange(q) · flange_to_tool`.
//! - Gravity is given in the world frame; process wrenches act at the TCP.
//! - Joint torques are those the external load exerts on the joints
//!   (`τ = Jᵀ W`); the joints yield by `Δθ = Kθ⁻¹ τ`.

mod calib;
pub mod dh;
pub mod dynamics;
pub mod fanuc;
pub mod ik;
pub mod kinematics;
mod nearest;
pub(crate) mod numeric_ik;
mod params;
pub mod plausible;
pub mod pose;
pub mod process;
mod raw;
mod statics;
pub mod thermal;
mod with_tool;

pub use calib::Trial;
pub use dh::{Convention, DhJoint, DhParams};
pub use dynamics::{Modal, Mode, Resonance};
pub use ik::ConfData;
pub use ik::JOINT_JUMP_MAX_DEG;
pub use kinematics::Frames;
pub use params::{DhField, RobotParam, ThermalField};
pub use process::{ForceModel, ProcessForce};
pub use thermal::{DhGrowth, Thermal, ThermalTerm};

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

use crate::error::{Error, Invalid, Located, Result};
use crate::machine::yaml;
use raw::{RawConvention, RawFrame, RawJoint, RawRobot};

/// Why a target could not be turned into joint values (or compensated).
/// The pipeline turns it into [`Error::Unachievable`] with [`RobotError::at`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RobotError {
    /// The wrist centre is out of reach of the arm.
    #[error("target out of reach: {0}")]
    Unreachable(String),
    /// No inverse-kinematics solution has the requested confdata.
    #[error("no joint solution with confdata {conf} (reachable configurations: {available})")]
    ConfMismatch {
        /// The requested confdata.
        conf: ConfData,
        /// The confdata of the solutions that exist.
        available: String,
    },
    /// A joint value is outside its limits.
    #[error("joint {joint} at {value_deg:.4}° is outside its limits [{min_deg}°, {max_deg}°]")]
    JointLimit {
        /// Joint number 1..=6.
        joint: usize,
        /// The offending value, degrees.
        value_deg: f64,
        /// Lower limit, degrees.
        min_deg: f64,
        /// Upper limit, degrees.
        max_deg: f64,
    },
    /// An iterative solve stopped without reaching its tolerance.
    #[error(
        "{what} did not converge in {iterations} iterations (residual {pos_mm:.3e} mm, {rot_rad:.3e} rad)"
    )]
    NoConvergence {
        /// Which solve.
        what: &'static str,
        /// Iterations done.
        iterations: usize,
        /// Remaining position error, mm.
        pos_mm: f64,
        /// Remaining orientation error, rad.
        rot_rad: f64,
    },
    /// The nominal model has no closed-form inverse (not an ABB-style arm):
    /// its solutions cannot all be listed (confdata selects one
    /// numerically instead).
    #[error(
        "this robot has no closed-form inverse kinematics: its eight solutions cannot be listed"
    )]
    NoClosedForm,
    /// The compensated target's joints depart from the programmed ones by
    /// more than [`JOINT_JUMP_MAX_DEG`] on a joint, or its
    /// configuration differs (near a singularity): the motion would not be
    /// the programmed one.
    #[error(
        "the compensated target changes the arm's motion near a singularity: joint deltas {deltas} (limit {limit}°), configuration {from} → {to} (--allow-reconfiguration accepts it)"
    )]
    Reconfiguration {
        /// Compensated minus programmed joints, degrees, as `[d1, …, d6]`.
        deltas: String,
        /// The limit, degrees.
        limit: f64,
        /// Configuration of the programmed joints.
        from: ConfData,
        /// Configuration of the compensated joints.
        to: ConfData,
    },
}

impl RobotError {
    /// Turns the failure into an located "unachievable" error of a target.
    pub fn at(self, file: &str, line: usize, column: usize) -> Error {
        Error::Unachievable(Located::new(file, line, column, self.to_string()))
    }
}

/// The branch index of a solution of the numeric inverse kinematics (no
/// closed-form branch has it: those are `0..8`).
pub(crate) const NUMERIC_BRANCH: usize = 8;

/// Which parameter set to evaluate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Model {
    /// The controller's parameters.
    Nominal,
    /// The calibrated parameters.
    Actual,
}

/// How to pick one inverse-kinematics solution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum IkSelect {
    /// ABB confdata (needs the closed form).
    Conf(ConfData),
    /// The solution the numeric solver reaches from this joint vector (rad).
    Near([f64; 6]),
}

/// A limit in degrees rounded to nine decimals: the value the machine file
/// wrote, without the noise of its conversion to radians and back.
fn decimal_deg(x: f64) -> f64 {
    let r = (x * 1e9).round() / 1e9;
    if r.is_finite() { r } else { x }
}

/// Mass and centre of mass of a link (in the link's DH frame) or of the tool
/// load (in the flange frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointMass {
    /// Mass, kg.
    pub mass_kg: f64,
    /// Centre of mass, mm.
    pub com_mm: Vector3<f64>,
}

/// The maker's published figures of an arm (`datasheet:`): what `postproc
/// machines` lists. No prediction uses them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Datasheet {
    /// Rated payload, kg.
    pub payload_kg: f64,
    /// Published reach, mm.
    pub reach_mm: f64,
    /// Mass of the arm, kg, where published.
    pub robot_mass_kg: Option<f64>,
}

/// A validated 6R robot (immutable, `Send + Sync`).
#[derive(Debug, Clone)]
pub struct Robot {
    d: Box<RobotData>,
}

/// The validated content of a robot file (boxed: it is about 1 kB).
#[derive(Debug, Clone)]
struct RobotData {
    name: String,
    /// `measurement_frame`: pose of the measuring instrument in the robot
    /// base frame (not part of the model).
    measurement_frame: Option<Isometry3<f64>>,
    /// The controller's parameters, with their prepared rows (confdata).
    nominal: paired::Paired,
    /// The calibrated parameters, with their prepared rows (the kinematic
    /// stage at gain 1).
    actual: paired::Paired,
    closed_form: Option<ik::ClosedForm>,
    limits_rad: [[f64; 2]; 6],
    speed_rad_per_s: [f64; 6],
    tool: Isometry3<f64>,
    base: Isometry3<f64>,
    /// `tool.inverse()` and `base.inverse()`, set with them (every inverse
    /// kinematics uses both).
    tool_inv: Isometry3<f64>,
    base_inv: Isometry3<f64>,
    gravity_m_per_s2: Vector3<f64>,
    links: [PointMass; 6],
    tool_load: Option<PointMass>,
    /// Joint stiffness, N·m/rad (`k_nm_per_rad`).
    k_nm_per_rad: [f64; 6],
    /// The same in N·mm/rad, the unit of the torques the deflection divides
    /// (`k_nm_per_rad · 1000`, set with it).
    k_nmm_per_rad: [f64; 6],
    process_force: Option<ProcessForce>,
    thermal: Option<Thermal>,
    modal: Option<Modal>,
    output: OutputDecimals,
    /// `datasheet`: published payload, reach and mass.
    datasheet: Option<Datasheet>,
    /// Compensated targets may change configuration or move a joint by
    /// more than [`JOINT_JUMP_MAX_DEG`] (off unless set).
    allow_reconfiguration: bool,
    /// `fanuc:`: the controller's user and tool frames.
    fanuc: fanuc::FanucFrames,
    /// The file's values as read, from which [`Robot::with_params`]
    /// validates a robot with some of them changed.
    raw: std::sync::Arc<raw::RawRobot>,
}

/// Default decimals of written quaternion components: 7 keeps the written
/// orientation within 2·(5e-8·2) = 2e-7 rad of the computed one, below the
/// 1 µrad target (6 decimals give only 2 µrad in the worst case).
pub const DEFAULT_QUATERNION_DECIMALS: usize = 7;
/// Default decimals of written positions, mm.
pub const DEFAULT_POSITION_DECIMALS: usize = 3;

/// Decimals of rewritten targets (`output:` section).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OutputDecimals {
    /// Position decimals, mm.
    pub mm: usize,
    /// Quaternion component decimals.
    pub quaternion: usize,
}

/// Largest magnitude of any number of a robot file: beyond every length
/// (mm), angle, speed, mass or joint stiffness (N·m/rad) of a real robot,
/// so that an absurd value is an error rather than an infinity later on.
const MAX_VALUE: f64 = 1e9;

fn finite(path: &str, v: &[f64]) -> std::result::Result<(), Invalid> {
    within(path, v, MAX_VALUE)
}

/// Every value of `v` finite and within ±`max`.
fn within(path: &str, v: &[f64], max: f64) -> std::result::Result<(), Invalid> {
    match v.iter().find(|x| !x.is_finite() || x.abs() > max) {
        Some(x) if !x.is_finite() => Err(Invalid::new(
            path,
            format!("value `{x}` is not a finite number"),
        )),
        Some(x) => Err(Invalid::new(
            path,
            format!(
                "value `{}` is beyond ±{} (not a plausible value)",
                crate::error::show_number(*x),
                crate::error::show_number(max)
            ),
        )),
        None => Ok(()),
    }
}

fn six<T: Copy>(path: &str, v: &[T]) -> std::result::Result<[T; 6], Invalid> {
    <[T; 6]>::try_from(v).map_err(|_| {
        Invalid::new(
            path,
            format!("expected 6 entries (one per joint), found {}", v.len()),
        )
    })
}

fn joints(
    path: &str,
    conv: Convention,
    rows: &[RawJoint],
) -> std::result::Result<DhParams, Invalid> {
    let rows = six(path, rows.iter().collect::<Vec<_>>().as_slice())?;
    let mut out = [DhJoint {
        a_mm: 0.0,
        alpha_rad: 0.0,
        d_mm: 0.0,
        theta_offset_rad: 0.0,
    }; 6];
    for (i, r) in rows.iter().enumerate() {
        // Link lengths within 100 m, angles within a turn.
        within(&format!("{path}[{i}]"), &[r.a_mm, r.d_mm], 1e5)?;
        within(
            &format!("{path}[{i}]"),
            &[r.alpha_deg, r.theta_offset_deg],
            360.0,
        )?;
        out[i] = DhJoint {
            a_mm: r.a_mm,
            alpha_rad: r.alpha_deg.to_radians(),
            d_mm: r.d_mm,
            theta_offset_rad: r.theta_offset_deg.to_radians(),
        };
    }
    Ok(DhParams {
        convention: conv,
        joints: out,
    })
}

fn frame(path: &str, f: &RawFrame) -> std::result::Result<Isometry3<f64>, Invalid> {
    finite(path, &[f.x_mm, f.y_mm, f.z_mm])?;
    let rot = match (f.quaternion, f.rpy_deg) {
        (Some(_), Some(_)) => {
            return Err(Invalid::new(
                path,
                "give either `quaternion` or `rpy_deg`, not both",
            ));
        }
        (Some(q), None) => {
            let p = format!("{path}.quaternion");
            finite(&p, &q)?;
            let n = (q.iter().map(|x| x * x).sum::<f64>()).sqrt();
            if (n - 1.0).abs() > 1e-3 {
                return Err(Invalid::new(
                    p,
                    format!("quaternion {q:?} is not unit length (norm {n:.6})"),
                ));
            }
            pose::rotation_from_abb(q).ok_or_else(|| Invalid::new(p, "zero quaternion"))?
        }
        (None, Some(r)) => {
            finite(&format!("{path}.rpy_deg"), &r)?;
            pose::rotation_from_rpy(r[0].to_radians(), r[1].to_radians(), r[2].to_radians())
        }
        (None, None) => UnitQuaternion::identity(),
    };
    Ok(Isometry3::from_parts(
        Translation3::new(f.x_mm, f.y_mm, f.z_mm),
        rot,
    ))
}

/// Like [`yaml::invalid`], but when the full key path cannot be found in
/// the text (indices into flow sequences such as `k_nm_per_rad[2]`), points
/// at the deepest enclosing key that can be found.
fn locate_invalid(text: &str, file: &str, inv: Invalid) -> Error {
    let mut probe = inv.path.as_str();
    loop {
        if let Some((line, column)) = yaml::locate(text, probe) {
            return Error::Machine(Located::new(file, line, column, inv.to_string()));
        }
        match probe.rfind(['.', '[']) {
            Some(cut) if cut > 0 => probe = &probe[..cut],
            _ => return yaml::invalid(text, file, inv),
        }
    }
}

/// `joint_limits_deg`: six ordered pairs, as radians.
fn joint_limits(raw: &[[f64; 2]]) -> std::result::Result<[[f64; 2]; 6], Invalid> {
    let lim = six("joint_limits_deg", raw)?;
    let mut limits_rad = [[0.0; 2]; 6];
    for (i, l) in lim.iter().enumerate() {
        let p = format!("joint_limits_deg[{i}]");
        finite(&p, l)?;
        if l[0] >= l[1] {
            return Err(Invalid::new(
                p,
                format!("minimum {} must be below maximum {}", l[0], l[1]),
            ));
        }
        limits_rad[i] = [l[0].to_radians(), l[1].to_radians()];
    }
    Ok(limits_rad)
}

/// `joint_speed_deg_per_s`: six positive speeds, as rad/s.
fn joint_speeds(raw: &[f64]) -> std::result::Result<[f64; 6], Invalid> {
    let sp = six("joint_speed_deg_per_s", raw)?;
    let mut speed_rad_per_s = [0.0; 6];
    for (i, s) in sp.iter().enumerate() {
        let p = format!("joint_speed_deg_per_s[{i}]");
        finite(&p, &[*s])?;
        if *s <= 0.0 {
            return Err(Invalid::new(p, format!("speed {s} must be positive")));
        }
        speed_rad_per_s[i] = s.to_radians();
    }
    Ok(speed_rad_per_s)
}

/// `links`: the mass and centre of mass of each of the six links.
fn link_masses(raw: &[raw::RawLink]) -> std::result::Result<[PointMass; 6], Invalid> {
    let links_raw = six("links", raw.iter().collect::<Vec<_>>().as_slice())?;
    let mut links = [PointMass {
        mass_kg: 0.0,
        com_mm: Vector3::zeros(),
    }; 6];
    for (i, l) in links_raw.iter().enumerate() {
        let p = format!("links[{i}]");
        finite(&format!("{p}.mass_kg"), &[l.mass_kg])?;
        finite(&format!("{p}.com_mm"), &l.com_mm)?;
        if l.mass_kg <= 0.0 {
            return Err(Invalid::new(
                format!("{p}.mass_kg"),
                format!("mass {} must be positive", l.mass_kg),
            ));
        }
        links[i] = PointMass {
            mass_kg: l.mass_kg,
            com_mm: Vector3::from(l.com_mm),
        };
    }
    Ok(links)
}

/// `tool_load`: the mass and centre of gravity of the tool.
fn tool_load(l: &raw::RawLoad) -> std::result::Result<PointMass, Invalid> {
    finite("tool_load.mass_kg", &[l.mass_kg])?;
    finite("tool_load.cog_mm", &l.cog_mm)?;
    if l.mass_kg <= 0.0 {
        return Err(Invalid::new(
            "tool_load.mass_kg",
            format!("mass {} must be positive", l.mass_kg),
        ));
    }
    Ok(PointMass {
        mass_kg: l.mass_kg,
        com_mm: Vector3::from(l.cog_mm),
    })
}

/// `k_nm_per_rad`: six positive joint stiffnesses, N·m/rad.
fn joint_stiffness(raw: &[f64]) -> std::result::Result<[f64; 6], Invalid> {
    let k = six("k_nm_per_rad", raw)?;
    for (i, v) in k.iter().enumerate() {
        let p = format!("k_nm_per_rad[{i}]");
        finite(&p, &[*v])?;
        if *v <= 0.0 {
            return Err(Invalid::new(p, format!("stiffness {v} must be positive")));
        }
    }
    Ok(k)
}

/// `datasheet`: published payload, reach and mass, each positive.
fn datasheet(d: &raw::RawDatasheet) -> std::result::Result<Datasheet, Invalid> {
    let positive = |key: &str, v: f64, max: f64| {
        let path = format!("datasheet.{key}");
        within(&path, &[v], max)?;
        if v <= 0.0 {
            return Err(Invalid::new(path, format!("{v} must be positive")));
        }
        Ok(v)
    };
    // The heaviest arms weigh a few tonnes and reach a few metres.
    Ok(Datasheet {
        payload_kg: positive("payload_kg", d.payload_kg, 1e4)?,
        reach_mm: positive("reach_mm", d.reach_mm, 1e5)?,
        robot_mass_kg: d
            .robot_mass_kg
            .map(|m| positive("robot_mass_kg", m, 1e5))
            .transpose()?,
    })
}

/// `output`: decimals of positions and quaternions, defaults where unset.
fn output_decimals(raw: Option<&raw::RawOutput>) -> std::result::Result<OutputDecimals, Invalid> {
    let mut output = OutputDecimals {
        mm: DEFAULT_POSITION_DECIMALS,
        quaternion: DEFAULT_QUATERNION_DECIMALS,
    };
    if let Some(o) = raw {
        if let Some(d) = o.decimals_mm {
            if !(1..=6).contains(&d) {
                return Err(Invalid::new(
                    "output.decimals_mm",
                    format!("{d} must be 1..6"),
                ));
            }
            output.mm = d;
        }
        if let Some(d) = o.decimals_quaternion {
            if !(4..=9).contains(&d) {
                return Err(Invalid::new(
                    "output.decimals_quaternion",
                    format!("{d} must be 4..9"),
                ));
            }
            output.quaternion = d;
        }
    }
    Ok(output)
}

impl Robot {
    /// Parses and validates robot YAML; `file` names it in errors.
    pub fn from_yaml_str(text: &str, file: &str) -> Result<Self> {
        Self::from_source(&yaml::Source::read(text, file)?)
    }

    /// Validates a robot file read by [`yaml::Source::read`].
    pub fn from_source(src: &yaml::Source) -> Result<Self> {
        let (text, file) = (src.text(), src.file());
        let raw: RawRobot = src.deserialize()?;
        let r = Self::validate(raw).map_err(|inv| locate_invalid(text, file, inv))?;
        // The values accepted through `plausibility:` overrides.
        for w in plausible::check(&r.d.raw).unwrap_or_default() {
            tracing::warn!("{}", locate_invalid(text, file, w));
        }
        Ok(r)
    }

    fn validate(raw: RawRobot) -> std::result::Result<Self, Invalid> {
        if raw.kind != "robot" {
            return Err(Invalid::new(
                "kind",
                format!("expected `robot`, found `{}`", raw.kind),
            ));
        }
        let conv = match raw.convention {
            RawConvention::Dh => Convention::Dh,
            RawConvention::ModifiedDh => Convention::ModifiedDh,
        };
        let nominal = joints("nominal", conv, &raw.nominal)?;
        let actual = match &raw.actual {
            Some(a) => joints("actual", conv, a)?,
            None => nominal,
        };
        let limits_rad = joint_limits(&raw.joint_limits_deg)?;
        let speed_rad_per_s = joint_speeds(&raw.joint_speed_deg_per_s)?;
        let tool = match &raw.flange_to_tool {
            Some(f) => frame("flange_to_tool", f)?,
            None => Isometry3::identity(),
        };
        let base = match &raw.base {
            Some(f) => frame("base", f)?,
            None => Isometry3::identity(),
        };
        let measurement_frame = match &raw.measurement_frame {
            Some(f) => Some(frame("measurement_frame", f)?),
            None => None,
        };
        finite("gravity_m_per_s2", &raw.gravity_m_per_s2)?;
        let links = link_masses(&raw.links)?;
        let tool_load = raw.tool_load.as_ref().map(tool_load).transpose()?;
        let k_nm_per_rad = joint_stiffness(&raw.k_nm_per_rad)?;
        let process_force = match (&raw.process_wrench, &raw.process_force) {
            (Some(_), Some(_)) => {
                return Err(Invalid::new(
                    "process_wrench",
                    "give either `process_wrench` or `process_force`, not both",
                ));
            }
            (Some(w), None) => Some(ProcessForce::from_wrench(w)?),
            (None, Some(f)) => Some(ProcessForce::from_raw(f)?),
            (None, None) => None,
        };
        let thermal = raw.thermal.as_ref().map(Thermal::from_raw).transpose()?;
        let modal = raw
            .modal
            .as_deref()
            .map(dynamics::modal_from_raw)
            .transpose()?;
        let output = output_decimals(raw.output.as_ref())?;
        let datasheet = raw.datasheet.as_ref().map(datasheet).transpose()?;
        let fanuc = fanuc::FanucFrames::try_from(raw.fanuc.as_ref())?;
        plausible::check(&raw)?;
        let closed_form = ik::ClosedForm::new(&nominal);
        Ok(Robot {
            d: Box::new(RobotData {
                measurement_frame,
                name: raw.name.clone().unwrap_or_else(|| "robot".to_string()),
                nominal: paired::Paired::new(nominal),
                actual: paired::Paired::new(actual),
                closed_form,
                limits_rad,
                speed_rad_per_s,
                tool_inv: tool.inverse(),
                base_inv: base.inverse(),
                tool,
                base,
                gravity_m_per_s2: Vector3::from(raw.gravity_m_per_s2),
                links,
                tool_load,
                k_nm_per_rad,
                k_nmm_per_rad: k_nm_per_rad.map(|k| k * 1000.0),
                process_force,
                thermal,
                modal,
                output,
                datasheet,
                allow_reconfiguration: false,
                fanuc,
                raw: std::sync::Arc::new(raw),
            }),
        })
    }

    /// This robot, allowing (or not) compensated targets that change
    /// configuration or jump a joint ([`RobotError::Reconfiguration`]).
    pub fn allowing_reconfiguration(mut self, allow: bool) -> Robot {
        self.d.allow_reconfiguration = allow;
        self
    }

    /// The FANUC user and tool frames of the file (`fanuc:`; empty without
    /// it).
    pub fn fanuc_frames(&self) -> &fanuc::FanucFrames {
        &self.d.fanuc
    }

    /// Display name.
    pub fn name(&self) -> &str {
        &self.d.name
    }
    /// Parameter set of a model.
    pub fn params(&self, model: Model) -> &DhParams {
        match model {
            Model::Nominal => self.d.nominal.params(),
            Model::Actual => self.d.actual.params(),
        }
    }
    /// Whether the nominal model has the ABB-style closed-form inverse.
    pub fn has_closed_form(&self) -> bool {
        self.d.closed_form.is_some()
    }
    /// Joint limits `[min, max]`, rad.
    pub fn joint_limits_rad(&self) -> &[[f64; 2]; 6] {
        &self.d.limits_rad
    }
    /// Maximum joint speeds, rad/s.
    pub fn joint_speed_rad_per_s(&self) -> &[f64; 6] {
        &self.d.speed_rad_per_s
    }
    /// Default TCP: flange → tool.
    pub fn flange_to_tool(&self) -> &Isometry3<f64> {
        &self.d.tool
    }
    /// Pose of the measuring instrument in the robot base frame (the
    /// file's `measurement_frame`), if given.
    pub fn measurement_frame(&self) -> Option<&Isometry3<f64>> {
        self.d.measurement_frame.as_ref()
    }
    /// Robot base frame in the world frame.
    pub fn base(&self) -> &Isometry3<f64> {
        &self.d.base
    }
    /// Gravity vector in the world frame, m/s².
    pub fn gravity_m_per_s2(&self) -> &Vector3<f64> {
        &self.d.gravity_m_per_s2
    }
    /// Link masses and centres of mass (link DH frames).
    pub fn links(&self) -> &[PointMass; 6] {
        &self.d.links
    }
    /// Tool load (flange frame), if any.
    pub fn tool_load(&self) -> Option<&PointMass> {
        self.d.tool_load.as_ref()
    }
    /// Joint stiffness, N·m/rad (the unit of the file's `k_nm_per_rad`).
    pub fn k_nm_per_rad(&self) -> &[f64; 6] {
        &self.d.k_nm_per_rad
    }
    /// Decimals of rewritten targets (`output:`; defaults
    /// [`DEFAULT_POSITION_DECIMALS`], [`DEFAULT_QUATERNION_DECIMALS`]).
    pub fn output_decimals(&self) -> OutputDecimals {
        self.d.output
    }
    /// The maker's published figures (`datasheet:`), if given.
    pub fn datasheet(&self) -> Option<&Datasheet> {
        self.d.datasheet.as_ref()
    }
    /// The process wrench the file gives for every feed move: a constant
    /// force in the tool or base frame (`None` for the other models and
    /// frames, which depend on the move).
    pub fn file_wrench(&self) -> Option<crate::process::Wrench> {
        process::default_wrench(self.process_force())
    }

    /// All joint frames of a model in the robot base frame (from the
    /// model's stored prepared rows: the bits of [`kinematics::frames`]
    /// without recomputing the twists).
    pub fn frames(&self, model: Model, q: &[f64; 6]) -> Frames {
        kinematics::frames_prepared(self.prepared(model), q, 6)
    }
    /// Flange pose in the robot base frame (from the model's stored
    /// prepared rows: the bits of [`kinematics::flange`] without
    /// recomputing the twists or storing the link frames).
    pub fn flange_pose(&self, model: Model, q: &[f64; 6]) -> Isometry3<f64> {
        kinematics::flange_prepared(self.prepared(model), q)
    }
    /// The stored prepared rows of a model.
    fn prepared(&self, model: Model) -> &kinematics::Prepared {
        match model {
            Model::Nominal => self.d.nominal.prepared(),
            Model::Actual => self.d.actual.prepared(),
        }
    }
    /// TCP pose in the world frame: `base · flange(q) · flange_to_tool`.
    pub fn tcp_pose(&self, model: Model, q: &[f64; 6]) -> Isometry3<f64> {
        self.d.base * self.flange_pose(model, q) * self.d.tool
    }
    /// Flange pose (robot base frame) that puts the TCP at `tcp_world`.
    pub fn flange_for_tcp(&self, tcp_world: &Isometry3<f64>) -> Isometry3<f64> {
        self.d.base_inv * tcp_world * self.d.tool_inv
    }
    /// The nominal parameter set with its twists precomputed.
    pub(crate) fn nominal_prepared(&self) -> &kinematics::Prepared {
        self.d.nominal.prepared()
    }

    /// The actual parameter set with its twists precomputed.
    pub(crate) fn actual_prepared(&self) -> &kinematics::Prepared {
        self.d.actual.prepared()
    }

    /// Replaces the actual parameter set (and its prepared rows).
    pub(crate) fn set_actual(&mut self, actual: DhParams) {
        self.d.actual = paired::Paired::new(actual);
    }

    /// ABB confdata of a joint vector (nominal model).
    pub fn confdata(&self, q: &[f64; 6]) -> ConfData {
        ik::confdata_prepared(self.d.nominal.prepared(), q)
    }

    /// Checks every joint against its limits.
    pub fn check_limits(&self, q: &[f64; 6]) -> std::result::Result<(), RobotError> {
        const LIMIT_TOL_RAD: f64 = 1e-9;
        for (i, (v, l)) in q.iter().zip(self.d.limits_rad.iter()).enumerate() {
            if *v < l[0] - LIMIT_TOL_RAD || *v > l[1] + LIMIT_TOL_RAD || !v.is_finite() {
                return Err(RobotError::JointLimit {
                    joint: i + 1,
                    value_deg: v.to_degrees(),
                    // As the machine file gives them: degrees went to
                    // radians and back (−245.00000000000003° is −245°).
                    min_deg: decimal_deg(l[0].to_degrees()),
                    max_deg: decimal_deg(l[1].to_degrees()),
                });
            }
        }
        Ok(())
    }

    /// All eight closed-form solutions of the nominal model for a TCP pose
    /// (world frame), joints in (−π, π], no limit check. Index bits: 4 =
    /// second shoulder branch, 2 = second elbow branch, 1 = flipped wrist.
    pub fn ik_all(
        &self,
        tcp_world: &Isometry3<f64>,
    ) -> std::result::Result<[Option<[f64; 6]>; 8], RobotError> {
        let cf = self
            .d
            .closed_form
            .as_ref()
            .ok_or(RobotError::NoClosedForm)?;
        let sols = cf.solve(&self.flange_for_tcp(tcp_world), 0.0);
        if sols.iter().all(Option::is_none) {
            return Err(RobotError::Unreachable(
                "the wrist centre is farther from (or closer to) the shoulder than the arm can reach".into(),
            ));
        }
        Ok(sols)
    }

    /// Nominal (controller) inverse kinematics selecting the solution by ABB
    /// confdata; joints 1, 4, 6 get the turns their quadrants demand. Checks
    /// joint limits.
    pub fn ik_conf(
        &self,
        tcp_world: &Isometry3<f64>,
        conf: ConfData,
    ) -> std::result::Result<[f64; 6], RobotError> {
        let q = self
            .ik_conf_turns(tcp_world, conf, None)
            .map_err(|e| self.with_reaching_configurations(tcp_world, e))?;
        self.check_limits(&q)?;
        Ok(q)
    }

    /// [`Robot::ik_conf`] with the index of the closed-form branch of the
    /// solution (a seed of [`Robot::ik_conf_near_branch`]). A refusal of
    /// the numeric inverse does not list the configurations that reach the
    /// target ([`Robot::with_reaching_configurations`] adds them).
    pub(crate) fn ik_conf_indexed(
        &self,
        tcp_world: &Isometry3<f64>,
        conf: ConfData,
    ) -> std::result::Result<([f64; 6], usize), RobotError> {
        let (q, k) = self.ik_conf_branch(tcp_world, conf, None)?;
        self.check_limits(&q)?;
        Ok((q, k))
    }

    /// Closed-form solution with confdata `conf`, turns of joints 1, 4, 6
    /// nearest to `reference` (no limit check).
    pub(crate) fn ik_conf_near(
        &self,
        tcp_world: &Isometry3<f64>,
        conf: ConfData,
        reference: &[f64; 6],
    ) -> std::result::Result<[f64; 6], RobotError> {
        self.ik_conf_turns(tcp_world, conf, Some(reference))
    }

    /// Like [`Robot::ik_conf`] without the limit check; with `turn_ref`, the
    /// turns of joints 1, 4, 6 are the ones nearest to it instead of the
    /// confdata quadrants (used while iterating on a target). A robot
    /// without a closed form only starts its solver at `turn_ref` and
    /// keeps the quadrants and the limits (see `numeric_ik`).
    fn ik_conf_turns(
        &self,
        tcp_world: &Isometry3<f64>,
        conf: ConfData,
        turn_ref: Option<&[f64; 6]>,
    ) -> std::result::Result<[f64; 6], RobotError> {
        self.ik_conf_branch(tcp_world, conf, turn_ref)
            .map(|(q, _)| q)
    }

    /// [`Robot::ik_conf_near`] restricted to the closed-form branch `k` (an
    /// index of [`ik::ClosedForm::solve`], as returned by
    /// [`Robot::ik_conf_branch`]): no other branch and no confdata is
    /// computed. The caller checks the confdata of the final joints (the
    /// branch of a target does not change over sub-millimetre
    /// corrections). Falls back to the full search when branch `k` cannot
    /// reach.
    pub(crate) fn ik_conf_near_branch(
        &self,
        tcp_world: &Isometry3<f64>,
        conf: ConfData,
        reference: &[f64; 6],
        k: usize,
    ) -> std::result::Result<[f64; 6], RobotError> {
        let Some(cf) = self.d.closed_form.as_ref() else {
            return self.ik_conf_near(tcp_world, conf, reference);
        };
        let flange = self.flange_for_tcp(tcp_world);
        match cf.solve_branch(&flange, reference[3], k) {
            Some(mut q) => {
                for i in 0..6 {
                    q[i] = ik::nearest_turn(q[i], reference[i]);
                }
                Ok(q)
            }
            None => self.ik_conf_near(tcp_world, conf, reference),
        }
    }

    /// [`Robot::ik_conf_turns`] with the index of the closed-form branch
    /// that gave the solution ([`NUMERIC_BRANCH`] for a robot without a
    /// closed form, solved numerically: see `numeric_ik`).
    pub(crate) fn ik_conf_branch(
        &self,
        tcp_world: &Isometry3<f64>,
        conf: ConfData,
        turn_ref: Option<&[f64; 6]>,
    ) -> std::result::Result<([f64; 6], usize), RobotError> {
        let Some(cf) = self.d.closed_form.as_ref() else {
            return self
                .ik_conf_numeric(tcp_world, conf, turn_ref)
                .map(|q| (q, NUMERIC_BRANCH));
        };
        let wrist_ref = turn_ref.map_or(0.0, |r| r[3]);
        let flange = self.flange_for_tcp(tcp_world);
        // The first solution (in index order) with the asked cfx; the later
        // branches are not computed.
        let mut found = None;
        cf.solve_until(&flange, wrist_ref, |k, q| {
            // The last bit of cfx is `q5 < 0`: a branch whose wrist sign
            // differs cannot match, and needs no frames.
            let hit = (q[4] < 0.0) == (conf.cfx & 1 == 1)
                && ik::confdata_prepared(self.d.nominal.prepared(), &q).cfx == conf.cfx;
            if hit {
                found = Some((q, k));
            }
            hit
        });
        let mismatch = || {
            let sols = cf.solve(&flange, wrist_ref);
            if sols.iter().all(Option::is_none) {
                return RobotError::Unreachable(
                    "the wrist centre is farther from (or closer to) the shoulder than the arm can reach".into(),
                );
            }
            RobotError::ConfMismatch {
                conf,
                available: sols
                    .iter()
                    .flatten()
                    .map(|q| ik::confdata_prepared(self.d.nominal.prepared(), q).to_string())
                    .collect::<Vec<_>>()
                    .join(" "),
            }
        };
        let (mut q, k) = found.ok_or_else(mismatch)?;
        match turn_ref {
            Some(r) => {
                for i in 0..6 {
                    q[i] = ik::nearest_turn(q[i], r[i]);
                }
            }
            None => {
                for (i, c) in [(0, conf.cf1), (3, conf.cf4), (5, conf.cf6)] {
                    q[i] = ik::into_quadrant(q[i], c).ok_or_else(mismatch)?;
                }
                // Joints 2, 3, 5 carry no quadrant: take the turn that lies
                // inside the limits (e.g. q3 = −217° rather than 143°).
                for i in [1, 2, 4] {
                    let [lo, hi] = self.d.limits_rad[i];
                    for t in [0.0, -2.0 * std::f64::consts::PI, 2.0 * std::f64::consts::PI] {
                        if (lo..=hi).contains(&(q[i] + t)) {
                            q[i] += t;
                            break;
                        }
                    }
                }
            }
        }
        Ok((q, k))
    }

    /// Numeric inverse kinematics of a model from a seed joint vector (rad);
    /// checks joint limits.
    pub fn ik_numeric(
        &self,
        model: Model,
        tcp_world: &Isometry3<f64>,
        seed: &[f64; 6],
    ) -> std::result::Result<[f64; 6], RobotError> {
        let q = ik::solve_numeric(self.params(model), &self.flange_for_tcp(tcp_world), seed)?;
        self.check_limits(&q)?;
        Ok(q)
    }

    /// Inverse kinematics of the actual (calibrated) model: the nominal
    /// closed-form solution with this confdata refined numerically.
    pub fn ik_actual_conf(
        &self,
        tcp_world: &Isometry3<f64>,
        conf: ConfData,
    ) -> std::result::Result<[f64; 6], RobotError> {
        let seed = self
            .ik_conf_turns(tcp_world, conf, None)
            .map_err(|e| self.with_reaching_configurations(tcp_world, e))?;
        self.ik_numeric(Model::Actual, tcp_world, &seed)
    }

    /// Nominal (controller) joint values of a TCP pose by either selection.
    pub fn ik_nominal(
        &self,
        tcp_world: &Isometry3<f64>,
        sel: &IkSelect,
    ) -> std::result::Result<[f64; 6], RobotError> {
        self.ik_nominal_unlisted(tcp_world, sel)
            .map_err(|e| self.with_reaching_configurations(tcp_world, e))
    }

    /// [`Robot::ik_nominal`] whose refusal by the numeric inverse does not
    /// list the configurations that reach the target
    /// ([`Robot::with_reaching_configurations`] adds them).
    pub(crate) fn ik_nominal_unlisted(
        &self,
        tcp_world: &Isometry3<f64>,
        sel: &IkSelect,
    ) -> std::result::Result<[f64; 6], RobotError> {
        match sel {
            IkSelect::Conf(c) => {
                let q = self.ik_conf_turns(tcp_world, *c, None)?;
                self.check_limits(&q)?;
                Ok(q)
            }
            IkSelect::Near(seed) => self.ik_numeric(Model::Nominal, tcp_world, seed),
        }
    }
}

/// A parameter set with its prepared rows, made together and only
/// together: the rows can never describe other parameters than the set
/// (the fields are private to this module, so not even the rest of the
/// robot module can change one without the other).
mod paired {
    use super::DhParams;
    use super::kinematics::Prepared;

    /// Parameters and their prepared rows.
    #[derive(Debug, Clone)]
    pub(super) struct Paired {
        params: DhParams,
        prepared: Prepared,
    }

    impl Paired {
        /// Prepares `params`.
        pub(super) fn new(params: DhParams) -> Self {
            Paired {
                prepared: Prepared::new(&params),
                params,
            }
        }

        /// The parameters.
        pub(super) fn params(&self) -> &DhParams {
            &self.params
        }

        /// Their prepared rows.
        pub(super) fn prepared(&self) -> &Prepared {
            &self.prepared
        }
    }
}

/// The bundled ABB IRB 1600 file (tests).
#[cfg(test)]
pub(crate) fn test_irb1600() -> Robot {
    let text = include_str!("../../../machines/abb-irb1600.yaml");
    let Ok(crate::machine::Machine::Robot(r)) =
        crate::machine::Machine::from_yaml_str(text, "abb-irb1600.yaml")
    else {
        panic!("abb-irb1600.yaml is a robot file")
    };
    r
}

/// A fixed pseudo-random sequence in [−1, 1) (tests).
#[cfg(test)]
pub(crate) fn test_sequence(seed: u64) -> impl FnMut() -> f64 {
    let mut state = seed;
    move || {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 2.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The wrist-sign pre-check of [`Robot::ik_conf_branch`] against the
    /// full search: the first branch (in index order) whose confdata has
    /// the asked cfx, or none, for random poses and every cfx.
    #[test]
    fn conf_branch_equals_the_first_matching_branch() {
        let r = super::test_irb1600();
        let Some(cf) = r.d.closed_form.as_ref() else {
            panic!("the IRB 1600 has a closed form")
        };
        let mut next = super::test_sequence(0x2545_f491_4f6c_dd1d);
        let mut matched = 0;
        for _ in 0..300 {
            let q: [f64; 6] = std::array::from_fn(|_| next());
            let tcp = r.tcp_pose(Model::Nominal, &q);
            let base = r.confdata(&q);
            let sols = cf.solve(&r.flange_for_tcp(&tcp), 0.0);
            for cfx in -1..9 {
                let conf = ConfData { cfx, ..base };
                let expected = sols
                    .iter()
                    .enumerate()
                    .find_map(|(k, s)| s.filter(|s| r.confdata(s).cfx == cfx).map(|_| k));
                let got = r.ik_conf_branch(&tcp, conf, Some(&q)).ok().map(|(_, k)| k);
                assert_eq!(got, expected, "cfx {cfx}");
                matched += usize::from(got.is_some());
            }
        }
        assert!(matched > 300);
    }

    /// The stored inverses of the tool and base frames follow their
    /// setters: `flange_for_tcp` equals the product with fresh inverses.
    #[test]
    fn flange_for_tcp_uses_current_inverses() {
        let r = super::test_irb1600();
        let frame = |x: f64, a: f64| {
            Isometry3::from_parts(
                nalgebra::Translation3::new(x, -2.0 * x, 0.5 * x),
                nalgebra::UnitQuaternion::from_euler_angles(a, -0.5 * a, 0.25 * a),
            )
        };
        let tcp = frame(700.0, 2.9);
        let views = [
            r.clone(),
            r.with_tool(frame(12.0, 0.3), None),
            r.trial_with_params(&[Trial::Base(frame(-150.0, 0.1))]),
            r.with_tool(frame(3.0, -1.2), None)
                .trial_with_params(&[Trial::Base(frame(40.0, 2.0))]),
        ];
        for v in &views {
            let fresh = v.base().inverse() * tcp * v.flange_to_tool().inverse();
            let got = v.flange_for_tcp(&tcp);
            assert_eq!(got.translation.vector, fresh.translation.vector);
            assert_eq!(got.rotation.coords, fresh.rotation.coords);
        }
    }

    /// `flange_pose` and `frames` from the stored prepared rows have the
    /// bits of the frame-by-frame product of the model's parameters, for
    /// both models, also after the actual set is replaced (a thermal state).
    #[test]
    fn flange_pose_and_frames_equal_the_frame_product_bit_for_bit() {
        let r = super::test_irb1600();
        let warm = r.at_joint_power(&[900.0, 700.0, 0.0, 0.0, 0.0, 0.0]);
        let mut next = super::test_sequence(0x9e37_79b9_7f4a_7c15);
        for _ in 0..200 {
            let q: [f64; 6] = std::array::from_fn(|_| 3.0 * next());
            for robot in [&r, &warm] {
                for model in [Model::Nominal, Model::Actual] {
                    let fast = robot.flange_pose(model, &q);
                    let slow = kinematics::flange(robot.params(model), &q);
                    assert_eq!(fast.translation.vector, slow.translation.vector);
                    assert_eq!(fast.rotation.coords, slow.rotation.coords);
                    let (fast, slow) = (
                        robot.frames(model, &q),
                        kinematics::frames(robot.params(model), &q),
                    );
                    for i in 0..6 {
                        assert_eq!(fast.link[i].translation, slow.link[i].translation);
                        assert_eq!(fast.link[i].rotation.coords, slow.link[i].rotation.coords);
                        assert_eq!(fast.axis_origin[i], slow.axis_origin[i]);
                        assert_eq!(fast.axis_dir[i], slow.axis_dir[i]);
                    }
                }
            }
        }
        assert_ne!(
            warm.flange_pose(Model::Actual, &[0.0; 6])
                .translation
                .vector,
            r.flange_pose(Model::Actual, &[0.0; 6]).translation.vector,
            "the warm robot's actual set differs"
        );
    }

    #[test]
    fn robot_is_send_sync() {
        fn check<T: Send + Sync>() {}
        check::<Robot>();
    }
}
