//! `optimise`: search a design file's space for its objective, race the finalists, verify them on
//! held-out worlds and write the results; or one shard of the restarts, or the merge of them.

use std::path::PathBuf;
use std::time::Instant;

use super::{Error, Observer, thread_pool, threads_label};
use crate::design::optimise::{self, Context, DesignSpace, OptimiseError, plots::OptimisePlotInputs, results};

/// What `optimise` is asked.
#[derive(Clone, Debug)]
pub struct OptimiseSpec {
    /// The design file.
    pub file: PathBuf,
    /// The directory of the evaluations and of the results.
    pub out: PathBuf,
    /// Only the restarts `r % K == k` (`None`: every restart, then the merge).
    pub shard: Option<(usize, usize)>,
    /// Only the merge of finished restarts (race, verification, results).
    pub merge: bool,
    /// Worker threads.
    pub threads: Option<u32>,
    /// The search method replacing the file's.
    pub method: Option<optimise::spec::Method>,
    /// Draw the figures.
    pub plots: bool,
}

/// What a run did.
#[derive(Clone, Debug)]
pub struct OptimiseReport {
    /// The design file's name.
    pub name: String,
    /// Restarts this run was responsible for, and designs they evaluated.
    pub restarts: usize,
    /// See `restarts`.
    pub evaluations: usize,
    /// Wall time of the search, of the race and verification, s.
    pub search_s: f64,
    /// See `search_s`.
    pub finish_s: f64,
    /// The results directory and the summary, when this run merged.
    pub dest: Option<PathBuf>,
    /// See `dest`.
    pub summary: Option<String>,
    /// The winner's timing line (one world of it, run again): where its time goes.
    pub cost: Option<String>,
}

fn design_err(e: optimise::DesignError) -> Error {
    Error::input(format!("{}: {}", e.path, e.key), e.message)
}

fn opt_err(e: OptimiseError) -> Error {
    match e {
        OptimiseError::Io { path, source } => Error::Io { path, source },
        OptimiseError::Record { path, key, why } => Error::input(format!("{path}: {key}"), why),
        OptimiseError::World { path, why } => Error::input(path, why),
        other => Error::input("optimise", other.to_string()),
    }
}

