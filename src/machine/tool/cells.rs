//! The geometric chain of a machine whose axes are all linear (X, Y, Z) as
//! a multi-affine polynomial per cell, for the per-point hot path.
//!
//! Between two knots of its merged component tables, every error of a
//! linear axis is affine in the axis position, and so is the axis factor
//! `LOC · Trans(q·ê) · COM(q)` of the chain (the small-angle HTM has the
//! errors as entries, the translation adds `q`). The chain multiplies one
//! factor per axis with constant factors between them (gauge line, tool
//! length, spindle), so inside a *cell* — one table region per axis, one
//! direction of motion per axis, one tool length — the chain is exactly
//!
//! ```text
//! W_T_tip(q) = Σ_S  C_S · Π_{i ∈ S} (q_i − o_i)       S ⊆ {X, Y, Z}
//! ```
//!
//! with eight constant coefficient HTMs `C_S` expanded about a fixed point
//! `o` of the cell. The coefficients come from expanding the product
//! `Π (A_i + u_i B_i)` factor by factor (`A_i` the factor at `o_i`, `B_i`
//! its derivative), which is exact; an evaluation is then 4 products and
//! 42 multiply-adds instead of the chain's table searches and HTM
//! products (about 1 100 instructions). The two agree to rounding, below
//! 1e-11 mm (tested against the chain on the bundled three-axis machine and
//! variants of it: axes on either side, spindle errors, tables on
//! different knots; at knots and beyond the tables). Commands beyond
//! ±1e9 mm, where the monomials could overflow, use the chain itself.
//!
//! The coefficients of a cell are a pure function of the machine and the
//! cell (the expansion point is the cell's lower knot), so a result never
//! depends on which cells were computed before: the output is the same for
//! any number of threads. They are kept in a small per-thread cache (the
//! per-thread workspace of this path), keyed by the chain's identity.

use std::cell::RefCell;
use std::sync::atomic::{AtomicU64, Ordering};

use super::fast::{self, Aff, AxisFast};
use super::{Axis, AxisKind, MachineTool};

/// Identities of chains with cells, one per loaded machine.
static NEXT_ID: AtomicU64 = AtomicU64::new(1);

/// A fresh identity when the chain of `axes` has multi-affine cells: every
/// axis linear, in its own slot among X, Y, Z, with merged tables.
pub(crate) fn chain_id(axes: &[Axis], fast: &[AxisFast]) -> Option<u64> {
    let mut seen = [false; 3];
    for (a, f) in axes.iter().zip(fast) {
        let slot_free = seen
            .get_mut(a.slot)
            .is_some_and(|s| !std::mem::replace(s, true));
        if a.kind != AxisKind::Linear || !slot_free || f.merged.is_none() {
            return None;
        }
    }
    Some(NEXT_ID.fetch_add(1, Ordering::Relaxed))
}

/// The key of a cell: the chain, the tool length, and per slot the table
/// region and the direction of motion (reverse when the bit is set).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Key {
    chain: u64,
    tool_bits: u64,
    reverse: u8,
    region: [u32; 3],
}

/// One cell: where it holds and its coefficients (columns 2 and 3 of the
/// top three rows of `C_S`, by subset mask `S` over the slots).
#[derive(Debug, Clone, Copy)]
struct Cell {
    key: Key,
    lo: [f64; 3],
    hi: [f64; 3],
    origin: [f64; 3],
    /// `dir[S][row]`, `pos[S][row]`.
    dir: [[f64; 3]; 8],
    pos: [[f64; 3]; 8],
}

impl Cell {
    #[inline(always)]
    fn contains(&self, q: &[f64; 3]) -> bool {
        (0..3).all(|s| q[s] >= self.lo[s] && q[s] < self.hi[s])
    }

