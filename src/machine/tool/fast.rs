//! The per-point hot path of the geometric chain: everything that does not
//! depend on the command is computed once when the machine is loaded, and
//! one evaluation does only the position-dependent arithmetic.
//!
//! * The chain is accumulated as the top three rows of each 4×4 HTM (the
//!   last row of every factor is `[0, 0, 0, 1]`): 36 products per factor
//!   instead of 64, summed in the same order as nalgebra's 4×4 product, so
//!   the result is bit for bit the one of the full product.
//! * The component-error tables of one axis are merged over the union of
//!   their positions: one search per axis gives, for each of the six
//!   errors and each direction of motion, the segment's start, value and
//!   slope (computed once with the very expression of
//!   [`super::table::ErrorTable::lookup`]), so a lookup is one
//!   multiply-add with the same result as the table's own.
//! * Position-independent factors (the spindle HTM, the location-error
//!   orientation, a rotary axis' `Trans(P + d) · LOC` and `Trans(−(P + d))`)
//!   are stored.

use nalgebra::{Matrix4, Vector3};

use super::component::ComponentErrors;
use super::geometry;
use super::location::LocationErrors;
use super::{Axis, AxisKind, SpindleErrors};

/// The top three rows of an HTM whose last row is `[0, 0, 0, 1]`.
pub(crate) type Aff = [[f64; 4]; 3];

/// The identity HTM.
pub(crate) const IDENTITY: Aff = [
    [1.0, 0.0, 0.0, 0.0],
    [0.0, 1.0, 0.0, 0.0],
    [0.0, 0.0, 1.0, 0.0],
];

/// Top three rows of `a · b` for HTMs with last row `[0, 0, 0, 1]`, with
/// the same operations in the same order as nalgebra's 4×4 product (each
/// entry summed over k = 0..4 from the left), hence the same bits.
///
/// Written as one expression per row over the four columns (the last row
/// of `b` is `[0, 0, 0, 1]`, and `x · 1 = x` exactly), so that the compiler
/// can compute two or four columns per instruction; every entry keeps its
/// own operations in the same order (no fused multiply-add in Rust).
#[inline(always)]
pub(crate) fn mul(a: &Aff, b: &Aff) -> Aff {
    const LAST: [f64; 4] = [0.0, 0.0, 0.0, 1.0];
    let row = |ai: &[f64; 4]| {
        let mut o = [0.0; 4];
        for (j, v) in o.iter_mut().enumerate() {
            *v = ai[0] * b[0][j] + ai[1] * b[1][j] + ai[2] * b[2][j] + ai[3] * LAST[j];
        }
        o
    };
    [row(&a[0]), row(&a[1]), row(&a[2])]
}

/// The top three rows of a 4×4 HTM.
pub(crate) fn from_m4(m: &Matrix4<f64>) -> Aff {
    let mut r = [[0.0; 4]; 3];
    for (i, row) in r.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = m[(i, j)];
        }
    }
    r
}

/// `acc · Trans(0, 0, l)`: column 3 gains `l` times column 2.
#[inline(always)]
pub(crate) fn translate_z(acc: &mut Aff, l: f64) {
    for row in acc.iter_mut() {
        row[3] += row[2] * l;
    }
}

/// Top three rows of `a · b` where the last row of `b` is zero (the
/// derivative of an HTM): the same as [`mul`] without the translation of `a`.
#[inline(always)]
pub(crate) fn mul0(a: &Aff, b: &Aff) -> Aff {
    let row = |ai: &[f64; 4]| {
        let mut o = [0.0; 4];
        for (j, v) in o.iter_mut().enumerate() {
            *v = ai[0] * b[0][j] + ai[1] * b[1][j] + ai[2] * b[2][j];
        }
        o
    };
    [row(&a[0]), row(&a[1]), row(&a[2])]
}

