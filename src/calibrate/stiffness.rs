//! Robot joint-stiffness identification (Paper C eq. 6–8).
//!
//! Data: *load groups*. Rows are grouped by identical joint angles and
//! measured point (one configuration of the arm, one measured point); a
//! group holds the unloaded reference row and the rows under one or more
//! loads — as with the loaded double ball bar (LDBB) of Paper C, where each
//! configuration is measured with and without the load. The unknown
//! position of the point without load is a nuisance parameter of every
//! group; it is eliminated by centring each group (least squares with one
//! free offset per group, Frisch–Waugh), so the kinematic errors of the arm,
//! the gravity sag and the registration of the measuring frame cancel. The
//! degrees of freedom lose 3 per group, and the uncertainties are computed
//! with that (sharing one reference row between two loads correlates their
//! loaded − unloaded differences; the centred form accounts for it). A
//! loaded row alone in its group is an error. With instrument-frame data
//! the small rotation of the instrument's frame is identified with the
//! compliances (three more columns of the centred design; its origin
//! cancels), and the origin is the mean offset of the unloaded fit rows
//! from the calibrated model.
//!
//! Model: with the compliances `c_i = 1/kθi` the deflection of a loaded row
//! from its unloaded state is linear in c:
//! `Δx = Σ_i c_i · J_MP[:3, i] · (J_WPᵀ W)_i` (actual kinematics at the
//! commanded joints). The unknowns are `c_i` in µrad/(N·m); they are found by
//! linear least squares ([`super::lsq::solve_linear`]), then two fixed-point corrections
//! remove the second-order part (the deflected Jacobian, the gravity-loaded
//! pose) by evaluating the exact forward model
//! ([`super::forward::predict`]) at the estimate:
//! `y ← y − (Δx_model(c) − A c)`.
//! Rows with a measured orientation add the turn of the tool frame under
//! load, `Δθ = Σ_i c_i · z_i · τ_i` (the angular rows of the Jacobian),
//! centred per group like the positions and weighted by
//! [`Options::orientation_mm_per_rad`] (see [`centred_system`]).
//! Uncertainties: `u(c)` from the residual variance; `u(k) = u(c) / c²`
//! (first-order propagation). A non-positive compliance is refused; an
//! uncertain stiffness ([`super::honesty`]) keeps the file's value.

use std::collections::HashMap;

use nalgebra::{DMatrix, DVector, Isometry3, Matrix3, SMatrix, Vector3, Vector6};

use crate::calibrate::lsq::{LsqOptions, Solution, data_error, solve_for};
use crate::error::{Error, Result};
use crate::machine::Machine;
use crate::machine::robot::kinematics::jacobian;
use crate::machine::robot::{Model, Robot, Trial};

use super::forward::{check_kind, joints_rad, measured_point, predict, row_wrench, wrench_point};
use super::frame::{
    DEG_PER_MRAD, carry, conditional_covariance, estimate, frame_with, point_jacobian,
    screen_model, start_frame, world_note, world_to_reference,
};
use super::observations::{MeasurementFrame, Observation, Observations, Pose, holdout_split};
use super::report::{CONDITION_LIMIT, Calibration, Estimate, FrameEstimate, Validation};
use crate::machine::robot::RobotParam;
use crate::machine::yaml_write::{self, Edit, round_to};

/// Decimals of the joint stiffnesses written, N·m/rad.
const STIFFNESS_DECIMALS: usize = 1;

/// µrad/(N·m) expressed in rad/(N·mm).
const C_UNIT: f64 = 1e-9;

/// Options of a calibration run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Options {
    /// Fraction of the items held out for validation (0 ≤ f < 1).
    pub holdout: f64,
    /// Seed of the reproducible split.
    pub seed: u64,
    /// Weight of the orientation residuals of rows with `qw…qz`: the ratio
    /// of the position noise to the orientation noise, mm per rad (an
    /// orientation residual of θ rad counts like a position residual of
    /// `θ · weight` mm). 0 ignores measured orientations.
    pub orientation_mm_per_rad: f64,
    /// What happens to uncertain parameters ([`super::honesty`]).
    pub honesty: super::honesty::Rule,
}

/// Default ratio of position to orientation noise, mm/rad: a laser tracker
/// with a 6-DOF probe measures position to ≈ 20 µm and orientation to
/// ≈ 0.01° (≈ 0.17 mrad): 0.02 mm / 0.00017 rad ≈ 115 mm/rad, rounded to 100.
pub const ORIENTATION_MM_PER_RAD: f64 = 100.0;

