//! Result files of a budget in `out/<scenario>.budget/`: `budget.parquet` (one row per
//! configuration: its source, mode and factor, the after-calibration median and p95 over
//! realisations), `summary.md` (the budget sorted by share, as a GUM budget table, then every
//! configuration) and a tornado plot, with `manifest.json` (the table's sha256).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use polars::prelude::*;

use super::{Config, Line, Source};
use crate::design::sweep::PointRow;
use crate::io::results::{Cell, Head, Results, Row, Summary};
use crate::study::interval::Paired;
use crate::study::prediction::Prediction;

/// Everything a budget's files show.
pub struct BudgetReport<'a> {
    /// The budget's name (`<scenario>.budget`).
    pub name: &'a str,
    /// Realisations per configuration.
    pub realisations: u32,
    /// The sources.
    pub sources: &'a [Source],
    /// The configurations, in point order.
    pub configs: &'a [Config],
    /// Per configuration, its row at the table set size (`None`: it could not run).
    pub rows: Vec<Option<&'a PointRow>>,
    /// p95 with every source on and off, mm, and the lines sorted by share.
    pub all_mm: f64,
    /// See `all_mm`.
    pub none_mm: f64,
    /// See `all_mm`.
    pub lines: &'a [Line],
    /// Per configuration, the linear prediction beside the Monte Carlo (TriCal; `None` where there
    /// is none).
    pub predictions: &'a [Option<Prediction>],
    /// The sources' shares over worlds with their intervals, largest first.
    pub shares: &'a [super::Share],
    /// Per configuration, its p95 against every source on, paired per world.
    pub against: &'a [Option<Paired>],
    /// What the worlds cannot tell.
    pub warnings: &'a [String],
    /// The command-line changes to the scenario (`key`, TOML value), as the manifest records them.
    pub overrides: &'a [(String, String)],
}

/// Writes the budget into `out/<name>`, replacing what was there; the directory and the summary
/// as written.
pub fn write(out: &Path, b: &BudgetReport<'_>) -> std::io::Result<(PathBuf, String)> {
    crate::io::results::write(out, results(b)?).map(|w| (w.dest, w.summary))
}

/// The budget's results: its tables, the tornado and prediction figures, the summary.
pub fn results<'a>(b: &'a BudgetReport<'a>) -> std::io::Result<Results<'a>> {
    let mut r = Results::new(b.name, Head::Run(crate::io::manifest::Provenance::of_run(b.overrides)));
    tables(b, &mut r)?;
    r.field("budget", b.name)?.field("realisations", b.realisations)?.field("configurations", b.configs.len())?;
    r.draw(Box::new(move |dir| {
        let mut drawn = super::plots::write_tornado(dir, &tornado(b), b.all_mm)?;
        let spreads = |mode: &str| {
            b.configs.iter().zip(b.predictions).find(|(c, _)| c.mode == mode).and_then(|(_, p)| p.as_ref()).map(|p| p.parameter_spreads())
        };
        if let Some(all) = spreads("all") {
            let none = spreads("none").unwrap_or_default();
            drawn.extend(super::plots::write_prediction(dir, &all, &none)?);
        }
        Ok(drawn)
    }));
    summary(b, &mut r.summary);
    r.summary.figures("");
    Ok(r)
}

