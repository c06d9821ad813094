//! "Where", in the frames where effects show: the residual (measured −
//! simulated) is fitted, one pattern at a time, by a few columns that a
//! family of effects would produce, and the patterns are ranked by the
//! share of the residual they explain (adjusted R²):
//!
//! - a constant offset in the base (measurement) frame, and in the tool
//!   (flange) frame — a TCP offset is constant in the latter only;
//! - along the load: the residual proportional to the row's force vector
//!   (a compliance shows there, whatever the direction of the load);
//! - joint space through the Jacobian (robots): for each joint `i` its
//!   column `J_P[:, i]` — the motion of the measured point per radian of
//!   that joint — times 1 (a zero offset), the joint torque (a compliance)
//!   or the last-motion sign (a backlash);
//! - the tool axis (machine tools): the residual along the tool, constant,
//!   with time or with spindle power (tool length, spindle growth);
//! - each row covariate: the residual linear in it, per base component.
//!
//! Unlike a rank correlation of one base component against one covariate,
//! these see a constant offset that turns with the tool, a deflection whose
//! base components change sign with the load, and a joint error whose base
//! direction changes with the pose.

use nalgebra::{DMatrix, DVector, Vector3, Vector6};
use serde::Serialize;

use super::residuals::covariates;
use crate::calibrate::forward;
use crate::calibrate::lsq::{LsqOptions, solve_linear};
use crate::calibrate::observations::{Observation, Pose};
use crate::machine::Machine;
use crate::machine::robot::Model;

/// Patterns listed in the report.
pub const PATTERNS_SHOWN: usize = 5;

/// One pattern and how much of the residual it explains.
#[derive(Debug, Clone, Serialize)]
pub struct Pattern {
    /// What the columns are, e.g. `joint 3 × torque` or `constant, tool frame`.
    pub name: String,
    /// Columns fitted.
    pub params: usize,
    /// Adjusted share of the residual sum of squares explained (≤ 1).
    pub r2_adj: f64,
}

/// A pattern under construction: name and its columns (3 per row, mm per
/// unit of an arbitrary coefficient).
struct Cols {
    name: String,
    cols: Vec<Vec<f64>>,
}

impl Cols {
    fn new(name: impl Into<String>, k: usize, n: usize) -> Cols {
        Cols {
            name: name.into(),
            cols: vec![vec![0.0; 3 * n]; k],
        }
    }
}

/// Ranks the patterns of `rows` against `residual_mm`, best first.
pub fn rank(machine: &Machine, rows: &[Observation], residual_mm: &[Vector3<f64>]) -> Vec<Pattern> {
    let n = rows.len().min(residual_mm.len());
    if n < 4 {
        return Vec::new();
    }
    let mut y = DVector::zeros(3 * n);
    for (i, r) in residual_mm.iter().take(n).enumerate() {
        for c in 0..3 {
            y[3 * i + c] = r[c] * 1000.0;
        }
    }
    let tss = y.norm_squared();
    if tss.is_nan() || tss <= 0.0 {
        return Vec::new();
    }
    let mut pats = Vec::new();
    let mut base = Cols::new("constant, base frame", 3, n);
    let mut load = Cols::new("along the load, ∝ force", 1, n);
    for (i, row) in rows.iter().take(n).enumerate() {
        for c in 0..3 {
            base.cols[c][3 * i + c] = 1.0;
            load.cols[0][3 * i + c] = row.force_n[c];
        }
    }
    pats.push(base);
    pats.push(load);
    match machine {
        Machine::Robot(_) => robot_patterns(machine, &rows[..n], &mut pats),
        Machine::Tool(_) => tool_patterns(machine, &rows[..n], &mut pats),
    }
    covariate_patterns(&rows[..n], &mut pats);
    let mut out: Vec<Pattern> = pats
        .into_iter()
        .filter_map(|p| {
            let k = p.cols.len();
            if k == 0 || 3 * n <= k + 1 {
                return None;
            }
            let x = DMatrix::from_fn(3 * n, k, |r, c| p.cols[c][r]);
            if x.iter().all(|v| *v == 0.0) || !x.iter().all(|v| v.is_finite()) {
                return None;
            }
            let sol = solve_linear(&x, &y, &LsqOptions::default()).ok()?;
            let m = (3 * n) as f64;
            let r2_adj = 1.0 - (sol.rss / (m - k as f64)) / (tss / m);
            Some(Pattern {
                name: p.name,
                params: k,
                r2_adj,
            })
        })
        .collect();
    out.sort_by(|a, b| b.r2_adj.total_cmp(&a.r2_adj).then(a.name.cmp(&b.name)));
    out
}

