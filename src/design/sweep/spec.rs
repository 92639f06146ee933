//! A sweep file: a base scenario, axes over its keys by dotted path, the number of realisations,
//! the success thresholds; expanded into grid points, each a scenario validated like any other
//! before anything runs.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::device::scenario::{self, ScenarioError};
use crate::device::{self, Scenario};

/// Most grid points of a sweep, and most realisations per point.
pub const MAX_POINTS: usize = 10_000;
/// Most realisations per grid point.
pub const MAX_REALISATIONS: u32 = 10_000;

/// How the axes combine.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Combine {
    /// Every combination of the axes' values.
    #[default]
    Product,
    /// The axes' values side by side (all axes of one length).
    Zip,
}

/// A range of numbers, both ends included.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Range {
    /// First value.
    pub start: f64,
    /// Last value (included when the steps land on it).
    pub stop: f64,
    /// Step, > 0.
    pub step: f64,
}

/// One axis: a scenario key and its values.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Axis {
    /// Dotted key of the scenario (`trical.epsilon_mm`, `cell.spheres_w_mm`), or `cell.layout`
    /// for a named sphere layout (`{ n = 4, spacing_mm = 300 }`: n spheres on a circle).
    pub key: String,
    /// The values, as TOML values of the key's type.
    pub values: Option<Vec<toml::Value>>,
    /// Or a range of numbers.
    pub range: Option<Range>,
}

/// The sweep file as written.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SweepFile {
    base: PathBuf,
    /// A count, or `{ max, confidence, batch, min }` for adaptive realisations.
    #[serde(default)]
    realisations: Option<toml::Value>,
    #[serde(default)]
    objective: Option<super::objective::ObjectiveFile>,
    #[serde(default)]
    combine: Combine,
    #[serde(default)]
    thresholds_mm: Vec<f64>,
    /// Keys set at every grid point (dotted, quoted: `"study.set_sizes" = [75]`).
    #[serde(default)]
    fixed: toml::Table,
    #[serde(default, rename = "axis")]
    axes: Vec<Axis>,
}

/// One grid point: its axis values and its checked scenario.
#[derive(Clone, Debug)]
pub struct Point {
    /// The axis values, as written (`key = value`).
    pub values: Vec<(String, String)>,
    /// The scenario of the point (a unit's study, without the compensated validation: a unit's
    /// tables hold the plain validation).
    pub scenario: Box<dyn Scenario>,
}

/// A loaded, checked sweep.
#[derive(Clone, Debug)]
pub struct Sweep {
    /// Name (the sweep file's stem).
    pub name: String,
    /// Realisations per grid point (the most, for adaptive realisations).
    pub realisations: u32,
    /// Command-line changes to the sweep file (`key`, TOML value): `realisations` when given.
    pub overrides: Vec<(String, String)>,
    /// Adaptive realisations, when the sweep races its designs.
    pub race: Option<super::race::Race>,
    /// What the sweep decides.
    pub objective: super::objective::Objective,
    /// Success thresholds on the after-calibration error, mm.
    pub thresholds_mm: Vec<f64>,
    /// The axes' keys.
    pub keys: Vec<String>,
    /// The grid.
    pub points: Vec<Point>,
    /// sha256 of the sweep file and the base scenario: shards of one sweep carry the same.
    pub identity: String,
    /// Whether each unit also makes the linear prediction at the table set size (the budget's).
    pub predict: bool,
}

/// A sweep that cannot run.
#[derive(Debug, thiserror::Error)]
pub enum SweepError {
    /// The sweep file itself.
    #[error("{path}: {key}: {message}")]
    File {
        /// Sweep file.
        path: String,
        /// Key.
        key: String,
        /// What is wrong.
        message: String,
    },
    /// A grid point is not a valid scenario.
    #[error("{path}: axis {axis}: {error}")]
    Point {
        /// Sweep file.
        path: String,
        /// The axis values of the point.
        axis: String,
        /// The scenario error.
        error: Box<ScenarioError>,
    },
}

fn file_err(path: &Path, key: &str, message: impl Into<String>) -> SweepError {
    SweepError::File { path: path.display().to_string(), key: key.into(), message: message.into() }
}

/// Most parts of a dotted key: a scenario nests its keys three deep; a deeper key would build
/// tables whose dropping and printing recurse once per part (100,000 parts overflow the stack).
pub const MOST_KEY_PARTS: usize = 16;