impl Default for Options {
    fn default() -> Self {
        Options {
            holdout: 0.3,
            seed: 1,
            orientation_mm_per_rad: ORIENTATION_MM_PER_RAD,
            honesty: super::honesty::Rule::default(),
        }
    }
}

fn key(obs: &Observations, i: usize) -> Option<Vec<u64>> {
    let row = obs.rows.get(i)?;
    let Pose::Robot(rp) = &row.pose else {
        return None;
    };
    let mut k: Vec<u64> = rp.q_deg.iter().map(|v| v.to_bits()).collect();
    match rp.mp_mm {
        Some(p) => k.extend(p.iter().map(|v| v.to_bits())),
        None => k.push(u64::MAX),
    }
    Some(k)
}

fn loaded(r: &Observation) -> bool {
    r.force_n != Vector3::zeros() || r.moment_nm != Vector3::zeros()
}

/// Groups the rows by joint angles and measured point (row indices, in
/// file order). Groups without a loaded row carry no stiffness information
/// and are dropped; a loaded row alone in its group is an error. `file`
/// names the observation file in errors.
pub fn load_groups(obs: &Observations, file: &str) -> Result<Vec<Vec<usize>>> {
    let mut index: HashMap<Vec<u64>, usize> = HashMap::new();
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for i in 0..obs.rows.len() {
        let Some(k) = key(obs, i) else { continue };
        let g = *index.entry(k).or_insert_with(|| {
            groups.push(Vec::new());
            groups.len() - 1
        });
        if let Some(v) = groups.get_mut(g) {
            v.push(i);
        }
    }
    let mut orphans = Vec::new();
    groups.retain(|g| {
        let n_loaded = g
            .iter()
            .filter(|&&i| obs.rows.get(i).is_some_and(loaded))
            .count();
        if n_loaded > 0 && g.len() == 1 {
            if let Some(r) = g.first().and_then(|&i| obs.rows.get(i)) {
                orphans.push(format!("{} (line {})", r.id, r.line));
            }
        }
        n_loaded > 0 && g.len() > 1
    });
    if !orphans.is_empty() {
        let shown: Vec<&str> = orphans.iter().take(5).map(String::as_str).collect();
        return Err(Error::Data(format!(
            "{file}: {} loaded row(s) have no other row at the same joint angles and \
             measured point: {}{}; the stiffness is identified from the differences between \
             the load states of one configuration (measure every configuration also \
             without the load)",
            orphans.len(),
            shown.join(", "),
            if orphans.len() > 5 { ", …" } else { "" }
        )));
    }
    if groups.is_empty() {
        return Err(Error::Data(format!(
            "{file}: no row has a force or moment (fx_n … mz_nm): nothing deflects the \
             joints, the stiffness cannot be identified"
        )));
    }
    Ok(groups)
}

/// Design block (6 × 6) of one row: `A[r, i] = J_MP[r, i] · τ_i · C_UNIT`
/// with `τ = J_WPᵀ W` (zero for an unloaded row); rows 0..3 the measured
/// point's deflection (mm), rows 3..6 the flange's small rotation (rad).
fn design_block(robot: &Robot, row: &Observation) -> SMatrix<f64, 6, 6> {
    let mut a = SMatrix::<f64, 6, 6>::zeros();
    let Pose::Robot(rp) = &row.pose else {
        return a;
    };
    let q = joints_rad(rp);
    let f = robot.frames(Model::Actual, &q);
    let jmp = jacobian(&f, &measured_point(robot, rp));
    let jwp = jacobian(&f, &wrench_point(robot, rp));
    let tau = jwp.transpose() * row_wrench(row);
    for i in 0..6 {
        for r in 0..6 {
            a[(r, i)] = jmp[(r, i)] * tau[i] * C_UNIT;
        }
    }
    a
}

