//! The plan's Rerun recording (`plan.rrd`, mm in the robot's base frame): the cell, the arm at
//! every planned pose in the order of the tour with the lines of sight from the tracker to its
//! targets, and the predicted held-out error per world, with a blueprint that opens on the 3D
//! cell next to the tour's moves.
//!
//! Entity paths:
//! - `cell/tracker`, `cell/workspace`, `cell/keep_out`, `cell/floor`, `cell/frames/base`: static;
//! - `plan/targets`: static, every target at every pose (training blue, validation green,
//!   labelled with the pose);
//! - `plan/shown/robot`: static, the arm at the figure's poses ([`super::plot::shown`]);
//! - `plan/vias/via01` ...: static, the arm at each via configuration of the tour (a re-routed
//!   move's stop on the way, passed, not measured), one entity each, in orange;
//! - `plan/robot` and `plan/sight` on the `tour_step` timeline: the arm at each stop of the tour
//!   (`tour.csv`'s rows: the planned poses and the via configurations, a via in orange and
//!   labelled) and the lines from the tracker to its targets (none at a via);
//! - `tour/largest_move_deg` on `tour_step`: the largest joint move to each stop;
//! - `study/heldout_median_mm` on the `world` timeline: each world's predicted held-out median.
//!
//! The recording is an observer: it is written from the finished plan, after the numerical work.

use std::path::Path;

use nalgebra::Vector3;
use rerun::{Boxes3D, Color, LineStrips3D, Points3D, RecordingStream, Scalars, SeriesLines};

use super::cell::Cell;
use super::plot::{arm_at, shown};
use super::select::{Routing, Stop, stops};
use super::{Outcome, Plan, VALIDATION};
use crate::io::record::{RecordError, Rr, capsules, log_axes, p3};
use crate::robot::KinState;

/// The recording's file name in the plan's directory.
pub const FILE: &str = "plan.rrd";

/// Half extent of the floor drawn, mm.
const FLOOR_HALF_MM: f64 = 1500.0;

const TRAINING_RGB: [u8; 3] = [60, 90, 220];
const VALIDATION_RGB: [u8; 3] = [40, 170, 70];
const SIGHT_RGB: [u8; 3] = [235, 90, 90];
/// Colour of the arm at a via configuration of the tour.
pub const VIA_RGB: [u8; 3] = [230, 150, 30];

fn rgb(c: [u8; 3]) -> Color {
    Color::from_rgb(c[0], c[1], c[2])
}

/// The arm at each stop of the tour on the `tour_step` timeline (a via configuration in
/// [`VIA_RGB`], labelled, without lines of sight), the lines of sight from the tracker to its
/// targets, the largest joint move to each stop, and the arm at every via configuration.
fn log_tour(rec: &RecordingStream, plan: &Plan, cell: &Cell, o: &Outcome, views: &[super::plot::ArmView]) -> Rr {
    let t = cell.tracker();
    let mut st = KinState::default();
    let colour = |i: usize| if o.rows[i].split == VALIDATION { VALIDATION_RGB } else { TRAINING_RGB };
    log_vias(rec, &o.tour.0, &o.routing, |q| arm_at(plan, cell, q, &mut KinState::default()).capsules)?;
    rec.log_static("tour/largest_move_deg", &SeriesLines::new().with_names(["largest joint move, deg"]))?;
    let mut prev: Option<crate::robot::Joints> = None;
    for (step, stop) in stops(&o.tour.0, &o.routing).iter().enumerate() {
        rec.set_time_sequence("tour_step", step as i64);
        let q = match stop {
            Stop::Pose(i) => {
                let v = &views[*i];
                rec.log("plan/robot", &capsules(&v.capsules).with_colors([rgb(colour(*i))]))?;
                rec.log(
                    "plan/sight",
                    &LineStrips3D::new(v.targets.iter().map(|p| vec![p3(&t), p3(p)]))
                        .with_radii([1.5f32])
                        .with_colors([rgb(SIGHT_RGB)])
                        .with_labels(plan.targets.iter().map(|tg| format!("{} {}", o.rows[*i].label, tg.name))),
                )?;
                o.rows[*i].q
            }
            Stop::Via(label, q) => {
                let v = arm_at(plan, cell, q, &mut st);
                rec.log("plan/robot", &capsules(&v.capsules).with_colors([rgb(VIA_RGB)]).with_labels([label.clone()]))?;
                // A via configuration is passed, not measured: no line of sight.
                rec.log("plan/sight", &LineStrips3D::new(std::iter::empty::<Vec<[f32; 3]>>()))?;
                *q
            }
        };
        let step_deg = prev.map_or(0.0, |p| p.iter().zip(&q).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max).to_degrees());
        rec.log("tour/largest_move_deg", &Scalars::new([step_deg]))?;
        prev = Some(q);
    }
    Ok(())
}

/// The arm at every via configuration of the tour, static, one entity each
/// (`plan/vias/via01` ...: the label of its `tour.csv` row), drawn in [`VIA_RGB`] by `arm` (the
/// capsules at a configuration); `order` the tour (positions in the rows), `routing` its
/// re-routed moves.
pub fn log_vias(rec: &RecordingStream, order: &[usize], routing: &Routing, arm: impl Fn(&crate::robot::Joints) -> Vec<Capsule>) -> Rr {
    for stop in stops(order, routing) {
        if let Stop::Via(label, q) = stop {
            rec.log_static(
                format!("plan/vias/{label}"),
                &capsules(&arm(&q)).with_colors([rgb(VIA_RGB)]).with_labels([format!("{label} (passed, not measured)")]),
            )?;
        }
    }
    Ok(())
}

