//! The deviation picture of `report --format svg`: the toolpath in plan (XY)
//! and side (XZ) view coloured by the predicted |deviation|, the deviation
//! along the program, a colour bar, the worst block marked, and the cutting
//! moves' predicted deviation before compensation next to the residual
//! after it — drawn with `plotters` (SVG backend, no system fonts).
//!
//! The two series of the before/after panel are written as SVG groups of
//! their own (`<g id="before-after">` holding `before-after-before`,
//! `before-after-after` and the legend), on the panel's axes, so that a
//! reader or a program can pick them out.
//!
//! Long programs are decimated into a bounded number of points by
//! [`Decimator`]: contiguous buckets of blocks, each represented by its block
//! of largest deviation, so peaks survive and the output is the same bytes
//! on every run.

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::emit::html::{MAX_EFFECTS, Shape};
use crate::error::{Error, Result};

/// Canvas size, pixels.
const SIZE: (u32, u32) = (1200, 1240);
/// Height of the toolpath views' row, pixels.
const VIEWS_H: u32 = 500;
/// Height of the deviation-along-the-program panel, pixels (the
/// before/after panel takes the rest).
const ALONG_H: u32 = 350;
/// Colour of the before-compensation series.
const BEFORE: RGBColor = RGBColor(59, 82, 139);
/// Colour of the after-compensation series.
const AFTER: RGBColor = RGBColor(230, 110, 0);
/// Width of the colour-bar column, pixels.
const BAR_W: u32 = 130;
/// Colour levels of the toolpath (runs of one level become one polyline).
const LEVELS: usize = 32;

/// One programmed point of the picture.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlotPoint {
    /// 1-based source line.
    pub line: usize,
    /// Programmed tool-tip position, mm.
    pub pos: [f64; 3],
    /// Predicted |deviation|, mm.
    pub dev: f64,
    /// A positioning move (rapid, joint move), drawn thin.
    pub rapid: bool,
    /// Predicted position error left after compensation, mm (`None` when
    /// the report does not predict it: robot programs).
    pub residual: Option<f64>,
    /// Programmed start (`None`: the previous point's position).
    pub start: Option<[f64; 3]>,
    /// How the move is drawn: arcs as arcs, holes ringed in plan view.
    pub shape: Shape,
    /// Length of each effect's part, mm, in the report's effect order.
    pub parts: [f64; MAX_EFFECTS],
}

impl PlotPoint {
    /// Points along the move (`prev`: the point before it).
    fn path(&self, prev: Option<&PlotPoint>) -> Vec<[f64; 3]> {
        let start = self.start.or(prev.map(|p| p.pos)).unwrap_or(self.pos);
        self.shape.samples(start, self.pos)
    }

    /// A hole (drilling cycle) or a straight plunge on the spot: ringed in
    /// plan view, where its line has no length.
    fn hole(&self, prev: Option<&PlotPoint>) -> bool {
        let start = self.start.or(prev.map(|p| p.pos)).unwrap_or(self.pos);
        match self.shape {
            Shape::Hole => true,
            Shape::Line => {
                !self.rapid
                    && (self.pos[0] - start[0]).hypot(self.pos[1] - start[1]) < PLUNGE_XY_MM
                    && start[2] - self.pos[2] > PLUNGE_Z_MM
            }
            Shape::Arc { .. } => false,
        }
    }
}

/// A straight cutting move counts as a plunge (a hole) when it moves less
/// than this across and more than [`PLUNGE_Z_MM`] down, mm.
pub const PLUNGE_XY_MM: f64 = 0.05;
/// Depth of a plunge, mm.
pub const PLUNGE_Z_MM: f64 = 0.5;

/// A block marked in the picture: the largest deviation of all moves, and
/// the largest of the cutting moves (where it lands on the part).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Worst {
    /// 1-based source line.
    pub line: usize,
    /// Programmed tool-tip position, mm.
    pub pos: [f64; 3],
    /// Predicted |deviation|, mm.
    pub dev: f64,
    /// A cutting move (feed, arc, cycle, MoveL/MoveC): labelled "cut".
    pub cut: bool,
    /// Expanded uncertainty U (k=2) of its |deviation|, mm (`None`: the
    /// machine file carries no parameter covariance).
    pub u: Option<f64>,
}

const MARK_ALL: RGBColor = RGBColor(220, 30, 30);
const MARK_CUT: RGBColor = RGBColor(230, 110, 0);

fn mark_style(w: &Worst) -> (RGBColor, &'static str) {
    if w.cut {
        (MARK_CUT, "max cutting")
    } else {
        (MARK_ALL, "max")
    }
}

/// Keeps at most about `2 × cap` points of a stream of any length: the stream
/// is cut into buckets of `stride` consecutive points, each kept as its point
/// of largest deviation (the earlier one on ties); when the buffer is full,
/// neighbouring buckets merge and the stride doubles. Deterministic.
#[derive(Debug, Clone)]
pub struct Decimator<T = PlotPoint> {
    cap: usize,
    stride: usize,
    in_bucket: usize,
    bucket: Option<T>,
    points: Vec<T>,
}

