//! The first-order (linear) prediction of a study's identification beside its Monte Carlo: what a
//! calibration tool reports from one run, `sigma^2 (J^T J)^-1`, against what the simulated worlds
//! give.
//!
//! Per task at one set size: `sigma` is the fit's own noise estimate (`sigma^2 = SSR / (3n - m)`,
//! per coordinate), `J` the identification Jacobian of the chosen configurations at the true robot.
//! The predicted parameter covariance `C = sigma^2 (J^T J)^-1` is set beside the squared errors of
//! the identified values (identified minus true), and the predicted validation errors `|J_v d|`,
//! `d ~ N(0, C)` at the validation poses, beside the simulated ones. The prediction assumes white
//! noise on every coordinate: an error source that is a bias (an unmodelled effect, a sphere that
//! is not where the cell file says) is absorbed by the parameters and leaves the residuals small,
//! so the simulated errors exceed the prediction. The sums merge over tasks and realisations.

use nalgebra::{DMatrix, DVector};
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use super::stats::{finite_sorted, median, quantile};
use crate::identify::observability::parameter_covariance;
use crate::robot::{Joints, ParamSet, RobotModel};

/// Draws of the parameter error per task for the predicted validation-error distribution.
const DRAWS: usize = 8;

/// The linear prediction against the simulation at one set size, as sums over tasks.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Prediction {
    /// Parameter names.
    pub names: Vec<String>,
    /// Per parameter: the sum over tasks of the squared error of the identified value (internal units).
    pub simulated_sq: Vec<f64>,
    /// Per parameter: the sum over tasks of the predicted variance.
    pub predicted_var: Vec<f64>,
    /// Tasks summed.
    pub tasks: u32,
    /// Per task: the predicted validation error's median and p95, mm.
    pub predicted_mm: Vec<[f64; 2]>,
    /// Per task: the simulated validation error's median and p95, mm.
    pub simulated_mm: Vec<[f64; 2]>,
    /// Per task: the fit's noise estimate per coordinate, mm.
    pub sigma_mm: Vec<f64>,
}

impl Prediction {
    /// Adds another's sums (another realisation of the same configuration).
    pub fn merge(&mut self, other: &Prediction) {
        if self.names.is_empty() {
            *self = other.clone();
            return;
        }
        for (a, b) in self.simulated_sq.iter_mut().zip(&other.simulated_sq) {
            *a += b;
        }
        for (a, b) in self.predicted_var.iter_mut().zip(&other.predicted_var) {
            *a += b;
        }
        self.tasks += other.tasks;
        self.predicted_mm.extend_from_slice(&other.predicted_mm);
        self.simulated_mm.extend_from_slice(&other.simulated_mm);
        self.sigma_mm.extend_from_slice(&other.sigma_mm);
    }

    /// Per parameter: the predicted standard deviation and the simulated RMS error (the prediction
    /// expects a zero mean, so its std is the RMS it predicts), internal units.
    pub fn parameter_spreads(&self) -> Vec<(f64, f64)> {
        let n = f64::from(self.tasks.max(1));
        self.predicted_var.iter().zip(&self.simulated_sq).map(|(p, s)| ((p / n).sqrt(), (s / n).sqrt())).collect()
    }

    /// The median over parameters of simulated RMS over predicted std.
    pub fn median_ratio(&self) -> f64 {
        median(&self.parameter_spreads().iter().map(|(p, s)| s / p).collect::<Vec<_>>())
    }

    /// Medians over tasks: predicted median and p95, simulated median and p95, sigma, mm.
    pub fn errors_mm(&self) -> [f64; 5] {
        let m = |v: &[[f64; 2]], k: usize| median(&v.iter().map(|x| x[k]).collect::<Vec<_>>());
        [m(&self.predicted_mm, 0), m(&self.predicted_mm, 1), m(&self.simulated_mm, 0), m(&self.simulated_mm, 1), median(&self.sigma_mm)]
    }
}

