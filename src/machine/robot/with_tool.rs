//! A copy of a [`Robot`] with another tool mounted: the TCP and the tool
//! load are properties of the move (RAPID `tooldata`), not of the robot
//! file, so the RAPID pipeline builds one such view per distinct tool.

use nalgebra::Isometry3;

use super::{PointMass, Robot};

impl Robot {
    /// The same robot with the TCP `flange_to_tool` (tool frame in the flange
    /// frame) and the tool load `load` (centre of gravity in the flange
    /// frame; `None` = no load). Kinematics, stiffness, links, limits and
    /// base are unchanged.
    pub fn with_tool(&self, flange_to_tool: Isometry3<f64>, load: Option<PointMass>) -> Robot {
        let mut r = self.clone();
        r.d.tool = flange_to_tool;
        r.d.tool_inv = flange_to_tool.inverse();
        r.d.tool_load = load;
        r
    }
}
