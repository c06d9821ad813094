//! The G-code commands: `check`, `compensate` and `report`.

use std::fs::File;
use std::io::{BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};

use super::machines::Loaded;
use super::output::{Staged, check_report_path, emit_to, finish_both, refuse_overwrite};
/// The output writing of `calibrate` and `simulate`.
use super::{
    Annotate, CheckArgs, CompensateArgs, EffectArgs, Format, ProgramArgs, ReportArgs, usage,
};
use crate::compensate::Settings;
use crate::compensate::outcome::Summary;
use crate::emit::gcode::EmitOptions;
use crate::emit::header::{HeaderWriter, Provenance};
use crate::emit::report::ReportWriter;
use crate::emit::subprograms::Written;
use crate::error::{Error, Result};
use crate::machine::tool::MachineTool;
use crate::pipeline::gcode::Job;
use crate::predict::{EffectSet, ProcessSetup, ToolPredictor};
use crate::process::{ForceModel, ForceTable};
use crate::program::interp::Setup;

pub(super) fn parse_setup(args: &ProgramArgs, machine: Option<&MachineTool>) -> Result<Setup> {
    let mut setup = match machine {
        Some(m) => Setup::for_machine(m),
        None => Setup {
            axes: [true; 6],
            ..Setup::default()
        },
    };
    setup.expand_cycles |= args.expand_cycles;
    for t in &args.tools {
        setup.tools.insert(t.h, t.length_mm);
    }
    for w in &args.work_offsets {
        match w.slot {
            Some(i) => setup.work_offsets[i] = Some(w.xyz_mm),
            None => {
                setup.extra_offsets.insert(w.code.clone(), w.xyz_mm);
            }
        }
    }
    if let Some(u) = args.units {
        setup.units_default = Some(match u {
            super::UnitsArg::Mm => crate::program::interp::Units::Mm,
            super::UnitsArg::Inch => crate::program::interp::Units::Inch,
        });
    }
    Ok(setup)
}

fn open_input(path: &Path) -> Result<(Box<dyn BufRead>, String)> {
    if path == Path::new("-") {
        let stdin: Box<dyn Read> = Box::new(std::io::stdin());
        return Ok((
            Box::new(BufReader::with_capacity(1 << 18, stdin)),
            "-".into(),
        ));
    }
    let f = File::open(path).map_err(|e| Error::io(path, e))?;
    Ok((
        Box::new(BufReader::with_capacity(1 << 18, f)),
        path.display().to_string(),
    ))
}

/// The machine-tool effects of `--effects` and `--gain`.
pub(super) fn effects(args: &EffectArgs) -> Result<EffectSet> {
    EffectSet::from_flags(
        &args.effects,
        &args.gains,
        crate::predict::MachineKind::Tool,
    )
}

/// The job's process settings from the machine file and the flags.
pub(super) fn process_setup(args: &EffectArgs, machine: &MachineTool) -> Result<ProcessSetup> {
    let mut p = ProcessSetup::for_machine(machine);
    if let Some(spec) = args.force {
        p.force = spec.model();
    }
    if let Some(path) = &args.force_table {
        p.force = Some(ForceModel::Table);
        p.force_table = Some(ForceTable::load(path)?);
    }
    for (flag, v) in [
        ("--milling-depth", args.milling_depth),
        ("--milling-width", args.milling_width),
    ] {
        if let Some(v) = v {
            if !v.is_finite() || !(0.0..=1e4).contains(&v) {
                return Err(usage(format!(
                    "{flag} {}: must be within 0..10000 mm",
                    crate::error::show_number(v)
                )));
            }
        }
    }
    p.milling_depth_mm = args.milling_depth;
    p.milling_width_mm = args.milling_width;
    p.thermal_start = args.thermal_start;
    Ok(p)
}

/// For a `steady` or warm-up thermal start: the program's mean power from a
/// first pass over the file.
fn add_mean_power(
    process: &mut ProcessSetup,
    machine: &MachineTool,
    setup: &Setup,
    effects: EffectSet,
    input: &Path,
) -> Result<()> {
    if !process.thermal_start.needs_mean_power() || machine.thermal().is_none() {
        return Ok(());
    }
    if input == Path::new("-") {
        return Err(usage(
            "--thermal-start steady or MINUTES reads the program twice; give a file, not standard input",
        ));
    }
    let mean = {
        let job = Job {
            predictor: Some(ToolPredictor::new(machine, effects).with_process(process)),
            setup: setup.clone(),
            settings: Settings::default(),
            emit: EmitOptions {
                decimals_mm: None,
                decimals_deg: None,
                annotate: false,
            },
            pool: None,
            travel: None,
        };
        let (input, name) = open_input(input)?;
        job.mean_power(input, &name)?
    };
    tracing::debug!("mean power over the program (spindle, X, Y, Z): {mean:?} W");
    process.mean_power_w = Some(mean);
    Ok(())
}

