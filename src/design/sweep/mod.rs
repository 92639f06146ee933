//! Design studies: a sweep over a cell's design (grid points), many realisations each, sharded
//! onto a cluster and merged.
//!
//! A **work unit** is one grid point in one realisation: the whole study of that point's scenario
//! (campaign, set sizes x repetitions) in the physical world of that realisation. Realisation `r`
//! of a scenario with seed `s` draws every random quantity from the seed [`crate::seeds::realisation_seed`]`(s,
//! r)`, which depends on neither the grid point nor the shard: two designs are compared on the
//! same worlds (common random numbers), and realisation 0 is the plain `calsim run` of the point.
//!
//! A shard (`--shard k/K`) runs the units `u` with `u % K == k` and writes each as
//! `units/uNNNNNN.json` of its shard directory, atomically: a shard re-run after a kill keeps the
//! units it finished. `merge` reads the units of every shard, in unit order, and writes the
//! tables: any sharding and any thread count give the same bytes.

pub mod designs;
pub mod objective;
pub mod plots;
pub mod race;
pub mod record;
pub mod results;
pub mod spec;

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::study::ErrorStats;
use crate::study::interval::{clopper_pearson, median_interval};
use crate::study::stats::{finite_sorted, median, quantile};
pub use spec::{Sweep, SweepError};

/// JSON has no NaN: a number that is not finite (a median of nothing, a unit that could not run) is
/// written as `null` and read back as NaN.
mod nan_as_null {
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        if v.is_finite() { s.serialize_f64(*v) } else { s.serialize_none() }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
    }

    /// The same for arrays of three.
    pub mod three {
        use serde::{Deserialize, Deserializer, Serializer};

        pub fn serialize<S: Serializer>(v: &[f64; 3], s: S) -> Result<S::Ok, S::Error> {
            use serde::ser::SerializeTuple;
            let mut t = s.serialize_tuple(3)?;
            for x in v {
                t.serialize_element(&x.is_finite().then_some(*x))?;
            }
            t.end()
        }

        pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<[f64; 3], D::Error> {
            Ok(<[Option<f64>; 3]>::deserialize(d)?.map(|x| x.unwrap_or(f64::NAN)))
        }
    }
}

/// One set size of one selection in one work unit: the statistics over its repetitions.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct UnitRow {
    /// How sets were chosen.
    pub selection: String,
    /// Set size.
    pub set_size: u32,
    /// Whether this is the point's table set size.
    pub table: bool,
    /// Repetitions run.
    pub repetitions: u32,
    /// Repetitions that gave no model.
    pub no_model: u32,
    /// Median over repetitions of the validation error's median, p95, max and mean, mm (SPMS: of
    /// the ISO 9283 AP over P1-P5).
    #[serde(with = "nan_as_null")]
    pub after_median_mm: f64,
    /// See `after_median_mm`.
    #[serde(with = "nan_as_null")]
    pub after_p95_mm: f64,
    /// See `after_median_mm`.
    #[serde(with = "nan_as_null")]
    pub after_max_mm: f64,
    /// See `after_median_mm`.
    #[serde(with = "nan_as_null")]
    pub after_mean_mm: f64,
    /// Per threshold of the sweep: repetitions whose max error is within it.
    pub max_within: Vec<u32>,
    /// Per threshold: repetitions whose mean error is within it.
    pub mean_within: Vec<u32>,
    /// Per threshold: repetitions whose p95 error is within it.
    #[serde(default)]
    pub p95_within: Vec<u32>,
    /// Per threshold: repetitions whose median error is within it.
    #[serde(default)]
    pub median_within: Vec<u32>,
    /// Median O1 of the chosen sets.
    #[serde(with = "nan_as_null")]
    pub o1_median: f64,
}

/// What one work unit gave.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Unit {
    /// Unit index: `point * realisations + realisation`.
    pub unit: usize,
    /// Grid point.
    pub point: usize,
    /// Realisation.
    pub realisation: u32,
    /// Why the unit could not run (the campaign failed in this world), if it could not.
    pub error: Option<String>,
    /// Error before calibration: median, p95 and max, mm.
    #[serde(with = "nan_as_null::three")]
    pub before_mm: [f64; 3],
    /// Modelled campaign time (centring of the pool), s.
    #[serde(with = "nan_as_null")]
    pub campaign_s: f64,
    /// Per selection and set size.
    pub rows: Vec<UnitRow>,
    /// The linear prediction at the table set size, when the sweep asks for it (TriCal).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub prediction: Option<crate::study::prediction::Prediction>,
    /// The design a unit of the optimiser belongs to (`<world context>/<design key>`, the
    /// directory its per-world file is kept in); a sweep's units have none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub design: Option<String>,
    /// An optimiser's unit: the sha256 of its JSON written without this field (an edit of the
    /// file, however plausible its numbers, is seen); a sweep's units have none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub digest: Option<String>,
}