/// `budget.parquet`, `shares.parquet` and (where a configuration has a prediction)
/// `prediction.parquet`. Long by design: the tables' columns listed one after the other.
fn tables(b: &BudgetReport<'_>, r: &mut Results<'_>) -> std::io::Result<()> {
    let q = |i: usize, m: usize, k: usize| b.rows[i].map_or(f64::NAN, |r| r.after[m][k]);
    let n = b.configs.len();
    let f = |name: &str, v: Vec<f64>| Column::new(name.into(), v);
    r.table(
        "budget.parquet",
        vec![
            Column::new("configuration".into(), b.configs.iter().map(|c| c.label.clone()).collect::<Vec<_>>()),
            Column::new(
                "source".into(),
                b.configs.iter().map(|c| c.source.map_or(String::new(), |s| b.sources[s].label.to_string())).collect::<Vec<_>>(),
            ),
            Column::new("mode".into(), b.configs.iter().map(|c| c.mode.to_string()).collect::<Vec<_>>()),
            f("factor", b.configs.iter().map(|c| c.factor).collect()),
            Column::new("realisations".into(), (0..n).map(|i| b.rows[i].map_or(0, |r| r.realisations)).collect::<Vec<_>>()),
            f("after_median_mm_median", (0..n).map(|i| q(i, 0, 0)).collect()),
            f("after_median_mm_p10", (0..n).map(|i| q(i, 0, 1)).collect()),
            f("after_median_mm_p90", (0..n).map(|i| q(i, 0, 2)).collect()),
            f("after_p95_mm_median", (0..n).map(|i| q(i, 1, 0)).collect()),
            f("after_p95_mm_p10", (0..n).map(|i| q(i, 1, 1)).collect()),
            f("after_p95_mm_p90", (0..n).map(|i| q(i, 1, 2)).collect()),
            // Against every source on, paired per world: median difference of the p95 with its
            // interval at the budget's confidence, the sign test's p-value (NaN for all on itself).
            f("vs_all_on_p95_mm", b.against.iter().map(|p| p.map_or(f64::NAN, |p| p.median)).collect()),
            f("vs_all_on_p95_mm_lo", b.against.iter().map(|p| p.map_or(f64::NAN, |p| p.interval.0)).collect()),
            f("vs_all_on_p95_mm_hi", b.against.iter().map(|p| p.map_or(f64::NAN, |p| p.interval.1)).collect()),
            f("vs_all_on_p_value", b.against.iter().map(|p| p.map_or(f64::NAN, |p| p.test.p_value)).collect()),
        ],
    )?;
    r.table(
        "shares.parquet",
        vec![
            Column::new("source".into(), b.shares.iter().map(|x| b.sources[x.source].label.to_string()).collect::<Vec<_>>()),
            f("share", b.shares.iter().map(|x| x.share).collect()),
            f("share_lo", b.shares.iter().map(|x| x.interval.0).collect()),
            f("share_hi", b.shares.iter().map(|x| x.interval.1).collect()),
            f("effect_p95_mm", b.shares.iter().map(|x| x.effect.median).collect()),
            f("effect_p95_mm_lo", b.shares.iter().map(|x| x.effect.interval.0).collect()),
            f("effect_p95_mm_hi", b.shares.iter().map(|x| x.effect.interval.1).collect()),
            Column::new("effect_resolved".into(), b.shares.iter().map(|x| x.resolved).collect::<Vec<_>>()),
            Column::new("ranked_above_next".into(), b.shares.iter().map(|x| x.above_next.map(|(_, r)| r)).collect::<Vec<Option<bool>>>()),
            f("pairing_correlation", b.shares.iter().map(|x| x.effect.correlation).collect()),
        ],
    )?;
    r.table("lines.parquet", line_columns(b))?;
    prediction_table(b, r)
}

/// `prediction.parquet`, where a configuration has a prediction.
fn prediction_table(b: &BudgetReport<'_>, r: &mut Results<'_>) -> std::io::Result<()> {
    let f = |name: &str, v: Vec<f64>| Column::new(name.into(), v);
    let compared = compared(b);
    if !compared.is_empty() {
        r.table(PREDICTION_SUMMARY, prediction_summary_columns(b, &compared))?;
    }
    if let Some(rows) = prediction_rows(b) {
        r.table(
            "prediction.parquet",
            vec![
                Column::new("configuration".into(), rows.iter().map(|r| r.0.clone()).collect::<Vec<_>>()),
                Column::new("parameter".into(), rows.iter().map(|r| r.1.clone()).collect::<Vec<_>>()),
                f("predicted_std", rows.iter().map(|r| r.2).collect()),
                f("simulated_rms", rows.iter().map(|r| r.3).collect()),
                f("ratio", rows.iter().map(|r| r.3 / r.2).collect()),
                Column::new("identifications".into(), rows.iter().map(|r| r.4).collect::<Vec<_>>()),
            ],
        )?;
    }
    Ok(())
}

