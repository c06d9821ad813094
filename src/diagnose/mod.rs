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

pub mod effects;
pub mod patterns;
pub mod report;
pub mod residuals;
pub mod screen;
pub mod select;
pub mod write;

use nalgebra::{DMatrix, DVector, Vector3};
use serde::Serialize;
use tracing::warn;

use crate::calibrate::forward;
use crate::calibrate::observations::{MeasuredKind, Observations, holdout_split};
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
}

impl Default for Options {
    fn default() -> Self {
        Options {
            holdout: 0.3,
            seed: 1,
            bootstrap: 30,
            instrument: false,
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
    /// Forward-selection steps.
    pub steps: Vec<Step>,
    /// Accepted effects with fitted parameters.
    pub found: Vec<Found>,
    /// Held-out gap.
    pub gap: Gap,
    /// One-sentence verdict.
    pub verdict: String,
}

pub use screen::{Group, SCREEN_COS};

/// Smallest adjusted R² of a pattern for the "where" sentence to name it.
const PATTERN_R2: f64 = 0.1;

/// Largest sensitivity (mm per display unit) a candidate the rows cannot
/// see at all may have: numerical differences of identical predictions.
const NO_SENSITIVITY_MM: f64 = 1e-12;

/// Projection off the columns of an instrument frame's six parameters
/// (a shift, and a small rotation `−[p]×` about the reference axes, at the
/// measured points `p`), on each of the row sets separately: what remains
/// of a residual or a sensitivity after the frame of those rows is fitted
/// with it (Frisch–Waugh–Lovell).
struct FrameProjection {
    /// Per row set: the rows and an orthonormal basis of the frame columns.
    blocks: Vec<(Vec<usize>, DMatrix<f64>)>,
}

impl FrameProjection {
    fn new(rows: &[crate::calibrate::observations::Observation], sets: &[&[usize]]) -> Self {
        let blocks = sets
            .iter()
            .map(|set| {
                let mut j = DMatrix::zeros(3 * set.len(), 6);
                for (k, &i) in set.iter().enumerate() {
                    let p = rows.get(i).map_or(Vector3::zeros(), |r| r.measured_mm);
                    j.view_mut((3 * k, 0), (3, 3))
                        .copy_from(&nalgebra::Matrix3::identity());
                    j.view_mut((3 * k, 3), (3, 3))
                        .copy_from(&(-p.cross_matrix()));
                }
                (set.to_vec(), j.qr().q())
            })
            .collect();
        FrameProjection { blocks }
    }

    /// `m` (3 rows per observation row) with the frame's part removed.
    fn apply(&self, m: &DMatrix<f64>) -> DMatrix<f64> {
        let mut out = m.clone();
        for (set, q) in &self.blocks {
            let idx: Vec<usize> = set
                .iter()
                .flat_map(|&i| [3 * i, 3 * i + 1, 3 * i + 2])
                .collect();
            let block = m.select_rows(idx.iter());
            let rest = &block - q * (q.transpose() * &block);
            for (k, &r) in idx.iter().enumerate() {
                out.row_mut(r).copy_from(&rest.row(k));
            }
        }
        out
    }
}

/// The candidates' sensitivities (µm per display unit), the candidates the
/// rows can see. With an instrument frame, a candidate the frame's columns
/// explain (to within [`crate::calibrate::frame::FRAME_RANK_RTOL`]) is
/// absorbed by the frame and left out.
fn sensitivities(
    lib: Vec<Effect>,
    ctx: &effects::Context<'_>,
    rows: &[crate::calibrate::observations::Observation],
    frame: Option<&FrameProjection>,
) -> (Vec<Effect>, Vec<DMatrix<f64>>) {
    let mut kept = Vec::new();
    let mut sens = Vec::new();
    for e in lib {
        match effects::sensitivity(&e, ctx, rows) {
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
fn found_effects(sel: &select::Selection, kept: &[Effect]) -> (Vec<Found>, DVector<f64>) {
    let mut found = Vec::new();
    let Some(fit) = &sel.fit else {
        return (found, DVector::zeros(0));
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
    (found, fit.params.clone())
}

/// The held-out gap with the accepted effects (fitted on the training rows).
fn held_out_gap(
    sel: &select::Selection,
    sens: &[DMatrix<f64>],
    r: &DVector<f64>,
    res: &[Vector3<f64>],
    beta: &DVector<f64>,
    train: &[usize],
    hold: &[usize],
) -> Gap {
    let n = res.len();
    let before: Vec<Vector3<f64>> = hold.iter().filter_map(|&i| res.get(i).copied()).collect();
    let after: Vec<Vector3<f64>> = if sel.accepted.is_empty() {
        before.clone()
    } else {
        let x = select::design(sens, &sel.accepted, 3 * n);
        let corr: DVector<f64> = if x.ncols() == beta.len() {
            &x * beta
        } else {
            DVector::zeros(3 * n)
        };
        hold.iter()
            .filter_map(|&i| {
                let v = res.get(i)?;
                Some(Vector3::new(
                    v.x - corr[3 * i] * 1e-3,
                    v.y - corr[3 * i + 1] * 1e-3,
                    v.z - corr[3 * i + 2] * 1e-3,
                ))
            })
            .collect()
    };
    let mb = metrics(&before);
    let ma = metrics(&after);
    let (rss_t, k_t) = match &sel.fit {
        Some(f) => (f.rss, f.params.len()),
        None => (sel.steps.first().map_or(0.0, |s| s.rss_before_um2), 0),
    };
    let dof = (3 * train.len()).saturating_sub(k_t).max(1) as f64;
    let noise_floor_um = match library_noise_floor(r, sens, train) {
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
    let yaml: serde_yaml::Value = serde_yaml::from_str(machine_text)
        .map_err(|e| Error::Usage(format!("machine file: {e}")))?;
    let ctx = effects::Context {
        machine,
        yaml: &yaml,
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
    let (train, hold) = holdout_split(rows.len(), opts.holdout, opts.seed);
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
    let frame = opts
        .instrument
        .then(|| FrameProjection::new(rows, &[&train, &hold]));
    let sim = effects::simulate(&ctx, rows)?;
    let mut r = DVector::zeros(3 * rows.len());
    for (i, (row, s)) in rows.iter().zip(&sim).enumerate() {
        let v = row.measured_mm - s;
        for c in 0..3 {
            r[3 * i + c] = v[c] * 1000.0;
        }
    }
    let res: Vec<Vector3<f64>> = match &frame {
        Some(f) => {
            r = f
                .apply(&DMatrix::from_column_slice(r.len(), 1, r.as_slice()))
                .column(0)
                .into_owned();
            (0..rows.len())
                .map(|i| Vector3::new(r[3 * i], r[3 * i + 1], r[3 * i + 2]) * 1e-3)
                .collect()
        }
        None => rows
            .iter()
            .zip(&sim)
            .map(|(r, s)| r.measured_mm - s)
            .collect(),
    };
    let mut where_ = residuals::analyse(rows, &res);
    where_.patterns = patterns::rank(machine, rows, &res);
    if let Some(p) = where_.patterns.first().filter(|p| p.r2_adj >= PATTERN_R2) {
        where_.sentence.push_str(&format!(
            " The pattern that explains most of the residual: {} (adjusted R² {:.2}).",
            p.name, p.r2_adj
        ));
    }

    let mut lib = library(machine, rows);
    if obs.measured == MeasuredKind::Deviation {
        for e in lib.iter_mut().filter(|e| e.action == effects::Action::Tcp) {
            e.not_writable = Some(effects::NOT_TCP_DEVIATION.into());
        }
    }
    let (kept, sens) = sensitivities(lib, &ctx, rows, frame.as_ref());
    let names: Vec<String> = kept.iter().map(|e| e.name.clone()).collect();
    let screen = screen::pairs(&sens, &names);
    let groups = screen::groups(&sens, &names, &screen);
    let sel = select::select(&select::Problem {
        r: &r,
        s: &sens,
        names: &names,
        train: &train,
        holdout: &hold,
        bootstrap: opts.bootstrap,
        seed: opts.seed,
    });
    let (found, beta) = found_effects(&sel, &kept);
    let gap = held_out_gap(&sel, &sens, &r, &res, &beta, &train, &hold);
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
        steps: sel.steps,
        found,
        gap,
        verdict,
    })
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
/// freedom (the estimate would rest on too little).
fn library_noise_floor(r: &DVector<f64>, sens: &[DMatrix<f64>], train: &[usize]) -> Option<f64> {
    let n = 3 * train.len();
    let k: usize = sens.iter().map(DMatrix::ncols).sum();
    if n == 0 || k == 0 {
        return None;
    }
    let mut x = DMatrix::zeros(n, k);
    let mut y = DVector::zeros(n);
    for (row, &i) in train.iter().enumerate() {
        for c in 0..3 {
            y[3 * row + c] = r.get(3 * i + c).copied().unwrap_or(0.0);
        }
    }
    let mut col = 0;
    for s in sens {
        for j in 0..s.ncols() {
            for (row, &i) in train.iter().enumerate() {
                for c in 0..3 {
                    x[(3 * row + c, col)] = s.get((3 * i + c, j)).copied().unwrap_or(0.0);
                }
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
    forward::check_kind(machine, obs, obs_file)?;
    let (_, hold) = holdout_split(obs.rows.len(), opts.holdout, opts.seed);
    let mut e = Vec::with_capacity(hold.len());
    for &i in &hold {
        let Some(row) = obs.rows.get(i) else { continue };
        let p = forward::predict(machine, row, obs_file)?;
        e.push(row.measured_mm - p.measured(obs.measured));
    }
    Ok(metrics(&e))
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
