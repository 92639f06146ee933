//! What a calibration learned about a robot beyond its model: the `[learned]` table of a robot
//! file (the twin `calsim calibrate` writes), and its effect on the link angles of a move.
//!
//! ```toml
//! [learned]
//! source = "calsim calibrate of m.csv (geometric model, calibration split)"
//! repeatability_mm = 0.012          # ISO 9283 RP of a move (joint noise scaled as the scenarios')
//! repeatability_std_mm = 0.002      # standard deviation of that level's estimate (calibrate's plan)
//! pose_error_mdeg = 1.5             # per-joint error the effects below leave, repeatable per pose
//! pose_error_std_mdeg = 0.4         # standard deviation of that level's estimate
//! pose_error_length_rad = 0.6       # where the twin says Smooth: the error's correlation length
//! pose_error_length_std_rad = 0.2   # in joint space, and its standard deviation
//! backlash_mdeg = [0, 6, 4, 0, 0, 0]      # full width per joint: the link lags half of it
//! backlash_std_mdeg = [0, 1, 1, 0, 0, 0]
//! sag_mdeg_per_m = [0, 9, 5, 0, 0, 0]     # joint error per metre of a TCP mass's lever arm
//! sag_std_mdeg_per_m = [0, 2, 2, 0, 0, 0]
//! drift_mm_per_pose = [0.002, 0, -0.001]  # the base's translation per pose of a session (calibrate's plan)
//! drift_std_mm_per_pose = [0.0001, 0, 0.0001]
//!
//! [[learned.harmonic]]              # delta theta_j = sin_mdeg sin(order q_j) + cos_mdeg cos(order q_j)
//! joint = 2
//! order = 1
//! sin_mdeg = 12.3
//! cos_mdeg = -4.0
//! std_mdeg = 1.2                    # standard deviation of each coefficient
//! ```
//!
//! Each world of a simulation draws the coefficients once from their fitted distribution
//! ([`LearnedEffects::draw`]): a plan with the twin carries what the calibration could not pin
//! down. The per-pose error is drawn as encoder-like harmonics of orders in the thousands (each
//! joint's error repeatable at a joint value, unrelated from one pose to the next), of RMS
//! `pose_error_mdeg`, its level itself drawn per world where `pose_error_std_mdeg` is given;
//! where `pose_error_length_rad` is given, as a smooth random field of that correlation length
//! in joint space instead (random Fourier features, [`FIELD_FEATURES`] per joint).

use std::f64::consts::PI;

use rand::{Rng, RngExt};
use rand_distr::{Distribution, Normal, Uniform};
use serde::{Deserialize, Serialize};

use super::kinematics::gravity_torques;
use super::model::{Inertial, JOINTS, Joints, RobotModel};

/// The most harmonics a `[learned]` table may carry.
pub const MOST_HARMONICS: usize = 600;

/// Encoder-like harmonics per joint that carry the per-pose error.
const POSE_ERROR_HARMONICS: usize = 4;

/// Random Fourier features per joint that carry a smooth per-pose error: enough that a long field,
/// of which a calibration absorbs all but the high frequencies, keeps those of its kernel.
pub const FIELD_FEATURES: usize = 512;

/// One learned harmonic of a joint's transmission error.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct LearnedHarmonic {
    /// Joint, 1..=6.
    pub joint: usize,
    /// Periods per turn of the joint (positive, at most 100000).
    pub order: f64,
    /// Coefficient of `sin(order q)`, mdeg.
    pub sin_mdeg: f64,
    /// Coefficient of `cos(order q)`, mdeg.
    pub cos_mdeg: f64,
    /// Standard deviation of each coefficient, mdeg.
    #[serde(default)]
    pub std_mdeg: f64,
}