/// Largest error a unit may report, mm (1000 km: beyond any arm, however badly calibrated).
const MOST_MM: f64 = 1e9;

impl Unit {
    /// Whether this unit, read from `file` in the directory of shard `shard`, can be one of
    /// `sweep`'s: its indices within the sweep, the file's name and the shard's units, exactly the
    /// rows its point's study promises (`studies`: each selection and set size once, over the
    /// study's repetitions; none when the unit could not run), its counts within its repetitions,
    /// one count per threshold, and every error, time and O1 either absent (NaN) or a finite
    /// number >= 0 (errors up to `MOST_MM`, the campaign's modelled time up to 1e15 s, above any
    /// the scenario limits allow). A unit file is written by calsim; this refuses one that was cut
    /// short, edited or mixed up.
    fn check(&self, sweep: &ShardInfo, studies: &[record::PointStudy], shard: usize, file: &Path) -> Result<(), String> {
        let (points, reals) = (sweep.points.len(), sweep.realisations as usize);
        if self.point >= points || self.realisation as usize >= reals || self.unit != self.point * reals + self.realisation as usize {
            return Err(format!(
                "unit {} (point {}, realisation {}) is not a unit of this sweep ({points} points x {reals} realisations)",
                self.unit, self.point, self.realisation
            ));
        }
        if file.file_stem().and_then(|s| s.to_str()) != Some(unit_file_stem(self.unit).as_str()) {
            return Err(format!("holds unit {}, not the unit its name gives", self.unit));
        }
        if self.unit % sweep.count != shard {
            return Err(format!(
                "holds unit {}, a unit of shard {} of {}, not of this shard {shard}",
                self.unit,
                self.unit % sweep.count,
                sweep.count
            ));
        }
        if let Some(d) = &self.design {
            return Err(format!("design = {d:?}: a unit of the optimiser's, not of a sweep"));
        }
        self.check_values(&studies[self.point], sweep.thresholds_mm.len())
    }

    /// Whether what this unit reports can be a unit of a grid point whose study promises `study`
    /// judged at `thresholds` thresholds: exactly the promised rows (none when the unit could not
    /// run), counts within their repetitions, one count per threshold, every error, time and O1
    /// absent (NaN) or a finite number >= 0. The check the sweeps' merge and the optimiser's
    /// resume hold every unit file to.
    pub fn check_values(&self, study: &record::PointStudy, thresholds: usize) -> Result<(), String> {
        self.check_rows(study)?;
        let size = |what: &str, x: f64, most: f64| {
            if x.is_nan() || (0.0..=most).contains(&x) { Ok(()) } else { Err(format!("{what} = {x}: not within [0, {most:e}]")) }
        };
        for (i, x) in self.before_mm.iter().enumerate() {
            size(&format!("before_mm[{i}]"), *x, MOST_MM)?;
        }
        size("campaign_s", self.campaign_s, 1e15)?;
        for (i, r) in self.rows.iter().enumerate() {
            let at = |k: &str| format!("rows[{i}].{k}");
            for (k, x) in [
                ("after_median_mm", r.after_median_mm),
                ("after_p95_mm", r.after_p95_mm),
                ("after_max_mm", r.after_max_mm),
                ("after_mean_mm", r.after_mean_mm),
            ] {
                size(&at(k), x, MOST_MM)?;
            }
            size(&at("o1_median"), r.o1_median, f64::MAX)?;
            if r.no_model > r.repetitions {
                return Err(format!("{} = {} of {} repetitions", at("no_model"), r.no_model, r.repetitions));
            }
            for (k, counts) in [
                ("max_within", &r.max_within),
                ("mean_within", &r.mean_within),
                ("p95_within", &r.p95_within),
                ("median_within", &r.median_within),
            ] {
                if counts.len() != thresholds || counts.iter().any(|&c| c > r.repetitions) {
                    return Err(format!(
                        "{} = {counts:?}: one count of at most {} repetitions per threshold ({} thresholds)",
                        at(k),
                        r.repetitions,
                        thresholds
                    ));
                }
            }
        }
        Ok(())
    }
}

