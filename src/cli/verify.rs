//! `postproc verify`: acceptance figures to ISO 230-2, ISO 230-4 and
//! ISO 9283 from measured data (or predicted by a machine model), held
//! against limits; exit 1 when a figure exceeds its limit.

use std::path::{Path, PathBuf};

use clap::{Args, Subcommand, ValueEnum};

use crate::error::{Error, Result};
use crate::machine::{Machine, MachineFile, axis_slot};
use crate::predict::uncertainty::BlockUncertainty;
use crate::verify::iso230_2::AxisRuns;
use crate::verify::iso230_2::{self, Iso230_2};
use crate::verify::predicted::{
    AxisSetup, CircleSetup, compensated, figure_uncertainty, predicted_circle, predicted_runs,
    prediction_covariance,
};
use crate::verify::{
    Evaluation, Limit, Source, Standard, iso230_4, iso9283, limits, report_json, report_table,
};

use super::output::{emit_to, refuse_overwrite};
use super::usage;

/// Exit codes of `verify`, also listed in its `--help`.
pub const VERIFY_EXIT_HELP: &str = "Exit codes: 0 every figure within its limit (or no limits); 1 a figure exceeds its limit; 2 bad input or usage; 3 internal error.";

/// `postproc verify`.
#[derive(Debug, Args)]
pub struct VerifyArgs {
    /// The standard.
    #[command(subcommand)]
    pub test: VerifyTest,
}

/// The standards.
#[derive(Debug, Subcommand)]
pub enum VerifyTest {
    /// ISO 230-2: E, M, A, R, B and the mean reversal of each linear axis
    /// from bidirectional runs (at least 5 targets, 5 runs per direction),
    /// or predicted by a machine model (--predict).
    #[command(name = "iso230-2", after_help = VERIFY_EXIT_HELP)]
    Iso230_2(Iso230_2Args),
    /// ISO 230-4: circular deviation G of each direction, bidirectional
    /// G_b and hysteresis H from radial deviations of a circular test, or
    /// predicted by a machine model (--predict).
    #[command(name = "iso230-4", after_help = VERIFY_EXIT_HELP)]
    Iso230_4(Iso230_4Args),
    /// ISO 9283: pose accuracy AP and repeatability RP from repeated visits
    /// of at least 5 poses; path accuracy AT and repeatability RT from
    /// repeated runs of a path (--path).
    #[command(name = "iso9283", after_help = VERIFY_EXIT_HELP)]
    Iso9283(Iso9283Args),
}

/// Output format of `verify`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum VerifyFormat {
    /// Aligned text.
    Table,
    /// JSON (schemas/verify.schema.json).
    Json,
}

/// Options of every standard.
#[derive(Debug, Args)]
pub struct CommonArgs {
    /// Largest value of a figure, mm: `A=0.012` for every axis, `X.R=0.004`
    /// for one (repeatable); replaces the machine file's `acceptance` limit.
    #[arg(long = "limit", value_name = "[GROUP.]FIGURE=MM")]
    pub limits: Vec<Limit>,
    /// Machine file (or the name of a bundled one): limits from its
    /// `acceptance` key; the model for --predict and --compensated.
    #[arg(short, long)]
    pub machine: Option<String>,
    /// Output format.
    #[arg(long, value_enum, default_value_t = VerifyFormat::Table)]
    pub format: VerifyFormat,
    /// Write to this file instead of standard output.
    #[arg(short, long)]
    pub output: Option<PathBuf>,
}

/// `postproc verify iso230-2`.
#[derive(Debug, Args)]
pub struct Iso230_2Args {
    /// Measurement file (docs/verify.md); not with --predict.
    #[arg(required_unless_present = "predict", conflicts_with = "predict")]
    pub file: Option<PathBuf>,
    /// The axis of a file without an `axis` column; with --predict and
    /// --compensated the axis of the model.
    #[arg(long, default_value = "X")]
    pub axis: String,
    /// Predict the axis from the machine model instead of measuring it
    /// (needs --machine and --targets).
    #[arg(long, requires_all = ["machine", "targets"])]
    pub predict: bool,
    /// The measured runs as they would read after compensation by the
    /// model (--machine): each run's deviation minus the prediction.
    #[arg(long, requires = "machine", conflicts_with = "predict")]
    pub compensated: bool,
    /// Targets of a predicted axis, mm (at least 5).
    #[arg(long, value_delimiter = ',', requires = "predict")]
    pub targets: Vec<f64>,
    /// Position of the other axes of a prediction: Y=250,Z=100 (mm, deg;
    /// default: linear axes mid-travel, rotary axes 0).
    #[arg(long, value_name = "AXIS=VALUE,...")]
    pub at: Option<String>,
    /// Tool length of a prediction, mm.
    #[arg(long, default_value_t = 0.0)]
    pub tool_mm: f64,
    /// Limits, machine and output.
    #[command(flatten)]
    pub common: CommonArgs,
}

