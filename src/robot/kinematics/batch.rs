//! The TCPs and identification Jacobians of many configurations of one model: forward kinematics
//! with gravity torques and compliance, and the Jacobian, for four configurations side by side, a
//! configuration per lane.
//!
//! Each lane performs exactly the operations of [`super::portable::forward_portable`] on its
//! configuration, in the same order: nalgebra's products of a 3 x 3 matrix and a vector
//! (`(a_0 x_0 + a_1 x_1) + a_2 x_2`, column by column), its cross and dot products, separate
//! multiplies and adds (no fused operations), `sincos` of each angle by the same library call, the
//! same short series for small deflections. So every TCP is the same to the bit as [`forward`]'s
//! (a test compares them over 50 models), and every Jacobian column the same as
//! [`super::tcp_jacobian`]'s (`tcp_jacobian_portable`'s operations: torque
//! sensitivities, the suffix and prefix sums of the compliance term, each parameter's motion);
//! the lanes only share the model's constants and the loop. A configuration's joint angles enter as
//! their sines and cosines ([`AngleSines`], the same call), which callers measuring one pose at
//! several targets (a model per target) take once for all of them (`*_by`). The validation of
//! every identified model takes its TCPs here (506 poses, one model), the identification its
//! Jacobians (every configuration of the set, one model per iteration).
//!
//! [`forward`]: super::forward

use nalgebra::{Matrix3, Vector3};

use crate::robot::model::{JOINTS, Joints, RobotModel};
use crate::robot::params::{BaseParam, LinkParam, ParamId, ParamSet};

/// Configurations side by side.
const LANES: usize = 4;

/// One number for each of the [`LANES`] configurations.
type L = [f64; LANES];
/// A 3-vector for each configuration (coordinates, each in lanes).
type V = [L; 3];
/// A 3 x 3 matrix for each configuration (columns).
type M = [V; 3];

#[inline(always)]
fn splat(x: f64) -> L {
    [x; LANES]
}

#[inline(always)]
fn add(a: L, b: L) -> L {
    std::array::from_fn(|l| a[l] + b[l])
}

#[inline(always)]
fn sub(a: L, b: L) -> L {
    std::array::from_fn(|l| a[l] - b[l])
}

#[inline(always)]
fn mul(a: L, b: L) -> L {
    std::array::from_fn(|l| a[l] * b[l])
}

#[inline(always)]
fn vadd(a: &V, b: &V) -> V {
    std::array::from_fn(|i| add(a[i], b[i]))
}

/// `v * x` (a vector times a scalar of each lane).
#[inline(always)]
fn vscale(v: &V, x: L) -> V {
    std::array::from_fn(|i| mul(v[i], x))
}

#[inline(always)]
fn vsub(a: &V, b: &V) -> V {
    std::array::from_fn(|i| sub(a[i], b[i]))
}

/// A constant vector in every lane.
#[inline(always)]
fn vsplat(v: &Vector3<f64>) -> V {
    [splat(v.x), splat(v.y), splat(v.z)]
}

/// nalgebra's cross product: `(a_y b_z - a_z b_y, a_z b_x - a_x b_z, a_x b_y - a_y b_x)`.
#[inline(always)]
fn cross(a: &V, b: &V) -> V {
    [sub(mul(a[1], b[2]), mul(a[2], b[1])), sub(mul(a[2], b[0]), mul(a[0], b[2])), sub(mul(a[0], b[1]), mul(a[1], b[0]))]
}

/// `m * x`, both of each lane: `(m_0 x_0 + m_1 x_1) + m_2 x_2`.
#[inline(always)]
fn mat_vec(m: &M, x: &V) -> V {
    std::array::from_fn(|i| add(add(mul(m[0][i], x[0]), mul(m[1][i], x[1])), mul(m[2][i], x[2])))
}

/// `m * x` for a constant vector x: `(m_0 x_0 + m_1 x_1) + m_2 x_2`.
#[inline(always)]
fn times(m: &M, x: &Vector3<f64>) -> V {
    std::array::from_fn(|i| add(add(mul(m[0][i], splat(x.x)), mul(m[1][i], splat(x.y))), mul(m[2][i], splat(x.z))))
}

