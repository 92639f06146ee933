//! Hardening: nothing a user gives calsim crashes it, hangs it,
//! overwrites their files or is silently accepted. One test per class of bad input, each through
//! the binary: exit code 2 (1 for `compensate` with some targets out of reach), one line on
//! standard error naming the file (and key), nothing written, no temporary directory left.
//! The full disk is kept by the kit's own tests (`io::out_dir`, `io::record`: /dev/full).

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::{Duration, Instant};

use common::{calsim, repo, scratch};

/// Longest any refused input may take to be answered: a hang (a FIFO read, a minute-long parse)
/// fails here instead of blocking the suite.
const BOUND: Duration = Duration::from_secs(120);

/// Runs calsim with `args` from `cwd`, killing it after [`BOUND`]; the exit code and stderr.
fn run_in(cwd: &Path, args: &[&str]) -> (Option<i32>, String) {
    let t = Instant::now();
    let mut child = calsim().current_dir(cwd).args(args).stdout(Stdio::null()).stderr(Stdio::piped()).spawn().unwrap();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if t.elapsed() > BOUND {
            let _ = child.kill();
            panic!("{args:?}: no answer within {BOUND:?}");
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    let mut err = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut err).unwrap();
    (status.code(), err)
}

/// Asserts the refusal of `args` (run from `cwd`): exit 2, one error line (after, at most, the
/// command's start line `calsim <command>: ...`), holding every one of `parts`; the error line.
fn refused(cwd: &Path, args: &[&str], parts: &[&str]) -> String {
    let (code, err) = run_in(cwd, args);
    assert_eq!(code, Some(2), "{args:?}: {err}");
    let lines: Vec<&str> = err.trim_end().lines().collect();
    let (errors, others): (Vec<&str>, Vec<&str>) = lines.iter().partition(|l| l.starts_with("error: "));
    assert_eq!(errors.len(), 1, "{args:?}: one error line: {err}");
    assert!(others.len() <= 1 && others.iter().all(|l| l.starts_with("calsim ")), "{args:?}: nothing but the start line: {err}");
    for part in parts {
        assert!(errors[0].contains(part), "{args:?}: `{part}` not in {err}");
    }
    errors[0].to_string()
}

/// Every file under `dir` with its bytes (empty when `dir` is absent).
fn snapshot(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else { continue };
        for e in entries {
            let p = e.unwrap().path();
            if p.is_dir() {
                out.insert(p.clone(), Vec::new());
                stack.push(p);
            } else {
                out.insert(p.clone(), std::fs::read(&p).unwrap_or_default());
            }
        }
    }
    out
}

