//! The calibration report's figures (PNG and SVG through the plot kit of `io::plots`): the error
//! of every point before and after, the error against each joint's angle, the error map in the
//! robot's base frame, and the held-out errors beside their prediction.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use super::Calibration;
use crate::io::plot::{
    DrawResult, FAMILY, Mark, PlotError, Side, Written, both, colour_bar, e2s, heat, interval_bar, keyed, range_of, register_font, whole,
};

/// Writes the figures of `c` into `dir` (side by side: each its own files).
pub fn write(dir: &Path, c: &Calibration) -> Result<Vec<Written>, PlotError> {
    use rayon::prelude::*;
    register_font();
    // The marks each figure draws: a point before and after; three coordinates per joint; a point
    // in each of two views. A figure of more is written as a PNG alone.
    let n = c.chosen().fit.errors_mm.len();
    let svg = |marks: usize| marks <= crate::io::plot::MOST_SVG_MARKS;
    type Draw<'c> = Box<dyn Fn(&Path) -> DrawResult + Send + Sync + 'c>;
    let written = |svg: bool, stem: &str, caption: &str| Written { svg, stem: stem.into(), caption: caption.into() };
    let (per_point_svg, per_joint_svg, map_svg) = (svg(2 * n), svg(3 * crate::robot::JOINTS * n), svg(2 * n));
    let mut figures: Vec<(Draw<'_>, Written)> = vec![
        (
            Box::new(move |dir| {
                both!(dir, "residuals_per_point", png_only: !per_point_svg, |root| per_point(root, c));
                Ok(())
            }),
            written(
                per_point_svg,
                "residuals_per_point",
                "Error of every point before (nominal robot, fitted bases and tools) and after calibration, in file order; outliers circled",
            ),
        ),
        (
            Box::new(move |dir| {
                both!(dir, "residuals_per_joint", png_only: !per_joint_svg, |root| per_joint(root, c));
                Ok(())
            }),
            written(
                per_joint_svg,
                "residuals_per_joint",
                "Residual after calibration (x, y, z in the robot's base frame, signed) against each joint's angle: a pattern along a \
                 joint (a sag growing with the arm's reach) is an error the model does not hold",
            ),
        ),
        (
            Box::new(move |dir| {
                both!(dir, "error_map", png_only: !map_svg, |root| error_map(root, c));
                Ok(())
            }),
            written(map_svg, "error_map", "Error after calibration where each point was measured, in the robot's base frame"),
        ),
    ];
    if c.chosen().held_out.is_some() {
        figures.push((
            Box::new(move |dir| {
                both!(dir, "held_out", |root| held_out(root, c));
                Ok(())
            }),
            written(
                true,
                "held_out",
                "Held-out errors of every model (cumulative distributions), measured, with the chosen model's prediction",
            ),
        ));
    }
    figures.par_iter().map(|(draw, _)| draw(dir)).collect::<Result<Vec<()>, PlotError>>()?;
    Ok(figures.into_iter().map(|(_, w)| w).collect())
}

fn per_point<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, c: &Calibration) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let (before, after) = (&c.before.fit, &c.chosen().fit);
    let n = after.errors_mm.len();
    let ymax = before.errors_mm.iter().chain(&after.errors_mm).copied().filter(|v| v.is_finite()).fold(1e-9, f64::max) * 1.05;
    let title =
        format!("Error per point: before {:.3} mm RMS, after ({}) {:.3} mm RMS", before.stats.rms, c.chosen().name(), after.stats.rms);
    // The key under the chart: the points fill the whole width.
    let key = [
        ("before".to_string(), Mark::Dot(RED)),
        ("after".to_string(), Mark::Dot(BLUE)),
        ("outlier (after)".to_string(), Mark::Ring(BLACK)),
    ];
    let root = &keyed(root, &key, Side::Bottom)?;
    let mut chart = ChartBuilder::on(root)
        .caption(title, (FAMILY, 20))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(65)
        .build_cartesian_2d(0.0..n as f64, 0.0..ymax)
        .map_err(e2s)?;
    chart
        .configure_mesh()
        .x_desc("point (file order)")
        .y_desc("position error (mm)")
        .x_label_formatter(&whole)
        .label_style((FAMILY, 13))
        .draw()
        .map_err(e2s)?;
    for (fit, colour) in [(before, RED), (after, BLUE)] {
        chart
            .draw_series(fit.errors_mm.iter().enumerate().map(|(i, e)| Circle::new((i as f64, *e), 2, colour.mix(0.6).filled())))
            .map_err(e2s)?;
    }
    chart
        .draw_series(
            after
                .errors_mm
                .iter()
                .enumerate()
                .filter(|(i, _)| after.outlier[*i])
                .map(|(i, e)| Circle::new((i as f64, *e), 8, BLACK.stroke_width(2))),
        )
        .map_err(e2s)?;
    Ok(())
}

