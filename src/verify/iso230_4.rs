//! ISO 230-4: circular tests from radial deviations (a ballbar or a grid
//! encoder) in both directions (docs/verify.md).
//!
//! Each path is referred to its least-squares circle: the radial
//! deviations dr(θ) are fitted by c + a cos θ + b sin θ (the centre offset
//! (a, b) and radius change c of the least-squares circle, to first order
//! in deviation over radius, which is below 1e-6 for a ballbar), and
//! - the circular deviation G of a path is the range of its residuals
//!   (the radial separation of the two circles about that centre that
//!   enclose it);
//! - the bidirectional circular deviation G_b is that range of both paths
//!   about their common least-squares circle;
//! - the circular hysteresis H is the largest radial difference between
//!   the two paths at the same angle (each path interpolated linearly in
//!   angle at the other's points), which a common centre leaves unchanged.

use nalgebra::{Matrix3, Vector3};
use serde_json::json;

use super::table::{Column, Kind, Table};
use super::{Evaluation, Figure, Group, Standard, fmt_mm, json_mm};
use crate::error::{Error, Located, Result};

/// The figures, in report order (`G` is the larger of the two paths').
pub const FIGURES: [&str; 5] = ["G_ccw", "G_cw", "G", "G_b", "H"];

/// Fewest points per direction.
pub const MIN_POINTS: usize = 8;

/// Largest angle between neighbouring points of a path, degrees.
pub const MAX_GAP_DEG: f64 = 45.0;

/// Angles closer than this are the same angle, degrees.
const SAME_ANGLE_DEG: f64 = 1e-9;

/// The columns of a circular-test file.
pub const COLUMNS: &[Column] = &[
    Column::optional("id", Kind::Text),
    Column::required("dir", Kind::Sign),
    Column::required("angle_deg", Kind::Number),
    Column::required("dr_mm", Kind::Number),
    Column::optional("t_s", Kind::Number),
];

/// One path: (angle rad in [0, 2π), radial deviation mm), sorted by angle.
pub type Path = Vec<(f64, f64)>;

/// The two paths of a test.
#[derive(Debug, Clone, PartialEq)]
pub struct Circle {
    /// Counter-clockwise (`dir` +1).
    pub ccw: Path,
    /// Clockwise (`dir` −1).
    pub cw: Path,
}

/// The least-squares circle of points: (a, b, c) mm.
pub fn fit(points: &[(f64, f64)]) -> Vector3<f64> {
    let mut n = Matrix3::zeros();
    let mut r = Vector3::zeros();
    for &(t, d) in points {
        let basis = Vector3::new(1.0, t.cos(), t.sin());
        n += basis * basis.transpose();
        r += basis * d;
    }
    n.lu().solve(&r).unwrap_or_else(Vector3::zeros)
}

/// Residual of a point about a circle (c, a, b).
fn residual(p: (f64, f64), f: &Vector3<f64>) -> f64 {
    p.1 - f[0] - f[1] * p.0.cos() - f[2] * p.0.sin()
}

fn range(it: impl Iterator<Item = f64> + Clone) -> f64 {
    it.clone().fold(f64::NEG_INFINITY, f64::max) - it.fold(f64::INFINITY, f64::min)
}

/// The deviation of a sorted path at angle `t`, linear between neighbours
/// (around the circle).
fn at(path: &Path, t: f64) -> f64 {
    let n = path.len();
    let i = path.partition_point(|p| p.0 <= t);
    let (p0, p1) = if i == 0 || i == n {
        let (a, b) = (path[n - 1], path[0]);
        (a, (b.0 + std::f64::consts::TAU, b.1))
    } else {
        (path[i - 1], path[i])
    };
    let t = if t < p0.0 {
        t + std::f64::consts::TAU
    } else {
        t
    };
    let w = (t - p0.0) / (p1.0 - p0.0);
    p0.1 + (p1.1 - p0.1) * w
}

/// The evaluated test.
#[derive(Debug, Clone, PartialEq)]
pub struct Iso230_4 {
    /// Points of each path (ccw, cw).
    pub points: (usize, usize),
    /// Least-squares circles (c, a, b) of each path and of both, mm.
    pub fits: [Vector3<f64>; 3],
    /// The figures in the order of [`FIGURES`], mm.
    pub figures: [f64; 5],
}

