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
//! The robot base frame is the frame of the observations (contract), so the
//! `base` of the machine file is neither identified nor edited: in a
//! modified-DH model the x and z offsets of the arm in that frame are the
//! first row's `a_mm` and `d_mm`.

use nalgebra::{DVector, Isometry3, Translation3};

use crate::calibrate::lsq::{
    LmOptions, LsqOptions, expand_free, fit_free, numeric_jacobian, solve_linear,
};
use crate::error::{Error, Result};
use crate::machine::Machine;
use crate::machine::robot::{DhParams, Model, Robot};

use super::forward::{check_kind, predict};
use super::observations::{MeasuredKind, Observations, Pose, holdout_split};
use super::report::{CONDITION_LIMIT, Calibration, Estimate, Validation};
use super::stiffness::Options;
use super::yaml_edit::{DhRow, set_actual_dh, set_frame_translation};

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

/// Forward-difference step of the identification Jacobian (mm or mrad).
const FD_STEP: f64 = 1e-4;

/// Degrees per internal angle unit (mrad).
const DEG_PER_UNIT: f64 = 0.18 / std::f64::consts::PI;

const DH_NAMES: [(&str, &str); 4] = [
    ("a_mm", "mm"),
    ("alpha_deg", "deg"),
    ("d_mm", "mm"),
    ("theta_offset_deg", "deg"),
];

/// Parameter vector layout: 24 DH corrections, then optionally 3 TCP ones.
struct Layout {
    base: Robot,
    dh: DhParams,
    tool: bool,
}

impl Layout {
    fn n(&self) -> usize {
        if self.tool { 27 } else { 24 }
    }

