//! The result of a calibration run: identified parameters with standard and
//! expanded uncertainties, identifiability figures, the held-out validation
//! and the calibrated machine file text; printed as a plain-text table.

use std::fmt;

use super::honesty::{Rule, relative_uncertainty};
use super::lsq::{COVERAGE_K, Identifiability};

/// A scaled condition number (unit-norm columns) above this makes the data
/// set *badly conditioned*: a relative error of 10⁻⁴ in the data (a few µm
/// on a deflection of some tenths of a mm, or on a 1 m robot) could change a
/// parameter by 100 %. Such a run is refused (exit 2) instead of returning
/// confident nonsense.
pub const CONDITION_LIMIT: f64 = 1e4;

/// One identified (or fixed) parameter.
#[derive(Debug, Clone, PartialEq)]
pub struct Estimate {
    /// Name as listed in the report, e.g. `a2` or `k3`.
    pub name: String,
    /// Unit of `start`, `value` and `u`.
    pub unit: &'static str,
    /// Value in the machine file before the calibration.
    pub start: f64,
    /// Identified value (the start value when fixed).
    pub value: f64,
    /// Standard uncertainty (k = 1); `None` when fixed as unidentifiable or
    /// when the residual variance is unknown (no redundancy). A parameter
    /// kept at the file's value because its correction is not significant
    /// carries the uncertainty the full fit gives that correction.
    pub u: Option<f64>,
    /// True when the data cannot identify it: kept at the start value.
    pub fixed: bool,
}

/// Mean and maximum residual norm over the held-out rows (or pairs), mm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Validation {
    /// Number of held-out items.
    pub n: usize,
    /// Mean residual norm with the original machine file, mm.
    pub before_mean_mm: f64,
    /// Max residual norm with the original machine file, mm.
    pub before_max_mm: f64,
    /// Mean residual norm with the calibrated machine file, mm.
    pub after_mean_mm: f64,
    /// Max residual norm with the calibrated machine file, mm.
    pub after_max_mm: f64,
    /// RMS residual norm (per point) with the original machine file, mm.
    pub before_rms_mm: f64,
    /// RMS residual norm (per point) with the calibrated machine file, mm.
    pub after_rms_mm: f64,
}

impl Validation {
    /// Builds the summary from per-item residual norms (mm).
    pub fn from_norms(before: &[f64], after: &[f64]) -> Option<Validation> {
        if before.is_empty() || before.len() != after.len() {
            return None;
        }
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        let max = |v: &[f64]| v.iter().copied().fold(0.0, f64::max);
        let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
        Some(Validation {
            before_rms_mm: rms(before),
            after_rms_mm: rms(after),
            n: before.len(),
            before_mean_mm: mean(before),
            before_max_mm: max(before),
            after_mean_mm: mean(after),
            after_max_mm: max(after),
        })
    }
}

/// Everything a calibration run found.
#[derive(Debug, Clone)]
pub struct Calibration {
    /// `stiffness`, `kinematics`, `geometry` or `thermal`.
    pub kind: &'static str,
    /// Items (rows or load pairs) used for the fit.
    pub n_fit: usize,
    /// Residual equations of the fit (3 per item).
    pub n_equations: usize,
    /// Observability index O1 of the identification Jacobian (unscaled).
    pub observability_o1: f64,
    /// Condition number of the column-scaled Jacobian over the identified
    /// parameters.
    pub condition_number: f64,
    /// RMS of the fit residuals per coordinate, `√(RSS / degrees of freedom)`, mm.
    pub rms_fit_mm: f64,
    /// Parameters, in report order.
    pub params: Vec<Estimate>,
    /// Held-out validation; `None` when nothing was held out.
    pub validation: Option<Validation>,
    /// The same figures on the rows (items) of the fit.
    pub fit_check: Option<Validation>,
    /// The identified measurement frame (instrument data), if any.
    pub frame: Option<FrameEstimate>,
    /// Fixed parameters that the data could identify but whose correction
    /// is not significant on the fit rows (subset selection).
    pub insignificant: Vec<String>,
    /// Indices into `params` of the uncertain parameters
    /// ([`super::honesty`]); they keep the file's value in `yaml` unless
    /// `honesty.write_uncertain`.
    pub uncertain: Vec<usize>,
    /// The rule that judged them.
    pub honesty: Rule,
    /// Things the data does not support, said in words.
    pub notes: Vec<String>,
    /// The calibrated machine file (original text with edited values).
    pub yaml: String,
    /// The covariance of the written, identified values (`None`: the
    /// calibration kind records none, or the fit has no covariance).
    pub covariance: Option<FitCovariance>,
}

