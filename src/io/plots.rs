//! The paper's figures 7-13 as PNG and SVG (plotters), written beside the result tables and
//! embedded in `summary.md`. Every figure is drawn once by a function generic over the backend.

use std::path::Path;
use std::sync::Once;

use nalgebra::Vector3;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::FontStyle;

use crate::study::StudyResults;
use crate::study::stats::{ErrorStats, pearson, quantile, regression as least_squares_line};

/// The font every figure uses, embedded (see `assets/README.md`).
static FONT: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");
pub(crate) const FAMILY: &str = "sans-serif";
pub(crate) const SIZE: (u32, u32) = (900, 600);

/// What the figures show, gathered from a study and its experiment.
pub struct PlotInputs {
    /// Validation TCP positions in {W}, mm.
    pub validation_w: Vec<Vector3<f64>>,
    /// Datum-sphere centres in {W}, mm.
    pub spheres_w: Vec<Vector3<f64>>,
    /// Robot base origin in {W}, mm.
    pub base_w: Vector3<f64>,
    /// Set size of Figs. 10-13.
    pub table_n: usize,
}

/// A figure written as `<stem>.png` and `<stem>.svg`, with its caption.
pub struct Written {
    /// File stem.
    pub stem: String,
    /// Caption for the summary.
    pub caption: String,
}

pub(crate) type DrawResult = Result<(), String>;

/// Values per set size: `(n, values)`.
pub type BySize = Vec<(usize, Vec<f64>)>;

/// Registers the embedded font once per process.
pub(crate) fn register_font() {
    static REGISTER: Once = Once::new();
    REGISTER.call_once(|| {
        // The font is a fixed asset: a failure here is a build defect, reported by the first text drawn.
        let _ = plotters::style::register_font(FAMILY, FontStyle::Normal, FONT);
    });
}

