//! Result files of a study in `results/<scenario>/`: `tasks.parquet`, `parameters.parquet`,
//! `validation_errors.parquet` (polars), `manifest.json` and `summary.md`. Everything is written
//! into a temporary directory beside the destination, which is renamed into place at the end: an
//! interrupted run leaves no half-written result.

use std::fmt::Write as _;
use std::fs;
use std::path::{Path, PathBuf};

use polars::prelude::*;
use serde::Serialize;
use sha2::{Digest, Sha256};

use crate::io::plots::{PlotInputs, Written};
use crate::io::scenario::Scenario;
use crate::robot::{ParamSet, RobotModel};
use crate::study::check::Check;
use crate::study::figures::Figures;
use crate::study::published::published;
use crate::study::{Identified, StudyResults, Task};

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

/// Where a result came from: the head of every `manifest.json`.
#[derive(Serialize)]
pub(crate) struct Provenance<'a> {
    scenario: &'a str,
    scenario_path: String,
    scenario_sha256: String,
    seed: u64,
    threads: usize,
    crate_version: &'static str,
    git_commit: String,
}

impl<'a> Provenance<'a> {
    /// The provenance of a run of the scenario `name` read from `path` with `text`.
    pub(crate) fn new(name: &'a str, path: &Path, text: &str, seed: u64, threads: usize) -> Self {
        Self {
            scenario: name,
            scenario_path: path.display().to_string(),
            scenario_sha256: format!("{:x}", Sha256::digest(text.as_bytes())),
            seed,
            threads,
            crate_version: env!("CARGO_PKG_VERSION"),
            git_commit: git_commit(),
        }
    }
}

/// The sha256 of every result table (`*.parquet`) in `dir`, by file name: two runs gave the same
/// results when these agree (the tables carry no wall-clock value).
pub(crate) fn table_hashes(dir: &Path) -> std::io::Result<std::collections::BTreeMap<String, String>> {
    let mut out = std::collections::BTreeMap::new();
    for entry in fs::read_dir(dir)? {
        let path = entry?.path();
        if path.extension().is_some_and(|e| e == "parquet") {
            let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            out.insert(name, format!("{:x}", Sha256::digest(fs::read(&path)?)));
        }
    }
    Ok(out)
}

#[derive(Serialize)]
struct Manifest<'a> {
    #[serde(flatten)]
    provenance: Provenance<'a>,
    tables_sha256: std::collections::BTreeMap<String, String>,
    tasks: usize,
    set_sizes: Vec<u32>,
    repetitions: u32,
    timings: &'a Timings,
}

fn git_commit() -> String {
    std::process::Command::new("git")
        .args(["rev-parse", "HEAD"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .unwrap_or_else(|| "unknown".into())
}

pub(crate) fn err(e: impl std::fmt::Display) -> std::io::Error {
    std::io::Error::other(e.to_string())
}

/// The columns every study's `tasks.parquet` starts with: where the task sits in the grid, the set
/// chosen and how the fit ended.
pub(crate) fn task_columns<'a>(rows: impl Iterator<Item = (&'a Task, &'a Identified)> + Clone) -> Vec<Column> {
    let u32c = |name: &str, f: &dyn Fn(&Task, &Identified) -> u32| {
        Column::new(name.into(), rows.clone().map(|(t, i)| f(t, i)).collect::<Vec<_>>())
    };
    let f64c = |name: &str, f: &dyn Fn(&Identified) -> f64| Column::new(name.into(), rows.clone().map(|(_, i)| f(i)).collect::<Vec<_>>());
    let strc = |name: &str, f: &dyn Fn(&Task, &Identified) -> String| {
        Column::new(name.into(), rows.clone().map(|(t, i)| f(t, i)).collect::<Vec<_>>())
    };
    vec![
        u32c("task", &|t, _| t.index as u32),
        strc("selection", &|t, _| t.selection.label().to_string()),
        u32c("set_size", &|t, _| t.set_size as u32),
        u32c("repetition", &|t, _| t.repetition as u32),
        f64c("o1", &|i| i.observability.o1),
        f64c("o2", &|i| i.observability.o2),
        f64c("o3", &|i| i.observability.o3),
        f64c("o4", &|i| i.observability.o4),
        f64c("o5", &|i| i.observability.o5),
        f64c("condition_number", &|i| i.condition_number),
        strc("outcome", &|_, i| i.outcome.label().to_string()),
        strc("unidentifiable", &|_, i| i.outcome.unidentifiable().join(" ")),
        u32c("iterations", &|_, i| i.iterations as u32),
        u32c("detmax_steps", &|_, i| i.detmax_steps as u32),
        f64c("residual_rms_mm", &|i| i.residual_rms_mm),
    ]
}

/// `parameters.parquet` of any study: one row per task and identified parameter, in the unit of the
/// paper's tables, beside the truth and the nominal (start) value.
pub(crate) fn parameter_columns<'a>(
    set: &ParamSet,
    rows: impl Iterator<Item = (&'a Task, &'a Identified)>,
    truth: &RobotModel,
    nominal: &RobotModel,
) -> Vec<Column> {
    let ids = set.ids();
    let in_unit = |id: &crate::robot::ParamId, m: &RobotModel| id.unit().from_internal(id.get(m.data()));
    let (truth_v, nominal_v): (Vec<f64>, Vec<f64>) = ids.iter().map(|id| (in_unit(id, truth), in_unit(id, nominal))).unzip();
    let (mut task, mut param, mut unit, mut value, mut tv, mut nv) = (vec![], vec![], vec![], vec![], vec![], vec![]);
    for (t, x) in rows {
        for (j, id) in ids.iter().enumerate() {
            task.push(t.index as u32);
            param.push(id.name());
            unit.push(id.unit().symbol().to_string());
            value.push(x.values[j].map(|v| id.unit().from_internal(v)));
            tv.push(truth_v[j]);
            nv.push(nominal_v[j]);
        }
    }
    vec![
        Column::new("task".into(), task),
        Column::new("parameter".into(), param),
        Column::new("unit".into(), unit),
        Column::new("identified".into(), value),
        Column::new("truth".into(), tv),
        Column::new("nominal".into(), nv),
    ]
}

