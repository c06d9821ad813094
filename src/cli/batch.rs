//! `postproc batch`: compensates many programs (G-code and RAPID, given as
//! files or folders) into an output folder, in parallel, carrying on past a
//! bad file, and writes `batch-summary.json`.
//!
//! Determinism: the programs are sorted by input path, each is compensated
//! by the same deterministic pipeline as `compensate`, and the summary holds
//! no times, so every byte written is the same for any `--threads`.
//! Every output is written atomically (temporary file, then rename).

use std::collections::{BTreeMap, BTreeSet};
use std::io::{BufReader, IsTerminal, Write};
use std::path::{Path, PathBuf};

use rayon::prelude::*;
use serde::Serialize;

use super::config::{Given, Kind};
use super::gcode::{build_job, effects, parse_setup, process_setup, run_reporting, thread_pool};
use super::output::{Staged, finish_both, refuse_overwrite, write_atomically};
use super::rapid::Source;
use super::{Annotate, BatchArgs, Format, ProgramArgs, usage};
use crate::emit::header::{HeaderWriter, Provenance};
use crate::error::{Error, Result};
use crate::machine::Machine;
use crate::pipeline::rapid::{RapidOptions, compensate_module};

/// Extensions of the programs picked up from folders.
pub use crate::program::language::{GCODE_EXTENSIONS, RAPID_EXTENSIONS};
/// Name of the summary written into the output folder.
pub const SUMMARY_FILE: &str = "batch-summary.json";

fn extension(path: &Path) -> Option<String> {
    path.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
}

fn is_program(path: &Path) -> bool {
    extension(path).is_some_and(|e| {
        GCODE_EXTENSIONS.contains(&e.as_str()) || RAPID_EXTENSIONS.contains(&e.as_str())
    })
}

fn is_rapid(path: &Path) -> bool {
    crate::program::language::is_rapid(path)
}

/// Whether a file without a program extension is a program of the
/// machine's language by its first block (a RAPID module for a robot,
/// G-code for a machine tool).
fn sniffed(path: &Path, robot: bool) -> bool {
    use crate::program::language::{
        gcode_extension, gcode_text, head, rapid_extension, rapid_text,
    };
    if rapid_extension(path) || gcode_extension(path) {
        return false;
    }
    head(path).is_some_and(|h| {
        let rapid = rapid_text(&h);
        if robot {
            rapid
        } else {
            !rapid && gcode_text(&h)
        }
    })
}

/// One program to compensate: where it is, where its output goes (relative
/// to the output folder), or why it cannot be taken.
#[derive(Debug, Clone)]
struct Item {
    input: PathBuf,
    rel: PathBuf,
    problem: Option<String>,
    /// A RAPID program of several modules (a task folder, a `.pgf`).
    program: bool,
    /// The message of a file in a language postproc does not read
    /// ([`crate::program::language::unread`]).
    unread: Option<String>,
}

impl Item {
    /// One program file under `root` (its name in the output folder kept
    /// relative to it), or one in a language not read (`unread`).
    fn file(input: PathBuf, root: &Path, unread: Option<String>) -> Item {
        let rel = super::output::folder_name(&input, &[root]);
        Item {
            input,
            rel,
            problem: None,
            program: false,
            unread,
        }
    }
}

/// The message of the file at `path` when it is in a language postproc
/// does not read.
fn unread(path: &Path) -> Option<String> {
    crate::program::language::unread(path).map(|n| n.error(&path.display().to_string()).to_string())
}

/// Programs under a folder, recursively, in name order; hidden entries,
/// the output folder, compensated outputs (`*.comp.*`), anything but
/// regular files (named pipes, devices), links that lead out of the input
/// folder (with a warning) and folders seen before (a link back up the
/// tree) are skipped. For a robot, a task folder below (one
/// with `PROGMOD` or `SYSMOD`, as in a controller backup) is one program.
/// A file without a program extension is taken when its first block is
/// one of the machine's language. A folder that cannot be read becomes a
/// failed entry.
fn walk(
    (root, robot): (&Path, bool),
    dir: &Path,
    skip: Option<&Path>,
    seen: &mut BTreeSet<PathBuf>,
    items: &mut Vec<Item>,
    skipped: &mut Vec<Skipped>,
) {
    if let Ok(canonical) = dir.canonicalize() {
        if !seen.insert(canonical) {
            return;
        }
    }
    let read = match std::fs::read_dir(dir) {
        Ok(r) => r,
        Err(e) => {
            items.push(Item {
                input: dir.to_path_buf(),
                rel: dir.to_path_buf(),
                problem: Some(format!("{}: {e}", dir.display())),
                program: false,
                unread: None,
            });
            return;
        }
    };
    let mut entries: Vec<PathBuf> = read.filter_map(|e| e.ok().map(|e| e.path())).collect();
    entries.sort();
    for path in entries {
        let hidden = path
            .file_name()
            .is_some_and(|n| n.to_string_lossy().starts_with('.'));
        let mut skip_as = |reason: &str| {
            skipped.push(Skipped {
                path: path.display().to_string(),
                reason: reason.to_string(),
            })
        };
        if hidden {
            skip_as("hidden");
            continue;
        }
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        if leaves(root, &path) {
            tracing::warn!(
                "{}: a link out of the input folder {}, not followed",
                path.display(),
                root.display()
            );
            skip_as("a link out of the input folder");
            continue;
        }
        if path.is_dir() {
            if skip.is_some_and(|s| path.canonicalize().is_ok_and(|p| p == s)) {
                skip_as("the output folder");
                continue;
            }
            if robot && is_rapid_program(&path) {
                let rel = super::output::folder_name(&path, &[root]);
                items.push(Item {
                    input: path,
                    rel,
                    problem: None,
                    program: true,
                    unread: None,
                });
                continue;
            }
            walk((root, robot), &path, skip, seen, items, skipped);
        } else if super::output::is_compensated_name(&name) {
            skip_as("a compensated program (*.comp.*)");
        } else if robot && (super::krl::is_krl(&path) || super::tp::is_tp(&path)) && path.is_file()
        {
            items.push(Item::file(path, root, None));
        } else if robot && super::krl::is_krl_data(&path) {
            skip_as("a KRL data list (read with its .src)");
        } else if let Some(message) = path.is_file().then(|| unread(&path)).flatten() {
            items.push(Item::file(path, root, Some(message)));
        } else if is_program(&path) && is_rapid(&path) != robot {
            // A folder of both languages: the programs of the other one are
            // for another machine.
            skip_as(if robot {
                "a G-code program, and the machine is a robot"
            } else {
                "a RAPID module, and the machine is a machine tool"
            });
        } else if !is_program(&path) && !sniffed(&path, robot) {
            skip_as("not a program (by its extension or its first block)");
        } else if !path.is_file() {
            skip_as("not a regular file");
        } else {
            items.push(Item::file(path, root, None));
        }
    }
}

