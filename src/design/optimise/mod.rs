//! The optimiser: searches a design file's space (sphere count and positions, plate height and
//! tilt, any scenario key, set size) for the sweeps' objective, on common worlds, then races the
//! finalists and verifies them on held-out worlds.
//!
//! - **Evaluation.** A design is a scenario; its value in world `r` is the sweep's work unit of
//!   that scenario in realisation `r` ([`crate::design::sweep::run_world`]), judged by the sweep's
//!   statistics ([`crate::design::sweep::designs::judge`]): every set size of the study is a
//!   design too (enumerated in each world: one campaign, one selection per size). Every search
//!   evaluation runs the same worlds `0..worlds` (common random numbers: two designs differ by
//!   their design, not by their luck). A design whose geometry is ruled out (points closer than
//!   the spacing, no {W}) runs nothing and scores its violation's margin; a design whose campaign
//!   fails counts that world as a failure (P = 0 there), and its score says in how many worlds.
//! - **Search.** One restart per count of points (and per `restarts`): argmin's Nelder-Mead or
//!   particle swarm over the unit cube of the other variables ([`search`]), at most `evaluations`
//!   designs each. Restarts are independent: `--shard k/n` runs the restarts `r % n == k`.
//! - **Race.** The best `finalists` of each count race on more search worlds (the sweeps' racing,
//!   [`crate::design::sweep::race`]): worlds are added where the decision is close.
//! - **Verification.** The best design of each count, and the designs of the sweep files to
//!   compare with, are evaluated on `held_out` worlds never used in the search (realisations from
//!   [`HELD_OUT_BASE`] on); the reported figures are those, the search's estimates beside them.
//!   The winner is the race's first (design, set size and selection, on the search worlds); the
//!   held-out worlds report it and do not choose it.
//!
//! Every world of every design is one file (`<out>/<name>.evaluations/<design>/r<NNNNNNN>.json`),
//! written atomically: a killed run resumes where it stopped, and the searches being
//! deterministic, any thread count and any sharding give the same files and tables.

pub mod plots;
pub mod reach;
pub mod results;
pub mod search;
pub mod sheet;
pub mod space;
pub mod spec;
pub mod summary;

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::design::sweep::designs::{self, DesignRow};
use crate::design::sweep::objective::Goal;
use crate::design::sweep::record::PointStudy;
use crate::design::sweep::spec::Point;
use crate::design::sweep::{ShardInfo, Sweep, Unit, run_world, shard_info};
pub use spec::{DesignError, DesignSpace};

/// The first realisation of the held-out worlds (the search uses realisations below 10,000).
pub const HELD_OUT_BASE: u32 = 1_000_000;

/// Weight of a constraint's shortfall in a search score (a P(success) is within [0, 1]).
const PENALTY: f64 = 10.0;

/// What a repaired design's search score gains per mm its points were moved
/// ([`DesignSpace::repair`]): 0.1 per 100 mm, so that of two designs that repair to the same
/// valid one, the search prefers the nearer, and a valid design beats its repaired copies.
pub const REPAIR_PER_MM: f64 = 1e-3;

/// Why the optimiser could not run or write.
#[derive(Debug, thiserror::Error)]
pub enum OptimiseError {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The error.
        source: std::io::Error,
    },
    /// The restarts of a merge are not all there.
    #[error("{dir}: {why}")]
    Incomplete {
        /// The directory of the restarts.
        dir: String,
        /// What is missing.
        why: String,
    },
    /// The search library refused its problem.
    #[error("search: {0}")]
    Search(String),
    /// A per-world file is not one this design's world could have written.
    #[error("{path}: {why}")]
    World {
        /// The file.
        path: String,
        /// What is wrong.
        why: String,
    },
    /// A restart's record is not one this design file's search could have written.
    #[error("{path}: {key}: {why}")]
    Record {
        /// The record.
        path: String,
        /// Where in it (`[3].x`).
        key: String,
        /// What is wrong.
        why: String,
    },
}

/// A restart record read back (`asked`, from `file`) checked against the search of restart `r`:
/// its restart, order, count of points and a finite point of the right dimension at every entry
/// (records come from other machines' shards; a wrong one must not reach the decoding).
fn check_record(space: &DesignSpace, r: usize, asked: &[Asked], file: &Path) -> Result<(), OptimiseError> {
    let (count, _) = restarts(space)[r];
    let fail = |i: usize, k: &str, why: String| OptimiseError::Record { path: file.display().to_string(), key: format!("[{i}].{k}"), why };
    if asked.is_empty() {
        return Err(OptimiseError::Record {
            path: file.display().to_string(),
            key: "(file)".into(),
            why: "no designs: a finished restart asked at least one".into(),
        });
    }
    if asked.len() > space.search.evaluations as usize {
        return Err(OptimiseError::Record {
            path: file.display().to_string(),
            key: "(file)".into(),
            why: format!("{} designs: more than the search's {} evaluations", asked.len(), space.search.evaluations),
        });
    }
    for (i, a) in asked.iter().enumerate() {
        if a.restart as usize != r || a.index as usize != i {
            return Err(fail(i, "restart", format!("restart {} #{}: not entry {i} of restart {r}", a.restart, a.index)));
        }
        if a.count != count {
            return Err(fail(i, "count", format!("{}: restart {r} searches {count} points", a.count)));
        }
        let dim = space.dimensions(count);
        if a.x.len() != dim {
            return Err(fail(i, "x", format!("{} values: {dim} values expected", a.x.len())));
        }
        if let Some((k, v)) = a.x.iter().enumerate().find(|(_, v)| !(0.0..=1.0).contains(*v)) {
            return Err(fail(i, &format!("x[{k}]"), format!("{v}: not within the unit box [0, 1]")));
        }
    }
    Ok(())
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> OptimiseError + '_ {
    move |source| OptimiseError::Io { path: path.display().to_string(), source }
}

/// A design the search asked for: its restart, its place in the restart, its count of points and
/// its point of the unit cube.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Asked {
    /// Restart.
    pub restart: u32,
    /// Order within the restart.
    pub index: u32,
    /// Count of points.
    pub count: usize,
    /// The point of the unit cube.
    pub x: Vec<f64>,
}

/// One set size of a design judged over the worlds it ran.
#[derive(Clone, Debug)]
pub struct SizeScore {
    /// The sweep's judgement (estimate, interval, success, campaign hours, feasibility).
    pub row: DesignRow,
    /// Its search score (lower is better; constraints' shortfalls added, see [`score_of`]).
    pub score: f64,
}

/// A design evaluated: what it is, and how it did.
#[derive(Clone, Debug)]
pub struct Evaluated {
    /// What the search asked.
    pub asked: Asked,
    /// The design's values, `key = value`.
    pub values: Vec<(String, String)>,
    /// The points in the region's frame, mm.
    pub points_mm: Vec<[f64; 3]>,
    /// The scenario table (absent: the geometry rules the design out).
    pub table: Option<toml::Table>,
    /// The design's key (sha256 of its scenario, 16 hex digits).
    pub key: String,
    /// Geometric violation or refusal: what, and the margin (mm, or 1 for a refusal).
    pub violation: Option<(String, f64)>,
    /// The design asked broke a geometric rule and was moved to the valid design evaluated
    /// ([`DesignSpace::repair`], `[search] repair`): its values, points and table are the
    /// repaired design's.
    pub repaired: Option<space::Repaired>,
    /// Worlds run, and of them failed (the campaign could not run), with the first reason.
    pub worlds: u32,
    /// See `worlds`.
    pub failed: u32,
    /// See `worlds`.
    pub first_error: Option<String>,
    /// Where some world failed: per point, how far it is from what the arm reaches with the
    /// device in its approach cone, mm ([`reach`]; empty otherwise).
    pub reach_mm: Vec<f64>,
    /// Where some world failed: how far the campaign's pools and validation set are from having
    /// enough candidate poses reachable without collision (the sets' shortfalls summed,
    /// [`crate::device::trical::campaign::Feasibility`]; 0 where the device has no such measure).
    pub shortfall: f64,
    /// Per set size (with `[robust]`: each row the first model's that has it, its score the
    /// models' scores combined).
    pub sizes: Vec<SizeScore>,
    /// The design's score: its best set size's, or the violation's.
    pub score: f64,
    /// With `[robust]`: the design under each error model (empty without).
    pub models: Vec<ModelScore>,
}

