//! Guarded decompositions: every SVD and symmetric eigen-decomposition of calsim goes through here,
//! with a NaN/infinity guard and an iteration cap, so that no numerical routine can spin. A matrix
//! that is not finite, or a decomposition that does not converge within the cap, gives `None`,
//! which the caller turns into an error that names what failed.

use nalgebra::{DMatrix, DVector, Dim, Matrix3, OMatrix, SVD, SymmetricEigen};

/// Convergence tolerance of the SVD: nalgebra's own default for `svd()` (5 machine epsilons), so
/// that a guarded decomposition gives the same bits as an unguarded one.
const SVD_EPS: f64 = 5.0 * f64::EPSILON;

/// Iteration cap of the QR sweeps (nalgebra counts iterations in all; a 31 x 31 problem converges
/// in about a hundred).
pub const MAX_ITERATIONS: usize = 100_000;

fn finite<D: Dim, C: Dim>(m: &OMatrix<f64, D, C>) -> bool
where
    nalgebra::DefaultAllocator: nalgebra::allocator::Allocator<D, C>,
{
    m.iter().all(|x| x.is_finite())
}

/// SVD of a dynamic matrix, or `None` when it has a non-finite entry or does not converge.
pub fn svd(m: DMatrix<f64>, compute_u: bool, compute_v: bool) -> Option<SVD<f64, nalgebra::Dyn, nalgebra::Dyn>> {
    if m.is_empty() || !finite(&m) {
        return None;
    }
    SVD::try_new(m, compute_u, compute_v, SVD_EPS, MAX_ITERATIONS)
}

/// SVD of a 3 x 3 matrix, or `None` when it has a non-finite entry or does not converge.
pub fn svd3(m: Matrix3<f64>) -> Option<SVD<f64, nalgebra::U3, nalgebra::U3>> {
    if !finite(&m) {
        return None;
    }
    SVD::try_new(m, true, true, SVD_EPS, MAX_ITERATIONS)
}

/// Eigen-decomposition of a symmetric matrix, or `None` when it has a non-finite entry or does not
/// converge.
pub fn symmetric_eigen(m: DMatrix<f64>) -> Option<SymmetricEigen<f64, nalgebra::Dyn>> {
    if m.is_empty() || !finite(&m) {
        return None;
    }
    SymmetricEigen::try_new(m, f64::EPSILON, MAX_ITERATIONS)
}

/// The second factor of [`gemm_product`]: `b[(l, j)] = data[l * row_stride + j * col_stride]`.
#[derive(Clone, Copy)]
pub struct Factor<'a> {
    /// The entries.
    pub data: &'a [f64],
    /// Step between rows.
    pub row_stride: usize,
    /// Step between columns.
    pub col_stride: usize,
}

/// `out = a * b` (a: column-major m x k, `out`: column-major m x n), the same to the bit as
/// `out.gemm(1.0, a, b, 0.0)` with nalgebra, without its packing buffers (a fresh allocation per
/// call, and page faults with it) or a transposed copy of `b`. `symmetric`: `a * b` is known to be
/// symmetric (as `x x^T`), so each entry (i, j) with j >= i is summed once and mirrored.
///
/// nalgebra hands products with more than five rows and columns to matrixmultiply, whose kernels
/// sum each entry's products in order from zero over blocks of 256 (its `kc`) and add the blocks in
/// turn, with fused multiply-adds where its kernel uses them (AVX-512, AVX2 with FMA, aarch64) and
/// separate products and sums otherwise; that order is followed here. Smaller products go through
/// `gemm` itself (nalgebra's own loops).
pub fn gemm_product(a: &DMatrix<f64>, b: Factor<'_>, n: usize, out: &mut DMatrix<f64>, symmetric: bool) {
    let (m, k) = a.shape();
    assert_eq!(out.shape(), (m, n), "output is m x n");
    if m <= 5 || n <= 5 || k <= 5 {
        let b = DMatrix::from_fn(k, n, |l, j| b.data[l * b.row_stride + j * b.col_stride]);
        out.gemm(1.0, a, &b, 0.0);
        return;
    }
    let (x, y) = (a.as_slice(), out.as_mut_slice());
    #[cfg(target_arch = "x86_64")]
    {
        let avx512 = std::arch::is_x86_feature_detected!("avx512f");
        if avx512 || (std::arch::is_x86_feature_detected!("fma") && std::arch::is_x86_feature_detected!("avx2")) {
            // SAFETY: the CPU was just found to support AVX2 and FMA (matrixmultiply's AVX-512
            // kernel runs only on CPUs that have both), or AVX-512F: the requirements of
            // `product_fused_avx2` and `product_fused_avx512`.
            #[allow(unsafe_code)]
            unsafe {
                if avx512 && m >= 8 && n >= 8 {
                    product_fused_avx512(x, (m, k), b, n, y, symmetric);
                } else {
                    product_fused_avx2(x, (m, k), b, n, y, symmetric);
                }
            }
        } else {
            product_body(x, (m, k), b, n, y, symmetric, block_sums::<false, 4, 4>);
        }
    }
    #[cfg(target_arch = "aarch64")]
    product_body(x, (m, k), b, n, y, symmetric, block_sums::<true, 4, 4>);
    #[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
    product_body(x, (m, k), b, n, y, symmetric, block_sums::<false, 4, 4>);
}

