//! The TriCal device (2018 paper, section 2.1-2.2, Tables 1-2): three digital indicators along the
//! tool axes X, Y, Z touch a 12.7 mm ball; Algorithm 1 moves the TCP by the reading vector until
//! its norm is below epsilon.
//!
//! Geometry. The tool frame {T} sits at the TCP with its three axes symmetric about the flange
//! axis, each pointing back towards the flange (a corner cube facing the ball, as the conical
//! bracket holds them). The plunger of indicator i slides on the line through the TCP along its
//! actual axis `u_i` (the nominal axis tilted by the machining misalignment); its ball tip of
//! radius `r_t` rests on the ball. The reading is the plunger's travel from where it was zeroed on
//! the reference ball of the kinematic platform, positive when the ball pushes it in:
//! `r_i = (c . u_i) + sqrt((R + r_t)^2 - |c|^2 + (c . u_i)^2) - (R0 + r_t)` for a ball of radius
//! `R` whose centre is at `c` from the TCP, which is `c . u_i` to first order.

use crate::cell::collision::CapsuleSpec;
use nalgebra::{Isometry3, Matrix3, Rotation3, Unit, Vector3};
use rand::Rng;
use rand_distr::{Distribution, Normal, Uniform};
use serde::Deserialize;

/// The device as a scenario describes it.
#[derive(Clone, Debug, Deserialize, serde::Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct TriCalSpec {
    /// Accuracy of each indicator, um (Table 1: 3 um, Mitutoyo ID-C112XB); a reading's error is
    /// drawn uniformly within +- this.
    pub indicator_accuracy_um: f64,
    /// Display resolution, um (1 um for the ID-C112XB).
    pub indicator_resolution_um: f64,
    /// Largest angular deviation of an indicator axis, deg (Table 1: 0.122 deg); each axis is
    /// tilted by a uniform angle up to this, in a uniform direction.
    pub indicator_misalignment_deg: f64,
    /// Measuring range (stroke) of an indicator, mm (12.7 mm); zeroed at mid-stroke.
    pub indicator_range_mm: f64,
    /// Radius of the plunger's contact tip, mm.
    pub tip_radius_mm: f64,
    /// Centring tolerance epsilon, mm (Algorithm 1: 0.010 mm).
    pub epsilon_mm: f64,
    /// Iteration cap of the centring loop.
    pub max_iterations: u32,
    /// Wait after every move, s (Algorithm 1: 1 s).
    pub wait_s: f64,
    /// Duration of one correction move including the exchange between the PC, the receiver and
    /// the controller, s. FITTED: 6.4 s makes a configuration take about 20 s at epsilon = 10 um,
    /// as the paper reports (section 2.2); the time at other tolerances is then a prediction.
    pub correction_move_s: f64,
    /// Duration of the approach move to a new configuration, s.
    pub approach_move_s: f64,
    /// Standard deviation of the CMM measurement of the TCP in the flange frame, per axis, um
    /// (Table 2: 2.7 um at 95 %, i.e. about 1.4 um per axis).
    pub cmm_sigma_um: f64,
}

impl Default for TriCalSpec {
    fn default() -> Self {
        Self {
            indicator_accuracy_um: 3.0,
            indicator_resolution_um: 1.0,
            indicator_misalignment_deg: 0.122,
            indicator_range_mm: 12.7,
            tip_radius_mm: 1.5,
            epsilon_mm: 0.010,
            max_iterations: 30,
            wait_s: 1.0,
            correction_move_s: 6.4,
            approach_move_s: 4.0,
            cmm_sigma_um: 1.4,
        }
    }
}

/// Why the device gives no reading.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ReadingError {
    /// An indicator's plunger does not reach the ball.
    #[error("indicator {axis} has lost contact with the ball")]
    NoContact {
        /// 0 = X, 1 = Y, 2 = Z.
        axis: usize,
    },
    /// An indicator is beyond its stroke.
    #[error("indicator {axis} is out of range ({reading_mm:.3} mm)")]
    OutOfRange {
        /// 0 = X, 1 = Y, 2 = Z.
        axis: usize,
        /// The travel it would show, mm.
        reading_mm: f64,
    },
}