/// A design under one error model of `[robust]` on the worlds it ran.
#[derive(Clone, Debug)]
pub struct ModelScore {
    /// Per set size.
    pub sizes: Vec<SizeScore>,
    /// Worlds whose campaign failed.
    pub failed: u32,
    /// The design's score under the model: its best set size's, or the failures'.
    pub score: f64,
}

impl Evaluated {
    /// The best set size (lowest score), if any ran.
    pub fn best(&self) -> Option<&SizeScore> {
        self.sizes.iter().min_by(|a, b| a.score.total_cmp(&b.score).then(a.row.design.set_size.cmp(&b.row.design.set_size)))
    }
}

/// The search score of one set size's judgement: the objective in the minimising sense (minus
/// P(success), or the minimised quantity) plus [`PENALTY`] times each constraint's relative
/// shortfall at the point estimates (the race and the held-out worlds decide at the confidence).
pub fn score_of(space: &DesignSpace, r: &DesignRow) -> f64 {
    let o = &space.objective;
    let value = match o.goal {
        Goal::MaximiseSuccess => -r.estimate,
        _ => r.estimate,
    };
    let mut penalty = 0.0;
    if let (Some(target), Some((p, _))) = (o.success_at_least, r.success) {
        penalty += (target - p).max(0.0);
    }
    let penalty = with_constraint_shortfalls(o, r, penalty);
    let value = if value.is_finite() { value } else { PENALTY };
    value + PENALTY * penalty
}

/// `penalty` plus the campaign and set size constraints' relative shortfalls of `r` (a campaign
/// that has no finite time falls short by 1).
fn with_constraint_shortfalls(o: &crate::design::sweep::objective::Objective, r: &DesignRow, mut penalty: f64) -> f64 {
    if let Some(h) = o.campaign_h_at_most {
        penalty += if r.campaign_h.is_finite() { (r.campaign_h / h - 1.0).max(0.0) } else { 1.0 };
    }
    if let Some(n) = o.set_size_at_most {
        penalty += (f64::from(r.design.set_size) / f64::from(n) - 1.0).max(0.0);
    }
    penalty
}

/// The search score of one set size's judgement with its per-world values of the objective's
/// error statistic (`per_world`, +inf where the world's campaign failed, NaN where it has none):
/// for `maximise = "success"` under `[search] score = "quantile"`, the quantile score
/// ([`spec::SearchScore::Quantile`], [`quantile_score`]) plus the campaign and set size
/// constraints' shortfalls as in [`score_of`]; otherwise [`score_of`].
pub fn search_score(space: &DesignSpace, r: &DesignRow, per_world: &[f64]) -> f64 {
    let o = &space.objective;
    let Some(threshold) = o.threshold_mm.filter(|_| o.goal == Goal::MaximiseSuccess && space.search.score == spec::SearchScore::Quantile)
    else {
        return ran(score_of(space, r));
    };
    let value = quantile_score(per_world, o.success_at_least.unwrap_or(0.95), threshold);
    let penalty = with_constraint_shortfalls(o, r, 0.0);
    let value = if value.is_finite() { value } else { PENALTY };
    ran(value + PENALTY * penalty)
}

/// The empirical quantile at `level` (linear between order statistics: at `(n - 1) level`) of
/// per-world errors over `threshold` (each capped at [`spec::QUANTILE_CAP`] thresholds, a failed
/// world's +inf with them; NaN left out); NaN without a value.
pub fn quantile_score(per_world: &[f64], level: f64, threshold: f64) -> f64 {
    let mut v: Vec<f64> = per_world.iter().filter(|x| !x.is_nan()).map(|x| (x / threshold).min(spec::QUANTILE_CAP)).collect();
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let h = (v.len() - 1) as f64 * level.clamp(0.0, 1.0);
    let (lo, hi) = (v[h.floor() as usize], v[h.ceil() as usize]);
    lo + (h - h.floor()) * (hi - lo)
}

/// The reach part of the score of a design whose every world failed: the sum over its points of
/// their distances from the arm's reach ([`reach::sphere_margins_mm`], mm) / 100, at most
/// 6 [`PENALTY`]. Continuous in every point's position, so that a search moves each point that
/// is out of reach towards the arm; the scores keep their order: a design that ran in some world
/// (under [`FAILED`], [`ran`]) beats one that failed in every world ([`FAILED`] and this, under 9
/// [`PENALTY`]), which beats one its geometry rules out (10 [`PENALTY`] and more); among those
/// that failed in every world, the nearer to the arm's reach the better.
pub fn reach_score(reach_mm: &[f64]) -> f64 {
    let sum: f64 = reach_mm.iter().map(|d| if d.is_finite() { d.max(0.0) } else { 1e4 }).sum();
    (sum / 100.0).min(6.0 * PENALTY)
}

/// The score of a design whose every world failed: [`FAILED`], its [`reach_score`], and its
/// campaign's shortfall (`shortfall`: the pools' and the validation set's, each 0 to 1, summed;
/// [`crate::device::trical::campaign::Feasibility`]): a design whose spheres are all within reach
/// still falls as its fixtures move out of the arm's way and more of its candidate poses are
/// reachable without collision. Under 9 [`PENALTY`] (the reach and the shortfall together at most
/// 6.9 [`PENALTY`]).
pub fn failed_score(reach_mm: &[f64], shortfall: f64) -> f64 {
    let s = if shortfall.is_finite() { shortfall.max(0.0) } else { PENALTY };
    FAILED + (reach_score(reach_mm) + s).min(6.9 * PENALTY)
}

/// How far a scenario is from a campaign that runs, in mm of the reach's distance: the sum of its
/// points' distances from the arm's reach, plus 100 mm per unit of its campaign's shortfall
/// ([`failed_score`]'s two terms on one scale; 0: in reach with enough candidate poses in every set).
fn runs_distance(s: &dyn crate::device::Scenario) -> f64 {
    let reach: f64 = reach::sphere_margins_mm(s).map_or(0.0, |v| v.iter().map(|m| m.min(1e5)).sum());
    let shortfall = s.campaign_feasibility().map_or(0.0, |f| f.total());
    reach + 100.0 * shortfall
}

/// The least score of a design whose every world failed (its reach, [`reach_score`], added).
pub const FAILED: f64 = 3.0 * PENALTY;

/// The score of a design that ran in some world, kept under [`FAILED`]: `s` itself up to 2
/// [`PENALTY`], above that rising towards [`FAILED`] - 1 (continuous and increasing, so that the
/// order among such designs is kept; +inf and NaN at [`FAILED`] - 1).
pub fn ran(s: f64) -> f64 {
    let knee = 2.0 * PENALTY;
    let width = FAILED - 1.0 - knee;
    if s <= knee {
        return s;
    }
    let t = (s - knee) / width;
    if t.is_finite() { knee + width * t / (1.0 + t) } else { FAILED - 1.0 }
}

/// Where a design's worlds come from: the device's own work unit ([`Devices`]), or another
/// source of the same units (a synthetic problem with a known optimum, for the search's tests).
pub trait WorldSource: Sync {
    /// The unit of point `point` of `sweep` in realisation `realisation`.
    fn run(&self, sweep: &Sweep, point: usize, realisation: u32) -> Unit;
}

/// The device's own work unit ([`run_world`]).
pub struct Devices;

impl WorldSource for Devices {
    fn run(&self, sweep: &Sweep, point: usize, realisation: u32) -> Unit {
        run_world(sweep, point, realisation)
    }
}