/// What a [`Decimator`] keeps of each bucket: the point of largest value.
pub trait Peak {
    /// The value compared (|deviation|, mm).
    fn peak(&self) -> f64;
}

impl Peak for PlotPoint {
    fn peak(&self) -> f64 {
        self.dev
    }
}

fn larger<T: Peak>(a: T, b: T) -> T {
    if b.peak() > a.peak() { b } else { a }
}

impl<T: Peak + Copy> Decimator<T> {
    /// A decimator keeping between `cap` and `2 × cap` points (cap ≥ 2).
    pub fn new(cap: usize) -> Self {
        let cap = cap.max(2);
        Decimator {
            cap,
            stride: 1,
            in_bucket: 0,
            bucket: None,
            points: Vec::with_capacity(2 * cap),
        }
    }

    /// Adds the next point.
    pub fn push(&mut self, p: T) {
        self.bucket = Some(match self.bucket {
            Some(b) => larger(b, p),
            None => p,
        });
        self.in_bucket += 1;
        if self.in_bucket >= self.stride {
            if let Some(b) = self.bucket.take() {
                self.points.push(b);
            }
            self.in_bucket = 0;
            if self.points.len() >= 2 * self.cap {
                let merged: Vec<T> = self
                    .points
                    .chunks(2)
                    .map(|c| c.iter().copied().reduce(larger).unwrap_or(c[0]))
                    .collect();
                self.points = merged;
                self.stride *= 2;
            }
        }
    }

    /// The points kept, in program order.
    pub fn finish(mut self) -> Vec<T> {
        if let Some(b) = self.bucket.take() {
            self.points.push(b);
        }
        self.points
    }
}

fn plot_err<E: std::error::Error + Send + Sync>(e: DrawingAreaErrorKind<E>) -> Error {
    Error::io("svg", std::io::Error::other(e.to_string()))
}

/// Viridis-like colour of `t` in [0, 1] (dark blue → green → yellow).
pub fn colour(t: f64) -> RGBColor {
    const STOPS: [(f64, f64, f64); 5] = [
        (68.0, 1.0, 84.0),
        (59.0, 82.0, 139.0),
        (33.0, 145.0, 140.0),
        (94.0, 201.0, 98.0),
        (253.0, 231.0, 37.0),
    ];
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let x = t * (STOPS.len() - 1) as f64;
    let i = (x.floor() as usize).min(STOPS.len() - 2);
    let f = x - i as f64;
    let (a, b) = (STOPS[i], STOPS[i + 1]);
    let mix = |p: f64, q: f64| (p + (q - p) * f).round().clamp(0.0, 255.0) as u8;
    RGBColor(mix(a.0, b.0), mix(a.1, b.1), mix(a.2, b.2))
}

/// The colour scale, mm: `lo` and below darkest, `hi` and above brightest.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Scale {
    lo: f64,
    hi: f64,
}

impl Scale {
    /// The range of the cutting moves' deviations (the part), so that its
    /// variation uses every colour; rapids beyond it saturate. Without
    /// cutting moves, 0 … the largest deviation.
    fn of(points: &[PlotPoint], marks: &[Worst]) -> Scale {
        let range = |it: &mut dyn Iterator<Item = f64>| {
            it.filter(|d| d.is_finite())
                .fold((f64::INFINITY, 0.0f64), |(lo, hi), d| {
                    (lo.min(d), hi.max(d))
                })
        };
        let (lo, hi) = range(&mut points.iter().filter(|p| !p.rapid).map(|p| p.dev));
        if hi > 0.0 && hi - lo > 1e-6 {
            return Scale { lo, hi };
        }
        let (_, hi) = range(
            &mut points
                .iter()
                .map(|p| p.dev)
                .chain(marks.iter().map(|w| w.dev)),
        );
        Scale {
            lo: 0.0,
            hi: if hi > 0.0 { hi } else { 1e-3 },
        }
    }
}

fn level(dev: f64, s: &Scale) -> usize {
    let t = (dev - s.lo) / (s.hi - s.lo);
    if t.is_finite() {
        ((t.max(0.0) * LEVELS as f64) as usize).min(LEVELS - 1)
    } else {
        0
    }
}

fn level_colour(l: usize) -> RGBColor {
    colour((l as f64 + 0.5) / LEVELS as f64)
}

