//! The plot kit every figure is drawn with (plotters): the embedded font, the PNG + SVG pair of a
//! figure (`both!`), keys drawn beside the chart (never over its data), box plots per set size,
//! the error colour scale and its bar, whole-number tick labels, error bars. Each producer (a
//! device, a sweep, a budget) draws its own figures with it.

use std::sync::Once;

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::FontStyle;

use crate::numeric::quantile;

/// The font every figure uses, embedded (see `assets/README.md`).
pub static FONT: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");
/// The font family the embedded font is registered as.
pub const FAMILY: &str = "sans-serif";
/// Pixels of every figure.
pub const SIZE: (u32, u32) = (900, 600);

/// A figure written as `<stem>.png` and `<stem>.svg`, with its caption.
pub struct Written {
    /// File stem.
    pub stem: String,
    /// Caption for the summary.
    pub caption: String,
    /// Whether `<stem>.svg` was written (a figure of more than [`MOST_SVG_MARKS`] marks is a PNG
    /// alone).
    pub svg: bool,
}

/// The most marks a figure is also written as SVG with: an SVG holds an element per mark, about
/// 100 bytes each (10 MB at this count; a browser renders it slowly beyond), where a PNG's size does
/// not grow with them.
pub const MOST_SVG_MARKS: usize = 100_000;

/// A figure could not be drawn or written.
#[derive(Debug, thiserror::Error)]
#[error("figure: {0}")]
pub struct PlotError(pub String);

/// What drawing a figure returns.
pub type DrawResult = Result<(), PlotError>;

/// Values per set size: `(n, values)`.
pub type BySize = Vec<(usize, Vec<f64>)>;

/// Registers the embedded font once per process.
pub fn register_font() {
    static REGISTER: Once = Once::new();
    REGISTER.call_once(|| {
        // The font is a fixed asset: a failure here is a build defect, reported by the first text drawn.
        let _ = plotters::style::register_font(FAMILY, FontStyle::Normal, FONT);
    });
}

/// `c` at opacity `a` over white, as an opaque colour (for a key's mark of a translucent fill).
pub fn pale(c: RGBColor, a: f64) -> RGBColor {
    let m = |v: u8| (a * f64::from(v) + (1.0 - a) * 255.0).round() as u8;
    RGBColor(m(c.0), m(c.1), m(c.2))
}

/// How a key entry is marked.
#[derive(Clone, Copy, Debug)]
pub enum Mark {
    /// A filled dot (points).
    Dot(RGBColor),
    /// A line (fits, references, curves).
    Line(RGBColor),
    /// A dashed line (targets, thresholds).
    Dashed(RGBColor),
    /// A filled box (bars, boxes).
    Bar(RGBColor),
    /// A filled triangle (the robot base, datum spheres).
    Triangle(RGBColor),
    /// An open ring (circled points, reach).
    Ring(RGBColor),
    /// A vertical bar with caps (an interval).
    Interval(RGBColor),
}

/// Where a key goes beside the chart.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// A strip under the chart, entries in rows.
    Bottom,
    /// A column right of the chart, one entry per line.
    Right,
}

const KEY_FONT: u32 = 13;
const KEY_LINE: i32 = 19;
const KEY_MARK: i32 = 28;

fn draw_mark<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, mark: Mark, (x, y): (i32, i32)) -> DrawResult {
    let d = |e: DrawResult| e;
    d(match mark {
        Mark::Dot(c) => area.draw(&Circle::new((x + 10, y), 4, c.filled())).map_err(e2s),
        Mark::Line(c) => area.draw(&PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2))).map_err(e2s),
        Mark::Dashed(c) => area
            .draw(&PathElement::new(vec![(x, y), (x + 7, y)], c.stroke_width(2)))
            .and_then(|_| area.draw(&PathElement::new(vec![(x + 13, y), (x + 20, y)], c.stroke_width(2))))
            .map_err(e2s),
        Mark::Bar(c) => area.draw(&Rectangle::new([(x + 3, y - 6), (x + 17, y + 6)], c.filled())).map_err(e2s),
        Mark::Triangle(c) => area.draw(&TriangleMarker::new((x + 10, y), 6, c.filled())).map_err(e2s),
        Mark::Ring(c) => area.draw(&Circle::new((x + 10, y), 6, c.stroke_width(2))).map_err(e2s),
        Mark::Interval(c) => {
            let v = PathElement::new(vec![(x + 10, y - 7), (x + 10, y + 7)], c.stroke_width(2));
            let caps = [(y - 7), (y + 7)].map(|yy| PathElement::new(vec![(x + 6, yy), (x + 14, yy)], c.stroke_width(2)));
            area.draw(&v).and_then(|_| area.draw(&caps[0])).and_then(|_| area.draw(&caps[1])).map_err(e2s)
        }
    })
}