/// `c * x` for a constant matrix c and a vector of each lane.
#[inline(always)]
fn const_times(c: &Matrix3<f64>, x: &V) -> V {
    std::array::from_fn(|i| add(add(mul(splat(c[(i, 0)]), x[0]), mul(splat(c[(i, 1)]), x[1])), mul(splat(c[(i, 2)]), x[2])))
}

/// The identity in every lane.
#[inline(always)]
fn identity() -> M {
    std::array::from_fn(|j| std::array::from_fn(|i| splat(if i == j { 1.0 } else { 0.0 })))
}

/// The frames of the chain from the sines and cosines of the joint angles (`kinematics::chain`):
/// the last one, and every one into `frames` when given.
#[inline(always)]
fn chain(model: &RobotModel, sc: &[(L, L); JOINTS], mut frames: Option<(&mut [M; JOINTS + 1], &mut [V; JOINTS + 1])>) -> (M, V) {
    let mut r = identity();
    let mut o: V = [splat(0.0); 3];
    for i in 1..=JOINTS {
        let link = &model.data().links[i - 1];
        let f = &model.joint[i - 1].fixed;
        let mut p: M = [[splat(0.0); 3]; 3];
        for (j, pj) in p.iter_mut().enumerate() {
            *pj = times(&r, &f.column(j).into_owned());
        }
        let (s, c) = sc[i - 1];
        let (a, d) = (splat(link.a), splat(link.d));
        for k in 0..3 {
            o[k] = add(add(o[k], mul(r[0][k], a)), mul(p[2][k], d));
            r[0][k] = add(mul(p[0][k], c), mul(p[1][k], s));
            r[1][k] = sub(mul(p[1][k], c), mul(p[0][k], s));
            r[2][k] = p[2][k];
        }
        if let Some((rot, org)) = frames.as_mut() {
            rot[i] = r;
            org[i] = o;
        }
    }
    (r, o)
}

/// The forward pass of four configurations: what the TCP and the Jacobian read (the fields of
/// `KinState` that `forward_portable` fills, in lanes).
struct Frames {
    rot0: [M; JOINTS + 1],
    org0: [V; JOINTS + 1],
    rot: [M; JOINTS + 1],
    org: [V; JOINTS + 1],
    /// Mass moment of links k..6 and the payload (kg mm), undeflected frames.
    moment: [V; JOINTS + 1],
    /// Their mass (kg), the same in every lane.
    mass: [f64; JOINTS + 1],
    /// Holding torques, N m.
    tau: [L; JOINTS],
    tcp_base: V,
    tcp_world: V,
}

