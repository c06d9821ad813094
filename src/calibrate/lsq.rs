//! Least-squares identification: linear least squares and Levenberg–Marquardt
//! with parameter covariance, standard and expanded uncertainties, and an
//! identifiability report (singular values, condition number, observability
//! index O1 of docs/physics.md, and the parameters that cannot be identified).
//!
//! Conventions:
//! - Residuals are `r = A x − b` (linear) or `r = f(x)` (nonlinear); the
//!   objective is `‖r‖²` (RSS).
//! - Residual variance `σ² = RSS / (m − r)` with `r` the number of identified
//!   parameters; covariance `σ² (AᵀA)⁻¹` over the identified parameters.
//! - Rank deficiency is found by column-pivoted Gram–Schmidt (a rank-revealing
//!   QR) on the column-scaled design: a parameter whose column, after removing
//!   the part explained by the already chosen columns, keeps less than
//!   [`RANK_RTOL`] of the largest column norm is *unidentifiable*. It is fixed
//!   at 0 (the nominal value when the unknowns are corrections), gets zero
//!   variance, and is listed so the caller can report it.

use nalgebra::{DMatrix, DVector};

/// Default relative threshold of the rank decision: a pivot (remaining column
/// norm of the unit-norm-scaled design) below `RANK_RTOL` times the largest one
/// marks the column unidentifiable. `1e-8 ≈ √ε`: such a parameter would have
/// its uncertainty amplified by more than 10⁸ relative to the best one.
pub const RANK_RTOL: f64 = 1e-8;

/// Coverage factor of the expanded uncertainty (≈ 95 % for a normal distribution).
pub const COVERAGE_K: f64 = 2.0;

/// Iteration limit of the singular value decomposition.
const SVD_MAX_ITER: usize = 10_000;

/// Why a least-squares problem could not be solved.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LsqError {
    /// The design matrix and the right-hand side do not fit together, or are empty.
    #[error("least squares: bad shape: {0}")]
    Shape(String),
    /// An input (design, observations, start point, Jacobian) is NaN or infinite.
    #[error("least squares: non-finite value in {0}")]
    NonFinite(&'static str),
    /// The singular value decomposition did not converge.
    #[error("least squares: singular value decomposition did not converge")]
    Svd,
}

/// Options shared by the linear and nonlinear solvers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LsqOptions {
    /// Scale every column to unit norm before the rank decision and the
    /// solve (makes the result independent of parameter units). Default true.
    pub scale_columns: bool,
    /// Relative rank threshold, see [`RANK_RTOL`].
    pub rank_rtol: f64,
}

impl Default for LsqOptions {
    fn default() -> Self {
        LsqOptions {
            scale_columns: true,
            rank_rtol: RANK_RTOL,
        }
    }
}

/// How well the parameters are determined by the design (or Jacobian).
#[derive(Debug, Clone, PartialEq)]
pub struct Identifiability {
    /// Singular values of the design as solved (column-scaled when
    /// [`LsqOptions::scale_columns`]), descending; `min(m, n)` of them.
    pub singular_values: DVector<f64>,
    /// `σ_max / σ_min` of the design as solved over all `n` columns
    /// (infinite when rank deficient or `m < n`).
    pub condition_number: f64,
    /// Condition number over the identified columns only.
    pub condition_number_identified: f64,
    /// Observability index `O1 = (σ_1 ⋯ σ_n)^(1/n) / √m` of the *unscaled*
    /// design (Paper A eq. 5), computed through logarithms; 0 when rank
    /// deficient or `m < n`.
    pub observability_o1: f64,
    /// Number of identified parameters.
    pub rank: usize,
    /// Indices of the identified parameters, ascending.
    pub identifiable: Vec<usize>,
    /// Indices of the parameters that cannot be identified, ascending; they
    /// are fixed at 0 (nominal).
    pub unidentifiable: Vec<usize>,
}

/// A least-squares solution with its uncertainty.
#[derive(Debug, Clone, PartialEq)]
pub struct Solution {
    /// Estimated parameters (unidentifiable ones are 0).
    pub params: DVector<f64>,
    /// Residuals at the solution (`A x − b`, or `f(x)`).
    pub residuals: DVector<f64>,
    /// Residual sum of squares `‖r‖²`.
    pub rss: f64,
    /// Degrees of freedom `m − rank`.
    pub dof: usize,
    /// Residual variance `RSS / dof`; `None` when `dof = 0`.
    pub sigma2: Option<f64>,
    /// Parameter covariance `σ² (AᵀA)⁻¹` (zero rows/columns for unidentifiable
    /// parameters); `None` when `dof = 0`.
    pub covariance: Option<DMatrix<f64>>,
    /// Identifiability report of the design at the solution.
    pub identifiability: Identifiability,
}

