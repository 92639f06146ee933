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
    let m = measurements::parse(Path::new("line.csv"), &to_csv(&spec), &robot).unwrap();
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
    let m = measurements::parse(Path::new("line.csv"), &to_csv(&spec), &robot).unwrap();
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