    /// The monomials `Π_{i ∈ S} (q_i − o_i)` at `q`, by subset mask `S`.
    #[inline(always)]
    fn weights(&self, q: &[f64; 3]) -> [f64; 8] {
        let ux = q[0] - self.origin[0];
        let uy = q[1] - self.origin[1];
        let uz = q[2] - self.origin[2];
        let uxy = ux * uy;
        [1.0, ux, uy, uxy, uz, ux * uz, uy * uz, uxy * uz]
    }

    /// One column of the chain from its coefficients `t` (`dir`: column 2,
    /// the tool axis, not normalised; `pos`: column 3, the tip) and the
    /// monomials `w` of the point.
    #[inline(always)]
    fn col(t: &[[f64; 3]; 8], w: &[f64; 8]) -> [f64; 3] {
        let mut p = [0.0; 3];
        for (r, v) in p.iter_mut().enumerate() {
            *v = t[0][r]
                + t[1][r] * w[1]
                + t[2][r] * w[2]
                + t[3][r] * w[3]
                + t[4][r] * w[4]
                + t[5][r] * w[5]
                + t[6][r] * w[6]
                + t[7][r] * w[7];
        }
        p
    }
}

/// Number of cell slots of a thread's cache (direct mapped; a cell is
/// boxed, so an empty slot costs a pointer). A raster over a whole
/// three-axis machine with reversals touches about a hundred cells.
const SLOTS: usize = 1024;

/// Largest command (and tool length) magnitude evaluated from cells, mm:
/// the product of three monomials stays far below overflow.
const CELL_RANGE_MM: f64 = 1e9;

/// The per-thread cache of cells.
struct Cache {
    cells: Vec<Option<Box<Cell>>>,
    /// Slot of the cell used last, tried before the region lookup: the
    /// points of a solve and of neighbouring moves mostly share a cell
    /// (remembering two or four cells cost more to scan than the lookups
    /// they saved).
    last: usize,
    /// Per slot, the table region found last: chain, bounds and index
    /// (regions do not depend on the direction of motion or the tool).
    regions: [(u64, f64, f64, u32); 3],
}

impl Cache {
    const fn new() -> Self {
        Cache {
            cells: Vec::new(),
            last: 0,
            regions: [(0, 0.0, 0.0, 0); 3],
        }
    }
}

thread_local! {
    static CACHE: RefCell<Cache> = const { RefCell::new(Cache::new()) };
}

/// `acc · Trans(0, 0, l)` for every term.
fn translate_terms(terms: &mut [Option<Aff>; 8], l: f64) {
    for t in terms.iter_mut().flatten() {
        fast::translate_z(t, l);
    }
}

