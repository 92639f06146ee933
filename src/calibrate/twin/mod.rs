//! The robot's twin: what a calibration's chosen model misses, learned from its fit on the
//! calibration (training) split.
//!
//! ```text
//! the chosen model refitted on the training points (outliers left out)
//!  ─► residual decomposition: instrument noise (the file's sigma column, --instrument-noise-mm,
//!     or the scatter of distances between targets measured at one pose), repeatability (the
//!     scatter of poses visited more than once, less the instrument's), the systematic rest
//!  ─► effect families (effects.rs: harmonics per joint of orders 1-3 and of the one order above
//!     3 a scan of the residual picks per joint, backlash, sag, drift) fitted jointly
//!     with the model (their columns projected off the model's Jacobian: Frisch-Waugh-Lovell),
//!     kept one at a time while each lowers the error cross-validated over the calibration
//!     split's folds by more than [`KEEP_SE`] ([`KEEP_SE_SCANNED`] for a scanned order) paired
//!     standard errors (poses as the pairs); the
//!     held-out split is left to judge the result (and the plan)
//!  ─► the twin: the calibrated robot moved by the joint fit, its [learned] table (the kept
//!     effects with their standard deviations, the repeatability, the per-pose joint error left)
//! ```
//!
//! Variances are per coordinate (mm^2); an interval is 95 %: chi-square on a variance with its
//! degrees of freedom (Wilson-Hilferty), a normal approximation on a difference of variances,
//! and for an effect coefficient its least-squares standard deviation with the residuals
//! clustered by pose (a sandwich), times 1.96.

pub mod effects;
mod report;
pub mod shape;

use std::collections::HashMap;

use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

pub use effects::{Coefficient, Family, KEEP_SE, KEEP_SE_SCANNED};
use effects::{PointData, columns};
pub use report::{markdown, results_into};

use super::problem::{Layout, Problem, SolveOptions};
use super::robust::fit_without;
use super::validation::{free_columns, start_values};
use super::{CalibrateError, Calibration};
use crate::robot::learned::{LearnedEffects, LearnedHarmonic, lever_arms_m};
use crate::robot::{JOINTS, LinkParam, ParamId, ParamSet, RobotModel};

/// Two poses whose joint values agree to this (rad, every joint) are one pose visited twice.
pub const SAME_POSE_RAD: f64 = 1e-4;
/// The two-sided 95 % normal quantile.
const Z95: f64 = 1.959_963_984_540_054;
/// Families whose projected column spaces have a principal angle with cosine above this are named
/// as not told apart.
pub const CONFOUNDED_COS: f64 = 0.95;
/// A column that keeps less than this fraction of its norm once projected off the model's
/// Jacobian is absorbed by the model.
pub const ABSORBED: f64 = 0.05;
/// ISO 9283 RP of an isotropic 3-D Gaussian scatter per unit of its standard deviation per
/// coordinate: mean plus 3 standard deviations of a Maxwell distance (`2 sqrt(2/pi) + 3 sqrt(3 - 8/pi)`).
pub const RP_PER_SIGMA: f64 = 3.6163;

/// A level per coordinate (mm), with its 95 % interval and what estimated it.
#[derive(Clone, Debug, PartialEq)]
pub struct Level {
    /// Standard deviation per coordinate, mm.
    pub sigma_mm: f64,
    /// Its 95 % interval, mm (equal to the value when stated).
    pub interval_mm: [f64; 2],
    /// What estimated it (or who stated it).
    pub by: String,
}

impl Level {
    /// A variance `var` (mm^2) with `dof` degrees of freedom: chi-square interval.
    fn chi2(var: f64, dof: f64, by: String) -> Self {
        let (lo, hi) = (var * dof / chi2_quantile(0.975, dof), var * dof / chi2_quantile(0.025, dof));
        Level { sigma_mm: var.max(0.0).sqrt(), interval_mm: [lo.max(0.0).sqrt(), hi.max(0.0).sqrt()], by }
    }

    /// A variance stated, not estimated.
    fn stated(sigma: f64, by: String) -> Self {
        Level { sigma_mm: sigma, interval_mm: [sigma, sigma], by }
    }

    /// A difference of variances `var` with the variance of its estimate `var_var`: normal
    /// approximation, clipped at zero.
    fn difference(var: f64, var_var: f64, by: String) -> Self {
        let h = Z95 * var_var.max(0.0).sqrt();
        Level { sigma_mm: var.max(0.0).sqrt(), interval_mm: [(var - h).max(0.0).sqrt(), (var + h).max(0.0).sqrt()], by }
    }

    /// This level with its variance (and interval) multiplied by `f`, estimated `by`.
    fn scaled(&self, f: f64, by: String) -> Self {
        let r = f.max(0.0).sqrt();
        Level { sigma_mm: self.sigma_mm * r, interval_mm: [self.interval_mm[0] * r, self.interval_mm[1] * r], by }
    }

    fn var(&self) -> f64 {
        self.sigma_mm * self.sigma_mm
    }

    /// Variance of the variance estimate (from the interval's half width).
    fn var_var(&self) -> f64 {
        let h = (self.interval_mm[1].powi(2) - self.interval_mm[0].powi(2)) / (2.0 * Z95);
        h * h
    }
}

/// The quantile `p` of a chi-square distribution with `nu` degrees of freedom (Wilson-Hilferty).
pub fn chi2_quantile(p: f64, nu: f64) -> f64 {
    let z = if p > 0.5 { Z95 } else { -Z95 };
    debug_assert!((p - 0.975).abs() < 1e-12 || (p - 0.025).abs() < 1e-12, "95 % intervals only");
    let c = 2.0 / (9.0 * nu);
    (nu * (1.0 - c + z * c.sqrt()).powi(3)).max(1e-300)
}

/// The residual's parts on the training split.
#[derive(Clone, Debug, PartialEq)]
pub struct Decomposition {
    /// Training points used (outliers left out).
    pub points: usize,
    /// Poses of those points.
    pub poses: usize,
    /// The chosen model's residual per coordinate on them (degrees of freedom: 3 points less the
    /// free unknowns).
    pub total: Level,
    /// The instrument's noise (`None`: not estimated, with why in `notes`).
    pub instrument: Option<Level>,
    /// Every other estimate of the instrument's noise the data hold (a check on the one used).
    pub instrument_checks: Vec<Level>,
    /// The robot's repeatability per coordinate (`None`: not estimated).
    pub repeatability: Option<Level>,
    /// Instrument and repeatability together, where they cannot be separated.
    pub together: Option<Level>,
    /// The systematic part the model misses (total less instrument and repeatability).
    pub systematic: Option<Level>,
    /// The residual after the kept effects.
    pub after: Level,
    /// The part of the residual the kept effects explain.
    pub explained: Level,
    /// The systematic part left after the kept effects.
    pub left: Option<Level>,
    /// What cannot be separated or was not estimated, and why.
    pub notes: Vec<String>,
}

/// One family tried, with its held-out evidence.
#[derive(Clone, Debug, PartialEq)]
pub struct FamilyTrial {
    /// The family.
    pub family: Family,
    /// Its columns (coefficients) on these data.
    pub columns: usize,
    /// Columns the model's parameters absorb (kept less than [`ABSORBED`] of their norm).
    pub absorbed: Vec<String>,
    /// Mean cross-validated gain in squared error per training pose (mm^2 when the points carry
    /// no uncertainty) when the family was last tried, and its paired standard error.
    pub gain: (f64, f64),
    /// Kept.
    pub kept: bool,
}

/// A kept effect's coefficient.
#[derive(Clone, Debug, PartialEq)]
pub struct Effect {
    /// The coefficient.
    pub coefficient: Coefficient,
    /// Value, in [`Coefficient::unit`].
    pub value: f64,
    /// Standard deviation, same unit.
    pub std: f64,
}

/// What the twin analysis gives.
#[derive(Clone, Debug)]
pub struct Twin {
    /// The residual's parts.
    pub decomposition: Decomposition,
    /// Held-out poses (the split the plan compares with; not used to choose).
    pub held_out_poses: usize,
    /// Training poses the families were judged on (cross-validation over the calibration split's folds).
    pub cv_poses: usize,
    /// The kept families' gain in squared error per held-out pose and its paired standard error
    /// (`None`: no held-out pose).
    pub held_out_gain: Option<(f64, f64)>,
    /// Every family tried.
    pub families: Vec<FamilyTrial>,
    /// The kept families' coefficients.
    pub effects: Vec<Effect>,
    /// Pairs of families the data cannot tell apart: names and the cosine of their smallest
    /// principal angle (after projection off the model).
    pub confounded: Vec<(String, String, f64)>,
    /// The `[learned]` table.
    pub learned: LearnedEffects,
    /// The calibrated robot moved by the joint fit of the kept effects.
    pub model: RobotModel,
    /// The instrument's noise per coordinate for a plan, mm (`None`: not known).
    pub noise_mm: Option<f64>,
    /// How the residual left is correlated between poses by their joint-space distance.
    pub correlation: shape::Correlation,
    /// The smooth field's length and level fitted to [`Twin::correlation`] (`None`: no bin of
    /// distinct poses above white, or a length the bins do not resolve).
    pub length: Option<shape::LengthScale>,
}

