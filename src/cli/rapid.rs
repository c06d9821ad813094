//! The RAPID commands: `check` and `compensate` of an ABB RAPID module
//! against a robot machine file.

use std::io::Write;
use std::path::{Path, PathBuf};

use super::gcode::{default_output, write_atomically};
use super::{Annotate, CheckArgs, CompensateArgs, EffectArgs, ProgramArgs, ReportArgs, usage};
use crate::compensate::rapid::{
    MoveRecord, RapidOptions, RapidOutcome, compensate_module, compensate_parsed, stream,
};
use crate::emit::rapid::Format;
use crate::error::{Error, Result};
use crate::machine::Machine;
use crate::machine::robot::{Effects, Robot, ThermalStart};
use crate::program::rapid::parse_module_bytes;

/// True when the program should take the RAPID path: its extension is
/// `.mod`, `.modx` or `.prg`, or the machine file is a robot.
pub fn wants(program: &ProgramArgs) -> bool {
    let ext = program
        .file
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    if matches!(ext.as_deref(), Some("mod" | "modx" | "prg")) {
        return true;
    }
    match program.machine.as_deref() {
        Some(name) => matches!(
            Machine::resolve(name).and_then(|p| Machine::load(&p)),
            Ok(Machine::Robot(_))
        ),
        None => false,
    }
}

pub(super) fn load_robot(name: &str) -> Result<Robot> {
    let path = Machine::resolve(name)?;
    match Machine::load(&path)? {
        Machine::Robot(r) => Ok(r),
        Machine::Tool(_) => Err(usage(format!(
            "{}: is a machine tool; RAPID programs need a robot",
            path.display()
        ))),
    }
}

/// Parses `--effects` for a robot: `all`, `none`, or a comma list of
/// `kinematic` (alias `geometric`), `gravity`, `process` (alias `load`),
/// `thermal`, `dynamic` (alias `vibration`).
pub fn robot_effects(text: &str) -> Result<Effects> {
    match text.trim().to_ascii_lowercase().as_str() {
        "all" => return Ok(Effects::ALL),
        "none" => return Ok(Effects::NONE),
        _ => {}
    }
    let mut e = Effects::NONE;
    for part in text.split(',') {
        *robot_effect(&mut e, part.trim()).ok_or_else(|| {
            usage(format!(
                "--effects: unknown robot effect `{}` (all, none, {ROBOT_EFFECTS})",
                part.trim()
            ))
        })? = 1.0;
    }
    Ok(e)
}

const ROBOT_EFFECTS: &str = "kinematic, gravity, process, thermal, dynamic";

/// The gain field of the robot effect `name` (with its aliases).
fn robot_effect<'e>(e: &'e mut Effects, name: &str) -> Option<&'e mut f64> {
    match name.to_ascii_lowercase().as_str() {
        "kinematic" | "geometric" => Some(&mut e.kinematic),
        "gravity" => Some(&mut e.gravity),
        "process" | "load" => Some(&mut e.process),
        "thermal" => Some(&mut e.thermal),
        "dynamic" | "vibration" => Some(&mut e.dynamic),
        _ => None,
    }
}

/// Applies `--gain EFFECT=GAIN` (0..10) to the effects that are on; an
/// effect switched off by `--effects` stays off.
pub fn robot_gains(mut e: Effects, gains: &[String]) -> Result<Effects> {
    for spec in gains {
        let (name, value) = spec
            .split_once('=')
            .ok_or_else(|| usage(format!("--gain expects EFFECT=GAIN, got `{spec}`")))?;
        let v: f64 = value
            .trim()
            .parse()
            .map_err(|_| usage(format!("--gain {name}: `{value}` is not a number")))?;
        if !v.is_finite() || !(0.0..=10.0).contains(&v) {
            return Err(usage(format!("--gain {name}: {v} is outside 0..10")));
        }
        let g = robot_effect(&mut e, name.trim()).ok_or_else(|| {
            usage(format!(
                "--gain: unknown robot effect `{}` ({ROBOT_EFFECTS})",
                name.trim()
            ))
        })?;
        if *g != 0.0 {
            *g = v;
        }
    }
    Ok(e)
}

pub(super) fn read_program(path: &Path) -> Result<(String, String)> {
    let name = path.display().to_string();
    let bytes = if path == Path::new("-") {
        let mut b = Vec::new();
        std::io::Read::read_to_end(&mut std::io::stdin(), &mut b).map_err(|e| Error::io("-", e))?;
        b
    } else {
        std::fs::read(path).map_err(|e| Error::io(path, e))?
    };
    // Keep the text; invalid UTF-8 gets a located error (the module itself
    // is parsed once, by the caller).
    let text = match String::from_utf8(bytes) {
        Ok(t) => t,
        Err(e) => {
            parse_module_bytes(e.as_bytes(), &name)?;
            return Err(usage(format!("{name}: {}", e.utf8_error())));
        }
    };
    Ok((text, name))
}

