//! Outliers: found, reported and left out of the fit, never dropped silently.
//!
//! The rule (iteratively reweighted least squares with 0/1 weights): fit the points not yet
//! flagged; take the robust scale of the weighted residual norms, `s = median |r_i| / 1.5382` (the
//! median of the chi distribution with 3 degrees of freedom, so that `s` estimates the noise per
//! coordinate of Gaussian points whatever the outliers); flag every point whose norm exceeds
//! `threshold * s`; repeat until the flags do not change (a flagged point comes back when a later
//! fit explains it). The default threshold 4.5943 is the chi(3) quantile at 1 - 1e-4: a Gaussian
//! point is flagged with probability 1e-4 (one in 10,000 points). Every flagged point stays in
//! the report with its residual.
//!
//! Orientation readings follow the same rule on their own scale: a reading's weighted rotation
//! residual `|e| / sigma_rad` (e the rotation vector between the measured and the model's probe
//! frame) is chi(3)-distributed times one scale when the readings are Gaussian, as a point's
//! weighted position residual is; that scale is taken robustly over the readings alone
//! (`median / 1.5382`), so a misstated `--orientation-noise-mdeg` neither flags nor hides readings,
//! and a Gaussian reading exceeds the threshold with the same probability as a Gaussian point. A
//! flagged reading is left out of the next round's fit while its point's position stays in (and
//! the other way round).

use nalgebra::DMatrix;

use super::problem::{Fit, Oriented, Reading, SolveOptions, Solved, solve};

/// Median of the chi distribution with 3 degrees of freedom (the square root of the median of
/// chi-square(3), 2.365974).
pub const CHI3_MEDIAN: f64 = 1.538_172;
/// The default outlier threshold in robust standard deviations: P(chi(3) > 4.5943) = 1e-4
/// (chi-square(3) quantile at 0.9999 = 21.1075 = 4.5943^2).
pub const DEFAULT_THRESHOLD: f64 = 4.5943;
/// The least robust scale (1 nm when the points carry no uncertainty): the rounding residuals of a
/// noise-free fit are not outliers.
const LEAST_SCALE: f64 = 1e-6;
/// Rounds of fitting and flagging at most.
const MOST_ROUNDS: usize = 10;

/// What the outlier rule does with the points it flags (`--outliers`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OutlierMode {
    /// No point is flagged.
    Off,
    /// Points are flagged and reported, and kept in every fit and statistic (the default: the
    /// figures then include every measured point, and a flagged point cannot hide what the model
    /// misses).
    Report,
    /// Points are flagged, reported and left out of every fit and statistic.
    Reject,
}

impl OutlierMode {
    /// The option's value.
    pub fn name(self) -> &'static str {
        match self {
            OutlierMode::Off => "off",
            OutlierMode::Report => "report",
            OutlierMode::Reject => "reject",
        }
    }

    /// The mode named `s` (`off`, `report`, `reject`).
    pub fn parse(s: &str) -> Option<Self> {
        [OutlierMode::Off, OutlierMode::Report, OutlierMode::Reject].into_iter().find(|m| m.name() == s)
    }
}

/// A fit with its outliers.
#[derive(Clone, Debug)]
pub struct RobustFit {
    /// The last fit (over the points not flagged).
    pub solved: Solved,
    /// The points considered (indices into the problem's points).
    pub idx: Vec<usize>,
    /// Per point of `idx`: flagged as an outlier.
    pub outlier: Vec<bool>,
    /// Per point of `idx`: its weighted residual norm over the robust scale.
    pub normalized: Vec<f64>,
    /// The robust scale of the weighted residual norms (per coordinate).
    pub robust_scale: f64,
    /// The a-posteriori noise per coordinate of unit weight, `sqrt(SSR / (3 n - m))` over the points
    /// not flagged (mm when the points carry no uncertainty).
    pub sigma_hat: f64,
    /// Rounds of fitting and flagging.
    pub rounds: usize,
    /// Per point of `idx`: its orientation reading flagged as an outlier (false without one).
    pub reading_outlier: Vec<bool>,
    /// Per point of `idx`: its reading's weighted rotation residual norm over the readings' robust
    /// scale (NaN without a reading, or for a reading the fit left out).
    pub reading_normalized: Vec<f64>,
}

