//! The thermal state a program run starts from (`--thermal-start`), shared
//! by the machine-tool thermal model and the robot's: cold, the steady state
//! of the program repeated, or a warm-up of some minutes at the program's
//! mean power.

/// Longest warm-up of `--thermal-start MINUTES` (about ten weeks: any
/// machine is at its steady state long before).
pub const MAX_WARM_UP_MIN: f64 = 1e5;

/// Initial thermal state of a program run.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum ThermalStart {
    /// Cold machine: every thermal state at ambient (effective power 0).
    #[default]
    Cold,
    /// The steady state of the program run as a repeated task (machine
    /// tools: at the program's mean power; robots: the periodic state).
    Steady,
    /// After this many minutes of the program's mean power from cold.
    WarmUpMin(f64),
}

impl ThermalStart {
    /// True when the start needs the program's mean power (a first pass
    /// over the program).
    pub fn needs_mean_power(self) -> bool {
        match self {
            ThermalStart::Cold => false,
            ThermalStart::Steady => true,
            ThermalStart::WarmUpMin(m) => m > 0.0,
        }
    }
}

/// Parses `cold`, `steady` (any case) or a number of minutes within
/// 0..[`MAX_WARM_UP_MIN`]; the message names the value, not the flag.
impl std::str::FromStr for ThermalStart {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim().to_ascii_lowercase().as_str() {
            "cold" => Ok(ThermalStart::Cold),
            "steady" => Ok(ThermalStart::Steady),
            t => match t.parse::<f64>() {
                Ok(m) if m.is_finite() && (0.0..=MAX_WARM_UP_MIN).contains(&m) => {
                    Ok(ThermalStart::WarmUpMin(m))
                }
                _ => Err(format!(
                    "`{s}` is not cold, steady or a number of minutes (0..100000)"
                )),
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_every_spelling_in_any_case() {
        let parse = |s: &str| s.parse::<ThermalStart>();
        assert_eq!(parse("cold"), Ok(ThermalStart::Cold));
        assert_eq!(parse("COLD"), Ok(ThermalStart::Cold));
        assert_eq!(parse(" steady "), Ok(ThermalStart::Steady));
        assert_eq!(parse("STEADY"), Ok(ThermalStart::Steady));
        assert_eq!(parse("Steady"), Ok(ThermalStart::Steady));
        assert_eq!(parse("30"), Ok(ThermalStart::WarmUpMin(30.0)));
        assert_eq!(parse("0"), Ok(ThermalStart::WarmUpMin(0.0)));
        assert_eq!(
            parse("100000"),
            Ok(ThermalStart::WarmUpMin(MAX_WARM_UP_MIN))
        );
    }

    #[test]
    fn refuses_other_values_naming_them_but_not_the_flag() {
        for bad in ["warm", "-5", "1e308", "100001", "NaN", "inf", ""] {
            let err = bad.parse::<ThermalStart>().expect_err(bad);
            assert!(err.contains(&format!("`{bad}`")), "{err}");
            assert!(err.contains("(0..100000)"), "{err}");
            assert!(!err.contains("--"), "{err}");
        }
    }

    #[test]
    fn only_a_warm_start_needs_the_mean_power() {
        assert!(!ThermalStart::Cold.needs_mean_power());
        assert!(!ThermalStart::WarmUpMin(0.0).needs_mean_power());
        assert!(ThermalStart::WarmUpMin(0.5).needs_mean_power());
        assert!(ThermalStart::Steady.needs_mean_power());
    }
}
