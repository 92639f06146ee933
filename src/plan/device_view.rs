//! A device plan's figure (`plan_poses.png`/`.svg`) and Rerun recording (`plan.rrd`), mm in the
//! robot's base frame: the device's TCP at every configuration, the datum spheres, the validation
//! configurations, the arm with its device at a few of them, the workspace of interest.
//!
//! Entity paths of the recording: `cell/spheres`, `cell/workspace`, `cell/keep_out`, `cell/floor`,
//! `cell/frames/base` (static); `plan/tcp` (static, every configuration's TCP, labelled);
//! `plan/vias/via01` ... (static, the arm and the device at each via configuration of the tour,
//! passed, not measured, in orange); `plan/robot` on the `tour_step` timeline (the arm and the
//! device at each stop of `tour.csv`, a via in orange and labelled);
//! `tour/largest_move_deg` on `tour_step`; `study/heldout_median_mm` on the `world` timeline.

use std::path::Path;

use nalgebra::{Point3, Vector3};
use plotters::coord::Shift;
use plotters::prelude::*;
use rerun::{Boxes3D, Points3D, RecordingStream, Scalars, SeriesLines};

use super::device::{DeviceOutcome, DevicePlan};
use super::plot::{SHOWN, STEM};
use crate::io::plot::{DrawResult, FAMILY, Mark, PlotError, Side, both, e2s, keyed, range_of, register_font};
use crate::io::record::{RecordError, Rr, capsules, log_axes, p3};
use crate::robot::{JOINTS, Joints, KinState, forward};

/// Colours of the spheres' configurations (sphere k takes `SPHERES[k % len]`).
const SPHERES: [RGBColor; 4] = [RGBColor(40, 80, 220), RGBColor(220, 120, 0), RGBColor(150, 40, 170), RGBColor(0, 140, 140)];
const CAPSULE: RGBColor = RGBColor(175, 175, 175);

/// The arm and its device at `q`: capsules (ends, radius), the frame origins, the TCP; base frame.
type View = (Vec<(Vector3<f64>, Vector3<f64>, f64)>, Vec<Vector3<f64>>, Vector3<f64>);

fn view(o: &DeviceOutcome, q: &Joints, st: &mut KinState) -> View {
    forward(&o.start, st, q);
    let mut caps = Vec::new();
    let ends = |frame: usize, a: &[f64; 3], b: &[f64; 3], st: &KinState| {
        let f = st.base_from_frame(frame);
        ((f * Point3::from(Vector3::from(*a))).coords, (f * Point3::from(Vector3::from(*b))).coords)
    };
    for (i, cs) in o.links.iter().enumerate() {
        for c in cs {
            let (a, b) = ends(i, &c.a, &c.b, st);
            caps.push((a, b, c.radius));
        }
    }
    for c in &o.device {
        let (a, b) = ends(JOINTS, &c.a, &c.b, st);
        caps.push((a, b, c.radius));
    }
    let skeleton = (0..=JOINTS).map(|i| st.base_from_frame(i).translation.vector).collect();
    (caps, skeleton, st.tcp_base)
}

/// The sphere centres in the base frame (the model before calibration's base in {W}), mm.
fn spheres_base(o: &DeviceOutcome) -> Vec<Vector3<f64>> {
    let base_from_world = crate::robot::world_from_base(&o.start).inverse();
    o.groups_w_mm.iter().map(|c| (base_from_world * Point3::from(Vector3::from(*c))).coords).collect()
}

/// The rows the arm is drawn at: [`SHOWN`] steps spread along the tour.
fn shown(o: &DeviceOutcome) -> Vec<usize> {
    let n = o.tour.0.len();
    let mut v: Vec<usize> = (0..SHOWN.min(n)).map(|k| o.tour.0[k * n / SHOWN.min(n).max(1)]).collect();
    v.dedup();
    v
}

/// Writes the figure of `o` into `dir`.
pub fn write_figure(dir: &Path, plan: &DevicePlan, o: &DeviceOutcome) -> Result<(), PlotError> {
    register_font();
    let mut st = KinState::default();
    let points: Vec<(Vector3<f64>, Option<usize>)> = o.rows.iter().map(|r| (view(o, &r.q, &mut st).2, r.group)).collect();
    let arms: Vec<(String, View)> = shown(o).into_iter().map(|i| (o.rows[i].label.clone(), view(o, &o.rows[i].q, &mut st))).collect();
    let spheres = spheres_base(o);
    both!(dir, STEM, |root| draw(root, plan, &points, &arms, &spheres));
    Ok(())
}

