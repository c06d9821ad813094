//! Static stiffness of a machine tool at the tool tip (docs/physics.md): a
//! diagonal translational stiffness per axis direction and per load sign,
//! each a function of the position in the workspace given on a grid and
//! interpolated trilinearly (clamped at the grid ends). The deflection of
//! the tool tip under a force `F` on the tool from the workpiece is
//! `F_i / k_i(p, sign F_i)` per axis: the tool gives way in the direction of
//! the force, so attained = programmed + F/k.

use nalgebra::Vector3;

use super::raw::{RawGridValues, RawStiffness};
use crate::error::Invalid;

/// Lowest accepted stiffness, N/µm.
const MIN_K: f64 = 0.01;
/// Highest accepted stiffness, N/µm.
const MAX_K: f64 = 1e5;

/// Validated stiffness map.
#[derive(Debug, Clone, PartialEq)]
pub struct Stiffness {
    /// Grid positions per axis (machine coordinates, mm), strictly
    /// increasing; a single position for a uniform value.
    grid: [Vec<f64>; 3],
    /// Values, N/µm, indexed `[direction * 2 + (0 positive | 1 negative)]`,
    /// each flattened `ix + nx·(iy + ny·iz)`.
    k: [Vec<f64>; 6],
}

/// Lower index and weight of `q` in the sorted `pts` (clamped).
fn locate(pts: &[f64], q: f64) -> (usize, f64) {
    let n = pts.len();
    if n < 2 {
        return (0, 0.0);
    }
    let first = pts.first().copied().unwrap_or(0.0);
    let last = pts.last().copied().unwrap_or(0.0);
    if q <= first {
        return (0, 0.0);
    }
    if q >= last {
        return (n - 2, 1.0);
    }
    let i = pts
        .partition_point(|&p| p <= q)
        .saturating_sub(1)
        .min(n - 2);
    let (a, b) = (
        pts.get(i).copied().unwrap_or(0.0),
        pts.get(i + 1).copied().unwrap_or(1.0),
    );
    (i, if b > a { (q - a) / (b - a) } else { 0.0 })
}

impl Stiffness {
    /// A uniform stiffness map: `k[dir][0 = positive load, 1 = negative]`, N/µm.
    pub fn uniform(k: [[f64; 2]; 3]) -> Self {
        let mut vals: [Vec<f64>; 6] = Default::default();
        for (d, pair) in k.iter().enumerate() {
            for (s, &v) in pair.iter().enumerate() {
                if let Some(slot) = vals.get_mut(d * 2 + s) {
                    *slot = vec![v];
                }
            }
        }
        Stiffness {
            grid: [vec![0.0], vec![0.0], vec![0.0]],
            k: vals,
        }
    }

    /// Grid positions along x, y and z (machine coordinates, mm): the map is
    /// trilinear between them.
    pub fn grid_mm(&self) -> [&[f64]; 3] {
        [&self.grid[0], &self.grid[1], &self.grid[2]]
    }

    /// Stiffness in direction `dir` (0..3) at position `p` (mm) for a load
    /// of the given sign, N/µm.
    pub fn k_n_per_um(&self, p: &Vector3<f64>, dir: usize, positive: bool) -> f64 {
        let Some(vals) = self.k.get(dir * 2 + usize::from(!positive)) else {
            return f64::INFINITY;
        };
        let [gx, gy, gz] = &self.grid;
        let (nx, ny) = (gx.len(), gy.len());
        let (ix, tx) = locate(gx, p[0]);
        let (iy, ty) = locate(gy, p[1]);
        let (iz, tz) = locate(gz, p[2]);
        let at = |i: usize, j: usize, k: usize| -> f64 {
            let i = i.min(nx.saturating_sub(1));
            let j = j.min(ny.saturating_sub(1));
            let k = k.min(gz.len().saturating_sub(1));
            vals.get(i + nx * (j + ny * k))
                .copied()
                .unwrap_or(f64::INFINITY)
        };
        let lerp = |a: f64, b: f64, t: f64| a + (b - a) * t;
        let c00 = lerp(at(ix, iy, iz), at(ix + 1, iy, iz), tx);
        let c10 = lerp(at(ix, iy + 1, iz), at(ix + 1, iy + 1, iz), tx);
        let c01 = lerp(at(ix, iy, iz + 1), at(ix + 1, iy, iz + 1), tx);
        let c11 = lerp(at(ix, iy + 1, iz + 1), at(ix + 1, iy + 1, iz + 1), tx);
        lerp(lerp(c00, c10, ty), lerp(c01, c11, ty), tz)
    }

