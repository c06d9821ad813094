//! Robot kinematic calibration: corrections of the actual DH parameters
//! (a, α, d, θ offset of every row of the machine file) and of the TCP
//! translation, by Levenberg–Marquardt on the forward model of the rows
//! ([`super::forward::predict`], which also carries the gravity sag with the
//! file's stiffness).
//!
//! Parameters are corrections to the file's `actual` model (mm and mrad inside, reported in mm and degrees),
//! named after the file's row: `j2.a_mm` is `a_mm` of the second row (for
//! modified DH that row holds `a₁`). The TCP translation (`tool.x_mm` …) is
//! included only when no row gives its own measured point (`mp_*`) and the
//! file holds positions: a deviation (attained − commanded of the same
//! point) barely depends on where that point is.
//!
//! Identifiability: the Jacobian at the start is analysed by a rank-revealing
//! pivoted QR and an SVD ([`solve_linear`]); parameters it cannot separate
//! from the others are fixed at the file's value and listed by name. (In a
//! modified-DH model, for example, `d` of the last row and the TCP z are the
//! same motion; with a TCP on the joint-6 axis the joint-6 offset moves
//! nothing; with joint 1 always at the same angle, the first link's offsets
//! look like a shift of the measuring frame.) A remaining condition number
//! above [`CONDITION_LIMIT`] is refused.
//!
//! Frames ([`super::frame`], docs/frames.md): positions in the robot base
//! frame are used as they are (the `base` of the machine file is neither
//! identified nor edited: in a modified-DH model the x and z offsets of the
//! arm in that frame are the first row's `a_mm` and `d_mm`); world-frame
//! rows are carried back through `base`; for instrument-frame rows the six
//! parameters of the instrument's pose are identified with the model, and
//! model parameters that move the points like a rigid motion of the
//! instrument are fixed and listed as absorbed by it.
//!
//! Rows with a measured orientation add three residuals (the rotation
//! vector of measured · predicted⁻¹, times
//! [`Options::orientation_mm_per_rad`]).
//!
//! Subset selection: after the identifiability screen and a full fit,
//! corrections that are not significant on the fit rows (Bayesian
//! information criterion, linearised at the solution) keep the file's
//! value and the rest is fitted again; the held-out rows check
//! the result (per-point RMS and max before and after, fit and held-out).
//! Rows whose deleted residual marks them as outliers
//! ([`super::screen::dominating_rows`]) leave the fit, named. Uncertain
//! parameters ([`super::honesty`]) keep the file's value in the written
//! file and its validation; the instrument frame is then solved again alone
//! for the corrections written, and that frame is written and validated.

use nalgebra::{DMatrix, DVector, Isometry3, Translation3};

use crate::calibrate::lsq::{
    LmOptions, LsqOptions, Solution, data_error, expand_free, fit_free, forward_jacobian_free,
    numeric_jacobian, solve_linear,
};
use crate::error::{Error, Result};
use crate::machine::Machine;
use crate::machine::robot::{DhParams, Model, Robot, Trial};

use super::forward::{check_kind, predict};
use super::frame::{
    FRAME_NAMES, FRAME_PARAMS, IDENTIFIED_NOTE, absorbed_note, conditional_uncertainty, estimate,
    frame_with, screen_model, start_frame, world_note, world_to_reference,
};
use super::honesty::zero_withheld;
use super::observations::{MeasuredKind, MeasurementFrame, Observation, Observations, Pose};
use super::report::{
    CONDITION_LIMIT, Calibration, Estimate, FitCovariance, FrameEstimate, validations,
};
use super::screen::{
    describe_outliers, distinct_poses, dominating_rows, drop_copies, grouped_split, implausible,
};
use super::stiffness::Options;
use crate::machine::robot::{DhField, RobotParam};
use crate::machine::yaml_write::{self, Edit, round_to};

/// Relative rank threshold of the identification Jacobian: a parameter
/// whose effect, after removing what the already chosen parameters explain,
/// is below 10⁻³ of the strongest parameter's is *practically*
/// unidentifiable (its uncertainty would be ≥ 1000 × the best one's). This
/// catches exact redundancies (finite differences leave ≈10⁻⁸) and the
/// near-redundancies that only the gravity sag separates (e.g. `j6.d_mm` and
/// `tool.z_mm` differ by the lever of the tool load, ≈10⁻⁴ relative).
/// The columns are *not* scaled to unit norm (a parameter that moves nothing
/// must stay a zero column, not become normalised noise); instead the
/// unknowns have comparable physical units: mm for lengths, mrad for angles
/// (1 mrad moves a point 1 m away by 1 mm).
pub const KIN_RANK_RTOL: f64 = 1e-3;

/// Most rows a kinematic calibration leaves out as outliers (one per
/// refit, the worst first).
const MAX_OUTLIER_PASSES: usize = 3;

/// Forward-difference step of the identification Jacobian (mm or mrad).
const FD_STEP: f64 = 1e-4;

/// Degrees per internal angle unit (mrad).
const DEG_PER_UNIT: f64 = super::frame::DEG_PER_MRAD;

const DH_NAMES: [(&str, &str); 4] = [
    ("a_mm", "mm"),
    ("alpha_deg", "deg"),
    ("d_mm", "mm"),
    ("theta_offset_deg", "deg"),
];

