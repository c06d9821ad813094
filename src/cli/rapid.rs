//! The RAPID commands: `check` and `compensate` of an ABB RAPID module
//! against a robot machine file.

use std::io::Write;
use std::path::{Path, PathBuf};

use super::machines::Loaded;
use super::output::{Pending, Staged};
use super::{Annotate, CheckArgs, CompensateArgs, EffectArgs, ReportArgs, usage};
use crate::compensate::outcome::{Compensated, Row, Summary};
use crate::emit::header::{HeaderWriter, Provenance};
use crate::emit::rapid::Format;
use crate::error::{Error, Result};
use crate::machine::ThermalStart;
use crate::machine::robot::Robot;
use crate::pipeline::rapid::program::{compensate_member, left_as_written_member};
use crate::pipeline::rapid::{RapidOptions, compensate_module, compensate_parsed, stream};
use crate::predict::EffectSet;
use crate::program::charset::{Charset, Latin1Writer, file_columns};
use crate::program::rapid::program::{is_program, load, module_files};

/// Modules of at least this size are read a window at a time when their
/// shape and the run allow it ([`crate::pipeline::rapid::stream`]):
/// from a window's length up, windows take no more time than the module
/// read whole and far less memory, bounded whatever the module's length
/// (`scripts/bench` prints the peak memory of its runs on a 100 000-target
/// module; docs/performance.md).
pub const STREAM_MIN_BYTES: u64 = 1 << 20;

/// The same with a warm thermal start (`steady`, a warm-up), whose first
/// pass over the module costs more CPU time read a window at a time than
/// read whole: windows from this size on, where memory matters more.
pub const STREAM_MIN_BYTES_WARM: u64 = 16 << 20;

/// A module to read: a file, or standard input. Standard input is held in
/// memory while it is shorter than [`STREAM_MIN_BYTES`]; a longer one is
/// copied to an unnamed temporary file as it is read, so that it can be
/// read a window at a time (and twice, for a warm thermal start or after
/// an error) like a file.
pub(super) struct Source {
    path: PathBuf,
    name: String,
    stdin: Option<Stdin>,
    /// `--rapid-window-lines`.
    forced: Option<usize>,
    /// A warm thermal start (windows from [`STREAM_MIN_BYTES_WARM`] on).
    warm: bool,
}

/// Standard input, read.
enum Stdin {
    Held(Vec<u8>),
    /// Copied to a temporary file of this many bytes.
    Spilled(std::fs::File, u64),
}

impl Source {
    /// The module `path` names (`-`: standard input, read now; copied to
    /// a temporary file whatever its length when `forced`, the
    /// `--rapid-window-lines` of the run, asks for windows).
    /// `warm`: the run has a warm thermal start (windows from
    /// [`STREAM_MIN_BYTES_WARM`] on).
    pub(super) fn new(path: &Path, forced: Option<usize>, warm: bool) -> Result<Self> {
        if forced == Some(0) {
            return Err(usage("--rapid-window-lines must be at least 1"));
        }
        let name = path.display().to_string();
        let stdin = if path == Path::new("-") {
            let spill_from = match (forced, warm) {
                (Some(_), _) => 0,
                (None, false) => STREAM_MIN_BYTES,
                (None, true) => STREAM_MIN_BYTES_WARM,
            };
            Some(read_stdin(spill_from).map_err(|e| crate::limits::io_error("-", e))?)
        } else {
            None
        };
        Ok(Source {
            path: path.to_path_buf(),
            name,
            stdin,
            forced,
            warm,
        })
    }

    /// The name of the module in messages.
    pub(super) fn name(&self) -> &str {
        &self.name
    }

    /// The window size, in lines, when the module should be read a window
    /// at a time: a regular file (standard input copied to a file) of at
    /// least [`STREAM_MIN_BYTES`] ([`STREAM_MIN_BYTES_WARM`] for a warm
    /// thermal start), or any regular file with `--rapid-window-lines`.
    pub(super) fn window_lines(&self) -> Option<usize> {
        let len = match &self.stdin {
            Some(Stdin::Held(_)) => return None,
            Some(Stdin::Spilled(_, len)) => *len,
            // A regular file only: the module may be read twice (after an
            // error, or for a warm thermal start).
            None => match std::fs::metadata(&self.path) {
                Ok(meta) if meta.is_file() => meta.len(),
                _ => return None,
            },
        };
        let min = if self.warm {
            STREAM_MIN_BYTES_WARM
        } else {
            STREAM_MIN_BYTES
        };
        self.forced.or((len >= min).then_some(stream::WINDOW_LINES))
    }

