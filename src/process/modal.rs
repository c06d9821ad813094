//! Vibration under the cutting force, for machine tools and robots alike:
//! one single-degree-of-freedom mode per Cartesian direction (natural
//! frequency, damping ratio, modal stiffness), the amplitude a harmonic
//! force drives at the tooth-passing frequency,
//! `X = F / k · 1 / √((1 − r²)² + (2ζr)²)` with `r = f / f_n`
//! (docs/physics.md), and the resonance check: an excitation within
//! [`RESONANCE_BAND`] of a natural frequency, with a spindle speed that
//! leaves it. Vibration is predicted and reported, never compensated.

use nalgebra::Vector3;

/// Relative distance of an excitation from a natural frequency that counts
/// as resonant (10 %).
pub const RESONANCE_BAND: f64 = 0.10;
/// Ratios of excitation to natural frequency proposed to leave a
/// resonance: below (0.7) and above (1.3) a mode, where the amplification
/// of a lightly damped mode is under 2.
pub const SUGGEST_RATIOS: [f64; 2] = [0.7, 1.3];
/// Slack on the ratio test of a suggested frequency against the mode it is
/// derived from (it lies on the boundary by construction).
const RATIO_SLACK: f64 = 1e-9;

/// One mode.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mode {
    /// Natural frequency, Hz.
    pub natural_frequency_hz: f64,
    /// Damping ratio ζ (dimensionless).
    pub damping_ratio: f64,
    /// Modal (static) stiffness, N/mm.
    pub stiffness_n_per_mm: f64,
}

impl Mode {
    /// Dynamic amplification `1/√((1−r²)² + (2ζr)²)` at `f_hz`,
    /// `r = f/f_n`.
    pub fn amplification(&self, f_hz: f64) -> f64 {
        let r = f_hz / self.natural_frequency_hz;
        let a = 1.0 - r * r;
        let b = 2.0 * self.damping_ratio * r;
        1.0 / (a * a + b * b).sqrt()
    }

    /// Derivative of [`Mode::amplification`] with respect to the
    /// excitation frequency, 1/Hz.
    pub fn amplification_slope(&self, f_hz: f64) -> f64 {
        let fn_ = self.natural_frequency_hz;
        let (r, z) = (f_hz / fn_, self.damping_ratio);
        let d = (1.0 - r * r).powi(2) + (2.0 * z * r).powi(2);
        let dd_dr = -4.0 * r * (1.0 - r * r) + 8.0 * z * z * r;
        -0.5 * d.powf(-1.5) * dd_dr / fn_
    }

    /// Amplitude (mm) under a harmonic force of amplitude `force_n` (N) at
    /// `f_hz`.
    pub fn amplitude_mm(&self, force_n: f64, f_hz: f64) -> f64 {
        force_n.abs() / self.stiffness_n_per_mm * self.amplification(f_hz)
    }
}

/// The modes along x, y and z (a direction without one does not vibrate).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Modal {
    /// Mode per direction x, y, z.
    pub modes: [Option<Mode>; 3],
}

/// An excitation close to a natural frequency.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Resonance {
    /// Direction of the mode: 0, 1, 2 for x, y, z.
    pub axis: usize,
    /// Natural frequency of the mode, Hz.
    pub natural_hz: f64,
    /// Excitation frequency, Hz.
    pub excitation_hz: f64,
}

impl Resonance {
    /// The direction's letter, `X`, `Y` or `Z`.
    pub fn axis_letter(&self) -> char {
        ['X', 'Y', 'Z'].get(self.axis).copied().unwrap_or('?')
    }
}

impl Modal {
    /// Amplitude per direction (mm) under a harmonic force whose amplitude
    /// per direction is `force_n` (N), at `f_hz`. Zero at `f_hz ≤ 0`.
    pub fn amplitude_mm(&self, force_n: &Vector3<f64>, f_hz: f64) -> Vector3<f64> {
        if f_hz <= 0.0 || !f_hz.is_finite() {
            return Vector3::zeros();
        }
        Vector3::from_fn(|i, _| self.modes[i].map_or(0.0, |m| m.amplitude_mm(force_n[i], f_hz)))
    }