/// Exact model deflection of a row from its unloaded state: the measured
/// point's (mm), then the rotation vector of the tool frame's turn (rad).
fn model_deflection(m: &Machine, row: &Observation, file: &str) -> Result<Vector6<f64>> {
    if !loaded(row) {
        return Ok(Vector6::zeros());
    }
    let mut free = row.clone();
    free.force_n = Vector3::zeros();
    free.moment_nm = Vector3::zeros();
    let (a, b) = (predict(m, row, file)?, predict(m, &free, file)?);
    let d = a.attained_mm - b.attained_mm;
    let t = match (a.attained_rot, b.attained_rot) {
        (Some(qa), Some(qb)) => (qa * qb.inverse()).scaled_axis(),
        _ => Vector3::zeros(),
    };
    Ok(Vector6::new(d.x, d.y, d.z, t.x, t.y, t.z))
}

/// Subtracts the mean of rows `[start, end)` (3-vectors) from the design
/// and the observations.
fn center(a: &mut DMatrix<f64>, y: &mut DVector<f64>, start: usize, end: usize) {
    if end <= start {
        return;
    }
    let n = (end - start) as f64;
    for r in 0..3 {
        let idx: Vec<usize> = (start..end).map(|k| 3 * k + r).collect();
        let ym = idx.iter().map(|&i| y[i]).sum::<f64>() / n;
        for &i in &idx {
            y[i] -= ym;
        }
        for c in 0..a.ncols() {
            let am = idx.iter().map(|&i| a[(i, c)]).sum::<f64>() / n;
            for &i in &idx {
                a[(i, c)] -= am;
            }
        }
    }
}

/// Joint stiffnesses, N·m/rad, of the compliances `c` (in [`C_UNIT`]).
fn stiffness_from(c: &DVector<f64>) -> [f64; 6] {
    std::array::from_fn(|i| 1.0 / (c[i] * C_UNIT) / 1000.0)
}

/// The part of the exact model the linear design misses, per row (given
/// the row's design block): the point's (mm), then the rotation's (rad).
type SecondOrder<'a> = dyn Fn(&Observation, &SMatrix<f64, 6, 6>) -> Result<Vector6<f64>> + 'a;

/// Columns of the frame's small rotation in the centred design.
const ROT_PARAMS: usize = 3;

/// Equations of the centred system of the fit groups and the degrees of
/// freedom its centring takes: 3 per row and per group for the positions,
/// and, with orientations weighted (`w_rot > 0`), 3 per row with a
/// measured orientation and per group that has one.
fn equations(obs: &Observations, fit: &[Vec<usize>], w_rot: f64) -> (usize, usize) {
    let mut m = 0;
    let mut lost = 0;
    for g in fit {
        let rot = if w_rot > 0.0 {
            g.iter()
                .filter(|&&i| obs.rows.get(i).is_some_and(|r| r.orientation.is_some()))
                .count()
        } else {
            0
        };
        m += 3 * (g.len() + rot);
        lost += 3 * (1 + usize::from(rot > 0));
    }
    (m, lost)
}

/// The centred system of the fit groups (rows in group order): the design
/// of the compliances (6 columns) and, with an instrument frame `f`, the
/// negated columns of the frame's small rotation (its origin cancels in
/// the centring); the observations are the measured points carried by `f`
/// minus `second(row)` (the part of the exact model the design misses).
/// With `w_rot > 0` the rows with a measured orientation add, after all
/// positions, the turn of the measured frame from the group's first such
/// row (rotation vector, carried by `f`), centred per group and weighted
/// by `w_rot` (mm/rad); the frame's rotation turns every one of a group's
/// orientations alike, so it cancels there.
fn centred_system(
    robot: &Robot,
    obs: &Observations,
    fit: &[Vec<usize>],
    f: Option<&Isometry3<f64>>,
    w_rot: f64,
    second: &SecondOrder<'_>,
) -> Result<(DMatrix<f64>, DVector<f64>)> {
    let (m, _) = equations(obs, fit, w_rot);
    let m_pos = 3 * fit.iter().map(Vec::len).sum::<usize>();
    let nr = if f.is_some() { ROT_PARAMS } else { 0 };
    let mut a = DMatrix::zeros(m, 6 + nr);
    let mut y = DVector::zeros(m);
    let mut k = 0;
    let mut kr = m_pos / 3;
    let rot = f.map_or(nalgebra::UnitQuaternion::identity(), |f| f.rotation);
    for g in fit {
        let start = k;
        let start_r = kr;
        let mut reference = None;
        for &i in g {
            let Some(row) = obs.rows.get(i) else { continue };
            let blk = design_block(robot, row);
            let miss = second(row, &blk)?;
            a.view_mut((3 * k, 0), (3, 6))
                .copy_from(&blk.fixed_rows::<3>(0));
            let meas = match f {
                Some(f) => {
                    let j = point_jacobian(f, &row.measured_mm);
                    a.view_mut((3 * k, 6), (3, ROT_PARAMS))
                        .copy_from(&(-j.fixed_columns::<3>(3)));
                    carry(f, &row.measured_mm)
                }
                None => row.measured_mm,
            };
            y.rows_mut(3 * k, 3)
                .copy_from(&(meas - miss.fixed_rows::<3>(0)));
            k += 1;
            if let (true, Some(q)) = (w_rot > 0.0, row.orientation) {
                let q = rot * q;
                let q0 = *reference.get_or_insert(q);
                let turn = (q * q0.inverse()).scaled_axis();
                a.view_mut((3 * kr, 0), (3, 6))
                    .copy_from(&(blk.fixed_rows::<3>(3) * w_rot));
                y.rows_mut(3 * kr, 3)
                    .copy_from(&((turn - miss.fixed_rows::<3>(3)) * w_rot));
                kr += 1;
            }
        }
        center(&mut a, &mut y, start, k);
        center(&mut a, &mut y, start_r, kr);
    }
    Ok((a, y))
}

