//! Models for the tests that compare two computations of the same kinematics.

use nalgebra::Vector3;
use rand::RngExt;
use rand_chacha::ChaCha8Rng;

use super::builtin::{er20c10_table4, er20c10_table5, irb120, trical_2018_nominal, trical_2018_table7};
use super::{Inertial, RobotModel};

/// A model with every link, body, base, tool and gravity number moved at random (on the scale of
/// its size).
pub(crate) fn scrambled(m: &RobotModel, rng: &mut ChaCha8Rng) -> RobotModel {
    m.edited(|d| {
        let mut r = |x: f64, s: f64| x + rng.random_range(-1.0..1.0) * s;
        for l in &mut d.links {
            (l.alpha, l.a, l.beta) = (r(l.alpha, 0.5), r(l.a, 50.0), r(l.beta, 0.1));
            (l.theta_offset, l.d, l.compliance) = (r(l.theta_offset, 0.5), r(l.d, 50.0), r(l.compliance, 1e-3));
        }
        for b in d.links_inertial.iter_mut().chain(std::iter::once(&mut d.payload)) {
            *b = Inertial { mass_kg: r(b.mass_kg, 1.0).abs(), com_mm: b.com_mm.map(|c| r(c, 80.0)) };
        }
        let w = &mut d.world_from_base;
        (w.x, w.alpha, w.beta, w.gamma) = (r(w.x, 500.0), r(w.alpha, 3.0), r(w.beta, 3.0), r(w.gamma, 3.0));
        d.flange_tcp_mm = d.flange_tcp_mm.map(|c| r(c, 100.0));
        d.gravity_base = Vector3::new(r(0.0, 2.0), r(0.0, 2.0), r(-9.81, 2.0));
    })
    .expect("finite model")
}

/// 50 models: the 5 built-in robots, their rigid forms and 40 scrambled ones.
pub(crate) fn models(rng: &mut ChaCha8Rng) -> Vec<RobotModel> {
    let mut models = vec![irb120(), trical_2018_nominal(), trical_2018_table7(), er20c10_table4(), er20c10_table5(true)];
    let rigid: Vec<_> = models.iter().map(|m| m.edited(|d| d.links.iter_mut().for_each(|l| l.compliance = 0.0)).unwrap()).collect();
    assert!(rigid.iter().all(|m| m.rigid));
    models.extend(rigid);
    for i in 0..40 {
        let m = scrambled(&models[i % 5], rng);
        models.push(m);
    }
    models
}

/// Configuration j of a test: within +-3.2 rad, one in four (j a multiple of 4) within +-20 rad
/// (far outside any joint range).
pub(crate) fn configuration(rng: &mut ChaCha8Rng, j: usize) -> [f64; 6] {
    let wide = if j.is_multiple_of(4) { 20.0 } else { 3.2 };
    std::array::from_fn(|_| rng.random_range(-wide..wide))
}