/// Nominal orientation of {T} in the flange frame: three axes at 54.7 deg from the flange axis,
/// 120 deg apart around it, each pointing back towards the flange.
pub fn flange_from_tool_rotation() -> Matrix3<f64> {
    let s = (2.0_f64 / 3.0).sqrt();
    let c = -(1.0_f64 / 3.0).sqrt();
    let axis = |deg: f64| {
        let a = deg.to_radians();
        Vector3::new(s * a.cos(), s * a.sin(), c)
    };
    // 0, 240, 120 deg: the order that makes the frame right-handed with all three towards the flange.
    let (x, y) = (axis(0.0), axis(240.0));
    Matrix3::from_columns(&[x, y, x.cross(&y)])
}

/// One TriCal device: its actual indicator axes in {T} and its reference ball.
#[derive(Clone, Debug)]
pub struct TriCal {
    /// The specification.
    pub spec: TriCalSpec,
    /// Actual indicator axes in {T} (unit vectors).
    pub axes: [Vector3<f64>; 3],
    /// Radius of the reference ball the indicators were zeroed on, mm.
    pub reference_radius_mm: f64,
    /// The flange frame in MDH frame 6 of the arm it is mounted on (`None`: frame 6 is the flange).
    pub frame6_from_flange: Option<Matrix3<f64>>,
}

impl TriCal {
    /// A device with misalignments drawn from `spec`, zeroed on a reference ball of `diameter_mm`.
    pub fn build<R: Rng + ?Sized>(spec: &TriCalSpec, diameter_mm: f64, rng: &mut R) -> Self {
        let tilt = Uniform::new_inclusive(0.0, spec.indicator_misalignment_deg.to_radians()).expect("range");
        let azimuth = Uniform::new(0.0, std::f64::consts::TAU).expect("range");
        let axes = std::array::from_fn(|i| {
            let nominal = Vector3::ith(i, 1.0);
            let perp = Vector3::ith((i + 1) % 3, 1.0);
            let dir = Rotation3::from_axis_angle(&Unit::new_normalize(nominal), azimuth.sample(rng)) * perp;
            Rotation3::from_axis_angle(&Unit::new_normalize(dir), tilt.sample(rng)) * nominal
        });
        Self { spec: spec.clone(), axes, reference_radius_mm: diameter_mm / 2.0, frame6_from_flange: None }
    }

    /// The device's capsules in MDH frame 6 of the arm it is mounted on, for its TCP `tcp` there.
    pub fn capsules(&self, tcp: &Vector3<f64>) -> Vec<CapsuleSpec> {
        trical_capsules(tcp, self.frame6_from_flange.as_ref())
    }

    /// The flange's axis (the device's, from the flange to the TCP) in MDH frame 6.
    pub fn flange_axis(&self) -> Vector3<f64> {
        self.frame6_from_flange.map_or_else(Vector3::z, |r| r.column(2).into_owned())
    }

    /// Nominal orientation of {T} in MDH frame 6 ([`flange_from_tool_rotation`] on this arm's flange).
    pub fn frame6_from_tool(&self) -> Matrix3<f64> {
        self.frame6_from_flange.map_or_else(flange_from_tool_rotation, |r| r * flange_from_tool_rotation())
    }

    /// `world_from_tcp` with the device on the flange (the device axis along the flange's z) as the
    /// pose of MDH frame 6 at the TCP that IK takes.
    pub fn frame6_pose(&self, world_from_tcp: Isometry3<f64>) -> Isometry3<f64> {
        match self.frame6_from_flange {
            None => world_from_tcp,
            Some(r) => {
                // A half-turn flange is common (a last axis pointing into the wrist): the closed
                // form, not nalgebra's iteration, which stalls there (see `robot::rotation`).
                let flange_from_frame6 = crate::robot::rotation::quaternion(&r.transpose());
                Isometry3::from_parts(world_from_tcp.translation, world_from_tcp.rotation * flange_from_frame6)
            }
        }
    }

