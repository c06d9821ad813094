//! Observation files (the measured-data contract of
//! docs/calibration.md): reading with located errors, writing in
//! a canonical form, a reproducible train/holdout split and seeded noise.
//!
//! Decisions on top of the contract:
//! - **Columns** are located by the 1-based *byte* column of the first byte of
//!   the cell (after leading blanks; for a quoted cell, the opening quote), as
//!   [`Located`] documents. A cell missing at the end of a short row is
//!   reported one past the last byte of the line.
//! - Lines whose first non-blank byte is `#` are comments, anywhere (also
//!   before the header). Blank lines are skipped. A UTF-8 byte-order mark on
//!   line 1 and `\r\n` line ends are accepted. Blanks (space, tab) around a
//!   cell are ignored; a quoted cell (`"…"`, `""` for a quote) keeps its text
//!   verbatim but cannot span lines. A quote inside an unquoted cell is an error.
//! - Column names are case sensitive (`x_mm` is the measured position,
//!   `X_mm` the commanded machine-tool axis).
//! - **Exactly one position triple per file**: the header must contain all of
//!   `x_mm, y_mm, z_mm` or all of `dx_mm, dy_mm, dz_mm`, not both, and every row
//!   must fill all three cells. The mp/wp points also need all three columns;
//!   in a row they are all empty (→ `None`, the caller uses the TCP) or all
//!   given. Force and moment components are independent (each defaults to 0).
//! - The kind is decided by the kind-specific columns: any robot column
//!   (`q*_deg`, `mp_*`, `wp_*`, `p1_w`…, `dir1`…) makes a robot file, any
//!   machine-tool column (`X_mm`…, `dirX`…, `tool_mm`, `spindle_*`, `pX_w`…) a
//!   machine-tool file; both or neither is an error.
//! - Required cells (joint angles, X/Y/Z, the position triple) must not be empty.
//! - `dir*` cells must be exactly `1` or `-1` (`+1`, `1.0` accepted).
//! - The default `id` is the 1-based data-row number.

use std::collections::BTreeSet;
use std::io::{BufRead, Write};
use std::path::Path;

use nalgebra::{Quaternion, UnitQuaternion, Vector3};

use crate::calibrate::stats::SplitMix64;
use crate::error::{Error, Located, Result};
use crate::limits;
use crate::machine::{AxisVec, DirVec};

/// Every known column name, in the canonical (writing) order.
const NAMES: [&str; 64] = [
    "id",
    "t_s",
    "x_mm",
    "y_mm",
    "z_mm",
    "dx_mm",
    "dy_mm",
    "dz_mm",
    "fx_n",
    "fy_n",
    "fz_n",
    "mx_nm",
    "my_nm",
    "mz_nm",
    "ambient_c",
    "q1_deg",
    "q2_deg",
    "q3_deg",
    "q4_deg",
    "q5_deg",
    "q6_deg",
    "mp_x_mm",
    "mp_y_mm",
    "mp_z_mm",
    "wp_x_mm",
    "wp_y_mm",
    "wp_z_mm",
    "p1_w",
    "p2_w",
    "p3_w",
    "p4_w",
    "p5_w",
    "p6_w",
    "dir1",
    "dir2",
    "dir3",
    "dir4",
    "dir5",
    "dir6",
    "X_mm",
    "Y_mm",
    "Z_mm",
    "A_deg",
    "B_deg",
    "C_deg",
    "dirX",
    "dirY",
    "dirZ",
    "dirA",
    "dirB",
    "dirC",
    "tool_mm",
    "spindle_rpm",
    "spindle_w",
    "pX_w",
    "pY_w",
    "pZ_w",
    "pA_w",
    "pB_w",
    "pC_w",
    "qw",
    "qx",
    "qy",
    "qz",
];

// Index of the first column of each group in NAMES.
const ID: usize = 0;
const T_S: usize = 1;
const POS: usize = 2;
const DEV: usize = 5;
const FORCE: usize = 8;
const MOMENT: usize = 11;
const AMBIENT: usize = 14;
const Q: usize = 15;
const MP: usize = 21;
const WP: usize = 24;
const P_ROBOT: usize = 27;
const DIR_ROBOT: usize = 33;
const AXES: usize = 39;
const DIR_TOOL: usize = 45;
const TOOL_MM: usize = 51;
const SPINDLE_RPM: usize = 52;
const SPINDLE_W: usize = 53;
const P_TOOL: usize = 54;
const QUAT: usize = 60;
/// Robot-only columns are `ROBOT_ONLY`, machine-tool-only ones `TOOL_ONLY`.
const ROBOT_ONLY: std::ops::Range<usize> = Q..AXES;
const TOOL_ONLY: std::ops::Range<usize> = AXES..QUAT;

/// A known column of an observation file. Ordered canonically (the order
/// [`write_observations`] uses).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Column(u8);

impl Column {
    /// The column with this exact (case-sensitive) name.
    pub fn from_name(name: &str) -> Option<Column> {
        NAMES
            .iter()
            .position(|n| *n == name)
            .map(|i| Column(i as u8))
    }

    /// The column's name as written in the header.
    pub fn name(self) -> &'static str {
        NAMES.get(self.0 as usize).copied().unwrap_or("?")
    }

    /// Every known column name in canonical order.
    pub fn all_names() -> &'static [&'static str] {
        &NAMES
    }

    fn idx(self) -> usize {
        self.0 as usize
    }
}

/// Which machine the observations were measured on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ObsKind {
    /// An articulated robot (joint angles `q1_deg`…`q6_deg`).
    Robot,
    /// A machine tool (axis positions `X_mm`, `Y_mm`, `Z_mm`, …).
    MachineTool,
}

/// What the measured triple of every row of a file means.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MeasuredKind {
    /// `x_mm, y_mm, z_mm`: the attained position.
    Position,
    /// `dx_mm, dy_mm, dz_mm`: the deviation attained − commanded.
    Deviation,
}

