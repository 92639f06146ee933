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
//! Adding or removing a configuration a updates `M^-1` by Woodbury and every `D_k` by a symmetric
//! rank-3 product (`lanes`, which also holds the blocks side by side and the kernels): O(N m) per
//! step instead of an SVD per candidate.

mod lanes;
mod pool;

use nalgebra::DMatrix;
#[cfg(test)]
use nalgebra::Matrix3;
use rand::Rng;
use rand::seq::index::sample;

pub use lanes::Lanes;
use lanes::{Group, LANES, Update};

pub use pool::PoolJacobian;

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
    /// `M^-1`, exactly symmetric, each column padded with zeros to `mp` rows.
    minv: DMatrix<f64>,
    /// The rows of `minv`: m rounded up to a multiple of 4.
    mp: usize,
    logdet: f64,
    /// `D_k = J_k M^-1 J_k^T` for every pool configuration, [`LANES`] to a group, after the first
    /// `applied[g]` updates of `pending` (g the group).
    d: Vec<Group>,
    /// How many of the pending updates each group has taken.
    applied: Vec<u32>,
    /// Exchange steps made since every `D_k` was last current, in order. A pick reads only the
    /// `D_k` it scores (additions the non-members, removals the members), so only their groups are
    /// brought up to date; an excursion that is rejected never pays for the rest. Each `D_k` takes
    /// the same updates in the same order as an eager update would, so the numbers are the same.
    pending: Vec<Update>,
    /// Row buffers of updates no longer pending, for the next ones.
    spare: Vec<Vec<[f64; 4]>>,
    /// The members of every group, a bit per lane.
    member: Vec<u8>,
    size: usize,
}

/// Buffers reused by every step.
struct Scratch {
    /// The columns of `U = M^-1 J_a^T`, then of `U' = U L^-T`, m values each and zeros to a
    /// multiple of 4.
    u: [Vec<f64>; 3],
}

impl Scratch {
    fn new(pool: &PoolJacobian) -> Self {
        Self { u: std::array::from_fn(|_| vec![0.0; pool.m.div_ceil(4) * 4]) }
    }
}

/// Which `D_k` a pick reads.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Rows {
    Members,
    NonMembers,
    All,
}

impl Rows {
    /// The lanes of group g these rows are (`member`: the members of every group, as bits; `len`
    /// configurations), as bits.
    fn lanes(self, member: &[u8], len: usize, g: usize) -> u8 {
        let valid = lanes::valid_lanes(len, g);
        match self {
            Rows::All => valid,
            Rows::Members => member[g],
            Rows::NonMembers => !member[g] & valid,
        }
    }
}

/// The Cholesky factor `(l00, l10, l11, l20, l21, l22)` of the symmetric `s` (its six entries in
/// the order of [`lanes::ENTRIES`]), or `None` when `s` is not positive definite.
fn cholesky3(s: [f64; 6]) -> Option<[f64; 6]> {
    // NaN is not positive either.
    let positive = |x: f64| x > 0.0;
    let [s00, s11, s22, s01, s02, s12] = s;
    if !positive(s00) {
        return None;
    }
    let l00 = s00.sqrt();
    let (l10, l20) = (s01 / l00, s02 / l00);
    let t11 = s11 - l10 * l10;
    if !positive(t11) {
        return None;
    }
    let l11 = t11.sqrt();
    let l21 = (s12 - l20 * l10) / l11;
    let t22 = (s22 - l20 * l20) - l21 * l21;
    if !(positive(t22) && t22.is_finite()) {
        return None;
    }
    Some([l00, l10, l11, l20, l21, t22.sqrt()])
}

