//! Deviation reports (`postproc report`, `compensate --report`): a row per
//! motion block or robot move with its per-effect breakdown, and a summary
//! per effect (mean, 95th percentile, maximum, worst blocks with their source
//! line), as an aligned table, CSV, JSON (schema: `schemas/report.schema.json`),
//! an SVG picture or an interactive HTML page ([`crate::emit::html`]).
//!
//! Rows are streamed: the text formats write each row as it comes, the
//! statistics use a fixed-size histogram, and the picture keeps a bounded,
//! deterministically decimated set of points ([`crate::emit::svg::Decimator`]).
//! G-code and RAPID reports share the writer through [`Layout`] and [`Entry`].

use std::io::Write;

use crate::compensate::outcome::{DevStats, RobotMove, Row};
pub use crate::emit::html::Shape;
use crate::emit::svg::{Decimator, PlotPoint, Worst as PlotWorst};
use crate::error::{Error, Result};
use crate::machine::AXIS_LETTERS;
use crate::predict::Effect;
use crate::program::interp::Setup;
use crate::program::rapid::MoveKind;
use crate::program::rapid::instructions::motion_instruction;

/// Report formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// Aligned text table.
    Table,
    /// Comma-separated values.
    Csv,
    /// JSON document (schema: schemas/report.schema.json).
    Json,
    /// SVG picture: toolpath in plan and side view coloured by deviation,
    /// deviation along the program.
    Svg,
    /// Self-contained HTML page: plan, side and 3-D views, the predicted
    /// path magnified, each block's parts on hover.
    Html,
}

impl Format {
    /// The format a report path asks for by its extension (`.csv`, `.json`,
    /// `.svg`, `.html`, `.txt`); CSV for any other.
    pub fn from_path(path: &std::path::Path) -> Format {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase());
        match ext.as_deref() {
            Some("json") => Format::Json,
            Some("svg") => Format::Svg,
            Some("html" | "htm") => Format::Html,
            Some("txt" | "text" | "table") => Format::Table,
            _ => Format::Csv,
        }
    }
}

/// Smallest deviation listed among the worst blocks, mm: half the last
/// printed digit (values below print as 0.00000).
pub const LISTED_MIN_MM: f64 = 0.5e-5;

/// Worst blocks listed per effect in the summary.
pub const WORST_BLOCKS: usize = 5;

/// What the columns of a report are.
#[derive(Debug, Clone, PartialEq)]
pub struct Layout {
    /// Program kind: `gcode` or `rapid`.
    pub kind: &'static str,
    /// Position columns: name and unit (`("X", "mm")`).
    pub axes: Vec<(String, &'static str)>,
    /// Effect names in breakdown order.
    pub effects: Vec<&'static str>,
    /// Rows carry the position error left after compensation.
    pub residual: bool,
    /// G-code: axis slot (0..6) of each position column.
    slots: Vec<usize>,
    /// The report covers several files (the modules of a RAPID program):
    /// rows and worst blocks name their file ([`ReportWriter::file`]).
    pub files: bool,
}

impl Layout {
    /// A G-code report: the machine's axes and [`Effect::TOOL`].
    pub fn gcode(setup: &Setup) -> Self {
        Layout {
            kind: "gcode",
            axes: (0..6)
                .filter(|&s| setup.axes.get(s).copied().unwrap_or(false))
                .map(|s| {
                    (
                        (AXIS_LETTERS[s] as char).to_string(),
                        if s < 3 { "mm" } else { "deg" },
                    )
                })
                .collect(),
            effects: Effect::TOOL.iter().map(|e| e.name()).collect(),
            residual: true,
            slots: (0..6)
                .filter(|&s| setup.axes.get(s).copied().unwrap_or(false))
                .collect(),
            files: false,
        }
    }

    /// A RAPID report: programmed TCP position in the world frame and the
    /// robot effects (kinematic, gravity, process).
    pub fn rapid() -> Self {
        Layout {
            kind: "rapid",
            axes: ["X", "Y", "Z"]
                .iter()
                .map(|a| (a.to_string(), "mm"))
                .collect(),
            effects: vec!["kinematic", "thermal", "gravity", "process", "dynamic"],
            residual: false,
            slots: vec![0, 1, 2],
            files: false,
        }
    }

    /// The same layout for a report of several files: a `file` column
    /// before `line`, and every line named with its file.
    pub fn with_files(mut self) -> Self {
        self.files = true;
        self
    }
}

/// One report row, whatever the program kind.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Entry<'a> {
    /// 1-based source line.
    pub line: usize,
    /// Motion label (`feed`, `rapid`, `MoveL`, …).
    pub motion: &'a str,
    /// Values of the [`Layout::axes`] columns.
    pub axes: &'a [f64],
    /// Programmed tool-tip position for the picture (X, Y, Z), mm.
    pub position_mm: [f64; 3],
    /// Predicted deviation vector (attained − programmed), mm.
    pub deviation_mm: [f64; 3],
    /// Length of each effect's deviation, in [`Layout::effects`] order, mm.
    pub effects_mm: &'a [f64],
    /// Position error left after compensation, mm (when the layout has it).
    pub residual_mm: Option<f64>,
    /// Tool-axis direction error, µrad.
    pub orient_urad: f64,
    /// Programmed start of the move (`None`: where the previous row ended).
    pub start_mm: Option<[f64; 3]>,
    /// How the move is drawn (HTML page).
    pub shape: Shape,
    /// Circle point of a `MoveC`: drawn as the arc through it.
    pub via_mm: Option<[f64; 3]>,
}

/// Counts for the summary.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Totals {
    /// Blocks (G-code) or motion instructions (RAPID).
    pub blocks: usize,
    /// Moves.
    pub moves: usize,
}

/// Statistics of |deviation| of one effect (or the total): the histogram
/// statistics of [`DevStats`] (mean, percentiles) and the worst blocks.
#[derive(Debug, Clone)]
struct Stat {
    hist: DevStats,
    /// Worst blocks, largest first: (value, line, motion, file index).
    worst: Vec<(f64, usize, String, usize)>,
}

impl Stat {
    fn new() -> Self {
        Stat {
            hist: DevStats::default(),
            worst: Vec::with_capacity(WORST_BLOCKS + 1),
        }
    }

