//! Diagnosis of disagreement between simulation and measurement: where the
//! model and the measured observations disagree ([`residuals`],
//! [`patterns`]), which named
//! effect is missing ([`effects`], [`screen`], [`select`]), the model with that effect
//! added ([`mod@write`]) and the gap before and after on held-out rows
//! ([`report`]).
//!
//! Simulated = [`crate::calibrate::forward::predict`] of the current model;
//! residual = measured − simulated. Everything is linearised about the
//! current model: each candidate is a parametric addition whose sensitivity
//! is computed once, and a fit is linear least squares on those columns.
//! Rows with a measured orientation add weighted orientation residuals to
//! every fit, test and held-out figure ([`equations`]); the "where" analysis
//! looks at the positions. Gross outliers are named and left out of all of
//! it ([`outliers`]).

pub mod effects;
pub mod equations;
pub mod outliers;
pub mod patterns;
pub mod report;
pub mod residuals;
pub mod screen;
pub mod select;
pub mod write;

use nalgebra::{DMatrix, DVector, Vector3};

use equations::{Equations, FrameProjection};
use serde::Serialize;
use tracing::warn;

use crate::calibrate::forward;
use crate::calibrate::observations::{MeasuredKind, Observations};
use crate::calibrate::stats;
use crate::error::{Error, Result};
use crate::machine::Machine;

pub use effects::{Effect, library};
pub use residuals::Where;
pub use select::{Outcome, Step};

/// Options of a diagnosis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Options {
    /// Fraction of rows held out of every fit (0..1).
    pub holdout: f64,
    /// Seed of the hold-out split and the bootstrap.
    pub seed: u64,
    /// Bootstrap resamples.
    pub bootstrap: usize,
    /// The positions were measured in an instrument frame and carried into
    /// the reference frame by a registration to the current model: the
    /// frame's six parameters are fitted again with every candidate variant
    /// (the residual and every sensitivity are projected off the frame's
    /// columns, separately on the fitted and the held-out rows).
    pub instrument: bool,
    /// Weight of the orientation residuals of rows with `qw…qz`: the ratio
    /// of position to orientation noise, mm/rad, as in `calibrate` (0
    /// leaves measured orientations out).
    pub orientation_mm_per_rad: f64,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            holdout: 0.3,
            seed: 1,
            bootstrap: 30,
            instrument: false,
            orientation_mm_per_rad: crate::calibrate::stiffness::ORIENTATION_MM_PER_RAD,
        }
    }
}

/// Two candidates whose sensitivities the rows cannot tell apart (their
/// column spaces share a direction).
#[derive(Debug, Clone, Serialize)]
pub struct Confusable {
    /// First candidate.
    pub a: String,
    /// Second candidate.
    pub b: String,
    /// Cosine of the smallest principal angle between their column spaces.
    pub cos: f64,
}

/// A fitted parameter.
#[derive(Debug, Clone, Serialize)]
pub struct Param {
    /// Name with unit.
    pub name: String,
    /// Fitted value (display unit).
    pub value: f64,
    /// Standard uncertainty (1σ).
    pub u: f64,
}

/// An accepted effect with its fitted parameters.
#[derive(Debug, Clone, Serialize)]
pub struct Found {
    /// The effect.
    pub effect: Effect,
    /// Fitted parameters.
    pub params: Vec<Param>,
    /// Bootstrap inclusion frequency when it was accepted (0..1).
    pub bootstrap: f64,
}

/// Error statistics of a set of rows, µm.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Metrics {
    /// RMS of the 3D error.
    pub rms_um: f64,
    /// Largest 3D error.
    pub max_um: f64,
    /// 95th percentile of the 3D error.
    pub p95_um: f64,
    /// RMS per axis x, y, z.
    pub axis_rms_um: [f64; 3],
}

/// Orientation error statistics of a set of rows, degrees.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct AngleMetrics {
    /// RMS of the rotation angle of `measured · predicted⁻¹`.
    pub rms_deg: f64,
    /// Largest such angle.
    pub max_deg: f64,
}

impl AngleMetrics {
    /// RMS and max of angles given in rad.
    pub fn of_rad(angles: &[f64]) -> AngleMetrics {
        let deg: Vec<f64> = angles.iter().map(|a| a.to_degrees()).collect();
        AngleMetrics {
            rms_deg: stats::rms(&deg).unwrap_or(0.0),
            max_deg: stats::max(&deg).unwrap_or(0.0),
        }
    }
}