/// The part of the segment `p`–`q` inside the rectangle `(x0, x1, y0, y1)`
/// (Liang–Barsky), or `None` when none of it is.
fn clip(
    p: (f64, f64),
    q: (f64, f64),
    (x0, x1, y0, y1): (f64, f64, f64, f64),
) -> Option<((f64, f64), (f64, f64))> {
    let (dx, dy) = (q.0 - p.0, q.1 - p.1);
    let (mut t0, mut t1) = (0.0_f64, 1.0_f64);
    for (pk, qk) in [
        (-dx, p.0 - x0),
        (dx, x1 - p.0),
        (-dy, p.1 - y0),
        (dy, y1 - p.1),
    ] {
        if pk == 0.0 {
            if qk < 0.0 {
                return None;
            }
        } else {
            let t = qk / pk;
            if pk < 0.0 {
                t0 = t0.max(t);
            } else {
                t1 = t1.min(t);
            }
        }
    }
    if t0 > t1 {
        return None;
    }
    let at = |t: f64| (p.0 + t * dx, p.1 + t * dy);
    Some((
        if t0 > 0.0 { at(t0) } else { p },
        if t1 < 1.0 { at(t1) } else { q },
    ))
}

/// Axis ranges with equal mm per pixel on both axes for a plot area of
/// `px` × `py` pixels.
fn equal_ranges(
    xs: (f64, f64),
    ys: (f64, f64),
    px: f64,
    py: f64,
) -> (std::ops::Range<f64>, std::ops::Range<f64>) {
    let span = |r: (f64, f64)| (r.1 - r.0).max(1.0) * 1.08;
    let scale = (span(xs) / px).max(span(ys) / py);
    let (cx, cy) = ((xs.0 + xs.1) / 2.0, (ys.0 + ys.1) / 2.0);
    let (hx, hy) = (scale * px / 2.0, scale * py / 2.0);
    (cx - hx..cx + hx, cy - hy..cy + hy)
}

/// Decimals that tell apart the ten or so ticks of an axis spanning
/// `range` (0 for spans of 10 and more, at most 6).
fn tick_decimals(range: &std::ops::Range<f64>) -> usize {
    let step = (range.end - range.start).abs() / 10.0;
    if !(step.is_finite() && step > 0.0) {
        return 0;
    }
    (-step.log10()).ceil().clamp(0.0, 6.0) as usize
}

/// A tick label with `d` decimals, never `-0`.
fn tick_label(v: f64, d: usize) -> String {
    let s = format!("{v:.d$}");
    match s.strip_prefix('-') {
        Some(rest) if rest.bytes().all(|b| b == b'0' || b == b'.') => rest.to_string(),
        _ => s,
    }
}

/// A tick label of a source-line axis: whole lines only (ticks between
/// two lines get none).
fn line_label(v: f64) -> String {
    if v.fract() == 0.0 {
        tick_label(v, 0)
    } else {
        String::new()
    }
}

/// A chart of the toolpath views.
type ViewChart<'a, 'b> = ChartContext<
    'a,
    SVGBackend<'b>,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

/// Draws the polyline `run` (when it has a segment) and empties it.
fn flush(chart: &mut ViewChart, run: &mut Vec<(f64, f64)>, style: ShapeStyle) -> Result<()> {
    if run.len() > 1 {
        chart
            .draw_series(std::iter::once(PathElement::new(
                std::mem::take(run),
                style,
            )))
            .map_err(plot_err)?;
    }
    run.clear();
    Ok(())
}

