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
use crate::io::report::{Check, Figures};
use crate::io::scenario::Scenario;
use crate::study::StudyResults;

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

#[derive(Serialize)]
struct Manifest<'a> {
    #[serde(flatten)]
    provenance: Provenance<'a>,
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

/// Writes every result file of `results` into `out/<scenario name>`, replacing what was there.
///
/// `extras` adds the figures (PNG and SVG, embedded in `summary.md`) and the recording.
#[allow(clippy::too_many_arguments)]
pub fn write(out: &Path, scenario: &Scenario, results: &StudyResults, figures: &Figures, checks: &[Check], threads: usize, timings: &Timings, extras: &Extras<'_>) -> std::io::Result<PathBuf> {
    write_atomically(out, &scenario.name, |tmp| write_into(tmp, scenario, results, figures, checks, threads, timings, extras))
}

/// Runs `fill` on a fresh temporary directory beside `out/<name>` and renames it into place;
/// on failure the temporary directory is removed and `out/<name>` is left as it was.
pub(crate) fn write_atomically(out: &Path, name: &str, fill: impl FnOnce(&Path) -> std::io::Result<()>) -> std::io::Result<PathBuf> {
    fs::create_dir_all(out)?;
    let dest = out.join(name);
    let tmp = out.join(format!(".{name}.tmp-{}", std::process::id()));
    if tmp.exists() {
        fs::remove_dir_all(&tmp)?;
    }
    fs::create_dir_all(&tmp)?;
    if let Err(e) = fill(&tmp) {
        let _ = fs::remove_dir_all(&tmp);
        return Err(e);
    }
    let old = out.join(format!(".{name}.old-{}", std::process::id()));
    if dest.exists() {
        fs::rename(&dest, &old)?;
    }
    fs::rename(&tmp, &dest)?;
    if old.exists() {
        fs::remove_dir_all(&old)?;
    }
    Ok(dest)
}

