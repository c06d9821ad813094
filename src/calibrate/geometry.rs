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
//! - Instrument-frame data (`# frame: instrument`): the six parameters of
//!   the instrument's pose are identified with the tables
//!   ([`super::frame`]); the values that move the points like a rigid
//!   motion of the instrument (one of each positioning table, one of
//!   `EYX`, `EZX`, `EZY`) are absorbed by it, keep the file's values and
//!   are listed.
//! - Angular errors (`EAX` … `ECZ`) and rotary axes are *not* identified:
//!   tip positions at one tool length cannot separate an angular error from
//!   the straightness it causes at the tip. They keep the file's values (and
//!   still act in the model); measure them with angular optics or a level.
//! - Entries no row reaches (a target never approached in one direction)
//!   are detected as unidentifiable, kept at the file's value and listed.
//!
//! Identification: the tip deviation is linear in these values to first
//! order; the design matrix is the finite difference (1 µm or 1 µrad) of the
//! exact forward model ([`super::forward::predict`]) of the model with the
//! values set ([`MachineTool::trial_with_params`] on the file's model with the
//! tables on the target grids, each value at the resolution the file is
//! written with), solved by linear least squares with one Gauss–Newton
//! refinement; the values found are written into the file once
//! ([`crate::machine::yaml_write`]). Uncertain values
//! ([`super::honesty`]) keep the file's value.

use nalgebra::{DMatrix, DVector, Isometry3, Vector3};

use crate::calibrate::lsq::{LsqOptions, Solution, data_error, solve_for};
use crate::error::{Error, Result};
use crate::machine::Machine;
use crate::machine::tool::{AxisKind, LocationParam, MachineTool, ToolParam};

use super::forward::{check_kind, predict};
use super::frame::{
    FRAME_PARAMS, FRAME_RANK_RTOL, carry, conditional_uncertainty, finish_if_any, frame_columns,
    frame_with, refit, screen_model, start_frame,
};
use super::observations::{MeasurementFrame, Observations, Pose};
use super::report::{CONDITION_LIMIT, Calibration, Estimate, FitCovariance, validations};
use super::screen::{
    describe_outliers, distinct_poses, dominating_rows, drop_copies, grouped_split, implausible,
};
use super::stiffness::Options;
use crate::machine::yaml_write::{self, Edit, fmt_value, round_to};

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
    /// The start values of the unknowns: the file's table values and
    /// squareness errors.
    fn start(&self, tool: &MachineTool) -> Vec<f64> {
        self.params
            .iter()
            .map(|p| start_value(tool, self, p))
            .collect()
    }

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
                fmt_value(
                    self.grids[axis].get(node).copied().unwrap_or(0.0),
                    POSITION_DECIMALS
                ),
                if forward { "+" } else { "-" }
            ),
            Param::Square { key, .. } => key.to_string(),
        }
    }

    /// Writes all identified values `x` (µm, µrad) into `text`.
    fn write(&self, text: &str, file: &str, x: &[f64]) -> Result<String> {
        let mut edits = Vec::new();
        let positions: [Vec<f64>; 3] = std::array::from_fn(|a| {
            self.grids[a]
                .iter()
                .map(|&q| round_to(q, POSITION_DECIMALS))
                .collect()
        });
        for &a in &self.axes {
            let n = self.grids[a].len();
            for e in 0..LETTERS.len() {
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
                                *c = as_written(*v);
                            }
                        }
                    }
                }
                edits.push(Edit::ComponentTable {
                    axis: a,
                    error: e,
                    positions: positions[a].clone(),
                    forward: fwd,
                    reverse: rev,
                });
            }
        }
        for (p, v) in self.params.iter().zip(x) {
            if let Param::Square { axis, key } = *p {
                edits.push(Edit::Tool(square(axis, key), as_written(*v)));
            }
        }
        yaml_write::apply(text, file, "postproc calibrate geometry", &edits)
    }

    /// The model of the file with the values `x` written in
    /// ([`Problem::write`]): every identified table on its axis' grid, so
    /// that each unknown is one value of the model ([`Problem::edits`]).
    fn on_grid(&self, text: &str, file: &str, x: &[f64]) -> Result<MachineTool> {
        match Machine::from_yaml_str(&self.write(text, file, x)?, file)? {
            Machine::Tool(t) => Ok(t),
            Machine::Robot(_) => Err(Error::Internal(format!(
                "{file}: a machine-tool file read back as a robot"
            ))),
        }
    }

    /// The values `x` as parameters of the model [`Problem::on_grid`]
    /// gives, each at the resolution it is written with
    /// ([`as_written`]): every trial model is one the written file could
    /// hold.
    fn edits(&self, x: &[f64]) -> Vec<(ToolParam, f64)> {
        self.params
            .iter()
            .zip(x)
            .map(|(p, &v)| {
                let id = match *p {
                    Param::Table {
                        axis,
                        err,
                        node,
                        forward,
                    } => ToolParam::Component {
                        axis,
                        error: err,
                        node,
                        forward,
                    },
                    Param::Square { axis, key } => square(axis, key),
                };
                (id, as_written(v))
            })
            .collect()
    }
}