/// [`Frames`] of four configurations into `f` (`kinematics::forward_portable`, lane by lane).
/// `all`: the deflected chain's frames too (the Jacobian reads them; the TCP only the last).
#[inline(always)]
fn forward(model: &RobotModel, sines: &[AngleSines; LANES], all: bool, f: &mut Frames) {
    let data = model.data();
    let links = &data.links;
    let mut sc0 = [(splat(0.0), splat(1.0)); JOINTS];
    for (i, sci) in sc0.iter_mut().enumerate() {
        for l in 0..LANES {
            (sci.0[l], sci.1[l]) = sines[l][i];
        }
    }
    let (r6, o6) = chain(model, &sc0, Some((&mut f.rot0, &mut f.org0)));
    // The gravity pass (`statics::gravity_pass`): holding torques at the undeflected frames.
    let g = data.gravity_base;
    let (gx, gy, gz) = (splat(g.x), splat(g.y), splat(g.z));
    let payload = &data.payload;
    let mut s = vscale(&vadd(&o6, &times(&r6, &payload.com_mm)), splat(payload.mass_kg));
    let mut m = payload.mass_kg;
    for k in (1..=JOINTS).rev() {
        let body = &data.links_inertial[k - 1];
        s = vadd(&s, &vscale(&vadd(&f.org0[k], &times(&f.rot0[k], &body.com_mm)), splat(body.mass_kg)));
        m += body.mass_kg;
        f.moment[k] = s;
        f.mass[k] = m;
        let r = vsub(&s, &vscale(&f.org0[k], splat(m)));
        // -z . (r x g) * 1e-3, nalgebra's cross and dot.
        let c = cross(&r, &[gx, gy, gz]);
        let z = &f.rot0[k][2];
        let dot = add(add(mul(z[0], c[0]), mul(z[1], c[1])), mul(z[2], c[2]));
        f.tau[k - 1] = dot.map(|d| -d * 1e-3);
    }
    let (rot, org) = if model.rigid {
        f.rot = f.rot0;
        f.org = f.org0;
        (r6, o6)
    } else {
        // The same operations as `kinematics::sincos_shifted`, its series in every lane and
        // `sin_cos` of the deflection where it is 1e-3 rad or more.
        let mut sc = sc0;
        for (i, sci) in sc.iter_mut().enumerate() {
            let delta = mul(splat(links[i].compliance), f.tau[i]);
            let d2 = mul(delta, delta);
            let one = splat(1.0);
            let (div6, div20, div2, div12) = (d2.map(|x| x / 6.0), d2.map(|x| x / 20.0), d2.map(|x| x / 2.0), d2.map(|x| x / 12.0));
            let mut sd = mul(delta, sub(one, mul(div6, sub(one, div20))));
            let mut cd = sub(one, mul(div2, sub(one, div12)));
            for l in 0..LANES {
                let small = delta[l].abs() < 1e-3;
                if !small {
                    (sd[l], cd[l]) = delta[l].sin_cos();
                }
            }
            let (s0, c0) = sc0[i];
            *sci = (add(mul(s0, cd), mul(c0, sd)), sub(mul(c0, cd), mul(s0, sd)));
        }
        chain(model, &sc, all.then_some((&mut f.rot, &mut f.org)))
    };
    f.tcp_base = vadd(&org, &times(&rot, &data.flange_tcp_mm));
    f.tcp_world = vadd(&vsplat(&model.base_pos), &const_times(&model.base_rot, &f.tcp_base));
}

impl Frames {
    /// Frame 0 in both chains is the base: the identity at the origin (as in `KinState`); the rest
    /// is written by [`forward`].
    fn new() -> Self {
        Frames {
            rot0: [identity(); JOINTS + 1],
            org0: [[splat(0.0); 3]; JOINTS + 1],
            rot: [identity(); JOINTS + 1],
            org: [[splat(0.0); 3]; JOINTS + 1],
            moment: [[splat(0.0); 3]; JOINTS + 1],
            mass: [0.0; JOINTS + 1],
            tau: [splat(0.0); JOINTS],
            tcp_base: [splat(0.0); 3],
            tcp_world: [splat(0.0); 3],
        }
    }
}

/// A motion of frames i..6 caused by one parameter (`kinematics::Motion`), in lanes.
enum Motion {
    Rotation { axis: V, point: V },
    Translation(V),
}

/// `kinematics::link_motion` in lanes.
#[inline(always)]
fn link_motion(model: &RobotModel, rot: &[M; JOINTS + 1], org: &[V; JOINTS + 1], i: usize, kind: LinkParam) -> Option<Motion> {
    let prev_x = rot[i - 1][0];
    Some(match kind {
        LinkParam::Alpha => Motion::Rotation { axis: prev_x, point: org[i - 1] },
        LinkParam::A => Motion::Translation(prev_x),
        LinkParam::Beta => Motion::Rotation {
            axis: times(&rot[i - 1], &model.joint[i - 1].beta_axis),
            point: vadd(&org[i - 1], &vscale(&prev_x, splat(model.data().links[i - 1].a))),
        },
        LinkParam::ThetaOffset => Motion::Rotation { axis: rot[i][2], point: org[i] },
        LinkParam::D => Motion::Translation(rot[i][2]),
        LinkParam::Compliance => return None,
    })
}

