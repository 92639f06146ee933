//! `table8`: Table 8 of the TriCal paper, the same robot calibrated with the TriCal, a laser
//! tracker and an optical CMM, over realisations.

use std::path::PathBuf;
use std::time::Instant;

use super::{Error, Observer, thread_pool, threads_label};
use crate::device::trical::{self, TricalScenario};
use crate::study::stats::{finite_sorted, median, quantile};

/// What `table8` is asked.
#[derive(Clone, Debug)]
pub struct Table8Spec {
    /// A TriCal scenario file.
    pub scenario: PathBuf,
    /// Realisations (worlds).
    pub realisations: u32,
    /// Configurations of each external instrument's pool.
    pub pool: u32,
    /// Worker threads.
    pub threads: Option<u32>,
}

/// One row of Table 8: an instrument, the published median, std and max after calibration, and
/// calsim's (medians over the worlds), with the P10-P90 of the median over the worlds, mm.
#[derive(Clone, Debug)]
pub struct Table8Row {
    /// Instrument.
    pub instrument: &'static str,
    /// Published median, std, max.
    pub published: [f64; 3],
    /// calsim's median, std, max (each the median over worlds).
    pub calsim: [f64; 3],
    /// P10 and P90 over worlds of the median.
    pub median_p10_p90: [f64; 2],
}

/// What `table8` did.
#[derive(Clone, Debug)]
pub struct Table8Report {
    /// The rows: TriCal, laser tracker, optical CMM.
    pub rows: Vec<Table8Row>,
    /// Worlds calibrated.
    pub worlds: usize,
    /// Wall time, s.
    pub run_s: f64,
}

/// Most realisations of a Table 8.
pub const MOST_REALISATIONS: u32 = 10_000;
/// Configurations of an external instrument's pool.
pub const POOL: std::ops::RangeInclusive<u32> = 100..=100_000;

/// Median, std and max after calibration (medians over the repetitions at the table set size) of
/// the TriCal, the laser tracker and the optical CMM in one world.
fn world(s: &TricalScenario, seed: u64, pool_size: u32) -> Result<[[f64; 3]; 3], String> {
    let mut one = s.clone();
    one.study.set_sizes = vec![one.study.table_set_size];
    let o = trical::TricalOutcome::run(&one, seed, &|_, _| {}).map_err(|e| e.to_string())?;
    let f = o.figures();
    let [tracker, cmm] =
        trical::table8::external_instruments(&s.experiment, o.experiment(), &o.results().start, &s.study, seed, pool_size)?;
    Ok([[f.after_median, f.after_std, f.after_max], tracker, cmm])
}

/// Calibrates the robot of `spec.scenario` with the three instruments in each world.
pub fn run(spec: &Table8Spec, observer: &dyn Observer) -> Result<Table8Report, Error> {
    if !(1..=MOST_REALISATIONS).contains(&spec.realisations) {
        return Err(Error::input("--realisations", format!("{}: within [1, {MOST_REALISATIONS}]", spec.realisations)));
    }
    if !POOL.contains(&spec.pool) {
        return Err(Error::input("--pool", format!("{}: within [{}, {}]", spec.pool, POOL.start(), POOL.end())));
    }
    let t0 = Instant::now();
    let s = trical::spec::load(&spec.scenario)?;
    let (pool, threads) = thread_pool(spec.threads)?;
    observer.started(&format!(
        "calsim table8: {} (seed {}), {} realisations, {}",
        s.header.name,
        s.header.seed,
        spec.realisations,
        threads_label(threads)
    ));
    let mut worlds = Vec::new();
    for r in 0..spec.realisations {
        match pool.install(|| world(&s, crate::seeds::realisation_seed(s.header.seed, r), spec.pool)) {
            Ok(w) => worlds.push(w),
            Err(e) => observer.warning(&format!("realisation {r} left out: {e}")),
        }
        observer.progress(r as usize + 1, spec.realisations as usize, "realisations");
    }
    observer.stage_done();
    if worlds.is_empty() {
        return Err(Error::input(spec.scenario.display().to_string(), "no realisation could be calibrated"));
    }
    let p = &crate::study::published::published().trical_2018;
    let rows = ["TriCal", "laser tracker", "optical CMM"]
        .iter()
        .enumerate()
        .map(|(k, &instrument)| {
            let row = p.table8(instrument);
            let col = |m: usize| median(&worlds.iter().map(|w| w[k][m]).collect::<Vec<_>>());
            let meds = finite_sorted(&worlds.iter().map(|w| w[k][0]).collect::<Vec<_>>());
            Table8Row {
                instrument,
                published: [row.median_mm, row.std_mm, row.max_mm],
                calsim: [col(0), col(1), col(2)],
                median_p10_p90: [quantile(&meds, 0.1), quantile(&meds, 0.9)],
            }
        })
        .collect();
    Ok(Table8Report { rows, worlds: worlds.len(), run_s: t0.elapsed().as_secs_f64() })
}
