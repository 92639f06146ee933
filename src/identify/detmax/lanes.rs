//! DETMAX's blocks side by side: the pool's Jacobian laid out with [`LANES`] configurations in one
//! vector, the blocks `D_k` the same way, and the kernels that bring the blocks up to date.
//!
//! **The arithmetic.** An exchange step adds (`sign = 1`) or removes (`sign = -1`) configuration
//! a. With `S = I + sign D_a = L L^T` (a 3 x 3 Cholesky factor) and `U' = M^-1 J_a^T L^-T`, every
//! block takes `D_k -= sign P_k P_k^T` with `P_k = J_k U'`: the Woodbury identity with its 3 x 3
//! weight factored, so that the per-block product after `P_k` is a symmetric rank-3 one (six
//! entries, three products each) and the blocks stay exactly symmetric. Columns of the pool's
//! Jacobian that are the same in every configuration (the base translations: the identity) add the
//! same 3 x 3 to every `P_k`; it is computed once per step ([`Update::pc`]) and the kernels run over
//! the other columns only.
//!
//! **One result whichever kernel runs.** Entry `(r, c)` of `P_k` starts at `pc[r][c]` and takes
//! `J_k[r][j] U'[j][c]` by fused multiply-adds over the varying columns in order; entry `(r, s)` of
//! the block takes `D -= sign ((P_r0 P_s0 + P_r1 P_s1) + P_r2 P_s2)`, the first a product and the
//! others fused. The AVX2 kernel (a whole group of [`LANES`] configurations in the lanes of one
//! vector) and the portable one (`f64::mul_add`, exactly rounded everywhere) perform these same
//! operations on the same operands, so they give the same bits (tests below); which one runs is a
//! matter of speed only.

use nalgebra::DMatrix;

/// Configurations in one group: the lanes of a 256-bit vector of `f64`.
pub const LANES: usize = 4;

/// The six entries of the symmetric blocks of one group, each for its [`LANES`] configurations:
/// `(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)`.
pub type Group = [[f64; LANES]; 6];

/// Row and column of each entry of a [`Group`].
pub const ENTRIES: [(usize, usize); 6] = [(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)];

/// The pool's stacked Jacobian as DETMAX reads it.
#[derive(Clone, Debug, Default)]
pub struct Lanes {
    /// Configurations.
    pub len: usize,
    /// Groups of [`LANES`] configurations (the last one padded with zero rows).
    pub groups: usize,
    /// Columns that differ between configurations, in order.
    pub varying: Vec<usize>,
    /// Columns whose three rows are the same in every configuration, with those rows.
    pub constant: Vec<(usize, [f64; 3])>,
    /// `J_k[r][varying[j]]` at `((g * 3 + r) * varying.len() + j) * LANES + lane`, `k = LANES g + lane`.
    pub j: Vec<f64>,
}

impl Lanes {
    /// The layout of the stacked Jacobian `j` (rows `3k..3k + 3` are configuration k).
    pub fn new(j: &DMatrix<f64>) -> Self {
        let len = j.nrows() / 3;
        let same = |c: usize| len > 1 && (1..len).all(|k| (0..3).all(|r| j[(3 * k + r, c)] == j[(r, c)]));
        let (constant_cols, varying): (Vec<usize>, Vec<usize>) = (0..j.ncols()).partition(|&c| same(c));
        let constant = constant_cols.iter().map(|&c| (c, [j[(0, c)], j[(1, c)], j[(2, c)]])).collect();
        let groups = len.div_ceil(LANES);
        let mv = varying.len();
        let mut data = vec![0.0; groups * 3 * mv * LANES];
        for k in 0..len {
            let (g, lane) = (k / LANES, k % LANES);
            for r in 0..3 {
                for (jv, &c) in varying.iter().enumerate() {
                    data[((g * 3 + r) * mv + jv) * LANES + lane] = j[(3 * k + r, c)];
                }
            }
        }
        Self { len, groups, varying, constant, j: data }
    }

    /// The rows of group g: `3 * varying.len() * LANES` values.
    fn group(&self, g: usize) -> &[f64] {
        let size = 3 * self.varying.len() * LANES;
        &self.j[g * size..(g + 1) * size]
    }
}

/// The blocks `D_k = J_k M^-1 J_k^T` of every configuration from the inverse Cholesky factor
/// `linv = L^-1` of `M = L L^T`, in the lanes' column order (the varying columns, then the
/// constant ones): `X_k = J_k L^-T` (`X_k[r][c]`: the products `J_k[r][i] linv[c][i]` for i from 0
/// to c, the first a product, the others fused, in order) and `D_k = X_k X_k^T` (entry `(r, s)`:
/// `X_k[r][c] X_k[s][c]` the same way over c). The AVX2 build (chosen at run time) gives the same
/// numbers.
pub fn start_blocks(lanes: &Lanes, linv: &DMatrix<f64>) -> Vec<Group> {
    let m = lanes.varying.len() + lanes.constant.len();
    assert_eq!(linv.shape(), (m, m));
    // Row c of L^-1 up to its diagonal, rows one after another.
    let rows: Vec<f64> = (0..m).flat_map(|c| (0..=c).map(move |i| (c, i))).map(|(c, i)| linv[(c, i)]).collect();
    let mut d = vec![[[0.0; LANES]; 6]; lanes.groups];
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
        // SAFETY: the CPU was just found to support AVX2 and FMA, the only requirement of
        // `start_blocks_avx2`.
        #[allow(unsafe_code)]
        unsafe {
            start_blocks_avx2(lanes, m, &rows, &mut d)
        };
        return d;
    }
    start_blocks_portable(lanes, m, &rows, &mut d);
    d
}

