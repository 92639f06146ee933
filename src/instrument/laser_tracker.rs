//! The laser tracker of the validation (2018 paper, setup 2): a FARO ION-class instrument placed
//! about 2 m in front of sphere 3, measuring an SMR at the TCP; registered to {W} through SMRs in
//! the sphere nests.
//!
//! Noise model: in the tracker's spherical coordinates, range noise `sigma_r = a_r + b_r d` and
//! transverse (angular) noise `sigma_t = a_t + b_t d` on each of the two transverse axes, with `d`
//! the distance in metres. The defaults are half the FARO ION maximum permissible errors (ADM
//! 16 um + 0.8 um/m, angular 18 um + 3 um/m): at 5 m this gives a point-to-point error of about
//! 35 um, the paper's quoted 32 um.

use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use rand::Rng;
use rand_distr::{Distribution, Normal};
use serde::Deserialize;

/// The tracker as a scenario describes it.
#[derive(Clone, Debug, Deserialize, serde::Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct LaserTrackerSpec {
    /// Horizontal distance from sphere 3, away from the robot base, mm.
    pub distance_from_sphere3_mm: f64,
    /// Height of the tracker head above the plane of the spheres, mm.
    pub height_above_spheres_mm: f64,
    /// Range noise, constant part, um.
    pub range_sigma_um: f64,
    /// Range noise per metre of distance, um/m.
    pub range_sigma_um_per_m: f64,
    /// Transverse noise, constant part, um.
    pub transverse_sigma_um: f64,
    /// Transverse noise per metre of distance, um/m.
    pub transverse_sigma_um_per_m: f64,
    /// Largest distance the tracker measures, mm.
    pub max_range_mm: f64,
    /// Acceptance half-angle of the SMR around the device's axis (away from the flange), deg.
    pub smr_acceptance_deg: f64,
    /// Readings averaged per nest SMR for the registration to {W}.
    pub registration_samples: u32,
}

impl Default for LaserTrackerSpec {
    fn default() -> Self {
        Self {
            distance_from_sphere3_mm: 2000.0,
            height_above_spheres_mm: 300.0,
            range_sigma_um: 8.0,
            range_sigma_um_per_m: 0.4,
            transverse_sigma_um: 9.0,
            transverse_sigma_um_per_m: 1.5,
            max_range_mm: 35_000.0,
            smr_acceptance_deg: 60.0,
            registration_samples: 10,
        }
    }
}

/// A placed tracker: its position in {W} and its registration to {W}.
#[derive(Clone, Debug)]
pub struct LaserTracker {
    /// The specification.
    pub spec: LaserTrackerSpec,
    /// Tracker head in {W}, mm.
    pub position_w: Vector3<f64>,
    /// `world_from_tracker` as estimated by the registration on the nest SMRs.
    pub registration: Isometry3<f64>,
    /// The true `world_from_tracker`.
    truth: Isometry3<f64>,
}

