//! Property: whatever one defect a scenario file of either kind carries (a number turned NaN,
//! infinite, zero, negative or huge, a value of another type, an array shortened, emptied or
//! lengthened, a key dropped), `calsim run` exits 0 or 2, never panics, answers bad input in one
//! line, and returns within a time bound.
//!
//! The mutations are drawn by proptest from a fixed seed: 12 cases per kind in CI (about a minute
//! in the test profile); `CALSIM_FUZZ_CASES=500 cargo test --test fuzz_scenarios` runs more.

mod common;

use std::path::Path;
use std::time::{Duration, Instant};

use proptest::prelude::*;
use proptest::test_runner::{Config, RngAlgorithm, TestCaseError, TestRng, TestRunner};

/// Longest a mutated run may take (the base scenarios take a few seconds in the test profile).
const BOUND: Duration = Duration::from_secs(90);

#[derive(Clone, Debug)]
enum Seg {
    Key(String),
    Index(usize),
}

/// Every value under `v` (tables excluded) by its path.
fn leaves(v: &toml::Value, path: &mut Vec<Seg>, out: &mut Vec<Vec<Seg>>) {
    match v {
        toml::Value::Table(t) => {
            for (k, v) in t {
                path.push(Seg::Key(k.clone()));
                leaves(v, path, out);
                path.pop();
            }
        }
        toml::Value::Array(a) => {
            out.push(path.clone());
            for (i, v) in a.iter().enumerate() {
                path.push(Seg::Index(i));
                leaves(v, path, out);
                path.pop();
            }
        }
        _ => out.push(path.clone()),
    }
}

fn at<'a>(v: &'a mut toml::Value, path: &[Seg]) -> &'a mut toml::Value {
    path.iter().fold(v, |v, s| match (s, v) {
        (Seg::Key(k), toml::Value::Table(t)) => t.get_mut(k).expect("path exists"),
        (Seg::Index(i), toml::Value::Array(a)) => &mut a[*i],
        _ => unreachable!("paths come from the same value"),
    })
}

/// Applies mutation `m` to the value at `path`.
fn mutate(doc: &toml::Value, path: &[Seg], m: usize) -> toml::Value {
    let mut doc = doc.clone();
    let replacement = match m {
        0 => Some(toml::Value::Float(f64::NAN)),
        1 => Some(toml::Value::Float(f64::INFINITY)),
        2 => Some(toml::Value::Float(f64::NEG_INFINITY)),
        3 => Some(toml::Value::Integer(0)),
        4 => Some(toml::Value::Float(0.0)),
        5 => Some(toml::Value::Integer(-1)),
        6 => Some(toml::Value::Float(-1.0)),
        7 => Some(toml::Value::Float(1e300)),
        8 => Some(toml::Value::Integer(4_294_967_295)),
        9 => Some(toml::Value::Integer(i64::MAX)),
        10 => Some(toml::Value::String("x".into())),
        _ => None,
    };
    if let Some(r) = replacement {
        *at(&mut doc, path) = r;
        return doc;
    }
    let (last, parent) = path.split_last().expect("a leaf has a path");
    match m {
        // Shorten, empty or lengthen an array (or, for a scalar, drop its key / element).
        11..=13 => match at(&mut doc, path) {
            toml::Value::Array(a) if m == 11 => {
                a.pop();
            }
            toml::Value::Array(a) if m == 12 => a.clear(),
            toml::Value::Array(a) => {
                let first = a.first().cloned().unwrap_or(toml::Value::Integer(1));
                a.push(first);
            }
            _ => drop_at(&mut doc, parent, last),
        },
        _ => drop_at(&mut doc, parent, last),
    }
    doc
}

fn drop_at(doc: &mut toml::Value, parent: &[Seg], last: &Seg) {
    match (at(doc, parent), last) {
        (toml::Value::Table(t), Seg::Key(k)) => {
            t.remove(k);
        }
        (toml::Value::Array(a), Seg::Index(i)) => {
            a.remove(*i);
        }
        _ => {}
    }
}

