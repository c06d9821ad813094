//! Machine-tool geometric calibration: the translational component errors
//! of the linear axes X, Y, Z as bidirectional tables (ISO 230-2 style:
//! positioning `EXX`, `EYY`, `EZZ`; straightness `EYX`, `EZX`, `EXY`, `EZY`,
//! `EXZ`, `EYZ`) and the three squareness errors with X as the reference axis
//! (`EC0Y` X–Y, `EA0Z` Y–Z, `EB0Z` X–Z), from tool-tip measurements.
//!
//! What the data support, and the conventions that make it identifiable:
//! - Tables are written on the *measured target positions* of each axis
//!   (the distinct commanded positions in the data, at most
//!   [`MAX_TARGETS`]); the measurements must be taken on such a grid.
//!   Forward values come from rows approached in `+` direction (`dir… = 1`),
//!   reverse values from `−` rows; a row without a sign counts as `+`.
//! - Datum: every straightness table's forward value at the first target is
//!   0; the constant offset of each direction is in the positioning table
//!   (`EXX` for x, …), since only the sum of the three is observable.
//! - The straightness tables whose slope is a squareness error use the
//!   end-point reference line (forward values 0 at the first and the last
//!   target): `EXY`↔`EC0Y`, `EYZ`↔`EA0Z`, `EXZ`↔`EB0Z` (X is the reference
//!   axis). The slopes of `EYX`, `EZX`, `EZY` are identified as they are:
//!   the observations are in the machine's own workpiece frame, whose
//!   orientation is not a free parameter.
//! - Angular errors (`EAX` … `ECZ`) and rotary axes are *not* identified:
//!   tip positions at one tool length cannot separate an angular error from
//!   the straightness it causes at the tip. They keep the file's values (and
//!   still act in the model); measure them with angular optics or a level.
//! - Entries no row reaches (a target never approached in one direction)
//!   are detected as unidentifiable, kept at the file's value and listed.
//!
//! Identification: the tip deviation is linear in these values to first
//! order; the design matrix is the finite difference (1 µm or 1 µrad) of the
//! exact forward model ([`super::forward::predict`]) of the machine file with
//! the values written in ([`super::yaml_edit`]), solved by linear least
//! squares with one Gauss–Newton refinement.

use nalgebra::{DMatrix, DVector};

use crate::calibrate::lsq::{LsqOptions, solve_linear};
use crate::error::{Error, Result};
use crate::machine::Machine;
use crate::machine::tool::{AxisKind, MachineTool};

use super::forward::{check_kind, predict};
use super::observations::{Observations, Pose, holdout_split};
use super::report::{CONDITION_LIMIT, Calibration, Estimate, Validation};
use super::stiffness::Options;
use super::yaml_edit::{set_component_table, set_location_error};

/// Largest number of distinct target positions per axis.
pub const MAX_TARGETS: usize = 41;

const LETTERS: [char; 3] = ['X', 'Y', 'Z'];

/// One unknown.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Param {
    /// Table `E{err}{axis}_um`, node `node`, forward (true) or reverse.
    Table {
        axis: usize,
        err: usize,
        node: usize,
        forward: bool,
    },
    /// Squareness `(axis letter, key)`, µrad.
    Square { axis: usize, key: &'static str },
}

struct Problem {
    grids: [Vec<f64>; 3],
    /// Axes (slots 0..3) whose tables are identified.
    axes: Vec<usize>,
    params: Vec<Param>,
    square: bool,
}

impl Problem {
    fn name(&self, p: &Param) -> String {
        match *p {
            Param::Table {
                axis,
                err,
                node,
                forward,
            } => format!(
                "E{}{}@{}{}",
                LETTERS[err],
                LETTERS[axis],
                crate::calibrate::yaml_edit::fmt_value(
                    self.grids[axis].get(node).copied().unwrap_or(0.0),
                    3
                ),
                if forward { "+" } else { "-" }
            ),
            Param::Square { key, .. } => key.to_string(),
        }
    }

