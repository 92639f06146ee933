//! The tables an SPMS summary shows beside the study's own, and the summary rendered from them:
//! `heads.parquet` (the beam solvers, Tables 2-3), `table6.parquet` (ISO 9283 AP per point beside
//! the paper's), `set_sizes.parquet` (random against DETMAX sets per set size) and
//! `parameter_medians.parquet` (the identified parameters at the table set size).

use polars::prelude::Column;

use super::spec::SpmsScenario;
use super::study::{SpmsFigures, SpmsResults};
use crate::io::results::{Results, Row, Summary, cell};
use crate::robot::params::display_name;
use crate::study::Selection;
use crate::study::published::published;
use crate::study::stats::median;

/// `x` with three decimals, `-` when it is not a number.
fn f3(x: f64) -> String {
    if x.is_finite() { format!("{x:.3}") } else { "-".into() }
}

/// Every table of this module.
pub fn tables(r: &SpmsResults, f: &SpmsFigures, out: &mut Results<'_>) -> std::io::Result<()> {
    out.table("heads.parquet", head_columns(r))?;
    out.table("table6.parquet", table6_columns(r, f))?;
    out.table("set_sizes.parquet", set_columns(r, f))?;
    out.table("parameter_medians.parquet", parameter_columns(r, f))?;
    Ok(())
}

/// `heads.parquet`: per identified head (`head` as in `beams.parquet`), the solver and its fit,
/// the worst beam errors, the accuracy test (Table 3) and, for the PSO + LM head, the PSO stage's
/// own residual.
fn head_columns(r: &SpmsResults) -> Vec<Column> {
    let h = &r.head;
    let ids = [("pso_lm_paper", &h.paper), ("lm_paper", &h.paper_lm_only), ("lm_minimal", &h.minimal)];
    let worst = |v: &[f64]| v.iter().fold(0.0, |a: f64, b| a.max(*b));
    let acc: Vec<(f64, f64, f64)> = ids.iter().map(|(_, id)| super::iso9283::summary(&id.measuring_error_mm)).collect();
    let f = |name: &str, v: Vec<f64>| Column::new(name.into(), v);
    let u = |name: &str, v: Vec<u32>| Column::new(name.into(), v);
    vec![
        Column::new("head".into(), ids.iter().map(|x| x.0).collect::<Vec<_>>()),
        Column::new("solver".into(), ids.iter().map(|x| x.1.label).collect::<Vec<_>>()),
        u("unknowns", ids.iter().map(|x| x.1.form.len(x.1.beams.len()) as u32).collect()),
        f("rms_residual_mm", ids.iter().map(|x| x.1.rms_mm).collect()),
        u("iterations", ids.iter().map(|x| x.1.iterations as u32).collect()),
        f("condition", ids.iter().map(|x| x.1.condition).collect()),
        f("worst_point_error_at_100mm_mm", ids.iter().map(|x| worst(&x.1.point_error_mm)).collect()),
        f("worst_angle_error_deg", ids.iter().map(|x| worst(&x.1.angle_error_deg)).collect()),
        f("measuring_error_max_mm", acc.iter().map(|a| a.0).collect()),
        f("measuring_error_mean_mm", acc.iter().map(|a| a.1).collect()),
        f("measuring_error_rms_mm", acc.iter().map(|a| a.2).collect()),
        u("fits_residual_below_30um", ids.iter().map(|x| x.1.fit_residual_max_mm.iter().filter(|v| **v < 0.03).count() as u32).collect()),
        u("fits", ids.iter().map(|x| x.1.fit_residual_max_mm.len() as u32).collect()),
        Column::new("pso_rms_residual_mm".into(), ids.iter().map(|x| (x.0 == "pso_lm_paper").then_some(h.pso_rms_mm)).collect::<Vec<_>>()),
    ]
}

/// `table6.parquet`: per point P1-P5, the published AP before and after calibration beside
/// calsim's before and, per selection, after (`after_<selection>_mm`, the median over the
/// repetitions at the table set size), mm.
fn table6_columns(r: &SpmsResults, f: &SpmsFigures) -> Vec<Column> {
    let t6 = &published().spms_2023.iso9283;
    let mut cols = vec![
        Column::new("point".into(), (1..=5).map(|k| format!("P{k}")).collect::<Vec<_>>()),
        Column::new("published_before_mm".into(), t6.ap_before_mm.to_vec()),
        Column::new("before_mm".into(), r.before.ap_mm.to_vec()),
        Column::new("published_after_mm".into(), t6.ap_after_mm.to_vec()),
    ];
    for a in &f.after {
        cols.push(Column::new(format!("after_{}_mm", a.selection.label()).into(), a.ap_mm.to_vec()));
    }
    cols
}

