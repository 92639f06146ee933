//! A URDF arm into calsim's MDH form: the ROS-Industrial IRB 120 (joint origins as pure
//! translations, axes along z, y and x; values as cited in reference/irb120.toml) gives the
//! built-in Table 3 arm's flange position at every configuration; a URDF calsim cannot take is one
//! error naming the joint or link.

mod common;

use calsim::robot::builtin::irb120;
use calsim::robot::{KinState, forward};

/// The ROS-Industrial abb_irb120_support irb120_3_58 chain (base_link to tool0), with `edit`
/// applied to its text.
fn irb120_urdf(edit: impl Fn(&str) -> String) -> String {
    let joint = |i: usize, xyz: &str, axis: &str, lo: f64, hi: f64| {
        let parent = if i == 1 { "base_link".to_string() } else { format!("link_{}", i - 1) };
        format!(
            r#"<joint name="joint_{i}" type="revolute"><origin xyz="{xyz}" rpy="0 0 0"/><parent link="{parent}"/><child link="link_{i}"/><axis xyz="{axis}"/><limit lower="{lo}" upper="{hi}" effort="0" velocity="4.3"/></joint>"#
        )
    };
    let links: String = (1..=6).map(|i| format!(r#"<link name="link_{i}"/>"#)).collect();
    let text = format!(
        r#"<robot name="abb_irb120_3_58"><link name="base_link"/>{links}<link name="tool0"/>{}{}{}{}{}{}<joint name="joint_6-tool0" type="fixed"><origin xyz="0 0 0" rpy="0 1.5708 0"/><parent link="link_6"/><child link="tool0"/></joint></robot>"#,
        joint(1, "0 0 0", "0 0 1", -2.87979, 2.87979),
        joint(2, "0 0 0.29", "0 1 0", -1.91986, 1.91986),
        joint(3, "0 0 0.27", "0 1 0", -1.91986, 1.22173),
        joint(4, "0 0 0.07", "1 0 0", -2.79253, 2.79253),
        joint(5, "0.302 0 0", "0 1 0", -2.094395, 2.094395),
        joint(6, "0.072 0 0", "1 0 0", -6.98132, 6.98132),
    );
    edit(&text)
}

/// `text` written as `name` in a scratch directory of its own, removed when the guard is dropped.
fn write(name: &str, text: &str) -> (tempfile::TempDir, std::path::PathBuf) {
    let tmp = common::scratch(&format!("urdf-import-{name}"));
    let p = tmp.path().join(name);
    std::fs::write(&p, text).unwrap();
    (tmp, p)
}

#[test]
fn the_ros_industrial_irb120_is_the_table3_arm() {
    let (_urdf_dir, urdf) = write("irb120.urdf", &irb120_urdf(str::to_string));
    let model = calsim::robot::urdf::load(&urdf).expect("the URDF converts");
    let table3 = irb120();
    let mut rng = common::rng(120);
    // 1,000 configurations within the limits: the flange positions agree to 1e-6 mm.
    let worst = common::largest_tcp_difference(&model, &table3, &table3, &mut rng);
    assert!(worst < 1e-6, "largest flange difference {worst:e} mm");
    // The MDH geometry: a2 = 270, a3 = 70, d4 = 302 (Table 3), joints 2 and 3 parallel.
    let l = &model.data().links;
    assert!((l[2].a - 270.0).abs() < 1e-9 && (l[3].a - 70.0).abs() < 1e-9 && (l[3].d - 302.0).abs() < 1e-9, "{l:?}");
    assert!(l[2].alpha.abs() < 1e-12, "joints 2 and 3 are parallel");

    // Through the command line into a robot file, and back: the same flange positions.
    let tmp = common::scratch("urdf-import-cli");
    let dir = tmp.path();
    let out = dir.join("irb120_from_urdf.toml");
    let (_cli_dir, urdf) = write("irb120_cli.urdf", &irb120_urdf(str::to_string));
    let o = common::calsim().args(["import-urdf", urdf.to_str().unwrap(), "--out", out.to_str().unwrap()]).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let file = calsim::robot::file::RobotFile::load(&out).expect("the robot file loads");
    let worst = common::largest_tcp_difference(&file.nominal, &model, &table3, &mut rng);
    assert!(worst < 1e-9, "robot file against the converted model: {worst:e} mm");
}

#[test]
fn a_urdf_calsim_cannot_take_is_one_error_naming_the_joint_or_link() {
    for (name, edit, expect) in [
        ("prismatic.urdf", ("name=\"joint_3\" type=\"revolute\"", "name=\"joint_3\" type=\"prismatic\""), "joint `joint_3` is Prismatic"),
        ("reversed.urdf", ("lower=\"-1.91986\" upper=\"1.22173\"", "lower=\"1.22173\" upper=\"-1.91986\""), "joint `joint_3`: limits"),
        ("axis.urdf", ("<axis xyz=\"1 0 0\"/>", "<axis xyz=\"0 0 0\"/>"), "joint `joint_4`: axis"),
        (
            "branch.urdf",
            (
                "<link name=\"tool0\"/>",
                "<link name=\"tool0\"/><link name=\"extra\"/><joint name=\"joint_x\" type=\"revolute\"><parent link=\"link_2\"/><child link=\"extra\"/><axis xyz=\"0 0 1\"/><limit lower=\"-1\" upper=\"1\" effort=\"0\" velocity=\"1\"/></joint>",
            ),
            "link `link_2` branches",
        ),
        ("five.urdf", ("name=\"joint_6\" type=\"revolute\"", "name=\"joint_6\" type=\"fixed\""), "5 revolute joints"),
    ] {
        let (_dir, p) = write(name, &irb120_urdf(|t| t.replacen(edit.0, edit.1, 1)));
        let e = calsim::robot::urdf::load(&p).expect_err(name).to_string();
        assert!(e.contains(name) && e.contains(expect), "{name}: {e}");
        assert_eq!(e.lines().count(), 1, "{name}: {e}");
        let o = common::calsim().args(["import-urdf", p.to_str().unwrap(), "--out", "/dev/null/x.toml"]).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{name}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{name}: {err}");
    }
}

#[test]
fn a_malformed_or_missing_urdf_is_one_line_and_exit_2() {
    let (_dir, broken) = write("broken.urdf", &irb120_urdf(|t| t.replace("</robot>", "")));
    let missing = broken.with_file_name("missing.urdf");
    for p in [broken, missing] {
        let o = common::calsim().args(["import-urdf", p.to_str().unwrap(), "--out", "/tmp/never-written.toml"]).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{err}");
        assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
        assert!(err.contains(p.file_name().unwrap().to_str().unwrap()), "{err}");
    }
}

/// A URDF that parses but gives a robot calsim cannot use (a link of 1e300 kg, a joint limit of
/// 1e300 rad) is refused in one line naming the URDF and the field, and no robot file is written.
#[test]
fn a_urdf_with_absurd_values_is_refused_and_nothing_written() {
    let urdf = std::fs::read_to_string(common::repo().join("robots/kr6r900sixx.urdf")).unwrap();
    let first = |t: &str, from: &str, to: &str| {
        let i = t.find(from).expect("the shipped URDF has it") + from.len();
        let j = i + t[i..].find('"').unwrap();
        format!("{}{to}{}", &t[..i], &t[j..])
    };
    for (name, text, field) in [
        ("heavy.urdf", first(&urdf, "<mass value=\"", "1e300"), "link `link_1`: mass 1e300"),
        ("limitless.urdf", first(&urdf, "upper=\"", "1e300"), "limits"),
    ] {
        let (_dir, p) = write(name, &text);
        let out = p.with_extension("toml");
        let o = common::calsim().args(["import-urdf", p.to_str().unwrap(), "--out", out.to_str().unwrap()]).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{name}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
        assert!(err.contains(name) && err.contains(field), "names the URDF and the field: {err}");
        assert!(!out.exists(), "{name}: nothing written");
    }
}

/// The shipped third arm: robots/kr6r900sixx.toml is the conversion of robots/kr6r900sixx.urdf
/// (the ROS-Industrial KR 6 R900 sixx, first axis pointing down: {0} upside down, gravity along its
/// +z), to 1e-9 mm at 1,000 configurations, and its gravity points down in the root frame.
#[test]
fn the_shipped_kr6_file_is_its_urdf() {
    let root = common::repo().join("robots");
    let from_urdf = calsim::robot::urdf::load(&root.join("kr6r900sixx.urdf")).expect("the URDF converts");
    let file = calsim::robot::file::RobotFile::load(&root.join("kr6r900sixx.toml")).expect("the robot file loads");
    let worst = common::largest_tcp_difference(&from_urdf, &file.nominal, &from_urdf, &mut common::rng(6));
    assert!(worst < 1e-9, "{worst:e} mm");
    let d = file.nominal.data();
    let down = d.world_from_base.rotation() * d.gravity_base;
    assert!((down - nalgebra::Vector3::new(0.0, 0.0, -9.81)).norm() < 1e-9, "gravity in the root frame: {down}");
}

/// The converted KR 6's flange: its last URDF axis points into the wrist, so MDH frame 6 does, and
/// the file turns the flange back out (the tip link `tool0`'s z, along the forearm at q = 0).
#[test]
fn the_kr6_flange_faces_out_of_the_wrist() {
    let file = calsim::robot::file::RobotFile::load(&common::repo().join("robots/kr6r900sixx.toml")).expect("loads");
    let r = file.flange.expect("the KR 6 flange is not frame 6");
    let mut st = KinState::default();
    let f = calsim::robot::world_from_flange(&file.nominal, &mut st, &[0.0; 6]);
    let out = f.rotation * (r * nalgebra::Vector3::z());
    // At q = 0 the arm stretches along the root's +x: the flange faces +x.
    assert!((out - nalgebra::Vector3::x()).norm() < 1e-12, "flange z at q = 0: {out}");
}

/// The third arm runs the TriCal study from its files: campaign (numeric IK, its own link
/// capsules, the upside-down {0}, the turned flange) and identification of the 31 parameters. On
/// 10 sets of 75 the calibration must cut the error several-fold: the after-calibration median
/// below a third of the before-calibration mean.
#[test]
fn the_kr6_runs_the_trical_study() {
    let mut s = calsim::io::scenario::load(&common::repo().join("scenarios/kr6r900sixx_trical.toml")).expect("scenario");
    s.study.set_sizes = vec![75];
    s.study.repetitions = 10;
    let e = s.experiment.build(s.seed).expect("the KR 6 campaign");
    assert_eq!(e.campaign.pool.len(), 360);
    assert_eq!(e.campaign.validation.len(), 506);
    let before = s.experiment.before_model(&e.campaign);
    let r = calsim::study::run(&e, &before, &s.study, s.seed, &|_, _| {}).expect("study");
    let before_mean = r.before_errors.iter().sum::<f64>() / r.before_errors.len() as f64;
    let mut medians: Vec<f64> = r.tasks.iter().filter(|t| t.id.outcome.label() == "converged").map(|t| t.validation.median).collect();
    assert_eq!(medians.len(), 10, "every set identified");
    medians.sort_by(f64::total_cmp);
    let median = medians[5];
    eprintln!("KR 6: before mean {before_mean:.3} mm, after median of medians {median:.3} mm");
    assert!(median < before_mean / 3.0, "after {median} mm vs before {before_mean} mm");
}

/// The URDF's collision cylinders become capsules of the same size and place: the KR 6's upper-arm
/// cylinder (link_2: radius 70 mm, 300 mm long, centred 227.5 mm along the link from joint 2,
/// 25 mm out and 400 mm up in the root frame) lies, at q = 0, from (102.5, 0, 400) to
/// (402.5, 0, 400) mm in the root frame; and a cylinder of negative radius is one error naming its
/// link.
#[test]
fn urdf_collision_cylinders_become_capsules_in_place() {
    let c = calsim::robot::urdf::load_all(&common::repo().join("robots/kr6r900sixx.urdf"), &Default::default()).expect("converts");
    let caps = c.capsules.expect("the KR 6 URDF has collision cylinders");
    assert_eq!(caps.iter().map(Vec::len).sum::<usize>(), 7);
    let mut st = KinState::default();
    forward(&c.model, &mut st, &[0.0; 6]);
    let root_from_2 = calsim::robot::world_from_base(&c.model) * st.base_from_frame(2);
    let [cap] = caps[2].as_slice() else { panic!("one capsule on link 2: {:?}", caps[2]) };
    let mut ends = [root_from_2 * nalgebra::Point3::from(cap.a), root_from_2 * nalgebra::Point3::from(cap.b)];
    ends.sort_by(|p, q| p.x.total_cmp(&q.x));
    assert!((ends[0].coords - nalgebra::Vector3::new(102.5, 0.0, 400.0)).norm() < 1e-9, "{}", ends[0]);
    assert!((ends[1].coords - nalgebra::Vector3::new(402.5, 0.0, 400.0)).norm() < 1e-9, "{}", ends[1]);
    assert_eq!(cap.radius, 70.0);
    let text = std::fs::read_to_string(common::repo().join("robots/kr6r900sixx.urdf")).unwrap();
    let (_dir, bad) = write("negative-radius.urdf", &text.replacen("<cylinder radius=\"0.07\"", "<cylinder radius=\"-0.07\"", 1));
    let e = calsim::robot::urdf::load_all(&bad, &Default::default()).err().expect("refused").to_string();
    assert!(e.contains("negative-radius.urdf") && e.contains("link_2") && e.lines().count() == 1, "{e}");
}
