//! `calsim calibrate` with six-degree-of-freedom probes: the orientation columns in the fit (round
//! trips through the measurement layout with orientation readings), line sessions registered by
//! their readings, the fitted standard deviations against the scatter over seeds, and bad readings.

mod common;

use std::path::Path;

use calsim::calibrate::simulate::{OrientationSim, SimulationSpec, to_csv, to_csv_with};
use calsim::calibrate::{Calibration, Options, ParamStatus, default_params, measurements, run};
use calsim::robot::file::RobotFile;
use calsim::robot::{ParamId, ParamSet, RobotModel, UnmodelledSpec, XyzZyx};
use nalgebra::{Rotation3, Vector3};

fn irb120() -> RobotFile {
    RobotFile::load(&common::repo().join("robots/irb120.toml")).unwrap()
}

/// The default parameters less d6 and theta_offs6 (a target's position and its probe's rotation on
/// the flange absorb them).
fn identifiable() -> ParamSet {
    default_params().fixed(ParamId::parse("d6").unwrap()).fixed(ParamId::parse("theta_offs6").unwrap())
}

/// The nominal arm with Table 7's values of `set`'s parameters (the robot file's `[truth]`).
fn truth_on(robot: &RobotFile, set: &ParamSet) -> RobotModel {
    let deviated: Vec<(ParamId, f64)> = robot.truth.iter().filter(|(id, _)| set.position(*id).is_some()).copied().collect();
    let values: Vec<f64> = deviated.iter().map(|(_, v)| *v).collect();
    ParamSet::new(deviated.iter().map(|(id, _)| *id).collect()).unwrap().unpack(&robot.nominal, &values).unwrap()
}

/// The shipped example's sessions and targets (3 sessions x 40 poses x 2 targets), the robot
/// `truth` inside the model, `noise_mm` per coordinate, the poses and noise of `seed`.
fn spec(truth: RobotModel, robot: &RobotFile, noise_mm: f64, seed: u64) -> SimulationSpec {
    SimulationSpec {
        truth,
        unmodelled: UnmodelledSpec::default(),
        repeatability_mm: 0.0,
        noise_mm,
        outliers: vec![],
        seed,
        comments: vec!["joints = controller".into()],
        ..calsim::calibrate::simulate::example_spec(robot).unwrap()
    }
}

/// The probes' rotations on the flange: (10, -20, 35) deg and (-5, 15, 100) deg as rotation vectors.
fn probes(noise_mdeg: f64) -> OrientationSim {
    OrientationSim {
        probe_rotations: vec![Vector3::new(10.0, -20.0, 35.0).map(f64::to_radians), Vector3::new(-5.0, 15.0, 100.0).map(f64::to_radians)],
        noise_rad: (noise_mdeg * 1e-3).to_radians(),
    }
}

fn parse(text: &str, robot: &RobotFile) -> measurements::Measurements {
    measurements::parse(Path::new("probe.csv"), text, robot).unwrap()
}

fn options() -> Options {
    Options { plots: false, params: Some(identifiable()), ..Options::default() }
}

/// The angle between each target's fitted probe rotation and its truth, deg.
fn probe_errors_deg(c: &Calibration, o: &OrientationSim) -> Vec<f64> {
    c.probe_rotations
        .iter()
        .zip(&o.probe_rotations)
        .map(|(r, t)| {
            let r = r.as_ref().expect("a probe rotation").flange_from_probe;
            calsim::calibrate::problem::log(&(r * Rotation3::new(*t).inverse())).norm().to_degrees()
        })
        .collect()
}

