//! The deviation picture of `report --format svg`: the toolpath in plan (XY)
//! and side (XZ) view coloured by the predicted |deviation|, the deviation
//! along the program, a colour bar, and the worst block marked — drawn with
//! `plotters` (SVG backend, no system fonts).
//!
//! Long programs are decimated into a bounded number of points by
//! [`Decimator`]: contiguous buckets of blocks, each represented by its block
//! of largest deviation, so peaks survive and the output is the same bytes
//! on every run.

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::error::{Error, Result};

/// Canvas size, pixels.
const SIZE: (u32, u32) = (1200, 900);
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
}

/// The block with the largest deviation, marked in the picture.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Worst {
    /// 1-based source line.
    pub line: usize,
    /// Programmed tool-tip position, mm.
    pub pos: [f64; 3],
    /// Predicted |deviation|, mm.
    pub dev: f64,
}

/// Keeps at most about `2 × cap` points of a stream of any length: the stream
/// is cut into buckets of `stride` consecutive points, each kept as its point
/// of largest deviation (the earlier one on ties); when the buffer is full,
/// neighbouring buckets merge and the stride doubles. Deterministic.
#[derive(Debug, Clone)]
pub struct Decimator {
    cap: usize,
    stride: usize,
    in_bucket: usize,
    bucket: Option<PlotPoint>,
    points: Vec<PlotPoint>,
}

fn larger(a: PlotPoint, b: PlotPoint) -> PlotPoint {
    if b.dev > a.dev { b } else { a }
}