/// The tornado's lines in the order of the shares table, every bar and dot a change from every
/// source on read per world: at the all-on p95 plus the median of the paired differences, with
/// their interval (the medians over worlds of two configurations' p95 differ by more than the
/// paired change where the worlds spread).
fn tornado(b: &BudgetReport<'_>) -> Vec<super::plots::TornadoLine> {
    let order: Vec<usize> = b.shares.iter().map(|s| s.source).chain(b.lines.iter().map(|l| l.source)).collect();
    let mut lines: Vec<&super::Line> = b.lines.iter().collect();
    lines.sort_by_key(|l| order.iter().position(|&s| s == l.source).unwrap_or(usize::MAX));
    lines
        .iter()
        .map(|l| {
            let change = |mode: &str, factor: Option<f64>, fallback: f64| {
                let paired = b
                    .configs
                    .iter()
                    .position(|c| c.mode == mode && c.source == Some(l.source) && factor.is_none_or(|f| c.factor == f))
                    .and_then(|i| b.against[i])
                    .filter(|p| p.median.is_finite());
                match paired {
                    Some(p) => (b.all_mm + p.median, Some((b.all_mm + p.interval.0, b.all_mm + p.interval.1))),
                    None => (fallback, None),
                }
            };
            let (off_mm, off_interval_mm) = change("off", None, l.off_mm);
            let scaled: Vec<((f64, f64), Option<(f64, f64)>)> = l
                .scaled_mm
                .iter()
                .map(|&(f, v)| {
                    let (m, ci) = change("scaled", Some(f), v);
                    ((f, m), ci)
                })
                .collect();
            super::plots::TornadoLine {
                source: b.sources[l.source].label.to_string(),
                off_mm,
                off_interval_mm,
                scaled_mm: scaled.iter().map(|x| x.0).collect(),
                scaled_interval_mm: scaled.iter().map(|x| x.1).collect(),
            }
        })
        .collect()
}

fn f3(x: f64) -> String {
    if x.is_finite() { format!("{x:.3}") } else { "-".into() }
}

/// A row of `prediction.parquet`.
type PredictionRow = (String, String, f64, f64, u32);

/// Per configuration and parameter: configuration, parameter, predicted std, simulated RMS error
/// (internal units), identifications. `None` when no configuration has a prediction.
fn prediction_rows(b: &BudgetReport<'_>) -> Option<Vec<PredictionRow>> {
    let rows: Vec<_> = b
        .configs
        .iter()
        .zip(b.predictions)
        .filter_map(|(c, p)| p.as_ref().map(|p| (c, p)))
        .flat_map(|(c, p)| {
            p.names.iter().zip(p.parameter_spreads()).map(move |(name, (pr, sim))| (c.label.clone(), name.clone(), pr, sim, p.tasks))
        })
        .collect();
    (!rows.is_empty()).then_some(rows)
}

/// Where a source alone's simulated parameter errors over the predicted std (median over
/// parameters) exceed the floor's ratio ([`floor_ratio`]) by more than this factor (20 %, the
/// agreement a white-noise source reaches), the prediction misses the source.
const MISSED_RATIO: f64 = 1.2;

/// The ratio a source alone is judged against: the floor's (every source off: the solver's own
/// error, present in every configuration), or 1 (white noise) where the floor's is below 1 or
/// not predicted.
fn floor_ratio(rows: &[(&Config, &Prediction)]) -> f64 {
    rows.iter().find(|(c, _)| c.mode == "none").map(|(_, p)| p.median_ratio()).filter(|r| r.is_finite()).map_or(1.0, |r| r.max(1.0))
}

/// The configurations the linear prediction is compared in (every source on, none, and each source
/// alone), with their prediction, in the configurations' order.
fn compared<'a>(b: &BudgetReport<'a>) -> Vec<(&'a Config, &'a Prediction)> {
    b.configs
        .iter()
        .zip(b.predictions)
        .filter(|(c, _)| c.mode != "off" && c.mode != "scaled")
        .filter_map(|(c, p)| p.as_ref().map(|p| (c, p)))
        .collect()
}