/// The reduced CI scenario (one set size, one repetition) with its robot file named absolutely.
fn small_scenario() -> String {
    common::scenario_text_anywhere("ci_quick.toml")
        .replace("set_sizes = [20, 50, 75, 100]", "set_sizes = [20]")
        .replace("repetitions = 10 ", "repetitions = 1 ")
        .replace("table_set_size = 75 ", "table_set_size = 20 ")
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Every command's one-line error starts `error: `: calsim's (each refusal above) and the
/// examples' the docs run (`cargo run --example ...`). An example's `main` returning a `Result`
/// would print Rust's `Error: "..."` instead, so none does: it ends through
/// `calsim::app::message::exit_code` (an error: its `error: ` line, exit 2) or exits 2 itself
/// after an `error: ` line. Every exit 2, in the examples and in `exit_code`, follows an
/// `error: ` line.
#[test]
fn every_commands_error_line_starts_the_same_way() {
    let mut files: Vec<PathBuf> = std::fs::read_dir(repo().join("examples"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "rs"))
        .collect();
    files.push(repo().join("src/app/message.rs"));
    let (mut exits, mut through_exit_code) = (0, 0);
    for path in &files {
        let text = std::fs::read_to_string(path).unwrap();
        let text = text.split("\n#[cfg(test)]").next().unwrap_or_default();
        assert!(!text.contains("fn main() -> Result"), "{}: main returns a Result (`Error: ...`)", path.display());
        through_exit_code += usize::from(text.contains("calsim::app::message::exit_code("));
        let lines: Vec<&str> = text.lines().collect();
        for (k, line) in lines.iter().enumerate() {
            if line.contains("exit(2)") || line.contains("ExitCode::from(2)") {
                let before = &lines[k.saturating_sub(3)..k];
                assert!(
                    before.iter().any(|l| l.contains("eprintln!(\"error: ")),
                    "{}:{}: exit 2 without an `error: ` line before it",
                    path.display(),
                    k + 1
                );
                exits += 1;
            }
        }
    }
    assert!(exits >= 3, "exit_code's and the examples' own exits 2: {exits}");
    assert!(through_exit_code >= 4, "the examples that end through message::exit_code: {through_exit_code}");
    let (code, err) = run_in(&repo(), &["run", "no-such-scenario.toml"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.starts_with("error: no-such-scenario.toml: "), "{err}");
}

#[test]
fn inputs_nested_without_bound_are_refused_in_one_line_before_any_parser_recurses() {
    let tmp = scratch("deep");
    let dir = tmp.path();
    std::fs::write(dir.join("base.toml"), small_scenario()).unwrap();
    for n in [10_000, 200_000] {
        let urdf = dir.join(format!("deep{n}.urdf"));
        std::fs::write(&urdf, format!("<?xml version=\"1.0\"?>\n<robot name=\"r\">\n{}{}</robot>\n", "<x>".repeat(n), "</x>".repeat(n)))
            .unwrap();
        refused(dir, &["import-urdf", s(&urdf), "--out", s(&dir.join("arm.toml"))], &[&format!("deep{n}.urdf"), "line 3", "nested"]);
    }
    // A COLLADA mesh of the arm, nested 100,000 deep.
    let kr6 = std::fs::read_to_string(repo().join("robots/kr6r900sixx.urdf")).unwrap();
    let mesh = "<link name=\"flange\"><collision><geometry><mesh filename=\"deep.dae\"/></geometry></collision></link>";
    std::fs::write(dir.join("meshed.urdf"), kr6.replace("<link name=\"flange\"/>", mesh)).unwrap();
    let n = 100_000;
    std::fs::write(
        dir.join("deep.dae"),
        format!("<?xml version=\"1.0\"?>\n<COLLADA>{}{}</COLLADA>\n", "<node>".repeat(n), "</node>".repeat(n)),
    )
    .unwrap();
    refused(dir, &["import-urdf", "meshed.urdf", "--out", "arm.toml"], &["meshed.urdf", "flange", "deep.dae", "nested"]);
    assert!(!dir.join("arm.toml").exists());
    // Dotted keys of 100,000 parts: in a sweep axis, in [fixed], in a scenario and a robot file.
    let key = vec!["a"; 100_000].join(".");
    std::fs::write(dir.join("axis.toml"), format!("base = \"base.toml\"\n[[axis]]\nkey = \"{key}\"\nvalues = [1]\n")).unwrap();
    std::fs::write(dir.join("fixed.toml"), format!("base = \"base.toml\"\n[fixed]\n\"{key}\" = 1\n")).unwrap();
    for f in ["axis.toml", "fixed.toml"] {
        let err = refused(dir, &["sweep", f, "--out", "out"], &[f, "dotted parts"]);
        assert!(err.len() < 1000, "the key is shortened in the line: {} characters", err.len());
    }
    std::fs::write(dir.join("dotted.toml"), format!("seed = 1\n{key} = 1\n")).unwrap();
    refused(dir, &["run", "dotted.toml", "--out", "out"], &["dotted.toml"]);
    let arm = std::fs::read_to_string(repo().join("robots/irb120.toml")).unwrap();
    std::fs::write(dir.join("deep_arm.toml"), format!("{arm}\nx = {}{}\n", "[".repeat(100_000), "]".repeat(100_000))).unwrap();
    std::fs::write(dir.join("joints.csv"), "q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n0,0,0,0,0,0\n").unwrap();
    refused(dir, &["fk", "deep_arm.toml", "joints.csv"], &["deep_arm.toml"]);
    assert!(!dir.join("out").exists(), "nothing ran");
}

/// The text of the repository's file `rel` with every path it names relative to itself (`"../`)
/// made absolute, so that a copy written elsewhere still finds them.
fn text_anywhere(rel: &str) -> String {
    let path = repo().join(rel);
    let text = std::fs::read_to_string(&path).unwrap();
    text.replace("\"../", &format!("\"{}/../", path.parent().unwrap().display()))
}

/// An array of a fixed length (a point's three coordinates, a range's two ends) given more values
/// is refused, not read as its first ones, and given fewer too: in every kind of TOML file calsim
/// reads, the one line naming the file, the key, the count written and the count the key takes.
#[test]
fn an_array_longer_or_shorter_than_its_key_takes_is_refused_in_every_kind_of_file() {
    let tmp = scratch("array-lengths");
    let dir = tmp.path();
    let scenario = small_scenario();
    std::fs::write(dir.join("base.toml"), &scenario).unwrap();
    std::fs::write(dir.join("joints.csv"), "q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n0,0,0,0,0,0\n").unwrap();
    let sweep = "base = \"base.toml\"\n[[axis]]\nkey = \"robot.tcp_mm\"\nvalues = [[35.0, 0.0, 125.0]]\n";
    // (kind, file text, the array as written, its first values, command, key named, length taken)
    let cases = [
        ("scenario", scenario.clone(), "tcp_mm = [35.0, 0.0, 125.0]", "tcp_mm = [35.0, 0.0", "run", "robot.tcp_mm", 3),
        ("sweep", sweep.to_string(), "[[35.0, 0.0, 125.0]]", "[[35.0, 0.0", "sweep", "robot.tcp_mm", 3),
        ("robot", text_anywhere("robots/irb120.toml"), "com_mm = [101.24, 0.78, -2.12]", "com_mm = [101.24, 0.78", "fk", "com_mm", 3),
        (
            "twin",
            text_anywhere("robots/examples/irb120_twin.toml"),
            "backlash_mdeg = [0.0, 4.0, 3.0, 0.0, 0.0, 0.0]",
            "backlash_mdeg = [0.0, 4.0, 3.0, 0.0, 0.0",
            "fk",
            "backlash_mdeg",
            6,
        ),
        (
            "design",
            text_anywhere("scenarios/designs/irb120_spheres.toml"),
            "x_mm = [-150.0, 450.0]",
            "x_mm = [-150.0",
            "optimise",
            "points.x_mm",
            2,
        ),
        (
            "tracker plan",
            text_anywhere("scenarios/plans/irb120_tracker.toml"),
            "position_mm = [1800.0, 0.0, 300.0]",
            "position_mm = [1800.0, 0.0",
            "plan",
            "position_mm",
            3,
        ),
        (
            "device plan",
            text_anywhere("scenarios/plans/irb120_trical.toml"),
            "workspace_min_mm = [200.0, -250.0, 250.0]",
            "workspace_min_mm = [200.0, -250.0",
            "plan",
            "workspace_min_mm",
            3,
        ),
        (
            "device plan",
            text_anywhere("scenarios/plans/irb120_trical.toml"),
            "[150.0, 259.8076, 0.0]]",
            "[150.0, 259.8076",
            "plan",
            "spheres_w_mm",
            3,
        ),
        (
            "simulation",
            text_anywhere("docs/calibrate/probe_example.toml"),
            "flange_mm = [20.0, -10.0, 60.0]",
            "flange_mm = [20.0, -10.0",
            "simulate-measurements",
            "flange_mm",
            3,
        ),
    ];
    for (k, (kind, text, array, first, command, key, n)) in cases.into_iter().enumerate() {
        let close = if array.ends_with("]]") { "]]" } else { "]" };
        for (name, written, count) in
            [("long", format!("{}, 7.0{close}", &array[..array.len() - close.len()]), n + 1), ("short", format!("{first}{close}"), n - 1)]
        {
            let changed = text.replacen(array, &written, 1);
            assert_ne!(changed, text, "{kind}: `{array}` is in the shipped file");
            let file = format!("{name}{k}.toml");
            std::fs::write(dir.join(&file), changed).unwrap();
            let mut args = vec![command, &file];
            args.extend(if command == "fk" { ["joints.csv"].as_slice() } else { ["--out", "out"].as_slice() });
            let length = format!("invalid length {count}, expected an array of length {n}");
            refused(dir, &args, &[&file, key, &length]);
        }
    }
    assert!(!dir.join("out").exists(), "nothing ran");
}

#[test]
fn names_that_are_not_one_path_component_are_refused_before_any_work() {
    let tmp = scratch("names");
    let dir = tmp.path();
    let scenario = small_scenario();
    for (file, name) in [("..toml", "\".\""), ("...toml", "\"..\""), ("a\nb.toml", "\"a\\nb\""), ("a\u{1b}b.toml", "\"a\\u{1b}b\"")] {
        std::fs::write(dir.join(file), &scenario).unwrap();
        for command in ["run", "budget"] {
            refused(dir, &[command, file, "--out", "out"], &[name, "cannot name results"]);
        }
    }
    std::fs::write(dir.join("...toml"), "base = \"..toml\"\n[[axis]]\nkey = \"seed\"\nvalues = [1]\n").unwrap();
    refused(dir, &["sweep", "...toml", "--out", "out"], &["...toml", "\"..\""]);
    std::fs::copy(repo().join("docs/calibrate/example_measurements.csv"), dir.join("..csv")).unwrap();
    refused(dir, &["calibrate", s(&repo().join("robots/irb120.toml")), "..csv", "--out", "out"], &["..csv", "\".\""]);
    assert!(!dir.join("out").exists(), "no results directory, no temporary directory");
    assert!(std::fs::read_dir(dir).unwrap().all(|e| !e.unwrap().file_name().to_string_lossy().contains(".tmp-")));
}

#[test]
fn outputs_are_never_an_input_a_device_a_pipe_or_inside_other_results() {
    let tmp = scratch("outputs");
    let dir = tmp.path();
    let urdf = dir.join("X.urdf");
    std::fs::copy(repo().join("robots/kr6r900sixx.urdf"), &urdf).unwrap();
    let before = std::fs::read(&urdf).unwrap();
    refused(dir, &["import-urdf", "X.urdf", "--out", "X.urdf"], &["X.urdf", "is the input"]);
    std::fs::create_dir(dir.join("sub")).unwrap();
    refused(dir, &["import-urdf", "X.urdf", "--out", "./sub/../X.urdf"], &["is the input"]);
    assert_eq!(std::fs::read(&urdf).unwrap(), before, "the URDF is left as it was");
    refused(dir, &["import-urdf", "X.urdf", "--out", "/dev/null"], &["/dev/null", "is a device"]);
    assert!(std::os::unix::fs::FileTypeExt::is_char_device(&std::fs::metadata("/dev/null").unwrap().file_type()));
    let fifo = dir.join("fifo.csv");
    assert!(std::process::Command::new("mkfifo").arg(&fifo).status().unwrap().success());
    let targets = dir.join("t.csv");
    std::fs::write(&targets, "x_mm,y_mm,z_mm,alpha_deg,beta_deg,gamma_deg\n300,0,400,0,180,0\n").unwrap();
    let irb120 = repo().join("robots/irb120.toml");
    refused(dir, &["compensate", s(&irb120), "t.csv", "--out", "fifo.csv"], &["fifo.csv", "pipe"]);
    refused(dir, &["compensate", s(&irb120), "t.csv", "--out", "t.csv"], &["t.csv", "is the input"]);
    refused(dir, &["fk", s(&irb120), "t.csv", "--out", s(&irb120)], &["irb120.toml", "is the input"]);

    // The results of a run: nothing of calsim's goes inside them.
    std::fs::write(dir.join("small.toml"), small_scenario()).unwrap();
    let (code, err) = run_in(dir, &["run", "small.toml", "--out", "res", "--no-plots", "--no-recording"]);
    assert_eq!(code, Some(0), "{err}");
    let results = dir.join("res/small");
    let kept = snapshot(&results);
    std::fs::write(dir.join("joints.csv"), "q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n0,0,0,0,0,0\n").unwrap();
    let measurements = repo().join("docs/calibrate/example_measurements.csv");
    for args in [
        vec!["run", "small.toml", "--out", "res/small"],
        vec!["run", "small.toml", "--out", "res/small/deeper"],
        vec!["export", "res/small", "--out", "res/small"],
        vec!["fk", s(&irb120), "joints.csv", "--out", "res/small/fk.csv"],
        vec!["compensate", s(&irb120), "t.csv", "--out", "res/small/joints.csv"],
        vec!["import-urdf", "X.urdf", "--out", "res/small/arm.toml"],
        vec!["calibrate", s(&irb120), s(&measurements), "--out", "res/small"],
    ] {
        refused(dir, &args, &["res/small", "manifest.json"]);
    }
    assert_eq!(snapshot(&results), kept, "the results are left as they were");
}

#[test]
fn values_that_only_make_sense_together_are_checked_together_naming_every_key() {
    let tmp = scratch("plausible");
    let dir = tmp.path();
    let scenario = small_scenario();
    for (file, from, to, keys) in [
        ("eps_low.toml", "epsilon_mm = 0.010", "epsilon_mm = 0.0005", ["epsilon_mm", "indicator_resolution_um"]),
        ("eps_high.toml", "indicator_range_mm = 12.7", "indicator_range_mm = 0.5\nepsilon_mm = 0.4", ["epsilon_mm", "indicator_range_mm"]),
        ("jog.toml", "jog_error_mm = 0.5", "jog_error_mm = 4.5", ["jog_error_mm", "indicator_range_mm"]),
    ] {
        let text = scenario.replacen(from, to, 1);
        let text = match file {
            "eps_high.toml" => text.replacen("epsilon_mm = 0.010", "", 1),
            "jog.toml" => text.replacen("indicator_range_mm = 12.7", "indicator_range_mm = 8.0", 1),
            _ => text,
        };
        assert_ne!(text, scenario);
        std::fs::write(dir.join(file), text).unwrap();
        refused(dir, &["run", file, "--out", "out"], &[file, keys[0], keys[1]]);
    }
    // Robot files: a 10-tonne link, a centre of mass 100 m out, a compliance that bends a joint.
    let arm = std::fs::read_to_string(repo().join("robots/irb120.toml")).unwrap();
    std::fs::write(dir.join("joints.csv"), "q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n0,0,0,0,0,0\n").unwrap();
    for (file, from, to, keys) in [
        ("heavy.toml", "mass_kg = 3.909", "mass_kg = 10000.0", vec!["joint[2].mass_kg", "a_mm", "d_mm"]),
        ("far.toml", "com_mm = [101.24, 0.78, -2.12]", "com_mm = [100000.0, 0.78, -2.12]", vec!["joint[2].com_mm", "a_mm"]),
        ("bent.toml", "mass_kg = 3.909", "mass_kg = 3000.0", vec!["truth.c2", "mass_kg", "com_mm"]),
    ] {
        std::fs::write(dir.join(file), arm.replacen(from, to, 1)).unwrap();
        let mut parts = vec![file];
        parts.extend(keys);
        refused(dir, &["fk", file, "joints.csv"], &parts);
    }
    // URDFs: names given twice, a detached cycle, an undefined child.
    let urdf = std::fs::read_to_string(repo().join("robots/kr6r900sixx.urdf")).unwrap();
    let flange = "  <link name=\"flange\"/>";
    let boxed =
        |name: &str| format!("  <link name=\"{name}\"><collision><geometry><box size=\"0.1 0.1 0.1\"/></geometry></collision></link>\n");
    let cycle = format!(
        "{}  <link name=\"g2\"/>\n  <joint name=\"j1\" type=\"fixed\"><parent link=\"g1\"/><child link=\"g2\"/></joint>\n  <joint name=\"j2\" type=\"fixed\"><parent link=\"g2\"/><child link=\"g1\"/></joint>\n",
        boxed("g1")
    );
    for (file, text, parts) in [
        ("duplink.urdf", urdf.replace(flange, &format!("{}{flange}", boxed("link_3"))), vec!["two links", "link_3"]),
        ("dupjoint.urdf", urdf.replace("<joint name=\"flange-tool0\"", "<joint name=\"joint_a2\""), vec!["two joints", "joint_a2"]),
        ("cycle.urdf", urdf.replace(flange, &format!("{cycle}{flange}")), vec!["`g1`", "`g2`", "not connected", "base_link"]),
        ("nochild.urdf", urdf.replace("<child link=\"tool0\"/>", "<child link=\"tool9\"/>"), vec!["flange-tool0", "tool9", "not defined"]),
    ] {
        std::fs::write(dir.join(file), text).unwrap();
        let mut all = vec![file];
        all.extend(parts);
        refused(dir, &["import-urdf", file, "--out", "arm.toml"], &all);
    }
    assert!(!dir.join("arm.toml").exists());

    // compensate: every target out of reach is an error and writes nothing; some out of reach
    // give rows of `unreachable` and exit 1; the nominal model of another arm is refused.
    let irb120 = repo().join("robots/irb120.toml");
    std::fs::write(dir.join("far.csv"), "x_mm,y_mm,z_mm,alpha_deg,beta_deg,gamma_deg\n90000,0,400,0,180,0\n0,90000,400,0,180,0\n").unwrap();
    refused(dir, &["compensate", s(&irb120), "far.csv", "--out", "out.csv"], &["far.csv", "none of the 2 targets", "irb120.toml"]);
    assert!(!dir.join("out.csv").exists());
    std::fs::write(dir.join("half.csv"), "x_mm,y_mm,z_mm,alpha_deg,beta_deg,gamma_deg\n90000,0,400,0,180,0\n400,0,400,0,180,0\n").unwrap();
    let (code, err) = run_in(dir, &["compensate", s(&irb120), "half.csv", "--out", "out.csv"]);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("1 of 2 targets cannot be reached") && err.contains("targets 1;"), "{err}");
    let rows: Vec<String> = std::fs::read_to_string(dir.join("out.csv")).unwrap().lines().map(str::to_string).collect();
    assert!(rows[1].starts_with("unreachable,") && !rows[2].starts_with("unreachable"), "{rows:?}");
    let kr6 = repo().join("robots/kr6r900sixx.toml");
    refused(dir, &["compensate", s(&irb120), "half.csv", "--nominal", s(&kr6)], &["--nominal", "kr6r900sixx.toml", "irb120.toml", "d_mm"]);
}

#[test]
fn late_failures_come_early_and_in_calsims_words() {
    let tmp = scratch("late");
    let dir = tmp.path();
    std::fs::write(dir.join("base.toml"), small_scenario()).unwrap();
    std::fs::write(dir.join("th.toml"), "base = \"base.toml\"\nthresholds_mm = [0.5, 0.5]\n[[axis]]\nkey = \"seed\"\nvalues = [1]\n")
        .unwrap();
    refused(dir, &["sweep", "th.toml", "--out", "out"], &["th.toml", "thresholds_mm", "twice"]);
    std::fs::write(
        dir.join("axes.toml"),
        "base = \"base.toml\"\n[[axis]]\nkey = \"seed\"\nvalues = [1]\n[[axis]]\nkey = \"seed\"\nvalues = [2]\n",
    )
    .unwrap();
    refused(dir, &["sweep", "axes.toml", "--out", "out"], &["axes.toml", "axis[1] (seed)"]);
    assert!(!dir.join("out").exists(), "refused before the run: no shard directory");
    // A sweep.json cut short, found by a re-run: the error names it.
    std::fs::write(dir.join("ok.toml"), "base = \"base.toml\"\n[[axis]]\nkey = \"seed\"\nvalues = [1, 2]\n").unwrap();
    let (code, err) = run_in(dir, &["sweep", "ok.toml", "--out", "out", "--shard", "0/2"]);
    assert_eq!(code, Some(0), "{err}");
    let info = dir.join("out/ok.shard-0-of-2/sweep.json");
    let text = std::fs::read(&info).unwrap();
    std::fs::write(&info, &text[..text.len() / 2]).unwrap();
    refused(dir, &["sweep", "ok.toml", "--out", "out", "--shard", "0/2"], &["ok.shard-0-of-2/sweep.json"]);
    // A line break in a directory of the path: the error stays one line.
    let odd = dir.join("odd\ndir");
    std::fs::create_dir(&odd).unwrap();
    std::fs::write(odd.join("bad.toml"), "seed = [").unwrap();
    refused(dir, &["run", s(&odd.join("bad.toml")), "--out", "out"], &["odd\\ndir/bad.toml"]);
}

#[test]
fn a_pipe_given_as_an_input_is_refused_not_waited_on() {
    let tmp = scratch("fifo");
    let dir = tmp.path();
    std::fs::write(dir.join("small.toml"), small_scenario()).unwrap();
    let (code, err) = run_in(dir, &["run", "small.toml", "--out", "res", "--no-plots", "--no-recording"]);
    assert_eq!(code, Some(0), "{err}");
    let tasks = dir.join("res/small/tasks.parquet");
    std::fs::remove_file(&tasks).unwrap();
    let fifo = |p: &Path| assert!(std::process::Command::new("mkfifo").arg(p).status().unwrap().success());
    fifo(&tasks);
    refused(dir, &["export", "res/small", "--out", "exported"], &["tasks.parquet", "not a regular file"]);
    let pipe = dir.join("pipe");
    fifo(&pipe);
    let irb120 = repo().join("robots/irb120.toml");
    let measurements = repo().join("docs/calibrate/example_measurements.csv");
    for args in [
        vec!["run", "pipe", "--out", "out"],
        vec!["fk", s(&irb120), "pipe"],
        vec!["fk", "pipe", s(&measurements)],
        vec!["compensate", s(&irb120), "pipe"],
        vec!["import-urdf", "pipe", "--out", "arm.toml"],
        vec!["calibrate", s(&irb120), "pipe", "--out", "out"],
        vec!["sweep", "pipe", "--out", "out"],
    ] {
        refused(dir, &args, &["pipe", "not a regular file"]);
    }
}

/// a study run with `--set-sizes` and `--repetitions` from one directory is
/// exported from another; the manifest's absolute scenario path and overrides redo the same
/// identification, and the exported model is the one recomputed here from the scenario with those
/// overrides (TCP to 1e-9 mm at 1,000 configurations); both exports are byte for byte the same.
#[test]
fn a_run_with_overrides_exports_from_another_directory_as_the_same_model() {
    let tmp = scratch("export-overrides");
    let dir = tmp.path();
    let (here, elsewhere) = (dir.join("here"), dir.join("elsewhere"));
    std::fs::create_dir_all(&here).unwrap();
    std::fs::create_dir_all(&elsewhere).unwrap();
    std::fs::write(here.join("study.toml"), common::scenario_text_anywhere("ci_quick.toml")).unwrap();
    let args = [
        "run",
        "study.toml",
        "--set-sizes",
        "30:40:10",
        "--repetitions",
        "2",
        "--seed",
        "7",
        "--out",
        "res",
        "--no-plots",
        "--no-recording",
    ];
    let (code, err) = run_in(&here, &args);
    assert_eq!(code, Some(0), "{err}");
    let results = here.join("res/study");
    let (code, err) = run_in(&elsewhere, &["export", s(&results), "--out", "exported"]);
    assert_eq!(code, Some(0), "export from another directory: {err}");
    let (code, err) = run_in(&here, &["export", "res/study", "--out", "exported"]);
    assert_eq!(code, Some(0), "{err}");
    let task_dir = |root: &Path| std::fs::read_dir(root.join("exported")).unwrap().map(|e| e.unwrap().path()).find(|p| p.is_dir()).unwrap();
    let (a, b) = (task_dir(&elsewhere), task_dir(&here));
    assert_eq!(a.file_name(), b.file_name());
    for f in ["robot.toml", "before.toml", "robot.urdf", "calibration.yaml"] {
        assert_eq!(std::fs::read(a.join(f)).unwrap(), std::fs::read(b.join(f)).unwrap(), "{f}");
    }
    // The model recomputed from the scenario with the same overrides.
    let task: usize = a.to_str().unwrap().rsplit("task-").next().unwrap().parse().unwrap();
    let overrides = calsim::app::run::Overrides { seed: Some(7), set_sizes: Some(vec![30, 40]), repetitions: Some(2) };
    let s = calsim::app::run::load(&here.join("study.toml"), &overrides).unwrap();
    let model = s.refit(task).unwrap().expect("the task exists").model.expect("a model");
    let file = calsim::robot::file::RobotFile::load(&a.join("robot.toml")).unwrap();
    let worst = common::largest_tcp_difference(&model, &file.nominal, &model, &mut common::rng(34));
    assert!(worst < 1e-9, "largest TCP difference {worst:e} mm");
    // Without the overrides the same task is another identification (the override matters).
    let plain = calsim::app::run::load(&here.join("study.toml"), &Default::default()).unwrap();
    let other = plain.refit(task).unwrap().and_then(|r| r.model);
    let differs = other.is_none_or(|m| common::largest_tcp_difference(&m, &file.nominal, &m, &mut common::rng(34)) > 1e-6);
    assert!(differs, "the overrides change the identification of task {task}");
}

/// A sweep of 2 points x 2 realisations run whole as shard 0 of 1 under `dir/out` (thresholds 0.5
/// mm): its shard directory.
fn one_shard(dir: &Path) -> PathBuf {
    std::fs::write(dir.join("base.toml"), small_scenario()).unwrap();
    std::fs::write(
        dir.join("m.toml"),
        "base = \"base.toml\"\nrealisations = 2\nthresholds_mm = [0.5]\n[[axis]]\nkey = \"seed\"\nvalues = [1, 2]\n",
    )
    .unwrap();
    let (code, err) = run_in(dir, &["sweep", "m.toml", "--out", "out", "--shard", "0/1"]);
    assert_eq!(code, Some(0), "{err}");
    dir.join("out/m.shard-0-of-1")
}

/// `merge` holds a shard's record (`sweep.json`) against itself, against the
/// bounds the sweep loader allows and against its units before it allocates or sums anything: each
/// edit below is one line naming the file and the key, exit 2, nothing merged; the record put back,
/// the shard merges.
#[test]
fn shard_records_are_checked_whole_against_themselves_and_their_units_before_a_merge() {
    let tmp = scratch("records");
    let dir = tmp.path();
    let shard = one_shard(dir);
    let info_path = shard.join("sweep.json");
    let good = std::fs::read_to_string(&info_path).unwrap();
    let info: serde_json::Value = serde_json::from_str(&good).unwrap();
    let edited = |edit: &dyn Fn(&mut serde_json::Value)| {
        let mut v = info.clone();
        edit(&mut v);
        v.to_string()
    };
    use serde_json::json;
    let merge = ["merge", "out/m.shard-0-of-1", "--out", "merged"];
    let cases: Vec<(String, Vec<&str>)> = vec![
        (edited(&|v| v["keys"] = json!(["seed", "x"])), vec!["points[0]", "2 keys"]),
        (edited(&|v| v["realisations"] = json!(4294967295u32)), vec!["realisations", "4294967295"]),
        (edited(&|v| v["realisations"] = json!(3)), vec!["m.shard-0-of-1/units/u000000", "not a unit of this sweep"]),
        (edited(&|v| v["thresholds_mm"] = json!([0.5, 0.5])), vec!["thresholds_mm", "twice"]),
        (edited(&|v| v["thresholds_mm"] = json!([0.5, 1e300])), vec!["thresholds_mm", "1e300"]),
        (edited(&|v| v["thresholds_mm"] = json!([null])), vec!["invalid type: null"]),
        (edited(&|v| v["points"] = json!([["1"]])), vec!["layouts", "1 grid points"]),
        (edited(&|v| v["points"] = json!([])), vec!["points", "0 grid points"]),
        (edited(&|v| v["changes"][1] = json!([{ "key": ["seed"], "value": "\"garbage\"" }])), vec!["scenario of grid point 1", "seed"]),
        (edited(&|v| v["changes"][1] = json!([{ "key": ["seed"], "value": "1\n[x]\ny = 2" }])), vec!["changes[1][0]", "one TOML value"]),
        (edited(&|v| v["scenario"] = json!("seed = [")), vec!["scenario", "not TOML"]),
        (edited(&|v| v["layouts"][0][1][0] = json!(301.0)), vec!["layouts[0]", "datum spheres"]),
        (edited(&|v| v["objective"]["confidence"] = json!(2.0)), vec!["objective.confidence"]),
        (edited(&|v| v["objective"]["threshold_mm"] = json!(0.7)), vec!["objective.threshold_mm", "0.7"]),
        (edited(&|v| v["race"] = json!({ "min": 1, "batch": 0, "max": 2, "confidence": 0.9 })), vec!["race.batch"]),
        (edited(&|v| v["race"] = json!({ "min": 1, "batch": 1, "max": 4000000, "confidence": 0.9 })), vec!["race.max"]),
        (edited(&|v| v["count"] = json!(1_000_000_000_000u64)), vec!["count"]),
        (edited(&|v| v["shard"] = json!(1)), vec!["shard", "count - 1"]),
        (edited(&|v| v["name"] = json!("")), vec!["name", "empty"]),
        (edited(&|v| v["name"] = json!("..")), vec!["name"]),
        (edited(&|v| v["identity"] = json!("x")), vec!["identity"]),
        (edited(&|v| v["extra"] = json!(1)), vec!["unknown field `extra`"]),
        (edited(&|v| drop(v.as_object_mut().unwrap().remove("objective"))), vec!["missing field `objective`"]),
        (good[..good.len() / 2].to_string(), vec!["EOF"]),
    ];
    for (text, parts) in &cases {
        std::fs::write(&info_path, text).unwrap();
        let mut all = if parts[0].contains("/units/") { vec![] } else { vec!["m.shard-0-of-1/sweep.json"] };
        all.extend(parts.iter().copied());
        refused(dir, &merge, &all);
        assert!(!dir.join("merged").exists(), "nothing merged for {parts:?}");
    }
    std::fs::write(&info_path, &good).unwrap();

    // The units against what their points' studies promise.
    let unit_path = shard.join("units/u0000001.json");
    let unit_text = std::fs::read_to_string(&unit_path).unwrap();
    let unit: serde_json::Value = serde_json::from_str(&unit_text).unwrap();
    let edited = |edit: &dyn Fn(&mut serde_json::Value)| {
        let mut v = unit.clone();
        edit(&mut v);
        v.to_string()
    };
    for (text, parts) in [
        (edited(&|u| u["rows"] = json!([])), vec!["rows", "no row of detmax sets of 20"]),
        (edited(&|u| u["rows"][0]["set_size"] = json!(999999)), vec!["rows[0].set_size = 999999"]),
        (edited(&|u| u["rows"][0]["selection"] = json!("magic")), vec!["rows[0].selection", "magic"]),
        (edited(&|u| u["rows"][0]["repetitions"] = json!(4294967295u32)), vec!["rows[0].repetitions = 4294967295"]),
        (edited(&|u| u["rows"][0]["table"] = json!(false)), vec!["rows[0].table"]),
        (
            edited(&|u| {
                let row = u["rows"][0].clone();
                u["rows"].as_array_mut().unwrap().push(row);
            }),
            vec!["rows[1]", "a second time"],
        ),
        (edited(&|u| u["error"] = json!("failed")), vec!["rows", "could not run"]),
    ] {
        std::fs::write(&unit_path, text).unwrap();
        let mut all = vec!["u0000001.json"];
        all.extend(parts);
        refused(dir, &merge, &all);
        assert!(!dir.join("merged").exists());
    }
    std::fs::write(&unit_path, &unit_text).unwrap();
    // A unit deleted is named; a unit of another shard is refused.
    std::fs::remove_file(&unit_path).unwrap();
    refused(dir, &merge, &["1 of 4 work units missing", "first: 1"]);
    std::fs::write(&unit_path, &unit_text).unwrap();
    let (code, err) = run_in(dir, &merge);
    assert_eq!(code, Some(0), "the shard put back merges: {err}");
    assert!(dir.join("merged/m/best_design.toml").exists());
    assert!(
        std::fs::read_dir(dir.join("merged")).unwrap().all(|e| !e.unwrap().file_name().to_string_lossy().starts_with('.')),
        "no temporary directory"
    );
}

/// two shards of one sweep whose records differ beyond their shard index, or a
/// shard given twice, are refused naming the record and its key.
#[test]
fn shards_whose_records_disagree_are_refused_naming_the_key() {
    let tmp = scratch("records2");
    let dir = tmp.path();
    std::fs::write(dir.join("base.toml"), small_scenario()).unwrap();
    std::fs::write(dir.join("m.toml"), "base = \"base.toml\"\nthresholds_mm = [0.5]\n[[axis]]\nkey = \"seed\"\nvalues = [1, 2]\n").unwrap();
    for k in ["0/2", "1/2"] {
        let (code, err) = run_in(dir, &["sweep", "m.toml", "--out", "out", "--shard", k]);
        assert_eq!(code, Some(0), "{err}");
    }
    let second = dir.join("out/m.shard-1-of-2/sweep.json");
    let good = std::fs::read_to_string(&second).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&good).unwrap();
    v["thresholds_mm"] = serde_json::json!([0.6]);
    std::fs::write(&second, v.to_string()).unwrap();
    let merge = ["merge", "out/m.shard-0-of-2", "out/m.shard-1-of-2", "--out", "merged"];
    refused(dir, &merge, &["m.shard-1-of-2/sweep.json", "thresholds_mm", "not the record of"]);
    std::fs::write(&second, &good).unwrap();
    refused(dir, &["merge", "out/m.shard-0-of-2", "out/m.shard-0-of-2", "--out", "merged"], &["shard 0 of 2 a second time"]);
    // A unit moved into the other shard's directory.
    std::fs::rename(dir.join("out/m.shard-1-of-2/units/u0000001.json"), dir.join("out/m.shard-0-of-2/units/u0000001.json")).unwrap();
    refused(dir, &merge, &["m.shard-0-of-2/units/u0000001.json", "a unit of shard 1 of 2"]);
    assert!(!dir.join("merged").exists());
}

