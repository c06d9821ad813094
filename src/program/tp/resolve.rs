//! TP resolution: a parsed `.ls` program to the language-neutral robot
//! move stream ([`crate::program::robot_moves`]).
//!
//! The `/MN` motions are read in order, each once as written. A motion to
//! `P[n]` takes its position from `/POS` (group `GP1`): in Cartesian form
//! a [`RobotTarget`] in the user frame `UF` it was taught in, with the
//! tool frame `UT`, both from the robot file's `fanuc:` frames
//! ([`FanucFrames`]; frame 0 is the world frame and the faceplate), and
//! its `CONFIG` as the configuration rule; in joint form a [`JointMove`].
//! Left as written, each with its reason: a position register `PR[i]`
//! (its value is in the controller), a motion with `Offset`, `Tool_Offset`,
//! `VOFFSET` or `INC` (a displacement known at run time), a position not
//! in `/POS`, a frame the robot file does not give or the program sets
//! anywhere (`UFRAME[i]=…`, `UTOOL[i]=…`), a frame number in force that a
//! register gave (`UFRAME_NUM=R[i]`: after it, before the first
//! `UFRAME_NUM=n` and after a label `LBL[i]`), a position whose `UF`/`UT` differs from the
//! `UFRAME_NUM`/`UTOOL_NUM` the program selected before it (the controller
//! stops with a frame mismatch), extended axes (`E1`…).
//!
//! Speed: `mm/sec`, `cm/min` and `inch/min` of a `L` or `C` motion; a
//! `J` motion's `%` is not a TCP speed. `FINE` and `CNTn` are no distance:
//! no zone is given.

use std::collections::HashMap;
use std::sync::Arc;

use nalgebra::Isometry3;

use super::config::{Config, joints_to_model};
use super::syntax::{Group, Instruction, Motion, PosRef, Position, Program};
use crate::machine::robot::Robot;
use crate::machine::robot::fanuc::{FanucFrames, xyzwpr};
use crate::program::robot_moves::{
    Configuration, JointMove, LeftAsWritten, PathKind, Place, RobotStep, RobotTarget, ToolUse,
};

/// Known offline, or why not.
type Known<T> = std::result::Result<T, String>;

/// The name of a motion, as written in reports.
pub fn motion_name(m: Motion) -> &'static str {
    match m {
        Motion::J => "J",
        Motion::L => "L",
        Motion::C => "C",
    }
}

/// A frame selection in force: a number, or one read from a register at
/// a line (known at run time only).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Selected {
    /// `UFRAME_NUM=n`.
    Number(u32),
    /// `UFRAME_NUM=R[i]` at this line.
    Register(usize),
}

/// What the instructions before a motion set.
#[derive(Default)]
struct State {
    /// `UFRAME_NUM` in force (`None`: the frame the program starts in).
    uframe: Option<Selected>,
    /// `UTOOL_NUM` in force.
    utool: Option<Selected>,
    /// Frames the program sets anywhere (`UFRAME[i]=…`): (user, index) →
    /// the first line. A frame's value outlives the program, and a jump
    /// may come back to a motion before the line, so every motion in the
    /// frame is concerned.
    set: HashMap<(bool, u32), usize>,
    /// The first register selection of the user frame and of the tool
    /// frame anywhere in the program: in force at its start (the program
    /// may have run before) and after every label (a jump may come from
    /// after it).
    register: [Option<usize>; 2],
}

/// The pose of a Cartesian group, `None` without all of `X … R`.
pub fn pose_of(g: &Group) -> Option<Isometry3<f64>> {
    let v = |k: &str| g.value(k).map(|n| n.value);
    Some(xyzwpr(v("X")?, v("Y")?, v("Z")?, v("W")?, v("P")?, v("R")?))
}

/// The joint angles `J1 … J6` of a joint group, degrees.
fn joints_of(g: &Group) -> Option<[f64; 6]> {
    let mut j = [0.0; 6];
    for (i, v) in j.iter_mut().enumerate() {
        *v = g.value(&format!("J{}", i + 1))?.value;
    }
    Some(j)
}

/// A frame number `UF : n` of a group.
fn frame_no(n: Option<&super::syntax::Number>) -> Option<u32> {
    let v = n?.value;
    (v >= 0.0 && v.fract() == 0.0 && v < f64::from(u32::MAX)).then_some(v as u32)
}

/// The 1-based byte column of each line's first character after its
/// `n:` (the motion letter), by line.
fn columns(text: &str) -> Vec<usize> {
    text.split_inclusive('\n')
        .map(|l| {
            let colon = l.find(':').map_or(0, |c| c + 1);
            let rest = &l[colon..];
            colon + (rest.len() - rest.trim_start().len()) + 1
        })
        .collect()
}

