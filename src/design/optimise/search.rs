//! The two searches over the unit cube, both argmin's: Nelder-Mead's simplex started around the
//! start design, and the particle swarm over the whole cube. The objective is any function of a
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
/// `seed` keys the swarm's draws. The caller keeps what `f` was called with (its trace).
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
    fn folding_reflects_at_the_faces_of_the_cube() {
        assert_eq!(fold(&[0.25, 1.25, -0.25, 2.5, f64::NAN]), vec![0.25, 0.75, 0.25, 0.5, 0.5]);
    }
}
