//! Result files of a sweep in `out/<sweep>/`: `sweep.parquet` (one row per grid point x
//! realisation x selection x set size), `points.parquet` (the aggregates over realisations, with
//! the intervals of their medians and probabilities), `designs.parquet` (every design judged by the
//! sweep's objective: estimate, interval, feasibility, rank, the paired comparison with the leader,
//! ties, eliminations), `summary.md` (the designs ranked by the objective, ties named, then the
//! errors and success probabilities with their intervals), `best_design.toml` and
//! `worst_design.toml`, and `manifest.json` (the sha256 of every table). Written into a temporary
//! directory exchanged with the old results atomically.

use std::path::{Path, PathBuf};

use polars::prelude::*;
use serde::Serialize;

use super::designs::{DesignRow, Feasibility};
use super::race::Plan;
use super::{PointRow, ShardInfo, Unit, UnitRow};
use crate::io::results::{Cell, Head, Results, Row, Rows, Summary};

/// A merged sweep: its record, its units, the aggregates per point and the designs judged.
pub struct Merged {
    /// The sweep's record.
    pub info: ShardInfo,
    /// Every unit run, in unit order.
    pub units: Vec<Unit>,
    /// Aggregates per point, selection and set size.
    pub points: Vec<PointRow>,
    /// The designs judged by the objective, in design order.
    pub designs: Vec<DesignRow>,
    /// What the race did (a single stage for fixed realisations).
    pub plan: Plan,
}

impl Merged {
    /// Aggregates and judges the units of a complete sweep.
    pub fn of(info: ShardInfo, units: Vec<Unit>, plan: Plan) -> Self {
        let points = super::aggregate(&info, &units);
        let designs = super::designs::judge(&info, &units, &plan.eliminated);
        Self { info, units, points, designs, plan }
    }

    /// The designs in rank order.
    pub fn ranked(&self) -> Vec<&DesignRow> {
        let mut v: Vec<&DesignRow> = self.designs.iter().collect();
        v.sort_by_key(|d| d.rank);
        v
    }
}

#[derive(Serialize)]
struct Fields<'a> {
    sweep: &'a str,
    identity: &'a str,
    objective: String,
    stages: usize,
    points: usize,
    realisations: u32,
    units: usize,
    failed_units: usize,
}

/// The best and the worst design by the objective as scenario files of their own,
/// `best_design.toml` and `worst_design.toml`, with the design's selection and set size as the
/// study's table: `calsim run` on one (from any directory) redoes its realisation 0 with the
/// figures and the Rerun recording.
fn extremes(m: &Merged) -> std::io::Result<Vec<(&'static str, String)>> {
    let ranked: Vec<&DesignRow> = m.ranked().into_iter().filter(|d| d.estimate.is_finite()).collect();
    let info = &m.info;
    if ranked.len() < 2 {
        return Ok(Vec::new());
    }
    let mut out = Vec::new();
    for (file, d) in [("best_design.toml", ranked[0]), ("worst_design.toml", ranked[ranked.len() - 1])] {
        // The record was checked whole before the merge: every point's scenario loads.
        let mut table = info.point_table(d.design.point).map_err(std::io::Error::other)?;
        let study = table.entry("study").or_insert_with(|| toml::Value::Table(toml::Table::new()));
        if let Some(s) = study.as_table_mut() {
            s.insert("table_set_size".into(), toml::Value::Integer(i64::from(d.design.set_size)));
            s.insert("selections".into(), toml::Value::Array(vec![toml::Value::String(d.design.selection.clone())]));
        }
        let head = format!(
            "# {}: rank {} of {} by the objective ({}): grid point {} ({}), {} sets of {}; {} (interval {}-{}), {} over {} realisations.\n\
             # `calsim run {file}` redoes its realisation 0 with the figures and the Rerun recording (from any directory).\n",
            info.name,
            d.rank,
            m.designs.len(),
            info.objective.describe(),
            d.design.point,
            point_label(info, d.design.point),
            d.design.selection,
            d.design.set_size,
            f3(d.estimate),
            f3(d.interval.0),
            f3(d.interval.1),
            d.feasibility.label(),
            d.worlds
        );
        out.push((file, head + &toml::to_string(&table).map_err(std::io::Error::other)?));
    }
    Ok(out)
}