/// The legend of a chart: a white box with a black border, labels in `size` points at `pos`.
pub(crate) fn legend<'a, DB: DrawingBackend + 'a, CT: plotters::coord::CoordTranslate>(
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

pub(crate) fn e2s<E: std::fmt::Debug>(e: E) -> String {
    format!("{e:?}")
}

/// Draws `draw` into `dir/<stem>.png` and `dir/<stem>.svg`.
macro_rules! both {
    ($dir:expr, $stem:expr, $draw:expr) => {{
        let png = $dir.join(format!("{}.png", $stem));
        let svg = $dir.join(format!("{}.svg", $stem));
        {
            let root = BitMapBackend::new(&png, SIZE).into_drawing_area();
            $draw(&root)?;
            root.present().map_err(e2s)?;
        }
        {
            let root = SVGBackend::new(&svg, SIZE).into_drawing_area();
            $draw(&root)?;
            root.present().map_err(e2s)?;
        }
    }};
}
pub(crate) use both;

/// Writes every figure into `dir`; returns what was written.
///
/// Long by design: one call per figure of the paper, in the paper's order, each a few lines.
pub fn write_all(dir: &Path, results: &StudyResults, inputs: &PlotInputs) -> Result<Vec<Written>, String> {
    register_font();
    let mut out = Vec::new();

    both!(dir, "fig07_validation_poses", |root| fig07(root, inputs));
    out.push(Written {
        stem: "fig07_validation_poses".into(),
        caption: format!("Fig. 7: the {} validation poses and the datum spheres, top and side views", inputs.validation_w.len()),
    });

    let mut sizes: Vec<usize> = results.tasks.iter().map(|t| t.task.set_size).collect();
    sizes.sort_unstable();
    sizes.dedup();
    let per_size = |f: &dyn Fn(&ErrorStats) -> f64| -> Vec<(usize, Vec<f64>)> {
        sizes
            .iter()
            .map(|&n| {
                (
                    n,
                    results
                        .tasks
                        .iter()
                        .filter(|t| t.task.set_size == n && !t.id.outcome.is_rank_deficient())
                        .map(|t| f(&t.validation))
                        .collect(),
                )
            })
            .collect()
    };
    let means = per_size(&|v| v.mean);
    let stds = per_size(&|v| v.std);
    both!(dir, "fig08_mean_error_by_set_size", |root| boxplot(
        root,
        &means,
        "Fig. 8: mean validation error per identification",
        "mean error after calibration (mm)"
    ));
    out.push(Written {
        stem: "fig08_mean_error_by_set_size".into(),
        caption: "Fig. 8: mean validation error of each identification per set size (box: quartiles; whiskers: 1.5 IQR; crosses: outliers)"
            .into(),
    });
    both!(dir, "fig09_std_error_by_set_size", |root| boxplot(
        root,
        &stds,
        "Fig. 9: standard deviation of the validation error",
        "std of error after calibration (mm)"
    ));
    out.push(Written {
        stem: "fig09_std_error_by_set_size".into(),
        caption: "Fig. 9: standard deviation of the validation error of each identification per set size".into(),
    });

    let Some((task, after)) = crate::study::figures::representative(results, inputs.table_n) else {
        return Ok(out);
    };
    let n = inputs.table_n;
    both!(dir, "fig10_error_map", |root| fig10(root, inputs, after, n, task));
    out.push(Written {
        stem: "fig10_error_map".into(),
        caption: format!(
            "Fig. 10: error after calibration at each validation pose (set of {n}, task {task}: the median of the \
             repetitions), the 10 largest circled"
        ),
    });
    let db = &results.distance_to_base_mm;
    let dc = &results.distance_to_ccz_mm;
    both!(dir, "fig11_error_vs_distance_to_base", |root| regression(
        root,
        db,
        after,
        "Fig. 11: error vs distance to the robot base",
        "distance from the base origin (mm)"
    ));
    out.push(Written {
        stem: "fig11_error_vs_distance_to_base".into(),
        caption: "Fig. 11: error after calibration against the distance to the base, with the least-squares line".into(),
    });
    both!(dir, "fig12_error_vs_distance_to_ccz", |root| regression(
        root,
        dc,
        after,
        "Fig. 12: error vs distance to the centre of the calibration zone",
        "distance from the CCZ (mm)"
    ));
    out.push(Written {
        stem: "fig12_error_vs_distance_to_ccz".into(),
        caption: "Fig. 12: error after calibration against the distance to the centre of the calibration zone (centroid of the spheres)"
            .into(),
    });
    both!(dir, "fig13_error_histograms", |root| fig13(root, &results.before_errors, after, n));
    out.push(Written {
        stem: "fig13_error_histograms".into(),
        caption: "Fig. 13: distribution of the position errors before and after calibration, with descriptive statistics".into(),
    });
    Ok(out)
}

pub(crate) fn range_of(v: impl Iterator<Item = f64> + Clone, pad: f64) -> std::ops::Range<f64> {
    let lo = v.clone().fold(f64::INFINITY, f64::min);
    let hi = v.fold(f64::NEG_INFINITY, f64::max);
    let (lo, hi) = if lo.is_finite() && hi.is_finite() { (lo, hi) } else { (0.0, 1.0) };
    let span = (hi - lo).max(1e-9);
    (lo - pad * span)..(hi + pad * span)
}

fn fig07<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, p: &PlotInputs) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let root = root.titled("Fig. 7: validation poses (TCP in {W}) and datum spheres", (FAMILY, 22)).map_err(e2s)?;
    let panels = root.split_evenly((1, 2));
    let views: [(&str, usize, usize); 2] = [("top view", 0, 1), ("side view", 0, 2)];
    for (area, (name, a, b)) in panels.iter().zip(views) {
        let all = p.validation_w.iter().chain(&p.spheres_w).chain(std::iter::once(&p.base_w));
        let xr = range_of(all.clone().map(|v| v[a]), 0.05);
        let yr = range_of(all.map(|v| v[b]), 0.05);
        let axis = ["x", "y", "z"];
        let mut chart = ChartBuilder::on(area)
            .caption(name, (FAMILY, 16))
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(55)
            .build_cartesian_2d(xr, yr)
            .map_err(e2s)?;
        chart
            .configure_mesh()
            .x_desc(format!("{} in {{W}} (mm)", axis[a]))
            .y_desc(format!("{} in {{W}} (mm)", axis[b]))
            .label_style((FAMILY, 12))
            .draw()
            .map_err(e2s)?;
        chart
            .draw_series(p.validation_w.iter().map(|v| Circle::new((v[a], v[b]), 2, BLUE.mix(0.5).filled())))
            .map_err(e2s)?
            .label("validation pose")
            .legend(|(x, y)| Circle::new((x, y), 3, BLUE.filled()));
        chart
            .draw_series(p.spheres_w.iter().map(|v| Circle::new((v[a], v[b]), 6, RED.filled())))
            .map_err(e2s)?
            .label("datum sphere")
            .legend(|(x, y)| Circle::new((x, y), 4, RED.filled()));
        chart
            .draw_series(std::iter::once(TriangleMarker::new((p.base_w[a], p.base_w[b]), 8, BLACK.filled())))
            .map_err(e2s)?
            .label("robot base")
            .legend(|(x, y)| TriangleMarker::new((x, y), 5, BLACK.filled()));
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font((FAMILY, 12))
            .draw()
            .map_err(e2s)?;
    }
    Ok(())
}

