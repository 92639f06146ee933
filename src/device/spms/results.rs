//! Result files of an SPMS study in `results/<scenario>/`: `beams.parquet`, `measurements.parquet`,
//! `tasks.parquet`, `parameters.parquet`, `iso9283.parquet`, `manifest.json`, `summary.md`, the
//! figures and, when asked, the recording. Written into a temporary directory renamed into place.

use std::fmt::Write as _;

use polars::prelude::*;
use serde::Serialize;

use super::plots::SpmsPlotInputs;
use super::spec::SpmsScenario;
use super::study::{SpmsFigures, SpmsResults, SpmsTimings};
use crate::io::manifest::ScenarioHead;
use crate::io::results::{Head, Record, Results, Summary};
use crate::robot::params::display_name;
use crate::study::Selection;
use crate::study::check::Check;
use crate::study::check::checks_markdown;
use crate::study::published::published;
use crate::study::stats::median;
use crate::study::tables::{parameter_columns, task_columns};

#[derive(Serialize)]
struct Fields<'a> {
    kind: &'static str,
    tasks: usize,
    set_sizes: Vec<u32>,
    repetitions: u32,
    selections: Vec<String>,
    timings: &'a SpmsTimings,
}

/// Optional outputs beside the tables.
pub struct SpmsExtras<'a> {
    /// Draw the figures.
    pub plots: bool,
    /// Writes the Rerun recording to the path it is given; `None` records nothing.
    pub recording: Option<Record<'a>>,
    /// Worker threads (recorded in the manifest).
    pub threads: usize,
    /// Command-line overrides of the scenario (`key`, `value`).
    pub overrides: &'a [(String, String)],
}

/// The results of an SPMS study: the tables (README's list of result files), the manifest's
/// fields, the figures, the recording and the summary.
pub fn results<'a>(
    s: &'a SpmsScenario,
    r: &'a SpmsResults,
    f: &'a SpmsFigures,
    checks: &'a [Check],
    extras: SpmsExtras<'a>,
) -> std::io::Result<Results<'a>> {
    let head = ScenarioHead::new(&s.header.name, &s.header.path, &s.header.text, s.header.seed, extras.overrides);
    let mut out = Results::new(s.header.name.clone(), Head::Scenario(head));
    beam_tables(r, &mut out)?;
    task_tables(r, &mut out)?;
    out.fields(Fields {
        kind: "spms",
        tasks: r.tasks.len(),
        set_sizes: s.spec.study.set_sizes.clone(),
        repetitions: s.spec.study.repetitions,
        selections: s.spec.study.selections.iter().map(|s| s.label().to_string()).collect(),
        timings: &r.timings,
    })?;
    if let Some(record) = extras.recording {
        out.record(record);
    }
    if extras.plots {
        out.draw(Box::new(move |dir| super::plots::write(dir, &plot_inputs(r, f))));
    }
    summary(s, r, f, checks, &mut out.summary);
    out.summary.figures("## Figures\n\n");
    Ok(out)
}

/// `beams.parquet` (the truth and every identification of the head), then `measurements.parquet`.
fn beam_tables(r: &SpmsResults, r_: &mut Results<'_>) -> std::io::Result<()> {
    let h = &r.head;
    // Beams: truth and both identifications.
    let (mut which, mut beam, mut px, mut py, mut pz, mut dx, mut dy, mut dz, mut gain, mut perr, mut aerr) =
        (vec![], vec![], vec![], vec![], vec![], vec![], vec![], vec![], vec![], vec![], vec![]);
    let truth: Vec<_> = h.spms.sensors.iter().map(|s| s.beam).collect();
    let mut push = |label: &str, beams: &[crate::device::spms::Beam], gains: &[f64], pe: &[f64], ae: &[f64]| {
        for (k, b) in beams.iter().enumerate() {
            which.push(label.to_string());
            beam.push(k as u32 + 1);
            px.push(b.p.x);
            py.push(b.p.y);
            pz.push(b.p.z);
            dx.push(b.dir.x);
            dy.push(b.dir.y);
            dz.push(b.dir.z);
            gain.push(gains[k]);
            perr.push(pe[k]);
            aerr.push(ae[k]);
        }
    };
    let ones = vec![1.0; truth.len()];
    let zeros = vec![0.0; truth.len()];
    push("truth", &truth, &ones, &zeros, &zeros);
    for (label, id) in [("pso_lm_paper", &h.paper), ("lm_paper", &h.paper_lm_only), ("lm_minimal", &h.minimal)] {
        push(label, &id.beams, &id.gains, &id.point_error_mm, &id.angle_error_deg);
    }
    let c = |n: &str, v: Vec<f64>| Column::new(n.into(), v);
    r_.table(
        "beams.parquet",
        vec![
            Column::new("head".into(), which),
            Column::new("beam".into(), beam),
            c("p_x_mm", px),
            c("p_y_mm", py),
            c("p_z_mm", pz),
            c("dir_x", dx),
            c("dir_y", dy),
            c("dir_z", dz),
            c("gain", gain),
            c("point_error_at_100mm_mm", perr),
            c("angle_error_deg", aerr),
        ],
    )?;
    measurement_table(r, r_)
}