/// [`start_blocks`] one configuration at a time (`rows`: L^-1's rows up to the diagonal).
fn start_blocks_portable(lanes: &Lanes, m: usize, rows: &[f64], d: &mut [Group]) {
    let mut x = vec![[0.0; 3]; m];
    for k in 0..lanes.len {
        let (g, lane) = (k / LANES, k % LANES);
        let mv = lanes.varying.len();
        let jv = |r: usize, i: usize| if i < mv { lanes.j[((g * 3 + r) * mv + i) * LANES + lane] } else { lanes.constant[i - mv].1[r] };
        for c in 0..m {
            let lc = &rows[c * (c + 1) / 2..][..=c];
            for (r, xr) in x[c].iter_mut().enumerate() {
                *xr = (1..=c).fold(jv(r, 0) * lc[0], |acc, i| jv(r, i).mul_add(lc[i], acc));
            }
        }
        for (e, &(r, s)) in ENTRIES.iter().enumerate() {
            d[g][e][lane] = (1..m).fold(x[0][r] * x[0][s], |acc, c| x[c][r].mul_add(x[c][s], acc));
        }
    }
}

/// [`start_blocks`] with AVX2: a group's configurations in the lanes, columns of `X` four at a
/// time.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn start_blocks_avx2(lanes: &Lanes, m: usize, rows: &[f64], d: &mut [Group]) {
    use std::arch::x86_64::{
        __m256d, _mm256_fmadd_pd, _mm256_loadu_pd, _mm256_mul_pd, _mm256_set1_pd, _mm256_setzero_pd, _mm256_storeu_pd,
    };
    let mv = lanes.varying.len();
    assert!(lanes.j.len() >= lanes.groups * 3 * mv * LANES && rows.len() >= m * (m + 1) / 2 && d.len() >= lanes.groups);
    let mut x = vec![[_mm256_setzero_pd(); 3]; m];
    for (g, dg) in d.iter_mut().enumerate().take(lanes.groups) {
        let jg = lanes.group(g).as_ptr();
        // Row r, column i of the group's J in the lanes' order.
        let jv = |r: usize, i: usize| -> __m256d {
            if i < mv {
                // SAFETY: (r * mv + i) * LANES + LANES <= 3 * mv * LANES, the group's size.
                #[allow(unsafe_code)]
                unsafe {
                    _mm256_loadu_pd(jg.add((r * mv + i) * LANES))
                }
            } else {
                _mm256_set1_pd(lanes.constant[i - mv].1[r])
            }
        };
        let mut c0 = 0;
        while c0 < m {
            let nc = (m - c0).min(4);
            let mut acc = [[_mm256_setzero_pd(); 4]; 3];
            // Terms 0..=c0 belong to every column of the block.
            for i in 0..=c0 {
                let xr = [jv(0, i), jv(1, i), jv(2, i)];
                for cc in 0..nc {
                    let l = _mm256_set1_pd(rows[(c0 + cc) * (c0 + cc + 1) / 2 + i]);
                    for r in 0..3 {
                        acc[r][cc] = if i == 0 { _mm256_mul_pd(xr[r], l) } else { _mm256_fmadd_pd(xr[r], l, acc[r][cc]) };
                    }
                }
            }
            // Then term c0 + t for the columns from c0 + t on.
            for t in 1..nc {
                let i = c0 + t;
                let xr = [jv(0, i), jv(1, i), jv(2, i)];
                for cc in t..nc {
                    let l = _mm256_set1_pd(rows[(c0 + cc) * (c0 + cc + 1) / 2 + i]);
                    for r in 0..3 {
                        acc[r][cc] = _mm256_fmadd_pd(xr[r], l, acc[r][cc]);
                    }
                }
            }
            for cc in 0..nc {
                x[c0 + cc] = [acc[0][cc], acc[1][cc], acc[2][cc]];
            }
            c0 += nc;
        }
        for (e, &(r, s)) in ENTRIES.iter().enumerate() {
            let mut acc = _mm256_mul_pd(x[0][r], x[0][s]);
            for xc in &x[1..] {
                acc = _mm256_fmadd_pd(xc[r], xc[s], acc);
            }
            // SAFETY: dg[e] holds LANES = 4 values; unaligned store.
            #[allow(unsafe_code)]
            unsafe {
                _mm256_storeu_pd(dg[e].as_mut_ptr(), acc)
            };
        }
    }
}

/// One exchange step as every block takes it (see the module's text).
#[derive(Clone, Debug)]
pub struct Update {
    /// `U'` on the varying columns, a row per column: `(U'_j0, U'_j1, U'_j2, 0)`.
    pub urows: Vec<[f64; 4]>,
    /// The constant columns' share of every `P_k`: `pc[r][c]`.
    pub pc: [[f64; 3]; 3],
    /// 1 for an addition, -1 for a removal.
    pub sign: f64,
}

impl Update {
    /// The update from `U'` (m values per column, in the pool's column order).
    #[cfg(test)]
    pub fn new(lanes: &Lanes, u: [&[f64]; 3], sign: f64) -> Self {
        Self::new_in(Vec::new(), lanes, u, sign)
    }