/// What evaluations share: the space, where worlds are kept, the base scenario's path.
pub struct Context<'a> {
    /// The design space.
    pub space: &'a DesignSpace,
    /// Directory of the per-world files.
    pub cache: PathBuf,
    /// Where worlds come from ([`Devices`] but in tests of the search).
    pub worlds: &'a dyn WorldSource,
    /// The first repetitions' best design, once found ([`run_restart`]).
    best_of_first: std::sync::OnceLock<Option<(usize, Vec<f64>)>>,
}

impl<'a> Context<'a> {
    /// The context of `space` keeping its worlds under `cache`, run by the devices.
    pub fn new(space: &'a DesignSpace, cache: PathBuf) -> Self {
        Self::with_worlds(space, cache, &Devices)
    }

    /// The context of `space` keeping its worlds under `cache`, run by `worlds`.
    pub fn with_worlds(space: &'a DesignSpace, cache: PathBuf, worlds: &'a dyn WorldSource) -> Self {
        Self { space, cache, worlds, best_of_first: std::sync::OnceLock::new() }
    }

    /// The sweep-shaped record of one design point (for the sweep's statistics).
    fn sweep_of(&self, points: Vec<Point>, realisations: u32) -> Sweep {
        Sweep {
            name: self.space.name.clone(),
            realisations,
            overrides: Vec::new(),
            race: None,
            objective: self.space.objective.clone(),
            thresholds_mm: self.space.objective.threshold_mm.into_iter().collect(),
            keys: vec!["design".into()],
            points,
            identity: self.space.identity.clone(),
            predict: false,
        }
    }

    /// The scenario of a table as a unit runs it (checked; without the compensated validation).
    fn point(&self, label: String, table: &toml::Table) -> Result<Point, String> {
        let text = toml::to_string(table).unwrap_or_default();
        let mut s = crate::device::from_table(&text, table.clone(), Path::new(&format!("{}#{label}", self.space.name)))
            .map_err(|e| e.to_string())?;
        s.study_mut().compensated_validation = false;
        Ok(Point { values: vec![("design".into(), label)], scenario: s })
    }

    /// The units of `points` (each `(key, point)`) in `worlds`, read from the per-world files or
    /// run (in parallel) and written; unit `p * stride + k` for the `k`-th world of point `p`.
    fn units(&self, points: &[(String, Point)], worlds: &[u32], stride: u32) -> Result<Vec<Unit>, OptimiseError> {
        let sweep = self.sweep_of(points.iter().map(|(_, p)| p.clone()).collect(), 1);
        let studies: Vec<PointStudy> = points.iter().map(|(_, p)| PointStudy::of(p.scenario.as_ref())).collect();
        let thresholds = sweep.thresholds_mm.len();
        let jobs: Vec<(usize, usize, u32)> =
            (0..points.len()).flat_map(|p| worlds.iter().enumerate().map(move |(k, &r)| (p, k, r))).collect();
        let mut units: Vec<Unit> = jobs
            .par_iter()
            .map(|&(p, k, r)| -> Result<Unit, OptimiseError> {
                let dir = self.cache.join(&self.space.world_context).join(&points[p].0);
                let file = dir.join(format!("r{r:07}.json"));
                let design = format!("{}/{}", self.space.world_context, points[p].0);
                let mut u = match read_world(&file, r, &design, &studies[p], thresholds)? {
                    Some(u) => u,
                    None => {
                        let u = self.worlds.run(&sweep, p, r);
                        fs::create_dir_all(&dir).map_err(io_err(&dir))?;
                        let u = Unit { point: 0, unit: r as usize, design: Some(design), digest: None, ..u };
                        let bytes = serde_json::to_vec(&Unit { digest: Some(unit_digest(&u)), ..u })
                            .map_err(|e| io_err(&file)(std::io::Error::other(e)))?;
                        crate::io::out_dir::write_cache_file(&file, &bytes).map_err(io_err(&file))?;
                        // The unit as the file gives it back (JSON's decimal numbers can move a
                        // value by its last bit): a resumed run then judges the same numbers.
                        serde_json::from_slice::<Unit>(&bytes).map_err(|e| io_err(&file)(std::io::Error::other(e)))?
                    }
                };
                u.point = p;
                u.unit = p * stride as usize + k;
                Ok(u)
            })
            .collect::<Result<_, _>>()?;
        units.sort_by_key(|u| u.unit);
        Ok(units)
    }

    /// The scenario of `table` under each error model (one without `[robust]`), each keyed by
    /// its own text: a model's keys are in its per-world files' name, so that no model ever
    /// reads another's worlds.
    fn model_points(&self, table: &toml::Table) -> Result<Vec<(String, Point)>, (usize, String)> {
        (0..self.space.model_names().len())
            .map(|m| {
                let t = self.space.with_model(table, m);
                let key = design_key(&t);
                self.point(key.clone(), &t).map(|p| (key, p)).map_err(|why| (m, why))
            })
            .collect()
    }

    /// Evaluates what the search asked on the search worlds `0..worlds` (under every error
    /// model of `[robust]`, on the same worlds).
    pub fn evaluate(&self, asked: Asked) -> Result<Evaluated, OptimiseError> {
        let mut d = self.space.decode(asked.count, &asked.x);
        let mut repaired = None;
        if d.violation.is_some()
            && self.space.search.repair
            && let Some(r) = self.space.repair(asked.count, &asked.x)
        {
            d = self.space.decode(asked.count, &r.x);
            repaired = Some(r);
        }
        let key = design_key(&d.table);
        let mut e = Evaluated {
            asked,
            values: d.values,
            points_mm: d.points_mm,
            table: None,
            key,
            violation: d.violation,
            repaired,
            worlds: 0,
            failed: 0,
            first_error: None,
            reach_mm: Vec::new(),
            shortfall: 0.0,
            sizes: Vec::new(),
            score: f64::INFINITY,
            models: Vec::new(),
        };
        if let Some((_, margin)) = &e.violation {
            e.score = 10.0 * PENALTY + margin / 10.0;
            return Ok(e);
        }
        let names = self.space.model_names();
        let points = match self.model_points(&d.table) {
            Ok(p) => p,
            Err((m, why)) => {
                let under = if self.space.robust.is_some() { format!(" under model {:?}", names[m]) } else { String::new() };
                e.violation = Some((format!("the scenario refuses it{under}: {why}"), 1.0));
                e.score = 10.0 * PENALTY + 0.1;
                return Ok(e);
            }
        };
        e.table = Some(d.table);
        let stride = self.space.search.worlds;
        let worlds: Vec<u32> = (0..stride).collect();
        let units = self.units(&points, &worlds, stride)?;
        e.worlds = stride;
        let failed: Vec<u32> =
            (0..points.len()).map(|m| units.iter().filter(|u| u.point == m && u.error.is_some()).count() as u32).collect();
        e.failed = failed.iter().copied().max().unwrap_or(0);
        e.first_error = units.iter().find_map(|u| u.error.clone());
        if e.failed > 0 {
            let s = points[0].1.scenario.as_ref();
            e.reach_mm = reach::sphere_margins_mm(s).unwrap_or_default();
            e.shortfall = s.campaign_feasibility().map_or(0.0, |f| f.total());
        }
        // Every world failed: a violation measured by the worlds (all of them), by how far the
        // points are from the arm's reach and by the campaign's shortfall ([`failed_score`]).
        let all_failed = failed_score(&e.reach_mm, e.shortfall);
        let info = self.info(&self.sweep_of(points.iter().map(|p| p.1.clone()).collect(), stride));
        let rows = designs::judge(&info, &units, &[]);
        // Each design's per-world values of the error statistic (for the quantile score).
        let per_world = designs::values(&info, &units, Goal::MinimiseError(self.space.objective.statistic));
        let mut per_model: Vec<ModelScore> = (0..points.len())
            .map(|m| {
                let sizes: Vec<SizeScore> = rows
                    .iter()
                    .filter(|r| r.design.point == m)
                    .map(|r| {
                        let values: Vec<f64> = per_world
                            .iter()
                            .find(|(d, _, _)| *d == r.design)
                            .map(|(_, _, v)| v.iter().map(|x| x.1).collect())
                            .unwrap_or_default();
                        let mut row = r.clone();
                        row.design.point = 0;
                        SizeScore { score: search_score(self.space, &row, &values), row }
                    })
                    .collect();
                let score = sizes.iter().map(|z| z.score).min_by(f64::total_cmp).unwrap_or(all_failed);
                ModelScore { sizes, failed: failed[m], score }
            })
            .collect();
        match &self.space.robust {
            None => {
                let only = per_model.remove(0);
                e.sizes = only.sizes;
                e.score = only.score;
            }
            Some(r) => {
                // Per set size and selection: the models' scores combined (a model in which every
                // world failed scores the failures'); the row shown is the first model's that has it.
                let mut keys: Vec<(String, u32)> = Vec::new();
                for m in &per_model {
                    for z in &m.sizes {
                        let k = (z.row.design.selection.clone(), z.row.design.set_size);
                        if !keys.contains(&k) {
                            keys.push(k);
                        }
                    }
                }
                fn find<'a>(m: &'a ModelScore, k: &(String, u32)) -> Option<&'a SizeScore> {
                    m.sizes.iter().find(|z| z.row.design.selection == k.0 && z.row.design.set_size == k.1)
                }
                e.sizes = keys
                    .iter()
                    .map(|k| {
                        let scores: Vec<f64> = per_model.iter().map(|m| find(m, k).map_or(all_failed, |z| z.score)).collect();
                        let row = per_model.iter().find_map(|m| find(m, k)).expect("a model has it").row.clone();
                        SizeScore { row, score: r.combine.of(&scores) }
                    })
                    .collect();
                e.score = e.best().map_or(all_failed, |b| b.score);
                e.models = per_model;
            }
        }
        if let Some(r) = &e.repaired {
            e.score += REPAIR_PER_MM * r.moved_mm;
        }
        Ok(e)
    }

    fn info(&self, sweep: &Sweep) -> ShardInfo {
        let mut info = shard_info(sweep, 0, 1);
        info.objective = self.space.objective.clone();
        info
    }
}