/// Why the linear prediction misses a source acting alone (empty where it holds), its parameter
/// ratio judged against `floor` ([`floor_ratio`]).
fn missed_because(p: &Prediction, floor: f64) -> String {
    let (ratio, e) = (p.median_ratio(), p.errors_mm());
    let mut why = Vec::new();
    let biased = ratio > MISSED_RATIO * floor;
    if biased {
        why.push(format!(
            "its parameter errors are {ratio:.2} times the predicted std, more than {MISSED_RATIO} times {floor:.2} (the floor's ratio, \
             at least 1): a bias the parameters absorb"
        ));
    }
    if e[3] > VALIDATION_MISSED * e[1] && e[3] - e[1] > 0.01 {
        why.push(format!(
            "the simulated validation p95 is {:.3} mm against {:.3} mm predicted{}",
            e[3],
            e[1],
            if biased { "" } else { ": error at the validation poses themselves, which no parameter carries" }
        ));
    }
    why.join("; ")
}

/// The table of the prediction section.
const PREDICTION_SUMMARY: &str = "prediction_summary.parquet";

/// `prediction_summary.parquet`: per configuration [`compared`], its source (empty for every
/// source on or none), the identifications, the fit's noise estimate, the simulated parameter
/// errors over the predicted std (median over parameters), the predicted and simulated median and
/// p95 of the validation errors (medians over identifications), whether the validation errors
/// are predicted at all, and for a source alone why the linear prediction misses it.
fn prediction_summary_columns(b: &BudgetReport<'_>, rows: &[(&Config, &Prediction)]) -> Vec<Column> {
    let floor = floor_ratio(rows);
    let f = |name: &str, k: usize| Column::new(name.into(), rows.iter().map(|(_, p)| p.errors_mm()[k]).collect::<Vec<f64>>());
    let text = |name: &str, v: &dyn Fn(&Config, &Prediction) -> String| {
        Column::new(name.into(), rows.iter().map(|(c, p)| v(c, p)).collect::<Vec<String>>())
    };
    vec![
        text("configuration", &|c, _| c.label.clone()),
        text("mode", &|c, _| c.mode.to_string()),
        text("source", &|c, _| c.source.map_or(String::new(), |k| b.sources[k].label.to_string())),
        Column::new("identifications".into(), rows.iter().map(|(_, p)| p.tasks).collect::<Vec<u32>>()),
        f("sigma_mm", 4),
        Column::new("parameter_ratio".into(), rows.iter().map(|(_, p)| p.median_ratio()).collect::<Vec<f64>>()),
        f("predicted_median_mm", 0),
        f("predicted_p95_mm", 1),
        f("simulated_median_mm", 2),
        f("simulated_p95_mm", 3),
        Column::new("validation_predicted".into(), rows.iter().map(|(_, p)| !p.predicted_mm.is_empty()).collect::<Vec<bool>>()),
        text("missed_because", &|c, p| if c.mode == "alone" && c.source.is_some() { missed_because(p, floor) } else { String::new() }),
    ]
}

