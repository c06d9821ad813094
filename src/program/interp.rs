//! Modal interpretation of G-code blocks into moves in machine coordinates.
//!
//! The interpreter walks parsed [`Block`]s in program order, keeps the modal
//! state of a Fanuc-style milling controller (motion, plane, units, distance
//! modes, work offset, tool length, canned cycle) and turns each block into a
//! [`Plan`]: the moves it commands, in machine coordinates of the nominal tool
//! tip, plus what the emitter needs to rewrite the block's coordinate words.
//! Constructs that cannot be compensated offline are refused with a located
//! message.

use std::collections::BTreeMap;

use std::f64::consts::{FRAC_PI_2, PI};

use nalgebra::Vector3;

use crate::error::Located;
pub use crate::machine::tool::{CornerWords, IntegerWords, Units};
use crate::machine::{AxisVec, DirVec, axis_slot};
use crate::program::gcode::{Block, Word};
use crate::program::gcode::{CHAMFER, CORNER_RADIUS};

/// Millimetres per inch.
pub const MM_PER_INCH: f64 = 25.4;

/// Radius mismatch between an arc's start and end that is refused, mm
/// (absolute part; a relative part of 0.1 % of the radius is added).
pub const ARC_RADIUS_TOL_MM: f64 = 0.01;

/// Arc parameter just inside the ends, where tangent directions are read.
pub const END_INSIDE: f64 = 1.0 - 1e-6;

/// Largest accepted spindle speed, 1/min.
const MAX_SPINDLE_RPM: f64 = crate::process::limits::SPINDLE_MAX_RPM;

/// Longest block text quoted in a message, characters.
const LINE_QUOTE_MAX: usize = 60;

/// Number of modal groups checked by [`modal_group`].
const MODAL_GROUPS: usize = 9;

/// The modal group of a G code (code × 10) whose members exclude each other
/// within one block, other than the motion group (checked on its own): plane,
/// distance mode, arc distance mode, units, work offset, cutter compensation,
/// tool length offset, canned-cycle return level, feed mode.
fn modal_group(code: i64) -> Option<usize> {
    Some(match code {
        170 | 180 | 190 => 0,
        900 | 910 => 1,
        901 | 911 => 2,
        200 | 210 => 3,
        540 | 550 | 560 | 570 | 580 | 590 | 541 | 1540 => 4,
        1100..=1290 if code % 10 == 0 => 4,
        400 | 410 | 420 => 5,
        430 | 434 | 435 | 490 => 6,
        980 | 990 => 7,
        930 | 940 | 950 => 8,
        _ => return None,
    })
}

/// Below this an axis is considered not to move, mm or deg.
pub const MOTION_EPS: f64 = 1e-9;

/// Travel below which an axis keeps its direction of motion, mm or deg: a
/// reversal of the direction-dependent errors (backlash, the reverse column
/// of the error tables) needs travel to take up the lash, and a move this
/// short leaves the axis against the side it last moved on. A compensated
/// program moves axes that stand still in the programmed block by fractions
/// of a micron (the correction changes along the path); with this deadband
/// those moves keep the directions the compensation was solved with. See
/// docs/compensation.md, "Directions of motion".
pub const DIRECTION_DEADBAND: f64 = 1e-3;

/// Most stretches between reversals looked at, from the end of an arc back.
const ARC_STRETCHES: usize = 8;

/// The direction of motion at the end of an arc of the in-plane axis whose
/// position is `r·cos(θ − phase)` about the centre (`phase` 0: the plane's
/// first axis, π/2: the second), the arc starting at angle `theta0`: the
/// direction of the last stretch between its reversals (quadrant points)
/// along which it travels more than [`DIRECTION_DEADBAND`]. An arc that
/// ends just past a quadrant point leaves the axis moving the way it went
/// before it. `None` when no stretch travels that far.
fn arc_axis_direction(g: &ArcGeom, theta0: f64, phase: f64) -> Option<i8> {
    let pos = |t: f64| g.radius * (t - phase).cos();
    let end = theta0 + g.sweep;
    let back = -g.sweep.signum();
    // The reversal nearest the end, on the arc's side of it: (t − phase) a
    // multiple of π.
    let k = ((end - phase) / PI).floor();
    let mut turn = phase + PI * if back < 0.0 { k } else { k + 1.0 };
    let mut hi = end;
    for _ in 0..ARC_STRETCHES {
        let inside = (turn - theta0) * g.sweep.signum() > 0.0;
        let lo = if inside { turn } else { theta0 };
        let d = pos(hi) - pos(lo);
        if d.abs() > DIRECTION_DEADBAND {
            return Some(if d > 0.0 { 1 } else { -1 });
        }
        if !inside {
            return None;
        }
        hi = turn;
        turn += back * PI;
    }
    None
}

/// The direction of motion of each axis over the move `start → end` (for an
/// arc in its plane: along its tangent just before the end), given the
/// directions `prev` before it: an axis that travels less than
/// [`DIRECTION_DEADBAND`] keeps its direction. A programmed block and the
/// pieces of its compensated program are read with this one rule, so that
/// small moves of the pieces keep the block's directions.
pub fn directions(prev: &DirVec, start: &AxisVec, end: &AxisVec, arc: Option<&ArcGeom>) -> DirVec {
    let mut dirs = *prev;
    for i in 0..6 {
        let d = end[i] - start[i];
        if d.abs() > DIRECTION_DEADBAND {
            dirs[i] = if d > 0.0 { 1 } else { -1 };
        }
    }
    if let Some(g) = arc {
        let (a, b, _) = g.plane.axes();
        let theta0 = (start[b] - g.center[b]).atan2(start[a] - g.center[a]);
        dirs[a] = arc_axis_direction(g, theta0, 0.0).unwrap_or(prev[a]);
        dirs[b] = arc_axis_direction(g, theta0, FRAC_PI_2).unwrap_or(prev[b]);
    }
    dirs
}

/// Kind of motion of a move.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Motion {
    /// G0 rapid positioning.
    Rapid,
    /// G1 linear feed.
    Linear,
    /// G2 clockwise arc (seen from the positive end of the plane normal).
    ArcCw,
    /// G3 counter-clockwise arc.
    ArcCcw,
}

/// The active arc plane.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Plane {
    /// G17: arcs in X–Y, helix along Z.
    XY,
    /// G18: arcs in Z–X, helix along Y.
    ZX,
    /// G19: arcs in Y–Z, helix along X.
    YZ,
}

impl Plane {
    /// Slots of the two in-plane axes (first, second) and of the normal axis,
    /// ordered so that (first × second) = normal.
    pub fn axes(self) -> (usize, usize, usize) {
        match self {
            Plane::XY => (0, 1, 2),
            Plane::ZX => (2, 0, 1),
            Plane::YZ => (1, 2, 0),
        }
    }

    /// Letters of the centre-offset words of the two in-plane axes.
    pub fn center_letters(self) -> (u8, u8) {
        match self {
            Plane::XY => (b'I', b'J'),
            Plane::ZX => (b'K', b'I'),
            Plane::YZ => (b'J', b'K'),
        }
    }
}

/// Arc geometry of a G2/G3 move, machine coordinates.
///
/// An arc whose end lies off the circle of its start (within the limit of
/// [`ARC_RADIUS_TOL_MM`]) is the spiral Fanuc and LinuxCNC move: the
/// radius about the centre changes linearly with the swept angle, from the
/// start's radius `r0` to the end's `r1`, so the point at parameter `s` is
/// the centre plus `(r0 + (r1 − r0)·s)` in the direction `θ0 + sweep·s`
/// ([`ArcGeom::point`]). Start and end on one circle make the circle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArcGeom {
    /// The plane of the arc.
    pub plane: Plane,
    /// Centre (the normal-axis component equals the start's).
    pub center: Vector3<f64>,
    /// Signed swept angle, rad (positive counter-clockwise about the normal).
    pub sweep: f64,
    /// Radius, mm: the mean of the start's and the end's (equal on a
    /// circle; a spiral's radius at a point is [`ArcGeom::radius_at`]).
    pub radius: f64,
}

impl ArcGeom {
    /// The in-plane distance of `p` from the centre, mm.
    fn radius_of(&self, p: &Vector3<f64>) -> f64 {
        let (a, b, _) = self.plane.axes();
        (p[a] - self.center[a]).hypot(p[b] - self.center[b])
    }

    /// Radius of the arc (spiral) from `start` to `end` at parameter `s`:
    /// linear in the swept angle from the start's radius to the end's.
    pub fn radius_at(&self, start: &Vector3<f64>, end: &Vector3<f64>, s: f64) -> f64 {
        let r0 = self.radius_of(start);
        r0 + (self.radius_of(end) - r0) * s
    }

    /// Point on the arc (helix; spiral when the end's radius differs from
    /// the start's) at parameter `s` in [0, 1] from `start` to `end`.
    pub fn point(&self, start: &Vector3<f64>, end: &Vector3<f64>, s: f64) -> Vector3<f64> {
        let (a, b, n) = self.plane.axes();
        let a0 = start[a] - self.center[a];
        let b0 = start[b] - self.center[b];
        let ang = b0.atan2(a0) + self.sweep * s;
        let r = self.radius_at(start, end, s);
        let mut p = Vector3::zeros();
        p[a] = self.center[a] + r * ang.cos();
        p[b] = self.center[b] + r * ang.sin();
        p[n] = start[n] + (end[n] - start[n]) * s;
        if s >= 1.0 {
            p[a] = end[a];
            p[b] = end[b];
        }
        p
    }

    /// Unit tangent direction at parameter `s` (direction of travel).
    pub fn tangent(&self, start: &Vector3<f64>, end: &Vector3<f64>, s: f64) -> Vector3<f64> {
        let (a, b, n) = self.plane.axes();
        let ang = (start[b] - self.center[b]).atan2(start[a] - self.center[a]) + self.sweep * s;
        let r = self.radius_at(start, end, s);
        // d/ds of the radius along a spiral (0 on a circle).
        let dr = self.radius_of(end) - self.radius_of(start);
        let mut t = Vector3::zeros();
        t[a] = dr * ang.cos() - ang.sin() * r * self.sweep;
        t[b] = dr * ang.sin() + ang.cos() * r * self.sweep;
        t[n] = end[n] - start[n];
        let norm = t.norm();
        if norm > 0.0 { t / norm } else { t }
    }

    /// Path length of the arc (helix), mm. In its plane a spiral is taken
    /// as `√((r̄·sweep)² + Δr²)` (r̄ the mean radius, Δr its change), a
    /// lower bound of its length within `Δr²/(2·r_min·|sweep|)`; a circle
    /// exactly.
    pub fn length(&self, start: &Vector3<f64>, end: &Vector3<f64>) -> f64 {
        let (_, _, n) = self.plane.axes();
        let dr = self.radius_of(end) - self.radius_of(start);
        (self.radius * self.sweep)
            .hypot(dr)
            .hypot(end[n] - start[n])
    }
}

/// One move in machine coordinates of the nominal tool tip.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Move {
    /// Kind of motion.
    pub motion: Motion,
    /// Start position (mm, deg).
    pub start: AxisVec,
    /// End position (mm, deg).
    pub end: AxisVec,
    /// Arc geometry for G2/G3.
    pub arc: Option<ArcGeom>,
    /// Direction of motion of each axis during the move (the last direction
    /// for an axis that does not move); for arcs, at the end point.
    pub dirs: DirVec,
    /// Directions before the move.
    pub prev_dirs: DirVec,
    /// Feed rate, mm/min (rapids: 0, the machine's rapid rate applies).
    pub feed_mm_min: f64,
    /// Spindle speed, 1/min; 0 while the spindle is stopped (before M3/M4,
    /// after M5, M2 or M30).
    pub spindle_rpm: f64,
    /// Active tool number.
    pub tool: u32,
    /// Active tool length (G43), mm; 0 without tool length compensation.
    pub tool_len_mm: f64,
}

impl Move {
    /// Linear-axis start as a vector.
    pub fn start3(&self) -> Vector3<f64> {
        Vector3::new(self.start[0], self.start[1], self.start[2])
    }

    /// Linear-axis end as a vector.
    pub fn end3(&self) -> Vector3<f64> {
        Vector3::new(self.end[0], self.end[1], self.end[2])
    }

    /// Path length of the linear axes, mm.
    pub fn length_mm(&self) -> f64 {
        match &self.arc {
            Some(arc) => arc.length(&self.start3(), &self.end3()),
            None => (self.end3() - self.start3()).norm(),
        }
    }

    /// The length the feed is taken along: the path length of the linear
    /// axes, or for a move of rotary axes alone the largest angle, deg.
    pub fn timed_length(&self) -> f64 {
        let len = self.length_mm();
        if len > 1e-9 {
            len
        } else {
            (3..6)
                .map(|s| (self.end[s] - self.start[s]).abs())
                .fold(0.0, f64::max)
        }
    }
}

/// What a block does, for prediction and for rewriting.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum PlanKind {
    /// Nothing to compensate: written back unchanged.
    #[default]
    Pass,
    /// A programmed move whose coordinate words are rewritten.
    Motion,
    /// A move to a machine-defined place (G28, G53): predicted, not rewritten.
    Fixed,
    /// A canned-cycle hole: the X/Y/Z words are the hole bottom, R the R level.
    Cycle {
        /// Machine Z of the R level.
        r_level: f64,
        /// Machine Z of the hole bottom.
        bottom: f64,
        /// Machine Z the tool returns to after the hole.
        retract: f64,
    },
}

/// The interpretation of one block.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Plan {
    /// What the block does.
    pub kind: PlanKind,
    /// The programmed move (for cycles: the feed to the bottom).
    pub mv: Option<Move>,
    /// Machine = program × scale + offset, per axis (rotary: offset 0, scale 1).
    pub offset: AxisVec,
    /// 1 for mm programs, 25.4 for inch.
    pub scale: f64,
    /// G90 absolute (true) or G91 incremental.
    pub absolute: bool,
    /// G90.1 absolute arc centres (true) or G91.1 incremental.
    pub arc_absolute: bool,
    /// Dwell time of the block, s.
    pub dwell_s: f64,
    /// Bit `i` set when the block programs axis slot `i` (X Y Z A B C).
    pub programmed: u8,
    /// Milling engagement set by `(POSTPROC MILLING DEPTH=… WIDTH=…)`
    /// directives so far: axial depth and radial width, mm.
    pub milling_mm: [Option<f64>; 2],
    /// Cutter radius compensation (G41/G42) may be active during this
    /// block's move: it was before the block or is after it (so the
    /// block that starts it and the `G40` block that ends it count), with
    /// the block-delete switch in either position (a `/G41` line may
    /// start it, a `/G40` line may not end it).
    pub cutter_comp: bool,
    /// Times the block's move runs again after the first (a repeat count
    /// `L`/`K` whose repeats run the same path: a closed move, or a hole
    /// drilled again).
    pub extra_repeats: u32,
    /// A feed move under G93: its F word is the inverse of its duration
    /// (1/min), so each piece of a split move needs its own F.
    pub inverse_time: bool,
    /// A move under tool centre point control (G43.4/G43.5): its axis
    /// positions come from programmed tool tips, and its words are written
    /// back as the tool tips of the compensated axis positions.
    pub tcpm: bool,
    /// A canned-cycle hole: what the cycle does along the hole, for
    /// writing it as moves (default otherwise).
    pub cycle: CycleSpec,
    /// The corner the control makes between this G1 move and the next
    /// (`,C`/`,R`, where the machine file's `corner_words` reads them).
    pub corner: Option<Corner>,
    /// The G1 move after a corner: the control's corner joins it to the
    /// line before, so no takeup point may start it.
    pub after_corner: bool,
}

