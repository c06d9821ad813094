//! How well a prediction is known: the covariance of a predicted
//! deviation from the covariance of the model's identified parameters,
//! to first order through the prediction's sensitivities,
//! C = J Σ Jᵀ (J: 3 × n, mm per parameter unit; Σ: n × n in the units
//! of the parameters' keys), and its expanded uncertainty U = k·u with
//! k = [`COVERAGE_K`] = 2 — per coordinate, along a direction, or per
//! effect (the parameters of one effect alone).
//!
//! The sensitivities of a machine tool's tip deviation and of a robot's
//! TCP deviation to their parameters come from central differences of
//! models with each parameter moved by its step, built once
//! ([`ToolSensitivity`], [`RobotSensitivity`]); each evaluation at a pose
//! is then two predictions per parameter.
//!
//! A machine file carries the covariance of what a calibration identified
//! in its top-level `covariance` list, one entry per calibrated section
//! ([`CovarianceBlock`]: the key path of each parameter, its standard
//! uncertainty in the key's unit, the correlations, and the data it came
//! from); a file without the list carries no uncertainty and
//! [`read_covariance`] says so with an empty list:
//!
//! ```yaml
//! covariance:
//!   - kind: geometry
//!     observations: grid.csv
//!     observations_sha256: 9f…
//!     rows: 242
//!     parameters: ["axes[Y].location_errors.EC0Y_urad", "axes[X].component_errors.EXX_um.forward[3]"]
//!     u: [1.2, 0.8]
//!     correlation:
//!       - [1.0, 0.12]
//!       - [0.12, 1.0]
//! ```

use nalgebra::{DMatrix, Matrix3, Matrix3xX, Vector3};

use crate::error::{Error, Result};
use crate::machine::robot::{DhField, Model, Robot, RobotParam, ThermalField};
use crate::machine::tool::{LocationParam, MachineTool, ToolParam};
use crate::machine::{AxisVec, DirVec};

/// Coverage factor of an expanded uncertainty (about 95 % for a normal
/// distribution).
pub const COVERAGE_K: f64 = 2.0;

/// Largest relative asymmetry of a covariance matrix accepted.
pub const SYMMETRY_RTOL: f64 = 1e-9;

/// The covariance of a model's parameters, with the effect each belongs
/// to (`geometric`, `kinematic`, …).
#[derive(Debug, Clone, PartialEq)]
pub struct ParamCovariance {
    effects: Vec<&'static str>,
    cov: DMatrix<f64>,
}

impl ParamCovariance {
    /// A covariance of `effects.len()` parameters: square, of that size,
    /// finite, symmetric within [`SYMMETRY_RTOL`] and with a non-negative
    /// diagonal.
    pub fn new(effects: Vec<&'static str>, cov: DMatrix<f64>) -> Result<Self> {
        let n = effects.len();
        if cov.shape() != (n, n) {
            return Err(Error::Data(format!(
                "a covariance of {n} parameters is {n}×{n}, not {}×{}",
                cov.nrows(),
                cov.ncols()
            )));
        }
        if cov.iter().any(|v| !v.is_finite()) {
            return Err(Error::Data(
                "a covariance holds a value that is not finite".into(),
            ));
        }
        let scale = cov.amax().max(f64::MIN_POSITIVE);
        for i in 0..n {
            if cov[(i, i)] < 0.0 {
                return Err(Error::Data(format!(
                    "parameter {i} has a negative variance"
                )));
            }
            for j in 0..i {
                if (cov[(i, j)] - cov[(j, i)]).abs() > SYMMETRY_RTOL * scale {
                    return Err(Error::Data(format!(
                        "the covariance is not symmetric at ({i}, {j})"
                    )));
                }
            }
        }
        Ok(ParamCovariance { effects, cov })
    }

    /// Number of parameters.
    pub fn len(&self) -> usize {
        self.effects.len()
    }

    /// Whether there are no parameters.
    pub fn is_empty(&self) -> bool {
        self.effects.is_empty()
    }

    /// The covariance matrix.
    pub fn matrix(&self) -> &DMatrix<f64> {
        &self.cov
    }

    /// The effects, each once, in the order of their first parameter.
    pub fn effect_names(&self) -> Vec<&'static str> {
        let mut out: Vec<&'static str> = Vec::new();
        for e in &self.effects {
            if !out.contains(e) {
                out.push(e);
            }
        }
        out
    }
}

/// The covariance of a predicted deviation, mm².
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DeviationUncertainty {
    /// C = J Σ Jᵀ, mm².
    pub cov_mm2: Matrix3<f64>,
}

impl DeviationUncertainty {
    /// Expanded uncertainty of each coordinate, k·√C_ii, mm.
    pub fn expanded_xyz_mm(&self, k: f64) -> Vector3<f64> {
        self.cov_mm2.diagonal().map(|v| k * v.max(0.0).sqrt())
    }

    /// Expanded uncertainty of the component along `dir` (normalised
    /// here), mm; 0 for a zero direction.
    pub fn expanded_along_mm(&self, dir: &Vector3<f64>, k: f64) -> f64 {
        let n = dir.norm();
        if n == 0.0 {
            return 0.0;
        }
        let u = dir / n;
        k * (u.transpose() * self.cov_mm2 * u)[0].max(0.0).sqrt()
    }

    /// Expanded uncertainty of the length of the deviation `dev`, to first
    /// order (along `dev`), mm; for a deviation of zero the largest
    /// along any direction.
    pub fn expanded_length_mm(&self, dev: &Vector3<f64>, k: f64) -> f64 {
        if dev.norm() > 0.0 {
            self.expanded_along_mm(dev, k)
        } else {
            k * self.cov_mm2.symmetric_eigenvalues().max().max(0.0).sqrt()
        }
    }
}

/// C = J Σ Jᵀ of sensitivities `jac` (3 × n) and a parameter covariance.
pub fn propagate(jac: &Matrix3xX<f64>, cov: &ParamCovariance) -> Result<DeviationUncertainty> {
    if jac.ncols() != cov.len() {
        return Err(Error::Internal(format!(
            "{} sensitivities for {} parameters",
            jac.ncols(),
            cov.len()
        )));
    }
    let c = jac * &cov.cov * jac.transpose();
    Ok(DeviationUncertainty {
        cov_mm2: (c + c.transpose()) * 0.5,
    })
}

