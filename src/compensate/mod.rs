//! Inverse solve and segmentation: for each programmed target find the
//! command whose predicted attained pose equals it, and split moves whose
//! compensated straight line (or arc) would leave the exact compensation by
//! more than the tolerance.

mod arc;
pub mod cycles;
pub mod outcome;
pub mod robot;
pub mod tcpm;

pub use arc::{ArcPiece, MAX_ARC_DEPTH};

use nalgebra::{SMatrix, SVector, Vector3};

use crate::machine::tool::MachineTool;
use crate::machine::{AxisVec, DirVec, TipPose};
use crate::predict::{Breakdown, LipschitzBound, MoveContext, ToolPredictor};
use crate::program::interp::{DIRECTION_DEADBAND, Motion, Move, Plan, PlanKind, directions};

pub use crate::limits::{MIN_TOLERANCE_MM, SOLVE_TOL_MM};
/// Convergence of the inverse solve on the tool direction, rad.
pub const SOLVE_TOL_RAD: f64 = 1e-8;
/// Largest number of solver iterations before a block is reported.
pub const MAX_ITER: usize = 50;
/// Deepest bisection of one move (2^16 segments).
pub const MAX_SPLIT_DEPTH: u32 = 16;
/// Weight (mm² per deg²) pulling rotary axes toward their programmed
/// values in the five-axis solve: a 0.01° change costs like 1 µm.
const ROTARY_WEIGHT: f64 = 1e-2;
/// Step size below which the five-axis solve has stalled, mm or deg.
const STALL_STEP: f64 = 1e-10;
/// Relative Levenberg damping of the five-axis solve.
const DAMPING: f64 = 1e-9;
/// Lever arm that weighs direction errors against position errors in the
/// five-axis solve, mm per rad.
const DIR_WEIGHT_MM: f64 = 100.0;

/// Allowance for rounding (mm) when a Lipschitz bound decides the outcome
/// of an evaluation without doing it.
const SKIP_MARGIN_MM: f64 = 1e-10;

/// The block's Lipschitz bound ([`ToolPredictor::lipschitz_bound`]),
/// computed on first use and then shared by every solve and piece of the
/// block (same predictor and tool length).
struct Lip<'m> {
    tool_mm: f64,
    v: std::cell::Cell<Option<Option<LipschitzBound<'m>>>>,
    /// The block's [`ToolPredictor::static_curvature_mm`], on first use.
    stat: std::cell::Cell<Option<f64>>,
}

impl<'m> Lip<'m> {
    fn new(tool_mm: f64) -> Self {
        Lip {
            tool_mm,
            v: std::cell::Cell::new(None),
            stat: std::cell::Cell::new(None),
        }
    }

    /// [`ToolPredictor::static_curvature_mm`] of the block.
    fn static_curvature(&self, pred: &ToolPredictor<'m>) -> f64 {
        match self.stat.get() {
            Some(v) => v,
            None => {
                let v = pred.static_curvature_mm();
                self.stat.set(Some(v));
                v
            }
        }
    }

    /// The bound on the segment `a → b`, as [`ToolPredictor::lipschitz`]
    /// gives it.
    fn on(&self, pred: &ToolPredictor<'m>, a: &AxisVec, b: &AxisVec) -> Option<f64> {
        let bound = match self.v.get() {
            Some(v) => v,
            None => {
                let v = pred.lipschitz_bound(self.tool_mm);
                self.v.set(Some(v));
                v
            }
        };
        bound?.on(a, b)
    }
}

/// Why a target could not be compensated.
#[derive(Debug, Clone, PartialEq)]
pub enum Failure {
    /// The solve did not reach the tolerance.
    NotConverged {
        /// Remaining error, mm.
        residual_mm: f64,
    },
    /// The compensated position leaves the travel of an axis.
    OutOfTravel {
        /// Axis letter.
        axis: char,
        /// Compensated value, mm or deg.
        value: f64,
        /// Travel limits.
        limits: (f64, f64),
    },
    /// The programmed position itself leaves the travel of an axis.
    ProgrammedOutOfTravel {
        /// Axis letter.
        axis: char,
        /// Programmed value, mm or deg.
        value: f64,
        /// Travel limits.
        limits: (f64, f64),
    },
    /// The move needs more segments than allowed.
    TooManySegments,
}

impl std::fmt::Display for Failure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Failure::NotConverged { residual_mm } => write!(
                f,
                "compensation did not converge (residual {residual_mm:.6} mm)"
            ),
            Failure::OutOfTravel {
                axis,
                value,
                limits,
            } => {
                write!(
                    f,
                    "compensated {axis} = {value:.4} is outside the travel [{}, {}]",
                    limits.0, limits.1
                )
            }
            Failure::ProgrammedOutOfTravel {
                axis,
                value,
                limits,
            } => {
                write!(
                    f,
                    "programmed {axis} = {value:.4} is outside the travel [{}, {}]",
                    limits.0, limits.1
                )
            }
            Failure::TooManySegments => write!(
                f,
                "the move would need more than {} segments to stay within the tolerance",
                1u32 << MAX_SPLIT_DEPTH
            ),
        }
    }
}

/// Settings of one compensation run.
#[derive(Debug, Clone, Copy)]
pub struct Settings {
    /// Largest allowed gap between the attained path and the programmed
    /// path along a move, mm; at least [`MIN_TOLERANCE_MM`] (below it no
    /// piece can be proven and long moves fail with
    /// [`Failure::TooManySegments`]; the command line refuses it).
    pub tolerance_mm: f64,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            tolerance_mm: 0.001,
        }
    }
}

/// The compensation of one block.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BlockResult {
    /// Compensated end point (cycles: the hole bottom), machine coordinates.
    pub end: AxisVec,
    /// Cycles: compensated machine Z of the R level.
    pub r_level: f64,
    /// Arcs whose last piece is an arc: its compensated centre.
    pub center: Option<Vector3<f64>>,
    /// Intermediate compensated points before `end` when the move is split.
    /// The block's own line goes to the first (to `end` when there are
    /// none), added lines to the others and then to `end`; each is reached
    /// by a straight move unless [`Self::arcs`] names it.
    pub segments: Vec<AxisVec>,
    /// The pieces of an arc that are written as arcs, in order of their
    /// targets (an arc kept whole: one piece to `end`).
    pub arcs: Vec<ArcPiece>,
    /// Takeup points among `segments` after the first (inside an arc, at a
    /// reversal of an axis), by index.
    pub takeup_at: Vec<usize>,
    /// Part of the arc is written as straight chords.
    pub arc_replaced: bool,
    /// The first of `segments` is a takeup point: the programmed start
    /// solved for this move, where the previous block's end (solved for its
    /// own directions of motion, load or temperature) would leave the
    /// attained point more than [`TAKEUP_SHARE`] of the tolerance away.
    /// Never while cutter radius compensation is active
    /// ([`Plan::cutter_comp`]): a short move against the direction of
    /// travel would upset the controller's offset path (an interference
    /// alarm or a gouge), so there the move starts where the machine
    /// stands, as before takeup points existed.
    pub takeup: bool,
    /// Predicted deviation of the uncompensated target, with its breakdown.
    pub deviation: Breakdown,
    /// Predicted position error left by the compensation, mm: at the
    /// compensated end point, or, where takeup points are not written
    /// (cutter radius compensation), at the start of a move that leaves
    /// from where the machine stands more than [`TAKEUP_SHARE`] of the
    /// tolerance off its programmed start.
    pub residual_mm: f64,
    /// The largest distance of a written piece of the block from the
    /// programmed path where the block holds one its proofs do not cover,
    /// mm: a canned-cycle hole drilled at one X and Y along its depth, a
    /// straight move whose pieces move an axis against the directions they
    /// were solved with, the gap a move starts with where no takeup is
    /// written (cutter radius compensation). 0 when none; the pipeline warns about the block
    /// and counts it when this exceeds the tolerance.
    pub miss_mm: f64,
    /// The directions of motion the block's end is solved with (its
    /// written pieces' own, see `straight`; an arc's at its end).
    pub dirs: DirVec,
    /// The directions of motion the block's first written piece (after a
    /// takeup point) is solved with, and its takeup point: `dirs` unless
    /// the pieces of a split move take different directions (an axis the
    /// block does not drive reversed by the correction's drift) or an
    /// arc's axes reverse inside it.
    pub start_dirs: DirVec,
    /// The end of travel a written point of the block is held at, where
    /// the correction would cross it by less than the tolerance (the
    /// largest such crossing of the block); `None` when none is.
    pub held: Option<HeldAtTravel>,
    /// A canned-cycle hole written as moves ([`cycles::expand`]): its
    /// lines in order; empty for every other block.
    pub expansion: Vec<cycles::Step>,
}

/// A compensated point held at an end of travel: the correction would
/// have taken the axis past it by less than the tolerance (a 2D program
/// whose tool stays at the reference position at the top of Z, say).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeldAtTravel {
    /// Axis letter.
    pub axis: char,
    /// The end of travel it is held at, mm or deg.
    pub end: f64,
    /// How far the correction would have crossed it, mm or deg.
    pub by: f64,
}

/// Solves for the command whose predicted attained pose equals the nominal
/// pose of `target` (programmed command). Rotary axes take part when the
/// machine has them; a three-axis machine matches the position only.
pub fn solve(
    pred: &ToolPredictor,
    target: &AxisVec,
    dirs: &DirVec,
    tool_mm: f64,
) -> Result<(AxisVec, f64), Failure> {
    let goal = pred.nominal(target, tool_mm);
    let lip = Lip::new(tool_mm);
    solve_from(pred, target, &goal, target, None, dirs, &lip)
}

/// [`solve`] started from the correction found at a nearby point: the
/// command `near_c` compensates the programmed `near_p`.
fn solve_near<'m>(
    pred: &ToolPredictor<'m>,
    target: &AxisVec,
    near_c: &AxisVec,
    near_p: &AxisVec,
    dirs: &DirVec,
    lip: &Lip<'m>,
) -> Result<(AxisVec, f64), Failure> {
    let tool_mm = lip.tool_mm;
    let mut start = *target;
    for s in 0..6 {
        let corr = near_c[s] - near_p[s];
        if corr.is_finite() {
            start[s] += corr;
        }
    }
    let goal = pred.nominal(target, tool_mm);
    solve_from(pred, target, &goal, &start, None, dirs, lip)
}

/// [`solve`] with the nominal pose `goal` of `target`, the iteration started
/// at the command `start`, and, when known, the attained pose at `start`.
/// `lip` holds the tool length and the block's Lipschitz bound.
fn solve_from<'m>(
    pred: &ToolPredictor<'m>,
    target: &AxisVec,
    goal: &TipPose,
    start: &AxisVec,
    mut first: Option<TipPose>,
    dirs: &DirVec,
    lip: &Lip<'m>,
) -> Result<(AxisVec, f64), Failure> {
    let tool_mm = lip.tool_mm;
    let goal = *goal;
    let m = pred.machine;
    let rotary = (3..6).any(|s| m.has_axis(s));
    let mut c = *start;
    if !rotary {
        for it in 0..MAX_ITER {
            let got = match first.take() {
                Some(p) => p,
                None => pred.attained(&c, dirs, tool_mm),
            };
            let r = got.pos - goal.pos;
            let rn = r.norm();
            if rn < SOLVE_TOL_MM {
                return Ok((c, rn));
            }
            let prev = c;
            for i in 0..3 {
                c[i] -= r[i];
            }
            // The step moved the command by exactly the residual, so the
            // next residual is the change of the error over the step: at
            // most L·|r|. When that is certainly below the tolerance, the
            // next evaluation would only confirm convergence; the bound is
            // reported as the residual.
            if it + 1 < MAX_ITER {
                if let Some(l) = lip.on(pred, &prev, &c) {
                    let bound = l * rn + SKIP_MARGIN_MM;
                    if bound < SOLVE_TOL_MM / 2.0 {
                        return Ok((c, bound));
                    }
                }
            }
        }
        let r = (pred.attained(&c, dirs, tool_mm).pos - goal.pos).norm();
        return Err(Failure::NotConverged { residual_mm: r });
    }
    // Gauss–Newton on the machine's axes with a finite-difference Jacobian.
    // The machine's axis slots, without allocating on the per-block path.
    let mut slot_buf = [0usize; 6];
    let mut n_slots = 0;
    for s in (0..6).filter(|&s| m.has_axis(s)) {
        slot_buf[n_slots] = s;
        n_slots += 1;
    }
    let slots = &slot_buf[..n_slots];
    let resid = |c: &AxisVec| -> SVector<f64, 6> {
        let got = pred.attained(c, dirs, tool_mm);
        residual(&got, &goal)
    };
    for _ in 0..MAX_ITER {
        let r = resid(&c);
        let pos_err = Vector3::new(r[0], r[1], r[2]).norm();
        let dir_err = Vector3::new(r[3], r[4], r[5]).norm() / DIR_WEIGHT_MM;
        if pos_err < SOLVE_TOL_MM && dir_err < SOLVE_TOL_RAD {
            return Ok((c, pos_err));
        }
        let mut jac = SMatrix::<f64, 6, 6>::zeros();
        for (k, &s) in slots.iter().enumerate() {
            let h = if s < 3 { 1e-4 } else { 1e-5 };
            let mut cp = c;
            let mut cm = c;
            cp[s] += h;
            cm[s] -= h;
            let col = (resid(&cp) - resid(&cm)) / (2.0 * h);
            jac.set_column(k, &col);
        }
        let n = slots.len();
        let jtj = jac.transpose() * jac;
        let mut jtr = jac.transpose() * r;
        // Only the first n columns are used; pad the rest with identity.
        // Damped (Levenberg) step: near a singular configuration (C on its
        // own axis, A at zero) one axis barely changes the pose and the
        // plain normal equations are singular.
        let mut a = jtj;
        let scale = (0..n).map(|k| a[(k, k)]).fold(0.0, f64::max).max(1e-12);
        for k in 0..n {
            a[(k, k)] += DAMPING * scale;
        }
        // Tikhonov pull of the rotary axes toward their programmed values, so
        // that neighbouring targets get neighbouring solutions where the
        // direction leaves a rotary axis undetermined (C at A = 0).
        for (k, &s) in slots.iter().enumerate() {
            if s >= 3 {
                a[(k, k)] += ROTARY_WEIGHT;
                jtr[k] += ROTARY_WEIGHT * (c[s] - target[s]);
            }
        }
        for k in n..6 {
            a[(k, k)] = 1.0;
        }
        let Some(step) = a.lu().solve(&jtr) else {
            break;
        };
        for (k, &s) in slots.iter().enumerate() {
            c[s] -= step[k];
        }
        // The direction cannot always be reached (an AC table at A = 0 cannot
        // tilt the tool about Y): once the position is met and the step has
        // stalled, the rest is a tool-orientation error to report.
        if step.amax() < STALL_STEP {
            break;
        }
    }
    // The position comes first: finish it with the linear axes alone.
    for _ in 0..MAX_ITER {
        let r = pred.attained(&c, dirs, tool_mm).pos - goal.pos;
        if r.norm() < SOLVE_TOL_MM {
            return Ok((c, r.norm()));
        }
        for i in 0..3 {
            c[i] -= r[i];
        }
    }
    let r = resid(&c);
    Err(Failure::NotConverged {
        residual_mm: Vector3::new(r[0], r[1], r[2]).norm(),
    })
}

