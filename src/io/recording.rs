//! The Rerun recording of a study (`study.rrd`): the cell, the robot at every pool and validation
//! configuration, the TriCal centring readings, the validation errors before and after
//! calibration, and the per-task figures of the study, with a blueprint that opens on the 3D cell
//! next to the time series (in tabs: the one of the opening timeline first).
//!
//! The recorder is an observer: it is fed the finished experiment and study results and runs after
//! the numerical work, so a run without a recording executes no Rerun code at all.
//!
//! Entity paths (all lengths in mm, in {W}):
//! - `cell/spheres`, `cell/solids/{risers,boxes}`, `cell/tracker`, `cell/frames/{world,base}`: static;
//! - `pool/tcp` (static, coloured by sphere) and `pool/robot` on the `pool_configuration` timeline;
//! - `pool/centring/{x,y,z}`: indicator readings per iteration on the `centring_reading` timeline;
//! - `validation/robot` on the `validation_pose` timeline;
//! - `validation/{before,after}`: static points coloured by error; `validation/error_vectors`:
//!   the after-calibration error vectors magnified by [`ERROR_MAGNIFICATION`];
//! - `study/{validation_mean_mm,validation_max_mm,o1}` on the `task` and `set_size` timelines.

use std::path::Path;

use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};
use rerun::blueprint::{Blueprint, BlueprintActivation, Horizontal, Spatial3DView, Tabs, TimePanel, TimeSeriesView};
use rerun::{Arrows3D, Boxes3D, Capsules3D, Color, Points3D, RecordingStream, Scalars, SeriesLines};

use crate::cell::collision::{CapsuleSpec, LinkCapsules};
use crate::cell::solids::{Solid, cell_solids};
use crate::experiment::Experiment;
use crate::robot::{JOINTS, KinState, RobotModel, forward, world_from_base};
use crate::study::StudyResults;

/// Factor by which the after-calibration error vectors are drawn longer than they are.
pub const ERROR_MAGNIFICATION: f64 = 200.0;

/// Sphere colours of the pool (sphere 1, 2, 3, then repeating).
const SPHERE_COLOURS: [[u8; 3]; 4] = [[230, 80, 60], [60, 160, 80], [70, 110, 230], [200, 160, 40]];

type Rr = Result<(), rerun::RecordingStreamError>;

fn p3(v: &Vector3<f64>) -> [f32; 3] {
    [v.x as f32, v.y as f32, v.z as f32]
}

fn quat(q: &UnitQuaternion<f64>) -> rerun::Quaternion {
    rerun::Quaternion::from_xyzw([q.i as f32, q.j as f32, q.k as f32, q.w as f32])
}

/// The error colour scale of the figures ([`crate::io::plots::heat_rgb`]).
fn heat(t: f64) -> Color {
    let [r, g, b] = crate::io::plots::heat_rgb(t);
    Color::from_rgb(r, g, b)
}

/// Capsules between world points, as Rerun draws them (a length along +Z, moved and turned).
fn capsules(ends: &[(Vector3<f64>, Vector3<f64>, f64)]) -> Capsules3D {
    let lengths: Vec<f32> = ends.iter().map(|(a, b, _)| (b - a).norm() as f32).collect();
    let radii: Vec<f32> = ends.iter().map(|(_, _, r)| *r as f32).collect();
    let translations: Vec<[f32; 3]> = ends.iter().map(|(a, _, _)| p3(a)).collect();
    let rotations: Vec<rerun::Quaternion> = ends
        .iter()
        .map(|(a, b, _)| {
            quat(
                &UnitQuaternion::rotation_between(&Vector3::z(), &(b - a))
                    .unwrap_or_else(|| UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)),
            )
        })
        .collect();
    Capsules3D::from_lengths_and_radii(lengths, radii).with_translations(translations).with_quaternions(rotations)
}