impl LaserTracker {
    /// Places the tracker `spec.distance_from_sphere3_mm` beyond sphere 3 from `base_in_w` and
    /// registers it on SMRs in the nests at `nests_w` (true positions), fitted to `nests_w_nominal`
    /// (the {W} coordinates from the ballbar); `None` when the registration has no finite fit.
    pub fn place<R: Rng + ?Sized>(
        spec: &LaserTrackerSpec,
        sphere3_w: &Vector3<f64>,
        base_in_w: &Vector3<f64>,
        nests_w: &[Vector3<f64>],
        nests_w_nominal: &[Vector3<f64>],
        rng: &mut R,
    ) -> Option<Self> {
        let mut away = sphere3_w - base_in_w;
        away.z = 0.0;
        let away = if away.norm() > 1e-9 { away.normalize() } else { Vector3::x() };
        let position_w = sphere3_w + away * spec.distance_from_sphere3_mm + Vector3::z() * spec.height_above_spheres_mm;
        // The tracker's own frame: any orientation; it faces the robot (x towards the base).
        let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[
            -away,
            Vector3::z().cross(&-away),
            Vector3::z(),
        ])));
        let truth = Isometry3::from_parts(Translation3::from(position_w), rot);
        let mut tracker = Self { spec: spec.clone(), position_w, registration: truth, truth };
        let k = spec.registration_samples.max(1);
        let measured: Vec<Vector3<f64>> =
            nests_w.iter().map(|p| (0..k).map(|_| tracker.measure_in_tracker(p, rng)).sum::<Vector3<f64>>() / k as f64).collect();
        tracker.registration = rigid_fit(&measured, nests_w_nominal)?;
        Some(tracker)
    }

    /// Measures a point given in {W}: the reading in the tracker frame, with noise, mm.
    fn measure_in_tracker<R: Rng + ?Sized>(&self, p_w: &Vector3<f64>, rng: &mut R) -> Vector3<f64> {
        let p = self.truth.inverse_transform_point(&Point3::from(*p_w)).coords;
        let d_m = p.norm() * 1e-3;
        let n = Normal::new(0.0, 1.0).expect("unit normal");
        let sr = (self.spec.range_sigma_um + self.spec.range_sigma_um_per_m * d_m) * 1e-3;
        let st = (self.spec.transverse_sigma_um + self.spec.transverse_sigma_um_per_m * d_m) * 1e-3;
        let u = p.normalize();
        let t1 = u.cross(&if u.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() }).normalize();
        let t2 = u.cross(&t1);
        p + u * (sr * n.sample(rng)) + t1 * (st * n.sample(rng)) + t2 * (st * n.sample(rng))
    }

    /// Measures a point given in {W} and expresses it in {W} through the registration, mm.
    pub fn measure<R: Rng + ?Sized>(&self, p_w: &Vector3<f64>, rng: &mut R) -> Vector3<f64> {
        let m = self.measure_in_tracker(p_w, rng);
        self.registration.transform_point(&Point3::from(m)).coords
    }
}

/// Least-squares rigid transform `b_from_a` mapping points `a` onto `b` (Horn/Kabsch by SVD);
/// `None` when the points are not finite.
pub fn rigid_fit(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> Option<Isometry3<f64>> {
    let ca = a.iter().sum::<Vector3<f64>>() / a.len() as f64;
    let cb = b.iter().sum::<Vector3<f64>>() / b.len() as f64;
    let h = a.iter().zip(b).fold(Matrix3::zeros(), |h, (p, q)| h + (p - ca) * (q - cb).transpose());
    let svd = crate::numeric::svd3(h)?;
    let (u, vt) = (svd.u?, svd.v_t?);
    let mut d = Matrix3::identity();
    if (vt.transpose() * u.transpose()).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let r = vt.transpose() * d * u.transpose();
    let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    Some(Isometry3::from_parts(Translation3::from(cb - rot * ca), rot))
}

/// A tracker point measurement with the same noise on each axis of its frame: the model of the
/// SPMS experiments (A1-A3 of the head, the sphere centre, the ISO 9283 points), whose papers give
/// one figure per axis rather than the range and angle terms of [`LaserTracker`].
#[derive(Clone, Copy, Debug)]
pub struct AxisNoise {
    noise: Normal<f64>,
}

impl AxisNoise {
    /// Noise of `sigma_um` per axis (finite and >= 0, as the scenario checks guarantee).
    pub fn new(sigma_um: f64) -> Self {
        Self { noise: Normal::new(0.0, sigma_um * 1e-3).expect("a finite sigma >= 0") }
    }

    /// `p` as the tracker measures it: one draw per coordinate, x then y then z, mm.
    pub fn measure<R: Rng + ?Sized>(&self, p: &Vector3<f64>, rng: &mut R) -> Vector3<f64> {
        p + Vector3::from_fn(|_, _| self.noise.sample(rng))
    }
}