/// Whether `path` is a symbolic link whose target lies outside the input
/// folder `root` (or cannot be resolved): a batch never leaves its inputs.
fn leaves(root: &Path, path: &Path) -> bool {
    if !std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_symlink()) {
        return false;
    }
    match (root.canonicalize(), path.canonicalize()) {
        (Ok(root), Ok(target)) => !target.starts_with(root),
        _ => false,
    }
}

/// A file or folder of the inputs' folders that is not compensated, and
/// why.
#[derive(Debug, Clone, Serialize, serde::Deserialize, PartialEq, Eq, PartialOrd, Ord)]
struct Skipped {
    path: String,
    reason: String,
}

/// Expands the inputs into programs, sorted by input path, each file once
/// however it is reached; an input that does not exist, or two programs
/// with one output name, become failures. Also gives the entries of the
/// folders that are skipped.
fn collect(inputs: &[PathBuf], out_dir: &Path, robot: bool) -> (Vec<Item>, Vec<Skipped>) {
    let skip = out_dir.canonicalize().ok();
    let mut items = Vec::new();
    let mut skipped = Vec::new();
    for input in inputs {
        if robot && is_rapid_program(input) {
            let rel = match input.is_dir() {
                true => input.file_name().map(PathBuf::from),
                false => input.file_stem().map(PathBuf::from),
            };
            items.push(Item {
                input: input.clone(),
                rel: rel.unwrap_or_else(|| PathBuf::from("program")),
                problem: None,
                program: true,
                unread: None,
            });
        } else if input.is_dir() {
            // Folders are followed once per input (links may lead back).
            let mut seen = BTreeSet::new();
            walk(
                (input, robot),
                input,
                skip.as_deref(),
                &mut seen,
                &mut items,
                &mut skipped,
            );
        } else {
            let rel = super::output::folder_name::<&Path>(input, &[]);
            let problem = match std::fs::metadata(input) {
                Ok(m) if m.is_file() => None,
                Ok(_) => Some(format!("{}: not a regular file", input.display())),
                Err(_) => Some(format!("{}: no such file", input.display())),
            };
            let krl = robot && (super::krl::is_krl(input) || super::tp::is_tp(input));
            let unread = (problem.is_none() && !krl).then(|| unread(input)).flatten();
            items.push(Item {
                input: input.clone(),
                rel,
                problem,
                program: false,
                unread,
            });
        }
    }
    items.sort_by(|a, b| a.input.cmp(&b.input));
    items.dedup_by(|a, b| a.input == b.input);
    // One file named two ways (`./a.nc`, `d/../a.nc`, a link): the first
    // spelling in path order is kept.
    let mut files = BTreeSet::new();
    items.retain(|item| match item.input.canonicalize() {
        Ok(c) if item.problem.is_none() => files.insert(c),
        _ => true,
    });
    let mut owner: BTreeMap<PathBuf, PathBuf> = BTreeMap::new();
    for item in &mut items {
        if item.problem.is_some() || item.unread.is_some() {
            continue;
        }
        match owner.get(&item.rel) {
            Some(first) => {
                item.problem = Some(format!(
                    "{}: its output name {} is already taken by {}",
                    item.input.display(),
                    item.rel.display(),
                    first.display()
                ));
            }
            None => {
                owner.insert(item.rel.clone(), item.input.clone());
            }
        }
    }
    skipped.sort();
    skipped.dedup();
    (items, skipped)
}

/// True when `input` is a RAPID program of several modules for a robot
/// batch: a `.pgf` program file, or a task folder (one with a `PROGMOD` or
/// `SYSMOD` sub-folder, as a controller backup has).
fn is_rapid_program(input: &Path) -> bool {
    if crate::program::rapid::program::is_pgf(input) {
        return input.is_file();
    }
    ["PROGMOD", "SYSMOD"].iter().any(|sub| {
        std::fs::read_dir(input).is_ok_and(|mut r| {
            r.any(|e| {
                e.is_ok_and(|e| {
                    e.path().is_dir() && e.file_name().to_string_lossy().eq_ignore_ascii_case(sub)
                })
            })
        })
    })
}

