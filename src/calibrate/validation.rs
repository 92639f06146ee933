//! Honest accuracy: which poses are held out, k-fold cross-validation on the rest, the errors at
//! held-out points beside their first-order prediction, and the choice of model by held-out error.
//!
//! Held-out points are predicted by a model fitted without them. A held-out session has no base
//! from the training fit: its base is registered on its own points (6 numbers, with the outlier
//! rule), and its errors are what remains after that registration; the prediction then projects
//! the predicted errors the same way.

use nalgebra::{DMatrix, DVector};
use rand::seq::SliceRandom;
use rand_distr::{Distribution, StandardNormal};

use super::measurements::Measurements;
use super::problem::{Fit, Layout, SolveOptions, mul_vectors};
use super::robust::{RobustFit, covariance, fit_without};
use crate::study::stats::{ErrorStats, finite_sorted, quantile};

/// Which points are held out of the fit whose errors the report gives.
#[derive(Clone, Debug, PartialEq)]
pub enum Split {
    /// The file's `split` column when it has one, else 20 % of each session's poses drawn at random.
    Default,
    /// A fraction of every session's poses, drawn at random (`--seed`).
    Poses {
        /// Fraction of the poses held out, (0, 0.5].
        fraction: f64,
    },
    /// Every pose of one session (its base registered on its own points).
    Session(String),
    /// The poses the file's `split` column marks `holdout`.
    Column,
    /// The poses listed, as (session, pose) labels (`--hold-out-file`).
    Listed {
        /// Where the list comes from (named in the report).
        source: String,
        /// The poses, as (session, pose).
        poses: Vec<(String, String)>,
    },
}

impl Split {
    /// The split in words, for the report.
    pub fn describe(&self) -> String {
        match self {
            Split::Default => "the file's split column, else 20 % of each session's poses drawn at random".into(),
            Split::Poses { fraction } => format!("{:.0} % of each session's poses, drawn at random", fraction * 100.0),
            Split::Session(s) => format!("every pose of session {s} (its base registered on its own points)"),
            Split::Column => "the poses the file's split column marks holdout (a session held out whole has its base registered on \
                              its own points; any other session's base is the training fit's)"
                .into(),
            Split::Listed { source, poses } => format!(
                "the {} poses listed in {source} (a session held out whole has its base registered on its own points; any other \
                 session's base is the training fit's)",
                poses.len()
            ),
        }
    }

    /// The option that asks for this split (for messages).
    pub fn option(&self) -> &'static str {
        match self {
            Split::Default | Split::Column => "split",
            Split::Poses { .. } => "hold-out",
            Split::Session(_) => "hold-out-session",
            Split::Listed { .. } => "hold-out-file",
        }
    }
}

/// Why a split cannot be made.
#[derive(Clone, Debug, PartialEq)]
pub enum SplitError {
    /// No session of that label.
    UnknownSession(String),
    /// One session only: none can be held out.
    OneSession,
    /// A target measured in the held-out poses only: its position is unknown to the training fit.
    TargetOnlyThere(String),
    /// The file gives its split (a `split` column) and an option asks for another.
    ColumnAndOption,
    /// `Split::Column` on a file without a `split` column.
    NoColumn,
    /// A listed pose (session, pose) is not in the file.
    UnknownPose(String, String),
    /// The split holds no pose out.
    NoneHeldOut,
    /// The split holds out every pose.
    AllHeldOut,
    /// A session keeps some poses for training, but too few to fix its base: (session, poses kept).
    TooFewKept(String, usize),
}

impl SplitError {
    /// The error in words (`source`: the measurement file).
    pub fn message(&self, source: &std::path::Path) -> String {
        let file = source.display();
        match self {
            SplitError::UnknownSession(l) => format!("{l}: no such session in {file}"),
            SplitError::OneSession => format!("{file} has one session: none can be held out"),
            SplitError::TargetOnlyThere(t) => format!("target {t} is measured in held-out poses only: the training fit cannot place it"),
            SplitError::ColumnAndOption => {
                format!("{file} gives its split in the column `split`: drop the option or the column")
            }
            SplitError::NoColumn => format!("{file} has no `split` column"),
            SplitError::UnknownPose(s, p) => format!("pose {p} of session {s} is not in {file}"),
            SplitError::NoneHeldOut => "no pose is held out".into(),
            SplitError::AllHeldOut => "every pose is held out: nothing is left to fit".into(),
            SplitError::TooFewKept(s, n) => format!(
                "session {s} keeps {n} training poses: hold out all of its poses (its base is then registered on them) or keep at least \
                 {KEEP_POSES} to fit its base"
            ),
        }
    }
}