/// `measurements.parquet`: per accuracy measurement and identified head.
fn measurement_table(r: &SpmsResults, r_: &mut Results<'_>) -> std::io::Result<()> {
    let h = &r.head;
    let c = |n: &str, v: Vec<f64>| Column::new(n.into(), v);
    let (mut which, mut sample, mut error, mut resid) = (vec![], vec![], vec![], vec![]);
    for (label, id) in [("pso_lm_paper", &h.paper), ("lm_paper", &h.paper_lm_only), ("lm_minimal", &h.minimal)] {
        for (k, (e, res)) in id.measuring_error_mm.iter().zip(&id.fit_residual_max_mm).enumerate() {
            which.push(label.to_string());
            sample.push(k as u32 + 1);
            error.push(*e);
            resid.push(*res);
        }
    }
    r_.table(
        "measurements.parquet",
        vec![
            Column::new("head".into(), which),
            Column::new("sample".into(), sample),
            c("measuring_error_mm", error),
            c("fit_residual_max_mm", resid),
        ],
    )?;

    Ok(())
}

/// `tasks.parquet`, `parameters.parquet` and `iso9283_before.parquet`.
fn task_tables(r: &SpmsResults, r_: &mut Results<'_>) -> std::io::Result<()> {
    let c = |n: &str, v: Vec<f64>| Column::new(n.into(), v);
    let t = &r.tasks;
    let opt = |n: &str, v: Vec<Option<f64>>| Column::new(n.into(), v);
    let mut cols = task_columns(t.iter().map(|x| (&x.task, &x.id)));
    for k in 0..5 {
        cols.push(opt(&format!("ap_p{}_mm", k + 1), t.iter().map(|x| x.iso.as_ref().map(|i| i.ap_mm[k])).collect()));
    }
    for k in 0..5 {
        cols.push(opt(&format!("rp_p{}_mm", k + 1), t.iter().map(|x| x.iso.as_ref().map(|i| i.rp_mm[k])).collect()));
    }
    cols.push(opt("ap_max_mm", t.iter().map(|x| x.iso.as_ref().map(|i| i.ap_summary().0)).collect()));
    cols.push(opt("ap_mean_mm", t.iter().map(|x| x.iso.as_ref().map(|i| i.ap_summary().1)).collect()));
    cols.push(opt("ap_rms_mm", t.iter().map(|x| x.iso.as_ref().map(|i| i.ap_summary().2)).collect()));
    r_.table("tasks.parquet", cols)?;
    r_.table("parameters.parquet", parameter_columns(&r.set, t.iter().map(|x| (&x.task, &x.id)), &r.cell.robot.truth, &r.cell.nominal))?;
    let (mut which, mut point, mut ap, mut rp) = (vec![], vec![], vec![], vec![]);
    for k in 0..5 {
        which.push("before".to_string());
        point.push(format!("P{}", k + 1));
        ap.push(r.before.ap_mm[k]);
        rp.push(r.before.rp_mm[k]);
    }
    r_.table(
        "iso9283_before.parquet",
        vec![Column::new("calibration".into(), which), Column::new("point".into(), point), c("ap_mm", ap), c("rp_mm", rp)],
    )?;

    Ok(())
}

/// What the figures show.
fn plot_inputs<'a>(r: &'a SpmsResults, f: &'a SpmsFigures) -> SpmsPlotInputs<'a> {
    let (h, t) = (&r.head, &r.tasks);
    let mut sizes: Vec<usize> = t.iter().map(|x| x.task.set_size).collect();
    sizes.sort_unstable();
    sizes.dedup();
    let by_size = |sel: Selection| -> Vec<(usize, Vec<f64>)> {
        sizes
            .iter()
            .map(|&n| {
                (
                    n,
                    t.iter()
                        .filter(|x| x.task.selection == sel && x.task.set_size == n)
                        .filter_map(|x| x.iso.as_ref().map(|i| i.ap_summary().1))
                        .collect(),
                )
            })
            .collect()
    };
    SpmsPlotInputs {
        residuals: [&h.paper.fit_residual_max_mm, &h.minimal.fit_residual_max_mm],
        measuring: [&h.paper.measuring_error_mm, &h.minimal.measuring_error_mm],
        ap_published: [published().spms_2023.iso9283.ap_before_mm, published().spms_2023.iso9283.ap_after_mm],
        ap_before: r.before.ap_mm,
        ap_after: f.after.iter().map(|a| (a.selection.label().to_string(), a.ap_mm)).collect(),
        ap_mean_by_size: f.after.iter().map(|a| (a.selection.label().to_string(), by_size(a.selection))).collect(),
        table_n: f.table_n,
    }
}

