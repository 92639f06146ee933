//! Coverage of the twin's smooth-field intervals: for each true length, `WORLDS` worlds (world `w`
//! of length index `i` seeded `1000 (i + 1) + w`), each the IRB 120 with Table 7's parameters at
//! 100 random poses per session of the shipped example's 3 sessions and 2 targets (12 um noise),
//! its link angles moved by a smooth per-pose field drawn by calsim (`[learned]`
//! `pose_error_mdeg = 20`, `pose_error_length_rad` the true length), calibrated and its twin
//! analysed. Per length: the worlds that gave a length, the median fitted length with its P10-P90
//! over them, and how many of their 95 % intervals hold the true length and the true level
//! (Wilson 95 % intervals of those shares), for the bootstrap's basic interval (in log scale) and
//! its percentile interval; and the replicates censored at the ends of the lengths tried.
//!
//! `cargo run --release --example twin_length_coverage -- WORLDS LENGTHS` (e.g. `40 0.5,1.5,4.0`),
//! from the repository root.

use std::path::Path;

use calsim::calibrate::simulate::{SimulationSpec, example_spec, joint_error_csv};
use calsim::calibrate::twin::shape::BOOTSTRAP_REPLICATES;
use calsim::calibrate::{Options, default_params, measurements, run};
use calsim::robot::file::RobotFile;
use calsim::robot::{LearnedEffects, ParamSet, RobotModel, UnmodelledSpec};
use rand::SeedableRng;

/// The field's level per joint, mdeg.
const LEVEL_MDEG: f64 = 20.0;
/// The two-sided 95 % normal quantile.
const Z95: f64 = 1.959_963_984_540_054;

/// The IRB 120 with Table 7's values of the default parameters.
fn truth(robot: &RobotFile) -> Result<RobotModel, String> {
    let set = default_params();
    let deviated: Vec<(calsim::robot::ParamId, f64)> = robot.truth.iter().filter(|(id, _)| set.position(*id).is_some()).copied().collect();
    let values: Vec<f64> = deviated.iter().map(|(_, v)| *v).collect();
    ParamSet::new(deviated.iter().map(|(id, _)| *id).collect())
        .map_err(|e| e.to_string())?
        .unpack(&robot.nominal, &values)
        .map_err(|e| e.to_string())
}

/// One world's fitted length and its intervals (the basic one and the percentile one),
/// the level's likewise (mdeg), and its replicates censored at the grid's ends, when the twin
/// gives a length.
struct Fitted {
    length: f64,
    interval: [[f64; 2]; 2],
    level_mdeg: [[f64; 2]; 2],
    censored: usize,
}

fn world(robot: &RobotFile, truth: &RobotModel, length: f64, seed: u64) -> Result<Option<Fitted>, String> {
    let field = LearnedEffects { pose_error_mdeg: LEVEL_MDEG, pose_error_length_rad: length, ..LearnedEffects::default() };
    let drawn = field.draw(truth, &mut rand_chacha::ChaCha8Rng::seed_from_u64(seed));
    let spec = SimulationSpec {
        truth: truth.clone(),
        unmodelled: UnmodelledSpec::default(),
        repeatability_mm: 0.0,
        learned: None,
        repeats_per_session: 0,
        poses_per_session: 100,
        noise_mm: 0.012,
        outliers: vec![],
        seed,
        ..example_spec(robot)?
    };
    let text = joint_error_csv(&spec, &mut rand_chacha::ChaCha8Rng::seed_from_u64(seed), |q, _| drawn.joint_errors(q, q));
    let m = measurements::parse(Path::new("field.csv"), &text, robot).map_err(|e| e.to_string())?;
    let c = run(robot, &m, &Options { plots: false, prediction_draws: 10, ..Options::default() }).map_err(|e| e.to_string())?;
    let t = calsim::calibrate::twin::analyse(&c, None).map_err(|e| e.to_string())?;
    Ok(t.length.as_ref().map(|s| {
        let mdeg = |[a, b]: [f64; 2]| [a.to_degrees() * 1e3, b.to_degrees() * 1e3];
        Fitted {
            length: s.length_rad,
            interval: [s.basic[0], s.percentile[0]],
            level_mdeg: [mdeg(s.basic[1]), mdeg(s.percentile[1])],
            censored: s.censored[0] + s.censored[1],
        }
    }))
}

