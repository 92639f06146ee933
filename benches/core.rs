//! Core kernels: forward kinematics with gravity compliance, FK plus the 3 x 31 identification
//! Jacobian, one 75-configuration identification to convergence, and DETMAX on the 360 pool of
//! the paper's campaign (n = 20, 75, 100) with the Jacobian of the pool it works on.

use std::hint::black_box;

use calsim::device::trical::experiment::ExperimentSpec;
use calsim::identify::{DetmaxOptions, FitOptions, Observation, PoolJacobian, detmax, identify};
use calsim::robot::builtin::{trical_2018_nominal, trical_2018_table7};
use calsim::robot::uniform_configuration;
use calsim::robot::{KinState, ParamSet, forward, tcp_jacobian};
use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::Vector3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

fn kernels(c: &mut Criterion) {
    let truth = trical_2018_table7();
    let set = ParamSet::trical_31();
    let mut rng = ChaCha8Rng::seed_from_u64(42);
    let qs: Vec<_> = (0..64).map(|_| uniform_configuration(&truth, 0.1, &mut rng)).collect();
    let mut st = KinState::default();

    let mut k = 0;
    c.bench_function("fk_torques_compliance", |b| {
        b.iter(|| {
            k = (k + 1) % qs.len();
            black_box(forward(black_box(&truth), &mut st, black_box(&qs[k])))
        })
    });

    let mut cols = vec![Vector3::zeros(); set.len()];
    c.bench_function("fk_jacobian_3x31", |b| {
        b.iter(|| {
            k = (k + 1) % qs.len();
            black_box(tcp_jacobian(black_box(&truth), &mut st, black_box(&qs[k]), &set, &mut cols));
            black_box(&cols);
        })
    });

    let noise = Normal::new(0.0, 0.010).unwrap();
    let obs: Vec<Observation> = (0..75)
        .map(|_| {
            let q = uniform_configuration(&truth, 0.1, &mut rng);
            let p = forward(&truth, &mut st, &q);
            Observation { q, tcp_world_mm: p + Vector3::from_fn(|_, _| noise.sample(&mut rng)) }
        })
        .collect();
    let nominal = trical_2018_nominal();
    let opts = FitOptions::default();
    c.bench_function("identify_75_gauss_newton", |b| b.iter(|| black_box(identify(black_box(&nominal), &set, black_box(&obs), &opts))));
}

fn design(c: &mut Criterion) {
    let e = ExperimentSpec::default().build(2018).expect("campaign");
    let qs: Vec<_> = e.campaign.pool.iter().map(|p| p.q).collect();
    let set = ParamSet::trical_31();
    c.bench_function("pool_jacobian_360", |b| {
        b.iter(|| black_box(PoolJacobian::new(black_box(&e.campaign.nominal), &set, black_box(&qs))))
    });
    let pool = PoolJacobian::new(&e.campaign.nominal, &set, &qs);
    let opts = DetmaxOptions::default();
    for n in [20, 75, 100] {
        let mut seed = 0;
        c.bench_function(&format!("detmax_o1_n{n}_of_360"), |b| {
            b.iter(|| {
                seed += 1;
                black_box(detmax(&pool, n, &opts, &mut ChaCha8Rng::seed_from_u64(seed)).expect("design"))
            })
        });
    }
}

criterion_group!(benches, kernels, design);
criterion_main!(benches);