pub(super) fn thread_pool(threads: Option<usize>) -> Result<rayon::ThreadPool> {
    let mut b = rayon::ThreadPoolBuilder::new();
    if let Some(n) = threads {
        if n == 0 {
            return Err(usage("--threads must be at least 1"));
        }
        b = b.num_threads(n);
    }
    b.build()
        .map_err(|e| usage(format!("cannot start worker threads: {e}")))
}

fn fmt_axes(v: &[f64; 6], setup: &Setup) -> String {
    let mut s = String::new();
    for (slot, &l) in crate::machine::AXIS_LETTERS.iter().enumerate() {
        if setup.axes[slot] {
            if !s.is_empty() {
                s.push(' ');
            }
            s.push_str(&format!("{}{:.3}", l as char, v[slot]));
        }
    }
    s
}

/// Most errors `check` lists (then it stops, as a compiler does).
pub const CHECK_MAX_ERRORS: usize = 20;

/// The line of the program `name` an error is located at.
fn error_line(e: &Error, name: &str) -> Option<usize> {
    match e {
        Error::Input(l) | Error::Unachievable(l) if l.file == name => Some(l.line),
        _ => None,
    }
}

/// Checks the whole program as a compiler does: at an error located on a
/// line of the program, the error is kept, that line is read as blank
/// and the program checked again (the passes after the first say no
/// warning: the summary lists those of the last), up to
/// [`CHECK_MAX_ERRORS`] errors. Gives the summary of the last pass (the
/// program without its bad lines) and the errors in line order; an error
/// of no line of the program is returned as it is when it is the first.
fn check_all(job: &Job, mut input: Box<dyn BufRead>, name: &str) -> Result<(Summary, Vec<Error>)> {
    let mut text = Vec::new();
    (&mut input)
        .take(crate::pipeline::shop::WHOLE_MAX_BYTES + 1)
        .read_to_end(&mut text)
        .map_err(|e| Error::io(name, e))?;
    if text.len() as u64 > crate::pipeline::shop::WHOLE_MAX_BYTES {
        // Too long to hold for passes again (or endless, as /dev/zero):
        // one streaming pass, which stops at the first error.
        let input: Box<dyn BufRead> = Box::new(std::io::BufReader::new(
            std::io::Cursor::new(text).chain(input),
        ));
        let (s, _) = crate::pipeline::shop::run(job, input, name, None, None)?;
        return Ok((s, Vec::new()));
    }
    let mut errors: Vec<Error> = Vec::new();
    loop {
        let pass = |text: &[u8]| {
            let input: Box<dyn BufRead> = Box::new(std::io::Cursor::new(text.to_vec()));
            crate::pipeline::shop::run(job, input, name, None, None)
        };
        let result = if errors.is_empty() {
            pass(&text)
        } else {
            tracing::subscriber::with_default(tracing::subscriber::NoSubscriber::default(), || {
                pass(&text)
            })
        };
        let e = match result {
            Ok((s, _)) => {
                errors.sort_by_key(|k| error_line(k, name));
                return Ok((s, errors));
            }
            Err(e) => e,
        };
        let line = error_line(&e, name);
        let again = line.is_some_and(|l| errors.iter().any(|k| error_line(k, name) == Some(l)));
        match line {
            Some(l) if !again && errors.len() < CHECK_MAX_ERRORS => {
                errors.push(e);
                blank_line(&mut text, l);
            }
            _ if errors.is_empty() => return Err(e),
            _ => {
                // Past the limit, or an error the blanking does not clear:
                // the errors so far, and the summary up to the last.
                if !again && errors.len() < CHECK_MAX_ERRORS {
                    errors.push(e);
                }
                errors.sort_by_key(|k| error_line(k, name));
                let summary = tracing::subscriber::with_default(
                    tracing::subscriber::NoSubscriber::default(),
                    || stop_before(job, &text, name, &errors),
                );
                return Ok((summary, errors));
            }
        }
    }
}

