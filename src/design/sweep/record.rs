//! The record a shard directory keeps of its sweep (`sweep.json`, [`ShardInfo`]): how it stores
//! every grid point's scenario, and its check as a whole before `merge` trusts any of it.
//!
//! **Storage.** The scenario of grid point 0 is kept once as TOML, every point as the changes of
//! its scenario from it (a dotted key and its value as TOML, or its removal). The record then grows
//! with what varies between points, not with points x scenario size: a 9,001-point sweep of seeds
//! keeps about 1 MB instead of 21 MB, under the 16 MiB that calsim reads of any input
//! ([`crate::io::MOST_INPUT_BYTES`]), and a sweep whose record would not fit is refused before it
//! runs (`run_shard`): calsim never writes a record it cannot read back.
//!
//! **Check.** A record is written by calsim, but a shard directory travels (clusters, copies,
//! edits): before anything is allocated or summed from it, [`check`] holds it against itself and
//! against the bounds the sweep loader allows (points, realisations, points x realisations,
//! thresholds, keys, objective, race), re-loads every point's scenario through the device loader
//! (garbage never becomes a `best_design.toml`), and returns what each point's study promises its
//! units: their selections, set sizes and repetitions ([`PointStudy`]), which `Unit::check`
//! holds every unit to. Every refusal names the record's file and its key.

use std::path::Path;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::objective::{Goal, Objective};
use super::spec::{MAX_POINTS, MAX_REALISATIONS, MOST_KEY_PARTS};
use super::{MergeError, ShardInfo};
use crate::device::Scenario;

/// One change of a grid point's scenario from grid point 0's.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Change {
    /// The key, one part per table level (`["cell", "spheres_w_mm"]`).
    pub key: Vec<String>,
    /// Its value as TOML (`[[0.0, 0.0, 0.0], ...]`), or `None`: the point has no such key.
    pub value: Option<String>,
}

/// The changes that make table `t` of `base`, in key order.
pub fn changes(base: &toml::Table, t: &toml::Table) -> Vec<Change> {
    let mut out = Vec::new();
    diff_into(base, t, &mut Vec::new(), &mut out);
    out
}

fn diff_into(base: &toml::Table, t: &toml::Table, path: &mut Vec<String>, out: &mut Vec<Change>) {
    let at = |path: &[String], k: &str| path.iter().cloned().chain([k.to_string()]).collect::<Vec<_>>();
    for (k, v) in t {
        match (base.get(k), v) {
            (Some(b), v) if b == v => {}
            (b, toml::Value::Table(x)) => {
                let empty = toml::Table::new();
                let b = match b {
                    Some(toml::Value::Table(b)) => b,
                    Some(_) => {
                        out.push(Change { key: at(path, k), value: None });
                        &empty
                    }
                    None => &empty,
                };
                if x.is_empty() {
                    out.push(Change { key: at(path, k), value: Some("{}".into()) });
                } else {
                    path.push(k.clone());
                    diff_into(b, x, path, out);
                    path.pop();
                }
            }
            (_, v) => out.push(Change { key: at(path, k), value: Some(v.to_string()) }),
        }
    }
    for k in base.keys().filter(|k| !t.contains_key(*k)) {
        out.push(Change { key: at(path, k), value: None });
    }
}

/// `base` with `changes` made (a missing table on the way is made); an error says which change
/// cannot be made and why.
pub fn apply(base: &toml::Table, changes: &[Change]) -> Result<toml::Table, (usize, String)> {
    let mut t = base.clone();
    for (i, c) in changes.iter().enumerate() {
        let fail = |why: String| Err((i, why));
        if c.key.is_empty() || c.key.len() > MOST_KEY_PARTS || c.key.iter().any(|p| p.is_empty()) {
            return fail(format!("key {:?}: 1 to {MOST_KEY_PARTS} parts, none empty", c.key));
        }
        let (last, parents) = c.key.split_last().expect("checked not empty");
        let mut cur = &mut t;
        for p in parents {
            let entry = cur.entry(p.clone()).or_insert_with(|| toml::Value::Table(toml::Table::new()));
            match entry.as_table_mut() {
                Some(next) => cur = next,
                None => return fail(format!("key {}: {p} is not a table", c.key.join("."))),
            }
        }
        match &c.value {
            None => {
                if cur.remove(last).is_none() {
                    return fail(format!("key {}: removed, but grid point 0's scenario has no such key", c.key.join(".")));
                }
            }
            Some(text) => {
                let doc: toml::Table = match toml::from_str::<toml::Table>(&format!("v = {text}")) {
                    Ok(doc) => doc,
                    Err(e) => return fail(format!("key {}: value {text:?} is not one TOML value ({})", c.key.join("."), e.message())),
                };
                match (doc.len(), doc.get("v")) {
                    (1, Some(v)) => {
                        cur.insert(last.clone(), v.clone());
                    }
                    _ => return fail(format!("key {}: value {text:?} is not one TOML value", c.key.join("."))),
                }
            }
        }
    }
    Ok(t)
}

