//! Plausibility of a machine file's model quantities, shared by both kinds
//! of machine: each quantity has a range from physics and from the real
//! machines it describes (docs/limits.md lists them); a value outside it
//! is a typing or unit mistake that would otherwise become a confident,
//! wrong correction, and is refused with its key path and the range.
//!
//! A file may accept such a value on purpose with a top-level
//! `plausibility:` mapping of key paths (or leading parts of them: a
//! section, a whole list) to `off`:
//!
//! ```yaml
//! plausibility:
//!   k_nm_per_rad: off          # every joint's stiffness
//!   links[5].mass_kg: off      # one value
//! ```
//!
//! An override key that names no checked quantity is an error; every value
//! accepted through one is a warning each time the file is read.
//!
//! These checks come on top of the hard limits of each loader (finite
//! numbers, signs, the limits of the model's validity), which no override
//! lifts.

use std::collections::BTreeMap;

use crate::error::{Invalid, show_number};

/// The value of a `plausibility:` entry: only `off` exists.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub(crate) enum Switch {
    /// The checks under the key are not applied (with a warning).
    Off,
}

/// The `plausibility:` mapping of a machine file.
pub(crate) type Overrides = BTreeMap<String, Switch>;

/// One plausibility pass over a file: the key paths it checked and the
/// values it found beyond their ranges.
#[derive(Debug, Default)]
pub(crate) struct Pass {
    checked: Vec<String>,
    found: Vec<Invalid>,
}

/// A range `lo..=hi` in a unit, for messages.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Range {
    /// Lowest plausible value.
    pub lo: f64,
    /// Highest plausible value.
    pub hi: f64,
    /// Unit as written in messages (`N/µm`, `kg`).
    pub unit: &'static str,
    /// What the range is of (`a wrist joint's stiffness`).
    pub what: &'static str,
}

impl Range {
    /// Builds a range.
    pub const fn new(lo: f64, hi: f64, unit: &'static str, what: &'static str) -> Range {
        Range { lo, hi, unit, what }
    }

    /// `lo..hi unit`, as messages and docs write it.
    pub fn shown(&self) -> String {
        let u = if self.unit.is_empty() {
            String::new()
        } else {
            format!(" {}", self.unit)
        };
        format!("{}..{}{u}", show_number(self.lo), show_number(self.hi))
    }
}

impl Pass {
    /// A new pass.
    pub(crate) fn new() -> Pass {
        Pass::default()
    }

    /// Checks that `v` at `path` lies within `r` (values that are not
    /// finite are the loaders' to refuse).
    pub(crate) fn range(&mut self, path: &str, v: f64, r: Range) {
        self.checked.push(path.to_string());
        if v.is_finite() && (v < r.lo || v > r.hi) {
            let u = if r.unit.is_empty() {
                String::new()
            } else {
                format!(" {}", r.unit)
            };
            self.found.push(Invalid::new(
                path,
                format!(
                    "{}{u} is outside {}, the plausible range of {} (check the unit)",
                    show_number(v),
                    r.shown(),
                    r.what
                ),
            ));
        }
    }

    /// Checks each value of `v` (`path[i]`) against `r`.
    pub(crate) fn each(&mut self, path: &str, v: &[f64], r: Range) {
        for (i, x) in v.iter().enumerate() {
            self.range(&format!("{path}[{i}]"), *x, r);
        }
    }

    /// Checks the length of a vector (`path`) against `r`.
    pub(crate) fn norm(&mut self, path: &str, v: &[f64], r: Range) {
        let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        self.checked.push(path.to_string());
        if n.is_finite() && (n < r.lo || n > r.hi) {
            self.found.push(Invalid::new(
                path,
                format!(
                    "a length of {} {} is outside {}, the plausible range of {} (check the unit)",
                    show_number(n),
                    r.unit,
                    r.shown(),
                    r.what
                ),
            ));
        }
    }

