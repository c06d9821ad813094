//! Thermal calibration of a robot: the Paper B terms of the machine file's
//! `thermal:` section, `Δp = ub − lb · exp(−ts · P)` (mm) per DH length and
//! driving joint power, identified by Levenberg–Marquardt from rows measured
//! at the thermal steady state of several mean joint powers (`p1_w…p6_w`).
//!
//! Only the terms the file declares are fitted (the coupling is a modelling
//! choice, Paper B Table 2); each has three unknowns `lb` (mm), `ub` (mm) and
//! `ts` (1/W, handled internally per kW so the unknowns have comparable
//! sizes). The forward model is [`forward::predict_robot_with_growth`]: the
//! actual DH lengths grown by the trial terms, with gravity sag and the row
//! loads as in every other calibration. Rows without any power column keep
//! the file's lengths (as in [`forward::predict`]) and only anchor the cold
//! geometry.
//!
//! Identifiability: a term whose joint power takes a single value in the
//! fitted rows is fixed (all three unknowns) and listed; the remaining
//! columns go through the rank-revealing analysis of [`super::lsq::solve_linear`] at the
//! start point (e.g. two terms on the same length share the constant `ub`
//! direction, so one `ub` is fixed; with fewer than three power levels `ts`
//! cannot be told from `lb`). The time constant is not identified: rows at
//! the steady state carry no time information. Uncertain unknowns
//! ([`super::honesty`]) keep the file's value, in both kinds.
//!
//! Machine tools ([`calibrate_tool_thermal`]): the steady-state gains of the
//! file's `thermal:` section from rows with powers — the spindle growth
//! `growth_um_per_kw` from `spindle_w` (added to the file when absent) and
//! the positioning scale `scale_ppm_per_kw` of each axis with a
//! `thermal.axes` entry from its `pX_w`. The forward model is linear in
//! them, so it is one linear least-squares step on the residuals of the
//! file's model ([`super::lsq::solve_linear`], same identifiability analysis).
//!
//! Robot rows with a measured orientation add the rotation vector of
//! `measured · predicted⁻¹` weighted by
//! [`super::stiffness::Options::orientation_mm_per_rad`], as in the
//! kinematic calibration; the machine-tool model predicts positions only
//! and says that it leaves orientations out.
//!
//! Both kinds identify an instrument frame (`# frame: instrument`) with
//! their unknowns: its six parameters beside the model's, the model's
//! screened against them ([`super::frame::screen_model`]).

use nalgebra::{DMatrix, DVector, Isometry3, Vector3};

use crate::calibrate::lsq::{
    LmOptions, LsqOptions, Solution, data_error, expand_free, fit_free, numeric_jacobian, solve_for,
};
use crate::error::{Error, Result};
use crate::machine::Machine;
use crate::machine::robot::thermal::DhLength;
use crate::machine::robot::{DhGrowth, Robot, ThermalTerm};
use crate::machine::tool::MachineTool;

use super::forward::{self, check_kind};
use super::frame::{
    FRAME_PARAMS, FRAME_RANK_RTOL, carry, conditional_uncertainty, finish, finish_if_any,
    frame_with, point_jacobian, refit, screen_model, start_frame, world_note, world_to_reference,
};
use super::honesty::zero_withheld;
use super::observations::{MeasurementFrame, Observations, Pose, holdout_split};
use super::report::{CONDITION_LIMIT, Calibration, Estimate, FrameEstimate, Validation, names_at};
use super::stiffness::Options;
use crate::machine::robot::{RobotParam, ThermalField};
use crate::machine::tool::ToolParam;
use crate::machine::yaml_write::{self, Edit, round_sig, round_to};

/// Decimals of the thermal lengths and gains written (mm, µm/kW, ppm/kW).
const THERMAL_DECIMALS: usize = 6;
/// Time constant of a new spindle entry, min: assumed, since rows at the
/// thermal steady state carry no time information.
const ASSUMED_TIME_CONSTANT_MIN: f64 = 30.0;

/// Internal unit of `ts`: per kW (1/W × 1000).
const TS_SCALE: f64 = 1000.0;

/// Relative rank threshold (unit-norm columns): an unknown whose effect,
/// beyond what the others explain, is below 10⁻³ of the strongest one is
/// practically unidentifiable and fixed (as in the kinematic calibration).
pub const THERMAL_RANK_RTOL: f64 = 1e-3;

/// Iteration limit of Levenberg–Marquardt.
const MAX_ITERATIONS: usize = 60;

/// Forward-difference step (mm for lb/ub, per kW for ts).
const FD_STEP: f64 = 1e-6;

/// Largest accepted `ts`, 1/W (e^−(ts·1 W) would already be 0 at 1 W).
const TS_MAX: f64 = 10.0;

/// The joint powers of a robot row, W, or `None` when it gives none.
pub fn row_powers(row: &crate::calibrate::observations::Observation) -> Option<[f64; 6]> {
    match &row.pose {
        Pose::Robot(rp) if rp.p_w.iter().any(Option::is_some) => {
            Some(rp.p_w.map(|p| p.unwrap_or(0.0)))
        }
        _ => None,
    }
}

/// Sum of the growth of `terms` at the powers `p_w`, mm.
pub fn growth(terms: &[ThermalTerm], p_w: &[f64; 6]) -> DhGrowth {
    let mut g = [[0.0; 2]; 6];
    for t in terms {
        let p = p_w.get(t.joint).copied().unwrap_or(0.0);
        if let Some(row) = g.get_mut(t.row) {
            row[t.length as usize] += t.growth_mm(p);
        }
    }
    g
}