/// The held-out orientation gap (rows with a measured orientation).
#[derive(Debug, Clone, Copy, Serialize)]
pub struct AngleGap {
    /// Held-out rows with a measured orientation.
    pub rows: usize,
    /// Current model.
    pub before: AngleMetrics,
    /// With the accepted effects.
    pub after: AngleMetrics,
}

/// How measured orientations entered the diagnosis.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct OrientationUse {
    /// Rows whose orientation residuals are in the fits.
    pub rows: usize,
    /// Their weight, mm/rad (an orientation residual of θ rad counts like
    /// a position residual of θ × weight mm).
    pub weight_mm_per_rad: f64,
}

/// Held-out gap before and after adding the accepted effects.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Gap {
    /// Held-out rows.
    pub rows: usize,
    /// Current model.
    pub before: Metrics,
    /// With the accepted effects.
    pub after: Metrics,
    /// Percentage of the RMS gap closed.
    pub closed_pct: f64,
    /// Estimated measurement-noise floor of the 3D RMS, µm: √3 × the
    /// dof-corrected per-coordinate standard deviation of the training
    /// residual left by every candidate of the library fitted at once (or by
    /// the accepted effects, if lower) — what no effect of the library can
    /// explain.
    pub noise_floor_um: f64,
    /// Percentage of the closable gap (before − noise floor) closed.
    pub closed_of_closable_pct: f64,
    /// The orientation error of the held-out rows with a measured
    /// orientation, when orientations are in the fits.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub orientation: Option<AngleGap>,
}

/// The whole diagnosis.
#[derive(Debug, Clone, Serialize)]
pub struct Diagnosis {
    /// `robot` or `machine_tool`.
    pub machine_kind: String,
    /// Rows in the file.
    pub rows: usize,
    /// Training rows.
    pub train_rows: usize,
    /// Held-out rows.
    pub holdout_rows: usize,
    /// Candidates in the library.
    pub candidates: usize,
    /// Where the model and the measurements disagree.
    #[serde(rename = "where")]
    pub where_: Where,
    /// Identifiability screen: candidate pairs the rows cannot separate.
    pub screen: Vec<Confusable>,
    /// Identifiability screen: candidates that are combinations of several
    /// others in these rows.
    pub groups: Vec<Group>,
    /// Measured orientations in the fits (`None`: positions only). The
    /// training RSS and held-out RMS of the selection steps then count the
    /// weighted orientation residuals too.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub orientation: Option<OrientationUse>,
    /// Forward-selection steps.
    pub steps: Vec<Step>,
    /// Accepted effects with fitted parameters.
    pub found: Vec<Found>,
    /// Held-out gap.
    pub gap: Gap,
    /// One-sentence verdict.
    pub verdict: String,
    /// Gross outliers left out of every fit, test and held-out figure
    /// ([`outliers`]).
    pub outliers: outliers::Outliers,
    /// The covariance of the fitted parameters of `found` (the columns in
    /// their order, each effect's parameters in turn; display units), of
    /// the final fit on the training rows; `None` without accepted effects
    /// or without redundancy.
    #[serde(skip)]
    pub covariance: Option<DMatrix<f64>>,
}

pub use screen::{Group, SCREEN_COS};

/// Smallest adjusted R² of a pattern for the "where" sentence to name it.
const PATTERN_R2: f64 = 0.1;

/// Largest sensitivity (mm per display unit) a candidate the rows cannot
/// see at all may have: numerical differences of identical predictions.
const NO_SENSITIVITY_MM: f64 = 1e-12;

/// The candidates' sensitivities (µm per display unit, on the equations
/// `eq`), the candidates the rows can see. With an instrument frame, a candidate the frame's columns
/// explain (to within [`crate::calibrate::frame::FRAME_RANK_RTOL`]) is
/// absorbed by the frame and left out.
fn sensitivities(
    lib: Vec<Effect>,
    ctx: &effects::Context<'_>,
    rows: &[crate::calibrate::observations::Observation],
    eq: &Equations,
    frame: Option<&FrameProjection>,
) -> (Vec<Effect>, Vec<DMatrix<f64>>) {
    let mut kept = Vec::new();
    let mut sens = Vec::new();
    for e in lib {
        match effects::pose_sensitivity(&e, ctx, rows).map(|s| eq.from_slots(&s)) {
            Ok(s) if s.iter().all(|v| v.is_finite()) && s.amax() > NO_SENSITIVITY_MM => {
                let s = s * 1000.0;
                let s = match frame {
                    Some(f) => {
                        let p = f.apply(&s);
                        if p.norm() < crate::calibrate::frame::FRAME_RANK_RTOL * s.norm() {
                            warn!("candidate {}: absorbed by the instrument frame", e.name);
                            continue;
                        }
                        p
                    }
                    None => s,
                };
                sens.push(s);
                kept.push(e);
            }
            Ok(_) => {}
            Err(err) => warn!("candidate {}: {err}", e.name),
        }
    }
    (kept, sens)
}