/// Modules of at least this size are read a window at a time when their
/// shape and the run allow it ([`crate::compensate::rapid::stream`]).
pub const STREAM_MIN_BYTES: u64 = 16 << 20;

/// The window size, in lines, when the module `program` names should be
/// read a window at a time: a file (not standard input) of at least
/// [`STREAM_MIN_BYTES`], or any file with `--rapid-window-lines`.
fn window_lines(program: &ProgramArgs) -> Result<Option<usize>> {
    let path = &program.file;
    if path == Path::new("-") {
        return Ok(None);
    }
    if program.rapid_window_lines == Some(0) {
        return Err(usage("--rapid-window-lines must be at least 1"));
    }
    // A regular file only: the module may be read twice (after an error,
    // or for a warm thermal start).
    let Ok(meta) = std::fs::metadata(path) else {
        return Ok(None);
    };
    if !meta.is_file() {
        return Ok(None);
    }
    Ok(match program.rapid_window_lines {
        Some(n) => Some(n),
        None => (meta.len() >= STREAM_MIN_BYTES).then_some(stream::WINDOW_LINES),
    })
}

/// Compensates (`body` given) or checks the module at `path` a window at a
/// time; `None` when it is to be read whole instead (its shape, or an
/// error that the whole-module run reports).
fn try_streamed(
    path: &Path,
    name: &str,
    robot: &Robot,
    opts: &RapidOptions,
    lines: usize,
    body: Option<&mut dyn Write>,
    records: Option<stream::RecordSink>,
) -> Result<Option<(stream::Streamed, String)>> {
    let mut open =
        || std::fs::File::open(path).map(|f| std::io::BufReader::with_capacity(1 << 16, f));
    match stream::compensate_streamed(&mut open, name, robot, opts, lines, body, records) {
        Ok(done) => {
            tracing::info!("{name}: read a window of {lines} lines at a time");
            Ok(Some(done))
        }
        Err(stream::Fallback::Shape(why)) => {
            tracing::info!("{name}: read whole: {}", why.0);
            Ok(None)
        }
        Err(stream::Fallback::Error(e)) => {
            tracing::debug!("{name}: read whole after an error in a window: {e}");
            Ok(None)
        }
    }
}

/// `postproc check` of a RAPID module: parse, resolve and (with a robot)
/// check that every target is reachable with its confdata.
pub fn check(a: &CheckArgs) -> Result<i32> {
    let (name, module_name, decls, procs, moves) = match check_streamed(a)? {
        Some(found) => found,
        None => {
            let (src, name) = read_program(&a.program.file)?;
            let module = crate::program::rapid::parse_module(&src, &name)?;
            let found = (
                module.name.clone(),
                module.decls.len(),
                module.procs.len(),
                module.moves().count(),
            );
            // The compensation takes the parsed module (one parse, one
            // module in memory).
            if let Some(m) = a.program.machine.as_deref() {
                let robot = load_robot(m)?;
                compensate_parsed(module, &src, &name, &robot, &check_options())?;
            }
            (name, found.0, found.1, found.2, found.3)
        }
    };
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "{name}: module {module_name}, {decls} declarations, {procs} routines, {moves} moves"
    )
    .map_err(|e| Error::io("stdout", e))?;
    Ok(0)
}

/// What `check` prints: file name, module name, and the counts of
/// declarations, routines and moves.
type CheckSummary = (String, String, usize, usize, usize);

/// The [`CheckSummary`] of a check against a robot read a window at a time; `None` when
/// the module is to be read whole.
fn check_streamed(a: &CheckArgs) -> Result<Option<CheckSummary>> {
    let (Some(lines), Some(m)) = (window_lines(&a.program)?, a.program.machine.as_deref()) else {
        return Ok(None);
    };
    let robot = load_robot(m)?;
    let name = a.program.file.display().to_string();
    let streamed = try_streamed(
        &a.program.file,
        &name,
        &robot,
        &check_options(),
        lines,
        None,
        None,
    )?;
    Ok(streamed.map(|(s, _)| (name, s.name, s.decls, s.routines, s.moves)))
}

/// The options of a check: resolve and solve every target, compensate
/// nothing.
fn check_options() -> RapidOptions {
    RapidOptions {
        effects: Effects::NONE,
        annotate: false,
        format: Format::default(),
        thermal_start: ThermalStart::Cold,
        records: false,
    }
}

