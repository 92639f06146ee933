//! Result files of a sweep in `out/<sweep>/`: `sweep.parquet` (one row per grid point x
//! realisation x selection x set size), `points.parquet` (the aggregates over realisations, with
//! the intervals of their medians and probabilities), `designs.parquet` (every design judged by the
//! sweep's objective: estimate, interval, feasibility, rank, the paired comparison with the leader,
//! ties, eliminations), `summary.md` (the designs ranked by the objective, ties named, then the
//! errors and success probabilities with their intervals), `best_design.toml` and
//! `worst_design.toml`, and `manifest.json` (the sha256 of every table). Written into a temporary
//! directory exchanged with the old results atomically.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use polars::prelude::*;
use serde::Serialize;

use super::designs::{DesignRow, Feasibility};
use super::race::Plan;
use super::{PointRow, ShardInfo, Unit, UnitRow};
use crate::io::out_dir::write_atomically;
use crate::io::table::{err, parquet, table_hashes};

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
struct Manifest<'a> {
    sweep: &'a str,
    identity: &'a str,
    objective: String,
    stages: usize,
    tables_sha256: std::collections::BTreeMap<String, String>,
    points: usize,
    realisations: u32,
    units: usize,
    failed_units: usize,
    #[serde(flatten)]
    provenance: crate::io::manifest::Provenance,
}

/// The best and the worst design by the objective as scenario files of their own,
/// `best_design.toml` and `worst_design.toml`, with the design's selection and set size as the
/// study's table: `calsim run` on one (from any directory) redoes its realisation 0 with the
/// figures and the Rerun recording.
fn write_extremes(dir: &Path, m: &Merged) -> std::io::Result<()> {
    let ranked: Vec<&DesignRow> = m.ranked().into_iter().filter(|d| d.estimate.is_finite()).collect();
    let info = &m.info;
    if ranked.len() < 2 {
        return Ok(());
    }
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
        crate::io::out_dir::write_file(&dir.join(file), head + &toml::to_string(&table).map_err(std::io::Error::other)?)?;
    }
    Ok(())
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

/// Writes the merged results of a sweep into `out/<name>`, replacing what was there.
pub fn write(out: &Path, m: &Merged) -> std::io::Result<PathBuf> {
    write_atomically(out, &m.info.name, |dir| write_into(dir, m))
}

/// Long by design: one block per result file, in the order of the module doc.
fn write_into(dir: &Path, m: &Merged) -> std::io::Result<()> {
    let (info, units, points) = (&m.info, &m.units[..], &m.points[..]);
    let f = |n: &str, v: Vec<f64>| Column::new(n.into(), v);
    let u = |n: &str, v: Vec<u32>| Column::new(n.into(), v);
    // Long form: one row per unit and (selection, set size); a failed unit has one row with its error.
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
    parquet(dir, "sweep.parquet", cols)?;

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
    parquet(dir, "points.parquet", cols)?;
    write_designs(dir, m)?;

    let manifest = Manifest {
        sweep: &info.name,
        identity: &info.identity,
        objective: info.objective.describe(),
        stages: m.plan.stages_run,
        tables_sha256: table_hashes(dir)?,
        points: info.points.len(),
        realisations: info.realisations,
        units: units.len(),
        failed_units: units.iter().filter(|x| x.error.is_some()).count(),
        provenance: crate::io::manifest::Provenance::of_run(&[]),
    };
    crate::io::out_dir::write_file(&dir.join("manifest.json"), serde_json::to_string_pretty(&manifest).map_err(err)?)?;
    write_extremes(dir, m)?;
    let drawn = super::plots::write(dir, info, points, &m.designs).map_err(std::io::Error::other)?;
    let mut text = summary(m);
    let _ = writeln!(text, "\n## Figures\n");
    for w in drawn {
        let _ = writeln!(text, "![{}]({}.png)\n\n{} ([SVG]({}.svg))\n", w.caption, w.stem, w.caption, w.stem);
    }
    crate::io::out_dir::write_file(&dir.join("summary.md"), text)?;
    Ok(())
}

