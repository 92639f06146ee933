//! The per-thread scratch of a kinematic evaluation: every frame of the last forward pass and the
//! gravity torques, filled by [`super::portable`] (and the vector paths) and [`super::statics`] and read by both.

use nalgebra::{Isometry3, Matrix3, Translation3, Vector3};

use crate::robot::model::{JOINTS, Joints};

/// Per-evaluation scratch: the frames of the last forward pass, in the base frame {0}.
///
/// Index 0 is the base frame itself, index i is MDH frame i; frame 6 is the flange.
#[derive(Clone, Debug)]
pub struct KinState {
    pub(crate) rot0: [Matrix3<f64>; JOINTS + 1],
    pub(crate) org0: [Vector3<f64>; JOINTS + 1],
    pub(crate) rot: [Matrix3<f64>; JOINTS + 1],
    pub(crate) org: [Vector3<f64>; JOINTS + 1],
    pub(crate) sincos0: [(f64, f64); JOINTS],
    pub(crate) theta: Joints,
    pub(crate) tau: Joints,
    /// Mass moment of links k..6 plus payload, kg mm, at theta0.
    pub(crate) moment: [Vector3<f64>; JOINTS + 1],
    /// Mass of links k..6 plus payload, kg.
    pub(crate) mass: [f64; JOINTS + 1],
    pub(crate) tcp_base: Vector3<f64>,
    pub(crate) tcp_world: Vector3<f64>,
    /// The same frames with every 3-vector in four lanes, for the vector kernels.
    pub(crate) lanes: Lanes,
}

/// The frames of the last evaluation with every 3-vector (and matrix column) in the low three of
/// four lanes, the fourth zero: written and read by the AVX kernels (`kinematics_avx`) only.
#[derive(Clone, Debug)]
#[repr(C, align(32))]
pub(crate) struct Lanes {
    pub(crate) rot0: [[[f64; 4]; 3]; JOINTS + 1],
    pub(crate) org0: [[f64; 4]; JOINTS + 1],
    pub(crate) rot: [[[f64; 4]; 3]; JOINTS + 1],
    pub(crate) org: [[f64; 4]; JOINTS + 1],
    pub(crate) moment: [[f64; 4]; JOINTS + 1],
    pub(crate) tcp_base: [f64; 4],
}

impl Default for Lanes {
    fn default() -> Self {
        const IDENTITY: [[f64; 4]; 3] = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]];
        Self {
            rot0: [IDENTITY; JOINTS + 1],
            org0: [[0.0; 4]; JOINTS + 1],
            rot: [IDENTITY; JOINTS + 1],
            org: [[0.0; 4]; JOINTS + 1],
            moment: [[0.0; 4]; JOINTS + 1],
            tcp_base: [0.0; 4],
        }
    }
}

impl Default for KinState {
    fn default() -> Self {
        Self {
            rot0: [Matrix3::identity(); JOINTS + 1],
            org0: [Vector3::zeros(); JOINTS + 1],
            rot: [Matrix3::identity(); JOINTS + 1],
            org: [Vector3::zeros(); JOINTS + 1],
            sincos0: [(0.0, 1.0); JOINTS],
            theta: [0.0; JOINTS],
            tau: [0.0; JOINTS],
            moment: [Vector3::zeros(); JOINTS + 1],
            mass: [0.0; JOINTS + 1],
            tcp_base: Vector3::zeros(),
            tcp_world: Vector3::zeros(),
            lanes: Lanes::default(),
        }
    }
}

impl KinState {
    /// Holding torques of the last evaluation, N m.
    pub fn torques(&self) -> &Joints {
        &self.tau
    }

    /// Joint angles of the last evaluation including offsets and deflections, rad.
    pub fn theta(&self) -> &Joints {
        &self.theta
    }

    /// TCP in {W} of the last evaluation, mm.
    pub fn tcp_world(&self) -> Vector3<f64> {
        self.tcp_world
    }

    /// `base_from_frame_i` of the last evaluation (i = 0..=6, deflected configuration), mm.
    pub fn base_from_frame(&self, i: usize) -> Isometry3<f64> {
        isometry(&self.rot[i], &self.org[i])
    }
}

pub(crate) fn isometry(r: &Matrix3<f64>, p: &Vector3<f64>) -> Isometry3<f64> {
    // Not `UnitQuaternion::from_matrix` alone: it stalls at a half-turn (see `robot::rotation`).
    Isometry3::from_parts(Translation3::from(*p), crate::robot::rotation::quaternion(r))
}
