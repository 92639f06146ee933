//! The TriCal campaign of a scenario at several centring tolerances: iterations and modelled
//! seconds per pool configuration (Algorithm 1), centring failures, the worst true offset, and the
//! wall time to generate and measure the pool.
//!
//! `cargo run --release --example centring_timing [scenario] [epsilon_um ...]`

use calsim::device::trical::spec as scenario;

fn main() {
    let mut args = std::env::args().skip(1);
    let path = args.next().unwrap_or_else(|| "scenarios/irb120_trical.toml".into());
    let eps: Vec<f64> = args.filter_map(|a| a.parse().ok()).collect();
    let eps = if eps.is_empty() { vec![10.0, 5.0, 20.0] } else { eps };
    let s = match scenario::load(std::path::Path::new(&path)) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("error: {}", calsim::app::message::one_line(&e.to_string()));
            std::process::exit(2);
        }
    };
    println!(
        "{:>8} {:>10} {:>12} {:>10} {:>12} {:>10} {:>10}",
        "eps_um", "iter_mean", "seconds_mean", "failures", "worst_um", "pool_s", "pool_h"
    );
    for e in eps {
        let mut spec = s.experiment.clone();
        spec.trical.epsilon_mm = e * 1e-3;
        let ex = match spec.build(s.header.seed) {
            Ok(x) => x,
            Err(err) => {
                eprintln!("epsilon {e} um: {err}");
                continue;
            }
        };
        let pool = &ex.campaign.pool;
        let n = pool.len() as f64;
        let it = pool.iter().map(|p| p.iterations as f64).sum::<f64>() / n;
        let secs = pool.iter().map(|p| p.seconds).sum::<f64>() / n;
        let worst = pool.iter().map(|p| p.true_offset_mm).fold(0.0, f64::max) * 1e3;
        println!(
            "{e:>8.1} {it:>10.2} {secs:>12.1} {:>10} {worst:>12.1} {:>10.3} {:>10.2}",
            ex.campaign.centring_failures,
            ex.campaign.pool_wall_s,
            pool.iter().map(|p| p.seconds).sum::<f64>() / 3600.0
        );
    }
}
