//! `postproc simulate` (measured columns from a "true" machine file plus
//! noise) and `postproc calibrate` (identify parameters, write a calibrated
//! machine file, print the result table).

use std::io::Write;
use std::path::{Path, PathBuf};

use clap::{Args, ValueEnum};

use crate::calibrate::forward::Switches;
use crate::calibrate::geometry::calibrate_geometry;
use crate::calibrate::honesty::{MAX_RELATIVE_UNCERTAINTY, Rule};
use crate::calibrate::kinematics::calibrate_kinematics;
use crate::calibrate::observations::{
    MeasurementFrame, load_observations, load_poses, write_observations_with,
};
use crate::calibrate::simulate::{Noise, OutputFrame, Simulation, simulate_with};
use crate::calibrate::stiffness::{ORIENTATION_MM_PER_RAD, Options, calibrate_stiffness};
use crate::calibrate::thermal::calibrate_thermal;
use crate::error::{Error, Result};
use crate::machine::status::Calibration;
use crate::machine::{Machine, MachineFile};

use super::output::write_atomically;
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
    /// Decimals of every number written (fixed format; the default 9
    /// keeps simulated data exact to a nanometre).
    #[arg(long, default_value_t = 9)]
    pub decimals: usize,
    /// Effects simulated: all, none, or a list of geometric, static, thermal.
    #[arg(long, default_value = "all")]
    pub effects: String,
    /// Frame of the written positions: base (the machine's reference
    /// frame), world (robot: through the machine file's `base`) or
    /// instrument (`--instrument`, else the machine file's `measurement_frame`).
    #[arg(long, value_parser = parse_frame, default_value = "base")]
    pub frame: MeasurementFrame,
    /// Pose of the instrument in the reference frame for `--frame
    /// instrument`: `X,Y,Z,ROLL,PITCH,YAW` (mm, degrees).
    #[arg(long, value_name = "X,Y,Z,R,P,Y")]
    pub instrument: Option<String>,
    /// Also write the measured orientation of the tool frame (qw, qx, qy, qz; robots).
    #[arg(long)]
    pub orientation: bool,
    /// Orientation noise, standard deviation of a rotation about each axis, mrad.
    #[arg(long, default_value_t = 0.0)]
    pub noise_mrad: f64,
}

/// Largest `--decimals` of `simulate`.
const MAX_DECIMALS: usize = 12;

fn parse_instrument(s: &str) -> Result<nalgebra::Isometry3<f64>> {
    let v: Vec<f64> = s
        .split(',')
        .map(|t| t.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| {
            usage(format!(
                "--instrument expects X,Y,Z,ROLL,PITCH,YAW numbers, got `{}`",
                crate::error::clip(s)
            ))
        })?;
    let ok = v.len() == 6
        && v.iter().all(|x| x.is_finite())
        && v[..3].iter().all(|x| x.abs() <= 1e6)
        && v[3..].iter().all(|x| x.abs() <= 360.0);
    if !ok {
        return Err(usage(format!(
            "--instrument expects six numbers X,Y,Z (mm, within ±1e6) and ROLL,PITCH,YAW (deg, within ±360), got `{}`",
            crate::error::clip(s)
        )));
    }
    Ok(nalgebra::Isometry3::from_parts(
        nalgebra::Translation3::new(v[0], v[1], v[2]),
        nalgebra::UnitQuaternion::from_euler_angles(
            v[3].to_radians(),
            v[4].to_radians(),
            v[5].to_radians(),
        ),
    ))
}