/// The sums of the compliance terms along the chain, in lanes: `w_suffix[i]` over joints k >= i,
/// `u_prefix[i]` over k < i (see [`jacobian`]). For a compliant model, entries 1..=6 of `w_suffix`
/// and 2..=7 of `u_prefix` are written for each four configurations before they are read (a rigid
/// one reads none); `w_suffix[7]` and `u_prefix[1]` are the empty sums and stay zero. Made once
/// per call and reused (zeroing them for every four configurations was a memset of 4.6 kB each
/// time).
struct ComplianceSums {
    w_suffix: [M; JOINTS + 2],
    u_prefix: [M; JOINTS + 2],
}

impl ComplianceSums {
    fn new() -> Self {
        let zero: M = [[splat(0.0); 3]; 3];
        Self { w_suffix: [zero; JOINTS + 2], u_prefix: [zero; JOINTS + 2] }
    }
}

/// The Jacobian columns of `set` at four configurations (`kinematics::tcp_jacobian_portable`, lane
/// by lane): `emit(column, value in lanes)`.
#[inline(always)]
fn jacobian(model: &RobotModel, f: &Frames, set: &ParamSet, sums: &mut ComplianceSums, mut emit: impl FnMut(usize, &V)) {
    let p = &f.tcp_base;
    let pw = &f.tcp_world;
    let links = &model.data().links;
    let mut jt = [[splat(0.0); 3]; JOINTS];
    for (k, jk) in jt.iter_mut().enumerate() {
        *jk = cross(&f.rot[k + 1][2], &vsub(p, &f.org[k + 1]));
    }
    let compliant = !model.rigid;
    let ComplianceSums { w_suffix, u_prefix } = sums;
    if compliant {
        // `torque_sensitivities`: w_k = -((z_k x r_k) x g) 1e-3, u_k = -(g x z_k) 1e-3.
        let g = vsplat(&model.data().gravity_base);
        let milli = splat(1e-3);
        let neg = |v: V| v.map(|c| c.map(|x| -x));
        let mut w = [[splat(0.0); 3]; JOINTS];
        let mut u = [[splat(0.0); 3]; JOINTS];
        for k in 1..=JOINTS {
            let z = f.rot0[k][2];
            let r = vsub(&f.moment[k], &vscale(&f.org0[k], splat(f.mass[k])));
            w[k - 1] = vscale(&neg(cross(&cross(&z, &r), &g)), milli);
            u[k - 1] = vscale(&neg(cross(&g, &z)), milli);
        }
        // The outer products `c_k jt_k w_k^T` (column j: `c_k jt_k` times `w_k[j]`), summed.
        for k in (1..=JOINTS).rev() {
            let cj = vscale(&jt[k - 1], splat(links[k - 1].compliance));
            for j in 0..3 {
                let next = w_suffix[k + 1][j];
                w_suffix[k][j] = vadd(&next, &vscale(&cj, w[k - 1][j]));
            }
        }
        for k in 1..=JOINTS {
            let cj = vscale(&jt[k - 1], splat(links[k - 1].compliance));
            for j in 0..3 {
                let prev = u_prefix[k][j];
                u_prefix[k + 1][j] = vadd(&prev, &vscale(&cj, u[k - 1][j]));
            }
        }
    }
    let rel = vsub(pw, &vsplat(&model.base_pos));
    for (c, id) in set.ids().iter().enumerate() {
        let col = match *id {
            ParamId::Link { joint: i, kind } => {
                let mut dp = match link_motion(model, &f.rot, &f.org, i, kind) {
                    Some(Motion::Rotation { axis, point }) => cross(&axis, &vsub(p, &point)),
                    Some(Motion::Translation(t)) => t,
                    None => vscale(&jt[i - 1], f.tau[i - 1]),
                };
                if compliant && let Some(m0) = link_motion(model, &f.rot0, &f.org0, i, kind) {
                    let extra = match m0 {
                        Motion::Rotation { axis, point } => vadd(
                            &mat_vec(&w_suffix[i], &axis),
                            &mat_vec(&u_prefix[i], &cross(&axis, &vsub(&f.moment[i], &vscale(&point, splat(f.mass[i]))))),
                        ),
                        Motion::Translation(t) => mat_vec(&u_prefix[i], &vscale(&t, splat(f.mass[i]))),
                    };
                    dp = vadd(&dp, &extra);
                }
                const_times(&model.base_rot, &dp)
            }
            // `kinematics::base_column`.
            ParamId::Base(b) => match b {
                BaseParam::X => vsplat(&Vector3::x()),
                BaseParam::Y => vsplat(&Vector3::y()),
                BaseParam::Z => vsplat(&Vector3::z()),
                BaseParam::Alpha => cross(&vsplat(&Vector3::z()), &rel),
                BaseParam::Beta => cross(&vsplat(&model.base_beta_axis), &rel),
                BaseParam::Gamma => cross(&vsplat(&model.base_rot.column(0).into_owned()), &rel),
            },
            ParamId::Tool(k) => const_times(&model.base_rot, &f.rot[JOINTS][k]),
        };
        emit(c, &col);
    }
}

