//! Deviation reports (dry run and `--report`): a row per motion block and a
//! summary, as an aligned table, CSV or JSON, streamed row by row.

use std::io::Write;

use crate::cli::Format;
use crate::error::{Error, Result};
use crate::job::{Row, Summary};
use crate::machine::AXIS_LETTERS;
use crate::predict::Effect;
use crate::program::interp::Setup;

/// Streams report rows to a writer.
pub struct ReportWriter<'w> {
    out: &'w mut dyn Write,
    format: Format,
    axes: Vec<usize>,
    rows: usize,
    file: String,
}

fn io(e: std::io::Error) -> Error {
    Error::io("report", e)
}

fn num(v: f64, d: usize) -> String {
    crate::emit::gcode::format_number(v, d, false)
        .trim_end_matches('.')
        .to_string()
}

/// One aligned table line: the motion column left-aligned, numbers right.
fn table_line(cells: &[String]) -> String {
    let cells: Vec<String> = cells
        .iter()
        .enumerate()
        .map(|(i, c)| {
            if i == 1 {
                format!("{c:<7}")
            } else {
                format!("{c:>12}")
            }
        })
        .collect();
    cells.join(" ")
}

fn json_str(s: &str) -> String {
    serde_json::to_string(s).unwrap_or_else(|_| "\"\"".into())
}

impl<'w> ReportWriter<'w> {
    /// Starts a report (writes the header).
    pub fn new(out: &'w mut dyn Write, setup: &Setup, format: Format, file: &str) -> Result<Self> {
        let axes: Vec<usize> = (0..6).filter(|&s| setup.axes[s]).collect();
        let w = ReportWriter {
            out,
            format,
            axes,
            rows: 0,
            file: file.to_string(),
        };
        let mut cols: Vec<String> = vec!["line".into(), "motion".into()];
        for &s in &w.axes {
            cols.push(format!(
                "{}_{}",
                AXIS_LETTERS[s] as char,
                if s < 3 { "mm" } else { "deg" }
            ));
        }
        for c in ["dx_mm", "dy_mm", "dz_mm", "dev_mm"] {
            cols.push(c.into());
        }
        for e in Effect::ALL {
            cols.push(format!("{}_mm", e.name()));
        }
        cols.push("residual_mm".into());
        cols.push("orient_urad".into());
        match format {
            Format::Csv => writeln!(w.out, "{}", cols.join(",")).map_err(io)?,
            Format::Table => writeln!(w.out, "{}", table_line(&cols)).map_err(io)?,
            Format::Json => {
                write!(w.out, "{{\"file\":{},\"rows\":[", json_str(&w.file)).map_err(io)?
            }
        }
        Ok(w)
    }

    /// Writes one row.
    pub fn row(&mut self, r: &Row) -> Result<()> {
        let dev = r.result.deviation.total();
        let mut vals: Vec<String> = vec![r.line.to_string(), r.motion.to_string()];
        for &s in &self.axes {
            vals.push(num(r.commanded[s], 4));
        }
        for v in [dev[0], dev[1], dev[2], dev.norm()] {
            vals.push(num(v, 5));
        }
        for e in Effect::ALL {
            vals.push(num(r.result.deviation.parts[e as usize].norm(), 5));
        }
        vals.push(num(r.result.residual_mm, 6));
        // Tool-axis direction error: a three-axis machine cannot correct it.
        vals.push(num(r.result.deviation.orientation.norm() * 1e6, 2));
        match self.format {
            Format::Csv => writeln!(self.out, "{}", vals.join(",")).map_err(io)?,
            Format::Table => writeln!(self.out, "{}", table_line(&vals)).map_err(io)?,
            Format::Json => {
                let mut o = format!(
                    "{}{{\"line\":{},\"motion\":{},\"commanded\":{{",
                    if self.rows > 0 { "," } else { "" },
                    r.line,
                    json_str(r.motion)
                );
                let parts: Vec<String> = self
                    .axes
                    .iter()
                    .map(|&s| format!("\"{}\":{}", AXIS_LETTERS[s] as char, num(r.commanded[s], 4)))
                    .collect();
                o.push_str(&parts.join(","));
                o.push_str(&format!(
                    "}},\"deviation_mm\":[{},{},{}],\"dev_mm\":{},\"effects_mm\":{{",
                    num(dev[0], 5),
                    num(dev[1], 5),
                    num(dev[2], 5),
                    num(dev.norm(), 5)
                ));
                let parts: Vec<String> = Effect::ALL
                    .iter()
                    .map(|&e| {
                        format!(
                            "\"{}\":{}",
                            e.name(),
                            num(r.result.deviation.parts[e as usize].norm(), 5)
                        )
                    })
                    .collect();
                o.push_str(&parts.join(","));
                o.push_str(&format!(
                    "}},\"residual_mm\":{},\"orient_urad\":{}}}",
                    num(r.result.residual_mm, 6),
                    num(r.result.deviation.orientation.norm() * 1e6, 2)
                ));
                self.out.write_all(o.as_bytes()).map_err(io)?;
            }
        }
        self.rows += 1;
        Ok(())
    }

    /// Writes the summary and ends the report.
    pub fn finish(self, s: &Summary) -> Result<()> {
        let d = &s.deviation;
        match self.format {
            Format::Json => {
                writeln!(
                    self.out,
                    "],\"summary\":{{\"blocks\":{},\"moves\":{},\"rows\":{},\"mean_mm\":{},\"max_mm\":{},\"max_line\":{},\"p95_mm\":{}}}}}",
                    s.blocks,
                    s.moves,
                    self.rows,
                    num(d.mean(), 5),
                    num(d.max, 5),
                    d.max_line,
                    num(d.percentile(95.0), 5)
                )
                .map_err(io)?;
            }
            Format::Csv | Format::Table => {
                let prefix = if self.format == Format::Csv { "# " } else { "" };
                writeln!(
                    self.out,
                    "{prefix}summary: {} rows; |dev| mean {} mm, max {} mm (line {}), p95 {} mm",
                    self.rows,
                    num(d.mean(), 5),
                    num(d.max, 5),
                    d.max_line,
                    num(d.percentile(95.0), 5)
                )
                .map_err(io)?;
            }
        }
        Ok(())
    }
}