/// How the k-fold cross-validation over every pose groups the poses into folds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KFoldBy {
    /// The poses of each session shuffled and dealt into the folds (every session in every fold's
    /// training part).
    Pose,
    /// A fold per session (leave one session out: its base registered on its own points).
    Session,
}

impl KFoldBy {
    /// The option's value.
    pub fn name(self) -> &'static str {
        match self {
            KFoldBy::Pose => "pose",
            KFoldBy::Session => "session",
        }
    }

    /// The grouping named `s` (`pose`, `session`).
    pub fn parse(s: &str) -> Option<Self> {
        [KFoldBy::Pose, KFoldBy::Session].into_iter().find(|m| m.name() == s)
    }
}

/// The split and folds of the poses.
#[derive(Clone, Debug, PartialEq)]
pub struct Assignment {
    /// Per pose: held out.
    pub held_out: Vec<bool>,
    /// Per pose: its cross-validation fold (`None` for held-out poses).
    pub fold: Vec<Option<usize>>,
    /// Folds.
    pub folds: usize,
    /// Per pose: its fold in the k-fold cross-validation over every pose ([`assign_every_pose`]).
    pub fold_all: Vec<usize>,
    /// Folds of the k-fold cross-validation over every pose.
    pub folds_all: usize,
}

/// Fewest training poses a session keeps when a fraction of its poses is held out.
const KEEP_POSES: usize = 4;

/// The split `split` resolved for the file `m`: [`Split::Default`] becomes the file's column when it
/// has one, else 20 % of each session's poses; an option beside a file's column is an error.
pub fn resolve(m: &Measurements, split: &Split) -> Result<Split, SplitError> {
    match split {
        Split::Default if m.split_column => Ok(Split::Column),
        Split::Default => Ok(Split::Poses { fraction: 0.2 }),
        Split::Column if !m.split_column => Err(SplitError::NoColumn),
        Split::Column => Ok(Split::Column),
        _ if m.split_column => Err(SplitError::ColumnAndOption),
        other => Ok(other.clone()),
    }
}

/// Assigns the poses of `m` to the held-out set and to `folds` folds, with the stream `seed`
/// (poses are shuffled within each session; folds are balanced across sessions). `split` is
/// resolved first ([`resolve`]).
pub fn assign(m: &Measurements, split: &Split, folds: usize, seed: u64) -> Result<Assignment, SplitError> {
    let split = resolve(m, split)?;
    let mut rng = crate::seeds::stream(seed, crate::seeds::calibrate::SPLIT);
    let mut held_out = vec![false; m.poses.len()];
    match &split {
        Split::Default => unreachable!("resolved above"),
        Split::Poses { fraction } => {
            for s in 0..m.sessions.len() {
                let mut poses: Vec<usize> = (0..m.poses.len()).filter(|&p| m.poses[p].session == s).collect();
                poses.shuffle(&mut rng);
                let n = ((poses.len() as f64 * fraction).round() as usize).clamp(1, poses.len().saturating_sub(KEEP_POSES).max(1));
                for &p in &poses[..n] {
                    held_out[p] = true;
                }
            }
        }
        Split::Session(label) => {
            let s = m.sessions.iter().position(|x| x == label).ok_or_else(|| SplitError::UnknownSession(label.clone()))?;
            if m.sessions.len() < 2 {
                return Err(SplitError::OneSession);
            }
            for (p, pose) in m.poses.iter().enumerate() {
                held_out[p] = pose.session == s;
            }
        }
        Split::Column => {
            for (p, pose) in m.poses.iter().enumerate() {
                held_out[p] = pose.held_out == Some(true);
            }
        }
        Split::Listed { poses, .. } => {
            for (session, label) in poses {
                let p = m
                    .poses
                    .iter()
                    .position(|x| &x.label == label && &m.sessions[x.session] == session)
                    .ok_or_else(|| SplitError::UnknownPose(session.clone(), label.clone()))?;
                held_out[p] = true;
            }
        }
    }
    if !matches!(split, Split::Poses { .. }) {
        if !held_out.iter().any(|h| *h) {
            return Err(SplitError::NoneHeldOut);
        }
        if held_out.iter().all(|h| *h) {
            return Err(SplitError::AllHeldOut);
        }
        for (s, label) in m.sessions.iter().enumerate() {
            let kept = (0..m.poses.len()).filter(|&p| m.poses[p].session == s && !held_out[p]).count();
            let all = (0..m.poses.len()).filter(|&p| m.poses[p].session == s).count();
            if kept > 0 && kept < all && kept < KEEP_POSES {
                return Err(SplitError::TooFewKept(label.clone(), kept));
            }
        }
        for (t, target) in m.targets.iter().enumerate() {
            // A target measured only in sessions held out whole is registered with their bases.
            let whole = |s: usize| m.poses.iter().enumerate().filter(|(_, p)| p.session == s).all(|(p, _)| held_out[p]);
            let points = || m.points.iter().filter(|pt| pt.target == t);
            if !points().any(|pt| !held_out[pt.pose]) && !points().all(|pt| whole(m.poses[pt.pose].session)) {
                return Err(SplitError::TargetOnlyThere(target.clone()));
            }
        }
    }
    let mut fold = vec![None; m.poses.len()];
    let mut offset = 0;
    for s in 0..m.sessions.len() {
        let mut poses: Vec<usize> = (0..m.poses.len()).filter(|&p| m.poses[p].session == s && !held_out[p]).collect();
        poses.shuffle(&mut rng);
        for (k, &p) in poses.iter().enumerate() {
            fold[p] = Some((offset + k) % folds);
        }
        offset += poses.len();
    }
    Ok(Assignment { held_out, fold, folds, fold_all: Vec::new(), folds_all: 0 })
}