/// The `[learned]` table of a robot file.
#[derive(Clone, Debug, Default, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct LearnedEffects {
    /// Where it was learned.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source: Option<String>,
    /// ISO 9283 repeatability of a move, mm.
    #[serde(default)]
    pub repeatability_mm: f64,
    /// Standard deviation of the estimate of `repeatability_mm`, mm: each world of `calsim
    /// calibrate`'s plan draws the level from a normal distribution about it (kept non-negative,
    /// [`LearnedEffects::drawn_repeatability_mm`]); so does each world of a scenario whose robot
    /// takes the twin's level ([`crate::robot::VirtualRobot::with_learned_repeatability`]).
    #[serde(default)]
    pub repeatability_std_mm: f64,
    /// RMS of the per-pose joint error the effects leave, mdeg (repeatable at a pose).
    #[serde(default)]
    pub pose_error_mdeg: f64,
    /// Standard deviation of the estimate of `pose_error_mdeg`, mdeg: each world draws the level
    /// from a normal distribution about it (kept non-negative).
    #[serde(default)]
    pub pose_error_std_mdeg: f64,
    /// Correlation length of the per-pose error in joint space, rad (0: independent per pose):
    /// the error is a smooth random field whose correlation between poses `d` apart (Euclidean
    /// over the six joint values) is `exp(-d^2 / (2 length^2))`.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub pose_error_length_rad: f64,
    /// Standard deviation of the estimate of `pose_error_length_rad`, rad (its 95 % interval's
    /// width over 2 x 1.96; stated, not drawn).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub pose_error_length_std_rad: f64,
    /// Backlash per joint, full width, mdeg.
    #[serde(default)]
    pub backlash_mdeg: [f64; JOINTS],
    /// Standard deviation of each backlash width, mdeg.
    #[serde(default)]
    pub backlash_std_mdeg: [f64; JOINTS],
    /// Gravity sag per joint: joint error per metre of the lever arm of a mass at the TCP about
    /// the joint's axis (its holding torque per kg and per g), mdeg/m.
    #[serde(default)]
    pub sag_mdeg_per_m: [f64; JOINTS],
    /// Standard deviation of each sag coefficient, mdeg/m.
    #[serde(default)]
    pub sag_std_mdeg_per_m: [f64; JOINTS],
    /// Drift of the base over a session: its translation per pose of the session, in the base
    /// frame, mm per pose (the pose order of a measurement file). A robot file has no pose order:
    /// the scenarios leave it out; `calsim calibrate`'s plan draws it.
    #[serde(default)]
    pub drift_mm_per_pose: [f64; 3],
    /// Standard deviation of each drift component, mm per pose.
    #[serde(default)]
    pub drift_std_mm_per_pose: [f64; 3],
    /// Transmission harmonics.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub harmonic: Vec<LearnedHarmonic>,
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

/// One world's draw of [`LearnedEffects`], in rad.
#[derive(Clone, Debug)]
pub struct DrawnEffects {
    /// `(joint 0-based, order, sin coefficient, cos coefficient)`, rad.
    pub harmonics: Vec<(usize, f64, f64, f64)>,
    /// The smooth per-pose error: `(joint 0-based, frequency over the six joint values (rad^-1),
    /// phase, amplitude rad)`, each adding `amplitude cos(frequency . q + phase)` to the joint.
    pub field: Vec<(usize, Joints, f64, f64)>,
    /// Half the backlash per joint, rad.
    pub half_backlash: [f64; JOINTS],
    /// Sag per joint, rad per metre of lever arm.
    pub sag_per_m: [f64; JOINTS],
    /// The base's translation per pose of a session, base frame, mm.
    pub drift_mm_per_pose: [f64; 3],
    /// The arm that gives the lever arms: the truth without link masses, 1 kg at the TCP
    /// (`None`: no sag).
    sag_arm: Option<RobotModel>,
}

