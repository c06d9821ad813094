//! The CSV tables `verify` reads: one header row of column names that carry
//! their unit, `#` comment lines, empty cells meaning "not given", comma
//! separated. Every column a table may have is declared by the standard
//! that reads it; an unknown or repeated column name, a missing required
//! column, a row of the wrong width or a cell that is not of its column's
//! kind is an error at `file:line:column` naming the column.

use crate::error::{Error, Located, Result, clip};
use crate::limits::OBSERVATION_MAX_ROWS;

/// What a column's cells hold.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// A finite number.
    Number,
    /// A whole number of at least 1 (a run, a cycle).
    Count,
    /// `+1` or `-1` (also `+`, `-`, `1`).
    Sign,
    /// Any text (a label).
    Text,
}

/// A column a table may have.
#[derive(Debug, Clone, Copy)]
pub struct Column {
    /// Its name in the header (with its unit).
    pub name: &'static str,
    /// What its cells hold.
    pub kind: Kind,
    /// Whether the header must name it.
    pub required: bool,
}

impl Column {
    /// A required column.
    pub const fn required(name: &'static str, kind: Kind) -> Self {
        Column {
            name,
            kind,
            required: true,
        }
    }

    /// An optional column.
    pub const fn optional(name: &'static str, kind: Kind) -> Self {
        Column {
            name,
            kind,
            required: false,
        }
    }
}

/// A cell's value.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    /// A number (also counts and signs).
    Number(f64),
    /// Text.
    Text(String),
}

/// One data row: its line and, per declared column, the value and the
/// 1-based byte column of its cell (`None`: column absent or cell empty).
#[derive(Debug, Clone)]
pub struct Row {
    /// 1-based line number in the file.
    pub line: usize,
    cells: Vec<Option<(Value, usize)>>,
}

/// A table read against its column declarations.
#[derive(Debug, Clone)]
pub struct Table {
    /// The file name as errors show it.
    pub file: String,
    /// Line of the header row.
    pub header_line: usize,
    columns: &'static [Column],
    present: Vec<bool>,
    /// The data rows in file order.
    pub rows: Vec<Row>,
}

impl Row {
    /// The value of the declared column `name` (`None`: not given).
    pub fn get(&self, table: &Table, name: &str) -> Option<&Value> {
        let i = table.index(name)?;
        self.cells.get(i)?.as_ref().map(|(v, _)| v)
    }

    /// The number in column `name`, if given.
    pub fn number(&self, table: &Table, name: &str) -> Option<f64> {
        match self.get(table, name) {
            Some(Value::Number(v)) => Some(*v),
            _ => None,
        }
    }

    /// The text in column `name`, if given.
    pub fn text(&self, table: &Table, name: &str) -> Option<&str> {
        match self.get(table, name) {
            Some(Value::Text(t)) => Some(t),
            _ => None,
        }
    }

    /// The 1-based byte column of the cell of `name` (1 when not given).
    pub fn column_of(&self, table: &Table, name: &str) -> usize {
        table
            .index(name)
            .and_then(|i| self.cells.get(i)?.as_ref().map(|(_, c)| *c))
            .unwrap_or(1)
    }

    /// An error located at this row's cell of `name`.
    pub fn error(&self, table: &Table, name: &str, message: impl Into<String>) -> Error {
        Error::Input(Located::new(
            &table.file,
            self.line,
            self.column_of(table, name),
            message,
        ))
    }
}

impl Table {
    fn index(&self, name: &str) -> Option<usize> {
        self.columns.iter().position(|c| c.name == name)
    }

    /// Whether the header names column `name`.
    pub fn has(&self, name: &str) -> bool {
        self.index(name).is_some_and(|i| self.present[i])
    }

    /// An error at the header row.
    pub fn header_error(&self, message: impl Into<String>) -> Error {
        Error::Input(Located::new(&self.file, self.header_line, 1, message))
    }

    /// Reads `text` (file name `file`) against the declared `columns`.
    pub fn parse(text: &str, file: &str, columns: &'static [Column]) -> Result<Table> {
        let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l));
        let (header_line, header) = loop {
            match lines.next() {
                Some((n, l)) if !is_skipped(l) => break (n, l),
                Some(_) => continue,
                None => {
                    return Err(Error::Input(Located::whole_file(
                        file,
                        "no header row: the file holds no table",
                    )));
                }
            }
        };
        let map = parse_header(file, header_line, header, columns)?;
        let mut present = vec![false; columns.len()];
        for &i in &map {
            present[i] = true;
        }
        let mut table = Table {
            file: file.to_string(),
            header_line,
            columns,
            present,
            rows: Vec::new(),
        };
        if let Some(c) = columns
            .iter()
            .enumerate()
            .find(|(i, c)| c.required && !table.present[*i])
        {
            return Err(table.header_error(format!("missing required column `{}`", c.1.name)));
        }
        for (n, l) in lines {
            if is_skipped(l) {
                continue;
            }
            if table.rows.len() >= OBSERVATION_MAX_ROWS {
                return Err(Error::Input(Located::new(
                    file,
                    n,
                    1,
                    format!("more than {OBSERVATION_MAX_ROWS} data rows"),
                )));
            }
            let row = parse_row(file, n, l, columns, &map)?;
            table.rows.push(row);
        }
        if table.rows.is_empty() {
            return Err(table.header_error("no data rows below the header"));
        }
        Ok(table)
    }
}

/// Comment and blank lines.
fn is_skipped(line: &str) -> bool {
    let t = line.trim();
    t.is_empty() || t.starts_with('#')
}