/// A design's key: the first 16 hex digits of the sha256 of its scenario, the robot file it names
/// (`robot.file`, resolved to an absolute path on loading) keyed by the sha256 of its bytes rather
/// than by its place on disk, so that the same design has the same key, and its cached worlds
/// serve, from any checkout or directory (a file that cannot be read keeps its path).
pub fn design_key(table: &toml::Table) -> String {
    use sha2::Digest;
    let mut table = table.clone();
    if let Some(robot) = table.get_mut("robot").and_then(toml::Value::as_table_mut)
        && let Some(bytes) = robot
            .get("file")
            .and_then(toml::Value::as_str)
            .and_then(|f| crate::io::read_own(Path::new(f), crate::io::MOST_INPUT_BYTES).ok())
    {
        robot.insert("file".into(), toml::Value::String(format!("sha256:{:x}", sha2::Sha256::digest(&bytes))));
    }
    let text = toml::to_string(&table).unwrap_or_default();
    format!("{:x}", sha2::Sha256::digest(text.as_bytes()))[..16].to_string()
}

#[cfg(test)]
mod key_tests {
    /// The same design naming copies of one robot file in two directories has one key; another
    /// robot file, or another value of any key, gives another.
    #[test]
    fn a_design_key_does_not_depend_on_where_the_robot_file_lies() {
        let tmp = std::env::temp_dir().join(format!("calsim-design-key-{}", std::process::id()));
        let (a, b) = (tmp.join("a"), tmp.join("b"));
        for d in [&a, &b] {
            std::fs::create_dir_all(d).unwrap();
            std::fs::write(d.join("arm.toml"), "the same bytes").unwrap();
        }
        std::fs::write(a.join("other.toml"), "other bytes").unwrap();
        let design = |file: &std::path::Path, height: f64| -> toml::Table {
            let text = format!("[robot]\nfile = {:?}\nrepeatability_mm = 0.01\n[cell]\nheight_mm = {height}\n", file.display().to_string());
            toml::from_str(&text).unwrap()
        };
        let key = super::design_key(&design(&a.join("arm.toml"), 100.0));
        assert_eq!(key, super::design_key(&design(&b.join("arm.toml"), 100.0)));
        assert_ne!(key, super::design_key(&design(&a.join("other.toml"), 100.0)));
        assert_ne!(key, super::design_key(&design(&a.join("arm.toml"), 100.5)));
        assert_eq!(key.len(), 16);
        std::fs::remove_dir_all(&tmp).unwrap();
    }
}

/// Removes the temporaries of the cache writer ([`crate::io::out_dir::write_cache_file`]) that a
/// killed run left in `dir` (the restart records) and in the per-world directories of
/// `dir/<world context>/<design>/`: those of processes that are gone. Returns how many it removed.
pub fn remove_stale_temporaries(dir: &Path, world_context: &str) -> Result<usize, OptimiseError> {
    use crate::io::out_dir::{OutDirError, remove_stale_cache_temporaries};
    let err = |e: OutDirError| match e {
        OutDirError::Io { path, source } => OptimiseError::Io { path, source },
        other => OptimiseError::Io { path: dir.display().to_string(), source: std::io::Error::other(other.to_string()) },
    };
    let mut removed = remove_stale_cache_temporaries(dir).map_err(err)?;
    let worlds = dir.join(world_context);
    if let Ok(designs) = fs::read_dir(&worlds) {
        for entry in designs {
            let entry = entry.map_err(io_err(&worlds))?;
            if entry.file_type().map_err(io_err(&worlds))?.is_dir() {
                removed += remove_stale_cache_temporaries(&entry.path()).map_err(err)?;
            }
        }
    }
    Ok(removed)
}

/// The unit in the per-world file `file` of world `r` of `design` (`<world context>/<key>`),
/// checked whole: its JSON, its world, its design, and what it reports against what the design's
/// study promises (`study`, at `thresholds` thresholds; [`Unit::check_values`], the sweeps'
/// check). `None`: there is no such file (the world has not run).
fn read_world(file: &Path, r: u32, design: &str, study: &PointStudy, thresholds: usize) -> Result<Option<Unit>, OptimiseError> {
    let fail = |why: String| OptimiseError::World { path: file.display().to_string(), why };
    let bytes = match crate::io::read_bytes(file) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(fail(e.to_string())),
    };
    let u: Unit =
        serde_json::from_slice(&bytes).map_err(|e| fail(format!("not a per-world file calsim writes: {}", one_line(&e.to_string()))))?;
    if u.realisation != r || u.unit != r as usize || u.point != 0 {
        return Err(fail(format!("holds world {} (unit {}, point {}), not world {r} its name gives", u.realisation, u.unit, u.point)));
    }
    if u.design.as_deref() != Some(design) {
        return Err(fail(format!("design = {:?}: a world of another design or run, not of {design:?}", u.design.as_deref().unwrap_or(""))));
    }
    u.check_values(study, thresholds).map_err(fail)?;
    let digest = unit_digest(&Unit { digest: None, ..u.clone() });
    if u.digest.as_deref() != Some(digest.as_str()) {
        return Err(fail("digest: not the sha256 of the unit calsim wrote (the file was edited)".into()));
    }
    Ok(Some(u))
}

/// The sha256 of `u`'s JSON (hexadecimal): a per-world file's digest of itself without it.
fn unit_digest(u: &Unit) -> String {
    use sha2::Digest;
    format!("{:x}", sha2::Sha256::digest(serde_json::to_vec(u).expect("plain data")))
}

/// `s` on one line (a parser's message can span several).
fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// The restarts of a space: `(count of points, repetition)` in restart order: the first
/// repetition of every count, then the second of every count, and so on (the second
/// repetitions start from the first ones' best design, [`run_restart`]).
pub fn restarts(space: &DesignSpace) -> Vec<(usize, u32)> {
    let counts = space.counts();
    (0..space.search.restarts).flat_map(|k| counts.iter().map(move |&c| (c, k))).collect()
}