/// Robot part of a row.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotPose {
    /// Joint angles q1…q6 as reported by the controller, degrees.
    pub q_deg: [f64; 6],
    /// Measured point in the flange frame, mm (`None`: the machine's TCP).
    pub mp_mm: Option<Vector3<f64>>,
    /// Wrench point in the flange frame, mm (`None`: the machine's TCP).
    pub wp_mm: Option<Vector3<f64>>,
    /// Mean motor power of each joint, W.
    pub p_w: [Option<f64>; 6],
    /// Sign of the last motion of each joint.
    pub dir: [Option<i8>; 6],
}

/// Machine-tool part of a row.
#[derive(Debug, Clone, PartialEq)]
pub struct ToolPose {
    /// Commanded X, Y, Z, mm.
    pub xyz_mm: Vector3<f64>,
    /// Commanded A, B, C, degrees (`None`: not given).
    pub abc_deg: [Option<f64>; 3],
    /// Sign of the last motion of each axis, slot order X Y Z A B C.
    pub dir: [Option<i8>; 6],
    /// Tool length, mm (`None`: the machine file's active tool).
    pub tool_mm: Option<f64>,
    /// Spindle speed, 1/min.
    pub spindle_rpm: Option<f64>,
    /// Spindle motor power, W.
    pub spindle_w: Option<f64>,
    /// Mean feed-drive motor power per axis X Y Z A B C, W.
    pub p_w: [Option<f64>; 6],
}

impl ToolPose {
    /// Commanded axes in slot order X Y Z A B C; rotary axes not given are 0.
    pub fn axes(&self) -> AxisVec {
        let [a, b, c] = self.abc_deg.map(|v| v.unwrap_or(0.0));
        [self.xyz_mm.x, self.xyz_mm.y, self.xyz_mm.z, a, b, c]
    }

    /// Last-motion signs in slot order; 0 where not given.
    pub fn dirs(&self) -> DirVec {
        self.dir.map(|d| d.unwrap_or(0))
    }
}

/// The machine-specific part of a row.
#[derive(Debug, Clone, PartialEq)]
pub enum Pose {
    /// Robot joint data.
    Robot(RobotPose),
    /// Machine-tool axis data.
    Tool(ToolPose),
}

/// One measured pose (one data row).
#[derive(Debug, Clone)]
pub struct Observation {
    /// Source line of the row (1-based; 0 for rows not read from a file).
    /// Not part of equality.
    pub line: usize,
    /// Row label (default: the 1-based data-row number).
    pub id: String,
    /// Time since the start of the campaign, s.
    pub t_s: Option<f64>,
    /// The measured triple, mm: position or deviation per
    /// [`Observations::measured`].
    pub measured_mm: Vector3<f64>,
    /// External force at the wrench point, N (0 where not given).
    pub force_n: Vector3<f64>,
    /// External moment about the wrench point, N·m (0 where not given).
    pub moment_nm: Vector3<f64>,
    /// Ambient temperature, °C.
    pub ambient_c: Option<f64>,
    /// Machine-specific data.
    pub pose: Pose,
    /// Measured orientation of the measured frame (`qw, qx, qy, qz`), in
    /// the frame of the positions; `None` when not given.
    pub orientation: Option<UnitQuaternion<f64>>,
}

impl PartialEq for Observation {
    /// Compares the data, not the source line.
    fn eq(&self, o: &Self) -> bool {
        self.id == o.id
            && self.t_s == o.t_s
            && self.measured_mm == o.measured_mm
            && self.force_n == o.force_n
            && self.moment_nm == o.moment_nm
            && self.ambient_c == o.ambient_c
            && self.pose == o.pose
            && self.orientation.map(|q| q.coords) == o.orientation.map(|q| q.coords)
    }
}

/// The frame the measured positions (and orientations) of a file are in:
/// the comment line `# frame: …` before the header.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MeasurementFrame {
    /// The machine's reference frame (robot: base frame; machine tool:
    /// workpiece frame). `# frame: base` or `# frame: reference`, or no line.
    #[default]
    Reference,
    /// Robot: the world frame, related to the base frame by the machine
    /// file's `base` (`# frame: world`).
    World,
    /// An instrument frame whose transform to the reference frame is not
    /// known: identified together with the model (`# frame: instrument`).
    Instrument,
}

impl MeasurementFrame {
    /// The word of the `# frame:` line.
    pub fn name(self) -> &'static str {
        match self {
            MeasurementFrame::Reference => "base",
            MeasurementFrame::World => "world",
            MeasurementFrame::Instrument => "instrument",
        }
    }

    /// Parses the word of a `# frame:` line or of `--frame`.
    pub fn parse(word: &str) -> Option<MeasurementFrame> {
        match word {
            "base" | "reference" => Some(MeasurementFrame::Reference),
            "world" => Some(MeasurementFrame::World),
            "instrument" => Some(MeasurementFrame::Instrument),
            _ => None,
        }
    }
}

/// The content of an observation file.
#[derive(Debug, Clone, PartialEq)]
pub struct Observations {
    /// Robot or machine tool.
    pub kind: ObsKind,
    /// The frame of the measured positions.
    pub frame: MeasurementFrame,
    /// Meaning of every row's `measured_mm`.
    pub measured: MeasuredKind,
    /// Columns present in the file (or to be written), canonical order.
    pub columns: BTreeSet<Column>,
    /// The rows in file order.
    pub rows: Vec<Observation>,
}

// ---------------------------------------------------------------------------
// Reading
// ---------------------------------------------------------------------------

/// One cell of a line: its 1-based byte column and unescaped, trimmed bytes.
struct Cell {
    col: usize,
    text: Vec<u8>,
}

/// Largest accepted magnitude of a cell other than `t_s` (mm, deg, N, N·m,
/// W, 1/min, °C): 10 km in mm, far beyond any machine, so only corrupt data
/// is refused.
pub const MAX_MAGNITUDE: f64 = 1e7;