/// The TCP speed of a motion's rest (`500mm/sec`), mm/s.
fn speed_of(rest: &str) -> Option<f64> {
    let word = rest.split_whitespace().next()?;
    let lower = word.to_ascii_lowercase();
    let (num, scale) = [
        ("mm/sec", 1.0),
        ("cm/min", 10.0 / 60.0),
        ("inch/min", 25.4 / 60.0),
    ]
    .iter()
    .find_map(|(u, s)| lower.strip_suffix(u).map(|n| (n.to_string(), *s)))?;
    num.parse::<f64>().ok().map(|v| v * scale)
}

/// Why a motion's options make its target known at run time only.
fn run_time_option(rest: &str) -> Option<String> {
    rest.split([' ', '\t', ','])
        .map(str::to_ascii_uppercase)
        .find(|w| matches!(w.as_str(), "OFFSET" | "TOOL_OFFSET" | "VOFFSET" | "INC"))
        .map(|w| format!("`{w}` displaces the position at run time"))
}

/// Resolves `program` (`text` its source) with the robot file's frames.
pub fn resolve(program: &Program, text: &str, frames: &FanucFrames) -> Vec<RobotStep> {
    let cols = columns(text);
    let positions: HashMap<u32, &Position> =
        program.positions.iter().map(|p| (p.index, p)).collect();
    let mut st = State::default();
    for l in &program.mn {
        match &l.instruction {
            Instruction::SetFrame { user, index } => {
                st.set.entry((*user, *index)).or_insert(l.line);
            }
            Instruction::FrameNumAtRunTime { user } => {
                st.register[usize::from(!*user)].get_or_insert(l.line);
            }
            _ => {}
        }
    }
    let at_register = |k: usize| st.register[k].map(Selected::Register);
    st.uframe = at_register(0);
    st.utool = at_register(1);
    let mut steps = Vec::new();
    for l in &program.mn {
        match &l.instruction {
            Instruction::UframeNum(n) => st.uframe = Some(Selected::Number(*n)),
            Instruction::UtoolNum(n) => st.utool = Some(Selected::Number(*n)),
            Instruction::FrameNumAtRunTime { user: true } => {
                st.uframe = Some(Selected::Register(l.line));
            }
            Instruction::FrameNumAtRunTime { user: false } => {
                st.utool = Some(Selected::Register(l.line));
            }
            Instruction::Label => {
                st.uframe = at_register(0).or(st.uframe);
                st.utool = at_register(1).or(st.utool);
            }
            Instruction::SetFrame { .. } | Instruction::Other => {}
            Instruction::Move {
                motion,
                via,
                target,
                rest,
            } => {
                let m = Move {
                    line: l.line,
                    column: cols.get(l.line.wrapping_sub(1)).copied().unwrap_or(1),
                    motion: *motion,
                    rest: text.get(rest.clone()).unwrap_or(""),
                };
                steps.push(step(&st, frames, &positions, &m, via.as_ref(), target));
            }
        }
    }
    steps
}

/// A motion instruction being resolved.
struct Move<'a> {
    line: usize,
    column: usize,
    motion: Motion,
    rest: &'a str,
}

/// A position, its group `GP1`, its user frame and its tool (each known
/// offline or not).
type Found<'a> = (
    &'a Position,
    &'a Group,
    Known<Isometry3<f64>>,
    Known<ToolUse>,
);

/// A position's group `GP1`, its user frame and its tool, or why not.
fn located<'a>(
    st: &State,
    frames: &FanucFrames,
    positions: &HashMap<u32, &'a Position>,
    r: &PosRef,
) -> Known<Found<'a>> {
    if r.register {
        return Err(format!(
            "PR[{}] is a position register: its value is in the controller, set at run time",
            r.index
        ));
    }
    let p: &'a Position = positions
        .get(&r.index)
        .copied()
        .ok_or_else(|| format!("P[{}] is not in /POS", r.index))?;
    let g = p
        .groups
        .iter()
        .find(|g| g.name == "GP1")
        .ok_or_else(|| format!("P[{}] has no group GP1", r.index))?;
    if let Some((e, _)) = g.values.iter().find(|(n, _)| n.starts_with('E')) {
        return Err(format!(
            "P[{}] has the extended axis {e}: the robot's base moves with it",
            r.index
        ));
    }
    let joint = g.is_joint();
    let frame = |user: bool| -> Known<u32> {
        let (key, selected) = if user {
            ("UF", st.uframe)
        } else {
            ("UT", st.utool)
        };
        let n = frame_no(if user { g.uf.as_ref() } else { g.ut.as_ref() })
            .ok_or_else(|| format!("P[{}] has no {key} number", r.index))?;
        let what = if user { "UFRAME_NUM" } else { "UTOOL_NUM" };
        match selected {
            // A joint position has no frame to mismatch; its UT is its tool.
            Some(Selected::Number(s)) if s != n && !joint => {
                return Err(format!(
                    "P[{}] is taught in {key} {n} but {what}={s} is selected: the controller stops with a frame mismatch",
                    r.index
                ));
            }
            // A frame number from a register: the program runs its
            // positions in other frames (the controller's frame check
            // off), so the frame is known at run time only.
            Some(Selected::Register(line)) if !joint || !user => {
                return Err(format!(
                    "{what} is set from a register at line {line}: the {} frame of the motion is known at run time only",
                    if user { "user" } else { "tool" }
                ));
            }
            _ => {}
        }
        if let Some(line) = st.set.get(&(user, n)) {
            let name = if user { "UFRAME" } else { "UTOOL" };
            return Err(format!(
                "{name}[{n}] is set by the program at line {line}, at run time"
            ));
        }
        Ok(n)
    };
    let work = frame(true).and_then(|n| {
        frames.user(n).ok_or_else(|| {
            format!("user frame UF {n} is in the controller: give it in the robot file (fanuc: user_frames)")
        })
    });
    let tool = frame(false).and_then(|n| {
        frames
            .tool(n)
            .map(|f| ToolUse {
                key: format!("UT {n}"),
                flange_to_tcp: f,
                load: None,
            })
            .ok_or_else(|| {
                format!("tool frame UT {n} is in the controller: give it in the robot file (fanuc: tool_frames)")
            })
    });
    Ok((p, g, work, tool))
}

