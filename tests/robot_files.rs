//! Robots as files: the shipped files are the built-in arms bit for bit, and a bad robot file is
//! one error naming the file and the field.

mod common;

use std::path::{Path, PathBuf};

use calsim::robot::builtin::{er20c10_table4, er20c10_table5, irb120, trical_2018_nominal, trical_2018_table7};
use calsim::robot::file::RobotFile;

fn shipped(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("robots").join(name)
}

#[test]
fn the_shipped_irb120_is_the_built_in_bit_for_bit() {
    let f = RobotFile::load(&shipped("irb120.toml")).expect("robots/irb120.toml loads");
    assert_eq!(f.nominal.data(), irb120().data());
    let truth = f.truth_on(&trical_2018_nominal()).expect("Table 7 applies");
    assert_eq!(truth.data(), trical_2018_table7().data());
    assert_eq!(f.truth.len(), 31);
    assert_eq!(f.capsules.as_ref(), Some(&calsim::cell::collision::irb120_link_capsules()), "the link capsules");
}

#[test]
fn the_shipped_er20c10_is_the_built_in_bit_for_bit() {
    let f = RobotFile::load(&shipped("er20c10.toml")).expect("robots/er20c10.toml loads");
    assert_eq!(f.nominal.data(), er20c10_table4().data());
    assert_eq!(f.truth_on(&f.nominal).expect("Table 5 applies").data(), er20c10_table5(true).data());
}

/// The IRB 120 file with `edit` applied to its text.
fn bad(name: &str, edit: impl Fn(&str) -> String) -> String {
    let text = std::fs::read_to_string(shipped("irb120.toml")).unwrap();
    let tmp = common::scratch("robot-files");
    let path = tmp.path().join(name);
    std::fs::write(&path, edit(&text)).unwrap();
    let e = RobotFile::load(&path).expect_err(name).to_string();
    assert!(e.contains(path.to_str().unwrap()), "{name}: the error names the file: {e}");
    assert_eq!(e.lines().count(), 1, "{name}: one line: {e}");
    e
}

#[test]
fn a_bad_robot_file_is_one_line_naming_the_file_and_the_field() {
    // The sixth joint row removed.
    let e = bad("missing.toml", |t| {
        let cut = t.rfind("[[joint]]").unwrap();
        let end = t[cut..].find("\n\n").map(|k| cut + k).unwrap();
        format!("{}{}", &t[..cut], &t[end..])
    });
    assert!(e.contains("joint") && e.contains("5 joint rows"), "{e}");
    let e = bad("nan.toml", |t| t.replacen("a_mm = 270.0", "a_mm = nan", 1));
    assert!(e.contains("joint[3].a_mm") && e.contains("finite"), "{e}");
    let e = bad("inf.toml", |t| t.replacen("mass_kg = 3.067", "mass_kg = inf", 1));
    assert!(e.contains("joint[1].mass_kg"), "{e}");
    let e = bad("reversed.toml", |t| t.replacen("limits_deg = [-110.0, 70.0]", "limits_deg = [70.0, -110.0]", 1));
    assert!(e.contains("joint[3].limits_deg") && e.contains("lower limit"), "{e}");
    // Joint 2's alpha is -90 deg: its axis is not parallel to joint 1's.
    let e = bad("beta.toml", |t| t.replacen("alpha_deg = -90.0\n", "alpha_deg = -90.0\nbeta_deg = 0.5\n", 1));
    assert!(e.contains("joint[2].beta_deg") && e.contains("parallel"), "{e}");
    let e = bad("unknown.toml", |t| t.replacen("a_mm = 270.0", "a_mm = 270.0\nlenght_mm = 3.0", 1));
    assert!(e.contains("lenght_mm"), "{e}");
    let e = bad("truth.toml", |t| t.replacen("a2 = 270.146", "a9 = 270.146", 1));
    assert!(e.contains("truth.a9") && e.contains("unknown parameter"), "{e}");
    let e = bad("huge.toml", |t| t.replacen("d_mm = 302.0", "d_mm = 1e300", 1));
    assert!(e.contains("joint[4].d_mm"), "{e}");
    let e = bad("capsule-link.toml", |t| t.replacen("link = 6", "link = 7", 1));
    assert!(e.contains("collision[9].link"), "{e}");
    let e = bad("capsule-radius.toml", |t| t.replacen("radius_mm = 21.2", "radius_mm = -1.0", 1));
    assert!(e.contains("collision[9].radius_mm"), "{e}");
    let e = bad("capsule-nan.toml", |t| t.replacen("a_mm = [0.0, -28.6, 0.0]", "a_mm = [0.0, nan, 0.0]", 1));
    assert!(e.contains("collision[8].a_mm[1]"), "{e}");
}