/// The section on the linear prediction against the Monte Carlo, read from
/// `prediction_summary.parquet` (nothing where no configuration has a prediction).
fn prediction_section<'a>(b: &BudgetReport<'a>, parts: &mut Summary<'a>) {
    if compared(b).is_empty() {
        return;
    }
    parts.text(format!(
        "\n## Predicted (linear, from one fit) versus Monte Carlo\n\n\
         What a calibration tool reports from one run: the parameter covariance sigma^2 (J^T J)^-1, with sigma the fit's own \
         noise estimate (SSR / (3n - m) per coordinate) and J the identification Jacobian of the chosen set; the predicted \
         validation errors |J_v d| with d drawn from it. Beside it what the simulated worlds gave: the RMS error of each \
         identified parameter against the truth and the validation errors, over every identification at the table set size and \
         every realisation. Ratio: simulated RMS over predicted std, median over the parameters (per-parameter values in \
         `prediction.parquet`, internal units mm, rad, rad/(N m)). A ratio near 1 means the source acts as white noise and one run's covariance is right. \
         Every configuration keeps the floor (the row all off: the solver's own error), so a source alone is judged against the \
         floor's ratio, {floor:.2} here (1 where the floor's is below 1): above {MISSED_RATIO} times it the linear prediction \
         misses the source: it is a bias (the same in every configuration of a set) that the parameters absorb while the \
         residuals stay small; a source that leaves the parameters alone keeps the floor's ratio.\n\n",
        floor = floor_ratio(&compared(b))
    ));
    parts.text_from(PREDICTION_SUMMARY, |r| {
        if (0..r.height()).any(|i| r.at(i).bool("validation_predicted")) {
            return String::new();
        }
        "Here the figure of merit (ISO 9283 AP over P1-P5, after the controller's inverse kinematics, in the base frame) is not \
         predicted: the comparison covers the parameters; the simulated columns give the AP's median and p95.\n\n"
            .to_string()
    });
    let pair = |a: &'static str, b: &'static str| move |r: &Row<'_>| format!("{} / {}", f3(r.f64(a)), f3(r.f64(b)));
    parts.table(
        PREDICTION_SUMMARY,
        Summary::all_rows(),
        vec![
            crate::io::results::cell("configuration", |r| r.str("configuration")),
            crate::io::results::cell("identifications", |r| r.u64("identifications").to_string()),
            crate::io::results::cell("sigma (fit), um", |r| format!("{:.2}", r.f64("sigma_mm") * 1e3)),
            crate::io::results::cell("ratio, parameters", |r| format!("{:.2}", r.f64("parameter_ratio"))),
            crate::io::results::cell("predicted median / p95, mm", pair("predicted_median_mm", "predicted_p95_mm")),
            crate::io::results::cell("simulated median / p95, mm", pair("simulated_median_mm", "simulated_p95_mm")),
        ],
    );
    parts.text_from(PREDICTION_SUMMARY, prediction_verdict);
}

/// Which sources the linear prediction misses and for which it holds, from
/// `prediction_summary.parquet`.
fn prediction_verdict(r: &Row<'_>) -> String {
    let rows: Vec<Row<'_>> = (0..r.height()).map(|i| r.at(i)).collect();
    let alone: Vec<&Row<'_>> = rows.iter().filter(|x| x.str("mode") == "alone" && !x.str("source").is_empty()).collect();
    let mut s = String::new();
    let missed: Vec<String> = alone
        .iter()
        .filter(|x| !x.str("missed_because").is_empty())
        .map(|x| format!("**{}**: {}", x.str("source"), x.str("missed_because")))
        .collect();
    if !missed.is_empty() {
        s.push_str("The linear prediction misses:\n\n");
        for m in &missed {
            let _ = writeln!(s, "- {m}");
        }
        s.push('\n');
    }
    let held: Vec<String> = alone
        .iter()
        .filter(|x| x.str("missed_because").is_empty())
        .map(|x| format!("{} ({:.2})", x.str("source"), x.f64("parameter_ratio")))
        .collect();
    let _ = writeln!(
        s,
        "It holds (parameter ratio in brackets, within {MISSED_RATIO} times the floor's; validation p95 as predicted) for: {}.{}",
        if held.is_empty() { "none of the sources".to_string() } else { held.join(", ") },
        rows.iter().find(|x| x.str("mode") == "all").map_or(String::new(), |x| format!(
            " With every source on, the simulated parameter errors are {:.1} times the predicted std (median over parameters).",
            x.f64("parameter_ratio")
        ))
    );
    s
}

/// Where the simulated validation p95 exceeds the predicted one by more than this factor (and by
/// more than 0.01 mm), the prediction misses error that is not in the parameters.
const VALIDATION_MISSED: f64 = 1.25;