/// Sets `key` (dotted) of `t` to `v`, making the tables on the way; a key under a value that is not
/// a table, or of more than [`MOST_KEY_PARTS`] parts, is an error.
pub fn set_dotted(t: &mut toml::Table, key: &str, v: toml::Value) -> Result<(), String> {
    if key.split('.').nth(MOST_KEY_PARTS).is_some() {
        return Err(format!("a key of more than {MOST_KEY_PARTS} dotted parts: no scenario key is that deep"));
    }
    let parts: Vec<&str> = key.split('.').collect();
    if parts.iter().any(|p| p.is_empty()) {
        return Err(format!("{key:?} is not a dotted key"));
    }
    let (last, parents) = parts.split_last().expect("split gives one part at least");
    let mut cur = t;
    for p in parents {
        let entry = cur.entry(p.to_string()).or_insert_with(|| toml::Value::Table(toml::Table::new()));
        cur = entry.as_table_mut().ok_or_else(|| format!("{p} in {key} is not a table"))?;
    }
    cur.insert(last.to_string(), v);
    Ok(())
}

/// The sphere centres of a named layout: `n` spheres on a circle whose neighbours are `spacing_mm`
/// apart, sphere 1 at the origin of {W}, sphere 2 on +x, the rest counter-clockwise (eqs. 1-5).
pub fn circle_layout(n: usize, spacing_mm: f64) -> Vec<[f64; 3]> {
    let step = std::f64::consts::TAU / n as f64;
    let r = spacing_mm / (2.0 * (step / 2.0).sin());
    // Points on the circle, rotated so that sphere 1 -> sphere 2 runs along +x from the origin.
    let p: Vec<(f64, f64)> = (0..n).map(|k| (r * (k as f64 * step).cos(), r * (k as f64 * step).sin())).collect();
    let (dx, dy) = (p[1].0 - p[0].0, p[1].1 - p[0].1);
    let a = dy.atan2(dx);
    let (c, s) = (a.cos(), a.sin());
    p.iter()
        .map(|&(x, y)| {
            let (x, y) = (x - p[0].0, y - p[0].1);
            let (xr, yr) = (c * x + s * y, -s * x + c * y);
            // Round off the last bits so that sphere 2 lies exactly on +x and sphere 1 at 0.
            let snap = |v: f64| if v.abs() < 1e-9 { 0.0 } else { v };
            [snap(xr), snap(yr), 0.0]
        })
        .collect()
}

/// The sphere centres of `n` spheres on a line along +x, neighbours `spacing_mm` apart.
pub fn line_layout(n: usize, spacing_mm: f64) -> Vec<[f64; 3]> {
    (0..n).map(|k| [k as f64 * spacing_mm, 0.0, 0.0]).collect()
}

/// The keys a named layout takes.
const LAYOUT_KEYS: [&str; 5] = ["n", "spacing_mm", "shape", "height_mm", "tilt_deg"];

/// The values an axis puts at its key: a named layout (`{ n, spacing_mm, shape = "circle" |
/// "line", height_mm = 0, tilt_deg = 0 }`) becomes `cell.spheres_w_mm`, and, when it raises or
/// tilts the plate, `cell.plate_offset_mm_deg` (the spheres `height_mm` higher relative to the
/// robot, the plate turned `tilt_deg` about the line of spheres 1 and 2).
fn resolve(key: &str, v: &toml::Value) -> Result<Vec<(String, toml::Value)>, String> {
    if key != "cell.layout" {
        return Ok(vec![(key.to_string(), v.clone())]);
    }
    let t = v.as_table().ok_or("a layout is a table { n = ..., spacing_mm = ... }")?;
    let num = |k: &str| t.get(k).and_then(|v| v.as_float().or(v.as_integer().map(|i| i as f64)));
    let n = t.get("n").and_then(toml::Value::as_integer).ok_or("layout.n: the number of spheres, 3 to 6")?;
    let s = num("spacing_mm").ok_or("layout.spacing_mm: a number")?;
    if let Some(k) = t.keys().find(|k| !LAYOUT_KEYS.contains(&k.as_str())) {
        return Err(format!("layout.{k}: unknown (a layout has the keys {})", LAYOUT_KEYS.join(", ")));
    }
    if !(3..=6).contains(&n) {
        return Err(format!("layout.n = {n}: 3 to 6 spheres"));
    }
    if !(s.is_finite() && (50.0..=2000.0).contains(&s)) {
        return Err(format!("layout.spacing_mm = {s}: within [50, 2000] mm"));
    }
    let optional = |k: &str, lo: f64, hi: f64| -> Result<f64, String> {
        match (t.get(k), num(k)) {
            (None, _) => Ok(0.0),
            (Some(_), Some(x)) if x.is_finite() && (lo..=hi).contains(&x) => Ok(x),
            (Some(v), _) => Err(format!("layout.{k} = {v}: a number within [{lo}, {hi}]")),
        }
    };
    let (height, tilt) = (optional("height_mm", -1000.0, 1000.0)?, optional("tilt_deg", -60.0, 60.0)?);
    let pts = match t.get("shape").map(|v| v.as_str()) {
        None | Some(Some("circle")) => circle_layout(n as usize, s),
        Some(Some("line")) => line_layout(n as usize, s),
        Some(_) => return Err(format!("layout.shape = {}: \"circle\" or \"line\"", t["shape"])),
    };
    let floats = |v: &[f64]| toml::Value::Array(v.iter().map(|x| toml::Value::Float(*x)).collect());
    let mut out = vec![("cell.spheres_w_mm".to_string(), toml::Value::Array(pts.iter().map(|p| floats(p)).collect()))];
    if height != 0.0 || tilt != 0.0 {
        out.push(("cell.plate_offset_mm_deg".to_string(), floats(&[0.0, 0.0, height, 0.0, 0.0, tilt])));
    }
    Ok(out)
}

