//! Limits of the acceptance figures: `--limit [GROUP.]FIGURE=MM` on the
//! command line, or the machine file's `acceptance` key:
//!
//! ```yaml
//! acceptance:
//!   iso230_2:
//!     X: { A_mm: 0.012, R_mm: 0.005, B_mm: 0.004 }
//!   iso230_4: { G_mm: 0.015, H_mm: 0.005 }
//!   iso9283: { AP_mm: 0.5, RP_mm: 0.06 }
//! ```
//!
//! A figure passes when its magnitude, to the nanometre the reports give,
//! is at most its limit. A limit of the
//! command line replaces the machine file's for the same figure; a limit
//! naming a group (an axis) replaces one that names none.

use std::collections::BTreeMap;

use serde::Deserialize;

use super::{Group, Standard};
use crate::error::{Error, Result, show_number};
use crate::machine::yaml;

/// Where a limit comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LimitSource {
    /// `--limit`.
    CommandLine,
    /// The machine file's `acceptance` key.
    MachineFile,
}

impl LimitSource {
    /// As reports name it.
    pub fn name(self) -> &'static str {
        match self {
            LimitSource::CommandLine => "command line",
            LimitSource::MachineFile => "machine file",
        }
    }
}

/// The largest value a figure may have.
#[derive(Debug, Clone, PartialEq)]
pub struct Limit {
    /// The group (axis) it applies to; `None`: every group.
    pub group: Option<String>,
    /// The figure (`A`, `RP`).
    pub figure: String,
    /// The limit, mm.
    pub max_mm: f64,
    /// Where it comes from.
    pub source: LimitSource,
}

impl std::str::FromStr for Limit {
    type Err = String;

    /// `[GROUP.]FIGURE=MM`, e.g. `A=0.012`, `X.R=0.004`.
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        let (name, value) = s
            .split_once('=')
            .ok_or_else(|| format!("`{s}`: expected [GROUP.]FIGURE=MM, e.g. A=0.012"))?;
        let max_mm: f64 = value
            .trim()
            .parse()
            .map_err(|_| format!("`{s}`: the limit `{value}` is not a number (mm)"))?;
        if !(max_mm.is_finite() && max_mm > 0.0) {
            return Err(format!("`{s}`: the limit must be a positive number of mm"));
        }
        let (group, figure) = match name.trim().split_once('.') {
            Some((g, f)) => (Some(g.trim().to_string()), f.trim().to_string()),
            None => (None, name.trim().to_string()),
        };
        if figure.is_empty() || group.as_deref() == Some("") {
            return Err(format!("`{s}`: expected [GROUP.]FIGURE=MM, e.g. A=0.012"));
        }
        Ok(Limit {
            group,
            figure,
            max_mm,
            source: LimitSource::CommandLine,
        })
    }
}

/// A figure held against its limit.
#[derive(Debug, Clone, PartialEq)]
pub struct Check {
    /// The group (axis, `circle`, `poses`).
    pub group: String,
    /// The figure.
    pub figure: &'static str,
    /// Its value, mm.
    pub value_mm: f64,
    /// Its limit, mm.
    pub limit_mm: f64,
    /// Where the limit comes from.
    pub source: LimitSource,
    /// `|value| <= limit`.
    pub pass: bool,
}

/// Refuses a command-line limit naming a figure of another standard or a
/// group the data do not have.
pub fn validate(standard: Standard, limits: &[Limit], groups: &[Group]) -> Result<()> {
    for l in limits
        .iter()
        .filter(|l| l.source == LimitSource::CommandLine)
    {
        if !standard.figures().contains(&l.figure.as_str()) {
            return Err(Error::Usage(format!(
                "--limit {}: {} has no figure `{}` (figures: {})",
                l.figure,
                standard.title(),
                l.figure,
                standard.figures().join(", ")
            )));
        }
        if let Some(g) = &l.group {
            if !groups.iter().any(|x| &x.name == g) {
                let names: Vec<&str> = groups.iter().map(|x| x.name.as_str()).collect();
                return Err(Error::Usage(format!(
                    "--limit {g}.{}: no `{g}` in the data (there: {})",
                    l.figure,
                    names.join(", ")
                )));
            }
        }
    }
    Ok(())
}

/// Each figure that has a limit, held against it (group order, then figure
/// order).
pub fn check(groups: &[Group], limits: &[Limit]) -> Vec<Check> {
    let rank = |l: &Limit| (l.source == LimitSource::CommandLine, l.group.is_some());
    let mut out = Vec::new();
    for g in groups {
        for f in &g.figures {
            let best = limits
                .iter()
                .filter(|l| l.figure == f.name && l.group.as_ref().is_none_or(|n| *n == g.name))
                .max_by_key(|l| rank(l));
            if let Some(l) = best {
                out.push(Check {
                    group: g.name.clone(),
                    figure: f.name,
                    value_mm: f.value_mm,
                    limit_mm: l.max_mm,
                    source: l.source,
                    pass: reported(f.value_mm.abs()) <= l.max_mm,
                });
            }
        }
    }
    out
}

/// A value as reports give it, to the nanometre: what a limit is held
/// against, so that a figure shown equal to its limit passes whatever the
/// rounding of the data it came from.
fn reported(v: f64) -> f64 {
    (v * 1e6).round() / 1e6
}

