//! The rule every calibration kind applies before writing a parameter: a
//! parameter whose expanded uncertainty U (k = 2) exceeds
//! [`MAX_RELATIVE_UNCERTAINTY`] of its identified value's magnitude (the
//! `U/|v| %` column of the report) is *uncertain*: it is listed and keeps
//! the input file's value unless the user asks for it to be written.
//! Parameters fixed as unidentifiable, or kept as insignificant, are
//! already at the file's value and are not judged again.

use super::lsq::COVERAGE_K;
use super::report::Estimate;

/// Largest accepted `U(k=2)/|value|`: 0.5 (50 %).
pub const MAX_RELATIVE_UNCERTAINTY: f64 = 0.5;

/// Relative expanded uncertainty `U(k=2)/|value|` of an identified
/// parameter; `None` when it is fixed or has no uncertainty. A value of
/// exactly zero with a non-zero uncertainty gives infinity.
pub fn relative_uncertainty(p: &Estimate) -> Option<f64> {
    if p.fixed {
        return None;
    }
    let u = p.u?;
    let big_u = COVERAGE_K * u;
    if p.value == 0.0 {
        return Some(if big_u == 0.0 { 0.0 } else { f64::INFINITY });
    }
    Some(big_u / p.value.abs())
}

/// True when `p` is identified but its relative expanded uncertainty
/// exceeds [`MAX_RELATIVE_UNCERTAINTY`].
pub fn is_uncertain(p: &Estimate) -> bool {
    relative_uncertainty(p).is_some_and(|r| r > MAX_RELATIVE_UNCERTAINTY)
}

/// Names of the uncertain parameters among `params`, in their order.
pub fn uncertain_names(params: &[Estimate]) -> Vec<&str> {
    params
        .iter()
        .filter(|p| is_uncertain(p))
        .map(|p| p.name.as_str())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn est(value: f64, u: Option<f64>, fixed: bool) -> Estimate {
        Estimate {
            name: "p".into(),
            unit: "mm",
            start: 0.0,
            value,
            u,
            fixed,
        }
    }

    #[test]
    fn threshold_is_on_the_expanded_uncertainty() {
        // U = 2 u: u = 0.2 on 1.0 is 40 % (kept), u = 0.3 is 60 % (uncertain).
        assert!(!is_uncertain(&est(1.0, Some(0.2), false)));
        assert!(is_uncertain(&est(1.0, Some(0.3), false)));
        assert!(is_uncertain(&est(-1.0, Some(0.3), false)));
    }

    #[test]
    fn fixed_or_unknown_uncertainty_is_not_judged() {
        assert!(!is_uncertain(&est(1.0, Some(10.0), true)));
        assert!(!is_uncertain(&est(1.0, None, false)));
    }

    #[test]
    fn zero_value_with_uncertainty_is_uncertain() {
        assert!(is_uncertain(&est(0.0, Some(1e-6), false)));
        assert!(!is_uncertain(&est(0.0, Some(0.0), false)));
    }

    #[test]
    fn names_keep_their_order() {
        let mut a = est(1.0, Some(1.0), false);
        a.name = "a".into();
        let b = est(1.0, Some(0.01), false);
        let mut c = est(2.0, Some(2.0), false);
        c.name = "c".into();
        assert_eq!(uncertain_names(&[a, b, c]), vec!["a", "c"]);
    }
}