/// Largest accepted `t_s`: about 30 years in seconds.
pub const MAX_TIME_S: f64 = 1e9;

fn is_blank(b: u8) -> bool {
    b == b' ' || b == b'\t'
}

/// Splits one line (without its line end) into cells. Errors carry the
/// 1-based byte column.
fn split_cells(b: &[u8]) -> std::result::Result<Vec<Cell>, (usize, String)> {
    let mut cells = Vec::new();
    let mut i = 0;
    loop {
        while i < b.len() && is_blank(b[i]) {
            i += 1;
        }
        let start = i;
        let mut text = Vec::new();
        if b.get(i) == Some(&b'"') {
            i += 1;
            loop {
                match b.get(i) {
                    None => {
                        return Err((
                            start + 1,
                            "unterminated quoted cell (a quoted cell cannot span lines)".into(),
                        ));
                    }
                    Some(b'"') if b.get(i + 1) == Some(&b'"') => {
                        text.push(b'"');
                        i += 2;
                    }
                    Some(b'"') => {
                        i += 1;
                        break;
                    }
                    Some(&c) => {
                        text.push(c);
                        i += 1;
                    }
                }
            }
            while i < b.len() && is_blank(b[i]) {
                i += 1;
            }
            if i < b.len() && b[i] != b',' {
                return Err((i + 1, "unexpected text after a quoted cell".into()));
            }
        } else {
            while i < b.len() && b[i] != b',' {
                if b[i] == b'"' {
                    return Err((
                        i + 1,
                        "quote inside an unquoted cell (quote the whole cell)".into(),
                    ));
                }
                i += 1;
            }
            let mut end = i;
            while end > start && is_blank(b[end - 1]) {
                end -= 1;
            }
            text.extend_from_slice(&b[start..end]);
        }
        cells.push(Cell {
            col: start + 1,
            text,
        });
        if i >= b.len() {
            return Ok(cells);
        }
        i += 1; // the comma
    }
}

/// Levenshtein distance of two byte strings.
fn levenshtein(a: &[u8], b: &[u8]) -> usize {
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    let mut cur = vec![0; b.len() + 1];
    for (i, ca) in a.iter().enumerate() {
        cur[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let sub = prev[j] + usize::from(ca != cb);
            cur[j + 1] = sub.min(prev[j + 1] + 1).min(cur[j] + 1);
        }
        std::mem::swap(&mut prev, &mut cur);
    }
    prev[b.len()]
}

/// The known column name closest to `name`, if reasonably close.
fn suggest(name: &str) -> Option<&'static str> {
    let lower = name.to_ascii_lowercase();
    let (best, key) = NAMES
        .iter()
        .map(|n| {
            let key = (
                levenshtein(lower.as_bytes(), n.to_ascii_lowercase().as_bytes()),
                levenshtein(name.as_bytes(), n.as_bytes()),
            );
            (*n, key)
        })
        .min_by_key(|(_, k)| *k)?;
    (key.0 <= 2.max(name.len() / 3)).then_some(best)
}

/// The parsed header.
struct Header {
    line: usize,
    /// Column of each field.
    cols: Vec<Column>,
    /// Byte column of each header cell.
    byte_cols: Vec<usize>,
    kind: ObsKind,
    measured: MeasuredKind,
    /// A poses file: the measured cells may be empty.
    poses_only: bool,
}

impl Header {
    fn has(&self, idx: usize) -> bool {
        self.cols.iter().any(|c| c.idx() == idx)
    }
    fn byte_col(&self, idx: usize) -> usize {
        self.cols
            .iter()
            .position(|c| c.idx() == idx)
            .and_then(|p| self.byte_cols.get(p).copied())
            .unwrap_or(1)
    }
}

struct Ctx<'a> {
    file: &'a str,
}

impl Ctx<'_> {
    fn err(&self, line: usize, col: usize, msg: impl Into<String>) -> Error {
        Error::Input(Located::new(self.file, line, col, msg))
    }
}