fn residual(got: &TipPose, goal: &TipPose) -> SVector<f64, 6> {
    let dp = got.pos - goal.pos;
    let dd = (got.dir - goal.dir) * DIR_WEIGHT_MM;
    SVector::<f64, 6>::new(dp[0], dp[1], dp[2], dd[0], dd[1], dd[2])
}

fn lerp(a: &AxisVec, b: &AxisVec, t: f64) -> AxisVec {
    let mut o = [0.0; 6];
    for i in 0..6 {
        o[i] = a[i] + (b[i] - a[i]) * t;
    }
    o
}

/// The programmed end of a move must lie in the travel before anything is
/// solved or split (a wild target would otherwise surface as a segment or
/// convergence failure).
fn check_programmed_travel(pred: &ToolPredictor, p: &AxisVec) -> Result<(), Failure> {
    programmed_travel(pred.machine, p)
}

/// [`check_programmed_travel`] against a machine (also for `check`, which
/// solves nothing).
pub(crate) fn programmed_travel(m: &MachineTool, p: &AxisVec) -> Result<(), Failure> {
    match travel(m, p) {
        Err(Failure::OutOfTravel {
            axis,
            value,
            limits,
        }) => Err(Failure::ProgrammedOutOfTravel {
            axis,
            value,
            limits,
        }),
        other => other,
    }
}

/// Rounding allowance of the travel limits, mm or deg.
const TRAVEL_SLACK: f64 = 1e-9;

/// Solves of one block at most, each with the directions of motion the
/// pieces of the solve before it really take, until they agree.
const DIR_PASSES: usize = 3;

fn check_travel(pred: &ToolPredictor, c: &AxisVec) -> Result<(), Failure> {
    travel(pred.machine, c)
}

/// Every axis of `c` within the travel, or beyond an end by at most
/// `hold` (the tolerance: [`hold_at_travel`] holds it at the end).
fn check_travel_within(pred: &ToolPredictor, c: &AxisVec, hold: f64) -> Result<(), Failure> {
    travel_within(pred.machine, c, hold.max(TRAVEL_SLACK))
}

/// Every axis of `c` within the travel of `m`.
fn travel(m: &MachineTool, c: &AxisVec) -> Result<(), Failure> {
    travel_within(m, c, TRAVEL_SLACK)
}

/// Every axis of `c` within the travel of `m`, give or take `slack`.
fn travel_within(m: &MachineTool, c: &AxisVec, slack: f64) -> Result<(), Failure> {
    for (s, &letter) in crate::machine::AXIS_LETTERS.iter().enumerate() {
        if let Some((lo, hi)) = m.travel(s) {
            if c[s] < lo - slack || c[s] > hi + slack {
                return Err(Failure::OutOfTravel {
                    axis: letter as char,
                    value: c[s],
                    limits: (lo, hi),
                });
            }
        }
    }
    Ok(())
}

/// The written points of `res` (its split points and end) within the
/// travel: a point the correction takes past an end by less than `tol` is
/// held at the end (the largest such crossing named in
/// [`BlockResult::held`]); one farther is refused. Returns whether a point
/// was held.
fn hold_at_travel(pred: &ToolPredictor, res: &mut BlockResult, tol: f64) -> Result<bool, Failure> {
    let m = pred.machine;
    check_travel_within(pred, &res.end, tol)?;
    for p in &res.segments {
        check_travel_within(pred, p, tol)?;
    }
    let mut held: Option<HeldAtTravel> = None;
    for p in res.segments.iter_mut().chain(std::iter::once(&mut res.end)) {
        for (s, &letter) in crate::machine::AXIS_LETTERS.iter().enumerate() {
            let Some((lo, hi)) = m.travel(s) else {
                continue;
            };
            let end = p[s].clamp(lo, hi);
            let by = (p[s] - end).abs();
            if by > TRAVEL_SLACK {
                p[s] = end;
                if held.is_none_or(|h| by > h.by) {
                    held = Some(HeldAtTravel {
                        axis: letter as char,
                        end,
                        by,
                    });
                }
            }
        }
    }
    res.held = held;
    Ok(held.is_some())
}

/// Largest number of model breakpoints considered inside one move; a move
/// crossing more is bisected at its midpoints.
const MAX_BREAKS: usize = 64;
/// Crossings closer than this to a piece's end (as a fraction of the piece)
/// are not used as split points.
const BREAK_MARGIN: f64 = 1e-6;

/// Splits the straight move `p0 → p1` (programmed commands) into compensated
/// points so that, between consecutive points, the attained path stays
/// within `tol` of the programmed one. Pushes the points after `c0`, the
/// final one `c1` only with `keep_end` (so that a move that needs no split
/// pushes nothing and allocates nothing).
///
/// `c1` must be a solution of `p1` (residual below [`SOLVE_TOL_MM`] with
/// `dirs`, `tool` and the predictor's context); `c0` is where the machine
/// starts, with `start_gap` (at least [`SOLVE_TOL_MM`]) the distance from
/// its attained point to the nominal point of `p0` — [`SOLVE_TOL_MM`] when
/// it is a solution of `p0` too, more when it was solved for the previous
/// block's directions of motion, load or temperature.
///
/// The error model is piecewise linear in each axis position (component
/// tables, stiffness grid), so the exact compensation of a straight move
/// has its kinks where a moving axis crosses a breakpoint of the model.
/// A piece that fails the tolerance check is cut at the crossing nearest
/// its middle (at its middle when it crosses none): the pieces follow the
/// kinks instead of halving across them.
#[allow(clippy::too_many_arguments)]
fn split_line<'m>(
    pred: &ToolPredictor<'m>,
    p0: &AxisVec,
    p1: &AxisVec,
    c0: &AxisVec,
    c1: &AxisVec,
    start_gap: f64,
    dirs: &DirVec,
    lip: &Lip<'m>,
    (tol, grid): (f64, Option<&Grid>),
    keep_end: bool,
    out: &mut Vec<AxisVec>,
) -> Result<(), Failure> {
    let mut ts = [0.0f64; MAX_BREAKS];
    let n = crossings(pred, p0, p1, &mut ts);
    let ts = ts.get(..n).unwrap_or(&[]);
    let tool = lip.tool_mm;
    // Without rotary axes the nominal chain is a translation, affine in the
    // command: the nominal point of a blend is the blend of the nominal points.
    let affine = !(3..6).any(|s| pred.machine.has_axis(s));
    let ends = affine.then(|| (pred.nominal(p0, tool).pos, pred.nominal(p1, tool).pos));
    let piece = Piece {
        pred,
        p0,
        p1,
        ends,
        ts,
        dirs,
        lip,
        tol,
        grid,
        keep_end,
    };
    piece.split(0.0, 1.0, c0, c1, start_gap, 0, out)
}

/// Parameters in (0, 1), sorted, where the straight move `p0 → p1` crosses
/// a breakpoint of the error model; 0 when there are more than `ts` holds.
fn crossings(pred: &ToolPredictor, p0: &AxisVec, p1: &AxisVec, ts: &mut [f64]) -> usize {
    let mut n = 0;
    for s in 0..6 {
        let (a, b) = (p0[s], p1[s]);
        let d = b - a;
        let inner = breaks_inside(pred, s, a, b);
        if n + inner.len() > ts.len() {
            return 0;
        }
        for &x in inner {
            if let Some(slot) = ts.get_mut(n) {
                *slot = (x - a) / d;
                n += 1;
            }
        }
    }
    if let Some(t) = ts.get_mut(..n) {
        t.sort_unstable_by(f64::total_cmp);
    }
    n
}

/// The breakpoints of slot `s` strictly between the positions `a` and `b`
/// (none when they are equal or not finite), ascending.
fn breaks_inside<'m>(pred: &ToolPredictor<'m>, s: usize, a: f64, b: f64) -> &'m [f64] {
    if a == b || !(b - a).is_finite() {
        return &[];
    }
    let bp = pred.machine.breakpoints(s);
    let (lo, hi) = if a < b { (a, b) } else { (b, a) };
    let i0 = bp.partition_point(|&x| x <= lo);
    let i1 = bp.partition_point(|&x| x < hi);
    bp.get(i0..i1).unwrap_or(&[])
}

/// One straight move being split: its programmed ends, the nominal tip at
/// both ends (machines without rotary axes) and its breakpoint crossings.
struct Piece<'a, 'p> {
    pred: &'a ToolPredictor<'p>,
    lip: &'a Lip<'p>,
    p0: &'a AxisVec,
    p1: &'a AxisVec,
    ends: Option<(Vector3<f64>, Vector3<f64>)>,
    ts: &'a [f64],
    dirs: &'a DirVec,
    tol: f64,
    /// The grid of the written words (a piece whose travel it reads on
    /// either side of the deadband of a direction of motion is halved).
    grid: Option<&'a Grid>,
    keep_end: bool,
}

impl Piece<'_, '_> {
    /// Nominal tip at parameter `t` of the move.
    fn nominal(&self, t: f64) -> Vector3<f64> {
        match &self.ends {
            Some((a, b)) => a + (b - a) * t,
            None => {
                self.pred
                    .nominal(&lerp(self.p0, self.p1, t), self.lip.tool_mm)
                    .pos
            }
        }
    }

    /// Splits the part `ta..tb` of the move (compensated ends `ca`, `cb`;
    /// `ga` the gap at `ca`, [`SOLVE_TOL_MM`] where it is solved).
    #[allow(clippy::too_many_arguments)]
    fn split(
        &self,
        ta: f64,
        tb: f64,
        ca: &AxisVec,
        cb: &AxisVec,
        ga: f64,
        depth: u32,
        out: &mut Vec<AxisVec>,
    ) -> Result<(), Failure> {
        // The end is solved (residual below SOLVE_TOL_MM), the start's gap
        // is `ga`, and the nominal chain is affine, so the gap at any point
        // of the piece is at most the larger end gap plus L·|cb − ca| (the
        // error's departure from its chord): when that meets the
        // tolerance, the check below would pass.
        let ga = ga.max(SOLVE_TOL_MM);
        if self.ends.is_some() {
            if let Some(l) = self.lip.on(self.pred, ca, cb) {
                let dc = (0..3).map(|s| (cb[s] - ca[s]).powi(2)).sum::<f64>().sqrt();
                if ga + l * dc + SKIP_MARGIN_MM <= self.tol {
                    if tb < 1.0 || self.keep_end {
                        out.push(*cb);
                    }
                    return Ok(());
                }
            }
        }
        let verdict = if self.ends.is_some() {
            self.certify(ta, tb, ca, cb, ga)
        } else {
            None
        };
        let pass = match verdict {
            Some(pass) => pass,
            None => self.sampled(ta, tb, ca, cb),
        };
        // A piece whose written travel in an axis may be read on either
        // side of the deadband is halved (each half travels half of it,
        // well inside the deadband): read back, it keeps the directions it
        // was solved with. At the deepest split it stays, and its miss is
        // measured under both readings.
        let ambiguous = pass
            && depth < MAX_SPLIT_DEPTH
            && self
                .grid
                .is_some_and(|g| (0..3).any(|s| g.ambiguous(s, ca[s], cb[s])));
        if pass && !ambiguous {
            // `tb` is exactly 1 only for the last piece of the move.
            if tb < 1.0 || self.keep_end {
                out.push(*cb);
            }
            return Ok(());
        }
        if depth >= MAX_SPLIT_DEPTH {
            return Err(Failure::TooManySegments);
        }
        // The crossing nearest the middle of the part, or the middle (an
        // ambiguous piece: the middle).
        let mid = (ta + tb) / 2.0;
        let margin = (tb - ta) * BREAK_MARGIN;
        let tm = self
            .ts
            .iter()
            .copied()
            .filter(|&t| !ambiguous && t > ta + margin && t < tb - margin)
            .min_by(|x, y| (x - mid).abs().total_cmp(&(y - mid).abs()))
            .unwrap_or(mid);
        let pa = lerp(self.p0, self.p1, ta);
        let pm = lerp(self.p0, self.p1, tm);
        let (cm, _) = solve_near(self.pred, &pm, ca, &pa, self.dirs, self.lip)?;
        self.split(ta, tm, ca, &cm, ga, depth + 1, out)?;
        self.split(tm, tb, &cm, cb, SOLVE_TOL_MM, depth + 1, out)
    }

