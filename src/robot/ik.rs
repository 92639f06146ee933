//! Inverse kinematics of the model a controller believes: the closed form of the nominal
//! spherical wrist (every solution), then Newton refinement on the full model (identified
//! parameters, Hayati beta, compliance).
//!
//! Closed form, from Table 3 with `theta2 = q2 - 90 deg`: the wrist centre in the arm plane is
//! `r = a2 sin q2 + L sin(q2 + q3 + phi)`, `h = a2 cos q2 + L cos(q2 + q3 + phi)` above the shoulder,
//! with `L = hypot(a3, d4)` and `phi = atan2(d4, a3)`; the wrist is `R_36 = Rx(-90) Rz(q4) Ry(-q5) Rz(q6 + 180)`.
//!
//! Choice among solutions: the one within the joint limits closest to the seed (Euclidean in joint
//! space, joint 6 unwrapped to the seed's turn).
//!
//! Arms of another structure (a shoulder offset, other twists: the ER20-C10, the KR 6 of
//! `robots/`) take [`numeric`]: damped least squares from the seed and a fixed set of starts.

use std::f64::consts::PI;

use nalgebra::{Isometry3, Matrix3, Matrix6, Rotation3, Vector3, Vector6};

use super::kinematics::KinState;
use super::kinematics::forward;
use super::model::{JOINTS, Joints, RobotModel};

/// Why no configuration was returned.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum IkError {
    /// The wrist centre is out of the arm's reach.
    #[error("target out of reach")]
    Unreachable,
    /// Every solution violates a joint limit.
    #[error("every solution violates a joint limit")]
    Limits,
    /// Newton refinement on the full model did not converge, or converged on a frame turned from
    /// the target (the first-order orientation error vanishes at a half-turn as at agreement).
    #[error("refinement did not converge (residual {position_mm:e} mm, {orientation_deg:e} deg)")]
    NoConvergence {
        /// Position residual at the last iterate, mm.
        position_mm: f64,
        /// Angle between the frame reached and the target frame at the last iterate, deg.
        orientation_deg: f64,
    },
}

/// How far the TCP frame of a model at some joints is from a target frame: both errors.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseError {
    /// Distance between the TCP and the target position, mm.
    pub position_mm: f64,
    /// Angle of the rotation between the frame reached and the target frame, rad in [0, pi].
    pub orientation_rad: f64,
}

/// Largest angle, rad, between the frame Newton's method reached and the target frame for
/// [`refine_oriented`] to accept it: the method stops at 1e-13 of first-order error, which also
/// holds a half-turn away, so any bound well below a half-turn tells the two apart.
const ORIENTATION_TOLERANCE_RAD: f64 = 1e-6;

/// The TCP position and frame-6 orientation errors of `model` at `q` against `world_from_tcp`
/// (the pose [`inverse`] takes: the TCP position, frame 6's orientation).
pub fn pose_error(model: &RobotModel, q: &Joints, world_from_tcp: &Isometry3<f64>) -> PoseError {
    let mut st = KinState::default();
    let p = forward(model, &mut st, q);
    let r = model.base_rot * st.rot[JOINTS];
    PoseError {
        position_mm: (p - world_from_tcp.translation.vector).norm(),
        orientation_rad: super::rotation::angle(&r, world_from_tcp.rotation.to_rotation_matrix().matrix()),
    }
}

