//! Command line: raw flags → validated run configuration → engine calls.
//! Nothing else in the crate parses flags.

mod batch;
mod calibrate;
mod completions;
mod config;
mod diagnose;
mod gcode;
mod interrupt;
mod krl;
mod machines;
pub mod memory;
mod output;
pub use output::is_broken_pipe;
mod rapid;
mod tp;
mod verify;

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand, ValueEnum};

use crate::error::{Error, Result};
use crate::machine::ThermalStart;
use crate::machine::effects::{EffectSpec, Gain};
use crate::machine::tool::{ToolLength, WorkOffset};
use crate::process::ForceSpec;

pub use crate::emit::report::Format;
pub use batch::{Shard, ShardSpec};
pub use diagnose::{DiagnoseArgs, DiagnoseFormat};

/// Exit codes, also listed in `--help`.
pub const EXIT_HELP: &str = "Exit codes: 0 success; 1 completed, but blocks are out of tolerance or limits; 2 bad input or usage; 3 internal error (a bug in postproc).";

/// postproc — offline compensation post-processor for CNC machine tools and robots.
#[derive(Debug, Parser)]
#[command(name = "postproc", version, about, after_help = EXIT_HELP)]
pub struct Cli {
    /// Only errors on stderr.
    #[arg(short, long, global = true)]
    pub quiet: bool,
    /// More log output on stderr (-v info, -vv debug).
    #[arg(short, long, global = true, action = clap::ArgAction::Count)]
    pub verbose: u8,
    /// The command.
    #[command(subcommand)]
    pub command: Command,
}

/// The commands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Parse and interpret a program only; print a summary.
    #[command(after_help = EXIT_HELP)]
    Check(CheckArgs),
    /// Write a compensated program whose targets land on the programmed ones.
    #[command(
        after_help = EXIT_HELP,
        override_usage = "postproc compensate --machine <MACHINE> [OPTIONS] <FILE> [MORE]..."
    )]
    Compensate(CompensateArgs),
    /// Dry run: predicted deviation per block and summary per effect, as a
    /// table, CSV, JSON or SVG picture; nothing else is written.
    #[command(
        after_help = EXIT_HELP,
        override_usage = "postproc report --machine <MACHINE> [OPTIONS] <FILE> [MORE]..."
    )]
    Report(ReportArgs),
    /// Compensate many programs (files or folders) in parallel into a folder.
    #[command(
        after_help = BATCH_EXIT_HELP,
        override_usage = "postproc batch --machine <MACHINE> --out-dir <OUT_DIR> [OPTIONS] <INPUTS>...\n       postproc batch --merge-summaries --out-dir <OUT_DIR> <SUMMARIES>..."
    )]
    Batch(BatchArgs),
    /// Fill the measured columns of a poses file from a machine file plus noise.
    #[command(after_help = EXIT_HELP)]
    Simulate(calibrate::SimulateArgs),
    /// Identify model parameters from measurements; write a calibrated machine file.
    ///
    /// Prints every parameter with its uncertainty. A parameter whose
    /// expanded uncertainty U(k=2) is above --uncertain-above (default 50 %)
    /// of the larger of its identified value and its change is uncertain:
    /// it is listed and keeps the input file's value unless
    /// --write-uncertain (docs/calibration.md, "Uncertain parameters").
    #[command(after_help = EXIT_HELP)]
    Calibrate(calibrate::CalibrateArgs),
    /// Find where model and measurements disagree, name the missing effect, add it.
    #[command(
        after_help = DIAGNOSE_EXIT_HELP,
        override_usage = "postproc diagnose --machine <MACHINE> --observations <OBSERVATIONS> [OPTIONS]\n       postproc diagnose --list-effects [--machine <MACHINE>] [--observations <OBSERVATIONS>]"
    )]
    Diagnose(DiagnoseArgs),
    /// List the machine files bundled in the binary (status, a robot's
    /// reach and payload); `machines new NAME -o FILE` writes a robot cell
    /// file to start from.
    #[command(after_help = PLAIN_EXIT_HELP)]
    Machines(machines::MachinesArgs),
    /// Acceptance tests: ISO 230-2, ISO 230-4 and ISO 9283 figures from
    /// measured (or predicted) data, held against limits.
    #[command(after_help = verify::VERIFY_EXIT_HELP)]
    Verify(verify::VerifyArgs),
    /// Print a shell completion script (bash, zsh, fish, elvish, powershell).
    ///
    /// For example `postproc completions bash > ~/.local/share/bash-completion/completions/postproc`.
    #[command(after_help = PLAIN_EXIT_HELP)]
    Completions {
        /// The shell.
        shell: clap_complete::Shell,
    },
    /// Print the manual page (roff), e.g. `postproc man > postproc.1`.
    #[command(after_help = PLAIN_EXIT_HELP)]
    Man,
}

