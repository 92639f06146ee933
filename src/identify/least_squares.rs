//! Least-squares identification of a [`ParamSet`] from TCP positions measured in {W}
//! (paper eqs. 11-15): Gauss-Newton with column scaling and a Moore-Penrose step, or
//! Levenberg-Marquardt.
//!
//! Each iteration forms the transposed Jacobian (p x 3n, four configurations at a time), the
//! normal matrix `N = J^T J` and `J^T r`, scales the columns to unit norm, and solves for the
//! step. While the scaled matrix is well conditioned, the step comes from its Cholesky factor, which
//! equals the pseudo-inverse solution (eq. 14 = eq. 15 at full rank). When a Cholesky pivot signals
//! near-dependence, the step comes from the eigendecomposition of the scaled normal matrix (the SVD
//! of the scaled Jacobian through its Gram matrix: `sigma_k^2` are its eigenvalues), truncated at the
//! rank tolerance, and the parameters the poses cannot separate are named. The singular values,
//! condition number and the final rank check always come from that decomposition at the last
//! iterate.

use super::damping::Damping;
use nalgebra::{DMatrix, DVector, SymmetricEigen, Vector3};

use crate::robot::{Joints, ParamSet, RobotModel, tcp_jacobians_transposed};

/// One measured configuration: joint values commanded and the TCP measured in {W}.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Observation {
    /// Joint values, rad.
    pub q: Joints,
    /// Measured TCP position in {W}, mm.
    pub tcp_world_mm: Vector3<f64>,
}

/// The solver.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Solver {
    /// Gauss-Newton with the pseudo-inverse step (the paper's method).
    GaussNewton,
    /// Levenberg-Marquardt with Nielsen's damping update, starting at `tau` times the largest
    /// diagonal element of the scaled normal matrix.
    LevenbergMarquardt {
        /// Initial damping factor.
        tau: f64,
    },
}

/// Stopping rules and tolerances.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FitOptions {
    /// Solver.
    pub solver: Solver,
    /// Iteration cap (Jacobian evaluations).
    pub max_iterations: usize,
    /// Converged when an accepted step changes the predicted positions by less than this RMS, mm.
    /// Gauss-Newton converges quadratically here, so what remains after such a step is orders of
    /// magnitude smaller still.
    pub step_tol_mm: f64,
    /// Converged when an accepted step changes the cost by less than this fraction of it.
    pub cost_rtol: f64,
    /// Singular values of the column-scaled Jacobian below `rank_rtol * sigma_max` count as zero.
    /// Through the Gram matrix, values below about 1e-7 are not resolved: keep this above that.
    pub rank_rtol: f64,
    /// What to do with directions below `rank_rtol`: `false` refuses the fit
    /// ([`FitOutcome::RankDeficient`], no model); `true` leaves them at the start values (the
    /// truncated pseudo-inverse step, eq. 15 of the TriCal paper) and returns the model
    /// ([`FitOutcome::Truncated`]).
    pub truncate: bool,
}

impl Default for FitOptions {
    fn default() -> Self {
        Self { solver: Solver::GaussNewton, max_iterations: 50, step_tol_mm: 1e-6, cost_rtol: 1e-12, rank_rtol: 1e-6, truncate: false }
    }
}

/// How an identification ended.
#[derive(Clone, Debug, PartialEq)]
pub enum FitOutcome {
    /// The step criterion was met.
    Converged {
        /// Jacobian evaluations.
        iterations: usize,
    },
    /// The iteration cap was reached first.
    IterationCap {
        /// Jacobian evaluations.
        iterations: usize,
    },
    /// Converged with the directions below the rank tolerance left at the start values
    /// ([`FitOptions::truncate`]).
    Truncated {
        /// Jacobian evaluations.
        iterations: usize,
        /// Parameters with a large share in the directions left out.
        unidentifiable: Vec<String>,
    },
    /// The residuals or the normal equations became NaN or infinite (or their decomposition did
    /// not converge): no model.
    NotFinite,
    /// The configurations cannot separate these parameters; no values are returned for them.
    RankDeficient {
        /// Names of the parameters in the (numerical) null space of the scaled Jacobian.
        unidentifiable: Vec<String>,
    },
}