/// Result of one program, as written to `batch-summary.json`.
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct FileResult {
    input: String,
    output: Option<String>,
    report: Option<String>,
    /// `ok`, `empty` (written, but it has no moves), `findings` (out of
    /// tolerance), `failed`, or `unread` (in a language postproc does not
    /// read, named in `error`).
    status: String,
    error: Option<String>,
    blocks: usize,
    moves: usize,
    /// `None` for a failed program.
    max_deviation_mm: Option<f64>,
    max_deviation_line: Option<usize>,
    max_residual_mm: Option<f64>,
}

/// `--shard K/N`: the K-th (1-based) of N shares of the programs.
#[derive(Debug, Clone, Copy, Serialize, serde::Deserialize, PartialEq, Eq)]
#[serde(deny_unknown_fields)]
pub struct Shard {
    /// K, 1..=N.
    pub index: usize,
    /// N, at least 1.
    pub count: usize,
}

/// Parses `K/N` (1 <= K <= N); the message names the value, not the flag.
impl std::str::FromStr for Shard {
    type Err = String;
    fn from_str(text: &str) -> std::result::Result<Self, String> {
        let bad = || format!("`{text}`: expected K/N with 1 <= K <= N");
        let (k, n) = text.split_once('/').ok_or_else(bad)?;
        let (index, count): (usize, usize) = (
            k.trim().parse().map_err(|_| bad())?,
            n.trim().parse().map_err(|_| bad())?,
        );
        if index == 0 || index > count {
            return Err(bad());
        }
        Ok(Shard { index, count })
    }
}

/// The `--shard` value: `K/N`, or `auto` (`auto/N`) for the scheduler's
/// index and count ([`ShardSpec::resolve`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ShardSpec {
    /// `K/N` as given.
    Given(Shard),
    /// `auto` or `auto/N`: K (and N) from the environment.
    Auto(Option<usize>),
}

impl std::str::FromStr for ShardSpec {
    type Err = String;
    fn from_str(text: &str) -> std::result::Result<Self, String> {
        let t = text.trim();
        if t == "auto" {
            return Ok(ShardSpec::Auto(None));
        }
        if let Some(n) = t.strip_prefix("auto/") {
            return match n.trim().parse::<usize>() {
                Ok(n) if n >= 1 => Ok(ShardSpec::Auto(Some(n))),
                _ => Err(format!("`{text}`: expected auto/N with N >= 1")),
            };
        }
        text.parse::<Shard>()
            .map(ShardSpec::Given)
            .map_err(|e| format!("{e}, auto or auto/N"))
    }
}

impl ShardSpec {
    /// The shard of this run: `K/N` as given; for `auto`, from the
    /// scheduler's variables `var` reads: a Slurm job array's
    /// `SLURM_ARRAY_TASK_ID` counted from `SLURM_ARRAY_TASK_MIN` (by
    /// `SLURM_ARRAY_TASK_STEP`), of `SLURM_ARRAY_TASK_COUNT` tasks (else
    /// `MAX`, `MIN` and `STEP` say how many), or a Kubernetes indexed
    /// Job's `JOB_COMPLETION_INDEX` (from 0), whose count `auto/N` gives.
    /// An N given with `auto/N` must agree with Slurm's count. Returns the
    /// shard and where it came from.
    pub fn resolve(
        self,
        var: impl Fn(&str) -> Option<String>,
    ) -> std::result::Result<(Shard, String), String> {
        let n = match self {
            ShardSpec::Given(s) => return Ok((s, format!("{}/{}", s.index, s.count))),
            ShardSpec::Auto(n) => n,
        };
        let num = |name: &str| -> std::result::Result<Option<usize>, String> {
            match var(name) {
                None => Ok(None),
                Some(v) if v.trim().is_empty() => Ok(None),
                Some(v) => v.trim().parse::<usize>().map(Some).map_err(|_| {
                    format!(
                        "--shard auto: {name}=`{}` is not a whole number",
                        crate::error::clip(&v)
                    )
                }),
            }
        };
        let slurm = num("SLURM_ARRAY_TASK_ID")?;
        let k8s = num("JOB_COMPLETION_INDEX")?;
        let (index, count, from) = match (slurm, k8s) {
            (Some(_), Some(_)) => {
                return Err(
                    "--shard auto: both SLURM_ARRAY_TASK_ID and JOB_COMPLETION_INDEX are set; give --shard K/N"
                        .into(),
                );
            }
            (Some(id), None) => {
                let min = num("SLURM_ARRAY_TASK_MIN")?.unwrap_or(1);
                let step = num("SLURM_ARRAY_TASK_STEP")?.unwrap_or(1).max(1);
                if id < min || (id - min) % step != 0 {
                    return Err(format!(
                        "--shard auto: SLURM_ARRAY_TASK_ID={id} is not a task of an array from {min} by {step}"
                    ));
                }
                let counted = match (num("SLURM_ARRAY_TASK_COUNT")?, num("SLURM_ARRAY_TASK_MAX")?) {
                    (Some(c), _) => Some(c),
                    (None, Some(max)) if max >= min => Some((max - min) / step + 1),
                    _ => None,
                };
                let count = match (counted, n) {
                    (Some(c), Some(n)) if c != n => {
                        return Err(format!("--shard auto/{n}: the Slurm array has {c} tasks"));
                    }
                    (Some(c), _) | (None, Some(c)) => c,
                    (None, None) => {
                        return Err(
                            "--shard auto: SLURM_ARRAY_TASK_ID without SLURM_ARRAY_TASK_COUNT or SLURM_ARRAY_TASK_MAX; give --shard auto/N"
                                .into(),
                        );
                    }
                };
                (
                    (id - min) / step + 1,
                    count,
                    format!("SLURM_ARRAY_TASK_ID={id}"),
                )
            }
            (None, Some(i)) => {
                let count = n.ok_or(
                    "--shard auto: JOB_COMPLETION_INDEX does not say how many pods there are; give --shard auto/N (the Job's completions)",
                )?;
                (i + 1, count, format!("JOB_COMPLETION_INDEX={i}"))
            }
            (None, None) => {
                return Err(
                    "--shard auto: no scheduler index in the environment (SLURM_ARRAY_TASK_ID of a Slurm job array, JOB_COMPLETION_INDEX of a Kubernetes indexed Job)"
                        .into(),
                );
            }
        };
        if index == 0 || index > count {
            return Err(format!(
                "--shard auto: {from} gives shard {index} of {count}, outside 1..={count}"
            ));
        }
        Ok((Shard { index, count }, from))
    }
}