/// The RAPID options of a run from the effect flags (`--effects`, `--gain`,
/// `--thermal-start`), the annotation switch and `--decimals`; output
/// precision from the robot file.
pub(super) fn rapid_options(
    robot: &Robot,
    effects: &EffectArgs,
    annotate: bool,
    decimals: Option<usize>,
) -> Result<RapidOptions> {
    let mut format = RapidOptions::for_robot(robot).format;
    if let Some(d) = decimals {
        if d > 6 {
            return Err(usage("--decimals: at most 6"));
        }
        format.position_decimals = d.max(3);
    }
    let thermal_start: ThermalStart = effects
        .thermal_start
        .parse()
        .map_err(|e| usage(format!("--thermal-start: {e}")))?;
    Ok(RapidOptions {
        effects: robot_gains(robot_effects(&effects.effects)?, &effects.gains)?,
        annotate,
        format,
        thermal_start,
        records: true,
    })
}

/// The robot with the process-force flags of a run applied: `--force none`
/// removes the process force, `--force constant:FX,FY,FZ[@frame]` sets a
/// constant force (frames: `workpiece` = the move's work object, the
/// default; `tool` = the TCP frame; `feed` = tangential, normal, axial),
/// `--force-table FILE` per-move forces by line (work-object frame), and
/// `--milling-depth`/`--milling-width` replace the defaults of a `milling`
/// model (the program's `! POSTPROC MILLING` directives still override
/// them). Milling flags without a milling model are refused.
pub(super) fn robot_with_process(robot: Robot, e: &EffectArgs) -> Result<Robot> {
    use crate::machine::robot::{ForceFrame, ForceModel, ProcessForce};
    let mut robot = robot;
    if let Some(spec) = &e.force {
        let pf = match super::gcode::parse_force(spec)? {
            Some(crate::process::ForceModel::Constant { force_n, frame }) => {
                let old = robot.process_force();
                Some(ProcessForce {
                    model: ForceModel::Constant {
                        force_n,
                        moment_nmm: nalgebra::Vector3::zeros(),
                        frame: match frame {
                            crate::process::Frame::Workpiece => ForceFrame::Workpiece,
                            crate::process::Frame::Tool => ForceFrame::Tool,
                            crate::process::Frame::Feed => ForceFrame::Feed,
                        },
                    },
                    spindle_rpm: old.and_then(|p| p.spindle_rpm),
                    flutes: old
                        .map_or(crate::machine::robot::process::DEFAULT_FLUTES, |p| p.flutes),
                    axis_tolerance_rad: crate::machine::robot::process::DEFAULT_AXIS_TOLERANCE_DEG
                        .to_radians(),
                })
            }
            _ => None,
        };
        robot = robot.with_process_force(pf);
    }
    if let Some(path) = &e.force_table {
        robot = robot.with_force_table(crate::process::ForceTable::load(path)?);
    }
    if e.milling_depth.is_none() && e.milling_width.is_none() {
        return Ok(robot);
    }
    let Some(mut pf) = robot.process_force().copied() else {
        return Err(usage(
            "--milling-depth/--milling-width: the robot has no process force; they need `process_force: {model: milling}`",
        ));
    };
    let ForceModel::Milling(mut m) = pf.model else {
        return Err(usage(
            "--milling-depth/--milling-width: the robot's process force is not `milling`",
        ));
    };
    for (flag, v, slot) in [
        ("--milling-depth", e.milling_depth, &mut m.axial_depth_mm),
        ("--milling-width", e.milling_width, &mut m.radial_width_mm),
    ] {
        if let Some(v) = v {
            if !v.is_finite() || !(0.0..=1e4).contains(&v) {
                return Err(usage(format!("{flag} {v}: must be within 0..10000 mm")));
            }
            *slot = v;
        }
    }
    pf.model = ForceModel::Milling(m);
    Ok(robot.with_process_force(Some(pf)))
}

