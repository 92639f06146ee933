//! The calibrated model out of calsim: one identification of a results directory, redone from its
//! scenario and seed (the same stream, so the same set and fit, checked against the results), as a
//! robot file (every value of the identified model, each identified parameter's standard deviation
//! from the fit's covariance) and a YAML overlay of per-joint corrections against the model before
//! calibration.

use std::path::{Path, PathBuf};

use polars::prelude::*;
use sha2::Digest;

use super::Error;
use crate::identify::observability::parameter_covariance;
use crate::robot::{ParamId, RobotModel};
use crate::study::prediction::noise_estimate;

/// Which identification of the results to export.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Pick {
    /// Task by index.
    Task(usize),
    /// At a set size (`None`: the scenario's table set size): the task whose validation median is
    /// the median (the lower middle of an even count), the lowest or the highest.
    Median(Option<usize>),
    /// See `Median`.
    Best(Option<usize>),
    /// See `Median`.
    Worst(Option<usize>),
}

/// An identification redone for export.
pub struct Export {
    /// The scenario's name.
    pub scenario: String,
    /// Task index.
    pub task: usize,
    /// Its set size.
    pub set_size: usize,
    /// Validation median of the task, mm.
    pub validation_median_mm: f64,
    /// The model before calibration.
    pub before: RobotModel,
    /// The identified model.
    pub model: RobotModel,
    /// The arm's link capsules (carried into the exported robot files).
    pub links: crate::robot::file::LinkCapsules,
    /// The arm's flange in MDH frame 6 (carried into the exported robot files).
    pub flange: Option<nalgebra::Matrix3<f64>>,
    /// Identified parameters and their standard deviation (internal units).
    pub std: Vec<(ParamId, f64)>,
}

fn err(dir: &Path, what: impl std::fmt::Display) -> Error {
    Error::input(dir.display().to_string(), what.to_string())
}

/// Redoes the identification `pick` of the TriCal results in `dir`.
pub fn identification(dir: &Path, pick: Pick) -> Result<Export, Error> {
    #[derive(serde::Deserialize)]
    struct Manifest {
        scenario_path: PathBuf,
        scenario_sha256: String,
        seed: u64,
        #[serde(default)]
        overrides: Vec<(String, String)>,
    }
    let bytes = crate::io::read_bytes(&dir.join("manifest.json"))
        .map_err(|e| err(dir, format!("manifest.json: {e} (not a results directory of `calsim run`)")))?;
    if serde_json::from_slice::<serde_json::Value>(&bytes).is_ok_and(|v| v.get("sweep").is_some()) {
        return Err(err(
            dir,
            "the results of a sweep, not of a run: export takes a run's results; run one design with `calsim run <sweep results>/best_design.toml`, then export that",
        ));
    }
    let manifest: Manifest = serde_json::from_slice(&bytes).map_err(|e| err(dir, format!("manifest.json: {e}")))?;
    let text = crate::io::read_text(&manifest.scenario_path).map_err(|e| err(dir, format!("{}: {e}", manifest.scenario_path.display())))?;
    if format!("{:x}", sha2::Sha256::digest(text.as_bytes())) != manifest.scenario_sha256 {
        return Err(err(dir, format!("{} changed since these results were written: run it again", manifest.scenario_path.display())));
    }
    let overrides = crate::app::run::Overrides::from_pairs(&manifest.overrides)
        .ok_or_else(|| err(dir, format!("manifest.json: overrides {:?}: not ones calsim writes", manifest.overrides)))?;
    let mut s = crate::device::load(&manifest.scenario_path)?;
    overrides.apply(s.as_mut())?;
    s.header_mut().seed = manifest.seed;
    let tasks = tasks_table(dir)?;
    let index = match pick {
        Pick::Task(t) => t,
        Pick::Median(n) | Pick::Best(n) | Pick::Worst(n) => {
            let n = n.unwrap_or(s.study().table_set_size as usize);
            let mut at: Vec<(f64, usize)> = tasks.iter().filter(|t| t.1 == n && t.2.is_finite()).map(|t| (t.2, t.0)).collect();
            at.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            let k = match pick {
                Pick::Best(_) => 0,
                Pick::Worst(_) => at.len().saturating_sub(1),
                _ => (at.len().saturating_sub(1)) / 2,
            };
            at.get(k).map(|x| x.1).ok_or_else(|| err(dir, format!("--set-size {n}: no identified task of that size in tasks.parquet")))?
        }
    };
    let row = tasks.iter().find(|t| t.0 == index).ok_or_else(|| err(dir, format!("--task {index}: no such task in tasks.parquet")))?;
    let r = s.refit(index).map_err(|e| err(dir, e))?.ok_or_else(|| err(dir, format!("task {index} is not in the scenario's study")))?;
    let model = r.model.ok_or_else(|| err(dir, format!("task {index}: its set could not separate the parameters: no model")))?;
    if r.validation_median_mm.to_bits() != row.2.to_bits() {
        return Err(err(
            dir,
            format!("task {index}: redone it gives a validation median of {} mm, the results say {} mm", r.validation_median_mm, row.2),
        ));
    }
    let (n, m) = (r.observations.len(), r.set.len());
    let sigma = noise_estimate(r.residual_rms_mm, n, m);
    let qs: Vec<_> = r.observations.iter().map(|o| o.q).collect();
    let cov = parameter_covariance(&model, &r.set, &qs, sigma);
    let std = r.set.ids().iter().enumerate().map(|(j, id)| (*id, cov.as_ref().map_or(f64::NAN, |c| c[(j, j)].max(0.0).sqrt()))).collect();
    Ok(Export {
        scenario: s.header().name.clone(),
        task: index,
        set_size: r.set_size,
        validation_median_mm: r.validation_median_mm,
        before: r.before,
        model,
        std,
        links: r.links,
        flange: r.flange,
    })
}