/// Runs the optimiser of `spec.file` (or one shard of its restarts, or only their merge).
pub fn run(spec: &OptimiseSpec, observer: &dyn Observer) -> Result<OptimiseReport, Error> {
    let _inputs = crate::io::inputs::Ledger::open();
    if let Some((k, n)) = spec.shard {
        if n == 0 || n > super::sweep::MOST_SHARDS || k >= n {
            return Err(Error::input("--shard", format!("{k}/{n}: k/K with 1 <= K <= {} and 0 <= k < K", super::sweep::MOST_SHARDS)));
        }
        if spec.merge {
            return Err(Error::input("--merge", "merge or one shard of the restarts, not both: merge when every shard has run"));
        }
    }
    crate::io::names::of_file(&spec.file)?;
    let mut space = optimise::spec::load(&spec.file).map_err(design_err)?;
    if let Some(m) = spec.method {
        space.search.method = m;
    }
    let (pool, threads) = thread_pool(spec.threads)?;
    // Every input read (the compared scenarios too) before the outputs are vetted against them.
    let compare: Vec<optimise::Candidate> =
        space.compare.iter().map(|p| optimise::compared(p)).collect::<Result<Vec<_>, _>>()?.into_iter().flatten().collect();
    crate::io::out_dir::prepare_cache(&spec.out, &format!("{}.evaluations", space.name))?;
    let merge = spec.merge || spec.shard.is_none();
    if merge {
        crate::io::out_dir::prepare(&spec.out, &space.name)?;
    }
    let ctx = Context::new(&space, optimise::work_dir(&spec.out, &space.name));
    // A killed run's temporaries (a per-world file or a record cut short by the kill) go first.
    optimise::remove_stale_temporaries(&ctx.cache, &space.world_context).map_err(opt_err)?;
    let (k, count) = spec.shard.unwrap_or((0, 1));
    let all = optimise::restarts(&space);
    observer.started(&format!(
        "calsim optimise: {} ({} restarts over {} counts, {} designs each at most, {} search worlds, {}){}, {}",
        space.name,
        all.len(),
        space.counts().len(),
        space.search.evaluations,
        space.search.worlds,
        space.search.method.label(),
        if spec.shard.is_some() { format!(", shard {k} of {count}") } else { String::new() },
        threads_label(threads)
    ));
    let t0 = Instant::now();
    let mut evaluations = 0;
    let mut mine = 0;
    if !spec.merge {
        let rs: Vec<usize> = (0..all.len()).filter(|r| r % count == k).collect();
        let total = rs.len() * space.search.evaluations as usize;
        for (i, &r) in rs.iter().enumerate() {
            let base = i * space.search.evaluations as usize;
            let e = pool
                .install(|| optimise::run_restart(&ctx, r, &|done| observer.progress(base + done, total, "designs")))
                .map_err(opt_err)?;
            evaluations += e.len();
            mine += 1;
        }
        observer.stage_done();
    }
    let search_s = t0.elapsed().as_secs_f64();
    let mut report = OptimiseReport {
        name: space.name.clone(),
        restarts: mine,
        evaluations,
        search_s,
        finish_s: 0.0,
        dest: None,
        summary: None,
        cost: None,
    };
    if !merge {
        return Ok(report);
    }
    let t1 = Instant::now();
    let trace: Vec<optimise::Evaluated> = pool.install(|| optimise::read_restarts(&ctx)).map_err(opt_err)?;
    let verdict = pool
        .install(|| optimise::finish(&ctx, trace, compare, &|done, total, what| observer.progress(done, total, what)))
        .map_err(opt_err)?;
    observer.stage_done();
    report.finish_s = t1.elapsed().as_secs_f64();
    let outcome = results::Outcome::of(&space, verdict);
    // Where a world's time goes: the winner's realisation 0 run again, its timing line.
    let mut world: Option<Box<dyn crate::device::Outcome>> = None;
    if let Some((i, r)) = &outcome.winner {
        let c = &outcome.verdict.verified[*i];
        let table = results::design_table(c, r);
        let text = toml::to_string(&table).unwrap_or_default();
        if let Ok(s) = crate::device::from_table(&text, table, &spec.file)
            && let Ok(o) = pool.install(|| s.run(s.header().seed, &|_, _| {}))
        {
            report.cost = Some(o.timing());
            world = Some(o);
        }
    }
    let plots = spec.plots.then(|| plot_inputs(&space, &outcome));
    let overrides: Vec<(String, String)> =
        spec.method.iter().map(|m| ("search.method".to_string(), format!("\"{}\"", m.label()))).collect();
    let fields = serde_json::json!({
        "design_file": std::path::absolute(&spec.file).unwrap_or_else(|_| spec.file.clone()).display().to_string(),
        "identity": space.identity,
        "search_s": search_s,
        "finish_s": report.finish_s,
        "evaluations": outcome.verdict.trace.len(),
        "winner_timing": report.cost,
    });
    let options = crate::device::WriteOptions { threads, plots: spec.plots, recording: spec.plots, overrides: Vec::new() };
    let winner = match &world {
        Some(o) => Some(o.results(&[], &options).map_err(|e| Error::io(&spec.out)(std::io::Error::other(e)))?),
        None => None,
    };
    let results = results::results(&space, &outcome, plots, fields, &overrides, winner).map_err(Error::io(&spec.out))?;
    let written = crate::io::results::write(&spec.out, results).map_err(Error::io(&spec.out))?;
    let dest = written.dest;
    report.summary = Some(written.summary);
    report.dest = Some(dest);
    Ok(report)
}

/// The figures' inputs: convergence per restart, the held-out front, the winning cell.
fn plot_inputs(space: &DesignSpace, o: &results::Outcome) -> OptimisePlotInputs {
    let v = &o.verdict;
    let restarts = optimise::restarts(space);
    let convergence = (0..restarts.len())
        .map(|r| {
            let scores: Vec<f64> = v.trace.iter().filter(|e| e.asked.restart as usize == r).map(|e| e.score).collect();
            (format!("restart {r}: {} points", restarts[r].0), scores)
        })
        .collect();
    let ours = v.verified.iter().filter(|c| !c.compared).count();
    let mut front = Vec::new();
    for (p, c) in v.verified.iter().enumerate() {
        let best = v.held_out_rows.iter().filter(|r| r.design.point == p).min_by_key(|r| r.rank);
        if let Some(r) = best {
            front.push((c.label.clone(), r.campaign_h, [r.estimate, r.interval.0, r.interval.1], p < ours));
        }
    }
    let cell = o.sheet.clone();
    let o = &space.objective;
    let target = match o.goal {
        crate::design::sweep::objective::Goal::MaximiseSuccess => o.success_at_least,
        crate::design::sweep::objective::Goal::MinimiseError(_) => o.threshold_mm,
        _ => None,
    };
    OptimisePlotInputs {
        convergence,
        front,
        objective: o.describe(),
        score: results::score_words(space),
        cell,
        target,
        budget_h: o.campaign_h_at_most,
    }
}