/// The exchange step's `M^-1` (m columns of `mp` values, the rows from m on zero): `U = M^-1
/// J_a^T` (`ja`: the three rows of `J_a`, m values from each third), `U' = U L^-T` (`l` from
/// [`cholesky3`]) and `M^-1 -= sign U' U'^T`, written so that `M^-1` stays exactly symmetric;
/// `U'` is left in `u` (mp values per column). Every number is the same whichever build runs:
/// `U`'s entries are summed over j in order (a product, then fused multiply-adds), `U'` takes
/// separate products, differences and quotients, and `M^-1`'s entries `-= sign ((u_i0 u_j0 +
/// u_i1 u_j1) + u_i2 u_j2)` with the first a product and the others fused.
fn woodbury(minv: &mut [f64], mp: usize, m: usize, ja: &[f64], l: &[f64; 6], sign: f64, u: &mut [Vec<f64>; 3]) {
    assert!(mp.is_multiple_of(4) && mp >= m && minv.len() >= mp * m && ja.len() >= 3 * m && u.iter().all(|c| c.len() >= mp));
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
        // SAFETY: the CPU was just found to support AVX2 and FMA, the only requirement of
        // `woodbury_avx2`; the sizes were asserted above.
        #[allow(unsafe_code)]
        unsafe {
            woodbury_avx2(minv, mp, m, ja, l, sign, u)
        };
        return;
    }
    woodbury_portable(minv, mp, m, ja, l, sign, u);
}

/// [`woodbury`] one value at a time.
fn woodbury_portable(minv: &mut [f64], mp: usize, m: usize, ja: &[f64], l: &[f64; 6], sign: f64, u: &mut [Vec<f64>; 3]) {
    let stride = ja.len() / 3;
    let jr: [&[f64]; 3] = std::array::from_fn(|c| &ja[c * stride..c * stride + m]);
    for (c, uc) in u.iter_mut().enumerate() {
        for i in 0..mp {
            uc[i] = (1..m).fold(minv[i] * jr[c][0], |acc, j| minv[j * mp + i].mul_add(jr[c][j], acc));
        }
    }
    let [l00, l10, l11, l20, l21, l22] = *l;
    let [u0, u1, u2] = u;
    for i in 0..mp {
        let p0 = u0[i] / l00;
        let p1 = (u1[i] - l10 * p0) / l11;
        let p2 = ((u2[i] - l20 * p0) - l21 * p1) / l22;
        (u0[i], u1[i], u2[i]) = (p0, p1, p2);
    }
    for j in 0..m {
        let (y0, y1, y2) = (u0[j], u1[j], u2[j]);
        for i in 0..mp {
            let t = u2[i].mul_add(y2, u1[i].mul_add(y1, u0[i] * y0));
            minv[j * mp + i] -= sign * t;
        }
    }
}

/// [`woodbury`] with AVX2: four rows of `M^-1` in a vector, `U` by blocks of up to 16 rows whose
/// sums stay in registers over j.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn woodbury_avx2(minv: &mut [f64], mp: usize, m: usize, ja: &[f64], l: &[f64; 6], sign: f64, u: &mut [Vec<f64>; 3]) {
    use std::arch::x86_64::{_mm256_div_pd, _mm256_loadu_pd, _mm256_mul_pd, _mm256_set1_pd, _mm256_storeu_pd, _mm256_sub_pd};
    let stride = ja.len() / 3;
    let blocks = mp / 4;
    let mut b0 = 0;
    while b0 < blocks {
        match blocks - b0 {
            1 => woodbury_u_avx2::<1>(minv, mp, m, ja, stride, b0, u),
            2 => woodbury_u_avx2::<2>(minv, mp, m, ja, stride, b0, u),
            3 => woodbury_u_avx2::<3>(minv, mp, m, ja, stride, b0, u),
            _ => woodbury_u_avx2::<4>(minv, mp, m, ja, stride, b0, u),
        }
        b0 += 4;
    }
    let lv = l.map(|x| _mm256_set1_pd(x));
    let [u0, u1, u2] = u;
    for b in 0..blocks {
        // SAFETY: 4 b + 4 <= mp <= the length of each column of U (asserted by the caller).
        #[allow(unsafe_code)]
        unsafe {
            let (q0, q1, q2) = (u0.as_mut_ptr().add(4 * b), u1.as_mut_ptr().add(4 * b), u2.as_mut_ptr().add(4 * b));
            let p0 = _mm256_div_pd(_mm256_loadu_pd(q0), lv[0]);
            let p1 = _mm256_div_pd(_mm256_sub_pd(_mm256_loadu_pd(q1), _mm256_mul_pd(lv[1], p0)), lv[2]);
            let p2 =
                _mm256_div_pd(_mm256_sub_pd(_mm256_sub_pd(_mm256_loadu_pd(q2), _mm256_mul_pd(lv[3], p0)), _mm256_mul_pd(lv[4], p1)), lv[5]);
            _mm256_storeu_pd(q0, p0);
            _mm256_storeu_pd(q1, p1);
            _mm256_storeu_pd(q2, p2);
        }
    }
    let sv = _mm256_set1_pd(sign);
    for j in 0..m {
        let (y0, y1, y2) = (_mm256_set1_pd(u0[j]), _mm256_set1_pd(u1[j]), _mm256_set1_pd(u2[j]));
        for b in 0..blocks {
            // SAFETY: j < m and 4 b + 4 <= mp: within M^-1 (mp * m values) and U's columns.
            #[allow(unsafe_code)]
            unsafe {
                use std::arch::x86_64::_mm256_fmadd_pd;
                let t = _mm256_mul_pd(_mm256_loadu_pd(u0.as_ptr().add(4 * b)), y0);
                let t = _mm256_fmadd_pd(_mm256_loadu_pd(u1.as_ptr().add(4 * b)), y1, t);
                let t = _mm256_fmadd_pd(_mm256_loadu_pd(u2.as_ptr().add(4 * b)), y2, t);
                let col = minv.as_mut_ptr().add(j * mp + 4 * b);
                _mm256_storeu_pd(col, _mm256_sub_pd(_mm256_loadu_pd(col), _mm256_mul_pd(sv, t)));
            }
        }
    }
}