fn parse_header(ctx: &Ctx, line: usize, cells: &[Cell], poses_only: bool) -> Result<Header> {
    let mut cols = Vec::with_capacity(cells.len());
    let mut byte_cols = Vec::with_capacity(cells.len());
    for cell in cells {
        let name = String::from_utf8_lossy(&cell.text);
        if name.is_empty() {
            return Err(ctx.err(line, cell.col, "empty column name"));
        }
        let Some(c) = Column::from_name(&name) else {
            let hint = suggest(&name)
                .map(|s| format!(" (did you mean \"{s}\"?)"))
                .unwrap_or_default();
            return Err(ctx.err(line, cell.col, format!("unknown column \"{name}\"{hint}")));
        };
        if let Some(first) = cols.iter().position(|&k| k == c) {
            let at = byte_cols.get(first).copied().unwrap_or(1);
            return Err(ctx.err(
                line,
                cell.col,
                format!("duplicate column \"{name}\" (first at column {at})"),
            ));
        }
        cols.push(c);
        byte_cols.push(cell.col);
    }
    let first_in = |range: std::ops::Range<usize>| {
        cols.iter()
            .position(|c| range.contains(&c.idx()))
            .map(|p| (p, cols[p]))
    };
    let kind = match (first_in(ROBOT_ONLY), first_in(TOOL_ONLY)) {
        (Some((pr, cr)), Some((pt, ct))) => {
            let (later, lp, earlier, what) = if pr > pt {
                (cr, pr, ct, ("robot", "machine-tool"))
            } else {
                (ct, pt, cr, ("machine-tool", "robot"))
            };
            return Err(ctx.err(
                line,
                byte_cols.get(lp).copied().unwrap_or(1),
                format!(
                    "column \"{}\" belongs to {} files, but column \"{}\" makes this a {} file",
                    later.name(),
                    what.0,
                    earlier.name(),
                    what.1
                ),
            ));
        }
        (Some(_), None) => ObsKind::Robot,
        (None, Some(_)) => ObsKind::MachineTool,
        (None, None) => {
            return Err(ctx.err(
                line,
                1,
                "cannot tell the machine kind: no robot joint columns (q1_deg … q6_deg) \
                 nor machine-tool axis columns (X_mm, Y_mm, Z_mm)",
            ));
        }
    };
    let mut h = Header {
        line,
        cols,
        byte_cols,
        kind,
        measured: MeasuredKind::Position,
        poses_only,
    };
    let required: std::ops::Range<usize> = match kind {
        ObsKind::Robot => Q..Q + 6,
        ObsKind::MachineTool => AXES..AXES + 3,
    };
    for idx in required {
        if !h.has(idx) {
            return Err(ctx.err(
                line,
                1,
                format!("missing required column \"{}\"", NAMES[idx]),
            ));
        }
    }
    // Triples must be complete.
    for start in [POS, DEV, MP, WP] {
        let given: Vec<usize> = (start..start + 3).filter(|&i| h.has(i)).collect();
        if let Some(&first) = given.first() {
            if given.len() < 3 {
                let missing: Vec<String> = (start..start + 3)
                    .filter(|i| !given.contains(i))
                    .map(|i| format!("\"{}\"", NAMES[i]))
                    .collect();
                return Err(ctx.err(
                    line,
                    h.byte_col(first),
                    format!(
                        "column \"{}\" needs {} too (a point needs all three coordinates)",
                        NAMES[first],
                        missing.join(" and ")
                    ),
                ));
            }
        }
    }
    let quat: Vec<usize> = (QUAT..QUAT + 4).filter(|&i| h.has(i)).collect();
    if let Some(&first) = quat.first() {
        if quat.len() < 4 {
            return Err(ctx.err(
                line,
                h.byte_col(first),
                format!(
                    "column \"{}\" needs the other orientation columns too (qw, qx, qy, qz: all four or none)",
                    NAMES[first]
                ),
            ));
        }
    }
    h.measured = match (h.has(POS), h.has(DEV)) {
        (true, true) => {
            let at = h.byte_col(POS).max(h.byte_col(DEV));
            return Err(ctx.err(
                line,
                at,
                "both the measured position (x_mm, y_mm, z_mm) and the deviation \
                 (dx_mm, dy_mm, dz_mm) are given; a file holds exactly one of them",
            ));
        }
        (true, false) => MeasuredKind::Position,
        (false, true) => MeasuredKind::Deviation,
        (false, false) if poses_only => MeasuredKind::Position,
        (false, false) => {
            return Err(ctx.err(
                line,
                1,
                "missing the measured position (x_mm, y_mm, z_mm) or deviation \
                 (dx_mm, dy_mm, dz_mm) columns",
            ));
        }
    };
    Ok(h)
}

fn is_dir(idx: usize) -> bool {
    (DIR_ROBOT..DIR_ROBOT + 6).contains(&idx) || (DIR_TOOL..DIR_TOOL + 6).contains(&idx)
}

/// The cells of one row by column index: the value of each numeric cell
/// (`None` when empty), the byte column of each cell, and the `id` cell.
struct Cells {
    vals: [Option<f64>; NAMES.len()],
    at: [usize; NAMES.len()],
    id: Option<String>,
}

/// Reads and checks each cell of a row whose count matches the header:
/// valid UTF-8, a finite number of plausible size, `1` or `-1` for a
/// direction.
fn read_cells(ctx: &Ctx, h: &Header, line: usize, cells: &[Cell]) -> Result<Cells> {
    let mut vals: [Option<f64>; NAMES.len()] = [None; NAMES.len()];
    let mut at = [0usize; NAMES.len()];
    let mut id = None;
    for (cell, c) in cells.iter().zip(&h.cols) {
        let idx = c.idx();
        at[idx] = cell.col;
        let Ok(text) = std::str::from_utf8(&cell.text) else {
            return Err(ctx.err(
                line,
                cell.col,
                format!(
                    "column \"{}\": cell \"{}\" is not valid UTF-8",
                    c.name(),
                    String::from_utf8_lossy(&cell.text)
                ),
            ));
        };
        if text.is_empty() {
            continue;
        }
        if idx == ID {
            id = Some(text.to_string());
            continue;
        }
        let Ok(v) = text.parse::<f64>() else {
            return Err(ctx.err(
                line,
                cell.col,
                format!("column \"{}\": non-numeric cell \"{text}\"", c.name()),
            ));
        };
        if !v.is_finite() {
            return Err(ctx.err(
                line,
                cell.col,
                format!(
                    "column \"{}\": cell \"{text}\" is not a finite number",
                    c.name()
                ),
            ));
        }
        let limit = if c.name() == "t_s" {
            MAX_TIME_S
        } else {
            MAX_MAGNITUDE
        };
        if v.abs() > limit {
            return Err(ctx.err(
                line,
                cell.col,
                format!(
                    "column \"{}\": cell \"{}\" is absurdly large (limit {})",
                    c.name(),
                    crate::error::clip(text),
                    crate::error::show_number(limit)
                ),
            ));
        }
        if is_dir(idx) && v != 1.0 && v != -1.0 {
            return Err(ctx.err(
                line,
                cell.col,
                format!("column \"{}\": cell \"{text}\" must be 1 or -1", c.name()),
            ));
        }
        vals[idx] = Some(v);
    }
    Ok(Cells { vals, at, id })
}

