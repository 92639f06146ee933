//! Simulated instruments: each answers where the TCP (or a target) is in {W}, with what error.

pub mod laser_tracker;
pub mod optical_cmm;
pub mod spms;
pub mod trical;