/// The fit's estimate of the noise per coordinate, `sqrt(SSR / (3n - m))`, from its residual RMS
/// per configuration (`sqrt(SSR / n)`), for n configurations and m parameters; NaN when 3n <= m.
pub fn noise_estimate(residual_rms_mm: f64, n: usize, m: usize) -> f64 {
    let dof = (3 * n).saturating_sub(m);
    if dof == 0 { f64::NAN } else { residual_rms_mm * (n as f64 / dof as f64).sqrt() }
}

/// What the prediction needs of one identification.
pub struct TaskView<'a> {
    /// Task index (keys the draws).
    pub index: usize,
    /// Chosen pool indices.
    pub chosen: &'a [usize],
    /// Identified values (`None`: not identified).
    pub values: &'a [Option<f64>],
    /// The fit's residual RMS per configuration, mm.
    pub residual_rms_mm: f64,
    /// The simulated figure of merit after calibration: median and p95, mm.
    pub simulated_mm: [f64; 2],
}

/// The prediction over `tasks` (identifications of `set` from `truth`'s configurations
/// `pool_qs`); the predicted validation errors at `validation_qs` (none when empty).
pub fn predict_tasks<'a>(
    set: &ParamSet,
    truth: &RobotModel,
    tasks: impl Iterator<Item = TaskView<'a>>,
    pool_qs: &[Joints],
    validation_qs: &[Joints],
    seed: u64,
) -> Option<Prediction> {
    let m = set.len();
    let truth_values = set.pack(truth);
    let jv = crate::identify::observability::stacked_jacobian(truth, set, validation_qs);
    let mut out = Prediction { names: set.names(), simulated_sq: vec![0.0; m], predicted_var: vec![0.0; m], ..Prediction::default() };
    for t in tasks {
        let n = t.chosen.len();
        if !t.simulated_mm.iter().all(|v| v.is_finite()) {
            continue;
        }
        let Some(values) = t.values.iter().copied().collect::<Option<Vec<f64>>>() else {
            continue;
        };
        if values.len() != m {
            continue;
        }
        let sigma = noise_estimate(t.residual_rms_mm, n, m);
        if !(sigma.is_finite() && sigma > 0.0) {
            continue;
        }
        let qs: Vec<Joints> = t.chosen.iter().map(|&k| pool_qs[k]).collect();
        let Some(cov) = parameter_covariance(truth, set, &qs, sigma) else {
            continue;
        };
        if !cov.iter().all(|c| c.is_finite()) {
            continue;
        }
        let Some(chol) = cov.clone().cholesky() else {
            continue;
        };
        let errors = DVector::from_vec(values) - &truth_values;
        if !errors.iter().all(|e| e.is_finite()) {
            continue;
        }
        for j in 0..m {
            out.simulated_sq[j] += errors[j] * errors[j];
            out.predicted_var[j] += cov[(j, j)];
        }
        if !validation_qs.is_empty() {
            // The validation errors of DRAWS parameter errors drawn from N(0, C).
            let rng = &mut crate::seeds::task_stream(seed, crate::seeds::PREDICTION, t.index);
            let z = DMatrix::from_fn(m, DRAWS, |_, _| StandardNormal.sample(rng));
            let moved = &jv * (chol.l() * z);
            let e: Vec<f64> = (0..DRAWS)
                .flat_map(|d| (0..validation_qs.len()).map(move |v| (d, v)))
                .map(|(d, v)| moved.fixed_view::<3, 1>(3 * v, d).norm())
                .collect();
            let sorted = finite_sorted(&e);
            out.predicted_mm.push([quantile(&sorted, 0.5), quantile(&sorted, 0.95)]);
        }
        out.simulated_mm.push(t.simulated_mm);
        out.sigma_mm.push(sigma);
        out.tasks += 1;
    }
    (out.tasks > 0).then_some(out)
}