impl Plan {
    /// Whether the compensation may start this block's move with a takeup
    /// point: not while cutter radius compensation may be active (a short
    /// move against the direction of travel would upset the controller's
    /// offset path) nor on the move after a corner (the corner would be
    /// made with the takeup move).
    pub fn takeups_allowed(&self) -> bool {
        !self.cutter_comp && !self.after_corner
    }
}

/// A corner the control inserts between a G1 move and the next G1 move
/// (Fanuc and Haas chamfering and corner rounding): it moves along the
/// first line to the first tangent point, along the chamfer line or the
/// round arc to the second, and on along the next line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Corner {
    /// A chamfer (`,C`) or a round (`,R`).
    pub kind: CornerKind,
    /// `,C`: the distance of each tangent point from the corner along its
    /// line; `,R`: the radius of the arc tangent to both lines; mm.
    pub size_mm: f64,
}

/// What a corner word asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CornerKind {
    /// `,C`: a straight line between the two tangent points.
    Chamfer,
    /// `,R`: an arc tangent to both lines.
    Round,
}

impl Corner {
    /// Distance of the tangent points from the corner along each line, mm,
    /// for lines of unit directions `u1` (into the corner) and `u2` (out of
    /// it); `None` when the lines run on in one straight line or turn
    /// back on themselves (no corner to chamfer or round).
    pub fn tangent_distance(&self, u1: &Vector3<f64>, u2: &Vector3<f64>) -> Option<f64> {
        let cos = u1.dot(u2).clamp(-1.0, 1.0);
        let turn = cos.acos();
        if !(CORNER_MIN_TURN_RAD..=std::f64::consts::PI - CORNER_MIN_TURN_RAD).contains(&turn) {
            return None;
        }
        Some(match self.kind {
            CornerKind::Chamfer => self.size_mm,
            CornerKind::Round => self.size_mm * (turn / 2.0).tan(),
        })
    }
}

/// The smallest turn between two lines (and the smallest turn short of a
/// reversal) at which a corner word makes a corner, rad (0.01°).
pub const CORNER_MIN_TURN_RAD: f64 = 1.745_329_251_994_33e-4;

/// How far a corner's line may move along the plane normal (or a rotary
/// axis) and still lie in the plane, mm (deg); and the shortest line.
const CORNER_PLANE_MM: f64 = 1e-9;

/// How far a corner's line may move along the plane normal, mm: the
/// corrections a compensation writes into the lines of a corner, not a
/// ramp (the corner is then the one of the two lines in space, the
/// chamfer or arc joining them in their own plane).
pub const CORNER_NORMAL_MM: f64 = 0.05;

/// Distance of the linear axes of two positions, mm.
fn dist3(a: &AxisVec, b: &AxisVec) -> f64 {
    Vector3::new(b[0] - a[0], b[1] - a[1], b[2] - a[2]).norm()
}

/// A corner word's block, waiting for the move after it.
#[derive(Debug, Clone, Copy)]
struct PendingCorner {
    line: usize,
    /// Offset of the corner word's comma.
    col: u32,
    corner: Corner,
    start: AxisVec,
    end: AxisVec,
}

/// What a canned cycle does along its hole besides the feed to the bottom
/// (grammar/gcode.md, "Canned cycles").
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CycleSpec {
    /// The cycle's G code × 10 (830 for G83); 0 for no cycle.
    pub code10: i64,
    /// Peck depth of G73/G83 (`Q`, modal), mm; 0 for one feed.
    pub peck_mm: f64,
    /// Dwell at the bottom of G82/G89 (`P`, modal) as written, and its
    /// decimals (`None`: written without a point).
    pub dwell_p: Option<(f64, Option<u8>)>,
    /// The modal motion (G0–G3) the cycle leaves in force when it ends.
    pub motion_before: Option<Motion>,
    /// The hole may be written as moves: the setup allows it, the block
    /// drills once (no `K`/`L` repeat; G90 or G91), and the cycle is
    /// one a sequence of `G0`/`G1`/`G4` moves does the same as (G73,
    /// G81, G82, G83, G85, G89; not tapping, boring with a spindle stop or
    /// back boring).
    pub expandable: bool,
}

/// Tool table and work offsets the interpreter uses.
#[derive(Debug, Clone, Default)]
pub struct Setup {
    /// Tool lengths by H number, mm.
    pub tools: BTreeMap<u32, f64>,
    /// Work offsets G54..G59 (index 0..6), machine coordinates of the work zero, mm.
    pub work_offsets: [Option<[f64; 3]>; 6],
    /// Which axis slots the machine has (X Y Z A B C).
    pub axes: [bool; 6],
    /// Reference position (power-on position and G28 target), machine
    /// coordinates.
    pub home: AxisVec,
    /// Work offsets beyond G59 by key (`G54.1P1`, `G154P1`; `G110`–`G129`
    /// are `G154P1`–`G154P20`), machine coordinates of the work zero, mm.
    pub extra_offsets: BTreeMap<String, [f64; 3]>,
    /// Reference points of G30 by key (`G30` for P2, `G30P3`, `G30P4`),
    /// machine coordinates of X, Y, Z, mm.
    pub reference_points: BTreeMap<String, [f64; 3]>,
    /// The control's unit at power-on, for programs that set none
    /// (`None`: such a program is refused at its first length).
    pub units_default: Option<Units>,
    /// How length and angle words without a decimal point are read
    /// (`None`: in whole units, with a warning at the first one).
    pub integer_words: Option<IntegerWords>,
    /// The corner words (`,C`, `,R`) the control reads (`None`: refused
    /// by name).
    pub corner_words: Option<CornerWords>,
    /// The machine's nominal kinematics, for tool centre point control
    /// (G43.4/G43.5); `None` refuses it.
    pub kinematics: Option<std::sync::Arc<crate::machine::tool::MachineTool>>,
    /// Canned-cycle holes whose one X and Y would miss the tolerance may
    /// be written as the `G0`/`G1` moves of the cycle (`--expand-cycles`;
    /// see [`CycleSpec::expandable`]).
    pub expand_cycles: bool,
}

impl Setup {
    /// The setup a machine tool file gives: its axes, its tool table, its
    /// work offsets G54..G59 and its reference position (machine zero
    /// clamped into each axis' travel, Z at its upper limit).
    pub fn for_machine(m: &crate::machine::tool::MachineTool) -> Setup {
        let mut setup = Setup::default();
        for (slot, has) in setup.axes.iter_mut().enumerate() {
            *has = m.has_axis(slot);
        }
        setup.tools.extend(m.tools());
        for (i, wo) in setup.work_offsets.iter_mut().enumerate() {
            *wo = m.work_offset_mm(&format!("G{}", 54 + i));
        }
        setup.extra_offsets.extend(
            m.work_offsets()
                .filter(|(k, _)| {
                    !matches!(k.as_str(), "G54" | "G55" | "G56" | "G57" | "G58" | "G59")
                })
                .map(|(k, v)| (k.clone(), *v)),
        );
        setup
            .reference_points
            .extend(m.reference_points().map(|(k, v)| (k.clone(), *v)));
        setup.units_default = m.units_default();
        setup.integer_words = m.integer_words();
        setup.corner_words = m.corner_words();
        setup.expand_cycles = m.expand_deep_holes_to_moves();
        if (3..6).any(|s| m.has_axis(s)) {
            setup.kinematics = Some(std::sync::Arc::new(m.clone()));
        }
        setup.home = home_position(m);
        setup
    }
}

/// The reference position the interpreter starts from and G28 returns to:
/// machine zero clamped into each axis' travel, with Z at its upper limit
/// (spindle retracted).
fn home_position(m: &crate::machine::tool::MachineTool) -> AxisVec {
    let mut home = [0.0; 6];
    for (slot, h) in home.iter_mut().enumerate() {
        if let Some((lo, hi)) = m.travel(slot) {
            *h = if slot == 2 { hi } else { 0.0f64.clamp(lo, hi) };
        }
    }
    home
}

/// A warning about the program (not an error), with its first line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Warning {
    /// First line where it applies.
    pub line: usize,
    /// What it says.
    pub message: String,
    /// How many blocks it applies to.
    pub count: usize,
    /// A robot move left as written: which, where and why
    /// ([`crate::program::robot_moves`]); `None` for every other warning.
    pub left: Option<crate::program::robot_moves::LeftAsWritten>,
}

/// Modal state of the controller.
#[derive(Debug, Clone)]
pub struct Interpreter {
    setup: Setup,
    file: String,
    motion: Option<Motion>,
    cycle: Option<i64>,
    plane: Plane,
    absolute: bool,
    arc_absolute: bool,
    /// G20 (`Some(true)`) or G21; `None` until the program or the
    /// setup's default says.
    inch: Option<bool>,
    /// G93 inverse-time feed.
    inverse_time: bool,
    /// The active work offset, machine coordinates of the work zero, mm.
    work: [f64; 3],
    /// Tool centre point control (G43.4/G43.5) is on.
    tcpm: bool,
    /// Under tool centre point control: the programmed tool tip (X, Y, Z
    /// in the workpiece frame; rotary axes as programmed).
    tip: AxisVec,
    tool_len_mm: f64,
    h_active: Option<u32>,
    retract_initial: bool,
    cycle_r: Option<f64>,
    cycle_z: Option<f64>,
    cycle_initial: f64,
    /// The cycle's modal peck depth `Q` and dwell `P` (value, decimals).
    cycle_q: Option<f64>,
    cycle_p: Option<(f64, Option<u8>)>,
    feed: f64,
    /// The feed mode (G93, G94 or G95, × 10) whose F no longer holds: the
    /// mode changed since the last F word.
    feed_dropped: Option<i64>,
    per_rev: bool,
    spindle: f64,
    spindle_on: bool,
    milling_mm: [Option<f64>; 2],
    tool_selected: u32,
    tool_active: u32,
    /// Programmed position of the nominal tool tip, machine coordinates.
    pos: AxisVec,
    dirs: DirVec,
    warnings: Vec<Warning>,
    /// A block whose words without a decimal point are read in increments
    /// (`integer_words: increments`), reused between blocks.
    scaled: Block,
    /// A word without a decimal point was warned about.
    integer_warned: bool,
    /// The program set its units (G20/G21), or a length read in the
    /// machine file's `units_default` was warned about.
    units_said: bool,
    /// A G53 move down in Z was warned about.
    g53_down_warned: bool,
    comp_warned: bool,
    /// G41/G42 may be active with the block-delete switch in either
    /// position: set by G41/G42 on any line, cleared by G40 on a line
    /// without `/`.
    cutter_comp: bool,
    /// The corner of the last corner word, until the move after it.
    corner: Option<PendingCorner>,
}

const MAX_WARNINGS: usize = 64;

impl Interpreter {
    /// A controller in its power-on state: G0 G17 G90 G91.1 G21 G54 G49 G98,
    /// tool tip at the reference position, every axis last moved in the +
    /// direction.
    pub fn new(setup: Setup, file: &str) -> Self {
        let home = setup.home;
        let setup_units = setup.units_default;
        let first_offset = setup.work_offsets[0];
        Interpreter {
            setup,
            file: file.to_string(),
            motion: None,
            cycle: None,
            plane: Plane::XY,
            absolute: true,
            arc_absolute: false,
            inch: setup_units.map(|u| u == Units::Inch),
            inverse_time: false,
            work: first_offset.unwrap_or([0.0; 3]),
            tcpm: false,
            tip: home,
            tool_len_mm: 0.0,
            h_active: None,
            retract_initial: true,
            cycle_r: None,
            cycle_z: None,
            cycle_initial: 0.0,
            cycle_q: None,
            cycle_p: None,
            feed: 0.0,
            feed_dropped: None,
            per_rev: false,
            spindle: 0.0,
            spindle_on: false,
            milling_mm: [None; 2],
            tool_selected: 0,
            tool_active: 0,
            pos: home,
            dirs: [1; 6],
            warnings: Vec::new(),
            scaled: Block::default(),
            integer_warned: false,
            units_said: false,
            g53_down_warned: false,
            comp_warned: false,
            cutter_comp: false,
            corner: None,
        }
    }

    /// Warnings collected so far (deduplicated by message).
    pub fn warnings(&self) -> &[Warning] {
        &self.warnings
    }

    /// Current programmed tool-tip position, machine coordinates.
    pub fn position(&self) -> AxisVec {
        self.pos
    }

    /// Effective spindle speed after the last block, 1/min (0 while stopped).
    pub fn spindle_rpm(&self) -> f64 {
        if self.spindle_on { self.spindle } else { 0.0 }
    }

    /// Whether the program is in inches (G20).
    pub fn inch(&self) -> bool {
        self.inch == Some(true)
    }

    fn warn(&mut self, line: usize, message: String) {
        if let Some(w) = self.warnings.iter_mut().find(|w| w.message == message) {
            w.count += 1;
        } else if self.warnings.len() < MAX_WARNINGS {
            tracing::warn!("{}:{}: {}", self.file, line, message);
            self.warnings.push(Warning {
                line,
                message,
                count: 1,
                left: None,
            });
        }
    }

    fn err(&self, line: usize, w: Option<&Word>, msg: String) -> Located {
        Located::new(&self.file, line, w.map_or(1, |w| w.start as usize + 1), msg)
    }

    fn offset(&self) -> AxisVec {
        let wo = self.work;
        [wo[0], wo[1], wo[2], 0.0, 0.0, 0.0]
    }

    fn scale(&self) -> f64 {
        if self.inch == Some(true) {
            MM_PER_INCH
        } else {
            1.0
        }
    }

    /// Interprets one parsed block. `text` is the line (for messages): an
    /// error that does not quote its word quotes the block.
    pub fn step(&mut self, block: &Block, text: &[u8]) -> Result<Plan, Located> {
        let mut plan = Plan::default();
        self.step_into(block, text, &mut plan)?;
        Ok(plan)
    }

