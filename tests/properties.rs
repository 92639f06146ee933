//! Property tests of the input surfaces: a real, valid input is mutated at random
//! (lines dropped, repeated, swapped or cut short, numbers made extreme, junk put in; for the JSON
//! of a shard, keys dropped, elements duplicated, arrays grown and shrunk, numbers made NaN or
//! huge) and given to the command that reads it. Every case must end in exit 0, or in exit 2 with
//! one error line naming the file (1 for `compensate` with some targets out of reach): never a
//! panic or an abort, never a hang (each case is killed after [`BOUND`]), never debris (no
//! temporary directory; after a refusal, no result).
//!
//! Seeded: each surface draws its cases from its own stream of `CALSIM_PROPERTY_SEED` (default 34),
//! `CALSIM_PROPERTY_CASES` per surface (default 4 in CI). The long run (`CALSIM_PROPERTY_CASES=300
//! cargo test --test properties -- --nocapture`) prints each surface's counts; with
//! `CALSIM_PROPERTY_LOG=<file>` it also writes every case's exit code and error line there.

mod common;

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::{Duration, Instant};

use common::{calsim, repo, scratch};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::Value;

/// Longest a case may take: a hang fails here instead of blocking the suite.
const BOUND: Duration = Duration::from_secs(180);

fn cases() -> usize {
    std::env::var("CALSIM_PROPERTY_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(4)
}

/// The stream of surface `surface`.
fn rng(surface: u64) -> ChaCha8Rng {
    let seed: u64 = std::env::var("CALSIM_PROPERTY_SEED").ok().and_then(|v| v.parse().ok()).unwrap_or(34);
    ChaCha8Rng::seed_from_u64(seed.wrapping_mul(1_000_003).wrapping_add(surface))
}

/// Numbers no input should take silently.
const EXTREMES: [&str; 16] = [
    "0",
    "-1",
    "-0.0",
    "1e308",
    "-1e308",
    "1e-320",
    "4294967295",
    "4294967296",
    "18446744073709551615",
    "99999999999999999999999999",
    "nan",
    "inf",
    "-inf",
    "0.5",
    "1000000",
    "2147483648",
];

/// Snippets that break a file's structure.
const JUNK: [&str; 12] = ["[", "]]]", "\"", "<x>", "</robot>", ",", "=", "\u{0}", "[[axis]]", "key = 1", "<link name=\"x\"/>", "é\u{202e}"];

/// One random change of `text`, line- or token-wise.
fn mutate_text(text: &str, rng: &mut ChaCha8Rng) -> String {
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    if lines.is_empty() {
        return "x".into();
    }
    let pick = |rng: &mut ChaCha8Rng, n: usize| rng.random_range(0..n);
    match rng.random_range(0..8) {
        0 => {
            let i = pick(rng, lines.len());
            lines.remove(i);
        }
        1 => {
            let i = pick(rng, lines.len());
            lines.insert(i, lines[i].clone());
        }
        2 => {
            let (i, j) = (pick(rng, lines.len()), pick(rng, lines.len()));
            lines.swap(i, j);
        }
        3 => {
            let joined = lines.join("\n");
            let mut cut = pick(rng, joined.len().max(1));
            while !joined.is_char_boundary(cut) {
                cut -= 1;
            }
            return joined[..cut].to_string();
        }
        4 | 5 => {
            // A number made extreme.
            let i = pick(rng, lines.len());
            let line = &lines[i];
            let starts: Vec<usize> = line
                .char_indices()
                .filter(|&(k, c)| {
                    c.is_ascii_digit() && (k == 0 || !line[..k].ends_with(|p: char| p.is_ascii_alphanumeric() || p == '.' || p == '_'))
                })
                .map(|(k, _)| k)
                .collect();
            if let Some(&s) = starts.get(pick(rng, starts.len().max(1))) {
                let end = line[s..]
                    .find(|c: char| !(c.is_ascii_alphanumeric() || c == '.' || c == '-' || c == '+'))
                    .map_or(line.len(), |e| s + e);
                let x = EXTREMES[pick(rng, EXTREMES.len())];
                lines[i] = format!("{}{x}{}", &line[..s], &line[end..]);
            } else {
                lines[i].push_str(EXTREMES[pick(rng, EXTREMES.len())]);
            }
        }
        6 => {
            let i = pick(rng, lines.len() + 1);
            lines.insert(i, JUNK[pick(rng, JUNK.len())].to_string());
        }
        _ => {
            // A line repeated many times (a file grown).
            let i = pick(rng, lines.len());
            let n = [10, 1000, 20_000][pick(rng, 3)];
            let copy = lines[i].clone();
            lines.splice(i..i, std::iter::repeat_n(copy, n));
        }
    }
    let mut out = lines.join("\n");
    if text.ends_with('\n') {
        out.push('\n');
    }
    out
}

/// Every path into `v` (object keys and array indices).
fn paths(v: &Value, at: &mut Vec<PathPart>, out: &mut Vec<Vec<PathPart>>) {
    out.push(at.clone());
    match v {
        Value::Object(m) => {
            for (k, x) in m {
                at.push(PathPart::Key(k.clone()));
                paths(x, at, out);
                at.pop();
            }
        }
        Value::Array(a) => {
            for (i, x) in a.iter().enumerate() {
                at.push(PathPart::Index(i));
                paths(x, at, out);
                at.pop();
            }
        }
        _ => {}
    }
}

#[derive(Clone, Debug)]
enum PathPart {
    Key(String),
    Index(usize),
}

fn at_mut<'a>(v: &'a mut Value, path: &[PathPart]) -> &'a mut Value {
    path.iter().fold(v, |v, p| match p {
        PathPart::Key(k) => &mut v[k.as_str()],
        PathPart::Index(i) => &mut v[*i],
    })
}

