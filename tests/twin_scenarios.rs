//! A twin (a robot file with a `[learned]` table) named by a scenario in another directory: `run`,
//! `sweep`, `budget` and `optimise` take it from a third working directory; its learned effects
//! reach every world (a larger error after calibration, the same seeds); an all-zero table, or a
//! scale of 0, leaves the results bit for bit as without it; the twin's repeatability is the
//! robot's unless the scenario sets its own; a bad learned value is one line naming the scenario,
//! the robot file and `learned.<key>`, exit 2.

mod common;

use std::path::{Path, PathBuf};

use common::{calsim, repo, scratch};

/// Effects of every kind, large enough to show against the scenario's fitted harmonic.
const LEARNED: &str = "\n[learned]\nsource = \"a test's twin\"\nrepeatability_mm = 0.012\npose_error_mdeg = 4.0\n\
    backlash_mdeg = [0.0, 8.0, 6.0, 0.0, 0.0, 0.0]\nbacklash_std_mdeg = [0.0, 1.0, 1.0, 0.0, 0.0, 0.0]\n\
    sag_mdeg_per_m = [0.0, 10.0, 6.0, 0.0, 0.0, 0.0]\nsag_std_mdeg_per_m = [0.0, 2.0, 1.0, 0.0, 0.0, 0.0]\n\n\
    [[learned.harmonic]]\njoint = 2\norder = 1.0\nsin_mdeg = 12.0\ncos_mdeg = -4.0\nstd_mdeg = 1.0\n\n\
    [[learned.harmonic]]\njoint = 3\norder = 37.0\nsin_mdeg = 3.0\ncos_mdeg = 2.0\nstd_mdeg = 0.5\n";

/// A `[learned]` table whose every amplitude and spread is zero.
const ZERO: &str = "\n[learned]\nsource = \"nothing learned\"\nrepeatability_mm = 0.0\npose_error_mdeg = 0.0\n\
    backlash_mdeg = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]\nsag_mdeg_per_m = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]\n\n\
    [[learned.harmonic]]\njoint = 2\norder = 3.0\nsin_mdeg = 0.0\ncos_mdeg = 0.0\n";

/// `<dir>/arms/<name>`: the shipped IRB 120 robot file with `table` after it.
fn arm(dir: &Path, name: &str, table: &str) -> PathBuf {
    let text = std::fs::read_to_string(repo().join("robots/irb120.toml")).unwrap() + table;
    std::fs::create_dir_all(dir.join("arms")).unwrap();
    let p = dir.join("arms").join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// The reduced CI scenario (one set size of 20, one repetition, a campaign of 60 pool and 60
/// validation poses) naming `../arms/<arm>`, with `edit` applied, as `<dir>/studies/<name>`.
fn scenario(dir: &Path, name: &str, arm: &str, edit: impl Fn(String) -> String) -> PathBuf {
    let text = std::fs::read_to_string(repo().join("scenarios/ci_quick.toml"))
        .unwrap()
        .replace("file = \"../robots/irb120.toml\"", &format!("file = \"../arms/{arm}\""))
        .replace("set_sizes = [20, 50, 75, 100]", "set_sizes = [20]")
        .replace("repetitions = 10 ", "repetitions = 1 ")
        .replace("table_set_size = 75 ", "table_set_size = 20 ")
        .replace("pool_per_sphere = 120 ", "pool_per_sphere = 20 ")
        .replace("validation_poses = 506 ", "validation_poses = 60 ");
    assert!(text.contains(&format!("../arms/{arm}")) && text.contains("validation_poses = 60"), "the CI scenario's lines moved");
    std::fs::create_dir_all(dir.join("studies")).unwrap();
    let p = dir.join("studies").join(name);
    std::fs::write(&p, edit(text)).unwrap();
    p
}

fn load(p: &Path) -> calsim::device::trical::TricalScenario {
    calsim::device::trical::spec::load(p).unwrap_or_else(|e| panic!("{e}"))
}

/// `calsim <args>` run in `cwd`: exit code and stderr.
fn run_in(cwd: &Path, args: &[&str]) -> (Option<i32>, String) {
    let o = calsim().current_dir(cwd).args(args).output().unwrap();
    (o.status.code(), String::from_utf8_lossy(&o.stderr).into_owned())
}

fn succeeds(cwd: &Path, args: &[&str]) {
    let (code, err) = run_in(cwd, args);
    assert_eq!(code, Some(0), "{args:?}: {err}");
}

/// Exit 2 with one error line (besides the command's start line) holding every one of `parts`.
fn refused(cwd: &Path, args: &[&str], parts: &[&str]) {
    let (code, err) = run_in(cwd, args);
    assert_eq!(code, Some(2), "{args:?}: {err}");
    let errors: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty() && !l.starts_with("calsim ")).collect();
    assert_eq!(errors.len(), 1, "{args:?}: one line: {err}");
    for p in parts {
        assert!(errors[0].contains(p), "{args:?}: `{p}` not in {err}");
    }
}