    /// [`Interpreter::step`] writing the plan into `plan` (no copy of the
    /// plan on the way back; `plan`'s previous content is overwritten).
    #[inline]
    pub fn step_into(
        &mut self,
        block: &Block,
        text: &[u8],
        plan: &mut Plan,
    ) -> Result<(), Located> {
        if self.integer_words(block) {
            let mut scaled = std::mem::take(&mut self.scaled);
            scaled.clone_from(block);
            self.to_increments(&mut scaled);
            let done = self.step_scaled(&scaled, text, plan);
            self.scaled = scaled;
            return done;
        }
        self.step_scaled(block, text, plan)
    }

    /// Reads the length and angle words of `block` without a decimal point
    /// as the control does, in place: with `integer_words: increments` they
    /// are turned into whole units (and marked as written with a point, so
    /// that they are not turned twice); without `integer_words` the first
    /// one is warned about. A pipeline calls it before [`Interpreter::step`]
    /// so that every later stage sees the values the control uses.
    pub fn whole_units(&mut self, block: &mut Block) {
        if self.integer_words(block) {
            self.to_increments(block);
        }
    }

    /// Whether `block` holds a length or angle word without a decimal point
    /// that the control reads in increments; without `integer_words` in the
    /// machine file, warns at the first such word (read in whole units).
    fn integer_words(&mut self, block: &Block) -> bool {
        // Nothing to turn or to warn about: no scan of the words.
        match self.setup.integer_words {
            Some(IntegerWords::Units) => return false,
            None if self.integer_warned => return false,
            _ => {}
        }
        let Some(w) = block.words.iter().find(|w| {
            w.decimals.is_none() && w.value != 0.0 && self.incremental_letter(block, w.letter)
        }) else {
            return false;
        };
        match self.setup.integer_words {
            Some(IntegerWords::Increments) => {
                if !self.integer_warned {
                    self.integer_warned = true;
                    let step = if (b'A'..=b'C').contains(&w.letter) {
                        "0.001°"
                    } else if self.block_inch(block) {
                        "0.0001 inch"
                    } else {
                        "0.001 mm"
                    };
                    self.warn(
                        block.line_no,
                        format!(
                            "`{}{}` has no decimal point: read as {} increments of {step}, the machine file's `integer_words: increments`",
                            w.letter as char, w.value, w.value
                        ),
                    );
                }
                true
            }
            Some(IntegerWords::Units) => false,
            None => {
                if !self.integer_warned {
                    self.integer_warned = true;
                    let unit = if w.letter >= b'A' && w.letter <= b'C' {
                        "degrees"
                    } else if self.inch() {
                        "inches"
                    } else {
                        "mm"
                    };
                    self.warn(
                        block.line_no,
                        format!(
                            "`{}{}` has no decimal point: read as {} {unit}; Fanuc and Haas controls as delivered read it in increments (0.001 mm, 0.0001 inch, 0.001°): say which with `integer_words: units` or `increments` in the machine file",
                            w.letter as char, w.value, w.value
                        ),
                    );
                }
                false
            }
        }
    }

    /// Whether a word of `letter` in `block` is a length or an angle that
    /// a control reads in increments when it has no decimal point: the axis
    /// words, arc centres and radius, the cycle's R and Q; not `K` in a
    /// canned cycle (its repeat count).
    fn incremental_letter(&self, block: &Block, letter: u8) -> bool {
        match letter {
            b'X' | b'Y' | b'Z' | b'A' | b'B' | b'C' | b'I' | b'J' | b'R' | b'Q' => true,
            CHAMFER | CORNER_RADIUS => true,
            b'K' => {
                self.cycle.is_none()
                    && !block.words.iter().any(|w| {
                        w.letter == b'G' && matches!(w.value as i64, 73 | 74 | 76 | 81..=89)
                    })
            }
            _ => false,
        }
    }

    /// The words of `block` without a decimal point, in increments, turned
    /// into whole units (0.001 mm or 0.0001 inch for lengths — the block's
    /// own G20/G21 first — and 0.001° for angles).
    fn to_increments(&self, block: &mut Block) {
        let inch = self.block_inch(block);
        let length = if inch { 1e-4 } else { 1e-3 };
        for i in 0..block.words.len() {
            let w = block.words[i];
            if w.decimals.is_none() && self.incremental_letter(block, w.letter) {
                let step = if (b'A'..=b'C').contains(&w.letter) {
                    1e-3
                } else {
                    length
                };
                block.words[i].value = w.value * step;
                block.words[i].decimals = Some(0);
            }
        }
    }

    /// Whether the lengths of `block` are in inches: its own G20/G21, else
    /// the modal units.
    fn block_inch(&self, block: &Block) -> bool {
        block
            .words
            .iter()
            .rev()
            .find(|w| {
                w.letter == b'G' && matches!(w.value as i64, 20 | 21) && w.value.fract() == 0.0
            })
            .map_or(self.inch(), |w| w.value as i64 == 20)
    }

    /// [`Interpreter::step_into`] of a block whose words are in whole units.
    fn step_scaled(&mut self, block: &Block, text: &[u8], plan: &mut Plan) -> Result<(), Located> {
        let before = self.cutter_comp;
        let done = self
            .step_block(block, text, plan)
            .and_then(|()| self.corner_words(block, text, plan));
        plan.cutter_comp = before || self.cutter_comp;
        done.map_err(|mut e| {
            if !e.message.contains('`') {
                let line = String::from_utf8_lossy(text);
                let line = line.trim();
                if !line.is_empty() {
                    e.message = format!(
                        "{}: `{}`",
                        e.message,
                        crate::error::clip_to(line, LINE_QUOTE_MAX)
                    );
                }
            }
            e
        })
    }

    fn step_block(&mut self, block: &Block, text: &[u8], plan: &mut Plan) -> Result<(), Located> {
        *plan = Plan {
            scale: self.scale(),
            absolute: self.absolute,
            arc_absolute: self.arc_absolute,
            offset: self.offset(),
            milling_mm: self.milling_mm,
            ..Plan::default()
        };
        if let Some(o) = &block.oword {
            // The resolution pass (`program::gcode::subprograms`) takes
            // these lines out of the block stream it hands over.
            return Err(Located::new(
                &self.file,
                block.line_no,
                1,
                format!(
                    "O-word `{}` lines are read by the subprogram pass, not block by block: `{}`",
                    o.keyword.as_str(),
                    crate::error::clip_to(String::from_utf8_lossy(text).trim(), LINE_QUOTE_MAX)
                ),
            ));
        }
        if block.is_empty() || block.block_delete && block.words.is_empty() {
            if !block.block_delete {
                self.directives(block, text)?;
                plan.milling_mm = self.milling_mm;
            }
            return Ok(());
        }
        let words = self.gather(block, text)?;
        self.check(block, &words, text)?;
        self.modal(block, &words)?;
        self.check_feed(block, &words, text)?;
        self.check_units(block, &words)?;
        if let Some(w) = words.tool_length {
            self.tool_length(block, &words)?;
            if let (true, Some(k)) = (self.tcpm, &self.setup.kinematics) {
                if matches!(w.code10(), 434 | 435) {
                    self.tip = k.tip_of(&self.pos, self.tool_len_mm);
                }
            }
        }
        plan.scale = self.scale();
        self.directives(block, text)?;
        plan.milling_mm = self.milling_mm;
        plan.absolute = self.absolute;
        plan.arc_absolute = self.arc_absolute;
        plan.offset = self.offset();
        if words.axis_naming.is_some() && words.axis.iter().any(Option::is_some) {
            // G50.1 X0 Y0: the axis words name the axes whose mirroring is
            // cancelled; nothing moves.
            return Ok(());
        }
        plan.programmed = programmed_axes(&words.axis);
        if let Some(w) = words.non_modal {
            if let Some(done) = self.non_modal(block, &words, w, plan, text)? {
                return Ok(done);
            }
        }
        self.motion(block, &words, plan, text)
    }