/// Decimals of the component-table values and location errors written:
/// 0.01 µm or µrad.
pub const ERROR_DECIMALS: usize = 2;

/// Decimals of the table positions written, mm.
const POSITION_DECIMALS: usize = 3;

/// `v` as the file is written with it ([`ERROR_DECIMALS`]): the value a
/// model read from the written file holds.
pub fn as_written(v: f64) -> f64 {
    round_to(v, ERROR_DECIMALS)
}

/// The covariance of the identified values written (neither fixed nor
/// withheld), by their key paths (table nodes in µm, squareness in µrad:
/// the keys' units).
fn written_covariance(
    prob: &Problem,
    sol: &Solution,
    params: &[Estimate],
    withheld: &[bool],
) -> Option<FitCovariance> {
    let cols: Vec<(usize, String, f64)> = prob
        .params
        .iter()
        .enumerate()
        .filter(|(k, _)| {
            params.get(*k).is_some_and(|e| !e.fixed) && withheld.get(*k) != Some(&true)
        })
        .map(|(k, p)| {
            let key = match *p {
                Param::Table {
                    axis,
                    err,
                    node,
                    forward,
                } => ToolParam::Component {
                    axis,
                    error: err,
                    node,
                    forward,
                },
                Param::Square { axis, key } => square(axis, key),
            };
            (k, key.path(), 1.0)
        })
        .collect();
    FitCovariance::select(sol.covariance.as_ref(), &cols)
}

/// The squareness parameter of `axis` named by `key`.
fn square(axis: usize, key: &str) -> ToolParam {
    ToolParam::Location {
        axis,
        error: LocationParam::Angle(square_rotation(key)),
    }
}