/// Noise-free readings and positions of a robot with Table 7's values of the identifiable
/// parameters (23 of them), two probes turned on the flange: every identified parameter within
/// 1e-9 of its truth (internal units), each probe's rotation within 1e-7 deg, the tools within
/// 1e-6 mm, the rotation errors of the fit and at the held-out points below 1e-6 mdeg.
#[test]
fn a_noise_free_round_trip_with_orientation_recovers_the_robot_and_the_probe_rotations() {
    let robot = irb120();
    let truth = truth_on(&robot, &identifiable());
    let s = spec(truth.clone(), &robot, 0.0, 7);
    let o = probes(0.0);
    let m = parse(&to_csv_with(&s, Some(&o)).unwrap(), &robot);
    assert!(m.orientation_columns && m.points.iter().all(|p| p.orientation.is_some()));
    let c = run(&robot, &m, &options()).unwrap();
    for e in c.estimates.iter().filter(|e| identifiable().position(e.id).is_some()) {
        assert_eq!(e.status, ParamStatus::Identified, "{}", e.id.name());
        let t = e.id.get(truth.data());
        assert!((e.value - t).abs() < 1e-9, "{}: {} against {t}", e.id.name(), e.value);
    }
    for (k, err) in probe_errors_deg(&c, &o).iter().enumerate() {
        assert!(*err < 1e-7, "probe {k}: {err:e} deg off");
    }
    for (t, (_, tool)) in c.tools.iter().zip(&s.targets) {
        assert!((t.flange_mm - tool).norm() < 1e-6, "{}", t.target);
    }
    let fit = &c.chosen().fit.rotation_base_mdeg;
    assert_eq!(fit.len(), m.points.len());
    assert!(fit.iter().all(|e| e.expect("a reading").norm() < 1e-6));
    let held = c.chosen().held_out.as_ref().unwrap().rotation.unwrap();
    assert!(held.max < 1e-6, "held-out rotation max {:e} mdeg", held.max);
}

/// A session of one target with readings (the first target alone, 3 sessions x 40 poses): its
/// probe's rotation on the flange comes out within 1e-7 deg of the truth, with a standard
/// deviation; the file without the readings has none.
#[test]
fn a_single_target_session_with_orientation_gets_its_probe_rotation() {
    let robot = irb120();
    let truth = truth_on(&robot, &identifiable());
    let mut s = spec(truth, &robot, 0.0, 11);
    s.targets.truncate(1);
    let mut o = probes(0.0);
    o.probe_rotations.truncate(1);
    let c = run(&robot, &parse(&to_csv_with(&s, Some(&o)).unwrap(), &robot), &options()).unwrap();
    let err = probe_errors_deg(&c, &o)[0];
    assert!(err < 1e-7, "{err:e} deg off");
    let std = c.probe_rotations[0].as_ref().unwrap().std_mdeg;
    assert!(std.iter().all(|v| v.is_finite()), "{std:?}");
    let without = run(&robot, &parse(&to_csv(&s).unwrap(), &robot), &options()).unwrap();
    assert_eq!(without.probe_rotations, vec![None]);
}

/// A session measured along a straight line (one target, the flange turning 1 deg per pose about
/// the base's x axis) beside two whole sessions: with orientation readings its base is registered
/// whole (all six numbers free, within 1e-6 mm and 1e-9 rad of the truth, noise-free); from its
/// positions alone the turn about the line is kept at the registration (its standard deviation 0).
#[test]
fn a_line_session_with_orientation_gets_its_full_registration() {
    let robot = irb120();
    let truth = truth_on(&robot, &identifiable());
    let mut s = spec(truth, &robot, 0.0, 5);
    s.sessions.truncate(2);
    s.lines = vec![calsim::calibrate::simulate::LineSession {
        label: "L".into(),
        frame: XyzZyx::from_mm_deg([1500.0, 800.0, -380.0, 140.0, 0.2, -0.2]),
        target: 0,
        start: [-10.0, 10.0, -10.0, 0.0, -50.0, 0.0].map(f64::to_radians),
        step_mm: Vector3::new(0.0, 8.0, 0.0),
        turn_rad: Vector3::new(1.0, 0.0, 0.0).map(f64::to_radians),
        poses: 20,
    }];
    let truth_frame = s.lines[0].frame.isometry();
    let o = probes(0.0);
    let opts = Options { split: calsim::calibrate::validation::Split::Poses { fraction: 0.2 }, ..options() };
    let c = run(&robot, &parse(&to_csv_with(&s, Some(&o)).unwrap(), &robot), &opts).unwrap();
    let l = c.bases.iter().find(|b| b.session == "L").unwrap();
    let delta = truth_frame.inverse() * l.session_from_base.isometry();
    assert!(delta.translation.vector.norm() < 1e-6, "{:e} mm", delta.translation.vector.norm());
    assert!(delta.rotation.angle() < 1e-9, "{:e} rad", delta.rotation.angle());
    assert!(l.std.iter().all(|v| *v > 0.0), "every number free: {:?}", l.std);
    let positions = run(&robot, &parse(&to_csv(&s).unwrap(), &robot), &opts).unwrap();
    let l = positions.bases.iter().find(|b| b.session == "L").unwrap();
    assert_eq!(l.std[3..].iter().filter(|v| **v == 0.0).count(), 1, "one turn kept at the registration: {:?}", l.std);
}

