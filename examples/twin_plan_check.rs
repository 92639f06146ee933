//! The plan against the outcome over many files of one generating process: the shipped example's
//! arm and sessions (`calibrate::simulate::example_spec`) at seeds `$1..$2`; per file, the
//! measured held-out median and RMS per coordinate, the twin's decomposition on the calibration
//! split, and (with `$3` > 0 worlds) the plans named in `$5`, with the measured median's place in
//! each plan's worlds (inside P10-P90, above the P90 or below the P10; its rank among the worlds);
//! then, per plan, the count of files inside with its 95 % Clopper-Pearson interval, the counts
//! above and below, the mean rank (0.5 for a plan that is the process itself) and the mean ratio
//! of its median to the first plan's.
//!
//! `$4`: `as-shipped` (default), `no-outlier` (the example without its outlier of line 66), `pure`
//! (no effect outside the model, no repeatability, no outlier: the instrument's noise alone); with
//! `@world` (`as-shipped@world`), the file is not the spec's own draw but one more world of the
//! process plan's (a check of the check: its place among the worlds is then uniform).
//!
//! `$5`: plans, comma separated (default `noise,twin,residual`):
//! - `noise`, `twin`, `residual`: the plans of `calsim calibrate --plan-with`;
//! - `process`: the generating process itself (the true robot in the true frames, the harmonics,
//!   repeatability, noise and outlier of the spec drawn anew in each world at the file's poses): a
//!   plan that is exactly right, the reference the others are set beside;
//! - `true-effects`: the plan's machinery (the calibrated robot in the registered frames, the
//!   flagged point carried) with the spec's own effects, repeatability and noise drawn per world;
//! - `effects-4x20`, `effects-1x1000`: `true-effects` with the spec's harmonic as four per joint of
//!   half its amplitude (the same RMS), or as one of orders 1000-4000 per turn;
//! - `twin-true-level`: the twin's plan with its per-pose error at the spec's RMS per joint (one
//!   harmonic of amplitude a has RMS a / sqrt 2), the spec's repeatability and noise, no spread.
//!
//! Usage: cargo run --release --example twin_plan_check -- FIRST_SEED LAST_SEED [WORLDS [VARIANT [PLANS]]]
use std::path::Path;

use calsim::calibrate::plan::{Basis, Effects, Noise, Statistic, compare_values, residual_noise_mm, simulate_basis};
use calsim::calibrate::simulate::SimulationSpec;
use nalgebra::Vector3;
use rand_distr::{Distribution, Normal};

/// World `w` of the spec's own process: the spec's file with its poses and the world's own draws of
/// the robot's effects, its moves' noise and the instrument's noise (the outliers added as in the
/// spec).
fn process_world(spec: &SimulationSpec, w: u64) -> String {
    let rng = calsim::seeds::stream(calsim::seeds::split_seed(spec.seed, 1_000_000 + w), calsim::seeds::calibrate::SIMULATED_NOISE);
    process_file(spec, rng)
}

/// The spec's file (its sessions of random poses, no line, no coupling) with the draws of the
/// robot's effects and the noises from `rng`: with the spec's own stream, the spec's file itself
/// (checked at every seed).
fn process_file(spec: &SimulationSpec, mut rng: rand_chacha::ChaCha8Rng) -> String {
    use calsim::robot::{KinState, VirtualRobot, forward};
    let mut poses = calsim::seeds::stream(spec.seed, calsim::seeds::calibrate::SIMULATED_POSES);
    let reference: calsim::robot::Joints = std::array::from_fn(|i| {
        let l = spec.truth.limits()[i];
        0.5 * (l.min + l.max)
    });
    let robot = VirtualRobot::new(spec.truth.clone(), &spec.unmodelled, spec.repeatability_mm, &reference, &mut rng);
    let noise = Normal::new(0.0, spec.noise_mm).expect("finite noise");
    let mut st = KinState::default();
    let mut from = reference;
    let mut rows = Vec::new();
    for (s, (session, frame)) in spec.sessions.iter().enumerate() {
        for k in 0..spec.poses_per_session {
            let q = calsim::robot::uniform_configuration(&spec.truth, spec.margin, &mut poses);
            let links = robot.link_angles(&q, &from, &mut rng);
            from = q;
            for (target, tool) in &spec.targets {
                let model = spec
                    .truth
                    .edited(|d| {
                        d.world_from_base = *frame;
                        d.flange_tcp_mm = *tool;
                    })
                    .expect("placed");
                let p = forward(&model, &mut st, &links) + Vector3::from_fn(|_, _| noise.sample(&mut rng));
                rows.push((format!("p{:03}", s * spec.poses_per_session + k + 1), session.clone(), target.clone(), q, p));
            }
        }
    }
    for (row, error) in &spec.outliers {
        if let Some(r) = rows.get_mut(*row) {
            r.4 += error;
        }
    }
    let mut text = String::from("# simulated = true\n");
    text += &format!("# format = {}\n", calsim::calibrate::measurements::FORMAT);
    for c in &spec.comments {
        text += &format!("# {c}\n");
    }
    text += "pose,session,target,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,x_mm,y_mm,z_mm\n";
    for (pose, session, target, q, p) in rows {
        let q: Vec<String> = q.iter().map(|v| format!("{}", v.to_degrees())).collect();
        text += &format!("{pose},{session},{target},{},{},{},{}\n", q.join(","), p.x, p.y, p.z);
    }
    text
}

