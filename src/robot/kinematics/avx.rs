//! Forward kinematics and the identification Jacobian with AVX vectors, chosen at run time by
//! [`super::forward`] and [`super::tcp_jacobian`].
//!
//! Every 3-vector and every matrix column lives in the low three lanes of a 256-bit vector (the
//! fourth lane is zero and never read into the others), and every operation is lane-wise, with
//! separate multiplies and adds in the order of the `Matrix3` code it replaces: nalgebra's
//! matrix-vector and matrix-matrix products sum `(a_0 x_0 + a_1 x_1) + a_2 x_2` column by column,
//! its cross product takes `a_y b_z - a_z b_y` (here: the lanes rotated, multiplied and
//! subtracted). Each lane therefore computes the same numbers as the portable path, to the bit; the
//! dot products of the gravity torques and the sines and cosines stay scalar and shared. Tests
//! compare the two paths over every field of the state and every Jacobian column.

use std::arch::x86_64::{
    __m256d, _mm_store_sd, _mm_storeu_pd, _mm256_add_pd, _mm256_castpd256_pd128, _mm256_extractf128_pd, _mm256_loadu_pd, _mm256_mul_pd,
    _mm256_permute4x64_pd, _mm256_set_pd, _mm256_set1_pd, _mm256_storeu_pd, _mm256_sub_pd, _mm256_xor_pd,
};

use nalgebra::{Matrix3, Vector3};

use super::portable::{angles, base_column, deflected_sincos};
use super::state::KinState;
use super::statics::holding_torque;
use crate::robot::model::{JOINTS, Joints, RobotModel};
use crate::robot::params::{LinkParam, ParamId, ParamSet};

type V = __m256d;

#[inline]
#[target_feature(enable = "avx")]
fn splat(x: f64) -> V {
    _mm256_set1_pd(x)
}

#[inline]
#[target_feature(enable = "avx")]
fn vector(v: &Vector3<f64>) -> V {
    _mm256_set_pd(0.0, v.z, v.y, v.x)
}

#[inline]
#[target_feature(enable = "avx")]
fn columns(m: &Matrix3<f64>) -> [V; 3] {
    std::array::from_fn(|j| _mm256_set_pd(0.0, m[(2, j)], m[(1, j)], m[(0, j)]))
}

#[inline]
#[target_feature(enable = "avx")]
fn load(x: &[f64; 4]) -> V {
    // SAFETY: `x` holds four f64; an unaligned load (the arrays of `Lanes` are 32-byte aligned, so
    // theirs never cross a cache line).
    #[allow(unsafe_code)]
    unsafe {
        _mm256_loadu_pd(x.as_ptr())
    }
}

#[inline]
#[target_feature(enable = "avx")]
fn store(x: &mut [f64; 4], v: V) {
    // SAFETY: `x` holds four f64; an unaligned store.
    #[allow(unsafe_code)]
    unsafe {
        _mm256_storeu_pd(x.as_mut_ptr(), v)
    }
}

#[inline]
#[target_feature(enable = "avx")]
fn to_vector(v: V) -> Vector3<f64> {
    let mut out = Vector3::zeros();
    put(&mut out, v);
    out
}

/// The low three lanes of `v` into `out` (a 128-bit store and one of the high half's low lane).
#[inline]
#[target_feature(enable = "avx")]
fn put(out: &mut Vector3<f64>, v: V) {
    let p = out.as_mut_slice().as_mut_ptr();
    // SAFETY: `out` holds three contiguous f64: two at `p`, one at `p + 2`; unaligned stores.
    #[allow(unsafe_code)]
    unsafe {
        _mm_storeu_pd(p, _mm256_castpd256_pd128(v));
        _mm_store_sd(p.add(2), _mm256_extractf128_pd::<1>(v));
    }
}

/// The low three lanes of each column into `out` (column-major): columns 0 and 1 as four lanes
/// each, the next store overwriting the fourth, column 2 as in [`put`].
#[inline]
#[target_feature(enable = "avx")]
fn put_matrix(out: &mut Matrix3<f64>, c: &[V; 3]) {
    let p = out.as_mut_slice().as_mut_ptr();
    // SAFETY: `out` holds nine contiguous f64, column-major: the stores write p[0..4], p[3..7],
    // p[6..8] and p[8], in that order, so each column's fourth lane is overwritten by the next.
    #[allow(unsafe_code)]
    unsafe {
        _mm256_storeu_pd(p, c[0]);
        _mm256_storeu_pd(p.add(3), c[1]);
        _mm_storeu_pd(p.add(6), _mm256_castpd256_pd128(c[2]));
        _mm_store_sd(p.add(8), _mm256_extractf128_pd::<1>(c[2]));
    }
}

