//! Orientations as rotations, not angle triples: every writing of a robot file's flange
//! (`flange_rpy_deg`) gives one rotation, and the TriCal campaign does not depend on the writing.
//!
//! The defect this guards: the KR 6's flange written `[180, -0, -180]` (as `import-urdf` wrote the
//! M-10iA's) made every campaign fail, while `[180, 2.5e-14, 180]` ran. nalgebra's iterative
//! `UnitQuaternion::from_matrix` stalls at an exact half-turn and returned a rotation of 0.00027
//! rad for it, so the device pointed into the wrist.

mod common;

use calsim::instrument::trical::{TriCal, TriCalSpec};
use calsim::robot::file::RobotFile;
use calsim::robot::rotation::{angle, rpy_deg};
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use proptest::prelude::*;

/// The KR 6 robot file's text with its flange written `rpy`.
fn kr6_with_flange(rpy: [f64; 3]) -> String {
    let text = std::fs::read_to_string(common::repo().join("robots/kr6r900sixx.toml")).unwrap();
    let line = text.lines().find(|l| l.starts_with("flange_rpy_deg")).expect("the KR 6 file has a flange").to_string();
    // `{:?}` keeps the sign of a zero and every digit.
    text.replace(&line, &format!("flange_rpy_deg = [{:?}, {:?}, {:?}]", rpy[0], rpy[1], rpy[2]))
}

/// The flange rotation the robot file gives for the writing `rpy`.
fn flange_of(rpy: [f64; 3]) -> Matrix3<f64> {
    let path = common::repo().join("robots/kr6r900sixx.toml");
    RobotFile::from_text(&path, &kr6_with_flange(rpy)).expect("the file loads").flange.expect("a flange")
}

/// Other writings of the triple `[r, p, y]` (deg) of one rotation: the other pitch branch, whole
/// turns added where the file's +-360 deg bound allows, zeros with their sign turned.
fn writings([r, p, y]: [f64; 3], turns: [i32; 3]) -> Vec<[f64; 3]> {
    let wrap = |a: f64| {
        if a > 180.0 {
            a - 360.0
        } else if a <= -180.0 {
            a + 360.0
        } else {
            a
        }
    };
    let other = [wrap(r + 180.0), if p >= 0.0 { 180.0 - p } else { -180.0 - p }, wrap(y + 180.0)];
    let shifted = |t: [f64; 3]| -> [f64; 3] {
        std::array::from_fn(|k| {
            let s = t[k] + 360.0 * f64::from(turns[k]);
            if s.abs() <= 360.0 { s } else { t[k] }
        })
    };
    let negzero = |t: [f64; 3]| t.map(|a| if a == 0.0 { -0.0 } else { a });
    vec![[r, p, y], other, shifted([r, p, y]), shifted(other), negzero([r, p, y]), negzero(other)]
}

/// A device on a flange `rotation` in frame 6: the pose of frame 6 that IK is given for a TCP pose.
fn frame6_pose(flange: Matrix3<f64>, world_from_tcp: Isometry3<f64>) -> Isometry3<f64> {
    let mut device = TriCal::build(&TriCalSpec::default(), 12.7, &mut common::rng(1));
    device.frame6_from_flange = Some(flange);
    device.frame6_pose(world_from_tcp)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    /// 256 random rotations, half of them half-turns about a random axis, each written six ways
    /// (the two pitch branches, whole turns, negative zeros): one rotation to 1e-14 rad, and the
    /// device's frame-6 target to 1e-14 rad (scaled by 1 / |cos(pitch)| near gimbal lock).
    #[test]
    fn every_writing_of_a_random_rotation_gives_one_flange(
        mut w in prop::array::uniform4(-1.0f64..1.0),
        half_turn in any::<bool>(),
        turns in prop::array::uniform3(-1i32..=1),
        target in prop::array::uniform3(-3.0f64..3.0),
    ) {
        if half_turn {
            w[0] = 0.0;
        }
        prop_assume!(w.iter().map(|v| v * v).sum::<f64>() > 1e-3);
        let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w[0], w[1], w[2], w[3]));
        let truth = q.to_rotation_matrix();
        let pose = Isometry3::from_parts(Translation3::new(400.0, 0.0, 300.0), UnitQuaternion::from_euler_angles(target[0], target[1], target[2]));
        let reference = frame6_pose(*truth.matrix(), pose);
        let rpy = rpy_deg(&truth);
        // Near gimbal lock the roll and yaw of a rotation are ill-conditioned: taking the triple
        // from the matrix loses a factor 1 / |cos(pitch)| (59 at a pitch of 89.03 deg, where a
        // writing came back 1.8e-14 rad off), so the bound is 1e-14 rad scaled by it.
        let bound = 1e-14 * (1.0 + 1.0 / rpy[1].to_radians().cos().abs());
        for t in writings(rpy, turns) {
            let m = flange_of(t);
            prop_assert!(angle(truth.matrix(), &m) < bound, "{t:?}: {:e} rad (bound {bound:e})", angle(truth.matrix(), &m));
            let p = frame6_pose(m, pose);
            prop_assert!(p.rotation.angle_to(&reference.rotation) < bound, "{t:?}");
        }
    }

    /// Gimbal lock: at a pitch of +-90 deg only yaw - roll (pitch 90) or yaw + roll (pitch -90)
    /// counts; every split of it gives one rotation to 1e-14 rad (256 random cases).
    #[test]
    fn every_split_of_roll_and_yaw_at_gimbal_lock_gives_one_flange(
        sum in -170.0f64..170.0,
        split in -170.0f64..170.0,
        up in any::<bool>(),
    ) {
        let (p, s) = if up { (90.0, 1.0) } else { (-90.0, -1.0) };
        // pitch 90: R = Rz(y - r) Ry(90); pitch -90: R = Rz(y + r) Ry(-90).
        let truth = Rotation3::from_axis_angle(&Vector3::z_axis(), sum.to_radians()) * Rotation3::from_axis_angle(&Vector3::y_axis(), f64::to_radians(p));
        for (r, y) in [(0.0, sum), (split, sum + s * split), (-split, sum - s * split)] {
            let m = flange_of([r, p, y]);
            prop_assert!(angle(truth.matrix(), &m) < 1e-14, "[{r}, {p}, {y}]: {:e}", angle(truth.matrix(), &m));
        }
    }
}