/// One random change of a JSON document: a key or element dropped, an element duplicated, an
/// array grown or shrunk, a value made an extreme number, null, a string or empty; or, one time
/// in five, a change of its text.
fn mutate_json(text: &str, rng: &mut ChaCha8Rng) -> String {
    let Ok(mut v) = serde_json::from_str::<Value>(text) else { return mutate_text(text, rng) };
    if rng.random_range(0..5) == 0 {
        return mutate_text(text, rng);
    }
    let mut all = Vec::new();
    paths(&v, &mut Vec::new(), &mut all);
    let path = all[rng.random_range(0..all.len())].clone();
    let op = rng.random_range(0..7);
    if let (Some((last, parent)), 0) = (path.split_last(), op) {
        match (at_mut(&mut v, parent), last) {
            (Value::Object(m), PathPart::Key(k)) => drop(m.remove(k)),
            (Value::Array(a), PathPart::Index(i)) => drop(a.remove(*i)),
            _ => {}
        }
        return v.to_string();
    }
    let node = at_mut(&mut v, &path);
    match (op, node) {
        (1, Value::Array(a)) if !a.is_empty() => {
            let i = rng.random_range(0..a.len());
            a.insert(i, a[i].clone());
        }
        (2, Value::Array(a)) if !a.is_empty() => {
            let n = [1, 100, 10_000][rng.random_range(0..3)];
            let last = a[a.len() - 1].clone();
            a.extend(std::iter::repeat_n(last, n));
        }
        (3, Value::Array(a)) => {
            a.pop();
        }
        (_, node) => {
            *node = match rng.random_range(0..6) {
                0 => Value::Null,
                1 => Value::String(["NaN", "", "x", "../.."][rng.random_range(0..4)].into()),
                2 => Value::Array(Vec::new()),
                3 => Value::Object(Default::default()),
                _ => serde_json::from_str(EXTREMES[rng.random_range(0..EXTREMES.len())]).unwrap_or(Value::from(f64::MAX)),
            };
        }
    }
    v.to_string()
}

/// How one case ended.
#[derive(Default)]
struct Counts {
    cases: usize,
    ok: usize,
    one: usize,
    refused: usize,
}

/// Runs `args` from `cwd` within [`BOUND`]: the exit code (`None`: a signal) and standard error.
fn run_in(cwd: &Path, args: &[&str]) -> (Option<i32>, String) {
    let t = Instant::now();
    let mut child = calsim().current_dir(cwd).args(args).stdout(Stdio::null()).stderr(Stdio::piped()).spawn().unwrap();
    let mut err_pipe = child.stderr.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = std::io::Read::read_to_string(&mut err_pipe, &mut s);
        s
    });
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if t.elapsed() > BOUND {
            let _ = child.kill();
            panic!("{args:?} in {}: no answer within {BOUND:?} (a hang)", cwd.display());
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    (status.code(), reader.join().unwrap())
}

/// Names under `dir` (recursively) that are calsim's temporary files or directories.
fn debris(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else { continue };
        for e in entries.flatten() {
            let p = e.path();
            if e.file_name().to_string_lossy().contains(".tmp-") {
                out.push(p.clone());
            }
            if p.is_dir() {
                stack.push(p);
            }
        }
    }
    out
}

/// The cases of one surface: its name, counts and log.
struct Surface {
    name: &'static str,
    counts: Counts,
    log: Option<std::fs::File>,
    /// Whether exit 1 is an answer (`compensate`: some targets out of reach).
    allow_one: bool,
}

impl Surface {
    fn new(name: &'static str, allow_one: bool) -> Self {
        let log = std::env::var_os("CALSIM_PROPERTY_LOG").map(|p| std::fs::OpenOptions::new().create(true).append(true).open(p).unwrap());
        Self { name, counts: Counts::default(), log, allow_one }
    }

