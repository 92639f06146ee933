//! Identification of the beams of an SPMS head (paper sections 3.3 and 4) from m poses of the head
//! around a fixed reference sphere, each pose known through the measurement frame `T_i`
//! (tracker_from_head) and giving K readings.
//!
//! Two parametrisations of the same residuals `|T_i (P_k + gamma_k L_ki) - P_Bw| - R` (eq. 14):
//! - [`Form::Paper`]: the paper's 6K + 3 unknowns, `P_k` and `gamma_k` free (gamma is not kept
//!   unit: its norm acts as a gain of the reading), plus the sphere centre `P_Bw`;
//! - [`Form::Minimal`]: 5K + 3 unknowns, `P_k` (3: the line's 2 and the reading offset along it)
//!   and `gamma_k` as two angles (unit by construction), plus `P_Bw`.
//!
//! Solvers: Levenberg-Marquardt with the damping rule of the paper (eqs. 17-23: `lambda_0 = tau
//! max diag(J^T J)`, gain ratio `rho`, `lambda *= max(1/3, 1 - (2 rho - 1)^3)` on success, `lambda
//! *= nu, nu *= 2` on failure), and particle swarm optimisation (eqs. 15-16) for a start.

use crate::identify::damping::Damping;
use nalgebra::{DMatrix, DVector, Isometry3, Point3, Vector3};
use rand::RngExt;

use super::Beam;

/// The parametrisation of the beams.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Form {
    /// The paper's `P_k`, `gamma_k` (6 per beam), sphere centre.
    Paper,
    /// `P_k` and two direction angles (5 per beam), sphere centre.
    Minimal,
}

impl Form {
    /// Label for tables (`paper`, `minimal`), as a scenario names it.
    pub fn label(self) -> &'static str {
        match self {
            Self::Paper => "paper",
            Self::Minimal => "minimal",
        }
    }

    /// Unknowns per beam.
    pub fn per_beam(self) -> usize {
        match self {
            Self::Paper => 6,
            Self::Minimal => 5,
        }
    }

    /// Number of unknowns for `k` beams.
    pub fn len(self, k: usize) -> usize {
        self.per_beam() * k + 3
    }

    /// Packs beams (and the sphere centre) into a parameter vector.
    pub fn pack(self, beams: &[Beam], centre: &Vector3<f64>) -> DVector<f64> {
        let mut x = Vec::with_capacity(self.len(beams.len()));
        for b in beams {
            x.extend_from_slice(b.p.as_slice());
            let g = b.dir.into_inner();
            match self {
                Self::Paper => x.extend_from_slice(g.as_slice()),
                Self::Minimal => x.extend_from_slice(&[g.z.clamp(-1.0, 1.0).acos(), g.y.atan2(g.x)]),
            }
        }
        x.extend_from_slice(centre.as_slice());
        DVector::from_vec(x)
    }

    /// The beam `k` of a parameter vector: origin and (for the paper's form, unnormalised) direction.
    pub fn beam(self, x: &DVector<f64>, k: usize) -> (Vector3<f64>, Vector3<f64>) {
        let o = self.per_beam() * k;
        let p = Vector3::new(x[o], x[o + 1], x[o + 2]);
        let g = match self {
            Self::Paper => Vector3::new(x[o + 3], x[o + 4], x[o + 5]),
            Self::Minimal => {
                let (t, f) = (x[o + 3], x[o + 4]);
                Vector3::new(t.sin() * f.cos(), t.sin() * f.sin(), t.cos())
            }
        };
        (p, g)
    }

    /// The sphere centre of a parameter vector.
    pub fn centre(self, x: &DVector<f64>) -> Vector3<f64> {
        let n = x.len();
        Vector3::new(x[n - 3], x[n - 2], x[n - 1])
    }

    /// Unpacks the beams with unit directions. In the paper's form a direction that is not unit
    /// also scales the readings: that gain is reported by [`Form::gains`], and a reading `L` of
    /// beam k measures the point `p + dir * gains[k] * L`.
    pub fn unpack(self, x: &DVector<f64>, k: usize) -> Vec<Beam> {
        (0..k)
            .map(|j| {
                let (p, g) = self.beam(x, j);
                Beam { p, dir: nalgebra::Unit::new_normalize(g) }
            })
            .collect()
    }

    /// Norms of the directions (1 for the minimal form): the reading gain the paper's form implies.
    pub fn gains(self, x: &DVector<f64>, k: usize) -> Vec<f64> {
        (0..k).map(|j| self.beam(x, j).1.norm()).collect()
    }
}