    fn add(&mut self, v: f64, (line, file): (usize, usize), motion: &str) {
        let v = if v.is_finite() { v.abs() } else { 0.0 };
        self.hist.add(v, line);
        // Ties keep the earlier block; blocks whose deviation prints as zero
        // (below half the last printed digit) are not listed.
        if v < LISTED_MIN_MM {
            return;
        }
        let at = self.worst.iter().position(|w| v > w.0);
        match at {
            Some(i) => {
                self.worst.insert(i, (v, line, motion.to_string(), file));
                self.worst.truncate(WORST_BLOCKS);
            }
            None if self.worst.len() < WORST_BLOCKS => {
                self.worst.push((v, line, motion.to_string(), file));
            }
            None => {}
        }
    }

    fn mean(&self) -> f64 {
        self.hist.mean()
    }

    fn max(&self) -> f64 {
        self.worst.first().map_or(0.0, |w| w.0)
    }

    fn max_line(&self) -> usize {
        self.worst.first().map_or(0, |w| w.1)
    }

    /// File index and line of the maximum.
    fn max_at(&self) -> (usize, usize) {
        self.worst.first().map_or((0, 0), |w| (w.3, w.1))
    }

    fn percentile(&self, p: f64) -> f64 {
        self.hist.percentile(p)
    }
}

/// Streams report rows to a writer.
pub struct ReportWriter<'w> {
    out: &'w mut dyn Write,
    format: Format,
    layout: Layout,
    rows: usize,
    file: String,
    /// Index 0: total; then one per effect.
    stats: Vec<Stat>,
    /// |deviation| of the cutting moves, and of rapids and moves to
    /// machine-defined places (G28, G53; RAPID MoveJ, MoveAbsJ).
    cutting: Stat,
    positioning: Stat,
    /// Robot programs with a process effect: the linear and circular moves
    /// under process force, and the positioning moves with the linear ones
    /// in air (approach, retract). When the program has process moves,
    /// they are the headline's group ([`Self::process_split`]).
    process: Stat,
    positioning_and_air: Stat,
    /// The `process` effect's index in the rows' effects (robot reports).
    process_effect: Option<usize>,
    /// The headline is on the process moves (set when the report ends).
    process_split: bool,
    plot: Option<Decimator>,
    /// The last position of the picture's moves.
    plot_end: Option<[f64; 3]>,
    /// The moves of an HTML page.
    html: Option<crate::emit::html::Collector>,
    /// Largest deviation of all moves, and of the cutting moves.
    worst_point: Option<PlotWorst>,
    worst_cut: Option<PlotWorst>,
    /// The files of the two marks.
    worst_point_file: usize,
    worst_cut_file: usize,
    /// The program file, re-read at the end for the text of the worst blocks.
    source: Option<std::path::PathBuf>,
    /// With [`Layout::files`]: the files rows were written for (name, file
    /// to re-read), the last one current.
    files: Vec<(String, Option<std::path::PathBuf>)>,
    /// What made the run (machine file, effects, tolerance).
    provenance: Option<crate::emit::header::Provenance>,
    /// Widths of the table's columns.
    widths: Vec<usize>,
    /// The header is still to be written (at the first row or the end, so
    /// that the provenance decides the uncertainty columns).
    header_due: bool,
    /// The uncertainty of the rows (G-code reports of a machine file with
    /// a parameter covariance; from the provenance).
    uncertainty: Option<std::sync::Arc<crate::predict::uncertainty::BlockUncertainty>>,
    /// The uncertainty of the row being written.
    row_u: Option<crate::predict::uncertainty::BlockU>,
    /// Largest U of the cutting moves: U, (line, file).
    worst_u: Option<(f64, (usize, usize))>,
}

/// Longest source text quoted for a worst block, characters.
const SOURCE_CHARS: usize = 72;

/// The text of the given 1-based lines of a file (trimmed, shortened); lines
/// that cannot be read are left out.
fn source_lines(
    path: &std::path::Path,
    wanted: &std::collections::BTreeSet<usize>,
) -> std::collections::BTreeMap<usize, String> {
    use std::io::BufRead;
    let mut found = std::collections::BTreeMap::new();
    let Some(&last) = wanted.last() else {
        return found;
    };
    let Ok(f) = std::fs::File::open(path) else {
        tracing::debug!("{}: cannot re-read for the worst blocks", path.display());
        return found;
    };
    let mut r = std::io::BufReader::new(f);
    let mut buf = Vec::new();
    for line in 1..=last {
        buf.clear();
        match r.read_until(b'\n', &mut buf) {
            Ok(0) | Err(_) => break,
            Ok(_) => {}
        }
        if wanted.contains(&line) {
            let text = String::from_utf8_lossy(&buf);
            let text = text.trim();
            let short: String = text.chars().take(SOURCE_CHARS).collect();
            let short = if short.len() < text.len() {
                format!("{short}…")
            } else {
                short
            };
            found.insert(line, short);
        }
    }
    found
}

fn io(e: std::io::Error) -> Error {
    Error::io("report", e)
}

/// A number with `d` decimals, no exponent, no `-0`.
fn num(v: f64, d: usize) -> String {
    if !v.is_finite() {
        return "nan".into();
    }
    crate::emit::gcode::format_number(v, d, false)
        .trim_end_matches('.')
        .to_string()
}

/// A JSON number with `d` decimals (`null` when not finite).
fn jnum(v: f64, d: usize) -> String {
    if v.is_finite() {
        num(v, d)
    } else {
        "null".into()
    }
}

/// Widest line of a table report, characters.
pub const TABLE_COLUMNS: usize = 120;

/// Width of the table's `line` column.
const LINE_W: usize = 6;
/// Width of the table's `motion` column.
const MOTION_W: usize = 8;

/// Width of the table's `file` column (a report of several files).
const FILE_W: usize = 16;