/// The budget table, sorted by share, and every configuration: the shares' and configurations'
/// figures read from `shares.parquet` and `budget.parquet`.
pub fn summary<'a>(b: &'a BudgetReport<'a>, parts: &mut Summary<'a>) {
    let mut s = String::new();
    let _ = writeln!(s, "# {}: uncertainty budget over {} realisations\n", b.name, b.realisations);
    let _ = writeln!(
        s,
        "p95 of the validation error after calibration at the table set size, median over realisations: {} mm with every \
         source, {} mm with none (the solver's floor).\n",
        f3(b.all_mm),
        f3(b.none_mm)
    );
    let conf = 100.0 * super::CONFIDENCE;
    let _ = writeln!(
        s,
        "Every figure of this table is read per world (the unit of independence: every configuration runs in the same worlds). \
         Share: the mean over worlds of the square a source adds alone to the floor's p95, over the mean of the sum of those \
         squares, with its {conf:.0} % bootstrap-t interval; effect: the p95 alone minus the floor's, median of the per-world \
         differences with its {conf:.0} % interval; resolved: the sign test over worlds tells the effect from none; ranked: tells \
         this source's added square from the next one's; at xF: the change of the p95 from every source on when the source is \
         scaled by F, median of the per-world differences with its {conf:.0} % interval (`noise`: not told from none).\n"
    );
    for w in b.warnings {
        let _ = writeln!(s, "**Warning:** {w}.\n");
    }
    parts.text(s);
    shares_table(b, parts);
    detail(b, parts);
    prediction_section(b, parts);
    parts.text("\n## Every configuration\n\n");
    parts.table(
        "budget.parquet",
        Summary::all_rows(),
        vec![
            cell("configuration", |r| r.str("configuration")),
            cell("realisations", |r| r.u64("realisations").to_string()),
            cell("after median, mm (P10-P90)", |r| after(r, "median")),
            cell("after p95, mm (P10-P90)", |r| if r.u64("realisations") == 0 { "-".to_string() } else { after(r, "p95") }),
        ],
    );
}

/// A configuration's error after calibration with its P10-P90 from its row of `budget.parquet`
/// (`could not run` where no realisation ran).
fn after(r: &Row<'_>, stat: &str) -> String {
    if r.u64("realisations") == 0 {
        return "could not run".to_string();
    }
    let c = |q: &str| f3(r.f64(&format!("after_{stat}_mm_{q}")));
    format!("{} ({}-{})", c("median"), c("p10"), c("p90"))
}

/// A cell of a summary table.
fn cell<'a>(header: impl Into<String>, show: impl Fn(&Row<'_>) -> String + 'a) -> Cell<'a> {
    (header.into(), Box::new(show))
}

/// The paired change from every source on of a configuration's row of `budget.parquet`:
/// `+0.012 (+0.004 to +0.020)`, `, noise` when the worlds do not tell it from none.
fn change(r: &Row<'_>) -> String {
    let (m, lo, hi, p) =
        (r.f64("vs_all_on_p95_mm"), r.f64("vs_all_on_p95_mm_lo"), r.f64("vs_all_on_p95_mm_hi"), r.f64("vs_all_on_p_value"));
    if p.is_nan() && m.is_nan() {
        return "-".to_string();
    }
    format!("{m:+.3} ({lo:+.3} to {hi:+.3}){}", if p < 1.0 - super::CONFIDENCE { "" } else { ", noise" })
}

/// The budget table from `shares.parquet`, sorted by share, with the scaled sources' changes from
/// `budget.parquet`.
fn shares_table<'a>(b: &'a BudgetReport<'a>, parts: &mut Summary<'a>) {
    let conf = 100.0 * super::CONFIDENCE;
    let factors: Vec<f64> = b.lines.first().map(|l| l.scaled_mm.iter().map(|x| x.0).collect()).unwrap_or_default();
    // The shares' rows whose source has a line, in the table's (share) order.
    let rows: Vec<usize> = (0..b.shares.len()).filter(|&i| b.lines.iter().any(|l| l.source == b.shares[i].source)).collect();
    let source = move |r: &Row<'_>| &b.sources[b.shares[r.index()].source];
    let mut cells = vec![
        cell("source", |r| r.str("source")),
        cell("value", move |r| value(source(r))),
        cell(format!("share ({conf:.0} % interval)"), |r| {
            format!("{:.2} ({:.2}-{:.2})", r.f64("share"), r.f64("share_lo"), r.f64("share_hi"))
        }),
        cell("effect alone, mm", |r| {
            format!("{} ({}-{})", f3(r.f64("effect_p95_mm")), f3(r.f64("effect_p95_mm_lo")), f3(r.f64("effect_p95_mm_hi")))
        }),
        cell("resolved", |r| if r.bool("effect_resolved") { "yes" } else { "no: within the noise" }.to_string()),
        cell("ranked above next", |r| r.opt_bool("ranked_above_next").map_or("-", |x| if x { "yes" } else { "no" }).to_string()),
    ];
    for f in factors {
        cells.push(cell(format!("at x{f}, mm"), move |r| {
            let k = b.shares[r.index()].source;
            b.configs
                .iter()
                .position(|c| c.mode == "scaled" && c.source == Some(k) && c.factor == f)
                .map_or("-".to_string(), |i| change(&r.of("budget.parquet", i)))
        }));
    }
    parts.table("shares.parquet", Box::new(move |_| rows.clone()), cells);
}

