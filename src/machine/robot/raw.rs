//! Raw (serde) form of a robot machine file: the YAML exactly as written,
//! with `deny_unknown_fields` everywhere. Validation into the immutable
//! [`super::Robot`] happens in `mod.rs`.

use serde::Deserialize;

/// Top level of a `kind: robot` machine file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawRobot {
    pub kind: String,
    #[serde(default)]
    pub name: Option<String>,
    pub convention: RawConvention,
    pub nominal: Vec<RawJoint>,
    #[serde(default)]
    pub actual: Option<Vec<RawJoint>>,
    pub joint_limits_deg: Vec<[f64; 2]>,
    pub joint_speed_deg_per_s: Vec<f64>,
    #[serde(default)]
    pub flange_to_tool: Option<RawFrame>,
    #[serde(default)]
    pub base: Option<RawFrame>,
    /// Pose of the measuring instrument in the robot base frame (written
    /// by calibration from instrument-frame observations; not part of the
    /// model).
    #[serde(default)]
    pub measurement_frame: Option<RawFrame>,
    pub gravity_m_per_s2: [f64; 3],
    pub links: Vec<RawLink>,
    #[serde(default)]
    pub tool_load: Option<RawLoad>,
    pub k_nm_per_rad: Vec<f64>,
    #[serde(default)]
    pub process_wrench: Option<RawWrench>,
    #[serde(default)]
    pub process_force: Option<RawProcessForce>,
    #[serde(default)]
    pub thermal: Option<RawThermal>,
    #[serde(default)]
    pub modal: Option<Vec<RawMode>>,
    #[serde(default)]
    pub output: Option<RawOutput>,
    #[serde(default)]
    pub datasheet: Option<RawDatasheet>,
    /// `fanuc:` — the controller's user and tool frames.
    #[serde(default)]
    pub fanuc: Option<super::fanuc::RawFanuc>,
    /// `status` and `calibrations`, read by [`crate::machine::status`].
    #[serde(default, rename = "status")]
    pub _status: Option<serde::de::IgnoredAny>,
    #[serde(default, rename = "calibrations")]
    pub _calibrations: Option<serde::de::IgnoredAny>,
    /// `plausibility:` — key paths whose plausibility ranges are not
    /// applied ([`crate::machine::plausibility`]).
    #[serde(default)]
    pub plausibility: Option<crate::machine::plausibility::Overrides>,
    /// Limits of the acceptance tests, read by `crate::verify::limits`.
    #[serde(default, rename = "acceptance")]
    pub _acceptance: Option<serde::de::IgnoredAny>,
    /// Parameter covariance per calibrated section, read by
    /// `crate::predict::uncertainty::read_covariance`.
    #[serde(default, rename = "covariance")]
    pub _covariance: Option<serde::de::IgnoredAny>,
}

/// `process_force:` — the predicted process force at the TCP.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawProcessForce {
    pub model: RawForceModel,
    #[serde(default)]
    pub force_n: Option<[f64; 3]>,
    #[serde(default)]
    pub moment_nm: Option<[f64; 3]>,
    #[serde(default)]
    pub frame: Option<RawForceFrame>,
    #[serde(default)]
    pub thrust_coefficient_n_per_mm2: Option<f64>,
    #[serde(default)]
    pub drill_diameter_mm: Option<f64>,
    #[serde(default)]
    pub spindle_rpm: Option<f64>,
    #[serde(default)]
    pub flutes: Option<u32>,
    #[serde(default)]
    pub max_feed_mm_per_rev: Option<f64>,
    #[serde(default)]
    pub axis_tolerance_deg: Option<f64>,
    #[serde(default)]
    pub kt_n_per_mm2: Option<f64>,
    #[serde(default)]
    pub kr_n_per_mm2: Option<f64>,
    #[serde(default)]
    pub ka_n_per_mm2: Option<f64>,
    #[serde(default)]
    pub kte_n_per_mm: Option<f64>,
    #[serde(default)]
    pub kre_n_per_mm: Option<f64>,
    #[serde(default)]
    pub kae_n_per_mm: Option<f64>,
    #[serde(default)]
    pub tool_diameter_mm: Option<f64>,
    #[serde(default)]
    pub axial_depth_mm: Option<f64>,
    #[serde(default)]
    pub radial_width_mm: Option<f64>,
}

/// `process_force.model`.
#[derive(Debug, Deserialize, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub(crate) enum RawForceModel {
    Constant,
    Milling,
    Drilling,
    Table,
}

/// `process_force.frame`.
#[derive(Debug, Deserialize, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub(crate) enum RawForceFrame {
    Tool,
    Workpiece,
    Base,
    Feed,
}

/// `thermal:` — Paper B power-dependent DH lengths.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawThermal {
    pub time_constant_min: f64,
    /// Highest mean motor power of a joint the robot is rated for, W: the
    /// plausibility limit of every term is evaluated from 0 to it.
    #[serde(default)]
    pub rated_power_w: Option<f64>,
    pub terms: Vec<RawThermalTerm>,
}

/// One coupling term of `thermal.terms`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawThermalTerm {
    pub parameter: String,
    pub joint: usize,
    pub lb_mm: f64,
    pub ub_mm: f64,
    pub ts_per_w: f64,
}

/// One entry of `modal:`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawMode {
    pub direction: String,
    pub frequency_hz: f64,
    pub damping_ratio: f64,
    pub stiffness_n_per_um: f64,
}

/// `datasheet:` — the maker's published figures of the arm.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawDatasheet {
    pub payload_kg: f64,
    pub reach_mm: f64,
    #[serde(default)]
    pub robot_mass_kg: Option<f64>,
}

/// `output:` — number formatting of rewritten targets.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawOutput {
    #[serde(default)]
    pub decimals_mm: Option<usize>,
    #[serde(default)]
    pub decimals_quaternion: Option<usize>,
}

/// `convention: dh | modified_dh`.
#[derive(Debug, Deserialize, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub(crate) enum RawConvention {
    Dh,
    ModifiedDh,
}

/// One joint's DH parameters as written.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawJoint {
    pub a_mm: f64,
    pub alpha_deg: f64,
    pub d_mm: f64,
    pub theta_offset_deg: f64,
}

/// A rigid frame: translation plus exactly one of quaternion / rpy.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawFrame {
    #[serde(default)]
    pub x_mm: f64,
    #[serde(default)]
    pub y_mm: f64,
    #[serde(default)]
    pub z_mm: f64,
    #[serde(default)]
    pub quaternion: Option<[f64; 4]>,
    #[serde(default)]
    pub rpy_deg: Option<[f64; 3]>,
}

/// Mass and centre of mass of one link, in that link's DH frame.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawLink {
    pub mass_kg: f64,
    pub com_mm: [f64; 3],
}

/// Tool (payload) load: mass and centre of gravity in the flange frame.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawLoad {
    pub mass_kg: f64,
    pub cog_mm: [f64; 3],
}

/// Process wrench applied at the TCP.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawWrench {
    pub force_n: [f64; 3],
    #[serde(default)]
    pub moment_nm: [f64; 3],
    pub frame: RawWrenchFrame,
}

/// Frame in which a process wrench is expressed.
#[derive(Debug, Deserialize, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub(crate) enum RawWrenchFrame {
    Tool,
    Base,
}
