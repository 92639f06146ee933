//! The robot model as data: a Craig modified-DH table with a Hayati beta, the base transform of the
//! paper's eq. 7, the TCP offset in the flange frame, joint limits, link inertials and payload.
//!
//! [`RobotData`] is plain, editable data. [`RobotModel`] is its immutable, validated form with the
//! per-joint constants precomputed; one model serves every thread, and each evaluation keeps its
//! scratch in a [`crate::robot::KinState`] of its own.

use nalgebra::{Matrix3, Rotation3, Vector3};

/// Number of joints of the serial arms calsim models.
pub const JOINTS: usize = 6;

/// Joint values, rad, in the controller's convention (ABB joint angles for the IRB 120).
pub type Joints = [f64; JOINTS];

/// One row of the modified-DH table: `T(i-1,i) = Rx(alpha) Dx(a) Ry(beta) Rz(theta) Dz(d)` with
/// `theta = q + theta_offset + compliance * tau` (paper eqs. 6 and Table 5).
///
/// `alpha`, `a` and `beta` carry the index `i-1` in the paper's notation, `theta_offset`, `d` and
/// `compliance` the index `i`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Link {
    /// Twist angle alpha_{i-1}, rad.
    pub alpha: f64,
    /// Common-normal length a_{i-1}, mm.
    pub a: f64,
    /// Hayati angle beta_{i-1} about the intermediate y axis, rad (non-zero only after a parallel pair).
    pub beta: f64,
    /// Joint offset theta_offs,i added to the joint value, rad.
    pub theta_offset: f64,
    /// Link offset d_i along z_i, mm.
    pub d: f64,
    /// Joint compliance c_i, rad/(N m), multiplying the holding torque (see [`crate::robot::kinematics::statics`]).
    pub compliance: f64,
}

/// A frame given by eq. 7 of the TriCal paper: `T = Dx(x) Dy(y) Dz(z) Rz(alpha) Ry(beta) Rx(gamma)`.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct XyzZyx {
    /// Translation x, mm.
    pub x: f64,
    /// Translation y, mm.
    pub y: f64,
    /// Translation z, mm.
    pub z: f64,
    /// Rotation about z, rad (applied first after the translation).
    pub alpha: f64,
    /// Rotation about the new y, rad.
    pub beta: f64,
    /// Rotation about the new x, rad.
    pub gamma: f64,
}

impl XyzZyx {
    /// From `[x, y, z]` mm and `[alpha, beta, gamma]` deg, as scenario and robot files give it.
    pub fn from_mm_deg([x, y, z, a, b, g]: [f64; 6]) -> Self {
        Self { x, y, z, alpha: a.to_radians(), beta: b.to_radians(), gamma: g.to_radians() }
    }

    /// The rigid transform (translation, then `Rz(alpha) Ry(beta) Rx(gamma)`).
    pub fn isometry(&self) -> nalgebra::Isometry3<f64> {
        nalgebra::Isometry3::from_parts(
            nalgebra::Translation3::from(self.translation()),
            nalgebra::UnitQuaternion::from_euler_angles(self.gamma, self.beta, self.alpha),
        )
    }

    /// Rotation part `Rz(alpha) Ry(beta) Rx(gamma)`.
    pub fn rotation(&self) -> Matrix3<f64> {
        let rz = Rotation3::from_axis_angle(&Vector3::z_axis(), self.alpha);
        let ry = Rotation3::from_axis_angle(&Vector3::y_axis(), self.beta);
        let rx = Rotation3::from_axis_angle(&Vector3::x_axis(), self.gamma);
        (rz * ry * rx).into_inner()
    }

    /// Translation part, mm.
    pub fn translation(&self) -> Vector3<f64> {
        Vector3::new(self.x, self.y, self.z)
    }
}

/// Joint range, rad.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointLimit {
    /// Lower bound, rad.
    pub min: f64,
    /// Upper bound, rad.
    pub max: f64,
}

/// Mass and centre of mass of a rigid body attached to a link frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Inertial {
    /// Mass, kg.
    pub mass_kg: f64,
    /// Centre of mass in the frame the body is attached to, mm.
    pub com_mm: Vector3<f64>,
}

impl Inertial {
    /// A body without mass.
    pub const NONE: Inertial = Inertial { mass_kg: 0.0, com_mm: Vector3::new(0.0, 0.0, 0.0) };
}

