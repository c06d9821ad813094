//! Simulated measurements: fills the measured columns of a poses file from
//! a "true" machine file ([`super::forward::predict`]) plus seeded Gaussian
//! measurement noise — how the test data of calibration and diagnosis are
//! made.
//!
//! Noise model (laser-tracker style, MODELS.md §5: ≈ 15 µm + 6 µm/m): every
//! coordinate of every row gets an independent normal error with standard
//! deviation `noise_um + noise_um_per_m · ‖p‖` (µm), `‖p‖` the distance of
//! the attained point from the origin of the measuring frame in metres.
//! The same seed gives the same numbers on every platform
//! ([`super::stats::SplitMix64`]).

use crate::error::Result;
use crate::machine::Machine;

use super::forward::{check_kind, predict};
use super::observations::{MeasuredKind, Observations};
use super::stats::SplitMix64;

/// Measurement noise of a simulation.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Noise {
    /// Standard deviation per coordinate, µm.
    pub um: f64,
    /// Distance-proportional part of the standard deviation, µm per metre.
    pub um_per_m: f64,
    /// Seed of the random numbers.
    pub seed: u64,
}

/// Returns `poses` with every row's measured triple replaced by the model's
/// prediction for `machine` plus noise. The measured kind of `poses` is kept
/// (position or deviation; a poses file without measured columns is read as
/// position). `file` names the poses file in errors.
pub fn simulate(
    machine: &Machine,
    poses: &Observations,
    file: &str,
    noise: &Noise,
) -> Result<Observations> {
    check_kind(machine, poses, file)?;
    let mut out = poses.clone();
    let mut rng = SplitMix64::new(noise.seed);
    for row in &mut out.rows {
        let p = predict(machine, row, file)?;
        let sd_mm = (noise.um + noise.um_per_m * p.attained_mm.norm() / 1000.0) / 1000.0;
        let mut v = p.measured(poses.measured);
        for c in v.iter_mut() {
            *c += rng.gaussian(0.0, sd_mm);
        }
        row.measured_mm = v;
    }
    if poses.measured == MeasuredKind::Position {
        tracing::debug!("simulated {} rows (positions)", out.rows.len());
    } else {
        tracing::debug!("simulated {} rows (deviations)", out.rows.len());
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calibrate::observations::parse_observations;
    use approx::assert_abs_diff_eq;

    const POS_TOL_MM: f64 = 1e-6;

    fn machine() -> Machine {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/machines/abb-irb1600.yaml");
        Machine::load(std::path::Path::new(path)).expect("machine file loads")
    }

    /// Without noise and without load, the deviation of the nominal pose at
    /// all joints zero equals the actual-minus-nominal flange of the file plus
    /// the gravity sag; without noise two seeds give the same data, with
    /// noise the same seed gives the same data and another seed other data.
    #[test]
    fn noise_free_is_seed_independent_and_seeded_noise_reproducible() {
        let m = machine();
        let poses = parse_observations(
            "q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,dx_mm,dy_mm,dz_mm\n0,0,0,0,0,0,0,0,0\n10,20,-10,0,30,0,0,0,0\n",
            "p.csv",
        )
        .unwrap();
        let a = simulate(
            &m,
            &poses,
            "p",
            &Noise {
                seed: 1,
                ..Noise::default()
            },
        )
        .unwrap();
        let b = simulate(
            &m,
            &poses,
            "p",
            &Noise {
                seed: 2,
                ..Noise::default()
            },
        )
        .unwrap();
        assert_abs_diff_eq!(
            a.rows[1].measured_mm,
            b.rows[1].measured_mm,
            epsilon = POS_TOL_MM
        );
        let n = Noise {
            um: 15.0,
            um_per_m: 6.0,
            seed: 7,
        };
        let c = simulate(&m, &poses, "p", &n).unwrap();
        let d = simulate(&m, &poses, "p", &n).unwrap();
        assert_eq!(c, d);
        let e = simulate(&m, &poses, "p", &Noise { seed: 8, ..n }).unwrap();
        assert_ne!(c.rows[0].measured_mm, e.rows[0].measured_mm);
        // 15 µm + 6 µm/m at ≈1.4 m: a single draw beyond 10 sd (0.25 mm) would be absurd.
        assert_abs_diff_eq!(c.rows[0].measured_mm, a.rows[0].measured_mm, epsilon = 0.25);
    }
}
