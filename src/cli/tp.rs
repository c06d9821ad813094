//! `postproc check`, `compensate` and `report` of a FANUC TP program in
//! its ASCII form (`.ls`). The program is resolved into the robot move
//! stream ([`crate::program::tp::resolve`]) with the user and tool frames
//! of the robot file (`fanuc:`), run through the robot pipeline
//! ([`crate::pipeline::robot`]) and written back by the TP writer
//! ([`crate::emit::tp`]) to `<stem>.comp.ls` (the one output-naming rule),
//! with the provenance header as `!` lines after the `/PROG` line.

use std::io::Write;
use std::path::{Path, PathBuf};

use super::krl::{robot_of, stage, write_report};
use super::output::Staged;
use super::{CheckArgs, CompensateArgs, ReportArgs};
use crate::emit::header::{Provenance, Syntax};
use crate::emit::tp::{TpWrite, rewrite};
use crate::error::{Error, Result};
use crate::machine::robot::Robot;
use crate::pipeline::robot::RobotRun;
use crate::pipeline::robot::{RobotOptions, refuse_left_as_written};
use crate::predict::EffectSet;
use crate::program::charset::Charset;
use crate::program::robot_moves::RobotStep;
use crate::program::tp::resolve::resolve;
use crate::program::tp::{Program, parse};

/// Whether `path` is a TP program postproc reads: a `.ls` file.
pub fn is_tp(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("ls"))
}

/// The program: its path, name in messages, text, character set and
/// parsed form.
struct Text {
    path: PathBuf,
    name: String,
    text: String,
    charset: Charset,
    program: Program,
}

fn read(path: &Path, more: &[PathBuf]) -> Result<Text> {
    if let Some(m) = more.first() {
        return Err(super::usage(format!(
            "{}: a TP program is one .ls file; its frames are in the robot file",
            m.display()
        )));
    }
    let name = path.display().to_string();
    let bytes = crate::limits::read_file_bounded(path, u64::MAX)?;
    let (text, charset) = crate::program::charset::decode(bytes);
    let program = parse(&text, &name)?;
    Ok(Text {
        path: path.to_path_buf(),
        name,
        text,
        charset,
        program,
    })
}

/// Runs the pipeline over the program's stream.
fn run(t: &Text, robot: &Robot, opts: &RobotOptions) -> Result<(Vec<RobotStep>, RobotRun)> {
    let steps = resolve(&t.program, &t.text, robot.fanuc_frames());
    let run = crate::pipeline::robot::run(robot, &steps, opts, &t.name)?;
    refuse_left_as_written(&run.summary.warnings, &t.name, opts)?;
    Ok((steps, run))
}

/// `postproc check` of a TP program: its syntax and resolution (with the
/// frames of `--machine`, and then every target reached in its
/// configuration).
pub fn check(a: &CheckArgs) -> Result<i32> {
    let t = read(&a.program.file, &a.program.more)?;
    let steps = match a.program.machine.as_deref() {
        Some(m) => {
            let (robot, _) = robot_of(Some(m), "check", None)?;
            let opts = RobotOptions {
                effects: EffectSet::NONE,
                records: false,
                strict: a.program.strict,
                ..RobotOptions::default()
            };
            run(&t, &robot, &opts)?.0
        }
        None => resolve(&t.program, &t.text, &Default::default()),
    };
    let count = |f: fn(&RobotStep) -> bool| steps.iter().filter(|s| f(s)).count();
    let targets = count(|s| matches!(s, RobotStep::Target(_)));
    let joints = count(|s| matches!(s, RobotStep::Joints(_)));
    let left = count(|s| matches!(s, RobotStep::Left(_)));
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "{}: FANUC TP program {}, {} ({targets} targets, {joints} joint targets, {left} left as written)",
        a.program.file.display(),
        t.program.name,
        if steps.len() == 1 {
            "1 motion".to_string()
        } else {
            format!("{} motions", steps.len())
        }
    )
    .map_err(|e| Error::io("stdout", e))?;
    Ok(0)
}

/// `text` with the provenance header as `!` lines after its `/PROG` line
/// (at the start when it has none), in the file's line ending.
fn with_header(text: &str, provenance: &Provenance) -> String {
    let eol = if text.contains("\r\n") { "\r\n" } else { "\n" };
    let mut at = 0;
    for l in text.split_inclusive('\n') {
        at += l.len();
        if l.trim_start().starts_with("/PROG") {
            break;
        }
        if !l.trim().is_empty() {
            at = 0;
            break;
        }
    }
    let header = provenance.render(Syntax::Rapid, eol.as_bytes());
    let mut out = String::with_capacity(text.len() + header.len() + 2);
    out.push_str(&text[..at]);
    if at > 0 && !text[..at].ends_with('\n') {
        out.push_str(eol);
    }
    out.push_str(&String::from_utf8_lossy(&header));
    out.push_str(&text[at..]);
    out
}

/// `postproc compensate` of a TP program.
pub fn compensate(a: &CompensateArgs, quiet: bool) -> Result<i32> {
    super::krl::compensate_with(a, quiet, compensate_to)
}

/// What a compensation of TP programs runs with: that of KRL programs.
pub(super) use super::krl::Job;

/// Compensates the TP program `src` into `out`, with its report; no file
/// is put in place unless all are written.
pub(super) fn compensate_to(
    job: &Job,
    (src, more): (&Path, &[PathBuf]),
    out: &Path,
    report: Option<(&Path, super::Format)>,
) -> Result<crate::compensate::outcome::Summary> {
    let t = read(src, more)?;
    super::machines::refuse_compensated(t.text.as_bytes(), &t.name, job.recompensate)?;
    let (steps, mut run) = run(&t, job.robot, job.opts)?;
    let solved = run.solved();
    let how = TpWrite {
        decimals: job.opts.format.position_decimals,
        compensate: job.opts.effects.compensates(),
        annotate: job.opts.annotate,
    };
    let u = job.provenance.uncertainty.as_deref();
    let (text, warnings) = rewrite(&t.text, &t.program, &steps, &solved, (job.robot, u), how)?;
    run.summary.warnings.extend(warnings);
    let inputs = [t.path.as_path()];
    super::output::refuse_overwrite(out, &inputs)?;
    let mut pending = vec![stage(out, &with_header(&text, job.provenance), t.charset)?];
    if let Some((path, format)) = report {
        super::output::refuse_overwrite(path, &inputs)?;
        let mut rep = Staged::open(path)?;
        write_report(rep.writer(), run.clone(), &t.name, format, job.provenance)?;
        pending.push(rep.finish()?);
    }
    for p in pending {
        p.commit()?;
    }
    Ok(run.summary)
}

/// `postproc report` of a TP program (a dry run against a robot).
pub fn report(a: &ReportArgs) -> Result<i32> {
    let (robot, loaded) = robot_of(a.program.machine.as_deref(), "report", Some(&a.effects))?;
    let t = read(&a.program.file, &a.program.more)?;
    let opts = RobotOptions {
        strict: a.program.strict,
        ..super::rapid::rapid_options(&robot, &a.effects, false, None)?
    };
    let (_, run) = run(&t, &robot, &opts)?;
    let provenance = super::machines::provenance(
        &loaded,
        super::machines::robot_effects(&opts.effects),
        None,
        false,
    );
    let out = a.output.clone().unwrap_or_else(|| PathBuf::from("-"));
    super::output::refuse_overwrite(&out, &[t.path.as_path()])?;
    super::output::emit_to(&out, |w| {
        write_report(w, run, &t.name, a.format, &provenance)
    })?;
    Ok(0)
}
