//! The dispersion study of the TriCal paper (section 3.1): for each set size and repetition,
//! choose the configurations from the pool by DETMAX on O1, identify, validate on the tracker
//! poses. Tasks are pure functions of the experiment and their own seeded stream, run in
//! parallel with rayon; results do not depend on the number of threads.

pub mod stats;

use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use nalgebra::Point3;
use rayon::prelude::*;
use serde::Deserialize;

use crate::experiment::{Experiment, split_seed};
use crate::identify::{DetmaxOptions, FitOptions, Observability, Observation, PoolJacobian, Solver, detmax, identify};
use crate::robot::{KinState, ParamSet, RobotModel, forward, world_from_base};
pub use stats::ErrorStats;

/// The study as a scenario describes it.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct StudySpec {
    /// Identification set sizes (the paper: 20 to 100).
    pub set_sizes: Vec<u32>,
    /// Identifications per set size (the paper: 30).
    pub repetitions: u32,
    /// Set size of the paper's Tables 7 and 8 and Figures 10-13 (75).
    pub table_set_size: u32,
    /// Solver: `gauss_newton` (the paper's) or `levenberg_marquardt`.
    pub solver: String,
    /// Longest DETMAX excursion.
    pub detmax_max_excursion: u32,
    /// Identified parameters by name; absent: the paper's 31 (Table 7).
    pub parameters: Option<Vec<String>>,
}

impl Default for StudySpec {
    fn default() -> Self {
        Self { set_sizes: (20..=100).step_by(5).collect(), repetitions: 30, table_set_size: 75, solver: "gauss_newton".into(), detmax_max_excursion: 3, parameters: None }
    }
}

impl StudySpec {
    /// The identified parameter set.
    pub fn parameter_set(&self) -> Result<ParamSet, crate::robot::ParamError> {
        match &self.parameters {
            Some(names) => ParamSet::from_names(names),
            None => Ok(ParamSet::trical_31()),
        }
    }

    /// Fit options for the solver named in the spec.
    pub fn fit_options(&self) -> FitOptions {
        let solver = if self.solver == "levenberg_marquardt" { Solver::LevenbergMarquardt { tau: 1e-3 } } else { Solver::GaussNewton };
        FitOptions { solver, ..FitOptions::default() }
    }
}

/// One identification of the study.
#[derive(Clone, Debug, PartialEq)]
pub struct Task {
    /// Position in the study, the seed index.
    pub index: usize,
    /// Configurations identified from.
    pub set_size: usize,
    /// Repetition number, 0-based.
    pub repetition: usize,
}

/// What one identification gave.
#[derive(Clone, Debug, PartialEq)]
pub struct TaskResult {
    /// The task.
    pub task: Task,
    /// Chosen pool indices.
    pub selection: Vec<usize>,
    /// Observability of the chosen set (pool column scaling).
    pub observability: Observability,
    /// DETMAX additions and removals.
    pub detmax_steps: usize,
    /// Outcome label (`converged`, `iteration_cap`, `rank_deficient`).
    pub outcome: String,
    /// Parameters the set could not separate.
    pub unidentifiable: Vec<String>,
    /// Gauss-Newton iterations.
    pub iterations: usize,
    /// Condition number of the column-scaled identification Jacobian.
    pub condition_number: f64,
    /// Residual RMS of the identification, mm.
    pub residual_rms_mm: f64,
    /// Identified values, internal units, in the order of the parameter set.
    pub values: Vec<Option<f64>>,
    /// Validation error statistics (zero when no model was identified).
    pub validation: ErrorStats,
    /// Per-pose validation errors, kept for the table set size only, mm.
    pub errors: Option<Vec<f64>>,
    /// Wall time of the task, s (the only field that differs between runs).
    pub seconds: f64,
}

/// Everything a study produced.
pub struct StudyResults {
    /// The identified parameter set.
    pub set: ParamSet,
    /// Per-task results, in task order.
    pub tasks: Vec<TaskResult>,
    /// Validation errors of the model before calibration, mm.
    pub before_errors: Vec<f64>,
    /// Distance of each validation TCP to the robot base origin, mm.
    pub distance_to_base_mm: Vec<f64>,
    /// Distance of each validation TCP to the centre of the calibration zone, mm.
    pub distance_to_ccz_mm: Vec<f64>,
    /// Wall time of the pool Jacobian, s.
    pub pool_jacobian_s: f64,
    /// Wall time of the tasks, s.
    pub tasks_s: f64,
}

/// The tasks of a spec, in order: set sizes outer, repetitions inner.
pub fn tasks(spec: &StudySpec) -> Vec<Task> {
    let mut out = Vec::new();
    for &n in &spec.set_sizes {
        for r in 0..spec.repetitions as usize {
            out.push(Task { index: out.len(), set_size: n as usize, repetition: r });
        }
    }
    out
}