/// The configurations of one chunk in lanes; a short last chunk repeats its last configuration
/// (computed, not returned).
#[inline(always)]
fn padded(n: usize, first: usize, sines: &impl Fn(usize) -> AngleSines) -> [AngleSines; LANES] {
    std::array::from_fn(|l| sines((first + l).min(n - 1)))
}

/// The sines and cosines of a configuration's joint angles at a model's joint offsets,
/// `(q_i + theta_offset_i).sin_cos()` per joint: what the kernels here take a configuration as.
pub type AngleSines = [(f64, f64); JOINTS];

/// [`AngleSines`] of `q` at `model`'s joint offsets. Configurations shared by many calls (a pose
/// measured at several targets, each with its own tool) take them once.
#[inline(always)]
pub fn angle_sines(model: &RobotModel, q: &Joints) -> AngleSines {
    let links = &model.data().links;
    std::array::from_fn(|i| (q[i] + links[i].theta_offset).sin_cos())
}

/// The TCP in {W} (mm) of every configuration of `qs` at `model`, in order: the same to the bit as
/// [`super::forward`] of each.
pub fn tcps_world<'a>(model: &RobotModel, qs: impl IntoIterator<Item = &'a Joints>) -> Vec<Vector3<f64>> {
    let qs: Vec<&Joints> = qs.into_iter().collect();
    tcps_world_by(model, qs.len(), |k| angle_sines(model, qs[k]))
}

/// [`tcps_world`] of `n` configurations given by their [`AngleSines`] at `model`, `sines(k)` the
/// k-th's (the same bits).
pub fn tcps_world_by(model: &RobotModel, n: usize, sines: impl Fn(usize) -> AngleSines) -> Vec<Vector3<f64>> {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU was just found to support AVX2, the only requirement of `tcps_avx2`.
        #[allow(unsafe_code)]
        return unsafe { tcps_avx2(model, n, sines) };
    }
    tcps_body(model, n, sines)
}

/// [`tcps_world`] compiled for AVX2 (the lanes in one vector; the same operations).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn tcps_avx2(model: &RobotModel, n: usize, sines: impl Fn(usize) -> AngleSines) -> Vec<Vector3<f64>> {
    tcps_body(model, n, sines)
}

#[inline(always)]
fn tcps_body(model: &RobotModel, n: usize, sines: impl Fn(usize) -> AngleSines) -> Vec<Vector3<f64>> {
    let mut out = Vec::with_capacity(n);
    let mut f = Frames::new();
    for first in (0..n).step_by(LANES) {
        forward(model, &padded(n, first, &sines), false, &mut f);
        let w = &f.tcp_world;
        out.extend((0..LANES.min(n - first)).map(|l| Vector3::new(w[0][l], w[1][l], w[2][l])));
    }
    out
}

