//! The G-code pipeline: streams a program through parse → interpret →
//! predict/compensate → emit in bounded chunks.
//!
//! Lines are read in chunks of [`CHUNK_LINES`]; parsing runs on the rayon
//! pool, the modal interpretation in program order on the calling thread,
//! the per-block prediction and inverse solve in parallel on the pool
//! (order kept; runs of [`GROUP_BLOCKS`] blocks in order per task, cut at
//! fixed blocks so that the output is the same for any thread count), and
//! the emitter formats a chunk on the pool (one task per chunk, in order)
//! while the calling thread interprets a later one, then writes its bytes
//! out. Memory is bounded by the chunk size, whatever the length of the
//! program.

use std::io::{BufRead, Write};

use rayon::prelude::*;

use crate::compensate::outcome::{Row, Summary};
use crate::compensate::{self, BlockResult, Failure, Settings};
use crate::emit::gcode::{EmitOptions, Emitter, rotary_rounding_mm, rounding_mm};
use crate::error::{Error, Located, Result};
use nalgebra::Vector3;

use crate::machine::AxisVec;
use crate::machine::ThermalStart;
use crate::machine::tool::thermal::Powers;
use crate::machine::tool::{MachineTool, Modal, Thermal, ThermalState};
use crate::pipeline::resonance::ResonanceWatch;
use crate::predict::{Effect, MoveContext, ThermalInput, ToolPredictor, Wrench, WrenchFrame};
use crate::process::modal::harmonic_amplitude;
use crate::process::{CutState, ForceModel, MillingCache};
use crate::program::gcode::{Block, parse_line};
use crate::program::interp::{END_INSIDE, Interpreter, Motion, Plan, PlanKind, Setup, Warning};

/// Lines processed per chunk.
pub const CHUNK_LINES: usize = 4096;

/// Blocks compensated in order on one thread, within a chunk.
pub const GROUP_BLOCKS: usize = 64;

/// A configured job.
pub struct Job<'m> {
    /// Predictor (machine + effects); `None` only parses and interprets.
    pub predictor: Option<ToolPredictor<'m>>,
    /// Tool table, work offsets and axes.
    pub setup: Setup,
    /// Compensation settings.
    pub settings: Settings,
    /// Output options.
    pub emit: EmitOptions,
    /// Worker threads for the per-block prediction (rayon's global pool when `None`).
    pub pool: Option<&'m rayon::ThreadPool>,
    /// A machine whose travel every programmed position must keep to, for
    /// runs without a predictor (`check --machine`); a compensation checks
    /// the travel as it solves.
    pub travel: Option<&'m MachineTool>,
}

/// The in-order pass of the process effects: puts the program on a time
/// line, predicts the process force, integrates the thermal state and the
/// vibration amplitude, and hands each block its [`MoveContext`].
struct Tracker<'a> {
    machine: &'a MachineTool,
    force: Option<&'a ForceModel>,
    table: Option<&'a crate::process::ForceTable>,
    thermal: Option<&'a Thermal>,
    modal: Option<&'a Modal>,
    depth_mm: Option<f64>,
    width_mm: Option<f64>,
    cache: MillingCache,
    state: ThermalState,
    time_s: f64,
    energy_j: Powers,
    pos: Option<AxisVec>,
    rpm: f64,
    resonance: ResonanceWatch,
    /// The dynamic effect is on: moves are checked for resonance.
    dynamic: bool,
    active: bool,
}

/// Rapid-traverse time between two commands (each axis at its own rate), s.
fn rapid_time_s(m: &MachineTool, a: &AxisVec, b: &AxisVec) -> f64 {
    (0..6)
        .map(|s| (b[s] - a[s]).abs() / m.rapid_per_min(s) * 60.0)
        .fold(0.0, f64::max)
}

fn axis_speed(a: &AxisVec, b: &AxisVec, dt_s: f64) -> Vector3<f64> {
    if dt_s <= 0.0 {
        return Vector3::zeros();
    }
    Vector3::new(b[0] - a[0], b[1] - a[1], b[2] - a[2]) * (60.0 / dt_s)
}

impl<'a> Tracker<'a> {
    fn new(pred: &ToolPredictor<'a>, cold: bool) -> Self {
        let m = pred.machine;
        let force = match pred.process {
            Some(p) => p.force.as_ref(),
            None => m.process_force(),
        };
        let e = pred.effects;
        let thermal = m.thermal();
        let mut state = ThermalState::default();
        if let (Some(t), Some(p), false) = (thermal, pred.process, cold) {
            let mean = p.mean_power_w.unwrap_or([0.0; 4]);
            state = match p.thermal_start {
                ThermalStart::Cold => state,
                ThermalStart::Steady => t.warm_up(&mean, f64::INFINITY),
                ThermalStart::WarmUpMin(min) => t.warm_up(&mean, min),
            };
        }
        let active = (force.is_some()
            && (e.gain(Effect::Static) != 0.0
                || e.gain(Effect::Dynamic) != 0.0
                || e.gain(Effect::Thermal) != 0.0))
            || (thermal.is_some() && e.gain(Effect::Thermal) != 0.0);
        Tracker {
            machine: m,
            force,
            table: pred.process.and_then(|p| p.force_table.as_ref()),
            thermal,
            modal: m.modal(),
            depth_mm: pred.process.and_then(|p| p.milling_depth_mm),
            width_mm: pred.process.and_then(|p| p.milling_width_mm),
            cache: MillingCache::default(),
            state,
            time_s: 0.0,
            energy_j: [0.0; 4],
            pos: None,
            rpm: 0.0,
            resonance: ResonanceWatch::default(),
            dynamic: e.gain(Effect::Dynamic) != 0.0,
            active,
        }
    }

    /// Lets `dt_s` pass with the given process load and axis speeds.
    fn phase(&mut self, dt_s: f64, force: &Vector3<f64>, cut_w: f64, speed: &Vector3<f64>) {
        if dt_s <= 0.0 || !dt_s.is_finite() {
            return;
        }
        self.time_s += dt_s;
        if let Some(t) = self.thermal {
            let p = t.powers(self.rpm, cut_w, force, speed);
            for (e, p) in self.energy_j.iter_mut().zip(p) {
                *e += p * dt_s;
            }
            self.state = t.step(&self.state, &p, dt_s);
        }
    }

    /// Mean power of each heat source so far, W.
    fn mean_power(&self) -> Powers {
        if self.time_s <= 0.0 {
            return [0.0; 4];
        }
        self.energy_j.map(|e| e / self.time_s)
    }

    fn context(&self) -> MoveContext {
        MoveContext {
            time_s: self.time_s,
            thermal: ThermalInput::Tool(self.state),
            spindle_rpm: self.rpm,
            ..MoveContext::default()
        }
    }

