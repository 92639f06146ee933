//! The pool of feasible configurations, the validation poses spread over the workspace of
//! interest, DETMAX's choice of the training poses, and the tour between them.

use nalgebra::Vector3;
use rayon::prelude::*;

use super::cell::{Cell, Refusal};
use super::spec::{Plan, PlanError, model_params};
use crate::identify::detmax::{DetmaxOptions, PoolJacobian, detmax, o1_of};
use crate::robot::{BaseParam, Joints, KinState, ParamId, ParamSet, uniform_configuration};

/// Candidates drawn per feasible configuration asked for before the pool is given up as too
/// small.
pub const MOST_TRIES_PER_POSE: usize = 200;

/// The pool: feasible configurations in the order of their candidate index, with the count of
/// each refusal among the candidates tried.
#[derive(Clone, Debug, PartialEq)]
pub struct Pool {
    /// Feasible configurations, rad.
    pub qs: Vec<Joints>,
    /// Candidates drawn.
    pub tried: usize,
    /// Refusals per [`Refusal::ALL`].
    pub refused: [usize; 6],
}

/// Draws `want` feasible configurations: candidate i is uniform within the plan's limits, drawn
/// from its own stream (`seeds::plan::POOL`, i), so the pool is the same for any thread count.
pub fn pool(plan: &Plan, cell: &Cell, want: usize) -> Result<Pool, PlanError> {
    let seed = crate::seeds::split_seed(plan.seed, crate::seeds::plan::POOL);
    let most = want.saturating_mul(MOST_TRIES_PER_POSE);
    let mut out = Pool { qs: Vec::with_capacity(want), tried: 0, refused: [0; 6] };
    let mut chunk = (2 * want).max(256);
    while out.qs.len() < want && out.tried < most {
        let start = out.tried;
        let end = (start + chunk).min(most);
        let results: Vec<(Joints, Result<(), Refusal>)> = (start..end)
            .into_par_iter()
            .map_init(KinState::default, |st, i| {
                let mut rng = crate::seeds::stream(seed, i as u64);
                let q = uniform_configuration(&cell.model, 0.0, &mut rng);
                (q, cell.check(&q, st))
            })
            .collect();
        for (q, r) in results {
            out.tried += 1;
            match r {
                Ok(()) => {
                    out.qs.push(q);
                    if out.qs.len() == want {
                        break;
                    }
                }
                Err(why) => out.refused[Refusal::ALL.iter().position(|x| *x == why).expect("a refusal")] += 1,
            }
        }
        chunk *= 2;
    }
    if out.qs.is_empty() {
        return Err(PlanError::new(&plan.path, "tracker", format!("no feasible pose in {} candidates ({})", out.tried, refusals(&out))));
    }
    Ok(out)
}

/// The refusals in words.
pub fn refusals(p: &Pool) -> String {
    Refusal::ALL.iter().zip(&p.refused).filter(|(_, n)| **n > 0).map(|(r, n)| format!("{} {n}", r.name())).collect::<Vec<_>>().join(", ")
}

/// Validation poses: `n` of the pool whose first target lies in the workspace of interest,
/// spread by farthest-point sampling of the target positions (the first is the one nearest the
/// box's centre). Returns pool indices; an error when fewer than `n` lie in the box.
pub fn validation(plan: &Plan, cell: &Cell, qs: &[Joints], n: usize) -> Result<Vec<usize>, PlanError> {
    if n == 0 {
        return Ok(Vec::new());
    }
    let mut st = KinState::default();
    let inside: Vec<(usize, Vector3<f64>)> = qs
        .iter()
        .enumerate()
        .filter_map(|(i, q)| {
            crate::robot::forward(&cell.model, &mut st, q);
            let (p, _) = cell.target(&st, 0);
            plan.workspace.contains(&p).then_some((i, p))
        })
        .collect();
    if inside.len() < n {
        return Err(PlanError::new(
            &plan.path,
            "cell.workspace_min_mm",
            format!(
                "{} feasible poses of the pool put the first target in the workspace of interest: fewer than validation = {n}",
                inside.len()
            ),
        ));
    }
    let centre = (plan.workspace.min + plan.workspace.max) / 2.0;
    let first =
        (0..inside.len()).min_by(|&a, &b| (inside[a].1 - centre).norm().total_cmp(&(inside[b].1 - centre).norm())).expect("not empty");
    let mut chosen = vec![first];
    let mut nearest: Vec<f64> = inside.iter().map(|(_, p)| (p - inside[first].1).norm()).collect();
    while chosen.len() < n {
        let next = (0..inside.len()).max_by(|&a, &b| nearest[a].total_cmp(&nearest[b]).then(b.cmp(&a))).expect("not empty");
        chosen.push(next);
        for (k, (_, p)) in inside.iter().enumerate() {
            nearest[k] = nearest[k].min((p - inside[next].1).norm());
        }
    }
    let mut out: Vec<usize> = chosen.into_iter().map(|k| inside[k].0).collect();
    out.sort_unstable();
    Ok(out)
}