impl Unit {
    /// Whether the rows are exactly those `study` promises (see [`Unit::check`]).
    fn check_rows(&self, study: &record::PointStudy) -> Result<(), String> {
        if self.error.is_some() {
            return if self.rows.is_empty() { Ok(()) } else { Err("rows: a unit that could not run has none".into()) };
        }
        for (i, r) in self.rows.iter().enumerate() {
            let at = |k: &str| format!("rows[{i}].{k}");
            if !study.selections.contains(&r.selection.as_str()) {
                return Err(format!(
                    "{} = {:?}: not a selection of the point's study {:?}",
                    at("selection"),
                    r.selection,
                    study.selections
                ));
            }
            if !study.set_sizes.contains(&r.set_size) {
                return Err(format!("{} = {}: not a set size of the point's study {:?}", at("set_size"), r.set_size, study.set_sizes));
            }
            if self.rows[..i].iter().any(|o| o.selection == r.selection && o.set_size == r.set_size) {
                return Err(format!("rows[{i}]: {} sets of {} a second time", r.selection, r.set_size));
            }
            if r.repetitions != study.repetitions {
                return Err(format!("{} = {}: the point's study has {} repetitions", at("repetitions"), r.repetitions, study.repetitions));
            }
            if r.table != (r.set_size == study.table_set_size) {
                return Err(format!("{} = {}: the point's table set size is {}", at("table"), r.table, study.table_set_size));
            }
        }
        for sel in &study.selections {
            for n in &study.set_sizes {
                if !self.rows.iter().any(|r| r.selection == *sel && r.set_size == *n) {
                    return Err(format!(
                        "rows: no row of {sel} sets of {n} (the point's study has {:?} x set sizes {:?})",
                        study.selections, study.set_sizes
                    ));
                }
            }
        }
        Ok(())
    }
}

/// Statistics over repetitions of one selection and set size.
fn row(selection: &str, n: usize, table: bool, per_rep: &[Option<ErrorStats>], o1: &[f64], thresholds: &[f64]) -> UnitRow {
    let ok: Vec<&ErrorStats> = per_rep.iter().flatten().collect();
    let med = |f: fn(&ErrorStats) -> f64| median(&ok.iter().map(|s| f(s)).collect::<Vec<_>>());
    UnitRow {
        selection: selection.into(),
        set_size: n as u32,
        table,
        repetitions: per_rep.len() as u32,
        no_model: (per_rep.len() - ok.len()) as u32,
        after_median_mm: med(|s| s.median),
        after_p95_mm: med(|s| s.p95),
        after_max_mm: med(|s| s.max),
        after_mean_mm: med(|s| s.mean),
        max_within: thresholds.iter().map(|t| ok.iter().filter(|s| s.max <= *t).count() as u32).collect(),
        mean_within: thresholds.iter().map(|t| ok.iter().filter(|s| s.mean <= *t).count() as u32).collect(),
        p95_within: thresholds.iter().map(|t| ok.iter().filter(|s| s.p95 <= *t).count() as u32).collect(),
        median_within: thresholds.iter().map(|t| ok.iter().filter(|s| s.median <= *t).count() as u32).collect(),
        o1_median: median(o1),
    }
}

/// Groups per-task results by (selection, set size), in grid order.
fn grouped<T>(tasks: &[T], key: impl Fn(&T) -> (crate::study::Selection, usize)) -> Vec<((crate::study::Selection, usize), Vec<&T>)> {
    let mut out: Vec<((crate::study::Selection, usize), Vec<&T>)> = Vec::new();
    for t in tasks {
        let k = key(t);
        match out.iter_mut().find(|(g, _)| *g == k) {
            Some((_, v)) => v.push(t),
            None => out.push((k, vec![t])),
        }
    }
    out
}

/// Runs one work unit: the point's study in the unit's world, kept as its statistics.
pub fn run_unit(sweep: &Sweep, unit: usize) -> Unit {
    let (point, realisation) = (unit / sweep.realisations as usize, (unit % sweep.realisations as usize) as u32);
    Unit { unit, ..run_world(sweep, point, realisation) }
}

