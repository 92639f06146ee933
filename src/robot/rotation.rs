//! Orientations as rotations, not angle triples.
//!
//! A roll-pitch-yaw triple is one writing of a rotation among many (`[180, -0, -180]`,
//! `[180, 0, 180]` and `[0, 180, 0]` are one half-turn; any angle may gain a whole turn; at a pitch
//! of +-90 deg only the difference or sum of roll and yaw counts). Code that takes a triple turns it
//! into a rotation here, once, and compares rotations by their angle, never triples.
//!
//! Two traps this module keeps out:
//! - nalgebra's `UnitQuaternion::from_matrix` is Müller's iterative polar method started at the
//!   identity. For a half-turn (a symmetric rotation matrix, trace -1) the identity is a stationary
//!   point of its objective: it stops there, or a rounding step away, and returns a rotation of
//!   about 0 deg for one of 180 deg. [`quaternion`] takes the closed form there.
//! - The first-order orientation error `0.5 sum_k r_k x t_k` of two frames vanishes when they are a
//!   half-turn apart as well as when they agree: [`angle`] tells the two apart.

use nalgebra::{Matrix3, Rotation3, UnitQuaternion};

/// Entries this close to -1, 0 or 1 make a matrix a signed permutation (a rotation by multiples of
/// 90 deg written with rounding residues such as `sin(pi) = 1.2e-16`).
const AXIS_ALIGNED: f64 = 1e-9;

/// The unit quaternion of the rotation matrix `r` (orthonormal, determinant +1).
///
/// Müller's iteration (`UnitQuaternion::from_matrix`) where its answer is `r` (to 1e-9), since the
/// shipped result tables were computed with it and stay the same to the bit; the closed form
/// (Shepperd's method, `from_rotation_matrix`) where it is not: at a half-turn, where the iteration
/// stalls (see the module).
pub fn quaternion(r: &Matrix3<f64>) -> UnitQuaternion<f64> {
    let q = UnitQuaternion::from_matrix(r);
    if (q.to_rotation_matrix().matrix() - r).amax() > 1e-9 {
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*r))
    } else {
        q
    }
}

/// The angle of the rotation taking `a` to `b` (both rotation matrices), rad in [0, pi]: from the
/// sine and cosine together, accurate near 0 and near pi.
pub fn angle(a: &Matrix3<f64>, b: &Matrix3<f64>) -> f64 {
    let rel = a.transpose() * b;
    let cos = (rel.trace() - 1.0) / 2.0;
    let axial = nalgebra::Vector3::new(rel[(2, 1)] - rel[(1, 2)], rel[(0, 2)] - rel[(2, 0)], rel[(1, 0)] - rel[(0, 1)]);
    (axial.norm() / 2.0).atan2(cos)
}

/// The rotation of a roll-pitch-yaw triple in degrees (`Rz(yaw) Ry(pitch) Rx(roll)` about fixed
/// axes, as a URDF origin's `rpy`), the same matrix for every writing of a rotation by multiples of
/// 90 deg (exact entries -1, 0, 1) and for angles a whole turn apart.
pub fn from_rpy_deg(rpy_deg: [f64; 3]) -> Rotation3<f64> {
    // `rem_euclid` is exact: 370, -350 and 10 give the same bits, and so do -180 and 180.
    let [r, p, y] = rpy_deg.map(|a| a.rem_euclid(360.0).to_radians());
    let m = Rotation3::from_euler_angles(r, p, y).into_inner();
    Rotation3::from_matrix_unchecked(snapped(&m).unwrap_or(m))
}

/// The signed permutation `m` is within rounding of (every entry within 1e-9 of -1, 0 or 1), with
/// exact entries and no negative zero; `None` for any other matrix.
fn snapped(m: &Matrix3<f64>) -> Option<Matrix3<f64>> {
    let mut out = Matrix3::zeros();
    for (o, v) in out.iter_mut().zip(m.iter()) {
        let near = v.round();
        if (v - near).abs() > AXIS_ALIGNED || near.abs() > 1.0 {
            return None;
        }
        *o = near + 0.0;
    }
    Some(out)
}

/// One writing of `r` as a roll-pitch-yaw triple in degrees (see [`from_rpy_deg`]): each angle in
/// (-180, 180], pitch in [-90, 90], angles within 1e-9 deg of a multiple of 90 deg written exactly,
/// no negative zero.
pub fn rpy_deg(r: &Rotation3<f64>) -> [f64; 3] {
    let m = snapped(r.matrix()).unwrap_or(*r.matrix());
    let (roll, pitch, yaw) = Rotation3::from_matrix_unchecked(m).euler_angles();
    [roll, pitch, yaw].map(|a| {
        let d = a.to_degrees();
        let quarter = (d / 90.0).round() * 90.0;
        let d = if (d - quarter).abs() < 1e-9 { quarter } else { d };
        let d = if d <= -180.0 { d + 360.0 } else { d };
        d + 0.0
    })
}