impl FitOutcome {
    /// A short label for tables: `converged`, `iteration_cap`, `rank_deficient`.
    pub fn label(&self) -> &'static str {
        match self {
            FitOutcome::Converged { .. } => "converged",
            FitOutcome::IterationCap { .. } => "iteration_cap",
            FitOutcome::Truncated { .. } => "truncated",
            FitOutcome::RankDeficient { .. } => "rank_deficient",
            FitOutcome::NotFinite => "not_finite",
        }
    }

    /// The parameters the configurations could not separate (empty unless rank deficient or truncated).
    pub fn unidentifiable(&self) -> &[String] {
        match self {
            FitOutcome::RankDeficient { unidentifiable } | FitOutcome::Truncated { unidentifiable, .. } => unidentifiable,
            _ => &[],
        }
    }

    /// Whether the fit returned no model (the set cannot separate the parameters, or the numbers
    /// stopped being finite).
    pub fn is_rank_deficient(&self) -> bool {
        matches!(self, FitOutcome::RankDeficient { .. } | FitOutcome::NotFinite)
    }

    /// Whether the step criterion was met with every parameter identified.
    pub fn is_converged(&self) -> bool {
        matches!(self, FitOutcome::Converged { .. })
    }
}

/// Result of an identification.
#[derive(Clone, Debug)]
pub struct Fit {
    /// How it ended.
    pub outcome: FitOutcome,
    /// The identified model; `None` when rank deficient.
    pub model: Option<RobotModel>,
    /// Identified values in the order of the set, internal units; `None` for parameters the
    /// configurations cannot separate.
    pub values: Vec<Option<f64>>,
    /// Jacobian evaluations.
    pub iterations: usize,
    /// Singular values of the column-scaled identification Jacobian at the last iterate, descending.
    pub singular_values: Vec<f64>,
    /// `sigma_max / sigma_min` of the column-scaled Jacobian (infinite when rank deficient).
    pub condition_number: f64,
    /// Root mean square of the position residual norms at the returned values, mm.
    pub residual_rms_mm: f64,
    /// Cost and step of every iteration.
    pub history: Vec<Iteration>,
}

impl Fit {
    /// The fit of `p` parameters that stopped at `iterations` because the numbers were not finite.
    fn not_finite(p: usize, iterations: usize, history: Vec<Iteration>) -> Self {
        Fit {
            outcome: FitOutcome::NotFinite,
            model: None,
            values: vec![None; p],
            iterations,
            singular_values: vec![],
            condition_number: f64::NAN,
            residual_rms_mm: f64::NAN,
            history,
        }
    }
}

/// One iteration of an identification.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Iteration {
    /// Sum of squared position residuals at the iterate, mm^2.
    pub cost_mm2: f64,
    /// RMS change of the predicted positions by the step taken from it, mm.
    pub step_rms_mm: f64,
}

/// Normal equations of one iterate, column-scaled.
struct Normal {
    /// Scaled `J^T J` (unit diagonal where the column is non-zero).
    n: DMatrix<f64>,
    /// Scaled `J^T r`.
    b: DVector<f64>,
    /// Column norms of the unscaled Jacobian.
    norms: DVector<f64>,
    /// Sum of squared residuals, mm^2.
    cost: f64,
}

/// Scratch of one identification, allocated once.
struct Workspace {
    /// The configurations of the observations.
    qs: Vec<Joints>,
    /// The predicted TCPs in {W}.
    tcps: Vec<Vector3<f64>>,
    /// Transposed stacked Jacobian, p x 3n.
    jt: DMatrix<f64>,
    /// Stacked residuals, 3n.
    r: DVector<f64>,
    /// Unscaled normal matrix, p x p.
    n: DMatrix<f64>,
}

thread_local! {
    /// The transposed Jacobian's storage, kept between the identifications one thread runs: every
    /// entry is written before it is read, so a fit needs neither a fresh allocation nor zeroes.
    static JT_STORAGE: std::cell::Cell<Vec<f64>> = const { std::cell::Cell::new(Vec::new()) };
}

impl Workspace {
    fn new(p: usize, obs: &[Observation]) -> Self {
        let configurations = obs.len();
        let mut storage = JT_STORAGE.take();
        storage.resize(p * 3 * configurations, 0.0);
        Self {
            qs: obs.iter().map(|o| o.q).collect(),
            tcps: vec![Vector3::zeros(); configurations],
            jt: DMatrix::from_vec(p, 3 * configurations, storage),
            r: DVector::zeros(3 * configurations),
            n: DMatrix::zeros(p, p),
        }
    }
}