    /// Whether the compensated straight piece `ca → cb` (programmed part
    /// `ta..tb`) keeps the attained point within the tolerance of the
    /// programmed one everywhere, proven rather than sampled (machines
    /// whose nominal chain is affine and whose error model has the cell
    /// form); `None` where the proof does not apply (the caller samples).
    ///
    /// Between two breakpoints crossed by the compensated piece the gap
    /// `g(f) = attained(c(f)) − nominal(t(f))` is smooth, and `|g|` is at
    /// most the larger of its end values plus `M₂ h² / 8`, where `h` is the
    /// length of that stretch (mm) and `M₂` bounds `|g''|`
    /// ([`ToolPredictor::curvature`]; the nominal part is affine). The end
    /// of the piece is solved (gap below [`SOLVE_TOL_MM`]), its start has
    /// the gap `ga`; the gap is evaluated at each crossing.
    fn certify(&self, ta: f64, tb: f64, ca: &AxisVec, cb: &AxisVec, ga: f64) -> Option<bool> {
        let budget = self.tol - SKIP_MARGIN_MM;
        if ga > budget {
            return Some(false);
        }
        let (inner, total) = self.inside(ca, cb);
        let stretches = Stretches::new(self, ta, tb, ca, cb, budget);
        if total > MAX_BREAKS {
            return self.certify_in_order(&inner, &stretches, ga);
        }
        let mut fs = [0.0f64; MAX_BREAKS + 2];
        let mut n = 1;
        let mut axes_crossing = 0;
        for (s, xs) in inner.iter().enumerate() {
            if xs.is_empty() {
                continue;
            }
            let (a, d) = (ca[s], cb[s] - ca[s]);
            axes_crossing += 1;
            // In the order of the piece: ascending parameters.
            let first = n;
            for &x in xs.iter() {
                *fs.get_mut(n)? = ((x - a) / d).clamp(0.0, 1.0);
                n += 1;
            }
            if d < 0.0 {
                fs.get_mut(first..n)?.reverse();
            }
        }
        if axes_crossing > 1 {
            fs.get_mut(1..n)?.sort_unstable_by(f64::total_cmp);
        }
        *fs.get_mut(n)? = 1.0;
        let fs = fs.get(..=n)?;
        // The gap at each crossing (both ends are solved): a crossing beyond
        // the tolerance fails the piece at once.
        // Crossings from the middle of the piece outwards: the gap of a
        // failing piece is largest there most often, so a failure usually
        // costs one evaluation.
        let mut gaps = [SOLVE_TOL_MM; MAX_BREAKS + 2];
        gaps[0] = ga;
        let centre = fs.get(1..n)?.partition_point(|&f| f < 0.5) + 1;
        let (mut lo, mut hi) = (centre, centre);
        while lo > 1 || hi < n {
            let up = hi < n && (lo <= 1 || *fs.get(hi)? - 0.5 <= 0.5 - *fs.get(lo - 1)?);
            let k = if up {
                hi += 1;
                hi - 1
            } else {
                lo -= 1;
                lo
            };
            match stretches.gap(*fs.get(k)?) {
                Some(gap) => *gaps.get_mut(k)? = gap,
                None => return Some(false),
            }
        }
        // Then the bend of each stretch between crossings.
        let mut unknown = false;
        for (k, w) in fs.windows(2).enumerate() {
            let [fa, fb] = [*w.first()?, *w.get(1)?];
            let base = gaps.get(k)?.max(*gaps.get(k + 1)?);
            match stretches.bend_fits(fa, fb, base) {
                Some(false) => return Some(false),
                Some(true) => {}
                None => unknown = true,
            }
        }
        (!unknown).then_some(true)
    }

    /// Per axis, the breakpoints strictly inside the compensated piece
    /// `ca → cb`, and how many there are in all.
    fn inside(&self, ca: &AxisVec, cb: &AxisVec) -> ([&[f64]; 3], usize) {
        let inner: [&[f64]; 3] = [0, 1, 2].map(|s| breaks_inside(self.pred, s, ca[s], cb[s]));
        (inner, inner.iter().map(|x| x.len()).sum())
    }

    /// [`Self::certify`] for a piece crossing more breakpoints than its
    /// arrays hold (fine-pitch tables): the crossings of the three axes are
    /// merged in the order of the piece and each stretch is checked as it
    /// comes, without storing them.
    fn certify_in_order(&self, inner: &[&[f64]; 3], st: &Stretches, ga: f64) -> Option<bool> {
        let (ca, cb) = (st.ca, st.cb);
        // Per axis, how many of its crossings are taken.
        let mut taken = [0usize; 3];
        let next = |s: usize, taken: &[usize; 3]| -> Option<f64> {
            let xs = inner.get(s)?;
            let k = *taken.get(s)?;
            let d = cb[s] - ca[s];
            let x = if d > 0.0 {
                xs.get(k)?
            } else {
                xs.get(xs.len().checked_sub(k + 1)?)?
            };
            Some(((x - ca[s]) / d).clamp(0.0, 1.0))
        };
        let (mut f_prev, mut gap_prev) = (0.0, ga);
        // A stretch neither bend bound applies to: the verdict is then the
        // samples' (as in the array path), unless a crossing fails.
        let mut unknown = false;
        loop {
            let pick = (0..3)
                .filter_map(|s| next(s, &taken).map(|f| (s, f)))
                .min_by(|a, b| a.1.total_cmp(&b.1));
            let (f, gap) = match pick {
                Some((s, f)) => {
                    *taken.get_mut(s)? += 1;
                    match st.gap(f) {
                        Some(g) => (f, g),
                        None => return Some(false),
                    }
                }
                None => (1.0, SOLVE_TOL_MM),
            };
            match st.bend_fits(f_prev, f, gap_prev.max(gap)) {
                Some(false) => return Some(false),
                Some(true) => {}
                None => unknown = true,
            }
            if pick.is_none() {
                return (!unknown).then_some(true);
            }
            (f_prev, gap_prev) = (f, gap);
        }
    }

    /// Whether the gap along the piece, bounded by [`piece_bound`], is
    /// within the tolerance (the check where [`Self::certify`] does not
    /// apply): the gap is the distance of the attained point from the
    /// nominal point at the same share of the programmed part.
    fn sampled(&self, ta: f64, tb: f64, ca: &AxisVec, cb: &AxisVec) -> bool {
        #[cfg(test)]
        tests::SAMPLED.with(|n| n.set(n.get() + 1));
        let gap = |f: f64, q: Vector3<f64>| (q - self.nominal(ta + (tb - ta) * f)).norm();
        let tool = self.lip.tool_mm;
        piece_bound(
            self.pred,
            (ca, cb),
            self.dirs,
            (tool, self.tol, self.tol),
            &gap,
        ) <= self.tol
    }
}

/// What [`Piece::certify`] needs of one compensated piece: the gap at a
/// parameter and the bend of a stretch between two crossings.
struct Stretches<'a, 'b, 'p> {
    piece: &'a Piece<'b, 'p>,
    ta: f64,
    tb: f64,
    ca: &'a AxisVec,
    cb: &'a AxisVec,
    budget: f64,
    /// Length of the piece, mm of command.
    len: f64,
    /// The machine-wide bend bound on this piece, on first use (a piece
    /// that fails at a crossing never needs it).
    global: std::cell::Cell<Option<Option<f64>>>,
}

impl<'a, 'b, 'p> Stretches<'a, 'b, 'p> {
    fn new(
        piece: &'a Piece<'b, 'p>,
        ta: f64,
        tb: f64,
        ca: &'a AxisVec,
        cb: &'a AxisVec,
        budget: f64,
    ) -> Self {
        Stretches {
            piece,
            ta,
            tb,
            ca,
            cb,
            budget,
            len: (0..3).map(|s| (cb[s] - ca[s]).powi(2)).sum::<f64>().sqrt(),
            global: std::cell::Cell::new(None),
        }
    }

    /// [`ToolPredictor::curvature`] of the piece.
    fn global(&self) -> Option<f64> {
        if let Some(g) = self.global.get() {
            return g;
        }
        let p = self.piece;
        let stat = p.lip.static_curvature(p.pred);
        let g = p.pred.curvature(self.ca, self.cb, p.lip.tool_mm, stat);
        self.global.set(Some(g));
        g
    }

    /// The gap at parameter `f` of the piece (at least the solve
    /// tolerance), or `None` beyond the budget (NaN included).
    fn gap(&self, f: f64) -> Option<f64> {
        let p = self.piece;
        let got = p
            .pred
            .attained(&lerp(self.ca, self.cb, f), p.dirs, p.lip.tool_mm)
            .pos;
        let gap = (got - p.nominal(self.ta + (self.tb - self.ta) * f)).norm();
        (gap <= self.budget).then_some(gap.max(SOLVE_TOL_MM))
    }

    /// Whether the stretch `fa..fb` (no breakpoint inside) stays within the
    /// budget with `base` the larger gap at its ends: the machine's global
    /// bend bound first, the stretch's own where that is too loose. `None`
    /// where neither applies (the piece is then sampled).
    fn bend_fits(&self, fa: f64, fb: f64, base: f64) -> Option<bool> {
        // The stretches come in order (fb ≥ fa); the length is taken
        // whatever the order, so a wrong one could not skip the bend.
        let h = (fb - fa).abs() * self.len;
        if h == 0.0 {
            return Some(base <= self.budget);
        }
        let fits = |m2: f64| base + m2 * h * h / 8.0 <= self.budget;
        let global = self.global();
        if global.is_some_and(fits) {
            return Some(true);
        }
        let p = self.piece;
        match p.pred.curvature_in_cell(
            &lerp(self.ca, self.cb, fa),
            &lerp(self.ca, self.cb, fb),
            p.dirs,
            p.lip.tool_mm,
        ) {
            Some(m2) => Some(fits(m2)),
            // Split: the global bound shrinks with h², so the pieces of a
            // machine without the cell form (a table value of −0) are
            // proven too, only shorter.
            None if global.is_some() => Some(false),
            None => None,
        }
    }
}

fn dirs_of(t: &Vector3<f64>, base: &DirVec) -> DirVec {
    let mut d = *base;
    for i in 0..3 {
        if t[i].abs() > 1e-9 {
            d[i] = if t[i] > 0.0 { 1 } else { -1 };
        }
    }
    d
}

fn with_xyz(base: &AxisVec, p: &Vector3<f64>) -> AxisVec {
    let mut o = *base;
    o[0] = p[0];
    o[1] = p[1];
    o[2] = p[2];
    o
}

/// Share of the tolerance up to which a move starts from where the
/// previous block left the machine; beyond it a takeup move comes first.
pub const TAKEUP_SHARE: f64 = 0.5;

/// Share of the tolerance up to which a move that may not start with a
/// takeup point (cutter radius compensation) is proven from where the
/// machine stands, the gap there counted: its pieces are split until they
/// fit. Beyond it the split could not end (the first piece keeps the gap
/// however short it gets), and the gap is left over and warned about.
pub const NO_TAKEUP_SHARE: f64 = 0.9;

/// How far from the programmed start `p0` the machine is when it stands at
/// the command `at` and moves off with the directions of motion `dirs`, mm.
fn start_gap(pred: &ToolPredictor, p0: &AxisVec, at: &AxisVec, dirs: &DirVec, tool: f64) -> f64 {
    (pred.attained(at, dirs, tool).pos - pred.nominal(p0, tool).pos).norm()
}

/// How a move that starts at the programmed `p0` begins when the machine
/// stands at the command `at`, solved for the previous block's directions
/// of motion, load or temperature. While the attained point of `at` under
/// this move's conditions stays within [`TAKEUP_SHARE`] of the tolerance
/// of the nominal start, the move starts from `at` and its pieces are
/// proven with that gap. Otherwise (typically an axis that reverses: the
/// direction-dependent error changes at once) the start solved for this
/// move is pushed to `out` as a takeup point — the machine first moves
/// there, as a controller's reversal compensation would, so that the move
/// itself leaves from the programmed point. A takeup point the correction
/// takes past an end of travel by less than the tolerance is held at the
/// end, as the written points are ([`hold_at_travel`]), and the move's
/// pieces are proven with the gap it leaves there. Without `takeups`
/// (cutter radius compensation active, see [`BlockResult::takeup`]), the
/// move starts from `at` and its pieces are proven with the gap up to
/// [`NO_TAKEUP_SHARE`] of the tolerance. A larger gap, or one where the
/// takeup point lies farther beyond an end of travel, cannot be proven
/// away: it is returned as left over, and the pieces are fitted from the
/// start solved for this move ([`Start::fit`]), where the split can end.
fn start_from<'m>(
    pred: &ToolPredictor<'m>,
    p0: &AxisVec,
    at: &AxisVec,
    dirs: &DirVec,
    lip: &Lip<'m>,
    (tol, takeups): (f64, bool),
    out: &mut Vec<AxisVec>,
) -> Result<Start, Failure> {
    let gap = start_gap(pred, p0, at, dirs, lip.tool_mm);
    let from_at = |gap: f64| Start {
        c: *at,
        fit: *at,
        gap: gap.max(SOLVE_TOL_MM),
        takeup: false,
        left_mm: 0.0,
    };
    if gap <= tol * TAKEUP_SHARE || (!takeups && gap <= tol * NO_TAKEUP_SHARE) {
        // Within the share, or no takeup may be written and the gap can
        // be proven: the move leaves from where the machine stands, and
        // its pieces are proven with that gap.
        return Ok(from_at(gap));
    }
    let (c0, _) = solve_near(pred, p0, at, p0, dirs, lip)?;
    let left = Start {
        c: *at,
        fit: c0,
        gap: SOLVE_TOL_MM,
        takeup: false,
        left_mm: gap,
    };
    if !takeups {
        return Ok(left);
    }
    let held = match check_travel(pred, &c0) {
        Ok(()) => None,
        // The start solved for this move lies beyond an end of travel
        // (a move straight out of a point at the end of Z, say): by less
        // than the tolerance it is held at the end.
        Err(_) if check_travel_within(pred, &c0, tol).is_ok() => {
            let mut h = c0;
            for (s, v) in h.iter_mut().enumerate() {
                if let Some((lo, hi)) = pred.machine.travel(s) {
                    *v = v.clamp(lo, hi);
                }
            }
            Some(h)
        }
        // Farther: the machine cannot stand there, so the move starts
        // where it stands and the gap is left over.
        Err(_) => return Ok(left),
    };
    let Some(h) = held else {
        out.push(c0);
        return Ok(Start {
            c: c0,
            fit: c0,
            gap: SOLVE_TOL_MM,
            takeup: true,
            left_mm: 0.0,
        });
    };
    let g = start_gap(pred, p0, &h, dirs, lip.tool_mm);
    if g >= gap {
        // Held, the takeup point would bring the start no closer.
        return Ok(left);
    }
    out.push(h);
    Ok(if g <= tol * NO_TAKEUP_SHARE {
        Start {
            c: h,
            fit: h,
            gap: g.max(SOLVE_TOL_MM),
            takeup: true,
            left_mm: 0.0,
        }
    } else {
        Start {
            c: h,
            fit: c0,
            gap: SOLVE_TOL_MM,
            takeup: true,
            left_mm: g,
        }
    })
}

/// Where a move starts ([`start_from`]).
struct Start {
    /// The start command: where the machine stands when the move leaves.
    c: AxisVec,
    /// The command the proof of the first piece starts from: `c`, or
    /// where a gap is left over, the start solved for the move (the piece
    /// leaves from `c`, and the gap left is its miss there).
    fit: AxisVec,
    /// The start's gap that the proof of the first piece counts, mm (at
    /// least [`SOLVE_TOL_MM`]).
    gap: f64,
    /// A takeup point was pushed.
    takeup: bool,
    /// The gap left at the start, beyond what the proof counts, mm (0
    /// unless takeup points are not allowed or the start is held at an end
    /// of travel).
    left_mm: f64,
}

/// Compensates one interpreted block.
pub fn block(
    pred: &ToolPredictor,
    plan: &Plan,
    settings: &Settings,
) -> Result<BlockResult, Failure> {
    block_after(pred, plan, settings, &mut None)
}

