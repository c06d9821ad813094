//! A process load at the tool: force and moment with the frame they are
//! given in. Machine tools take the force in the workpiece frame; robots a
//! wrench at the tool centre point in the tool or the robot base frame.

use nalgebra::Vector3;

/// Frame a [`Wrench`] is given in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum WrenchFrame {
    /// Workpiece coordinates (a machine tool's process force).
    #[default]
    Workpiece,
    /// The tool (TCP) frame.
    Tool,
    /// The robot base frame.
    Base,
}

/// Force and moment the workpiece exerts on the tool.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Wrench {
    /// Force, N.
    pub force_n: Vector3<f64>,
    /// Moment, N·mm.
    pub moment_nmm: Vector3<f64>,
    /// Frame of force and moment.
    pub frame: WrenchFrame,
}

impl Wrench {
    /// A force without moment in `frame`.
    pub fn force(force_n: Vector3<f64>, frame: WrenchFrame) -> Self {
        Wrench {
            force_n,
            moment_nmm: Vector3::zeros(),
            frame,
        }
    }

    /// True when force and moment are given in the tool (TCP) frame.
    pub fn in_tool_frame(&self) -> bool {
        self.frame == WrenchFrame::Tool
    }
}