/// The small-angle error HTM of [`geometry::small_angle`].
#[inline(always)]
pub(crate) fn small_angle(d: &[f64; 3], e: &[f64; 3]) -> Aff {
    [
        [1.0, -e[2], e[1], d[0]],
        [e[2], 1.0, -e[0], d[1]],
        [-e[1], e[0], 1.0, d[2]],
    ]
}

/// One error on one segment of the merged tables: `v0 + slope·(q − p0)`,
/// or `v0` where the table is clamped (or absent: zero).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Lin {
    p0: f64,
    v0: f64,
    slope: f64,
    constant: bool,
}

impl Lin {
    #[inline(always)]
    fn at(&self, q: f64) -> f64 {
        if self.constant {
            self.v0
        } else {
            self.v0 + self.slope * (q - self.p0)
        }
    }

    fn constant(v: f64) -> Self {
        Lin {
            p0: 0.0,
            v0: v,
            slope: 0.0,
            constant: true,
        }
    }
}

/// The six component-error tables of one axis over the union of their
/// positions.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct MergedTables {
    /// Sorted, distinct positions of all six tables.
    knots: Vec<f64>,
    /// Per region `k` (positions `knots[k−1] ≤ q < knots[k]`, `k` in
    /// `0..=knots.len()`) and direction (0 forward, 1 reverse): the six errors.
    segs: Vec<[Lin; 6]>,
}

impl MergedTables {
    /// Merges the tables; `None` when a merged lookup could differ from the
    /// tables' own in the sign of a zero (a table value of −0.0).
    fn new(c: &ComponentErrors) -> Option<Self> {
        let mut knots: Vec<f64> = Vec::new();
        for t in c.tables.iter().flatten() {
            let (p, fw, rv) = t.columns();
            if fw
                .iter()
                .chain(rv)
                .any(|v| *v == 0.0 && v.is_sign_negative())
            {
                return None;
            }
            if p.iter().any(|x| !x.is_finite()) {
                return None;
            }
            knots.extend_from_slice(p);
        }
        knots.sort_by(f64::total_cmp);
        knots.dedup();
        let mut segs = Vec::with_capacity(2 * (knots.len() + 1));
        for k in 0..=knots.len() {
            let lo = lower_knot(&knots, k);
            for dir in [1i8, -1] {
                let mut errs = [Lin::constant(0.0); 6];
                for (e, t) in errs.iter_mut().zip(&c.tables) {
                    let Some(t) = t else { continue };
                    let (p, fw, rv) = t.columns();
                    let col = if super::table::uses_forward(dir) {
                        fw
                    } else {
                        rv
                    };
                    *e = segment(p, col, lo);
                }
                segs.push(errs);
            }
        }
        Some(MergedTables { knots, segs })
    }

    /// Translations (mm) and rotations (rad) at `q` for the direction of
    /// motion `dir`, as [`ComponentErrors::eval`] gives them; `None` for NaN.
    #[inline(always)]
    fn eval(&self, q: f64, dir: i8) -> Option<([f64; 3], [f64; 3])> {
        if q.is_nan() {
            return None;
        }
        let s = self
            .segs
            .get(2 * self.region(q) + usize::from(!super::table::uses_forward(dir)))?;
        Some((
            [s[0].at(q), s[1].at(q), s[2].at(q)],
            [s[3].at(q), s[4].at(q), s[5].at(q)],
        ))
    }

    /// The region of `q` (see [`Self::segs`]): `knots[k−1] ≤ q < knots[k]`.
    #[inline(always)]
    pub(crate) fn region(&self, q: f64) -> usize {
        self.knots.partition_point(|&x| x <= q)
    }

    /// Bounds of region `k` (infinite at the open ends) and a fixed point
    /// of it: its lower knot, else its upper knot, else zero.
    pub(crate) fn region_bounds(&self, k: usize) -> (f64, f64, f64) {
        let lo = lower_knot(&self.knots, k);
        let hi = self.knots.get(k).copied();
        let origin = lo.or(hi).unwrap_or(0.0);
        (
            lo.unwrap_or(f64::NEG_INFINITY),
            hi.unwrap_or(f64::INFINITY),
            origin,
        )
    }