/// What a grid point's study promises each of its units: one row per selection and set size, each
/// over `repetitions`, the row of `table_set_size` marked as the table's.
#[derive(Clone, Debug, PartialEq)]
pub struct PointStudy {
    /// Selection labels.
    pub selections: Vec<&'static str>,
    /// Set sizes.
    pub set_sizes: Vec<u32>,
    /// Repetitions per selection and set size.
    pub repetitions: u32,
    /// The table set size.
    pub table_set_size: u32,
}

impl PointStudy {
    /// The promise of a loaded point scenario.
    pub fn of(s: &dyn Scenario) -> Self {
        let st = s.study();
        Self {
            selections: st.selections.iter().map(|x| x.label()).collect(),
            set_sizes: st.set_sizes.clone(),
            repetitions: st.repetitions,
            table_set_size: st.table_set_size,
        }
    }
}

/// Most shards of a sweep (the command line's `--shard k/K` takes K up to this).
pub const MOST_SHARDS: usize = 100_000;

/// Most work units of a sweep (points x realisations), as the sweep loader allows.
pub const MOST_UNITS: u64 = 1_000_000;

/// Column names of the result tables a key of an axis must not take.
const COLUMNS: [&str; 12] = [
    "unit",
    "point",
    "realisation",
    "error",
    "selection",
    "set_size",
    "table_set_size",
    "repetitions",
    "no_model",
    "rank",
    "objective",
    "estimate",
];