/// The data of a beam identification: per pose, `tracker_from_head` and the K readings.
#[derive(Clone, Debug, Default)]
pub struct BeamData {
    /// Measurement frames, one per pose.
    pub frames: Vec<Isometry3<f64>>,
    /// Readings per pose, mm.
    pub readings: Vec<Vec<f64>>,
    /// Reference sphere radius, mm.
    pub radius_mm: f64,
}

impl BeamData {
    /// Residuals `|T_i (P_k + gamma_k L_ki) - P_Bw| - R`, pose-major.
    pub fn residuals(&self, form: Form, x: &DVector<f64>) -> DVector<f64> {
        let mut scratch = CostScratch::default();
        self.fill_residuals(form, x, &mut scratch);
        DVector::from_vec(scratch.r)
    }

    /// The residuals into `scratch.r` (no allocation once the scratch has grown).
    fn fill_residuals(&self, form: Form, x: &DVector<f64>, scratch: &mut CostScratch) {
        let k = self.readings.first().map(|r| r.len()).unwrap_or(0);
        let c = form.centre(x);
        scratch.beams.clear();
        scratch.beams.extend((0..k).map(|j| form.beam(x, j)));
        scratch.r.clear();
        for (t, ls) in self.frames.iter().zip(&self.readings) {
            for ((p, g), l) in scratch.beams.iter().zip(ls) {
                let f = t * Point3::from(p + g * *l);
                scratch.r.push((f.coords - c).norm() - self.radius_mm);
            }
        }
    }

    /// Sum of squared residuals.
    pub fn cost(&self, form: Form, x: &DVector<f64>) -> f64 {
        self.cost_with(form, x, &mut CostScratch::default())
    }

    /// Sum of squared residuals with buffers of the caller's.
    fn cost_with(&self, form: Form, x: &DVector<f64>, scratch: &mut CostScratch) -> f64 {
        self.fill_residuals(form, x, scratch);
        nalgebra::DVectorView::from_slice(&scratch.r, scratch.r.len()).norm_squared()
    }

    /// Jacobian of the residuals by central differences (step 1e-6 of the parameter scale).
    pub fn jacobian(&self, form: Form, x: &DVector<f64>) -> DMatrix<f64> {
        let r0 = self.residuals(form, x);
        let mut j = DMatrix::zeros(r0.len(), x.len());
        let mut xp = x.clone();
        for c in 0..x.len() {
            let h = 1e-6 * x[c].abs().max(1.0);
            xp[c] = x[c] + h;
            let rp = self.residuals(form, &xp);
            xp[c] = x[c] - h;
            let rm = self.residuals(form, &xp);
            xp[c] = x[c];
            j.set_column(c, &((rp - rm) / (2.0 * h)));
        }
        j
    }
}

/// The data of a beam identification laid out for the particle swarm's many cost evaluations:
/// structure of arrays over the poses (frame quaternion and translation, each beam's readings),
/// padded to a multiple of eight poses with identity frames and zero readings.
struct Packed {
    poses: usize,
    beams: usize,
    /// Quaternion (x, y, z, w), then translation (x, y, z) of `tracker_from_head`, per pose.
    frame: [Vec<f64>; 7],
    /// Readings per beam, per pose.
    readings: Vec<Vec<f64>>,
    radius_mm: f64,
}

impl Packed {
    fn new(data: &BeamData) -> Self {
        let poses = data.frames.len();
        let beams = data.readings.first().map(|r| r.len()).unwrap_or(0);
        let padded = poses.div_ceil(8) * 8;
        let mut frame: [Vec<f64>; 7] = std::array::from_fn(|i| vec![if i == 3 { 1.0 } else { 0.0 }; padded]);
        for (j, t) in data.frames.iter().enumerate() {
            let q = t.rotation.quaternion();
            let v = t.translation.vector;
            for (i, x) in [q.i, q.j, q.k, q.w, v.x, v.y, v.z].into_iter().enumerate() {
                frame[i][j] = x;
            }
        }
        let readings = (0..beams)
            .map(|b| {
                let mut l = vec![0.0; padded];
                for (j, ls) in data.readings.iter().enumerate() {
                    l[j] = ls.get(b).copied().unwrap_or(f64::NAN);
                }
                l
            })
            .collect();
        Self { poses, beams, frame, readings, radius_mm: data.radius_mm }
    }

