//! The language-neutral robot move stream: what a robot language's front
//! end hands to the robot pipeline.
//!
//! A front end (ABB RAPID today; KUKA KRL and FANUC TP next) reads its
//! language, resolves every motion instruction to what the controller will
//! do, and reports each one either as a resolved move or as a move it
//! leaves as written, with the reason. After it the pipeline is the same
//! for every language: the time line, the prediction, the compensation,
//! the records and the summary.
//!
//! What is left as written goes out on the one diagnostics channel of
//! every pipeline, [`crate::program::interp::Warning`], with a
//! [`LeftAsWritten`] that names the instruction, its column and the
//! reason: the summary counts them, `--strict` refuses the program at the
//! first one.
//!
//! The stream itself is [`RobotStep`]: a [`RobotTarget`] (a Cartesian
//! target as a pose in its work object's frame, with the work object in
//! the world frame, the tool, the path kind, speed, zone and the
//! configuration rule of its language as typed data, and the span of the
//! numbers the language's writer replaces), a [`JointMove`] (a joint
//! target, reported and left as written), or a move left as written with
//! its warning. KUKA KRL produces it ([`crate::program::krl::resolve`]);
//! [`crate::pipeline::robot`] consumes it.

use std::ops::Range;
use std::sync::Arc;

use nalgebra::Isometry3;

use crate::machine::robot::{ConfData, PointMass, Robot};

/// A motion instruction a front end leaves as written (its target is not
/// compensated), and why: the part of a [`crate::program::interp::Warning`]
/// that a `--strict` run refuses.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LeftAsWritten {
    /// 1-based byte column of the instruction's name.
    pub column: usize,
    /// The instruction's name as written (`MoveL`, `SpotL`).
    pub instruction: String,
    /// Why it is not compensated.
    pub reason: String,
}

impl LeftAsWritten {
    /// The warning of a move left as written at `line`, on the one
    /// diagnostics channel: `MoveL left as written (reason)`.
    pub fn warning(
        line: usize,
        column: usize,
        instruction: &str,
        reason: &str,
    ) -> crate::program::interp::Warning {
        crate::program::interp::Warning {
            line,
            message: format!("{instruction} left as written ({reason})"),
            count: 1,
            left: Some(LeftAsWritten {
                column,
                instruction: instruction.to_string(),
                reason: reason.to_string(),
            }),
        }
    }
}

/// How the controller moves to a target.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PathKind {
    /// Joint interpolation (`MoveJ`, KUKA `PTP`, FANUC `J`).
    Joint,
    /// Straight line (`MoveL`, `LIN`, `L`).
    Linear,
    /// Circle through an auxiliary point (`MoveC`, `CIRC`, `C`).
    Circular,
}

/// The tool of a move: the TCP frame on the flange and its load.
#[derive(Debug, Clone, PartialEq)]
pub struct ToolUse {
    /// What names the tool in the program (`TOOL_DATA[2]`, `tool1`): moves
    /// with the same key share a robot view.
    pub key: String,
    /// The TCP in the flange frame, mm.
    pub flange_to_tcp: Isometry3<f64>,
    /// The tool's load, when the program says it.
    pub load: Option<PointMass>,
}

/// The test of a maker's configuration rule on a joint solution.
pub type Admits = Arc<dyn Fn(&Robot, &[f64; 6]) -> bool + Send + Sync>;

/// A language's rule that tells which joint solution of a pose is the
/// programmed one.
#[derive(Clone)]
pub enum Configuration {
    /// The model's configuration data (ABB confdata: cfx and the quadrants
    /// of joints 1, 4 and 6).
    Conf(ConfData),
    /// The solution nearest the joints of the target before (KUKA `LIN` and
    /// `CIRC` ignore Status and Turn; a `PTP` without them).
    Previous,
    /// The solution whose joints the rule admits (KUKA Status and Turn,
    /// FANUC `CONFIG`), with the rule as written for messages.
    Admits(Admits, String),
}

impl std::fmt::Debug for Configuration {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Configuration::Conf(c) => write!(f, "Conf({c})"),
            Configuration::Previous => f.write_str("Previous"),
            Configuration::Admits(_, text) => write!(f, "Admits({text})"),
        }
    }
}

/// A Cartesian target of a motion instruction, resolved before run time.
#[derive(Debug, Clone)]
pub struct RobotTarget {
    /// 1-based line of the instruction.
    pub line: usize,
    /// 1-based byte column of the instruction's name.
    pub column: usize,
    /// The instruction's name as written in reports (`LIN`, `MoveL`).
    pub instruction: &'static str,
    /// How the controller moves there.
    pub path: PathKind,
    /// The target in its work object's frame, mm.
    pub pose: Isometry3<f64>,
    /// The work object (KUKA `$BASE`, FANUC user frame) in the world frame.
    pub work: Isometry3<f64>,
    /// The tool.
    pub tool: ToolUse,
    /// The auxiliary (circle) point of a circular move, in the work
    /// object's frame, with where its numbers are.
    pub via: Option<(Isometry3<f64>, Place)>,
    /// Which joint solution is programmed.
    pub configuration: Configuration,
    /// TCP speed, mm/s, when known offline.
    pub speed_mm_s: Option<f64>,
    /// Approximation (zone) distance, mm; `None`: the target is reached
    /// exactly.
    pub zone_mm: Option<f64>,
    /// Where the target's numbers are (what the writer replaces).
    pub place: Place,
}

/// Where a target's numbers are written: the source (0 the program, then
/// the data files the front end read) and the bytes of its value.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Place {
    /// Index of the source text.
    pub source: usize,
    /// Bytes of the value (a KRL aggregate, a FANUC position).
    pub span: Range<usize>,
}

/// A joint target: the controller goes to its joints; it is reported (its
/// predicted deviation) and left as written.
#[derive(Debug, Clone)]
pub struct JointMove {
    /// 1-based line.
    pub line: usize,
    /// 1-based byte column of the instruction's name.
    pub column: usize,
    /// The instruction's name (`PTP`, `MoveAbsJ`).
    pub instruction: &'static str,
    /// The model's joints, rad.
    pub q: [f64; 6],
    /// The tool, when the program set one before.
    pub tool: Option<ToolUse>,
}

/// One motion instruction of the stream, in program order.
#[derive(Debug, Clone)]
pub enum RobotStep {
    /// A Cartesian target to compensate.
    Target(Box<RobotTarget>),
    /// A joint target, reported and left as written.
    Joints(JointMove),
    /// A move left as written: its warning (with [`LeftAsWritten`]).
    Left(crate::program::interp::Warning),
}

/// Why a joint target is left as written: its joints are what the
/// controller goes to, not a pose it solves.
pub const JOINT_TARGET: &str = "joint target: reported, not compensated";
