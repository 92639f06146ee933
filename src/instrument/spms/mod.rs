//! The SPMS of Gao et al. (Sensors 2023): K laser range sensors fixed in a head measure a
//! reference sphere. A reading is where the beam first meets the sphere; the sphere centre is the
//! least-squares fit of the K surface points (paper eqs. 1-3). The head's measurement frame comes
//! from three points measured by a laser tracker, by Gram-Schmidt (eqs. 4-7).
//!
//! Lengths in mm. A beam that misses the sphere or whose distance leaves the sensor's range is an
//! error, never a number.

pub mod beams;

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, Unit, UnitQuaternion, Vector3};
use rand::{Rng, RngExt};
use rand_distr::{Distribution, Normal};
use serde::Deserialize;

use crate::instrument::laser_tracker::AxisNoise;

/// One laser beam in the head frame: origin `p` (the zero of the reading) and unit direction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Beam {
    /// Point of the beam where the sensor reads 0, mm.
    pub p: Vector3<f64>,
    /// Unit direction.
    pub dir: Unit<Vector3<f64>>,
}

impl Beam {
    /// A beam from a point and any non-zero direction.
    pub fn new(p: [f64; 3], dir: [f64; 3]) -> Self {
        Self { p: Vector3::from(p), dir: Unit::new_normalize(Vector3::from(dir)) }
    }

    /// The surface point of a reading `l`: `F = P + gamma L` (eq. 1).
    pub fn point(&self, l: f64) -> Vector3<f64> {
        self.p + self.dir.into_inner() * l
    }

    /// Distance along the beam to the first intersection with the sphere (centre `c`, radius `r`),
    /// or `None` when the beam misses it or the sphere is behind the sensor.
    pub fn hit(&self, c: &Vector3<f64>, r: f64) -> Option<f64> {
        let oc = c - self.p;
        let b = self.dir.dot(&oc);
        let disc = b * b - (oc.norm_squared() - r * r);
        if disc < 0.0 {
            return None;
        }
        let t = b - disc.sqrt();
        (t > 0.0).then_some(t)
    }
}

/// The five beams of the paper's Table 2 (identified on the real head; directions as printed,
/// normalised here).
pub fn table2_beams() -> Vec<Beam> {
    vec![
        Beam::new([74.420, 67.247, 97.126], [-0.104, 0.976, 0.189]),
        Beam::new([11.612, 69.074, 146.755], [0.210, 0.975, -0.069]),
        Beam::new([92.918, 67.986, 142.254], [-0.190, 0.981, -0.031]),
        Beam::new([52.951, 69.811, 175.249], [0.018, 0.981, -0.194]),
        Beam::new([25.346, 70.181, 97.548], [0.143, 0.982, 0.124]),
    ]
}

/// The laser range sensor (paper Table 1).
#[derive(Clone, Debug, Deserialize, serde::Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct SensorSpec {
    /// Lower end of the measuring range, mm.
    pub range_min_mm: f64,
    /// Upper end of the measuring range, mm.
    pub range_max_mm: f64,
    /// Linearity, % of full scale: the amplitude of the systematic error curve.
    pub linearity_pct_fs: f64,
    /// Repeatability (one standard deviation), um.
    pub repeatability_um: f64,
    /// Temperature drift, % of full scale per degree C.
    pub temperature_pct_fs_per_c: f64,
    /// Temperature difference from the identification, degrees C.
    pub temperature_delta_c: f64,
}

impl Default for SensorSpec {
    fn default() -> Self {
        Self {
            range_min_mm: 75.0,
            range_max_mm: 130.0,
            linearity_pct_fs: 0.15,
            repeatability_um: 10.0,
            temperature_pct_fs_per_c: 0.06,
            temperature_delta_c: 0.0,
        }
    }
}

impl SensorSpec {
    /// Full scale, mm.
    pub fn full_scale(&self) -> f64 {
        self.range_max_mm - self.range_min_mm
    }
}

/// Why a sensor gave no reading.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ReadingError {
    /// The beam does not meet the sphere.
    #[error("beam {beam}: misses the sphere")]
    Miss {
        /// Beam index (0-based).
        beam: usize,
    },
    /// The distance is outside the sensor's range.
    #[error("beam {beam}: distance {distance_mm:.3} mm outside the range {min_mm}-{max_mm} mm")]
    OutOfRange {
        /// Beam index (0-based).
        beam: usize,
        /// True distance, mm.
        distance_mm: f64,
        /// Range, mm.
        min_mm: f64,
        /// Range, mm.
        max_mm: f64,
    },
}

/// One physical sensor: its true beam and its own linearity curve.
#[derive(Clone, Debug, PartialEq)]
pub struct Sensor {
    /// The true beam in the head frame.
    pub beam: Beam,
    /// Phase of the linearity curve, rad.
    pub linearity_phase: f64,
}

/// The SPMS head: sensors, their specification, the reference sphere radius.
#[derive(Clone, Debug, PartialEq)]
pub struct Spms {
    /// The sensors.
    pub sensors: Vec<Sensor>,
    /// The sensor model.
    pub spec: SensorSpec,
    /// Reference sphere radius, mm (diameter 50.8143 mm in the paper).
    pub sphere_radius_mm: f64,
}

impl Spms {
    /// A head with `beams` and linearity phases drawn from `rng`.
    pub fn new<R: Rng + ?Sized>(beams: &[Beam], spec: SensorSpec, sphere_radius_mm: f64, rng: &mut R) -> Self {
        let sensors = beams.iter().map(|&beam| Sensor { beam, linearity_phase: rng.random_range(0.0..std::f64::consts::TAU) }).collect();
        Self { sensors, spec, sphere_radius_mm }
    }