/// The robot's link and device capsules in {W} at joint values `q` of `model`.
fn robot_capsules(
    model: &RobotModel,
    wb: &Isometry3<f64>,
    st: &mut KinState,
    q: &[f64; JOINTS],
    links: &LinkCapsules,
    tool: &[CapsuleSpec],
) -> Vec<(Vector3<f64>, Vector3<f64>, f64)> {
    forward(model, st, q);
    let mut out = Vec::new();
    let mut push = |frame: Isometry3<f64>, c: &CapsuleSpec| {
        let a = wb * frame * Point3::from(Vector3::from(c.a));
        let b = wb * frame * Point3::from(Vector3::from(c.b));
        out.push((a.coords, b.coords, c.radius));
    };
    for (i, caps) in links.iter().enumerate() {
        for c in caps {
            push(st.base_from_frame(i), c);
        }
    }
    for c in tool {
        push(st.base_from_frame(JOINTS), c);
    }
    out
}

/// The identified model of task `index`, or `None` when it identified nothing.
fn identified(results: &StudyResults, before: &RobotModel, index: usize) -> Option<RobotModel> {
    let t = results.tasks.iter().find(|t| t.task.index == index)?;
    let values: Option<Vec<f64>> = t.id.values.iter().copied().collect();
    results.set.unpack(before, &values?).ok()
}

/// Writes the recording of `experiment` and `results` to `path`; `representative` is the task of
/// the after-calibration views (see [`crate::study::figures::representative`]).
pub fn write(
    path: &Path,
    name: &str,
    experiment: &Experiment,
    before: &RobotModel,
    results: &StudyResults,
    representative: Option<usize>,
) -> Result<(), String> {
    let rec = rerun::RecordingStreamBuilder::new("calsim").recording_name(name).save(path).map_err(|e| e.to_string())?;
    log_all(&rec, experiment, before, results, representative).map_err(|e| e.to_string())?;
    blueprint(
        &["/cell/**", "/pool/tcp", "/pool/robot", "/validation/**"],
        ("TriCal centring: indicator readings", "/pool/centring"),
        "study: validation error and O1 per task (timeline `task`)",
    )
    .send(&rec, BlueprintActivation { make_active: true, make_default: true })
    .map_err(|e| e.to_string())?;
    rec.flush_blocking().map_err(|e| e.to_string())?;
    Ok(())
}

/// The layout both kinds of recording open on: the 3D cell (`cell_contents`) next to two time
/// series in tabs, the first on the `pool_configuration` timeline the file opens on, the second the
/// study's per-task series (on `task`).
fn blueprint(cell_contents: &[&str], first_series: (&str, &str), study_title: &str) -> Blueprint {
    Blueprint::new(
        Horizontal::new([
            Spatial3DView::new("cell").with_origin("/").with_contents(cell_contents.iter().copied()).into(),
            Tabs::new([
                TimeSeriesView::new(first_series.0).with_origin(first_series.1).into(),
                TimeSeriesView::new(study_title).with_origin("/study").into(),
            ])
            .into(),
        ])
        .with_column_shares([3.0, 2.0]),
    )
    .with_time_panel(TimePanel::new().with_timeline("pool_configuration"))
}

/// Static x, y, z arrows (red, green, blue) of `frame`, `len` mm long.
fn log_axes(rec: &RecordingStream, path: &str, frame: &Isometry3<f64>, len: f64) -> Rr {
    let o = frame.translation.vector;
    let v: Vec<[f32; 3]> = (0..3).map(|k| p3(&(frame.rotation * Vector3::ith(k, len)))).collect();
    rec.log_static(
        path,
        &Arrows3D::from_vectors(v).with_origins([p3(&o); 3]).with_colors([
            Color::from_rgb(230, 40, 40),
            Color::from_rgb(40, 200, 40),
            Color::from_rgb(40, 80, 230),
        ]),
    )
}

