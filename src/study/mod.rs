//! The dispersion study of the TriCal paper (section 3.1): for each set size and repetition,
//! choose the configurations from the pool by DETMAX on O1, identify, validate on the tracker
//! poses. Tasks are pure functions of the experiment and their own seeded stream, run in
//! parallel with rayon; results do not depend on the number of threads.

pub mod check;
pub mod engine;
pub mod figures;
pub mod prediction;
pub mod published;
pub mod stats;

use std::time::Instant;

use nalgebra::Point3;
use serde::Deserialize;

use crate::experiment::Experiment;
use crate::identify::{DetmaxOptions, FitOptions, Observation, PoolJacobian, Solver, identify};
use crate::robot::{KinState, ParamSet, RobotModel, forward, world_from_base};
pub use engine::{Identified, Selection, Task};
pub use stats::ErrorStats;

/// The name of an identification solver, as a scenario gives it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SolverName {
    /// Gauss-Newton with the pseudo-inverse step (the TriCal paper, eqs. 14-15).
    GaussNewton,
    /// Levenberg-Marquardt.
    LevenbergMarquardt,
}

/// The `[study]` table of a scenario, the same for every device: which sets are identified and how.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct StudySpec {
    /// Identification set sizes (the TriCal paper: 20 to 100).
    pub set_sizes: Vec<u32>,
    /// Identifications per set size and selection (the TriCal paper: 30).
    pub repetitions: u32,
    /// Set size of the paper's tables (TriCal: 75, Tables 7 and 8 and Figs. 10-13).
    pub table_set_size: u32,
    /// How sets are chosen, each a study of its own: `detmax` (TriCal), `random` (SPMS).
    pub selections: Vec<Selection>,
    /// Solver: `gauss_newton` (the paper's) or `levenberg_marquardt`.
    pub solver: SolverName,
    /// Longest DETMAX excursion.
    pub detmax_max_excursion: u32,
    /// Identified parameters by name; absent: the device's default set.
    pub parameters: Option<Vec<String>>,
    /// Relative singular-value threshold of the identification.
    pub rank_rtol: f64,
    /// Leave directions below the threshold at the start values instead of refusing the fit.
    pub truncate: bool,
    /// Validate the identifications at the table set size with compensated targets too
    /// ([`compensated_errors`]).
    pub compensated_validation: bool,
}

impl Default for StudySpec {
    fn default() -> Self {
        Self {
            set_sizes: (20..=100).step_by(5).collect(),
            repetitions: 30,
            table_set_size: 75,
            selections: vec![Selection::Detmax],
            solver: SolverName::GaussNewton,
            detmax_max_excursion: 3,
            parameters: None,
            rank_rtol: FitOptions::default().rank_rtol,
            truncate: false,
            compensated_validation: true,
        }
    }
}

impl StudySpec {
    /// The identified parameter set; `default` when the spec names none.
    pub fn parameter_set(&self, default: impl FnOnce() -> ParamSet) -> Result<ParamSet, crate::robot::ParamError> {
        match &self.parameters {
            Some(names) => ParamSet::from_names(names),
            None => Ok(default()),
        }
    }

    /// Fit options of the spec.
    pub fn fit_options(&self) -> FitOptions {
        let solver = match self.solver {
            SolverName::GaussNewton => Solver::GaussNewton,
            SolverName::LevenbergMarquardt => Solver::LevenbergMarquardt { tau: 1e-3 },
        };
        FitOptions { solver, rank_rtol: self.rank_rtol, truncate: self.truncate, ..FitOptions::default() }
    }

    /// DETMAX options of the spec.
    pub fn detmax_options(&self) -> DetmaxOptions {
        DetmaxOptions { max_excursion: self.detmax_max_excursion.max(1) as usize, ..DetmaxOptions::default() }
    }

    /// The task grid of the spec.
    pub fn tasks(&self) -> Vec<Task> {
        engine::grid(&self.selections, &self.set_sizes, self.repetitions)
    }
}