/// The covariance of the values a calibration identified and wrote, by the
/// key path of each in the machine file and in the units of those keys.
#[derive(Debug, Clone, PartialEq)]
pub struct FitCovariance {
    /// Key path of each value (`axes[X].component_errors.EXX_um.forward[3]`).
    pub parameters: Vec<String>,
    /// Their covariance, in the units of their keys.
    pub matrix: nalgebra::DMatrix<f64>,
}

impl FitCovariance {
    /// The covariance of the columns `cols` of a fit's covariance `cov`:
    /// each `(column, key path, factor)` with `factor` the key's units per
    /// unit of the column. `None` without a covariance or columns, or with
    /// a column outside `cov`.
    pub fn select(
        cov: Option<&nalgebra::DMatrix<f64>>,
        cols: &[(usize, String, f64)],
    ) -> Option<FitCovariance> {
        let cov = cov?;
        let n = cols.len();
        if n == 0
            || cols
                .iter()
                .any(|c| c.0 >= cov.nrows() || c.0 >= cov.ncols())
        {
            return None;
        }
        let matrix = nalgebra::DMatrix::from_fn(n, n, |i, j| {
            cols[i].2 * cols[j].2 * cov[(cols[i].0, cols[j].0)]
        });
        Some(FitCovariance {
            parameters: cols.iter().map(|c| c.1.clone()).collect(),
            matrix,
        })
    }
}

/// The identified transform of an instrument frame: the pose of the
/// instrument in the machine's reference frame, with standard uncertainties.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameEstimate {
    /// Origin of the instrument frame in the reference frame, mm.
    pub xyz_mm: [f64; 3],
    /// Its orientation as roll, pitch, yaw (fixed x, y, z), degrees.
    pub rpy_deg: [f64; 3],
    /// Standard uncertainty of `xyz_mm`, mm (`None` without redundancy).
    pub u_xyz_mm: Option<[f64; 3]>,
    /// Standard uncertainty of the orientation as small rotations about
    /// the reference frame's x, y, z axes, degrees.
    pub u_rot_deg: Option<[f64; 3]>,
}

impl fmt::Display for FrameEstimate {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let u = |v: Option<[f64; 3]>, k: usize| v.map_or("?".to_string(), |v| g(v[k]));
        writeln!(
            f,
            "measurement frame (instrument in the reference frame), value ± u (k=1):"
        )?;
        for (k, c) in ["x", "y", "z"].iter().enumerate() {
            writeln!(
                f,
                "  {c}: {:>14} ± {:>10} mm",
                format!("{:.4}", self.xyz_mm[k]),
                u(self.u_xyz_mm, k)
            )?;
        }
        for (k, c) in ["roll", "pitch", "yaw"].iter().enumerate() {
            writeln!(
                f,
                "  {c}: {:>11} ± {:>10} deg",
                format!("{:.6}", self.rpy_deg[k]),
                u(self.u_rot_deg, k)
            )?;
        }
        Ok(())
    }
}