#[test]
fn a_twin_named_from_another_directory_runs_run_sweep_budget_and_optimise() {
    let tmp = scratch("twin-commands");
    let dir = tmp.path();
    arm(dir, "twin.toml", LEARNED);
    scenario(dir, "s.toml", "twin.toml", |t| t);
    std::fs::write(
        dir.join("studies/sweep.toml"),
        "base = \"s.toml\"\nrealisations = 1\nthresholds_mm = [0.5]\n\n[[axis]]\nkey = \"robot.learned_scale\"\nvalues = [0.0, 1.0]\n",
    )
    .unwrap();
    std::fs::write(
        dir.join("studies/design.toml"),
        "base = \"s.toml\"\n[points]\nkey = \"cell.spheres_w_mm\"\ncount = [3, 3]\nregion = \"plate\"\nx_mm = [0.0, 300.0]\ny_mm = [0.0, 300.0]\n\
         height_mm = [0.0, 100.0]\ntilt_deg = [0.0, 20.0]\nmin_spacing_mm = 150.0\nstart_spacing_mm = 300.0\n\n[search]\nevaluations = 2\nrestarts = 1\n\
         worlds = 1\nfinalists = 1\nrace = { max = 2, batch = 1 }\n\n[verify]\nheld_out = 1\n\n[objective]\nmaximise = \"success\"\nstatistic = \"max\"\n\
         threshold_mm = 0.5\nconfidence = 0.9\n",
    )
    .unwrap();
    // A third directory: the scenario and the twin are named only by relative paths.
    let elsewhere = dir.join("elsewhere");
    std::fs::create_dir_all(&elsewhere).unwrap();
    let quiet = ["--no-plots", "--no-recording"];
    succeeds(&elsewhere, &[&["run", "../studies/s.toml"][..], &quiet, &["--out", "out-run"]].concat());
    succeeds(&elsewhere, &["sweep", "../studies/sweep.toml", "--out", "out-sweep"]);
    succeeds(&elsewhere, &["budget", "../studies/s.toml", "--realisations", "1", "--factors", "0.5", "--out", "out-budget"]);
    succeeds(&elsewhere, &["optimise", "../studies/design.toml", "--out", "out-optimise"]);
    // The budget has the twin's effects and its repeatability among its sources.
    let budget = std::fs::read_dir(elsewhere.join("out-budget"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.is_dir() && p.file_name().unwrap().to_string_lossy().starts_with("s.budget"))
        .expect("the budget's directory");
    let summary = std::fs::read_dir(&budget)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "md"))
        .map(|p| std::fs::read_to_string(p).unwrap())
        .collect::<String>();
    assert!(summary.contains("the twin's learned effects"), "{summary}");
}