/// Builds the cell of `key` for machine `m` (whose chain has cells).
fn build(m: &MachineTool, key: Key, dirs: &[i8; 3]) -> Option<Cell> {
    let tool = f64::from_bits(key.tool_bits);
    let mut lo = [f64::NEG_INFINITY; 3];
    let mut hi = [f64::INFINITY; 3];
    let mut origin = [0.0; 3];
    let mut terms: [Option<Aff>; 8] = [None; 8];
    terms[0] = Some(fast::IDENTITY);
    for (i, (a, f)) in m.axes.iter().zip(&m.pre.axes).enumerate() {
        if i == m.n_workpiece {
            translate_terms(&mut terms, tool);
        }
        let s = a.slot;
        let merged = f.merged.as_ref()?;
        let k = *key.region.get(s)? as usize;
        let (l, h, o) = merged.region_bounds(k);
        lo[s] = l;
        hi[s] = h;
        origin[s] = o;
        let (v, dv) = merged.affine(k, *dirs.get(s)?, o)?;
        // The factor at the expansion point and its derivative.
        let mut at = fast::small_angle(&[v[0], v[1], v[2]], &[v[3], v[4], v[5]]);
        let mut der = fast::small_angle(&[dv[0], dv[1], dv[2]], &[dv[3], dv[4], dv[5]]);
        for (r, (ra, rd)) in at.iter_mut().zip(der.iter_mut()).enumerate() {
            // The derivative has no unit diagonal.
            rd[r] = 0.0;
            if r == s % 3 {
                ra[3] += o;
                rd[3] += 1.0;
            }
        }
        if let Some(or) = &f.orient {
            at = fast::mul(or, &at);
            der = fast::mul0(or, &der);
        }
        let bit = 1usize << s;
        let mut next: [Option<Aff>; 8] = [None; 8];
        for (mask, t) in terms.iter().enumerate() {
            let Some(t) = t else { continue };
            let with_a = fast::mul(t, &at);
            let with_b = fast::mul0(t, &der);
            for (dst, v) in [(mask, with_a), (mask | bit, with_b)] {
                let slot = next.get_mut(dst)?;
                *slot = Some(match slot {
                    Some(prev) => add(prev, &v),
                    None => v,
                });
            }
        }
        terms = next;
    }
    if m.n_workpiece == m.axes.len() {
        translate_terms(&mut terms, tool);
    }
    if let Some(sp) = &m.pre.spindle {
        for t in terms.iter_mut().flatten() {
            *t = fast::mul(t, sp);
        }
    }
    translate_terms(&mut terms, -tool);
    let mut dir = [[0.0; 3]; 8];
    let mut pos = [[0.0; 3]; 8];
    for (mask, t) in terms.iter().enumerate() {
        if let Some(t) = t {
            for r in 0..3 {
                dir[mask][r] = t[r][2];
                pos[mask][r] = t[r][3];
            }
        }
    }
    Some(Cell {
        key,
        lo,
        hi,
        origin,
        dir,
        pos,
    })
}

fn add(a: &Aff, b: &Aff) -> Aff {
    let mut o = *a;
    for (ro, rb) in o.iter_mut().zip(b) {
        for (x, y) in ro.iter_mut().zip(rb) {
            *x += y;
        }
    }
    o
}

/// Columns 2 and 3 of the geometric chain of `m` at `cmd` from its cell
/// (`None` when the chain has no cells or the command is not finite: use
/// the chain itself).
#[inline]
pub(crate) fn geometric(
    m: &MachineTool,
    cmd: &[f64; 6],
    dirs: &[i8; 6],
    tool_mm: f64,
) -> Option<([f64; 3], [f64; 3])> {
    with_cell(m, cmd, dirs, tool_mm, |c, q| {
        let w = c.weights(q);
        (Cell::col(&c.dir, &w), Cell::col(&c.pos, &w))
    })
}

/// Bounds of the derivatives of the geometric chain along a straight
/// segment of commands that lies in one cell (no knot strictly inside),
/// with respect to the arc length `s` (mm) of the segment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct SegmentBounds {
    /// Bound of `|d² tip / ds²|`, 1/mm.
    pub(crate) pos2: f64,
    /// Bound of `|dv / ds|` of the (not normalised) tool-axis column `v`,
    /// 1/mm.
    pub(crate) dir1: f64,
    /// Bound of `|d² v / ds²|`, 1/mm².
    pub(crate) dir2: f64,
    /// Lower bound of `|v|` on the segment.
    pub(crate) dir_norm_lo: f64,
}

/// Subset masks of two slots, with the two slots.
const PAIRS: [(usize, usize, usize); 3] = [(3, 0, 1), (5, 0, 2), (6, 1, 2)];

impl Cell {
    /// Whether `q` lies in the closed cell, with a rounding allowance.
    fn holds(&self, q: &[f64; 3]) -> bool {
        (0..3).all(|s| {
            let slack = 1e-9 * (1.0 + q[s].abs());
            q[s] >= self.lo[s] - slack && q[s] <= self.hi[s] + slack
        })
    }