/// A capsule: its ends and radius, mm.
pub type Capsule = (Vector3<f64>, Vector3<f64>, f64);

/// Writes the recording of `o` to `path`.
pub fn write(path: &Path, plan: &Plan, cell: &Cell, o: &Outcome) -> Result<(), RecordError> {
    let name = plan.path.file_stem().map_or_else(|| "plan".to_string(), |s| s.to_string_lossy().into_owned());
    crate::io::record::save_on(
        path,
        &format!("calsim plan {name}"),
        |rec| log_all(rec, plan, cell, o),
        &["/cell/**", "/plan/**"],
        ("tour: largest joint move to each stop, deg", "/tour"),
        "predicted held-out median per world, mm (timeline `world`)",
        "tour_step",
    )
}

/// The cell, static: the tracker, the workspace of interest, the keep-out boxes, the floor and
/// the base frame.
fn log_cell(rec: &RecordingStream, plan: &Plan, cell: &Cell) -> Rr {
    let t = cell.tracker();
    rec.log_static(
        "cell/tracker",
        &Points3D::new([p3(&t)])
            .with_radii([plan.tracker.head_radius_mm as f32])
            .with_labels(["laser tracker"])
            .with_colors([Color::from_rgb(240, 200, 0)]),
    )?;
    let boxed = |lo: &Vector3<f64>, hi: &Vector3<f64>| (p3(&((lo + hi) / 2.0)), p3(&((hi - lo) / 2.0)));
    let (c, h) = boxed(&plan.workspace.min, &plan.workspace.max);
    rec.log_static(
        "cell/workspace",
        &Boxes3D::from_centers_and_half_sizes([c], [h])
            .with_labels(["workspace of interest"])
            .with_colors([Color::from_unmultiplied_rgba(40, 40, 40, 40)]),
    )?;
    if !plan.keep_out.is_empty() {
        let b: Vec<_> = plan.keep_out.iter().map(|b| boxed(&b.min, &b.max)).collect();
        rec.log_static(
            "cell/keep_out",
            &Boxes3D::from_centers_and_half_sizes(b.iter().map(|x| x.0), b.iter().map(|x| x.1))
                .with_labels(plan.keep_out.iter().map(|b| b.name.clone()))
                .with_colors([Color::from_unmultiplied_rgba(200, 60, 60, 60)]),
        )?;
    }
    if let Some(z) = plan.floor_z_mm {
        rec.log_static(
            "cell/floor",
            &Boxes3D::from_centers_and_half_sizes([[0.0, 0.0, z as f32]], [[FLOOR_HALF_MM as f32, FLOOR_HALF_MM as f32, 0.0]])
                .with_colors([Color::from_unmultiplied_rgba(150, 130, 100, 50)]),
        )?;
    }
    log_axes(rec, "cell/frames/base", &nalgebra::Isometry3::identity(), 150.0)?;
    Ok(())
}

fn log_all(rec: &RecordingStream, plan: &Plan, cell: &Cell, o: &Outcome) -> Rr {
    rec.log_static("/", &rerun::ViewCoordinates::RIGHT_HAND_Z_UP())?;
    log_cell(rec, plan, cell)?;

    let mut st = KinState::default();
    let views: Vec<_> = o.rows.iter().map(|r| arm_at(plan, cell, &r.q, &mut st)).collect();
    let colour = |i: usize| if o.rows[i].split == VALIDATION { VALIDATION_RGB } else { TRAINING_RGB };
    rec.log_static(
        "plan/targets",
        &Points3D::new(views.iter().flat_map(|v| v.targets.iter().map(p3)))
            .with_radii([(plan.tracker.smr_diameter_mm / 2.0) as f32])
            .with_colors(views.iter().enumerate().flat_map(|(i, v)| v.targets.iter().map(move |_| rgb(colour(i)))))
            .with_labels(
                views
                    .iter()
                    .enumerate()
                    .flat_map(|(i, v)| plan.targets.iter().take(v.targets.len()).map(move |tg| format!("{} {}", o.rows[i].label, tg.name))),
            ),
    )?;
    let shown_caps: Vec<_> = shown(o).into_iter().flat_map(|i| views[i].capsules.clone()).collect();
    rec.log_static("plan/shown/robot", &capsules(&shown_caps).with_colors([Color::from_unmultiplied_rgba(110, 110, 110, 160)]))?;

    log_tour(rec, plan, cell, o, &views)?;
    rec.reset_time();
    log_heldout_medians(rec, &o.prediction.per_world_mm)
}

/// The simulated worlds' held-out medians as a series over the worlds (the finite ones), for
/// both kinds of plan.
pub(super) fn log_heldout_medians(rec: &RecordingStream, per_world_mm: &[f64]) -> Rr {
    rec.log_static("study/heldout_median_mm", &SeriesLines::new().with_names(["held-out median, mm"]))?;
    for (w, m) in per_world_mm.iter().enumerate() {
        if m.is_finite() {
            rec.set_time_sequence("world", w as i64);
            rec.log("study/heldout_median_mm", &Scalars::new([*m]))?;
        }
    }
    rec.reset_time();
    Ok(())
}
