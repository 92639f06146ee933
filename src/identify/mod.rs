//! Identification: least squares on measured TCP positions.

pub mod damping;
pub mod least_squares;

pub use least_squares::{Fit, FitOptions, FitOutcome, Iteration, Observation, Solver, identify};
pub mod detmax;
pub mod observability;

pub use detmax::{Design, DetmaxOptions, PoolJacobian, detmax};
pub use observability::Observability;
