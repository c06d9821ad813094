//! The G-code commands: `check`, `compensate` and `report`.

use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};

use super::machines::Loaded;
use super::{
    Annotate, CheckArgs, CompensateArgs, EffectArgs, Format, ProgramArgs, ReportArgs, usage,
};
use crate::compensate::Settings;
use crate::emit::gcode::EmitOptions;
use crate::emit::header::{HeaderWriter, Provenance};
use crate::emit::report::ReportWriter;
use crate::error::{Error, Result};
use crate::job::{Job, Summary};
use crate::machine::Machine;
use crate::machine::tool::MachineTool;
use crate::predict::{EffectSet, ProcessSetup, ToolPredictor};
use crate::process::{ForceModel, ForceTable, Frame};
use crate::program::interp::Setup;

fn load_machine(name: &str) -> Result<(MachineTool, Loaded)> {
    match super::machines::open(name)? {
        (Machine::Tool(m), loaded) => Ok((m, loaded)),
        (Machine::Robot(_), loaded) => Err(usage(format!(
            "{}: is a robot; G-code programs need a machine tool",
            loaded.file.shown
        ))),
    }
}

pub(super) fn parse_setup(args: &ProgramArgs, machine: Option<&MachineTool>) -> Result<Setup> {
    let mut setup = match machine {
        Some(m) => Setup::for_machine(m),
        None => Setup {
            axes: [true; 6],
            ..Setup::default()
        },
    };
    for t in &args.tools {
        let (h, len) = t
            .split_once('=')
            .ok_or_else(|| usage(format!("--tool expects H<n>=LENGTH, got `{t}`")))?;
        let h = h.trim().trim_start_matches(['H', 'h']);
        let h: u32 = h
            .parse()
            .map_err(|_| usage(format!("--tool: `{t}`: bad H number")))?;
        let len: f64 = len
            .trim()
            .parse()
            .map_err(|_| usage(format!("--tool: `{t}`: bad length")))?;
        if !len.is_finite() || !(0.0..=2000.0).contains(&len) {
            return Err(usage(format!(
                "--tool: `{t}`: length must be within 0..2000 mm"
            )));
        }
        setup.tools.insert(h, len);
    }
    for w in &args.work_offsets {
        let (code, xyz) = w
            .split_once('=')
            .ok_or_else(|| usage(format!("--work-offset expects G54=X,Y,Z, got `{w}`")))?;
        let code = code.trim().to_ascii_uppercase();
        let idx = match code.as_str() {
            "G54" => Some(0),
            "G55" => Some(1),
            "G56" => Some(2),
            "G57" => Some(3),
            "G58" => Some(4),
            "G59" => Some(5),
            c if crate::machine::tool::work_offset_key(c) => None,
            _ => {
                return Err(usage(format!(
                    "--work-offset: `{code}` is not G54..G59, G54.1P1..G54.1P300 or G154P1..G154P99"
                )));
            }
        };
        let v: Vec<f64> = xyz
            .split(',')
            .map(|s| s.trim().parse::<f64>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|_| usage(format!("--work-offset: `{w}`: expected three numbers")))?;
        if v.len() != 3 || v.iter().any(|x| !x.is_finite() || x.abs() > 1e6) {
            return Err(usage(format!(
                "--work-offset: `{w}`: expected three finite numbers"
            )));
        }
        match idx {
            Some(i) => setup.work_offsets[i] = Some([v[0], v[1], v[2]]),
            None => {
                setup.extra_offsets.insert(code, [v[0], v[1], v[2]]);
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

pub(super) fn effects(args: &EffectArgs) -> Result<EffectSet> {
    let mut set = EffectSet::parse(&args.effects)?;
    for g in &args.gains {
        set.set_gain(g)?;
    }
    Ok(set)
}

/// Parses `--force`: `none` or `constant:FX,FY,FZ[@frame]`.
pub(super) fn parse_force(spec: &str) -> Result<Option<ForceModel>> {
    let spec = spec.trim();
    if spec == "none" {
        return Ok(None);
    }
    let bad = || {
        usage(format!(
            "--force: `{spec}`: expected none or constant:FX,FY,FZ[@workpiece|tool|feed] (N)"
        ))
    };
    let body = spec.strip_prefix("constant:").ok_or_else(bad)?;
    let (vals, frame) = match body.split_once('@') {
        Some((v, f)) => (v, Frame::parse(f).ok_or_else(bad)?),
        None => (body, Frame::Workpiece),
    };
    let v: Vec<f64> = vals
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| bad())?;
    match v.as_slice() {
        [x, y, z] if v.iter().all(|c| c.is_finite() && c.abs() <= 1e6) => {
            Ok(Some(ForceModel::Constant {
                force_n: nalgebra::Vector3::new(*x, *y, *z),
                frame,
            }))
        }
        _ => Err(bad()),
    }
}

/// The job's process settings from the machine file and the flags.
pub(super) fn process_setup(args: &EffectArgs, machine: &MachineTool) -> Result<ProcessSetup> {
    let mut p = ProcessSetup::for_machine(machine);
    if let Some(spec) = &args.force {
        p.force = parse_force(spec)?;
    }
    if let Some(path) = &args.force_table {
        p.force = Some(ForceModel::Table(ForceTable::load(path)?));
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

/// `postproc check`.
pub fn check(a: &CheckArgs) -> Result<i32> {
    let machine = a
        .program
        .machine
        .as_deref()
        .map(load_machine)
        .transpose()?
        .map(|(m, _)| m);
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
    let s = job.run(input, &name, None, None)?;
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
    Ok(0)
}

/// Default output path: `<stem>.comp.<ext>` beside the input.
pub fn default_output(input: &Path) -> PathBuf {
    let stem = input
        .file_stem()
        .map(|s| s.to_string_lossy().to_string())
        .unwrap_or_else(|| "program".into());
    let name = match input.extension() {
        Some(ext) => format!("{stem}.comp.{}", ext.to_string_lossy()),
        None => format!("{stem}.comp"),
    };
    input.with_file_name(name)
}

/// Refuses an output path that is one of the command's input files (stdout
/// `-` and stdin are never the same file). Every command that writes a file
/// calls this before writing.
pub fn refuse_overwrite<P: AsRef<Path>>(out: &Path, inputs: &[P]) -> Result<()> {
    if out == Path::new("-") {
        return Ok(());
    }
    for input in inputs.iter().map(AsRef::as_ref) {
        if input != Path::new("-") && (out == input || same_file(input, out)) {
            return Err(usage(format!(
                "{}: the output would overwrite the input",
                out.display()
            )));
        }
    }
    Ok(())
}

/// Whether the paths `a` and `b` name the same file: the same device and
/// inode when both exist (symbolic and hard links included), else the same
/// path once the folders are resolved (for a file not made yet: `./x`,
/// `d/../x` and an absolute spelling are one file).
pub(super) fn same_file(a: &Path, b: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if let (Ok(x), Ok(y)) = (std::fs::metadata(a), std::fs::metadata(b)) {
            return x.dev() == y.dev() && x.ino() == y.ino();
        }
    }
    match (resolved(a), resolved(b)) {
        (Some(x), Some(y)) => x == y,
        _ => false,
    }
}

/// `path` with its links, `.` and `..` resolved, also when the file itself
/// does not exist yet (its folder is resolved and its name joined).
fn resolved(path: &Path) -> Option<PathBuf> {
    if let Ok(p) = path.canonicalize() {
        return Some(p);
    }
    let name = path.file_name()?;
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    Some(dir.canonicalize().ok()?.join(name))
}

/// Writes through a temporary file in the target directory and renames it
/// into place only when `f` succeeds; on failure nothing is left behind.
///
/// An output that already exists and is not an ordinary file (`/dev/null`,
/// `/dev/stdout`, a named pipe) is written to directly: renaming over it
/// would replace the device or pipe with a file. A symbolic link is followed,
/// so the file it points at is replaced and the link stays.
pub fn write_atomically<T>(path: &Path, f: impl FnOnce(&mut dyn Write) -> Result<T>) -> Result<T> {
    let mut out = Staged::file(path)?;
    let value = f(out.writer())?;
    out.finish()?.commit()?;
    Ok(value)
}

/// An output being written ([`write_atomically`]'s parts, for runs that
/// write two outputs and put neither in place unless both are written): a
/// temporary file beside it, renamed into place by [`Pending::commit`], or
/// a special file or standard output written straight.
pub(super) struct Staged {
    shown: PathBuf,
    sink: Sink,
}

enum Sink {
    /// A temporary file to be renamed to the path (removed on an
    /// interrupt while the guard lives).
    Temp(
        BufWriter<std::fs::File>,
        tempfile::TempPath,
        PathBuf,
        super::interrupt::Guard,
    ),
    /// A device or named pipe, written straight.
    Through(BufWriter<std::fs::File>),
    /// Standard output.
    Stdout(BufWriter<std::io::Stdout>),
}

/// A written output waiting to be put in place.
pub(super) struct Pending(
    Option<(
        tempfile::TempPath,
        PathBuf,
        PathBuf,
        super::interrupt::Guard,
    )>,
);

impl Staged {
    /// The output `path`, or standard output for `-`.
    pub(super) fn open(path: &Path) -> Result<Self> {
        if path == Path::new("-") {
            return Ok(Staged {
                shown: PathBuf::from("stdout"),
                sink: Sink::Stdout(BufWriter::new(std::io::stdout())),
            });
        }
        Staged::file(path)
    }

    /// The output file `path` (see [`write_atomically`]).
    fn file(path: &Path) -> Result<Self> {
        let is_link = std::fs::symlink_metadata(path)
            .map(|m| m.file_type().is_symlink())
            .unwrap_or(false);
        let target = match std::fs::metadata(path) {
            Ok(m) if !m.is_file() && !m.is_dir() => {
                let file = std::fs::OpenOptions::new()
                    .write(true)
                    .open(path)
                    .map_err(|e| Error::io(path, e))?;
                return Ok(Staged {
                    shown: path.to_path_buf(),
                    sink: Sink::Through(BufWriter::with_capacity(1 << 16, file)),
                });
            }
            Ok(m) if m.is_file() && is_link => {
                path.canonicalize().map_err(|e| Error::io(path, e))?
            }
            _ => path.to_path_buf(),
        };
        let dir = match target.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        // The temporary file's random name means nothing to the user: name
        // the output and its folder only.
        let tmp = tempfile::Builder::new()
            .prefix(".postproc-")
            .tempfile_in(&dir)
            .map_err(|e| {
                Error::io(
                    path,
                    std::io::Error::new(
                        e.kind(),
                        format!("cannot create a file in {}: {}", dir.display(), e.kind()),
                    ),
                )
            })?;
        let (file, tmp_path) = tmp.into_parts();
        let guard = super::interrupt::register(&tmp_path);
        Ok(Staged {
            shown: path.to_path_buf(),
            sink: Sink::Temp(
                BufWriter::with_capacity(1 << 20, file),
                tmp_path,
                target,
                guard,
            ),
        })
    }

    /// Where the output goes.
    pub(super) fn writer(&mut self) -> &mut dyn Write {
        match &mut self.sink {
            Sink::Temp(w, ..) | Sink::Through(w) => w,
            Sink::Stdout(w) => w,
        }
    }

    /// Flushes the output (and syncs a temporary file): what is left is to
    /// put it in place.
    pub(super) fn finish(self) -> Result<Pending> {
        let shown = self.shown;
        match self.sink {
            Sink::Through(mut w) => w.flush().map_err(|e| Error::io(&shown, e))?,
            Sink::Stdout(mut w) => w.flush().map_err(|e| Error::io(&shown, e))?,
            Sink::Temp(w, tmp_path, target, guard) => {
                let file = w
                    .into_inner()
                    .map_err(|e| Error::io(&shown, e.into_error()))?;
                file.sync_all().map_err(|e| Error::io(&shown, e))?;
                // Temporary files are private (0600); the result is an
                // ordinary file.
                #[cfg(unix)]
                {
                    use std::os::unix::fs::PermissionsExt;
                    file.set_permissions(std::fs::Permissions::from_mode(0o644))
                        .map_err(|e| Error::io(&shown, e))?;
                }
                return Ok(Pending(Some((tmp_path, target, shown, guard))));
            }
        }
        Ok(Pending(None))
    }
}

/// Finishes a program and its report, then puts both in place: neither
/// is, unless both are written.
pub(super) fn finish_both(out: Staged, report: Staged) -> Result<()> {
    let (report, out) = (report.finish()?, out.finish()?);
    out.commit()?;
    report.commit()
}

impl Pending {
    /// Puts the output in place (renames the temporary file).
    pub(super) fn commit(self) -> Result<()> {
        if let Some((tmp_path, target, shown, guard)) = self.0 {
            tmp_path
                .persist(&target)
                .map_err(|e| Error::io(&shown, e.error))?;
            drop(guard);
        }
        Ok(())
    }
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
    let min = crate::compensate::MIN_TOLERANCE_MM;
    if !tolerance.is_finite() || tolerance < min || tolerance > 1.0 {
        return Err(usage(format!(
            "--tolerance {}: must be within [{min}, 1] mm (the solver converges to {} mm)",
            crate::error::show_number(tolerance),
            crate::compensate::SOLVE_TOL_MM
        )));
    }
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
            decimals_deg: machine.output_decimals_deg(),
            annotate,
        },
        pool: Some(pool),
        travel: None,
    })
}

/// Loads the `--machine` file with the program's tool table and work offsets.
fn machine_setup(program: &ProgramArgs, command: &str) -> Result<(MachineTool, Loaded, Setup)> {
    let name = program
        .machine
        .as_deref()
        .ok_or_else(|| usage(format!("{command} needs --machine")))?;
    let (machine, loaded) = load_machine(name)?;
    let setup = parse_setup(program, Some(&machine))?;
    Ok((machine, loaded, setup))
}

/// Refuses a `--report` path that would replace the input or the output.
pub(super) fn check_report_path(
    report: Option<&Path>,
    inputs: &[PathBuf],
    output: &Path,
) -> Result<()> {
    let Some(report) = report else {
        return Ok(());
    };
    if report == Path::new("-") {
        return Err(usage("--report needs a file path (the program goes to -o)"));
    }
    let named = inputs.iter().map(|p| (p.as_path(), "input"));
    for (other, what) in named.chain([(output, "output")]) {
        if other != Path::new("-") && (report == other || same_file(report, other)) {
            return Err(usage(format!(
                "{}: the report would overwrite the {what}",
                report.display()
            )));
        }
    }
    Ok(())
}

/// The files a run reads: the program, the machine file and the force
/// table (none of them may be an output).
pub(super) fn input_files(program: &ProgramArgs, effects: &EffectArgs) -> Result<Vec<PathBuf>> {
    let mut files = vec![program.file.clone()];
    if let Some(m) = &program.machine {
        files.extend(crate::machine::MachineFile::open(m)?.path);
    }
    files.extend(effects.force_table.clone());
    Ok(files)
}

/// Writes to `path` atomically, or to standard output for `-`.
pub(super) fn emit_to<T>(path: &Path, f: impl FnOnce(&mut dyn Write) -> Result<T>) -> Result<T> {
    let mut out = Staged::open(path)?;
    let value = f(out.writer())?;
    out.finish()?.commit()?;
    Ok(value)
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
    let mut rw = ReportWriter::new(report, &job.setup, format, file)?
        .with_source(Path::new(file))
        .with_provenance(provenance);
    let mut err = None;
    let summary = job.run(
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
    Ok(summary)
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
    fn new(program: &ProgramArgs, args: &EffectArgs, command: &str) -> Result<Self> {
        let (machine, loaded, setup) = machine_setup(program, command)?;
        let pool = thread_pool(args.threads)?;
        let effects = effects(args)?;
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
pub fn compensate(a: &CompensateArgs, quiet: bool) -> Result<i32> {
    let run = Prepared::new(&a.program, &a.effects, "compensate")?;
    let tolerance = tolerance_of(a.tolerance, Some(&run.machine));
    let annotate = a.annotate == Annotate::Comment;
    let job = run.job(tolerance, a.decimals, annotate)?;
    let input_path = &a.program.file;
    let out_path = match &a.output {
        Some(p) => p.clone(),
        None if input_path == Path::new("-") => PathBuf::from("-"),
        None => default_output(input_path),
    };
    let inputs = input_files(&a.program, &a.effects)?;
    refuse_overwrite(&out_path, &inputs)?;
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
    let summary: Summary = match &a.report {
        Some(report_path) => {
            let format = a
                .report_format
                .unwrap_or_else(|| Format::from_path(report_path));
            // Neither is put in place unless both are written.
            let mut rep = Staged::open(report_path)?;
            let mut out = Staged::open(&out_path)?;
            let mut hw = HeaderWriter::new(out.writer(), provenance.clone(), false);
            let summary = run_reporting(
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
            let s = job.run(input, &file, Some(&mut hw), None)?;
            hw.finish().map_err(|e| Error::io(&out_path, e))?;
            Ok(s)
        })?,
    };
    if !quiet {
        eprintln!("{}", summary_line(&file, &out_path, &summary, tolerance));
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
pub fn report(a: &ReportArgs) -> Result<i32> {
    let run = Prepared::new(&a.program, &a.effects, "report")?;
    let job = run.job(0.001, None, false)?;
    let (input, file) = open_input(&a.program.file)?;
    let out = a.output.clone().unwrap_or_else(|| PathBuf::from("-"));
    refuse_overwrite(&out, &input_files(&a.program, &a.effects)?)?;
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
