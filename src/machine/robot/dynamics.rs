//! Dynamic amplification of a robot (`modal:` section): one
//! single-degree-of-freedom mode per Cartesian direction of the robot base
//! frame (natural frequency, damping ratio, modal stiffness). A harmonic
//! force of amplitude `F` at frequency `f` gives the amplitude
//! `X = F / k · 1 / √((1 − r²)² + (2ζr)²)`, `r = f / f_n` (docs/physics.md).
//! Vibration is reported, never compensated.

use nalgebra::Vector3;

use super::Robot;
use super::raw::RawMode;
use crate::error::Invalid;

/// Relative band around a natural frequency taken as resonance (10 %).
pub const RESONANCE_BAND: f64 = 0.10;
/// Margin of a suggested excitation frequency from every natural
/// frequency (15 %, outside the 10 % band).
pub const SUGGESTION_MARGIN: f64 = 0.15;

/// One mode.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mode {
    /// Natural frequency, Hz.
    pub frequency_hz: f64,
    /// Damping ratio ζ (dimensionless).
    pub damping_ratio: f64,
    /// Modal stiffness, N/mm.
    pub k_n_per_mm: f64,
}

impl Mode {
    /// Dynamic amplification `|H(f)|·k` at excitation frequency `f_hz`.
    pub fn amplification(&self, f_hz: f64) -> f64 {
        let r = f_hz / self.frequency_hz;
        let a = 1.0 - r * r;
        let b = 2.0 * self.damping_ratio * r;
        1.0 / (a * a + b * b).sqrt()
    }

    /// Amplitude (mm) under a harmonic force amplitude `force_n` at `f_hz`.
    pub fn amplitude_mm(&self, force_n: f64, f_hz: f64) -> f64 {
        force_n.abs() / self.k_n_per_mm * self.amplification(f_hz)
    }
}

/// Modes along x, y, z of the robot base frame (`None`: not given).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Modal {
    /// Mode per direction x, y, z.
    pub modes: [Option<Mode>; 3],
}

/// An excitation close to a natural frequency.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Resonance {
    /// Direction `x`, `y` or `z` (robot base frame).
    pub direction: char,
    /// Natural frequency, Hz.
    pub natural_hz: f64,
    /// Excitation frequency, Hz.
    pub excitation_hz: f64,
    /// Nearest excitation frequency at least [`SUGGESTION_MARGIN`] away
    /// from every natural frequency, Hz.
    pub suggested_hz: f64,
}

impl Modal {
    /// Amplitude per direction (mm) of a harmonic force (robot base frame,
    /// N) at `f_hz`.
    pub fn amplitude_mm(&self, force_base_n: &Vector3<f64>, f_hz: f64) -> Vector3<f64> {
        Vector3::from_fn(|i, _| {
            self.modes[i].map_or(0.0, |m| m.amplitude_mm(force_base_n[i], f_hz))
        })
    }

    /// The first mode within [`RESONANCE_BAND`] of `f_hz`, with a suggested
    /// excitation frequency.
    pub fn resonance(&self, f_hz: f64) -> Option<Resonance> {
        let (i, m) = self.modes.iter().enumerate().find_map(|(i, m)| {
            m.filter(|m| (f_hz - m.frequency_hz).abs() <= RESONANCE_BAND * m.frequency_hz)
                .map(|m| (i, m))
        })?;
        let clear = |f: f64| {
            self.modes
                .iter()
                .flatten()
                .all(|m| (f - m.frequency_hz).abs() >= SUGGESTION_MARGIN * m.frequency_hz * 0.999)
        };
        let suggested_hz = self
            .modes
            .iter()
            .flatten()
            .flat_map(|m| {
                [
                    m.frequency_hz * (1.0 - SUGGESTION_MARGIN),
                    m.frequency_hz * (1.0 + SUGGESTION_MARGIN),
                ]
            })
            .filter(|f| *f > 0.0 && clear(*f))
            .min_by(|a, b| (a - f_hz).abs().total_cmp(&(b - f_hz).abs()))
            .unwrap_or(f_hz);
        Some(Resonance {
            direction: ['x', 'y', 'z'].get(i).copied().unwrap_or('?'),
            natural_hz: m.frequency_hz,
            excitation_hz: f_hz,
            suggested_hz,
        })
    }

    pub(crate) fn from_raw(raw: &[RawMode]) -> Result<Self, Invalid> {
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
                frequency_hz: m.frequency_hz,
                damping_ratio: m.damping_ratio,
                k_n_per_mm: m.stiffness_n_per_um * 1000.0,
            });
        }
        Ok(out)
    }
}

impl Robot {
    /// The modal model, if the file has one.
    pub fn modal(&self) -> Option<&Modal> {
        self.d.modal.as_ref()
    }
}