/// Splits `root` into the chart's area and a key on `side`, draws the key there and returns the
/// chart's area: the key never covers the data. A bottom key flows its entries into rows; a right
/// key takes the width of its longest label (at most 40 % of the figure).
pub fn keyed<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    entries: &[(String, Mark)],
    side: Side,
) -> Result<DrawingArea<DB, Shift>, PlotError> {
    if entries.is_empty() {
        return Ok(root.clone());
    }
    let font: TextStyle = (FAMILY, KEY_FONT).into_font().into();
    let width = |t: &str| root.estimate_text_size(t, &font).map(|(w, _)| w as i32).unwrap_or(7 * t.len() as i32);
    let (w, h) = root.dim_in_pixel();
    let (w, h) = (w as i32, h as i32);
    match side {
        Side::Bottom => {
            // Lay the entries out in rows first, to know the strip's height.
            let mut rows: Vec<Vec<(i32, &(String, Mark))>> = vec![Vec::new()];
            let mut x = 20;
            for e in entries {
                let ew = KEY_MARK + width(&e.0) + 24;
                if x + ew > w - 10 && x > 20 {
                    rows.push(Vec::new());
                    x = 20;
                }
                rows.last_mut().expect("one row").push((x, e));
                x += ew;
            }
            let strip = rows.len() as i32 * KEY_LINE + 8;
            let (chart, key) = root.split_vertically(h - strip);
            for (r, row) in rows.iter().enumerate() {
                let y = 4 + r as i32 * KEY_LINE + KEY_LINE / 2;
                for (x, (label, mark)) in row {
                    draw_mark(&key, *mark, (*x, y))?;
                    key.draw(&Text::new(label.clone(), (x + KEY_MARK, y - KEY_FONT as i32 / 2 - 1), font.clone())).map_err(e2s)?;
                }
            }
            Ok(chart)
        }
        Side::Right => {
            let longest = entries.iter().map(|e| width(&e.0)).max().unwrap_or(0);
            let strip = (KEY_MARK + longest + 16).min(w * 2 / 5);
            let (chart, key) = root.split_horizontally(w - strip);
            let top = (h - entries.len() as i32 * KEY_LINE) / 2;
            for (i, (label, mark)) in entries.iter().enumerate() {
                let y = top.max(40) + i as i32 * KEY_LINE;
                draw_mark(&key, *mark, (4, y))?;
                key.draw(&Text::new(label.clone(), (4 + KEY_MARK, y - KEY_FONT as i32 / 2 - 1), font.clone())).map_err(e2s)?;
            }
            Ok(chart)
        }
    }
}

/// Splits a colour bar of [`heat`] from 0 to `max` (labelled `label`) off the right of `root` and
/// returns the rest, for a figure that colours its points by a value.
pub fn colour_bar<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, max: f64, label: &str) -> Result<DrawingArea<DB, Shift>, PlotError> {
    let (w, _) = root.dim_in_pixel();
    let (rest, bar) = root.split_horizontally(w as i32 - 105);
    let mut chart = ChartBuilder::on(&bar)
        .margin_top(50)
        .margin_bottom(60)
        .margin_left(8)
        .margin_right(5)
        .set_label_area_size(LabelAreaPosition::Right, 62)
        .build_cartesian_2d(0f64..1.0, 0f64..max.max(1e-9))
        .map_err(e2s)?;
    chart.configure_mesh().disable_mesh().disable_x_axis().y_desc(label).y_labels(6).label_style((FAMILY, 12)).draw().map_err(e2s)?;
    let steps = 100;
    chart
        .draw_series((0..steps).map(|k| {
            let (a, b) = (k as f64 / steps as f64, (k + 1) as f64 / steps as f64);
            Rectangle::new([(0.0, a * max), (1.0, b * max)], heat((a + b) / 2.0).filled())
        }))
        .map_err(e2s)?;
    chart.draw_series(std::iter::once(Rectangle::new([(0.0, 0.0), (1.0, max)], BLACK.stroke_width(1)))).map_err(e2s)?;
    Ok(rest)
}

/// A tick label for a whole-number axis (counts, indices, set sizes): the integer, or nothing
/// between integers.
pub fn whole(x: &f64) -> String {
    let k = x.round();
    if (x - k).abs() < 1e-6 { format!("{k:.0}") } else { String::new() }
}

