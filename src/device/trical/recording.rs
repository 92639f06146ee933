//! The Rerun recording of a TriCal study (`study.rrd`): the cell, the robot at every pool and validation
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

use nalgebra::{Isometry3, Point3, Vector3};
use rerun::{Arrows3D, Boxes3D, Color, Points3D, RecordingStream, Scalars, SeriesLines};

use super::experiment::Experiment;
use super::study::StudyResults;
use crate::cell::collision::{CapsuleSpec, LinkCapsules};
use crate::cell::solids::{Solid, cell_solids};
use crate::io::record::{RecordError, Rr, SPHERE_COLOURS, capsules, heat, log_axes, p3, quat};
use crate::robot::{JOINTS, KinState, RobotModel, forward, world_from_base};

/// Factor by which the after-calibration error vectors are drawn longer than they are.
pub const ERROR_MAGNIFICATION: f64 = 200.0;

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
/// the after-calibration views (see [`crate::device::trical::figures::representative`]).
pub fn write(
    path: &Path,
    name: &str,
    experiment: &Experiment,
    before: &RobotModel,
    results: &StudyResults,
    representative: Option<usize>,
) -> Result<(), RecordError> {
    crate::io::record::save(
        path,
        name,
        |rec| log_all(rec, experiment, before, results, representative),
        &["/cell/**", "/pool/tcp", "/pool/robot", "/validation/**"],
        ("TriCal centring: indicator readings", "/pool/centring"),
        "study: validation error and O1 per task (timeline `task`)",
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