/// a legal sweep of 9,001 grid points keeps a record that `merge` reads (the
/// scenario once and each point's changes: about 1 MB, under calsim's 16 MiB input cap; the
/// whole scenario per point took 21 MB). The units are made here with plausible values, not run
/// (running 9,001 studies is a cluster's work): this is the merge's capacity, not a study's
/// figures.
#[test]
fn a_sweep_of_9001_points_keeps_a_record_that_merge_reads() {
    use calsim::design::sweep::{Unit, UnitRow, shard_dir, shard_info, spec};
    let tmp = scratch("records-9001");
    let dir = tmp.path();
    std::fs::write(dir.join("base.toml"), small_scenario()).unwrap();
    let seeds: Vec<String> = (1..=9001).map(|s| s.to_string()).collect();
    std::fs::write(dir.join("big.toml"), format!("base = \"base.toml\"\n[[axis]]\nkey = \"seed\"\nvalues = [{}]\n", seeds.join(", ")))
        .unwrap();
    let sweep = spec::load(&dir.join("big.toml")).unwrap();
    assert_eq!(sweep.points.len(), 9001);
    let out = dir.join("out");
    let shard = shard_dir(&out, &sweep.name, 0, 1);
    std::fs::create_dir_all(shard.join("units")).unwrap();
    let record = serde_json::to_vec(&shard_info(&sweep, 0, 1)).unwrap();
    assert!(record.len() < 2 << 20, "the record of 9,001 points takes {} bytes", record.len());
    std::fs::write(shard.join("sweep.json"), &record).unwrap();
    for p in 0..9001 {
        let e = 0.2 + (p % 97) as f64 * 1e-3;
        let row = UnitRow {
            selection: "detmax".into(),
            set_size: 20,
            table: true,
            repetitions: 1,
            no_model: 0,
            after_median_mm: e,
            after_p95_mm: 2.0 * e,
            after_max_mm: 3.0 * e,
            after_mean_mm: 1.1 * e,
            max_within: Vec::new(),
            mean_within: Vec::new(),
            p95_within: Vec::new(),
            median_within: Vec::new(),
            o1_median: 0.25,
        };
        let unit = Unit {
            unit: p,
            point: p,
            realisation: 0,
            error: None,
            before_mm: [3.0, 5.0, 7.0],
            campaign_s: 7000.0,
            rows: vec![row],
            prediction: None,
            design: None,
            digest: None,
        };
        std::fs::write(shard.join(format!("units/u{p:07}.json")), serde_json::to_vec(&unit).unwrap()).unwrap();
    }
    let m = calsim::app::sweep::merge(&[shard], &out).unwrap();

    assert_eq!((m.units, m.failed), (9001, 0));
    assert!(m.summary.contains("9001 grid points"), "{}", &m.summary[..200]);
}