/// The folds of the k-fold cross-validation over every pose of `m`, held-out ones included: by
/// pose, each session's poses shuffled (its own stream of `seed`, so that the split and the folds
/// of [`assign`] do not move) and dealt into `folds` folds, balanced across sessions; by session,
/// a fold per session. Returns the fold of every pose and the number of folds.
pub fn assign_every_pose(m: &Measurements, by: KFoldBy, folds: usize, seed: u64) -> Result<(Vec<usize>, usize), String> {
    match by {
        KFoldBy::Session => {
            if m.sessions.len() < 2 {
                return Err(format!("session: {} has one session: none can be left out", m.path.display()));
            }
            for (t, target) in m.targets.iter().enumerate() {
                let mut sessions = m.points.iter().filter(|p| p.target == t).map(|p| m.poses[p.pose].session);
                let first = sessions.next().unwrap_or(0);
                if sessions.all(|s| s == first) {
                    return Err(format!(
                        "session: target {target} is measured in session {} only: a fit without that session cannot place it",
                        m.sessions[first]
                    ));
                }
            }
            Ok((m.poses.iter().map(|p| p.session).collect(), m.sessions.len()))
        }
        KFoldBy::Pose => {
            let mut rng = crate::seeds::stream(seed, crate::seeds::calibrate::FOLDS_EVERY_POSE);
            let mut fold = vec![0; m.poses.len()];
            let mut offset = 0;
            for s in 0..m.sessions.len() {
                let mut poses: Vec<usize> = (0..m.poses.len()).filter(|&p| m.poses[p].session == s).collect();
                poses.shuffle(&mut rng);
                for (k, &p) in poses.iter().enumerate() {
                    fold[p] = (offset + k) % folds;
                }
                offset += poses.len();
            }
            Ok((fold, folds))
        }
    }
}

/// The columns free in a fit over the points `idx`: the robot's (unless `robot` is false), and the
/// base and tool blocks of the sessions and targets those points have.
pub fn free_columns<P: Fit + ?Sized>(fit: &P, idx: &[usize], robot: bool) -> Vec<usize> {
    let problem = fit.positions();
    let l = &problem.layout;
    let mut free: Vec<usize> = if robot { (0..l.robot.len()).collect() } else { Vec::new() };
    for s in 0..l.sessions {
        if idx.iter().any(|&i| problem.obs[i].session == s) {
            free.extend(l.base_columns(s));
        }
    }
    for t in 0..l.targets {
        if idx.iter().any(|&i| problem.obs[i].target == t) {
            free.extend(l.tool(t)..l.tool(t) + 3);
        }
    }
    free.extend(fit.own_columns(idx));
    free
}

