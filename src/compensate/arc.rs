//! Compensation of circular and helical moves: an arc is cut where an axis
//! of its plane reverses (the direction-dependent errors change there at
//! once), each part is written as an arc about its own shifted centre
//! (halved until it fits the tolerance), with a takeup point where the
//! reversal would otherwise leave the machine off the path; only a part
//! that no arc fits is written as chords, each split like a straight move.

use nalgebra::Vector3;

use super::{
    BlockResult, Carry, Failure, Lip, SKIP_MARGIN_MM, SOLVE_TOL_MM, TAKEUP_SHARE,
    check_travel_within, dirs_of, lerp, solve, solve_near, split_line, start_from, start_gap,
    with_xyz,
};
use crate::machine::{AxisVec, DirVec};
use crate::predict::{ToolPredictor, Wrench, WrenchFrame};
use crate::process::{ForceModel, Frame};
use crate::program::interp::{ArcGeom, DIRECTION_DEADBAND, END_INSIDE, Move};

/// Deepest halving of one part of an arc between reversals (up to 2^3
/// arcs) before it is written as chords.
pub const MAX_ARC_DEPTH: u32 = 3;
/// Largest angle between the points at which an arc piece is checked, rad
/// (2°).
const ARC_SAMPLE_RAD: f64 = std::f64::consts::PI / 90.0;
/// Largest arc length between the points at which an arc piece is
/// checked, mm.
const ARC_SAMPLE_MM: f64 = 2.0;
/// Most points at which one arc piece is checked.
const MAX_ARC_SAMPLES: usize = 720;
/// Arc parameters closer than this to an end of the arc are no reversal
/// inside it.
const REVERSAL_MARGIN: f64 = 1e-6;
/// Largest change of a piece's sweep by the compensation, rad: more means
/// the compensated ends are not where the piece's arc would take them.
const MAX_SWEEP_CHANGE_RAD: f64 = 0.01;
/// Parameter distance from a reversal at which the directions of its two
/// sides are taken.
const REVERSAL_SIDE: f64 = 1e-9;
/// Share of the tolerance the rise of the gap between two checked points of
/// an arc piece is brought under where the piece is long enough to need
/// it ([`ArcJob::between_points`]).
const BOUND_SHARE: f64 = 0.01;
/// Half chord from which a piece's centre may move along the chord by more
/// than the tolerance ([`ArcJob::fit`]), mm.
const MIN_FREE_HALF_CHORD_MM: f64 = 0.1;
/// Sweep within which of a whole turn an arc counts as a full turn, rad.
const FULL_TURN_EPS_RAD: f64 = 1e-9;
/// Most reversals inside one arc (a full turn has four).
const MAX_REVERSALS: usize = 6;

/// Deepest halving of an arc's part under a process load that turns with
/// the feed direction (2^6 pieces between two reversals), before a takeup
/// point takes up the change of load between two pieces.
const MAX_LOAD_DEPTH: u32 = 6;

/// The process load of an arc whose force turns with the feed direction
/// (a milling force, a constant force in the feed frame): read back, each
/// written piece gets the load of its own feed direction at its end, as
/// the time line gives every block (`pipeline::gcode`), so each piece is
/// solved with it.
#[derive(Debug, Clone, Copy)]
struct TurningLoad {
    /// The tool axis, unit.
    axis: Vector3<f64>,
    /// The block's force in its feed frame (along the feed across the
    /// axis, normal to it, along the axis), N.
    feed_frame: Vector3<f64>,
}

/// The feed frame of the feed direction `feed` about the tool axis `axis`
/// (unit): x the feed across the axis, y = axis × x, z the axis; `None`
/// where the feed is within [`crate::process::AXIAL_FEED_RAD`] of the axis.
fn feed_frame(axis: &Vector3<f64>, feed: &Vector3<f64>) -> Option<[Vector3<f64>; 3]> {
    let x = (feed - axis * axis.dot(feed)).try_normalize(crate::process::AXIAL_FEED_RAD.sin())?;
    Some([x, axis.cross(&x), *axis])
}