impl Drop for Workspace {
    fn drop(&mut self) {
        let jt = std::mem::replace(&mut self.jt, DMatrix::zeros(0, 0));
        JT_STORAGE.set(jt.data.into());
    }
}

fn accumulate(model: &RobotModel, set: &ParamSet, obs: &[Observation], ws: &mut Workspace) -> Normal {
    let p = set.len();
    // Rows 3i..3i + 3 of J are columns of jt (p x 3n, column-major).
    tcp_jacobians_transposed(model, set, &ws.qs, ws.jt.as_mut_slice(), &mut ws.tcps);
    for ((o, pw), r3) in obs.iter().zip(&ws.tcps).zip(ws.r.as_mut_slice().chunks_exact_mut(3)) {
        let res = o.tcp_world_mm - pw;
        r3.copy_from_slice(res.as_slice());
    }
    normal_matrix(&ws.jt, &mut ws.n);
    // `&jt * &r` (nalgebra's gemv), the same to the bit.
    let mut b = DVector::zeros(p);
    crate::numeric::matrix_vector(&ws.jt, ws.r.as_slice(), b.as_mut_slice());
    let cost = ws.r.norm_squared();
    let norms = DVector::from_fn(p, |j, _| ws.n[(j, j)].sqrt());
    let inv = norms.map(|v| if v > 0.0 { 1.0 / v } else { 0.0 });
    let n = DMatrix::from_fn(p, p, |i, j| ws.n[(i, j)] * inv[i] * inv[j]);
    let b = b.component_mul(&inv);
    Normal { n, b, norms, cost }
}

/// `N = J^T J` from the transposed Jacobian `jt` (p x m): the same to the bit as
/// `n.gemm(1.0, jt, &jt.transpose(), 0.0)` ([`crate::numeric::gemm_product`]).
fn normal_matrix(jt: &DMatrix<f64>, n: &mut DMatrix<f64>) {
    let p = jt.nrows();
    let b = crate::numeric::Factor { data: jt.as_slice(), row_stride: p, col_stride: 1 };
    crate::numeric::gemm_product(jt, b, p, n, true);
}

/// Eigen-decomposition of the scaled normal matrix: singular values (descending) and the rank test.
struct Spectrum {
    eig: SymmetricEigen<f64, nalgebra::Dyn>,
    sigma_max: f64,
}

impl Spectrum {
    fn new(n: &DMatrix<f64>) -> Option<Self> {
        let eig = crate::numeric::symmetric_eigen(n.clone())?;
        let sigma_max = eig.eigenvalues.iter().fold(0.0_f64, |m, &l| m.max(l)).max(0.0).sqrt();
        Some(Self { eig, sigma_max })
    }

    fn is_null(&self, k: usize, rank_rtol: f64) -> bool {
        self.eig.eigenvalues[k].max(0.0).sqrt() < rank_rtol * self.sigma_max
    }

    /// Parameters with a large component in a null vector (at least 10 % of that vector's largest).
    fn unidentifiable(&self, set: &ParamSet, rank_rtol: f64) -> Vec<usize> {
        let mut out = Vec::new();
        for k in 0..self.eig.eigenvalues.len() {
            if !self.is_null(k, rank_rtol) {
                continue;
            }
            let v = self.eig.eigenvectors.column(k);
            let vmax = v.amax();
            for (j, x) in v.iter().enumerate() {
                if x.abs() >= 0.1 * vmax && !out.contains(&j) {
                    out.push(j);
                }
            }
        }
        out.sort_unstable();
        debug_assert!(out.iter().all(|&j| j < set.len()));
        out
    }

    /// Truncated pseudo-inverse solution of `(N + mu I) x = b`.
    fn solve(&self, b: &DVector<f64>, mu: f64, rank_rtol: f64) -> DVector<f64> {
        let v = &self.eig.eigenvectors;
        let mut x = DVector::zeros(b.len());
        for k in 0..self.eig.eigenvalues.len() {
            if self.is_null(k, rank_rtol) {
                continue;
            }
            let coef = v.column(k).dot(b) / (self.eig.eigenvalues[k] + mu);
            x.axpy(coef, &v.column(k), 1.0);
        }
        x
    }
}