fn per_joint<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, c: &Calibration) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let title = format!("Residual after calibration ({}) against each joint, signed, in the base frame", c.chosen().name());
    let root = root.titled(&title, (FAMILY, 20)).map_err(e2s)?;
    let fit = &c.chosen().fit;
    let m = &c.measurements;
    let r = &fit.residual_base_mm;
    let keep: Vec<usize> = (0..r.len()).filter(|&i| !fit.outlier[i] && r[i].iter().all(|v| v.is_finite())).collect();
    let ymax = keep.iter().map(|&i| r[i].amax()).fold(1e-9, f64::max) * 1.05;
    let colours = [RED, GREEN, BLUE];
    let key: Vec<(String, Mark)> =
        ["x", "y", "z"].iter().zip(colours).map(|(a, colour)| (format!("{a} (base frame)"), Mark::Dot(colour))).collect();
    let root = &keyed(&root, &key, Side::Bottom)?;
    for (j, area) in root.split_evenly((2, 3)).iter().enumerate() {
        let angle = |i: usize| m.poses[m.points[i].pose].q[j].to_degrees();
        let xr = range_of(keep.iter().map(|&i| angle(i)), 0.03);
        let mut chart = ChartBuilder::on(area)
            .caption(format!("joint {}", j + 1), (FAMILY, 14))
            .margin(8)
            .x_label_area_size(30)
            .y_label_area_size(50)
            .build_cartesian_2d(xr, -ymax..ymax)
            .map_err(e2s)?;
        chart.configure_mesh().x_labels(5).x_desc("angle (deg)").y_desc("mm").label_style((FAMILY, 11)).draw().map_err(e2s)?;
        for (a, colour) in colours.iter().enumerate() {
            chart.draw_series(keep.iter().map(|&i| Circle::new((angle(i), r[i][a]), 2, colour.mix(0.5).filled()))).map_err(e2s)?;
        }
    }
    Ok(())
}

fn error_map<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, c: &Calibration) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let fit = &c.chosen().fit;
    let keep: Vec<usize> = (0..fit.errors_mm.len()).filter(|&i| !fit.outlier[i] && fit.errors_mm[i].is_finite()).collect();
    let emax = keep.iter().map(|&i| fit.errors_mm[i]).fold(1e-9, f64::max);
    let title = format!("Error after calibration ({}) in the base frame", c.chosen().name());
    let root = root.titled(&title, (FAMILY, 20)).map_err(e2s)?;
    let root = colour_bar(&root, emax, "error after calibration (mm)")?;
    let p = &c.points_base_mm;
    for (area, (name, a, b)) in root.split_evenly((1, 2)).iter().zip([("top view", 0, 1), ("side view", 0, 2)]) {
        let axis = ["x", "y", "z"];
        let mut chart = ChartBuilder::on(area)
            .caption(name, (FAMILY, 16))
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(55)
            .build_cartesian_2d(range_of(keep.iter().map(|&i| p[i][a]), 0.05), range_of(keep.iter().map(|&i| p[i][b]), 0.05))
            .map_err(e2s)?;
        chart
            .configure_mesh()
            .x_desc(format!("{} in {{0}} (mm)", axis[a]))
            .y_desc(format!("{} in {{0}} (mm)", axis[b]))
            .label_style((FAMILY, 12))
            .draw()
            .map_err(e2s)?;
        chart.draw_series(keep.iter().map(|&i| Circle::new((p[i][a], p[i][b]), 3, heat(fit.errors_mm[i] / emax).filled()))).map_err(e2s)?;
    }
    Ok(())
}

fn held_out<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, c: &Calibration) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let curves: Vec<(String, Vec<f64>)> = std::iter::once(&c.before)
        .chain(&c.models)
        .filter_map(|r| {
            let h = r.held_out.as_ref()?;
            let mut v: Vec<f64> = h.errors_mm.iter().zip(&h.outlier).filter(|(e, o)| !**o && e.is_finite()).map(|(e, _)| *e).collect();
            v.sort_by(f64::total_cmp);
            Some((r.name().to_string(), v))
        })
        .collect();
    let xmax = curves.iter().flat_map(|(_, v)| v.last()).copied().fold(1e-9, f64::max) * 1.05;
    let colours = [RED, GREEN, MAGENTA, BLUE];
    // The key under the chart: the curves reach every corner of it.
    let mut key: Vec<(String, Mark)> =
        curves.iter().enumerate().map(|(k, (name, _))| (format!("{name}, measured"), Mark::Line(colours[k % colours.len()]))).collect();
    if c.chosen().held_out.is_some() {
        key.push((format!("{}: predicted median and p95", c.chosen().name()), Mark::Ring(BLACK)));
    }
    let root = &keyed(root, &key, Side::Bottom)?;
    let mut chart = ChartBuilder::on(root)
        .caption(format!("Held-out errors: {}", c.options.split.describe()), (FAMILY, 18))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(65)
        .build_cartesian_2d(0.0..xmax, 0.0..1.0)
        .map_err(e2s)?;
    chart
        .configure_mesh()
        .x_desc("position error at held-out points (mm)")
        .y_desc("fraction of points")
        .label_style((FAMILY, 13))
        .draw()
        .map_err(e2s)?;
    for (k, (_, v)) in curves.iter().enumerate() {
        let colour = colours[k % colours.len()];
        let n = v.len().max(1) as f64;
        chart
            .draw_series(LineSeries::new(v.iter().enumerate().map(|(i, e)| (*e, (i + 1) as f64 / n)), colour.stroke_width(2)))
            .map_err(e2s)?;
    }
    if let Some(h) = &c.chosen().held_out {
        let pr = &h.predicted;
        let marks = [(pr.median, 0.5), (pr.p95, 0.95)];
        chart
            .draw_series(marks.iter().filter(|(x, _)| x.is_finite()).map(|&(x, y)| Circle::new((x, y), 7, BLACK.stroke_width(2))))
            .map_err(e2s)?;
    }
    Ok(())
}