/// A source's terms, each with its own unit read from its key (`_um_per_m` is um/m), the source's
/// otherwise.
fn value(src: &Source) -> String {
    const UNITS: [(&str, &str); 7] =
        [("_um_per_m", "um/m"), ("_um", "um"), ("_mm", "mm"), ("_deg", "deg"), ("_pct_fs", "% FS"), ("_c", "C"), ("_kg", "kg")];
    let unit = |key: &str| UNITS.iter().find(|(suffix, _)| key.ends_with(suffix)).map_or(src.unit, |u| u.1);
    src.keys.iter().zip(&src.values).map(|(k, v)| format!("{v} {}", unit(k))).collect::<Vec<_>>().join(", ")
}

/// `lines.parquet`: per source with a line, in the shares' order: the medians of its separate
/// configurations (alone, off, at each factor), the share from removing it, and whether the paired
/// change says the medians' difference is noise (`medians_only`) or the sources interact.
fn line_columns(b: &BudgetReport<'_>) -> Vec<Column> {
    let lines: Vec<(&super::Share, &Line)> =
        b.shares.iter().filter_map(|sh| b.lines.iter().find(|l| l.source == sh.source).map(|l| (sh, l))).collect();
    let f = |name: &str, v: Vec<f64>| Column::new(name.into(), v);
    let mut cols = vec![
        Column::new("source".into(), lines.iter().map(|(_, l)| b.sources[l.source].label.to_string()).collect::<Vec<_>>()),
        f("share_removed", lines.iter().map(|(_, l)| l.share_removed).collect()),
        f("p95_alone_mm", lines.iter().map(|(_, l)| l.alone_mm).collect()),
        f("p95_off_mm", lines.iter().map(|(_, l)| l.off_mm).collect()),
    ];
    let factors: Vec<f64> = b.lines.first().map(|l| l.scaled_mm.iter().map(|x| x.0).collect()).unwrap_or_default();
    for (k, factor) in factors.iter().enumerate() {
        cols.push(f(&format!("p95_at_x{factor}_mm"), lines.iter().map(|(_, l)| l.scaled_mm.get(k).map_or(f64::NAN, |x| x.1)).collect()));
    }
    let medians_only = |l: &Line| {
        let off = b.configs.iter().position(|c| c.mode == "off" && c.source == Some(l.source)).and_then(|i| b.against[i]);
        // The medians' difference a reader would take for the saving, beside the paired change.
        off.is_some_and(|p| !p.separated(super::CONFIDENCE)) && (b.all_mm - l.off_mm).abs() > 0.02
    };
    cols.push(Column::new("medians_only".into(), lines.iter().map(|(_, l)| medians_only(l)).collect::<Vec<_>>()));
    cols.push(Column::new("interacts".into(), lines.iter().map(|(sh, l)| (sh.share - l.share_removed).abs() > 0.15).collect::<Vec<_>>()));
    cols
}

