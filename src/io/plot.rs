//! The plot kit every figure is drawn with (plotters): the embedded font, the PNG + SVG pair of a
//! figure (`both!`), legends, box plots per set size, the error colour scale. Each producer (a
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
}

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

/// The legend of a chart: a white box with a black border, labels in `size` points at `pos`.
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

/// Draws `draw` into `dir/<stem>.png` and `dir/<stem>.svg`; a write error names the file.
macro_rules! both {
    ($dir:expr, $stem:expr, $draw:expr) => {{
        let png = $dir.join(format!("{}.png", $stem));
        let svg = $dir.join(format!("{}.svg", $stem));
        {
            let root = plotters::prelude::IntoDrawingArea::into_drawing_area(plotters::prelude::BitMapBackend::new(&png, $crate::io::plot::SIZE));
            $draw(&root)?;
            root.present().map_err($crate::io::plot::written(&png))?;
        }
        {
            let root = plotters::prelude::IntoDrawingArea::into_drawing_area(plotters::prelude::SVGBackend::new(&svg, $crate::io::plot::SIZE));
            $draw(&root)?;
            root.present().map_err($crate::io::plot::written(&svg))?;
        }
    }};
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
        .x_label_formatter(&|x| format!("{x:.0}"))
        .x_labels(sizes.len().max(2))
        .light_line_style(WHITE)
        .label_style((FAMILY, 13))
        .draw()
        .map_err(e2s)?;
    for (si, (label, colour, data)) in series.iter().enumerate() {
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
        if !label.is_empty() {
            let c = *colour;
            chart
                .draw_series(std::iter::once(Rectangle::new([(f64::NAN, f64::NAN), (f64::NAN, f64::NAN)], c.mix(0.25).filled())))
                .map_err(e2s)?
                .label(*label)
                .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 14, y + 6)], c.mix(0.5).filled()));
        }
    }
    if series.iter().any(|s| !s.0.is_empty()) {
        legend(&mut chart, SeriesLabelPosition::MiddleRight, 14)?;
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
