//! The TCPs of many configurations of one model: forward kinematics with gravity torques and
//! compliance for four configurations side by side, a configuration per lane.
//!
//! Each lane performs exactly the operations of [`super::kinematics::forward_portable`] on its
//! configuration, in the same order: nalgebra's products of a 3 x 3 matrix and a vector
//! (`(a_0 x_0 + a_1 x_1) + a_2 x_2`, column by column), its cross and dot products, separate
//! multiplies and adds (no fused operations), `sincos` of each angle by the same library call, the
//! same short series for small deflections. So every TCP is the same to the bit as [`forward`]'s
//! (a test compares them over 50 models); the lanes only share the model's constants and the
//! loop. The validation of every identified model takes its TCPs here: 506 poses, one model.
//!
//! [`forward`]: super::kinematics::forward

use nalgebra::{Matrix3, Vector3};

use super::model::{JOINTS, Joints, RobotModel};

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

/// The frames of the chain from the sines and cosines of the joint angles (`kinematics::chain`):
/// the last one, and every one into `frames` when given.
#[inline(always)]
fn chain(model: &RobotModel, sc: &[(L, L); JOINTS], mut frames: Option<(&mut [M; JOINTS + 1], &mut [V; JOINTS + 1])>) -> (M, V) {
    let mut r: M = [[splat(0.0); 3]; 3];
    for (j, col) in r.iter_mut().enumerate() {
        col[j] = splat(1.0);
    }
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

/// The TCPs in {W} (mm) of four configurations.
#[inline(always)]
fn four(model: &RobotModel, q: &[Joints; LANES]) -> [Vector3<f64>; LANES] {
    let data = model.data();
    let links = &data.links;
    let mut sc0 = [(splat(0.0), splat(1.0)); JOINTS];
    for (i, sci) in sc0.iter_mut().enumerate() {
        for l in 0..LANES {
            (sci.0[l], sci.1[l]) = (q[l][i] + links[i].theta_offset).sin_cos();
        }
    }
    let mut rot0 = [[[splat(0.0); 3]; 3]; JOINTS + 1];
    let mut org0 = [[splat(0.0); 3]; JOINTS + 1];
    let (r6, o6) = chain(model, &sc0, Some((&mut rot0, &mut org0)));
    let (rot, org) = if model.rigid {
        (r6, o6)
    } else {
        // The gravity pass (`statics::gravity_pass`): holding torques at the undeflected frames.
        let g = data.gravity_base;
        let (gx, gy, gz) = (splat(g.x), splat(g.y), splat(g.z));
        let payload = &data.payload;
        let mut s = vscale(&vadd(&o6, &times(&r6, &payload.com_mm)), splat(payload.mass_kg));
        let mut m = payload.mass_kg;
        let mut tau = [splat(0.0); JOINTS];
        for k in (1..=JOINTS).rev() {
            let body = &data.links_inertial[k - 1];
            s = vadd(&s, &vscale(&vadd(&org0[k], &times(&rot0[k], &body.com_mm)), splat(body.mass_kg)));
            m += body.mass_kg;
            let mv = splat(m);
            let r = [sub(s[0], mul(org0[k][0], mv)), sub(s[1], mul(org0[k][1], mv)), sub(s[2], mul(org0[k][2], mv))];
            // -z . (r x g) * 1e-3, nalgebra's cross and dot.
            let cross = [sub(mul(r[1], gz), mul(r[2], gy)), sub(mul(r[2], gx), mul(r[0], gz)), sub(mul(r[0], gy), mul(r[1], gx))];
            let z = &rot0[k][2];
            let dot = add(add(mul(z[0], cross[0]), mul(z[1], cross[1])), mul(z[2], cross[2]));
            tau[k - 1] = dot.map(|d| -d * 1e-3);
        }
        // The deflected angles' sines and cosines (`kinematics::deflected_sincos`).
        // The same operations as `kinematics::sincos_shifted`, its series in every lane and
        // `sin_cos` of the deflection where it is 1e-3 rad or more.
        let mut sc = sc0;
        for (i, sci) in sc.iter_mut().enumerate() {
            let delta = mul(splat(links[i].compliance), tau[i]);
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
        chain(model, &sc, None)
    };
    let tcp_base = vadd(&org, &times(&rot, &data.flange_tcp_mm));
    let world =
        vadd(&[splat(model.base_pos.x), splat(model.base_pos.y), splat(model.base_pos.z)], &const_times(&model.base_rot, &tcp_base));
    let mut out = [Vector3::zeros(); LANES];
    for (l, p) in out.iter_mut().enumerate() {
        *p = Vector3::new(world[0][l], world[1][l], world[2][l]);
    }
    out
}

/// The TCP in {W} (mm) of every configuration of `qs` at `model`, in order: the same to the bit as
/// [`super::kinematics::forward`] of each.
pub fn tcps_world<'a>(model: &RobotModel, qs: impl IntoIterator<Item = &'a Joints>) -> Vec<Vector3<f64>> {
    let qs: Vec<&Joints> = qs.into_iter().collect();
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU was just found to support AVX2, the only requirement of `tcps_avx2`.
        #[allow(unsafe_code)]
        return unsafe { tcps_avx2(model, &qs) };
    }
    tcps_body(model, &qs)
}

/// [`tcps_world`] compiled for AVX2 (the lanes in one vector; the same operations).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn tcps_avx2(model: &RobotModel, qs: &[&Joints]) -> Vec<Vector3<f64>> {
    tcps_body(model, qs)
}

#[inline(always)]
fn tcps_body(model: &RobotModel, qs: &[&Joints]) -> Vec<Vector3<f64>> {
    let mut out = Vec::with_capacity(qs.len());
    for chunk in qs.chunks(LANES) {
        // A short last chunk repeats its last configuration (computed, not returned).
        let q: [Joints; LANES] = std::array::from_fn(|l| *chunk[l.min(chunk.len() - 1)]);
        out.extend_from_slice(&four(model, &q)[..chunk.len()]);
    }
    out
}

#[cfg(test)]
mod tests {
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;
    use crate::robot::KinState;
    use crate::robot::kinematics::{forward, forward_portable};

    /// The batched TCPs equal `forward`'s (and the portable path's) to the bit: the 5 built-in
    /// arms, their rigid forms and 40 models with every link, body, base, tool and gravity number
    /// moved at random (large compliances among them, so that deflections take both branches of
    /// the series), 203 configurations each (a short last chunk), one in four within +-20 rad.
    #[test]
    fn batched_tcps_equal_forward_bit_for_bit() {
        let mut rng = ChaCha8Rng::seed_from_u64(17);
        let models = crate::robot::test_models::models(&mut rng);
        let mut large = 0;
        let mut st = KinState::default();
        for model in &models {
            let qs: Vec<Joints> = (0..203)
                .map(|j| {
                    let wide = if j % 4 == 0 { 20.0 } else { 3.2 };
                    std::array::from_fn(|_| rng.random_range(-wide..wide))
                })
                .collect();
            let batch = tcps_world(model, &qs);
            let body = tcps_body(model, &qs.iter().collect::<Vec<_>>());
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
}
