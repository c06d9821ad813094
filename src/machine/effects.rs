//! The effects a run predicts, as the command line names them (`--effects`,
//! `--gain`), for either kind of machine. The names are read here, once,
//! with one rule (any case); each engine then takes the names that apply to
//! it (machine tools: geometric, static, thermal, dynamic; robots:
//! kinematic or geometric, gravity, process or load, thermal, dynamic or
//! vibration) and refuses the others.

use std::str::FromStr;

/// An effect name of `--effects` and `--gain`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EffectName {
    /// `geometric`: machine-tool geometric errors; robots: as `kinematic`.
    Geometric,
    /// `kinematic`: robot DH parameter errors.
    Kinematic,
    /// `static`: machine-tool deflection under the process force.
    Static,
    /// `gravity`: robot joint deflection under gravity.
    Gravity,
    /// `process`: robot joint deflection under the process wrench.
    Process,
    /// `load`: robots, as `process`.
    Load,
    /// `thermal`: thermal drift (both kinds).
    Thermal,
    /// `dynamic`: vibration amplitude, reported only (both kinds).
    Dynamic,
    /// `vibration`: robots, as `dynamic`.
    Vibration,
}

/// Every effect name, in the order messages list them.
const NAMES: [EffectName; 9] = [
    EffectName::Geometric,
    EffectName::Kinematic,
    EffectName::Static,
    EffectName::Gravity,
    EffectName::Process,
    EffectName::Load,
    EffectName::Thermal,
    EffectName::Dynamic,
    EffectName::Vibration,
];

/// The names each kind of machine takes, for messages.
const KNOWN: &str = "machine tools: geometric, static, thermal, dynamic; robots: kinematic (geometric), gravity, process (load), thermal, dynamic (vibration)";

impl EffectName {
    /// The name as written on the command line.
    pub fn as_str(self) -> &'static str {
        match self {
            EffectName::Geometric => "geometric",
            EffectName::Kinematic => "kinematic",
            EffectName::Static => "static",
            EffectName::Gravity => "gravity",
            EffectName::Process => "process",
            EffectName::Load => "load",
            EffectName::Thermal => "thermal",
            EffectName::Dynamic => "dynamic",
            EffectName::Vibration => "vibration",
        }
    }
}

impl std::fmt::Display for EffectName {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for EffectName {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let name = s.trim();
        NAMES
            .into_iter()
            .find(|n| n.as_str().eq_ignore_ascii_case(name))
            .ok_or_else(|| format!("unknown effect `{name}` ({KNOWN})"))
    }
}

/// `--effects`: every effect of the machine, none, or a comma list of
/// names (any case; empty is none).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum EffectSpec {
    /// Every effect the machine has.
    All,
    /// These effects only (empty: none).
    Only(Vec<EffectName>),
}

impl FromStr for EffectSpec {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let spec = s.trim();
        if spec.eq_ignore_ascii_case("all") {
            return Ok(EffectSpec::All);
        }
        if spec.is_empty() || spec.eq_ignore_ascii_case("none") {
            return Ok(EffectSpec::Only(Vec::new()));
        }
        spec.split(',')
            .map(|name| {
                name.parse()
                    .map_err(|_| format!("unknown effect `{}` (all, none; {KNOWN})", name.trim()))
            })
            .collect::<Result<_, _>>()
            .map(EffectSpec::Only)
    }
}

/// Largest gain of `--gain`.
pub const MAX_GAIN: f64 = 10.0;

/// `--gain EFFECT=GAIN`: a scale of 0..[`MAX_GAIN`] on one effect.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gain {
    /// The effect.
    pub effect: EffectName,
    /// Its scale (1: as modelled).
    pub value: f64,
}

impl FromStr for Gain {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let (name, value) = s
            .split_once('=')
            .ok_or_else(|| format!("expected EFFECT=GAIN, got `{s}`"))?;
        let effect: EffectName = name.parse()?;
        let v: f64 = value
            .trim()
            .parse()
            .map_err(|_| format!("{effect}: `{}` is not a number", value.trim()))?;
        if !v.is_finite() || !(0.0..=MAX_GAIN).contains(&v) {
            return Err(format!(
                "{effect}: {} is outside 0..10",
                crate::error::show_number(v)
            ));
        }
        Ok(Gain { effect, value: v })
    }
}

