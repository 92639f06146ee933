//! Observability indices (Sun and Hollerbach 2008) of a set of configurations, the column-scaled
//! stacked Jacobian they are computed from, and the first-order parameter covariance.
//!
//! **Column scaling.** Indices compare sets of configurations, so every set is scaled the same
//! way: column j of the identification Jacobian is divided by `s_j`, the root mean square over the
//! whole pool of the norm of that column per configuration (`s_j^2 = sum_k |J_kj|^2 / N`), computed
//! once at the model DETMAX starts from. Identification scales each set's columns to unit norm
//! for its own numerics; for one set the two scalings differ by a diagonal matrix, so the fitted
//! values are the same, but the singular values each reports are of its own scaling.

use nalgebra::DMatrix;

use crate::robot::{Joints, ParamSet, RobotModel};

/// The identification Jacobians of `qs` at `model` for `set`, stacked: rows 3k..3k+3 are
/// configuration k (unscaled).
pub fn stacked_jacobian(model: &RobotModel, set: &ParamSet, qs: &[Joints]) -> DMatrix<f64> {
    let p = set.len();
    let mut jt = DMatrix::zeros(p, 3 * qs.len());
    let mut tcps = vec![nalgebra::Vector3::zeros(); qs.len()];
    crate::robot::tcp_jacobians_transposed(model, set, qs, jt.as_mut_slice(), &mut tcps);
    jt.transpose()
}

/// The identification Jacobians of `qs` at `model` for `set`, stacked (rows 3k..3k+3:
/// configuration k) and column-scaled as the module docs say; returns the scaled matrix and the
/// scale factors `s_j` (internal units of the parameter per mm; a zero column keeps scale 0).
pub fn scaled_stacked_jacobian(model: &RobotModel, set: &ParamSet, qs: &[Joints]) -> (DMatrix<f64>, Vec<f64>) {
    let mut j = stacked_jacobian(model, set, qs);
    let n = qs.len().max(1) as f64;
    let scale: Vec<f64> = j.column_iter().map(|c| (c.norm_squared() / n).sqrt()).collect();
    for (c, s) in scale.iter().enumerate() {
        if *s > 0.0 {
            j.column_mut(c).unscale_mut(*s);
        }
    }
    (j, scale)
}

/// The five observability indices of a set of `n` configurations.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Observability {
    /// O1 = (s1 s2 ... sm)^(1/m) / sqrt(n) (paper eq. 16).
    pub o1: f64,
    /// O2 = s_min / s_max (inverse condition number).
    pub o2: f64,
    /// O3 = s_min.
    pub o3: f64,
    /// O4 = s_min^2 / s_max (noise amplification index).
    pub o4: f64,
    /// O5 = 1 / (1/s1 + ... + 1/sm).
    pub o5: f64,
}

impl Observability {
    /// Indices from the information matrix `J^T J` of the scaled Jacobian of `n` configurations.
    pub fn from_information(info: &DMatrix<f64>, n: usize) -> Self {
        let Some(eigenvalues) = crate::numeric::symmetric_eigenvalues(info.clone()) else {
            return Self::from_singular_values(&vec![f64::NAN; info.nrows()], n);
        };
        let mut s: Vec<f64> = eigenvalues.iter().map(|l| l.max(0.0).sqrt()).collect();
        s.sort_by(|a, b| b.total_cmp(a));
        Self::from_singular_values(&s, n)
    }

    /// Indices from the singular values (any order) of the scaled Jacobian of `n` configurations.
    pub fn from_singular_values(s: &[f64], n: usize) -> Self {
        let m = s.len() as f64;
        let smax = s.iter().copied().fold(0.0, f64::max);
        let smin = s.iter().copied().fold(f64::INFINITY, f64::min);
        let log_mean = s.iter().map(|v| v.max(f64::MIN_POSITIVE).ln()).sum::<f64>() / m;
        Self {
            o1: log_mean.exp() / (n as f64).sqrt(),
            o2: smin / smax,
            o3: smin,
            o4: smin * smin / smax,
            o5: 1.0 / s.iter().map(|v| 1.0 / v).sum::<f64>(),
        }
    }
}

/// Parameters of `set` that no set of configurations can separate on `model`: the information
/// Jacobian of 200 configurations drawn across the joint ranges (a fixed stream, so the answer is the
/// same every time), column-scaled; a parameter is named when its unit vector has at least 1 % of
/// its squared length in the numerical null space (singular values below 1e-9 of the largest), a
/// test that does not depend on which basis of a repeated null space the eigen-solver returns. A
/// zero column (a parameter that moves nothing) and an exact redundancy (two parameters that move
/// the TCP alike everywhere) are both found.
pub fn structurally_unidentifiable(model: &RobotModel, set: &crate::robot::ParamSet) -> Vec<String> {
    if set.is_empty() {
        return Vec::new();
    }
    use rand::RngExt;
    let mut rng = crate::seeds::structural_check();
    let qs: Vec<crate::robot::Joints> = (0..200)
        .map(|_| {
            std::array::from_fn(|i| {
                let l = model.limits()[i];
                let (lo, hi) = (l.min.max(-std::f64::consts::PI), l.max.min(std::f64::consts::PI));
                if hi > lo { rng.random_range(lo..hi) } else { lo }
            })
        })
        .collect();
    let (j, _) = scaled_stacked_jacobian(model, set, &qs);
    let names = set.names();
    let Some(shares) = null_space_shares(j, 1e-9) else {
        return names;
    };
    (0..names.len()).filter(|&j| shares[j] >= 0.01).map(|j| names[j].clone()).collect()
}

