//! `--force`: the process force a run uses instead of the machine file's,
//! for machine tools and robots alike: `none`, or a constant force
//! `constant:FX,FY,FZ[@workpiece|tool|feed]` (N, force on the tool).

use nalgebra::Vector3;

use super::{ForceModel, Frame};

/// Largest force component of `--force constant:…`, N.
pub const MAX_FORCE_N: f64 = 1e6;

/// A `--force` value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ForceSpec {
    /// No process force.
    None,
    /// A constant force on the tool, on feed moves only.
    Constant {
        /// Components in `frame`, N.
        force_n: Vector3<f64>,
        /// Their frame (`workpiece` when not given).
        frame: Frame,
    },
}

impl ForceSpec {
    /// The machine-tool force model it sets (`None`: no force).
    pub fn model(self) -> Option<ForceModel> {
        match self {
            ForceSpec::None => None,
            ForceSpec::Constant { force_n, frame } => Some(ForceModel::constant(force_n, frame)),
        }
    }
}

impl std::str::FromStr for ForceSpec {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let spec = s.trim();
        if spec.eq_ignore_ascii_case("none") {
            return Ok(ForceSpec::None);
        }
        let bad =
            || format!("`{spec}`: expected none or constant:FX,FY,FZ[@workpiece|tool|feed] (N)");
        let body = spec.strip_prefix("constant:").ok_or_else(bad)?;
        let (vals, frame) = match body.split_once('@') {
            Some((v, f)) => (v, Frame::parse(f).ok_or_else(bad)?),
            None => (body, Frame::Workpiece),
        };
        let v: Vec<f64> = vals
            .split(',')
            .map(|x| x.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|_| bad())?;
        match v.as_slice() {
            [x, y, z] if v.iter().all(|c| c.is_finite() && c.abs() <= MAX_FORCE_N) => {
                Ok(ForceSpec::Constant {
                    force_n: Vector3::new(*x, *y, *z),
                    frame,
                })
            }
            _ => Err(bad()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_none_and_constant_forces_in_each_frame() {
        assert_eq!("none".parse::<ForceSpec>(), Ok(ForceSpec::None));
        assert_eq!(" NONE ".parse::<ForceSpec>(), Ok(ForceSpec::None));
        assert_eq!(
            "constant:1,-2,3.5".parse::<ForceSpec>(),
            Ok(ForceSpec::Constant {
                force_n: Vector3::new(1.0, -2.0, 3.5),
                frame: Frame::Workpiece
            })
        );
        for (text, frame) in [
            ("workpiece", Frame::Workpiece),
            ("tool", Frame::Tool),
            ("feed", Frame::Feed),
        ] {
            let spec: ForceSpec = format!("constant:0,0,-200@{text}")
                .parse()
                .unwrap_or_else(|e| panic!("{text}: {e}"));
            assert_eq!(
                spec.model(),
                Some(ForceModel::constant(Vector3::new(0.0, 0.0, -200.0), frame))
            );
        }
        assert_eq!(ForceSpec::None.model(), None);
    }

    #[test]
    fn refuses_malformed_forces_naming_the_value_not_the_flag() {
        for bad in [
            "constant:1,2",
            "constant:1,2,3@wrist",
            "constant:1,2,x",
            "constant:1,2,1e7",
            "constant:1,2,NaN",
            "1,2,3",
            "",
        ] {
            let err = bad.parse::<ForceSpec>().expect_err(bad);
            assert!(
                err.starts_with(&format!("`{bad}`: expected none or constant:")),
                "{err}"
            );
            assert!(!err.contains("--"), "{err}");
        }
    }
}
