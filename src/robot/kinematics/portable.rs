//! The kinematics without vector extensions: the reference every vector path reproduces to the
//! bit. Forward kinematics with gravity-induced joint compliance and the analytic identification
//! Jacobian of the TCP position in {W}, operation for operation as [`super::avx`] and
//! [`super::batch`] compute them.

use nalgebra::{Matrix3, Vector3};

use super::state::KinState;
use super::statics::{gravity_pass, torque_sensitivities};
use crate::robot::model::{JOINTS, Joints, RobotModel};
use crate::robot::params::{BaseParam, LinkParam, ParamId, ParamSet};

/// Builds frames 1..=6 for MDH angles given by their sines and cosines.
#[inline(always)]
fn chain(model: &RobotModel, sc: &[(f64, f64); JOINTS], rot: &mut [Matrix3<f64>; JOINTS + 1], org: &mut [Vector3<f64>; JOINTS + 1]) {
    for i in 1..=JOINTS {
        let link = &model.data().links[i - 1];
        let prev_r = rot[i - 1];
        let p = prev_r * model.joint[i - 1].fixed;
        let (s, c) = sc[i - 1];
        let c0 = p.column(0) * c + p.column(1) * s;
        let c1 = p.column(1) * c - p.column(0) * s;
        let c2 = p.column(2).into_owned();
        rot[i] = Matrix3::from_columns(&[c0, c1, c2]);
        org[i] = org[i - 1] + prev_r.column(0) * link.a + c2 * link.d;
    }
}

/// sin and cos of `theta0 + delta` from those of `theta0`; a short series for the small deflections.
#[inline(always)]
fn sincos_shifted((s0, c0): (f64, f64), delta: f64) -> (f64, f64) {
    let (sd, cd) = if delta.abs() < 1e-3 {
        // Truncation below 2e-21 for |delta| < 1e-3.
        let d2 = delta * delta;
        (delta * (1.0 - d2 / 6.0 * (1.0 - d2 / 20.0)), 1.0 - d2 / 2.0 * (1.0 - d2 / 12.0))
    } else {
        delta.sin_cos()
    };
    (s0 * cd + c0 * sd, c0 * cd - s0 * sd)
}

/// `theta0 = q + theta_offs`, rad.
#[inline(always)]
pub(super) fn angles(model: &RobotModel, q: &Joints) -> Joints {
    let links = &model.data().links;
    std::array::from_fn(|i| q[i] + links[i].theta_offset)
}

/// Sines and cosines of the deflected angles `theta0 + c tau` (from those of `theta0` in
/// `st.sincos0` and the torques in `st.tau`); stores the angles in `st.theta`.
#[inline(always)]
pub(super) fn deflected_sincos(model: &RobotModel, st: &mut KinState, q: &Joints) -> [(f64, f64); JOINTS] {
    let links = &model.data().links;
    let mut sc = [(0.0, 1.0); JOINTS];
    for i in 0..JOINTS {
        let delta = links[i].compliance * st.tau[i];
        st.theta[i] = q[i] + links[i].theta_offset + delta;
        sc[i] = sincos_shifted(st.sincos0[i], delta);
    }
    sc
}

/// [`forward`] without vector extensions.
pub(crate) fn forward_portable(model: &RobotModel, st: &mut KinState, q: &Joints) -> Vector3<f64> {
    st.sincos0 = angles(model, q).map(f64::sin_cos);
    let sc0 = st.sincos0;
    chain(model, &sc0, &mut st.rot0, &mut st.org0);
    gravity_pass(model, st);
    if model.rigid {
        st.rot = st.rot0;
        st.org = st.org0;
        st.theta = angles(model, q);
    } else {
        let sc = deflected_sincos(model, st, q);
        chain(model, &sc, &mut st.rot, &mut st.org);
    }
    st.tcp_base = st.org[JOINTS] + st.rot[JOINTS] * model.data().flange_tcp_mm;
    st.tcp_world = model.base_pos + model.base_rot * st.tcp_base;
    st.tcp_world
}

/// An infinitesimal motion of frames j..6 caused by one parameter, in {0}.
#[derive(Clone, Copy)]
enum Motion {
    Rotation { axis: Vector3<f64>, point: Vector3<f64> },
    Translation(Vector3<f64>),
}

impl Motion {
    #[inline(always)]
    fn of_point(&self, p: &Vector3<f64>) -> Vector3<f64> {
        match self {
            Motion::Rotation { axis, point } => axis.cross(&(p - point)),
            Motion::Translation(t) => *t,
        }
    }
}

