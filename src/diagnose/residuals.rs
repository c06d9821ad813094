//! "Where": residuals (measured − simulated) against every covariate the
//! rows carry — time, load magnitude and direction, approach direction, each
//! joint or axis position, powers — with Spearman rank correlation, a runs
//! test and the Durbin–Watson statistic of the residuals sorted by the
//! covariate, binned means and Holm-corrected p-values.

use nalgebra::Vector3;
use serde::Serialize;

use crate::calibrate::observations::{Observation, Pose};
use crate::calibrate::stats;

/// Number of bins of the binned means.
pub const BINS: usize = 5;
/// Fewest rows with a value for a covariate to be analysed.
pub const MIN_ROWS: usize = 8;
/// Family-wise significance level of the "where" tests.
pub const ALPHA: f64 = 0.01;

/// One covariate against one residual component.
#[derive(Debug, Clone, Serialize)]
pub struct Trend {
    /// Covariate name (the observation column, or `|F|_n`).
    pub covariate: String,
    /// Residual component `x`, `y` or `z`.
    pub component: char,
    /// Rows with a value.
    pub n: usize,
    /// Spearman rank correlation.
    pub rho: f64,
    /// Its two-sided p-value.
    pub p_spearman: f64,
    /// Runs-test p-value of the residuals sorted by the covariate.
    pub p_runs: f64,
    /// Durbin–Watson statistic of the residuals sorted by the covariate
    /// (≈2 for no structure, small for a smooth trend).
    pub durbin_watson: f64,
    /// Holm-adjusted p-value (min of the two tests, over all trends).
    pub p_holm: f64,
    /// Bin centres (covariate) and mean residual (µm) of each bin.
    pub bins: Vec<(f64, f64)>,
}

/// The "where" analysis.
#[derive(Debug, Clone, Serialize)]
pub struct Where {
    /// RMS of the residual per component, µm.
    pub rms_um: [f64; 3],
    /// Every trend, strongest (smallest Holm p) first.
    pub trends: Vec<Trend>,
    /// Patterns in the frames where effects show (tool frame, joint space,
    /// load), best first ([`super::patterns`]).
    pub patterns: Vec<super::patterns::Pattern>,
    /// One plain sentence.
    pub sentence: String,
}

/// Covariates of a row: (name, value) where the row has one.
pub fn covariates(row: &Observation) -> Vec<(String, f64)> {
    let mut out = Vec::new();
    if let Some(t) = row.t_s {
        out.push(("t_s".to_string(), t));
    }
    let f = row.force_n;
    out.push(("|F|_n".to_string(), f.norm()));
    for (i, c) in ["fx_n", "fy_n", "fz_n"].iter().enumerate() {
        out.push((c.to_string(), f[i]));
    }
    if let Some(a) = row.ambient_c {
        out.push(("ambient_c".into(), a));
    }
    match &row.pose {
        Pose::Robot(rp) => {
            for i in 0..6 {
                out.push((format!("q{}_deg", i + 1), rp.q_deg[i]));
                if let Some(p) = rp.p_w[i] {
                    out.push((format!("p{}_w", i + 1), p));
                }
                if let Some(d) = rp.dir[i] {
                    out.push((format!("dir{}", i + 1), f64::from(d)));
                }
            }
        }
        Pose::Tool(tp) => {
            let names = ["X_mm", "Y_mm", "Z_mm", "A_deg", "B_deg", "C_deg"];
            let ax = tp.axes();
            for i in 0..6 {
                if i < 3 || tp.abc_deg[i - 3].is_some() {
                    out.push((names[i].to_string(), ax[i]));
                }
                if let Some(d) = tp.dir[i] {
                    out.push((
                        format!("dir{}", names[i].chars().next().unwrap_or('X')),
                        f64::from(d),
                    ));
                }
                if let Some(p) = tp.p_w[i] {
                    out.push((format!("p{}_w", names[i].chars().next().unwrap_or('X')), p));
                }
            }
            if let Some(l) = tp.tool_mm {
                out.push(("tool_mm".into(), l));
            }
            if let Some(s) = tp.spindle_rpm {
                out.push(("spindle_rpm".into(), s));
            }
            if let Some(w) = tp.spindle_w {
                out.push(("spindle_w".into(), w));
            }
        }
    }
    out
}

