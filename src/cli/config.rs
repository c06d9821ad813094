//! The run of `check`, `compensate`, `report` and `batch`, set up once from
//! the flags: the machine file loaded once, the engine chosen (G-code on a
//! machine tool, RAPID on a robot) and the flags that do not apply to that
//! engine refused with a message (exit 2) rather than ignored.
//!
//! | flag | machine tool (G-code) | robot (RAPID) |
//! |---|---|---|
//! | `--tool`, `--work-offset`, `--units` | yes | refused |
//! | `--tolerance` | yes | refused |
//! | `--gain-auto` | yes | refused |
//! | `--allow-reconfiguration` | refused | yes |
//! | `--rapid-window-lines` | refused | yes |
//! | every other flag | yes | yes |
//!
//! `--effects` and `--gain` take the names of the engine's effects; a name
//! of the other engine's is refused when the machine is known.

use super::machines::Loaded;
use super::{CheckArgs, CompensateArgs, ProgramArgs, ReportArgs, usage};
use crate::error::{Error, Result};
use crate::machine::Machine;
use crate::machine::robot::Robot;
use crate::machine::tool::MachineTool;

/// The engine of a run on one program, with its machine.
pub(super) enum Engine {
    /// G-code; the machine tool of `--machine`, when given.
    Tool(Option<(MachineTool, Loaded)>),
    /// RAPID; the robot of `--machine`, when given, or why there is none
    /// (a file that does not load, or a machine tool): `check` reports the
    /// module's own errors first.
    Robot(Option<Result<(Robot, Loaded)>>),
}

/// The kinds of engine.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Kind {
    /// G-code on a machine tool.
    Tool,
    /// RAPID on a robot.
    Robot,
}

/// Which engine-specific flags a command line gives.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Given {
    /// `--tool` or `--work-offset`.
    pub tools_or_offsets: bool,
    /// `--units`.
    pub units: bool,
    /// `--tolerance`.
    pub tolerance: bool,
    /// `--allow-reconfiguration`.
    pub allow_reconfiguration: bool,
    /// `--rapid-window-lines`.
    pub rapid_window_lines: bool,
    /// `--gain-auto`.
    pub gain_auto: bool,
}

impl Given {
    /// The program flags.
    fn program(p: &ProgramArgs) -> Self {
        Given {
            tools_or_offsets: !p.tools.is_empty() || !p.work_offsets.is_empty(),
            units: p.units.is_some(),
            rapid_window_lines: p.rapid_window_lines.is_some(),
            ..Given::default()
        }
    }

    /// The flags of `check`.
    pub(super) fn check(a: &CheckArgs) -> Self {
        Given::program(&a.program)
    }

    /// The flags of `compensate`.
    pub(super) fn compensate(a: &CompensateArgs) -> Self {
        Given {
            tolerance: a.tolerance.is_some(),
            allow_reconfiguration: a.effects.allow_reconfiguration,
            gain_auto: a.effects.gain_auto,
            ..Given::program(&a.program)
        }
    }

    /// The flags of `report`.
    pub(super) fn report(a: &ReportArgs) -> Self {
        Given {
            allow_reconfiguration: a.effects.allow_reconfiguration,
            gain_auto: a.effects.gain_auto,
            ..Given::program(&a.program)
        }
    }

    /// Refuses the flags that do not apply to an engine of `kind`.
    pub(super) fn refuse_for(self, kind: Kind) -> Result<()> {
        let refused = match kind {
            Kind::Robot if self.tools_or_offsets => {
                "--tool and --work-offset are G-code options; RAPID takes tooldata and wobjdata from the module"
            }
            Kind::Robot if self.units => {
                "--units is a G-code option; RAPID modules are in mm and degrees"
            }
            Kind::Robot if self.tolerance => {
                "--tolerance is a G-code option (the largest gap along a move between compensated blocks); a robot's targets are each solved to the solver's convergence, and the path between them is the controller's"
            }
            Kind::Robot if self.gain_auto => {
                "--gain-auto is a G-code option: a robot's gains are given with --gain"
            }
            Kind::Tool if self.allow_reconfiguration => {
                "--allow-reconfiguration is a robot option; a machine tool has no joint configuration"
            }
            Kind::Tool if self.rapid_window_lines => {
                "--rapid-window-lines is a RAPID option; G-code programs are always read a block at a time"
            }
            _ => return Ok(()),
        };
        Err(usage(refused))
    }
}