/// `postproc compensate` of a RAPID module.
pub fn compensate(a: &CompensateArgs) -> Result<i32> {
    let machine = a
        .program
        .machine
        .as_deref()
        .ok_or_else(|| usage("compensate needs --machine"))?;
    let robot = robot_with_process(load_robot(machine)?, &a.effects)?;
    if !a.program.tools.is_empty() || !a.program.work_offsets.is_empty() {
        return Err(usage(
            "--tool and --work-offset are G-code options; RAPID takes tooldata and wobjdata from the module",
        ));
    }
    let opts = RapidOptions {
        records: a.report.is_some(),
        ..rapid_options(
            &robot,
            &a.effects,
            a.annotate == Annotate::Comment,
            a.decimals,
        )?
    };
    let input = &a.program.file;
    let out_path = match &a.output {
        Some(p) => p.clone(),
        None if input == Path::new("-") => PathBuf::from("-"),
        None => default_output(input),
    };
    super::gcode::refuse_overwrite(&out_path, &[input])?;
    super::gcode::check_report_path(a.report.as_deref(), input, &out_path)?;
    let mut pool = rayon::ThreadPoolBuilder::new();
    if let Some(n) = a.effects.threads {
        if n == 0 {
            return Err(usage("--threads must be at least 1"));
        }
        pool = pool.num_threads(n);
    }
    let pool = pool
        .build()
        .map_err(|e| usage(format!("cannot start worker threads: {e}")))?;
    if let Some(lines) = window_lines(&a.program)? {
        let name = input.display().to_string();
        let report = a.report.as_deref().map(|path| {
            let format = a
                .report_format
                .unwrap_or_else(|| super::Format::from_path(path));
            (path, format)
        });
        let outcome = pool.install(|| {
            compensate_streamed_to(input, &name, &robot, &opts, lines, Some(&out_path), report)
        })?;
        if let Some(outcome) = outcome {
            log_outcome(&out_path, &outcome);
            return Ok(0);
        }
    }
    let (src, name) = read_program(input)?;
    let outcome = pool.install(|| compensate_module(&src, &name, &robot, &opts))?;
    if out_path == Path::new("-") {
        let mut stdout = std::io::stdout().lock();
        stdout
            .write_all(outcome.text.as_bytes())
            .and_then(|()| stdout.flush())
            .map_err(|e| Error::io("stdout", e))?;
    } else {
        write_atomically(&out_path, |w| {
            w.write_all(outcome.text.as_bytes())
                .map_err(|e| Error::io(&out_path, e))
        })?;
    }
    if let Some(path) = &a.report {
        let format = a
            .report_format
            .unwrap_or_else(|| super::Format::from_path(path));
        write_atomically(path, |w| write_report(w, &outcome, &name, format))?;
    }
    log_outcome(&out_path, &outcome);
    Ok(0)
}

fn log_outcome(out_path: &Path, outcome: &RapidOutcome) {
    tracing::info!(
        "{}: {} moves compensated, {} targets added; largest predicted deviation {:.4} mm (line {})",
        out_path.display(),
        outcome.moves,
        outcome.added,
        outcome.max_deviation_mm,
        outcome.max_deviation_line
    );
}

/// A temporary file beside `path` — in the temporary folder for standard
/// output, a device, or a folder that takes no new file — unnamed: nothing
/// is left behind whatever happens. `None` when neither place takes one
/// (the module is then read whole, and the output's own errors are those
/// of that run).
fn spill_beside(path: &Path) -> Option<std::fs::File> {
    let regular = std::fs::metadata(path).map_or(true, |m| m.is_file());
    let beside = match path.parent() {
        _ if path == Path::new("-") || !regular => None,
        Some(p) if !p.as_os_str().is_empty() => Some(p.to_path_buf()),
        _ => Some(PathBuf::from(".")),
    };
    beside
        .and_then(|dir| tempfile::tempfile_in(dir).ok())
        .or_else(|| tempfile::tempfile().ok())
}

/// Writes `head` and then the contents of `spill` (written, not yet
/// rewound) to `path`, atomically (or to standard output for `-`).
fn write_spilled(path: &Path, head: &str, spill: std::io::BufWriter<std::fs::File>) -> Result<()> {
    let mut file = spill
        .into_inner()
        .map_err(|e| Error::io(path, e.into_error()))?;
    std::io::Seek::rewind(&mut file).map_err(|e| Error::io(path, e))?;
    super::gcode::emit_to(path, |w| {
        w.write_all(head.as_bytes())
            .map_err(|e| Error::io(path, e))?;
        std::io::copy(&mut file, w).map_err(|e| Error::io(path, e))?;
        Ok(())
    })
}

