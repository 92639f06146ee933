#![doc = include_str!("../README.md")]
#![doc = include_str!("../docs/library.md")]

pub mod app;
pub mod calibrate;
pub mod cell;
pub mod cli;
pub mod design;
pub mod device;
pub mod identify;
pub mod instrument;
pub mod io;
pub mod numeric;
pub mod plan;
pub mod robot;
pub mod seeds;
pub mod study;