    /// Advances over one block and returns its context.
    fn advance(&mut self, plan: &Plan, spindle_rpm: f64, line: usize) -> MoveContext {
        if !self.active {
            return MoveContext::default();
        }
        self.rpm = spindle_rpm;
        let Some(mv) = plan.mv else {
            if plan.dwell_s > 0.0 {
                self.phase(plan.dwell_s, &Vector3::zeros(), 0.0, &Vector3::zeros());
            }
            return self.context();
        };
        self.rpm = mv.spindle_rpm;
        let m = self.machine;
        let prev = self.pos.unwrap_or(mv.start);
        // Positioning before a canned-cycle hole: over the hole at the
        // current height, then down to the R level.
        if let PlanKind::Cycle { .. } = plan.kind {
            let mut above = mv.start;
            above[2] = prev[2];
            for (a, b) in [(prev, above), (above, mv.start)] {
                let dt = rapid_time_s(m, &a, &b);
                self.phase(dt, &Vector3::zeros(), 0.0, &axis_speed(&a, &b, dt));
            }
        }
        let cutting = mv.motion != Motion::Rapid && plan.kind != PlanKind::Fixed;
        let mut ctx_force = Vector3::zeros();
        let mut tooth_hz = 0.0;
        let mut vibration = Vector3::zeros();
        if cutting {
            let s3 = mv.start3();
            let e3 = mv.end3();
            let feed_dir = match &mv.arc {
                Some(arc) => arc.tangent(&s3, &e3, END_INSIDE),
                None => (e3 - s3)
                    .try_normalize(1e-12)
                    .unwrap_or_else(Vector3::zeros),
            };
            let mut load = crate::process::ProcessLoad::default();
            if let Some(f) = self.force {
                let tool_axis = m.nominal(&mv.end, mv.tool_len_mm).dir;
                let drilling = matches!(plan.kind, PlanKind::Cycle { .. })
                    || (mv.arc.is_none()
                        && feed_dir.dot(&tool_axis) < -crate::process::AXIAL_FEED_RAD.cos());
                let state = CutState {
                    line,
                    cutting,
                    drilling,
                    feed_dir,
                    tool_axis,
                    feed_mm_min: mv.feed_mm_min,
                    spindle_rpm: mv.spindle_rpm,
                    depth_mm: plan.milling_mm[0].or(self.depth_mm),
                    width_mm: plan.milling_mm[1].or(self.width_mm),
                };
                load = f.load(&state, &mut self.cache, self.table);
            }
            let len = mv.length_mm();
            let len = if len > 1e-9 {
                len
            } else {
                (3..6)
                    .map(|s| (mv.end[s] - mv.start[s]).abs())
                    .fold(0.0, f64::max)
            };
            // A repeat count runs the same path again (`Plan::extra_repeats`).
            let dt = if mv.feed_mm_min > 0.0 {
                len / mv.feed_mm_min * 60.0 * f64::from(1 + plan.extra_repeats)
            } else {
                0.0
            };
            self.phase(
                dt,
                &load.force_n,
                load.cutting_power_w,
                &axis_speed(&mv.start, &mv.end, dt),
            );
            ctx_force = load.force_n;
            tooth_hz = load.tooth_hz;
            if let (Some(modal), true) = (self.modal, tooth_hz > 0.0) {
                vibration = modal.amplitude_mm(&harmonic_amplitude(&load.harmonic_n), tooth_hz);
                let teeth = match self.force {
                    Some(ForceModel::Milling(mi)) => mi.flutes,
                    _ => 1,
                };
                if self.dynamic {
                    self.resonance.observe(
                        modal,
                        (self.rpm, teeth, tooth_hz),
                        vibration.norm(),
                        line,
                    );
                }
            }
        } else {
            let dt = rapid_time_s(m, &mv.start, &mv.end);
            self.phase(
                dt,
                &Vector3::zeros(),
                0.0,
                &axis_speed(&mv.start, &mv.end, dt),
            );
        }
        let mut end = mv.end;
        if let PlanKind::Cycle { retract, .. } = plan.kind {
            let mut up = mv.end;
            up[2] = retract;
            let dt = rapid_time_s(m, &mv.end, &up);
            self.phase(dt, &Vector3::zeros(), 0.0, &axis_speed(&mv.end, &up, dt));
            end = up;
        }
        self.pos = Some(end);
        if plan.dwell_s > 0.0 {
            self.phase(plan.dwell_s, &Vector3::zeros(), 0.0, &Vector3::zeros());
        }
        MoveContext {
            wrench: Some(Wrench::force(ctx_force, WrenchFrame::Workpiece)),
            tooth_hz,
            vibration_mm: vibration,
            ..self.context()
        }
    }
}

/// A compensation failure in words. A programmed position beyond the
/// travel is a machine coordinate: it is given with its work coordinate
/// and the work and tool offsets between them (`machine Y = 500.0500
/// (work Y350.0500 + offsets 150.0000 mm) is outside the travel [0, 500]`).
fn failure_text(f: &Failure, plan: &Plan) -> String {
    match *f {
        Failure::ProgrammedOutOfTravel {
            axis,
            value,
            limits,
        } => {
            let slot = crate::machine::axis_slot(axis as u8).unwrap_or(0);
            let (offset, scale) = if slot < 3 {
                (plan.offset[slot], plan.scale)
            } else {
                (0.0, 1.0)
            };
            let scale = if scale.is_finite() && scale > 0.0 {
                scale
            } else {
                1.0
            };
            let program = (value - offset) / scale;
            let unit = if slot >= 3 {
                " deg"
            } else if scale != 1.0 {
                " in"
            } else {
                ""
            };
            format!(
                "machine {axis} = {value:.4} (work {axis}{program:.4}{unit} + offsets {offset:.4} mm) is outside the travel [{}, {}]",
                limits.0, limits.1
            )
        }
        _ => f.to_string(),
    }
}

fn motion_label(plan: &Plan) -> &'static str {
    match (plan.kind, plan.mv.map(|m| m.motion)) {
        (PlanKind::Cycle { .. }, _) => "cycle",
        (PlanKind::Fixed, _) => "fixed",
        (_, Some(Motion::Rapid)) => "rapid",
        (_, Some(Motion::Linear)) => "feed",
        (_, Some(Motion::ArcCw)) => "arc_cw",
        (_, Some(Motion::ArcCcw)) => "arc_ccw",
        _ => "",
    }
}

/// Largest split-point storage (points) kept for reuse by a later block:
/// a move split into very many pieces gives its storage back, so that the
/// chunks in flight do not hold on to it.
const REUSE_SEGMENTS: usize = 64;

/// The compensation of a block: `None` for blocks not solved.
type Solved = Option<std::result::Result<BlockResult, Failure>>;

/// The last lines with a move (plan and block context), newest first: those
/// of `plans` (with their `contexts`), then those of `before` (the moves
/// before them, in order); at most [`compensate::CARRY_LOOKBACK`] + 1, what
/// [`compensate::carry_before`] looks at.
fn moves_back<'a>(
    plans: &'a [Plan],
    contexts: &'a [MoveContext],
    before: &'a [(Plan, MoveContext)],
) -> impl Iterator<Item = (Plan, MoveContext)> + 'a {
    plans
        .iter()
        .zip(contexts)
        .rev()
        .filter(|(p, _)| p.mv.is_some())
        .map(|(p, c)| (*p, *c))
        .chain(before.iter().rev().copied())
        .take(compensate::CARRY_LOOKBACK + 1)
}

/// One chunk in flight through [`Job::run`] with what the stages made of it.
#[derive(Default)]
struct Stage {
    chunk: Chunk,
    /// The plans of the chunk's lines (one per line of `chunk`; kept between
    /// chunks so that they are reused).
    plans: Vec<Plan>,
    /// The block context of each line (with process effects).
    contexts: Vec<MoveContext>,
    /// The compensation of each line.
    results: Vec<Solved>,
    /// The last lines with a move before the chunk (plan and block context,
    /// in order; at most [`compensate::CARRY_LOOKBACK`] + 1): where the
    /// chunk's runs of blocks estimate their start from.
    before: Vec<(Plan, MoveContext)>,
    /// Where the chunk before left the machine (its last carry): where
    /// the chunk's first block starts from.
    seed: Option<compensate::Carry>,
    /// The carry after each line of the chunk.
    carries: Vec<Option<compensate::Carry>>,
    /// The carry each run of [`GROUP_BLOCKS`] blocks was started from.
    seeds: Vec<Option<compensate::Carry>>,
}

impl Stage {
    /// Where the stage's chunk left the machine.
    fn last_carry(&self) -> Option<compensate::Carry> {
        match self.carries.last() {
            Some(k) => *k,
            None => self.seed,
        }
    }
}

/// The points of an arc move where one of its in-plane axes turns (the
/// quadrant points its sweep passes between its ends), which reach
/// further than its ends; none for other moves.
fn arc_extremes(mv: &crate::program::interp::Move) -> [Option<crate::machine::AxisVec>; 4] {
    let mut out = [None; 4];
    let Some(arc) = mv.arc else { return out };
    let (a, b, _) = arc.plane.axes();
    let (start, end) = (mv.start3(), mv.end3());
    let ang0 = (start[b] - arc.center[b]).atan2(start[a] - arc.center[a]);
    let turn = std::f64::consts::TAU;
    for (k, slot) in out.iter_mut().enumerate() {
        let quadrant = k as f64 * std::f64::consts::FRAC_PI_2;
        let d = if arc.sweep >= 0.0 {
            (quadrant - ang0).rem_euclid(turn)
        } else {
            -(ang0 - quadrant).rem_euclid(turn)
        };
        if d != 0.0 && d.abs() < arc.sweep.abs() {
            let p = arc.point(&start, &end, d / arc.sweep);
            let mut q = mv.end;
            q[..3].copy_from_slice(p.as_slice());
            *slot = Some(q);
        }
    }
    out
}

