//! "What": forward selection over the candidate library.
//!
//! Each step refits the whole current candidate set (accepted effects plus
//! one candidate) by linear least squares on the training rows, for every
//! candidate. A candidate is accepted only when all of these agree:
//! - it is identifiable with the accepted effects (full rank);
//! - its nested F test against the accepted set, Holm-corrected over the
//!   candidates tested in the step, is below [`ALPHA`];
//! - its ΔBIC is below −[`BIC_MIN`];
//! - no other candidate explains the residual nearly as well: the runner-up's
//!   RSS exceeds the best one's by at least [`MARGIN_CHI2`] σ² (else the best
//!   one is reported "confounded with …", never claimed);
//! - the held-out rows' RMS drops by at least [`HOLDOUT_GAIN`].
//!
//! A bootstrap of the training rows (deterministic from the seed) gives each
//! candidate's inclusion frequency.

use nalgebra::{DMatrix, DVector};
use serde::Serialize;

use super::equations::Equations;
use crate::calibrate::lsq::{LsqOptions, Solution, solve_linear};
use crate::calibrate::stats::{self, SplitMix64};

/// Family-wise level of the F tests.
pub const ALPHA: f64 = 0.01;
/// Smallest BIC improvement (strong evidence on the Kass–Raftery scale).
pub const BIC_MIN: f64 = 10.0;
/// Smallest RSS margin of the best candidate over every other, in units of
/// the residual variance (a χ² value: 10 ≈ p 0.002 for one parameter).
pub const MARGIN_CHI2: f64 = 10.0;
/// Smallest relative drop of the held-out RMS.
pub const HOLDOUT_GAIN: f64 = 0.01;
/// Most effects accepted in one run.
pub const MAX_EFFECTS: usize = 4;
/// Candidates listed per step in the report.
pub const SHOW: usize = 6;

/// The evaluation of one candidate in one step.
#[derive(Debug, Clone, Serialize)]
pub struct Evaluation {
    /// Candidate index into the library.
    #[serde(skip)]
    pub index: usize,
    /// Candidate name.
    pub name: String,
    /// Training RSS with the candidate, µm².
    pub rss_um2: f64,
    /// F statistic against the accepted set.
    pub f: f64,
    /// Raw p-value of the F test.
    pub p: f64,
    /// Holm-adjusted p-value.
    pub p_holm: f64,
    /// BIC change against the accepted set.
    pub delta_bic: f64,
    /// Bootstrap inclusion frequency (0..1).
    pub bootstrap: f64,
}

/// Outcome of one step.
#[derive(Debug, Clone, Serialize)]
#[serde(tag = "outcome", rename_all = "snake_case")]
pub enum Outcome {
    /// The best candidate is accepted.
    Accepted {
        /// Its name.
        name: String,
    },
    /// The best candidate cannot be separated from others.
    Confounded {
        /// Best candidate.
        name: String,
        /// Candidates explaining the residual as well.
        with: Vec<String>,
    },
    /// The best candidate is significant on the training rows but does not
    /// improve the held-out rows (or there are no held-out rows).
    NotConfirmed {
        /// Its name.
        name: String,
    },
    /// No candidate passes the tests.
    NothingDetectable,
}

/// One forward-selection step.
#[derive(Debug, Clone, Serialize)]
pub struct Step {
    /// Training RSS of the accepted set, µm².
    pub rss_before_um2: f64,
    /// Candidates, best (lowest BIC) first.
    pub candidates: Vec<Evaluation>,
    /// Candidates that could not be fitted with the accepted set (rank
    /// deficient: no sensitivity in these rows or collinear with accepted).
    pub unidentifiable: Vec<String>,
    /// Margin of the best over the runner-up, σ² units.
    pub margin_chi2: f64,
    /// Held-out RMS before and with the best candidate, µm.
    pub holdout_rms_um: (f64, f64),
    /// Outcome.
    pub outcome: Outcome,
}

/// Data of a selection run (µm and µm per display unit).
pub struct Problem<'a> {
    /// Residual vector (measured − simulated) on the equations `eq`, µm.
    pub r: &'a DVector<f64>,
    /// Sensitivities per candidate, equations × parameters, µm per unit.
    pub s: &'a [DMatrix<f64>],
    /// The equations of each row.
    pub eq: &'a Equations,
    /// Candidate names.
    pub names: &'a [String],
    /// Training row indices.
    pub train: &'a [usize],
    /// Held-out row indices.
    pub holdout: &'a [usize],
    /// Bootstrap resamples.
    pub bootstrap: usize,
    /// Seed.
    pub seed: u64,
}