/// `designs.parquet`: one row per design judged by the objective.
fn write_designs(dir: &Path, m: &Merged) -> std::io::Result<()> {
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
    parquet(dir, "designs.parquet", cols)
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

/// A value with its interval, `0.950 (0.881-0.986)`.
fn with_interval(x: f64, (lo, hi): (f64, f64)) -> String {
    if lo.is_finite() && hi.is_finite() {
        format!("{} ({}-{})", f3(x), f3(lo), f3(hi))
    } else {
        format!("{} (too few worlds for an interval)", f3(x))
    }
}

/// The design of a row in words: `point 3 (cell.layout = ...), detmax sets of 75`.
fn design_label(info: &ShardInfo, r: &DesignRow) -> String {
    format!("{} {}, {} sets of {}", r.design.point, point_label(info, r.design.point), r.design.selection, r.design.set_size)
}

/// The summary: the designs ranked by the objective with their intervals, the leader and the
/// designs tied with it, eliminations, then the errors after calibration and the success
/// probabilities with their intervals, and the designs whose campaign failed.
///
/// Long by design: the summary document top to bottom, one block per section.
pub fn summary(m: &Merged) -> String {
    let (info, units, points) = (&m.info, &m.units[..], &m.points[..]);
    let o = &info.objective;
    let mut s = String::new();
    let failed = units.iter().filter(|u| u.error.is_some()).count();
    let _ = writeln!(
        s,
        "# {}: {} grid points x {} realisations{} ({} work units, {failed} failed)\n",
        info.name,
        info.points.len(),
        info.realisations,
        if info.race.is_some() { " at most" } else { "" },
        units.len()
    );
    let conf = o.confidence * 100.0;
    let constraints = o.constraints();
    let _ = writeln!(
        s,
        "**Objective**: {}{}. Intervals at {conf} % confidence over realisations (the unit of independence: one robot, cell and \
         set of draws each); a design is tied with the leader when the sign test of their paired values on common \
         realisations does not separate them at that confidence.{}\n",
        o.describe(),
        if constraints.is_empty() { String::new() } else { format!(", subject to {}", constraints.join(", ")) },
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
    );
    let ranked = m.ranked();
    let _ = writeln!(s, "## Designs ranked by the objective\n");
    let _ = writeln!(
        s,
        "| rank | design | objective ({conf} % interval) | feasibility | vs leader (paired on common worlds) | pairing: r, variance saved | tied | P(success) | campaign, h | realisations |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|");
    for r in &ranked {
        let vs = r.vs_leader.as_ref().map_or("leader".to_string(), |p| {
            let (better, worse) = if o.maximises() { (p.test.positive, p.test.negative) } else { (p.test.negative, p.test.positive) };
            if o.maximises() {
                // Fractions of successes tie in most worlds: the mean difference and the counts say more.
                format!("mean {:+.3}; better in {better}, worse in {worse} worlds, p = {:.3}", p.mean, p.test.p_value)
            } else {
                format!(
                    "{} ({}-{}); better in {better}, worse in {worse}, p = {:.3}",
                    f3(p.median),
                    f3(p.interval.0),
                    f3(p.interval.1),
                    p.test.p_value
                )
            }
        });
        let pairing = r.vs_leader.as_ref().map_or("-".to_string(), |p| format!("{:.2}, {:.0} %", p.correlation, 100.0 * p.variance_saving));
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {vs} | {pairing} | {} | {} | {} | {}{} |",
            r.rank,
            design_label(info, r),
            with_interval(r.estimate, r.interval),
            r.feasibility.label(),
            if r.rank == 1 {
                "-"
            } else if r.tied {
                "**tied**"
            } else if r.eliminated.is_some() {
                "left the race"
            } else {
                "no"
            },
            r.success.map_or("-".to_string(), |(p, ci)| with_interval(p, ci)),
            f3(r.campaign_h),
            r.worlds,
            if r.failed_worlds > 0 { format!(" ({} failed)", r.failed_worlds) } else { String::new() }
        );
    }
    if let Some(leader) = ranked.first() {
        let tied: Vec<String> = ranked.iter().filter(|r| r.tied).map(|r| design_label(info, r)).collect();
        let _ = writeln!(
            s,
            "\n**Leader**: {} ({}){}. {}\n",
            design_label(info, leader),
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
        );
    }
    let out: Vec<&&DesignRow> = ranked.iter().filter(|r| r.eliminated.is_some()).collect();
    if !out.is_empty() {
        let _ = writeln!(s, "### Designs that left the race\n\n| design | realisations | why |\n|---|---|---|");
        for r in out {
            let (n, why) = r.eliminated.as_ref().expect("filtered");
            let _ = writeln!(s, "| {} | {n} | {why} |", design_label(info, r));
        }
        s.push('\n');
    }
    let _ = writeln!(
        s,
        "## Errors after calibration at each point's table set size\n\nMedian over realisations with its {conf} % interval \
         (order statistics) and the P10-P90 range of the worlds, of each realisation's median (over repetitions) of the \
         validation errors' median, p95 and max (SPMS: ISO 9283 AP over P1-P5).\n"
    );
    let mut table: Vec<&PointRow> = points.iter().filter(|p| p.table).collect();
    table.sort_by(|a, b| a.after[1][0].total_cmp(&b.after[1][0]).then(a.point.cmp(&b.point)));
    let th = &info.thresholds_mm;
    let _ = write!(s, "| point | design | selection | n | after median, mm | after p95, mm | after max, mm | before median, mm |");
    for t in th {
        let _ = write!(s, " P(max <= {t} mm) |");
    }
    let _ = writeln!(s, " campaign, s | realisations |");
    let _ = writeln!(s, "|{}", "---|".repeat(10 + th.len()));
    for p in &table {
        let cell = |k: usize| {
            format!(
                "{} ({}-{}; P10-P90 {}-{})",
                f3(p.after[k][0]),
                f3(p.after_ci[k][0]),
                f3(p.after_ci[k][1]),
                f3(p.after[k][1]),
                f3(p.after[k][2])
            )
        };
        let _ = write!(
            s,
            "| {} | {} | {} | {} | {} | {} | {} | {} |",
            p.point,
            point_label(info, p.point),
            p.selection,
            p.set_size,
            cell(0),
            cell(1),
            cell(2),
            f3(p.before[0])
        );
        for (k, (m, _)) in p.success.iter().enumerate() {
            let _ = write!(s, " {:.2} ({:.2}-{:.2}) |", m, p.success_ci[k][0], p.success_ci[k][1]);
        }
        let _ = writeln!(s, " {:.0} | {} |", p.campaign_s, p.realisations);
    }
    let mut sizes: Vec<u32> = points.iter().map(|p| p.set_size).collect();
    sizes.sort_unstable();
    sizes.dedup();
    let mut keys: Vec<(usize, &str)> = points.iter().map(|p| (p.point, p.selection.as_str())).collect();
    keys.dedup();
    for (t, limit) in th.iter().enumerate() {
        let _ = writeln!(s, "\n## P(max error <= {limit} mm) by set size, with its {conf} % interval over realisations\n");
        let _ = writeln!(s, "| point | selection | {} |", sizes.iter().map(|n| format!("n = {n}")).collect::<Vec<_>>().join(" | "));
        let _ = writeln!(s, "|---|---|{}", "---|".repeat(sizes.len()));
        for &(pt, sel) in &keys {
            let cells: Vec<String> = sizes
                .iter()
                .map(|n| {
                    points
                        .iter()
                        .find(|p| p.point == pt && p.selection == sel && p.set_size == *n)
                        .map_or("-".into(), |p| format!("{:.2} ({:.2}-{:.2})", p.success[t].0, p.success_ci[t][0], p.success_ci[t][1]))
                })
                .collect();
            let _ = writeln!(s, "| {pt} | {sel} | {} |", cells.join(" | "));
        }
    }
    let failing: Vec<usize> = (0..info.points.len()).filter(|p| units.iter().any(|u| u.point == *p && u.error.is_some())).collect();
    if !failing.is_empty() {
        let _ = writeln!(
            s,
            "\n## Designs whose campaign failed in some realisations\n\n| point | design | failed | first reason |\n|---|---|---|---|"
        );
        for p in failing {
            let fails: Vec<&Unit> = units.iter().filter(|u| u.point == p && u.error.is_some()).collect();
            let of = units.iter().filter(|u| u.point == p).count();
            let _ =
                writeln!(s, "| {p} | {} | {} of {of} | {} |", point_label(info, p), fails.len(), fails[0].error.as_deref().unwrap_or(""));
        }
    }
    s
}
