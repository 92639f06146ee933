//! Static gravity torques by the iterative Newton-Euler recursion (Craig ch. 6, with zero velocities
//! and accelerations), for the links plus the payload.
//!
//! **Sign convention, stated once.** `tau_i` is the *holding* torque the actuator of joint i exerts
//! on link i about `+z_i`: `tau_i = n_i . z_i` of Craig's recursion, which is what
//! `reference/irb120.toml` tabulates. The joint deflects along the gravity load, i.e. against the
//! holding torque, so a physical (positive) stiffness gives a *negative* compliance in
//! `theta_i = q_i + theta_offs_i + c_i tau_i`. This is the sign of the paper's Table 7
//! (c2..c6 from -2.06 to -44.6 mdeg/(N m)).
//!
//! The torques are evaluated at the commanded configuration `theta0 = q + theta_offs` (without the
//! deflection itself), with the gravity vector fixed in the robot base frame {0}.

use nalgebra::{Matrix3, Vector3};

use super::state::KinState;
use crate::robot::model::{JOINTS, RobotModel};

/// Fills `st.tau` (N m), `st.moment` and `st.mass` from the frames at `theta0` already in `st`.
pub(crate) fn gravity_pass(model: &RobotModel, st: &mut KinState) {
    let data = model.data();
    let g = data.gravity_base;
    let payload = &data.payload;
    let mut s = (st.org0[JOINTS] + st.rot0[JOINTS] * payload.com_mm) * payload.mass_kg;
    let mut m = payload.mass_kg;
    for k in (1..=JOINTS).rev() {
        let body = &data.links_inertial[k - 1];
        s += (st.org0[k] + st.rot0[k] * body.com_mm) * body.mass_kg;
        m += body.mass_kg;
        st.moment[k] = s;
        st.mass[k] = m;
        let r = s - st.org0[k] * m;
        st.tau[k - 1] = holding_torque(&st.rot0[k], &r, &g);
    }
}

/// The holding torque about `z_k` (column 2 of `rot_k`) of the weight of bodies whose mass moment
/// about the origin of frame k is `r` (kg mm), N m.
#[inline(always)]
pub(crate) fn holding_torque(rot_k: &Matrix3<f64>, r: &Vector3<f64>, g: &Vector3<f64>) -> f64 {
    // kg mm m/s^2 = N mm; holding torque is minus the gravity moment about z_k.
    -rot_k.column(2).dot(&r.cross(g)) * 1e-3
}

/// Direction of gravity's derivative helpers used by the Jacobian: for a rigid rotation `omega` of
/// links k..6 about any point, `d tau_k = omega . w_k`; for a displacement `dr` of the mass moment of
/// links j..6 (j > k), `d tau_k = dr . u_k`.
pub(crate) fn torque_sensitivities(model: &RobotModel, st: &KinState) -> ([Vector3<f64>; JOINTS], [Vector3<f64>; JOINTS]) {
    let g = model.data().gravity_base;
    let mut w = [Vector3::zeros(); JOINTS];
    let mut u = [Vector3::zeros(); JOINTS];
    for k in 1..=JOINTS {
        let z = st.rot0[k].column(2).into_owned();
        let r = st.moment[k] - st.org0[k] * st.mass[k];
        w[k - 1] = -(z.cross(&r)).cross(&g) * 1e-3;
        u[k - 1] = -g.cross(&z) * 1e-3;
    }
    (w, u)
}