/// Refuses a design whose compliances are not identified or badly
/// conditioned.
fn check_identified(sol: &Solution, obs_file: &str) -> Result<()> {
    let id = &sol.identifiability;
    if !id.unidentifiable.is_empty() {
        let names: Vec<String> = id
            .unidentifiable
            .iter()
            .map(|&i| {
                if i < 6 {
                    format!("k{}", i + 1)
                } else {
                    format!("the instrument frame's rotation {}", i - 5)
                }
            })
            .collect();
        return Err(Error::Data(format!(
            "{obs_file}: badly conditioned data set: the stiffness of {} cannot be identified \
             (the loads do not twist these joints independently of the others; O1 = {:.3e}). \
             Load the arm in more directions and configurations",
            names.join(", "),
            id.observability_o1
        )));
    }
    if id.condition_number_identified > CONDITION_LIMIT {
        return Err(Error::Data(format!(
            "{obs_file}: badly conditioned data set: condition number {:.3e} > {:.0e} \
             (O1 = {:.3e}); the joint compliances are nearly linearly dependent in these \
             data (e.g. all loads in one direction). Vary the load direction and the \
             configuration",
            id.condition_number_identified, CONDITION_LIMIT, id.observability_o1
        )));
    }
    Ok(())
}

/// The identified compliances: the linear solution, then two fixed-point
/// corrections with the exact forward model; with an instrument frame its
/// small rotation is found with them (the frame moves to each solution).
/// Returns the solution and the final frame.
fn solve_compliances(
    robot: &Robot,
    obs: &Observations,
    fit: &[Vec<usize>],
    f0: Option<Isometry3<f64>>,
    w_rot: f64,
    obs_file: &str,
) -> Result<(Solution, Option<Isometry3<f64>>)> {
    let lsq = LsqOptions::default();
    let solve = |a: &DMatrix<f64>, b: &DVector<f64>| -> Result<Solution> {
        solve_for(a, b, &lsq, obs_file)
    };
    let turn = |f: Option<Isometry3<f64>>, sol: &Solution| {
        f.map(|f| {
            let d: Vec<f64> = (0..6)
                .map(|k| if k < 3 { 0.0 } else { sol.params[k + 3] })
                .collect();
            frame_with(&f, &d)
        })
    };
    let none = |_: &Observation, _: &SMatrix<f64, 6, 6>| Ok(Vector6::zeros());
    let (a, y) = centred_system(robot, obs, fit, f0.as_ref(), w_rot, &none)?;
    if f0.is_some() {
        screen_model(
            &a.columns(0, 6).into_owned(),
            Some(&a.columns(6, ROT_PARAMS).into_owned()),
            &y,
            &lsq,
        )
        .map_err(|e| data_error(obs_file, e))?;
    }
    let mut sol = solve(&a, &y)?;
    check_identified(&sol, obs_file)?;
    let mut f = turn(f0, &sol);
    // Second-order correction with the exact forward model.
    for _ in 0..2 {
        let c = sol.params.rows(0, 6).into_owned();
        if c.iter().any(|&c| c <= 0.0) {
            break;
        }
        let trial =
            Machine::Robot(robot.trial_with_params(&[Trial::JointStiffness(stiffness_from(&c))]));
        let second = |row: &Observation, blk: &SMatrix<f64, 6, 6>| -> Result<Vector6<f64>> {
            Ok(model_deflection(&trial, row, obs_file)?
                - blk * Vector6::from_column_slice(c.as_slice()))
        };
        let (a, y) = centred_system(robot, obs, fit, f.as_ref(), w_rot, &second)?;
        sol = solve(&a, &y)?;
        f = turn(f, &sol);
    }
    Ok((sol, f))
}