/// Blocks with a piece beyond the tolerance that are warned about one by
/// one; the summary counts every one.
const MAX_BEYOND_WARNINGS: usize = 100;

/// Lines parsed in order by one task when a chunk is parsed in parallel.
const PARSE_LINES: usize = 512;

/// One chunk of whole lines (at most [`CHUNK_LINES`]) and their syntax.
#[derive(Default)]
struct Chunk {
    /// The lines' bytes, end-of-line bytes included.
    buf: Vec<u8>,
    /// Byte range of each line in `buf`.
    ranges: Vec<(usize, usize)>,
    /// The parsed lines (the first `parsed` are valid; kept between chunks
    /// so that their word lists are reused).
    blocks: Vec<Block>,
    /// Line number of the chunk's first line, minus one.
    first_line: usize,
    /// Lines parsed without error from the start of the chunk.
    parsed: usize,
    /// The syntax error of line `parsed`, when there is one.
    error: Option<Located>,
    /// The input ended with this chunk.
    eof: bool,
}

impl Chunk {
    fn line(&self, i: usize) -> &[u8] {
        let (s, e) = self.ranges[i];
        &self.buf[s..e]
    }

    /// Reads the next lines (up to [`CHUNK_LINES`]) from `input`, with large
    /// reads and no copy other than into the chunk's buffer.
    #[inline(never)]
    fn read<R: BufRead>(&mut self, input: &mut R, file: &str, first_line: usize) -> Result<()> {
        self.buf.clear();
        self.ranges.clear();
        self.parsed = 0;
        self.error = None;
        self.first_line = first_line;
        let mut start = 0;
        while self.ranges.len() < CHUNK_LINES {
            let avail = match input.fill_buf() {
                Ok(a) => a,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(Error::io(file, e)),
            };
            if avail.is_empty() {
                if self.buf.len() > start {
                    self.ranges.push((start, self.buf.len()));
                }
                self.eof = true;
                return Ok(());
            }
            let base = self.buf.len();
            let mut taken = avail.len();
            for nl in memchr::memchr_iter(b'\n', avail) {
                let end = base + nl + 1;
                if end - start > crate::limits::LINE_MAX_BYTES + 1 {
                    let line = first_line + self.ranges.len() + 1;
                    return Err(crate::limits::line_too_long(file, line).into());
                }
                self.ranges.push((start, end));
                start = end;
                if self.ranges.len() == CHUNK_LINES {
                    taken = nl + 1;
                    break;
                }
            }
            self.buf.extend_from_slice(&avail[..taken]);
            input.consume(taken);
            if self.buf.len() - start > crate::limits::LINE_MAX_BYTES + 1 {
                let line = first_line + self.ranges.len() + 1;
                return Err(crate::limits::line_too_long(file, line).into());
            }
        }
        self.eof = false;
        Ok(())
    }

    /// Parses every line of the chunk, in parallel runs of [`PARSE_LINES`]
    /// lines (the syntax is per line); stops at the first error in line order.
    fn parse(&mut self, file: &str, numbers: Option<&[usize]>) {
        let n = self.ranges.len();
        if self.blocks.len() < n {
            self.blocks.resize_with(n, Block::default);
        }
        let buf = &self.buf;
        let first = self.first_line;
        let error = self.blocks[..n]
            .par_chunks_mut(PARSE_LINES)
            .zip(self.ranges.par_chunks(PARSE_LINES))
            .enumerate()
            .filter_map(|(k, (blocks, ranges))| {
                for (j, (block, &(s, e))) in blocks.iter_mut().zip(ranges).enumerate() {
                    let i = k * PARSE_LINES + j;
                    let no = numbers
                        .and_then(|n| n.get(first + i).copied())
                        .unwrap_or(first + i + 1);
                    if let Err(err) = parse_one(&buf[s..e], no, file, block) {
                        return Some((i, err));
                    }
                }
                None
            })
            .min_by_key(|(i, _)| *i);
        match error {
            Some((i, e)) => {
                self.parsed = i;
                self.error = Some(e);
            }
            None => self.parsed = n,
        }
    }

    /// The parsed block of line `i`, or its syntax error.
    fn block(&mut self, i: usize) -> Result<&Block> {
        if i >= self.parsed {
            if let Some(e) = self.error.take() {
                return Err(e.into());
            }
        }
        Ok(&self.blocks[i])
    }
}

/// [`parse_line`], kept out of line: profiles show the parsing on its own
/// (`scripts/bench-stages`).
#[inline(never)]
fn parse_one(
    line: &[u8],
    line_no: usize,
    file: &str,
    out: &mut Block,
) -> std::result::Result<(), Located> {
    parse_line(line, line_no, file, out)
}

/// The interpretation stage of a [`Job::run`]: runs in program order over
/// each parsed chunk, giving its plans, block contexts and counts.
struct InterpretStage<'j, 'm> {
    job: &'j Job<'m>,
    file: &'j str,
    interp: Interpreter,
    tools: std::collections::BTreeSet<u32>,
    last_tool: u32,
    /// Axes whose component-error tables were already reported as clamped.
    clamped: u8,
    /// Warnings found by the job itself: clamped tables, resonance.
    extra_warnings: Vec<Warning>,
    tracker: Option<Tracker<'m>>,
    /// The last lines with a move so far (plan and context, in order).
    last_moves: Vec<(Plan, MoveContext)>,
    /// The first position beyond the travel (`travel` runs): reported
    /// after the input errors, like a compensation failure.
    travel_failure: Option<Error>,
}

impl<'j, 'm> InterpretStage<'j, 'm> {
    fn new(job: &'j Job<'m>, file: &'j str) -> Self {
        InterpretStage {
            job,
            file,
            interp: Interpreter::new(job.setup.clone(), file),
            tools: Default::default(),
            last_tool: 0,
            clamped: 0,
            extra_warnings: Vec::new(),
            tracker: job.predictor.as_ref().map(|p| Tracker::new(p, false)),
            last_moves: Vec::new(),
            travel_failure: None,
        }
    }

    /// Interprets one parsed chunk: its plans and block contexts.
    #[inline(never)]
    fn chunk(&mut self, st: &mut Stage, summary: &mut Summary) -> Result<()> {
        let chunk = &mut st.chunk;
        let n = chunk.ranges.len();
        if st.plans.len() < n {
            st.plans.resize(n, Plan::default());
        }
        st.contexts.clear();
        st.before.clear();
        st.before.extend_from_slice(&self.last_moves);
        for (i, plan) in st.plans[..n].iter_mut().enumerate() {
            chunk.block(i)?;
            self.interp.whole_units(&mut chunk.blocks[i]);
            let (s, e) = chunk.ranges[i];
            let line = &chunk.buf[s..e];
            let block = &chunk.blocks[i];
            self.interp.step_into(block, line, plan)?;
            let plan = &*plan;
            if !block.is_empty() {
                summary.blocks += 1;
            }
            if let Some(mv) = plan.mv {
                self.count_move(plan, &mv, block.line_no, line, summary);
            }
            if let Some(t) = self.tracker.as_mut() {
                st.contexts
                    .push(t.advance(plan, self.interp.spindle_rpm(), block.line_no));
            }
        }
        summary.lines = chunk.first_line + chunk.ranges.len();
        // The chunk's last moves, after those before it.
        let last: Vec<(Plan, MoveContext)> =
            moves_back(&st.plans[..n], &st.contexts, &self.last_moves).collect();
        self.last_moves.clear();
        self.last_moves.extend(last.into_iter().rev());
        Ok(())
    }

