//! The RAPID commands: `check` and `compensate` of an ABB RAPID module
//! against a robot machine file.

use std::io::Write;
use std::path::{Path, PathBuf};

use super::gcode::{default_output, write_atomically};
use super::{Annotate, CheckArgs, CompensateArgs, ProgramArgs, usage};
use crate::compensate::rapid::{RapidOptions, compensate_module};
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

fn load_robot(name: &str) -> Result<Robot> {
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

fn read_program(path: &Path) -> Result<(String, String)> {
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

/// `postproc check` of a RAPID module: parse, resolve and (with a robot)
/// check that every target is reachable with its confdata.
pub fn check(a: &CheckArgs) -> Result<i32> {
    let (src, name) = read_program(&a.program.file)?;
    let module = crate::program::rapid::parse_module(&src, &name)?;
    if let Some(m) = a.program.machine.as_deref() {
        let robot = load_robot(m)?;
        let opts = RapidOptions {
            effects: Effects::NONE,
            annotate: false,
            format: Format::default(),
            thermal_start: ThermalStart::Cold,
        };
        compensate_module(&src, &name, &robot, &opts)?;
    }
    let moves = module.moves().count();
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "{name}: module {}, {} declarations, {} routines, {} moves",
        module.name,
        module.decls.len(),
        module.procs.len(),
        moves
    )
    .map_err(|e| Error::io("stdout", e))?;
    Ok(0)
}

/// `postproc compensate` of a RAPID module.
pub fn compensate(a: &CompensateArgs) -> Result<i32> {
    let machine = a
        .program
        .machine
        .as_deref()
        .ok_or_else(|| usage("compensate needs --machine"))?;
    let robot = load_robot(machine)?;
    if a.report.is_some() {
        return Err(usage("--report is not supported for RAPID programs yet"));
    }
    if !a.program.tools.is_empty() || !a.program.work_offsets.is_empty() {
        return Err(usage(
            "--tool and --work-offset are G-code options; RAPID takes tooldata and wobjdata from the module",
        ));
    }
    let mut format = RapidOptions::for_robot(&robot).format;
    if let Some(d) = a.decimals {
        if d > 6 {
            return Err(usage("--decimals: at most 6"));
        }
        format.position_decimals = d.max(3);
    }
    let thermal_start: ThermalStart = a
        .effects
        .thermal_start
        .parse()
        .map_err(|e| usage(format!("--thermal-start: {e}")))?;
    let opts = RapidOptions {
        effects: robot_gains(robot_effects(&a.effects.effects)?, &a.effects.gains)?,
        annotate: a.annotate == Annotate::Comment,
        format,
        thermal_start,
    };
    let input = &a.program.file;
    let out_path = match &a.output {
        Some(p) => p.clone(),
        None if input == Path::new("-") => PathBuf::from("-"),
        None => default_output(input),
    };
    if out_path != Path::new("-")
        && input != Path::new("-")
        && (out_path == *input
            || matches!((input.canonicalize(), out_path.canonicalize()), (Ok(x), Ok(y)) if x == y))
    {
        return Err(usage(format!(
            "{}: the output would overwrite the input",
            out_path.display()
        )));
    }
    let (src, name) = read_program(input)?;
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
    tracing::info!(
        "{}: {} moves compensated, {} targets added; largest predicted deviation {:.4} mm (line {})",
        out_path.display(),
        outcome.moves,
        outcome.added,
        outcome.max_deviation_mm,
        outcome.max_deviation_line
    );
    Ok(0)
}