/// Rows `4 b0 .. 4 (b0 + NB)` of `U = M^-1 J_a^T`, their sums in registers over j.
#[cfg(target_arch = "x86_64")]
#[inline]
#[target_feature(enable = "avx2,fma")]
fn woodbury_u_avx2<const NB: usize>(minv: &[f64], mp: usize, m: usize, ja: &[f64], stride: usize, b0: usize, u: &mut [Vec<f64>; 3]) {
    use std::arch::x86_64::{_mm256_fmadd_pd, _mm256_loadu_pd, _mm256_mul_pd, _mm256_set1_pd, _mm256_setzero_pd, _mm256_storeu_pd};
    let mut acc = [[_mm256_setzero_pd(); 3]; NB];
    for j in 0..m {
        let y = [_mm256_set1_pd(ja[j]), _mm256_set1_pd(ja[stride + j]), _mm256_set1_pd(ja[2 * stride + j])];
        for (b, acc) in acc.iter_mut().enumerate() {
            // SAFETY: j < m and 4 (b0 + b) + 4 <= mp: within M^-1 (mp * m values, asserted by the caller).
            #[allow(unsafe_code)]
            let x = unsafe { _mm256_loadu_pd(minv.as_ptr().add(j * mp + 4 * (b0 + b))) };
            for c in 0..3 {
                acc[c] = if j == 0 { _mm256_mul_pd(x, y[c]) } else { _mm256_fmadd_pd(x, y[c], acc[c]) };
            }
        }
    }
    for (b, acc) in acc.iter().enumerate() {
        for c in 0..3 {
            // SAFETY: 4 (b0 + b) + 4 <= mp <= the length of U's columns (asserted by the caller).
            #[allow(unsafe_code)]
            unsafe {
                _mm256_storeu_pd(u[c].as_mut_ptr().add(4 * (b0 + b)), acc[c])
            };
        }
    }
}

