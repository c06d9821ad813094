//! Robot joint-stiffness identification (Paper C eq. 6–8, MODELS.md §2).
//!
//! Data: *load pairs*. Rows are grouped by identical joint angles and
//! measured point; in every group the row without force and moment is the
//! unloaded reference and every loaded row forms a pair with it. The measured
//! deflection of a pair is loaded − unloaded (positions or deviations alike),
//! which cancels the kinematic errors of the arm, the gravity sag and the
//! registration of the measuring frame — as with the loaded double ball bar
//! (LDBB) of Paper C, where each configuration is measured with and without
//! the load. A loaded row without an unloaded partner is an error.
//!
//! Model: with the compliances `c_i = 1/kθi` every pair's deflection is
//! linear in c: `Δx = Σ_i c_i · J_MP[:3, i] · (J_WPᵀ W)_i` (actual kinematics
//! at the commanded joints). The unknowns are `c_i` in µrad/(N·m); they are
//! found by linear least squares ([`solve_linear`]), then two fixed-point
//! corrections remove the second-order part (the deflected Jacobian, the
//! gravity-loaded pose) by evaluating the exact forward model
//! ([`super::forward::predict`]) at the estimate: `b ← b − (Δx_model(c) − A c)`.
//! Uncertainties: `u(c)` from the residual variance; `u(k) = u(c) / c²`
//! (first-order propagation). A non-positive compliance is refused.

use std::collections::HashMap;

use nalgebra::{DMatrix, DVector, Vector3};

use crate::calibrate::lsq::{LsqOptions, Solution, solve_linear};
use crate::error::{Error, Result};
use crate::machine::Machine;
use crate::machine::robot::kinematics::jacobian;
use crate::machine::robot::{Model, Robot};

use super::forward::{check_kind, joints_rad, measured_point, predict, row_wrench, wrench_point};
use super::observations::{Observations, Pose, holdout_split};
use super::report::{CONDITION_LIMIT, Calibration, Estimate, Validation};
use super::yaml_edit::{fmt_value, set_top_level_list};

/// µrad/(N·m) expressed in rad/(N·mm).
const C_UNIT: f64 = 1e-9;

/// Options of a calibration run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Options {
    /// Fraction of the items held out for validation (0 ≤ f < 1).
    pub holdout: f64,
    /// Seed of the reproducible split.
    pub seed: u64,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            holdout: 0.3,
            seed: 1,
        }
    }
}

/// A loaded row and its unloaded reference (row indices).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LoadPair {
    /// The row with a force or moment.
    pub loaded: usize,
    /// The row at the same joints and measured point without a load.
    pub unloaded: usize,
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

/// Pairs every loaded row with the unloaded row of the same joints and
/// measured point. `file` names the observation file in errors.
pub fn load_pairs(obs: &Observations, file: &str) -> Result<Vec<LoadPair>> {
    let mut reference: HashMap<Vec<u64>, usize> = HashMap::new();
    for (i, r) in obs.rows.iter().enumerate() {
        if r.force_n == Vector3::zeros() && r.moment_nm == Vector3::zeros() {
            if let Some(k) = key(obs, i) {
                reference.entry(k).or_insert(i);
            }
        }
    }
    let mut pairs = Vec::new();
    let mut orphans = Vec::new();
    for (i, r) in obs.rows.iter().enumerate() {
        if r.force_n == Vector3::zeros() && r.moment_nm == Vector3::zeros() {
            continue;
        }
        match key(obs, i).and_then(|k| reference.get(&k)) {
            Some(&u) => pairs.push(LoadPair {
                loaded: i,
                unloaded: u,
            }),
            None => orphans.push(format!("{} (line {})", r.id, r.line)),
        }
    }
    if !orphans.is_empty() {
        let shown: Vec<&str> = orphans.iter().take(5).map(String::as_str).collect();
        return Err(Error::Usage(format!(
            "{file}: {} loaded row(s) have no unloaded row at the same joint angles and \
             measured point: {}{}; the stiffness is identified from loaded − unloaded \
             differences (measure every configuration also without the load)",
            orphans.len(),
            shown.join(", "),
            if orphans.len() > 5 { ", …" } else { "" }
        )));
    }
    if pairs.is_empty() {
        return Err(Error::Usage(format!(
            "{file}: no row has a force or moment (fx_n … mz_nm): nothing deflects the \
             joints, the stiffness cannot be identified"
        )));
    }
    Ok(pairs)
}

