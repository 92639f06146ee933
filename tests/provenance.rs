//! The provenance block, over every command that writes a results directory (run, check, sweep,
//! merge, budget, optimise, calibrate, plan, export): every `manifest.json` each writes carries the
//! same block, of the same shape (the version, the commit the binary was built from as git says
//! it, the command line, every input with its sha256, the overrides; no thread count), and lists
//! the command's own input file with the sha256 of its bytes.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::{calsim, repo, scratch};

/// What the crate is compiled from: a change to one of them marks the build `-dirty` (the list
/// of `build.rs`).
const BUILT_FROM: [&str; 8] = [
    "src",
    "build.rs",
    "Cargo.toml",
    "Cargo.lock",
    "README.md",
    "docs/library.md",
    "assets/DejaVuSans.ttf",
    "reference/published-figures.toml",
];

fn git(args: &[&str]) -> Option<String> {
    let o = Command::new("git").arg("--no-optional-locks").arg("-C").arg(repo()).args(args).output().ok()?;
    o.status.success().then(|| String::from_utf8_lossy(&o.stdout).trim().to_string())
}

/// The commit git gives for the checkout this test was built from: `HEAD`, `-dirty` when a file
/// the crate is compiled from differs from it; `unknown` outside a git checkout of calsim; the
/// packager's `CALSIM_GIT_COMMIT` when one was stated.
fn expected_commit() -> String {
    if let Ok(stated) = std::env::var("CALSIM_GIT_COMMIT")
        && !stated.trim().is_empty()
    {
        return stated.trim().to_string();
    }
    if git(&["ls-files", "--error-unmatch", "build.rs"]).is_none() {
        return "unknown".into();
    }
    let head = git(&["rev-parse", "HEAD"]).expect("HEAD");
    let mut status = vec!["status", "--porcelain", "--untracked-files=normal", "--"];
    status.extend(BUILT_FROM);
    if git(&status).expect("git status").is_empty() { head } else { format!("{head}-dirty") }
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

/// Every `manifest.json` under `dir`.
fn manifests(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else if p.file_name().is_some_and(|n| n == "manifest.json") {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

/// The shape of a JSON value: its kind, an object's keys with theirs, an array's elements' shape
/// (one, when they agree).
fn shape(v: &serde_json::Value) -> String {
    use serde_json::Value::*;
    match v {
        Null => "null".into(),
        Bool(_) => "bool".into(),
        Number(_) => "number".into(),
        String(_) => "string".into(),
        Array(a) => {
            let mut shapes: Vec<std::string::String> = a.iter().map(shape).collect();
            shapes.dedup();
            format!("[{}]", shapes.join(" | "))
        }
        Object(o) => format!("{{{}}}", o.iter().map(|(k, v)| format!("{k}: {}", shape(v))).collect::<Vec<_>>().join(", ")),
    }
}

/// A small plan file (the shipped IRB 120 arm, `ROBOT` its path).
const PLAN: &str = r#"robot = "ROBOT"
model = "compliance"
poses = 40
pool = 200
validation = 6
seed = 3
worlds = 5

[tracker]
position_mm = [1800.0, 0.0, 300.0]
aim_mm = [400.0, 0.0, 400.0]
field_of_view_half_angle_deg = 60.0
min_range_mm = 500.0
max_range_mm = 6000.0
incidence_max_deg = 45.0

[[target]]
name = "SMR1"
flange_mm = [0.0, 0.0, 40.0]

[[target]]
name = "SMR2"
flange_mm = [40.0, 30.0, 30.0]

[cell]
joint_limits_deg = [[-120.0, 120.0], [-90.0, 100.0], [-100.0, 60.0], [-150.0, 150.0], [-115.0, 115.0], [-180.0, 180.0]]
floor_z_mm = 0.0
workspace_min_mm = [250.0, -300.0, 100.0]
workspace_max_mm = [550.0, 300.0, 500.0]
"#;

/// The fields of the provenance block.
const BLOCK: [&str; 5] = ["crate_version", "git_commit", "command_line", "inputs", "overrides"];

/// Runs `calsim args` (exit 0, or 1 for a check that missed), then checks every manifest under
/// `out`: the block present with `commit`, the command line this one, `input` listed with the
/// sha256 of its bytes. Returns the blocks' shapes (the inputs and overrides of one element).
fn ran(args: &[&str], out: &Path, input: &Path, commit: &str) -> Vec<String> {
    let o = calsim().args(args).output().unwrap();
    assert!(matches!(o.status.code(), Some(0 | 1)), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
    let found = manifests(out);
    assert!(!found.is_empty(), "{args:?}: no manifest.json under {}", out.display());
    let input_real = std::fs::canonicalize(input).unwrap();
    let input_sha = sha256(&std::fs::read(input).unwrap());
    let mut shapes = Vec::new();
    for path in found {
        let m: serde_json::Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
        let at = path.display();
        for k in BLOCK {
            assert!(m.get(k).is_some(), "{at}: no {k}: {m}");
        }
        assert_eq!(m["crate_version"], env!("CARGO_PKG_VERSION"), "{at}");
        assert_eq!(m["git_commit"], commit, "{at}: the commit git gives for this build");
        let line: Vec<&str> = m["command_line"].as_array().unwrap().iter().map(|a| a.as_str().unwrap()).collect();
        assert_eq!(&line[1..], args, "{at}");
        let inputs = m["inputs"].as_array().unwrap();
        assert!(
            inputs.iter().any(|i| i["path"] == s(&input_real) && i["sha256"] == input_sha.as_str()),
            "{at}: {} with its sha256 among the inputs: {m}",
            input.display()
        );
        assert!(m.get("threads").is_none(), "{at}: results do not depend on threads: {m}");
        let overrides = m["overrides"].as_array().unwrap();
        assert!(overrides.iter().all(|o| shape(o) == "[string]" && o.as_array().unwrap().len() == 2), "{at}: {m}");
        // The shape of the block: its fields, an input's, an override's (of the first when any).
        let block = serde_json::json!({
            "crate_version": m["crate_version"],
            "git_commit": m["git_commit"],
            "command_line": m["command_line"],
            "inputs": [inputs[0]],
            "overrides": [["key", "value"]],
        });
        shapes.push(shape(&block));
    }
    shapes
}

#[test]
fn every_command_writes_the_same_provenance_block_with_the_built_commit() {
    let commit = expected_commit();
    let tmp = scratch("provenance");
    let t = tmp.path();
    let scenario = write(&t.join("s/ci_quick.toml"), common::scenario_text_anywhere("ci_quick.toml"));
    let small = ["--set-sizes", "20:30:10", "--repetitions", "2", "--no-plots", "--no-recording", "--realisations", "1"];
    let mut shapes: Vec<(String, String)> = Vec::new();
    let mut record = |verb: &str, found: Vec<String>| shapes.extend(found.into_iter().map(|f| (verb.to_string(), f)));

    let res = t.join("res");
    let mut a = vec!["run", s(&scenario)];
    a.extend(small);
    a.extend(["--out", s(&res)]);
    record("run", ran(&a, &res, &scenario, &commit));

    let chk = t.join("chk");
    let junit = t.join("chk.xml");
    let mut a = vec!["check", s(&scenario)];
    a.extend(small);
    a.extend(["--out", s(&chk), "--junit", s(&junit)]);
    record("check", ran(&a, &chk, &scenario, &commit));

    let sweep = write(
        &t.join("sweeps/sw.toml"),
        format!(
            "base = {:?}\nrealisations = 2\nthresholds_mm = [0.5]\n\n[fixed]\n\"study.set_sizes\" = [20, 30]\n\"study.table_set_size\" = 30\n\
             \"study.repetitions\" = 2\n\n[[axis]]\nkey = \"trical.epsilon_mm\"\nvalues = [0.010, 0.020]\n",
            s(&scenario)
        ),
    );
    let sw = t.join("sw");
    record("sweep", ran(&["sweep", s(&sweep), "--realisations", "1", "--out", s(&sw)], &sw, &sweep, &commit));
    let shards = t.join("shards");
    let o = calsim().args(["sweep", s(&sweep), "--realisations", "1", "--shard", "0/1", "--out", s(&shards)]).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let shard = shards.join("sw.shard-0-of-1");
    let merged = t.join("merged");
    // A merge's input is the shard it reads: the shard's record of the sweep file.
    let shard_file =
        std::fs::read_dir(&shard).unwrap().map(|e| e.unwrap().path()).find(|p| p.is_file()).expect("a file in the shard directory");
    record("merge", ran(&["merge", s(&shard), "--out", s(&merged)], &merged, &shard_file, &commit));
    // `--realisations` changes the sweep file: an override, kept by the shard's record for the merge.
    for dir in [&sw, &merged] {
        let m: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("sw/manifest.json")).unwrap()).unwrap();
        assert_eq!(m["overrides"], serde_json::json!([["realisations", "1"]]), "{}", dir.display());
    }

    let bud = t.join("bud");
    let a = ["budget", s(&scenario), "--realisations", "1", "--repetitions", "1", "--factors", "2", "--out", s(&bud)];
    record("budget", ran(&a, &bud, &scenario, &commit));

    let design = write(
        &t.join("designs/op.toml"),
        format!(
            "base = {:?}\n[objective]\nmaximise = \"success\"\nstatistic = \"max\"\nthreshold_mm = 0.5\nconfidence = 0.9\n\
             [fixed]\n\"study.set_sizes\" = [20, 30]\n\"study.table_set_size\" = 30\n\"study.repetitions\" = 2\n\
             \"campaign.validation_poses\" = 60\n\"campaign.pool_per_sphere\" = 20\n\n[[variable]]\nkey = \"trical.epsilon_mm\"\n\
             range = [0.01, 0.02]\n\n[search]\nevaluations = 2\nrestarts = 1\nworlds = 1\nfinalists = 1\nrace = {{ max = 2, batch = 1 }}\n\n\
             [verify]\nheld_out = 1\n",
            s(&scenario)
        ),
    );
    let op = t.join("op");
    record("optimise", ran(&["optimise", s(&design), "--no-plots", "--out", s(&op)], &op.join("op"), &design, &commit));

    let csv = write(&t.join("meas/m.csv"), std::fs::read(repo().join("docs/calibrate/example_measurements.csv")).unwrap());
    let cal = t.join("cal");
    let robot = repo().join("robots/irb120.toml");
    record("calibrate", ran(&["calibrate", s(&robot), s(&csv), "--no-plots", "--out", s(&cal)], &cal, &csv, &commit));

    let plan = write(&t.join("plans/small.toml"), PLAN.replace("ROBOT", s(&robot)));
    let pl = t.join("pl");
    record("plan", ran(&["plan", s(&plan), "--out", s(&pl)], &pl, &plan, &commit));

    let exp = t.join("exp");
    let results_manifest = res.join("ci_quick/manifest.json");
    record("export", ran(&["export", s(&res.join("ci_quick")), "--task", "0", "--out", s(&exp)], &exp, &results_manifest, &commit));

    // One shape for every manifest of every command.
    let (first_verb, first) = shapes[0].clone();
    for (verb, shape) in &shapes {
        assert_eq!(shape, &first, "{verb}'s block differs in shape from {first_verb}'s");
    }
    let verbs: std::collections::BTreeSet<&str> = shapes.iter().map(|(v, _)| v.as_str()).collect();
    assert_eq!(verbs.len(), 9, "{verbs:?}");
}