/// Result of the selection.
#[derive(Debug, Clone)]
pub struct Selection {
    /// Steps in order.
    pub steps: Vec<Step>,
    /// Accepted candidate indices, in order.
    pub accepted: Vec<usize>,
    /// Final fit on the training rows (accepted set), if any.
    pub fit: Option<Solution>,
}

/// The equations of rows `idx` of `m`, row after row.
fn take_rows(m: &DMatrix<f64>, eq: &Equations, idx: &[usize]) -> DMatrix<f64> {
    m.select_rows(eq.of(idx).iter())
}

fn take_vec(v: &DVector<f64>, eq: &Equations, idx: &[usize]) -> DVector<f64> {
    v.select_rows(eq.of(idx).iter())
}

/// Design matrix of a set of candidates.
pub fn design(s: &[DMatrix<f64>], set: &[usize], rows: usize) -> DMatrix<f64> {
    let k: usize = set.iter().map(|&c| s.get(c).map_or(0, |m| m.ncols())).sum();
    let mut out = DMatrix::zeros(rows, k);
    let mut col = 0;
    for &c in set {
        let Some(m) = s.get(c) else { continue };
        for j in 0..m.ncols() {
            for r in 0..rows.min(m.nrows()) {
                out[(r, col)] = m[(r, j)];
            }
            col += 1;
        }
    }
    out
}

/// Fits `set` to `r`; `None` when rank deficient or the solve fails.
fn fit(x: &DMatrix<f64>, r: &DVector<f64>) -> Option<Solution> {
    if x.ncols() == 0 {
        return None;
    }
    let sol = solve_linear(x, r, &LsqOptions::default()).ok()?;
    if sol.identifiability.unidentifiable.is_empty() {
        Some(sol)
    } else {
        None
    }
}

struct Scored {
    index: usize,
    rss: f64,
    k: usize,
    f: f64,
    p: f64,
    dbic: f64,
}

/// Scores every candidate against the accepted set on rows given by the
/// (already row-selected) residual and sensitivities.
fn score(
    r: &DVector<f64>,
    s: &[DMatrix<f64>],
    accepted: &[usize],
) -> (f64, Vec<Scored>, Vec<usize>) {
    let n = r.len();
    let p0: usize = accepted
        .iter()
        .map(|&c| s.get(c).map_or(0, |m| m.ncols()))
        .sum();
    let rss0 = if accepted.is_empty() {
        r.norm_squared()
    } else {
        fit(&design(s, accepted, n), r).map_or(r.norm_squared(), |f| f.rss)
    };
    let bic0 = stats::bic(rss0, n, p0).unwrap_or(f64::INFINITY);
    let mut out = Vec::new();
    let mut bad = Vec::new();
    for c in 0..s.len() {
        if accepted.contains(&c) {
            continue;
        }
        let mut set = accepted.to_vec();
        set.push(c);
        let x = design(s, &set, n);
        let Some(sol) = fit(&x, r) else {
            bad.push(c);
            continue;
        };
        let k = x.ncols();
        let ft = stats::f_test_nested(rss0, p0, sol.rss, k, n);
        let dbic = stats::bic(sol.rss, n, k).map_or(f64::INFINITY, |b| b - bic0);
        out.push(Scored {
            index: c,
            rss: sol.rss,
            k,
            f: ft.map_or(0.0, |t| t.f),
            p: ft.map_or(1.0, |t| t.p_value),
            dbic,
        });
    }
    out.sort_by(|a, b| a.dbic.total_cmp(&b.dbic));
    (rss0, out, bad)
}

