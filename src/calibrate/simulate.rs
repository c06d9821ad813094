//! Simulated measurements: fills the measured columns of a poses file from
//! a "true" machine file ([`super::forward::predict`]) plus seeded Gaussian
//! measurement noise — how the test data of calibration and diagnosis are
//! made.
//!
//! Noise model (laser-tracker style, docs/physics.md: ≈ 15 µm + 6 µm/m): every
//! coordinate of every row gets an independent normal error with standard
//! deviation `noise_um + noise_um_per_m · ‖p‖` (µm), `‖p‖` the distance of
//! the attained point from the origin of the measuring frame in metres.
//! The same seed gives the same numbers on every platform
//! ([`super::stats::SplitMix64`]).

use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};

use crate::error::{Error, Result};
use crate::machine::Machine;

use super::forward::{Switches, check_kind, predict_with};
use super::observations::{MeasuredKind, MeasurementFrame, Observations};
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
    simulate_with(
        machine,
        poses,
        file,
        &Simulation {
            noise: *noise,
            ..Simulation::default()
        },
    )
}

/// The frame simulated positions are written in.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum OutputFrame {
    /// The machine's reference frame (robot base, workpiece frame).
    #[default]
    Reference,
    /// Robot: the world frame, `base · p`.
    World,
    /// An instrument whose pose in the reference frame is `F`: `F⁻¹ · p`.
    Instrument(Isometry3<f64>),
}

/// Everything a simulation is asked for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Simulation {
    /// Position noise.
    pub noise: Noise,
    /// Orientation noise: standard deviation of a small rotation about each
    /// axis, mrad (only with `orientation`).
    pub noise_mrad: f64,
    /// Frame of the written positions.
    pub frame: OutputFrame,
    /// Also write the measured orientation (`qw, qx, qy, qz`, robots).
    pub orientation: bool,
    /// The effects simulated.
    pub effects: Switches,
}

impl Default for Simulation {
    fn default() -> Self {
        Simulation {
            noise: Noise::default(),
            noise_mrad: 0.0,
            frame: OutputFrame::Reference,
            orientation: false,
            effects: Switches::default(),
        }
    }
}

/// [`simulate`] with a frame, orientations and a choice of effects. The
/// noise is added in the output frame (an instrument's noise grows with
/// the distance from the instrument).
pub fn simulate_with(
    machine: &Machine,
    poses: &Observations,
    file: &str,
    sim: &Simulation,
) -> Result<Observations> {
    check_kind(machine, poses, file)?;
    let noise = &sim.noise;
    let to_out = match (sim.frame, machine) {
        (OutputFrame::Reference, _) => Isometry3::identity(),
        (OutputFrame::World, Machine::Robot(r)) => *r.base(),
        (OutputFrame::World, Machine::Tool(_)) => {
            return Err(Error::Usage(
                "--frame world is for robots (the world frame of `base`); a machine tool's \
                 positions are in its workpiece frame"
                    .into(),
            ));
        }
        (OutputFrame::Instrument(f), _) => f.inverse(),
    };
    if sim.frame != OutputFrame::Reference && poses.measured == MeasuredKind::Deviation {
        return Err(Error::Usage(format!(
            "{file}: deviations (dx_mm …) are always in the reference frame; give a poses \
             file with x_mm, y_mm, z_mm (or none) to simulate positions in another frame"
        )));
    }
    if sim.orientation && !matches!(machine, Machine::Robot(_)) {
        return Err(Error::Usage(
            "--orientation is for robots (the orientation of the tool frame)".into(),
        ));
    }
    let mut out = poses.clone();
    out.frame = match sim.frame {
        OutputFrame::Reference => MeasurementFrame::Reference,
        OutputFrame::World => MeasurementFrame::World,
        OutputFrame::Instrument(_) => MeasurementFrame::Instrument,
    };
    let mut rng = SplitMix64::new(noise.seed);
    for row in &mut out.rows {
        let p = predict_with(machine, row, file, sim.effects)?;
        let mut v = p.measured(poses.measured);
        if poses.measured == MeasuredKind::Position {
            v = (to_out * Point3::from(v)).coords;
        }
        let dist_mm = if sim.frame == OutputFrame::Reference {
            p.attained_mm.norm()
        } else {
            v.norm()
        };
        let sd_mm = (noise.um + noise.um_per_m * dist_mm / 1000.0) / 1000.0;
        for c in v.iter_mut() {
            *c += rng.gaussian(0.0, sd_mm);
        }
        row.measured_mm = v;
        row.orientation = match (sim.orientation, p.attained_rot) {
            (true, Some(q)) => {
                let e = Vector3::new(
                    rng.gaussian(0.0, sim.noise_mrad),
                    rng.gaussian(0.0, sim.noise_mrad),
                    rng.gaussian(0.0, sim.noise_mrad),
                ) * 1e-3;
                Some(UnitQuaternion::from_scaled_axis(e) * to_out.rotation * q)
            }
            _ => None,
        };
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
