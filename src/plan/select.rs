//! The pool of feasible configurations, the validation poses spread over the workspace of
//! interest, DETMAX's choice of the training poses, and the tour between them.

use std::fmt::Write as _;

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
        .map_init(KinState::default, |st, (k, w)| move_collides(&qs[w[0]], &qs[w[1]], st, &collides).then_some((k, k + 1)))
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

/// A move of the tour re-routed through via configurations (stops on the way, not measured).
#[derive(Clone, Debug, PartialEq)]
pub struct Via {
    /// The move: (from, to) positions in the tour.
    pub between: (usize, usize),
    /// The via configurations in the order they are passed, rad.
    pub qs: Vec<Joints>,
}

/// The tour's colliding moves re-routed, and those no via path was found for.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Routing {
    /// The re-routed moves, in the order of the tour.
    pub vias: Vec<Via>,
    /// Colliding moves without a via path found: (from, to) positions in the tour.
    pub unrouted: Vec<(usize, usize)>,
    /// Length of the tour with its via paths in joint space (Euclidean, rad).
    pub length_rad: f64,
}

/// Joint offsets of the via search's lifted and retracted configurations about the move's
/// middle, deg: every combination of joints 2, 3 and 5 (joint 1, 4 and 6 kept on the straight
/// line).
pub const VIA_OFFSETS_DEG: [f64; 5] = [-40.0, -20.0, 0.0, 20.0, 40.0];

/// Candidates of the search with two vias: the nearest this many one-leg-free candidates of each
/// end.
const TWO_VIA_NEAREST: usize = 40;

/// Joint-space distance (Euclidean, rad).
fn dist(a: &Joints, b: &Joints) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>().sqrt()
}

/// Whether the straight move `a` -> `b` passes through a configuration where `collides`, checked
/// every [`MOVE_STEP_RAD`] of the joint that moves most (the ends not checked).
pub fn move_collides(a: &Joints, b: &Joints, st: &mut KinState, collides: &impl Fn(&mut KinState, &Joints) -> bool) -> bool {
    let most = a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
    let steps = (most / MOVE_STEP_RAD).ceil().max(1.0) as usize;
    (1..steps).any(|s| {
        let f = s as f64 / steps as f64;
        let q: Joints = std::array::from_fn(|i| a[i] + f * (b[i] - a[i]));
        collides(st, &q)
    })
}

/// Re-routes each colliding move of `order` through `qs` (`colliding`, as
/// [`colliding_moves_with`] gives them) by a deterministic search: the candidates are `extra`
/// (configurations free of collision, such as the pool's) and the move's middle with joints 2, 3
/// and 5 offset by every combination of [`VIA_OFFSETS_DEG`] (clamped to `limits`); the path with
/// one via of the smallest detour (|a - v| + |v - b|, then the candidate's index) whose via is free
/// and whose two moves are free at the same step is taken, else two vias among the nearest
/// candidates of each end. A move no such path clears is named in `unrouted`.
pub fn reroute(
    qs: &[Joints],
    order: &[usize],
    colliding: &[(usize, usize)],
    extra: &[Joints],
    limits: &[crate::robot::JointLimit; crate::robot::JOINTS],
    collides: impl Fn(&mut KinState, &Joints) -> bool + Sync,
) -> Routing {
    let mut out = Routing::default();
    let straight: f64 = order.windows(2).map(|w| dist(&qs[w[0]], &qs[w[1]])).sum();
    out.length_rad = straight;
    for &(from, to) in colliding {
        let (a, b) = (qs[order[from]], qs[order[to]]);
        match via_path(&a, &b, extra, limits, &collides) {
            Some(path) => {
                let mut prev = a;
                let mut len = 0.0;
                for v in path.iter().chain(std::iter::once(&b)) {
                    len += dist(&prev, v);
                    prev = *v;
                }
                out.length_rad += len - dist(&a, &b);
                out.vias.push(Via { between: (from, to), qs: path });
            }
            None => out.unrouted.push((from, to)),
        }
    }
    out
}