impl Solution {
    /// RMS per coordinate of a fit of `m` equations, mm: `√σ²` when the fit
    /// has redundancy, else `√(RSS / m)`.
    pub fn rms_fit(&self, m: usize) -> f64 {
        self.sigma2.map_or((self.rss / m as f64).sqrt(), f64::sqrt)
    }

    /// Standard uncertainties `√diag(cov)`; `None` when there is no covariance.
    pub fn std_uncertainty(&self) -> Option<DVector<f64>> {
        self.covariance.as_ref().map(|c| {
            DVector::from_iterator(c.nrows(), c.diagonal().iter().map(|v| v.max(0.0).sqrt()))
        })
    }

    /// Expanded uncertainties `k · u` (use [`COVERAGE_K`] for k = 2).
    pub fn expanded_uncertainty(&self, k: f64) -> Option<DVector<f64>> {
        self.std_uncertainty().map(|u| u * k)
    }
}

/// Internal decomposition of a (column-scaled, column-selected) design.
struct Decomposition {
    /// Column scale factors (multiply a scaled-problem parameter by it).
    scale: Vec<f64>,
    /// Identified columns.
    selected: Vec<usize>,
    /// SVD of the scaled, selected design: U (m × r), σ (r), V (r × r).
    u: DMatrix<f64>,
    sv: DVector<f64>,
    v: DMatrix<f64>,
    ident: Identifiability,
}

fn svd_values(a: &DMatrix<f64>) -> Result<DVector<f64>, LsqError> {
    if a.ncols() == 0 || a.nrows() == 0 {
        return Ok(DVector::zeros(0));
    }
    let svd = a
        .clone()
        .try_svd(false, false, f64::EPSILON, SVD_MAX_ITER)
        .ok_or(LsqError::Svd)?;
    let mut v: Vec<f64> = svd.singular_values.iter().copied().collect();
    v.sort_by(|a, b| b.total_cmp(a));
    Ok(DVector::from_vec(v))
}

fn condition(sv: &DVector<f64>, n: usize) -> f64 {
    if sv.is_empty() || sv.len() < n {
        return f64::INFINITY;
    }
    let max = sv.iter().copied().fold(0.0, f64::max);
    let min = sv.iter().copied().fold(f64::INFINITY, f64::min);
    if min <= 0.0 { f64::INFINITY } else { max / min }
}

/// Observability index O1 through logarithms (no overflow of the product).
fn observability(sv: &DVector<f64>, n: usize, m: usize) -> f64 {
    if n == 0 || m == 0 || sv.len() < n || sv.iter().any(|&s| s <= 0.0) {
        return 0.0;
    }
    let mean_log = sv.iter().map(|s| s.ln()).sum::<f64>() / n as f64;
    mean_log.exp() / (m as f64).sqrt()
}

/// Column-pivoted modified Gram–Schmidt: returns the chosen columns in
/// ascending order. Ties pick the lowest index.
fn select_columns(a: &DMatrix<f64>, rtol: f64) -> Vec<usize> {
    let (m, n) = a.shape();
    let mut w = a.clone();
    let reference = (0..n).map(|j| w.column(j).norm()).fold(0.0, f64::max);
    let mut remaining: Vec<usize> = (0..n).collect();
    let mut chosen = Vec::new();
    if reference <= 0.0 {
        return chosen;
    }
    for _ in 0..n.min(m) {
        let mut best: Option<(usize, f64)> = None;
        for (pos, &j) in remaining.iter().enumerate() {
            let norm = w.column(j).norm();
            if best.is_none_or(|(_, b)| norm > b) {
                best = Some((pos, norm));
            }
        }
        let Some((pos, norm)) = best else { break };
        if norm <= rtol * reference {
            break;
        }
        let j = remaining.remove(pos);
        let q = w.column(j) / norm;
        for &k in &remaining {
            // Twice is enough (Kahan–Parlett re-orthogonalization).
            for _ in 0..2 {
                let proj = q.dot(&w.column(k));
                let mut col = w.column_mut(k);
                col.axpy(-proj, &q, 1.0);
            }
        }
        chosen.push(j);
    }
    chosen.sort_unstable();
    chosen
}