    /// `BeamData::cost`, the same numbers.
    fn cost(&self, form: Form, x: &DVector<f64>, scratch: &mut CostScratch) -> f64 {
        let c = form.centre(x);
        scratch.beams.clear();
        scratch.beams.extend((0..self.beams).map(|j| form.beam(x, j)));
        scratch.r.clear();
        scratch.r.resize(self.poses * self.beams, 0.0);
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx512f") {
            // SAFETY: the CPU was just found to support AVX-512F, the only requirement of
            // `residuals_avx512`.
            #[allow(unsafe_code)]
            unsafe {
                residuals_avx512(self, &scratch.beams, &c, &mut scratch.r)
            };
            return nalgebra::DVectorView::from_slice(&scratch.r, scratch.r.len()).norm_squared();
        }
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU was just found to support AVX2, the only requirement of
            // `residuals_avx2`.
            #[allow(unsafe_code)]
            unsafe {
                residuals_avx2(self, &scratch.beams, &c, &mut scratch.r)
            };
            return nalgebra::DVectorView::from_slice(&scratch.r, scratch.r.len()).norm_squared();
        }
        residuals_by_lanes(self, &scratch.beams, &c, &mut scratch.r);
        nalgebra::DVectorView::from_slice(&scratch.r, scratch.r.len()).norm_squared()
    }
}

/// A residual kernel over `$lanes` poses per vector with the `$feature` intrinsics `$p*`: separate
/// multiplies and adds (no fused multiply-add) and a correctly rounded square root, so each lane is
/// the number of `residuals_by_lanes`.
macro_rules! residuals_simd {
    ($(#[$doc:meta])* $name:ident, $feature:literal, $lanes:literal, $vector:ident,
     $load:ident, $store:ident, $set1:ident, $add:ident, $mul:ident, $sub:ident, $sqrt:ident) => {
        $(#[$doc])*
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = $feature)]
        fn $name(pk: &Packed, beams: &[(Vector3<f64>, Vector3<f64>)], c: &Vector3<f64>, r: &mut [f64]) {
            use std::arch::x86_64::{$vector, $add, $load, $mul, $set1, $sqrt, $store, $sub};
            let k = pk.beams;
            let padded = pk.poses.div_ceil($lanes) * $lanes;
            assert!(pk.frame.iter().chain(&pk.readings).all(|v| v.len() >= padded) && r.len() >= pk.poses * k);
            let (two, radius) = ($set1(2.0), $set1(pk.radius_mm));
            let (cx, cy, cz) = ($set1(c.x), $set1(c.y), $set1(c.z));
            for (b, ((p, g), ls)) in beams.iter().zip(&pk.readings).enumerate() {
                let (px, py, pz) = ($set1(p.x), $set1(p.y), $set1(p.z));
                let (gx, gy, gz) = ($set1(g.x), $set1(g.y), $set1(g.z));
                for j0 in (0..pk.poses).step_by($lanes) {
                    // SAFETY: j0 + $lanes <= padded, the length of every array (asserted above).
                    #[allow(unsafe_code)]
                    let (f, l): ([$vector; 7], $vector) = unsafe {
                        let f = [0, 1, 2, 3, 4, 5, 6].map(|i| $load(pk.frame[i].as_ptr().add(j0)));
                        (f, $load(ls.as_ptr().add(j0)))
                    };
                    let [ax, ay, az, w, tx, ty, tz] = f;
                    let (add, mul, sub) = ($add, $mul, $sub);
                    let (vx, vy, vz) = (add(px, mul(gx, l)), add(py, mul(gy, l)), add(pz, mul(gz, l)));
                    let t0 = mul(sub(mul(ay, vz), mul(az, vy)), two);
                    let t1 = mul(sub(mul(az, vx), mul(ax, vz)), two);
                    let t2 = mul(sub(mul(ax, vy), mul(ay, vx)), two);
                    let c0 = sub(mul(ay, t2), mul(az, t1));
                    let c1 = sub(mul(az, t0), mul(ax, t2));
                    let c2 = sub(mul(ax, t1), mul(ay, t0));
                    let dx = sub(add(add(add(mul(t0, w), c0), vx), tx), cx);
                    let dy = sub(add(add(add(mul(t1, w), c1), vy), ty), cy);
                    let dz = sub(add(add(add(mul(t2, w), c2), vz), tz), cz);
                    let norm = $sqrt(add(add(mul(dx, dx), mul(dy, dy)), mul(dz, dz)));
                    let mut out = [0.0; $lanes];
                    // SAFETY: `out` holds $lanes values.
                    #[allow(unsafe_code)]
                    unsafe {
                        $store(out.as_mut_ptr(), sub(norm, radius))
                    };
                    for (i, o) in out.into_iter().enumerate().take(pk.poses - j0) {
                        r[(j0 + i) * k + b] = o;
                    }
                }
            }
        }
    };
}