/// A vertical interval `lo`-`hi` at `x` with caps `half` wide (x units), for an estimate's
/// interval; nothing when either end is not finite.
pub fn interval_bar(x: f64, (lo, hi): (f64, f64), half: f64, style: ShapeStyle) -> Vec<PathElement<(f64, f64)>> {
    if !(lo.is_finite() && hi.is_finite()) {
        return Vec::new();
    }
    vec![
        PathElement::new(vec![(x, lo), (x, hi)], style),
        PathElement::new(vec![(x - half, lo), (x + half, lo)], style),
        PathElement::new(vec![(x - half, hi), (x + half, hi)], style),
    ]
}

/// A horizontal interval `lo`-`hi` at `y` with caps `half` high (y units).
pub fn interval_bar_h(y: f64, (lo, hi): (f64, f64), half: f64, style: ShapeStyle) -> Vec<PathElement<(f64, f64)>> {
    if !(lo.is_finite() && hi.is_finite()) {
        return Vec::new();
    }
    vec![
        PathElement::new(vec![(lo, y), (hi, y)], style),
        PathElement::new(vec![(lo, y - half), (lo, y + half)], style),
        PathElement::new(vec![(hi, y - half), (hi, y + half)], style),
    ]
}

/// A legend inside a chart (a white box with a black border, labels in `size` points at `pos`):
/// only where the corner is known to be free of data; elsewhere [`keyed`] puts the key beside it.
pub fn legend<'a, DB: DrawingBackend + 'a, CT: plotters::coord::CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
    pos: SeriesLabelPosition,
    size: u32,
) -> DrawResult {
    chart
        .configure_series_labels()
        .position(pos)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font((FAMILY, size))
        .draw()
        .map_err(e2s)
}

/// A plotters error as a [`PlotError`].
pub fn e2s<E: std::fmt::Debug>(e: E) -> PlotError {
    PlotError(format!("{e:?}"))
}

/// A plotters error writing the file `path` as a [`PlotError`] naming the file.
pub fn written<E: std::fmt::Display>(path: &std::path::Path) -> impl FnOnce(E) -> PlotError + '_ {
    move |e| PlotError(format!("{}: {e}", path.file_name().map_or_else(String::new, |n| n.to_string_lossy().into_owned())))
}

/// Draws `draw` into `dir/<stem>.png` and `dir/<stem>.svg` ([`SIZE`] pixels, or `size`), the SVG
/// left out where `png_only:` is true; a write error names the file.
macro_rules! both {
    ($dir:expr, $stem:expr, png_only: $png_only:expr, $draw:expr) => {
        $crate::io::plot::both!($dir, $stem, $crate::io::plot::SIZE, png_only: $png_only, $draw)
    };
    ($dir:expr, $stem:expr, $size:expr, png_only: $png_only:expr, $draw:expr) => {{
        let png = $dir.join(format!("{}.png", $stem));
        {
            let root = plotters::prelude::IntoDrawingArea::into_drawing_area(plotters::prelude::BitMapBackend::new(&png, $size));
            $draw(&root)?;
            root.present().map_err($crate::io::plot::written(&png))?;
        }
        if !$png_only {
            let svg = $dir.join(format!("{}.svg", $stem));
            let root = plotters::prelude::IntoDrawingArea::into_drawing_area(plotters::prelude::SVGBackend::new(&svg, $size));
            $draw(&root)?;
            root.present().map_err($crate::io::plot::written(&svg))?;
        }
    }};
    ($dir:expr, $stem:expr, $draw:expr) => {
        $crate::io::plot::both!($dir, $stem, $crate::io::plot::SIZE, png_only: false, $draw)
    };
    ($dir:expr, $stem:expr, $size:expr, $draw:expr) => {
        $crate::io::plot::both!($dir, $stem, $size, png_only: false, $draw)
    };
}

/// The range of `v` widened by `pad` of its span on each side (0..1 when `v` has no finite value).
pub fn range_of(v: impl Iterator<Item = f64> + Clone, pad: f64) -> std::ops::Range<f64> {
    let lo = v.clone().fold(f64::INFINITY, f64::min);
    let hi = v.fold(f64::NEG_INFINITY, f64::max);
    let (lo, hi) = if lo.is_finite() && hi.is_finite() { (lo, hi) } else { (0.0, 1.0) };
    let span = (hi - lo).max(1e-9);
    (lo - pad * span)..(hi + pad * span)
}

/// Box plots per set size: quartiles, median, whiskers at 1.5 IQR, outliers as crosses.
pub fn boxplot<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, data: &[(usize, Vec<f64>)], title: &str, ylabel: &str) -> DrawResult {
    boxplots(root, &[("", BLUE, data.to_vec())], title, ylabel)
}

