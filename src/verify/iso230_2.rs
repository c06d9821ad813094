//! ISO 230-2: accuracy and repeatability of positioning of a linear axis
//! from bidirectional runs to a set of targets (docs/verify.md).
//!
//! With x_ij the positional deviation (attained − target) of run j at
//! target i, per direction (↑ positive, ↓ negative approach):
//! mean unidirectional positional deviation x̄_i↑ = mean_j x_ij↑;
//! estimator of the unidirectional repeatability
//! s_i↑ = sqrt(Σ_j (x_ij↑ − x̄_i↑)² / (n − 1)); R_i↑ = 4 s_i↑;
//! reversal value B_i = x̄_i↑ − x̄_i↓; mean bidirectional positional
//! deviation x̄_i = (x̄_i↑ + x̄_i↓) / 2; bidirectional repeatability
//! R_i = max(2 s_i↑ + 2 s_i↓ + |B_i|, R_i↑, R_i↓). Of the axis:
//! B = max |B_i|, B̄ = mean B_i; R↑ = max R_i↑, R↓, R = max R_i;
//! E↑ = max x̄_i↑ − min x̄_i↑, E↓, E = max(x̄_i↑, x̄_i↓) − min(x̄_i↑, x̄_i↓);
//! M = max x̄_i − min x̄_i;
//! A↑ = max(x̄_i↑ + 2 s_i↑) − min(x̄_i↑ − 2 s_i↑), A↓, and
//! A = max(x̄_i↑ + 2 s_i↑, x̄_i↓ + 2 s_i↓) − min(x̄_i↑ − 2 s_i↑, x̄_i↓ − 2 s_i↓).

use serde_json::json;

use super::table::{Column, Kind, Table};
use super::{Evaluation, Figure, Group, Standard, fmt_mm, json_mm};
use crate::error::{Error, Located, Result};

/// Fewest runs per direction at a target the standard accepts.
pub const MIN_RUNS: usize = 5;

/// Fewest targets per axis the standard accepts.
pub const MIN_TARGETS: usize = 5;

/// Targets closer than this are the same target, mm.
pub const SAME_TARGET_MM: f64 = 1e-6;

/// The figures of an axis, in report order.
pub const FIGURES: [&str; 12] = [
    "E_up", "E_down", "E", "M", "A_up", "A_down", "A", "R_up", "R_down", "R", "B", "B_mean",
];

/// The columns of a linear-axis measurement file.
pub const COLUMNS: &[Column] = &[
    Column::optional("id", Kind::Text),
    Column::optional("axis", Kind::Text),
    Column::required("target_mm", Kind::Number),
    Column::required("run", Kind::Count),
    Column::required("dir", Kind::Sign),
    Column::optional("actual_mm", Kind::Number),
    Column::optional("deviation_mm", Kind::Number),
    Column::optional("t_s", Kind::Number),
    Column::optional("ambient_c", Kind::Number),
];

/// The deviations measured at one target, mm.
#[derive(Debug, Clone, PartialEq)]
pub struct TargetRuns {
    /// The target position, mm.
    pub target_mm: f64,
    /// Positional deviations of the runs approaching in the positive direction.
    pub up: Vec<f64>,
    /// Positional deviations of the runs approaching in the negative direction.
    pub down: Vec<f64>,
}

/// An axis' runs, targets ascending.
#[derive(Debug, Clone, PartialEq)]
pub struct AxisRuns {
    /// Axis name (`X`).
    pub axis: String,
    /// The targets with their runs.
    pub targets: Vec<TargetRuns>,
}

/// The statistics at one target, mm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TargetStats {
    /// Target, mm.
    pub target_mm: f64,
    /// Runs per direction (↑, ↓).
    pub runs: (usize, usize),
    /// x̄_i↑.
    pub mean_up: f64,
    /// x̄_i↓.
    pub mean_down: f64,
    /// s_i↑ (0 with a single run: a prediction).
    pub s_up: f64,
    /// s_i↓.
    pub s_down: f64,
    /// B_i.
    pub reversal: f64,
    /// R_i.
    pub repeatability: f64,
}

/// One axis evaluated.
#[derive(Debug, Clone, PartialEq)]
pub struct AxisResult {
    /// Axis name.
    pub axis: String,
    /// Per target.
    pub targets: Vec<TargetStats>,
    /// The axis figures in the order of [`FIGURES`], mm.
    pub figures: [f64; 12],
    /// Their expanded uncertainties U (k=2) from a model's parameter
    /// covariance, mm (`None`: not stated).
    pub u_mm: Option<[f64; 12]>,
}