/// Closed-form solutions of the *nominal* geometry of `model` (its a2, a3, d1, d4, d6 and the
/// Table 3 twists; every other parameter taken as zero) for `base_from_flange`.
pub fn closed_form(model: &RobotModel, base_from_flange: &Isometry3<f64>) -> Vec<Joints> {
    let l = model.links();
    let (d1, a2, a3, d4, d6) = (l[0].d, l[2].a, l[3].a, l[3].d, l[5].d);
    let r06 = base_from_flange.rotation.to_rotation_matrix().into_inner();
    let wc = base_from_flange.translation.vector - r06.column(2) * d6;
    let len = a3.hypot(d4);
    let phi = d4.atan2(a3);
    let mut out = Vec::with_capacity(8);
    let rho = wc.x.hypot(wc.y);
    let h = wc.z - d1;
    for (q1, r) in [(wc.y.atan2(wc.x), rho), (wc.y.atan2(wc.x) + PI, -rho)] {
        let c = (r * r + h * h - a2 * a2 - len * len) / (2.0 * a2 * len);
        // Slightly past full stretch for the nominal geometry can still be inside the reach of the
        // full model: clamp, and let the refinement decide.
        if c.abs() > 1.0 + 1e-3 {
            continue;
        }
        let c = c.clamp(-1.0, 1.0);
        for elbow in [1.0, -1.0] {
            let psi = elbow * c.acos(); // q3 + phi
            let q3 = psi - phi;
            let q2 = r.atan2(h) - (len * psi.sin()).atan2(a2 + len * psi.cos());
            let q = [wrap(q1), wrap(q2), wrap(q3), 0.0, 0.0, 0.0];
            let r03 = arm_rotation(model, &q);
            let m = rx(PI / 2.0) * r03.transpose() * r06; // Rz(q4) Ry(-q5) Rz(theta6)
            let b = m[(0, 2)].hypot(m[(1, 2)]).atan2(m[(2, 2)]);
            for (b, flip) in [(b, 0.0), (-b, PI)] {
                let (a, cc) = if b.abs() < 1e-12 {
                    // Wrist singularity: only q4 + theta6 is defined; keep q4 = 0.
                    (0.0, m[(1, 0)].atan2(m[(0, 0)]))
                } else {
                    (m[(1, 2)].atan2(m[(0, 2)]) + flip, m[(2, 1)].atan2(-m[(2, 0)]) + flip)
                };
                out.push([q[0], q[1], q[2], wrap(a), wrap(-b), wrap(cc - l[5].theta_offset)]);
            }
        }
    }
    out
}

fn rx(a: f64) -> Matrix3<f64> {
    Rotation3::from_axis_angle(&Vector3::x_axis(), a).into_inner()
}

fn wrap(a: f64) -> f64 {
    let mut x = (a + PI).rem_euclid(2.0 * PI) - PI;
    if x <= -PI {
        x += 2.0 * PI;
    }
    x
}

/// Rotation of frame 3 in the base frame for the nominal Table 3 twists and offsets.
fn arm_rotation(model: &RobotModel, q: &Joints) -> Matrix3<f64> {
    let l = model.links();
    let rz = |t: f64| Rotation3::from_axis_angle(&Vector3::z_axis(), t).into_inner();
    rz(q[0] + l[0].theta_offset) * rx(-PI / 2.0) * rz(q[1] + l[1].theta_offset) * rz(q[2] + l[2].theta_offset)
}

/// Moves joint 6 by whole turns to the value nearest `seed6` within the limits.
fn unwrap_joint6(model: &RobotModel, q6: f64, seed6: f64) -> f64 {
    let lim = model.limits()[5];
    let turns = ((seed6 - q6) / (2.0 * PI)).round();
    let mut best = q6 + turns * 2.0 * PI;
    for k in [-1.0, 1.0] {
        let cand = q6 + (turns + k) * 2.0 * PI;
        if (best < lim.min || best > lim.max) && cand >= lim.min && cand <= lim.max {
            best = cand;
        }
    }
    best
}

/// `base_from_flange` for a TCP pose in {W}: `world_from_tcp` with the TCP frame parallel to the
/// flange frame (calsim's tools are position-only; the TCP frame carries the flange orientation).
pub fn base_from_flange_for_tcp(model: &RobotModel, world_from_tcp: &Isometry3<f64>) -> Isometry3<f64> {
    let world_from_base = super::kinematics::world_from_base(model);
    let base_from_tcp = world_from_base.inverse() * world_from_tcp;
    let r = base_from_tcp.rotation;
    Isometry3::from_parts((base_from_tcp.translation.vector - r * model.data().flange_tcp_mm).into(), r)
}

/// Joint values that put the TCP of `model` at `world_from_tcp` (position and flange orientation),
/// nearest `seed` among the closed-form branches, refined by Newton's method on the full model;
/// for an arm without the closed form, [`numeric`].
pub fn inverse(model: &RobotModel, world_from_tcp: &Isometry3<f64>, seed: &Joints) -> Result<Joints, IkError> {
    if !has_closed_form(model) {
        return numeric(model, world_from_tcp, seed);
    }
    let target_flange = base_from_flange_for_tcp(model, world_from_tcp);
    let mut candidates = closed_form(model, &target_flange);
    if candidates.is_empty() {
        return Err(IkError::Unreachable);
    }
    for q in &mut candidates {
        q[5] = unwrap_joint6(model, q[5], seed[5]);
    }
    candidates.sort_by(|a, b| distance(a, seed).total_cmp(&distance(b, seed)));
    let mut last = IkError::Limits;
    for q0 in candidates.iter().filter(|q| model.within_limits(q)) {
        match refine_oriented(model, world_from_tcp, q0) {
            Ok(q) if model.within_limits(&q) => return Ok(q),
            Ok(_) => {}
            Err(e) => last = e,
        }
    }
    Err(last)
}

