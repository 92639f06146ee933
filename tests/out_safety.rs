//! The one safety rule of the writer, over every command that writes: an `--out` (or `--junit`)
//! that holds or is an input of the run (the scenario, the robot file it names, a sweep's or a
//! design's base, measurements, targets), a directory that is not a calsim results directory, or a
//! symbolic link into either is refused before anything runs: exit 2, one line on standard error
//! naming the flag and the path, and nothing in the scratch tree changed (every path, every byte,
//! every link target compared before and after).

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use common::{calsim, repo, scratch};

/// Every entry under `root`: its path relative to `root` and its bytes (a directory: its mark; a
/// symbolic link: its target, not followed).
fn snapshot(root: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for e in std::fs::read_dir(&dir).unwrap() {
            let p = e.unwrap().path();
            let rel = p.strip_prefix(root).unwrap().to_path_buf();
            let meta = std::fs::symlink_metadata(&p).unwrap();
            if meta.file_type().is_symlink() {
                out.insert(rel, format!("link -> {}", std::fs::read_link(&p).unwrap().display()).into_bytes());
            } else if meta.is_dir() {
                out.insert(rel, b"(directory)".to_vec());
                stack.push(p);
            } else {
                out.insert(rel, std::fs::read(&p).unwrap());
            }
        }
    }
    out
}

/// Runs `calsim args` and asserts the refusal: exit 2, one line naming `flag` and `says`, and the
/// tree under `root` unchanged.
fn refused(root: &Path, args: &[&str], flag: &str, says: &str) {
    let before = snapshot(root);
    let o = calsim().args(args).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: {err}");
    assert!(err.contains(flag) && err.contains(says), "{args:?}: expected {flag:?} and {says:?} in: {err}");
    let after = snapshot(root);
    assert_eq!(before.keys().collect::<Vec<_>>(), after.keys().collect::<Vec<_>>(), "{args:?}: the listing changed");
    assert!(before == after, "{args:?}: some file's bytes changed");
}

/// The manifest at `path`, after checking its provenance block: the version, the commit the
/// binary was built from, the command line, the inputs with their sha256, the overrides, and no
/// thread count.
fn provenance(path: &Path) -> serde_json::Value {
    let m: serde_json::Value = serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap();
    assert_eq!(m["crate_version"], env!("CARGO_PKG_VERSION"), "{m}");
    let commit = m["git_commit"].as_str().unwrap();
    let hex = commit.strip_suffix("-dirty").unwrap_or(commit);
    assert!(commit == "unknown" || (hex.len() == 40 && hex.bytes().all(|b| b.is_ascii_hexdigit())), "{m}");
    assert!(m["command_line"].as_array().unwrap().len() > 1, "{m}");
    assert!(m["inputs"].as_array().unwrap().iter().all(|i| i["sha256"].as_str().is_some_and(|h| h.len() == 64)), "{m}");
    assert!(m["overrides"].is_array(), "{m}");
    assert!(m.get("threads").is_none(), "{m}");
    m
}