/// The published-versus-reproduced table of a summary, under a heading.
pub(crate) fn checks_markdown(heading: &str, checks: &[Check]) -> String {
    let mut s = format!("## {heading}\n\n| figure | published | calsim | band | result |\n|---|---|---|---|---|\n");
    for c in checks {
        let v = if c.pass == Some(false) { "**miss**" } else { c.verdict() };
        let _ = writeln!(s, "| {} | {} | {} | {} | {} |", c.figure, c.published, c.reproduced, c.band, v);
    }
    s
}

pub(crate) fn parquet(dir: &Path, name: &str, columns: Vec<Column>) -> std::io::Result<()> {
    let mut df = DataFrame::new_infer_height(columns).map_err(err)?;
    let file = fs::File::create(dir.join(name))?;
    ParquetWriter::new(file).finish(&mut df).map_err(err)?;
    Ok(())
}

/// Writes a recording to the path it is given.
pub type Recorder<'a> = &'a dyn Fn(&Path) -> Result<(), String>;

/// Optional outputs beside the tables.
#[derive(Default)]
pub struct Extras<'a> {
    /// Inputs of the figures; `None` draws none.
    pub plots: Option<&'a PlotInputs>,
    /// Writes the Rerun recording to the path it is given; `None` records nothing.
    pub recording: Option<Recorder<'a>>,
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
    /// The figures (PNG and SVG, embedded in `summary.md`) and the recording.
    pub extras: Extras<'a>,
}

/// Writes every result file of `results` into `out/<scenario name>`, replacing what was there.
pub fn write(out: &Path, scenario: &Scenario, results: &StudyResults, report: &Report<'_>) -> std::io::Result<PathBuf> {
    write_atomically(out, &scenario.name, |tmp| write_into(tmp, scenario, results, report))
}

pub(crate) use crate::io::out_dir::write_atomically;

fn write_into(dir: &Path, scenario: &Scenario, r: &StudyResults, report: &Report<'_>) -> std::io::Result<()> {
    let Report { figures: f, checks, threads, timings, ref extras } = *report;
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
    parquet(dir, "tasks.parquet", cols)?;
    let comp: Vec<(&crate::study::TaskResult, &crate::study::Compensated)> =
        t.iter().filter_map(|x| x.compensated.as_ref().map(|c| (x, c))).collect();
    if !comp.is_empty() {
        let stat = |name: &str, g: fn(&crate::study::ErrorStats) -> f64| f64c(name, comp.iter().map(|(_, c)| g(&c.stats)).collect());
        parquet(
            dir,
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
    parquet(dir, "parameters.parquet", parameter_columns(&r.set, t.iter().map(|x| (&x.task, &x.id)), &r.truth, &r.start))?;

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
    parquet(
        dir,
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

    let manifest = Manifest {
        provenance: Provenance::new(&scenario.name, &scenario.path, &scenario.text, scenario.seed, threads),
        tables_sha256: table_hashes(dir)?,
        tasks: t.len(),
        set_sizes: scenario.study.set_sizes.clone(),
        repetitions: scenario.study.repetitions,
        timings,
    };
    fs::write(dir.join("manifest.json"), serde_json::to_string_pretty(&manifest).map_err(err)?)?;
    if let Some(record) = extras.recording {
        record(&dir.join("study.rrd")).map_err(|e| std::io::Error::other(format!("recording: {e}")))?;
    }
    let drawn = match extras.plots {
        Some(p) => crate::io::plots::write_all(dir, r, p).map_err(|e| std::io::Error::other(format!("plots: {e}")))?,
        None => Vec::new(),
    };
    fs::write(dir.join("summary.md"), summary(scenario, r, f, checks, &drawn))?;
    Ok(())
}

/// The summary: the paper's Tables 7 and 8 and before/after figures next to calsim's.
///
/// Long by design: the summary document top to bottom, one block per section.
pub fn summary(scenario: &Scenario, r: &StudyResults, f: &Figures, checks: &[Check], drawn: &[Written]) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# {}: calsim against the published figures\n", scenario.name);
    let _ = writeln!(
        s,
        "Seed {}, {} identifications ({} set sizes x {} repetitions), DETMAX on O1 over a pool of {}, validation on {} poses.\n",
        scenario.seed,
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
    let comp: Vec<&crate::study::Compensated> = r.tasks.iter().filter_map(|x| x.compensated.as_ref()).collect();
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
    let _ = writeln!(
        s,
        "| parameter | unit | truth | mean | std | min | max | paper mean | paper std | std within x3 | mean \
             within 3 std |\n|---|---|---|---|---|---|---|---|---|---|---|"
    );
    for p in &f.table7 {
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
    if !drawn.is_empty() {
        let _ = writeln!(s, "\n## Figures\n\nEach as PNG (shown) and SVG beside this file.\n");
        for w in drawn {
            let _ = writeln!(s, "![{}]({}.png)\n\n*{}* ([SVG]({}.svg))\n", w.caption, w.stem, w.caption, w.stem);
        }
    }
    s
}