/// The readers of `fk` and `compensate` take time in proportion to their rows (each record's line
/// is counted on from the last, never from the file's start): a file past the row cap is refused at
/// once, and a bad value after 300,000 CRLF rows is named at its line, both within [`BOUND`].
#[test]
fn tabular_readers_answer_large_files_at_once_naming_the_line() {
    use std::fmt::Write as _;
    let tmp = scratch("readers-large");
    let dir = tmp.path();
    let robot = repo().join("robots/irb120.toml");
    // Past the cap: 1,000,001 rows.
    let mut joints = String::from("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n");
    let mut targets = String::from("x_mm,y_mm,z_mm,alpha_deg,beta_deg,gamma_deg\n");
    for _ in 0..1_000_001 {
        joints.push_str("0,0,0,0,30,0\n");
        targets.push_str("400,0,500,0,90,0\n");
    }
    let (j, t) = (dir.join("many_joints.csv"), dir.join("many_targets.csv"));
    std::fs::write(&j, &joints).unwrap();
    std::fs::write(&t, &targets).unwrap();
    refused(dir, &["fk", s(&robot), s(&j)], &[s(&j), "more than 1000000 rows"]);
    refused(dir, &["compensate", s(&robot), s(&t)], &[s(&t), "more than 1000000 targets"]);
    // A bad value on the last of 300,000 CRLF rows: line 300,001 (the header is line 1).
    let rows = 300_000;
    let mut joints = String::from("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\r\n");
    let mut targets = String::from("x_mm,y_mm,z_mm,alpha_deg,beta_deg,gamma_deg\r\n");
    for i in 0..rows {
        let bad = i + 1 == rows;
        write!(joints, "{},0,0,0,30,0\r\n", if bad { "nope" } else { "1" }).unwrap();
        write!(targets, "{},0,500,0,90,0\r\n", if bad { "nope" } else { "400" }).unwrap();
    }
    std::fs::write(&j, &joints).unwrap();
    std::fs::write(&t, &targets).unwrap();
    refused(dir, &["fk", s(&robot), s(&j)], &[s(&j), "line 300001", "q1_deg"]);
    refused(dir, &["compensate", s(&robot), s(&t)], &[s(&t), "line 300001", "x_mm"]);
}

