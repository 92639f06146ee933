//! Identifies the paper's IRB 120 (Table 7 truth) from random TCP positions with position noise,
//! with no cell and no instruments, and validates it: the identification kernel on its own.
//!
//! `cargo run --release --example demo -- [--configurations 75] [--validation 506] [--noise-um 10]
//! [--seed 1] [--solver gn|lm]`

use std::process::ExitCode;
use std::time::Instant;

use clap::{Parser, ValueEnum};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use calsim::identify::{FitOptions, Observation, Solver, identify};
use calsim::robot::builtin::{trical_2018_nominal, trical_2018_table7};
use calsim::robot::uniform_configuration;
use calsim::robot::{KinState, ParamSet, forward};

#[derive(ValueEnum, Clone, Copy, Debug)]
enum SolverArg {
    /// Gauss-Newton with the pseudo-inverse step (paper eqs. 14-15).
    Gn,
    /// Levenberg-Marquardt.
    Lm,
}

/// Identify the paper's IRB 120 (Table 7 truth) from simulated TCP positions and validate it.
#[derive(Parser, Debug)]
struct Args {
    /// Configurations used for identification (random, inside the joint limits).
    #[arg(long, default_value_t = 75, value_parser = clap::value_parser!(u32).range(1..=100_000))]
    configurations: u32,
    /// Validation configurations.
    #[arg(long, default_value_t = 506, value_parser = clap::value_parser!(u32).range(1..=1_000_000))]
    validation: u32,
    /// Standard deviation of the position noise on each measured coordinate, um.
    #[arg(long, default_value_t = 10.0)]
    noise_um: f64,
    /// Seed of the random streams.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Solver.
    #[arg(long, value_enum, default_value_t = SolverArg::Gn)]
    solver: SolverArg,
}

fn main() -> ExitCode {
    calsim::app::message::exit_code(demo(&Args::parse()))
}

fn demo(args: &Args) -> Result<(), String> {
    if !(args.noise_um.is_finite() && args.noise_um >= 0.0) {
        return Err(format!("--noise-um {}: must be a finite number >= 0", args.noise_um));
    }
    let t0 = Instant::now();
    let truth = trical_2018_table7();
    let nominal = trical_2018_nominal();
    let set = ParamSet::trical_31();
    let mut rng = ChaCha8Rng::seed_from_u64(args.seed);
    let noise = Normal::new(0.0, args.noise_um * 1e-3).map_err(|e| e.to_string())?;
    let mut st = KinState::default();
    let obs: Vec<Observation> = (0..args.configurations)
        .map(|_| {
            let q = uniform_configuration(&truth, 0.1, &mut rng);
            let mut p = forward(&truth, &mut st, &q);
            for k in 0..3 {
                p[k] += noise.sample(&mut rng);
            }
            Observation { q, tcp_world_mm: p }
        })
        .collect();
    let solver = match args.solver {
        SolverArg::Gn => Solver::GaussNewton,
        SolverArg::Lm => Solver::LevenbergMarquardt { tau: 1e-3 },
    };
    let t_fit = Instant::now();
    let fit = identify(&nominal, &set, &obs, &FitOptions { solver, ..FitOptions::default() });
    let fit_s = t_fit.elapsed().as_secs_f64();

    println!(
        "calsim demo: {} ({} configurations, noise {} um per axis, seed {})",
        truth.name(),
        args.configurations,
        args.noise_um,
        args.seed
    );
    println!(
        "outcome {}, {} iterations, condition number {:.1}, residual RMS {:.4} mm, {:.0} us",
        fit.outcome.label(),
        fit.iterations,
        fit.condition_number,
        fit.residual_rms_mm,
        fit_s * 1e6
    );
    println!("\n{:<12} {:>11} {:>12} {:>12} {:>12}  unit", "parameter", "nominal", "truth", "identified", "error");
    for (id, v) in set.ids().iter().zip(&fit.values) {
        let u = id.unit();
        let nom = u.from_internal(id.get(nominal.data()));
        let tru = u.from_internal(id.get(truth.data()));
        match v {
            Some(v) => {
                let v = u.from_internal(*v);
                println!("{:<12} {:>11.3} {:>12.4} {:>12.4} {:>12.5}  {}", id.name(), nom, tru, v, v - tru, u.symbol());
            }
            None => println!("{:<12} {:>11.3} {:>12.4} {:>12} {:>12}  {}", id.name(), nom, tru, "-", "-", u.symbol()),
        }
    }
    let validation: Vec<calsim::robot::Joints> = (0..args.validation).map(|_| uniform_configuration(&truth, 0.0, &mut rng)).collect();
    let stats = |model: &calsim::robot::RobotModel| {
        let mut st = KinState::default();
        let mut st2 = KinState::default();
        let errs: Vec<f64> = validation.iter().map(|q| (forward(model, &mut st, q) - forward(&truth, &mut st2, q)).norm()).collect();
        let mean = errs.iter().sum::<f64>() / errs.len() as f64;
        let max = errs.iter().copied().fold(0.0, f64::max);
        (mean, max)
    };
    let (b_mean, b_max) = stats(&nominal);
    println!("\nvalidation over {} random configurations (position error against the truth):", args.validation);
    println!("  before calibration: mean {b_mean:.3} mm, max {b_max:.3} mm");
    if let Some(model) = &fit.model {
        let (a_mean, a_max) = stats(model);
        println!("  after calibration:  mean {a_mean:.4} mm, max {a_max:.4} mm");
    }
    println!("total {:.3} s", t0.elapsed().as_secs_f64());
    Ok(())
}
