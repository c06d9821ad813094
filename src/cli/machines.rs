//! The machine file of a run: resolving `--machine` (a file, or a machine
//! bundled in the binary), its status (with the warning for an example
//! file), the provenance a compensated program and its report carry, the
//! refusal of a program compensated before, and `postproc machines`
//! (the listing, and `machines new`: a robot cell file to start from).

use std::io::{BufRead, Read, Write};
use std::path::{Path, PathBuf};

use crate::emit::header::{self, EffectGain, Provenance};
use crate::error::{Error, Located, Result, show_number};
use crate::machine::status::SectionStatus;
use crate::machine::{BUNDLED, Machine, MachineFile, Status};
use crate::predict::{Effect, EffectSet};

/// A machine file read for a run: the file and its status.
#[derive(Debug, Clone)]
pub(super) struct Loaded {
    pub file: MachineFile,
    pub status: Status,
    /// The uncertainty of the model's predictions from the file's
    /// `covariance` list (`None`: it carries none).
    pub uncertainty: Option<std::sync::Arc<crate::predict::uncertainty::BlockUncertainty>>,
    /// The gains `--gain-auto` gave the effects, if asked for.
    pub auto_gains: Vec<(&'static str, f64)>,
}

/// Reads `--machine NAME` for a run on programs (its validated model and
/// the file), warning when the file holds example values.
pub(super) fn open(name: &str) -> Result<(Machine, Loaded)> {
    let file = MachineFile::open(name)?;
    let (machine, status) = file.read()?;
    warn_example(&file, &status);
    let blocks = crate::predict::uncertainty::read_covariance(&file.text, &file.shown)?;
    let uncertainty =
        crate::predict::uncertainty::BlockUncertainty::of_machine(&machine, &blocks, &file.shown)?
            .map(std::sync::Arc::new);
    Ok((
        machine,
        Loaded {
            file,
            status,
            uncertainty,
            auto_gains: Vec::new(),
        },
    ))
}

/// The machine file of `status: example` or `nominal`, or with model
/// sections still at such values, a run used: its name, its status and
/// its sections.
type Unmeasured = (String, Status, Vec<SectionStatus>);

/// The machine file with unmeasured values a run used, if any.
static UNMEASURED_USED: std::sync::OnceLock<Unmeasured> = std::sync::OnceLock::new();

/// Notes a run with a machine file of `status: example` or `nominal`, or
/// one whose `status` map leaves sections at such values, warned about by
/// [`warn_example_used`] once the command is done.
pub(super) fn warn_example(file: &MachineFile, status: &Status) {
    let sections = crate::machine::yaml::Source::read(&file.text, &file.shown)
        .and_then(|src| crate::machine::status::sections(&src))
        .unwrap_or_default();
    let partly = sections.iter().any(SectionStatus::unmeasured);
    if matches!(status, Status::Example | Status::Nominal) || partly {
        let _ = UNMEASURED_USED.set((file.shown.clone(), status.clone(), sections));
    }
}

/// The warning of every run that used a machine file of `status:
/// example` or `nominal`, or with sections still at example or nominal
/// values (named): once, after the command (whatever path it took through
/// the program), so that the run's own messages come first.
pub(super) fn warn_example_used() {
    match UNMEASURED_USED.get() {
        Some((shown, Status::Nominal, _)) => tracing::warn!(
            "{shown}: nominal model, not measured data (`status: nominal`): the published kinematics predict no kinematic error, and the gravity sag comes from estimated masses and joint stiffness; calibrate the robot (`postproc calibrate kinematics`) before compensating real parts"
        ),
        Some((shown, Status::Calibrated(_), sections)) => {
            let left = |word: &str| {
                sections
                    .iter()
                    .filter(|s| s.word == word)
                    .map(|s| s.section.label())
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            let done: Vec<String> = sections
                .iter()
                .filter(|s| s.calibration.is_some())
                .map(SectionStatus::describe)
                .collect();
            let (example, nominal) = (left("example"), left("nominal"));
            let mut still = Vec::new();
            if !example.is_empty() {
                still.push(format!("{example} still example values"));
            }
            if !nominal.is_empty() {
                still.push(format!("{nominal} still nominal values"));
            }
            tracing::warn!(
                "{shown}: {}, not measured data ({}): calibrate them before compensating real parts",
                still.join("; "),
                done.join("; ")
            )
        }
        Some((shown, _, _)) => tracing::warn!(
            "{shown}: example values, not measured data (`status: example`): calibrate the machine before compensating real parts"
        ),
        None => {}
    }
}

/// The provenance of a run with `file`.
pub(super) fn provenance(
    loaded: &Loaded,
    effects: Vec<EffectGain>,
    tolerance_mm: Option<f64>,
    annotated: bool,
) -> Provenance {
    Provenance {
        version: env!("CARGO_PKG_VERSION"),
        machine_file: loaded.file.file_name.clone(),
        machine_bundled: loaded.file.is_bundled(),
        machine_sha256: loaded.file.sha256(),
        status: loaded.status.clone(),
        effects,
        tolerance_mm,
        annotated,
        uncertainty: loaded.uncertainty.clone(),
        auto_gains: loaded.auto_gains.clone(),
    }
}

/// `--gain-auto`: each effect's gain in `set` times the gain the machine
/// file's parameter covariance gives it
/// ([`crate::predict::uncertainty::BlockUncertainty::auto_gains`]),
/// recorded in `loaded` for the provenance. Refused for a file without a
/// covariance.
pub(super) fn auto_gain(set: EffectSet, on: bool, loaded: &mut Loaded) -> Result<EffectSet> {
    if !on {
        return Ok(set);
    }
    let Some(u) = &loaded.uncertainty else {
        return Err(super::usage(format!(
            "--gain-auto: {} carries no parameter covariance of its geometry (`postproc calibrate geometry` writes one)",
            loaded.file.shown
        )));
    };
    let mut set = set;
    loaded.auto_gains.clear();
    for (name, g) in u.auto_gains() {
        if let Some(&e) = Effect::TOOL.iter().find(|e| e.name() == name) {
            let gain = set.gain(e) * g;
            set = set.with_gain(e, gain);
            loaded.auto_gains.push((name, g));
        }
    }
    Ok(set)
}

/// The effects and gains of a machine-tool run.
pub(super) fn tool_effects(set: &EffectSet) -> Vec<EffectGain> {
    Effect::TOOL
        .iter()
        .map(|&e| EffectGain {
            effect: e.name(),
            gain: set.gain(e),
            reported_only: !e.compensated(),
        })
        .collect()
}

/// The effects and gains of a robot run.
pub(super) fn robot_effects(set: &crate::predict::EffectSet) -> Vec<EffectGain> {
    Effect::ROBOT
        .iter()
        .map(|&e| EffectGain {
            effect: e.robot_name(),
            gain: set.gain(e),
            reported_only: !e.compensated(),
        })
        .collect()
}

/// The refusal of a program that carries a postproc header at `line`.
pub(super) fn compensated_before(file: &str, line: usize) -> Error {
    Error::Input(Located::new(
        file,
        line,
        1,
        "this program was compensated by postproc (its header says so); compensating it again would apply the correction twice: compensate the original program, or give --recompensate",
    ))
}

/// Refuses a program whose head (`head`, its first bytes) carries a
/// postproc header, unless `recompensate`.
pub(super) fn refuse_compensated(head: &[u8], file: &str, recompensate: bool) -> Result<()> {
    match header::find_marker(head) {
        Some(line) if !recompensate => Err(compensated_before(file, line)),
        Some(_) => {
            tracing::warn!(
                "{file}: compensated by postproc before; compensated again (--recompensate)"
            );
            Ok(())
        }
        None => Ok(()),
    }
}

/// Reads the head of `input` ([`header::HEAD_BYTES`]) and gives it back
/// with a reader of the whole input.
pub(super) fn peek_head(
    input: Box<dyn BufRead>,
    file: &str,
) -> Result<(Vec<u8>, Box<dyn BufRead>)> {
    let mut input = input;
    let mut head = Vec::with_capacity(4096);
    (&mut input)
        .take(header::HEAD_BYTES as u64)
        .read_to_end(&mut head)
        .map_err(|e| Error::io(file, e))?;
    let again = std::io::Cursor::new(head.clone());
    Ok((head, Box::new(again.chain(input))))
}

/// `postproc machines [new NAME -o FILE]`.
#[derive(Debug, clap::Args)]
pub struct MachinesArgs {
    /// Without one, list the bundled machine files.
    #[command(subcommand)]
    pub action: Option<MachinesAction>,
}

/// What `postproc machines` does besides listing.
#[derive(Debug, clap::Subcommand)]
pub enum MachinesAction {
    /// Write a robot cell file to start from: a bundled robot model with
    /// its base, tool and tool load to fill in, and comments saying what to
    /// measure.
    New {
        /// The bundled robot (`postproc machines` lists them).
        name: String,
        /// Cell file to write (`-` for standard output); an existing file
        /// is not replaced.
        #[arg(short, long)]
        output: PathBuf,
    },
}

/// `postproc machines`: lists the bundled machine files, or writes a cell
/// file.
pub fn run(args: &MachinesArgs) -> Result<i32> {
    match &args.action {
        None => list(),
        Some(MachinesAction::New { name, output }) => new_cell(name, output),
    }
}

/// The listing: every bundled machine file with its kind, status, the
/// published reach and payload of a robot (its `datasheet`) and its name.
fn list() -> Result<i32> {
    let mut rows = Vec::with_capacity(BUNDLED.len());
    for (name, _) in BUNDLED {
        let file = MachineFile::bundled(name).expect("a bundled machine");
        let (machine, status) = file.read()?;
        let (kind, title, sheet) = match machine {
            Machine::Tool(m) => ("machine tool", m.name().to_string(), None),
            Machine::Robot(r) => ("robot", r.name().to_string(), r.datasheet().copied()),
        };
        let (reach, payload) = match sheet {
            Some(d) => (
                format!("{:.0} mm", d.reach_mm),
                format!("{} kg", show_number(d.payload_kg)),
            ),
            None => ("-".to_string(), "-".to_string()),
        };
        rows.push([
            name.to_string(),
            kind.to_string(),
            status.word().to_string(),
            reach,
            payload,
            title,
        ]);
    }
    let width = rows.iter().map(|r| r[0].len()).max().unwrap_or(0);
    let mut text = String::from(
        "bundled machine files (use with --machine NAME from any folder; a file path is read instead):\n",
    );
    text.push_str(&format!(
        "  {:<width$} {:<13} {:<11} {:>7} {:>7}  machine\n",
        "name", "kind", "status", "reach", "payload"
    ));
    for [name, kind, status, reach, payload, title] in &rows {
        text.push_str(&format!(
            "  {name:<width$} {kind:<13} {status:<11} {reach:>7} {payload:>7}  {title}\n"
        ));
    }
    text.push_str(
        "reach and payload: the maker's published figures (robots with a `datasheet`); `postproc machines new NAME -o cell.yaml` starts a robot cell\n",
    );
    write_stdout(&text)?;
    Ok(0)
}

fn write_stdout(text: &str) -> Result<()> {
    let mut out = std::io::stdout().lock();
    out.write_all(text.as_bytes())
        .and_then(|()| out.flush())
        .map_err(|e| Error::io("stdout", e))
}

/// `postproc machines new NAME -o FILE`: writes the cell file of the
/// bundled robot `name` ([`cell_text`]), checked to load, to `output`
/// (never over an existing file).
fn new_cell(name: &str, output: &Path) -> Result<i32> {
    let file = MachineFile::bundled(name).ok_or_else(|| {
        let names: Vec<&str> = BUNDLED.iter().map(|(n, _)| *n).collect();
        Error::Usage(format!(
            "`{name}` is not a bundled machine ({})",
            names.join(", ")
        ))
    })?;
    let Machine::Robot(robot) = file.load()? else {
        return Err(Error::Usage(format!(
            "`{name}` is a machine tool: a cell file starts from a robot model"
        )));
    };
    let text = cell_text(&file, &robot);
    // The written file must load as it is.
    Machine::from_yaml_str(&text, &format!("{name} cell"))?;
    if output.as_os_str() == "-" {
        write_stdout(&text)?;
        return Ok(0);
    }
    let shown = output.display().to_string();
    if output.exists() {
        return Err(Error::Usage(format!(
            "{shown} exists: a cell file is never written over (remove it or name another file)"
        )));
    }
    std::fs::write(output, text.as_bytes()).map_err(|e| Error::io(&shown, e))?;
    tracing::info!(
        "wrote {shown}: fill in what the comments ask, then `postproc check PROGRAM --machine {shown}`"
    );
    Ok(0)
}

/// Top-level keys of a robot file that a cell file sets itself.
const CELL_KEYS: [&str; 3] = ["base:", "flange_to_tool:", "tool_load:"];

/// The cell file of a bundled robot: a head saying what it is and what to
/// measure, the model's text without its `base`, `flange_to_tool` and
/// `tool_load` lines (and the comment lines right above them), then those
/// keys again with what to measure for each, and the work objects the
/// programs carry.
fn cell_text(file: &MachineFile, robot: &crate::machine::robot::Robot) -> String {
    let lines: Vec<&str> = file.text.lines().collect();
    let mut keep = vec![true; lines.len()];
    for (i, line) in lines.iter().enumerate() {
        if CELL_KEYS.iter().any(|k| line.starts_with(k)) {
            keep[i] = false;
            let mut j = i;
            while j > 0 && lines[j - 1].starts_with('#') {
                j -= 1;
                keep[j] = false;
            }
        }
    }
    let stem = file.file_name.trim_end_matches(".yaml");
    let mut text = format!(
        "# Robot cell with an {title}, started by `postproc machines new {stem}`.\n\
         # Measure what the comments at the end ask (base, tool, tool load), then\n\
         # check a program with `postproc check PROGRAM --machine THIS_FILE`. The\n\
         # arm's own errors come from `postproc calibrate kinematics` (a laser\n\
         # tracker or other 3D measurement of the TCP in 50 or more poses).\n\
         #\n\
         # The robot model as bundled ({stem}.yaml):\n",
        title = robot.name()
    );
    for (line, _) in lines.iter().zip(&keep).filter(|(_, k)| **k) {
        text.push_str(line);
        text.push('\n');
    }
    text.push_str(CELL_TAIL);
    text
}

/// The cell part of a cell file: base, tool, tool load and work objects,
/// each with what to measure.
const CELL_TAIL: &str = "\
#
# ---- The cell: MEASURE these ----
# base: where the robot base frame stands in the world frame of your
# programs (RAPID's wobjdata and robtargets are given in the world frame).
# Identity when the world frame is the robot base frame (a single robot on
# the floor, no `world` set in the controller). Else copy the base frame
# from the controller's configuration (Motion, Robot, base frame), or
# measure three or more points on the base plate with a tracker.
base: { x_mm: 0.0, y_mm: 0.0, z_mm: 0.0, quaternion: [1.0, 0.0, 0.0, 0.0] }
# flange_to_tool: the TCP of the tool the programs use, in the flange
# frame (tooldata `tframe`). The identity is tool0, the flange centre.
# Copy the tooldata the controller holds (defined by the 4- or 5-point
# method on a fixed tip), or measure the tool on a presetter. A program's
# own tooldata takes precedence for its moves.
flange_to_tool: { x_mm: 0.0, y_mm: 0.0, z_mm: 0.0, quaternion: [1.0, 0.0, 0.0, 0.0] }
# tool_load: mass (kg) and centre of gravity (mm, flange frame) of the tool
# and what it carries; it sets the gravity sag of the arm. Run the
# controller's LoadIdentify service routine, or weigh the tool, and write:
# tool_load: { mass_kg: 5.0, cog_mm: [0.0, 0.0, 80.0] }
#
# Work objects are not part of this file: the programs carry them
# (wobjdata, user frame `uframe` and object frame `oframe`) and postproc
# reads them from there. Measure each fixture with the controller's
# three-point user-frame method (origin, a point on x, a point in the
# xy plane) with a calibrated tool, and write it into the program:
#   PERS wobjdata wobjFixture:=[FALSE,TRUE,\"\",[[x,y,z],[q1,q2,q3,q4]],[[0,0,0],[1,0,0,0]]];
";