/// Box plots per set size: quartiles, median, whiskers at 1.5 IQR, outliers as crosses.
fn boxplot<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, data: &[(usize, Vec<f64>)], title: &str, ylabel: &str) -> DrawResult {
    boxplots(root, &[("", BLUE, data.to_vec())], title, ylabel)
}

/// Box plots per set size of one or more series side by side (box: quartiles, red bar: median,
/// whiskers: 1.5 IQR, crosses: outliers); a legend when the series are labelled.
fn boxplots<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    series: &[(&str, RGBColor, BySize)],
    title: &str,
    ylabel: &str,
) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let sizes: Vec<usize> = series.first().map(|s| s.2.iter().map(|(n, _)| *n).collect()).unwrap_or_default();
    let xr = range_of(sizes.iter().map(|n| *n as f64), 0.06);
    let yr = range_of(series.iter().flat_map(|s| s.2.iter().flat_map(|(_, v)| v.iter().copied())), 0.08);
    let yr = 0f64.min(yr.start)..yr.end;
    let step = if sizes.len() > 1 { sizes.windows(2).map(|w| (w[1] - w[0]) as f64).fold(f64::INFINITY, f64::min) } else { 10.0 };
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

pub(crate) fn heat(t: f64) -> RGBColor {
    let [r, g, b] = heat_rgb(t);
    RGBColor(r, g, b)
}

fn fig10<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, p: &PlotInputs, after: &[f64], n: usize, task: usize) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let xr = range_of(p.validation_w.iter().map(|v| v.x), 0.05);
    let yr = range_of(p.validation_w.iter().map(|v| v.y), 0.05);
    let emax = after.iter().copied().fold(0.0, f64::max).max(1e-9);
    let title = format!("Fig. 10: error after calibration (n = {n}, task {task}), top view; max {emax:.3} mm");
    let mut chart = ChartBuilder::on(root)
        .caption(title, (FAMILY, 20))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(65)
        .build_cartesian_2d(xr, yr)
        .map_err(e2s)?;
    chart.configure_mesh().x_desc("x in {W} (mm)").y_desc("y in {W} (mm)").label_style((FAMILY, 13)).draw().map_err(e2s)?;
    chart.draw_series(p.validation_w.iter().zip(after).map(|(v, e)| Circle::new((v.x, v.y), 3, heat(e / emax).filled()))).map_err(e2s)?;
    let mut order: Vec<usize> = (0..after.len()).collect();
    order.sort_by(|&a, &b| after[b].total_cmp(&after[a]));
    chart
        .draw_series(order.iter().take(10).map(|&k| Circle::new((p.validation_w[k].x, p.validation_w[k].y), 10, BLACK.stroke_width(2))))
        .map_err(e2s)?
        .label("10 largest errors")
        .legend(|(x, y)| Circle::new((x, y), 6, BLACK.stroke_width(2)));
    chart
        .draw_series(p.spheres_w.iter().map(|v| TriangleMarker::new((v.x, v.y), 7, GREEN.filled())))
        .map_err(e2s)?
        .label("datum spheres")
        .legend(|(x, y)| TriangleMarker::new((x, y), 5, GREEN.filled()));
    chart
        .draw_series(std::iter::once(Circle::new((0.0, 0.0), 0, WHITE)))
        .map_err(e2s)?
        .label(format!("colour: 0 mm (blue) to {emax:.3} mm (red)"))
        .legend(|(x, y)| Rectangle::new([(x - 6, y - 4), (x + 6, y + 4)], heat(1.0).filled()));
    legend(&mut chart, SeriesLabelPosition::MiddleRight, 12)?;
    Ok(())
}