/// Everything that defines a robot arm, as plain data. Validate and freeze it with [`RobotModel::new`].
#[derive(Clone, Debug, PartialEq)]
pub struct RobotData {
    /// Display name.
    pub name: String,
    /// Modified-DH rows, joint 1 first.
    pub links: [Link; JOINTS],
    /// `world_from_base`, eq. 7 (the paper's x_0^W ... gamma_0^W).
    pub world_from_base: XyzZyx,
    /// TCP position in the flange frame {6}, mm (the paper's x_T^6, y_T^6, z_T^6).
    pub flange_tcp_mm: Vector3<f64>,
    /// Joint limits, rad.
    pub limits: [JointLimit; JOINTS],
    /// Link i's mass and centre of mass in MDH frame i.
    pub links_inertial: [Inertial; JOINTS],
    /// Payload (instrument plus anything carried) in the flange frame {6}.
    pub payload: Inertial,
    /// Gravity acceleration in the base frame {0}, m/s^2.
    pub gravity_base: Vector3<f64>,
}

/// Why [`RobotData`] cannot be turned into a model.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ModelError {
    /// A number that must be finite is not.
    #[error("{field} is not finite ({value})")]
    NotFinite {
        /// Which field.
        field: String,
        /// Its value.
        value: f64,
    },
    /// A mass is negative.
    #[error("{field} = {value} kg: a mass cannot be negative")]
    NegativeMass {
        /// Which field.
        field: String,
        /// Its value, kg.
        value: f64,
    },
    /// A joint range is empty.
    #[error("joint {joint}: limit min {min} rad is not below max {max} rad")]
    EmptyRange {
        /// Joint number, 1-based.
        joint: usize,
        /// Lower bound, rad.
        min: f64,
        /// Upper bound, rad.
        max: f64,
    },
}

/// Per-joint constants derived once from the data.
#[derive(Clone, Copy, Debug)]
pub(crate) struct JointConst {
    /// `Rx(alpha) Ry(beta)`.
    pub fixed: Matrix3<f64>,
    /// `Rx(alpha) e_y`: the beta axis expressed in frame i-1.
    pub beta_axis: Vector3<f64>,
}

/// The immutable robot model shared by every thread: validated [`RobotData`] plus derived constants.
#[derive(Clone, Debug)]
pub struct RobotModel {
    data: RobotData,
    pub(crate) joint: [JointConst; JOINTS],
    pub(crate) base_rot: Matrix3<f64>,
    pub(crate) base_pos: Vector3<f64>,
    /// `(-sin alpha, cos alpha, 0)` of `world_from_base`: the axis of its beta rotation in {W}.
    pub(crate) base_beta_axis: Vector3<f64>,
    /// Compliance is exactly zero on every joint: the gravity pass can be skipped.
    pub(crate) rigid: bool,
}

impl RobotModel {
    /// Validates the data and precomputes the per-joint constants.
    pub fn new(data: RobotData) -> Result<Self, ModelError> {
        validate(&data)?;
        let joint = std::array::from_fn(|i| {
            let l = &data.links[i];
            let rx = Rotation3::from_axis_angle(&Vector3::x_axis(), l.alpha).into_inner();
            let ry = Rotation3::from_axis_angle(&Vector3::y_axis(), l.beta).into_inner();
            JointConst { fixed: rx * ry, beta_axis: rx.column(1).into_owned() }
        });
        let rigid = data.links.iter().all(|l| l.compliance == 0.0);
        let (s, c) = data.world_from_base.alpha.sin_cos();
        Ok(Self {
            base_rot: data.world_from_base.rotation(),
            base_pos: data.world_from_base.translation(),
            base_beta_axis: Vector3::new(-s, c, 0.0),
            joint,
            rigid,
            data,
        })
    }

    /// The data this model was built from.
    pub fn data(&self) -> &RobotData {
        &self.data
    }

    /// Display name.
    pub fn name(&self) -> &str {
        &self.data.name
    }

    /// Modified-DH rows.
    pub fn links(&self) -> &[Link; JOINTS] {
        &self.data.links
    }

    /// Joint limits, rad.
    pub fn limits(&self) -> &[JointLimit; JOINTS] {
        &self.data.limits
    }