/// The compensated end of a block, handed to the next block of a run of
/// blocks compensated in order (see [`block_after`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Carry {
    /// Programmed end point, machine coordinates.
    target: AxisVec,
    /// Directions of motion it was solved with.
    dirs: DirVec,
    /// Tool length, mm.
    tool: f64,
    /// Block context it was solved with.
    ctx: MoveContext,
    /// Where the block left the machine: the compensated command.
    c: AxisVec,
    /// `c` is the solution of `target` (false after a positioning move that
    /// leaves some axes where they were).
    solved: bool,
    /// Positioning moves in a row that left axes where they were, up to
    /// this block (a chain longer than [`CARRY_LOOKBACK`] ends the carry,
    /// as [`carry_before`] does not look back further).
    positioned: usize,
    /// The axes (bit `s` for axis `s`) whose command `c` holds. At the
    /// start of a program no axis is known ([`Carry::program_start`]); the
    /// positioning moves there name them one by one (`G0 X Y`, then
    /// `G43 H1 Z`), and a straight move starts from the carry once every
    /// axis of the machine is known.
    known: u8,
    /// The direction each axis last moved in on the written pieces, as the
    /// interpreter reads them from the compensated program
    /// ([`directions`] of each piece, the deadband included): the state
    /// the next block's pieces start from.
    moved: DirVec,
    /// After a canned-cycle hole: the initial level of the cycle in force,
    /// programmed (machine Z) and as commanded in the written program
    /// (where the tool stood when the cycle began), the level a G98 hole
    /// returns to also after G99 holes (Fanuc, Haas).
    initial: Option<(f64, f64)>,
}

/// Every axis known (see [`Carry::known`]).
const ALL_AXES: u8 = 0b11_1111;

impl Carry {
    /// Where the machine stands at the start of a program: at its
    /// reference position `home` (where the interpreter starts too),
    /// commanded there uncompensated, every axis last moved in the +
    /// direction. Seeds a run that begins with the program's first block,
    /// so that the positioning moves there, each naming some axes, leave a
    /// carry the first feed move starts from, and an axis the program
    /// never names (a rotary axis of a five-axis machine) is known where
    /// it stands.
    pub fn program_start(home: AxisVec) -> Self {
        Carry {
            target: home,
            dirs: [1; 6],
            tool: 0.0,
            ctx: MoveContext::default(),
            c: home,
            solved: false,
            positioned: 0,
            known: ALL_AXES,
            moved: [1; 6],
            initial: None,
        }
    }

    /// The command of every axis is known.
    fn complete(&self) -> bool {
        self.known == ALL_AXES
    }

    /// The machine stands at a known command whose programmed point is `p`.
    fn stands_at(&self, p: &AxisVec) -> bool {
        self.complete() && self.target == *p
    }

    fn matches(&self, target: &AxisVec, dirs: &DirVec, tool: f64, ctx: &MoveContext) -> bool {
        self.complete()
            && self.solved
            && self.target == *target
            && self.dirs == *dirs
            && self.tool == tool
            && self.ctx == *ctx
    }

    /// Where the move `mv` of `plan`, whose end is solved as `c1`, leaves
    /// the machine, given where the block before left it. A positioning
    /// move leaves the axes it does not program where they were (`None`
    /// when that is not known, or after more than [`CARRY_LOOKBACK`] such
    /// moves in a row).
    fn after(
        pred: &ToolPredictor,
        plan: &Plan,
        mv: &Move,
        c1: AxisVec,
        before: Option<&Carry>,
    ) -> Option<Carry> {
        Self::standing(pred, plan, mv, c1, true, before)
    }

    /// Where a move to a machine-defined place (G28, G53), which is not
    /// compensated, leaves the machine: its programmed axes at their
    /// commanded end, the others where the block before left them (`None`
    /// when that is not known, or after more than [`CARRY_LOOKBACK`]
    /// positioning moves in a row). Never the solution of its end, so the
    /// move after it starts from where the machine stands (a takeup point,
    /// or the gap measured).
    fn at_fixed(
        pred: &ToolPredictor,
        plan: &Plan,
        mv: &Move,
        before: Option<&Carry>,
    ) -> Option<Carry> {
        Self::standing(pred, plan, mv, mv.end, false, before)
    }

    /// The carry of a move commanded to `c` (`solution`: `c` solves the
    /// move's end), its unprogrammed axes where `before` left them when
    /// [`needs_carry`].
    fn standing(
        pred: &ToolPredictor,
        plan: &Plan,
        mv: &Move,
        c: AxisVec,
        solution: bool,
        before: Option<&Carry>,
    ) -> Option<Carry> {
        let mut carry = Carry {
            target: mv.end,
            dirs: mv.dirs,
            tool: mv.tool_len_mm,
            ctx: pred.ctx,
            c,
            solved: solution,
            positioned: 0,
            known: ALL_AXES,
            moved: mv.dirs,
            initial: None,
        };
        if needs_carry(pred, plan) {
            let before = before?;
            for (s, v) in carry.c.iter_mut().enumerate() {
                if positioned(plan) & (1 << s) == 0 && pred.machine.has_axis(s) {
                    *v = *before.c.get(s)?;
                    if before.known & (1 << s) == 0 {
                        carry.known &= !(1 << s);
                    }
                }
            }
            carry.solved = solution && carry.c == c && carry.complete();
            carry.positioned = before.positioned + 1;
        }
        if let Some(k) = before {
            carry.moved = directions(&k.moved, &k.c, &carry.c, None);
        }
        Some(carry)
    }
}

/// [`block`] for the next block of a run compensated in order: `carry`
/// holds where the previous move left the machine (`None` where that is not
/// known) and is updated. A straight move (or replaced arc) that starts
/// there starts from that command: reused as it is when the directions of
/// motion, tool and context agree, otherwise with its gap measured or a
/// takeup point first (see [`BlockResult::takeup`]). A run that starts
/// after other blocks is seeded with [`carry_before`] of them, so the
/// result does not depend on where runs begin.
pub fn block_after(
    pred: &ToolPredictor,
    plan: &Plan,
    settings: &Settings,
    carry: &mut Option<Carry>,
) -> Result<BlockResult, Failure> {
    block_reusing(pred, plan, settings, carry, Vec::new())
}

/// Positioning moves that [`carry_before`] looks back over for the last
/// move that sets every axis.
pub const CARRY_LOOKBACK: usize = 8;

/// The carry a run of blocks holds after the moves `before` (each with the
/// predictor of its block context, in program order; the last one just
/// before the run), so that a run seeded with it gives the same results as
/// one that went through those blocks (see [`block_after`]): the output
/// then does not depend on where runs begin. Only the last move matters,
/// unless it is a positioning move that leaves axes where they were: then
/// the moves before it count, up to [`CARRY_LOOKBACK`] of them. `None`
/// where no move leaves a carry (or one cannot be compensated: the run
/// fails there anyway). With `from_start` (the reference position),
/// `before` holds every move since the start of the program, and the carry
/// is folded from [`Carry::program_start`], as a run from the first block
/// does.
pub fn carry_before<'p>(
    before: &[(ToolPredictor<'p>, Plan)],
    settings: &Settings,
    from_start: Option<AxisVec>,
) -> Option<Carry> {
    if let Some(home) = from_start {
        let mut carry = Some(Carry::program_start(home));
        for (pred, plan) in before {
            carry = carry_after(pred, plan, settings, carry.as_ref());
        }
        return carry;
    }
    // The last move that does not depend on the carry before it.
    let n = before.len();
    let first = (0..n).rev().take(CARRY_LOOKBACK + 1).find(|&i| {
        before
            .get(i)
            .is_some_and(|(pred, plan)| !needs_carry(pred, plan))
    })?;
    let mut carry = None;
    for (pred, plan) in before.get(first..)? {
        carry = carry_after(pred, plan, settings, carry.as_ref());
    }
    carry
}

/// A positioning move (a rapid, or a move to a machine-defined place) that
/// leaves some axes of the machine where they were.
fn needs_carry(pred: &ToolPredictor, plan: &Plan) -> bool {
    let positioning = match plan.kind {
        PlanKind::Motion => plan.mv.is_some_and(|mv| mv.motion == Motion::Rapid),
        PlanKind::Fixed => plan.mv.is_some(),
        PlanKind::Pass | PlanKind::Cycle { .. } => false,
    };
    positioning && (0..6).any(|s| positioned(plan) & (1 << s) == 0 && pred.machine.has_axis(s))
}

/// The axes (bit `s` for axis `s`) a positioning block moves to where it
/// is solved: those it programs, or under tool centre point control every
/// axis — its words are the tool tip of the compensated axis positions,
/// each tip word moves every linear axis, and the block is written with
/// each word its correction needs, so the machine goes to the solved
/// command on every axis (the one the next move starts from).
fn positioned(plan: &Plan) -> u8 {
    if plan.tcpm { ALL_AXES } else { plan.programmed }
}

/// The carry after `plan` given the one before it, as [`block_after`]
/// leaves it.
fn carry_after(
    pred: &ToolPredictor,
    plan: &Plan,
    settings: &Settings,
    before: Option<&Carry>,
) -> Option<Carry> {
    let mut carry = before.copied();
    block_reusing(pred, plan, settings, &mut carry, Vec::new()).ok()?;
    carry
}

/// The deviation of the move's programmed end, its compensated end with
/// the residual left there, and its nominal pose.
fn solve_end<'m>(
    pred: &ToolPredictor<'m>,
    mv: &Move,
    lip: &Lip<'m>,
) -> Result<(Breakdown, AxisVec, f64, TipPose), Failure> {
    let (dev, at_end, nom_end) = pred.evaluate(&mv.end, &mv.dirs, lip.tool_mm);
    let (c1, r1) = solve_from(
        pred,
        &mv.end,
        &nom_end,
        &mv.end,
        Some(at_end),
        &mv.dirs,
        lip,
    )?;
    Ok((dev, c1, r1, nom_end))
}

/// The directions of motion the hole of a canned cycle is drilled with:
/// the positioning from where the machine stands (`from`, with the
/// directions `moved` it last moved in) to the hole's compensated `c`,
/// then Z down the hole, as the interpreter reads the written hole.
fn hole_dirs(moved: &DirVec, from: &AxisVec, c: &AxisVec) -> DirVec {
    let mut above = *c;
    above[2] = from[2];
    let mut d = directions(moved, from, &above, None);
    d[2] = -1;
    d
}

/// Compensates the hole of a canned-cycle block into `res` (its bottom and
/// R level) and returns where the cycle leaves the machine: above the
/// hole's compensated X and Y at the retract level (the compensated R
/// level under G99, the commanded initial level under G98), Z last moved
/// up. The hole is solved with the directions its positioning really
/// takes from where the machine stands; its miss is measured under every
/// reading of the written positioning (its words' rounding moving its
/// travel by up to `band` mm).
fn cycle_hole(
    pred: &ToolPredictor,
    mv: &Move,
    (r_level, retract, band): (f64, f64, f64),
    carry_in: Option<&Carry>,
    res: &mut BlockResult,
) -> Result<Carry, Failure> {
    let tool = mv.tool_len_mm;
    let (from, moved) = carry_in.map_or((mv.start, mv.prev_dirs), |k| (k.c, k.moved));
    let (mut c, mut r) = solve(pred, &mv.end, &mv.dirs, tool)?;
    let mut d = mv.dirs;
    for _ in 0..DIR_PASSES {
        let real = hole_dirs(&moved, &from, &c);
        if real == d {
            break;
        }
        d = real;
        (c, r) = solve(pred, &mv.end, &d, tool)?;
    }
    check_travel(pred, &c)?;
    res.end = c;
    res.residual_mm = r;
    res.dirs = d;

    let mut at_r = mv.end;
    at_r[2] = r_level;
    // No process force at the R level: the drill is not cutting yet.
    let free = pred.with_context(MoveContext {
        wrench: None,
        ..pred.ctx
    });
    // The R level is reached with the directions before the feed:
    // moving down from above for the first hole, moving up (the
    // retract of the hole before) for the next G99 holes.
    let (cr, _) = solve(&free, &at_r, &mv.prev_dirs, tool)?;
    check_travel(pred, &cr)?;
    res.r_level = cr[2];
    // The whole hole at the one X and Y: its miss along the feed.
    let mut top = c;
    top[2] = cr[2];
    res.miss_mm = hole_miss(pred, mv, (&top, &c), &d, r_level);
    // Where the solve and the directions its positioning gives do not
    // agree (with one direction the correction reverses an axis, with the
    // other it moves it less than the deadband), or the written
    // positioning may be read either way, the hole is read back otherwise
    // than solved: measured under every reading.
    for real in cycles::hole_readings((&from, &moved), &c, band) {
        if real != d {
            res.miss_mm = res
                .miss_mm
                .max(hole_miss(pred, mv, (&top, &c), &real, r_level));
        }
    }
    // The cycle's initial level: kept from the hole before, or where the
    // machine stands when the cycle begins.
    let initial = carry_in.map_or((retract, retract), |k| {
        k.initial.unwrap_or((k.target[2], k.c[2]))
    });
    let mut up = c;
    up[2] = if retract > r_level {
        if initial.0 == retract {
            initial.1
        } else {
            carry_in.map_or(retract, |k| k.c[2])
        }
    } else {
        cr[2]
    };
    let mut target = mv.end;
    target[2] = retract;
    let mut moved_out = d;
    if up[2] > c[2] {
        moved_out[2] = 1;
    }
    Ok(Carry {
        target,
        dirs: moved_out,
        tool,
        ctx: pred.ctx,
        c: up,
        solved: false,
        positioned: 0,
        known: carry_in.map_or(ALL_AXES, |k| k.known) | 0b111,
        moved: moved_out,
        initial: Some(initial),
    })
}

/// The largest distance across the programmed hole of the attained path
/// of a hole drilled at one X and Y (the compensated `top` → `bottom`, with
/// the directions `d`), mm. The error model is piecewise linear in Z
/// between its breakpoints, so the distance is largest at an end of the
/// hole or at a breakpoint of Z inside it: those are the points measured.
fn hole_miss(
    pred: &ToolPredictor,
    mv: &Move,
    (top, bottom): (&AxisVec, &AxisVec),
    d: &DirVec,
    r_level: f64,
) -> f64 {
    let tool = mv.tool_len_mm;
    let (zt, zb) = (top[2], bottom[2]);
    let across = |f: f64| -> f64 {
        let cmd = lerp(top, bottom, f);
        let mut prog = mv.end;
        prog[2] = r_level + (mv.end[2] - r_level) * f;
        let off = pred.attained(&cmd, d, tool).pos - pred.nominal(&prog, tool).pos;
        // The part across the hole (a line along Z).
        (off[0] * off[0] + off[1] * off[1]).sqrt()
    };
    let mut worst = across(0.0).max(across(1.0));
    if zt != zb {
        for &z in breaks_inside(pred, 2, zb, zt) {
            worst = worst.max(across((zt - z) / (zt - zb)));
        }
    }
    worst
}