impl LearnedEffects {
    /// The first key whose value is out of its range, with what is wrong (`learned.`-relative key).
    pub fn check(&self) -> Result<(), (String, String)> {
        let bad = |key: String, message: &str| Err((key, message.to_string()));
        let within = |v: f64, most: f64| v.is_finite() && (0.0..=most).contains(&v);
        if !within(self.repeatability_mm, 100.0) {
            return bad("repeatability_mm".into(), "within 0 to 100 mm");
        }
        if !within(self.repeatability_std_mm, 100.0) {
            return bad("repeatability_std_mm".into(), "within 0 to 100 mm");
        }
        if !within(self.pose_error_mdeg, 1.0e5) {
            return bad("pose_error_mdeg".into(), "within 0 to 100000 mdeg");
        }
        if !within(self.pose_error_std_mdeg, 1.0e5) {
            return bad("pose_error_std_mdeg".into(), "within 0 to 100000 mdeg");
        }
        if !within(self.pose_error_length_rad, 100.0) {
            return bad("pose_error_length_rad".into(), "within 0 to 100 rad");
        }
        if !within(self.pose_error_length_std_rad, 100.0) {
            return bad("pose_error_length_std_rad".into(), "within 0 to 100 rad");
        }
        for (name, v, most, what) in [
            ("backlash_mdeg", &self.backlash_mdeg, 1.0e5, "a width within 0 to 100000 mdeg"),
            ("backlash_std_mdeg", &self.backlash_std_mdeg, 1.0e5, "within 0 to 100000 mdeg"),
            ("sag_std_mdeg_per_m", &self.sag_std_mdeg_per_m, 1.0e6, "within 0 to 1000000 mdeg/m"),
        ] {
            if let Some(j) = v.iter().position(|&x| !within(x, most)) {
                return bad(format!("{name}[{j}]"), what);
            }
        }
        if let Some(j) = self.sag_mdeg_per_m.iter().position(|x| !(x.is_finite() && x.abs() <= 1.0e6)) {
            return bad(format!("sag_mdeg_per_m[{j}]"), "within -1000000 to 1000000 mdeg/m");
        }
        for (name, v) in [("drift_mm_per_pose", &self.drift_mm_per_pose), ("drift_std_mm_per_pose", &self.drift_std_mm_per_pose)] {
            let std = name.contains("std");
            if let Some(k) = v.iter().position(|&x| !(x.is_finite() && x.abs() <= 10.0 && (!std || x >= 0.0))) {
                return bad(format!("{name}[{k}]"), if std { "within 0 to 10 mm per pose" } else { "within -10 to 10 mm per pose" });
            }
        }
        if self.harmonic.len() > MOST_HARMONICS {
            return bad("harmonic".into(), "at most 600 harmonics");
        }
        for (k, h) in self.harmonic.iter().enumerate() {
            if !(1..=JOINTS).contains(&h.joint) {
                return bad(format!("harmonic[{k}].joint"), "a joint 1 to 6");
            }
            if !(h.order.is_finite() && h.order > 0.0 && h.order <= 1.0e5) {
                return bad(format!("harmonic[{k}].order"), "periods per turn above 0, at most 100000");
            }
            for (name, v) in [("sin_mdeg", h.sin_mdeg), ("cos_mdeg", h.cos_mdeg)] {
                if !(v.is_finite() && v.abs() <= 1.0e5) {
                    return bad(format!("harmonic[{k}].{name}"), "within -100000 to 100000 mdeg");
                }
            }
            if !within(h.std_mdeg, 1.0e5) {
                return bad(format!("harmonic[{k}].std_mdeg"), "within 0 to 100000 mdeg");
            }
        }
        Ok(())
    }

    /// No effect at all (every amplitude zero).
    pub fn is_none(&self) -> bool {
        self.repeatability_mm == 0.0
            && self.repeatability_std_mm == 0.0
            && self.pose_error_mdeg == 0.0
            && self.pose_error_std_mdeg == 0.0
            && self.backlash_mdeg.iter().all(|&x| x == 0.0)
            && self.sag_mdeg_per_m.iter().all(|&x| x == 0.0)
            && self.drift_mm_per_pose.iter().all(|&x| x == 0.0)
            && self.harmonic.iter().all(|h| h.sin_mdeg == 0.0 && h.cos_mdeg == 0.0)
    }