/// The summary of the program up to the line of the last error (a pass
/// that failed has none).
fn stop_before(job: &Job, text: &[u8], name: &str, errors: &[Error]) -> Summary {
    let last = errors
        .iter()
        .filter_map(|e| error_line(e, name))
        .max()
        .unwrap_or(1);
    let head: Vec<u8> = text
        .split_inclusive(|b| *b == b'\n')
        .take(last.saturating_sub(1))
        .flatten()
        .copied()
        .collect();
    let input: Box<dyn BufRead> = Box::new(std::io::Cursor::new(head));
    crate::pipeline::shop::run(job, input, name, None, None)
        .map_or_else(|_| Summary::default(), |(s, _)| s)
}

/// Empties line `line` (1-based) of `text`, keeping its line end, so the
/// lines after it keep their numbers.
fn blank_line(text: &mut Vec<u8>, line: usize) {
    let mut start = 0;
    for _ in 1..line {
        match text[start..].iter().position(|b| *b == b'\n') {
            Some(i) => start += i + 1,
            None => return,
        }
    }
    let end = text[start..]
        .iter()
        .position(|b| *b == b'\n' || *b == b'\r')
        .map_or(text.len(), |i| start + i);
    text.drain(start..end);
}

/// `postproc check`.
pub fn check(a: &CheckArgs, machine: Option<(MachineTool, Loaded)>) -> Result<i32> {
    let machine = machine.map(|(m, _)| m);
    let setup = parse_setup(&a.program, machine.as_ref())?;
    let (input, name) = open_input(&a.program.file)?;
    let job = Job {
        predictor: None,
        setup: setup.clone(),
        settings: Settings::default(),
        emit: EmitOptions {
            decimals_mm: None,
            decimals_deg: None,
            annotate: false,
        },
        pool: None,
        // With a machine, every programmed position must be within its
        // travel, as `compensate` requires.
        travel: machine.as_ref(),
    };
    let (s, errors) = check_all(&job, input, &name)?;
    for e in &errors {
        eprintln!("error: {e}");
    }
    if errors.len() >= CHECK_MAX_ERRORS {
        eprintln!(
            "error: {name}: {CHECK_MAX_ERRORS} errors shown; the rest of the program is not checked"
        );
    }
    let mut out = std::io::stdout().lock();
    let w = |out: &mut dyn Write, t: String| {
        out.write_all(t.as_bytes())
            .map_err(|e| Error::io("stdout", e))
    };
    w(
        &mut out,
        format!(
            "{name}: {} lines, {} blocks, {} moves ({} rapid, {} feed, {} arc, {} cycle holes)\n",
            s.lines, s.blocks, s.moves, s.rapids, s.feeds, s.arcs, s.holes
        ),
    )?;
    w(
        &mut out,
        format!("units: {}\n", if s.inch { "inch" } else { "mm" }),
    )?;
    if let Some((lo, hi)) = s.extents {
        w(
            &mut out,
            format!(
                "extents (machine): min {}\n                   max {}\n",
                fmt_axes(&lo, &setup),
                fmt_axes(&hi, &setup)
            ),
        )?;
    }
    let tools: Vec<String> = s.tools.iter().map(|t| format!("T{t}")).collect();
    w(
        &mut out,
        format!(
            "tools: {}\n",
            if tools.is_empty() {
                "none".into()
            } else {
                tools.join(" ")
            }
        ),
    )?;
    if !errors.is_empty() {
        w(&mut out, format!("errors: {}\n", errors.len()))?;
    }
    w(&mut out, format!("warnings: {}\n", s.warnings.len()))?;
    for warn in &s.warnings {
        w(
            &mut out,
            format!(
                "  line {}: {} ({} block{})\n",
                warn.line,
                warn.message,
                warn.count,
                if warn.count == 1 { "" } else { "s" }
            ),
        )?;
    }
    Ok(if errors.is_empty() { 0 } else { 2 })
}