fn parse_row(
    ctx: &Ctx,
    h: &Header,
    line: usize,
    line_len: usize,
    row_no: usize,
    cells: &[Cell],
) -> Result<Observation> {
    if cells.len() != h.cols.len() {
        let col = cells.get(h.cols.len()).map_or(line_len + 1, |c| c.col);
        return Err(ctx.err(
            line,
            col,
            format!(
                "row has {} cells but the header (line {}) has {} columns",
                cells.len(),
                h.line,
                h.cols.len()
            ),
        ));
    }
    let Cells { vals, at, id } = read_cells(ctx, h, line, cells)?;
    let required = |idx: usize| -> Result<f64> {
        vals[idx].ok_or_else(|| {
            ctx.err(
                line,
                at[idx],
                format!("column \"{}\": value required (empty cell)", NAMES[idx]),
            )
        })
    };
    let triple = |start: usize| -> Result<Vector3<f64>> {
        Ok(Vector3::new(
            required(start)?,
            required(start + 1)?,
            required(start + 2)?,
        ))
    };
    let optional_point = |start: usize| -> Result<Option<Vector3<f64>>> {
        let given: Vec<usize> = (start..start + 3).filter(|&i| vals[i].is_some()).collect();
        match given.first() {
            None => Ok(None),
            Some(&g) => {
                if let Some(miss) = (start..start + 3).find(|i| vals[*i].is_none()) {
                    return Err(ctx.err(
                        line,
                        at[miss],
                        format!(
                            "column \"{}\": empty but \"{}\" is given (a point needs all three coordinates)",
                            NAMES[miss], NAMES[g]
                        ),
                    ));
                }
                triple(start).map(Some)
            }
        }
    };
    let zero = |start: usize| {
        Vector3::new(
            vals[start].unwrap_or(0.0),
            vals[start + 1].unwrap_or(0.0),
            vals[start + 2].unwrap_or(0.0),
        )
    };
    let six = |start: usize| -> [Option<f64>; 6] { std::array::from_fn(|k| vals[start + k]) };
    let dirs = |start: usize| -> [Option<i8>; 6] {
        std::array::from_fn(|k| vals[start + k].map(|v| if v > 0.0 { 1 } else { -1 }))
    };
    let start = match h.measured {
        MeasuredKind::Position => POS,
        MeasuredKind::Deviation => DEV,
    };
    let all_empty = (start..start + 3).all(|i| vals[i].is_none());
    let measured_mm = match h.measured {
        _ if h.poses_only && all_empty => Vector3::zeros(),
        MeasuredKind::Position => triple(POS)?,
        MeasuredKind::Deviation => triple(DEV)?,
    };
    let pose = match h.kind {
        ObsKind::Robot => {
            let mut q_deg = [0.0; 6];
            for (k, q) in q_deg.iter_mut().enumerate() {
                *q = required(Q + k)?;
            }
            Pose::Robot(RobotPose {
                q_deg,
                mp_mm: optional_point(MP)?,
                wp_mm: optional_point(WP)?,
                p_w: six(P_ROBOT),
                dir: dirs(DIR_ROBOT),
            })
        }
        ObsKind::MachineTool => Pose::Tool(ToolPose {
            xyz_mm: triple(AXES)?,
            abc_deg: [vals[AXES + 3], vals[AXES + 4], vals[AXES + 5]],
            dir: dirs(DIR_TOOL),
            tool_mm: vals[TOOL_MM],
            spindle_rpm: vals[SPINDLE_RPM],
            spindle_w: vals[SPINDLE_W],
            p_w: six(P_TOOL),
        }),
    };
    let orientation = row_orientation(ctx, line, &vals, &at)?;
    Ok(Observation {
        line,
        orientation,
        id: id.unwrap_or_else(|| row_no.to_string()),
        t_s: vals[T_S],
        measured_mm,
        force_n: zero(FORCE),
        moment_nm: zero(MOMENT),
        ambient_c: vals[AMBIENT],
        pose,
    })
}

/// Largest accepted deviation of a measured quaternion's norm from 1.
pub const QUATERNION_NORM_TOL: f64 = 1e-3;

/// The orientation of a row: all four cells or none; the norm within
/// [`QUATERNION_NORM_TOL`] of 1 (then normalised).
fn row_orientation(
    ctx: &Ctx,
    line: usize,
    vals: &[Option<f64>; NAMES.len()],
    at: &[usize; NAMES.len()],
) -> Result<Option<UnitQuaternion<f64>>> {
    let q: [Option<f64>; 4] = std::array::from_fn(|k| vals[QUAT + k]);
    if q.iter().all(Option::is_none) {
        return Ok(None);
    }
    if let Some(k) = q.iter().position(Option::is_none) {
        return Err(ctx.err(
            line,
            at[QUAT + k],
            format!(
                "column \"{}\": empty but other orientation cells are given (all four or none)",
                NAMES[QUAT + k]
            ),
        ));
    }
    let [w, x, y, z] = q.map(|v| v.unwrap_or(0.0));
    let raw = Quaternion::new(w, x, y, z);
    if (raw.norm() - 1.0).abs() > QUATERNION_NORM_TOL {
        return Err(ctx.err(
            line,
            at[QUAT],
            format!(
                "the orientation (qw, qx, qy, qz) has norm {:.6}; a unit quaternion is expected",
                raw.norm()
            ),
        ));
    }
    Ok(Some(UnitQuaternion::from_quaternion(raw)))
}

/// The `# frame: …` comment: `Some(Ok(frame))`, `Some(Err((column, message)))`
/// for a frame line with an unknown word, `None` for any other comment.
fn frame_comment(b: &[u8]) -> Option<std::result::Result<MeasurementFrame, (usize, String)>> {
    let text = std::str::from_utf8(b).ok()?;
    let body = text.trim_start().strip_prefix('#')?.trim_start();
    let rest = body.strip_prefix("frame:")?;
    let word = rest.trim();
    Some(MeasurementFrame::parse(word).ok_or_else(|| {
        let col = text.len() - rest.trim_start().len() + 1;
        (
            col,
            format!(
                "unknown measurement frame \"{}\" (base, world or instrument)",
                crate::error::clip(word)
            ),
        )
    }))
}

/// Reads an observation file from a buffered reader, line by line. `file` is
/// the name used in error messages. Never panics, whatever the bytes.
pub fn read_observations<R: BufRead>(reader: R, file: &str) -> Result<Observations> {
    read_rows(reader, file, false)
}