/// P(X <= k) for X binomial(n, p).
fn binomial_cdf(k: usize, n: usize, p: f64) -> f64 {
    let mut term = (1.0 - p).powi(n as i32);
    let mut sum = 0.0;
    for i in 0..=k {
        if i > 0 {
            term *= (n - i + 1) as f64 / i as f64 * p / (1.0 - p);
        }
        sum += term;
    }
    sum.min(1.0)
}

/// The 95 % Clopper-Pearson interval of a binomial proportion, `k` of `n`.
fn clopper_pearson(k: usize, n: usize) -> (f64, f64) {
    let solve = |f: &dyn Fn(f64) -> f64| {
        let (mut lo, mut hi) = (0.0f64, 1.0f64);
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if f(mid) > 0.0 { lo = mid } else { hi = mid }
        }
        0.5 * (lo + hi)
    };
    let lower = if k == 0 { 0.0 } else { solve(&|p| 0.025 - (1.0 - binomial_cdf(k - 1, n, p))) };
    let upper = if k == n { 1.0 } else { solve(&|p| binomial_cdf(k, n, p) - 0.025) };
    (lower, upper)
}

#[derive(Default)]
struct Tally {
    inside: usize,
    above: usize,
    below: usize,
    ranks: Vec<f64>,
    median_over_first: Vec<f64>,
    failed: usize,
}

/// Mean and standard error of the mean (`NaN` below two values).
fn mean_se(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, if v.len() > 1 { (var / n).sqrt() } else { f64::NAN })
}

fn main() -> std::process::ExitCode {
    // Bad input: one line, `error: ...`, exit 2, as calsim's commands.
    calsim::app::message::exit_code(run())
}