/// Parameter vector layout: 24 DH corrections, then optionally 3 TCP ones,
/// then optionally the 6 parameters of an instrument frame
/// ([`super::frame`]).
struct Layout {
    base: Robot,
    dh: DhParams,
    tool: bool,
    /// Start pose of the instrument frame (instrument data only).
    frame: Option<Isometry3<f64>>,
    /// Weight of the orientation residuals, mm/rad (0: none).
    w_rot: f64,
}

impl Layout {
    /// Number of model parameters (DH and TCP).
    fn n_model(&self) -> usize {
        if self.tool { 27 } else { 24 }
    }

    fn n(&self) -> usize {
        self.n_model()
            + if self.frame.is_some() {
                FRAME_PARAMS
            } else {
                0
            }
    }

    fn name(&self, k: usize) -> (String, &'static str) {
        if k < 24 {
            let (n, u) = DH_NAMES[k % 4];
            (format!("j{}.{n}", k / 4 + 1), u)
        } else if k < self.n_model() {
            (format!("tool.{}_mm", ["x", "y", "z"][(k - 24) % 3]), "mm")
        } else {
            let (n, u) = FRAME_NAMES[(k - self.n_model()) % FRAME_PARAMS];
            (n.to_string(), u)
        }
    }

    fn start(&self, k: usize) -> f64 {
        if k < 24 {
            let j = &self.dh.joints[k / 4];
            match k % 4 {
                0 => j.a_mm,
                1 => j.alpha_rad.to_degrees(),
                2 => j.d_mm,
                _ => j.theta_offset_rad.to_degrees(),
            }
        } else {
            self.base.flange_to_tool().translation.vector[(k - 24) % 3]
        }
    }

    fn dh_with(&self, x: &[f64]) -> DhParams {
        let mut p = self.dh;
        for (j, joint) in p.joints.iter_mut().enumerate() {
            let v = |o: usize| x.get(4 * j + o).copied().unwrap_or(0.0);
            joint.a_mm += v(0);
            joint.alpha_rad += v(1) * 1e-3;
            joint.d_mm += v(2);
            joint.theta_offset_rad += v(3) * 1e-3;
        }
        p
    }

    fn robot(&self, x: &[f64]) -> Robot {
        let r = self
            .base
            .trial_with_params(&[Trial::Actual(self.dh_with(x))]);
        if self.tool {
            let t0 = self.base.flange_to_tool();
            let v = |o: usize| x.get(24 + o).copied().unwrap_or(0.0);
            let t = Isometry3::from_parts(
                Translation3::from(
                    t0.translation.vector + nalgebra::Vector3::new(v(0), v(1), v(2)),
                ),
                t0.rotation,
            );
            r.with_tool(t, self.base.tool_load().copied())
        } else {
            r
        }
    }

    /// The instrument frame for the parameters `x` (identity without one).
    fn frame_at(&self, x: &[f64]) -> Isometry3<f64> {
        match &self.frame {
            Some(f0) => frame_with(f0, x.get(self.n_model()..).unwrap_or(&[])),
            None => Isometry3::identity(),
        }
    }

    /// Equations of a row: 3 for the position, 3 more for a measured
    /// orientation when orientations are weighted.
    fn eqs(&self, row: &Observation) -> usize {
        if self.w_rot > 0.0 && row.orientation.is_some() {
            6
        } else {
            3
        }
    }
}

/// First equation of each of `rows` and the total number of equations.
fn offsets(layout: &Layout, obs: &Observations, rows: &[usize]) -> (Vec<usize>, usize) {
    let mut off = Vec::with_capacity(rows.len());
    let mut m = 0;
    for &i in rows {
        off.push(m);
        m += obs.rows.get(i).map_or(3, |r| layout.eqs(r));
    }
    (off, m)
}

/// Joints (1-based) at the same angle in every row.
fn constant_joints(obs: &Observations) -> Vec<usize> {
    (0..6)
        .filter(|&j| {
            let mut qs = obs.rows.iter().filter_map(|r| match &r.pose {
                Pose::Robot(rp) => rp.q_deg.get(j).copied(),
                Pose::Tool(_) => None,
            });
            let first = qs.next();
            first.is_some() && qs.all(|q| Some(q) == first)
        })
        .map(|j| j + 1)
        .collect()
}

/// Poses of the structural identifiability check.
const REFERENCE_POSES: usize = 60;

/// Which model parameters a Jacobian identifies. Without a frame: the rank
/// screen of [`solve_linear`] on the model columns. With one: the frame
/// columns must have full rank (else `Err` with the reason), and the model
/// columns are screened after removing what the frame columns explain
/// (`(I − Q Qᵀ) J_model`, `Q` an orthonormal basis of the frame columns):
/// a model parameter that moves the measured point like a rigid motion of
/// the instrument is unidentifiable. Returns (unidentifiable given the
/// frame, unidentifiable without it).
fn screen(
    layout: &Layout,
    j: &DMatrix<f64>,
    r0: &DVector<f64>,
    lsq: &LsqOptions,
) -> std::result::Result<(Vec<usize>, Vec<usize>), String> {
    let nm = layout.n_model();
    let jm = j.columns(0, nm).into_owned();
    let jf = layout
        .frame
        .map(|_| j.columns(nm, FRAME_PARAMS).into_owned());
    screen_model(&jm, jf.as_ref(), r0, lsq)
}

