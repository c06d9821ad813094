//! Tool lengths and work offsets given on the command line (`--tool
//! H=LENGTH`, `--work-offset GXX=X,Y,Z`), overriding the machine file's.

use std::str::FromStr;

use super::load::work_offset_key;

/// Longest tool of `--tool`, mm.
pub const MAX_TOOL_LENGTH_MM: f64 = 2000.0;

/// Largest coordinate of `--work-offset`, mm.
pub const MAX_WORK_OFFSET_MM: f64 = 1e6;

/// `--tool H=LENGTH`: the length of the tool of an H number, mm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ToolLength {
    /// The H number (`H1` or `1`).
    pub h: u32,
    /// Tool length, mm (0..[`MAX_TOOL_LENGTH_MM`]).
    pub length_mm: f64,
}

impl FromStr for ToolLength {
    type Err = String;
    fn from_str(t: &str) -> Result<Self, String> {
        let (h, len) = t
            .split_once('=')
            .ok_or_else(|| format!("expected H<n>=LENGTH, got `{t}`"))?;
        let h = h.trim().trim_start_matches(['H', 'h']);
        let h: u32 = h.parse().map_err(|_| format!("`{t}`: bad H number"))?;
        let len: f64 = len
            .trim()
            .parse()
            .map_err(|_| format!("`{t}`: bad length"))?;
        if !len.is_finite() || !(0.0..=MAX_TOOL_LENGTH_MM).contains(&len) {
            return Err(format!("`{t}`: length must be within 0..2000 mm"));
        }
        Ok(ToolLength { h, length_mm: len })
    }
}

/// `--work-offset GXX=X,Y,Z`: a work offset in machine coordinates, mm.
#[derive(Debug, Clone, PartialEq)]
pub struct WorkOffset {
    /// The code in upper case: `G54`…`G59`, `G54.1P1`…`G54.1P300`,
    /// `G154P1`…`G154P99`.
    pub code: String,
    /// Slot 0..5 of `G54`…`G59`; `None` for the extended offsets.
    pub slot: Option<usize>,
    /// The offset, mm.
    pub xyz_mm: [f64; 3],
}

impl FromStr for WorkOffset {
    type Err = String;
    fn from_str(w: &str) -> Result<Self, String> {
        let (code, xyz) = w
            .split_once('=')
            .ok_or_else(|| format!("expected G54=X,Y,Z, got `{w}`"))?;
        let code = code.trim().to_ascii_uppercase();
        let slot = match code.as_str() {
            "G54" => Some(0),
            "G55" => Some(1),
            "G56" => Some(2),
            "G57" => Some(3),
            "G58" => Some(4),
            "G59" => Some(5),
            c if work_offset_key(c) => None,
            _ => {
                return Err(format!(
                    "`{code}` is not G54..G59, G54.1P1..G54.1P300 or G154P1..G154P99"
                ));
            }
        };
        let v: Vec<f64> = xyz
            .split(',')
            .map(|s| s.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|_| format!("`{w}`: expected three numbers"))?;
        match v.as_slice() {
            [x, y, z]
                if v.iter()
                    .all(|c| c.is_finite() && c.abs() <= MAX_WORK_OFFSET_MM) =>
            {
                Ok(WorkOffset {
                    code,
                    slot,
                    xyz_mm: [*x, *y, *z],
                })
            }
            _ => Err(format!("`{w}`: expected three finite numbers")),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tool_lengths_parse_with_or_without_the_h() {
        for text in ["H1=123.4", "h1 = 123.4", "1=123.4"] {
            assert_eq!(
                text.parse::<ToolLength>(),
                Ok(ToolLength {
                    h: 1,
                    length_mm: 123.4
                }),
                "{text}"
            );
        }
        for (bad, want) in [
            ("H1", "expected H<n>=LENGTH, got `H1`"),
            ("Hx=1", "`Hx=1`: bad H number"),
            ("H1=abc", "`H1=abc`: bad length"),
            ("H1=2001", "`H1=2001`: length must be within 0..2000 mm"),
            ("H1=-1", "`H1=-1`: length must be within 0..2000 mm"),
        ] {
            let err = bad.parse::<ToolLength>().expect_err(bad);
            assert_eq!(err, want);
        }
    }

    #[test]
    fn work_offsets_parse_the_standard_and_extended_codes() {
        let g55: WorkOffset = "g55=1,2,-3".parse().unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            g55,
            WorkOffset {
                code: "G55".into(),
                slot: Some(1),
                xyz_mm: [1.0, 2.0, -3.0]
            }
        );
        let ext: WorkOffset = "G54.1P7 = 0, 0, 5"
            .parse()
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!((ext.code.as_str(), ext.slot), ("G54.1P7", None));
        for (bad, want) in [
            ("G54", "expected G54=X,Y,Z, got `G54`"),
            ("G53=0,0,0", "`G53` is not G54..G59"),
            ("G54.1P301=0,0,0", "`G54.1P301` is not G54..G59"),
            ("G54=1,2", "`G54=1,2`: expected three finite numbers"),
            ("G54=1,2,x", "`G54=1,2,x`: expected three numbers"),
            ("G54=1,2,1e7", "expected three finite numbers"),
        ] {
            let err = bad.parse::<WorkOffset>().expect_err(bad);
            assert!(err.contains(want), "{bad}: {err}");
            assert!(!err.contains("--"), "{err}");
        }
    }
}
