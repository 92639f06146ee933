//! Repeats one 75-configuration identification, for profilers.
use calsim::identify::{FitOptions, Observation, identify};
use calsim::robot::builtin::{trical_2018_nominal, trical_2018_table7};
use calsim::robot::uniform_configuration;
use calsim::robot::{KinState, ParamSet, forward};
use rand::SeedableRng;
fn main() {
    let truth = trical_2018_table7();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(42);
    let mut st = KinState::default();
    let obs: Vec<Observation> = (0..75)
        .map(|_| {
            let q = uniform_configuration(&truth, 0.1, &mut rng);
            Observation { q, tcp_world_mm: forward(&truth, &mut st, &q) }
        })
        .collect();
    let n: usize = std::env::args().nth(1).and_then(|a| a.parse().ok()).unwrap_or(2000);
    let (nominal, set) = (trical_2018_nominal(), ParamSet::trical_31());
    let t = std::time::Instant::now();
    let mut it = 0;
    for _ in 0..n {
        it += identify(&nominal, &set, &obs, &FitOptions::default()).iterations;
    }
    println!("{:.1} us per identification, {} iterations", t.elapsed().as_secs_f64() * 1e6 / n as f64, it / n);
}