/// (task, set size, validation median) of every row of `dir/tasks.parquet`.
fn tasks_table(dir: &Path) -> Result<Vec<(usize, usize, f64)>, Error> {
    let path = dir.join("tasks.parquet");
    let bytes = crate::io::read_bytes_at_most(&path, crate::io::MOST_TABLE_BYTES).map_err(|e| err(dir, format!("tasks.parquet: {e}")))?;
    let df = ParquetReader::new(std::io::Cursor::new(bytes)).finish().map_err(|e| err(dir, format!("tasks.parquet: {e}")))?;
    let col = |name: &str| {
        df.column(name).map_err(|_| {
            err(
                dir,
                format!(
                    "tasks.parquet has no column {name}: export redoes an identification judged by its validation median \
                     (a TriCal or tracker run's results), and these results have none (an SPMS study reports ISO 9283 figures)"
                ),
            )
        })
    };
    let task = col("task")?.cast(&DataType::UInt64).map_err(|e| err(dir, e))?;
    let size = col("set_size")?.cast(&DataType::UInt64).map_err(|e| err(dir, e))?;
    let median = col("validation_median_mm")?.cast(&DataType::Float64).map_err(|e| err(dir, e))?;
    let (task, size, median) =
        (task.u64().map_err(|e| err(dir, e))?, size.u64().map_err(|e| err(dir, e))?, median.f64().map_err(|e| err(dir, e))?);
    Ok(task
        .iter()
        .zip(size.iter())
        .zip(median.iter())
        .filter_map(|((t, s), m)| Some((t? as usize, s? as usize, m.unwrap_or(f64::NAN))))
        .collect())
}

/// `export`: the identification `pick` of the results directory `results` written to
/// `out/<scenario>.task-<task>` (`out` defaults to the directory holding `results`). The output is
/// vetted before anything is read and prepared before anything is written ([`crate::io::out_dir`]);
/// returns the export and the directory written.
pub fn run(results: &Path, pick: Pick, out: Option<&Path>) -> Result<(Export, PathBuf), Error> {
    let out = out.map(Path::to_path_buf).unwrap_or_else(|| results.parent().map(Path::to_path_buf).unwrap_or_default());
    let _inputs = crate::io::inputs::Ledger::open();
    crate::io::out_dir::vet_dir(&out)?;
    let e = identification(results, pick)?;
    let name = format!("{}.task-{}", e.scenario, e.task);
    crate::io::out_dir::prepare(&out, &name)?;
    let dest = write(&out, &name, &e).map_err(Error::io(&out))?;
    Ok((e, dest))
}

/// The YAML overlay of `e` ([`crate::robot::export::yaml_overlay`]).
pub fn yaml_overlay(e: &Export) -> String {
    crate::robot::export::yaml_overlay(&e.before, &e.model, &format!("scenario {}, task {}, n = {}", e.scenario, e.task, e.set_size))
}

/// Writes `robot.toml`, `before.toml` (the model before calibration), `robot.urdf`,
/// `calibration.yaml` and `manifest.json` (its provenance: the results directory's files and the
/// scenario it read) of `e` into `out/<name>` atomically.
pub fn write(out: &Path, name: &str, e: &Export) -> std::io::Result<PathBuf> {
    let source = format!(
        "calsim {} export: scenario {}, task {} (n = {}), validation median {:.4} mm",
        env!("CARGO_PKG_VERSION"),
        e.scenario,
        e.task,
        e.set_size,
        e.validation_median_mm
    );
    let robot = crate::robot::file::to_text(&e.model, &source, &e.std, Some(&e.links), e.flange.as_ref());
    let yaml = yaml_overlay(e);
    let urdf = urdf(e).map_err(std::io::Error::other)?;
    let before = crate::robot::file::to_text(
        &e.before,
        &format!("the model before calibration of {}", e.scenario),
        &[],
        Some(&e.links),
        e.flange.as_ref(),
    );
    let mut r = crate::io::results::Results::new(name, crate::io::results::Head::Run(crate::io::manifest::Provenance::of_run(&[])));
    r.field("export", &e.scenario)?
        .field("task", e.task)?
        .field("set_size", e.set_size)?
        .field("validation_median_mm", e.validation_median_mm)?;
    r.file("robot.toml", robot).file("before.toml", before).file("robot.urdf", urdf).file("calibration.yaml", yaml);
    crate::io::results::write(out, r).map(|w| w.dest)
}

/// The URDF of `e`'s identified model ([`crate::robot::export::urdf`]).
pub fn urdf(e: &Export) -> Result<String, Error> {
    crate::robot::export::urdf(&e.before, &e.model).map_err(|err| Error::input("URDF", err.to_string()))
}