    /// [`Update::new`] with its rows written into `urows` (whose allocation it keeps).
    pub fn new_in(mut urows: Vec<[f64; 4]>, lanes: &Lanes, u: [&[f64]; 3], sign: f64) -> Self {
        urows.clear();
        urows.extend(lanes.varying.iter().map(|&c| [u[0][c], u[1][c], u[2][c], 0.0]));
        let mut pc = [[0.0; 3]; 3];
        for (r, pr) in pc.iter_mut().enumerate() {
            for (c, v) in pr.iter_mut().enumerate() {
                let mut terms = lanes.constant.iter().map(|(col, rows)| (rows[r], u[c][*col]));
                if let Some((x, y)) = terms.next() {
                    *v = terms.fold(x * y, |acc, (x, y)| x.mul_add(y, acc));
                }
            }
        }
        Self { urows, pc, sign }
    }
}

/// `D -= sign ((P_r0 P_s0 + P_r1 P_s1) + P_r2 P_s2)` for the six entries of one block, from the
/// rows of `P` (`p[r][c]`).
#[inline(always)]
fn apply(d: [f64; 6], p: &[[f64; 4]; 3], sign: f64) -> [f64; 6] {
    std::array::from_fn(|e| {
        let (r, s) = ENTRIES[e];
        let t = p[r][2].mul_add(p[s][2], p[r][1].mul_add(p[s][1], p[r][0] * p[s][0]));
        d[e] - sign * t
    })
}

/// `P_k` of configuration `lane` of a group (`jg`: its rows), by the portable arithmetic.
#[inline(always)]
fn product(jg: &[f64], mv: usize, lane: usize, up: &Update) -> [[f64; 4]; 3] {
    std::array::from_fn(|r| {
        let mut acc = [up.pc[r][0], up.pc[r][1], up.pc[r][2], 0.0];
        for (j, u) in up.urows[..mv].iter().enumerate() {
            let x = jg[(r * mv + j) * LANES + lane];
            for c in 0..3 {
                acc[c] = x.mul_add(u[c], acc[c]);
            }
        }
        acc
    })
}

/// Block k (`d`: its group) after `up`, portable.
fn update_portable(lanes: &Lanes, d: &mut Group, k: usize, up: &Update) {
    let (g, lane) = (k / LANES, k % LANES);
    let p = product(lanes.group(g), lanes.varying.len(), lane, up);
    let new = apply(std::array::from_fn(|e| d[e][lane]), &p, up.sign);
    for e in 0..6 {
        d[e][lane] = new[e];
    }
}

/// The lanes of group g that hold configurations of a pool of `len`, as bits.
pub fn valid_lanes(len: usize, g: usize) -> u8 {
    let n = len.saturating_sub(g * LANES).min(LANES);
    ((1u16 << n) - 1) as u8
}

/// Brings the blocks of every group `want` selects up to date: the updates of `pending` from
/// `applied[g]` on, in order. A group is brought up to date whole, all its configurations
/// together, even when only some of them are to be read: the vector does the work of four in the
/// time of one, and a configuration not read now takes the same updates later anyway once an
/// excursion is kept.
pub fn catch_up(lanes: &Lanes, pending: &[Update], d: &mut [Group], applied: &mut [u32], want: impl Fn(usize) -> bool) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx512f")
        && std::arch::is_x86_feature_detected!("avx2")
        && std::arch::is_x86_feature_detected!("fma")
    {
        // SAFETY: the CPU was just found to support AVX-512F, AVX2 and FMA, the only requirement
        // of `catch_up_avx512`.
        #[allow(unsafe_code)]
        unsafe {
            catch_up_avx512(lanes, pending, d, applied, want)
        };
        return;
    }
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
        // SAFETY: the CPU was just found to support AVX2 and FMA, the only requirement of
        // `catch_up_avx2`.
        #[allow(unsafe_code)]
        unsafe {
            catch_up_avx2(lanes, pending, d, applied, want)
        };
        return;
    }
    catch_up_portable(lanes, pending, d, applied, want);
}

/// [`catch_up`] without vector extensions, one configuration and one update at a time.
pub fn catch_up_portable(lanes: &Lanes, pending: &[Update], d: &mut [Group], applied: &mut [u32], want: impl Fn(usize) -> bool) {
    let len = pending.len() as u32;
    for (g, (dg, ag)) in d.iter_mut().zip(applied.iter_mut()).enumerate().take(lanes.groups) {
        if *ag == len || !want(g) {
            continue;
        }
        for k in (g * LANES..(g + 1) * LANES).filter(|&k| k < lanes.len) {
            for up in &pending[*ag as usize..] {
                update_portable(lanes, dg, k, up);
            }
        }
        *ag = len;
    }
}

/// [`catch_up`] with AVX2: a group's configurations in the lanes of one vector.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn catch_up_avx2(lanes: &Lanes, pending: &[Update], d: &mut [Group], applied: &mut [u32], want: impl Fn(usize) -> bool) {
    let len = pending.len() as u32;
    let mv = lanes.varying.len();
    assert!(lanes.j.len() >= lanes.groups * 3 * mv * LANES);
    assert!(pending.iter().all(|up| up.urows.len() == mv));
    for (g, (dg, ag)) in d.iter_mut().zip(applied.iter_mut()).enumerate().take(lanes.groups) {
        if *ag == len || !want(g) {
            continue;
        }
        avx2::dense(lanes.group(g), mv, &pending[*ag as usize..], dg);
        *ag = len;
    }
}

