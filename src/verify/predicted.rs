//! ISO 230-2 of a machine model: what the standard's test would find on a
//! linear axis, predicted, and what it would find after compensation
//! (docs/verify.md, "Predicted figures").
//!
//! The positional deviation of the axis at a target, approached in one
//! direction, is the component along the axis of the predicted deviation
//! of the tool tip (attained − nominal, workpiece frame) with the other
//! axes at a fixed position — what a laser interferometer aligned with the
//! axis reads. A model has no scatter: each target gets one predicted run
//! per direction, s = 0, so A = E and R = max |B_i|.
//!
//! After compensation each target is commanded where the model puts it on
//! the target, so a run measured before compensation would read its
//! deviation minus the model's: [`compensated`] subtracts the prediction
//! from each measured run and keeps the measured scatter.
//!
//! When the machine file carries a parameter covariance, each figure of
//! a prediction or of runs after compensation gets its expanded
//! uncertainty U (k=2) ([`figure_uncertainty`]): the covariance of the
//! model's predicted deviations at the targets ([`prediction_covariance`],
//! correlated through the parameters they share) carried through the
//! figure's sensitivity to each of them, to first order.
//!
//! A circular test (ISO 230-4) of a model: [`predicted_circle`] gives the
//! radial deviations on a nominal circle in the plane of two linear axes,
//! each direction with the axes' directions of motion of its approach (a
//! reversal error shows as hysteresis).

use nalgebra::DMatrix;

use super::iso230_2::{AxisRuns, TargetRuns, evaluate_axis};
use crate::error::{Error, Result};
use crate::machine::tool::MachineTool;
use crate::machine::{AxisVec, DirVec, axis_slot};
use crate::predict::uncertainty::{BlockUncertainty, COVERAGE_K};
use crate::predict::{EffectSet, ToolPredictor};

/// Where the predicted axis is measured.
#[derive(Debug, Clone, PartialEq)]
pub struct AxisSetup {
    /// The axis (slot of `X`, `Y` or `Z`).
    pub slot: usize,
    /// Position of every axis but the measured one.
    pub at: AxisVec,
    /// Tool length, mm.
    pub tool_mm: f64,
}

impl AxisSetup {
    /// The setup for the linear axis `name` of `machine`: the other linear
    /// axes in the middle of their travel and rotary axes at 0 unless `at`
    /// gives them (`(slot, value)` pairs).
    pub fn new(
        machine: &MachineTool,
        name: &str,
        at: &[(usize, f64)],
        tool_mm: f64,
    ) -> Result<AxisSetup> {
        let slot = match name.as_bytes() {
            [c] => axis_slot(c.to_ascii_uppercase()).filter(|&s| s < 3),
            _ => None,
        }
        .ok_or_else(|| {
            Error::Usage(format!(
                "--axis {name}: ISO 230-2 is predicted for a linear axis X, Y or Z"
            ))
        })?;
        if !machine.has_axis(slot) {
            return Err(Error::Usage(format!(
                "--axis {name}: the machine `{}` has no such axis",
                machine.name()
            )));
        }
        let mut pos: AxisVec = [0.0; 6];
        for (s, p) in pos.iter_mut().enumerate() {
            if s < 3 {
                if let Some((lo, hi)) = machine.travel(s) {
                    *p = (lo + hi) / 2.0;
                }
            }
        }
        for &(s, v) in at {
            if !machine.has_axis(s) {
                return Err(Error::Usage(format!(
                    "--at: the machine `{}` has no axis {}",
                    machine.name(),
                    ["X", "Y", "Z", "A", "B", "C"][s.min(5)]
                )));
            }
            pos[s] = v;
        }
        Ok(AxisSetup {
            slot,
            at: pos,
            tool_mm,
        })
    }

