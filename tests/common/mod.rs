//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::path::PathBuf;
use std::process::Command;

use calsim::robot::{Joints, RobotModel};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// `reference/<name>`: the repository's copy of the reference data.
pub fn reference(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("reference").join(name)
}

/// `shared/reference/<name>` beside the clone, when it is there (the project's upstream copy).
pub fn shared_reference(name: &str) -> Option<PathBuf> {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/reference").join(name);
    p.exists().then_some(p)
}

/// A seeded RNG for a test.
pub fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// `n` random configurations inside the joint limits (10 % margin each side; joint 6 within +-180 deg).
pub fn random_configs(model: &RobotModel, n: usize, rng: &mut ChaCha8Rng) -> Vec<Joints> {
    (0..n).map(|_| calsim::robot::uniform_configuration(model, 0.1, rng)).collect()
}

/// The repository root.
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The `calsim` binary, run from the repository root without backtraces.
pub fn calsim() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_calsim"));
    c.env("RUST_LIB_BACKTRACE", "0").env("RUST_BACKTRACE", "0").current_dir(repo());
    c
}

/// An empty scratch directory, removed with everything in it when the returned guard is dropped
/// (at the end of the test, passed or failed).
pub fn scratch(name: &str) -> tempfile::TempDir {
    tempfile::Builder::new().prefix(&format!("calsim-test-{name}-")).tempdir().unwrap()
}

/// The text of the repo's scenario `name` with its robot file named by absolute path, so that a
/// copy written elsewhere still finds it.
#[allow(dead_code)]
pub fn scenario_text_anywhere(name: &str) -> String {
    let text = std::fs::read_to_string(repo().join("scenarios").join(name)).unwrap();
    text.replace("file = \"../robots/", &format!("file = \"{}/robots/", repo().display()))
}

/// The largest distance between the TCPs of `a` and `b` over 1,000 configurations drawn within the
/// limits of `limits` from `rng`, mm.
pub fn largest_tcp_difference(a: &RobotModel, b: &RobotModel, limits: &RobotModel, rng: &mut ChaCha8Rng) -> f64 {
    let (mut sa, mut sb) = (calsim::robot::KinState::default(), calsim::robot::KinState::default());
    (0..1000)
        .map(|_| {
            let q = calsim::robot::uniform_configuration(limits, 0.0, rng);
            (calsim::robot::forward(a, &mut sa, &q) - calsim::robot::forward(b, &mut sb, &q)).norm()
        })
        .fold(0.0, f64::max)
}

/// The TriCal study of `s` in `worlds` worlds (realisations 0, 1, ... of its seed): per world, the
/// before-calibration mean error and the median over its converged sets of their validation
/// medians, mm. Panics when a campaign fails or a set does not converge.
pub fn trical_worlds(s: &calsim::device::trical::spec::TricalScenario, worlds: u32) -> Vec<(f64, f64)> {
    (0..worlds)
        .map(|r| {
            let seed = calsim::seeds::realisation_seed(s.header.seed, r);
            let e = s.experiment.build(seed).unwrap_or_else(|err| panic!("world {r}: campaign: {err}"));
            let before = s.experiment.before_model(&e.campaign);
            let study = calsim::device::trical::study::run(&e, &before, &s.study, seed, &|_, _| {}).expect("study");
            let before_mean = study.before_errors.iter().sum::<f64>() / study.before_errors.len() as f64;
            let mut medians: Vec<f64> =
                study.tasks.iter().filter(|t| t.id.outcome.label() == "converged").map(|t| t.validation.median).collect();
            assert_eq!(medians.len(), study.tasks.len(), "world {r}: every set identified");
            medians.sort_by(f64::total_cmp);
            (before_mean, medians[medians.len() / 2])
        })
        .collect()
}

/// The median of the worlds' ratios of after-calibration median to before-calibration mean.
pub fn median_ratio(worlds: &[(f64, f64)]) -> f64 {
    let mut r: Vec<f64> = worlds.iter().map(|(before, after)| after / before).collect();
    r.sort_by(f64::total_cmp);
    r[r.len() / 2]
}
