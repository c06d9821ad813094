//! Raw (serde) form of a robot machine file: the YAML exactly as written,
//! with `deny_unknown_fields` everywhere. Validation into the immutable
//! [`super::Robot`] happens in `mod.rs`.

use serde::Deserialize;

/// Top level of a `kind: robot` machine file.
#[derive(Debug, Deserialize)]
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
    pub gravity_m_per_s2: [f64; 3],
    pub links: Vec<RawLink>,
    #[serde(default)]
    pub tool_load: Option<RawLoad>,
    pub k_nm_per_rad: Vec<f64>,
    #[serde(default)]
    pub process_wrench: Option<RawWrench>,
}

/// `convention: dh | modified_dh`.
#[derive(Debug, Deserialize, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub(crate) enum RawConvention {
    Dh,
    ModifiedDh,
}

/// One joint's DH parameters as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawJoint {
    pub a_mm: f64,
    pub alpha_deg: f64,
    pub d_mm: f64,
    pub theta_offset_deg: f64,
}

/// A rigid frame: translation plus exactly one of quaternion / rpy.
#[derive(Debug, Deserialize)]
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
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawLink {
    pub mass_kg: f64,
    pub com_mm: [f64; 3],
}

/// Tool (payload) load: mass and centre of gravity in the flange frame.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawLoad {
    pub mass_kg: f64,
    pub cog_mm: [f64; 3],
}

/// Process wrench applied at the TCP.
#[derive(Debug, Deserialize)]
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
