//! Orientation readings of six-degree-of-freedom probes (the file's `quat_w .. quat_z` columns)
//! before the fit: each reading in its session's registered frame with its weight, the start value
//! of each probe's rotation on the flange, and the rotation of a session whose positions fix no
//! whole frame (a line, or one position) found from its readings.

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use rayon::prelude::*;

use super::measurements::Measurements;
use super::problem::{Obs, Reading};
use super::registration::Span;
use crate::robot::{KinState, RobotModel, world_from_flange};

/// The orientation readings' uncertainty when the file gives no `sigma_deg` column, mdeg (a
/// rotation about any axis): `--orientation-noise-mdeg`.
pub const DEFAULT_ORIENTATION_NOISE_MDEG: f64 = 10.0;
/// The positions' uncertainty per coordinate the rotation residuals are weighted against when the
/// file has orientation columns and no `sigma_mm` column, mm: `--position-noise-mm`.
pub const DEFAULT_POSITION_NOISE_MM: f64 = 0.025;
/// Largest `--orientation-noise-mdeg`, mdeg (10 degrees).
pub const MOST_ORIENTATION_NOISE_MDEG: f64 = 1e4;
/// Largest `--position-noise-mm`, mm.
pub const MOST_POSITION_NOISE_MM: f64 = 100.0;
/// Step of the search for a line session's rotation about its line, deg.
const SCAN_STEP_DEG: f64 = 0.25;
/// A session's readings fix its rotation about its line when the mean squared angle between the
/// readings and the model varies over the turns about the line by more than this, rad^2 (one
/// degree squared: a turn of the flange that the readings see).
const SCAN_CONTRAST_RAD2: f64 = 3.046_174_197_867_086e-4;
/// A relative turn of the flange counts in the rotation of a session at one position when it is
/// at least this large, rad (1 degree).
const LEAST_TURN_RAD: f64 = 0.017_453_292_519_943_295;

/// How the readings are weighted.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Noise {
    /// The readings' uncertainty when the file gives none, rad.
    pub orientation_rad: f64,
    /// The positions' uncertainty per coordinate when the file gives none, mm (the rotation
    /// residuals are then in mm-equivalent: the angle over its uncertainty times this).
    pub position_mm: f64,
}

impl Default for Noise {
    fn default() -> Self {
        Self { orientation_rad: (DEFAULT_ORIENTATION_NOISE_MDEG * 1e-3).to_radians(), position_mm: DEFAULT_POSITION_NOISE_MM }
    }
}

/// The flange's rotation at each point of `obs` on `nominal` with its base at the origin (the
/// model's flange rotation in a session's registered frame at the start values).
fn flange_rotations(nominal: &RobotModel, obs: &[Obs]) -> Vec<Rotation3<f64>> {
    let at_origin = nominal.edited(|d| d.world_from_base = Default::default()).expect("the nominal model with its base at the origin");
    obs.par_iter().map_init(KinState::default, |st, o| world_from_flange(&at_origin, st, &o.q).rotation.to_rotation_matrix()).collect()
}

/// The chordal mean of `rs` (the rotation nearest their sum).
fn mean(rs: impl Iterator<Item = Rotation3<f64>>) -> Option<Rotation3<f64>> {
    let sum: Matrix3<f64> = rs.map(|r| r.into_inner()).sum();
    if sum == Matrix3::zeros() {
        return None;
    }
    let svd = sum.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let d = (u * v_t).determinant().signum();
    Some(Rotation3::from_matrix_unchecked(u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * v_t))
}

/// Kabsch: the rotation `B` minimising `sum |B a - c|^2` over the pairs, and the second largest
/// singular value of the cross-covariance over the largest (0: the pairs fix no rotation).
fn kabsch(pairs: &[(Vector3<f64>, Vector3<f64>)]) -> Option<(Rotation3<f64>, f64)> {
    let h: Matrix3<f64> = pairs.iter().map(|(a, c)| c * a.transpose()).sum();
    let svd = h.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let d = (u * v_t).determinant().signum();
    let r = u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * v_t;
    let mut s: Vec<f64> = svd.singular_values.iter().copied().collect();
    s.sort_by(|a, b| b.total_cmp(a));
    Some((Rotation3::from_matrix_unchecked(r), if s[0] > 0.0 { s[1] / s[0] } else { 0.0 }))
}

/// The readings of the file's points in their sessions' frames (`file`: per point, its quaternion
/// in the measuring frame and its uncertainty, rad), turned into the registered frames `frames`.
pub fn readings(m: &Measurements, frames: &[Isometry3<f64>], noise: &Noise) -> Vec<Option<Reading>> {
    m.points
        .iter()
        .map(|p| {
            let q = p.orientation?;
            let s = m.poses[p.pose].session;
            let measured = (frames[s].rotation.inverse() * q).to_rotation_matrix();
            let sigma = p.sigma_rad.unwrap_or(noise.orientation_rad);
            // Positions without their own uncertainty have unit weight (residuals in mm): the
            // rotations are weighted against `position_mm`.
            let sigma_rad = if p.sigma_mm.is_some() { sigma } else { sigma / noise.position_mm };
            Some(Reading { measured, sigma_rad })
        })
        .collect()
}