/// Exit codes of commands that read no program.
pub const PLAIN_EXIT_HELP: &str = "Exit codes: 0 success; 2 bad usage or an output that cannot be written; 3 internal error (a bug in postproc).";

/// Exit codes of `diagnose`.
pub const DIAGNOSE_EXIT_HELP: &str = "Exit codes: 0 success; 2 bad input (machine file, observations) or usage; 3 internal error (a bug in postproc).";

/// Exit codes of `batch`, also listed in its `--help`.
pub const BATCH_EXIT_HELP: &str = "Exit codes: 0 every program compensated; 1 every program compensated, but some have blocks out of tolerance or limits; 2 a program failed (bad input; the others are still written) or bad usage.";

/// `postproc batch`.
#[derive(Debug, Args)]
pub struct BatchArgs {
    /// Programs or folders (searched recursively for .nc .ngc .tap .gcode
    /// .cnc and RAPID .mod .modx .prg); with --merge-summaries, the
    /// summaries of the shards.
    #[arg(required = true)]
    pub inputs: Vec<PathBuf>,
    /// Machine file, or the name of a bundled one (`postproc machines`).
    #[arg(short, long, required_unless_present = "merge_summaries")]
    pub machine: Option<String>,
    /// Compensate only the K-th of N shares of the programs (1 <= K <= N):
    /// program i of the sorted list belongs to share i mod N + 1, so N runs
    /// with K = 1..N cover every program once (a Slurm job array, a
    /// Kubernetes indexed Job; docs/batch.md). `auto` reads K and N from
    /// a Slurm job array's variables, `auto/N` K from a Kubernetes indexed
    /// Job's JOB_COMPLETION_INDEX.
    #[arg(long, value_name = "K/N|auto[/N]", conflicts_with = "merge_summaries")]
    pub shard: Option<ShardSpec>,
    /// Merge the batch-summary.json files of shards (the inputs) into one
    /// in --out-dir; nothing is compensated.
    #[arg(long)]
    pub merge_summaries: bool,
    /// Folder for the compensated programs (same names; folder inputs keep
    /// their sub-folders) and batch-summary.json.
    #[arg(long)]
    pub out_dir: PathBuf,
    /// Read RAPID modules a window of this many lines at a time whatever
    /// their size (those of 1 MB and more are read so by default, 16 MB with
    /// a warm thermal start; for
    /// tests).
    #[arg(long = "rapid-window-lines", value_name = "LINES", hide = true)]
    pub rapid_window_lines: Option<usize>,
    /// G-code: tool length for an H number, overriding the machine file: H1=123.4 (mm).
    #[arg(long = "tool", value_name = "H=LENGTH")]
    pub tools: Vec<ToolLength>,
    /// G-code: work offset overriding the machine file: G54=X,Y,Z (mm, machine coordinates).
    #[arg(long = "work-offset", value_name = "GXX=X,Y,Z")]
    pub work_offsets: Vec<WorkOffset>,
    /// G-code: the control's unit for programs without G20/G21.
    #[arg(long, value_enum)]
    pub units: Option<UnitsArg>,
    /// Effects.
    #[command(flatten)]
    pub effects: EffectArgs,
    /// Machine tools: largest gap between attained and programmed path
    /// along a move, mm (at least 0.000001: ten times the solver's
    /// convergence; default: the machine file's
    /// `compensation.tolerance_mm`, else 0.001).
    #[arg(long)]
    pub tolerance: Option<f64>,
    /// Annotate compensated blocks with their predicted deviation.
    #[arg(long, value_enum, default_value_t = Annotate::Comment)]
    pub annotate: Annotate,
    /// Also write each program's deviation report beside its output, as
    /// `<output>.report.<txt|csv|json|svg>`.
    #[arg(long, value_enum)]
    pub report_format: Option<Format>,
    /// Compensate programs that carry a postproc header too (refused by
    /// default: the correction would be applied twice).
    #[arg(long)]
    pub recompensate: bool,
    /// RAPID modules: a module in which a move is left as written (its
    /// target known at run time only) fails, naming the first one.
    #[arg(long)]
    pub strict: bool,
}

