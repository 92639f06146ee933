//! The physical robot of a simulation: the true model, the effects its 31 parameters cannot
//! express, and the repeatability of every move.
//!
//! A move to commanded joints `q` puts the links at `q + transmission(q) + backlash(direction) +
//! noise`; the encoders report `q` (the servo reached it), so none of these terms is visible to
//! the controller: they reach identification and validation as position errors.

use std::f64::consts::PI;

use rand::{Rng, RngExt};
use rand_distr::{Distribution, Normal, Uniform};
use serde::Deserialize;

use super::kinematics::KinState;
use super::kinematics::forward;
use super::model::{JOINTS, Joints, RobotModel};

/// Effects outside the identified model, as a scenario describes them. Every amplitude defaults
/// to zero (off).
#[derive(Clone, Debug, Default, Deserialize, serde::Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct UnmodelledSpec {
    /// Amplitude of the low-order transmission harmonics (orders 1 and 2: eccentricity), per joint
    /// 2..6 (joint 1 too), mdeg.
    pub transmission_low_mdeg: f64,
    /// Amplitude of the high-order harmonics (gear mesh, encoder cycles), mdeg.
    pub transmission_high_mdeg: f64,
    /// Range of the high orders, periods per turn `[min, max]`; the orders of each joint drawn in it.
    pub transmission_high_orders: Option<[u32; 2]>,
    /// High-order harmonics per joint (several gear stages across the band), each of the amplitude
    /// `transmission_high_mdeg`; absent: one.
    pub transmission_high_count: Option<u32>,
    /// Amplitude of the encoder interpolation error per joint, mdeg: a harmonic of order drawn in
    /// `encoder_orders` (thousands of periods per turn: repeatable, yet random from pose to pose).
    pub encoder_mdeg: f64,
    /// Range of the encoder orders, periods per turn (absent: `[1000, 4000]`).
    pub encoder_orders: Option<[u32; 2]>,
    /// Backlash per joint (full width), mdeg: the link lags by half of it behind the last motion.
    pub backlash_mdeg: f64,
    /// Thermal growth of every link length between identification and validation, ppm.
    pub thermal_drift_ppm: f64,
}

/// One harmonic of a joint's transmission error, rad.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Harmonic {
    /// Periods per turn of the joint.
    pub order: f64,
    /// Amplitude, rad.
    pub amplitude: f64,
    /// Phase, rad.
    pub phase: f64,
}

/// The physical robot: true model, drawn unmodelled effects, repeatability.
#[derive(Clone, Debug)]
pub struct VirtualRobot {
    /// The true geometry and compliance.
    pub truth: RobotModel,
    /// Transmission harmonics per joint.
    pub harmonics: [Vec<Harmonic>; JOINTS],
    /// Half the backlash per joint, rad.
    pub half_backlash: [f64; JOINTS],
    /// Standard deviation of the joint-level noise of a move, rad.
    pub sigma_q: f64,
    /// The effects a calibration learned (a twin's `[learned]` table), drawn for this world.
    pub learned: Option<super::learned::DrawnEffects>,
}

impl VirtualRobot {
    /// Draws the unmodelled effects of `spec` and scales the joint noise so that the ISO 9283
    /// repeatability at `reference_q` is `repeatability_mm`.
    pub fn new<R: Rng + ?Sized>(
        truth: RobotModel,
        spec: &UnmodelledSpec,
        repeatability_mm: f64,
        reference_q: &Joints,
        rng: &mut R,
    ) -> Self {
        let phase = Uniform::new(0.0, 2.0 * PI).expect("range");
        let harmonics = std::array::from_fn(|_| {
            let mut h = Vec::new();
            if spec.transmission_low_mdeg > 0.0 {
                for order in [1.0, 2.0] {
                    h.push(Harmonic { order, amplitude: (spec.transmission_low_mdeg * 1e-3).to_radians(), phase: phase.sample(rng) });
                }
            }
            if spec.transmission_high_mdeg > 0.0 {
                let [lo, hi] = spec.transmission_high_orders.unwrap_or([20, 120]);
                for _ in 0..spec.transmission_high_count.unwrap_or(1) {
                    let order = rng.random_range(lo..=hi.max(lo)) as f64;
                    h.push(Harmonic { order, amplitude: (spec.transmission_high_mdeg * 1e-3).to_radians(), phase: phase.sample(rng) });
                }
            }
            if spec.encoder_mdeg > 0.0 {
                let [lo, hi] = spec.encoder_orders.unwrap_or([1000, 4000]);
                let order = rng.random_range(lo..=hi.max(lo)) as f64;
                h.push(Harmonic { order, amplitude: (spec.encoder_mdeg * 1e-3).to_radians(), phase: phase.sample(rng) });
            }
            h
        });
        let half_backlash = [(spec.backlash_mdeg * 1e-3).to_radians() / 2.0; JOINTS];
        let sigma_q = repeatability_mm / repeatability_per_radian(&truth, reference_q);
        Self { truth, harmonics, half_backlash, sigma_q, learned: None }
    }