impl<'a> State<'a> {
    fn new(pool: &'a PoolJacobian, set: &[usize]) -> Option<Self> {
        let (m, lanes) = (pool.m, &pool.lanes);
        // M of the set in the lanes' column order (the varying columns, then the constant ones):
        // the product of the stacked rows' transpose with themselves.
        let order: Vec<usize> = lanes.varying.iter().copied().chain(lanes.constant.iter().map(|(c, _)| *c)).collect();
        let mut at = DMatrix::zeros(m, 3 * set.len());
        for (t, &k) in set.iter().enumerate() {
            for r in 0..3 {
                let row = &pool.rows[(3 * k + r) * pool.stride..][..m];
                for (i, &c) in order.iter().enumerate() {
                    at[(i, 3 * t + r)] = row[c];
                }
            }
        }
        let mut info = DMatrix::zeros(m, m);
        crate::numeric::gemm_product(&at, crate::numeric::Factor { data: at.as_slice(), row_stride: m, col_stride: 1 }, m, &mut info, true);
        let chol = info.cholesky()?;
        let logdet = 2.0 * chol.l_dirty().diagonal().iter().map(|v| v.ln()).sum::<f64>();
        if !logdet.is_finite() {
            return None;
        }
        let linv = chol.l().solve_lower_triangular(&DMatrix::identity(m, m))?;
        // M^-1 = L^-T L^-1, exactly symmetric (the Woodbury steps keep it so), back in the pool's
        // column order and padded with zero rows.
        let mut inverse = DMatrix::zeros(m, m);
        let linv_factor = crate::numeric::Factor { data: linv.as_slice(), row_stride: 1, col_stride: m };
        crate::numeric::gemm_product(&linv.transpose(), linv_factor, m, &mut inverse, true);
        let mut position = vec![0; m];
        for (i, &c) in order.iter().enumerate() {
            position[c] = i;
        }
        let mp = m.div_ceil(4) * 4;
        let minv = DMatrix::from_fn(mp, m, |i, j| if i < m { inverse[(position[i], position[j])] } else { 0.0 });
        let mut member = vec![0u8; lanes.groups];
        for &k in set {
            member[k / LANES] |= 1 << (k % LANES);
        }
        let d = lanes::start_blocks(lanes, &linv);
        let applied = vec![0; lanes.groups];
        Some(Self { pool, minv, mp, logdet, d, applied, pending: Vec::new(), spare: Vec::new(), member, size: set.len() })
    }

    /// Becomes a copy of `other` (a state of the same pool), keeping its own allocations.
    fn copy_from(&mut self, other: &Self) {
        self.minv.copy_from(&other.minv);
        self.logdet = other.logdet;
        self.d.clone_from(&other.d);
        self.applied.clone_from(&other.applied);
        self.spare.extend(self.pending.drain(..).map(|up| up.urows));
        for up in &other.pending {
            let mut rows = self.spare.pop().unwrap_or_default();
            rows.clone_from(&up.urows);
            self.pending.push(Update { urows: rows, ..*up });
        }
        self.member.clone_from(&other.member);
        self.size = other.size;
    }

    /// The six entries of `D_k`.
    fn entries(&self, k: usize) -> [f64; 6] {
        std::array::from_fn(|e| self.d[k / LANES][e][k % LANES])
    }

    /// Adds (sign = 1) or removes (sign = -1) configuration a; its `D_a` must be current.
    fn update(&mut self, a: usize, sign: f64, sc: &mut Scratch) -> bool {
        debug_assert_eq!(self.applied[a / LANES] as usize, self.pending.len());
        let da = self.entries(a);
        let s: [f64; 6] = std::array::from_fn(|e| if e < 3 { 1.0 + sign * da[e] } else { sign * da[e] });
        let Some(l) = cholesky3(s) else {
            return false;
        };
        let det = (l[0] * l[2] * l[5]).powi(2);
        if det.is_nan() || det <= 0.0 {
            return false;
        }
        let stride = self.pool.stride;
        let ja = &self.pool.rows[3 * a * stride..3 * (a + 1) * stride];
        woodbury(self.minv.as_mut_slice(), self.mp, self.pool.m, ja, &l, sign, &mut sc.u);
        let rows = self.spare.pop().unwrap_or_default();
        self.pending.push(Update::new_in(rows, &self.pool.lanes, [&sc.u[0], &sc.u[1], &sc.u[2]], sign));
        self.logdet += det.ln();
        self.member[a / LANES] ^= 1 << (a % LANES);
        self.size = (self.size as isize + sign as isize) as usize;
        true
    }

    /// Whether configuration k is in the design.
    fn is_member(&self, k: usize) -> bool {
        self.member[k / LANES] >> (k % LANES) & 1 == 1
    }