    /// Collects the block's words and checks each on its own (codes written
    /// exactly, numbers that must be whole, words given twice, codes of one
    /// modal group) before the block changes any state.
    fn gather<'b>(&self, block: &'b Block, text: &[u8]) -> Result<Words<'b>, Located> {
        let line = block.line_no;
        let quote = |w: &Word| quote_word(text, w);
        let mut g = Words::default();
        for w in &block.words {
            match w.letter {
                b'X' | b'Y' | b'Z' | b'A' | b'B' | b'C' => {
                    let slot = axis_slot(w.letter).unwrap_or(0);
                    if g.axis[slot].is_some() {
                        return Err(self.err(
                            line,
                            Some(w),
                            format!("axis word `{}` given twice in one block", quote(w)),
                        ));
                    }
                    if !self.setup.axes[slot] {
                        // A `C` on a machine without a C axis is most often
                        // a chamfer written without its comma.
                        let hint = if w.letter == b'C' {
                            "; a chamfer is written `,C` (read where the machine file says `corner_words: comma`)"
                        } else {
                            ""
                        };
                        return Err(self.err(
                            line,
                            Some(w),
                            format!(
                                "the machine has no {} axis{hint}: `{}`",
                                w.letter as char,
                                quote(w)
                            ),
                        ));
                    }
                    g.axis[slot] = Some(w);
                }
                b'I' | b'J' | b'K' => g.center[(w.letter - b'I') as usize] = Some(w),
                b'R' => g.r = Some(w),
                b'P' => g.p = Some(w),
                b'Q' => g.q = Some(w),
                b'F' => {
                    if w.value < 0.0 {
                        return Err(self.err(
                            line,
                            Some(w),
                            format!("negative feed `{}`", quote(w)),
                        ));
                    }
                    g.f = Some(w);
                }
                b'S' => {
                    if w.value < 0.0 {
                        return Err(self.err(
                            line,
                            Some(w),
                            format!("negative spindle speed `{}`", quote(w)),
                        ));
                    }
                    if w.value > MAX_SPINDLE_RPM {
                        return Err(self.err(
                            line,
                            Some(w),
                            format!(
                                "spindle speed above {MAX_SPINDLE_RPM} 1/min: `{}`",
                                quote(w)
                            ),
                        ));
                    }
                    g.s = Some(w);
                }
                b'T' | b'H' | b'D' | b'L' => {
                    if w.whole().is_none() {
                        let what = match w.letter {
                            b'T' => "tool number",
                            b'H' => "tool length offset number",
                            b'D' => "cutter radius offset number",
                            _ => "repeat count",
                        };
                        return Err(self.err(
                            line,
                            Some(w),
                            format!("{what} must be a whole number ≥ 0: `{}`", quote(w)),
                        ));
                    }
                    match w.letter {
                        b'T' => g.t = Some(w),
                        b'H' => g.h = Some(w),
                        b'L' => g.l = Some(w),
                        _ => {}
                    }
                }
                b'M' => self.gather_m(line, w, &mut g, text)?,
                b'G' => self.gather_g(line, w, &mut g, text)?,
                CHAMFER | CORNER_RADIUS if self.setup.corner_words.is_none() => {
                    return Err(self.err(line, Some(w), corner_refused(w, text)));
                }
                _ => {}
            }
        }
        Ok(g)
    }

    fn gather_m<'b>(
        &self,
        line: usize,
        w: &'b Word,
        g: &mut Words<'b>,
        text: &[u8],
    ) -> Result<(), Located> {
        let quote = |w: &Word| quote_word(text, w);
        let code = match w.exact_code10() {
            Some(c) if c % 10 == 0 => c,
            _ => {
                return Err(self.err(
                    line,
                    Some(w),
                    format!(
                        "`{}` is not an M code: M numbers are whole numbers (`M3`, `M30`)",
                        quote(w)
                    ),
                ));
            }
        };
        match code {
            30 | 40 | 50 => {
                if let Some(first) = g.spindle_m {
                    return Err(self.err(
                        line,
                        Some(w),
                        format!(
                            "`{}` and `{}` both set the spindle in one block",
                            quote(first),
                            quote(w)
                        ),
                    ));
                }
                g.spindle_m = Some(w);
            }
            980 | 990 | 970 | 1980 => {
                return Err(self.err(
                    line,
                    Some(w),
                    format!(
                        "subprogram calls cannot be compensated offline (expand them in CAM): `{}`",
                        quote(w)
                    ),
                ));
            }
            _ => {}
        }
        Ok(())
    }

    fn gather_g<'b>(
        &self,
        line: usize,
        w: &'b Word,
        g: &mut Words<'b>,
        text: &[u8],
    ) -> Result<(), Located> {
        let quote = |w: &Word| quote_word(text, w);
        let Some(code) = w.exact_code10() else {
            return Err(self.err(
                line,
                Some(w),
                format!(
                    "`{}` is not a G code: G numbers are written exactly as listed (`G1`, `G54.1`, `G43.4`)",
                    quote(w)
                ),
            ));
        };
        if let Some(k) = modal_group(code) {
            if let Some(first) = g.groups[k] {
                return Err(self.err(
                    line,
                    Some(w),
                    format!(
                        "`{}` and `{}` belong to the same modal group and cannot share a block",
                        quote(first),
                        quote(w)
                    ),
                ));
            }
            g.groups[k] = Some(w);
        }
        match g_class(code) {
            GClass::Motion | GClass::Cycle => {
                if let Some(first) = g.motion {
                    return Err(self.err(
                        line,
                        Some(w),
                        format!(
                            "two motion codes in one block: `{}` and `{}`",
                            quote(first),
                            quote(w)
                        ),
                    ));
                }
                g.motion = Some(w);
            }
            GClass::NonModal => {
                if let Some(first) = g.non_modal {
                    return Err(self.err(
                        line,
                        Some(w),
                        format!(
                            "`{}` and `{}` are both one-block codes and cannot share a block",
                            quote(first),
                            quote(w)
                        ),
                    ));
                }
                g.non_modal = Some(w);
            }
            GClass::Modal | GClass::Neutral => {}
            GClass::Spline => g.spline = Some(w),
            GClass::Refused(what) => {
                return Err(self.err(
                    line,
                    Some(w),
                    format!("{what} cannot be compensated offline: `{}`", quote(w)),
                ));
            }
        }
        if matches!(code, 430 | 434 | 435) {
            g.tool_length = Some(w);
        }
        if matches!(code, 500 | 501) {
            g.axis_naming = Some(w);
        }
        Ok(())
    }

    /// Checks that need the block as a whole: G5/G5.1 as a mode or as a
    /// spline.
    fn check(&self, block: &Block, g: &Words, text: &[u8]) -> Result<(), Located> {
        let line = block.line_no;
        if let Some(w) = g.spline {
            let moves = g.axis.iter().any(Option::is_some) || g.center.iter().any(Option::is_some);
            let mode = match w.code10() {
                // `G05 P10000` / `G05 P0`: high-speed machining mode.
                50 => g.p.is_some() && g.q.is_none() && g.r.is_none() && !moves,
                // `G05.1 Q1` (`R` level): AI contour control.
                51 => g.q.is_some() && g.p.is_none() && !moves,
                _ => false,
            };
            if !mode {
                let what = match w.code10() {
                    50 => "G5 (cubic spline)",
                    51 => "G5.1 (quadratic spline)",
                    _ => "G5.2/G5.3 and G6.2 (NURBS)",
                };
                return Err(self.err(
                    line,
                    Some(w),
                    format!(
                        "{what} cannot be compensated offline (post the path as lines and arcs): `{}`",
                        quote_word(text, w)
                    ),
                ));
            }
        }
        self.check_axis_naming(line, g, text)
    }

    /// G50.1 with axis words cancels mirroring on the axes it names (a
    /// mirror that is never on here: G51.1 is refused), so its words are
    /// not a move and a motion code beside them is refused. G50 with axis
    /// words is the lathe's coordinate-system setting (or a Fanuc
    /// scaling cancel written with words it does not take): refused.
    fn check_axis_naming(&self, line: usize, g: &Words, text: &[u8]) -> Result<(), Located> {
        let Some(w) = g.axis_naming else {
            return Ok(());
        };
        let Some(first) = g.axis.iter().flatten().next().copied() else {
            return Ok(());
        };
        let refuse = |what: &str| {
            Err(self.err(
                line,
                Some(w),
                format!(
                    "{what}: `{}` (`{}` is not a move)",
                    quote_word(text, w),
                    quote_word(text, first)
                ),
            ))
        };
        if w.code10() == 500 {
            return refuse(
                "G50 with axis words (lathe coordinate-system setting; on mills G50 cancels scaling and takes no axis words) cannot be compensated offline",
            );
        }
        if let Some(m) = g.motion {
            return refuse(&format!(
                "G50.1 (mirror cancel) names axes, and cannot share a block with the motion code `{}`",
                quote_word(text, m)
            ));
        }
        Ok(())
    }

    /// Applies the block's modal words in the order written.
    fn modal(&mut self, block: &Block, g: &Words) -> Result<(), Located> {
        if let Some(f) = g.f {
            self.feed = f.value;
            self.feed_dropped = None;
        }
        if let Some(s) = g.s {
            self.spindle = s.value;
        }
        if let Some(t) = g.t {
            self.tool_selected = t.whole().unwrap_or(0);
        }
        for w in &block.words {
            match (w.letter, w.code10()) {
                (b'M', 60) => self.tool_active = self.tool_selected,
                (b'M', 30 | 40) => self.spindle_on = true,
                (b'M', 50 | 20 | 300) => self.spindle_on = false,
                (b'G', code) => self.modal_g(block, g, w, code)?,
                _ => {}
            }
        }
        Ok(())
    }

    /// Refuses a feed beyond the plausibility limit, in the unit and feed
    /// mode the block leaves in force.
    fn check_feed(&self, block: &Block, g: &Words, text: &[u8]) -> Result<(), Located> {
        let Some(w) = g.f else { return Ok(()) };
        let f = if self.inverse_time {
            w.value
        } else {
            w.value * self.scale()
        };
        match crate::process::limits::feed_limit_in(f, self.per_rev, self.inverse_time) {
            Some((max, unit)) => Err(self.err(
                block.line_no,
                Some(w),
                format!("feed above {max} {unit}: `{}`", quote_word(text, w)),
            )),
            None => Ok(()),
        }
    }

    fn modal_g(&mut self, block: &Block, g: &Words, w: &Word, code: i64) -> Result<(), Located> {
        match code {
            800 => {
                self.cycle = None;
                self.cycle_r = None;
                self.cycle_z = None;
                self.cycle_q = None;
                self.cycle_p = None;
                if self.motion.is_none() {
                    self.motion = Some(Motion::Rapid);
                }
            }
            170 => self.plane = Plane::XY,
            180 => self.plane = Plane::ZX,
            190 => self.plane = Plane::YZ,
            200 => {
                self.inch = Some(true);
                self.units_said = true;
            }
            210 => {
                self.inch = Some(false);
                self.units_said = true;
            }
            900 => self.absolute = true,
            910 => self.absolute = false,
            901 => self.arc_absolute = true,
            911 => self.arc_absolute = false,
            540..=590 if code % 10 == 0 => {
                let i = ((code - 540) / 10) as usize;
                self.work = self.setup.work_offsets[i].unwrap_or([0.0; 3]);
            }
            541 | 1540 | 1100..=1290 => self.work = self.extended_offset(block, g, w, code)?,
            400 if !block.block_delete => self.cutter_comp = false,
            410 | 420 => {
                self.cutter_comp = true;
                if !self.comp_warned {
                    self.comp_warned = true;
                    self.warn(block.line_no, "cutter radius compensation (G41/G42) is passed through: deviations are evaluated on the programmed path, not the offset path, and no takeup points are written while it is active (a short move against the direction of travel would upset the controller's offset path)".into());
                }
            }
            490 => {
                self.tool_len_mm = 0.0;
                self.h_active = None;
                self.tcpm = false;
            }
            430 => self.tcpm = false,
            434 | 435 => {
                if self.setup.kinematics.is_none() {
                    return Err(self.err(
                        block.line_no,
                        Some(w),
                        "G43.4/G43.5 (tool centre point control) needs the machine's kinematics: a machine file with rotary axes (--machine)".into(),
                    ));
                }
                self.tcpm = true;
            }
            980 => self.retract_initial = true,
            990 => self.retract_initial = false,
            930 | 940 | 950 => self.feed_mode(g, code),
            _ => {}
        }
        Ok(())
    }

    /// The work offset of `G54.1 Pn`, `G154 Pn` or `G110`–`G129` (the same
    /// registers as `G154 P1`–`P20`), from the setup's extended offsets.
    fn extended_offset(
        &self,
        block: &Block,
        g: &Words,
        w: &Word,
        code: i64,
    ) -> Result<[f64; 3], Located> {
        let line = block.line_no;
        let key = match code {
            1100..=1290 => {
                if code % 10 != 0 {
                    return Err(self.err(
                        line,
                        Some(w),
                        format!("this G code cannot be compensated offline: `{}`", w.value),
                    ));
                }
                format!("G154P{}", (code - 1100) / 10 + 1)
            }
            _ => {
                let base = if code == 541 { "G54.1" } else { "G154" };
                let n = match g.p {
                    Some(p) => match p.whole() {
                        Some(n) if n >= 1 => n,
                        _ => {
                            return Err(self.err(
                                line,
                                Some(p),
                                format!(
                                    "the work offset number of {base} must be a whole number ≥ 1: `P{}`",
                                    p.value
                                ),
                            ));
                        }
                    },
                    None if code == 541 => 1,
                    None => {
                        return Err(self.err(
                            line,
                            Some(w),
                            "G154 needs the work offset number as a P word (`G154 P1`)".into(),
                        ));
                    }
                };
                format!("{base}P{n}")
            }
        };
        self.setup.extra_offsets.get(&key).copied().ok_or_else(|| {
            self.err(
                line,
                Some(w),
                format!(
                    "work offset {key} is not in the machine file (`work_offsets_mm: {{{key}: [X, Y, Z]}}`, or --work-offset {key}=X,Y,Z)"
                ),
            )
        })
    }

    /// A block with a length in program units needs to know the units:
    /// set by G20/G21, or the control's default from the setup, which the
    /// first block that relies on it names once.
    fn check_units(&mut self, block: &Block, g: &Words) -> Result<(), Located> {
        if self.units_said {
            return Ok(());
        }
        let dwell = g.non_modal.is_some_and(|w| w.code10() == 40);
        let inverse_time = self.inverse_time;
        let first = block.words.iter().find(|w| match w.letter {
            b'X' => !dwell,
            b'Y' | b'Z' | b'I' | b'J' | b'K' | b'R' => true,
            b'F' => !inverse_time,
            _ => false,
        });
        let Some(w) = first else {
            return Ok(());
        };
        match self.inch {
            Some(inch) => {
                self.units_said = true;
                let unit = if inch { "inch" } else { "mm" };
                self.warn(
                    block.line_no,
                    format!(
                        "the program sets no units (G20 inch or G21 mm) before `{}{}`: read in {unit}, the machine file's `units_default: {unit}` (or --units)",
                        w.letter as char, w.value
                    ),
                );
                Ok(())
            }
            None => Err(self.err(
                block.line_no,
                Some(w),
                format!(
                    "the program has not set its units (G20 inch or G21 mm) before `{}{}`, and the machine file gives no `units_default` (or pass --units mm|inch)",
                    w.letter as char, w.value
                ),
            )),
        }
    }

    /// G43 (G43.4, G43.5): the tool length of H, or of the active tool.
    fn tool_length(&mut self, block: &Block, g: &Words) -> Result<(), Located> {
        let h = match g.h {
            Some(hw) => hw.whole().unwrap_or(0),
            None => self.tool_active.max(self.tool_selected),
        };
        // `H0` written: offset number 0, which holds zero on Fanuc and Haas
        // controls whatever the tool table says.
        let zero = (g.h.is_some() && h == 0).then_some(&0.0);
        match zero.or_else(|| self.setup.tools.get(&h)) {
            Some(&len) => {
                self.tool_len_mm = len;
                self.h_active = Some(h);
                Ok(())
            }
            None => Err(self.err(
                block.line_no,
                g.h,
                format!(
                    "tool length offset H{h} is not in the tool table (machine file `tools`, or --tool H{h}=LENGTH)"
                ),
            )),
        }
    }

    /// One-block codes (dwell, reference returns, machine coordinates):
    /// `Some(())` when the block is done.
    fn non_modal(
        &mut self,
        block: &Block,
        g: &Words,
        w: &Word,
        plan: &mut Plan,
        text: &[u8],
    ) -> Result<Option<()>, Located> {
        let line = block.line_no;
        if self.tcpm && w.code10() != 40 {
            return Err(self.err(
                line,
                Some(w),
                format!(
                    "`{}` under G43.4/G43.5 (tool centre point control) cannot be compensated offline: cancel it with G49 first",
                    quote_word(text, w)
                ),
            ));
        }
        match w.code10() {
            40 => {
                // Dwell: P in ms (integer) / s (with point), or X in s.
                let (word, dwell_s) = match (g.p, g.axis[0]) {
                    (Some(p), _) if p.decimals.is_none() => (Some(p), p.value / 1000.0),
                    (Some(p), _) => (Some(p), p.value),
                    (None, Some(x)) => (Some(x), x.value),
                    _ => (None, 0.0),
                };
                if dwell_s < 0.0 {
                    return Err(self.err(
                        line,
                        word,
                        format!(
                            "negative dwell time: `{}`",
                            word.map(|w| quote_word(text, w)).unwrap_or_default()
                        ),
                    ));
                }
                plan.dwell_s = dwell_s;
                Ok(Some(()))
            }
            280 | 300 => {
                // A motion code written with G28/G30 stays modal (`G0 G28 G91 Z0.`).
                if let Some(m) = g.motion {
                    self.set_motion_mode(m);
                }
                let target = if w.code10() == 280 {
                    self.setup.home
                } else {
                    self.second_reference(line, g, w)?
                };
                self.reference_return(&g.axis, plan, &target);
                Ok(Some(()))
            }
            530 => {
                self.machine_move(&g.axis, plan, g.motion, line)?;
                Ok(Some(()))
            }
            _ => Ok(None),
        }
    }

    /// The position `G30` (P2, the default, P3 or P4) returns to, from the
    /// setup's reference points; rotary axes go to the reference position.
    fn second_reference(&self, line: usize, g: &Words, w: &Word) -> Result<AxisVec, Located> {
        let n = match g.p {
            None => 2,
            Some(p) => match p.whole() {
                Some(n @ 2..=4) => n,
                _ => {
                    return Err(self.err(
                        line,
                        Some(p),
                        format!(
                            "G30 takes P2, P3 or P4 (the reference point): `P{}`",
                            p.value
                        ),
                    ));
                }
            },
        };
        let key = if n == 2 {
            "G30".to_string()
        } else {
            format!("G30P{n}")
        };
        let xyz = self.setup.reference_points.get(&key).ok_or_else(|| {
            self.err(
                line,
                Some(w),
                format!(
                    "{key} returns to a reference point the machine file does not give (`reference_points_mm: {{{key}: [X, Y, Z]}}`)"
                ),
            )
        })?;
        let mut target = self.setup.home;
        target[..3].copy_from_slice(xyz);
        Ok(target)
    }

    /// Motion codes and the move of the block: G0–G3, canned-cycle holes.
    fn motion(
        &mut self,
        block: &Block,
        g: &Words,
        plan: &mut Plan,
        text: &[u8],
    ) -> Result<(), Located> {
        let line = block.line_no;
        if let Some(m) = g.motion {
            match m.code10() {
                0 | 10 | 20 | 30 => self.set_motion_mode(m),
                code => {
                    if self.plane != Plane::XY {
                        return Err(self.err(
                            line,
                            Some(m),
                            format!(
                                "canned cycles are supported in the G17 plane only: `{}`",
                                quote_word(text, m)
                            ),
                        ));
                    }
                    if self.cycle.is_none() {
                        self.cycle_initial = self.pos[2];
                    }
                    self.cycle = Some(code);
                }
            }
        }
        let any_axis = g.axis.iter().any(|a| a.is_some());
        if self.cycle.is_some() {
            if let Some(r) = g.r {
                self.cycle_r = Some(r.value);
            }
            if let Some(z) = g.axis[2] {
                self.cycle_z = Some(z.value);
            }
            if let Some(q) = g.q {
                self.cycle_q = Some(q.value);
            }
            if let Some(p) = g.p {
                self.cycle_p = Some((p.value, p.decimals));
            }
            if any_axis {
                if self.tcpm {
                    return Err(self.err(
                        line,
                        g.motion.or(g.axis.iter().flatten().next().copied()),
                        "canned cycles cannot run under G43.4/G43.5 (tool centre point control)"
                            .into(),
                    ));
                }
                if self.inverse_time {
                    return Err(self.err(
                        line,
                        g.motion.or(g.axis.iter().flatten().next().copied()),
                        "canned cycles cannot run under G93 (inverse-time feed)".into(),
                    ));
                }
                return self.cycle_hole(block, g, plan, line, text);
            }
            return Ok(());
        }
        let full_circle = g.motion.is_some_and(|m| matches!(m.code10(), 20 | 30))
            && g.center.iter().any(|c| c.is_some());
        if !any_axis && !full_circle {
            return Ok(());
        }
        let motion = match self.motion {
            Some(m) => m,
            None => {
                let first = g.axis.iter().flatten().next().copied();
                return Err(self.err(
                    line,
                    first,
                    "axis words before any motion mode (G0/G1/G2/G3) was set".into(),
                ));
            }
        };
        let start = self.pos;
        let end = if self.tcpm {
            self.tcpm_target(block, g, motion, plan)?
        } else {
            self.target(&g.axis, plan.scale, &plan.offset)
        };
        let arc = match motion {
            Motion::ArcCw | Motion::ArcCcw => {
                Some(self.arc(block, &start, &end, &g.center, g.r, g.p, motion, line, text)?)
            }
            // Outside a canned cycle an `R` on a G1 line is a corner
            // radius in the dialects that write it without the comma
            // (Fanuc with its comma-less corner words, Haas lathes); read
            // as nothing it would be a corner the control rounds and the
            // prediction does not.
            Motion::Linear => {
                if let Some(r) = g.r {
                    return Err(self.err(line, Some(r), plain_radius_refused(r, text)));
                }
                None
            }
            Motion::Rapid => None,
        };
        for (slot, a) in g.axis.iter().enumerate() {
            if let Some(w) = a {
                if !end[slot].is_finite() {
                    return Err(self.err(
                        line,
                        Some(w),
                        format!("coordinate out of range: `{}`", quote_word(text, w)),
                    ));
                }
            }
        }
        if motion != Motion::Rapid && self.inverse_time && g.f.is_none() {
            let first = g.axis.iter().flatten().next().copied();
            return Err(self.err(
                line,
                first,
                "under G93 (inverse-time feed) every feed move needs its own F word".into(),
            ));
        }
        if motion != Motion::Rapid && end != start {
            self.require_feed(line, g.f)?;
        }
        plan.extra_repeats = self.repeats(line, g, motion, &start, &end, text)?;
        let mut mv = self.make_move(motion, start, end, arc);
        plan.tcpm = self.tcpm;
        if motion != Motion::Rapid && self.inverse_time {
            // F is 1/min: the block lasts 1/F minutes whatever its length.
            mv.feed_mm_min = mv.timed_length() * self.feed;
            plan.inverse_time = true;
        }
        plan.kind = PlanKind::Motion;
        plan.mv = Some(mv);
        Ok(())
    }

    /// The corner words of `block` once its move is known: a corner word
    /// waiting for this move checks that it is a G1 line in the corner's
    /// plane long enough for the corner; a corner word of this block
    /// (where the machine file reads them) must stand on such a line and
    /// waits for the next move.
    fn corner_words(&mut self, block: &Block, text: &[u8], plan: &mut Plan) -> Result<(), Located> {
        let word = block
            .words
            .iter()
            .find(|w| matches!(w.letter, CHAMFER | CORNER_RADIUS));
        if let (Some(p), Some(mv)) = (self.corner, plan.mv.as_ref()) {
            self.corner = None;
            let next = (plan.kind == PlanKind::Motion && mv.motion == Motion::Linear)
                .then(|| self.in_plane(&mv.start, &mv.end))
                .flatten();
            let at = |msg: String| Located::new(&self.file, p.line, p.col as usize + 1, msg);
            let (Some(u2), Some(u1)) = (next, self.in_plane(&p.start, &p.end)) else {
                return Err(at(format!(
                    "the corner of line {} needs a G1 move in the {} plane after it, and line {} is not one: `{}`",
                    p.line,
                    self.plane_name(),
                    block.line_no,
                    crate::error::clip_to(String::from_utf8_lossy(text).trim(), LINE_QUOTE_MAX)
                )));
            };
            let d = p.corner.tangent_distance(&u1, &u2).ok_or_else(|| {
                at("the lines of the corner run on in one straight line or turn back on themselves: no corner to chamfer or round".into())
            })?;
            let shortest = dist3(&p.start, &p.end).min(dist3(&mv.start, &mv.end));
            if d > shortest {
                return Err(at(format!(
                    "the corner needs {d:.4} mm of each line and the shorter line is {shortest:.4} mm long"
                )));
            }
            plan.after_corner = true;
        }
        let Some(w) = word else {
            return Ok(());
        };
        let line = block.line_no;
        let on_line = plan
            .mv
            .as_ref()
            .filter(|mv| plan.kind == PlanKind::Motion && mv.motion == Motion::Linear)
            .filter(|mv| self.in_plane(&mv.start, &mv.end).is_some());
        let Some(mv) = on_line else {
            return Err(self.err(
                line,
                Some(w),
                format!(
                    "a corner word stands on a G1 move in the {} plane (the control makes the corner between it and the next one): `{}`",
                    self.plane_name(),
                    quote_word(text, w)
                ),
            ));
        };
        if w.value <= 0.0 {
            return Err(self.err(
                line,
                Some(w),
                format!(
                    "a corner word needs a size above 0: `{}`",
                    quote_word(text, w)
                ),
            ));
        }
        let corner = Corner {
            kind: if w.letter == CHAMFER {
                CornerKind::Chamfer
            } else {
                CornerKind::Round
            },
            size_mm: w.value * plan.scale,
        };
        plan.corner = Some(corner);
        self.corner = Some(PendingCorner {
            line,
            col: w.start,
            corner,
            start: mv.start,
            end: mv.end,
        });
        Ok(())
    }

    /// The unit direction of a line from `a` to `b` when it lies in the
    /// active plane (no motion of a rotary axis, none along the plane's
    /// normal beyond [`CORNER_NORMAL_MM`]).
    fn in_plane(&self, a: &AxisVec, b: &AxisVec) -> Option<Vector3<f64>> {
        let (_, _, n) = self.plane.axes();
        let still = |s: usize| (b[s] - a[s]).abs() <= CORNER_PLANE_MM;
        if (b[n] - a[n]).abs() > CORNER_NORMAL_MM || !(3..6).all(still) {
            return None;
        }
        let d = Vector3::new(b[0] - a[0], b[1] - a[1], b[2] - a[2]);
        let len = d.norm();
        (len > CORNER_PLANE_MM).then(|| d / len)
    }

    fn plane_name(&self) -> &'static str {
        match self.plane {
            Plane::XY => "G17",
            Plane::ZX => "G18",
            Plane::YZ => "G19",
        }
    }

    /// Repeats of a move after the first (`L`): accepted when every repeat
    /// runs the same path (a closed move, run again) or goes nowhere (an
    /// absolute line, already at its end), so one correction serves them
    /// all; refused when each repeat would go elsewhere.
    fn repeats(
        &self,
        line: usize,
        g: &Words,
        motion: Motion,
        start: &AxisVec,
        end: &AxisVec,
        text: &[u8],
    ) -> Result<u32, Located> {
        let Some(l) = g.l else { return Ok(0) };
        let n = l.whole().unwrap_or(0);
        if n == 1 {
            return Ok(0);
        }
        let closed = (0..6).all(|s| (end[s] - start[s]).abs() <= MOTION_EPS);
        let linear = matches!(motion, Motion::Rapid | Motion::Linear);
        if n == 0 {
            Err(self.err(
                line,
                Some(l),
                format!(
                    "repeat count must be a whole number ≥ 1: `{}`",
                    quote_word(text, l)
                ),
            ))
        } else if closed {
            // The same path again each time: predicted as often as run.
            Ok(n - 1)
        } else if linear && self.absolute {
            // Already at the end: the repeats do not move.
            Ok(0)
        } else {
            Err(self.err(
                line,
                Some(l),
                format!(
                    "repeat count `{}`: each repeat goes elsewhere and needs its own correction; repeat counts cannot be compensated offline here (expand them in CAM)",
                    quote_word(text, l)
                ),
            ))
        }
    }

    /// Reads `(POSTPROC MILLING DEPTH=d WIDTH=w)` directive comments (values
    /// in program units, either key optional; modal until the next one),
    /// with [`crate::program::directive::read`].
    fn directives(&mut self, block: &Block, text: &[u8]) -> Result<(), Located> {
        for c in &block.comments {
            let raw = text.get(c.start as usize..c.end as usize).unwrap_or(b"");
            let body = String::from_utf8_lossy(raw);
            let open = body.get(..1).unwrap_or("");
            let inner = body.get(1..).unwrap_or("");
            let inner = if open == "(" {
                inner.strip_suffix(')').unwrap_or(inner)
            } else {
                inner
            };
            let cur = crate::process::CutSettings {
                depth_mm: self.milling_mm[0],
                width_mm: self.milling_mm[1],
                spindle_rpm: None,
            };
            match crate::program::directive::read(inner, false, self.scale(), cur) {
                Ok(None) => {}
                Ok(Some(set)) => self.milling_mm = [set.depth_mm, set.width_mm],
                Err(r) => {
                    // Columns are 1-based: the opener is at `c.start + 1`.
                    let col = c.start as usize + 1 + r.word_at.map_or(0, |off| 1 + off);
                    return Err(Located::new(&self.file, block.line_no, col, r.message));
                }
            }
        }
        Ok(())
    }

    /// Makes a G0/G1/G2/G3 word the modal motion (cancelling a canned cycle);
    /// other codes are left alone.
    fn set_motion_mode(&mut self, g: &Word) {
        let motion = match g.code10() {
            0 => Motion::Rapid,
            10 => Motion::Linear,
            20 => Motion::ArcCw,
            30 => Motion::ArcCcw,
            _ => return,
        };
        self.motion = Some(motion);
        self.cycle = None;
    }

    /// G93, G94 or G95. A change of feed mode leaves no feed rate in force
    /// unless its block gives one: an F of one mode (1/min, mm/min, mm/rev)
    /// means something else in the next, and the controls want a new F.
    fn feed_mode(&mut self, g: &Words, code: i64) {
        let before = if self.inverse_time {
            930
        } else if self.per_rev {
            950
        } else {
            940
        };
        self.inverse_time = code == 930;
        self.per_rev = code == 950;
        if before != code && g.f.is_none() && self.feed > 0.0 {
            self.feed = 0.0;
            self.feed_dropped = Some(before);
        }
    }

    fn feed_mm_min(&self) -> f64 {
        let f = self.feed * self.scale();
        if self.per_rev { f * self.spindle } else { f }
    }

    /// A feed move needs a feed rate: F0, or no F yet, would never finish
    /// on the controller (an alarm), and gives the move no duration.
    fn require_feed(&self, line: usize, f_word: Option<&Word>) -> Result<(), Located> {
        if self.feed > 0.0 && (!self.per_rev || self.spindle > 0.0) {
            return Ok(());
        }
        if let (Some(before), None) = (self.feed_dropped, f_word) {
            let name = |c: i64| match c {
                930 => "G93 (inverse time)",
                950 => "G95 (per revolution)",
                _ => "G94 (per minute)",
            };
            let now = if self.inverse_time {
                930
            } else if self.per_rev {
                950
            } else {
                940
            };
            return Err(self.err(
                line,
                None,
                format!(
                    "feed move without a new F after the change of feed mode to {}: the F in force was given under {} and does not carry over",
                    name(now),
                    name(before)
                ),
            ));
        }
        let what = if self.per_rev && self.feed > 0.0 {
            "feed per revolution (G95) with the spindle speed S at 0"
        } else if f_word.is_some() {
            "feed move with F0"
        } else {
            "feed move before any feed rate F was programmed"
        };
        Err(self.err(line, f_word, what.to_string()))
    }

    fn make_move(
        &mut self,
        motion: Motion,
        start: AxisVec,
        end: AxisVec,
        arc: Option<ArcGeom>,
    ) -> Move {
        let prev_dirs = self.dirs;
        let dirs = directions(&prev_dirs, &start, &end, arc.as_ref());
        self.dirs = dirs;
        self.pos = end;
        Move {
            motion,
            start,
            end,
            arc,
            dirs,
            prev_dirs,
            feed_mm_min: if motion == Motion::Rapid {
                0.0
            } else {
                self.feed_mm_min()
            },
            spindle_rpm: if self.spindle_on { self.spindle } else { 0.0 },
            tool: self.tool_active,
            tool_len_mm: self.tool_len_mm,
        }
    }

    /// Under tool centre point control: the programmed tip of the block
    /// (kept as the new tip) turned into axis positions by the nominal
    /// kinematics.
    fn tcpm_target(
        &mut self,
        block: &Block,
        g: &Words,
        motion: Motion,
        plan: &Plan,
    ) -> Result<AxisVec, Located> {
        let first = g.motion.or(g.axis.iter().flatten().next().copied());
        if matches!(motion, Motion::ArcCw | Motion::ArcCcw) {
            return Err(self.err(
                block.line_no,
                first,
                "arcs under G43.4/G43.5 (tool centre point control) cannot be compensated offline"
                    .into(),
            ));
        }
        if let Some(w) = g.center.iter().flatten().next() {
            return Err(self.err(
                block.line_no,
                Some(w),
                "tool orientation vectors (I J K) under G43.4/G43.5 cannot be compensated offline: program the rotary axes' angles".into(),
            ));
        }
        let tip = self.target_from(&self.tip, &g.axis, plan.scale, &plan.offset);
        let axes = self
            .setup
            .kinematics
            .as_ref()
            .and_then(|k| k.axes_for_tip(&tip, self.tool_len_mm));
        match axes {
            Some(end) => {
                self.tip = tip;
                Ok(end)
            }
            None => Err(self.err(
                block.line_no,
                first,
                "no axis positions put the tool tip there".into(),
            )),
        }
    }

    /// Machine coordinates of the block's end point.
    fn target(&self, axis: &[Option<&Word>; 6], scale: f64, offset: &AxisVec) -> AxisVec {
        self.target_from(&self.pos, axis, scale, offset)
    }

    /// The block's end point from `from` (absolute words replace, incremental
    /// words add to it).
    fn target_from(
        &self,
        from: &AxisVec,
        axis: &[Option<&Word>; 6],
        scale: f64,
        offset: &AxisVec,
    ) -> AxisVec {
        let mut end = *from;
        for (slot, a) in axis.iter().enumerate() {
            if let Some(w) = a {
                let s = if slot < 3 { scale } else { 1.0 };
                end[slot] = if self.absolute {
                    w.value * s + offset[slot]
                } else {
                    from[slot] + w.value * s
                };
            }
        }
        end
    }

    #[allow(clippy::too_many_arguments)]
    fn arc(
        &self,
        block: &Block,
        start: &AxisVec,
        end: &AxisVec,
        center: &[Option<&Word>; 3],
        r_word: Option<&Word>,
        p_word: Option<&Word>,
        motion: Motion,
        line: usize,
        text: &[u8],
    ) -> Result<ArcGeom, Located> {
        let plane = self.plane;
        let (a, b, n) = plane.axes();
        let (la, lb) = plane.center_letters();
        let idx = |l: u8| (l - b'I') as usize;
        let first_word = block
            .words
            .iter()
            .find(|w| w.letter == b'G' && matches!(w.code10(), 20 | 30))
            .or(block.words.first());
        let s3 = Vector3::new(start[0], start[1], start[2]);
        let e3 = Vector3::new(end[0], end[1], end[2]);
        let scale = self.scale();
        let ccw = motion == Motion::ArcCcw;
        // The normal-axis centre word is not allowed (would be a non-planar arc).
        let normal_letter = [b'I', b'J', b'K'][n];
        if let Some(w) = center[idx(normal_letter)] {
            if w.value.abs() > MOTION_EPS {
                return Err(self.err(
                    line,
                    Some(w),
                    format!(
                        "centre offset along the plane normal is not allowed in this plane: `{}`",
                        String::from_utf8_lossy(
                            text.get(w.start as usize..w.end as usize).unwrap_or(b"")
                        )
                    ),
                ));
            }
        }
        let (ca, cb) = match (center[idx(la)], center[idx(lb)], r_word) {
            (None, None, Some(r)) => {
                let da = e3[a] - s3[a];
                let db = e3[b] - s3[b];
                let chord = da.hypot(db);
                let rad = r.value.abs() * scale;
                if chord < MOTION_EPS {
                    return Err(self.err(
                        line,
                        Some(r),
                        "an R arc cannot be a full circle; use I/J/K".into(),
                    ));
                }
                if chord > 2.0 * rad + ARC_RADIUS_TOL_MM {
                    return Err(self.err(
                        line,
                        Some(r),
                        format!(
                            "arc radius {} is smaller than half the chord {:.4}",
                            r.value,
                            chord / 2.0 / scale
                        ),
                    ));
                }
                let h = (rad * rad - chord * chord / 4.0).max(0.0).sqrt();
                let (ma, mb) = (s3[a] + da / 2.0, s3[b] + db / 2.0);
                // Left normal of the chord direction.
                let (na, nb) = (-db / chord, da / chord);
                // CCW with R>0 (short arc) puts the centre on the left.
                let left = ccw == (r.value > 0.0);
                let sgn = if left { 1.0 } else { -1.0 };
                (ma + sgn * h * na, mb + sgn * h * nb)
            }
            (None, None, None) => {
                return Err(self.err(line, first_word, no_centre(ccw, la, lb)));
            }
            (ia, ib, None) => {
                let off = |w: Option<&Word>, slot: usize| -> f64 {
                    match w {
                        Some(w) if self.arc_absolute => w.value * scale + self.offset()[slot],
                        Some(w) => s3[slot] + w.value * scale,
                        None if self.arc_absolute => self.offset()[slot],
                        None => s3[slot],
                    }
                };
                (off(ia, a), off(ib, b))
            }
            (_, _, Some(r)) => {
                return Err(self.err(
                    line,
                    Some(r),
                    "an arc has both R and a centre offset".into(),
                ));
            }
        };
        let r0 = (s3[a] - ca).hypot(s3[b] - cb);
        let r1 = (e3[a] - ca).hypot(e3[b] - cb);
        if r0 < MOTION_EPS {
            return Err(self.err(line, first_word, "arc of zero radius".into()));
        }
        if (r0 - r1).abs() > ARC_RADIUS_TOL_MM + 1e-3 * r0 {
            return Err(self.err(line, first_word, format!("arc end point is not on the circle: start radius {r0:.4} mm, end radius {r1:.4} mm")));
        }
        let a0 = (s3[b] - cb).atan2(s3[a] - ca);
        let a1 = (e3[b] - cb).atan2(e3[a] - ca);
        let mut sweep = a1 - a0;
        let tau = std::f64::consts::TAU;
        let full = (e3[a] - s3[a]).hypot(e3[b] - s3[b]) < 1e-7;
        if ccw {
            while sweep <= 0.0 {
                sweep += tau;
            }
            if !full && sweep > tau {
                sweep -= tau;
            }
        } else {
            while sweep >= 0.0 {
                sweep -= tau;
            }
            if !full && sweep < -tau {
                sweep += tau;
            }
        }
        if full {
            sweep = if ccw { tau } else { -tau };
        }
        if let Some(p) = p_word {
            let turns = p.value.round();
            if turns >= 2.0 {
                return Err(self.err(
                    line,
                    Some(p),
                    "multi-turn arcs (P ≥ 2) cannot be compensated offline".into(),
                ));
            }
        }
        let mut center3 = s3;
        center3[a] = ca;
        center3[b] = cb;
        Ok(ArcGeom {
            plane,
            center: center3,
            sweep,
            radius: (r0 + r1) / 2.0,
        })
    }

    fn cycle_hole(
        &mut self,
        block: &Block,
        g: &Words,
        plan: &mut Plan,
        line: usize,
        text: &[u8],
    ) -> Result<(), Located> {
        let axis = &g.axis;
        let scale = plan.scale;
        let off = plan.offset;
        let first = axis.iter().flatten().next().copied();
        let (Some(r), Some(z)) = (self.cycle_r, self.cycle_z) else {
            return Err(self.err(
                line,
                first,
                format!(
                    "canned cycle without {} : `{}`",
                    if self.cycle_r.is_none() {
                        "an R level"
                    } else {
                        "a Z depth"
                    },
                    String::from_utf8_lossy(crate::program::gcode::strip_eol(text))
                ),
            ));
        };
        plan.extra_repeats = self.cycle_repeats(block, g, text)?;
        // The dwell at the hole bottom (G82, G89; P) cannot be negative.
        if let Some(p) = g.p.filter(|p| p.value < 0.0) {
            return Err(self.err(
                line,
                Some(p),
                format!("negative dwell time: `{}`", quote_word(text, p)),
            ));
        }
        let initial = self.cycle_initial;
        // Hole XY position.
        let mut xy = self.pos;
        for slot in [0usize, 1, 3, 4, 5] {
            if let Some(w) = axis[slot] {
                let s = if slot < 3 { scale } else { 1.0 };
                xy[slot] = if self.absolute {
                    w.value * s + off[slot]
                } else {
                    self.pos[slot] + w.value * s
                };
            }
        }
        let (r_level, bottom) = if self.absolute {
            (r * scale + off[2], z * scale + off[2])
        } else {
            // G91: R from the initial level, Z from the R level.
            let rl = initial + r * scale;
            (rl, rl + z * scale)
        };
        let retract = if self.retract_initial {
            initial.max(r_level)
        } else {
            r_level
        };
        if bottom > r_level + MOTION_EPS {
            return Err(self.err(
                line,
                axis[2].or(first),
                format!(
                    "hole bottom Z is above the R level ({:.4} > {:.4})",
                    bottom / scale,
                    r_level / scale
                ),
            ));
        }
        // Positioning at the current height, then to R, feed to the bottom, retract.
        let mut above = xy;
        above[2] = self.pos[2];
        self.make_move(Motion::Rapid, self.pos, above, None);
        let mut at_r = xy;
        at_r[2] = r_level;
        self.make_move(Motion::Rapid, above, at_r, None);
        let mut at_bottom = xy;
        at_bottom[2] = bottom;
        self.require_feed(line, block.words.iter().find(|w| w.letter == b'F'))?;
        let feed = self.make_move(Motion::Linear, at_r, at_bottom, None);
        let mut up = xy;
        up[2] = retract;
        self.make_move(Motion::Rapid, at_bottom, up, None);
        plan.kind = PlanKind::Cycle {
            r_level,
            bottom,
            retract,
        };
        plan.mv = Some(feed);
        plan.cycle = self.cycle_spec(plan);
        Ok(())
    }

    /// What the cycle of the hole `plan` does along it ([`CycleSpec`]).
    fn cycle_spec(&self, plan: &Plan) -> CycleSpec {
        let code10 = self.cycle.unwrap_or(0);
        let pecks = matches!(code10, 730 | 830);
        let dwells = matches!(code10, 820 | 890);
        CycleSpec {
            code10,
            peck_mm: if pecks {
                self.cycle_q.map_or(0.0, |q| q.abs() * plan.scale)
            } else {
                0.0
            },
            dwell_p: self.cycle_p.filter(|_| dwells),
            motion_before: self.motion,
            expandable: self.setup.expand_cycles
                && plan.extra_repeats == 0
                && matches!(code10, 730 | 810 | 820 | 830 | 850 | 890),
        }
    }

    /// The holes a cycle block drills after the first (`K`, or Haas `L`):
    /// under G90 the same hole again (one correction serves them all);
    /// under G91 each repeat is another hole, refused.
    fn cycle_repeats(&self, block: &Block, g: &Words, text: &[u8]) -> Result<u32, Located> {
        let Some(w) = g.l.or(g.center[2]) else {
            return Ok(0);
        };
        let n = match w.whole() {
            Some(0) | None => {
                return Err(self.err(
                    block.line_no,
                    Some(w),
                    format!(
                        "repeat count must be a whole number ≥ 1: `{}`",
                        quote_word(text, w)
                    ),
                ));
            }
            Some(n) => n,
        };
        if n > 1 && !self.absolute {
            return Err(self.err(
                block.line_no,
                Some(w),
                format!(
                    "repeat count `{}` under G91 drills a row of holes, each needing its own correction; repeat counts cannot be compensated offline here (expand them in CAM)",
                    quote_word(text, w)
                ),
            ));
        }
        Ok(n - 1)
    }

    /// G28/G30: the axes named move at rapid to the intermediate point (in
    /// the current G90/G91 mode) and then to `reference`.
    fn reference_return(
        &mut self,
        axis: &[Option<&Word>; 6],
        plan: &mut Plan,
        reference: &AxisVec,
    ) {
        let mid = self.target(axis, plan.scale, &plan.offset);
        let start = self.pos;
        self.make_move(Motion::Rapid, start, mid, None);
        let mut home = mid;
        for (slot, a) in axis.iter().enumerate() {
            if a.is_some() {
                home[slot] = reference[slot];
            }
        }
        let mv = self.make_move(Motion::Rapid, mid, home, None);
        plan.kind = PlanKind::Fixed;
        plan.mv = Some(mv);
    }

    fn machine_move(
        &mut self,
        axis: &[Option<&Word>; 6],
        plan: &mut Plan,
        motion_g: Option<&Word>,
        line: usize,
    ) -> Result<(), Located> {
        if let Some(g) = motion_g {
            if !matches!(g.code10(), 0 | 10) {
                return Err(self.err(line, Some(g), "G53 moves only with G0 or G1".into()));
            }
            // G53 is one-shot, but the G0/G1 written with it stays modal.
            self.set_motion_mode(g);
        }
        let mut end = self.pos;
        for (slot, a) in axis.iter().enumerate() {
            if let Some(w) = a {
                let s = if slot < 3 { plan.scale } else { 1.0 };
                end[slot] = w.value * s;
            }
        }
        if axis[2].is_some() && end[2] < self.pos[2] - G53_DOWN_MM && !self.g53_down_warned {
            self.g53_down_warned = true;
            self.warn(
                line,
                format!(
                    "G53 moves Z down, from machine Z{:.3} to Z{:.3}: programs write a G53 Z move as a retract (on Haas and Fanuc machine Z0 is the top of the travel); check that the machine file's Z axis counts the same way",
                    self.pos[2], end[2]
                ),
            );
        }
        let mv = self.make_move(Motion::Rapid, self.pos, end, None);
        plan.kind = PlanKind::Fixed;
        plan.mv = Some(mv);
        Ok(())
    }
}

