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
    /// `D_k = J_k M^-1 J_k^T` for every pool configuration, after the first `applied[k]` updates
    /// of `pending`.
    d: Vec<Matrix3<f64>>,
    /// How many of the pending updates each `D_k` has taken.
    applied: Vec<usize>,
    /// Rank-3 updates made since every `D_k` was last current, in order. A pick reads only the
    /// `D_k` it scores (additions the non-members, removals the members), so only those are brought
    /// up to date; an excursion that is rejected never pays for the rest. Each `D_k` takes the same
    /// updates in the same order as an eager update would, so the numbers are the same.
    pending: Vec<Pending>,
    member: Vec<bool>,
    size: usize,
}

/// One rank-3 update of every `D_k`: `D_k -= P_k ws P_k^T` with `P_k = J_k U`.
#[derive(Clone)]
struct Pending {
    /// The columns of `U = M^-1 J_a^T`, zero-padded to the pool's stride.
    u_cols: [Vec<f64>; 3],
    /// `sign (I + sign D_a)^-1`.
    ws: Matrix3<f64>,
}

/// Buffers reused by every update.
struct Scratch {
    /// `U = M^-1 J_a^T`, m x 3.
    u: DMatrix<f64>,
    /// `U W`, m x 3.
    v: DMatrix<f64>,
}

impl Scratch {
    fn new(pool: &PoolJacobian) -> Self {
        Self { u: DMatrix::zeros(pool.m, 3), v: DMatrix::zeros(pool.m, 3) }
    }
}

/// Which `D_k` a pick reads.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Rows {
    Members,
    NonMembers,
    All,
}

/// Brings `d[k]` up to date for every k that `want` selects: the pending updates it has not taken,
/// in order. The product `J_k U` is written so that it vectorises (nalgebra's GEMM takes a scalar
/// path when a dimension is below 6).
fn catch_up(pool: &PoolJacobian, pending: &[Pending], d: &mut [Matrix3<f64>], applied: &mut [usize], want: impl Fn(usize) -> bool) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
        // SAFETY: the CPU was just found to support AVX2 and FMA, the only requirement of
        // `catch_up_avx2` (it holds no other unsafe operation).
        #[allow(unsafe_code)]
        unsafe {
            catch_up_avx2(pool, pending, d, applied, want)
        };
        return;
    }
    catch_up_kernel::<false>(pool, pending, d, applied, want);
}

/// The hot loop of DETMAX compiled for AVX2 with fused multiply-adds: 4-wide vectors instead of
/// the 2-wide SSE2 of the x86-64 baseline (chosen at run time by `catch_up`).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn catch_up_avx2(pool: &PoolJacobian, pending: &[Pending], d: &mut [Matrix3<f64>], applied: &mut [usize], want: impl Fn(usize) -> bool) {
    catch_up_kernel::<true>(pool, pending, d, applied, want);
}

#[inline(always)]
fn catch_up_kernel<const FMA: bool>(
    pool: &PoolJacobian,
    pending: &[Pending],
    d: &mut [Matrix3<f64>],
    applied: &mut [usize],
    want: impl Fn(usize) -> bool,
) {
    let stride = pool.stride;
    for (k, (dk, done)) in d.iter_mut().zip(applied.iter_mut()).enumerate() {
        if *done == pending.len() || !want(k) {
            continue;
        }
        let rows = &pool.rows[3 * k * stride..3 * (k + 1) * stride];
        for up in &pending[*done..] {
            #[cfg(target_arch = "x86_64")]
            let p = if FMA {
                // SAFETY: `FMA` is true only inside `catch_up_avx2`, on a CPU found to support AVX2
                // and FMA, the only requirement of `config_times_columns_avx2`.
                #[allow(unsafe_code)]
                unsafe {
                    config_times_columns_avx2(rows, stride, &up.u_cols)
                }
            } else {
                config_times_columns(rows, stride, &up.u_cols)
            };
            #[cfg(not(target_arch = "x86_64"))]
            let p = config_times_columns(rows, stride, &up.u_cols);
            let pk = Matrix3::new(p[0][0], p[0][1], p[0][2], p[1][0], p[1][1], p[1][2], p[2][0], p[2][1], p[2][2]);
            *dk -= pk * up.ws * pk.transpose();
        }
        *done = pending.len();
    }
}

