#![doc = include_str!("../README.md")]

pub mod campaign;
pub mod cli;
pub mod identify;
pub mod robot;
