//! Table 8 of the TriCal paper: the same robot calibrated from pools measured by external
//! instruments (the laser tracker and the optical CMM) over the whole workspace.

use super::experiment::Experiment;
use super::figures;
use super::study::run_on_pool;
use crate::identify::Observation;
use crate::robot::RobotModel;
use crate::study::StudySpec;

/// Table 8's external instruments in one world: the robot calibrated from a pool of `pool_size`
/// random workspace configurations measured by the laser tracker, and by the optical CMM (placed
/// where the tracker stands), each with `spec`'s sets at the table set size; per instrument the
/// medians over repetitions of the validation error's median, std and max, mm.
pub fn external_instruments(
    experiment_spec: &crate::device::trical::experiment::ExperimentSpec,
    e: &Experiment,
    before: &RobotModel,
    spec: &StudySpec,
    seed: u64,
    pool_size: u32,
) -> Result<[[f64; 3]; 2], String> {
    use crate::instrument::optical_cmm::{OpticalCmm, OpticalCmmSpec};
    let mut study = spec.clone();
    study.set_sizes = vec![study.table_set_size];
    // Table 8 compares the plain validation only.
    study.compensated_validation = false;
    let n = study.table_set_size as usize;
    let cmm = OpticalCmm::new(&OpticalCmmSpec::default(), e.tracker.position_w);
    let quiet = |_: usize, _: usize| {};
    let run = |measure: crate::device::trical::campaign::Measure<'_>, what: &str| -> Result<[f64; 3], String> {
        let pool = experiment_spec.instrument_pool(e, seed, pool_size, measure).map_err(|err| format!("{what} pool: {err}"))?;
        let obs: Vec<Observation> = pool.iter().map(|v| Observation { q: v.q, tcp_world_mm: v.measured_w }).collect();
        let r = run_on_pool(e, before, &study, seed, &obs, &quiet).map_err(|err| err.to_string())?;
        let f = figures::Figures::of(&r, &e.robot.truth, n);
        Ok([f.after_median, f.after_std, f.after_max])
    };
    Ok([run(&|p, rng| Some(e.tracker.measure(p, rng)), "tracker")?, run(&|p, rng| cmm.measure(p, rng), "optical CMM")?])
}