fn run() -> Result<(), String> {
    let args: Vec<u64> =
        std::env::args().skip(1).take(3).map(|a| a.parse::<u64>().map_err(|e| format!("{a}: {e}"))).collect::<Result<_, _>>()?;
    let (first, last, worlds) =
        (args.first().copied().unwrap_or(35), args.get(1).copied().unwrap_or(35), args.get(2).copied().unwrap_or(0));
    let variant_arg = std::env::args().nth(4).unwrap_or_else(|| "as-shipped".into());
    let (variant, from_world) = match variant_arg.split_once('@') {
        Some((v, "world")) => (v.to_string(), true),
        Some((_, w)) => return Err(format!("{w}: the only suffix is @world")),
        None => (variant_arg.clone(), false),
    };
    let plans: Vec<String> = std::env::args().nth(5).unwrap_or_else(|| "noise,twin,residual".into()).split(',').map(String::from).collect();
    let robot = calsim::robot::file::RobotFile::load(Path::new("robots/irb120.toml")).map_err(|e| e.to_string())?;
    println!(
        "seed | held-out median | held-out RMS/coord | train total | instrument | left | pose_error_mdeg (std) | kept | flagged point's error after | {}",
        plans.iter().map(|p| format!("{p} P10-P90 (rank)")).collect::<Vec<_>>().join(" | ")
    );
    let mut tallies: Vec<Tally> = plans.iter().map(|_| Tally::default()).collect();
    // Per file: the held-out median, the held-out RMS per coordinate over the training residual per
    // coordinate, the twin's per-pose error and its count of kept effects.
    let (mut medians, mut inflation, mut pose_errors, mut kept) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for seed in first..=last {
        let mut spec = SimulationSpec { seed, ..calsim::calibrate::simulate::example_spec(&robot)? };
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
        let text = calsim::calibrate::simulate::to_csv(&spec).map_err(|e| e.to_string())?;
        if !(spec.lines.is_empty() && spec.coupling.is_none() && spec.learned.is_none() && spec.repeats_per_session == 0)
            || text != process_file(&spec, calsim::seeds::stream(spec.seed, calsim::seeds::calibrate::SIMULATED_NOISE))
        {
            return Err(format!("seed {seed}: the process plan's worlds do not follow the spec's own process"));
        }
        let text = if from_world { process_world(&spec, u32::MAX as u64) } else { text };
        let m = calsim::calibrate::measurements::parse(Path::new("example.csv"), &text, &robot).map_err(|e| e.to_string())?;
        let opts = calsim::calibrate::Options { plots: false, ..Default::default() };
        let c = calsim::calibrate::run(&robot, &m, &opts).map_err(|e| e.to_string())?;
        let t = calsim::calibrate::twin::analyse(&c, None).map_err(|e| e.to_string())?;
        let h = &c.chosen().held_out.as_ref().ok_or("no held-out")?.measured;
        let d = &t.decomposition;
        medians.push(h.median);
        inflation.push(h.rms / 3f64.sqrt() / d.total.sigma_mm);
        pose_errors.push(t.learned.pose_error_mdeg);
        kept.push(t.effects.len() as f64);
        let flagged: Vec<String> =
            (0..m.points.len()).filter(|&i| c.flagged[i]).map(|i| format!("{:.3}", c.chosen().fit.errors_mm[i])).collect();
        let mut line = format!(
            "{seed} | {:.4} | {:.4} | {:.4} | {:.4} | {:.4} | {:.3} ({:.3}) | {} | {}",
            h.median,
            h.rms / 3f64.sqrt(),
            d.total.sigma_mm,
            d.instrument.as_ref().map_or(f64::NAN, |l| l.sigma_mm),
            d.left.as_ref().map_or(f64::NAN, |l| l.sigma_mm),
            t.learned.pose_error_mdeg,
            t.learned.pose_error_std_mdeg,
            t.effects.len(),
            if flagged.is_empty() { "-".into() } else { flagged.join(" ") }
        );
        if worlds > 0 {
            let noise = t.noise_mm.unwrap_or(0.0);
            let learned = t.plan_effects();
            let true_effects = Effects {
                source: "the spec".into(),
                unmodelled: spec.unmodelled.clone(),
                repeatability_mm: spec.repeatability_mm,
                learned: None,
            };
            // The spec's harmonics as four per joint of half the amplitude (the same RMS), and as one of
            // orders 1000-4000.
            let mut four_low = true_effects.clone();
            four_low.unmodelled.transmission_high_mdeg /= 2.0;
            four_low.unmodelled.transmission_high_count = Some(4);
            let mut one_high = true_effects.clone();
            one_high.unmodelled.transmission_high_orders = Some([1000, 4000]);
            let true_level = calsim::robot::learned::LearnedEffects {
                pose_error_mdeg: spec.unmodelled.transmission_high_mdeg / 2f64.sqrt(),
                pose_error_std_mdeg: 0.0,
                repeatability_mm: spec.repeatability_mm,
                ..learned.clone()
            };
            let mut first_median = f64::NAN;
            for (k, plan) in plans.iter().enumerate() {
                let per_world: Vec<f64> = match plan.as_str() {
                    "process" => {
                        use rayon::prelude::*;
                        let per: Vec<f64> = (0..worlds)
                            .into_par_iter()
                            .map(|w| {
                                let text = process_world(&spec, w);
                                calsim::calibrate::measurements::parse(Path::new("world.csv"), &text, &robot)
                                    .ok()
                                    .and_then(|mw| calsim::calibrate::run(&robot, &mw, &opts).ok())
                                    .and_then(|cw| cw.chosen().held_out.as_ref().map(|h| h.measured.median))
                                    .unwrap_or(f64::NAN)
                            })
                            .collect();
                        per
                    }
                    name => {
                        let basis = match name {
                            "noise" => Basis { noise: Noise::Fixed(noise), effects: None, twin: None, label: None },
                            "twin" => Basis { noise: Noise::Fixed(noise), effects: None, twin: Some((&t.model, &learned)), label: None },
                            "residual" => Basis { noise: Noise::PointsElse(residual_noise_mm(&c)), effects: None, twin: None, label: None },
                            "true-effects" => {
                                Basis { noise: Noise::Fixed(spec.noise_mm), effects: Some(&true_effects), twin: None, label: None }
                            }
                            "effects-4x20" => {
                                Basis { noise: Noise::Fixed(spec.noise_mm), effects: Some(&four_low), twin: None, label: None }
                            }
                            "effects-1x1000" => {
                                Basis { noise: Noise::Fixed(spec.noise_mm), effects: Some(&one_high), twin: None, label: None }
                            }
                            "twin-true-level" => Basis {
                                noise: Noise::Fixed(spec.noise_mm),
                                effects: None,
                                twin: Some((&t.model, &true_level)),
                                label: None,
                            },
                            p => return Err(format!("{p}: not a plan of this check (see its doc)")),
                        };
                        simulate_basis(&c, worlds as usize, Statistic::Median, c.options.seed, &basis)
                            .map_err(|e| e.to_string())?
                            .per_world_mm
                    }
                };
                let p = compare_values(h.median, &per_world);
                let finite: Vec<f64> = per_world.iter().copied().filter(|v| v.is_finite()).collect();
                let rank = finite.iter().filter(|&&v| v < h.median).count() as f64 / finite.len().max(1) as f64;
                let tally = &mut tallies[k];
                let place = if p.inside {
                    tally.inside += 1;
                    "in"
                } else if h.median > p.simulated_mm[2] {
                    tally.above += 1;
                    "ABOVE"
                } else {
                    tally.below += 1;
                    "BELOW"
                };
                tally.ranks.push(rank);
                tally.failed += per_world.len() - finite.len();
                if k == 0 {
                    first_median = p.simulated_mm[1];
                } else {
                    tally.median_over_first.push(p.simulated_mm[1] / first_median);
                }
                line += &format!(" | {:.4}-{:.4}-{:.4} {place} ({rank:.2})", p.simulated_mm[0], p.simulated_mm[1], p.simulated_mm[2]);
            }
        }
        println!("{line} | {} | held-out points {}", c.chosen().name(), c.chosen().held_out.as_ref().map_or(0, |h| h.points));
    }
    let files = (last + 1 - first) as usize;
    println!(
        "\nfiles | held-out median, mm (mean, s.e.) | held-out RMS per coordinate over the training residual per coordinate (mean, s.e.) | pose_error_mdeg (mean, s.e.) | kept coefficients (mean)"
    );
    let (a, b, e, k) = (mean_se(&medians), mean_se(&inflation), mean_se(&pose_errors), mean_se(&kept));
    println!("{files} | {:.4} ({:.4}) | {:.3} ({:.3}) | {:.3} ({:.3}) | {:.2}", a.0, a.1, b.0, b.1, e.0, e.1, k.0);
    if worlds > 0 {
        println!(
            "\nplan | inside P10-P90 of {files} (95 % Clopper-Pearson) | above P90 | below P10 | mean rank (s.e.) | median over the first plan's (mean, s.e.) | worlds without a value"
        );
        for (plan, t) in plans.iter().zip(&tallies) {
            let (lo, hi) = clopper_pearson(t.inside, files);
            let ratio = if t.median_over_first.is_empty() {
                "-".to_string()
            } else {
                let (m, se) = mean_se(&t.median_over_first);
                format!("{m:.3} ({se:.3})")
            };
            let rank = mean_se(&t.ranks);
            println!(
                "{plan} | {} ({lo:.2}-{hi:.2}) | {} | {} | {:.3} ({:.3}) | {ratio} | {}",
                t.inside, t.above, t.below, rank.0, rank.1, t.failed
            );
        }
        let exact = 0.8 * (worlds as f64 - 1.0) / (worlds as f64 + 1.0);
        println!("an exact plan: inside with probability {exact:.3} per file (mean rank 0.5)");
    }
    Ok(())
}