    /// The first direction (x, y, z in order) whose natural frequency lies
    /// within [`RESONANCE_BAND`] of `f_hz`.
    pub fn resonance(&self, f_hz: f64) -> Option<Resonance> {
        self.modes.iter().enumerate().find_map(|(axis, m)| {
            let fn_ = m.as_ref()?.natural_frequency_hz;
            ((f_hz - fn_).abs() <= RESONANCE_BAND * fn_).then_some(Resonance {
                axis,
                natural_hz: fn_,
                excitation_hz: f_hz,
            })
        })
    }

    /// An excitation frequency (Hz) that leaves every resonance: of the
    /// frequencies at [`SUGGEST_RATIOS`] times each natural frequency,
    /// those at least that far from every mode (ratio to each mode outside
    /// 0.7–1.3), the one nearest to `f_hz`; the lower one of two equally
    /// near (a slower spindle). There is always one: 0.7 times the lowest
    /// natural frequency is below 0.7 of every mode. Without any mode,
    /// `f_hz` itself.
    pub fn suggested_hz(&self, f_hz: f64) -> f64 {
        let [lo, hi] = SUGGEST_RATIOS;
        let clear = |f: f64| {
            self.modes.iter().flatten().all(|m| {
                let r = f / m.natural_frequency_hz;
                r <= lo + RATIO_SLACK || r >= hi - RATIO_SLACK
            })
        };
        let candidates = self
            .modes
            .iter()
            .flatten()
            .flat_map(|m| SUGGEST_RATIOS.map(|k| k * m.natural_frequency_hz));
        let nearest = |best: Option<f64>, f: f64| match best {
            Some(b) if ((b - f_hz).abs(), b) <= ((f - f_hz).abs(), f) => Some(b),
            _ => Some(f),
        };
        candidates
            .filter(|&f| clear(f))
            .fold(None, nearest)
            .unwrap_or(f_hz)
    }
}

