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
    use nalgebra::linalg::{SymmetricTridiagonal, givens::GivensRotation, wilkinson_shift};
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
    let (mut diag, mut off_diag) = SymmetricTridiagonal::new(m).unpack_tridiagonal();
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

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

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
                let a = DMatrix::from_fn(n + 3, n, |_, _| rng.random_range(-1.0..1.0) * 10f64.powi(rng.random_range(-3..=3)));
                let mut gram = a.tr_mul(&a);
                if draw % 4 == 1 && n > 1 {
                    // Repeated column: one eigenvalue (numerically) zero.
                    let mut b = a.clone();
                    let c0 = b.column(0).into_owned();
                    b.set_column(n - 1, &c0);
                    gram = b.tr_mul(&b);
                }
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
}