/// A G53 Z move down by more than this is warned about (a retract that
/// plunges), mm.
const G53_DOWN_MM: f64 = 1.0;

/// How the interpreter takes a G code (code × 10).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum GClass {
    /// G0, G1, G2, G3.
    Motion,
    /// A canned drilling cycle.
    Cycle,
    /// One-block codes with their own handling: G4, G28, G30, G53.
    NonModal,
    /// A mode the interpreter keeps (plane, units, offsets, …).
    Modal,
    /// A mode or one-block code that changes no geometry (smoothing,
    /// look-ahead, exact stop, …): passed through with its words.
    Neutral,
    /// G5, G5.1 (a mode with P or Q alone, else a spline), G5.2, G5.3, G6.2.
    Spline,
    /// Refused, with what the code is.
    Refused(&'static str),
}

/// The class of a G code written exactly (code × 10).
fn g_class(code: i64) -> GClass {
    match code {
        0 | 10 | 20 | 30 => GClass::Motion,
        730 | 740 | 760 | 810 | 820 | 830 | 840 | 850 | 860 | 870 | 880 | 890 => GClass::Cycle,
        40 | 280 | 300 | 530 => GClass::NonModal,
        800 | 170 | 180 | 190 | 200 | 210 | 900 | 910 | 901 | 911 | 400 | 410 | 420 | 430 | 490
        | 980 | 990 | 930 | 940 | 950 | 541 | 1540 | 434 | 435 => GClass::Modal,
        540..=590 | 1100..=1290 if code % 10 == 0 => GClass::Modal,
        // G8 look-ahead, G9 exact stop, G11, G13.1 polar interpolation
        // cancel, G15 polar cancel, G50/G50.1 scaling/mirror cancel,
        // G61/G61.1 exact stop and path modes, G62/G63 corner override
        // and tapping modes, G64 path blending, G67 modal macro cancel,
        // G69 rotation cancel, G96/G97 spindle speed modes, G103 block
        // look-ahead, G187 smoothing.
        80 | 90 | 110 | 131 | 150 | 500 | 501 | 610 | 611 | 620 | 630 | 640 | 670 | 690 | 960
        | 970 | 1030 | 1870 => GClass::Neutral,
        50 | 51 | 52 | 53 | 62 => GClass::Spline,
        _ => GClass::Refused(refused_g(code)),
    }
}