    /// Deflection of the tool tip (mm) at position `p` (mm) under the force
    /// `f` (N) on the tool from the workpiece: `F_i / k_i` per axis.
    pub fn deflection_mm(&self, p: &Vector3<f64>, f: &Vector3<f64>) -> Vector3<f64> {
        let mut d = Vector3::zeros();
        for i in 0..3 {
            if f[i] != 0.0 {
                d[i] = f[i] / self.k_n_per_um(p, i, f[i] > 0.0) * 1e-3;
            }
        }
        d
    }

    /// Upper bound of the Lipschitz constant (Euclidean norms) of
    /// [`Self::deflection_mm`] in the position under the force `f`: the
    /// deflection `F_i / k_i · 1e-3` changes by at most
    /// `|F_i| · 1e-3 / k_min² · |∇k_i|`, and the gradient of a trilinear
    /// interpolation is bounded by the grid's largest difference quotients.
    pub fn lipschitz_mm(&self, f: &Vector3<f64>) -> f64 {
        let mut l = 0.0;
        for i in 0..3 {
            if f[i] == 0.0 {
                continue;
            }
            let mut worst = 0.0f64;
            for s in 0..2 {
                let Some(vals) = self.k.get(i * 2 + s) else {
                    continue;
                };
                let kmin = vals.iter().fold(f64::INFINITY, |m, &v| m.min(v));
                let (nx, ny) = (self.grid[0].len(), self.grid[1].len());
                let mut grad = 0.0;
                for (d, pts) in self.grid.iter().enumerate() {
                    let stride = match d {
                        0 => 1,
                        1 => nx,
                        _ => nx * ny,
                    };
                    let mut m = 0.0f64;
                    for (idx, &v) in vals.iter().enumerate() {
                        let along = (idx / stride) % pts.len().max(1);
                        let (Some(&a), Some(&b), Some(&w)) =
                            (pts.get(along), pts.get(along + 1), vals.get(idx + stride))
                        else {
                            continue;
                        };
                        m = m.max(((w - v) / (b - a)).abs());
                    }
                    grad += m;
                }
                worst = worst.max(grad / (kmin * kmin));
            }
            l += f[i].abs() * 1e-3 * worst;
        }
        l
    }

    /// Upper bound of the second derivative (Euclidean norm, mm per mm²)
    /// of [`Self::deflection_mm`] along any straight line of positions
    /// under the force `f`, away from the grid positions (where the
    /// trilinear map has kinks).
    ///
    /// Along a unit direction `d` the deflection `F_i / k_i · 1e-3` has the
    /// second derivative `F_i · 1e-3 · (2 (∇k_i·d)² / k_i³ − dᵀ H_i d / k_i²)`.
    /// A trilinear map has `|∇k·d|² ≤ Σ_j G_j²` with `G_j` its largest
    /// difference quotient along `j`, and a Hessian with a zero diagonal
    /// whose entries are convex combinations of the mixed quotients of the
    /// grid faces, so `|dᵀ H d| ≤ 2 H_max` (`Σ_{j<l} |d_j d_l| ≤ 1`).
    pub fn curvature_mm(&self, f: &Vector3<f64>) -> f64 {
        let mut sq = 0.0;
        for i in 0..3 {
            if f[i] == 0.0 {
                continue;
            }
            let table = i * 2 + usize::from(f[i] < 0.0);
            let c = f[i].abs() * 1e-3 * self.second_bound(table);
            sq += c * c;
        }
        sq.sqrt()
    }

