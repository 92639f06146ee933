//! The searches over the unit cube: argmin's Nelder-Mead simplex started around the start design
//! and its particle swarm over the whole cube, and a CMA-ES (Hansen's covariance matrix
//! adaptation evolution strategy, [`cmaes`]) started at the start design, whose ranking of a
//! generation's samples and averaging over the best half tolerate a noisy objective. The objective is any function of a
//! point of `[0, 1]^d` (a design's score on common worlds, or a synthetic test function); a
//! budget caps the evaluations, after which the objective is no longer called.
//!
//! Nelder-Mead moves outside the cube; its points are folded back (a reflection at each face), so
//! that every point it asks for is a design and the start's neighbourhood is searched first. The
//! swarm keeps its particles inside the bounds itself.

use std::cell::RefCell;

use argmin::core::{CostFunction, Error as ArgminError, Executor};
use argmin::solver::neldermead::NelderMead;
use argmin::solver::particleswarm::ParticleSwarm;
use rand_xoshiro::rand_core::SeedableRng;

use super::spec::Method;

/// A point of `R^d` folded into `[0, 1]^d` (reflected at each face: a triangle wave).
pub fn fold(x: &[f64]) -> Vec<f64> {
    x.iter()
        .map(|v| {
            if !v.is_finite() {
                return 0.5;
            }
            let z = v.rem_euclid(2.0);
            if z <= 1.0 { z } else { 2.0 - z }
        })
        .collect()
}

/// An objective over the unit cube.
type Objective<'a> = &'a mut dyn FnMut(&[f64]) -> f64;

/// The objective as argmin sees it: folds the point, counts the budget.
struct Budgeted<'a> {
    f: RefCell<Objective<'a>>,
    left: RefCell<u32>,
}

impl CostFunction for Budgeted<'_> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, x: &Vec<f64>) -> Result<f64, ArgminError> {
        let mut left = self.left.borrow_mut();
        if *left == 0 {
            // Spent: the search winds down without running anything more.
            return Ok(f64::INFINITY);
        }
        *left -= 1;
        Ok((self.f.borrow_mut())(&fold(x)))
    }
}

/// Minimises `f` over `[0, 1]^d` from `start` with `method`, calling it at most `budget` times;
/// `seed` keys the swarm's and CMA-ES's draws. The caller keeps what `f` was called with (its trace).
pub fn minimise(method: Method, start: &[f64], budget: u32, seed: u64, f: &mut dyn FnMut(&[f64]) -> f64) -> Result<(), ArgminError> {
    let d = start.len();
    if d == 0 {
        f(&[]);
        return Ok(());
    }
    let problem = Budgeted { f: RefCell::new(f), left: RefCell::new(budget) };
    match method {
        Method::NelderMead => {
            // The simplex: the start and one step of 0.15 (of each variable's range) along each axis,
            // inwards where the start is near the upper face.
            let mut simplex = vec![start.to_vec()];
            for k in 0..d {
                let mut p = start.to_vec();
                p[k] += if p[k] > 0.85 { -0.15 } else { 0.15 };
                simplex.push(p);
            }
            let solver: NelderMead<Vec<f64>, f64> = NelderMead::new(simplex).with_sd_tolerance(1e-4)?;
            Executor::new(problem, solver).configure(|s| s.max_iters(u64::from(budget))).run()?;
        }
        Method::Cmaes => {
            let Budgeted { f, left } = problem;
            let f = f.into_inner();
            cmaes(start, *left.borrow(), seed, &mut |x| f(&fold(x)));
        }
        Method::ParticleSwarm => {
            let particles = (4 + d).min(budget as usize).max(2);
            let solver = ParticleSwarm::new((vec![0.0; d], vec![1.0; d]), particles)
                .with_rng_generator(rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(seed));
            let iters = u64::from(budget).div_ceil(particles as u64);
            Executor::new(problem, solver).configure(|s| s.max_iters(iters)).run()?;
        }
    }
    Ok(())
}

/// Step size CMA-ES starts with, in units of each variable's range.
pub const CMAES_SIGMA: f64 = 0.2;

