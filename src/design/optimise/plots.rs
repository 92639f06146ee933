//! The optimiser's figures: convergence of each restart, the Pareto front of campaign time
//! against P(success) on the held-out worlds, and the winning cell to scale in {W}.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::io::plot::{DrawResult, FAMILY, PlotError, Written, both, e2s, legend, range_of, register_font};

/// The winning cell: its points in the region's frame, sampled reachable tool points in the same
/// frame, and the base's origin, mm.
pub type CellDrawing = (Vec<[f64; 3]>, Vec<[f64; 3]>, [f64; 3]);

/// What the figures draw.
pub struct OptimisePlotInputs {
    /// Per restart: its label and its scores in ask order.
    pub convergence: Vec<(String, Vec<f64>)>,
    /// Per verified design: label, campaign hours, (estimate, lower, upper) on held-out worlds,
    /// whether it is the optimiser's.
    pub front: Vec<(String, f64, [f64; 3], bool)>,
    /// The objective in words (the y axis of the front).
    pub objective: String,
    /// The winning cell: its points in the region's frame, mm, and sampled reachable tool points
    /// of the arm in the same frame (empty where the device has none), the base's origin.
    pub cell: Option<CellDrawing>,
    /// The objective's target on the front's y axis (the least P(success), or the error
    /// threshold of a minimised error), if it has one.
    pub target: Option<f64>,
    /// The campaign budget, h, if the objective has one.
    pub budget_h: Option<f64>,
}

/// Writes the figures into `dir`.
pub fn write(dir: &Path, p: &OptimisePlotInputs) -> Result<Vec<Written>, PlotError> {
    register_font();
    let mut out = Vec::new();
    both!(dir, "optimise_convergence", |root| convergence(root, p));
    out.push(Written {
        stem: "optimise_convergence".into(),
        caption: "Best search score so far per restart against the designs evaluated (lower is better: minus P(success) plus the \
                  constraints' shortfalls; designs the geometry rules out score 100 and more)"
            .into(),
    });
    if !p.front.is_empty() {
        both!(dir, "optimise_front", |root| front(root, p));
        out.push(Written {
            stem: "optimise_front".into(),
            caption: "Campaign time against the objective on the held-out worlds, with its interval: the optimiser's best design of \
                      each count (red) and the compared designs (blue)"
                .into(),
        });
    }
    if p.cell.is_some() {
        both!(dir, "optimise_cell", |root| cell(root, p));
        out.push(Written {
            stem: "optimise_cell".into(),
            caption: "The winning cell to scale in the base scenario's {W}: the points (red), the robot base (black square) and tool \
                      points the arm reaches (grey), from above and from the side"
                .into(),
        });
    }
    Ok(out)
}

fn convergence<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, p: &OptimisePlotInputs) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let best: Vec<(String, Vec<(f64, f64)>)> = p
        .convergence
        .iter()
        .map(|(l, s)| {
            let mut m = f64::INFINITY;
            (
                l.clone(),
                s.iter()
                    .enumerate()
                    .map(|(i, v)| {
                        m = m.min(*v);
                        ((i + 1) as f64, m)
                    })
                    .filter(|x| x.1.is_finite() && x.1 < 50.0)
                    .collect(),
            )
        })
        .collect();
    let xr = range_of(best.iter().flat_map(|b| b.1.iter().map(|v| v.0)), 0.03);
    let yr = range_of(best.iter().flat_map(|b| b.1.iter().map(|v| v.1)), 0.1);
    let mut chart = ChartBuilder::on(root)
        .caption("Search: best score so far per restart", (FAMILY, 18))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(65)
        .build_cartesian_2d(xr, yr)
        .map_err(e2s)?;
    chart
        .configure_mesh()
        .x_desc("designs evaluated")
        .y_desc("best score (lower is better)")
        .label_style((FAMILY, 13))
        .draw()
        .map_err(e2s)?;
    for (i, (label, pts)) in best.iter().enumerate() {
        let c = Palette99::pick(i).to_rgba();
        chart
            .draw_series(LineSeries::new(pts.iter().copied(), c.stroke_width(2)))
            .map_err(e2s)?
            .label(label.as_str())
            .legend(move |(x, y)| PathElement::new(vec![(x - 8, y), (x + 8, y)], c.stroke_width(2)));
    }
    legend(&mut chart, SeriesLabelPosition::UpperRight, 12)?;
    Ok(())
}

