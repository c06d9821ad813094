//! The interactive deviation report of `report --format html`: one
//! self-contained page (styles, script and data inline; nothing fetched)
//! with the toolpath in plan (XY), side (XZ) and a turnable 3-D view
//! coloured by the predicted |deviation|, arcs (G2/G3, helices, `MoveC`)
//! drawn as arcs, holes (drilling cycles, plunges) as rings, the predicted
//! path beside the programmed one at a magnification the reader sets, the
//! block under the pointer with its source line, deviation, each effect's
//! part and the residual after compensation, and the summary tables and
//! provenance of the text report.
//!
//! The page draws on `<canvas>` elements with the script of
//! `src/emit/html/report.js`; the data are one JSON document in a
//! `<script type="application/json">` element, columns in integer units
//! (µm, 0.1 µm, nm) to keep the page small. Long programs are thinned by
//! [`Decimator`] like the SVG picture (each kept point the worst of its run
//! of blocks, so the worst blocks are always drawn); up to twice
//! [`HTML_POINTS`] moves (a 10 000-block program) are kept whole.

use std::collections::{BTreeMap, BTreeSet};

use crate::emit::svg::{Decimator, Peak};

/// A page keeps up to twice this many moves whole; a longer program is
/// thinned to between this and twice this many points.
pub const HTML_POINTS: usize = 6_000;

/// Effects a point carries at most (robots: five).
pub const MAX_EFFECTS: usize = 5;

/// The drawn shape of a move.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Shape {
    /// A straight move from start to end.
    Line,
    /// A circular arc (or helix) about `center`, turning `sweep_rad` about
    /// the unit `normal` (right-handed), the part of the move along the
    /// normal spread evenly over the sweep.
    Arc {
        /// Centre, mm (its component along the normal is the start's).
        center: [f64; 3],
        /// Unit normal of the arc's plane.
        normal: [f64; 3],
        /// Signed swept angle, rad.
        sweep_rad: f64,
    },
    /// A drilling cycle: positioning over the hole, then down to its bottom
    /// (the end point).
    Hole,
}

impl Shape {
    /// The arc through `start`, `via` and `end` (a `MoveC`), or a line when
    /// the three points are (nearly) on one line.
    pub fn through(start: [f64; 3], via: [f64; 3], end: [f64; 3]) -> Shape {
        let v = |p: [f64; 3]| nalgebra::Vector3::new(p[0], p[1], p[2]);
        let (a, b, c) = (v(start), v(via), v(end));
        let (ab, ac) = (b - a, c - a);
        let n = ab.cross(&ac);
        let n2 = n.norm_squared();
        // Collinear within 1e-9 of the chord lengths' product: a line.
        if n2 <= 1e-18 * ab.norm_squared() * ac.norm_squared() || n2 == 0.0 {
            return Shape::Line;
        }
        // Circumcentre of the triangle.
        let centre =
            a + (n.cross(&ab) * ac.norm_squared() + ac.cross(&n) * ab.norm_squared()) / (2.0 * n2);
        let normal = n / n2.sqrt();
        let (r0, r1) = (a - centre, c - centre);
        // The sweep from start to end about the normal, passing the via
        // point (the normal is oriented start → via → end, so the sweep is
        // positive).
        let mut sweep = normal.dot(&r0.cross(&r1)).atan2(r0.dot(&r1));
        if sweep <= 0.0 {
            sweep += std::f64::consts::TAU;
        }
        Shape::Arc {
            center: centre.into(),
            normal: normal.into(),
            sweep_rad: sweep,
        }
    }

    /// Points along the move from `start` to `end`: both ends of a line,
    /// an arc every 2° at most, a hole's position over it and its bottom.
    pub fn samples(&self, start: [f64; 3], end: [f64; 3]) -> Vec<[f64; 3]> {
        match *self {
            Shape::Line => vec![start, end],
            Shape::Hole => vec![start, [end[0], end[1], start[2]], end],
            Shape::Arc {
                center,
                normal,
                sweep_rad,
            } => {
                let v = |p: [f64; 3]| nalgebra::Vector3::new(p[0], p[1], p[2]);
                let (c, n) = (v(center), v(normal));
                let v0 = v(start) - c;
                let ax0 = v0.dot(&n);
                let vp = v0 - n * ax0;
                let nxv = n.cross(&vp);
                let axial = (v(end) - v(start)).dot(&n);
                let steps = (sweep_rad.abs() / 2f64.to_radians()).ceil();
                let steps = if steps.is_finite() {
                    (steps as usize).clamp(4, 360)
                } else {
                    4
                };
                (0..=steps)
                    .map(|j| {
                        if j == steps {
                            return end;
                        }
                        let s = j as f64 / steps as f64;
                        let t = sweep_rad * s;
                        (c + vp * t.cos() + nxv * t.sin() + n * (ax0 + axial * s)).into()
                    })
                    .collect()
            }
        }
    }