/// Evaluates a test.
pub fn evaluate(c: &Circle) -> Iso230_4 {
    let f_ccw = fit(&c.ccw);
    let f_cw = fit(&c.cw);
    let both: Vec<(f64, f64)> = c.ccw.iter().chain(&c.cw).copied().collect();
    let f_both = fit(&both);
    let g_ccw = range(c.ccw.iter().map(|&p| residual(p, &f_ccw)));
    let g_cw = range(c.cw.iter().map(|&p| residual(p, &f_cw)));
    let g_b = range(both.iter().map(|&p| residual(p, &f_both)));
    let h = c
        .ccw
        .iter()
        .map(|&(t, d)| (d - at(&c.cw, t)).abs())
        .chain(c.cw.iter().map(|&(t, d)| (d - at(&c.ccw, t)).abs()))
        .fold(0.0, f64::max);
    Iso230_4 {
        points: (c.ccw.len(), c.cw.len()),
        fits: [f_ccw, f_cw, f_both],
        figures: [g_ccw, g_cw, g_ccw.max(g_cw), g_b, h],
    }
}

/// Reads a circular-test file.
pub fn read_circle(text: &str, file: &str) -> Result<Circle> {
    let table = Table::parse(text, file, COLUMNS)?;
    let mut paths: [Vec<(f64, f64, usize)>; 2] = [Vec::new(), Vec::new()];
    for row in &table.rows {
        let need = |name: &str| {
            row.number(&table, name)
                .ok_or_else(|| row.error(&table, name, format!("empty `{name}`")))
        };
        let dir = need("dir")?;
        let deg = need("angle_deg")?.rem_euclid(360.0);
        let dr = need("dr_mm")?;
        let path = &mut paths[usize::from(dir < 0.0)];
        if path.iter().any(|p| {
            let d = (p.0 - deg).abs();
            d.min(360.0 - d) <= SAME_ANGLE_DEG
        }) {
            return Err(row.error(
                &table,
                "angle_deg",
                format!(
                    "angle {} deg of the {} path given twice",
                    deg,
                    if dir > 0.0 { "ccw" } else { "cw" }
                ),
            ));
        }
        path.push((deg, dr, row.line));
    }
    let [ccw, cw] = paths;
    Ok(Circle {
        ccw: checked_path(file, table.header_line, ccw, "ccw (dir +1)")?,
        cw: checked_path(file, table.header_line, cw, "cw (dir -1)")?,
    })
}

/// A path sorted by angle, with enough points around the whole circle.
fn checked_path(
    file: &str,
    header_line: usize,
    mut p: Vec<(f64, f64, usize)>,
    name: &str,
) -> Result<Path> {
    let err = |line, m: String| Error::Input(Located::new(file, line, 1, m));
    if p.len() < MIN_POINTS {
        return Err(err(
            header_line,
            format!(
                "the {name} path has {} points; at least {MIN_POINTS} around the circle are needed",
                p.len()
            ),
        ));
    }
    p.sort_by(|a, b| a.0.total_cmp(&b.0));
    for (i, w) in p.iter().enumerate() {
        let next = p.get(i + 1).map_or(p[0].0 + 360.0, |n| n.0);
        if next - w.0 > MAX_GAP_DEG + SAME_ANGLE_DEG {
            return Err(err(
                w.2,
                format!(
                    "the {name} path leaves {:.1} deg without a point after {} deg (at most {MAX_GAP_DEG}); a full circle is needed",
                    next - w.0,
                    w.0
                ),
            ));
        }
    }
    Ok(p.into_iter().map(|(d, r, _)| (d.to_radians(), r)).collect())
}

impl Evaluation for Iso230_4 {
    fn standard(&self) -> Standard {
        Standard::Iso230_4
    }

    fn groups(&self) -> Vec<Group> {
        vec![Group {
            name: "circle".into(),
            figures: FIGURES
                .iter()
                .zip(self.figures)
                .map(|(&name, value_mm)| Figure {
                    name,
                    value_mm,
                    u_mm: None,
                })
                .collect(),
        }]
    }

    fn detail_json(&self) -> serde_json::Value {
        let fit = |f: &Vector3<f64>| {
            json!({
                "centre_x_mm": json_mm(f[1]),
                "centre_y_mm": json_mm(f[2]),
                "radius_change_mm": json_mm(f[0]),
            })
        };
        json!({
            "points_ccw": self.points.0,
            "points_cw": self.points.1,
            "circle_ccw": fit(&self.fits[0]),
            "circle_cw": fit(&self.fits[1]),
            "circle_both": fit(&self.fits[2]),
        })
    }

