//! `postproc simulate` (measured columns from a "true" machine file plus
//! noise) and `postproc calibrate` (identify parameters, write a calibrated
//! machine file, print the result table).

use std::io::Write;
use std::path::{Path, PathBuf};

use clap::{Args, ValueEnum};

use crate::calibrate::geometry::calibrate_geometry;
use crate::calibrate::kinematics::calibrate_kinematics;
use crate::calibrate::observations::{load_observations, load_poses, write_observations};
use crate::calibrate::simulate::{Noise, simulate};
use crate::calibrate::stiffness::{Options, calibrate_stiffness};
use crate::calibrate::thermal::calibrate_thermal;
use crate::error::{Error, Result};
use crate::machine::Machine;

use super::gcode::write_atomically;
use super::usage;

/// `postproc simulate`.
#[derive(Debug, Args)]
pub struct SimulateArgs {
    /// The "true" machine file (or the name of a bundled one).
    #[arg(short, long)]
    pub machine: String,
    /// Poses file (observation CSV; measured columns may be absent).
    #[arg(long)]
    pub observations: PathBuf,
    /// Measurement noise, standard deviation per coordinate, µm.
    #[arg(long, default_value_t = 0.0)]
    pub noise_um: f64,
    /// Distance-proportional noise, µm per metre from the frame origin.
    #[arg(long, default_value_t = 0.0)]
    pub noise_um_per_m: f64,
    /// Seed of the noise (same seed, same data).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output observation file (`-` for standard output).
    #[arg(short, long)]
    pub output: PathBuf,
}

/// What to identify.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum CalibrationKind {
    /// Robot joint stiffness from loaded/unloaded pairs (Paper C).
    Stiffness,
    /// Robot DH parameters and TCP translation (Levenberg–Marquardt).
    Kinematics,
    /// Machine-tool component error tables and squareness.
    Geometry,
    /// Robot Paper B thermal terms (lb, ub, ts) from rows at several joint powers.
    Thermal,
}

/// `postproc calibrate`.
#[derive(Debug, Args)]
pub struct CalibrateArgs {
    /// What to identify.
    pub kind: CalibrationKind,
    /// The machine file to calibrate (or the name of a bundled one).
    #[arg(short, long)]
    pub machine: String,
    /// Measured observation file (CSV).
    #[arg(long)]
    pub observations: PathBuf,
    /// Calibrated machine file to write (the original with edited values).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Fraction of the rows (stiffness: load pairs) held out for validation.
    #[arg(long, default_value_t = 0.3)]
    pub holdout: f64,
    /// Seed of the reproducible hold-out split.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

fn read_machine(name: &str) -> Result<(String, String)> {
    let path = Machine::resolve(name)?;
    let text = Machine::read_text(&path)?;
    Ok((text, path.display().to_string()))
}

/// Largest simulated measurement noise, µm (and µm per metre): 10 mm, far
/// beyond any metrology instrument, keeps every simulated coordinate within
/// the observation files' magnitude limit.
const MAX_NOISE_UM: f64 = 1e4;

fn non_negative(flag: &str, v: f64) -> Result<()> {
    if v.is_finite() && (0.0..=MAX_NOISE_UM).contains(&v) {
        Ok(())
    } else {
        Err(usage(format!(
            "{flag} must be a number within 0..{MAX_NOISE_UM}, got {}",
            crate::error::show_number(v)
        )))
    }
}

fn emit(path: &Path, f: impl FnOnce(&mut dyn Write) -> Result<()>) -> Result<()> {
    if path == Path::new("-") {
        let stdout = std::io::stdout();
        let mut lock = stdout.lock();
        f(&mut lock)?;
        lock.flush().map_err(|e| Error::io("<stdout>", e))
    } else {
        write_atomically(path, f)
    }
}

/// Runs `postproc simulate`.
pub fn run_simulate(a: &SimulateArgs) -> Result<i32> {
    non_negative("--noise-um", a.noise_um)?;
    non_negative("--noise-um-per-m", a.noise_um_per_m)?;
    let (text, file) = read_machine(&a.machine)?;
    let machine = Machine::from_yaml_str(&text, &file)?;
    let poses = load_poses(&a.observations)?;
    let obs_file = a.observations.display().to_string();
    let noise = Noise {
        um: a.noise_um,
        um_per_m: a.noise_um_per_m,
        seed: a.seed,
    };
    let out = simulate(&machine, &poses, &obs_file, &noise)?;
    super::gcode::refuse_overwrite(
        &a.output,
        &[&a.observations, &Machine::resolve(&a.machine)?],
    )?;
    let out_name = a.output.display().to_string();
    emit(&a.output, |w| {
        write_observations(w, &out).map_err(|e| Error::io(&out_name, e))
    })?;
    tracing::info!("wrote {} simulated rows to {out_name}", out.rows.len());
    Ok(0)
}

/// Runs `postproc calibrate`.
pub fn run_calibrate(a: &CalibrateArgs) -> Result<i32> {
    if !(a.holdout.is_finite() && (0.0..0.9).contains(&a.holdout)) {
        return Err(usage(format!(
            "--holdout must be in [0, 0.9), got {}",
            crate::error::show_number(a.holdout)
        )));
    }
    let (text, file) = read_machine(&a.machine)?;
    let obs = load_observations(&a.observations)?;
    let obs_file = a.observations.display().to_string();
    let opts = Options {
        holdout: a.holdout,
        seed: a.seed,
    };
    let cal = match a.kind {
        CalibrationKind::Stiffness => calibrate_stiffness(&text, &file, &obs, &obs_file, &opts)?,
        CalibrationKind::Kinematics => calibrate_kinematics(&text, &file, &obs, &obs_file, &opts)?,
        CalibrationKind::Geometry => calibrate_geometry(&text, &file, &obs, &obs_file, &opts)?,
        CalibrationKind::Thermal => calibrate_thermal(&text, &file, &obs, &obs_file, &opts)?,
    };
    let yaml = cal.yaml.clone();
    super::gcode::refuse_overwrite(
        &a.output,
        &[&a.observations, &Machine::resolve(&a.machine)?],
    )?;
    // The summary first: standard output that fails (closed, full) fails
    // the run before the model is written.
    let mut stdout = std::io::stdout().lock();
    let say = |out: &mut std::io::StdoutLock, text: &str| {
        out.write_all(text.as_bytes())
            .and_then(|()| out.flush())
            .map_err(|e| Error::io("stdout", e))
    };
    say(&mut stdout, &cal.to_string())?;
    write_atomically(&a.output, |w| {
        w.write_all(yaml.as_bytes())
            .map_err(|e| Error::io(&a.output, e))
    })?;
    say(&mut stdout, &format!("wrote {}\n", a.output.display()))?;
    Ok(0)
}