/// The column of axis `key` from its values as written (TOML): integers where every value is an
/// integer, numbers where every value is a number, else the values' text (arrays, strings).
fn axis_column<'a>(key: &str, values: impl Iterator<Item = &'a str>) -> Column {
    let values: Vec<&str> = values.collect();
    if let Some(v) = values.iter().map(|v| v.parse::<i64>().ok()).collect::<Option<Vec<i64>>>() {
        return Column::new(key.into(), v);
    }
    if let Some(v) = values.iter().map(|v| v.parse::<f64>().ok().filter(|x| x.is_finite())).collect::<Option<Vec<f64>>>() {
        return Column::new(key.into(), v);
    }
    Column::new(key.into(), values.iter().map(|v| v.to_string()).collect::<Vec<String>>())
}

/// The axis values of a point, `key = value, ...`.
pub fn point_label(info: &ShardInfo, p: usize) -> String {
    info.keys.iter().zip(&info.points[p]).map(|(k, v)| format!("{k} = {v}")).collect::<Vec<_>>().join(", ")
}

/// Writes the merged results of a sweep into `out/<name>`, replacing what was there; the
/// directory and the summary as written.
pub fn write(out: &Path, m: &Merged) -> std::io::Result<(PathBuf, String)> {
    crate::io::results::write(out, results(m)?).map(|w| (w.dest, w.summary))
}

/// The results of a merged sweep (the files of the module doc).
pub fn results(m: &Merged) -> std::io::Result<Results<'_>> {
    let (info, units) = (&m.info, &m.units[..]);
    let mut r = Results::new(info.name.clone(), Head::Run(crate::io::manifest::Provenance::of_run(&info.overrides)));
    r.table("sweep.parquet", unit_columns(m))?;
    r.table("points.parquet", point_columns(m))?;
    r.table("designs.parquet", design_columns(m))?;
    r.fields(Fields {
        sweep: &info.name,
        identity: &info.identity,
        objective: info.objective.describe(),
        stages: m.plan.stages_run,
        points: info.points.len(),
        realisations: info.realisations,
        units: units.len(),
        failed_units: units.iter().filter(|x| x.error.is_some()).count(),
    })?;
    for (file, text) in extremes(m)? {
        r.file(file, text);
    }
    r.draw(Box::new(move |dir| super::plots::write(dir, info, &m.points, &m.designs)));
    summary(m, &mut r.summary);
    r.summary.figures("\n## Figures\n\n");
    Ok(r)
}