    /// A check of its own: `problem` is the message when the value at
    /// `path` is implausible.
    pub(crate) fn custom(&mut self, path: &str, problem: Option<String>) {
        self.checked.push(path.to_string());
        if let Some(m) = problem {
            self.found.push(Invalid::new(path, m));
        }
    }

    /// The outcome of the pass under the file's overrides: the first value
    /// beyond its range that no override covers is the error (with how to
    /// accept it); otherwise the warnings, one per value accepted through
    /// an override and one per override that accepts nothing.
    pub(crate) fn settle(self, overrides: Option<&Overrides>) -> Result<Vec<Invalid>, Invalid> {
        let empty = Overrides::new();
        let overrides = overrides.unwrap_or(&empty);
        for key in overrides.keys() {
            if !self.checked.iter().any(|p| covers(key, p)) {
                return Err(Invalid::new(
                    format!("plausibility.{key}"),
                    format!(
                        "`{key}` is not the key path of a quantity with a plausible range (a key path such as `k_nm_per_rad`, `links[5].mass_kg`, `stiffness.k_n_per_um`)"
                    ),
                ));
            }
        }
        let mut warnings = Vec::new();
        for inv in self.found {
            match overrides.keys().find(|k| covers(k, &inv.path)) {
                Some(key) => warnings.push(Invalid::new(
                    inv.path,
                    format!(
                        "{}; accepted because `plausibility: {{ {key}: off }}`",
                        strip_hint(&inv.message)
                    ),
                )),
                None => {
                    let message = format!(
                        "{} (or accept it with `plausibility: {{ {}: off }}`)",
                        inv.message, inv.path
                    );
                    return Err(Invalid::new(inv.path, message));
                }
            }
        }
        for key in overrides.keys() {
            if !warnings
                .iter()
                .any(|w| w.message.ends_with(&format!("{{ {key}: off }}`")))
            {
                warnings.push(Invalid::new(
                    format!("plausibility.{key}"),
                    "every value under it is within its plausible range: the override can go",
                ));
            }
        }
        Ok(warnings)
    }
}

/// Largest distance of a frame (a robot's base, a measuring instrument)
/// from the reference, mm: the largest cells and machines are a few tens
/// of metres across.
pub const PLACEMENT: Range = Range::new(0.0, 100_000.0, "mm", "a frame's placement");

/// The values of a `process_force:` section, by key (both machine kinds).
#[derive(Debug, Default)]
pub(crate) struct ForceKeys {
    /// `force_n` (constant model).
    pub force_n: Option<[f64; 3]>,
    /// `moment_nm` (constant model, robots).
    pub moment_nm: Option<[f64; 3]>,
    /// Milling coefficients `kt`, `kr`, `ka` (N/mm²) and `kte`, `kre`,
    /// `kae` (N/mm).
    pub k: [Option<f64>; 6],
    /// `tool_diameter_mm`.
    pub tool_diameter_mm: Option<f64>,
    /// `axial_depth_mm`.
    pub axial_depth_mm: Option<f64>,
    /// `thrust_coefficient_n_per_mm2`.
    pub thrust_n_per_mm2: Option<f64>,
    /// `drill_diameter_mm`.
    pub drill_diameter_mm: Option<f64>,
    /// `spindle_rpm`.
    pub spindle_rpm: Option<f64>,
    /// `max_feed_mm_per_rev`.
    pub max_feed_mm_per_rev: Option<f64>,
}