    /// Writes all identified values `x` (µm, µrad) into `text`.
    fn write(&self, text: &str, file: &str, x: &[f64]) -> Result<String> {
        let mut t = text.to_string();
        for &a in &self.axes {
            let n = self.grids[a].len();
            for (e, letter) in LETTERS.iter().enumerate() {
                let mut fwd = vec![0.0; n];
                let mut rev = vec![0.0; n];
                for (p, v) in self.params.iter().zip(x) {
                    if let Param::Table {
                        axis,
                        err,
                        node,
                        forward,
                    } = *p
                    {
                        if axis == a && err == e {
                            let col = if forward { &mut fwd } else { &mut rev };
                            if let Some(c) = col.get_mut(node) {
                                *c = *v;
                            }
                        }
                    }
                }
                let key = format!("E{letter}{}_um", LETTERS[a]);
                t = set_component_table(
                    &t,
                    file,
                    &LETTERS[a].to_string(),
                    &key,
                    &self.grids[a],
                    &fwd,
                    &rev,
                )?;
            }
        }
        for (p, v) in self.params.iter().zip(x) {
            if let Param::Square { axis, key } = *p {
                t = set_location_error(&t, file, &LETTERS[axis].to_string(), key, *v)?;
            }
        }
        Ok(t)
    }
}

/// Value of a parameter in the start machine (µm, µrad).
fn start_value(tool: &MachineTool, prob: &Problem, p: &Param) -> f64 {
    match *p {
        Param::Table {
            axis,
            err,
            node,
            forward,
        } => {
            let q = prob.grids[axis].get(node).copied().unwrap_or(0.0);
            tool.axis(axis)
                .and_then(|ax| ax.components.tables.get(err).and_then(|t| t.as_ref()))
                .map_or(0.0, |t| {
                    t.lookup(q, if forward { 1 } else { -1 }).value * 1000.0
                })
        }
        Param::Square { axis, key } => {
            let r = match key {
                "EC0Y_urad" => 2,
                "EA0Z_urad" => 0,
                _ => 1,
            };
            tool.axis(axis)
                .map_or(0.0, |ax| ax.location.angles_rad[r] * 1e6)
        }
    }
}

fn deviations(m: &Machine, obs: &Observations, rows: &[usize], file: &str) -> Result<DVector<f64>> {
    let mut v = DVector::zeros(3 * rows.len());
    for (k, &i) in rows.iter().enumerate() {
        if let Some(row) = obs.rows.get(i) {
            let p = predict(m, row, file)?;
            v.rows_mut(3 * k, 3).copy_from(&p.measured(obs.measured));
        }
    }
    Ok(v)
}

fn measured(obs: &Observations, rows: &[usize]) -> DVector<f64> {
    let mut v = DVector::zeros(3 * rows.len());
    for (k, &i) in rows.iter().enumerate() {
        if let Some(row) = obs.rows.get(i) {
            v.rows_mut(3 * k, 3).copy_from(&row.measured_mm);
        }
    }
    v
}

fn norms(r: &DVector<f64>) -> Vec<f64> {
    (0..r.len() / 3).map(|k| r.rows(3 * k, 3).norm()).collect()
}