    /// A G2/G3 arc of the interpreter.
    pub fn of_arc(arc: &crate::program::interp::ArcGeom) -> Shape {
        let (_, _, n) = arc.plane.axes();
        let mut normal = [0.0; 3];
        normal[n] = 1.0;
        Shape::Arc {
            center: arc.center.into(),
            normal,
            sweep_rad: arc.sweep,
        }
    }
}

/// One move of the page.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Point {
    /// 1-based source line.
    pub line: usize,
    /// Index of its file (a report of several files), else 0.
    pub file: usize,
    /// Index of its motion label in [`Collector`]'s list.
    pub motion: usize,
    /// Programmed start and end, mm.
    pub start: [f64; 3],
    /// Programmed end point, mm.
    pub end: [f64; 3],
    /// Predicted deviation, attained − programmed, mm.
    pub dev: [f64; 3],
    /// Length of each effect's part, mm.
    pub effects: [f64; MAX_EFFECTS],
    /// Position error left after compensation, mm.
    pub residual: Option<f64>,
    /// Tool-axis direction error, µrad.
    pub orient_urad: f64,
    /// How the move is drawn.
    pub shape: Shape,
    /// Expanded uncertainty U (k=2) of |deviation|, mm (`None`: the
    /// machine file carries no parameter covariance).
    pub u: Option<f64>,
}

impl Peak for Point {
    fn peak(&self) -> f64 {
        let [x, y, z] = self.dev;
        let d = (x * x + y * y + z * z).sqrt();
        if d.is_finite() { d } else { 0.0 }
    }
}

/// Gathers the moves of a page as they stream by.
#[derive(Debug, Clone)]
pub struct Collector {
    points: Decimator<Point>,
    motions: Vec<String>,
    last_end: Option<[f64; 3]>,
}

impl Default for Collector {
    fn default() -> Self {
        Collector {
            points: Decimator::new(HTML_POINTS),
            motions: Vec::new(),
            last_end: None,
        }
    }
}

/// A move handed to [`Collector::push`].
#[derive(Debug, Clone, Copy)]
pub struct Move<'a> {
    /// 1-based source line and file index.
    pub at: (usize, usize),
    /// Motion label.
    pub motion: &'a str,
    /// Programmed start (`None`: where the previous move ended).
    pub start: Option<[f64; 3]>,
    /// Circle point of a `MoveC`: the move is the arc through it.
    pub via: Option<[f64; 3]>,
    /// Programmed end point, mm.
    pub end: [f64; 3],
    /// Deviation vector, mm.
    pub dev: [f64; 3],
    /// Effects' parts, mm.
    pub effects: &'a [f64],
    /// Residual after compensation, mm.
    pub residual: Option<f64>,
    /// Tool-axis direction error, µrad.
    pub orient_urad: f64,
    /// Shape.
    pub shape: Shape,
    /// Expanded uncertainty U (k=2) of |deviation|, mm.
    pub u: Option<f64>,
}

impl Collector {
    /// Adds the next move.
    pub fn push(&mut self, m: &Move) {
        let motion = match self.motions.iter().position(|s| s == m.motion) {
            Some(i) => i,
            None => {
                self.motions.push(m.motion.to_string());
                self.motions.len() - 1
            }
        };
        let start = m.start.or(self.last_end).unwrap_or(m.end);
        self.last_end = Some(m.end);
        let shape = match m.via {
            Some(via) => Shape::through(start, via, m.end),
            None => m.shape,
        };
        let mut effects = [0.0; MAX_EFFECTS];
        for (e, v) in effects.iter_mut().zip(m.effects) {
            *e = *v;
        }
        self.points.push(Point {
            line: m.at.0,
            file: m.at.1,
            motion,
            start,
            end: m.end,
            dev: m.dev,
            effects,
            residual: m.residual,
            orient_urad: m.orient_urad,
            shape,
            u: m.u,
        });
    }