/// A CSV cell: quoted when it holds a comma, a quote or a line break.
fn csv_cell(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// Mean, maximum and the (file, line) of the maximum of all moves.
type Overall = (f64, f64, (usize, usize));

/// Source texts of worst blocks by (file index, line).
type Texts = std::collections::BTreeMap<(usize, usize), String>;
/// Width of a position column of the table (3 decimals: `-1234.567`).
const AXIS_W: usize = 9;
/// Narrowest deviation column of the table (5 decimals: `12.34567`).
const DEV_W: usize = 8;
/// Decimals of the table's position columns (1 µm; CSV and JSON keep 4).
const TABLE_AXIS_DECIMALS: usize = 3;

/// One aligned table line: the motion column (and the file column of a
/// report of several files) left-aligned, numbers right,
/// each cell at least its column's width.
fn table_line(cells: &[String], widths: &[usize], files: bool) -> String {
    let mut line = String::with_capacity(TABLE_COLUMNS);
    let motion = if files { 2 } else { 1 };
    for (i, c) in cells.iter().enumerate() {
        let w = widths.get(i).copied().unwrap_or(DEV_W);
        if i > 0 {
            line.push(' ');
        }
        if i == motion || files && i == 0 {
            line.push_str(&format!("{c:<w$}"));
        } else {
            line.push_str(&format!("{c:>w$}"));
        }
    }
    line
}

fn json_str(s: &str) -> String {
    serde_json::to_string(s).unwrap_or_else(|_| "\"\"".into())
}

/// Label of statistic `i` (0 total, then the effects).
fn stat_name(layout: &Layout, i: usize) -> &str {
    if i == 0 {
        "total"
    } else {
        layout.effects.get(i - 1).copied().unwrap_or("?")
    }
}

/// Whether a motion is a positioning move (rapid, machine-defined place,
/// RAPID joint move) rather than a cutting move.
fn is_positioning(motion: &str) -> bool {
    matches!(motion, "rapid" | "fixed")
        || motion_instruction(motion)
            .is_some_and(|m| matches!(m.kind, MoveKind::MoveJ | MoveKind::MoveAbsJ))
}

/// The statistics of one group of moves as a JSON object.
fn group_json(w: &ReportWriter, s: &Stat, texts: &Texts) -> String {
    format!(
        "{{\"moves\":{},\"mean_mm\":{},\"p95_mm\":{},\"max_mm\":{},\"max_line\":{}{},\"worst\":[{}]}}",
        s.hist.count,
        jnum(s.mean(), 5),
        jnum(s.percentile(95.0), 5),
        jnum(s.max(), 5),
        s.max_line(),
        max_file_json(w, s),
        worst_json(w, s, texts)
    )
}

/// The worst blocks of `s` as JSON objects, comma-separated.
fn worst_json(w: &ReportWriter, s: &Stat, texts: &Texts) -> String {
    let worst: Vec<String> = s
        .worst
        .iter()
        .map(|(v, line, motion, file)| {
            let source = texts
                .get(&(*file, *line))
                .map(|t| format!(",\"source\":{}", json_str(t)))
                .unwrap_or_default();
            format!(
                "{{\"line\":{line},\"motion\":{},\"dev_mm\":{}{source}{}}}",
                json_str(motion),
                jnum(*v, 5),
                w.json_file(*file)
            )
        })
        .collect();
    worst.join(",")
}

/// `,"max_file":…` (the file of `max_line`) in a report of several files.
fn max_file_json(w: &ReportWriter, s: &Stat) -> String {
    if s.worst.is_empty() {
        return String::new();
    }
    w.json_file(s.max_at().0)
        .replacen("\"file\"", "\"max_file\"", 1)
}

/// Points kept for the picture, whatever the program length.
pub const PLOT_POINTS: usize = 4000;

impl<'w> ReportWriter<'w> {
    /// Starts a report for a G-code program (its header is written with
    /// the first row).
    pub fn new(out: &'w mut dyn Write, setup: &Setup, format: Format, file: &str) -> Result<Self> {
        Self::with_layout(out, Layout::gcode(setup), format, file)
    }

    /// Starts a report with the given columns (its header is written with
    /// the first row, or at the end).
    pub fn with_layout(
        out: &'w mut dyn Write,
        layout: Layout,
        format: Format,
        file: &str,
    ) -> Result<Self> {
        let stats = (0..=layout.effects.len()).map(|_| Stat::new()).collect();
        let process_effect = (layout.kind == "rapid")
            .then(|| layout.effects.iter().position(|e| *e == "process"))
            .flatten();
        let w = ReportWriter {
            out,
            format,
            layout,
            rows: 0,
            file: file.to_string(),
            stats,
            cutting: Stat::new(),
            positioning: Stat::new(),
            process: Stat::new(),
            positioning_and_air: Stat::new(),
            process_effect,
            process_split: false,
            plot: (format == Format::Svg).then(|| Decimator::new(PLOT_POINTS)),
            html: (format == Format::Html).then(Default::default),
            plot_end: None,
            worst_point: None,
            worst_cut: None,
            worst_point_file: 0,
            worst_cut_file: 0,
            source: None,
            files: Vec::new(),
            provenance: None,
            widths: Vec::new(),
            header_due: true,
            uncertainty: None,
            row_u: None,
            worst_u: None,
        };
        Ok(w)
    }

    /// The effects the rows state an uncertainty for (empty: no U columns).
    fn u_effects(&self) -> Vec<&'static str> {
        match &self.uncertainty {
            Some(u) => u.effects(),
            _ => Vec::new(),
        }
    }

    /// Writes the header of the table, CSV or JSON report once.
    fn write_header(&mut self) -> Result<()> {
        if !std::mem::replace(&mut self.header_due, false) {
            return Ok(());
        }
        let w = self;
        let u_effects = w.u_effects();
        let format = w.format;
        // The table keeps the columns a reader scans (where, how far off,
        // which effect); the components, the residual and the tool-axis
        // error are in CSV and JSON.
        let mut table: Vec<String> = vec!["line".into(), "motion".into()];
        w.widths = vec![LINE_W, MOTION_W];
        if w.layout.files {
            table.insert(0, "file".into());
            w.widths.insert(0, FILE_W);
        }
        for (a, unit) in &w.layout.axes {
            table.push(format!("{a}_{unit}"));
            w.widths.push(AXIS_W);
        }
        table.push("dev_mm".into());
        w.widths.push(DEV_W);
        if !u_effects.is_empty() {
            table.push("U_mm".into());
            w.widths.push(DEV_W);
        }
        for e in &w.layout.effects {
            let name = format!("{e}_mm");
            w.widths.push(name.len().max(DEV_W));
            table.push(name);
        }
        let mut cols: Vec<String> = vec!["line".into(), "motion".into()];
        if w.layout.files {
            cols.insert(0, "file".into());
        }
        for (a, unit) in &w.layout.axes {
            cols.push(format!("{a}_{unit}"));
        }
        for c in ["dx_mm", "dy_mm", "dz_mm", "dev_mm"] {
            cols.push(c.into());
        }
        if !u_effects.is_empty() {
            cols.push("u_mm".into());
        }
        for e in &w.layout.effects {
            cols.push(format!("{e}_mm"));
        }
        cols.extend(u_effects.iter().map(|e| format!("u_{e}_mm")));
        if w.layout.residual {
            cols.push("residual_mm".into());
        }
        cols.push("orient_urad".into());
        match format {
            Format::Csv => writeln!(w.out, "{}", cols.join(",")).map_err(io)?,
            Format::Table => {
                writeln!(w.out, "{}", table_line(&table, &w.widths, w.layout.files)).map_err(io)?
            }
            Format::Json => {
                let effects: Vec<String> = w.layout.effects.iter().map(|e| json_str(e)).collect();
                let axes: Vec<String> = w
                    .layout
                    .axes
                    .iter()
                    .map(|(a, u)| format!("{{\"name\":{},\"unit\":{}}}", json_str(a), json_str(u)))
                    .collect();
                write!(
                    w.out,
                    "{{\"file\":{},\"kind\":{},\"axes\":[{}],\"positions\":{},\"effects\":[{}],\"rows\":[",
                    json_str(&w.file),
                    json_str(w.layout.kind),
                    axes.join(","),
                    json_str(w.positions_frame()),
                    effects.join(",")
                )
                .map_err(io)?
            }
            Format::Svg | Format::Html => {}
        }
        Ok(())
    }

    /// Quotes the source text of the worst blocks from this file (re-read at
    /// the end; not for standard input).
    pub fn with_source(mut self, path: &std::path::Path) -> Self {
        if path != std::path::Path::new("-") {
            self.source = Some(path.to_path_buf());
        }
        self
    }

    /// With [`Layout::files`]: the rows that follow are of the file named
    /// `name` (its text re-read from `path` at the end for the worst
    /// blocks; `None`: not quoted).
    pub fn file(&mut self, name: &str, path: Option<&std::path::Path>) {
        self.files
            .push((name.to_string(), path.map(std::path::Path::to_path_buf)));
    }

    /// The index of the current file.
    fn current(&self) -> usize {
        self.files.len().saturating_sub(1)
    }

    /// A line as the summary names it: `12`, or `Main.mod:12` in a report
    /// of several files.
    fn place(&self, (file, line): (usize, usize)) -> String {
        match self.files.get(file) {
            Some((name, _)) if self.layout.files => format!("{name}:{line}"),
            _ => line.to_string(),
        }
    }

    /// `,"file":…` of a JSON object in a report of several files.
    fn json_file(&self, file: usize) -> String {
        match self.files.get(file) {
            Some((name, _)) if self.layout.files => format!(",\"file\":{}", json_str(name)),
            _ => String::new(),
        }
    }

    /// Records what made the run in the report (CSV and table: a comment
    /// line at the end; JSON: `provenance`).
    pub fn with_provenance(mut self, provenance: Option<&crate::emit::header::Provenance>) -> Self {
        self.provenance = provenance.cloned();
        self.uncertainty = provenance.and_then(|p| p.uncertainty.clone());
        self
    }

    /// Writes the row of a motion block or instruction: a G-code block's
    /// effects, or a robot move's ([`ReportWriter::robot_row`]).
    pub fn row(&mut self, r: &Row) -> Result<()> {
        if let Some(robot) = &r.robot {
            return self.robot_row(r, robot);
        }
        let mut axes = [0.0; 6];
        let mut n = 0;
        for (x, &slot) in axes.iter_mut().zip(&self.layout.slots) {
            *x = r.commanded.get(slot).copied().unwrap_or(0.0);
            n += 1;
        }
        let mut effects = [0.0; Effect::TOOL.len()];
        for (e, v) in Effect::TOOL.iter().zip(effects.iter_mut()) {
            *v = r.result.deviation.part(*e).norm();
        }
        let dev = r.result.deviation.total();
        // The tip's U at the spindle nose: the identified values are
        // translations and axis orientations, which the tool's length does
        // not lever.
        self.row_u = self
            .uncertainty
            .as_ref()
            .and_then(|u| u.tool(&r.commanded, &r.result.dirs, 0.0, &dev));
        let shape = match (&r.arc, r.motion) {
            (Some(arc), _) => Shape::of_arc(arc),
            (None, "cycle") => Shape::Hole,
            _ => Shape::Line,
        };
        self.entry(&Entry {
            line: r.line,
            motion: r.motion,
            axes: &axes[..n],
            start_mm: Some([r.start[0], r.start[1], r.start[2]]),
            shape,
            via_mm: None,
            position_mm: [r.commanded[0], r.commanded[1], r.commanded[2]],
            deviation_mm: [dev[0], dev[1], dev[2]],
            effects_mm: &effects,
            residual_mm: Some(r.result.residual_mm),
            // Tool-axis direction error: a three-axis machine cannot correct it.
            orient_urad: r.result.deviation.total.rot_rad.norm() * 1e6,
        })
    }

    /// The row of a robot move: the kinematic, thermal, gravity, process
    /// and dynamic (vibration) parts of its predicted deviation
    /// ([`Layout::rapid`]).
    fn robot_row(&mut self, r: &Row, t: &RobotMove) -> Result<()> {
        let d = &t.deviation;
        let programmed_mm = [r.commanded[0], r.commanded[1], r.commanded[2]];
        self.row_u = self
            .uncertainty
            .as_ref()
            .zip(t.q_rad)
            .and_then(|(u, q)| u.robot(&q, &d.total.pos_mm));
        self.entry(&Entry {
            line: r.line,
            motion: r.motion,
            axes: &programmed_mm,
            start_mm: None,
            shape: Shape::Line,
            via_mm: t.via_mm,
            position_mm: programmed_mm,
            deviation_mm: d.total.pos_mm.into(),
            effects_mm: &[
                d.kinematic.pos_mm.norm(),
                d.thermal.pos_mm.norm(),
                d.gravity.pos_mm.norm(),
                d.process.pos_mm.norm(),
                d.vibration_mm.norm(),
            ],
            residual_mm: None,
            orient_urad: d.total.rot_rad.norm() * 1e6,
        })
    }

    /// Writes one row.
    pub fn entry(&mut self, r: &Entry) -> Result<()> {
        self.write_header()?;
        let [dx, dy, dz] = r.deviation_mm;
        let dev = (dx * dx + dy * dy + dz * dz).sqrt();
        let file = self.current();
        let at = (r.line, file);
        let u = self.row_u.take().filter(|_| !self.u_effects().is_empty());
        if let (Some(u), false) = (&u, is_positioning(r.motion)) {
            if self.worst_u.is_none_or(|w| u.total_mm > w.0) {
                self.worst_u = Some((u.total_mm, at));
            }
        }
        if let Some(s) = self.stats.first_mut() {
            s.add(dev, at, r.motion);
        }
        for (s, &v) in self.stats.iter_mut().skip(1).zip(r.effects_mm) {
            s.add(v, at, r.motion);
        }
        let rapid = is_positioning(r.motion);
        if rapid {
            self.positioning.add(dev, at, r.motion);
        } else {
            self.cutting.add(dev, at, r.motion);
        }
        self.add_process(r, dev, at, rapid);
        let file_cell = match self.files.get(file) {
            Some((name, _)) if self.layout.files => Some(name.clone()),
            _ => None,
        };
        let u_total = u.as_ref().map(|u| u.total_mm);
        if let Some(c) = self.html.as_mut() {
            c.push(&crate::emit::html::Move {
                at: (r.line, file),
                motion: r.motion,
                start: r.start_mm,
                via: r.via_mm,
                end: r.position_mm,
                dev: r.deviation_mm,
                effects: r.effects_mm,
                residual: r.residual_mm,
                orient_urad: r.orient_urad,
                shape: r.shape,
                u: u_total,
            });
        }
        match self.format {
            Format::Html => self.mark(r, dev, rapid, u_total),
            Format::Svg => {
                let mut parts = [0.0; crate::emit::html::MAX_EFFECTS];
                for (p, v) in parts.iter_mut().zip(r.effects_mm) {
                    *p = *v;
                }
                let start = r.start_mm.or(self.plot_end);
                let p = PlotPoint {
                    line: r.line,
                    pos: r.position_mm,
                    dev,
                    rapid,
                    residual: r.residual_mm,
                    start,
                    shape: match (r.via_mm, start) {
                        (Some(via), Some(s)) => Shape::through(s, via, r.position_mm),
                        _ => r.shape,
                    },
                    parts,
                };
                self.plot_end = Some(r.position_mm);
                if let Some(plot) = self.plot.as_mut() {
                    plot.push(p);
                }
                self.mark(r, dev, rapid, u_total);
            }
            Format::Table | Format::Csv | Format::Json => {
                self.text_row(r, dev, file_cell.as_deref(), u.as_ref())?;
            }
        }
        self.rows += 1;
        Ok(())
    }

    /// A row of the table, CSV or JSON report, with its U (`u`; the U
    /// columns empty without one when the report has them).
    fn text_row(
        &mut self,
        r: &Entry,
        dev: f64,
        file_cell: Option<&str>,
        u: Option<&crate::predict::uncertainty::BlockU>,
    ) -> Result<()> {
        let [dx, dy, dz] = r.deviation_mm;
        let u_cols = !self.u_effects().is_empty();
        match self.format {
            Format::Table => {
                let mut vals: Vec<String> = vec![r.line.to_string(), r.motion.to_string()];
                if let Some(f) = file_cell {
                    vals.insert(0, f.to_string());
                }
                for &v in r.axes {
                    vals.push(num(v, TABLE_AXIS_DECIMALS));
                }
                vals.push(num(dev, 5));
                match u {
                    Some(u) => vals.push(num(u.total_mm, 5)),
                    None if u_cols => vals.push("-".into()),
                    None => {}
                }
                for &v in r.effects_mm {
                    vals.push(num(v, 5));
                }
                writeln!(
                    self.out,
                    "{}",
                    table_line(&vals, &self.widths, self.layout.files)
                )
                .map_err(io)?;
            }
            Format::Csv => {
                let mut vals: Vec<String> = vec![r.line.to_string(), r.motion.to_string()];
                if let Some(f) = file_cell {
                    vals.insert(0, csv_cell(f));
                }
                for &v in r.axes {
                    vals.push(num(v, 4));
                }
                for v in [dx, dy, dz, dev] {
                    vals.push(num(v, 5));
                }
                match u {
                    Some(u) => vals.push(num(u.total_mm, 5)),
                    None if u_cols => vals.push(String::new()),
                    None => {}
                }
                for &v in r.effects_mm {
                    vals.push(num(v, 5));
                }
                match u {
                    Some(u) => vals.extend(u.effects_mm.iter().map(|v| num(*v, 5))),
                    None if u_cols => vals.extend(self.u_effects().iter().map(|_| String::new())),
                    None => {}
                }
                if let Some(res) = r.residual_mm {
                    vals.push(num(res, 6));
                }
                vals.push(num(r.orient_urad, 2));
                writeln!(self.out, "{}", vals.join(",")).map_err(io)?;
            }
            Format::Json => {
                let mut o = format!(
                    "{}{{{}\"line\":{},\"motion\":{},\"commanded\":{{",
                    if self.rows > 0 { "," } else { "" },
                    file_cell
                        .map(|f| format!("\"file\":{},", json_str(f)))
                        .unwrap_or_default(),
                    r.line,
                    json_str(r.motion)
                );
                let parts: Vec<String> = self
                    .layout
                    .axes
                    .iter()
                    .zip(r.axes)
                    .map(|((a, _), &v)| format!("{}:{}", json_str(a), jnum(v, 4)))
                    .collect();
                o.push_str(&parts.join(","));
                o.push_str(&format!(
                    "}},\"deviation_mm\":[{},{},{}],\"dev_mm\":{},\"effects_mm\":{{",
                    jnum(dx, 5),
                    jnum(dy, 5),
                    jnum(dz, 5),
                    jnum(dev, 5)
                ));
                let parts: Vec<String> = self
                    .layout
                    .effects
                    .iter()
                    .zip(r.effects_mm)
                    .map(|(e, &v)| format!("{}:{}", json_str(e), jnum(v, 5)))
                    .collect();
                o.push_str(&parts.join(","));
                o.push('}');
                if let Some(u) = u {
                    o.push_str(&self.u_json(u));
                }
                if let Some(res) = r.residual_mm {
                    o.push_str(&format!(",\"residual_mm\":{}", jnum(res, 6)));
                }
                o.push_str(&format!(",\"orient_urad\":{}}}", jnum(r.orient_urad, 2)));
                self.out.write_all(o.as_bytes()).map_err(io)?;
            }
            Format::Svg | Format::Html => {}
        }
        Ok(())
    }

    /// `,"u_mm":…,"u_effects_mm":{…}` of a JSON row.
    fn u_json(&self, u: &crate::predict::uncertainty::BlockU) -> String {
        let parts: Vec<String> = self
            .u_effects()
            .iter()
            .zip(&u.effects_mm)
            .map(|(e, v)| format!("{}:{}", json_str(e), jnum(*v, 5)))
            .collect();
        format!(
            ",\"u_mm\":{},\"u_effects_mm\":{{{}}}",
            jnum(u.total_mm, 5),
            parts.join(",")
        )
    }

    /// The summary's line of the cutting moves' largest U (`None`: the
    /// report states no uncertainty).
    fn u_line(&self) -> Option<String> {
        if self.u_effects().is_empty() {
            return None;
        }
        Some(match self.worst_u {
            Some((u, at)) => format!(
                "uncertainty U(k=2) of {}: max {} mm (line {})",
                self.group_names().0,
                num(u, 5),
                self.place(at)
            ),
            None => format!("uncertainty U(k=2) of {}: none", self.group_names().0),
        })
    }

    /// `,"uncertainty":{…}` of the JSON summary (empty: none stated).
    fn u_summary_json(&self) -> String {
        if self.u_effects().is_empty() {
            return String::new();
        }
        let effects: Vec<String> = self.u_effects().iter().map(|e| json_str(e)).collect();
        match self.worst_u {
            Some((u, (line, file))) => format!(
                ",\"uncertainty\":{{\"k\":{},\"effects\":[{}],\"cutting_max_u_mm\":{},\"cutting_max_u_line\":{line}{}}}",
                jnum(crate::predict::uncertainty::COVERAGE_K, 1),
                effects.join(","),
                jnum(u, 5),
                self.json_file(file)
            ),
            None => format!(
                ",\"uncertainty\":{{\"k\":{},\"effects\":[{}]}}",
                jnum(crate::predict::uncertainty::COVERAGE_K, 1),
                effects.join(",")
            ),
        }
    }

    /// Keeps the row when it is the largest deviation so far (of all moves,
    /// of the cutting moves), for the picture's marks.
    /// `u`: its U (k=2), mm, when the report states one.
    fn mark(&mut self, r: &Entry, dev: f64, rapid: bool, u: Option<f64>) {
        let mark = PlotWorst {
            line: r.line,
            pos: r.position_mm,
            dev,
            cut: !rapid,
            u,
        };
        if self.worst_point.is_none_or(|w| dev > w.dev) {
            self.worst_point = Some(mark);
            self.worst_point_file = self.current();
        }
        if !rapid && self.worst_cut.is_none_or(|w| dev > w.dev) {
            self.worst_cut = Some(mark);
            self.worst_cut_file = self.current();
        }
    }

    /// Counts a robot row as a process move (linear or circular, under
    /// process force) or with the positioning moves and moves in air.
    fn add_process(&mut self, r: &Entry, dev: f64, at: (usize, usize), rapid: bool) {
        if let Some(i) = self.process_effect {
            let under_force = r.effects_mm.get(i).is_some_and(|v| *v > 0.0);
            if !rapid && under_force {
                self.process.add(dev, at, r.motion);
            } else {
                self.positioning_and_air.add(dev, at, r.motion);
            }
        }
    }

    /// The names of the two groups of moves in the summary: the
    /// headline's and the others'.
    fn group_names(&self) -> (&'static str, &'static str) {
        if self.process_split {
            ("process moves", "positioning moves and moves in air")
        } else {
            ("cutting moves", "rapids and machine-defined moves")
        }
    }

    /// The headline: the cutting moves (robot programs with process
    /// moves: those under process force, not the approach and retract
    /// moves in air).
    fn cutting_line(&self) -> String {
        let c = &self.cutting;
        format!(
            "{} ({}): |dev| mean {} mm, max {} mm (line {}), p95 {} mm",
            self.group_names().0,
            c.hist.count,
            num(c.mean(), 5),
            num(c.max(), 5),
            self.place(c.max_at()),
            num(c.percentile(95.0), 5)
        )
    }

    /// The rapids and moves to machine-defined places, on their own (`None`
    /// when the program has none).
    fn positioning_line(&self) -> Option<String> {
        let p = &self.positioning;
        (p.hist.count > 0).then(|| {
            format!(
                "{} ({}): max {} mm (line {})",
                self.group_names().1,
                p.hist.count,
                num(p.max(), 5),
                self.place(p.max_at())
            )
        })
    }

    /// The frame of the position columns: `machine` or `world`.
    fn positions_frame(&self) -> &'static str {
        if self.layout.kind == "rapid" {
            "world"
        } else {
            "machine"
        }
    }

    /// What the position columns are.
    fn positions_label(&self) -> &'static str {
        if self.layout.kind == "rapid" {
            "programmed TCP, world frame"
        } else {
            "machine coordinates (work offsets and tool lengths applied)"
        }
    }

    /// The summary of a table report, every line at most [`TABLE_COLUMNS`]
    /// characters: the cutting moves, the positioning moves on their own
    /// line, all moves, the effects, the worst blocks of each group, what
    /// the positions are and the provenance as `key: value` lines.
    fn table_summary(
        &mut self,
        rows: usize,
        (mean, max, max_at): (f64, f64, (usize, usize)),
        p95: &[f64],
        texts: &Texts,
    ) -> Result<()> {
        let max_line = self.place(max_at);
        let mut lines = vec![self.cutting_line()];
        lines.extend(self.positioning_line());
        lines.extend(self.u_line());
        lines.push(format!(
            "summary: {rows} rows; |dev| mean {} mm, max {} mm (line {max_line}), p95 {} mm",
            num(mean, 5),
            num(max, 5),
            num(p95.first().copied().unwrap_or(0.0), 5)
        ));
        lines.push(format!(
            "{:<10} {:>10} {:>10} {:>10}   worst blocks (all moves): line (mm)",
            "effect", "mean_mm", "p95_mm", "max_mm"
        ));
        for (i, s) in self.stats.iter().enumerate() {
            let mut line = format!(
                "{:<10} {:>10} {:>10} {:>10}  ",
                stat_name(&self.layout, i),
                num(s.mean(), 5),
                num(p95.get(i).copied().unwrap_or(0.0), 5),
                num(s.max(), 5),
            );
            // As many of the worst blocks as the width holds.
            for (k, (v, at, _, file)) in s.worst.iter().enumerate() {
                let item = format!(
                    "{} {} ({})",
                    if k == 0 { "" } else { "," },
                    self.place((*file, *at)),
                    num(*v, 5)
                );
                if line.chars().count() + item.chars().count() > TABLE_COLUMNS {
                    break;
                }
                line.push_str(&item);
            }
            lines.push(line.trim_end().to_string());
        }
        let (cut, other) = self.group_names();
        let groups = [
            (cut.replace(" moves", " blocks"), &self.cutting),
            (other.to_string(), &self.positioning),
        ];
        for (title, s) in groups {
            if s.worst.is_empty() {
                continue;
            }
            lines.push(format!("worst {title}:"));
            for (v, line, motion, file) in &s.worst {
                let text = texts.get(&(*file, *line)).map_or("", String::as_str);
                let line = self.place((*file, *line));
                let row = format!("  line {line:<6} {:>10} mm  {motion:<9} {text}", num(*v, 5));
                lines.push(row.trim_end().to_string());
            }
        }
        lines.push(format!("positions: {}", self.positions_label()));
        if let Some(p) = &self.provenance {
            lines.push("provenance:".into());
            lines.extend(p.key_lines().into_iter().map(|l| format!("  {l}")));
        }
        for line in lines {
            writeln!(self.out, "{line}").map_err(io)?;
        }
        Ok(())
    }

    /// The source text of the worst blocks, re-read from their files.
    fn worst_texts(&self) -> Texts {
        let mut out = Texts::new();
        let sources: Vec<(usize, &std::path::Path)> = if self.layout.files {
            self.files
                .iter()
                .enumerate()
                .filter_map(|(i, (_, p))| p.as_deref().map(|p| (i, p)))
                .collect()
        } else {
            self.source.iter().map(|p| (0, p.as_path())).collect()
        };
        for (file, path) in sources {
            let wanted = self
                .stats
                .iter()
                .chain([&self.cutting, &self.positioning])
                .flat_map(|s| s.worst.iter())
                .filter(|w| w.3 == file)
                .map(|w| w.1)
                .collect();
            for (line, text) in source_lines(path, &wanted) {
                out.insert((file, line), text);
            }
        }
        out
    }

    /// Writes the summary (and, for SVG, the picture) and ends the report.
    pub fn finish(mut self, totals: Totals) -> Result<()> {
        self.write_header()?;
        if self.process_effect.is_some() && self.process.hist.count > 0 {
            self.cutting = std::mem::replace(&mut self.process, Stat::new());
            self.positioning = std::mem::replace(&mut self.positioning_and_air, Stat::new());
            self.process_split = true;
        }
        let p95: Vec<f64> = self.stats.iter().map(|s| s.percentile(95.0)).collect();
        let rows = self.rows;
        let total = self
            .stats
            .first()
            .map_or((0.0, 0.0, (0, 0)), |s| (s.mean(), s.max(), s.max_at()));
        let p95_total = p95.first().copied().unwrap_or(0.0);
        let texts = match self.format {
            Format::Json | Format::Table => self.worst_texts(),
            _ => Default::default(),
        };
        match self.format {
            Format::Json => {
                let mut effects = Vec::new();
                for (i, s) in self.stats.iter().enumerate() {
                    effects.push(format!(
                        "{{\"name\":{},\"mean_mm\":{},\"p95_mm\":{},\"max_mm\":{},\"max_line\":{}{},\"worst\":[{}]}}",
                        json_str(stat_name(&self.layout, i)),
                        jnum(s.mean(), 5),
                        jnum(p95.get(i).copied().unwrap_or(0.0), 5),
                        jnum(s.max(), 5),
                        s.max_line(),
                        max_file_json(&self, s),
                        worst_json(&self, s, &texts)
                    ));
                }
                let provenance = self
                    .provenance
                    .as_ref()
                    .map(|p| format!(",\"provenance\":{}", p.to_json()))
                    .unwrap_or_default();
                let max_file = self
                    .stats
                    .first()
                    .map_or(String::new(), |s| max_file_json(&self, s));
                let cutting = group_json(&self, &self.cutting, &texts);
                let positioning = group_json(&self, &self.positioning, &texts);
                writeln!(
                    self.out,
                    "],\"summary\":{{\"blocks\":{},\"moves\":{},\"rows\":{},\"mean_mm\":{},\"max_mm\":{},\"max_line\":{}{},\"p95_mm\":{},\"cutting\":{},\"positioning\":{},\"effects\":[{}]{}}}{provenance}}}",
                    totals.blocks,
                    totals.moves,
                    rows,
                    jnum(total.0, 5),
                    jnum(total.1, 5),
                    total.2.1,
                    max_file,
                    jnum(p95_total, 5),
                    cutting,
                    positioning,
                    effects.join(","),
                    self.u_summary_json()
                )
                .map_err(io)?;
            }
            Format::Csv => {
                // One comment line, so the file stays a plain CSV table.
                let mut line = format!(
                    "# summary: {rows} rows; |dev| mean {} mm, max {} mm (line {}), p95 {} mm",
                    num(total.0, 5),
                    num(total.1, 5),
                    self.place(total.2),
                    num(p95_total, 5)
                );
                for (i, s) in self.stats.iter().enumerate().skip(1) {
                    line.push_str(&format!(
                        "; {} mean {} p95 {} max {} mm",
                        stat_name(&self.layout, i),
                        num(s.mean(), 5),
                        num(p95.get(i).copied().unwrap_or(0.0), 5),
                        num(s.max(), 5),
                    ));
                    if s.max_line() > 0 {
                        line.push_str(&format!(" (line {})", self.place(s.max_at())));
                    }
                }
                let worst: Vec<String> = self
                    .stats
                    .first()
                    .map(|s| s.worst.iter().map(|w| self.place((w.3, w.1))).collect())
                    .unwrap_or_default();
                line.push_str(&format!("; worst lines {}", worst.join(" ")));
                let mut groups = self.cutting_line();
                if let Some(p) = self.positioning_line() {
                    groups.push_str(&format!("; {p}"));
                }
                if let Some(u) = self.u_line() {
                    groups.push_str(&format!("; {u}"));
                }
                writeln!(self.out, "# positions: {}", self.positions_label()).map_err(io)?;
                writeln!(self.out, "# {groups}").map_err(io)?;
                writeln!(self.out, "{line}").map_err(io)?;
                if let Some(p) = &self.provenance {
                    writeln!(self.out, "# provenance: {}", p.one_line()).map_err(io)?;
                }
            }
            Format::Table => self.table_summary(rows, total, &p95, &texts)?,
            Format::Svg => {
                let points = self.plot.take().map(Decimator::finish).unwrap_or_default();
                let title = format!(
                    "{}: predicted |deviation|, {rows} moves; max {} mm at line {}, p95 {} mm",
                    self.file,
                    num(total.1, 4),
                    self.place(total.2),
                    num(p95_total, 4)
                );
                // The overall maximum, and the cutting maximum when it is
                // another block.
                let mut marks: Vec<PlotWorst> = self.worst_point.into_iter().collect();
                if let Some(c) = self.worst_cut {
                    if self.worst_point.is_none_or(|w| w.line != c.line) {
                        marks.push(c);
                    }
                }
                let svg = crate::emit::svg::render(&points, &marks, &title, &self.layout.effects)?;
                self.out.write_all(svg.as_bytes()).map_err(io)?;
            }
            Format::Html => {
                let page = self.html_page(totals, (rows, total, &p95))?;
                self.out.write_all(page.as_bytes()).map_err(io)?;
            }
        }
        Ok(())
    }

    /// A worst block as a table of the page lists it.
    fn listed(&self, w: &(f64, usize, String, usize), texts: &Texts) -> crate::emit::html::Listed {
        crate::emit::html::Listed {
            place: self.place((w.3, w.1)),
            at: (w.3, w.1),
            dev_mm: w.0,
            motion: w.2.clone(),
            text: texts.get(&(w.3, w.1)).cloned().unwrap_or_default(),
        }
    }

    /// The source text of the given lines of each file.
    fn texts_of(
        &self,
        wanted: &std::collections::BTreeMap<usize, std::collections::BTreeSet<usize>>,
    ) -> Texts {
        let mut out = Texts::new();
        for (&file, lines) in wanted {
            let path = if self.layout.files {
                self.files.get(file).and_then(|f| f.1.clone())
            } else {
                self.source.clone()
            };
            if let Some(path) = path {
                for (line, text) in source_lines(&path, lines) {
                    out.insert((file, line), text);
                }
            }
        }
        out
    }

    /// The HTML page of the report.
    fn html_page(
        &mut self,
        totals: Totals,
        (rows, total, p95): (usize, Overall, &[f64]),
    ) -> Result<String> {
        use crate::emit::html::{Doc, EffectRow, Mark};
        let (points, motions) = self.html.take().map(|c| c.finish()).unwrap_or_default();
        let mut wanted = crate::emit::html::wanted_lines(&points);
        for w in self
            .stats
            .iter()
            .chain([&self.cutting, &self.positioning])
            .flat_map(|s| s.worst.iter())
        {
            wanted.entry(w.3).or_default().insert(w.1);
        }
        let texts = self.texts_of(&wanted);
        let mut headline = vec![self.cutting_line()];
        headline.extend(self.positioning_line());
        headline.push(format!(
            "all moves ({rows}): |dev| mean {} mm, max {} mm (line {}), p95 {} mm",
            num(total.0, 5),
            num(total.1, 5),
            self.place(total.2),
            num(p95.first().copied().unwrap_or(0.0), 5)
        ));
        let effect_rows = self
            .stats
            .iter()
            .enumerate()
            .map(|(i, s)| EffectRow {
                name: stat_name(&self.layout, i).to_string(),
                mean_p95_max: [s.mean(), p95.get(i).copied().unwrap_or(0.0), s.max()],
                worst: s.worst.iter().map(|w| self.listed(w, &texts)).collect(),
            })
            .collect();
        let groups = vec![
            (
                "Worst cutting moves".to_string(),
                self.cutting
                    .worst
                    .iter()
                    .map(|w| self.listed(w, &texts))
                    .collect(),
            ),
            (
                "Worst rapids and machine-defined moves".to_string(),
                self.positioning
                    .worst
                    .iter()
                    .map(|w| self.listed(w, &texts))
                    .collect(),
            ),
        ];
        let mut marks: Vec<Mark> = Vec::new();
        if let Some(w) = self.worst_point {
            marks.push(Mark {
                at: (self.worst_point_file, w.line),
                pos: w.pos,
                dev: w.dev,
                cut: false,
                u: w.u,
            });
        }
        if let Some(c) = self.worst_cut {
            if self
                .worst_point
                .is_none_or(|w| w.line != c.line || self.worst_point_file != self.worst_cut_file)
            {
                marks.push(Mark {
                    at: (self.worst_cut_file, c.line),
                    pos: c.pos,
                    dev: c.dev,
                    cut: true,
                    u: c.u,
                });
            }
        }
        let files = if self.layout.files {
            self.files.iter().map(|f| f.0.clone()).collect()
        } else {
            vec![self.file.clone()]
        };
        let positioning = motions.iter().map(|m| is_positioning(m)).collect();
        let doc = Doc {
            title: format!(
                "{}: predicted deviation, {rows} moves; max {} mm at line {}",
                self.file,
                num(total.1, 4),
                self.place(total.2)
            ),
            kind: self.layout.kind,
            positions: self.positions_label().to_string(),
            effects: self.layout.effects.iter().map(|e| e.to_string()).collect(),
            residual: self.layout.residual,
            files,
            points,
            motions,
            positioning,
            texts,
            headline,
            effect_rows,
            groups,
            marks,
            provenance: self
                .provenance
                .as_ref()
                .map(|p| p.key_lines())
                .unwrap_or_default(),
            totals: (totals.blocks, totals.moves),
        };
        Ok(crate::emit::html::render(&doc))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    const TOL_MM: f64 = 1e-12;

    #[test]
    fn stat_percentile_mean_and_worst() {
        // Values 0.001 .. 0.100 mm (100 values): mean 0.0505, p95 is the
        // 95th value 0.095 (upper bin edge 0.09501 capped by nothing), the
        // worst five are 0.100 .. 0.096 at lines 100 .. 96.
        let mut s = Stat::new();
        for i in 1..=100 {
            s.add(i as f64 * 0.001, (i, 0), "feed");
        }
        assert_abs_diff_eq!(s.mean(), 0.0505, epsilon = TOL_MM);
        assert_abs_diff_eq!(
            s.percentile(95.0),
            0.095,
            epsilon = crate::compensate::outcome::DEV_BIN_MM + TOL_MM
        );
        let lines: Vec<usize> = s.worst.iter().map(|w| w.1).collect();
        assert_eq!(lines, [100, 99, 98, 97, 96]);
        assert_eq!(s.max_line(), 100);
    }

    #[test]
    fn stat_percentile_beyond_the_histogram_is_exact() {
        // 3, 4, 5 mm: all beyond 2 mm; p50 = 2nd value = 4 mm.
        let mut s = Stat::new();
        for (i, v) in [5.0, 3.0, 4.0].into_iter().enumerate() {
            s.add(v, (i + 1, 0), "MoveL");
        }
        assert_abs_diff_eq!(s.percentile(50.0), 4.0, epsilon = TOL_MM);
        assert_abs_diff_eq!(s.percentile(100.0), 5.0, epsilon = TOL_MM);
        assert_eq!(s.max_line(), 1);
    }

    #[test]
    fn ties_keep_the_earlier_block() {
        let mut s = Stat::new();
        s.add(0.5, (7, 0), "feed");
        s.add(0.5, (9, 0), "feed");
        assert_eq!(s.max_line(), 7);
    }
}