/// The figure's title and key.
fn title_and_key(plan: &DevicePlan, points: &[(Vector3<f64>, Option<usize>)], groups: usize) -> (String, Vec<(String, Mark)>) {
    let validation = points.iter().filter(|p| p.1.is_none()).count();
    let chosen = points.len() - validation;
    let (title, on) = if plan.kind == "spms" {
        (
            format!("SPMS plan: the sphere centre at the {chosen} measured and {validation} validation configurations (base frame, mm)"),
            "measured at station",
        )
    } else {
        (
            format!("TriCal plan: the TCP at the {chosen} centred and {validation} validation configurations (base frame, mm)"),
            "centred on sphere",
        )
    };
    let mut key: Vec<(String, Mark)> = (0..groups).map(|g| (format!("{on} {}", g + 1), Mark::Dot(SPHERES[g % SPHERES.len()]))).collect();
    key.extend([
        ("validation configuration".to_string(), Mark::Ring(GREEN)),
        ("arm at three configurations (frame origins)".to_string(), Mark::Line(BLACK)),
        ("its and the device's capsules' axes".to_string(), Mark::Line(CAPSULE)),
        ("robot base".to_string(), Mark::Triangle(BLACK)),
        ("workspace of interest".to_string(), Mark::Line(BLACK)),
    ]);
    (title, key)
}

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    plan: &DevicePlan,
    points: &[(Vector3<f64>, Option<usize>)],
    arms: &[(String, View)],
    spheres: &[Vector3<f64>],
) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let (title, key) = title_and_key(plan, points, spheres.len());
    let root = root.titled(&title, (FAMILY, 18)).map_err(e2s)?;
    let root = keyed(&root, &key, Side::Bottom)?;
    let (lo, hi) = (plan.workspace.min, plan.workspace.max);
    for (area, (a, b, name)) in root.split_evenly((1, 2)).iter().zip([(0usize, 1usize, "top view"), (0, 2, "side view")]) {
        let ends = arms.iter().flat_map(|(_, v)| v.0.iter().flat_map(|c| [c.0, c.1]).chain(v.1.iter().copied()));
        let axis = |k: usize| points.iter().map(move |p| p.0[k]).chain([0.0, lo[k], hi[k]]).chain(ends.clone().map(move |e| e[k]));
        let mut chart = ChartBuilder::on(area)
            .caption(name, (FAMILY, 14))
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(55)
            .build_cartesian_2d(range_of(axis(a), 0.05), range_of(axis(b), 0.05))
            .map_err(e2s)?;
        let label = |k: usize| ["x (mm)", "y (mm)", "z (mm)"][k];
        chart.configure_mesh().x_desc(label(a)).y_desc(label(b)).label_style((FAMILY, 12)).draw().map_err(e2s)?;
        let corners = vec![(lo[a], lo[b]), (hi[a], lo[b]), (hi[a], hi[b]), (lo[a], hi[b]), (lo[a], lo[b])];
        chart.draw_series(std::iter::once(PathElement::new(corners, BLACK.stroke_width(1)))).map_err(e2s)?;
        for (_, v) in arms {
            chart
                .draw_series(v.0.iter().map(|c| PathElement::new(vec![(c.0[a], c.0[b]), (c.1[a], c.1[b])], CAPSULE.stroke_width(4))))
                .map_err(e2s)?;
            let mut stick: Vec<(f64, f64)> = v.1.iter().map(|p| (p[a], p[b])).collect();
            stick.push((v.2[a], v.2[b]));
            chart.draw_series(std::iter::once(PathElement::new(stick, BLACK.stroke_width(2)))).map_err(e2s)?;
        }
        chart
            .draw_series(
                points.iter().filter_map(|p| p.1.map(|g| Circle::new((p.0[a], p.0[b]), 3, SPHERES[g % SPHERES.len()].mix(0.7).filled()))),
            )
            .map_err(e2s)?;
        chart
            .draw_series(points.iter().filter(|p| p.1.is_none()).map(|p| Circle::new((p.0[a], p.0[b]), 5, GREEN.stroke_width(2))))
            .map_err(e2s)?;
        chart.draw_series(spheres.iter().map(|c| Cross::new((c[a], c[b]), 6, BLACK.stroke_width(2)))).map_err(e2s)?;
        chart.draw_series([TriangleMarker::new((0.0, 0.0), 8, BLACK.filled())]).map_err(e2s)?;
    }
    Ok(())
}

