//! The optimiser's figures: convergence of each restart, the Pareto front of campaign time
//! against P(success) on the held-out worlds, and the winning cell to scale in {W} and in the
//! robot's base frame.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::io::plot::{DrawResult, FAMILY, PlotError, Written, both, e2s, legend, range_of, register_font};

use super::sheet::{CellSheet, tidy};

/// What the figures draw.
pub struct OptimisePlotInputs {
    /// Per restart: its label and its scores in ask order.
    pub convergence: Vec<(String, Vec<f64>)>,
    /// Per verified design: label, campaign hours, (estimate, lower, upper) on held-out worlds,
    /// whether it is the optimiser's.
    pub front: Vec<(String, f64, [f64; 3], bool)>,
    /// The objective in words (the y axis of the front).
    pub objective: String,
    /// What the search score is, in words (the convergence figure's caption).
    pub score: String,
    /// The winning cell (TriCal designs).
    pub cell: Option<CellSheet>,
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
        svg: true,
        stem: "optimise_convergence".into(),
        caption: format!(
            "Best search score so far per restart against the designs evaluated (lower is better: {}; designs the geometry \
             rules out score 100 and more, designs whose every world fails 30 and more)",
            p.score
        ),
    });
    if !p.front.is_empty() {
        both!(dir, "optimise_front", |root| front(root, p));
        out.push(Written {
            svg: true,
            stem: "optimise_front".into(),
            caption: "Campaign time against the objective on the held-out worlds, with its interval: the optimiser's best design of \
                      each count (red) and the compared designs (blue)"
                .into(),
        });
    }
    if let Some(sheet) = &p.cell {
        let panels = cell_panels(sheet);
        both!(dir, "optimise_cell", (1400, 1400), |root| cell(root, &panels));
        out.push(Written {
            svg: true,
            stem: "optimise_cell".into(),
            caption: "The winning cell to scale, in {W} (top) and in the robot's base frame (bottom), from above and from the side: \
                      the sphere centres (red, numbered, with their height z), the plate's top (blue), the robot base's origin \
                      (black, its x axis 100 mm long) and the tool points the arm reaches with the device in its approach cone \
                      (grey); the coordinates are in `spheres.csv` and the summary"
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

/// One panel of the cell drawing: what it draws in its own plane, mm.
#[derive(Clone, Debug, PartialEq)]
pub struct CellPanel {
    /// Its title.
    pub title: String,
    /// Its axes.
    pub x_desc: String,
    /// See `x_desc`.
    pub y_desc: String,
    /// The spheres: label and position.
    pub spheres: Vec<(String, [f64; 2])>,
    /// The robot base's origin, and the tip of its x axis (100 mm).
    pub base: [f64; 2],
    /// See `base`.
    pub base_x: [f64; 2],
    /// The outline of the plate's top (its corners in order).
    pub plate: Vec<[f64; 2]>,
    /// The reachable tool points.
    pub reach: Vec<[f64; 2]>,
}

/// The four panels of the cell drawing: {W} from above (x, y) and from the side (x, z), the base
/// frame from above (x, y) and from the side along the plate's slope (the horizontal direction of
/// the plate's normal in the base frame, or x for a level plate; against z).
pub fn cell_panels(s: &CellSheet) -> Vec<CellPanel> {
    let w_from_b = s.world_from_base_iso();
    let base_x_w = w_from_b * nalgebra::Point3::new(100.0, 0.0, 0.0);
    let normal_b = w_from_b.rotation.inverse() * nalgebra::Vector3::z();
    let h = nalgebra::Vector2::new(normal_b.x, normal_b.y);
    let u = if h.norm() > 1e-6 { h.normalize() } else { nalgebra::Vector2::x() };
    let mut out = Vec::new();
    type Projection<'a> = &'a dyn Fn([f64; 3]) -> [f64; 2];
    let mut panel = |title: String, x_desc: &str, y_desc: &str, to: &dyn Fn([f64; 3]) -> [f64; 3], proj: Projection<'_>| {
        let sphere_label = |k: usize, p: [f64; 3]| format!("{} (z {})", k + 1, tidy(p[2], 1));
        out.push(CellPanel {
            title,
            x_desc: x_desc.into(),
            y_desc: y_desc.into(),
            spheres: s.spheres_w_mm.iter().enumerate().map(|(k, p)| (sphere_label(k, to(*p)), proj(to(*p)))).collect(),
            base: proj(to(s.base_origin_w_mm())),
            base_x: proj(to([base_x_w.x, base_x_w.y, base_x_w.z])),
            plate: s.plate_top_w_mm.iter().map(|p| proj(to(*p))).collect(),
            reach: s.reach_w_mm.iter().map(|p| proj(to(*p))).collect(),
        });
    };
    let in_w = |p: [f64; 3]| p;
    let in_base = |p: [f64; 3]| s.to_base(p);
    panel("{W} from above".into(), "x in {W}, mm", "y in {W}, mm", &in_w, &|p| [p[0], p[1]]);
    panel("{W} from the side".into(), "x in {W}, mm", "z in {W}, mm", &in_w, &|p| [p[0], p[2]]);
    panel("base frame from above".into(), "x in the base frame, mm", "y in the base frame, mm", &in_base, &|p| [p[0], p[1]]);
    panel(
        format!("base frame from the side, along the plate's slope ({}, {}) of x, y", tidy(u.x, 2), tidy(u.y, 2)),
        "along the slope in the base frame, mm",
        "z in the base frame, mm",
        &in_base,
        &|p| [u.x * p[0] + u.y * p[1], p[2]],
    );
    out
}

/// Ranges of a panel's axes holding every point drawn, padded by 50 mm and widened on one axis so
/// that a millimetre is as long on both axes of a plot area of `px` pixels (to scale).
fn to_scale(p: &CellPanel, px: (u32, u32)) -> (std::ops::Range<f64>, std::ops::Range<f64>) {
    let all: Vec<[f64; 2]> =
        p.spheres.iter().map(|x| x.1).chain([p.base, p.base_x]).chain(p.plate.iter().copied()).chain(p.reach.iter().copied()).collect();
    let lo = |k: usize| all.iter().map(|q| q[k]).fold(f64::INFINITY, f64::min) - 50.0;
    let hi = |k: usize| all.iter().map(|q| q[k]).fold(f64::NEG_INFINITY, f64::max) + 50.0;
    let (mut x, mut y) = ((lo(0), hi(0)), (lo(1), hi(1)));
    let (w, h) = (f64::from(px.0.max(1)), f64::from(px.1.max(1)));
    let per_px = ((x.1 - x.0) / w).max((y.1 - y.0) / h);
    let grow = |r: (f64, f64), n: f64| {
        let c = (r.0 + r.1) / 2.0;
        (c - per_px * n / 2.0, c + per_px * n / 2.0)
    };
    x = grow(x, w);
    y = grow(y, h);
    (x.0..x.1, y.0..y.1)
}

fn cell<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, panels: &[CellPanel]) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let (margin, x_area, y_area) = (10u32, 40u32, 60u32);
    for (area, p) in root.split_evenly((2, 2)).iter().zip(panels) {
        let area = area.titled(&p.title, (FAMILY, 15)).map_err(e2s)?;
        let (w, h) = area.dim_in_pixel();
        let (xr, yr) = to_scale(p, (w.saturating_sub(2 * margin + y_area), h.saturating_sub(2 * margin + x_area)));
        let mut chart = ChartBuilder::on(&area)
            .margin(margin)
            .x_label_area_size(x_area)
            .y_label_area_size(y_area)
            .build_cartesian_2d(xr, yr)
            .map_err(e2s)?;
        chart.configure_mesh().x_desc(p.x_desc.as_str()).y_desc(p.y_desc.as_str()).label_style((FAMILY, 12)).draw().map_err(e2s)?;
        let grey = RGBColor(200, 200, 200);
        chart
            .draw_series(p.reach.iter().map(|q| Circle::new((q[0], q[1]), 1, grey.filled())))
            .map_err(e2s)?
            .label("tool points reached (device in its cone)")
            .legend(move |(x, y)| Circle::new((x, y), 3, grey.filled()));
        // Edge by edge: a side view folds the outline back on itself, and a wide path's joins
        // at such turns would spike.
        let edges = p.plate.iter().zip(p.plate.iter().cycle().skip(1)).map(|(a, b)| (a[0], a[1], b[0], b[1]));
        chart
            .draw_series(edges.map(|(x0, y0, x1, y1)| PathElement::new(vec![(x0, y0), (x1, y1)], BLUE.stroke_width(2))))
            .map_err(e2s)?
            .label("plate top")
            .legend(move |(x, y)| PathElement::new(vec![(x - 8, y), (x + 8, y)], BLUE.stroke_width(2)));
        chart
            .draw_series(std::iter::once(PathElement::new(vec![(p.base[0], p.base[1]), (p.base_x[0], p.base_x[1])], BLACK.stroke_width(2))))
            .map_err(e2s)?;
        chart
            .draw_series(std::iter::once(Circle::new((p.base[0], p.base[1]), 6, BLACK.filled())))
            .map_err(e2s)?
            .label("robot base origin, x axis")
            .legend(move |(x, y)| Circle::new((x, y), 4, BLACK.filled()));
        chart
            .draw_series(p.spheres.iter().map(|(_, q)| Circle::new((q[0], q[1]), 5, RED.filled())))
            .map_err(e2s)?
            .label("sphere centres (number, z)")
            .legend(move |(x, y)| Circle::new((x, y), 4, RED.filled()));
        chart
            .draw_series(p.spheres.iter().map(|(l, q)| EmptyElement::at((q[0], q[1])) + Text::new(l.clone(), (7, -16), (FAMILY, 12))))
            .map_err(e2s)?;
        legend(&mut chart, SeriesLabelPosition::UpperRight, 11)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A millimetre is as many pixels on both axes, whatever the points' spread and the area.
    #[test]
    fn the_cell_panels_are_to_scale() {
        let panel = CellPanel {
            title: String::new(),
            x_desc: String::new(),
            y_desc: String::new(),
            spheres: vec![("1".into(), [0.0, 0.0]), ("2".into(), [300.0, 20.0])],
            base: [150.0, -250.0],
            base_x: [150.0, -150.0],
            plate: vec![[-40.0, -40.0], [340.0, -40.0], [340.0, 60.0], [-40.0, 60.0]],
            reach: vec![[900.0, 10.0]],
        };
        for px in [(600, 400), (400, 600), (640, 640)] {
            let (x, y) = to_scale(&panel, px);
            let (mx, my) = ((x.end - x.start) / f64::from(px.0), (y.end - y.start) / f64::from(px.1));
            assert!((mx - my).abs() < 1e-9 * mx, "{px:?}: {mx} vs {my} mm per pixel");
            for q in panel
                .spheres
                .iter()
                .map(|s| s.1)
                .chain([panel.base, panel.base_x])
                .chain(panel.plate.iter().copied())
                .chain(panel.reach.iter().copied())
            {
                assert!(x.contains(&q[0]) && y.contains(&q[1]), "{q:?} outside {x:?} x {y:?}");
            }
        }
    }
}