/// Reads a *poses* file: like [`read_observations`], but the measured triple
/// may be absent (then every row's `measured_mm` is zero and the kind is
/// [`MeasuredKind::Position`]) and a row may leave all three measured cells
/// empty (zero). This is the input of `postproc simulate`.
pub fn read_poses<R: BufRead>(reader: R, file: &str) -> Result<Observations> {
    read_rows(reader, file, true)
}

/// Reads a poses file from disk, see [`read_poses`].
pub fn load_poses(path: &Path) -> Result<Observations> {
    let f = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    read_poses(std::io::BufReader::new(f), &path.display().to_string())
}

fn read_rows<R: BufRead>(mut reader: R, file: &str, poses_only: bool) -> Result<Observations> {
    let ctx = Ctx { file };
    let mut buf = Vec::new();
    let mut line_no = 0usize;
    let mut header: Option<Header> = None;
    let mut rows = Vec::new();
    let mut frame: Option<(MeasurementFrame, usize)> = None;
    loop {
        buf.clear();
        let n = std::io::Read::take(&mut reader, limits::LINE_MAX_BYTES as u64 + 2)
            .read_until(b'\n', &mut buf)
            .map_err(|e| Error::io(file, e))?;
        if n == 0 {
            break;
        }
        line_no += 1;
        if buf.last() == Some(&b'\n') {
            buf.pop();
        }
        if buf.last() == Some(&b'\r') {
            buf.pop();
        }
        if buf.len() > limits::LINE_MAX_BYTES {
            return Err(limits::line_too_long(file, line_no).into());
        }
        let bytes: &[u8] = if line_no == 1 {
            buf.strip_prefix(b"\xEF\xBB\xBF".as_slice()).unwrap_or(&buf)
        } else {
            &buf
        };
        match bytes.iter().find(|b| !is_blank(**b)) {
            Some(b'#') if header.is_none() => {
                match frame_comment(bytes) {
                    Some(Ok(f)) => {
                        if let Some((_, first)) = frame {
                            return Err(ctx.err(
                                line_no,
                                1,
                                format!("second \"# frame:\" line (the first is line {first})"),
                            ));
                        }
                        frame = Some((f, line_no));
                    }
                    Some(Err((col, msg))) => return Err(ctx.err(line_no, col, msg)),
                    None => {}
                }
                continue;
            }
            None | Some(b'#') => continue,
            Some(_) => {}
        }
        let cells = split_cells(bytes).map_err(|(col, msg)| ctx.err(line_no, col, msg))?;
        match &header {
            None => header = Some(parse_header(&ctx, line_no, &cells, poses_only)?),
            Some(h) => {
                if rows.len() >= limits::OBSERVATION_MAX_ROWS {
                    return Err(ctx.err(
                        line_no,
                        1,
                        format!(
                            "more than {} data rows (the limit of an observation file)",
                            limits::OBSERVATION_MAX_ROWS
                        ),
                    ));
                }
                let row = parse_row(&ctx, h, line_no, bytes.len(), rows.len() + 1, &cells)?;
                rows.push(row);
            }
        }
    }
    let Some(h) = header else {
        return Err(ctx.err(line_no.max(1), 1, "no header row (the file has no data)"));
    };
    let frame = match frame {
        Some((MeasurementFrame::Reference, _)) | None => MeasurementFrame::Reference,
        Some((f, at)) if h.measured == MeasuredKind::Deviation && h.has(DEV) => {
            return Err(ctx.err(
                at,
                1,
                format!(
                    "\"# frame: {}\" with deviation columns (dx_mm, dy_mm, dz_mm): deviations \
                     are always in the reference frame",
                    f.name()
                ),
            ));
        }
        Some((MeasurementFrame::World, at)) if h.kind == ObsKind::MachineTool => {
            return Err(ctx.err(
                at,
                1,
                "\"# frame: world\" is for robots (the world frame of `base`); a machine tool's \
                 reference frame is its workpiece frame",
            ));
        }
        Some((f, _)) => f,
    };
    Ok(Observations {
        kind: h.kind,
        frame,
        measured: h.measured,
        columns: h.cols.iter().copied().collect(),
        rows,
    })
}

/// Reads an observation file held in memory.
pub fn parse_observations(text: &str, file: &str) -> Result<Observations> {
    read_observations(text.as_bytes(), file)
}

/// Opens and reads an observation file; errors name the path.
pub fn load_observations(path: &Path) -> Result<Observations> {
    let f = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    read_observations(std::io::BufReader::new(f), &path.display().to_string())
}

// ---------------------------------------------------------------------------
// Writing
// ---------------------------------------------------------------------------

/// Formats a number: fixed 6 decimals when that reads back to the same `f64`
/// (every value read from a file with ≤ 6 decimals), otherwise Rust's
/// shortest round-trip representation (`{}`, never an exponent). `-0` is
/// written as `0.000000`.
pub fn format_number(v: f64) -> String {
    let v = if v == 0.0 { 0.0 } else { v };
    let fixed = format!("{v:.6}");
    if fixed.parse::<f64>() == Ok(v) {
        fixed
    } else {
        format!("{v}")
    }
}