/// `out = a x` (`a`: column-major m x k, `x`: k values, `out`: m), the same to the bit as
/// nalgebra 0.35's `a.mul_to(&x, &mut out)` for a vector: its gemv, `out = x_0 a_0` and then
/// `out += x_j a_j` column by column, each product rounded and then added (no fused multiply-adds);
/// compiled for AVX2 where the CPU has it (four rows at a time, the same roundings).
pub fn matrix_vector(a: &DMatrix<f64>, x: &[f64], out: &mut [f64]) {
    assert_eq!(a.ncols(), x.len(), "a is m x k, x has k values");
    assert_eq!(a.nrows(), out.len(), "out has m values");
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU was just found to support AVX2, the only requirement of
        // `matrix_vector_avx2`.
        #[allow(unsafe_code)]
        unsafe {
            matrix_vector_avx2(a, x, out)
        };
        return;
    }
    matrix_vector_body(a, x, out);
}

/// [`matrix_vector_body`] compiled for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn matrix_vector_avx2(a: &DMatrix<f64>, x: &[f64], out: &mut [f64]) {
    matrix_vector_body(a, x, out);
}

#[inline(always)]
fn matrix_vector_body(a: &DMatrix<f64>, x: &[f64], out: &mut [f64]) {
    let m = a.nrows();
    out.fill(0.0);
    for (j, (col, &xj)) in a.as_slice().chunks_exact(m.max(1)).zip(x).enumerate() {
        if j == 0 {
            for (y, &c) in out.iter_mut().zip(col) {
                *y = c * xj;
            }
        } else {
            for (y, &c) in out.iter_mut().zip(col) {
                *y += c * xj;
            }
        }
    }
}

/// [`product_body`] with fused multiply-adds, blocks of 8 x 8, compiled for AVX-512 (m, n >= 8).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
fn product_fused_avx512(a: &[f64], mk: (usize, usize), b: Factor<'_>, n: usize, out: &mut [f64], symmetric: bool) {
    product_body(a, mk, b, n, out, symmetric, block_sums::<true, 8, 8>);
}

/// [`product_body`] with fused multiply-adds, compiled for AVX2 and FMA: blocks of 8 x 4 (two
/// vectors of rows, so eight independent sums) with [`block_sums_avx2_8x4`], 4 x 4 for fewer than
/// 8 rows.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn product_fused_avx2(a: &[f64], mk: (usize, usize), b: Factor<'_>, n: usize, out: &mut [f64], symmetric: bool) {
    if mk.0 >= 8 {
        product_body(a, mk, b, n, out, symmetric, |a, m, b, rc, ls| block_sums_avx2_8x4(a, m, b, rc, ls));
    } else {
        product_body(a, mk, b, n, out, symmetric, block_sums::<true, 4, 4>);
    }
}

/// [`block_sums`] of an 8 x 4 block with fused multiply-adds, written with AVX2 vectors: the
/// compiler leaves the generic form's two vectors of rows as scalar products. Each lane is the
/// same fused multiply-add in the same order, so the sums are the same to the bit.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[allow(unsafe_code)]
fn block_sums_avx2_8x4(a: &[f64], m: usize, b: Factor<'_>, (r, c): (usize, usize), ls: std::ops::Range<usize>) -> [[f64; 8]; 4] {
    use std::arch::x86_64::{_mm256_fmadd_pd, _mm256_loadu_pd, _mm256_set1_pd, _mm256_setzero_pd, _mm256_storeu_pd};
    let mut lo = [_mm256_setzero_pd(); 4];
    let mut hi = [_mm256_setzero_pd(); 4];
    for l in ls {
        let xa: &[f64; 8] = a[l * m + r..][..8].try_into().expect("8 values");
        let xb: [f64; 4] = std::array::from_fn(|t| b.data[l * b.row_stride + (c + t) * b.col_stride]);
        // SAFETY: `xa` holds 8 values, read as two vectors of 4 at offsets 0 and 4.
        let (x0, x1) = unsafe { (_mm256_loadu_pd(xa.as_ptr()), _mm256_loadu_pd(xa.as_ptr().add(4))) };
        for t in 0..4 {
            let y = _mm256_set1_pd(xb[t]);
            lo[t] = _mm256_fmadd_pd(x0, y, lo[t]);
            hi[t] = _mm256_fmadd_pd(x1, y, hi[t]);
        }
    }
    let mut sums = [[0.0; 8]; 4];
    for ((col, lo), hi) in sums.iter_mut().zip(lo).zip(hi) {
        // SAFETY: `col` holds 8 values, written as two vectors of 4 at offsets 0 and 4.
        unsafe {
            _mm256_storeu_pd(col.as_mut_ptr(), lo);
            _mm256_storeu_pd(col.as_mut_ptr().add(4), hi);
        }
    }
    sums
}