    /// [`Self::curvature_mm`] on the straight segment `a → b`, which must
    /// lie in one cell of the grid (the stretch of a move between two
    /// breakpoints does). Local to the segment: inside a cell the map is
    /// trilinear, so over the segment's bounding box the value is at least
    /// its smallest corner value, each partial `∂_j k` (bilinear in the two
    /// other coordinates) at most its largest value at the box's corners,
    /// and each mixed partial (linear in the third coordinate) at most its
    /// largest at the box's faces; the direction `d` of the segment weighs
    /// them: `|∇k·d| ≤ Σ_j G_j |d_j|`, `|dᵀHd| ≤ 2 Σ_{j<l} H_jl |d_j d_l|`.
    /// Along an axis where the segment is beyond the grid the map is
    /// constant (clamped). The bound tends to the exact second derivative
    /// as the segment shrinks, so a move split where the deflection bends
    /// is not split much further.
    pub fn curvature_on_mm(&self, a: &Vector3<f64>, b: &Vector3<f64>, f: &Vector3<f64>) -> f64 {
        let diff = b - a;
        let len = diff.norm();
        let d = if len > 0.0 {
            diff / len
        } else {
            Vector3::zeros()
        };
        let mid = (a + b) * 0.5;
        // Per axis: the cell's lower corner index and width, whether the
        // map varies along the axis there, and the segment's range in the
        // cell's unit coordinate.
        let mut lo = [0usize; 3];
        let mut width = [1.0; 3];
        let mut varies = [false; 3];
        let mut range = [(0.0, 0.0); 3];
        for j in 0..3 {
            let pts = &self.grid[j];
            let (Some(&first), Some(&last)) = (pts.first(), pts.last()) else {
                continue;
            };
            if pts.len() < 2 {
                continue;
            }
            let i = pts
                .partition_point(|&x| x <= mid[j])
                .saturating_sub(1)
                .min(pts.len() - 2);
            let x0 = pts.get(i).copied().unwrap_or(0.0);
            lo[j] = i;
            width[j] = pts.get(i + 1).copied().unwrap_or(1.0) - x0;
            varies[j] = mid[j] > first && mid[j] < last;
            let unit = |x: f64| ((x - x0) / width[j]).clamp(0.0, 1.0);
            let (ua, ub) = (unit(a[j]), unit(b[j]));
            range[j] = (ua.min(ub), ua.max(ub));
        }
        let n = [self.grid[0].len(), self.grid[1].len(), self.grid[2].len()];
        let pick = |j: usize, hi: bool| if hi { range[j].1 } else { range[j].0 };
        let mut sq = 0.0;
        for i in 0..3 {
            if f[i] == 0.0 {
                continue;
            }
            let Some(vals) = self.k.get(i * 2 + usize::from(f[i] < 0.0)) else {
                continue;
            };
            // Corner `c` ∈ {0, 1}³ of the cell.
            let corner = |c: [usize; 3]| -> f64 {
                let ix = (lo[0] + c[0]).min(n[0].saturating_sub(1));
                let iy = (lo[1] + c[1]).min(n[1].saturating_sub(1));
                let iz = (lo[2] + c[2]).min(n[2].saturating_sub(1));
                vals.get(ix + n[0] * (iy + n[1] * iz))
                    .copied()
                    .unwrap_or(f64::INFINITY)
            };
            // A function of the corners, interpolated multilinearly at the
            // unit coordinates `t` over the axes in `axes`, the others at 0.
            let lerp = |t: [f64; 3], value: &dyn Fn([usize; 3]) -> f64, axes: [bool; 3]| -> f64 {
                let mut sum = 0.0;
                for c in 0..8 {
                    let bits = [c & 1, (c >> 1) & 1, (c >> 2) & 1];
                    let mut w = 1.0;
                    for j in 0..3 {
                        if axes[j] {
                            w *= if bits[j] == 1 { t[j] } else { 1.0 - t[j] };
                        } else if bits[j] == 1 {
                            w = 0.0;
                        }
                    }
                    if w != 0.0 {
                        sum += w * value(bits);
                    }
                }
                sum
            };
            let box_corner = |c: usize| {
                [
                    pick(0, c & 1 == 1),
                    pick(1, c & 2 == 2),
                    pick(2, c & 4 == 4),
                ]
            };
            let kmin = (0..8)
                .map(|c| lerp(box_corner(c), &corner, [true; 3]))
                .fold(f64::INFINITY, f64::min);
            let mut slope = 0.0;
            let mut mixed = 0.0;
            for j in 0..3 {
                if !varies[j] {
                    continue;
                }
                // ∂_j k: the quotient of the two faces across j, bilinear
                // in the other coordinates.
                let quotient = |c: [usize; 3]| {
                    let (mut p, mut q) = (c, c);
                    p[j] = 1;
                    q[j] = 0;
                    (corner(p) - corner(q)) / width[j]
                };
                let mut other = [true; 3];
                other[j] = false;
                let g = (0..8)
                    .map(|c| lerp(box_corner(c), &quotient, other).abs())
                    .fold(0.0, f64::max);
                slope += g * d[j].abs();
                for l in (j + 1)..3 {
                    if !varies[l] {
                        continue;
                    }
                    let cross = |c: [usize; 3]| {
                        let at = |x: usize, y: usize| {
                            let mut e = c;
                            e[j] = x;
                            e[l] = y;
                            corner(e)
                        };
                        (at(1, 1) - at(1, 0) - at(0, 1) + at(0, 0)) / (width[j] * width[l])
                    };
                    let mut third = [false; 3];
                    third[3 - j - l] = true;
                    let h = (0..8)
                        .map(|c| lerp(box_corner(c), &cross, third).abs())
                        .fold(0.0, f64::max);
                    mixed += 2.0 * h * (d[j] * d[l]).abs();
                }
            }
            let bound = 2.0 * slope * slope / (kmin * kmin * kmin) + mixed / (kmin * kmin);
            let c = f[i].abs() * 1e-3 * bound;
            sq += c * c;
        }
        sq.sqrt()
    }