/// Mean and estimator of the standard deviation (n − 1; 0 for one value).
pub fn mean_s(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    if v.len() < 2 {
        return (mean, 0.0);
    }
    let ss: f64 = v.iter().map(|x| (x - mean).powi(2)).sum();
    (mean, (ss / (n - 1.0)).sqrt())
}

fn max_of(it: impl Iterator<Item = f64>) -> f64 {
    it.fold(f64::NEG_INFINITY, f64::max)
}

fn min_of(it: impl Iterator<Item = f64>) -> f64 {
    it.fold(f64::INFINITY, f64::min)
}

/// Evaluates one axis (every target with at least one run per direction).
pub fn evaluate_axis(runs: &AxisRuns) -> AxisResult {
    let targets: Vec<TargetStats> = runs
        .targets
        .iter()
        .map(|t| {
            let (mean_up, s_up) = mean_s(&t.up);
            let (mean_down, s_down) = mean_s(&t.down);
            let reversal = mean_up - mean_down;
            let repeatability = (2.0 * s_up + 2.0 * s_down + reversal.abs())
                .max(4.0 * s_up)
                .max(4.0 * s_down);
            TargetStats {
                target_mm: t.target_mm,
                runs: (t.up.len(), t.down.len()),
                mean_up,
                mean_down,
                s_up,
                s_down,
                reversal,
                repeatability,
            }
        })
        .collect();
    let t = &targets;
    let span = |f: &dyn Fn(&TargetStats) -> f64| max_of(t.iter().map(f)) - min_of(t.iter().map(f));
    let e = max_of(t.iter().map(|s| s.mean_up.max(s.mean_down)))
        - min_of(t.iter().map(|s| s.mean_up.min(s.mean_down)));
    let a_up = max_of(t.iter().map(|s| s.mean_up + 2.0 * s.s_up))
        - min_of(t.iter().map(|s| s.mean_up - 2.0 * s.s_up));
    let a_down = max_of(t.iter().map(|s| s.mean_down + 2.0 * s.s_down))
        - min_of(t.iter().map(|s| s.mean_down - 2.0 * s.s_down));
    let a = max_of(
        t.iter()
            .map(|s| (s.mean_up + 2.0 * s.s_up).max(s.mean_down + 2.0 * s.s_down)),
    ) - min_of(
        t.iter()
            .map(|s| (s.mean_up - 2.0 * s.s_up).min(s.mean_down - 2.0 * s.s_down)),
    );
    let figures = [
        span(&|s| s.mean_up),
        span(&|s| s.mean_down),
        e,
        span(&|s| (s.mean_up + s.mean_down) / 2.0),
        a_up,
        a_down,
        a,
        max_of(t.iter().map(|s| 4.0 * s.s_up)),
        max_of(t.iter().map(|s| 4.0 * s.s_down)),
        max_of(t.iter().map(|s| s.repeatability)),
        max_of(t.iter().map(|s| s.reversal.abs())),
        t.iter().map(|s| s.reversal).sum::<f64>() / t.len() as f64,
    ];
    AxisResult {
        axis: runs.axis.clone(),
        targets,
        figures,
        u_mm: None,
    }
}

/// The runs of every axis of a measurement file (axes in order of first
/// appearance; `default_axis` names the axis of a file without an `axis`
/// column).
pub fn read_runs(text: &str, file: &str, default_axis: &str) -> Result<Vec<AxisRuns>> {
    let table = Table::parse(text, file, COLUMNS)?;
    let value_col = match (table.has("actual_mm"), table.has("deviation_mm")) {
        (true, false) => "actual_mm",
        (false, true) => "deviation_mm",
        (true, true) => {
            return Err(
                table.header_error("both `actual_mm` and `deviation_mm`: give one of the two")
            );
        }
        (false, false) => {
            return Err(table.header_error(
                "missing column `actual_mm` (attained position) or `deviation_mm` (attained − target)",
            ));
        }
    };
    // Per axis: its first line and its targets.
    let mut axes: Vec<(String, usize, Vec<Gathered>)> = Vec::new();
    for row in &table.rows {
        let need = |name: &str| {
            row.number(&table, name)
                .ok_or_else(|| row.error(&table, name, format!("empty `{name}`")))
        };
        let target = need("target_mm")?;
        let run = need("run")? as u32;
        let dir = need("dir")?;
        let value = need(value_col)?;
        let dev = if value_col == "actual_mm" {
            value - target
        } else {
            value
        };
        let axis = row.text(&table, "axis").unwrap_or(default_axis).to_string();
        let a = match axes.iter().position(|(n, _, _)| *n == axis) {
            Some(a) => a,
            None => {
                axes.push((axis.clone(), row.line, Vec::new()));
                axes.len() - 1
            }
        };
        let targets = &mut axes[a].2;
        let t = match targets
            .iter()
            .position(|g| (g.target - target).abs() <= SAME_TARGET_MM)
        {
            Some(t) => t,
            None => {
                targets.push(Gathered {
                    target,
                    line: row.line,
                    up: Vec::new(),
                    down: Vec::new(),
                });
                targets.len() - 1
            }
        };
        let side = if dir > 0.0 {
            &mut targets[t].up
        } else {
            &mut targets[t].down
        };
        if side.iter().any(|(r, _)| *r == run) {
            return Err(row.error(
                &table,
                "run",
                format!(
                    "run {run} to target {target} mm in the {} direction of axis {axis} given twice",
                    if dir > 0.0 { "+" } else { "-" }
                ),
            ));
        }
        side.push((run, dev));
    }
    axes.into_iter()
        .map(|(axis, line, mut targets)| {
            check_counts(file, &axis, line, &targets)?;
            targets.sort_by(|a, b| a.target.total_cmp(&b.target));
            let targets = targets
                .into_iter()
                .map(|g| TargetRuns {
                    target_mm: g.target,
                    up: g.up.into_iter().map(|(_, d)| d).collect(),
                    down: g.down.into_iter().map(|(_, d)| d).collect(),
                })
                .collect();
            Ok(AxisRuns { axis, targets })
        })
        .collect()
}