/// The best design the first repetitions found at any count (`[search] across_counts`): the
/// least search score among the designs that ran in some world (repaired ones as repaired),
/// the first of equal ones in restart order; `(count, x)`. `None` when none ran. Each first
/// repetition is run (or its record read back, [`run_restart`]) once per context.
fn best_of_first(ctx: &Context<'_>) -> Result<Option<(usize, Vec<f64>)>, OptimiseError> {
    if let Some(b) = ctx.best_of_first.get() {
        return Ok(b.clone());
    }
    let all = restarts(ctx.space);
    let mut best: Option<(f64, usize, Vec<f64>)> = None;
    for r in (0..all.len()).filter(|&r| all[r].1 == 0) {
        for e in run_restart(ctx, r, &|_| {})? {
            if e.violation.is_some() || e.worlds == 0 || e.failed == e.worlds {
                continue;
            }
            if best.as_ref().is_none_or(|b| e.score < b.0) {
                let x = e.repaired.as_ref().map_or_else(|| e.asked.x.clone(), |r| r.x.clone());
                best = Some((e.score, e.asked.count, x));
            }
        }
    }
    let b = best.map(|b| (b.1, b.2));
    Ok(ctx.best_of_first.get_or_init(|| b).clone())
}

/// The directory of the restarts' records and of the per-world files under `out`.
pub fn work_dir(out: &Path, name: &str) -> PathBuf {
    out.join(format!("{name}.evaluations"))
}

/// The record of restart `r` of `space`: named by the design file's identity and the search's
/// settings, so that a changed file or method runs its searches again (the per-world files,
/// named by their scenarios, are reused).
fn restart_file(dir: &Path, space: &DesignSpace, r: usize) -> PathBuf {
    use sha2::Digest;
    let s = &space.search;
    let settings = format!(
        "{}\u{0}{}\u{0}{}\u{0}{}\u{0}{}\u{0}{}\u{0}{}\u{0}start into reach and feasibility\u{0}{}\u{0}repair {}\u{0}across counts {}",
        space.identity,
        s.method.label(),
        s.evaluations,
        s.restarts,
        s.worlds,
        s.seed,
        s.score.label(),
        "latin-hypercube repetitions",
        s.repair,
        s.across_counts
    );
    let key = format!("{:x}", sha2::Sha256::digest(settings.as_bytes()));
    dir.join(format!("restart-{r:03}-{}.json", &key[..12]))
}

/// The record of restart `r` if a finished run left one, checked ([`check_record`]); a record that
/// cannot be read or parsed is refused naming it.
fn read_record(ctx: &Context<'_>, r: usize) -> Result<Option<Vec<Asked>>, OptimiseError> {
    let file = restart_file(&ctx.cache, ctx.space, r);
    let fail = |why: String| OptimiseError::Record { path: file.display().to_string(), key: "(file)".into(), why };
    let bytes = match crate::io::read_bytes(&file) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(fail(e.to_string())),
    };
    let asked: Vec<Asked> =
        serde_json::from_slice(&bytes).map_err(|e| fail(format!("not a restart record calsim writes: {}", one_line(&e.to_string()))))?;
    check_record(ctx.space, r, &asked, &file)?;
    Ok(Some(asked))
}

/// Latin-hypercube designs drawn per [`spread_starts`], the one whose closest two starts are the
/// farthest apart kept.
pub const SPREAD_DRAWS: usize = 32;

/// `n` starts spread over the box `[0.05, 0.95]^d` for the later repetitions of the searches of
/// `count` points: a Latin hypercube (each variable's range cut into `n` strata, each stratum
/// holding one start, the strata paired at random), the best of [`SPREAD_DRAWS`] by the least
/// distance between two of its starts (maximin), drawn from the count's own stream
/// ([`crate::seeds::optimise::spread`]). In 14-16 dimensions a handful of uniform draws leave
/// whole ranges of some variable unvisited; the hypercube visits every stratum of every variable.
pub fn spread_starts(d: usize, n: usize, seed: u64, count: usize) -> Vec<Vec<f64>> {
    use rand::RngExt;
    if n == 0 {
        return Vec::new();
    }
    let mut rng = crate::seeds::optimise::spread(seed, count);
    let mut best: Option<(f64, Vec<Vec<f64>>)> = None;
    for _ in 0..SPREAD_DRAWS {
        let mut pts = vec![vec![0.0; d]; n];
        for k in 0..d {
            // A random permutation of the strata (Fisher-Yates), a uniform place within each.
            let mut strata: Vec<usize> = (0..n).collect();
            for i in (1..n).rev() {
                strata.swap(i, rng.random_range(0..=i));
            }
            for (i, p) in pts.iter_mut().enumerate() {
                p[k] = 0.05 + 0.9 * (strata[i] as f64 + rng.random_range(0.0..1.0)) / n as f64;
            }
        }
        let mut closest = f64::INFINITY;
        for i in 0..n {
            for j in 0..i {
                closest = closest.min(pts[i].iter().zip(&pts[j]).map(|(a, b)| (a - b).powi(2)).sum::<f64>());
            }
        }
        if best.as_ref().is_none_or(|b| closest > b.0) {
            best = Some((closest, pts));
        }
    }
    best.map(|b| b.1).unwrap_or_default()
}

/// Designs the search to bring a start into reach may try ([`into_reach`]).
pub const INTO_REACH_BUDGET: u32 = 600;

/// The start `start` of a restart of `count` points brought into the arm's reach and to a
/// campaign that can run: where the design there has points out of reach
/// ([`reach::sphere_margins_mm`], a TriCal design) or a pool or validation set short of candidate
/// poses reachable without collision ([`crate::device::Scenario::campaign_feasibility`]), the
/// first design of the least such distance ([`runs_distance`]: the points' distances from the
/// reach plus 100 mm per unit of the sets' shortfalls) that Nelder-Mead finds from the start
/// within [`INTO_REACH_BUDGET`] designs, minimising it (designs the geometry rules out or the
/// scenario refuses counting as farther than any); elsewhere `start` itself. No world runs: the
/// reach and the candidate poses are the arm's kinematics and the cell's solids at their mean
/// values, so the search then starts from designs that run rather than spending its evaluations
/// on campaigns that fail.
pub fn into_reach(ctx: &Context<'_>, count: usize, start: Vec<f64>) -> Vec<f64> {
    let space = ctx.space;
    let distance = |x: &[f64]| -> f64 {
        let d = space.decode(count, x);
        if let Some((_, m)) = d.violation {
            return 1e6 + m;
        }
        match ctx.point(String::new(), &d.table) {
            Ok(p) => runs_distance(p.scenario.as_ref()),
            Err(_) => 1e7,
        }
    };
    let at_start = distance(&start);
    if at_start <= 0.0 {
        return start;
    }
    let mut best = (at_start, start.clone());
    let mut f = |x: &[f64]| -> f64 {
        if best.0 <= 0.0 {
            // In reach: the search winds down.
            return 0.0;
        }
        let v = distance(x);
        if v < best.0 {
            best = (v, x.to_vec());
        }
        v
    };
    // A search that stops early (argmin's error) keeps the best design it found.
    let _ = search::minimise(spec::Method::NelderMead, &start, INTO_REACH_BUDGET, 0, &mut f);
    best.1
}