/// Scatter of error against a distance, with the least-squares line and Pearson r.
fn regression<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, d: &[f64], e: &[f64], title: &str, xlabel: &str) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let xr = range_of(d.iter().copied(), 0.04);
    let yr = range_of(e.iter().copied(), 0.06);
    let yr = 0f64.min(yr.start)..yr.end;
    let r = pearson(d, e);
    let (intercept, slope) = least_squares_line(d, e);
    let mut chart = ChartBuilder::on(root)
        .caption(title, (FAMILY, 20))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(65)
        .build_cartesian_2d(xr.clone(), yr)
        .map_err(e2s)?;
    chart.configure_mesh().x_desc(xlabel).y_desc("error after calibration (mm)").label_style((FAMILY, 13)).draw().map_err(e2s)?;
    chart
        .draw_series(d.iter().zip(e).map(|(&x, &y)| Circle::new((x, y), 2, BLUE.mix(0.6).filled())))
        .map_err(e2s)?
        .label("validation pose")
        .legend(|(x, y)| Circle::new((x, y), 3, BLUE.filled()));
    let line = [xr.start, xr.end].map(|x| (x, intercept + slope * x));
    chart
        .draw_series(LineSeries::new(line, RED.stroke_width(2)))
        .map_err(e2s)?
        .label(format!("least squares: {:.2e} mm/mm, r = {r:.3}, r^2 = {:.3}", slope, r * r))
        .legend(|(x, y)| PathElement::new(vec![(x - 8, y), (x + 8, y)], RED.stroke_width(2)));
    legend(&mut chart, SeriesLabelPosition::UpperLeft, 13)?;
    Ok(())
}

fn fig13<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, before: &[f64], after: &[f64], n: usize) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let root = root.titled("Fig. 13: distribution of the position errors", (FAMILY, 22)).map_err(e2s)?;
    let panels = root.split_evenly((1, 2));
    for (area, (name, v, colour)) in
        panels.iter().zip([("before calibration".to_string(), before, RED), (format!("after calibration (n = {n})"), after, BLUE)])
    {
        let s = ErrorStats::of(v);
        let bins = 25usize;
        let hi = s.max.max(1e-9) * 1.0001;
        let w = hi / bins as f64;
        let mut counts = vec![0u32; bins];
        for &x in v {
            counts[((x / w) as usize).min(bins - 1)] += 1;
        }
        let cmax = counts.iter().copied().max().unwrap_or(1) as f64;
        let mut chart = ChartBuilder::on(area)
            .caption(&name, (FAMILY, 16))
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(50)
            .build_cartesian_2d(0.0..hi, 0.0..cmax * 1.45)
            .map_err(e2s)?;
        chart.configure_mesh().x_desc("position error (mm)").y_desc("validation poses").label_style((FAMILY, 12)).draw().map_err(e2s)?;
        chart
            .draw_series(
                counts
                    .iter()
                    .enumerate()
                    .map(|(k, &c)| Rectangle::new([(k as f64 * w, 0.0), ((k + 1) as f64 * w, c as f64)], colour.mix(0.6).filled())),
            )
            .map_err(e2s)?;
        let text = [
            format!("poses {}", v.len()),
            format!("mean {:.3} mm", s.mean),
            format!("median {:.3} mm", s.median),
            format!("std {:.3} mm", s.std),
            format!("p95 {:.3} mm", s.p95),
            format!("max {:.3} mm", s.max),
        ];
        for (i, t) in text.iter().enumerate() {
            chart
                .draw_series(std::iter::once(Text::new(t.clone(), (0.55 * hi, cmax * (1.4 - 0.07 * i as f64)), (FAMILY, 13))))
                .map_err(e2s)?;
        }
    }
    Ok(())
}