    /// The predicted positional deviation at `target` approached in
    /// direction `dir` (±1), mm.
    pub fn deviation_mm(&self, machine: &MachineTool, target: f64, dir: i8) -> f64 {
        let p = ToolPredictor::new(machine, EffectSet::default());
        let mut cmd = self.at;
        cmd[self.slot] = target;
        let mut dirs: DirVec = [1; 6];
        dirs[self.slot] = dir;
        p.breakdown(&cmd, &dirs, self.tool_mm).total()[self.slot]
    }
}

/// One predicted run per direction at each target (targets within the
/// axis' travel).
pub fn predicted_runs(
    machine: &MachineTool,
    setup: &AxisSetup,
    name: &str,
    targets: &[f64],
) -> Result<AxisRuns> {
    if let Some((lo, hi)) = machine.travel(setup.slot) {
        if let Some(t) = targets.iter().find(|t| **t < lo || **t > hi) {
            return Err(Error::Usage(format!(
                "--targets: {t} mm is outside the travel of {name} ({lo} to {hi} mm)"
            )));
        }
    }
    let mut ts: Vec<f64> = targets.to_vec();
    ts.sort_by(f64::total_cmp);
    ts.dedup();
    Ok(AxisRuns {
        axis: name.to_string(),
        targets: ts
            .into_iter()
            .map(|t| TargetRuns {
                target_mm: t,
                up: vec![setup.deviation_mm(machine, t, 1)],
                down: vec![setup.deviation_mm(machine, t, -1)],
            })
            .collect(),
    })
}

/// Measured runs as they would read after compensation by the model: each
/// run's deviation minus the model's prediction at its target and
/// direction.
pub fn compensated(machine: &MachineTool, setup: &AxisSetup, measured: &AxisRuns) -> AxisRuns {
    AxisRuns {
        axis: measured.axis.clone(),
        targets: measured
            .targets
            .iter()
            .map(|t| {
                let up = setup.deviation_mm(machine, t.target_mm, 1);
                let down = setup.deviation_mm(machine, t.target_mm, -1);
                TargetRuns {
                    target_mm: t.target_mm,
                    up: t.up.iter().map(|d| d - up).collect(),
                    down: t.down.iter().map(|d| d - down).collect(),
                }
            })
            .collect(),
    }
}

/// The covariance (mm²) of the model's predicted positional deviations
/// at the targets of `runs` (in their order), up then down at each:
/// entry `2i` is target i approached in +, `2i + 1` in −. `None` for a
/// model `u` cannot differentiate (a robot's).
pub fn prediction_covariance(
    u: &BlockUncertainty,
    setup: &AxisSetup,
    runs: &AxisRuns,
) -> Option<DMatrix<f64>> {
    let points: Vec<(AxisVec, DirVec)> = runs
        .targets
        .iter()
        .flat_map(|t| {
            [1i8, -1].map(|dir| {
                let mut cmd = setup.at;
                cmd[setup.slot] = t.target_mm;
                let mut dirs: DirVec = [1; 6];
                dirs[setup.slot] = dir;
                (cmd, dirs)
            })
        })
        .collect();
    u.tool_covariance_along(&points, setup.tool_mm, setup.slot)
}

/// Step of the figures' one-sided differences, mm: far below the gap
/// between two targets' values that the four decimals of a report can
/// tell apart, far above the rounding of a deviation.
pub const FIGURE_STEP_MM: f64 = 1e-7;