/// Analyses residuals (mm) of `rows`.
pub fn analyse(rows: &[Observation], residual_mm: &[Vector3<f64>]) -> Where {
    let mut names: Vec<String> = Vec::new();
    let per_row: Vec<Vec<(String, f64)>> = rows.iter().map(covariates).collect();
    for c in per_row.iter().flatten() {
        if !names.contains(&c.0) {
            names.push(c.0.clone());
        }
    }
    let mut trends = Vec::new();
    for name in &names {
        let pairs: Vec<(f64, Vector3<f64>)> = per_row
            .iter()
            .zip(residual_mm)
            .filter_map(|(cs, r)| cs.iter().find(|c| &c.0 == name).map(|c| (c.1, *r)))
            .filter(|(x, _)| x.is_finite())
            .collect();
        if pairs.len() < MIN_ROWS {
            continue;
        }
        let first = pairs.first().map(|p| p.0).unwrap_or(0.0);
        if pairs.iter().all(|p| p.0 == first) {
            continue;
        }
        let mut sorted = pairs.clone();
        sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
        let x: Vec<f64> = sorted.iter().map(|p| p.0).collect();
        for (ci, comp) in ['x', 'y', 'z'].into_iter().enumerate() {
            let e: Vec<f64> = sorted.iter().map(|p| p.1[ci] * 1000.0).collect();
            let Some(sp) = stats::spearman(&x, &e) else {
                continue;
            };
            let mean = stats::mean(&e).unwrap_or(0.0);
            let centred: Vec<f64> = e.iter().map(|v| v - mean).collect();
            let p_runs = stats::runs_test(&centred).map_or(1.0, |r| r.p_value);
            let dw = stats::durbin_watson(&centred).unwrap_or(2.0);
            let bins = binned(&x, &e);
            trends.push(Trend {
                covariate: name.clone(),
                component: comp,
                n: x.len(),
                rho: sp.rho,
                p_spearman: sp.p_value,
                p_runs,
                durbin_watson: dw,
                p_holm: 1.0,
                bins,
            });
        }
    }
    // Each trend is summarised by the smaller of its two p-values (times 2,
    // Bonferroni within the trend), then Holm across all trends.
    let raw: Vec<f64> = trends
        .iter()
        .map(|t| (2.0 * t.p_spearman.min(t.p_runs)).min(1.0))
        .collect();
    let adj = stats::holm_bonferroni(&raw);
    for (t, p) in trends.iter_mut().zip(adj) {
        t.p_holm = p;
    }
    trends.sort_by(|a, b| {
        a.p_holm
            .total_cmp(&b.p_holm)
            .then(b.rho.abs().total_cmp(&a.rho.abs()))
    });
    let comp_rms = |c: usize| {
        let v: Vec<f64> = residual_mm.iter().map(|r| r[c] * 1000.0).collect();
        stats::rms(&v).unwrap_or(0.0)
    };
    let rms_um = [comp_rms(0), comp_rms(1), comp_rms(2)];
    let sentence = match trends.first() {
        Some(t) if t.p_holm < ALPHA => {
            let lo = t.bins.first().map_or(0.0, |b| b.1);
            let hi = t.bins.last().map_or(0.0, |b| b.1);
            format!(
                "The model and the measurements disagree most in {} against {}: the mean {} residual goes from {:+.1} µm to {:+.1} µm across its range (Spearman ρ = {:+.2}, Holm-corrected p = {:.1e}).",
                t.component, t.covariate, t.component, lo, hi, t.rho, t.p_holm
            )
        }
        _ => format!(
            "No residual trend against any covariate is significant at {:.0} % after Holm correction; the residual RMS is x {:.1}, y {:.1}, z {:.1} µm.",
            ALPHA * 100.0,
            rms_um[0],
            rms_um[1],
            rms_um[2]
        ),
    };
    Where {
        rms_um,
        trends,
        patterns: Vec::new(),
        sentence,
    }
}

/// Means of `e` in [`BINS`] equal-count bins of sorted `x`.
fn binned(x: &[f64], e: &[f64]) -> Vec<(f64, f64)> {
    let n = x.len();
    let mut out = Vec::new();
    for b in 0..BINS {
        let lo = b * n / BINS;
        let hi = (b + 1) * n / BINS;
        if hi <= lo {
            continue;
        }
        let xs = x.get(lo..hi).unwrap_or(&[]);
        let es = e.get(lo..hi).unwrap_or(&[]);
        if let (Some(mx), Some(me)) = (stats::mean(xs), stats::mean(es)) {
            out.push((mx, me));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calibrate::observations::ToolPose;
    use approx::assert_abs_diff_eq;

    /// Correlation tolerance.
    const RHO_TOL: f64 = 1e-12;

    fn row(x: f64) -> Observation {
        Observation {
            orientation: None,
            line: 0,
            id: "r".into(),
            t_s: None,
            measured_mm: Vector3::zeros(),
            force_n: Vector3::zeros(),
            moment_nm: Vector3::zeros(),
            ambient_c: None,
            pose: Pose::Tool(ToolPose {
                xyz_mm: Vector3::new(x, 10.0, 20.0),
                abc_deg: [None; 3],
                dir: [None; 6],
                tool_mm: None,
                spindle_rpm: None,
                spindle_w: None,
                p_w: [None; 6],
            }),
        }
    }

    /// A y residual that grows monotonically with X (1 µm per 10 mm) has
    /// Spearman ρ = 1 against X_mm, is the strongest trend, and the sentence
    /// names it; the bins of 20 rows (X 0…190, 200…390, …) have means
    /// 9.5, 29.5, 49.5, 69.5, 89.5 µm.
    #[test]
    fn monotonic_trend_is_found() {
        let rows: Vec<Observation> = (0..100).map(|i| row(f64::from(i) * 10.0)).collect();
        let res: Vec<Vector3<f64>> = (0..100)
            .map(|i| Vector3::new(0.0, f64::from(i) * 1e-3, 0.0))
            .collect();
        let w = analyse(&rows, &res);
        let t = w.trends.first().expect("a trend");
        assert_eq!((t.covariate.as_str(), t.component), ("X_mm", 'y'));
        assert_abs_diff_eq!(t.rho, 1.0, epsilon = RHO_TOL);
        let means: Vec<f64> = t.bins.iter().map(|b| b.1).collect();
        for (m, want) in means.iter().zip([9.5, 29.5, 49.5, 69.5, 89.5]) {
            assert_abs_diff_eq!(*m, want, epsilon = RHO_TOL * 1e3);
        }
        assert!(w.sentence.contains("in y against X_mm"), "{}", w.sentence);
    }
}
