//! The designs of a sweep judged by its objective: each design's value in each world, its estimate
//! with an interval, its feasibility under the constraints, the ranking, and which designs are
//! statistically tied with the leader (paired on common worlds).
//!
//! A design is (grid point, selection, set size). Its value in one world (one realisation):
//! - success: the fraction of the world's repetitions whose statistic is within the threshold (a
//!   world whose campaign could not run counts as 0: no calibration there);
//! - an error statistic: the world's median over repetitions (a failed world counts as +inf);
//! - campaign hours: the world's modelled campaign time; set size: the design's.
//!
//! Over worlds: success by its mean with a Clopper-Pearson interval on the number of worlds, the
//! others by their median with the order-statistic interval. Two designs are compared by the
//! sign test of their paired values (common random numbers make the worlds common); a design
//! whose comparison with the leader does not separate them at the confidence is tied with it.

use serde::{Deserialize, Serialize};

use super::objective::{Goal, Objective, Statistic};
use super::{ShardInfo, Unit, UnitRow};
use crate::study::interval::{Paired, clopper_pearson, clopper_pearson_lower, clopper_pearson_upper};

/// A design: one grid point with one selection and one set size.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct Design {
    /// Grid point.
    pub point: usize,
    /// Selection label.
    pub selection: String,
    /// Set size.
    pub set_size: u32,
}

/// Whether a design meets the objective's constraints at its confidence.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Feasibility {
    /// Every constraint holds at the confidence.
    Feasible,
    /// Some constraint can neither be confirmed nor ruled out by the worlds run.
    Undecided,
    /// Some constraint fails at the confidence.
    Infeasible,
}

impl Feasibility {
    /// The word in tables.
    pub fn label(self) -> &'static str {
        match self {
            Feasibility::Feasible => "feasible",
            Feasibility::Undecided => "undecided",
            Feasibility::Infeasible => "infeasible",
        }
    }
}

/// One design judged: its objective with an interval, feasibility, rank, and its comparison with
/// the leader.
#[derive(Clone, Debug)]
pub struct DesignRow {
    /// The design.
    pub design: Design,
    /// Whether it is its point's table set size.
    pub table: bool,
    /// Worlds it was evaluated in, and of them the worlds its campaign failed in.
    pub worlds: u32,
    /// See `worlds`.
    pub failed_worlds: u32,
    /// The objective's estimate and its two-sided interval at the confidence.
    pub estimate: f64,
    /// See `estimate`.
    pub interval: (f64, f64),
    /// P(statistic <= threshold) over worlds and its interval, where the objective has a threshold.
    pub success: Option<(f64, (f64, f64))>,
    /// Median modelled campaign time over worlds, h.
    pub campaign_h: f64,
    /// Feasibility under the constraints.
    pub feasibility: Feasibility,
    /// Rank (1: the leader).
    pub rank: usize,
    /// The paired comparison `design - leader` on common worlds (`None` for the leader).
    pub vs_leader: Option<Paired>,
    /// Whether the worlds cannot separate it from the leader at the confidence.
    pub tied: bool,
    /// When an adaptive sweep stopped evaluating it: the worlds it had, and why.
    pub eliminated: Option<(u32, String)>,
}

/// The fraction of a unit row's repetitions whose `statistic` is within threshold `t` (index).
fn within(row: &UnitRow, statistic: Statistic, t: usize) -> f64 {
    let counts = match statistic {
        Statistic::Max => &row.max_within,
        Statistic::Mean => &row.mean_within,
        Statistic::P95 => &row.p95_within,
        Statistic::Median => &row.median_within,
    };
    counts.get(t).map_or(f64::NAN, |&c| f64::from(c) / f64::from(row.repetitions.max(1)))
}

/// The value of design `d` in one world (`unit`), by `goal` (see the module docs).
fn value(goal: Goal, objective: &Objective, threshold: Option<usize>, d: &Design, unit: &Unit) -> f64 {
    let row = unit.rows.iter().find(|r| r.selection == d.selection && r.set_size == d.set_size);
    match goal {
        Goal::MaximiseSuccess => match (row, threshold) {
            (Some(r), Some(t)) => within(r, objective.statistic, t),
            (None, Some(_)) if unit.error.is_some() => 0.0,
            _ => f64::NAN,
        },
        Goal::MinimiseError(s) => match row {
            Some(r) => {
                let v = match s {
                    Statistic::Median => r.after_median_mm,
                    Statistic::Mean => r.after_mean_mm,
                    Statistic::P95 => r.after_p95_mm,
                    Statistic::Max => r.after_max_mm,
                };
                if v.is_nan() && r.no_model == r.repetitions { f64::INFINITY } else { v }
            }
            None if unit.error.is_some() => f64::INFINITY,
            None => f64::NAN,
        },
        Goal::MinimiseCampaignHours => {
            if unit.error.is_some() {
                f64::INFINITY
            } else {
                unit.campaign_s / 3600.0
            }
        }
        Goal::MinimiseSetSize => f64::from(d.set_size),
    }
}