impl TurningLoad {
    /// The arc's turning load, `None` where its force does not turn with
    /// the feed (no force, a workpiece- or tool-frame force, drilling, a
    /// table) or its feed runs along the tool axis.
    fn of(pred: &ToolPredictor, mv: &Move, arc: &ArcGeom) -> Option<Self> {
        let force = match pred.process {
            Some(p) => p.force.as_ref(),
            None => pred.machine.process_force(),
        }?;
        let turns = matches!(
            force,
            ForceModel::Milling(_)
                | ForceModel::Constant {
                    frame: Frame::Feed,
                    ..
                }
        );
        let w = pred.ctx.wrench?;
        if !turns || w.frame != WrenchFrame::Workpiece || w.force_n == Vector3::zeros() {
            return None;
        }
        let axis = pred.machine.nominal(&mv.end, mv.tool_len_mm).dir;
        let (s3, e3) = (mv.start3(), mv.end3());
        let b = feed_frame(&axis, &arc.tangent(&s3, &e3, END_INSIDE))?;
        let f = w.force_n;
        Some(TurningLoad {
            axis,
            feed_frame: Vector3::new(b[0].dot(&f), b[1].dot(&f), b[2].dot(&f)),
        })
    }

    /// The load of a piece whose feed direction at its end is `feed`:
    /// the block's (`ctx`) turned with it.
    fn at(&self, pred: &ToolPredictor, feed: &Vector3<f64>) -> Option<Wrench> {
        let b = feed_frame(&self.axis, feed)?;
        let v = &self.feed_frame;
        let f = b[0] * v[0] + b[1] * v[1] + b[2] * v[2];
        Some(Wrench {
            force_n: f,
            ..pred.ctx.wrench?
        })
    }
}

/// A piece of a compensated arc that is written as an arc.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArcPiece {
    /// The target the piece ends at: `segments[to]` of the block's result,
    /// its `end` when `to` is the number of segments.
    pub to: usize,
    /// Compensated centre, machine coordinates (in the normal axis: the
    /// piece's start).
    pub center: Vector3<f64>,
    /// Signed swept angle of the piece, rad.
    pub sweep: f64,
}

/// The parameters in (0, 1) of `arc` (from `s3` to `e3`) at which an axis of
/// its plane reverses (its tangent component changes sign: the quadrant
/// points), ascending, in `ts`; returns how many.
pub fn reversals(arc: &ArcGeom, s3: &Vector3<f64>, ts: &mut [f64; MAX_REVERSALS]) -> usize {
    let (a, b, _) = arc.plane.axes();
    let a0 = (s3[b] - arc.center[b]).atan2(s3[a] - arc.center[a]);
    if arc.sweep == 0.0 || !arc.sweep.is_finite() {
        return 0;
    }
    let quarter = std::f64::consts::FRAC_PI_2;
    let a1 = a0 + arc.sweep;
    let (lo, hi) = if a1 > a0 { (a0, a1) } else { (a1, a0) };
    let mut n = 0;
    let mut k = (lo / quarter).ceil();
    while k * quarter <= hi && n < MAX_REVERSALS {
        let s = (k * quarter - a0) / arc.sweep;
        if s > REVERSAL_MARGIN && s < 1.0 - REVERSAL_MARGIN {
            if let Some(t) = ts.get_mut(n) {
                *t = s;
                n += 1;
            }
        }
        k += 1.0;
    }
    if let Some(t) = ts.get_mut(..n) {
        t.sort_unstable_by(f64::total_cmp);
    }
    n
}

/// One arc being compensated.
#[derive(Clone, Copy)]
struct ArcJob<'a, 'm> {
    pred: &'a ToolPredictor<'m>,
    mv: &'a Move,
    arc: &'a ArcGeom,
    s3: Vector3<f64>,
    e3: Vector3<f64>,
    lip: &'a Lip<'m>,
    tol: f64,
    /// Nominal tip minus command (machines without rotary axes: the
    /// nominal chain is a translation), to measure the distance to the
    /// programmed arc; `None` compares with the programmed point at the
    /// same parameter.
    offset: Option<Vector3<f64>>,
    /// The load where it turns with the feed direction: each piece is
    /// then solved with its own.
    load: Option<TurningLoad>,
}