/// The plan figure's stem and caption.
pub const PLAN_FIGURE: (&str, &str) = (
    "plan",
    "Held-out median error after calibration: the measured one (black diamond, dashed line) against each plan's simulated \
     P10-P90 (bar) and median (dot)",
);

/// Writes the plan figure (`plan.png`, `plan.svg`) of `plans` into `dir`: per plan, the simulated
/// P10-P90 as a bar, its median as a dot, the measured figure as a mark beside it (nothing when
/// `plans` is empty).
pub fn write_plan(dir: &Path, plans: &[(super::plan::PlanWith, super::plan::PlanComparison)]) -> Result<Option<Written>, PlotError> {
    if plans.is_empty() {
        return Ok(None);
    }
    register_font();
    both!(dir, PLAN_FIGURE.0, |root| plan(root, plans));
    Ok(Some(Written { svg: true, stem: PLAN_FIGURE.0.into(), caption: PLAN_FIGURE.1.into() }))
}

fn plan<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, plans: &[(super::plan::PlanWith, super::plan::PlanComparison)]) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let measured = plans[0].1.measured_mm;
    let hi =
        plans.iter().flat_map(|(_, p)| p.simulated_mm).chain(std::iter::once(measured)).filter(|v| v.is_finite()).fold(0.0f64, f64::max)
            * 1.15
            + 1e-9;
    let n = plans.len();
    let key = [
        ("simulated P10-P90, inside".to_string(), Mark::Interval(BLUE)),
        ("simulated P10-P90, measured outside".to_string(), Mark::Interval(RED)),
        ("simulated median".to_string(), Mark::Dot(BLACK)),
        ("measured".to_string(), Mark::Dashed(BLACK)),
    ];
    let root = &keyed(root, &key, Side::Bottom)?;
    let names: Vec<String> = plans.iter().map(|(k, _)| k.name().to_string()).collect();
    let label = |x: &f64| {
        let k = x.round();
        if (x - k).abs() < 1e-6 && k >= 0.0 && (k as usize) < names.len() { names[k as usize].clone() } else { String::new() }
    };
    let title = if measured.is_finite() {
        format!("Held-out median: measured {measured:.4} mm against each plan")
    } else {
        "Held-out median: no measured figure (the held-out fit gave no model)".to_string()
    };
    let mut chart = ChartBuilder::on(root)
        .caption(title, (FAMILY, 20))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(-0.6..(n as f64 - 0.4), 0.0..hi)
        .map_err(e2s)?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(n + 1)
        .x_label_formatter(&label)
        .x_desc("plan (what each simulated world draws)")
        .y_desc("held-out median error (mm)")
        .label_style((FAMILY, 13))
        .draw()
        .map_err(e2s)?;
    if measured.is_finite() {
        chart
            .draw_series(DashedLineSeries::new([(-0.6, measured), (n as f64 - 0.4, measured)], 8, 6, BLACK.stroke_width(1)))
            .map_err(e2s)?;
    }
    for (x, (_, p)) in plans.iter().enumerate() {
        let x = x as f64;
        let [p10, p50, p90] = p.simulated_mm;
        let colour = if p.inside { BLUE } else { RED };
        chart.draw_series(interval_bar(x, (p10, p90), 0.12, colour.stroke_width(3))).map_err(e2s)?;
        if p50.is_finite() {
            chart.draw_series(std::iter::once(Circle::new((x, p50), 4, BLACK.filled()))).map_err(e2s)?;
        }
        if measured.is_finite() {
            chart
                .draw_series(std::iter::once(PathElement::new(
                    vec![
                        (x + 0.2, measured),
                        (x + 0.25, measured * 1.02),
                        (x + 0.3, measured),
                        (x + 0.25, measured * 0.98),
                        (x + 0.2, measured),
                    ],
                    BLACK.stroke_width(2),
                )))
                .map_err(e2s)?;
        }
    }
    Ok(())
}
