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

/// Eigenvalues of a symmetric matrix (see [`symmetric_eigen`]).
pub fn symmetric_eigenvalues(m: DMatrix<f64>) -> Option<DVector<f64>> {
    symmetric_eigen(m).map(|e| e.eigenvalues)
}