/// The parameters that no pose set identifies: the identifiability of the
/// same parameters and measured points at [`REFERENCE_POSES`] joint vectors
/// spread over the joint ranges (deterministic). Returns (given the frame,
/// without the frame), as [`screen`].
fn structurally_unidentifiable(
    layout: &Layout,
    obs: &Observations,
    fit: &[usize],
    file: &str,
    lm_opts: &LmOptions,
) -> Result<(Vec<usize>, Vec<usize>)> {
    let limits = *layout.base.joint_limits_rad();
    let mut rng = crate::calibrate::stats::SplitMix64::new(0x5EED_CA1B);
    let mut reference = obs.clone();
    reference.rows.clear();
    for k in 0..REFERENCE_POSES {
        let Some(template) = fit.get(k % fit.len().max(1)).and_then(|&i| obs.rows.get(i)) else {
            break;
        };
        let mut row = template.clone();
        if let Pose::Robot(rp) = &mut row.pose {
            for (q, [lo, hi]) in rp.q_deg.iter_mut().zip(limits) {
                // The inner 80 % of each range, clear of the singular ends.
                let (lo, hi) = (lo.max(-std::f64::consts::PI), hi.min(std::f64::consts::PI));
                let t = 0.1 + 0.8 * rng.next_f64();
                *q = (lo + t * (hi - lo)).to_degrees();
            }
        }
        if let Some(f0) = &layout.frame {
            // The point where the start model puts it, seen by the
            // instrument: the frame columns need the real lever arms.
            let m = Machine::Robot(layout.base.clone());
            if let Ok(p) = predict(&m, &row, file) {
                row.measured_mm = (f0.inverse() * nalgebra::Point3::from(p.attained_mm)).coords;
            }
        }
        reference.rows.push(row);
    }
    let rows: Vec<usize> = (0..reference.rows.len()).collect();
    let (_, m) = offsets(layout, &reference, &rows);
    let n = layout.n();
    let zero = DVector::zeros(n);
    let mut r0 = DVector::zeros(m);
    residuals(layout, &reference, &rows, zero.as_slice(), &mut r0, file);
    if r0.iter().any(|v| !v.is_finite()) {
        return Ok((Vec::new(), Vec::new()));
    }
    let j = numeric_jacobian(
        |x, r| residuals(layout, &reference, &rows, x.as_slice(), r, file),
        &zero,
        m,
        lm_opts.fd_relative_step,
    );
    // A reference set that cannot register the frame (it always can with
    // varied poses) says nothing structural.
    Ok(screen(layout, &j, &r0, &lm_opts.lsq).unwrap_or_default())
}

/// Residuals `measured − model` of `rows` for the full parameter vector:
/// per row the position (the measured point carried into the reference
/// frame by the instrument frame, if any) and, for a row with a measured
/// orientation, the rotation vector of `measured · predicted⁻¹` times the
/// orientation weight.
fn residuals(
    layout: &Layout,
    obs: &Observations,
    rows: &[usize],
    x: &[f64],
    out: &mut DVector<f64>,
    file: &str,
) {
    let m = Machine::Robot(layout.robot(x));
    let f = layout.frame_at(x);
    let mut at = 0;
    for &i in rows {
        let Some(row) = obs.rows.get(i) else { continue };
        let eqs = layout.eqs(row);
        match predict(&m, row, file) {
            Ok(p) => {
                let meas = if layout.frame.is_some() {
                    (f * nalgebra::Point3::from(row.measured_mm)).coords
                } else {
                    row.measured_mm
                };
                let d = meas - p.measured(obs.measured);
                for r in 0..3 {
                    out[at + r] = d[r];
                }
                if eqs == 6 {
                    let e = match (row.orientation, p.attained_rot) {
                        (Some(q), Some(pr)) => {
                            (f.rotation * q * pr.inverse()).scaled_axis() * layout.w_rot
                        }
                        _ => nalgebra::Vector3::zeros(),
                    };
                    for r in 0..3 {
                        out[at + 3 + r] = e[r];
                    }
                }
            }
            Err(_) => {
                for r in 0..eqs {
                    out[at + r] = f64::NAN;
                }
            }
        }
        at += eqs;
    }
}

/// Per-point position residual norms of `rows` for the model `m` and the
/// frame `f` (measured points carried by `f`).
fn row_norms(
    m: &Machine,
    f: &Isometry3<f64>,
    obs: &Observations,
    rows: &[usize],
    file: &str,
) -> Result<Vec<f64>> {
    let mut v = Vec::with_capacity(rows.len());
    for &i in rows {
        if let Some(row) = obs.rows.get(i) {
            let p = predict(m, row, file)?;
            let meas = (f * nalgebra::Point3::from(row.measured_mm)).coords;
            v.push((meas - p.measured(obs.measured)).norm());
        }
    }
    Ok(v)
}

/// Position equations (3 per row) of a Jacobian and residual vector laid
/// out by [`offsets`].
fn position_rows(
    off: &[usize],
    j: &DMatrix<f64>,
    e: &DVector<f64>,
) -> (DMatrix<f64>, DVector<f64>) {
    let idx: Vec<usize> = off.iter().flat_map(|&o| [o, o + 1, o + 2]).collect();
    (j.select_rows(idx.iter()), e.select_rows(idx.iter()))
}