/// Most runs of pieces with their own directions of motion one straight
/// move is solved in; a move whose pieces change directions more often is
/// measured instead ([`BlockResult::miss_mm`]).
const MAX_RUNS: usize = 8;

/// A stretch `t0..t1` of a straight move (parameters of the programmed
/// move) whose written pieces are solved with the directions `dirs`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Run {
    t0: f64,
    t1: f64,
    dirs: DirVec,
}

/// The straight move `mv` into `res` (its end already solved with the
/// programmed directions): where it starts (from where the machine stands,
/// or a takeup point first), then split within the tolerance. Solved again
/// (up to [`DIR_PASSES`] times) with the directions of motion its written
/// pieces really take, as the interpreter reads them from the compensated
/// program: an axis the block does not drive follows the correction's
/// drift and a takeup point's push, and keeps the direction it had where
/// it moves less than the deadband. Pieces that take different directions
/// are solved in runs, each with its own; where an axis reverses between
/// two runs a takeup point is written at the split when the machine would
/// otherwise leave it more than [`TAKEUP_SHARE`] of the tolerance off the
/// path. Returns the directions its end is solved with and those its last
/// piece leaves. Where no pass agrees with its pieces, their largest
/// distance from the programmed line under their own directions is
/// measured into [`BlockResult::miss_mm`].
#[allow(clippy::too_many_arguments)]
fn straight<'m>(
    pred: &ToolPredictor<'m>,
    plan: &Plan,
    mv: &Move,
    carry_in: Option<&Carry>,
    lip: &Lip<'m>,
    (tol, rounding): (f64, f64),
    nom_end: &TipPose,
    res: &mut BlockResult,
) -> Result<(DirVec, DirVec), Failure> {
    let tool = lip.tool_mm;
    let moved_in = carry_in.map_or(mv.prev_dirs, |k| k.moved);
    let end_residual = res.residual_mm;
    let mut runs = [Run {
        t0: 0.0,
        t1: 1.0,
        dirs: mv.dirs,
    }; MAX_RUNS];
    let mut n_runs = 1;
    let mut result = (mv.dirs, mv.dirs);
    // The pass whose pieces missed least, where none agrees: its miss and
    // runs, and whether the last pass solved was it.
    let mut best: Option<(f64, [Run; MAX_RUNS], usize)> = None;
    let mut last_best = false;
    let grid = Grid::of(plan, rounding);
    for pass in 0..=DIR_PASSES {
        let rewrite = pass == DIR_PASSES || n_runs == 0;
        if rewrite {
            // No pass agreed: the one that missed least is written.
            match best {
                Some((_, r, n)) if !last_best => (runs, n_runs) = (r, n),
                _ => break,
            }
        }
        let runs_now = runs.get(..n_runs).unwrap_or(&[]);
        let (left, c0) = solve_runs(
            pred,
            plan,
            mv,
            carry_in,
            lip,
            (tol, nom_end, end_residual, pass == 0),
            (runs_now, &grid),
            res,
        )?;
        // The pieces as the interpreter reads them: from where the machine
        // stands (a takeup point first) through the split points.
        let from = match carry_in {
            Some(k) if res.takeup => k.c,
            _ => c0,
        };
        let d_end = runs_now.last().map_or(mv.dirs, |r| r.dirs);
        res.start_dirs = runs_now.first().map_or(mv.dirs, |r| r.dirs);
        let mut next = runs;
        let (agree, n_next, moved) = piece_runs(mv, (&moved_in, &from), res, runs_now, &mut next);
        result = (d_end, moved);
        // A gap left at the start (no takeup under cutter radius
        // compensation) is a miss of the pieces from there; so is a piece
        // whose travel in an axis is within the rounding of the written
        // words of the deadband (read back, it may take either direction).
        // (On a machine with rotary axes the nominal path of a piece is
        // no straight line: only a gap left is measured.)
        let affine = !(3..6).any(|s| pred.machine.has_axis(s));
        let measure = left > 0.0 || (affine && any_ambiguous(res, &from, &grid));
        if agree {
            res.miss_mm = if measure {
                pieces_miss(pred, mv, (&from, &moved_in), res, (tool, tol, &grid)).max(left)
            } else {
                0.0
            };
            break;
        }
        res.miss_mm = pieces_miss(pred, mv, (&from, &moved_in), res, (tool, tol, &grid)).max(left);
        if rewrite {
            break;
        }
        last_best = best.is_none_or(|(m, _, _)| res.miss_mm < m);
        if last_best {
            best = Some((res.miss_mm, runs, n_runs));
        }
        (runs, n_runs) = (next, n_next.unwrap_or(0));
    }
    for p in &res.segments {
        check_travel_within(pred, p, tol)?;
    }
    Ok(result)
}

/// Solves and splits the straight move `mv` into `res` in the runs `runs`
/// (covering it from 0 to 1 in order), each with its own directions; the
/// end is solved again unless this is the `first` pass (already solved
/// with the programmed directions, residual `end_residual`). Returns the
/// gap left at a start where no takeup point may be written, and the
/// command the first run starts from.
#[allow(clippy::too_many_arguments)]
fn solve_runs<'m>(
    pred: &ToolPredictor<'m>,
    plan: &Plan,
    mv: &Move,
    carry_in: Option<&Carry>,
    lip: &Lip<'m>,
    (tol, nom_end, end_residual, first): (f64, &TipPose, f64, bool),
    (runs, grid): (&[Run], &Grid),
    res: &mut BlockResult,
) -> Result<(f64, AxisVec), Failure> {
    let tool = lip.tool_mm;
    let takeups = plan.takeups_allowed();
    res.segments.clear();
    res.takeup_at.clear();
    res.takeup = false;
    res.residual_mm = end_residual;
    let Some(last) = runs.last() else {
        return Ok((0.0, res.end));
    };
    if !first || last.dirs != mv.dirs {
        let (c1, r1) = solve_from(pred, &mv.end, nom_end, &res.end, None, &last.dirs, lip)?;
        res.end = c1;
        res.residual_mm = r1;
    }
    let mut left = 0.0;
    let mut start = res.end;
    // Where the previous run ended.
    let mut prev: Option<AxisVec> = None;
    for (i, run) in runs.iter().enumerate() {
        let d = &run.dirs;
        let p0 = lerp(&mv.start, &mv.end, run.t0);
        let last_run = i + 1 == runs.len();
        let (p1, c1) = if last_run {
            (mv.end, res.end)
        } else {
            let p1 = lerp(&mv.start, &mv.end, run.t1);
            (p1, solve_near(pred, &p1, &res.end, &mv.end, d, lip)?.0)
        };
        // The proof of the run's first piece starts from `fit` (the start
        // `c0` unless a gap is left over there, see [`Start::fit`]).
        let (fit, gap) = match prev {
            Some(c) => {
                let st = start_from(pred, &p0, &c, d, lip, (tol, takeups), &mut res.segments)?;
                if st.takeup {
                    res.takeup_at.push(res.segments.len() - 1);
                }
                left = f64::max(left, st.left_mm);
                (st.fit, st.gap)
            }
            None => {
                // The start is the previous block's end: where that block
                // left the machine (with whatever tool length it was
                // solved for).
                let (c0, fit, gap) = match carry_in {
                    Some(k) if k.matches(&mv.start, d, tool, &pred.ctx) => (k.c, k.c, SOLVE_TOL_MM),
                    Some(k) if k.stands_at(&mv.start) => {
                        let st = start_from(
                            pred,
                            &mv.start,
                            &k.c,
                            d,
                            lip,
                            (tol, takeups),
                            &mut res.segments,
                        )?;
                        res.takeup = st.takeup;
                        left = st.left_mm;
                        (st.c, st.fit, st.gap)
                    }
                    _ => {
                        let c0 = solve_near(pred, &mv.start, &c1, &p1, d, lip)?.0;
                        (c0, c0, SOLVE_TOL_MM)
                    }
                };
                start = c0;
                (fit, gap)
            }
        };
        split_line(
            pred,
            &p0,
            &p1,
            &fit,
            &c1,
            gap,
            d,
            lip,
            (tol, Some(grid)),
            !last_run,
            &mut res.segments,
        )?;
        prev = Some(c1);
    }
    res.residual_mm = res.residual_mm.max(left);
    Ok((left, start))
}

/// Whether piece `j` of a block's written pieces (to `segments[j]`, or to
/// its end) goes onto a takeup point.
fn is_takeup(res: &BlockResult, j: usize) -> bool {
    (j == 0 && res.takeup) || res.takeup_at.contains(&j)
}

/// The parameter of the programmed move `mv` nearest the command `c`.
fn param_of(mv: &Move, c: &AxisVec) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for ((&ci, &a), &b) in c.iter().zip(&mv.start).zip(&mv.end) {
        let d = b - a;
        if d.is_finite() && (ci - a).is_finite() {
            num += (ci - a) * d;
            den += d * d;
        }
    }
    if den > 0.0 {
        (num / den).clamp(0.0, 1.0)
    } else {
        0.0
    }
}

/// The directions of motion of the written pieces of a straight move, from
/// `from` (the machine last moved with `moved`) through the split points of
/// `res` to its end, against the runs they were solved in: whether every
/// piece (takeup moves excepted) takes its run's directions, the runs the
/// pieces really fall into (in `next`; `None` when more than
/// [`MAX_RUNS`]), and the directions the last piece leaves.
fn piece_runs(
    mv: &Move,
    (moved, from): (&DirVec, &AxisVec),
    res: &BlockResult,
    runs: &[Run],
    next: &mut [Run; MAX_RUNS],
) -> (bool, Option<usize>, DirVec) {
    let mut w = *moved;
    let mut a = *from;
    let mut agree = true;
    let mut n = 0usize;
    let mut overflow = false;
    for (j, b) in res
        .segments
        .iter()
        .chain(std::iter::once(&res.end))
        .enumerate()
    {
        w = directions(&w, &a, b, None);
        if !is_takeup(res, j) {
            let tb = param_of(mv, b);
            // The run the piece was solved in: the one its middle is in.
            let tm = (param_of(mv, &a) + tb) / 2.0;
            let solved = runs.iter().find(|r| tm <= r.t1).or(runs.last());
            if solved.is_some_and(|r| r.dirs != w) {
                agree = false;
            }
            match n.checked_sub(1).and_then(|k| next.get_mut(k)) {
                Some(r) if r.dirs == w => r.t1 = tb,
                Some(r) => {
                    let t0 = r.t1;
                    match next.get_mut(n) {
                        Some(slot) => {
                            *slot = Run {
                                t0,
                                t1: tb,
                                dirs: w,
                            };
                            n += 1;
                        }
                        None => overflow = true,
                    }
                }
                None => {
                    next[0] = Run {
                        t0: 0.0,
                        t1: tb,
                        dirs: w,
                    };
                    n = 1;
                }
            }
        }
        a = *b;
    }
    if let Some(r) = n.checked_sub(1).and_then(|k| next.get_mut(k)) {
        r.t1 = 1.0;
    }
    let n = (!overflow && n > 0).then_some(n);
    (agree, n, w)
}

/// Whether a written piece of `res` (from `from`) travels, in some axis,
/// within the rounding of its written words (`rounding` bounds the move of
/// each end, so a travel by half of it) of the deadband of a direction of
/// motion: read back, the axis may keep its direction or take the
/// piece's.
fn any_ambiguous(res: &BlockResult, from: &AxisVec, grid: &Grid) -> bool {
    let mut a = from;
    for b in res.segments.iter().chain(std::iter::once(&res.end)) {
        if (0..3).any(|s| grid.ambiguous(s, a[s], b[s])) {
            return true;
        }
        a = b;
    }
    false
}

/// Distance from the deadband within which a written travel may be read
/// on either side of it, mm.
const DEADBAND_EDGE_MM: f64 = 1e-9;

/// The grid the written words of a block fall on: in absolute mode
/// (`G90`) a written machine coordinate is `offset + k · unit`, `unit`
/// the last decimal (half of `rounding`, see `emit::gcode::rounding_mm`).
struct Grid {
    rounding: f64,
    offset: Option<[f64; 3]>,
}

impl Grid {
    fn of(plan: &Plan, rounding: f64) -> Self {
        Grid {
            rounding,
            offset: plan
                .absolute
                .then(|| [plan.offset[0], plan.offset[1], plan.offset[2]]),
        }
    }

    /// Whether the travel of axis `s` from `a` to `b` may be read back on
    /// the other side of the deadband of a direction of motion than
    /// solved: in absolute mode, where the written (rounded) ends put it
    /// there; otherwise where it is within the rounding of the deadband.
    fn ambiguous(&self, s: usize, a: f64, b: f64) -> bool {
        if self.rounding <= 0.0 {
            return false;
        }
        let d = b - a;
        match self.offset {
            Some(o) => {
                let unit = self.rounding / 2.0;
                let at = |x: f64| ((x - o[s]) / unit).round();
                let read = (at(b) - at(a)) * unit;
                // (a written travel of the deadband itself is read either
                // way by the floating-point sum of its words and offsets)
                (read.abs() > DIRECTION_DEADBAND) != (d.abs() > DIRECTION_DEADBAND)
                    || (read.abs() - DIRECTION_DEADBAND).abs() <= DEADBAND_EDGE_MM
            }
            None => (d.abs() - DIRECTION_DEADBAND).abs() <= self.rounding / 2.0,
        }
    }
}

/// The directions `w` a piece from `a` to `b` takes after `prev`, with
/// each axis whose travel is [`Grid::ambiguous`] given the other reading:
/// the previous direction where the travel passes the deadband, the
/// travel's where it does not.
fn other_reading(prev: &DirVec, w: &DirVec, a: &AxisVec, b: &AxisVec, grid: &Grid) -> DirVec {
    let mut o = *w;
    for s in 0..3 {
        let d = b[s] - a[s];
        if grid.ambiguous(s, a[s], b[s]) {
            o[s] = if d.abs() > DIRECTION_DEADBAND {
                prev[s]
            } else if d > 0.0 {
                1
            } else {
                -1
            };
        }
    }
    o
}

/// Most intervals [`piece_bound`] cuts one piece into.
const MAX_BOUND_INTERVALS: usize = 4096;
/// Share of the tolerance the part of [`piece_bound`] between its points
/// is brought under where the piece is long enough to need it.
const BOUND_SHARE: f64 = 0.01;
/// Spacing of the points of [`piece_bound`] along a piece of a machine
/// without a Lipschitz bound (rotary axes), mm, and fewest points.
const UNBOUNDED_SAMPLE_MM: f64 = 0.25;
const MIN_PIECE_SAMPLES: usize = 8;

