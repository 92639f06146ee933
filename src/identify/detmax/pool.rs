//! The pool's identification Jacobians, column-scaled (see [`crate::identify::observability`]),
//! in the layouts DETMAX reads: the stacked matrix, padded rows for the information matrix, and
//! four configurations to a vector ([`Lanes`]).

use nalgebra::DMatrix;

use super::lanes::Lanes;
use crate::identify::observability::scaled_stacked_jacobian;
use crate::robot::{Joints, ParamSet, RobotModel};

/// The pool's identification Jacobians, column-scaled, stacked: rows 3k..3k+3 are configuration k.
#[derive(Clone, Debug)]
pub struct PoolJacobian {
    /// Parameters (columns).
    pub m: usize,
    /// Configurations.
    pub len: usize,
    /// The stacked scaled Jacobian, 3N x m.
    pub j: DMatrix<f64>,
    /// The same rows, row-major, each zero-padded to `stride` (a multiple of 4) for the hot
    /// products of DETMAX.
    pub rows: Vec<f64>,
    /// Padded row length.
    pub stride: usize,
    /// Column scale factors `s_j` (internal units of the parameter per mm).
    pub scale: Vec<f64>,
    /// The same rows laid out for DETMAX's kernels.
    pub lanes: Lanes,
}

impl PoolJacobian {
    /// Evaluates and scales the Jacobians of `qs` at `model` for `set`.
    pub fn new(model: &RobotModel, set: &ParamSet, qs: &[Joints]) -> Self {
        let (j, scale) = scaled_stacked_jacobian(model, set, qs);
        Self::from_scaled(j, scale)
    }

    /// The pool of the scaled stacked Jacobian `j` (rows 3k..3k + 3: configuration k) and its
    /// column scales.
    pub(crate) fn from_scaled(j: DMatrix<f64>, scale: Vec<f64>) -> Self {
        let m = j.ncols();
        let stride = m.div_ceil(4) * 4;
        let mut rows = vec![0.0; j.nrows() * stride];
        for (i, row) in rows.chunks_exact_mut(stride).enumerate() {
            for c in 0..m {
                row[c] = j[(i, c)];
            }
        }
        let lanes = Lanes::new(&j);
        Self { m, len: j.nrows() / 3, j, rows, stride, scale, lanes }
    }

    /// Information matrix `sum_k J_k^T J_k` of the configurations `set`, m x m.
    ///
    /// Every entry is the dot product of two columns of the stacked Jacobian summed as nalgebra's
    /// `tr_mul` sums it (eight interleaved partial sums over blocks of eight rows, combined as
    /// `((a0 + a4) + (a1 + a5)) ...`, then the remaining rows in order), so the matrix is the same
    /// to the bit as `stacked.tr_mul(&stacked)`; the sums run for all entries of a row at once and
    /// vectorise (AVX2 build chosen at run time).
    pub fn information(&self, set: &[usize]) -> DMatrix<f64> {
        let mut out = DMatrix::zeros(self.m, self.m);
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU was just found to support AVX2, the only requirement of
            // `information_avx2`.
            #[allow(unsafe_code)]
            unsafe {
                information_avx2(self, set, out.as_mut_slice())
            };
            return out;
        }
        information_body(self, set, out.as_mut_slice());
        out
    }
}

/// [`PoolJacobian::information`] compiled for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn information_avx2(pool: &PoolJacobian, set: &[usize], out: &mut [f64]) {
    information_body(pool, set, out);
}