impl RobustFit {
    /// The points of `idx` not flagged.
    pub fn inliers(&self) -> Vec<usize> {
        self.idx.iter().zip(&self.outlier).filter(|(_, o)| !**o).map(|(i, _)| *i).collect()
    }
}

/// Fits `free` over the points `idx` from `x0` with the outlier rule of this module.
pub fn robust_fit(problem: &Oriented<'_>, x0: &[f64], free: &[usize], idx: &[usize], threshold: f64, opts: &SolveOptions) -> RobustFit {
    robust_fit_and_first(problem, x0, free, idx, threshold, opts).0
}

/// [`robust_fit`] and its first round: the fit of every point of `idx` from `x0`
/// ([`fit_without`] with no point flagged). Points and orientation readings are flagged
/// separately: a flagged reading leaves its point's position in the fit.
pub fn robust_fit_and_first(
    problem: &Oriented<'_>,
    x0: &[f64],
    free: &[usize],
    idx: &[usize],
    threshold: f64,
    opts: &SolveOptions,
) -> (RobustFit, RobustFit) {
    let mut outlier = vec![false; idx.len()];
    let mut dropped = vec![false; idx.len()];
    let mut x = x0.to_vec();
    let mut rounds = 0;
    let mut first = None;
    loop {
        rounds += 1;
        let kept: Vec<Option<Reading>>;
        let reduced;
        let on = if dropped.iter().any(|d| *d) {
            kept = without_readings(problem.readings, idx, &dropped);
            reduced = Oriented { readings: &kept, ..problem.clone() };
            &reduced
        } else {
            problem
        };
        let mut fit = fit_without(on, &x, free, idx, &outlier, opts);
        // Every reading's residual, the ones left out of this round's fit included.
        fit.reading_normalized = reading_residuals(problem, &fit.solved.x, idx);
        let first = first.get_or_insert_with(|| fit.clone());
        // NaN (no model) flags nothing: the fit's outcome says what happened.
        let flags: Vec<bool> = fit.normalized.iter().map(|u| *u > threshold).collect();
        let reading_flags: Vec<bool> = fit.reading_normalized.iter().map(|u| *u > threshold).collect();
        if (flags == outlier && reading_flags == dropped) || rounds == MOST_ROUNDS || !fit.robust_scale.is_finite() {
            return (RobustFit { rounds, reading_outlier: dropped, ..fit }, first.clone());
        }
        x.clone_from(&fit.solved.x);
        outlier = flags;
        dropped = reading_flags;
    }
}

/// `readings` with the readings of the points of `idx` flagged in `dropped` taken out.
pub fn without_readings(readings: &[Option<Reading>], idx: &[usize], dropped: &[bool]) -> Vec<Option<Reading>> {
    let mut kept = readings.to_vec();
    for (&i, _) in idx.iter().zip(dropped).filter(|(_, d)| **d) {
        kept[i] = None;
    }
    kept
}

/// Per point of `idx`: its reading's weighted rotation residual norm `|e| / sigma_rad` at `x` over
/// the robust scale of those norms (`median / chi(3)'s median`); NaN without a reading.
fn reading_residuals<P: Fit + ?Sized>(problem: &P, x: &[f64], idx: &[usize]) -> Vec<f64> {
    let Some(errors) = problem.rotation_errors(x, idx) else { return vec![f64::NAN; idx.len()] };
    let norms: Vec<f64> =
        errors.iter().zip(idx).map(|(e, &i)| e.zip(problem.reading_sigma(i)).map_or(f64::NAN, |(e, s)| e.norm() / s)).collect();
    let read: Vec<f64> = norms.iter().copied().filter(|u| !u.is_nan()).collect();
    if read.is_empty() {
        return norms;
    }
    let scale = (crate::study::stats::median(&read) / CHI3_MEDIAN).max(LEAST_SCALE);
    norms.iter().map(|u| u / scale).collect()
}