/// `sweep.parquet`, long form: one row per unit and (selection, set size); a failed unit has one
/// row with its error.
fn unit_columns(m: &Merged) -> Vec<Column> {
    let (info, units) = (&m.info, &m.units[..]);
    let f = |n: &str, v: Vec<f64>| Column::new(n.into(), v);
    let u = |n: &str, v: Vec<u32>| Column::new(n.into(), v);
    let rows: Vec<(&Unit, Option<&UnitRow>)> = units
        .iter()
        .flat_map(|x| if x.rows.is_empty() { vec![(x, None)] } else { x.rows.iter().map(|r| (x, Some(r))).collect() })
        .collect();
    let opt = |g: &dyn Fn(&UnitRow) -> f64| rows.iter().map(|(_, r)| r.map_or(f64::NAN, g)).collect::<Vec<_>>();
    let mut cols = vec![
        u("unit", rows.iter().map(|(x, _)| x.unit as u32).collect()),
        u("point", rows.iter().map(|(x, _)| x.point as u32).collect()),
        u("realisation", rows.iter().map(|(x, _)| x.realisation).collect()),
    ];
    for (a, key) in info.keys.iter().enumerate() {
        cols.push(axis_column(key, rows.iter().map(|(x, _)| info.points[x.point][a].as_str())));
    }
    cols.extend([
        Column::new("error".into(), rows.iter().map(|(x, _)| x.error.clone().unwrap_or_default()).collect::<Vec<_>>()),
        Column::new("selection".into(), rows.iter().map(|(_, r)| r.map(|r| r.selection.clone()).unwrap_or_default()).collect::<Vec<_>>()),
        u("set_size", rows.iter().map(|(_, r)| r.map_or(0, |r| r.set_size)).collect()),
        Column::new("table_set_size".into(), rows.iter().map(|(_, r)| r.is_some_and(|r| r.table)).collect::<Vec<_>>()),
        u("repetitions", rows.iter().map(|(_, r)| r.map_or(0, |r| r.repetitions)).collect()),
        u("no_model", rows.iter().map(|(_, r)| r.map_or(0, |r| r.no_model)).collect()),
        f("before_median_mm", rows.iter().map(|(x, _)| x.before_mm[0]).collect()),
        f("before_p95_mm", rows.iter().map(|(x, _)| x.before_mm[1]).collect()),
        f("before_max_mm", rows.iter().map(|(x, _)| x.before_mm[2]).collect()),
        f("after_median_mm", opt(&|r| r.after_median_mm)),
        f("after_p95_mm", opt(&|r| r.after_p95_mm)),
        f("after_max_mm", opt(&|r| r.after_max_mm)),
        f("after_mean_mm", opt(&|r| r.after_mean_mm)),
        f("o1_median", opt(&|r| r.o1_median)),
        f("campaign_s", rows.iter().map(|(x, _)| x.campaign_s).collect()),
    ]);
    for (t, th) in info.thresholds_mm.iter().enumerate() {
        cols.push(u(&format!("max_within_{th}mm"), rows.iter().map(|(_, r)| r.map_or(0, |r| r.max_within[t])).collect()));
        cols.push(u(&format!("mean_within_{th}mm"), rows.iter().map(|(_, r)| r.map_or(0, |r| r.mean_within[t])).collect()));
    }
    for (t, th) in info.thresholds_mm.iter().enumerate() {
        let count = |c: &Vec<u32>| c.get(t).copied().unwrap_or(0);
        cols.push(u(&format!("p95_within_{th}mm"), rows.iter().map(|(_, r)| r.map_or(0, |r| count(&r.p95_within))).collect()));
        cols.push(u(&format!("median_within_{th}mm"), rows.iter().map(|(_, r)| r.map_or(0, |r| count(&r.median_within))).collect()));
    }
    cols
}