/// Every writing of every rotation by multiples of 90 deg (each angle one of -180, -90, -0, 0,
/// 90, 180, 270, -270, 360: 729 triples) gives the exact signed permutation, the same to the bit
/// for every writing of it.
#[test]
fn every_writing_of_an_axis_aligned_rotation_gives_the_same_bits() {
    let angles = [-180.0, -90.0, -0.0, 0.0, 90.0, 180.0, 270.0, -270.0, 360.0];
    let mut seen: Vec<(Matrix3<f64>, [f64; 3])> = Vec::new();
    for r in angles {
        for p in angles {
            for y in angles {
                let m = flange_of([r, p, y]);
                let exact =
                    Rotation3::from_euler_angles(f64::to_radians(r), f64::to_radians(p), f64::to_radians(y)).into_inner().map(f64::round);
                assert_eq!(m.map(f64::to_bits), (exact.map(|v| v + 0.0)).map(f64::to_bits), "[{r}, {p}, {y}]");
                if !seen.iter().any(|(s, _)| *s == m) {
                    seen.push((m, [r, p, y]));
                }
            }
        }
    }
    assert_eq!(seen.len(), 24, "the 24 rotations of the cube");
}

/// The KR 6's half-turn flange written five ways (among them the `[180, -0, -180]` that broke
/// every campaign and the `[180, 2.5e-14, 180]` that ran) gives the same campaign to the bit: the
/// same pool of 360 configurations and the same validation poses.
#[test]
fn every_writing_of_the_kr6_half_turn_flange_gives_the_same_campaign() {
    let scenario = std::fs::read_to_string(common::repo().join("scenarios/kr6r900sixx_trical.toml")).unwrap();
    // The pool's and the validation's joint values, as bits.
    type Campaign = (Vec<[u64; 6]>, Vec<[u64; 6]>);
    let mut reference: Option<Campaign> = None;
    for rpy in [[180.0, -0.0, -180.0], [180.0, 2.5444437451708134e-14, 180.0], [0.0, 180.0, 0.0], [-180.0, 0.0, 180.0], [0.0, -180.0, -0.0]]
    {
        let tmp = common::scratch("orientation-writings");
        std::fs::create_dir_all(tmp.path().join("robots")).unwrap();
        std::fs::create_dir_all(tmp.path().join("scenarios")).unwrap();
        std::fs::write(tmp.path().join("robots/kr6r900sixx.toml"), kr6_with_flange(rpy)).unwrap();
        let path = tmp.path().join("scenarios/kr6.toml");
        std::fs::write(&path, &scenario).unwrap();
        let s = calsim::device::trical::spec::load(&path).expect("scenario");
        let e = s.experiment.build(s.header.seed).unwrap_or_else(|err| panic!("{rpy:?}: {err}"));
        assert_eq!(e.campaign.pool.len(), 360, "{rpy:?}");
        let bits = |q: &[f64; 6]| q.map(f64::to_bits);
        let got = (e.campaign.pool.iter().map(|p| bits(&p.q)).collect(), e.campaign.validation.iter().map(|v| bits(&v.q)).collect());
        match &reference {
            None => reference = Some(got),
            Some(r) => assert!(*r == got, "{rpy:?}: another campaign"),
        }
    }
}
