//! Campaigns: the configurations a cell measures. Owns its random streams (seeded by the caller).

use rand::{Rng, RngExt};

use crate::robot::{JOINTS, Joints, RobotModel};

/// A configuration drawn uniformly inside the joint limits, leaving `margin` (a fraction of each
/// range) free at both ends; joint 6 is drawn within +-180 deg, its full turn.
pub fn uniform_configuration<R: Rng + ?Sized>(model: &RobotModel, margin: f64, rng: &mut R) -> Joints {
    std::array::from_fn::<f64, JOINTS, _>(|i| {
        let l = model.limits()[i];
        let (lo, hi) = if i == JOINTS - 1 {
            (l.min.max(-std::f64::consts::PI), l.max.min(std::f64::consts::PI))
        } else {
            (l.min, l.max)
        };
        let m = margin * (hi - lo);
        rng.random_range(lo + m..hi - m)
    })
}
