//! The Rerun recording of an SPMS study.

use std::path::Path;

use nalgebra::{Isometry3, Point3, Vector3};
use rerun::{Boxes3D, Color, Points3D, RecordingStream, Scalars, SeriesLines};

use crate::io::record::{RecordError, Rr, SPHERE_COLOURS, heat, log_axes, p3};
use crate::robot::{JOINTS, KinState, forward, world_from_base};

/// Writes the recording of an SPMS study to `path`. Entity paths (mm, robot base frame):
/// - `cell/frames/base`, `cell/heads/<k>/{beams,frame}`: static, one head per station;
/// - `pool/sphere` (static, true sphere centres coloured by station), `pool/robot` (the arm as a
///   line through its joint frames and the sphere) and `pool/measuring_error_um` on the
///   `pool_configuration` timeline;
/// - `iso9283/{cube,before,after}`: the cube, P1-P5 coloured and labelled by AP before and after
///   calibration (random set of the table size whose mean AP is the median);
/// - `study/<selection>/{ap_mean_mm,ap_max_mm,o1}` on the `task`, `set_size` and `repetition` timelines.
pub fn write(path: &Path, name: &str, spec: &super::study::SpmsSpec, r: &super::study::SpmsResults) -> Result<(), RecordError> {
    crate::io::record::save(
        path,
        name,
        |rec| log_spms(rec, spec, r),
        &["/cell/**", "/pool/sphere", "/pool/robot", "/iso9283/**"],
        ("pool: SPMS measuring error", "/pool/measuring_error_um"),
        "study: AP after calibration and O1 per task (timeline `task`)",
    )
}

///
/// Long by design: one block per entity of the SPMS recording, in the order of its blueprint.
fn log_spms(rec: &RecordingStream, spec: &super::study::SpmsSpec, r: &super::study::SpmsResults) -> Rr {
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
    let points = crate::device::spms::calibration::iso_points(iso);
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