/// Over the same 10 worlds (seeds), the twin's effects raise the after-calibration median of every
/// world above the same arm's without its `[learned]` table, by more than half in the median world; the twin's repeatability (0.012 mm)
/// is the robot's where the scenario leaves its key out.
#[test]
fn the_twins_effects_raise_the_error_after_calibration_in_every_world() {
    let tmp = scratch("twin-effect");
    let dir = tmp.path();
    arm(dir, "twin.toml", LEARNED);
    arm(dir, "plain.toml", "");
    let no_rp = |t: String| t.replace("repeatability_mm = 0.010 ", "# repeatability_mm left to the twin ");
    let twin = load(&scenario(dir, "twin.toml", "twin.toml", no_rp));
    assert_eq!(twin.experiment.robot.repeatability_mm, 0.012, "the twin's repeatability");
    // The shipped campaign (360 pool poses), 200 validation poses, 3 sets of 50 per world.
    let study = |t: String| {
        t.replace("pool_per_sphere = 20 ", "pool_per_sphere = 120 ")
            .replace("validation_poses = 60 ", "validation_poses = 200 ")
            .replace("set_sizes = [20]", "set_sizes = [50]")
            .replace("table_set_size = 20 ", "table_set_size = 50 ")
            .replace("repetitions = 1 ", "repetitions = 3 ")
    };
    let plain = load(&scenario(dir, "plain.toml", "plain.toml", study));
    assert_eq!(plain.experiment.robot.repeatability_mm, 0.010);
    // The same repeatability on both sides: the difference is the learned effects alone.
    let twin_same_rp = load(&scenario(dir, "twin_rp.toml", "twin.toml", study));
    assert_eq!(twin_same_rp.experiment.robot.repeatability_mm, 0.010, "a scenario's own key is a what-if on the twin");
    let worlds = 10;
    let (with, without) = (common::trical_worlds(&twin_same_rp, worlds), common::trical_worlds(&plain, worlds));
    for (r, (w, p)) in with.iter().zip(&without).enumerate() {
        eprintln!("world {r}: before {:.4} / {:.4} mm, after {:.4} / {:.4} mm (twin / plain)", w.0, p.0, w.1, p.1);
    }
    for (r, (w, p)) in with.iter().zip(&without).enumerate() {
        assert_ne!(w.0, p.0, "world {r}: the twin moves the error before calibration too");
        assert!(w.1 > p.1, "world {r}: after calibration {:.4} mm with the twin against {:.4} mm without", w.1, p.1);
    }
    let mut ratios: Vec<f64> = with.iter().zip(&without).map(|(w, p)| w.1 / p.1).collect();
    ratios.sort_by(f64::total_cmp);
    assert!(ratios[worlds as usize / 2] > 1.5, "the median ratio over {worlds} worlds: {ratios:?}");
}