    /// Value at `q` and slope of the six errors (translations, then
    /// rotations) on region `k` for the direction of motion `dir`.
    pub(crate) fn affine(&self, k: usize, dir: i8, q: f64) -> Option<([f64; 6], [f64; 6])> {
        let s = self
            .segs
            .get(2 * k + usize::from(!super::table::uses_forward(dir)))?;
        let mut v = [0.0; 6];
        let mut d = [0.0; 6];
        for ((l, v), d) in s.iter().zip(&mut v).zip(&mut d) {
            *v = l.at(q);
            *d = if l.constant { 0.0 } else { l.slope };
        }
        Some((v, d))
    }
}

/// The lower knot of region `k` of `knots` (none for the first region).
fn lower_knot(knots: &[f64], k: usize) -> Option<f64> {
    k.checked_sub(1).and_then(|i| knots.get(i)).copied()
}

/// The table `p`, `col` on the region starting at `lo` (`None`: below every
/// knot), as [`super::table::ErrorTable::lookup_hinted`] evaluates it.
fn segment(p: &[f64], col: &[f64], lo: Option<f64>) -> Lin {
    let n = p.len().min(col.len());
    let (Some(&first), Some(&last)) = (p.first(), p.get(n.wrapping_sub(1))) else {
        return Lin::constant(0.0);
    };
    let end = |i: usize| Lin::constant(col.get(i).copied().unwrap_or(0.0));
    let Some(lo) = lo else { return end(0) };
    if lo >= last {
        return end(n - 1);
    }
    if lo < first {
        // The region ends at or before `first`.
        return end(0);
    }
    // first ≤ lo < last: the region lies inside the segment k - 1 .. k
    // (at q = first the lookup gives col[0], which this gives too).
    let k = p.get(..n).map_or(0, |s| s.partition_point(|&x| x <= lo));
    match (
        p.get(k.wrapping_sub(1)),
        p.get(k),
        col.get(k.wrapping_sub(1)),
        col.get(k),
    ) {
        (Some(&p0), Some(&p1), Some(&v0), Some(&v1)) => Lin {
            p0,
            v0,
            slope: (v1 - v0) / (p1 - p0),
            constant: false,
        },
        _ => end(0),
    }
}

/// What one axis needs per evaluation, computed once.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct AxisFast {
    /// Merged component tables (`None`: use [`ComponentErrors::eval`]).
    pub(crate) merged: Option<MergedTables>,
    /// Location orientation HTM, if not the identity.
    pub(crate) orient: Option<Aff>,
    /// Rotary axis with errors: `Trans(P + d) · LOC`, `Trans(−(P + d))`
    /// and the zero-angle error.
    rot_err: (Aff, Aff, f64),
    /// Rotary axis without errors: the same.
    rot_nom: (Aff, Aff, f64),
    /// The positions where no table of the axis is clamped: from the
    /// largest first position to the smallest last one (`None`: no table).
    unclamped: Option<(f64, f64)>,
}

impl AxisFast {
    /// Precomputes the position-independent parts of axis `a`.
    pub(crate) fn new(a: &Axis) -> Self {
        let rotary = |loc: &LocationErrors| {
            let c = a.pivot_mm + loc.offset_mm;
            let to = geometry::translation(&c) * loc.orientation_htm();
            let back = geometry::translation(&-c);
            (from_m4(&to), from_m4(&back), loc.zero_rad)
        };
        AxisFast {
            merged: MergedTables::new(&a.components),
            orient: (a.location.angles_rad != Vector3::zeros())
                .then(|| from_m4(&a.location.orientation_htm())),
            rot_err: rotary(&a.location),
            rot_nom: rotary(&LocationErrors::default()),
            unclamped: a
                .components
                .tables
                .iter()
                .flatten()
                .map(super::table::ErrorTable::range)
                .reduce(|(l0, h0), (l1, h1)| (l0.max(l1), h0.min(h1))),
        }
    }