/// What a refused G code is, for the message.
fn refused_g(code: i64) -> &'static str {
    match code {
        24 | 34 => "G2.4/G3.4 (3D arcs)",
        71 => "G7.1 (cylindrical interpolation)",
        100 => "G10 (programmable data input)",
        120 | 130 => "G12/G13 (circular pocket milling)",
        121 => "G12.1 (polar interpolation)",
        160 => "G16 (polar coordinates)",
        310 | 311 | 312 | 313 | 382 | 383 | 384 | 385 => "G31/G38 (probing)",
        320 | 330 | 340 | 350 => "G32–G35 (thread cutting)",
        470 => "G47 (engraving)",
        520 => "G52 (local coordinate system)",
        510 => "G51 (scaling/mirroring)",
        511 => "G51.1 (programmable mirror image)",
        531 => "G53.1 (tool axis direction control)",
        600 => "G60 (single-direction positioning)",
        650 | 660 | 661 => "G65/G66 (macro calls)",
        680 => "G68 (coordinate rotation)",
        681 | 682 | 684 => "G68.2 (tilted working plane)",
        700 | 710 | 720 | 750 => {
            "G70–G72, G75 (lathe turning cycles; lathe programs are not supported)"
        }
        920 | 921 => "G92 (coordinate system shift)",
        1410 => "G141 (3D cutter compensation)",
        1500 => "G150 (pocket milling)",
        2340 => "G234 (Haas tool centre point control, TCPC; G43.4 is read for it)",
        2540 | 2550 => "G254/G255 (Haas dynamic work offset, DWO)",
        _ => "this G code",
    }
}