/// Compensates the module at `input` a window at a time into `out_path`
/// (`None` for a dry run) and the report of every move into `report`:
/// the rewritten routines and the report rows go to temporary files beside
/// their outputs as they are made, then to the outputs (atomically, as
/// always). `None` when the module is to be read whole.
pub(super) fn compensate_streamed_to(
    input: &Path,
    name: &str,
    robot: &Robot,
    opts: &RapidOptions,
    lines: usize,
    out_path: Option<&Path>,
    report: Option<(&Path, super::Format)>,
) -> Result<Option<RapidOutcome>> {
    use crate::emit::report::{Layout, ReportWriter};
    let spill = |p: &Path| spill_beside(p).map(|f| std::io::BufWriter::with_capacity(1 << 16, f));
    let mut body = match out_path {
        Some(p) => match spill(p) {
            Some(b) => Some(b),
            None => return Ok(None),
        },
        None => None,
    };
    let mut report_spill = match report {
        Some((p, _)) => match spill(p) {
            Some(b) => Some(b),
            None => return Ok(None),
        },
        None => None,
    };
    let mut writer = match (report, report_spill.as_mut()) {
        (Some((_, format)), Some(w)) => Some(
            ReportWriter::with_layout(w, Layout::rapid(), format, name)?
                .with_source(Path::new(name)),
        ),
        _ => None,
    };
    let mut sink = |records: &[MoveRecord]| -> Result<()> {
        match writer.as_mut() {
            Some(rw) => write_records(rw, records),
            None => Ok(()),
        }
    };
    let streamed = try_streamed(
        input,
        name,
        robot,
        &RapidOptions {
            records: report.is_some(),
            ..*opts
        },
        lines,
        body.as_mut().map(|b| b as &mut dyn Write),
        Some(&mut sink),
    )?;
    let Some((streamed, prologue)) = streamed else {
        return Ok(None);
    };
    if let (Some(p), Some(b)) = (out_path, body) {
        write_spilled(p, &prologue, b)?;
    }
    if let (Some(rw), Some((p, _))) = (writer, report) {
        rw.finish(crate::emit::report::Totals {
            blocks: streamed.outcome.moves,
            moves: streamed.outcome.moves,
        })?;
        if let Some(spill) = report_spill {
            write_spilled(p, "", spill)?;
        }
    }
    Ok(Some(streamed.outcome))
}

/// Writes the report rows of `records`.
fn write_records(rw: &mut crate::emit::report::ReportWriter, records: &[MoveRecord]) -> Result<()> {
    use crate::emit::report::Entry;
    for t in records {
        let d = &t.deviation;
        rw.entry(&Entry {
            line: t.line,
            motion: t.kind,
            axes: &t.programmed_mm,
            position_mm: t.programmed_mm,
            deviation_mm: d.total.pos_mm.into(),
            effects_mm: &[
                d.kinematic.pos_mm.norm(),
                d.thermal.pos_mm.norm(),
                d.gravity.pos_mm.norm(),
                d.process.pos_mm.norm(),
                d.vibration_mm.norm(),
            ],
            residual_mm: None,
            orient_urad: d.total.rot_rad.norm() * 1e6,
        })?;
    }
    Ok(())
}

/// Writes the deviation report of a compensated (or dry-run) RAPID module:
/// a row per motion instruction with the kinematic, thermal, gravity, process and dynamic (vibration)
/// parts of its predicted deviation.
pub(super) fn write_report(
    out: &mut dyn Write,
    outcome: &RapidOutcome,
    name: &str,
    format: super::Format,
) -> Result<()> {
    use crate::emit::report::{Layout, ReportWriter, Totals};
    let mut rw =
        ReportWriter::with_layout(out, Layout::rapid(), format, name)?.with_source(Path::new(name));
    write_records(&mut rw, &outcome.records)?;
    rw.finish(Totals {
        blocks: outcome.moves,
        moves: outcome.moves,
    })
}

/// `postproc report` of a RAPID module (dry run against a robot).
pub fn report(a: &ReportArgs) -> Result<i32> {
    let machine = a
        .program
        .machine
        .as_deref()
        .ok_or_else(|| usage("report needs --machine"))?;
    let robot = robot_with_process(load_robot(machine)?, &a.effects)?;
    if !a.program.tools.is_empty() || !a.program.work_offsets.is_empty() {
        return Err(usage(
            "--tool and --work-offset are G-code options; RAPID takes tooldata and wobjdata from the module",
        ));
    }
    let opts = rapid_options(&robot, &a.effects, false, None)?;
    let out = a.output.clone().unwrap_or_else(|| PathBuf::from("-"));
    super::gcode::refuse_overwrite(&out, &[&a.program.file])?;
    if let Some(lines) = window_lines(&a.program)? {
        let name = a.program.file.display().to_string();
        let report = Some((out.as_path(), a.format));
        if compensate_streamed_to(&a.program.file, &name, &robot, &opts, lines, None, report)?
            .is_some()
        {
            return Ok(0);
        }
    }
    let (src, name) = read_program(&a.program.file)?;
    let outcome = compensate_module(&src, &name, &robot, &opts)?;
    super::gcode::emit_to(&out, |w| write_report(w, &outcome, &name, a.format))?;
    Ok(0)
}
