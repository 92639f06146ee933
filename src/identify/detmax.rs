//! DETMAX (Mitchell 1974): choose n configurations of a pool that maximise the determinant of the
//! information matrix `M = sum J_k^T J_k`, i.e. the observability index O1 at fixed n.
//!
//! From a random n-point design, an *excursion* of length k adds the k best configurations one by
//! one, then removes the k worst (or removes first, then adds); it is kept when the n-point design
//! it returns to has a larger determinant, after which k starts again at 1, and otherwise k grows
//! up to a cap. "Best" to add is the configuration that raises det M the most, "worst" to remove
//! the one whose removal lowers it the least.
//!
//! Rank-3 updates: for every pool configuration the 3 x 3 matrix `D_k = J_k M^-1 J_k^T` is kept, so
//! `det(M +- J_k^T J_k) = det M det(I +- D_k)` scores each candidate without a factorisation.
//! Adding or removing a configuration a updates `M^-1` by Woodbury with `U = M^-1 J_a^T` and every
//! `D_k` by `-+ (J_k U) (I +- D_a)^-1 (J_k U)^T`: O(N m) per step instead of an SVD per candidate.

use nalgebra::{DMatrix, Matrix3};
use rand::Rng;
use rand::seq::index::sample;

use super::observability::PoolJacobian;

/// Settings of the exchange.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DetmaxOptions {
    /// Longest excursion tried before stopping.
    pub max_excursion: usize,
    /// Cap on accepted excursions.
    pub max_improvements: usize,
    /// Random starts tried when a start design is singular.
    pub max_starts: usize,
}

impl Default for DetmaxOptions {
    fn default() -> Self {
        Self { max_excursion: 3, max_improvements: 10_000, max_starts: 100 }
    }
}

/// A DETMAX design.
#[derive(Clone, Debug, PartialEq)]
pub struct Design {
    /// Chosen pool indices, ascending.
    pub selection: Vec<usize>,
    /// O1 after the start and after every accepted excursion (never decreasing).
    pub o1_history: Vec<f64>,
    /// Additions and removals made, kept or not.
    pub steps: usize,
}

/// Why no design was found.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum DetmaxError {
    /// n is outside 1..=pool size, or too small for the parameters.
    #[error("cannot choose {n} configurations from a pool of {pool} for {m} parameters")]
    Size {
        /// Requested size.
        n: usize,
        /// Pool size.
        pool: usize,
        /// Parameters.
        m: usize,
    },
    /// Every random start was singular.
    #[error("no non-singular start design in {0} tries")]
    Singular(usize),
}

#[derive(Clone)]
struct State<'a> {
    pool: &'a PoolJacobian,
    /// `M^-1`.
    minv: DMatrix<f64>,
    logdet: f64,
    /// `D_k = J_k M^-1 J_k^T` for every pool configuration.
    d: Vec<Matrix3<f64>>,
    member: Vec<bool>,
    size: usize,
}

/// Buffers reused by every update.
struct Scratch {
    /// `U = M^-1 J_a^T`, m x 3.
    u: DMatrix<f64>,
    /// `U W`, m x 3.
    v: DMatrix<f64>,
    /// The columns of U, zero-padded to the pool's stride.
    u_cols: [Vec<f64>; 3],
    /// `J_pool U`, one row of three per pool row.
    p: Vec<[f64; 3]>,
}

impl Scratch {
    fn new(pool: &PoolJacobian) -> Self {
        Self {
            u: DMatrix::zeros(pool.m, 3),
            v: DMatrix::zeros(pool.m, 3),
            u_cols: std::array::from_fn(|_| vec![0.0; pool.stride]),
            p: vec![[0.0; 3]; 3 * pool.len],
        }
    }
}

/// `out[i] = row_i . (u0, u1, u2)` for every padded row of `rows`: the product J U, written so
/// that it vectorises (nalgebra's GEMM takes a scalar path when a dimension is below 6).
fn rows_times_columns(rows: &[f64], stride: usize, u: &[Vec<f64>; 3], out: &mut [[f64; 3]]) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
        // SAFETY: the CPU was just found to support AVX2 and FMA, the only requirement of
        // `rows_times_columns_avx2` (it holds no other unsafe operation).
        #[allow(unsafe_code)]
        unsafe {
            rows_times_columns_avx2(rows, stride, u, out)
        };
        return;
    }
    rows_times_columns_kernel::<false>(rows, stride, u, out);
}