residuals_simd!(
    /// `residuals_by_lanes` with AVX-512 vectors over eight poses.
    residuals_avx512, "avx512f", 8, __m512d,
    _mm512_loadu_pd, _mm512_storeu_pd, _mm512_set1_pd, _mm512_add_pd, _mm512_mul_pd, _mm512_sub_pd, _mm512_sqrt_pd
);
residuals_simd!(
    /// `residuals_by_lanes` with AVX2 vectors over four poses.
    residuals_avx2, "avx2", 4, __m256d,
    _mm256_loadu_pd, _mm256_storeu_pd, _mm256_set1_pd, _mm256_add_pd, _mm256_mul_pd, _mm256_sub_pd, _mm256_sqrt_pd
);

/// The residuals of `BeamData::residuals`, each the same operations in the same order as
/// nalgebra's `Isometry3 * Point3` (`t = 2 q_v x v`, `v' = (t w + q_v x t) + v`, plus the
/// translation) and `norm`.
fn residuals_by_lanes(pk: &Packed, beams: &[(Vector3<f64>, Vector3<f64>)], c: &Vector3<f64>, r: &mut [f64]) {
    let [qx, qy, qz, qw, tx, ty, tz] = &pk.frame;
    let k = pk.beams;
    for (b, ((p, g), ls)) in beams.iter().zip(&pk.readings).enumerate() {
        for j in 0..pk.poses {
            let l = ls[j];
            let (vx, vy, vz) = (p.x + g.x * l, p.y + g.y * l, p.z + g.z * l);
            let (ax, ay, az) = (qx[j], qy[j], qz[j]);
            let t0 = (ay * vz - az * vy) * 2.0;
            let t1 = (az * vx - ax * vz) * 2.0;
            let t2 = (ax * vy - ay * vx) * 2.0;
            let c0 = ay * t2 - az * t1;
            let c1 = az * t0 - ax * t2;
            let c2 = ax * t1 - ay * t0;
            let fx = ((t0 * qw[j] + c0) + vx) + tx[j];
            let fy = ((t1 * qw[j] + c1) + vy) + ty[j];
            let fz = ((t2 * qw[j] + c2) + vz) + tz[j];
            let (dx, dy, dz) = (fx - c.x, fy - c.y, fz - c.z);
            r[j * k + b] = ((dx * dx + dy * dy) + dz * dz).sqrt() - pk.radius_mm;
        }
    }
}

/// Buffers of one cost evaluation.
#[derive(Default)]
struct CostScratch {
    beams: Vec<(Vector3<f64>, Vector3<f64>)>,
    r: Vec<f64>,
}

/// What a solver reached.
#[derive(Clone, Debug)]
pub struct Solution {
    /// Parameters.
    pub x: DVector<f64>,
    /// Iterations made.
    pub iterations: usize,
    /// Root mean square of the residuals, mm.
    pub rms_mm: f64,
    /// Singular values of the Jacobian at the solution (LM only; empty for PSO).
    pub singular_values: Vec<f64>,
}

/// Levenberg-Marquardt from `x0` with the paper's damping rule; `tau` sets `lambda_0`.
pub fn levenberg_marquardt(data: &BeamData, form: Form, x0: &DVector<f64>, tau: f64, max_iterations: usize) -> Solution {
    let mut x = x0.clone();
    let mut r = data.residuals(form, &x);
    let mut j = data.jacobian(form, &x);
    let mut a = j.transpose() * &j;
    let mut g = j.transpose() * &r;
    let mut damping = Damping::start(tau, a.diagonal().max());
    let mut iterations = 0;
    while iterations < max_iterations {
        iterations += 1;
        let mut damped = a.clone();
        for i in 0..damped.nrows() {
            damped[(i, i)] += damping.mu;
        }
        let Some(step) = damped.cholesky().map(|c| c.solve(&(-&g))) else {
            damping.reject();
            continue;
        };
        if step.norm() <= 1e-12 * (x.norm() + 1e-12) {
            break;
        }
        let xn = &x + &step;
        let rn = data.residuals(form, &xn);
        // Gain ratio: actual over predicted decrease (eq. 21).
        let predicted = step.dot(&(damping.mu * &step - &g)) / 2.0;
        let rho = (r.norm_squared() - rn.norm_squared()) / 2.0 / predicted.max(f64::MIN_POSITIVE);
        if damping.update(rho) {
            x = xn;
            r = rn;
            j = data.jacobian(form, &x);
            a = j.transpose() * &j;
            g = j.transpose() * &r;
            if g.amax() < 1e-14 {
                break;
            }
        }
    }
    let singular_values = crate::numeric::svd(j.clone(), false, false).map(|s| s.singular_values.as_slice().to_vec()).unwrap_or_default();
    Solution { rms_mm: (r.norm_squared() / r.len().max(1) as f64).sqrt(), x, iterations, singular_values }
}

