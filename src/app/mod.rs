//! The application layer, as cargo's `ops` beside its thin commands: every command of calsim as a
//! library function that takes a spec and returns a report value (`run`, `check`, `sweep`,
//! `merge`, `budget`, `table8`, `export`, `compensate`, `import_urdf`, `calibrate`, `fk`,
//! `optimise`). The CLI, the tests and the
//! Python package are its callers; it knows no terminal: what happens while a command runs reaches
//! an [`Observer`], which sees the state and never steers it.

pub mod budget;
pub mod calibrate;
pub mod compensate;
pub mod export;
pub mod fk;
pub mod import_urdf;
pub mod keys;
pub mod message;
pub mod optimise;
pub mod plan;
pub mod run;
pub mod simulate;
pub mod sweep;
pub mod table8;

use crate::design::budget::BudgetError;
use crate::design::sweep::{MergeError, SweepError};
use crate::device::{DeviceError, ScenarioError};
use crate::io::out_dir::OutDirError;

/// What a command tells the one who runs it while it runs (a progress bar, a notebook widget).
pub trait Observer: Sync {
    /// The command starts: one line saying what runs (`calsim run: irb120_trical (seed 2018), 2 threads`).
    fn started(&self, _line: &str) {}

    /// `done` of `total` items of a stage (`identifications`, `work units`, `realisations`).
    fn progress(&self, _done: usize, _total: usize, _what: &str) {}

    /// The stage whose progress was shown has ended.
    fn stage_done(&self) {}

    /// A warning the user should read (a realisation left out, identifications without a model).
    fn warning(&self, _line: &str) {}
}

/// An observer that shows nothing.
pub struct Quiet;

impl Observer for Quiet {}

/// Why a command could not do what it was asked.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A scenario file is unusable.
    #[error(transparent)]
    Scenario(#[from] ScenarioError),
    /// A sweep file is unusable.
    #[error(transparent)]
    Sweep(#[from] SweepError),
    /// Shard directories cannot be merged.
    #[error(transparent)]
    Merge(#[from] MergeError),
    /// A budget cannot run.
    #[error(transparent)]
    Budget(#[from] BudgetError),
    /// A URDF cannot be converted.
    #[error(transparent)]
    Urdf(#[from] crate::robot::urdf::UrdfError),
    /// A robot file is unusable.
    #[error(transparent)]
    RobotFile(#[from] crate::robot::file::RobotFileError),
    /// A joints file is unusable.
    #[error(transparent)]
    Joints(#[from] crate::robot::fk::JointsCsvError),
    /// A calibration cannot run (its robot file, its measurements, an option, the fit).
    #[error(transparent)]
    Calibrate(#[from] crate::calibrate::CalibrateError),
    /// The results cannot go where they were asked to.
    #[error(transparent)]
    OutDir(#[from] OutDirError),
    /// A file's name cannot name its results.
    #[error(transparent)]
    Name(#[from] crate::io::names::NameError),
    /// A study could not run (its campaign, its parameter set).
    #[error("{path}: {source}")]
    Device {
        /// The scenario.
        path: String,
        /// What went wrong.
        source: DeviceError,
    },
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file or directory.
        path: String,
        /// The error.
        source: std::io::Error,
    },
    /// A value given to the command is unusable.
    #[error("{what}: {why}")]
    Input {
        /// The file, option or variable, with the key or line where there is one.
        what: String,
        /// What is wrong and what to do.
        why: String,
    },
    /// Every identification of a study failed: its parameter set is not identifiable from any set
    /// of its pool.
    #[error(
        "{scenario}: [study] parameters: every one of the {total} identifications failed{hidden}: no set of the pool identifies this parameter set"
    )]
    NoModel {
        /// The scenario.
        scenario: String,
        /// Identifications.
        total: usize,
        /// ` (could not separate: ...)` or empty.
        hidden: String,
    },
}

impl Error {
    /// A bad input value: `what` names the file, option or variable (and key or line), `why` the rule.
    pub fn input(what: impl Into<String>, why: impl Into<String>) -> Self {
        Self::Input { what: what.into(), why: why.into() }
    }

    /// An I/O error at `path`.
    pub fn io(path: &std::path::Path) -> impl FnOnce(std::io::Error) -> Self + '_ {
        move |source| Self::Io { path: path.display().to_string(), source }
    }
}

/// Most worker threads a command takes (`threads` and `RAYON_NUM_THREADS`).
pub const MOST_THREADS: u32 = 1024;

/// The worker pool of a command and its size: `threads`, else `RAYON_NUM_THREADS` (rayon's own
/// variable, read here because rayon ignores a value it cannot read; 0 means every core, as in
/// rayon; set but empty counts as unset), else every core.
pub fn thread_pool(threads: Option<u32>) -> Result<(rayon::ThreadPool, usize), Error> {
    let asked = match threads {
        Some(t) if !(1..=MOST_THREADS).contains(&t) => {
            return Err(Error::input("--threads", format!("{t}: a number of worker threads within [1, {MOST_THREADS}]")));
        }
        Some(t) => t,
        None => match std::env::var_os("RAYON_NUM_THREADS").filter(|v| !v.is_empty()) {
            None => 0,
            Some(v) => v.to_str().and_then(|s| s.trim().parse::<u32>().ok()).filter(|n| *n <= MOST_THREADS).ok_or_else(|| {
                Error::input(
                    "environment",
                    format!(
                        "RAYON_NUM_THREADS = {:?} is not a number of threads (1 to {MOST_THREADS}, or 0 for every core)",
                        v.to_string_lossy()
                    ),
                )
            })?,
        },
    };
    let threads = if asked == 0 { std::thread::available_parallelism().map_or(1, usize::from) } else { asked as usize };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| Error::input("threads", format!("{threads}: the worker pool cannot start: {e}")))?;
    Ok((pool, threads))
}

/// A thread count as the start line shows it: "1 thread" or "n threads".
pub fn threads_label(n: usize) -> String {
    if n == 1 { "1 thread".into() } else { format!("{n} threads") }
}
