//! Acceptance tests to the standards (docs/verify.md): ISO 230-2
//! positioning of a linear axis ([`iso230_2`]), ISO 230-4 circular tests
//! ([`iso230_4`]), ISO 9283 robot pose and path accuracy and repeatability
//! ([`iso9283`]), from measured data or predicted by a machine model
//! ([`predicted`]); each figure held against limits from the command line
//! or the machine file's `acceptance` key ([`limits`]), written as a table
//! or JSON (`schemas/verify.schema.json`).

pub mod iso230_2;
pub mod iso230_4;
pub mod iso9283;
pub mod limits;
pub mod predicted;
pub mod table;

use serde_json::json;

pub use limits::{Check, Limit, LimitSource};

/// The standards `verify` evaluates.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Standard {
    /// ISO 230-2, positioning of linear axes.
    Iso230_2,
    /// ISO 230-4, circular tests.
    Iso230_4,
    /// ISO 9283, robot pose and path characteristics.
    Iso9283,
}

impl Standard {
    /// The name as reports write it (`ISO 230-2`).
    pub fn title(self) -> &'static str {
        match self {
            Standard::Iso230_2 => "ISO 230-2",
            Standard::Iso230_4 => "ISO 230-4",
            Standard::Iso9283 => "ISO 9283",
        }
    }

    /// The key of the standard under the machine file's `acceptance`.
    pub fn key(self) -> &'static str {
        match self {
            Standard::Iso230_2 => "iso230_2",
            Standard::Iso230_4 => "iso230_4",
            Standard::Iso9283 => "iso9283",
        }
    }

    /// The figures a limit can name.
    pub fn figures(self) -> &'static [&'static str] {
        match self {
            Standard::Iso230_2 => &iso230_2::FIGURES,
            Standard::Iso230_4 => &iso230_4::FIGURES,
            Standard::Iso9283 => &iso9283::FIGURES,
        }
    }
}

/// The unit of a figure: `deg` for ISO 9283's orientation figures, `mm`
/// for every other.
pub fn unit_of(figure: &str) -> &'static str {
    if iso9283::ORIENTATION_FIGURES.contains(&figure) {
        "deg"
    } else {
        "mm"
    }
}

/// One figure of a group, mm (degrees for an orientation figure:
/// [`unit_of`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Figure {
    /// Its name (`A`, `R_up`, `RP`).
    pub name: &'static str,
    /// Its value, mm.
    pub value_mm: f64,
    /// Its expanded uncertainty U (k=2) from the model's parameter
    /// covariance, mm (`None`: not stated — measured data, or a model
    /// without a covariance).
    pub u_mm: Option<f64>,
}

/// The figures of one thing evaluated: an axis, the circle, the robot's
/// poses or path.
#[derive(Debug, Clone, PartialEq)]
pub struct Group {
    /// Its name (`X`, `circle`, `poses`, `path`).
    pub name: String,
    /// The figures, in the standard's order.
    pub figures: Vec<Figure>,
}

/// The result of one standard: figures by group, and the standard's
/// intermediate values for the detail of a report.
pub trait Evaluation {
    /// The standard.
    fn standard(&self) -> Standard;
    /// The figures that limits are held against.
    fn groups(&self) -> Vec<Group>;
    /// The intermediate values as JSON (`detail` of the report).
    fn detail_json(&self) -> serde_json::Value;
    /// The intermediate values as table lines.
    fn detail_table(&self, out: &mut String);
}

/// Where the evaluated data come from.
#[derive(Debug, Clone, PartialEq)]
pub enum Source {
    /// Measured data in a file.
    Measured {
        /// The file as given.
        file: String,
    },
    /// Predicted by a machine model.
    Predicted {
        /// The machine file as shown.
        machine: String,
        /// What the prediction stands for, in a sentence.
        note: String,
    },
}

/// Millimetres as the table shows them: four decimals (0.1 µm).
pub fn fmt_mm(v: f64) -> String {
    let s = format!("{v:.4}");
    if s == "-0.0000" { "0.0000".into() } else { s }
}

/// Millimetres as the JSON report writes them: rounded to a nanometre
/// (the same bytes on every platform).
pub fn json_mm(v: f64) -> serde_json::Value {
    let r = (v * 1e6).round() / 1e6;
    json!(if r == 0.0 { 0.0 } else { r })
}

/// The verdict of a set of checks: `pass`, `fail` or `no limits`.
pub fn verdict(checks: &[Check]) -> &'static str {
    if checks.is_empty() {
        "no limits"
    } else if checks.iter().all(|c| c.pass) {
        "pass"
    } else {
        "fail"
    }
}