/// Backward elimination on the fit rows, linearised at the full fit: drops,
/// one at a time, the free model parameter whose correction is least
/// significant (`t² = δ² / var(δ)`), while its `t²` is below `ln(m)` — the
/// Bayesian information criterion's price of a parameter (dropping it
/// lowers the BIC). Frame parameters always stay, and so does the last
/// model parameter when nothing else is free (a fit needs an unknown; the
/// honesty rule of [`super::honesty`] still judges it). Returns the kept and the
/// dropped parameters, each dropped one with the standard uncertainty (mm
/// or mrad) the full fit would give its correction.
fn select_parameters(
    j0: &DMatrix<f64>,
    r0: &DVector<f64>,
    free: &[usize],
    n_model: usize,
    lsq: &LsqOptions,
) -> (Vec<usize>, Vec<(usize, f64)>) {
    let m = j0.nrows();
    let price = (m as f64).ln();
    let mut kept = free.to_vec();
    let mut dropped = Vec::new();
    // σ² of the full linearised fit: the yardstick of every step.
    let full = j0.select_columns(kept.iter());
    let Ok(sol) = solve_linear(&full, r0, lsq) else {
        return (kept, dropped);
    };
    let Some(s2) = sol.sigma2.filter(|s| *s > 0.0) else {
        return (kept, dropped);
    };
    let u_full = sol.std_uncertainty();
    let u_of = |k: usize| {
        free.iter()
            .position(|&f| f == k)
            .and_then(|c| u_full.as_ref().map(|u| u[c]))
            .unwrap_or(f64::NAN)
    };
    loop {
        let a = j0.select_columns(kept.iter());
        let Ok(sol) = solve_linear(&a, r0, lsq) else {
            break;
        };
        let Some(cov) = sol.covariance else { break };
        let sigma2 = sol.sigma2.unwrap_or(s2).max(f64::MIN_POSITIVE);
        let weakest = kept
            .iter()
            .enumerate()
            .filter(|(_, k)| **k < n_model)
            .map(|(c, &k)| {
                let var = cov[(c, c)] / sigma2 * s2;
                let t2 = if var > 0.0 {
                    sol.params[c] * sol.params[c] / var
                } else {
                    f64::INFINITY
                };
                (k, t2)
            })
            .min_by(|a, b| a.1.total_cmp(&b.1));
        match weakest {
            Some((k, t2)) if t2 < price && kept.len() > 1 => {
                kept.retain(|&x| x != k);
                dropped.push((k, u_of(k)));
            }
            _ => break,
        }
    }
    dropped.sort_unstable_by_key(|d| d.0);
    (kept, dropped)
}

/// The data of a kinematic calibration run after the screening.
struct Prepared {
    layout: Layout,
    obs: Observations,
    fit: Vec<usize>,
    hold: Vec<usize>,
    notes: Vec<String>,
}

fn prepare(robot: &Robot, obs: &Observations, obs_file: &str, opts: &Options) -> Result<Prepared> {
    let mut notes = Vec::new();
    let (obs, copies) = drop_copies(
        &world_to_reference(&Machine::Robot(robot.clone()), obs),
        obs_file,
    );
    notes.extend(copies);
    let instrument = obs.frame == MeasurementFrame::Instrument;
    // Deviations (attained − commanded of the same point) hardly see where
    // the point is: the TCP translation is identified from positions only.
    let tool = obs.measured == MeasuredKind::Position
        && obs
            .rows
            .iter()
            .all(|r| matches!(&r.pose, Pose::Robot(rp) if rp.mp_mm.is_none()));
    let mut layout = Layout {
        base: robot.clone(),
        dh: *robot.params(Model::Actual),
        tool,
        frame: None,
        w_rot: opts.orientation_mm_per_rad,
    };
    let (fit, hold) = grouped_split(&obs, opts.holdout, opts.seed);
    if instrument {
        let m = Machine::Robot(robot.clone());
        layout.frame = Some(start_frame(&m, &obs, &fit, obs_file)?);
    }
    let n = layout.n();
    let distinct = distinct_poses(&obs, &fit);
    if 3 * distinct < 2 * n {
        return Err(Error::Data(format!(
            "{obs_file}: {distinct} distinct poses left for the fit ({} rows; repeated poses \
             count once) for {n} parameters; kinematic calibration needs at least {} distinct \
             poses, better several times more",
            fit.len(),
            (2 * n).div_ceil(3)
        )));
    }
    Ok(Prepared {
        layout,
        obs,
        fit,
        hold,
        notes,
    })
}

/// The outcome of the fit with outlier removal and subset selection.
struct Fitted {
    fit_result: crate::calibrate::lsq::LmFit,
    /// The parameters fitted in the end (model and frame).
    free: Vec<usize>,
    /// Corrections dropped as insignificant, with the uncertainty the full
    /// fit gives them.
    insignificant: Vec<(usize, f64)>,
}