/// The shard of this run from `--shard` and the environment, logged.
fn shard_of_run(spec: ShardSpec) -> Result<Shard> {
    let (shard, from) = spec
        .resolve(|name| std::env::var(name).ok())
        .map_err(usage)?;
    tracing::info!("shard {}/{} ({from})", shard.index, shard.count);
    Ok(shard)
}

/// The summary file.
#[derive(Debug, Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct BatchSummary {
    machine: String,
    tolerance_mm: f64,
    /// What made the outputs (docs/provenance.md).
    provenance: serde_json::Value,
    /// The share of the inputs this summary covers (`None`: all of them;
    /// a merged summary lists the shards it holds in `merged`).
    shard: Option<Shard>,
    merged: Vec<Shard>,
    programs: usize,
    ok: usize,
    empty: usize,
    findings: usize,
    failed: usize,
    exit_code: i32,
    results: Vec<FileResult>,
    skipped: Vec<Skipped>,
}

/// Rounds to 6 decimals (1 nm) for the summary.
fn round6(v: f64) -> f64 {
    (v * 1e6).round() / 1e6
}

/// An error with its source chain, as the binary prints it.
fn message(e: &Error) -> String {
    let mut msg = e.to_string();
    let mut src = std::error::Error::source(e);
    while let Some(s) = src {
        msg.push_str(&format!(": {s}"));
        src = s.source();
    }
    msg
}

/// What one compensation gave.
struct Done {
    blocks: usize,
    moves: usize,
    max_dev: f64,
    /// `None` for a program of several modules (no one file's line).
    max_line: Option<usize>,
    residual: Option<f64>,
}

/// The configured engine for the batch's machine.
enum Engine<'m> {
    Tool(Box<crate::pipeline::gcode::Job<'m>>),
    /// A robot, the options of its runs, and the window size forced by
    /// `--rapid-window-lines`.
    Robot(crate::machine::robot::Robot, RapidOptions, Option<usize>),
}

/// What every program of the batch shares: the engine, the provenance its
/// outputs carry, and whether programs compensated before are taken.
struct Setting<'m> {
    engine: Engine<'m>,
    provenance: Provenance,
    recompensate: bool,
}

/// Path of a program's report beside its output: `<output>.report.<ext>`.
fn report_path(output: &Path, format: Format) -> PathBuf {
    let ext = match format {
        Format::Table => "txt",
        Format::Csv => "csv",
        Format::Json => "json",
        Format::Svg => "svg",
        Format::Html => "html",
    };
    let mut name = output.as_os_str().to_owned();
    name.push(format!(".report.{ext}"));
    PathBuf::from(name)
}