    /// The points kept and the motion labels.
    pub fn finish(self) -> (Vec<Point>, Vec<String>) {
        (self.points.finish(), self.motions)
    }
}

/// A worst block in a table of the page.
#[derive(Debug, Clone, PartialEq)]
pub struct Listed {
    /// How the summary names its place (`12` or `Main.mod:12`).
    pub place: String,
    /// File index and 1-based line.
    pub at: (usize, usize),
    /// |deviation|, mm.
    pub dev_mm: f64,
    /// Motion label.
    pub motion: String,
    /// Source text (may be empty).
    pub text: String,
}

/// The statistics row of one effect (or the total).
#[derive(Debug, Clone, PartialEq)]
pub struct EffectRow {
    /// `total` or the effect's name.
    pub name: String,
    /// Mean, 95th percentile and maximum, mm.
    pub mean_p95_max: [f64; 3],
    /// The worst blocks, largest first.
    pub worst: Vec<Listed>,
}

/// A block marked in every view.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mark {
    /// File index and 1-based line.
    pub at: (usize, usize),
    /// Programmed position, mm.
    pub pos: [f64; 3],
    /// |deviation|, mm.
    pub dev: f64,
    /// The worst of the cutting moves (the overall worst: `false`).
    pub cut: bool,
    /// Expanded uncertainty U (k=2) of its |deviation|, mm.
    pub u: Option<f64>,
}

/// Everything a page shows.
#[derive(Debug, Clone)]
pub struct Doc {
    /// The headline.
    pub title: String,
    /// `gcode` or `rapid`.
    pub kind: &'static str,
    /// What the positions are (machine or world coordinates).
    pub positions: String,
    /// Effect names in breakdown order.
    pub effects: Vec<String>,
    /// Points carry the residual after compensation.
    pub residual: bool,
    /// The files' names (one for a single program).
    pub files: Vec<String>,
    /// The drawn moves and the motion labels they index.
    pub points: Vec<Point>,
    /// Motion labels.
    pub motions: Vec<String>,
    /// Which motion labels are positioning moves.
    pub positioning: Vec<bool>,
    /// Source text by (file index, line).
    pub texts: BTreeMap<(usize, usize), String>,
    /// Summary lines (cutting moves, positioning, all moves).
    pub headline: Vec<String>,
    /// Per-effect statistics.
    pub effect_rows: Vec<EffectRow>,
    /// Worst blocks by group (cutting, positioning).
    pub groups: Vec<(String, Vec<Listed>)>,
    /// Marked blocks.
    pub marks: Vec<Mark>,
    /// Provenance as `key: value` lines.
    pub provenance: Vec<String>,
    /// Blocks and moves of the program.
    pub totals: (usize, usize),
}

/// The lines of each file whose text a page quotes: the kept points'.
pub fn wanted_lines(points: &[Point]) -> BTreeMap<usize, BTreeSet<usize>> {
    let mut out: BTreeMap<usize, BTreeSet<usize>> = BTreeMap::new();
    for p in points {
        out.entry(p.file).or_default().insert(p.line);
    }
    out
}

/// Text for HTML content and attribute values.
fn esc(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            _ => out.push(c),
        }
    }
    out
}

/// A JSON string safe inside a `<script>` element (no `<`).
fn jstr(s: &str) -> String {
    serde_json::to_string(s)
        .unwrap_or_else(|_| "\"\"".into())
        .replace('<', "\\u003c")
}

/// `v` × `unit` rounded to an integer (0 when not finite).
fn int(v: f64, per_mm: f64) -> i64 {
    let x = (v * per_mm).round();
    if x.is_finite() { x as i64 } else { 0 }
}

/// A float with at most `d` decimals, trailing zeros dropped.
fn float(v: f64, d: usize) -> String {
    if !v.is_finite() {
        return "0".into();
    }
    let s = format!("{v:.d$}");
    let s = if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    };
    if s == "-0" { "0".into() } else { s }
}

/// Positions: µm.
const POS_PER_MM: f64 = 1e3;
/// Deviations and effects: 0.1 µm.
const DEV_PER_MM: f64 = 1e4;
/// Residuals: nm.
const RES_PER_MM: f64 = 1e6;