/// Fits the free parameters on the `fit` rows; then, once each: rows that
/// disagree with all the others leave the fit (the worst first, at most
/// [`MAX_OUTLIER_PASSES`]; named in `notes`), and the corrections that are
/// not significant at the solution are dropped (subset selection,
/// linearised there); after either, fits again.
fn fit_and_select(
    layout: &Layout,
    obs: &Observations,
    fit: &mut Vec<usize>,
    free: Vec<usize>,
    lm_opts: &LmOptions,
    obs_file: &str,
    notes: &mut Vec<String>,
) -> Result<Fitted> {
    let n = layout.n();
    let nm = layout.n_model();
    let usage = |e: String| data_error(obs_file, e);
    let mut free = free;
    // Fit; then, once each: rows that disagree with all the others leave
    // the fit (the worst first, at most MAX_OUTLIER_PASSES), and the
    // corrections that are not significant at the solution are dropped
    // (subset selection, linearised there); after either, fit again.
    let mut insignificant: Vec<(usize, f64)> = Vec::new();
    let mut outlier_passes = 0;
    let mut selected = false;
    let fit_result = loop {
        let (off, m) = offsets(layout, obs, fit);
        let fr = fit_free(
            |x, out| residuals(layout, obs, fit, x, out, obs_file),
            n,
            &free,
            m,
            FD_STEP,
            lm_opts,
        )
        .map_err(|e| usage(e.to_string()))?;
        if selected && outlier_passes >= MAX_OUTLIER_PASSES {
            break fr;
        }
        let full = expand_free(n, &free, fr.solution.params.as_slice());
        let mut r = DVector::zeros(m);
        residuals(layout, obs, fit, &full, &mut r, obs_file);
        let mut jf = DMatrix::zeros(m, free.len());
        forward_jacobian_free(
            |x, out| residuals(layout, obs, fit, x, out, obs_file),
            &full,
            &free,
            &r,
            FD_STEP,
            &mut jf,
        );
        if outlier_passes < MAX_OUTLIER_PASSES {
            let (jp, ep) = position_rows(&off, &jf, &r);
            if let Some(worst) = dominating_rows(&jp, &ep, fit).into_iter().next() {
                outlier_passes += 1;
                let text = describe_outliers(obs, obs_file, std::slice::from_ref(&worst));
                tracing::warn!("row left out of the fit as an outlier: {text}");
                notes.push(format!("row left out of the fit as an outlier: {text}"));
                fit.retain(|&i| i != worst.row);
                continue;
            }
            outlier_passes = MAX_OUTLIER_PASSES;
        }
        if !selected {
            selected = true;
            // The linear model at the solution: r(x) ≈ (r* − J x*) + J x.
            let mut jn = DMatrix::zeros(m, n);
            for (c, &k) in free.iter().enumerate() {
                jn.set_column(k, &jf.column(c));
            }
            let xs = DVector::from_column_slice(&full);
            let b = &jn * &xs - &r;
            let (kept, dropped) = select_parameters(&jn, &b, &free, nm, &lm_opts.lsq);
            if !dropped.is_empty() {
                free = kept;
                insignificant = dropped;
                continue;
            }
        }
        break fr;
    };
    Ok(Fitted {
        fit_result,
        free,
        insignificant,
    })
}

/// Refuses a badly conditioned fit (after fixing `n_fixed` unidentifiable
/// parameters).
fn check_condition(
    id: &crate::calibrate::lsq::Identifiability,
    n_fixed: usize,
    obs_file: &str,
) -> Result<()> {
    if id.condition_number_identified > CONDITION_LIMIT {
        Err(Error::Data(format!(
            "{obs_file}: badly conditioned data set: condition number {:.3e} > {:.0e} \
             (O1 = {:.3e}) after fixing {} unidentifiable parameter(s); the poses do not \
             excite the kinematic parameters independently. Measure more varied poses \
             (all joints over their range)",
            id.condition_number_identified, CONDITION_LIMIT, id.observability_o1, n_fixed
        )))
    } else {
        Ok(())
    }
}

/// The estimates of the model parameters: start values from the file,
/// values corrected by `full` (angles in degrees), uncertainties of the
/// `free` ones from the fit `sol`, of the `insignificant` ones the full fit's
/// (those count as fixed, as the unidentifiable ones).
fn estimates(
    layout: &Layout,
    full: &[f64],
    sol: &Solution,
    free: &[usize],
    insignificant: &[(usize, f64)],
) -> Vec<Estimate> {
    let u_red = sol.std_uncertainty();
    let u_of = |k: usize| {
        free.iter()
            .position(|&f| f == k)
            .and_then(|a| u_red.as_ref().map(|u| u[a]))
    };
    let nm = layout.n_model();
    let mut params = Vec::with_capacity(nm);
    for k in 0..nm {
        let (name, unit) = layout.name(k);
        let is_free = free.contains(&k);
        let start = layout.start(k);
        let f = if unit == "deg" { DEG_PER_UNIT } else { 1.0 };
        params.push(Estimate {
            name,
            unit,
            start,
            value: start + f * full.get(k).copied().unwrap_or(0.0),
            u: if is_free {
                u_of(k).map(|u| f * u)
            } else {
                // A correction left out as insignificant: the uncertainty
                // the full fit gives it (the file's value is within it).
                insignificant
                    .iter()
                    .find(|d| d.0 == k)
                    .map(|d| f * d.1)
                    .filter(|u| u.is_finite())
            },
            fixed: !is_free,
        });
    }
    params
}