fn decompose(a: &DMatrix<f64>, opts: &LsqOptions) -> Result<Decomposition, LsqError> {
    let (m, n) = a.shape();
    let scale: Vec<f64> = (0..n)
        .map(|j| {
            let norm = a.column(j).norm();
            if opts.scale_columns && norm > 0.0 {
                1.0 / norm
            } else {
                1.0
            }
        })
        .collect();
    let mut scaled = a.clone();
    for (j, s) in scale.iter().enumerate() {
        scaled.column_mut(j).scale_mut(*s);
    }
    let full_sv = svd_values(&scaled)?;
    let raw_sv = if opts.scale_columns {
        svd_values(a)?
    } else {
        full_sv.clone()
    };
    let selected = select_columns(&scaled, opts.rank_rtol);
    let reduced = scaled.select_columns(selected.iter());
    let r = selected.len();
    let (u, sv, v) = if r == 0 {
        (
            DMatrix::zeros(m, 0),
            DVector::zeros(0),
            DMatrix::zeros(0, 0),
        )
    } else {
        let svd = reduced
            .try_svd(true, true, f64::EPSILON, SVD_MAX_ITER)
            .ok_or(LsqError::Svd)?;
        let u = svd.u.ok_or(LsqError::Svd)?;
        let v = svd.v_t.ok_or(LsqError::Svd)?.transpose();
        (u, svd.singular_values, v)
    };
    let unidentifiable: Vec<usize> = (0..n).filter(|j| !selected.contains(j)).collect();
    let ident = Identifiability {
        condition_number: condition(&full_sv, n),
        condition_number_identified: condition(&sv, r),
        observability_o1: if r < n {
            0.0
        } else {
            observability(&raw_sv, n, m)
        },
        singular_values: full_sv,
        rank: r,
        identifiable: selected.clone(),
        unidentifiable,
    };
    Ok(Decomposition {
        scale,
        selected,
        u,
        sv,
        v,
        ident,
    })
}

impl Decomposition {
    /// Minimum-norm solution of `A x ≈ b` over the identified columns.
    fn solve(&self, b: &DVector<f64>, n: usize) -> DVector<f64> {
        let mut x = DVector::zeros(n);
        let utb = self.u.tr_mul(b);
        let mut y = DVector::zeros(self.sv.len());
        for k in 0..self.sv.len() {
            if self.sv[k] > 0.0 {
                y[k] = utb[k] / self.sv[k];
            }
        }
        let z = &self.v * y;
        for (k, &j) in self.selected.iter().enumerate() {
            x[j] = self.scale[j] * z[k];
        }
        x
    }

    /// `σ² D V Σ⁻² Vᵀ D` embedded in an n × n matrix.
    fn covariance(&self, sigma2: f64, n: usize) -> DMatrix<f64> {
        let r = self.sv.len();
        let mut vs = self.v.clone();
        for k in 0..r {
            let s = self.sv[k];
            let inv = if s > 0.0 { 1.0 / s } else { 0.0 };
            vs.column_mut(k).scale_mut(inv);
        }
        let cy = &vs * vs.transpose();
        let mut cov = DMatrix::zeros(n, n);
        for (a, &i) in self.selected.iter().enumerate() {
            for (b, &j) in self.selected.iter().enumerate() {
                cov[(i, j)] = sigma2 * self.scale[i] * self.scale[j] * cy[(a, b)];
            }
        }
        cov
    }
}

fn finish(
    a: &DMatrix<f64>,
    dec: Decomposition,
    params: DVector<f64>,
    residuals: DVector<f64>,
) -> Solution {
    let (m, n) = a.shape();
    let rss = residuals.norm_squared();
    let dof = m.saturating_sub(dec.ident.rank);
    let sigma2 = (dof > 0).then(|| rss / dof as f64);
    let covariance = sigma2.map(|s2| dec.covariance(s2, n));
    Solution {
        params,
        residuals,
        rss,
        dof,
        sigma2,
        covariance,
        identifiability: dec.ident,
    }
}

/// A fit the observations of `obs_file` cannot give (too few rows, an
/// ill-conditioned or rank-deficient design, points that do not span the
/// space): [`crate::error::Error::Data`] naming the file.
pub fn data_error(obs_file: &str, e: impl std::fmt::Display) -> crate::error::Error {
    crate::error::Error::Data(format!("{obs_file}: {e}"))
}

/// [`solve_linear`] on the observations of `obs_file`; a failure is a
/// problem with the data ([`data_error`]).
pub fn solve_for(
    a: &DMatrix<f64>,
    b: &DVector<f64>,
    opts: &LsqOptions,
    obs_file: &str,
) -> crate::error::Result<Solution> {
    solve_linear(a, b, opts).map_err(|e| data_error(obs_file, e))
}

/// Solves `min ‖A x − b‖` with covariance and identifiability report.
/// Unidentifiable parameters (see the module doc) are fixed at 0.
pub fn solve_linear(
    a: &DMatrix<f64>,
    b: &DVector<f64>,
    opts: &LsqOptions,
) -> Result<Solution, LsqError> {
    let (m, n) = a.shape();
    if m == 0 || n == 0 {
        return Err(LsqError::Shape(format!("design matrix is {m}×{n}")));
    }
    if b.len() != m {
        return Err(LsqError::Shape(format!(
            "design matrix has {m} rows but the observation vector has {}",
            b.len()
        )));
    }
    if a.iter().any(|v| !v.is_finite()) {
        return Err(LsqError::NonFinite("design matrix"));
    }
    if b.iter().any(|v| !v.is_finite()) {
        return Err(LsqError::NonFinite("observation vector"));
    }
    let dec = decompose(a, opts)?;
    let x = dec.solve(b, n);
    let residuals = a * &x - b;
    Ok(finish(a, dec, x, residuals))
}