/// The JSON report (`schemas/verify.schema.json`).
pub fn report_json(eval: &dyn Evaluation, source: &Source, checks: &[Check]) -> serde_json::Value {
    let groups: Vec<serde_json::Value> = eval
        .groups()
        .iter()
        .map(|g| {
            let figures: serde_json::Map<String, serde_json::Value> = g
                .figures
                .iter()
                .map(|f| {
                    (
                        format!("{}_{}", f.name, unit_of(f.name)),
                        json_mm(f.value_mm),
                    )
                })
                .collect();
            let u: serde_json::Map<String, serde_json::Value> = g
                .figures
                .iter()
                .filter_map(|f| {
                    f.u_mm
                        .map(|u| (format!("{}_{}", f.name, unit_of(f.name)), json_mm(u)))
                })
                .collect();
            if u.is_empty() {
                json!({ "name": g.name, "figures": figures })
            } else {
                json!({
                    "name": g.name,
                    "figures": figures,
                    "uncertainty": {
                        "k": crate::predict::uncertainty::COVERAGE_K,
                        "figures": u,
                    },
                })
            }
        })
        .collect();
    let source = match source {
        Source::Measured { file } => json!({ "kind": "measured", "file": file }),
        Source::Predicted { machine, note } => {
            json!({ "kind": "predicted", "machine": machine, "note": note })
        }
    };
    let rows: Vec<serde_json::Value> = checks
        .iter()
        .map(|c| {
            let unit = unit_of(c.figure);
            json!({
                "group": c.group,
                "figure": c.figure,
                format!("value_{unit}"): json_mm(c.value_mm),
                format!("limit_{unit}"): json_mm(c.limit_mm),
                "source": c.source.name(),
                "pass": c.pass,
            })
        })
        .collect();
    json!({
        "standard": eval.standard().title(),
        "source": source,
        "groups": groups,
        "detail": eval.detail_json(),
        "checks": rows,
        "verdict": verdict(checks),
    })
}

/// The table report.
pub fn report_table(eval: &dyn Evaluation, source: &Source, checks: &[Check]) -> String {
    let mut out = String::new();
    out.push_str(eval.standard().title());
    match source {
        Source::Measured { file } => out.push_str(&format!(" — measured: {file}\n")),
        Source::Predicted { machine, note } => {
            out.push_str(&format!(" — predicted by {machine}: {note}\n"))
        }
    }
    out.push('\n');
    eval.detail_table(&mut out);
    out.push('\n');
    let groups = eval.groups();
    let with_u = groups
        .iter()
        .any(|g| g.figures.iter().any(|f| f.u_mm.is_some()));
    let width = if with_u { 21 } else { 12 };
    out.push_str(&format!("{:<8}", "figure"));
    for g in &groups {
        out.push_str(&format!(" {:>width$}", g.name));
    }
    if with_u {
        out.push_str("   (mm; value ± U, k=2)\n");
    } else if groups
        .iter()
        .any(|g| g.figures.iter().any(|f| unit_of(f.name) == "deg"))
    {
        out.push_str("   (mm; APa … RPc: deg)\n");
    } else {
        out.push_str("   (mm)\n");
    }
    let names: Vec<&str> = groups
        .iter()
        .flat_map(|g| g.figures.iter().map(|f| f.name))
        .fold(Vec::new(), |mut v, n| {
            if !v.contains(&n) {
                v.push(n);
            }
            v
        });
    for name in names {
        out.push_str(&format!("{name:<8}"));
        for g in &groups {
            let cell = g.figures.iter().find(|f| f.name == name).map_or_else(
                || "-".to_string(),
                |f| match f.u_mm {
                    Some(u) => format!("{} ± {}", fmt_mm(f.value_mm), fmt_mm(u)),
                    None => fmt_mm(f.value_mm),
                },
            );
            out.push_str(&format!(" {cell:>width$}"));
        }
        out.push('\n');
    }
    if !checks.is_empty() {
        out.push_str("\nchecks:\n");
        for c in checks {
            out.push_str(&format!(
                "  {:<8} {:<7} {:>10} {} {:>10}  {}  ({})\n",
                c.group,
                c.figure,
                fmt_mm(c.value_mm),
                if c.pass { "<=" } else { "> " },
                fmt_mm(c.limit_mm),
                if c.pass { "pass" } else { "FAIL" },
                c.source.name()
            ));
        }
    }
    out.push_str(&format!("verdict: {}\n", verdict(checks)));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_have_a_fixed_form() {
        assert_eq!(fmt_mm(-0.00001), "0.0000");
        assert_eq!(fmt_mm(0.01234), "0.0123");
        assert_eq!(json_mm(0.0028000000000000004), json!(0.0028));
        assert_eq!(json_mm(-1e-9), json!(0.0));
    }
}