/// The via path of one move (see [`reroute`]).
fn via_path(
    a: &Joints,
    b: &Joints,
    extra: &[Joints],
    limits: &[crate::robot::JointLimit; crate::robot::JOINTS],
    collides: &(impl Fn(&mut KinState, &Joints) -> bool + Sync),
) -> Option<Vec<Joints>> {
    let mid: Joints = std::array::from_fn(|i| 0.5 * (a[i] + b[i]));
    let mut candidates: Vec<Joints> = extra.to_vec();
    for d2 in VIA_OFFSETS_DEG {
        for d3 in VIA_OFFSETS_DEG {
            for d5 in VIA_OFFSETS_DEG {
                let mut v = mid;
                for (j, d) in [(1, d2), (2, d3), (4, d5)] {
                    v[j] = (v[j] + d.to_radians()).clamp(limits[j].min, limits[j].max);
                }
                candidates.push(v);
            }
        }
    }
    let mut ranked: Vec<(f64, usize)> = candidates.iter().enumerate().map(|(k, v)| (dist(a, v) + dist(v, b), k)).collect();
    ranked.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
    // The first candidate by rank that is free, with free moves from `a` and to `b`.
    let one = ranked
        .par_iter()
        .map_init(KinState::default, |st, &(_, k)| {
            let v = &candidates[k];
            !collides(st, v) && !move_collides(a, v, st, collides) && !move_collides(v, b, st, collides)
        })
        .position_first(|ok| ok);
    if let Some(r) = one {
        return Some(vec![candidates[ranked[r].1]]);
    }
    // Each candidate: free, the move from `a` free, the move to `b` free.
    let legs: Vec<(bool, bool, bool)> = ranked
        .par_iter()
        .map_init(KinState::default, |st, &(_, k)| {
            let v = &candidates[k];
            if collides(st, v) {
                return (false, false, false);
            }
            (true, !move_collides(a, v, st, collides), !move_collides(v, b, st, collides))
        })
        .collect();
    // Two vias: v1 reached from `a`, v2 reaching `b`, the move v1 -> v2 free; the pairs by their
    // path length, then by their ranks.
    let nearest = |leg: fn(&(bool, bool, bool)) -> bool, end: &Joints| -> Vec<usize> {
        let mut v: Vec<usize> = (0..ranked.len()).filter(|&r| legs[r].0 && leg(&legs[r])).collect();
        v.sort_by(|&x, &y| dist(end, &candidates[ranked[x].1]).total_cmp(&dist(end, &candidates[ranked[y].1])).then(x.cmp(&y)));
        v.truncate(TWO_VIA_NEAREST);
        v
    };
    let firsts = nearest(|l| l.1, a);
    let seconds = nearest(|l| l.2, b);
    let mut pairs: Vec<(f64, usize, usize)> = firsts
        .iter()
        .flat_map(|&x| seconds.iter().map(move |&y| (x, y)))
        .filter(|(x, y)| x != y)
        .map(|(x, y)| {
            let (v1, v2) = (&candidates[ranked[x].1], &candidates[ranked[y].1]);
            (dist(a, v1) + dist(v1, v2) + dist(v2, b), x, y)
        })
        .collect();
    pairs.sort_by(|p, q| p.0.total_cmp(&q.0).then(p.1.cmp(&q.1)).then(p.2.cmp(&q.2)));
    pairs
        .par_iter()
        .map_init(KinState::default, |st, &(_, x, y)| {
            let (v1, v2) = (&candidates[ranked[x].1], &candidates[ranked[y].1]);
            (!move_collides(v1, v2, st, collides)).then(|| vec![*v1, *v2])
        })
        .find_first(|p| p.is_some())
        .flatten()
}

/// A stop of the tour with its via paths.
#[derive(Clone, Debug, PartialEq)]
pub enum Stop {
    /// A planned pose: its position in the plan's rows.
    Pose(usize),
    /// A via configuration (not measured): its label (`via01`, in the order of the tour) and joints, rad.
    Via(String, Joints),
}

/// The stops of the tour `order` (positions in the rows) with the via paths of `routing`.
pub fn stops(order: &[usize], routing: &Routing) -> Vec<Stop> {
    let mut out = Vec::with_capacity(order.len());
    let mut n = 0;
    for (k, &i) in order.iter().enumerate() {
        if let Some(v) = routing.vias.iter().find(|v| v.between.1 == k) {
            for q in &v.qs {
                n += 1;
                out.push(Stop::Via(format!("via{n:02}"), *q));
            }
        }
        out.push(Stop::Pose(i));
    }
    out
}

/// Split column of a via configuration in `tour.csv`.
pub const VIA: &str = "via";

/// A straight move of the tour through a collision, as `tour_moves.parquet` holds it.
#[derive(Clone, Debug, PartialEq)]
pub struct TourMove {
    /// The pose it leaves.
    pub from: String,
    /// The pose it reaches.
    pub to: String,
    /// Via configurations of its re-routed path (0: no via path found).
    pub vias: usize,
    /// A via path was found.
    pub routed: bool,
}

/// The tour's colliding moves in its order (`label` names the pose at a position in the tour).
pub fn tour_moves(colliding: &[(usize, usize)], routing: &Routing, label: impl Fn(usize) -> String) -> Vec<TourMove> {
    colliding
        .iter()
        .map(|&(a, b)| {
            let via = routing.vias.iter().find(|v| v.between == (a, b));
            TourMove { from: label(a), to: label(b), vias: via.map_or(0, |v| v.qs.len()), routed: via.is_some() }
        })
        .collect()
}