/// One projection of the toolpath (axes `a`, `b` of the position).
#[allow(clippy::too_many_arguments)]
fn view(
    area: &DrawingArea<SVGBackend, Shift>,
    points: &[PlotPoint],
    marks: &[Worst],
    (a, b): (usize, usize),
    caption: &str,
    (xdesc, ydesc): (&str, &str),
    scale: &Scale,
) -> Result<()> {
    // The view fits the cutting moves (both ends of each), so that rapids
    // to far places (G28, a tool change position) do not shrink the part;
    // without cutting moves it fits every point.
    let cutting = points.iter().any(|p| !p.rapid);
    let fitted =
        |i: usize| !cutting || !points[i].rapid || points.get(i + 1).is_some_and(|n| !n.rapid);
    let bounds = |k: usize| {
        (0..points.len())
            .filter(|&i| fitted(i))
            .fold((f64::INFINITY, f64::NEG_INFINITY), |r, i| {
                let v = points[i].pos.get(k).copied().unwrap_or(0.0);
                (r.0.min(v), r.1.max(v))
            })
    };
    let (mut xs, mut ys) = (bounds(a), bounds(b));
    if !(xs.0.is_finite() && xs.1.is_finite() && ys.0.is_finite() && ys.1.is_finite()) {
        (xs, ys) = ((0.0, 1.0), (0.0, 1.0));
    }
    let (w, h) = area.dim_in_pixel();
    // Plot area: minus label areas (70 left, 45 bottom), margins and caption.
    let (px, py) = (w as f64 - 70.0 - 30.0, h as f64 - 45.0 - 60.0);
    let (xr, yr) = equal_ranges(xs, ys, px.max(10.0), py.max(10.0));
    let (dx, dy) = (tick_decimals(&xr), tick_decimals(&yr));
    let rect = (xr.start, xr.end, yr.start, yr.end);
    let mut chart = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", 18))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(xr, yr)
        .map_err(plot_err)?;
    chart
        .configure_mesh()
        .x_desc(xdesc)
        .y_desc(ydesc)
        .x_label_formatter(&|v| tick_label(*v, dx))
        .y_label_formatter(&|v| tick_label(*v, dy))
        .label_style(("sans-serif", 13))
        .axis_desc_style(("sans-serif", 14))
        .light_line_style(RGBColor(235, 235, 235))
        .bold_line_style(RGBColor(215, 215, 215))
        .draw()
        .map_err(plot_err)?;
    let at = |p: &[f64; 3]| {
        (
            p.get(a).copied().unwrap_or(0.0),
            p.get(b).copied().unwrap_or(0.0),
        )
    };
    // Runs of moves with the same colour level and kind: one polyline
    // each (arcs along their arc), cut at the view's edges (a rapid leaving
    // the view is drawn up to its edge).
    let mut i = 1;
    while i < points.len() {
        let key = (level(points[i].dev, scale), points[i].rapid);
        let style = level_colour(key.0).stroke_width(if key.1 { 1 } else { 3 });
        let mut run: Vec<(f64, f64)> = Vec::new();
        let mut j = i;
        while j < points.len() && (j == i || (level(points[j].dev, scale), points[j].rapid) == key)
        {
            let path = points[j].path(points.get(j - 1));
            for w in path.windows(2) {
                match clip(at(&w[0]), at(&w[1]), rect) {
                    Some((p, q)) => {
                        if run.last() != Some(&p) {
                            flush(&mut chart, &mut run, style)?;
                            run.push(p);
                        }
                        run.push(q);
                    }
                    None => flush(&mut chart, &mut run, style)?,
                }
            }
            j += 1;
        }
        flush(&mut chart, &mut run, style)?;
        i = j;
    }
    // Holes and plunges: a ring in plan view, where they have no length.
    if (a, b) == (0, 1) {
        for (k, p) in points.iter().enumerate() {
            if !p.hole(k.checked_sub(1).and_then(|k| points.get(k))) {
                continue;
            }
            let c = at(&p.pos);
            if !(rect.0..=rect.1).contains(&c.0) || !(rect.2..=rect.3).contains(&c.1) {
                continue;
            }
            let fill = level_colour(level(p.dev, scale));
            chart
                .draw_series(std::iter::once(
                    EmptyElement::at(c)
                        + Circle::new((0, 0), 5, fill.filled())
                        + Circle::new((0, 0), 5, RGBColor(34, 34, 34).stroke_width(1)),
                ))
                .map_err(plot_err)?;
        }
    }
    // Circles on the marks; their meaning in a boxed legend in the upper
    // left corner, so labels never cover each other or the toolpath's ends.
    for wp in marks {
        let (colour, label) = mark_style(wp);
        let c = (
            wp.pos.get(a).copied().unwrap_or(0.0),
            wp.pos.get(b).copied().unwrap_or(0.0),
        );
        // A mark outside the view (a far rapid) is named in the title and
        // the deviation plot only.
        if !(rect.0..=rect.1).contains(&c.0) || !(rect.2..=rect.3).contains(&c.1) {
            continue;
        }
        chart
            .draw_series(std::iter::once(
                EmptyElement::at(c) + Circle::new((0, 0), 9, colour.stroke_width(3)),
            ))
            .map_err(plot_err)?
            .label(match wp.u {
                Some(u) => format!("{label}, line {} ({:.4} mm, U {u:.4})", wp.line, wp.dev),
                None => format!("{label}, line {} ({:.4} mm)", wp.line, wp.dev),
            })
            .legend(move |(x, y)| Circle::new((x + 8, y), 6, colour.stroke_width(3)));
    }
    if !marks.is_empty() {
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(0.4))
            .label_font(("sans-serif", 13))
            .draw()
            .map_err(plot_err)?;
    }
    Ok(())
}

/// The colour bar over the scale's range, mm.
fn colour_bar(area: &DrawingArea<SVGBackend, Shift>, scale: &Scale) -> Result<()> {
    let mut chart = ChartBuilder::on(area)
        .caption("|dev| (mm)", ("sans-serif", 15))
        .margin_top(15)
        .margin_bottom(60)
        .margin_right(20)
        .y_label_area_size(80)
        .build_cartesian_2d(0.0..1.0, scale.lo..scale.hi)
        .map_err(plot_err)?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .disable_y_mesh()
        .x_labels(0)
        .y_labels(8)
        .y_desc("cutting moves' range; beyond it saturates")
        .label_style(("sans-serif", 13))
        .axis_desc_style(("sans-serif", 14))
        .y_label_formatter(&|v| tick_label(*v, 4))
        .draw()
        .map_err(plot_err)?;
    chart
        .draw_series((0..LEVELS).map(|l| {
            let step = (scale.hi - scale.lo) / LEVELS as f64;
            let lo = scale.lo + step * l as f64;
            let hi = lo + step;
            Rectangle::new([(0.0, lo), (1.0, hi)], level_colour(l).filled())
        }))
        .map_err(plot_err)?;
    Ok(())
}

