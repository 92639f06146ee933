//! Why a fit gave no model, in the terms of the data: the unknowns whose columns of the normal
//! matrix are zero or dependent (its null space), and the sessions and targets those unknowns
//! belong to, with their points in the fit, their distinct positions and their lines.

use std::fmt::Write as _;

use super::problem::{Fit, Problem};
use super::registration::RANK_RTOL;

/// A dependent unknown's least share of a null direction to be named (as `registration::prune`).
const NULL_SHARE: f64 = 0.01;
/// Lines named per session or target at most.
const MOST_LINES: usize = 8;

/// What names the problem's unknowns and points.
pub struct Labels<'a> {
    /// Session labels.
    pub sessions: &'a [String],
    /// Target labels.
    pub targets: &'a [String],
    /// Per problem point: its line in the measurement file.
    pub lines: &'a [u64],
    /// Per problem point: left out of the fits as an outlier (`--outliers reject`).
    pub outliers: &'a [bool],
}

/// Why the normal matrix of the columns `free` over the points `idx` at `x` is singular (or the
/// fit failed): the unknowns with no effect on these points, else those of its null space (else
/// of its weakest direction, with the condition number), and every session and target they
/// belong to with its points in the fit.
pub fn why<P: Fit + ?Sized>(fit: &P, x: &[f64], free: &[usize], idx: &[usize], labels: &Labels<'_>) -> String {
    let problem = fit.positions();
    let l = &problem.layout;
    let mut names = l.names(labels.sessions, labels.targets);
    names.extend(fit.own_names(labels.targets));
    let Some((_, j)) = fit.linearise(x, idx) else {
        return "the model gives no finite prediction at these values".into();
    };
    let mut j = j.select_columns(free);
    let norms: Vec<f64> = j.column_iter().map(|c| c.norm()).collect();
    let zero: Vec<usize> = (0..free.len()).filter(|&k| !(norms[k] > 0.0 && norms[k].is_finite())).collect();
    let mut out = String::new();
    let involved: Vec<usize> = if !zero.is_empty() {
        let _ = write!(
            out,
            "no effect on the points of the fit: {}",
            zero.iter().map(|&k| names[free[k]].as_str()).collect::<Vec<_>>().join(", ")
        );
        zero.iter().map(|&k| free[k]).collect()
    } else {
        for (k, mut c) in j.column_iter_mut().enumerate() {
            c.unscale_mut(norms[k]);
        }
        let Some(svd) = crate::numeric::svd(j, false, true) else {
            return "the SVD of the fit's Jacobian did not converge".into();
        };
        let Some(v_t) = svd.v_t else { return "the SVD of the fit's Jacobian did not converge".into() };
        let s = &svd.singular_values;
        let smax = s.iter().fold(0.0_f64, |m, &v| m.max(v));
        let (weakest, smin) = (0..s.len()).map(|k| (k, s[k])).min_by(|a, b| a.1.total_cmp(&b.1)).unwrap_or((0, 0.0));
        let null: Vec<usize> = (0..s.len()).filter(|&k| !(smax > 0.0 && s[k] >= RANK_RTOL * smax)).collect();
        let (rows, what): (Vec<usize>, String) = if null.is_empty() {
            (vec![weakest], format!("nearly dependent (condition number {:.1e} of the column-scaled Jacobian)", smax / smin))
        } else {
            (null, "dependent (the null space of the column-scaled normal matrix)".into())
        };
        let mut shares: Vec<(usize, f64)> = (0..free.len())
            .map(|c| (c, rows.iter().map(|&r| v_t[(r, c)].powi(2)).sum::<f64>()))
            .filter(|(_, v)| *v >= NULL_SHARE)
            .collect();
        shares.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
        let _ = write!(
            out,
            "{what}: {}",
            shares.iter().map(|(c, v)| format!("{} ({:.0} %)", names[free[*c]], 100.0 * v)).collect::<Vec<_>>().join(", ")
        );
        shares.iter().map(|(c, _)| free[*c]).collect()
    };
    for s in 0..l.sessions {
        if involved.iter().any(|&c| (l.base(s)..l.base(s) + 6).contains(&c)) {
            let _ = write!(out, "; session {}: {}", labels.sessions[s], points(problem, idx, labels, |i| problem.obs[i].session == s));
        }
    }
    for t in 0..l.targets {
        if involved.iter().any(|&c| (l.tool(t)..l.tool(t) + 3).contains(&c)) {
            let _ = write!(out, "; target {}: {}", labels.targets[t], points(problem, idx, labels, |i| problem.obs[i].target == t));
        }
    }
    out
}

/// The points of a session or target (`of`): how many the fit has, at how many distinct
/// positions, how many are left out as outliers, and their lines.
fn points(problem: &Problem<'_>, idx: &[usize], labels: &Labels<'_>, of: impl Fn(usize) -> bool) -> String {
    let all: Vec<usize> = (0..problem.obs.len()).filter(|&i| of(i)).collect();
    let used: Vec<usize> = idx.iter().copied().filter(|&i| of(i)).collect();
    let mut positions: Vec<[i64; 3]> =
        used.iter().map(|&i| std::array::from_fn(|a| (problem.obs[i].measured_mm[a] * 1e3).round() as i64)).collect();
    positions.sort_unstable();
    positions.dedup();
    let rejected: Vec<usize> = all.iter().copied().filter(|&i| labels.outliers[i]).collect();
    let lines = |v: &[usize]| {
        let mut l: Vec<String> = v.iter().take(MOST_LINES).map(|&i| labels.lines[i].to_string()).collect();
        if v.len() > MOST_LINES {
            l.push(format!("{} more", v.len() - MOST_LINES));
        }
        l.join(", ")
    };
    let mut s = format!("{} of its {} points in the fit, at {} distinct positions", used.len(), all.len(), positions.len());
    if !used.is_empty() {
        let _ = write!(s, " (lines {})", lines(&used));
    }
    if !rejected.is_empty() {
        let _ = write!(s, ", {} left out as outliers (--outliers reject; lines {})", rejected.len(), lines(&rejected));
    }
    s
}