/// Box plots per set size of one or more series side by side (box: quartiles, red bar: median,
/// whiskers: 1.5 IQR, crosses: outliers); a legend when the series are labelled.
pub fn boxplots<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    series: &[(&str, RGBColor, BySize)],
    title: &str,
    ylabel: &str,
) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let entries: Vec<(String, Mark)> =
        series.iter().filter(|s| !s.0.is_empty()).map(|s| (s.0.to_string(), Mark::Bar(pale(s.1, 0.4)))).collect();
    let root = &keyed(root, &entries, Side::Bottom)?;
    let sizes: Vec<usize> = series.first().map(|s| s.2.iter().map(|(n, _)| *n).collect()).unwrap_or_default();
    let step = if sizes.len() > 1 { sizes.windows(2).map(|w| (w[1] - w[0]) as f64).fold(f64::INFINITY, f64::min) } else { 10.0 };
    // One set size: the axis spans a step either side, so that its box has a width to be drawn in
    // (a range of the one size alone is 1e-9 wide, and the box's edges overflow the pixel grid).
    let xr = match sizes.as_slice() {
        [n] => (*n as f64 - step)..(*n as f64 + step),
        _ => range_of(sizes.iter().map(|n| *n as f64), 0.06),
    };
    let yr = range_of(series.iter().flat_map(|s| s.2.iter().flat_map(|(_, v)| v.iter().copied())), 0.08);
    let yr = 0f64.min(yr.start)..yr.end;
    let k = series.len().max(1) as f64;
    let half = 0.3 * step / k;
    let mut chart = ChartBuilder::on(root)
        .caption(title, (FAMILY, 22))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(65)
        .build_cartesian_2d(xr, yr)
        .map_err(e2s)?;
    chart
        .configure_mesh()
        .x_desc("set size n (configurations)")
        .y_desc(ylabel)
        .x_label_formatter(&whole)
        .x_labels(sizes.len().max(2))
        .light_line_style(WHITE)
        .label_style((FAMILY, 13))
        .draw()
        .map_err(e2s)?;
    for (si, (_, colour, data)) in series.iter().enumerate() {
        let offset = (si as f64 - (k - 1.0) / 2.0) * 2.2 * half;
        for (n, v) in data {
            if v.is_empty() {
                continue;
            }
            let x = *n as f64 + offset;
            let mut v = v.clone();
            v.sort_by(f64::total_cmp);
            let (q1, q2, q3) = (quantile(&v, 0.25), quantile(&v, 0.5), quantile(&v, 0.75));
            let iqr = q3 - q1;
            let inside = |y: &&f64| **y >= q1 - 1.5 * iqr && **y <= q3 + 1.5 * iqr;
            let lo = v.iter().filter(inside).fold(f64::INFINITY, |a, &b| a.min(b));
            let hi = v.iter().filter(inside).fold(f64::NEG_INFINITY, |a, &b| a.max(b));
            chart.draw_series(std::iter::once(Rectangle::new([(x - half, q1), (x + half, q3)], colour.mix(0.25).filled()))).map_err(e2s)?;
            chart.draw_series(std::iter::once(Rectangle::new([(x - half, q1), (x + half, q3)], colour.stroke_width(1)))).map_err(e2s)?;
            let line = |pts: Vec<(f64, f64)>, style: ShapeStyle| PathElement::new(pts, style);
            chart
                .draw_series([
                    line(vec![(x - half, q2), (x + half, q2)], RED.stroke_width(2)),
                    line(vec![(x, q3), (x, hi)], BLACK.stroke_width(1)),
                    line(vec![(x, q1), (x, lo)], BLACK.stroke_width(1)),
                    line(vec![(x - half / 2.0, hi), (x + half / 2.0, hi)], BLACK.stroke_width(1)),
                    line(vec![(x - half / 2.0, lo), (x + half / 2.0, lo)], BLACK.stroke_width(1)),
                ])
                .map_err(e2s)?;
            chart.draw_series(v.iter().filter(|y| !inside(y)).map(|&y| Cross::new((x, y), 4, BLACK.stroke_width(1)))).map_err(e2s)?;
        }
    }
    Ok(())
}

/// Error colour scale from blue (0, small) to red (1, large), as RGB; the figures and the
/// recording both use it.
pub fn heat_rgb(t: f64) -> [u8; 3] {
    let t = t.clamp(0.0, 1.0);
    [(255.0 * t) as u8, (80.0 * (1.0 - (2.0 * t - 1.0).abs())) as u8, (255.0 * (1.0 - t)) as u8]
}

/// [`heat_rgb`] as a plotters colour.
pub fn heat(t: f64) -> RGBColor {
    let [r, g, b] = heat_rgb(t);
    RGBColor(r, g, b)
}

pub(crate) use both;
