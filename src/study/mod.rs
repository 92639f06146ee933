//! The study layer every device shares: the `[study]` spec (which sets are identified and how),
//! the one driver that runs a task grid in parallel (`engine`), the statistics of error samples
//! and over realisations (`stats`), the published figures (`published`), the comparison rows and
//! their bands (`check`), the linear prediction beside the Monte Carlo (`prediction`) and the
//! result columns every study writes (`tables`).

pub mod check;
pub mod engine;
pub mod interval;
pub mod prediction;
pub mod published;
pub mod stats;
pub mod tables;

use serde::Deserialize;

use crate::identify::{DetmaxOptions, FitOptions, Solver};
use crate::robot::ParamSet;
pub use engine::{Identified, Selection, Task};
pub use stats::ErrorStats;

/// The name of an identification solver, as a scenario gives it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SolverName {
    /// Gauss-Newton with the pseudo-inverse step (the TriCal paper, eqs. 14-15).
    GaussNewton,
    /// Levenberg-Marquardt.
    LevenbergMarquardt,
}

/// The `[study]` table of a scenario, the same for every device: which sets are identified and how.
#[derive(Clone, Debug, Deserialize, serde::Serialize, PartialEq)]
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
    /// Worlds `calsim check` judges the figures over (1: the scenario's own world, as it is).
    pub check_realisations: u32,
    /// The false-alarm rate of `calsim check` over realisations: the probability of a miss when
    /// the model's medians satisfy every bound.
    pub check_false_alarm: f64,
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
            check_realisations: 1,
            check_false_alarm: 0.01,
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

/// Most identifications per set size a study takes, in a file and on the command line alike.
pub const MAX_REPETITIONS: u32 = 10_000;
/// Most set sizes a study takes.
pub const MAX_SET_SIZES: usize = 1_000;
/// Most realisations `calsim check` judges over.
pub const MAX_CHECK_REALISATIONS: u32 = 10_000;
/// Most identifications a study takes in all (selections x set sizes x repetitions).
pub const MAX_TASKS: u64 = 1_000_000;
