//! K-fold cross-validation of a calibration that holds nothing out
//! (`--holdout 0`): every row is predicted by a model fitted without it.
//!
//! The rows are grouped by pose (repeats of one pose, and the loaded and
//! unloaded rows of a stiffness group, are one group:
//! [`super::screen::pose_groups`]); the groups are dealt to [`FOLDS`] folds
//! in a seeded random order (fewer groups: one fold per group,
//! leave-one-pose-out). For each fold the calibration is run on the other
//! folds' rows and the written model predicts the fold's rows; the RMS per
//! point of all rows so predicted is compared with the input model's on
//! the same rows. Stiffness compares residuals centred per pose group (the
//! unknown unloaded position of a group cancels, as in its fit). The model
//! is worse when the mean of the rows' `|e_after|² − |e_before|²` exceeds
//! [`WORSE_SE`] standard errors of those paired differences.

use nalgebra::Vector3;

use super::forward;
use super::observations::{MeasurementFrame, Observations};
use super::report::Calibration;
use super::stats::SplitMix64;
use crate::error::Result;
use crate::machine::Machine;

/// Folds of the cross-validation.
pub const FOLDS: usize = 5;

/// The cross-validated figures.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CrossValidation {
    /// Folds run.
    pub folds: usize,
    /// Rows predicted (every row of the folds whose calibration ran).
    pub rows: usize,
    /// RMS per point of the input model on those rows, mm.
    pub before_rms_mm: f64,
    /// RMS per point of the fold models on the rows they did not fit, mm.
    pub after_rms_mm: f64,
    /// Mean over the rows of `|e_after|² − |e_before|²`, mm².
    pub mean_increase_mm2: f64,
    /// Its standard error (the rows' paired differences), mm².
    pub se_increase_mm2: f64,
}

/// Standard errors by which the mean squared error of the fold models must
/// exceed the input model's for the calibration to count as worse: a
/// smaller difference is within what the rows' own scatter gives.
pub const WORSE_SE: f64 = 2.0;

impl CrossValidation {
    /// True when the calibrated models predict the rows they did not fit
    /// worse than the input model, by more than [`WORSE_SE`] standard
    /// errors of the paired difference of squared errors.
    pub fn worse(&self) -> bool {
        self.mean_increase_mm2 > WORSE_SE * self.se_increase_mm2
    }
}

/// Mean and standard error of `a_i² − b_i²`.
fn paired(after: &[Vector3<f64>], before: &[Vector3<f64>]) -> (f64, f64) {
    let d: Vec<f64> = after
        .iter()
        .zip(before)
        .map(|(a, b)| a.norm_squared() - b.norm_squared())
        .collect();
    let n = d.len() as f64;
    if d.len() < 2 {
        return (d.first().copied().unwrap_or(0.0), f64::INFINITY);
    }
    let mean = d.iter().sum::<f64>() / n;
    let var = d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}

/// The position errors of `m` on the rows `idx` of `obs`, mm.
fn errors(m: &Machine, obs: &Observations, idx: &[usize], file: &str) -> Result<Vec<Vector3<f64>>> {
    idx.iter()
        .filter_map(|&i| obs.rows.get(i))
        .map(|r| forward::predict(m, r, file).map(|p| r.measured_mm - p.measured(obs.measured)))
        .collect()
}

/// Errors centred per pose group (`group[k]` of `idx[k]`).
fn centred(e: &mut [Vector3<f64>], group: &[usize]) {
    let mut groups: Vec<usize> = group.to_vec();
    groups.sort_unstable();
    groups.dedup();
    for g in groups {
        let members: Vec<usize> = (0..e.len()).filter(|&k| group[k] == g).collect();
        let mean = members.iter().map(|&k| e[k]).sum::<Vector3<f64>>() / members.len() as f64;
        for k in members {
            e[k] -= mean;
        }
    }
}