impl Twin {
    /// The learned effects a plan draws: the coefficients at their fitted values, without their
    /// standard deviations. The coefficients are correlated with each other and with the model's
    /// parameters (a harmonic of a joint with its geometry), and `[learned]` keeps one standard
    /// deviation each: drawn independently, they would put a world's robot far from the data the
    /// twin was fitted on. Per world, the randomness is the repeatability, the per-pose error (its
    /// level drawn from its estimate's standard deviation: a level, not a coefficient the model's
    /// parameters share) and the noise.
    pub fn plan_effects(&self) -> LearnedEffects {
        let mut l = self.learned.clone();
        l.backlash_std_mdeg = [0.0; JOINTS];
        l.sag_std_mdeg_per_m = [0.0; JOINTS];
        l.drift_std_mm_per_pose = [0.0; 3];
        for h in &mut l.harmonic {
            h.std_mdeg = 0.0;
        }
        l
    }
}

/// Least squares on columns `a` with column scaling and a pseudo-inverse of the normal matrix.
struct Lsq {
    a: DMatrix<f64>,
    scale: Vec<f64>,
    pinv: DMatrix<f64>,
}

impl Lsq {
    fn new(a: DMatrix<f64>) -> Self {
        let scale: Vec<f64> = a.column_iter().map(|c| c.norm()).map(|v| if v > 0.0 { 1.0 / v } else { 0.0 }).collect();
        let pinv = scaled_pinv(super::problem::tr_mul(&a, None), &scale);
        Self { a, scale, pinv }
    }

    /// Coefficients of `b`'s columns on `a` (internal units).
    fn coef(&self, b: &DMatrix<f64>) -> DMatrix<f64> {
        scaled_solve(&self.pinv, &self.scale, super::problem::tr_mul(&self.a, Some(b)))
    }

    /// `b` less its projection on `a`'s columns.
    fn resid(&self, b: &DMatrix<f64>) -> DMatrix<f64> {
        if self.a.ncols() == 0 {
            return b.clone();
        }
        b - super::problem::mul(&self.a, &self.coef(b))
    }

    /// Covariance of the coefficients (internal units) with the residuals `u` clustered by `groups`
    /// (a group per row triple).
    fn sandwich(&self, u: &DVector<f64>, groups: &[usize]) -> DMatrix<f64> {
        let k = self.a.ncols();
        let g = groups.iter().copied().max().map_or(0, |m| m + 1);
        let mut score = DMatrix::zeros(g, k);
        for (row, &gr) in groups.iter().enumerate() {
            for a in 0..3 {
                let r = 3 * row + a;
                for c in 0..k {
                    score[(gr, c)] += self.a[(r, c)] * self.scale[c] * u[r];
                }
            }
        }
        let used = groups.iter().collect::<std::collections::BTreeSet<_>>().len() as f64;
        let meat = score.tr_mul(&score) * if used > 1.0 { used / (used - 1.0) } else { 1.0 };
        let mut cov = &self.pinv * meat * &self.pinv;
        for r in 0..k {
            for c in 0..k {
                cov[(r, c)] *= self.scale[r] * self.scale[c];
            }
        }
        cov
    }
}

/// The pseudo-inverse of the normal matrix `n` (`A^T A`) scaled by `scale` on both sides (each
/// column of `A` to unit norm): its eigenvalues above 1e-12 of the largest inverted.
fn scaled_pinv(mut n: DMatrix<f64>, scale: &[f64]) -> DMatrix<f64> {
    let k = n.nrows();
    for r in 0..k {
        for c in 0..k {
            n[(r, c)] *= scale[r] * scale[c];
        }
    }
    if k == 0 {
        return DMatrix::zeros(0, 0);
    }
    let e = n.symmetric_eigen();
    let top = e.eigenvalues.iter().fold(0.0f64, |m, v| m.max(*v));
    let inv = DVector::from_iterator(k, e.eigenvalues.iter().map(|v| if *v > 1e-12 * top { 1.0 / v } else { 0.0 }));
    &e.eigenvectors * DMatrix::from_diagonal(&inv) * e.eigenvectors.transpose()
}

/// The coefficients `S P S A^T b` from `A^T b` (`atb`), `P` of [`scaled_pinv`] and `S` its scale.
fn scaled_solve(pinv: &DMatrix<f64>, scale: &[f64], mut atb: DMatrix<f64>) -> DMatrix<f64> {
    for (r, s) in scale.iter().enumerate() {
        atb.row_mut(r).scale_mut(*s);
    }
    let mut x = pinv * atb;
    for (r, s) in scale.iter().enumerate() {
        x.row_mut(r).scale_mut(*s);
    }
    x
}

/// Rows per piece of [`fold_grams`] (each piece's Gram matrix on its own, side by side).
const GRAM_PIECE: usize = 1024;

/// Per fold, the Gram matrix `M_f^T M_f` of the columns of `parts` side by side (`M`), over the
/// rows of the training points in fold `f` (`fold_of`, per point; rows `3 r .. 3 r + 3`): each
/// fold's rows in pieces of [`GRAM_PIECE`], each piece's product by a blocked matrix product, the
/// products summed in order (the same bits for any thread count).
fn fold_grams(parts: &[&DMatrix<f64>], fold_of: &[usize], folds: usize) -> Vec<DMatrix<f64>> {
    let cols: usize = parts.iter().map(|p| p.ncols()).sum();
    let rows_of: Vec<Vec<usize>> =
        (0..folds).map(|f| (0..fold_of.len()).filter(|&r| fold_of[r] == f).flat_map(|r| [3 * r, 3 * r + 1, 3 * r + 2]).collect()).collect();
    let pieces: Vec<(usize, &[usize])> =
        rows_of.iter().enumerate().flat_map(|(f, rows)| rows.chunks(GRAM_PIECE).map(move |c| (f, c))).collect();
    let products: Vec<DMatrix<f64>> = pieces
        .par_iter()
        .map(|(_, rows)| {
            let mut block = DMatrix::zeros(rows.len(), cols);
            let mut c = 0;
            for part in parts {
                for k in 0..part.ncols() {
                    let column = part.column(k);
                    for (row, &r) in rows.iter().enumerate() {
                        block[(row, c)] = column[r];
                    }
                    c += 1;
                }
            }
            // A blocked matrix product (the same operations for the same piece, on any thread).
            block.transpose() * &block
        })
        .collect();
    let mut grams = vec![DMatrix::zeros(cols, cols); folds];
    for ((f, _), product) in pieces.iter().zip(products) {
        grams[*f] += product;
    }
    grams
}

/// An orthonormal basis of the column space of `m` (its left singular vectors of singular values
/// above 1e-9 of the largest).
fn column_basis(m: &DMatrix<f64>) -> DMatrix<f64> {
    if m.nrows() == 0 || m.ncols() == 0 {
        return DMatrix::zeros(m.nrows(), 0);
    }
    let svd = m.clone().svd(true, false);
    let u = svd.u.expect("u asked");
    let top = svd.singular_values.iter().fold(0.0f64, |x, v| x.max(*v));
    let keep: Vec<usize> = (0..svd.singular_values.len()).filter(|&k| svd.singular_values[k] > 1e-9 * top).collect();
    u.select_columns(&keep)
}

/// The largest cosine of the principal angles between two column spaces, given by orthonormal
/// bases ([`column_basis`]).
fn principal_cos(ua: &DMatrix<f64>, ub: &DMatrix<f64>) -> f64 {
    if ua.ncols() == 0 || ub.ncols() == 0 {
        return 0.0;
    }
    (ua.transpose() * ub).singular_values().iter().fold(0.0f64, |m, v| m.max(*v)).min(1.0)
}

/// The twin of calibration `c`: the chosen model refitted on the training split, its residual
/// decomposed, effect families fitted and chosen by held-out error. `stated_noise_mm`: the
/// instrument's noise per coordinate as the user states it.
pub fn analyse(c: &Calibration, stated_noise_mm: Option<f64>) -> Result<Twin, CalibrateError> {
    analyse_with(c, stated_noise_mm, None)
}