/// The gains of a run for one engine, which maps each [`EffectName`] to
/// the slot of its effect (`None`: the name does not apply to it, refused
/// naming `engine`, "a machine tool" or "a robot", and `known`, its names):
/// one per slot, 1 for the effects `spec` turns on, `--gain` applied to
/// those that are on (an effect switched off stays off).
pub fn gains_for<const N: usize>(
    spec: &EffectSpec,
    gains: &[Gain],
    slot: impl Fn(EffectName) -> Option<usize>,
    engine: &str,
    known: &str,
) -> crate::error::Result<[f64; N]> {
    let find = |name: EffectName, flag: &str| {
        slot(name).filter(|&i| i < N).ok_or_else(|| {
            crate::error::Error::Usage(format!(
                "unknown effect `{name}` in {flag} for {engine} (known: {known})"
            ))
        })
    };
    let mut out = [0.0; N];
    match spec {
        EffectSpec::All => out = [1.0; N],
        EffectSpec::Only(names) => {
            for &n in names {
                out[find(n, "--effects")?] = 1.0;
            }
        }
    }
    for g in gains {
        let i = find(g.effect, "--gain")?;
        if out[i] != 0.0 {
            out[i] = g.value;
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn effect_names_parse_in_any_case_and_refuse_others() {
        for n in NAMES {
            assert_eq!(n.as_str().parse::<EffectName>(), Ok(n));
            assert_eq!(n.as_str().to_uppercase().parse::<EffectName>(), Ok(n));
        }
        let err = "magic".parse::<EffectName>().expect_err("unknown");
        assert!(err.starts_with("unknown effect `magic` ("), "{err}");
        assert!(!err.contains("--"), "{err}");
    }

    #[test]
    fn effect_specs_parse_all_none_and_lists() {
        let parse = |s: &str| s.parse::<EffectSpec>();
        assert_eq!(parse("all"), Ok(EffectSpec::All));
        assert_eq!(parse(" ALL "), Ok(EffectSpec::All));
        assert_eq!(parse("none"), Ok(EffectSpec::Only(vec![])));
        assert_eq!(parse(""), Ok(EffectSpec::Only(vec![])));
        assert_eq!(
            parse("geometric, Thermal"),
            Ok(EffectSpec::Only(vec![
                EffectName::Geometric,
                EffectName::Thermal
            ]))
        );
        let err = parse("geometric,magic").expect_err("unknown");
        assert!(err.contains("unknown effect `magic` (all, none;"), "{err}");
        assert!(!err.contains("--"), "{err}");
    }

    #[test]
    fn gains_parse_name_and_value_within_range() {
        assert_eq!(
            "thermal=0.8".parse::<Gain>(),
            Ok(Gain {
                effect: EffectName::Thermal,
                value: 0.8
            })
        );
        assert_eq!(
            "Gravity = 10".parse::<Gain>().map(|g| g.value),
            Ok(MAX_GAIN)
        );
        for (bad, want) in [
            ("thermal", "expected EFFECT=GAIN, got `thermal`"),
            ("thermal=x", "thermal: `x` is not a number"),
            ("thermal=11", "thermal: 11 is outside 0..10"),
            ("thermal=-1", "thermal: -1 is outside 0..10"),
            ("thermal=NaN", "outside 0..10"),
            ("magic=1", "unknown effect `magic`"),
        ] {
            let err = bad.parse::<Gain>().expect_err(bad);
            assert!(err.contains(want), "{bad}: {err}");
            assert!(!err.contains("--"), "{err}");
        }
    }

    #[test]
    fn gains_for_an_engine_map_names_and_keep_switched_off_effects_off() {
        // A two-slot engine: geometric and kinematic are slot 0, thermal 1.
        let slot = |n: EffectName| match n {
            EffectName::Geometric | EffectName::Kinematic => Some(0),
            EffectName::Thermal => Some(1),
            _ => None,
        };
        let run = |spec: &str, gains: &[&str]| {
            let spec: EffectSpec = spec.parse().expect("spec");
            let gains: Vec<Gain> = gains.iter().map(|g| g.parse().expect("gain")).collect();
            gains_for::<2>(&spec, &gains, slot, "a test engine", "geometric, thermal")
        };
        assert_eq!(run("all", &["kinematic=0.5"]).ok(), Some([0.5, 1.0]));
        assert_eq!(run("thermal", &["geometric=0.5"]).ok(), Some([0.0, 1.0]));
        assert_eq!(run("none", &[]).ok(), Some([0.0, 0.0]));
        let err = run("all", &["gravity=2"]).expect_err("not this engine's");
        assert!(
            err.to_string()
                .contains("unknown effect `gravity` in --gain for a test engine"),
            "{err}"
        );
        let err = run("static", &[]).expect_err("not this engine's");
        assert!(
            err.to_string().contains(
                "unknown effect `static` in --effects for a test engine (known: geometric, thermal)"
            ),
            "{err}"
        );
    }
}
