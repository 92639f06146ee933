//! The intervals calsim reports cover the true value as often as they claim: 2,000 simulated
//! studies per case at the 95 % level, at small and large counts, must cover in at least 93 % of
//! them (the 2,000-trial estimate of a 95 % coverage has a standard error of 0.5 %).

use calsim::study::interval::{bootstrap_t, clopper_pearson, median_interval, ratio_of_means};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Beta, Distribution, LogNormal, Normal, StandardNormal};

const TRIALS: usize = 2_000;
const LEAST: f64 = 0.93;

/// Clopper-Pearson over binary outcomes: 10, 20, 50 and 200 worlds, P = 0.5 to 0.99.
#[test]
fn clopper_pearson_covers_binary_outcomes_at_small_and_large_counts() {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut worst = (1.0, 0, 0.0);
    for n in [10usize, 20, 50, 200] {
        for p in [0.5, 0.8, 0.95, 0.99] {
            let covered = (0..TRIALS)
                .filter(|_| {
                    let k = (0..n).filter(|_| rng.random::<f64>() < p).count();
                    let (lo, hi) = clopper_pearson(k as f64, n as f64, 0.95);
                    lo <= p && p <= hi
                })
                .count() as f64
                / TRIALS as f64;
            if covered < worst.0 {
                worst = (covered, n, p);
            }
        }
    }
    eprintln!("worst coverage {:.3} at {} worlds, P = {}", worst.0, worst.1, worst.2);
    assert!(worst.0 >= LEAST, "coverage {:.3} at {} worlds, P = {}", worst.0, worst.1, worst.2);
}

/// Clopper-Pearson over worlds whose repetitions succeed together or apart: R worlds of m
/// repetitions, each world's success probability drawn from a Beta law of mean P whose intra-world
/// correlation is 0, 0.3 or 1; the interval takes R trials and R times the mean fraction.
#[test]
fn clopper_pearson_over_worlds_covers_correlated_repetitions() {
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let mut worst = (1.0, String::new());
    for r in [10usize, 40, 200] {
        for m in [1usize, 5, 30] {
            for rho in [0.0, 0.3, 1.0] {
                for p in [0.6, 0.9, 0.97] {
                    let covered = (0..TRIALS)
                        .filter(|_| {
                            let mean_fraction = (0..r)
                                .map(|_| {
                                    // Beta(a, b) of mean p and ICC rho = 1 / (a + b + 1).
                                    let q = if rho == 0.0 {
                                        p
                                    } else if rho == 1.0 {
                                        f64::from(rng.random::<f64>() < p)
                                    } else {
                                        let s = 1.0 / rho - 1.0;
                                        Beta::new(p * s, (1.0 - p) * s).unwrap().sample(&mut rng)
                                    };
                                    (0..m).filter(|_| rng.random::<f64>() < q).count() as f64 / m as f64
                                })
                                .sum::<f64>()
                                / r as f64;
                            let (lo, hi) = clopper_pearson(mean_fraction * r as f64, r as f64, 0.95);
                            lo <= p && p <= hi
                        })
                        .count() as f64
                        / TRIALS as f64;
                    if covered < worst.0 {
                        worst = (covered, format!("R {r}, m {m}, rho {rho}, P {p}"));
                    }
                }
            }
        }
    }
    eprintln!("worst coverage {:.3} at {}", worst.0, worst.1);
    assert!(worst.0 >= LEAST, "coverage {:.3} at {}", worst.0, worst.1);
}

/// The order-statistic interval of the median: 6 to 200 worlds, normal, skewed and uniform laws.
#[test]
fn the_median_interval_covers_any_continuous_law() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let laws: [(&str, Box<dyn Fn(&mut ChaCha8Rng) -> f64>, f64); 3] = [
        ("normal", Box::new(|r: &mut ChaCha8Rng| Normal::new(0.4, 0.1).unwrap().sample(r)), 0.4),
        ("lognormal", Box::new(|r: &mut ChaCha8Rng| LogNormal::new(-1.0, 0.8).unwrap().sample(r)), (-1.0f64).exp()),
        ("uniform", Box::new(|r: &mut ChaCha8Rng| r.random::<f64>()), 0.5),
    ];
    let mut worst = (1.0, String::new());
    for n in [6usize, 10, 20, 50, 200] {
        for (name, draw, median) in &laws {
            let covered = (0..TRIALS)
                .filter(|_| {
                    let v: Vec<f64> = (0..n).map(|_| draw(&mut rng)).collect();
                    let (lo, hi) = median_interval(&v, 0.95);
                    lo <= *median && *median <= hi
                })
                .count() as f64
                / TRIALS as f64;
            if covered < worst.0 {
                worst = (covered, format!("{n} worlds, {name}"));
            }
        }
    }
    eprintln!("worst coverage {:.3} at {}", worst.0, worst.1);
    assert!(worst.0 >= LEAST, "coverage {:.3} at {}", worst.0, worst.1);
}

