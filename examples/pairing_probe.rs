//! Where two designs' worlds diverge: the pools of a TriCal scenario and a variant of it (one
//! source changed: `repeatability` x 2, `epsilon` / 2, `indicator` x 2, `harmonics` x 2, `ballbar`
//! x 2) built on the same realisations, compared slot by slot (docs/guide-sweeps.md, "Common
//! worlds"): `cargo run --release --example pairing_probe -- <scenario> <worlds> <variant>`.
use calsim::device::trical::spec;
use calsim::seeds::realisation_seed;
use std::path::Path;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = Path::new(&args[1]);
    let worlds: u32 = args.get(2).map_or(10, |s| s.parse().unwrap());
    let a = spec::load(path).unwrap();
    let mut b = a.clone();
    match args.get(3).map_or("repeatability", String::as_str) {
        "repeatability" => b.experiment.robot.repeatability_mm *= 2.0,
        "epsilon" => b.experiment.trical.epsilon_mm *= 0.5,
        "indicator" => b.experiment.trical.indicator_accuracy_um *= 2.0,
        "harmonics" => b.experiment.robot.unmodelled.transmission_high_mdeg *= 2.0,
        "ballbar" => b.experiment.cell.ballbar_sigma_um *= 2.0,
        other => panic!("unknown variant {other}"),
    }
    for r in 1..=worlds {
        let seed = realisation_seed(a.header.seed, r);
        let ea = a.experiment.build(seed).unwrap();
        let eb = b.experiment.build(seed).unwrap();
        let (pa, pb) = (&ea.campaign.pool, &eb.campaign.pool);
        let same_cmd = pa.iter().zip(pb).filter(|(x, y)| x.q_commanded == y.q_commanded).count();
        let close_cmd =
            pa.iter().zip(pb).filter(|(x, y)| x.q_commanded.iter().zip(&y.q_commanded).all(|(u, v)| (u - v).abs() < 1e-4)).count();
        let first_diff = pa.iter().zip(pb).position(|(x, y)| x.q_commanded.iter().zip(&y.q_commanded).any(|(u, v)| (u - v).abs() >= 1e-4));
        let dq: f64 = pa
            .iter()
            .zip(pb)
            .map(|(x, y)| x.q_commanded.iter().zip(&y.q_commanded).map(|(u, v)| (u - v).abs()).fold(0.0, f64::max))
            .fold(0.0, f64::max);
        let it_a: u32 = pa.iter().map(|p| p.iterations).sum();
        let it_b: u32 = pb.iter().map(|p| p.iterations).sum();
        println!(
            "r{r}: pool {} / {}; same q_cmd {same_cmd}, within 1e-4 rad {close_cmd}, first diff {first_diff:?}, max dq {dq:.2e}; rejected {} / {}, centring failures {} / {}; iterations {it_a} / {it_b}",
            pa.len(),
            pb.len(),
            ea.campaign.pool_rejected,
            eb.campaign.pool_rejected,
            ea.campaign.centring_failures,
            eb.campaign.centring_failures
        );
    }
}