/// Checks the record `info` read from `file` as a whole (see the module doc) and returns each grid
/// point's promise to its units.
pub fn check(info: &ShardInfo, file: &Path) -> Result<Vec<PointStudy>, MergeError> {
    let fail = |key: &str, why: String| MergeError::Record { path: crate::io::names::shown(file), key: key.into(), why };
    if let Some(why) = crate::io::names::rule_broken(&info.name) {
        return Err(fail("name", format!("{:?} cannot name results: {why}", crate::io::names::escape_controls(&info.name))));
    }
    if info.identity.len() != 64 || !info.identity.bytes().all(|b| b.is_ascii_hexdigit()) {
        return Err(fail("identity", "not the sha256 calsim writes (64 hexadecimal digits)".into()));
    }
    if !(1..=MOST_SHARDS).contains(&info.count) {
        return Err(fail("count", format!("{}: a number of shards within [1, {MOST_SHARDS}]", info.count)));
    }
    if info.shard >= info.count {
        return Err(fail("shard", format!("{}: shards are numbered 0 to count - 1 = {}", info.shard, info.count - 1)));
    }
    let points = info.points.len();
    if !(1..=MAX_POINTS).contains(&points) {
        return Err(fail("points", format!("{points} grid points: within [1, {MAX_POINTS}]")));
    }
    if !(1..=MAX_REALISATIONS).contains(&info.realisations) {
        return Err(fail("realisations", format!("{}: within [1, {MAX_REALISATIONS}]", info.realisations)));
    }
    let units = points as u64 * u64::from(info.realisations);
    if units > MOST_UNITS {
        return Err(fail(
            "realisations",
            format!("{points} points x {} realisations = {units} work units: at most {MOST_UNITS}", info.realisations),
        ));
    }
    check_thresholds(&info.thresholds_mm).map_err(|why| fail("thresholds_mm", why))?;
    check_keys(&info.keys).map_err(|(k, why)| fail(&k, why))?;
    if let Some(p) = info.points.iter().position(|v| v.len() != info.keys.len()) {
        return Err(fail(&format!("points[{p}]"), format!("{} axis values for {} keys", info.points[p].len(), info.keys.len())));
    }
    check_objective(&info.objective, &info.thresholds_mm).map_err(|(k, why)| fail(&k, why))?;
    if let Some(r) = &info.race {
        check_race(r, info.realisations).map_err(|(k, why)| fail(&k, why))?;
    }
    for (key, n) in [("layouts", info.layouts.len()), ("changes", info.changes.len())] {
        if n != points {
            return Err(fail(key, format!("{n} entries for {points} grid points")));
        }
    }
    // Where each point's robot stands (drawn in the layout figures only): none, one for every point, or one per point,
    // each finite, within a kilometre, its up axis a unit vector.
    if info.robots.len() > 1 && info.robots.len() != points {
        return Err(fail("robots", format!("{} entries for {points} grid points", info.robots.len())));
    }
    for (p, r) in info.robots.iter().enumerate() {
        let Some(r) = r else { continue };
        let reach = [r.reach_mm, r.horizontal_reach_mm];
        let mut coords = r.base_w_mm.iter().chain(&r.shoulder_w_mm).chain(&reach);
        let sane = coords.all(|x| x.is_finite() && x.abs() <= 1e6) && r.reach_mm >= 0.0 && r.horizontal_reach_mm >= 0.0;
        let norm = r.base_up_w.iter().map(|x| x * x).sum::<f64>().sqrt();
        if !sane || !((norm - 1.0).abs() <= 1e-6) {
            return Err(fail(&format!("robots[{p}]"), "not a robot's place in the cell (finite mm within 1 km, a unit up axis)".into()));
        }
    }
    let base = toml::from_str::<toml::Table>(&info.scenario)
        .map_err(|e: toml::de::Error| fail("scenario", format!("not TOML: {}", e.message())))?;
    // Loading a scenario checks it whole (the identifiability of its parameters among it): the
    // points load in parallel, and the first failing point in grid order is the one named.
    let studies: Vec<Result<PointStudy, MergeError>> = (0..points)
        .into_par_iter()
        .map(|p| {
            let table = apply(&base, &info.changes[p]).map_err(|(i, why)| fail(&format!("changes[{p}][{i}]"), why))?;
            let text = toml::to_string(&table).map_err(|e| fail(&format!("changes[{p}]"), e.to_string()))?;
            let s = crate::device::from_table(&text, table, Path::new(&format!("{}#{p}", info.name)))
                .map_err(|e| fail(&format!("scenario of grid point {p}"), e.to_string()))?;
            let layout = s.layout_mm();
            let same = layout.len() == info.layouts[p].len()
                && layout.iter().zip(&info.layouts[p]).all(|(a, b)| a.iter().zip(b).all(|(x, y)| (x - y).abs() <= 1e-6));
            if !same {
                return Err(fail(&format!("layouts[{p}]"), "not the datum spheres of the point's scenario".into()));
            }
            Ok(PointStudy::of(s.as_ref()))
        })
        .collect();
    studies.into_iter().collect()
}

/// The thresholds as the sweep loader allows them: at most 16, each within (0, 1000) mm, once.
fn check_thresholds(t: &[f64]) -> Result<(), String> {
    if t.len() > 16 {
        return Err(format!("{} thresholds: at most 16", t.len()));
    }
    if let Some(x) = t.iter().find(|x| !(x.is_finite() && **x > 0.0 && **x < 1000.0)) {
        return Err(format!("{x}: each threshold within (0, 1000) mm"));
    }
    if let Some(x) = t.iter().enumerate().find(|(i, x)| t[..*i].contains(x)).map(|(_, x)| x) {
        return Err(format!("{x} given twice: each threshold once"));
    }
    Ok(())
}

/// The axes' keys: each a dotted key of at most [`MOST_KEY_PARTS`] plain parts, given once, no
/// column name of the tables.
fn check_keys(keys: &[String]) -> Result<(), (String, String)> {
    for (a, k) in keys.iter().enumerate() {
        let fail = |why: &str| Err((format!("keys[{a}]"), format!("{:?}: {why}", crate::io::names::escape_controls(k))));
        let parts: Vec<&str> = k.split('.').collect();
        if k.len() > 200 || parts.len() > MOST_KEY_PARTS || parts.iter().any(|p| p.is_empty()) {
            return fail(&format!("not a dotted scenario key (at most {MOST_KEY_PARTS} parts, 200 bytes)"));
        }
        if k.chars().any(crate::io::names::is_line_or_control) {
            return fail("holds a control character or a line break");
        }
        if keys[..a].contains(k) {
            return fail("the key of an earlier axis");
        }
        if COLUMNS.contains(&k.as_str()) {
            return fail("the name of a column of the result tables");
        }
    }
    Ok(())
}