/// [`analyse`], taking from `reuse` what the calibration computed that the twin computes again
/// (the points' setup, the chosen model's training fit) where it is the same computation.
pub(crate) fn analyse_with(c: &Calibration, stated_noise_mm: Option<f64>, reuse: Option<&super::Kept>) -> Result<Twin, CalibrateError> {
    let m = &c.measurements;
    let owned;
    let s = match reuse.and_then(|k| k.setup()) {
        Some(s) => s,
        None => {
            owned = super::setup(&c.robot, m)?;
            &owned
        }
    };
    let chosen = c.chosen();
    let layout = chosen.layout.clone();
    let nominal = &c.robot.nominal;
    let problem = Problem { start: nominal, layout: layout.clone(), obs: &s.obs };
    let held_pose = |i: usize| c.assignment.held_out[m.points[i].pose];
    let train: Vec<usize> = (0..m.points.len()).filter(|&i| !held_pose(i) && !c.flagged[i]).collect();
    let held: Vec<usize> = (0..m.points.len()).filter(|&i| held_pose(i) && !c.flagged[i]).collect();
    let no_model = |outcome: String| CalibrateError::NoModel { path: m.path.clone(), model: chosen.name(), outcome };
    let x0 = start_values(&layout, nominal, &s.frames_x);
    let with_robot = !layout.robot.is_empty();
    let free = free_columns(&problem, &train, with_robot);
    let solved = match reuse.and_then(|k| k.train_fit(&train, &layout, &free)) {
        Some(solved) => solved.clone(),
        None => fit_without(&problem, &x0, &free, &train, &vec![false; train.len()], &SolveOptions::default()).solved,
    };
    if !solved.outcome.is_converged() {
        return Err(no_model(format!("the twin's training fit: {}", solved.outcome.label())));
    }
    let x = solved.x;
    let pr = layout.robot.len();
    let fitted = layout.robot.unpack(nominal, &x[..pr]).map_err(|e| no_model(e.to_string()))?;
    // The link-angle Jacobian: the fitted robot with the six joint offsets as its only parameters.
    let offsets = ParamSet::new((1..=JOINTS).map(|joint| ParamId::Link { joint, kind: LinkParam::ThetaOffset }).collect())
        .expect("six joint offsets");
    let lay6 = Layout { robot: offsets.clone(), ..layout.clone() };
    let mut x6: Vec<f64> = offsets.pack(&fitted).iter().copied().collect();
    x6.extend_from_slice(&x[layout.frames()]);
    let p6 = Problem { start: &fitted, layout: lay6, obs: &s.obs };
    let link_jacobian = |idx: &[usize]| p6.linearise(&x6, idx).map(|(_, j)| j.columns(0, JOINTS).into_owned());
    // The model's residuals and Jacobian, and the link-angle Jacobian, side by side.
    let (model_rows, jl) =
        rayon::join(|| problem.linearise(&x, &train).map(|(rw, jw)| (rw, jw.select_columns(&free))), || link_jacobian(&train));
    let (rw, jf) = model_rows.ok_or_else(|| no_model("the twin's training fit has no model".into()))?;
    let jl = jl.ok_or_else(|| no_model("the twin's link Jacobian".into()))?;
    let data = point_data(c, &s.obs, &fitted);
    // Pose of each training row, and the per-pose groups.
    let pose_of = |idx: &[usize]| -> Vec<usize> {
        let mut ids: HashMap<usize, usize> = HashMap::new();
        idx.iter()
            .map(|&i| {
                let n = ids.len();
                *ids.entry(m.points[i].pose).or_insert(n)
            })
            .collect()
    };
    let train_pose = pose_of(&train);
    let model_lsq = Lsq::new(jf);
    let jf = &model_lsq.a;

    // Held-out rows: residuals of the training fit, the model's Jacobian, the columns the held-out
    // points need that the training fit did not free (a session or target held out whole: its
    // frame registered on the held-out points, to first order).
    let held_parts = if held.is_empty() {
        None
    } else {
        let (rows, jlh) = rayon::join(|| problem.linearise(&x, &held), || link_jacobian(&held));
        let (rh, jh) = rows.ok_or_else(|| no_model("the twin's held-out points".into()))?;
        let jlh = jlh.ok_or_else(|| no_model("the twin's link Jacobian".into()))?;
        let own: Vec<usize> = (0..layout.len()).filter(|k| !free.contains(k) && jh.column(*k).iter().any(|v| *v != 0.0)).collect();
        let own = Lsq::new(jh.select_columns(&own));
        Some((rh, jh.select_columns(&free), jlh, own, pose_of(&held)))
    };

    // Every family's columns, projected off the model's all at once; those the model absorbs
    // left out (the calibrated robot carries them).
    // The families' columns side by side (the scan beside the fixed families'), in their order.
    let family_columns = |families: Vec<Family>| -> Vec<(Family, DMatrix<f64>, Vec<Coefficient>)> {
        families
            .into_par_iter()
            .map(|f| {
                let (e, coefs) = columns(f, &train, &jl, &data);
                (f, e, coefs)
            })
            .collect()
    };
    let (fixed, scanned) = rayon::join(|| family_columns(Family::all()), || family_columns(effects::scan(&train, &jl, &data, &rw)));
    let candidates: Vec<(Family, DMatrix<f64>, Vec<Coefficient>)> =
        fixed.into_iter().chain(scanned).filter(|(_, e, _)| e.ncols() > 0).collect();
    let projected_every = model_lsq.resid(&hstack(candidates.iter().map(|(_, e, _)| e)));
    let mut families: Vec<(Family, DMatrix<f64>, Vec<Coefficient>)> = Vec::new();
    let mut absorbed: Vec<Vec<String>> = Vec::new();
    let mut projected: Vec<DMatrix<f64>> = Vec::new();
    let mut at = 0;
    for (f, e, coefs) in candidates {
        let p = projected_every.columns(at, e.ncols());
        at += e.ncols();
        let keep: Vec<usize> = (0..e.ncols()).filter(|&k| p.column(k).norm() >= ABSORBED * e.column(k).norm()).collect();
        absorbed.push((0..e.ncols()).filter(|k| !keep.contains(k)).map(|k| coefs[k].name.clone()).collect());
        projected.push(p.select_columns(&keep));
        families.push((f, e.select_columns(&keep), keep.iter().map(|&k| coefs[k].clone()).collect()));
    }
    drop(projected_every);
    // Column ranges of each family in the stacked matrix of every family.
    let mut ranges = Vec::new();
    let mut at = 0;
    for (_, e, _) in &families {
        ranges.push(at..at + e.ncols());
        at += e.ncols();
    }
    let all_e = hstack(families.iter().map(|(_, e, _)| e));
    let rw_m = DMatrix::from_column_slice(rw.len(), 1, rw.as_slice());

    // Cross-validation on the calibration split's folds (poses as units): per fold, the model and
    // the families fitted on the other folds (Frisch-Waugh-Lovell through Gram matrices), the
    // error at the fold's poses.
    let fold_of: Vec<usize> = train.iter().map(|&i| c.assignment.fold[m.points[i].pose].unwrap_or(0)).collect();
    // The Gram matrix of [model's columns | families' columns | residuals] over each fold's rows;
    // a fold's training part is the sum of the other folds' (no copy of its rows).
    let folds_n = c.assignment.folds;
    let grams = fold_grams(&[jf, &all_e, &rw_m], &fold_of, folds_n);
    let (p, q) = (jf.ncols(), all_e.ncols());
    // The folds side by side, gathered in their order (the same for any thread count).
    let folds: Vec<CvFold> = (0..folds_n)
        .into_par_iter()
        .filter_map(|f| {
            let out: Vec<usize> = (0..train.len()).filter(|&r| fold_of[r] == f).collect();
            if out.is_empty() || out.len() == train.len() {
                return None;
            }
            let mut inside = DMatrix::zeros(p + q + 1, p + q + 1);
            for (h, g) in grams.iter().enumerate() {
                if h != f {
                    inside += g;
                }
            }
            // The model's fit on the fold's training part (Frisch-Waugh-Lovell): the families'
            // columns and the residuals less their projections on the model's columns, through
            // the blocks of the Gram matrix.
            let ata = inside.view((0, 0), (p, p)).into_owned();
            let ate = inside.view((0, p), (p, q)).into_owned();
            let atr = inside.view((0, p + q), (p, 1)).into_owned();
            let ete = inside.view((p, p), (q, q)).into_owned();
            let etr = inside.view((p, p + q), (q, 1)).into_owned();
            let scale: Vec<f64> = (0..p).map(|k| ata[(k, k)].sqrt()).map(|v| if v > 0.0 { 1.0 / v } else { 0.0 }).collect();
            let pinv = scaled_pinv(ata.clone(), &scale);
            let (g, beta) = (scaled_solve(&pinv, &scale, ate.clone()), scaled_solve(&pinv, &scale, atr.clone()));
            // (E - A g)^T (E - A g) and (E - A g)^T (r - A beta), expanded.
            let gram = &ete - ate.tr_mul(&g) - g.tr_mul(&ate) + g.tr_mul(&(&ata * &g));
            let gram = (&gram + gram.transpose()) * 0.5;
            let rhs = &etr - ate.tr_mul(&beta) - g.tr_mul(&atr) + g.tr_mul(&(&ata * &beta));
            let ro: Vec<usize> = out.iter().flat_map(|&r| [3 * r, 3 * r + 1, 3 * r + 2]).collect();
            let j_out = jf.select_rows(&ro);
            Some(CvFold {
                gram,
                rhs,
                r_out: rw_m.select_rows(&ro) - &j_out * beta,
                e_out: all_e.select_rows(&ro) - &j_out * g,
                pose: out.iter().map(|&r| train_pose[r]).collect(),
            })
        })
        .collect();
    let poses_train = train_pose.iter().copied().max().map_or(0, |v| v + 1);
    let cv_sse = |set: &[usize]| -> Vec<f64> {
        let cols: Vec<usize> = set.iter().flat_map(|&k| ranges[k].clone()).collect();
        let mut sse = vec![0.0; poses_train];
        for f in &folds {
            let pred = if cols.is_empty() {
                f.r_out.column(0).into_owned()
            } else {
                let a = gram_solve(&f.gram.select_rows(&cols).select_columns(&cols), &f.rhs.select_rows(&cols));
                f.r_out.column(0) - columns_times(&f.e_out, &cols, a.as_slice())
            };
            for (row, p) in f.pose.iter().enumerate() {
                sse[*p] += (0..3).map(|a| pred[3 * row + a].powi(2)).sum::<f64>();
            }
        }
        sse
    };

    // Forward selection by cross-validated error.
    let mut kept: Vec<usize> = Vec::new();
    let mut gains: Vec<(f64, f64)> = vec![(f64::NAN, f64::NAN); families.len()];
    if !folds.is_empty() {
        let mut current = cv_sse(&[]);
        loop {
            let mut best: Option<(usize, f64, Vec<f64>)> = None;
            // Each candidate's error side by side, weighed in order.
            let candidates: Vec<usize> = (0..families.len()).filter(|k| !kept.contains(k)).collect();
            let errors: Vec<Vec<f64>> = candidates
                .par_iter()
                .map(|&k| {
                    let mut set = kept.clone();
                    set.push(k);
                    cv_sse(&set)
                })
                .collect();
            for (k, sse) in candidates.into_iter().zip(errors) {
                let d: Vec<f64> = current.iter().zip(&sse).map(|(a, b)| a - b).collect();
                let (mean, se) = mean_se(&d);
                gains[k] = (mean, se);
                let qualifies = mean > families[k].0.keep_se() * se && mean > 0.0;
                if qualifies && best.as_ref().is_none_or(|b| mean > b.1) {
                    best = Some((k, mean, sse));
                }
            }
            let Some((k, _, sse)) = best else { break };
            kept.push(k);
            current = sse;
        }
    }
    kept.sort_unstable();

    // The joint fit of the kept families on the training points.
    let (coef, cov, fitted_w) = if kept.is_empty() {
        (DVector::zeros(0), DMatrix::zeros(0, 0), DVector::zeros(rw.len()))
    } else {
        let a = hstack(kept.iter().map(|&k| &projected[k]));
        let lsq = Lsq::new(a);
        let coef = lsq.coef(&rw_m).column(0).into_owned();
        let fitted_w = &lsq.a * &coef;
        let u = &rw - &fitted_w;
        let cov = lsq.sandwich(&u, &train_pose);
        (coef, cov, fitted_w)
    };
    // The held-out split: the error of the joint fit at its poses, without and with the kept
    // families (evidence beside the choice, which saw none of it).
    let held_evidence = held_parts.as_ref().map(|(rh, jhf, jlh, own, hpose)| {
        let rh = own.resid(&DMatrix::from_column_slice(rh.len(), 1, rh.as_slice()));
        let mut after = rh.clone();
        if !kept.is_empty() {
            let eh: Vec<DMatrix<f64>> = kept
                .iter()
                .map(|&k| {
                    let (e, coefs) = columns(families[k].0, &held, jlh, &data);
                    let keep: Vec<usize> = (0..coefs.len()).filter(|&c| families[k].2.iter().any(|x| x.name == coefs[c].name)).collect();
                    let g = model_lsq.coef(&families[k].1);
                    own.resid(&(e.select_columns(&keep) - jhf * g))
                })
                .collect();
            after = rh.clone() - hstack(eh.iter()) * DMatrix::from_column_slice(coef.len(), 1, coef.as_slice());
        }
        let poses = hpose.iter().copied().max().map_or(0, |v| v + 1);
        let mut d = vec![0.0; poses];
        for (row, p) in hpose.iter().enumerate() {
            d[*p] += (0..3).map(|a| rh[3 * row + a].powi(2) - after[3 * row + a].powi(2)).sum::<f64>();
        }
        mean_se(&d)
    });
    let kept_coefs: Vec<Coefficient> = kept.iter().flat_map(|&k| families[k].2.iter().cloned()).collect();
    let effects: Vec<Effect> = kept_coefs
        .iter()
        .enumerate()
        .map(|(k, co)| Effect { coefficient: co.clone(), value: co.shown(coef[k]), std: co.shown(cov[(k, k)].max(0.0).sqrt()).abs() })
        .collect();
    // The model's shift in the joint fit: -G a, its robot part onto the calibrated robot.
    let model = if kept.is_empty() || !with_robot {
        c.model.clone()
    } else {
        let e = hstack(kept.iter().map(|&k| &families[k].1));
        let shift = model_lsq.coef(&e) * &coef;
        let mut values: Vec<f64> = layout.robot.pack(&c.model).iter().copied().collect();
        for (a, &col) in free.iter().enumerate() {
            if col < pr {
                values[col] -= shift[a];
            }
        }
        layout.robot.unpack(&c.model, &values).map_err(|e| no_model(format!("the twin's robot: {e}")))?
    };

    let confounded = confounded_pairs(&families, &projected);
    let trials: Vec<FamilyTrial> = families
        .iter()
        .enumerate()
        .map(|(k, (f, e, _))| FamilyTrial {
            family: *f,
            columns: e.ncols(),
            absorbed: absorbed[k].clone(),
            gain: gains[k],
            kept: kept.contains(&k),
        })
        .collect();

    // The decomposition, in mm per coordinate.
    let sig: Vec<f64> = train.iter().map(|&i| s.obs[i].sigma).collect();
    let unweigh = |v: &DVector<f64>| DVector::from_fn(v.len(), |r, _| v[r] * sig[r / 3]);
    let resid_mm = unweigh(&rw);
    let after_mm = unweigh(&(&rw - &fitted_w));
    let dof_total = (3 * train.len()).saturating_sub(free.len()) as f64;
    let dof_after = dof_total - kept_coefs.len() as f64;
    let mut decomposition = decompose(DecomposeInput {
        c,
        train: &train,
        resid_mm: &resid_mm,
        after_mm: &after_mm,
        dof: (dof_total, dof_after),
        stated_noise_mm,
    });
    // The fit's share of a per-pose joint error: the residual's degrees of freedom are white
    // noise's; a per-pose joint error moves every point of a pose together along the link-angle
    // Jacobian, and the fit (model and kept effects) absorbs more of it where its leverage is.
    let kept_projected = hstack(kept.iter().map(|&k| &projected[k]));
    // A per-pose error is repeatable at a joint value: the visits of one pose (joints within
    // SAME_POSE_RAD, any session) share it.
    let mut visited = SamePose::default();
    let same_q: Vec<usize> = train.iter().map(|&i| visited.group(&m.poses[m.points[i].pose].q)).collect();
    let field = field_share(&jl, &same_q, &model_lsq, &kept_projected, dof_after);
    if let Some(left) = decomposition.left.as_mut() {
        *left = left.scaled(
            1.0 / field,
            format!(
                "{}; divided by {field:.3}, the share of a per-pose joint error the fit leaves in the residual over the white noise's",
                left.by
            ),
        );
    }
    let (correlation, length) = left_correlation(m, &train, &train_pose, &(&rw - &fitted_w), jf, &kept_projected, &jl);
    let jl_mm = DMatrix::from_fn(jl.nrows(), jl.ncols(), |r, k| jl[(r, k)] * sig[r / 3]);
    let mut learned = learned_table(c, &decomposition, &effects, &jl_mm, train.len(), field);
    let length = length.filter(|_| learned.pose_error_mdeg > 0.0);
    if let Some(scale) = &length {
        // A smooth field: its length, and its level as the fit of the bins gives it (the level
        // above assumes an error independent per pose, of which the fit absorbs less).
        learned.pose_error_length_rad = scale.length_rad;
        learned.pose_error_length_std_rad = (scale.interval[1] - scale.interval[0]) / (2.0 * Z95);
        learned.pose_error_mdeg = scale.level_rad[0].to_degrees() * 1e3;
        learned.pose_error_std_mdeg = scale.level_rad[1].to_degrees() * 1e3;
        decomposition.left = Some(smooth_left(scale, &jl_mm));
    }
    let noise_mm = decomposition.instrument.as_ref().map(|l| l.sigma_mm);
    Ok(Twin {
        decomposition,
        held_out_poses: held_parts.as_ref().map_or(0, |h| h.4.iter().copied().max().map_or(0, |v| v + 1)),
        cv_poses: poses_train,
        held_out_gain: held_evidence,
        families: trials,
        effects,
        confounded,
        learned,
        model,
        noise_mm,
        correlation,
        length,
    })
}