/// The range of source lines a panel spans (at least one line wide).
fn line_range<'a>(lines: impl Iterator<Item = &'a PlotPoint> + Clone) -> std::ops::Range<f64> {
    let first = lines.clone().next().map_or(0, |p| p.line) as f64;
    let last = lines.last().map_or(1, |p| p.line) as f64;
    first..if last > first { last } else { first + 1.0 }
}

/// A chart of deviations (0..`ymax` mm) against the source lines `x`, with
/// its caption, axes and grid drawn.
fn line_chart<'a, 'b>(
    area: &'a DrawingArea<SVGBackend<'b>, Shift>,
    caption: &str,
    x: std::ops::Range<f64>,
    ymax: f64,
    (x_desc, y_desc): (&str, &str),
) -> Result<
    ChartContext<
        'a,
        SVGBackend<'b>,
        Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
    >,
> {
    let mut chart = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", 18))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(x, 0.0..ymax)
        .map_err(plot_err)?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .x_label_formatter(&|v| line_label(*v))
        .label_style(("sans-serif", 13))
        .axis_desc_style(("sans-serif", 14))
        .y_label_formatter(&|v| tick_label(*v, 4))
        .light_line_style(RGBColor(235, 235, 235))
        .bold_line_style(RGBColor(215, 215, 215))
        .draw()
        .map_err(plot_err)?;
    Ok(chart)
}

/// |deviation| against the source line.
fn along(
    area: &DrawingArea<SVGBackend, Shift>,
    points: &[PlotPoint],
    marks: &[Worst],
    dmax: f64,
    scale: &Scale,
) -> Result<()> {
    let x = line_range(points.iter());
    let mut chart = line_chart(
        area,
        "Predicted |deviation| along the program",
        x,
        dmax * 1.1,
        ("source line", "|deviation| (mm)"),
    )?;
    chart
        .draw_series(LineSeries::new(
            points.iter().map(|p| (p.line as f64, p.dev)),
            RGBColor(59, 82, 139).stroke_width(1),
        ))
        .map_err(plot_err)?;
    chart
        .draw_series(points.iter().map(|p| {
            Circle::new(
                (p.line as f64, p.dev),
                2,
                level_colour(level(p.dev, scale)).filled(),
            )
        }))
        .map_err(plot_err)?;
    for wp in marks {
        let (colour, label) = mark_style(wp);
        let c = (wp.line as f64, wp.dev);
        chart
            .draw_series(std::iter::once(
                EmptyElement::at(c)
                    + Circle::new((0, 0), 7, colour.stroke_width(2))
                    + Text::new(
                        format!("{label} {:.4} mm, line {}", wp.dev, wp.line),
                        (10, -18),
                        ("sans-serif", 14).into_font().color(&colour),
                    ),
            ))
            .map_err(plot_err)?;
    }
    Ok(())
}

/// `x` in `[lo, hi]` mapped linearly onto the pixels `[p0, p1]`.
fn to_pixel(x: f64, (lo, hi): (f64, f64), (p0, p1): (f64, f64)) -> f64 {
    let t = if hi > lo { (x - lo) / (hi - lo) } else { 0.0 };
    p0 + t.clamp(-0.05, 1.05) * (p1 - p0)
}

/// One series of the before/after panel as an SVG group: a polyline
/// through its points and a dot on each.
fn series_group(id: &str, colour: RGBColor, pixels: &[(f64, f64)]) -> String {
    let RGBColor(r, g, b) = colour;
    let stroke = format!("#{r:02X}{g:02X}{b:02X}");
    let mut out = format!("<g id=\"{id}\" fill=\"{stroke}\" stroke=\"{stroke}\">\n");
    if !pixels.is_empty() {
        let pts: Vec<String> = pixels
            .iter()
            .map(|(x, y)| format!("{x:.1},{y:.1}"))
            .collect();
        out.push_str(&format!(
            "<polyline fill=\"none\" stroke-width=\"2\" points=\"{}\"/>\n",
            pts.join(" ")
        ));
        for (x, y) in pixels {
            out.push_str(&format!(
                "<circle cx=\"{x:.1}\" cy=\"{y:.1}\" r=\"2.5\" stroke=\"none\"/>\n"
            ));
        }
    }
    out.push_str("</g>\n");
    out
}

/// Smallest deviation the before/after panel's logarithmic axis shows,
/// mm (1 nm): a residual below it, or zero, is drawn on the axis's floor.
const LOG_FLOOR_MM: f64 = 1e-6;

/// Colours of the effects' series of a robot's panel, in effect order.
const PART_COLOURS: [RGBColor; MAX_EFFECTS] = [
    RGBColor(230, 110, 0),
    RGBColor(200, 30, 30),
    RGBColor(33, 145, 140),
    RGBColor(150, 60, 170),
    RGBColor(120, 120, 120),
];

/// A tick label of a logarithmic deviation axis.
fn log_label(v: f64) -> String {
    if v >= 1e-3 {
        tick_label(v, 3)
    } else {
        format!("{v:.0e}")
    }
}

