//! `sweep` and `merge`: a design sweep over realisations, whole or one shard of it, and the merge
//! of its shard directories into the results.

use std::path::{Path, PathBuf};
use std::time::Instant;

use super::{Error, Observer, thread_pool, threads_label};
use crate::design::sweep::{self, shard_dir};

/// What `sweep` is asked.
#[derive(Clone, Debug)]
pub struct SweepSpec {
    /// The sweep file.
    pub file: PathBuf,
    /// The directory of the shard directories and of the merged results.
    pub out: PathBuf,
    /// Only shard `k` of `K` (`None`: every unit, then merged).
    pub shard: Option<(usize, usize)>,
    /// Worker threads.
    pub threads: Option<u32>,
    /// Realisations replacing the file's count (or the most of an adaptive sweep).
    pub realisations: Option<u32>,
}

/// What a sweep (or one shard of it) did.
#[derive(Clone, Debug)]
pub struct SweepReport {
    /// The sweep's name.
    pub name: String,
    /// Units this run was responsible for, and its wall time, s.
    pub units: usize,
    /// See `units`.
    pub run_s: f64,
    /// The shard directory its units were written to (removed once merged).
    pub shard_dir: PathBuf,
    /// This shard and the number of shards.
    pub shard: (usize, usize),
    /// Where the sweep stands after this run: complete, or the stage whose units other shards
    /// still owe (adaptive sweeps run stage by stage).
    pub plan: sweep::race::Plan,
    /// Whether its realisations are adaptive (a race run stage by stage).
    pub adaptive: bool,
    /// The merge, when the sweep ran whole.
    pub merged: Option<MergeReport>,
}

/// What a merge did.
#[derive(Clone, Debug)]
pub struct MergeReport {
    /// The merged results.
    pub dest: PathBuf,
    /// Work units merged, and of them failed (their campaign could not run in that world).
    pub units: usize,
    /// See `units`.
    pub failed: usize,
    /// The summary table (`summary.md`'s text).
    pub summary: String,
}

/// Most shards of a sweep.
pub const MOST_SHARDS: usize = 100_000;
/// Most realisations a sweep takes (the most of an adaptive one).
pub const MOST_REALISATIONS: u32 = 10_000;

/// Runs the sweep of `spec.file` (or one shard of it), then, unsharded, merges it.
pub fn run(spec: &SweepSpec, observer: &dyn Observer) -> Result<SweepReport, Error> {
    let _inputs = crate::io::inputs::Ledger::open();
    let t0 = Instant::now();
    // The sweep's name is its file's stem: one path component, checked before anything runs.
    crate::io::names::of_file(&spec.file)?;
    if let Some((k, n)) = spec.shard
        && (n == 0 || n > MOST_SHARDS || k >= n)
    {
        return Err(Error::input("--shard", format!("{k}/{n}: k/K with 1 <= K <= {MOST_SHARDS} and 0 <= k < K")));
    }
    if let Some(r) = spec.realisations
        && !(1..=MOST_REALISATIONS).contains(&r)
    {
        return Err(Error::input("--realisations", format!("{r}: within [1, {MOST_REALISATIONS}]")));
    }
    let sweep = sweep::spec::load_with(&spec.file, spec.realisations)?;
    let (k, count) = spec.shard.unwrap_or((0, 1));
    crate::io::out_dir::prepare_work(
        &spec.out,
        &shard_dir(Path::new(""), &sweep.name, k, count).display().to_string(),
        sweep::SHARD_MARKER,
    )?;
    if spec.shard.is_none() {
        crate::io::out_dir::prepare(&spec.out, &sweep.name)?;
    }
    let (pool, threads) = thread_pool(spec.threads)?;
    let units = sweep.points.len() * sweep.realisations as usize;
    observer.started(&format!(
        "calsim sweep: {} ({} grid points x {} realisations = {units} work units{}), {}",
        sweep.name,
        sweep.points.len(),
        sweep.realisations,
        if count > 1 { format!(", shard {k} of {count}") } else { String::new() },
        threads_label(threads)
    ));
    let run = pool
        .install(|| sweep::run_shard(&sweep, &spec.out, k, count, &|done, total| observer.progress(done, total, "work units")))
        .map_err(Error::io(&spec.out))?;
    observer.stage_done();
    let dir = run.dir.clone();
    let mut report = SweepReport {
        name: sweep.name.clone(),
        units: run.ran,
        run_s: t0.elapsed().as_secs_f64(),
        shard_dir: dir.clone(),
        shard: (k, count),
        plan: run.plan,
        adaptive: sweep.race.is_some(),
        merged: None,
    };
    if spec.shard.is_none() {
        report.merged = Some(merge(std::slice::from_ref(&dir), &spec.out)?);
        std::fs::remove_dir_all(&dir).map_err(Error::io(&dir))?;
    }
    Ok(report)
}

/// Merges the shard directories of one sweep into `out/<sweep>`; every unit failing is an error
/// naming the sweep (its results are written first, with the reasons).
pub fn merge(shards: &[PathBuf], out: &Path) -> Result<MergeReport, Error> {
    let _inputs = crate::io::inputs::Ledger::open();
    let (info, units) = sweep::read_shards(shards)?;
    let plan = sweep::complete(&info, &units)?;
    crate::io::out_dir::prepare(out, &info.name)?;
    let merged = sweep::results::Merged::of(info, units, plan);
    let (dest, summary) = sweep::results::write(out, &merged).map_err(Error::io(out))?;
    let (info, units) = (&merged.info, &merged.units);
    let failed = units.iter().filter(|u| u.error.is_some()).count();
    if failed == units.len() {
        return Err(Error::input(info.name.clone(), format!("every work unit failed (see {}/summary.md)", dest.display())));
    }
    Ok(MergeReport { dest, units: units.len(), failed, summary })
}
