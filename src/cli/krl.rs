//! `postproc check`, `compensate` and `report` of a KUKA KRL program: its
//! `.src`, the `.dat` of the same name beside it, and a `$config.dat`
//! (given after the `.src`, or found beside it) for `TOOL_DATA[n]` and
//! `BASE_DATA[n]`. The program is resolved into the robot move stream
//! ([`crate::program::krl::resolve`]), run through the robot pipeline
//! ([`crate::pipeline::robot`]) and written back by the KRL writer
//! ([`crate::emit::krl`]): `<stem>.comp.src` and `<stem>.comp.dat` (the
//! one output-naming rule), each with the provenance header after its `&`
//! header lines.

use std::io::Write;
use std::path::{Path, PathBuf};

use super::output::Staged;
use super::{Annotate, CheckArgs, CompensateArgs, ReportArgs};
use crate::compensate::outcome::Compensated;
use crate::emit::header::{Provenance, Syntax};
use crate::emit::krl::{KrlWrite, rewrite};
use crate::error::{Error, Result};
use crate::machine::Machine;
use crate::machine::robot::Robot;
use crate::pipeline::robot::RobotRun;
use crate::pipeline::robot::{RobotOptions, refuse_left_as_written};
use crate::predict::EffectSet;
use crate::program::charset::{Charset, Latin1Writer};
use crate::program::krl::resolve::{Program, resolve};
use crate::program::krl::syntax::{File, parse};
use crate::program::robot_moves::RobotStep;

/// Whether `path` is a KRL program postproc reads: a `.src` file.
pub fn is_krl(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("src"))
}

/// Whether `path` is a KRL data list read with a `.src`: a `$config.dat`,
/// or a `.dat` with a `.src` of its name beside it.
pub fn is_krl_data(path: &Path) -> bool {
    let Some(name) = path.file_name().map(|n| n.to_string_lossy().to_string()) else {
        return false;
    };
    if name.eq_ignore_ascii_case("$config.dat") {
        return true;
    }
    let dat = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("dat"));
    let stem = path.file_stem().map(|s| s.to_string_lossy().to_string());
    dat && stem.is_some_and(|s| beside(path, &format!("{s}.src")).is_some())
}

/// One file of the program: its path, name in messages, text, character
/// set and parsed lines.
struct Text {
    path: PathBuf,
    name: String,
    text: String,
    charset: Charset,
    file: File,
}

fn read(path: &Path) -> Result<Text> {
    let name = path.display().to_string();
    let bytes = crate::limits::read_file_bounded(path, u64::MAX)?;
    let (text, charset) = crate::program::charset::decode(bytes);
    let file = parse(&text, &name)?;
    Ok(Text {
        path: path.to_path_buf(),
        name,
        text,
        charset,
        file,
    })
}

/// A file beside `path` named `name` in any letter case.
fn beside(path: &Path, name: &str) -> Option<PathBuf> {
    let dir = path.parent().filter(|d| !d.as_os_str().is_empty());
    let dir = dir.unwrap_or(Path::new("."));
    std::fs::read_dir(dir).ok()?.flatten().find_map(|e| {
        let n = e.file_name();
        n.to_string_lossy()
            .eq_ignore_ascii_case(name)
            .then(|| e.path())
    })
}

/// The `.src`, its `.dat` and a `$config.dat` of the program of `a`.
fn read_program(src: &Path, more: &[PathBuf]) -> Result<Vec<Option<Text>>> {
    let stem = src.file_stem().map(|s| s.to_string_lossy().to_string());
    let dat = stem.and_then(|s| beside(src, &format!("{s}.dat")));
    let config = more
        .iter()
        .find(|p| {
            p.file_name()
                .is_some_and(|n| n.to_string_lossy().eq_ignore_ascii_case("$config.dat"))
        })
        .cloned()
        .or_else(|| beside(src, "$config.dat"));
    for m in more {
        if config.as_ref() != Some(m) {
            return Err(super::usage(format!(
                "{}: a KRL program is its .src with the .dat beside it; only a $config.dat may follow it",
                m.display()
            )));
        }
    }
    Ok(vec![
        Some(read(src)?),
        dat.as_deref().map(read).transpose()?,
        config.as_deref().map(read).transpose()?,
    ])
}

/// The stream of a read program.
fn steps_of(texts: &[Option<Text>]) -> Vec<RobotStep> {
    let file = |i: usize| texts.get(i).and_then(Option::as_ref).map(|t| &t.file);
    let Some(src) = texts.first().and_then(Option::as_ref) else {
        return Vec::new();
    };
    let program = Program {
        src: &src.file,
        dat: file(1),
        config: file(2),
    };
    resolve(&program, &src.text)
}

/// The robot of `--machine` (a robot), with the process-force flags.
pub(super) fn robot_of(
    machine: Option<&str>,
    command: &str,
    effects: Option<&super::EffectArgs>,
) -> Result<(Robot, super::machines::Loaded)> {
    if effects.is_some_and(|e| e.gain_auto) {
        return Err(super::usage(
            "--gain-auto is a G-code option: a robot's gains are given with --gain",
        ));
    }
    let name = super::config::needed(machine, command)?;
    let (m, loaded) = super::machines::open(name)?;
    let Machine::Robot(r) = m else {
        return Err(super::config::not_a_robot(&loaded));
    };
    match effects {
        Some(e) => Ok((super::rapid::robot_with_process(r, e)?, loaded)),
        None => Ok((r, loaded)),
    }
}