/// Solves `(N + mu I) x = b` by Cholesky; `None` when a pivot shows near-dependence.
fn cholesky_step(n: &DMatrix<f64>, b: &DVector<f64>, mu: f64, rank_rtol: f64) -> Option<DVector<f64>> {
    let mut m = n.clone();
    for i in 0..m.nrows() {
        m[(i, i)] += mu;
    }
    let chol = m.cholesky()?;
    let l = chol.l_dirty();
    // A unit-diagonal SPD matrix has lambda_min <= min pivot^2: a small pivot means a small sigma.
    let min_pivot = (0..l.nrows()).map(|i| l[(i, i)]).fold(f64::INFINITY, f64::min);
    if mu == 0.0 && min_pivot < rank_rtol * 1e2 {
        return None;
    }
    Some(chol.solve(b))
}

/// Identifies the parameters of `set` from `obs`, starting at `start` (which also supplies every
/// parameter outside the set).
pub fn identify(start: &RobotModel, set: &ParamSet, obs: &[Observation], opts: &FitOptions) -> Fit {
    let p = set.len();
    let mut ws = Workspace::new(p, obs);
    let mut x = set.pack(start);
    let mut model = start.clone();
    let scale_rms = 1.0 / ((3 * obs.len()).max(1) as f64).sqrt();

    let mut damping = Damping::none();
    let mut iterations = 0;
    let mut converged = false;
    let mut last_normal: Option<Normal> = None;
    let mut history = Vec::new();
    let mut accepted_cost: Option<f64> = None;
    while iterations < opts.max_iterations {
        iterations += 1;
        let ne = accumulate(&model, set, obs, &mut ws);
        // Every entry looked at (no early exit), so that the test runs four at a time.
        if !(ne.cost.is_finite() && ne.n.iter().fold(true, |all, v| all & v.is_finite())) {
            return Fit::not_finite(p, iterations, history);
        }
        if let Some(prev) = accepted_cost
            && (prev - ne.cost).abs() <= opts.cost_rtol * prev
        {
            // The last accepted step no longer changes the cost: this iterate is the solution.
            converged = true;
            history.push(Iteration { cost_mm2: ne.cost, step_rms_mm: 0.0 });
            last_normal = Some(ne);
            break;
        }
        if iterations == 1
            && let Solver::LevenbergMarquardt { tau } = opts.solver
        {
            damping = Damping::start(tau, (0..p).map(|i| ne.n[(i, i)]).fold(0.0, f64::max));
        }
        let Some(step_scaled) = cholesky_step(&ne.n, &ne.b, damping.mu, opts.rank_rtol)
            .or_else(|| Spectrum::new(&ne.n).map(|s| s.solve(&ne.b, damping.mu, opts.rank_rtol)))
        else {
            return Fit::not_finite(p, iterations, history);
        };
        let step = step_scaled.zip_map(&ne.norms, |s, nrm| if nrm > 0.0 { s / nrm } else { 0.0 });
        // RMS change of the predicted positions, from the linear model: |J dx| = |Js ds|.
        let predicted = (step_scaled.dot(&(&ne.n * &step_scaled))).max(0.0).sqrt() * scale_rms;
        history.push(Iteration { cost_mm2: ne.cost, step_rms_mm: predicted });
        let trial_x = &x + &step;
        let Ok(trial) = set.unpack(start, trial_x.as_slice()) else {
            break;
        };
        let accept = match opts.solver {
            Solver::GaussNewton => true,
            Solver::LevenbergMarquardt { .. } => {
                let new_cost = cost(&trial, obs);
                let gain = 2.0 * step_scaled.dot(&ne.b) - step_scaled.dot(&(&ne.n * &step_scaled));
                let rho = if gain > 0.0 { (ne.cost - new_cost) / gain } else { -1.0 };
                damping.update(rho)
            }
        };
        accepted_cost = accept.then_some(ne.cost);
        last_normal = Some(ne);
        if accept {
            x = trial_x;
            model = trial;
            if predicted < opts.step_tol_mm {
                converged = true;
                break;
            }
        } else if damping.mu > 1e16 {
            // Damping has run away: no step lowers the cost any more.
            converged = true;
            break;
        }
    }

    let residual_rms_mm = (cost(&model, obs) / obs.len().max(1) as f64).sqrt();
    conclude(set, opts, Iterate { model, x, iterations, converged, residual_rms_mm, history }, last_normal)
}

/// Where the iterations of [`identify`] stopped.
struct Iterate {
    model: RobotModel,
    x: DVector<f64>,
    iterations: usize,
    converged: bool,
    residual_rms_mm: f64,
    history: Vec<Iteration>,
}