/// One series of the panel: its group id, colour, legend text and value
/// at each cutting move.
type Series = (String, RGBColor, String, Vec<f64>);

/// The before/after panel: for each cutting move along the program, the
/// predicted |deviation| without compensation and the predicted residual
/// after it, on a logarithmic deviation axis (the residual is orders of
/// magnitude smaller). A robot report predicts no residual: the panel shows
/// the deviation and each effect's part instead, on a linear axis.
/// Plotters draws the axes; the series and the legend come back as SVG
/// markup to append to the document.
fn before_after(
    area: &DrawingArea<SVGBackend, Shift>,
    points: &[PlotPoint],
    effects: &[&str],
) -> Result<String> {
    let cuts: Vec<&PlotPoint> = points.iter().filter(|p| !p.rapid).collect();
    let residuals = !cuts.is_empty() && cuts.iter().all(|p| p.residual.is_some());
    let x = line_range(cuts.iter().copied());
    let (first, last) = (x.start, x.end);
    let mut series: Vec<Series> = vec![(
        "before-after-before".into(),
        BEFORE,
        "before compensation: predicted |deviation| (dev_mm)".into(),
        cuts.iter().map(|p| p.dev).collect(),
    )];
    if residuals {
        series.push((
            "before-after-after".into(),
            AFTER,
            "after compensation: predicted residual (residual_mm; ≤ 1 nm on the floor)".into(),
            cuts.iter().map(|p| p.residual.unwrap_or(0.0)).collect(),
        ));
    } else {
        for (k, name) in effects.iter().enumerate().take(MAX_EFFECTS) {
            series.push((
                format!("before-after-part-{name}"),
                PART_COLOURS[k],
                format!("{name} part ({name}_mm)"),
                cuts.iter().map(|p| p.parts[k]).collect(),
            ));
        }
    }
    let top = series
        .iter()
        .flat_map(|s| s.3.iter().copied())
        .filter(|d| d.is_finite())
        .fold(0.0, f64::max);
    let caption = if residuals {
        "Cutting moves: predicted deviation before and after compensation (log scale)"
    } else {
        "Cutting moves: predicted deviation and each effect's part (no residual is predicted for robots)"
    };
    let desc = ("source line (cutting moves)", "deviation (mm)");
    // Pixel range of the plot and the map of a value onto its rows.
    let (px, py, ylo, yhi, log) = if residuals {
        let lo = series
            .iter()
            .flat_map(|s| s.3.iter().copied())
            .filter(|d| d.is_finite() && *d >= LOG_FLOOR_MM)
            .fold(f64::INFINITY, f64::min);
        let lo = if lo.is_finite() { lo } else { LOG_FLOOR_MM };
        // A value below the floor (a residual of zero) puts the floor on
        // the axis, so the gap between before and after shows.
        let below = series
            .iter()
            .flat_map(|s| s.3.iter())
            .any(|d| !(d.is_finite() && *d >= LOG_FLOOR_MM));
        let ylo = if below {
            LOG_FLOOR_MM
        } else {
            10f64.powf(lo.log10().floor()).max(LOG_FLOOR_MM)
        };
        // Two decades of headroom for the legend.
        let yhi = 10f64.powf(top.max(ylo * 10.0).log10().ceil() + 1.0);
        let mut chart = ChartBuilder::on(area)
            .caption(caption, ("sans-serif", 18))
            .margin(15)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d(x.clone(), (ylo..yhi).log_scale())
            .map_err(plot_err)?;
        chart
            .configure_mesh()
            .x_desc(desc.0)
            .y_desc(desc.1)
            .x_label_formatter(&|v| line_label(*v))
            .y_label_formatter(&|v| log_label(*v))
            .label_style(("sans-serif", 13))
            .axis_desc_style(("sans-serif", 14))
            .light_line_style(RGBColor(235, 235, 235))
            .bold_line_style(RGBColor(215, 215, 215))
            .draw()
            .map_err(plot_err)?;
        let (xs, ys) = chart.plotting_area().get_pixel_range();
        (
            (f64::from(xs.start), f64::from(xs.end - 1)),
            (f64::from(ys.end - 1), f64::from(ys.start)),
            ylo,
            yhi,
            true,
        )
    } else {
        let rows = series.len() as f64;
        let ymax = if top > 0.0 {
            top * (1.2 + 0.1 * rows)
        } else {
            1e-3
        };
        let chart = line_chart(area, caption, x, ymax, desc)?;
        let (xs, ys) = chart.plotting_area().get_pixel_range();
        (
            (f64::from(xs.start), f64::from(xs.end - 1)),
            (f64::from(ys.end - 1), f64::from(ys.start)),
            0.0,
            ymax,
            false,
        )
    };
    let at = |line: usize, v: f64| {
        let y = if log {
            to_pixel(v.max(ylo).log10(), (ylo.log10(), yhi.log10()), py)
        } else {
            to_pixel(v, (ylo, yhi), py)
        };
        (to_pixel(line as f64, (first, last), px), y)
    };
    let mut svg = String::from("<g id=\"before-after\">\n");
    for (id, colour, _, values) in &series {
        let pixels: Vec<(f64, f64)> = cuts
            .iter()
            .zip(values)
            .map(|(p, v)| at(p.line, *v))
            .collect();
        svg.push_str(&series_group(id, *colour, &pixels));
    }
    // The legend, in the panel's upper right corner above the plot.
    let (x0, y0) = (px.1 - 470.0, py.1 + 8.0);
    svg.push_str("<g id=\"before-after-legend\" font-family=\"sans-serif\" font-size=\"12\">\n");
    svg.push_str(&format!(
        "<rect x=\"{:.1}\" y=\"{:.1}\" width=\"465\" height=\"{:.1}\" fill=\"#FFFFFF\" fill-opacity=\"0.85\" stroke=\"#999999\"/>\n",
        x0 - 6.0,
        y0 - 4.0,
        8.0 + 18.0 * series.len() as f64
    ));
    for (k, (_, colour, label, _)) in series.iter().enumerate() {
        let RGBColor(r, g, b) = *colour;
        let y = y0 + 10.0 + 18.0 * k as f64;
        svg.push_str(&format!(
            "<line x1=\"{x0:.1}\" y1=\"{y:.1}\" x2=\"{:.1}\" y2=\"{y:.1}\" stroke=\"#{r:02X}{g:02X}{b:02X}\" stroke-width=\"2\"/>\n",
            x0 + 24.0
        ));
        svg.push_str(&format!(
            "<text x=\"{:.1}\" y=\"{:.1}\" fill=\"#000000\">{label}</text>\n",
            x0 + 32.0,
            y + 4.0
        ));
    }
    svg.push_str("</g>\n</g>\n");
    Ok(svg)
}