fn compensate_one(
    setting: &Setting,
    input: &Path,
    output: &Path,
    report: Option<Format>,
    files: &[PathBuf],
) -> Result<Done> {
    // Neither output may be an input (the program, the machine file, the
    // force table), also through a link planted in the output folder.
    let mut inputs = vec![input.to_path_buf()];
    inputs.extend_from_slice(files);
    refuse_overwrite(output, &inputs)?;
    if let Some(format) = report {
        refuse_overwrite(&report_path(output, format), &inputs)?;
    }
    if let Some(dir) = output.parent() {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    }
    let name = input.display().to_string();
    let provenance = &setting.provenance;
    match &setting.engine {
        Engine::Tool(job) => {
            if super::krl::is_krl(input) {
                return Err(usage(format!(
                    "{name}: a KRL program needs a robot machine file"
                )));
            }
            if is_rapid(input) {
                return Err(usage(format!(
                    "{name}: a RAPID module needs a robot machine file"
                )));
            }
            let f = std::fs::File::open(input).map_err(|e| Error::io(input, e))?;
            let reader = Box::new(BufReader::with_capacity(1 << 16, f));
            let (head, reader) = super::machines::peek_head(reader, &name)?;
            super::machines::refuse_compensated(&head, &name, setting.recompensate)?;
            let s = match report {
                Some(format) => {
                    // Neither output is put in place unless both are written.
                    let mut rep = Staged::open(&report_path(output, format))?;
                    let mut out = Staged::open(output)?;
                    let mut hw = HeaderWriter::new(out.writer(), provenance.clone(), false);
                    let s = run_reporting(
                        job,
                        reader,
                        &name,
                        Some(&mut hw),
                        rep.writer(),
                        format,
                        Some(provenance),
                    )?;
                    hw.finish().map_err(|e| Error::io(output, e))?;
                    finish_both(out, rep)?;
                    s
                }
                None => write_atomically(output, |w| {
                    let mut hw = HeaderWriter::new(w, provenance.clone(), false);
                    let s = job.run(reader, &name, Some(&mut hw), None)?;
                    hw.finish().map_err(|e| Error::io(output, e))?;
                    Ok(s)
                })?,
            };
            Ok(Done {
                blocks: s.blocks,
                moves: s.moves,
                max_dev: s.deviation.max,
                max_line: Some(s.deviation.max_line),
                residual: Some(s.max_residual_mm),
            })
        }
        Engine::Robot(robot, opts, _) if super::krl::is_krl(input) || super::tp::is_tp(input) => {
            let opts = crate::pipeline::rapid::RapidOptions {
                records: report.is_some(),
                ..opts.clone()
            };
            let job = super::krl::Job {
                robot,
                opts: &opts,
                provenance,
                recompensate: setting.recompensate,
            };
            let report_file = report.map(|f| (report_path(output, f), f));
            let report_to = report_file.as_ref().map(|(p, f)| (p.as_path(), *f));
            let s = if super::tp::is_tp(input) {
                super::tp::compensate_to(&job, (input, &[]), output, report_to)?
            } else {
                super::krl::compensate_to(&job, (input, &[]), output, report_to)?
            };
            Ok(Done {
                blocks: s.moves,
                moves: s.moves,
                max_dev: s.deviation.max,
                max_line: Some(s.deviation.max_line),
                residual: None,
            })
        }
        Engine::Robot(robot, opts, forced_window) => {
            if !is_rapid(input) {
                return Err(usage(format!(
                    "{name}: a G-code program needs a machine-tool machine file"
                )));
            }
            // Move records only feed the report.
            let opts = crate::pipeline::rapid::RapidOptions {
                records: report.is_some(),
                ..opts.clone()
            };
            let report_file = report.map(|f| (report_path(output, f), f));
            let report_to = report_file.as_ref().map(|(p, f)| (p.as_path(), *f));
            let done = |o: &crate::compensate::outcome::Summary| Done {
                blocks: o.moves,
                moves: o.moves,
                max_dev: o.deviation.max,
                max_line: Some(o.deviation.max_line),
                residual: None,
            };
            // A large module is read a window at a time, as by `compensate`.
            let warm = crate::pipeline::rapid::stream::first_pass(robot, &opts);
            let source = Source::new(input, *forced_window, warm)?;
            super::machines::refuse_compensated(
                &source.head()?,
                source.name(),
                setting.recompensate,
            )?;
            if let Some(lines) = source.window_lines() {
                let streamed = super::rapid::compensate_streamed_to(
                    &source,
                    robot,
                    &opts,
                    lines,
                    Some(output),
                    report_to,
                    provenance,
                )?;
                if let Some(outcome) = streamed {
                    return Ok(done(&outcome));
                }
            }
            let (src, name, charset) = source.read_whole_text()?;
            let outcome = compensate_module(&src, &name, robot, &opts)
                .map_err(|e| crate::program::charset::file_columns(e, &src, charset))?;
            super::rapid::write_outcome(output, &outcome, &name, report_to, provenance, charset)?;
            Ok(done(&outcome.summary))
        }
    }
}

/// Compensates the RAPID program of several modules at `input` (a task
/// folder, a `.pgf`): the modules that change are written into the folder
/// `output`, the report of every module beside it.
fn compensate_program(
    setting: &Setting,
    input: &Path,
    output: &Path,
    report: Option<Format>,
) -> Result<Done> {
    let Engine::Robot(robot, opts, _) = &setting.engine else {
        return Err(usage(format!(
            "{}: a RAPID program needs a robot machine file",
            input.display()
        )));
    };
    let opts = RapidOptions {
        records: report.is_some(),
        ..opts.clone()
    };
    let run = super::rapid::ProgramRun {
        robot,
        opts: &opts,
        provenance: &setting.provenance,
        recompensate: setting.recompensate,
    };
    let report_file = report.map(|f| (report_path(output, f), f));
    // The report lands beside the program's folder (`out/RAPID/TASK1` and
    // `out/RAPID/TASK1.report.csv`): its folder is made like the program's.
    if let Some(dir) = report_file.as_ref().and_then(|(p, _)| p.parent()) {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    }
    let report_to = report_file.as_ref().map(|(p, f)| (p.as_path(), *f));
    let (_, _, total, worst) =
        super::rapid::compensate_program_to(&run, &[input.to_path_buf()], Some(output), report_to)?;
    Ok(Done {
        blocks: total.moves,
        moves: total.moves,
        max_dev: worst.0,
        max_line: None,
        residual: None,
    })
}

/// The progress bar of `n` programs: hidden when `quiet` or when standard
/// error is not a terminal.
fn progress_bar(quiet: bool, n: usize) -> indicatif::ProgressBar {
    if quiet || !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let b = indicatif::ProgressBar::new(n as u64);
    if let Ok(style) = indicatif::ProgressStyle::with_template(
        "{bar:40} {pos}/{len} programs {elapsed_precise} {wide_msg}",
    ) {
        b.set_style(style);
    }
    b
}