///
/// Long by design: one block per entity of the recording (cell, pool, centring readings,
/// validation, study series), in the order of the blueprint.
fn log_all(rec: &RecordingStream, e: &Experiment, before: &RobotModel, results: &StudyResults, representative: Option<usize>) -> Rr {
    rec.log_static("/", &rerun::ViewCoordinates::RIGHT_HAND_Z_UP())?;
    let truth = &e.robot.truth;
    let world_from_base_true = world_from_base(truth);
    let base_from_world = world_from_base_true.inverse();

    // The cell, static.
    let r_ball = e.cell.spec.ball_diameter_mm as f32 / 2.0;
    rec.log_static(
        "cell/spheres",
        &Points3D::new(e.cell.spheres_w.iter().map(p3))
            .with_radii([r_ball])
            .with_labels((1..=e.cell.spheres_w.len()).map(|k| format!("sphere {k}")))
            .with_colors(e.cell.spheres_w.iter().enumerate().map(|(k, _)| {
                let c = SPHERE_COLOURS[k % SPHERE_COLOURS.len()];
                Color::from_rgb(c[0], c[1], c[2])
            })),
    )?;
    let solids = cell_solids(&e.cell, &base_from_world, &-e.robot.truth.data().gravity_base.normalize());
    let risers: Vec<_> = solids
        .iter()
        .filter_map(|s| match s {
            Solid::Capsule { a, b, radius, .. } => {
                Some(((world_from_base_true * Point3::from(*a)).coords, (world_from_base_true * Point3::from(*b)).coords, *radius))
            }
            _ => None,
        })
        .collect();
    rec.log_static("cell/solids/risers", &capsules(&risers).with_colors([Color::from_rgb(150, 150, 150)]))?;
    let boxes: Vec<(&str, Vector3<f64>, Isometry3<f64>)> = solids
        .iter()
        .filter_map(|s| match s {
            Solid::Cuboid { name, half, pose } => Some((*name, *half, world_from_base_true * pose)),
            _ => None,
        })
        .collect();
    rec.log_static(
        "cell/solids/boxes",
        &Boxes3D::from_centers_and_half_sizes(boxes.iter().map(|(_, _, p)| p3(&p.translation.vector)), boxes.iter().map(|(_, h, _)| p3(h)))
            .with_quaternions(boxes.iter().map(|(_, _, p)| quat(&p.rotation)))
            .with_labels(boxes.iter().map(|(n, _, _)| n.to_string()))
            .with_colors(boxes.iter().map(|(n, _, _)| {
                if *n == "table" { Color::from_unmultiplied_rgba(120, 100, 80, 60) } else { Color::from_rgb(170, 170, 180) }
            })),
    )?;
    rec.log_static(
        "cell/tracker",
        &Points3D::new([p3(&e.tracker.position_w)])
            .with_radii([40.0f32])
            .with_labels(["laser tracker"])
            .with_colors([Color::from_rgb(240, 200, 0)]),
    )?;
    for (path, frame) in [("cell/frames/world", Isometry3::identity()), ("cell/frames/base", world_from_base_true)] {
        log_axes(rec, path, &frame, 150.0)?;
    }

    // The pool: TCP targets coloured by sphere, the robot per configuration, the centring readings.
    let nominal = &e.campaign.nominal;
    let links = &e.links;
    let tool = e.trical.capsules(&nominal.data().flange_tcp_mm);
    let mut st = KinState::default();
    let pool = &e.campaign.pool;
    let pool_tcp: Vec<[f32; 3]> = pool.iter().map(|p| p3(&e.cell.spheres_w[p.sphere])).collect();
    rec.log_static(
        "pool/tcp",
        &Points3D::new(pool_tcp).with_radii([2.0f32]).with_colors(pool.iter().map(|p| {
            let c = SPHERE_COLOURS[p.sphere % SPHERE_COLOURS.len()];
            Color::from_rgb(c[0], c[1], c[2])
        })),
    )?;
    for name in ["x", "y", "z"] {
        rec.log_static(format!("pool/centring/{name}"), &SeriesLines::new().with_names([format!("indicator {name}, mm")]))?;
    }
    let mut reading = 0i64;
    for (k, p) in pool.iter().enumerate() {
        rec.set_time_sequence("pool_configuration", k as i64);
        let c = SPHERE_COLOURS[p.sphere % SPHERE_COLOURS.len()];
        rec.log(
            "pool/robot",
            &capsules(&robot_capsules(truth, &world_from_base_true, &mut st, &p.q, links, &tool))
                .with_colors([Color::from_rgb(c[0], c[1], c[2])]),
        )?;
        for r in &p.readings {
            rec.set_time_sequence("centring_reading", reading);
            reading += 1;
            for (i, name) in ["x", "y", "z"].iter().enumerate() {
                rec.log(format!("pool/centring/{name}"), &Scalars::new([r[i]]))?;
            }
        }
    }
    rec.reset_time();

    // Validation: the robot per pose, the errors before and after calibration.
    let validation = &e.campaign.validation;
    for (k, v) in validation.iter().enumerate() {
        rec.set_time_sequence("validation_pose", k as i64);
        rec.log(
            "validation/robot",
            &capsules(&robot_capsules(truth, &world_from_base_true, &mut st, &v.q, links, &tool))
                .with_colors([Color::from_rgb(120, 120, 200)]),
        )?;
    }
    rec.reset_time();
    let points: Vec<[f32; 3]> = validation.iter().map(|v| p3(&v.measured_w)).collect();
    let emax = results.before_errors.iter().copied().fold(0.0, f64::max).max(1e-9);
    rec.log_static(
        "validation/before",
        &Points3D::new(points.clone())
            .with_radii([5.0f32])
            .with_colors(results.before_errors.iter().map(|x| heat(x / emax)))
            .with_labels(results.before_errors.iter().map(|x| format!("{x:.3} mm before"))),
    )?;
    if let Some(model) = representative.and_then(|i| identified(results, before, i)) {
        let predicted: Vec<Vector3<f64>> = validation.iter().map(|v| forward(&model, &mut st, &v.q)).collect();
        let errors: Vec<Vector3<f64>> = validation.iter().zip(&predicted).map(|(v, p)| v.measured_w - p).collect();
        let amax = errors.iter().map(|x| x.norm()).fold(0.0, f64::max).max(1e-9);
        rec.log_static(
            "validation/after",
            &Points3D::new(points.clone())
                .with_radii([5.0f32])
                .with_colors(errors.iter().map(|x| heat(x.norm() / amax)))
                .with_labels(errors.iter().map(|x| format!("{:.3} mm after", x.norm()))),
        )?;
        rec.log_static(
            "validation/error_vectors",
            &Arrows3D::from_vectors(errors.iter().map(|x| p3(&(x * ERROR_MAGNIFICATION))))
                .with_origins(points)
                .with_colors(errors.iter().map(|x| heat(x.norm() / amax))),
        )?;
    }

    // The study, per task.
    rec.log_static("study/validation_mean_mm", &SeriesLines::new().with_names(["validation mean error, mm"]))?;
    rec.log_static("study/validation_max_mm", &SeriesLines::new().with_names(["validation max error, mm"]))?;
    rec.log_static("study/o1", &SeriesLines::new().with_names(["O1"]))?;
    for t in &results.tasks {
        rec.set_time_sequence("task", t.task.index as i64);
        rec.set_time_sequence("set_size", t.task.set_size as i64);
        rec.set_time_sequence("repetition", t.task.repetition as i64);
        rec.log("study/validation_mean_mm", &Scalars::new([t.validation.mean]))?;
        rec.log("study/validation_max_mm", &Scalars::new([t.validation.max]))?;
        rec.log("study/o1", &Scalars::new([t.id.observability.o1]))?;
    }
    rec.reset_time();
    Ok(())
}