    /// Bounds of the first and second derivative of the column `t` along
    /// the unit direction `d` between the monomial offsets `ua` and `ub`
    /// (`u = q − origin` at the ends).
    ///
    /// Inside a cell a column is `Σ_S t_S Π_{i∈S} u_i` with `u` affine in
    /// `s`, so the second derivative is `Σ_{|S|=2} 2 t_S d_i d_j + 2 t_xyz
    /// (d_x d_y u_z + d_x d_z u_y + d_y d_z u_x)`: affine in `s`, its norm
    /// is largest at an end. The first derivative is bounded term by term
    /// with `|u_i| ≤ max(|ua_i|, |ub_i|)`.
    fn derivative_bounds(
        t: &[[f64; 3]; 8],
        d: &[f64; 3],
        ua: &[f64; 3],
        ub: &[f64; 3],
    ) -> (f64, f64) {
        let norm = |v: &[f64; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        let mut v0 = [0.0; 3];
        for &(mask, i, j) in &PAIRS {
            for (r, v) in v0.iter_mut().enumerate() {
                *v += 2.0 * t[mask][r] * d[i] * d[j];
            }
        }
        let w = |u: &[f64; 3]| d[0] * d[1] * u[2] + d[0] * d[2] * u[1] + d[1] * d[2] * u[0];
        let at = |u: &[f64; 3]| {
            let wu = w(u);
            let mut v = v0;
            for (r, x) in v.iter_mut().enumerate() {
                *x += 2.0 * t[7][r] * wu;
            }
            norm(&v)
        };
        let second = at(ua).max(at(ub));
        let um = [0, 1, 2].map(|i| ua[i].abs().max(ub[i].abs()));
        let mut lin = [0.0; 3];
        for (i, mask) in [1usize, 2, 4].into_iter().enumerate() {
            for (r, v) in lin.iter_mut().enumerate() {
                *v += t[mask][r] * d[i];
            }
        }
        let mut first = norm(&lin);
        for &(mask, i, j) in &PAIRS {
            first += norm(&t[mask]) * (d[i].abs() * um[j] + d[j].abs() * um[i]);
        }
        first += norm(&t[7])
            * (d[0].abs() * um[1] * um[2]
                + um[0] * d[1].abs() * um[2]
                + um[0] * um[1] * d[2].abs());
        (first, second)
    }
}

/// Derivative bounds of the geometric chain of `m` along the straight
/// segment `a → b` of commands, which must lie in one cell (no knot of the
/// merged tables strictly between its ends); the tool-axis bounds only
/// with `axis` (zero otherwise): `None` when the chain has no cells, or the
/// ends are not in the cell of the segment's midpoint.
pub(crate) fn segment_bounds(
    m: &MachineTool,
    a: &[f64; 6],
    b: &[f64; 6],
    dirs: &[i8; 6],
    tool_mm: f64,
    axis: bool,
) -> Option<SegmentBounds> {
    let mut mid = *a;
    for (s, v) in mid.iter_mut().enumerate() {
        *v = 0.5 * (a[s] + b[s]);
    }
    let qa = [a[0], a[1], a[2]];
    let qb = [b[0], b[1], b[2]];
    let dq = [qb[0] - qa[0], qb[1] - qa[1], qb[2] - qa[2]];
    let len = (dq[0] * dq[0] + dq[1] * dq[1] + dq[2] * dq[2]).sqrt();
    if !len.is_finite() {
        return None;
    }
    let d = if len > 0.0 {
        [dq[0] / len, dq[1] / len, dq[2] / len]
    } else {
        [0.0; 3]
    };
    with_cell(m, &mid, dirs, tool_mm, |c, _| {
        if !(c.holds(&qa) && c.holds(&qb)) {
            return None;
        }
        let ua = [0, 1, 2].map(|i| qa[i] - c.origin[i]);
        let ub = [0, 1, 2].map(|i| qb[i] - c.origin[i]);
        let (_, pos2) = Cell::derivative_bounds(&c.pos, &d, &ua, &ub);
        if !axis {
            return Some(SegmentBounds {
                pos2,
                dir1: 0.0,
                dir2: 0.0,
                dir_norm_lo: 0.0,
            });
        }
        let (dir1, dir2) = Cell::derivative_bounds(&c.dir, &d, &ua, &ub);
        let norm = |v: [f64; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        let na = norm(Cell::col(&c.dir, &c.weights(&qa)));
        let nb = norm(Cell::col(&c.dir, &c.weights(&qb)));
        Some(SegmentBounds {
            pos2,
            dir1,
            dir2,
            dir_norm_lo: na.min(nb) - dir1 * len / 2.0,
        })
    })
    .flatten()
}

/// `f` applied to the cell of `cmd` (from the thread's cache, built when
/// missing) and the command's X Y Z.
#[inline]
fn with_cell<T>(
    m: &MachineTool,
    cmd: &[f64; 6],
    dirs: &[i8; 6],
    tool_mm: f64,
    f: impl Fn(&Cell, &[f64; 3]) -> T,
) -> Option<T> {
    let chain = m.pre.cells_id?;
    let q = [cmd[0], cmd[1], cmd[2]];
    // Far beyond any travel the monomials could overflow (and a zero
    // coefficient times an infinite monomial is NaN): the chain instead.
    if !(q.iter().all(|v| v.abs() <= CELL_RANGE_MM) && tool_mm.abs() <= CELL_RANGE_MM) {
        return None;
    }
    let d3 = [dirs[0], dirs[1], dirs[2]];
    // Only the slots of the machine's axes select tables.
    let reverse = (u8::from(d3[0] <= 0) | u8::from(d3[1] <= 0) << 1 | u8::from(d3[2] <= 0) << 2)
        & m.pre.cells_slots;
    let tool_bits = tool_mm.to_bits();
    CACHE.with_borrow_mut(|cache| {
        // The cell used last first (the points of a move and of its
        // neighbours mostly share it).
        if let Some(c) = cache.cells.get(cache.last).and_then(Option::as_deref) {
            if c.key.chain == chain
                && c.key.tool_bits == tool_bits
                && c.key.reverse == reverse
                && c.contains(&q)
            {
                return Some(f(c, &q));
            }
        }
        let mut region = [0u32; 3];
        for (a, f) in m.axes.iter().zip(&m.pre.axes) {
            let v = *q.get(a.slot)?;
            let memo = cache.regions.get_mut(a.slot)?;
            let k = if memo.0 == chain && v >= memo.1 && v < memo.2 {
                memo.3
            } else {
                let merged = f.merged.as_ref()?;
                let k = merged.region(v);
                let (lo, hi, _) = merged.region_bounds(k);
                let k = u32::try_from(k).ok()?;
                *memo = (chain, lo, hi, k);
                k
            };
            *region.get_mut(a.slot)? = k;
        }
        let key = Key {
            chain,
            tool_bits,
            reverse,
            region,
        };
        if cache.cells.is_empty() {
            cache.cells.resize_with(SLOTS, || None);
        }
        let h = hash(&key) % SLOTS;
        let slot = cache.cells.get_mut(h)?;
        match slot {
            Some(c) if c.key == key => {}
            Some(c) => **c = build(m, key, &d3)?,
            None => *slot = Some(Box::new(build(m, key, &d3)?)),
        }
        cache.last = h;
        cache.cells.get(h)?.as_deref().map(|c| f(c, &q))
    })
}

fn hash(k: &Key) -> usize {
    const M: u64 = 0x9E37_79B9_7F4A_7C15;
    let mut h = k.chain.wrapping_mul(M);
    for v in [
        k.tool_bits,
        u64::from(k.reverse),
        u64::from(k.region[0]),
        u64::from(k.region[1]),
        u64::from(k.region[2]),
    ] {
        h = (h.rotate_left(5) ^ v).wrapping_mul(M);
    }
    (h >> 40) as usize
}