/// Why Levenberg–Marquardt stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Termination {
    /// The residuals are exactly zero.
    ZeroResidual,
    /// Every gradient component is orthogonal to the residual within `gtol`.
    SmallGradient,
    /// Actual and predicted relative reductions of the RSS are below `ftol`.
    SmallReduction,
    /// The step is below `xtol` relative to the parameters.
    SmallStep,
    /// The iteration limit was reached (not converged).
    MaxIterations,
}

impl Termination {
    /// Whether this termination counts as convergence.
    pub fn converged(self) -> bool {
        !matches!(self, Termination::MaxIterations)
    }
}

/// Levenberg–Marquardt options.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LmOptions {
    /// Maximum number of iterations (Jacobian evaluations). Default 200.
    pub max_iterations: usize,
    /// Relative RSS reduction tolerance (actual and predicted). Default 1e-14.
    pub ftol: f64,
    /// Relative step tolerance `‖δ‖ ≤ xtol (‖x‖ + xtol)`. Default 1e-12.
    pub xtol: f64,
    /// Tolerance on the largest cosine between a Jacobian column and the
    /// residual vector. Default 1e-12.
    pub gtol: f64,
    /// Initial damping relative to the largest diagonal of `JᵀJ` (τ of
    /// Nielsen's strategy). Default 1e-3.
    pub initial_damping: f64,
    /// Relative step of the central-difference Jacobian,
    /// `h_j = step · max(|x_j|, 1)`. Default `ε^(1/3) ≈ 6.06e-6`.
    pub fd_relative_step: f64,
    /// Options of the covariance and identifiability analysis at the solution.
    pub lsq: LsqOptions,
}

impl Default for LmOptions {
    fn default() -> Self {
        LmOptions {
            max_iterations: 200,
            ftol: 1e-14,
            xtol: 1e-12,
            gtol: 1e-12,
            initial_damping: 1e-3,
            fd_relative_step: f64::EPSILON.cbrt(),
            lsq: LsqOptions::default(),
        }
    }
}

/// Result of [`levenberg_marquardt`].
#[derive(Debug, Clone, PartialEq)]
pub struct LmFit {
    /// Parameters, residuals, RSS, covariance and identifiability at the end point.
    pub solution: Solution,
    /// Iterations done (Jacobian evaluations in the loop).
    pub iterations: usize,
    /// Why the iteration stopped.
    pub termination: Termination,
}

/// Central-difference Jacobian of `f: Rⁿ → Rᵐ` at `x`, with
/// Forward-difference Jacobian columns of `residuals` for the parameters
/// `free` of the full vector `full` (step `step`), written into `jac`
/// column by column; `r` holds the residuals at `full`. Half the cost of
/// central differences, for models smooth on the scale of `step`.
pub fn forward_jacobian_free<F>(
    mut residuals: F,
    full: &[f64],
    free: &[usize],
    r: &DVector<f64>,
    step: f64,
    jac: &mut DMatrix<f64>,
) where
    F: FnMut(&[f64], &mut DVector<f64>),
{
    let mut xp = full.to_vec();
    let mut rp = DVector::zeros(r.len());
    for (a, &k) in free.iter().enumerate() {
        if let Some(v) = xp.get_mut(k) {
            *v += step;
        }
        residuals(&xp, &mut rp);
        if let Some(v) = xp.get_mut(k) {
            *v -= step;
        }
        jac.set_column(a, &((&rp - r) / step));
    }
}

/// The full parameter vector of `n` entries with the values `x` of the free
/// parameters `free` in place and zeros (the file's values) elsewhere.
pub fn expand_free(n: usize, free: &[usize], x: &[f64]) -> Vec<f64> {
    let mut full = vec![0.0; n];
    for (&k, &v) in free.iter().zip(x) {
        if let Some(f) = full.get_mut(k) {
            *f = v;
        }
    }
    full
}