/// The systematic part left as the smooth field fitted to the correlation gives it: its level
/// before the fit, per coordinate (an error of RMS `s` per joint moves a point by `s^2 |J|_F^2 / 3`
/// on average, `jl_mm` the link-angle Jacobian over the training points, mm per rad).
fn smooth_left(scale: &shape::LengthScale, jl_mm: &DMatrix<f64>) -> Level {
    let per_rad = (jl_mm.iter().map(|v| v * v).sum::<f64>() / (3 * (jl_mm.nrows() / 3).max(1)) as f64).sqrt();
    let ([level, _], [low, high]) = (scale.level_rad, scale.level_interval_rad);
    Level {
        sigma_mm: level * per_rad,
        interval_mm: [low.max(0.0) * per_rad, high * per_rad],
        by: format!(
            "a smooth joint-space field of length {:.2} rad fitted to the error left's correlation by pose distance (below), its \
             level before the fit",
            scale.length_rad
        ),
    }
}

/// The shape of the residual left ([`shape::correlation`]) and a smooth field's length and level
/// fitted to it ([`shape::length_scale`]): `resid` the weighted residual after the kept effects on
/// the training points `train` (dense poses `train_pose`), the fit's columns the model's (`model`)
/// and the kept effects' projected off them (`kept_projected`), `jl` the weighted link-angle
/// Jacobian at the training points.
fn left_correlation(
    m: &super::Measurements,
    train: &[usize],
    train_pose: &[usize],
    resid: &DVector<f64>,
    model: &DMatrix<f64>,
    kept_projected: &DMatrix<f64>,
    jl: &DMatrix<f64>,
) -> (shape::Correlation, Option<shape::LengthScale>) {
    let poses = train_pose.iter().copied().max().map_or(0, |v| v + 1);
    let mut q = vec![[0.0; JOINTS]; poses];
    for (&i, &p) in train.iter().zip(train_pose) {
        q[p] = m.poses[m.points[i].pose].q;
    }
    let a = hstack([model, kept_projected].into_iter().filter(|a| a.ncols() > 0));
    let sub = shape::Subset::of(train_pose, &q);
    // Many poses: the hat matrix's rows at the kept points only, `A_s V S^-1` from the Gram
    // matrix's eigenvectors (the same projection as the tall matrix's singular vectors, without
    // them).
    let basis = match &sub {
        None => column_basis(&a),
        Some(sub) if a.ncols() == 0 => DMatrix::zeros(sub.rows.len(), 0),
        Some(sub) => {
            let eig = nalgebra::SymmetricEigen::new(super::problem::tr_mul(&a, None));
            let top = eig.eigenvalues.iter().fold(0.0f64, |x, v| x.max(*v));
            let keep: Vec<usize> = (0..eig.eigenvalues.len()).filter(|&k| eig.eigenvalues[k] > 1e-12 * top).collect();
            let mut v = eig.eigenvectors.select_columns(&keep);
            for (c, &k) in keep.iter().enumerate() {
                v.column_mut(c).scale_mut(1.0 / eig.eigenvalues[k].sqrt());
            }
            a.select_rows(&sub.rows) * v
        }
    };
    let (resid, jl, pose_of, q) = match &sub {
        None => (std::borrow::Cow::Borrowed(resid), std::borrow::Cow::Borrowed(jl), train_pose, &q[..]),
        Some(sub) => (
            std::borrow::Cow::Owned(resid.select_rows(&sub.rows)),
            std::borrow::Cow::Owned(jl.select_rows(&sub.rows)),
            &sub.pose_of[..],
            &sub.q[..],
        ),
    };
    let (correlation, binning) = shape::correlation_binned(&resid, pose_of, q, &basis);
    let Some(binning) = binning.filter(|_| correlation.bins.iter().any(|b| !b.same_pose && b.above_white())) else {
        return (correlation, None);
    };
    // The field's prediction projects off the fit's columns at the binned points alone: a fit of
    // that many points absorbs the same slow part of a field as the fit of them all.
    let own = match &sub {
        None => basis,
        Some(sub) => column_basis(&a.select_rows(&sub.rows)),
    };
    let length = shape::length_scale(&binning, &correlation, &jl, pose_of, q, &own);
    (correlation, length)
}

