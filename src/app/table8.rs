//! `table8`: Table 8 of the TriCal paper, the same robot calibrated with the TriCal, a laser
//! tracker and an optical CMM, over realisations.

use std::path::PathBuf;
use std::time::Instant;

use polars::prelude::Column;

use super::{Error, Observer, thread_pool, threads_label};
use crate::device::trical::{self, TricalScenario};
use crate::io::table::Frame;
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
    /// The table ([`frame`]): a row per instrument, TriCal, laser tracker, optical CMM. The CLI
    /// prints it ([`terminal`]) and Python receives it as it is.
    pub table: Frame,
    /// Worlds calibrated.
    pub worlds: usize,
    /// Wall time, s.
    pub run_s: f64,
}

/// The name of the table.
pub const TABLE: &str = "table8";

/// The table of `rows`: `instrument`, then `published_<figure>_mm` beside `calsim_<figure>_mm`
/// for the median, std and max after calibration, and `median_p10_mm`, `median_p90_mm`.
pub fn frame(rows: &[Table8Row]) -> std::io::Result<Frame> {
    let number = |name: &str, v: &dyn Fn(&Table8Row) -> f64| Column::new(name.into(), rows.iter().map(v).collect::<Vec<f64>>());
    let mut columns = vec![Column::new("instrument".into(), rows.iter().map(|r| r.instrument).collect::<Vec<&str>>())];
    for (k, figure) in ["median", "std", "max"].into_iter().enumerate() {
        columns.push(number(&format!("published_{figure}_mm"), &|r| r.published[k]));
        columns.push(number(&format!("calsim_{figure}_mm"), &|r| r.calsim[k]));
    }
    columns.push(number("median_p10_mm", &|r| r.median_p10_p90[0]));
    columns.push(number("median_p90_mm", &|r| r.median_p10_p90[1]));
    crate::io::table::frame(TABLE, columns)
}

/// The table as `calsim table8` prints it (a header line, then a line per instrument), read from
/// its frame; `worlds`: the worlds its medians are over.
pub fn terminal(table: &Frame, worlds: usize) -> std::io::Result<String> {
    let calsim = if worlds == 1 {
        "calsim median / std / max (one world; --realisations N for the P10-P90 over worlds)".to_string()
    } else {
        format!("calsim median / std / max (median of {worlds} worlds; P10-P90 of the median)")
    };
    let tables = [(TABLE.to_string(), table.clone())];
    crate::io::results::read_row(&tables, TABLE, |r| {
        let mut s = format!("{:<16} {:>26} {calsim:>44}\n", "instrument", "published median / std / max");
        for k in 0..r.height() {
            let r = r.at(k);
            let f = |name: &str| r.f64(name);
            s += &format!(
                "{:<16} {:>10.3} / {:.3} / {:.3} {:>14.3} / {:.3} / {:.3}  ({:.3}-{:.3})\n",
                r.str("instrument"),
                f("published_median_mm"),
                f("published_std_mm"),
                f("published_max_mm"),
                f("calsim_median_mm"),
                f("calsim_std_mm"),
                f("calsim_max_mm"),
                f("median_p10_mm"),
                f("median_p90_mm")
            );
        }
        s
    })
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
        .collect::<Vec<_>>();
    let table = frame(&rows).map_err(|e| Error::input(TABLE, e.to_string()))?;
    Ok(Table8Report { table, worlds: worlds.len(), run_s: t0.elapsed().as_secs_f64() })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The printed table is read from the frame, each figure from its column: the published
    /// figures on the left, calsim's on the right with the P10-P90 of the median.
    #[test]
    fn the_printed_table_reads_each_figure_from_its_column() {
        let rows = [
            Table8Row { instrument: "TriCal", published: [0.1, 0.2, 0.3], calsim: [0.4, 0.5, 0.6], median_p10_p90: [0.35, 0.45] },
            Table8Row { instrument: "optical CMM", published: [1.0, 2.0, 3.0], calsim: [4.0, 5.0, 6.0], median_p10_p90: [3.5, 4.5] },
        ];
        let table = frame(&rows).unwrap();
        assert_eq!(
            table.get_column_names().iter().map(|n| n.as_str()).collect::<Vec<_>>(),
            [
                "instrument",
                "published_median_mm",
                "calsim_median_mm",
                "published_std_mm",
                "calsim_std_mm",
                "published_max_mm",
                "calsim_max_mm",
                "median_p10_mm",
                "median_p90_mm"
            ]
        );
        let text = terminal(&table, 20).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 3, "{text}");
        assert!(lines[0].ends_with("calsim median / std / max (median of 20 worlds; P10-P90 of the median)"), "{text}");
        assert_eq!(lines[1], "TriCal                0.100 / 0.200 / 0.300          0.400 / 0.500 / 0.600  (0.350-0.450)");
        assert_eq!(lines[2], "optical CMM           1.000 / 2.000 / 3.000          4.000 / 5.000 / 6.000  (3.500-4.500)");
        assert!(
            terminal(&table, 1).unwrap().lines().next().unwrap().ends_with("(one world; --realisations N for the P10-P90 over worlds)")
        );
    }
}