    /// A reader of the module from its start.
    fn open(&self) -> std::io::Result<std::io::BufReader<std::fs::File>> {
        let file = match &self.stdin {
            Some(Stdin::Spilled(f, _)) => {
                let mut f = f.try_clone()?;
                std::io::Seek::rewind(&mut f)?;
                f
            }
            Some(Stdin::Held(_)) => {
                return Err(std::io::Error::other("standard input is held in memory"));
            }
            None => std::fs::File::open(&self.path)?,
        };
        Ok(std::io::BufReader::with_capacity(1 << 16, file))
    }

    /// The first bytes of the module ([`crate::emit::header::HEAD_BYTES`]),
    /// where a postproc header would be.
    pub(super) fn head(&self) -> Result<Vec<u8>> {
        use std::io::Read;
        let limit = crate::emit::header::HEAD_BYTES;
        if let Some(Stdin::Held(b)) = &self.stdin {
            return Ok(b[..b.len().min(limit)].to_vec());
        }
        let mut head = Vec::new();
        self.open()
            .and_then(|r| r.take(limit as u64).read_to_end(&mut head))
            .map_err(|e| Error::io(&self.name, e))?;
        Ok(head)
    }

    /// The whole module text, its name (the module itself is parsed once,
    /// by the caller) and its character set: UTF-8,
    /// or ISO-8859-1 when it is not valid UTF-8
    /// ([`crate::program::charset`]).
    pub(super) fn read_whole_text(self) -> Result<(String, String, Charset)> {
        let name = self.name;
        let bytes = match self.stdin {
            Some(Stdin::Held(b)) => b,
            Some(Stdin::Spilled(mut f, _)) => {
                let mut b = Vec::new();
                std::io::Seek::rewind(&mut f)
                    .and_then(|()| std::io::Read::read_to_end(&mut f, &mut b))
                    .map_err(|e| Error::io("-", e))?;
                b
            }
            None => crate::limits::read_file_bounded(&self.path, u64::MAX)?,
        };
        let (text, charset) = crate::program::charset::decode(bytes);
        if charset == Charset::Latin1 {
            tracing::info!("{name}: not UTF-8; read as ISO-8859-1");
        }
        Ok((text, name, charset))
    }
}

/// Reads standard input: held in memory while shorter than `spill_from`
/// bytes, copied to an unnamed temporary file from there on. When no
/// temporary file can be made or written (a full temporary folder), it is
/// held whole instead: what was copied is read back.
fn read_stdin(spill_from: u64) -> std::io::Result<Stdin> {
    use std::io::{Read, Seek};
    let mut input = crate::limits::LineLimited::new(std::io::stdin().lock(), "-");
    let mut head = Vec::new();
    (&mut input).take(spill_from).read_to_end(&mut head)?;
    if (head.len() as u64) < spill_from {
        return Ok(Stdin::Held(head));
    }
    let Ok(mut file) = tempfile::tempfile() else {
        input.read_to_end(&mut head)?;
        return Ok(Stdin::Held(head));
    };
    // Copied a chunk at a time: the chunk that fails to go to the file is
    // still at hand, and every byte before it is in the file.
    let mut chunk = head;
    let mut copied = 0u64;
    loop {
        if let Err(e) = file.write_all(&chunk) {
            tracing::debug!("standard input held in memory: temporary file: {e}");
            let mut held = Vec::new();
            file.rewind()?;
            (&mut file).take(copied).read_to_end(&mut held)?;
            held.extend_from_slice(&chunk);
            input.read_to_end(&mut held)?;
            return Ok(Stdin::Held(held));
        }
        copied += chunk.len() as u64;
        chunk.clear();
        if (&mut input).take(1 << 16).read_to_end(&mut chunk)? == 0 {
            break;
        }
    }
    Ok(Stdin::Spilled(file, copied))
}

/// Compensates (`body` given) or checks the module of `source` a window at a
/// time; `None` when it is to be read whole instead (its shape, or an
/// error that the whole-module run reports).
fn try_streamed(
    source: &Source,
    robot: &Robot,
    opts: &RapidOptions,
    lines: usize,
    body: Option<&mut dyn Write>,
    records: Option<stream::RecordSink>,
) -> Result<Option<(stream::Streamed, String)>> {
    let name = source.name();
    let mut open = || source.open();
    let done = stream::compensate_streamed(&mut open, name, robot, opts, lines, body, records);
    Ok(windowed(name, lines, done))
}

