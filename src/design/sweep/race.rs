//! Adaptive realisations (racing): worlds are added in batches only where the decision is still
//! open, until the leader is separated from every other design at the asked confidence or the
//! most realisations are spent.
//!
//! Stage 0 runs realisations `0..min` of every point; each later stage runs the next `batch`
//! realisations of the points that still have a design in the race. After each stage the designs
//! are judged on every world run so far ([`super::designs`]): the leader is the best design still
//! in the race; a design leaves the race when a constraint fails at level `(1 - confidence) /
//! looks` (below), or when the
//! sign test of its paired values against the leader's rejects equality at level
//! `(1 - confidence) / looks` (Bonferroni over the stages planned, so that repeated looks do not
//! inflate the error of an elimination) with the leader ahead. The race ends when the leader is
//! alone and its constraints are confirmed or ruled out, or at the most realisations. It is a
//! pure function of the
//! units run: any thread count and any sharding give the same stages, eliminations and tables.

use std::collections::{BTreeMap, BTreeSet};

use serde::{Deserialize, Serialize};

use super::designs::{self, Design};
use super::{ShardInfo, Unit};
use crate::study::interval::Paired;

/// `realisations = { max = N, confidence = c, batch = b, min = m }` of a sweep file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Race {
    /// Realisations of every point in stage 0.
    pub min: u32,
    /// Realisations added per later stage.
    pub batch: u32,
    /// Most realisations of any point.
    pub max: u32,
    /// Confidence of the eliminations.
    pub confidence: f64,
}

impl Race {
    /// The stages: realisation ranges `[lo, hi)`.
    pub fn stages(&self) -> Vec<(u32, u32)> {
        let mut out = vec![(0, self.min.min(self.max))];
        while out.last().expect("one stage").1 < self.max {
            let lo = out.last().expect("one stage").1;
            out.push((lo, (lo + self.batch).min(self.max)));
        }
        out
    }
}

/// Where a sweep stands: what it still needs, and what the race decided.
#[derive(Clone, Debug, Default)]
pub struct Plan {
    /// Every unit the sweep needs is there and, adaptive, the race is decided.
    pub complete: bool,
    /// The stage under way (0 for a sweep of fixed realisations).
    pub stage: usize,
    /// The units the current stage still needs.
    pub missing: Vec<usize>,
    /// Designs that left the race: the design, the worlds it had, why.
    pub eliminated: Vec<(Design, u32, String)>,
    /// Stages run in all.
    pub stages_run: usize,
}

/// The plan of `info`'s sweep given the units `present` (by unit index).
pub fn plan(info: &ShardInfo, present: &BTreeMap<usize, Unit>) -> Plan {
    let r = info.realisations as usize;
    let all_points: Vec<usize> = (0..info.points.len()).collect();
    let Some(race) = &info.race else {
        let missing: Vec<usize> = (0..all_points.len() * r).filter(|u| !present.contains_key(u)).collect();
        return Plan { complete: missing.is_empty(), stage: 0, missing, eliminated: Vec::new(), stages_run: 1 };
    };
    let stages = race.stages();
    let alpha = (1.0 - race.confidence) / stages.len() as f64;
    let mut alive_points = all_points;
    let mut alive: Option<BTreeSet<Design>> = None;
    let mut eliminated: Vec<(Design, u32, String)> = Vec::new();
    for (s, &(lo, hi)) in stages.iter().enumerate() {
        let needed = alive_points.iter().flat_map(|p| (lo..hi).map(move |k| p * r + k as usize));
        let missing: Vec<usize> = needed.filter(|u| !present.contains_key(u)).collect();
        if !missing.is_empty() {
            return Plan { complete: false, stage: s, missing, eliminated, stages_run: s };
        }
        let so_far: Vec<Unit> = present.values().filter(|u| u.realisation < hi).cloned().collect();
        let rows = designs::judge(info, &so_far, &[]);
        let alive_set = alive.get_or_insert_with(|| rows.iter().map(|x| x.design.clone()).collect());
        let in_race: Vec<&designs::DesignRow> = rows.iter().filter(|x| alive_set.contains(&x.design)).collect();
        let Some(leader) = in_race.iter().min_by_key(|x| x.rank).copied() else { break };
        let values = designs::values(info, &so_far, info.objective.goal);
        let of = |d: &Design| values.iter().find(|v| v.0 == *d).map(|v| v.2.clone()).unwrap_or_default();
        let leader_values = of(&leader.design);
        for x in &in_race {
            if x.design == leader.design {
                continue;
            }
            let why = if designs::infeasible_at(&info.objective, x, 1.0 - alpha) {
                Some(format!("infeasible under the constraints at {:.2e}", alpha))
            } else {
                let (a, b) = designs::paired_values(&of(&x.design), &leader_values);
                let p = Paired::of(&a, &b, race.confidence);
                let behind = if info.objective.maximises() { p.test.negative > p.test.positive } else { p.test.positive > p.test.negative };
                (p.test.p_value < alpha && behind).then(|| {
                    format!(
                        "behind the leader (point {} {} n = {}): sign test {} of {} worlds, p = {:.2e} < {:.2e}",
                        leader.design.point,
                        leader.design.selection,
                        leader.design.set_size,
                        if info.objective.maximises() { p.test.negative } else { p.test.positive },
                        p.test.positive + p.test.negative,
                        p.test.p_value,
                        alpha
                    )
                })
            };
            if let Some(why) = why {
                eliminated.push((x.design.clone(), x.worlds, why));
                alive_set.remove(&x.design);
            }
        }
        alive_points = alive_set.iter().map(|d| d.point).collect::<BTreeSet<_>>().into_iter().collect();
        // Decided: the leader alone, and its constraints confirmed or ruled out (an undecided
        // leader gets more worlds while the stages last).
        let leader_open = leader.feasibility == designs::Feasibility::Undecided;
        if alive_set.len() <= 1 && !leader_open {
            return Plan { complete: true, stage: s, missing: Vec::new(), eliminated, stages_run: s + 1 };
        }
    }
    Plan { complete: true, stage: stages.len() - 1, missing: Vec::new(), eliminated, stages_run: stages.len() }
}