    /// Brings the `D_k` of `rows` up to date; with `Rows::All` the pending list is emptied.
    fn catch_up(&mut self, rows: Rows) {
        let (member, len) = (&self.member, self.pool.len);
        lanes::catch_up(&self.pool.lanes, &self.pending, &mut self.d, &mut self.applied, |g| rows.lanes(member, len, g) != 0);
        if rows == Rows::All {
            self.spare.extend(self.pending.drain(..).map(|up| up.urows));
            self.applied.fill(0);
        }
    }

    /// The configuration whose addition (sign = 1, among the non-members) or removal (sign = -1,
    /// among the members) leaves the largest determinant: the last of equal ones (scores that are
    /// not positive count as minus infinity).
    fn best(&mut self, sign: f64) -> Option<usize> {
        let rows = if sign < 0.0 { Rows::Members } else { Rows::NonMembers };
        self.catch_up(rows);
        lanes::best(&self.d, sign, |g| rows.lanes(&self.member, self.pool.len, g))
    }

    fn selection(&self) -> Vec<usize> {
        (0..self.pool.len).filter(|&k| self.is_member(k)).collect()
    }

    fn o1(&self) -> f64 {
        (self.logdet / (2.0 * self.pool.m as f64)).exp() / (self.size as f64).sqrt()
    }
}

/// Chooses `n` configurations of `pool` by DETMAX from a random start drawn with `rng`.
pub fn detmax<R: Rng + ?Sized>(pool: &PoolJacobian, n: usize, opts: &DetmaxOptions, rng: &mut R) -> Result<Design, DetmaxError> {
    detmax_from(pool, n, opts, rng, None)
}

/// [`detmax`] from the set `warm` where it can: the random start is drawn from `rng` as always
/// (the stream moves on the same), then replaced by `warm`'s indices that are in the pool
/// (ascending, each once, the first n), completed to n by the random start's indices not among
/// them in their drawn order; a warm set whose information matrix is singular leaves the random
/// start. `warm = None` is [`detmax`].
pub fn detmax_from<R: Rng + ?Sized>(
    pool: &PoolJacobian,
    n: usize,
    opts: &DetmaxOptions,
    rng: &mut R,
    warm: Option<&[usize]>,
) -> Result<Design, DetmaxError> {
    let size = pool.len;
    if n == 0 || n >= size || 3 * n < pool.m {
        return Err(DetmaxError::Size { n, pool: size, m: pool.m });
    }
    let mut state = None;
    for _ in 0..opts.max_starts {
        let start: Vec<usize> = sample(rng, size, n).into_vec();
        if let Some(s) = State::new(pool, &start) {
            state = Some((s, start));
            break;
        }
    }
    let (random, drawn) = state.ok_or(DetmaxError::Singular(opts.max_starts))?;
    let state = match warm {
        Some(w) => State::new(pool, &warm_start(w, &drawn, size, n)).unwrap_or(random),
        None => random,
    };
    Ok(exchange(state, opts))
}

/// The start set of [`detmax_from`]: `warm`'s indices below `size`, ascending and each once, the
/// first n; then `drawn`'s indices not among them, in order, up to n.
fn warm_start(warm: &[usize], drawn: &[usize], size: usize, n: usize) -> Vec<usize> {
    let mut set: Vec<usize> = warm.iter().copied().filter(|&k| k < size).collect();
    set.sort_unstable();
    set.dedup();
    set.truncate(n);
    let mut member = vec![false; size];
    set.iter().for_each(|&k| member[k] = true);
    for &k in drawn {
        if set.len() == n {
            break;
        }
        if !member[k] {
            member[k] = true;
            set.push(k);
        }
    }
    set
}

