//! A sweep's figures: the p95 per design with its band, the success probability per set size,
//! the layouts from above.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::io::plot::{DrawResult, FAMILY, PlotError, Written, both, e2s, legend, range_of, register_font};

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
pub fn write(dir: &Path, p: &SweepPlotInputs) -> Result<Vec<Written>, PlotError> {
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