/// The entries of `a * b` into `out` in matrixmultiply's summation order (see [`gemm_product`]):
/// blocks of L rows (the lanes; `a` is column-major, so they are contiguous) by R columns, each entry
/// its own running sum; a block that would pass the last row or column is shifted back to end at it
/// (overlapping blocks recompute the same values). Needs m >= L and n >= R.
#[inline(always)]
fn product_body<const L: usize, const R: usize>(
    a: &[f64],
    (m, k): (usize, usize),
    b: Factor<'_>,
    n: usize,
    out: &mut [f64],
    symmetric: bool,
    sums: impl Fn(&[f64], usize, Factor<'_>, (usize, usize), std::ops::Range<usize>) -> [[f64; L]; R],
) {
    /// matrixmultiply's `kc` for f64 (its default; it is a build-time setting of that crate).
    const KC: usize = 256;
    for c0 in (0..n).step_by(R) {
        let c = c0.min(n - R);
        let rows_end = if symmetric { (c + R).min(m) } else { m };
        for r0 in (0..rows_end).step_by(L) {
            let r = r0.min(m - L);
            let mut total = [[0.0_f64; L]; R];
            for kb in (0..k).step_by(KC) {
                let acc = sums(a, m, b, (r, c), kb..(kb + KC).min(k));
                for (t, a) in total.iter_mut().zip(&acc) {
                    for (t, a) in t.iter_mut().zip(a) {
                        *t = if kb == 0 { *a } else { *t + *a };
                    }
                }
            }
            for (t, col) in total.iter().enumerate() {
                for (i, &v) in col.iter().enumerate() {
                    out[(c + t) * m + r + i] = v;
                    if symmetric {
                        out[(r + i) * m + c + t] = v;
                    }
                }
            }
        }
    }
}

/// The sums over `ls` (from zero) of the L x R block of `a * b` at row r and column c, each entry
/// its own running sum in the order of l, fused (`FUSED`) or a product then a sum: the inner loop
/// of [`product_body`].
#[inline(always)]
fn block_sums<const FUSED: bool, const L: usize, const R: usize>(
    a: &[f64],
    m: usize,
    b: Factor<'_>,
    (r, c): (usize, usize),
    ls: std::ops::Range<usize>,
) -> [[f64; L]; R] {
    let mut acc = [[0.0_f64; L]; R];
    for l in ls {
        let xa: &[f64; L] = a[l * m + r..][..L].try_into().expect("L values");
        for (t, acc_col) in acc.iter_mut().enumerate() {
            let xb = b.data[l * b.row_stride + (c + t) * b.col_stride];
            for (s, &xi) in acc_col.iter_mut().zip(xa) {
                *s = if FUSED { xi.mul_add(xb, *s) } else { *s + xi * xb };
            }
        }
    }
    acc
}

/// Eigenvalues of a symmetric matrix (see [`symmetric_eigen`]), the same to the bit as the
/// eigenvalues of [`symmetric_eigen`] without forming the eigenvectors (their Householder product
/// and rotations are most of the work).
///
/// nalgebra's own eigenvalues-only path (`symmetric_eigenvalues`) has no iteration cap, so its
/// implicit QR sweeps are repeated here as nalgebra 0.35's `SymmetricEigen::do_decompose` runs them
/// with `eigenvectors = false` (scaling by the largest entry, its tridiagonalisation, Wilkinson
/// shift, Givens rotations, 2 x 2 blocks and deflation test), with [`MAX_ITERATIONS`]. A test holds
/// the values equal to `SymmetricEigen::try_new`'s.
pub fn symmetric_eigenvalues(mut m: DMatrix<f64>) -> Option<DVector<f64>> {
    use nalgebra::linalg::{givens::GivensRotation, wilkinson_shift};
    use nalgebra::{Matrix2, Vector2};
    if m.is_empty() || !finite(&m) || !m.is_square() {
        return None;
    }
    let eps = f64::EPSILON;
    let dim = m.nrows();
    let m_amax = m.camax();
    if m_amax != 0.0 {
        m.unscale_mut(m_amax);
    }
    let (mut diag, mut off_diag) = tridiagonal(m);
    if dim == 1 {
        diag.scale_mut(m_amax);
        return Some(diag);
    }
    let mut niter = 0;
    let (mut start, mut end) = delimit_subproblem(&diag, &mut off_diag, dim - 1, eps);
    while end != start {
        let subdim = end - start + 1;
        if subdim > 2 {
            let m = end - 1;
            let n = end;
            let mut vec = Vector2::new(diag[start] - wilkinson_shift(diag[m], diag[n], off_diag[m]), off_diag[start]);
            for i in start..n {
                let j = i + 1;
                let Some((rot, norm)) = GivensRotation::cancel_y(&vec) else {
                    break;
                };
                if i > start {
                    off_diag[i - 1] = norm;
                }
                let (mii, mjj, mij) = (diag[i], diag[j], off_diag[i]);
                let cc = rot.c() * rot.c();
                let ss = rot.s() * rot.s();
                let cs = rot.c() * rot.s();
                let b = cs * 2.0 * mij;
                diag[i] = (cc * mii + ss * mjj) - b;
                diag[j] = (ss * mii + cc * mjj) + b;
                off_diag[i] = cs * (mii - mjj) + mij * (cc - ss);
                if i != n - 1 {
                    vec.x = off_diag[i];
                    vec.y = -rot.s() * off_diag[i + 1];
                    off_diag[i + 1] *= rot.c();
                }
            }
            if off_diag[m].abs() <= eps * (diag[m].abs() + diag[n].abs()) {
                end -= 1;
            }
        } else if subdim == 2 {
            let block = Matrix2::new(diag[start], off_diag[start], off_diag[start], diag[start + 1]);
            let eigvals = block.eigenvalues()?;
            diag[start] = eigvals[0];
            diag[start + 1] = eigvals[1];
            end -= 1;
        }
        (start, end) = delimit_subproblem(&diag, &mut off_diag, end, eps);
        niter += 1;
        if niter == MAX_ITERATIONS {
            return None;
        }
    }
    diag.scale_mut(m_amax);
    Some(diag)
}

/// The diagonal and the off-diagonal magnitudes of the symmetric tridiagonal form of `m` (square,
/// n >= 1): the same to the bit as nalgebra 0.35's `SymmetricTridiagonal::new(m).unpack_tridiagonal()`.
///
/// nalgebra's Householder steps are followed operation for operation: its reflection
/// (`householder::reflection_axis_mut`, called as it is), `p = 2 A v` by its symmetric
/// matrix-vector product (an axpy per column, each column's dot product below the diagonal with
/// its eight running sums, [`dot`]), `d = v . p`, and its three rank-1 updates of the lower
/// triangle (`A -= p v^T`, `A -= v p^T`, `A += 2d v v^T`). The updates change each entry by three
/// products in that order, each rounded and added as nalgebra does (no fused multiply-adds), so
/// they are made in one pass over the triangle instead of three; compiled for AVX2 where the CPU
/// has it, the columns' loops four entries at a time, with the same roundings.
fn tridiagonal(m: DMatrix<f64>) -> (DVector<f64>, DVector<f64>) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU was just found to support AVX2, the only requirement of `tridiagonal_avx2`.
        #[allow(unsafe_code)]
        return unsafe { tridiagonal_avx2(m) };
    }
    tridiagonal_body(m)
}