/// The accepted effects with their fitted parameters, and the fitted
/// coefficients.
fn found_effects(
    sel: &select::Selection,
    kept: &[Effect],
) -> (Vec<Found>, DVector<f64>, Option<DMatrix<f64>>) {
    let mut found = Vec::new();
    let Some(fit) = &sel.fit else {
        return (found, DVector::zeros(0), None);
    };
    let u = fit
        .std_uncertainty()
        .unwrap_or_else(|| DVector::from_element(fit.params.len(), f64::NAN));
    let mut col = 0;
    for (step, &c) in sel.accepted.iter().enumerate() {
        let Some(e) = kept.get(c) else { continue };
        let params = e
            .params
            .iter()
            .map(|p| {
                let v = Param {
                    name: p.clone(),
                    value: fit.params.get(col).copied().unwrap_or(0.0),
                    u: u.get(col).copied().unwrap_or(f64::NAN),
                };
                col += 1;
                v
            })
            .collect();
        let bootstrap = sel
            .steps
            .get(step)
            .and_then(|s| s.candidates.iter().find(|x| x.index == c))
            .map_or(0.0, |x| x.bootstrap);
        found.push(Found {
            effect: e.clone(),
            params,
            bootstrap,
        });
    }
    (found, fit.params.clone(), fit.covariance.clone())
}

/// The residual with the accepted effects' correction removed (µm, on the
/// equations): `r − X β` over the accepted candidates' columns.
fn corrected(
    sel: &select::Selection,
    sens: &[DMatrix<f64>],
    r: &DVector<f64>,
    beta: &DVector<f64>,
) -> DVector<f64> {
    if sel.accepted.is_empty() {
        return r.clone();
    }
    let x = select::design(sens, &sel.accepted, r.len());
    if x.ncols() == beta.len() {
        r - &x * beta
    } else {
        r.clone()
    }
}

/// The position errors (mm) of `rows` in a residual `r` (µm, on `eq`).
fn positions(eq: &Equations, r: &DVector<f64>, rows: &[usize]) -> Vec<Vector3<f64>> {
    rows.iter()
        .map(|&i| {
            let s = eq.start(i);
            let v = |c: usize| r.get(s + c).copied().unwrap_or(0.0) * 1e-3;
            Vector3::new(v(0), v(1), v(2))
        })
        .collect()
}

/// The held-out gap with the accepted effects (fitted on the training rows).
fn held_out_gap(
    sel: &select::Selection,
    sens: &[DMatrix<f64>],
    r: &DVector<f64>,
    eq: &Equations,
    beta: &DVector<f64>,
    train: &[usize],
    hold: &[usize],
) -> Gap {
    let after_r = corrected(sel, sens, r, beta);
    let mb = metrics(&positions(eq, r, hold));
    let ma = metrics(&positions(eq, &after_r, hold));
    let angles = |v: &DVector<f64>| -> Vec<f64> {
        hold.iter().filter_map(|&i| eq.angle_rad(v, i)).collect()
    };
    let (ab, aa) = (angles(r), angles(&after_r));
    let orientation = (!ab.is_empty()).then(|| AngleGap {
        rows: ab.len(),
        before: AngleMetrics::of_rad(&ab),
        after: AngleMetrics::of_rad(&aa),
    });
    // The floor is a position figure, as the gap it is compared with: it
    // comes from the training rows' position equations only (weighted
    // orientation residuals have another noise).
    let train_pos: Vec<usize> = train
        .iter()
        .flat_map(|&i| {
            let s = eq.start(i);
            s..s + 3
        })
        .collect();
    let rss_t: f64 = train_pos
        .iter()
        .map(|&e| after_r.get(e).copied().unwrap_or(0.0).powi(2))
        .sum();
    let k_t = sel.fit.as_ref().map_or(0, |f| f.params.len());
    let dof = train_pos.len().saturating_sub(k_t).max(1) as f64;
    let noise_floor_um = match library_noise_floor(r, sens, &train_pos) {
        Some(f) => f.min((3.0 * rss_t / dof).sqrt()),
        None => (3.0 * rss_t / dof).sqrt(),
    };
    let closable = mb.rms_um - noise_floor_um;
    Gap {
        rows: hold.len(),
        before: mb,
        after: ma,
        closed_pct: if mb.rms_um > 0.0 {
            100.0 * (1.0 - ma.rms_um / mb.rms_um)
        } else {
            0.0
        },
        noise_floor_um,
        closed_of_closable_pct: if closable > 0.0 {
            (100.0 * (mb.rms_um - ma.rms_um) / closable).min(100.0)
        } else {
            0.0
        },
        orientation,
    }
}