/// The summary line of the program `input` written to `output`: its
/// status, counts and deviation, or its error.
fn file_result(
    input: &Path,
    output: &Path,
    done: Result<Done>,
    report_format: Option<Format>,
    tolerance: f64,
) -> FileResult {
    let input = input.display().to_string();
    match done {
        Ok(d) => {
            let findings = d.residual.is_some_and(|r| r > tolerance);
            let status = match (findings, d.moves) {
                (true, _) => "findings",
                (false, 0) => "empty",
                (false, _) => "ok",
            };
            FileResult {
                input,
                output: Some(output.display().to_string()),
                report: report_format.map(|f| report_path(output, f).display().to_string()),
                status: status.into(),
                error: None,
                blocks: d.blocks,
                moves: d.moves,
                max_deviation_mm: Some(round6(d.max_dev)),
                max_deviation_line: d.max_line,
                max_residual_mm: d.residual.map(round6),
            }
        }
        Err(e) => {
            tracing::debug!("{}", message(&e));
            FileResult {
                input,
                output: None,
                report: None,
                status: "failed".into(),
                error: Some(message(&e)),
                blocks: 0,
                moves: 0,
                max_deviation_mm: None,
                max_deviation_line: None,
                max_residual_mm: None,
            }
        }
    }
}

/// The summary line of a file in a language postproc does not read.
fn unread_result(input: &Path, message: &str) -> FileResult {
    FileResult {
        input: input.display().to_string(),
        output: None,
        report: None,
        status: "unread".into(),
        error: Some(message.to_string()),
        blocks: 0,
        moves: 0,
        max_deviation_mm: None,
        max_deviation_line: None,
        max_residual_mm: None,
    }
}

/// `postproc batch`; `quiet` hides the progress bar.
pub fn run(a: &BatchArgs, quiet: bool) -> Result<i32> {
    if a.merge_summaries {
        return merge(a);
    }
    let machine_name = a
        .machine
        .clone()
        .ok_or_else(|| usage("batch needs --machine"))?;
    let pool = thread_pool(a.effects.threads)?;
    let (machine, mut loaded) = super::machines::open(&machine_name)?;
    Given {
        tools_or_offsets: !a.tools.is_empty() || !a.work_offsets.is_empty(),
        units: a.units.is_some(),
        tolerance: a.tolerance.is_some(),
        allow_reconfiguration: a.effects.allow_reconfiguration,
        rapid_window_lines: a.rapid_window_lines.is_some(),
        gain_auto: a.effects.gain_auto,
    }
    .refuse_for(match machine {
        Machine::Tool(_) => Kind::Tool,
        Machine::Robot(_) => Kind::Robot,
    })?;
    let tolerance = super::gcode::tolerance_for(a.tolerance, &machine);
    // The files every program's run reads besides the program itself.
    let mut files: Vec<PathBuf> = loaded.file.path.iter().cloned().collect();
    files.extend(a.effects.force_table.clone());
    let (items, skipped) = collect(&a.inputs, &a.out_dir, matches!(machine, Machine::Robot(_)));
    let shard = a.shard.map(shard_of_run).transpose()?;
    if items.is_empty() {
        return Err(usage(format!(
            "no programs found (extensions: {}, {})",
            GCODE_EXTENSIONS.join(" "),
            RAPID_EXTENSIONS.join(" ")
        )));
    }
    let annotate = a.annotate == Annotate::Comment;
    let tool;
    let process;
    let (engine, effects_run) = match machine {
        Machine::Tool(m) => {
            tool = m;
            let program = ProgramArgs {
                file: PathBuf::new(),
                machine: None,
                tools: a.tools.clone(),
                work_offsets: a.work_offsets.clone(),
                units: a.units,
                rapid_window_lines: None,
                strict: false,
                compensate_joint_targets: false,
                expand_cycles: false,
                more: Vec::new(),
            };
            let setup = parse_setup(&program, Some(&tool))?;
            process = process_setup(&a.effects, &tool)?;
            if process.thermal_start.needs_mean_power() && tool.thermal().is_some() {
                return Err(usage(
                    "batch starts every program cold (--thermal-start cold); a steady or warm-up start needs each program's mean power, so compensate those one by one",
                ));
            }
            let set =
                super::machines::auto_gain(effects(&a.effects)?, a.effects.gain_auto, &mut loaded)?;
            let mut job = build_job(
                &tool, &process, &pool, setup, set, tolerance, None, annotate,
            )?;
            // The programs already run on the pool's threads.
            job.pool = None;
            // Annotations state U from the file's covariance, as `compensate`'s.
            let u = loaded.uncertainty.as_ref();
            job.predictor = job.predictor.map(|p| p.with_uncertainty(u));
            (
                Engine::Tool(Box::new(job)),
                super::machines::tool_effects(&set),
            )
        }
        Machine::Robot(robot) => {
            let robot = super::rapid::robot_with_process(robot, &a.effects)?;
            let opts = crate::pipeline::rapid::RapidOptions {
                strict: a.strict,
                uncertainty: loaded.uncertainty.clone(),
                ..super::rapid::rapid_options(&robot, &a.effects, annotate, None)?
            };
            if a.rapid_window_lines == Some(0) {
                return Err(usage("--rapid-window-lines must be at least 1"));
            }
            let effects = super::machines::robot_effects(&opts.effects);
            (Engine::Robot(robot, opts, a.rapid_window_lines), effects)
        }
    };
    let is_tool = matches!(engine, Engine::Tool(_));
    let setting = Setting {
        engine,
        provenance: super::machines::provenance(
            &loaded,
            effects_run,
            is_tool.then_some(tolerance),
            annotate,
        ),
        recompensate: a.recompensate,
    };
    // The output folder is made once every option has been checked; the
    // summary may not be an input either (checked before any program).
    std::fs::create_dir_all(&a.out_dir).map_err(|e| Error::io(&a.out_dir, e))?;
    refuse_overwrite(&a.out_dir.join(SUMMARY_FILE), &files)?;
    let bar = progress_bar(quiet, items.len());
    let items: Vec<Item> = match shard {
        Some(sh) => items
            .into_iter()
            .enumerate()
            .filter(|(i, _)| i % sh.count == sh.index - 1)
            .map(|(_, item)| item)
            .collect(),
        None => items,
    };
    let results: Vec<FileResult> = pool.install(|| {
        items
            .par_iter()
            .map(|item| {
                let output = a.out_dir.join(&item.rel);
                if let Some(message) = &item.unread {
                    bar.inc(1);
                    return unread_result(&item.input, message);
                }
                let done = match &item.problem {
                    Some(p) => Err(usage(p.clone())),
                    None if item.program => {
                        compensate_program(&setting, &item.input, &output, a.report_format)
                    }
                    None => compensate_one(&setting, &item.input, &output, a.report_format, &files),
                };
                bar.inc(1);
                file_result(&item.input, &output, done, a.report_format, tolerance)
            })
            .collect()
    });
    bar.finish_and_clear();
    let summary = summarize(
        machine_name,
        tolerance,
        setting.provenance.to_json(),
        shard,
        Vec::new(),
        results,
        skipped,
    );
    let summary_path = a.out_dir.join(SUMMARY_FILE);
    write_summary(&summary_path, &summary)?;
    print_summary(&summary, &summary_path)?;
    Ok(summary.exit_code)
}