/// One fold of the cross-validation: the Gram matrix and right-hand side of every family's
/// columns projected off the model on the other folds, and at the fold's rows the model's
/// prediction error and the families' columns less the model's share of them.
struct CvFold {
    gram: DMatrix<f64>,
    rhs: DMatrix<f64>,
    r_out: DMatrix<f64>,
    e_out: DMatrix<f64>,
    pose: Vec<usize>,
}

/// `m[:, cols] a` as nalgebra's product of the selected columns by the vector `a` forms it
/// (`gemv`: each row's sum starts at the first column's product, and each next column's product
/// is added to it in order; the columns taken one after another), without copying the columns.
fn columns_times(m: &DMatrix<f64>, cols: &[usize], a: &[f64]) -> DVector<f64> {
    let rows = m.nrows();
    let mut y = vec![0.0; rows];
    for (j, &c) in cols.iter().enumerate() {
        let (column, x) = (&m.as_slice()[c * rows..(c + 1) * rows], a[j]);
        if j == 0 {
            y.iter_mut().zip(column).for_each(|(y, v)| *y = v * x);
        } else {
            y.iter_mut().zip(column).for_each(|(y, v)| *y += v * x);
        }
    }
    DVector::from_vec(y)
}

/// Least squares from a Gram matrix: column-scaled, pseudo-inverse of its eigenvalues above 1e-12
/// of the largest.
fn gram_solve(n: &DMatrix<f64>, b: &DMatrix<f64>) -> DMatrix<f64> {
    let k = n.nrows();
    let s: Vec<f64> = (0..k).map(|i| if n[(i, i)] > 0.0 { 1.0 / n[(i, i)].sqrt() } else { 0.0 }).collect();
    let ns = DMatrix::from_fn(k, k, |a, c| n[(a, c)] * s[a] * s[c]);
    let e = ns.symmetric_eigen();
    let top = e.eigenvalues.iter().fold(0.0f64, |m, v| m.max(*v));
    let inv = DVector::from_iterator(k, e.eigenvalues.iter().map(|v| if *v > 1e-12 * top { 1.0 / v } else { 0.0 }));
    let bs = DMatrix::from_fn(k, b.ncols(), |a, c| b[(a, c)] * s[a]);
    let x = &e.eigenvectors * DMatrix::from_diagonal(&inv) * e.eigenvectors.transpose() * bs;
    DMatrix::from_fn(k, b.ncols(), |a, c| x[(a, c)] * s[a])
}

fn hstack<'a>(parts: impl Iterator<Item = &'a DMatrix<f64>>) -> DMatrix<f64> {
    let parts: Vec<&DMatrix<f64>> = parts.collect();
    let rows = parts.first().map_or(0, |p| p.nrows());
    let cols: usize = parts.iter().map(|p| p.ncols()).sum();
    let mut out = DMatrix::zeros(rows, cols);
    let mut at = 0;
    for p in parts {
        out.columns_mut(at, p.ncols()).copy_from(p);
        at += p.ncols();
    }
    out
}

