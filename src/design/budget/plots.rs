//! A budget's figures: the tornado of the sources and the linear prediction against the Monte
//! Carlo.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::io::plot::{
    DrawResult, FAMILY, Mark, PlotError, Side, Written, both, e2s, interval_bar_h, keyed, pale, range_of, register_font,
};

/// One bar of the tornado: a source and the p95 after calibration without it and scaled.
pub struct TornadoLine {
    /// The source's label.
    pub source: String,
    /// p95 after calibration with the source off (the all-on p95 plus the median per-world change,
    /// where the worlds were paired), mm.
    pub off_mm: f64,
    /// Where the change from every source on puts the p95 with the source off: `all_mm` plus the
    /// interval of the paired per-world difference (drawn as an error bar; one that crosses the
    /// all-sources line is noise), mm.
    pub off_interval_mm: Option<(f64, f64)>,
    /// Per what-if factor: the factor and the p95 after calibration with the source scaled by it, mm.
    pub scaled_mm: Vec<(f64, f64)>,
    /// Per what-if factor, as `off_interval_mm` for the scaled source, mm.
    pub scaled_interval_mm: Vec<Option<(f64, f64)>>,
}

/// Writes the budget's tornado plot: per source (largest share first), the p95 after calibration
/// without it and at each what-if factor, against the p95 with every source (`all_mm`).
pub fn write_tornado(dir: &Path, lines: &[TornadoLine], all_mm: f64) -> Result<Vec<Written>, PlotError> {
    register_font();
    both!(dir, "budget_tornado", |root| tornado(root, lines, all_mm));
    Ok(vec![Written {
        svg: true,
        stem: "budget_tornado".into(),
        caption: format!(
            "p95 after calibration with each source off or scaled (every other source as in the scenario), each read as a change from all sources on, paired per world: the line, all sources, {all_mm:.3} mm, plus the median per-world change, with its 95 % interval (a bar that crosses the line is noise)"
        ),
    }])
}

fn tornado<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, lines: &[TornadoLine], all_mm: f64) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let colours = [RGBColor(0, 140, 60), RGBColor(230, 120, 0), RGBColor(200, 30, 30)];
    let factors: Vec<f64> = lines.first().map(|l| l.scaled_mm.iter().map(|x| x.0).collect()).unwrap_or_default();
    let mut key = vec![("source off".to_string(), Mark::Bar(pale(BLUE, 0.35)))];
    if lines.iter().any(|l| l.off_interval_mm.is_some()) {
        key.push(("its change from all on, 95 % interval over worlds".to_string(), Mark::Interval(BLACK)));
    }
    key.extend(factors.iter().enumerate().map(|(j, f)| (format!("source x{f}"), Mark::Dot(colours[j % colours.len()]))));
    key.push((format!("all sources, {all_mm:.3} mm"), Mark::Line(BLACK)));
    let root = &keyed(root, &key, Side::Bottom)?;
    let ends = |l: &TornadoLine| {
        std::iter::once(l.off_interval_mm)
            .chain(l.scaled_interval_mm.iter().copied())
            .flatten()
            .flat_map(|(a, b)| [a, b])
            .collect::<Vec<_>>()
    };
    let values = || {
        lines
            .iter()
            .flat_map(|l| std::iter::once(l.off_mm).chain(l.scaled_mm.iter().map(|x| x.1)).chain(ends(l)))
            .filter(|v| v.is_finite())
            .chain(std::iter::once(all_mm))
    };
    let xr = range_of(values(), 0.1);
    let n = lines.len().max(1);
    let mut chart = ChartBuilder::on(root)
        .caption("Uncertainty budget: p95 after calibration per source", (FAMILY, 18))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(220)
        .build_cartesian_2d(xr.clone(), -0.5..(n as f64 - 0.5))
        .map_err(e2s)?;
    let labels: Vec<String> = lines.iter().map(|l| l.source.clone()).collect();
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
    chart
        .draw_series(lines.iter().enumerate().map(|(k, l)| {
            Rectangle::new([(all_mm.min(l.off_mm), y(k) - 0.3), (all_mm.max(l.off_mm), y(k) + 0.3)], BLUE.mix(0.35).filled())
        }))
        .map_err(e2s)?;
    // The interval of the p95 without the source, at the bar's end.
    for (k, l) in lines.iter().enumerate() {
        if let Some(ci) = l.off_interval_mm {
            chart.draw_series(interval_bar_h(y(k), ci, 0.15, BLACK.stroke_width(2))).map_err(e2s)?;
        }
    }
    for j in 0..factors.len() {
        let c = colours[j % colours.len()];
        // Each factor's interval just below its dot, so that the bars of the factors do not overlap.
        let dy = 0.12 * (j + 1) as f64;
        for (k, l) in lines.iter().enumerate() {
            if let Some(Some(ci)) = l.scaled_interval_mm.get(j) {
                chart.draw_series(interval_bar_h(y(k) - dy, *ci, 0.05, c.stroke_width(2))).map_err(e2s)?;
            }
        }
        chart
            .draw_series(lines.iter().enumerate().filter_map(|(k, l)| l.scaled_mm.get(j).map(|v| Circle::new((v.1, y(k)), 5, c.filled()))))
            .map_err(e2s)?;
    }
    chart
        .draw_series(std::iter::once(PathElement::new(vec![(all_mm, -0.5), (all_mm, n as f64 - 0.5)], BLACK.stroke_width(2))))
        .map_err(e2s)?;
    Ok(())
}

/// Writes the budget's predicted-versus-simulated plot: per parameter, the linear prediction's std
/// against the simulated RMS error (internal units, log-log), with every source on and with none.
pub fn write_prediction(dir: &Path, all: &[(f64, f64)], none: &[(f64, f64)]) -> Result<Vec<Written>, PlotError> {
    register_font();
    both!(dir, "budget_predicted_vs_simulated", |root| prediction(root, all, none));
    Ok(vec![Written {
        svg: true,
        stem: "budget_predicted_vs_simulated".into(),
        caption: "Per identified parameter: the linear prediction's std (sigma^2 (J^T J)^-1, sigma from the fit) against the \
                  simulated RMS error over identifications and realisations; on the line the prediction is right"
            .into(),
    }])
}

fn prediction<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, all: &[(f64, f64)], none: &[(f64, f64)]) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let series = [(all, RGBColor(200, 30, 30), "every source on"), (none, RGBColor(0, 90, 200), "every source off (solver floor)")];
    let mut key = vec![("simulated = predicted".to_string(), Mark::Line(BLACK))];
    key.extend(series.iter().filter(|s| !s.0.is_empty()).map(|s| (format!("{} (one dot per parameter)", s.2), Mark::Dot(s.1))));
    let root = &keyed(root, &key, Side::Bottom)?;
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
    chart.draw_series(std::iter::once(PathElement::new(vec![(lo, lo), (hi, hi)], BLACK.stroke_width(1)))).map_err(e2s)?;
    for (points, colour, _) in series {
        chart.draw_series(points.iter().filter(ok).map(|v| Circle::new((v.0, v.1), 4, colour.filled()))).map_err(e2s)?;
    }
    Ok(())
}