/// The held-out validation and the fit check of a calibration, in that
/// order: `norms(calibrated, rows)` gives the residual norms of `rows`
/// under the input model (`false`) or the calibrated one (`true`).
pub fn validations(
    hold: &[usize],
    fit: &[usize],
    norms: impl Fn(bool, &[usize]) -> crate::error::Result<Vec<f64>>,
) -> crate::error::Result<(Option<Validation>, Option<Validation>)> {
    let before = norms(false, hold)?;
    let after = norms(true, hold)?;
    let fit_before = norms(false, fit)?;
    let fit_after = norms(true, fit)?;
    Ok((
        Validation::from_norms(&before, &after),
        Validation::from_norms(&fit_before, &fit_after),
    ))
}

/// Names of the parameters of `params` at the indices `idx`, in that order
/// (indices past the end are skipped).
pub fn names_at(params: &[Estimate], idx: &[usize]) -> Vec<String> {
    idx.iter()
        .filter_map(|&k| params.get(k).map(|p| p.name.clone()))
        .collect()
}

impl Calibration {
    /// True when the calibrated model predicts the held-out items worse
    /// (higher RMS per point) than the input model: such a model is not
    /// written unless forced.
    pub fn worse_on_holdout(&self) -> bool {
        self.validation
            .is_some_and(|v| v.after_rms_mm > v.before_rms_mm)
    }

    /// The report made final: O1 and the condition number filled from `id`
    /// ([`Calibration::set_identifiability`]) and the held-out verdict
    /// checked ([`Calibration::check_validation`]).
    pub fn finished(mut self, id: &Identifiability) -> Calibration {
        self.set_identifiability(id);
        self.check_validation();
        self
    }

    /// Fills O1 and the condition number from an identifiability report.
    pub fn set_identifiability(&mut self, id: &Identifiability) {
        self.observability_o1 = id.observability_o1;
        self.condition_number = id.condition_number_identified;
    }

    /// Adds a loud note (and a warning) when the calibrated file predicts
    /// the held-out items worse than the original *and* not at the noise
    /// level of the fit (mean norm above 1.5 × 1.6 × the fit RMS per
    /// coordinate; 1.6 σ is the mean norm of 3-D noise): the model or its
    /// conventions do not fit the data, the result must not be used. (When
    /// the original file is already right, the calibrated one is slightly
    /// worse by its estimation noise; that is not flagged.)
    pub fn check_validation(&mut self) {
        if let Some(v) = self.validation {
            if v.after_mean_mm > v.before_mean_mm && v.after_mean_mm > 2.4 * self.rms_fit_mm {
                let msg = format!(
                    "WORSE after calibration on the held-out items (mean {:.4} → {:.4} mm): \
                     the model does not fit these data; do not use the calibrated file",
                    v.before_mean_mm, v.after_mean_mm
                );
                tracing::warn!("{msg}");
                self.notes.push(msg);
            }
        }
    }

    /// Names of the fixed (unidentifiable) parameters.
    pub fn fixed(&self) -> Vec<&str> {
        self.params
            .iter()
            .filter(|p| p.fixed && !self.insignificant.contains(&p.name))
            .map(|p| p.name.as_str())
            .collect()
    }
}

impl Calibration {
    /// The list of uncertain parameters: value ± U, the judged ratio and
    /// what was written.
    fn fmt_uncertain(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.uncertain.is_empty() {
            return Ok(());
        }
        // The threshold in per cent, without trailing zeros (50, 12.5).
        let pct = format!("{:.3}", 100.0 * self.honesty.max_relative);
        let limit = pct.trim_end_matches('0').trim_end_matches('.');
        if self.honesty.write_uncertain {
            writeln!(
                f,
                "uncertain (U(k=2) above {limit} % of max(|value|, |change|)), written because \
                 of --write-uncertain:"
            )?;
        } else {
            writeln!(
                f,
                "uncertain (U(k=2) above {limit} % of max(|value|, |change|)), NOT written \
                 (the file's value is kept; --write-uncertain writes them):"
            )?;
        }
        for p in self.uncertain.iter().filter_map(|&i| self.params.get(i)) {
            let big_u = p.u.map_or("?".to_string(), |u| g(COVERAGE_K * u));
            let ratio =
                relative_uncertainty(p).map_or("?".to_string(), |r| format!("{:.1} %", 100.0 * r));
            write!(
                f,
                "  {}: {} ± {} {} ({ratio})",
                p.name,
                g(p.value),
                big_u,
                p.unit
            )?;
            if self.honesty.write_uncertain {
                writeln!(f)?;
            } else {
                writeln!(f, ", kept {}", g(p.start))?;
            }
        }
        Ok(())
    }
}

