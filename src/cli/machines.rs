//! The machine file of a run: resolving `--machine` (a file, or a machine
//! bundled in the binary), its status (with the warning for an example
//! file), the provenance a compensated program and its report carry, the
//! refusal of a program compensated before, and `postproc machines`.

use std::io::{BufRead, Read, Write};

use crate::emit::header::{self, EffectGain, Provenance};
use crate::error::{Error, Located, Result};
use crate::machine::{BUNDLED, Machine, MachineFile, Status};
use crate::predict::{Effect, EffectSet};

/// A machine file read for a run: the file and its status.
#[derive(Debug, Clone)]
pub(super) struct Loaded {
    pub file: MachineFile,
    pub status: Status,
}

/// Reads `--machine NAME` for a run on programs (its validated model and
/// the file), warning when the file holds example values.
pub(super) fn open(name: &str) -> Result<(Machine, Loaded)> {
    let file = MachineFile::open(name)?;
    let machine = file.load()?;
    let status = file.status()?;
    warn_example(&file, &status);
    Ok((machine, Loaded { file, status }))
}

/// The machine file of `status: example` a run used, if any.
static EXAMPLE_USED: std::sync::OnceLock<String> = std::sync::OnceLock::new();

/// Notes a run with a machine file of `status: example`, warned about by
/// [`warn_example_used`] once the command is done.
pub(super) fn warn_example(file: &MachineFile, status: &Status) {
    if *status == Status::Example {
        let _ = EXAMPLE_USED.set(file.shown.clone());
    }
}

/// The warning of every run that used a machine file of `status:
/// example`: once, after the command (whatever path it took through the
/// program), so that the run's own messages come first.
pub(super) fn warn_example_used() {
    if let Some(shown) = EXAMPLE_USED.get() {
        tracing::warn!(
            "{shown}: example values, not measured data (`status: example`): calibrate the machine before compensating real parts"
        );
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
    }
}

/// The effects and gains of a machine-tool run.
pub(super) fn tool_effects(set: &EffectSet) -> Vec<EffectGain> {
    Effect::ALL
        .iter()
        .map(|&e| EffectGain {
            effect: e.name(),
            gain: set.gain(e),
            reported_only: !e.compensated(),
        })
        .collect()
}

/// The effects and gains of a robot run.
pub(super) fn robot_effects(e: &crate::machine::robot::Effects) -> Vec<EffectGain> {
    let g = |effect, gain, reported_only| EffectGain {
        effect,
        gain,
        reported_only,
    };
    vec![
        g("kinematic", e.kinematic, false),
        g("gravity", e.gravity, false),
        g("process", e.process, false),
        g("thermal", e.thermal, false),
        g("dynamic", e.dynamic, true),
    ]
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

/// `postproc machines`: the bundled machine files with their kind, name
/// and status.
pub fn list() -> Result<i32> {
    let mut text = String::from(
        "bundled machine files (use with --machine NAME from any folder; a file path is read instead):\n",
    );
    for (name, _) in BUNDLED {
        let file = MachineFile::bundled(name).expect("a bundled machine");
        let (kind, title) = match file.load()? {
            Machine::Tool(m) => ("machine tool", m.name().to_string()),
            Machine::Robot(r) => ("robot", r.name().to_string()),
        };
        text.push_str(&format!(
            "  {name:<14} {kind:<13} {:<12} {title}\n",
            file.status()?.word()
        ));
    }
    let mut out = std::io::stdout().lock();
    out.write_all(text.as_bytes())
        .and_then(|()| out.flush())
        .map_err(|e| Error::io("stdout", e))?;
    Ok(0)
}