/// Four lanes on a 32-byte boundary: a spill slot that never crosses a cache line.
#[repr(align(32))]
struct Aligned([f64; 4]);

/// `c * x` for a matrix given by its columns: `(c_0 x_0 + c_1 x_1) + c_2 x_2`, nalgebra's order.
#[inline]
#[target_feature(enable = "avx")]
fn times(c: &[V; 3], x0: f64, x1: f64, x2: f64) -> V {
    _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(c[0], splat(x0)), _mm256_mul_pd(c[1], splat(x1))), _mm256_mul_pd(c[2], splat(x2)))
}

/// `c * x` with `x` in memory (its lanes broadcast by loads, not shuffles).
#[inline]
#[target_feature(enable = "avx")]
fn times_at(c: &[V; 3], x: &[f64; 4]) -> V {
    times(c, x[0], x[1], x[2])
}

/// `c * (x s)`, each `x_j s` formed lane-wise from `x` in memory.
#[inline]
#[target_feature(enable = "avx")]
fn times_scaled(c: &[V; 3], x: &[f64; 4], s: V) -> V {
    let xs: [V; 3] = std::array::from_fn(|j| _mm256_mul_pd(splat(x[j]), s));
    _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(c[0], xs[0]), _mm256_mul_pd(c[1], xs[1])), _mm256_mul_pd(c[2], xs[2]))
}

/// `c * x` with `x` in lanes.
#[inline]
#[target_feature(enable = "avx")]
fn times_lanes(c: &[V; 3], x: V) -> V {
    let mut t = Aligned([0.0; 4]);
    store(&mut t.0, x);
    times(c, t.0[0], t.0[1], t.0[2])
}

/// `a x b` in nalgebra's arithmetic: `(a_y b_z - a_z b_y, a_z b_x - a_x b_z, a_x b_y - a_y b_x)`,
/// taken as the lanes of `a (b_y, b_z, b_x) - (a_y, a_z, a_x) b` rotated once more (three
/// shuffles; each lane the same two products and difference).
#[inline]
#[target_feature(enable = "avx2")]
fn cross(a: V, b: V) -> V {
    const YZX: i32 = 0b11_00_10_01;
    let c = _mm256_sub_pd(_mm256_mul_pd(a, _mm256_permute4x64_pd::<YZX>(b)), _mm256_mul_pd(_mm256_permute4x64_pd::<YZX>(a), b));
    _mm256_permute4x64_pd::<YZX>(c)
}

/// `-v`: the sign flipped, as `f64`'s negation.
#[inline]
#[target_feature(enable = "avx")]
fn neg(v: V) -> V {
    _mm256_xor_pd(v, splat(-0.0))
}

/// Frames 1..=6 for MDH angles given by their sines and cosines, into `rot`/`org` (lanes) and
/// `rot_m`/`org_m` (the state's matrices): the arithmetic of `kinematics::chain`, lane-wise.
/// Returns frame 6.
#[inline]
#[target_feature(enable = "avx")]
fn chain(
    model: &RobotModel,
    sc: &[(f64, f64); JOINTS],
    rot: &mut [[[f64; 4]; 3]; JOINTS + 1],
    org: &mut [[f64; 4]; JOINTS + 1],
    rot_m: &mut [Matrix3<f64>; JOINTS + 1],
    org_m: &mut [Vector3<f64>; JOINTS + 1],
) -> ([V; 3], V) {
    let mut r = [load(&rot[0][0]), load(&rot[0][1]), load(&rot[0][2])];
    let mut o = load(&org[0]);
    for i in 1..=JOINTS {
        let link = &model.data().links[i - 1];
        let f = &model.joint[i - 1].fixed;
        let p: [V; 3] = std::array::from_fn(|j| times(&r, f[(0, j)], f[(1, j)], f[(2, j)]));
        let (s, c) = (splat(sc[i - 1].0), splat(sc[i - 1].1));
        let c0 = _mm256_add_pd(_mm256_mul_pd(p[0], c), _mm256_mul_pd(p[1], s));
        let c1 = _mm256_sub_pd(_mm256_mul_pd(p[1], c), _mm256_mul_pd(p[0], s));
        o = _mm256_add_pd(_mm256_add_pd(o, _mm256_mul_pd(r[0], splat(link.a))), _mm256_mul_pd(p[2], splat(link.d)));
        r = [c0, c1, p[2]];
        for (j, v) in r.iter().enumerate() {
            store(&mut rot[i][j], *v);
        }
        store(&mut org[i], o);
        put_matrix(&mut rot_m[i], &r);
        put(&mut org_m[i], o);
    }
    (r, o)
}