fn term_name(t: &ThermalTerm) -> String {
    let l = match t.length {
        DhLength::A => 'a',
        DhLength::D => 'd',
    };
    format!("{l}{}←P{}", t.row + 1, t.joint + 1)
}

/// The terms for the correction vector `x` (3 per term: Δlb mm, Δub mm,
/// Δts per kW).
fn terms_with(base: &[ThermalTerm], x: &[f64]) -> Vec<ThermalTerm> {
    base.iter()
        .enumerate()
        .map(|(k, t)| {
            let v = |o: usize| x.get(3 * k + o).copied().unwrap_or(0.0);
            ThermalTerm {
                lb_mm: t.lb_mm + v(0),
                ub_mm: t.ub_mm + v(1),
                ts_per_w: t.ts_per_w + v(2) / TS_SCALE,
                ..*t
            }
        })
        .collect()
}

/// The terms' unknowns and, for instrument-frame data, the frame's six
/// parameters after them.
struct Unknowns<'a> {
    robot: &'a Robot,
    base: &'a [ThermalTerm],
    /// Start pose of the instrument frame (instrument data only).
    frame: Option<Isometry3<f64>>,
    /// Weight of the orientation residuals, mm/rad (0: none).
    w_rot: f64,
}

impl Unknowns<'_> {
    /// Equations of a row: 3 for the position, 3 more for a measured
    /// orientation when orientations are weighted.
    fn eqs(&self, row: &crate::calibrate::observations::Observation) -> usize {
        if self.w_rot > 0.0 && row.orientation.is_some() {
            6
        } else {
            3
        }
    }

    /// Equations of `rows`.
    fn equations(&self, obs: &Observations, rows: &[usize]) -> usize {
        rows.iter()
            .map(|&i| obs.rows.get(i).map_or(3, |r| self.eqs(r)))
            .sum()
    }

    /// Number of model unknowns (3 per term).
    fn n_model(&self) -> usize {
        3 * self.base.len()
    }

    fn n(&self) -> usize {
        self.n_model()
            + if self.frame.is_some() {
                FRAME_PARAMS
            } else {
                0
            }
    }

    /// The instrument frame for the unknowns `x` (identity without one).
    fn frame_at(&self, x: &[f64]) -> Isometry3<f64> {
        match &self.frame {
            Some(f0) => frame_with(f0, x.get(self.n_model()..).unwrap_or(&[])),
            None => Isometry3::identity(),
        }
    }
}

