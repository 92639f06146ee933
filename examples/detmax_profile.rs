//! Repeats DETMAX on the default campaign's pool, for profilers: `detmax_profile [designs] [set size]
//! [pool per sphere]` (200 designs of 75 from 3 x 120 unless given); prints steps and accepted
//! excursions, and a digest of every selection (FNV-1a over the indices) to compare builds.
use calsim::device::trical::experiment::ExperimentSpec;
use calsim::identify::{DetmaxOptions, PoolJacobian, detmax};
use calsim::robot::ParamSet;
use rand::SeedableRng;
fn main() {
    let mut spec = ExperimentSpec::default();
    if let Some(per) = std::env::args().nth(3).and_then(|a| a.parse().ok()) {
        spec.campaign.pool_per_sphere = per;
    }
    let e = spec.build(2018).expect("campaign");
    let qs: Vec<_> = e.campaign.pool.iter().map(|p| p.q).collect();
    let pool = PoolJacobian::new(&e.campaign.nominal, &ParamSet::trical_31(), &qs);
    let n: usize = std::env::args().nth(1).and_then(|a| a.parse().ok()).unwrap_or(200);
    let size: usize = std::env::args().nth(2).and_then(|a| a.parse().ok()).unwrap_or(75);
    let t = std::time::Instant::now();
    let (mut steps, mut kept, mut digest) = (0, 0, 0xcbf2_9ce4_8422_2325u64);
    for seed in 0..n as u64 {
        let d = detmax(&pool, size, &DetmaxOptions::default(), &mut rand_chacha::ChaCha8Rng::seed_from_u64(seed)).expect("design");
        steps += d.steps;
        kept += d.o1_history.len() - 1;
        for &k in &d.selection {
            digest = (digest ^ k as u64).wrapping_mul(0x0100_0000_01b3);
        }
    }
    println!(
        "pool of {}: {:.1} us per design, {} steps, {} accepted excursions, selections {digest:016x}",
        pool.len,
        t.elapsed().as_secs_f64() * 1e6 / n as f64,
        steps / n,
        kept / n
    );
}
