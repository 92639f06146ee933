//! `calsim fk`: the tool frame, gravity torques and deflections of a robot file's arm per row of a
//! joints CSV, checked against an independent kinematics (the `k` crate reading the URDF the arm
//! came from) at 1,000 configurations, against `compensate` (its rows are targets the IK reaches
//! again), and bad CSVs refused in one line naming file, line and column.

mod common;

use calsim::robot::file::RobotFile;
use calsim::robot::fk::{fk_rows, read_joints};
use nalgebra::{Isometry3, Vector3};

/// The largest tool-frame differences (position mm, orientation rad) between the robot file
/// `robot` (through `calsim::robot::fk`) and the `k` crate's chain of `urdf` at its link `tip`,
/// over 1,000 configurations drawn within the limits.
fn against_k(robot: &str, urdf: &str, tip: &str) -> (f64, f64) {
    let file = RobotFile::load(&common::repo().join(robot)).expect("the robot file loads");
    let chain = k::Chain::<f64>::from_urdf_file(common::repo().join(urdf)).expect("k reads the URDF");
    let tool0 = chain.find_link(tip).expect("the tip link");
    let mut rng = common::rng(500);
    let qs = common::random_configs(&file.nominal, 1000, &mut rng);
    let rows = fk_rows(&file, &qs);
    let (mut dp, mut dr): (f64, f64) = (0.0, 0.0);
    for (q, row) in qs.iter().zip(&rows) {
        chain.set_joint_positions(q).expect("within the limits");
        chain.update_transforms();
        let t = tool0.world_transform().expect("updated");
        // k stands on another nalgebra: its numbers crossed one by one.
        let (v, r) = (t.translation.vector, t.rotation.quaternion().coords);
        let theirs = Isometry3::from_parts(
            nalgebra::Translation3::new(v[0] * 1e3, v[1] * 1e3, v[2] * 1e3),
            nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(r[3], r[0], r[1], r[2])),
        );
        let ours = row.tool.isometry();
        dp = dp.max((theirs.translation.vector - ours.translation.vector).norm());
        dr = dr.max(theirs.rotation.angle_to(&ours.rotation));
    }
    eprintln!("{robot} against k on {urdf} ({tip}): {dp:.3e} mm, {dr:.3e} rad over 1,000 configurations");
    (dp, dr)
}

/// The imported arms' tool frames (position and orientation, the flange turned as the file says)
/// equal those of the `k` crate on their URDFs at 1,000 configurations: the KR 6 and the LR Mate
/// 200iC to 1e-9 mm and 1e-12 rad.
#[test]
fn fk_of_the_imported_arms_equals_an_independent_kinematics() {
    for (robot, urdf) in
        [("robots/kr6r900sixx.toml", "robots/kr6r900sixx.urdf"), ("robots/lrmate200ic.toml", "robots/lrmate200ic/lrmate200ic.urdf")]
    {
        let (dp, dr) = against_k(robot, urdf, "tool0");
        assert!(dp < 1e-9 && dr < 1e-12, "{robot}: {dp:e} mm, {dr:e} rad");
    }
}

/// Every row `calsim fk` gives is a target `compensate` reaches again: on the LR Mate (numeric IK,
/// flange a half-turn from MDH frame 6) the 200 tool frames of random configurations come back as
/// joints whose tool frame is the target (1e-6 mm, 1e-6 deg), and the gravity torques and
/// deflections of fk are those of the statics (a file with masses and compliance: the KR 6's truth).
#[test]
fn fk_rows_are_compensate_targets_and_carry_the_statics() {
    let file = RobotFile::load(&common::repo().join("robots/lrmate200ic.toml")).unwrap();
    let qs = common::random_configs(&file.nominal, 200, &mut common::rng(7));
    let targets: Vec<Isometry3<f64>> = fk_rows(&file, &qs).iter().map(|r| r.tool.isometry()).collect();
    let back = calsim::app::compensate::compensate(&file, None, &targets);
    let reached = back.iter().filter(|r| r.q.is_some()).count();
    assert!(reached >= 195, "{reached} of 200");
    for (r, t) in back.iter().zip(&targets) {
        let Some(q) = r.q else { continue };
        assert!(r.error_mm < 1e-6 && r.error_deg < 1e-6, "{r:?}");
        let again = fk_rows(&file, &[q])[0].tool.isometry();
        assert!((again.translation.vector - t.translation.vector).norm() < 1e-6 && again.rotation.angle_to(&t.rotation) < 1e-8);
    }

    let kr6 = RobotFile::load(&common::repo().join("robots/kr6r900sixx.toml")).unwrap();
    let truth = RobotFile { nominal: kr6.truth_on(&kr6.nominal).unwrap(), ..kr6.clone() };
    let qs = common::random_configs(&truth.nominal, 100, &mut common::rng(8));
    for (q, row) in qs.iter().zip(fk_rows(&truth, &qs)) {
        let tau = calsim::robot::gravity_torques(&truth.nominal, q);
        assert_eq!(row.torque_nm, tau);
        for i in 0..6 {
            let c = truth.nominal.links()[i].compliance;
            assert!((row.deflection_rad[i] - c * tau[i]).abs() < 1e-15, "joint {}: {} vs {}", i + 1, row.deflection_rad[i], c * tau[i]);
        }
        assert!(row.torque_nm[1].abs() > 0.1, "the KR 6's truth has masses: {:?}", row.torque_nm);
    }
}