    /// One case: `args` run in `dir`; its end checked (see the module doc) and counted. `names`: what
    /// the error line must hold one of (the file, or the files it may name); `result`: what a
    /// refusal must not leave.
    fn case(&mut self, dir: &Path, args: &[&str], names: &[&str], result: &Path) {
        let (code, err) = run_in(dir, args);
        self.counts.cases += 1;
        let (surface, n) = (self.name, self.counts.cases);
        let keep = || {
            let kept = std::env::temp_dir().join(format!("calsim-property-{surface}-{n}"));
            let _ = std::fs::remove_dir_all(&kept);
            let _ = std::process::Command::new("cp").arg("-r").arg(dir).arg(&kept).status();
            kept.display().to_string()
        };
        let error_lines: Vec<&str> = err.lines().filter(|l| !l.starts_with("calsim ")).collect();
        if let Some(log) = &mut self.log {
            // One write per line: the surfaces run in parallel into one log.
            let line = format!("{surface}\t{}\t{}\n", code.map_or("signal".into(), |c| c.to_string()), error_lines.join(" | "));
            let _ = log.write_all(line.as_bytes());
        }
        match code {
            Some(0) => self.counts.ok += 1,
            Some(1) if self.allow_one => self.counts.one += 1,
            Some(2) => {
                self.counts.refused += 1;
                assert!(
                    error_lines.len() == 1 && error_lines[0].starts_with("error: "),
                    "{surface}: {args:?}: one error line, not {err:?} (kept in {})",
                    keep()
                );
                assert!(
                    names.iter().any(|n| error_lines[0].contains(n)),
                    "{surface}: {args:?}: none of {names:?} in {err:?} (kept in {})",
                    keep()
                );
                assert!(!result.exists(), "{surface}: {args:?}: refused, yet {} was written (kept in {})", result.display(), keep());
            }
            _ => panic!("{surface}: {args:?}: exit {code:?}: {err} (kept in {})", keep()),
        }
        let left = debris(dir);
        assert!(left.is_empty(), "{surface}: {args:?}: temporary files left: {left:?}");
    }

    fn report(&self, what: &str) {
        let c = &self.counts;
        eprintln!("property {what}: {} cases: {} exit 0, {} exit 1, {} exit 2, 0 otherwise", c.cases, c.ok, c.one, c.refused);
    }
}

/// The reduced CI scenario (one set size, one repetition) with its robot file named absolutely.
fn small_scenario() -> String {
    common::scenario_text_anywhere("ci_quick.toml")
        .replace("set_sizes = [20, 50, 75, 100]", "set_sizes = [20]")
        .replace("repetitions = 10 ", "repetitions = 1 ")
        .replace("table_set_size = 75 ", "table_set_size = 20 ")
}

const SWEEP: &str = "base = \"base.toml\"\nrealisations = 2\nthresholds_mm = [0.5, 1.0]\n\n[objective]\nmaximise = \"success\"\nthreshold_mm = 0.5\nconfidence = 0.9\n\n[fixed]\n\"trical.epsilon_mm\" = 0.01\n\n[[axis]]\nkey = \"seed\"\nvalues = [1, 2]\n";

#[test]
fn sweep_files_mutated_at_random_run_or_are_refused_in_one_line() {
    let mut rng = rng(1);
    let mut surface = Surface::new("sweep", false);
    for _ in 0..cases() {
        let tmp = scratch("prop-sweep");
        let dir = tmp.path();
        std::fs::write(dir.join("base.toml"), small_scenario()).unwrap();
        let text = (0..rng.random_range(1..3)).fold(SWEEP.to_string(), |t, _| mutate_text(&t, &mut rng));
        std::fs::write(dir.join("s.toml"), text).unwrap();
        // One shard of many: a sweep grown to its limits runs a few units, not all of them.
        surface.case(dir, &["sweep", "s.toml", "--out", "out", "--shard", "0/1000"], &["s.toml"], &dir.join("out/s.shard-0-of-1000/units"));
    }
    surface.report("sweep files");
}