fn mean_se(d: &[f64]) -> (f64, f64) {
    let n = d.len() as f64;
    if d.len() < 2 {
        return (f64::NAN, f64::NAN);
    }
    let mean = d.iter().sum::<f64>() / n;
    let var = d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}

fn confounded_pairs(families: &[(Family, DMatrix<f64>, Vec<Coefficient>)], projected: &[DMatrix<f64>]) -> Vec<(String, String, f64)> {
    let bases: Vec<DMatrix<f64>> = projected.par_iter().map(column_basis).collect();
    // Every pair side by side, gathered in order.
    let pairs: Vec<(usize, usize)> = (0..families.len()).flat_map(|a| (a + 1..families.len()).map(move |b| (a, b))).collect();
    let cosines: Vec<f64> = pairs.par_iter().map(|&(a, b)| principal_cos(&bases[a], &bases[b])).collect();
    pairs
        .iter()
        .zip(cosines)
        .filter(|(_, cos)| *cos > CONFOUNDED_COS)
        .map(|(&(a, b), cos)| (families[a].0.name(), families[b].0.name(), cos))
        .collect()
}

/// Per point of the problem: link angles, approach directions (from the pose before in the
/// session; the first pose of a session has none), lever arms, pose index, uncertainty.
fn point_data(c: &Calibration, obs: &[super::problem::Obs], fitted: &RobotModel) -> PointData {
    let m = &c.measurements;
    let mut direction_of_pose = vec![[0.0; JOINTS]; m.poses.len()];
    let mut index_of_pose = vec![0.0; m.poses.len()];
    let mut last: HashMap<usize, (usize, crate::robot::Joints)> = HashMap::new();
    for (p, pose) in m.poses.iter().enumerate() {
        if let Some((k, prev)) = last.get(&pose.session) {
            direction_of_pose[p] = std::array::from_fn(|j| {
                let d = pose.q[j] - prev[j];
                if d > 0.0 {
                    1.0
                } else if d < 0.0 {
                    -1.0
                } else {
                    0.0
                }
            });
            index_of_pose[p] = (*k + 1) as f64;
        }
        let k = index_of_pose[p] as usize;
        last.insert(pose.session, (k, pose.q));
    }
    let lever_of_pose: Vec<[f64; JOINTS]> = m.poses.iter().map(|p| lever_arms_m(fitted, &p.q)).collect();
    let pose = |i: usize| m.points[i].pose;
    PointData {
        q: obs.iter().map(|o| o.q).collect(),
        direction: (0..obs.len()).map(|i| direction_of_pose[pose(i)]).collect(),
        lever_m: (0..obs.len()).map(|i| lever_of_pose[pose(i)]).collect(),
        pose_index: (0..obs.len()).map(|i| index_of_pose[pose(i)]).collect(),
        sigma: obs.iter().map(|o| o.sigma).collect(),
    }
}

struct DecomposeInput<'a> {
    c: &'a Calibration,
    train: &'a [usize],
    /// Residuals (measured less model) of the training fit, mm, 3 per training point.
    resid_mm: &'a DVector<f64>,
    /// The same after the kept effects.
    after_mm: &'a DVector<f64>,
    /// Degrees of freedom of the residual, before and after the effects.
    dof: (f64, f64),
    stated_noise_mm: Option<f64>,
}

fn decompose(d: DecomposeInput<'_>) -> Decomposition {
    let m = &d.c.measurements;
    let (dof_total, dof_after) = d.dof;
    let n = d.train.len();
    let poses = d.train.iter().map(|&i| m.points[i].pose).collect::<std::collections::BTreeSet<_>>().len();
    let mut notes = Vec::new();
    let total_var = d.resid_mm.norm_squared() / dof_total;
    let after_var = d.after_mm.norm_squared() / dof_after.max(1.0);
    let total =
        Level::chi2(total_var, dof_total, format!("the chosen model's residual on {n} training points ({dof_total} degrees of freedom)"));
    let after = Level::chi2(after_var, dof_after, "the residual after the kept effects".into());
    let explained_var = (total_var - after_var).max(0.0);
    let explained =
        Level::difference(explained_var, total.var_var() + after.var_var(), "the residual less the residual after the kept effects".into());

    // The instrument: stated, the file's sigma column, the distances between targets at one pose.
    let distances = target_distances(m, d.train);
    let sigma_column = d.train.iter().all(|&i| m.points[i].sigma_mm.is_some()).then(|| {
        let v = d.train.iter().map(|&i| m.points[i].sigma_mm.unwrap_or(0.0).powi(2)).sum::<f64>() / n as f64;
        Level::stated(v.sqrt(), "the file's sigma column (RMS over the training points)".into())
    });
    let stated = d.stated_noise_mm.map(|s| Level::stated(s, "--instrument-noise-mm".into()));
    let mut candidates: Vec<Level> = [stated, sigma_column, distances].into_iter().flatten().collect();
    let instrument = (!candidates.is_empty()).then(|| candidates.remove(0));
    if instrument.is_none() {
        notes.push("instrument noise not estimated: no sigma column, no --instrument-noise-mm, no pose with two targets or more".into());
    }

    // Repeated poses: the scatter of the residuals after the kept effects about each group's mean.
    let (repeat_var, repeat_dof, groups) = repeated_scatter(m, d.train, d.after_mm);
    let (repeatability, together) = match (repeat_dof, &instrument) {
        (0, _) => {
            notes.push("repeatability not estimated: no pose visited more than once in the training split".into());
            (None, None)
        }
        (dof, Some(inst)) => {
            let within = Level::chi2(repeat_var, dof as f64, String::new());
            let by = format!("{groups} poses visited more than once ({dof} degrees of freedom), less the instrument's noise");
            (Some(Level::difference(repeat_var - inst.var(), within.var_var() + inst.var_var(), by)), None)
        }
        (dof, None) => {
            let by = format!("{groups} poses visited more than once ({dof} degrees of freedom)");
            notes.push(
                "instrument noise and repeatability cannot be separated (repeated poses but no instrument estimate): their sum is reported"
                    .into(),
            );
            (None, Some(Level::chi2(repeat_var, dof as f64, by)))
        }
    };
    let random: Option<(f64, f64)> = match (&instrument, &repeatability, &together) {
        (_, _, Some(t)) => Some((t.var(), t.var_var())),
        (Some(i), Some(r), None) => Some((i.var() + r.var(), i.var_var() + r.var_var())),
        (Some(i), None, None) => Some((i.var(), i.var_var())),
        _ => None,
    };
    if instrument.is_some() && repeatability.is_none() && together.is_none() {
        notes.push("the systematic part includes the robot's repeatability (not estimated)".into());
    }
    let (systematic, left) = match random {
        Some((v, vv)) => (
            Some(Level::difference(total_var - v, total.var_var() + vv, "the residual less the instrument and repeatability".into())),
            Some(Level::difference(
                after_var - v,
                after.var_var() + vv,
                "the residual after the kept effects less the instrument and repeatability".into(),
            )),
        ),
        None => {
            notes
                .push("the systematic part is not separated from the random (neither instrument noise nor repeatability estimated)".into());
            (None, None)
        }
    };
    Decomposition {
        points: n,
        poses,
        total,
        instrument,
        instrument_checks: candidates,
        repeatability,
        together,
        systematic,
        after,
        explained,
        left,
        notes,
    }
}

/// The instrument's noise per coordinate from the distances between targets measured at one
/// pose: a rigid flange keeps them, whatever the robot's errors; their scatter about each pair's
/// mean has variance twice the noise per coordinate (along the line between the targets).
fn target_distances(m: &super::Measurements, train: &[usize]) -> Option<Level> {
    let mut by_pose: std::collections::BTreeMap<usize, Vec<usize>> = std::collections::BTreeMap::new();
    for &i in train {
        by_pose.entry(m.points[i].pose).or_default().push(i);
    }
    let mut pairs: std::collections::BTreeMap<(usize, usize), Vec<f64>> = std::collections::BTreeMap::new();
    for points in by_pose.values() {
        for (a, &i) in points.iter().enumerate() {
            for &k in &points[a + 1..] {
                let (pi, pk) = (&m.points[i], &m.points[k]);
                let key = (pi.target.min(pk.target), pi.target.max(pk.target));
                pairs.entry(key).or_default().push((pi.measured_mm - pk.measured_mm).norm());
            }
        }
    }
    let (mut ss, mut dof, mut used) = (0.0, 0usize, 0usize);
    for d in pairs.values().filter(|d| d.len() >= 2) {
        let mean = d.iter().sum::<f64>() / d.len() as f64;
        ss += d.iter().map(|v| (v - mean).powi(2)).sum::<f64>();
        dof += d.len() - 1;
        used += 1;
    }
    (dof >= 2).then(|| {
        let by = format!("distances between targets at one pose ({used} target pairs, {dof} degrees of freedom)");
        Level::chi2(ss / (2.0 * dof as f64), dof as f64, by)
    })
}