/// Writes the recording of an SPMS study to `path`. Entity paths (mm, robot base frame):
/// - `cell/frames/base`, `cell/heads/<k>/{beams,frame}`: static, one head per station;
/// - `pool/sphere` (static, true sphere centres coloured by station), `pool/robot` (the arm as a
///   line through its joint frames and the sphere) and `pool/measuring_error_um` on the
///   `pool_configuration` timeline;
/// - `iso9283/{cube,before,after}`: the cube, P1-P5 coloured and labelled by AP before and after
///   calibration (random set of the table size whose mean AP is the median);
/// - `study/<selection>/{ap_mean_mm,ap_max_mm,o1}` on the `task`, `set_size` and `repetition` timelines.
pub fn write_spms(path: &Path, name: &str, spec: &crate::spms::study::SpmsSpec, r: &crate::spms::study::SpmsResults) -> Result<(), String> {
    let rec = rerun::RecordingStreamBuilder::new("calsim").recording_name(name).save(path).map_err(|e| e.to_string())?;
    log_spms(&rec, spec, r).map_err(|e| e.to_string())?;
    let bp = blueprint(
        &["/cell/**", "/pool/sphere", "/pool/robot", "/iso9283/**"],
        ("pool: SPMS measuring error", "/pool/measuring_error_um"),
        "study: AP after calibration and O1 per task (timeline `task`)",
    );
    bp.send(&rec, BlueprintActivation { make_active: true, make_default: true }).map_err(|e| e.to_string())?;
    rec.flush_blocking().map_err(|e| e.to_string())?;
    Ok(())
}

