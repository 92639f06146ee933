//! Result files of a study in `results/<scenario>/`: `tasks.parquet`, `parameters.parquet`,
//! `validation_errors.parquet` (polars), `manifest.json` and `summary.md`. Everything is written
//! into a temporary directory beside the destination, which is renamed into place at the end: an
//! interrupted run leaves no half-written result.

use std::fmt::Write as _;

use polars::prelude::*;
use serde::Serialize;

use super::figures::Figures;
use super::plots::PlotInputs;
use super::spec::TricalScenario;
use super::study::StudyResults;
use crate::io::manifest::ScenarioHead;
use crate::io::results::{Head, Record, Results};
use crate::study::check::{Check, checks_markdown};
use crate::study::published::published;
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
    out.summary.text(summary(scenario, r, f, checks));
    out.summary.figures("\n## Figures\n\nEach as PNG (shown) and SVG beside this file.\n\n");
    Ok(out)
}

/// The tables of a study validated on the tracker poses: `tasks.parquet`,
/// `compensated.parquet` (when the study ran the compensated validation), `parameters.parquet`
/// and `validation_errors.parquet`.
///
/// Long by design: one block per table, in the order of the README's list of result files.
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
    for x in t {
        if let Some(errs) = &x.errors {
            push("after", Some(x.task.index as u32), errs);
        }
    }
    out.table(
        "validation_errors.parquet",
        vec![
            Column::new("calibration".into(), which),
            Column::new("task".into(), task),
            Column::new("pose".into(), pose),
            Column::new("error_mm".into(), error),
            Column::new("distance_to_base_mm".into(), dbase),
            Column::new("distance_to_ccz_mm".into(), dccz),
        ],
    )?;
    Ok(())
}

/// The summary: the paper's Tables 7 and 8 and before/after figures next to calsim's.
///
/// Each identified parameter's standard deviation (in the unit Table 7 shows) from the fit of the
/// representative set at `n`: `sigma^2 (J^T J)^-1` with sigma from the fit's residuals, as `calsim
/// export` writes it. `None` when that set cannot be refitted or its covariance is singular.
fn fit_std(scenario: &TricalScenario, r: &StudyResults, n: usize) -> Option<Vec<f64>> {
    use crate::device::Scenario as _;
    let (index, _) = super::figures::representative(r, n)?;
    let refit = scenario.refit(index).ok()??;
    let model = refit.model?;
    let (count, m) = (refit.observations.len(), refit.set.len());
    let sigma = crate::study::prediction::noise_estimate(refit.residual_rms_mm, count, m);
    let qs: Vec<_> = refit.observations.iter().map(|o| o.q).collect();
    let cov = crate::identify::observability::parameter_covariance(&model, &refit.set, &qs, sigma)?;
    Some(refit.set.ids().iter().enumerate().map(|(j, id)| id.unit().from_internal(cov[(j, j)].max(0.0).sqrt())).collect())
}