fn quote_if_needed(s: &str) -> String {
    let needs = s.is_empty()
        || s.starts_with('#')
        || s.bytes().any(|b| matches!(b, b',' | b'"' | b'\r' | b'\n'))
        || s.starts_with(is_blank_char)
        || s.ends_with(is_blank_char);
    if needs {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

fn is_blank_char(c: char) -> bool {
    c == ' ' || c == '\t'
}

/// Why a machine-tool calibration leaves measured orientations out.
pub const TOOL_ORIENTATION_UNUSED: &str = "the machine-tool model predicts the tool tip's \
    position only (its geometric and thermal errors are fitted to positions; an angular \
    error shows through the lever of the tool)";

impl Observations {
    /// Rows with a measured orientation (`qw…qz`).
    pub fn oriented_rows(&self) -> usize {
        self.rows.iter().filter(|r| r.orientation.is_some()).count()
    }

    /// What a calibration did with the measured orientations (`None` when
    /// no row has one): `used` — their residuals are in the fit, weighted
    /// `w_rot` mm/rad (0: left out, said so); otherwise `why_not` says why
    /// the model cannot use them.
    pub fn orientation_note(&self, w_rot: f64, why_not: Option<&str>) -> Option<String> {
        let n = self.oriented_rows();
        if n == 0 {
            return None;
        }
        let w = crate::error::show_number(w_rot);
        Some(match why_not {
            Some(why) => {
                format!("{n} row(s) carry a measured orientation (qw, qx, qy, qz), not used: {why}")
            }
            None if w_rot > 0.0 => format!(
                "{n} row(s) carry a measured orientation (qw, qx, qy, qz): their orientation \
                 residuals are in the fit, weighted {w} mm/rad (--orientation-weight-mm-per-rad)"
            ),
            None => format!(
                "{n} row(s) carry a measured orientation (qw, qx, qy, qz), left out by \
                 --orientation-weight-mm-per-rad 0"
            ),
        })
    }

    /// The columns [`write_observations`] writes: the declared columns that
    /// fit the kind, the required ones, and every column some row has a
    /// non-default value for. Canonical order.
    pub fn effective_columns(&self) -> BTreeSet<Column> {
        let mut set: BTreeSet<usize> = self.columns.iter().map(|c| c.idx()).collect();
        let (own, other) = match self.kind {
            ObsKind::Robot => (Q..Q + 6, TOOL_ONLY),
            ObsKind::MachineTool => (AXES..AXES + 3, ROBOT_ONLY),
        };
        set.retain(|i| !other.contains(i));
        let (mine, theirs) = match self.measured {
            MeasuredKind::Position => (POS, DEV),
            MeasuredKind::Deviation => (DEV, POS),
        };
        set.retain(|i| !(theirs..theirs + 3).contains(i));
        set.extend(own);
        set.extend(mine..mine + 3);
        for (k, r) in self.rows.iter().enumerate() {
            if r.id != (k + 1).to_string() {
                set.insert(ID);
            }
            if r.t_s.is_some() {
                set.insert(T_S);
            }
            if r.ambient_c.is_some() {
                set.insert(AMBIENT);
            }
            if r.orientation.is_some() {
                set.extend(QUAT..QUAT + 4);
            }
            for i in 0..3 {
                if r.force_n[i] != 0.0 {
                    set.insert(FORCE + i);
                }
                if r.moment_nm[i] != 0.0 {
                    set.insert(MOMENT + i);
                }
            }
            let mut opt = |start: usize, vals: &[bool]| {
                for (i, &given) in vals.iter().enumerate() {
                    if given {
                        set.insert(start + i);
                    }
                }
            };
            match (&r.pose, self.kind) {
                (Pose::Robot(p), ObsKind::Robot) => {
                    opt(MP, &[p.mp_mm.is_some(); 3]);
                    opt(WP, &[p.wp_mm.is_some(); 3]);
                    opt(P_ROBOT, &p.p_w.map(|v| v.is_some()));
                    opt(DIR_ROBOT, &p.dir.map(|v| v.is_some()));
                }
                (Pose::Tool(p), ObsKind::MachineTool) => {
                    opt(AXES + 3, &p.abc_deg.map(|v| v.is_some()));
                    opt(DIR_TOOL, &p.dir.map(|v| v.is_some()));
                    opt(TOOL_MM, &[p.tool_mm.is_some()]);
                    opt(SPINDLE_RPM, &[p.spindle_rpm.is_some()]);
                    opt(SPINDLE_W, &[p.spindle_w.is_some()]);
                    opt(P_TOOL, &p.p_w.map(|v| v.is_some()));
                }
                _ => {}
            }
        }
        set.into_iter().map(|i| Column(i as u8)).collect()
    }
}

fn cell_value(
    obs: &Observations,
    r: &Observation,
    k: usize,
    idx: usize,
    fmt: &dyn Fn(f64) -> String,
) -> Option<String> {
    let num = |v: f64| Some(fmt(v));
    let opt = |v: Option<f64>| v.map(fmt);
    let dir = |v: Option<i8>| v.map(|d| if d > 0 { "1".into() } else { "-1".into() });
    let in3 = |start: usize| (start..start + 3).contains(&idx).then(|| idx - start);
    let in6 = |start: usize| (start..start + 6).contains(&idx).then(|| idx - start);
    if idx == ID {
        return Some(if r.id.is_empty() {
            (k + 1).to_string()
        } else {
            quote_if_needed(&r.id)
        });
    }
    if idx == T_S {
        return opt(r.t_s);
    }
    if idx == AMBIENT {
        return opt(r.ambient_c);
    }
    let mine = match obs.measured {
        MeasuredKind::Position => POS,
        MeasuredKind::Deviation => DEV,
    };
    if let Some(i) = in3(mine) {
        return num(r.measured_mm[i]);
    }
    if (QUAT..QUAT + 4).contains(&idx) {
        return r.orientation.map(|q| {
            let c = [q.w, q.i, q.j, q.k];
            fmt(c[idx - QUAT])
        });
    }
    if let Some(i) = in3(FORCE) {
        return num(r.force_n[i]);
    }
    if let Some(i) = in3(MOMENT) {
        return num(r.moment_nm[i]);
    }
    match &r.pose {
        Pose::Robot(p) => {
            if let Some(i) = in6(Q) {
                return num(p.q_deg[i]);
            }
            if let Some(i) = in3(MP) {
                return p.mp_mm.and_then(|v| num(v[i]));
            }
            if let Some(i) = in3(WP) {
                return p.wp_mm.and_then(|v| num(v[i]));
            }
            if let Some(i) = in6(P_ROBOT) {
                return opt(p.p_w[i]);
            }
            if let Some(i) = in6(DIR_ROBOT) {
                return dir(p.dir[i]);
            }
        }
        Pose::Tool(p) => {
            if let Some(i) = in3(AXES) {
                return num(p.xyz_mm[i]);
            }
            if let Some(i) = in3(AXES + 3) {
                return opt(p.abc_deg[i]);
            }
            if let Some(i) = in6(DIR_TOOL) {
                return dir(p.dir[i]);
            }
            if idx == TOOL_MM {
                return opt(p.tool_mm);
            }
            if idx == SPINDLE_RPM {
                return opt(p.spindle_rpm);
            }
            if idx == SPINDLE_W {
                return opt(p.spindle_w);
            }
            if let Some(i) = in6(P_TOOL) {
                return opt(p.p_w[i]);
            }
        }
    }
    None
}

/// Writes observations as CSV: the header of [`Observations::effective_columns`]
/// (canonical order), then one line per row, numbers by [`format_number`],
/// empty cells for values not given, `\n` line ends, no comments.
/// `read_observations(write_observations(x)) == x` (equality ignores source lines).
/// Fails with `InvalidInput` when a row's pose does not match `obs.kind`.
pub fn write_observations<W: Write>(mut w: W, obs: &Observations) -> std::io::Result<()> {
    write_observations_with(&mut w, obs, &format_number)
}

/// [`write_observations`] with every number written by `num`.
pub fn write_observations_with<W: Write>(
    mut w: W,
    obs: &Observations,
    num: &dyn Fn(f64) -> String,
) -> std::io::Result<()> {
    let cols = obs.effective_columns();
    let names: Vec<&str> = cols.iter().map(|c| c.name()).collect();
    if obs.frame != MeasurementFrame::Reference {
        writeln!(w, "# frame: {}", obs.frame.name())?;
    }
    writeln!(w, "{}", names.join(","))?;
    for (k, r) in obs.rows.iter().enumerate() {
        let fits = matches!(
            (&r.pose, obs.kind),
            (Pose::Robot(_), ObsKind::Robot) | (Pose::Tool(_), ObsKind::MachineTool)
        );
        if !fits {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                format!(
                    "row {} (id {}): pose does not match the file kind",
                    k + 1,
                    r.id
                ),
            ));
        }
        let cells: Vec<String> = cols
            .iter()
            .map(|c| cell_value(obs, r, k, c.idx(), num).unwrap_or_default())
            .collect();
        writeln!(w, "{}", cells.join(","))?;
    }
    Ok(())
}

