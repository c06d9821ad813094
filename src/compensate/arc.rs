//! Compensation of circular and helical moves: an arc is cut where an axis
//! of its plane reverses (the direction-dependent errors change there at
//! once), each part is written as an arc about its own shifted centre
//! (halved until it fits the tolerance), with a takeup point where the
//! reversal would otherwise leave the machine off the path; only a part
//! that no arc fits is written as chords, each split like a straight move.

use nalgebra::Vector3;

use super::{
    BlockResult, Carry, Failure, Lip, SKIP_MARGIN_MM, SOLVE_TOL_MM, check_travel_within, dirs_of,
    lerp, solve, solve_near, split_line, start_from, with_xyz,
};
use crate::machine::{AxisVec, DirVec};
use crate::predict::ToolPredictor;
use crate::program::interp::{ArcGeom, DIRECTION_DEADBAND, Move};

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
/// Sweep within which of a whole turn an arc counts as a full turn, rad.
const FULL_TURN_EPS_RAD: f64 = 1e-9;
/// Most reversals inside one arc (a full turn has four).
const MAX_REVERSALS: usize = 6;

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
}

impl ArcJob<'_, '_> {
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
            // a centre moved by more than the tolerance is no fit.
            if (k * k * l2).sqrt() > self.tol {
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
        let k = ((want.abs() / ARC_SAMPLE_RAD).ceil())
            .max((r * want.abs() / ARC_SAMPLE_MM).ceil())
            .clamp(4.0, MAX_ARC_SAMPLES as f64) as usize;
        let tool = self.lip.tool_mm;
        for j in 1..k {
            let f = j as f64 / k as f64;
            let ang = start + sweep * f;
            let mut cmd = lerp(ca, cb, f);
            cmd[a] = cc[a] + (r + dr * f) * ang.cos();
            cmd[b] = cc[b] + (r + dr * f) * ang.sin();
            let s = s0 + (s1 - s0) * f;
            let dirs = if local {
                dirs_of(&self.arc.tangent(&self.s3, &self.e3, s), d)
            } else {
                *d
            };
            let got = self.pred.attained(&cmd, &dirs, tool).pos;
            // (NaN fails too)
            let fits = self.gap(&got, s) <= budget;
            if !fits {
                return None;
            }
        }
        Some((cc, sweep))
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
            res.segments.push(*cb);
            res.arcs.push(ArcPiece {
                to: res.segments.len() - 1,
                center,
                sweep,
            });
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
    /// from its solved start and the gap left is raised in `left`.
    fn start(
        &self,
        (i, p0, c, d): (usize, AxisVec, AxisVec, DirVec),
        takeups: bool,
        left: &mut f64,
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
            *left = left.max(st.left_mm);
            return Ok((solve_near(pred, &p0, &c, &p0, &d, lip)?.0, SOLVE_TOL_MM));
        }
        Ok((st.c, st.gap))
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
                self.tol - sag,
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
    };
    let mut ts = [0.0; MAX_REVERSALS];
    let n = reversals(arc, &job.s3, &mut ts);
    // Where the machine stands: the previous block's end, when it ended at
    // the arc's start.
    let mut at: Option<(AxisVec, DirVec)> = carry_in
        .filter(|k| k.stands_at(&mv.start))
        .map(|k| (k.c, k.dirs));
    let mut left = 0.0f64;
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
                res.segments.push(res.end);
                res.arcs.push(ArcPiece {
                    to: res.segments.len() - 1,
                    center,
                    sweep,
                });
                last_dirs = base;
                break;
            }
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
    res.residual_mm = res.residual_mm.max(left);
    res.miss_mm = res.miss_mm.max(left);
    for p in res.segments.iter() {
        check_travel_within(pred, p, tol)?;
    }
    Ok(last_dirs)
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