fn axis_values(path: &Path, i: usize, a: &Axis) -> Result<Vec<toml::Value>, SweepError> {
    let key = format!("axis[{i}] ({})", a.key);
    let values = match (&a.values, &a.range) {
        (Some(v), None) => v.clone(),
        (None, Some(r)) => {
            if !(r.start.is_finite() && r.stop.is_finite() && r.step.is_finite() && r.step > 0.0 && r.stop >= r.start) {
                return Err(file_err(path, &key, "range needs finite start <= stop and a step > 0"));
            }
            let n = ((r.stop - r.start) / r.step + 1e-9).floor() as usize + 1;
            if n > MAX_POINTS {
                return Err(file_err(path, &key, format!("range gives {n} values: at most {MAX_POINTS}")));
            }
            (0..n).map(|k| toml::Value::Float(r.start + k as f64 * r.step)).collect()
        }
        _ => return Err(file_err(path, &key, "give either values = [...] or range = { start, stop, step }")),
    };
    if values.is_empty() {
        return Err(file_err(path, &key, "an axis needs at least one value"));
    }
    Ok(values)
}

/// The grid's index tuples (one value index per axis) for the axes' lengths.
pub fn grid(lengths: &[usize], combine: Combine) -> Result<Vec<Vec<usize>>, String> {
    match combine {
        Combine::Zip => {
            let n = lengths.first().copied().unwrap_or(1);
            if lengths.iter().any(|&l| l != n) {
                return Err(format!("zip needs axes of one length, not {lengths:?}"));
            }
            Ok((0..n).map(|k| vec![k; lengths.len()]).collect())
        }
        Combine::Product => {
            let total = lengths.iter().try_fold(1usize, |acc, &l| acc.checked_mul(l)).filter(|&t| t <= MAX_POINTS);
            let Some(total) = total else {
                return Err(format!("the product of the axes has more than {MAX_POINTS} points"));
            };
            Ok((0..total)
                .map(|mut k| {
                    let mut idx = vec![0; lengths.len()];
                    for a in (0..lengths.len()).rev() {
                        idx[a] = k % lengths[a];
                        k /= lengths[a];
                    }
                    idx
                })
                .collect())
        }
    }
}