/// A twin whose `[learned]` table gives the spread of its repeatability's estimate
/// (`repeatability_std_mm = 0.004` about 0.012 mm): a scenario that takes the twin's level draws it
/// in every world (the joint noise of the robot's moves scales with it), every other draw of the
/// world unchanged. Over 100 worlds the drawn levels' mean is within four standard errors of
/// 0.012 mm (0.004 / sqrt(100)) and their standard deviation within four of 0.004 mm
/// (0.004 / sqrt(200)); a scenario that sets its own `robot.repeatability_mm` takes it in every
/// world (the first 5).
#[test]
fn a_twins_repeatability_spread_draws_the_level_per_world() {
    let tmp = scratch("twin-rp-spread");
    let dir = tmp.path();
    arm(dir, "point.toml", LEARNED);
    arm(dir, "spread.toml", &LEARNED.replace("repeatability_mm = 0.012\n", "repeatability_mm = 0.012\nrepeatability_std_mm = 0.004\n"));
    let no_rp = |t: String| t.replace("repeatability_mm = 0.010 ", "# repeatability_mm left to the twin ");
    let point = load(&scenario(dir, "point.toml", "point.toml", no_rp));
    let spread = load(&scenario(dir, "spread.toml", "spread.toml", no_rp));
    let own = load(&scenario(dir, "own.toml", "spread.toml", |t| t));
    assert_eq!(spread.experiment.robot.learned.as_ref().map(|l| l.repeatability_std_mm), Some(0.004));
    let worlds = 100;
    let mut levels = Vec::new();
    for seed in 0..worlds {
        let (p, s) = (point.experiment.build(seed).unwrap(), spread.experiment.build(seed).unwrap());
        assert_eq!(p.robot.harmonics, s.robot.harmonics, "world {seed}: the scenario's own harmonics");
        assert_eq!(
            p.robot.learned.as_ref().map(|l| &l.harmonics),
            s.robot.learned.as_ref().map(|l| &l.harmonics),
            "world {seed}: the learned effects"
        );
        if seed < 5 {
            let own_level = 0.012 * own.experiment.build(seed).unwrap().robot.sigma_q / p.robot.sigma_q;
            assert!((own_level - 0.010).abs() < 1e-12, "world {seed}: the scenario's own level, {own_level} mm");
        }
        levels.push(0.012 * s.robot.sigma_q / p.robot.sigma_q);
    }
    let n = levels.len() as f64;
    let mean = levels.iter().sum::<f64>() / n;
    let sd = (levels.iter().map(|l| (l - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    assert!((mean - 0.012).abs() < 4.0 * 0.004 / n.sqrt(), "mean level {mean} mm over {worlds} worlds");
    assert!((sd - 0.004).abs() < 4.0 * 0.004 / (2.0 * n).sqrt(), "std of the level {sd} mm over {worlds} worlds");
}

/// An all-zero `[learned]` table, and a twin scaled by 0, give the results of the arm without the
/// table bit for bit (the learned effects draw after every draw of the scenario's own).
#[test]
fn an_all_zero_learned_table_or_a_zero_scale_changes_nothing() {
    let tmp = scratch("twin-zero");
    let dir = tmp.path();
    arm(dir, "zero.toml", ZERO);
    arm(dir, "twin.toml", LEARNED);
    arm(dir, "plain.toml", "");
    let plain = load(&scenario(dir, "plain.toml", "plain.toml", |t| t));
    let zero = load(&scenario(dir, "zero.toml", "zero.toml", |t| t));
    let no_rp = |t: String| t.replace("repeatability_mm = 0.010 ", "learned_scale = 0.0 # ");
    let scaled = load(&scenario(dir, "scaled.toml", "twin.toml", no_rp));
    assert_eq!(scaled.experiment.robot.repeatability_mm, 0.012, "the scale leaves the twin's repeatability");
    // The twin's repeatability set as the scenario's: then only the scale differs from `plain`.
    let scaled = load(&scenario(dir, "scaled_rp.toml", "twin.toml", |t| t.replace("[robot]\n", "[robot]\nlearned_scale = 0.0\n")));
    assert_eq!(scaled.experiment.robot.learned_scale, 0.0);
    let bits = |w: Vec<(f64, f64)>| w.into_iter().map(|(a, b)| (a.to_bits(), b.to_bits())).collect::<Vec<_>>();
    let reference = bits(common::trical_worlds(&plain, 2));
    assert_eq!(bits(common::trical_worlds(&zero, 2)), reference, "an all-zero table");
    assert_eq!(bits(common::trical_worlds(&scaled, 2)), reference, "a twin scaled by 0");
    let (a, b) = (plain.experiment.build(7).unwrap(), zero.experiment.build(7).unwrap());
    let measured =
        |e: &calsim::device::trical::experiment::Experiment| e.campaign.validation.iter().map(|v| v.measured_w).collect::<Vec<_>>();
    assert_eq!(measured(&a), measured(&b), "the validation measurements");
    // A twin with effects draws them after the scenario's own: the harmonics of [robot.unmodelled]
    // and the repeatability's joint noise are those of the arm without the table.
    let twin = load(&scenario(dir, "twin.toml", "twin.toml", |t| t)).experiment.build(7).unwrap();
    assert_eq!((&twin.robot.harmonics, twin.robot.sigma_q), (&a.robot.harmonics, a.robot.sigma_q));
    assert!(twin.robot.learned.is_some() && a.robot.learned.is_none() && b.robot.learned.is_none());
}

#[test]
fn bad_learned_values_through_a_scenario_are_one_line_naming_the_robot_file_and_the_key() {
    let tmp = scratch("twin-bad");
    let dir = tmp.path();
    let cases = [
        ("backlash.toml", LEARNED.replace("backlash_mdeg = [0.0, 8.0", "backlash_mdeg = [0.0, -8.0"), "learned.backlash_mdeg[1]"),
        ("joint.toml", LEARNED.replace("joint = 3", "joint = 0"), "learned.harmonic[1].joint"),
        ("nan.toml", LEARNED.replace("pose_error_mdeg = 4.0", "pose_error_mdeg = nan"), "learned.pose_error_mdeg"),
        ("huge.toml", LEARNED.replace("sin_mdeg = 12.0", "sin_mdeg = 1e300"), "learned.harmonic[0].sin_mdeg"),
        ("unknown.toml", LEARNED.replace("pose_error_mdeg = 4.0", "pose_error_mdeg = 4.0\nwobble = 1.0"), "wobble"),
        ("rp.toml", LEARNED.replace("repeatability_mm = 0.012", "repeatability_mm = 5.0"), "learned.repeatability_mm"),
    ];
    for (name, table, key) in &cases {
        let a = arm(dir, name, table);
        let s = scenario(dir, &format!("s-{name}"), name, |t| t.replace("repeatability_mm = 0.010 ", "# "));
        // The robot file as the scenario names it, from the scenario's directory.
        let named = format!("arms/{}", a.file_name().unwrap().to_string_lossy());
        let shown = [s.display().to_string(), named];
        let parts = [shown[0].as_str(), shown[1].as_str(), "robot.file", key];
        refused(dir, &["run", s.to_str().unwrap(), "--no-plots", "--no-recording", "--out", "out"], &parts);
        refused(dir, &["budget", s.to_str().unwrap(), "--realisations", "1", "--out", "out"], &parts[1..]);
    }
    let sweep = dir.join("studies/sweep.toml");
    std::fs::write(&sweep, "base = \"s-backlash.toml\"\nrealisations = 1\n\n[[axis]]\nkey = \"seed\"\nvalues = [1, 2]\n").unwrap();
    refused(dir, &["sweep", sweep.to_str().unwrap(), "--out", "out"], &["backlash.toml", "learned.backlash_mdeg[1]"]);
    assert!(!dir.join("out").exists(), "nothing written");
    // A scale without a twin to scale.
    arm(dir, "plain.toml", "");
    let s = scenario(dir, "scale.toml", "plain.toml", |t| t.replace("[robot]\n", "[robot]\nlearned_scale = 0.5\n"));
    refused(dir, &["run", s.to_str().unwrap(), "--out", "out"], &[&s.display().to_string(), "robot.learned_scale", "[learned]"]);
    arm(dir, "twin.toml", LEARNED);
    let s = scenario(dir, "scale-negative.toml", "twin.toml", |t| t.replace("[robot]\n", "[robot]\nlearned_scale = -1.0\n"));
    refused(dir, &["run", s.to_str().unwrap(), "--out", "out"], &[&s.display().to_string(), "[robot] learned_scale = -1"]);
}

/// An SPMS scenario takes a twin the same way: its learned effects and repeatability reach the
/// robot the cell builds.
#[test]
fn an_spms_scenario_takes_a_twin() {
    let tmp = scratch("twin-spms");
    let dir = tmp.path();
    let text = std::fs::read_to_string(repo().join("robots/er20c10.toml")).unwrap() + LEARNED;
    std::fs::create_dir_all(dir.join("arms")).unwrap();
    std::fs::write(dir.join("arms/twin.toml"), text).unwrap();
    let base = std::fs::read_to_string(repo().join("scenarios/er20c10_spms.toml")).unwrap();
    assert!(base.contains("file = \"../robots/er20c10.toml\"") && base.contains("repeatability_mm = 0.05 "));
    std::fs::create_dir_all(dir.join("studies")).unwrap();
    let p = dir.join("studies/s.toml");
    std::fs::write(
        &p,
        base.replace("file = \"../robots/er20c10.toml\"", "file = \"../arms/twin.toml\"").replace("repeatability_mm = 0.05 ", "# "),
    )
    .unwrap();
    let s = calsim::device::spms::spec::load(&p).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(s.spec.robot.repeatability_mm, 0.012);
    let learned = s.spec.robot.learned.as_ref().expect("the twin's effects");
    assert_eq!((learned.backlash_mdeg[1], learned.harmonic.len(), learned.repeatability_mm), (8.0, 2, 0.0));
}

/// The shipped example: scenarios/irb120_twin.toml names robots/examples/irb120_twin.toml, the
/// shipped IRB 120 robot file with a `[learned]` table; its worlds draw the twin's effects and
/// repeatability.
#[test]
fn the_shipped_example_twin_is_the_shipped_arm_with_its_learned_table() {
    let twin = calsim::robot::file::RobotFile::load(&repo().join("robots/examples/irb120_twin.toml")).unwrap();
    let arm = calsim::robot::file::RobotFile::load(&repo().join("robots/irb120.toml")).unwrap();
    assert_eq!((format!("{:?}", twin.nominal), format!("{:?}", twin.truth)), (format!("{:?}", arm.nominal), format!("{:?}", arm.truth)));
    let learned = twin.learned.as_ref().expect("a [learned] table");
    let s = load(&repo().join("scenarios/irb120_twin.toml"));
    assert_eq!(s.experiment.robot.repeatability_mm, learned.repeatability_mm, "the twin's repeatability");
    assert!(s.experiment.robot.unmodelled == calsim::robot::UnmodelledSpec::default(), "no invented effects beside the twin's");
    let world = s.experiment.build(s.header.seed).unwrap();
    assert!(world.robot.learned.is_some() && world.robot_validation.learned.is_some());
}
