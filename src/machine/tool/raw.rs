//! Raw (as-written) machine-tool YAML structures. Every struct denies unknown
//! keys; all checking of values happens in [`super::load`].

use std::collections::BTreeMap;

use serde::Deserialize;

/// Top level of a `kind: machine_tool` file.
#[derive(Debug, Deserialize)]
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
    pub output: Option<RawOutput>,
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
#[derive(Debug, Deserialize)]
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
#[derive(Debug, Deserialize)]
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
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawSpindle {
    #[serde(default)]
    pub location_errors: BTreeMap<String, f64>,
}

/// One entry of `tools`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawTool {
    pub length_mm: f64,
}

/// `output:` block.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawOutput {
    #[serde(default)]
    pub decimals_mm: Option<usize>,
    #[serde(default)]
    pub decimals_deg: Option<usize>,
}