/// The realisations of a sweep file: a count, or `{ max, confidence, batch, min }` (the
/// confidence defaulting to the objective's); `override_count` (the command line's) replaces the
/// count, or the most of an adaptive sweep.
fn realisations(
    path: &Path,
    v: Option<&toml::Value>,
    confidence: f64,
    override_count: Option<u32>,
) -> Result<(u32, Option<super::race::Race>), SweepError> {
    let bad = |key: &str, m: String| Err(file_err(path, key, m));
    let count = |key: &str, v: &toml::Value| -> Result<u32, SweepError> {
        match v.as_integer() {
            Some(n) if (1..=i64::from(MAX_REALISATIONS)).contains(&n) => Ok(n as u32),
            _ => Err(file_err(path, key, format!("{v}: a whole number within [1, {MAX_REALISATIONS}]"))),
        }
    };
    let (mut n, mut race) = match v {
        None => (1, None),
        Some(toml::Value::Table(t)) => {
            if let Some(k) = t.keys().find(|k| !["max", "confidence", "batch", "min"].contains(&k.as_str())) {
                // In serde's words, so that `calsim keys sweep` finds the table's fields by probing.
                return bad(
                    &format!("realisations.{k}"),
                    format!("unknown field `{k}`, expected one of `max`, `min`, `batch`, `confidence` (adaptive realisations)"),
                );
            }
            let max = match t.get("max") {
                Some(v) => count("realisations.max", v)?,
                None => return bad("realisations.max", "adaptive realisations need their most: max = <count>".into()),
            };
            let batch = t.get("batch").map(|v| count("realisations.batch", v)).transpose()?.unwrap_or(10);
            let min = t.get("min").map(|v| count("realisations.min", v)).transpose()?.unwrap_or(batch);
            let c = match t.get("confidence") {
                None => confidence,
                Some(v) => match v.as_float() {
                    Some(c) if (0.5..=0.999).contains(&c) => c,
                    _ => return bad("realisations.confidence", format!("{v}: within [0.5, 0.999]")),
                },
            };
            if min > max {
                // Name the key written: min, or batch when min is left to its default (batch).
                return match t.contains_key("min") {
                    true => bad("realisations.min", format!("{min}: above max = {max}")),
                    false => bad("realisations.batch", format!("{batch}: above max = {max} (min, not given, is the batch)")),
                };
            }
            (max, Some(super::race::Race { min, batch, max, confidence: c }))
        }
        Some(v) => (count("realisations", v)?, None),
    };
    if let Some(o) = override_count {
        if !(1..=MAX_REALISATIONS).contains(&o) {
            return bad("--realisations", format!("{o}: within [1, {MAX_REALISATIONS}]"));
        }
        n = o;
        if let Some(r) = &mut race {
            r.max = o;
            r.min = r.min.min(o);
        }
    }
    Ok((n, race))
}

/// Reads and checks a sweep file: every grid point is loaded and checked as a scenario.
pub fn load(path: &Path) -> Result<Sweep, SweepError> {
    load_with(path, None)
}

/// [`load`] with the command line's realisations replacing the file's count (or the most of an
/// adaptive sweep).
///
/// Long by design: the file's keys checked in the order they are written (base, realisations,
/// objective, thresholds, fixed keys, axes), then every grid point built and checked, each error
/// naming its key.
pub fn load_with(path: &Path, realisations_override: Option<u32>) -> Result<Sweep, SweepError> {
    let shown = path.display().to_string();
    let text = crate::io::read_text(path).map_err(|e| file_err(path, "(file)", format!("cannot read: {e}")))?;
    let file: SweepFile = crate::io::toml_de::from_str_keyed(&text).map_err(|(key, message)| file_err(path, &key, message))?;
    let objective = match file.objective.clone() {
        Some(o) => o.check().map_err(|(k, m)| file_err(path, &k, m))?,
        None => super::objective::Objective::default(),
    };
    let (realisations_n, race) = realisations(path, file.realisations.as_ref(), objective.confidence, realisations_override)?;
    let mut thresholds_mm = file.thresholds_mm.clone();
    if let Some(t) = objective.threshold_mm
        && !thresholds_mm.contains(&t)
    {
        thresholds_mm.push(t);
    }
    if thresholds_mm.len() > 16 || file.thresholds_mm.iter().any(|t| !(t.is_finite() && *t > 0.0 && *t < 1000.0)) {
        return Err(file_err(path, "thresholds_mm", format!("{:?}: at most 16 thresholds, each within (0, 1000) mm", file.thresholds_mm)));
    }
    // Each threshold and each axis names columns of the tables: two alike would fail after the run.
    if let Some(t) = file.thresholds_mm.iter().enumerate().find(|(i, t)| file.thresholds_mm[..*i].contains(t)).map(|(_, t)| t) {
        return Err(file_err(path, "thresholds_mm", format!("{t} given twice: each threshold once")));
    }
    if let Some((i, a)) = file.axes.iter().enumerate().find(|(i, a)| file.axes[..*i].iter().any(|b| b.key == a.key)) {
        return Err(file_err(
            path,
            &format!("axis[{i}] ({})", a.key),
            "the key of an earlier axis: each key once (combine its values in one axis)",
        ));
    }
    let base_path = path.parent().unwrap_or(Path::new(".")).join(&file.base);
    let (base_text, mut base_table) =
        scenario::read_table(&base_path).map_err(|e| SweepError::Point { path: shown.clone(), axis: "base".into(), error: Box::new(e) })?;
    for (k, v) in &file.fixed {
        for (target, value) in resolve(k, v).map_err(|m| file_err(path, &format!("fixed.{k}"), m))? {
            set_dotted(&mut base_table, &target, value).map_err(|m| file_err(path, &format!("fixed.{k}"), m))?;
        }
    }
    let values: Vec<Vec<toml::Value>> = file.axes.iter().enumerate().map(|(i, a)| axis_values(path, i, a)).collect::<Result<_, _>>()?;
    let lengths: Vec<usize> = values.iter().map(Vec::len).collect();
    let tuples = grid(&lengths, file.combine).map_err(|m| file_err(path, "axis", m))?;
    let units = tuples.len() as u64 * u64::from(realisations_n);
    if units > 1_000_000 {
        return Err(file_err(path, "realisations", format!("{units} work units (points x realisations): at most 1e6")));
    }
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "sweep".into());
    // Every point built and checked in parallel (a large grid's load is most of a small shard's
    // cost); the first failing point in grid order is the one reported.
    let build = |p: usize, idx: &Vec<usize>| -> Result<Point, SweepError> {
        let mut t = base_table.clone();
        let mut shown_values = Vec::new();
        for (a, &k) in idx.iter().enumerate() {
            let key = &file.axes[a].key;
            let v = &values[a][k];
            let resolved = resolve(key, v).map_err(|m| file_err(path, &format!("axis[{a}] ({key})"), format!("value {v}: {m}")))?;
            for (target, value) in resolved {
                set_dotted(&mut t, &target, value).map_err(|m| file_err(path, &format!("axis[{a}] ({key})"), m))?;
            }
            shown_values.push((key.clone(), v.to_string()));
        }
        let axis = shown_values.iter().map(|(k, v)| format!("{k} = {v}")).collect::<Vec<_>>().join(", ");
        let point_path = PathBuf::from(format!("{stem}#{p}"));
        let text = toml::to_string(&t).unwrap_or_default();
        let scenario = unit_scenario(&text, t, &point_path).map_err(|e| SweepError::Point {
            path: shown.clone(),
            axis: if axis.is_empty() { "(base)".into() } else { axis.clone() },
            error: Box::new(e),
        })?;
        Ok(Point { values: shown_values, scenario })
    };
    let built: Vec<Result<Point, SweepError>> = {
        use rayon::prelude::*;
        tuples.par_iter().enumerate().map(|(p, idx)| build(p, idx)).collect()
    };
    let points = built.into_iter().collect::<Result<Vec<Point>, SweepError>>()?;
    use sha2::Digest;
    let identity = format!("{:x}", sha2::Sha256::digest(format!("{text}\u{0}{base_text}")));
    Ok(Sweep {
        name: stem,
        realisations: realisations_n,
        overrides: realisations_override.map(|r| ("realisations".to_string(), r.to_string())).into_iter().collect(),
        race,
        objective,
        thresholds_mm,
        keys: file.axes.iter().map(|a| a.key.clone()).collect(),
        points,
        identity,
        predict: false,
    })
}

