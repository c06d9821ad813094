//! Calibration: reading measured observations and identifying model
//! parameters from them.

pub mod crossval;
pub mod forward;
pub mod frame;
pub mod geometry;
pub mod honesty;
pub mod kinematics;
pub mod lsq;
pub mod observations;
pub mod report;
pub mod screen;
pub mod simulate;
pub mod stats;
pub mod stiffness;
pub mod thermal;