/// Runs grid point `point` of `sweep` in the world of realisation `realisation` (any index, also
/// beyond the sweep's count: the optimiser's held-out worlds), kept as its statistics; the unit
/// index is the sweep's (`point * realisations + realisation`, saturating).
pub fn run_world(sweep: &Sweep, point: usize, realisation: u32) -> Unit {
    let unit = point.saturating_mul(sweep.realisations as usize).saturating_add(realisation as usize);
    let th = &sweep.thresholds_mm;
    let mut out = Unit {
        unit,
        point,
        realisation,
        error: None,
        before_mm: [f64::NAN; 3],
        campaign_s: 0.0,
        rows: Vec::new(),
        prediction: None,
        design: None,
        digest: None,
    };
    let s = &sweep.points[point].scenario;
    let seed = crate::seeds::realisation_seed(s.header().seed, realisation);
    let outcome = match s.run(seed, &|_, _| {}) {
        Ok(o) => o,
        Err(e) => {
            out.error = Some(e.to_string());
            return out;
        }
    };
    let world = outcome.world();
    let b = world.before;
    out.before_mm = [b.median, b.p95, b.max];
    out.campaign_s = world.campaign_s;
    let table_n = s.study().table_set_size as usize;
    for ((sel, n), ts) in grouped(&world.tasks, |t| (t.selection, t.set_size)) {
        let per: Vec<Option<ErrorStats>> = ts.iter().map(|t| t.after).collect();
        let o1: Vec<f64> = ts.iter().map(|t| t.o1).collect();
        out.rows.push(row(sel.label(), n, n == table_n, &per, &o1, th));
    }
    if sweep.predict {
        out.prediction = outcome.prediction(seed);
    }
    out
}

/// What a shard directory records of its sweep (`sweep.json`), so that `merge` needs only the
/// shards (and the robot files their scenarios name); stored and checked as [`record`] says.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShardInfo {
    /// The sweep's name.
    pub name: String,
    /// sha256 of the sweep file and its base scenario.
    pub identity: String,
    /// Realisations per point.
    pub realisations: u32,
    /// Command-line changes to the sweep file (`key`, TOML value), recorded in the merged
    /// manifest's provenance.
    #[serde(default)]
    pub overrides: Vec<(String, String)>,
    /// Thresholds, mm.
    pub thresholds_mm: Vec<f64>,
    /// The axes' keys.
    pub keys: Vec<String>,
    /// Per grid point, its axis values as written.
    pub points: Vec<Vec<String>>,
    /// Per grid point, the datum spheres in {W}, mm (TriCal; empty for other devices).
    pub layouts: Vec<Vec<[f64; 3]>>,
    /// Per grid point, where the robot stands in {W} (TriCal; empty for other devices; one entry
    /// when it is the same at every point).
    #[serde(default)]
    pub robots: Vec<Option<crate::device::RobotInCell>>,
    /// The whole scenario of grid point 0 as TOML (what `calsim run` takes to redo it, recording
    /// included).
    pub scenario: String,
    /// Per grid point, the changes of its scenario from grid point 0's ([`ShardInfo::point_table`]).
    pub changes: Vec<Vec<record::Change>>,
    /// What the sweep decides (its default: minimise the p95 at the table set size).
    pub objective: objective::Objective,
    /// Adaptive realisations, when the sweep races its designs.
    #[serde(default)]
    pub race: Option<race::Race>,
    /// This shard, `k` of `count`.
    pub shard: usize,
    /// Shards in all.
    pub count: usize,
}

impl ShardInfo {
    /// The whole scenario of grid point `p` as a table (a record read from disk is checked by
    /// [`record::check`] first).
    pub fn point_table(&self, p: usize) -> Result<toml::Table, String> {
        let base = toml::from_str::<toml::Table>(&self.scenario).map_err(|e: toml::de::Error| format!("scenario: {}", e.message()))?;
        let changes = self.changes.get(p).ok_or_else(|| format!("no grid point {p}"))?;
        record::apply(&base, changes).map_err(|(i, why)| format!("changes[{p}][{i}]: {why}"))
    }
}

/// The file a shard directory holds from its start (its record): how the writer knows the
/// directory as calsim's own ([`crate::io::out_dir::prepare_work`]).
pub const SHARD_MARKER: &str = "sweep.json";

/// The shard directory of shard `k` of `count` of `sweep` under `out`.
pub fn shard_dir(out: &Path, name: &str, k: usize, count: usize) -> PathBuf {
    out.join(format!("{name}.shard-{k}-of-{count}"))
}

fn unit_file(dir: &Path, unit: usize) -> PathBuf {
    dir.join("units").join(format!("{}.json", unit_file_stem(unit)))
}