    /// `2 Σ_j G_j² / k_min³ + 2 H_max / k_min²` of one table of values (see
    /// [`Self::curvature_mm`]).
    fn second_bound(&self, table: usize) -> f64 {
        let Some(vals) = self.k.get(table) else {
            return 0.0;
        };
        let kmin = vals.iter().fold(f64::INFINITY, |m, &v| m.min(v));
        let n = [self.grid[0].len(), self.grid[1].len(), self.grid[2].len()];
        let stride = [1, n[0], n[0] * n[1]];
        let value = |i: [usize; 3]| {
            vals.get(i[0] + stride[1] * i[1] + stride[2] * i[2])
                .copied()
                .unwrap_or(0.0)
        };
        let step = |j: usize, i: usize| -> f64 {
            let pts = &self.grid[j];
            match (pts.get(i), pts.get(i + 1)) {
                (Some(a), Some(b)) => b - a,
                _ => f64::INFINITY,
            }
        };
        let mut grad_sq = 0.0;
        let mut mixed = 0.0f64;
        for j in 0..3 {
            let mut g = 0.0f64;
            for l in (j + 1)..3 {
                for iz in 0..n[2] {
                    for iy in 0..n[1] {
                        for ix in 0..n[0] {
                            let i = [ix, iy, iz];
                            if i[j] + 1 >= n[j] || i[l] + 1 >= n[l] {
                                continue;
                            }
                            let (mut a, mut b, mut c) = (i, i, i);
                            a[j] += 1;
                            b[l] += 1;
                            c[j] += 1;
                            c[l] += 1;
                            let q = (value(c) - value(a) - value(b) + value(i))
                                / (step(j, i[j]) * step(l, i[l]));
                            mixed = mixed.max(q.abs());
                        }
                    }
                }
            }
            for iz in 0..n[2] {
                for iy in 0..n[1] {
                    for ix in 0..n[0] {
                        let i = [ix, iy, iz];
                        if i[j] + 1 >= n[j] {
                            continue;
                        }
                        let mut a = i;
                        a[j] += 1;
                        g = g.max(((value(a) - value(i)) / step(j, i[j])).abs());
                    }
                }
            }
            grad_sq += g * g;
        }
        2.0 * grad_sq / (kmin * kmin * kmin) + 2.0 * mixed / (kmin * kmin)
    }

