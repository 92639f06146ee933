//! Repeats DETMAX at n = 75 on the default pool, for profilers; prints steps and accepted excursions.
use calsim::device::trical::experiment::ExperimentSpec;
use calsim::identify::{DetmaxOptions, PoolJacobian, detmax};
use calsim::robot::ParamSet;
use rand::SeedableRng;
fn main() {
    let e = ExperimentSpec::default().build(2018).expect("campaign");
    let qs: Vec<_> = e.campaign.pool.iter().map(|p| p.q).collect();
    let pool = PoolJacobian::new(&e.campaign.nominal, &ParamSet::trical_31(), &qs);
    let n: usize = std::env::args().nth(1).and_then(|a| a.parse().ok()).unwrap_or(200);
    let size: usize = std::env::args().nth(2).and_then(|a| a.parse().ok()).unwrap_or(75);
    let t = std::time::Instant::now();
    let (mut steps, mut kept) = (0, 0);
    for seed in 0..n as u64 {
        let d = detmax(&pool, size, &DetmaxOptions::default(), &mut rand_chacha::ChaCha8Rng::seed_from_u64(seed)).expect("design");
        steps += d.steps;
        kept += d.o1_history.len() - 1;
    }
    println!("{:.1} us per design, {} steps, {} accepted excursions", t.elapsed().as_secs_f64() * 1e6 / n as f64, steps / n, kept / n);
}