/// `--effects` of `simulate`: the effects of the forward model.
fn parse_switches(spec: &str) -> Result<Switches> {
    let spec_value: crate::machine::effects::EffectSpec =
        spec.parse().map_err(|e| usage(format!("--effects: {e}")))?;
    let set =
        crate::predict::EffectSet::from_flags(&spec_value, &[], crate::predict::MachineKind::Tool)?;
    use crate::predict::Effect;
    if spec.split(',').any(|s| s.trim() == "dynamic") {
        return Err(usage(
            "--effects: dynamic is not simulated (observations are static poses)".to_string(),
        ));
    }
    Ok(Switches {
        geometric: set.gain(Effect::Geometric) > 0.0,
        static_: set.gain(Effect::Static) > 0.0,
        thermal: set.gain(Effect::Thermal) > 0.0,
    })
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
    /// Frame of the measured positions, overriding the file's `# frame:`
    /// line: `base` (the machine's reference frame), `world` (robot: through
    /// the machine file's `base`) or `instrument` (unknown; identified).
    #[arg(long, value_parser = parse_frame)]
    pub frame: Option<MeasurementFrame>,
    /// Ratio of position to orientation noise for rows with `qw…qz`, mm per
    /// rad (0 ignores measured orientations).
    #[arg(long, default_value_t = ORIENTATION_MM_PER_RAD)]
    pub orientation_weight_mm_per_rad: f64,
    /// Write the calibrated file even when it predicts the held-out rows
    /// worse than the input file.
    #[arg(long)]
    pub force: bool,
    /// Largest accepted expanded uncertainty U(k=2) of a parameter, as a
    /// fraction of the larger of its identified value and its change (a
    /// length known to within 2 µm is always accepted). Parameters above
    /// it are uncertain: listed, and not written unless --write-uncertain.
    #[arg(long, value_name = "FRACTION", default_value_t = MAX_RELATIVE_UNCERTAINTY)]
    pub uncertain_above: f64,
    /// Write the uncertain parameters too (they are still listed).
    #[arg(long)]
    pub write_uncertain: bool,
}

/// What the cross-validation of a `--holdout 0` run says, and whether the
/// model is refused (worse on the rows it did not fit, without `--force`).
fn cross_validation_verdict(
    cv: std::result::Result<crate::calibrate::crossval::CrossValidation, String>,
    force: bool,
) -> (String, bool) {
    match cv {
        Ok(cv) => {
            let numbers = format!(
                "cross-validation ({} folds by pose, each of the {} rows predicted by a model \
                 fitted without it): RMS per point {:.4} mm before, {:.4} mm after (mean \
                 squared error {:+.3e} ± {:.3e} mm²)",
                cv.folds,
                cv.rows,
                cv.before_rms_mm,
                cv.after_rms_mm,
                cv.mean_increase_mm2,
                cv.se_increase_mm2
            );
            match (cv.worse(), force) {
                (true, false) => (
                    format!(
                        "{numbers}\nnot written: the calibrated model predicts rows it did not \
                         fit worse than the input model (by more than 2 standard errors); the \
                         data do not support this model (--force writes it anyway)\n"
                    ),
                    true,
                ),
                (true, true) => (
                    format!("{numbers}; worse, written because of --force\n"),
                    false,
                ),
                (false, _) => (format!("{numbers}\n"), false),
            }
        }
        Err(why) => (
            format!(
                "note: --holdout 0 and no cross-validation ({why}): nothing judges this model \
                 on rows it did not fit\n"
            ),
            false,
        ),
    }
}

/// Largest `--uncertain-above`: 100 (10 000 %).
const MAX_UNCERTAIN_ABOVE: f64 = 100.0;

/// Checks `--uncertain-above` (calibrate and diagnose).
pub(super) fn check_uncertain_above(v: f64) -> Result<()> {
    if v.is_finite() && v > 0.0 && v <= MAX_UNCERTAIN_ABOVE {
        return Ok(());
    }
    Err(usage(format!(
        "--uncertain-above must be a fraction above 0 and at most {MAX_UNCERTAIN_ABOVE} \
         (0.5 = 50 %), got {}",
        crate::error::show_number(v)
    )))
}

/// Parses `--frame`.
pub fn parse_frame(s: &str) -> std::result::Result<MeasurementFrame, String> {
    MeasurementFrame::parse(s)
        .ok_or_else(|| format!("unknown frame `{s}` (base, world or instrument)"))
}

fn read_machine(name: &str) -> Result<(String, String)> {
    let file = MachineFile::open(name)?;
    Ok((file.text.into_owned(), file.shown))
}

/// The files a run reads: the observations and the machine file (none of
/// them may be the output).
fn read_files(observations: &Path, machine: &str) -> Result<Vec<PathBuf>> {
    let mut files = vec![observations.to_path_buf()];
    files.extend(MachineFile::open(machine)?.path);
    Ok(files)
}

/// The record of a calibration from the observation file at `path` (of
/// `rows` rows) with fit residual RMS `fit_rms_mm`.
pub(super) fn calibration_record(
    kind: &str,
    path: &Path,
    rows: usize,
    fit_rms_mm: f64,
) -> Result<Calibration> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    Ok(Calibration {
        date: crate::machine::status::today(),
        kind: kind.to_string(),
        observations: path.file_name().map_or_else(
            || path.display().to_string(),
            |n| n.to_string_lossy().into_owned(),
        ),
        observations_sha256: crate::machine::status::sha256_hex(&bytes),
        rows,
        fit_rms_mm,
    })
}