    /// Validates the `stiffness:` block.
    pub(crate) fn from_raw(raw: &RawStiffness) -> Result<Self, Invalid> {
        let grid_given = raw.grid_mm.is_some();
        let grid: [Vec<f64>; 3] = match &raw.grid_mm {
            Some(g) => [g.x.clone(), g.y.clone(), g.z.clone()],
            None => [vec![0.0], vec![0.0], vec![0.0]],
        };
        for (name, pts) in ["x", "y", "z"].iter().zip(&grid) {
            let path = format!("stiffness.grid_mm.{name}");
            if pts.is_empty() {
                return Err(Invalid::new(path, "the grid has no positions"));
            }
            if pts.iter().any(|v| !v.is_finite()) {
                return Err(Invalid::new(path, "positions must be finite numbers"));
            }
            for w in pts.windows(2) {
                if let [a, b] = w {
                    if a >= b {
                        return Err(Invalid::new(
                            path,
                            format!(
                                "positions must be strictly increasing (`{a}` is followed by `{b}`)"
                            ),
                        ));
                    }
                }
            }
        }
        let (nx, ny, nz) = (grid[0].len(), grid[1].len(), grid[2].len());
        let v = &raw.k_n_per_um;
        let entries = [
            ("x_pos", &v.x_pos),
            ("x_neg", &v.x_neg),
            ("y_pos", &v.y_pos),
            ("y_neg", &v.y_neg),
            ("z_pos", &v.z_pos),
            ("z_neg", &v.z_neg),
        ];
        let mut k: [Vec<f64>; 6] = Default::default();
        for (slot, (name, values)) in k.iter_mut().zip(entries) {
            let path = format!("stiffness.k_n_per_um.{name}");
            let check = |x: f64| -> Result<f64, Invalid> {
                if x.is_finite() && (MIN_K..=MAX_K).contains(&x) {
                    Ok(x)
                } else {
                    Err(Invalid::new(
                        &path,
                        format!(
                            "stiffness `{x}` N/µm is outside {MIN_K}..{MAX_K} (check the unit)"
                        ),
                    ))
                }
            };
            *slot = match values {
                RawGridValues::Uniform(x) => vec![check(*x)?; nx * ny * nz],
                RawGridValues::Grid(g) => {
                    if !grid_given {
                        return Err(Invalid::new(
                            &path,
                            "a grid of values needs `stiffness.grid_mm`",
                        ));
                    }
                    let shape = |got: usize, want: usize, what: &str| {
                        if got == want {
                            Ok(())
                        } else {
                            Err(Invalid::new(
                                &path,
                                format!(
                                    "{got} {what} for {want} grid positions (values are indexed [z][y][x])"
                                ),
                            ))
                        }
                    };
                    shape(g.len(), nz, "z layers")?;
                    let mut flat = Vec::with_capacity(nx * ny * nz);
                    for layer in g {
                        shape(layer.len(), ny, "y rows")?;
                        for row in layer {
                            shape(row.len(), nx, "x values")?;
                            for &x in row {
                                flat.push(check(x)?);
                            }
                        }
                    }
                    flat
                }
            };
        }
        Ok(Stiffness { grid, k })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    const K_TOL: f64 = 1e-12;
    const POS_TOL_MM: f64 = 1e-12;

    fn map() -> Stiffness {
        // k_x+ varies along X: 10 at X=0, 30 at X=100 (uniform in Y, Z); the
        // rest uniform.
        let mut s = Stiffness::uniform([[20.0, 25.0], [15.0, 16.0], [40.0, 50.0]]);
        s.grid = [vec![0.0, 100.0], vec![0.0], vec![0.0]];
        s.k = [
            vec![10.0, 30.0],
            vec![25.0, 25.0],
            vec![15.0, 15.0],
            vec![16.0, 16.0],
            vec![40.0, 40.0],
            vec![50.0, 50.0],
        ];
        s
    }

    #[test]
    fn interpolates_and_clamps() {
        let s = map();
        assert_abs_diff_eq!(
            s.k_n_per_um(&Vector3::new(25.0, 7.0, 3.0), 0, true),
            15.0,
            epsilon = K_TOL
        );
        assert_abs_diff_eq!(
            s.k_n_per_um(&Vector3::new(-5.0, 0.0, 0.0), 0, true),
            10.0,
            epsilon = K_TOL
        );
        assert_abs_diff_eq!(
            s.k_n_per_um(&Vector3::new(500.0, 0.0, 0.0), 0, true),
            30.0,
            epsilon = K_TOL
        );
        assert_abs_diff_eq!(
            s.k_n_per_um(&Vector3::new(50.0, 0.0, 0.0), 0, false),
            25.0,
            epsilon = K_TOL
        );
    }

    #[test]
    fn deflection_follows_the_force_sign() {
        // 200 N along +Z at 40 N/µm: +5 µm; −200 N at 50 N/µm: −4 µm;
        // +300 N along X at X = 50 (k = 20): +15 µm.
        let s = map();
        let p = Vector3::new(50.0, 0.0, 0.0);
        let d = s.deflection_mm(&p, &Vector3::new(300.0, 0.0, 200.0));
        assert_abs_diff_eq!(d, Vector3::new(0.015, 0.0, 0.005), epsilon = POS_TOL_MM);
        let d = s.deflection_mm(&p, &Vector3::new(0.0, 0.0, -200.0));
        assert_abs_diff_eq!(d[2], -0.004, epsilon = POS_TOL_MM);
    }

    #[test]
    fn trilinear_on_a_full_grid() {
        // k = 10 + x/10 + y/20 + z/50 on a 2×2×2 grid is trilinear, so the
        // interpolation is exact inside: at (30, 40, 50): 10 + 3 + 2 + 1 = 16.
        let g = [0.0, 100.0];
        let f = |x: f64, y: f64, z: f64| 10.0 + x / 10.0 + y / 20.0 + z / 50.0;
        let mut vals = Vec::new();
        for &z in &g {
            for &y in &g {
                for &x in &g {
                    vals.push(f(x, y, z));
                }
            }
        }
        let mut s = Stiffness::uniform([[1.0; 2]; 3]);
        s.grid = [g.to_vec(), g.to_vec(), g.to_vec()];
        for v in s.k.iter_mut() {
            *v = vals.clone();
        }
        assert_abs_diff_eq!(
            s.k_n_per_um(&Vector3::new(30.0, 40.0, 50.0), 1, false),
            16.0,
            epsilon = K_TOL
        );
    }

    #[test]
    fn deflection_sensitivity_to_position_matches_the_analytic_slope() {
        // d(F/k)/dx with k = 10 + 0.2 x (the map's k_x+): −F·0.2/k² µm/mm.
        // At x = 50 (k = 20), F = 300 N: −300·0.2/400 = −0.15 µm/mm.
        let s = map();
        let f = Vector3::new(300.0, 0.0, 0.0);
        let h = 1e-4;
        let dp = s.deflection_mm(&Vector3::new(50.0 + h, 0.0, 0.0), &f);
        let dm = s.deflection_mm(&Vector3::new(50.0 - h, 0.0, 0.0), &f);
        assert_abs_diff_eq!((dp[0] - dm[0]) / (2.0 * h), -0.15e-3, epsilon = 1e-9);
    }

    /// Hand-derived: `k_x+` grows from 10 to 30 N/µm over 100 mm along X
    /// (G = 0.2 N/µm per mm, no mixed term), so under 1 000 N along +X the
    /// bound is `1e-3 · 1000 · 2 · 0.2² / 10³ = 8e-5` mm/mm², which is the
    /// exact `F · 1e-3 · 2 k'² / k³` at X = 0, the softest point. The other
    /// tables are uniform: a force along −X or Y bends nothing.
    #[test]
    fn curvature_golden() {
        let s = map();
        assert_abs_diff_eq!(
            s.curvature_mm(&Vector3::new(1000.0, 0.0, 0.0)),
            8e-5,
            epsilon = 1e-18
        );
        assert_abs_diff_eq!(
            s.curvature_mm(&Vector3::new(-1000.0, 300.0, 0.0)),
            0.0,
            epsilon = 1e-18
        );
        let fd = |x: f64| {
            let h = 1e-2;
            let d = |x: f64| {
                s.deflection_mm(&Vector3::new(x, 0.0, 0.0), &Vector3::new(1000.0, 0.0, 0.0))[0]
            };
            (d(x + h) - 2.0 * d(x) + d(x - h)) / (h * h)
        };
        assert_abs_diff_eq!(fd(1.0), 8e-5 * (10.0f64 / 10.2).powi(3), epsilon = 1e-9);
    }

    /// A map on a 3 × 2 × 3 grid with values drawn from `lo..hi` N/µm, and
    /// the generator (seeded with `seed`) for the test to go on with.
    fn random_map(seed: u64, lo: f64, hi: f64) -> (Stiffness, impl FnMut() -> f64) {
        let mut s = Stiffness::uniform([[20.0, 25.0], [15.0, 16.0], [40.0, 50.0]]);
        s.grid = [
            vec![0.0, 100.0, 300.0],
            vec![0.0, 200.0],
            vec![0.0, 50.0, 150.0],
        ];
        let mut state = seed;
        let mut rnd = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for slot in s.k.iter_mut() {
            *slot = (0..18).map(|_| lo + (hi - lo) * rnd()).collect();
        }
        (s, rnd)
    }

    /// The bound holds against central second differences of the deflection
    /// along random lines through a three-dimensional map with mixed terms,
    /// away from the grid positions.
    #[test]
    fn curvature_bounds_second_differences() {
        let (s, mut rnd) = random_map(7, 5.0, 45.0);
        // Within one grid cell, clamped beyond: the cells of the lines below.
        let cells = [[0.0, 100.0], [0.0, 200.0], [0.0, 50.0]];
        let mut worst = 0.0f64;
        for _ in 0..2000 {
            let f = Vector3::new(
                2000.0 * rnd() - 1000.0,
                2000.0 * rnd() - 1000.0,
                2000.0 * rnd() - 1000.0,
            );
            let bound = s.curvature_mm(&f);
            let d = Vector3::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5).normalize();
            let p = Vector3::new(
                cells[0][0] + 10.0 + 80.0 * rnd(),
                cells[1][0] + 10.0 + 180.0 * rnd(),
                cells[2][0] + 10.0 + 30.0 * rnd(),
            );
            let h = 1.0;
            let at = |t: f64| s.deflection_mm(&(p + d * t), &f);
            let second = (at(h) - at(0.0) * 2.0 + at(-h)).norm() / (h * h);
            assert!(
                second <= bound * (1.0 + 1e-9) + 1e-15,
                "{second:e} > {bound:e}"
            );
            worst = worst.max(second / bound);
        }
        // Not vacuous. The bound takes the softest value of the whole map
        // (here 5 of 5..45 N/µm, cubed), so a random line reaches about 1 %
        // of it; the golden above shows it exact where the map is softest.
        assert!(worst > 0.005, "largest ratio {worst}");
    }