/// The page's data document (see `report.js` for its layout).
fn data_json(doc: &Doc) -> String {
    let mut rows = String::with_capacity(doc.points.len() * 64);
    let mut starts = Vec::new();
    let mut arcs = Vec::new();
    let mut src = Vec::with_capacity(doc.points.len());
    let mut prev_end: Option<[f64; 3]> = None;
    // U (k=2) of the rows that have one, in deviation units (the key
    // only when the report states U).
    let mut us = Vec::new();
    // Lines and end points as differences from the previous row (integer
    // µm, so that the sums are exact).
    let (mut line0, mut end0) = (0i64, [0i64; 3]);
    let files = doc.files.len() > 1;
    for (i, p) in doc.points.iter().enumerate() {
        if i > 0 {
            rows.push(',');
        }
        let mut r = format!("[{},{}", p.line as i64 - line0, p.motion);
        line0 = p.line as i64;
        for (v, v0) in p.end.iter().zip(end0.iter_mut()) {
            let e = int(*v, POS_PER_MM);
            r.push_str(&format!(",{}", e - *v0));
            *v0 = e;
        }
        for v in p.dev {
            r.push_str(&format!(",{}", int(v, DEV_PER_MM)));
        }
        for v in &p.effects[..doc.effects.len().min(MAX_EFFECTS)] {
            r.push_str(&format!(",{}", int(*v, DEV_PER_MM)));
        }
        r.push_str(&format!(
            ",{},{}",
            p.residual.map_or(-1, |v| int(v, RES_PER_MM).max(0)),
            int(p.orient_urad, 1.0)
        ));
        if files {
            r.push_str(&format!(",{}", p.file));
        }
        r.push(']');
        rows.push_str(&r);
        let moved = prev_end.is_none_or(|e| {
            e.iter()
                .zip(p.start)
                .any(|(a, b)| int(*a, POS_PER_MM) != int(b, POS_PER_MM))
        });
        if moved {
            let s: Vec<String> = p
                .start
                .iter()
                .map(|v| int(*v, POS_PER_MM).to_string())
                .collect();
            starts.push(format!("\"{i}\":[{}]", s.join(",")));
        }
        prev_end = Some(p.end);
        if let Some(u) = p.u {
            us.push(format!("\"{i}\":{}", int(u, DEV_PER_MM)));
        }
        match p.shape {
            Shape::Arc {
                center,
                normal,
                sweep_rad,
            } => {
                let c: Vec<String> = center
                    .iter()
                    .map(|v| int(*v, POS_PER_MM).to_string())
                    .collect();
                let n: Vec<String> = normal.iter().map(|v| float(*v, 6)).collect();
                arcs.push(format!(
                    "\"{i}\":[{},{},{}]",
                    c.join(","),
                    n.join(","),
                    float(sweep_rad, 6)
                ));
            }
            Shape::Hole | Shape::Line => {}
        }
        src.push(jstr(
            doc.texts.get(&(p.file, p.line)).map_or("", String::as_str),
        ));
    }
    let marks: Vec<String> = doc
        .marks
        .iter()
        .map(|m| {
            format!(
                "{{\"line\":{},\"file\":{},\"pos\":[{},{},{}],\"dev\":{},\"cut\":{}{}}}",
                m.at.1,
                m.at.0,
                float(m.pos[0], 4),
                float(m.pos[1], 4),
                float(m.pos[2], 4),
                float(m.dev, 6),
                m.cut,
                m.u.map_or(String::new(), |u| format!(",\"u\":{}", float(u, 6)))
            )
        })
        .collect();
    let strs = |v: &[String]| v.iter().map(|s| jstr(s)).collect::<Vec<_>>().join(",");
    let holes: Vec<String> = doc
        .motions
        .iter()
        .map(|m| (m == "cycle").to_string())
        .collect();
    let positioning: Vec<String> = doc.positioning.iter().map(|b| b.to_string()).collect();
    format!(
        "{{\"kind\":{},\"effects\":[{}],\"residual\":{},\"files\":[{}],\"motions\":[{}],\"positioning\":[{}],\"holes\":[{}],\"units\":{{\"pos_per_mm\":{},\"dev_per_mm\":{},\"res_per_mm\":{}}},\"rows\":[{rows}],\"starts\":{{{}}},\"arcs\":{{{}}},\"src\":[{}],\"marks\":[{}]{}}}",
        jstr(doc.kind),
        strs(&doc.effects),
        doc.residual,
        strs(&doc.files),
        strs(&doc.motions),
        positioning.join(","),
        holes.join(","),
        POS_PER_MM,
        DEV_PER_MM,
        RES_PER_MM,
        starts.join(","),
        arcs.join(","),
        src.join(","),
        marks.join(","),
        if us.is_empty() {
            String::new()
        } else {
            format!(",\"u\":{{{}}}", us.join(","))
        }
    )
}

