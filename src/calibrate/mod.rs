//! Calibration: reading measured observations and identifying model
//! parameters from them.

pub mod observations;