/// Validation errors of `model` over the tracker poses, mm.
pub fn validation_errors(model: &RobotModel, experiment: &Experiment, st: &mut KinState) -> Vec<f64> {
    experiment.campaign.validation.iter().map(|v| (forward(model, st, &v.q) - v.measured_w).norm()).collect()
}

/// Salt separating the study's task streams from the experiment's.
const STUDY_STREAM: u64 = 0x5354_5544_5900_0000;

/// Runs every task of `spec` on `experiment`, starting identifications from `before`, with
/// `progress` called after each finished task (from any thread).
pub fn run(experiment: &Experiment, before: &RobotModel, spec: &StudySpec, seed: u64, progress: &(dyn Fn(usize, usize) + Sync)) -> Result<StudyResults, crate::robot::ParamError> {
    let set = spec.parameter_set()?;
    let t0 = Instant::now();
    let qs: Vec<_> = experiment.campaign.pool.iter().map(|p| p.q).collect();
    let pool = PoolJacobian::new(before, &set, &qs);
    let pool_jacobian_s = t0.elapsed().as_secs_f64();
    let observations: Vec<Observation> = experiment.campaign.pool.iter().map(|p| experiment.campaign.observation(&experiment.cell, p)).collect();
    let opts = spec.fit_options();
    let dopts = DetmaxOptions { max_excursion: spec.detmax_max_excursion.max(1) as usize, ..DetmaxOptions::default() };
    let all = tasks(spec);
    let done = AtomicUsize::new(0);
    let t1 = Instant::now();
    let results: Vec<TaskResult> = all
        .par_iter()
        .map(|task| {
            let r = run_task(experiment, before, &set, &pool, &observations, &opts, &dopts, spec.table_set_size as usize, seed, task);
            progress(done.fetch_add(1, Ordering::Relaxed) + 1, all.len());
            r
        })
        .collect();
    let tasks_s = t1.elapsed().as_secs_f64();

    let mut st = KinState::default();
    let before_errors = validation_errors(before, experiment, &mut st);
    let base_w = world_from_base(&experiment.robot.truth).transform_point(&Point3::origin()).coords;
    let ccz = experiment.cell.calibration_zone_centre();
    let distance_to_base_mm = experiment.campaign.validation.iter().map(|v| (v.measured_w - base_w).norm()).collect();
    let distance_to_ccz_mm = experiment.campaign.validation.iter().map(|v| (v.measured_w - ccz).norm()).collect();
    Ok(StudyResults { set, tasks: results, before_errors, distance_to_base_mm, distance_to_ccz_mm, pool_jacobian_s, tasks_s })
}

/// One task: DETMAX from its own random start, identification, validation.
fn run_task(
    experiment: &Experiment,
    before: &RobotModel,
    set: &ParamSet,
    pool: &PoolJacobian,
    observations: &[Observation],
    opts: &FitOptions,
    dopts: &DetmaxOptions,
    table_set_size: usize,
    seed: u64,
    task: &Task,
) -> TaskResult {
    let t0 = Instant::now();
    let mut rng = crate::experiment::stream(split_seed(seed, STUDY_STREAM), task.index as u64);
    let n = task.set_size;
    let (selection, steps) = match detmax(pool, n, dopts, &mut rng) {
        Ok(d) => (d.selection, d.steps),
        Err(_) => (Vec::new(), 0),
    };
    let observability = Observability::from_information(&pool.information(&selection), n.max(1));
    let obs: Vec<Observation> = selection.iter().map(|&k| observations[k]).collect();
    let fit = identify(before, set, &obs, opts);
    let unidentifiable = match &fit.outcome {
        crate::identify::FitOutcome::RankDeficient { unidentifiable } | crate::identify::FitOutcome::Truncated { unidentifiable, .. } => unidentifiable.clone(),
        _ => Vec::new(),
    };
    let mut st = KinState::default();
    let errors = fit.model.as_ref().map(|m| validation_errors(m, experiment, &mut st));
    let validation = errors.as_deref().map(ErrorStats::of).unwrap_or_default();
    TaskResult {
        task: task.clone(),
        selection,
        observability,
        detmax_steps: steps,
        outcome: fit.outcome.label().to_string(),
        unidentifiable,
        iterations: fit.iterations,
        condition_number: fit.condition_number,
        residual_rms_mm: fit.residual_rms_mm,
        values: fit.values,
        validation,
        errors: if n == table_set_size { errors } else { None },
        seconds: t0.elapsed().as_secs_f64(),
    }
}