/// [`tridiagonal_body`] compiled for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn tridiagonal_avx2(m: DMatrix<f64>) -> (DVector<f64>, DVector<f64>) {
    tridiagonal_body(m)
}

#[inline(always)]
fn tridiagonal_body(mut m: DMatrix<f64>) -> (DVector<f64>, DVector<f64>) {
    let n = m.nrows();
    assert!(n >= 1 && m.is_square(), "a non-empty square matrix");
    let mut off = DVector::zeros(n - 1);
    let mut p = vec![0.0; n - 1];
    for i in 0..n - 1 {
        // The trailing block below and right of (i, i), k x k, and the column below (i, i).
        let k = n - 1 - i;
        let (norm, not_zero) = nalgebra::linalg::householder::reflection_axis_mut(
            &mut m.generic_view_mut((i + 1, i), (nalgebra::Dyn(k), nalgebra::Const::<1>)),
        );
        off[i] = norm.abs();
        if !not_zero {
            continue;
        }
        let data = m.as_mut_slice();
        let (head, tail) = data.split_at_mut((i + 1) * n);
        let axis = &head[i * n + i + 1..][..k];
        // Where column j of the block meets its diagonal, in `tail` (the columns from i + 1).
        let col = |j: usize| j * n + i + 1 + j;
        let p = &mut p[i..];
        // p = 2 A v (`hegemv(2, A, v, 0)`): column 0 whole, then each column's dot product
        // below its diagonal and its axpy below that.
        let a0 = 2.0 * axis[0];
        let c0 = &tail[col(0)..][..k];
        for (p, &a) in p.iter_mut().zip(c0) {
            *p = a0 * a;
        }
        p[0] += 2.0 * dot(&c0[1..], &axis[1..]);
        for j in 1..k {
            let cj = &tail[col(j)..][..k - j];
            p[j] += 2.0 * dot(cj, &axis[j..]);
            let a = 2.0 * axis[j];
            for (p, &x) in p[j + 1..].iter_mut().zip(&cj[1..]) {
                *p += a * x;
            }
        }
        let two_dot = dot(axis, p) * 2.0;
        // A -= p v^T, A -= v p^T, A += 2d v v^T on the lower triangle, entry by entry.
        for j in 0..k {
            let (v1, v2, v3) = (-axis[j], -p[j], two_dot * axis[j]);
            let cj = &mut tail[col(j)..][..k - j];
            for ((a, &pr), &vr) in cj.iter_mut().zip(&p[j..]).zip(&axis[j..]) {
                let mut x = *a;
                x += v1 * pr;
                x += v2 * vr;
                x += v3 * vr;
                *a = x;
            }
        }
    }
    (m.map_diagonal(|e| e), off)
}

/// nalgebra 0.35's dot product of two vectors (`dotc` of a column view): eight running sums over
/// blocks of eight, added in pairs (0 + 4, 1 + 5, 2 + 6, 3 + 7) to a sum from zero, then the
/// remaining products in turn.
#[inline(always)]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    debug_assert_eq!(a.len(), b.len());
    let mut res = 0.0;
    let mut acc = [0.0; 8];
    let blocks = a.len() / 8 * 8;
    for (x, y) in a[..blocks].chunks_exact(8).zip(b[..blocks].chunks_exact(8)) {
        for t in 0..8 {
            acc[t] += x[t] * y[t];
        }
    }
    res += acc[0] + acc[4];
    res += acc[1] + acc[5];
    res += acc[2] + acc[6];
    res += acc[3] + acc[7];
    for (x, y) in a[blocks..].iter().zip(&b[blocks..]) {
        res += x * y;
    }
    res
}

/// nalgebra 0.35's deflation search of the symmetric eigen-decomposition: the last unreduced block
/// ending at or before `end`, small off-diagonal entries above it set to zero.
fn delimit_subproblem(diag: &DVector<f64>, off_diag: &mut DVector<f64>, end: usize, eps: f64) -> (usize, usize) {
    let mut n = end;
    while n > 0 {
        let m = n - 1;
        if off_diag[m].abs() > eps * (diag[n].abs() + diag[m].abs()) {
            break;
        }
        n -= 1;
    }
    if n == 0 {
        return (0, 0);
    }
    let mut new_start = n - 1;
    while new_start > 0 {
        let m = new_start - 1;
        if off_diag[m] == 0.0 || off_diag[m].abs() <= eps * (diag[new_start].abs() + diag[m].abs()) {
            off_diag[m] = 0.0;
            break;
        }
        new_start -= 1;
    }
    (new_start, n)
}

/// Quantile `p` of an ascending sample, linear interpolation between order statistics.
pub fn quantile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let h = (sorted.len() - 1) as f64 * p.clamp(0.0, 1.0);
    let (lo, hi) = (h.floor() as usize, h.ceil() as usize);
    sorted[lo] + (h - lo as f64) * (sorted[hi] - sorted[lo])
}