impl<'m> ArcJob<'_, 'm> {
    /// The programmed command at parameter `s` of the arc.
    fn at(&self, s: f64) -> AxisVec {
        with_xyz(
            &lerp(&self.mv.start, &self.mv.end, s),
            &self.arc.point(&self.s3, &self.e3, s),
        )
    }

    /// How far the attained tip `got`, reached near parameter `s`, is from
    /// the programmed arc, mm: with a translating nominal chain, from the
    /// programmed helix or spiral (radially and along its axis at the same
    /// angle), else from the programmed point at `s`.
    fn gap(&self, got: &Vector3<f64>, s: f64) -> f64 {
        let Some(off) = self.offset else {
            let want = self.pred.nominal(&self.at(s), self.lip.tool_mm).pos;
            return (got - want).norm();
        };
        let q = got - off;
        let arc = self.arc;
        let (a, b, n) = arc.plane.axes();
        let c = arc.center;
        let a0 = (self.s3[b] - c[b]).atan2(self.s3[a] - c[a]);
        let phi = (q[b] - c[b]).atan2(q[a] - c[a]);
        let expected = a0 + arc.sweep * s;
        let tau = std::f64::consts::TAU;
        let d_phi = (phi - expected + std::f64::consts::PI).rem_euclid(tau) - std::f64::consts::PI;
        let s_at = (s + d_phi / arc.sweep).clamp(0.0, 1.0);
        let z = self.s3[n] + (self.e3[n] - self.s3[n]) * s_at;
        // The programmed radius there (a spiral's changes with the angle).
        let radial = (q[a] - c[a]).hypot(q[b] - c[b]) - arc.radius_at(&self.s3, &self.e3, s_at);
        radial.hypot(q[n] - z)
    }

    /// The arc from the command `ca` (gap `ga` to the programmed point of
    /// `s0`) to `cb` (a solution of `s1`) about the programmed centre
    /// shifted by the mean of the ends' corrections (moved onto the
    /// perpendicular bisector of `ca`–`cb`, so both ends lie on it): its
    /// centre and sweep when the attained path keeps within the tolerance
    /// at every checked point, with the directions of motion `d`.
    /// With `local`, each point is checked with the directions of motion
    /// of the arc there (`d` the base for axes that do not move), for an
    /// arc with reversals inside.
    fn fit(
        &self,
        (s0, s1): (f64, f64),
        (ca, ga): (&AxisVec, f64),
        cb: &AxisVec,
        (d, local): (&DirVec, bool),
    ) -> Option<(Vector3<f64>, f64)> {
        let budget = self.tol - SKIP_MARGIN_MM;
        if ga > budget {
            return None;
        }
        let (a, b, n) = self.arc.plane.axes();
        let (pa, pb) = (self.at(s0), self.at(s1));
        let corr = |c: &AxisVec, p: &AxisVec| Vector3::new(c[0] - p[0], c[1] - p[1], c[2] - p[2]);
        let mut cc = self.arc.center + (corr(ca, &pa) + corr(cb, &pb)) / 2.0;
        let (ua, ub) = (cb[a] - ca[a], cb[b] - ca[b]);
        let l2 = ua * ua + ub * ub;
        if l2 > SOLVE_TOL_MM * SOLVE_TOL_MM {
            let (ma, mb) = ((ca[a] + cb[a]) / 2.0, (ca[b] + cb[b]) / 2.0);
            let k = ((cc[a] - ma) * ua + (cc[b] - mb) * ub) / l2;
            // On a piece microns long the bisector's direction is noise:
            // a centre moved by more than the tolerance is no fit. On a
            // longer piece a move along its chord by `m` turns the arc
            // through the ends by about `m` times the half chord over the
            // radius, and the points below check it: the centre may move
            // by the tolerance times the radius over the half chord.
            let half = l2.sqrt() / 2.0;
            let allowed = if half >= MIN_FREE_HALF_CHORD_MM {
                self.tol * (self.arc.radius / half).max(1.0)
            } else {
                self.tol
            };
            if (k * k * l2).sqrt() > allowed {
                return None;
            }
            cc[a] -= k * ua;
            cc[b] -= k * ub;
        }
        cc[n] = ca[n];
        let r = (ca[a] - cc[a]).hypot(ca[b] - cc[b]);
        // The control moves the written piece as a spiral where its ends
        // are not on one circle about the centre (grammar/gcode.md, "Arcs").
        let dr = (cb[a] - cc[a]).hypot(cb[b] - cc[b]) - r;
        let start = (ca[b] - cc[b]).atan2(ca[a] - cc[a]);
        let want = self.arc.sweep * (s1 - s0);
        let mut sweep = (cb[b] - cc[b]).atan2(cb[a] - cc[a]) - start;
        let (pi, tau) = (std::f64::consts::PI, std::f64::consts::TAU);
        while sweep - want > pi {
            sweep -= tau;
        }
        while want - sweep > pi {
            sweep += tau;
        }
        if sweep * want <= 0.0 || (sweep - want).abs() > MAX_SWEEP_CHANGE_RAD || !r.is_finite() {
            return None;
        }
        // A full turn stays one only while its ends coincide: an arc
        // between two points microns apart reads as almost nothing or
        // almost a full turn, depending on the controller.
        let turn = want.abs() >= tau - FULL_TURN_EPS_RAD;
        if turn && (cb[a] - ca[a]).hypot(cb[b] - ca[b]) > SOLVE_TOL_MM {
            return None;
        }
        let len = (r * want.abs()).hypot(cb[n] - ca[n]);
        let lip = self.lip.on(self.pred, ca, cb);
        let mut k = ((want.abs() / ARC_SAMPLE_RAD).ceil())
            .max((r * want.abs() / ARC_SAMPLE_MM).ceil())
            .max(lip.map_or(0.0, |l| (l * len / (self.tol * BOUND_SHARE)).ceil()))
            .clamp(4.0, MAX_ARC_SAMPLES as f64) as usize;
        if turn {
            k = k.max(4);
        }
        let budget = budget - self.between_points(lip, (ca, cb), (&cc, r), (len, want, k));
        let tool = self.lip.tool_mm;
        let point = |f: f64, dirs: &DirVec| -> bool {
            let ang = start + sweep * f;
            let mut cmd = lerp(ca, cb, f);
            cmd[a] = cc[a] + (r + dr * f) * ang.cos();
            cmd[b] = cc[b] + (r + dr * f) * ang.sin();
            let s = s0 + (s1 - s0) * f;
            let got = self.pred.attained(&cmd, dirs, tool).pos;
            // (NaN fails too)
            self.gap(&got, s) <= budget
        };
        let dirs_at = |f: f64| -> DirVec {
            if local {
                dirs_of(&self.arc.tangent(&self.s3, &self.e3, s0 + (s1 - s0) * f), d)
            } else {
                *d
            }
        };
        for j in 1..k {
            let f = j as f64 / k as f64;
            if !point(f, &dirs_at(f)) {
                return None;
            }
        }
        if local {
            // The direction-dependent error jumps at each reversal: the
            // point there under the directions of both sides.
            let mut ts = [0.0; MAX_REVERSALS];
            let m = reversals(self.arc, &self.s3, &mut ts);
            for &t in ts.get(..m).unwrap_or(&[]) {
                let f = ((t - s0) / (s1 - s0)).clamp(0.0, 1.0);
                let (before, after) = (
                    dirs_at((f - REVERSAL_SIDE).max(0.0)),
                    dirs_at((f + REVERSAL_SIDE).min(1.0)),
                );
                if !point(f, &before) || !point(f, &after) {
                    return None;
                }
            }
        }
        Some((cc, sweep))
    }

    /// How far the gap of an arc piece from `ca` to `cb` (centre `cc`,
    /// radius `r`, length `len` mm, sweep `want`, checked at `k` points) can
    /// rise between two checked points above the larger of the two, mm:
    /// with a translating nominal chain the gap is the norm of the radial
    /// and axial distances of `c + e(c)` from the programmed helix; along
    /// the piece each is a smooth function of the angle (the circles'
    /// offset, the error turned against the radial direction, the error's
    /// bend) plus the error's departure from smooth, which the model's
    /// Lipschitz constant `L` bounds. Between points `h` mm and `Δθ` apart
    /// that is at most `L·h` plus `(|e| + |cc − c₀| + L·r + M₂·r²)·Δθ²/4`
    /// (`|e|` the larger correction at the ends plus the tolerance, `c₀`
    /// the programmed centre, `M₂` the stiffness map's bend). `L` and
    /// `M₂` are the block's; without `L` (rotary axes) the points are the
    /// check, at most [`ARC_SAMPLE_MM`] and [`ARC_SAMPLE_RAD`] apart.
    fn between_points(
        &self,
        lip: Option<f64>,
        (ca, cb): (&AxisVec, &AxisVec),
        (cc, r): (&Vector3<f64>, f64),
        (len, want, k): (f64, f64, usize),
    ) -> f64 {
        let (Some(l), Some(_)) = (lip, self.offset) else {
            return 0.0;
        };
        let (pa, pb) = (self.at(0.0), self.at(1.0));
        let corr =
            |c: &AxisVec, p: &AxisVec| (0..3).map(|s| (c[s] - p[s]).powi(2)).sum::<f64>().sqrt();
        let e = corr(ca, &pa).max(corr(cb, &pb)).min(1.0) + self.tol;
        let shift = (cc - self.arc.center).norm();
        let stat = self.lip.static_curvature(self.pred);
        let (h, dth) = (len / k as f64, want.abs() / k as f64);
        l * h + (e + shift + l * r + stat * r * r) * dth * dth / 4.0
    }

    /// Writes the part `s0..s1` of the arc (no reversal inside; directions
    /// of motion `d`) from `ca` (gap `ga`) to `cb` into `res`: one arc when
    /// it fits, else its halves, down to [`MAX_ARC_DEPTH`], then chords.
    /// Pushes `cb` last. Returns whether chords were written.
    #[allow(clippy::too_many_arguments)]
    fn part(
        &self,
        (s0, s1): (f64, f64),
        (ca, ga): (&AxisVec, f64),
        cb: &AxisVec,
        d: &DirVec,
        depth: u32,
        res: &mut BlockResult,
    ) -> Result<bool, Failure> {
        if let Some((center, sweep)) = self.fit((s0, s1), (ca, ga), cb, (d, false)) {
            push_arc(res, *cb, (center, sweep));
            return Ok(false);
        }
        // A part one chord can follow within the tolerance is not halved.
        let sag = self.arc.radius * (1.0 - (self.arc.sweep * (s1 - s0) / 2.0).cos());
        if depth < MAX_ARC_DEPTH && sag > self.tol / 2.0 {
            let sm = (s0 + s1) / 2.0;
            let (cm, _) = solve_near(self.pred, &self.at(sm), ca, &self.at(s0), d, self.lip)?;
            let first = self.part((s0, sm), (ca, ga), &cm, d, depth + 1, res)?;
            let second = self.part((sm, s1), (&cm, SOLVE_TOL_MM), cb, d, depth + 1, res)?;
            return Ok(first || second);
        }
        self.chords((s0, s1), (ca, ga), cb, d, res)?;
        Ok(true)
    }

    /// Where part `i` of the arc (programmed start `p0`, directions `d`)
    /// starts when the machine stands at `c`, solved for other directions
    /// ([`start_from`]): the start command and its gap. A takeup point is
    /// pushed to `res` where needed; without takeups, the part is fitted
    /// from its solved start and the gap left is raised in `left` (with
    /// the bound of the miss it causes).
    fn start(
        &self,
        (i, p0, c, d): (usize, AxisVec, AxisVec, DirVec),
        takeups: bool,
        left: &mut (f64, f64),
        res: &mut BlockResult,
    ) -> Result<(AxisVec, f64), Failure> {
        let (pred, lip) = (self.pred, self.lip);
        let st = start_from(
            pred,
            &p0,
            &c,
            &d,
            lip,
            (self.tol, takeups),
            &mut res.segments,
        )?;
        if st.takeup {
            if i == 0 {
                res.takeup = true;
            } else {
                res.takeup_at.push(res.segments.len() - 1);
            }
        }
        if st.left_mm > 0.0 {
            // The part is fitted from its solved start `c0`, but leaves from
            // `c` (where the machine stands, or its takeup point held at an
            // end of travel): the written arc (its centre words relative to
            // `c`) is off the fitted one by up to their distance, so its
            // miss is at most the gap at `c` or the tolerance plus that
            // distance (a bound, beyond the tolerance: warned).
            let (c, c0) = (st.c, st.fit);
            let apart = (0..3).map(|s| (c[s] - c0[s]).powi(2)).sum::<f64>().sqrt();
            let l = lip.on(pred, &c, &c0).unwrap_or(1.0);
            left.0 = left.0.max(st.left_mm);
            left.1 = left.1.max(st.left_mm).max(self.tol + apart * (1.0 + l));
            return Ok((c0, SOLVE_TOL_MM));
        }
        Ok((st.c, st.gap))
    }

    /// The predictor of the piece `s0..s1` under a turning load: the
    /// block's with the load of the piece's feed direction at its end (as
    /// the time line reads the written piece back); the block's where the
    /// load does not turn.
    fn piece_pred(&self, s0: f64, s1: f64) -> ToolPredictor<'m> {
        let pred = *self.pred;
        let Some(load) = &self.load else {
            return pred;
        };
        let t = self
            .arc
            .tangent(&self.s3, &self.e3, s0 + (s1 - s0) * END_INSIDE);
        match load.at(&pred, &t) {
            Some(w) => pred.with_context(crate::predict::MoveContext {
                wrench: Some(w),
                ..pred.ctx
            }),
            None => pred,
        }
    }

    /// [`Self::part`] under a turning load: the part `s0..s1` (directions
    /// `d`) from where the machine stands, `ca` (solved for the load of the
    /// piece before), each piece solved with its own load. Where the change
    /// of load leaves the start more than [`TAKEUP_SHARE`] of the
    /// tolerance off the path, the part is halved (the load turns less
    /// along each half), down to [`MAX_LOAD_DEPTH`]; beyond it a takeup
    /// point comes first ([`Self::start`]). Pushes its end last.
    #[allow(clippy::too_many_arguments)]
    fn part_loaded(
        &self,
        (s0, s1): (f64, f64),
        ca: &AxisVec,
        d: &DirVec,
        depth: u32,
        takeups: bool,
        left: &mut (f64, f64),
        res: &mut BlockResult,
    ) -> Result<bool, Failure> {
        let pp = self.piece_pred(s0, s1);
        let tool = self.lip.tool_mm;
        let p0 = self.at(s0);
        let gap = start_gap(&pp, &p0, ca, d, tool);
        if gap > self.tol * TAKEUP_SHARE && depth < MAX_LOAD_DEPTH {
            let sm = (s0 + s1) / 2.0;
            let first = self.part_loaded((s0, sm), ca, d, depth + 1, takeups, left, res)?;
            let cm = res.segments.last().copied().unwrap_or(*ca);
            let second = self.part_loaded((sm, s1), &cm, d, depth + 1, takeups, left, res)?;
            return Ok(first || second);
        }
        let lip = Lip::new(tool);
        let job = ArcJob {
            pred: &pp,
            lip: &lip,
            load: None,
            ..*self
        };
        let (c0, ga) = job.start((res.segments.len(), p0, *ca, *d), takeups, left, res)?;
        let (cb, _) = solve_near(&pp, &job.at(s1), &c0, &p0, d, &lip)?;
        if let Some((center, sweep)) = job.fit((s0, s1), (&c0, ga), &cb, (d, false)) {
            push_arc(res, cb, (center, sweep));
            return Ok(false);
        }
        // Halved as an arc without a turning load is, each half with its
        // own load.
        let sag = self.arc.radius * (1.0 - (self.arc.sweep * (s1 - s0) / 2.0).cos());
        if depth < MAX_LOAD_DEPTH + MAX_ARC_DEPTH && sag > self.tol / 2.0 {
            let sm = (s0 + s1) / 2.0;
            let first = self.part_loaded((s0, sm), &c0, d, depth + 1, takeups, left, res)?;
            let cm = res.segments.last().copied().unwrap_or(c0);
            let second = self.part_loaded((sm, s1), &cm, d, depth + 1, takeups, left, res)?;
            return Ok(first || second);
        }
        job.chords((s0, s1), (&c0, ga), &cb, d, res)?;
        Ok(true)
    }

    /// The part `s0..s1` as chords: sagitta within half the tolerance,
    /// each chord split like a straight move with the rest of the budget.
    fn chords(
        &self,
        (s0, s1): (f64, f64),
        (ca, ga): (&AxisVec, f64),
        cb: &AxisVec,
        d: &DirVec,
        res: &mut BlockResult,
    ) -> Result<(), Failure> {
        let sag = self.tol / 2.0;
        let r = self.arc.radius.max(1e-9);
        let max_step = 2.0 * (1.0 - sag / r).clamp(-1.0, 1.0).acos();
        let sweep = (self.arc.sweep * (s1 - s0)).abs();
        let n = ((sweep / max_step.max(1e-6)).ceil() as usize).clamp(1, 1 << 16);
        let (mut prev_p, mut prev_c, mut gap) = (self.at(s0), *ca, ga);
        for k in 1..=n {
            let s = s0 + (s1 - s0) * k as f64 / n as f64;
            let p = self.at(s);
            let c = if k == n {
                *cb
            } else {
                solve(self.pred, &p, d, self.lip.tool_mm)?.0
            };
            split_line(
                self.pred,
                &prev_p,
                &p,
                &prev_c,
                &c,
                gap,
                d,
                self.lip,
                (self.tol - sag, None),
                true,
                &mut res.segments,
            )?;
            (prev_p, prev_c, gap) = (p, c, SOLVE_TOL_MM);
        }
        Ok(())
    }
}