/// An upper bound of `dist(f, attained(c(f)))`, mm, along the straight
/// piece of commands `c(f) = a + f·(b − a)` under the directions `d`,
/// where `dist` is a distance to a convex set (the programmed line) in
/// space, or to a point moving affinely with `f` (the nominal point of
/// the programmed part: the gap). On a machine whose
/// nominal chain is a translation, the attained point is the affine
/// nominal point plus the error `e`, so between two points of the piece
/// `dist` is at most the larger of its values there plus the departure of
/// `e` from its chord, which the model's Lipschitz constant `L` bounds by
/// `L` times the length between them: the piece is evaluated at `n + 1`
/// points with `L · len / n` within [`BOUND_SHARE`] of the tolerance
/// (at most [`MAX_BOUND_INTERVALS`] intervals), and the bound is the
/// largest value plus `L · len / n`. Without a Lipschitz bound (rotary
/// axes) it is the largest of points every [`UNBOUNDED_SAMPLE_MM`]. The
/// points stop at the first beyond `stop` (the bound is then above it).
fn piece_bound(
    pred: &ToolPredictor,
    (a, b): (&AxisVec, &AxisVec),
    d: &DirVec,
    (tool, tol, stop): (f64, f64, f64),
    dist: &dyn Fn(f64, Vector3<f64>) -> f64,
) -> f64 {
    let len = (0..3).map(|s| (b[s] - a[s]).powi(2)).sum::<f64>().sqrt();
    let affine = !(3..6).any(|s| pred.machine.has_axis(s));
    let l = if affine {
        pred.lipschitz(a, b, tool)
    } else {
        None
    };
    let (n, between) = match l {
        Some(l) => {
            let n = ((l * len / (tol * BOUND_SHARE)).ceil() as usize).clamp(1, MAX_BOUND_INTERVALS);
            (n, l * len / n as f64)
        }
        None => {
            let n = ((len / UNBOUNDED_SAMPLE_MM).ceil() as usize)
                .clamp(MIN_PIECE_SAMPLES, MAX_BOUND_INTERVALS);
            (n, 0.0)
        }
    };
    let mut worst = 0.0f64;
    for k in 0..=n {
        let f = k as f64 / n as f64;
        let q = pred.attained(&lerp(a, b, f), d, tool).pos;
        // (NaN counts as infinitely far)
        let v = dist(f, q);
        worst = if v.is_nan() {
            f64::INFINITY
        } else {
            worst.max(v)
        };
        if worst > stop {
            break;
        }
    }
    worst + between
}