    fn detail_table(&self, out: &mut String) {
        out.push_str(&format!(
            "{:<6} {:>7} {:>12} {:>12} {:>14}\n",
            "path", "points", "centre_x_mm", "centre_y_mm", "radius_chg_mm"
        ));
        let names = ["ccw", "cw", "both"];
        let pts = [self.points.0, self.points.1, self.points.0 + self.points.1];
        for ((n, f), p) in names.iter().zip(&self.fits).zip(pts) {
            out.push_str(&format!(
                "{n:<6} {p:>7} {:>12} {:>12} {:>14}\n",
                fmt_mm(f[1]),
                fmt_mm(f[2]),
                fmt_mm(f[0])
            ));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    const NM: f64 = 1e-6;

    /// Eight points at 0, 45, … 315 deg: `base` µm plus a centre offset of
    /// (3, 1.5) µm and a radius change of 0.5 µm.
    fn path(base: [f64; 8]) -> Path {
        base.iter()
            .enumerate()
            .map(|(i, b)| {
                let t = (45.0 * i as f64).to_radians();
                (t, (b + 3.0 * t.cos() + 1.5 * t.sin() + 0.5) * 1e-3)
            })
            .collect()
    }

    #[test]
    fn figures_of_a_hand_derived_test() {
        // Neither base has a first harmonic, so each fit removes exactly
        // the offset: G_ccw = 2 − 0, G_cw = 3 − 1, G_b = 3 − 0 µm, and
        // H = max |cw − ccw| = 1 µm.
        let c = Circle {
            ccw: path([2.0, 0.0, 2.0, 0.0, 2.0, 0.0, 2.0, 0.0]),
            cw: path([3.0, 1.0, 2.0, 1.0, 3.0, 1.0, 2.0, 1.0]),
        };
        let r = evaluate(&c);
        let want = [0.002, 0.002, 0.002, 0.003, 0.001];
        for ((name, got), want) in FIGURES.iter().zip(r.figures).zip(want) {
            assert!((got - want).abs() <= NM, "{name}: {got} vs {want}");
        }
        assert_abs_diff_eq!(r.fits[0][1], 0.003, epsilon = NM);
        assert_abs_diff_eq!(r.fits[0][2], 0.0015, epsilon = NM);
        // Mean of the ccw base (1 µm) plus the radius change.
        assert_abs_diff_eq!(r.fits[0][0], 0.0015, epsilon = NM);
    }

    #[test]
    fn interpolation_wraps_around_the_circle() {
        let p: Path = vec![(0.5, 1.0), (3.0, 2.0), (6.0, 3.0)];
        assert_abs_diff_eq!(at(&p, 1.75), 1.5, epsilon = 1e-12);
        // Between 6.0 and 0.5 + 2π.
        let mid = (6.0 + 0.5 + std::f64::consts::TAU) / 2.0;
        assert_abs_diff_eq!(at(&p, mid - std::f64::consts::TAU), 2.0, epsilon = 1e-12);
        assert_abs_diff_eq!(at(&p, mid), 2.0, epsilon = 1e-12);
    }

    #[test]
    fn a_partial_or_sparse_path_is_refused() {
        let mut text = String::from("dir,angle_deg,dr_mm\n");
        for i in 0..8 {
            text.push_str(&format!("+1,{},0\n", i * 45));
        }
        for i in 0..8 {
            text.push_str(&format!("-1,{},0\n", i * 30));
        }
        let e = read_circle(&text, "c.csv").unwrap_err().to_string();
        assert!(
            e.starts_with("c.csv:17:1: the cw (dir -1) path leaves 150.0 deg"),
            "{e}"
        );
        let e = read_circle("dir,angle_deg,dr_mm\n+1,0,0\n-1,0,0\n", "c.csv")
            .unwrap_err()
            .to_string();
        assert!(e.contains("1 points"), "{e}");
        let e = read_circle("dir,angle_deg,dr_mm\n+1,0,0\n+1,360,0\n", "c.csv")
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("c.csv:3:4: angle 0 deg of the ccw path given twice"),
            "{e}"
        );
    }
}