/// What the SPMS figures show.
pub struct SpmsPlotInputs<'a> {
    /// Per accuracy sample, largest sphere-fit residual: paper's form, minimal form, mm.
    pub residuals: [&'a [f64]; 2],
    /// Per accuracy sample, measuring error: paper's form, minimal form, mm.
    pub measuring: [&'a [f64]; 2],
    /// Table 6 per point: published before, calsim before, published after, and calsim after per
    /// selection (label, values), mm.
    pub ap_published: [[f64; 5]; 2],
    /// calsim before calibration, per point, mm.
    pub ap_before: [f64; 5],
    /// calsim after calibration per selection, per point, mm.
    pub ap_after: Vec<(String, [f64; 5])>,
    /// Mean AP after calibration per identification, per selection and set size.
    pub ap_mean_by_size: Vec<(String, BySize)>,
    /// Set size of the Table 6 comparison.
    pub table_n: usize,
}

/// Writes the SPMS figures into `dir`; returns what was written.
pub fn write_spms(dir: &Path, p: &SpmsPlotInputs<'_>) -> Result<Vec<Written>, String> {
    register_font();
    let mut out = Vec::new();
    both!(dir, "spms_fig05_fit_residuals", |root| per_sample(
        root,
        &p.residuals,
        "Fig. 5: sphere-fit residuals per measurement",
        "largest |residual| of the fit (mm)",
        Some((0.03, "0.03 mm (paper: nearly all below)"))
    ));
    out.push(Written {
        stem: "spms_fig05_fit_residuals".into(),
        caption: "Fig. 5: largest sphere-fit residual of each accuracy measurement, head identified by PSO + LM \
             (paper's form) and by LM on the minimal form"
            .into(),
    });
    both!(dir, "spms_fig06_measuring_error", |root| per_sample(
        root,
        &p.measuring,
        "Fig. 6: measuring error of the SPMS against the laser tracker",
        "|SPMS - tracker| (mm)",
        Some((0.034, "paper mean 0.034 mm"))
    ));
    out.push(Written {
        stem: "spms_fig06_measuring_error".into(),
        caption: "Fig. 6: measuring error of each sphere measurement against the laser tracker (Table 3)".into(),
    });
    both!(dir, "spms_table6_ap_per_point", |root| ap_bars(root, p));
    out.push(Written {
        stem: "spms_table6_ap_per_point".into(),
        caption: format!(
            "Table 6: ISO 9283 AP per test point before and after calibration, published and calsim (after: \
             median over the repetitions with sets of {})",
            p.table_n
        ),
    });
    let colours = [BLUE, RGBColor(230, 120, 0), RGBColor(0, 140, 60)];
    let series: Vec<(&str, RGBColor, BySize)> =
        p.ap_mean_by_size.iter().enumerate().map(|(i, (l, d))| (l.as_str(), colours[i % 3], d.clone())).collect();
    both!(dir, "spms_ap_by_set_size", |root| boxplots(
        root,
        &series,
        "Mean AP over P1-P5 after calibration per identification",
        "mean AP after calibration (mm)"
    ));
    out.push(Written {
        stem: "spms_ap_by_set_size".into(),
        caption: "Mean ISO 9283 AP over P1-P5 after each identification, per set size: random sets (the paper) and DETMAX sets on O1"
            .into(),
    });
    Ok(out)
}

fn per_sample<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    v: &[&[f64]; 2],
    title: &str,
    ylabel: &str,
    line: Option<(f64, &str)>,
) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let n = v[0].len().max(v[1].len()).max(1);
    let top = v.iter().flat_map(|s| s.iter().copied()).chain(line.map(|l| l.0)).fold(0.0, f64::max) * 1.15;
    let mut chart = ChartBuilder::on(root)
        .caption(title, (FAMILY, 22))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(65)
        .build_cartesian_2d(0.0..(n as f64 + 1.0), 0.0..top.max(1e-6))
        .map_err(e2s)?;
    chart.configure_mesh().x_desc("measurement").y_desc(ylabel).light_line_style(WHITE).label_style((FAMILY, 13)).draw().map_err(e2s)?;
    for (s, (label, colour)) in v.iter().zip([("PSO + LM, paper's 6K+3 form", BLUE), ("LM, minimal 5K+3 form", RGBColor(230, 120, 0))]) {
        chart
            .draw_series(s.iter().enumerate().map(|(i, y)| Circle::new((i as f64 + 1.0, *y), 4, colour.filled())))
            .map_err(e2s)?
            .label(label)
            .legend(move |(x, y)| Circle::new((x + 7, y), 4, colour.filled()));
    }
    if let Some((y, label)) = line {
        chart
            .draw_series(std::iter::once(PathElement::new(vec![(0.0, y), (n as f64 + 1.0, y)], BLACK.stroke_width(1))))
            .map_err(e2s)?
            .label(label)
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 14, y)], BLACK.stroke_width(1)));
    }
    legend(&mut chart, SeriesLabelPosition::MiddleRight, 14)?;
    Ok(())
}