/// The step of one motion.
fn step(
    st: &State,
    frames: &FanucFrames,
    positions: &HashMap<u32, &Position>,
    m: &Move,
    via: Option<&PosRef>,
    target: &PosRef,
) -> RobotStep {
    let name = motion_name(m.motion);
    let left =
        |reason: &str| RobotStep::Left(LeftAsWritten::warning(m.line, m.column, name, reason));
    let (p, g, work, tool) = match located(st, frames, positions, target) {
        Ok(v) => v,
        Err(reason) => return left(&reason),
    };
    if let Some(reason) = run_time_option(m.rest) {
        return left(&reason);
    }
    if g.is_joint() {
        let Some(j) = joints_of(g) else {
            return left(&format!("P[{}] has not all of J1 … J6", p.index));
        };
        return RobotStep::Joints(JointMove {
            line: m.line,
            column: m.column,
            instruction: name,
            q: joints_to_model(&j),
            tool: tool.ok(),
        });
    }
    let Some(pose) = pose_of(g) else {
        return left(&format!("P[{}] has not all of X, Y, Z, W, P, R", p.index));
    };
    let (work, tool) = match (work, tool) {
        (Ok(w), Ok(t)) => (w, t),
        (Err(reason), _) | (_, Err(reason)) => return left(&reason),
    };
    let configuration = match &g.config {
        Some((text, _)) => match Config::parse(text) {
            Ok(c) => {
                let admits = move |r: &Robot, q: &[f64; 6]| c.matches(r, q);
                Configuration::Admits(Arc::new(admits), format!("CONFIG '{text}'"))
            }
            Err(e) => return left(&e.to_string()),
        },
        None => Configuration::Previous,
    };
    let via = match via {
        Some(v) => match located(st, frames, positions, v) {
            Ok((vp, vg, _, _)) if frame_no(vg.uf.as_ref()) != frame_no(g.uf.as_ref()) => {
                return left(&format!(
                    "its via point P[{}] is in another user frame",
                    vp.index
                ));
            }
            Ok((vp, vg, _, _)) => match pose_of(vg) {
                Some(pose) => Some((
                    pose,
                    Place {
                        source: 0,
                        span: vp.span.clone(),
                    },
                )),
                None => return left(&format!("its via point P[{}] is not Cartesian", vp.index)),
            },
            Err(reason) => return left(&format!("via point: {reason}")),
        },
        None => None,
    };
    let path = match m.motion {
        Motion::J => PathKind::Joint,
        Motion::L => PathKind::Linear,
        Motion::C => PathKind::Circular,
    };
    RobotStep::Target(Box::new(RobotTarget {
        line: m.line,
        column: m.column,
        instruction: name,
        path,
        pose,
        work,
        tool,
        via,
        configuration,
        speed_mm_s: (m.motion != Motion::J).then(|| speed_of(m.rest)).flatten(),
        zone_mm: None,
        place: Place {
            source: 0,
            span: p.span.clone(),
        },
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn speeds_are_read_in_mm_per_second() {
        assert_eq!(speed_of(" 500mm/sec FINE"), Some(500.0));
        assert_eq!(speed_of(" 600cm/min CNT50"), Some(100.0));
        assert_eq!(speed_of(" 60inch/min FINE"), Some(25.4));
        assert_eq!(speed_of(" 100% FINE"), None);
        assert_eq!(speed_of(""), None);
    }

    #[test]
    fn run_time_options_are_named() {
        assert!(run_time_option(" 800mm/sec CNT30 Offset,PR[7]").is_some());
        assert!(run_time_option(" 800mm/sec FINE Tool_Offset,PR[2]").is_some());
        assert!(run_time_option(" 100mm/sec FINE INC").is_some());
        assert!(run_time_option(" 100mm/sec FINE ACC80").is_none());
    }
}
