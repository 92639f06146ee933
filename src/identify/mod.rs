//! Identification: least squares on measured TCP positions.

pub mod least_squares;

pub use least_squares::{Fit, FitOptions, FitOutcome, Iteration, Observation, Solver, identify};