    /// True when a table of the axis is clamped at `q` (or `q` is NaN), as
    /// [`ComponentErrors::is_clamped`] says.
    #[inline]
    pub(crate) fn is_clamped(&self, q: f64) -> bool {
        self.unclamped
            .is_some_and(|(lo, hi)| q.is_nan() || q < lo || q > hi)
    }

    /// Component errors at `q` (translations, rotations).
    #[inline(always)]
    fn components(&self, a: &Axis, q: f64, dir: i8) -> ([f64; 3], [f64; 3]) {
        if let Some(v) = self.merged.as_ref().and_then(|m| m.eval(q, dir)) {
            return v;
        }
        let c = a.components.eval(q, dir);
        ([c.d.x, c.d.y, c.d.z], [c.e.x, c.e.y, c.e.z])
    }
}

/// Everything position-independent of a machine's chain.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Precomputed {
    /// Per axis, in chain order.
    pub(crate) axes: Vec<AxisFast>,
    /// The spindle location HTM (`None` when it is the identity).
    pub(crate) spindle: Option<Aff>,
    /// Lipschitz bounds (machines without rotary axes).
    pub(crate) lip: Option<LipGeo>,
    /// The spindle location errors.
    pub(crate) spindle_errors: SpindleErrors,
    /// Identity of this chain for the cell caches of [`super::cells`]
    /// (`None` when the chain has no multi-affine cells: a rotary axis, an
    /// axis beyond X Y Z or tables that could not be merged).
    pub(crate) cells_id: Option<u64>,
    /// Bit `s` set when slot `s` has an axis.
    pub(crate) cells_slots: u8,
    /// Chain index of the axis in slot Z (`usize::MAX` when there is none).
    pub(crate) z_index: usize,
}

impl Precomputed {
    /// Precomputes the chain of `axes` (chain order) and `spindle`.
    pub(crate) fn new(axes: &[Axis], spindle: SpindleErrors) -> Self {
        let fast: Vec<AxisFast> = axes.iter().map(AxisFast::new).collect();
        Precomputed {
            cells_id: super::cells::chain_id(axes, &fast),
            cells_slots: axes.iter().fold(0u8, |m, a| m | (1u8 << (a.slot % 8))),
            z_index: axes.iter().position(|a| a.slot == 2).unwrap_or(usize::MAX),
            axes: fast,
            spindle: (!spindle.is_zero()).then(|| from_m4(&spindle.htm())),
            lip: LipGeo::new(axes, &spindle),
            spindle_errors: spindle,
        }
    }
}

/// `acc · E(q)` for axis `a` (see the chain in the module docs of
/// [`super`]), the same arithmetic as the 4×4 path.
#[inline(always)]
pub(crate) fn apply_axis(acc: &mut Aff, a: &Axis, f: &AxisFast, q: f64, dir: i8, errors: bool) {
    let r = a.slot % 3;
    match (a.kind, errors) {
        (AxisKind::Linear, false) => {
            for row in acc.iter_mut() {
                row[3] += row[r] * q;
            }
        }
        (AxisKind::Linear, true) => {
            let (d, e) = f.components(a, q, dir);
            let mut m = small_angle(&d, &e);
            if let Some(row) = m.get_mut(r) {
                row[3] += q;
            }
            if let Some(o) = &f.orient {
                m = mul(o, &m);
            }
            *acc = mul(acc, &m);
        }
        (AxisKind::Rotary, _) => {
            let (to, back, zero) = if errors { &f.rot_err } else { &f.rot_nom };
            let theta = q.to_radians() + zero;
            let rot = from_m4(&geometry::rotation(r, theta));
            let com = if errors {
                let (d, e) = f.components(a, q, dir);
                small_angle(&d, &e)
            } else {
                small_angle(&[0.0; 3], &[0.0; 3])
            };
            let m = mul(&mul(&mul(to, &rot), &com), back);
            *acc = mul(acc, &m);
        }
    }
}