/// Runs the pipeline over the program's stream.
fn run(
    texts: &[Option<Text>],
    robot: &Robot,
    opts: &RobotOptions,
) -> Result<(Vec<RobotStep>, RobotRun)> {
    let steps = steps_of(texts);
    let name = texts
        .first()
        .and_then(Option::as_ref)
        .map_or("", |t| &t.name);
    let run = crate::pipeline::robot::run(robot, &steps, opts, name)?;
    refuse_left_as_written(&run.summary.warnings, name, opts)?;
    Ok((steps, run))
}

/// `postproc check` of a KRL program: its syntax and resolution, and with
/// `--machine` every target reached in its configuration.
pub fn check(a: &CheckArgs) -> Result<i32> {
    let texts = read_program(&a.program.file, &a.program.more)?;
    let steps = steps_of(&texts);
    if a.program.machine.is_some() {
        let (robot, _) = robot_of(a.program.machine.as_deref(), "check", None)?;
        let opts = RobotOptions {
            effects: EffectSet::NONE,
            records: false,
            strict: a.program.strict,
            ..RobotOptions::default()
        };
        run(&texts, &robot, &opts)?;
    }
    let count = |f: fn(&RobotStep) -> bool| steps.iter().filter(|s| f(s)).count();
    let targets = count(|s| matches!(s, RobotStep::Target(_)));
    let joints = count(|s| matches!(s, RobotStep::Joints(_)));
    let left = count(|s| matches!(s, RobotStep::Left(_)));
    let name = a.program.file.display();
    let dat = if texts.get(1).is_some_and(Option::is_some) {
        " with its .dat"
    } else {
        ""
    };
    writeln!(
        std::io::stdout().lock(),
        "{name}: KRL program{dat}, {} ({targets} targets, {joints} joint targets, {left} left as written)",
        if steps.len() == 1 {
            "1 motion".to_string()
        } else {
            format!("{} motions", steps.len())
        }
    )
    .map_err(|e| Error::io("stdout", e))?;
    Ok(0)
}

/// Where the provenance header goes in a KRL file: after its leading `&`
/// header lines.
fn header_at(text: &str) -> usize {
    let mut at = 0;
    for l in text.split_inclusive('\n') {
        if !l.trim_start().starts_with('&') {
            break;
        }
        at += l.len();
    }
    at
}

/// `text` with the provenance header, in the file's line ending.
fn with_header(text: &str, provenance: &Provenance) -> String {
    let eol = if text.contains("\r\n") { "\r\n" } else { "\n" };
    let at = header_at(text);
    let header = provenance.render(Syntax::GcodeSemicolon, eol.as_bytes());
    let mut out = String::with_capacity(text.len() + header.len() + 2);
    out.push_str(&text[..at]);
    if at > 0 && !text[..at].ends_with('\n') {
        out.push_str(eol);
    }
    out.push_str(&String::from_utf8_lossy(&header));
    out.push_str(&text[at..]);
    out
}

/// Writes `text` to a staged file in `charset`.
pub(super) fn stage(path: &Path, text: &str, charset: Charset) -> Result<super::output::Pending> {
    let mut out = Staged::open(path)?;
    let written = match charset {
        Charset::Utf8 => out.writer().write_all(text.as_bytes()),
        Charset::Latin1 => {
            let mut w = Latin1Writer::new(out.writer());
            w.write_all(text.as_bytes()).and_then(|()| w.flush())
        }
    };
    written.map_err(|e| Error::io(path, e))?;
    out.finish()
}

/// `postproc compensate` of a KRL program.
pub fn compensate(a: &CompensateArgs, quiet: bool) -> Result<i32> {
    compensate_with(a, quiet, compensate_to)
}

/// How one robot language compensates its program `src` (with the files
/// given with it) into `out`, with its report.
pub(super) type CompensateTo = fn(
    &Job,
    (&Path, &[PathBuf]),
    &Path,
    Option<(&Path, super::Format)>,
) -> Result<crate::compensate::outcome::Summary>;

