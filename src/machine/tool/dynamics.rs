//! Dynamics of a machine tool (docs/physics.md): the dominant mode per axis
//! direction (natural frequency, damping ratio, modal stiffness) and the
//! single-degree-of-freedom response to a harmonic force. The vibration
//! amplitude is reported, never compensated.

use nalgebra::Vector3;

use super::raw::{RawModal, RawMode};
use crate::error::Invalid;

/// Relative distance of an excitation from a natural frequency that counts
/// as resonant.
pub const RESONANCE_BAND: f64 = 0.10;
/// Ratios of tooth-passing to natural frequency proposed to leave a
/// resonance: below (0.7) and above (1.3) the mode.
pub const SUGGEST_RATIOS: [f64; 2] = [0.7, 1.3];

/// One mode.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mode {
    /// Natural frequency, Hz.
    pub natural_frequency_hz: f64,
    /// Damping ratio ζ.
    pub damping_ratio: f64,
    /// Modal (static) stiffness, N/µm.
    pub stiffness_n_per_um: f64,
}

impl Mode {
    /// Dynamic amplification `1/sqrt((1−r²)² + (2ζr)²)` at frequency `f`, r = f/f_n.
    pub fn amplification(&self, f_hz: f64) -> f64 {
        let r = f_hz / self.natural_frequency_hz;
        let a = 1.0 - r * r;
        let b = 2.0 * self.damping_ratio * r;
        1.0 / (a * a + b * b).sqrt()
    }

    /// Vibration amplitude (mm) under a harmonic force amplitude `f_n` (N) at `f_hz`.
    pub fn amplitude_mm(&self, force_n: f64, f_hz: f64) -> f64 {
        force_n / self.stiffness_n_per_um * 1e-3 * self.amplification(f_hz)
    }
}

/// The dominant modes in X, Y and Z (absent directions do not vibrate).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Modal {
    /// Mode per direction.
    pub modes: [Option<Mode>; 3],
}

impl Modal {
    /// Vibration amplitude per direction (mm) for a complex force amplitude
    /// `(re, im)` (N, workpiece frame) at `f_hz`.
    pub fn amplitude_mm(&self, harmonic_n: &[Vector3<f64>; 2], f_hz: f64) -> Vector3<f64> {
        let mut a = Vector3::zeros();
        if f_hz <= 0.0 {
            return a;
        }
        for (i, m) in self.modes.iter().enumerate() {
            if let Some(m) = m {
                let f = harmonic_n[0][i].hypot(harmonic_n[1][i]);
                a[i] = m.amplitude_mm(f, f_hz);
            }
        }
        a
    }

    /// The first direction (0..3) whose natural frequency lies within
    /// [`RESONANCE_BAND`] of `f_hz`, with the mode.
    pub fn resonance(&self, f_hz: f64) -> Option<(usize, Mode)> {
        self.modes.iter().enumerate().find_map(|(i, m)| {
            let m = (*m)?;
            let fn_ = m.natural_frequency_hz;
            ((f_hz - fn_).abs() <= RESONANCE_BAND * fn_).then_some((i, m))
        })
    }

    /// Spindle speed (1/min) proposed to move the tooth-passing frequency of
    /// `flutes` teeth away from mode `m`: of the speeds that put it at 0.7 or
    /// 1.3 times the natural frequency, the one nearest to `rpm` that is not
    /// itself resonant with another mode (the nearest one otherwise).
    pub fn suggest_rpm(&self, m: &Mode, flutes: u32, rpm: f64) -> f64 {
        let n = f64::from(flutes.max(1));
        let mut best: Option<(bool, f64, f64)> = None;
        for r in SUGGEST_RATIOS {
            let s = r * m.natural_frequency_hz * 60.0 / n;
            let clash = self.resonance(s * n / 60.0).is_some();
            let cand = (clash, (s - rpm).abs(), s);
            best = match best {
                Some(b) if (b.0, b.1) <= (cand.0, cand.1) => Some(b),
                _ => Some(cand),
            };
        }
        best.map_or(rpm, |b| b.2)
    }

    /// Validates the `modal:` block.
    pub(crate) fn from_raw(raw: &RawModal) -> Result<Self, Invalid> {
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
}

fn mode(p: &str, m: &RawMode) -> Result<Mode, Invalid> {
    let check = |key: &str, v: f64, lo: f64, hi: f64| {
        if v.is_finite() && v > lo && v <= hi {
            Ok(v)
        } else {
            Err(Invalid::new(
                format!("{p}.{key}"),
                format!("`{v}` is outside ({lo}, {hi}]"),
            ))
        }
    };
    Ok(Mode {
        natural_frequency_hz: check("natural_frequency_hz", m.natural_frequency_hz, 0.0, 1e5)?,
        damping_ratio: check("damping_ratio", m.damping_ratio, 0.0, 1.0)?,
        stiffness_n_per_um: check("stiffness_n_per_um", m.stiffness_n_per_um, 0.0, 1e5)?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    const AMP_TOL: f64 = 1e-12;

    fn mode60() -> Mode {
        Mode {
            natural_frequency_hz: 60.0,
            damping_ratio: 0.05,
            stiffness_n_per_um: 20.0,
        }
    }

    #[test]
    fn amplification_at_known_ratios() {
        let m = mode60();
        // r = 0: 1 (static); r = 1: 1/(2ζ) = 10; r = 2: 1/sqrt(9 + 0.04).
        assert_abs_diff_eq!(m.amplification(0.0), 1.0, epsilon = AMP_TOL);
        assert_abs_diff_eq!(m.amplification(60.0), 10.0, epsilon = AMP_TOL);
        assert_abs_diff_eq!(
            m.amplification(120.0),
            1.0 / 9.04f64.sqrt(),
            epsilon = AMP_TOL
        );
        // 100 N at resonance on 20 N/µm: 5 µm static × 10 = 0.05 mm.
        assert_abs_diff_eq!(m.amplitude_mm(100.0, 60.0), 0.05, epsilon = AMP_TOL);
    }

    #[test]
    fn amplification_slope_matches_finite_differences() {
        // dA/dr = −A³ · (−2r(1−r²) + 4ζ²r)·… written out: A = D^(−1/2) with
        // D = (1−r²)² + (2ζr)², dD/dr = −4r(1−r²) + 8ζ²r, dA/dr = −D^(−3/2)/2 · dD/dr.
        let m = mode60();
        let r: f64 = 0.8;
        let z = 0.05;
        let d = (1.0 - r * r).powi(2) + (2.0 * z * r).powi(2);
        let dd = -4.0 * r * (1.0 - r * r) + 8.0 * z * z * r;
        let analytic = -0.5 * d.powf(-1.5) * dd / 60.0; // per Hz
        let h = 1e-5;
        let fd = (m.amplification(48.0 + h) - m.amplification(48.0 - h)) / (2.0 * h);
        assert_abs_diff_eq!(fd, analytic, epsilon = 1e-8);
    }

    #[test]
    fn resonance_band_and_suggestion() {
        let modal = Modal {
            modes: [Some(mode60()), None, None],
        };
        assert!(modal.resonance(60.0).is_some());
        assert!(modal.resonance(65.9).is_some());
        assert!(modal.resonance(66.1).is_none());
        // 2 flutes at 1750 rpm = 58.3 Hz: 0.7·60·60/2 = 1260, 1.3·60·60/2 =
        // 2340; 1260 is nearer (490 against 590 rpm).
        assert_abs_diff_eq!(
            modal.suggest_rpm(&mode60(), 2, 1750.0),
            1260.0,
            epsilon = AMP_TOL
        );
    }
}
