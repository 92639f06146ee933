//! DETMAX on the identification pool and the observability indices.

mod common;

use calsim::device::trical::experiment::ExperimentSpec;
use calsim::identify::detmax::o1_of;
use calsim::identify::{DetmaxOptions, Observability, PoolJacobian, detmax};
use calsim::robot::ParamSet;
use rand::seq::index::sample;

fn pool() -> PoolJacobian {
    let e = ExperimentSpec::default().build(21).unwrap();
    let qs: Vec<_> = e.campaign.pool.iter().map(|p| p.q).collect();
    PoolJacobian::new(&e.campaign.nominal, &ParamSet::trical_31(), &qs)
}

#[test]
fn detmax_never_lowers_o1_and_its_updates_match_a_fresh_computation() {
    let pool = pool();
    for (n, seed) in [(20, 1), (75, 2), (100, 3)] {
        let design = detmax(&pool, n, &DetmaxOptions::default(), &mut common::rng(seed)).unwrap();
        assert_eq!(design.selection.len(), n);
        assert!(design.o1_history.windows(2).all(|w| w[1] > w[0]), "{:?}", design.o1_history);
        let fresh = o1_of(&pool, &design.selection);
        let tracked = *design.o1_history.last().unwrap();
        assert!((fresh - tracked).abs() < 1e-9 * fresh, "n = {n}: tracked {tracked} vs fresh {fresh}");
        assert!(design.o1_history.len() > 1, "n = {n}: no improvement over a random start");
    }
}

#[test]
fn detmax_beats_the_best_of_1000_random_subsets() {
    let pool = pool();
    let mut rng = common::rng(8);
    for n in [20, 75] {
        let best_random = (0..1000).map(|_| o1_of(&pool, &sample(&mut rng, pool.len, n).into_vec())).fold(0.0, f64::max);
        let design = detmax(&pool, n, &DetmaxOptions::default(), &mut rng).unwrap();
        let o1 = o1_of(&pool, &design.selection);
        eprintln!("n = {n}: DETMAX O1 {o1:.5}, best of 1000 random {best_random:.5}");
        assert!(o1 > best_random);
    }
}

#[test]
fn observability_indices_follow_their_definitions() {
    let s = [4.0, 2.0, 1.0];
    let o = Observability::from_singular_values(&s, 4);
    assert!((o.o1 - 2.0 / 2.0).abs() < 1e-12); // (4*2*1)^(1/3) / sqrt(4)
    assert!((o.o2 - 0.25).abs() < 1e-12);
    assert!((o.o3 - 1.0).abs() < 1e-12);
    assert!((o.o4 - 0.25).abs() < 1e-12);
    assert!((o.o5 - 1.0 / 1.75).abs() < 1e-12);
    let pool = pool();
    let set: Vec<usize> = (0..60).map(|k| k * 6).collect();
    let from_info = Observability::from_information(&pool.information(&set), set.len());
    assert!((from_info.o1 - o1_of(&pool, &set)).abs() < 1e-9 * from_info.o1);
}
