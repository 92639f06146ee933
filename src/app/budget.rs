//! `budget`: every error source of a scenario alone, off and scaled, over the same realisations,
//! with the linear prediction beside the Monte Carlo.

use std::path::{Path, PathBuf};
use std::time::Instant;

use super::{Error, Observer, thread_pool, threads_label};
use crate::design::budget::{self, results::BudgetReport};
use crate::design::sweep;
use crate::study::prediction::Prediction;

/// What `budget` is asked.
#[derive(Clone, Debug)]
pub struct BudgetSpec {
    /// The scenario file (any device).
    pub scenario: PathBuf,
    /// The directory the budget goes in (in `<scenario>.budget`).
    pub out: PathBuf,
    /// Realisations per configuration.
    pub realisations: u32,
    /// What-if factors applied to each source in turn.
    pub factors: Vec<f64>,
    /// Repetitions per configuration and realisation (`None`: the scenario's).
    pub repetitions: Option<u32>,
    /// Worker threads.
    pub threads: Option<u32>,
}

/// What a budget did.
#[derive(Clone, Debug)]
pub struct BudgetRun {
    /// Where the budget's results are.
    pub dest: PathBuf,
    /// Work units run.
    pub units: usize,
    /// Wall time, s.
    pub run_s: f64,
    /// The budget table (`summary.md`'s text).
    pub summary: String,
}

/// Most realisations a budget takes.
pub const MOST_REALISATIONS: u32 = 10_000;

/// Most what-if factors a budget takes.
pub const MOST_FACTORS: usize = 8;

/// Runs the budget of `spec.scenario`.
pub fn run(spec: &BudgetSpec, observer: &dyn Observer) -> Result<BudgetRun, Error> {
    let _inputs = crate::io::inputs::Ledger::open();
    let t0 = Instant::now();
    if spec.factors.len() > MOST_FACTORS {
        return Err(Error::input("--factors", format!("{} factors, at most {MOST_FACTORS}", spec.factors.len())));
    }
    if let Some(f) = spec.factors.iter().find(|f| !(f.is_finite() && (0.0..=100.0).contains(*f))) {
        return Err(Error::input("--factors", format!("{f}: a factor within [0, 100]")));
    }
    if !(1..=MOST_REALISATIONS).contains(&spec.realisations) {
        return Err(Error::input("--realisations", format!("{}: within [1, {MOST_REALISATIONS}]", spec.realisations)));
    }
    if let Some(r) = spec.repetitions
        && !(1..=crate::study::MAX_REPETITIONS).contains(&r)
    {
        return Err(Error::input("--repetitions", format!("{r}: within [1, {}]", crate::study::MAX_REPETITIONS)));
    }
    // The budget's name is the scenario file's stem: one path component, checked before anything runs.
    crate::io::names::of_file(&spec.scenario)?;
    let (sources, configs, mut plan) = budget::plan(&spec.scenario, spec.realisations, &spec.factors, spec.repetitions)?;
    plan.predict = true;
    crate::io::out_dir::prepare(&spec.out, &plan.name)?;
    crate::io::out_dir::prepare_work(
        &spec.out,
        &sweep::shard_dir(Path::new(""), &plan.name, 0, 1).display().to_string(),
        sweep::SHARD_MARKER,
    )?;
    let (pool, threads) = thread_pool(spec.threads)?;
    observer.started(&format!(
        "calsim budget: {} ({} sources, {} configurations x {} realisations), {}",
        plan.name,
        sources.len(),
        configs.len(),
        spec.realisations,
        threads_label(threads)
    ));
    let dir = pool
        .install(|| sweep::run_shard(&plan, &spec.out, 0, 1, &|done, total| observer.progress(done, total, "work units")))
        .map_err(Error::io(&spec.out))?
        .dir;
    observer.stage_done();
    let (info, units) = sweep::read_shards(std::slice::from_ref(&dir))?;
    let points = sweep::aggregate(&info, &units);
    let rows: Vec<Option<&sweep::PointRow>> = (0..configs.len()).map(|i| points.iter().find(|p| p.point == i && p.table)).collect();
    let p95: Vec<f64> = rows.iter().map(|r| r.map_or(f64::NAN, |r| r.after[1][0])).collect();
    let (all_mm, none_mm, lines) = budget::lines(&sources, &configs, &p95);
    // Per configuration and world, the p95 at the table set size (NaN where the world could not run it).
    let per_world: Vec<Vec<f64>> = (0..configs.len())
        .map(|i| {
            (0..info.realisations)
                .map(|r| {
                    units
                        .iter()
                        .find(|u| u.point == i && u.realisation == r)
                        .and_then(|u| u.rows.iter().find(|row| row.table))
                        .map_or(f64::NAN, |row| row.after_p95_mm)
                })
                .collect()
        })
        .collect();
    let shares = budget::shares(&sources, &configs, &per_world);
    let against = budget::against_all_on(&configs, &per_world);
    let warnings = budget::warnings(&sources, &shares, spec.realisations);
    for w in &warnings {
        observer.warning(w);
    }
    // The linear prediction per configuration, merged over realisations in unit order.
    let predictions: Vec<Option<Prediction>> = (0..configs.len())
        .map(|i| {
            units.iter().filter(|u| u.point == i).filter_map(|u| u.prediction.as_ref()).fold(None, |acc, p| {
                let mut acc: Prediction = acc.unwrap_or_default();
                acc.merge(p);
                Some(acc)
            })
        })
        .collect();
    let overrides: Vec<(String, String)> = spec.repetitions.iter().map(|r| ("study.repetitions".to_string(), r.to_string())).collect();
    let report = BudgetReport {
        name: &plan.name,
        realisations: spec.realisations,
        sources: &sources,
        configs: &configs,
        rows,
        all_mm,
        none_mm,
        lines: &lines,
        predictions: &predictions,
        shares: &shares,
        against: &against,
        warnings: &warnings,
        overrides: &overrides,
    };
    let (dest, summary) = budget::results::write(&spec.out, &report).map_err(Error::io(&spec.out))?;
    std::fs::remove_dir_all(&dir).map_err(Error::io(&dir))?;
    Ok(BudgetRun { dest, units: units.len(), run_s: t0.elapsed().as_secs_f64(), summary })
}