/// `postproc verify iso230-4`.
#[derive(Debug, Args)]
pub struct Iso230_4Args {
    /// Circular-test file (docs/verify.md); not with --predict.
    #[arg(required_unless_present = "predict", conflicts_with = "predict")]
    pub file: Option<PathBuf>,
    /// Predict the test from the machine model (needs --machine and
    /// --radius).
    #[arg(long, requires_all = ["machine", "radius"])]
    pub predict: bool,
    /// Plane of a predicted circle: two linear axes, the first the angle's
    /// zero (XY, YZ, ZX, …).
    #[arg(long, default_value = "XY", requires = "predict")]
    pub plane: String,
    /// Radius of a predicted circle, mm.
    #[arg(long, requires = "predict")]
    pub radius: Option<f64>,
    /// Centre of a predicted circle: X=200,Y=250,Z=100 (default: linear
    /// axes mid-travel, rotary axes 0).
    #[arg(long, value_name = "AXIS=VALUE,...", requires = "predict")]
    pub at: Option<String>,
    /// Points per direction of a predicted circle.
    #[arg(long, default_value_t = 360, requires = "predict")]
    pub points: usize,
    /// Tool length of a prediction, mm.
    #[arg(long, default_value_t = 0.0)]
    pub tool_mm: f64,
    /// Limits, machine and output.
    #[command(flatten)]
    pub common: CommonArgs,
}

/// `postproc verify iso9283`.
#[derive(Debug, Args)]
pub struct Iso9283Args {
    /// Pose file (docs/verify.md).
    pub file: PathBuf,
    /// Path file: AT and RT as well.
    #[arg(long)]
    pub path: Option<PathBuf>,
    /// Limits, machine and output.
    #[command(flatten)]
    pub common: CommonArgs,
}

/// Runs `verify`; the exit code is 1 when a figure exceeds its limit.
pub fn run(a: &VerifyArgs) -> Result<i32> {
    match &a.test {
        VerifyTest::Iso230_2(a) => run_230_2(a),
        VerifyTest::Iso230_4(a) => run_230_4(a),
        VerifyTest::Iso9283(a) => {
            let poses = iso9283::read_visits(&read_text(&a.file)?, &shown(&a.file), false)?;
            let path = match &a.path {
                Some(p) => iso9283::read_visits(&read_text(p)?, &shown(p), true)?,
                None => Vec::new(),
            };
            let eval = iso9283::evaluate(&poses, &path);
            let mut inputs = vec![a.file.as_path()];
            inputs.extend(a.path.as_deref());
            finish(&eval, &measured(&a.file), &a.common, &inputs)
        }
    }
}