    /// One world's effects on `truth`: every coefficient drawn from its normal distribution
    /// (a backlash width kept non-negative), the per-pose error's level likewise (where its
    /// standard deviation is given: a table without one draws no level), the per-pose error as
    /// encoder-like harmonics of random orders and phases. Draws from `rng` in a fixed order.
    pub fn draw<R: Rng + ?Sized>(&self, truth: &RobotModel, rng: &mut R) -> DrawnEffects {
        let mdeg = |x: f64| (x * 1e-3).to_radians();
        let unit = Normal::new(0.0, 1.0).expect("unit normal");
        let mut around = |mean: f64, std: f64| mean + std * unit.sample(rng);
        let mut harmonics: Vec<(usize, f64, f64, f64)> = self
            .harmonic
            .iter()
            .map(|h| (h.joint - 1, h.order, mdeg(around(h.sin_mdeg, h.std_mdeg)), mdeg(around(h.cos_mdeg, h.std_mdeg))))
            .collect();
        let half_backlash = std::array::from_fn(|j| mdeg(around(self.backlash_mdeg[j], self.backlash_std_mdeg[j]).max(0.0)) / 2.0);
        let sag_per_m: Joints = std::array::from_fn(|j| mdeg(around(self.sag_mdeg_per_m[j], self.sag_std_mdeg_per_m[j])));
        let pose_error_mdeg = if self.pose_error_std_mdeg > 0.0 {
            around(self.pose_error_mdeg, self.pose_error_std_mdeg).max(0.0)
        } else {
            self.pose_error_mdeg
        };
        let mut field = Vec::new();
        if pose_error_mdeg > 0.0 && self.pose_error_length_rad > 0.0 {
            field = smooth_field(mdeg(pose_error_mdeg), self.pose_error_length_rad, rng);
        } else if pose_error_mdeg > 0.0 {
            // Each harmonic's RMS is amplitude / sqrt(2); POSE_ERROR_HARMONICS of them per joint.
            let amplitude = mdeg(pose_error_mdeg) * (2.0 / POSE_ERROR_HARMONICS as f64).sqrt();
            let phase = Uniform::new(0.0, 2.0 * PI).expect("range");
            for j in 0..JOINTS {
                for _ in 0..POSE_ERROR_HARMONICS {
                    let order = rng.random_range(1000..=4000) as f64;
                    let p = phase.sample(rng);
                    harmonics.push((j, order, amplitude * p.cos(), amplitude * p.sin()));
                }
            }
        }
        let sag_arm = sag_per_m.iter().any(|&s| s != 0.0).then(|| {
            truth
                .edited(|d| {
                    d.links_inertial = [Inertial::NONE; JOINTS];
                    d.payload = Inertial { mass_kg: 1.0, com_mm: d.flange_tcp_mm };
                    for l in &mut d.links {
                        l.compliance = 0.0;
                    }
                })
                .expect("the truth with a unit mass at its TCP")
        });
        // Drawn last, and only when the table has a drift: tables without one draw as before.
        let drift_mm_per_pose = if self.drift_mm_per_pose.iter().chain(&self.drift_std_mm_per_pose).any(|&x| x != 0.0) {
            std::array::from_fn(|k| self.drift_mm_per_pose[k] + self.drift_std_mm_per_pose[k] * unit.sample(rng))
        } else {
            [0.0; 3]
        };
        DrawnEffects { harmonics, field, half_backlash, sag_per_m, drift_mm_per_pose, sag_arm }
    }
}

/// Random Fourier features of a smooth field of RMS `rms_rad` per joint whose correlation
/// between poses `d` apart is `exp(-d^2 / (2 length^2))`: per joint [`FIELD_FEATURES`] cosines
/// of amplitude `rms sqrt(2 / features)`, each frequency drawn from the kernel's spectral
/// density (a normal of standard deviation `1 / length` per joint value), each phase uniform.
/// Over worlds, the field's covariance is the kernel's exactly.
pub(crate) fn smooth_field<R: Rng + ?Sized>(rms_rad: f64, length_rad: f64, rng: &mut R) -> Vec<(usize, Joints, f64, f64)> {
    smooth_field_of(rms_rad, length_rad, FIELD_FEATURES, rng)
}