/// The words of one block, gathered and checked before the block changes
/// any state.
#[derive(Default)]
struct Words<'b> {
    axis: [Option<&'b Word>; 6],
    center: [Option<&'b Word>; 3],
    r: Option<&'b Word>,
    p: Option<&'b Word>,
    q: Option<&'b Word>,
    h: Option<&'b Word>,
    f: Option<&'b Word>,
    s: Option<&'b Word>,
    t: Option<&'b Word>,
    l: Option<&'b Word>,
    /// G0–G3 or a cycle code.
    motion: Option<&'b Word>,
    /// G4, G28, G30 or G53.
    non_modal: Option<&'b Word>,
    /// G43, G43.4 or G43.5.
    tool_length: Option<&'b Word>,
    /// G5, G5.1, G5.2, G5.3 or G6.2.
    spline: Option<&'b Word>,
    /// G50 (scaling cancel) or G50.1 (mirror cancel): their axis words
    /// name axes, they are not a move.
    axis_naming: Option<&'b Word>,
    groups: [Option<&'b Word>; MODAL_GROUPS],
    spindle_m: Option<&'b Word>,
}

/// A word's text within its line.
fn quote_word(text: &[u8], w: &Word) -> String {
    String::from_utf8_lossy(text.get(w.start as usize..w.end as usize).unwrap_or(b"")).to_string()
}

/// The axis slots a block gives words for, one bit each.
fn programmed_axes(axis: &[Option<&Word>; 6]) -> u8 {
    axis.iter()
        .enumerate()
        .filter(|(_, a)| a.is_some())
        .fold(0u8, |m, (i, _)| m | (1 << i))
}

/// The refusal of corner word `w` on a control the machine file does not
/// say reads it.
fn corner_refused(w: &Word, text: &[u8]) -> String {
    let shown = String::from_utf8_lossy(text.get(w.start as usize..).unwrap_or(b""));
    let shown: String = shown.trim_end().chars().take(40).collect();
    let (word, what, how) = if w.letter == CHAMFER {
        (",C", "chamfer", "moves")
    } else {
        (",R", "rounding", "an arc")
    };
    let kind = if w.letter == CHAMFER {
        "a chamfer word"
    } else {
        "a corner-radius word"
    };
    format!(
        "{kind} `{word}` is not read: the control inserts the {what} between this move and the next; write the corner as {how}, or say `corner_words: comma` in the machine file if the control reads it: `{shown}`"
    )
}

/// The message for an `R` word on a G1 line outside a canned cycle: a
/// corner radius written without its comma.
fn plain_radius_refused(w: &Word, text: &[u8]) -> String {
    let shown = String::from_utf8_lossy(text.get(w.start as usize..).unwrap_or(b""));
    let shown: String = shown.trim_end().chars().take(40).collect();
    format!(
        "`R` on a G1 line is not read: outside a canned cycle it is a corner radius written without the comma, which the control rounds between this move and the next; write the corner as an arc, or as `,R` with `corner_words: comma` in the machine file if the control reads it: `{shown}`"
    )
}

/// The message for an arc with neither a centre offset nor `R`, naming its
/// code and the plane's centre letters `la`, `lb`.
fn no_centre(ccw: bool, la: u8, lb: u8) -> String {
    let g = if ccw { "G3" } else { "G2" };
    format!(
        "{g} without a centre: an arc needs its centre offset `{}`/`{}` or a radius `R`",
        la as char, lb as char
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::program::gcode::parse_line;
    use approx::assert_abs_diff_eq;

    const TOL: f64 = 1e-9;

    fn run(lines: &[&str]) -> Result<Vec<Plan>, Located> {
        let mut setup = Setup {
            axes: [true, true, true, false, false, true],
            units_default: Some(Units::Mm),
            ..Setup::default()
        };
        setup.tools.insert(1, 100.0);
        setup.work_offsets[0] = Some([100.0, 50.0, -200.0]);
        let mut it = Interpreter::new(setup, "t.nc");
        let mut b = Block::default();
        let mut out = vec![];
        for (i, l) in lines.iter().enumerate() {
            parse_line(l.as_bytes(), i + 1, "t.nc", &mut b)?;
            out.push(it.step(&b, l.as_bytes())?);
        }
        Ok(out)
    }

    #[test]
    fn work_offset_and_incremental() {
        let p = run(&["G90 G54 G0 X10 Y20 Z5", "G91 G1 X5 F100"]).unwrap();
        let m0 = p[0].mv.unwrap();
        assert_eq!(&m0.end[..3], &[110.0, 70.0, -195.0]);
        let m1 = p[1].mv.unwrap();
        assert_eq!(&m1.end[..3], &[115.0, 70.0, -195.0]);
        assert_eq!(m1.dirs[0], 1);
        assert_eq!(m1.feed_mm_min, 100.0);
    }

    #[test]
    fn an_arc_off_its_circle_is_read_as_the_spiral_of_fanuc_and_linuxcnc() {
        // A quarter turn CCW about the program origin (machine (100, 50))
        // from radius 10 at 0° to radius 10.005 at 90°: at parameter s the
        // radius is 10 + 0.005·s and the angle 90°·s. By hand:
        // s = 1/4: 10.00125·(cos 22.5°, sin 22.5°) = (9.23995017, 3.82731268);
        // s = 1/2: 10.0025·(cos 45°, sin 45°) = (7.07283558, 7.07283558);
        // s = 3/4: 10.00375·(cos 67.5°, sin 67.5°) = (3.82826939, 9.24225987).
        let p = run(&["G90 G54 G0 X10 Y0", "G3 X0 Y10.005 I-10 J0 F100"]).unwrap();
        let mv = p[1].mv.unwrap();
        let arc = mv.arc.unwrap();
        let (s3, e3) = (mv.start3(), mv.end3());
        for (s, x, y) in [
            (0.25, 9.239950174528508, 3.827312677941354),
            (0.5, 7.072835578818442, 7.072835578818441),
            (0.75, 3.8282693865222677, 9.242259873359785),
        ] {
            let q = arc.point(&s3, &e3, s);
            assert_abs_diff_eq!(q[0], 100.0 + x, epsilon = TOL);
            assert_abs_diff_eq!(q[1], 50.0 + y, epsilon = TOL);
            assert_abs_diff_eq!(arc.radius_at(&s3, &e3, s), 10.0 + 0.005 * s, epsilon = TOL);
        }
        // The ends are the programmed points.
        assert_abs_diff_eq!(arc.point(&s3, &e3, 0.0)[0], 110.0, epsilon = TOL);
        let end = arc.point(&s3, &e3, 1.0);
        assert_eq!((end[0], end[1]), (100.0, 60.005));
        // Tangent at the start: d/ds of the point is (Δr, r0·sweep) =
        // (0.005, 10·π/2), normalised: (0.000318310, 0.999999949).
        let t = arc.tangent(&s3, &e3, 0.0);
        assert_abs_diff_eq!(t[0], 0.00031830987005802467, epsilon = TOL);
        assert_abs_diff_eq!(t[1], 0.9999999493394119, epsilon = TOL);
        // Length: √((r̄·π/2)² + Δr²) = √((10.0025·π/2)² + 0.005²).
        assert_abs_diff_eq!(mv.length_mm(), 15.711891054341752, epsilon = TOL);
        // Beyond the mismatch limit (0.01 mm + 0.1 % of the radius) the
        // block is refused as before.
        let e = run(&["G90 G54 G0 X10 Y0", "G3 X0 Y10.021 I-10 J0 F100"]).unwrap_err();
        assert!(e.to_string().contains("not on the circle"), "{e}");
    }

    #[test]
    fn arc_with_ij_and_r_agree() {
        // Quarter circle CCW from (10,0) to (0,10) about the origin (program coordinates).
        let a = run(&["G90 G54 G0 X10 Y0", "G3 X0 Y10 I-10 J0 F100"]).unwrap();
        let b = run(&["G90 G54 G0 X10 Y0", "G3 X0 Y10 R10 F100"]).unwrap();
        let ga = a[1].mv.unwrap().arc.unwrap();
        let gb = b[1].mv.unwrap().arc.unwrap();
        // Z was never programmed: it stays at machine zero.
        assert_abs_diff_eq!(ga.center, Vector3::new(100.0, 50.0, 0.0), epsilon = TOL);
        assert_abs_diff_eq!(gb.center, ga.center, epsilon = 1e-6);
        assert_abs_diff_eq!(ga.sweep, std::f64::consts::FRAC_PI_2, epsilon = TOL);
        // Direction at the end of a CCW quarter from +x to +y: moving in −x.
        assert_eq!(a[1].mv.unwrap().dirs[0], -1);
    }

    #[test]
    fn full_circle_and_helix() {
        let p = run(&["G0 X10 Y0 Z0", "G2 I-10 Z-1 F50"]).unwrap();
        let mv = p[1].mv.unwrap();
        let g = mv.arc.unwrap();
        assert_abs_diff_eq!(g.sweep, -std::f64::consts::TAU, epsilon = TOL);
        assert_abs_diff_eq!(mv.end[2], -201.0, epsilon = TOL);
    }

    #[test]
    fn drilling_cycle_points() {
        let p = run(&[
            "G90 G0 X0 Y0 Z50",
            "G99 G81 X10 Y5 Z-3 R2 F80",
            "X20",
            "G80",
        ])
        .unwrap();
        match p[1].kind {
            PlanKind::Cycle {
                r_level,
                bottom,
                retract,
            } => {
                // G54 puts program Z0 at machine Z −200.
                assert_eq!((r_level, bottom, retract), (-198.0, -203.0, -198.0));
            }
            k => panic!("{k:?}"),
        }
        assert_eq!(p[2].mv.unwrap().end[0], 120.0);
        assert_eq!(p[3].kind, PlanKind::Pass);
    }

    #[test]
    fn tool_length_and_refusals() {
        let p = run(&["T1 M6", "G43 H1 G0 Z10"]).unwrap();
        assert_eq!(p[1].mv.unwrap().tool_len_mm, 100.0);
        assert!(run(&["G43 H7 Z1"]).unwrap_err().message.contains("H7"));
        assert!(run(&["G92 X0"]).unwrap_err().message.contains("G92"));
        assert!(
            run(&["M98 P100"])
                .unwrap_err()
                .message
                .contains("subprogram")
        );
        assert!(
            run(&["G68 X0 Y0 R45"])
                .unwrap_err()
                .message
                .contains("rotation")
        );
        assert!(
            run(&["G0 X0 Y0", "G2 X5 Y0 I1 J0"])
                .unwrap_err()
                .message
                .contains("not on the circle")
        );
        assert!(run(&["G0 B10"]).unwrap_err().message.contains("no B axis"));
    }

    /// The interpreter of [`run`] with `integer_words`, and what it read.
    fn run_integer(words: Option<IntegerWords>, lines: &[&str]) -> (Vec<Plan>, Vec<Warning>) {
        let mut setup = Setup {
            axes: [true, true, true, true, false, true],
            units_default: Some(Units::Mm),
            integer_words: words,
            ..Setup::default()
        };
        setup.work_offsets[0] = Some([0.0; 3]);
        let mut it = Interpreter::new(setup, "t.nc");
        let mut b = Block::default();
        let mut out = vec![];
        for (i, l) in lines.iter().enumerate() {
            parse_line(l.as_bytes(), i + 1, "t.nc", &mut b).expect("syntax");
            // Every other line through the pipeline's in-place reading.
            if i % 2 == 1 {
                it.whole_units(&mut b);
            }
            out.push(it.step(&b, l.as_bytes()).expect("read"));
        }
        (out, it.warnings().to_vec())
    }

    #[test]
    fn words_without_a_point_are_increments_where_the_control_says_so() {
        let lines = [
            "G21 G90 G54 G0 X100 Y50.5 Z-5",
            "G1 X2000 A100 F500",
            "G20 G0 X100",
            "G21 G81 X0 Y0 Z-2000 R1000 K3 F100",
        ];
        let (p, warnings) = run_integer(Some(IntegerWords::Increments), &lines);
        // The first word read in increments names the machine file's key,
        // once.
        assert_eq!(warnings.len(), 1, "{warnings:?}");
        assert_eq!(warnings[0].line, 1);
        assert_eq!(
            warnings[0].message,
            "`X100` has no decimal point: read as 100 increments of 0.001 mm, the machine file's `integer_words: increments`"
        );
        let end = |i: usize| p[i].mv.expect("a move").end;
        // 100 µm, 50.5 mm as written with its point, 5 µm down.
        assert_abs_diff_eq!(end(0)[0], 0.1, epsilon = TOL);
        assert_abs_diff_eq!(end(0)[1], 50.5, epsilon = TOL);
        assert_abs_diff_eq!(end(0)[2], -0.005, epsilon = TOL);
        // 2 mm and 0.1° (the A axis, slot 3).
        assert_abs_diff_eq!(end(1)[0], 2.0, epsilon = TOL);
        assert_abs_diff_eq!(end(1)[3], 0.1, epsilon = TOL);
        // In inches: 0.0100 inch.
        assert_abs_diff_eq!(end(2)[0], 0.254, epsilon = TOL);
        // A cycle's Z and R are lengths, its K a repeat count.
        let PlanKind::Cycle { .. } = p[3].kind else {
            panic!("{:?}", p[3].kind)
        };
        assert_eq!(p[3].extra_repeats, 2);
        assert_abs_diff_eq!(p[3].mv.expect("a hole").end[2], -2.0, epsilon = TOL);
        // The same words read in whole units, as the machine file says.
        let (p, warnings) = run_integer(Some(IntegerWords::Units), &lines[..2]);
        assert!(warnings.is_empty(), "{warnings:?}");
        assert_abs_diff_eq!(p[0].mv.expect("a move").end[0], 100.0, epsilon = TOL);
        // Not said: whole units, and one warning at the first such word.
        let (p, warnings) = run_integer(None, &lines[..2]);
        assert_abs_diff_eq!(p[0].mv.expect("a move").end[0], 100.0, epsilon = TOL);
        assert_eq!(warnings.len(), 1, "{warnings:?}");
        assert_eq!(warnings[0].line, 1);
        assert!(
            warnings[0].message.contains("`X100` has no decimal point"),
            "{warnings:?}"
        );
        // Words with a point, and zeros, need no word on the matter.
        let (_, warnings) = run_integer(None, &["G21 G90 G54 G0 X10. Y0 Z.5"]);
        assert!(warnings.is_empty(), "{warnings:?}");
    }

    #[test]
    fn a_g53_move_down_in_z_is_warned_about_once() {
        let mut setup = Setup {
            axes: [true, true, true, false, false, false],
            units_default: Some(Units::Mm),
            ..Setup::default()
        };
        setup.home = [0.0, 0.0, 500.0, 0.0, 0.0, 0.0];
        let mut it = Interpreter::new(setup, "t.nc");
        let mut b = Block::default();
        for (i, l) in [
            "G21 G53 G0 Z400.",
            "G53 G0 Z0.",
            "G53 G0 Z450.",
            "G53 G0 Z0.",
        ]
        .iter()
        .enumerate()
        {
            parse_line(l.as_bytes(), i + 1, "t.nc", &mut b).expect("syntax");
            it.step(&b, l.as_bytes()).expect("read");
        }
        let w = it.warnings();
        assert_eq!(w.len(), 1, "{w:?}");
        assert_eq!(w[0].line, 1);
        assert!(
            w[0].message
                .starts_with("G53 moves Z down, from machine Z500.000 to Z400.000")
        );
    }

    #[test]
    fn h0_is_a_zero_tool_length() {
        let p = run(&["T1 M6", "G43 H0 G0 Z10"]).unwrap();
        assert_eq!(p[1].mv.unwrap().tool_len_mm, 0.0);
        // Without H and without a tool, there is no length to take.
        assert!(run(&["G43 Z10"]).is_err());
    }

    #[test]
    fn inch_program_scales_to_mm() {
        let p = run(&["G20 G0 X1 Y0 Z0"]).unwrap();
        assert_abs_diff_eq!(p[0].mv.unwrap().end[0], 25.4 + 100.0, epsilon = TOL);
    }
    fn run_setup(setup: Setup, lines: &[&str]) -> Result<Vec<Plan>, Located> {
        let mut it = Interpreter::new(setup, "t.nc");
        let mut b = Block::default();
        let mut out = vec![];
        for (i, l) in lines.iter().enumerate() {
            parse_line(l.as_bytes(), i + 1, "t.nc", &mut b)?;
            out.push(it.step(&b, l.as_bytes())?);
        }
        Ok(out)
    }

    /// The error of the last line of `lines`, which must be refused there.
    fn refused_at_last(lines: &[&str]) -> Located {
        let e = run(lines).expect_err("refused");
        assert_eq!(e.line, lines.len(), "{e}");
        e
    }

    #[test]
    fn codes_with_more_than_a_written_decimal_are_refused_where_they_stand() {
        // Each of these once ran as the nearest tenth: a CCW arc, a feed
        // move, incremental mode, G56.
        for (line, col) in [
            ("G0 X0 Y0 G2.95 X1 I1 F100", 10),
            ("G0.96 X1", 1),
            ("G90.96 X1", 1),
            ("G55.96", 1),
            ("M3.5", 1),
        ] {
            let e = refused_at_last(&["G0 X0", line]);
            assert_eq!(e.column, col, "{line}: {e}");
            assert!(
                e.message.contains("is not a G code") || e.message.contains("is not an M code"),
                "{line}: {e}"
            );
        }
        // Listed codes with their decimals, and zeros after them, are codes.
        let p = run(&["G90.1", "G1.0 X1 F100", "G54.0", "G91.10"]).expect("valid");
        assert_eq!(p[1].mv.map(|m| m.motion), Some(Motion::Linear));
    }

    #[test]
    fn tool_and_offset_numbers_must_be_whole() {
        for (line, what) in [
            ("G43 H1.96 Z10", "tool length offset number"),
            ("G43 H0.96 Z10", "tool length offset number"),
            ("T1.5 M6", "tool number"),
            ("G41 D1.5 X1", "cutter radius offset number"),
        ] {
            let e = refused_at_last(&["G0 X0", line]);
            assert!(e.message.contains(what), "{line}: {e}");
            assert!(e.message.contains("whole number"), "{line}: {e}");
            assert_eq!(e.column, line.find(['H', 'T', 'D']).unwrap() + 1, "{line}");
        }
        let mut setup = Setup {
            axes: [true, true, true, false, false, false],
            units_default: Some(Units::Mm),
            ..Setup::default()
        };
        setup
            .extra_offsets
            .insert("G54.1P1".into(), [1.0, 2.0, 3.0]);
        let e = run_setup(setup, &["G54.1 P1.5"]).expect_err("P not whole");
        assert!(e.message.contains("whole number ≥ 1"), "{e}");
        assert_eq!(e.column, 7);
    }

    #[test]
    fn extended_work_offsets_come_from_the_setup() {
        let mut setup = Setup {
            axes: [true, true, true, false, false, false],
            units_default: Some(Units::Mm),
            ..Setup::default()
        };
        setup
            .extra_offsets
            .insert("G54.1P7".into(), [10.0, 20.0, 30.0]);
        setup
            .extra_offsets
            .insert("G154P1".into(), [-5.0, 0.0, 0.0]);
        setup
            .extra_offsets
            .insert("G154P20".into(), [0.0, -7.0, 0.0]);
        let p = run_setup(
            setup.clone(),
            &[
                "G54.1 P7 G0 X1 Y1 Z1",
                "G154 P1 X1",
                "G110 X2",
                "G129 Y3",
                "G54 X0",
            ],
        )
        .expect("valid");
        assert_eq!(&p[0].mv.unwrap().end[..3], &[11.0, 21.0, 31.0]);
        assert_eq!(p[1].mv.unwrap().end[0], -4.0);
        // G110 is G154 P1, G129 is G154 P20.
        assert_eq!(p[2].mv.unwrap().end[0], -3.0);
        assert_eq!(p[3].mv.unwrap().end[1], -4.0);
        assert_eq!(p[4].mv.unwrap().end[0], 0.0);
        for (line, key) in [
            ("G54.1 P2", "G54.1P2"),
            ("G154 P3", "G154P3"),
            ("G111", "G154P2"),
        ] {
            let e = run_setup(setup.clone(), &[line]).expect_err("not in the setup");
            assert!(e.message.contains(key), "{line}: {e}");
        }
        let e = run_setup(setup, &["G154 G0 X1"]).expect_err("no P");
        assert!(e.message.contains("P word"), "{e}");
    }

    #[test]
    fn g30_returns_to_the_reference_point_of_the_setup() {
        let mut setup = Setup {
            axes: [true, true, true, false, false, false],
            units_default: Some(Units::Mm),
            ..Setup::default()
        };
        let e = run_setup(setup.clone(), &["G91 G30 Z0"]).expect_err("no G30 point");
        assert!(e.message.contains("reference_points_mm"), "{e}");
        setup
            .reference_points
            .insert("G30".into(), [1.0, 2.0, 300.0]);
        setup
            .reference_points
            .insert("G30P3".into(), [5.0, 6.0, 7.0]);
        let p = run_setup(
            setup.clone(),
            &["G0 X10 Y10 Z10", "G91 G30 Z0", "G90 G30 P3 X0 Y0"],
        )
        .expect("valid");
        assert_eq!(p[1].kind, PlanKind::Fixed);
        assert_eq!(&p[1].mv.unwrap().end[..3], &[10.0, 10.0, 300.0]);
        assert_eq!(&p[2].mv.unwrap().end[..3], &[5.0, 6.0, 300.0]);
        let e = run_setup(setup, &["G30 P5 Z0"]).expect_err("P5");
        assert!(e.message.contains("P2, P3 or P4"), "{e}");
    }

    #[test]
    fn a_program_without_units_needs_the_controls_default() {
        let bare = Setup {
            axes: [true, true, true, false, false, false],
            ..Setup::default()
        };
        let e = run_setup(bare.clone(), &["G90 G17", "G0 X1 Y2"]).expect_err("no units");
        assert_eq!((e.line, e.column), (2, 4));
        assert!(e.message.contains("units_default"), "{e}");
        // Units set by the program, or the setup's default, are fine.
        let p = run_setup(bare.clone(), &["G20", "G0 X1"]).expect("G20");
        assert_abs_diff_eq!(p[1].mv.unwrap().end[0], 25.4, epsilon = TOL);
        let inch = Setup {
            units_default: Some(Units::Inch),
            ..bare
        };
        let p = run_setup(inch, &["G0 X1", "G21 G0 X1"]).expect("default inch");
        assert_abs_diff_eq!(p[0].mv.unwrap().end[0], 25.4, epsilon = TOL);
        assert_abs_diff_eq!(p[1].mv.unwrap().end[0], 1.0, epsilon = TOL);
    }

    /// An inch program without G20 on a control whose default is mm: the
    /// first length read in the default names the machine file's key and
    /// the line, once; a program that sets its units hears nothing.
    #[test]
    fn lengths_read_in_the_default_unit_say_so_once() {
        let mm = Setup {
            axes: [true, true, true, false, false, false],
            units_default: Some(Units::Mm),
            ..Setup::default()
        };
        let lines = ["G90 G17", "G0 X1.5 Y0.75", "G1 Z-0.1 F20.", "G0 Z0.5"];
        let mut it = Interpreter::new(mm.clone(), "t.nc");
        let mut b = Block::default();
        for (i, l) in lines.iter().enumerate() {
            parse_line(l.as_bytes(), i + 1, "t.nc", &mut b).expect("syntax");
            it.step(&b, l.as_bytes()).expect("read");
        }
        let w = it.warnings();
        assert_eq!(w.len(), 1, "{w:?}");
        assert_eq!(w[0].line, 2);
        assert_eq!(
            w[0].message,
            "the program sets no units (G20 inch or G21 mm) before `X1.5`: read in mm, the machine file's `units_default: mm` (or --units)"
        );
        let mut it = Interpreter::new(mm, "t.nc");
        for (i, l) in ["G20 G90", "G0 X1.5"].iter().enumerate() {
            parse_line(l.as_bytes(), i + 1, "t.nc", &mut b).expect("syntax");
            it.step(&b, l.as_bytes()).expect("read");
        }
        assert!(it.warnings().is_empty(), "{:?}", it.warnings());
    }

    #[test]
    fn geometry_neutral_modes_pass_with_their_words() {
        let p = run(&[
            "G187 P1 E0.005",
            "G05 P10000",
            "G05.1 Q1 R5",
            "G08 P1",
            "G61.1",
            "G64 P0.01 Q0.01",
            "G103 P1",
            "G67",
            "G0 X1 Y1",
            "G61",
            "G1 X2 F100",
        ])
        .expect("valid");
        assert!(
            p[..8]
                .iter()
                .all(|p| p.kind == PlanKind::Pass && p.mv.is_none())
        );
        assert_eq!(p[10].mv.unwrap().end[0], 102.0);
    }

    #[test]
    fn splines_are_refused() {
        for (line, what) in [
            ("G5 I1 J1 P2 Q2 X5 Y5", "G5 (cubic spline)"),
            ("G5 P1 Q1", "G5 (cubic spline)"),
            ("G5.1 X5 Y5 I1 J1", "G5.1 (quadratic spline)"),
            ("G5.2 X1 Y1 P1 L3", "NURBS"),
            ("G6.2 X1 Y1 P1 K0", "NURBS"),
        ] {
            let e = refused_at_last(&["G0 X0 Y0", line]);
            assert!(e.message.contains(what), "{line}: {e}");
            assert_eq!(e.column, 1, "{line}");
        }
    }

    #[test]
    fn repeats_of_the_same_path_are_kept_and_counted() {
        let p = run(&[
            "G0 X0 Y0 Z5",
            "G99 G81 X10 Y5 Z-3 R2 F80 L3",
            "G80",
            "G0 X10 Y0",
            "G2 I-10 F100 L4",
            "G1 X20 L2",
        ])
        .expect("valid");
        assert_eq!(p[1].extra_repeats, 2);
        assert_eq!(p[4].extra_repeats, 3);
        assert_eq!(p[5].extra_repeats, 0);
        assert_eq!(p[5].mv.unwrap().end[0], 120.0);
        for lines in [
            &["G0 X0 Y0 Z5", "G91 G81 X10 Z-3 R-3 F80 L3"][..],
            &["G0 X0 Y0 Z5", "G91 G1 X1 F100 L5"][..],
            &["G0 X0 Y0 Z5", "G1 X1 F100 L0"][..],
        ] {
            let e = refused_at_last(lines);
            assert!(e.message.contains("repeat count"), "{lines:?}: {e}");
        }
    }

    #[test]
    fn other_dialects_are_named() {
        for (line, dialect) in [
            ("DEF REAL DEPTH=5", "Siemens"),
            ("N10 R1=5", "Siemens"),
            ("CYCLE81(10,0,2,-5)", "Siemens"),
            ("0 BEGIN PGM PART MM", "Heidenhain"),
            ("5 L X+10 Y+5 R0 FMAX", "Heidenhain"),
            ("G1 U-1.5 F0.2", "lathe"),
        ] {
            let e = run(&[line]).expect_err("other dialect");
            assert!(e.message.contains(dialect), "{line}: {e}");
            assert!(e.message.contains("not supported"), "{line}: {e}");
        }
        let e = refused_at_last(&["G0 X0", "G71 P10 Q20 U0.5 W0.1 F0.2"]);
        assert!(e.message.contains("lathe"), "{e}");
        let e = refused_at_last(&["G0 X0", "G71 P10 Q20 D1. F0.2"]);
        assert!(e.message.contains("lathe"), "{e}");
    }

    #[test]
    fn tool_centre_point_control_takes_tips_and_refuses_orientation_vectors() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/machines/five-axis-ac.yaml");
        let text = std::fs::read_to_string(path).unwrap_or_default();
        let m = crate::machine::tool::testing::load(&text, "ac");
        let setup = Setup::for_machine(&m);
        let p = run_setup(
            setup.clone(),
            &["G90 G21 G54 G43.4 H1 G0 X10 Y20 Z30 A30 C45", "G49 G0 Z50"],
        )
        .expect("valid");
        // The axis positions put the nominal tip on the programmed one.
        let mv = p[0].mv.unwrap();
        assert!(p[0].tcpm && !p[1].tcpm);
        let tip = m.tip_of(&mv.end, mv.tool_len_mm);
        let g54 = m.work_offset_mm("G54").unwrap();
        for (k, want) in [10.0, 20.0, 30.0].iter().enumerate() {
            assert_abs_diff_eq!(tip[k], want + g54[k], epsilon = 1e-9);
        }
        assert!((mv.end[1] - (20.0 + g54[1])).abs() > 1.0, "A30 moves Y");
        let e = run_setup(
            setup.clone(),
            &["G90 G21 G43.5 H1 G1 X10 Y20 Z30 I0 J0.5 K0.866 F100"],
        )
        .expect_err("orientation vector");
        assert!(e.message.contains("orientation vectors"), "{e}");
        assert_eq!(e.column, 33);
        let e =
            run_setup(setup, &["G21 G43.4 H1 G0 X0 Y0 Z0", "G2 X1 Y1 R1 F100"]).expect_err("arc");
        assert!(e.message.contains("arcs under G43.4"), "{e}");
        let e = run(&["G43.4 H1"]).expect_err("no kinematics");
        assert!(e.message.contains("kinematics"), "{e}");
    }
}