fn run_230_2(a: &Iso230_2Args) -> Result<i32> {
    let machine = match &a.common.machine {
        Some(m) if a.predict || a.compensated => Some(tool_machine(m)?),
        _ => None,
    };
    let setup = match &machine {
        Some((m, _)) => Some(AxisSetup::new(
            m,
            &a.axis,
            &parse_at(a.at.as_deref())?,
            a.tool_mm,
        )?),
        None => None,
    };
    let uncertainty = match &a.common.machine {
        Some(name) if a.predict || a.compensated => model_uncertainty(name)?,
        _ => None,
    };
    // Each figure's U, and the provenance sentence of the note.
    let with_u = |runs: &AxisRuns, sign: f64, r: &mut iso230_2::AxisResult| -> String {
        let (Some(u), Some(setup)) = (&uncertainty, &setup) else {
            return String::new();
        };
        r.u_mm =
            prediction_covariance(u, setup, runs).and_then(|c| figure_uncertainty(runs, sign, &c));
        match r.u_mm {
            Some(_) => format!(
                "; ± U (k=2) from the parameter covariance of {}",
                u.sources.join(", ")
            ),
            None => String::new(),
        }
    };
    if let (true, Some((m, shown_m)), Some(setup)) = (a.predict, &machine, &setup) {
        if a.targets.len() < iso230_2::MIN_TARGETS {
            return Err(usage(format!(
                "--targets: {} targets; ISO 230-2 asks for at least {}",
                a.targets.len(),
                iso230_2::MIN_TARGETS
            )));
        }
        let runs = predicted_runs(m, setup, &a.axis.to_ascii_uppercase(), &a.targets)?;
        let mut axis = iso230_2::evaluate_axis(&runs);
        let said = with_u(&runs, 1.0, &mut axis);
        let eval = Iso230_2 { axes: vec![axis] };
        let source = Source::Predicted {
            machine: shown_m.clone(),
            note: format!("the model's systematic deviations, one run per direction (s = 0){said}"),
        };
        return finish(&eval, &source, &a.common, &[]);
    }
    let file = a
        .file
        .as_deref()
        .ok_or_else(|| usage("iso230-2: a measurement file, or --predict"))?;
    let mut axes = iso230_2::read_runs(&read_text(file)?, &shown(file), &a.axis)?;
    let mut source = measured(file);
    if let (Some((m, shown_m)), Some(setup)) = (&machine, &setup) {
        let name = a.axis.to_ascii_uppercase();
        let Some(runs) = axes.iter_mut().find(|r| r.axis.eq_ignore_ascii_case(&name)) else {
            return Err(usage(format!(
                "--compensated --axis {name}: {} has no axis {name}",
                file.display()
            )));
        };
        *runs = compensated(m, setup, runs);
        let runs = runs.clone();
        let mut axis = iso230_2::evaluate_axis(&runs);
        let said = with_u(&runs, -1.0, &mut axis);
        source = Source::Predicted {
            machine: shown_m.clone(),
            note: format!(
                "after compensation: the runs of {} minus the model's deviations{said}",
                file.display()
            ),
        };
        let eval = Iso230_2 { axes: vec![axis] };
        return finish(&eval, &source, &a.common, &[file]);
    }
    let eval = Iso230_2 {
        axes: axes.iter().map(iso230_2::evaluate_axis).collect(),
    };
    finish(&eval, &source, &a.common, &[file])
}

fn run_230_4(a: &Iso230_4Args) -> Result<i32> {
    if let (true, Some(m)) = (a.predict, &a.common.machine) {
        let (machine, shown_m) = tool_machine(m)?;
        let setup = circle_setup(&machine, a)?;
        let eval = iso230_4::evaluate(&predicted_circle(&machine, &setup));
        let source = Source::Predicted {
            machine: shown_m,
            note: format!(
                "a circle of {} mm in {}, {} points per direction",
                a.radius.unwrap_or_default(),
                a.plane.to_ascii_uppercase(),
                a.points
            ),
        };
        return finish(&eval, &source, &a.common, &[]);
    }
    let file = a
        .file
        .as_deref()
        .ok_or_else(|| usage("iso230-4: a circular-test file, or --predict"))?;
    let circle = iso230_4::read_circle(&read_text(file)?, &shown(file))?;
    finish(
        &iso230_4::evaluate(&circle),
        &measured(file),
        &a.common,
        &[file],
    )
}

/// The circle of `verify iso230-4 --predict`.
fn circle_setup(m: &crate::machine::tool::MachineTool, a: &Iso230_4Args) -> Result<CircleSetup> {
    let slot = |c: u8| axis_slot(c.to_ascii_uppercase()).filter(|&s| s < 3 && m.has_axis(s));
    let plane = match a.plane.as_bytes() {
        [p, q] => slot(*p).zip(slot(*q)).filter(|(p, q)| p != q),
        _ => None,
    }
    .ok_or_else(|| {
        usage(format!(
            "--plane {}: two different linear axes of the machine (XY, YZ, ZX, …)",
            a.plane
        ))
    })?;
    let radius_mm = a.radius.unwrap_or_default();
    if !(radius_mm.is_finite() && radius_mm > 0.0) {
        return Err(usage("--radius: a positive number of mm"));
    }
    if a.points < iso230_4::MIN_POINTS {
        return Err(usage(format!(
            "--points: at least {}",
            iso230_4::MIN_POINTS
        )));
    }
    let setup = AxisSetup::new(m, &a.plane[..1], &parse_at(a.at.as_deref())?, a.tool_mm)?;
    for s in [plane.0, plane.1] {
        if let Some((lo, hi)) = m.travel(s) {
            let c = setup.at[s];
            if c - radius_mm < lo || c + radius_mm > hi {
                return Err(usage(format!(
                    "the circle leaves the travel of {} ({lo} to {hi} mm) about {c} mm",
                    ["X", "Y", "Z"][s]
                )));
            }
        }
    }
    Ok(CircleSetup {
        plane,
        centre: setup.at,
        radius_mm,
        points: a.points,
        tool_mm: a.tool_mm,
    })
}