/// `set_sizes.parquet`: per selection and set size, the identifications with a model, the median
/// O1 and condition, and the quartiles of the mean AP after calibration, mm.
fn set_columns(r: &SpmsResults, f: &SpmsFigures) -> Vec<Column> {
    let mut sizes: Vec<usize> = r.tasks.iter().map(|t| t.task.set_size).collect();
    sizes.sort_unstable();
    sizes.dedup();
    let keys: Vec<(Selection, usize)> = f.after.iter().flat_map(|a| sizes.iter().map(move |&n| (a.selection, n))).collect();
    let rows: Vec<[f64; 7]> = keys
        .iter()
        .map(|&(sel, n)| {
            let ts: Vec<_> = r.tasks.iter().filter(|t| t.task.selection == sel && t.task.set_size == n).collect();
            let mut means: Vec<f64> = ts.iter().filter_map(|t| t.iso.as_ref().map(|i| i.ap_summary().1)).collect();
            means.sort_by(f64::total_cmp);
            let q = |p: f64| crate::study::stats::quantile(&means, p);
            [
                means.len() as f64,
                ts.len() as f64,
                median(&ts.iter().map(|t| t.id.observability.o1).collect::<Vec<_>>()),
                median(&ts.iter().map(|t| t.id.condition_number).collect::<Vec<_>>()),
                q(0.5),
                q(0.75) - q(0.25),
                means.last().copied().unwrap_or(f64::NAN),
            ]
        })
        .collect();
    let f = |name: &str, k: usize| Column::new(name.into(), rows.iter().map(|x| x[k]).collect::<Vec<_>>());
    let u = |name: &str, k: usize| Column::new(name.into(), rows.iter().map(|x| x[k] as u32).collect::<Vec<_>>());
    vec![
        Column::new("selection".into(), keys.iter().map(|k| k.0.label()).collect::<Vec<_>>()),
        Column::new("set_size".into(), keys.iter().map(|k| k.1 as u32).collect::<Vec<_>>()),
        u("identified", 0),
        u("tasks", 1),
        f("median_o1", 2),
        f("median_condition", 3),
        f("median_mean_ap_mm", 4),
        f("iqr_mean_ap_mm", 5),
        f("worst_mean_ap_mm", 6),
    ]
}

/// `parameter_medians.parquet`: per identified parameter (in Table 4's unit), the nominal, the
/// truth and the median over the repetitions of the random sets at the table set size.
fn parameter_columns(r: &SpmsResults, f: &SpmsFigures) -> Vec<Column> {
    let ids = r.set.ids();
    let at_n = |j: usize| -> Vec<f64> {
        let unit = ids[j].unit();
        let random = r.tasks.iter().filter(|t| t.task.selection == Selection::Random && t.task.set_size == f.table_n);
        random.filter_map(|t| t.id.values[j]).map(|v| unit.from_internal(v)).collect()
    };
    let med: Vec<f64> = (0..ids.len()).map(|j| median(&at_n(j))).collect();
    let truth: Vec<f64> = ids.iter().map(|id| id.unit().from_internal(id.get(r.cell.robot.truth.data()))).collect();
    let nominal: Vec<f64> = ids.iter().map(|id| id.unit().from_internal(id.get(r.cell.nominal.data()))).collect();
    vec![
        Column::new("parameter".into(), ids.iter().map(|id| display_name(&id.name())).collect::<Vec<_>>()),
        Column::new("unit".into(), ids.iter().map(|id| id.unit().symbol()).collect::<Vec<_>>()),
        Column::new("set_size".into(), vec![f.table_n as u32; ids.len()]),
        Column::new("nominal".into(), nominal),
        Column::new("truth".into(), truth.clone()),
        Column::new("identified_median".into(), med.clone()),
        Column::new("identified_minus_truth".into(), med.iter().zip(&truth).map(|(m, t)| m - t).collect::<Vec<_>>()),
    ]
}

