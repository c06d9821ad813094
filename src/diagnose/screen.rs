//! Identifiability screen of the candidate library on the rows at hand,
//! before any fit: which candidates (or groups of candidates) the rows
//! cannot tell apart.
//!
//! - **Pairs**: the cosine of the smallest principal angle between the
//!   column spaces of two candidates (any number of parameters each: the
//!   largest singular value of `Q_aᵀ Q_b`, with `Q` orthonormal bases). Above
//!   [`SCREEN_COS`] the pair is inseparable — e.g. `joint6_zero` against the
//!   three-column `tcp_offset` on position-only data.
//! - **Groups**: a column-pivoting pass over the whole library (in library
//!   order, Gram–Schmidt with re-orthogonalisation) keeps the columns that
//!   add a new direction; a column whose part outside the span of the kept
//!   ones is below `sin` of the same angle is a combination of them. Its
//!   least-squares coefficients on the kept columns name the group (every
//!   candidate contributing at least [`GROUP_SHARE`] of it). Groups that are
//!   a pair already listed are not repeated.

use nalgebra::{DMatrix, DVector};
use serde::Serialize;

use super::Confusable;

/// |cos| above which two candidates (or a candidate and a group) count as
/// inseparable.
pub const SCREEN_COS: f64 = 0.9995;
/// Smallest share (|coefficient| of the normalised column) for a candidate
/// to be named in a group.
pub const GROUP_SHARE: f64 = 0.1;

/// A candidate that is (nearly) a combination of other candidates.
#[derive(Debug, Clone, Serialize)]
pub struct Group {
    /// The dependent candidate.
    pub candidate: String,
    /// The candidates it is a combination of.
    pub of: Vec<String>,
    /// Sine of the angle between the dependent column and their span.
    pub sin: f64,
}

/// Orthonormal basis of the columns of `s` (rank-revealing: columns that
/// add nothing are dropped); `None` when `s` has no direction.
fn basis(s: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let svd = s.clone().svd(true, false);
    let u = svd.u?;
    let smax = svd.singular_values.max();
    if smax.is_nan() || smax <= 0.0 {
        return None;
    }
    let keep: Vec<usize> = (0..svd.singular_values.len())
        .filter(|&j| svd.singular_values[j] > 1e-9 * smax)
        .collect();
    Some(u.select_columns(keep.iter()))
}

/// Pairs of candidates whose column spaces nearly share a direction.
pub fn pairs(sens: &[DMatrix<f64>], names: &[String]) -> Vec<Confusable> {
    let bases: Vec<Option<DMatrix<f64>>> = sens.iter().map(basis).collect();
    let mut out = Vec::new();
    for i in 0..bases.len() {
        for j in i + 1..bases.len() {
            let (Some(Some(a)), Some(Some(b))) = (bases.get(i), bases.get(j)) else {
                continue;
            };
            let m = a.transpose() * b;
            let cos = m.svd(false, false).singular_values.max();
            if cos > SCREEN_COS {
                out.push(Confusable {
                    a: names.get(i).cloned().unwrap_or_default(),
                    b: names.get(j).cloned().unwrap_or_default(),
                    cos: cos.min(1.0),
                });
            }
        }
    }
    out
}

/// Candidates that are combinations of several others (see the module
/// documentation); pairs already in `pairs` are left out.
pub fn groups(sens: &[DMatrix<f64>], names: &[String], pairs: &[Confusable]) -> Vec<Group> {
    let sin_tol = (1.0 - SCREEN_COS * SCREEN_COS).sqrt();
    let n = sens.first().map_or(0, DMatrix::nrows);
    // Kept (independent) normalised columns, their orthonormal basis and
    // their candidate index.
    let mut kept: Vec<DVector<f64>> = Vec::new();
    let mut ortho: Vec<DVector<f64>> = Vec::new();
    let mut owner: Vec<usize> = Vec::new();
    let mut dependent: Vec<(usize, DVector<f64>, f64)> = Vec::new();
    for (c, s) in sens.iter().enumerate() {
        for j in 0..s.ncols() {
            let col = s.column(j).into_owned();
            let norm = col.norm();
            if norm.is_nan() || norm <= 0.0 || col.len() != n {
                continue;
            }
            let x = col / norm;
            let mut r = x.clone();
            for _ in 0..2 {
                for q in &ortho {
                    let d = q.dot(&r);
                    r -= q * d;
                }
            }
            let rn = r.norm();
            if rn < sin_tol {
                dependent.push((c, x, rn));
            } else {
                ortho.push(r / rn);
                kept.push(x);
                owner.push(c);
            }
        }
    }
    if kept.is_empty() {
        return Vec::new();
    }
    let xk = DMatrix::from_columns(&kept);
    let svd = xk.svd(true, true);
    let mut out: Vec<Group> = Vec::new();
    for (c, x, rn) in dependent {
        let Ok(coef) = svd.solve(&x, 1e-12) else {
            continue;
        };
        let mut of: Vec<usize> = coef
            .iter()
            .zip(&owner)
            .filter(|(v, o)| v.abs() >= GROUP_SHARE && **o != c)
            .map(|(_, o)| *o)
            .collect();
        of.sort_unstable();
        of.dedup();
        let name = |i: usize| names.get(i).cloned().unwrap_or_default();
        if of.is_empty() {
            continue;
        }
        if of.len() == 1 {
            let (a, b) = (name(c), name(of[0]));
            if pairs
                .iter()
                .any(|p| (p.a == a && p.b == b) || (p.a == b && p.b == a))
            {
                continue;
            }
        }
        let g = Group {
            candidate: name(c),
            of: of.into_iter().map(name).collect(),
            sin: rn,
        };
        if !out
            .iter()
            .any(|o| o.candidate == g.candidate && o.of == g.of)
        {
            out.push(g);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(n: &[&str]) -> Vec<String> {
        n.iter().map(|s| s.to_string()).collect()
    }

    /// A one-column candidate inside the span of a three-column one is a
    /// pair (principal angle 0) though no single column of the other
    /// matches it; a column equal to the sum of two independent ones is a
    /// group of three that no pair shows.
    #[test]
    fn pairs_across_widths_and_groups_of_three() {
        let e = |i: usize| DVector::from_fn(6, |r, _| if r == i { 1.0 } else { 0.0 });
        let tcp = DMatrix::from_columns(&[e(0), e(1), e(2)]);
        let zero = DMatrix::from_columns(&[(e(0) + e(1)) * 0.5]);
        let a = DMatrix::from_columns(&[e(3)]);
        let b = DMatrix::from_columns(&[e(4)]);
        let ab = DMatrix::from_columns(&[e(3) * 2.0 - e(4)]);
        let sens = vec![zero, tcp, a, b, ab];
        let nm = names(&["zero", "tcp", "a", "b", "ab"]);
        let p = pairs(&sens, &nm);
        assert_eq!(p.len(), 1, "{p:?}");
        assert_eq!((p[0].a.as_str(), p[0].b.as_str()), ("zero", "tcp"));
        let g = groups(&sens, &nm, &p);
        assert_eq!(g.len(), 1, "{g:?}");
        assert_eq!(g[0].candidate, "ab");
        assert_eq!(g[0].of, vec!["a".to_string(), "b".to_string()]);
    }
}