/// `kinematics::forward` with AVX vectors (same numbers to the bit).
#[target_feature(enable = "avx")]
pub(super) fn forward(model: &RobotModel, st: &mut KinState, q: &Joints) -> Vector3<f64> {
    let data = model.data();
    st.sincos0 = angles(model, q).map(f64::sin_cos);
    let sc0 = st.sincos0;
    let lanes = &mut st.lanes;
    let (r6, o6) = chain(model, &sc0, &mut lanes.rot0, &mut lanes.org0, &mut st.rot0, &mut st.org0);

    // The gravity pass of `statics::gravity_pass`, its sums lane-wise.
    let g = data.gravity_base;
    let payload = &data.payload;
    let pc = payload.com_mm;
    let mut s = _mm256_mul_pd(_mm256_add_pd(o6, times(&r6, pc.x, pc.y, pc.z)), splat(payload.mass_kg));
    let mut m = payload.mass_kg;
    for k in (1..=JOINTS).rev() {
        let body = &data.links_inertial[k - 1];
        let rk = [load(&lanes.rot0[k][0]), load(&lanes.rot0[k][1]), load(&lanes.rot0[k][2])];
        let ok = load(&lanes.org0[k]);
        let c = body.com_mm;
        s = _mm256_add_pd(s, _mm256_mul_pd(_mm256_add_pd(ok, times(&rk, c.x, c.y, c.z)), splat(body.mass_kg)));
        m += body.mass_kg;
        store(&mut lanes.moment[k], s);
        st.moment[k] = to_vector(s);
        st.mass[k] = m;
        let arm = to_vector(_mm256_sub_pd(s, _mm256_mul_pd(ok, splat(m))));
        st.tau[k - 1] = holding_torque(&st.rot0[k], &arm, &g);
    }

    let (r, o) = if model.rigid {
        st.rot = st.rot0;
        st.org = st.org0;
        st.lanes.rot = st.lanes.rot0;
        st.lanes.org = st.lanes.org0;
        st.theta = angles(model, q);
        (r6, o6)
    } else {
        let sc = deflected_sincos(model, st, q);
        let lanes = &mut st.lanes;
        chain(model, &sc, &mut lanes.rot, &mut lanes.org, &mut st.rot, &mut st.org)
    };
    let t = data.flange_tcp_mm;
    let tcp = _mm256_add_pd(o, times(&r, t.x, t.y, t.z));
    store(&mut st.lanes.tcp_base, tcp);
    st.tcp_base = to_vector(tcp);
    let b = columns(&model.base_rot);
    let tb = st.tcp_base;
    st.tcp_world = to_vector(_mm256_add_pd(vector(&model.base_pos), times(&b, tb.x, tb.y, tb.z)));
    st.tcp_world
}

/// A motion of frames j..6 (see `kinematics::Motion`), in lanes; `at` is where the axis or the
/// translation is stored when it is a column of a frame (its lanes then broadcast by loads).
#[derive(Clone, Copy)]
enum Motion<'a> {
    Rotation { axis: V, at: Option<&'a [f64; 4]>, point: V },
    Translation(&'a [f64; 4]),
}

/// `kinematics::link_motion` in lanes.
#[inline]
#[target_feature(enable = "avx")]
fn link_motion<'a>(
    model: &RobotModel,
    rot: &'a [[[f64; 4]; 3]; JOINTS + 1],
    org: &[[f64; 4]; JOINTS + 1],
    i: usize,
    kind: LinkParam,
) -> Option<Motion<'a>> {
    let prev_x = &rot[i - 1][0];
    Some(match kind {
        LinkParam::Alpha => Motion::Rotation { axis: load(prev_x), at: Some(prev_x), point: load(&org[i - 1]) },
        LinkParam::A => Motion::Translation(prev_x),
        LinkParam::Beta => {
            let prev = [load(prev_x), load(&rot[i - 1][1]), load(&rot[i - 1][2])];
            let b = model.joint[i - 1].beta_axis;
            Motion::Rotation {
                axis: times(&prev, b.x, b.y, b.z),
                at: None,
                point: _mm256_add_pd(load(&org[i - 1]), _mm256_mul_pd(prev[0], splat(model.data().links[i - 1].a))),
            }
        }
        LinkParam::ThetaOffset => Motion::Rotation { axis: load(&rot[i][2]), at: Some(&rot[i][2]), point: load(&org[i]) },
        LinkParam::D => Motion::Translation(&rot[i][2]),
        LinkParam::Compliance => return None,
    })
}

