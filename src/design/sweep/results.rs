//! Result files of a sweep in `out/<sweep>/`: `sweep.parquet` (one row per grid point x
//! realisation x selection x set size), `points.parquet` (the aggregates over realisations),
//! `summary.md` (the design table ranked by the after-calibration p95 at the table set size, with
//! the success probabilities) and `manifest.json` (the sha256 of every table). Written into a
//! temporary directory exchanged with the old results atomically.

use std::fmt::Write as _;
use std::fs;
use std::path::{Path, PathBuf};

use polars::prelude::*;
use serde::Serialize;

use super::{PointRow, ShardInfo, Unit, UnitRow};
use crate::io::out_dir::write_atomically;
use crate::io::table::{err, parquet, table_hashes};

#[derive(Serialize)]
struct Manifest<'a> {
    sweep: &'a str,
    identity: &'a str,
    tables_sha256: std::collections::BTreeMap<String, String>,
    points: usize,
    realisations: u32,
    units: usize,
    failed_units: usize,
    crate_version: &'static str,
}

/// The best and the worst design (by the median p95 at the table set size) as scenario files of
/// their own, `best_design.toml` and `worst_design.toml`: `calsim run` on one redoes realisation 0
/// of that design with its figures and Rerun recording.
fn write_extremes(dir: &Path, info: &ShardInfo, points: &[PointRow]) -> std::io::Result<()> {
    let mut ranked: Vec<&PointRow> = points.iter().filter(|p| p.table && p.after[1][0].is_finite()).collect();
    ranked.sort_by(|a, b| a.after[1][0].total_cmp(&b.after[1][0]).then(a.point.cmp(&b.point)));
    if ranked.len() < 2 || info.scenarios.len() != info.points.len() {
        return Ok(());
    }
    for (file, p) in [("best_design.toml", ranked[0]), ("worst_design.toml", ranked[ranked.len() - 1])] {
        let head = format!(
            "# {}: grid point {} ({}), {} sets; p95 after calibration {:.3} mm (median over {} realisations).\n# `calsim run {file}` redoes its realisation 0 with the figures and the Rerun recording.\n",
            info.name,
            p.point,
            point_label(info, p.point),
            p.selection,
            p.after[1][0],
            p.realisations
        );
        fs::write(dir.join(file), head + &info.scenarios[p.point])?;
    }
    Ok(())
}

/// The axis values of a point, `key = value, ...`.
pub fn point_label(info: &ShardInfo, p: usize) -> String {
    info.keys.iter().zip(&info.points[p]).map(|(k, v)| format!("{k} = {v}")).collect::<Vec<_>>().join(", ")
}

/// Writes the merged results of a sweep into `out/<name>`, replacing what was there.
pub fn write(out: &Path, info: &ShardInfo, units: &[Unit], points: &[PointRow]) -> std::io::Result<PathBuf> {
    write_atomically(out, &info.name, |dir| write_into(dir, info, units, points))
}