fn sha256(bytes: &[u8]) -> String {
    use sha2::Digest;
    format!("{:x}", sha2::Sha256::digest(bytes))
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn write(p: &Path, text: impl AsRef<[u8]>) -> PathBuf {
    std::fs::create_dir_all(p.parent().unwrap()).unwrap();
    std::fs::write(p, text).unwrap();
    p.to_path_buf()
}

fn link(target: &Path, at: &Path) -> PathBuf {
    std::os::unix::fs::symlink(target, at).unwrap();
    at.to_path_buf()
}

/// The reduced scenario with its robot file named by absolute path (`robot`, default the shipped
/// IRB 120 file), small enough that a run that escaped the rule would finish.
fn quick_text(robot: Option<&Path>) -> String {
    let text = common::scenario_text_anywhere("ci_quick.toml");
    match robot {
        None => text,
        Some(r) => text.replace(&format!("file = \"{}/robots/irb120.toml\"", repo().display()), &format!("file = {:?}", s(r))),
    }
}

const SMALL: [&str; 7] = ["--set-sizes", "20:30:10", "--repetitions", "2", "--no-plots", "--no-recording", "--realisations"];

#[test]
fn run_and_check_refuse_an_out_or_junit_that_holds_or_is_an_input_or_is_not_calsims() {
    let tmp = scratch("safety-run");
    let t = tmp.path();
    let run = |scenario: &Path, out: &Path, verb: &str| {
        let mut v = vec![verb.to_string(), s(scenario).to_string()];
        v.extend(SMALL.iter().map(|a| a.to_string()));
        v.extend(["1".to_string(), "--out".to_string(), s(out).to_string()]);
        v
    };
    // The scenario inside the directory its results would replace.
    let d = t.join("d");
    let inside = write(&d.join("ci_quick/ci_quick.toml"), quick_text(None));
    std::fs::write(d.join("ci_quick/notes.txt"), "a user's file").unwrap();
    let a = run(&inside, &d, "run");
    refused(t, &a.iter().map(String::as_str).collect::<Vec<_>>(), "--out", "an input of this run");
    // Through a symbolic link to that directory.
    let l = link(&d, &t.join("link_to_d"));
    let a = run(&inside, &l, "run");
    refused(t, &a.iter().map(String::as_str).collect::<Vec<_>>(), "--out", "an input of this run");
    // The robot file the scenario names, inside the results directory to be replaced.
    let robot = write(&t.join("r/ci_quick/arm.toml"), std::fs::read(repo().join("robots/irb120.toml")).unwrap());
    let named = write(&t.join("s/ci_quick.toml"), quick_text(Some(&robot)));
    let a = run(&named, &t.join("r"), "check");
    refused(t, &a.iter().map(String::as_str).collect::<Vec<_>>(), "--out", "arm.toml");
    // A directory of the results' name that is not calsim's.
    write(&t.join("u/ci_quick/thesis.tex"), "\\documentclass{article}");
    let plain = write(&t.join("plain/ci_quick.toml"), quick_text(None));
    let a = run(&plain, &t.join("u"), "run");
    refused(t, &a.iter().map(String::as_str).collect::<Vec<_>>(), "--out", "not a calsim results directory");
    // A symbolic link in the results' place, to a user's directory.
    std::fs::create_dir_all(t.join("v")).unwrap();
    link(&t.join("u/ci_quick"), &t.join("v/ci_quick"));
    let a = run(&plain, &t.join("v"), "run");
    refused(t, &a.iter().map(String::as_str).collect::<Vec<_>>(), "--out", "not a directory");
    // --junit: the robot file the scenario names, the scenario itself, a link to the robot file.
    let out = t.join("out");
    for junit in [robot.clone(), named.clone(), link(&robot, &t.join("arm_link.toml"))] {
        let mut a = run(&named, &out, "check");
        a.extend(["--junit".to_string(), s(&junit).to_string()]);
        refused(t, &a.iter().map(String::as_str).collect::<Vec<_>>(), "--junit", "is the input");
    }
}

#[test]
fn sweep_merge_budget_and_optimise_refuse_an_out_that_holds_an_input_or_is_not_calsims() {
    let tmp = scratch("safety-design");
    let t = tmp.path();
    let base = write(&t.join("base/ci_quick.toml"), quick_text(None));
    let sweep_text = |base: &Path| {
        format!(
            "base = {:?}\nrealisations = 1\nthresholds_mm = [0.5]\n\n[fixed]\n\"study.set_sizes\" = [20, 30]\n\"study.table_set_size\" = 30\n\
             \"study.repetitions\" = 2\n\n[[axis]]\nkey = \"trical.epsilon_mm\"\nvalues = [0.010, 0.020]\n",
            s(base)
        )
    };
    // The sweep file inside the directory of its results; its base scenario inside it.
    let sw = write(&t.join("d/sw/sw.toml"), sweep_text(&base));
    refused(t, &["sweep", s(&sw), "--out", s(&t.join("d"))], "--out", "an input of this run");
    let base_inside = write(&t.join("e/sw2/base.toml"), quick_text(None));
    let sw2 = write(&t.join("sweeps/sw2.toml"), sweep_text(&base_inside));
    refused(t, &["sweep", s(&sw2), "--out", s(&t.join("e"))], "--out", "base.toml");
    // A user's directory of the shard's name: the sweep would fill it and delete it.
    write(&t.join("f/sw3.shard-0-of-1/data.csv"), "1,2,3");
    let sw3 = write(&t.join("sweeps/sw3.toml"), sweep_text(&base));
    refused(t, &["sweep", s(&sw3), "--out", s(&t.join("f"))], "--out", "not a calsim work directory");

    // merge: a shard of a real sweep merged into a user's directory, or into one holding the shard.
    let shards = t.join("shards");
    let o = calsim().args(["sweep", s(&sw3), "--shard", "0/1", "--out", s(&shards)]).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let shard = shards.join("sw3.shard-0-of-1");
    write(&t.join("g/sw3/keep.md"), "mine");
    refused(t, &["merge", s(&shard), "--out", s(&t.join("g"))], "--out", "not a calsim results directory");
    let nested = t.join("h/sw3");
    std::fs::create_dir_all(&nested).unwrap();
    std::fs::rename(&shard, nested.join("sw3.shard-0-of-1")).unwrap();
    refused(t, &["merge", s(&nested.join("sw3.shard-0-of-1")), "--out", s(&t.join("h"))], "--out", "an input of this run");
    // Merged elsewhere: the sweep's manifest carries the provenance block.
    let o = calsim().args(["merge", s(&nested.join("sw3.shard-0-of-1")), "--out", s(&t.join("merged"))]).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let m = provenance(&t.join("merged/sw3/manifest.json"));
    assert!(m["command_line"].as_array().unwrap().iter().any(|a| a == "merge"), "{m}");

    // budget: the scenario inside `<scenario>.budget`, a user's directory of that name.
    let bs = write(&t.join("b/ci_quick.budget/ci_quick.toml"), quick_text(None));
    refused(t, &["budget", s(&bs), "--realisations", "1", "--out", s(&t.join("b"))], "--out", "an input of this run");
    write(&t.join("c/ci_quick.budget/x.txt"), "x");
    refused(t, &["budget", s(&base), "--realisations", "1", "--out", s(&t.join("c"))], "--out", "not a calsim results directory");

    // optimise: the design file inside the directory of its results (a link to it too).
    let design = std::fs::read_to_string(repo().join("scenarios/designs/irb120_spheres.toml"))
        .unwrap()
        .replace("base = \"../irb120_trical.toml\"", &format!("base = {:?}", s(&repo().join("scenarios/irb120_trical.toml"))))
        .replace("\"../sweeps/", &format!("\"{}/scenarios/sweeps/", repo().display()));
    let op = write(&t.join("o/op/op.toml"), design);
    refused(t, &["optimise", s(&op), "--out", s(&t.join("o"))], "--out", "an input of this run");
    let ol = link(&t.join("o"), &t.join("o_link"));
    refused(t, &["optimise", s(&op), "--out", s(&ol)], "--out", "an input of this run");
}

#[test]
fn calibrate_export_and_the_file_writers_refuse_their_inputs() {
    let tmp = scratch("safety-files");
    let t = tmp.path();
    // calibrate: the measurements inside `<stem>.calibration`, and a user's directory of that name.
    let csv = std::fs::read(repo().join("docs/calibrate/example_measurements.csv")).unwrap();
    let m = write(&t.join("d/m.calibration/m.csv"), &csv);
    refused(t, &["calibrate", "robots/irb120.toml", s(&m), "--no-plots", "--out", s(&t.join("d"))], "--out", "an input of this run");
    let m2 = write(&t.join("meas/m.csv"), &csv);
    write(&t.join("u/m.calibration/report.docx"), "mine");
    refused(
        t,
        &["calibrate", "robots/irb120.toml", s(&m2), "--no-plots", "--out", s(&t.join("u"))],
        "--out",
        "not a calsim results directory",
    );

    // calibrate's twin.toml goes inside its results directory, which a second run replaces (a
    // calsim results directory holding no input); nothing is written beside it.
    let m3 = write(&t.join("twin/m.csv"), &csv);
    for _ in 0..2 {
        let o = calsim().args(["calibrate", "robots/irb120.toml", s(&m3), "--no-plots", "--out", s(&t.join("tw"))]).output().unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    assert!(t.join("tw/m.calibration/twin.toml").is_file());
    let beside: Vec<_> = std::fs::read_dir(t.join("tw")).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(beside, ["m.calibration"], "nothing beside the results directory");

    // export: into a user's directory of the export's name (results of a real run).
    let scenario = write(&t.join("s/ci_quick.toml"), quick_text(None));
    let res = t.join("res");
    let mut a = vec!["run", s(&scenario)];
    a.extend(SMALL);
    a.extend(["1", "--out", s(&res)]);
    let o = calsim().args(&a).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // The run's manifest: its block lists the scenario and the robot file it names, with their sha256.
    let m = provenance(&res.join("ci_quick/manifest.json"));
    let listed = |p: &Path| {
        let real = std::fs::canonicalize(p).unwrap();
        let bytes = std::fs::read(p).unwrap();
        m["inputs"].as_array().unwrap().iter().any(|i| i["path"] == s(&real) && i["sha256"] == sha256(&bytes))
    };
    assert!(listed(&scenario) && listed(&repo().join("robots/irb120.toml")), "{m}");
    assert_eq!(m["overrides"][0], serde_json::json!(["study.set_sizes", "[20, 30]"]), "{m}");
    write(&t.join("x/ci_quick.task-0/notes.txt"), "mine");
    refused(t, &["export", s(&res.join("ci_quick")), "--task", "0", "--out", s(&t.join("x"))], "--out", "not a calsim results directory");
    // Export into the results directory it reads: refused (inside other results).
    refused(t, &["export", s(&res.join("ci_quick")), "--task", "0", "--out", s(&res.join("ci_quick"))], "--out", "results directory");
    // Exported elsewhere: a manifest with the block, listing the results it read; exported again
    // over its own earlier export (a calsim directory holding no input): replaced.
    for _ in 0..2 {
        let o = calsim().args(["export", s(&res.join("ci_quick")), "--task", "0", "--out", s(&t.join("ok"))]).output().unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    let m = provenance(&t.join("ok/ci_quick.task-0/manifest.json"));
    let results_manifest = std::fs::canonicalize(res.join("ci_quick/manifest.json")).unwrap();
    assert!(m["inputs"].as_array().unwrap().iter().any(|i| i["path"] == s(&results_manifest)), "{m}");

    // compensate --out: the model, the targets, a link to the targets.
    let model = write(&t.join("model.toml"), std::fs::read(repo().join("robots/irb120.toml")).unwrap());
    let targets = write(&t.join("targets.csv"), "x_mm,y_mm,z_mm,alpha_deg,beta_deg,gamma_deg\n300,0,400,0,180,0\n");
    let targets_link = link(&targets, &t.join("targets_link.csv"));
    for out in [&model, &targets, &targets_link] {
        refused(t, &["compensate", s(&model), s(&targets), "--out", s(out)], "--out", "is the input");
    }
    // fk --out: the joints, a link to the robot file.
    let joints = write(&t.join("joints.csv"), "q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n0,0,0,0,0,0\n");
    let model_link = link(&model, &t.join("model_link.toml"));
    for out in [&joints, &model_link] {
        refused(t, &["fk", s(&model), s(&joints), "--out", s(out)], "--out", "is the input");
    }
    // import-urdf --out: the URDF itself, through a link.
    let urdf = write(&t.join("arm.urdf"), "<robot name=\"x\"/>");
    let urdf_link = link(&urdf, &t.join("arm_link.urdf"));
    refused(t, &["import-urdf", s(&urdf), "--out", s(&urdf_link)], "--out", "is the input");
    // compensate, fk, import-urdf --out and check --junit: a user's file already there (or a
    // dangling link) is refused and left as it is; no temporary is left beside it.
    let mine = write(&t.join("mine/joints.csv"), "my joints");
    let mine_link = link(&t.join("mine/nowhere.csv"), &t.join("mine/dangling.csv"));
    let chk = t.join("chk");
    for out in [&mine, &mine_link] {
        refused(t, &["compensate", s(&model), s(&targets), "--out", s(out)], "--out", "the file exists");
        refused(t, &["fk", s(&model), s(&joints), "--out", s(out)], "--out", "the file exists");
        refused(t, &["import-urdf", "robots/kr6r900sixx.urdf", "--out", s(out)], "--out", "the file exists");
        let mut a = vec!["check", s(&scenario)];
        a.extend(SMALL);
        a.extend(["1", "--out", s(&chk), "--junit", s(out)]);
        refused(t, &a, "--junit", "the file exists");
    }
    assert_eq!(std::fs::read_to_string(&mine).unwrap(), "my joints");
    // A JUnit report calsim wrote is a CI job's output of every run: replaced.
    let report = t.join("mine/check.xml");
    for _ in 0..2 {
        let mut a = vec!["check", s(&scenario)];
        a.extend(SMALL);
        a.extend(["1", "--out", s(&chk), "--junit", s(&report)]);
        let o = calsim().args(&a).output().unwrap();
        assert!(o.status.code().is_some_and(|c| c < 2), "{}", String::from_utf8_lossy(&o.stderr));
    }
    assert!(std::fs::read_to_string(&report).unwrap().contains("<testsuite name=\"calsim check"));
    std::fs::remove_file(&report).unwrap();
    let left: Vec<_> = std::fs::read_dir(t.join("mine")).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(left.len(), 2, "only the user's file and link: {left:?}");
    // init: an existing file, and a link (even a dangling one), are never replaced.
    let dangling = link(&t.join("nowhere.toml"), &t.join("dangling.toml"));
    for f in [&model, &dangling] {
        refused(t, &["init", "trical", s(f)], "", "does not replace a file");
    }
}