fn unit_file_stem(unit: usize) -> String {
    format!("u{unit:07}")
}

/// Writes `bytes` to `path` through the kit's atomic writer: a reader sees all or nothing.
fn write_file_atomically(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    crate::io::out_dir::write_file_atomically(path, bytes)
}

/// What one run of a shard did.
#[derive(Clone, Debug)]
pub struct ShardRun {
    /// The shard directory.
    pub dir: PathBuf,
    /// Where the sweep stands after it (complete, or the stage and units it still needs: an
    /// adaptive sweep's later stages need every shard's units of the stages before).
    pub plan: race::Plan,
    /// Units this run computed.
    pub ran: usize,
}

/// The record of `sweep` that shard `k` of `count` writes as its `sweep.json`.
pub fn shard_info(sweep: &Sweep, k: usize, count: usize) -> ShardInfo {
    // Every point's text is calsim's own TOML of a table it loaded (`spec::load`, `from_tables`).
    let tables: Vec<toml::Table> =
        sweep.points.par_iter().map(|p| toml::from_str::<toml::Table>(&p.scenario.header().text).unwrap_or_default()).collect();
    let base = tables.first().cloned().unwrap_or_default();
    ShardInfo {
        name: sweep.name.clone(),
        identity: sweep.identity.clone(),
        realisations: sweep.realisations,
        overrides: sweep.overrides.clone(),
        thresholds_mm: sweep.thresholds_mm.clone(),
        keys: sweep.keys.clone(),
        points: sweep.points.iter().map(|p| p.values.iter().map(|(_, v)| v.clone()).collect()).collect(),
        layouts: sweep.points.par_iter().map(|p| p.scenario.layout_mm()).collect(),
        robots: robots_once(sweep.points.par_iter().map(|p| p.scenario.robot_in_cell()).collect()),
        scenario: sweep.points.first().map(|p| p.scenario.header().text.clone()).unwrap_or_default(),
        changes: tables.par_iter().map(|t| record::changes(&base, t)).collect(),
        objective: sweep.objective.clone(),
        race: sweep.race.clone(),
        shard: k,
        count,
    }
}

/// Where each point's robot stands, kept once when it is the same at every point (the record
/// grows with what varies: a 9,001-point sweep of one cell keeps one entry).
fn robots_once(robots: Vec<Option<crate::device::RobotInCell>>) -> Vec<Option<crate::device::RobotInCell>> {
    if robots.windows(2).all(|w| w[0] == w[1]) { robots.into_iter().take(1).collect() } else { robots }
}

/// Runs the units shard `k` of `count` owes to the sweep's current stage (every unit of the shard,
/// for a sweep of fixed realisations), in parallel, calling `progress(done, total)` after each;
/// unsharded, stage after stage until the sweep is complete. Units already in the shard directory
/// are kept (a killed run resumes).
pub fn run_shard(sweep: &Sweep, out: &Path, k: usize, count: usize, progress: &(dyn Fn(usize, usize) + Sync)) -> std::io::Result<ShardRun> {
    let dir = shard_dir(out, &sweep.name, k, count);
    let info = shard_info(sweep, k, count);
    let bytes = serde_json::to_vec(&info).map_err(std::io::Error::other)?;
    // Never write a record that merge cannot read back: refused before anything runs.
    if bytes.len() as u64 > crate::io::MOST_INPUT_BYTES {
        return Err(std::io::Error::other(format!(
            "sweep {}: its record (sweep.json) would take {:.1} MiB, more than the {} MiB calsim reads of an input: fewer grid points or \
             smaller axis values",
            sweep.name,
            bytes.len() as f64 / f64::from(1 << 20),
            crate::io::MOST_INPUT_BYTES >> 20
        )));
    }
    let studies: Vec<record::PointStudy> = sweep.points.par_iter().map(|p| record::PointStudy::of(p.scenario.as_ref())).collect();
    fs::create_dir_all(dir.join("units"))?;
    let info_path = dir.join("sweep.json");
    if info_path.exists() {
        let old = crate::io::read_bytes(&info_path)
            .map_err(|e| std::io::Error::new(e.kind(), format!("{}: {e}", crate::io::names::shown(&info_path))))?;
        let old: ShardInfo = serde_json::from_slice(&old).map_err(|e| {
            std::io::Error::other(format!(
                "{}: {e} (a sweep.json calsim did not write: remove the directory)",
                crate::io::names::shown(&info_path)
            ))
        })?;
        if old != info {
            return Err(std::io::Error::other(format!(
                "{} holds units of another sweep or sharding: remove it or choose another --out",
                dir.display()
            )));
        }
    }
    write_file_atomically(&info_path, &bytes)?;
    // Temporary files of killed runs are not units: remove them.
    for e in fs::read_dir(dir.join("units"))? {
        let p = e?.path();
        if p.extension().is_some_and(|x| x != "json") {
            let _ = fs::remove_file(&p);
        }
    }
    let mut ran = 0;
    let done = std::sync::atomic::AtomicUsize::new(0);
    loop {
        let present = sibling_units(out, &info, &studies).map_err(|e| std::io::Error::other(e.to_string()))?;
        let plan = race::plan(&info, &present);
        let mine: Vec<usize> = plan.missing.iter().copied().filter(|u| u % count == k).collect();
        if mine.is_empty() {
            return Ok(ShardRun { dir, plan, ran });
        }
        let total = done.load(std::sync::atomic::Ordering::Relaxed) + mine.len();
        progress(done.load(std::sync::atomic::Ordering::Relaxed), total);
        mine.par_iter().try_for_each(|&u| -> std::io::Result<()> {
            let unit = run_unit(sweep, u);
            write_file_atomically(&unit_file(&dir, u), &serde_json::to_vec(&unit).map_err(std::io::Error::other)?)?;
            progress(done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1, total);
            Ok(())
        })?;
        ran += mine.len();
    }
}