/// `points.parquet`: the aggregates per point, selection and set size, then their intervals.
fn point_columns(m: &Merged) -> Vec<Column> {
    let (info, points) = (&m.info, &m.points[..]);
    let f = |n: &str, v: Vec<f64>| Column::new(n.into(), v);
    let u = |n: &str, v: Vec<u32>| Column::new(n.into(), v);
    let mut cols = vec![u("point", points.iter().map(|p| p.point as u32).collect())];
    for (a, key) in info.keys.iter().enumerate() {
        cols.push(axis_column(key, points.iter().map(|p| info.points[p.point][a].as_str())));
    }
    cols.extend([
        Column::new("selection".into(), points.iter().map(|p| p.selection.clone()).collect::<Vec<_>>()),
        u("set_size", points.iter().map(|p| p.set_size).collect()),
        Column::new("table_set_size".into(), points.iter().map(|p| p.table).collect::<Vec<_>>()),
        u("realisations", points.iter().map(|p| p.realisations).collect()),
    ]);
    for (m, name) in ["median", "p95", "max"].iter().enumerate() {
        for (q, qn) in ["median", "p10", "p90"].iter().enumerate() {
            cols.push(f(&format!("after_{name}_mm_{qn}"), points.iter().map(|p| p.after[m][q]).collect()));
        }
    }
    cols.extend([
        f("before_median_mm", points.iter().map(|p| p.before[0]).collect()),
        f("before_p95_mm", points.iter().map(|p| p.before[1]).collect()),
        f("before_max_mm", points.iter().map(|p| p.before[2]).collect()),
    ]);
    for (t, th) in info.thresholds_mm.iter().enumerate() {
        cols.push(f(&format!("p_max_within_{th}mm"), points.iter().map(|p| p.success[t].0).collect()));
        cols.push(f(&format!("p_mean_within_{th}mm"), points.iter().map(|p| p.success[t].1).collect()));
    }
    cols.extend([
        u("no_model", points.iter().map(|p| p.no_model).collect()),
        f("o1_median", points.iter().map(|p| p.o1).collect()),
        f("campaign_s_median", points.iter().map(|p| p.campaign_s).collect()),
    ]);
    // The intervals at the sweep's confidence, after the columns above.
    for (m, name) in ["median", "p95", "max"].iter().enumerate() {
        for (q, qn) in ["lo", "hi"].iter().enumerate() {
            cols.push(f(&format!("after_{name}_mm_median_{qn}"), points.iter().map(|p| p.after_ci[m][q]).collect()));
        }
    }
    for (t, th) in info.thresholds_mm.iter().enumerate() {
        for (q, qn) in ["p_max_within", "p_max_within", "p_mean_within", "p_mean_within"].iter().enumerate() {
            let side = if q % 2 == 0 { "lo" } else { "hi" };
            cols.push(f(&format!("{qn}_{th}mm_{side}"), points.iter().map(|p| p.success_ci[t][q]).collect()));
        }
    }
    cols
}

/// `designs.parquet`: one row per design judged by the objective.
fn design_columns(m: &Merged) -> Vec<Column> {
    let d = &m.designs;
    let f = |n: &str, v: Vec<f64>| Column::new(n.into(), v);
    let u = |n: &str, v: Vec<u32>| Column::new(n.into(), v);
    let vs =
        |g: &dyn Fn(&crate::study::interval::Paired) -> f64| d.iter().map(|r| r.vs_leader.as_ref().map_or(f64::NAN, g)).collect::<Vec<_>>();
    let mut cols = vec![u("point", d.iter().map(|r| r.design.point as u32).collect())];
    for (a, key) in m.info.keys.iter().enumerate() {
        cols.push(axis_column(key, d.iter().map(|r| m.info.points[r.design.point][a].as_str())));
    }
    cols.extend([
        Column::new("selection".into(), d.iter().map(|r| r.design.selection.clone()).collect::<Vec<_>>()),
        u("set_size", d.iter().map(|r| r.design.set_size).collect()),
        u("rank", d.iter().map(|r| r.rank as u32).collect()),
        Column::new("objective".into(), vec![m.info.objective.describe(); d.len()]),
        f("estimate", d.iter().map(|r| r.estimate).collect()),
        f("estimate_lo", d.iter().map(|r| r.interval.0).collect()),
        f("estimate_hi", d.iter().map(|r| r.interval.1).collect()),
        Column::new("feasibility".into(), d.iter().map(|r| r.feasibility.label().to_string()).collect::<Vec<_>>()),
        Column::new("tied_with_leader".into(), d.iter().map(|r| r.tied).collect::<Vec<_>>()),
        f("vs_leader_median_difference", vs(&|p| p.median)),
        f("vs_leader_difference_lo", vs(&|p| p.interval.0)),
        f("vs_leader_difference_hi", vs(&|p| p.interval.1)),
        f("vs_leader_sign_test_p", vs(&|p| p.test.p_value)),
        f("vs_leader_correlation", vs(&|p| p.correlation)),
        f("vs_leader_variance_saving", vs(&|p| p.variance_saving)),
        f("vs_leader_mean_difference", vs(&|p| p.mean)),
        u("vs_leader_better", d.iter().map(|r| r.vs_leader.as_ref().map_or(0, |p| better_worse(m, p).0 as u32)).collect()),
        u("vs_leader_worse", d.iter().map(|r| r.vs_leader.as_ref().map_or(0, |p| better_worse(m, p).1 as u32)).collect()),
        f("success", d.iter().map(|r| r.success.map_or(f64::NAN, |s| s.0)).collect()),
        f("success_lo", d.iter().map(|r| r.success.map_or(f64::NAN, |s| s.1.0)).collect()),
        f("success_hi", d.iter().map(|r| r.success.map_or(f64::NAN, |s| s.1.1)).collect()),
        f("campaign_h_median", d.iter().map(|r| r.campaign_h).collect()),
        u("worlds", d.iter().map(|r| r.worlds).collect()),
        u("failed_worlds", d.iter().map(|r| r.failed_worlds).collect()),
        Column::new(
            "eliminated".into(),
            d.iter().map(|r| r.eliminated.as_ref().map(|e| e.1.clone()).unwrap_or_default()).collect::<Vec<_>>(),
        ),
    ]);
    cols
}