#[allow(clippy::too_many_arguments)]
fn write_into(dir: &Path, scenario: &Scenario, r: &StudyResults, f: &Figures, checks: &[Check], threads: usize, timings: &Timings, extras: &Extras<'_>) -> std::io::Result<()> {
    let t = &r.tasks;
    let col_u32 = |name: &str, v: Vec<u32>| Column::new(name.into(), v);
    let col_f64 = |name: &str, v: Vec<f64>| Column::new(name.into(), v);
    parquet(
        dir,
        "tasks.parquet",
        vec![
            col_u32("task", t.iter().map(|x| x.task.index as u32).collect()),
            col_u32("set_size", t.iter().map(|x| x.task.set_size as u32).collect()),
            col_u32("repetition", t.iter().map(|x| x.task.repetition as u32).collect()),
            col_f64("o1", t.iter().map(|x| x.observability.o1).collect()),
            col_f64("o2", t.iter().map(|x| x.observability.o2).collect()),
            col_f64("o3", t.iter().map(|x| x.observability.o3).collect()),
            col_f64("o4", t.iter().map(|x| x.observability.o4).collect()),
            col_f64("o5", t.iter().map(|x| x.observability.o5).collect()),
            col_f64("condition_number", t.iter().map(|x| x.condition_number).collect()),
            Column::new("outcome".into(), t.iter().map(|x| x.outcome.clone()).collect::<Vec<_>>()),
            Column::new("unidentifiable".into(), t.iter().map(|x| x.unidentifiable.join(" ")).collect::<Vec<_>>()),
            col_u32("iterations", t.iter().map(|x| x.iterations as u32).collect()),
            col_u32("detmax_steps", t.iter().map(|x| x.detmax_steps as u32).collect()),
            col_f64("residual_rms_mm", t.iter().map(|x| x.residual_rms_mm).collect()),
            col_f64("validation_mean_mm", t.iter().map(|x| x.validation.mean).collect()),
            col_f64("validation_median_mm", t.iter().map(|x| x.validation.median).collect()),
            col_f64("validation_std_mm", t.iter().map(|x| x.validation.std).collect()),
            col_f64("validation_p95_mm", t.iter().map(|x| x.validation.p95).collect()),
            col_f64("validation_max_mm", t.iter().map(|x| x.validation.max).collect()),
            col_f64("validation_rms_mm", t.iter().map(|x| x.validation.rms).collect()),
            col_f64("seconds", t.iter().map(|x| x.seconds).collect()),
        ],
    )?;

    let ids = r.set.ids();
    let truth = &f.table7;
    let (mut task, mut param, mut unit, mut value, mut truth_v) = (vec![], vec![], vec![], vec![], vec![]);
    for x in t {
        for (j, id) in ids.iter().enumerate() {
            task.push(x.task.index as u32);
            param.push(id.name());
            unit.push(id.unit().symbol().to_string());
            value.push(x.values[j].map(|v| id.unit().from_internal(v)));
            truth_v.push(truth[j].truth);
        }
    }
    parquet(
        dir,
        "parameters.parquet",
        vec![Column::new("task".into(), task), Column::new("parameter".into(), param), Column::new("unit".into(), unit), Column::new("identified".into(), value), Column::new("truth".into(), truth_v)],
    )?;

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
    let _ = writeln!(s, "## Published versus reproduced\n\n| figure | published | calsim | band | result |\n|---|---|---|---|---|");
    for c in checks {
        let v = match c.pass {
            Some(true) => "pass",
            Some(false) => "**miss**",
            None => "-",
        };
        let _ = writeln!(s, "| {} | {} | {} | {} | {} |", c.figure, c.published, c.reproduced, c.band, v);
    }
    let _ =
        writeln!(s, "\nAfter-calibration figures are medians over the {} repetitions at n = {} of each identification's statistic over the validation poses.", scenario.study.repetitions, f.table_n);
    let _ = writeln!(
        s,
        "\n## Errors before and after calibration (mm)\n\n| | mean | median | std | p95 | max |\n|---|---|---|---|---|---|\n| before (paper: mean 2.628, max 6.282) | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} |\n| after, n = {} (median over repetitions; paper Table 8: median 0.208, std 0.084, max 0.482) | {:.3} | {:.3} | {:.3} | - | {:.3} |",
        f.before.mean, f.before.median, f.before.std, f.before.p95, f.before.max, f.table_n, f.after_mean, f.after_median, f.after_std, f.after_max
    );
    let _ = writeln!(s, "\n## Table 7: identified parameters over the sets of {}\n", f.table_n);
    let _ = writeln!(s, "| parameter | unit | truth | mean | std | min | max | paper mean | paper std | std within x3 | mean within 3 std |\n|---|---|---|---|---|---|---|---|---|---|---|");
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
    let _ = writeln!(s, "\n## Figs. 8-9: validation error per set size\n\n| n | median of mean (mm) | IQR of mean (mm) | median of std (mm) | not converged |\n|---|---|---|---|---|");
    for z in &f.sizes {
        let _ = writeln!(s, "| {} | {:.4} | {:.4} | {:.4} | {} |", z.n, z.median_of_means, z.iqr_of_means, z.median_of_stds, z.not_converged);
    }
    let _ = writeln!(
        s,
        "\nFig. 11: Pearson r of the error after calibration against the distance to the base: {:.3}. Fig. 12: against the distance to the centre of the calibration zone: {:.3}.",
        f.r_base, f.r_ccz
    );
    if !drawn.is_empty() {
        let _ = writeln!(s, "\n## Figures\n\nEach as PNG (shown) and SVG beside this file.\n");
        for w in drawn {
            let _ = writeln!(s, "![{}]({}.png)\n\n*{}* ([SVG]({}.svg))\n", w.caption, w.stem, w.caption, w.stem);
        }
    }
    s
}
