#![doc = include_str!("../README.md")]

pub mod budget;
pub mod campaign;
pub mod cell;
pub mod cli;
pub mod compensate;
pub mod experiment;
pub mod export;
pub mod identify;
pub mod instrument;
pub mod io;
pub mod numeric;
pub mod robot;
pub mod seeds;
pub mod spms;
pub mod study;
pub mod sweep;