/// The worlds in which a design did better and worse than the leader, by the objective's sense.
fn better_worse(m: &Merged, p: &crate::study::interval::Paired) -> (usize, usize) {
    if m.info.objective.maximises() { (p.test.positive, p.test.negative) } else { (p.test.negative, p.test.positive) }
}

fn f3(x: f64) -> String {
    if x.is_finite() {
        format!("{x:.3}")
    } else if x == f64::INFINITY {
        "fails".into()
    } else {
        "-".into()
    }
}

/// A difference with its sign, `+0.012`, `-0.002` (`fails` where the design fails more often).
fn signed(x: f64) -> String {
    if x.is_finite() { format!("{x:+.3}") } else { f3(x) }
}

/// A value with its interval, `0.950 (0.881-0.986)`.
fn with_interval(x: f64, (lo, hi): (f64, f64)) -> String {
    if lo.is_finite() && hi.is_finite() {
        format!("{} ({}-{})", f3(x), f3(lo), f3(hi))
    } else {
        format!("{} (too few worlds for an interval)", f3(x))
    }
}

/// The design of a row of `designs.parquet` or `points.parquet` in words: `point 3 (cell.layout =
/// ...), detmax sets of 75`.
fn design_label(info: &ShardInfo, row: &Row<'_>) -> String {
    let point = row.u64("point") as usize;
    format!("{point} {}, {} sets of {}", point_label(info, point), row.str("selection"), row.u64("set_size"))
}

/// A cell of a summary table.
fn cell<'a>(header: impl Into<String>, show: impl Fn(&Row<'_>) -> String + 'a) -> Cell<'a> {
    (header.into(), Box::new(show))
}

/// `x (lo-hi)` of three columns of a row.
fn shown_interval(row: &Row<'_>, x: &str, lo: &str, hi: &str) -> String {
    with_interval(row.f64(x), (row.f64(lo), row.f64(hi)))
}