/// Largest process force, N (the heaviest roughing and friction stir
/// welding reach about 20 kN).
pub const FORCE: Range = Range::new(0.0, 50_000.0, "N", "a process force");
/// Largest process moment, N·m.
const MOMENT: Range = Range::new(0.0, 5_000.0, "N·m", "a process moment");
/// Specific cutting coefficients (`kt`, `kr`, `ka`): about 100 N/mm² for
/// plastics and wood, 600–900 for aluminium, 1500–3500 for steels and
/// titanium, up to about 6000 for hardened steel.
const K_CUT: Range = Range::new(0.0, 10_000.0, "N/mm²", "a specific cutting coefficient");
/// Edge coefficients (`kte`, `kre`, `kae`): tens of N/mm.
const K_EDGE: Range = Range::new(0.0, 500.0, "N/mm", "an edge coefficient");
/// Milling cutters from micro end mills to large face mills.
const TOOL_DIAMETER: Range = Range::new(0.1, 500.0, "mm", "a milling cutter's diameter");
/// Axial depth of cut (the limit of a program's `DEPTH=`).
const DEPTH: Range = Range::new(
    0.0,
    crate::process::limits::CUT_MAX_MM,
    "mm",
    "a depth of cut",
);
/// Thrust coefficient of a drill: about half the specific cutting force.
const THRUST: Range = Range::new(0.0, 10_000.0, "N/mm²", "a drill's thrust coefficient");
/// Twist drills from 0.1 mm to the largest indexable drills.
const DRILL_DIAMETER: Range = Range::new(0.1, 150.0, "mm", "a drill's diameter");
/// Spindle speed (the limit of a program's `S`).
const RPM: Range = Range::new(
    10.0,
    crate::process::limits::SPINDLE_MAX_RPM,
    "1/min",
    "a spindle speed",
);
/// Cutting speed `π·D·n` of a cutter or drill, m/min: from tapping at a
/// few m/min to high-speed cutting of aluminium.
pub const CUTTING_SPEED: Range = Range::new(2.0, 6000.0, "m/min", "a cutting speed");
/// Feed per revolution above which a move along the tool axis is taken for
/// positioning (the limit of a program's G95 `F`).
const FEED_REV: Range = Range::new(
    0.001,
    crate::process::limits::FEED_MAX_MM_PER_REV,
    "mm/rev",
    "a feed per revolution",
);

impl Pass {
    /// The plausibility of a `process_force:` section.
    pub(crate) fn force(&mut self, f: &ForceKeys) {
        const P: &str = "process_force";
        if let Some(v) = f.force_n {
            self.norm(&format!("{P}.force_n"), &v, FORCE);
        }
        if let Some(v) = f.moment_nm {
            self.norm(&format!("{P}.moment_nm"), &v, MOMENT);
        }
        let keys = [
            ("kt_n_per_mm2", K_CUT),
            ("kr_n_per_mm2", K_CUT),
            ("ka_n_per_mm2", K_CUT),
            ("kte_n_per_mm", K_EDGE),
            ("kre_n_per_mm", K_EDGE),
            ("kae_n_per_mm", K_EDGE),
        ];
        for ((key, r), v) in keys.into_iter().zip(f.k) {
            if let Some(v) = v {
                self.range(&format!("{P}.{key}"), v, r);
            }
        }
        for (key, v, r) in [
            ("tool_diameter_mm", f.tool_diameter_mm, TOOL_DIAMETER),
            ("axial_depth_mm", f.axial_depth_mm, DEPTH),
            ("thrust_coefficient_n_per_mm2", f.thrust_n_per_mm2, THRUST),
            ("drill_diameter_mm", f.drill_diameter_mm, DRILL_DIAMETER),
            ("spindle_rpm", f.spindle_rpm, RPM),
            ("max_feed_mm_per_rev", f.max_feed_mm_per_rev, FEED_REV),
        ] {
            if let Some(v) = v {
                self.range(&format!("{P}.{key}"), v, r);
            }
        }
        // The spindle speed with the cutter's diameter: a cutting speed
        // `π·D·n` far below any real cut makes a feed per tooth of
        // centimetres, and a force to match.
        if let (Some(n), Some(d)) = (f.spindle_rpm, f.tool_diameter_mm.or(f.drill_diameter_mm)) {
            let vc = std::f64::consts::PI * d * n / 1000.0;
            self.custom(
                &format!("{P}.spindle_rpm"),
                (vc.is_finite() && !(CUTTING_SPEED.lo..=CUTTING_SPEED.hi).contains(&vc)).then(|| {
                    format!(
                        "{} 1/min with the {} mm {} is a cutting speed of {} m/min, outside {}, the plausible range of {} (check the unit)",
                        show_number(n),
                        show_number(d),
                        if f.tool_diameter_mm.is_some() { "cutter" } else { "drill" },
                        show_number((vc * 1000.0).round() / 1000.0),
                        CUTTING_SPEED.shown(),
                        CUTTING_SPEED.what
                    )
                }),
            );
        }
    }
}