/// Bounds of how fast the geometric error of a machine without rotary axes
/// changes with the command, for skipping evaluations whose outcome is
/// certain (see [`super::MachineTool::lipschitz_geo`]).
///
/// With `p(c)` the attained tip and `c` the command, the error
/// `G(c) = p(c) − nominal(c)` has, between table knots, the column
/// `∂G/∂q_k = (R_k − I)·ê + R_k·(δ'_k + ε'_k × w_k)`: `R_k` the rotation
/// part of the factors up to axis `k` (small-angle factors, so
/// `‖R_k‖ ≤ e^E` and `‖R_k − I‖ ≤ e^E − 1` with `E` the sum of every
/// largest angular error), `δ'`, `ε'` the table slopes and `w_k` the tip
/// seen from axis `k` (`|w_k| ≤ e^2E · Σ |translations|`). `G` is
/// continuous, so these bound its Lipschitz constant over a box of commands.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct LipGeo {
    /// Box of commands (by slot 0..3) where the bounds hold.
    lo: [f64; 3],
    hi: [f64; 3],
    /// `L_geo(tool) = pos0 + pos1 · |tool|`.
    pos0: f64,
    pos1: f64,
    /// Bound of the change of the unit tool axis per mm of command.
    dir: f64,
    /// Second derivatives (see [`LipGeo::second`]): `K₂(tool) = k2_0 +
    /// k2_1 · |tool|`, and the tool-axis terms.
    k2_0: f64,
    k2_1: f64,
    axis2: f64,
    axis1_sq: f64,
}

/// Global bounds of the second derivatives of the geometric chain of a
/// machine without rotary axes along a straight segment of commands that
/// crosses no knot, per unit `X = (Σ|d_i|)² − 1` of a unit direction `d`
/// (zero when a single axis moves: the chain is affine in each axis).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct SecondGeo {
    /// Bound of the mixed partials `|∂²G/∂q_k∂q_j|` of the tip (1/mm): the
    /// tip's second derivative is at most `k2 · X`.
    pub(crate) k2: f64,
    /// The unit tool axis' second derivative is at most
    /// `axis2 · X + axis1_sq` (1/mm²).
    pub(crate) axis2: f64,
    /// See `axis2`.
    pub(crate) axis1_sq: f64,
}