/// [`catch_up`] with AVX-512: two neighbouring groups that both are to be brought up to date from
/// the same update on go together, their eight configurations in the lanes of one vector (the
/// same operations lane by lane as [`avx2::dense`], so the same numbers); any other group as
/// [`catch_up_avx2`] takes it.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
fn catch_up_avx512(lanes: &Lanes, pending: &[Update], d: &mut [Group], applied: &mut [u32], want: impl Fn(usize) -> bool) {
    let len = pending.len() as u32;
    let mv = lanes.varying.len();
    let groups = lanes.groups.min(d.len()).min(applied.len());
    assert!(lanes.j.len() >= groups * 3 * mv * LANES);
    assert!(pending.iter().all(|up| up.urows.len() == mv));
    let due = |g: usize, applied: &[u32]| applied[g] != len && want(g);
    let mut g = 0;
    while g < groups {
        if !due(g, applied) {
            g += 1;
            continue;
        }
        let from = applied[g] as usize;
        if g + 1 < groups && applied[g + 1] == applied[g] && due(g + 1, applied) {
            let (first, second) = d[g..g + 2].split_at_mut(1);
            avx512::dense_pair(lanes.group(g), lanes.group(g + 1), mv, &pending[from..], &mut first[0], &mut second[0]);
            applied[g] = len;
            applied[g + 1] = len;
            g += 2;
        } else {
            avx2::dense(lanes.group(g), mv, &pending[from..], &mut d[g]);
            applied[g] = len;
            g += 1;
        }
    }
}

#[cfg(target_arch = "x86_64")]
mod avx512 {
    use std::arch::x86_64::{
        __m512d, _mm256_loadu_pd, _mm256_storeu_pd, _mm512_add_pd, _mm512_castpd256_pd512, _mm512_extractf64x4_pd, _mm512_fmadd_pd,
        _mm512_insertf64x4, _mm512_mul_pd, _mm512_set1_pd, _mm512_sub_pd,
    };

    use super::{ENTRIES, Group, LANES, Update};

    /// The groups `d0` and `d1` (rows `j0` and `j1`) after the updates `ups`, in order: group 0 in
    /// the low four lanes, group 1 in the high four, each lane taking the operations of
    /// [`super::avx2::dense`] in the same order.
    #[inline]
    #[target_feature(enable = "avx512f,avx2,fma")]
    pub(super) fn dense_pair(j0: &[f64], j1: &[f64], mv: usize, ups: &[Update], d0: &mut Group, d1: &mut Group) {
        assert!(j0.len() >= 3 * mv * LANES && j1.len() >= 3 * mv * LANES && ups.iter().all(|up| up.urows.len() >= mv));
        let (p0, p1) = (j0.as_ptr(), j1.as_ptr());
        // SAFETY: d0[e] and d1[e] hold LANES = 4 values; unaligned loads.
        #[allow(unsafe_code)]
        let mut dv: [__m512d; 6] = std::array::from_fn(|e| unsafe {
            _mm512_insertf64x4::<1>(_mm512_castpd256_pd512(_mm256_loadu_pd(d0[e].as_ptr())), _mm256_loadu_pd(d1[e].as_ptr()))
        });
        for up in ups {
            let mut acc: [[__m512d; 3]; 3] = std::array::from_fn(|r| std::array::from_fn(|c| _mm512_set1_pd(up.pc[r][c])));
            for (j, u) in up.urows[..mv].iter().enumerate() {
                // SAFETY: (r * mv + j) * LANES + LANES <= 3 * mv * LANES <= the length of each
                // group's rows (asserted).
                #[allow(unsafe_code)]
                let x: [__m512d; 3] = std::array::from_fn(|r| unsafe {
                    let at = (r * mv + j) * LANES;
                    _mm512_insertf64x4::<1>(_mm512_castpd256_pd512(_mm256_loadu_pd(p0.add(at))), _mm256_loadu_pd(p1.add(at)))
                });
                let y = [_mm512_set1_pd(u[0]), _mm512_set1_pd(u[1]), _mm512_set1_pd(u[2])];
                for r in 0..3 {
                    for c in 0..3 {
                        acc[r][c] = _mm512_fmadd_pd(x[r], y[c], acc[r][c]);
                    }
                }
            }
            let add = up.sign < 0.0;
            for (e, &(r, s)) in ENTRIES.iter().enumerate() {
                let t = _mm512_mul_pd(acc[r][0], acc[s][0]);
                let t = _mm512_fmadd_pd(acc[r][1], acc[s][1], t);
                let t = _mm512_fmadd_pd(acc[r][2], acc[s][2], t);
                dv[e] = if add { _mm512_add_pd(dv[e], t) } else { _mm512_sub_pd(dv[e], t) };
            }
        }
        for e in 0..6 {
            // SAFETY: as above; unaligned stores.
            #[allow(unsafe_code)]
            unsafe {
                _mm256_storeu_pd(d0[e].as_mut_ptr(), _mm512_extractf64x4_pd::<0>(dv[e]));
                _mm256_storeu_pd(d1[e].as_mut_ptr(), _mm512_extractf64x4_pd::<1>(dv[e]));
            }
        }
    }
}