/// The rotation (0..3 = about X, Y, Z) of a squareness key.
fn square_rotation(key: &str) -> usize {
    match key {
        "EC0Y_urad" => 2,
        "EA0Z_urad" => 0,
        _ => 1,
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
        Param::Square { axis, key } => tool
            .axis(axis)
            .map_or(0.0, |ax| ax.location.angles_rad[square_rotation(key)] * 1e6),
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

/// The forward model of a trial value vector on some rows: the rows'
/// predictions by the model with the values set.
type Eval<'a> = dyn Fn(&[f64], &[usize]) -> Result<DVector<f64>> + 'a;

/// The design matrix: the change of the fit rows' predictions for +1 µm
/// (µrad) of each value, at `x0` (predictions `d0`).
fn design(
    x0: &[f64],
    d0: &DVector<f64>,
    n: usize,
    eval: &Eval<'_>,
    fit: &[usize],
) -> Result<DMatrix<f64>> {
    let mut a = DMatrix::zeros(d0.len(), n);
    let mut xp = x0.to_vec();
    for k in 0..n {
        if let Some(v) = xp.get_mut(k) {
            *v += 1.0;
        }
        let dk = eval(&xp, fit)?;
        if let Some(v) = xp.get_mut(k) {
            *v -= 1.0;
        }
        a.set_column(k, &(dk - d0));
    }
    Ok(a)
}

/// The linear axes with at least two positions (an axis at one position
/// is said in `notes`) and their target grids; refuses moving rotary axes
/// and too many targets.
fn axes_and_grids(
    tool: &MachineTool,
    obs: &Observations,
    obs_file: &str,
    notes: &mut Vec<String>,
) -> Result<(Vec<usize>, [Vec<f64>; 3], bool)> {
    let linear: Vec<usize> = (0..3)
        .filter(|&s| tool.axis(s).is_some_and(|a| a.kind == AxisKind::Linear))
        .collect();
    let positions = |a: usize| {
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
        g
    };
    // An axis at one position in every row: its tables cannot be written
    // on one target (that would replace the file's table by a constant) and
    // its squareness is not seen. It keeps the file's values.
    let mut axes = Vec::new();
    for &a in &linear {
        if positions(a).len() >= 2 {
            axes.push(a);
        } else {
            notes.push(format!(
                "axis {} is at one position in every row: its tables and the squareness \
                 errors involving it are not identified and keep the file's values",
                LETTERS[a]
            ));
        }
    }
    if axes.is_empty() {
        return Err(Error::Data(format!(
            "{obs_file}: no linear axis takes two different positions; geometric calibration \
             needs measurements along the axes"
        )));
    }
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
            return Err(Error::Data(format!(
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
        let g = positions(a);
        if g.len() > MAX_TARGETS {
            return Err(Error::Data(format!(
                "{obs_file}: axis {} has {} distinct commanded positions; geometric \
                 calibration needs the measurements on target positions (ISO 230-2), \
                 at most {MAX_TARGETS} per axis",
                LETTERS[a],
                g.len()
            )));
        }
        grids[a] = g;
    }
    let square = axes.len() == 3 && linear.len() == 3;
    Ok((axes, grids, square))
}

/// The unknowns: every table value the datums leave free, then the
/// squareness errors (X, Y and Z linear and varied).
fn unknowns(axes: &[usize], grids: &[Vec<f64>; 3], square: bool) -> Vec<Param> {
    let mut params = Vec::new();
    for &a in axes {
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
        for (axis, key) in [(1, "EC0Y_urad"), (2, "EA0Z_urad"), (2, "EB0Z_urad")] {
            params.push(Param::Square { axis, key });
        }
    }
    params
}

/// The measured points of `rows` carried into the reference frame by `f`.
fn measured_at(obs: &Observations, rows: &[usize], f: &Isometry3<f64>) -> DVector<f64> {
    let mut v = measured(obs, rows);
    if *f == Isometry3::identity() {
        return v;
    }
    for k in 0..rows.len() {
        let p = carry(f, &v.fixed_rows::<3>(3 * k).into_owned());
        v.fixed_rows_mut::<3>(3 * k).copy_from(&p);
    }
    v
}

/// The design with the frame's columns (negated, at `f`) beside the
/// model's, for instrument data.
fn with_frame(
    a: &DMatrix<f64>,
    f: Option<&Isometry3<f64>>,
    obs: &Observations,
    fit: &[usize],
) -> DMatrix<f64> {
    let Some(f) = f else { return a.clone() };
    let n = a.ncols();
    let mut out = a.clone().resize_horizontally(n + FRAME_PARAMS, 0.0);
    out.columns_mut(n, FRAME_PARAMS)
        .copy_from(&(-frame_columns(f, obs, fit)));
    out
}

/// The result of the geometric fit.
struct Fitted {
    sol: Solution,
    /// Identified values (µm, µrad), all unknowns.
    x: Vec<f64>,
    /// The fit rows left after the outliers.
    fit: Vec<usize>,
    /// The identified instrument frame.
    frame: Option<Isometry3<f64>>,
}

/// The geometric fit: linear least squares at the start values `x0` with
/// one Gauss–Newton refinement, rows that disagree with every other row
/// left out first (the worst first, one per pass, at most a tenth of the
/// rows; said in `notes`). For instrument data the frame's six columns
/// are appended (from the start registration `f0`), and the model columns
/// in `absorbed` are zeroed (they keep the file's values).
#[allow(clippy::too_many_arguments)]
fn fit_tables(
    eval: &Eval<'_>,
    x0: &[f64],
    obs: &Observations,
    mut fit: Vec<usize>,
    f0: Option<Isometry3<f64>>,
    absorbed: &[usize],
    obs_file: &str,
    notes: &mut Vec<String>,
) -> Result<Fitted> {
    let n = x0.len();
    let mut d0_all = eval(x0, &fit)?;
    let mut a_all = design(x0, &d0_all, n, eval, &fit)?;
    for &c in absorbed {
        a_all.column_mut(c).fill(0.0);
    }
    let lsq = LsqOptions::default();
    let solve = |a: &DMatrix<f64>, b: &DVector<f64>| solve_for(a, b, &lsq, obs_file);
    let id = Isometry3::identity();
    let max_passes = (fit.len() / 10).max(1);
    let mut passes = 0;
    loop {
        let a = with_frame(&a_all, f0.as_ref(), obs, &fit);
        let meas = measured_at(obs, &fit, f0.as_ref().unwrap_or(&id));
        let sol0 = solve(&a, &(&meas - &d0_all))?;
        if passes < max_passes {
            passes += 1;
            let ident: Vec<usize> = sol0.identifiability.identifiable.clone();
            let a_id = a.select_columns(ident.iter());
            let outliers: Vec<_> = dominating_rows(&a_id, &sol0.residuals, &fit)
                .into_iter()
                .take(1)
                .collect();
            if !outliers.is_empty() {
                let text = describe_outliers(obs, obs_file, &outliers);
                tracing::warn!("rows left out of the fit as outliers: {text}");
                notes.push(format!("row left out of the fit as an outlier: {text}"));
                let rows_kept: Vec<usize> = fit
                    .iter()
                    .enumerate()
                    .filter(|(_, i)| !outliers.iter().any(|o| o.row == **i))
                    .flat_map(|(k, _)| [3 * k, 3 * k + 1, 3 * k + 2])
                    .collect();
                a_all = a_all.select_rows(rows_kept.iter());
                d0_all = d0_all.select_rows(rows_kept.iter());
                fit.retain(|i| !outliers.iter().any(|o| o.row == *i));
                continue;
            }
        }
        let step = |x: &[f64], d: &DVector<f64>| -> Vec<f64> {
            x.iter().zip(d.iter()).map(|(s, d)| s + d).collect()
        };
        let tail = |d: &DVector<f64>| -> Vec<f64> { d.iter().skip(n).copied().collect() };
        let x1 = step(x0, &sol0.params);
        let f1 = f0.map(|f| frame_with(&f, &tail(&sol0.params)));
        let d1 = eval(&x1, &fit).map_err(|e| implausible(&e, obs_file, fit.len()))?;
        let a = with_frame(&a_all, f1.as_ref(), obs, &fit);
        let meas = measured_at(obs, &fit, f1.as_ref().unwrap_or(&id));
        let sol = solve(&a, &(&meas - &d1))?;
        let x = step(&x1, &sol.params);
        let frame = f1.map(|f| frame_with(&f, &tail(&sol.params)));
        return Ok(Fitted { sol, x, fit, frame });
    }
}

/// The model columns an instrument frame absorbs at the start values:
/// the table values and squareness errors that move the fit rows' points
/// like a rigid motion of the instrument.
fn absorbed_by_frame(
    eval: &Eval<'_>,
    x0: &[f64],
    obs: &Observations,
    fit: &[usize],
    f0: &Isometry3<f64>,
    obs_file: &str,
) -> Result<Vec<usize>> {
    let d0 = eval(x0, fit)?;
    let a = design(x0, &d0, x0.len(), eval, fit)?;
    // The frame's columns at the points the start model predicts, seen by
    // the instrument: a rigid motion is then exactly a motion of those
    // points, whatever the noise.
    let mut seen = obs.clone();
    let back = f0.inverse();
    for (k, &i) in fit.iter().enumerate() {
        if let Some(row) = seen.rows.get_mut(i) {
            row.measured_mm = carry(&back, &d0.fixed_rows::<3>(3 * k).into_owned());
        }
    }
    let jf = frame_columns(f0, &seen, fit);
    let b = measured_at(obs, fit, f0) - d0;
    let lsq = LsqOptions {
        rank_rtol: FRAME_RANK_RTOL,
        scale_columns: true,
    };
    let (given, plain) =
        screen_model(&a, Some(&jf), &b, &lsq).map_err(|e| data_error(obs_file, e))?;
    Ok(given.into_iter().filter(|c| !plain.contains(c)).collect())
}

/// The report's rows: every unknown, identified (with its uncertainty) or
/// kept at its start value `x0` when the solution cannot identify it.
fn estimates(prob: &Problem, sol: &Solution, x0: &[f64], x: &[f64]) -> Vec<Estimate> {
    let u = sol.std_uncertainty();
    let fixed: std::collections::BTreeSet<usize> =
        sol.identifiability.unidentifiable.iter().copied().collect();
    let mut params = Vec::with_capacity(prob.params.len());
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
    params
}

/// The notes every geometric calibration gives: what is not identified and
/// the table conventions.
fn fixed_notes(square: bool) -> Vec<String> {
    let mut notes = vec![
        "angular errors (EA*, EB*, EC*) and rotary axes are not identified from tip positions \
         at one tool length; they keep the file's values"
            .to_string(),
        "straightness tables are zero at the first target (forward; the offsets are in the \
         positioning tables); EXY, EXZ, EYZ use the end-point reference line, their slopes \
         are in EC0Y, EB0Z, EA0Z"
            .to_string(),
    ];
    if !square {
        notes.push("squareness needs X, Y and Z linear axes, all varied; not identified".into());
    }
    notes
}

/// The instrument frame written with the calibrated model `calibrated`,
/// with its uncertainties: the joint fit's frame `f` (columns `n..` of
/// `sol`) when every identified value is written, else the frame re-solved
/// alone for the written values (the withheld ones at the file's value,
/// [`refit`]), so that it is the frame of the model it is written with.
fn written_frame(
    calibrated: &Machine,
    obs: &Observations,
    fit: &[usize],
    (f, sol): (Isometry3<f64>, &Solution),
    n: usize,
    withheld: &[bool],
    obs_file: &str,
) -> Result<(Isometry3<f64>, Option<[f64; FRAME_PARAMS]>)> {
    let fixed: Vec<usize> = (0..n).filter(|&k| withheld.get(k) == Some(&true)).collect();
    let frame_cols: Vec<usize> = (n..n + FRAME_PARAMS).collect();
    let joint = conditional_uncertainty(sol.covariance.as_ref(), &frame_cols, &fixed);
    if fixed.is_empty() {
        return Ok((f, joint));
    }
    let model = deviations(calibrated, obs, fit, obs_file)?;
    let points = |v: &DVector<f64>| -> Vec<Vector3<f64>> {
        (0..fit.len())
            .map(|k| v.fixed_rows::<3>(3 * k).into_owned())
            .collect()
    };
    refit(
        &points(&measured(obs, fit)),
        &points(&model),
        joint,
        obs_file,
    )
}

/// Refuses a badly conditioned fit.
fn check_condition(id: &crate::calibrate::lsq::Identifiability, obs_file: &str) -> Result<()> {
    if id.condition_number_identified > CONDITION_LIMIT {
        return Err(Error::Data(format!(
            "{obs_file}: badly conditioned data set: condition number {:.3e} > {:.0e} \
             (O1 = {:.3e}); vary all axes independently over their targets and the \
             approach directions",
            id.condition_number_identified, CONDITION_LIMIT, id.observability_o1
        )));
    }
    Ok(())
}

/// The unknowns of a geometric calibration: the axes and grids
/// [`axes_and_grids`] chooses (its notes added to `notes`), their table
/// values and the squareness errors when identified.
fn problem(
    tool: &MachineTool,
    obs: &Observations,
    obs_file: &str,
    notes: &mut Vec<String>,
) -> Result<Problem> {
    let (axes, grids, square) = axes_and_grids(tool, obs, obs_file, notes)?;
    let params = unknowns(&axes, &grids, square);
    Ok(Problem {
        grids,
        axes,
        params,
        square,
    })
}

/// The values written: the fitted `x`, with the file's value `x0` where
/// the honesty rule withholds the estimate (`withheld`).
fn kept_where_withheld(x: &[f64], x0: &[f64], withheld: &[bool]) -> Vec<f64> {
    x.iter()
        .zip(x0)
        .zip(withheld)
        .map(|((&v, &v0), &w)| if w { v0 } else { v })
        .collect()
}

/// Refuses a fit with too few distinct poses (`distinct` among `n_rows`
/// fitted rows) for its `n` table values and squareness errors (and the six
/// frame parameters when `instrument`).
fn check_enough_poses(
    distinct: usize,
    n_rows: usize,
    n: usize,
    instrument: bool,
    obs_file: &str,
) -> Result<()> {
    if n == 0 || 3 * distinct <= (n + if instrument { FRAME_PARAMS } else { 0 }) {
        Err(Error::Data(format!(
            "{obs_file}: {distinct} distinct poses left for the fit ({} rows; repeated poses \
             count once) for {n} table values and squareness errors{}; measure more points \
             (or fewer targets per axis)",
            n_rows,
            if instrument {
                " and the 6 parameters of the instrument frame"
            } else {
                ""
            }
        )))
    } else {
        Ok(())
    }
}

/// Identifies the component error tables and squareness from `obs` (and
/// the instrument frame for `# frame: instrument` data).
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
    let (clean, copies) = drop_copies(obs, obs_file);
    let obs = &clean;
    let mut early_notes: Vec<String> = copies.into_iter().collect();
    let prob = problem(tool, obs, obs_file, &mut early_notes)?;
    let n = prob.params.len();
    let instrument = obs.frame == MeasurementFrame::Instrument;
    let (fit, hold) = grouped_split(obs, opts.holdout, opts.seed);
    let distinct = distinct_poses(obs, &fit);
    check_enough_poses(distinct, fit.len(), n, instrument, obs_file)?;
    tracing::info!(
        "geometry: {} rows for the fit, {} held out, {n} values",
        fit.len(),
        hold.len()
    );
    let x0 = prob.start(tool);
    let on_grid = prob.on_grid(text, machine_file, &x0)?;
    let eval = |x: &[f64], rows: &[usize]| -> Result<DVector<f64>> {
        let trial = Machine::Tool(on_grid.trial_with_params(&prob.edits(x))?);
        deviations(&trial, obs, rows, obs_file)
    };
    let f0 = if instrument {
        Some(start_frame(&machine, obs, &fit, obs_file)?)
    } else {
        None
    };
    let absorbed = match &f0 {
        Some(f) => absorbed_by_frame(&eval, &x0, obs, &fit, f, obs_file)?,
        None => Vec::new(),
    };
    let Fitted { sol, x, fit, frame } = fit_tables(
        &eval,
        &x0,
        obs,
        fit,
        f0,
        &absorbed,
        obs_file,
        &mut early_notes,
    )?;
    let m = 3 * fit.len();
    let id = &sol.identifiability;
    check_condition(id, obs_file)?;
    let params = estimates(&prob, &sol, &x0, &x);
    // Uncertain values keep the file's value (super::honesty).
    let withheld = opts.honesty.withheld(&params);
    let uncertain = opts.honesty.uncertain(&params);
    let x = kept_where_withheld(&x, &x0, &withheld);
    let written = prob.write(text, machine_file, &x).and_then(|t| {
        let m = Machine::from_yaml_str(&t, machine_file)?;
        Ok((t, m))
    });
    let (yaml, calibrated) = written.map_err(|e| implausible(&e, obs_file, fit.len()))?;
    let frame = match frame {
        Some(f) => Some(written_frame(
            &calibrated,
            obs,
            &fit,
            (f, &sol),
            n,
            &withheld,
            obs_file,
        )?),
        None => None,
    };
    let ident = Isometry3::identity();
    let f_start = f0.unwrap_or(ident);
    let f_end = frame.map_or(ident, |(f, _)| f);
    let (validation, fit_check) = validations(&hold, &fit, |cal, rows| {
        let (m, f) = if cal {
            (&calibrated, &f_end)
        } else {
            (&machine, &f_start)
        };
        Ok(norms(
            &(measured_at(obs, rows, f) - deviations(m, obs, rows, obs_file)?),
        ))
    })?;
    let covariance = written_covariance(&prob, &sol, &params, &withheld);
    let mut notes = fixed_notes(prob.square);
    notes.append(&mut early_notes);
    let (yaml, frame_est) = finish_if_any(
        yaml,
        machine_file,
        frame,
        (&params, &absorbed),
        "the positioning offsets and the straightness slopes are then relative to the \
         frame",
        &mut notes,
    )?;
    Ok(Calibration {
        kind: "geometry",
        n_fit: fit.len(),
        n_equations: m,
        observability_o1: 0.0,
        condition_number: 0.0,
        rms_fit_mm: sol.rms_fit(m),
        params,
        validation,
        fit_check,
        frame: frame_est,
        insignificant: Vec::new(),
        uncertain,
        honesty: opts.honesty,
        notes: std::mem::take(&mut notes),
        yaml,
        covariance,
    }
    .finished(id))
}