/// Levenberg–Marquardt over the parameters `free` of a model of `n`
/// parameters (the others stay zero), from zero, with `m` residuals written
/// by `residuals(full, r)` and forward-difference Jacobian columns of step
/// `step` ([`forward_jacobian_free`]). Logs the iteration count and warns
/// when the iteration stopped without converging.
pub fn fit_free<F>(
    mut residuals: F,
    n: usize,
    free: &[usize],
    m: usize,
    step: f64,
    opts: &LmOptions,
) -> Result<LmFit, LsqError>
where
    F: FnMut(&[f64], &mut DVector<f64>),
{
    let fit = levenberg_marquardt(
        |xr, r, jac| {
            let full = expand_free(n, free, xr.as_slice());
            residuals(&full, r);
            let Some(jac) = jac else { return false };
            forward_jacobian_free(&mut residuals, &full, free, r, step, jac);
            true
        },
        &DVector::zeros(free.len()),
        m,
        opts,
    )?;
    tracing::info!(
        "Levenberg–Marquardt: {} iterations, {:?}",
        fit.iterations,
        fit.termination
    );
    if !fit.termination.converged() {
        tracing::warn!(
            "Levenberg–Marquardt stopped after {} iterations without converging",
            fit.iterations
        );
    }
    Ok(fit)
}

/// `h_j = rel_step · max(|x_j|, 1)`: `J[:, j] = (f(x + h e_j) − f(x − h e_j)) / 2h`.
pub fn numeric_jacobian<F>(mut f: F, x: &DVector<f64>, m: usize, rel_step: f64) -> DMatrix<f64>
where
    F: FnMut(&DVector<f64>, &mut DVector<f64>),
{
    let n = x.len();
    let mut jac = DMatrix::zeros(m, n);
    let mut xp = x.clone();
    let mut rp = DVector::zeros(m);
    let mut rm = DVector::zeros(m);
    for j in 0..n {
        let h = rel_step * x[j].abs().max(1.0);
        xp[j] = x[j] + h;
        f(&xp, &mut rp);
        xp[j] = x[j] - h;
        f(&xp, &mut rm);
        xp[j] = x[j];
        let col = (&rp - &rm) / (2.0 * h);
        jac.set_column(j, &col);
    }
    jac
}