/// Rows with the same joints and measured point (a stiffness group:
/// the configuration, whatever the load), group of every row and count.
fn configuration_groups(obs: &Observations) -> (Vec<usize>, usize) {
    let mut keys: Vec<Vec<u64>> = Vec::new();
    let mut of_row = Vec::with_capacity(obs.rows.len());
    for r in &obs.rows {
        let mut k = Vec::new();
        if let super::observations::Pose::Robot(p) = &r.pose {
            k.extend(p.q_deg.iter().map(|v| v.to_bits()));
            if let Some(mp) = p.mp_mm {
                k.extend(mp.iter().map(|v| v.to_bits()));
            }
        }
        let g = match keys.iter().position(|x| *x == k) {
            Some(g) => g,
            None => {
                keys.push(k);
                keys.len() - 1
            }
        };
        of_row.push(g);
    }
    (of_row, keys.len())
}

fn rms(e: &[Vector3<f64>]) -> f64 {
    if e.is_empty() {
        return 0.0;
    }
    (e.iter().map(|v| v.norm_squared()).sum::<f64>() / e.len() as f64).sqrt()
}

/// Cross-validates `fit` (a calibration of the observations it is given,
/// holding nothing out) on `obs` against the input machine `text`;
/// `centre`: compare residuals centred per pose group (stiffness). `None`
/// when it cannot be judged: fewer than two pose groups, instrument-frame
/// data (each fold identifies its own frame), or a fold whose calibration
/// fails (too few rows for it) — the reason is returned then.
pub fn cross_validate(
    text: &str,
    obs: &Observations,
    file: &str,
    seed: u64,
    centre: bool,
    fit: impl Fn(&Observations) -> Result<Calibration>,
) -> std::result::Result<CrossValidation, String> {
    if obs.frame == MeasurementFrame::Instrument {
        return Err("instrument-frame data: each fold would identify its own frame".into());
    }
    let input = Machine::from_yaml_str(text, file).map_err(|e| e.to_string())?;
    let reference = super::frame::world_to_reference(&input, obs);
    let (of_row, n_groups) = if centre {
        configuration_groups(obs)
    } else {
        super::screen::pose_groups(obs)
    };
    if n_groups < 2 {
        return Err(format!("{n_groups} distinct pose(s)"));
    }
    let folds = FOLDS.min(n_groups);
    let mut order: Vec<usize> = (0..n_groups).collect();
    let mut rng = SplitMix64::new(seed ^ 0x6b_f01d);
    for i in (1..order.len()).rev() {
        let j = (rng.next_f64() * (i + 1) as f64) as usize;
        order.swap(i, j.min(i));
    }
    let mut fold_of_group = vec![0; n_groups];
    for (k, g) in order.iter().enumerate() {
        fold_of_group[*g] = k % folds;
    }
    let (mut before, mut after) = (Vec::new(), Vec::new());
    for f in 0..folds {
        let (test, train): (Vec<usize>, Vec<usize>) =
            (0..obs.rows.len()).partition(|&i| fold_of_group[of_row[i]] == f);
        let mut sub = obs.clone();
        sub.rows = train
            .iter()
            .filter_map(|&i| obs.rows.get(i).cloned())
            .collect();
        let cal = fit(&sub).map_err(|e| format!("fold {} of {folds}: {e}", f + 1))?;
        let model = Machine::from_yaml_str(&cal.yaml, file).map_err(|e| e.to_string())?;
        let mut eb = errors(&input, &reference, &test, file).map_err(|e| e.to_string())?;
        let mut ea = errors(&model, &reference, &test, file).map_err(|e| e.to_string())?;
        if centre {
            let g: Vec<usize> = test.iter().map(|&i| of_row[i]).collect();
            centred(&mut eb, &g);
            centred(&mut ea, &g);
        }
        before.extend(eb);
        after.extend(ea);
    }
    let (mean_increase_mm2, se_increase_mm2) = paired(&after, &before);
    Ok(CrossValidation {
        folds,
        rows: before.len(),
        before_rms_mm: rms(&before),
        after_rms_mm: rms(&after),
        mean_increase_mm2,
        se_increase_mm2,
    })
}