    /// Whether every joint value lies within its limits.
    pub fn within_limits(&self, q: &Joints) -> bool {
        q.iter().zip(&self.data.limits).all(|(v, l)| *v >= l.min && *v <= l.max)
    }

    /// A copy of this model with its data changed by `edit`.
    pub fn edited(&self, edit: impl FnOnce(&mut RobotData)) -> Result<Self, ModelError> {
        let mut data = self.data.clone();
        edit(&mut data);
        Self::new(data)
    }
}

fn validate(d: &RobotData) -> Result<(), ModelError> {
    // Field names are formatted only on failure: models are rebuilt at every identification step.
    let finite = |field: &dyn Fn() -> String, value: f64| {
        if value.is_finite() { Ok(()) } else { Err(ModelError::NotFinite { field: field(), value }) }
    };
    for (i, l) in d.links.iter().enumerate() {
        let j = i + 1;
        let named =
            [("alpha", l.alpha), ("a", l.a), ("beta", l.beta), ("theta_offset", l.theta_offset), ("d", l.d), ("compliance", l.compliance)];
        for (name, v) in named {
            finite(&|| format!("joint {j} {name}"), v)?;
        }
    }
    let b = &d.world_from_base;
    for (name, v) in [("x", b.x), ("y", b.y), ("z", b.z), ("alpha", b.alpha), ("beta", b.beta), ("gamma", b.gamma)] {
        finite(&|| format!("world_from_base {name}"), v)?;
    }
    for k in 0..3 {
        finite(&|| format!("flange_tcp_mm[{k}]"), d.flange_tcp_mm[k])?;
        finite(&|| format!("gravity_base[{k}]"), d.gravity_base[k])?;
    }
    for (i, lim) in d.limits.iter().enumerate() {
        finite(&|| format!("joint {} limit min", i + 1), lim.min)?;
        finite(&|| format!("joint {} limit max", i + 1), lim.max)?;
        if lim.min >= lim.max {
            return Err(ModelError::EmptyRange { joint: i + 1, min: lim.min, max: lim.max });
        }
    }
    let bodies = d.links_inertial.iter().enumerate().map(|(i, b)| (Some(i + 1), b)).chain(std::iter::once((None, &d.payload)));
    for (link, body) in bodies {
        let field = || link.map_or_else(|| "payload".to_string(), |i| format!("link {i}"));
        finite(&|| format!("{} mass", field()), body.mass_kg)?;
        if body.mass_kg < 0.0 {
            return Err(ModelError::NegativeMass { field: format!("{} mass", field()), value: body.mass_kg });
        }
        for k in 0..3 {
            finite(&|| format!("{} com_mm[{k}]", field()), body.com_mm[k])?;
        }
    }
    Ok(())
}

impl XyzZyx {
    /// The eq. 7 parameters of a rigid transform: `T = Dx Dy Dz Rz(alpha) Ry(beta) Rx(gamma)`.
    pub fn from_isometry(t: &nalgebra::Isometry3<f64>) -> Self {
        let r = t.rotation.to_rotation_matrix();
        // Rz(a) Ry(b) Rx(g): r20 = -sin b, r21 = cos b sin g, r22 = cos b cos g, r10 = sin a cos b, r00 = cos a cos b.
        let m = r.matrix();
        let beta = (-m[(2, 0)]).asin();
        let gamma = m[(2, 1)].atan2(m[(2, 2)]);
        let alpha = m[(1, 0)].atan2(m[(0, 0)]);
        let p = t.translation.vector;
        Self { x: p.x, y: p.y, z: p.z, alpha, beta, gamma }
    }
}

/// A configuration drawn uniformly inside the joint limits, leaving `margin` (a fraction of each
/// range) free at both ends; joint 6 is drawn within +-180 deg, its full turn.
pub fn uniform_configuration<R: rand::Rng + ?Sized>(model: &RobotModel, margin: f64, rng: &mut R) -> Joints {
    std::array::from_fn::<f64, JOINTS, _>(|i| {
        let l = model.limits()[i];
        let (lo, hi) = if i == JOINTS - 1 { (l.min.max(-std::f64::consts::PI), l.max.min(std::f64::consts::PI)) } else { (l.min, l.max) };
        let m = margin * (hi - lo);
        rand::RngExt::random_range(rng, lo + m..hi - m)
    })
}