/// Errors at held-out points: measured, and predicted to first order.
#[derive(Clone, Debug, PartialEq)]
pub struct HeldOut {
    /// Per held-out point: its error, mm (NaN when the model gave none).
    pub errors_mm: Vec<f64>,
    /// Per held-out point: left out of the statistics (a flagged point under `--outliers reject`).
    pub outlier: Vec<bool>,
    /// Statistics of the errors of the points not left out, mm.
    pub measured: ErrorStats,
    /// Held-out points flagged by the outlier rule (whatever `--outliers` does with them).
    pub flagged: usize,
    /// Statistics of every held-out point's error, flagged ones included, mm.
    pub with_flagged: ErrorStats,
    /// Statistics of the held-out points not flagged, mm.
    pub without_flagged: ErrorStats,
    /// The same statistics predicted from the training fit's covariance and noise estimate
    /// (parameter errors drawn from `N(0, C)` plus the points' own noise); `max` is the median
    /// over the draws of the largest error.
    pub predicted: ErrorStats,
    /// Points in the statistics.
    pub points: usize,
    /// Per held-out point: its rotation error, mdeg (NaN for a point without an orientation
    /// reading or when the model gave none; empty when the file has no orientation columns).
    pub rotation_errors_mdeg: Vec<f64>,
    /// Statistics of the rotation errors of the held-out points with a reading not left out,
    /// mdeg (`None`: the file has no orientation columns).
    pub rotation: Option<ErrorStats>,
    /// Held-out readings flagged by the outlier rule (whatever `--outliers` does with them).
    pub readings_flagged: usize,
    /// Statistics of the rotation errors of [`Self::rotation`]'s readings less the flagged ones, mdeg.
    pub rotation_without_flagged: Option<ErrorStats>,
}

/// What [`held_out`] needs besides the training fit.
pub struct HeldOutSpec<'a> {
    /// The held-out points.
    pub test: &'a [usize],
    /// Sessions whose bases are registered on the held-out points (a held-out session).
    pub register: &'a [usize],
    /// Targets whose tools are registered on the held-out points with those bases (a target
    /// measured in held-out sessions only: `--tool-per-session`).
    pub register_tools: &'a [usize],
    /// Per problem point: left out of every fit and statistic.
    pub outliers: &'a [bool],
    /// Per problem point: flagged by the outlier rule.
    pub flagged: &'a [bool],
    /// Per problem point: its orientation reading flagged by the outlier rule.
    pub readings_flagged: &'a [bool],
    /// Parameter-error draws of the prediction.
    pub draws: usize,
    /// The stream key of the draws (under the calibration's seed).
    pub key: u64,
    /// The calibration's seed.
    pub seed: u64,
}