/// The hot product of DETMAX compiled for AVX2 with fused multiply-adds: 4-wide vectors instead of
/// the 2-wide SSE2 of the x86-64 baseline (chosen at run time by `rows_times_columns`).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn rows_times_columns_avx2(rows: &[f64], stride: usize, u: &[Vec<f64>; 3], out: &mut [[f64; 3]]) {
    rows_times_columns_kernel::<true>(rows, stride, u, out);
}

/// `out[r] = (row_r . u0, row_r . u1, row_r . u2)` over padded rows, with four independent partial
/// sums per column so that the compiler vectorises it. `FMA` selects fused multiply-adds (only
/// where the target has them; elsewhere `mul_add` would be a slow library call).
#[inline(always)]
fn rows_times_columns_kernel<const FMA: bool>(rows: &[f64], stride: usize, u: &[Vec<f64>; 3], out: &mut [[f64; 3]]) {
    let [u0, u1, u2] = u;
    let madd = |a: f64, x: f64, y: f64| if FMA { x.mul_add(y, a) } else { a + x * y };
    for (row, o) in rows.chunks_exact(stride).zip(out.iter_mut()) {
        let (mut a0, mut a1, mut a2) = ([0.0; 4], [0.0; 4], [0.0; 4]);
        for (((x, y0), y1), y2) in row.chunks_exact(4).zip(u0.chunks_exact(4)).zip(u1.chunks_exact(4)).zip(u2.chunks_exact(4)) {
            for i in 0..4 {
                a0[i] = madd(a0[i], x[i], y0[i]);
                a1[i] = madd(a1[i], x[i], y1[i]);
                a2[i] = madd(a2[i], x[i], y2[i]);
            }
        }
        *o = [(a0[0] + a0[1]) + (a0[2] + a0[3]), (a1[0] + a1[1]) + (a1[2] + a1[3]), (a2[0] + a2[1]) + (a2[2] + a2[3])];
    }
}

impl<'a> State<'a> {
    fn new(pool: &'a PoolJacobian, set: &[usize]) -> Option<Self> {
        let info = pool.information(set);
        let chol = info.cholesky()?;
        let logdet = 2.0 * chol.l_dirty().diagonal().iter().map(|v| v.ln()).sum::<f64>();
        if !logdet.is_finite() {
            return None;
        }
        let minv = chol.inverse();
        let mut member = vec![false; pool.len];
        for &k in set {
            member[k] = true;
        }
        // D_k for all k at once: the 3 x 3 diagonal blocks of J M^-1 J^T.
        let jm = &pool.j * &minv;
        let d = (0..pool.len)
            .map(|k| jm.rows(3 * k, 3) * pool.j.rows(3 * k, 3).transpose())
            .map(|x| Matrix3::from_iterator(x.iter().copied()))
            .collect();
        Some(Self { pool, minv, logdet, d, member, size: set.len() })
    }

    /// Adds (sign = 1) or removes (sign = -1) configuration a.
    fn update(&mut self, a: usize, sign: f64, sc: &mut Scratch) -> bool {
        let s = Matrix3::identity() + self.d[a] * sign;
        let det = s.determinant();
        if det <= 0.0 {
            return false;
        }
        let Some(w) = s.try_inverse() else {
            return false;
        };
        let ja_t = self.pool.j.rows(3 * a, 3).transpose();
        // U = M^-1 J_a^T.
        sc.u.gemm(1.0, &self.minv, &ja_t, 0.0);
        // M'^-1 = M^-1 - sign U W U^T.
        sc.v.gemm(1.0, &sc.u, &w, 0.0);
        self.minv.gemm(-sign, &sc.v, &sc.u.transpose(), 1.0);
        // Every D_k: P = J U, D_k -= sign P_k W P_k^T.
        for c in 0..3 {
            for l in 0..self.pool.m {
                sc.u_cols[c][l] = sc.u[(l, c)];
            }
        }
        rows_times_columns(&self.pool.rows, self.pool.stride, &sc.u_cols, &mut sc.p);
        let ws = w * sign;
        for (dk, pk) in self.d.iter_mut().zip(sc.p.chunks_exact(3)) {
            let pk = Matrix3::new(pk[0][0], pk[0][1], pk[0][2], pk[1][0], pk[1][1], pk[1][2], pk[2][0], pk[2][1], pk[2][2]);
            *dk -= pk * ws * pk.transpose();
        }
        self.logdet += det.ln();
        self.member[a] = sign > 0.0;
        self.size = (self.size as isize + sign as isize) as usize;
        true
    }