/// The `acceptance` key of a machine file.
#[derive(Debug, Deserialize)]
struct RawFile {
    #[serde(default)]
    acceptance: Option<RawAcceptance>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAcceptance {
    #[serde(default)]
    iso230_2: BTreeMap<String, BTreeMap<String, f64>>,
    #[serde(default)]
    iso230_4: BTreeMap<String, f64>,
    #[serde(default)]
    iso9283: BTreeMap<String, f64>,
}

/// The limits of `standard` in the machine file's `acceptance` key (none
/// without one); `file` names the file in errors.
pub fn from_machine_file(text: &str, file: &str, standard: Standard) -> Result<Vec<Limit>> {
    let raw: RawFile = yaml::deserialize(text, file)?;
    let Some(acc) = raw.acceptance else {
        return Ok(Vec::new());
    };
    let mut entries: Vec<(Option<String>, String, f64)> = Vec::new();
    match standard {
        Standard::Iso230_2 => {
            for (axis, figs) in acc.iso230_2 {
                for (k, v) in figs {
                    entries.push((Some(axis.clone()), k, v));
                }
            }
        }
        Standard::Iso230_4 => entries.extend(acc.iso230_4.into_iter().map(|(k, v)| (None, k, v))),
        Standard::Iso9283 => entries.extend(acc.iso9283.into_iter().map(|(k, v)| (None, k, v))),
    }
    entries
        .into_iter()
        .map(|(group, key, v)| {
            let path = match &group {
                Some(g) => format!("acceptance.{}.{g}.{key}", standard.key()),
                None => format!("acceptance.{}.{key}", standard.key()),
            };
            let figure = key
                .rsplit_once('_')
                .filter(|(f, unit)| standard.figures().contains(f) && super::unit_of(f) == *unit)
                .map(|(f, _)| f)
                .ok_or_else(|| {
                    let keys: Vec<String> = standard
                        .figures()
                        .iter()
                        .map(|f| format!("{f}_{}", super::unit_of(f)))
                        .collect();
                    yaml::located(
                        text,
                        file,
                        &path,
                        &format!("unknown figure key (keys: {})", keys.join(", ")),
                    )
                })?;
            if !(v.is_finite() && v > 0.0) {
                return Err(yaml::located(
                    text,
                    file,
                    &path,
                    &format!(
                        "a limit is a positive number of mm, found {}",
                        show_number(v)
                    ),
                ));
            }
            Ok(Limit {
                group,
                figure: figure.to_string(),
                max_mm: v,
                source: LimitSource::MachineFile,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::super::Figure;
    use super::*;

    #[test]
    fn a_limit_parses_from_the_command_line() {
        let l: Limit = "X.R=0.004".parse().unwrap();
        assert_eq!(l.group.as_deref(), Some("X"));
        assert_eq!(l.figure, "R");
        assert_eq!(l.max_mm, 0.004);
        assert!("A".parse::<Limit>().is_err());
        assert!("A=-1".parse::<Limit>().is_err());
        assert!("A=x".parse::<Limit>().is_err());
        assert!(".A=1".parse::<Limit>().is_err());
    }

    #[test]
    fn the_most_specific_limit_wins() {
        let groups = vec![Group {
            name: "X".into(),
            figures: vec![
                Figure {
                    name: "A",
                    value_mm: 0.010,
                    u_mm: None,
                },
                Figure {
                    name: "B_mean",
                    value_mm: -0.003,
                    u_mm: None,
                },
            ],
        }];
        let text = "kind: machine_tool\nacceptance:\n  iso230_2:\n    X: { A_mm: 0.008, B_mean_mm: 0.002 }\n";
        let mut limits = from_machine_file(text, "m.yaml", Standard::Iso230_2).unwrap();
        let c = check(&groups, &limits);
        assert_eq!(c.len(), 2);
        assert!(!c[0].pass && c[0].source == LimitSource::MachineFile);
        // The magnitude is held against the limit.
        assert!(!c[1].pass);
        limits.push("A=0.011".parse().unwrap());
        let c = check(&groups, &limits);
        assert!(c[0].pass && c[0].source == LimitSource::CommandLine);
        assert!(validate(Standard::Iso230_2, &limits, &groups).is_ok());
        let bad = vec!["Y.A=1".parse().unwrap()];
        assert!(validate(Standard::Iso230_2, &bad, &groups).is_err());
        let bad = vec!["AP=1".parse().unwrap()];
        assert!(validate(Standard::Iso230_2, &bad, &groups).is_err());
    }

    #[test]
    fn a_bad_acceptance_key_is_located() {
        let text = "kind: robot\nacceptance:\n  iso9283:\n    AP_mm: 0.5\n    XX_mm: 1\n";
        let e = from_machine_file(text, "m.yaml", Standard::Iso9283).unwrap_err();
        assert!(e.to_string().starts_with("m.yaml:5:5:"), "{e}");
        assert!(e.to_string().contains("acceptance.iso9283.XX_mm"), "{e}");
        let text = "kind: robot\nacceptance:\n  iso9283: { AP_mm: 0 }\n";
        assert!(from_machine_file(text, "m.yaml", Standard::Iso9283).is_err());
        let text = "kind: robot\nacceptance:\n  iso9999: {}\n";
        assert!(from_machine_file(text, "m.yaml", Standard::Iso9283).is_err());
    }
}