fn f3(x: f64) -> String {
    if x.is_finite() { format!("{x:.3}") } else { "-".into() }
}

/// The summary: Tables 3 and 6 next to calsim's, the two beam solvers, random vs DETMAX sets, the
/// identified parameters and the timing, one section each.
pub fn summary(s: &SpmsScenario, r: &SpmsResults, f: &SpmsFigures, checks: &[Check], parts: &mut Summary<'_>) {
    parts.text(head(s, r, checks)).text(beams(s, r)).text(iso9283(r, f)).text(sets(r, f)).text(parameters(r, f)).text(timing(r));
}

/// The title, the study in one line, the checks and the note on Table 6.
fn head(s: &SpmsScenario, r: &SpmsResults, checks: &[Check]) -> String {
    let mut o = String::new();
    let _ = writeln!(o, "# {}: SPMS and ER20-C10 (Gao et al. 2023), seed {}\n", s.header.name, s.header.seed);
    let _ = writeln!(
        o,
        "{} identifications ({} selections x {} set sizes x {} repetitions) from a pool of {} configurations \
             at {} station(s); {} candidates rejected (no IK within limits, or a beam off the sphere or out of \
             range).\n",
        r.tasks.len(),
        s.spec.study.selections.len(),
        s.spec.study.set_sizes.len(),
        s.spec.study.repetitions,
        r.cell.pool.len(),
        r.cell.stations.len(),
        r.cell.rejected
    );
    o.push_str(&checks_markdown("Published figures", checks));
    let t6 = &published().spms_2023.iso9283;
    let (own_before, own_after) =
        (crate::device::spms::iso9283::summary(&t6.ap_before_mm).2, crate::device::spms::iso9283::summary(&t6.ap_after_mm).2);
    let _ = writeln!(
        o,
        "\nTable 6 prints an RMS ({:.3} before, {:.3} after) that is not the RMS of its own five AP values \
             ({own_before:.3} and {own_after:.3}); calsim's RMS is that of the five values.\n",
        t6.rms_before_mm, t6.rms_after_mm
    );

    o
}

/// Beam identification (Table 2) and measuring accuracy (Table 3).
fn beams(s: &SpmsScenario, r: &SpmsResults) -> String {
    let mut o = String::new();
    let h = &r.head;
    let _ = writeln!(o, "## Beam identification (Table 2) and measuring accuracy (Table 3)\n");
    let _ = writeln!(
        o,
        "| solver | unknowns | rms residual, mm | iterations | time, s | condition | worst beam point error \
             at 100 mm, mm | worst direction error, deg | gains | measuring error max / mean / RMS, mm | fits \
             with residual < 0.03 mm |"
    );
    let _ = writeln!(o, "|---|---|---|---|---|---|---|---|---|---|---|");
    for id in [&h.paper, &h.paper_lm_only, &h.minimal] {
        let (mx, mean, rms) = crate::device::spms::iso9283::summary(&id.measuring_error_mm);
        let below = id.fit_residual_max_mm.iter().filter(|x| **x < 0.03).count();
        let _ = writeln!(
            o,
            "| {} | {} | {:.4} | {} | {:.3} | {:.2e} | {:.3} | {:.3} | {} | {} / {} / {} | {} of {} |",
            id.label,
            id.form.len(id.beams.len()),
            id.rms_mm,
            id.iterations,
            id.seconds,
            id.condition,
            id.point_error_mm.iter().fold(0.0, |a: f64, b| a.max(*b)),
            id.angle_error_deg.iter().fold(0.0, |a: f64, b| a.max(*b)),
            id.gains.iter().map(|g| format!("{g:.4}")).collect::<Vec<_>>().join(" "),
            f3(mx),
            f3(mean),
            f3(rms),
            below,
            id.fit_residual_max_mm.len()
        );
    }
    let _ = writeln!(
        o,
        "\nPSO alone ({} particles, {} iterations): rms {:.4} mm in {:.3} s. Published Table 3: {} / {} / {} mm. \
             The robot calibration measures with the `{}` head.\n",
        s.spec.beams.pso_population,
        s.spec.beams.pso_iterations,
        h.pso_rms_mm,
        h.pso_s,
        published().spms_2023.measuring_error.max_mm,
        published().spms_2023.measuring_error.mean_mm,
        published().spms_2023.measuring_error.rms_mm,
        s.spec.beams.calibration_form.label()
    );

    o
}