    /// Counts a move in the summary, checks it against the travel
    /// (`travel` runs) and reports component-error tables it leaves.
    fn count_move(
        &mut self,
        plan: &Plan,
        mv: &crate::program::interp::Move,
        line_no: usize,
        line: &[u8],
        summary: &mut Summary,
    ) {
        let file = self.file;
        if let (Some(m), None) = (self.job.travel, &self.travel_failure) {
            // The end, then the points of an arc's bulge between its ends.
            let failed = std::iter::once((&mv.end, ""))
                .chain(
                    arc_extremes(mv)
                        .iter()
                        .flatten()
                        .map(|p| (p, " on the arc")),
                )
                .find_map(|(p, at)| {
                    crate::compensate::programmed_travel(m, p)
                        .err()
                        .map(|f| (f, at))
                });
            if let Some((f, at)) = failed {
                let text = crate::program::gcode::strip_eol(line);
                self.travel_failure = Some(Error::Unachievable(Located::new(
                    file,
                    line_no,
                    1,
                    format!(
                        "{}{at}: `{}`",
                        failure_text(&f, plan),
                        String::from_utf8_lossy(text).trim()
                    ),
                )));
            }
        }
        summary.moves += 1;
        match (plan.kind, mv.motion) {
            (PlanKind::Cycle { .. }, _) => summary.holes += 1,
            (_, Motion::Rapid) => summary.rapids += 1,
            (_, Motion::Linear) => summary.feeds += 1,
            _ => summary.arcs += 1,
        }
        let (lo, hi) = summary.extents.get_or_insert((mv.end, mv.end));
        for k in 0..6 {
            lo[k] = lo[k].min(mv.end[k]);
            hi[k] = hi[k].max(mv.end[k]);
        }
        if mv.tool != 0 && mv.tool != self.last_tool {
            self.tools.insert(mv.tool);
            self.last_tool = mv.tool;
        }
        // Component-error tables are clamped at their ends: say so once
        // per axis.
        if let Some(pred) = &self.job.predictor {
            let fresh = pred.machine.clamped_axes(&mv.end) & !self.clamped;
            for slot in (0..6).filter(|s| fresh & (1 << s) != 0) {
                let message = format!(
                    "{} axis position {:.3} lies outside its component-error tables; the table end values are used",
                    crate::machine::AXIS_LETTERS[slot] as char,
                    mv.end[slot]
                );
                tracing::warn!("{file}:{line_no}: {message}");
                self.extra_warnings.push(Warning {
                    line: line_no,
                    message,
                    count: 1,
                    left: None,
                });
            }
            self.clamped |= fresh;
        }
    }

    /// Completes the summary after the last chunk: units, warnings, tools
    /// and the time line.
    fn finish(self, summary: &mut Summary) {
        summary.inch = self.interp.inch();
        summary.warnings = self.interp.warnings().to_vec();
        summary.warnings.extend(self.extra_warnings);
        summary.tools = self.tools.into_iter().collect();
        if let Some(t) = &self.tracker {
            summary.duration_s = t.time_s;
            summary.mean_power_w = t.mean_power();
            if let Some(modal) = t.modal {
                summary
                    .warnings
                    .extend(t.resonance.warnings(modal, self.file));
            }
        }
    }
}

/// The writing stage of a [`Job::run`]: formats each compensated chunk
/// into its buffer and records its deviations (summary and report rows).
/// It holds nothing of the caller's (the output and the rows are handed
/// to it), so that it runs on a worker thread while the calling thread
/// interprets the next chunk.
struct WriteStage<'j, 'm> {
    job: &'j Job<'m>,
    file: &'j str,
    solving: bool,
    /// The program is written (not only reported on).
    writing: bool,
    emitter: Emitter,
    /// The lines formatted for the last chunk (when `solving`).
    out_buf: Vec<u8>,
    /// The deviation fields of the summary (deviation, cutting moves,
    /// beyond the tolerance, largest residual), merged by [`Self::finish`].
    summary: Summary,
    /// The warnings about blocks with a piece beyond the tolerance (at most
    /// [`MAX_BEYOND_WARNINGS`]; the summary counts them all).
    beyond: Vec<Warning>,
    /// The warning about points held at an end of travel (the first
    /// block's, counting every block).
    held: Option<Warning>,
    /// Bytes written before the chunk being written.
    written: usize,
    /// Where each line's output ends (bytes written so far), when asked.
    marks: Option<Vec<usize>>,
    /// Storage of a block under tool centre point control in tool tips.
    tip_plan: Plan,
    tip_res: BlockResult,
    /// [`Job::solve_rule`] of millimetre blocks.
    mm_rule: (f64, Settings),
}

impl<'j, 'm> WriteStage<'j, 'm> {
    fn new(job: &'j Job<'m>, file: &'j str, solving: bool, writing: bool) -> Self {
        WriteStage {
            job,
            file,
            solving,
            writing,
            emitter: Emitter::new(job.emit)
                .with_tolerance(job.settings.tolerance_mm)
                .with_uncertainty(job.predictor.and_then(|p| p.uncertainty).cloned()),
            out_buf: if solving && writing {
                Vec::with_capacity(1 << 20)
            } else {
                Vec::new()
            },
            summary: Summary::default(),
            beyond: Vec::new(),
            held: None,
            written: 0,
            marks: None,
            tip_plan: Plan::default(),
            tip_res: BlockResult::default(),
            mm_rule: job.mm_rule(),
        }
    }

    /// Formats one compensated chunk into [`Self::out_buf`] (nothing to
    /// format when nothing is solved: [`Self::sink`] writes the lines as
    /// they are) and hands over its rows.
    #[inline(never)]
    fn chunk(&mut self, st: &mut Stage, mut rows: Option<&mut dyn FnMut(Row)>) -> Result<()> {
        let chunk = &st.chunk;
        let plans = &st.plans[..chunk.ranges.len()];
        if !self.solving {
            if let Some(marks) = self.marks.as_mut() {
                let base = self.written;
                marks.extend(chunk.ranges.iter().map(|&(_, e)| base + e));
            }
            self.written += chunk.buf.len();
            return Ok(());
        }
        self.out_buf.clear();
        for (i, plan) in plans.iter().enumerate() {
            let block = &chunk.blocks[i];
            let res = match st.results.get(i) {
                Some(Some(Ok(r))) => Some(r),
                Some(Some(Err(f))) => {
                    return Err(Error::Unachievable(Located::new(
                        self.file,
                        block.line_no,
                        1,
                        format!(
                            "{}: `{}`",
                            failure_text(f, plan),
                            String::from_utf8_lossy(crate::program::gcode::strip_eol(
                                chunk.line(i)
                            ))
                            .trim()
                        ),
                    )));
                }
                _ => None,
            };
            if let (Some(r), Some(mv)) = (res, plan.mv) {
                if plan.kind != PlanKind::Pass {
                    self.record(plan, &mv, r, block.line_no, rows.as_deref_mut());
                }
            }
            if self.writing {
                match (plan.tcpm, res, &self.job.predictor) {
                    // Tool centre point control: written as tool tips.
                    (true, Some(r), Some(pred)) => {
                        compensate::tcpm::to_tips(
                            pred.machine,
                            plan,
                            r,
                            &mut self.tip_plan,
                            &mut self.tip_res,
                        );
                        self.emitter.set_limits(tip_limits(
                            pred.machine,
                            &r.end,
                            &self.tip_res.end,
                        ));
                        self.emitter.write(
                            chunk.line(i),
                            block,
                            &self.tip_plan,
                            Some(&self.tip_res),
                            &mut self.out_buf,
                        );
                    }
                    (_, _, pred) => {
                        if let Some(p) = pred {
                            self.emitter.set_limits(machine_limits(p.machine));
                        }
                        self.emitter
                            .write(chunk.line(i), block, plan, res, &mut self.out_buf)
                    }
                }
                if let (Some(pred), Some(mv)) = (&self.job.predictor, plan.mv) {
                    self.written_travel(
                        pred.machine,
                        plan,
                        mv.tool_len_mm,
                        block.line_no,
                        chunk.line(i),
                    )?;
                }
            }
            if let Some(marks) = self.marks.as_mut() {
                marks.push(self.written + self.out_buf.len());
            }
        }
        self.written += self.out_buf.len();
        // The stage waits for its next chunk: large split-point storage
        // is given back now rather than when it is compensated again.
        for r in st.results.iter_mut().flatten().flatten() {
            if r.segments.capacity() > REUSE_SEGMENTS {
                r.segments = Vec::new();
            }
        }
        Ok(())
    }