/// The motion caused by a unit change of link parameter `kind` of joint `i`, in the frames `rot/org`.
#[inline(always)]
fn link_motion(
    model: &RobotModel,
    rot: &[Matrix3<f64>; JOINTS + 1],
    org: &[Vector3<f64>; JOINTS + 1],
    i: usize,
    kind: LinkParam,
) -> Option<Motion> {
    let prev_x = rot[i - 1].column(0).into_owned();
    Some(match kind {
        LinkParam::Alpha => Motion::Rotation { axis: prev_x, point: org[i - 1] },
        LinkParam::A => Motion::Translation(prev_x),
        LinkParam::Beta => {
            Motion::Rotation { axis: rot[i - 1] * model.joint[i - 1].beta_axis, point: org[i - 1] + prev_x * model.data().links[i - 1].a }
        }
        LinkParam::ThetaOffset => Motion::Rotation { axis: rot[i].column(2).into_owned(), point: org[i] },
        LinkParam::D => Motion::Translation(rot[i].column(2).into_owned()),
        LinkParam::Compliance => return None,
    })
}

/// [`tcp_jacobian`] without vector extensions (its frames from [`forward_portable`]).
pub(crate) fn tcp_jacobian_portable(
    model: &RobotModel,
    st: &mut KinState,
    q: &Joints,
    set: &ParamSet,
    jac: &mut [Vector3<f64>],
) -> Vector3<f64> {
    let pw = forward_portable(model, st, q);
    let p = st.tcp_base;
    let links = &model.data().links;
    // Position sensitivity of each joint angle (deflected frames).
    let jt: [Vector3<f64>; JOINTS] = std::array::from_fn(|k| st.rot[k + 1].column(2).cross(&(p - st.org[k + 1])));
    let (w, u) = torque_sensitivities(model, st);
    let compliant = !model.rigid;
    // The compliance term of a column is sum_k c_k (d tau_k / d rho) jt_k. A rigid rotation `omega`
    // of links i..6 changes tau_k by omega . w_k for k >= i, and a displacement `dr` of their mass
    // moment changes tau_k by dr . u_k for k < i: so the term is W_i omega + U_i dr, with the
    // suffix sums W_i = sum_{k>=i} c_k jt_k w_k^T and prefix sums U_i = sum_{k<i} c_k jt_k u_k^T.
    let mut w_suffix = [Matrix3::zeros(); JOINTS + 2];
    let mut u_prefix = [Matrix3::zeros(); JOINTS + 2];
    if compliant {
        for k in (1..=JOINTS).rev() {
            let cj = jt[k - 1] * links[k - 1].compliance;
            w_suffix[k] = w_suffix[k + 1] + cj * w[k - 1].transpose();
        }
        for k in 1..=JOINTS {
            let cj = jt[k - 1] * links[k - 1].compliance;
            u_prefix[k + 1] = u_prefix[k] + cj * u[k - 1].transpose();
        }
    }

    for (col, id) in jac.iter_mut().zip(set.ids()) {
        *col = match *id {
            ParamId::Link { joint: i, kind } => {
                let mut dp = match link_motion(model, &st.rot, &st.org, i, kind) {
                    Some(m) => m.of_point(&p),
                    None => jt[i - 1] * st.tau[i - 1],
                };
                if compliant && let Some(m0) = link_motion(model, &st.rot0, &st.org0, i, kind) {
                    dp += match m0 {
                        Motion::Rotation { axis, point } => {
                            w_suffix[i] * axis + u_prefix[i] * axis.cross(&(st.moment[i] - point * st.mass[i]))
                        }
                        Motion::Translation(t) => u_prefix[i] * (t * st.mass[i]),
                    };
                }
                model.base_rot * dp
            }
            ParamId::Base(b) => base_column(model, b, &pw),
            ParamId::Tool(k) => model.base_rot * st.rot[JOINTS].column(k),
        };
    }
    pw
}

/// The Jacobian column of base parameter `b` at the TCP `pw` (in {W}, mm).
#[inline(always)]
pub(super) fn base_column(model: &RobotModel, b: BaseParam, pw: &Vector3<f64>) -> Vector3<f64> {
    let rel = pw - model.base_pos;
    match b {
        BaseParam::X => Vector3::x(),
        BaseParam::Y => Vector3::y(),
        BaseParam::Z => Vector3::z(),
        BaseParam::Alpha => Vector3::z().cross(&rel),
        BaseParam::Beta => model.base_beta_axis.cross(&rel),
        BaseParam::Gamma => model.base_rot.column(0).cross(&rel),
    }
}