/// The uncertainty due to each effect's parameters alone (their block of
/// the covariance), in the order of [`ParamCovariance::effect_names`].
pub fn per_effect(
    jac: &Matrix3xX<f64>,
    cov: &ParamCovariance,
) -> Result<Vec<(&'static str, DeviationUncertainty)>> {
    if jac.ncols() != cov.len() {
        return Err(Error::Internal(format!(
            "{} sensitivities for {} parameters",
            jac.ncols(),
            cov.len()
        )));
    }
    Ok(cov
        .effect_names()
        .into_iter()
        .map(|e| {
            let idx: Vec<usize> = (0..cov.len()).filter(|&i| cov.effects[i] == e).collect();
            let mut c = Matrix3::zeros();
            for &i in &idx {
                for &j in &idx {
                    c += jac.column(i) * jac.column(j).transpose() * cov.cov[(i, j)];
                }
            }
            (e, DeviationUncertainty { cov_mm2: c })
        })
        .collect())
}

/// The covariance of one calibrated section as a machine file records it.
#[derive(Debug, Clone, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CovarianceBlock {
    /// What was identified (`geometry`, `kinematics`, `stiffness`,
    /// `thermal`, `diagnose`).
    pub kind: String,
    /// File name of the observation file.
    pub observations: String,
    /// SHA-256 of the observation file's bytes, lower-case hex.
    pub observations_sha256: String,
    /// Rows of the observation file used.
    pub rows: usize,
    /// Key path of each parameter.
    pub parameters: Vec<String>,
    /// Standard uncertainty of each, in the unit of its key.
    pub u: Vec<f64>,
    /// Correlation matrix, one row per parameter.
    pub correlation: Vec<Vec<f64>>,
}

/// Largest departure of a correlation from symmetry or of its diagonal
/// from 1 accepted (the four decimals a file writes).
pub const CORRELATION_TOL: f64 = 1e-4;

impl CovarianceBlock {
    /// The block of a fit: parameters, their covariance and the data.
    pub fn from_fit(
        kind: &str,
        observations: &str,
        observations_sha256: &str,
        rows: usize,
        parameters: Vec<String>,
        cov: &DMatrix<f64>,
    ) -> Self {
        let u: Vec<f64> = cov.diagonal().iter().map(|v| v.max(0.0).sqrt()).collect();
        let n = u.len();
        let correlation = (0..n)
            .map(|i| {
                (0..n)
                    .map(|j| {
                        if i == j {
                            1.0
                        } else if u[i] > 0.0 && u[j] > 0.0 {
                            (cov[(i, j)] / (u[i] * u[j])).clamp(-1.0, 1.0)
                        } else {
                            0.0
                        }
                    })
                    .collect()
            })
            .collect();
        CovarianceBlock {
            kind: kind.to_string(),
            observations: observations.to_string(),
            observations_sha256: observations_sha256.to_string(),
            rows,
            parameters,
            u,
            correlation,
        }
    }

    /// The effect the parameters of a calibration kind belong to.
    pub fn effect(&self) -> &'static str {
        match self.kind.as_str() {
            "geometry" => "geometric",
            "kinematics" => "kinematic",
            "stiffness" => "static",
            "thermal" => "thermal",
            _ => "other",
        }
    }

    /// Refuses a block whose sizes disagree, whose uncertainties are
    /// negative or not finite, or whose correlation is not symmetric with
    /// a unit diagonal and entries within ±1 (to [`CORRELATION_TOL`]).
    pub fn validate(&self) -> std::result::Result<(), String> {
        let n = self.parameters.len();
        if self.u.len() != n || self.correlation.len() != n {
            return Err(format!(
                "{n} parameters but {} uncertainties and {} correlation rows",
                self.u.len(),
                self.correlation.len()
            ));
        }
        if let Some(v) = self.u.iter().find(|v| !(v.is_finite() && **v >= 0.0)) {
            return Err(format!("an uncertainty of {v}: not a number of at least 0"));
        }
        for (i, row) in self.correlation.iter().enumerate() {
            if row.len() != n {
                return Err(format!(
                    "correlation row {i} has {} values, not {n}",
                    row.len()
                ));
            }
            for (j, r) in row.iter().enumerate() {
                let bad = !r.is_finite()
                    || r.abs() > 1.0 + CORRELATION_TOL
                    || (i == j && (r - 1.0).abs() > CORRELATION_TOL)
                    || (r - self.correlation[j][i]).abs() > CORRELATION_TOL;
                if bad {
                    return Err(format!("correlation ({i}, {j}) = {r} is not a correlation"));
                }
            }
        }
        Ok(())
    }

    /// The covariance matrix u_i ρ_ij u_j (symmetrised).
    pub fn covariance(&self) -> Result<ParamCovariance> {
        self.validate().map_err(Error::Data)?;
        let n = self.u.len();
        let c = DMatrix::from_fn(n, n, |i, j| {
            let r = 0.5 * (self.correlation[i][j] + self.correlation[j][i]);
            self.u[i] * r * self.u[j]
        });
        ParamCovariance::new(vec![self.effect(); n], c)
    }

    /// The block as an entry of the `covariance` list (two-space indent,
    /// uncertainties in shortest round-trip form, correlations to four
    /// decimals).
    pub fn to_yaml_entry(&self) -> String {
        let (parameters, u, rows) = self.texts();
        let mut out = format!(
            "  - kind: {}\n    observations: {}\n    observations_sha256: {}\n    rows: {}\n    parameters: [{parameters}]\n    u: [{u}]\n    correlation:\n",
            self.kind,
            serde_json::to_string(&self.observations).unwrap_or_default(),
            self.observations_sha256,
            self.rows,
        );
        for r in rows {
            out.push_str(&format!("      - [{r}]\n"));
        }
        out
    }

    /// The block as one flow mapping, for a machine file in flow style.
    pub fn to_flow_entry(&self) -> String {
        let (parameters, u, rows) = self.texts();
        let rows: Vec<String> = rows.iter().map(|r| format!("[{r}]")).collect();
        format!(
            "{{ kind: {}, observations: {}, observations_sha256: {}, rows: {}, parameters: [{parameters}], u: [{u}], correlation: [{}] }}",
            self.kind,
            serde_json::to_string(&self.observations).unwrap_or_default(),
            self.observations_sha256,
            self.rows,
            rows.join(", ")
        )
    }

    /// The parameter list, the u list and each correlation row, as the
    /// text inside their brackets.
    fn texts(&self) -> (String, String, Vec<String>) {
        let quoted: Vec<String> = self
            .parameters
            .iter()
            .map(|p| serde_json::to_string(p).unwrap_or_default())
            .collect();
        let u: Vec<String> = self.u.iter().map(|v| format!("{v:?}")).collect();
        let rows = self
            .correlation
            .iter()
            .map(|row| {
                let r: Vec<String> = row
                    .iter()
                    .map(|v| {
                        let s = format!("{v:.4}");
                        if s == "-0.0000" { "0.0000".into() } else { s }
                    })
                    .collect();
                r.join(", ")
            })
            .collect();
        (quoted.join(", "), u.join(", "), rows)
    }
}