/// `postproc compensate` of a program of a robot language other than
/// RAPID: the robot with the run's process force, the options, the
/// provenance and the output name the same for each, the program written
/// by the language's `compensate_to`.
pub(super) fn compensate_with(a: &CompensateArgs, quiet: bool, write: CompensateTo) -> Result<i32> {
    let (robot, loaded) = robot_of(a.program.machine.as_deref(), "compensate", Some(&a.effects))?;
    let opts = RobotOptions {
        records: a.report.is_some(),
        strict: a.program.strict,
        ..super::rapid::rapid_options(
            &robot,
            &a.effects,
            a.annotate == Annotate::Comment,
            a.decimals,
        )?
    };
    let provenance = super::machines::provenance(
        &loaded,
        super::machines::robot_effects(&opts.effects),
        None,
        opts.annotate,
    );
    let src = &a.program.file;
    let out = super::output::output_path(src, a.output.as_deref(), None, &[])?;
    let report = a.report.as_deref().map(|path| {
        let format = a
            .report_format
            .unwrap_or_else(|| super::Format::from_path(path));
        (path, format)
    });
    let job = Job {
        robot: &robot,
        opts: &opts,
        provenance: &provenance,
        recompensate: a.recompensate,
    };
    let summary = write(&job, (src, &a.program.more), &out, report)?;
    for w in summary.warnings.iter().filter(|w| w.left.is_none()) {
        tracing::warn!("{}: {}", src.display(), w.message);
    }
    super::rapid::log_outcome(&src.display().to_string(), &out, &summary, quiet);
    Ok(0)
}

/// What a compensation of KRL programs runs with.
pub(super) struct Job<'a> {
    /// The robot, with the run's process force.
    pub(super) robot: &'a Robot,
    /// The run's options.
    pub(super) opts: &'a RobotOptions,
    /// The header of the outputs.
    pub(super) provenance: &'a Provenance,
    /// `--recompensate`.
    pub(super) recompensate: bool,
}

/// Compensates the KRL program `src` (with `more`: a `$config.dat`) into
/// `out_src` and the `.dat` beside it, with its report; no file is put in
/// place unless all are written.
pub(super) fn compensate_to(
    job: &Job,
    (src, more): (&Path, &[PathBuf]),
    out_src: &Path,
    report: Option<(&Path, super::Format)>,
) -> Result<crate::compensate::outcome::Summary> {
    let (robot, opts, provenance) = (job.robot, job.opts, job.provenance);
    let texts = read_program(src, more)?;
    let Some(first) = texts.first().and_then(Option::as_ref) else {
        return Err(Error::Internal("no .src".into()));
    };
    super::machines::refuse_compensated(first.text.as_bytes(), &first.name, job.recompensate)?;
    let (steps, mut run) = run(&texts, robot, opts)?;
    let strs: Vec<&str> = texts
        .iter()
        .map(|t| t.as_ref().map_or("", |t| t.text.as_str()))
        .collect();
    let empty = File { lines: Vec::new() };
    let files: Vec<&File> = texts
        .iter()
        .map(|t| t.as_ref().map_or(&empty, |t| &t.file))
        .collect();
    let how = KrlWrite {
        position_decimals: opts.format.position_decimals,
        annotate: opts.annotate,
        compensate: opts.effects.compensates(),
    };
    let solved = run.solved();
    let u = provenance.uncertainty.as_deref();
    let (out_texts, warnings) = rewrite(&strs, &files, &steps, &solved, (robot, u), how)?;
    run.summary.warnings.extend(warnings);
    let inputs: Vec<&Path> = texts.iter().flatten().map(|t| t.path.as_path()).collect();
    let mut pending = Vec::new();
    for (i, t) in texts.iter().enumerate().take(2) {
        let Some(t) = t else { continue };
        let out = if i == 0 {
            out_src.to_path_buf()
        } else {
            out_src.with_extension("dat")
        };
        super::output::refuse_overwrite(&out, &inputs)?;
        pending.push(stage(
            &out,
            &with_header(&out_texts[i], provenance),
            t.charset,
        )?);
    }
    if let Some((path, format)) = report {
        super::output::refuse_overwrite(path, &inputs)?;
        let mut rep = Staged::open(path)?;
        write_report(rep.writer(), run.clone(), &first.name, format, provenance)?;
        pending.push(rep.finish()?);
    }
    for p in pending {
        p.commit()?;
    }
    Ok(run.summary)
}

/// Writes the deviation report of a run.
pub(super) fn write_report(
    out: &mut dyn Write,
    run: RobotRun,
    name: &str,
    format: super::Format,
    provenance: &Provenance,
) -> Result<()> {
    let outcome = Compensated {
        text: String::new(),
        summary: run.summary,
        records: run.records,
    };
    super::rapid::write_report(out, &outcome, name, format, Some(provenance))
}

/// `postproc report` of a KRL program (a dry run against a robot).
pub fn report(a: &ReportArgs) -> Result<i32> {
    let (robot, loaded) = robot_of(a.program.machine.as_deref(), "report", Some(&a.effects))?;
    let texts = read_program(&a.program.file, &a.program.more)?;
    let opts = RobotOptions {
        strict: a.program.strict,
        ..super::rapid::rapid_options(&robot, &a.effects, false, None)?
    };
    let (_, run) = run(&texts, &robot, &opts)?;
    let provenance = super::machines::provenance(
        &loaded,
        super::machines::robot_effects(&opts.effects),
        None,
        false,
    );
    let out = a.output.clone().unwrap_or_else(|| PathBuf::from("-"));
    let inputs: Vec<&Path> = texts.iter().flatten().map(|t| t.path.as_path()).collect();
    super::output::refuse_overwrite(&out, &inputs)?;
    let name = a.program.file.display().to_string();
    super::output::emit_to(&out, |w| write_report(w, run, &name, a.format, &provenance))?;
    Ok(0)
}