#[cfg(target_arch = "x86_64")]
mod avx2 {
    use std::arch::x86_64::{
        __m256d, _mm256_add_pd, _mm256_fmadd_pd, _mm256_loadu_pd, _mm256_mul_pd, _mm256_set1_pd, _mm256_storeu_pd, _mm256_sub_pd,
    };

    use super::{ENTRIES, Group, LANES, Update};

    /// Group `d` after the updates `ups`, in order: every configuration of the group in one
    /// vector (`jg`: the group's rows, `mv` varying columns). The blocks stay in registers from
    /// the first update to the last.
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    pub(super) fn dense(jg: &[f64], mv: usize, ups: &[Update], d: &mut Group) {
        assert!(jg.len() >= 3 * mv * LANES && ups.iter().all(|up| up.urows.len() >= mv));
        let jp = jg.as_ptr();
        // SAFETY: d[e] holds LANES = 4 values; unaligned loads.
        #[allow(unsafe_code)]
        let mut dv: [__m256d; 6] = std::array::from_fn(|e| unsafe { _mm256_loadu_pd(d[e].as_ptr()) });
        for up in ups {
            let mut acc: [[__m256d; 3]; 3] = std::array::from_fn(|r| std::array::from_fn(|c| _mm256_set1_pd(up.pc[r][c])));
            for (j, u) in up.urows[..mv].iter().enumerate() {
                // SAFETY: (r * mv + j) * LANES + LANES <= 3 * mv * LANES <= jg.len() (asserted).
                #[allow(unsafe_code)]
                let x: [__m256d; 3] = std::array::from_fn(|r| unsafe { _mm256_loadu_pd(jp.add((r * mv + j) * LANES)) });
                let y = [_mm256_set1_pd(u[0]), _mm256_set1_pd(u[1]), _mm256_set1_pd(u[2])];
                for r in 0..3 {
                    for c in 0..3 {
                        acc[r][c] = _mm256_fmadd_pd(x[r], y[c], acc[r][c]);
                    }
                }
            }
            // `D - sign t` with sign = +-1 is exactly `D - t` or `D + t`.
            let add = up.sign < 0.0;
            for (e, &(r, s)) in ENTRIES.iter().enumerate() {
                let t = _mm256_mul_pd(acc[r][0], acc[s][0]);
                let t = _mm256_fmadd_pd(acc[r][1], acc[s][1], t);
                let t = _mm256_fmadd_pd(acc[r][2], acc[s][2], t);
                dv[e] = if add { _mm256_add_pd(dv[e], t) } else { _mm256_sub_pd(dv[e], t) };
            }
        }
        for e in 0..6 {
            // SAFETY: as above; unaligned stores.
            #[allow(unsafe_code)]
            unsafe {
                _mm256_storeu_pd(d[e].as_mut_ptr(), dv[e])
            };
        }
    }
}

/// `det(I + sign D_k)` for the configurations of group `d`, each as
/// `a (b c - z z) - x (x c - z y) + y (x z - b y)` with `a, b, c` the diagonal of `I + sign D_k`
/// and `x, y, z` its entries (0, 1), (0, 2), (1, 2) (separate products and sums, no fused ones).
pub fn scores(d: &Group, sign: f64) -> [f64; LANES] {
    std::array::from_fn(|l| {
        let (a, b, c) = (1.0 + sign * d[0][l], 1.0 + sign * d[1][l], 1.0 + sign * d[2][l]);
        let (x, y, z) = (sign * d[3][l], sign * d[4][l], sign * d[5][l]);
        a * (b * c - z * z) - x * (x * c - z * y) + y * (x * z - b * y)
    })
}

/// The key that orders a score for the pick: its bits when it is positive (positive floats order
/// as their bits), -1 otherwise (a score that is not positive counts as minus infinity).
#[inline(always)]
fn key(v: f64) -> i64 {
    if v > 0.0 { v.to_bits() as i64 } else { -1 }
}

/// Among the configurations `cand` selects (`cand(g)`: the lanes of group g, as bits), the one
/// with the largest `det(I + sign D_k)` ([`scores`]), the last of equal ones; scores that are not
/// positive count as minus infinity. `None` when there is no candidate.
pub fn best(d: &[Group], sign: f64, cand: impl Fn(usize) -> u8) -> Option<usize> {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU was just found to support AVX2, the only requirement of `best_avx2`.
        #[allow(unsafe_code)]
        return unsafe { best_avx2(d, sign, cand) };
    }
    best_portable(d, sign, cand)
}

/// [`best`] one lane at a time. Per lane, the best candidate so far as (key, group), `i64::MIN`
/// (no key) for none yet; then the lanes' bests, the larger configuration index among equal keys.
fn best_portable(d: &[Group], sign: f64, cand: impl Fn(usize) -> u8) -> Option<usize> {
    let (mut kbest, mut gbest) = ([i64::MIN; LANES], [0usize; LANES]);
    for (g, dg) in d.iter().enumerate() {
        let bits = cand(g);
        let sc = scores(dg, sign);
        for l in 0..LANES {
            let k = key(sc[l]);
            if bits >> l & 1 == 1 && k >= kbest[l] {
                (kbest[l], gbest[l]) = (k, g);
            }
        }
    }
    (0..LANES).filter(|&l| kbest[l] > i64::MIN).map(|l| (kbest[l], gbest[l] * LANES + l)).max().map(|(_, k)| k)
}