/// The `covariance` list of a machine file (empty: the file carries no
/// parameter uncertainty); `file` names it in errors.
pub fn read_covariance(text: &str, file: &str) -> Result<Vec<CovarianceBlock>> {
    #[derive(serde::Deserialize)]
    struct Raw {
        #[serde(default)]
        covariance: Vec<CovarianceBlock>,
    }
    let raw: Raw = crate::machine::yaml::deserialize(text, file)?;
    for (i, b) in raw.covariance.iter().enumerate() {
        b.validate().map_err(|m| {
            crate::machine::yaml::located(text, file, &format!("covariance[{i}]"), &m)
        })?;
    }
    Ok(raw.covariance)
}

/// The machine file `text` with `block` in its `covariance` list: the
/// block of the same kind replaced, or added (with the list when the file
/// has none, at its end). The list is written whole in block style where
/// the file had it; every other line is kept as it is.
pub fn put_covariance(text: &str, file: &str, block: &CovarianceBlock) -> Result<String> {
    let mut blocks = read_covariance(text, file)?;
    blocks.retain(|b| b.kind != block.kind);
    blocks.push(block.clone());
    write_covariance_list(text, file, &blocks)
}

/// Why the parameters of `block`, written for the model `before`, no
/// longer name the same values of the model `after` (`None`: they do): a
/// key path `before` has and `after` does not, or a node of a component
/// table whose node positions changed (the table re-gridded: node `i` of
/// the new table is another position, and the table interpolates
/// between other nodes). Paths neither model resolves are not judged.
pub fn stale_reason(
    before: &crate::machine::Machine,
    after: &crate::machine::Machine,
    block: &CovarianceBlock,
) -> Option<String> {
    let (b, a) = (path_meanings(before), path_meanings(after));
    for p in &block.parameters {
        match (b.get(p), a.get(p)) {
            (Some(_), None) => {
                return Some(format!("`{p}` is not a value of the written model"));
            }
            (Some(x), Some(y)) if x != y => {
                let table = p.rsplit_once('.').map_or(p.as_str(), |(t, _)| t);
                return Some(format!(
                    "the table `{table}` was re-gridded ({} nodes at {} → {} nodes at {}), so `{p}` names another value",
                    x.len(),
                    positions_text(x),
                    y.len(),
                    positions_text(y)
                ));
            }
            _ => {}
        }
    }
    None
}

/// The node positions of a table as a short text (`0, 250, …, 1000`).
fn positions_text(p: &[f64]) -> String {
    let all: Vec<String> = p.iter().map(|v| format!("{v}")).collect();
    if all.len() <= 4 {
        all.join(", ")
    } else {
        format!("{}, {}, …, {}", all[0], all[1], all[all.len() - 1])
    }
}

/// Each parameter key path of a model with what fixes its meaning beyond
/// the path: the node positions of its component table (empty for every
/// other value).
fn path_meanings(machine: &crate::machine::Machine) -> std::collections::HashMap<String, Vec<f64>> {
    use crate::machine::Machine;
    match machine {
        Machine::Tool(t) => tool_params(t)
            .into_iter()
            .map(|p| {
                let at = match p {
                    ToolParam::Component { axis, error, .. } => t
                        .component_table(axis, error)
                        .map(|[pos, _, _]| pos)
                        .unwrap_or_default(),
                    _ => Vec::new(),
                };
                (p.path(), at)
            })
            .collect(),
        Machine::Robot(r) => robot_params(r)
            .into_iter()
            .map(|p| (p.path(), Vec::new()))
            .collect(),
    }
}

/// The machine file `text` (of the model written from `before`) without
/// the blocks of its `covariance` list whose parameters no longer match
/// its model ([`stale_reason`]), with one warning per block dropped
/// (naming it and why). The block of kind `fresh`, just written for the
/// file's model, is not judged. A file with every block dropped keeps an
/// empty list; a file with none dropped is returned as it is.
pub fn drop_stale_covariance(
    before: &crate::machine::Machine,
    text: &str,
    file: &str,
    fresh: Option<&str>,
) -> Result<(String, Vec<String>)> {
    let blocks = read_covariance(text, file)?;
    if blocks.is_empty() {
        return Ok((text.to_string(), Vec::new()));
    }
    let after = crate::machine::Machine::from_yaml_str(text, file)?;
    let mut keep = Vec::with_capacity(blocks.len());
    let mut warnings = Vec::new();
    for (i, b) in blocks.into_iter().enumerate() {
        let why = match fresh {
            Some(k) if k == b.kind => None,
            _ => stale_reason(before, &after, &b),
        };
        match why {
            Some(why) => warnings.push(format!(
                "{file}: covariance[{i}] (kind {}, from {}) dropped: {why}; its parameters no longer match the model (recalibrate to get their uncertainty back)",
                b.kind, b.observations
            )),
            None => keep.push(b),
        }
    }
    if warnings.is_empty() {
        return Ok((text.to_string(), warnings));
    }
    Ok((write_covariance_list(text, file, &keep)?, warnings))
}

