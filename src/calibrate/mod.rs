//! Calibration: reading measured observations and identifying model
//! parameters from them.

pub mod forward;
pub mod lsq;
pub mod observations;
pub mod stats;