/// Options shared by the commands that read a G-code program.
#[derive(Debug, Args, Clone)]
pub struct ProgramArgs {
    /// The program (`-` reads standard input); for RAPID also a folder
    /// (a controller backup's task folder) or a `.pgf` program file.
    pub file: PathBuf,
    /// RAPID: more modules of the same program (names resolve across
    /// them).
    #[arg(value_name = "MORE")]
    pub more: Vec<PathBuf>,
    /// Machine file, or the name of a bundled one (`postproc machines`).
    #[arg(short, long)]
    pub machine: Option<String>,
    /// G-code: tool length for an H number, overriding the machine file: H1=123.4 (mm).
    #[arg(long = "tool", value_name = "H=LENGTH")]
    pub tools: Vec<ToolLength>,
    /// G-code: work offset overriding the machine file: G54=X,Y,Z (mm,
    /// machine coordinates; also G54.1P1, G154P1).
    #[arg(long = "work-offset", value_name = "GXX=X,Y,Z")]
    pub work_offsets: Vec<WorkOffset>,
    /// G-code: the control's unit for a program without G20/G21,
    /// overriding the machine file's `units_default`.
    #[arg(long, value_enum)]
    pub units: Option<UnitsArg>,
    /// Read a RAPID module a window of this many lines at a time whatever
    /// its size (modules of 1 MB and more are read so by default, 16 MB
    /// with a warm thermal start; for
    /// tests).
    #[arg(long = "rapid-window-lines", value_name = "LINES", hide = true)]
    pub rapid_window_lines: Option<usize>,
    /// RAPID: refuse a module in which a move is left as written (its
    /// target known at run time only), naming the first one (exit code 2).
    /// Refused for G-code, where no block is left as written.
    #[arg(long)]
    pub strict: bool,
    /// RAPID: compensate `MoveAbsJ` targets as Cartesian poses (their
    /// joints moved so that the TCP reaches the nominal pose of the
    /// programmed joints); by default each is reported and left as written.
    #[arg(long)]
    pub compensate_joint_targets: bool,
    /// G-code: write a canned-cycle hole (G73, G81, G82, G83, G85, G89,
    /// drilled once) whose one X and Y would miss the tolerance along its
    /// depth as the cycle's G0/G1/G4 moves, corrected along the depth;
    /// without it (or the machine file's
    /// `output.expand_deep_holes_to_moves`) such a hole is warned about.
    #[arg(long)]
    pub expand_cycles: bool,
}

/// `postproc check`.
#[derive(Debug, Args)]
pub struct CheckArgs {
    /// The program and machine.
    #[command(flatten)]
    pub program: ProgramArgs,
}

/// `--units`: the control's unit for programs that set none.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum UnitsArg {
    /// Millimetres (as G21).
    Mm,
    /// Inches (as G20).
    Inch,
}

/// Where annotations go.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Annotate {
    /// Append a comment with the predicted deviation to compensated blocks
    /// (ending in `takeup` where the block's own line first moves onto its
    /// start, solved for the new direction of motion, load or tool).
    Comment,
    /// No annotation.
    None,
}