/// [`quantile`] of `values` sorted ascending by `f64::total_cmp`, the same bits, found by
/// selection (linear time) instead of a sort; `values` is reordered.
pub fn quantile_selected(values: &mut [f64], p: f64) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    let h = (values.len() - 1) as f64 * p.clamp(0.0, 1.0);
    let (lo, hi) = (h.floor() as usize, h.ceil() as usize);
    let (_, at_lo, above) = values.select_nth_unstable_by(lo, f64::total_cmp);
    let at_lo = *at_lo;
    // The next order statistic is the least of those above (there is one: `hi` <= len - 1).
    let at_hi = if hi == lo { at_lo } else { above.iter().copied().min_by(f64::total_cmp).expect("a value above") };
    at_lo + (h - lo as f64) * (at_hi - at_lo)
}

/// Arguments of [`cosines`] up to this size (rad) are reduced by three parts of pi / 2 (each
/// part's product with the quadrant exact, the quadrant below 2^20); larger ones, and those that
/// are not finite, take the library's cosine.
const COS_REDUCED_UP_TO: f64 = 5.0e5;

/// `xs[k] = cos(xs[k])` for every value, the same bits on every x86-64 and other CPU (multiplies
/// and adds, no fused operations, no table), within a unit in the last place of the correctly
/// rounded value (the unit test measures it against the library's cosine): the argument reduced by
/// pi / 2 in fdlibm's parts (33, 33, 33 and 53 bits), carried as a head and a tail with every
/// rounding of the differences kept, then musl's `__cos` and `__sin` polynomials of the head and
/// tail on [-pi/4, pi/4]. Compiled for AVX2 where the CPU has
/// it (four values at a time, the same roundings): many cosines of unrelated arguments cost what a
/// few of the library's do.
pub fn cosines(xs: &mut [f64]) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU was just found to support AVX2, the only requirement of `cosines_avx2`.
        #[allow(unsafe_code)]
        unsafe {
            cosines_avx2(xs)
        };
        return;
    }
    cosines_body(xs);
}

/// [`cosines_body`] compiled for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn cosines_avx2(xs: &mut [f64]) {
    cosines_body(xs);
}

#[inline(always)]
fn cosines_body(xs: &mut [f64]) {
    const LANES: usize = 4;
    let mut chunks = xs.chunks_exact_mut(LANES);
    for c in &mut chunks {
        let x: [f64; LANES] = [c[0], c[1], c[2], c[3]];
        let y = cos_lanes(x);
        if x.iter().all(|v| v.abs() <= COS_REDUCED_UP_TO) {
            c.copy_from_slice(&y);
        } else {
            for (out, (v, w)) in c.iter_mut().zip(x.iter().zip(y)) {
                *out = if v.abs() <= COS_REDUCED_UP_TO { w } else { v.cos() };
            }
        }
    }
    for v in chunks.into_remainder() {
        *v = if v.abs() <= COS_REDUCED_UP_TO { cos_lanes([*v; LANES])[0] } else { v.cos() };
    }
}

/// `a + b` and its rounding error, exactly (Knuth's two-sum, for any magnitudes).
#[inline(always)]
fn two_sum(a: f64, b: f64) -> (f64, f64) {
    let s = a + b;
    let bb = s - a;
    (s, (a - (s - bb)) + (b - bb))
}