/// With 12 um noise per coordinate and 10 mdeg per axis on the readings (the options saying so),
/// the fitted standard deviations agree with the scatter over seeds: over 6 seeds, the identified
/// robot parameters' and the probes' rotation errors over their own fitted standard deviation
/// (166 values of at most 6 x (23 + 6) = 174, correlated within a seed) have an RMS within
/// [0.7, 1.4] (1 when the standard deviations are right; its sampling spread over 6 independent
/// fits is about 0.1).
#[test]
fn the_fitted_std_agrees_with_the_scatter_over_seeds() {
    let robot = irb120();
    let truth = truth_on(&robot, &identifiable());
    let o = probes(10.0);
    let opts =
        Options { position_noise_mm: 0.012, orientation_noise_mdeg: 10.0, outliers: calsim::calibrate::OutlierMode::Off, ..options() };
    let mut z = Vec::new();
    for seed in 0..6 {
        let s = spec(truth.clone(), &robot, 0.012, 100 + seed);
        let c = run(&robot, &parse(&to_csv_with(&s, Some(&o)).unwrap(), &robot), &opts).unwrap();
        for e in c.estimates.iter().filter(|e| e.status == ParamStatus::Identified) {
            z.push((e.value - e.id.get(truth.data())) / e.std);
        }
        for (r, t) in c.probe_rotations.iter().zip(&o.probe_rotations) {
            let r = r.as_ref().unwrap();
            // The error as a small rotation about the flange's axes (the standard deviations' axes).
            let e = calsim::calibrate::problem::log(&(r.flange_from_probe * Rotation3::new(*t).inverse())).map(|v| v.to_degrees() * 1e3);
            z.extend((0..3).map(|k| e[k] / r.std_mdeg[k]));
        }
    }
    let rms = (z.iter().map(|v| v * v).sum::<f64>() / z.len() as f64).sqrt();
    eprintln!("{} normalised errors: RMS {rms:.3}", z.len());
    // Every probe rotation and most of the 23 parameters (a compliance the rule of
    // calibrate::DETERMINED keeps nominal in a seed drops out of that seed).
    assert!(z.len() >= 6 * (20 + 6), "{} normalised errors", z.len());
    assert!((0.7..1.4).contains(&rms), "RMS of error / std {rms:.3}");
}

/// A file without orientation columns and the same file with them: the positions-only run is
/// what it is without (no rotation column in points.parquet, no orientation section); with them,
/// points.parquet carries the rotation errors and summary.md its section.
#[test]
fn orientation_columns_reach_points_parquet_and_the_summary() {
    let robot_path = common::repo().join("robots/irb120.toml");
    let robot = irb120();
    let truth = truth_on(&robot, &identifiable());
    let mut s = spec(truth, &robot, 0.01, 3);
    s.poses_per_session = 12;
    let dir = common::scratch("orientation-report");
    let plain = dir.path().join("plain.csv");
    let probe = dir.path().join("probe.csv");
    std::fs::write(&plain, to_csv(&s).unwrap()).unwrap();
    std::fs::write(&probe, to_csv_with(&s, Some(&probes(5.0))).unwrap()).unwrap();
    let params = "a2,a3,d4,theta_offs2,theta_offs3,theta_offs4";
    for (csv, with) in [(&plain, false), (&probe, true)] {
        let o = common::calsim()
            .args(["calibrate", robot_path.to_str().unwrap(), "--no-plots", "--params", params, "--out"])
            .arg(dir.path().join("out"))
            .arg(csv)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let stem = csv.file_stem().unwrap().to_str().unwrap();
        let report = dir.path().join(format!("out/{stem}.calibration"));
        let summary = std::fs::read_to_string(report.join("summary.md")).unwrap();
        assert_eq!(summary.contains("## Orientation readings"), with, "{summary}");
        let stdout = String::from_utf8_lossy(&o.stdout);
        assert_eq!(stdout.contains("held-out rotation error"), with, "{stdout}");
        let points = {
            use polars::prelude::SerReader;
            polars::prelude::ParquetReader::new(std::fs::File::open(report.join("points.parquet")).unwrap()).finish().unwrap()
        };
        let names: Vec<String> = points.get_column_names().iter().map(|n| n.to_string()).collect();
        for col in ["rotation_residual_x_mdeg", "rotation_error_after_mdeg", "held_out_rotation_error_mdeg"] {
            assert_eq!(names.iter().any(|n| n == col), with, "{col} in {names:?}");
        }
    }
}

