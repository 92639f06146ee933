//! The plan against the outcome over many files of one generating process: the shipped example's
//! arm and sessions (`calibrate::simulate::example_spec`) at seeds `$1..$2`; per file, the
//! measured held-out median and RMS per coordinate, the twin's decomposition on the calibration
//! split, and (with `$3` > 0 worlds) the plans with noise only, the twin and the residual as
//! noise, and whether the measured median lies within each plan's P10-P90.
//!
//! `$4`: `as-shipped` (default), `no-outlier` (the example without its outlier of line 66), `pure`
//! (no effect outside the model, no repeatability, no outlier: the instrument's noise alone).
//!
//! Usage: cargo run --release --example twin_plan_check -- FIRST_SEED LAST_SEED [WORLDS [VARIANT]]
use std::path::Path;

use calsim::calibrate::plan::{Basis, Noise, Statistic, compare, residual_noise_mm, simulate_basis};

fn main() -> Result<(), String> {
    let args: Vec<u64> =
        std::env::args().skip(1).take(3).map(|a| a.parse::<u64>().map_err(|e| format!("{a}: {e}"))).collect::<Result<_, _>>()?;
    let (first, last, worlds) =
        (args.first().copied().unwrap_or(35), args.get(1).copied().unwrap_or(35), args.get(2).copied().unwrap_or(0));
    let variant = std::env::args().nth(4).unwrap_or_else(|| "as-shipped".into());
    let robot = calsim::robot::file::RobotFile::load(Path::new("robots/irb120.toml")).map_err(|e| e.to_string())?;
    println!(
        "seed | held-out median | held-out RMS/coord | train total | instrument | left | pose_error_mdeg | kept | noise P10-P90 | twin P10-P90 | residual P10-P90"
    );
    for seed in first..=last {
        let mut spec = calsim::calibrate::simulate::SimulationSpec { seed, ..calsim::calibrate::simulate::example_spec(&robot)? };
        match variant.as_str() {
            "as-shipped" => {}
            "no-outlier" => spec.outliers.clear(),
            "pure" => {
                spec.unmodelled = calsim::robot::UnmodelledSpec::default();
                spec.repeatability_mm = 0.0;
                spec.outliers.clear();
            }
            v => return Err(format!("{v}: as-shipped, no-outlier or pure")),
        }
        let m = calsim::calibrate::measurements::parse(Path::new("example.csv"), &calsim::calibrate::simulate::to_csv(&spec), &robot)
            .map_err(|e| e.to_string())?;
        let c = calsim::calibrate::run(&robot, &m, &calsim::calibrate::Options { plots: false, ..Default::default() })
            .map_err(|e| e.to_string())?;
        let t = calsim::calibrate::twin::analyse(&c, None).map_err(|e| e.to_string())?;
        let h = &c.chosen().held_out.as_ref().ok_or("no held-out")?.measured;
        let d = &t.decomposition;
        let mut line = format!(
            "{seed} | {:.4} | {:.4} | {:.4} | {:.4} | {:.4} | {:.3} | {}",
            h.median,
            h.rms / 3f64.sqrt(),
            d.total.sigma_mm,
            d.instrument.as_ref().map_or(f64::NAN, |l| l.sigma_mm),
            d.left.as_ref().map_or(f64::NAN, |l| l.sigma_mm),
            t.learned.pose_error_mdeg,
            t.effects.len()
        );
        if worlds > 0 {
            let noise = t.noise_mm.unwrap_or(0.0);
            let learned = t.plan_effects();
            let bases = [
                Basis { noise: Noise::Fixed(noise), effects: None, twin: None, label: None },
                Basis { noise: Noise::Fixed(noise), effects: None, twin: Some((&t.model, &learned)), label: None },
                Basis { noise: Noise::PointsElse(residual_noise_mm(&c)), effects: None, twin: None, label: None },
            ];
            for b in &bases {
                let sim = simulate_basis(&c, worlds as usize, Statistic::Median, c.options.seed, b).map_err(|e| e.to_string())?;
                let p = compare(&c, &sim);
                line += &format!(" | {:.4}-{:.4}{}", p.simulated_mm[0], p.simulated_mm[2], if p.inside { " in" } else { " OUT" });
            }
        }
        println!("{line} | {} | held-out points {}", c.chosen().name(), c.chosen().held_out.as_ref().map_or(0, |h| h.points));
    }
    Ok(())
}