/// The bootstrap-t of a budget-like share: three sources whose per-world effects are skewed and
/// correlated, the share of the first the ratio of its mean effect to the sum of the means; 20, 50
/// and 200 worlds, 999 resamples each.
#[test]
fn the_bootstrap_t_covers_a_share_of_correlated_skewed_effects() {
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    let means = [0.30, 0.05, 0.02];
    let truth = means[0] / means.iter().sum::<f64>();
    let mut worst = (1.0, 0);
    for n in [20usize, 50, 200] {
        let trials = TRIALS;
        let covered = (0..trials)
            .filter(|_| {
                // Per world: a common factor and one per source, lognormal with mean 1.
                let effects: Vec<[f64; 3]> = (0..n)
                    .map(|_| {
                        let common: f64 = rng.sample(StandardNormal);
                        std::array::from_fn(|k| {
                            let own: f64 = rng.sample(StandardNormal);
                            let z = 0.6 * common + 0.8 * own;
                            means[k] * (0.7 * z - 0.245).exp()
                        })
                    })
                    .collect();
                let rows: Vec<Vec<f64>> = effects.iter().map(|e| e.to_vec()).collect();
                let (lo, hi) = bootstrap_t(n, |idx| ratio_of_means(&rows, 0, idx), 999, 0.95, &mut rng);
                lo <= truth && truth <= hi
            })
            .count() as f64
            / trials as f64;
        if covered < worst.0 {
            worst = (covered, n);
        }
    }
    eprintln!("worst coverage {:.3} at {} worlds", worst.0, worst.1);
    assert!(worst.0 >= LEAST, "coverage {:.3} at {} worlds", worst.0, worst.1);
}

/// The check over realisations is a test with its stated false-alarm rate: three banded figures
/// whose true medians sit exactly on a band edge (the worst case for a model that meets its
/// bands), skewed and symmetric, judged over 40 worlds at a false-alarm rate of 0.05, fail in at
/// most 5 % of 2,000 simulated checks (plus 3 binomial standard errors, 0.015); a figure moved well
/// outside its band (its median at 1.5 band widths beyond the edge) is caught in at least 95 %.
#[test]
fn the_check_over_realisations_keeps_its_false_alarm_rate_and_catches_a_figure_moved_out_of_its_band() {
    use calsim::study::check::{Band, Bound, Check, over_realisations};
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let (trials, worlds, alpha) = (2000, 40, 0.05);
    // Band of each figure: 1.0 +-20 %; the true median at the upper edge 1.2 (shift 0) or beyond.
    let band = Band { value: 1.0, tolerance: 0.2 };
    let world = |rng: &mut ChaCha8Rng, shift: f64| -> Vec<Check> {
        let ln = LogNormal::new(0.0, 0.5).unwrap();
        let normal = Normal::new(0.0, 0.1).unwrap();
        vec![
            // Lognormal with median 1: scaled so that its median is the edge.
            Check::band("skewed", 1.0, (1.2 + shift) * ln.sample(rng), Some(band)),
            Check::band("symmetric", 1.0, 1.2 + shift + normal.sample(rng), Some(band)),
            Check::rule("at least", "", 2.0 - shift + normal.sample(rng), String::new(), Some(Bound::AtLeast(2.0)), |_| String::new()),
        ]
    };
    let mut failed = [0usize; 2];
    for (k, shift) in [0.0, 0.6].into_iter().enumerate() {
        for _ in 0..trials {
            let runs: Vec<Vec<Check>> = (0..worlds).map(|_| world(&mut rng, shift)).collect();
            let d = over_realisations(&runs, worlds, alpha);
            if d.iter().any(|c| c.pass == Some(false)) {
                failed[k] += 1;
            }
        }
    }
    let rate = failed[0] as f64 / trials as f64;
    let se = (alpha * (1.0 - alpha) / trials as f64).sqrt();
    assert!(rate <= alpha + 3.0 * se, "false alarms: {rate} over {trials} checks of {worlds} worlds");
    let caught = failed[1] as f64 / trials as f64;
    assert!(caught >= 0.95, "detections: {caught} over {trials} checks");
    eprintln!("false alarms {rate:.4}, detections {caught:.4} over {trials} checks of {worlds} worlds");
}