/// Readings in another convention (the quaternion written x, y, z, w) are one line naming the file,
/// a line and the column, exit 2; so are those of one target in one session among right ones
/// (naming both), and a reading that is no rotation.
#[test]
fn readings_in_another_convention_are_one_line_exit_2() {
    let robot_path = common::repo().join("robots/irb120.toml");
    let robot = irb120();
    let truth = truth_on(&robot, &identifiable());
    let mut s = spec(truth, &robot, 0.0, 3);
    s.poses_per_session = 12;
    let text = to_csv_with(&s, Some(&probes(0.0))).unwrap();
    // w, x, y, z -> x, y, z, w under the same column names.
    let swapped: String = text
        .lines()
        .map(|l| {
            if l.starts_with('#') || l.starts_with("pose,") {
                return format!("{l}\n");
            }
            let mut f: Vec<&str> = l.split(',').collect();
            let n = f.len();
            f[n - 4..].rotate_left(1);
            format!("{}\n", f.join(","))
        })
        .collect();
    // Only the readings of one target in the last session in the other convention, among right ones.
    let header: Vec<&str> = text.lines().find(|l| l.starts_with("pose,")).unwrap().split(',').collect();
    let (col, tcol) = (header.iter().position(|c| *c == "session").unwrap(), header.iter().position(|c| *c == "target").unwrap());
    let last_row: Vec<&str> = text.lines().filter(|l| !l.starts_with('#') && !l.starts_with("pose,")).last().unwrap().split(',').collect();
    let (last, target) = (last_row[col].to_string(), last_row[tcol].to_string());
    let one_session: String = text
        .lines()
        .map(|l| {
            let mut f: Vec<&str> = l.split(',').collect();
            if !l.starts_with('#') && !l.starts_with("pose,") && f[col] == last && f[tcol] == target {
                let n = f.len();
                f[n - 4..].rotate_left(1);
            }
            format!("{}\n", f.join(","))
        })
        .collect();
    assert_ne!(one_session, text);
    let not_unit: String = text
        .lines()
        .enumerate()
        .map(|(k, l)| if k == 10 { format!("{},0.1\n", l.rsplit_once(',').unwrap().0) } else { format!("{l}\n") })
        .collect();
    let dir = common::scratch("orientation-bad");
    let in_session = format!("of target {target} in session {last}");
    for (name, text, want) in
        [("swapped.csv", &swapped, "quat_w"), ("norm.csv", &not_unit, "quat_w"), ("one_session.csv", &one_session, in_session.as_str())]
    {
        let csv = dir.path().join(name);
        std::fs::write(&csv, text).unwrap();
        let o = common::calsim()
            .args(["calibrate", robot_path.to_str().unwrap(), "--no-plots", "--out"])
            .arg(dir.path().join("out"))
            .arg(&csv)
            .output()
            .unwrap();
        let e = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{name}: {e}");
        assert_eq!(e.trim().lines().count(), 1, "{name}: one line: {e}");
        assert!(e.contains(name) && e.contains("line ") && e.contains(want), "{name}: {e}");
    }
}

