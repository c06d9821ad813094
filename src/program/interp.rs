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

use nalgebra::Vector3;

use crate::error::Located;
use crate::machine::{AxisVec, DirVec, axis_slot};
use crate::program::gcode::{Block, Word};

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
const MODAL_GROUPS: usize = 8;

/// The modal group of a G code (code × 10) whose members exclude each other
/// within one block, other than the motion group (checked on its own): plane,
/// distance mode, arc distance mode, units, work offset, cutter compensation,
/// tool length offset, canned-cycle return level.
fn modal_group(code: i64) -> Option<usize> {
    Some(match code {
        170 | 180 | 190 => 0,
        900 | 910 => 1,
        901 | 911 => 2,
        200 | 210 => 3,
        540 | 550 | 560 | 570 | 580 | 590 => 4,
        400 | 410 | 420 => 5,
        430 | 490 => 6,
        980 | 990 => 7,
        _ => return None,
    })
}

/// Below this an axis is considered not to move, mm or deg.
pub const MOTION_EPS: f64 = 1e-9;

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
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArcGeom {
    /// The plane of the arc.
    pub plane: Plane,
    /// Centre (the normal-axis component equals the start's).
    pub center: Vector3<f64>,
    /// Signed swept angle, rad (positive counter-clockwise about the normal).
    pub sweep: f64,
    /// Radius, mm.
    pub radius: f64,
}

impl ArcGeom {
    /// Point on the arc (helix) at parameter `s` in [0, 1] from `start` to `end`.
    pub fn point(&self, start: &Vector3<f64>, end: &Vector3<f64>, s: f64) -> Vector3<f64> {
        let (a, b, n) = self.plane.axes();
        let a0 = start[a] - self.center[a];
        let b0 = start[b] - self.center[b];
        let ang = b0.atan2(a0) + self.sweep * s;
        let mut p = Vector3::zeros();
        p[a] = self.center[a] + self.radius * ang.cos();
        p[b] = self.center[b] + self.radius * ang.sin();
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
        let mut t = Vector3::zeros();
        t[a] = -ang.sin() * self.radius * self.sweep;
        t[b] = ang.cos() * self.radius * self.sweep;
        t[n] = end[n] - start[n];
        let norm = t.norm();
        if norm > 0.0 { t / norm } else { t }
    }