/// Levenberg–Marquardt minimisation of `‖f(x)‖²` from `x0` with `m` residuals.
///
/// `model(x, r, jac)` writes the `m` residuals into `r`; when `jac` is
/// `Some`, it may also write the `m × n` Jacobian `∂r/∂x` and return `true`;
/// returning `false` makes the solver use central differences
/// ([`numeric_jacobian`]). A model that cannot be evaluated at `x` writes
/// non-finite residuals: the step is then rejected and the damping increased.
///
/// Damping: Marquardt's diagonal scaling by the running maximum of
/// `diag(JᵀJ)`, Nielsen's update of the damping factor. At the end the
/// covariance and the identifiability report are computed from the Jacobian
/// at the solution exactly as in [`solve_linear`].
pub fn levenberg_marquardt<F>(
    mut model: F,
    x0: &DVector<f64>,
    m: usize,
    opts: &LmOptions,
) -> Result<LmFit, LsqError>
where
    F: FnMut(&DVector<f64>, &mut DVector<f64>, Option<&mut DMatrix<f64>>) -> bool,
{
    let n = x0.len();
    if n == 0 || m == 0 {
        return Err(LsqError::Shape(format!("{n} parameters, {m} residuals")));
    }
    if x0.iter().any(|v| !v.is_finite()) {
        return Err(LsqError::NonFinite("start point"));
    }
    let mut x = x0.clone();
    let mut r = DVector::zeros(m);
    model(&x, &mut r, None);
    if r.iter().any(|v| !v.is_finite()) {
        return Err(LsqError::NonFinite("residuals at the start point"));
    }
    let mut cost = r.norm_squared();
    let jacobian = |model: &mut F, x: &DVector<f64>| -> Result<DMatrix<f64>, LsqError> {
        let mut jac = DMatrix::zeros(m, n);
        let mut scratch = DVector::zeros(m);
        let filled = model(x, &mut scratch, Some(&mut jac));
        if !filled {
            jac = numeric_jacobian(
                |xx, rr| {
                    model(xx, rr, None);
                },
                x,
                m,
                opts.fd_relative_step,
            );
        }
        if jac.iter().any(|v| !v.is_finite()) {
            return Err(LsqError::NonFinite("Jacobian"));
        }
        Ok(jac)
    };

    let mut diag = DVector::<f64>::zeros(n);
    let mut mu: Option<f64> = None;
    let mut nu = 2.0;
    let mut iterations = 0;
    let termination = 'outer: loop {
        if cost == 0.0 {
            break Termination::ZeroResidual;
        }
        if iterations >= opts.max_iterations {
            break Termination::MaxIterations;
        }
        iterations += 1;
        let jac = jacobian(&mut model, &x)?;
        let jtj = jac.tr_mul(&jac);
        let g = jac.tr_mul(&r);
        // Scaled gradient test: |g_j| / (‖J_j‖ ‖r‖) is the cosine between column j and r.
        let rnorm = cost.sqrt();
        let gmax = (0..n)
            .map(|j| {
                let cn = jtj[(j, j)].sqrt();
                if cn > 0.0 {
                    g[j].abs() / (cn * rnorm)
                } else {
                    0.0
                }
            })
            .fold(0.0, f64::max);
        if gmax <= opts.gtol {
            break Termination::SmallGradient;
        }
        for j in 0..n {
            diag[j] = diag[j].max(jtj[(j, j)]).max(f64::MIN_POSITIVE);
        }
        let mut damping = match mu {
            Some(v) => v,
            None => opts.initial_damping * diag.max(),
        };
        loop {
            if !damping.is_finite() {
                break 'outer Termination::SmallStep;
            }
            let mut lhs = jtj.clone();
            for j in 0..n {
                lhs[(j, j)] += damping * diag[j];
            }
            let Some(chol) = lhs.cholesky() else {
                damping *= nu;
                nu *= 2.0;
                continue;
            };
            let delta = chol.solve(&(-&g));
            if delta.norm() <= opts.xtol * (x.norm() + opts.xtol) {
                break 'outer Termination::SmallStep;
            }
            let x_new = &x + &delta;
            let mut r_new = DVector::zeros(m);
            model(&x_new, &mut r_new, None);
            let cost_new = if r_new.iter().all(|v| v.is_finite()) {
                r_new.norm_squared()
            } else {
                f64::INFINITY
            };
            let dd = delta.component_mul(&diag);
            let predicted = damping * delta.dot(&dd) - g.dot(&delta);
            let actual = cost - cost_new;
            let rho = if predicted > 0.0 {
                actual / predicted
            } else {
                -1.0
            };
            if rho > 0.0 && cost_new.is_finite() {
                x = x_new;
                r = r_new;
                let old = cost;
                cost = cost_new;
                damping *= (1.0 / 3.0f64).max(1.0 - (2.0 * rho - 1.0).powi(3));
                nu = 2.0;
                mu = Some(damping);
                if actual <= opts.ftol * old && predicted <= opts.ftol * old {
                    break 'outer Termination::SmallReduction;
                }
                break;
            }
            damping *= nu;
            nu *= 2.0;
        }
    };
    let jac = jacobian(&mut model, &x)?;
    let dec = decompose(&jac, &opts.lsq)?;
    let solution = finish(&jac, dec, x, r);
    Ok(LmFit {
        solution,
        iterations,
        termination,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calibrate::stats::SplitMix64;
    use approx::assert_abs_diff_eq;

    /// Tolerance for exact (hand-computed) linear-algebra results.
    const EXACT_TOL: f64 = 1e-12;
    /// Tolerance of converged nonlinear solutions.
    const CONV_TOL: f64 = 1e-8;
    /// Agreement of analytic and central-difference Jacobians.
    const JAC_TOL: f64 = 1e-7;

    #[test]
    fn two_parameter_covariance_by_hand() {
        // Line b = x0 + x1 t at t = 0, 1, 2 with b = 1, 2, 2.
        // AᵀA = [[3, 3], [3, 5]], det 6, (AᵀA)⁻¹ = [[5, −3], [−3, 3]]/6; Aᵀb = [5, 6].
        // x = [25 − 18, −15 + 18]/6 = [7/6, 1/2]. Residuals Ax − b = [1/6, −1/3, 1/6],
        // RSS = 6/36 = 1/6, dof 1, σ² = 1/6, cov = (1/36)[[5, −3], [−3, 3]].
        let a = DMatrix::from_row_slice(3, 2, &[1.0, 0.0, 1.0, 1.0, 1.0, 2.0]);
        let b = DVector::from_vec(vec![1.0, 2.0, 2.0]);
        for scale in [false, true] {
            let opts = LsqOptions {
                scale_columns: scale,
                ..LsqOptions::default()
            };
            let s = solve_linear(&a, &b, &opts).expect("solvable");
            assert_abs_diff_eq!(s.params[0], 7.0 / 6.0, epsilon = EXACT_TOL);
            assert_abs_diff_eq!(s.params[1], 0.5, epsilon = EXACT_TOL);
            assert_abs_diff_eq!(s.rss, 1.0 / 6.0, epsilon = EXACT_TOL);
            assert_eq!(s.dof, 1);
            let c = s.covariance.clone().expect("dof > 0");
            assert_abs_diff_eq!(c[(0, 0)], 5.0 / 36.0, epsilon = EXACT_TOL);
            assert_abs_diff_eq!(c[(0, 1)], -3.0 / 36.0, epsilon = EXACT_TOL);
            assert_abs_diff_eq!(c[(1, 1)], 3.0 / 36.0, epsilon = EXACT_TOL);
            let u = s.expanded_uncertainty(COVERAGE_K).expect("dof > 0");
            assert_abs_diff_eq!(u[1], 2.0 * (3.0f64 / 36.0).sqrt(), epsilon = EXACT_TOL);
            assert!(s.identifiability.unidentifiable.is_empty());
        }
    }

    #[test]
    fn observability_and_condition_by_hand() {
        // A = [[3, 0], [0, 4], [0, 0]]: σ = 4, 3; O1 = √(4·3)/√3 = 2.
        // Unscaled condition 4/3; column-scaled design is orthonormal → 1.
        let a = DMatrix::from_row_slice(3, 2, &[3.0, 0.0, 0.0, 4.0, 0.0, 0.0]);
        let b = DVector::from_vec(vec![3.0, 8.0, 1.0]);
        let s = solve_linear(&a, &b, &LsqOptions::default()).expect("solvable");
        assert_abs_diff_eq!(s.identifiability.observability_o1, 2.0, epsilon = EXACT_TOL);
        assert_abs_diff_eq!(s.identifiability.condition_number, 1.0, epsilon = EXACT_TOL);
        let opts = LsqOptions {
            scale_columns: false,
            ..LsqOptions::default()
        };
        let s = solve_linear(&a, &b, &opts).expect("solvable");
        assert_abs_diff_eq!(
            s.identifiability.condition_number,
            4.0 / 3.0,
            epsilon = EXACT_TOL
        );
        // x = [1, 2], residual [0, 0, −1].
        assert_abs_diff_eq!(s.params[1], 2.0, epsilon = EXACT_TOL);
        assert_abs_diff_eq!(s.rss, 1.0, epsilon = EXACT_TOL);
    }

    #[test]
    fn duplicated_column_is_unidentifiable() {
        // Columns [1, t, t]: the third duplicates the second; it is fixed at 0
        // and the other two fit b = 1 + 2t exactly.
        let t = [0.0, 1.0, 2.0, 3.0, 4.0];
        let mut a = DMatrix::zeros(5, 3);
        let mut b = DVector::zeros(5);
        for (i, &ti) in t.iter().enumerate() {
            a[(i, 0)] = 1.0;
            a[(i, 1)] = ti;
            a[(i, 2)] = ti;
            b[i] = 1.0 + 2.0 * ti;
        }
        let s = solve_linear(&a, &b, &LsqOptions::default()).expect("solvable");
        assert_eq!(s.identifiability.unidentifiable, vec![2]);
        assert_eq!(s.identifiability.rank, 2);
        assert_eq!(s.identifiability.observability_o1, 0.0);
        assert!(s.identifiability.condition_number > 1e12);
        assert_abs_diff_eq!(s.params[0], 1.0, epsilon = EXACT_TOL);
        assert_abs_diff_eq!(s.params[1], 2.0, epsilon = EXACT_TOL);
        assert_eq!(s.params[2], 0.0);
        let c = s.covariance.expect("dof 3");
        assert_eq!(c[(2, 2)], 0.0);
    }

    #[test]
    fn recovers_known_parameters_within_uncertainty() {
        // b = 2 − 0.5 t + 0.03 t² + noise(σ = 0.01), t = 0..40 step 0.25.
        let truth = [2.0, -0.5, 0.03];
        let sigma = 0.01;
        let mut rng = SplitMix64::new(7);
        let ts: Vec<f64> = (0..161).map(|i| i as f64 * 0.25).collect();
        let a = DMatrix::from_fn(ts.len(), 3, |i, j| ts[i].powi(j as i32));
        let b = DVector::from_iterator(
            ts.len(),
            ts.iter()
                .map(|t| truth[0] + truth[1] * t + truth[2] * t * t + rng.gaussian(0.0, sigma)),
        );
        let s = solve_linear(&a, &b, &LsqOptions::default()).expect("solvable");
        let u = s.std_uncertainty().expect("dof > 0");
        for j in 0..3 {
            // 3σ: a fixed seed, so this either always or never holds.
            assert!((s.params[j] - truth[j]).abs() <= 3.0 * u[j], "param {j}");
        }
        // σ²/σ_true² has relative sd √(2/158) ≈ 0.113 with 158 dof; allow 3 sd.
        // (The 161 draws of seed 7 have mean square 1.2525, checked independently.)
        assert_abs_diff_eq!(
            s.sigma2.unwrap_or(f64::NAN) / (sigma * sigma),
            1.0,
            epsilon = 0.34
        );
    }

    #[test]
    fn shape_and_finiteness_errors() {
        let a = DMatrix::from_row_slice(2, 1, &[1.0, f64::NAN]);
        let b = DVector::from_vec(vec![1.0, 2.0]);
        assert_eq!(
            solve_linear(&a, &b, &LsqOptions::default()),
            Err(LsqError::NonFinite("design matrix"))
        );
        let a = DMatrix::from_row_slice(2, 1, &[1.0, 1.0]);
        let b = DVector::from_vec(vec![1.0]);
        assert!(matches!(
            solve_linear(&a, &b, &LsqOptions::default()),
            Err(LsqError::Shape(_))
        ));
    }

    fn rosenbrock(
        x: &DVector<f64>,
        r: &mut DVector<f64>,
        j: Option<&mut DMatrix<f64>>,
        analytic: bool,
    ) -> bool {
        // r1 = 10 (x2 − x1²), r2 = 1 − x1; J = [[−20 x1, 10], [−1, 0]].
        r[0] = 10.0 * (x[1] - x[0] * x[0]);
        r[1] = 1.0 - x[0];
        match j {
            Some(j) if analytic => {
                j[(0, 0)] = -20.0 * x[0];
                j[(0, 1)] = 10.0;
                j[(1, 0)] = -1.0;
                j[(1, 1)] = 0.0;
                true
            }
            _ => false,
        }
    }

    #[test]
    fn lm_solves_rosenbrock() {
        let x0 = DVector::from_vec(vec![-1.2, 1.0]);
        for analytic in [true, false] {
            let fit = levenberg_marquardt(
                |x, r, j| rosenbrock(x, r, j, analytic),
                &x0,
                2,
                &LmOptions::default(),
            )
            .expect("runs");
            assert!(fit.termination.converged(), "{:?}", fit.termination);
            assert_abs_diff_eq!(fit.solution.params[0], 1.0, epsilon = CONV_TOL);
            assert_abs_diff_eq!(fit.solution.params[1], 1.0, epsilon = CONV_TOL);
            assert!(fit.solution.rss < 1e-16);
            // m = n: no degrees of freedom → no covariance.
            assert!(fit.solution.covariance.is_none());
        }
        // Analytic Jacobian against central differences at a generic point.
        let x = DVector::from_vec(vec![0.3, -0.7]);
        let mut ja = DMatrix::zeros(2, 2);
        let mut r = DVector::zeros(2);
        rosenbrock(&x, &mut r, Some(&mut ja), true);
        let jn = numeric_jacobian(
            |x, r| {
                rosenbrock(x, r, None, false);
            },
            &x,
            2,
            1e-6,
        );
        for (a, n) in ja.iter().zip(jn.iter()) {
            assert_abs_diff_eq!(*a, *n, epsilon = JAC_TOL);
        }
    }

    #[test]
    fn lm_fits_exponential_decay_within_uncertainty() {
        // y = a exp(−k t) + c, truth a = 5, k = 0.4, c = 1, noise σ = 0.02.
        let truth = [5.0, 0.4, 1.0];
        let mut rng = SplitMix64::new(11);
        let ts: Vec<f64> = (0..60).map(|i| i as f64 * 0.2).collect();
        let ys: Vec<f64> = ts
            .iter()
            .map(|t| truth[0] * (-truth[1] * t).exp() + truth[2] + rng.gaussian(0.0, 0.02))
            .collect();
        let mut model = |p: &DVector<f64>, r: &mut DVector<f64>, j: Option<&mut DMatrix<f64>>| {
            for (i, (t, y)) in ts.iter().zip(&ys).enumerate() {
                r[i] = p[0] * (-p[1] * t).exp() + p[2] - y;
            }
            if let Some(j) = j {
                for (i, t) in ts.iter().enumerate() {
                    let e = (-p[1] * t).exp();
                    j[(i, 0)] = e;
                    j[(i, 1)] = -p[0] * t * e;
                    j[(i, 2)] = 1.0;
                }
                return true;
            }
            false
        };
        let x0 = DVector::from_vec(vec![1.0, 1.0, 0.0]);
        let fit =
            levenberg_marquardt(&mut model, &x0, ts.len(), &LmOptions::default()).expect("runs");
        assert!(fit.termination.converged(), "{:?}", fit.termination);
        let u = fit.solution.std_uncertainty().expect("dof 57");
        for j in 0..3 {
            assert!(
                (fit.solution.params[j] - truth[j]).abs() <= 3.0 * u[j],
                "param {j}"
            );
        }
        // Analytic Jacobian of this model against central differences.
        let p = DVector::from_vec(vec![4.0, 0.3, 0.5]);
        let mut ja = DMatrix::zeros(ts.len(), 3);
        let mut r = DVector::zeros(ts.len());
        model(&p, &mut r, Some(&mut ja));
        let jn = numeric_jacobian(
            |x, r| {
                model(x, r, None);
            },
            &p,
            ts.len(),
            1e-6,
        );
        for (a, n) in ja.iter().zip(jn.iter()) {
            assert_abs_diff_eq!(*a, *n, epsilon = JAC_TOL);
        }
    }
}