/// The runs of one target as read: (run, deviation) per direction.
struct Gathered {
    target: f64,
    /// Line of its first row.
    line: usize,
    up: Vec<(u32, f64)>,
    down: Vec<(u32, f64)>,
}

/// At least [`MIN_TARGETS`] targets and [`MIN_RUNS`] runs per direction.
fn check_counts(file: &str, axis: &str, line: usize, targets: &[Gathered]) -> Result<()> {
    if targets.len() < MIN_TARGETS {
        return Err(Error::Input(Located::new(
            file,
            line,
            1,
            format!(
                "axis {axis}: {} targets; ISO 230-2 asks for at least {MIN_TARGETS}",
                targets.len()
            ),
        )));
    }
    for g in targets {
        let target = g.target;
        for (n, sign) in [(g.up.len(), "+"), (g.down.len(), "-")] {
            if n < MIN_RUNS {
                return Err(Error::Input(Located::new(
                    file,
                    g.line,
                    1,
                    format!(
                        "axis {axis}, target {target} mm: {n} runs in the {sign} direction; ISO 230-2 asks for at least {MIN_RUNS}"
                    ),
                )));
            }
        }
    }
    Ok(())
}

/// ISO 230-2 results of every axis of a file (or of a prediction).
#[derive(Debug, Clone, PartialEq)]
pub struct Iso230_2 {
    /// Per axis.
    pub axes: Vec<AxisResult>,
}

impl Evaluation for Iso230_2 {
    fn standard(&self) -> Standard {
        Standard::Iso230_2
    }

    fn groups(&self) -> Vec<Group> {
        self.axes
            .iter()
            .map(|a| Group {
                name: a.axis.clone(),
                figures: FIGURES
                    .iter()
                    .zip(a.figures)
                    .zip(a.u_mm.map_or([None; 12], |u| u.map(Some)))
                    .map(|((&name, value_mm), u_mm)| Figure {
                        name,
                        value_mm,
                        u_mm,
                    })
                    .collect(),
            })
            .collect()
    }

    fn detail_json(&self) -> serde_json::Value {
        let axes: Vec<serde_json::Value> = self
            .axes
            .iter()
            .map(|a| {
                let targets: Vec<serde_json::Value> = a
                    .targets
                    .iter()
                    .map(|t| {
                        json!({
                            "target_mm": json_mm(t.target_mm),
                            "runs_up": t.runs.0,
                            "runs_down": t.runs.1,
                            "mean_up_mm": json_mm(t.mean_up),
                            "mean_down_mm": json_mm(t.mean_down),
                            "mean_mm": json_mm((t.mean_up + t.mean_down) / 2.0),
                            "s_up_mm": json_mm(t.s_up),
                            "s_down_mm": json_mm(t.s_down),
                            "reversal_mm": json_mm(t.reversal),
                            "repeatability_mm": json_mm(t.repeatability),
                        })
                    })
                    .collect();
                json!({ "axis": a.axis, "targets": targets })
            })
            .collect();
        json!({ "axes": axes })
    }

