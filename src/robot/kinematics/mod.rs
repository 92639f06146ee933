//! Forward kinematics with gravity-induced joint compliance, the gravity torques it needs, and the
//! analytic identification Jacobian of the TCP position in {W} with respect to any [`ParamSet`].
//!
//! Algorithms are free functions `f(&model, &mut state, q)`: the [`RobotModel`] is shared, the
//! [`KinState`] is per-thread scratch that holds every frame of the last evaluation.
//!
//! The TCP position is `p = world_from_base * base_from_6(theta) * tcp`, with
//! `theta = theta0 + c * tau(theta0)` and `theta0 = q + theta_offs` (paper eqs. 6-10, Table 5).
//!
//! One arithmetic, three ways to run it: [`portable`] is the reference; [`avx`] computes the same
//! operations in the same order lane-wise (every 3-vector in four lanes), chosen at run time; and
//! [`batch`] runs four configurations of one model side by side. All three give the same numbers
//! to the bit (tests in each). [`statics`] gives the gravity torques the compliance multiplies.

#[cfg(target_arch = "x86_64")]
mod avx;
mod batch;
mod portable;
pub mod state;
pub mod statics;

use nalgebra::{Isometry3, Matrix3xX, Vector3};

use crate::robot::model::{JOINTS, Joints, RobotModel};
use crate::robot::params::ParamSet;
pub use batch::{AngleSines, angle_sines, tcp_jacobians_transposed, tcp_jacobians_transposed_by, tcps_world, tcps_world_by};
pub(crate) use portable::{forward_portable, tcp_jacobian_portable};
pub use state::KinState;
use state::isometry;

/// Forward kinematics with compliance: fills `st` and returns the TCP position in {W}, mm.
///
/// With AVX (detected at run time) the frames are computed lane-wise in 256-bit vectors
/// ([`avx`]), with the same operations in the same order: the same numbers to the bit.
pub fn forward(model: &RobotModel, st: &mut KinState, q: &Joints) -> Vector3<f64> {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        // SAFETY: the CPU was just found to support AVX, the only requirement of `kinematics_avx::forward`.
        #[allow(unsafe_code)]
        return unsafe { avx::forward(model, st, q) };
    }
    forward_portable(model, st, q)
}

/// Identification Jacobian `d p_W / d rho` (3 x p, internal units) at `q` for the parameters in
/// `set`, written column by column into `jac`; returns the TCP position in {W}, mm.
///
/// Every column is analytic, including the change of the gravity torques with the kinematic
/// parameters (the compliance term `c_k d tau_k / d rho`).
///
/// With AVX2 (detected at run time) the columns are computed lane-wise ([`avx`]), with
/// the same operations in the same order: the same numbers to the bit.
pub fn tcp_jacobian(model: &RobotModel, st: &mut KinState, q: &Joints, set: &ParamSet, jac: &mut [Vector3<f64>]) -> Vector3<f64> {
    assert_eq!(jac.len(), set.len(), "one Jacobian column per parameter");
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU was just found to support AVX2 (and so AVX), the only requirement of
        // `kinematics_avx::tcp_jacobian`.
        #[allow(unsafe_code)]
        return unsafe { avx::tcp_jacobian(model, st, q, set, jac) };
    }
    tcp_jacobian_portable(model, st, q, set, jac)
}

/// TCP position in {W}, mm, with a scratch state of its own (convenience for non-hot code).
pub fn tcp_world(model: &RobotModel, q: &Joints) -> Vector3<f64> {
    forward(model, &mut KinState::default(), q)
}

/// `world_from_flange` at `q` (deflected configuration), mm.
pub fn world_from_flange(model: &RobotModel, st: &mut KinState, q: &Joints) -> Isometry3<f64> {
    forward(model, st, q);
    let r = model.base_rot * st.rot[JOINTS];
    let p = model.base_pos + model.base_rot * st.org[JOINTS];
    isometry(&r, &p)
}

/// `world_from_base` of the model.
pub fn world_from_base(model: &RobotModel) -> Isometry3<f64> {
    isometry(&model.base_rot, &model.base_pos)
}

/// Convenience form of [`tcp_jacobian`] returning a fresh 3 x p matrix.
pub fn tcp_jacobian_matrix(model: &RobotModel, q: &Joints, set: &ParamSet) -> (Vector3<f64>, Matrix3xX<f64>) {
    let mut cols = vec![Vector3::zeros(); set.len()];
    let p = tcp_jacobian(model, &mut KinState::default(), q, set, &mut cols);
    (p, Matrix3xX::from_columns(&cols))
}

/// Holding torques of the gravity load at `q`, N m (the sign convention in [`statics`]).
pub fn gravity_torques(model: &RobotModel, q: &Joints) -> Joints {
    let mut st = KinState::default();
    forward(model, &mut st, q);
    st.tau
}