/// Amplitude per direction of a complex harmonic force `(re, im)` (N).
pub fn harmonic_amplitude(harmonic_n: &[Vector3<f64>; 2]) -> Vector3<f64> {
    Vector3::from_fn(|i, _| harmonic_n[0][i].hypot(harmonic_n[1][i]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    /// Agreement of closed forms evaluated two ways (rounding only).
    const AMP_TOL: f64 = 1e-12;
    /// Agreement of a central difference (step 1e-5 Hz) with the slope.
    const SLOPE_TOL: f64 = 1e-8;

    fn mode(f: f64) -> Mode {
        Mode {
            natural_frequency_hz: f,
            damping_ratio: 0.05,
            stiffness_n_per_mm: 20_000.0,
        }
    }

    #[test]
    fn amplification_at_known_ratios() {
        let m = mode(60.0);
        // r = 0: 1 (static); r = 1: 1/(2ζ) = 10; r = 2: 1/√(9 + 0.04).
        assert_abs_diff_eq!(m.amplification(0.0), 1.0, epsilon = AMP_TOL);
        assert_abs_diff_eq!(m.amplification(60.0), 10.0, epsilon = AMP_TOL);
        assert_abs_diff_eq!(
            m.amplification(120.0),
            1.0 / 9.04f64.sqrt(),
            epsilon = AMP_TOL
        );
        // 100 N at resonance on 20 N/µm: 5 µm static × 10 = 0.05 mm.
        assert_abs_diff_eq!(m.amplitude_mm(100.0, 60.0), 0.05, epsilon = AMP_TOL);
        assert_abs_diff_eq!(m.amplitude_mm(-100.0, 60.0), 0.05, epsilon = AMP_TOL);
    }

    #[test]
    fn amplification_slope_matches_finite_differences() {
        let m = mode(60.0);
        let h = 1e-5;
        for f in [12.0, 48.0, 59.0, 61.0, 90.0] {
            let fd = (m.amplification(f + h) - m.amplification(f - h)) / (2.0 * h);
            assert_abs_diff_eq!(fd, m.amplification_slope(f), epsilon = SLOPE_TOL);
        }
    }

    #[test]
    fn resonance_band_is_ten_percent_and_modes_are_searched_x_y_z() {
        let modal = Modal {
            modes: [Some(mode(8.5)), Some(mode(7.5)), Some(mode(9.5))],
        };
        assert_eq!(modal.resonance(8.5).map(|r| r.axis), Some(0));
        // 9.2 Hz: 8.2 % above x and 3.2 % below z; x comes first.
        assert_eq!(modal.resonance(9.2).map(|r| r.axis), Some(0));
        // 10.3 Hz: 21 % above x, 8.4 % above z.
        assert_eq!(modal.resonance(10.3).map(|r| r.axis_letter()), Some('Z'));
        assert!(modal.resonance(100.0).is_none());
        let one = Modal {
            modes: [Some(mode(60.0)), None, None],
        };
        assert!(one.resonance(65.9).is_some());
        assert!(one.resonance(66.1).is_none());
    }

    #[test]
    fn suggested_frequency_is_clear_of_every_mode() {
        // One mode at 60 Hz: 42 and 78 Hz; from 58.3 Hz the nearer is 42;
        // from 60 Hz both are 18 Hz away and the lower one is taken.
        let one = Modal {
            modes: [Some(mode(60.0)), None, None],
        };
        assert_abs_diff_eq!(
            one.suggested_hz(1750.0 * 2.0 / 60.0),
            42.0,
            epsilon = AMP_TOL
        );
        assert_abs_diff_eq!(one.suggested_hz(60.0), 42.0, epsilon = AMP_TOL);
        // Modes 8.5, 7.5, 9.5 Hz. Candidates 5.95, 11.05 (x), 5.25, 9.75
        // (y), 6.65, 12.35 (z). 5.95 is 0.79 of y, 11.05 1.16 of z, 9.75
        // and 6.65 lie between modes: only 5.25 and 12.35 are clear, and
        // 5.25 is the nearer to 8.5.
        let three = Modal {
            modes: [Some(mode(8.5)), Some(mode(7.5)), Some(mode(9.5))],
        };
        assert_abs_diff_eq!(three.suggested_hz(8.5), 5.25, epsilon = AMP_TOL);
        // Modes 10 and 14 Hz: candidates 7, 13 (x), 9.8, 18.2 (y); 13 and
        // 9.8 lie between them; 7 and 18.2 are clear; from 12 Hz, 7 (5 Hz
        // away) beats 18.2 (6.2 Hz).
        let two = Modal {
            modes: [Some(mode(10.0)), Some(mode(14.0)), None],
        };
        assert_abs_diff_eq!(two.suggested_hz(12.0), 7.0, epsilon = AMP_TOL);
    }

    #[test]
    fn amplitude_per_direction_and_of_a_complex_force() {
        let modal = Modal {
            modes: [Some(mode(60.0)), None, Some(mode(120.0))],
        };
        let f = harmonic_amplitude(&[Vector3::new(60.0, 5.0, 0.0), Vector3::new(80.0, 0.0, 10.0)]);
        assert_abs_diff_eq!(f, Vector3::new(100.0, 5.0, 10.0), epsilon = AMP_TOL);
        let a = modal.amplitude_mm(&f, 60.0);
        // x at resonance: 100/20000 × 10; y has no mode; z at r = 0.5:
        // 10/20000 / √(0.5625 + 0.0025).
        assert_abs_diff_eq!(a.x, 0.05, epsilon = AMP_TOL);
        assert_abs_diff_eq!(a.y, 0.0, epsilon = AMP_TOL);
        assert_abs_diff_eq!(a.z, 0.0005 / 0.565f64.sqrt(), epsilon = AMP_TOL);
        assert_eq!(modal.amplitude_mm(&f, 0.0), Vector3::zeros());
    }
}
