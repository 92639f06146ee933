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
    minv: Vec<f64>,
    logdet: f64,
    d: Vec<Matrix3<f64>>,
    member: Vec<bool>,
    size: usize,
}

impl<'a> State<'a> {
    fn new(pool: &'a PoolJacobian, set: &[usize]) -> Option<Self> {
        let m = pool.m;
        let info = pool.information(set);
        let chol = info.cholesky()?;
        let logdet = 2.0 * chol.l_dirty().diagonal().iter().map(|v| v.ln()).sum::<f64>();
        if !logdet.is_finite() {
            return None;
        }
        let inv = chol.inverse();
        let minv: Vec<f64> = (0..m * m).map(|i| inv[(i / m, i % m)]).collect();
        let mut member = vec![false; pool.blocks.len()];
        for &k in set {
            member[k] = true;
        }
        let mut s = Self { pool, minv, logdet, d: vec![Matrix3::zeros(); pool.blocks.len()], member, size: set.len() };
        for k in 0..pool.blocks.len() {
            let u = s.times_minv(k);
            s.d[k] = s.block_times(k, &u);
        }
        Some(s)
    }

    /// `U = M^-1 J_k^T`, stored as three columns of length m.
    fn times_minv(&self, k: usize) -> [Vec<f64>; 3] {
        let m = self.pool.m;
        let j = &self.pool.blocks[k];
        std::array::from_fn(|c| {
            let row = &j[c * m..(c + 1) * m];
            (0..m).map(|l| self.minv[l * m..(l + 1) * m].iter().zip(row).map(|(a, b)| a * b).sum()).collect()
        })
    }

    /// `J_k U` (3 x 3).
    fn block_times(&self, k: usize, u: &[Vec<f64>; 3]) -> Matrix3<f64> {
        let m = self.pool.m;
        let j = &self.pool.blocks[k];
        Matrix3::from_fn(|r, c| j[r * m..(r + 1) * m].iter().zip(&u[c]).map(|(a, b)| a * b).sum())
    }

    /// Adds (sign = 1) or removes (sign = -1) configuration a.
    fn update(&mut self, a: usize, sign: f64) -> bool {
        let s = Matrix3::identity() + self.d[a] * sign;
        let det = s.determinant();
        if det <= 0.0 {
            return false;
        }
        let Some(w) = s.try_inverse() else { return false };
        let u = self.times_minv(a);
        let m = self.pool.m;
        // M'^-1 = M^-1 - sign U W U^T, row by row: V = U W, then row l -= sign V_l U^T.
        for l in 0..m {
            let v = [0, 1, 2].map(|c| u[0][l] * w[(0, c)] + u[1][l] * w[(1, c)] + u[2][l] * w[(2, c)]);
            let row = &mut self.minv[l * m..(l + 1) * m];
            for (jj, x) in row.iter_mut().enumerate() {
                *x -= sign * (v[0] * u[0][jj] + v[1] * u[1][jj] + v[2] * u[2][jj]);
            }
        }
        for k in 0..self.d.len() {
            let p = self.block_times(k, &u);
            self.d[k] -= p * w * p.transpose() * sign;
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
    let size = pool.blocks.len();
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
    let mut history = vec![state.o1()];
    let mut steps = 0;
    let mut k = 1;
    while k <= opts.max_excursion && history.len() <= opts.max_improvements {
        let mut improved = false;
        for up_first in [true, false] {
            let mut trial = state.clone();
            let mut ok = true;
            for phase in [up_first, !up_first] {
                for _ in 0..k {
                    let pick = if phase { trial.best_addition() } else { trial.best_removal() };
                    steps += 1;
                    ok &= pick.is_some_and(|a| trial.update(a, if phase { 1.0 } else { -1.0 }));
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
        Some(c) => ((2.0 * c.l_dirty().diagonal().iter().map(|v| v.ln()).sum::<f64>()) / (2.0 * pool.m as f64)).exp() / (set.len() as f64).sqrt(),
        None => 0.0,
    }
}
