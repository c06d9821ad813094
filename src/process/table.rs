//! Per-block process forces from a CSV file written by an external force
//! predictor: header `line,fx_n,fy_n,fz_n`, one row per program line
//! (workpiece frame, force on the tool, N). Lines without a row get no force.

use std::collections::BTreeMap;

use nalgebra::Vector3;

use crate::error::{Error, Located, Result};

/// The expected header.
pub const TABLE_HEADER: [&str; 4] = ["line", "fx_n", "fy_n", "fz_n"];

/// Largest accepted force component, N.
const MAX_FORCE_N: f64 = 1e6;

/// Forces by program line.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ForceTable {
    rows: BTreeMap<usize, Vector3<f64>>,
}

impl ForceTable {
    /// Reads a table from CSV text; `file` names it in errors
    /// (`file:line:column: message`, quoting the offending field).
    pub fn from_csv_str(text: &str, file: &str) -> Result<Self> {
        let mut rdr = csv::ReaderBuilder::new()
            .has_headers(false)
            .trim(csv::Trim::All)
            .flexible(true)
            .comment(Some(b'#'))
            .from_reader(text.as_bytes());
        let mut rows = BTreeMap::new();
        let mut header_seen = false;
        let mut record = csv::StringRecord::new();
        loop {
            let more = rdr.read_record(&mut record).map_err(|e| {
                let line = e.position().map_or(1, |p| p.line() as usize);
                Error::Input(Located::new(file, line, 1, format!("bad CSV: {e}")))
            })?;
            if !more {
                break;
            }
            let line = record.position().map_or(1, |p| p.line() as usize);
            // Column of field i in the raw line (fields split at commas).
            let raw_line = text.lines().nth(line.saturating_sub(1)).unwrap_or("");
            let col = |i: usize| {
                let mut start = 0;
                for (k, part) in raw_line.split(',').enumerate() {
                    if k == i {
                        return start + (part.len() - part.trim_start().len()) + 1;
                    }
                    start += part.len() + 1;
                }
                1
            };
            let err = |i: usize, msg: String| Error::Input(Located::new(file, line, col(i), msg));
            if !header_seen {
                let got: Vec<&str> = record.iter().collect();
                if got != TABLE_HEADER {
                    return Err(err(
                        0,
                        format!(
                            "expected the header `{}`, found `{}`",
                            TABLE_HEADER.join(","),
                            got.join(",")
                        ),
                    ));
                }
                header_seen = true;
                continue;
            }
            if record.len() != 4 {
                return Err(err(
                    0,
                    format!(
                        "expected 4 fields (line,fx_n,fy_n,fz_n), found {}",
                        record.len()
                    ),
                ));
            }
            let field = |i: usize| record.get(i).unwrap_or("");
            let key: usize = field(0)
                .parse()
                .ok()
                .filter(|&l: &usize| l > 0)
                .ok_or_else(|| err(0, format!("`{}` is not a line number", field(0))))?;
            let mut f = Vector3::zeros();
            for k in 0..3 {
                let v: f64 = field(k + 1)
                    .parse()
                    .ok()
                    .filter(|v: &f64| v.is_finite() && v.abs() <= MAX_FORCE_N)
                    .ok_or_else(|| {
                        err(
                            k + 1,
                            format!(
                                "{}: `{}` is not a force within ±{MAX_FORCE_N} N",
                                TABLE_HEADER[k + 1],
                                field(k + 1)
                            ),
                        )
                    })?;
                f[k] = v;
            }
            if rows.insert(key, f).is_some() {
                return Err(err(0, format!("line {key} is given twice")));
            }
        }
        if !header_seen {
            return Err(Error::Input(Located::new(
                file,
                1,
                1,
                format!(
                    "empty force table (expected the header `{}`)",
                    TABLE_HEADER.join(",")
                ),
            )));
        }
        Ok(ForceTable { rows })
    }

    /// Reads a table from a file.
    pub fn load(path: &std::path::Path) -> Result<Self> {
        let bytes = crate::limits::read_file_bounded(path, u64::MAX)?;
        let name = path.display().to_string();
        Self::from_csv_str(crate::error::utf8_text(&bytes, &name)?, &name)
    }

    /// Force for a program line, N.
    pub fn get(&self, line: usize) -> Option<Vector3<f64>> {
        self.rows.get(&line).copied()
    }

    /// Number of rows.
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    /// True without rows.
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_rows_and_locates_errors() {
        let t = ForceTable::from_csv_str(
            "line,fx_n,fy_n,fz_n\n3, 1, -2.5, 300\n# note\n9,0,0,1\n",
            "f.csv",
        )
        .unwrap();
        assert_eq!(t.get(3), Some(Vector3::new(1.0, -2.5, 300.0)));
        assert_eq!(t.get(4), None);
        assert_eq!(t.len(), 2);
        let e = ForceTable::from_csv_str("line,fx_n,fy_n,fz_n\n3,1,x2,3\n", "f.csv")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("f.csv:2:5: fy_n: `x2`"), "{e}");
        let e = ForceTable::from_csv_str("line,fx,fy,fz\n", "f.csv")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("f.csv:1:1: expected the header"), "{e}");
        let e = ForceTable::from_csv_str("line,fx_n,fy_n,fz_n\n3,1,2\n", "f.csv")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("f.csv:2:1: expected 4 fields"), "{e}");
        let e = ForceTable::from_csv_str("line,fx_n,fy_n,fz_n\n3,1,2,3\n3,1,2,3\n", "f.csv")
            .unwrap_err()
            .to_string();
        assert!(e.contains("f.csv:3:1: line 3 is given twice"), "{e}");
        assert!(ForceTable::from_csv_str("", "f.csv").is_err());
        assert!(ForceTable::from_csv_str("line,fx_n,fy_n,fz_n\n0,1,2,3\n", "f.csv").is_err());
    }
}