impl LipGeo {
    /// The bounds of a machine whose axes are all linear (`None` otherwise).
    pub(crate) fn new(axes: &[Axis], spindle: &SpindleErrors) -> Option<Self> {
        if axes
            .iter()
            .any(|a| a.kind != AxisKind::Linear || a.slot >= 3)
        {
            return None;
        }
        let max_abs = |a: &Axis, range: std::ops::Range<usize>| -> f64 {
            a.components
                .tables
                .get(range)
                .unwrap_or(&[])
                .iter()
                .flatten()
                .map(super::table::ErrorTable::max_abs)
                .sum()
        };
        let max_slope = |a: &Axis, range: std::ops::Range<usize>| -> f64 {
            a.components
                .tables
                .get(range)
                .unwrap_or(&[])
                .iter()
                .flatten()
                .map(super::table::ErrorTable::max_abs_slope)
                .sum()
        };
        let abs_sum = |v: &Vector3<f64>| v.iter().map(|x| x.abs()).sum::<f64>();
        let mut lo = [f64::NEG_INFINITY; 3];
        let mut hi = [f64::INFINITY; 3];
        let mut angles = abs_sum(&spindle.angles_rad);
        let mut translations = abs_sum(&spindle.offset_mm);
        let mut slopes_d = 0.0;
        let mut slopes_e = 0.0;
        for a in axes {
            let (t0, t1) = a.travel;
            let margin = 0.1 * (t1 - t0).abs() + 10.0;
            let (b0, b1) = (t0 - margin, t1 + margin);
            if let (Some(l), Some(h)) = (lo.get_mut(a.slot), hi.get_mut(a.slot)) {
                *l = b0;
                *h = b1;
            }
            angles += max_abs(a, 3..6) + abs_sum(&a.location.angles_rad);
            translations += max_abs(a, 0..3) + b0.abs().max(b1.abs());
            slopes_d += max_slope(a, 0..3);
            slopes_e += max_slope(a, 3..6);
        }
        let n = axes.len() as f64;
        let grow = angles.exp();
        let grow2 = grow * grow;
        let pos0 = n * (grow - 1.0) + grow * slopes_d + grow * slopes_e * grow2 * translations;
        // Gauge line and tool: two translations of |tool|.
        let pos1 = grow * slopes_e * grow2 * 2.0;
        // The z column moves by at most e^2E · Σ ε' per mm; the unit axis by
        // at most twice that (its norm stays above 1/2).
        let dir = 2.0 * grow2 * slopes_e;
        // Second derivatives. Differentiating the column ∂G/∂q_k above by
        // another axis j: R_k changes by at most e^E·|ε'_j| and w_k by at
        // most e^2E·(1 + |δ'_j| + |ε'_j|·|w|), so
        // |∂²G/∂q_k∂q_j| ≤ Σε'·(e^E + e^3E)·(1 + Σδ' + Σε'·W) with
        // W = e^2E·(Σ translations + 2|tool|). The pure second derivatives
        // vanish (each factor is affine in its own axis between knots), so
        // along a unit d the tip bends by at most that times
        // Σ_{k≠j}|d_k d_j| = (Σ|d_i|)² − 1. The z column v = R·ẑ has
        // |∂²v/∂q_k∂q_j| ≤ e^E·(Σε')² and |v'| ≤ e^2E·Σε', |v| ≥ ½, and the
        // unit axis u = v/|v| has |u''| ≤ 2|v''|/|v| + 6|v'|²/|v|².
        let cross = slopes_e * (grow + grow * grow2);
        let k2_0 = cross * (1.0 + slopes_d + slopes_e * grow2 * translations);
        let k2_1 = cross * slopes_e * grow2 * 2.0;
        let axis2 = 4.0 * grow * slopes_e * slopes_e;
        let axis1_sq = 24.0 * (grow2 * slopes_e).powi(2);
        let all = [pos0, pos1, dir, angles, k2_0, k2_1, axis2, axis1_sq];
        (all.iter().all(|v| v.is_finite()) && angles < 0.1).then_some(LipGeo {
            lo,
            hi,
            pos0,
            pos1,
            dir,
            k2_0,
            k2_1,
            axis2,
            axis1_sq,
        })
    }

    /// The second-derivative bounds for tool length `tool_mm`.
    #[inline]
    pub(crate) fn second(&self, tool_mm: f64) -> SecondGeo {
        SecondGeo {
            k2: self.k2_0 + self.k2_1 * tool_mm.abs(),
            axis2: self.axis2,
            axis1_sq: self.axis1_sq,
        }
    }

    /// True when every linear slot of `c` lies in the box of the bounds.
    #[inline]
    pub(crate) fn contains(&self, c: &[f64; 6]) -> bool {
        (0..3).all(|s| c[s] >= self.lo[s] && c[s] <= self.hi[s])
    }

    /// Lipschitz bound of the geometric error for tool length `tool_mm`,
    /// and the bound of the tool-axis change (per mm).
    #[inline]
    pub(crate) fn bounds(&self, tool_mm: f64) -> (f64, f64) {
        (self.pos0 + self.pos1 * tool_mm.abs(), self.dir)
    }
}