/// [`best`] with AVX2: the scores, keys and running bests of a group's lanes in one vector each.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn best_avx2(d: &[Group], sign: f64, cand: impl Fn(usize) -> u8) -> Option<usize> {
    use std::arch::x86_64::{
        _CMP_GT_OQ, _mm256_add_pd, _mm256_and_si256, _mm256_andnot_si256, _mm256_blendv_pd, _mm256_castpd_si256, _mm256_castsi256_pd,
        _mm256_cmp_pd, _mm256_cmpeq_epi64, _mm256_cmpgt_epi64, _mm256_loadu_pd, _mm256_mul_pd, _mm256_set1_epi64x, _mm256_set1_pd,
        _mm256_setr_epi64x, _mm256_setzero_pd, _mm256_storeu_si256, _mm256_sub_pd,
    };
    let (one, s, zero) = (_mm256_set1_pd(1.0), _mm256_set1_pd(sign), _mm256_setzero_pd());
    let minus_one = _mm256_set1_epi64x(-1);
    let lane_bit = _mm256_setr_epi64x(1, 2, 4, 8);
    let mut kbest = _mm256_set1_epi64x(i64::MIN);
    let mut gbest = _mm256_set1_epi64x(0);
    for (g, dg) in d.iter().enumerate() {
        // SAFETY: each entry of a group holds LANES = 4 values; unaligned loads.
        #[allow(unsafe_code)]
        let e: [_; 6] = std::array::from_fn(|i| unsafe { _mm256_loadu_pd(dg[i].as_ptr()) });
        let (a, b, c) = (
            _mm256_add_pd(one, _mm256_mul_pd(s, e[0])),
            _mm256_add_pd(one, _mm256_mul_pd(s, e[1])),
            _mm256_add_pd(one, _mm256_mul_pd(s, e[2])),
        );
        let (x, y, z) = (_mm256_mul_pd(s, e[3]), _mm256_mul_pd(s, e[4]), _mm256_mul_pd(s, e[5]));
        let t0 = _mm256_mul_pd(a, _mm256_sub_pd(_mm256_mul_pd(b, c), _mm256_mul_pd(z, z)));
        let t1 = _mm256_mul_pd(x, _mm256_sub_pd(_mm256_mul_pd(x, c), _mm256_mul_pd(z, y)));
        let t2 = _mm256_mul_pd(y, _mm256_sub_pd(_mm256_mul_pd(x, z), _mm256_mul_pd(b, y)));
        let v = _mm256_add_pd(_mm256_sub_pd(t0, t1), t2);
        // key: the bits of a positive score, -1 otherwise.
        let positive = _mm256_cmp_pd::<_CMP_GT_OQ>(v, zero);
        let k = _mm256_castpd_si256(_mm256_blendv_pd(_mm256_castsi256_pd(minus_one), v, positive));
        let bits = _mm256_set1_epi64x(cand(g) as i64);
        let is_cand = _mm256_cmpeq_epi64(_mm256_and_si256(bits, lane_bit), lane_bit);
        // take = candidate and not (best > key).
        let take = _mm256_andnot_si256(_mm256_cmpgt_epi64(kbest, k), is_cand);
        kbest = _mm256_castpd_si256(_mm256_blendv_pd(_mm256_castsi256_pd(kbest), _mm256_castsi256_pd(k), _mm256_castsi256_pd(take)));
        let gv = _mm256_set1_epi64x(g as i64);
        gbest = _mm256_castpd_si256(_mm256_blendv_pd(_mm256_castsi256_pd(gbest), _mm256_castsi256_pd(gv), _mm256_castsi256_pd(take)));
    }
    let (mut kb, mut gb) = ([0i64; LANES], [0i64; LANES]);
    // SAFETY: four i64 values each; unaligned stores.
    #[allow(unsafe_code)]
    unsafe {
        _mm256_storeu_si256(kb.as_mut_ptr().cast(), kbest);
        _mm256_storeu_si256(gb.as_mut_ptr().cast(), gbest);
    }
    (0..LANES).filter(|&l| kb[l] > i64::MIN).map(|l| (kb[l], gb[l] as usize * LANES + l)).max().map(|(_, k)| k)
}

/// The block of configuration k as a 3 x 3 matrix (for checks).
#[cfg(test)]
pub fn block(d: &[Group], k: usize) -> nalgebra::Matrix3<f64> {
    let (g, l) = (k / LANES, k % LANES);
    let e = |i: usize| d[g][i][l];
    nalgebra::Matrix3::new(e(0), e(3), e(4), e(3), e(1), e(5), e(4), e(5), e(2))
}

#[cfg(test)]
mod tests {
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;

    /// A stacked Jacobian of `len` random configurations and `m` columns, columns 2 and 5 (when
    /// there) the same in every configuration.
    fn random_j(len: usize, m: usize, rng: &mut ChaCha8Rng) -> DMatrix<f64> {
        let mut j = DMatrix::from_fn(3 * len, m, |_, _| rng.random_range(-1.0..1.0));
        for c in [2, 5].into_iter().filter(|&c| c < m) {
            for k in 1..len {
                for r in 0..3 {
                    j[(3 * k + r, c)] = j[(r, c)];
                }
            }
        }
        j
    }

    fn random_update(lanes: &Lanes, m: usize, sign: f64, rng: &mut ChaCha8Rng) -> Update {
        let u: [Vec<f64>; 3] = std::array::from_fn(|_| (0..m).map(|_| rng.random_range(-0.3..0.3)).collect());
        Update::new(lanes, [&u[0], &u[1], &u[2]], sign)
    }