/// The median of values that may hold +inf (a failed world is the worst), NaN left out.
fn median_with_inf(v: &[f64]) -> f64 {
    let mut s: Vec<f64> = v.iter().copied().filter(|x| !x.is_nan()).collect();
    s.sort_by(f64::total_cmp);
    if s.is_empty() {
        return f64::NAN;
    }
    let h = (s.len() - 1) as f64 * 0.5;
    let (lo, hi) = (s[h.floor() as usize], s[h.ceil() as usize]);
    if lo == hi { lo } else { lo + 0.5 * (hi - lo) }
}

/// The interval of a median of values that may hold +inf (order statistics).
fn median_interval_with_inf(v: &[f64], confidence: f64) -> (f64, f64) {
    let mut s: Vec<f64> = v.iter().copied().filter(|x| !x.is_nan()).collect();
    s.sort_by(f64::total_cmp);
    match crate::study::interval::median_ranks(s.len(), confidence) {
        Some((j, k)) => (s[j - 1], s[k - 1]),
        None => (f64::NEG_INFINITY, f64::INFINITY),
    }
}

/// Every design of the sweep with its values per world (realisation order; NaN where the design
/// has no value in a world that ran), over the units given.
pub fn values(info: &ShardInfo, units: &[Unit], goal: Goal) -> Vec<(Design, bool, Vec<(u32, f64)>)> {
    let o = &info.objective;
    let threshold = o.threshold_mm.and_then(|t| info.thresholds_mm.iter().position(|x| *x == t));
    let mut designs: Vec<(Design, bool)> = Vec::new();
    for u in units {
        for r in &u.rows {
            let d = Design { point: u.point, selection: r.selection.clone(), set_size: r.set_size };
            if !designs.iter().any(|(x, _)| *x == d) {
                designs.push((d, r.table));
            }
        }
    }
    designs.sort();
    designs
        .into_iter()
        .map(|(d, table)| {
            let mut v: Vec<(u32, f64)> =
                units.iter().filter(|u| u.point == d.point).map(|u| (u.realisation, value(goal, o, threshold, &d, u))).collect();
            v.sort_by_key(|x| x.0);
            (d, table, v)
        })
        .collect()
}

/// Judges every design over the units given: estimates, intervals, feasibility, ranking, ties.
/// `eliminated` carries what an adaptive sweep decided on the way (design, worlds, reason).
pub fn judge(info: &ShardInfo, units: &[Unit], eliminated: &[(Design, u32, String)]) -> Vec<DesignRow> {
    let o = &info.objective;
    let threshold = o.threshold_mm.and_then(|t| info.thresholds_mm.iter().position(|x| *x == t));
    let objective = values(info, units, o.goal);
    let success = threshold.map(|_| values(info, units, Goal::MaximiseSuccess));
    let hours = values(info, units, Goal::MinimiseCampaignHours);
    let mut rows: Vec<DesignRow> = objective
        .iter()
        .enumerate()
        .map(|(i, (d, table, v))| {
            let x: Vec<f64> = v.iter().map(|p| p.1).collect();
            let (estimate, interval) = summary(o.goal, &x, o.confidence);
            let success = success.as_ref().map(|s| {
                let y: Vec<f64> = s[i].2.iter().map(|p| p.1).filter(|x| !x.is_nan()).collect();
                let n = y.len() as f64;
                let p = y.iter().sum::<f64>() / n;
                (p, clopper_pearson(p * n, n, o.confidence))
            });
            let h: Vec<f64> = hours[i].2.iter().map(|p| p.1).collect();
            let failed = units.iter().filter(|u| u.point == d.point && u.error.is_some()).count() as u32;
            let campaign_h = median_with_inf(&h);
            DesignRow {
                design: d.clone(),
                table: *table,
                worlds: x.iter().filter(|v| !v.is_nan()).count() as u32,
                failed_worlds: failed,
                estimate,
                interval,
                success,
                campaign_h,
                feasibility: feasibility(o, d, success.as_ref().map(|s| s.0), x.iter().filter(|v| !v.is_nan()).count(), campaign_h),
                rank: 0,
                vs_leader: None,
                tied: false,
                eliminated: eliminated.iter().find(|e| e.0 == *d).map(|e| (e.1, e.2.clone())),
            }
        })
        .collect();
    rank(&mut rows, o);
    if let Some(leader) = rows.iter().position(|r| r.rank == 1) {
        let lv: Vec<(u32, f64)> = objective[leader].2.clone();
        for (i, r) in rows.iter_mut().enumerate() {
            if i == leader {
                continue;
            }
            let (a, b) = paired_values(&objective[i].2, &lv);
            let p = Paired::of(&a, &b, o.confidence);
            // A design an adaptive sweep eliminated was separated at its stage: not tied.
            r.tied = !p.separated(o.confidence) && r.eliminated.is_none();
            r.vs_leader = Some(p);
        }
    }
    rows
}