/// About seven significant digits, fixed point where that reads well.
fn g(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 {
        "0".into()
    } else if a >= 1e3 {
        format!("{v:.1}")
    } else if a >= 100.0 {
        format!("{v:.4}")
    } else if a >= 10.0 {
        format!("{v:.5}")
    } else if a >= 1e-3 {
        format!("{v:.6}")
    } else {
        format!("{v:.3e}")
    }
}

impl fmt::Display for Calibration {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "calibrate {}: {} items ({} equations), O1 = {}, condition number = {:.1}, fit RMS = {:.4} mm",
            self.kind,
            self.n_fit,
            self.n_equations,
            g(self.observability_o1),
            self.condition_number,
            self.rms_fit_mm
        )?;
        writeln!(
            f,
            "{:<18} {:>14} {:>14} {:>12} {:>12} {:>8}  unit",
            "parameter", "start", "identified", "u (k=1)", "U (k=2)", "U/|v| %"
        )?;
        for p in &self.params {
            let (u, uu, rel) = match (p.fixed, p.u) {
                (true, Some(u)) => (g(u), g(COVERAGE_K * u), "kept".to_string()),
                (true, None) => ("fixed".to_string(), "-".to_string(), "-".to_string()),
                (false, Some(u)) => {
                    let rel = if p.value != 0.0 {
                        format!("{:.2}", 100.0 * COVERAGE_K * u / p.value.abs())
                    } else {
                        "-".into()
                    };
                    (g(u), g(COVERAGE_K * u), rel)
                }
                (false, None) => ("?".into(), "?".into(), "-".into()),
            };
            writeln!(
                f,
                "{:<18} {:>14} {:>14} {:>12} {:>12} {:>8}  {}",
                p.name,
                g(p.start),
                g(p.value),
                u,
                uu,
                rel,
                p.unit
            )?;
        }
        let fixed = self.fixed();
        if !fixed.is_empty() {
            writeln!(
                f,
                "not identifiable from these data (kept at the file's value): {}",
                fixed.join(", ")
            )?;
        }
        self.fmt_uncertain(f)?;
        match &self.validation {
            Some(v) => writeln!(
                f,
                "held-out validation ({} items): mean {:.4} mm, max {:.4} mm before; mean {:.4} mm, max {:.4} mm after",
                v.n, v.before_mean_mm, v.before_max_mm, v.after_mean_mm, v.after_max_mm
            )?,
            None => writeln!(f, "held-out validation: none (--holdout 0)")?,
        }
        let per_point = |f: &mut fmt::Formatter<'_>, what: &str, v: &Validation| {
            writeln!(
                f,
                "per point, {what} ({}): RMS {:.4} mm, max {:.4} mm before; RMS {:.4} mm, max {:.4} mm after",
                v.n, v.before_rms_mm, v.before_max_mm, v.after_rms_mm, v.after_max_mm
            )
        };
        if let Some(v) = &self.fit_check {
            per_point(f, "fit", v)?;
        }
        if let Some(v) = &self.validation {
            per_point(f, "held-out", v)?;
        }
        if let Some(fr) = &self.frame {
            write!(f, "{fr}")?;
        }
        for n in &self.notes {
            writeln!(f, "note: {n}")?;
        }
        Ok(())
    }
}