/// The identification Jacobians `d p_W / d rho` of `set` at every configuration of `qs` (`model`),
/// transposed and stacked as least squares reads them: `jt` is p x 3n, column-major (column 3k + i
/// holds row i of configuration k's 3 x p Jacobian); `tcps` gets the TCP in {W} of each (mm). The
/// same to the bit as [`super::tcp_jacobian`] of each.
pub fn tcp_jacobians_transposed(model: &RobotModel, set: &ParamSet, qs: &[Joints], jt: &mut [f64], tcps: &mut [Vector3<f64>]) {
    tcp_jacobians_transposed_by(model, set, qs.len(), |k| angle_sines(model, &qs[k]), jt, tcps);
}

/// [`tcp_jacobians_transposed`] of `n` configurations given by their [`AngleSines`] at `model`,
/// `sines(k)` the k-th's (the same bits).
pub fn tcp_jacobians_transposed_by(
    model: &RobotModel,
    set: &ParamSet,
    n: usize,
    sines: impl Fn(usize) -> AngleSines,
    jt: &mut [f64],
    tcps: &mut [Vector3<f64>],
) {
    assert_eq!(jt.len(), 3 * n * set.len(), "p x 3n");
    assert_eq!(tcps.len(), n, "one TCP per configuration");
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU was just found to support AVX2, the only requirement of
        // `jacobians_avx2`.
        #[allow(unsafe_code)]
        unsafe {
            jacobians_avx2(model, set, n, sines, jt, tcps)
        };
        return;
    }
    jacobians_body(model, set, n, sines, jt, tcps);
}

/// [`tcp_jacobians_transposed`] compiled for AVX2 (the lanes in one vector; the same operations).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn jacobians_avx2(
    model: &RobotModel,
    set: &ParamSet,
    n: usize,
    sines: impl Fn(usize) -> AngleSines,
    jt: &mut [f64],
    tcps: &mut [Vector3<f64>],
) {
    jacobians_body(model, set, n, sines, jt, tcps);
}