/// The summary: Tables 3 and 6 next to calsim's, the two beam solvers, random vs DETMAX sets, the
/// identified parameters and the timing, one section each, every figure read from the tables.
pub fn summary<'a>(s: &'a SpmsScenario, r: &'a SpmsResults, f: &SpmsFigures, checks: bool, parts: &mut Summary<'a>) {
    head(s, r, checks, parts);
    beams(s, r, parts);
    iso9283(f, parts);
    sets(parts);
    parameters(parts);
    let t = &r.timings;
    parts.text_from("tasks.parquet", move |row| {
        format!(
            "## Timing\n\nhead (build, PSO + LM, LM alone on both forms, accuracy) {:.3} s; cell and pool {:.3} s; pool \
             Jacobian {:.3} s; {} identifications with their ISO 9283 tests {:.3} s; study {:.3} s.\n\n",
            t.head_s,
            t.cell_s,
            t.pool_jacobian_s,
            row.height(),
            t.tasks_s,
            t.study_s
        )
    });
}

/// The title, the study in one line, the checks and the note on Table 6.
fn head(s: &SpmsScenario, r: &SpmsResults, checks: bool, parts: &mut Summary<'_>) {
    let study = &s.spec.study;
    let (selections, sizes, reps) = (study.selections.len(), study.set_sizes.len(), study.repetitions);
    let (pool, stations, rejected) = (r.cell.pool.len(), r.cell.stations.len(), r.cell.rejected);
    parts.text(format!("# {}: SPMS and ER20-C10 (Gao et al. 2023), seed {}\n\n", s.header.name, s.header.seed));
    parts.text_from("tasks.parquet", move |row| {
        format!(
            "{} identifications ({selections} selections x {sizes} set sizes x {reps} repetitions) from a pool of {pool} \
             configurations at {stations} station(s); {rejected} candidates rejected (no IK within limits, or a beam off the \
             sphere or out of range).\n\n",
            row.height()
        )
    });
    if checks {
        crate::study::check::checks_summary("Published figures", parts);
    }
    let t6 = &published().spms_2023.iso9283;
    let own = |ap: &[f64]| super::iso9283::summary(ap).2;
    parts.text(format!(
        "Table 6 prints an RMS ({:.3} before, {:.3} after) that is not the RMS of its own five AP values ({:.3} and {:.3}); \
         calsim's RMS is that of the five values.\n\n",
        t6.rms_before_mm,
        t6.rms_after_mm,
        own(&t6.ap_before_mm),
        own(&t6.ap_after_mm)
    ));
}

/// Beam identification (Table 2) and measuring accuracy (Table 3) from `heads.parquet`, the gains
/// from `beams.parquet`; the solvers' wall times (which no table holds: tables do not depend on
/// the run's timing) from the run.
fn beams<'a>(s: &'a SpmsScenario, r: &'a SpmsResults, parts: &mut Summary<'a>) {
    parts.text("## Beam identification (Table 2) and measuring accuracy (Table 3)\n\n");
    let h = &r.head;
    let seconds = [h.paper.seconds, h.paper_lm_only.seconds, h.minimal.seconds];
    let gains = |row: &Row<'_>| {
        let (head, beams) = (row.str("head"), row.of("beams.parquet", 0));
        let rows = (0..beams.height()).map(|i| beams.at(i)).filter(|b| b.str("head") == head);
        rows.map(|b| format!("{:.4}", b.f64("gain"))).collect::<Vec<_>>().join(" ")
    };
    let accuracy = |row: &Row<'_>| {
        let m = |q: &str| f3(row.f64(&format!("measuring_error_{q}_mm")));
        format!("{} / {} / {}", m("max"), m("mean"), m("rms"))
    };
    let cells = vec![
        cell("solver", |row| row.str("solver")),
        cell("unknowns", |row| row.u64("unknowns").to_string()),
        cell("rms residual, mm", |row| format!("{:.4}", row.f64("rms_residual_mm"))),
        cell("iterations", |row| row.u64("iterations").to_string()),
        cell("time, s", move |row| format!("{:.3}", seconds[row.index()])),
        cell("condition", |row| format!("{:.2e}", row.f64("condition"))),
        cell("worst beam point error at 100 mm, mm", |row| format!("{:.3}", row.f64("worst_point_error_at_100mm_mm"))),
        cell("worst direction error, deg", |row| format!("{:.3}", row.f64("worst_angle_error_deg"))),
        cell("gains", gains),
        cell("measuring error max / mean / RMS, mm", accuracy),
        cell("fits with residual < 0.03 mm", |row| format!("{} of {}", row.u64("fits_residual_below_30um"), row.u64("fits"))),
    ];
    parts.table("heads.parquet", Summary::all_rows(), cells);
    let (b, m) = (&s.spec.beams, &published().spms_2023.measuring_error);
    let (population, iterations, form, pso_s) = (b.pso_population, b.pso_iterations, b.calibration_form.label(), h.pso_s);
    parts.text_from("heads.parquet", move |row| {
        format!(
            "PSO alone ({population} particles, {iterations} iterations): rms {:.4} mm in {pso_s:.3} s. Published Table 3: {} / \
             {} / {} mm. The robot calibration measures with the `{form}` head.\n\n",
            row.f64("pso_rms_residual_mm"),
            m.max_mm,
            m.mean_mm,
            m.rms_mm
        )
    });
}