    /// Writes the chunk [`Self::chunk`] formatted (`st` the same stage) to
    /// `out`: its lines as they are when nothing is solved.
    fn sink(&self, st: &Stage, out: &mut dyn Write) -> Result<()> {
        let bytes = if self.solving {
            &self.out_buf
        } else {
            &st.chunk.buf
        };
        out.write_all(bytes).map_err(|e| Error::io("output", e))
    }

    /// Every point the lines just written for a block command (as the
    /// control reads their words: through the tool tip under TCPM) within
    /// the travel of `m`, or the block refused naming the axis: the
    /// compensated program never holds a move its own `check` refuses.
    fn written_travel(
        &self,
        m: &MachineTool,
        plan: &Plan,
        tool_mm: f64,
        line_no: usize,
        line: &[u8],
    ) -> Result<()> {
        for p in self.emitter.written() {
            let machine = if plan.tcpm {
                match m.axes_for_tip(p, tool_mm) {
                    Some(a) => a,
                    None => continue,
                }
            } else {
                *p
            };
            if let Err(f) = compensate::programmed_travel(m, &machine) {
                let shown = String::from_utf8_lossy(crate::program::gcode::strip_eol(line));
                return Err(Error::Unachievable(Located::new(
                    self.file,
                    line_no,
                    1,
                    format!(
                        "the compensated words of this block, as written, would command {}: `{}`",
                        written_failure_text(&f),
                        shown.trim()
                    ),
                )));
            }
        }
        Ok(())
    }

    /// Says that a block's point is held at an end of travel: worded at
    /// the first such block, counted at the others.
    fn held_at_travel(&mut self, h: compensate::HeldAtTravel, line_no: usize) {
        if let Some(w) = self.held.as_mut() {
            w.count += 1;
            return;
        }
        let tol = self.job.settings.tolerance_mm;
        let unit = if matches!(h.axis, 'A' | 'B' | 'C') {
            "deg"
        } else {
            "mm"
        };
        let message = format!(
            "the correction of {axis} would take it {by:.4} {unit} past the end of its travel ({end}), less than the tolerance {tol} mm: held at the end, where the point misses its target by as much",
            axis = h.axis,
            by = h.by,
            end = h.end,
        );
        tracing::warn!("{}:{line_no}: {message}", self.file);
        self.held = Some(Warning {
            line: line_no,
            message,
            count: 1,
            left: None,
        });
    }

    /// Adds a compensated move's deviation to the summary and hands over
    /// its report row.
    fn record(
        &mut self,
        plan: &Plan,
        mv: &crate::program::interp::Move,
        r: &BlockResult,
        line_no: usize,
        rows: Option<&mut (dyn FnMut(Row) + '_)>,
    ) {
        if let Some(h) = r.held {
            self.held_at_travel(h, line_no);
        }
        let summary = &mut self.summary;
        let dev = r.deviation.total().norm();
        summary.deviation.add(dev, line_no);
        if plan.kind != PlanKind::Fixed && mv.motion != Motion::Rapid {
            summary.cutting.add(dev, line_no);
        }
        let tol = self.job.settings.tolerance_mm;
        // Only a written program states a tolerance (a report has none).
        let written = self.writing;
        // The miss of the solved pieces, and of the written ones at most
        // the rounding of their words more.
        let (rounding, settings) = self.job.solve_rule(plan.scale, &self.mm_rule);
        let miss = r.miss_mm + rounding;
        if r.miss_mm > settings.tolerance_mm && written {
            summary.beyond.add(miss, line_no);
            let what = crate::compensate::cycles::miss_words(plan, r);
            // Worded only for the warnings kept: nothing allocates per
            // block once they are full.
            if self.beyond.len() < MAX_BEYOND_WARNINGS {
                let message = format!(
                    "{what} is predicted {miss:.4} mm from the programmed path, beyond the tolerance {tol} mm"
                );
                tracing::warn!("{}:{line_no}: {message}", self.file);
                self.beyond.push(Warning {
                    line: line_no,
                    message,
                    count: 1,
                    left: None,
                });
            }
        }
        let left = if written {
            r.residual_mm.max(r.miss_mm)
        } else {
            r.residual_mm
        };
        if mv.motion != Motion::Rapid && left > summary.max_residual_mm {
            summary.max_residual_mm = left;
            summary.max_residual_line = line_no;
        }
        if let Some(rows) = rows {
            rows(Row {
                line: line_no,
                motion: motion_label(plan),
                start: mv.start,
                commanded: mv.end,
                arc: mv.arc,
                compensated: r.end,
                result: r.clone(),
                robot: None,
            });
        }
    }

    /// Completes the summary after the last chunk: the deviations, the
    /// lines changed and added.
    fn finish(self, summary: &mut Summary) {
        summary.deviation = self.summary.deviation;
        summary.cutting = self.summary.cutting;
        summary.beyond = self.summary.beyond;
        summary.max_residual_mm = self.summary.max_residual_mm;
        summary.max_residual_line = self.summary.max_residual_line;
        summary.changed = self.emitter.changed_blocks();
        summary.added = self.emitter.added_blocks();
        summary.added_by = self.emitter.added_by();
        summary.warnings.extend(self.beyond);
        summary.warnings.extend(self.held);
    }
}

/// [`compensate::carry_before`], kept out of line: profiles show the
/// estimates of where runs start on their own (`scripts/bench-stages`).
#[inline(never)]
fn estimate_carry(
    before: &[(ToolPredictor, Plan)],
    settings: &Settings,
    from_start: Option<AxisVec>,
) -> Option<compensate::Carry> {
    compensate::carry_before(before, settings, from_start)
}

/// Runs `op` in a fork-join scope of the job's pool (rayon's global pool
/// when `None`), on the calling thread.
fn in_scope<'s, R>(pool: Option<&rayon::ThreadPool>, op: impl FnOnce(&rayon::Scope<'s>) -> R) -> R {
    match pool {
        Some(p) => p.in_place_scope(op),
        None => rayon::in_place_scope(op),
    }
}

/// The travel of each axis of `m` (machine coordinates).
fn machine_limits(m: &MachineTool) -> [Option<(f64, f64)>; 6] {
    std::array::from_fn(|s| m.travel(s))
}

/// The travel of each axis of `m` in tool-tip coordinates about a point
/// whose machine coordinates are `machine` and tool tip `tip`: each
/// linear axis' travel shifted by the offset of the tip from the machine
/// point there (the rotary axes are the same in both).
fn tip_limits(m: &MachineTool, machine: &AxisVec, tip: &AxisVec) -> [Option<(f64, f64)>; 6] {
    std::array::from_fn(|s| {
        m.travel(s).map(|(lo, hi)| {
            let shift = if s < 3 { tip[s] - machine[s] } else { 0.0 };
            (lo + shift, hi + shift)
        })
    })
}

/// What a written point beyond the travel commands, for
/// [`WriteStage::written_travel`].
fn written_failure_text(f: &compensate::Failure) -> String {
    match f {
        compensate::Failure::ProgrammedOutOfTravel {
            axis,
            value,
            limits,
        }
        | compensate::Failure::OutOfTravel {
            axis,
            value,
            limits,
        } => format!(
            "machine {axis} = {value:.4}, outside the travel [{}, {}]",
            limits.0, limits.1
        ),
        other => format!("{other:?}"),
    }
}

impl<'m> Job<'m> {
    /// How far the rounding of the written words can move a written piece
    /// of a block in units of `scale` mm ([`rounding_mm`], with the rotary
    /// words' [`rotary_rounding_mm`] on a machine with rotary axes), mm.
    fn rounding(&self, scale: f64) -> f64 {
        let tol = self.settings.tolerance_mm;
        let rotary = self
            .predictor
            .as_ref()
            .is_some_and(|p| (3..6).any(|s| p.machine.has_axis(s)));
        rounding_mm(&self.emit, tol, scale)
            + if rotary {
                rotary_rounding_mm(&self.emit, tol)
            } else {
                0.0
            }
    }