/// The summary: the designs ranked by the objective with their intervals, the leader and the
/// designs tied with it, eliminations, then the errors after calibration and the success
/// probabilities with their intervals, and the designs whose campaign failed. Every figure of its
/// tables is read from the result tables.
pub fn summary<'a>(m: &'a Merged, s: &mut Summary<'a>) {
    let (info, units) = (&m.info, &m.units[..]);
    let o = &info.objective;
    let failed = units.iter().filter(|u| u.error.is_some()).count();
    s.text(format!(
        "# {}: {} grid points x {} realisations{} ({} work units, {failed} failed)\n\n",
        info.name,
        info.points.len(),
        info.realisations,
        if info.race.is_some() { " at most" } else { "" },
        units.len()
    ));
    let conf = o.confidence * 100.0;
    let constraints = o.constraints();
    s.text(format!(
        "**Objective**: {}{}. Intervals at {conf} % confidence over realisations (the unit of independence: one robot, cell and \
         set of draws each); a design is tied with the leader when the sign test of their paired values on common \
         realisations does not separate them at that confidence. The comparison with the leader is this design minus the \
         leader in each common realisation ({}), with the realisations in which the design did better and worse; \
         between tied designs its sign can run against the ranking, which orders each design's own estimate.{}\n\n",
        o.describe(),
        if constraints.is_empty() { String::new() } else { format!(", subject to {}", constraints.join(", ")) },
        if o.maximises() {
            "the mean of the differences: above 0, the design did better"
        } else {
            "the median of the differences with its interval: above 0, the design did worse"
        },
        match &info.race {
            Some(r) => format!(
                " Adaptive realisations: {} then batches of {} up to {}, {} stages run; a design leaves the race when it is infeasible or \
                 the sign test against the leader rejects equality at {:.2e} (Bonferroni over the stages).",
                r.min,
                r.batch,
                r.max,
                m.plan.stages_run,
                (1.0 - r.confidence) / r.stages().len() as f64
            ),
            None => String::new(),
        }
    ));
    ranked(m, s);
    leader(m, s);
    left_the_race(m, s);
    errors(m, s);
    success(m, s);
    failed_campaigns(m, s);
}