/// True when `program` names a RAPID module, by its extension or its
/// content ([`crate::program::language::is_rapid`]).
fn rapid_program(program: &ProgramArgs) -> bool {
    crate::program::language::is_rapid(&program.file)
}

/// Whether the program is G-code: by its extension, or by its first
/// block when the extension is neither language's.
fn gcode_program(program: &ProgramArgs) -> bool {
    use crate::program::language;
    let path = &program.file;
    !language::is_rapid(path)
        && (language::gcode_extension(path)
            || language::head(path).is_some_and(|h| language::gcode_text(&h)))
}

impl Engine {
    /// Loads the machine of `program` once and chooses the engine: RAPID
    /// for a module (by its extension or content) or a robot, G-code otherwise; then
    /// refuses the `given` flags that do not apply to it. A program in a
    /// language postproc does not read is refused first, with its language
    /// named ([`crate::program::language::unread`]).
    pub(super) fn choose(program: &ProgramArgs, given: Given) -> Result<Engine> {
        // A language postproc does not read is named before any reader.
        if let Some(named) = crate::program::language::unread(&program.file) {
            return Err(named.error(&program.file.display().to_string()).into());
        }
        let rapid = rapid_program(program);
        let machine = program.machine.as_deref().map(super::machines::open);
        let engine = match machine {
            None if rapid => Engine::Robot(None),
            None => Engine::Tool(None),
            Some(Ok((Machine::Robot(_), loaded))) if gcode_program(program) => {
                return Err(usage(format!(
                    "{}: is a G-code program, and {} is a robot, which runs RAPID modules: give a machine tool's file (postproc machines)",
                    program.file.display(),
                    loaded.file.shown
                )));
            }
            Some(Ok((Machine::Robot(r), loaded))) => Engine::Robot(Some(Ok((r, loaded)))),
            Some(Ok((Machine::Tool(_), loaded))) if rapid => {
                Engine::Robot(Some(Err(not_a_robot(&loaded))))
            }
            Some(Ok((Machine::Tool(m), loaded))) => Engine::Tool(Some((m, loaded))),
            Some(Err(e)) if rapid => Engine::Robot(Some(Err(e))),
            Some(Err(e)) => return Err(e),
        };
        given.refuse_for(engine.kind())?;
        Ok(engine)
    }

    /// The kind of engine.
    pub(super) fn kind(&self) -> Kind {
        match self {
            Engine::Tool(_) => Kind::Tool,
            Engine::Robot(_) => Kind::Robot,
        }
    }
}

/// The refusal of a machine tool for a RAPID module.
pub(super) fn not_a_robot(loaded: &Loaded) -> Error {
    usage(format!(
        "{}: is a machine tool; RAPID programs need a robot",
        loaded.file.shown
    ))
}

/// The machine a command needs: `command needs --machine` without one.
pub(super) fn needed<T>(machine: Option<T>, command: &str) -> Result<T> {
    machine.ok_or_else(|| usage(format!("{command} needs --machine")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_engine_refuses_the_other_engines_flags() {
        let cases = [
            (
                Given {
                    tools_or_offsets: true,
                    ..Given::default()
                },
                Kind::Robot,
                "--tool and --work-offset are G-code options",
            ),
            (
                Given {
                    units: true,
                    ..Given::default()
                },
                Kind::Robot,
                "--units is a G-code option",
            ),
            (
                Given {
                    tolerance: true,
                    ..Given::default()
                },
                Kind::Robot,
                "--tolerance is a G-code option",
            ),
            (
                Given {
                    allow_reconfiguration: true,
                    ..Given::default()
                },
                Kind::Tool,
                "--allow-reconfiguration is a robot option",
            ),
            (
                Given {
                    rapid_window_lines: true,
                    ..Given::default()
                },
                Kind::Tool,
                "--rapid-window-lines is a RAPID option",
            ),
            (
                Given {
                    gain_auto: true,
                    ..Given::default()
                },
                Kind::Robot,
                "--gain-auto is a G-code option",
            ),
        ];
        for (given, kind, want) in cases {
            let err = given.refuse_for(kind).expect_err(want);
            assert!(err.to_string().contains(want), "{err}");
            assert_eq!(err.exit_code(), 2);
            let other = match kind {
                Kind::Tool => Kind::Robot,
                Kind::Robot => Kind::Tool,
            };
            assert!(given.refuse_for(other).is_ok(), "{want}");
        }
        assert!(Given::default().refuse_for(Kind::Tool).is_ok());
        assert!(Given::default().refuse_for(Kind::Robot).is_ok());
    }
}
