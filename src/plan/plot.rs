//! The plan's figure: the first target's position at every planned pose in the robot's base frame
//! (a top and a side view), the validation poses marked, the tracker, the robot's base and the
//! workspace of interest.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use super::cell::Cell;
use super::{Outcome, Plan, VALIDATION};
use crate::io::plot::{DrawResult, FAMILY, Mark, PlotError, Side, both, e2s, keyed, range_of, register_font};
use crate::robot::{KinState, forward};

/// The figure's file stem (`<stem>.png`, `<stem>.svg`).
pub const STEM: &str = "plan_poses";

/// Writes the figure of `o` into `dir`.
pub fn write(dir: &Path, plan: &Plan, cell: &Cell, o: &Outcome) -> Result<(), PlotError> {
    register_font();
    let mut st = KinState::default();
    let points: Vec<([f64; 3], bool)> = o
        .rows
        .iter()
        .map(|r| {
            forward(&cell.model, &mut st, &r.q);
            let p = cell.target(&st, 0).0;
            ([p.x, p.y, p.z], r.split == VALIDATION)
        })
        .collect();
    both!(dir, STEM, |root| draw(root, plan, cell, &points));
    Ok(())
}

fn draw<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, plan: &Plan, cell: &Cell, points: &[([f64; 3], bool)]) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let validation = points.iter().filter(|p| p.1).count();
    let title = format!(
        "Plan: {} at the {} training and {validation} validation poses (base frame, mm)",
        plan.targets[0].name,
        points.len() - validation
    );
    let root = root.titled(&title, (FAMILY, 18)).map_err(e2s)?;
    let key = [
        ("training pose".to_string(), Mark::Dot(BLUE)),
        ("validation pose".to_string(), Mark::Ring(GREEN)),
        ("tracker".to_string(), Mark::Triangle(RED)),
        ("robot base".to_string(), Mark::Triangle(BLACK)),
        ("workspace of interest".to_string(), Mark::Line(BLACK)),
    ];
    let root = keyed(&root, &key, Side::Bottom)?;
    let t = cell.tracker();
    let (lo, hi) = (plan.workspace.min, plan.workspace.max);
    for (area, (a, b, view)) in root.split_evenly((1, 2)).iter().zip([(0usize, 1usize, "top view"), (0, 2, "side view")]) {
        let axis = |k: usize| points.iter().map(move |p| p.0[k]).chain([t[k], 0.0, lo[k], hi[k]]);
        let mut chart = ChartBuilder::on(area)
            .caption(view, (FAMILY, 14))
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(55)
            .build_cartesian_2d(range_of(axis(a), 0.05), range_of(axis(b), 0.05))
            .map_err(e2s)?;
        let name = |k: usize| ["x (mm)", "y (mm)", "z (mm)"][k];
        chart.configure_mesh().x_desc(name(a)).y_desc(name(b)).label_style((FAMILY, 12)).draw().map_err(e2s)?;
        let corners = vec![(lo[a], lo[b]), (hi[a], lo[b]), (hi[a], hi[b]), (lo[a], hi[b]), (lo[a], lo[b])];
        chart.draw_series(std::iter::once(PathElement::new(corners, BLACK.stroke_width(1)))).map_err(e2s)?;
        chart.draw_series(points.iter().filter(|p| !p.1).map(|p| Circle::new((p.0[a], p.0[b]), 3, BLUE.mix(0.7).filled()))).map_err(e2s)?;
        chart.draw_series(points.iter().filter(|p| p.1).map(|p| Circle::new((p.0[a], p.0[b]), 5, GREEN.stroke_width(2)))).map_err(e2s)?;
        chart
            .draw_series([TriangleMarker::new((t[a], t[b]), 8, RED.filled()), TriangleMarker::new((0.0, 0.0), 8, BLACK.filled())])
            .map_err(e2s)?;
    }
    Ok(())
}