/// The cosine of each of `x` (|x| <= [`COS_REDUCED_UP_TO`]), lane by lane, without branches.
#[inline(always)]
fn cos_lanes<const L: usize>(x: [f64; L]) -> [f64; L] {
    // 2 / pi, and fdlibm's pi / 2 in three parts of 33 bits each and the rest (pio2_1, pio2_2,
    // pio2_3, pio2_3t), each the shortest decimal of its bits.
    const INV_PIO2: f64 = std::f64::consts::FRAC_2_PI;
    const PIO2_1: f64 = 1.5707963267341256;
    const PIO2_2: f64 = 6.077100506303966e-11;
    const PIO2_3: f64 = 2.0222662487111665e-21;
    const PIO2_3T: f64 = 8.4784276603689e-32;
    // Adding and taking 1.5 * 2^52 rounds to the nearest integer (ties to even).
    const TO_INT: f64 = 6_755_399_441_055_744.0;
    const S1: f64 = -0.16666666666666632;
    const S2: f64 = 0.00833333333332249;
    const S3: f64 = -0.0001984126982985795;
    const S4: f64 = 2.7557313707070068e-06;
    const S5: f64 = -2.5050760253406863e-08;
    const S6: f64 = 1.58969099521155e-10;
    const C1: f64 = 0.0416666666666666;
    const C2: f64 = -0.001388888888887411;
    const C3: f64 = 2.480158728947673e-05;
    const C4: f64 = -2.7557314351390663e-07;
    const C5: f64 = 2.087572321298175e-09;
    const C6: f64 = -1.1359647557788195e-11;
    let mut out = [0.0; L];
    // Each lane's chain on its own (the lanes side by side in vectors), the quadrant's choice by
    // selection, not by branches.
    for l in 0..L {
        let v = if x[l].abs() <= COS_REDUCED_UP_TO { x[l] } else { 0.0 };
        let k = (v * INV_PIO2 + TO_INT) - TO_INT;
        // The reduced argument v - k pi / 2 as y0 + y1: each part's product with k exact (33
        // bits by at most 20), the first difference exact (the two within a factor 2), the next
        // two's rounding errors kept (Knuth's two-sum) and added to the tail with the last part.
        let t = v - k * PIO2_1;
        let (s1, e1) = two_sum(t, -(k * PIO2_2));
        let (s2, e2) = two_sum(s1, -(k * PIO2_3));
        let tail = (e1 + e2) - k * PIO2_3T;
        let y0 = s2 + tail;
        let y1 = (s2 - y0) + tail;
        let z = y0 * y0;
        let w = z * z;
        // musl's __cos(y0, y1).
        let rc = z * (C1 + z * (C2 + z * C3)) + w * w * (C4 + z * (C5 + z * C6));
        let hz = 0.5 * z;
        let wc = 1.0 - hz;
        let cos = wc + (((1.0 - wc) - hz) + (z * rc - y0 * y1));
        // musl's __sin(y0, y1, 1).
        let rs = S2 + z * (S3 + z * S4) + z * w * (S5 + z * S6);
        let v3 = z * y0;
        let sin = y0 - ((z * (0.5 * y1 - v3 * rs) - y1) - v3 * S1);
        // cos(y0 + y1 + k pi / 2) by the quadrant k mod 4 (0: cos, 1: -sin, 2: -cos, 3: sin).
        let quadrant = k - 4.0 * (0.25 * k).floor();
        let odd = quadrant == 1.0 || quadrant == 3.0;
        let value = if odd { sin } else { cos };
        out[l] = if quadrant == 1.0 || quadrant == 2.0 { -value } else { value };
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// The Gram matrix `a^T a` of an (n + extra) x n draw over six decades; `repeated`: with the
    /// last column of `a` a copy of the first (rank deficient).
    fn gram(rng: &mut ChaCha8Rng, n: usize, extra: usize, repeated: bool) -> DMatrix<f64> {
        let mut a = DMatrix::from_fn(n + extra, n, |_, _| rng.random_range(-1.0..1.0) * 10f64.powi(rng.random_range(-3..=3)));
        if repeated {
            let c0 = a.column(0).into_owned();
            a.set_column(n - 1, &c0);
        }
        a.tr_mul(&a)
    }

    /// The quantile by selection is that of the sorted sample bit for bit: samples of 1 to 300
    /// values, with ties (values drawn from a few), both zeros, infinities and NaN among them, at
    /// 0, 0.05, 0.5, 0.95, 0.999 and 1.
    #[test]
    fn quantile_by_selection_is_the_sorted_samples() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for n in (1..40).chain([97, 300]) {
            for case in 0..6 {
                let v: Vec<f64> = (0..n)
                    .map(|_| match case {
                        0 => rng.random_range(-1.0..1.0),
                        1 => [0.0, -0.0, 1.5, 2.0][rng.random_range(0..4)],
                        2 => [f64::NAN, 1.0, f64::INFINITY, -f64::INFINITY, -2.0][rng.random_range(0..5)],
                        _ => rng.random_range(0.0..1e-3) * 10f64.powi(rng.random_range(-3..=3)),
                    })
                    .collect();
                let mut sorted = v.clone();
                sorted.sort_by(f64::total_cmp);
                for p in [0.0, 0.05, 0.5, 0.95, 0.999, 1.0] {
                    let mut scratch = v.clone();
                    let (a, b) = (quantile_selected(&mut scratch, p), quantile(&sorted, p));
                    assert_eq!(a.to_bits(), b.to_bits(), "n {n} case {case} p {p}: {a} and {b}");
                }
            }
        }
        assert!(quantile_selected(&mut [], 0.5).is_nan());
    }

    /// The eigenvalues-only sweeps give nalgebra's eigenvalues bit for bit: 40 draws per size
    /// (1, 2, 3, 7, 31, 40) of Gram matrices (full rank, and rank deficient through repeated
    /// columns), indefinite symmetric matrices, diagonal ones (already reduced), the zero matrix and
    /// a multiple of the identity; a NaN or infinite entry gives `None`.
    #[test]
    fn eigenvalues_equal_nalgebra_bit_for_bit() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let bits = |v: &DVector<f64>| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        for n in [1, 2, 3, 7, 31, 40] {
            for draw in 0..40 {
                // Repeated column: one eigenvalue (numerically) zero.
                let gram = gram(&mut rng, n, 3, draw % 4 == 1 && n > 1);
                let indefinite = DMatrix::from_fn(n, n, |i, j| ((i * 7 + j * 7 + i * j) % 13) as f64 - 6.0 + rng.random_range(-0.5..0.5));
                let indefinite = &indefinite + indefinite.transpose();
                let diagonal = DMatrix::from_diagonal(&DVector::from_fn(n, |_, _| rng.random_range(-5.0..5.0)));
                for m in [gram, indefinite, diagonal, DMatrix::zeros(n, n), DMatrix::identity(n, n) * 3.0] {
                    let expected = SymmetricEigen::try_new(m.clone(), f64::EPSILON, MAX_ITERATIONS).expect("converges").eigenvalues;
                    let got = symmetric_eigenvalues(m.clone()).expect("converges");
                    assert_eq!(bits(&got), bits(&expected), "n = {n}, draw {draw}: {m}");
                }
            }
        }
        let mut m = DMatrix::<f64>::identity(4, 4);
        m[(2, 1)] = f64::NAN;
        assert!(symmetric_eigenvalues(m.clone()).is_none());
        m[(2, 1)] = f64::INFINITY;
        assert!(symmetric_eigenvalues(m).is_none());
        assert!(symmetric_eigenvalues(DMatrix::zeros(0, 0)).is_none());
    }

    /// The tridiagonal form equals nalgebra's `SymmetricTridiagonal` bit for bit, on both builds
    /// (AVX2 where the CPU has it, and the portable one): 30 draws per size (1, 2, 3, 8, 9, 17, 31,
    /// 40: dot products with and without blocks of eight) of Gram matrices over six decades, rank
    /// deficient ones, indefinite ones, diagonal ones (every reflection skipped), ones with zero
    /// columns below the diagonal part way, the zero matrix; the upper triangle is never read.
    #[test]
    fn tridiagonal_equals_nalgebra_bit_for_bit() {
        use nalgebra::linalg::SymmetricTridiagonal;
        let mut rng = ChaCha8Rng::seed_from_u64(17);
        let bits = |v: &DVector<f64>| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        for n in [1, 2, 3, 8, 9, 17, 31, 40] {
            for draw in 0..30 {
                let gram = gram(&mut rng, n, 2, draw % 3 == 1 && n > 1);
                let indefinite = DMatrix::from_fn(n, n, |_, _| rng.random_range(-2.0..2.0));
                let indefinite = &indefinite + indefinite.transpose();
                let diagonal = DMatrix::from_diagonal(&DVector::from_fn(n, |_, _| rng.random_range(-5.0..5.0)));
                // Block diagonal: the reflection of column 0 is skipped, the later ones are not.
                let mut blocks = indefinite.clone();
                for r in 1..n {
                    blocks[(r, 0)] = 0.0;
                    blocks[(0, r)] = 0.0;
                }
                for m in [gram, indefinite, diagonal, blocks, DMatrix::zeros(n, n)] {
                    let (d, e) = SymmetricTridiagonal::new(m.clone()).unpack_tridiagonal();
                    // Garbage above the diagonal: neither reads it.
                    let mut upper = m.clone();
                    for c in 1..n {
                        for r in 0..c {
                            upper[(r, c)] = f64::NAN;
                        }
                    }
                    for (got_d, got_e) in [tridiagonal(upper.clone()), tridiagonal_body(upper.clone())] {
                        assert_eq!(bits(&got_d), bits(&d), "n = {n}, draw {draw}: diagonal of {m}");
                        assert_eq!(bits(&got_e), bits(&e), "n = {n}, draw {draw}: off-diagonal of {m}");
                    }
                }
            }
        }
    }

    /// `matrix_vector` equals nalgebra's `mul_to` bit for bit, on both builds: m from 1 to 40, k
    /// from 0 to 600 (the least squares' 31 x 225 among them), entries over nine decades with zeros
    /// and signed zeros among them; 3 draws per shape.
    #[test]
    fn matrix_vector_equals_nalgebra_bit_for_bit() {
        let mut rng = ChaCha8Rng::seed_from_u64(23);
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        for m in [1, 3, 4, 5, 7, 31, 40] {
            for k in [0, 1, 2, 6, 225, 600] {
                for _ in 0..3 {
                    let mut draw = |_: usize, _: usize| match rng.random_range(0..10) {
                        0 => 0.0,
                        1 => -0.0,
                        _ => rng.random_range(-1.0..1.0) * 10f64.powi(rng.random_range(-6..=3)),
                    };
                    let a = DMatrix::from_fn(m, k, &mut draw);
                    let x = DVector::from_fn(k, &mut draw);
                    let mut expected = DVector::from_element(m, 7.0);
                    a.mul_to(&x, &mut expected);
                    let (mut got, mut portable) = (vec![7.0; m], vec![7.0; m]);
                    matrix_vector(&a, x.as_slice(), &mut got);
                    matrix_vector_body(&a, x.as_slice(), &mut portable);
                    assert_eq!(bits(&got), bits(expected.as_slice()), "{m} x {k}");
                    assert_eq!(bits(&portable), bits(expected.as_slice()), "{m} x {k}");
                }
            }
        }
    }

    /// `gemm_product` equals nalgebra's `gemm` bit for bit: m, n from 3 to 40 (4- and 8-wide
    /// blocks, exact and shifted), k from 3 to 600 (across matrixmultiply's blocks of 256), the
    /// second factor column-major and as the transpose of a column-major matrix, the symmetric
    /// form for `x x^T`; every build this CPU runs (AVX-512, AVX2 8 x 4 and 4 x 4), and the unfused
    /// order against the sum written out. 2 draws per shape.
    #[test]
    fn gemm_product_equals_gemm_bit_for_bit() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let bits = |a: &DMatrix<f64>| a.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        let mut draw =
            |r: usize, c: usize| DMatrix::from_fn(r, c, |_, _| rng.random_range(-1.0..1.0) * 10f64.powi(rng.random_range(-6..=3)));
        for m in [3, 6, 7, 8, 9, 31, 40] {
            for n in [3, 6, 8, 13, 31] {
                for k in [3, 6, 31, 256, 257, 600] {
                    for _ in 0..2 {
                        let a = draw(m, k);
                        let b = draw(k, n);
                        let bt = b.transpose();
                        let mut expected = DMatrix::zeros(m, n);
                        expected.gemm(1.0, &a, &b, 0.0);
                        let factors = [
                            Factor { data: b.as_slice(), row_stride: 1, col_stride: k },
                            Factor { data: bt.as_slice(), row_stride: n, col_stride: 1 },
                        ];
                        for f in factors {
                            let mut got = DMatrix::from_element(m, n, f64::NAN);
                            gemm_product(&a, f, n, &mut got, false);
                            assert_eq!(bits(&got), bits(&expected), "m = {m}, n = {n}, k = {k}");
                            let builds = product_builds(&a, f, n, false);
                            for (name, got) in builds {
                                assert_eq!(bits(&got), bits(&expected), "{name}: m = {m}, n = {n}, k = {k}");
                            }
                            if m >= 4 && n >= 4 {
                                let naive = DMatrix::from_fn(m, n, |i, j| {
                                    let block = |k0: usize| (k0..(k0 + 256).min(k)).fold(0.0, |s, l| s + a[(i, l)] * b[(l, j)]);
                                    (256..k).step_by(256).fold(block(0), |t, k0| t + block(k0))
                                });
                                product_body(a.as_slice(), (m, k), f, n, got.as_mut_slice(), false, block_sums::<false, 4, 4>);
                                assert_eq!(bits(&got), bits(&naive), "unfused: m = {m}, n = {n}, k = {k}");
                            }
                        }
                        if m == n {
                            // x x^T, symmetric.
                            let mut expected = DMatrix::zeros(m, m);
                            expected.gemm(1.0, &a, &a.transpose(), 0.0);
                            let f = Factor { data: a.as_slice(), row_stride: m, col_stride: 1 };
                            let mut got = DMatrix::from_element(m, m, f64::NAN);
                            gemm_product(&a, f, m, &mut got, true);
                            assert_eq!(bits(&got), bits(&expected), "symmetric: m = {m}, k = {k}");
                            for (name, got) in product_builds(&a, f, m, true) {
                                assert_eq!(bits(&got), bits(&expected), "symmetric {name}: m = {m}, k = {k}");
                            }
                        }
                    }
                }
            }
        }
    }

    /// The product by every compiled build this CPU can run and whose block fits (m >= 6 rows and
    /// n >= 6 columns, as `gemm_product` requires).
    fn product_builds(a: &DMatrix<f64>, b: Factor<'_>, n: usize, symmetric: bool) -> Vec<(&'static str, DMatrix<f64>)> {
        let (m, k) = a.shape();
        let mut out = Vec::new();
        if m <= 5 || n <= 5 || k <= 5 {
            return out;
        }
        #[cfg(target_arch = "x86_64")]
        {
            let run = |f: &dyn Fn(&mut [f64])| {
                let mut got = DMatrix::from_element(m, n, f64::NAN);
                f(got.as_mut_slice());
                got
            };
            let fma = std::arch::is_x86_feature_detected!("fma") && std::arch::is_x86_feature_detected!("avx2");
            #[allow(unsafe_code)]
            if fma {
                // SAFETY: AVX2 and FMA were just detected.
                out.push(("avx2", run(&|y| unsafe { product_fused_avx2(a.as_slice(), (m, k), b, n, y, symmetric) })));
                if m >= 8 {
                    // SAFETY: as above.
                    out.push(("avx2 4 x 4", run(&|y| unsafe { product_body_avx2_4x4(a.as_slice(), (m, k), b, n, y, symmetric) })));
                }
            }
            #[allow(unsafe_code)]
            if std::arch::is_x86_feature_detected!("avx512f") && m >= 8 && n >= 8 {
                // SAFETY: AVX-512F was just detected.
                out.push(("avx512", run(&|y| unsafe { product_fused_avx512(a.as_slice(), (m, k), b, n, y, symmetric) })));
            }
        }
        out
    }

    /// The 4 x 4 blocks of the AVX2 build, also for 8 rows or more.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn product_body_avx2_4x4(a: &[f64], mk: (usize, usize), b: Factor<'_>, n: usize, out: &mut [f64], symmetric: bool) {
        product_body(a, mk, b, n, out, symmetric, block_sums::<true, 4, 4>);
    }

    /// [`cosines`] against the library's cosine: 10^6 arguments log-uniform in magnitude from
    /// 1e-8 to the reduced range's end (both signs), and near multiples of pi / 2 up to 2e5, where
    /// the reduction matters most; every value within a unit in the last place of the library's
    /// (both are within one of the correctly rounded value), the chunks' and the remainder's the
    /// same bits, and beyond the reduced range and at infinities and NaN the library's own value.
    #[test]
    fn cosines_are_the_library_cosine_to_a_unit_in_the_last_place() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut xs: Vec<f64> = (0..1_000_000)
            .map(|k| {
                if k % 4 == 3 {
                    let m: f64 = rng.random_range(0.0..2e5f64 / std::f64::consts::FRAC_PI_2).round();
                    m * std::f64::consts::FRAC_PI_2 + rng.random_range(-1e-6..1e-6)
                } else {
                    let e: f64 = rng.random_range(-8.0..COS_REDUCED_UP_TO.log10());
                    let s = if rng.random::<bool>() { 1.0 } else { -1.0 };
                    s * 10f64.powf(e)
                }
            })
            .collect();
        xs.extend([0.0, -0.0, COS_REDUCED_UP_TO, -COS_REDUCED_UP_TO, 1e6, -3e9, 1e300, f64::INFINITY, f64::NEG_INFINITY, f64::NAN]);
        let mut ys = xs.clone();
        cosines(&mut ys);
        let mut worst = 0.0f64;
        for (x, y) in xs.iter().zip(&ys) {
            let want = x.cos();
            if x.abs() > COS_REDUCED_UP_TO || !x.is_finite() {
                assert_eq!(y.to_bits(), want.to_bits(), "cos({x}) is the library's beyond the reduced range");
                continue;
            }
            let ulp = f64::from_bits(want.abs().to_bits() + 1) - want.abs();
            worst = worst.max((y - want).abs() / ulp);
        }
        assert!(worst <= 1.0, "largest difference {worst} units in the last place");
        // One at a time (the remainder's path) gives the same bits as four at a time.
        for (x, y) in xs.iter().zip(&ys).take(1000) {
            let mut one = [*x];
            cosines(&mut one);
            assert_eq!(one[0].to_bits(), y.to_bits(), "cos({x}) alone");
        }
    }
}