/// The expanded uncertainty U (k = 2) of each ISO 230-2 figure of `runs`
/// (in the order of [`super::iso230_2::FIGURES`], mm) when each run holds
/// `sign` times the model's predicted deviation at its target and
/// direction (+1: the prediction, `--predict`; −1: measured runs less the
/// prediction, `--compensated`) and those predictions have the
/// covariance `cov` ([`prediction_covariance`]). A figure is a maximum or
/// minimum of the targets' means, so to first order it moves with the
/// targets that attain them: its sensitivity g to each prediction is the
/// figure's one-sided difference quotient with all runs of that target
/// and direction moved by [`FIGURE_STEP_MM`], and U = 2 √(gᵀ C g). Where
/// two targets attain the extreme together the two sides differ; the
/// larger U of the two is given. A `cov` of the wrong size gives `None`.
pub fn figure_uncertainty(runs: &AxisRuns, sign: f64, cov: &DMatrix<f64>) -> Option<[f64; 12]> {
    let n = 2 * runs.targets.len();
    if cov.nrows() != n || cov.ncols() != n {
        return None;
    }
    let f0 = evaluate_axis(runs).figures;
    let moved = |k: usize, h: f64| {
        let mut r = runs.clone();
        if let Some(t) = r.targets.get_mut(k / 2) {
            let side = if k % 2 == 0 { &mut t.up } else { &mut t.down };
            for v in side.iter_mut() {
                *v += sign * h;
            }
        }
        evaluate_axis(&r).figures
    };
    let mut up = DMatrix::zeros(12, n);
    let mut down = DMatrix::zeros(12, n);
    for k in 0..n {
        let (fp, fm) = (moved(k, FIGURE_STEP_MM), moved(k, -FIGURE_STEP_MM));
        for f in 0..12 {
            up[(f, k)] = (fp[f] - f0[f]) / FIGURE_STEP_MM;
            down[(f, k)] = (f0[f] - fm[f]) / FIGURE_STEP_MM;
        }
    }
    let (cu, cd) = (&up * cov * up.transpose(), &down * cov * down.transpose());
    Some(std::array::from_fn(|f| {
        COVERAGE_K * cu[(f, f)].max(cd[(f, f)]).max(0.0).sqrt()
    }))
}

/// A circular test of a machine model (ISO 230-4): a circle in the plane
/// of two linear axes.
#[derive(Debug, Clone, PartialEq)]
pub struct CircleSetup {
    /// The axes of the plane (slots; the first is the angle's zero).
    pub plane: (usize, usize),
    /// Every axis' position at the centre.
    pub centre: AxisVec,
    /// Radius, mm.
    pub radius_mm: f64,
    /// Points per direction, equally spaced from angle 0.
    pub points: usize,
    /// Tool length, mm.
    pub tool_mm: f64,
}

/// The sign of a velocity component, +1 for zero.
fn sign(v: f64) -> i8 {
    if v < 0.0 { -1 } else { 1 }
}

/// Angle just before a point along a path, rad: the directions of motion
/// are those of the approach.
const APPROACH_RAD: f64 = 1e-9;

/// The radial deviations a model predicts on a circle, both directions:
/// at each point the component along the radius of the tip's predicted
/// deviation, each axis' direction of motion that of the approach.
pub fn predicted_circle(machine: &MachineTool, c: &CircleSetup) -> super::iso230_4::Circle {
    let p = ToolPredictor::new(machine, EffectSet::default());
    let (a, b) = c.plane;
    let path = |ccw: bool| -> super::iso230_4::Path {
        (0..c.points)
            .map(|k| {
                let t = std::f64::consts::TAU * k as f64 / c.points as f64;
                let mut cmd = c.centre;
                cmd[a] += c.radius_mm * t.cos();
                cmd[b] += c.radius_mm * t.sin();
                let mut dirs: DirVec = [1; 6];
                if ccw {
                    let u = t - APPROACH_RAD;
                    dirs[a] = sign(-u.sin());
                    dirs[b] = sign(u.cos());
                } else {
                    let u = t + APPROACH_RAD;
                    dirs[a] = sign(u.sin());
                    dirs[b] = sign(-u.cos());
                }
                let d = p.breakdown(&cmd, &dirs, c.tool_mm).total();
                (t, d[a] * t.cos() + d[b] * t.sin())
            })
            .collect()
    };
    super::iso230_4::Circle {
        ccw: path(true),
        cw: path(false),
    }
}