fn distance(a: &Joints, b: &Joints) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>()
}

/// Newton's method on the full model from `q0`: TCP position and flange orientation to first
/// order, so a frame a half-turn from the target can come back ([`refine_oriented`] refuses it;
/// the SPMS steps call this one: their sphere does not care, and their shipped tables were
/// computed with it), with the geometric Jacobian of the deflected configuration (the compliance term dtau/dq is left out of
/// the Jacobian, which only slows convergence by a factor of order c * dtau/dq ~ 1e-3).
pub fn refine(model: &RobotModel, world_from_tcp: &Isometry3<f64>, q0: &Joints) -> Result<Joints, IkError> {
    newton(model, &Goal::new(model, world_from_tcp), q0)
}

/// [`refine_oriented`] with the base orientation taken from the model as it is stored, not
/// through the base's quaternion (whose iterative construction costs more than the Newton steps):
/// the same solution to rounding, for callers that need many (the study's compensated
/// validation). The frame reached is checked against the target's as [`oriented`] does (on the
/// rotation Newton's last step computed, no further forward kinematics): a frame a half-turn from
/// the target is [`IkError::NoConvergence`], not a solution.
pub fn refine_direct(model: &RobotModel, world_from_tcp: &Isometry3<f64>, q0: &Joints) -> Result<Joints, IkError> {
    let goal =
        Goal { rb: model.base_rot, p: world_from_tcp.translation.vector, r: world_from_tcp.rotation.to_rotation_matrix().into_inner() };
    let mut st = KinState::default();
    let q = newton_in(model, &goal, &mut st, q0)?;
    let turned = super::rotation::angle(&(goal.rb * st.rot[JOINTS]), &goal.r);
    if turned < ORIENTATION_TOLERANCE_RAD {
        Ok(q)
    } else {
        Err(IkError::NoConvergence { position_mm: (st.tcp_world() - goal.p).norm(), orientation_deg: turned.to_degrees() })
    }
}

/// Newton's method towards `goal` from `q0` (see [`refine`]).
fn newton(model: &RobotModel, goal: &Goal, q0: &Joints) -> Result<Joints, IkError> {
    newton_in(model, goal, &mut KinState::default(), q0)
}

/// [`newton`] in `st`, which holds the kinematics of the returned joints on success.
fn newton_in(model: &RobotModel, goal: &Goal, st: &mut KinState, q0: &Joints) -> Result<Joints, IkError> {
    let mut q = *q0;
    let mut residual = f64::INFINITY;
    for _ in 0..60 {
        let (rhs, jac) = goal.error_and_jacobian(model, st, &q);
        residual = rhs.fixed_rows::<3>(0).norm();
        if residual < 1e-11 && rhs.fixed_rows::<3>(3).norm() < 1e-13 {
            return Ok(q);
        }
        let Some(step) = lu_solve6(&jac, &rhs) else {
            break;
        };
        for k in 0..JOINTS {
            q[k] += step[k];
        }
    }
    let turned = super::rotation::angle(&(goal.rb * st.rot[JOINTS]), &goal.r);
    Err(IkError::NoConvergence { position_mm: residual, orientation_deg: turned.to_degrees() })
}

/// `q` if the TCP frame of `model` there is the target's, else the error naming both residuals:
/// Newton's method stops on a first-order orientation error, which vanishes a half-turn away as
/// well as at the target (a seed with joint 6 turned by 180 deg and the TCP on its axis).
fn oriented(model: &RobotModel, world_from_tcp: &Isometry3<f64>, q: Joints) -> Result<Joints, IkError> {
    let e = pose_error(model, &q, world_from_tcp);
    if e.orientation_rad < ORIENTATION_TOLERANCE_RAD {
        Ok(q)
    } else {
        Err(IkError::NoConvergence { position_mm: e.position_mm, orientation_deg: e.orientation_rad.to_degrees() })
    }
}