/// Options of a prediction (effects and gains).
#[derive(Debug, Args, Clone)]
pub struct EffectArgs {
    /// Effects to predict: all, none, or a list (machine tools: geometric, static, thermal, dynamic; robots: kinematic, gravity, process, thermal, dynamic; dynamic is reported, not compensated).
    #[arg(long, default_value = "all")]
    pub effects: EffectSpec,
    /// Scale an effect: --gain geometric=0.5, --gain thermal=0.8 (0..10).
    #[arg(long = "gain", value_name = "EFFECT=GAIN")]
    pub gains: Vec<Gain>,
    /// Machine tools: scale each effect's correction by how well its parameters are known (the machine file's parameter covariance, which `calibrate` writes; docs/verify.md), times its --gain.
    #[arg(long)]
    pub gain_auto: bool,
    /// Process force instead of the machine file's `process_force`: none, or `constant:FX,FY,FZ[@workpiece|tool|feed]` (N, force on the tool).
    #[arg(long, value_name = "SPEC")]
    pub force: Option<ForceSpec>,
    /// Per-line process forces from a CSV file (line,fx_n,fy_n,fz_n; workpiece frame, N).
    #[arg(long, value_name = "FILE", conflicts_with = "force")]
    pub force_table: Option<PathBuf>,
    /// Milling axial depth of cut until a program directive sets one, mm.
    #[arg(long, value_name = "MM")]
    pub milling_depth: Option<f64>,
    /// Milling radial width of cut until a program directive sets one, mm.
    #[arg(long, value_name = "MM")]
    pub milling_width: Option<f64>,
    /// Thermal state at the program start: cold, steady (the steady state of the program's mean power) or MINUTES of warm-up at that power.
    #[arg(long, value_name = "START", default_value = "cold")]
    pub thermal_start: ThermalStart,
    /// Worker threads (default: all cores); a G-code program's own thread
    /// interprets and writes alongside them. Output is the same for any
    /// count. At most 4 per core.
    #[arg(long, value_parser = crate::limits::parse_threads)]
    pub threads: Option<usize>,
    /// Robots: accept compensated targets that change the configuration or
    /// move a joint by more than 5° from the programmed solution (near a
    /// singularity); refused by default.
    #[arg(long)]
    pub allow_reconfiguration: bool,
}

/// `postproc compensate`.
#[derive(Debug, Args)]
pub struct CompensateArgs {
    /// The program and machine.
    #[command(flatten)]
    pub program: ProgramArgs,
    /// Effects.
    #[command(flatten)]
    pub effects: EffectArgs,
    /// Output path (default `<stem>.comp.<ext>` beside the input; `-` = stdout).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Write the output into this folder under the program's own file name
    /// instead of beside the input (a RAPID program of several modules: the
    /// modules that change, a folder input keeping its sub-folders).
    #[arg(long, conflicts_with = "output")]
    pub out_dir: Option<PathBuf>,
    /// Machine tools: largest gap between attained and programmed path
    /// along a move, mm (at least 0.000001: ten times the solver's
    /// convergence; default: the machine file's
    /// `compensation.tolerance_mm`, else 0.001).
    #[arg(long)]
    pub tolerance: Option<f64>,
    /// Annotate compensated blocks with their predicted deviation.
    #[arg(long, value_enum, default_value_t = Annotate::Comment)]
    pub annotate: Annotate,
    /// Decimals of rewritten mm coordinates and rotary degrees (default: the machine file's, else the program's, at least 3); half a unit of the last one must stay within the tolerance (RAPID: at least 3).
    #[arg(long)]
    pub decimals: Option<usize>,
    /// Also write the deviation report to this path (format from the
    /// extension: .csv, .json, .svg, .txt; else CSV).
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Format of the --report file, overriding its extension.
    #[arg(long, value_enum, requires = "report")]
    pub report_format: Option<Format>,
    /// Compensate a program that carries a postproc header (refused by
    /// default: the correction would be applied twice).
    #[arg(long)]
    pub recompensate: bool,
}

/// `postproc report`.
#[derive(Debug, Args)]
pub struct ReportArgs {
    /// The program and machine.
    #[command(flatten)]
    pub program: ProgramArgs,
    /// Effects.
    #[command(flatten)]
    pub effects: EffectArgs,
    /// Output format.
    #[arg(long, value_enum, default_value_t = Format::Table)]
    pub format: Format,
    /// Write to this file instead of standard output.
    #[arg(short, long)]
    pub output: Option<PathBuf>,
}