const MUTATIONS: usize = 15;

/// Runs `calsim run` on `doc` written to `dir/name` and checks the property.
fn run_case(doc: &toml::Value, dir: &Path, name: &str) -> Result<(), TestCaseError> {
    let file = dir.join(name);
    std::fs::write(&file, toml::to_string(doc).expect("serialisable")).unwrap();
    let t = Instant::now();
    let mut child = common::calsim()
        .args(["run", "--no-plots", "--no-recording", "--out"])
        .arg(dir.join("out"))
        .arg(&file)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if t.elapsed() > BOUND {
            let _ = child.kill();
            return Err(TestCaseError::fail(format!("{name}: no answer within {BOUND:?}: {}", toml::to_string(doc).unwrap())));
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let mut err = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut err).unwrap();
    let code = status.code();
    prop_assert!(code == Some(0) || code == Some(2), "exit {code:?}: {err}");
    prop_assert!(!err.contains("panicked"), "panic: {err}");
    if code == Some(2) {
        let lines: Vec<&str> = err.lines().filter(|l| l.starts_with("error")).collect();
        prop_assert_eq!(lines.len(), 1, "one error line: {}", err);
        prop_assert!(lines[0].contains(name), "the error names the file: {}", err);
    }
    Ok(())
}

fn base(path: &str, edit: impl Fn(&mut toml::Table)) -> toml::Value {
    let name = path.strip_prefix("scenarios/").expect("a scenario of the repo");
    let mut t: toml::Table = toml::from_str(&common::scenario_text_anywhere(name)).unwrap();
    edit(&mut t);
    toml::Value::Table(t)
}

fn set(t: &mut toml::Table, section: &str, key: &str, v: toml::Value) {
    t.entry(section).or_insert_with(|| toml::Value::Table(toml::Table::new())).as_table_mut().unwrap().insert(key.into(), v);
}

fn fuzz(kind: &str, doc: toml::Value) {
    let cases = std::env::var("CALSIM_FUZZ_CASES").ok().and_then(|c| c.parse().ok()).unwrap_or(12);
    let tmp = common::scratch(&format!("fuzz-{kind}"));
    let dir = tmp.path();
    let mut paths = Vec::new();
    leaves(&doc, &mut Vec::new(), &mut paths);
    let config = Config { cases, failure_persistence: None, ..Config::default() };
    let mut runner = TestRunner::new_with_rng(config, TestRng::deterministic_rng(RngAlgorithm::ChaCha));
    let n = paths.len();
    let result =
        runner.run(&(0..n, 0..MUTATIONS), |(leaf, m)| run_case(&mutate(&doc, &paths[leaf], m), dir, &format!("{kind}_{leaf}_{m}.toml")));
    if let Err(e) = result {
        panic!("{e}");
    }
}

#[test]
fn mutated_trical_scenarios_exit_0_or_2() {
    let doc = base("scenarios/ci_quick.toml", |t| {
        set(t, "study", "set_sizes", toml::Value::Array(vec![toml::Value::Integer(20), toml::Value::Integer(30)]));
        set(t, "study", "table_set_size", toml::Value::Integer(30));
        set(t, "study", "repetitions", toml::Value::Integer(2));
        t.remove("expect");
    });
    fuzz("trical", doc);
}

#[test]
fn mutated_spms_scenarios_exit_0_or_2() {
    let doc = base("scenarios/er20c10_spms.toml", |t| {
        set(t, "beams", "pso_population", toml::Value::Integer(200));
        set(t, "beams", "pso_iterations", toml::Value::Integer(10));
        set(t, "station", "pool", toml::Value::Integer(90));
        set(t, "study", "set_sizes", toml::Value::Array(vec![toml::Value::Integer(20), toml::Value::Integer(30)]));
        set(t, "study", "table_set_size", toml::Value::Integer(30));
        set(t, "study", "repetitions", toml::Value::Integer(2));
        t.remove("expect");
    });
    fuzz("spms", doc);
}