/// Fits `free` over the points of `idx` not flagged in `outlier` (one flag per point of `idx`):
/// the flags are given, not decided; the robust scale and normalized residuals are of every
/// point of `idx`.
pub fn fit_without<P: Fit + ?Sized>(
    problem: &P,
    x0: &[f64],
    free: &[usize],
    idx: &[usize],
    outlier: &[bool],
    opts: &SolveOptions,
) -> RobustFit {
    debug_assert_eq!(idx.len(), outlier.len(), "a flag per point");
    let active: Vec<usize> = idx.iter().zip(outlier).filter(|(_, o)| !**o).map(|(i, _)| *i).collect();
    let mut solved = solve(problem, x0, free, &active, opts);
    let positions = problem.positions();
    // The errors at the solution: the solver's last pass has the fitted points' (a point's error
    // is its own, whichever pass computes it), the flagged ones computed here.
    let errors = match solved.errors.take() {
        None => positions.errors(&solved.x, idx),
        Some(fitted) if fitted.len() == idx.len() => Some(fitted),
        Some(fitted) => {
            let flagged: Vec<usize> = idx.iter().zip(outlier).filter(|(_, o)| **o).map(|(i, _)| *i).collect();
            positions.errors(&solved.x, &flagged).map(|left| {
                let (mut fitted, mut left) = (fitted.into_iter(), left.into_iter());
                outlier.iter().map(|o| if *o { left.next() } else { fitted.next() }.expect("an error per point")).collect()
            })
        }
    };
    let norms: Vec<f64> = match errors {
        Some(e) => e.iter().zip(idx).map(|(e, &i)| e.norm() / positions.obs[i].sigma).collect(),
        None => vec![f64::NAN; idx.len()],
    };
    let scale = (crate::study::stats::median(&norms) / CHI3_MEDIAN).max(LEAST_SCALE);
    let dof = (3 * active.len() + problem.own_rows(&active)).saturating_sub(free.len());
    let sigma_hat = if dof == 0 { f64::NAN } else { (solved.cost / dof as f64).sqrt() };
    let normalized = norms.iter().map(|u| u / scale).collect();
    RobustFit {
        solved,
        idx: idx.to_vec(),
        outlier: outlier.to_vec(),
        normalized,
        robust_scale: scale,
        sigma_hat,
        rounds: 1,
        reading_outlier: vec![false; idx.len()],
        reading_normalized: vec![f64::NAN; idx.len()],
    }
}

/// The first-order covariance `sigma_hat^2 (J^T J)^-1` of the free unknowns of `fit` (internal
/// units, in the order of `free`), over its points not flagged: `J^T J` summed by
/// [`Problem::normal_equations`], scaled to a unit diagonal, inverted. `None` when singular.
pub fn covariance<P: Fit + ?Sized>(problem: &P, fit: &RobustFit, free: &[usize]) -> Option<DMatrix<f64>> {
    let (n, _) = problem.normal_equations(&fit.solved.x, &fit.inliers(), free)?;
    let k = n.nrows();
    let scale: Vec<f64> = (0..k).map(|c| n[(c, c)].sqrt()).collect();
    if scale.iter().any(|s| *s == 0.0 || !s.is_finite()) {
        return None;
    }
    let inv = DMatrix::from_fn(k, k, |a, c| n[(a, c)] / scale[a] / scale[c]).try_inverse()?;
    let s2 = fit.sigma_hat * fit.sigma_hat;
    Some(DMatrix::from_fn(k, k, |a, c| s2 * inv[(a, c)] / (scale[a] * scale[c])))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The chi(3) constants against Simpson's rule on the chi(3) density `sqrt(2 / pi) t^2
    /// exp(-t^2 / 2)` (smooth, 20,000 intervals): the median and the tail beyond the default
    /// threshold, 1e-4.
    #[test]
    fn chi3_constants_match_the_chi_density() {
        let density = |t: f64| (2.0 / std::f64::consts::PI).sqrt() * t * t * (-t * t / 2.0).exp();
        let cdf = |to: f64| {
            let n = 20_000;
            let h = to / n as f64;
            let mut s = density(0.0) + density(to);
            for k in 1..n {
                s += density(k as f64 * h) * if k % 2 == 1 { 4.0 } else { 2.0 };
            }
            s * h / 3.0
        };
        assert!((cdf(CHI3_MEDIAN) - 0.5).abs() < 1e-6, "median: {}", cdf(CHI3_MEDIAN));
        let tail = 1.0 - cdf(DEFAULT_THRESHOLD);
        assert!((tail - 1e-4).abs() < 1e-7, "tail beyond the threshold: {tail}");
    }
}