fn residuals(
    u: &Unknowns<'_>,
    obs: &Observations,
    rows: &[usize],
    x: &[f64],
    out: &mut DVector<f64>,
    file: &str,
) {
    let terms = terms_with(u.base, x);
    let f = u.frame_at(x);
    let mut at = 0;
    for &i in rows {
        let Some(row) = obs.rows.get(i) else { continue };
        let eqs = u.eqs(row);
        let g = row_powers(row).map_or([[0.0; 2]; 6], |p| growth(&terms, &p));
        match forward::predict_robot_with_growth(u.robot, row, &g, file) {
            Ok(p) => {
                let d = carry(&f, &row.measured_mm) - p.measured(obs.measured);
                for r in 0..3 {
                    out[at + r] = d[r];
                }
                if eqs == 6 {
                    let e = match (row.orientation, p.attained_rot) {
                        (Some(q), Some(pr)) => {
                            (f.rotation * q * pr.inverse()).scaled_axis() * u.w_rot
                        }
                        _ => Vector3::zeros(),
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

fn norms(
    robot: &Robot,
    terms: &[ThermalTerm],
    f: &Isometry3<f64>,
    obs: &Observations,
    rows: &[usize],
    file: &str,
) -> Result<Vec<f64>> {
    let mut v = Vec::with_capacity(rows.len());
    for &i in rows {
        if let Some(row) = obs.rows.get(i) {
            let g = row_powers(row).map_or([[0.0; 2]; 6], |p| growth(terms, &p));
            let p = forward::predict_robot_with_growth(robot, row, &g, file)?;
            v.push((carry(f, &row.measured_mm) - p.measured(obs.measured)).norm());
        }
    }
    Ok(v)
}

/// Which terms' joint power varies in the fitted rows (the others are
/// fixed, said in `notes`).
fn varying_terms(
    base: &[ThermalTerm],
    obs: &Observations,
    fit: &[usize],
    notes: &mut Vec<String>,
) -> Vec<bool> {
    let mut varies = vec![true; base.len()];
    for (k, t) in base.iter().enumerate() {
        let ps: Vec<f64> = fit
            .iter()
            .filter_map(|&i| obs.rows.get(i).and_then(row_powers))
            .filter_map(|p| p.get(t.joint).copied())
            .collect();
        let lo = ps.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = ps.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let spread = hi - lo;
        if spread.is_nan() || spread <= 1e-9 {
            varies[k] = false;
            notes.push(format!(
                "term {}: the power of joint {} never varies in the fitted rows; \
                 its lb, ub and ts are fixed at the file's values",
                term_name(t),
                t.joint + 1
            ));
        }
    }
    varies
}

/// The identifiability screen at the start point over the unknowns of the
/// varying terms (`candidates`), with the frame's columns beside them for
/// instrument data. Returns (free unknowns, frame last; model unknowns the
/// frame absorbs).
fn screen_unknowns(
    u: &Unknowns<'_>,
    obs: &Observations,
    fit: &[usize],
    candidates: &[usize],
    lm_opts: &LmOptions,
    obs_file: &str,
) -> Result<(Vec<usize>, Vec<usize>)> {
    let n = u.n();
    let nm = u.n_model();
    let m = u.equations(obs, fit);
    let mut r0 = DVector::zeros(m);
    residuals(u, obs, fit, &vec![0.0; n], &mut r0, obs_file);
    if r0.iter().any(|v| !v.is_finite()) {
        return Err(Error::Data(format!(
            "{obs_file}: the model cannot be evaluated for some rows"
        )));
    }
    let frame_cols: Vec<usize> = (nm..n).collect();
    if candidates.is_empty() {
        return Ok((frame_cols, Vec::new()));
    }
    let cols: Vec<usize> = candidates.iter().chain(&frame_cols).copied().collect();
    let j0 = numeric_jacobian(
        |x, r| {
            let full = expand_free(n, &cols, x.as_slice());
            residuals(u, obs, fit, &full, r, obs_file);
        },
        &DVector::zeros(cols.len()),
        m,
        lm_opts.fd_relative_step,
    );
    let jm = j0.columns(0, candidates.len()).into_owned();
    let jf = u
        .frame
        .map(|_| j0.columns(candidates.len(), FRAME_PARAMS).into_owned());
    let (given, plain) =
        screen_model(&jm, jf.as_ref(), &r0, &lm_opts.lsq).map_err(|e| data_error(obs_file, e))?;
    let free: Vec<usize> = candidates
        .iter()
        .enumerate()
        .filter(|(a, _)| !given.contains(a))
        .map(|(_, &k)| k)
        .chain(frame_cols)
        .collect();
    let absorbed: Vec<usize> = given
        .iter()
        .filter(|a| !plain.contains(a))
        .filter_map(|&a| candidates.get(a).copied())
        .collect();
    Ok((free, absorbed))
}

/// The report's rows: three unknowns per term, identified (with their
/// uncertainty) or kept; `true` when some unknown of a varying term was
/// fixed by the rank screen.
fn term_estimates(
    base: &[ThermalTerm],
    varies: &[bool],
    free: &[usize],
    full: &[f64],
    u_red: Option<&DVector<f64>>,
) -> (Vec<Estimate>, bool) {
    let mut params = Vec::with_capacity(3 * base.len());
    let mut any_fixed_by_rank = false;
    for (k, t) in base.iter().enumerate() {
        let name = term_name(t);
        for (o, (key, unit, start, scale)) in [
            ("lb", "mm", t.lb_mm, 1.0),
            ("ub", "mm", t.ub_mm, 1.0),
            ("ts", "1/W", t.ts_per_w, 1.0 / TS_SCALE),
        ]
        .into_iter()
        .enumerate()
        {
            let j = 3 * k + o;
            let pos = free.iter().position(|&f| f == j);
            if pos.is_none() && varies.get(k) == Some(&true) {
                any_fixed_by_rank = true;
            }
            params.push(Estimate {
                name: format!("{name}.{key}"),
                unit,
                start,
                value: start + scale * full.get(j).copied().unwrap_or(0.0),
                u: pos.and_then(|a| u_red.map(|u| scale * u[a])),
                fixed: pos.is_none(),
            });
        }
    }
    (params, any_fixed_by_rank)
}

/// Refuses a fitted `ts` outside `0..TS_MAX`.
fn check_ts(terms: &[ThermalTerm], obs_file: &str) -> Result<()> {
    for t in terms {
        if !(t.ts_per_w.is_finite() && (0.0..=TS_MAX).contains(&t.ts_per_w)) {
            return Err(Error::Data(format!(
                "{obs_file}: term {}: the fit gives ts = {} 1/W, outside 0..{TS_MAX}; \
                 the data do not support this term's exponential form (too few power \
                 levels, or the coupling is not in the data)",
                term_name(t),
                t.ts_per_w
            )));
        }
    }
    Ok(())
}

/// The calibrated file: the terms' lines and, for instrument data, the
/// frame (with its notes: what it absorbs, that it was identified).
fn write_terms(
    text: &str,
    machine_file: &str,
    terms: &[ThermalTerm],
    frame: Option<(Isometry3<f64>, Option<[f64; FRAME_PARAMS]>)>,
    absorbed: &[String],
    notes: &mut Vec<String>,
) -> Result<(String, Option<FrameEstimate>)> {
    let mut edits = Vec::with_capacity(3 * terms.len());
    for (term, t) in terms.iter().enumerate() {
        for (field, v) in [
            (ThermalField::Lb, round_to(t.lb_mm, THERMAL_DECIMALS)),
            (ThermalField::Ub, round_to(t.ub_mm, THERMAL_DECIMALS)),
            (ThermalField::Ts, round_sig(t.ts_per_w)),
        ] {
            edits.push(Edit::Robot(RobotParam::Thermal { term, field }, v));
        }
    }
    let yaml = yaml_write::apply(text, machine_file, "postproc calibrate thermal", &edits)?;
    let Some((f, u)) = frame else {
        return Ok((yaml, None));
    };
    let (yaml, est) = finish(
        &yaml,
        machine_file,
        &f,
        u,
        absorbed,
        "a growth that shifts every point alike moves the frame's origin",
        notes,
    )?;
    Ok((yaml, Some(est)))
}

/// Points in millimetres, one per row.
type Points = Vec<Vector3<f64>>;

/// The measured points of `rows` and the positions the robot with the
/// thermal `terms` predicts for them.
fn robot_points(
    robot: &Robot,
    terms: &[ThermalTerm],
    obs: &Observations,
    rows: &[usize],
    file: &str,
) -> Result<(Points, Points)> {
    let mut meas = Vec::with_capacity(rows.len());
    let mut model = Vec::with_capacity(rows.len());
    for row in rows.iter().filter_map(|&i| obs.rows.get(i)) {
        let g = row_powers(row).map_or([[0.0; 2]; 6], |p| growth(terms, &p));
        let p = forward::predict_robot_with_growth(robot, row, &g, file)?;
        meas.push(row.measured_mm);
        model.push(p.measured(obs.measured));
    }
    Ok((meas, model))
}

/// The notes of a robot thermal fit: unknowns the rank analysis fixed
/// (`any_fixed_by_rank`), and the time constant.
fn fit_notes(any_fixed_by_rank: bool, notes: &mut Vec<String>) {
    if any_fixed_by_rank {
        notes.push(
            "some unknowns move the measured points like a combination of the others \
             (e.g. the ub of two terms on the same length, or ts with too few power levels); \
             they keep the file's value"
                .into(),
        );
    }
    notes.push(
        "rows are at the thermal steady state of their powers: time_constant_min is not identified"
            .into(),
    );
}

/// The thermal terms of the robot's file (start values of the fit), refused
/// when the file declares none or no row of `obs` gives joint powers.
fn thermal_terms(
    robot: &Robot,
    obs: &Observations,
    machine_file: &str,
    obs_file: &str,
) -> Result<Vec<ThermalTerm>> {
    let base: Vec<ThermalTerm> = robot.thermal().map(|t| t.terms.clone()).unwrap_or_default();
    if base.is_empty() {
        return Err(Error::Machine(crate::error::Located::whole_file(
            machine_file,
            "no thermal terms to identify; add a `thermal:` section with \
             `time_constant_min` and the `terms` (DH length ← joint power, Paper B Table 2: \
             a2 ← P1, P2; d4 ← P1, P2, P3; a3 ← P2, P3) with start values",
        )));
    }
    if !obs.rows.iter().any(|r| row_powers(r).is_some()) {
        return Err(Error::Data(format!(
            "{obs_file}: no row gives joint powers (p1_w…p6_w); thermal calibration needs \
             rows measured at the steady state of several power levels"
        )));
    }
    Ok(base)
}

/// The instrument frame written with the terms written (`terms`, from
/// `full` with the `withheld` unknowns at zero) and its uncertainties from
/// the joint fit `sol` over the `free` unknowns: the fitted frame when
/// nothing is withheld, else refitted to the model as written.
fn robot_frame(
    unknowns: &Unknowns,
    (sol, free): (&Solution, &[usize]),
    (full, withheld): (&[f64], &[bool]),
    terms: &[ThermalTerm],
    obs: &Observations,
    fit: &[usize],
    obs_file: &str,
) -> Result<(Isometry3<f64>, Option<[f64; FRAME_PARAMS]>)> {
    let n = unknowns.n();
    let at = |k: usize| free.iter().position(|&f| f == k);
    let frame_cols: Vec<usize> = (unknowns.n_model()..n).filter_map(at).collect();
    let fixed: Vec<usize> = (0..unknowns.n_model())
        .filter(|&j| withheld.get(j) == Some(&true))
        .filter_map(at)
        .collect();
    let joint = conditional_uncertainty(sol.covariance.as_ref(), &frame_cols, &fixed);
    if fixed.is_empty() {
        Ok((unknowns.frame_at(full), joint))
    } else {
        let (meas, model) = robot_points(unknowns.robot, terms, obs, fit, obs_file)?;
        refit(&meas, &model, joint, obs_file)
    }
}

/// Refuses a fit of `n` unknowns with fewer than two equations per
/// unknown from its `n_rows` rows (three equations each).
fn check_enough_rows(n_rows: usize, n: usize, obs_file: &str) -> Result<()> {
    let m = 3 * n_rows;
    if m < 2 * n {
        return Err(Error::Data(format!(
            "{obs_file}: {n_rows} rows left for the fit ({m} equations) for {n} parameters; \
             thermal calibration needs at least {} rows, better several times more",
            (2 * n).div_ceil(3)
        )));
    }
    Ok(())
}

/// Refuses a badly conditioned fit of the robot terms.
fn check_condition(id: &crate::calibrate::lsq::Identifiability, obs_file: &str) -> Result<()> {
    if id.condition_number_identified > CONDITION_LIMIT {
        return Err(Error::Data(format!(
            "{obs_file}: badly conditioned data set: condition number {:.3e} > {:.0e} \
             (O1 = {:.3e}); the power levels do not excite the thermal terms independently. \
             Measure at more power levels, varying the joints' powers independently",
            id.condition_number_identified, CONDITION_LIMIT, id.observability_o1
        )));
    }
    Ok(())
}

/// Identifies the Paper B terms of the robot file `text` from `obs` (and
/// the instrument frame for `# frame: instrument` data).
pub fn calibrate_thermal(
    text: &str,
    machine_file: &str,
    obs: &Observations,
    obs_file: &str,
    opts: &Options,
) -> Result<Calibration> {
    let machine = Machine::from_yaml_str(text, machine_file)?;
    check_kind(&machine, obs, obs_file)?;
    let robot = match &machine {
        Machine::Robot(r) => r,
        Machine::Tool(_) => {
            return calibrate_tool_thermal(text, machine_file, &machine, obs, obs_file, opts);
        }
    };
    // World positions are carried into the base frame (and said so).
    let world = world_note(&machine, obs.frame);
    let obs = &world_to_reference(&machine, obs);
    let base = thermal_terms(robot, obs, machine_file, obs_file)?;
    let (fit, hold) = holdout_split(obs.rows.len(), opts.holdout, opts.seed);
    let frame = if obs.frame == MeasurementFrame::Instrument {
        Some(start_frame(&machine, obs, &fit, obs_file)?)
    } else {
        None
    };
    let unknowns = Unknowns {
        robot,
        base: &base,
        frame,
        w_rot: opts.orientation_mm_per_rad,
    };
    let n = unknowns.n();
    let m = unknowns.equations(obs, &fit);
    check_enough_rows(fit.len(), n, obs_file)?;
    // Terms whose power never varies in the fitted rows are fixed.
    let mut notes = Vec::new();
    let varies = varying_terms(&base, obs, &fit, &mut notes);
    let candidates: Vec<usize> = (0..unknowns.n_model()).filter(|&k| varies[k / 3]).collect();
    let lm_opts = LmOptions {
        max_iterations: MAX_ITERATIONS,
        lsq: LsqOptions {
            rank_rtol: THERMAL_RANK_RTOL,
            scale_columns: true,
        },
        ..LmOptions::default()
    };
    let (free, absorbed) = screen_unknowns(&unknowns, obs, &fit, &candidates, &lm_opts, obs_file)?;
    if free.iter().all(|&k| k >= unknowns.n_model()) {
        return Err(Error::Data(format!(
            "{obs_file}: no thermal parameter can be identified from these rows: \
             measure at several power levels of the joints the terms name"
        )));
    }
    // Forward differences (half the cost of central ones); the growth is
    // smooth on the scale of FD_STEP (1e-6 mm, 1e-6/kW).
    let fit_result = fit_free(
        |x, out| residuals(&unknowns, obs, &fit, x, out, obs_file),
        n,
        &free,
        m,
        FD_STEP,
        &lm_opts,
    )
    .map_err(|e| data_error(obs_file, e))?;
    let sol = &fit_result.solution;
    let id = &sol.identifiability;
    check_condition(id, obs_file)?;
    let full = expand_free(n, &free, sol.params.as_slice());
    check_ts(&terms_with(&base, &full), obs_file)?;
    let u_red = sol.std_uncertainty();
    let (params, any_fixed_by_rank) = term_estimates(&base, &varies, &free, &full, u_red.as_ref());
    fit_notes(any_fixed_by_rank, &mut notes);
    // Uncertain unknowns keep the file's value (super::honesty).
    let withheld = opts.honesty.withheld(&params);
    let uncertain = opts.honesty.uncertain(&params);
    let mut full = full;
    zero_withheld(&mut full, &withheld);
    let terms = terms_with(&base, &full);
    let f_start = unknowns.frame_at(&[]);
    let frame = match unknowns.frame {
        Some(_) => Some(robot_frame(
            &unknowns,
            (sol, &free),
            (&full, &withheld),
            &terms,
            obs,
            &fit,
            obs_file,
        )?),
        None => None,
    };
    let f_end = frame.map_or(Isometry3::identity(), |(f, _)| f);
    let before = norms(robot, &base, &f_start, obs, &hold, obs_file)?;
    let after = norms(robot, &terms, &f_end, obs, &hold, obs_file)?;
    let names = names_at(&params, &absorbed);
    let (yaml, frame) = write_terms(text, machine_file, &terms, frame, &names, &mut notes)?;
    Machine::from_yaml_str(&yaml, machine_file)
        .map_err(|e| super::screen::implausible(&e, obs_file, obs.rows.len()))?;
    notes.extend(world);
    notes.extend(obs.orientation_note(opts.orientation_mm_per_rad, None));
    Ok(Calibration {
        kind: "thermal",
        n_fit: fit.len(),
        n_equations: m,
        observability_o1: 0.0,
        condition_number: 0.0,
        rms_fit_mm: sol.rms_fit(m),
        params,
        validation: Validation::from_norms(&before, &after),
        fit_check: None,
        frame,
        insignificant: Vec::new(),
        uncertain,
        honesty: opts.honesty,
        notes,
        yaml,
        covariance: None,
    }
    .finished(id))
}

/// Residual norms of the rows `rows` for a machine and the instrument
/// frame `f` (identity for reference-frame data), mm.
fn machine_norms(
    m: &Machine,
    f: &Isometry3<f64>,
    obs: &Observations,
    rows: &[usize],
    file: &str,
) -> Result<Vec<f64>> {
    let mut v = Vec::with_capacity(rows.len());
    for &i in rows {
        if let Some(row) = obs.rows.get(i) {
            let p = forward::predict(m, row, file)?;
            v.push((carry(f, &row.measured_mm) - p.measured(obs.measured)).norm());
        }
    }
    Ok(v)
}

/// The unknowns of a machine-tool thermal calibration that the rows can
/// identify: 0 = spindle (µm/kW), 1..4 = X, Y, Z scale (ppm/kW); what is
/// left out is said in `notes`.
fn tool_unknowns(
    tool: &MachineTool,
    obs: &Observations,
    obs_file: &str,
    notes: &mut Vec<String>,
) -> Result<Vec<usize>> {
    let thermal = tool.thermal().copied().unwrap_or_default();
    let powers = |i: usize| -> Vec<f64> {
        obs.rows
            .iter()
            .filter_map(|r| match &r.pose {
                Pose::Tool(tp) => forward::tool_powers(tp),
                Pose::Robot(_) => None,
            })
            .filter_map(|p| p.get(i).copied())
            .collect()
    };
    let varies = |v: &[f64]| {
        let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        hi - lo > 1e-9
    };
    let mut unknowns: Vec<usize> = Vec::new();
    if varies(&powers(0)) {
        unknowns.push(0);
    } else {
        notes.push("spindle_w does not vary in the rows: spindle growth not identified".into());
    }
    for a in 0..3 {
        let name = ["X", "Y", "Z"][a];
        if !varies(&powers(a + 1)) {
            continue;
        }
        if thermal.axes[a].is_some() {
            unknowns.push(a + 1);
        } else {
            notes.push(format!(
                "p{name}_w varies but the file has no thermal.axes.{name} entry (time constant, \
                 friction) to write a scale into: not identified"
            ));
        }
    }
    if unknowns.is_empty() {
        return Err(Error::Data(format!(
            "{obs_file}: no thermal gain can be identified: the rows need spindle_w (or pX_w \
             for an axis with a thermal.axes entry) at several power levels"
        )));
    }
    Ok(unknowns)
}

/// The linear problem of a machine-tool thermal calibration on the fit
/// rows: the design (one column per unknown, then the negated frame
/// columns at `f` for instrument data) and the residuals of the file's
/// model, the measured points carried by `f`.
fn tool_design(
    machine: &Machine,
    tool: &MachineTool,
    obs: &Observations,
    fit: &[usize],
    unknowns: &[usize],
    f: Option<&Isometry3<f64>>,
    obs_file: &str,
) -> Result<(DMatrix<f64>, DVector<f64>)> {
    let m = 3 * fit.len();
    let nf = if f.is_some() { FRAME_PARAMS } else { 0 };
    let mut a = DMatrix::zeros(m, unknowns.len() + nf);
    let mut b = DVector::zeros(m);
    let id = Isometry3::identity();
    for (k, &i) in fit.iter().enumerate() {
        let Some(row) = obs.rows.get(i) else { continue };
        let Pose::Tool(tp) = &row.pose else { continue };
        let p = forward::predict(machine, row, obs_file)?;
        let d = carry(f.unwrap_or(&id), &row.measured_mm) - p.measured(obs.measured);
        let pw = forward::tool_powers(tp).unwrap_or([0.0; 4]);
        let cmd = tp.axes();
        let dir = tool.nominal(&cmd, forward::tool_length(tool, tp)).dir;
        for r in 0..3 {
            b[3 * k + r] = d[r];
        }
        for (c, &u) in unknowns.iter().enumerate() {
            if u == 0 {
                // g µm/kW × P/1000 kW, tip moves against the tool axis, mm.
                for r in 0..3 {
                    a[(3 * k + r, c)] = -dir[r] * pw[0] * 1e-6;
                }
            } else {
                // s ppm/kW × P/1000 kW × q mm × 1e-6, along the axis.
                let ax = u - 1;
                a[(3 * k + ax, c)] = cmd[ax] * pw[u] * 1e-9;
            }
        }
        if let Some(f) = f {
            a.view_mut((3 * k, unknowns.len()), (3, FRAME_PARAMS))
                .copy_from(&(-point_jacobian(f, &row.measured_mm)));
        }
    }
    Ok((a, b))
}

/// Solves the machine-tool thermal problem; for instrument data the frame
/// is found with the gains: the model columns the frame explains (to within
/// [`FRAME_RANK_RTOL`]) are zeroed (they keep the file's value) and the
/// linearisation of the frame is repeated once at the first solution.
/// Returns the solution, the final frame and the model columns the frame
/// absorbs.
fn solve_tool(
    machine: &Machine,
    tool: &MachineTool,
    obs: &Observations,
    fit: &[usize],
    unknowns: &[usize],
    f0: Option<Isometry3<f64>>,
    obs_file: &str,
) -> Result<(Solution, Option<Isometry3<f64>>, Vec<usize>)> {
    let lsq = LsqOptions::default();
    let solve = |a: &DMatrix<f64>, b: &DVector<f64>| solve_for(a, b, &lsq, obs_file);
    let nu = unknowns.len();
    let Some(f) = f0 else {
        let (a, b) = tool_design(machine, tool, obs, fit, unknowns, None, obs_file)?;
        return Ok((solve(&a, &b)?, None, Vec::new()));
    };
    let (a, b) = tool_design(machine, tool, obs, fit, unknowns, Some(&f), obs_file)?;
    let jm = a.columns(0, nu).into_owned();
    let jf = a.columns(nu, FRAME_PARAMS).into_owned();
    let screen = LsqOptions {
        rank_rtol: FRAME_RANK_RTOL,
        scale_columns: true,
    };
    let (given, plain) =
        screen_model(&jm, Some(&jf), &b, &screen).map_err(|e| data_error(obs_file, e))?;
    let absorbed: Vec<usize> = given.into_iter().filter(|c| !plain.contains(c)).collect();
    // The solution at `f`, and the frame moved to it.
    let step = |f: &Isometry3<f64>| -> Result<(Solution, Isometry3<f64>)> {
        let (mut a, b) = tool_design(machine, tool, obs, fit, unknowns, Some(f), obs_file)?;
        for &c in &absorbed {
            a.column_mut(c).fill(0.0);
        }
        let s = solve(&a, &b)?;
        let d: Vec<f64> = (nu..nu + FRAME_PARAMS).map(|k| s.params[k]).collect();
        let moved = frame_with(f, &d);
        Ok((s, moved))
    };
    let (_, f1) = step(&f)?;
    let (sol, f2) = step(&f1)?;
    Ok((sol, Some(f2), absorbed))
}

/// The instrument frame written with the machine-tool gains of
/// `calibrated`, with its uncertainties: the joint fit's frame `f`
/// (columns `nu..` of `sol`) when every identified gain is written, else
/// the frame re-solved alone for the written gains (those at `withheld`
/// keep the file's value, [`refit`]).
fn tool_frame(
    calibrated: &Machine,
    obs: &Observations,
    fit: &[usize],
    (f, sol): (Isometry3<f64>, &Solution),
    nu: usize,
    withheld: &[usize],
    obs_file: &str,
) -> Result<(Isometry3<f64>, Option<[f64; FRAME_PARAMS]>)> {
    let frame_cols: Vec<usize> = (nu..nu + FRAME_PARAMS).collect();
    let joint = conditional_uncertainty(sol.covariance.as_ref(), &frame_cols, withheld);
    if withheld.is_empty() {
        return Ok((f, joint));
    }
    let mut meas = Vec::with_capacity(fit.len());
    let mut model = Vec::with_capacity(fit.len());
    for row in fit.iter().filter_map(|&i| obs.rows.get(i)) {
        meas.push(row.measured_mm);
        model.push(forward::predict(calibrated, row, obs_file)?.measured(obs.measured));
    }
    refit(&meas, &model, joint, obs_file)
}

/// The estimates of the tool's thermal gains (`unknowns` as
/// [`tool_unknowns`]) from the solution `sol` of their corrections, with the
/// indices of the identified ones the honesty rule withholds and the file
/// `text` with the others written (the spindle growth with its assumed time
/// constant, the axis scales).
fn tool_estimates(
    text: &str,
    machine_file: &str,
    tool: &MachineTool,
    unknowns: &[usize],
    sol: &Solution,
    opts: &Options,
) -> Result<(Vec<Estimate>, Vec<usize>, String)> {
    let thermal = tool.thermal().copied().unwrap_or_default();
    let id = &sol.identifiability;
    let u = sol.std_uncertainty();
    let mut params = Vec::new();
    let mut withheld = Vec::new();
    let mut edits = Vec::new();
    for (c, &k) in unknowns.iter().enumerate() {
        let fixed = id.unidentifiable.contains(&c);
        let delta = sol.params.get(c).copied().unwrap_or(0.0);
        let uc = if fixed {
            None
        } else {
            u.as_ref().and_then(|u| u.get(c).copied())
        };
        if k == 0 {
            let start = thermal.spindle.map_or(0.0, |s| s.gain_per_kw);
            let est = Estimate {
                name: "spindle.growth".into(),
                unit: "µm/kW",
                start,
                value: start + delta,
                u: uc,
                fixed,
            };
            let write = !fixed && !opts.honesty.withholds(&est);
            if !fixed && !write {
                withheld.push(c);
            }
            params.push(est);
            if write {
                let growth = round_to(start + delta, THERMAL_DECIMALS);
                edits.push(if thermal.spindle.is_some() {
                    Edit::Tool(ToolParam::SpindleGrowth, growth)
                } else {
                    Edit::Spindle {
                        growth_um_per_kw: growth,
                        time_constant_min: ASSUMED_TIME_CONSTANT_MIN,
                        comment: "postproc calibrate thermal: time_constant_min is ASSUMED (steady-state rows carry no time information)".into(),
                    }
                });
            }
        } else {
            let name = ["X", "Y", "Z"][k - 1];
            let start = thermal.axes[k - 1].map_or(0.0, |s| s.gain_per_kw);
            let est = Estimate {
                name: format!("{name}.scale"),
                unit: "ppm/kW",
                start,
                value: start + delta,
                u: uc,
                fixed,
            };
            let write = !fixed && !opts.honesty.withholds(&est);
            if !fixed && !write {
                withheld.push(c);
            }
            params.push(est);
            if write {
                let scale = round_to(start + delta, THERMAL_DECIMALS);
                edits.push(Edit::Tool(ToolParam::AxisScale { axis: k - 1 }, scale));
            }
        }
    }
    let yaml = yaml_write::apply(text, machine_file, "postproc calibrate thermal", &edits)?;
    Ok((params, withheld, yaml))
}

/// Identifies the steady-state thermal gains of a machine-tool file: spindle
/// `growth_um_per_kw` (rows with `spindle_w`) and `scale_ppm_per_kw` of the
/// axes that have a `thermal.axes` entry (rows with `pX_w` …); and the
/// instrument frame for `# frame: instrument` data.
pub fn calibrate_tool_thermal(
    text: &str,
    machine_file: &str,
    machine: &Machine,
    obs: &Observations,
    obs_file: &str,
    opts: &Options,
) -> Result<Calibration> {
    let Machine::Tool(tool) = machine else {
        return Err(Error::Usage(format!(
            "{machine_file}: not a machine-tool file"
        )));
    };
    let mut notes = Vec::new();
    let unknowns = tool_unknowns(tool, obs, obs_file, &mut notes)?;
    let (fit, hold) = holdout_split(obs.rows.len(), opts.holdout, opts.seed);
    let m = 3 * fit.len();
    let instrument = obs.frame == MeasurementFrame::Instrument;
    let nf = if instrument { FRAME_PARAMS } else { 0 };
    if m < 2 * (unknowns.len() + nf) {
        return Err(Error::Data(format!(
            "{obs_file}: {} rows left for the fit; too few",
            fit.len()
        )));
    }
    let f0 = if instrument {
        Some(start_frame(machine, obs, &fit, obs_file)?)
    } else {
        None
    };
    let (sol, frame, absorbed) = solve_tool(machine, tool, obs, &fit, &unknowns, f0, obs_file)?;
    let id = &sol.identifiability;
    if id.condition_number_identified > CONDITION_LIMIT {
        return Err(Error::Data(format!(
            "{obs_file}: badly conditioned data set: condition number {:.3e} > {:.0e}",
            id.condition_number_identified, CONDITION_LIMIT
        )));
    }
    let (params, withheld, yaml) = tool_estimates(text, machine_file, tool, &unknowns, &sol, opts)?;
    notes.push(
        "rows are at the thermal steady state of their powers: time constants are not identified"
            .into(),
    );
    notes.extend(obs.orientation_note(
        opts.orientation_mm_per_rad,
        Some(super::observations::TOOL_ORIENTATION_UNUSED),
    ));
    let uncertain = opts.honesty.uncertain(&params);
    // The frame goes with the gains as written (measurement_frame itself
    // plays no part in a prediction).
    let calibrated = Machine::from_yaml_str(&yaml, machine_file)?;
    let frame = match frame {
        Some(f) => Some(tool_frame(
            &calibrated,
            obs,
            &fit,
            (f, &sol),
            unknowns.len(),
            &withheld,
            obs_file,
        )?),
        None => None,
    };
    let (yaml, frame_est) = finish_if_any(
        yaml,
        machine_file,
        frame,
        (&params, &absorbed),
        "a growth that moves every point alike moves the frame's origin",
        &mut notes,
    )?;
    let id_frame = Isometry3::identity();
    let before = machine_norms(
        machine,
        f0.as_ref().unwrap_or(&id_frame),
        obs,
        &hold,
        obs_file,
    )?;
    let after = machine_norms(
        &calibrated,
        &frame.map_or(id_frame, |(f, _)| f),
        obs,
        &hold,
        obs_file,
    )?;
    Ok(Calibration {
        kind: "thermal",
        n_fit: fit.len(),
        n_equations: m,
        observability_o1: 0.0,
        condition_number: 0.0,
        rms_fit_mm: sol.rms_fit(m),
        params,
        validation: Validation::from_norms(&before, &after),
        fit_check: None,
        frame: frame_est,
        insignificant: Vec::new(),
        uncertain,
        honesty: opts.honesty,
        notes,
        yaml,
        covariance: None,
    }
    .finished(id))
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    const LEN_TOL_MM: f64 = 1e-12;

    /// Paper B form by hand: ub − lb·e^(−ts·P); a2 ← P1 with lb = ub = 0.1,
    /// ts = 0.015 at P1 = 126 W: 0.1·(1 − e^(−1.89)) = 0.1·(1 − 0.151072)
    /// = 0.0848928 mm; a second term on a2 ← P2 (0.12, 0.12, 0.02) at
    /// 112 W adds 0.12·(1 − e^(−2.24)) = 0.12·(1 − 0.106459) = 0.1072249.
    #[test]
    fn growth_sums_terms_by_hand() {
        let t = |joint, lb, ts| ThermalTerm {
            length: DhLength::A,
            row: 1,
            joint,
            lb_mm: lb,
            ub_mm: lb,
            ts_per_w: ts,
        };
        let terms = [t(0, 0.10, 0.015), t(1, 0.12, 0.020)];
        let g = growth(&terms, &[126.0, 112.0, 0.0, 0.0, 0.0, 0.0]);
        let want = 0.1 * (1.0 - (-1.89f64).exp()) + 0.12 * (1.0 - (-2.24f64).exp());
        assert_abs_diff_eq!(g[1][0], want, epsilon = LEN_TOL_MM);
        assert_abs_diff_eq!(g[1][0], 0.0848928 + 0.1072249, epsilon = 1e-6);
        assert_abs_diff_eq!(g[2][0], 0.0, epsilon = LEN_TOL_MM);
        // The correction vector moves lb, ub (mm) and ts (per kW).
        let moved = terms_with(&terms, &[0.01, 0.02, 5.0]);
        assert_abs_diff_eq!(moved[0].lb_mm, 0.11, epsilon = LEN_TOL_MM);
        assert_abs_diff_eq!(moved[0].ub_mm, 0.12, epsilon = LEN_TOL_MM);
        assert_abs_diff_eq!(moved[0].ts_per_w, 0.020, epsilon = LEN_TOL_MM);
    }

    /// ∂growth/∂ts = lb·P·e^(−ts·P) against a central difference.
    #[test]
    fn ts_sensitivity_matches_finite_difference() {
        let t = ThermalTerm {
            length: DhLength::D,
            row: 3,
            joint: 2,
            lb_mm: 0.08,
            ub_mm: 0.07,
            ts_per_w: 0.03,
        };
        let p = [0.0, 0.0, 35.0, 0.0, 0.0, 0.0];
        let h = 1e-3; // per kW
        let gp = growth(&terms_with(&[t], &[0.0, 0.0, h]), &p)[3][1];
        let gm = growth(&terms_with(&[t], &[0.0, 0.0, -h]), &p)[3][1];
        let fd = (gp - gm) / (2.0 * h) * TS_SCALE;
        let analytic = 0.08 * 35.0 * (-0.03f64 * 35.0).exp();
        assert_abs_diff_eq!(fd, analytic, epsilon = 1e-8);
    }
}