#[allow(clippy::too_many_arguments)]
pub(super) fn build_job<'m>(
    machine: &'m MachineTool,
    process: &'m ProcessSetup,
    pool: &'m rayon::ThreadPool,
    setup: Setup,
    effects: EffectSet,
    tolerance: f64,
    decimals: Option<usize>,
    annotate: bool,
) -> Result<Job<'m>> {
    crate::limits::tolerance_mm(tolerance).map_err(|m| usage(format!("--tolerance {m}")))?;
    if let Some(d) = decimals {
        if d > 6 {
            return Err(usage("--decimals: at most 6"));
        }
        // Rounding moves a coordinate by up to half a unit of its last
        // decimal: that must stay within the tolerance, or the rounding
        // would undo the compensation.
        let half_unit = 0.5 * 10f64.powi(-(d as i32));
        if half_unit > tolerance {
            return Err(usage(format!(
                "--decimals {d}: rounding moves coordinates by up to {half_unit} mm, more than the tolerance {tolerance} mm"
            )));
        }
    }
    Ok(Job {
        predictor: Some(ToolPredictor::new(machine, effects).with_process(process)),
        setup,
        settings: Settings {
            tolerance_mm: tolerance,
        },
        emit: EmitOptions {
            decimals_mm: decimals.or(machine.output_decimals()),
            decimals_deg: decimals.or(machine.output_decimals_deg()),
            annotate,
        },
        pool: Some(pool),
        // With every effect off nothing is solved, so nothing meets the
        // travel on the way: every programmed position is checked instead.
        travel: effects.is_none().then_some(machine),
    })
}

/// The files a run reads: the program, the machine file and the force
/// table (none of them may be an output).
pub(super) fn input_files(
    program: &ProgramArgs,
    loaded: &Loaded,
    effects: &EffectArgs,
) -> Vec<PathBuf> {
    let mut files = vec![program.file.clone()];
    files.extend(loaded.file.path.clone());
    files.extend(effects.force_table.clone());
    files
}

/// Runs the job, streaming a row per motion block into a report.
pub(super) fn run_reporting(
    job: &Job,
    input: Box<dyn BufRead>,
    file: &str,
    out: Option<&mut dyn Write>,
    report: &mut dyn Write,
    format: Format,
    provenance: Option<&Provenance>,
) -> Result<Summary> {
    run_reporting_shop(job, input, file, out, report, format, provenance).map(|r| r.0)
}

/// [`run_reporting`] with what was made of the program's subprograms.
fn run_reporting_shop(
    job: &Job,
    input: Box<dyn BufRead>,
    file: &str,
    out: Option<&mut dyn Write>,
    report: &mut dyn Write,
    format: Format,
    provenance: Option<&Provenance>,
) -> Result<(Summary, Option<Written>)> {
    let mut rw = ReportWriter::new(report, &job.setup, format, file)?
        .with_source(Path::new(file))
        .with_provenance(provenance);
    let mut err = None;
    let (summary, written) = crate::pipeline::shop::run(
        job,
        input,
        file,
        out,
        Some(&mut |r| {
            if err.is_none() {
                err = rw.row(&r).err();
            }
        }),
    )?;
    if let Some(e) = err {
        return Err(e);
    }
    rw.finish(crate::emit::report::Totals {
        blocks: summary.blocks,
        moves: summary.moves,
    })?;
    Ok((summary, written))
}

/// What `compensate` and `report` set up before running a job: the machine
/// and setup, the worker pool, the effects and the process settings (with
/// the program's mean power for a warm thermal start).
struct Prepared {
    machine: MachineTool,
    loaded: Loaded,
    setup: Setup,
    pool: rayon::ThreadPool,
    effects: EffectSet,
    process: ProcessSetup,
}

impl Prepared {
    fn new(
        program: &ProgramArgs,
        args: &EffectArgs,
        machine: Option<(MachineTool, Loaded)>,
        command: &str,
    ) -> Result<Self> {
        let (machine, mut loaded) = super::config::needed(machine, command)?;
        let setup = parse_setup(program, Some(&machine))?;
        let pool = thread_pool(args.threads)?;
        let effects = super::machines::auto_gain(effects(args)?, args.gain_auto, &mut loaded)?;
        let mut process = process_setup(args, &machine)?;
        add_mean_power(&mut process, &machine, &setup, effects, &program.file)?;
        Ok(Prepared {
            machine,
            loaded,
            setup,
            pool,
            effects,
            process,
        })
    }

    fn job(&self, tolerance: f64, decimals: Option<usize>, annotate: bool) -> Result<Job<'_>> {
        build_job(
            &self.machine,
            &self.process,
            &self.pool,
            self.setup.clone(),
            self.effects,
            tolerance,
            decimals,
            annotate,
        )
    }
}