/// The objective as the sweep loader allows it (`objective::ObjectiveFile::check`), its threshold
/// one of the sweep's.
fn check_objective(o: &Objective, thresholds: &[f64]) -> Result<(), (String, String)> {
    let fail = |k: &str, m: String| Err((format!("objective.{k}"), m));
    if !(o.confidence.is_finite() && (0.5..=0.999).contains(&o.confidence)) {
        return fail("confidence", format!("{}: within [0.5, 0.999]", o.confidence));
    }
    match o.threshold_mm {
        Some(t) if !thresholds.contains(&t) => return fail("threshold_mm", format!("{t}: not one of thresholds_mm {thresholds:?}")),
        None if o.goal == Goal::MaximiseSuccess || o.success_at_least.is_some() => {
            return fail("threshold_mm", "success needs its threshold".into());
        }
        _ => {}
    }
    if let Some(p) = o.success_at_least
        && !(p.is_finite() && p > 0.0 && p < 1.0)
    {
        return fail("success_at_least", format!("{p}: a probability within (0, 1)"));
    }
    if let Some(h) = o.campaign_h_at_most
        && !(h.is_finite() && h > 0.0 && h <= 1e4)
    {
        return fail("campaign_h_at_most", format!("{h}: hours within (0, 10000]"));
    }
    if o.set_size_at_most == Some(0) {
        return fail("set_size_at_most", "0: a set size of at least 1".into());
    }
    Ok(())
}

/// Adaptive realisations as the sweep loader allows them, their most the record's realisations.
fn check_race(r: &super::race::Race, realisations: u32) -> Result<(), (String, String)> {
    let fail = |k: &str, m: String| Err((format!("race.{k}"), m));
    if r.max != realisations {
        return fail("max", format!("{}: not the record's realisations = {realisations}", r.max));
    }
    if !(1..=r.max).contains(&r.min) {
        return fail("min", format!("{}: within [1, max = {}]", r.min, r.max));
    }
    if !(1..=MAX_REALISATIONS).contains(&r.batch) {
        return fail("batch", format!("{}: within [1, {MAX_REALISATIONS}]", r.batch));
    }
    if !(r.confidence.is_finite() && (0.5..=0.999).contains(&r.confidence)) {
        return fail("confidence", format!("{}: within [0.5, 0.999]", r.confidence));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(s: &str) -> toml::Table {
        toml::from_str(s).unwrap()
    }

    #[test]
    fn changes_made_to_the_base_give_back_each_table() {
        let base = table("seed = 1\n[cell]\nspheres_w_mm = [[0.0, 0.0, 0.0]]\nx = 2\n[study]\nset_sizes = [20]\n");
        for t in [
            "seed = 2\n[cell]\nspheres_w_mm = [[0.0, 0.0, 0.0], [300.0, 0.1, 0.0]]\nx = 2\n[study]\nset_sizes = [20]\n",
            "seed = 1\n[cell]\nx = 2.5\n[study]\nset_sizes = [20]\n[robot.unmodelled]\nbacklash_mdeg = 1.0\n",
            "seed = 1\ncell = 3\nstudy = {}\n",
            "seed = 1\n[cell]\nspheres_w_mm = [[0.0, 0.0, 0.0]]\nx = 2\n[study]\nset_sizes = [20]\n",
        ] {
            let t = table(t);
            let c = changes(&base, &t);
            assert_eq!(apply(&base, &c).unwrap(), t, "{c:?}");
        }
        assert!(changes(&base, &base).is_empty());
    }

    #[test]
    fn a_change_that_is_not_one_value_or_removes_nothing_is_refused_naming_it() {
        let base = table("seed = 1\n[cell]\nx = 2\n");
        let c = |key: &[&str], value: Option<&str>| Change {
            key: key.iter().map(|s| s.to_string()).collect(),
            value: value.map(str::to_string),
        };
        for (changes, why) in [
            (vec![c(&["seed"], Some("1\n[evil]\ny = 2"))], "not one TOML value"),
            (vec![c(&["seed"], Some("[1,"))], "not one TOML value"),
            (vec![c(&["seed", "x"], Some("1"))], "seed is not a table"),
            (vec![c(&["cell", "y"], None)], "no such key"),
            (vec![c(&[], Some("1"))], "parts"),
            (vec![c(&["cell", ""], Some("1"))], "parts"),
            (vec![c(&["a"; 17], Some("1"))], "parts"),
        ] {
            let (i, e) = apply(&base, &changes).unwrap_err();
            assert_eq!(i, 0);
            assert!(e.contains(why), "{e}");
        }
    }
}