/// What one identification gave.
#[derive(Clone, Debug, PartialEq)]
pub struct TaskResult {
    /// The task.
    pub task: Task,
    /// The chosen set and the fit.
    pub id: Identified,
    /// Validation error statistics (zero when no model was identified).
    pub validation: ErrorStats,
    /// Per-pose validation errors, kept for the table set size only, mm.
    pub errors: Option<Vec<f64>>,
    /// The validation with compensated targets (table set size only, see [`compensated_errors`]).
    pub compensated: Option<Compensated>,
}

/// The validation as a user of the calibration meets it: each validation TCP of the model before
/// calibration taken as a Cartesian target, the joint values that put the identified model there
/// (Newton on the full model with compliance from the validation configuration, damped least
/// squares where Newton fails), the physical robot of setup 2 moved there and measured by the
/// tracker; the error is measured minus target.
#[derive(Clone, Debug, PartialEq)]
pub struct Compensated {
    /// Error statistics over the targets reached, mm.
    pub stats: ErrorStats,
    /// Targets the identified model found no joint values for (beyond its reach: near full stretch,
    /// the model before calibration reaches farther than the identified one).
    pub failed: usize,
}

/// The compensated validation's Cartesian targets: the TCP of the model before calibration at
/// every validation configuration, in {W}, mm (the same for every identified model: computed once
/// per study).
pub fn compensation_targets(before: &RobotModel, experiment: &Experiment) -> Vec<nalgebra::Vector3<f64>> {
    let mut st = KinState::default();
    experiment.campaign.validation.iter().map(|v| forward(before, &mut st, &v.q)).collect()
}

/// The validation with compensated targets of `model` (see [`Compensated`]) towards `targets`
/// ([`compensation_targets`], one per validation pose), the robot's and the tracker's noise from
/// `rng`.
pub fn compensated_errors(
    model: &RobotModel,
    targets: &[nalgebra::Vector3<f64>],
    experiment: &Experiment,
    rng: &mut rand_chacha::ChaCha8Rng,
) -> Compensated {
    assert_eq!(targets.len(), experiment.campaign.validation.len(), "one target per validation pose");
    let mut st = KinState::default();
    let mut errors = Vec::with_capacity(experiment.campaign.validation.len());
    let mut failed = 0;
    let mut from = experiment.campaign.semi_automatic.located_q[0];
    let base_rot = model.base_rot;
    for (v, &target_w) in experiment.campaign.validation.iter().zip(targets) {
        // The identified model's flange orientation there (a product of rotations: converted
        // directly, not through `from_matrix`'s iterative orthonormalisation).
        forward(model, &mut st, &v.q);
        let r = nalgebra::Rotation3::from_matrix_unchecked(base_rot * st.rot[crate::robot::JOINTS]);
        let target = nalgebra::Isometry3::from_parts(target_w.into(), nalgebra::UnitQuaternion::from_rotation_matrix(&r));
        // Newton from the validation configuration; near the shoulder singularity (the wrist
        // centre on axis 1) it diverges, and damped least squares takes over.
        let Ok(q) = crate::robot::ik::refine_direct(model, &target, &v.q).or_else(|_| crate::robot::ik::damped_from(model, &target, &v.q))
        else {
            failed += 1;
            continue;
        };
        let true_w = experiment.robot_validation.tcp_after_move(&mut st, &q, &from, rng);
        from = q;
        errors.push((experiment.tracker.measure(&true_w, rng) - target_w).norm());
    }
    Compensated { stats: if errors.is_empty() { ErrorStats::default() } else { ErrorStats::of(&errors) }, failed }
}