/// The instrument frame's rotation re-solved alone for the stiffnesses of
/// `calibrated` as written (some kept at the file's value): the rotation
/// columns of the centred system, with the exact deflections of
/// `calibrated` removed, solved twice from `f` (the frame moves to each
/// solution).
fn refit_rotation(
    robot: &Robot,
    calibrated: &Machine,
    obs: &Observations,
    fit: &[Vec<usize>],
    mut f: Isometry3<f64>,
    w_rot: f64,
    obs_file: &str,
) -> Result<Isometry3<f64>> {
    let deflection = |row: &Observation, _: &SMatrix<f64, 6, 6>| -> Result<Vector6<f64>> {
        model_deflection(calibrated, row, obs_file)
    };
    for _ in 0..2 {
        let (a, y) = centred_system(robot, obs, fit, Some(&f), w_rot, &deflection)?;
        let rot = a.columns(6, ROT_PARAMS).into_owned();
        let s = solve_for(&rot, &y, &LsqOptions::default(), obs_file)?;
        f = frame_with(&f, &[0.0, 0.0, 0.0, s.params[0], s.params[1], s.params[2]]);
    }
    Ok(f)
}

/// The origin of an instrument frame of rotation `f.rotation`: the mean of
/// `p_i − R m_i` over the unloaded fit rows `p_i` of the calibrated model
/// `m`. Its standard uncertainty per coordinate combines that of the mean
/// with the rotation's (covariance `cov_rot`, mrad²) carried over the lever
/// `R m̄` of the mean measured point (`None` below two rows). The load
/// differences do not see the origin.
fn frame_origin(
    m: &Machine,
    f: &Isometry3<f64>,
    cov_rot: Option<Matrix3<f64>>,
    obs: &Observations,
    fit: &[Vec<usize>],
    obs_file: &str,
) -> Result<(Isometry3<f64>, Option<[f64; 3]>)> {
    let mut d = Vec::new();
    let mut lever = Vector3::zeros();
    for row in fit.iter().flatten().filter_map(|&i| obs.rows.get(i)) {
        if !loaded(row) {
            let v = f.rotation * row.measured_mm;
            d.push(predict(m, row, obs_file)?.attained_mm - v);
            lever += v;
        }
    }
    let n = d.len();
    if n == 0 {
        return Ok((*f, None));
    }
    let mean = d.iter().sum::<Vector3<f64>>() / n as f64;
    let j = (lever / n as f64).cross_matrix() * 1e-3;
    let turned = cov_rot.map(|c| j * c * j.transpose());
    let u = (n > 1).then_some(()).and(turned).map(|t| {
        std::array::from_fn(|r| {
            let ss: f64 = d.iter().map(|v| (v[r] - mean[r]).powi(2)).sum();
            (ss / (n - 1) as f64 / n as f64 + t[(r, r)]).max(0.0).sqrt()
        })
    });
    Ok((
        Isometry3::from_parts(nalgebra::Translation3::from(mean), f.rotation),
        u,
    ))
}

/// The note of a stiffness run on instrument-frame data.
const FRAME_NOTE: &str = "positions measured in an instrument frame: its rotation is \
    identified together with the stiffnesses (from the load differences); its origin, which \
    load differences do not see, is the mean offset of the unloaded rows from the calibrated \
    model (its uncertainty that of the mean and of the rotation over the lever of the \
    points); written to `measurement_frame`";