// ---------------------------------------------------------------------------
// Split and noise
// ---------------------------------------------------------------------------

/// Reproducible split of row indices `0..n` into (train, holdout), both
/// ascending. The holdout has `round(fraction · n)` rows (`fraction` clamped
/// to `[0, 1]`, NaN counts as 0), chosen by a Fisher–Yates shuffle driven by
/// [`SplitMix64`] seeded with `seed` — integer arithmetic only, so the split is
/// identical on every platform and version of this crate's PRNG.
pub fn holdout_split(n: usize, fraction: f64, seed: u64) -> (Vec<usize>, Vec<usize>) {
    let fraction = if fraction.is_nan() {
        0.0
    } else {
        fraction.clamp(0.0, 1.0)
    };
    let n_hold = ((fraction * n as f64).round() as usize).min(n);
    let mut idx: Vec<usize> = (0..n).collect();
    let mut rng = SplitMix64::new(seed);
    for i in (1..n).rev() {
        let j = rng.below(i as u64 + 1) as usize;
        idx.swap(i, j);
    }
    let mut hold = idx.split_off(n - n_hold);
    idx.sort_unstable();
    hold.sort_unstable();
    (idx, hold)
}

/// Adds independent Gaussian noise of standard deviation `sd_mm` to every
/// coordinate of every row's measured triple (x, y, z of row 1, then row 2, …),
/// from a [`SplitMix64`] seeded with `seed`. For `simulate`.
pub fn add_measurement_noise(obs: &mut Observations, sd_mm: f64, seed: u64) {
    let mut rng = SplitMix64::new(seed);
    for r in &mut obs.rows {
        for i in 0..3 {
            r.measured_mm[i] += rng.gaussian(0.0, sd_mm);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_and_columns() {
        // Bytes (0-based): 1 'a'; 5..=11 the quoted cell "b,""c"; 12 blank;
        // 13 and 14 commas → empty cell at byte 14 (column 15); 'd' at 15 (column 16).
        let c = split_cells(b" a , \"b,\"\"c\" ,,d").unwrap_or_default();
        let got: Vec<(usize, &[u8])> = c.iter().map(|c| (c.col, c.text.as_slice())).collect();
        assert_eq!(
            got,
            vec![
                (2, b"a".as_slice()),
                (6, b"b,\"c".as_slice()),
                (15, b"".as_slice()),
                (16, b"d".as_slice())
            ]
        );
        assert_eq!(split_cells(b"a,").map(|c| c.len()).ok(), Some(2));
        assert!(split_cells(b"\"abc").is_err());
        assert!(split_cells(b"a\"b").is_err());
    }

    #[test]
    fn suggestions() {
        assert_eq!(suggest("x_mn"), Some("x_mm"));
        assert_eq!(suggest("X_MM"), Some("X_mm"));
        assert_eq!(suggest("q7_deg"), Some("q1_deg"));
        assert_eq!(suggest("completely_unrelated"), None);
        assert_eq!(levenshtein(b"kitten", b"sitting"), 3);
    }

    #[test]
    fn number_format() {
        assert_eq!(format_number(-0.0), "0.000000");
        assert_eq!(format_number(1.5), "1.500000");
        assert_eq!(format_number(0.1 + 0.2), "0.30000000000000004");
        assert_eq!(format_number(1e-9), "0.000000001");
    }
}