    /// The AVX2 pick equals the portable one and a plain scan with `total_cmp` (the last of
    /// equal maxima), over 200 random block sets of 9 groups with random candidates, scores that
    /// are not positive, ties and no candidate at all.
    #[test]
    fn best_is_the_last_largest_score_among_the_candidates() {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        for case in 0..200 {
            let mut d: Vec<Group> = (0..9)
                .map(|_| {
                    std::array::from_fn(|e| {
                        std::array::from_fn(|_| if e < 3 { rng.random_range(-0.5..2.0) } else { rng.random_range(-0.3..0.3) })
                    })
                })
                .collect();
            if case % 5 == 0 {
                // Ties: a copy of one configuration's block in two others.
                for (g, l) in [(4, 2), (7, 1)] {
                    for e in 0..6 {
                        d[g][e][l] = d[1][e][3];
                    }
                }
            }
            let bits: Vec<u8> = (0..9).map(|g| if case % 17 == 3 { 0 } else { rng.random_range(0..16u8) & valid_lanes(34, g) }).collect();
            for sign in [1.0, -1.0] {
                let plain = (0..34)
                    .filter(|&k| bits[k / LANES] >> (k % LANES) & 1 == 1)
                    .map(|k| (k, scores(&d[k / LANES], sign)[k % LANES]))
                    .map(|(k, v)| (k, if v > 0.0 { v } else { f64::NEG_INFINITY }))
                    .max_by(|a, b| a.1.total_cmp(&b.1))
                    .map(|(k, _)| k);
                assert_eq!(best_portable(&d, sign, |g| bits[g]), plain, "case {case}");
                assert_eq!(best(&d, sign, |g| bits[g]), plain, "case {case}");
            }
        }
    }

    /// The start blocks are `J_k M^-1 J_k^T` (nalgebra, to rounding) and the AVX2 build gives the
    /// portable one's numbers bit for bit: 23 configurations, 31 and 6 columns (two constant).
    #[test]
    fn start_blocks_are_the_blocks_of_j_m_inverse_j_t() {
        let mut rng = ChaCha8Rng::seed_from_u64(6);
        for m in [31, 6] {
            let len = 23;
            let j = random_j(len, m, &mut rng);
            let lanes = Lanes::new(&j);
            let order: Vec<usize> = lanes.varying.iter().copied().chain(lanes.constant.iter().map(|(c, _)| *c)).collect();
            let jp = DMatrix::from_fn(3 * len, m, |i, c| j[(i, order[c])]);
            let info = jp.tr_mul(&jp);
            let linv = info.clone().cholesky().unwrap().l().try_inverse().unwrap();
            let d = start_blocks(&lanes, &linv);
            let minv = info.try_inverse().unwrap();
            for k in 0..len {
                let jk = jp.rows(3 * k, 3);
                let expected = jk * &minv * jk.transpose();
                let got = block(&d, k);
                assert!((got - &expected).abs().max() <= 1e-12 * (1.0 + expected.abs().max()), "m = {m}, k = {k}: {got} vs {expected}");
            }
            let rows: Vec<f64> = (0..m).flat_map(|c| (0..=c).map(move |i| (c, i))).map(|(c, i)| linv[(c, i)]).collect();
            let mut slow = vec![[[0.0; LANES]; 6]; lanes.groups];
            start_blocks_portable(&lanes, m, &rows, &mut slow);
            // Every configuration's entries (the padded lanes of the last group hold no block).
            let bits = |d: &[Group]| {
                (0..len).flat_map(|k| (0..6).map(move |e| (k, e))).map(|(k, e)| d[k / LANES][e][k % LANES].to_bits()).collect::<Vec<_>>()
            };
            assert_eq!(bits(&d[..]), bits(&slow), "m = {m}");
        }
    }