/// Long by design: one block per result file, in the order of the module doc.
fn write_into(dir: &Path, info: &ShardInfo, units: &[Unit], points: &[PointRow]) -> std::io::Result<()> {
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
        cols.push(Column::new(key.as_str().into(), rows.iter().map(|(x, _)| info.points[x.point][a].clone()).collect::<Vec<_>>()));
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
    parquet(dir, "sweep.parquet", cols)?;

    let mut cols = vec![u("point", points.iter().map(|p| p.point as u32).collect())];
    for (a, key) in info.keys.iter().enumerate() {
        cols.push(Column::new(key.as_str().into(), points.iter().map(|p| info.points[p.point][a].clone()).collect::<Vec<_>>()));
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
    parquet(dir, "points.parquet", cols)?;

    let manifest = Manifest {
        sweep: &info.name,
        identity: &info.identity,
        tables_sha256: table_hashes(dir)?,
        points: info.points.len(),
        realisations: info.realisations,
        units: units.len(),
        failed_units: units.iter().filter(|x| x.error.is_some()).count(),
        crate_version: env!("CARGO_PKG_VERSION"),
    };
    fs::write(dir.join("manifest.json"), serde_json::to_string_pretty(&manifest).map_err(err)?)?;
    write_extremes(dir, info, points)?;
    let drawn = super::plots::write(dir, &plot_inputs(info, points)).map_err(std::io::Error::other)?;
    let mut text = summary(info, units, points);
    let _ = writeln!(text, "\n## Figures\n");
    for w in drawn {
        let _ = writeln!(text, "![{}]({}.png)\n\n{} ([SVG]({}.svg))\n", w.caption, w.stem, w.caption, w.stem);
    }
    fs::write(dir.join("summary.md"), text)?;
    Ok(())
}

/// The figures' inputs: x is the axis value where the sweep has one numeric axis, else the point.
fn plot_inputs(info: &ShardInfo, points: &[PointRow]) -> super::plots::SweepPlotInputs {
    let numeric: Option<Vec<f64>> =
        if info.keys.len() == 1 { info.points.iter().map(|v| v[0].parse::<f64>().ok()).collect() } else { None };
    let x = |p: usize| numeric.as_ref().map_or(p as f64, |v| v[p]);
    let label = |p: &PointRow| format!("{} {}", p.point, p.selection);
    let designs = points.iter().filter(|p| p.table).map(|p| (label(p), x(p.point), p.after[1], p.campaign_s)).collect();
    let mut success: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    if !info.thresholds_mm.is_empty() {
        for p in points {
            let l = label(p);
            let v = (f64::from(p.set_size), p.success[0].0);
            match success.iter_mut().find(|s| s.0 == l) {
                Some(s) => s.1.push(v),
                None => success.push((l, vec![v])),
            }
        }
    }
    // The cell from above, one panel per design, when the sweep moves the spheres.
    let moves_spheres = info.keys.iter().any(|k| k == "cell.layout" || k == "cell.spheres_w_mm");
    let layouts = if moves_spheres && info.layouts.len() == info.points.len() {
        (0..info.points.len())
            .map(|p| {
                let at = points.iter().find(|r| r.point == p && r.table);
                let title = match at {
                    Some(r) => format!("{p}: p95 {:.3} mm", r.after[1][0]),
                    None => format!("{p}: campaign failed"),
                };
                (title, info.layouts[p].clone(), at.is_some())
            })
            .collect()
    } else {
        Vec::new()
    };
    super::plots::SweepPlotInputs {
        layouts,
        designs,
        xlabel: if numeric.is_some() { info.keys[0].clone() } else { "grid point (see the design table)".into() },
        success,
        threshold_mm: info.thresholds_mm.first().copied().unwrap_or(f64::NAN),
    }
}

fn f3(x: f64) -> String {
    if x.is_finite() { format!("{x:.3}") } else { "-".into() }
}

/// The design table: the points at their table set size ranked by the median over realisations of
/// the after-calibration p95, then the success probability per set size.
///
/// Long by design: the summary document top to bottom, one block per section.
pub fn summary(info: &ShardInfo, units: &[Unit], points: &[PointRow]) -> String {
    let mut s = String::new();
    let failed = units.iter().filter(|u| u.error.is_some()).count();
    let _ = writeln!(
        s,
        "# {}: {} grid points x {} realisations ({} work units, {failed} failed)\n",
        info.name,
        info.points.len(),
        info.realisations,
        units.len()
    );
    let _ = writeln!(
        s,
        "Errors after calibration at each point's table set size: the median over realisations with its P10-P90 range, of each \
         realisation's median (over repetitions) of the validation errors' median, p95 and max (SPMS: ISO 9283 AP over P1-P5). \
         Ranked by the p95 column.\n"
    );
    let mut table: Vec<&PointRow> = points.iter().filter(|p| p.table).collect();
    table.sort_by(|a, b| a.after[1][0].total_cmp(&b.after[1][0]).then(a.point.cmp(&b.point)));
    let th = &info.thresholds_mm;
    let _ = write!(s, "| rank | point | design | selection | n | after median, mm | after p95, mm | after max, mm | before median, mm |");
    for t in th {
        let _ = write!(s, " P(max <= {t} mm) |");
    }
    let _ = writeln!(s, " campaign, s | realisations |");
    let _ = writeln!(s, "|{}", "---|".repeat(11 + th.len()));
    for (rank, p) in table.iter().enumerate() {
        let band = |m: [f64; 3]| format!("{} ({}-{})", f3(m[0]), f3(m[1]), f3(m[2]));
        let _ = write!(
            s,
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            rank + 1,
            p.point,
            point_label(info, p.point),
            p.selection,
            p.set_size,
            band(p.after[0]),
            band(p.after[1]),
            band(p.after[2]),
            f3(p.before[0])
        );
        for (m, _) in &p.success {
            let _ = write!(s, " {:.2} |", m);
        }
        let _ = writeln!(s, " {:.0} | {} |", p.campaign_s, p.realisations);
    }
    let mut sizes: Vec<u32> = points.iter().map(|p| p.set_size).collect();
    sizes.sort_unstable();
    sizes.dedup();
    let mut keys: Vec<(usize, &str)> = points.iter().map(|p| (p.point, p.selection.as_str())).collect();
    keys.dedup();
    for (t, limit) in th.iter().enumerate() {
        let _ = writeln!(s, "\n## P(max error <= {limit} mm) by set size (over realisations x repetitions)\n");
        let _ = writeln!(s, "| point | selection | {} |", sizes.iter().map(|n| format!("n = {n}")).collect::<Vec<_>>().join(" | "));
        let _ = writeln!(s, "|---|---|{}", "---|".repeat(sizes.len()));
        for &(pt, sel) in &keys {
            let cells: Vec<String> = sizes
                .iter()
                .map(|n| {
                    points
                        .iter()
                        .find(|p| p.point == pt && p.selection == sel && p.set_size == *n)
                        .map_or("-".into(), |p| format!("{:.2}", p.success[t].0))
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
