//! Gross outliers: rows whose position residual no effect of the library
//! can explain, left out of every fit, test and held-out figure, and named.
//!
//! The rule: the residual of the current model (positions, µm) is fitted by
//! greedy forward selection of at most [`max_steps`] candidates of the
//! library (each step the candidate that lowers the residual sum of squares
//! most, by orthogonal projection; no test, only to remove the structure a
//! missing effect leaves). Of what remains, the robust standard deviation
//! is `σ = 1.4826 · MAD` of the pooled x, y, z residuals of the rows still
//! in; a row with a coordinate more than [`K_SIGMA`] σ from their median is
//! a gross outlier. Its equations are left out and the procedure repeats
//! until no row is added (a row once out stays out), at most
//! [`MAX_SHARE`] of the rows: if more rows than that lie beyond the bound,
//! the data do not have a few gross errors but another problem (units,
//! frame, a wrong model), and nothing is left out.

use nalgebra::{DMatrix, DVector};
use serde::Serialize;

use super::equations::Equations;

/// Robust standard deviations beyond which a coordinate is a gross error.
pub const K_SIGMA: f64 = 6.0;
/// Largest share of the rows that may be left out as outliers.
pub const MAX_SHARE: f64 = 0.2;
/// Normal-consistency factor of the median absolute deviation.
const MAD_TO_SIGMA: f64 = 1.4826;
/// A direction whose norm falls below this share of its own after
/// projection is already in the basis.
const DEPENDENT: f64 = 1e-8;
/// Relative singular value below which the structure fit drops a direction.
const RANK_RTOL: f64 = 1e-10;

/// A row left out as a gross outlier.
#[derive(Debug, Clone, Serialize)]
pub struct Outlier {
    /// Index of the row in the observations, 0-based.
    pub index: usize,
    /// Row label (`id`).
    pub id: String,
    /// Line of the row in the observation file (0: not from a file).
    pub line: usize,
    /// Largest coordinate residual (from the median of the rows kept) after
    /// the structure fit of the rows kept, µm.
    pub residual_um: f64,
    /// That residual in robust standard deviations.
    pub sigmas: f64,
}

/// The outliers found, with the robust σ of the rows kept.
#[derive(Debug, Clone, Serialize)]
pub struct Outliers {
    /// Rows left out.
    pub rows: Vec<Outlier>,
    /// Robust standard deviation of a coordinate of the rows kept, µm.
    pub sigma_um: f64,
    /// Candidates the structure fit used.
    pub structure_candidates: usize,
}

/// Greedy steps of the structure fit for `rows` rows: one per five rows,
/// at most 8.
pub fn max_steps(rows: usize) -> usize {
    (rows / 5).min(8)
}

fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Orthonormal directions of the columns of `s` on the equations `e`,
/// orthogonal to `basis`.
fn new_directions(s: &DMatrix<f64>, e: &[usize], basis: &[DVector<f64>]) -> Vec<DVector<f64>> {
    let mut out: Vec<DVector<f64>> = Vec::new();
    for j in 0..s.ncols() {
        let mut v = DVector::from_iterator(
            e.len(),
            e.iter().map(|&k| s.get((k, j)).copied().unwrap_or(0.0)),
        );
        let n0 = v.norm();
        if !(n0 > 0.0 && n0.is_finite()) {
            continue;
        }
        for q in basis.iter().chain(out.iter()) {
            let d = q.dot(&v);
            v -= q * d;
        }
        let n = v.norm();
        if n > DEPENDENT * n0 {
            out.push(v / n);
        }
    }
    out
}

/// The position residual of the rows `kept` after the greedy structure fit
/// (µm, 3 per row in the order of `kept`), and the candidates used.
fn structure_residual(
    r: &DVector<f64>,
    sens: &[DMatrix<f64>],
    eq: &Equations,
    kept: &[usize],
) -> (DVector<f64>, Vec<usize>) {
    let e: Vec<usize> = kept
        .iter()
        .flat_map(|&i| {
            let s = eq.start(i);
            s..s + 3
        })
        .collect();
    let mut res =
        DVector::from_iterator(e.len(), e.iter().map(|&k| r.get(k).copied().unwrap_or(0.0)));
    let mut basis: Vec<DVector<f64>> = Vec::new();
    let mut used = vec![false; sens.len()];
    let mut chosen = Vec::new();
    for _ in 0..max_steps(kept.len()) {
        let mut best: Option<(usize, f64, Vec<DVector<f64>>)> = None;
        for (c, s) in sens.iter().enumerate() {
            if used[c] {
                continue;
            }
            let dirs = new_directions(s, &e, &basis);
            let gain: f64 = dirs.iter().map(|q| q.dot(&res).powi(2)).sum();
            if best.as_ref().is_none_or(|b| gain > b.1) {
                best = Some((c, gain, dirs));
            }
        }
        let Some((c, gain, dirs)) = best else { break };
        // A gain that is not positive (or not a number) explains nothing.
        if gain.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            break;
        }
        used[c] = true;
        chosen.push(c);
        for q in dirs {
            let d = q.dot(&res);
            res -= &q * d;
            basis.push(q);
        }
    }
    (res, chosen)
}

