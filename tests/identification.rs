//! Identification of the 31 parameters: noise-free recovery of injected truth, robot populations,
//! rank deficiency, and the Levenberg-Marquardt option.

mod common;

use calsim::identify::{FitOptions, FitOutcome, Observation, Solver, identify};
use calsim::robot::builtin::{trical_2018_nominal, trical_2018_table7};
use calsim::robot::{DeviationSpec, ParamId, ParamSet, RobotModel, Unit, deviate, tcp_world};

/// Exact TCP positions of `truth` at `n` random configurations.
fn exact_observations(truth: &RobotModel, n: usize, seed: u64) -> Vec<Observation> {
    let mut rng = common::rng(seed);
    common::random_configs(truth, n, &mut rng).into_iter().map(|q| Observation { q, tcp_world_mm: tcp_world(truth, &q) }).collect()
}

/// Largest error over the set, in the units at the edges (mm, deg, mdeg/(N m)).
fn worst_error(set: &ParamSet, values: &[Option<f64>], truth: &RobotModel) -> (String, f64) {
    set.ids()
        .iter()
        .zip(values)
        .map(|(id, v)| {
            let unit = id.unit();
            let v = v.expect("every parameter identified");
            (id.name(), (unit.from_internal(v) - unit.from_internal(id.get(truth.data()))).abs())
        })
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap()
}

#[test]
fn identification_recovers_table7_robot_from_noise_free_poses() {
    let truth = trical_2018_table7();
    let set = ParamSet::trical_31();
    let obs = exact_observations(&truth, 75, 7);
    let fit = identify(&trical_2018_nominal(), &set, &obs, &FitOptions::default());
    assert!(matches!(fit.outcome, FitOutcome::Converged { .. }), "{:?}", fit.outcome);
    let (name, err) = worst_error(&set, &fit.values, &truth);
    eprintln!(
        "iterations {}, condition {:.1}, residual {:e} mm, worst {name} {err:e}",
        fit.iterations, fit.condition_number, fit.residual_rms_mm
    );
    assert!(err < 1e-6, "{name} off by {err:e}");
    assert!(fit.residual_rms_mm < 1e-9);
    assert_eq!(fit.singular_values.len(), 31);
    assert!(fit.singular_values.windows(2).all(|w| w[0] >= w[1]));
    assert!(fit.condition_number.is_finite() && fit.condition_number > 1.0);
}

#[test]
fn identification_recovers_random_robots_over_20_seeds() {
    let nominal = trical_2018_nominal();
    let set = ParamSet::trical_31();
    for seed in 0..20 {
        let truth = deviate(&nominal, &set, &DeviationSpec::TYPICAL, &mut common::rng(1000 + seed));
        let obs = exact_observations(&truth, 75, 2000 + seed);
        let fit = identify(&nominal, &set, &obs, &FitOptions::default());
        assert!(matches!(fit.outcome, FitOutcome::Converged { .. }), "seed {seed}: {:?}", fit.outcome);
        let (name, err) = worst_error(&set, &fit.values, &truth);
        assert!(err < 1e-6, "seed {seed}: {name} off by {err:e}");
    }
}

#[test]
fn levenberg_marquardt_recovers_the_same_robot() {
    let truth = trical_2018_table7();
    let set = ParamSet::trical_31();
    let obs = exact_observations(&truth, 75, 9);
    let opts = FitOptions { solver: Solver::LevenbergMarquardt { tau: 1e-3 }, ..FitOptions::default() };
    let fit = identify(&trical_2018_nominal(), &set, &obs, &opts);
    assert!(matches!(fit.outcome, FitOutcome::Converged { .. }), "{:?}", fit.outcome);
    let (name, err) = worst_error(&set, &fit.values, &truth);
    assert!(err < 1e-6, "{name} off by {err:e}");
}

#[test]
fn freeing_d2_with_the_31_is_rank_deficient_and_names_d2_and_d3() {
    let truth = trical_2018_table7();
    let set = ParamSet::trical_31().freed(ParamId::parse("d2").unwrap());
    let obs = exact_observations(&truth, 75, 5);
    let fit = identify(&trical_2018_nominal(), &set, &obs, &FitOptions::default());
    let FitOutcome::RankDeficient { unidentifiable } = &fit.outcome else { panic!("expected rank deficiency, got {:?}", fit.outcome) };
    assert!(unidentifiable.contains(&"d2".to_string()) && unidentifiable.contains(&"d3".to_string()), "{unidentifiable:?}");
    assert!(fit.model.is_none(), "no model from a rank-deficient fit");
    for (name, v) in set.names().iter().zip(&fit.values) {
        assert_eq!(v.is_none(), unidentifiable.contains(name), "{name}");
    }
    assert!(fit.condition_number.is_infinite());
}