    fn best_addition(&self) -> Option<usize> {
        (0..self.d.len()).filter(|&k| !self.member[k]).max_by(|&a, &b| score(&self.d[a], 1.0).total_cmp(&score(&self.d[b], 1.0)))
    }

    fn best_removal(&self) -> Option<usize> {
        (0..self.d.len()).filter(|&k| self.member[k]).max_by(|&a, &b| score(&self.d[a], -1.0).total_cmp(&score(&self.d[b], -1.0)))
    }

    fn selection(&self) -> Vec<usize> {
        (0..self.member.len()).filter(|&k| self.member[k]).collect()
    }

    fn o1(&self) -> f64 {
        (self.logdet / (2.0 * self.pool.m as f64)).exp() / (self.size as f64).sqrt()
    }
}

/// `det(I + sign D)`, or minus infinity when it is not positive.
fn score(d: &Matrix3<f64>, sign: f64) -> f64 {
    let v = (Matrix3::identity() + d * sign).determinant();
    if v > 0.0 { v } else { f64::NEG_INFINITY }
}

/// Chooses `n` configurations of `pool` by DETMAX from a random start drawn with `rng`.
pub fn detmax<R: Rng + ?Sized>(pool: &PoolJacobian, n: usize, opts: &DetmaxOptions, rng: &mut R) -> Result<Design, DetmaxError> {
    let size = pool.len;
    if n == 0 || n >= size || 3 * n < pool.m {
        return Err(DetmaxError::Size { n, pool: size, m: pool.m });
    }
    let mut state = None;
    for _ in 0..opts.max_starts {
        let start: Vec<usize> = sample(rng, size, n).into_vec();
        if let Some(s) = State::new(pool, &start) {
            state = Some(s);
            break;
        }
    }
    let mut state = state.ok_or(DetmaxError::Singular(opts.max_starts))?;
    let mut scratch = Scratch::new(pool);
    let mut history = vec![state.o1()];
    let mut steps = 0;
    let mut k = 1;
    while k <= opts.max_excursion && history.len() <= opts.max_improvements {
        let mut improved = false;
        for up_first in [true, false] {
            let mut trial = state.clone();
            let mut ok = true;
            let mut first_moved = None;
            'excursion: for (half, phase) in [up_first, !up_first].into_iter().enumerate() {
                for _ in 0..k {
                    let pick = if phase { trial.best_addition() } else { trial.best_removal() };
                    // An exchange of length 1 that would undo its own first move returns to the
                    // start design: a failure known before its last update.
                    if k == 1 && half == 1 && pick == first_moved {
                        ok = false;
                        break 'excursion;
                    }
                    steps += 1;
                    ok &= pick.is_some_and(|a| trial.update(a, if phase { 1.0 } else { -1.0 }, &mut scratch));
                    if half == 0 {
                        first_moved = pick;
                    }
                }
            }
            if ok && trial.logdet > state.logdet + 1e-9 {
                state = trial;
                improved = true;
                break;
            }
        }
        if improved {
            history.push(state.o1());
            k = 1;
        } else {
            k += 1;
        }
    }
    Ok(Design { selection: state.selection(), o1_history: history, steps })
}

/// O1 of a set from scratch (the information matrix's log-determinant), for checks.
pub fn o1_of(pool: &PoolJacobian, set: &[usize]) -> f64 {
    let info: DMatrix<f64> = pool.information(set);
    match info.cholesky() {
        Some(c) => {
            ((2.0 * c.l_dirty().diagonal().iter().map(|v| v.ln()).sum::<f64>()) / (2.0 * pool.m as f64)).exp() / (set.len() as f64).sqrt()
        }
        None => 0.0,
    }
}