/// The detail from `lines.parquet`: medians of separate configurations, each on its own, with the
/// paired change of its `off` configuration from `budget.parquet`.
fn detail<'a>(b: &'a BudgetReport<'a>, parts: &mut Summary<'a>) {
    parts.text(
        "\n### Detail: medians of separate configurations\n\n\
         The p95 of each configuration as a median over the worlds, each configuration on its own (not paired per world). \
         Share (removed, medians): the square of what removing a source saves from the whole, medians over realisations, over \
         the sum; where it differs from the share above by more than 0.15 the sources interact. Two medians over worlds that \
         spread differ by more than the per-world change: what removing or scaling a source buys is the paired change (the \
         column `off` here, `at xF` above); where a difference of medians is not, the row says `medians only`.\n\n",
    );
    let factors: Vec<f64> = b.lines.first().map(|l| l.scaled_mm.iter().map(|x| x.0).collect()).unwrap_or_default();
    let mut cells = vec![
        cell("source", |r| r.str("source")),
        cell("share (removed, medians)", |r| {
            let only = if r.bool("medians_only") { " (medians only: the paired change is noise)" } else { "" };
            format!("{:.2}{only}", r.f64("share_removed"))
        }),
        cell("p95 alone, mm", |r| f3(r.f64("p95_alone_mm"))),
        cell("p95 without it, mm", |r| f3(r.f64("p95_off_mm"))),
        cell("off, mm (paired)", move |r| {
            let label = r.str("source");
            let off = b.configs.iter().position(|c| c.mode == "off" && c.source.is_some_and(|k| b.sources[k].label == label));
            off.map_or("-".to_string(), |i| change(&r.of("budget.parquet", i)))
        }),
    ];
    for factor in factors {
        cells.push(cell(format!("p95 at x{factor}, mm"), move |r| f3(r.f64(&format!("p95_at_x{factor}_mm")))));
    }
    cells.push(cell("interaction", |r| if r.bool("interacts") { "yes" } else { "" }.to_string()));
    parts.table("lines.parquet", Summary::all_rows(), cells);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A prediction of `tasks` identifications whose parameter errors are `ratio` times the
    /// predicted std, with the predicted and simulated validation p95 (mm).
    fn prediction(ratio: f64, predicted_p95: f64, simulated_p95: f64) -> Prediction {
        Prediction {
            names: vec!["a".into(), "b".into(), "c".into()],
            simulated_sq: vec![ratio * ratio; 3],
            predicted_var: vec![1.0; 3],
            tasks: 1,
            predicted_mm: vec![[0.007, predicted_p95]],
            simulated_mm: vec![[0.008, simulated_p95]],
            sigma_mm: vec![0.0007],
        }
    }

    fn config(mode: &'static str, source: Option<usize>) -> Config {
        Config { label: mode.into(), source, mode, factor: 1.0, factors: vec![1.0] }
    }

    /// A source acting at the validation only keeps the floor's parameter ratio (above 1.2 in the
    /// TriCal cell): judged against the floor, it is missed for its validation error alone, and a
    /// source that raises the ratio beyond 1.2 times the floor's is a bias.
    #[test]
    fn a_source_alone_is_judged_against_the_floors_ratio() {
        let (none, all) = (config("none", None), config("all", None));
        let floor = prediction(1.32, 0.023, 0.023);
        let on = prediction(1.07, 0.5, 0.47);
        let rows = [(&all, &on), (&none, &floor)];
        let reference = floor_ratio(&rows);
        assert!((reference - 1.32).abs() < 1e-12, "{reference}");
        let validation_only = missed_because(&prediction(1.32, 0.023, 0.042), reference);
        assert!(!validation_only.contains("bias"), "{validation_only}");
        assert!(validation_only.contains("which no parameter carries"), "{validation_only}");
        assert_eq!(missed_because(&prediction(1.41, 0.031, 0.031), reference), "", "within 1.2 times the floor's ratio");
        let biased = missed_because(&prediction(1.61, 0.036, 0.036), reference);
        assert!(biased.contains("1.61 times the predicted std, more than 1.2 times 1.32"), "{biased}");
        // A floor below 1 (white noise) leaves the reference at 1; no floor row, the same.
        let low = prediction(0.91, 0.0, 0.0);
        assert_eq!(floor_ratio(&[(&none, &low)]), 1.0);
        assert_eq!(floor_ratio(&[(&all, &on)]), 1.0);
        assert!(missed_because(&prediction(1.25, 0.0, 0.0), 1.0).contains("bias"));
    }
}