/// With `truncate`, the same rank-deficient set gives a model: the direction d2 and d3 share stays
/// at the start (d2 + d3 is what the poses see), everything else is recovered, and the positions
/// are reproduced exactly.
#[test]
fn truncation_leaves_the_unobservable_direction_at_the_start() {
    let truth = trical_2018_table7();
    let start = trical_2018_nominal();
    let set = ParamSet::trical_31().freed(ParamId::parse("d2").unwrap());
    let obs = exact_observations(&truth, 75, 5);
    let fit = identify(&start, &set, &obs, &FitOptions { truncate: true, ..FitOptions::default() });
    let FitOutcome::Truncated { unidentifiable, .. } = &fit.outcome else { panic!("expected a truncated fit, got {:?}", fit.outcome) };
    assert!(unidentifiable.contains(&"d2".to_string()) && unidentifiable.contains(&"d3".to_string()), "{unidentifiable:?}");
    let model = fit.model.expect("a truncated fit returns its model");
    assert!(fit.residual_rms_mm < 1e-7, "rms {}", fit.residual_rms_mm);
    let (d2, d3) = (ParamId::parse("d2").unwrap(), ParamId::parse("d3").unwrap());
    let sum = |m: &RobotModel| d2.get(m.data()) + d3.get(m.data());
    assert!((sum(&model) - sum(&truth)).abs() < 1e-6, "d2 + d3 {} vs {}", sum(&model), sum(&truth));
    // The minimum-norm step splits the change of d2 + d3 equally: d2 - d3 keeps its start value
    // (to the accuracy of the null vector through the Gram matrix; the truth is 0.094 mm away).
    let diff = |m: &RobotModel| d2.get(m.data()) - d3.get(m.data());
    assert!((diff(&model) - diff(&start)).abs() < 1e-4, "d2 - d3 {} vs start {}", diff(&model), diff(&start));
    // The rest: recovered to the accuracy of that null vector (the truth is 0.01-0.3 mm and
    // 1e-4-1e-3 rad from the start).
    for id in set.ids().iter().filter(|id| **id != d2 && **id != d3) {
        let tol = if id.unit() == Unit::Mm { 1e-4 } else { 1e-6 };
        assert!(
            (id.get(model.data()) - id.get(truth.data())).abs() < tol,
            "{} off by {:e}",
            id.name(),
            id.get(model.data()) - id.get(truth.data())
        );
    }
    assert!(fit.condition_number.is_finite());
}

#[test]
fn too_few_configurations_are_rank_deficient() {
    // 8 configurations give 24 equations for 31 unknowns.
    let truth = trical_2018_table7();
    let obs = exact_observations(&truth, 8, 5);
    let fit = identify(&trical_2018_nominal(), &ParamSet::trical_31(), &obs, &FitOptions::default());
    assert!(matches!(fit.outcome, FitOutcome::RankDeficient { .. }), "{:?}", fit.outcome);
}

#[test]
fn the_iteration_cap_is_reported_as_such() {
    let truth = trical_2018_table7();
    let obs = exact_observations(&truth, 75, 5);
    let opts = FitOptions { max_iterations: 1, ..FitOptions::default() };
    let fit = identify(&trical_2018_nominal(), &ParamSet::trical_31(), &obs, &opts);
    assert_eq!(fit.outcome, FitOutcome::IterationCap { iterations: 1 });
    assert!(fit.model.is_some());
}

#[test]
fn compliance_is_recovered_in_table7_units() {
    let truth = trical_2018_table7();
    let set = ParamSet::trical_31();
    let fit = identify(&trical_2018_nominal(), &set, &exact_observations(&truth, 75, 21), &FitOptions::default());
    let j = set.position(ParamId::parse("c4").unwrap()).unwrap();
    let c4 = Unit::MdegPerNm.from_internal(fit.values[j].unwrap());
    assert!((c4 - (-33.738)).abs() < 1e-6, "c4 = {c4}");
}