/// The tour's sentence in `plan.md`: its length, deg of joint-space path, the straight moves
/// through a collision, the via paths (`path_deg`: the length with them) and what could not be
/// re-routed.
pub fn tour_words(straight_deg: f64, path_deg: f64, moves: &[TourMove]) -> String {
    let named = |routed: Option<bool>| {
        moves.iter().filter(|m| routed.is_none_or(|r| m.routed == r)).map(|m| format!("{} -> {}", m.from, m.to)).collect::<Vec<_>>()
    };
    let mut s = format!(
        "- Tour (`tour.csv`): greedy nearest neighbour in joint space, {straight_deg:.1} deg of joint-space path; straight moves through a collision (checked every {:.0} deg of the joint that moves most): ",
        MOVE_STEP_RAD.to_degrees()
    );
    if moves.is_empty() {
        s.push_str("none.");
        return s;
    }
    s.push_str(&named(None).join(", "));
    let vias: usize = moves.iter().map(|m| m.vias).sum();
    if moves.iter().any(|m| m.routed) {
        let _ = write!(
            s,
            ". Re-routed through {vias} via configuration{} (rows `{VIA}` in `tour.csv`, not measured: each move of the path free of collision at the same step), {path_deg:.1} deg of path in all",
            if vias == 1 { "" } else { "s" },
        );
    }
    let unrouted = named(Some(false));
    if unrouted.is_empty() {
        s.push('.');
    } else {
        let _ = write!(s, "; no via path found for {}: move around it by hand.", unrouted.join(", "));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::{JOINTS, JointLimit};

    const LIMITS: [JointLimit; JOINTS] = [JointLimit { min: -3.0, max: 3.0 }; JOINTS];

    /// A wall in joint space: joint 1 between 0.4 and 0.6 rad with joint 2 below 0.5 rad (or at
    /// any joint 2 with `solid`).
    fn wall(solid: bool) -> impl Fn(&mut KinState, &Joints) -> bool + Sync {
        move |_, q| q[0] > 0.4 && q[0] < 0.6 && (solid || q[1] < 0.5)
    }

    /// Every configuration of the straight move a -> b at the stated step, computed here.
    fn steps(a: &Joints, b: &Joints) -> Vec<Joints> {
        let most = (0..JOINTS).map(|i| (a[i] - b[i]).abs()).fold(0.0, f64::max);
        let n = (most / MOVE_STEP_RAD).ceil() as usize;
        (0..=n).map(|s| std::array::from_fn(|i| a[i] + (b[i] - a[i]) * s as f64 / n as f64)).collect()
    }

    #[test]
    fn a_colliding_move_is_re_routed_through_a_via_whose_every_step_is_free() {
        let qs = [[0.0; JOINTS], [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]];
        let order = [0, 1];
        let c = colliding_moves_with(&qs, &order, wall(false));
        assert_eq!(c, [(0, 1)]);
        let r = reroute(&qs, &order, &c, &[], &LIMITS, wall(false));
        assert!(r.unrouted.is_empty());
        assert_eq!(r.vias.len(), 1);
        let path: Vec<Joints> = std::iter::once(qs[0]).chain(r.vias[0].qs.iter().copied()).chain(std::iter::once(qs[1])).collect();
        let mut st = KinState::default();
        for w in path.windows(2) {
            for q in steps(&w[0], &w[1]) {
                assert!(!wall(false)(&mut st, &q), "{q:?} in the wall");
            }
        }
        let length: f64 = path.windows(2).map(|w| dist(&w[0], &w[1])).sum();
        assert!((r.length_rad - length).abs() < 1e-12 && length > 1.0);
        let stops = stops(&order, &r);
        assert_eq!(stops.len(), 2 + r.vias[0].qs.len());
        assert!(matches!(&stops[1], Stop::Via(l, _) if l == "via01"));
    }

    #[test]
    fn a_move_no_via_clears_is_named() {
        let qs = [[0.0; JOINTS], [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]];
        let c = colliding_moves_with(&qs, &[0, 1], wall(true));
        let r = reroute(&qs, &[0, 1], &c, &[], &LIMITS, wall(true));
        assert_eq!((r.vias.len(), r.unrouted.clone()), (0, vec![(0, 1)]));
        let moves = tour_moves(&c, &r, |k| format!("p{k}"));
        assert_eq!(moves, [TourMove { from: "p0".into(), to: "p1".into(), vias: 0, routed: false }]);
        assert!(tour_words(1.0, 1.0, &moves).contains("no via path found for p0 -> p1"));
    }
}