/// [`smooth_field`] with `features` cosines per joint (its covariance over worlds is the kernel's
/// for any count; a single draw's departs from it by about `1 / sqrt(features)`).
pub(crate) fn smooth_field_of<R: Rng + ?Sized>(
    rms_rad: f64,
    length_rad: f64,
    features: usize,
    rng: &mut R,
) -> Vec<(usize, Joints, f64, f64)> {
    let frequency = Normal::new(0.0, 1.0 / length_rad).expect("a positive length");
    let phase = Uniform::new(0.0, 2.0 * PI).expect("range");
    let amplitude = rms_rad * (2.0 / features as f64).sqrt();
    let mut field = Vec::with_capacity(JOINTS * features);
    for j in 0..JOINTS {
        for _ in 0..features {
            let w: Joints = std::array::from_fn(|_| frequency.sample(rng));
            field.push((j, w, phase.sample(rng), amplitude));
        }
    }
    field
}

/// Adds the smooth field `field` ([`smooth_field`]'s features) at joint values `q` to `e`, rad.
pub(crate) fn add_field(field: &[(usize, Joints, f64, f64)], q: &Joints, e: &mut Joints) {
    for (j, w, phase, amplitude) in field {
        let x: f64 = w.iter().zip(q).map(|(a, b)| a * b).sum::<f64>() + phase;
        e[*j] += amplitude * x.cos();
    }
}

impl LearnedEffects {
    /// One world's repeatability, ISO 9283 RP, mm: a normal draw about `repeatability_mm` with
    /// standard deviation `repeatability_std_mm`, kept non-negative (a level estimated at zero with
    /// an interval above zero still gives some worlds a repeatability); without a standard
    /// deviation the level itself, and nothing is drawn from `rng`.
    pub fn drawn_repeatability_mm<R: Rng + ?Sized>(&self, rng: &mut R) -> f64 {
        self.drawn_repeatability_about(self.repeatability_mm, rng)
    }

    /// [`LearnedEffects::drawn_repeatability_mm`] about the level `level_mm` (a scenario's robot
    /// takes the twin's level as its own `robot.repeatability_mm`).
    pub fn drawn_repeatability_about<R: Rng + ?Sized>(&self, level_mm: f64, rng: &mut R) -> f64 {
        if self.repeatability_std_mm > 0.0 {
            let unit: f64 = Normal::new(0.0, 1.0).expect("unit normal").sample(rng);
            (level_mm + self.repeatability_std_mm * unit).max(0.0)
        } else {
            level_mm
        }
    }
}

impl DrawnEffects {
    /// The joint errors at commanded `q` coming from `from`, rad: harmonics of `q`, backlash by
    /// the approach direction, sag by the TCP's lever arms.
    pub fn joint_errors(&self, q: &Joints, from: &Joints) -> Joints {
        let mut e = [0.0; JOINTS];
        for &(j, order, s, c) in &self.harmonics {
            let x = order * q[j];
            e[j] += s * x.sin() + c * x.cos();
        }
        add_field(&self.field, q, &mut e);
        for j in 0..JOINTS {
            e[j] += if q[j] > from[j] {
                -self.half_backlash[j]
            } else if q[j] < from[j] {
                self.half_backlash[j]
            } else {
                0.0
            };
        }
        if let Some(arm) = &self.sag_arm {
            let g = arm.data().gravity_base.norm();
            if g > 0.0 {
                let tau = gravity_torques(arm, q);
                for j in 0..JOINTS {
                    e[j] += self.sag_per_m[j] * tau[j] / g;
                }
            }
        }
        e
    }
}