#[test]
fn shard_records_and_units_mutated_at_random_merge_or_are_refused_in_one_line() {
    let tmp = scratch("prop-shard");
    let dir = tmp.path();
    std::fs::write(dir.join("base.toml"), small_scenario()).unwrap();
    std::fs::write(dir.join("m.toml"), SWEEP).unwrap();
    let (code, err) = run_in(dir, &["sweep", "m.toml", "--out", "out", "--shard", "0/1"]);
    assert_eq!(code, Some(0), "{err}");
    let shard = dir.join("out/m.shard-0-of-1");
    let record = std::fs::read_to_string(shard.join("sweep.json")).unwrap();
    let units: Vec<(PathBuf, String)> =
        (0..4).map(|u| shard.join(format!("units/u{u:07}.json"))).map(|p| (p.clone(), std::fs::read_to_string(&p).unwrap())).collect();
    let mut rng = rng(2);
    let mut surface = Surface::new("shard", false);
    for _ in 0..cases() {
        // Three in four cases change the record, the others a unit.
        let (file, good) =
            if rng.random_range(0..4) > 0 { (shard.join("sweep.json"), record.clone()) } else { units[rng.random_range(0..4)].clone() };
        let text = (0..rng.random_range(1..3)).fold(good.clone(), |t, _| mutate_json(&t, &mut rng));
        std::fs::write(&file, text).unwrap();
        surface.case(
            dir,
            &["merge", "out/m.shard-0-of-1", "--out", "merged"],
            &["sweep.json", "/units/u", "work units", "m.shard-0-of-1"],
            &dir.join("merged/m"),
        );
        std::fs::write(&file, good).unwrap();
        let _ = std::fs::remove_dir_all(dir.join("merged"));
    }
    surface.report("shard records");
}

#[test]
fn robot_files_mutated_at_random_load_or_are_refused_in_one_line() {
    let arm = std::fs::read_to_string(repo().join("robots/irb120.toml")).unwrap();
    let tmp = scratch("prop-robot");
    let dir = tmp.path();
    std::fs::write(dir.join("joints.csv"), "q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n0,0,0,0,0,0\n10,-20,30,-40,50,-60\n").unwrap();
    let mut rng = rng(3);
    let mut surface = Surface::new("robot", false);
    for _ in 0..cases() {
        let text = (0..rng.random_range(1..3)).fold(arm.clone(), |t, _| mutate_text(&t, &mut rng));
        std::fs::write(dir.join("arm.toml"), text).unwrap();
        surface.case(dir, &["fk", "arm.toml", "joints.csv", "--out", "fk.csv"], &["arm.toml"], &dir.join("fk.csv"));
        let _ = std::fs::remove_file(dir.join("fk.csv"));
    }
    surface.report("robot files");
}

#[test]
fn urdfs_mutated_at_random_import_or_are_refused_in_one_line() {
    let urdf = std::fs::read_to_string(repo().join("robots/kr6r900sixx.urdf")).unwrap();
    let tmp = scratch("prop-urdf");
    let dir = tmp.path();
    let mut rng = rng(4);
    let mut surface = Surface::new("urdf", false);
    for _ in 0..cases() {
        let text = (0..rng.random_range(1..3)).fold(urdf.clone(), |t, _| mutate_text(&t, &mut rng));
        std::fs::write(dir.join("arm.urdf"), text).unwrap();
        surface.case(dir, &["import-urdf", "arm.urdf", "--out", "arm.toml"], &["arm.urdf"], &dir.join("arm.toml"));
        let _ = std::fs::remove_file(dir.join("arm.toml"));
    }
    surface.report("URDFs");
}

#[test]
fn target_csvs_mutated_at_random_compensate_or_are_refused_in_one_line() {
    let targets = std::fs::read_to_string(repo().join("docs/examples/targets.csv")).unwrap();
    let irb120 = repo().join("robots/irb120.toml");
    let tmp = scratch("prop-targets");
    let dir = tmp.path();
    let mut rng = rng(5);
    let mut surface = Surface::new("targets", true);
    for _ in 0..cases() {
        let text = (0..rng.random_range(1..3)).fold(targets.clone(), |t, _| mutate_text(&t, &mut rng));
        std::fs::write(dir.join("t.csv"), text).unwrap();
        surface.case(dir, &["compensate", irb120.to_str().unwrap(), "t.csv", "--out", "c.csv"], &["t.csv"], &dir.join("c.csv"));
        let _ = std::fs::remove_file(dir.join("c.csv"));
    }
    surface.report("target CSVs");
}

#[test]
fn measurement_csvs_mutated_at_random_calibrate_or_are_refused_in_one_line() {
    let measurements = std::fs::read_to_string(repo().join("docs/calibrate/example_measurements.csv")).unwrap();
    let irb120 = repo().join("robots/irb120.toml");
    let tmp = scratch("prop-measurements");
    let dir = tmp.path();
    let mut rng = rng(6);
    let mut surface = Surface::new("measurements", false);
    for _ in 0..cases() {
        let text = (0..rng.random_range(1..3)).fold(measurements.clone(), |t, _| mutate_text(&t, &mut rng));
        std::fs::write(dir.join("m.csv"), text).unwrap();
        let result = dir.join("out/m.calibration");
        surface.case(dir, &["calibrate", irb120.to_str().unwrap(), "m.csv", "--out", "out", "--no-plots"], &["m.csv"], &result);
        let _ = std::fs::remove_dir_all(dir.join("out"));
    }
    surface.report("measurement CSVs");
}