/// Runs the diagnosis. `machine_text` is the YAML of `machine`; `obs_file`
/// names the observation file in errors.
pub fn diagnose(
    machine: &Machine,
    machine_text: &str,
    obs: &Observations,
    obs_file: &str,
    opts: &Options,
) -> Result<Diagnosis> {
    forward::check_kind(machine, obs, obs_file)?;
    let ctx = effects::Context {
        machine,
        text: machine_text,
        kind: obs.measured,
        file: obs_file,
    };
    let rows = &obs.rows;
    if rows.len() < 4 {
        return Err(Error::Data(format!(
            "{obs_file}: {} rows; diagnose needs at least 4",
            rows.len()
        )));
    }
    // Repeats and near-copies of a pose stay on one side of the split.
    let (train, hold) = crate::calibrate::screen::grouped_split(obs, opts.holdout, opts.seed);
    // An effect is accepted only when held-out rows confirm it: a split
    // that leaves either side empty could confirm nothing.
    if hold.is_empty() || train.is_empty() {
        return Err(crate::error::Error::Usage(format!(
            "--holdout {}: holds out {} of the {} rows; both the held-out and the fitted rows need at least one",
            crate::error::show_number(opts.holdout),
            hold.len(),
            rows.len()
        )));
    }
    let eq = Equations::new(machine, rows, opts.orientation_mm_per_rad);
    let frame = opts
        .instrument
        .then(|| FrameProjection::new(rows, &eq, &[&train, &hold]));
    let mut r = residual(machine, rows, obs, &eq, obs_file)?;
    if let Some(f) = &frame {
        r = f
            .apply(&DMatrix::from_column_slice(r.len(), 1, r.as_slice()))
            .column(0)
            .into_owned();
    }
    let mut lib = library(machine, rows);
    if obs.measured == MeasuredKind::Deviation {
        for e in lib.iter_mut().filter(|e| e.action == effects::Action::Tcp) {
            e.not_writable = Some(effects::NOT_TCP_DEVIATION.into());
        }
    }
    let (kept, sens) = sensitivities(lib, &ctx, rows, &eq, frame.as_ref());
    let outliers = outliers::find(&r, &sens, &eq, rows.len(), |i| {
        rows.get(i)
            .map_or((String::new(), 0), |row| (row.id.clone(), row.line))
    });
    let (train, hold) = without_outliers(train, hold, &outliers, rows.len())?;
    let inliers: Vec<usize> = (0..rows.len())
        .filter(|i| !outliers.rows.iter().any(|o| o.index == *i))
        .collect();
    let in_rows: Vec<_> = inliers
        .iter()
        .filter_map(|&i| rows.get(i).cloned())
        .collect();
    let res = positions(&eq, &r, &inliers);
    let mut where_ = residuals::analyse(&in_rows, &res);
    where_.patterns = patterns::rank(machine, &in_rows, &res);
    if let Some(p) = where_.patterns.first().filter(|p| p.r2_adj >= PATTERN_R2) {
        where_.sentence.push_str(&format!(
            " The pattern that explains most of the residual: {} (adjusted R² {:.2}).",
            p.name, p.r2_adj
        ));
    }
    let names: Vec<String> = kept.iter().map(|e| e.name.clone()).collect();
    let screen = screen::pairs(&sens, &names);
    let groups = screen::groups(&sens, &names, &screen);
    let sel = select::select(&select::Problem {
        r: &r,
        s: &sens,
        eq: &eq,
        names: &names,
        train: &train,
        holdout: &hold,
        bootstrap: opts.bootstrap,
        seed: opts.seed,
    });
    let (found, beta, covariance) = found_effects(&sel, &kept);
    let gap = held_out_gap(&sel, &sens, &r, &eq, &beta, &train, &hold);
    let verdict = verdict(&sel.steps, &found);
    Ok(Diagnosis {
        machine_kind: match machine {
            Machine::Robot(_) => "robot".into(),
            Machine::Tool(_) => "machine_tool".into(),
        },
        rows: rows.len(),
        train_rows: train.len(),
        holdout_rows: hold.len(),
        candidates: kept.len(),
        where_,
        screen,
        groups,
        orientation: (eq.oriented_rows() > 0).then(|| OrientationUse {
            rows: eq.oriented_rows(),
            weight_mm_per_rad: eq.weight(),
        }),
        steps: sel.steps,
        found,
        gap,
        verdict,
        outliers,
        covariance,
    })
}