/// Identifies the component error tables and squareness from `obs`.
pub fn calibrate_geometry(
    text: &str,
    machine_file: &str,
    obs: &Observations,
    obs_file: &str,
    opts: &Options,
) -> Result<Calibration> {
    let machine = Machine::from_yaml_str(text, machine_file)?;
    check_kind(&machine, obs, obs_file)?;
    let Machine::Tool(tool) = &machine else {
        return Err(Error::Usage(format!(
            "{machine_file}: geometric calibration needs a machine-tool file"
        )));
    };
    let axes: Vec<usize> = (0..3)
        .filter(|&s| tool.axis(s).is_some_and(|a| a.kind == AxisKind::Linear))
        .collect();
    for slot in 3..6 {
        let mut values: Vec<f64> = obs
            .rows
            .iter()
            .filter_map(|r| match &r.pose {
                Pose::Tool(tp) => tp.abc_deg.get(slot - 3).copied().flatten(),
                Pose::Robot(_) => None,
            })
            .collect();
        values.sort_by(f64::total_cmp);
        values.dedup();
        if values.len() > 1 {
            return Err(Error::Usage(format!(
                "{obs_file}: the {} axis takes {} different positions; geometric calibration \
                 identifies the linear-axis errors with every rotary axis at one fixed position \
                 (with moving rotary axes the table datums and squareness conventions do not \
                 hold); measure the linear axes at one rotary position",
                ["A", "B", "C"][slot - 3],
                values.len()
            )));
        }
    }
    let mut grids: [Vec<f64>; 3] = Default::default();
    for &a in &axes {
        let mut g: Vec<f64> = obs
            .rows
            .iter()
            .filter_map(|r| match &r.pose {
                Pose::Tool(tp) => Some(tp.xyz_mm[a]),
                Pose::Robot(_) => None,
            })
            .collect();
        g.sort_by(f64::total_cmp);
        g.dedup();
        if g.len() > MAX_TARGETS {
            return Err(Error::Usage(format!(
                "{obs_file}: axis {} has {} distinct commanded positions; geometric \
                 calibration needs the measurements on target positions (ISO 230-2), \
                 at most {MAX_TARGETS} per axis",
                LETTERS[a],
                g.len()
            )));
        }
        grids[a] = g;
    }
    let square = axes.len() == 3;
    let mut params = Vec::new();
    for &a in &axes {
        let n = grids[a].len();
        for e in 0..3 {
            for node in 0..n {
                // Datum: straightness forward value 0 at the first target
                // (the constant of each direction is in the positioning
                // table). End-point reference line for the straightness
                // tables whose slope is a squareness error (EXY↔EC0Y,
                // EXZ↔EB0Z, EYZ↔EA0Z).
                let paired = square && matches!((e, a), (0, 1) | (0, 2) | (1, 2));
                let constrained = e != a && (node == 0 || (paired && node + 1 == n));
                if !constrained {
                    params.push(Param::Table {
                        axis: a,
                        err: e,
                        node,
                        forward: true,
                    });
                }
                params.push(Param::Table {
                    axis: a,
                    err: e,
                    node,
                    forward: false,
                });
            }
        }
    }
    if square {
        params.push(Param::Square {
            axis: 1,
            key: "EC0Y_urad",
        });
        params.push(Param::Square {
            axis: 2,
            key: "EA0Z_urad",
        });
        params.push(Param::Square {
            axis: 2,
            key: "EB0Z_urad",
        });
    }
    let prob = Problem {
        grids,
        axes,
        params,
        square,
    };
    let n = prob.params.len();
    let (fit, hold) = holdout_split(obs.rows.len(), opts.holdout, opts.seed);
    let m = 3 * fit.len();
    if n == 0 || m <= n {
        return Err(Error::Usage(format!(
            "{obs_file}: {} rows left for the fit ({m} equations) for {n} table values and \
             squareness errors; measure more points (or fewer targets per axis)",
            fit.len()
        )));
    }
    tracing::info!(
        "geometry: {} rows for the fit, {} held out, {n} values",
        fit.len(),
        hold.len()
    );
    let x0: Vec<f64> = prob
        .params
        .iter()
        .map(|p| start_value(tool, &prob, p))
        .collect();
    let eval = |x: &[f64], rows: &[usize]| -> Result<(String, DVector<f64>)> {
        let t = prob.write(text, machine_file, x)?;
        let mm = Machine::from_yaml_str(&t, machine_file)?;
        Ok((t, deviations(&mm, obs, rows, obs_file)?))
    };
    let (_, d0) = eval(&x0, &fit)?;
    let mut a = DMatrix::zeros(m, n);
    let mut xp = x0.clone();
    for k in 0..n {
        if let Some(v) = xp.get_mut(k) {
            *v += 1.0;
        }
        let (_, dk) = eval(&xp, &fit)?;
        if let Some(v) = xp.get_mut(k) {
            *v -= 1.0;
        }
        a.set_column(k, &(dk - &d0));
    }
    let meas = measured(obs, &fit);
    let lsq = LsqOptions::default();
    let solve = |b: &DVector<f64>| {
        solve_linear(&a, b, &lsq).map_err(|e| Error::Usage(format!("{obs_file}: {e}")))
    };
    let sol0 = solve(&(&meas - &d0))?;
    let x1: Vec<f64> = x0
        .iter()
        .zip(sol0.params.iter())
        .map(|(s, d)| s + d)
        .collect();
    let (_, d1) = eval(&x1, &fit)?;
    let sol = solve(&(&meas - &d1))?;
    let x: Vec<f64> = x1
        .iter()
        .zip(sol.params.iter())
        .map(|(s, d)| s + d)
        .collect();
    let id = &sol.identifiability;
    if id.condition_number_identified > CONDITION_LIMIT {
        return Err(Error::Usage(format!(
            "{obs_file}: badly conditioned data set: condition number {:.3e} > {:.0e} \
             (O1 = {:.3e}); vary all axes independently over their targets and the \
             approach directions",
            id.condition_number_identified, CONDITION_LIMIT, id.observability_o1
        )));
    }
    let (yaml, _) = eval(&x, &[])?;
    Machine::from_yaml_str(&yaml, machine_file)?;
    let u = sol.std_uncertainty();
    let fixed: std::collections::BTreeSet<usize> = id.unidentifiable.iter().copied().collect();
    let mut params = Vec::with_capacity(n);
    for (k, p) in prob.params.iter().enumerate() {
        let is_fixed = fixed.contains(&k);
        params.push(Estimate {
            name: prob.name(p),
            unit: match p {
                Param::Table { .. } => "µm",
                Param::Square { .. } => "µrad",
            },
            start: x0.get(k).copied().unwrap_or(0.0),
            value: if is_fixed {
                x0.get(k).copied().unwrap_or(0.0)
            } else {
                x.get(k).copied().unwrap_or(0.0)
            },
            u: if is_fixed {
                None
            } else {
                u.as_ref().map(|u| u[k])
            },
            fixed: is_fixed,
        });
    }
    let calibrated = Machine::from_yaml_str(&yaml, machine_file)?;
    let mh = measured(obs, &hold);
    let before = norms(&(&mh - deviations(&machine, obs, &hold, obs_file)?));
    let after = norms(&(&mh - deviations(&calibrated, obs, &hold, obs_file)?));
    let mut notes = vec![
        "angular errors (EA*, EB*, EC*) and rotary axes are not identified from tip positions \
         at one tool length; they keep the file's values"
            .to_string(),
        "straightness tables are zero at the first target (forward; the offsets are in the \
         positioning tables); EXY, EXZ, EYZ use the end-point reference line, their slopes \
         are in EC0Y, EB0Z, EA0Z"
            .to_string(),
    ];
    if !prob.square {
        notes.push("squareness needs X, Y and Z linear axes; not identified".into());
    }
    let mut cal = Calibration {
        kind: "geometry",
        n_fit: fit.len(),
        n_equations: m,
        observability_o1: 0.0,
        condition_number: 0.0,
        rms_fit_mm: sol.sigma2.map_or((sol.rss / m as f64).sqrt(), f64::sqrt),
        params,
        validation: Validation::from_norms(&before, &after),
        notes: std::mem::take(&mut notes),
        yaml,
    };
    cal.set_identifiability(id);
    cal.check_validation();
    Ok(cal)
}
