//! Dynamics of a robot: the `modal:` list (one mode per Cartesian
//! direction of the robot base frame, keyed by `direction`) validated into
//! the shared modal model of [`crate::process::modal`]. Vibration is
//! reported, never compensated.

use super::Robot;
use super::raw::RawMode;
use crate::error::Invalid;
pub use crate::process::modal::{Modal, Mode, Resonance};

/// Validates the `modal:` list.
/// Lowest natural frequency of any mode, Hz.
pub const MIN_FREQUENCY_HZ: f64 = 1e-3;
/// Lowest modal stiffness, N/µm (1 N/mm).
pub const MIN_STIFFNESS_N_PER_UM: f64 = 1e-3;
/// Lowest damping ratio (an amplification of 5000 at resonance).
pub const MIN_DAMPING: f64 = 1e-4;

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
        // Hard limits, which keep the amplitude `F / k / (2ζ)` finite; the
        // plausible ranges are narrower ([`super::plausible`]).
        for (key, v, lo, hi) in [
            ("frequency_hz", m.frequency_hz, MIN_FREQUENCY_HZ, 1e5),
            (
                "stiffness_n_per_um",
                m.stiffness_n_per_um,
                MIN_STIFFNESS_N_PER_UM,
                1e5,
            ),
            ("damping_ratio", m.damping_ratio, MIN_DAMPING, 1.0),
        ] {
            if !v.is_finite() || v < lo || v >= hi {
                return Err(Invalid::new(
                    format!("{p}.{key}"),
                    format!(
                        "`{}` is outside {}..{} (below {} no model is meaningful)",
                        crate::error::show_number(v),
                        crate::error::show_number(lo),
                        crate::error::show_number(hi),
                        crate::error::show_number(lo)
                    ),
                ));
            }
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