/// Runs the forward selection.
pub fn select(pb: &Problem) -> Selection {
    let r_train = take_vec(pb.r, pb.eq, pb.train);
    let s_train: Vec<DMatrix<f64>> = pb.s.iter().map(|m| take_rows(m, pb.eq, pb.train)).collect();
    let r_hold = take_vec(pb.r, pb.eq, pb.holdout);
    let s_hold: Vec<DMatrix<f64>> =
        pb.s.iter()
            .map(|m| take_rows(m, pb.eq, pb.holdout))
            .collect();
    let n = r_train.len();
    let mut accepted: Vec<usize> = Vec::new();
    let mut steps = Vec::new();
    let mut rng = SplitMix64::new(pb.seed ^ 0x9e37_79b9_7f4a_7c15);
    for _ in 0..MAX_EFFECTS {
        let (rss0, scored, bad) = score(&r_train, &s_train, &accepted);
        let p_raw: Vec<f64> = scored.iter().map(|s| s.p).collect();
        let p_holm = stats::holm_bonferroni(&p_raw);
        // Bootstrap: which candidate would win on resampled training rows.
        let mut wins = vec![0usize; pb.s.len()];
        let m = pb.train.len();
        for _ in 0..pb.bootstrap {
            let idx: Vec<usize> = (0..m)
                .map(|_| pb.train[rng.below(m as u64) as usize])
                .collect();
            let rb = take_vec(pb.r, pb.eq, &idx);
            let sb: Vec<DMatrix<f64>> = pb.s.iter().map(|x| take_rows(x, pb.eq, &idx)).collect();
            let (_, sc, _) = score(&rb, &sb, &accepted);
            let ph = stats::holm_bonferroni(&sc.iter().map(|s| s.p).collect::<Vec<_>>());
            if let (Some(best), Some(p)) = (sc.first(), ph.first())
                && *p < ALPHA
                && best.dbic < -BIC_MIN
                && let Some(w) = wins.get_mut(best.index)
            {
                *w += 1;
            }
        }
        let freq = |c: usize| {
            if pb.bootstrap == 0 {
                0.0
            } else {
                wins.get(c).copied().unwrap_or(0) as f64 / pb.bootstrap as f64
            }
        };
        let name = |c: usize| pb.names.get(c).cloned().unwrap_or_default();
        let candidates: Vec<Evaluation> = scored
            .iter()
            .zip(&p_holm)
            .map(|(s, ph)| Evaluation {
                index: s.index,
                name: name(s.index),
                rss_um2: s.rss,
                f: s.f,
                p: s.p,
                p_holm: *ph,
                delta_bic: s.dbic,
                bootstrap: freq(s.index),
            })
            .collect();
        let unidentifiable = bad.iter().map(|&c| name(c)).collect();
        let hold_rms = |set: &[usize]| -> f64 {
            if r_hold.is_empty() {
                return 0.0;
            }
            let e = if set.is_empty() {
                r_hold.clone()
            } else {
                match fit(&design(&s_train, set, n), &r_train) {
                    Some(sol) => &r_hold - design(&s_hold, set, r_hold.len()) * &sol.params,
                    None => r_hold.clone(),
                }
            };
            (e.norm_squared() / pb.holdout.len() as f64).sqrt()
        };
        let Some(best) = scored.first() else {
            steps.push(Step {
                rss_before_um2: rss0,
                candidates,
                unidentifiable,
                margin_chi2: 0.0,
                holdout_rms_um: (hold_rms(&accepted), hold_rms(&accepted)),
                outcome: Outcome::NothingDetectable,
            });
            break;
        };
        let sigma2 = best.rss / (n.saturating_sub(best.k).max(1) as f64);
        let margins: Vec<(usize, f64)> = scored
            .iter()
            .skip(1)
            .map(|s| (s.index, (s.rss - best.rss) / sigma2))
            .collect();
        let margin = margins.iter().map(|m| m.1).fold(f64::INFINITY, f64::min);
        let mut with_set = accepted.clone();
        with_set.push(best.index);
        let holdout_rms_um = (hold_rms(&accepted), hold_rms(&with_set));
        let significant = p_holm.first().is_some_and(|p| *p < ALPHA) && best.dbic < -BIC_MIN;
        let outcome = if !significant {
            Outcome::NothingDetectable
        } else if margin < MARGIN_CHI2 {
            Outcome::Confounded {
                name: name(best.index),
                with: margins
                    .iter()
                    .filter(|m| m.1 < MARGIN_CHI2)
                    .map(|m| name(m.0))
                    .collect(),
            }
        } else if r_hold.is_empty() || holdout_rms_um.1 > holdout_rms_um.0 * (1.0 - HOLDOUT_GAIN) {
            Outcome::NotConfirmed {
                name: name(best.index),
            }
        } else {
            Outcome::Accepted {
                name: name(best.index),
            }
        };
        let accept = matches!(outcome, Outcome::Accepted { .. });
        steps.push(Step {
            rss_before_um2: rss0,
            candidates,
            unidentifiable,
            margin_chi2: if margin.is_finite() { margin } else { f64::MAX },
            holdout_rms_um,
            outcome,
        });
        if !accept {
            break;
        }
        accepted.push(best.index);
    }
    let fit_final = if accepted.is_empty() {
        None
    } else {
        fit(&design(&s_train, &accepted, n), &r_train)
    };
    Selection {
        steps,
        accepted,
        fit: fit_final,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    /// Fitted-parameter tolerance (the residual is exactly 2·a plus a
    /// pattern orthogonal to every column, so the fit is exact).
    const PARAM_TOL: f64 = 1e-9;

    /// Columns over 40 rows (120 values): `a` a ramp on the x slots, `b` a
    /// pattern on the y slots; the residual is 2·a plus ±0.5 on the z slots.
    fn data() -> (DVector<f64>, DMatrix<f64>, DMatrix<f64>) {
        let n = 120;
        let a = DMatrix::from_fn(n, 1, |i, _| if i % 3 == 0 { i as f64 / 3.0 } else { 0.0 });
        let b = DMatrix::from_fn(n, 1, |i, _| {
            (i % 3 == 1) as u8 as f64 * ((i / 3) % 5) as f64
        });
        // ±0.5 on the z slots only: orthogonal to `a` (x slots) and `b` (y slots).
        let noise = DVector::from_fn(n, |i, _| match (i % 3, (i / 3) % 2) {
            (2, 0) => 0.5,
            (2, _) => -0.5,
            _ => 0.0,
        });
        let r = a.column(0) * 2.0 + noise;
        (r, a, b)
    }

    fn problem<'a>(
        r: &'a DVector<f64>,
        s: &'a [DMatrix<f64>],
        eq: &'a Equations,
        names: &'a [String],
        train: &'a [usize],
        hold: &'a [usize],
    ) -> Problem<'a> {
        Problem {
            r,
            s,
            eq,
            names,
            train,
            holdout: hold,
            bootstrap: 5,
            seed: 1,
        }
    }

    /// `a` is accepted with parameter 2 (exact: the rest of the residual is
    /// orthogonal to it), then nothing more.
    #[test]
    fn accepts_the_true_column() {
        let (r, a, b) = data();
        let s = vec![a, b];
        let names = vec!["a".to_string(), "b".to_string()];
        let train: Vec<usize> = (0..40).filter(|i| i % 4 != 0).collect();
        let hold: Vec<usize> = (0..40).filter(|i| i % 4 == 0).collect();
        let sel = select(&problem(
            &r,
            &s,
            &Equations::positions_only(40),
            &names,
            &train,
            &hold,
        ));
        assert_eq!(sel.accepted, vec![0]);
        let fit = sel.fit.expect("fit");
        assert_abs_diff_eq!(fit.params[0], 2.0, epsilon = PARAM_TOL);
        assert!(matches!(
            sel.steps.last().map(|s| &s.outcome),
            Some(Outcome::NothingDetectable)
        ));
    }

    /// A copy of `a` under another name explains the residual identically:
    /// confounded, nothing accepted.
    #[test]
    fn duplicate_columns_are_confounded() {
        let (r, a, b) = data();
        let s = vec![a.clone(), b, a * -3.0];
        let names = vec!["a".to_string(), "b".to_string(), "a_copy".to_string()];
        let train: Vec<usize> = (0..40).filter(|i| i % 4 != 0).collect();
        let hold: Vec<usize> = (0..40).filter(|i| i % 4 == 0).collect();
        let sel = select(&problem(
            &r,
            &s,
            &Equations::positions_only(40),
            &names,
            &train,
            &hold,
        ));
        assert!(sel.accepted.is_empty());
        match sel.steps.last().map(|s| &s.outcome) {
            Some(Outcome::Confounded { name, with }) => {
                let mut all = with.clone();
                all.push(name.clone());
                all.sort();
                assert_eq!(all, vec!["a", "a_copy"]);
            }
            other => panic!("expected confounded, got {other:?}"),
        }
    }
}