/// The identification problem DETMAX scores: the model's robot parameters the pool can
/// separate at the first target (calibrate's identifiability check on the pool), a base and a
/// tool at the first target.
pub fn detmax_set(plan: &Plan, cell: &Cell, qs: &[Joints]) -> Result<ParamSet, PlanError> {
    let robot = super::identifiable(plan, cell, qs, &model_params(plan.model), 1)?.0;
    let mut ids = robot.ids().to_vec();
    ids.extend([BaseParam::X, BaseParam::Y, BaseParam::Z, BaseParam::Alpha, BaseParam::Beta, BaseParam::Gamma].map(ParamId::Base));
    ids.extend((0..3).map(ParamId::Tool));
    ParamSet::new(ids).map_err(|e| PlanError::new(&plan.path, "model", e.to_string()))
}

/// The pool's scaled identification Jacobians at the first target for `set`.
pub fn pool_jacobian(plan: &Plan, cell: &Cell, qs: &[Joints], set: &ParamSet) -> Result<PoolJacobian, PlanError> {
    let model = cell
        .model
        .edited(|d| d.flange_tcp_mm = plan.targets[0].frame6_mm)
        .map_err(|e| PlanError::new(&plan.path, "target", e.to_string()))?;
    Ok(PoolJacobian::new(&model, set, qs))
}

/// DETMAX's `n` of the pool (indices into the pool's rows) and their O1.
pub fn choose(plan: &Plan, jac: &PoolJacobian, n: usize) -> Result<(Vec<usize>, f64), PlanError> {
    let mut rng = crate::seeds::stream(plan.seed, crate::seeds::plan::DETMAX);
    let d = detmax(jac, n, &DetmaxOptions::default(), &mut rng).map_err(|e| PlanError::new(&plan.path, "poses", e.to_string()))?;
    let o1 = o1_of(jac, &d.selection);
    Ok((d.selection, o1))
}

/// A tour through `qs`: greedy nearest neighbour in joint space (Euclidean, rad) from the
/// configuration nearest the middle of the limits. Returns the order and its length, rad.
pub fn tour(cell: &Cell, qs: &[Joints]) -> (Vec<usize>, f64) {
    let l = cell.model.limits();
    tour_from(&std::array::from_fn(|i| 0.5 * (l[i].min + l[i].max)), qs)
}

/// A tour through `qs`: greedy nearest neighbour in joint space (Euclidean, rad) from the
/// configuration nearest `mid`. Returns the order and its length, rad.
pub fn tour_from(mid: &Joints, qs: &[Joints]) -> (Vec<usize>, f64) {
    if qs.is_empty() {
        return (Vec::new(), 0.0);
    }
    let dist = |a: &Joints, b: &Joints| a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>().sqrt();
    let first = (0..qs.len()).min_by(|&a, &b| dist(&qs[a], mid).total_cmp(&dist(&qs[b], mid)).then(a.cmp(&b))).expect("not empty");
    let mut left: Vec<bool> = vec![true; qs.len()];
    left[first] = false;
    let mut order = vec![first];
    let mut length = 0.0;
    while order.len() < qs.len() {
        let at = &qs[*order.last().expect("not empty")];
        let (next, d) = (0..qs.len())
            .filter(|&k| left[k])
            .map(|k| (k, dist(at, &qs[k])))
            .min_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)))
            .expect("one left");
        left[next] = false;
        order.push(next);
        length += d;
    }
    (order, length)
}

