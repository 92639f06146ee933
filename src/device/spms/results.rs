//! Result files of an SPMS study in `results/<scenario>/`: `beams.parquet`, `measurements.parquet`,
//! `tasks.parquet`, `parameters.parquet`, `iso9283_before.parquet`, the tables its summary shows
//! ([`super::summary`]), `manifest.json`, `summary.md`, the figures and, when asked, the recording. Written into a temporary directory renamed into place.

use polars::prelude::*;
use serde::Serialize;

use super::plots::SpmsPlotInputs;
use super::spec::SpmsScenario;
use super::study::{SpmsFigures, SpmsResults, SpmsTimings};
use crate::io::manifest::ScenarioHead;
use crate::io::results::{Head, Record, Results};
use crate::study::Selection;
use crate::study::check::Check;
use crate::study::published::published;
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
    super::summary::tables(r, f, &mut out)?;
    super::summary::summary(s, r, f, !checks.is_empty(), &mut out.summary);
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