/// The message without its closing "(check the unit)".
fn strip_hint(m: &str) -> &str {
    m.strip_suffix(" (check the unit)").unwrap_or(m)
}

/// Whether override key `key` covers key path `path`: equal, or a leading
/// part of it ending at a `.` or `[`.
fn covers(key: &str, path: &str) -> bool {
    path.strip_prefix(key)
        .is_some_and(|rest| rest.is_empty() || rest.starts_with('.') || rest.starts_with('['))
}

#[cfg(test)]
mod tests {
    use super::*;

    const R: Range = Range::new(1.0, 10.0, "kg", "a test mass");

    fn overrides(keys: &[&str]) -> Overrides {
        keys.iter().map(|k| (k.to_string(), Switch::Off)).collect()
    }

    #[test]
    fn a_value_beyond_its_range_is_refused_with_the_range_and_the_override() {
        let mut p = Pass::new();
        p.range("links[5].mass_kg", 1000.0, R);
        let e = p.settle(None).unwrap_err();
        assert_eq!(e.path, "links[5].mass_kg");
        assert_eq!(
            e.message,
            "1000 kg is outside 1..10 kg, the plausible range of a test mass (check the unit) (or accept it with `plausibility: { links[5].mass_kg: off }`)"
        );
    }

    #[test]
    fn an_override_covers_its_key_and_the_keys_below_it_only() {
        for key in ["links", "links[5]", "links[5].mass_kg"] {
            let mut p = Pass::new();
            p.range("links[5].mass_kg", 1000.0, R);
            let w = p.settle(Some(&overrides(&[key]))).unwrap();
            assert_eq!(w.len(), 1, "{key}");
            assert!(w[0].message.contains("accepted because"), "{key}");
        }
        let mut p = Pass::new();
        p.range("links[5].mass_kg", 1000.0, R);
        p.range("links[50].mass_kg", 5.0, R);
        // `links[5` is no key path: `links[50]` does not cover `links[5]`.
        assert!(p.settle(Some(&overrides(&["links[50]"]))).is_err());
    }

    #[test]
    fn an_unknown_or_unused_override_is_an_error_or_a_warning() {
        let mut p = Pass::new();
        p.range("tool_load.mass_kg", 5.0, R);
        let e = p.settle(Some(&overrides(&["tool_lod"]))).unwrap_err();
        assert_eq!(e.path, "plausibility.tool_lod");
        let mut p = Pass::new();
        p.range("tool_load.mass_kg", 5.0, R);
        let w = p.settle(Some(&overrides(&["tool_load"]))).unwrap();
        assert_eq!(w.len(), 1);
        assert_eq!(w[0].path, "plausibility.tool_load");
    }

    #[test]
    fn values_within_the_range_and_not_finite_ones_pass() {
        let mut p = Pass::new();
        p.range("a", 1.0, R);
        p.range("b", 10.0, R);
        p.range("c", f64::NAN, R);
        p.norm("d", &[3.0, 4.0, 0.0], R);
        assert_eq!(p.settle(None).unwrap(), Vec::new());
        let mut p = Pass::new();
        p.norm("d", &[30.0, 40.0, 0.0], R);
        let e = p.settle(None).unwrap_err();
        assert!(e.message.starts_with("a length of 50 kg"), "{}", e.message);
    }
}