/// Options of the particle swarm (paper section 4.1).
#[derive(Clone, Debug)]
pub struct PsoOptions {
    /// Particles (5000 in the paper).
    pub population: usize,
    /// Iterations.
    pub iterations: usize,
    /// Cognitive factor (2 in the paper).
    pub c1: f64,
    /// Social factor (2 in the paper).
    pub c2: f64,
    /// Inertia at the first iteration (0.9 in the paper; eq. 16).
    pub w_max: f64,
    /// Inertia at the last iteration (0.4 in the paper).
    pub w_min: f64,
}

impl Default for PsoOptions {
    fn default() -> Self {
        Self { population: 5000, iterations: 100, c1: 2.0, c2: 2.0, w_max: 0.9, w_min: 0.4 }
    }
}

/// Particle swarm over the box `centre +- half_width` (eq. 15), inertia `w_n = w_max - (w_max -
/// w_min) n^2 / g^2` (eq. 16); velocities clamped to the box width.
///
/// The swarm is asynchronous: particle p moves towards the global best as it stands after particle
/// p - 1. Its particles are still moved and evaluated in parallel, speculatively: a chunk moves
/// towards the current global best and is then taken in order up to the first particle that
/// improves it, and the rest of the chunk is moved again from there. The random factors are drawn
/// up front, in parallel from their places in the stream (each factor takes two words of it), so
/// the result is the sequential swarm's for any thread count.
pub fn pso(
    data: &BeamData,
    form: Form,
    centre: &DVector<f64>,
    half_width: &DVector<f64>,
    opts: &PsoOptions,
    rng: &mut rand_chacha::ChaCha8Rng,
) -> Solution {
    use rayon::prelude::*;
    /// Particles moved together before the global best is looked at again.
    const CHUNK: usize = 256;
    let d = centre.len();
    let population = opts.population;
    let mut xs: Vec<DVector<f64>> =
        (0..population).map(|_| DVector::from_fn(d, |i, _| centre[i] + half_width[i] * rng.random_range(-1.0..=1.0))).collect();
    let mut vs: Vec<DVector<f64>> = (0..population).map(|_| DVector::zeros(d)).collect();
    let mut pbest = xs.clone();
    let packed = Packed::new(data);
    let mut pcost: Vec<f64> = xs.par_iter().map_init(CostScratch::default, |sc, x| packed.cost(form, x, sc)).collect();
    let first = pcost.iter().enumerate().min_by(|a, b| a.1.total_cmp(b.1)).map_or(0, |(i, _)| i);
    let mut gbest = pbest[first].clone();
    let mut gcost = pcost[first];
    let g2 = (opts.iterations.max(1) as f64).powi(2);
    let mut factors = vec![(0.0, 0.0); population * d];
    for n in 0..opts.iterations {
        let w = opts.w_max - (opts.w_max - opts.w_min) * (n as f64).powi(2) / g2;
        // (r1, r2) of particle p, dimension i at p d + i: the pairs drawn in that order, each pair
        // four words of the stream, so a block of them starts four words per pair further on.
        let base = rng.get_word_pos();
        factors.par_chunks_mut(CHUNK * d).enumerate().for_each(|(b, block)| {
            let mut r = rng.clone();
            r.set_word_pos(base + 4 * (b * CHUNK * d) as u128);
            block.iter_mut().for_each(|f| *f = (r.random(), r.random()));
        });
        rng.set_word_pos(base + 4 * (population * d) as u128);
        let mut p0 = 0;
        while p0 < population {
            let end = (p0 + CHUNK).min(population);
            let gb = &gbest;
            let moved: Vec<(DVector<f64>, DVector<f64>, f64)> = (p0..end)
                .into_par_iter()
                .map_init(CostScratch::default, |sc, p| {
                    let (mut x, mut v) = (xs[p].clone(), vs[p].clone());
                    for i in 0..d {
                        let (r1, r2) = factors[p * d + i];
                        let vi = w * v[i] + opts.c1 * r1 * (pbest[p][i] - x[i]) + opts.c2 * r2 * (gb[i] - x[i]);
                        v[i] = vi.clamp(-2.0 * half_width[i], 2.0 * half_width[i]);
                        x[i] += v[i];
                    }
                    let c = packed.cost(form, &x, sc);
                    (x, v, c)
                })
                .collect();
            p0 = end;
            for (p, (x, v, c)) in (p0 - moved.len()..).zip(moved) {
                xs[p] = x;
                vs[p] = v;
                if c < pcost[p] {
                    pcost[p] = c;
                    pbest[p] = xs[p].clone();
                    if c < gcost {
                        gcost = c;
                        gbest = xs[p].clone();
                        // The particles after p moved towards the old global best: move them again.
                        p0 = p + 1;
                        break;
                    }
                }
            }
        }
    }
    let n = data.frames.len() * data.readings.first().map(|r| r.len()).unwrap_or(0);
    Solution { x: gbest, iterations: opts.iterations, rms_mm: (gcost / n.max(1) as f64).sqrt(), singular_values: Vec::new() }
}