/// The arm and the device at each stop of the tour on the `tour_step` timeline (a via
/// configuration in the via colour, labelled), the largest joint move to each stop, and the arm
/// at every via configuration.
fn log_tour(rec: &RecordingStream, o: &DeviceOutcome, views: &[View], colour: impl Fn(usize) -> rerun::Color) -> Rr {
    let mut st = KinState::default();
    super::record::log_vias(rec, &o.tour.0, &o.routing, |q| view(o, q, &mut KinState::default()).0)?;
    rec.log_static("tour/largest_move_deg", &SeriesLines::new().with_names(["largest joint move, deg"]))?;
    let via = {
        let [r, g, b] = super::record::VIA_RGB;
        rerun::Color::from_rgb(r, g, b)
    };
    let mut prev: Option<Joints> = None;
    for (step, stop) in super::select::stops(&o.tour.0, &o.routing).iter().enumerate() {
        rec.set_time_sequence("tour_step", step as i64);
        let q = match stop {
            super::select::Stop::Pose(i) => {
                rec.log("plan/robot", &capsules(&views[*i].0).with_colors([colour(*i)]))?;
                o.rows[*i].q
            }
            super::select::Stop::Via(label, q) => {
                rec.log("plan/robot", &capsules(&view(o, q, &mut st).0).with_colors([via]).with_labels([label.clone()]))?;
                *q
            }
        };
        let step_deg = prev.map_or(0.0, |p| p.iter().zip(&q).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max).to_degrees());
        rec.log("tour/largest_move_deg", &Scalars::new([step_deg]))?;
        prev = Some(q);
    }
    Ok(())
}

/// Writes the recording of `o` to `path`.
pub fn write_recording(path: &Path, plan: &DevicePlan, o: &DeviceOutcome) -> Result<(), RecordError> {
    let name = plan.path.file_stem().map_or_else(|| "plan".to_string(), |s| s.to_string_lossy().into_owned());
    crate::io::record::save_on(
        path,
        &format!("calsim plan {name}"),
        |rec| log_all(rec, plan, o),
        &["/cell/**", "/plan/**"],
        ("tour: largest joint move to each stop, deg", "/tour"),
        "predicted held-out median per world, mm (timeline `world`)",
        "tour_step",
    )
}

/// The cell, static: the workspace of interest, the keep-out boxes, the floor and the base frame.
fn log_cell(rec: &RecordingStream, plan: &DevicePlan) -> Rr {
    let boxed = |lo: &Vector3<f64>, hi: &Vector3<f64>| (p3(&((lo + hi) / 2.0)), p3(&((hi - lo) / 2.0)));
    let (c, h) = boxed(&plan.workspace.min, &plan.workspace.max);
    rec.log_static(
        "cell/workspace",
        &Boxes3D::from_centers_and_half_sizes([c], [h])
            .with_labels(["workspace of interest"])
            .with_colors([rerun::Color::from_unmultiplied_rgba(40, 40, 40, 40)]),
    )?;
    if !plan.keep_out.is_empty() {
        let b: Vec<_> = plan.keep_out.iter().map(|b| boxed(&b.min, &b.max)).collect();
        rec.log_static(
            "cell/keep_out",
            &Boxes3D::from_centers_and_half_sizes(b.iter().map(|x| x.0), b.iter().map(|x| x.1))
                .with_labels(plan.keep_out.iter().map(|b| b.name.clone()))
                .with_colors([rerun::Color::from_unmultiplied_rgba(200, 60, 60, 60)]),
        )?;
    }
    if let Some(z) = plan.floor_z_mm {
        rec.log_static(
            "cell/floor",
            &Boxes3D::from_centers_and_half_sizes([[0.0, 0.0, z as f32]], [[1500.0f32, 1500.0, 0.0]])
                .with_colors([rerun::Color::from_unmultiplied_rgba(150, 130, 100, 50)]),
        )?;
    }
    log_axes(rec, "cell/frames/base", &nalgebra::Isometry3::identity(), 150.0)?;
    Ok(())
}

fn log_all(rec: &RecordingStream, plan: &DevicePlan, o: &DeviceOutcome) -> Rr {
    rec.log_static("/", &rerun::ViewCoordinates::RIGHT_HAND_Z_UP())?;
    let spheres = spheres_base(o);
    rec.log_static(
        "cell/spheres",
        &Points3D::new(spheres.iter().map(p3))
            .with_radii([6.35f32])
            .with_labels((1..=spheres.len()).map(|k| format!("{} {k}", super::device::group_word(plan))))
            .with_colors([rerun::Color::from_rgb(200, 200, 200)]),
    )?;
    log_cell(rec, plan)?;
    let mut st = KinState::default();
    let views: Vec<View> = o.rows.iter().map(|r| view(o, &r.q, &mut st)).collect();
    let colour = |i: usize| match o.rows[i].group {
        Some(g) => {
            let c = SPHERES[g % SPHERES.len()];
            rerun::Color::from_rgb(c.0, c.1, c.2)
        }
        None => rerun::Color::from_rgb(40, 170, 70),
    };
    rec.log_static(
        "plan/tcp",
        &Points3D::new(views.iter().map(|v| p3(&v.2)))
            .with_radii([3.0f32])
            .with_colors((0..views.len()).map(colour))
            .with_labels(o.rows.iter().map(|r| r.label.clone())),
    )?;
    log_tour(rec, o, &views, colour)?;
    rec.reset_time();
    super::record::log_heldout_medians(rec, &o.prediction.per_world_mm)
}