/// CMA-ES (Hansen, "The CMA Evolution Strategy: A Tutorial", 2016, its default parameters):
/// generations of `4 + 3 ln d` samples drawn around the mean with the step size and covariance,
/// the mean moved to the weighted best half, the step size by cumulative path length control
/// and the covariance by its rank-one and rank-mu updates; started at `start` with step
/// [`CMAES_SIGMA`], `f` called at most `budget` times (the last generation cut short). Each sample
/// is folded into the cube ([`fold`]) before `f` sees it, and the update takes the folded point
/// (the repair keeps the mean inside). `seed` keys the draws; the same seed, the same points.
pub fn cmaes(start: &[f64], budget: u32, seed: u64, f: &mut dyn FnMut(&[f64]) -> f64) {
    use nalgebra::{DMatrix, DVector};
    use rand_distr::{Distribution, StandardNormal};
    let n = start.len();
    if n == 0 || budget == 0 {
        return;
    }
    let nf = n as f64;
    let lambda = 4 + (3.0 * nf.ln()).floor() as usize;
    let mu = lambda / 2;
    let raw: Vec<f64> = (0..mu).map(|i| ((lambda as f64 + 1.0) / 2.0).ln() - ((i + 1) as f64).ln()).collect();
    let total: f64 = raw.iter().sum();
    let w: Vec<f64> = raw.iter().map(|v| v / total).collect();
    let mueff = 1.0 / w.iter().map(|v| v * v).sum::<f64>();
    let cc = (4.0 + mueff / nf) / (nf + 4.0 + 2.0 * mueff / nf);
    let cs = (mueff + 2.0) / (nf + mueff + 5.0);
    let c1 = 2.0 / ((nf + 1.3).powi(2) + mueff);
    let cmu = (1.0 - c1).min(2.0 * (mueff - 2.0 + 1.0 / mueff) / ((nf + 2.0).powi(2) + mueff));
    let damps = 1.0 + 2.0 * (0.0f64).max(((mueff - 1.0) / (nf + 1.0)).sqrt() - 1.0) + cs;
    let chi_n = nf.sqrt() * (1.0 - 1.0 / (4.0 * nf) + 1.0 / (21.0 * nf * nf));
    let mut mean = DVector::from_column_slice(&fold(start));
    let mut sigma = CMAES_SIGMA;
    let mut c = DMatrix::<f64>::identity(n, n);
    let (mut pc, mut ps) = (DVector::<f64>::zeros(n), DVector::<f64>::zeros(n));
    let mut b = DMatrix::<f64>::identity(n, n);
    let mut d = DVector::<f64>::from_element(n, 1.0);
    let mut rng = crate::seeds::fixed_stream(seed);
    let mut left = budget;
    let mut generation = 0u32;
    while left > 0 {
        generation += 1;
        // A generation: samples, folded, evaluated in order (the budget may cut it short).
        let mut pop: Vec<(f64, DVector<f64>)> = Vec::with_capacity(lambda);
        for _ in 0..lambda {
            if left == 0 {
                break;
            }
            let z = DVector::<f64>::from_fn(n, |_, _| StandardNormal.sample(&mut rng));
            let y = &b * d.component_mul(&z);
            let x = DVector::from_vec(fold((&mean + sigma * y).as_slice()));
            left -= 1;
            let v = f(x.as_slice());
            pop.push((if v.is_nan() { f64::INFINITY } else { v }, x));
        }
        if pop.len() < lambda {
            break;
        }
        pop.sort_by(|a, b| a.0.total_cmp(&b.0));
        let old = mean.clone();
        mean = DVector::zeros(n);
        for i in 0..mu {
            mean += w[i] * &pop[i].1;
        }
        let step = (&mean - &old) / sigma;
        // C^(-1/2) step, by the eigen decomposition C = B D^2 B^T.
        let inv_sqrt = &b * DMatrix::from_diagonal(&d.map(|v| 1.0 / v)) * b.transpose();
        ps = (1.0 - cs) * &ps + (cs * (2.0 - cs) * mueff).sqrt() * (&inv_sqrt * &step);
        let ps_norm = ps.norm();
        let hsig = ps_norm / (1.0 - (1.0 - cs).powi(2 * generation as i32)).sqrt() / chi_n < 1.4 + 2.0 / (nf + 1.0);
        let h = if hsig { 1.0 } else { 0.0 };
        pc = (1.0 - cc) * &pc + h * (cc * (2.0 - cc) * mueff).sqrt() * &step;
        let mut rank_mu = DMatrix::<f64>::zeros(n, n);
        for i in 0..mu {
            let y = (&pop[i].1 - &old) / sigma;
            rank_mu += w[i] * &y * y.transpose();
        }
        c = (1.0 - c1 - cmu) * &c + c1 * (&pc * pc.transpose() + (1.0 - h) * cc * (2.0 - cc) * &c) + cmu * rank_mu;
        sigma *= ((cs / damps) * (ps_norm / chi_n - 1.0)).exp();
        // A step size beyond the cube's width searches nothing more: capped there.
        sigma = sigma.min(1.0);
        c = (&c + c.transpose()) * 0.5;
        let eig = nalgebra::SymmetricEigen::new(c.clone());
        b = eig.eigenvectors;
        d = eig.eigenvalues.map(|v| v.max(1e-20).sqrt());
        if sigma * d.max() < 1e-8 {
            // Converged: nothing left to learn from more samples.
            break;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A smooth bowl with its minimum at (0.3, 0.7, 0.55).
    fn bowl(x: &[f64]) -> f64 {
        let t = [0.3, 0.7, 0.55];
        x.iter().zip(t).map(|(a, b)| (a - b).powi(2)).sum()
    }

    fn best_of(method: Method, budget: u32) -> (Vec<f64>, f64, usize) {
        let mut trace: Vec<(Vec<f64>, f64)> = Vec::new();
        let mut f = |x: &[f64]| {
            let v = bowl(x);
            trace.push((x.to_vec(), v));
            v
        };
        minimise(method, &[0.5; 3], budget, 7, &mut f).expect("runs");
        let best = trace.iter().min_by(|a, b| a.1.total_cmp(&b.1)).cloned().expect("evaluated");
        (best.0, best.1, trace.len())
    }

    /// The simplex stops when its costs spread by less than 1e-4 (a search score moves in steps
    /// of 0.01 of P(success)): the bowl's minimum is then within 0.015 of each coordinate.
    #[test]
    fn nelder_mead_finds_the_minimum_of_a_bowl_within_its_budget() {
        let (x, v, n) = best_of(Method::NelderMead, 300);
        assert!(n <= 300, "{n} evaluations for a budget of 300");
        assert!(x.iter().zip([0.3, 0.7, 0.55]).all(|(a, b)| (a - b).abs() < 0.015), "best {v} at {x:?}");
    }

    #[test]
    fn the_swarm_finds_the_minimum_of_a_bowl_within_its_budget() {
        let (x, v, n) = best_of(Method::ParticleSwarm, 700);
        assert!(n <= 700, "{n} evaluations for a budget of 700");
        assert!(x.iter().zip([0.3, 0.7, 0.55]).all(|(a, b)| (a - b).abs() < 0.015), "best {v} at {x:?}");
    }

    #[test]
    fn cmaes_finds_the_minimum_of_a_bowl_within_its_budget() {
        let (x, v, n) = best_of(Method::Cmaes, 300);
        assert!(n <= 300, "{n} evaluations for a budget of 300");
        assert!(x.iter().zip([0.3, 0.7, 0.55]).all(|(a, b)| (a - b).abs() < 0.015), "best {v} at {x:?}");
    }

    /// The same seed, the same points; another seed, other points.
    #[test]
    fn cmaes_is_deterministic_by_its_seed() {
        let trace = |seed: u64| {
            let mut t: Vec<Vec<f64>> = Vec::new();
            cmaes(&[0.5; 4], 40, seed, &mut |x| {
                t.push(x.to_vec());
                bowl(&x[..3])
            });
            t
        };
        assert_eq!(trace(3), trace(3));
        assert_ne!(trace(3), trace(4));
        assert_eq!(trace(3).len(), 40);
    }

    #[test]
    fn folding_reflects_at_the_faces_of_the_cube() {
        assert_eq!(fold(&[0.25, 1.25, -0.25, 2.5, f64::NAN]), vec![0.25, 0.75, 0.25, 0.5, 0.5]);
    }
}