/// An arc, cut at the reversals of its plane's axes into parts, each written
/// as arcs (or, where no arc fits, chords), with a takeup point before a part
/// whose start the machine would otherwise miss by more than
/// [`super::TAKEUP_SHARE`] of the tolerance. Returns the direction of motion
/// the arc ends with.
pub(super) fn arc_block(
    pred: &ToolPredictor,
    mv: &Move,
    arc: &ArcGeom,
    (tool, tol, takeups): (f64, f64, bool),
    carry_in: Option<&Carry>,
    res: &mut BlockResult,
) -> Result<DirVec, Failure> {
    let lip = Lip::new(tool);
    let affine = !(3..6).any(|s| pred.machine.has_axis(s));
    let job = ArcJob {
        pred,
        mv,
        arc,
        s3: mv.start3(),
        e3: mv.end3(),
        lip: &lip,
        tol,
        offset: affine.then(|| {
            let n = pred.nominal(&mv.start, tool).pos;
            n - mv.start3()
        }),
        load: TurningLoad::of(pred, mv, arc),
    };
    let mut ts = [0.0; MAX_REVERSALS];
    let n = reversals(arc, &job.s3, &mut ts);
    // Where the machine stands: the previous block's end, when it ended at
    // the arc's start.
    let mut at: Option<(AxisVec, DirVec)> = carry_in
        .filter(|k| k.stands_at(&mv.start))
        .map(|k| (k.c, k.dirs));
    // The gap left at a start where no takeup may be written, and the
    // bound of the miss it causes.
    let mut left = (0.0f64, 0.0f64);
    // An axis outside the arc's plane that the arc moves less than the
    // deadband keeps the direction the written pieces before left it in.
    let mut base = mv.dirs;
    if let Some(k) = carry_in {
        let (a, b, _) = arc.plane.axes();
        for s in (0..6).filter(|&s| s != a && s != b) {
            if (mv.end[s] - mv.start[s]).abs() <= DIRECTION_DEADBAND {
                base[s] = k.moved[s];
            }
        }
    }
    let mut last_dirs = base;
    let mut end_residual = res.residual_mm;
    for i in 0..=n {
        let s0 = if i == 0 { 0.0 } else { ts[i - 1] };
        let s1 = if i == n { 1.0 } else { ts[i] };
        let d = dirs_of(&arc.tangent(&job.s3, &job.e3, (s0 + s1) / 2.0), &base);
        if i == 0 {
            res.start_dirs = d;
        }
        let p0 = job.at(s0);
        if job.load.is_some() && !(i == 0 && n > 0) {
            // Each piece with its own load, from where the machine stands.
            let from = match at {
                Some((c, _)) => c,
                None => solve(&job.piece_pred(s0, s1), &p0, &d, tool)?.0,
            };
            let chords = job.part_loaded((s0, s1), &from, &d, 0, takeups, &mut left, res)?;
            res.arc_replaced |= chords;
            end_residual = SOLVE_TOL_MM;
            at = res.segments.last().map(|c| (*c, d));
            last_dirs = d;
            continue;
        }
        let c1 = if i == n && d == mv.dirs {
            res.end
        } else {
            let (c, r) = solve(pred, &job.at(s1), &d, tool)?;
            end_residual = r;
            c
        };
        let (c0, gap) = match at {
            Some((c, pd)) if pd == d && i > 0 => (c, SOLVE_TOL_MM),
            Some((c, _)) => {
                // From where the machine stands: a takeup point first where
                // it would start the part more than the takeup share of the
                // tolerance off the path (as a straight move does).
                job.start((i, p0, c, d), takeups, &mut left, res)?
            }
            None => (solve(pred, &p0, &d, tool)?.0, SOLVE_TOL_MM),
        };
        if i == 0 && n > 0 {
            // Reversals inside: one arc when the jumps of the correction
            // there stay within the tolerance.
            let fits = job.fit((0.0, 1.0), (&c0, gap), &res.end, (&d, true));
            if let Some((center, sweep)) = fits {
                push_arc(res, res.end, (center, sweep));
                last_dirs = base;
                break;
            }
        }
        if job.load.is_some() {
            // Not one arc: each piece with its own load, from the start.
            let chords = job.part_loaded((s0, s1), &c0, &d, 0, takeups, &mut left, res)?;
            res.arc_replaced |= chords;
            end_residual = SOLVE_TOL_MM;
            at = res.segments.last().map(|c| (*c, d));
            last_dirs = d;
            continue;
        }
        res.arc_replaced |= job.part((s0, s1), (&c0, gap), &c1, &d, 0, res)?;
        at = Some((c1, d));
        last_dirs = d;
    }
    // The arc ends where its last part does.
    if let Some(end) = res.segments.pop() {
        res.end = end;
        res.residual_mm = end_residual;
    }
    let count = res.segments.len();
    res.center = res.arcs.last().filter(|p| p.to == count).map(|p| p.center);
    res.residual_mm = res.residual_mm.max(left.0);
    res.miss_mm = res.miss_mm.max(left.1);
    for p in res.segments.iter() {
        check_travel_within(pred, p, tol)?;
    }
    Ok(last_dirs)
}