/// Runs restart `r`: the search's designs in the order asked, each evaluated (its worlds read from
/// the per-world files where a run left them), calling `progress(done)` after each. The search is
/// deterministic and evaluating a design whose worlds are kept costs their reading: a restart
/// whose record a finished run left is searched again, and the record must be exactly what the
/// search asks (a record edited, cut short, reordered or of another search is refused naming its
/// entry); without a record, the record is written.
pub fn run_restart(ctx: &Context<'_>, r: usize, progress: &(dyn Fn(usize) + Sync)) -> Result<Vec<Evaluated>, OptimiseError> {
    let space = ctx.space;
    let (count, rep) = restarts(space)[r];
    let file = restart_file(&ctx.cache, space, r);
    let record = read_record(ctx, r)?;
    let mismatch = |key: String, why: String| OptimiseError::Record { path: file.display().to_string(), key, why };
    let mut start = space.start(count);
    let seeded = if rep == 1 && space.search.across_counts { best_of_first(ctx)? } else { None };
    if let Some((from, x)) = seeded {
        // The second repetition: from the best design of the first ones at any count.
        start = space.recount(from, &x, count);
    } else if rep > 0 {
        // Later repetitions start elsewhere: spread over the box.
        start = spread_starts(space.dimensions(count), space.search.restarts as usize - 1, space.search.seed, count)
            .swap_remove(rep as usize - 1);
    }
    let start = into_reach(ctx, count, start);
    let mut out: Vec<Evaluated> = Vec::new();
    let mut failure: Option<OptimiseError> = None;
    let seed = crate::seeds::optimise::swarm(space.search.seed, r);
    let mut f = |x: &[f64]| -> f64 {
        if failure.is_some() {
            return f64::INFINITY;
        }
        let asked = Asked { restart: r as u32, index: out.len() as u32, count, x: x.to_vec() };
        if let Some(rec) = &record
            && rec.get(out.len()) != Some(&asked)
        {
            let i = out.len();
            failure = Some(match rec.get(i) {
                Some(_) => mismatch(
                    format!("[{i}].x"),
                    "not the design the search asks at this entry (the record was edited, reordered or written by another search)".into(),
                ),
                None => mismatch("(file)".into(), format!("{} designs: the search asks more (the record was cut short)", rec.len())),
            });
            return f64::INFINITY;
        }
        match ctx.evaluate(asked) {
            Ok(e) => {
                let s = e.score;
                out.push(e);
                progress(out.len());
                s
            }
            Err(e) => {
                failure = Some(e);
                f64::INFINITY
            }
        }
    };
    search::minimise(space.search.method, &start, space.search.evaluations, seed, &mut f)
        .map_err(|e| OptimiseError::Search(e.to_string()))?;
    if let Some(e) = failure {
        return Err(e);
    }
    match record {
        Some(rec) if rec.len() != out.len() => Err(mismatch(
            "(file)".into(),
            format!("{} designs: the search asks {} (the record holds designs it never asked)", rec.len(), out.len()),
        )),
        Some(_) => Ok(out),
        None => {
            let asked: Vec<&Asked> = out.iter().map(|e| &e.asked).collect();
            fs::create_dir_all(&ctx.cache).map_err(io_err(&ctx.cache))?;
            crate::io::out_dir::write_cache_file(&file, &serde_json::to_vec(&asked).expect("plain data")).map_err(io_err(&file))?;
            Ok(out)
        }
    }
}

/// Every restart's designs, evaluated, in restart order: all must have finished (their records
/// there), and each record is checked by searching its restart again ([`run_restart`]).
pub fn read_restarts(ctx: &Context<'_>) -> Result<Vec<Evaluated>, OptimiseError> {
    let n = restarts(ctx.space).len();
    for r in 0..n {
        if read_record(ctx, r)?.is_none() {
            return Err(OptimiseError::Incomplete {
                dir: ctx.cache.display().to_string(),
                why: format!("restart {r} of {n} has not finished (run its shard: `calsim optimise <file> --shard k/n`)"),
            });
        }
    }
    let mut out = Vec::new();
    for r in 0..n {
        out.extend(run_restart(ctx, r, &|_| {})?);
    }
    Ok(out)
}

/// A design of the final stages: a label, its scenario table, its key, where it came from.
#[derive(Clone, Debug)]
pub struct Candidate {
    /// What it is (`3 spheres, restart 0 #12`, or `sphere_layout #4`).
    pub label: String,
    /// Its count of points (0: a compared design).
    pub count: usize,
    /// Its scenario.
    pub table: toml::Table,
    /// Its key.
    pub key: String,
    /// Its points in the region's frame, mm (empty for a compared design).
    pub points_mm: Vec<[f64; 3]>,
    /// Its search score (compared designs: none).
    pub search_score: Option<f64>,
    /// Whether it is a compared design (of a sweep file), not the optimiser's.
    pub compared: bool,
}

/// The race of the finalists on search worlds, then the held-out verification.
#[derive(Clone, Debug)]
pub struct Verdict {
    /// Every design evaluated by the search, in restart and ask order.
    pub trace: Vec<Evaluated>,
    /// The finalists and their race over search worlds (judged rows; the race's plan).
    pub finalists: Vec<Candidate>,
    /// See `finalists`.
    pub race_rows: Vec<DesignRow>,
    /// Worlds the race ran (most of any finalist).
    pub race_worlds: u32,
    /// Designs verified on held-out worlds: the best of each count, then the compared designs.
    pub verified: Vec<Candidate>,
    /// Their judged rows on the held-out worlds.
    pub held_out_rows: Vec<DesignRow>,
    /// With `[robust]`: every model's race and held-out rows and the winner under each model and
    /// under the combined score (`race_rows` and `held_out_rows` are then the first model's).
    pub robust: Option<RobustVerdict>,
    /// Without `[robust]`: the answer rule's row of `race_rows` ([`answer_of`]) and how it chose.
    pub answer: Option<(usize, AnswerBasis)>,
}

/// A robust design's race and verification under each error model.
#[derive(Clone, Debug)]
pub struct RobustVerdict {
    /// The models' names.
    pub models: Vec<String>,
    /// How their scores combine.
    pub combine: spec::Combine,
    /// Per model, the finalists' rows on the race's search worlds (`0..race.max`, every world).
    pub race: Vec<Vec<DesignRow>>,
    /// Per model, the verified designs' rows on the held-out worlds.
    pub held_out: Vec<Vec<DesignRow>>,
    /// The winner under each model (in order) and last under the combined score: the best
    /// (finalist, selection, set size) by that score on the race's worlds, as a verified design.
    pub choices: Vec<Choice>,
}

/// A winner under one criterion of a robust design.
#[derive(Clone, Debug, PartialEq)]
pub struct Choice {
    /// A model's name, or `robust (mean)` / `robust (worst)`.
    pub criterion: String,
    /// The verified design (index into `Verdict::verified`).
    pub verified: usize,
    /// Its selection and set size.
    pub selection: String,
    /// See `selection`.
    pub set_size: u32,
    /// Its score by the criterion on the race's worlds.
    pub race_score: f64,
}

/// A judged row's design: (point, selection, set size).
pub type RowKey = (usize, String, u32);

/// One (point, selection, set size) under every model: the per-model scores and their combination.
#[derive(Clone, Debug, PartialEq)]
pub struct Combined {
    /// The point, selection and set size.
    pub key: RowKey,
    /// Per model, its score (lower is better).
    pub scores: Vec<f64>,
    /// The scores combined by `[robust] score`.
    pub score: f64,
}

/// Per (point, selection, set size) of rows judged per model (`rows[m]`): the per-model scores
/// and their combination. A model without the row (every world failed) scores 2 * PENALTY.
pub fn combined(space: &DesignSpace, rows: &[Vec<DesignRow>]) -> Vec<Combined> {
    let combine = space.robust.as_ref().map_or(spec::Combine::Mean, |r| r.combine);
    let mut keys: BTreeMap<RowKey, Vec<f64>> = BTreeMap::new();
    for (m, rs) in rows.iter().enumerate() {
        for r in rs {
            let k = (r.design.point, r.design.selection.clone(), r.design.set_size);
            keys.entry(k).or_insert_with(|| vec![FAILED; rows.len()])[m] = score_of(space, r);
        }
    }
    keys.into_iter()
        .map(|(key, scores)| {
            let score = combine.of(&scores);
            Combined { key, scores, score }
        })
        .collect()
}