/// A machine-tool model and how errors name its file.
fn tool_machine(name: &str) -> Result<(crate::machine::tool::MachineTool, String)> {
    let file = MachineFile::open(name)?;
    match file.load()? {
        Machine::Tool(t) => Ok((t, file.shown)),
        Machine::Robot(_) => Err(usage(format!(
            "{}: a robot; ISO 230-2 is predicted for the linear axis of a machine tool",
            file.shown
        ))),
    }
}

/// The uncertainty of a machine tool's predictions from its file's
/// parameter covariance (`None`: the file carries none).
fn model_uncertainty(name: &str) -> Result<Option<BlockUncertainty>> {
    let file = MachineFile::open(name)?;
    let blocks = crate::predict::uncertainty::read_covariance(&file.text, &file.shown)?;
    if blocks.is_empty() {
        return Ok(None);
    }
    BlockUncertainty::of_machine(&file.load()?, &blocks, &file.shown)
}

/// `--at Y=250,Z=100`.
fn parse_at(s: Option<&str>) -> Result<Vec<(usize, f64)>> {
    let Some(s) = s else {
        return Ok(Vec::new());
    };
    s.split(',')
        .map(|item| {
            let bad = || usage(format!("--at `{item}`: expected AXIS=VALUE, e.g. Y=250"));
            let (name, value) = item.split_once('=').ok_or_else(bad)?;
            let slot = match name.trim().as_bytes() {
                [c] => axis_slot(c.to_ascii_uppercase()),
                _ => None,
            }
            .ok_or_else(bad)?;
            let v: f64 = value.trim().parse().map_err(|_| bad())?;
            if !v.is_finite() {
                return Err(bad());
            }
            Ok((slot, v))
        })
        .collect()
}

fn shown(p: &Path) -> String {
    p.display().to_string()
}

fn measured(p: &Path) -> Source {
    Source::Measured { file: shown(p) }
}

/// The text of a measurement file (bounded, UTF-8).
fn read_text(p: &Path) -> Result<String> {
    let file = shown(p);
    let bytes = crate::limits::read_file_bounded(p, crate::limits::YAML_MAX_BYTES)?;
    crate::error::utf8_text(&bytes, &file).map_err(Error::Input)?;
    Ok(String::from_utf8(bytes).unwrap_or_default())
}

/// Limits, checks, the report; the exit code.
fn finish(
    eval: &dyn Evaluation,
    source: &Source,
    common: &CommonArgs,
    inputs: &[&Path],
) -> Result<i32> {
    let standard: Standard = eval.standard();
    let groups = eval.groups();
    let mut all: Vec<Limit> = match &common.machine {
        Some(m) => {
            let file = MachineFile::open(m)?;
            limits::from_machine_file(&file.text, &file.shown, standard)?
        }
        None => Vec::new(),
    };
    limits::validate(standard, &common.limits, &groups)?;
    all.extend(common.limits.iter().cloned());
    let checks = limits::check(&groups, &all);
    let text = match common.format {
        VerifyFormat::Table => report_table(eval, source, &checks),
        VerifyFormat::Json => {
            let mut s = serde_json::to_string_pretty(&report_json(eval, source, &checks))
                .map_err(|e| Error::Internal(format!("JSON report: {e}")))?;
            s.push('\n');
            s
        }
    };
    let out = common.output.clone().unwrap_or_else(|| PathBuf::from("-"));
    refuse_overwrite(&out, inputs)?;
    emit_to(&out, |w| {
        w.write_all(text.as_bytes())
            .map_err(|e| Error::io(out.clone(), e))
    })?;
    Ok(if checks.iter().all(|c| c.pass) { 0 } else { 1 })
}