/// The machine file `text` with its `covariance` list made `blocks`
/// (written whole in block style where the file had it, added at its end
/// when the file has none); every other line is kept as it is.
fn write_covariance_list(text: &str, file: &str, blocks: &[CovarianceBlock]) -> Result<String> {
    let flow = crate::machine::yaml::tree_root(text)
        .ok()
        .and_then(|r| r.as_mapping().map(|m| m.is_flow_style()))
        .unwrap_or(false);
    if flow {
        // A file in flow style gets the list in flow style, on the tree.
        let rows = blocks.iter().map(CovarianceBlock::to_flow_entry).collect();
        let edit = crate::machine::yaml_write::Edit::Section {
            path: "covariance".into(),
            value: crate::machine::yaml_write::NewValue::Rows(rows),
            comment: String::new(),
        };
        return crate::machine::yaml_write::apply(text, file, "calibrate", &[edit]);
    }
    let mut list = String::from(if blocks.is_empty() {
        "covariance: []\n"
    } else {
        "covariance:\n"
    });
    for b in blocks {
        list.push_str(&b.to_yaml_entry());
    }
    let lines: Vec<&str> = text.split_inclusive('\n').collect();
    let start = lines.iter().position(|l| {
        l.strip_prefix("covariance:")
            .is_some_and(|r| r.trim().is_empty() || r.starts_with([' ', '\t']))
    });
    let Some(start) = start else {
        let mut out = text.to_string();
        if !out.is_empty() && !out.ends_with('\n') {
            out.push('\n');
        }
        out.push_str(COVERAGE_COMMENT);
        out.push_str(&list);
        return Ok(out);
    };
    // The section runs to the next line at column 0 that is not a list
    // item of it (blank lines and comments before that line stay after it).
    let mut end = start + 1;
    let mut last = start + 1;
    while let Some(l) = lines.get(end) {
        let t = l.trim_end();
        if t.is_empty() || t.starts_with('#') {
            end += 1;
            continue;
        }
        if t.starts_with([' ', '\t', '-']) {
            end += 1;
            last = end;
            continue;
        }
        break;
    }
    let mut out: String = lines[..start].concat();
    out.push_str(&list);
    out.push_str(&lines[last..].concat());
    Ok(out)
}

/// The comment line above a new `covariance` list.
const COVERAGE_COMMENT: &str =
    "# parameter uncertainty of the calibrated values (postproc calibrate; docs/verify.md)\n";

/// Sensitivities of a machine tool's predicted tip deviation (attained −
/// nominal, geometric chain) to its parameters.
#[derive(Debug, Clone)]
pub struct ToolSensitivity {
    moved: Vec<(MachineTool, MachineTool, f64)>,
}

