//! The plan's figure: the first target's position at every planned pose in the robot's base frame
//! (a top and a side view), the validation poses marked, the arm (its collision capsules' axes)
//! at a few of the poses with the lines of sight from the tracker to their targets, the tracker,
//! the robot's base and the workspace of interest.

use std::path::Path;

use nalgebra::{Point3, Vector3};
use plotters::coord::Shift;
use plotters::prelude::*;

use super::cell::Cell;
use super::{Outcome, Plan, VALIDATION};
use crate::io::plot::{DrawResult, FAMILY, Mark, PlotError, Side, both, e2s, keyed, range_of, register_font};
use crate::robot::{JOINTS, Joints, KinState, forward};

/// The figure's file stem (`<stem>.png`, `<stem>.svg`).
pub const STEM: &str = "plan_poses";

/// Poses the arm is drawn at (in the figure and as the recording's highlighted poses).
pub const SHOWN: usize = 3;

/// The arm at one configuration, in the robot's base frame (mm).
#[derive(Clone, Debug, PartialEq)]
pub struct ArmView {
    /// The links' and SMRs' collision capsules: the ends and the radius.
    pub capsules: Vec<(Vector3<f64>, Vector3<f64>, f64)>,
    /// Every target's position.
    pub targets: Vec<Vector3<f64>>,
    /// The origins of the arm's frames 0 to 6 (a stick figure of the arm).
    pub skeleton: Vec<Vector3<f64>>,
}

/// The arm of `plan` at `q` (model joint angles): its link capsules (the robot file's), a sphere
/// per SMR, and the targets' positions.
pub fn arm_at(plan: &Plan, cell: &Cell, q: &Joints, st: &mut KinState) -> ArmView {
    forward(&cell.model, st, q);
    let mut capsules = Vec::new();
    let ends = |frame: usize, a: &[f64; 3], b: &[f64; 3], st: &KinState| {
        let f = st.base_from_frame(frame);
        ((f * Point3::from(Vector3::from(*a))).coords, (f * Point3::from(Vector3::from(*b))).coords)
    };
    if let Some(links) = &plan.robot.capsules {
        for (i, caps) in links.iter().enumerate() {
            for c in caps {
                let (a, b) = ends(i, &c.a, &c.b, st);
                capsules.push((a, b, c.radius));
            }
        }
    }
    let targets: Vec<Vector3<f64>> = (0..plan.targets.len()).map(|k| cell.target(st, k).0).collect();
    for t in &targets {
        capsules.push((*t, *t, plan.tracker.smr_diameter_mm / 2.0));
    }
    let skeleton = (0..=JOINTS).map(|i| st.base_from_frame(i).translation.vector).collect();
    ArmView { capsules, targets, skeleton }
}

/// The rows the arm is drawn at: [`SHOWN`] steps spread along the tour (its first, then every
/// third of it), positions in `o.rows`.
pub fn shown(o: &Outcome) -> Vec<usize> {
    let n = o.tour.0.len();
    let mut v: Vec<usize> = (0..SHOWN.min(n)).map(|k| o.tour.0[k * n / SHOWN.min(n).max(1)]).collect();
    v.dedup();
    v
}

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
    let arms: Vec<(String, ArmView)> =
        shown(o).into_iter().map(|i| (o.rows[i].label.clone(), arm_at(plan, cell, &o.rows[i].q, &mut st))).collect();
    both!(dir, STEM, |root| draw(root, plan, cell, &points, &arms));
    Ok(())
}

/// The colours of the arms drawn, one per pose shown.
const ARMS: [RGBColor; SHOWN] = [RGBColor(200, 110, 0), RGBColor(130, 50, 170), RGBColor(0, 140, 140)];
const CAPSULE: RGBColor = RGBColor(175, 175, 175);
const SIGHT: RGBColor = RGBColor(235, 120, 120);

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    plan: &Plan,
    cell: &Cell,
    points: &[([f64; 3], bool)],
    arms: &[(String, ArmView)],
) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let validation = points.iter().filter(|p| p.1).count();
    let title = format!(
        "Plan: {} at the {} training and {validation} validation poses (base frame, mm)",
        plan.targets[0].name,
        points.len() - validation
    );
    let root = root.titled(&title, (FAMILY, 18)).map_err(e2s)?;
    let mut key = vec![("training pose".to_string(), Mark::Dot(BLUE)), ("validation pose".to_string(), Mark::Ring(GREEN))];
    key.extend(arms.iter().zip(ARMS).map(|((l, _), c)| (format!("arm at {l} (frame origins)"), Mark::Line(c))));
    key.extend([
        ("its collision capsules' axes".to_string(), Mark::Line(CAPSULE)),
        ("line of sight".to_string(), Mark::Line(SIGHT)),
        ("tracker".to_string(), Mark::Triangle(RED)),
        ("robot base".to_string(), Mark::Triangle(BLACK)),
        ("workspace of interest".to_string(), Mark::Line(BLACK)),
    ]);
    let root = keyed(&root, &key, Side::Bottom)?;
    let t = cell.tracker();
    let (lo, hi) = (plan.workspace.min, plan.workspace.max);
    for (area, (a, b, view)) in root.split_evenly((1, 2)).iter().zip([(0usize, 1usize, "top view"), (0, 2, "side view")]) {
        let arm_ends = arms.iter().flat_map(|(_, v)| v.capsules.iter().flat_map(|c| [c.0, c.1]).chain(v.skeleton.iter().copied()));
        let axis =
            |k: usize| points.iter().map(move |p| p.0[k]).chain([t[k], 0.0, lo[k], hi[k]]).chain(arm_ends.clone().map(move |e| e[k]));
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
        for ((_, v), colour) in arms.iter().zip(ARMS) {
            chart
                .draw_series(v.targets.iter().map(|p| PathElement::new(vec![(t[a], t[b]), (p[a], p[b])], SIGHT.stroke_width(1))))
                .map_err(e2s)?;
            chart
                .draw_series(v.capsules.iter().map(|c| PathElement::new(vec![(c.0[a], c.0[b]), (c.1[a], c.1[b])], CAPSULE.stroke_width(4))))
                .map_err(e2s)?;
            let mut stick: Vec<(f64, f64)> = v.skeleton.iter().map(|p| (p[a], p[b])).collect();
            stick.extend(v.targets.first().map(|p| (p[a], p[b])));
            chart.draw_series(std::iter::once(PathElement::new(stick, colour.stroke_width(2)))).map_err(e2s)?;
        }
        chart.draw_series(points.iter().filter(|p| !p.1).map(|p| Circle::new((p.0[a], p.0[b]), 3, BLUE.mix(0.7).filled()))).map_err(e2s)?;
        chart.draw_series(points.iter().filter(|p| p.1).map(|p| Circle::new((p.0[a], p.0[b]), 5, GREEN.stroke_width(2)))).map_err(e2s)?;
        chart
            .draw_series([TriangleMarker::new((t[a], t[b]), 8, RED.filled()), TriangleMarker::new((0.0, 0.0), 8, BLACK.filled())])
            .map_err(e2s)?;
    }
    Ok(())
}