/// Everything a study produced.
pub struct StudyResults {
    /// The identified parameter set.
    pub set: ParamSet,
    /// The true robot (its parameters; the unmodelled effects are the experiment's).
    pub truth: RobotModel,
    /// The model every identification starts from (before calibration).
    pub start: RobotModel,
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

/// Validation errors of `model` over the tracker poses, mm.
pub fn validation_errors(model: &RobotModel, experiment: &Experiment) -> Vec<f64> {
    let poses = &experiment.campaign.validation;
    crate::robot::tcps_world(model, poses.iter().map(|v| &v.q)).iter().zip(poses).map(|(p, v)| (p - v.measured_w).norm()).collect()
}

/// Runs every task of `spec` on `experiment`, starting identifications from `before`, with
/// `progress` called after each finished task (from any thread).
pub fn run(
    experiment: &Experiment,
    before: &RobotModel,
    spec: &StudySpec,
    seed: u64,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<StudyResults, crate::robot::ParamError> {
    let observations: Vec<Observation> =
        experiment.campaign.pool.iter().map(|p| experiment.campaign.observation(&experiment.cell, p)).collect();
    run_on_pool(experiment, before, spec, seed, &observations, progress)
}

/// The study on any measured pool (`observations`: the TriCal's centred configurations, or a pool
/// measured by an external instrument for Table 8), validated on the experiment's tracker poses.
pub fn run_on_pool(
    experiment: &Experiment,
    before: &RobotModel,
    spec: &StudySpec,
    seed: u64,
    observations: &[Observation],
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<StudyResults, crate::robot::ParamError> {
    let set = spec.parameter_set(ParamSet::trical_31)?;
    let t0 = Instant::now();
    let qs: Vec<_> = observations.iter().map(|o| o.q).collect();
    let pool = PoolJacobian::new(before, &set, &qs);
    let pool_jacobian_s = t0.elapsed().as_secs_f64();
    let cx = TaskContext::new(experiment, before, &set, observations, &pool, spec, seed);
    let t1 = Instant::now();
    let results = engine::run_tasks(&spec.tasks(), seed, crate::seeds::study::TRICAL, progress, |task, rng| cx.run(task, rng).0);
    let tasks_s = t1.elapsed().as_secs_f64();

    let before_errors = validation_errors(before, experiment);
    let base_w = world_from_base(&experiment.robot.truth).transform_point(&Point3::origin()).coords;
    let ccz = experiment.cell.calibration_zone_centre();
    let distance_to_base_mm = experiment.campaign.validation.iter().map(|v| (v.measured_w - base_w).norm()).collect();
    let distance_to_ccz_mm = experiment.campaign.validation.iter().map(|v| (v.measured_w - ccz).norm()).collect();
    Ok(StudyResults {
        set,
        truth: experiment.robot.truth.clone(),
        start: before.clone(),
        tasks: results,
        before_errors,
        distance_to_base_mm,
        distance_to_ccz_mm,
        pool_jacobian_s,
        tasks_s,
    })
}

/// What every task of a TriCal study shares.
struct TaskContext<'a> {
    experiment: &'a Experiment,
    before: &'a RobotModel,
    set: &'a ParamSet,
    observations: &'a [Observation],
    pool: &'a PoolJacobian,
    table_n: usize,
    opts: FitOptions,
    dopts: DetmaxOptions,
    seed: u64,
    /// The compensated validation's targets, when the study runs it.
    targets: Option<Vec<nalgebra::Vector3<f64>>>,
}

impl<'a> TaskContext<'a> {
    fn new(
        experiment: &'a Experiment,
        before: &'a RobotModel,
        set: &'a ParamSet,
        observations: &'a [Observation],
        pool: &'a PoolJacobian,
        spec: &StudySpec,
        seed: u64,
    ) -> Self {
        let (opts, dopts, table_n) = (spec.fit_options(), spec.detmax_options(), spec.table_set_size as usize);
        let targets = spec.compensated_validation.then(|| compensation_targets(before, experiment));
        Self { experiment, before, set, observations, pool, table_n, opts, dopts, seed, targets }
    }
}

impl TaskContext<'_> {
    /// One task: its set, its fit, its validation; and the identified model.
    fn run(&self, task: &Task, rng: &mut rand_chacha::ChaCha8Rng) -> (TaskResult, Option<RobotModel>) {
        let (id, model) = engine::select_and_identify(task, self.pool, &self.dopts, rng, |chosen| {
            let obs: Vec<Observation> = chosen.iter().map(|&k| self.observations[k]).collect();
            identify(self.before, self.set, &obs, &self.opts)
        });
        let errors = model.as_ref().map(|m| validation_errors(m, self.experiment));
        let validation = errors.as_deref().map(ErrorStats::of).unwrap_or_default();
        let keep = task.set_size == self.table_n;
        let compensated = match (&model, &self.targets) {
            (Some(m), Some(targets)) if keep => {
                let rng = &mut crate::seeds::task_stream(self.seed, crate::seeds::study::COMPENSATED, task.index);
                Some(compensated_errors(m, targets, self.experiment, rng))
            }
            _ => None,
        };
        (TaskResult { task: task.clone(), id, validation, errors: if keep { errors } else { None }, compensated }, model)
    }
}

/// One task of a TriCal study redone on its own (the same stream, so the same set and fit as in
/// the whole study).
pub struct Recomputed {
    /// The task's record.
    pub result: TaskResult,
    /// The identified model (`None`: the set could not separate the parameters).
    pub model: Option<RobotModel>,
    /// The identified parameter set.
    pub set: ParamSet,
    /// The chosen set's observations.
    pub observations: Vec<Observation>,
}

/// Redoes task `index` of the study `spec` on `experiment` (`None`: no such task).
pub fn recompute_task(
    experiment: &Experiment,
    before: &RobotModel,
    spec: &StudySpec,
    seed: u64,
    index: usize,
) -> Result<Option<Recomputed>, crate::robot::ParamError> {
    let set = spec.parameter_set(ParamSet::trical_31)?;
    let observations: Vec<Observation> =
        experiment.campaign.pool.iter().map(|p| experiment.campaign.observation(&experiment.cell, p)).collect();
    let qs: Vec<_> = observations.iter().map(|o| o.q).collect();
    let pool = PoolJacobian::new(before, &set, &qs);
    let Some(task) = spec.tasks().into_iter().find(|t| t.index == index) else {
        return Ok(None);
    };
    let cx = TaskContext::new(experiment, before, &set, &observations, &pool, spec, seed);
    let (result, model) = cx.run(&task, &mut crate::seeds::task_stream(seed, crate::seeds::study::TRICAL, index));
    let chosen = result.id.chosen.iter().map(|&k| observations[k]).collect();
    Ok(Some(Recomputed { result, model, set, observations: chosen }))
}

/// Most identifications per set size a study takes, in a file and on the command line alike.
pub const MAX_REPETITIONS: u32 = 10_000;
/// Most set sizes a study takes.
pub const MAX_SET_SIZES: usize = 1_000;
/// Most identifications a study takes in all (selections x set sizes x repetitions).
pub const MAX_TASKS: u64 = 1_000_000;

/// Table 8's external instruments in one world: the robot calibrated from a pool of `pool_size`
/// random workspace configurations measured by the laser tracker, and by the optical CMM (placed
/// where the tracker stands), each with `spec`'s sets at the table set size; per instrument the
/// medians over repetitions of the validation error's median, std and max, mm.
pub fn external_instruments(
    experiment_spec: &crate::experiment::ExperimentSpec,
    e: &Experiment,
    before: &RobotModel,
    spec: &StudySpec,
    seed: u64,
    pool_size: u32,
) -> Result<[[f64; 3]; 2], String> {
    use crate::instrument::optical_cmm::{OpticalCmm, OpticalCmmSpec};
    let mut study = spec.clone();
    study.set_sizes = vec![study.table_set_size];
    // Table 8 compares the plain validation only.
    study.compensated_validation = false;
    let n = study.table_set_size as usize;
    let cmm = OpticalCmm::new(&OpticalCmmSpec::default(), e.tracker.position_w);
    let quiet = |_: usize, _: usize| {};
    let run = |measure: crate::campaign::Measure<'_>, what: &str| -> Result<[f64; 3], String> {
        let pool = experiment_spec.instrument_pool(e, seed, pool_size, measure).map_err(|err| format!("{what} pool: {err}"))?;
        let obs: Vec<Observation> = pool.iter().map(|v| Observation { q: v.q, tcp_world_mm: v.measured_w }).collect();
        let r = run_on_pool(e, before, &study, seed, &obs, &quiet).map_err(|err| err.to_string())?;
        let f = figures::Figures::of(&r, &e.robot.truth, n);
        Ok([f.after_median, f.after_std, f.after_max])
    };
    Ok([run(&|p, rng| Some(e.tracker.measure(p, rng)), "tracker")?, run(&|p, rng| cmm.measure(p, rng), "optical CMM")?])
}
