//! Table 8 of the TriCal paper: the same robot calibrated from pools measured by external
//! instruments (the laser tracker and the optical CMM) over the whole workspace.

use super::campaign::CampaignError;
use super::experiment::{Experiment, ExperimentSpec};
use super::figures;
use super::study::run_on_pool;
use crate::identify::Observation;
use crate::instrument::optical_cmm::{OpticalCmm, OpticalCmmSpec};
use crate::robot::RobotModel;
use crate::study::StudySpec;

/// An instrument that measures the TCP over the whole workspace (Table 8's other rows).
#[derive(Clone, Debug, PartialEq)]
pub enum External {
    /// The cell's laser tracker (its SMR on the flange).
    LaserTracker,
    /// An optical CMM placed where the tracker stands.
    OpticalCmm(OpticalCmmSpec),
}

impl External {
    /// The instrument's name in Table 8.
    pub fn label(&self) -> &'static str {
        match self {
            External::LaserTracker => "laser tracker",
            External::OpticalCmm(_) => "optical CMM",
        }
    }
}

/// An identification pool of `count` random workspace configurations of the experiment's robot
/// measured by `instrument`, as observations in {W}.
pub fn external_pool(
    experiment_spec: &ExperimentSpec,
    e: &Experiment,
    seed: u64,
    count: u32,
    instrument: &External,
) -> Result<Vec<Observation>, CampaignError> {
    let pool = match instrument {
        External::LaserTracker => experiment_spec.instrument_pool(e, seed, count, &|p, rng| Some(e.tracker.measure(p, rng)))?,
        External::OpticalCmm(spec) => {
            let cmm = OpticalCmm::new(spec, e.tracker.position_w);
            experiment_spec.instrument_pool(e, seed, count, &|p, rng| cmm.measure(p, rng))?
        }
    };
    Ok(pool.iter().map(|v| Observation { q: v.q, tcp_world_mm: v.measured_w }).collect())
}

/// Table 8's external instruments in one world: the robot calibrated from a pool of `pool_size`
/// random workspace configurations measured by the laser tracker, and by the optical CMM (placed
/// where the tracker stands), each with `spec`'s sets at the table set size; per instrument the
/// medians over repetitions of the validation error's median, std and max, mm.
pub fn external_instruments(
    experiment_spec: &ExperimentSpec,
    e: &Experiment,
    before: &RobotModel,
    spec: &StudySpec,
    seed: u64,
    pool_size: u32,
) -> Result<[[f64; 3]; 2], String> {
    let mut study = spec.clone();
    study.set_sizes = vec![study.table_set_size];
    // Table 8 compares the plain validation only.
    study.compensated_validation = false;
    let n = study.table_set_size as usize;
    let quiet = |_: usize, _: usize| {};
    let run = |instrument: External| -> Result<[f64; 3], String> {
        let obs =
            external_pool(experiment_spec, e, seed, pool_size, &instrument).map_err(|err| format!("{} pool: {err}", what(&instrument)))?;
        let r = run_on_pool(e, before, &study, seed, &obs, &quiet).map_err(|err| err.to_string())?;
        let f = figures::Figures::of(&r, &e.robot.truth, n);
        Ok([f.after_median, f.after_std, f.after_max])
    };
    Ok([run(External::LaserTracker)?, run(External::OpticalCmm(OpticalCmmSpec::default()))?])
}

/// How an instrument's pool is named in errors.
fn what(instrument: &External) -> &'static str {
    match instrument {
        External::LaserTracker => "tracker",
        External::OpticalCmm(_) => "optical CMM",
    }
}
