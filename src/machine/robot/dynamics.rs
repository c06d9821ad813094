//! Dynamics of a robot: the `modal:` list (one mode per Cartesian
//! direction of the robot base frame, keyed by `direction`) validated into
//! the shared modal model of [`crate::process::modal`]. Vibration is
//! reported, never compensated.

use super::Robot;
use super::raw::RawMode;
use crate::error::Invalid;
pub use crate::process::modal::{Modal, Mode, Resonance};

/// Validates the `modal:` list.
pub(crate) fn modal_from_raw(raw: &[RawMode]) -> Result<Modal, Invalid> {
    let mut out = Modal::default();
    for (i, m) in raw.iter().enumerate() {
        let p = format!("modal[{i}]");
        let k = match m.direction.trim().to_ascii_lowercase().as_str() {
            "x" => 0,
            "y" => 1,
            "z" => 2,
            _ => {
                return Err(Invalid::new(
                    format!("{p}.direction"),
                    format!("`{}` is not x, y or z", m.direction),
                ));
            }
        };
        for (key, v) in [
            ("frequency_hz", m.frequency_hz),
            ("stiffness_n_per_um", m.stiffness_n_per_um),
        ] {
            if !v.is_finite() || v <= 0.0 {
                return Err(Invalid::new(
                    format!("{p}.{key}"),
                    format!("`{v}` must be a positive number"),
                ));
            }
        }
        if !m.damping_ratio.is_finite() || m.damping_ratio <= 0.0 || m.damping_ratio >= 1.0 {
            return Err(Invalid::new(
                format!("{p}.damping_ratio"),
                format!("`{}` must lie in (0, 1)", m.damping_ratio),
            ));
        }
        if out.modes[k].is_some() {
            return Err(Invalid::new(
                format!("{p}.direction"),
                format!("direction `{}` given twice", m.direction),
            ));
        }
        out.modes[k] = Some(Mode {
            natural_frequency_hz: m.frequency_hz,
            damping_ratio: m.damping_ratio,
            stiffness_n_per_mm: m.stiffness_n_per_um * 1000.0,
        });
    }
    Ok(out)
}

impl Robot {
    /// The modal model, if the file has one.
    pub fn modal(&self) -> Option<&Modal> {
        self.d.modal.as_ref()
    }
}