fn ap_bars<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, p: &SpmsPlotInputs<'_>) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let mut bars: Vec<(String, RGBColor, [f64; 5])> = vec![
        ("published, before".into(), RGBColor(150, 150, 150), p.ap_published[0]),
        ("calsim, before".into(), RGBColor(200, 60, 60), p.ap_before),
        ("published, after".into(), RGBColor(90, 90, 90), p.ap_published[1]),
    ];
    let colours = [BLUE, RGBColor(0, 140, 60)];
    for (i, (l, v)) in p.ap_after.iter().enumerate() {
        bars.push((format!("calsim, after ({l})"), colours[i % 2], *v));
    }
    let top = bars.iter().flat_map(|b| b.2).filter(|x| x.is_finite()).fold(0.0, f64::max) * 1.15;
    let mut chart = ChartBuilder::on(root)
        .caption("Table 6: ISO 9283 AP per test point", (FAMILY, 22))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(65)
        .build_cartesian_2d(0.5..5.5, 0.0..top.max(1e-6))
        .map_err(e2s)?;
    chart
        .configure_mesh()
        .x_desc("test point")
        .y_desc("AP (mm)")
        .x_labels(5)
        .x_label_formatter(&|x| format!("P{x:.0}"))
        .light_line_style(WHITE)
        .label_style((FAMILY, 13))
        .draw()
        .map_err(e2s)?;
    let w = 0.8 / bars.len() as f64;
    for (i, (label, colour, v)) in bars.iter().enumerate() {
        let c = *colour;
        chart
            .draw_series(v.iter().enumerate().filter(|(_, y)| y.is_finite()).map(|(k, y)| {
                let x0 = k as f64 + 1.0 - 0.4 + i as f64 * w;
                Rectangle::new([(x0, 0.0), (x0 + w * 0.9, *y)], c.filled())
            }))
            .map_err(e2s)?
            .label(label.as_str())
            .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 14, y + 6)], c.filled()));
    }
    legend(&mut chart, SeriesLabelPosition::UpperRight, 14)?;
    Ok(())
}

/// What the sweep figures draw: per design (point and selection) the after-calibration p95 at the
/// table set size (median, P10, P90 over realisations) and the success probability per set size.
pub struct SweepPlotInputs {
    /// Per design: label, x value (the axis value where there is one numeric axis, else the point
    /// index), (median, P10, P90) of the p95, campaign time (s).
    pub designs: Vec<(String, f64, [f64; 3], f64)>,
    /// x-axis label.
    pub xlabel: String,
    /// Per design: label and (set size, P(max <= threshold)).
    pub success: Vec<(String, Vec<(f64, f64)>)>,
    /// The threshold of `success`, mm.
    pub threshold_mm: f64,
    /// Per design of a sweep that moves the datum spheres: a title, the spheres in {W} (mm) and
    /// whether its campaign ran; empty otherwise.
    pub layouts: Vec<(String, Vec<[f64; 3]>, bool)>,
}

/// Writes the sweep's figures into `dir`.
pub fn write_sweep(dir: &Path, p: &SweepPlotInputs) -> Result<Vec<Written>, String> {
    register_font();
    let mut out = Vec::new();
    both!(dir, "sweep_p95_by_design", |root| sweep_band(root, p));
    out.push(Written {
        stem: "sweep_p95_by_design".into(),
        caption: "p95 of the validation error after calibration at the table set size per design: median over realisations, bar P10-P90"
            .into(),
    });
    if !p.layouts.is_empty() {
        both!(dir, "sweep_layouts", |root| sweep_layouts(root, p));
        out.push(Written {
            stem: "sweep_layouts".into(),
            caption:
                "The datum spheres of each design seen from above in {W} (sphere 1 at the origin), with the median p95 after calibration; \
                      grey: the campaign could not measure it"
                    .into(),
        });
    }
    both!(dir, "sweep_success_by_set_size", |root| sweep_success(root, p));
    out.push(Written {
        stem: "sweep_success_by_set_size".into(),
        caption: format!("P(max error <= {} mm) per set size, one curve per design (over realisations x repetitions)", p.threshold_mm),
    });
    Ok(out)
}

fn sweep_band<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, p: &SweepPlotInputs) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let xr = range_of(p.designs.iter().map(|d| d.1), 0.08);
    let yr = range_of(p.designs.iter().flat_map(|d| [d.2[1], d.2[2]]), 0.1);
    let mut chart = ChartBuilder::on(root)
        .caption("After calibration: p95 of the validation error, median and P10-P90 over realisations", (FAMILY, 18))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(65)
        .build_cartesian_2d(xr, 0f64.min(yr.start)..yr.end)
        .map_err(e2s)?;
    chart
        .configure_mesh()
        .x_desc(p.xlabel.as_str())
        .y_desc("p95 error after calibration (mm)")
        .label_style((FAMILY, 13))
        .draw()
        .map_err(e2s)?;
    chart
        .draw_series(p.designs.iter().map(|d| PathElement::new(vec![(d.1, d.2[1]), (d.1, d.2[2])], BLUE.stroke_width(2))))
        .map_err(e2s)?
        .label("P10-P90 over realisations")
        .legend(|(x, y)| PathElement::new(vec![(x, y - 6), (x, y + 6)], BLUE.stroke_width(2)));
    chart
        .draw_series(p.designs.iter().map(|d| Circle::new((d.1, d.2[0]), 4, RED.filled())))
        .map_err(e2s)?
        .label("median")
        .legend(|(x, y)| Circle::new((x, y), 4, RED.filled()));
    legend(&mut chart, SeriesLabelPosition::MiddleRight, 13)?;
    Ok(())
}