/// Scatter per coordinate of `resid` (3 per training point) about the mean of each group of
/// visits of one pose (joints within [`SAME_POSE_RAD`], any session) at one target: variance,
/// degrees of freedom, groups.
fn repeated_scatter(m: &super::Measurements, train: &[usize], resid: &DVector<f64>) -> (f64, usize, usize) {
    // Poses of the training points, grouped by their joint values.
    let mut poses: Vec<usize> = train.iter().map(|&i| m.points[i].pose).collect();
    poses.sort_unstable();
    poses.dedup();
    let mut group_of: HashMap<usize, usize> = HashMap::new();
    let mut reps = SamePose::default();
    for &p in &poses {
        group_of.insert(p, reps.group(&m.poses[p].q));
    }
    let mut members: std::collections::BTreeMap<(usize, usize), Vec<usize>> = std::collections::BTreeMap::new();
    for (row, &i) in train.iter().enumerate() {
        members.entry((group_of[&m.points[i].pose], m.points[i].target)).or_default().push(row);
    }
    let (mut ss, mut dof) = (0.0, 0usize);
    let mut groups = std::collections::BTreeSet::new();
    for ((g, _), rows) in members.iter().filter(|(_, r)| r.len() >= 2) {
        groups.insert(*g);
        for a in 0..3 {
            let mean = rows.iter().map(|r| resid[3 * r + a]).sum::<f64>() / rows.len() as f64;
            ss += rows.iter().map(|r| (resid[3 * r + a] - mean).powi(2)).sum::<f64>();
        }
        dof += rows.len() - 1;
    }
    if dof == 0 {
        return (f64::NAN, 0, 0);
    }
    (ss / (3.0 * dof as f64), 3 * dof, groups.len())
}

/// The visits of one pose: each joint vector joins the first group (in the order the groups were
/// opened) whose first member is within [`SAME_POSE_RAD`] of it at every joint, else opens a group.
/// The groups' first members are kept in cells of [`SamePose::CELL`] per joint, so that a search
/// looks at the few cells within reach of the joints, not at every group (the same groups as a
/// scan of every group in order: the lowest matching group of the cells searched).
#[derive(Default)]
struct SamePose {
    /// Each group's first member.
    firsts: Vec<crate::robot::Joints>,
    /// Per cell, the groups whose first member lies in it, in order.
    cells: HashMap<[i64; JOINTS], Vec<usize>>,
}

impl SamePose {
    /// Cell size per joint, rad: sixteen times the reach, so that the interval within reach of a
    /// joint value spans one cell, or two near a cell's edge.
    const CELL: f64 = 16.0 * SAME_POSE_RAD;

    fn cell(v: f64) -> i64 {
        (v / Self::CELL).floor() as i64
    }

    /// The group of `q` (opened when no group is within reach).
    fn group(&mut self, q: &crate::robot::Joints) -> usize {
        // The cells of each joint within reach, widened by 1 % of the reach: a value within
        // SAME_POSE_RAD as the comparison below rounds it is inside, whatever the division rounds.
        let reach = 1.01 * SAME_POSE_RAD;
        let spans: [(i64, i64); JOINTS] = std::array::from_fn(|j| (Self::cell(q[j] - reach), Self::cell(q[j] + reach)));
        let mut best: Option<usize> = None;
        let mut key = [0i64; JOINTS];
        let mut visit = |key: &[i64; JOINTS]| {
            for &g in self.cells.get(key).into_iter().flatten() {
                if best.is_some_and(|b| b <= g) {
                    break;
                }
                if self.firsts[g].iter().zip(q).all(|(a, b)| (a - b).abs() <= SAME_POSE_RAD) {
                    best = Some(g);
                    break;
                }
            }
        };
        // Every combination of the joints' cells (1 to 2^6).
        let combos = spans.iter().map(|(lo, hi)| (hi - lo + 1) as usize).product::<usize>();
        for mut c in 0..combos {
            for j in 0..JOINTS {
                let width = (spans[j].1 - spans[j].0 + 1) as usize;
                key[j] = spans[j].0 + (c % width) as i64;
                c /= width;
            }
            visit(&key);
        }
        best.unwrap_or_else(|| {
            let g = self.firsts.len();
            self.firsts.push(*q);
            self.cells.entry(std::array::from_fn(|j| Self::cell(q[j]))).or_default().push(g);
            g
        })
    }
}

/// The share of a per-pose joint error's variance that the training fit leaves in its residual,
/// over the share it leaves of white noise (`dof / rows`): `(tr S - tr H S) / tr S` against
/// `dof / rows`, with `S` the covariance over the training rows of a unit independent error per
/// joint and per pose (block `L_p L_p^T` over the rows of every visit of pose `p`, `L` the weighted link-angle
/// Jacobian `jl`) and `H` the hat matrix of the model's columns and the kept effects' (projected
/// off the model). 1 when the fit absorbs the field as it absorbs white noise.
fn field_share(jl: &DMatrix<f64>, pose_of_point: &[usize], model: &Lsq, kept_projected: &DMatrix<f64>, dof: f64) -> f64 {
    let poses = pose_of_point.iter().copied().max().map_or(0, |p| p + 1);
    let mut rows_of: Vec<Vec<usize>> = vec![Vec::new(); poses];
    for (point, &p) in pose_of_point.iter().enumerate() {
        rows_of[p].extend([3 * point, 3 * point + 1, 3 * point + 2]);
    }
    // Each pose's block on its own: runs of poses side by side, written in order.
    let apply = |x: &DMatrix<f64>| -> DMatrix<f64> {
        let mut out = DMatrix::zeros(x.nrows(), x.ncols());
        for run in rows_of.chunks(GRAM_PIECE) {
            let blocks: Vec<DMatrix<f64>> = run
                .par_iter()
                .map(|rows| {
                    let l = jl.select_rows(rows);
                    &l * (l.tr_mul(&x.select_rows(rows)))
                })
                .collect();
            for (rows, y) in run.iter().zip(&blocks) {
                for (k, &r) in rows.iter().enumerate() {
                    out.row_mut(r).copy_from(&y.row(k));
                }
            }
        }
        out
    };
    let total = jl.norm_squared();
    let rows = jl.nrows() as f64;
    if total <= 0.0 || dof <= 0.0 || rows == 0.0 {
        return 1.0;
    }
    // The model's share and the kept effects' side by side.
    let (model_share, kept_share) = rayon::join(
        || model.coef(&apply(&model.a)).trace(),
        || {
            (kept_projected.ncols() > 0).then(|| {
                let e = Lsq::new(kept_projected.clone());
                e.coef(&apply(&e.a)).trace()
            })
        },
    );
    let mut absorbed = model_share;
    if let Some(share) = kept_share {
        absorbed += share;
    }
    let share = ((total - absorbed) / total) / (dof / rows);
    if share.is_finite() && share > 0.0 { share } else { 1.0 }
}