/// Design block (3 × 6) of one pair: `A[r, i] = J_MP[r, i] · τ_i · C_UNIT`.
fn design_block(
    robot: &Robot,
    obs: &Observations,
    p: LoadPair,
) -> Option<nalgebra::SMatrix<f64, 3, 6>> {
    let row = obs.rows.get(p.loaded)?;
    let Pose::Robot(rp) = &row.pose else {
        return None;
    };
    let q = joints_rad(rp);
    let f = robot.frames(Model::Actual, &q);
    let jmp = jacobian(&f, &measured_point(robot, rp));
    let jwp = jacobian(&f, &wrench_point(robot, rp));
    let tau = jwp.transpose() * row_wrench(row);
    let mut a = nalgebra::SMatrix::<f64, 3, 6>::zeros();
    for i in 0..6 {
        for r in 0..3 {
            a[(r, i)] = jmp[(r, i)] * tau[i] * C_UNIT;
        }
    }
    Some(a)
}

/// Measured deflection of a pair, mm.
fn measured_deflection(obs: &Observations, p: LoadPair) -> Vector3<f64> {
    match (obs.rows.get(p.loaded), obs.rows.get(p.unloaded)) {
        (Some(l), Some(u)) => l.measured_mm - u.measured_mm,
        _ => Vector3::zeros(),
    }
}

/// Model deflection of a pair (exact forward model), mm.
fn model_deflection(
    m: &Machine,
    obs: &Observations,
    p: LoadPair,
    file: &str,
) -> Result<Vector3<f64>> {
    let (Some(l), Some(u)) = (obs.rows.get(p.loaded), obs.rows.get(p.unloaded)) else {
        return Ok(Vector3::zeros());
    };
    Ok(predict(m, l, file)?.attained_mm - predict(m, u, file)?.attained_mm)
}

fn stiffness_from(c: &DVector<f64>) -> [f64; 6] {
    std::array::from_fn(|i| 1.0 / (c[i] * C_UNIT))
}