fn sweep_success<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, p: &SweepPlotInputs) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let xr = range_of(p.success.iter().flat_map(|s| s.1.iter().map(|v| v.0)), 0.05);
    let mut chart = ChartBuilder::on(root)
        .caption(format!("Probability of a successful calibration: max error <= {} mm", p.threshold_mm), (FAMILY, 18))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(65)
        .build_cartesian_2d(xr, 0f64..1.05)
        .map_err(e2s)?;
    chart.configure_mesh().x_desc("set size n").y_desc("P(max error <= threshold)").label_style((FAMILY, 13)).draw().map_err(e2s)?;
    for (i, (label, pts)) in p.success.iter().take(12).enumerate() {
        let c = Palette99::pick(i).to_rgba();
        chart
            .draw_series(LineSeries::new(pts.iter().copied(), c.stroke_width(2)).point_size(3))
            .map_err(e2s)?
            .label(label.as_str())
            .legend(move |(x, y)| PathElement::new(vec![(x - 8, y), (x + 8, y)], c.stroke_width(2)));
    }
    legend(&mut chart, SeriesLabelPosition::LowerRight, 11)?;
    Ok(())
}

fn sweep_layouts<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, p: &SweepPlotInputs) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let n = p.layouts.len();
    let cols = (n as f64).sqrt().ceil() as usize;
    let rows = n.div_ceil(cols);
    let all = || p.layouts.iter().flat_map(|l| l.1.iter());
    let xr = range_of(all().map(|s| s[0]), 0.15);
    let yr = range_of(all().map(|s| s[1]), 0.15);
    for (panel, (title, spheres, ran)) in root.split_evenly((rows, cols)).iter().zip(&p.layouts) {
        let colour = if *ran { BLUE } else { RGBColor(170, 170, 170) };
        let mut chart = ChartBuilder::on(panel)
            .caption(title.as_str(), (FAMILY, 12))
            .margin(6)
            .build_cartesian_2d(xr.clone(), yr.clone())
            .map_err(e2s)?;
        chart.configure_mesh().disable_mesh().x_labels(3).y_labels(3).label_style((FAMILY, 9)).draw().map_err(e2s)?;
        chart.draw_series(spheres.iter().map(|s| Circle::new((s[0], s[1]), 4, colour.filled()))).map_err(e2s)?;
    }
    Ok(())
}

/// One bar of the tornado: the source, the p95 without it, and the p95 at each what-if factor.
pub type TornadoLine = (String, f64, Vec<(f64, f64)>);

/// Writes the budget's tornado plot: per source (largest share first), the p95 after calibration
/// without it and at each what-if factor, against the p95 with every source (`all_mm`).
pub fn write_tornado(dir: &Path, lines: &[TornadoLine], all_mm: f64) -> Result<Vec<Written>, String> {
    register_font();
    both!(dir, "budget_tornado", |root| tornado(root, lines, all_mm));
    Ok(vec![Written {
        stem: "budget_tornado".into(),
        caption: format!(
            "p95 after calibration with each source off or scaled (every other source as in the scenario); line: all sources, {all_mm:.3} mm"
        ),
    }])
}