/// Renders the picture as an SVG document, with `marks` circled and
/// labelled in every view.
pub fn render(
    points: &[PlotPoint],
    marks: &[Worst],
    title: &str,
    effects: &[&str],
) -> Result<String> {
    let top = points
        .iter()
        .map(|p| p.dev)
        .chain(marks.iter().map(|w| w.dev))
        .filter(|d| d.is_finite())
        .fold(0.0, f64::max);
    let dmax = if top > 0.0 { top } else { 1e-3 };
    let scale = Scale::of(points, marks);
    let mut buf = String::new();
    let series = {
        let root = SVGBackend::with_string(&mut buf, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(plot_err)?;
        let (head, body) = root.split_vertically(40);
        head.draw(&Text::new(
            title.to_string(),
            (15, 12),
            ("sans-serif", 17).into_font(),
        ))
        .map_err(plot_err)?;
        let (top_row, rest) = body.split_vertically(VIEWS_H);
        let (along_row, before_after_row) = rest.split_vertically(ALONG_H);
        let (views, bar) = top_row.split_horizontally(SIZE.0 - BAR_W);
        let (plan, side) = views.split_horizontally((SIZE.0 - BAR_W) / 2);
        view(
            &plan,
            points,
            marks,
            (0, 1),
            "Plan view (XY)",
            ("X (mm)", "Y (mm)"),
            &scale,
        )?;
        view(
            &side,
            points,
            marks,
            (0, 2),
            "Side view (XZ)",
            ("X (mm)", "Z (mm)"),
            &scale,
        )?;
        colour_bar(&bar, &scale)?;
        let (program, _) = along_row.split_horizontally(SIZE.0 - BAR_W);
        along(&program, points, marks, dmax, &scale)?;
        let (panel, _) = before_after_row.split_horizontally(SIZE.0 - BAR_W);
        let series = before_after(&panel, points, effects)?;
        root.present().map_err(plot_err)?;
        series
    };
    // The before/after series go last, inside the document element.
    let end = buf.rfind("</svg>").unwrap_or(buf.len());
    buf.insert_str(end, &series);
    Ok(buf)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pt(line: usize, dev: f64) -> PlotPoint {
        PlotPoint {
            line,
            pos: [line as f64, 0.0, 0.0],
            dev,
            rapid: false,
            residual: Some(dev / 2.0),
            start: None,
            shape: Shape::Line,
            parts: [dev, 0.0, 0.0, 0.0, 0.0],
        }
    }

    #[test]
    fn decimator_is_bounded_and_keeps_the_peak() {
        // 100 000 points, one peak at line 54 321: at most 2 × 100 kept, in
        // order, and the peak among them.
        let mut d = Decimator::new(100);
        for i in 1..=100_000 {
            d.push(pt(i, if i == 54_321 { 1.0 } else { 0.001 }));
        }
        let kept = d.finish();
        assert!(kept.len() <= 201 && kept.len() >= 100, "{}", kept.len());
        assert!(kept.windows(2).all(|w| w[0].line < w[1].line));
        assert!(kept.iter().any(|p| p.line == 54_321));
    }

    #[test]
    fn short_streams_are_kept_whole() {
        let mut d = Decimator::new(100);
        for i in 1..=10 {
            d.push(pt(i, 0.0));
        }
        assert_eq!(d.finish().len(), 10);
    }

    #[test]
    fn segments_are_clipped_to_the_view() {
        let r = (0.0, 10.0, 0.0, 10.0);
        // Inside: unchanged; crossing the top edge: cut there; outside: none.
        assert_eq!(
            clip((1.0, 1.0), (2.0, 3.0), r),
            Some(((1.0, 1.0), (2.0, 3.0)))
        );
        assert_eq!(
            clip((5.0, 5.0), (5.0, 20.0), r),
            Some(((5.0, 5.0), (5.0, 10.0)))
        );
        assert_eq!(
            clip((-5.0, 5.0), (15.0, 5.0), r),
            Some(((0.0, 5.0), (10.0, 5.0)))
        );
        assert_eq!(clip((11.0, 11.0), (20.0, 30.0), r), None);
    }

    /// Points of the polyline in the SVG group `id` (`None` without one).
    fn group_points(svg: &str, id: &str) -> Option<usize> {
        let at = svg.find(&format!("<g id=\"{id}\""))?;
        let rest = &svg[at..];
        let end = rest.find("</g>")?;
        let line = rest[..end].split("points=\"").nth(1)?;
        Some(line.split('"').next()?.split_whitespace().count())
    }

    #[test]
    fn before_after_panel_takes_the_cutting_moves_only() {
        // Ten moves, every third a rapid: seven cutting moves.
        let points: Vec<PlotPoint> = (1..=10)
            .map(|i| PlotPoint {
                rapid: i % 3 == 0,
                ..pt(i, 0.01 * i as f64)
            })
            .collect();
        let svg = render(&points, &[], "t", &["geometric"]).expect("renders");
        assert_eq!(group_points(&svg, "before-after-before"), Some(7));
        assert_eq!(group_points(&svg, "before-after-after"), Some(7));
        assert!(svg.trim_end().ends_with("</svg>"));
        // Without residuals (robot programs): the before series alone.
        let robot: Vec<PlotPoint> = points
            .iter()
            .map(|p| PlotPoint {
                residual: None,
                ..*p
            })
            .collect();
        let svg = render(&robot, &[], "t", &["kinematic"]).expect("renders");
        assert_eq!(group_points(&svg, "before-after-before"), Some(7));
        assert_eq!(group_points(&svg, "before-after-after"), None);
    }

    /// The most points of one `<polyline>` of an SVG document.
    fn longest_polyline(svg: &str) -> usize {
        svg.split("<polyline")
            .skip(1)
            .filter_map(|p| p.split("points=\"").nth(1))
            .map(|p| p.split('"').next().unwrap_or("").split_whitespace().count())
            .max()
            .unwrap_or(0)
    }

    #[test]
    fn arcs_are_drawn_along_the_arc_and_holes_ringed() {
        // A half circle from (10, 0) to (-10, 0) about the origin: one
        // polyline of at least 90 points in each view (2° steps), not a
        // chord of two.
        let start = PlotPoint {
            pos: [10.0, 0.0, 0.0],
            ..pt(1, 0.01)
        };
        let arc = PlotPoint {
            pos: [-10.0, 0.0, 0.0],
            start: Some([10.0, 0.0, 0.0]),
            shape: Shape::Arc {
                center: [0.0; 3],
                normal: [0.0, 0.0, -1.0],
                sweep_rad: std::f64::consts::PI,
            },
            ..pt(2, 0.01)
        };
        let svg = render(&[start, arc], &[], "t", &["geometric"]).expect("renders");
        assert!(longest_polyline(&svg) >= 90, "{}", longest_polyline(&svg));
        let line = PlotPoint {
            shape: Shape::Line,
            ..arc
        };
        let svg = render(&[start, line], &[], "t", &["geometric"]).expect("renders");
        assert!(longest_polyline(&svg) < 10);
        // A hole: one ring (radius 5, outlined #222222) in plan view; a
        // line with length across: none.
        let hole = PlotPoint {
            pos: [30.0, 0.0, -5.0],
            start: Some([30.0, 0.0, 2.0]),
            shape: Shape::Hole,
            ..pt(3, 0.01)
        };
        let ring = |svg: &str| svg.matches("r=\"5\"").filter(|_| true).count();
        let svg = render(&[start, arc, hole], &[], "t", &["geometric"]).expect("renders");
        assert_eq!(ring(&svg), 2, "fill and outline of one ring");
        assert!(svg.contains("#222222"));
        let svg = render(&[start, arc], &[], "t", &["geometric"]).expect("renders");
        assert_eq!(ring(&svg), 0);
    }

    #[test]
    fn colour_map_ends() {
        assert_eq!(colour(0.0), RGBColor(68, 1, 84));
        assert_eq!(colour(1.0), RGBColor(253, 231, 37));
        assert_eq!(colour(f64::NAN), RGBColor(68, 1, 84));
    }
}