/// `text` with the orientation reading of data line `line` (1-based, as the report names lines)
/// turned by `deg` about the measuring frame's x axis.
fn turn_reading(text: &str, line: usize, deg: f64) -> String {
    let turn = nalgebra::UnitQuaternion::from_axis_angle(&Vector3::x_axis(), deg.to_radians());
    text.lines()
        .enumerate()
        .map(|(k, l)| {
            if k + 1 != line {
                return format!("{l}\n");
            }
            let mut f: Vec<String> = l.split(',').map(str::to_string).collect();
            let n = f.len();
            let q: Vec<f64> = f[n - 4..].iter().map(|v| v.parse().unwrap()).collect();
            let q = turn * nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]));
            for (k, v) in [q.w, q.i, q.j, q.k].iter().enumerate() {
                f[n - 4 + k] = format!("{v:.12}");
            }
            format!("{}\n", f.join(","))
        })
        .collect()
}

/// The file's 40th data line (a point of the first session).
fn data_line(text: &str, k: usize) -> usize {
    text.lines().enumerate().filter(|(_, l)| !l.starts_with('#') && !l.starts_with("pose,")).nth(k).unwrap().0 + 1
}

/// Noisy positions (12 um) and readings (10 mdeg), one reading turned by 2 deg (200 of its
/// standard deviations): the rule flags that reading alone, by its point (its position is not
/// flagged); under `reject` the calibration equals that of the file without that reading (the
/// same points, the reading taken out of the parsed file) to the last bit in every estimate and
/// probe rotation; under `report` the reading stays in the fit and moves it.
#[test]
fn a_corrupted_reading_is_flagged_and_reject_equals_the_file_without_it() {
    let robot = irb120();
    let truth = truth_on(&robot, &identifiable());
    let s = spec(truth, &robot, 0.012, 21);
    let text = to_csv_with(&s, Some(&probes(10.0))).unwrap();
    let line = data_line(&text, 40);
    let m = parse(&turn_reading(&text, line, 2.0), &robot);
    let k = m.points.iter().position(|p| p.line == line as u64).unwrap();
    let noisy = Options { position_noise_mm: 0.012, orientation_noise_mdeg: 10.0, ..options() };
    let reject = Options { outliers: calsim::calibrate::OutlierMode::Reject, ..noisy.clone() };
    let c = run(&robot, &m, &reject).unwrap();
    let flagged: Vec<usize> = (0..m.points.len()).filter(|&i| c.readings_flagged.flagged[i]).collect();
    assert_eq!(flagged, vec![k], "the turned reading alone: {:?}", flagged.iter().map(|&i| m.points[i].line).collect::<Vec<_>>());
    assert!(!c.flagged[k], "its position is not flagged");
    assert!(c.readings_flagged.normalized[k] > 100.0, "{}", c.readings_flagged.normalized[k]);
    let warning = calsim::calibrate::report::outlier_warning(&c).unwrap();
    assert!(warning.contains(&format!("orientation reading of {} flagged as outliers (line {line})", m.points.len())), "{warning}");
    let mut without = m.clone();
    without.points[k].orientation = None;
    let w = run(&robot, &without, &reject).unwrap();
    assert!(w.readings_flagged.flagged.iter().all(|f| !f), "the file without the reading flags none");
    for (a, b) in c.estimates.iter().zip(&w.estimates) {
        assert_eq!((a.value.to_bits(), a.std.to_bits()), (b.value.to_bits(), b.std.to_bits()), "{}", a.id.name());
    }
    assert_eq!(c.probe_rotations, w.probe_rotations);
    let report = run(&robot, &m, &Options { outliers: calsim::calibrate::OutlierMode::Report, ..noisy }).unwrap();
    assert_eq!(report.readings_flagged.flagged, c.readings_flagged.flagged);
    assert_ne!(report.probe_rotations, w.probe_rotations, "kept in the fit, the reading moves it");
}

