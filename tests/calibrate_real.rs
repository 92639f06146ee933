//! `calsim calibrate` on data as real measurement campaigns give them: sessions whose targets lie
//! on a line (a linear path), held out or fitted.

mod common;

use std::path::Path;

use calsim::calibrate::simulate::{LineSession, SimulationSpec, to_csv};
use calsim::calibrate::validation::Split;
use calsim::calibrate::{Calibration, Options, ParamStatus, measurements, run};
use calsim::robot::file::RobotFile;
use calsim::robot::{ParamSet, RobotModel, UnmodelledSpec};
use nalgebra::Vector3;

/// The IRB 120's robot file with a FANUC-style coupling of joint 3.
fn coupled_irb120() -> RobotFile {
    let text = std::fs::read_to_string(common::repo().join("robots/irb120.toml")).unwrap();
    let text = format!("{text}\n[[coupling]]\njoint = 3\ncontroller = [0.0, -1.0, 1.0, 0.0, 0.0, 0.0]\n");
    RobotFile::from_text(Path::new("irb120_coupled.toml"), &text).unwrap()
}

/// The joint-offset parameters (one model).
fn offsets_only() -> ParamSet {
    ParamSet::from_names(&["theta_offs2", "theta_offs3", "theta_offs4", "theta_offs5", "theta_offs6"]).unwrap()
}

/// The nominal arm with the robot file's `[truth]` values of `set`'s parameters.
fn truth_on(robot: &RobotFile, set: &ParamSet) -> RobotModel {
    let deviated: Vec<(calsim::robot::ParamId, f64)> = robot.truth.iter().filter(|(id, _)| set.position(*id).is_some()).copied().collect();
    let values: Vec<f64> = deviated.iter().map(|(_, v)| *v).collect();
    ParamSet::new(deviated.iter().map(|(id, _)| *id).collect()).unwrap().unpack(&robot.nominal, &values).unwrap()
}

/// The shipped example's three sessions (40 poses, two SMRs) and a session `L` in which SMR1 is
/// carried 30 times 8 mm along the base's y axis at a fixed flange orientation (232 mm: a line),
/// its tracker placed elsewhere; the robot inside the model, `noise_mm` per coordinate.
fn with_line(robot: &RobotFile, noise_mm: f64) -> SimulationSpec {
    let example = calsim::calibrate::simulate::example_spec(robot).unwrap();
    let deg = |v: [f64; 6]| v.map(f64::to_radians);
    SimulationSpec {
        truth: truth_on(robot, &offsets_only()),
        unmodelled: UnmodelledSpec::default(),
        repeatability_mm: 0.0,
        coupling: robot.coupling.clone(),
        noise_mm,
        outliers: vec![],
        seed: 7,
        comments: vec!["joints = controller".into()],
        lines: vec![LineSession {
            label: "L".into(),
            frame: calsim::robot::XyzZyx { x: 1500.0, y: 800.0, z: -380.0, alpha: 2.4, beta: 0.004, gamma: -0.003 },
            target: 0,
            start: deg([-10.0, 10.0, 10.0, 0.0, 40.0, 0.0]),
            step_mm: Vector3::new(0.0, 8.0, 0.0),
            turn_rad: Vector3::zeros(),
            poses: 30,
        }],
        ..example
    }
}

fn options(split: Split) -> Options {
    Options { params: Some(offsets_only()), split, outliers: calsim::calibrate::OutlierMode::Off, plots: false, ..Options::default() }
}

fn held_out_rms(c: &Calibration) -> f64 {
    c.chosen().held_out.as_ref().expect("held-out errors").measured.rms
}