/// The share of each column's unit vector in the numerical null space of `j` (a Jacobian, columns
/// scaled by the caller): the diagonal of the projector onto the right singular vectors whose
/// singular values are below `rtol` times the largest, from the SVD of `j` itself (not of `J^T J`,
/// which would square its condition). A share does not depend on which basis of a repeated null
/// space the solver returns. `None` when the SVD does not converge.
pub fn null_space_shares(j: DMatrix<f64>, rtol: f64) -> Option<Vec<f64>> {
    let m = j.ncols();
    let svd = crate::numeric::svd(j, false, true)?;
    let v_t = svd.v_t?;
    let s = &svd.singular_values;
    let smax = s.iter().fold(0.0_f64, |m, &x| m.max(x));
    let null: Vec<usize> = (0..s.len()).filter(|&k| !(smax > 0.0 && s[k] >= rtol * smax)).collect();
    // Fewer rows than columns: the SVD is thin, and the columns beyond the rows are null too.
    let thin = s.len() < m;
    Some(
        (0..m)
            .map(|c| {
                let captured: f64 = (0..s.len()).map(|k| v_t[(k, c)].powi(2)).sum();
                let null_part: f64 = null.iter().map(|&k| v_t[(k, c)].powi(2)).sum();
                if thin { null_part + (1.0 - captured).max(0.0) } else { null_part }
            })
            .collect(),
    )
}

/// First-order standard deviations of the identified parameters (internal units) when every
/// measured coordinate carries independent noise of `sigma_mm`: the square roots of the diagonal of
/// `sigma^2 (J^T J)^-1`, with `J` the identification Jacobian of the configurations `qs` at
/// `model`. `None` when `J^T J` is singular (the set cannot separate the parameters).
pub fn predicted_std(model: &RobotModel, set: &crate::robot::ParamSet, qs: &[crate::robot::Joints], sigma_mm: f64) -> Option<Vec<f64>> {
    let (inv, scale) = scaled_inverse(model, set, qs)?;
    Some((0..set.len()).map(|i| sigma_mm * inv[(i, i)].max(0.0).sqrt() / scale[i]).collect())
}

/// The first-order covariance `sigma^2 (J^T J)^-1` of the identified parameters (internal units)
/// whose diagonal [`predicted_std`] gives. `None` when `J^T J` is singular.
pub fn parameter_covariance(
    model: &RobotModel,
    set: &crate::robot::ParamSet,
    qs: &[crate::robot::Joints],
    sigma_mm: f64,
) -> Option<DMatrix<f64>> {
    let (inv, scale) = scaled_inverse(model, set, qs)?;
    let s2 = sigma_mm * sigma_mm;
    Some(DMatrix::from_fn(set.len(), set.len(), |i, j| s2 * inv[(i, j)] / (scale[i] * scale[j])))
}

/// `(J_s^T J_s)^-1` of the column-scaled identification Jacobian and the column scales (scaling
/// keeps the inverse well conditioned across mm and rad columns).
fn scaled_inverse(model: &RobotModel, set: &crate::robot::ParamSet, qs: &[crate::robot::Joints]) -> Option<(DMatrix<f64>, Vec<f64>)> {
    scaled_inverse_of(stacked_jacobian(model, set, qs))
}

/// The first-order covariance `sigma^2 (J^T J)^-1` of the unknowns of any least-squares problem
/// whose (weighted) Jacobian is `j`, in the units of its columns. `None` when `J^T J` is singular.
pub fn covariance_of_jacobian(j: DMatrix<f64>, sigma: f64) -> Option<DMatrix<f64>> {
    let (inv, scale) = scaled_inverse_of(j)?;
    let s2 = sigma * sigma;
    Some(DMatrix::from_fn(inv.nrows(), inv.ncols(), |i, k| s2 * inv[(i, k)] / (scale[i] * scale[k])))
}

/// `(J_s^T J_s)^-1` of `j` with its columns scaled to unit norm, and the scales.
fn scaled_inverse_of(mut j: DMatrix<f64>) -> Option<(DMatrix<f64>, Vec<f64>)> {
    let scale: Vec<f64> = j.column_iter().map(|c| c.norm()).collect();
    if scale.iter().any(|s| *s == 0.0 || !s.is_finite()) {
        return None;
    }
    for (c, s) in scale.iter().enumerate() {
        j.column_mut(c).unscale_mut(*s);
    }
    Some((j.tr_mul(&j).try_inverse()?, scale))
}