/// The identified instrument frame of a stiffness run: the rotation `f`
/// with the uncertainties of the joint solution `sol` given the
/// compliances at `fixed` (kept at the file's value; scaled by
/// `dof_factor`), the origin from [`frame_origin`].
fn frame_estimate(
    calibrated: &Machine,
    f: &Isometry3<f64>,
    (sol, fixed): (&Solution, &[usize]),
    dof_factor: f64,
    obs: &Observations,
    fit: &[Vec<usize>],
    obs_file: &str,
) -> Result<FrameEstimate> {
    let cov_rot = sol
        .covariance
        .as_ref()
        .and_then(|c| conditional_covariance(c, &[6, 7, 8], fixed))
        .map(|c| Matrix3::from_fn(|r, k| c[(r, k)]) * (dof_factor * dof_factor));
    let (f, u_xyz) = frame_origin(calibrated, f, cov_rot, obs, fit, obs_file)?;
    let u_rot = cov_rot.map(|c| std::array::from_fn(|r| c[(r, r)].max(0.0).sqrt() * DEG_PER_MRAD));
    Ok(FrameEstimate {
        u_xyz_mm: u_xyz,
        u_rot_deg: u_rot,
        ..estimate(&f, None)
    })
}

/// Residual norms of the loaded held-out rows' deflections (from their
/// group's unloaded row, turned by the frame's rotation for instrument
/// data) against the model, before and after: each side a machine and its
/// frame.
fn held_out_deflections(
    before_model: (&Machine, Option<&Isometry3<f64>>),
    after_model: (&Machine, Option<&Isometry3<f64>>),
    obs: &Observations,
    hold: &[Vec<usize>],
    obs_file: &str,
) -> Result<(Vec<f64>, Vec<f64>)> {
    let rot = |f: Option<&Isometry3<f64>>, v: Vector3<f64>| f.map_or(v, |f| f.rotation * v);
    let mut before = Vec::new();
    let mut after = Vec::new();
    for g in hold {
        let reference = g
            .iter()
            .filter_map(|&i| obs.rows.get(i))
            .find(|r| !loaded(r));
        let Some(u0) = reference else { continue };
        for row in g
            .iter()
            .filter_map(|&i| obs.rows.get(i))
            .filter(|r| loaded(r))
        {
            let meas = row.measured_mm - u0.measured_mm;
            let (m0, f0) = before_model;
            let (m1, f1) = after_model;
            let d0 = model_deflection(m0, row, obs_file)?
                .fixed_rows::<3>(0)
                .into_owned();
            let d1 = model_deflection(m1, row, obs_file)?
                .fixed_rows::<3>(0)
                .into_owned();
            before.push((rot(f0, meas) - d0).norm());
            after.push((rot(f1, meas) - d1).norm());
        }
    }
    Ok((before, after))
}

/// Load groups: the row indices of each group.
type Groups = Vec<Vec<usize>>;

/// The load groups of `obs` ([`load_groups`]) split into the fitted and the
/// held-out ones (whole groups, [`holdout_split`] with the run's options).
fn split_groups(obs: &Observations, obs_file: &str, opts: &Options) -> Result<(Groups, Groups)> {
    let groups = load_groups(obs, obs_file)?;
    let (fit_idx, hold_idx) = holdout_split(groups.len(), opts.holdout, opts.seed);
    let pick = |idx: &[usize]| -> Vec<Vec<usize>> {
        idx.iter().filter_map(|&i| groups.get(i).cloned()).collect()
    };
    Ok((pick(&fit_idx), pick(&hold_idx)))
}

/// The six joint stiffnesses (N·m/rad) from the compliances of `sol`, with
/// their uncertainties scaled by `dof_factor` (the redundancy the centring
/// used up); refused when a compliance comes out non-positive.
fn stiffness_estimates(
    robot: &Robot,
    sol: &Solution,
    dof_factor: f64,
    obs_file: &str,
) -> Result<Vec<Estimate>> {
    let c = sol.params.rows(0, 6).into_owned();
    if let Some(i) = c.iter().position(|&c| c <= 0.0) {
        let u = sol
            .std_uncertainty()
            .map(|u| u[i] * dof_factor)
            .unwrap_or(f64::NAN);
        return Err(Error::Data(format!(
            "{obs_file}: the compliance of joint {} came out non-positive ({:.4} ± {:.4} \
             µrad/(N·m)), i.e. a non-positive stiffness, which no real joint has. This \
             usually means a sign or frame error in the data (the force acting ON the \
             robot is expected, in the robot base frame; the wrench point in the flange \
             frame; joint angles in the controller convention), or a joint the loads hardly \
             twist, so its compliance is zero within the noise",
            i + 1,
            c[i],
            u
        )));
    }
    let k_nm = stiffness_from(&c);
    let uc = sol.std_uncertainty().map(|u| u * dof_factor);
    let mut params = Vec::with_capacity(6);
    for i in 0..6 {
        let k = k_nm[i];
        let u = uc.as_ref().map(|u| u[i] / (c[i] * c[i] * C_UNIT) / 1000.0);
        params.push(Estimate {
            name: format!("k{}", i + 1),
            unit: "N·m/rad",
            start: robot.k_nm_per_rad()[i],
            value: k,
            u,
            fixed: false,
        });
    }
    Ok(params)
}