/// A session whose only target runs along a line, held out whole: calibrate takes the file, the
/// line's base is registered on its own points with the rotation about the line kept at the
/// registration (one base column still: the rotation about the base's y axis, the line's
/// direction), and its held-out errors are the noise's (the robot is inside the model: 12 um per
/// coordinate, about 21 um RMS per point).
#[test]
fn a_line_session_held_out_is_calibrated_with_its_rotation_about_the_line_kept() {
    let robot = coupled_irb120();
    let spec = with_line(&robot, 0.012);
    let m = measurements::parse(Path::new("line.csv"), &to_csv(&spec).unwrap(), &robot).unwrap();
    assert_eq!(m.sessions, ["A", "B", "C", "L"]);
    assert_eq!(m.poses.iter().filter(|p| p.session == 3).count(), 30, "the whole line is within reach");
    let c = run(&robot, &m, &options(Split::Session("L".into()))).unwrap_or_else(|e| panic!("{e}"));
    let still = &c.chosen().layout.still;
    assert_eq!(still[..3], [[false; 6]; 3], "the three volume sessions fix their frames");
    assert_eq!(still[3], [false, false, false, false, true, false], "the line's base keeps beta (about y, the line) at the registration");
    let rms = held_out_rms(&c);
    assert!(rms > 0.005 && rms < 0.04, "the line's held-out RMS is the noise's: {rms} mm");
    assert_eq!(
        c.estimates.iter().filter(|e| e.status == ParamStatus::Identified).count(),
        4,
        "theta_offs2..5 (the tools absorb theta_offs6)"
    );
    for e in c.estimates.iter().filter(|e| e.status == ParamStatus::Identified) {
        let truth = e.id.get(spec.truth.data());
        assert!((e.value - truth).abs() < 5.0 * e.std + 1e-9, "{}: {} against {truth} (std {})", e.id.name(), e.value, e.std);
    }
}

/// The same line fitted with the other sessions (a random fifth of every session's poses held
/// out): its rotation about the line is kept, every other unknown fitted, and the noise-free
/// data give back the injected joint offsets exactly (1e-9 rad) and the line's measured points
/// to 1e-6 mm.
#[test]
fn a_line_session_in_the_fit_keeps_only_its_rotation_about_the_line() {
    let robot = coupled_irb120();
    let spec = with_line(&robot, 0.0);
    let m = measurements::parse(Path::new("line.csv"), &to_csv(&spec).unwrap(), &robot).unwrap();
    let c = run(&robot, &m, &options(Split::Poses { fraction: 0.2 })).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(c.chosen().layout.still[3], [false, false, false, false, true, false]);
    assert_eq!(
        c.estimates.iter().filter(|e| e.status == ParamStatus::Identified).count(),
        4,
        "theta_offs2..5 (the tools absorb theta_offs6)"
    );
    for e in c.estimates.iter().filter(|e| e.status == ParamStatus::Identified) {
        let truth = e.id.get(spec.truth.data());
        assert!((e.value - truth).abs() < 1e-9, "{}: {} against {truth}", e.id.name(), e.value);
    }
    let worst = c.chosen().fit.errors_mm.iter().copied().fold(0.0_f64, f64::max);
    assert!(worst < 1e-6, "every point fitted: {worst} mm");
}