/// `postproc compensate`.
pub fn compensate(
    a: &CompensateArgs,
    machine: Option<(MachineTool, Loaded)>,
    quiet: bool,
) -> Result<i32> {
    let run = Prepared::new(&a.program, &a.effects, machine, "compensate")?;
    let tolerance = tolerance_of(a.tolerance, Some(&run.machine));
    let annotate = a.annotate == Annotate::Comment;
    let mut job = run.job(tolerance, a.decimals, annotate)?;
    // The annotations state U where the machine file carries a covariance.
    job.predictor = job
        .predictor
        .map(|p| p.with_uncertainty(run.loaded.uncertainty.as_ref()));
    let input_path = &a.program.file;
    let out_path =
        super::output::output_path(input_path, a.output.as_deref(), a.out_dir.as_deref(), &[])?;
    let inputs = input_files(&a.program, &run.loaded, &a.effects);
    refuse_overwrite(&out_path, &inputs)?;
    if let Some(dir) = &a.out_dir {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    }
    check_report_path(a.report.as_deref(), &inputs, &out_path)?;
    let (input, file) = open_input(input_path)?;
    let (head, input) = super::machines::peek_head(input, &file)?;
    super::machines::refuse_compensated(&head, &file, a.recompensate)?;
    let provenance = super::machines::provenance(
        &run.loaded,
        super::machines::tool_effects(&run.effects),
        Some(tolerance),
        annotate,
    );
    let (summary, written): (Summary, Option<Written>) = match &a.report {
        Some(report_path) => {
            let format = a
                .report_format
                .unwrap_or_else(|| Format::from_path(report_path));
            // Neither is put in place unless both are written.
            let mut rep = Staged::open(report_path)?;
            let mut out = Staged::open(&out_path)?;
            let mut hw = HeaderWriter::new(out.writer(), provenance.clone(), false);
            let summary = run_reporting_shop(
                &job,
                input,
                &file,
                Some(&mut hw),
                rep.writer(),
                format,
                Some(&provenance),
            )?;
            hw.finish().map_err(|e| Error::io(&out_path, e))?;
            finish_both(out, rep)?;
            summary
        }
        None => emit_to(&out_path, |w| {
            let mut hw = HeaderWriter::new(w, provenance.clone(), false);
            let s = crate::pipeline::shop::run(&job, input, &file, Some(&mut hw), None)?;
            hw.finish().map_err(|e| Error::io(&out_path, e))?;
            Ok(s)
        })?,
    };
    if !quiet {
        let mut line = summary_line(&file, &out_path, &summary, tolerance);
        if let Some(w) = written {
            line.push_str(&subprogram_note(w));
        }
        eprintln!("{line}");
    }
    if summary.duration_s > 0.0 {
        tracing::info!(
            "time line {:.1} min; mean power spindle {:.0} W, drives X {:.0} Y {:.0} Z {:.0} W",
            summary.duration_s / 60.0,
            summary.mean_power_w[0],
            summary.mean_power_w[1],
            summary.mean_power_w[2],
            summary.mean_power_w[3]
        );
    }
    Ok(if summary.max_residual_mm > tolerance {
        tracing::warn!(
            "{file}:{}: the compensated program is still {:.4} mm off here, more than the tolerance {} mm",
            summary.max_residual_line,
            summary.max_residual_mm,
            tolerance
        );
        1
    } else {
        0
    })
}

/// What the summary line says of a program's subprograms: `; 2
/// subprograms, 3 copies for calls with different corrections`.
fn subprogram_note(w: Written) -> String {
    if let Some(lines) = w.flattened {
        return format!(
            "; macro program written out as it runs ({lines} lines: loops and macro calls run through, values known offline written as numbers where the compensation moves them)"
        );
    }
    let plural =
        |n: usize, one: &str, many: &str| format!("{n} {}", if n == 1 { one } else { many });
    format!(
        "; {}, {} for calls with different corrections",
        plural(w.subprograms, "subprogram", "subprograms"),
        plural(w.copies, "copy", "copies")
    )
}

/// The tolerance of a run: `--tolerance`, else the machine file's
/// `compensation.tolerance_mm`, else the default [`Settings`]' (mm).
pub(super) fn tolerance_of(arg: Option<f64>, machine: Option<&MachineTool>) -> f64 {
    arg.or_else(|| machine.and_then(MachineTool::compensation_tolerance_mm))
        .unwrap_or(Settings::default().tolerance_mm)
}