/// The covariance of the model parameters fitted (`free`, columns of
/// `sol` in that order) and written (not `withheld`), by their key paths
/// in the keys' units (angles in degrees).
fn written_covariance(
    layout: &Layout,
    sol: &Solution,
    free: &[usize],
    withheld: &[bool],
) -> Option<FitCovariance> {
    const DH: [DhField; 4] = [DhField::A, DhField::Alpha, DhField::D, DhField::ThetaOffset];
    let cols: Vec<(usize, String, f64)> = free
        .iter()
        .enumerate()
        .filter(|&(_, &k)| k < layout.n_model() && withheld.get(k) != Some(&true))
        .map(|(col, &k)| {
            let (key, unit) = if k < 24 {
                let field = DH[k % 4];
                let p = RobotParam::Dh {
                    joint: k / 4,
                    field,
                };
                (p.path(), layout.name(k).1)
            } else {
                (RobotParam::ToolOffset { axis: (k - 24) % 3 }.path(), "mm")
            };
            (col, key, if unit == "deg" { DEG_PER_UNIT } else { 1.0 })
        })
        .collect();
    FitCovariance::select(sol.covariance.as_ref(), &cols)
}

/// Identifies the actual DH parameters (and the TCP translation; and the
/// instrument frame for `# frame: instrument` data) from `obs`.
pub fn calibrate_kinematics(
    text: &str,
    machine_file: &str,
    obs: &Observations,
    obs_file: &str,
    opts: &Options,
) -> Result<Calibration> {
    let machine = Machine::from_yaml_str(text, machine_file)?;
    check_kind(&machine, obs, obs_file)?;
    let Machine::Robot(robot) = &machine else {
        return Err(Error::Usage(format!(
            "{machine_file}: kinematic calibration needs a robot machine file"
        )));
    };
    let read_frame = obs.frame;
    let Prepared {
        layout,
        obs,
        mut fit,
        hold,
        mut notes,
    } = prepare(robot, obs, obs_file, opts)?;
    let obs = &obs;
    let n = layout.n();
    tracing::info!(
        "kinematics: {} rows for the fit, {} held out, {n} parameters",
        fit.len(),
        hold.len()
    );
    let lm_opts = LmOptions {
        lsq: LsqOptions {
            rank_rtol: KIN_RANK_RTOL,
            scale_columns: false,
        },
        ..LmOptions::default()
    };
    let Screened {
        fixed,
        absorbed,
        free,
    } = screen_data(&layout, obs, &fit, obs_file, &lm_opts)?;
    let Fitted {
        fit_result,
        free,
        insignificant,
    } = fit_and_select(&layout, obs, &mut fit, free, &lm_opts, obs_file, &mut notes)?;
    let sol = &fit_result.solution;
    let id = &sol.identifiability;
    check_condition(id, fixed.len(), obs_file)?;
    let full = expand_free(n, &free, sol.params.as_slice());
    let params = estimates(&layout, &full, sol, &free, &insignificant);
    // Uncertain parameters keep the file's value (super::honesty): their
    // corrections are not applied.
    let withheld = opts.honesty.withheld(&params);
    let uncertain = opts.honesty.uncertain(&params);
    let mut full = full;
    zero_withheld(&mut full, &withheld);
    let frame_u = written_frame(
        &layout,
        obs,
        &fit,
        &mut full,
        (sol, &free),
        &withheld,
        &lm_opts,
        obs_file,
    )?;
    let calibrated_robot = layout.robot(&full);
    let calibrated = Machine::Robot(calibrated_robot.clone());
    let f_start = layout.frame_at(&[]);
    let f_end = layout.frame_at(&full);
    // The input model is judged with the frame registered to it, the
    // calibrated one with the identified frame.
    let (validation, fit_check) = validations(&hold, &fit, |cal, rows| {
        let (m, f) = if cal {
            (&calibrated, &f_end)
        } else {
            (&machine, &f_start)
        };
        row_norms(m, f, obs, rows, obs_file)
    })?;
    let frame = layout.frame.map(|_| estimate(&f_end, frame_u));
    let yaml = write_yaml(
        text,
        machine_file,
        &calibrated_robot,
        layout.tool,
        frame.as_ref(),
    )
    .map_err(|e| implausible(&e, obs_file, fit.len()))?;
    let insignificant: Vec<usize> = insignificant.iter().map(|d| d.0).collect();
    notes_for(&layout, obs, &fixed, &absorbed, &insignificant, &mut notes);
    notes.push(frame_note(&machine, &layout, read_frame));
    notes.extend(obs.orientation_note(layout.w_rot, None));
    let (_, m) = offsets(&layout, obs, &fit);
    let covariance = written_covariance(&layout, sol, &free, &withheld);
    Ok(Calibration {
        kind: "kinematics",
        n_fit: fit.len(),
        n_equations: m,
        observability_o1: 0.0,
        condition_number: 0.0,
        rms_fit_mm: sol.rms_fit(m),
        params,
        validation,
        fit_check,
        frame,
        insignificant: insignificant.iter().map(|&k| layout.name(k).0).collect(),
        uncertain,
        honesty: opts.honesty,
        notes,
        yaml,
        covariance,
    }
    .finished(id))
}

