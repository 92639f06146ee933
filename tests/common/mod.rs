//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::path::PathBuf;

use calsim::robot::{Joints, RobotModel};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// `shared/reference/<name>`, beside the clone.
pub fn reference(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/reference").join(name)
}

/// A seeded RNG for a test.
pub fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// `n` random configurations inside the joint limits (10 % margin each side; joint 6 within +-180 deg).
pub fn random_configs(model: &RobotModel, n: usize, rng: &mut ChaCha8Rng) -> Vec<Joints> {
    (0..n).map(|_| calsim::campaign::uniform_configuration(model, 0.1, rng)).collect()
}