/// The units of every shard of `info`'s sharding under `out` that exists (a sibling's record must
/// be the same sweep), by unit index; `studies` are the promises of `info`'s points.
fn sibling_units(out: &Path, info: &ShardInfo, studies: &[record::PointStudy]) -> Result<BTreeMap<usize, Unit>, MergeError> {
    let dirs: Vec<PathBuf> =
        (0..info.count).map(|j| shard_dir(out, &info.name, j, info.count)).filter(|d| d.join("sweep.json").exists()).collect();
    Ok(read_shards_of(&dirs, Some((info, studies)))?.1.into_iter().map(|u| (u.unit, u)).collect())
}

/// Why shards cannot be merged.
#[derive(Debug, thiserror::Error)]
pub enum MergeError {
    /// A shard directory is unreadable or not a shard.
    #[error("{path}: {why}")]
    Shard {
        /// The directory.
        path: String,
        /// What is wrong.
        why: String,
    },
    /// A shard's record (`sweep.json`) is not one calsim could have written.
    #[error("{path}: {key}: {why}")]
    Record {
        /// The record's file.
        path: String,
        /// Its key.
        key: String,
        /// What is wrong.
        why: String,
    },
}

fn shard_err(p: &Path, why: impl Into<String>) -> MergeError {
    MergeError::Shard { path: p.display().to_string(), why: why.into() }
}

/// Reads the shards `dirs` of one sweep: their common record, checked whole ([`record::check`]),
/// and every unit, checked against it, in unit order (whether the sweep is complete is
/// [`complete`]'s question).
pub fn read_shards(dirs: &[PathBuf]) -> Result<(ShardInfo, Vec<Unit>), MergeError> {
    read_shards_of(dirs, None)
}

