//! Machine-tool geometric calibration (placeholder while in progress).
use super::observations::Observations;
use super::report::Calibration;
use super::stiffness::Options;
use crate::error::{Error, Result};
/// Identifies component error tables and squareness.
pub fn calibrate_geometry(
    _t: &str,
    f: &str,
    _o: &Observations,
    _of: &str,
    _p: &Options,
) -> Result<Calibration> {
    Err(Error::Usage(format!("{f}: not yet")))
}