    /// Exact plunger travels for a ball of `radius_mm` centred at `c` (in {T}, mm), no noise.
    pub fn exact_reading(&self, c: &Vector3<f64>, radius_mm: f64) -> Result<Vector3<f64>, ReadingError> {
        let rt = self.spec.tip_radius_mm;
        let mut out = Vector3::zeros();
        for (i, u) in self.axes.iter().enumerate() {
            let along = c.dot(u);
            let disc = (radius_mm + rt).powi(2) - c.norm_squared() + along * along;
            if disc < 0.0 {
                return Err(ReadingError::NoContact { axis: i });
            }
            let travel = along + disc.sqrt() - (self.reference_radius_mm + rt);
            if travel.abs() > self.spec.indicator_range_mm / 2.0 {
                return Err(ReadingError::OutOfRange { axis: i, reading_mm: travel });
            }
            out[i] = travel;
        }
        Ok(out)
    }

    /// A reading: exact travels plus the indicator error, quantised to the resolution, mm.
    pub fn read<R: Rng + ?Sized>(&self, c: &Vector3<f64>, radius_mm: f64, rng: &mut R) -> Result<Vector3<f64>, ReadingError> {
        let exact = self.exact_reading(c, radius_mm)?;
        let acc = self.spec.indicator_accuracy_um * 1e-3;
        let res = self.spec.indicator_resolution_um * 1e-3;
        Ok(exact.map(|v| {
            let noisy = if acc > 0.0 { v + Uniform::new_inclusive(-acc, acc).expect("range").sample(rng) } else { v };
            if res > 0.0 { (noisy / res).round() * res } else { noisy }
        }))
    }

    /// A CMM measurement of the TCP in the flange frame, mm.
    pub fn cmm_tcp<R: Rng + ?Sized>(&self, true_tcp: &Vector3<f64>, rng: &mut R) -> Vector3<f64> {
        let n = Normal::new(0.0, self.spec.cmm_sigma_um * 1e-3).expect("finite sigma");
        true_tcp.map(|v| v + if self.spec.cmm_sigma_um > 0.0 { n.sample(rng) } else { 0.0 })
    }
}

/// Capsules of the TriCal device in MDH frame 6 (`tcp` there), mounted on a flange at
/// `frame6_from_flange` (`None`: frame 6): the conical bracket and the three indicator bodies behind
/// their plungers (dimensions estimated from the paper's Figure 1).
fn trical_capsules(tcp: &Vector3<f64>, frame6_from_flange: Option<&Matrix3<f64>>) -> Vec<CapsuleSpec> {
    let Some(r) = frame6_from_flange else { return trical_capsules_on_flange(tcp) };
    let turn = |p: [f64; 3]| -> [f64; 3] { (r * Vector3::from(p)).into() };
    trical_capsules_on_flange(&(r.transpose() * tcp))
        .into_iter()
        .map(|c| CapsuleSpec { a: turn(c.a), b: turn(c.b), radius: c.radius })
        .collect()
}

/// Capsules of the TriCal device in the flange frame (`tcp` there).
fn trical_capsules_on_flange(tcp: &Vector3<f64>) -> Vec<CapsuleSpec> {
    let r6t = flange_from_tool_rotation();
    let mut v = vec![CapsuleSpec { a: [0.0, 0.0, 15.0], b: [tcp.x * 0.5, tcp.y * 0.5, tcp.z * 0.55], radius: 30.0 }];
    for k in 0..3 {
        let axis = r6t.column(k).into_owned();
        let a = tcp + axis * 28.0;
        let b = tcp + axis * 75.0;
        v.push(CapsuleSpec { a: a.into(), b: b.into(), radius: 9.0 });
    }
    v
}