#[cfg(test)]
mod tests {
    use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
    use rand::{RngExt, SeedableRng};

    use super::{angle, from_rpy_deg, quaternion, rpy_deg};

    /// nalgebra's iterative extraction turns the KR 6's half-turn flange (`[180, -0, -180]`) into
    /// a rotation of 0.00027 rad; [`quaternion`] gives the half-turn.
    #[test]
    fn a_half_turn_matrix_gives_the_half_turn_quaternion() {
        let m = Rotation3::from_euler_angles(std::f64::consts::PI, -0.0, -std::f64::consts::PI).into_inner();
        let q = quaternion(&m.transpose());
        assert!((q.to_rotation_matrix().matrix() - m.transpose()).amax() < 1e-15, "{q:?}");
        assert!((q.angle() - std::f64::consts::PI).abs() < 1e-12);
    }

    /// Every rotation matrix, half-turns and near-half-turns among them, comes back from its
    /// quaternion to 1e-14 (20,000 random rotations, 24 axis-aligned ones, 2,000 within 1e-6 rad of
    /// a half-turn about a random axis).
    #[test]
    fn every_rotation_matrix_comes_back_from_its_quaternion() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(32);
        let axis = |rng: &mut rand_chacha::ChaCha8Rng| nalgebra::Unit::new_normalize(Vector3::from_fn(|_, _| rng.random_range(-1.0..1.0)));
        let mut cases: Vec<Matrix3<f64>> = Vec::new();
        for _ in 0..20_000 {
            let q =
                UnitQuaternion::from_quaternion(nalgebra::Quaternion::from(nalgebra::Vector4::from_fn(|_, _| rng.random_range(-1.0..1.0))));
            cases.push(q.to_rotation_matrix().into_inner());
        }
        for _ in 0..2_000 {
            let a = axis(&mut rng);
            cases.push(Rotation3::from_axis_angle(&a, std::f64::consts::PI - rng.random_range(0.0..1e-6)).into_inner());
        }
        cases.extend(axis_aligned());
        for m in cases {
            let back = quaternion(&m).to_rotation_matrix().into_inner();
            assert!((back - m).amax() < 1e-14, "{m}");
        }
    }

    /// The 24 rotations by multiples of 90 deg.
    fn axis_aligned() -> Vec<Matrix3<f64>> {
        let q = [0.0, 90.0, 180.0, 270.0];
        let mut out: Vec<Matrix3<f64>> = Vec::new();
        for r in q {
            for p in q {
                for y in q {
                    let m = from_rpy_deg([r, p, y]).into_inner();
                    if !out.contains(&m) {
                        out.push(m);
                    }
                }
            }
        }
        assert_eq!(out.len(), 24);
        out
    }

    /// The angle between two frames is right near 0 and near a half-turn, where the first-order
    /// error vector vanishes.
    #[test]
    fn the_angle_between_frames_tells_a_half_turn_from_agreement() {
        let a = Rotation3::from_euler_angles(0.3, -0.2, 1.1).into_inner();
        for t in [0.0, 1e-9, 0.5, std::f64::consts::PI - 1e-9, std::f64::consts::PI] {
            let b = a * Rotation3::from_axis_angle(&Vector3::y_axis(), t).into_inner();
            assert!((angle(&a, &b) - t).abs() < 1e-12, "{t}: {}", angle(&a, &b));
        }
    }

    /// Writing a rotation as a triple and reading it back gives the rotation to 1e-11 rad (10,000
    /// random ones, 1e-6 mm at 100 m),
    /// and an axis-aligned one exactly, with exact multiples of 90 deg in the triple.
    #[test]
    fn a_rotation_written_as_a_triple_reads_back() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut worst: f64 = 0.0;
        for _ in 0..10_000 {
            let r = Rotation3::from_euler_angles(rng.random_range(-3.2..3.2), rng.random_range(-1.6..1.6), rng.random_range(-3.2..3.2));
            let back = from_rpy_deg(rpy_deg(&r));
            worst = worst.max(angle(r.matrix(), back.matrix()));
        }
        // Near a pitch of +-90 deg roll and yaw are each ill-determined (9.0e-13 rad seen here).
        assert!(worst < 1e-11, "{worst:e}");
        for m in axis_aligned() {
            let t = rpy_deg(&Rotation3::from_matrix_unchecked(m));
            assert!(t.iter().all(|a| a % 90.0 == 0.0 && a.is_sign_positive() || *a < 0.0), "{t:?}");
            assert_eq!(from_rpy_deg(t).into_inner(), m, "{t:?}");
        }
    }
}