/// The instrument frame written with the model written: `full` holds the
/// joint fit's corrections with the withheld ones (`withheld`, the honesty
/// rule's flags per model parameter) at zero. When nothing is withheld the
/// joint fit's frame stays; otherwise the frame alone is solved again
/// (Levenberg–Marquardt from the joint fit's frame) against that model on
/// the fit rows, with the residuals of the fit (positions and, weighted the
/// same, measured orientations), and its parameters in `full` replaced.
/// Returns the frame's standard uncertainties (origin mm, small rotations
/// mrad): per component the larger of the frame-alone fit's own and those
/// of the joint fit `sol` (over the parameters `free`) conditioned on the
/// withheld values ([`conditional_uncertainty`]). `None` without an
/// instrument frame.
#[allow(clippy::too_many_arguments)]
fn written_frame(
    layout: &Layout,
    obs: &Observations,
    fit: &[usize],
    full: &mut [f64],
    (sol, free): (&Solution, &[usize]),
    withheld: &[bool],
    lm_opts: &LmOptions,
    obs_file: &str,
) -> Result<Option<[f64; FRAME_PARAMS]>> {
    if layout.frame.is_none() {
        return Ok(None);
    }
    let (nm, n) = (layout.n_model(), layout.n());
    let at = |k: usize| free.iter().position(|&f| f == k);
    let frame_cols: Option<Vec<usize>> = (nm..n).map(at).collect();
    let fixed: Vec<usize> = (0..nm)
        .filter(|&k| withheld.get(k) == Some(&true))
        .filter_map(at)
        .collect();
    let joint =
        frame_cols.and_then(|c| conditional_uncertainty(sol.covariance.as_ref(), &c, &fixed));
    if fixed.is_empty() {
        return Ok(joint);
    }
    let written = full.to_vec();
    let frame_idx: Vec<usize> = (nm..n).collect();
    let (_, m) = offsets(layout, obs, fit);
    let mut y = written.clone();
    let fr = fit_free(
        |x, out| {
            for k in nm..n {
                y[k] = written[k] + x.get(k).copied().unwrap_or(0.0);
            }
            residuals(layout, obs, fit, &y, out, obs_file);
        },
        n,
        &frame_idx,
        m,
        FD_STEP,
        lm_opts,
    )
    .map_err(|e| data_error(obs_file, e))?;
    for (o, d) in fr.solution.params.iter().enumerate() {
        if let Some(v) = full.get_mut(nm + o) {
            *v += d;
        }
    }
    let own: Option<[f64; FRAME_PARAMS]> = fr
        .solution
        .std_uncertainty()
        .and_then(|u| u.as_slice().try_into().ok());
    Ok(match (own, joint) {
        (Some(a), Some(b)) => Some(std::array::from_fn(|k| a[k].max(b[k]))),
        (a, b) => a.or(b),
    })
}

/// The outcome of the identifiability screen on the fit rows.
struct Screened {
    /// Model parameters kept at the file's value.
    fixed: Vec<usize>,
    /// Of those, the ones the instrument frame absorbs.
    absorbed: Vec<usize>,
    /// The parameters to fit (model and frame).
    free: Vec<usize>,
}

/// The identifiability screen at the start point: parameters no pose set
/// identifies (redundant with others in the model, or with the instrument
/// frame) are fixed quietly; parameters only THESE poses cannot identify
/// mean a badly conditioned data set: fitting the rest would push their
/// errors into neighbouring parameters with confident uncertainties — the
/// run is refused naming them.
fn screen_data(
    layout: &Layout,
    obs: &Observations,
    fit: &[usize],
    obs_file: &str,
    lm_opts: &LmOptions,
) -> Result<Screened> {
    let n = layout.n();
    let (_, m) = offsets(layout, obs, fit);
    let zero = DVector::zeros(n);
    let mut r0 = DVector::zeros(m);
    residuals(layout, obs, fit, zero.as_slice(), &mut r0, obs_file);
    if r0.iter().any(|v| !v.is_finite()) {
        return Err(Error::Data(format!(
            "{obs_file}: the model cannot be evaluated for some rows"
        )));
    }
    // With an instrument frame, the frame's columns are taken at the points
    // the start model predicts (seen by the instrument), so that a model
    // parameter that is a rigid motion is exactly parallel to them, whatever
    // the start model's errors.
    let seen;
    let obs = match &layout.frame {
        Some(f0) => {
            let m0 = Machine::Robot(layout.base.clone());
            let mut o = obs.clone();
            for &i in fit {
                if let Some(row) = o.rows.get_mut(i) {
                    let p = predict(&m0, row, obs_file)?;
                    row.measured_mm = (f0.inverse() * nalgebra::Point3::from(p.attained_mm)).coords;
                }
            }
            seen = o;
            &seen
        }
        None => obs,
    };
    let j0 = numeric_jacobian(
        |x, r| residuals(layout, obs, fit, x.as_slice(), r, obs_file),
        &zero,
        m,
        lm_opts.fd_relative_step,
    );
    let (fixed, _) = screen(layout, &j0, &r0, &lm_opts.lsq).map_err(|e| data_error(obs_file, e))?;
    let (structural, structural_plain) =
        structurally_unidentifiable(layout, obs, fit, obs_file, lm_opts)?;
    // The same number of unidentifiable parameters as at the reference
    // poses is the same redundancy (the rank decision may pick another
    // member of a redundant pair); more means these poses lack something.
    let data_caused: Vec<usize> = if fixed.len() <= structural.len() {
        Vec::new()
    } else {
        fixed
            .iter()
            .copied()
            .filter(|k| !structural.contains(k))
            .collect()
    };
    if !data_caused.is_empty() {
        let names: Vec<String> = data_caused.iter().map(|&k| layout.name(k).0).collect();
        let mut why = constant_joints(obs)
            .iter()
            .map(|j| format!("every row has joint {j} at the same angle"))
            .collect::<Vec<_>>()
            .join("; ");
        if why.is_empty() {
            why = "the poses do not vary the joints enough".into();
        }
        return Err(Error::Data(format!(
            "{obs_file}: badly conditioned data set: these poses cannot identify {} \
             (varied poses do) — {why}. Their errors would be absorbed by the other \
             parameters with misleadingly small uncertainties; measure poses that move \
             every joint over its range",
            names.join(", ")
        )));
    }
    let absorbed: Vec<usize> = fixed
        .iter()
        .copied()
        .filter(|k| !structural_plain.contains(k))
        .collect();
    if !fixed.is_empty() {
        let names: Vec<String> = fixed.iter().map(|&k| layout.name(k).0).collect();
        tracing::warn!(
            "{} parameter(s) cannot be identified from these data and stay at the file's value: {}",
            fixed.len(),
            names.join(", ")
        );
    }
    let free: Vec<usize> = (0..n).filter(|k| !fixed.contains(k)).collect();
    Ok(Screened {
        fixed,
        absorbed,
        free,
    })
}