/// ISO 9283 absolute positioning (Table 6) from `table6.parquet`, RP before calibration from
/// `iso9283_before.parquet`.
fn iso9283(f: &SpmsFigures, parts: &mut Summary<'_>) {
    parts.text("## ISO 9283 absolute positioning (Table 6)\n\n");
    let mut cells = vec![
        cell("point", |r| r.str("point")),
        cell("published before", |r| format!("{:.3}", r.f64("published_before_mm"))),
        cell("calsim before", |r| f3(r.f64("before_mm"))),
        cell("published after", |r| format!("{:.3}", r.f64("published_after_mm"))),
    ];
    for label in f.after.iter().map(|a| a.selection.label()) {
        let column = format!("after_{label}_mm");
        cells.push(cell(format!("calsim after, {label}"), move |r| f3(r.f64(&column))));
    }
    parts.table("table6.parquet", Summary::all_rows(), cells);
    parts.text_from("parameter_medians.parquet", |r| {
        let rp = r.of("iso9283_before.parquet", 0);
        let rp: Vec<String> = (0..rp.height()).map(|k| format!("{:.3}", rp.at(k).f64("rp_mm"))).collect();
        format!(
            "After calibration: median over the repetitions with sets of {}. RP before calibration per point: {} mm.\n\n",
            r.u64("set_size"),
            rp.join(", ")
        )
    });
}

/// Random sets against DETMAX sets from `set_sizes.parquet`.
fn sets(parts: &mut Summary<'_>) {
    parts.text("## Random sets and DETMAX sets\n\n");
    let f3c = |name: &'static str| move |r: &Row<'_>| f3(r.f64(name));
    let cells = vec![
        cell("selection", |r| r.str("selection")),
        cell("n", |r| r.u64("set_size").to_string()),
        cell("identified", |r| format!("{} of {}", r.u64("identified"), r.u64("tasks"))),
        cell("median O1", |r| format!("{:.4}", r.f64("median_o1"))),
        cell("median condition", |r| format!("{:.0}", r.f64("median_condition"))),
        cell("median mean AP, mm", f3c("median_mean_ap_mm")),
        cell("IQR mean AP, mm", f3c("iqr_mean_ap_mm")),
        cell("worst mean AP, mm", f3c("worst_mean_ap_mm")),
    ];
    parts.table("set_sizes.parquet", Summary::all_rows(), cells);
}

/// The identified parameters at the table set size from `parameter_medians.parquet`.
fn parameters(parts: &mut Summary<'_>) {
    parts.text_from("parameter_medians.parquet", |r| {
        format!("## Identified parameters (random sets of {}: median over the repetitions)\n\n", r.u64("set_size"))
    });
    let f4 = |name: &'static str| move |r: &Row<'_>| format!("{:.4}", r.f64(name));
    let cells = vec![
        cell("parameter", |r| r.str("parameter")),
        cell("unit", |r| r.str("unit")),
        cell("nominal (Table 4)", f4("nominal")),
        cell("truth", f4("truth")),
        cell("identified (median)", f4("identified_median")),
        cell("identified - truth", |r| format!("{:+.4}", r.f64("identified_minus_truth"))),
    ];
    parts.table("parameter_medians.parquet", Summary::all_rows(), cells);
}