/// The lever arm of a 1 kg mass at the TCP about each joint's axis at `q`, metres with the sign of
/// its holding torque (the column a sag coefficient multiplies): zero where the model has no gravity.
pub fn lever_arms_m(truth: &RobotModel, q: &Joints) -> Joints {
    let arm = truth
        .edited(|d| {
            d.links_inertial = [Inertial::NONE; JOINTS];
            d.payload = Inertial { mass_kg: 1.0, com_mm: d.flange_tcp_mm };
            for l in &mut d.links {
                l.compliance = 0.0;
            }
        })
        .expect("the truth with a unit mass at its TCP");
    let g = arm.data().gravity_base.norm();
    if g == 0.0 {
        return [0.0; JOINTS];
    }
    let tau = gravity_torques(&arm, q);
    std::array::from_fn(|j| tau[j] / g)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::builtin::irb120;
    use rand::SeedableRng;

    #[test]
    fn the_example_of_the_module_doc_parses_and_checks() {
        let text = "repeatability_mm = 0.012\npose_error_mdeg = 1.5\nbacklash_mdeg = [0, 6, 4, 0, 0, 0]\n\
                    [[harmonic]]\njoint = 2\norder = 1\nsin_mdeg = 12.3\ncos_mdeg = -4.0\nstd_mdeg = 1.2\n";
        let l: LearnedEffects = toml::from_str(text).expect("parses");
        assert_eq!(l.harmonic.len(), 1);
        assert!(l.check().is_ok());
        let mut bad = l.clone();
        bad.harmonic[0].joint = 7;
        assert_eq!(bad.check().unwrap_err().0, "harmonic[0].joint");
        let mut bad = l;
        bad.backlash_mdeg[1] = f64::NAN;
        assert_eq!(bad.check().unwrap_err().0, "backlash_mdeg[1]");
    }

    #[test]
    fn a_repeatability_with_a_spread_is_drawn_per_world_and_without_one_draws_nothing() {
        let point = LearnedEffects { repeatability_mm: 0.02, ..Default::default() };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        assert_eq!(point.drawn_repeatability_mm(&mut rng), 0.02);
        let next: u64 = rng.random();
        assert_eq!(next, rand_chacha::ChaCha8Rng::seed_from_u64(7).random::<u64>(), "nothing drawn without a spread");
        let spread = LearnedEffects { repeatability_std_mm: 0.01, ..point.clone() };
        let draws: Vec<f64> = (0..2000).map(|_| spread.drawn_repeatability_mm(&mut rng)).collect();
        assert!(draws.iter().all(|&d| d >= 0.0));
        let mean = draws.iter().sum::<f64>() / draws.len() as f64;
        let sd = (draws.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / (draws.len() - 1) as f64).sqrt();
        // A normal about 0.02 with sd 0.01 kept >= 0: mean 0.0201, sd 0.0098 (its 2.3 % below zero clipped).
        assert!((mean - 0.0201).abs() < 0.0007 && (sd - 0.0098).abs() < 0.0007, "{mean} {sd}");
        let zero = LearnedEffects { repeatability_std_mm: 0.01, ..Default::default() };
        assert!(!zero.is_none());
        assert!((0..50).any(|_| zero.drawn_repeatability_mm(&mut rng) > 0.0), "a level estimated at zero still draws some");
        let bad = LearnedEffects { repeatability_std_mm: f64::NAN, ..Default::default() };
        assert_eq!(bad.check().unwrap_err().0, "repeatability_std_mm");
    }

    #[test]
    fn a_drift_is_checked_drawn_last_and_leaves_tables_without_one_drawing_as_before() {
        let truth = irb120();
        let base = LearnedEffects { pose_error_mdeg: 1.5, backlash_std_mdeg: [0.0, 1.0, 0.0, 0.0, 0.0, 0.0], ..Default::default() };
        let drifting = LearnedEffects { drift_mm_per_pose: [0.002, 0.0, -0.001], ..base.clone() };
        let draw = |l: &LearnedEffects| l.draw(&truth, &mut rand_chacha::ChaCha8Rng::seed_from_u64(4));
        let (a, b) = (draw(&base), draw(&drifting));
        assert_eq!(a.harmonics, b.harmonics, "the drift is drawn after everything else");
        assert_eq!(a.half_backlash, b.half_backlash);
        assert_eq!((a.drift_mm_per_pose, b.drift_mm_per_pose), ([0.0; 3], [0.002, 0.0, -0.001]));
        assert!(!LearnedEffects { drift_mm_per_pose: [0.0, 0.001, 0.0], ..Default::default() }.is_none());
        let bad = LearnedEffects { drift_mm_per_pose: [0.0, f64::INFINITY, 0.0], ..Default::default() };
        assert_eq!(bad.check().unwrap_err().0, "drift_mm_per_pose[1]");
        let bad = LearnedEffects { drift_std_mm_per_pose: [0.0, 0.0, -1e-3], ..Default::default() };
        assert_eq!(bad.check().unwrap_err().0, "drift_std_mm_per_pose[2]");
    }

    #[test]
    fn the_per_pose_errors_level_is_drawn_per_world_only_where_its_spread_is_given() {
        let truth = irb120();
        let fixed = LearnedEffects { pose_error_mdeg: 2.0, backlash_mdeg: [0.0, 6.0, 0.0, 0.0, 0.0, 0.0], ..Default::default() };
        let spread = LearnedEffects { pose_error_std_mdeg: 0.5, ..fixed.clone() };
        let rms = |d: &DrawnEffects| {
            let s: f64 = d.harmonics.iter().map(|h| h.2 * h.2 + h.3 * h.3).sum::<f64>() / 2.0 / JOINTS as f64;
            (s.sqrt() * 1e3).to_degrees()
        };
        let mut levels = Vec::new();
        for seed in 0..200 {
            let draw = |l: &LearnedEffects| l.draw(&truth, &mut rand_chacha::ChaCha8Rng::seed_from_u64(seed));
            let (a, b) = (draw(&fixed), draw(&spread));
            assert!((rms(&a) - 2.0).abs() < 1e-9, "without a spread the level is the table's: {}", rms(&a));
            assert_eq!(a.half_backlash, b.half_backlash, "the level is drawn after the coefficients");
            levels.push(rms(&b));
        }
        let mean = levels.iter().sum::<f64>() / levels.len() as f64;
        let sd = (levels.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (levels.len() - 1) as f64).sqrt();
        // 200 draws: the mean within 4 standard errors of 2.0, the spread within 20 % of 0.5.
        assert!((mean - 2.0).abs() < 4.0 * 0.5 / 200f64.sqrt(), "mean level {mean}");
        assert!((sd - 0.5).abs() < 0.1, "level's spread {sd}");
        // A level estimated at zero with a spread: some worlds draw none, others some.
        let zero = LearnedEffects { pose_error_std_mdeg: 0.5, ..Default::default() };
        assert!(!zero.is_none());
        let some = (0..40).filter(|&s| !zero.draw(&truth, &mut rand_chacha::ChaCha8Rng::seed_from_u64(s)).harmonics.is_empty()).count();
        assert!((5..=35).contains(&some), "{some} of 40 worlds with a per-pose error");
        let bad = LearnedEffects { pose_error_std_mdeg: -0.1, ..Default::default() };
        assert_eq!(bad.check().unwrap_err().0, "pose_error_std_mdeg");
    }

    /// A smooth field of length 0.6 rad and 2 mdeg RMS drawn in 1,500 worlds, at pairs of poses
    /// 0, 0.3, 0.6 and 1.2 rad apart: over the 9,000 joint values per distance, the correlation
    /// matches the kernel `exp(-d^2 / (2 l^2))` (1, 0.882, 0.607, 0.135) within 0.042 (four times
    /// 1 / sqrt(9000), the largest standard error of a sample correlation), the RMS 2 mdeg within
    /// 4 standard errors of a normal's (sqrt(2 / 9000) relative); the field carries no harmonics,
    /// and a table without a length draws exactly the table without the key.
    #[test]
    fn a_smooth_per_pose_error_has_the_stated_kernel_and_level() {
        let truth = irb120();
        let l = LearnedEffects { pose_error_mdeg: 2.0, pose_error_length_rad: 0.6, ..Default::default() };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(17);
        let q0 = [0.2, -0.4, 0.3, 1.0, -0.5, 0.7];
        let u = [1.0, -1.0, 2.0, 0.5, -0.5, 1.5];
        let norm = u.iter().map(|x: &f64| x * x).sum::<f64>().sqrt();
        let distances = [0.0, 0.3, 0.6, 1.2];
        let mut sums = [[0.0f64; 3]; 4];
        let worlds = 1500;
        for _ in 0..worlds {
            let d = l.draw(&truth, &mut rng);
            assert!(d.harmonics.is_empty() && d.field.len() == JOINTS * FIELD_FEATURES);
            let e0 = d.joint_errors(&q0, &q0);
            for (k, &dist) in distances.iter().enumerate() {
                let q: Joints = std::array::from_fn(|j| q0[j] + dist * u[j] / norm);
                let e = d.joint_errors(&q, &q);
                for j in 0..JOINTS {
                    sums[k][0] += e0[j] * e[j];
                    sums[k][1] += e0[j] * e0[j];
                    sums[k][2] += e[j] * e[j];
                }
            }
        }
        let n = (worlds * JOINTS) as f64;
        for (k, &dist) in distances.iter().enumerate() {
            let rho = sums[k][0] / (sums[k][1] * sums[k][2]).sqrt();
            let kernel = (-dist * dist / (2.0 * 0.36)).exp();
            assert!((rho - kernel).abs() < 4.0 / n.sqrt(), "at {dist} rad: {rho} against {kernel}");
        }
        let rms = (sums[0][1] / n).sqrt().to_degrees() * 1e3;
        assert!((rms / 2.0 - 1.0).abs() < 4.0 * (2.0 / n).sqrt() / 2.0, "RMS {rms} mdeg");
        let plain = LearnedEffects { pose_error_mdeg: 2.0, ..Default::default() };
        let draw = |l: &LearnedEffects| l.draw(&truth, &mut rand_chacha::ChaCha8Rng::seed_from_u64(3));
        let with_zero = toml::from_str::<LearnedEffects>("pose_error_mdeg = 2.0\npose_error_length_rad = 0.0\n").unwrap();
        assert_eq!(draw(&plain).harmonics, draw(&with_zero).harmonics);
        assert!(draw(&plain).field.is_empty());
        assert!(!toml::to_string(&plain).unwrap().contains("length"), "a table without a length writes no key");
        let bad = LearnedEffects { pose_error_length_rad: f64::NAN, ..Default::default() };
        assert_eq!(bad.check().unwrap_err().0, "pose_error_length_rad");
        let bad = LearnedEffects { pose_error_length_std_rad: -1.0, ..Default::default() };
        assert_eq!(bad.check().unwrap_err().0, "pose_error_length_std_rad");
    }

    #[test]
    fn a_draw_without_spread_applies_the_coefficients_exactly() {
        let truth = irb120();
        let mut l = LearnedEffects { backlash_mdeg: [0.0, 6.0, 0.0, 0.0, 0.0, 0.0], ..Default::default() };
        l.harmonic.push(LearnedHarmonic { joint: 3, order: 2.0, sin_mdeg: 10.0, cos_mdeg: -5.0, std_mdeg: 0.0 });
        let d = l.draw(&truth, &mut rand_chacha::ChaCha8Rng::seed_from_u64(1));
        let q = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6];
        let from = [0.0; JOINTS];
        let e = d.joint_errors(&q, &from);
        let mdeg = |x: f64| (x * 1e-3).to_radians();
        assert!((e[2] - (mdeg(10.0) * (0.6f64).sin() + mdeg(-5.0) * (0.6f64).cos())).abs() < 1e-15);
        assert!((e[1] + mdeg(3.0)).abs() < 1e-15, "coming from below, the link lags half the width");
        assert_eq!(e[0], 0.0);
    }

    #[test]
    fn the_lever_arm_of_joint_two_is_the_horizontal_reach_from_its_axis() {
        // At q = 0 the IRB 120 stands upright with the wrist ahead: a central difference of the TCP
        // height against joint 2 is the horizontal lever arm (up to the sign convention of the torque).
        let truth = irb120();
        let q = [0.0, 0.3, 0.2, 0.0, 0.4, 0.0];
        let l = lever_arms_m(&truth, &q);
        let h = 1e-6;
        let z = |dq: f64| {
            let mut qq = q;
            qq[1] += dq;
            crate::robot::tcp_world(&truth, &qq).z
        };
        let dz_dq = (z(h) - z(-h)) / (2.0 * h) * 1e-3;
        assert!((l[1].abs() - dz_dq.abs()).abs() < 1e-6, "lever {} against d z / d q2 {}", l[1], dz_dq);
    }
}