/// Identifies the joint stiffnesses from the load pairs of `obs` (with
/// the instrument frame for `# frame: instrument` data).
/// `text`/`machine_file`: the machine file (edited into the result).
pub fn calibrate_stiffness(
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
            "{machine_file}: stiffness calibration needs a robot machine file"
        )));
    };
    // World positions are carried into the base frame (and said so).
    let world = world_note(&machine, obs.frame);
    let obs = &world_to_reference(&machine, obs);
    let (fit, hold) = split_groups(obs, obs_file, opts)?;
    let fit_rows: Vec<usize> = fit.iter().flatten().copied().collect();
    let n_loaded = fit_rows
        .iter()
        .filter(|&&i| obs.rows.get(i).is_some_and(loaded))
        .count();
    let (m, dof_lost) = equations(obs, &fit, opts.orientation_mm_per_rad);
    let instrument = obs.frame == MeasurementFrame::Instrument;
    let nr = if instrument { ROT_PARAMS } else { 0 };
    if m < dof_lost + 18 + 3 * nr {
        return Err(Error::Data(format!(
            "{obs_file}: {n_loaded} loaded row(s) in {} group(s) left for the fit; 6 \
             stiffnesses need at least 18 equations beyond the unloaded references, \
             better tens of loaded rows",
            fit.len()
        )));
    }
    tracing::info!(
        "stiffness: {} groups ({n_loaded} loaded rows) for the fit, {} held out",
        fit.len(),
        hold.len()
    );
    let f0 = if instrument {
        Some(start_frame(&machine, obs, &fit_rows, obs_file)?)
    } else {
        None
    };
    let w_rot = opts.orientation_mm_per_rad;
    let (sol, f_rot) = solve_compliances(robot, obs, &fit, f0, w_rot, obs_file)?;
    let id = sol.identifiability.clone();
    // The centring used 3 degrees of freedom per group.
    let dof_true = m.saturating_sub(dof_lost + 6 + nr);
    if dof_true == 0 {
        return Err(Error::Data(format!(
            "{obs_file}: no redundancy left for the uncertainty (equations = unknowns)"
        )));
    }
    let dof_factor = (sol.dof as f64 / dof_true as f64).sqrt();
    let params = stiffness_estimates(robot, &sol, dof_factor, obs_file)?;
    // Uncertain stiffnesses keep the file's value (super::honesty).
    let withheld = opts.honesty.withheld(&params);
    let uncertain = opts.honesty.uncertain(&params);
    let written: [f64; 6] = std::array::from_fn(|i| match params.get(i) {
        Some(p) if withheld.get(i) == Some(&true) => p.start,
        Some(p) => p.value,
        None => 0.0,
    });
    let calibrated = Machine::Robot(robot.trial_with_params(&[Trial::JointStiffness(written)]));
    let fixed: Vec<usize> = (0..6).filter(|&i| withheld.get(i) == Some(&true)).collect();
    let f_rot = match f_rot {
        Some(f) if !fixed.is_empty() => Some(refit_rotation(
            robot,
            &calibrated,
            obs,
            &fit,
            f,
            w_rot,
            obs_file,
        )?),
        other => other,
    };
    let (before, after) = held_out_deflections(
        (&machine, f0.as_ref()),
        (&calibrated, f_rot.as_ref()),
        obs,
        &hold,
        obs_file,
    )?;
    let mut edits: Vec<Edit> = written
        .iter()
        .enumerate()
        .map(|(joint, &k)| {
            Edit::Robot(
                RobotParam::JointStiffness { joint },
                round_to(k, STIFFNESS_DECIMALS),
            )
        })
        .collect();
    let mut notes: Vec<String> = world.into_iter().collect();
    notes.extend(obs.orientation_note(w_rot, None));
    let frame = match &f_rot {
        Some(f) => {
            let est = frame_estimate(
                &calibrated,
                f,
                (&sol, &fixed),
                dof_factor,
                obs,
                &fit,
                obs_file,
            )?;
            edits.push(Edit::MeasurementFrame {
                xyz_mm: est.xyz_mm,
                rpy_deg: est.rpy_deg,
            });
            notes.push(FRAME_NOTE.into());
            Some(est)
        }
        None => None,
    };
    let yaml = yaml_write::apply(text, machine_file, "postproc calibrate stiffness", &edits)?;
    Machine::from_yaml_str(&yaml, machine_file)
        .map_err(|e| super::screen::implausible(&e, obs_file, obs.rows.len()))?;
    Ok(Calibration {
        kind: "stiffness",
        n_fit: n_loaded,
        n_equations: m,
        observability_o1: 0.0,
        condition_number: 0.0,
        rms_fit_mm: (sol.rss / dof_true as f64).sqrt(),
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
    .finished(&id))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calibrate::observations::RobotPose;
    use approx::assert_abs_diff_eq;

    /// Finite-difference agreement of the linear design, mm per µrad/(N·m).
    const FD_TOL: f64 = 1e-6;

    fn robot() -> Robot {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/machines/abb-irb1600.yaml");
        match Machine::load(std::path::Path::new(path)) {
            Ok(Machine::Robot(r)) => r,
            _ => panic!("robot file"),
        }
    }

    fn row(force: Vector3<f64>) -> Observation {
        Observation {
            orientation: None,
            line: 2,
            id: "r".into(),
            t_s: None,
            measured_mm: Vector3::zeros(),
            force_n: force,
            moment_nm: Vector3::new(0.0, 5.0, 0.0),
            ambient_c: None,
            pose: Pose::Robot(RobotPose {
                q_deg: [-20.0, 15.0, 10.0, 40.0, 50.0, -30.0],
                mp_mm: Some(Vector3::new(20.0, 20.0, 35.0)),
                wp_mm: Some(Vector3::new(-14.0, -14.0, 35.0)),
                p_w: [None; 6],
                dir: [None; 6],
            }),
        }
    }

    /// Column i of the design is ∂Δx/∂c_i at c = 0: compare with a central
    /// difference of the exact forward model's loaded − unloaded deflection
    /// over the compliance of joint i, on a weightless arm (no gravity sag)
    /// at a tiny compliance (c = 1e-4 µrad/(N·m), Δc = ±1e-5), where the
    /// deflected-pose terms the solver corrects for separately vanish.
    #[test]
    fn design_matches_finite_differences_of_the_forward_model() {
        let r0 = robot();
        let weightless = std::array::from_fn(|_| crate::machine::robot::PointMass {
            mass_kg: 0.0,
            com_mm: Vector3::zeros(),
        });
        let r = r0
            .trial_with_params(&[Trial::Links(weightless)])
            .with_tool(*r0.flange_to_tool(), None);
        let obs_row = row(Vector3::new(120.0, -200.0, -250.0));
        let a = design_block(&r, &obs_row);
        let c0 = [1e-4; 6];
        let h = 1e-5;
        for i in 0..6 {
            let at = |dc: f64| {
                let mut c = c0;
                c[i] += dc;
                let k: [f64; 6] = std::array::from_fn(|j| 1.0 / (c[j] * C_UNIT));
                let m = Machine::Robot(
                    r.trial_with_params(&[Trial::JointStiffness(k.map(|v| v / 1000.0))]),
                );
                model_deflection(&m, &obs_row, "t").unwrap()
            };
            let fd = (at(h) - at(-h)) / (2.0 * h);
            assert_abs_diff_eq!(fd, a.column(i).into_owned(), epsilon = FD_TOL);
        }
    }

    /// Centring: a group of rows with observations y and design rows A loses
    /// its mean; for two rows (0, a) → (−a/2, a/2).
    #[test]
    fn centring_removes_the_group_mean() {
        let mut a = DMatrix::zeros(6, 6);
        let mut y = DVector::zeros(6);
        a[(3, 0)] = 2.0;
        y[4] = 4.0;
        center(&mut a, &mut y, 0, 2);
        assert_abs_diff_eq!(a[(0, 0)], -1.0, epsilon = 1e-15);
        assert_abs_diff_eq!(a[(3, 0)], 1.0, epsilon = 1e-15);
        assert_abs_diff_eq!(y[1], -2.0, epsilon = 1e-15);
        assert_abs_diff_eq!(y[4], 2.0, epsilon = 1e-15);
    }
}