fn front<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, p: &OptimisePlotInputs) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let pts: Vec<&(String, f64, [f64; 3], bool)> = p.front.iter().filter(|d| d.1.is_finite() && d.2[0].is_finite()).collect();
    let xr = range_of(pts.iter().map(|d| d.1).chain(p.budget_h), 0.08);
    let yr = range_of(pts.iter().flat_map(|d| [d.2[1], d.2[2]]).chain(p.target), 0.08);
    let (x0, x1, y0, y1) = (xr.start, xr.end, yr.start, yr.end);
    let mut chart = ChartBuilder::on(root)
        .caption("Held-out worlds: campaign time against the objective", (FAMILY, 18))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(65)
        .build_cartesian_2d(xr, yr)
        .map_err(e2s)?;
    chart
        .configure_mesh()
        .x_desc("campaign time, h (median over worlds)")
        .y_desc(p.objective.as_str())
        .label_style((FAMILY, 13))
        .draw()
        .map_err(e2s)?;
    let grey = RGBColor(90, 90, 90);
    if let Some(t) = p.target {
        chart
            .draw_series(std::iter::once(PathElement::new(vec![(x0, t), (x1, t)], grey.stroke_width(1))))
            .map_err(e2s)?
            .label(format!("target {t}"))
            .legend(move |(x, y)| PathElement::new(vec![(x - 8, y), (x + 8, y)], grey.stroke_width(1)));
    }
    if let Some(h) = p.budget_h {
        let dash = RGBColor(160, 110, 0);
        chart
            .draw_series(DashedLineSeries::new(vec![(h, y0), (h, y1)], 6, 4, dash.stroke_width(1)))
            .map_err(e2s)?
            .label(format!("campaign budget {h} h"))
            .legend(move |(x, y)| PathElement::new(vec![(x - 8, y), (x + 8, y)], dash.stroke_width(1)));
    }
    for (ours, colour, label) in [(true, RED, "optimiser (best of each count)"), (false, BLUE, "compared designs")] {
        let of: Vec<&&(String, f64, [f64; 3], bool)> = pts.iter().filter(|d| d.3 == ours).collect();
        chart.draw_series(of.iter().map(|d| PathElement::new(vec![(d.1, d.2[1]), (d.1, d.2[2])], colour.stroke_width(2)))).map_err(e2s)?;
        chart
            .draw_series(of.iter().map(|d| Circle::new((d.1, d.2[0]), 4, colour.filled())))
            .map_err(e2s)?
            .label(label)
            .legend(move |(x, y)| Circle::new((x, y), 4, colour.filled()));
        if ours {
            chart
                .draw_series(of.iter().map(|d| {
                    // Beside the marker, not over it: 8 px right, 14 px up.
                    EmptyElement::at((d.1, d.2[0])) + Text::new(d.0.split(',').next().unwrap_or("").to_string(), (8, -14), (FAMILY, 12))
                }))
                .map_err(e2s)?;
        }
    }
    legend(&mut chart, SeriesLabelPosition::LowerRight, 12)?;
    Ok(())
}

fn cell<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, p: &OptimisePlotInputs) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let Some((points, reach, base)) = &p.cell else { return Ok(()) };
    let panels = root.split_evenly((1, 2));
    for (panel, (a, b, title)) in panels.iter().zip([(0, 1, "from above: x, y in {W}, mm"), (0, 2, "from the side: x, z in {W}, mm")]) {
        let all = || points.iter().chain(reach.iter()).chain(std::iter::once(base));
        let lo = all().map(|q| q[a].min(q[b])).fold(f64::INFINITY, f64::min);
        let hi = all().map(|q| q[a].max(q[b])).fold(f64::NEG_INFINITY, f64::max);
        // One scale on both axes: the cell to scale.
        let (lo, hi) = (lo - 50.0, hi + 50.0);
        let mut chart = ChartBuilder::on(panel)
            .caption(title, (FAMILY, 14))
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(50)
            .build_cartesian_2d(lo..hi, lo..hi)
            .map_err(e2s)?;
        chart.configure_mesh().label_style((FAMILY, 11)).draw().map_err(e2s)?;
        chart.draw_series(reach.iter().map(|q| Circle::new((q[a], q[b]), 1, RGBColor(200, 200, 200).filled()))).map_err(e2s)?;
        chart
            .draw_series(std::iter::once(Rectangle::new(
                [(base[a] - 20.0, base[b] - 20.0), (base[a] + 20.0, base[b] + 20.0)],
                BLACK.filled(),
            )))
            .map_err(e2s)?;
        chart.draw_series(points.iter().map(|q| Circle::new((q[a], q[b]), 5, RED.filled()))).map_err(e2s)?;
        chart
            .draw_series(points.iter().enumerate().map(|(k, q)| Text::new(format!("{}", k + 1), (q[a] + 12.0, q[b] + 12.0), (FAMILY, 12))))
            .map_err(e2s)?;
    }
    Ok(())
}