/// The held-out errors of the model of `train` (fitted with the columns `free`).
pub fn held_out<P: Fit + ?Sized>(fit: &P, train: &RobustFit, free: &[usize], spec: &HeldOutSpec<'_>, opts: &SolveOptions) -> HeldOut {
    let problem = fit.positions();
    let l = &problem.layout;
    let mut x = train.solved.x.clone();
    let mut reg_cols: Vec<usize> = spec.register.iter().flat_map(|&s| l.base_columns(s)).collect();
    reg_cols.extend(spec.register_tools.iter().flat_map(|&t| l.tool(t)..l.tool(t) + 3));
    if !reg_cols.is_empty() {
        let mask: Vec<bool> = spec.test.iter().map(|&i| spec.outliers[i]).collect();
        x = fit_without(fit, &x, &reg_cols, spec.test, &mask, opts).solved.x;
    }
    let errors_mm: Vec<f64> =
        problem.errors(&x, spec.test).map_or_else(|| vec![f64::NAN; spec.test.len()], |e| e.iter().map(|v| v.norm()).collect());
    let outlier: Vec<bool> = spec.test.iter().map(|&i| spec.outliers[i]).collect();
    let kept: Vec<usize> = (0..spec.test.len()).filter(|&k| !outlier[k]).collect();
    let measured = ErrorStats::of(&kept.iter().map(|&k| errors_mm[k]).collect::<Vec<_>>());
    let predicted = predict(fit, train, free, &x, spec, &reg_cols, &kept).unwrap_or(ErrorStats {
        mean: f64::NAN,
        median: f64::NAN,
        std: f64::NAN,
        p95: f64::NAN,
        max: f64::NAN,
        rms: f64::NAN,
    });
    let of =
        |keep: &dyn Fn(usize) -> bool| ErrorStats::of(&(0..spec.test.len()).filter(|&k| keep(k)).map(|k| errors_mm[k]).collect::<Vec<_>>());
    let with_flagged = of(&|_| true);
    let without_flagged = of(&|k| !spec.flagged[spec.test[k]]);
    let flagged = spec.test.iter().filter(|&&i| spec.flagged[i]).count();
    let rotation_errors_mdeg: Vec<f64> = fit
        .rotation_errors(&x, spec.test)
        .map(|r| r.iter().map(|e| e.map_or(f64::NAN, |e| e.norm().to_degrees() * 1e3)).collect())
        .unwrap_or_default();
    let rotation_of = |keep: &dyn Fn(usize) -> bool| {
        (!rotation_errors_mdeg.is_empty()).then(|| {
            ErrorStats::of(
                &kept.iter().filter(|&&k| keep(k)).map(|&k| rotation_errors_mdeg[k]).filter(|v| v.is_finite()).collect::<Vec<_>>(),
            )
        })
    };
    let rotation = rotation_of(&|_| true);
    let rotation_without_flagged = rotation_of(&|k| !spec.readings_flagged[spec.test[k]]);
    let readings_flagged = spec.test.iter().filter(|&&i| spec.readings_flagged[i]).count();
    HeldOut {
        errors_mm,
        outlier,
        measured,
        predicted,
        points: kept.len(),
        flagged,
        with_flagged,
        without_flagged,
        rotation_errors_mdeg,
        rotation,
        readings_flagged,
        rotation_without_flagged,
    }
}

/// Draws of a prediction whose random numbers are taken before their errors are computed side by
/// side.
const PREDICTION_CHUNK: usize = 8;

/// The predicted error statistics at the held-out points `kept` (positions in `spec.test`).
fn predict<P: Fit + ?Sized>(
    fit: &P,
    train: &RobustFit,
    free: &[usize],
    x: &[f64],
    spec: &HeldOutSpec<'_>,
    reg_cols: &[usize],
    kept: &[usize],
) -> Option<ErrorStats> {
    use rayon::prelude::*;
    let problem = fit.positions();
    let c = covariance(fit, train, free)?;
    let chol = c.cholesky()?;
    let points: Vec<usize> = kept.iter().map(|&k| spec.test[k]).collect();
    if points.is_empty() {
        return None;
    }
    // The positions' rows (the fit's own rows follow them).
    let (_, j) = fit.linearise(x, &points)?;
    let j = j.rows(0, 3 * points.len()).into_owned();
    let sigmas: Vec<f64> = points.iter().map(|&i| problem.obs[i].sigma).collect();
    // Unweighted rows (mm per unit of each unknown).
    let unweight = |m: DMatrix<f64>| DMatrix::from_fn(m.nrows(), m.ncols(), |r, k| m[(r, k)] * sigmas[r / 3]);
    let jf = unweight(j.select_columns(free));
    // The registration of a held-out session removes what its base can absorb: the weighted
    // projection I - B (B^T W B)^-1 B^T W.
    let projection = if reg_cols.is_empty() {
        None
    } else {
        let b = unweight(j.select_columns(reg_cols));
        let w = DVector::from_fn(b.nrows(), |r, _| 1.0 / (sigmas[r / 3] * sigmas[r / 3]));
        let bw = DMatrix::from_fn(b.ncols(), b.nrows(), |k, r| b[(r, k)] * w[r]);
        let inv = (&bw * &b).try_inverse()?;
        Some((b, inv * bw))
    };
    let mut rng = crate::seeds::stream(crate::seeds::split_seed(spec.seed, crate::seeds::calibrate::PREDICTION), spec.key);
    let mut pooled = Vec::with_capacity(spec.draws * points.len());
    let mut maxima = Vec::with_capacity(spec.draws);
    // The draws' random numbers in order from the one stream, a few draws at a time; their
    // errors side by side (each draw's own arithmetic: the same for any thread count).
    let rows = 3 * points.len();
    for chunk in (0..spec.draws).collect::<Vec<_>>().chunks(PREDICTION_CHUNK) {
        let drawn: Vec<(DVector<f64>, Vec<f64>)> = chunk
            .iter()
            .map(|_| {
                let z = DVector::from_fn(free.len(), |_, _| StandardNormal.sample(&mut rng));
                let noise: Vec<f64> = (0..rows).map(|_| StandardNormal.sample(&mut rng)).collect();
                (z, noise)
            })
            .collect();
        let ys: Vec<DVector<f64>> = drawn.iter().map(|(z, _)| chol.l() * z).collect();
        let vs = mul_vectors(&jf, &ys);
        let norms: Vec<Vec<f64>> = vs
            .into_par_iter()
            .zip(&drawn)
            .map(|(mut v, (_, noise))| {
                for r in 0..v.len() {
                    v[r] += noise[r] * train.sigma_hat * sigmas[r / 3];
                }
                if let Some((b, solve)) = &projection {
                    v -= b * (solve * &v);
                }
                (0..points.len()).map(|k| v.fixed_rows::<3>(3 * k).norm()).collect()
            })
            .collect();
        for n in norms {
            maxima.push(n.iter().copied().fold(0.0, f64::max));
            pooled.extend(n);
        }
    }
    let mut stats = ErrorStats::of(&pooled);
    stats.max = quantile(&finite_sorted(&maxima), 0.5);
    Some(stats)
}

