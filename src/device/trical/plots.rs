//! The TriCal paper's figures 7-13 as PNG and SVG, written beside the result tables and embedded
//! in `summary.md`.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use nalgebra::Vector3;

use super::study::StudyResults;
use crate::io::plot::{
    DrawResult, FAMILY, Mark, PlotError, Side, Written, both, boxplot, colour_bar, e2s, heat, keyed, range_of, register_font, whole,
};
use crate::study::stats::{ErrorStats, pearson, regression as least_squares_line};

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

/// Writes every figure into `dir`; returns what was written.
///
/// Long by design: one call per figure of the paper, in the paper's order, each a few lines.
pub fn write_all(dir: &Path, results: &StudyResults, inputs: &PlotInputs) -> Result<Vec<Written>, PlotError> {
    register_font();
    let mut out = Vec::new();

    both!(dir, "fig07_validation_poses", |root| fig07(root, inputs));
    out.push(Written {
        svg: true,
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
        svg: true,
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
        svg: true,
        stem: "fig09_std_error_by_set_size".into(),
        caption: "Fig. 9: standard deviation of the validation error of each identification per set size".into(),
    });

    let Some((task, after)) = crate::device::trical::figures::representative(results, inputs.table_n) else {
        return Ok(out);
    };
    let n = inputs.table_n;
    both!(dir, "fig10_error_map", |root| fig10(root, inputs, after, n, task));
    out.push(Written {
        svg: true,
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
        svg: true,
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
        svg: true,
        stem: "fig12_error_vs_distance_to_ccz".into(),
        caption: "Fig. 12: error after calibration against the distance to the centre of the calibration zone (centroid of the spheres)"
            .into(),
    });
    both!(dir, "fig13_error_histograms", |root| fig13(root, &results.before_errors, after, n));
    out.push(Written {
        svg: true,
        stem: "fig13_error_histograms".into(),
        caption: "Fig. 13: distribution of the position errors before and after calibration, with descriptive statistics".into(),
    });
    Ok(out)
}

fn fig07<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, p: &PlotInputs) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let root = root.titled("Fig. 7: validation poses (TCP in {W}) and datum spheres", (FAMILY, 22)).map_err(e2s)?;
    let key = [
        ("validation pose".to_string(), Mark::Dot(BLUE)),
        ("datum sphere".to_string(), Mark::Dot(RED)),
        ("robot base (origin of its frame)".to_string(), Mark::Triangle(BLACK)),
    ];
    let root = keyed(&root, &key, Side::Bottom)?;
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
        chart.draw_series(p.validation_w.iter().map(|v| Circle::new((v[a], v[b]), 2, BLUE.mix(0.5).filled()))).map_err(e2s)?;
        chart.draw_series(p.spheres_w.iter().map(|v| Circle::new((v[a], v[b]), 6, RED.filled()))).map_err(e2s)?;
        chart.draw_series(std::iter::once(TriangleMarker::new((p.base_w[a], p.base_w[b]), 8, BLACK.filled()))).map_err(e2s)?;
    }
    Ok(())
}

fn fig10<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, p: &PlotInputs, after: &[f64], n: usize, task: usize) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let emax = after.iter().copied().fold(0.0, f64::max).max(1e-9);
    let key = [
        ("validation pose, coloured by its error".to_string(), Mark::Dot(heat(0.5))),
        ("the 10 largest errors".to_string(), Mark::Ring(BLACK)),
        ("datum sphere".to_string(), Mark::Triangle(GREEN)),
    ];
    let root = keyed(root, &key, Side::Bottom)?;
    let root = colour_bar(&root, emax, "error after calibration (mm)")?;
    let root = &root;
    let xr = range_of(p.validation_w.iter().map(|v| v.x), 0.05);
    let yr = range_of(p.validation_w.iter().map(|v| v.y), 0.05);
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
        .map_err(e2s)?;
    chart.draw_series(p.spheres_w.iter().map(|v| TriangleMarker::new((v.x, v.y), 7, GREEN.filled()))).map_err(e2s)?;
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
    let key = [
        ("validation pose".to_string(), Mark::Dot(BLUE)),
        (format!("least squares: {slope:.2e} mm/mm, r = {r:.3}, r^2 = {:.3}", r * r), Mark::Line(RED)),
    ];
    let root = &keyed(root, &key, Side::Bottom)?;
    let mut chart = ChartBuilder::on(root)
        .caption(title, (FAMILY, 20))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(65)
        .build_cartesian_2d(xr.clone(), yr)
        .map_err(e2s)?;
    chart.configure_mesh().x_desc(xlabel).y_desc("error after calibration (mm)").label_style((FAMILY, 13)).draw().map_err(e2s)?;
    chart.draw_series(d.iter().zip(e).map(|(&x, &y)| Circle::new((x, y), 2, BLUE.mix(0.6).filled()))).map_err(e2s)?;
    let line = [xr.start, xr.end].map(|x| (x, intercept + slope * x));
    chart.draw_series(LineSeries::new(line, RED.stroke_width(2))).map_err(e2s)?;
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
        chart
            .configure_mesh()
            .x_desc("position error (mm)")
            .y_desc("validation poses")
            .y_label_formatter(&whole)
            .label_style((FAMILY, 12))
            .draw()
            .map_err(e2s)?;
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