/// `kinematics::tcp_jacobian` with AVX2 vectors (same numbers to the bit).
#[target_feature(enable = "avx2")]
pub(super) fn tcp_jacobian(model: &RobotModel, st: &mut KinState, q: &Joints, set: &ParamSet, jac: &mut [Vector3<f64>]) -> Vector3<f64> {
    let pw = forward(model, st, q);
    let lv = &st.lanes;
    let p = load(&lv.tcp_base);
    let links = &model.data().links;
    let g = vector(&model.data().gravity_base);
    let milli = splat(1e-3);
    let jt: [V; JOINTS] = std::array::from_fn(|k| cross(load(&lv.rot[k + 1][2]), _mm256_sub_pd(p, load(&lv.org[k + 1]))));
    let compliant = !model.rigid;
    // The suffix and prefix sums of `kinematics::tcp_jacobian`, column by column.
    let zero = [splat(0.0); 3];
    let mut w_suffix = [zero; JOINTS + 2];
    let mut u_prefix = [zero; JOINTS + 2];
    if compliant {
        // `torque_sensitivities`: w_k = -((z_k x r_k) x g) 1e-3, u_k = -(g x z_k) 1e-3.
        let mut w = [[0.0; 4]; JOINTS];
        let mut u = [[0.0; 4]; JOINTS];
        for k in 1..=JOINTS {
            let z = load(&lv.rot0[k][2]);
            let r = _mm256_sub_pd(load(&lv.moment[k]), _mm256_mul_pd(load(&lv.org0[k]), splat(st.mass[k])));
            store(&mut w[k - 1], _mm256_mul_pd(neg(cross(cross(z, r), g)), milli));
            store(&mut u[k - 1], _mm256_mul_pd(neg(cross(g, z)), milli));
        }
        for k in (1..=JOINTS).rev() {
            let cj = _mm256_mul_pd(jt[k - 1], splat(links[k - 1].compliance));
            w_suffix[k] = std::array::from_fn(|j| _mm256_add_pd(w_suffix[k + 1][j], _mm256_mul_pd(cj, splat(w[k - 1][j]))));
        }
        for k in 1..=JOINTS {
            let cj = _mm256_mul_pd(jt[k - 1], splat(links[k - 1].compliance));
            u_prefix[k + 1] = std::array::from_fn(|j| _mm256_add_pd(u_prefix[k][j], _mm256_mul_pd(cj, splat(u[k - 1][j]))));
        }
    }
    let base = columns(&model.base_rot);

    for (col, id) in jac.iter_mut().zip(set.ids()) {
        match *id {
            ParamId::Link { joint: i, kind } => {
                let mut dp = match link_motion(model, &lv.rot, &lv.org, i, kind) {
                    Some(Motion::Rotation { axis, point, .. }) => cross(axis, _mm256_sub_pd(p, point)),
                    Some(Motion::Translation(t)) => load(t),
                    None => _mm256_mul_pd(jt[i - 1], splat(st.tau[i - 1])),
                };
                if compliant && let Some(m0) = link_motion(model, &lv.rot0, &lv.org0, i, kind) {
                    let mass = splat(st.mass[i]);
                    dp = _mm256_add_pd(
                        dp,
                        match m0 {
                            Motion::Rotation { axis, at, point } => {
                                let arm = _mm256_sub_pd(load(&lv.moment[i]), _mm256_mul_pd(point, mass));
                                let w = match at {
                                    Some(x) => times_at(&w_suffix[i], x),
                                    None => times_lanes(&w_suffix[i], axis),
                                };
                                _mm256_add_pd(w, times_lanes(&u_prefix[i], cross(axis, arm)))
                            }
                            Motion::Translation(t) => times_scaled(&u_prefix[i], t, mass),
                        },
                    );
                }
                put(col, times_lanes(&base, dp));
            }
            ParamId::Base(b) => *col = base_column(model, b, &pw),
            ParamId::Tool(k) => put(col, times_at(&base, &lv.rot[JOINTS][k])),
        }
    }
    pw
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector3;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    use crate::robot::kinematics::{forward_portable, tcp_jacobian_portable};
    use crate::robot::test_models::{configuration, models};
    use crate::robot::{KinState, ParamId, ParamSet};

    /// Every number of the state, in field order.
    fn numbers(st: &KinState) -> Vec<f64> {
        let mut v = Vec::new();
        for (rot, org) in [(&st.rot0, &st.org0), (&st.rot, &st.org)] {
            rot.iter().for_each(|m| v.extend(m.iter()));
            org.iter().for_each(|o| v.extend(o.iter()));
        }
        st.sincos0.iter().for_each(|(s, c)| v.extend([*s, *c]));
        v.extend(st.theta.iter().chain(&st.tau).chain(&st.mass));
        st.moment.iter().for_each(|m| v.extend(m.iter()));
        v.extend(st.tcp_base.iter().chain(st.tcp_world.iter()));
        v
    }

    /// The AVX forward pass gives the portable path's numbers to the bit: 50 models (see
    /// `models`), 200 configurations each.
    #[test]
    fn avx_forward_equals_portable_bit_for_bit() {
        if !std::arch::is_x86_feature_detected!("avx") {
            eprintln!("no AVX on this CPU: the portable path is the only one");
            return;
        }
        let mut rng = ChaCha8Rng::seed_from_u64(16);
        let models = models(&mut rng);
        let (mut a, mut b) = (KinState::default(), KinState::default());
        let mut compared = 0;
        for m in &models {
            for j in 0..200 {
                let q = configuration(&mut rng, j);
                // SAFETY: AVX was found above.
                #[allow(unsafe_code)]
                let pa = unsafe { super::forward(m, &mut a, &q) };
                let pb = forward_portable(m, &mut b, &q);
                assert_eq!(pa.map(f64::to_bits), pb.map(f64::to_bits));
                let (na, nb) = (numbers(&a), numbers(&b));
                for (k, (x, y)) in na.iter().zip(&nb).enumerate() {
                    assert_eq!(x.to_bits(), y.to_bits(), "{}: number {k} of the state at {q:?}: {x} vs {y}", m.name());
                }
                compared += na.len();
            }
        }
        assert_eq!(compared, 50 * 200 * numbers(&a).len());
    }

    /// The AVX2 Jacobian gives the portable path's columns to the bit, for every parameter calsim
    /// names (each link parameter of every joint, base and tool): 50 models, 100 configurations each.
    #[test]
    fn avx_jacobian_equals_portable_bit_for_bit() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            eprintln!("no AVX2 on this CPU: the portable path is the only one");
            return;
        }
        let mut rng = ChaCha8Rng::seed_from_u64(17);
        let models = models(&mut rng);
        let set = ParamSet::new(ParamId::all()).unwrap();
        let (mut a, mut b) = (KinState::default(), KinState::default());
        let (mut ja, mut jb) = (vec![Vector3::zeros(); set.len()], vec![Vector3::zeros(); set.len()]);
        for m in &models {
            for j in 0..100 {
                let q = configuration(&mut rng, j);
                // SAFETY: AVX2 was found above.
                #[allow(unsafe_code)]
                let pa = unsafe { super::tcp_jacobian(m, &mut a, &q, &set, &mut ja) };
                let pb = tcp_jacobian_portable(m, &mut b, &q, &set, &mut jb);
                assert_eq!(pa.map(f64::to_bits), pb.map(f64::to_bits));
                for (k, (x, y)) in ja.iter().zip(&jb).enumerate() {
                    assert_eq!(x.map(f64::to_bits), y.map(f64::to_bits), "{}: column {} at {q:?}: {x} vs {y}", m.name(), set.names()[k]);
                }
            }
        }
        assert_eq!(set.len(), 6 * 6 + 6 + 3, "every link, base and tool parameter");
    }
}