/// The cells of a line with their 1-based byte columns, trimmed.
fn cells(line: &str) -> Vec<(usize, &str)> {
    let line = line.strip_suffix('\r').unwrap_or(line);
    let mut out = Vec::new();
    let mut start = 0;
    for piece in line.split(',') {
        let lead = piece.len() - piece.trim_start().len();
        out.push((start + lead + 1, piece.trim()));
        start += piece.len() + 1;
    }
    out
}

/// Maps each header cell to its declared column.
fn parse_header(
    file: &str,
    line: usize,
    header: &str,
    columns: &'static [Column],
) -> Result<Vec<usize>> {
    let mut map: Vec<usize> = Vec::new();
    for (col, name) in cells(header) {
        let at = |m: String| Error::Input(Located::new(file, line, col, m));
        let Some(i) = columns.iter().position(|c| c.name == name) else {
            let known: Vec<&str> = columns.iter().map(|c| c.name).collect();
            return Err(at(format!(
                "unknown column `{}` (known: {})",
                clip(name),
                known.join(", ")
            )));
        };
        if map.contains(&i) {
            return Err(at(format!("column `{name}` given twice")));
        }
        map.push(i);
    }
    Ok(map)
}

/// Reads one data row.
fn parse_row(
    file: &str,
    line: usize,
    text: &str,
    columns: &'static [Column],
    map: &[usize],
) -> Result<Row> {
    let cs = cells(text);
    if cs.len() != map.len() {
        return Err(Error::Input(Located::new(
            file,
            line,
            1,
            format!(
                "{} cells where the header has {} columns",
                cs.len(),
                map.len()
            ),
        )));
    }
    let mut row = Row {
        line,
        cells: vec![None; columns.len()],
    };
    for ((col, cell), &i) in cs.into_iter().zip(map) {
        if cell.is_empty() {
            continue;
        }
        let c = &columns[i];
        let value = parse_cell(cell, c.kind).map_err(|what| {
            Error::Input(Located::new(
                file,
                line,
                col,
                format!("column `{}`: {what}, found `{}`", c.name, clip(cell)),
            ))
        })?;
        row.cells[i] = Some((value, col));
    }
    Ok(row)
}

/// A cell's value for its column's kind, or what it should be.
fn parse_cell(cell: &str, kind: Kind) -> std::result::Result<Value, &'static str> {
    let number = || {
        cell.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or("expected a finite number")
    };
    match kind {
        Kind::Text => Ok(Value::Text(cell.to_string())),
        Kind::Number => number().map(Value::Number),
        Kind::Count => match cell.parse::<u32>() {
            Ok(n) if n >= 1 => Ok(Value::Number(f64::from(n))),
            _ => Err("expected a whole number of at least 1"),
        },
        Kind::Sign => match cell {
            "+1" | "1" | "+" => Ok(Value::Number(1.0)),
            "-1" | "-" => Ok(Value::Number(-1.0)),
            _ => Err("expected +1 or -1"),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const COLS: &[Column] = &[
        Column::required("target_mm", Kind::Number),
        Column::required("dir", Kind::Sign),
        Column::optional("run", Kind::Count),
        Column::optional("axis", Kind::Text),
    ];

    #[test]
    fn reads_cells_by_name_in_any_order() {
        let t = Table::parse(
            "# c\ndir, target_mm,run\n-1,12.5,3\n\n+1, 0,\n",
            "f.csv",
            COLS,
        )
        .unwrap();
        assert_eq!(t.header_line, 2);
        assert_eq!(t.rows.len(), 2);
        assert_eq!(t.rows[0].number(&t, "target_mm"), Some(12.5));
        assert_eq!(t.rows[0].number(&t, "dir"), Some(-1.0));
        assert_eq!(t.rows[1].number(&t, "run"), None);
        assert_eq!(t.rows[1].line, 5);
        assert_eq!(t.rows[1].column_of(&t, "target_mm"), 5);
        assert!(!t.has("axis"));
    }

    #[test]
    fn errors_are_located_and_name_the_column() {
        let e = Table::parse("target_mm,dirr\n", "f.csv", COLS).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("f.csv:1:11: unknown column `dirr`"),
            "{e}"
        );
        let e = Table::parse("target_mm,dir\n1,x\n", "f.csv", COLS).unwrap_err();
        assert_eq!(
            e.to_string(),
            "f.csv:2:3: column `dir`: expected +1 or -1, found `x`"
        );
        let e = Table::parse("target_mm\n1\n", "f.csv", COLS).unwrap_err();
        assert_eq!(e.to_string(), "f.csv:1:1: missing required column `dir`");
        let e = Table::parse("target_mm,dir\n1\n", "f.csv", COLS).unwrap_err();
        assert!(e.to_string().starts_with("f.csv:2:1: 1 cells"), "{e}");
        let e = Table::parse("target_mm,dir\n1,+1,\n", "f.csv", COLS).unwrap_err();
        assert!(e.to_string().starts_with("f.csv:2:1: 3 cells"), "{e}");
        let e = Table::parse("target_mm,dir\nNaN,1\n", "f.csv", COLS).unwrap_err();
        assert!(e.to_string().contains("finite number"), "{e}");
        let e = Table::parse("target_mm,dir,run\n1,1,0\n", "f.csv", COLS).unwrap_err();
        assert!(e.to_string().starts_with("f.csv:2:5:"), "{e}");
        let e = Table::parse("target_mm,dir,dir\n", "f.csv", COLS).unwrap_err();
        assert!(e.to_string().contains("given twice"), "{e}");
        let e = Table::parse("# only\n", "f.csv", COLS).unwrap_err();
        assert!(e.to_string().contains("no header"), "{e}");
        let e = Table::parse("target_mm,dir\n", "f.csv", COLS).unwrap_err();
        assert!(e.to_string().contains("no data rows"), "{e}");
    }
}