impl ToolSensitivity {
    /// The models with each parameter moved by ± its step (in the unit of
    /// its key: µm, µrad, mm).
    pub fn new(machine: &MachineTool, params: &[(ToolParam, f64)]) -> Result<Self> {
        let moved = params
            .iter()
            .map(|&(p, step)| {
                let v = machine.param_value(p).unwrap_or(0.0);
                Ok((
                    machine.with_params(&[(p, v + step)])?,
                    machine.with_params(&[(p, v - step)])?,
                    step,
                ))
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(ToolSensitivity { moved })
    }

    /// J at a command: mm per unit of each parameter.
    pub fn jacobian(&self, cmd: &AxisVec, dirs: &DirVec, tool_mm: f64) -> Matrix3xX<f64> {
        let mut j = Matrix3xX::zeros(self.moved.len());
        for (c, (plus, minus, step)) in self.moved.iter().enumerate() {
            let d = plus.tip_error_mm(cmd, dirs, tool_mm) - minus.tip_error_mm(cmd, dirs, tool_mm);
            j.set_column(c, &(d / (2.0 * step)));
        }
        j
    }
}

/// Sensitivities of a robot's TCP position (the calibrated model) to its
/// parameters.
#[derive(Debug, Clone)]
pub struct RobotSensitivity {
    moved: Vec<(Robot, Robot, f64)>,
}

impl RobotSensitivity {
    /// The models with each parameter moved by ± its step (in the unit of
    /// its key: mm, deg, …).
    pub fn new(robot: &Robot, params: &[(RobotParam, f64)]) -> Result<Self> {
        let moved = params
            .iter()
            .map(|&(p, step)| {
                let v = robot.param_value(p).unwrap_or(0.0);
                Ok((
                    robot.with_params(&[(p, v + step)])?,
                    robot.with_params(&[(p, v - step)])?,
                    step,
                ))
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(RobotSensitivity { moved })
    }

    /// J at joint angles `q` (rad): mm per unit of each parameter.
    pub fn jacobian(&self, q: &[f64; 6]) -> Matrix3xX<f64> {
        let mut j = Matrix3xX::zeros(self.moved.len());
        for (c, (plus, minus, step)) in self.moved.iter().enumerate() {
            let d = plus.tcp_pose(Model::Actual, q).translation.vector
                - minus.tcp_pose(Model::Actual, q).translation.vector;
            j.set_column(c, &(d / (2.0 * step)));
        }
        j
    }
}

/// Every parameter of a machine tool's model with a value in its file, by
/// key path (stiffness and thermal grids by their one-value keys only).
fn tool_params(machine: &MachineTool) -> Vec<ToolParam> {
    let mut all = Vec::new();
    let locations = || {
        (0..3)
            .map(LocationParam::Offset)
            .chain((0..3).map(LocationParam::Angle))
            .chain([LocationParam::Zero])
    };
    for axis in 0..6 {
        for error in 0..6 {
            for forward in [true, false] {
                let mut node = 0;
                while machine
                    .param_value(ToolParam::Component {
                        axis,
                        error,
                        node,
                        forward,
                    })
                    .is_some()
                {
                    all.push(ToolParam::Component {
                        axis,
                        error,
                        node,
                        forward,
                    });
                    node += 1;
                }
            }
        }
        all.extend(locations().map(|error| ToolParam::Location { axis, error }));
        all.push(ToolParam::AxisScale { axis });
        all.push(ToolParam::AxisTimeConstant { axis });
    }
    all.extend(locations().map(|error| ToolParam::SpindleLocation { error }));
    all.extend([ToolParam::SpindleGrowth, ToolParam::SpindleTimeConstant]);
    all
}

/// The key paths of the parameters of a model's geometric chain (a
/// machine tool's component tables and location errors, a robot's DH
/// values and tool offset): those of a diagnosis's block that the
/// sensitivities propagate.
fn chain_paths(machine: &crate::machine::Machine) -> Vec<String> {
    use crate::machine::Machine;
    match machine {
        Machine::Tool(t) => tool_params(t)
            .into_iter()
            .filter(|p| {
                matches!(
                    p,
                    ToolParam::Component { .. }
                        | ToolParam::Location { .. }
                        | ToolParam::SpindleLocation { .. }
                )
            })
            .map(|p| p.path())
            .collect(),
        Machine::Robot(r) => robot_params(r)
            .into_iter()
            .filter(|p| matches!(p, RobotParam::Dh { .. } | RobotParam::ToolOffset { .. }))
            .map(|p| p.path())
            .collect(),
    }
}

/// The correction a robot parameter makes: its value less the nominal
/// model's for a DH value (angles in degrees), the value itself otherwise.
fn robot_correction(r: &Robot, p: RobotParam) -> f64 {
    let v = r.param_value(p).unwrap_or(0.0);
    match p {
        RobotParam::Dh { joint, field } => {
            let Some(j) = r.params(Model::Nominal).joints.get(joint) else {
                return v;
            };
            v - match field {
                DhField::A => j.a_mm,
                DhField::Alpha => j.alpha_rad.to_degrees(),
                DhField::D => j.d_mm,
                DhField::ThetaOffset => j.theta_offset_rad.to_degrees(),
            }
        }
        _ => v,
    }
}

/// Every parameter of a robot's model, by key path.
fn robot_params(robot: &Robot) -> Vec<RobotParam> {
    let mut all = Vec::new();
    for joint in 0..6 {
        for field in [DhField::A, DhField::Alpha, DhField::D, DhField::ThetaOffset] {
            all.push(RobotParam::Dh { joint, field });
        }
        all.push(RobotParam::JointStiffness { joint });
    }
    all.extend((0..3).map(|axis| RobotParam::ToolOffset { axis }));
    let mut term = 0;
    while robot
        .param_value(RobotParam::Thermal {
            term,
            field: ThermalField::Lb,
        })
        .is_some()
    {
        for field in [ThermalField::Lb, ThermalField::Ub, ThermalField::Ts] {
            all.push(RobotParam::Thermal { term, field });
        }
        term += 1;
    }
    all.extend([RobotParam::ThermalTimeConstant, RobotParam::PayloadMass]);
    all
}

/// The parameter of each key path in `paths` among `all` (named by
/// `key`), with its step; the first path that names none is the error.
fn by_path<P: Copy>(
    all: &[P],
    key: fn(&P) -> String,
    paths: &[String],
    steps: &[f64],
) -> std::result::Result<Vec<(P, f64)>, String> {
    let keys: Vec<String> = all.iter().map(key).collect();
    paths
        .iter()
        .zip(steps)
        .map(|(p, s)| {
            keys.iter()
                .position(|k| k == p)
                .and_then(|i| all.get(i))
                .map(|q| (*q, *s))
                .ok_or_else(|| p.clone())
        })
        .collect()
}

/// The expanded uncertainty (k = [`COVERAGE_K`]) of one predicted
/// deviation: of its length, and of the part of each effect.
#[derive(Debug, Clone, PartialEq)]
pub struct BlockU {
    /// U of the deviation's length (along the deviation; of its largest
    /// coordinate when the deviation is 0), mm.
    pub total_mm: f64,
    /// U of the deviation's length from each effect's parameters alone,
    /// in [`BlockUncertainty::effects`] order, mm.
    pub effects_mm: Vec<f64>,
}

/// How the sensitivities are taken.
#[derive(Debug, Clone)]
enum Sensitivity {
    Tool(ToolSensitivity),
    Robot(RobotSensitivity),
}

/// The uncertainty of every predicted deviation of a model whose machine
/// file carries a `covariance` list: the parameters of its geometric
/// (machine tool) or kinematic (robot) blocks with their covariance (the
/// blocks independent of one another) and the model's sensitivities to
/// them, and the parameters of a diagnosis's block (`diagnose
/// --write-model`) that are in that chain (component tables, location
/// errors; DH values, tool offset). Blocks of other kinds (stiffness,
/// thermal) and a diagnosis's other parameters (compliance, thermal
/// growth, payload) are not propagated: their effects' predictions are not
/// the tip deviation's geometric chain these sensitivities differentiate.
#[derive(Debug, Clone)]
pub struct BlockUncertainty {
    sens: Sensitivity,
    cov: ParamCovariance,
    /// (correction / u)² of each parameter (`None`: u = 0).
    z2: Vec<Option<f64>>,
    /// `kind (observations)` of each block propagated.
    pub sources: Vec<String>,
}

impl BlockUncertainty {
    /// The uncertainty of `machine`'s predictions from `blocks` (its file's
    /// `covariance` list; `file` names it in errors); `None` when no block
    /// is of the model's geometric or kinematic kind and no diagnosis's
    /// block holds a parameter of that chain. A parameter that is not a
    /// value of the file is refused by its key path.
    pub fn of_machine(
        machine: &crate::machine::Machine,
        blocks: &[CovarianceBlock],
        file: &str,
    ) -> Result<Option<Self>> {
        use crate::machine::Machine;
        let want = match machine {
            Machine::Tool(_) => "geometry",
            Machine::Robot(_) => "kinematics",
        };
        let chain = chain_paths(machine);
        // Each block with the parameters propagated: all of a block of the
        // model's kind, those of the geometric chain of a diagnosis.
        let mut used: Vec<(&CovarianceBlock, Vec<usize>)> = Vec::new();
        for b in blocks {
            let keep: Vec<usize> = match b.kind.as_str() {
                k if k == want => (0..b.parameters.len()).collect(),
                "diagnose" => (0..b.parameters.len())
                    .filter(|&i| b.parameters.get(i).is_some_and(|p| chain.contains(p)))
                    .collect(),
                _ => Vec::new(),
            };
            if !keep.is_empty() {
                used.push((b, keep));
            }
        }
        if used.is_empty() {
            return Ok(None);
        }
        let n: usize = used.iter().map(|(_, k)| k.len()).sum();
        let mut big = DMatrix::zeros(n, n);
        let mut steps = Vec::with_capacity(n);
        let mut paths = Vec::with_capacity(n);
        let mut u = Vec::with_capacity(n);
        let mut at = 0;
        for (b, keep) in &used {
            let c = b.covariance()?;
            let m = keep.len();
            let sub = c
                .matrix()
                .select_rows(keep.iter())
                .select_columns(keep.iter());
            big.view_mut((at, at), (m, m)).copy_from(&sub);
            for &i in keep {
                let ui = b.u.get(i).copied().unwrap_or(0.0);
                u.push(ui);
                steps.push(if ui > 0.0 { ui } else { 1.0 });
                paths.push(b.parameters.get(i).cloned().unwrap_or_default());
            }
            at += m;
        }
        let unknown = |p: &str| {
            let at = blocks.iter().enumerate().find_map(|(i, b)| {
                b.parameters
                    .iter()
                    .position(|q| q == p)
                    .map(|k| format!("covariance[{i}].parameters[{k}]"))
            });
            Error::Data(format!(
                "{file}: {}: `{p}` is not a value of this machine file (the block was written for \
                 another version of the model: delete it or recalibrate)",
                at.unwrap_or_else(|| "covariance".into())
            ))
        };
        let (sens, corrections): (Sensitivity, Vec<f64>) = match machine {
            Machine::Tool(t) => {
                let params = by_path(&tool_params(t), ToolParam::path, &paths, &steps)
                    .map_err(|p| unknown(&p))?;
                // A machine tool's error parameters are their corrections.
                let c = params
                    .iter()
                    .map(|(p, _)| t.param_value(*p).unwrap_or(0.0))
                    .collect();
                (Sensitivity::Tool(ToolSensitivity::new(t, &params)?), c)
            }
            Machine::Robot(r) => {
                let params = by_path(&robot_params(r), RobotParam::path, &paths, &steps)
                    .map_err(|p| unknown(&p))?;
                let c = params
                    .iter()
                    .map(|(p, _)| robot_correction(r, *p))
                    .collect();
                (Sensitivity::Robot(RobotSensitivity::new(r, &params)?), c)
            }
        };
        let z2 = corrections
            .iter()
            .zip(&u)
            .map(|(c, u)| (*u > 0.0).then(|| (c / u).powi(2)))
            .collect();
        let effect = if want == "geometry" {
            "geometric"
        } else {
            "kinematic"
        };
        Ok(Some(BlockUncertainty {
            sens,
            cov: ParamCovariance::new(vec![effect; n], big)?,
            z2,
            sources: used
                .iter()
                .map(|(b, _)| format!("{} ({})", b.kind, b.observations))
                .collect(),
        }))
    }

    /// The gain of each effect's correction by how well the calibration
    /// knows it: the positive-part James–Stein factor
    /// g = max(0, 1 − n / Σ (c_i/u_i)²) of its n parameters with
    /// corrections c_i (the identified value's departure from the nominal
    /// model) and standard uncertainties u_i — about 1 for corrections
    /// many times their uncertainty, 0 for corrections at the noise
    /// level (parameters with u = 0 are exactly known and not counted; an
    /// effect with none left keeps gain 1).
    pub fn auto_gains(&self) -> Vec<(&'static str, f64)> {
        self.effects()
            .into_iter()
            .map(|e| {
                let z: Vec<f64> = self
                    .cov
                    .effects
                    .iter()
                    .zip(&self.z2)
                    .filter(|(f, _)| **f == e)
                    .filter_map(|(_, z)| *z)
                    .collect();
                let sum: f64 = z.iter().sum();
                let g = if z.is_empty() {
                    1.0
                } else if sum > 0.0 {
                    (1.0 - z.len() as f64 / sum).max(0.0)
                } else {
                    0.0
                };
                (e, g)
            })
            .collect()
    }

    /// The model is a machine tool's.
    pub fn is_tool(&self) -> bool {
        matches!(self.sens, Sensitivity::Tool(_))
    }

    /// The effects the uncertainty is stated for.
    pub fn effects(&self) -> Vec<&'static str> {
        self.cov.effect_names()
    }

    /// U of a machine tool's predicted deviation `dev` at a command
    /// (`None` for a robot model).
    pub fn tool(
        &self,
        cmd: &AxisVec,
        dirs: &DirVec,
        tool_mm: f64,
        dev: &Vector3<f64>,
    ) -> Option<BlockU> {
        let Sensitivity::Tool(s) = &self.sens else {
            return None;
        };
        self.of_jacobian(&s.jacobian(cmd, dirs, tool_mm), dev)
    }

    /// U of a robot's predicted deviation `dev` at joint angles `q` (rad;
    /// `None` for a machine-tool model).
    pub fn robot(&self, q: &[f64; 6], dev: &Vector3<f64>) -> Option<BlockU> {
        let Sensitivity::Robot(s) = &self.sens else {
            return None;
        };
        self.of_jacobian(&s.jacobian(q), dev)
    }

    /// U (k=2) of a machine tool's predicted deviation alone, mm: what an
    /// annotation states ([`BlockUncertainty::tool`] without the split by
    /// effect).
    pub fn tool_total_mm(
        &self,
        cmd: &AxisVec,
        dirs: &DirVec,
        tool_mm: f64,
        dev: &Vector3<f64>,
    ) -> Option<f64> {
        let Sensitivity::Tool(s) = &self.sens else {
            return None;
        };
        self.total_of_jacobian(&s.jacobian(cmd, dirs, tool_mm), dev)
    }

    /// U (k=2) of a robot's predicted deviation alone, mm
    /// ([`BlockUncertainty::robot`] without the split by effect).
    pub fn robot_total_mm(&self, q: &[f64; 6], dev: &Vector3<f64>) -> Option<f64> {
        let Sensitivity::Robot(s) = &self.sens else {
            return None;
        };
        self.total_of_jacobian(&s.jacobian(q), dev)
    }

    /// The covariance (mm²) of a machine tool's predicted deviations along
    /// the coordinate `axis` (0..3: x, y, z) at the commands `points`
    /// (each with its directions of motion; tool of `tool_mm`): G Σ Gᵀ,
    /// G the rows `axis` of the points' sensitivities, so the points'
    /// correlations through shared parameters are kept (`None` for a robot
    /// model or an axis past z).
    pub fn tool_covariance_along(
        &self,
        points: &[(AxisVec, DirVec)],
        tool_mm: f64,
        axis: usize,
    ) -> Option<DMatrix<f64>> {
        let Sensitivity::Tool(s) = &self.sens else {
            return None;
        };
        if axis >= 3 {
            return None;
        }
        let n = self.cov.len();
        let mut g = DMatrix::zeros(points.len(), n);
        for (k, (cmd, dirs)) in points.iter().enumerate() {
            let j = s.jacobian(cmd, dirs, tool_mm);
            for c in 0..n {
                g[(k, c)] = j[(axis, c)];
            }
        }
        Some(&g * self.cov.matrix() * g.transpose())
    }

    fn total_of_jacobian(&self, j: &Matrix3xX<f64>, dev: &Vector3<f64>) -> Option<f64> {
        let total = propagate(j, &self.cov).ok()?;
        Some(total.expanded_length_mm(dev, COVERAGE_K))
    }

    fn of_jacobian(&self, j: &Matrix3xX<f64>, dev: &Vector3<f64>) -> Option<BlockU> {
        let total = propagate(j, &self.cov).ok()?;
        let effects = per_effect(j, &self.cov).ok()?;
        Some(BlockU {
            total_mm: total.expanded_length_mm(dev, COVERAGE_K),
            effects_mm: effects
                .iter()
                .map(|(_, u)| u.expanded_length_mm(dev, COVERAGE_K))
                .collect(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    #[test]
    fn a_hand_derived_propagation() {
        // Two parameters, u = 2 and 3 (units), correlation 0.5:
        // Σ = [[4, 3], [3, 9]]. J: x = p0 + p1, y = p0 − p1, z = 0.
        // Var x = 4 + 9 + 2·3 = 19, var y = 4 + 9 − 6 = 7, cov xy = 4 − 9 = −5.
        let cov = ParamCovariance::new(
            vec!["geometric", "thermal"],
            DMatrix::from_row_slice(2, 2, &[4.0, 3.0, 3.0, 9.0]),
        )
        .unwrap();
        let j = Matrix3xX::from_column_slice(&[1.0, 1.0, 0.0, 1.0, -1.0, 0.0]);
        let u = propagate(&j, &cov).unwrap();
        assert_abs_diff_eq!(u.cov_mm2[(0, 0)], 19.0, epsilon = 1e-12);
        assert_abs_diff_eq!(u.cov_mm2[(1, 1)], 7.0, epsilon = 1e-12);
        assert_abs_diff_eq!(u.cov_mm2[(0, 1)], -5.0, epsilon = 1e-12);
        let x = u.expanded_xyz_mm(COVERAGE_K);
        assert_abs_diff_eq!(x[0], 2.0 * 19f64.sqrt(), epsilon = 1e-12);
        assert_eq!(x[2], 0.0);
        // Along (1, 1)/√2: (19 + 7 − 10)/2 = 8 → U = 2·√8.
        let along = u.expanded_along_mm(&Vector3::new(1.0, 1.0, 0.0), COVERAGE_K);
        assert_abs_diff_eq!(along, 2.0 * 8f64.sqrt(), epsilon = 1e-12);
        // Per effect: p0 alone gives var x = var y = 4, p1 alone 9.
        let parts = per_effect(&j, &cov).unwrap();
        assert_eq!(parts[0].0, "geometric");
        assert_abs_diff_eq!(parts[0].1.cov_mm2[(1, 1)], 4.0, epsilon = 1e-12);
        assert_abs_diff_eq!(parts[1].1.cov_mm2[(0, 0)], 9.0, epsilon = 1e-12);
    }

    #[test]
    fn a_covariance_block_round_trips_through_its_yaml() {
        // u = (2, 3), ρ = 0.5: covariance [[4, 3], [3, 9]].
        let cov = DMatrix::from_row_slice(2, 2, &[4.0, 3.0, 3.0, 9.0]);
        let params = vec![
            "axes[Y].location_errors.EC0Y_urad".to_string(),
            "axes[X].component_errors.EXX_um.forward[3]".to_string(),
        ];
        let b = CovarianceBlock::from_fit("geometry", "grid.csv", "9f00", 242, params, &cov);
        let yaml = format!("kind: machine_tool\ncovariance:\n{}", b.to_yaml_entry());
        assert!(yaml.contains("      - [1.0000, 0.5000]\n"), "{yaml}");
        let back = read_covariance(&yaml, "m.yaml").unwrap();
        assert_eq!(back, vec![b]);
        let c = back[0].covariance().unwrap();
        assert_abs_diff_eq!(c.matrix()[(0, 1)], 3.0, epsilon = 1e-12);
        assert_abs_diff_eq!(c.matrix()[(1, 1)], 9.0, epsilon = 1e-12);
        assert_eq!(c.effect_names(), vec!["geometric"]);
        // A file without the list carries none.
        assert!(
            read_covariance("kind: robot\n", "r.yaml")
                .unwrap()
                .is_empty()
        );
        let bad = yaml.replace("[1.0000, 0.5000]", "[1.0000, 0.7000]");
        let e = read_covariance(&bad, "m.yaml").unwrap_err().to_string();
        assert!(e.contains("covariance[0]: correlation (0, 1)"), "{e}");
    }

    #[test]
    fn a_bad_covariance_is_refused() {
        let e = vec!["geometric", "geometric"];
        assert!(
            ParamCovariance::new(
                e.clone(),
                DMatrix::from_row_slice(2, 2, &[1.0, 0.5, 0.4, 1.0])
            )
            .is_err()
        );
        assert!(
            ParamCovariance::new(
                e.clone(),
                DMatrix::from_row_slice(2, 2, &[-1.0, 0.0, 0.0, 1.0])
            )
            .is_err()
        );
        assert!(ParamCovariance::new(e, DMatrix::identity(3, 3)).is_err());
    }

    #[test]
    fn tool_sensitivity_of_a_table_node_is_its_interpolation_weight() {
        // EXX(x) linear between nodes 0 and 1000 mm: at x = 250 the forward
        // value of node 1 weighs 0.25 and node 0 weighs 0.75, 1 µm each =
        // 0.001 mm.
        let text = "kind: machine_tool
name: t
axes:
  - { name: X, type: linear, side: workpiece, travel_mm: [0, 1000], rapid_mm_per_min: 1000,
      component_errors: { EXX_um: { positions_mm: [0, 1000], forward: [0, 20], reverse: [1, 21] } } }
  - { name: Y, type: linear, side: workpiece, travel_mm: [0, 500], rapid_mm_per_min: 1000 }
  - { name: Z, type: linear, side: tool, travel_mm: [0, 500], rapid_mm_per_min: 1000 }
";
        let m = MachineTool::from_yaml_str(text, "t.yaml").unwrap();
        let node = |node, forward| ToolParam::Component {
            axis: 0,
            error: 0,
            node,
            forward,
        };
        let s = ToolSensitivity::new(
            &m,
            &[
                (node(0, true), 1.0),
                (node(1, true), 1.0),
                (node(1, false), 1.0),
            ],
        )
        .unwrap();
        let j = s.jacobian(&[250.0, 100.0, 100.0, 0.0, 0.0, 0.0], &[1; 6], 0.0);
        assert_abs_diff_eq!(j[(0, 0)], 0.00075, epsilon = 1e-12);
        assert_abs_diff_eq!(j[(0, 1)], 0.00025, epsilon = 1e-12);
        // Moving in + does not read the reverse column.
        assert_abs_diff_eq!(j[(0, 2)], 0.0, epsilon = 1e-12);
        let j = s.jacobian(
            &[250.0, 100.0, 100.0, 0.0, 0.0, 0.0],
            &[-1, 1, 1, 1, 1, 1],
            0.0,
        );
        assert_abs_diff_eq!(j[(0, 2)], 0.00025, epsilon = 1e-12);
    }

    fn block(kind: &str, u: f64) -> CovarianceBlock {
        CovarianceBlock {
            kind: kind.into(),
            observations: "a.csv".into(),
            observations_sha256: "ab".into(),
            rows: 3,
            parameters: vec!["k_nm_per_rad[0]".into()],
            u: vec![u],
            correlation: vec![vec![1.0]],
        }
    }

    #[test]
    fn a_covariance_list_is_added_at_the_end_and_a_kind_replaced() {
        let text = "kind: robot\nname: r";
        let one = put_covariance(text, "m.yaml", &block("kinematics", 0.5)).unwrap();
        assert!(one.starts_with("kind: robot\nname: r\n# parameter uncertainty"));
        assert!(one.ends_with("covariance:\n  - kind: kinematics\n    observations: \"a.csv\"\n    observations_sha256: ab\n    rows: 3\n    parameters: [\"k_nm_per_rad[0]\"]\n    u: [0.5]\n    correlation:\n      - [1.0000]\n"), "{one}");
        // Another kind is added to the list; the same kind replaces its block,
        // and the key after the list is kept.
        let with_next = format!("{one}\n# next\nacceptance: {{}}\n");
        let two = put_covariance(&with_next, "m.yaml", &block("stiffness", 0.25)).unwrap();
        let three = put_covariance(&two, "m.yaml", &block("kinematics", 2.0)).unwrap();
        let b = read_covariance(&three, "m.yaml").unwrap();
        let kinds: Vec<(&str, f64)> = b.iter().map(|b| (b.kind.as_str(), b.u[0])).collect();
        assert_eq!(kinds, [("stiffness", 0.25), ("kinematics", 2.0)]);
        assert!(three.ends_with("\n# next\nacceptance: {}\n"), "{three}");
        assert_eq!(three.matches("covariance:").count(), 1);
    }

    /// A 3-axis file whose X table has the node positions `positions`
    /// (zero values), with `covariance` after it.
    fn mill(positions: &[f64], covariance: &str) -> String {
        let list = |v: &[String]| v.join(", ");
        let pos: Vec<String> = positions.iter().map(|p| format!("{p:?}")).collect();
        let zero: Vec<String> = positions.iter().map(|_| "0.0".to_string()).collect();
        let axis = |n: &str| {
            format!(
                "  - name: {n}\n    type: linear\n    side: workpiece\n    travel_mm: [0.0, 1000.0]\n    rapid_mm_per_min: 30000.0\n"
            )
        };
        format!(
            "kind: machine_tool\nname: mill\naxes:\n{}    location_errors: {{ EC0X_urad: 0.0 }}\n    component_errors:\n      EXX_um: {{ positions_mm: [{}], forward: [{}] }}\n{}{}{covariance}",
            axis("X"),
            list(&pos),
            list(&zero),
            axis("Y"),
            axis("Z"),
        )
    }

    #[test]
    fn a_block_on_a_regridded_table_is_stale_and_dropped() {
        let node = "axes[X].component_errors.EXX_um.forward[1]";
        let loc = "axes[X].location_errors.EC0X_urad";
        let block = |p: &str| {
            CovarianceBlock::from_fit(
                "geometry",
                "grid.csv",
                "9f00",
                10,
                vec![p.to_string()],
                &DMatrix::from_element(1, 1, 4.0),
            )
        };
        let load = |t: &str| crate::machine::Machine::from_yaml_str(t, "m.yaml").unwrap();
        let before = load(&mill(&[0.0, 500.0, 1000.0], ""));
        let same = load(&mill(&[0.0, 500.0, 1000.0], ""));
        let regridded = load(&mill(&[0.0, 250.0, 500.0, 750.0, 1000.0], ""));
        let shorter = load(&mill(&[0.0, 1000.0], ""));
        assert_eq!(stale_reason(&before, &same, &block(node)), None);
        assert_eq!(stale_reason(&before, &regridded, &block(loc)), None);
        let why = stale_reason(&before, &regridded, &block(node)).expect("stale");
        assert!(
            why.contains("`axes[X].component_errors.EXX_um` was re-gridded (3 nodes"),
            "{why}"
        );
        let gone = stale_reason(&before, &shorter, &block(node)).expect("stale");
        assert!(gone.contains("re-gridded"), "{gone}");
        // The file: the node's block dropped with a warning naming it, the
        // location error's kept; a block of the fresh kind is not judged.
        let list = format!(
            "covariance:\n{}{}",
            block(node).to_yaml_entry(),
            CovarianceBlock {
                kind: "diagnose".into(),
                ..block(loc)
            }
            .to_yaml_entry()
        );
        let text = mill(&[0.0, 250.0, 500.0, 750.0, 1000.0], &list);
        let (kept, warnings) = drop_stale_covariance(&before, &text, "m.yaml", None).unwrap();
        assert_eq!(warnings.len(), 1, "{warnings:?}");
        assert!(
            warnings[0].starts_with("m.yaml: covariance[0] (kind geometry, from grid.csv) dropped"),
            "{warnings:?}"
        );
        let left = read_covariance(&kept, "m.yaml").unwrap();
        assert_eq!(left.len(), 1);
        assert_eq!(left[0].parameters, [loc]);
        assert!(matches!(load(&kept), crate::machine::Machine::Tool(_)));
        let (same_text, none) =
            drop_stale_covariance(&before, &text, "m.yaml", Some("geometry")).unwrap();
        assert!(none.is_empty(), "{none:?}");
        assert_eq!(same_text, text);
        // Every block dropped: an empty list, which reads as none.
        let only = mill(
            &[0.0, 250.0, 500.0, 750.0, 1000.0],
            &format!("covariance:\n{}", block(node).to_yaml_entry()),
        );
        let (empty, _) = drop_stale_covariance(&before, &only, "m.yaml", None).unwrap();
        assert!(empty.ends_with("covariance: []\n"), "{empty}");
        assert!(read_covariance(&empty, "m.yaml").unwrap().is_empty());
    }
}