/// Clean files (12 um, 10 mdeg, Gaussian) flag no reading over 4 seeds: 4 x 240 = 960 readings,
/// where the threshold's false-alarm probability of 1e-4 per reading gives 0.096 false flags
/// expected (a flag in about 9 % of such 4-seed runs).
#[test]
fn clean_readings_are_not_flagged() {
    let robot = irb120();
    let truth = truth_on(&robot, &identifiable());
    let noisy = Options { position_noise_mm: 0.012, orientation_noise_mdeg: 10.0, ..options() };
    let mut readings = 0;
    for seed in 0..4 {
        let m = parse(&to_csv_with(&spec(truth.clone(), &robot, 0.012, 300 + seed), Some(&probes(10.0))).unwrap(), &robot);
        let c = run(&robot, &m, &noisy).unwrap();
        let flagged: Vec<u64> = (0..m.points.len()).filter(|&i| c.readings_flagged.flagged[i]).map(|i| m.points[i].line).collect();
        assert!(flagged.is_empty(), "seed {seed}: lines {flagged:?} flagged");
        let scaled: Vec<f64> = c.readings_flagged.normalized.iter().copied().filter(|v| v.is_finite()).collect();
        assert_eq!(scaled.len(), m.points.len(), "every reading scaled");
        readings += scaled.len();
    }
    assert_eq!(readings, 960);
}

/// On the command line: the turned reading is named by its line on standard error and in
/// summary.md's table, and points.parquet carries the flag; NaN, inf and absurd numbers in an
/// orientation column are one line naming the file, the line and the column, exit 2.
#[test]
fn a_flagged_reading_is_named_by_its_line_and_bad_readings_exit_2() {
    let robot_path = common::repo().join("robots/irb120.toml");
    let robot = irb120();
    let truth = truth_on(&robot, &identifiable());
    let mut s = spec(truth, &robot, 0.01, 3);
    s.poses_per_session = 12;
    let text = to_csv_with(&s, Some(&probes(5.0))).unwrap();
    let line = data_line(&text, 10);
    let dir = common::scratch("orientation-outlier");
    let csv = dir.path().join("turned.csv");
    std::fs::write(&csv, turn_reading(&text, line, 2.0)).unwrap();
    let args = ["calibrate", robot_path.to_str().unwrap(), "--no-plots", "--params", "a2,a3,d4,theta_offs2,theta_offs3,theta_offs4"];
    let o = common::calsim().args(args).arg("--out").arg(dir.path().join("out")).arg(&csv).output().unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{e}");
    assert!(e.contains(&format!("1 orientation reading of 72 flagged as outliers (line {line})")), "{e}");
    let report = dir.path().join("out/turned.calibration");
    let summary = std::fs::read_to_string(report.join("summary.md")).unwrap();
    assert!(summary.contains("1 of 72 readings flagged"), "{summary}");
    assert!(summary.lines().any(|l| l.starts_with(&format!("| {line} |"))), "{summary}");
    let points = {
        use polars::prelude::SerReader;
        polars::prelude::ParquetReader::new(std::fs::File::open(report.join("points.parquet")).unwrap()).finish().unwrap()
    };
    let flags = points.column("reading_outlier").unwrap().bool().unwrap().clone();
    let lines = points.column("line").unwrap().u64().unwrap().clone();
    let flagged: Vec<u64> = (0..flags.len()).filter(|&i| flags.get(i) == Some(true)).map(|i| lines.get(i).unwrap()).collect();
    assert_eq!(flagged, vec![line as u64]);
    for bad in ["NaN", "inf", "-inf", "1e308"] {
        let bad_text: String = text
            .lines()
            .enumerate()
            .map(|(k, l)| if k + 1 == line { format!("{},{bad}\n", l.rsplit_once(',').unwrap().0) } else { format!("{l}\n") })
            .collect();
        let csv = dir.path().join("bad.csv");
        std::fs::write(&csv, bad_text).unwrap();
        let o = common::calsim().args(args).arg("--out").arg(dir.path().join("out")).arg(&csv).output().unwrap();
        let e = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{bad}: {e}");
        assert_eq!(e.trim().lines().count(), 1, "{bad}: one line: {e}");
        assert!(e.contains("bad.csv") && e.contains(&format!("line {line}")) && e.contains("quat_z"), "{bad}: {e}");
    }
}