/// Writes an arc piece ending at `end` (its segment and its centre and
/// sweep) into `res`.
fn push_arc(res: &mut BlockResult, end: AxisVec, (center, sweep): (Vector3<f64>, f64)) {
    res.segments.push(end);
    res.arcs.push(ArcPiece {
        to: res.segments.len() - 1,
        center,
        sweep,
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::program::interp::Plane;

    /// Parameters agree with a hand count of quadrant points.
    const PARAM_TOL: f64 = 1e-12;

    fn arc_from(angle0_deg: f64, sweep_deg: f64) -> (ArcGeom, Vector3<f64>) {
        let a0 = angle0_deg.to_radians();
        let arc = ArcGeom {
            plane: Plane::XY,
            center: Vector3::new(10.0, 20.0, 0.0),
            sweep: sweep_deg.to_radians(),
            radius: 5.0,
        };
        let start = Vector3::new(10.0 + 5.0 * a0.cos(), 20.0 + 5.0 * a0.sin(), 0.0);
        (arc, start)
    }

    #[test]
    fn reversals_are_the_quadrant_points_inside_the_arc() {
        let mut ts = [0.0; MAX_REVERSALS];
        // A full turn from 0°: X reverses at 90° and 270°, Y at 180°.
        let (arc, s3) = arc_from(0.0, 360.0);
        assert_eq!(reversals(&arc, &s3, &mut ts), 3);
        for (t, want) in ts.iter().zip([0.25, 0.5, 0.75]) {
            assert!((t - want).abs() < PARAM_TOL, "{ts:?}");
        }
        // A quarter between quadrant points: none inside.
        let (arc, s3) = arc_from(0.0, 90.0);
        assert_eq!(reversals(&arc, &s3, &mut ts), 0);
        // Clockwise from 45° through 0° to −90°: one inside, at a third.
        let (arc, s3) = arc_from(45.0, -135.0);
        assert_eq!(reversals(&arc, &s3, &mut ts), 1);
        assert!((ts[0] - 1.0 / 3.0).abs() < PARAM_TOL, "{ts:?}");
    }
}
