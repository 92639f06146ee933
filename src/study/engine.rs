//! The one study driver: a grid of tasks (selection x set size x repetition), each run on its own
//! seeded stream in parallel with rayon, with progress, results in task order.
//!
//! What a task does is the caller's: a TriCal study validates against the tracker poses, an SPMS
//! study runs an ISO 9283 test. Both choose their sets with [`Selection`] and identify through
//! [`select_and_identify`], so a new device or a new kind of study is a new closure, not a new
//! driver. Results are bit-identical for any thread count because a task's stream is keyed by its
//! index alone ([`crate::seeds::task_stream`]).

use std::sync::atomic::{AtomicUsize, Ordering};

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::Deserialize;

use crate::identify::{DetmaxOptions, Fit, FitOutcome, Observability, PoolJacobian, detmax};

/// How an identification set is chosen from the pool.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Selection {
    /// Drawn uniformly from the pool (the SPMS paper).
    Random,
    /// DETMAX on O1 from a random start (the TriCal paper).
    Detmax,
}

impl Selection {
    /// Label for tables.
    pub fn label(self) -> &'static str {
        match self {
            Selection::Random => "random",
            Selection::Detmax => "detmax",
        }
    }

    /// `n` pool indices chosen this way, and the DETMAX exchanges made (0 for a random set). An
    /// empty selection means DETMAX could not build a set of `n` (the fit then reports it).
    pub fn choose<R: Rng + ?Sized>(self, pool: &PoolJacobian, n: usize, opts: &DetmaxOptions, rng: &mut R) -> (Vec<usize>, usize) {
        match self {
            Selection::Random => (random_selection(pool.len, n, rng), 0),
            Selection::Detmax => detmax(pool, n, opts, rng).map(|d| (d.selection, d.steps)).unwrap_or_default(),
        }
    }
}

/// `n` distinct pool indices drawn uniformly, ascending.
pub fn random_selection<R: Rng + ?Sized>(pool: usize, n: usize, rng: &mut R) -> Vec<usize> {
    let mut s = rand::seq::index::sample(rng, pool, n.min(pool)).into_vec();
    s.sort_unstable();
    s
}

/// One identification of a study: where it sits in the grid.
#[derive(Clone, Debug, PartialEq)]
pub struct Task {
    /// Position in the study, the key of its stream.
    pub index: usize,
    /// How its set is chosen.
    pub selection: Selection,
    /// Configurations identified from.
    pub set_size: usize,
    /// Repetition number, 0-based.
    pub repetition: usize,
}

/// The task grid: selections outer, then set sizes, repetitions inner.
pub fn grid(selections: &[Selection], set_sizes: &[u32], repetitions: u32) -> Vec<Task> {
    let mut out = Vec::with_capacity(selections.len() * set_sizes.len() * repetitions as usize);
    for &selection in selections {
        for &n in set_sizes {
            for repetition in 0..repetitions as usize {
                out.push(Task { index: out.len(), selection, set_size: n as usize, repetition });
            }
        }
    }
    out
}

/// Runs `work` on every task with its own stream (`seed`, `salt`, task index), in parallel, calling
/// `progress(done, total)` after each; results come back in task order.
pub fn run_tasks<R: Send>(
    tasks: &[Task],
    seed: u64,
    salt: u64,
    progress: &(dyn Fn(usize, usize) + Sync),
    work: impl Fn(&Task, &mut ChaCha8Rng) -> R + Sync,
) -> Vec<R> {
    let done = AtomicUsize::new(0);
    tasks
        .par_iter()
        .map(|task| {
            let mut rng = crate::seeds::task_stream(seed, salt, task.index);
            let r = work(task, &mut rng);
            progress(done.fetch_add(1, Ordering::Relaxed) + 1, tasks.len());
            r
        })
        .collect()
}

/// What an identification gave, whatever the device: the chosen set, its observability and the fit.
#[derive(Clone, Debug, PartialEq)]
pub struct Identified {
    /// Chosen pool indices.
    pub chosen: Vec<usize>,
    /// DETMAX additions and removals.
    pub detmax_steps: usize,
    /// Observability of the chosen set (pool column scaling).
    pub observability: Observability,
    /// How the fit ended (with the parameters it could not separate).
    pub outcome: FitOutcome,
    /// Jacobian evaluations of the fit.
    pub iterations: usize,
    /// Condition number of the column-scaled identification Jacobian.
    pub condition_number: f64,
    /// Residual RMS of the identification, mm.
    pub residual_rms_mm: f64,
    /// Identified values, internal units, in the order of the parameter set.
    pub values: Vec<Option<f64>>,
}

/// Chooses the set of `task` from `pool` and fits it with `fit` (which maps pool indices to a fit);
/// returns the record and the fit's model (`None` when the set could not separate the parameters).
pub fn select_and_identify(
    task: &Task,
    pool: &PoolJacobian,
    opts: &DetmaxOptions,
    rng: &mut ChaCha8Rng,
    fit: impl FnOnce(&[usize]) -> Fit,
) -> (Identified, Option<crate::robot::RobotModel>) {
    let n = task.set_size;
    let (chosen, detmax_steps) = task.selection.choose(pool, n, opts, rng);
    let observability = Observability::from_information(&pool.information(&chosen), n.max(1));
    let f = fit(&chosen);
    let id = Identified {
        chosen,
        detmax_steps,
        observability,
        outcome: f.outcome,
        iterations: f.iterations,
        condition_number: f.condition_number,
        residual_rms_mm: f.residual_rms_mm,
        values: f.values,
    };
    (id, f.model)
}