/// ISO 9283 absolute positioning (Table 6).
fn iso9283(r: &SpmsResults, f: &SpmsFigures) -> String {
    let mut o = String::new();
    let t6 = &published().spms_2023.iso9283;
    let _ = writeln!(o, "## ISO 9283 absolute positioning (Table 6)\n");
    let _ = write!(o, "| point | published before | calsim before | published after |");
    for a in &f.after {
        let _ = write!(o, " calsim after, {} |", a.selection.label());
    }
    let _ = write!(o, "\n|---|---|---|---|");
    for _ in &f.after {
        let _ = write!(o, "---|");
    }
    let _ = writeln!(o);
    for k in 0..5 {
        let _ = write!(o, "| P{} | {:.3} | {} | {:.3} |", k + 1, t6.ap_before_mm[k], f3(f.before.0[k]), t6.ap_after_mm[k]);
        for a in &f.after {
            let _ = write!(o, " {} |", f3(a.ap_mm[k]));
        }
        let _ = writeln!(o);
    }
    let _ = writeln!(
        o,
        "\nAfter calibration: median over the repetitions with sets of {}. RP before calibration per point: {} mm.\n",
        f.table_n,
        r.before.rp_mm.iter().map(|v| format!("{v:.3}")).collect::<Vec<_>>().join(", ")
    );

    o
}

/// Random sets against DETMAX sets.
fn sets(r: &SpmsResults, f: &SpmsFigures) -> String {
    let mut o = String::new();
    let _ = writeln!(
        o,
        "## Random sets and DETMAX sets\n\n| selection | n | identified | median O1 | median condition | \
             median mean AP, mm | IQR mean AP, mm | worst mean AP, mm |\n|---|---|---|---|---|---|---|---|"
    );
    let mut sizes: Vec<usize> = r.tasks.iter().map(|t| t.task.set_size).collect();
    sizes.sort_unstable();
    sizes.dedup();
    for a in &f.after {
        for &n in &sizes {
            let ts: Vec<_> = r.tasks.iter().filter(|t| t.task.selection == a.selection && t.task.set_size == n).collect();
            let means: Vec<f64> = ts.iter().filter_map(|t| t.iso.as_ref().map(|i| i.ap_summary().1)).collect();
            let mut sorted = means.clone();
            sorted.sort_by(f64::total_cmp);
            let q = |p: f64| crate::study::stats::quantile(&sorted, p);
            let _ = writeln!(
                o,
                "| {} | {} | {} of {} | {:.4} | {:.0} | {} | {} | {} |",
                a.selection.label(),
                n,
                means.len(),
                ts.len(),
                median(&ts.iter().map(|t| t.id.observability.o1).collect::<Vec<_>>()),
                median(&ts.iter().map(|t| t.id.condition_number).collect::<Vec<_>>()),
                f3(q(0.5)),
                f3(q(0.75) - q(0.25)),
                f3(sorted.last().copied().unwrap_or(f64::NAN))
            );
        }
    }
    o
}

/// The identified parameters at the table set size.
fn parameters(r: &SpmsResults, f: &SpmsFigures) -> String {
    let mut o = String::new();
    let tn = f.table_n;
    let ids = r.set.ids();
    let _ = writeln!(
        o,
        "\n## Identified parameters (random sets of {tn}: median over the repetitions)\n\n| parameter | unit \
             | nominal (Table 4) | truth | identified (median) | identified - truth |\n|---|---|---|---|---|---|"
    );
    for (j, id) in ids.iter().enumerate() {
        let unit = id.unit();
        let vals: Vec<f64> = r
            .tasks
            .iter()
            .filter(|t| t.task.selection == Selection::Random && t.task.set_size == tn)
            .filter_map(|t| t.id.values[j])
            .map(|v| unit.from_internal(v))
            .collect();
        let med = median(&vals);
        let truth = unit.from_internal(id.get(r.cell.robot.truth.data()));
        let nominal = unit.from_internal(id.get(r.cell.nominal.data()));
        let _ = writeln!(
            o,
            "| {} | {} | {:.4} | {:.4} | {:.4} | {:+.4} |",
            display_name(&id.name()),
            unit.symbol(),
            nominal,
            truth,
            med,
            med - truth
        );
    }
    o
}

/// What took how long.
fn timing(r: &SpmsResults) -> String {
    let mut o = String::new();
    let t = &r.timings;
    let _ = writeln!(
        o,
        "\n## Timing\n\nhead (build, PSO + LM, LM alone on both forms, accuracy) {:.3} s; cell and pool {:.3} \
             s; pool Jacobian {:.3} s; {} identifications with their ISO 9283 tests {:.3} s; study {:.3} s.\n",
        t.head_s,
        t.cell_s,
        t.pool_jacobian_s,
        r.tasks.len(),
        t.tasks_s,
        t.study_s
    );
    o
}