/// The `[learned]` table: the kept effects, the repeatability (RP from its level per coordinate),
/// the per-pose joint error the systematic part leaves and the standard deviation of its level
/// (`jl_mm`: the link-angle Jacobian over the training points, mm per rad; `field`: the fit's
/// share of a per-pose joint error, [`field_share`]).
fn learned_table(
    c: &Calibration,
    d: &Decomposition,
    effects: &[Effect],
    jl_mm: &DMatrix<f64>,
    points: usize,
    field: f64,
) -> LearnedEffects {
    let mut l = LearnedEffects {
        source: Some(format!(
            "calsim calibrate of {} ({} model, calibration split: {points} points)",
            c.measurements.path.display(),
            c.chosen().name()
        )),
        ..LearnedEffects::default()
    };
    let mut harmonics: std::collections::BTreeMap<(usize, usize), (f64, f64, f64, f64)> = std::collections::BTreeMap::new();
    for e in effects {
        let co = &e.coefficient;
        match (co.family, co.joint, co.harmonic, co.axis) {
            (Family::Harmonics(_) | Family::Harmonic(..), Some(j), Some((order, sine)), _) => {
                let h = harmonics.entry((j, order)).or_insert((0.0, 0.0, 0.0, 0.0));
                if sine {
                    (h.0, h.2) = (e.value, e.std);
                } else {
                    (h.1, h.3) = (e.value, e.std);
                }
            }
            (Family::Backlash, Some(j), _, _) => {
                // A width below zero is none: the table's widths are physical.
                l.backlash_mdeg[j] = e.value.max(0.0);
                l.backlash_std_mdeg[j] = e.std;
            }
            (Family::Sag, Some(j), _, _) => {
                l.sag_mdeg_per_m[j] = e.value;
                l.sag_std_mdeg_per_m[j] = e.std;
            }
            (Family::Drift, _, _, Some(a)) => {
                l.drift_mm_per_pose[a] = e.value;
                l.drift_std_mm_per_pose[a] = e.std;
            }
            _ => {}
        }
    }
    l.harmonic = harmonics
        .into_iter()
        .map(|((j, order), (s, co, ss, cs))| LearnedHarmonic {
            joint: j + 1,
            order: order as f64,
            sin_mdeg: s,
            cos_mdeg: co,
            std_mdeg: ((ss * ss + cs * cs) / 2.0).sqrt(),
        })
        .collect();
    // Repeatability: the estimate, else instrument and repeatability together (the plan then
    // draws no separate instrument noise).
    let rep = d.repeatability.as_ref().or(d.together.as_ref());
    l.repeatability_mm = rep.map_or(0.0, |r| RP_PER_SIGMA * r.sigma_mm);
    // Its standard deviation as the per-pose error's below: the 95 % interval's width over
    // 2 x 1.96 (a plan draws the level per world from it).
    l.repeatability_std_mm = rep.map_or(0.0, |r| RP_PER_SIGMA * (r.interval_mm[1] - r.interval_mm[0]).max(0.0) / (2.0 * Z95));
    // The systematic part left, as a per-pose joint error: per coordinate, an independent error of
    // RMS s per joint moves a point by s^2 |J|_F^2 / 3 on average.
    // Nothing random estimated: all the residual left after the effects is taken as per-pose error.
    // Its level's standard deviation: the 95 % interval's width over 2 x 1.96 (a plan draws the
    // level per world from it).
    let (left_var, left_interval) = match (&d.left, &d.instrument, &d.together) {
        (Some(left), _, _) => (left.var(), left.interval_mm),
        (None, None, None) => (d.after.var() / field, d.after.scaled(1.0 / field, String::new()).interval_mm),
        _ => (0.0, [0.0; 2]),
    };
    let mean_jf2 = jl_mm.iter().map(|v| v * v).sum::<f64>() / (jl_mm.nrows() / 3).max(1) as f64;
    if mean_jf2 > 0.0 {
        if left_var > 0.0 {
            l.pose_error_mdeg = (3.0 * left_var / mean_jf2).sqrt().to_degrees() * 1e3;
        }
        // mdeg per mm of the level per coordinate.
        let per_mm = (3.0 / mean_jf2).sqrt().to_degrees() * 1e3;
        l.pose_error_std_mdeg = per_mm * (left_interval[1] - left_interval[0]).max(0.0) / (2.0 * Z95);
    }
    l
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The visits of one pose: the groups of a scan of every group in order (the first whose first
    /// member is within reach at every joint), near the cells' edges and in a sweep of one joint.
    #[test]
    fn same_pose_groups_are_those_of_a_scan_in_order() {
        use rand::RngExt;
        let mut rng = crate::seeds::stream(7, 0);
        let mut qs: Vec<crate::robot::Joints> = Vec::new();
        for k in 0..3000 {
            let q: crate::robot::Joints = match k % 4 {
                // Random poses, revisited within and beyond the reach.
                0 => std::array::from_fn(|_| rng.random_range(-0.01..0.01)),
                1 => {
                    let mut q = qs[rng.random_range(0..qs.len())];
                    q[rng.random_range(0..JOINTS)] += rng.random_range(-2.0..2.0) * SAME_POSE_RAD;
                    q
                }
                // A sweep of one joint in steps of about the reach, on cell edges.
                2 => {
                    let mut q = [0.0; JOINTS];
                    q[1] = (k / 4) as f64 * SAME_POSE_RAD * 0.999;
                    q[2] = SamePose::CELL * (k % 7) as f64;
                    q
                }
                _ => std::array::from_fn(|j| SamePose::CELL * ((k + j) % 3) as f64 + rng.random_range(-1.5..1.5) * SAME_POSE_RAD),
            };
            qs.push(q);
        }
        let mut firsts: Vec<crate::robot::Joints> = Vec::new();
        let scanned: Vec<usize> = qs
            .iter()
            .map(|q| {
                firsts.iter().position(|v| v.iter().zip(q).all(|(a, b)| (a - b).abs() <= SAME_POSE_RAD)).unwrap_or_else(|| {
                    firsts.push(*q);
                    firsts.len() - 1
                })
            })
            .collect();
        let mut index = SamePose::default();
        let found: Vec<usize> = qs.iter().map(|q| index.group(q)).collect();
        assert_eq!(found, scanned);
        assert!(firsts.len() > 100 && firsts.len() < qs.len() - 100, "groups: {}", firsts.len());
    }

    /// The twin of a calibration with what the calibration kept (its setup and the chosen model's
    /// training fit) is the twin computed afresh: the shipped example, its flagged points left out
    /// of the fits (`--outliers reject`), as the twin leaves them out.
    #[test]
    fn the_twin_with_the_calibrations_setup_and_fit_is_the_twin_afresh() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let robot = crate::robot::file::RobotFile::load(&root.join("robots/irb120.toml")).unwrap();
        let m = crate::calibrate::measurements::read(&root.join("docs/calibrate/example_measurements.csv"), &robot).unwrap();
        let opts = crate::calibrate::Options { plots: false, outliers: crate::calibrate::OutlierMode::Reject, ..Default::default() };
        let (c, kept) = crate::calibrate::run_keeping(&robot, &m, &opts).unwrap();
        assert!(kept.setup.is_some());
        assert!(c.flagged.iter().any(|f| *f), "flagged points to leave out");
        // The training fit is taken (its points are the twin's).
        let train: Vec<usize> =
            (0..m.points.len()).filter(|&i| !c.assignment.held_out[c.measurements.points[i].pose] && !c.flagged[i]).collect();
        assert_eq!(kept.train_fit.as_ref().map(|t| &t.0), Some(&train));
        let with = analyse_with(&c, None, Some(&kept)).unwrap();
        let afresh = analyse(&c, None).unwrap();
        assert_eq!(format!("{with:?}"), format!("{afresh:?}"));
    }

    /// The product of selected columns by a vector, without copying them, is nalgebra's product of
    /// the copied columns bit for bit (1 to 9 columns in any order, 40 rows, signed zeros and an
    /// infinity among the entries).
    #[test]
    fn selected_columns_times_a_vector_is_nalgebras_product() {
        use rand::RngExt;
        let mut rng = crate::seeds::stream(17, 0);
        let mut m = DMatrix::from_fn(40, 12, |_, _| rng.random_range(-1.0..1.0));
        m[(3, 2)] = -0.0;
        m[(4, 5)] = 0.0;
        m[(7, 9)] = f64::INFINITY;
        for cols in [vec![4], vec![2, 0], vec![11, 3, 5, 7, 1, 0, 9], vec![0, 1, 2, 3, 4, 5, 6, 8, 10]] {
            let a = DMatrix::from_fn(cols.len(), 1, |_, _| rng.random_range(-2.0..2.0));
            let want = m.select_columns(&cols) * &a;
            let got = columns_times(&m, &cols, a.as_slice());
            assert!(want.iter().zip(got.iter()).all(|(x, y)| x.to_bits() == y.to_bits()), "{cols:?}: {want} {got}");
        }
    }

    /// A family with no rows (no training point where it acts) or no columns has an empty basis:
    /// it is confounded with nothing, and no decomposition of an empty matrix is attempted.
    #[test]
    fn an_empty_matrix_has_an_empty_basis_confounded_with_nothing() {
        for (rows, cols) in [(0, 3), (4, 0), (0, 0)] {
            let b = column_basis(&DMatrix::zeros(rows, cols));
            assert_eq!((b.nrows(), b.ncols()), (rows, 0));
        }
        let full = column_basis(&DMatrix::from_row_slice(3, 2, &[1.0, 0.0, 0.0, 1.0, 0.0, 0.0]));
        assert_eq!(full.ncols(), 2);
        assert_eq!(principal_cos(&column_basis(&DMatrix::zeros(0, 2)), &full), 0.0);
    }
}