/// Long by design: the summary document top to bottom, one block per section.
pub fn summary(scenario: &TricalScenario, r: &StudyResults, f: &Figures, checks: &[Check]) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# {}: calsim against the published figures\n", scenario.header.name);
    let _ = writeln!(
        s,
        "Seed {}, {} identifications ({} set sizes x {} repetitions), DETMAX on O1 over a pool of {}, validation on {} poses.\n",
        scenario.header.seed,
        r.tasks.len(),
        scenario.study.set_sizes.len(),
        scenario.study.repetitions,
        scenario.experiment.campaign.pool_per_sphere as usize * scenario.experiment.cell.spheres_w_mm.len(),
        r.before_errors.len()
    );
    s.push_str(&checks_markdown("Published versus reproduced", checks));
    let _ = writeln!(
        s,
        "\nAfter-calibration figures are medians over the {} repetitions at n = {} of each identification's statistic over the validation poses.",
        scenario.study.repetitions, f.table_n
    );
    let (pb, t8) = (&published().trical_2018.before_calibration, published().trical_2018.table8("TriCal"));
    let _ =
        writeln!(s, "\n## Errors before and after calibration (mm)\n\n| | mean | median | std | p95 | max |\n|---|---|---|---|---|---|");
    let _ = writeln!(
        s,
        "| before (paper: mean {}, max {}) | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} |",
        pb.mean_mm, pb.max_mm, f.before.mean, f.before.median, f.before.std, f.before.p95, f.before.max
    );
    let _ = writeln!(
        s,
        "| after, n = {} (median over repetitions; paper Table 8: median {}, std {}, max {}) | {:.3} | {:.3} | {:.3} | - | {:.3} |",
        f.table_n, t8.median_mm, t8.std_mm, t8.max_mm, f.after_mean, f.after_median, f.after_std, f.after_max
    );
    let comp: Vec<&crate::device::trical::study::Compensated> = r.tasks.iter().filter_map(|x| x.compensated.as_ref()).collect();
    if !comp.is_empty() {
        let med =
            |g: fn(&crate::study::ErrorStats) -> f64| crate::study::stats::median(&comp.iter().map(|c| g(&c.stats)).collect::<Vec<_>>());
        let failed: usize = comp.iter().map(|c| c.failed).sum();
        let _ = writeln!(
            s,
            "| after, n = {}, compensated targets (median over repetitions; {failed} targets without joint values) | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} |",
            f.table_n,
            med(|s| s.mean),
            med(|s| s.median),
            med(|s| s.std),
            med(|s| s.p95),
            med(|s| s.max)
        );
        let _ = writeln!(
            s,
            "\nCompensated targets: each validation TCP of the model before calibration as a Cartesian target, the joint values \
             that put the identified model there, the robot moved there and measured by the tracker (`compensated.parquet`)."
        );
    }
    let _ = writeln!(s, "\n## Table 7: identified parameters over the sets of {}\n", f.table_n);
    let fit = fit_std(scenario, r, f.table_n);
    if fit.is_some() {
        let _ = writeln!(
            s,
            "A parameter whose interval (its mean +- 2 standard deviations of the representative set's fit, sigma^2 (J^T J)^-1 \
             with sigma from the fit's residuals) holds zero, 2 standard deviations larger than its value, is not determined by \
             the sets: it is shown as such, not compared with the truth.\n"
        );
    }
    let _ = writeln!(
        s,
        "| parameter | unit | truth | mean | std | min | max | paper mean | paper std | std within x3 | mean \
             within 3 std |\n|---|---|---|---|---|---|---|---|---|---|---|"
    );
    for (j, p) in f.table7.iter().enumerate() {
        if let Some(half) = fit.as_ref().and_then(|v| v.get(j)).map(|sd| 2.0 * sd)
            && (half.is_nan() || half >= p.mean.abs())
        {
            let (pm, ps) = p.published.map(|(m, sd)| (format!("{m:.3}"), format!("{sd:.3}"))).unwrap_or(("-".into(), "-".into()));
            let _ = writeln!(
                s,
                "| {} | {} | {:.4} | not determined ({:.4} +- {:.4}) | {:.4} | {:.4} | {:.4} | {} | {} | - | - |",
                p.name, p.unit, p.truth, p.mean, half, p.std, p.min, p.max, pm, ps
            );
            continue;
        }
        let (pm, ps) = p.published.map(|(m, sd)| (format!("{m:.3}"), format!("{sd:.3}"))).unwrap_or(("-".into(), "-".into()));
        let yes = |b: Option<bool>| match b {
            Some(true) => "yes",
            Some(false) => "no",
            None => "-",
        };
        let _ = writeln!(
            s,
            "| {} | {} | {:.4} | {:.4} | {:.4} | {:.4} | {:.4} | {} | {} | {} | {} |",
            p.name,
            p.unit,
            p.truth,
            p.mean,
            p.std,
            p.min,
            p.max,
            pm,
            ps,
            yes(p.std_within_factor3()),
            yes(p.mean_within_3std())
        );
    }
    let _ = writeln!(
        s,
        "\n## Figs. 8-9: validation error per set size\n\n| n | median of mean (mm) | IQR of mean (mm) | \
             median of std (mm) | not converged |\n|---|---|---|---|---|"
    );
    for z in &f.sizes {
        let _ =
            writeln!(s, "| {} | {:.4} | {:.4} | {:.4} | {} |", z.n, z.median_of_means, z.iqr_of_means, z.median_of_stds, z.not_converged);
    }
    let _ = writeln!(
        s,
        "\nPearson r of the error after calibration over the representative set of {n} (the paper's Figs. 11-12 show one set): \
         against the distance to the base (Fig. 11) {:.3}, against the distance to the centre of the calibration zone (Fig. 12) {:.3}. \
         Over every set of {n} pooled: {:.3} and {:.3}.",
        f.r_base,
        f.r_ccz,
        f.r_base_pooled,
        f.r_ccz_pooled,
        n = f.table_n
    );
    s
}