/// Runs (or reads) every candidate under every model on `worlds` and judges each model's
/// candidates together: the rows per model.
fn judged_by_model(ctx: &Context<'_>, candidates: &[Candidate], worlds: &[u32], stride: u32) -> Result<Vec<Vec<DesignRow>>, OptimiseError> {
    let space = ctx.space;
    let models = space.model_names().len();
    let n = candidates.len();
    let mut points: Vec<(String, Point)> = Vec::with_capacity(models * n);
    for m in 0..models {
        for c in candidates {
            let t = space.with_model(&c.table, m);
            let key = design_key(&t);
            points.push(ctx.point(key.clone(), &t).map(|p| (key, p)).map_err(OptimiseError::Search)?);
        }
    }
    let units = ctx.units(&points, worlds, stride)?;
    Ok((0..models)
        .map(|m| {
            let of: Vec<Unit> = units
                .iter()
                .filter(|u| u.point / n.max(1) == m)
                .map(|u| {
                    let mut u = u.clone();
                    u.point -= m * n;
                    u.unit -= m * n * stride as usize;
                    u
                })
                .collect();
            let info = ctx.info(&ctx.sweep_of(points[m * n..(m + 1) * n].iter().map(|p| p.1.clone()).collect(), stride));
            designs::judge(&info, &of, &[])
        })
        .collect())
}

/// [`finish`] under `[robust]`: finalists per count by the combined score, and each model's best;
/// every finalist under every model on all the race's worlds (no elimination); the winner under
/// each model and under the combined score; the best of each count by the combined score, the
/// winners and the compared designs under every model on the held-out worlds.
fn finish_robust(
    ctx: &Context<'_>,
    trace: Vec<Evaluated>,
    compare: Vec<Candidate>,
    progress: &(dyn Fn(usize, usize, &str) + Sync),
) -> Result<Verdict, OptimiseError> {
    let space = ctx.space;
    let r = space.robust.as_ref().expect("robust");
    let names = space.model_names();
    let models = names.len();
    let candidate = |e: &Evaluated, count: usize| Candidate {
        label: format!("{count} points, restart {} #{}", e.asked.restart, e.asked.index),
        count,
        table: e.table.clone().expect("ran"),
        key: e.key.clone(),
        points_mm: e.points_mm.clone(),
        search_score: Some(e.score),
        compared: false,
    };
    let order = |a: &&Evaluated, b: &&Evaluated, sa: f64, sb: f64| {
        sa.total_cmp(&sb).then(a.asked.restart.cmp(&b.asked.restart)).then(a.asked.index.cmp(&b.asked.index))
    };
    let mut finalists: Vec<Candidate> = Vec::new();
    for count in space.counts() {
        let ran: Vec<&Evaluated> = trace.iter().filter(|e| e.asked.count == count && e.table.is_some() && e.best().is_some()).collect();
        let mut of = ran.clone();
        of.sort_by(|a, b| order(a, b, a.score, b.score));
        let mut taken = 0;
        for e in of {
            if taken == space.search.finalists || finalists.iter().any(|f| f.key == e.key) {
                continue;
            }
            finalists.push(candidate(e, count));
            taken += 1;
        }
        for m in 0..models {
            let best =
                ran.iter().filter(|e| !e.models[m].sizes.is_empty()).min_by(|a, b| order(a, b, a.models[m].score, b.models[m].score));
            if let Some(e) = best
                && !finalists.iter().any(|f| f.key == e.key)
            {
                finalists.push(candidate(e, count));
            }
        }
    }
    let stride = space.search.race.max;
    let worlds: Vec<u32> = (0..stride).collect();
    progress(0, finalists.len() * models * worlds.len(), "race: worlds of the finalists under every model");
    let race = judged_by_model(ctx, &finalists, &worlds, stride)?;
    let scores = combined(space, &race);
    // The winner under each model, then under the combined score (ties: the first in order).
    let pick = |c: usize| -> Option<(RowKey, f64)> {
        scores
            .iter()
            .map(|x| (&x.key, if c < models { x.scores[c] } else { x.score }))
            .min_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(b.0)))
            .map(|(k, s)| (k.clone(), s))
    };
    let mut verified: Vec<Candidate> = Vec::new();
    let add = |f: usize, verified: &mut Vec<Candidate>| -> usize {
        match verified.iter().position(|c| c.key == finalists[f].key) {
            Some(i) => i,
            None => {
                verified.push(finalists[f].clone());
                verified.len() - 1
            }
        }
    };
    for count in space.counts() {
        let best =
            scores.iter().filter(|x| finalists[x.key.0].count == count).min_by(|a, b| a.score.total_cmp(&b.score).then(a.key.cmp(&b.key)));
        if let Some(x) = best {
            add(x.key.0, &mut verified);
        }
    }
    let mut choices = Vec::new();
    for c in 0..=models {
        if let Some(((f, selection, set_size), race_score)) = pick(c) {
            let criterion = if c < models { names[c].clone() } else { format!("robust ({})", r.combine.label()) };
            choices.push(Choice { criterion, verified: add(f, &mut verified), selection, set_size, race_score });
        }
    }
    verified.extend(compare);
    let held: Vec<u32> = (0..space.held_out).map(|k| HELD_OUT_BASE + k).collect();
    progress(0, verified.len() * models * held.len(), "held-out worlds under every model");
    let held_out = judged_by_model(ctx, &verified, &held, space.held_out)?;
    Ok(Verdict {
        trace,
        finalists,
        race_rows: race[0].clone(),
        race_worlds: stride,
        verified,
        held_out_rows: held_out[0].clone(),
        robust: Some(RobustVerdict { models: names, combine: r.combine, race, held_out, choices }),
        answer: None,
    })
}

/// How the answer rule chose the answer among the race's rows ([`answer_of`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AnswerBasis {
    /// Some rows meet every constraint at the confidence: the one with the smallest campaign.
    SmallestMeeting,
    /// No row meets every constraint at the confidence (or the objective sets no least P(success)
    /// to meet): the race's first.
    RaceFirst,
}

/// The answer rule over the race's rows (designs, set sizes and selections of the finalists on the
/// search worlds): for `maximise = "success"` with `success_at_least`, the rows meeting every
/// constraint at the confidence (feasible), the smallest campaign first, then the smaller set
/// size, then the higher estimate, then the race's order; without such a row, or for another
/// objective, the race's first (feasible, then undecided, then the rest; the best estimate
/// within each). Returns the row's index in `rows`.
pub fn answer_of(space: &DesignSpace, rows: &[DesignRow]) -> Option<(usize, AnswerBasis)> {
    use crate::design::sweep::designs::Feasibility;
    let o = &space.objective;
    let first = || rows.iter().enumerate().min_by_key(|(_, r)| r.rank).map(|(i, _)| (i, AnswerBasis::RaceFirst));
    if !(o.goal == Goal::MaximiseSuccess && o.success_at_least.is_some()) {
        return first();
    }
    let meeting = rows.iter().enumerate().filter(|(_, r)| r.feasibility == Feasibility::Feasible).min_by(|(_, a), (_, b)| {
        a.campaign_h
            .total_cmp(&b.campaign_h)
            .then(a.design.set_size.cmp(&b.design.set_size))
            .then(b.estimate.total_cmp(&a.estimate))
            .then(a.rank.cmp(&b.rank))
    });
    match meeting {
        Some((i, _)) => Some((i, AnswerBasis::SmallestMeeting)),
        None => first(),
    }
}

