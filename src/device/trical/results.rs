//! Result files of a study in `results/<scenario>/`: `tasks.parquet`, `parameters.parquet`,
//! `validation_errors.parquet` (polars), the tables its summary shows ([`super::summary`]),
//! `manifest.json` and `summary.md`. Everything is written into a temporary directory beside the
//! destination, which is renamed into place at the end: an interrupted run leaves no half-written
//! result.

use polars::prelude::*;
use serde::Serialize;

use super::figures::Figures;
use super::plots::PlotInputs;
use super::spec::TricalScenario;
use super::study::StudyResults;
use crate::io::manifest::ScenarioHead;
use crate::io::results::{Head, Record, Results};
use crate::study::check::Check;
use crate::study::tables::{parameter_columns, task_columns};

/// Wall times of a run, s.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Timings {
    /// Cell, robot, instruments and campaign (pool and validation measured).
    pub campaign_s: f64,
    /// Of which: generating and measuring the identification pool.
    pub pool_s: f64,
    /// Pool Jacobian for DETMAX.
    pub pool_jacobian_s: f64,
    /// All identifications (DETMAX, identification, validation).
    pub tasks_s: f64,
    /// Whole study, campaign included (the results are written after the manifest is made).
    pub study_s: f64,
}

#[derive(Serialize)]
struct Fields<'a> {
    tasks: usize,
    set_sizes: Vec<u32>,
    repetitions: u32,
    timings: &'a Timings,
}

/// Optional outputs beside the tables.
#[derive(Default)]
pub struct Extras<'a> {
    /// Inputs of the figures; `None` draws none.
    pub plots: Option<PlotInputs>,
    /// Writes the Rerun recording to the path it is given; `None` records nothing.
    pub recording: Option<Record<'a>>,
}

/// What a run adds to its results: the figures and their checks, how it ran, optional outputs.
pub struct Report<'a> {
    /// The paper's figures.
    pub figures: &'a Figures,
    /// Their checks.
    pub checks: &'a [Check],
    /// Worker threads.
    pub threads: usize,
    /// Wall times.
    pub timings: &'a Timings,
    /// Command-line overrides of the scenario (`key`, `value`).
    pub overrides: &'a [(String, String)],
    /// The figures (PNG and SVG, embedded in `summary.md`) and the recording.
    pub extras: Extras<'a>,
}

/// The results of a study: the tables, the manifest's fields, the recording, the figures and the
/// summary.
pub fn results<'a>(scenario: &'a TricalScenario, r: &'a StudyResults, report: Report<'a>) -> std::io::Result<Results<'a>> {
    let Report { figures: f, checks, threads: _, timings, overrides, extras } = report;
    let h = &scenario.header;
    let mut out = Results::new(h.name.clone(), Head::Scenario(ScenarioHead::new(&h.name, &h.path, &h.text, h.seed, overrides)));
    tables(r, &mut out)?;
    out.fields(Fields {
        tasks: r.tasks.len(),
        set_sizes: scenario.study.set_sizes.clone(),
        repetitions: scenario.study.repetitions,
        timings,
    })?;
    if let Some(record) = extras.recording {
        out.record(record);
    }
    if let Some(p) = extras.plots {
        out.draw(Box::new(move |dir| super::plots::write_all(dir, r, &p)));
    }
    super::summary::figure_tables(r, f, true, &mut out)?;
    super::summary::trical_tables(scenario, r, f, &mut out)?;
    super::summary::trical(scenario, !checks.is_empty(), &mut out.summary);
    out.summary.figures("\n## Figures\n\nEach as PNG (shown) and SVG beside this file.\n\n");
    Ok(out)
}

/// The tables of a study validated on the tracker poses: `tasks.parquet`,
/// `compensated.parquet` (when the study ran the compensated validation), `parameters.parquet`
/// and `validation_errors.parquet`, in the order of the README's list of result files.
pub fn tables(r: &StudyResults, out: &mut Results<'_>) -> std::io::Result<()> {
    let t = &r.tasks;
    let f64c = |name: &str, v: Vec<f64>| Column::new(name.into(), v);
    let mut cols = task_columns(t.iter().map(|x| (&x.task, &x.id)));
    cols.extend([
        f64c("validation_mean_mm", t.iter().map(|x| x.validation.mean).collect()),
        f64c("validation_median_mm", t.iter().map(|x| x.validation.median).collect()),
        f64c("validation_std_mm", t.iter().map(|x| x.validation.std).collect()),
        f64c("validation_p95_mm", t.iter().map(|x| x.validation.p95).collect()),
        f64c("validation_max_mm", t.iter().map(|x| x.validation.max).collect()),
        f64c("validation_rms_mm", t.iter().map(|x| x.validation.rms).collect()),
    ]);
    out.table("tasks.parquet", cols)?;
    let comp: Vec<(&crate::device::trical::study::TaskResult, &crate::device::trical::study::Compensated)> =
        t.iter().filter_map(|x| x.compensated.as_ref().map(|c| (x, c))).collect();
    if !comp.is_empty() {
        let stat = |name: &str, g: fn(&crate::study::ErrorStats) -> f64| f64c(name, comp.iter().map(|(_, c)| g(&c.stats)).collect());
        out.table(
            "compensated.parquet",
            vec![
                Column::new("task".into(), comp.iter().map(|(x, _)| x.task.index as u32).collect::<Vec<_>>()),
                Column::new("set_size".into(), comp.iter().map(|(x, _)| x.task.set_size as u32).collect::<Vec<_>>()),
                stat("mean_mm", |s| s.mean),
                stat("median_mm", |s| s.median),
                stat("std_mm", |s| s.std),
                stat("p95_mm", |s| s.p95),
                stat("max_mm", |s| s.max),
                Column::new("targets_failed".into(), comp.iter().map(|(_, c)| c.failed as u32).collect::<Vec<_>>()),
            ],
        )?;
    }
    out.table("parameters.parquet", parameter_columns(&r.set, t.iter().map(|x| (&x.task, &x.id)), &r.truth, &r.start))?;
    out.table("validation_errors.parquet", validation_columns(r))?;
    Ok(())
}

/// `validation_errors.parquet`: every validation pose before calibration, then after each
/// identification validated at its poses.
fn validation_columns(r: &StudyResults) -> Vec<Column> {
    let (mut which, mut task, mut pose, mut error, mut dbase, mut dccz) = (vec![], vec![], vec![], vec![], vec![], vec![]);
    let mut push = |label: &str, tk: Option<u32>, errs: &[f64]| {
        for (k, e) in errs.iter().enumerate() {
            which.push(label.to_string());
            task.push(tk);
            pose.push(k as u32);
            error.push(*e);
            dbase.push(r.distance_to_base_mm[k]);
            dccz.push(r.distance_to_ccz_mm[k]);
        }
    };
    push("before", None, &r.before_errors);
    for x in &r.tasks {
        if let Some(errs) = &x.errors {
            push("after", Some(x.task.index as u32), errs);
        }
    }
    vec![
        Column::new("calibration".into(), which),
        Column::new("task".into(), task),
        Column::new("pose".into(), pose),
        Column::new("error_mm".into(), error),
        Column::new("distance_to_base_mm".into(), dbase),
        Column::new("distance_to_ccz_mm".into(), dccz),
    ]
}