/// The summary of `results`: the counts and the exit code.
fn summarize(
    machine: String,
    tolerance_mm: f64,
    provenance: serde_json::Value,
    shard: Option<Shard>,
    merged: Vec<Shard>,
    results: Vec<FileResult>,
    skipped: Vec<Skipped>,
) -> BatchSummary {
    let count = |s: &str| results.iter().filter(|r| r.status == s).count();
    let (ok, empty, findings, failed) = (
        count("ok"),
        count("empty"),
        count("findings"),
        count("failed"),
    );
    let exit_code = if failed > 0 || count("unread") > 0 {
        2
    } else if findings > 0 {
        1
    } else {
        0
    };
    BatchSummary {
        machine,
        tolerance_mm,
        provenance,
        shard,
        merged,
        programs: results.len(),
        ok,
        empty,
        findings,
        failed,
        exit_code,
        results,
        skipped,
    }
}

fn write_summary(path: &Path, summary: &BatchSummary) -> Result<()> {
    write_atomically(path, |w| {
        serde_json::to_writer_pretty(&mut *w, summary)
            .map_err(|e| Error::io(path, std::io::Error::other(e)))?;
        w.write_all(b"\n").map_err(|e| Error::io(path, e))
    })
}

/// Prints the failed, empty and out-of-tolerance programs, the skipped
/// entries and the totals on standard output.
fn print_summary(summary: &BatchSummary, summary_path: &Path) -> Result<()> {
    let mut out = std::io::stdout().lock();
    let mut say = |t: String| {
        out.write_all(t.as_bytes())
            .map_err(|e| Error::io("stdout", e))
    };
    for r in &summary.results {
        match r.status.as_str() {
            "empty" => say(format!("empty     {}: no moves\n", r.input))?,
            "failed" => {
                // An error that names the program first names it once.
                let error = r.error.as_deref().unwrap_or("");
                let prefix = format!("{}: ", r.input);
                let error = error.strip_prefix(&prefix).unwrap_or(error);
                say(format!("failed    {}: {error}\n", r.input))?
            }
            "findings" => say(format!(
                "findings  {}: residual {} mm > tolerance {} mm\n",
                r.input,
                r.max_residual_mm.unwrap_or(0.0),
                summary.tolerance_mm
            ))?,
            "unread" => say(format!("unread    {}\n", r.error.as_deref().unwrap_or("")))?,
            _ => {}
        }
    }
    for sk in &summary.skipped {
        say(format!("skipped   {}: {}\n", sk.path, sk.reason))?;
    }
    let unread = summary
        .results
        .iter()
        .filter(|r| r.status == "unread")
        .count();
    // Files in a language postproc does not read: counted apart from the
    // failures of programs it reads, and only when there are some.
    let unread = match unread {
        0 => String::new(),
        n => format!(", {n} in a language not read"),
    };
    say(format!(
        "batch: {} programs: {} compensated ({} with findings, {} empty), {} failed{unread}; {} skipped; summary in {}\n",
        summary.programs,
        summary.ok + summary.findings + summary.empty,
        summary.findings,
        summary.empty,
        summary.failed,
        summary.skipped.len(),
        summary_path.display()
    ))?;
    Ok(())
}