/// `P_k = J_k U` for the three padded rows of one configuration: `p[r][c] = row_r . u_c`, with
/// four independent partial sums per entry (lane i sums the terms 4j + i), added as
/// `(s0 + s1) + (s2 + s3)`.
fn config_times_columns(rows: &[f64], stride: usize, u: &[Vec<f64>; 3]) -> [[f64; 3]; 3] {
    let mut p = [[0.0; 3]; 3];
    for (row, pr) in rows.chunks_exact(stride).zip(p.iter_mut()) {
        for (v, col) in pr.iter_mut().zip(u) {
            let mut a = [0.0; 4];
            for (x, y) in row.chunks_exact(4).zip(col.chunks_exact(4)) {
                for i in 0..4 {
                    a[i] += x[i] * y[i];
                }
            }
            *v = (a[0] + a[1]) + (a[2] + a[3]);
        }
    }
    p
}

/// The same products with AVX2 fused multiply-adds (one rounding per term, so the sums differ from
/// `config_times_columns` in the last bits): the nine 4-lane partial sums stay in registers and
/// each loaded chunk of U serves the three rows.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn config_times_columns_avx2(rows: &[f64], stride: usize, u: &[Vec<f64>; 3]) -> [[f64; 3]; 3] {
    use std::arch::x86_64::{__m256d, _mm256_fmadd_pd, _mm256_loadu_pd, _mm256_setzero_pd, _mm256_storeu_pd};
    assert!(stride.is_multiple_of(4) && rows.len() >= 3 * stride && u.iter().all(|c| c.len() >= stride));
    let mut acc: [__m256d; 9] = [_mm256_setzero_pd(); 9];
    for j in (0..stride).step_by(4) {
        // SAFETY: j + 4 <= stride, and the three rows and the three columns hold `stride` values
        // each (asserted above); unaligned loads.
        #[allow(unsafe_code)]
        let (x, y) = unsafe {
            let x = [0, 1, 2].map(|r| _mm256_loadu_pd(rows.as_ptr().add(r * stride + j)));
            let y = [0, 1, 2].map(|c| _mm256_loadu_pd(u[c].as_ptr().add(j)));
            (x, y)
        };
        for r in 0..3 {
            for c in 0..3 {
                acc[3 * r + c] = _mm256_fmadd_pd(x[r], y[c], acc[3 * r + c]);
            }
        }
    }
    let mut p = [[0.0; 3]; 3];
    for r in 0..3 {
        for c in 0..3 {
            let mut a = [0.0; 4];
            // SAFETY: `a` holds four values.
            #[allow(unsafe_code)]
            unsafe {
                _mm256_storeu_pd(a.as_mut_ptr(), acc[3 * r + c])
            };
            p[r][c] = (a[0] + a[1]) + (a[2] + a[3]);
        }
    }
    p
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
        Some(Self { pool, minv, logdet, d, applied: vec![0; pool.len], pending: Vec::new(), member, size: set.len() })
    }

    /// Adds (sign = 1) or removes (sign = -1) configuration a; its `D_a` must be current.
    fn update(&mut self, a: usize, sign: f64, sc: &mut Scratch) -> bool {
        debug_assert_eq!(self.applied[a], self.pending.len());
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
        // Every D_k, when next read: P = J U, D_k -= sign P_k W P_k^T.
        let mut u_cols: [Vec<f64>; 3] = std::array::from_fn(|_| vec![0.0; self.pool.stride]);
        for (c, col) in u_cols.iter_mut().enumerate() {
            for l in 0..self.pool.m {
                col[l] = sc.u[(l, c)];
            }
        }
        self.pending.push(Pending { u_cols, ws: w * sign });
        self.logdet += det.ln();
        self.member[a] = sign > 0.0;
        self.size = (self.size as isize + sign as isize) as usize;
        true
    }

    /// Brings the `D_k` of `rows` up to date; with `Rows::All` the pending list is emptied.
    fn catch_up(&mut self, rows: Rows) {
        let member = &self.member;
        catch_up(self.pool, &self.pending, &mut self.d, &mut self.applied, |k| match rows {
            Rows::All => true,
            Rows::Members => member[k],
            Rows::NonMembers => !member[k],
        });
        if rows == Rows::All {
            self.pending.clear();
            self.applied.fill(0);
        }
    }

    fn best_addition(&mut self) -> Option<usize> {
        self.catch_up(Rows::NonMembers);
        (0..self.d.len()).filter(|&k| !self.member[k]).max_by(|&a, &b| score(&self.d[a], 1.0).total_cmp(&score(&self.d[b], 1.0)))
    }

    fn best_removal(&mut self) -> Option<usize> {
        self.catch_up(Rows::Members);
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
                trial.catch_up(Rows::All);
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