/// [`refine`], then the orientation checked (see [`oriented`]): what [`inverse`] and [`numeric`]
/// accept.
pub fn refine_oriented(model: &RobotModel, world_from_tcp: &Isometry3<f64>, q0: &Joints) -> Result<Joints, IkError> {
    oriented(model, world_from_tcp, refine(model, world_from_tcp, q0)?)
}

/// `a x = b` by LU with partial pivoting, the same to the bit as nalgebra's `a.lu().solve(&b)`
/// (0.35): the pivot is the first largest magnitude on or below the diagonal, the column below it
/// is scaled by `1 / pivot`, each entry of the rest takes `(-u) l + entry`, a column without a
/// non-zero entry is skipped; the solve swaps `b` as the factorisation swapped rows, then goes down
/// the unit lower triangle and up the upper one (`b_i / u_ii`), `None` on a zero on the diagonal.
/// Written out for 6 x 6 in fixed arrays: Newton's step of every IK target.
fn lu_solve6(a: &Matrix6<f64>, b: &Vector6<f64>) -> Option<Vector6<f64>> {
    const N: usize = 6;
    // m[r][c].
    let mut m: [[f64; N]; N] = std::array::from_fn(|r| std::array::from_fn(|c| a[(r, c)]));
    let mut swaps = [(0, 0); N];
    let mut nswaps = 0;
    for i in 0..N {
        // The first largest magnitude, without branches on the data.
        let (mut piv, mut best) = (i, m[i][i].abs());
        for (r, row) in m.iter().enumerate().skip(i + 1) {
            let larger = row[i].abs() > best;
            piv = if larger { r } else { piv };
            best = if larger { row[i].abs() } else { best };
        }
        let diag = m[piv][i];
        if diag == 0.0 {
            continue;
        }
        if piv != i {
            swaps[nswaps] = (i, piv);
            nswaps += 1;
            m.swap(i, piv);
        }
        let inv = 1.0 / diag;
        let pivot_row = m[i];
        for row in m.iter_mut().skip(i + 1) {
            row[i] *= inv;
            let l = row[i];
            for k in i + 1..N {
                row[k] += -pivot_row[k] * l;
            }
        }
    }
    let mut x: [f64; N] = std::array::from_fn(|r| b[r]);
    for &(i, piv) in &swaps[..nswaps] {
        x.swap(i, piv);
    }
    for i in 0..N - 1 {
        let coeff = x[i];
        for r in i + 1..N {
            x[r] += -coeff * m[r][i];
        }
    }
    for i in (0..N).rev() {
        let diag = m[i][i];
        if diag == 0.0 {
            return None;
        }
        let coeff = x[i] / diag;
        x[i] = coeff;
        for r in 0..i {
            x[r] += -coeff * m[r][i];
        }
    }
    Some(Vector6::from(x))
}

/// A TCP pose to reach, in the base orientation of the model.
struct Goal {
    rb: Matrix3<f64>,
    p: Vector3<f64>,
    r: Matrix3<f64>,
}

impl Goal {
    fn new(model: &RobotModel, world_from_tcp: &Isometry3<f64>) -> Self {
        Self {
            rb: super::kinematics::world_from_base(model).rotation.to_rotation_matrix().into_inner(),
            p: world_from_tcp.translation.vector,
            r: world_from_tcp.rotation.to_rotation_matrix().into_inner(),
        }
    }

    /// The pose error at `q` (position mm, then orientation as a first-order rotation vector, rad)
    /// and the geometric Jacobian in {W}.
    fn error_and_jacobian(&self, model: &RobotModel, st: &mut KinState, q: &Joints) -> (Vector6<f64>, Matrix6<f64>) {
        let p = forward(model, st, q);
        let r = self.rb * st.rot[JOINTS];
        let dp = self.p - p;
        // Orientation error as a rotation vector (first order), robust near the identity; it
        // vanishes a half-turn away too, which `oriented` catches.
        let dr = (0..3).map(|k| r.column(k).cross(&self.r.column(k))).fold(Vector3::zeros(), |a, v| a + v) * 0.5;
        let tcp = st.tcp_base;
        let mut jac = Matrix6::zeros();
        for k in 0..JOINTS {
            let z = st.rot[k + 1].column(2).into_owned();
            let v = self.rb * z.cross(&(tcp - st.org[k + 1]));
            let w = self.rb * z;
            jac.fixed_view_mut::<3, 1>(0, k).copy_from(&v);
            jac.fixed_view_mut::<3, 1>(3, k).copy_from(&w);
        }
        (Vector6::new(dp.x, dp.y, dp.z, dr.x, dr.y, dr.z), jac)
    }
}