/// The result of a run read a window at a time, logged; `None` (logged
/// why) when the module is to be read whole.
fn windowed<T>(
    name: &str,
    lines: usize,
    run: std::result::Result<T, stream::Fallback>,
) -> Option<T> {
    match run {
        Ok(done) => {
            tracing::info!("{name}: read a window of {lines} lines at a time");
            Some(done)
        }
        Err(stream::Fallback::Shape(why)) => {
            tracing::info!("{name}: read whole: {}", why.0);
            None
        }
        Err(stream::Fallback::Error(e)) => {
            tracing::debug!("{name}: read whole after an error in a window: {e}");
            None
        }
    }
}

/// `postproc check` of a RAPID module: parse, resolve and (with a robot)
/// check that every target is reachable with its confdata.
pub fn check(a: &CheckArgs, robot: Option<Result<(Robot, Loaded)>>) -> Result<i32> {
    let inputs = program_inputs(&a.program);
    if is_program(&inputs) {
        return check_program(a, robot, &inputs);
    }
    let source = Source::new(&a.program.file, a.program.rapid_window_lines, false)?;
    let mut robot = robot.map(|r| r.map(|(robot, _)| robot));
    let strict = a.program.strict;
    // Without a robot, a strict check reads the module whole (the moves
    // left as written are found there).
    let streamed = match (strict, robot.is_none()) {
        (true, true) => None,
        _ => check_streamed(&mut robot, &source, strict)?,
    };
    let (name, module_name, decls, procs, moves) = match streamed {
        Some(found) => found,
        None => {
            let (src, name, charset) = source.read_whole_text()?;
            let in_file = |e: Error| file_columns(e, &src, charset);
            let module =
                crate::program::rapid::parse_module(&src, &name).map_err(|e| in_file(e.into()))?;
            let found = (
                module.name.clone(),
                module.decls.len(),
                module.procs.len(),
                module.moves().count(),
            );
            // The compensation takes the parsed module (one parse, one
            // module in memory).
            match robot {
                Some(robot) => {
                    compensate_parsed(module, &src, &name, &robot?, &check_options(strict))
                        .map_err(in_file)?;
                }
                None if strict => {
                    let left = crate::pipeline::rapid::left_as_written(&module, &src, &name)
                        .map_err(in_file)?;
                    crate::pipeline::rapid::refuse_left_as_written(
                        &left,
                        &name,
                        &check_options(strict),
                    )
                    .map_err(in_file)?;
                }
                None => {}
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

/// The [`CheckSummary`] of a check read a window at a time (against the
/// robot of `--machine`, or of the syntax alone without one); `None` when
/// the module is to be read whole. Without a robot (a machine file that
/// does not load, or is no robot), the module's syntax errors come first:
/// the error of the machine is taken from `robot` when the syntax is good.
fn check_streamed(
    robot: &mut Option<Result<Robot>>,
    source: &Source,
    strict: bool,
) -> Result<Option<CheckSummary>> {
    let Some(lines) = source.window_lines() else {
        return Ok(None);
    };
    let name = source.name().to_string();
    let Some(found) = robot.as_ref() else {
        let reader = source.open().map_err(|e| Error::io(&name, e))?;
        let found = windowed(
            &name,
            lines,
            stream::check_syntax_streamed(reader, &name, lines),
        );
        return Ok(found.map(|s| (name, s.name, s.decls, s.routines, s.moves)));
    };
    let Ok(robot) = found else {
        // The module read whole is parsed before the machine is taken:
        // its syntax errors come first.
        let reader = source.open().map_err(|e| Error::io(&name, e))?;
        return match stream::check_syntax_streamed(reader, &name, lines) {
            Ok(_) => match robot.take() {
                Some(Err(e)) => Err(e),
                _ => Ok(None),
            },
            Err(_) => Ok(None),
        };
    };
    let streamed = try_streamed(source, robot, &check_options(strict), lines, None, None)?;
    Ok(streamed.map(|(s, _)| (name, s.name, s.decls, s.routines, s.moves)))
}

/// The options of a check: resolve and solve every target, compensate
/// nothing (`strict`: refuse a move left as written).
fn check_options(strict: bool) -> RapidOptions {
    RapidOptions {
        effects: EffectSet::NONE,
        annotate: false,
        format: Format::default(),
        thermal_start: ThermalStart::Cold,
        records: false,
        strict,
        joint_cartesian: false,
        force_table: None,
        uncertainty: None,
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
        // Fewer than three decimals (0.01 mm) would round the compensation
        // of a robot target, a few tenths of a millimetre, away in part.
        if d < 3 {
            return Err(usage(format!(
                "--decimals {d}: robot targets keep at least 3 decimals (0.001 mm); fewer would round the compensation away"
            )));
        }
        format.position_decimals = d;
    }
    let thermal_start = effects.thermal_start;
    let force_table = match &effects.force_table {
        Some(path) => Some(std::sync::Arc::new(crate::process::ForceTable::load(path)?)),
        None => None,
    };
    Ok(RapidOptions {
        effects: EffectSet::from_flags(
            &effects.effects,
            &effects.gains,
            crate::predict::MachineKind::Robot,
        )?,
        annotate,
        format,
        thermal_start,
        records: true,
        strict: false,
        joint_cartesian: false,
        force_table,
        uncertainty: None,
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
    use crate::machine::robot::{ForceModel, ProcessForce};
    let mut robot = robot.allowing_reconfiguration(e.allow_reconfiguration);
    if let Some(spec) = e.force {
        let pf = match spec {
            crate::process::ForceSpec::Constant { force_n, frame } => {
                let old = robot.process_force();
                Some(ProcessForce {
                    model: ForceModel::Constant {
                        force_n,
                        moment_nmm: nalgebra::Vector3::zeros(),
                        frame,
                    },
                    spindle_rpm: old.and_then(|p| p.spindle_rpm),
                    flutes: old
                        .map_or(crate::machine::robot::process::DEFAULT_FLUTES, |p| p.flutes),
                    axis_tolerance_rad: crate::machine::robot::process::DEFAULT_AXIS_TOLERANCE_DEG
                        .to_radians(),
                })
            }
            crate::process::ForceSpec::None => None,
        };
        robot = robot.with_process_force(pf);
    }
    if e.force_table.is_some() {
        robot = robot.with_process_force(Some(ProcessForce::table(robot.process_force())));
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
                return Err(usage(format!(
                    "{flag} {}: must be within 0..10000 mm",
                    crate::error::show_number(v)
                )));
            }
            *slot = v;
        }
    }
    pf.model = ForceModel::Milling(m);
    Ok(robot.with_process_force(Some(pf)))
}

/// `postproc compensate` of a RAPID module.
/// The options of a `compensate` of a module or a program: the
/// annotations carry U (k = 2) when the robot file has a covariance.
fn compensate_options(a: &CompensateArgs, robot: &Robot, loaded: &Loaded) -> Result<RapidOptions> {
    Ok(RapidOptions {
        records: a.report.is_some(),
        strict: a.program.strict,
        joint_cartesian: a.program.compensate_joint_targets,
        uncertainty: loaded.uncertainty.clone(),
        ..rapid_options(
            robot,
            &a.effects,
            a.annotate == Annotate::Comment,
            a.decimals,
        )?
    })
}

/// The provenance header of a `compensate` and where its report goes, in
/// which format (`--report-format`, else the path's extension).
fn provenance_and_report<'a>(
    a: &'a CompensateArgs,
    loaded: &Loaded,
    opts: &RapidOptions,
) -> (Provenance, Option<(&'a Path, super::Format)>) {
    let provenance = super::machines::provenance(
        loaded,
        super::machines::robot_effects(&opts.effects),
        None,
        a.annotate == Annotate::Comment,
    );
    let report = a.report.as_deref().map(|path| {
        let format = a
            .report_format
            .unwrap_or_else(|| super::Format::from_path(path));
        (path, format)
    });
    (provenance, report)
}

pub fn compensate(
    a: &CompensateArgs,
    robot: Option<Result<(Robot, Loaded)>>,
    quiet: bool,
) -> Result<i32> {
    let (robot, loaded) = super::config::needed(robot, "compensate")??;
    let robot = robot_with_process(robot, &a.effects)?;
    let inputs = program_inputs(&a.program);
    if is_program(&inputs) || a.out_dir.is_some() {
        return compensate_program(a, (robot, loaded), &inputs, quiet);
    }
    let opts = compensate_options(a, &robot, &loaded)?;
    let input = &a.program.file;
    let out_path = super::output::output_path(input, a.output.as_deref(), None, &[])?;
    let inputs = super::gcode::input_files(&a.program, &loaded, &a.effects);
    super::output::refuse_overwrite(&out_path, &inputs)?;
    super::output::check_report_path(a.report.as_deref(), &inputs, &out_path)?;
    let pool = super::gcode::thread_pool(a.effects.threads)?;
    let source = Source::new(
        input,
        a.program.rapid_window_lines,
        stream::first_pass(&robot, &opts),
    )?;
    super::machines::refuse_compensated(&source.head()?, source.name(), a.recompensate)?;
    let (provenance, report) = provenance_and_report(a, &loaded, &opts);
    let input_name = source.name().to_string();
    if let Some(lines) = source.window_lines() {
        let outcome = pool.install(|| {
            compensate_streamed_to(
                &source,
                &robot,
                &opts,
                lines,
                Some(&out_path),
                report,
                &provenance,
            )
        })?;
        if let Some(outcome) = outcome {
            log_outcome(&input_name, &out_path, &outcome, quiet);
            return Ok(0);
        }
    }
    let (src, name, charset) = source.read_whole_text()?;
    let outcome = pool.install(|| compensate_module(&src, &name, &robot, &opts));
    let outcome = outcome.map_err(|e| file_columns(e, &src, charset))?;
    write_outcome(&out_path, &outcome, &name, report, &provenance, charset)?;
    log_outcome(&input_name, &out_path, &outcome.summary, quiet);
    Ok(0)
}

/// Writes a module compensated whole to `out_path` (`-`: standard output)
/// in the character set of its input, and its report to `report`; neither
/// file is put in place unless both are written.
pub(super) fn write_outcome(
    out_path: &Path,
    outcome: &Compensated,
    name: &str,
    report: Option<(&Path, super::Format)>,
    provenance: &Provenance,
    charset: Charset,
) -> Result<()> {
    let mut out = Staged::open(out_path)?;
    let shown = if out_path == Path::new("-") {
        Path::new("stdout")
    } else {
        out_path
    };
    let mut latin1;
    let inner: &mut dyn Write = match charset {
        Charset::Utf8 => out.writer(),
        Charset::Latin1 => {
            latin1 = Latin1Writer::new(out.writer());
            &mut latin1
        }
    };
    let mut hw = HeaderWriter::new(inner, provenance.clone(), true);
    hw.write_all(outcome.text.as_bytes())
        .and_then(|()| hw.finish())
        .map_err(|e| Error::io(shown, e))?;
    let report = match report {
        Some((path, format)) => {
            let mut rep = Staged::open(path)?;
            write_report(rep.writer(), outcome, name, format, Some(provenance))?;
            Some(rep.finish()?)
        }
        None => None,
    };
    out.finish()?.commit()?;
    match report {
        Some(rep) => rep.commit(),
        None => Ok(()),
    }
}

/// The files a RAPID program is given as: the program argument and the
/// more modules after it.
fn program_inputs(p: &super::ProgramArgs) -> Vec<PathBuf> {
    std::iter::once(p.file.clone())
        .chain(p.more.iter().cloned())
        .collect()
}

/// `postproc check` of a program of several modules: each module that
/// holds moves is resolved (and, with a robot, solved) with the others.
fn check_program(
    a: &CheckArgs,
    robot: Option<Result<(Robot, Loaded)>>,
    inputs: &[PathBuf],
) -> Result<i32> {
    let members = load(&module_files(inputs)?)?;
    let robot = robot.map(|r| r.map(|(robot, _)| robot)).transpose()?;
    let opts = check_options(a.program.strict);
    let mut out = std::io::stdout().lock();
    for (i, m) in members.iter().enumerate() {
        let in_file = |e| file_columns(e, &m.text, m.charset);
        match &robot {
            Some(robot) => {
                compensate_member(&members, i, robot, &opts).map_err(in_file)?;
            }
            // Names resolve across the modules without a robot.
            None if a.program.strict => {
                let left = left_as_written_member(&members, i).map_err(in_file)?;
                crate::pipeline::rapid::refuse_left_as_written(&left, &m.name, &opts)
                    .map_err(in_file)?;
            }
            None => {}
        }
        writeln!(
            out,
            "{}: module {}, {} declarations, {} routines, {} moves",
            m.name,
            m.module.name,
            m.module.decls.len(),
            m.module.procs.len(),
            m.module.moves().count()
        )
        .map_err(|e| Error::io("stdout", e))?;
    }
    Ok(0)
}

/// `postproc compensate` of a program of several modules: each module is
/// compensated with the others in scope; those that change are written
/// (beside their inputs, or into `--out-dir`), once every module is
/// compensated.
fn compensate_program(
    a: &CompensateArgs,
    (robot, loaded): (Robot, Loaded),
    inputs: &[PathBuf],
    quiet: bool,
) -> Result<i32> {
    if a.output.is_some() {
        return Err(usage(
            "-o names one file: a program of several modules is written beside its inputs or into --out-dir",
        ));
    }
    let opts = compensate_options(a, &robot, &loaded)?;
    let pool = super::gcode::thread_pool(a.effects.threads)?;
    let (provenance, report) = provenance_and_report(a, &loaded, &opts);
    let run = ProgramRun {
        robot: &robot,
        opts: &opts,
        provenance: &provenance,
        recompensate: a.recompensate,
    };
    let (members, written, total, worst) =
        pool.install(|| compensate_program_to(&run, inputs, a.out_dir.as_deref(), report))?;
    if !quiet {
        let names: Vec<String> = written.iter().map(|p| p.display().to_string()).collect();
        eprintln!(
            "program of {} modules → {} written{}: {} compensated{}, {} added; largest predicted deviation {:.4} mm ({})",
            members.len(),
            written.len(),
            if names.is_empty() {
                String::new()
            } else {
                format!(" ({})", names.join(", "))
            },
            plural(total.moves, "move", "moves"),
            left_as_written(&total.warnings),
            plural(total.added, "target", "targets"),
            worst.0,
            if worst.1.is_empty() { "-" } else { &worst.1 }
        );
    }
    Ok(0)
}

/// What a program's run shares: the robot, options, provenance, and
/// whether modules compensated before are taken.
pub(super) struct ProgramRun<'r> {
    pub(super) robot: &'r Robot,
    pub(super) opts: &'r RapidOptions,
    pub(super) provenance: &'r Provenance,
    pub(super) recompensate: bool,
}

/// What a program's run did: its modules, the files written, the totals
/// and the largest predicted deviation with its `FILE:LINE`.
pub(super) type ProgramDone = (
    Vec<crate::program::rapid::program::Member>,
    Vec<PathBuf>,
    Summary,
    (f64, String),
);

/// Compensates the program `inputs` name: each module with the others in
/// scope; those that change are written (beside their inputs, or into
/// `out_dir`), with the report of every module into `report`, once every
/// module is compensated.
pub(super) fn compensate_program_to(
    run: &ProgramRun,
    inputs: &[PathBuf],
    out_dir: Option<&Path>,
    report: Option<(&Path, super::Format)>,
) -> Result<ProgramDone> {
    let members = load(&module_files(inputs)?)?;
    let mut written = Vec::new();
    let mut total = Summary::default();
    let mut worst = (0.0, String::new());
    let mut outcomes = Vec::with_capacity(members.len());
    for (i, m) in members.iter().enumerate() {
        super::machines::refuse_compensated(m.text.as_bytes(), &m.name, run.recompensate)?;
        let outcome = compensate_member(&members, i, run.robot, run.opts)
            .map_err(|e| file_columns(e, &m.text, m.charset))?;
        outcomes.push(outcome);
    }
    for ((i, m), outcome) in members.iter().enumerate().zip(outcomes.iter()) {
        let s = &outcome.summary;
        total.moves += s.moves;
        total.added += s.added;
        total.warnings.extend(s.warnings.iter().cloned());
        if s.deviation.max > worst.0 || worst.1.is_empty() && s.moves > 0 {
            worst = (
                s.deviation.max,
                format!("{}:{}", m.name, s.deviation.max_line),
            );
        }
        if outcome.text != m.text {
            let out = super::output::output_path(&m.path, None, out_dir, inputs)?;
            super::output::refuse_overwrite(&out, &[&m.path])?;
            written.push((out, outcome, i));
        }
    }
    // The report is written first and put in place after the modules.
    let staged = match report {
        Some((path, format)) => {
            let paths: Vec<PathBuf> = members.iter().map(|m| m.path.clone()).collect();
            for (out, _, _) in &written {
                super::output::check_report_path(Some(path), &paths, out)?;
            }
            super::output::check_report_path(Some(path), &paths, Path::new("-"))?;
            let mut rep = Staged::open(path)?;
            let name = inputs
                .first()
                .map(|p| p.display().to_string())
                .unwrap_or_default();
            write_program_report(
                rep.writer(),
                &members,
                &outcomes,
                &name,
                format,
                run.provenance,
            )?;
            Some(rep.finish()?)
        }
        None => None,
    };
    for (out, outcome, i) in &written {
        let m = &members[*i];
        if out_dir.is_some()
            && let Some(parent) = out.parent()
        {
            std::fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
        }
        write_outcome(out, outcome, &m.name, None, run.provenance, m.charset)?;
    }
    if let Some(rep) = staged {
        rep.commit()?;
    }
    let written = written.into_iter().map(|(p, _, _)| p).collect();
    Ok((members, written, total, worst))
}

/// `n one` or `n many`, with the count grouped.
fn plural(n: usize, one: &str, many: &str) -> String {
    format!(
        "{} {}",
        super::gcode::grouped(n),
        if n == 1 { one } else { many }
    )
}

/// The summary line on standard error (unless `quiet`).
pub(super) fn log_outcome(input: &str, out_path: &Path, outcome: &Summary, quiet: bool) {
    if quiet {
        return;
    }
    let out = if out_path == Path::new("-") {
        "stdout".to_string()
    } else {
        out_path.display().to_string()
    };
    let plural = |n: usize, one: &str, many: &str| {
        format!(
            "{} {}",
            super::gcode::grouped(n),
            if n == 1 { one } else { many }
        )
    };
    eprintln!(
        "{input} → {out}: {} compensated{}, {} added; largest predicted deviation {:.4} mm (line {})",
        plural(outcome.moves, "move", "moves"),
        left_as_written(&outcome.warnings),
        plural(outcome.added, "target", "targets"),
        outcome.deviation.max,
        outcome.deviation.max_line
    );
}

/// `, N left as written (reasons)` of the summary line, or nothing when
/// every move is compensated.
fn left_as_written(warnings: &[crate::program::interp::Warning]) -> String {
    let left = || warnings.iter().filter_map(|w| w.left.as_ref());
    if left().next().is_none() {
        return String::new();
    }
    let mut reasons: Vec<&str> = left().map(|a| a.reason.as_str()).collect();
    reasons.sort_unstable();
    reasons.dedup();
    format!(
        ", {} left as written ({})",
        super::gcode::grouped(left().count()),
        reasons.join("; ")
    )
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
/// rewound) to `path` (or to standard output for `-`, named
/// `stdout_name` in errors as the module read whole names it: `stdout` for
/// the program, `report` for a report); the file is put in place by the
/// caller, once every output is written.
fn write_spilled(
    path: &Path,
    stdout_name: &str,
    head: &str,
    spill: std::io::BufWriter<std::fs::File>,
    provenance: Option<&Provenance>,
) -> Result<Pending> {
    let shown = if path == Path::new("-") {
        Path::new(stdout_name)
    } else {
        path
    };
    let mut file = spill
        .into_inner()
        .map_err(|e| Error::io(shown, e.into_error()))?;
    std::io::Seek::rewind(&mut file).map_err(|e| Error::io(shown, e))?;
    let mut out = Staged::open(path)?;
    match provenance {
        Some(p) => {
            let mut w = HeaderWriter::new(out.writer(), p.clone(), true);
            w.write_all(head.as_bytes())
                .and_then(|()| std::io::copy(&mut file, &mut w).map(drop))
                .and_then(|()| w.finish())
                .map_err(|e| Error::io(shown, e))?;
        }
        None => {
            let w = out.writer();
            w.write_all(head.as_bytes())
                .map_err(|e| Error::io(shown, e))?;
            std::io::copy(&mut file, w).map_err(|e| Error::io(shown, e))?;
        }
    }
    out.finish()
}

/// Compensates the module at `input` a window at a time into `out_path`
/// (`None` for a dry run) and the report of every move into `report`:
/// the rewritten routines and the report rows go to temporary files beside
/// their outputs as they are made, then to the outputs (atomically, as
/// always). `None` when the module is to be read whole.
pub(super) fn compensate_streamed_to(
    source: &Source,
    robot: &Robot,
    opts: &RapidOptions,
    lines: usize,
    out_path: Option<&Path>,
    report: Option<(&Path, super::Format)>,
    provenance: &Provenance,
) -> Result<Option<Summary>> {
    use crate::emit::report::{Layout, ReportWriter};
    let name = source.name();
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
                .with_source(Path::new(name))
                .with_provenance(Some(provenance)),
        ),
        _ => None,
    };
    let mut sink = |records: &[Row]| -> Result<()> {
        match writer.as_mut() {
            Some(rw) => write_records(rw, records),
            None => Ok(()),
        }
    };
    let streamed = try_streamed(
        source,
        robot,
        &RapidOptions {
            records: report.is_some(),
            ..opts.clone()
        },
        lines,
        body.as_mut().map(|b| b as &mut dyn Write),
        Some(&mut sink),
    )?;
    let Some((streamed, prologue)) = streamed else {
        return Ok(None);
    };
    let mut pending = Vec::new();
    if let (Some(p), Some(b)) = (out_path, body) {
        pending.push(write_spilled(p, "stdout", &prologue, b, Some(provenance))?);
    }
    if let (Some(rw), Some((p, _))) = (writer, report) {
        rw.finish(crate::emit::report::Totals {
            blocks: streamed.summary.moves,
            moves: streamed.summary.moves,
        })?;
        if let Some(spill) = report_spill {
            pending.push(write_spilled(p, "report", "", spill, None)?);
        }
    }
    // Neither output is put in place unless both are written.
    for p in pending {
        p.commit()?;
    }
    Ok(Some(streamed.summary))
}

/// Writes the report rows of `records`.
fn write_records(rw: &mut crate::emit::report::ReportWriter, records: &[Row]) -> Result<()> {
    records.iter().try_for_each(|t| rw.row(t))
}

/// Writes the deviation report of a compensated (or dry-run) RAPID module:
/// a row per motion instruction with the kinematic, thermal, gravity, process and dynamic (vibration)
/// parts of its predicted deviation.
pub(super) fn write_report(
    out: &mut dyn Write,
    outcome: &Compensated,
    name: &str,
    format: super::Format,
    provenance: Option<&Provenance>,
) -> Result<()> {
    use crate::emit::report::{Layout, ReportWriter, Totals};
    let mut rw = ReportWriter::with_layout(out, Layout::rapid(), format, name)?
        .with_source(Path::new(name))
        .with_provenance(provenance);
    write_records(&mut rw, &outcome.records)?;
    rw.finish(Totals {
        blocks: outcome.summary.moves,
        moves: outcome.summary.moves,
    })
}

/// Writes the deviation report of a program of several modules: the rows
/// of every module, in program order, each naming its module file
/// ([`crate::emit::report::Layout::with_files`]); `name` names the
/// program.
fn write_program_report(
    out: &mut dyn Write,
    members: &[crate::program::rapid::program::Member],
    outcomes: &[Compensated],
    name: &str,
    format: super::Format,
    provenance: &Provenance,
) -> Result<()> {
    use crate::emit::report::{Layout, ReportWriter, Totals};
    let layout = Layout::rapid().with_files();
    let mut rw =
        ReportWriter::with_layout(out, layout, format, name)?.with_provenance(Some(provenance));
    let mut moves = 0;
    for (m, outcome) in members.iter().zip(outcomes) {
        rw.file(&m.name, Some(&m.path));
        write_records(&mut rw, &outcome.records)?;
        moves += outcome.summary.moves;
    }
    rw.finish(Totals {
        blocks: moves,
        moves,
    })
}

/// `postproc report` of a RAPID module (dry run against a robot).
pub fn report(a: &ReportArgs, robot: Option<Result<(Robot, Loaded)>>) -> Result<i32> {
    let (robot, loaded) = super::config::needed(robot, "report")??;
    let robot = robot_with_process(robot, &a.effects)?;
    let opts = RapidOptions {
        strict: a.program.strict,
        joint_cartesian: a.program.compensate_joint_targets,
        ..rapid_options(&robot, &a.effects, false, None)?
    };
    let out = a.output.clone().unwrap_or_else(|| PathBuf::from("-"));
    super::output::refuse_overwrite(
        &out,
        &super::gcode::input_files(&a.program, &loaded, &a.effects),
    )?;
    let inputs = program_inputs(&a.program);
    if is_program(&inputs) {
        let provenance = super::machines::provenance(
            &loaded,
            super::machines::robot_effects(&opts.effects),
            None,
            false,
        );
        let members = load(&module_files(&inputs)?)?;
        let paths: Vec<PathBuf> = members.iter().map(|m| m.path.clone()).collect();
        super::output::refuse_overwrite(&out, &paths)?;
        let pool = super::gcode::thread_pool(a.effects.threads)?;
        let mut outcomes = Vec::with_capacity(members.len());
        for (i, m) in members.iter().enumerate() {
            let outcome = pool
                .install(|| compensate_member(&members, i, &robot, &opts))
                .map_err(|e| file_columns(e, &m.text, m.charset))?;
            outcomes.push(outcome);
        }
        let name = inputs[0].display().to_string();
        super::output::emit_to(&out, |w| {
            write_program_report(w, &members, &outcomes, &name, a.format, &provenance)
        })?;
        return Ok(0);
    }
    let source = Source::new(
        &a.program.file,
        a.program.rapid_window_lines,
        stream::first_pass(&robot, &opts),
    )?;
    let provenance = super::machines::provenance(
        &loaded,
        super::machines::robot_effects(&opts.effects),
        None,
        false,
    );
    if let Some(lines) = source.window_lines() {
        let report = Some((out.as_path(), a.format));
        if compensate_streamed_to(&source, &robot, &opts, lines, None, report, &provenance)?
            .is_some()
        {
            return Ok(0);
        }
    }
    let (src, name, charset) = source.read_whole_text()?;
    let outcome = compensate_module(&src, &name, &robot, &opts)
        .map_err(|e| file_columns(e, &src, charset))?;
    super::output::emit_to(&out, |w| {
        write_report(w, &outcome, &name, a.format, Some(&provenance))
    })?;
    Ok(0)
}