/// [`read_shards`]; with `known`, the record and the promises of the sweep that runs (every shard's
/// record must be it, and it need not be checked again).
fn read_shards_of(dirs: &[PathBuf], known: Option<(&ShardInfo, &[record::PointStudy])>) -> Result<(ShardInfo, Vec<Unit>), MergeError> {
    // The records first, all of them: nothing of a unit is read before every record is trusted.
    let mut first: Option<(ShardInfo, PathBuf, Vec<record::PointStudy>)> =
        known.map(|(i, s)| (i.clone(), PathBuf::from("the sweep file"), s.to_vec()));
    let mut shards: Vec<(&Path, usize)> = Vec::with_capacity(dirs.len());
    for d in dirs {
        let file = d.join("sweep.json");
        let bytes = crate::io::read_bytes(&file).map_err(|e| shard_err(d, format!("not a shard directory (sweep.json: {e})")))?;
        let this: ShardInfo = from_json(&bytes, &file)?;
        match &first {
            None => {
                let studies = record::check(&this, &file)?;
                first = Some((this.clone(), file.clone(), studies));
            }
            Some((f, fp, _)) => {
                if f.identity != this.identity || f.name != this.name {
                    return Err(shard_err(d, format!("a shard of another sweep than {} ({} against {})", fp.display(), this.name, f.name)));
                }
                if this.shard >= f.count || (ShardInfo { shard: f.shard, ..this.clone() }) != *f {
                    let key = differing_key(f, &this);
                    return Err(MergeError::Record {
                        path: crate::io::names::shown(&file),
                        key,
                        why: format!("not the record of {} (the same sweep holds one record in every shard)", fp.display()),
                    });
                }
            }
        }
        if let Some((other, _)) = shards.iter().find(|(_, k)| *k == this.shard) {
            return Err(shard_err(d, format!("shard {} of {} a second time (also {})", this.shard, this.count, other.display())));
        }
        shards.push((d.as_path(), this.shard));
    }
    let (info, _, studies) = first.ok_or_else(|| shard_err(Path::new("merge"), "no shard directories given"))?;
    let mut units: BTreeMap<usize, Unit> = BTreeMap::new();
    for (d, shard) in shards {
        let entries = fs::read_dir(d.join("units")).map_err(|e| shard_err(d, format!("units: {e}")))?;
        for e in entries {
            let p = e.map_err(|e| shard_err(d, e.to_string()))?.path();
            if p.extension().is_none_or(|x| x != "json") {
                continue;
            }
            let u: Unit = from_json(&crate::io::read_bytes(&p).map_err(|e| shard_err(&p, e.to_string()))?, &p)?;
            u.check(&info, &studies, shard, &p).map_err(|why| shard_err(&p, why))?;
            units.insert(u.unit, u);
        }
    }
    Ok((info, units.into_values().collect()))
}

/// `bytes` of `file` as a `T`; an error names the key it is at (`thresholds_mm[0]`: a record is
/// one line, its column alone would not say where).
fn from_json<T: serde::de::DeserializeOwned>(bytes: &[u8], file: &Path) -> Result<T, MergeError> {
    let fail = |key: String, why: String| MergeError::Record {
        path: crate::io::names::shown(file),
        key: if key == "." { "(file)".into() } else { key },
        why: crate::io::names::escape_controls(&why),
    };
    let mut de = serde_json::Deserializer::from_slice(bytes);
    let value = serde_path_to_error::deserialize(&mut de).map_err(|e| fail(e.path().to_string(), e.into_inner().to_string()))?;
    // Anything after the document is not calsim's: a record or unit written twice, or edited.
    de.end().map_err(|e| fail(".".into(), e.to_string()))?;
    Ok(value)
}

/// The first key in which record `b` differs from record `a` (but for the shard index).
fn differing_key(a: &ShardInfo, b: &ShardInfo) -> String {
    let (Ok(serde_json::Value::Object(a)), Ok(serde_json::Value::Object(b))) = (serde_json::to_value(a), serde_json::to_value(b)) else {
        return "(record)".into();
    };
    a.iter().find(|(k, v)| k.as_str() != "shard" && b.get(k.as_str()) != Some(v)).map_or_else(|| "shard".into(), |(k, _)| k.clone())
}

/// The plan of a merged sweep, which must be complete: every unit of a sweep of fixed
/// realisations, and an adaptive sweep's race decided.
pub fn complete(info: &ShardInfo, units: &[Unit]) -> Result<race::Plan, MergeError> {
    let present: BTreeMap<usize, Unit> = units.iter().map(|u| (u.unit, u.clone())).collect();
    let plan = race::plan(info, &present);
    if plan.complete {
        return Ok(plan);
    }
    let why = match &info.race {
        None => format!(
            "{} of {} work units missing (first: {}): run the missing shards or give every shard directory",
            plan.missing.len(),
            info.points.len() * info.realisations as usize,
            plan.missing[0]
        ),
        Some(_) => format!(
            "the adaptive sweep is at stage {} and needs {} more work units (first: {}): run every shard again \
             (`calsim sweep <file> --shard k/{}`), then merge",
            plan.stage,
            plan.missing.len(),
            plan.missing[0],
            info.count
        ),
    };
    Err(shard_err(Path::new(&info.name), why))
}

