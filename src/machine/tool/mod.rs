//! Machine-tool model (placeholder with the final API; the geometric model
//! replaces the bodies).

use crate::error::Result;
use crate::machine::{AxisVec, DirVec, TipPose};
use nalgebra::Vector3;

/// A validated machine tool.
#[derive(Debug, Clone)]
pub struct MachineTool {}

impl MachineTool {
    /// Parses and validates machine-tool YAML; `file` names it in errors.
    pub fn from_yaml_str(_text: &str, _file: &str) -> Result<Self> {
        Ok(MachineTool {})
    }

    /// Display name of the machine.
    pub fn name(&self) -> &str {
        "placeholder"
    }

    /// Whether the machine has the axis in `slot` (0..6 = X Y Z A B C).
    pub fn has_axis(&self, slot: usize) -> bool {
        slot < 3
    }

    /// Travel limits of the axis in `slot` (mm or deg), `None` if absent.
    pub fn travel(&self, slot: usize) -> Option<(f64, f64)> {
        self.has_axis(slot).then_some((-1e9, 1e9))
    }

    /// Rapid traverse rate of the axis in `slot` (mm/min or deg/min).
    pub fn rapid_per_min(&self, _slot: usize) -> f64 {
        10_000.0
    }

    /// Tool length for offset number `h` from the tool table, mm.
    pub fn tool_length_mm(&self, _h: u32) -> Option<f64> {
        None
    }

    /// Work offset `G54`…`G59` (machine coordinates of the work zero), mm.
    pub fn work_offset_mm(&self, _code: &str) -> Option<[f64; 3]> {
        None
    }

    /// Output decimals for mm programs, if the machine file fixes them.
    pub fn output_decimals(&self) -> Option<usize> {
        None
    }

    /// True when every geometric error is zero.
    pub fn is_error_free(&self) -> bool {
        true
    }

    /// Nominal tool tip pose in the workpiece frame for commanded axis values
    /// (machine coordinates) and tool length.
    pub fn nominal(&self, cmd: &AxisVec, _tool_mm: f64) -> TipPose {
        TipPose {
            pos: Vector3::new(cmd[0], cmd[1], cmd[2]),
            dir: Vector3::z(),
        }
    }

    /// Predicted (attained) tool tip pose including the geometric errors,
    /// with component errors looked up for the given direction of motion.
    pub fn geometric(&self, cmd: &AxisVec, _dirs: &DirVec, tool_mm: f64) -> TipPose {
        self.nominal(cmd, tool_mm)
    }

    /// Bit `i` set when axis slot `i` of `cmd` lies outside its component
    /// error tables (the lookup is clamped at the table ends).
    pub fn clamped_axes(&self, _cmd: &AxisVec) -> u8 {
        0
    }
}