/// Joint step of the collision check along a move, rad (largest change of any joint between checks).
pub const MOVE_STEP_RAD: f64 = 1.0 * std::f64::consts::PI / 180.0;

/// The moves of `order` (straight lines in joint space) that pass through a collision, checked
/// every [`MOVE_STEP_RAD`] of the joint that moves most: (from, to) positions in `order`.
pub fn colliding_moves(cell: &Cell, qs: &[Joints], order: &[usize]) -> Vec<(usize, usize)> {
    colliding_moves_with(qs, order, |st, q| {
        crate::robot::forward(&cell.model, st, q);
        cell.collides(st)
    })
}

/// The moves of `order` through `qs` that pass through a configuration where `collides(st, q)`
/// (`st` scratch), checked every [`MOVE_STEP_RAD`] of the joint that moves most: (from, to)
/// positions in `order`.
pub fn colliding_moves_with(
    qs: &[Joints],
    order: &[usize],
    collides: impl Fn(&mut KinState, &Joints) -> bool + Sync,
) -> Vec<(usize, usize)> {
    order
        .par_windows(2)
        .enumerate()
        .map_init(KinState::default, |st, (k, w)| {
            let (a, b) = (&qs[w[0]], &qs[w[1]]);
            let most = a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
            let steps = (most / MOVE_STEP_RAD).ceil().max(1.0) as usize;
            let hit = (1..steps).any(|s| {
                let f = s as f64 / steps as f64;
                let q: Joints = std::array::from_fn(|i| a[i] + f * (b[i] - a[i]));
                collides(st, &q)
            });
            hit.then_some((k, k + 1))
        })
        .flatten()
        .collect()
}

/// Ridge of the greedy selection's information matrix (scaled columns), so its first steps, below
/// full rank, still rank the poses.
const GREEDY_RIDGE: f64 = 1e-8;

/// A greedy D-optimal set of `n` of the pool (sequential: each step adds the configuration that
/// raises `det(ridge I + sum J_k^T J_k)` most, the smallest index among equals). Returns pool
/// indices, ascending.
pub fn greedy(jac: &PoolJacobian, n: usize) -> Vec<usize> {
    use nalgebra::{DMatrix, Matrix3};
    let m = jac.m;
    let mut info = DMatrix::<f64>::identity(m, m) * GREEDY_RIDGE;
    let mut taken = vec![false; jac.len];
    let mut chosen = Vec::with_capacity(n);
    for _ in 0..n.min(jac.len) {
        let inv = info.clone().cholesky().map_or_else(|| DMatrix::identity(m, m), |c| c.inverse());
        // det(M + J_k^T J_k) / det(M) = det(I_3 + J_k M^-1 J_k^T).
        let gain = |k: usize| -> f64 {
            let jk = jac.j.rows(3 * k, 3);
            let s = jk * &inv * jk.transpose();
            (Matrix3::identity() + Matrix3::from_fn(|r, c| s[(r, c)])).determinant()
        };
        let best = (0..jac.len)
            .into_par_iter()
            .filter(|&k| !taken[k])
            .map(|k| (k, gain(k)))
            .reduce_with(|a, b| match a.1.total_cmp(&b.1) {
                std::cmp::Ordering::Less => b,
                std::cmp::Ordering::Greater => a,
                std::cmp::Ordering::Equal => {
                    if a.0 <= b.0 {
                        a
                    } else {
                        b
                    }
                }
            })
            .expect("a configuration left");
        taken[best.0] = true;
        chosen.push(best.0);
        let jk = jac.j.rows(3 * best.0, 3);
        info += jk.transpose() * jk;
    }
    chosen.sort_unstable();
    chosen
}