    /// This robot with the learned effects of a twin drawn once for this world (their
    /// coefficients from their fitted distributions; see [`super::learned`]). Draws from `rng`
    /// only when `learned` has an effect.
    pub fn with_learned<R: Rng + ?Sized>(mut self, learned: Option<&super::learned::LearnedEffects>, rng: &mut R) -> Self {
        if let Some(l) = learned.filter(|l| !l.is_none()) {
            self.learned = Some(l.draw(&self.truth, rng));
        }
        self
    }

    /// This robot with the repeatability of its moves drawn for this world when a twin's table
    /// gives the standard deviation of its level (`repeatability_std_mm`): a normal draw about
    /// `repeatability_mm` from `rng`, kept non-negative, made after every other draw of the robot.
    /// Without one (or without a twin) the robot is unchanged and nothing is drawn.
    pub fn with_learned_repeatability<R: Rng + ?Sized>(
        self,
        learned: Option<&super::learned::LearnedEffects>,
        repeatability_mm: f64,
        reference_q: &Joints,
        rng: &mut R,
    ) -> Self {
        match learned.filter(|l| l.repeatability_std_mm > 0.0) {
            Some(l) => {
                let level = l.drawn_repeatability_about(repeatability_mm, rng);
                self.with_repeatability(level, reference_q)
            }
            None => self,
        }
    }

    /// This robot with the joint noise of its moves scaled so that its ISO 9283 repeatability at
    /// `reference_q` is `repeatability_mm` (as [`VirtualRobot::new`] scales it).
    pub fn with_repeatability(mut self, repeatability_mm: f64, reference_q: &Joints) -> Self {
        self.sigma_q = repeatability_mm / repeatability_per_radian(&self.truth, reference_q);
        self
    }

    /// Link angles after a move to `q` coming from `from`, with a fresh draw of the joint noise.
    pub fn link_angles<R: Rng + ?Sized>(&self, q: &Joints, from: &Joints, rng: &mut R) -> Joints {
        let noise = Normal::new(0.0, self.sigma_q.max(0.0)).expect("finite sigma");
        let learned = self.learned.as_ref().map_or([0.0; JOINTS], |l| l.joint_errors(q, from));
        std::array::from_fn(|i| {
            let tx: f64 = self.harmonics[i].iter().map(|h| h.amplitude * (h.order * q[i] + h.phase).sin()).sum();
            let lag = if q[i] > from[i] {
                -self.half_backlash[i]
            } else if q[i] < from[i] {
                self.half_backlash[i]
            } else {
                0.0
            };
            q[i] + tx + lag + learned[i] + if self.sigma_q > 0.0 { noise.sample(rng) } else { 0.0 }
        })
    }

    /// True TCP in {W} after a move to `q` from `from`, mm.
    pub fn tcp_after_move<R: Rng + ?Sized>(&self, st: &mut KinState, q: &Joints, from: &Joints, rng: &mut R) -> nalgebra::Vector3<f64> {
        let links = self.link_angles(q, from, rng);
        forward(&self.truth, st, &links)
    }

    /// This robot with every link length grown by `ppm` (thermal drift).
    pub fn drifted(&self, ppm: f64) -> Self {
        let k = 1.0 + ppm * 1e-6;
        let truth = self
            .truth
            .edited(|d| {
                for l in &mut d.links {
                    l.a *= k;
                    l.d *= k;
                }
            })
            .expect("scaled lengths stay finite");
        Self { truth, ..self.clone() }
    }
}

/// ISO 9283 repeatability (RP = mean + 3 std of distances to the barycentre) per radian of
/// independent joint noise at `q`: for small noise the TCP scatter is Gaussian with covariance
/// `sigma^2 J J^T`; RP is estimated from 20000 draws of a fixed-seed stream (deterministic).
fn repeatability_per_radian(model: &RobotModel, q: &Joints) -> f64 {
    let mut st = KinState::default();
    let p0 = forward(model, &mut st, q);
    let h = 1e-7;
    let cols: Vec<nalgebra::Vector3<f64>> = (0..JOINTS)
        .map(|k| {
            let mut qk = *q;
            qk[k] += h;
            (forward(model, &mut st, &qk) - p0) / h
        })
        .collect();
    let mut rng = crate::seeds::fixed_stream(crate::seeds::fixed::REPEATABILITY);
    let normal = Normal::new(0.0, 1.0).expect("unit normal");
    let n = 20_000;
    let d: Vec<f64> = (0..n).map(|_| cols.iter().map(|c| c * normal.sample(&mut rng)).sum::<nalgebra::Vector3<f64>>().norm()).collect();
    let mean = d.iter().sum::<f64>() / n as f64;
    let std = (d.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / (n - 1) as f64).sqrt();
    mean + 3.0 * std
}