/// A twin's `[learned]` table: read with the file, and a bad value is one line naming its key.
#[test]
fn a_learned_table_is_read_and_its_bad_values_named() {
    let table = "\n[learned]\nrepeatability_mm = 0.01\nbacklash_mdeg = [0.0, 5.0, 3.0, 0.0, 0.0, 0.0]\n\n\
                 [[learned.harmonic]]\njoint = 2\norder = 1.0\nsin_mdeg = 10.0\ncos_mdeg = -2.0\nstd_mdeg = 1.0\n";
    let text = std::fs::read_to_string(shipped("irb120.toml")).unwrap() + table;
    let tmp = common::scratch("robot-files-learned");
    let path = tmp.path().join("twin.toml");
    std::fs::write(&path, &text).unwrap();
    let f = RobotFile::load(&path).expect("a twin loads");
    let l = f.learned.expect("its [learned] table");
    assert_eq!((l.repeatability_mm, l.backlash_mdeg[1], l.harmonic[0].joint, l.harmonic[0].sin_mdeg), (0.01, 5.0, 2, 10.0));
    let with = |from: &'static str, to: &'static str| move |t: &str| (t.to_string() + table).replacen(from, to, 1);
    let e = bad("joint.toml", with("joint = 2", "joint = 9"));
    assert!(e.contains("learned.harmonic[0].joint"), "{e}");
    let e = bad("order.toml", with("order = 1.0", "order = -1.0"));
    assert!(e.contains("learned.harmonic[0].order"), "{e}");
    let e = bad("rp.toml", with("repeatability_mm = 0.01", "repeatability_mm = nan"));
    assert!(e.contains("learned.repeatability_mm"), "{e}");
    let e = bad("backlash.toml", with("[0.0, 5.0, 3.0", "[0.0, -5.0, 3.0"));
    assert!(e.contains("learned.backlash_mdeg[1]"), "{e}");
    let e = bad("unknown.toml", with("repeatability_mm = 0.01", "repeatability_mm = 0.01\nbacklash = 3.0"));
    assert!(e.contains("backlash"), "{e}");
}

/// A TriCal scenario whose robot file gives no collision capsules is refused before anything runs:
/// one line naming the scenario, `robot.file`, the robot file and `collision`.
#[test]
fn a_trical_scenario_needs_the_arms_capsules() {
    let tmp = common::scratch("robot-file-no-capsules");
    let dir = tmp.path();
    let robot = dir.join("bare.toml");
    let text = std::fs::read_to_string(shipped("irb120.toml")).unwrap();
    let cut = text.find("[[collision]]").unwrap();
    let end = text.find("\n[truth]").unwrap();
    std::fs::write(&robot, format!("{}{}", &text[..cut], &text[end..])).unwrap();
    assert!(RobotFile::load(&robot).expect("loads without capsules").capsules.is_none());
    run_refused(dir, &robot, &["s.toml", "robot.file", "bare.toml", "collision"]);
}

/// `calsim run` of a scenario in `dir` naming `robot` exits 2 with one line holding every one of
/// `parts`.
fn run_refused(dir: &Path, robot: &Path, parts: &[&str]) {
    let scenario = dir.join("s.toml");
    std::fs::write(&scenario, format!("seed = 1\n[robot]\nfile = \"{}\"\n", robot.display())).unwrap();
    let o = common::calsim().args(["run", scenario.to_str().unwrap(), "--out", dir.join("out").to_str().unwrap()]).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
    for part in parts {
        assert!(err.contains(part), "{part} not in {err}");
    }
}

/// A scenario naming a bad robot file: `calsim run` exits 2 with one line naming the scenario, the
/// robot file and the field.
#[test]
fn a_scenario_with_a_bad_robot_file_exits_2_naming_it() {
    let tmp = common::scratch("robot-file-cli");
    let dir = tmp.path();
    let robot = dir.join("arm.toml");
    let text = std::fs::read_to_string(shipped("irb120.toml")).unwrap();
    std::fs::write(&robot, text.replacen("limits_deg = [-110.0, 70.0]", "limits_deg = [70.0, -110.0]", 1)).unwrap();
    run_refused(dir, &robot, &["s.toml", "robot.file", "arm.toml", "joint[3].limits_deg"]);
    // A missing robot file.
    run_refused(dir, Path::new("no-such-arm.toml"), &["s.toml", "robot.file", "no-such-arm.toml"]);
}