/// The designs ranked by the objective, from `designs.parquet`.
fn ranked<'a>(m: &'a Merged, s: &mut Summary<'a>) {
    let (info, o) = (&m.info, &m.info.objective);
    let conf = o.confidence * 100.0;
    s.text("## Designs ranked by the objective\n\n");
    let maximises = o.maximises();
    let by_rank: Rows<'a> = Box::new(|f: &DataFrame| {
        let ranks: Vec<u32> = f.column("rank").ok().and_then(|c| c.u32().ok()).map(|c| c.into_no_null_iter().collect()).unwrap_or_default();
        let mut order: Vec<usize> = (0..ranks.len()).collect();
        order.sort_by_key(|&i| ranks[i]);
        order
    });
    s.table(
        "designs.parquet",
        by_rank,
        vec![
            cell("rank", |r| r.u64("rank").to_string()),
            cell("design", move |r| design_label(info, r)),
            cell(format!("objective ({conf} % interval)"), |r| shown_interval(r, "estimate", "estimate_lo", "estimate_hi")),
            cell("feasibility", |r| r.str("feasibility")),
            cell("this design - leader (paired on common worlds)", move |r| vs_leader(r, maximises)),
            cell("pairing: r, variance saved", |r| {
                if r.u64("rank") == 1 {
                    "-".to_string()
                } else {
                    format!("{:.2}, {:.0} %", r.f64("vs_leader_correlation"), 100.0 * r.f64("vs_leader_variance_saving"))
                }
            }),
            cell("tied", |r| {
                if r.u64("rank") == 1 {
                    "-"
                } else if r.bool("tied_with_leader") {
                    "**tied**"
                } else if !r.str("eliminated").is_empty() {
                    "left the race"
                } else {
                    "no"
                }
                .to_string()
            }),
            cell("P(success)", |r| {
                if r.f64("success").is_nan() { "-".to_string() } else { shown_interval(r, "success", "success_lo", "success_hi") }
            }),
            cell("campaign, h", |r| f3(r.f64("campaign_h_median"))),
            cell("realisations", |r| {
                let failed = r.u64("failed_worlds");
                format!("{}{}", r.u64("worlds"), if failed > 0 { format!(" ({failed} failed)") } else { String::new() })
            }),
        ],
    );
}
/// The leader and the designs tied with it.
fn leader<'a>(m: &'a Merged, s: &mut Summary<'a>) {
    let info = &m.info;
    let ranked = m.ranked();
    if let Some(leader) = ranked.first() {
        let label = |d: &DesignRow| {
            format!("{} {}, {} sets of {}", d.design.point, point_label(info, d.design.point), d.design.selection, d.design.set_size)
        };
        let tied: Vec<String> = ranked.iter().filter(|r| r.tied).map(|r| label(r)).collect();
        s.text(format!(
            "**Leader**: {} ({}){}. {}\n\n",
            label(leader),
            leader.feasibility.label(),
            if leader.feasibility == Feasibility::Undecided {
                ": its constraints are not confirmed at this confidence; more realisations would decide"
            } else {
                ""
            },
            if tied.is_empty() {
                "No other design is tied with it at this confidence.".to_string()
            } else {
                format!("Statistically tied with it: {}.", tied.join("; "))
            }
        ));
    }
}
/// The designs an adaptive sweep eliminated, from `designs.parquet`.
fn left_the_race<'a>(m: &'a Merged, s: &mut Summary<'a>) {
    let info = &m.info;
    let out: Vec<usize> = (0..m.designs.len()).filter(|&i| m.designs[i].eliminated.is_some()).collect();
    if !out.is_empty() {
        let mut order = out;
        order.sort_by_key(|&i| m.designs[i].rank);
        s.text("### Designs that left the race\n\n");
        s.table(
            "designs.parquet",
            Box::new(move |_| order.clone()),
            vec![
                cell("design", move |r| design_label(info, r)),
                cell("realisations", |r| m.designs[r.index()].eliminated.as_ref().map_or(0, |e| e.0).to_string()),
                cell("why", |r| r.str("eliminated")),
            ],
        );
    }
}
/// The errors after calibration at each point's table set size, from `points.parquet`.
fn errors<'a>(m: &'a Merged, s: &mut Summary<'a>) {
    let (info, points) = (&m.info, &m.points[..]);
    let conf = info.objective.confidence * 100.0;
    s.text(format!(
        "## Errors after calibration at each point's table set size\n\nMedian over realisations with its {conf} % interval \
         (order statistics) and the P10-P90 range of the worlds, of each realisation's median (over repetitions) of the \
         validation errors' median, p95 and max (SPMS: ISO 9283 AP over P1-P5).\n\n"
    ));
    let th = &info.thresholds_mm;
    let by_p95: Rows<'a> = Box::new(|_| {
        let mut table: Vec<usize> = (0..points.len()).filter(|&i| points[i].table).collect();
        table.sort_by(|&a, &b| points[a].after[1][0].total_cmp(&points[b].after[1][0]).then(points[a].point.cmp(&points[b].point)));
        table
    });
    let after = |name: &'static str| {
        move |r: &Row<'_>| {
            let c = |q: &str| r.f64(&format!("after_{name}_mm_{q}"));
            format!("{} ({}-{}; P10-P90 {}-{})", f3(c("median")), f3(c("median_lo")), f3(c("median_hi")), f3(c("p10")), f3(c("p90")))
        }
    };
    let mut cells = vec![
        cell("point", |r| r.u64("point").to_string()),
        cell("design", move |r| point_label(info, r.u64("point") as usize)),
        cell("selection", |r| r.str("selection")),
        cell("n", |r| r.u64("set_size").to_string()),
        cell("after median, mm", after("median")),
        cell("after p95, mm", after("p95")),
        cell("after max, mm", after("max")),
        cell("before median, mm", |r| f3(r.f64("before_median_mm"))),
    ];
    for t in th {
        let t = *t;
        cells.push(cell(format!("P(max <= {t} mm)"), move |r| probability(r, t)));
    }
    cells.push(cell("campaign, s", |r| format!("{:.0}", r.f64("campaign_s_median"))));
    cells.push(cell("realisations", |r| r.u64("realisations").to_string()));
    s.table("points.parquet", by_p95, cells);
}
/// P(max error <= t) by set size for each threshold, from `points.parquet`.
fn success<'a>(m: &'a Merged, s: &mut Summary<'a>) {
    let (points, th) = (&m.points[..], &m.info.thresholds_mm);
    let conf = m.info.objective.confidence * 100.0;
    let mut sizes: Vec<u32> = points.iter().map(|p| p.set_size).collect();
    sizes.sort_unstable();
    sizes.dedup();
    let mut keys: Vec<(usize, &str)> = points.iter().map(|p| (p.point, p.selection.as_str())).collect();
    keys.dedup();
    // One row per (point, selection): the first of its rows in points.parquet.
    let firsts: Vec<usize> = keys.iter().filter_map(|k| points.iter().position(|p| (p.point, p.selection.as_str()) == *k)).collect();
    for limit in th {
        let limit = *limit;
        s.text(format!("## P(max error <= {limit} mm) by set size, with its {conf} % interval over realisations\n\n"));
        let mut cells = vec![cell("point", |r| r.u64("point").to_string()), cell("selection", |r| r.str("selection"))];
        for n in sizes.clone() {
            cells.push(cell(format!("n = {n}"), move |r| {
                let first = &points[r.index()];
                points
                    .iter()
                    .position(|p| p.point == first.point && p.selection == first.selection && p.set_size == n)
                    .map_or("-".into(), |j| probability(&r.at(j), limit))
            }));
        }
        let firsts = firsts.clone();
        s.table("points.parquet", Box::new(move |_| firsts.clone()), cells);
    }
}
/// The designs whose campaign failed in some realisations.
fn failed_campaigns<'a>(m: &'a Merged, s: &mut Summary<'a>) {
    let (info, units) = (&m.info, &m.units[..]);
    let failing: Vec<usize> = (0..info.points.len()).filter(|p| units.iter().any(|u| u.point == *p && u.error.is_some())).collect();
    if !failing.is_empty() {
        let mut t =
            "## Designs whose campaign failed in some realisations\n\n| point | design | failed | first reason |\n|---|---|---|---|\n"
                .to_string();
        for p in failing {
            let fails: Vec<&Unit> = units.iter().filter(|u| u.point == p && u.error.is_some()).collect();
            let of = units.iter().filter(|u| u.point == p).count();
            t.push_str(&format!(
                "| {p} | {} | {} of {of} | {} |\n",
                point_label(info, p),
                fails.len(),
                fails[0].error.as_deref().unwrap_or("")
            ));
        }
        s.text(t);
    }
}