/// DETMAX's excursions from `state` until no excursion up to the longest improves it.
fn exchange(mut state: State<'_>, opts: &DetmaxOptions) -> Design {
    let pool = state.pool;
    let mut scratch = Scratch::new(pool);
    // Each excursion runs on a copy of the design, kept in one buffer.
    let mut trial = state.clone();
    let mut history = vec![state.o1()];
    let mut steps = 0;
    let mut k = 1;
    while k <= opts.max_excursion && history.len() <= opts.max_improvements {
        let mut improved = false;
        for up_first in [true, false] {
            trial.copy_from(&state);
            let mut ok = true;
            let mut first_moved = None;
            'excursion: for (half, phase) in [up_first, !up_first].into_iter().enumerate() {
                for _ in 0..k {
                    let pick = trial.best(if phase { 1.0 } else { -1.0 });
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
                std::mem::swap(&mut state, &mut trial);
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
    Design { selection: state.selection(), o1_history: history, steps }
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

#[cfg(test)]
mod tests {
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::pool::random_pool;
    use super::*;

    /// A random pool whose columns 0 and 4 are the same in every configuration (as the base
    /// translations are in the TriCal pool).
    fn pool_with_constant_columns(len: usize, m: usize, rng: &mut ChaCha8Rng) -> PoolJacobian {
        let mut j = DMatrix::from_fn(3 * len, m, |_, _| rng.random_range(-1.0..1.0));
        for c in [0, 4] {
            for k in 1..len {
                for r in 0..3 {
                    j[(3 * k + r, c)] = j[(r, c)];
                }
            }
        }
        PoolJacobian::from_scaled(j, vec![1.0; m])
    }

    /// After exchanges of both signs, every `D_k` (brought up to date) and `M^-1` agree with a
    /// state computed from scratch for the same set, and `M^-1` is exactly symmetric: 40
    /// configurations, 31 parameters (two constant columns), 6 steps.
    #[test]
    fn updated_blocks_and_inverse_agree_with_a_fresh_state() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let pool = pool_with_constant_columns(40, 31, &mut rng);
        assert_eq!(pool.lanes.constant.len(), 2);
        let start: Vec<usize> = (0..15).collect();
        let mut state = State::new(&pool, &start).expect("non-singular start");
        let mut sc = Scratch::new(&pool);
        for (i, (a, sign)) in [(20, 1.0), (3, -1.0), (25, 1.0), (30, 1.0), (0, -1.0), (7, -1.0)].into_iter().enumerate() {
            // Half the steps from a fully current state, half with only the picked block current.
            if i % 2 == 0 {
                state.catch_up(Rows::All);
            } else {
                let member = state.is_member(a);
                state.catch_up(if member { Rows::Members } else { Rows::NonMembers });
            }
            assert!(state.update(a, sign, &mut sc));
        }
        state.catch_up(Rows::All);
        let fresh = State::new(&pool, &state.selection()).expect("non-singular end");
        for k in 0..pool.len {
            let (got, expected) = (lanes::block(&state.d, k), lanes::block(&fresh.d, k));
            assert!((got - expected).abs().max() <= 1e-10 * (1.0 + expected.abs().max()), "configuration {k}: {got} vs fresh {expected}");
        }
        let scale = fresh.minv.abs().max();
        assert!((&state.minv - &fresh.minv).abs().max() <= 1e-10 * scale);
        let square = state.minv.rows(0, pool.m);
        assert_eq!(square, square.transpose());
        assert!(state.minv.rows(pool.m, state.mp - pool.m).iter().all(|&v| v == 0.0), "padding stays zero");
        assert!((state.logdet - fresh.logdet).abs() <= 1e-10 * fresh.logdet.abs().max(1.0));
    }

    /// DETMAX written plainly: every candidate scored by the log-determinant of its information
    /// matrix from a fresh Cholesky factor, the same excursions and acceptance. Returns the
    /// selection and the steps.
    fn plain_detmax(pool: &PoolJacobian, n: usize, opts: &DetmaxOptions, rng: &mut ChaCha8Rng) -> (Vec<usize>, usize) {
        let logdet = |member: &[bool]| -> Option<f64> {
            let set: Vec<usize> = (0..pool.len).filter(|&k| member[k]).collect();
            let c = pool.information(&set).cholesky()?;
            let v = 2.0 * c.l_dirty().diagonal().iter().map(|v| v.ln()).sum::<f64>();
            v.is_finite().then_some(v)
        };
        let mut member = vec![false; pool.len];
        for _ in 0..opts.max_starts {
            let start: Vec<usize> = sample(rng, pool.len, n).into_vec();
            member.fill(false);
            start.iter().for_each(|&k| member[k] = true);
            if logdet(&member).is_some() {
                break;
            }
        }
        let mut current = logdet(&member).expect("non-singular start");
        let (mut steps, mut k, mut kept) = (0, 1, 0);
        while k <= opts.max_excursion && kept < opts.max_improvements {
            let mut improved = false;
            for up_first in [true, false] {
                let mut trial = member.clone();
                let mut ok = true;
                let mut first_moved = None;
                'excursion: for (half, add) in [up_first, !up_first].into_iter().enumerate() {
                    for _ in 0..k {
                        let mut best: Option<(usize, f64)> = None;
                        for c in 0..pool.len {
                            if trial[c] == add {
                                continue;
                            }
                            trial[c] = add;
                            let v = logdet(&trial).unwrap_or(f64::NEG_INFINITY);
                            trial[c] = !add;
                            if best.is_none_or(|(_, b)| v >= b) {
                                best = Some((c, v));
                            }
                        }
                        let pick = best.map(|(c, _)| c);
                        if k == 1 && half == 1 && pick == first_moved {
                            ok = false;
                            break 'excursion;
                        }
                        steps += 1;
                        match best {
                            Some((c, v)) if v > f64::NEG_INFINITY => trial[c] = add,
                            _ => ok = false,
                        }
                        if half == 0 {
                            first_moved = pick;
                        }
                    }
                }
                if let Some(v) = logdet(&trial).filter(|v| ok && *v > current + 1e-9) {
                    (member, current, improved) = (trial, v, true);
                    break;
                }
            }
            if improved {
                kept += 1;
                k = 1;
            } else {
                k += 1;
            }
        }
        ((0..pool.len).filter(|&c| member[c]).collect(), steps)
    }

    /// The rank-3 DETMAX makes the decisions of the plain one: the same selection after the same
    /// number of steps, over 24 designs (random pools of 60 configurations and 12 parameters, two
    /// of them constant columns in half the pools; n from 5 to 25; both draw their start from
    /// the same stream).
    #[test]
    fn detmax_makes_the_plain_algorithms_decisions() {
        let mut rng = ChaCha8Rng::seed_from_u64(12);
        let opts = DetmaxOptions::default();
        for case in 0..24 {
            let pool = if case % 2 == 0 { random_pool(60, 12, &mut rng) } else { pool_with_constant_columns(60, 12, &mut rng) };
            let n = 5 + case % 21;
            let seed = rng.random::<u64>();
            let fast = detmax(&pool, n, &opts, &mut ChaCha8Rng::seed_from_u64(seed)).expect("design");
            let (plain, steps) = plain_detmax(&pool, n, &opts, &mut ChaCha8Rng::seed_from_u64(seed));
            assert_eq!(fast.selection, plain, "case {case}, n = {n}");
            assert_eq!(fast.steps, steps, "case {case}, n = {n}");
            assert!((o1_of(&pool, &fast.selection) - fast.o1_history.last().unwrap()).abs() < 1e-9);
        }
    }

    /// The exchange's Woodbury step gives the inverse of the updated information matrix, to
    /// rounding, for an addition and a removal (31 parameters).
    #[test]
    fn woodbury_step_inverts_the_updated_information() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let pool = random_pool(40, 31, &mut rng);
        let set: Vec<usize> = (0..20).collect();
        for (a, sign) in [(30, 1.0), (4, -1.0)] {
            let state = State::new(&pool, &set).expect("non-singular start");
            let da = state.entries(a);
            let s: [f64; 6] = std::array::from_fn(|e| if e < 3 { 1.0 + sign * da[e] } else { sign * da[e] });
            let l = cholesky3(s).expect("positive definite");
            let mut minv = state.minv.clone();
            let mut sc = Scratch::new(&pool);
            let ja = &pool.rows[3 * a * pool.stride..3 * (a + 1) * pool.stride];
            woodbury(minv.as_mut_slice(), state.mp, pool.m, ja, &l, sign, &mut sc.u);
            let moved: Vec<usize> =
                if sign > 0.0 { set.iter().copied().chain([a]).collect() } else { set.iter().copied().filter(|&k| k != a).collect() };
            let expected = pool.information(&moved).try_inverse().expect("invertible");
            assert!((minv.rows(0, pool.m) - &expected).abs().max() <= 1e-10 * expected.abs().max());
            // Every build gives the same numbers: the portable step from the same state.
            let (mut slow, mut su) = (state.minv.clone(), Scratch::new(&pool).u);
            woodbury_portable(slow.as_mut_slice(), state.mp, pool.m, ja, &l, sign, &mut su);
            assert_eq!(minv.iter().map(|v| v.to_bits()).collect::<Vec<_>>(), slow.iter().map(|v| v.to_bits()).collect::<Vec<_>>());
            assert_eq!(sc.u, su);
        }
    }

    /// The 3 x 3 Cholesky factor reproduces its matrix and refuses indefinite ones.
    #[test]
    fn cholesky3_factors_and_refuses() {
        let s = [4.0, 5.0, 6.0, 1.0, 0.5, -0.7];
        let [l00, l10, l11, l20, l21, l22] = cholesky3(s).expect("positive definite");
        let l = Matrix3::new(l00, 0.0, 0.0, l10, l11, 0.0, l20, l21, l22);
        let a = l * l.transpose();
        let expected = Matrix3::new(4.0, 1.0, 0.5, 1.0, 5.0, -0.7, 0.5, -0.7, 6.0);
        assert!((a - expected).abs().max() < 1e-14);
        assert_eq!(cholesky3([1.0, 1.0, 1.0, 2.0, 0.0, 0.0]), None);
        assert_eq!(cholesky3([-1.0, 1.0, 1.0, 0.0, 0.0, 0.0]), None);
        assert_eq!(cholesky3([1.0, 1.0, f64::NAN, 0.0, 0.0, 0.0]), None);
    }

    /// The warm start keeps the warm set's indices that are in the pool, ascending and each once,
    /// the first n, and completes them from the drawn start in its order.
    #[test]
    fn warm_start_keeps_the_pools_indices_and_completes_from_the_draw() {
        assert_eq!(warm_start(&[9, 3, 3, 42, 7], &[5, 3, 8, 1], 10, 5), vec![3, 7, 9, 5, 8]);
        assert_eq!(warm_start(&[9, 3, 7, 1, 0], &[5, 3], 10, 3), vec![0, 1, 3]);
        assert_eq!(warm_start(&[], &[4, 2, 6], 10, 3), vec![4, 2, 6]);
    }

    /// Without a warm set, `detmax_from` is `detmax` (the same design, the stream left in the
    /// same place); warm-started from a finished design of the same pool, it makes no exchange
    /// that is kept and returns that design; from a singular warm set it is the cold run.
    #[test]
    fn warm_started_detmax_keeps_a_finished_design_and_falls_back_when_singular() {
        let mut rng = ChaCha8Rng::seed_from_u64(21);
        let pool = pool_with_constant_columns(80, 12, &mut rng);
        let opts = DetmaxOptions::default();
        let (mut a, mut b) = (ChaCha8Rng::seed_from_u64(3), ChaCha8Rng::seed_from_u64(3));
        let cold = detmax(&pool, 20, &opts, &mut a).expect("design");
        assert_eq!(detmax_from(&pool, 20, &opts, &mut b, None).expect("design"), cold);
        assert_eq!(a.random::<u64>(), b.random::<u64>());
        assert!(cold.o1_history.len() > 1, "the random start was improved");
        let warm = detmax_from(&pool, 20, &opts, &mut ChaCha8Rng::seed_from_u64(4), Some(&cold.selection)).expect("design");
        assert_eq!(warm.selection, cold.selection);
        assert_eq!(warm.o1_history.len(), 1);
        // A warm set of 20 copies of one configuration is singular: the random start is kept.
        let mut j = pool.j.clone();
        for k in 1..20 {
            for r in 0..3 {
                let row = j.row(r).into_owned();
                j.row_mut(3 * k + r).copy_from(&row);
            }
        }
        let copies = PoolJacobian::from_scaled(j, vec![1.0; 12]);
        let set: Vec<usize> = (0..20).collect();
        assert!(State::new(&copies, &set).is_none());
        let cold = detmax(&copies, 20, &opts, &mut ChaCha8Rng::seed_from_u64(5)).expect("design");
        assert_eq!(detmax_from(&copies, 20, &opts, &mut ChaCha8Rng::seed_from_u64(5), Some(&set)).expect("design"), cold);
    }
}