/// The Wilson 95 % interval of `k` successes in `n`, in %.
fn wilson(k: usize, n: usize) -> [f64; 2] {
    if n == 0 {
        return [f64::NAN; 2];
    }
    let (n, p) = (n as f64, k as f64 / n as f64);
    let z2 = Z95 * Z95;
    let centre = (p + z2 / (2.0 * n)) / (1.0 + z2 / n);
    let half = Z95 * (p * (1.0 - p) / n + z2 / (4.0 * n * n)).sqrt() / (1.0 + z2 / n);
    [100.0 * (centre - half), 100.0 * (centre + half)]
}

/// The value at fraction `f` of sorted `v` (nearest rank).
fn quantile(v: &[f64], f: f64) -> f64 {
    v[((f * (v.len() - 1) as f64).round() as usize).min(v.len() - 1)]
}

fn main() -> std::process::ExitCode {
    // Bad input: one line, `error: ...`, exit 2, as calsim's commands.
    calsim::app::message::exit_code(coverage())
}

fn coverage() -> Result<(), String> {
    let usage = "usage: twin_length_coverage WORLDS LENGTHS (e.g. 40 0.5,1.5,4.0)";
    let args: Vec<String> = std::env::args().skip(1).collect();
    let worlds: u64 = args.first().and_then(|a| a.parse().ok()).filter(|&w| w > 0).ok_or(usage)?;
    let lengths: Vec<f64> = args
        .get(1)
        .ok_or(usage)?
        .split(',')
        .map(|x| {
            x.trim().parse::<f64>().ok().filter(|v| v.is_finite() && *v > 0.0).ok_or(format!("LENGTHS: {x:?} is not a positive length"))
        })
        .collect::<Result<_, _>>()?;
    let robot = RobotFile::load(Path::new("robots/irb120.toml")).map_err(|e| e.to_string())?;
    let truth = truth(&robot)?;
    println!("{worlds} worlds per length, level {LEVEL_MDEG} mdeg per joint; intervals: basic (log) / percentile bootstrap");
    println!(
        "| true length (rad) | worlds with a length | median length (P10-P90) | length covered, basic | length covered, percentile | level \
         covered, basic | level covered, percentile | replicates censored |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for (i, &length) in lengths.iter().enumerate() {
        let mut fitted = Vec::new();
        for w in 0..worlds {
            if let Some(f) = world(&robot, &truth, length, 1000 * (i as u64 + 1) + w)? {
                fitted.push(f);
            }
        }
        let n = fitted.len();
        let mut ls: Vec<f64> = fitted.iter().map(|f| f.length).collect();
        ls.sort_by(f64::total_cmp);
        let covered = |k: usize| {
            let w = wilson(k, n);
            format!("{k} of {n}: {:.0} % ({:.0}-{:.0})", 100.0 * k as f64 / n.max(1) as f64, w[0], w[1])
        };
        let inside = |[lo, hi]: [f64; 2], x: f64| lo <= x && x <= hi;
        let cells: Vec<String> = [0, 1]
            .iter()
            .map(|&k| covered(fitted.iter().filter(|f| inside(f.interval[k], length)).count()))
            .chain([0, 1].iter().map(|&k| covered(fitted.iter().filter(|f| inside(f.level_mdeg[k], LEVEL_MDEG)).count())))
            .collect();
        let spread =
            if n > 0 { format!("{:.2} ({:.2}-{:.2})", quantile(&ls, 0.5), quantile(&ls, 0.1), quantile(&ls, 0.9)) } else { "-".into() };
        let censored: usize = fitted.iter().map(|f| f.censored).sum();
        println!("| {length} | {n} of {worlds} | {spread} | {} | {censored} of {} |", cells.join(" | "), n * BOOTSTRAP_REPLICATES);
    }
    Ok(())
}