/// Largest simulated measurement noise, µm (and µm per metre): 10 mm, far
/// beyond any metrology instrument, keeps every simulated coordinate within
/// the observation files' magnitude limit.
const MAX_NOISE_UM: f64 = 1e4;

/// Largest accepted position-to-orientation noise ratio, mm/rad.
const MAX_ORIENTATION_WEIGHT: f64 = 1e6;

/// Refuses an `--orientation-weight-mm-per-rad` outside
/// `0..MAX_ORIENTATION_WEIGHT`.
pub(super) fn check_orientation_weight(w: f64) -> Result<()> {
    if w.is_finite() && (0.0..=MAX_ORIENTATION_WEIGHT).contains(&w) {
        Ok(())
    } else {
        Err(usage(format!(
            "--orientation-weight-mm-per-rad must be within 0..{MAX_ORIENTATION_WEIGHT}, got {}",
            crate::error::show_number(w)
        )))
    }
}

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
    if a.decimals > MAX_DECIMALS {
        return Err(usage(format!(
            "--decimals must be within 0..{MAX_DECIMALS}, got {}",
            a.decimals
        )));
    }
    if !(a.noise_mrad.is_finite() && (0.0..=1000.0).contains(&a.noise_mrad)) {
        return Err(usage(format!(
            "--noise-mrad must be a number within 0..1000, got {}",
            crate::error::show_number(a.noise_mrad)
        )));
    }
    let noise = Noise {
        um: a.noise_um,
        um_per_m: a.noise_um_per_m,
        seed: a.seed,
    };
    let frame = match (a.frame, &a.instrument) {
        (MeasurementFrame::Instrument, Some(s)) => OutputFrame::Instrument(parse_instrument(s)?),
        (MeasurementFrame::Instrument, None) => {
            OutputFrame::Instrument(machine.measurement_frame().ok_or_else(|| {
                usage(format!(
                    "--frame instrument needs --instrument X,Y,Z,ROLL,PITCH,YAW or a \
                     `measurement_frame` in {file}"
                ))
            })?)
        }
        (_, Some(_)) => {
            return Err(usage("--instrument needs --frame instrument".to_string()));
        }
        (MeasurementFrame::World, None) => OutputFrame::World,
        (MeasurementFrame::Reference, None) => OutputFrame::Reference,
    };
    let sim = Simulation {
        noise,
        noise_mrad: a.noise_mrad,
        frame,
        orientation: a.orientation,
        effects: parse_switches(&a.effects)?,
    };
    let out = simulate_with(&machine, &poses, &obs_file, &sim)?;
    let decimals = a.decimals;
    let fixed = move |v: f64| {
        let s = format!("{v:.decimals$}");
        // No "-0.000": a value that rounds to zero is written as zero.
        if s.starts_with('-') && s[1..].bytes().all(|b| b == b'0' || b == b'.') {
            s[1..].to_string()
        } else {
            s
        }
    };
    super::output::refuse_overwrite(&a.output, &read_files(&a.observations, &a.machine)?)?;
    let out_name = a.output.display().to_string();
    emit(&a.output, |w| {
        write_observations_with(w, &out, &fixed).map_err(|e| Error::io(&out_name, e))
    })?;
    tracing::info!(
        "wrote {} simulated rows to {out_name} (positions in the {} frame)",
        out.rows.len(),
        out.frame.name()
    );
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
    check_orientation_weight(a.orientation_weight_mm_per_rad)?;
    check_uncertain_above(a.uncertain_above)?;
    let (text, file) = read_machine(&a.machine)?;
    let mut obs = load_observations(&a.observations)?;
    if let Some(f) = a.frame {
        obs.frame = f;
    }
    let obs_file = a.observations.display().to_string();
    let opts = Options {
        holdout: a.holdout,
        seed: a.seed,
        orientation_mm_per_rad: a.orientation_weight_mm_per_rad,
        honesty: Rule {
            max_relative: a.uncertain_above,
            write_uncertain: a.write_uncertain,
        },
    };
    tracing::info!(
        "measured positions in the {} frame",
        match obs.frame {
            MeasurementFrame::Instrument => "instrument",
            MeasurementFrame::World => "world",
            MeasurementFrame::Reference => "machine's reference (robot base or workpiece)",
        }
    );
    // The robot calibrations carry world positions into the base frame
    // themselves (and say so in their notes).
    let run = |o: &crate::calibrate::observations::Observations| match a.kind {
        CalibrationKind::Stiffness => calibrate_stiffness(&text, &file, o, &obs_file, &opts),
        CalibrationKind::Kinematics => calibrate_kinematics(&text, &file, o, &obs_file, &opts),
        CalibrationKind::Geometry => {
            calibrate_geometry(&text, &file, o, &obs_file, &opts).map(|mut c| {
                c.notes.extend(o.orientation_note(
                    opts.orientation_mm_per_rad,
                    Some(crate::calibrate::observations::TOOL_ORIENTATION_UNUSED),
                ));
                c
            })
        }
        CalibrationKind::Thermal => calibrate_thermal(&text, &file, o, &obs_file, &opts),
    };
    if let Ok(m) = crate::machine::Machine::from_yaml_str(&text, &file) {
        crate::calibrate::screen::check_units(&m, &obs, &obs_file)?;
    }
    let cal = run(&obs)?;

    let kind = format!("{:?}", a.kind).to_ascii_lowercase();
    let record = calibration_record(&kind, &a.observations, obs.rows.len(), cal.rms_fit_mm)?;
    let block = cal.covariance.as_ref().map(|c| {
        crate::predict::uncertainty::CovarianceBlock::from_fit(
            &kind,
            &record.observations,
            &record.observations_sha256,
            record.rows,
            c.parameters.clone(),
            &c.matrix,
        )
    });
    let status = crate::machine::yaml_write::Edit::Calibrated(record);
    let yaml =
        crate::machine::yaml_write::apply(&cal.yaml, &file, "postproc calibrate", &[status])?;
    let yaml = crate::machine::status::mark_calibrated(&cal.yaml, &yaml, &file, &kind)?;
    let yaml = match &block {
        Some(b) => crate::predict::uncertainty::put_covariance(&yaml, &file, b)?,
        None => yaml,
    };
    // Older blocks of the covariance list that the calibration's edits
    // made stale (a table re-gridded) are dropped, with a warning.
    let yaml = match crate::machine::Machine::from_yaml_str(&text, &file) {
        Ok(before) => {
            let fresh = block.as_ref().map(|b| b.kind.as_str());
            let (kept, stale) =
                crate::predict::uncertainty::drop_stale_covariance(&before, &yaml, &file, fresh)?;
            for line in stale {
                tracing::warn!("{line}");
            }
            kept
        }
        Err(_) => yaml,
    };
    super::output::refuse_overwrite(&a.output, &read_files(&a.observations, &a.machine)?)?;
    // The summary first: standard output that fails (closed, full) fails
    // the run before the model is written.
    let mut stdout = std::io::stdout().lock();
    let say = |out: &mut std::io::StdoutLock, text: &str| {
        out.write_all(text.as_bytes())
            .and_then(|()| out.flush())
            .map_err(|e| Error::io("stdout", e))
    };
    say(&mut stdout, &cal.to_string())?;
    if !cal.uncertain.is_empty() && !a.write_uncertain {
        tracing::warn!(
            "{} uncertain parameter(s) keep the file's value (--write-uncertain writes them)",
            cal.uncertain.len()
        );
    }
    if a.holdout == 0.0 {
        // Nothing held out: every row is predicted by a model fitted
        // without it, and that decides.
        let stiffness = matches!(a.kind, CalibrationKind::Stiffness);
        let cv = crate::calibrate::crossval::cross_validate(
            &text, &obs, &obs_file, a.seed, stiffness, run,
        );
        let (said, refuse) = cross_validation_verdict(cv, a.force);
        say(&mut stdout, &said)?;
        if refuse {
            return Ok(1);
        }
    }
    if let (true, Some(v)) = (cal.worse_on_holdout(), cal.validation) {
        let numbers = format!(
            "the calibrated model predicts the {} held-out items worse than the input model \
             (RMS per point {:.4} → {:.4} mm, max {:.4} → {:.4} mm)",
            v.n, v.before_rms_mm, v.after_rms_mm, v.before_max_mm, v.after_max_mm
        );
        if !a.force {
            say(
                &mut stdout,
                &format!(
                    "not written: {numbers}; the data do not support this model \
                     (--force writes it anyway)\n"
                ),
            )?;
            return Ok(1);
        }
        say(
            &mut stdout,
            &format!("warning: {numbers}; written because of --force\n"),
        )?;
    }
    write_atomically(&a.output, |w| {
        w.write_all(yaml.as_bytes())
            .map_err(|e| Error::io(&a.output, e))
    })?;
    say(&mut stdout, &format!("wrote {}\n", a.output.display()))?;
    Ok(0)
}
