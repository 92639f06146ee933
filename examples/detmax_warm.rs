//! DETMAX warm-started from a neighbouring design's set, against its random start: the default
//! campaign (seed 2018) and the same campaign with sphere 2 moved by `shift` mm along x, the
//! neighbour's pool indices handed over as they are. `detmax_warm [designs] [set size] [pool per
//! sphere] [shift mm]` (20 designs of 300 from 3 x 251, 20 mm unless given) prints, on the moved
//! cell, the CPU time (the thread's, from /proc/thread-self/stat, 10 ms ticks summed over the
//! designs), steps and accepted excursions of the cold and the warm starts and O1 of each (median
//! of warm / cold, and in how many designs the warm start ended higher).
use calsim::device::trical::experiment::ExperimentSpec;
use calsim::identify::detmax::{detmax_from, o1_of};
use calsim::identify::{DetmaxOptions, PoolJacobian};
use calsim::robot::ParamSet;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

fn pool(per: u32, shift: f64) -> PoolJacobian {
    let mut spec = ExperimentSpec::default();
    spec.campaign.pool_per_sphere = per;
    spec.cell.spheres_w_mm[1][0] += shift;
    let e = spec.build(2018).expect("campaign");
    let qs: Vec<_> = e.campaign.pool.iter().map(|p| p.q).collect();
    PoolJacobian::new(&e.campaign.nominal, &ParamSet::trical_31(), &qs)
}

/// The CPU time this thread has used, s (user and system, from /proc/thread-self/stat; 0 where
/// that file cannot be read).
fn thread_cpu_s() -> f64 {
    let stat = std::fs::read_to_string("/proc/thread-self/stat").unwrap_or_default();
    // The fields after the command's closing parenthesis: utime and stime are the 12th and 13th.
    let fields: Vec<&str> = stat.rsplit_once(')').map_or(Vec::new(), |(_, rest)| rest.split_whitespace().collect());
    let ticks = |i: usize| fields.get(i).and_then(|f| f.parse::<f64>().ok()).unwrap_or(0.0);
    (ticks(11) + ticks(12)) / 100.0
}

fn main() {
    let arg = |i: usize| std::env::args().nth(i);
    let designs: u64 = arg(1).and_then(|a| a.parse().ok()).unwrap_or(20);
    let n: usize = arg(2).and_then(|a| a.parse().ok()).unwrap_or(300);
    let per: u32 = arg(3).and_then(|a| a.parse().ok()).unwrap_or(251);
    let shift: f64 = arg(4).and_then(|a| a.parse().ok()).unwrap_or(20.0);
    let (before, after) = (pool(per, 0.0), pool(per, shift));
    let opts = DetmaxOptions::default();
    let (mut cold_s, mut warm_s) = (0.0, 0.0);
    let (mut cold_steps, mut warm_steps, mut cold_kept, mut warm_kept) = (0, 0, 0, 0);
    let (mut ratios, mut higher) = (Vec::new(), 0);
    for seed in 0..designs {
        let neighbour = detmax_from(&before, n, &opts, &mut ChaCha8Rng::seed_from_u64(seed), None).expect("design");
        let t = thread_cpu_s();
        let cold = detmax_from(&after, n, &opts, &mut ChaCha8Rng::seed_from_u64(seed + 1_000), None).expect("design");
        cold_s += thread_cpu_s() - t;
        let t = thread_cpu_s();
        let warm = detmax_from(&after, n, &opts, &mut ChaCha8Rng::seed_from_u64(seed + 1_000), Some(&neighbour.selection)).expect("design");
        warm_s += thread_cpu_s() - t;
        (cold_steps, warm_steps) = (cold_steps + cold.steps, warm_steps + warm.steps);
        (cold_kept, warm_kept) = (cold_kept + cold.o1_history.len() - 1, warm_kept + warm.o1_history.len() - 1);
        let (oc, ow) = (o1_of(&after, &cold.selection), o1_of(&after, &warm.selection));
        ratios.push(ow / oc);
        higher += usize::from(ow > oc);
    }
    ratios.sort_by(f64::total_cmp);
    let d = designs as f64;
    println!(
        "pools of {} and {} (sphere 2 moved {shift} mm), sets of {n}: cold {:.0} ms CPU, {:.0} steps, {:.0} accepted; warm {:.0} ms CPU, {:.0} steps, {:.0} accepted; O1 warm / cold median {:.5} (range {:.5}-{:.5}), warm higher in {higher} of {designs}",
        before.len,
        after.len,
        cold_s * 1e3 / d,
        cold_steps as f64 / d,
        cold_kept as f64 / d,
        warm_s * 1e3 / d,
        warm_steps as f64 / d,
        warm_kept as f64 / d,
        ratios[ratios.len() / 2],
        ratios[0],
        ratios[ratios.len() - 1],
    );
}