#[inline(always)]
fn jacobians_body(
    model: &RobotModel,
    set: &ParamSet,
    n: usize,
    sines: impl Fn(usize) -> AngleSines,
    jt: &mut [f64],
    tcps: &mut [Vector3<f64>],
) {
    let p = set.len();
    let mut f = Frames::new();
    let mut sums = ComplianceSums::new();
    for first in (0..n).step_by(LANES) {
        forward(model, &padded(n, first, &sines), true, &mut f);
        let len = LANES.min(n - first);
        for l in 0..len {
            tcps[first + l] = Vector3::new(f.tcp_world[0][l], f.tcp_world[1][l], f.tcp_world[2][l]);
        }
        // This chunk's 3 x len columns of jt, each p values.
        let out = &mut jt[3 * first * p..3 * (first + len) * p];
        jacobian(model, &f, set, &mut sums, |c, col| {
            for (l, rows) in out.chunks_exact_mut(3 * p).enumerate() {
                for (i, row) in rows.chunks_exact_mut(p).enumerate() {
                    row[c] = col[i][l];
                }
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    use super::*;
    use crate::robot::KinState;
    use crate::robot::kinematics::{forward, forward_portable};
    use crate::robot::params::ParamId;
    use crate::robot::test_models::{configuration, models};

    /// The batched TCPs equal `forward`'s (and the portable path's) to the bit: the 5 built-in
    /// arms, their rigid forms and 40 models with every link, body, base, tool and gravity number
    /// moved at random (large compliances among them, so that deflections take both branches of
    /// the series), 203 configurations each (a short last chunk), one in four within +-20 rad.
    #[test]
    fn batched_tcps_equal_forward_bit_for_bit() {
        let mut rng = ChaCha8Rng::seed_from_u64(17);
        let models = models(&mut rng);
        let mut large = 0;
        let mut st = KinState::default();
        for model in &models {
            let qs: Vec<Joints> = (0..203).map(|j| configuration(&mut rng, j)).collect();
            let batch = tcps_world(model, &qs);
            let body = tcps_body(model, qs.len(), |k| angle_sines(model, &qs[k]));
            // The angles taken once, ahead (as a pose's targets share them).
            let sines: Vec<AngleSines> = qs.iter().map(|q| angle_sines(model, q)).collect();
            assert_eq!(tcps_world_by(model, sines.len(), |k| sines[k]), batch);
            for (q, (b, p)) in qs.iter().zip(batch.iter().zip(&body)) {
                let expected = forward(model, &mut st, q);
                large += st.tau.iter().zip(&model.data().links).filter(|(t, l)| (l.compliance * *t).abs() >= 1e-3).count();
                let bits = |v: &Vector3<f64>| v.map(f64::to_bits);
                assert_eq!(bits(b), bits(&expected), "{q:?}");
                assert_eq!(bits(p), bits(&forward_portable(model, &mut KinState::default(), q)), "{q:?}");
            }
        }
        assert!(large > 100, "deflections of 1e-3 rad or more: {large}");
    }

    /// The batched Jacobians equal `tcp_jacobian`'s (and the portable path's) to the bit, for every
    /// parameter calsim names (each link parameter of every joint, base and tool): 50 models (see
    /// `test_models`), 101 configurations each (a short last chunk), one in four within +-20 rad.
    #[test]
    fn batched_jacobians_equal_tcp_jacobian_bit_for_bit() {
        use crate::robot::kinematics::{tcp_jacobian, tcp_jacobian_portable};
        let mut rng = ChaCha8Rng::seed_from_u64(23);
        let models = models(&mut rng);
        let set = ParamSet::new(ParamId::all()).unwrap();
        assert_eq!(set.len(), 6 * 6 + 6 + 3, "every link, base and tool parameter");
        let p = set.len();
        let mut st = KinState::default();
        let mut one = vec![Vector3::zeros(); p];
        for model in &models {
            let qs: Vec<Joints> = (0..101).map(|j| configuration(&mut rng, j)).collect();
            let (mut jt, mut tcps) = (vec![0.0; 3 * qs.len() * p], vec![Vector3::zeros(); qs.len()]);
            tcp_jacobians_transposed(model, &set, &qs, &mut jt, &mut tcps);
            let (mut jt_b, mut tcps_b) = (jt.clone(), tcps.clone());
            jacobians_body(model, &set, qs.len(), |k| angle_sines(model, &qs[k]), &mut jt_b, &mut tcps_b);
            // The angles taken once, ahead (as a pose's targets share them).
            let sines: Vec<AngleSines> = qs.iter().map(|q| angle_sines(model, q)).collect();
            let (mut jt_s, mut tcps_s) = (jt.clone(), tcps.clone());
            tcp_jacobians_transposed_by(model, &set, sines.len(), |k| sines[k], &mut jt_s, &mut tcps_s);
            assert_eq!(jt_s.iter().map(|v| v.to_bits()).collect::<Vec<_>>(), jt.iter().map(|v| v.to_bits()).collect::<Vec<_>>());
            assert_eq!(tcps_s, tcps);
            // Column c of configuration n's Jacobian, from the transposed layout.
            let column = |jt: &[f64], n: usize, c: usize| Vector3::from_fn(|i, _| jt[(3 * n + i) * p + c]);
            let bits = |v: &Vector3<f64>| v.map(f64::to_bits);
            for (n, q) in qs.iter().enumerate() {
                let pw = tcp_jacobian(model, &mut st, q, &set, &mut one);
                assert_eq!(bits(&tcps[n]), bits(&pw), "{q:?}");
                assert_eq!(bits(&tcps_b[n]), bits(&pw), "{q:?}");
                let mut portable = vec![Vector3::zeros(); p];
                tcp_jacobian_portable(model, &mut KinState::default(), q, &set, &mut portable);
                for c in 0..p {
                    let name = &set.names()[c];
                    assert_eq!(bits(&column(&jt, n, c)), bits(&one[c]), "{}: column {name} at {q:?}", model.name());
                    assert_eq!(bits(&column(&jt_b, n, c)), bits(&portable[c]), "{}: column {name} at {q:?}", model.name());
                }
            }
        }
    }
}