    fn detail_table(&self, out: &mut String) {
        for a in &self.axes {
            out.push_str(&format!(
                "axis {}: {} targets\n{:>12} {:>5} {:>10} {:>10} {:>9} {:>9} {:>10} {:>9}\n",
                a.axis,
                a.targets.len(),
                "target_mm",
                "runs",
                "mean_up",
                "mean_down",
                "s_up",
                "s_down",
                "B_i",
                "R_i"
            ));
            for t in &a.targets {
                out.push_str(&format!(
                    "{:>12} {:>5} {:>10} {:>10} {:>9} {:>9} {:>10} {:>9}\n",
                    fmt_mm(t.target_mm),
                    format!("{}/{}", t.runs.0, t.runs.1),
                    fmt_mm(t.mean_up),
                    fmt_mm(t.mean_down),
                    fmt_mm(t.s_up),
                    fmt_mm(t.s_down),
                    fmt_mm(t.reversal),
                    fmt_mm(t.repeatability)
                ));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    /// Figures equal to a nanometre.
    const NM: f64 = 1e-6;

    /// Five runs of deviation `m + a·(−1, −1, 0, 1, 1)` µm: mean m, s = a.
    fn runs(m: f64, a: f64) -> Vec<f64> {
        [-1.0, -1.0, 0.0, 1.0, 1.0]
            .iter()
            .map(|p| (m + a * p) * 1e-3)
            .collect()
    }

    #[test]
    fn figures_of_a_hand_derived_axis() {
        // (target, m_up, a_up, m_down, a_down) in mm and µm; the figures
        // below are derived by hand in docs/verify.md.
        let spec = [
            (0.0, 0.0, 1.0, -2.0, 1.0),
            (100.0, 3.0, 1.0, 1.0, 2.0),
            (200.0, 5.0, 2.0, 2.0, 1.0),
            (300.0, 4.0, 1.0, 0.0, 1.0),
            (400.0, 6.0, 1.0, 3.0, 2.0),
        ];
        let axis = AxisRuns {
            axis: "X".into(),
            targets: spec
                .iter()
                .map(|&(t, mu, au, md, ad)| TargetRuns {
                    target_mm: t,
                    up: runs(mu, au),
                    down: runs(md, ad),
                })
                .collect(),
        };
        let r = evaluate_axis(&axis);
        let want = [
            0.006, 0.005, 0.008, 0.0055, 0.011, 0.011, 0.013, 0.008, 0.008, 0.009, 0.004, 0.0028,
        ];
        for ((name, got), want) in FIGURES.iter().zip(r.figures).zip(want) {
            assert!((got - want).abs() <= NM, "{name}: {got} vs {want}");
        }
        assert_abs_diff_eq!(r.targets[2].s_up, 0.002, epsilon = NM);
        assert_abs_diff_eq!(r.targets[2].repeatability, 0.009, epsilon = NM);
    }

    #[test]
    fn one_run_per_direction_has_no_scatter() {
        let axis = AxisRuns {
            axis: "X".into(),
            targets: vec![
                TargetRuns {
                    target_mm: 0.0,
                    up: vec![0.001],
                    down: vec![0.003],
                },
                TargetRuns {
                    target_mm: 10.0,
                    up: vec![0.002],
                    down: vec![0.002],
                },
            ],
        };
        let r = evaluate_axis(&axis);
        // E = 0.003 − 0.001; A = E without scatter; R = max |B_i|.
        assert_abs_diff_eq!(r.figures[2], 0.002, epsilon = NM);
        assert_abs_diff_eq!(r.figures[6], 0.002, epsilon = NM);
        assert_abs_diff_eq!(r.figures[9], 0.002, epsilon = NM);
    }

    #[test]
    fn a_file_with_too_few_runs_or_targets_is_refused_at_its_row() {
        let mut text = String::from("target_mm,run,dir,deviation_mm\n");
        for t in 0..5 {
            for run in 1..=5 {
                for dir in ["+1", "-1"] {
                    if !(t == 3 && run == 5 && dir == "-1") {
                        text.push_str(&format!("{},{run},{dir},0.001\n", t * 10));
                    }
                }
            }
        }
        let e = read_runs(&text, "x.csv", "X").unwrap_err().to_string();
        assert!(
            e.starts_with("x.csv:32:1: axis X, target 30 mm: 4 runs in the - direction"),
            "{e}"
        );
        let e = read_runs(
            "target_mm,run,dir,deviation_mm\n0,1,+1,0\n0,1,+1,0\n",
            "x.csv",
            "X",
        )
        .unwrap_err()
        .to_string();
        assert!(e.starts_with("x.csv:3:3: run 1 to target 0 mm"), "{e}");
        let e = read_runs("target_mm,run,dir\n0,1,+1\n", "x.csv", "X")
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing column `actual_mm`"), "{e}");
        let e = read_runs("target_mm,run,dir,deviation_mm\n0,1,+1,0\n", "x.csv", "X")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("x.csv:2:1: axis X: 1 targets"), "{e}");
    }
}
