//! Raw (as-written) machine-tool YAML structures. Every struct denies unknown
//! keys; all checking of values happens in [`super::load`].

use std::collections::BTreeMap;

use serde::Deserialize;

/// Top level of a `kind: machine_tool` file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawMachineTool {
    pub kind: String,
    pub name: String,
    pub axes: Vec<RawAxis>,
    #[serde(default)]
    pub spindle: Option<RawSpindle>,
    #[serde(default)]
    pub tools: BTreeMap<u32, RawTool>,
    #[serde(default)]
    pub work_offsets_mm: BTreeMap<String, [f64; 3]>,
    #[serde(default)]
    pub reference_points_mm: BTreeMap<String, [f64; 3]>,
    #[serde(default)]
    pub units_default: Option<RawUnits>,
    #[serde(default)]
    pub integer_words: Option<RawIntegerWords>,
    #[serde(default)]
    pub corner_words: Option<RawCornerWords>,
    #[serde(default)]
    pub output: Option<RawOutput>,
    #[serde(default)]
    pub compensation: Option<RawCompensation>,
    #[serde(default)]
    pub process_force: Option<RawProcessForce>,
    #[serde(default)]
    pub stiffness: Option<RawStiffness>,
    #[serde(default)]
    pub thermal: Option<RawThermal>,
    #[serde(default)]
    pub modal: Option<RawModal>,
    /// `status` and `calibrations`, read by [`crate::machine::status`].
    #[serde(default, rename = "status")]
    pub _status: Option<serde::de::IgnoredAny>,
    #[serde(default, rename = "calibrations")]
    pub _calibrations: Option<serde::de::IgnoredAny>,
    /// Limits of the acceptance tests, read by `crate::verify::limits`.
    #[serde(default, rename = "acceptance")]
    pub _acceptance: Option<serde::de::IgnoredAny>,
    /// Parameter covariance per calibrated section, read by
    /// `crate::predict::uncertainty::read_covariance`.
    #[serde(default, rename = "covariance")]
    pub _covariance: Option<serde::de::IgnoredAny>,
    /// Pose of the measuring instrument in the workpiece frame (written by
    /// calibration from instrument-frame observations; not part of the model).
    #[serde(default)]
    pub measurement_frame: Option<RawMeasurementFrame>,
    /// `plausibility:` — key paths whose plausibility ranges are not
    /// applied ([`crate::machine::plausibility`]).
    #[serde(default)]
    pub plausibility: Option<crate::machine::plausibility::Overrides>,
}

/// `measurement_frame:` — translation and roll-pitch-yaw.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawMeasurementFrame {
    #[serde(default)]
    pub x_mm: f64,
    #[serde(default)]
    pub y_mm: f64,
    #[serde(default)]
    pub z_mm: f64,
    #[serde(default)]
    pub rpy_deg: [f64; 3],
}

/// The control's unit for programs without G20/G21.
#[derive(Debug, Deserialize, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub(crate) enum RawUnits {
    Mm,
    Inch,
}

/// `integer_words`: `units` or `increments`.
#[derive(Debug, Deserialize, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub(crate) enum RawIntegerWords {
    Units,
    Increments,
}

/// `corner_words`: `comma` (the control reads `,C`/`,R`).
#[derive(Debug, Deserialize, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub(crate) enum RawCornerWords {
    Comma,
}

/// Linear or rotary axis.
#[derive(Debug, Deserialize, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub(crate) enum RawAxisType {
    Linear,
    Rotary,
}

/// Which side of the machine frame carries the axis.
#[derive(Debug, Deserialize, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub(crate) enum RawSide {
    Workpiece,
    Tool,
}

/// One entry of `axes`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawAxis {
    pub name: String,
    #[serde(rename = "type")]
    pub axis_type: RawAxisType,
    pub side: RawSide,
    #[serde(default)]
    pub travel_mm: Option<[f64; 2]>,
    #[serde(default)]
    pub travel_deg: Option<[f64; 2]>,
    #[serde(default)]
    pub rapid_mm_per_min: Option<f64>,
    #[serde(default)]
    pub rapid_deg_per_min: Option<f64>,
    #[serde(default)]
    pub pivot_mm: Option<[f64; 3]>,
    #[serde(default)]
    pub location_errors: BTreeMap<String, f64>,
    #[serde(default)]
    pub component_errors: BTreeMap<String, RawTable>,
}