    /// Systematic error of sensor `k` at true distance `l`, mm: a linearity curve of amplitude
    /// `linearity_pct_fs` of full scale (one period over the range, a phase per sensor), plus the
    /// temperature drift.
    pub fn systematic_error(&self, k: usize, l: f64) -> f64 {
        let s = &self.spec;
        let u = (l - s.range_min_mm) / s.full_scale();
        let lin = s.linearity_pct_fs / 100.0 * s.full_scale() * (std::f64::consts::TAU * u + self.sensors[k].linearity_phase).sin();
        lin + s.temperature_pct_fs_per_c / 100.0 * s.full_scale() * s.temperature_delta_c
    }

    /// Readings of all sensors with the sphere centre at `c` in the head frame. `rng` adds the
    /// repeatability noise; `None` reads exactly (no noise, no systematic error).
    pub fn read<R: Rng + ?Sized>(&self, c: &Vector3<f64>, rng: Option<&mut R>) -> Result<Vec<f64>, ReadingError> {
        let s = &self.spec;
        let mut out = Vec::with_capacity(self.sensors.len());
        let noise = Normal::new(0.0, s.repeatability_um * 1e-3).expect("finite");
        let mut rng = rng;
        for (k, sensor) in self.sensors.iter().enumerate() {
            let l = sensor.beam.hit(c, self.sphere_radius_mm).ok_or(ReadingError::Miss { beam: k })?;
            if l < s.range_min_mm || l > s.range_max_mm {
                return Err(ReadingError::OutOfRange { beam: k, distance_mm: l, min_mm: s.range_min_mm, max_mm: s.range_max_mm });
            }
            out.push(match rng.as_mut() {
                Some(r) => l + self.systematic_error(k, l) + noise.sample(r),
                None => l,
            });
        }
        Ok(out)
    }
}

/// A1-A3 on a head, head frame, mm: the points a laser tracker measures to give the head's frame.
/// A1 is the origin, A2 on +x, A3 in the xy plane, so the Gram-Schmidt frame of the exact points
/// is the head frame itself.
pub const FRAME_POINTS_MM: [[f64; 3]; 3] = [[0.0, 0.0, 0.0], [120.0, 0.0, 0.0], [35.0, 80.0, 0.0]];

/// `tracker_from_head` as a tracker measures it: A1-A3 ([`FRAME_POINTS_MM`]) placed by the true
/// `tracker_from_head`, each measured by `tracker`, then Gram-Schmidt (eqs. 4-7).
pub fn measured_frame<R: Rng + ?Sized>(tracker_from_head: &Isometry3<f64>, tracker: &AxisNoise, rng: &mut R) -> Option<Isometry3<f64>> {
    let a = FRAME_POINTS_MM.map(|p| tracker.measure(&tracker_from_head.transform_point(&nalgebra::Point3::from(p)).coords, rng));
    frame_from_points(&a[0], &a[1], &a[2])
}

/// The sphere centre fitted to the surface points of the readings (eqs. 1-3): Gauss-Newton on
/// `sum (|F_k - c| - R)^2`, started beyond the mean point along the mean beam direction.
/// Returns the centre and the residuals `|F_k - c| - R`, mm.
pub fn fit_centre(beams: &[Beam], readings: &[f64], r: f64) -> Option<(Vector3<f64>, Vec<f64>)> {
    if beams.len() < 3 || beams.len() != readings.len() {
        return None;
    }
    let pts: Vec<Vector3<f64>> = beams.iter().zip(readings).map(|(b, &l)| b.point(l)).collect();
    let mean = pts.iter().sum::<Vector3<f64>>() / pts.len() as f64;
    let dir = beams.iter().map(|b| b.dir.into_inner()).sum::<Vector3<f64>>().normalize();
    let mut c = mean + dir * r;
    for _ in 0..50 {
        let mut jtj = Matrix3::zeros();
        let mut jtr = Vector3::zeros();
        for p in &pts {
            let v = c - p;
            let n = v.norm();
            if n == 0.0 {
                return None;
            }
            let g = v / n;
            jtj += g * g.transpose();
            jtr += g * (n - r);
        }
        let step = jtj.try_inverse()? * jtr;
        c -= step;
        if step.norm() < 1e-12 {
            break;
        }
    }
    let residuals = pts.iter().map(|p| (c - p).norm() - r).collect();
    Some((c, residuals))
}

/// The measurement frame `O_t` in the tracker frame from three points of the head (eqs. 4-7):
/// origin A1, x along A2 - A1, y from A3 - A1 made orthogonal (Gram-Schmidt), z = x cross y.
/// Returns `tracker_from_head`, or `None` for collinear points.
pub fn frame_from_points(a1: &Vector3<f64>, a2: &Vector3<f64>, a3: &Vector3<f64>) -> Option<Isometry3<f64>> {
    let b = a2 - a1;
    let c = a3 - a1;
    let d = b.cross(&c);
    if d.norm() < 1e-9 * b.norm() * c.norm() {
        return None;
    }
    let beta1 = b;
    let beta2 = c - beta1 * (c.dot(&beta1) / beta1.dot(&beta1));
    let beta3 = d - beta1 * (d.dot(&beta1) / beta1.dot(&beta1)) - beta2 * (d.dot(&beta2) / beta2.dot(&beta2));
    let r = Matrix3::from_columns(&[beta1.normalize(), beta2.normalize(), beta3.normalize()]);
    let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    Some(Isometry3::from_parts(Translation3::from(*a1), rot))
}