    /// The settings a block in units of `scale` mm is solved with: the
    /// tolerance less the rounding of its written words (at least half of
    /// it), so that the program as written keeps the tolerance its header
    /// states.
    fn solve_settings(&self, scale: f64) -> Settings {
        let tol = self.settings.tolerance_mm;
        Settings {
            tolerance_mm: (tol - self.rounding(scale)).max(tol / 2.0),
        }
    }

    /// The rounding of the written words of a block in units of `scale` mm
    /// and the settings it is solved with ([`Self::rounding`],
    /// [`Self::solve_settings`]); `mm` is that of millimetre blocks,
    /// worked out once.
    fn solve_rule(&self, scale: f64, mm: &(f64, Settings)) -> (f64, Settings) {
        if scale == 1.0 {
            *mm
        } else {
            (self.rounding(scale), self.solve_settings(scale))
        }
    }

    /// [`Self::solve_rule`] of millimetre blocks.
    fn mm_rule(&self) -> (f64, Settings) {
        (self.rounding(1.0), self.solve_settings(1.0))
    }

    fn install<R: Send>(&self, op: impl FnOnce() -> R + Send) -> R {
        match self.pool {
            Some(pool) => pool.install(op),
            None => op(),
        }
    }

    /// Compensates the blocks of a prepared stage (on the job's pool: the
    /// caller runs this inside a task of it). Runs of [`GROUP_BLOCKS`]
    /// blocks go in order on one thread (a move starts where the previous
    /// one left the machine, with the directions its pieces last moved
    /// in): the first from the carry the chunk before left
    /// ([`Stage::seed`]), each other one from the carry of the moves before
    /// it ([`compensate::carry_before`], an estimate). Then, in order, a
    /// run whose estimate was not the carry the run before it really left
    /// is solved again from that carry, block by block until a block
    /// leaves the carry it left before: the output is that of one run over
    /// the whole program, whatever the number of threads.
    fn compensate_stage(&self, st: &mut Stage, solving: bool) {
        let (true, Some(pred)) = (solving, &self.predictor) else {
            st.results.clear();
            st.carries.clear();
            return;
        };
        let n = st.chunk.ranges.len();
        // The results of the chunk this stage held before are overwritten
        // in place: their split-point storage is reused (`WriteStage::chunk` gave
        // large storage back).
        st.results.truncate(n);
        st.results.resize_with(n, || None);
        st.carries.clear();
        st.carries.resize(n, None);
        st.seeds.clear();
        st.seeds.resize(n.div_ceil(GROUP_BLOCKS), None);
        let plans = &st.plans[..n];
        let contexts = &st.contexts;
        let before = &st.before;
        let seed = st.seed;
        let home = self.setup.home;
        // (the estimates of where runs start: at the millimetre rounding)
        let settings = self.solve_settings(1.0);
        let mm = self.mm_rule();
        st.results
            .par_chunks_mut(GROUP_BLOCKS)
            .zip(st.carries.par_chunks_mut(GROUP_BLOCKS))
            .zip(st.seeds.par_iter_mut())
            .zip(plans.par_chunks(GROUP_BLOCKS))
            .zip(st.contexts.par_chunks(GROUP_BLOCKS))
            .enumerate()
            .for_each_init(
                || Vec::with_capacity(compensate::CARRY_LOOKBACK + 1),
                |last: &mut Vec<(ToolPredictor, Plan)>, (g, ((((rs, ks), sd), ps), cs))| {
                    let mut carry = if g == 0 {
                        seed
                    } else {
                        // An estimate of where the run starts: the last
                        // moves before it, as if it had gone through them.
                        let start = g * GROUP_BLOCKS;
                        last.clear();
                        last.extend(
                            moves_back(plans.get(..start).unwrap_or(&[]), contexts, before)
                                .map(|(p, c)| (pred.with_context(c), p)),
                        );
                        last.reverse();
                        // Fewer moves than the lookback: all since the start.
                        let from_start = (last.len() <= compensate::CARRY_LOOKBACK).then_some(home);
                        estimate_carry(last, &settings, from_start)
                    };
                    *sd = carry;
                    for (((r, k), p), c) in rs.iter_mut().zip(ks.iter_mut()).zip(ps).zip(cs) {
                        self.solve_block(pred, (p, c, &mm), &mut carry, r);
                        *k = carry;
                    }
                },
            );
        self.settle(pred, st, &mm);
    }

    /// Compensates one block into `r` (reusing its split-point storage);
    /// out of line, so that profiles show the solves on their own.
    #[inline(never)]
    fn solve_block(
        &self,
        pred: &ToolPredictor,
        (plan, ctx, mm): (&Plan, &MoveContext, &(f64, Settings)),
        carry: &mut Option<compensate::Carry>,
        r: &mut Solved,
    ) {
        let storage = match r.take() {
            Some(Ok(old)) => (old.segments, old.takeup_at),
            _ => (Vec::new(), Vec::new()),
        };
        let (rounding, settings) = self.solve_rule(plan.scale, mm);
        *r = Some(compensate::block_recycling(
            &pred.with_context(*ctx),
            plan,
            &settings,
            carry,
            storage,
            rounding,
        ));
    }

    /// The in-order pass of [`Self::compensate_stage`]: solves again, from
    /// the carry the run before really left, each run seeded with another
    /// estimate, until a block leaves the carry it left before.
    #[inline(never)]
    fn settle(&self, pred: &ToolPredictor, st: &mut Stage, mm: &(f64, Settings)) {
        let n = st.carries.len();
        let mut i = GROUP_BLOCKS;
        let mut dirty = false;
        while i < n {
            if i % GROUP_BLOCKS == 0 && !dirty {
                dirty = st.carries[i - 1] != st.seeds[i / GROUP_BLOCKS];
                if !dirty {
                    i += GROUP_BLOCKS;
                    continue;
                }
            }
            let mut carry = st.carries[i - 1];
            let old = st.carries[i];
            self.solve_block(
                pred,
                (&st.plans[i], &st.contexts[i], mm),
                &mut carry,
                &mut st.results[i],
            );
            st.carries[i] = carry;
            i += 1;
            if carry == old {
                // The rest of this run follows from the same carry.
                dirty = false;
                i = i.next_multiple_of(GROUP_BLOCKS);
            }
        }
    }

    /// Runs the job over `input`. With `out`, the (compensated) program is
    /// written; with `rows`, a row per motion block is handed over in order.
    ///
    /// The program streams through in chunks of [`CHUNK_LINES`] lines, four
    /// chunks in flight: while the pool compensates one chunk, parses the
    /// chunk after next and formats the chunk before, the calling thread
    /// interprets the next one (then writes the formatted bytes out). Errors of the input (syntax, interpretation,
    /// reading) come before compensation failures wherever they are in the
    /// program, each kind in line order: after a compensation failure the
    /// rest of the program is still read and interpreted.
    pub fn run<R: BufRead>(
        &self,
        input: R,
        file: &str,
        out: Option<&mut dyn Write>,
        rows: Option<&mut dyn FnMut(Row)>,
    ) -> Result<Summary> {
        self.run_traced(input, file, out, rows, None)
    }