/// Sets up logging on stderr from `-q`/`-v` (or `RUST_LOG`).
pub fn init_logging(quiet: bool, verbose: u8) {
    let level = if quiet {
        "error"
    } else {
        match verbose {
            0 => "warn",
            1 => "info",
            _ => "debug",
        }
    };
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(level));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(output::colour(
            std::io::IsTerminal::is_terminal(&std::io::stderr()),
            std::env::var_os("NO_COLOR").as_deref(),
        ))
        .with_target(false)
        .without_time()
        .try_init();
}

/// Runs a parsed command line; returns the process exit code.
pub fn run(cli: Cli) -> Result<i32> {
    use config::Engine;
    init_logging(cli.quiet, cli.verbose);
    let quiet = cli.quiet;
    let code = match cli.command {
        Command::Check(a) if krl::is_krl(&a.program.file) => krl::check(&a),
        Command::Compensate(a) if krl::is_krl(&a.program.file) => krl::compensate(&a, quiet),
        Command::Report(a) if krl::is_krl(&a.program.file) => krl::report(&a),
        Command::Check(a) if tp::is_tp(&a.program.file) => tp::check(&a),
        Command::Compensate(a) if tp::is_tp(&a.program.file) => tp::compensate(&a, quiet),
        Command::Report(a) if tp::is_tp(&a.program.file) => tp::report(&a),
        Command::Check(a) => match Engine::choose(&a.program, config::Given::check(&a))? {
            Engine::Robot(robot) => rapid::check(&a, robot),
            Engine::Tool(machine) => {
                refuse_strict(&a.program)?;
                gcode::check(&a, machine)
            }
        },
        Command::Compensate(a) => {
            match Engine::choose(&a.program, config::Given::compensate(&a))? {
                Engine::Robot(robot) => rapid::compensate(&a, robot, quiet),
                Engine::Tool(machine) => {
                    refuse_strict(&a.program)?;
                    gcode::compensate(&a, machine, quiet)
                }
            }
        }
        Command::Report(a) => match Engine::choose(&a.program, config::Given::report(&a))? {
            Engine::Robot(robot) => rapid::report(&a, robot),
            Engine::Tool(machine) => {
                refuse_strict(&a.program)?;
                gcode::report(&a, machine)
            }
        },
        Command::Batch(a) => batch::run(&a, quiet),
        Command::Simulate(a) => calibrate::run_simulate(&a),
        Command::Calibrate(a) => calibrate::run_calibrate(&a),
        Command::Diagnose(a) => diagnose::run(&a),
        Command::Machines(a) => machines::run(&a),
        Command::Verify(a) => verify::run(&a),
        Command::Completions { shell } => completions::completions(shell),
        Command::Man => completions::man(),
    }?;
    machines::warn_example_used();
    Ok(code)
}

/// `--strict` of a G-code program: refused (a G-code block is never left
/// as written).
fn refuse_strict(p: &ProgramArgs) -> Result<()> {
    if !p.more.is_empty() {
        return Err(usage(
            "several program files: a RAPID program of several modules (a G-code program is one file)",
        ));
    }
    if p.strict {
        return Err(usage(
            "--strict applies to RAPID modules (moves left as written); a G-code program has none",
        ));
    }
    Ok(())
}

pub(crate) fn usage(msg: impl Into<String>) -> Error {
    Error::Usage(msg.into())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    #[test]
    fn report_format_from_extension() {
        assert_eq!(Format::from_path(Path::new("a/r.JSON")), Format::Json);
        assert_eq!(Format::from_path(Path::new("r.svg")), Format::Svg);
        assert_eq!(Format::from_path(Path::new("r.txt")), Format::Table);
        assert_eq!(Format::from_path(Path::new("r.csv")), Format::Csv);
        // Anything else stays CSV, as before formats existed.
        assert_eq!(Format::from_path(Path::new("report")), Format::Csv);
    }

    #[test]
    fn cli_definition_is_consistent() {
        use clap::CommandFactory;
        Cli::command().debug_assert();
    }
}