    /// Hand-derived, where the mixed term decides: k = 1000 + 1e-4·x·y
    /// N/µm on a 100 mm square (corner values 1000, 1000, 1000, 1001), a
    /// force of 1 000 N along +X, the diagonal segment from (40, 40) to
    /// (60, 60). Over its box ∂k/∂x = 1e-4·y ≤ 6e-3, the same for y, the
    /// mixed partial is 1e-4, k ≥ 1000.16, and with d = (1, 1)/√2 the bound
    /// is `1e-3·1000·(2·(2·6e-3/√2)²/k³ + 2·1e-4·½/k²)`; the deflection's
    /// second derivative there, `−F·1e-3·(k''/k² − 2k'²/k³)`, is about
    /// 1e-10 — twenty times what the bound would be without its mixed term.
    #[test]
    fn curvature_on_golden_with_a_mixed_term() {
        let mut s = Stiffness::uniform([[1000.0, 1000.0], [1000.0, 1000.0], [1000.0, 1000.0]]);
        s.grid = [vec![0.0, 100.0], vec![0.0, 100.0], vec![0.0]];
        s.k[0] = vec![1000.0, 1000.0, 1000.0, 1001.0];
        let f = Vector3::new(1000.0, 0.0, 0.0);
        let (a, b) = (Vector3::new(40.0, 40.0, 0.0), Vector3::new(60.0, 60.0, 0.0));
        let bound = s.curvature_on_mm(&a, &b, &f);
        let k = 1000.16f64;
        let g = 6e-3 * 2.0 / 2f64.sqrt();
        let want = 2.0 * g * g / k.powi(3) + 2.0 * 1e-4 * 0.5 / (k * k);
        assert_abs_diff_eq!(bound, want, epsilon = 1e-22);
        let d = (b - a).normalize();
        let h = 10.0;
        let at = |t: f64| s.deflection_mm(&(Vector3::new(50.0, 50.0, 0.0) + d * t), &f)[0];
        let second = ((at(h) - 2.0 * at(0.0) + at(-h)) / (h * h)).abs();
        assert!(second <= bound, "{second:e} > {bound:e}");
        assert!(second > 20.0 * 2.0 * g * g / k.powi(3), "{second:e}");
        // Never above the whole map's bound.
        assert!(bound <= s.curvature_mm(&f));
    }