    /// [`Job::run`] over lines that are not the program's in order (its
    /// subprograms followed, `crate::pipeline::shop`): `numbers` gives
    /// each input line's line number in the program, and `marks` receives
    /// where each line's output ends.
    pub fn run_traced<R: BufRead>(
        &self,
        mut input: R,
        file: &str,
        mut out: Option<&mut dyn Write>,
        mut rows: Option<&mut dyn FnMut(Row)>,
        traced: Option<(&[usize], &mut Vec<usize>)>,
    ) -> Result<Summary> {
        // With every effect off the output is the input; a report still
        // wants its rows (of zero deviation).
        let solving = self
            .predictor
            .as_ref()
            .is_some_and(|p| !p.effects.is_none() || rows.is_some());
        let mut summary = Summary::default();
        let mut interpret = InterpretStage::new(self, file);
        let mut write = WriteStage::new(self, file, solving, out.is_some());
        let (numbers, marks_out) = traced.unzip();
        write.marks = marks_out.as_ref().map(|_| Vec::new());

        // The four chunks in flight, oldest first: `done` is compensated
        // (to be written), `solve` is interpreted (to be compensated),
        // `parsed` is parsed (to be interpreted), `read` is being read.
        let mut done = Stage::default();
        let mut solve = Stage::default();
        let mut parsed = Stage::default();
        let mut read = Stage::default();
        let (mut has_done, mut has_solve) = (false, false);
        parsed.chunk.read(&mut input, file, 0)?;
        self.install(|| parsed.chunk.parse(file, numbers));
        let mut has_parsed = true;
        let mut next_line = parsed.chunk.ranges.len();
        let mut input_done = parsed.chunk.eof;
        // The first compensation failure. Errors of the input (syntax,
        // interpretation, reading) come first wherever they are, so after a
        // failure the rest of the program is still read and interpreted
        // (nothing more is compensated or written).
        let mut failure: Option<Error> = None;
        while has_done || has_solve || has_parsed {
            let mut has_read = false;
            let mut read_error = None;
            if !input_done {
                match read.chunk.read(&mut input, file, next_line) {
                    Ok(()) => {
                        has_read = true;
                        next_line += read.chunk.ranges.len();
                        input_done = read.chunk.eof;
                    }
                    Err(e) => {
                        read_error = Some(e);
                        input_done = true;
                    }
                }
            }
            let mut written = Ok(());
            let mut interpreted = Ok(());
            let scanning = failure.is_some();
            // The chunk to compensate starts where the one before (solved
            // in the round before) left the machine.
            solve.seed = if has_done {
                done.last_carry()
            } else {
                Some(compensate::Carry::program_start(self.setup.home))
            };
            let (solve_ref, read_ref) = (&mut solve, &mut read.chunk);
            let (done_ref, write_ref, written_ref) = (&mut done, &mut write, &mut written);
            let rows_now = rows.as_deref_mut();
            // The calling thread interprets (in program order, the one
            // stage that cannot be split); the pool compensates, parses and
            // formats (a report's rows, handed to the caller's closure, are
            // made on this thread).
            in_scope(self.pool, |s| {
                if has_solve && !scanning {
                    s.spawn(move |_| self.compensate_stage(solve_ref, solving));
                }
                if has_read {
                    s.spawn(move |_| read_ref.parse(file, numbers));
                }
                if has_done && !scanning {
                    match rows_now {
                        Some(rows) => *written_ref = write_ref.chunk(done_ref, Some(rows)),
                        None => s.spawn(move |_| *written_ref = write_ref.chunk(done_ref, None)),
                    }
                }
                if has_parsed {
                    interpreted = interpret.chunk(&mut parsed, &mut summary);
                }
            });
            // Input errors in line order (this chunk's lines come before
            // the chunk being read), then a failed write.
            interpreted?;
            if let Some(e) = read_error {
                return Err(e);
            }
            match written {
                Err(e @ Error::Unachievable(_)) => failure = Some(e),
                other => other?,
            }
            if let (true, false, None, Some(out)) =
                (has_done, scanning, &failure, out.as_deref_mut())
            {
                write.sink(&done, out)?;
            }
            // Shift the stages: each chunk moves one stage on.
            std::mem::swap(&mut done, &mut solve);
            has_done = has_solve;
            std::mem::swap(&mut solve, &mut parsed);
            has_solve = has_parsed;
            std::mem::swap(&mut parsed, &mut read);
            has_parsed = has_read;
        }
        if let Some(e) = failure.or(interpret.travel_failure.take()) {
            return Err(e);
        }
        interpret.finish(&mut summary);
        if let (Some(dst), Some(marks)) = (marks_out, write.marks.take()) {
            *dst = marks;
        }
        write.finish(&mut summary);
        Ok(summary)
    }

    /// The forward pass of a program without the solver: each block's line,
    /// plan and the block context its time line gives it (the prediction
    /// path `report` and `compensate` share), in program order. For
    /// checks that predict a program independently of the compensation,
    /// such as reading a compensated program back.
    pub fn forward<R: BufRead>(
        &self,
        mut input: R,
        file: &str,
        each: &mut dyn FnMut(usize, &Plan, &MoveContext),
    ) -> Result<()> {
        let mut interp = Interpreter::new(self.setup.clone(), file);
        let mut tracker = self.predictor.as_ref().map(|p| Tracker::new(p, false));
        let (mut text, mut block, mut plan) = (Vec::new(), Block::default(), Plan::default());
        let mut line_no = 0;
        loop {
            text.clear();
            let n = input
                .read_until(b'\n', &mut text)
                .map_err(|e| Error::io(file, e))?;
            if n == 0 {
                return Ok(());
            }
            line_no += 1;
            parse_line(&text, line_no, file, &mut block)?;
            interp.whole_units(&mut block);
            interp.step_into(&block, &text, &mut plan)?;
            let ctx = match tracker.as_mut() {
                Some(t) => t.advance(&plan, interp.spindle_rpm(), line_no),
                None => MoveContext::default(),
            };
            each(line_no, &plan, &ctx);
        }
    }

    /// A first pass over the program for the thermal start: the mean power
    /// of each heat source (spindle, X, Y, Z drives), W, over the program's
    /// time line from a cold start. Parses and interprets only.
    #[inline(never)]
    pub fn mean_power<R: BufRead>(&self, mut input: R, file: &str) -> Result<Powers> {
        let Some(pred) = &self.predictor else {
            return Ok([0.0; 4]);
        };
        let mut tracker = Tracker::new(pred, true);
        tracker.modal = None;
        let mut interp = Interpreter::new(self.setup.clone(), file);
        let mut chunk = Chunk::default();
        let mut first_line = 0;
        loop {
            chunk.read(&mut input, file, first_line)?;
            self.install(|| chunk.parse(file, None));
            for i in 0..chunk.ranges.len() {
                chunk.block(i)?;
                let block = &chunk.blocks[i];
                let plan = interp.step(block, chunk.line(i))?;
                tracker.advance(&plan, interp.spindle_rpm(), block.line_no);
            }
            first_line += chunk.ranges.len();
            if chunk.eof {
                break;
            }
        }
        Ok(tracker.mean_power())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::compensate::Settings;
    use crate::emit::gcode::EmitOptions;
    use crate::predict::EffectSet;
    use approx::assert_abs_diff_eq;

    const TIME_TOL_S: f64 = 1e-9;
    const POWER_TOL_W: f64 = 1e-6;

    /// An error-free XYZ machine (travel ±500 mm).
    const XYZ_YAML: &str = "kind: machine_tool
name: t
axes:
  - { name: X, type: linear, side: workpiece, travel_mm: [-500, 500], rapid_mm_per_min: 60000 }
  - { name: Y, type: linear, side: workpiece, travel_mm: [-500, 500], rapid_mm_per_min: 60000 }
  - { name: Z, type: linear, side: tool, travel_mm: [-500, 500], rapid_mm_per_min: 60000 }
";

    /// [`XYZ_YAML`] with `extra` YAML sections.
    fn xyz_machine(extra: &str) -> MachineTool {
        let text = format!("{XYZ_YAML}{extra}");
        match MachineTool::from_yaml_str(&text, "t.yaml") {
            Ok(m) => m,
            Err(e) => panic!("{e}"),
        }
    }

    /// X, Y and Z on, a control reading programs in mm, everything else
    /// default.
    fn xyz_setup() -> Setup {
        Setup {
            axes: [true, true, true, false, false, false],
            units_default: Some(crate::program::interp::Units::Mm),
            ..Setup::default()
        }
    }

    /// Every effect, default settings, no annotation, the global pool.
    fn plain_job(m: &MachineTool, setup: Setup) -> Job<'_> {
        Job {
            predictor: Some(ToolPredictor::new(m, EffectSet::default())),
            setup,
            settings: Settings::default(),
            emit: EmitOptions {
                decimals_mm: None,
                decimals_deg: None,
                annotate: false,
            },
            pool: None,
            travel: None,
        }
    }