/// Through the command line: a joints CSV in, the rows out (the header and one row per
/// configuration); bad CSVs (wrong header, a field that is not a number (CRLF line ends too), NaN, infinite or beyond
/// three turns, a short row, no rows, a missing file) are one line naming the file, the line and
/// the column where there is one, exit 2.
#[test]
fn the_fk_command_writes_rows_and_refuses_bad_csvs_in_one_line() {
    let tmp = common::scratch("fk");
    let dir = tmp.path();
    let good = dir.join("joints.csv");
    std::fs::write(&good, "q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n0,0,0,0,0,0\n10,20,-30,40,50,60\n").unwrap();
    let out = dir.join("fk.csv");
    let o = common::calsim().args(["fk", "robots/irb120.toml", good.to_str().unwrap(), "--out", out.to_str().unwrap()]).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = std::fs::read_to_string(&out).unwrap();
    assert_eq!(text.lines().count(), 3);
    assert!(
        text.starts_with("q1_deg,")
            && text.lines().next().unwrap().contains("tau2_nm")
            && text.lines().next().unwrap().contains("deflection6_mdeg")
    );
    let row: Vec<f64> = text.lines().nth(2).unwrap().split(',').take(24).map(|x| x.parse().unwrap()).collect();
    let q = read_joints(&good).unwrap()[1];
    let ours = fk_rows(&RobotFile::load(&common::repo().join("robots/irb120.toml")).unwrap(), &[q])[0].clone();
    assert!((Vector3::new(row[6], row[7], row[8]) - ours.tool.translation()).norm() < 1e-9);

    let header = "q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n";
    for (name, text, expect) in [
        ("header.csv", "q1,q2,q3,q4,q5,q6\n0,0,0,0,0,0\n".to_string(), "line 1: header"),
        ("word.csv", format!("{header}0,0,0,0,0,0\n0,x,0,0,0,0\n"), "line 3, column 2 (q2_deg): \"x\": not a number"),
        ("crlf.csv", format!("{}\r\n0,0,0,0,0,0\r\n0,x,0,0,0,0\r\n", header.trim_end()), "line 3, column 2 (q2_deg)"),
        ("nan.csv", format!("{header}0,0,NaN,0,0,0\n"), "line 2, column 3 (q3_deg)"),
        ("inf.csv", format!("{header}0,0,0,inf,0,0\n"), "line 2, column 4 (q4_deg)"),
        ("huge.csv", format!("{header}0,0,0,0,1e300,0\n"), "line 2, column 5 (q5_deg)"),
        ("short.csv", format!("{header}0,0,0\n"), "line 2: 3 fields"),
        ("empty.csv", header.to_string(), "no rows"),
    ] {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        let o = common::calsim().args(["fk", "robots/irb120.toml", p.to_str().unwrap()]).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{name}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{name}: {err}");
        assert!(err.contains(name) && err.contains(expect), "{name}: {err}");
    }
    let o = common::calsim().args(["fk", "robots/irb120.toml", dir.join("absent.csv").to_str().unwrap()]).output().unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("absent.csv"));
}

/// The rows of `fk` are the controller's joint values: through a robot file's `[[coupling]]` (a
/// FANUC-style J3 against the horizon, theta3 = q3 - q2) the tool frames are those of the
/// uncoupled file at the model's angles, and the rows keep the controller's values.
#[test]
fn fk_rows_go_through_the_coupling() {
    let text = std::fs::read_to_string(common::repo().join("robots/irb120.toml")).unwrap();
    let coupled_text = format!("{text}\n[[coupling]]\njoint = 3\ncontroller = [0.0, -1.0, 1.0, 0.0, 0.0, 0.0]\n");
    let plain = RobotFile::from_text(std::path::Path::new("irb120.toml"), &text).unwrap();
    let coupled = RobotFile::from_text(std::path::Path::new("irb120_coupled.toml"), &coupled_text).unwrap();
    let mut rng = common::rng(8);
    let model_qs = common::random_configs(&plain.nominal, 200, &mut rng);
    // The controller's values of each model configuration: q3 = theta3 + theta2.
    let controller: Vec<[f64; 6]> = model_qs
        .iter()
        .map(|q| {
            let mut c = *q;
            c[2] = q[2] + q[1];
            c
        })
        .collect();
    let (through, direct) = (fk_rows(&coupled, &controller), fk_rows(&plain, &model_qs));
    for ((a, b), c) in through.iter().zip(&direct).zip(&controller) {
        assert_eq!(a.q, *c, "the row keeps the controller's values");
        let d = (a.tool.isometry().translation.vector - b.tool.isometry().translation.vector).norm();
        assert!(d < 1e-9, "tool frame {d} mm off the uncoupled file's at the model's angles");
    }
}

/// Output piped into a reader that stops at once (`calsim fk ... | head -n 1`): the process ends
/// quietly with the status of SIGPIPE (141), no panic and no backtrace. 20,000 rows print far more
/// than a pipe holds, so the write meets the closed pipe whatever the timing.
#[test]
fn a_reader_that_stops_early_ends_the_output_quietly() {
    let tmp = common::scratch("fk-pipe");
    let joints = tmp.path().join("joints.csv");
    let mut text = String::from("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n");
    for k in 0..20_000 {
        let a = f64::from(k % 90) - 45.0;
        text.push_str(&format!("{a},{},{},0,{},0\n", a / 3.0, a / 4.0, a / 2.0));
    }
    std::fs::write(&joints, text).unwrap();
    let mut child = common::calsim()
        .args(["fk"])
        .arg(common::repo().join("robots/irb120.toml"))
        .arg(&joints)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(141), "{err}");
    assert!(!err.contains("panicked") && !err.contains("backtrace"), "{err}");
}