/// The imported-arm example of docs/calibrate.md at 500 poses per session (3,030 rows in place of
/// 102,030), end to end through the binary: `calsim simulate-measurements` writes the file of
/// docs/calibrate/imported_example.toml (the massless LR Mate 200iC with its J2/J3 coupling, a
/// 2 kg plate, the probe re-mounted in session C, session L a line), and `calsim calibrate` with
/// the example's flags (the payload, a tool per session, session L held out) calibrates it: the
/// compliance is fitted through the payload, the re-mounted probe gets its own tools, and the
/// held-out line's errors are within the noise (12 um per coordinate). The file is not replaced
/// by a second run, and a bad simulation file is one line naming the key, exit 2.
#[test]
fn the_imported_arm_example_runs_end_to_end_from_the_binary() {
    let dir = common::scratch("imported-example");
    let text = std::fs::read_to_string(common::repo().join("docs/calibrate/imported_example.toml")).unwrap();
    let robot = common::repo().join("robots/examples/lrmate200ic_coupled.toml");
    let small = text
        .replace("poses_per_session = 17000", "poses_per_session = 500")
        .replace("\"../../robots/examples/lrmate200ic_coupled.toml\"", &format!("{:?}", robot.display().to_string()));
    assert_ne!(small, text);
    let spec = dir.path().join("imported_example.toml");
    std::fs::write(&spec, &small).unwrap();
    let data = dir.path().join("data");
    let o = common::calsim().arg("simulate-measurements").arg(&spec).arg("--out").arg(&data).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let csv = data.join("imported_example.csv");
    let rows = std::fs::read_to_string(&csv).unwrap().lines().filter(|l| !l.starts_with('#')).count() - 1;
    assert_eq!(rows, 3 * 500 * 2 + 30, "three sessions of 500 poses at 2 SMRs and a line of 30");
    let again = common::calsim().arg("simulate-measurements").arg(&spec).arg("--out").arg(&data).output().unwrap();
    assert_eq!(again.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&again.stderr).contains("the file exists"), "{}", String::from_utf8_lossy(&again.stderr));
    let o = common::calsim()
        .args(["calibrate", "robots/examples/lrmate200ic_coupled.toml"])
        .arg(&csv)
        .args(["--payload-kg", "2", "--payload-com-mm", "0,0,50", "--tool-per-session", "--hold-out-session", "L", "--no-plots", "--out"])
        .arg(dir.path().join("out"))
        .output()
        .unwrap();
    let (stdout, stderr) = (String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    assert!(o.status.success(), "{stdout}\n{stderr}");
    let summary = std::fs::read_to_string(dir.path().join("out/imported_example.calibration/summary.md")).unwrap();
    for t in ["SMR1@A", "SMR2@C", "SMR1@L"] {
        assert!(summary.contains(t), "a tool per session: {t}\n{summary}");
    }
    let m = measurements::read(&csv, &RobotFile::load(&robot).unwrap()).unwrap();
    let robot_file = RobotFile::load(&robot).unwrap();
    let opts = Options {
        split: Split::Session("L".into()),
        tool_per_session: true,
        payload: Some(calsim::calibrate::Payload { mass_kg: 2.0, com_mm: [0.0, 0.0, 50.0] }),
        plots: false,
        ..Options::default()
    };
    let c = run(&robot_file, &m, &opts).unwrap();
    assert_eq!(c.chosen().layout.still[3], [false, false, false, false, true, false], "the line (along y) keeps beta");
    let rms = held_out_rms(&c);
    assert!(rms < 0.04, "the line's held-out RMS: {rms} mm");
    let compliance: Vec<_> = c.estimates.iter().filter(|e| e.id.name() == "c2" || e.id.name() == "c3").collect();
    assert!(compliance.iter().all(|e| e.status == ParamStatus::Identified), "{compliance:?}");
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, small.replace("noise_mm = 0.012", "noise_mm = nan")).unwrap();
    let o = common::calsim().arg("simulate-measurements").arg(&bad).arg("--out").arg(dir.path().join("bad")).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("bad.toml") && err.contains("noise_mm"), "{err}");
}

/// A six-degree-of-freedom probe's orientation columns are read onto each point (normalised) with
/// their `sigma_deg` uncertainty; an uncertainty without the quaternion, or beyond 180 deg, is one
/// error naming the line and the column.
#[test]
fn orientation_readings_and_their_uncertainty_are_read_onto_each_point() {
    let robot = RobotFile::load(&common::repo().join("robots/irb120.toml")).unwrap();
    let text = std::fs::read_to_string(common::repo().join("docs/calibrate/example_measurements.csv")).unwrap();
    let (half, s) = (std::f64::consts::FRAC_1_SQRT_2, 0.5_f64);
    let with = |extra_header: &str, extra_row: &str| -> String {
        text.lines()
            .map(|l| {
                if l.starts_with('#') {
                    format!("{l}\n")
                } else if l.starts_with("pose,") {
                    format!("{l},{extra_header}\n")
                } else {
                    format!("{l},{extra_row}\n")
                }
            })
            .collect()
    };
    let good = with("quat_w,quat_x,quat_y,quat_z,sigma_deg", &format!("{half},0,0,{},{s}", half + 1e-5));
    let m = measurements::parse(Path::new("probe.csv"), &good, &robot).unwrap();
    let q = m.points[0].orientation.expect("an orientation");
    assert!((q.angle() - std::f64::consts::FRAC_PI_2).abs() < 1e-4 && (q.axis().unwrap().z - 1.0).abs() < 1e-12, "{q:?}");
    assert!((q.into_inner().norm() - 1.0).abs() < 1e-15, "normalised");
    assert_eq!(m.points[0].sigma_rad, Some(s.to_radians()));
    let alone = with("sigma_deg", "0.5");
    let e = measurements::parse(Path::new("probe.csv"), &alone, &robot).unwrap_err().to_string();
    assert!(e.contains("sigma_deg") && e.contains("without the quat_w"), "{e}");
    let wide = with("quat_w,quat_x,quat_y,quat_z,sigma_deg", "1,0,0,0,200");
    let e = measurements::parse(Path::new("probe.csv"), &wide, &robot).unwrap_err().to_string();
    assert!(e.contains("line ") && e.contains("sigma_deg") && e.contains("180 deg"), "{e}");
}