    /// A reader that yields `data`, then fails.
    struct FailingAfter<'a> {
        data: &'a [u8],
    }

    impl std::io::Read for FailingAfter<'_> {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            if self.data.is_empty() {
                return Err(std::io::Error::other("disk gone"));
            }
            let n = buf.len().min(self.data.len());
            buf[..n].copy_from_slice(&self.data[..n]);
            self.data = &self.data[n..];
            Ok(n)
        }
    }

    /// The first error in line order is the one reported: a located error
    /// in one chunk comes before a read error met while reading the next
    /// chunk, so the read error cannot hide it.
    #[test]
    fn an_error_in_a_chunk_comes_before_a_read_error_after_it() {
        let m = xyz_machine("");
        let job = plain_job(&m, xyz_setup());
        // Line 10 is bad; the program is longer than one chunk, and the
        // reader fails where the second chunk would start.
        let mut program = String::new();
        for k in 1..=CHUNK_LINES {
            if k == 10 {
                program.push_str("G1 X1 Q\n");
            } else {
                program.push_str("G0 X1\n");
            }
        }
        let reader = std::io::BufReader::with_capacity(
            64,
            FailingAfter {
                data: program.as_bytes(),
            },
        );
        let err = match job.run(reader, "p.nc", None, None) {
            Ok(_) => panic!("a bad line and a failing read must be an error"),
            Err(e) => e.to_string(),
        };
        assert!(err.starts_with("p.nc:10:"), "{err}");
    }

    /// A program of `lines` feed moves with the given lines replaced.
    fn program_with(lines: usize, replace: &[(usize, &str)]) -> String {
        let mut program = String::from("G0 X0 Y0 Z10\n");
        for k in 2..=lines {
            match replace.iter().find(|(at, _)| *at == k) {
                Some((_, text)) => program.push_str(text),
                None => program.push_str(&format!("G1 X{} Y{} F1000", k % 300, k % 7)),
            }
            program.push('\n');
        }
        program
    }

    fn run_error(job: &Job, program: &str) -> String {
        let mut out = Vec::new();
        match job.run(program.as_bytes(), "p.nc", Some(&mut out), None) {
            Ok(_) => panic!("the program must fail"),
            Err(e) => e.to_string(),
        }
    }

    /// The pipeline interprets a chunk while the one before is compensated
    /// and the one before that is written. Errors of the input (syntax,
    /// interpretation, reading) come before compensation failures wherever
    /// they are, each kind in line order, whatever chunks they fall in.
    #[test]
    fn input_errors_come_before_compensation_failures_each_in_line_order() {
        let m = xyz_machine("");
        let job = plain_job(&m, xyz_setup());
        let c = CHUNK_LINES;
        // A target beyond the travel (found by the compensation), syntax
        // errors and interpretation errors (an arc without centre).
        let travel = "G1 X900 F1000";
        let (syntax, interp) = ("G1 X1 Q", "G2 X5 Y5");
        let cases: [(&[(usize, &str)], usize); 9] = [
            (&[(5, travel), (c + 5, syntax), (2 * c + 5, interp)], c + 5),
            (&[(c + 5, syntax), (2 * c + 5, travel)], c + 5),
            (&[(c + 7, travel), (2 * c + 3, syntax)], 2 * c + 3),
            (&[(2 * c + 3, travel), (2 * c + 9, interp)], 2 * c + 9),
            (&[(10, travel), (3000, syntax)], 3000),
            (&[(c + 1, syntax), (c + 2, travel)], c + 1),
            (&[(20, interp), (c + 2, syntax)], 20),
            (&[(5, travel), (c + 9, travel)], 5),
            (&[(3 * c + 1, travel)], 3 * c + 1),
        ];
        for (replace, line) in cases {
            let program = program_with(4 * c + 100, replace);
            let err = run_error(&job, &program);
            assert!(
                err.starts_with(&format!("p.nc:{line}:")),
                "{replace:?}: {err}"
            );
        }
    }

    /// A read error is an error of the input: it comes after the syntax and
    /// interpretation errors of the lines read before it, and before any
    /// compensation failure.
    #[test]
    fn a_read_error_comes_after_the_input_errors_before_it() {
        let m = xyz_machine("");
        let job = plain_job(&m, xyz_setup());
        let c = CHUNK_LINES;
        let failing_run = |program: &str| {
            let reader = std::io::BufReader::with_capacity(
                64,
                FailingAfter {
                    data: program.as_bytes(),
                },
            );
            match job.run(reader, "p.nc", None, None) {
                Ok(_) => panic!("a failing read must be an error"),
                Err(e) => e.to_string(),
            }
        };
        for (lines, at) in [(c, 5), (2 * c, c + 5), (3 * c, 2 * c + 17), (3 * c, 3 * c)] {
            let err = failing_run(&program_with(lines, &[(at, "G2 X5 Y5")]));
            assert!(
                err.starts_with(&format!("p.nc:{at}:")),
                "{lines} lines: {err}"
            );
            let err = failing_run(&program_with(lines, &[(at, "G1 X900 F1000")]));
            assert!(err.contains("disk gone"), "{lines} lines: {err}");
        }
    }

    /// The same bytes and summary for one and two worker threads over a
    /// program of several chunks.
    #[test]
    fn pipelined_output_does_not_depend_on_the_threads() {
        let m = match MachineTool::from_yaml_str(
            &std::fs::read_to_string(concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/machines/afm-r1000.yaml"
            ))
            .unwrap_or_default(),
            "afm.yaml",
        ) {
            Ok(m) => m,
            Err(e) => panic!("{e}"),
        };
        let mut setup = xyz_setup();
        setup.work_offsets[0] = Some([250.0, 150.0, 150.0]);
        let program = program_with(3 * CHUNK_LINES + 517, &[(40, "G2 X59 Y4 I10 J0")]);
        let mut outs = Vec::new();
        for threads in [1, 2] {
            let pool = match rayon::ThreadPoolBuilder::new().num_threads(threads).build() {
                Ok(p) => p,
                Err(e) => panic!("{e}"),
            };
            let mut job = plain_job(&m, setup.clone());
            job.pool = Some(&pool);
            let mut out = Vec::new();
            let summary = match job.run(program.as_bytes(), "p.nc", Some(&mut out), None) {
                Ok(s) => s,
                Err(e) => panic!("{e}"),
            };
            assert_eq!(summary.lines, 3 * CHUNK_LINES + 517);
            assert!(summary.changed > 3 * CHUNK_LINES);
            outs.push((out, summary.changed, summary.added));
        }
        assert!(outs[0] == outs[1]);
    }

    #[test]
    fn time_line_of_rapids_cycles_and_dwells() {
        let m = xyz_machine(
            "thermal:
  spindle: { idle_w_per_rpm: 1.0, growth_um_per_kw: 10, time_constant_min: 10 }
",
        );
        let mut setup = xyz_setup();
        setup.home = [0.0, 0.0, 500.0, 0.0, 0.0, 0.0];
        let job = plain_job(&m, setup);
        let program = "G0 X0 Y0 Z10\nS1000 M3\nG81 X30 Y40 Z-10 R2 F120\nG80\nG4 P1.5\n";
        let s = match job.run(program.as_bytes(), "p.nc", None, None) {
            Ok(s) => s,
            Err(e) => panic!("{e}"),
        };
        // Rapid Z 500 → 10: 490 mm at 60000 mm/min = 0.49 s.
        // Cycle: over the hole at Z10 (40 mm in Y, the longest) 0.04 s, down
        // to R2 (8 mm) 0.008 s, feed 12 mm at 120 mm/min = 6 s, back to the
        // initial Z10 (G98, 20 mm) 0.02 s. Dwell P1.5 (with a point: s) 1.5 s.
        let spun = 0.04 + 0.008 + 6.0 + 0.02 + 1.5;
        assert_abs_diff_eq!(s.duration_s, 0.49 + spun, epsilon = TIME_TOL_S);
        // The spindle (1 W/rpm · 1000 rpm) runs from the M3 on.
        assert_abs_diff_eq!(
            s.mean_power_w[0],
            1000.0 * spun / (0.49 + spun),
            epsilon = POWER_TOL_W
        );
        let mean = match job.mean_power(program.as_bytes(), "p.nc") {
            Ok(p) => p,
            Err(e) => panic!("{e}"),
        };
        assert_abs_diff_eq!(mean[0], s.mean_power_w[0], epsilon = POWER_TOL_W);
    }
}