/// A sweep built from scenario tables directly (a budget's configurations): each point is
/// `(axis values, table)`, checked as a scenario; `identity` names the sweep's inputs.
pub fn from_tables(
    name: &str,
    identity: String,
    realisations: u32,
    thresholds_mm: Vec<f64>,
    keys: Vec<String>,
    points: Vec<(Vec<(String, String)>, toml::Table)>,
) -> Result<Sweep, SweepError> {
    let mut out = Vec::with_capacity(points.len());
    for (p, (values, t)) in points.into_iter().enumerate() {
        let axis = values.iter().map(|(k, v)| format!("{k} = {v}")).collect::<Vec<_>>().join(", ");
        let text = toml::to_string(&t).unwrap_or_default();
        let scenario = unit_scenario(&text, t, &PathBuf::from(format!("{name}#{p}"))).map_err(|e| SweepError::Point {
            path: name.into(),
            axis: if axis.is_empty() { "(base)".into() } else { axis },
            error: Box::new(e),
        })?;
        out.push(Point { values, scenario });
    }
    Ok(Sweep {
        name: name.into(),
        realisations,
        overrides: Vec::new(),
        race: None,
        objective: super::objective::Objective::default(),
        thresholds_mm,
        keys,
        points: out,
        identity,
        predict: false,
    })
}

/// The value at dotted `key` of `t`, if there is one.
pub fn get_dotted<'a>(t: &'a toml::Table, key: &str) -> Option<&'a toml::Value> {
    let mut parts = key.split('.');
    let first = parts.next()?;
    parts.try_fold(t.get(first)?, |v, p| v.as_table()?.get(p))
}

/// The scenario of a grid point as a unit runs it: loaded and checked from its table, without the
/// compensated validation (a unit keeps the plain validation's statistics).
fn unit_scenario(text: &str, t: toml::Table, path: &Path) -> Result<Box<dyn Scenario>, ScenarioError> {
    let mut s = device::from_table(text, t, path)?;
    s.study_mut().compensated_validation = false;
    Ok(s)
}