fn robot_patterns(machine: &Machine, rows: &[Observation], pats: &mut Vec<Cols>) {
    let Machine::Robot(r) = machine else { return };
    let n = rows.len();
    let mut tool = Cols::new("constant, tool (flange) frame", 3, n);
    let mut joint: Vec<[Cols; 3]> = (1..=6)
        .map(|j| {
            [
                Cols::new(format!("joint {j} angle, constant"), 1, n),
                Cols::new(format!("joint {j} angle × torque"), 1, n),
                Cols::new(format!("joint {j} angle × last-motion sign"), 1, n),
            ]
        })
        .collect();
    let k = r.k_nm_per_rad().map(|k| k * 1000.0);
    for (i, row) in rows.iter().enumerate() {
        let Pose::Robot(rp) = &row.pose else { continue };
        let q = forward::joints_rad(rp);
        let mp = forward::measured_point(r, rp);
        let wp = forward::wrench_point(r, rp);
        let rot = r.flange_pose(Model::Actual, &q).rotation;
        let tau = r.gravity_torques(Model::Actual, &q)
            + r.wrench_torques(Model::Actual, &q, &wp, &forward::row_wrench(row));
        for c in 0..3 {
            let e = rot * Vector3::ith(c, 1.0);
            for a in 0..3 {
                tool.cols[c][3 * i + a] = e[a];
            }
        }
        for (j, pj) in joint.iter_mut().enumerate() {
            // J_P[:, j] = point_deflection of a torque k_j·e_j (per rad).
            let mut t = Vector6::zeros();
            t[j] = k[j];
            let col = r.point_deflection(Model::Actual, &q, &mp, &t);
            let d = rp.dir[j].map_or(0.0, f64::from);
            for a in 0..3 {
                pj[0].cols[0][3 * i + a] = col[a];
                pj[1].cols[0][3 * i + a] = col[a] * tau[j] * 1e-6;
                pj[2].cols[0][3 * i + a] = col[a] * d;
            }
        }
    }
    pats.push(tool);
    for p in joint {
        pats.extend(p);
    }
}

fn tool_patterns(machine: &Machine, rows: &[Observation], pats: &mut Vec<Cols>) {
    let Machine::Tool(t) = machine else { return };
    let n = rows.len();
    let mut axis = Cols::new("along the tool axis, constant", 1, n);
    let mut time = Cols::new("along the tool axis × time", 1, n);
    let mut power = Cols::new("along the tool axis × spindle power", 1, n);
    for (i, row) in rows.iter().enumerate() {
        let Pose::Tool(tp) = &row.pose else { continue };
        let dir = t
            .geometric(&tp.axes(), &tp.dirs(), forward::tool_length(t, tp))
            .dir;
        for a in 0..3 {
            axis.cols[0][3 * i + a] = dir[a];
            time.cols[0][3 * i + a] = dir[a] * row.t_s.unwrap_or(0.0) / 3600.0;
            power.cols[0][3 * i + a] = dir[a] * tp.spindle_w.unwrap_or(0.0) / 1000.0;
        }
    }
    pats.push(axis);
    pats.push(time);
    pats.push(power);
}

fn covariate_patterns(rows: &[Observation], pats: &mut Vec<Cols>) {
    let n = rows.len();
    let per_row: Vec<Vec<(String, f64)>> = rows.iter().map(covariates).collect();
    let mut names: Vec<String> = Vec::new();
    for c in per_row.iter().flatten() {
        if !names.contains(&c.0) {
            names.push(c.0.clone());
        }
    }
    for name in names {
        let vals: Vec<f64> = per_row
            .iter()
            .map(|cs| cs.iter().find(|c| c.0 == name).map_or(0.0, |c| c.1))
            .collect();
        let mean = vals.iter().sum::<f64>() / n as f64;
        let mut p = Cols::new(format!("linear in {name}"), 3, n);
        for (i, v) in vals.iter().enumerate() {
            for c in 0..3 {
                p.cols[c][3 * i + c] = v - mean;
            }
        }
        pats.push(p);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calibrate::observations::RobotPose;

    fn robot_row(q_deg: [f64; 6], f: Vector3<f64>) -> Observation {
        Observation {
            line: 0,
            id: "r".into(),
            t_s: None,
            measured_mm: Vector3::zeros(),
            force_n: f,
            moment_nm: Vector3::zeros(),
            ambient_c: None,
            orientation: None,
            pose: Pose::Robot(RobotPose {
                q_deg,
                mp_mm: None,
                wp_mm: None,
                p_w: [None; 6],
                dir: [None; 6],
            }),
        }
    }

    /// A residual that is a constant 0.2 mm along the flange x axis (a TCP
    /// offset) turns with the tool in the base frame; the tool-frame
    /// pattern explains all of it, the base-frame constant far less.
    #[test]
    fn tool_frame_offset_is_found_in_the_tool_frame() {
        let text = include_str!("../../machines/abb-irb1600.yaml");
        let m = Machine::from_yaml_str(text, "m.yaml").expect("robot");
        let Machine::Robot(r) = &m else { panic!() };
        let mut seq = crate::machine::robot::test_sequence(5);
        let rows: Vec<Observation> = (0..40)
            .map(|_| {
                robot_row(
                    std::array::from_fn(|_| 60.0 * seq()),
                    Vector3::new(100.0 * seq(), 100.0 * seq(), 100.0 * seq()),
                )
            })
            .collect();
        let res: Vec<Vector3<f64>> = rows
            .iter()
            .map(|row| {
                let Pose::Robot(rp) = &row.pose else { panic!() };
                let q = forward::joints_rad(rp);
                r.flange_pose(Model::Actual, &q).rotation * Vector3::new(0.2, 0.0, 0.0)
            })
            .collect();
        let p = rank(&m, &rows, &res);
        assert_eq!(p[0].name, "constant, tool (flange) frame");
        assert!(p[0].r2_adj > 0.999, "{p:?}");
        let base = p.iter().find(|x| x.name == "constant, base frame").unwrap();
        assert!(base.r2_adj < 0.5, "{p:?}");
    }
}