///
/// Long by design: one block per entity of the SPMS recording, in the order of its blueprint.
fn log_spms(rec: &RecordingStream, spec: &crate::spms::study::SpmsSpec, r: &crate::spms::study::SpmsResults) -> Rr {
    use rerun::LineStrips3D;
    rec.log_static("/", &rerun::ViewCoordinates::RIGHT_HAND_Z_UP())?;
    log_axes(rec, "cell/frames/base", &Isometry3::identity(), 300.0)?;
    let cell = &r.cell;
    for (k, s) in cell.stations.iter().enumerate() {
        let strips: Vec<Vec<[f32; 3]>> = r
            .head
            .spms
            .sensors
            .iter()
            .map(|sn| {
                vec![
                    p3(&(s.base_from_head * Point3::from(sn.beam.p)).coords),
                    p3(&(s.base_from_head * Point3::from(sn.beam.point(130.0))).coords),
                ]
            })
            .collect();
        rec.log_static(
            format!("cell/heads/{k}/beams"),
            &LineStrips3D::new(strips).with_colors([Color::from_rgb(220, 30, 30)]).with_radii([1.0f32]),
        )?;
        log_axes(rec, &format!("cell/heads/{k}/frame"), &s.base_from_head, 80.0)?;
    }
    let truth = cell.robot.truth.edited(|d| d.world_from_base = crate::robot::XyzZyx::default()).expect("valid");
    let base_from_s = world_from_base(&cell.robot.truth).inverse();
    let colour = |k: usize| {
        let c = SPHERE_COLOURS[k % SPHERE_COLOURS.len()];
        Color::from_rgb(c[0], c[1], c[2])
    };
    rec.log_static(
        "pool/sphere",
        &Points3D::new(cell.pool.iter().map(|p| p3(&(base_from_s * Point3::from(p.true_world_mm)).coords)))
            .with_radii([spec.head.sphere_diameter_mm as f32 / 2.0])
            .with_colors(cell.pool.iter().map(|p| colour(p.station))),
    )?;
    rec.log_static("pool/measuring_error_um", &SeriesLines::new().with_names(["|SPMS - truth|, um"]))?;
    let mut st = KinState::default();
    for (k, p) in cell.pool.iter().enumerate() {
        rec.set_time_sequence("pool_configuration", k as i64);
        let tcp = forward(&truth, &mut st, &p.q);
        let mut line: Vec<[f32; 3]> = (0..=JOINTS).map(|i| p3(&st.base_from_frame(i).translation.vector)).collect();
        line.push(p3(&tcp));
        rec.log("pool/robot", &LineStrips3D::new([line]).with_radii([12.0f32]).with_colors([colour(p.station)]))?;
        rec.log("pool/measuring_error_um", &Scalars::new([(p.measured_world_mm - p.true_world_mm).norm() * 1e3]))?;
    }
    rec.reset_time();

    let iso = &spec.iso9283;
    let points = crate::spms::calibration::iso_points(iso);
    let h = iso.cube_mm as f32 / 2.0;
    rec.log_static(
        "iso9283/cube",
        &Boxes3D::from_centers_and_half_sizes([p3(&Vector3::from(iso.cube_centre_base_mm))], [[h, h, h]])
            .with_colors([Color::from_unmultiplied_rgba(120, 120, 120, 40)]),
    )?;
    let amax = r.before.ap_mm.iter().copied().fold(0.0, f64::max).max(1e-9);
    // Before: large points with their labels; after: smaller points inside them, labels on hover.
    let log_ap = |path: &str, ap: &[f64; 5], label: &str| {
        let before = label == "before";
        rec.log_static(
            path,
            &Points3D::new(points.iter().map(p3))
                .with_radii([if before { 14.0f32 } else { 8.0 }])
                .with_colors(ap.iter().map(|a| heat(a / amax)))
                .with_labels(ap.iter().enumerate().map(|(k, a)| format!("P{} AP {a:.3} mm {label}", k + 1)))
                .with_show_labels(before),
        )
    };
    log_ap("iso9283/before", &r.before.ap_mm, "before")?;
    let n = spec.study.table_set_size as usize;
    let mut at_n: Vec<_> =
        r.tasks.iter().filter(|t| t.task.selection == crate::study::Selection::Random && t.task.set_size == n && t.iso.is_some()).collect();
    at_n.sort_by(|a, b| {
        a.iso.as_ref().map(|i| i.ap_summary().1).unwrap_or(0.0).total_cmp(&b.iso.as_ref().map(|i| i.ap_summary().1).unwrap_or(0.0))
    });
    if let Some(t) = at_n.get(at_n.len().saturating_sub(1) / 2)
        && let Some(i) = &t.iso
    {
        log_ap("iso9283/after", &i.ap_mm, &format!("after (task {})", t.task.index))?;
    }

    for sel in ["random", "detmax"] {
        rec.log_static(format!("study/{sel}/ap_mean_mm"), &SeriesLines::new().with_names([format!("{sel}: mean AP after, mm")]))?;
        rec.log_static(format!("study/{sel}/ap_max_mm"), &SeriesLines::new().with_names([format!("{sel}: max AP after, mm")]))?;
        rec.log_static(format!("study/{sel}/o1"), &SeriesLines::new().with_names([format!("{sel}: O1")]))?;
    }
    for t in &r.tasks {
        rec.set_time_sequence("task", t.task.index as i64);
        rec.set_time_sequence("set_size", t.task.set_size as i64);
        rec.set_time_sequence("repetition", t.task.repetition as i64);
        let sel = t.task.selection.label();
        if let Some(i) = &t.iso {
            let (mx, mean, _) = i.ap_summary();
            rec.log(format!("study/{sel}/ap_mean_mm"), &Scalars::new([mean]))?;
            rec.log(format!("study/{sel}/ap_max_mm"), &Scalars::new([mx]))?;
        }
        rec.log(format!("study/{sel}/o1"), &Scalars::new([t.id.observability.o1]))?;
    }
    rec.reset_time();
    Ok(())
}