/// Identifies the joint stiffnesses from the load pairs of `obs`.
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
    let pairs = load_pairs(obs, obs_file)?;
    let (fit_idx, hold_idx) = holdout_split(pairs.len(), opts.holdout, opts.seed);
    let fit: Vec<LoadPair> = fit_idx
        .iter()
        .filter_map(|&i| pairs.get(i).copied())
        .collect();
    let hold: Vec<LoadPair> = hold_idx
        .iter()
        .filter_map(|&i| pairs.get(i).copied())
        .collect();
    if fit.len() < 3 {
        return Err(Error::Usage(format!(
            "{obs_file}: {} load pair(s) left for the fit; 6 stiffnesses need at least 3 \
             pairs (18 equations), better tens",
            fit.len()
        )));
    }
    tracing::info!(
        "stiffness: {} pairs for the fit, {} held out",
        fit.len(),
        hold.len()
    );
    let m = 3 * fit.len();
    let mut a = DMatrix::zeros(m, 6);
    let mut b0 = DVector::zeros(m);
    for (k, &p) in fit.iter().enumerate() {
        let blk = design_block(robot, obs, p)
            .ok_or_else(|| Error::Usage(format!("{obs_file}: not a robot row in a load pair")))?;
        a.view_mut((3 * k, 0), (3, 6)).copy_from(&blk);
        b0.rows_mut(3 * k, 3)
            .copy_from(&measured_deflection(obs, p));
    }
    let lsq = LsqOptions::default();
    let solve = |b: &DVector<f64>| -> Result<Solution> {
        solve_linear(&a, b, &lsq).map_err(|e| Error::Usage(format!("{obs_file}: {e}")))
    };
    let mut sol = solve(&b0)?;
    let id = sol.identifiability.clone();
    if !id.unidentifiable.is_empty() {
        let names: Vec<String> = id
            .unidentifiable
            .iter()
            .map(|i| format!("k{}", i + 1))
            .collect();
        return Err(Error::Usage(format!(
            "{obs_file}: badly conditioned data set: the stiffness of {} cannot be identified \
             (the loads do not twist these joints independently of the others; O1 = {:.3e}). \
             Load the arm in more directions and configurations",
            names.join(", "),
            id.observability_o1
        )));
    }
    if id.condition_number_identified > CONDITION_LIMIT {
        return Err(Error::Usage(format!(
            "{obs_file}: badly conditioned data set: condition number {:.3e} > {:.0e} \
             (O1 = {:.3e}); the joint compliances are nearly linearly dependent in these \
             data (e.g. all loads in one direction). Vary the load direction and the \
             configuration",
            id.condition_number_identified, CONDITION_LIMIT, id.observability_o1
        )));
    }
    // Second-order correction with the exact forward model.
    for _ in 0..2 {
        if sol.params.iter().any(|&c| c <= 0.0) {
            break;
        }
        let trial = Machine::Robot(robot.with_stiffness(stiffness_from(&sol.params)));
        let lin = &a * &sol.params;
        let mut b = b0.clone();
        for (k, &p) in fit.iter().enumerate() {
            let d = model_deflection(&trial, obs, p, obs_file)?;
            for r in 0..3 {
                b[3 * k + r] -= d[r] - lin[3 * k + r];
            }
        }
        sol = solve(&b)?;
    }
    if let Some(i) = sol.params.iter().position(|&c| c <= 0.0) {
        let u = sol.std_uncertainty().map(|u| u[i]).unwrap_or(f64::NAN);
        return Err(Error::Usage(format!(
            "{obs_file}: the compliance of joint {} came out non-positive ({:.4} ± {:.4} \
             µrad/(N·m)), i.e. a non-positive stiffness, which no real joint has. This \
             usually means a sign or frame error in the data (the force acting ON the \
             robot is expected, in the robot base frame; the wrench point in the flange \
             frame; joint angles in the controller convention), or a joint the loads hardly \
             twist, so its compliance is zero within the noise",
            i + 1,
            sol.params[i],
            u
        )));
    }
    let c = sol.params.clone();
    let k_nmm = stiffness_from(&c);
    let uc = sol.std_uncertainty();
    let mut params = Vec::with_capacity(6);
    let mut notes = Vec::new();
    for i in 0..6 {
        let k = k_nmm[i] / 1000.0;
        let u = uc.as_ref().map(|u| u[i] / (c[i] * c[i] * C_UNIT) / 1000.0);
        if let Some(u) = u {
            if 2.0 * u > 0.1 * k {
                notes.push(format!(
                    "k{} is poorly determined (U(k=2) = {:.0} % of the value): the loads twist \
                     joint {} little, its deflection is near the noise",
                    i + 1,
                    200.0 * u / k,
                    i + 1
                ));
            }
        }
        params.push(Estimate {
            name: format!("k{}", i + 1),
            unit: "N·m/rad",
            start: robot.k_nmm_per_rad()[i] / 1000.0,
            value: k,
            u,
            fixed: false,
        });
    }
    let calibrated = Machine::Robot(robot.with_stiffness(k_nmm));
    let mut before = Vec::with_capacity(hold.len());
    let mut after = Vec::with_capacity(hold.len());
    for &p in &hold {
        let meas = measured_deflection(obs, p);
        before.push((meas - model_deflection(&machine, obs, p, obs_file)?).norm());
        after.push((meas - model_deflection(&calibrated, obs, p, obs_file)?).norm());
    }
    let values: Vec<String> = params.iter().map(|p| fmt_value(p.value, 1)).collect();
    let yaml = set_top_level_list(text, machine_file, "k_nm_per_rad", &values)?;
    Machine::from_yaml_str(&yaml, machine_file)?;
    let mut cal = Calibration {
        kind: "stiffness",
        n_fit: fit.len(),
        n_equations: m,
        observability_o1: 0.0,
        condition_number: 0.0,
        rms_fit_mm: (sol.rss / m as f64).sqrt(),
        params,
        validation: Validation::from_norms(&before, &after),
        notes,
        yaml,
    };
    cal.set_identifiability(&id);
    Ok(cal)
}
