//! Design studies over any device: sweeps over realisations and the uncertainty budget.

pub mod budget;
pub mod sweep;
