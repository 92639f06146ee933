//! The candidate error models of the fidelity study as scenario options: each off by default
//! without moving any draw of the default scenario (common random numbers), each doing what its
//! physical reading says, and each refusing bad values with one line naming file, section and key.

mod common;

use calsim::device::trical::spec as scenario;
use calsim::robot::{UnmodelledSpec, VirtualRobot};

use common::{calsim, repo, scratch};

fn robot(spec: &UnmodelledSpec) -> VirtualRobot {
    let truth = calsim::robot::builtin::trical_2018_table7();
    VirtualRobot::new(truth, spec, 0.0, &[0.0, 0.3, 0.3, 0.0, 0.8, 0.0], &mut common::rng(11))
}

/// One harmonic per joint given explicitly is the default: the same draws, the same robot.
#[test]
fn an_explicit_harmonic_count_of_one_is_the_default() {
    let base = UnmodelledSpec { transmission_high_mdeg: 3.0, ..Default::default() };
    let one = UnmodelledSpec { transmission_high_count: Some(1), ..base.clone() };
    assert_eq!(robot(&base).harmonics, robot(&one).harmonics);
    let four = robot(&UnmodelledSpec { transmission_high_count: Some(4), ..base.clone() });
    for (i, h) in four.harmonics.iter().enumerate() {
        assert_eq!(h.len(), 4, "joint {}", i + 1);
        assert!(h.iter().all(|x| (20.0..=120.0).contains(&x.order)), "orders in the default band");
    }
}

/// The encoder error is repeatable (the same command gives the same link angles) and random from
/// pose to pose: over 2,000 random configurations, its values on joint 2 at q and at q + d (d drawn
/// in 0.01-0.1 rad, smaller than any two poses of a pool differ) are uncorrelated (|r| < 0.1: the
/// standard error of r is 0.022 at this size; at orders >= 1000 per turn d spans >= 1.6 periods),
/// and its RMS is amplitude / sqrt(2) within 10 %.
#[test]
fn the_encoder_error_is_repeatable_and_random_from_pose_to_pose() {
    use rand::RngExt;
    let r = robot(&UnmodelledSpec { encoder_mdeg: 5.0, ..Default::default() });
    let amp = (5e-3_f64).to_radians();
    let mut rng = common::rng(1);
    let q = |x: f64| [0.0, x, 0.2, 0.0, 0.5, 0.0];
    let err = |x: f64, rng: &mut rand_chacha::ChaCha8Rng| r.link_angles(&q(x), &q(x), rng)[1] - x;
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for _ in 0..2000 {
        let x = rng.random_range(-1.0..1.0);
        let d = rng.random_range(0.01..0.1);
        a.push(err(x, &mut rng));
        b.push(err(x + d, &mut rng));
    }
    assert_eq!(r.link_angles(&q(0.3), &q(0.3), &mut rng), r.link_angles(&q(0.3), &q(0.3), &mut rng), "repeatable");
    let rms = (a.iter().map(|x| x * x).sum::<f64>() / a.len() as f64).sqrt();
    assert!((rms / (amp / 2f64.sqrt()) - 1.0).abs() < 0.1, "rms {rms:e} rad against {:e}", amp / 2f64.sqrt());
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let (ma, mb) = (mean(&a), mean(&b));
    let cov: f64 = a.iter().zip(&b).map(|(x, y)| (x - ma) * (y - mb)).sum();
    let va: f64 = a.iter().map(|x| (x - ma).powi(2)).sum();
    let vb: f64 = b.iter().map(|y| (y - mb).powi(2)).sum();
    let corr = cov / (va * vb).sqrt();
    assert!(corr.abs() < 0.1, "correlation between nearby poses {corr}");
}

/// Setup 2's payload changes the validation robot only; without the key both robots are equal.
#[test]
fn the_setup2_payload_changes_the_validation_robot_only() {
    let mut s = scenario::load(&repo().join("scenarios/ci_quick.toml")).unwrap();
    s.study.set_sizes = vec![35];
    s.experiment.robot.validation_payload_change_kg = None;
    let e = s.experiment.build(s.header.seed).unwrap();
    assert_eq!(e.robot.truth.data(), e.robot_validation.truth.data());
    s.experiment.robot.validation_payload_change_kg = Some(-0.6);
    let e2 = s.experiment.build(s.header.seed).unwrap();
    assert_eq!(e2.robot.truth.data(), e.robot.truth.data());
    assert!((e2.robot_validation.truth.data().payload.mass_kg - 0.4).abs() < 1e-12, "1.0 - 0.6 kg");
    assert_eq!(e2.campaign.pool, e.campaign.pool, "setup 1 is untouched");
}

/// Setup 2 without the indicators: fewer device parts in the way, so no more validation
/// candidates are rejected than with them, and the identification pool is the same.
#[test]
fn setup2_without_indicators_rejects_no_more_validation_poses() {
    let s = scenario::load(&repo().join("scenarios/ci_quick.toml")).unwrap();
    let e = s.experiment.build(s.header.seed).unwrap();
    let mut spec = s.experiment.clone();
    spec.campaign.validation_indicators_removed = true;
    let e2 = spec.build(s.header.seed).unwrap();
    assert_eq!(e2.campaign.pool, e.campaign.pool);
    assert!(
        e2.campaign.validation_rejected <= e.campaign.validation_rejected,
        "{} > {}",
        e2.campaign.validation_rejected,
        e.campaign.validation_rejected
    );
    assert_eq!(e2.campaign.validation.len(), e.campaign.validation.len());
}

#[test]
fn bad_candidate_values_are_one_line_naming_the_key() {
    let tmp = scratch("candidate-keys");
    let dir = tmp.path();
    let base = common::scenario_text_anywhere("ci_quick.toml");
    for (name, from, to, key) in [
        ("count0.toml", "[robot.unmodelled]", "[robot.unmodelled]\ntransmission_high_count = 0", "transmission_high_count"),
        ("encnan.toml", "[robot.unmodelled]", "[robot.unmodelled]\nencoder_mdeg = nan", "encoder_mdeg"),
        ("encneg.toml", "[robot.unmodelled]", "[robot.unmodelled]\nencoder_mdeg = -1.0", "encoder_mdeg"),
        ("encorders.toml", "[robot.unmodelled]", "[robot.unmodelled]\nencoder_orders = [4000, 1000]", "encoder_orders"),
        ("payload.toml", "validation_payload_change_kg = -0.3", "validation_payload_change_kg = 1e300", "validation_payload_change_kg"),
        ("payload-neg.toml", "validation_payload_change_kg = -0.3", "validation_payload_change_kg = -1.5", "validation_payload_change_kg"),
        ("flag.toml", "[campaign]\n", "[campaign]\nvalidation_indicators_removed = 3\n", "validation_indicators_removed"),
    ] {
        assert!(base.contains(from), "{from}");
        let f = dir.join(name);
        std::fs::write(&f, base.replacen(from, to, 1)).unwrap();
        let out = calsim().arg("run").arg(&f).arg("--out").arg(dir).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{name}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{name}: one line: {err}");
        assert!(err.contains(name) && err.contains(key), "{name}: {err}");
    }
}