    fn name(&self, k: usize) -> (String, &'static str) {
        if k < 24 {
            let (n, u) = DH_NAMES[k % 4];
            (format!("j{}.{n}", k / 4 + 1), u)
        } else {
            (format!("tool.{}_mm", ["x", "y", "z"][(k - 24) % 3]), "mm")
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
        let r = self.base.with_actual(self.dh_with(x));
        if self.tool {
            let t0 = self.base.flange_to_tool();
            let v = |o: usize| x.get(24 + o).copied().unwrap_or(0.0);
            let t = Isometry3::from_parts(
                Translation3::from(
                    t0.translation.vector + nalgebra::Vector3::new(v(0), v(1), v(2)),
                ),
                t0.rotation,
            );
            r.with_tool(t, self.base.tool_load().copied(), true)
        } else {
            r
        }
    }
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

/// The parameters that no pose set identifies: the identifiability of the
/// same parameters and measured points at [`REFERENCE_POSES`] joint vectors
/// spread over the joint ranges (deterministic).
fn structurally_unidentifiable(
    layout: &Layout,
    obs: &Observations,
    fit: &[usize],
    file: &str,
    lm_opts: &LmOptions,
) -> Result<Vec<usize>> {
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
        reference.rows.push(row);
    }
    let rows: Vec<usize> = (0..reference.rows.len()).collect();
    let n = layout.n();
    let zero = DVector::zeros(n);
    let mut r0 = DVector::zeros(3 * rows.len());
    residuals(layout, &reference, &rows, zero.as_slice(), &mut r0, file);
    if r0.iter().any(|v| !v.is_finite()) {
        return Ok(Vec::new());
    }
    let j = numeric_jacobian(
        |x, r| residuals(layout, &reference, &rows, x.as_slice(), r, file),
        &zero,
        3 * rows.len(),
        lm_opts.fd_relative_step,
    );
    let sol =
        solve_linear(&j, &r0, &lm_opts.lsq).map_err(|e| Error::Usage(format!("{file}: {e}")))?;
    Ok(sol.identifiability.unidentifiable)
}

/// Residuals `measured − model` of `rows` for the full correction vector.
fn residuals(
    layout: &Layout,
    obs: &Observations,
    rows: &[usize],
    x: &[f64],
    out: &mut DVector<f64>,
    file: &str,
) {
    let m = Machine::Robot(layout.robot(x));
    for (k, &i) in rows.iter().enumerate() {
        let Some(row) = obs.rows.get(i) else { continue };
        match predict(&m, row, file) {
            Ok(p) => {
                let d = row.measured_mm - p.measured(obs.measured);
                for r in 0..3 {
                    out[3 * k + r] = d[r];
                }
            }
            Err(_) => {
                for r in 0..3 {
                    out[3 * k + r] = f64::NAN;
                }
            }
        }
    }
}

fn row_norms(m: &Machine, obs: &Observations, rows: &[usize], file: &str) -> Result<Vec<f64>> {
    let mut v = Vec::with_capacity(rows.len());
    for &i in rows {
        if let Some(row) = obs.rows.get(i) {
            let p = predict(m, row, file)?;
            v.push((row.measured_mm - p.measured(obs.measured)).norm());
        }
    }
    Ok(v)
}

/// Identifies the actual DH parameters (and the TCP translation) from `obs`.
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
    // Deviations (attained − commanded of the same point) hardly see where
    // the point is: the TCP translation is identified from positions only.
    let tool = obs.measured == MeasuredKind::Position
        && obs
            .rows
            .iter()
            .all(|r| matches!(&r.pose, Pose::Robot(rp) if rp.mp_mm.is_none()));
    let layout = Layout {
        base: robot.clone(),
        dh: *robot.params(Model::Actual),
        tool,
    };
    let n = layout.n();
    let (fit, hold) = holdout_split(obs.rows.len(), opts.holdout, opts.seed);
    let m = 3 * fit.len();
    if m < 2 * n {
        return Err(Error::Usage(format!(
            "{obs_file}: {} rows left for the fit ({m} equations) for {n} parameters; \
             kinematic calibration needs at least {} rows, better several times more",
            fit.len(),
            (2 * n).div_ceil(3)
        )));
    }
    tracing::info!(
        "kinematics: {} rows for the fit, {} held out, {n} parameters",
        fit.len(),
        hold.len()
    );
    // Identifiability at the start point.
    let zero = DVector::zeros(n);
    let mut r0 = DVector::zeros(m);
    residuals(&layout, obs, &fit, zero.as_slice(), &mut r0, obs_file);
    if r0.iter().any(|v| !v.is_finite()) {
        return Err(Error::Usage(format!(
            "{obs_file}: the model cannot be evaluated for some rows"
        )));
    }
    let lm_opts = LmOptions {
        lsq: LsqOptions {
            rank_rtol: KIN_RANK_RTOL,
            scale_columns: false,
        },
        ..LmOptions::default()
    };
    let j0 = numeric_jacobian(
        |x, r| residuals(&layout, obs, &fit, x.as_slice(), r, obs_file),
        &zero,
        m,
        lm_opts.fd_relative_step,
    );
    let pre = solve_linear(&j0, &r0, &lm_opts.lsq)
        .map_err(|e| Error::Usage(format!("{obs_file}: {e}")))?;
    let free = pre.identifiability.identifiable.clone();
    let fixed = pre.identifiability.unidentifiable.clone();
    // Parameters no pose set identifies (redundant with others in the
    // model) are fixed quietly; parameters only THESE poses cannot identify
    // mean a badly conditioned data set: fitting the rest would push their
    // errors into neighbouring parameters with confident uncertainties.
    let structural = structurally_unidentifiable(&layout, obs, &fit, obs_file, &lm_opts)?;
    let data_caused: Vec<usize> = fixed
        .iter()
        .copied()
        .filter(|k| !structural.contains(k))
        .collect();
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
        return Err(Error::Usage(format!(
            "{obs_file}: badly conditioned data set: these poses cannot identify {} \
             (varied poses do) — {why}. Their errors would be absorbed by the other \
             parameters with misleadingly small uncertainties; measure poses that move \
             every joint over its range",
            names.join(", ")
        )));
    }
    if !fixed.is_empty() {
        let names: Vec<String> = fixed.iter().map(|&k| layout.name(k).0).collect();
        tracing::warn!(
            "{} parameter(s) cannot be identified from these data and stay at the file's value: {}",
            fixed.len(),
            names.join(", ")
        );
    }
    // Forward differences (half the cost of central ones): the model is
    // smooth on the scale of FD_STEP, the truncation error is
    // ≈ FD_STEP · 1 mm/mrad² ≈ 1e-7 mm per unit.
    let fit_result = fit_free(
        |x, out| residuals(&layout, obs, &fit, x, out, obs_file),
        n,
        &free,
        m,
        FD_STEP,
        &lm_opts,
    )
    .map_err(|e| Error::Usage(format!("{obs_file}: {e}")))?;
    let sol = &fit_result.solution;
    let id = &sol.identifiability;
    if id.condition_number_identified > CONDITION_LIMIT {
        return Err(Error::Usage(format!(
            "{obs_file}: badly conditioned data set: condition number {:.3e} > {:.0e} \
             (O1 = {:.3e}) after fixing {} unidentifiable parameter(s); the poses do not \
             excite the kinematic parameters independently. Measure more varied poses \
             (all joints over their range)",
            id.condition_number_identified,
            CONDITION_LIMIT,
            id.observability_o1,
            fixed.len()
        )));
    }
    let full = expand_free(n, &free, sol.params.as_slice());
    let u_red = sol.std_uncertainty();
    let mut params = Vec::with_capacity(n);
    for k in 0..n {
        let (name, unit) = layout.name(k);
        let pos = free.iter().position(|&f| f == k);
        let start = layout.start(k);
        let f = if unit == "deg" { DEG_PER_UNIT } else { 1.0 };
        params.push(Estimate {
            name,
            unit,
            start,
            value: start + f * full.get(k).copied().unwrap_or(0.0),
            u: pos.and_then(|a| u_red.as_ref().map(|u| f * u[a])),
            fixed: pos.is_none(),
        });
    }
    let calibrated_robot = layout.robot(&full);
    let calibrated = Machine::Robot(calibrated_robot.clone());
    let before = row_norms(&machine, obs, &hold, obs_file)?;
    let after = row_norms(&calibrated, obs, &hold, obs_file)?;
    // The calibrated file.
    let dh = calibrated_robot.params(Model::Actual);
    let rows: [DhRow; 6] = std::array::from_fn(|j| DhRow {
        a_mm: dh.joints[j].a_mm,
        alpha_deg: dh.joints[j].alpha_rad.to_degrees(),
        d_mm: dh.joints[j].d_mm,
        theta_offset_deg: dh.joints[j].theta_offset_rad.to_degrees(),
    });
    let mut yaml = set_actual_dh(text, machine_file, &rows)?;
    if tool {
        let t = calibrated_robot.flange_to_tool().translation.vector;
        yaml = set_frame_translation(&yaml, machine_file, "flange_to_tool", [t.x, t.y, t.z])?;
    }
    Machine::from_yaml_str(&yaml, machine_file)?;
    let mut notes = Vec::new();
    if !fixed.is_empty() {
        notes.push(format!(
            "{} of {n} parameters are not identifiable from these poses (they move the \
             measured point like a combination of the others); they keep the file's value",
            fixed.len()
        ));
    }
    for j in constant_joints(obs) {
        notes.push(format!(
            "every row has joint {j} at the same angle: the parameters of the links \
             before it cannot be told from a shift or tilt of the measuring frame \
             (badly conditioned for those parameters); move joint {j} as well"
        ));
    }
    notes.push("the base frame is the frame of the observations and is not identified".into());
    let mut cal = Calibration {
        kind: "kinematics",
        n_fit: fit.len(),
        n_equations: m,
        observability_o1: 0.0,
        condition_number: 0.0,
        rms_fit_mm: sol.sigma2.map_or((sol.rss / m as f64).sqrt(), f64::sqrt),
        params,
        validation: Validation::from_norms(&before, &after),
        notes,
        yaml,
    };
    cal.set_identifiability(id);
    cal.check_validation();
    Ok(cal)
}
