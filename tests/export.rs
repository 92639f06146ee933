//! The calibrated model out: `calsim export` writes the identified model as a robot file whose
//! forward kinematics is the identified model's, with every identified parameter's std.

mod common;

use calsim::robot::file::RobotFile;
use calsim::robot::uniform_configuration;
use calsim::robot::{KinState, forward};
use common::{calsim, repo, scratch};

#[test]
fn an_exported_robot_file_is_the_identified_model() {
    let tmp = scratch("export");
    let dir = tmp.path();
    let scenario = repo().join("scenarios/ci_quick.toml");
    let out = dir.join("out");
    let spec = calsim::app::run::RunSpec {
        scenario: scenario.clone(),
        out: out.clone(),
        threads: None,
        overrides: Default::default(),
        plots: false,
        recording: false,
        realisations: Some(1),
        false_alarm: None,
        junit: None,
        check: false,
    };
    let results = calsim::app::run::run(&spec, &calsim::app::Quiet).unwrap().dest;
    let e = calsim::app::export::identification(&results, calsim::app::export::Pick::Median(None)).unwrap();
    let exported = calsim::app::export::write(&dir.join("export"), "ci_quick.task", &e).unwrap();
    let task = e.task;
    let file = RobotFile::load(&exported.join("robot.toml")).expect("the exported robot file loads");
    assert!(std::fs::read_to_string(exported.join("calibration.yaml")).unwrap().contains("joint_6:"));

    // The identified model, redone from the scenario.
    let s = calsim::device::trical::spec::load(&scenario).unwrap();
    let e = s.experiment.build(s.header.seed).unwrap();
    let before = s.experiment.before_model(&e.campaign);
    let r = calsim::device::trical::study::recompute_task(&e, &before, &s.study, s.header.seed, task).unwrap().expect("the task exists");
    let model = r.model.expect("an identified model");
    assert_eq!(file.std.len(), r.set.len(), "a std per identified parameter");
    assert!(file.std.iter().all(|(_, v)| v.is_finite() && *v > 0.0));
    // 1,000 configurations within the limits: the TCPs agree to 1e-9 mm (the file holds degrees,
    // so the angles come back to within their rounding).
    let mut rng = common::rng(1000);
    let worst = common::largest_tcp_difference(&model, &file.nominal, &model, &mut rng);
    assert!(worst < 1e-9, "largest TCP difference {worst:e} mm");

    // The URDF through an independent kinematics (the `k` crate): the TCP of the identified model
    // without its compliance, which URDF cannot hold, to 1e-6 mm at 1,000 configurations.
    let rigid = model
        .edited(|d| {
            for l in &mut d.links {
                l.compliance = 0.0;
            }
        })
        .unwrap();
    let (mut a, mut b) = (KinState::default(), KinState::default());
    let chain = k::Chain::<f64>::from_urdf_file(exported.join("robot.urdf")).expect("k reads the URDF");
    let tcp = chain.find_link("tcp").expect("a tcp link");
    let worst = (0..1000)
        .map(|_| {
            let q = uniform_configuration(&rigid, 0.0, &mut rng);
            chain.set_joint_positions(&q).expect("six joints within limits");
            chain.update_transforms();
            let p = tcp.world_transform().expect("updated").translation.vector;
            let ours = forward(&rigid, &mut a, &q);
            ((p.x * 1e3 - ours.x).powi(2) + (p.y * 1e3 - ours.y).powi(2) + (p.z * 1e3 - ours.z).powi(2)).sqrt()
        })
        .fold(0.0, f64::max);
    assert!(worst < 1e-6, "URDF through k: largest TCP difference {worst:e} mm");

    // Compensation: TCP targets the identified model reaches (20 random configurations); the joint
    // targets calsim compensate gives put the model's TCP on them, and its corrected Cartesian
    // targets are the nominal model's TCP at those joints.
    let mut targets = String::from("x_mm,y_mm,z_mm,alpha_deg,beta_deg,gamma_deg\n");
    for _ in 0..20 {
        let q = uniform_configuration(&model, 0.1, &mut rng);
        let f = calsim::robot::world_from_flange(&model, &mut a, &q);
        let p = f * nalgebra::Point3::from(model.data().flange_tcp_mm);
        let t = calsim::robot::XyzZyx::from_isometry(&f);
        targets.push_str(&format!("{},{},{},{},{},{}\n", p.x, p.y, p.z, t.alpha.to_degrees(), t.beta.to_degrees(), t.gamma.to_degrees()));
    }
    let targets_path = dir.join("targets.csv");
    std::fs::write(&targets_path, targets).unwrap();
    let out_csv = dir.join("joints.csv");
    let o = calsim()
        .args(["compensate", exported.join("robot.toml").to_str().unwrap(), targets_path.to_str().unwrap()])
        .args(["--nominal", exported.join("before.toml").to_str().unwrap(), "--out", out_csv.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let before = RobotFile::load(&exported.join("before.toml")).expect("before.toml loads").nominal;
    let text = std::fs::read_to_string(&out_csv).unwrap();
    let mut rows = 0;
    for (line, target) in text.lines().skip(1).zip(std::fs::read_to_string(&targets_path).unwrap().lines().skip(1)) {
        let v: Vec<f64> = line.split(',').map(|x| x.parse().expect("a number")).collect();
        let t: Vec<f64> = target.split(',').map(|x| x.parse().unwrap()).collect();
        let q: [f64; 6] = std::array::from_fn(|i| v[i].to_radians());
        let p = forward(&file.nominal, &mut a, &q);
        let miss = ((p.x - t[0]).powi(2) + (p.y - t[1]).powi(2) + (p.z - t[2]).powi(2)).sqrt();
        assert!(miss < 1e-6 && v[6] < 1e-6 && v[7] < 1e-6, "the model's TCP misses the target by {miss:e} mm, {} deg", v[7]);
        let n = forward(&before, &mut b, &q);
        let corrected = ((n.x - v[8]).powi(2) + (n.y - v[9]).powi(2) + (n.z - v[10]).powi(2)).sqrt();
        assert!(corrected < 1e-6, "the nominal target is the nominal TCP at q: {corrected:e} mm");
        rows += 1;
    }
    assert_eq!(rows, 20);
}

#[test]
fn bad_export_input_is_one_line_and_exit_2() {
    let tmp = scratch("export-bad");
    let dir = tmp.path();
    for (args, expect) in
        [(vec!["export", dir.to_str().unwrap()], "manifest.json"), (vec!["export", dir.to_str().unwrap(), "--task", "x"], "--task")]
    {
        let o = calsim().args(&args).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: {err}");
        assert!(err.contains(expect), "{args:?}: {err}");
    }
}

#[test]
fn bad_targets_are_one_line_naming_the_file_and_line() {
    let tmp = scratch("compensate-bad");
    let dir = tmp.path();
    let robot = repo().join("robots/irb120.toml");
    for (name, text, expect) in [
        ("nan.csv", "x_mm,y_mm,z_mm,alpha_deg,beta_deg,gamma_deg\n300,0,400,0,180,0\n300,nan,400,0,180,0\n", "line 3"),
        ("header.csv", "x,y,z\n300,0,400\n", "line 1"),
        ("text.csv", "x_mm,y_mm,z_mm,alpha_deg,beta_deg,gamma_deg\n300,zero,400,0,180,0\n", "y_mm"),
        ("short.csv", "x_mm,y_mm,z_mm,alpha_deg,beta_deg,gamma_deg\n300,0,400\n", "line 2"),
        ("empty.csv", "x_mm,y_mm,z_mm,alpha_deg,beta_deg,gamma_deg\n", "no targets"),
    ] {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        let o = calsim().args(["compensate", robot.to_str().unwrap(), p.to_str().unwrap()]).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{name}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{name}: {err}");
        assert!(err.contains(name) && err.contains(expect), "{name}: {err}");
    }
}

/// The third arm's calibration out: an export of a KR 6 study reloads as the identified model
/// (TCP to 1e-9 mm at 1,000 configurations) with the arm's collision capsules and its turned
/// flange, so the exported file can run a TriCal study of its own.
#[test]
fn an_exported_kr6_keeps_its_capsules_and_flange() {
    let tmp = scratch("export-kr6");
    let dir = tmp.path();
    let text = common::scenario_text_anywhere("kr6r900sixx_trical.toml")
        .replace("set_sizes = [20, 25, 30, 35, 40, 45, 50, 55, 60, 65, 70, 75, 80, 85, 90, 95, 100]", "set_sizes = [75]")
        .replace("repetitions = 30 ", "repetitions = 3 ");
    assert!(text.contains("set_sizes = [75]") && text.contains("repetitions = 3 "), "the study reduced");
    let scenario = dir.join("kr6.toml");
    std::fs::write(&scenario, &text).unwrap();
    let out = dir.join("out");
    let o = calsim()
        .args(["run", scenario.to_str().unwrap(), "--out", out.to_str().unwrap(), "--no-plots", "--no-recording"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = calsim().args(["export", out.join("kr6").to_str().unwrap(), "--out", dir.join("export").to_str().unwrap()]).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let exported = std::fs::read_dir(dir.join("export")).unwrap().map(|e| e.unwrap().path()).find(|p| p.is_dir()).expect("an export");
    let task: usize = exported.to_str().unwrap().rsplit("task-").next().unwrap().parse().unwrap();
    let file = RobotFile::load(&exported.join("robot.toml")).expect("the exported robot file loads");
    let arm = RobotFile::load(&repo().join("robots/kr6r900sixx.toml")).unwrap();
    assert_eq!(file.capsules, arm.capsules, "the arm's capsules");
    let (f, g) = (file.flange.expect("a flange"), arm.flange.unwrap());
    assert!((f - g).amax() < 1e-12, "the arm's flange");

    let s = calsim::device::trical::spec::load(&scenario).unwrap();
    let e = s.experiment.build(s.header.seed).unwrap();
    let before = s.experiment.before_model(&e.campaign);
    let model = calsim::device::trical::study::recompute_task(&e, &before, &s.study, s.header.seed, task)
        .unwrap()
        .expect("the task")
        .model
        .expect("a model");
    let worst = common::largest_tcp_difference(&model, &file.nominal, &model, &mut common::rng(1001));
    assert!(worst < 1e-9, "largest TCP difference {worst:e} mm");
}