/// [`tolerance_of`] for a machine file of either kind (robots have no
/// `compensation.tolerance_mm`).
pub(super) fn tolerance_for(arg: Option<f64>, machine: &crate::machine::Machine) -> f64 {
    match machine {
        crate::machine::Machine::Tool(m) => tolerance_of(arg, Some(m)),
        crate::machine::Machine::Robot(_) => tolerance_of(arg, None),
    }
}

/// How many lines the compensation added and why, for the summary line:
/// `12 lines added (8 after takeup points, 4 arcs cut at reversals) at
/// tolerance 0.003 mm`.
pub(super) fn added_lines(summary: &Summary, tolerance: f64) -> String {
    let by = summary.added_by;
    let mut why: Vec<String> = Vec::new();
    for (n, what) in [
        (by.takeups, "after takeup points"),
        (by.arcs, "arcs cut at reversals"),
        (by.chords, "arc chords"),
        (by.splits, "straight-move splits"),
    ] {
        if n > 0 {
            why.push(format!("{n} {what}"));
        }
    }
    let mut s = format!(
        "{} {} added",
        grouped(summary.added),
        if summary.added == 1 { "line" } else { "lines" }
    );
    if !why.is_empty() {
        s.push_str(&format!(" ({})", why.join(", ")));
    }
    s.push_str(&format!(
        " at tolerance {} mm",
        crate::error::show_number(tolerance)
    ));
    s
}

/// A count with thin groups of three digits: `1 040`.
pub(super) fn grouped(n: usize) -> String {
    let digits = n.to_string();
    let mut out = String::with_capacity(digits.len() + digits.len() / 3);
    for (i, c) in digits.chars().enumerate() {
        if i > 0 && (digits.len() - i) % 3 == 0 {
            out.push(' ');
        }
        out.push(c);
    }
    out
}

/// The line `compensate` prints on standard error: what was written, how
/// much it changed and the largest predicted deviation of the cutting
/// moves (the one of rapids and machine-defined moves after it).
pub(super) fn summary_line(input: &str, output: &Path, s: &Summary, tolerance: f64) -> String {
    let out = if output == Path::new("-") {
        "stdout".to_string()
    } else {
        output.display().to_string()
    };
    let plural = |n: usize, one: &str, many: &str| {
        format!("{} {}", grouped(n), if n == 1 { one } else { many })
    };
    let mut line = format!(
        "{input} → {out}: {} changed, {}",
        plural(s.changed, "block", "blocks"),
        added_lines(s, tolerance)
    );
    if s.cutting.count > 0 {
        line.push_str(&format!(
            "; predicted deviation of cutting moves max {:.4} mm (line {})",
            s.cutting.max, s.cutting.max_line
        ));
    }
    if s.beyond.count > 0 {
        line.push_str(&format!(
            "; {} beyond the tolerance (max {:.4} mm, line {})",
            plural(s.beyond.count, "block", "blocks"),
            s.beyond.max_mm,
            s.beyond.max_line
        ));
    }
    let other = s.deviation.count - s.cutting.count;
    if other > 0 {
        // The largest of rapids and machine-defined moves, when larger.
        if s.deviation.max > s.cutting.max || s.cutting.count == 0 {
            line.push_str(&format!(
                "; rapids and machine-defined moves max {:.4} mm (line {})",
                s.deviation.max, s.deviation.max_line
            ));
        }
    }
    line
}

/// `postproc report` (dry run).
pub fn report(a: &ReportArgs, machine: Option<(MachineTool, Loaded)>) -> Result<i32> {
    let run = Prepared::new(&a.program, &a.effects, machine, "report")?;
    // The machine file's tolerance: a point held at an end of travel in a
    // compensated program is held in its report too.
    let job = run.job(tolerance_of(None, Some(&run.machine)), None, false)?;
    let (input, file) = open_input(&a.program.file)?;
    let out = a.output.clone().unwrap_or_else(|| PathBuf::from("-"));
    refuse_overwrite(&out, &input_files(&a.program, &run.loaded, &a.effects))?;
    let provenance = super::machines::provenance(
        &run.loaded,
        super::machines::tool_effects(&run.effects),
        None,
        false,
    );
    emit_to(&out, |w| {
        run_reporting(&job, input, &file, None, w, a.format, Some(&provenance))
    })?;
    Ok(0)
}