/// Equations of the positions of `rows`.
fn position_equations(eq: &Equations, rows: &[usize]) -> Vec<usize> {
    rows.iter()
        .flat_map(|&i| {
            let s = eq.start(i);
            s..s + 3
        })
        .collect()
}

/// The position residual (µm, x y z) of each row of `out` after the least-
/// squares fit of the candidates `chosen` on the rows `kept`.
fn residual_of_left_out(
    r: &DVector<f64>,
    sens: &[DMatrix<f64>],
    eq: &Equations,
    kept: &[usize],
    out: &[usize],
    chosen: &[usize],
) -> Vec<[f64; 3]> {
    let design = |e: &[usize]| {
        let cols: Vec<&DMatrix<f64>> = chosen.iter().filter_map(|&c| sens.get(c)).collect();
        let k: usize = cols.iter().map(|s| s.ncols()).sum();
        let mut x = DMatrix::zeros(e.len(), k);
        let mut col = 0;
        for s in cols {
            for j in 0..s.ncols() {
                for (row, &q) in e.iter().enumerate() {
                    x[(row, col)] = s.get((q, j)).copied().unwrap_or(0.0);
                }
                col += 1;
            }
        }
        x
    };
    let ek = position_equations(eq, kept);
    let eo = position_equations(eq, out);
    let y = DVector::from_iterator(
        ek.len(),
        ek.iter().map(|&q| r.get(q).copied().unwrap_or(0.0)),
    );
    let yo = DVector::from_iterator(
        eo.len(),
        eo.iter().map(|&q| r.get(q).copied().unwrap_or(0.0)),
    );
    let xk = design(&ek);
    let pred = if xk.ncols() == 0 {
        DVector::zeros(eo.len())
    } else {
        match xk.svd(true, true).solve(&y, RANK_RTOL) {
            Ok(beta) => design(&eo) * beta,
            Err(_) => DVector::zeros(eo.len()),
        }
    };
    let e = yo - pred;
    (0..out.len())
        .map(|k| std::array::from_fn(|c| e.get(3 * k + c).copied().unwrap_or(0.0)))
        .collect()
}

/// Finds the gross outliers among `rows` (see the module comment): `r` the
/// residual and `sens` the candidates' sensitivities on the equations `eq`;
/// `label(i)` gives row `i`'s id and line.
pub fn find(
    r: &DVector<f64>,
    sens: &[DMatrix<f64>],
    eq: &Equations,
    n_rows: usize,
    label: impl Fn(usize) -> (String, usize),
) -> Outliers {
    let mut out: Vec<(usize, f64, f64)> = Vec::new();
    let max_out = (MAX_SHARE * n_rows as f64).floor() as usize;
    let (sigma, med, kept, chosen) = loop {
        let kept: Vec<usize> = (0..n_rows)
            .filter(|i| !out.iter().any(|o| o.0 == *i))
            .collect();
        let (res, chosen) = structure_residual(r, sens, eq, &kept);
        let mut v: Vec<f64> = res.iter().copied().collect();
        let med = median(&mut v);
        let mut dev: Vec<f64> = res.iter().map(|x| (x - med).abs()).collect();
        let sigma = MAD_TO_SIGMA * median(&mut dev);
        if !(sigma > 0.0 && sigma.is_finite()) {
            break (sigma, med, kept, chosen);
        }
        let new: Vec<(usize, f64, f64)> = kept
            .iter()
            .enumerate()
            .filter_map(|(k, &i)| {
                let worst = (0..3)
                    .map(|c| res.get(3 * k + c).copied().unwrap_or(0.0) - med)
                    .max_by(|a, b| a.abs().total_cmp(&b.abs()))
                    .unwrap_or(0.0);
                (worst.abs() > K_SIGMA * sigma).then_some((i, worst.abs(), worst.abs() / sigma))
            })
            .collect();
        if new.is_empty() {
            break (sigma, med, kept, chosen);
        }
        if out.len() + new.len() > max_out {
            // Not a few gross errors: leave every row in.
            out.clear();
            break (sigma, med, kept, chosen);
        }
        out.extend(new);
    };
    out.sort_by_key(|o| o.0);
    // Each row left out, against the structure fit and σ of the rows kept.
    let idx: Vec<usize> = out.iter().map(|o| o.0).collect();
    let final_res = residual_of_left_out(r, sens, eq, &kept, &idx, &chosen);
    Outliers {
        rows: idx
            .iter()
            .zip(&final_res)
            .map(|(&index, e)| {
                let (id, line) = label(index);
                let worst = e.iter().map(|v| (v - med).abs()).fold(0.0, f64::max);
                Outlier {
                    index,
                    id,
                    line,
                    residual_um: worst,
                    sigmas: if sigma > 0.0 {
                        worst / sigma
                    } else {
                        f64::INFINITY
                    },
                }
            })
            .collect(),
        sigma_um: sigma,
        structure_candidates: chosen.len(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Median of odd and even lengths; steps per row count.
    #[test]
    fn median_and_steps() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 2.0, 3.0]), 2.5);
        assert_eq!(max_steps(24), 4);
        assert_eq!(max_steps(120), 8);
    }
}