    /// Path length of the arc (helix), mm.
    pub fn length(&self, start: &Vector3<f64>, end: &Vector3<f64>) -> f64 {
        let (_, _, n) = self.plane.axes();
        (self.radius * self.sweep).hypot(end[n] - start[n])
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
    inch: bool,
    work: usize,
    tool_len_mm: f64,
    h_active: Option<u32>,
    retract_initial: bool,
    cycle_r: Option<f64>,
    cycle_z: Option<f64>,
    cycle_initial: f64,
    feed: f64,
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
    comp_warned: bool,
    /// G41/G42 may be active with the block-delete switch in either
    /// position: set by G41/G42 on any line, cleared by G40 on a line
    /// without `/`.
    cutter_comp: bool,
}

const MAX_WARNINGS: usize = 64;

impl Interpreter {
    /// A controller in its power-on state: G0 G17 G90 G91.1 G21 G54 G49 G98,
    /// tool tip at the reference position, every axis last moved in the +
    /// direction.
    pub fn new(setup: Setup, file: &str) -> Self {
        let home = setup.home;
        Interpreter {
            setup,
            file: file.to_string(),
            motion: None,
            cycle: None,
            plane: Plane::XY,
            absolute: true,
            arc_absolute: false,
            inch: false,
            work: 0,
            tool_len_mm: 0.0,
            h_active: None,
            retract_initial: true,
            cycle_r: None,
            cycle_z: None,
            cycle_initial: 0.0,
            feed: 0.0,
            per_rev: false,
            spindle: 0.0,
            spindle_on: false,
            milling_mm: [None; 2],
            tool_selected: 0,
            tool_active: 0,
            pos: home,
            dirs: [1; 6],
            warnings: Vec::new(),
            comp_warned: false,
            cutter_comp: false,
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
        self.inch
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
            });
        }
    }

    fn err(&self, line: usize, w: Option<&Word>, msg: String) -> Located {
        Located::new(&self.file, line, w.map_or(1, |w| w.start as usize + 1), msg)
    }

    fn offset(&self) -> AxisVec {
        let wo = self.setup.work_offsets[self.work].unwrap_or([0.0; 3]);
        [wo[0], wo[1], wo[2], 0.0, 0.0, 0.0]
    }

    fn scale(&self) -> f64 {
        if self.inch { MM_PER_INCH } else { 1.0 }
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
        let before = self.cutter_comp;
        let done = self.step_block(block, text, plan);
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
        let line = block.line_no;
        *plan = Plan {
            scale: self.scale(),
            absolute: self.absolute,
            arc_absolute: self.arc_absolute,
            offset: self.offset(),
            milling_mm: self.milling_mm,
            ..Plan::default()
        };
        if block.is_empty() || block.block_delete && block.words.is_empty() {
            if !block.block_delete {
                self.directives(block, text)?;
                plan.milling_mm = self.milling_mm;
            }
            return Ok(());
        }
        let quote = |w: &Word| {
            String::from_utf8_lossy(text.get(w.start as usize..w.end as usize).unwrap_or(b""))
                .to_string()
        };

        // Gather the block's words.
        let mut axis: [Option<&Word>; 6] = [None; 6];
        let mut center: [Option<&Word>; 3] = [None; 3];
        let mut r_word = None;
        let mut motion_g: Option<&Word> = None;
        let mut non_modal: Option<&Word> = None;
        let mut h_word = None;
        let mut p_word = None;
        let mut groups: [Option<&Word>; MODAL_GROUPS] = [None; MODAL_GROUPS];
        let mut spindle_m: Option<&Word> = None;
        for w in &block.words {
            match w.letter {
                b'X' | b'Y' | b'Z' | b'A' | b'B' | b'C' => {
                    let slot = axis_slot(w.letter).unwrap_or(0);
                    if axis[slot].is_some() {
                        return Err(self.err(
                            line,
                            Some(w),
                            format!("axis word `{}` given twice in one block", quote(w)),
                        ));
                    }
                    if !self.setup.axes[slot] {
                        return Err(self.err(
                            line,
                            Some(w),
                            format!(
                                "the machine has no {} axis: `{}`",
                                w.letter as char,
                                quote(w)
                            ),
                        ));
                    }
                    axis[slot] = Some(w);
                }
                b'I' | b'J' | b'K' => center[(w.letter - b'I') as usize] = Some(w),
                b'R' => r_word = Some(w),
                b'H' => h_word = Some(w),
                b'P' => p_word = Some(w),
                b'F' => {
                    if w.value < 0.0 {
                        return Err(self.err(
                            line,
                            Some(w),
                            format!("negative feed `{}`", quote(w)),
                        ));
                    }
                    if let Some((max, unit)) =
                        crate::process::limits::feed_limit(w.value * self.scale(), self.per_rev)
                    {
                        return Err(self.err(
                            line,
                            Some(w),
                            format!("feed above {max} {unit}: `{}`", quote(w)),
                        ));
                    }
                    self.feed = w.value;
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
                    self.spindle = w.value;
                }
                b'T' => {
                    if w.value < 0.0 || w.value.fract() != 0.0 {
                        return Err(self.err(
                            line,
                            Some(w),
                            format!("tool number must be a whole number ≥ 0: `{}`", quote(w)),
                        ));
                    }
                    self.tool_selected = w.value as u32;
                }
                b'L' if w.value != 1.0 => {
                    return Err(self.err(line, Some(w), format!("repeat counts cannot be compensated offline (expand them in CAM): `{}`", quote(w))));
                }
                b'M' => match w.code10() {
                    60 => self.tool_active = self.tool_selected,
                    30 | 40 | 50 if spindle_m.is_some() => {
                        return Err(self.err(
                            line,
                            Some(w),
                            format!(
                                "`{}` and `{}` both set the spindle in one block",
                                spindle_m.map(&quote).unwrap_or_default(),
                                quote(w)
                            ),
                        ));
                    }
                    30 | 40 => {
                        spindle_m = Some(w);
                        self.spindle_on = true;
                    }
                    50 => {
                        spindle_m = Some(w);
                        self.spindle_on = false;
                    }
                    20 | 300 => self.spindle_on = false,
                    980 | 990 | 970 | 1980 => {
                        return Err(self.err(line, Some(w), format!("subprogram calls cannot be compensated offline (expand them in CAM): `{}`", quote(w))));
                    }
                    _ => {}
                },
                b'G' => {
                    let code = w.code10();
                    if let Some(g) = modal_group(code) {
                        if let Some(first) = groups[g] {
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
                        groups[g] = Some(w);
                    }
                    match code {
                        0 | 10 | 20 | 30 => {
                            if motion_g.is_some() {
                                return Err(self.err(
                                    line,
                                    Some(w),
                                    format!("two motion codes in one block: `{}`", quote(w)),
                                ));
                            }
                            motion_g = Some(w);
                        }
                        730 | 810 | 820 | 830 | 840 | 850 | 860 | 870 | 880 | 890 => {
                            motion_g = Some(w);
                        }
                        800 => {
                            self.cycle = None;
                            self.cycle_r = None;
                            self.cycle_z = None;
                            if self.motion.is_none() {
                                self.motion = Some(Motion::Rapid);
                            }
                        }
                        40 | 280 | 530 | 90 => non_modal = Some(w),
                        170 => self.plane = Plane::XY,
                        180 => self.plane = Plane::ZX,
                        190 => self.plane = Plane::YZ,
                        200 => self.inch = true,
                        210 => self.inch = false,
                        900 => self.absolute = true,
                        910 => self.absolute = false,
                        901 => self.arc_absolute = true,
                        911 => self.arc_absolute = false,
                        540..=590 if code % 10 == 0 => self.work = ((code - 540) / 10) as usize,
                        400 if !block.block_delete => self.cutter_comp = false,
                        400 => {}
                        410 | 420 => {
                            self.cutter_comp = true;
                            if !self.comp_warned {
                                self.comp_warned = true;
                                self.warn(line, "cutter radius compensation (G41/G42) is passed through: deviations are evaluated on the programmed path, not the offset path, and no takeup points are written while it is active (a short move against the direction of travel would upset the controller's offset path)".into());
                            }
                        }
                        430 => h_word = h_word.or(Some(w)),
                        490 => {
                            self.tool_len_mm = 0.0;
                            self.h_active = None;
                        }
                        980 => self.retract_initial = true,
                        990 => self.retract_initial = false,
                        940 => self.per_rev = false,
                        950 => self.per_rev = true,
                        // Harmless modes: exact stop, path control, AI contour,
                        // polar/rotation/scaling cancel, spindle speed modes.
                        610 | 640 | 51 | 150 | 690 | 500 | 501 | 960 | 970 => {}
                        _ => {
                            let what = match code {
                                100 => "G10 (programmable data input)",
                                920 => "G92 (coordinate system shift)",
                                520 => "G52 (local coordinate system)",
                                680 | 682 | 684 => "G68 (coordinate rotation)",
                                510 | 511 => "G51 (scaling/mirroring)",
                                160 => "G16 (polar coordinates)",
                                650 | 660 | 661 | 670 => "G65/G66 (macro calls)",
                                434 | 435 => "G43.4/G43.5 (tool centre point control)",
                                _ => "this G code",
                            };
                            return Err(self.err(
                                line,
                                Some(w),
                                format!("{what} cannot be compensated offline: `{}`", quote(w)),
                            ));
                        }
                    }
                }
                _ => {}
            }
        }
        // G43 tool length.
        if block
            .words
            .iter()
            .any(|w| w.letter == b'G' && w.code10() == 430)
        {
            let h = match h_word {
                Some(hw) if hw.letter == b'H' => hw.value.max(0.0) as u32,
                _ => self.tool_active.max(self.tool_selected),
            };
            match self.setup.tools.get(&h) {
                Some(&len) => {
                    self.tool_len_mm = len;
                    self.h_active = Some(h);
                }
                None => {
                    let at = block.words.iter().find(|w| w.letter == b'H');
                    return Err(self.err(line, at, format!("tool length offset H{h} is not in the tool table (machine file `tools`, or --tool H{h}=LENGTH)")));
                }
            }
        }
        plan.scale = self.scale();
        self.directives(block, text)?;
        plan.milling_mm = self.milling_mm;
        plan.absolute = self.absolute;
        plan.arc_absolute = self.arc_absolute;
        plan.offset = self.offset();
        plan.programmed = programmed_axes(&axis);

        // Non-modal codes.
        if let Some(w) = non_modal {
            match w.code10() {
                40 => {
                    // Dwell: P in ms (integer) / s (with point), or X in s.
                    let (word, dwell_s) = match (p_word, axis[0]) {
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
                                word.map(&quote).unwrap_or_default()
                            ),
                        ));
                    }
                    plan.dwell_s = dwell_s;
                    return Ok(());
                }
                90 => {}
                280 => {
                    // A motion code written with G28 stays modal (`G0 G28 G91 Z0.`).
                    if let Some(g) = motion_g {
                        self.set_motion_mode(g);
                    }
                    return self.reference_return(block, &axis, plan, line);
                }
                530 => return self.machine_move(block, &axis, plan, motion_g, line),
                _ => {}
            }
        }

        if let Some(g) = motion_g {
            match g.code10() {
                0 => {
                    self.motion = Some(Motion::Rapid);
                    self.cycle = None;
                }
                10 => {
                    self.motion = Some(Motion::Linear);
                    self.cycle = None;
                }
                20 => {
                    self.motion = Some(Motion::ArcCw);
                    self.cycle = None;
                }
                30 => {
                    self.motion = Some(Motion::ArcCcw);
                    self.cycle = None;
                }
                code => {
                    if self.plane != Plane::XY {
                        return Err(self.err(
                            line,
                            Some(g),
                            format!(
                                "canned cycles are supported in the G17 plane only: `{}`",
                                quote(g)
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
        let any_axis = axis.iter().any(|a| a.is_some());
        if self.cycle.is_some() {
            if let Some(r) = r_word {
                self.cycle_r = Some(r.value);
            }
            if let Some(z) = axis[2] {
                self.cycle_z = Some(z.value);
            }
            if any_axis {
                return self.cycle_hole(block, &axis, plan, line, text);
            }
            return Ok(());
        }
        if !any_axis {
            if let Some(g) = motion_g {
                if matches!(g.code10(), 20 | 30) && center.iter().any(|c| c.is_some()) {
                    // A full circle written without end coordinates.
                } else {
                    return Ok(());
                }
            } else {
                return Ok(());
            }
        }
        let motion = match self.motion {
            Some(m) => m,
            None => {
                let first = axis.iter().flatten().next().copied();
                return Err(self.err(
                    line,
                    first,
                    "axis words before any motion mode (G0/G1/G2/G3) was set".into(),
                ));
            }
        };
        let end = self.target(&axis, plan.scale, &plan.offset);
        let start = self.pos;
        let arc = match motion {
            Motion::ArcCw | Motion::ArcCcw => Some(self.arc(
                block, &start, &end, &center, r_word, p_word, motion, line, text,
            )?),
            _ => None,
        };
        for (slot, a) in axis.iter().enumerate() {
            if let Some(w) = a {
                if !end[slot].is_finite() {
                    return Err(self.err(
                        line,
                        Some(w),
                        format!("coordinate out of range: `{}`", quote(w)),
                    ));
                }
            }
        }
        if motion != Motion::Rapid && end != start {
            self.require_feed(line, block.words.iter().find(|w| w.letter == b'F'))?;
        }
        let mv = self.make_move(motion, start, end, arc);
        plan.kind = PlanKind::Motion;
        plan.mv = Some(mv);
        Ok(())
    }

    /// Reads `(POSTPROC MILLING DEPTH=d WIDTH=w)` directive comments (values
    /// in program units, either key optional; modal until the next one).
    fn directives(&mut self, block: &Block, text: &[u8]) -> Result<(), Located> {
        for c in &block.comments {
            let raw = text.get(c.start as usize..c.end as usize).unwrap_or(b"");
            let body = String::from_utf8_lossy(raw);
            let body = body.trim_start_matches(['(', ';']).trim_end_matches(')');
            let mut tokens = body.split_whitespace();
            // Only `POSTPROC MILLING …` is a directive; any other comment
            // (including other text after POSTPROC) is left alone.
            match (tokens.next(), tokens.next()) {
                (Some(a), Some(b))
                    if a.eq_ignore_ascii_case("POSTPROC") && b.eq_ignore_ascii_case("MILLING") => {}
                _ => continue,
            }
            let at =
                |msg: String| Located::new(&self.file, block.line_no, c.start as usize + 1, msg);
            let mut any = false;
            for t in tokens {
                let (k, v) = t.split_once('=').ok_or_else(|| {
                    at(format!(
                        "expected KEY=VALUE, found `{t}` in `{}`",
                        body.trim()
                    ))
                })?;
                let slot = if k.eq_ignore_ascii_case("DEPTH") {
                    0
                } else if k.eq_ignore_ascii_case("WIDTH") {
                    1
                } else {
                    return Err(at(format!(
                        "unknown key `{k}` in `{}` (expected DEPTH or WIDTH)",
                        body.trim()
                    )));
                };
                let x: f64 = v
                    .parse()
                    .ok()
                    .filter(|x: &f64| x.is_finite() && *x >= 0.0)
                    .ok_or_else(|| at(format!("`{t}`: the value must be a length of 0 or more")))?;
                let scale = self.scale();
                let max = crate::process::limits::CUT_MAX_MM;
                if x * scale > max {
                    return Err(at(format!("`{t}`: more than {max} mm of cut")));
                }
                if let Some(m) = self.milling_mm.get_mut(slot) {
                    *m = Some(x * scale);
                }
                any = true;
            }
            if !any {
                return Err(at(format!(
                    "`{}` sets nothing (expected DEPTH=… and/or WIDTH=…)",
                    body.trim()
                )));
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
        let mut dirs = self.dirs;
        match &arc {
            Some(g) => {
                let s3 = Vector3::new(start[0], start[1], start[2]);
                let e3 = Vector3::new(end[0], end[1], end[2]);
                // Just before the end: at a quadrant point one component of
                // the tangent vanishes, and the axis still moved the way it
                // was going.
                let t = g.tangent(&s3, &e3, END_INSIDE);
                for i in 0..3 {
                    if t[i].abs() > 1e-12 {
                        dirs[i] = if t[i] > 0.0 { 1 } else { -1 };
                    }
                }
                for i in 3..6 {
                    let d = end[i] - start[i];
                    if d.abs() > MOTION_EPS {
                        dirs[i] = if d > 0.0 { 1 } else { -1 };
                    }
                }
            }
            None => {
                for i in 0..6 {
                    let d = end[i] - start[i];
                    if d.abs() > MOTION_EPS {
                        dirs[i] = if d > 0.0 { 1 } else { -1 };
                    }
                }
            }
        }
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

    /// Machine coordinates of the block's end point.
    fn target(&self, axis: &[Option<&Word>; 6], scale: f64, offset: &AxisVec) -> AxisVec {
        let mut end = self.pos;
        for (slot, a) in axis.iter().enumerate() {
            if let Some(w) = a {
                let s = if slot < 3 { scale } else { 1.0 };
                end[slot] = if self.absolute {
                    w.value * s + offset[slot]
                } else {
                    self.pos[slot] + w.value * s
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
        axis: &[Option<&Word>; 6],
        plan: &mut Plan,
        line: usize,
        text: &[u8],
    ) -> Result<(), Located> {
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
        if block
            .words
            .iter()
            .any(|w| w.letter == b'K' && w.value != 1.0)
            && self.cycle.is_some()
        {
            let k = block.words.iter().find(|w| w.letter == b'K');
            return Err(self.err(
                line,
                k,
                "repeat counts cannot be compensated offline (expand them in CAM)".into(),
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
        Ok(())
    }

    fn reference_return(
        &mut self,
        _block: &Block,
        axis: &[Option<&Word>; 6],
        plan: &mut Plan,
        _line: usize,
    ) -> Result<(), Located> {
        // Through the intermediate point to the reference position (machine zero).
        let mid = self.target(axis, plan.scale, &plan.offset);
        let start = self.pos;
        self.make_move(Motion::Rapid, start, mid, None);
        let mut home = mid;
        for (slot, a) in axis.iter().enumerate() {
            if a.is_some() {
                home[slot] = self.setup.home[slot];
            }
        }
        let mv = self.make_move(Motion::Rapid, mid, home, None);
        plan.kind = PlanKind::Fixed;
        plan.mv = Some(mv);
        Ok(())
    }

    fn machine_move(
        &mut self,
        _block: &Block,
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
        let mv = self.make_move(Motion::Rapid, self.pos, end, None);
        plan.kind = PlanKind::Fixed;
        plan.mv = Some(mv);
        Ok(())
    }
}

/// The axis slots a block gives words for, one bit each.
fn programmed_axes(axis: &[Option<&Word>; 6]) -> u8 {
    axis.iter()
        .enumerate()
        .filter(|(_, a)| a.is_some())
        .fold(0u8, |m, (i, _)| m | (1 << i))
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

    #[test]
    fn inch_program_scales_to_mm() {
        let p = run(&["G20 G0 X1 Y0 Z0"]).unwrap();
        assert_abs_diff_eq!(p[0].mv.unwrap().end[0], 25.4 + 100.0, epsilon = TOL);
    }
}