/// Aggregates over realisations: one row per grid point, selection and set size.
#[derive(Clone, Debug, PartialEq)]
pub struct PointRow {
    /// Grid point.
    pub point: usize,
    /// Selection.
    pub selection: String,
    /// Set size.
    pub set_size: u32,
    /// Whether this is the point's table set size.
    pub table: bool,
    /// Realisations that ran.
    pub realisations: u32,
    /// Median, P10 and P90 over realisations of the after-calibration median, p95 and max, mm.
    pub after: [[f64; 3]; 3],
    /// The interval of each median of `after` at the sweep's confidence (order statistics over
    /// realisations).
    pub after_ci: [[f64; 2]; 3],
    /// Median over realisations of the before-calibration median, p95, max, mm.
    pub before: [f64; 3],
    /// Per threshold: P(max <= t) and P(mean <= t) over realisations x repetitions.
    pub success: Vec<(f64, f64)>,
    /// Per threshold: the Clopper-Pearson intervals of the two probabilities at the sweep's
    /// confidence over the realisations (the unit of independence), `[max lo, max hi, mean lo, mean hi]`.
    pub success_ci: Vec<[f64; 4]>,
    /// Identifications without a model.
    pub no_model: u32,
    /// Median O1.
    pub o1: f64,
    /// Median modelled campaign time, s.
    pub campaign_s: f64,
}

fn spread(v: &[f64]) -> [f64; 3] {
    let s = finite_sorted(v);
    [quantile(&s, 0.5), quantile(&s, 0.1), quantile(&s, 0.9)]
}

/// The per-point aggregates of `units` (in unit order).
pub fn aggregate(info: &ShardInfo, units: &[Unit]) -> Vec<PointRow> {
    let mut out = Vec::new();
    for p in 0..info.points.len() {
        let us: Vec<&Unit> = units.iter().filter(|u| u.point == p && u.error.is_none()).collect();
        let mut keys: Vec<(String, u32, bool)> = Vec::new();
        for u in &us {
            for r in &u.rows {
                if !keys.iter().any(|k| k.0 == r.selection && k.1 == r.set_size) {
                    keys.push((r.selection.clone(), r.set_size, r.table));
                }
            }
        }
        for (sel, n, table) in keys {
            let rows: Vec<&UnitRow> = us.iter().filter_map(|u| u.rows.iter().find(|r| r.selection == sel && r.set_size == n)).collect();
            // Sums in u64: unit files are checked against their own counts, not against overflow.
            let reps: u64 = rows.iter().map(|r| u64::from(r.repetitions)).sum();
            let success: Vec<(f64, f64)> = (0..info.thresholds_mm.len())
                .map(|t| {
                    let m: u64 = rows.iter().map(|r| u64::from(r.max_within[t])).sum();
                    let a: u64 = rows.iter().map(|r| u64::from(r.mean_within[t])).sum();
                    (m as f64 / reps.max(1) as f64, a as f64 / reps.max(1) as f64)
                })
                .collect();
            let conf = info.objective.confidence;
            let worlds = rows.len() as f64;
            let success_ci = success
                .iter()
                .map(|(m, a): &(f64, f64)| {
                    let (ml, mh) = clopper_pearson(m * worlds, worlds, conf);
                    let (al, ah) = clopper_pearson(a * worlds, worlds, conf);
                    [ml, mh, al, ah]
                })
                .collect();
            let ci = |v: Vec<f64>| {
                let (lo, hi) = median_interval(&v, conf);
                [lo, hi]
            };
            let after_ci = [
                ci(rows.iter().map(|r| r.after_median_mm).collect()),
                ci(rows.iter().map(|r| r.after_p95_mm).collect()),
                ci(rows.iter().map(|r| r.after_max_mm).collect()),
            ];
            out.push(PointRow {
                point: p,
                selection: sel,
                set_size: n,
                table,
                realisations: rows.len() as u32,
                after: [
                    spread(&rows.iter().map(|r| r.after_median_mm).collect::<Vec<_>>()),
                    spread(&rows.iter().map(|r| r.after_p95_mm).collect::<Vec<_>>()),
                    spread(&rows.iter().map(|r| r.after_max_mm).collect::<Vec<_>>()),
                ],
                before: [0, 1, 2].map(|k| median(&us.iter().map(|u| u.before_mm[k]).collect::<Vec<_>>())),
                success,
                success_ci,
                after_ci,
                // At most MAX_REPETITIONS x MAX_REALISATIONS (1e8): units are checked against their study.
                no_model: u32::try_from(rows.iter().map(|r| u64::from(r.no_model)).sum::<u64>()).unwrap_or(u32::MAX),
                o1: median(&rows.iter().map(|r| r.o1_median).collect::<Vec<_>>()),
                campaign_s: median(&us.iter().map(|u| u.campaign_s).collect::<Vec<_>>()),
            });
        }
    }
    out
}
