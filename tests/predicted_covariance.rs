//! The first-order parameter covariance sigma^2 (J^T J)^-1 against Monte Carlo: for noise alone
//! (isotropic Gaussian noise on the measured TCP positions, no unmodelled effect), the predicted
//! and simulated standard deviations of every identified parameter agree at n = 75.

mod common;

use calsim::identify::observability::{parameter_covariance, predicted_std};
use calsim::identify::{FitOptions, Observation, identify};
use calsim::robot::builtin::{trical_2018_nominal, trical_2018_table7};
use calsim::robot::{KinState, ParamSet, forward};
use calsim::study::prediction::noise_estimate;
use rand_distr::{Distribution, Normal};

#[test]
fn predicted_and_simulated_parameter_std_agree_for_noise_alone() {
    let truth = trical_2018_table7();
    let start = trical_2018_nominal();
    let set = ParamSet::trical_31();
    let mut rng = common::rng(75);
    let qs = common::random_configs(&truth, 75, &mut rng);
    let sigma = 0.010; // mm per coordinate
    let predicted = predicted_std(&truth, &set, &qs, sigma).expect("75 random configurations separate the 31 parameters");
    // 400 identifications of the same 75 configurations with fresh noise. The sample std of 400
    // draws has a relative standard error of 1 / sqrt(2 x 399) = 3.5 %: the 20 % band is more than
    // 5 standard errors wide, and the linearisation error at 10 um is far below it.
    let reps = 400;
    let noise = Normal::new(0.0, sigma).unwrap();
    let mut st = KinState::default();
    let exact: Vec<_> = qs.iter().map(|q| forward(&truth, &mut st, q)).collect();
    let mut values: Vec<Vec<f64>> = vec![Vec::with_capacity(reps); set.len()];
    let mut sigma2_hat = 0.0;
    for _ in 0..reps {
        let obs: Vec<Observation> = qs
            .iter()
            .zip(&exact)
            .map(|(q, p)| Observation { q: *q, tcp_world_mm: p + nalgebra::Vector3::from_fn(|_, _| noise.sample(&mut rng)) })
            .collect();
        let fit = identify(&start, &set, &obs, &FitOptions::default());
        sigma2_hat += noise_estimate(fit.residual_rms_mm, qs.len(), set.len()).powi(2) / reps as f64;
        for (j, v) in fit.values.iter().enumerate() {
            values[j].push(v.expect("identified"));
        }
    }
    // The fit's noise estimate SSR / (3n - m) is unbiased: each of the 400 estimates has a relative
    // std of sqrt(2 / 194) = 10 %, their mean 0.5 %; the 3 % band is 6 standard errors wide.
    assert!((sigma2_hat / (sigma * sigma) - 1.0).abs() < 0.03, "mean sigma_hat^2 {sigma2_hat:e} against sigma^2 {:e}", sigma * sigma);
    // The covariance's diagonal is the predicted variance.
    let cov = parameter_covariance(&truth, &set, &qs, sigma).expect("non-singular");
    for (j, p) in predicted.iter().enumerate() {
        assert!((cov[(j, j)].sqrt() / p - 1.0).abs() < 1e-9, "parameter {j}");
    }
    let names = set.names();
    for (j, v) in values.iter().enumerate() {
        let mean = v.iter().sum::<f64>() / reps as f64;
        let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (reps - 1) as f64).sqrt();
        let ratio = sd / predicted[j];
        assert!((0.8..1.2).contains(&ratio), "{}: simulated {sd:e}, predicted {:e}, ratio {ratio:.3}", names[j], predicted[j]);
    }
}
