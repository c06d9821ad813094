//! The rule every calibration kind applies before writing a parameter.
//!
//! A parameter is *uncertain* when its expanded uncertainty U (k = 2)
//! exceeds [`MAX_RELATIVE_UNCERTAINTY`] (50 %) of the larger of its
//! identified value's magnitude and the change the calibration makes to it
//! (`|value − start|`), unless it is a length whose U is at most
//! [`LENGTH_FLOOR_UM`]. An uncertain parameter is listed in the report and
//! keeps the input file's value, unless the user asks for it to be written
//! ([`Rule::write_uncertain`]).
//!
//! Why the two refinements of the plain ratio `U/|value|`:
//! - A value near zero (a straightness entry crossing zero, a joint offset
//!   of a few millidegrees) makes `U/|value|` explode however well the data
//!   determine it. When the change from the input value is large against
//!   U, the data reject the input value: keeping it would be worse than
//!   writing the identified one, so the change counts as the reference.
//! - A length known to within [`LENGTH_FLOOR_UM`] is written whatever its
//!   relative uncertainty: its uncertainty moves the tool by no more than
//!   that.
//!
//! Parameters fixed as unidentifiable, or kept as insignificant, are
//! already at the file's value and are not judged again.

use super::lsq::COVERAGE_K;
use super::report::Estimate;

/// Largest accepted `U(k=2)` relative to the larger of `|value|` and
/// `|value − start|`: 0.5 (50 %).
pub const MAX_RELATIVE_UNCERTAINTY: f64 = 0.5;

/// A length parameter (unit mm or µm) whose expanded uncertainty is at
/// most this, µm, is never uncertain: 2 µm, the resolution of the
/// interferometer-class data of a machine-tool calibration.
pub const LENGTH_FLOOR_UM: f64 = 2.0;

/// How a calibration treats uncertain parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rule {
    /// Largest accepted relative expanded uncertainty (fraction, not %).
    pub max_relative: f64,
    /// Write uncertain parameters anyway (they are still listed).
    pub write_uncertain: bool,
}

impl Default for Rule {
    fn default() -> Self {
        Rule {
            max_relative: MAX_RELATIVE_UNCERTAINTY,
            write_uncertain: false,
        }
    }
}

/// Expanded uncertainty `U(k=2)` relative to the larger of `|value|` and
/// `|value − start|`; `None` when the parameter is fixed or has no
/// uncertainty. Infinity when both are zero and U is not.
pub fn relative_uncertainty(p: &Estimate) -> Option<f64> {
    if p.fixed {
        return None;
    }
    let big_u = COVERAGE_K * p.u?;
    let reference = p.value.abs().max((p.value - p.start).abs());
    if reference == 0.0 {
        return Some(if big_u == 0.0 { 0.0 } else { f64::INFINITY });
    }
    Some(big_u / reference)
}

/// Expanded uncertainty in µm of a length parameter (unit mm or µm).
fn length_u_um(p: &Estimate) -> Option<f64> {
    let u = COVERAGE_K * p.u?;
    match p.unit {
        "mm" => Some(u * 1000.0),
        "µm" => Some(u),
        _ => None,
    }
}

impl Rule {
    /// True when `p` is uncertain under this rule.
    pub fn is_uncertain(&self, p: &Estimate) -> bool {
        let over = relative_uncertainty(p).is_some_and(|r| r > self.max_relative);
        over && !length_u_um(p).is_some_and(|u| u <= LENGTH_FLOOR_UM)
    }

    /// Indices of the uncertain parameters among `params`, in their order.
    pub fn uncertain(&self, params: &[Estimate]) -> Vec<usize> {
        (0..params.len())
            .filter(|&i| params.get(i).is_some_and(|p| self.is_uncertain(p)))
            .collect()
    }

    /// True when `p` keeps the input file's value: uncertain, and not
    /// [`Rule::write_uncertain`].
    pub fn withholds(&self, p: &Estimate) -> bool {
        !self.write_uncertain && self.is_uncertain(p)
    }

    /// [`Rule::withholds`] of every parameter of `params`.
    pub fn withheld(&self, params: &[Estimate]) -> Vec<bool> {
        params.iter().map(|p| self.withholds(p)).collect()
    }
}

/// Sets to zero the corrections of `full` whose flag in `withheld` is set,
/// so that those parameters keep the file's value.
pub fn zero_withheld(full: &mut [f64], withheld: &[bool]) {
    for (x, _) in full.iter_mut().zip(withheld).filter(|(_, w)| **w) {
        *x = 0.0;
    }
}

/// True when `p` is uncertain under the default rule.
pub fn is_uncertain(p: &Estimate) -> bool {
    Rule::default().is_uncertain(p)
}

/// Names of the uncertain parameters among `params` (default rule), in
/// their order.
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
            unit: "1/W",
            start: value,
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
    fn a_change_large_against_u_is_not_uncertain() {
        // Value 0.001 ± 0.002 (U = 400 % of the value), but moved from
        // 0.016: the change 0.015 is 7.5 U, the data reject the input.
        let mut p = est(0.001, Some(0.001), false);
        p.start = 0.016;
        assert!(!is_uncertain(&p));
        // The same value moved from 0.003: change 0.002 = U, uncertain.
        p.start = 0.003;
        assert!(is_uncertain(&p));
    }

    #[test]
    fn lengths_known_to_the_floor_are_not_uncertain() {
        let mut p = est(0.1, Some(0.5 * LENGTH_FLOOR_UM), false);
        p.unit = "µm";
        assert!(!is_uncertain(&p));
        p.u = Some(0.6 * LENGTH_FLOOR_UM);
        assert!(is_uncertain(&p));
        p.unit = "mm";
        p.value = 1e-4;
        p.start = 1e-4;
        p.u = Some(0.5e-3 * LENGTH_FLOOR_UM);
        assert!(!is_uncertain(&p));
        p.u = Some(0.6e-3 * LENGTH_FLOOR_UM);
        assert!(is_uncertain(&p));
    }

    #[test]
    fn the_threshold_and_the_write_flag_are_the_rule_s() {
        let params = [est(1.0, Some(0.3), false), est(1.0, Some(0.1), false)];
        let strict = Rule {
            max_relative: 0.1,
            write_uncertain: false,
        };
        assert_eq!(strict.uncertain(&params), vec![0, 1]);
        assert_eq!(strict.withheld(&params), vec![true, true]);
        let lax = Rule {
            max_relative: 1.0,
            write_uncertain: false,
        };
        assert!(lax.uncertain(&params).is_empty());
        let writing = Rule {
            write_uncertain: true,
            ..Rule::default()
        };
        assert_eq!(writing.uncertain(&params), vec![0]);
        assert_eq!(writing.withheld(&params), vec![false, false]);
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
