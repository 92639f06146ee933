//! Per world, a TriCal scenario's before-calibration mean error and the median of its sets'
//! after-calibration medians: `cargo run --release --example arm_worlds -- <scenario> <worlds> <sets>`.
use calsim::device::trical::spec;
use calsim::seeds::realisation_seed;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let mut s = spec::load(std::path::Path::new(&args[1])).unwrap_or_else(|e| panic!("{e}"));
    let worlds: u32 = args.get(2).map_or(10, |a| a.parse().expect("worlds"));
    s.study.set_sizes = vec![75];
    s.study.repetitions = args.get(3).map_or(5, |a| a.parse().expect("sets"));
    let mut ratios = Vec::new();
    for r in 0..worlds {
        let seed = realisation_seed(s.header.seed, r);
        let e = s.experiment.build(seed).expect("campaign");
        let before = s.experiment.before_model(&e.campaign);
        let st = calsim::device::trical::study::run(&e, &before, &s.study, seed, &|_, _| {}).expect("study");
        let b = st.before_errors.iter().sum::<f64>() / st.before_errors.len() as f64;
        let mut m: Vec<f64> = st.tasks.iter().map(|t| t.validation.median).collect();
        m.sort_by(f64::total_cmp);
        let a = m[m.len() / 2];
        ratios.push(a / b);
        println!("world {r}: before mean {b:.3} mm, after median {a:.3} mm, ratio {:.3}", a / b);
    }
    ratios.sort_by(f64::total_cmp);
    let bad = ratios.iter().filter(|x| **x >= 1.0 / 3.0).count();
    println!("median ratio {:.3}; {bad} of {worlds} worlds at or above 1/3", ratios[ratios.len() / 2]);
}