/// The largest distance, mm, of the attained points of the written pieces
/// of a straight move, each under the directions the interpreter gives it,
/// from the programmed line, bounded along each piece ([`piece_bound`];
/// a piece whose travel is [`ambiguous`] under both readings): where no
/// pass of [`straight`] agrees with the pieces' directions, where the move
/// leaves a gap at its start, or where a travel is ambiguous. Takeup moves
/// are not on the line; their ends are the starts of the pieces after
/// them.
fn pieces_miss(
    pred: &ToolPredictor,
    mv: &Move,
    (from, moved): (&AxisVec, &DirVec),
    res: &BlockResult,
    (tool, tol, grid): (f64, f64, &Grid),
) -> f64 {
    let (p0, p1) = (
        pred.nominal(&mv.start, tool).pos,
        pred.nominal(&mv.end, tool).pos,
    );
    let line = p1 - p0;
    let len2 = line.norm_squared();
    let off_line = |_: f64, q: Vector3<f64>| -> f64 {
        let t = if len2 > 0.0 {
            ((q - p0).dot(&line) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        (q - (p0 + line * t)).norm()
    };
    let (mut w, mut a, mut worst) = (*moved, *from, 0.0f64);
    for (j, b) in res
        .segments
        .iter()
        .chain(std::iter::once(&res.end))
        .enumerate()
    {
        let prev = w;
        w = directions(&w, &a, b, None);
        if !is_takeup(res, j) {
            let alt = other_reading(&prev, &w, &a, b, grid);
            for d in [w, alt].iter().take(if alt == w { 1 } else { 2 }) {
                worst = worst.max(piece_bound(
                    pred,
                    (&a, b),
                    d,
                    (tool, tol, f64::INFINITY),
                    &off_line,
                ));
            }
        }
        a = *b;
    }
    worst
}

/// [`block_after`] with `segments` (cleared first) as the storage of the
/// result's split points, so that a caller that recycles the results of
/// earlier blocks allocates nothing for split moves once warmed up.
pub fn block_reusing(
    pred: &ToolPredictor,
    plan: &Plan,
    settings: &Settings,
    carry: &mut Option<Carry>,
    segments: Vec<AxisVec>,
) -> Result<BlockResult, Failure> {
    block_recycling(pred, plan, settings, carry, (segments, Vec::new()), 0.0)
}

/// [`block_reusing`] with the storage of the result's takeup points inside
/// a move ([`BlockResult::takeup_at`]) recycled too (both cleared first),
/// for a program written with words whose rounding moves a written piece
/// by up to `rounding_mm` (`emit::gcode::rounding_mm`; 0 for none): a
/// straight piece whose travel in an axis is that close to the deadband of
/// a direction of motion is measured under both readings into
/// [`BlockResult::miss_mm`].
pub fn block_recycling(
    pred: &ToolPredictor,
    plan: &Plan,
    settings: &Settings,
    carry: &mut Option<Carry>,
    (mut segments, mut takeup_at): (Vec<AxisVec>, Vec<usize>),
    rounding_mm: f64,
) -> Result<BlockResult, Failure> {
    segments.clear();
    takeup_at.clear();
    let Some(mv) = plan.mv else {
        return Ok(BlockResult {
            segments,
            takeup_at,
            ..BlockResult::default()
        });
    };
    if plan.kind != PlanKind::Pass {
        check_programmed_travel(pred, &mv.end)?;
    }
    let prev = carry.take();
    let carry_in = prev.as_ref();
    let mut res = BlockResult {
        segments,
        takeup_at,
        ..BlockResult::default()
    };
    let tool = mv.tool_len_mm;
    let tol = settings.tolerance_mm;
    match plan.kind {
        PlanKind::Pass => return Ok(res),
        PlanKind::Fixed => {
            res.end = mv.end;
            res.deviation = pred.breakdown(&mv.end, &mv.dirs, tool);
            res.residual_mm = res.deviation.total().norm();
            *carry = Carry::at_fixed(pred, plan, &mv, carry_in);
            return Ok(res);
        }
        PlanKind::Cycle {
            r_level, retract, ..
        } => {
            res.deviation = pred.breakdown(&mv.end, &mv.dirs, tool);
            let levels = (r_level, retract, rounding_mm / 2.0);
            let mut cycle = cycle_hole(pred, &mv, levels, carry_in, &mut res)?;
            // Written as moves when one X and Y cannot hold the hole.
            if plan.cycle.expandable && res.miss_mm > tol {
                let hole = (&mv, &plan.cycle);
                let tols = (tol, rounding_mm, plan.scale);
                let before = carry_in.map_or((&mv.start, &mv.prev_dirs), |k| (&k.c, &k.moved));
                let levels = (r_level, retract);
                cycles::expand(pred, hole, levels, tols, before, &mut cycle, &mut res)?;
            }
            *carry = Some(cycle);
            return Ok(res);
        }
        PlanKind::Motion => {}
    }
    let lip = Lip::new(tool);
    let (dev, c1, r1, nom_end) = solve_end(pred, &mv, &lip)?;
    res.deviation = dev;
    res.end = c1;
    res.residual_mm = r1;
    res.dirs = mv.dirs;
    res.start_dirs = mv.dirs;
    let mut carry_out = Carry::after(pred, plan, &mv, c1, carry_in);
    match (mv.motion, mv.arc) {
        (Motion::Rapid, _) => {
            // Positioning: only the axes the block moves ([`positioned`])
            // are corrected; the others stay where they are.
            for s in 0..6 {
                if positioned(plan) & (1 << s) == 0 {
                    res.end[s] = mv.end[s];
                }
            }
            res.residual_mm = (pred.attained(&res.end, &mv.dirs, tool).pos - nom_end.pos).norm();
        }
        (Motion::Linear, _) => {
            let (d, moved) = straight(
                pred,
                plan,
                &mv,
                carry_in,
                &lip,
                (tol, rounding_mm),
                &nom_end,
                &mut res,
            )?;
            res.dirs = d;
            if let Some(k) = carry_out.as_mut() {
                k.c = res.end;
                k.dirs = d;
                k.moved = moved;
            }
        }
        (_, Some(arc)) => {
            let takeups = plan.takeups_allowed();
            let d = arc::arc_block(pred, &mv, &arc, (tool, tol, takeups), carry_in, &mut res)?;
            res.dirs = d;
            if let Some(k) = carry_out.as_mut() {
                k.moved = d;
                k.dirs = d;
                k.c = res.end;
            }
        }
        (_, None) => {}
    }
    if hold_at_travel(pred, &mut res, tol)? {
        // Held at an end of travel: the machine stands there, and the
        // point attains its target only as far as the hold lets it.
        if let Some(k) = carry_out.as_mut() {
            for s in 0..6 {
                if let Some((lo, hi)) = pred.machine.travel(s) {
                    k.c[s] = k.c[s].clamp(lo, hi);
                }
            }
        }
        res.residual_mm = (pred.attained(&res.end, &res.dirs, tool).pos - nom_end.pos).norm();
        let by = res.held.map_or(0.0, |h| h.by);
        res.miss_mm = res.miss_mm.max(res.residual_mm).max(by);
    }
    *carry = carry_out;
    Ok(res)
}

#[cfg(test)]
mod tests {
    use super::*;

    thread_local! {
        /// Pieces judged by [`Piece::sampled`] on this thread.
        pub(super) static SAMPLED: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
    }
    use crate::machine::tool::testing;
    use crate::predict::EffectSet;
    use crate::program::interp::{Interpreter, Setup};

    /// The plans of `program` on the AFM R-1000 (three axes).
    fn afm_plans(program: &[&str]) -> Vec<Plan> {
        let mut setup = Setup {
            axes: [true, true, true, false, false, false],
            // The machine file's default unit.
            units_default: Some(crate::program::interp::Units::Mm),
            ..Setup::default()
        };
        setup.tools.insert(1, 150.0);
        let mut interp = Interpreter::new(setup, "p.nc");
        let mut plans = Vec::new();
        for (k, line) in program.iter().enumerate() {
            let mut block = crate::program::gcode::Block::default();
            if let Err(e) =
                crate::program::gcode::parse_line(line.as_bytes(), k + 1, "p.nc", &mut block)
            {
                panic!("{e}");
            }
            match interp.step(&block, line.as_bytes()) {
                Ok(p) => plans.push(p),
                Err(e) => panic!("{e}"),
            }
        }
        plans
    }

    /// The AFM R-1000 example machine, loaded once for the tests.
    fn afm_machine() -> &'static crate::machine::tool::MachineTool {
        static AFM: std::sync::OnceLock<crate::machine::tool::MachineTool> =
            std::sync::OnceLock::new();
        AFM.get_or_init(|| testing::load(&testing::afm_text(), "afm"))
    }

    /// A predictor of the AFM R-1000 with the default effects.
    fn afm_pred() -> ToolPredictor<'static> {
        ToolPredictor::new(afm_machine(), EffectSet::default())
    }

    /// [`block_after`] over `plans` in one run; panics on a failure.
    fn run_all(pred: &ToolPredictor, plans: &[Plan]) -> Vec<BlockResult> {
        run_at(pred, plans, Settings::default().tolerance_mm)
    }

    #[test]
    fn runs_seeded_with_the_carry_before_them_give_the_same_results() {
        // A run started at any block from `carry_before` of the moves
        // before it gives what one run over every block gives: takeups at
        // reversals, arcs replaced by chords (ending with their last
        // chord's direction), positioning moves that leave axes where they
        // were (also more of them in a row than it looks back over), a
        // tool length taken on between moves, and moves after a comment
        // line included, and moves to machine-defined places (G28, G53).
        let pred = afm_pred();
        let plans = afm_plans(&[
            // The program's first positioning moves name some axes each.
            "G0 X5 Y5",
            "G0 Z15",
            "G1 Z10 F500",
            "G0 X10 Y10 Z10",
            "G1 X400 Y10.5 F1000",
            "Y20",
            "X10",
            "(a comment)",
            "G2 X20 Y30 I0 J10",
            "G1 X300",
            "G0 Z20",
            "G0 Y40",
            "G1 Z5",
            "X10",
            // Moves to machine-defined places (not compensated) that leave
            // axes where they were, and moves after them.
            "G91 G28 Z0",
            "G90",
            "G0 X50 Y50",
            "G0 Z20",
            "G1 Z5",
            "G53 Z12",
            "G1 X60 Y40",
            // A tool length taken on without a move.
            "G43 H1",
            "G1 X200",
            // More positioning moves in a row than `carry_before` looks
            // back over, then fewer.
            "G0 Z40",
            "G0 X300",
            "G0 Y100",
            "G0 X400",
            "G0 Y200",
            "G0 X500",
            "G0 Y300",
            "G0 X600",
            "G0 Y400",
            "G0 X800",
            "G0 Y450",
            "G1 Z30",
            "X300",
            "G0 Z30",
            "G0 X100",
            "G1 Z10",
        ]);
        let settings = Settings::default();
        let mut carry = Some(Carry::program_start([0.0; 6]));
        let whole: Vec<_> = plans
            .iter()
            .map(|p| block_after(&pred, p, &settings, &mut carry))
            .collect();
        let takeups = whole
            .iter()
            .filter(|r| r.as_ref().is_ok_and(|r| r.takeup))
            .count();
        assert!(takeups >= 2, "{takeups} takeups");
        // The move after `G53 Z12` starts where the machine stands: X and
        // Y as the line before left them, Z at 12 uncompensated.
        let after_g53 = plans
            .iter()
            .position(|p| {
                p.kind == PlanKind::Fixed
                    && p.programmed == 0b100
                    && p.mv.is_some_and(|m| m.end[2] == 12.0)
            })
            .map(|k| k + 1);
        assert!(
            after_g53.is_some_and(|k| whole[k].as_ref().is_ok_and(|r| r.takeup)),
            "no takeup after G53"
        );
        // The carry after each block of the whole run: a run started at any
        // block from it gives what the whole run gives (what the pipeline
        // relies on when it solves a run again from the carry the run
        // before left), and where the estimate of `carry_before` is that
        // carry, it gives the same too.
        let mut carries = Vec::new();
        let mut carry = Some(Carry::program_start([0.0; 6]));
        for p in &plans {
            let _ = block_after(&pred, p, &settings, &mut carry);
            carries.push(carry);
        }
        let mut estimated = 0;
        for k in 1..plans.len() {
            let before: Vec<(ToolPredictor, Plan)> = plans[..k]
                .iter()
                .filter(|p| p.mv.is_some())
                .map(|p| (pred, *p))
                .collect();
            let from_start = (before.len() <= CARRY_LOOKBACK).then_some([0.0; 6]);
            let estimate = carry_before(&before, &settings, from_start);
            if estimate == carries[k - 1] {
                estimated += 1;
            }
            let mut carry = carries[k - 1];
            for (i, p) in plans.iter().enumerate().skip(k) {
                let r = block_after(&pred, p, &settings, &mut carry);
                assert_eq!(r, whole[i], "run from block {k}, block {i}");
            }
        }
        assert!(estimated * 2 > plans.len(), "{estimated} estimates right");
    }

    #[test]
    fn the_first_feed_starts_where_the_positioning_moves_left_the_machine() {
        // `G0 X Y` at the start of a program leaves Z unknown: X and Y are
        // solved for a Z that is not where the machine stands. `G43 H1 Z`
        // then moves Z only. The first feed move starts where these two
        // left the machine, all three axes now known; at 3 µm the X and Y
        // solved for the wrong Z are too far off, so it starts with a
        // takeup point onto its programmed start, and its pieces hold the
        // tolerance from there.
        let pred = afm_pred();
        let plans = afm_plans(&[
            "G90 G54 G0 X150 Y120",
            "G43 H1 Z50",
            "G1 Z5 F500",
            "G1 X350",
        ]);
        let tol = 0.003;
        let res = run_at(&pred, &plans, tol);
        let Some(mv) = plans[2].mv else {
            panic!("no move")
        };
        assert!(res[2].takeup, "the first feed starts without a takeup");
        let nominal = pred.nominal(&mv.start, mv.tool_len_mm).pos;
        let first = res[2].segments.first().copied().unwrap_or(res[2].end);
        let got = pred.attained(&first, &mv.dirs, mv.tool_len_mm).pos;
        assert!(
            (got - nominal).norm() <= tol,
            "starts {:.4} mm off",
            (got - nominal).norm()
        );
        // Where the positioning moves left it, it is further off than the
        // tolerance allows (otherwise this test proves nothing).
        let mut stands = res[0].end;
        stands[2] = res[1].end[2];
        let off = (pred.attained(&stands, &mv.dirs, mv.tool_len_mm).pos - nominal).norm();
        assert!(off > tol * TAKEUP_SHARE, "stands only {off:.4} mm off");
    }

    #[test]
    fn a_move_after_a_move_to_a_machine_position_starts_where_the_machine_stands() {
        // `G53 Z50` is not compensated: Z goes to its command, X and Y stay
        // where the line before left them (solved for Z 10). The next move
        // needs X, Y and Z solved for its own start, more than half the
        // tolerance away: it starts with a takeup point onto it (before,
        // the machine-coordinate move dropped what the block before left,
        // and the move assumed it started on its compensated start).
        let pred = afm_pred();
        let plans = afm_plans(&["G0 X10 Y10 Z10", "G1 X400 Y300 F1000", "G53 Z50", "G1 X500"]);
        assert_eq!(plans[2].kind, PlanKind::Fixed);
        let settings = Settings::default();
        let res = run_all(&pred, &plans);
        let Some(mv) = plans[3].mv else {
            panic!("no move")
        };
        let mut stands = res[1].end;
        stands[2] = 50.0;
        assert_eq!(res[2].end, [400.0, 300.0, 50.0, 0.0, 0.0, 0.0]);
        let off =
            (pred.attained(&stands, &mv.dirs, 0.0).pos - pred.nominal(&mv.start, 0.0).pos).norm();
        assert!(off > settings.tolerance_mm * TAKEUP_SHARE, "{off} mm");
        assert!(res[3].takeup);
        let at = pred.attained(&res[3].segments[0], &mv.dirs, 0.0).pos;
        assert!((at - pred.nominal(&mv.start, 0.0).pos).norm() <= SOLVE_TOL_MM);
    }

    #[test]
    fn a_tool_length_taken_on_between_moves_is_taken_up() {
        // `G43 H1` on its own line: the machine stands where the previous
        // move left it, solved without the tool; with 150 mm of tool the
        // angular errors move the tip there by more than half the
        // tolerance (Abbe), so the next move starts with a takeup point
        // solved with the tool.
        let pred = afm_pred();
        let plans = afm_plans(&["G0 X10 Y10 Z10", "G1 X400 Y300 F1000", "G43 H1", "G1 X500"]);
        let settings = Settings::default();
        let res = run_all(&pred, &plans);
        let Some(mv) = plans[3].mv else {
            panic!("no move")
        };
        assert_eq!(mv.tool_len_mm, 150.0);
        let off = (pred.attained(&res[1].end, &mv.dirs, 150.0).pos
            - pred.nominal(&mv.start, 150.0).pos)
            .norm();
        assert!(off > settings.tolerance_mm * TAKEUP_SHARE, "{off} mm");
        assert!(res[3].takeup);
        let at = pred.attained(&res[3].segments[0], &mv.dirs, 150.0).pos;
        assert!((at - pred.nominal(&mv.start, 150.0).pos).norm() <= SOLVE_TOL_MM);
    }

    #[test]
    fn a_reversal_is_taken_up_and_the_move_starts_on_the_programmed_point() {
        // X reverses after the Y step: the step's end was solved for +X.
        // Under −X the attained point there is off by the reversal value
        // (more than the tolerance on this machine), so the result starts
        // with the start solved for −X and the rest of the move is proven
        // from it; without a reversal no takeup is needed.
        let pred = afm_pred();
        let plans = afm_plans(&[
            "G0 X10 Y10 Z10",
            "G1 X400 F1000",
            "Y20",
            "X10",
            "Y30",
            "X400",
        ]);
        let settings = Settings::default();
        let tool = 0.0;
        let res = run_all(&pred, &plans);
        for (k, (r, p)) in res.iter().zip(&plans).enumerate().skip(2) {
            let Some(mv) = p.mv else { continue };
            let prev_end = res[k - 1].end;
            // Where the machine stands, seen with the directions this move
            // is solved with (its written pieces' own).
            let off = (pred.attained(&prev_end, &r.start_dirs, tool).pos
                - pred.nominal(&mv.start, tool).pos)
                .norm();
            let reversal = r.start_dirs != res[k - 1].dirs;
            assert_eq!(
                r.takeup,
                reversal && off > settings.tolerance_mm * TAKEUP_SHARE,
                "block {k}"
            );
            if r.takeup {
                assert!(off > settings.tolerance_mm, "block {k}: {off} mm");
                let c0 = r.segments[0];
                let at = pred.attained(&c0, &r.start_dirs, tool).pos;
                assert!((at - pred.nominal(&mv.start, tool).pos).norm() <= SOLVE_TOL_MM);
            }
        }
        assert!(res.iter().filter(|r| r.takeup).count() >= 2);
    }

    #[test]
    fn an_arc_that_starts_with_a_reversal_starts_on_the_programmed_point() {
        // A small arc (uniform correction: kept as an arc when nothing
        // else is in the way) that leaves its start in −X after a move in
        // +X. The machine stands where the straight move's end was solved
        // for +X; seen under −X it is off the arc's start by the reversal
        // value (more than the tolerance). The arc must not start from
        // there: the start solved for −X comes first (a takeup point), and
        // the arc, still kept, leaves from it.
        let pred = afm_pred();
        let tol = Settings::default().tolerance_mm;
        let tool = 0.0;
        // Without the reversal (the arc starts in +X), it is kept.
        let plans = afm_plans(&["G0 X10 Y10 Z10", "G1 X400 F1000", "G3 X402 Y12 I0 J2"]);
        let res = run_all(&pred, &plans);
        assert!(!res[2].arc_replaced);
        // A takeup only where the straight move's pieces left an axis
        // moving the other way than it was programmed (its drift).
        let programmed = plans[1].mv.map(|m| m.dirs);
        assert!(!res[2].takeup || Some(res[1].dirs) != programmed);
        assert!(res[2].center.is_some());
        // With it.
        let plans = afm_plans(&["G0 X10 Y10 Z10", "G1 X400 F1000", "G2 X398 Y12 I0 J2"]);
        let res = run_all(&pred, &plans);
        let (Some(line), Some(arc)) = (plans[1].mv, plans[2].mv) else {
            panic!("no move")
        };
        assert_eq!(line.dirs[0], 1);
        assert!(res[2].takeup, "no takeup point");
        assert!(!res[2].arc_replaced && res[2].center.is_some());
        assert_eq!(res[2].segments.len(), 1);
        // The clockwise quarter from the bottom of the circle about
        // (400, 12) to its left: −X and +Y all along.
        let start_dirs = dirs_of(&Vector3::new(-1.0, 1.0, 0.0), &arc.dirs);
        let off = (pred.attained(&res[1].end, &start_dirs, tool).pos
            - pred.nominal(&arc.start, tool).pos)
            .norm();
        assert!(off > tol, "{off} mm");
        let at = pred.attained(&res[2].segments[0], &start_dirs, tool).pos;
        assert!((at - pred.nominal(&arc.start, tool).pos).norm() <= SOLVE_TOL_MM);
    }

    /// [`block_after`] over `plans` in one run at `tolerance_mm`.
    fn run_at(pred: &ToolPredictor, plans: &[Plan], tolerance_mm: f64) -> Vec<BlockResult> {
        let settings = Settings { tolerance_mm };
        let mut carry = Some(Carry::program_start([0.0; 6]));
        plans
            .iter()
            .map(|p| match block_after(pred, p, &settings, &mut carry) {
                Ok(r) => r,
                Err(e) => panic!("{e}"),
            })
            .collect()
    }

    #[test]
    fn an_arc_whose_axes_reverse_inside_it_is_judged_with_them() {
        // 350° clockwise about (100, 92), from 95° to 105°: it starts and
        // ends moving +X +Y, but both axes reverse twice inside it, by
        // about 3.5 µm on this machine. Judged with the direction of motion
        // at the start only, the correction looked uniform within 2 µm and
        // the arc would be kept whole, its reversal errors left in; judged
        // with the direction at every point, it is cut at the four
        // reversals into arcs, with a takeup point at each reversal (3.5 µm
        // is beyond half the tolerance), and no chords.
        let pred = afm_pred();
        let plans = afm_plans(&[
            "G0 X99.30275 Y80 Z10",
            "G1 Y99.96956 F1000",
            "G2 X97.92945 Y99.72741 I0.69725 J-7.96956",
        ]);
        let res = run_at(&pred, &plans, 0.002);
        assert!(!res[2].arc_replaced, "chords");
        assert_eq!(res[2].arcs.len(), 5, "{:?}", res[2].arcs);
        assert_eq!(res[2].takeup_at.len(), 4, "{:?}", res[2].takeup_at);
        assert!(res[2].center.is_some());
        // Within one quadrant (no reversal inside) the same arc stays.
        let plans = afm_plans(&[
            "G0 X100 Y80 Z10",
            "G1 Y100 F1000",
            "G2 X105.65685 Y97.65685 I0 J-8",
        ]);
        let res = run_at(&pred, &plans, 0.002);
        assert!(!res[2].arc_replaced, "replaced");
        assert_eq!(res[2].arcs.len(), 1);
        assert_eq!(res[2].segments.len(), usize::from(res[2].takeup));
    }

    #[test]
    fn a_full_turn_that_does_not_close_is_cut_into_arcs() {
        // A full circle entered moving −X, leaving +X: the machine stands
        // where the entry's end was solved for −X, and the circle's end is
        // solved for +X, microns apart. With a tolerance loose enough for
        // its correction to count as uniform, kept whole it would run
        // between those two points: a controller reads that as an arc of
        // almost nothing (or almost a full turn). It is cut at its
        // reversals into quarter arcs that go round. Entered moving +X, its
        // start and end are the same command and it stays a full circle.
        let pred = afm_pred();
        let plans = afm_plans(&["G0 X200 Y100 Z10", "G1 X150 F1000", "X100", "G2 I0 J-8"]);
        let Some(arc) = plans[3].mv.and_then(|mv| mv.arc) else {
            panic!("no arc")
        };
        // A full circle as programmed: 2π but for rounding.
        const ROUNDING_RAD: f64 = 1e-12;
        // The end stays at the programmed point, corrected by microns (not
        // half a circle away).
        const NEAR_MM: f64 = 0.1;
        assert!((arc.sweep.abs() - std::f64::consts::TAU).abs() < ROUNDING_RAD);
        let res = run_at(&pred, &plans, 0.05);
        assert!(!res[3].arc_replaced, "chords");
        let end = res[3].end;
        assert!(
            (end[0] - 100.0).abs() < NEAR_MM && (end[1] - 100.0).abs() < NEAR_MM,
            "{end:?}"
        );
        assert_eq!(res[3].arcs.len(), 4, "{:?}", res[3].arcs);
        for piece in &res[3].arcs {
            assert!(piece.sweep.abs() < std::f64::consts::PI, "{piece:?}");
        }
        let plans = afm_plans(&["G0 X0 Y100 Z10", "G1 X50 F1000", "X100", "G2 I0 J-8"]);
        let res = run_at(&pred, &plans, 0.05);
        assert!(!res[3].arc_replaced && res[3].center.is_some());
        assert_eq!(res[3].arcs.len(), 1);
        assert_eq!(res[2].end, res[3].end);
    }

    #[test]
    fn no_takeup_points_under_cutter_radius_compensation() {
        // The raster passes and the pocket-corner arc of the takeup tests,
        // with G41 active: the controller offsets the path, and a takeup
        // (a move of microns against the direction of travel) would upset
        // its offset computation. Every move starts where the machine
        // stands; after G40 the takeups are back.
        let pred = afm_pred();
        let plans = afm_plans(&[
            "G0 X10 Y10 Z10",
            "G41 D1 G1 X400 F1000",
            "Y20",
            "X10",
            "Y30",
            "X400",
            "Y10",
            "G2 X398 Y12 I0 J2",
            "G40 G1 Y40",
            "X400",
        ]);
        let res = run_all(&pred, &plans);
        let tol = Settings::default().tolerance_mm;
        for (k, (p, r)) in plans.iter().zip(&res).enumerate() {
            // The G41 block starts it, the G40 block ends it: both count.
            assert_eq!(p.cutter_comp, (1..=8).contains(&k), "block {k}");
            assert_eq!(r.takeup, k == 9, "block {k}");
        }
        // The arc after the reversal is kept, from where the machine stands.
        assert!(!res[7].arc_replaced && res[7].segments.is_empty());
        // What the takeups would have removed is reported as left over:
        // the reversals of X (blocks 3, 5), of Y (6) and at the arc's
        // start (7), where the pieces before them have not already
        // reversed the axis by the correction's drift.
        for k in [3, 5, 6, 7]
            .into_iter()
            .filter(|&k| res[k].start_dirs != res[k - 1].dirs)
        {
            assert!(
                res[k].residual_mm > tol,
                "block {k}: {}",
                res[k].residual_mm
            );
        }
        for k in [2, 4, 9]
            .into_iter()
            .filter(|&k| res[k].dirs == res[k - 1].dirs)
        {
            assert!(
                res[k].residual_mm <= tol,
                "block {k}: {}",
                res[k].residual_mm
            );
        }
        // A `/G40` line may be skipped: compensation may go on after it.
        let plans = afm_plans(&[
            "G0 X10 Y10 Z10",
            "G41 D1 G1 X400 F1000",
            "/G40 Y20",
            "X10",
            "G40 Y30",
            "X400",
        ]);
        let comp: Vec<bool> = plans.iter().map(|p| p.cutter_comp).collect();
        assert_eq!(comp, [false, true, true, true, true, false]);
        // Without G41 the same blocks have their takeups.
        let plain: Vec<&str> = [
            "G0 X10 Y10 Z10",
            "G1 X400 F1000",
            "Y20",
            "X10",
            "Y30",
            "X400",
            "Y10",
            "G2 X398 Y12 I0 J2",
        ]
        .to_vec();
        let res = run_all(&pred, &afm_plans(&plain));
        assert!(res[3].takeup && res[5].takeup && res[7].takeup);
    }

    /// A recycled split-point storage, whatever it held, gives the result
    /// of a fresh one, and keeps its allocation.
    #[test]
    fn reused_segment_storage_gives_the_same_result() {
        let pred = afm_pred();
        let plans = afm_plans(&[
            "G0 X0 Y0 Z10",
            "G1 X900 Y20 F1000",
            "G2 X910 Y30 I0 J10",
            "G1 Y20",
        ]);
        let settings = Settings::default();
        let (mut fresh_carry, mut reuse_carry) = (None, None);
        let mut split = false;
        for plan in &plans {
            let fresh = block_after(&pred, plan, &settings, &mut fresh_carry);
            let mut junk = vec![[7.0; 6]; 40];
            junk.reserve(100_000);
            let ptr = junk.as_ptr();
            let reused = block_reusing(&pred, plan, &settings, &mut reuse_carry, junk);
            assert_eq!(fresh, reused);
            if let Ok(r) = &reused {
                split |= !r.segments.is_empty();
                if !r.segments.is_empty() {
                    assert_eq!(r.segments.as_ptr(), ptr, "the storage is kept");
                }
            }
        }
        assert!(split, "the long move is split");
    }

    /// Random straight moves over the travel of `m` (a third along X, a
    /// third in the XY plane, a third in space), with their directions of
    /// motion and solved ends.
    fn random_moves(
        pred: &ToolPredictor,
        tool: f64,
        n: usize,
        seed: u64,
    ) -> Vec<(AxisVec, AxisVec, DirVec, AxisVec, AxisVec)> {
        let mut s = seed;
        let mut rnd = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut out = Vec::new();
        for case in 0..n {
            let mut p0 = [0.0; 6];
            let mut p1 = [0.0; 6];
            for i in 0..3 {
                let (lo, hi) = pred.machine.travel(i).unwrap_or((0.0, 0.0));
                p0[i] = lo + (hi - lo) * rnd();
                p1[i] = lo + (hi - lo) * rnd();
            }
            if case % 3 == 0 {
                p1[1] = p0[1];
            }
            if case % 3 != 2 {
                p1[2] = p0[2];
            }
            let mut dirs = [1i8; 6];
            for i in 0..3 {
                if p1[i] < p0[i] {
                    dirs[i] = -1;
                }
            }
            let solved = |p: &AxisVec| match solve(pred, p, &dirs, tool) {
                Ok((c, _)) => c,
                Err(e) => panic!("{p:?}: {e}"),
            };
            let (c0, c1) = (solved(&p0), solved(&p1));
            out.push((p0, p1, dirs, c0, c1));
        }
        out
    }

    /// Regression: the attained point of a split straight move stays within
    /// the tolerance of the programmed point everywhere, not only where it
    /// is checked. The largest gaps sit where a piece crosses a knot of
    /// the error tables, so sampling a piece at a few points is not
    /// enough. Here the gap to the programmed point at the same
    /// parameter (the pieces' programmed ends from the attained ones) is
    /// sampled at 401 points and at every knot of each piece: the bundled
    /// machine, one with 30 times its angular errors, one with a stiffness
    /// map of 4 to 40 N/µm, one with its tables on a 5 mm pitch; cold and
    /// with force and thermal drift; at 1 and 0.3 µm.
    #[test]
    fn regression_split_pieces_stay_within_the_tolerance_between_samples() {
        use crate::machine::tool::ThermalState;
        let text = testing::afm_text();
        let machines = [
            testing::load(&text, "afm-r1000.yaml"),
            testing::load(&testing::scale_angles(&text, 30.0), "afm-angles-x30.yaml"),
            testing::load(&testing::soft_stiffness(&text), "afm-soft.yaml"),
            // Tables on a 5 mm pitch: the crossings are taken in order.
            testing::load(&testing::fine_tables(&text, 5.0), "afm-fine.yaml"),
        ];
        let hot = MoveContext {
            wrench: Some(crate::predict::Wrench::force(
                Vector3::new(1500.0, -1200.0, 900.0),
                crate::predict::WrenchFrame::Workpiece,
            )),
            thermal: crate::predict::ThermalInput::Tool(ThermalState {
                growth_um: 80.0,
                scale_ppm: [10.0, -6.0, 4.0],
            }),
            ..MoveContext::default()
        };
        let tool = 140.0;
        for m in &machines {
            let mut split = 0;
            let mut worst = 0.0f64;
            for ctx in [MoveContext::default(), hot] {
                let pred = ToolPredictor::new(m, EffectSet::default()).with_context(ctx);
                for tol in [1e-3, 3e-4] {
                    for (p0, p1, dirs, c0, c1) in random_moves(&pred, tool, 30, 999) {
                        let lip = Lip::new(tool);
                        let mut pts = vec![c0];
                        if let Err(e) = split_line(
                            &pred,
                            &p0,
                            &p1,
                            &c0,
                            &c1,
                            SOLVE_TOL_MM,
                            &dirs,
                            &lip,
                            (tol, None),
                            true,
                            &mut pts,
                        ) {
                            panic!("{}: {e}", m.name());
                        }
                        split += usize::from(pts.len() > 2);
                        let n0 = pred.nominal(&p0, tool).pos;
                        let d = pred.nominal(&p1, tool).pos - n0;
                        let param = |c: &AxisVec| {
                            (pred.attained(c, &dirs, tool).pos - n0).dot(&d) / d.norm_squared()
                        };
                        for w in pts.windows(2) {
                            let (ta, tb) = (param(&w[0]), param(&w[1]));
                            let mut fs: Vec<f64> = (0..=400).map(|k| k as f64 / 400.0).collect();
                            for (slot, (&a, &b)) in w[0].iter().zip(&w[1]).enumerate().take(3) {
                                if a != b {
                                    fs.extend(
                                        m.breakpoints(slot)
                                            .iter()
                                            .map(|x| (x - a) / (b - a))
                                            .filter(|f| *f > 0.0 && *f < 1.0),
                                    );
                                }
                            }
                            for f in fs {
                                let got = pred.attained(&lerp(&w[0], &w[1], f), &dirs, tool).pos;
                                let gap = (got - (n0 + d * (ta + (tb - ta) * f))).norm();
                                // The pieces' programmed ends are found from
                                // the attained ones, within the solve's 1e-7 mm.
                                assert!(
                                    gap <= tol + 2.0 * SOLVE_TOL_MM,
                                    "{}: gap {gap:.8} mm at tolerance {tol}",
                                    m.name()
                                );
                                worst = worst.max(gap / tol);
                            }
                        }
                    }
                }
            }
            // Each machine splits moves, and its pieces use the tolerance,
            // not a small part of it.
            assert!(split > 40, "{}: split moves: {split}", m.name());
            assert!(worst > 0.5, "{}: largest gap / tolerance {worst}", m.name());
        }
    }

    /// The proof applies to every piece of a machine without rotary axes:
    /// splitting random moves never falls back to the samples, also on a
    /// machine whose tables hold a −0 (no cell form: the global bounds
    /// decide, on shorter pieces), and the bend bounds are reached (moves
    /// proven whole or in pieces, not only failed at a crossing).
    #[test]
    fn every_piece_of_a_linear_machine_is_proven() {
        let text = testing::afm_text();
        let negative_zero = text.replacen("forward: [0.0, 2.3", "forward: [-0.0, 2.3", 1);
        assert_ne!(negative_zero, text);
        for m in [
            testing::load(&text, "afm-r1000.yaml"),
            testing::load(&negative_zero, "afm-negative-zero.yaml"),
        ] {
            let pred = ToolPredictor::new(&m, EffectSet::default());
            let tool = 62.5;
            let mut pieces = 0;
            SAMPLED.with(|n| n.set(0));
            for tol in [1e-3, 1e-2] {
                for (p0, p1, dirs, c0, c1) in random_moves(&pred, tool, 90, 7) {
                    let mut pts = vec![c0];
                    if let Err(e) = split_line(
                        &pred,
                        &p0,
                        &p1,
                        &c0,
                        &c1,
                        SOLVE_TOL_MM,
                        &dirs,
                        &Lip::new(tool),
                        (tol, None),
                        true,
                        &mut pts,
                    ) {
                        panic!("{e}");
                    }
                    pieces += pts.len() - 1;
                }
            }
            assert_eq!(SAMPLED.with(|n| n.get()), 0, "pieces sampled");
            assert!(pieces > 180, "{pieces} pieces");
        }
    }

    /// The two ways of taking the crossings of a piece (all at once from the
    /// middle outwards, or one by one in order) give the same verdict on
    /// every piece they can both take.
    #[test]
    fn both_orders_of_crossings_agree() {
        use crate::machine::tool::testing;
        let m = testing::load(&testing::afm_text(), "afm-r1000.yaml");
        let pred = ToolPredictor::new(&m, EffectSet::default());
        let tool = 62.5;
        let (mut compared, mut passed) = (0, 0);
        for tol in [1e-3, 1e-2] {
            for (p0, p1, dirs, c0, c1) in random_moves(&pred, tool, 120, 3) {
                let lip = Lip::new(tool);
                let piece = Piece {
                    pred: &pred,
                    p0: &p0,
                    p1: &p1,
                    ends: Some((pred.nominal(&p0, tool).pos, pred.nominal(&p1, tool).pos)),
                    ts: &[],
                    dirs: &dirs,
                    lip: &lip,
                    tol,
                    grid: None,
                    keep_end: true,
                };
                let (inner, total) = piece.inside(&c0, &c1);
                if total == 0 || total > MAX_BREAKS {
                    continue;
                }
                let budget = tol - SKIP_MARGIN_MM;
                let stretches = Stretches::new(&piece, 0.0, 1.0, &c0, &c1, budget);
                let at_once = piece.certify(0.0, 1.0, &c0, &c1, SOLVE_TOL_MM);
                assert_eq!(
                    at_once,
                    piece.certify_in_order(&inner, &stretches, SOLVE_TOL_MM)
                );
                compared += 1;
                passed += usize::from(at_once == Some(true));
            }
        }
        assert!(
            compared > 100 && passed > 20,
            "{compared} compared, {passed} proven"
        );
    }

    /// A piece crossing more breakpoints than the proof's arrays hold is
    /// proven by taking its crossings in order, not split for their number:
    /// with the tables resampled on a 5 mm pitch (the same error functions,
    /// about 200 knots on X), long moves get as many pieces as with the
    /// 100 mm tables (equal up to where a split falls), and moves that need
    /// no split on the coarse machine need none on the fine one.
    #[test]
    fn fine_pitch_tables_do_not_force_splits() {
        use crate::machine::tool::testing;
        let text = testing::afm_text();
        let fine_text = testing::fine_tables(&text, 5.0);
        let coarse = testing::load(&text, "afm-r1000.yaml");
        let fine = testing::load(&fine_text, "afm-fine.yaml");
        assert!(
            fine.breakpoints(0).len() > 3 * MAX_BREAKS,
            "{}",
            fine.breakpoints(0).len()
        );
        let tool = 62.5;
        let mut whole = 0;
        let mut long = 0;
        for tol in [1e-3, 1e-2] {
            let (pc, pf) = (
                ToolPredictor::new(&coarse, EffectSet::default()),
                ToolPredictor::new(&fine, EffectSet::default()),
            );
            for (k, ((p0, p1, dirs, c0, c1), (_, _, _, f0, f1))) in random_moves(&pc, tool, 60, 21)
                .into_iter()
                .zip(random_moves(&pf, tool, 60, 21))
                .enumerate()
            {
                let pieces = |pred: &ToolPredictor, a: &AxisVec, b: &AxisVec| {
                    let mut pts = Vec::new();
                    match split_line(
                        pred,
                        &p0,
                        &p1,
                        a,
                        b,
                        SOLVE_TOL_MM,
                        &dirs,
                        &Lip::new(tool),
                        (tol, None),
                        true,
                        &mut pts,
                    ) {
                        Ok(()) => pts.len(),
                        Err(e) => panic!("{k}: {e}"),
                    }
                };
                let (n_coarse, n_fine) = (pieces(&pc, &c0, &c1), pieces(&pf, &f0, &f1));
                let crossings = fine
                    .breakpoints(0)
                    .iter()
                    .filter(|&&x| (x - p0[0]) * (x - p1[0]) < 0.0)
                    .count();
                if crossings > MAX_BREAKS {
                    long += 1;
                }
                if n_coarse == 1 && crossings > MAX_BREAKS {
                    whole += 1;
                    assert_eq!(n_fine, 1, "{k}: a move proven whole on the coarse tables");
                }
                assert!(
                    n_fine <= n_coarse + 1 + n_coarse / 4,
                    "{k}: {n_fine} pieces, {n_coarse} with coarse tables"
                );
            }
        }
        assert!(long > 20 && whole > 3, "{long} long moves, {whole} whole");
    }
}