/// A model's k-fold cross-validation (over the training points, or over every point).
#[derive(Clone, Debug, PartialEq)]
pub struct CrossValidation {
    /// Per problem point: its error when its fold was held out, mm (NaN outside the folds or when
    /// the fold's fit gave no model).
    pub errors_mm: Vec<f64>,
    /// Per problem point: an outlier of the data (as given).
    pub outlier: Vec<bool>,
    /// Statistics over the held-out points not flagged, mm.
    pub stats: ErrorStats,
    /// Points in the statistics.
    pub points: usize,
    /// Folds whose fit did not converge, and how they ended.
    pub failed: Vec<(usize, String)>,
}

impl CrossValidation {
    /// No cross-validation over `n` points.
    pub fn empty(n: usize) -> Self {
        Self { errors_mm: vec![f64::NAN; n], outlier: vec![false; n], stats: ErrorStats::default(), points: 0, failed: Vec::new() }
    }
}

/// One fold of a cross-validation: none (no point in it), why its fit failed, or its points and
/// their errors, mm.
type FoldResult = Option<Result<(Vec<usize>, Vec<f64>), String>>;

/// Cross-validates the model of `problem` (its layout) from `x0`: for each fold, a fit on the
/// other training points (the data's `outliers` left out) and the errors at the fold's.
pub fn cross_validate<P: Fit + ?Sized>(
    problem: &P,
    x0: &[f64],
    point_fold: &[Option<usize>],
    folds: usize,
    outliers: &[bool],
    opts: &SolveOptions,
    labels: &super::diagnose::Labels<'_>,
) -> CrossValidation {
    use rayon::prelude::*;
    let fit_of = problem;
    let problem = fit_of.positions();
    let n = problem.obs.len();
    let l = &problem.layout;
    // Each fold on its own (in parallel: a fold's fit depends on nothing but its points, so the
    // result is the same for any thread count), then gathered in the order of the folds.
    let fold = |f: usize| -> FoldResult {
        let train: Vec<usize> = (0..n).filter(|&i| point_fold[i].is_some_and(|g| g != f)).collect();
        let test: Vec<usize> = (0..n).filter(|&i| point_fold[i] == Some(f)).collect();
        if test.is_empty() {
            return None;
        }
        let free = free_columns(fit_of, &train, true);
        let mask: Vec<bool> = train.iter().map(|&i| outliers[i]).collect();
        let fit = fit_without(fit_of, x0, &free, &train, &mask, opts);
        if !fit.solved.outcome.is_converged() {
            let why = super::diagnose::why(fit_of, &fit.solved.x, &free, &fit.inliers(), labels);
            return Some(Err(format!("{}: {why}", fit.solved.outcome.label())));
        }
        if let Some(t) =
            (0..l.targets).find(|&t| test.iter().any(|&i| problem.obs[i].target == t) && !train.iter().any(|&i| problem.obs[i].target == t))
        {
            return Some(Err(format!("target {} has no point outside the fold", labels.targets[t])));
        }
        // A session with no point outside the fold (a fold per session) has no base from the fit:
        // it is registered on its own points, as a held-out session is.
        let register: Vec<usize> = (0..l.sessions)
            .filter(|&s| test.iter().any(|&i| problem.obs[i].session == s) && !train.iter().any(|&i| problem.obs[i].session == s))
            .flat_map(|s| l.base_columns(s))
            .collect();
        let mut fit = fit;
        if !register.is_empty() {
            let mask: Vec<bool> = test.iter().map(|&i| outliers[i]).collect();
            fit.solved.x = fit_without(fit_of, &fit.solved.x, &register, &test, &mask, opts).solved.x;
        }
        let Some(e) = problem.errors(&fit.solved.x, &test) else {
            return Some(Err("not_finite".into()));
        };
        let norms = e.iter().map(|e| e.norm()).collect();
        Some(Ok((test, norms)))
    };
    let results: Vec<FoldResult> = (0..folds).into_par_iter().map(fold).collect();
    let mut errors_mm = vec![f64::NAN; n];
    let mut outlier = vec![false; n];
    let mut failed = Vec::new();
    for (f, r) in results.into_iter().enumerate() {
        match r {
            None => {}
            Some(Err(why)) => failed.push((f, why)),
            Some(Ok((test, norms))) => {
                for (i, e) in test.iter().zip(norms) {
                    errors_mm[*i] = e;
                    outlier[*i] = outliers[*i];
                }
            }
        }
    }
    let kept: Vec<f64> = (0..n).filter(|&i| errors_mm[i].is_finite() && !outlier[i]).map(|i| errors_mm[i]).collect();
    CrossValidation { points: kept.len(), stats: ErrorStats::of(&kept), errors_mm, outlier, failed }
}