    /// The segment bound holds against second differences along random
    /// segments inside random cells of a random three-dimensional map, is
    /// never above the whole map's bound, and comes near the truth (the
    /// largest ratio seen).
    #[test]
    fn curvature_on_bounds_second_differences_on_its_segment() {
        let (s, mut rnd) = random_map(3, 4.0, 40.0);
        let mut worst = 0.0f64;
        for k in 0..4000 {
            let f = Vector3::new(
                2000.0 * rnd() - 1000.0,
                2000.0 * rnd() - 1000.0,
                2000.0 * rnd() - 1000.0,
            );
            // A cell, or beyond the grid along some axes (clamped).
            let mut p = Vector3::zeros();
            let mut room = f64::INFINITY;
            for j in 0..3 {
                let g = &s.grid[j];
                let cell = (rnd() * (g.len() + 1) as f64) as usize;
                let (a, b) = match cell {
                    0 => (g[0] - 100.0, g[0]),
                    c if c >= g.len() => (g[g.len() - 1], g[g.len() - 1] + 100.0),
                    c => (g[c - 1], g[c]),
                };
                let t = 0.2 + 0.6 * rnd();
                p[j] = a + (b - a) * t;
                room = room.min((p[j] - a).min(b - p[j]));
            }
            let mut d = Vector3::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5);
            if k % 2 == 0 {
                // Along one axis, with a µm-scale drift of the others.
                d *= 1e-5;
                d[k % 3] = 1.0;
            }
            let d = d.normalize();
            let h = (room * 0.9).min(5.0);
            let at = |t: f64| s.deflection_mm(&(p + d * t), &f);
            let second = (at(h) - at(0.0) * 2.0 + at(-h)).norm() / (h * h);
            let bound = s.curvature_on_mm(&(p - d * h), &(p + d * h), &f);
            assert!(
                second <= bound * (1.0 + 1e-9) + 1e-15,
                "{k}: {second:e} > {bound:e}"
            );
            assert!(bound <= s.curvature_mm(&f) * (1.0 + 1e-12));
            if bound > 0.0 {
                worst = worst.max(second / bound);
            }
        }
        assert!(worst > 0.5, "largest ratio {worst}");
    }
}