/// A refusal names what the user wrote: adaptive realisations whose batch exceeds their most name
/// `batch` (not the `min` they left out), and the plan's noise without a plan names
/// `--plan-noise-mm` (as `--plan-scenario` without a plan is refused).
#[test]
fn refusals_name_the_key_or_flag_the_user_wrote() {
    let tmp = scratch("named-as-written");
    let dir = tmp.path();
    let base = repo().join("scenarios/ci_quick.toml");
    let f = dir.join("adaptive.toml");
    std::fs::write(
        &f,
        format!("base = {:?}\nrealisations = {{ max = 4, batch = 100 }}\nthresholds_mm = [1.0]\n", base.display().to_string()),
    )
    .unwrap();
    let line = refused(dir, &["sweep", s(&f), "--out", "out"], &[s(&f), "realisations.batch", "100", "max = 4"]);
    assert!(!line.contains("realisations.min"), "{line}");
    let m = repo().join("docs/calibrate/example_measurements.csv");
    let robot = repo().join("robots/irb120.toml");
    refused(dir, &["calibrate", s(&robot), s(&m), "--plan-noise-mm", "0.01", "--out", "out"], &["--plan-noise-mm", "--plan-worlds"]);
    assert!(!dir.join("out").exists(), "nothing written");
}

/// A negative number given to a counting flag is refused naming the flag and the value (clap
/// would otherwise read it as an unknown option), and a value TOML itself cannot read (an integer
/// beyond 64 bits) names its line, table and key.
#[test]
fn a_negative_count_names_its_flag_and_an_unreadable_value_its_key() {
    let tmp = scratch("negative-and-huge");
    let dir = tmp.path();
    let base = repo().join("scenarios/ci_quick.toml");
    for (flag, value) in [("--seed", "-1"), ("--realisations", "-3"), ("--threads", "-2"), ("--repetitions", "-5")] {
        refused(dir, &["run", s(&base), flag, value, "--out", "out"], &[flag, value]);
    }
    let text = common::scenario_text_anywhere("ci_quick.toml");
    let huge = text.replacen("repetitions = 10", "repetitions = 99999999999999999999", 1);
    assert_ne!(huge, text, "ci_quick.toml sets `repetitions = 10` in [study]");
    let f = dir.join("huge.toml");
    std::fs::write(&f, huge).unwrap();
    refused(dir, &["run", s(&f), "--out", "out"], &[s(&f), "line ", "[study] repetitions"]);
    assert!(!dir.join("out").exists(), "nothing written");
}