/// The outcome of a fit from its last iterate and normal equations: the rank test on the scaled
/// normal matrix names the parameters the configurations cannot separate.
fn conclude(set: &ParamSet, opts: &FitOptions, it: Iterate, last_normal: Option<Normal>) -> Fit {
    let Iterate { model, x, iterations, converged, residual_rms_mm, history } = it;
    let p = set.len();
    let Some(ne) = last_normal else {
        return Fit {
            outcome: FitOutcome::IterationCap { iterations },
            model: Some(model),
            values: x.iter().map(|v| Some(*v)).collect(),
            iterations,
            singular_values: vec![],
            condition_number: f64::NAN,
            residual_rms_mm,
            history,
        };
    };
    let Some(eigenvalues) = crate::numeric::symmetric_eigenvalues(ne.n.clone()) else {
        return Fit::not_finite(p, iterations, history);
    };
    let mut singular_values: Vec<f64> = eigenvalues.iter().map(|l| l.max(0.0).sqrt()).collect();
    singular_values.sort_by(|a, b| b.total_cmp(a));
    let smax = singular_values.first().copied().unwrap_or(0.0);
    let smin = singular_values.last().copied().unwrap_or(0.0);
    // Eigenvectors only when some singular value is numerically zero: they name the parameters.
    let hidden = if smin < opts.rank_rtol * smax || smax == 0.0 {
        Spectrum::new(&ne.n).map_or_else(|| (0..p).collect(), |s| s.unidentifiable(set, opts.rank_rtol))
    } else {
        Vec::new()
    };
    let condition_number = if hidden.is_empty() && smin > 0.0 { smax / smin } else { f64::INFINITY };
    if !hidden.is_empty() && opts.truncate {
        let names = set.names();
        // Ratio of the largest to the smallest singular value kept.
        let kept = singular_values.iter().copied().filter(|s| *s >= opts.rank_rtol * smax).fold(f64::INFINITY, f64::min);
        return Fit {
            outcome: FitOutcome::Truncated { iterations, unidentifiable: hidden.iter().map(|&j| names[j].clone()).collect() },
            model: Some(model),
            values: x.iter().map(|v| Some(*v)).collect(),
            iterations,
            singular_values,
            condition_number: smax / kept,
            residual_rms_mm,
            history,
        };
    }
    if !hidden.is_empty() {
        let names = set.names();
        return Fit {
            outcome: FitOutcome::RankDeficient { unidentifiable: hidden.iter().map(|&j| names[j].clone()).collect() },
            model: None,
            values: x.iter().enumerate().map(|(j, v)| (!hidden.contains(&j)).then_some(*v)).collect(),
            iterations,
            singular_values,
            condition_number,
            residual_rms_mm,
            history,
        };
    }
    Fit {
        outcome: if converged { FitOutcome::Converged { iterations } } else { FitOutcome::IterationCap { iterations } },
        model: Some(model),
        values: x.iter().map(|v| Some(*v)).collect(),
        iterations,
        singular_values,
        condition_number,
        residual_rms_mm,
        history,
    }
}

/// Sum of squared position residuals of `model` over `obs`, mm^2.
fn cost(model: &RobotModel, obs: &[Observation]) -> f64 {
    crate::robot::tcps_world(model, obs.iter().map(|o| &o.q)).iter().zip(obs).map(|(p, o)| (o.tcp_world_mm - p).norm_squared()).sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// The normal matrix equals nalgebra's `gemm` bit for bit (the kernels' own test is in
    /// `numeric`): parameter counts 3 to 33, 6 to 600 stacked rows, 3 draws each.
    #[test]
    fn normal_matrix_equals_gemm_bit_for_bit() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for p in [3, 5, 6, 7, 26, 31, 32, 33] {
            for m in [6, 9, 75, 225, 256, 257, 300, 600] {
                for _ in 0..3 {
                    let jt = DMatrix::from_fn(p, m, |_, _| rng.random_range(-1.0..1.0) * 10f64.powi(rng.random_range(-6..=3)));
                    let mut expected = DMatrix::zeros(p, p);
                    expected.gemm(1.0, &jt, &jt.transpose(), 0.0);
                    let mut got = DMatrix::from_element(p, p, f64::NAN);
                    normal_matrix(&jt, &mut got);
                    let bits = |a: &DMatrix<f64>| a.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                    assert_eq!(bits(&got), bits(&expected), "p = {p}, m = {m}");
                }
            }
        }
    }
}