/// Whether the closed form holds for `model`: the IRB 120's structure of Table 3 (twists 0, -90, 0,
/// -90, 90, -90 deg, joint 2 offset by -90 deg, no shoulder or wrist offsets) up to the small
/// errors a calibration identifies (0.5 deg, 1 mm).
pub fn has_closed_form(model: &RobotModel) -> bool {
    let l = model.links();
    let deg = |x: f64, want: f64| (x.to_degrees() - want).abs() < 0.5;
    let twists = [0.0, -90.0, 0.0, -90.0, 90.0, -90.0];
    let offsets = [0.0, -90.0, 0.0, 0.0, 0.0];
    (0..JOINTS).all(|i| deg(l[i].alpha, twists[i]))
        && (0..5).all(|i| deg(l[i].theta_offset, offsets[i]))
        && [l[0].a, l[1].a, l[4].a, l[5].a, l[1].d, l[2].d, l[4].d].iter().all(|v| v.abs() < 1.0)
}

/// IK of any six-joint arm by damped least squares from several starts (the seed first, then its
/// wrist flipped, then the shoulder towards and away from the target with the elbow at a few
/// angles and joint 5 at +0.5 rad), each polished by [`refine`]; the solution within the limits
/// nearest the seed (each joint moved by whole turns towards the seed where its range allows).
/// When none of them reaches the target, the same shoulder and elbow starts with joint 5 at
/// -0.5 rad: with the elbow a few degrees from stretched, damped least squares from every start of
/// the first wrist can stall on a branch that does not reach (the UR5 with the elbow 3.2 to 5.3 deg
/// from stretched: 4 of 200 reachable targets were reported unreachable, a test). Tried only
/// then, so that every target the first starts reach keeps its solution.
pub fn numeric(model: &RobotModel, world_from_tcp: &Isometry3<f64>, seed: &Joints) -> Result<Joints, IkError> {
    let goal = Goal::new(model, world_from_tcp);
    let base_target = super::kinematics::world_from_base(model).inverse_transform_point(&world_from_tcp.translation.vector.into());
    let toward = base_target.y.atan2(base_target.x);
    let grid = |q5: f64| {
        let mut starts = Vec::with_capacity(28);
        // Joint 1 towards the target and away from it; mirrored too, for a first axis that
        // points down (a {0} upside down turns the azimuth the other way).
        for q1 in [toward, wrap(toward + PI), -toward, wrap(PI - toward)] {
            for (q2, q3) in [(0.0, 0.0), (-0.8, 0.8), (0.8, -0.8), (-0.8, -0.8), (0.8, 0.8), (-1.6, 1.6), (1.6, -1.6)] {
                starts.push([q1, q2, q3, 0.0, q5, 0.0]);
            }
        }
        starts
    };
    let mut starts = vec![*seed, [seed[0], seed[1], seed[2], wrap(seed[3] + PI), -seed[4], wrap(seed[5] + PI)]];
    starts.extend(grid(0.5));
    let mut st = KinState::default();
    let mut best: Option<(f64, Joints)> = None;
    let mut last = IkError::Unreachable;
    for pass in 0..2 {
        if pass == 1 {
            if best.is_some() {
                break;
            }
            starts = grid(-0.5);
        }
        for (n, start) in starts.iter().enumerate() {
            let Some(q) = damped(model, &goal, &mut st, start) else { continue };
            match refine_oriented(model, world_from_tcp, &q) {
                Ok(q) => {
                    let q = toward_seed(model, q, seed);
                    if !model.within_limits(&q) {
                        last = IkError::Limits;
                        continue;
                    }
                    let d = distance(&q, seed);
                    if best.is_none_or(|(b, _)| d < b) {
                        best = Some((d, q));
                    }
                    // From the seed or its wrist flip: the branch the seed is on.
                    if pass == 0 && n < 2 {
                        break;
                    }
                }
                Err(e) => last = e,
            }
        }
    }
    best.map(|(_, q)| q).ok_or(last)
}