impl Decimator {
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
    pub fn push(&mut self, p: PlotPoint) {
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
                let merged: Vec<PlotPoint> = self
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
    pub fn finish(mut self) -> Vec<PlotPoint> {
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

fn level(dev: f64, dmax: f64) -> usize {
    ((dev / dmax * LEVELS as f64) as usize).min(LEVELS - 1)
}

fn level_colour(l: usize) -> RGBColor {
    colour((l as f64 + 0.5) / LEVELS as f64)
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

/// One projection of the toolpath (axes `a`, `b` of the position).
#[allow(clippy::too_many_arguments)]
fn view(
    area: &DrawingArea<SVGBackend, Shift>,
    points: &[PlotPoint],
    worst: Option<Worst>,
    (a, b): (usize, usize),
    caption: &str,
    (xdesc, ydesc): (&str, &str),
    dmax: f64,
) -> Result<()> {
    let bounds = |k: usize| {
        points
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |r, p| {
                let v = p.pos.get(k).copied().unwrap_or(0.0);
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
        .x_label_formatter(&|v| format!("{v:.0}"))
        .y_label_formatter(&|v| format!("{v:.0}"))
        .label_style(("sans-serif", 13))
        .axis_desc_style(("sans-serif", 14))
        .light_line_style(RGBColor(235, 235, 235))
        .bold_line_style(RGBColor(215, 215, 215))
        .draw()
        .map_err(plot_err)?;
    let at = |p: &PlotPoint| {
        (
            p.pos.get(a).copied().unwrap_or(0.0),
            p.pos.get(b).copied().unwrap_or(0.0),
        )
    };
    // Runs of segments with the same colour level and kind: one polyline each.
    let mut i = 1;
    while i < points.len() {
        let key = (level(points[i].dev, dmax), points[i].rapid);
        let mut run = vec![at(&points[i - 1]), at(&points[i])];
        let mut j = i + 1;
        while j < points.len() && (level(points[j].dev, dmax), points[j].rapid) == key {
            run.push(at(&points[j]));
            j += 1;
        }
        let style = level_colour(key.0).stroke_width(if key.1 { 1 } else { 3 });
        chart
            .draw_series(std::iter::once(PathElement::new(run, style)))
            .map_err(plot_err)?;
        i = j;
    }
    if let Some(wp) = worst {
        let c = (
            wp.pos.get(a).copied().unwrap_or(0.0),
            wp.pos.get(b).copied().unwrap_or(0.0),
        );
        chart
            .draw_series(std::iter::once(Circle::new(
                c,
                9,
                RGBColor(220, 30, 30).stroke_width(3),
            )))
            .map_err(plot_err)?;
        chart
            .draw_series(std::iter::once(Text::new(
                format!("max, line {}", wp.line),
                c,
                ("sans-serif", 14).into_font().color(&RGBColor(200, 20, 20)),
            )))
            .map_err(plot_err)?;
    }
    Ok(())
}

/// The colour bar: |deviation| 0 … `dmax` mm.
fn colour_bar(area: &DrawingArea<SVGBackend, Shift>, dmax: f64) -> Result<()> {
    let mut chart = ChartBuilder::on(area)
        .caption("|dev|", ("sans-serif", 16))
        .margin_top(15)
        .margin_bottom(60)
        .margin_right(20)
        .y_label_area_size(80)
        .build_cartesian_2d(0.0..1.0, 0.0..dmax)
        .map_err(plot_err)?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .disable_y_mesh()
        .x_labels(0)
        .y_labels(8)
        .y_desc("predicted |deviation| (mm)")
        .label_style(("sans-serif", 13))
        .axis_desc_style(("sans-serif", 14))
        .y_label_formatter(&|v| format!("{v:.4}"))
        .draw()
        .map_err(plot_err)?;
    chart
        .draw_series((0..LEVELS).map(|l| {
            let lo = dmax * l as f64 / LEVELS as f64;
            let hi = dmax * (l + 1) as f64 / LEVELS as f64;
            Rectangle::new([(0.0, lo), (1.0, hi)], level_colour(l).filled())
        }))
        .map_err(plot_err)?;
    Ok(())
}

/// |deviation| against the source line.
fn along(
    area: &DrawingArea<SVGBackend, Shift>,
    points: &[PlotPoint],
    worst: Option<Worst>,
    dmax: f64,
) -> Result<()> {
    let first = points.first().map_or(0, |p| p.line) as f64;
    let last = points.last().map_or(1, |p| p.line) as f64;
    let last = if last > first { last } else { first + 1.0 };
    let mut chart = ChartBuilder::on(area)
        .caption(
            "Predicted |deviation| along the program",
            ("sans-serif", 18),
        )
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(first..last, 0.0..dmax * 1.1)
        .map_err(plot_err)?;
    chart
        .configure_mesh()
        .x_desc("source line")
        .y_desc("|deviation| (mm)")
        .x_label_formatter(&|v| format!("{v:.0}"))
        .label_style(("sans-serif", 13))
        .axis_desc_style(("sans-serif", 14))
        .y_label_formatter(&|v| format!("{v:.4}"))
        .light_line_style(RGBColor(235, 235, 235))
        .bold_line_style(RGBColor(215, 215, 215))
        .draw()
        .map_err(plot_err)?;
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
                level_colour(level(p.dev, dmax)).filled(),
            )
        }))
        .map_err(plot_err)?;
    if let Some(wp) = worst {
        let c = (wp.line as f64, wp.dev);
        chart
            .draw_series(std::iter::once(Circle::new(
                c,
                7,
                RGBColor(220, 30, 30).stroke_width(2),
            )))
            .map_err(plot_err)?;
        chart
            .draw_series(std::iter::once(Text::new(
                format!("  max {:.4} mm, line {}", wp.dev, wp.line),
                c,
                ("sans-serif", 14).into_font().color(&RGBColor(200, 20, 20)),
            )))
            .map_err(plot_err)?;
    }
    Ok(())
}

/// Renders the picture as an SVG document.
pub fn render(points: &[PlotPoint], worst: Option<Worst>, title: &str) -> Result<String> {
    let top = points
        .iter()
        .map(|p| p.dev)
        .chain(worst.map(|w| w.dev))
        .filter(|d| d.is_finite())
        .fold(0.0, f64::max);
    let dmax = if top > 0.0 { top } else { 1e-3 };
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(plot_err)?;
        let (head, body) = root.split_vertically(40);
        head.draw(&Text::new(
            title.to_string(),
            (15, 12),
            ("sans-serif", 17).into_font(),
        ))
        .map_err(plot_err)?;
        let (top_row, bottom_row) = body.split_vertically(500);
        let (views, bar) = top_row.split_horizontally(SIZE.0 - BAR_W);
        let (plan, side) = views.split_horizontally((SIZE.0 - BAR_W) / 2);
        view(
            &plan,
            points,
            worst,
            (0, 1),
            "Plan view (XY)",
            ("X (mm)", "Y (mm)"),
            dmax,
        )?;
        view(
            &side,
            points,
            worst,
            (0, 2),
            "Side view (XZ)",
            ("X (mm)", "Z (mm)"),
            dmax,
        )?;
        colour_bar(&bar, dmax)?;
        let (program, _) = bottom_row.split_horizontally(SIZE.0 - BAR_W);
        along(&program, points, worst, dmax)?;
        root.present().map_err(plot_err)?;
    }
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
    fn colour_map_ends() {
        assert_eq!(colour(0.0), RGBColor(68, 1, 84));
        assert_eq!(colour(1.0), RGBColor(253, 231, 37));
        assert_eq!(colour(f64::NAN), RGBColor(68, 1, 84));
    }
}