/// The split without the outlier rows; both sides must keep a row.
fn without_outliers(
    mut train: Vec<usize>,
    mut hold: Vec<usize>,
    out: &outliers::Outliers,
    n: usize,
) -> Result<(Vec<usize>, Vec<usize>)> {
    let is_out = |i: &usize| out.rows.iter().any(|o| o.index == *i);
    train.retain(|i| !is_out(i));
    hold.retain(|i| !is_out(i));
    if train.is_empty() || hold.is_empty() {
        return Err(Error::Data(format!(
            "{} of the {n} rows are gross outliers; too few rows are left to fit and to hold out",
            out.rows.len()
        )));
    }
    Ok((train, hold))
}

/// The residual `measured − simulated` of the current model on the
/// equations `eq`, µm: the measured triple, and the weighted orientation
/// residual of the rows that have orientation equations.
fn residual(
    machine: &Machine,
    rows: &[crate::calibrate::observations::Observation],
    obs: &Observations,
    eq: &Equations,
    obs_file: &str,
) -> Result<DVector<f64>> {
    let mut r = DVector::zeros(eq.total());
    for (i, row) in rows.iter().enumerate() {
        let p = forward::predict(machine, row, obs_file)?;
        let v = row.measured_mm - p.measured(obs.measured);
        let s = eq.start(i);
        for c in 0..3 {
            r[s + c] = v[c] * 1000.0;
        }
        if let (Some(o), Some(q), Some(pq)) = (eq.orientation(i), row.orientation, p.attained_rot) {
            let e = eq.orientation_residual(&q, &pq);
            for c in 0..3 {
                r[o.start + c] = e[c] * 1000.0;
            }
        }
    }
    Ok(r)
}

fn verdict(steps: &[Step], found: &[Found]) -> String {
    let mut parts: Vec<String> = found
        .iter()
        .map(|f| {
            format!(
                "missing effect: {} ({})",
                f.effect.name, f.effect.description
            )
        })
        .collect();
    match steps.last().map(|s| &s.outcome) {
        Some(Outcome::Confounded { name, with }) => parts.push(format!(
            "{name} is confounded with {}: the data cannot tell them apart, nothing claimed",
            with.join(", ")
        )),
        Some(Outcome::NotConfirmed { name }) => parts.push(format!(
            "{name} fits the training rows but does not improve the held-out rows: not claimed"
        )),
        _ => {}
    }
    if parts.is_empty() {
        "no detectable missing effect".into()
    } else {
        if !matches!(
            steps.last().map(|s| &s.outcome),
            Some(Outcome::Confounded { .. } | Outcome::NotConfirmed { .. })
        ) {
            parts.push("nothing more detectable".into());
        }
        parts.join("; ")
    }
}

/// Relative singular value below which a direction of the whole library's
/// (column-normalised) design counts as absent.
const RANK_TOL: f64 = 1e-9;