/// A bidirectional error table over the axis position.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawTable {
    #[serde(default)]
    pub positions_mm: Option<Vec<f64>>,
    #[serde(default)]
    pub positions_deg: Option<Vec<f64>>,
    pub forward: Vec<f64>,
    #[serde(default)]
    pub reverse: Option<Vec<f64>>,
}

/// `spindle:` block.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawSpindle {
    #[serde(default)]
    pub location_errors: BTreeMap<String, f64>,
}

/// One entry of `tools`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawTool {
    pub length_mm: f64,
}

/// `output:` block.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawOutput {
    #[serde(default)]
    pub decimals_mm: Option<usize>,
    #[serde(default)]
    pub decimals_deg: Option<usize>,
    /// `output.expand_deep_holes_to_moves`: as `--expand-cycles`.
    #[serde(default)]
    pub expand_deep_holes_to_moves: Option<bool>,
}

/// `compensation:` block.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawCompensation {
    #[serde(default)]
    pub tolerance_mm: Option<f64>,
}

/// `process_force:` block.
#[derive(Debug, Clone, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawProcessForce {
    pub model: String,
    #[serde(default)]
    pub force_n: Option<[f64; 3]>,
    #[serde(default)]
    pub frame: Option<String>,
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
    pub flutes: Option<u32>,
    #[serde(default)]
    pub axial_depth_mm: Option<f64>,
    #[serde(default)]
    pub radial_width_mm: Option<f64>,
    #[serde(default)]
    pub thrust_coefficient_n_per_mm2: Option<f64>,
    #[serde(default)]
    pub drill_diameter_mm: Option<f64>,
}

/// A stiffness value: one number for the whole workspace, or a grid
/// `[iz][iy][ix]` over `stiffness.grid_mm`.
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
pub(crate) enum RawGridValues {
    Uniform(f64),
    Grid(Vec<Vec<Vec<f64>>>),
}

/// `stiffness.grid_mm`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawGrid {
    pub x: Vec<f64>,
    pub y: Vec<f64>,
    pub z: Vec<f64>,
}

/// `stiffness.k_n_per_um`: per direction and load sign.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawStiffnessValues {
    pub x_pos: RawGridValues,
    pub x_neg: RawGridValues,
    pub y_pos: RawGridValues,
    pub y_neg: RawGridValues,
    pub z_pos: RawGridValues,
    pub z_neg: RawGridValues,
}

/// `stiffness:` block.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawStiffness {
    #[serde(default)]
    pub grid_mm: Option<RawGrid>,
    pub k_n_per_um: RawStiffnessValues,
}

/// `thermal.spindle`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawSpindleThermal {
    #[serde(default)]
    pub idle_w_per_rpm: f64,
    pub growth_um_per_kw: f64,
    pub time_constant_min: f64,
}

/// One entry of `thermal.axes`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawAxisThermal {
    pub scale_ppm_per_kw: f64,
    pub time_constant_min: f64,
    #[serde(default)]
    pub friction_n: f64,
    /// Absent: the scale grows from machine zero.
    #[serde(default)]
    pub scale_origin_mm: Option<f64>,
}

/// `thermal:` block.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawThermal {
    #[serde(default)]
    pub spindle: Option<RawSpindleThermal>,
    #[serde(default)]
    pub axes: BTreeMap<String, RawAxisThermal>,
}

/// One mode of `modal:`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawMode {
    pub natural_frequency_hz: f64,
    pub damping_ratio: f64,
    pub stiffness_n_per_um: f64,
}

/// `modal:` block: the dominant mode per direction.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawModal {
    #[serde(default)]
    pub x: Option<RawMode>,
    #[serde(default)]
    pub y: Option<RawMode>,
    #[serde(default)]
    pub z: Option<RawMode>,
}