/// Races the best designs of the search on more search worlds, then verifies the best of each
/// count and the compared designs on the held-out worlds; `progress(done, total, stage)`.
pub fn finish(
    ctx: &Context<'_>,
    trace: Vec<Evaluated>,
    compare: Vec<Candidate>,
    progress: &(dyn Fn(usize, usize, &str) + Sync),
) -> Result<Verdict, OptimiseError> {
    let space = ctx.space;
    if space.robust.is_some() {
        return finish_robust(ctx, trace, compare, progress);
    }
    // Finalists: per count, the best distinct designs by search score that ran.
    let mut finalists: Vec<Candidate> = Vec::new();
    for count in space.counts() {
        let mut of: Vec<&Evaluated> = trace.iter().filter(|e| e.asked.count == count && e.table.is_some() && e.best().is_some()).collect();
        of.sort_by(|a, b| a.score.total_cmp(&b.score).then(a.asked.restart.cmp(&b.asked.restart)).then(a.asked.index.cmp(&b.asked.index)));
        let mut taken = 0;
        for e in of {
            if taken == space.search.finalists || finalists.iter().any(|f| f.key == e.key) {
                continue;
            }
            finalists.push(Candidate {
                label: format!("{count} points, restart {} #{}", e.asked.restart, e.asked.index),
                count,
                table: e.table.clone().expect("filtered"),
                key: e.key.clone(),
                points_mm: e.points_mm.clone(),
                search_score: Some(e.score),
                compared: false,
            });
            taken += 1;
        }
    }
    // The race: the sweeps' racing over the finalists' points, search worlds only.
    let race = space.search.race.clone();
    let points: Vec<(String, Point)> = finalists
        .iter()
        .map(|c| ctx.point(c.key.clone(), &c.table).map(|p| (c.key.clone(), p)))
        .collect::<Result<_, _>>()
        .map_err(OptimiseError::Search)?;
    let mut sweep = ctx.sweep_of(points.iter().map(|p| p.1.clone()).collect(), race.max);
    sweep.race = Some(race.clone());
    let info = ctx.info(&sweep);
    let mut present: BTreeMap<usize, Unit> = BTreeMap::new();
    let plan = loop {
        let plan = crate::design::sweep::race::plan(&info, &present);
        if plan.complete || points.is_empty() {
            break plan;
        }
        // Missing units grouped by point: each point's worlds read or run.
        let mut by_point: BTreeMap<usize, Vec<u32>> = BTreeMap::new();
        for &u in &plan.missing {
            by_point.entry(u / race.max as usize).or_default().push((u % race.max as usize) as u32);
        }
        progress(present.len(), present.len() + plan.missing.len(), "race: worlds of the finalists");
        let jobs: Vec<Vec<Unit>> = by_point
            .iter()
            .map(|(&p, worlds)| {
                let mut us = ctx.units(std::slice::from_ref(&points[p]), worlds, race.max)?;
                for u in &mut us {
                    u.point = p;
                    u.unit = p * race.max as usize + u.realisation as usize;
                }
                Ok(us)
            })
            .collect::<Result<_, OptimiseError>>()?;
        for u in jobs.into_iter().flatten() {
            present.insert(u.unit, u);
        }
    };
    let units: Vec<Unit> = present.values().cloned().collect();
    let race_rows = designs::judge(&info, &units, &plan.eliminated);
    let race_worlds = units.iter().map(|u| u.realisation + 1).max().unwrap_or(0);
    // The best finalist of each count by the race (its rank among that count's rows), and the
    // answer's finalist (the answer rule's row) if it is not one of them.
    let mut verified: Vec<Candidate> = Vec::new();
    for count in space.counts() {
        let best = race_rows.iter().filter(|r| finalists[r.design.point].count == count).min_by_key(|r| r.rank);
        if let Some(r) = best {
            verified.push(finalists[r.design.point].clone());
        }
    }
    let answer = answer_of(space, &race_rows);
    if let Some((i, _)) = answer {
        let f = &finalists[race_rows[i].design.point];
        if !verified.iter().any(|c| c.key == f.key) {
            verified.push(f.clone());
        }
    }
    verified.extend(compare);
    let held: Vec<u32> = (0..space.held_out).map(|k| HELD_OUT_BASE + k).collect();
    let vpoints: Vec<(String, Point)> = verified
        .iter()
        .map(|c| ctx.point(c.key.clone(), &c.table).map(|p| (c.key.clone(), p)))
        .collect::<Result<_, _>>()
        .map_err(OptimiseError::Search)?;
    progress(0, vpoints.len() * held.len(), "held-out worlds");
    let vunits = ctx.units(&vpoints, &held, space.held_out)?;
    let vinfo = ctx.info(&ctx.sweep_of(vpoints.iter().map(|p| p.1.clone()).collect(), space.held_out));
    let held_out_rows = designs::judge(&vinfo, &vunits, &[]);
    Ok(Verdict { trace, finalists, race_rows, race_worlds, verified, held_out_rows, robust: None, answer })
}

/// The designs of a sweep file as candidates to verify beside the optimiser's (each grid point
/// with the sweep's own fixed keys).
pub fn compared(path: &Path) -> Result<Vec<Candidate>, crate::design::sweep::SweepError> {
    let sweep = crate::design::sweep::spec::load(path)?;
    let stem = sweep.name.clone();
    Ok(sweep
        .points
        .iter()
        .enumerate()
        .map(|(p, point)| {
            let table: toml::Table = point.scenario.header().text.parse().unwrap_or_default();
            let label = format!("{stem} #{p}: {}", point.values.iter().map(|(k, v)| format!("{k} = {v}")).collect::<Vec<_>>().join(", "));
            Candidate {
                key: design_key(&table),
                label,
                count: 0,
                table,
                points_mm: point.scenario.layout_mm(),
                search_score: None,
                compared: true,
            }
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::out_dir::cache_temporaries as temporaries;

    /// The spread starts: every stratum of every variable holds one start, inside [0.05, 0.95],
    /// the same for the same seed and count, other starts for another count; and their closest
    /// pair farther apart than that of as many uniform draws would typically be.
    #[test]
    fn spread_starts_are_a_latin_hypercube_over_the_box() {
        let (d, n) = (16, 8);
        let s = spread_starts(d, n, 2018, 5);
        assert_eq!(s.len(), n);
        for k in 0..d {
            let mut strata: Vec<usize> = s.iter().map(|p| ((p[k] - 0.05) / 0.9 * n as f64).floor() as usize).collect();
            strata.sort();
            assert_eq!(strata, (0..n).collect::<Vec<_>>(), "variable {k}: one start per stratum");
        }
        assert!(s.iter().flatten().all(|v| (0.05..0.95).contains(v)));
        assert_eq!(s, spread_starts(d, n, 2018, 5));
        assert_ne!(s, spread_starts(d, n, 2018, 6));
        assert!(spread_starts(d, 0, 2018, 5).is_empty());
        let closest = |p: &[Vec<f64>]| {
            let mut c = f64::INFINITY;
            for i in 0..p.len() {
                for j in 0..i {
                    c = c.min(p[i].iter().zip(&p[j]).map(|(a, b)| (a - b).powi(2)).sum::<f64>().sqrt());
                }
            }
            c
        };
        // The median closest pair of 32 sets of 8 uniform draws in [0.05, 0.95]^16.
        use rand::RngExt;
        let mut rng = crate::seeds::fixed_stream(1);
        let mut uniform: Vec<f64> = (0..32)
            .map(|_| closest(&(0..n).map(|_| (0..d).map(|_| rng.random_range(0.05..0.95)).collect()).collect::<Vec<Vec<f64>>>()))
            .collect();
        uniform.sort_by(f64::total_cmp);
        assert!(closest(&s) > uniform[16], "{} against the uniform draws' median {}", closest(&s), uniform[16]);
    }

    #[test]
    fn temporaries_of_gone_processes_are_removed_and_a_live_ones_kept() {
        let dir = tempfile::tempdir().unwrap();
        let design = dir.path().join("ctx").join("0123456789abcdef");
        fs::create_dir_all(&design).unwrap();
        let mine = format!("r0000000.tmp-{}-ThreadId2", std::process::id());
        for (d, name) in [
            (dir.path(), "restart-000-abc.tmp-999999999-ThreadId1".to_string()),
            (design.as_path(), "r0000001.tmp-999999999-ThreadId7".to_string()),
            (design.as_path(), mine.clone()),
            (design.as_path(), "r0000002.json".to_string()),
        ] {
            fs::write(d.join(name), b"x").unwrap();
        }
        assert_eq!(remove_stale_temporaries(dir.path(), "ctx").unwrap(), 2);
        assert!(temporaries(dir.path()).is_empty());
        assert_eq!(temporaries(&design), vec![mine]);
        assert!(design.join("r0000002.json").exists(), "a per-world file is not a temporary");
        // A work directory not made yet has nothing to remove.
        assert_eq!(remove_stale_temporaries(&dir.path().join("none"), "ctx").unwrap(), 0);
    }
}