#[cfg(test)]
mod tests {
    use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
    use rand::{Rng, RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;

    /// Factor pairs drawn from their word positions in the stream are the pairs drawn one after
    /// another, and the stream continues where sequential draws leave it (1,000 pairs in blocks of
    /// 96, from a stream one word in).
    #[test]
    fn factors_from_word_positions_are_the_sequential_draws() {
        let mut seq = ChaCha8Rng::seed_from_u64(9);
        let _ = seq.next_u32();
        let mut par = seq.clone();
        let want: Vec<(f64, f64)> = (0..1000).map(|_| (seq.random(), seq.random())).collect();
        let base = par.get_word_pos();
        let mut got = vec![(0.0, 0.0); 1000];
        for (b, block) in got.chunks_mut(96).enumerate() {
            let mut r = par.clone();
            r.set_word_pos(base + 4 * (b * 96) as u128);
            block.iter_mut().for_each(|f| *f = (r.random(), r.random()));
        }
        par.set_word_pos(base + 4 * 1000);
        assert_eq!(got, want);
        assert_eq!(par.next_u64(), seq.next_u64());
    }

    /// The packed cost is `BeamData::cost` to the bit, through every path this CPU has (AVX-512,
    /// AVX2, portable): 23 poses (not a multiple of four or eight), 5 beams, 50 random parameter
    /// vectors, both forms.
    #[test]
    fn packed_cost_is_the_cost_to_the_bit() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut v = || Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
        let frames: Vec<Isometry3<f64>> =
            (0..23).map(|_| Isometry3::from_parts(Translation3::from(v() * 500.0), UnitQuaternion::from_scaled_axis(v() * 3.0))).collect();
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let readings: Vec<Vec<f64>> = (0..23).map(|_| (0..5).map(|_| rng.random_range(20.0..80.0)).collect()).collect();
        let data = BeamData { frames, readings, radius_mm: 12.7 };
        let packed = Packed::new(&data);
        let mut sc = CostScratch::default();
        for form in [Form::Paper, Form::Minimal] {
            let n = form.per_beam() * 5 + 3;
            for _ in 0..50 {
                let x = DVector::from_fn(n, |_, _| rng.random_range(-100.0..100.0));
                let want = data.cost(form, &x);
                assert_eq!(packed.cost(form, &x, &mut sc).to_bits(), want.to_bits());
                let c = form.centre(&x);
                let beams: Vec<_> = (0..5).map(|j| form.beam(&x, j)).collect();
                let mut r = vec![0.0; 23 * 5];
                residuals_by_lanes(&packed, &beams, &c, &mut r);
                assert_eq!(nalgebra::DVectorView::from_slice(&r, r.len()).norm_squared().to_bits(), want.to_bits());
                #[cfg(target_arch = "x86_64")]
                if std::arch::is_x86_feature_detected!("avx2") {
                    let mut r2 = vec![0.0; 23 * 5];
                    // SAFETY: the CPU supports AVX2 (checked).
                    #[allow(unsafe_code)]
                    unsafe {
                        residuals_avx2(&packed, &beams, &c, &mut r2)
                    };
                    assert_eq!(r2, r);
                }
            }
        }
    }
}