/// The information matrix of `set` into `out` (m x m, column-major), in the summation order of
/// nalgebra's dot product: entry (a, b) sums the products of rows 8q + t into partial sum t
/// (separate products and sums, q in order), adds the partial sums as `((0 + (s0 + s4)) + (s1 +
/// s5)) + ...` and then the products of the rows past the last full eight, in order. The entries
/// are computed in tiles of 4 x 4 with b >= a, each summed once and mirrored (the dot product of two
/// columns sums the same products in the same order whichever comes first); the set's rows are
/// gathered first, so that a tile reads them contiguously.
#[inline(always)]
fn information_body(pool: &PoolJacobian, set: &[usize], out: &mut [f64]) {
    let (m, stride) = (pool.m, pool.stride);
    let n = 3 * set.len();
    let mut x = Vec::with_capacity(n * stride);
    for &k in set {
        x.extend_from_slice(&pool.rows[3 * k * stride..3 * (k + 1) * stride]);
    }
    let row = |i: usize| -> &[f64] { &x[i * stride..(i + 1) * stride] };
    let full = n / 8 * 8;
    for a0 in (0..m).step_by(4) {
        for c in (a0..stride).step_by(4) {
            // Entries (a0 + i, c + l).
            let mut res = [[0.0; 4]; 4];
            for t in 0..4 {
                // Partial sums t and t + 4.
                let (mut s, mut u) = ([[0.0; 4]; 4], [[0.0; 4]; 4]);
                for q in (0..full).step_by(8) {
                    let (x1, x2) = (row(q + t), row(q + t + 4));
                    let (c1, c2): (&[f64; 4], &[f64; 4]) = (x1[c..c + 4].try_into().expect("four"), x2[c..c + 4].try_into().expect("four"));
                    for i in 0..4 {
                        let (a1, a2) = (x1[a0 + i], x2[a0 + i]);
                        for l in 0..4 {
                            s[i][l] += a1 * c1[l];
                            u[i][l] += a2 * c2[l];
                        }
                    }
                }
                for i in 0..4 {
                    for l in 0..4 {
                        res[i][l] += s[i][l] + u[i][l];
                    }
                }
            }
            for q in full..n {
                let xq = row(q);
                for i in 0..4 {
                    for l in 0..4 {
                        res[i][l] += xq[a0 + i] * xq[c + l];
                    }
                }
            }
            // Entries (a, b) and (b, a) for b >= a (column-major storage).
            for (i, ri) in res.iter().enumerate() {
                let a = a0 + i;
                for (l, &r) in ri.iter().enumerate() {
                    let b = c + l;
                    if a < m && b >= a && b < m {
                        out[b * m + a] = r;
                        out[a * m + b] = r;
                    }
                }
            }
        }
    }
}

/// A pool of `len` random 3 x m configurations, laid out like [`PoolJacobian::new`]'s, for tests.
#[cfg(test)]
pub(crate) fn random_pool(len: usize, m: usize, rng: &mut rand_chacha::ChaCha8Rng) -> PoolJacobian {
    use rand::RngExt;
    let j = DMatrix::from_fn(3 * len, m, |_, _| rng.random_range(-1.0..1.0));
    PoolJacobian::from_scaled(j, vec![1.0; m])
}

#[cfg(test)]
mod tests {
    use nalgebra::DMatrix;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    use super::random_pool;

    /// The information matrix equals the stacked Jacobian's `tr_mul` bit for bit, for sets whose
    /// row counts are and are not multiples of eight (1, 8, 25 and 120 configurations of a pool of
    /// 150, 31 parameters; 7 parameters for an unpadded-multiple stride).
    #[test]
    fn information_equals_tr_mul_bit_for_bit() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for m in [31, 7] {
            let len = 150;
            let pool = random_pool(len, m, &mut rng);
            for n in [1, 8, 25, 120] {
                let set: Vec<usize> = rand::seq::index::sample(&mut rng, len, n).into_vec();
                let mut stacked = DMatrix::zeros(3 * n, m);
                for (i, &k) in set.iter().enumerate() {
                    stacked.rows_mut(3 * i, 3).copy_from(&pool.j.rows(3 * k, 3));
                }
                assert_eq!(pool.information(&set), stacked.tr_mul(&stacked), "m = {m}, n = {n}");
            }
        }
    }
}