/// A design's paired comparison with the leader, from its row of `designs.parquet`.
fn vs_leader(r: &Row<'_>, maximises: bool) -> String {
    if r.u64("rank") == 1 {
        return "leader".to_string();
    }
    let (better, worse, p) = (r.u64("vs_leader_better"), r.u64("vs_leader_worse"), r.f64("vs_leader_sign_test_p"));
    if maximises {
        // Fractions of successes tie in most worlds: the mean difference and the counts say more.
        format!("mean {:+.3}; better in {better}, worse in {worse} worlds, p = {p:.3}", r.f64("vs_leader_mean_difference"))
    } else {
        let c = |name: &str| signed(r.f64(name));
        format!(
            "{} ({} to {}); better in {better}, worse in {worse} worlds, p = {p:.3}",
            c("vs_leader_median_difference"),
            c("vs_leader_difference_lo"),
            c("vs_leader_difference_hi")
        )
    }
}

/// `P (lo-hi)` of the success probability at `limit` mm of a row of `points.parquet`.
fn probability(r: &Row<'_>, limit: f64) -> String {
    let c = |side: &str| r.f64(&format!("p_max_within_{limit}mm{side}"));
    format!("{:.2} ({:.2}-{:.2})", c(""), c("_lo"), c("_hi"))
}