/// Decimals of the DH lengths and the TCP written, mm (0.1 µm).
const LENGTH_DECIMALS: usize = 4;
/// Decimals of the DH angles written, degrees (≈ 0.2 µrad).
const ANGLE_DECIMALS: usize = 5;

/// The calibrated machine file: the actual DH rows, the TCP translation
/// (when identified) and the measurement frame (instrument data).
fn write_yaml(
    text: &str,
    machine_file: &str,
    robot: &Robot,
    tool: bool,
    frame: Option<&FrameEstimate>,
) -> Result<String> {
    let dh = robot.params(Model::Actual);
    let mut edits = Vec::with_capacity(6 * 4 + 4);
    for (joint, j) in dh.joints.iter().enumerate() {
        for (field, v) in [
            (DhField::A, round_to(j.a_mm, LENGTH_DECIMALS)),
            (
                DhField::Alpha,
                round_to(j.alpha_rad.to_degrees(), ANGLE_DECIMALS),
            ),
            (DhField::D, round_to(j.d_mm, LENGTH_DECIMALS)),
            (
                DhField::ThetaOffset,
                round_to(j.theta_offset_rad.to_degrees(), ANGLE_DECIMALS),
            ),
        ] {
            edits.push(Edit::Robot(RobotParam::Dh { joint, field }, v));
        }
    }
    if tool {
        let t = robot.flange_to_tool().translation.vector;
        for axis in 0..3 {
            let v = round_to(t[axis], LENGTH_DECIMALS);
            edits.push(Edit::Robot(RobotParam::ToolOffset { axis }, v));
        }
    }
    if let Some(f) = frame {
        edits.push(Edit::MeasurementFrame {
            xyz_mm: f.xyz_mm,
            rpy_deg: f.rpy_deg,
        });
    }
    let yaml = yaml_write::apply(text, machine_file, "postproc calibrate kinematics", &edits)?;
    Machine::from_yaml_str(&yaml, machine_file)?;
    Ok(yaml)
}

fn notes_for(
    layout: &Layout,
    obs: &Observations,
    fixed: &[usize],
    absorbed: &[usize],
    insignificant: &[usize],
    notes: &mut Vec<String>,
) {
    let n = layout.n_model();
    if !fixed.is_empty() {
        notes.push(format!(
            "{} of {n} parameters are not identifiable from these poses (they move the \
             measured point like a combination of the others); they keep the file's value",
            fixed.len()
        ));
    }
    let absorbed: Vec<String> = absorbed.iter().map(|&k| layout.name(k).0).collect();
    notes.extend(absorbed_note(
        &absorbed,
        "a joint-1 offset wrong by θ turns the frame by θ",
    ));
    if !insignificant.is_empty() {
        let names: Vec<String> = insignificant.iter().map(|&k| layout.name(k).0).collect();
        notes.push(format!(
            "not significant on the fit rows (a correction below its price in the Bayesian \
             information criterion; kept at the file's value): {}",
            names.join(", ")
        ));
    }
    for j in constant_joints(obs) {
        notes.push(format!(
            "every row has joint {j} at the same angle: the parameters of the links \
             before it cannot be told from a shift or tilt of the measuring frame \
             (badly conditioned for those parameters); move joint {j} as well"
        ));
    }
}

/// The note on the frame of the positions read (`read`: the file's frame,
/// before world positions are carried into the base frame).
fn frame_note(machine: &Machine, layout: &Layout, read: MeasurementFrame) -> String {
    if layout.frame.is_some() {
        return IDENTIFIED_NOTE.into();
    }
    match world_note(machine, read) {
        Some(w) => format!("{w}; no measurement frame is identified"),
        None => "positions in the robot base frame (the machine's reference frame); no \
                 measurement frame is identified"
            .into(),
    }
}
