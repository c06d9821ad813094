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
use crate::machine::robot::{Model, Robot, RobotParam};
use crate::machine::tool::{MachineTool, ToolParam};
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
        let quoted: Vec<String> = self
            .parameters
            .iter()
            .map(|p| serde_json::to_string(p).unwrap_or_default())
            .collect();
        let u: Vec<String> = self.u.iter().map(|v| format!("{v:?}")).collect();
        let mut out = format!(
            "  - kind: {}\n    observations: {}\n    observations_sha256: {}\n    rows: {}\n    parameters: [{}]\n    u: [{}]\n    correlation:\n",
            self.kind,
            serde_json::to_string(&self.observations).unwrap_or_default(),
            self.observations_sha256,
            self.rows,
            quoted.join(", "),
            u.join(", ")
        );
        for row in &self.correlation {
            let r: Vec<String> = row
                .iter()
                .map(|v| {
                    let s = format!("{v:.4}");
                    if s == "-0.0000" { "0.0000".into() } else { s }
                })
                .collect();
            out.push_str(&format!("      - [{}]\n", r.join(", ")));
        }
        out
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
}