/// Turns the registered frame of every session with readings whose positions fix no whole frame
/// (`spans`) so that its readings agree with the nominal model: for a line, the turn about the line
/// (searched in steps of [`SCAN_STEP_DEG`]); for one position, the rotation that takes the
/// flange's relative turns to the readings' (Kabsch on their axes). `frames`, the points of `obs`
/// and `readings` of such a session are updated; returns per session whether its readings fix the
/// rotation its positions leave free.
pub fn orient_sessions(
    nominal: &RobotModel,
    spans: &[Span],
    frames: &mut [Isometry3<f64>],
    obs: &mut [Obs],
    readings: &mut [Option<Reading>],
) -> Vec<bool> {
    let mut fixed = vec![false; spans.len()];
    // The flanges' rotations, when a session has readings its positions do not already orient.
    let turned = |i: usize| readings[i].is_some() && spans[obs[i].session] != Span::Full;
    if !(0..obs.len()).any(turned) {
        return fixed;
    }
    let flanges = flange_rotations(nominal, obs);
    for (s, span) in spans.iter().enumerate() {
        let members: Vec<usize> = (0..obs.len()).filter(|&i| obs[i].session == s && readings[i].is_some()).collect();
        if members.is_empty() || *span == Span::Full {
            continue;
        }
        let measured = |i: usize| readings[i].map_or_else(Rotation3::identity, |r| r.measured);
        let turn = match span {
            Span::Full => continue,
            Span::Line(d) => {
                let u = frames[s].rotation.inverse_transform_vector(d).normalize();
                // Per candidate turn `phi` about the line: the readings turned back by it, each
                // target's rotation on the flange as their mean, the mean squared angle left.
                let cost = |phi: f64| {
                    let back = Rotation3::new(u * -phi);
                    let turned: Vec<Rotation3<f64>> = members.iter().map(|&i| back * measured(i)).collect();
                    let mut sum = 0.0;
                    for t in members.iter().map(|&i| obs[i].target).collect::<std::collections::BTreeSet<_>>() {
                        let of: Vec<usize> = (0..members.len()).filter(|&k| obs[members[k]].target == t).collect();
                        let Some(tool) = mean(of.iter().map(|&k| flanges[members[k]].inverse() * turned[k])) else { return f64::INFINITY };
                        sum += of.iter().map(|&k| (flanges[members[k]] * tool).angle_to(&turned[k]).powi(2)).sum::<f64>();
                    }
                    sum / members.len() as f64
                };
                let steps = (360.0 / SCAN_STEP_DEG) as usize;
                let costs: Vec<(f64, f64)> =
                    (0..steps).map(|k| ((k as f64 * SCAN_STEP_DEG).to_radians(), 0.0)).map(|(p, _)| (p, cost(p))).collect();
                let (best, least) = costs.iter().copied().min_by(|a, b| a.1.total_cmp(&b.1)).unwrap_or((0.0, f64::INFINITY));
                let most = costs.iter().map(|c| c.1).fold(0.0, f64::max);
                if !(least.is_finite() && most - least > SCAN_CONTRAST_RAD2) {
                    continue;
                }
                Rotation3::new(u * best)
            }
            Span::Point => {
                // M_i M_0^T = B (F_i F_0^T) B^T per target: the axes of the flange's relative turns,
                // turned by B, are the readings'.
                let mut pairs = Vec::new();
                for t in members.iter().map(|&i| obs[i].target).collect::<std::collections::BTreeSet<_>>() {
                    let of: Vec<usize> = members.iter().copied().filter(|&i| obs[i].target == t).collect();
                    let first = of[0];
                    for &i in &of[1..] {
                        let a = (flanges[i] * flanges[first].inverse()).scaled_axis();
                        let c = (measured(i) * measured(first).inverse()).scaled_axis();
                        if a.norm() >= LEAST_TURN_RAD {
                            pairs.push((a, c));
                        }
                    }
                }
                match kabsch(&pairs) {
                    Some((b, second)) if second > 0.05 => b,
                    _ => continue,
                }
            }
        };
        // The turn about the session's points' centroid (a line's points stay on it): the new
        // registered frame is the old one turned by `turn`.
        let of: Vec<usize> = (0..obs.len()).filter(|&i| obs[i].session == s).collect();
        let c: Vector3<f64> = of.iter().map(|&i| obs[i].measured_mm).sum::<Vector3<f64>>() / of.len() as f64;
        let rotation = UnitQuaternion::from_rotation_matrix(&turn);
        let d = Isometry3::from_parts(Translation3::from(c - turn * c), rotation);
        frames[s] *= d;
        for &i in &of {
            obs[i].measured_mm = d.inverse_transform_point(&obs[i].measured_mm.into()).coords;
            if let Some(r) = &mut readings[i] {
                r.measured = turn.inverse() * r.measured;
            }
        }
        fixed[s] = true;
    }
    fixed
}

/// Per target: the start value of its probe's rotation on the flange (the mean over its readings
/// of the nominal flange's rotation taken out of the reading); `None` for a target without one.
pub fn tool_rotations(nominal: &RobotModel, obs: &[Obs], readings: &[Option<Reading>], targets: usize) -> Vec<Option<Rotation3<f64>>> {
    if readings.iter().all(Option::is_none) {
        return vec![None; targets];
    }
    let flanges = flange_rotations(nominal, obs);
    (0..targets)
        .map(|t| {
            mean((0..obs.len()).filter(|&i| obs[i].target == t).filter_map(|i| readings[i].map(|r| flanges[i].inverse() * r.measured)))
        })
        .collect()
}
