//! Design studies over any device: sweeps over realisations, the uncertainty budget and the
//! optimiser.

pub mod budget;
pub mod optimise;
pub mod sweep;