/// A number in mm with 5 decimals for the tables.
fn mm(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.5}")
    } else {
        "nan".into()
    }
}

/// A clickable place of a worst block.
fn place_link(l: &Listed) -> String {
    format!(
        "<a href=\"#\" class=\"block\" data-file=\"{}\" data-line=\"{}\">{}</a>",
        l.at.0,
        l.at.1,
        esc(&l.place)
    )
}

/// The summary tables as HTML.
fn tables(doc: &Doc) -> String {
    let mut h = String::new();
    h.push_str("<section id=\"summary\"><h2>Summary</h2>\n<ul class=\"headline\">\n");
    for line in &doc.headline {
        h.push_str(&format!("<li>{}</li>\n", esc(line)));
    }
    h.push_str(&format!(
        "<li>{} blocks, {} moves; positions: {}</li>\n</ul>\n",
        doc.totals.0,
        doc.totals.1,
        esc(&doc.positions)
    ));
    h.push_str("<table id=\"effects\"><thead><tr><th>effect</th><th>mean (mm)</th><th>p95 (mm)</th><th>max (mm)</th><th>worst blocks: line (mm)</th></tr></thead><tbody>\n");
    for r in &doc.effect_rows {
        let worst: Vec<String> = r
            .worst
            .iter()
            .map(|l| format!("{} ({})", place_link(l), mm(l.dev_mm)))
            .collect();
        h.push_str(&format!(
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>\n",
            esc(&r.name),
            mm(r.mean_p95_max[0]),
            mm(r.mean_p95_max[1]),
            mm(r.mean_p95_max[2]),
            worst.join(", ")
        ));
    }
    h.push_str("</tbody></table>\n");
    for (title, list) in &doc.groups {
        if list.is_empty() {
            continue;
        }
        h.push_str(&format!(
            "<h3>{}</h3>\n<table class=\"worst\"><thead><tr><th>line</th><th>|dev| (mm)</th><th>motion</th><th>source</th></tr></thead><tbody>\n",
            esc(title)
        ));
        for l in list {
            h.push_str(&format!(
                "<tr><td>{}</td><td>{}</td><td>{}</td><td><code>{}</code></td></tr>\n",
                place_link(l),
                mm(l.dev_mm),
                esc(&l.motion),
                esc(&l.text)
            ));
        }
        h.push_str("</tbody></table>\n");
    }
    h.push_str("</section>\n");
    if !doc.provenance.is_empty() {
        h.push_str("<section id=\"provenance\"><h2>Provenance</h2>\n<dl>\n");
        for line in &doc.provenance {
            let (k, v) = line.split_once(": ").unwrap_or((line, ""));
            h.push_str(&format!("<dt>{}</dt><dd>{}</dd>\n", esc(k), esc(v)));
        }
        h.push_str("</dl></section>\n");
    }
    h
}

/// The page's style sheet.
const STYLE: &str = include_str!("html/report.css");
/// The page's script.
const SCRIPT: &str = include_str!("html/report.js");

/// Records script errors on the document element (`data-errors`) before
/// the page's script runs, so that a test can read them back.
const ERROR_TRAP: &str = "window.addEventListener('error',function(e){var d=document.documentElement;d.setAttribute('data-errors',(d.getAttribute('data-errors')||'')+(e.message||'error')+';');});";