fn tornado<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, lines: &[TornadoLine], all_mm: f64) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let values = || lines.iter().flat_map(|l| std::iter::once(l.1).chain(l.2.iter().map(|x| x.1))).chain(std::iter::once(all_mm));
    let xr = range_of(values(), 0.1);
    let n = lines.len().max(1);
    let mut chart = ChartBuilder::on(root)
        .caption("Uncertainty budget: p95 after calibration per source", (FAMILY, 18))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(220)
        .build_cartesian_2d(xr.clone(), -0.5..(n as f64 - 0.5))
        .map_err(e2s)?;
    let labels: Vec<String> = lines.iter().map(|l| l.0.clone()).collect();
    chart
        .configure_mesh()
        .disable_y_mesh()
        .y_labels(n)
        .y_label_formatter(&|y| {
            let k = y.round();
            if (y - k).abs() < 1e-6 && k >= 0.0 { labels.get(n - 1 - k as usize).cloned().unwrap_or_default() } else { String::new() }
        })
        .x_desc("p95 of the validation error after calibration (mm)")
        .label_style((FAMILY, 12))
        .draw()
        .map_err(e2s)?;
    let y = |k: usize| (n - 1 - k) as f64;
    let colours = [RGBColor(0, 140, 60), RGBColor(230, 120, 0), RGBColor(200, 30, 30)];
    chart
        .draw_series(
            lines
                .iter()
                .enumerate()
                .map(|(k, l)| Rectangle::new([(all_mm.min(l.1), y(k) - 0.3), (all_mm.max(l.1), y(k) + 0.3)], BLUE.mix(0.35).filled())),
        )
        .map_err(e2s)?
        .label("source off")
        .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 12, y + 5)], BLUE.mix(0.35).filled()));
    let factors: Vec<f64> = lines.first().map(|l| l.2.iter().map(|x| x.0).collect()).unwrap_or_default();
    for (j, f) in factors.iter().enumerate() {
        let c = colours[j % colours.len()];
        chart
            .draw_series(lines.iter().enumerate().filter_map(|(k, l)| l.2.get(j).map(|v| Circle::new((v.1, y(k)), 5, c.filled()))))
            .map_err(e2s)?
            .label(format!("source x{f}"))
            .legend(move |(x, y)| Circle::new((x, y), 4, c.filled()));
    }
    chart
        .draw_series(std::iter::once(PathElement::new(vec![(all_mm, -0.5), (all_mm, n as f64 - 0.5)], BLACK.stroke_width(2))))
        .map_err(e2s)?
        .label("all sources")
        .legend(|(x, y)| PathElement::new(vec![(x - 8, y), (x + 8, y)], BLACK.stroke_width(2)));
    legend(&mut chart, SeriesLabelPosition::LowerRight, 12)?;
    Ok(())
}

/// Writes the budget's predicted-versus-simulated plot: per parameter, the linear prediction's std
/// against the simulated RMS error (internal units, log-log), with every source on and with none.
pub fn write_prediction(dir: &Path, all: &[(f64, f64)], none: &[(f64, f64)]) -> Result<Vec<Written>, String> {
    register_font();
    both!(dir, "budget_predicted_vs_simulated", |root| prediction(root, all, none));
    Ok(vec![Written {
        stem: "budget_predicted_vs_simulated".into(),
        caption: "Per identified parameter: the linear prediction's std (sigma^2 (J^T J)^-1, sigma from the fit) against the \
                  simulated RMS error over identifications and realisations; on the line the prediction is right"
            .into(),
    }])
}

fn prediction<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, all: &[(f64, f64)], none: &[(f64, f64)]) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let ok = |v: &&(f64, f64)| v.0 > 0.0 && v.1 > 0.0 && v.0.is_finite() && v.1.is_finite();
    let values: Vec<f64> = all.iter().chain(none).filter(ok).flat_map(|v| [v.0, v.1]).collect();
    let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let (lo, hi) = if lo.is_finite() && hi > lo { (lo / 2.0, hi * 2.0) } else { (1e-6, 1.0) };
    let mut chart = ChartBuilder::on(root)
        .caption("Parameter errors: linear prediction against Monte Carlo", (FAMILY, 18))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d((lo..hi).log_scale(), (lo..hi).log_scale())
        .map_err(e2s)?;
    chart
        .configure_mesh()
        .x_desc("predicted std (internal units: mm, rad, rad/(N m))")
        .y_desc("simulated RMS error")
        .x_label_formatter(&|x| format!("{x:.0e}"))
        .y_label_formatter(&|y| format!("{y:.0e}"))
        .label_style((FAMILY, 12))
        .draw()
        .map_err(e2s)?;
    chart
        .draw_series(std::iter::once(PathElement::new(vec![(lo, lo), (hi, hi)], BLACK.stroke_width(1))))
        .map_err(e2s)?
        .label("simulated = predicted")
        .legend(|(x, y)| PathElement::new(vec![(x - 8, y), (x + 8, y)], BLACK.stroke_width(1)));
    let series = [(all, RGBColor(200, 30, 30), "every source on"), (none, RGBColor(0, 90, 200), "every source off (solver floor)")];
    for (points, colour, label) in series {
        if points.iter().filter(ok).count() == 0 {
            continue;
        }
        chart
            .draw_series(points.iter().filter(ok).map(|v| Circle::new((v.0, v.1), 4, colour.filled())))
            .map_err(e2s)?
            .label(label)
            .legend(move |(x, y)| Circle::new((x, y), 4, colour.filled()));
    }
    legend(&mut chart, SeriesLabelPosition::UpperLeft, 12)?;
    Ok(())
}