/// `postproc batch --merge-summaries`: the summaries of the shards of one
/// batch (the same machine, tolerance and provenance, each shard once)
/// merged into `--out-dir`/batch-summary.json, results in input order.
fn merge(a: &BatchArgs) -> Result<i32> {
    let mut parts = Vec::new();
    for path in &a.inputs {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        let part: BatchSummary = serde_json::from_str(&text).map_err(|e| {
            usage(format!(
                "{}: not a batch summary of this postproc: {e}",
                path.display()
            ))
        })?;
        parts.push((path, part));
    }
    let Some((first_path, first)) = parts.first() else {
        return Err(usage("--merge-summaries needs the summaries of the shards"));
    };
    let mut shards = Vec::new();
    for (path, part) in &parts {
        if part.machine != first.machine
            || part.tolerance_mm != first.tolerance_mm
            || part.provenance != first.provenance
        {
            return Err(usage(format!(
                "{}: another machine, tolerance or provenance than {}: not shards of one batch",
                path.display(),
                first_path.display()
            )));
        }
        let here: Vec<Shard> = match part.shard {
            Some(s) => vec![s],
            None => part.merged.clone(),
        };
        if here.is_empty() {
            return Err(usage(format!(
                "{}: the summary of a whole batch, not of a shard",
                path.display()
            )));
        }
        shards.extend(here);
    }
    shards.sort_by_key(|s| (s.count, s.index));
    let count = shards[0].count;
    if let Some(s) = shards.iter().find(|s| s.count != count) {
        return Err(usage(format!(
            "shards of {count} and of {} programs' shares mixed",
            s.count
        )));
    }
    if let Some(w) = shards.windows(2).find(|w| w[0] == w[1]) {
        return Err(usage(format!(
            "shard {}/{} given twice",
            w[0].index, w[0].count
        )));
    }
    if shards.len() < count {
        let missing: Vec<String> = (1..=count)
            .filter(|k| !shards.iter().any(|s| s.index == *k))
            .map(|k| format!("{k}/{count}"))
            .collect();
        tracing::warn!("shards missing: {}", missing.join(", "));
    }
    let machine = first.machine.clone();
    let tolerance = first.tolerance_mm;
    let provenance = first.provenance.clone();
    let mut results = Vec::new();
    let mut skipped = Vec::new();
    for (_, part) in parts {
        results.extend(part.results);
        skipped.extend(part.skipped);
    }
    results.sort_by(|x, y| x.input.cmp(&y.input));
    if let Some(w) = results.windows(2).find(|w| w[0].input == w[1].input) {
        return Err(usage(format!("{} is in two shards' summaries", w[0].input)));
    }
    skipped.sort();
    skipped.dedup();
    let summary = summarize(
        machine, tolerance, provenance, None, shards, results, skipped,
    );
    std::fs::create_dir_all(&a.out_dir).map_err(|e| Error::io(&a.out_dir, e))?;
    let summary_path = a.out_dir.join(SUMMARY_FILE);
    refuse_overwrite(&summary_path, &a.inputs)?;
    write_summary(&summary_path, &summary)?;
    print_summary(&summary, &summary_path)?;
    Ok(summary.exit_code)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shard_auto_reads_the_schedulers_index_and_count() {
        let env = |pairs: &'static [(&'static str, &'static str)]| {
            move |name: &str| {
                pairs
                    .iter()
                    .find(|(k, _)| *k == name)
                    .map(|(_, v)| v.to_string())
            }
        };
        let auto: ShardSpec = "auto".parse().unwrap();
        let auto8: ShardSpec = "auto/8".parse().unwrap();
        let got =
            |spec: ShardSpec, pairs| spec.resolve(env(pairs)).map(|(s, _)| (s.index, s.count));
        // Slurm `--array=1-8`: tasks 1..8.
        let slurm = &[
            ("SLURM_ARRAY_TASK_ID", "3"),
            ("SLURM_ARRAY_TASK_COUNT", "8"),
            ("SLURM_ARRAY_TASK_MIN", "1"),
            ("SLURM_ARRAY_TASK_MAX", "8"),
        ];
        assert_eq!(got(auto, slurm), Ok((3, 8)));
        assert_eq!(got(auto8, slurm), Ok((3, 8)));
        assert!(
            got("auto/4".parse().unwrap(), slurm)
                .unwrap_err()
                .contains("has 8 tasks")
        );
        // `--array=0-15:5` (0, 5, 10, 15): task 10 is the third of four,
        // counted from MIN and MAX when COUNT is absent.
        let stepped = &[
            ("SLURM_ARRAY_TASK_ID", "10"),
            ("SLURM_ARRAY_TASK_MIN", "0"),
            ("SLURM_ARRAY_TASK_MAX", "15"),
            ("SLURM_ARRAY_TASK_STEP", "5"),
        ];
        assert_eq!(got(auto, stepped), Ok((3, 4)));
        // Kubernetes: index from 0, the count given.
        let k8s = &[("JOB_COMPLETION_INDEX", "7")];
        assert_eq!(got(auto8, k8s), Ok((8, 8)));
        assert!(got(auto, k8s).unwrap_err().contains("give --shard auto/N"));
        assert!(
            got("auto/7".parse().unwrap(), k8s)
                .unwrap_err()
                .contains("outside 1..=7")
        );
        assert!(got(auto, &[]).unwrap_err().contains("no scheduler index"));
        assert!(
            got(auto, &[("SLURM_ARRAY_TASK_ID", "x")])
                .unwrap_err()
                .contains("not a whole number")
        );
        assert_eq!(got("2/3".parse().unwrap(), &[]), Ok((2, 3)));
        assert!("auto/0".parse::<ShardSpec>().is_err());
    }

    #[test]
    fn shards_parse_k_of_n_and_refuse_the_rest() {
        assert_eq!("2/3".parse::<Shard>(), Ok(Shard { index: 2, count: 3 }));
        assert_eq!(" 1 / 1 ".parse::<Shard>(), Ok(Shard { index: 1, count: 1 }));
        for bad in ["4/3", "0/3", "3", "a/3", "1/b", "-1/3", ""] {
            let err = bad.parse::<Shard>().expect_err(bad);
            assert_eq!(err, format!("`{bad}`: expected K/N with 1 <= K <= N"));
        }
    }
}