/// The paired comparison of two models' cross-validated squared errors on the points both
/// predicted and neither flagged: mean difference `a - b` (mm^2) and its standard error.
pub fn paired_difference(a: &CrossValidation, b: &CrossValidation) -> (f64, f64, usize) {
    let d: Vec<f64> = (0..a.errors_mm.len())
        .filter(|&i| a.errors_mm[i].is_finite() && b.errors_mm[i].is_finite() && !a.outlier[i] && !b.outlier[i])
        .map(|i| a.errors_mm[i].powi(2) - b.errors_mm[i].powi(2))
        .collect();
    let n = d.len();
    if n < 2 {
        return (f64::NAN, f64::NAN, n);
    }
    let mean = d.iter().sum::<f64>() / n as f64;
    let var = d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
    (mean, (var / n as f64).sqrt(), n)
}

/// The model chosen by held-out error: the one of least cross-validated mean squared error, unless
/// a simpler one (earlier in `cvs`) is within one standard error of it on the paired difference
/// (the one-standard-error rule: a difference the folds cannot tell from zero does not buy
/// parameters). `None` when no model cross-validated.
pub fn select(cvs: &[Option<&CrossValidation>]) -> Option<usize> {
    let mse = |cv: &CrossValidation| cv.stats.rms.powi(2);
    let best = (0..cvs.len()).filter(|&k| cvs[k].is_some_and(|c| c.points > 0)).min_by(|&a, &b| {
        let (ca, cb) = (cvs[a].expect("filtered"), cvs[b].expect("filtered"));
        mse(ca).total_cmp(&mse(cb))
    })?;
    let b = cvs[best].expect("filtered");
    (0..best)
        .find(|&k| {
            cvs[k].is_some_and(|a| {
                let (mean, se, _) = paired_difference(a, b);
                mean.is_finite() && mean <= se
            })
        })
        .or(Some(best))
}

/// The layouts' unknowns at their start: `layout`'s robot values from `start`, the frames `frames`.
pub fn start_values(layout: &Layout, start: &crate::robot::RobotModel, frames: &[f64]) -> Vec<f64> {
    let mut x: Vec<f64> = layout.robot.pack(start).iter().copied().collect();
    x.extend_from_slice(frames);
    x
}