    #[test]
    fn constant_columns_are_found_and_left_out_of_the_lanes() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let j = random_j(9, 7, &mut rng);
        let lanes = Lanes::new(&j);
        assert_eq!(lanes.varying, vec![0, 1, 3, 4, 6]);
        assert_eq!(lanes.constant.iter().map(|(c, _)| *c).collect::<Vec<_>>(), vec![2, 5]);
        assert_eq!(lanes.groups, 3);
        // Configuration 6 (group 1, lane 2), row 1, varying column 3 (pool column 4).
        assert_eq!(lanes.j[((3 + 1) * 5 + 3) * LANES + 2], j[(3 * 6 + 1, 4)]);
        // The padded lanes of the last group are zero.
        assert!((1..LANES).all(|lane| lanes.j[(2 * 3 * 5) * LANES + lane] == 0.0));
    }

    /// The portable update equals `D - sign (J_k U')(J_k U')^T` computed with nalgebra, to
    /// rounding: 13 configurations, 9 columns (two constant), both signs.
    #[test]
    fn portable_update_is_the_symmetric_rank_3_product() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let (len, m) = (13, 9);
        let j = random_j(len, m, &mut rng);
        let lanes = Lanes::new(&j);
        for sign in [1.0, -1.0] {
            let u: [Vec<f64>; 3] = std::array::from_fn(|_| (0..m).map(|_| rng.random_range(-0.3..0.3)).collect());
            let up = Update::new(&lanes, [&u[0], &u[1], &u[2]], sign);
            let um = DMatrix::from_fn(m, 3, |i, c| u[c][i]);
            let mut d = vec![[[0.0; LANES]; 6]; lanes.groups];
            for k in 0..len {
                let before = nalgebra::Matrix3::new(1.0, 0.2, 0.1, 0.2, 2.0, 0.3, 0.1, 0.3, 3.0) * k as f64;
                for (e, (r, s)) in ENTRIES.iter().enumerate() {
                    d[k / LANES][e][k % LANES] = before[(*r, *s)];
                }
                update_portable(&lanes, &mut d[k / LANES], k, &up);
                let p = j.rows(3 * k, 3) * &um;
                let expected = before - (&p * p.transpose()) * sign;
                let got = block(&d, k);
                assert!((got - expected).abs().max() <= 1e-13 * (1.0 + expected.abs().max()), "k = {k}: {got} vs {expected}");
            }
        }
    }

    /// The AVX2 catch-up gives the portable one's numbers bit for bit: 37 configurations, 31
    /// columns (two constant), 6 updates of both signs taken in three rounds by different sets of
    /// groups, so that groups take different numbers of updates at once.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn avx2_catch_up_equals_the_portable_one_bit_for_bit() {
        if !(std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")) {
            eprintln!("avx2_catch_up_equals_the_portable_one_bit_for_bit: this CPU has no AVX2 and FMA; the portable kernel runs");
            return;
        }
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let (len, m) = (37, 31);
        let lanes = Lanes::new(&random_j(len, m, &mut rng));
        let start: Vec<Group> =
            (0..lanes.groups).map(|_| std::array::from_fn(|_| std::array::from_fn(|_| rng.random_range(-1.0..1.0)))).collect();
        let pending: Vec<Update> = (0..6).map(|i| random_update(&lanes, m, if i % 2 == 0 { 1.0 } else { -1.0 }, &mut rng)).collect();
        let (mut fast, mut slow) = ((start.clone(), vec![0u32; lanes.groups]), (start, vec![0u32; lanes.groups]));
        let rounds: [(usize, &dyn Fn(usize) -> bool); 3] = [(2, &|g| g % 3 == 0), (4, &|g| g % 5 < 2 || g > 7), (6, &|_| true)];
        for (n, want) in rounds {
            #[allow(unsafe_code)]
            // SAFETY: the CPU supports AVX2 and FMA (checked above).
            unsafe {
                catch_up_avx2(&lanes, &pending[..n], &mut fast.0, &mut fast.1, want)
            };
            catch_up_portable(&lanes, &pending[..n], &mut slow.0, &mut slow.1, want);
            assert_eq!(fast.1, slow.1);
            // Every configuration's entries (the padded lanes of the last group hold no block).
            let bits = |d: &[Group]| {
                (0..len).flat_map(|k| (0..6).map(move |e| (k, e))).map(|(k, e)| d[k / LANES][e][k % LANES].to_bits()).collect::<Vec<_>>()
            };
            assert_eq!(bits(&fast.0), bits(&slow.0), "after the round of {n} updates");
        }
    }

    /// The AVX-512 catch-up (neighbouring groups in pairs, the others alone) gives the portable
    /// one's numbers bit for bit: 37 configurations (10 groups, the last padded), 31 columns (two
    /// constant), 7 updates of both signs taken in four rounds by different sets of groups, so
    /// that neighbours are paired, left alone, or due from different updates on.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn avx512_catch_up_equals_the_portable_one_bit_for_bit() {
        if !(std::arch::is_x86_feature_detected!("avx512f")
            && std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("fma"))
        {
            eprintln!("avx512_catch_up_equals_the_portable_one_bit_for_bit: this CPU has no AVX-512F; the AVX2 or portable kernel runs");
            return;
        }
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        let (len, m) = (37, 31);
        let lanes = Lanes::new(&random_j(len, m, &mut rng));
        assert_eq!(lanes.groups, 10);
        let start: Vec<Group> =
            (0..lanes.groups).map(|_| std::array::from_fn(|_| std::array::from_fn(|_| rng.random_range(-1.0..1.0)))).collect();
        let pending: Vec<Update> = (0..7).map(|i| random_update(&lanes, m, if i % 3 == 1 { -1.0 } else { 1.0 }, &mut rng)).collect();
        let (mut fast, mut slow) = ((start.clone(), vec![0u32; lanes.groups]), (start, vec![0u32; lanes.groups]));
        let rounds: [(usize, &dyn Fn(usize) -> bool); 4] =
            [(2, &|g| g % 3 == 0), (3, &|g| g != 5 && g != 6), (5, &|g| g % 5 < 2 || g > 7), (7, &|_| true)];
        for (n, want) in rounds {
            #[allow(unsafe_code)]
            // SAFETY: the CPU supports AVX-512F, AVX2 and FMA (checked above).
            unsafe {
                catch_up_avx512(&lanes, &pending[..n], &mut fast.0, &mut fast.1, want)
            };
            catch_up_portable(&lanes, &pending[..n], &mut slow.0, &mut slow.1, want);
            assert_eq!(fast.1, slow.1);
            let bits = |d: &[Group]| {
                (0..len).flat_map(|k| (0..6).map(move |e| (k, e))).map(|(k, e)| d[k / LANES][e][k % LANES].to_bits()).collect::<Vec<_>>()
            };
            assert_eq!(bits(&fast.0), bits(&slow.0), "after the round of {n} updates");
        }
    }
}