/// The values of two designs in the worlds both were evaluated in, in world order.
pub fn paired_values(a: &[(u32, f64)], b: &[(u32, f64)]) -> (Vec<f64>, Vec<f64>) {
    let mut out = (Vec::new(), Vec::new());
    for (r, x) in a {
        if let Some((_, y)) = b.iter().find(|(s, _)| s == r) {
            out.0.push(*x);
            out.1.push(*y);
        }
    }
    out
}

/// The estimate and interval of a design's per-world values under `goal`.
fn summary(goal: Goal, x: &[f64], confidence: f64) -> (f64, (f64, f64)) {
    match goal {
        Goal::MaximiseSuccess => {
            let y: Vec<f64> = x.iter().copied().filter(|v| !v.is_nan()).collect();
            let n = y.len() as f64;
            let p = y.iter().sum::<f64>() / n;
            (p, clopper_pearson(p * n, n, confidence))
        }
        Goal::MinimiseSetSize => {
            let v = x.iter().copied().find(|v| !v.is_nan()).unwrap_or(f64::NAN);
            (v, (v, v))
        }
        _ => (median_with_inf(x), median_interval_with_inf(x, confidence)),
    }
}

/// Feasibility of design `d` (P(success) `p` over `n` worlds, median campaign hours `h`).
fn feasibility(o: &Objective, d: &Design, p: Option<f64>, n: usize, h: f64) -> Feasibility {
    let mut worst = Feasibility::Feasible;
    let mut note = |f: Feasibility| {
        if f == Feasibility::Infeasible || (f == Feasibility::Undecided && worst == Feasibility::Feasible) {
            worst = f;
        }
    };
    if let (Some(target), Some(p)) = (o.success_at_least, p) {
        let n = n as f64;
        if clopper_pearson_lower(p * n, n, o.confidence) >= target {
            note(Feasibility::Feasible);
        } else if clopper_pearson_upper(p * n, n, o.confidence) < target {
            note(Feasibility::Infeasible);
        } else {
            note(Feasibility::Undecided);
        }
    }
    if let Some(most) = o.campaign_h_at_most
        && !(h <= most)
    {
        note(Feasibility::Infeasible);
    }
    if let Some(most) = o.set_size_at_most
        && d.set_size > most
    {
        note(Feasibility::Infeasible);
    }
    worst
}

/// Whether a design fails a constraint at `confidence`: its P(success) upper bound below the
/// target, or a campaign or set size above its limit (an adaptive sweep asks at its per-look
/// level, stricter than the objective's).
pub fn infeasible_at(o: &Objective, r: &DesignRow, confidence: f64) -> bool {
    let success = match (o.success_at_least, r.success) {
        (Some(target), Some((p, _))) => {
            let n = r.worlds as f64;
            clopper_pearson_upper(p * n, n, confidence) < target
        }
        _ => false,
    };
    let hours = o.campaign_h_at_most.is_some_and(|h| !(r.campaign_h <= h));
    let size = o.set_size_at_most.is_some_and(|n| r.design.set_size > n);
    success || hours || size
}

/// Ranks the designs: feasible, then undecided, then infeasible; within each by the objective's
/// estimate (best first), then by design for a stable order.
fn rank(rows: &mut [DesignRow], o: &Objective) {
    let class = |f: Feasibility| match f {
        Feasibility::Feasible => 0,
        Feasibility::Undecided => 1,
        Feasibility::Infeasible => 2,
    };
    let sign = if o.maximises() { -1.0 } else { 1.0 };
    let mut order: Vec<usize> = (0..rows.len()).collect();
    order.sort_by(|&a, &b| {
        let (ra, rb) = (&rows[a], &rows[b]);
        class(ra.feasibility)
            .cmp(&class(rb.feasibility))
            .then((sign * ra.estimate).total_cmp(&(sign * rb.estimate)))
            .then(ra.design.cmp(&rb.design))
    });
    for (k, &i) in order.iter().enumerate() {
        rows[i].rank = k + 1;
    }
}