/// The page: every style, script and datum inline.
pub fn render(doc: &Doc) -> String {
    let data = data_json(doc);
    let mut h = String::with_capacity(data.len() + STYLE.len() + SCRIPT.len() + 8192);
    h.push_str("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n");
    h.push_str(&format!("<title>{}</title>\n", esc(&doc.title)));
    h.push_str(&format!("<script>{ERROR_TRAP}</script>\n"));
    h.push_str(&format!("<style>\n{STYLE}</style>\n</head>\n<body>\n"));
    h.push_str(&format!("<h1>{}</h1>\n", esc(&doc.title)));
    h.push_str(include_str!("html/controls.html"));
    h.push_str(&tables(doc));
    h.push_str(&format!(
        "<script type=\"application/json\" id=\"report-data\">{data}</script>\n"
    ));
    h.push_str(&format!("<script>\n{SCRIPT}</script>\n</body>\n</html>\n"));
    h
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    const TOL: f64 = 1e-9;

    #[test]
    fn circle_through_three_points() {
        // A quarter circle of radius 10 about (5, 5, 2), in XY, via its
        // 45° point: centre, +Z normal, sweep π/2.
        let r = 10.0;
        let c = [5.0, 5.0, 2.0];
        let at = |a: f64| [c[0] + r * a.cos(), c[1] + r * a.sin(), c[2]];
        let s = Shape::through(
            at(0.0),
            at(std::f64::consts::FRAC_PI_4),
            at(std::f64::consts::FRAC_PI_2),
        );
        let Shape::Arc {
            center,
            normal,
            sweep_rad,
        } = s
        else {
            panic!("an arc: {s:?}");
        };
        for k in 0..3 {
            assert_abs_diff_eq!(center[k], c[k], epsilon = TOL);
        }
        assert_abs_diff_eq!(normal[2], 1.0, epsilon = TOL);
        assert_abs_diff_eq!(sweep_rad, std::f64::consts::FRAC_PI_2, epsilon = TOL);
        // The other way round (clockwise seen from +Z): the normal flips,
        // the sweep stays positive about it.
        let s = Shape::through(
            at(std::f64::consts::FRAC_PI_2),
            at(std::f64::consts::FRAC_PI_4),
            at(0.0),
        );
        let Shape::Arc {
            normal, sweep_rad, ..
        } = s
        else {
            panic!("an arc");
        };
        assert_abs_diff_eq!(normal[2], -1.0, epsilon = TOL);
        assert_abs_diff_eq!(sweep_rad, std::f64::consts::FRAC_PI_2, epsilon = TOL);
        // Three-quarters: via beyond the end's side.
        let s = Shape::through(
            at(0.0),
            at(std::f64::consts::PI),
            at(-std::f64::consts::FRAC_PI_2),
        );
        let Shape::Arc { sweep_rad, .. } = s else {
            panic!("an arc");
        };
        assert_abs_diff_eq!(sweep_rad, 1.5 * std::f64::consts::PI, epsilon = TOL);
    }

    #[test]
    fn arc_samples_follow_the_circle() {
        // Half circle about the origin from (10, 0, 0) clockwise (about
        // -Z) to (-10, 0, -2): through (0, -10, -1) halfway.
        let s = Shape::Arc {
            center: [0.0; 3],
            normal: [0.0, 0.0, -1.0],
            sweep_rad: std::f64::consts::PI,
        };
        let pts = s.samples([10.0, 0.0, 0.0], [-10.0, 0.0, -2.0]);
        assert_eq!(pts.len(), 91);
        let mid = pts[45];
        assert_abs_diff_eq!(mid[0], 0.0, epsilon = TOL);
        assert_abs_diff_eq!(mid[1], -10.0, epsilon = TOL);
        assert_abs_diff_eq!(mid[2], -1.0, epsilon = TOL);
        assert_eq!(pts[90], [-10.0, 0.0, -2.0]);
    }

    #[test]
    fn collinear_points_are_a_line() {
        let s = Shape::through([0.0; 3], [1.0, 1.0, 1.0], [2.0, 2.0, 2.0]);
        assert_eq!(s, Shape::Line);
        assert_eq!(Shape::through([0.0; 3], [0.0; 3], [0.0; 3]), Shape::Line);
    }

    #[test]
    fn script_text_cannot_close_its_element() {
        assert_eq!(jstr("</script><b>"), "\"\\u003c/script>\\u003cb>\"");
        assert_eq!(esc("a<b & \"c\""), "a&lt;b &amp; &quot;c&quot;");
    }

    #[test]
    fn numbers_are_compact() {
        assert_eq!(float(1.5, 6), "1.5");
        assert_eq!(float(-0.0000001, 3), "0");
        assert_eq!(float(2.0, 3), "2");
        assert_eq!(int(0.0123456, DEV_PER_MM), 123);
        assert_eq!(int(f64::NAN, POS_PER_MM), 0);
    }
}
