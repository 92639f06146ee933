//! The dispersion study of the TriCal paper (section 3.1): for each set size and repetition,
//! choose the configurations from the pool by DETMAX on O1, identify, validate on the tracker
//! poses. Tasks are pure functions of the experiment and their own seeded stream, run in
//! parallel with rayon; results do not depend on the number of threads.

use std::time::Instant;

use nalgebra::Point3;

use super::experiment::Experiment;
use crate::identify::{DetmaxOptions, FitOptions, Observation, PoolJacobian, identify};
use crate::robot::{Joints, KinState, ParamSet, RobotModel, forward, world_from_base};
use crate::study::engine::{self, Identified, Task};
use crate::study::{ErrorStats, StudySpec};

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

/// The prediction of every identification of a TriCal study at set size `n` that separated the
/// parameters; `pool_qs` are the configurations the sets index, `validation_qs` the validation
/// poses; `seed` keys the draws. `None` when no task qualifies.
pub fn predict(
    results: &StudyResults,
    pool_qs: &[Joints],
    validation_qs: &[Joints],
    n: usize,
    seed: u64,
) -> Option<crate::study::prediction::Prediction> {
    use crate::study::prediction::{TaskView, predict_tasks};
    let tasks = results.tasks.iter().filter(|t| t.task.set_size == n && !t.id.outcome.is_rank_deficient()).map(|t| TaskView {
        index: t.task.index,
        chosen: &t.id.chosen,
        values: &t.id.values,
        residual_rms_mm: t.id.residual_rms_mm,
        simulated_mm: [t.validation.median, t.validation.p95],
    });
    predict_tasks(&results.set, &results.truth, tasks, pool_qs, validation_qs, seed)
}