/// Noise floor (3D RMS, µm) from every candidate of the library fitted at
/// once on the training rows: √3 × the dof-corrected per-coordinate standard
/// deviation of what no combination of candidates explains. It depends on
/// no selection decision (an accepted or rejected effect); `None` when the
/// library leaves fewer than half the training equations as degrees of
/// freedom (the estimate would rest on too little). `train`: the training
/// rows' equations.
fn library_noise_floor(r: &DVector<f64>, sens: &[DMatrix<f64>], train: &[usize]) -> Option<f64> {
    let n = train.len();
    let k: usize = sens.iter().map(DMatrix::ncols).sum();
    if n == 0 || k == 0 {
        return None;
    }
    let mut x = DMatrix::zeros(n, k);
    let mut y = DVector::zeros(n);
    for (row, &e) in train.iter().enumerate() {
        y[row] = r.get(e).copied().unwrap_or(0.0);
    }
    let mut col = 0;
    for s in sens {
        for j in 0..s.ncols() {
            for (row, &e) in train.iter().enumerate() {
                x[(row, col)] = s.get((e, j)).copied().unwrap_or(0.0);
            }
            let norm = x.column(col).norm();
            if norm > 0.0 {
                x.column_mut(col).unscale_mut(norm);
            }
            col += 1;
        }
    }
    let svd = x.svd(true, false);
    let u = svd.u.as_ref()?;
    let smax = svd.singular_values.max();
    if smax.is_nan() || smax <= 0.0 {
        return None;
    }
    let mut fitted = DVector::zeros(n);
    let mut rank = 0;
    for (j, sv) in svd.singular_values.iter().enumerate() {
        if *sv > RANK_TOL * smax {
            let uj = u.column(j);
            fitted += uj * uj.dot(&y);
            rank += 1;
        }
    }
    let dof = n.checked_sub(rank)?;
    if 2 * dof < n {
        return None;
    }
    let rss = (y - fitted).norm_squared();
    Some((3.0 * rss / dof as f64).sqrt())
}

/// Error statistics of `machine` (e.g. a written model) on the held-out rows
/// of the split `opts` selects — the check of a written model with the full
/// (not linearised) forward model.
pub fn holdout_metrics(
    machine: &Machine,
    obs: &Observations,
    obs_file: &str,
    opts: &Options,
) -> Result<Metrics> {
    holdout_check(machine, obs, obs_file, opts).map(|c| c.0)
}

/// [`holdout_metrics`], and the orientation error of the held-out rows
/// with a measured orientation when the diagnosis compares orientations
/// (a robot and a positive `opts.orientation_mm_per_rad`).
pub fn holdout_check(
    machine: &Machine,
    obs: &Observations,
    obs_file: &str,
    opts: &Options,
) -> Result<(Metrics, Option<AngleMetrics>)> {
    holdout_check_without(machine, obs, obs_file, opts, &[])
}

/// [`holdout_check`] without the rows `skip` (the diagnosis' outliers).
pub fn holdout_check_without(
    machine: &Machine,
    obs: &Observations,
    obs_file: &str,
    opts: &Options,
    skip: &[usize],
) -> Result<(Metrics, Option<AngleMetrics>)> {
    forward::check_kind(machine, obs, obs_file)?;
    let (_, mut hold) = crate::calibrate::screen::grouped_split(obs, opts.holdout, opts.seed);
    hold.retain(|i| !skip.contains(i));
    let eq = Equations::new(machine, &obs.rows, opts.orientation_mm_per_rad);
    let mut e = Vec::with_capacity(hold.len());
    let mut angles = Vec::new();
    for &i in &hold {
        let Some(row) = obs.rows.get(i) else { continue };
        let p = forward::predict(machine, row, obs_file)?;
        e.push(row.measured_mm - p.measured(obs.measured));
        if let (Some(_), Some(q), Some(pq)) = (eq.orientation(i), row.orientation, p.attained_rot) {
            angles.push((q * pq.inverse()).angle());
        }
    }
    let orientation = (!angles.is_empty()).then(|| AngleMetrics::of_rad(&angles));
    Ok((metrics(&e), orientation))
}

/// RMS, max, 95th percentile and per-axis RMS of 3D errors (mm in, µm out).
pub fn metrics(e: &[Vector3<f64>]) -> Metrics {
    let norms: Vec<f64> = e.iter().map(|v| v.norm() * 1000.0).collect();
    let axis = |c: usize| {
        let v: Vec<f64> = e.iter().map(|x| x[c] * 1000.0).collect();
        stats::rms(&v).unwrap_or(0.0)
    };
    Metrics {
        rms_um: stats::rms(&norms).unwrap_or(0.0),
        max_um: stats::max(&norms).unwrap_or(0.0),
        p95_um: stats::percentile(&norms, 95.0).unwrap_or(0.0),
        axis_rms_um: [axis(0), axis(1), axis(2)],
    }
}