/// Damped least squares from `q0` alone, polished by [`refine_oriented`]: the solution of the
/// branch `q0` is on (near a singularity, where Newton from `q0` diverges), within the limits, its
/// frame the target's (a frame a half-turn away, where the first-order orientation error vanishes
/// too, is [`IkError::NoConvergence`]; the study's compensated validation falls back on it).
pub fn damped_from(model: &RobotModel, world_from_tcp: &Isometry3<f64>, q0: &Joints) -> Result<Joints, IkError> {
    let goal = Goal::new(model, world_from_tcp);
    let q = damped(model, &goal, &mut KinState::default(), q0).ok_or(IkError::Unreachable)?;
    let q = refine_oriented(model, world_from_tcp, &q)?;
    if model.within_limits(&q) { Ok(q) } else { Err(IkError::Limits) }
}

/// Damped least squares towards `goal` from `q0` (orientation weighted by 300 mm per rad, joint
/// steps at most 0.3 rad); `None` when it stalls away from the goal.
fn damped(model: &RobotModel, goal: &Goal, st: &mut KinState, q0: &Joints) -> Option<Joints> {
    const W: f64 = 300.0;
    let weight = Matrix6::from_diagonal(&Vector6::new(1.0, 1.0, 1.0, W, W, W));
    let mut q = *q0;
    let mut lambda = 10.0;
    let (e, j) = goal.error_and_jacobian(model, st, &q);
    let (mut e, mut j) = (weight * e, weight * j);
    let mut cost = e.norm_squared();
    for _ in 0..200 {
        if cost < 1e-8 {
            return Some(q);
        }
        let a = j * j.transpose() + Matrix6::identity() * (lambda * lambda);
        let mut step = j.transpose() * lu_solve6(&a, &e)?;
        let big = step.amax();
        if big > 0.3 {
            step *= 0.3 / big;
        }
        let trial: Joints = std::array::from_fn(|k| q[k] + step[k]);
        let (te, tj) = goal.error_and_jacobian(model, st, &trial);
        let (te, tj) = (weight * te, weight * tj);
        if te.norm_squared() < cost {
            (q, e, j, cost) = (trial, te, tj, te.norm_squared());
            lambda = (lambda * 0.5).max(1e-3);
        } else {
            lambda *= 4.0;
            if lambda > 1e6 {
                return None;
            }
        }
    }
    (cost < 1.0).then_some(q)
}

/// `q` with each joint moved by whole turns to the value nearest the seed's within its limits.
fn toward_seed(model: &RobotModel, mut q: Joints, seed: &Joints) -> Joints {
    for (k, lim) in model.limits().iter().enumerate() {
        let turns = ((seed[k] - q[k]) / (2.0 * PI)).round();
        let mut best = q[k];
        for t in [turns, turns - 1.0, turns + 1.0, 0.0] {
            let c = q[k] + t * 2.0 * PI;
            let inside = c >= lim.min && c <= lim.max;
            let best_inside = best >= lim.min && best <= lim.max;
            if inside && (!best_inside || (c - seed[k]).abs() < (best - seed[k]).abs()) {
                best = c;
            }
        }
        q[k] = best;
    }
    q
}

#[cfg(test)]
mod tests {
    use nalgebra::{Matrix6, Vector6};
    use rand::{RngExt, SeedableRng};

    use super::lu_solve6;

    /// The fixed-size LU solve equals nalgebra's `lu().solve()` bit for bit: 20,000 random 6 x 6
    /// systems, among them entries of mixed magnitude, repeated values (ties for the pivot), zero
    /// columns (skipped steps) and singular matrices (`None` alike).
    #[test]
    fn lu_solve6_equals_nalgebras_lu_bit_for_bit() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        let mut nones = 0;
        for case in 0..20_000 {
            let mut a = Matrix6::from_fn(|_, _| rng.random_range(-1.0..1.0) * 10f64.powi(rng.random_range(-3..=3)));
            let b = Vector6::from_fn(|_, _| rng.random_range(-1.0..1.0));
            match case % 5 {
                1 => a.set_column(rng.random_range(0..6), &Vector6::zeros()),
                2 => {
                    let (r, s) = (rng.random_range(0..6), rng.random_range(0..6));
                    let row = a.row(r).into_owned();
                    a.set_row(s, &(-row));
                }
                3 => a = a.map(|x| (x * 4.0).round() / 4.0),
                _ => {}
            }
            let expected = a.lu().solve(&b);
            let got = lu_solve6(&a, &b);
            nones += usize::from(expected.is_none());
            assert_eq!(got.map(|v| v.map(f64::to_bits)), expected.map(|v| v.map(f64::to_bits)), "case {case}: {a}");
        }
        assert!(nones > 100, "singular systems: {nones}");
    }
}
