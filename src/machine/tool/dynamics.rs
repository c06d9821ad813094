//! Dynamics of a machine tool: the `modal:` block (the dominant mode per
//! axis direction, keyed `x`, `y`, `z`) validated into the shared modal
//! model of [`crate::process::modal`]. The vibration amplitude is reported,
//! never compensated.

use super::raw::{RawModal, RawMode};
use crate::error::Invalid;
pub use crate::process::modal::{Modal, Mode};

/// Validates the `modal:` block.
pub(crate) fn modal_from_raw(raw: &RawModal) -> Result<Modal, Invalid> {
    let mut modes = [None; 3];
    for (i, (name, m)) in [("x", &raw.x), ("y", &raw.y), ("z", &raw.z)]
        .into_iter()
        .enumerate()
    {
        if let (Some(m), Some(slot)) = (m, modes.get_mut(i)) {
            *slot = Some(mode(&format!("modal.{name}"), m)?);
        }
    }
    Ok(Modal { modes })
}

fn mode(p: &str, m: &RawMode) -> Result<Mode, Invalid> {
    // Hard limits, which keep the amplitude `F / k / (2ζ)` finite; the
    // plausible ranges are narrower ([`super::plausible`]).
    let check = |key: &str, v: f64, lo: f64, hi: f64| {
        if v.is_finite() && v >= lo && v <= hi {
            Ok(v)
        } else {
            Err(Invalid::new(
                format!("{p}.{key}"),
                format!(
                    "`{}` is outside {}..{} (below {} no model is meaningful)",
                    crate::error::show_number(v),
                    crate::error::show_number(lo),
                    crate::error::show_number(hi),
                    crate::error::show_number(lo)
                ),
            ))
        }
    };
    use crate::machine::robot::dynamics::{MIN_DAMPING, MIN_FREQUENCY_HZ, MIN_STIFFNESS_N_PER_UM};
    Ok(Mode {
        natural_frequency_hz: check(
            "natural_frequency_hz",
            m.natural_frequency_hz,
            MIN_FREQUENCY_HZ,
            1e5,
        )?,
        damping_ratio: check("damping_ratio", m.damping_ratio, MIN_DAMPING, 1.0)?,
        stiffness_n_per_mm: check(
            "stiffness_n_per_um",
            m.stiffness_n_per_um,
            MIN_STIFFNESS_N_PER_UM,
            1e5,
        )? * 1e3,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    #[test]
    fn modal_block_is_validated_with_key_paths_and_stiffness_in_n_per_mm() {
        let mode = |damping_ratio: f64| RawMode {
            natural_frequency_hz: 60.0,
            damping_ratio,
            stiffness_n_per_um: 20.0,
        };
        let raw = RawModal {
            x: Some(mode(0.05)),
            y: None,
            z: None,
        };
        let m = modal_from_raw(&raw).expect("valid");
        let x = m.modes[0].expect("x");
        assert_abs_diff_eq!(x.stiffness_n_per_mm, 20_000.0);
        assert!(m.modes[1].is_none() && m.modes[2].is_none());
        let bad = RawModal {
            x: None,
            y: None,
            z: Some(mode(1.5)),
        };
        let e = modal_from_raw(&bad).expect_err("damping above 1");
        assert!(e.to_string().contains("modal.z.damping_ratio"), "{e}");
    }
}
