//! The shape of the error left: how the residual after the kept effects on the calibration split
//! is correlated between points as a function of their poses' distance in joint space.
//!
//! ```text
//! per pair of training points (outliers left out) at two poses, the dot product of their
//! residuals (weighted by the points' uncertainties, after the model and the kept effects)
//!  ─► pairs binned: the other targets of one pose (distance 0), then the pairs of distinct poses
//!     by the rank of their joint-space distance (Euclidean over the six joint values, rad):
//!     the nearest 1 %, 1-5 %, 5-25 %, the farthest 75 %
//!  ─► per bin, the correlation: the mean product over the mean squared residual of a point;
//!     its 95 % interval by the delete-one jackknife over poses (every pair a pose is in left
//!     out with it); beside it, the value the fit itself gives white residuals (the residual
//!     is (I - H) e: for white e, E[r_i . r_j] = -sigma^2 tr H_ij, H the hat matrix of the
//!     model's and the kept effects' columns)
//! ```
//!
//! A per-pose error independent between poses shares its value among the targets of a pose (the
//! distance-0 bin) and nothing between poses: the bins of distinct poses hold the fit's own value.
//! A smooth error field (correlated between nearby poses) lifts the nearest bins above it.

use nalgebra::{DMatrix, DVector};

/// The bins of distinct poses: upper edges of the rank of their distance, as a fraction of the
/// pairs of distinct poses (each bin from the previous edge).
pub const DISTANCE_BINS: [f64; 4] = [0.01, 0.05, 0.25, 1.0];
/// The most poses whose pairs are binned: the pairs of distinct poses grow as the square of their
/// count (70,000 poses would be 2.4e9 pairs); above it, every k-th pose (the least k that leaves at
/// most this many) and its points.
pub const MAX_POSES: usize = 3000;
/// The most pairs of poses per bin [`length_scale`] predicts the correlation over.
pub const PAIR_SAMPLE: usize = 4000;
/// Random Fourier features of the unit field [`length_scale`] predicts with (shared by the joints).
pub const LENGTH_FEATURES: usize = 48;
/// The two-sided 95 % normal quantile.
const Z95: f64 = 1.959_963_984_540_054;

/// One bin of pairs.
#[derive(Clone, Debug, PartialEq)]
pub struct CorrelationBin {
    /// What the bin holds.
    pub label: String,
    /// The other targets at one pose (distance 0), not pairs of distinct poses.
    pub same_pose: bool,
    /// The joint-space distances of its pairs, rad (least and greatest).
    pub distance_rad: [f64; 2],
    /// Pairs of points in it.
    pub pairs: usize,
    /// Pairs of poses in it (for the distance-0 bin: the poses with two targets or more).
    pub pose_pairs: usize,
    /// The correlation of the residuals of its pairs: the mean product over the mean squared
    /// residual of a point.
    pub correlation: f64,
    /// Its 95 % interval (delete-one jackknife over poses; `NaN` when too few poses).
    pub interval: [f64; 2],
    /// The value the fit gives white residuals (the hat matrix's share).
    pub white: f64,
    /// Its pairs of distinct poses (indices as the binned poses'): every k-th (k the least that
    /// leaves at most [`PAIR_SAMPLE`]), for [`length_scale`]; empty for the distance-0 bin.
    pub pair_sample: Vec<(u32, u32)>,
}

impl CorrelationBin {
    /// Above the fit's own value for white residuals: the interval's lower end above it.
    pub fn above_white(&self) -> bool {
        self.interval[0] > self.white
    }
}

/// The residual's correlation by joint-space distance (the first bin: the other targets at one
/// pose, when any pose has two).
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Correlation {
    /// The bins, the distance-0 bin first (when there is one).
    pub bins: Vec<CorrelationBin>,
    /// Poses of the training points.
    pub poses: usize,
    /// The mean squared residual of a point (the correlations' denominator).
    pub mean_sq: f64,
}

/// The correlation of `resid` (3 rows per training point, weighted) between points by the
/// distance of their poses: `pose_of[i]` the pose of training point `i` (0-based, dense), `q[p]`
/// the joint values of pose `p` (rad), `hat_basis` an orthonormal basis (rows as `resid`) of the
/// columns the fit absorbed (the model's and the kept effects').
/// Above [`MAX_POSES`] poses, every k-th pose's points (k the least that leaves at most that many,
/// [`Subset`]).
pub fn correlation(resid: &DVector<f64>, pose_of: &[usize], q: &[crate::robot::Joints], hat_basis: &DMatrix<f64>) -> Correlation {
    match Subset::of(pose_of, q) {
        None => correlation_of(resid, pose_of, q, hat_basis),
        Some(s) => correlation_of(&resid.select_rows(&s.rows), &s.pose_of, &s.q, &hat_basis.select_rows(&s.rows)),
    }
}

/// The points [`correlation`] bins when there are more than [`MAX_POSES`] poses: those of every
/// k-th pose, k the least that leaves at most that many.
pub struct Subset {
    /// The rows of the kept points (three per point), in order.
    pub rows: Vec<usize>,
    /// The kept points' poses, renumbered densely.
    pub pose_of: Vec<usize>,
    /// The kept poses' joint values.
    pub q: Vec<crate::robot::Joints>,
}

impl Subset {
    /// `None`: every pose is binned.
    pub fn of(pose_of: &[usize], q: &[crate::robot::Joints]) -> Option<Subset> {
        let stride = q.len().div_ceil(MAX_POSES).max(1);
        if stride == 1 {
            return None;
        }
        let kept: Vec<usize> = (0..pose_of.len()).filter(|&i| pose_of[i].is_multiple_of(stride)).collect();
        Some(Subset {
            rows: kept.iter().flat_map(|&i| [3 * i, 3 * i + 1, 3 * i + 2]).collect(),
            pose_of: kept.iter().map(|&i| pose_of[i] / stride).collect(),
            q: q.iter().step_by(stride).copied().collect(),
        })
    }
}

fn correlation_of(resid: &DVector<f64>, pose_of: &[usize], q: &[crate::robot::Joints], hat_basis: &DMatrix<f64>) -> Correlation {
    correlation_binned(resid, pose_of, q, hat_basis).0
}

/// [`correlation`] of every point given (no subset), and its binning for [`length_scale`]
/// (`None` when no pair was binned: fewer than two poses, or no point).
pub(crate) fn correlation_binned(
    resid: &DVector<f64>,
    pose_of: &[usize],
    q: &[crate::robot::Joints],
    hat_basis: &DMatrix<f64>,
) -> (Correlation, Option<Binning>) {
    let poses = q.len();
    if pose_of.is_empty() || poses < 2 || resid.len() != 3 * pose_of.len() {
        return (Correlation { bins: Vec::new(), poses, mean_sq: 0.0 }, None);
    }
    let binning = Binning::of(pose_of, q);
    let (traces, white_sq) = binning.traces(hat_basis);
    (binning.correlation(resid, &traces, white_sq), Some(binning))
}

/// The pairs [`correlation`] bins, which depend only on the poses: the points per pose, the pairs
/// of distinct poses sorted by distance and each bin's share of them.
pub(crate) struct Binning {
    pose_of: Vec<usize>,
    count: Vec<usize>,
    /// The pairs of distinct poses, by distance (ties by the poses' numbers).
    pairs: Vec<(f64, u32, u32)>,
    bins: Vec<BinPairs>,
}

/// One bin of a [`Binning`].
struct BinPairs {
    label: String,
    same_pose: bool,
    range: [f64; 2],
    /// Its pairs of distinct poses in [`Binning::pairs`] (empty for the distance-0 bin).
    span: std::ops::Range<usize>,
    pairs: usize,
    pose_pairs: usize,
    /// Per pose, the pairs of points it is in.
    per_pose: Vec<usize>,
    sample: Vec<(u32, u32)>,
    /// The farthest bin of distinct poses (three quarters of the pairs): its sums are those of
    /// every pair of distinct poses, which the poses' own sums give (`sum_{p<s} x_p . x_s =
    /// sum_p x_p . (X - x_p) / 2`, `X` the sum of every pose's), less the nearer bins', instead of
    /// a pass over its pairs.
    complement: bool,
}

impl Binning {
    /// The binning of the points of poses `pose_of` (at least two poses in `q`).
    pub(crate) fn of(pose_of: &[usize], q: &[crate::robot::Joints]) -> Binning {
        use rayon::prelude::*;
        let poses = q.len();
        let mut count = vec![0usize; poses];
        for &p in pose_of {
            count[p] += 1;
        }
        let new_bin = |label: String, same_pose: bool, span: std::ops::Range<usize>| BinPairs {
            label,
            same_pose,
            range: [f64::INFINITY, f64::NEG_INFINITY],
            span,
            pairs: 0,
            pose_pairs: 0,
            per_pose: vec![0; poses],
            sample: Vec::new(),
            complement: false,
        };
        let mut bins = Vec::new();
        // The other targets at one pose.
        if count.iter().any(|&c| c >= 2) {
            let mut b = new_bin("other targets at one pose".into(), true, 0..0);
            for p in (0..poses).filter(|&p| count[p] >= 2) {
                let pairs = count[p] * (count[p] - 1) / 2;
                b.pairs += pairs;
                b.pose_pairs += 1;
                b.per_pose[p] = pairs;
                b.range = [0.0, 0.0];
            }
            bins.push(b);
        }
        // Distinct poses, by the rank of their distance (each pose's pairs side by side).
        let pairs_of = |p: usize| {
            (p + 1..poses).map(move |s| (q[p].iter().zip(&q[s]).map(|(a, b)| (a - b).powi(2)).sum::<f64>().sqrt(), p as u32, s as u32))
        };
        let mut pairs: Vec<(f64, u32, u32)> = (0..poses).into_par_iter().flat_map_iter(pairs_of).collect();
        // The order is total and every pair is there once (ties by the poses' numbers): any sort,
        // stable or not, serial or parallel, gives this one.
        pairs.par_sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
        let total = pairs.len();
        let mut from = 0usize;
        let mut low = 0.0;
        for &edge in &DISTANCE_BINS {
            let to = ((edge * total as f64).round() as usize).clamp(from, total);
            if to == from {
                continue;
            }
            let label = format!("distinct poses, nearest {:.0}-{:.0} % of pairs", 100.0 * low, 100.0 * edge);
            low = edge;
            let mut b = new_bin(label, false, from..to);
            let stride = (to - from).div_ceil(PAIR_SAMPLE).max(1);
            b.sample = pairs[from..to].iter().step_by(stride).map(|&(_, p, s)| (p, s)).collect();
            for &(d, p, s) in &pairs[from..to] {
                let n_pairs = count[p as usize] * count[s as usize];
                b.pairs += n_pairs;
                b.pose_pairs += 1;
                b.per_pose[p as usize] += n_pairs;
                b.per_pose[s as usize] += n_pairs;
                b.range = [b.range[0].min(d), b.range[1].max(d)];
            }
            bins.push(b);
            from = to;
        }
        if let Some(last) = bins.last_mut().filter(|b| !b.same_pose) {
            last.complement = true;
        }
        Binning { pose_of: pose_of.to_vec(), count, pairs, bins }
    }

    /// The bin whose sums are every pair's less the other bins of distinct poses'.
    fn complement(&self) -> Option<usize> {
        self.bins.iter().position(|b| b.complement)
    }

    /// Every bin's sums over its pairs (none taken as the complement): the reference the
    /// complement's sums are checked against.
    #[cfg(test)]
    fn without_complement(mut self) -> Self {
        for b in &mut self.bins {
            b.complement = false;
        }
        self
    }

    /// Per bin, the sum of tr H_ij over its pairs of points (`hat_basis` an orthonormal basis of
    /// the fit's columns, 3 rows per point), and the mean over points of `3 - tr H_ii` (the mean
    /// squared residual of a point per unit variance of white residuals).
    fn traces(&self, hat_basis: &DMatrix<f64>) -> (Vec<f64>, f64) {
        use rayon::prelude::*;
        let (poses, k, n) = (self.count.len(), hat_basis.ncols(), self.pose_of.len());
        // Per pose: the sum of its rows of the hat basis (3 x k) and of tr H_ii.
        let mut q_sum = vec![0.0f64; poses * 3 * k];
        let mut h_ii = vec![0.0f64; poses];
        for (i, &p) in self.pose_of.iter().enumerate() {
            for a in 0..3 {
                for c in 0..k {
                    let h = hat_basis[(3 * i + a, c)];
                    q_sum[(p * 3 + a) * k + c] += h;
                    h_ii[p] += h * h;
                }
            }
        }
        let white_sq = (3.0 * n as f64 - h_ii.iter().sum::<f64>()) / n as f64;
        // Rows of `q_sum` per pose, four pairs of them at a time.
        let dots = |pairs: &[(f64, u32, u32)]| row_dots(&q_sum, 3 * k, pairs.iter().map(|&(_, p, s)| (p as usize, s as usize)));
        let mut traces: Vec<f64> = self
            .bins
            .iter()
            .map(|b| {
                let mut trace = 0.0;
                if b.complement {
                    // Below, from the others.
                } else if b.same_pose {
                    let repeated: Vec<usize> = (0..poses).filter(|&p| self.count[p] >= 2).collect();
                    for (&p, square) in repeated.iter().zip(row_dots(&q_sum, 3 * k, repeated.iter().map(|&p| (p, p)))) {
                        trace += 0.5 * (square - h_ii[p]);
                    }
                } else {
                    // The pairs' tr H_ij side by side, summed in the pairs' order.
                    let terms: Vec<f64> = self.pairs[b.span.clone()].par_chunks(DOT_CHUNK).flat_map_iter(dots).collect();
                    for t in terms {
                        trace += t;
                    }
                }
                trace
            })
            .collect();
        if let Some(c) = self.complement() {
            // Every pair of distinct poses: half the sum over poses of its row times the sum of
            // the other poses' rows (no column: no row, nothing summed).
            let width = (3 * k).max(1);
            let mut total = vec![0.0f64; width];
            for row in q_sum.chunks_exact(width) {
                for (t, v) in total.iter_mut().zip(row) {
                    *t += v;
                }
            }
            let mut every = 0.0;
            for row in q_sum.chunks_exact(width) {
                every += row.iter().zip(&total).map(|(v, t)| v * (t - v)).sum::<f64>();
            }
            let mut trace = 0.5 * every;
            for (b, t) in self.bins.iter().zip(&traces) {
                if !b.same_pose && !b.complement {
                    trace -= t;
                }
            }
            traces[c] = trace;
        }
        (traces, white_sq)
    }

    /// The correlation of `resid` (3 rows per point) over the bins, `traces` and `white_sq` those
    /// of [`Binning::traces`].
    fn correlation(&self, resid: &DVector<f64>, traces: &[f64], white_sq: f64) -> Correlation {
        self.correlations(&[resid], traces, white_sq).pop().expect("one residual")
    }

    /// [`Binning::correlation`] of each of `resids` (at most [`LANES`]), each the numbers it has
    /// alone: every bin's pairs read once for all of them, their sums per pose side by side in
    /// lanes (one per residual; the sums of a lane in the order of one residual alone, the first
    /// term added to -0.0 as `Iterator::sum` does).
    fn correlations(&self, resids: &[&DVector<f64>], traces: &[f64], white_sq: f64) -> Vec<Correlation> {
        let (poses, n, m) = (self.count.len(), self.pose_of.len(), resids.len());
        assert!(m <= LANES, "at most {LANES} residuals binned together");
        // Per pose, coordinate and residual: the sum of its points' residuals (`r_sum`) and of
        // their squared residuals (`sq`, a residual's together).
        let mut r_sum = vec![[[0.0f64; LANES]; 3]; poses];
        let mut sq = vec![vec![0.0f64; poses]; m];
        for (k, resid) in resids.iter().enumerate() {
            for (i, &p) in self.pose_of.iter().enumerate() {
                for a in 0..3 {
                    let v = resid[3 * i + a];
                    r_sum[p][a][k] += v;
                    sq[k][p] += v * v;
                }
            }
        }
        let total_sq: Vec<f64> = sq.iter().map(|s| s.iter().sum::<f64>()).collect();
        // Per bin and residual, the bin's sum of products, and per pose the same over the pairs
        // it is in.
        let mut sums: Vec<([f64; LANES], Vec<[f64; LANES]>)> = self
            .bins
            .iter()
            .map(|b| {
                let mut product = [0.0f64; LANES];
                let mut per_pose = vec![[0.0f64; LANES]; poses];
                if b.complement {
                    // Below, from the others.
                } else if b.same_pose {
                    for p in (0..poses).filter(|&p| self.count[p] >= 2) {
                        for k in 0..m {
                            let square = ((-0.0 + r_sum[p][0][k] * r_sum[p][0][k]) + r_sum[p][1][k] * r_sum[p][1][k])
                                + r_sum[p][2][k] * r_sum[p][2][k];
                            let s = 0.5 * (square - sq[k][p]);
                            product[k] += s;
                            per_pose[p][k] = s;
                        }
                    }
                } else {
                    for &(_, p, s) in &self.pairs[b.span.clone()] {
                        let (p, s) = (p as usize, s as usize);
                        let (rp, rs) = (&r_sum[p], &r_sum[s]);
                        let mut prod = [-0.0f64; LANES];
                        for a in 0..3 {
                            for k in 0..LANES {
                                prod[k] += rp[a][k] * rs[a][k];
                            }
                        }
                        for k in 0..LANES {
                            product[k] += prod[k];
                            per_pose[p][k] += prod[k];
                            per_pose[s][k] += prod[k];
                        }
                    }
                }
                (product, per_pose)
            })
            .collect();
        if let Some(c) = self.complement() {
            // Every pair of distinct poses, per pose: its sums times the sum of the other poses'
            // (the pairs it is in); their half sum over the poses is every pair's. Less the other
            // bins of distinct poses. Each residual (lane) on its own numbers.
            let mut total = [[0.0f64; LANES]; 3];
            for rp in &r_sum {
                for a in 0..3 {
                    for k in 0..LANES {
                        total[a][k] += rp[a][k];
                    }
                }
            }
            let mut product = [0.0f64; LANES];
            let mut per_pose = vec![[0.0f64; LANES]; poses];
            for (rp, out) in r_sum.iter().zip(per_pose.iter_mut()) {
                for k in 0..LANES {
                    let v =
                        (rp[0][k] * (total[0][k] - rp[0][k]) + rp[1][k] * (total[1][k] - rp[1][k])) + rp[2][k] * (total[2][k] - rp[2][k]);
                    out[k] = v;
                    product[k] += v;
                }
            }
            for v in &mut product {
                *v *= 0.5;
            }
            for (b, (other, other_per_pose)) in self.bins.iter().zip(&sums) {
                if b.same_pose || b.complement {
                    continue;
                }
                for k in 0..LANES {
                    product[k] -= other[k];
                }
                for (out, o) in per_pose.iter_mut().zip(other_per_pose) {
                    for k in 0..LANES {
                        out[k] -= o[k];
                    }
                }
            }
            sums[c] = (product, per_pose);
        }
        (0..m)
            .map(|k| {
                let (sq, total_sq) = (&sq[k], total_sq[k]);
                let mean_sq = sq.iter().sum::<f64>() / n as f64;
                let bins = self
                    .bins
                    .iter()
                    .zip(traces)
                    .zip(&sums)
                    .map(|((b, &trace), (product, per_pose))| {
                        let product = product[k];
                        let correlation = product / b.pairs as f64 / mean_sq;
                        // Delete-one jackknife over the poses with points.
                        let left_out: Vec<f64> = (0..poses)
                            .filter(|&p| self.count[p] > 0 && b.pairs > b.per_pose[p] && n > self.count[p])
                            .map(|p| {
                                ((product - per_pose[p][k]) / (b.pairs - b.per_pose[p]) as f64)
                                    / ((total_sq - sq[p]) / (n - self.count[p]) as f64)
                            })
                            .collect();
                        let g = left_out.len() as f64;
                        let interval = if left_out.len() >= 2 {
                            let mean = left_out.iter().sum::<f64>() / g;
                            let var = (g - 1.0) / g * left_out.iter().map(|v| (v - mean).powi(2)).sum::<f64>();
                            let h = Z95 * var.sqrt();
                            [correlation - h, correlation + h]
                        } else {
                            [f64::NAN; 2]
                        };
                        CorrelationBin {
                            same_pose: b.same_pose,
                            label: b.label.clone(),
                            distance_rad: b.range,
                            pairs: b.pairs,
                            pose_pairs: b.pose_pairs,
                            correlation,
                            interval,
                            white: -(trace / b.pairs as f64) / white_sq,
                            pair_sample: b.sample.clone(),
                        }
                    })
                    .collect();
                Correlation { bins, poses, mean_sq }
            })
            .collect()
    }
}

/// Residuals [`Binning::correlations`] bins together.
const LANES: usize = 8;

/// Pairs of poses per piece of [`Binning::traces`]' parallel sums.
const DOT_CHUNK: usize = 4096;

/// Per pair `(p, s)` of `pairs`, the dot product of rows `p` and `s` of `rows` (row-major, `width`
/// wide), each summed in the order of its entries from -0.0 (as `Iterator::sum`): four pairs side
/// by side, independent sums that the processor overlaps, the same numbers as one at a time.
fn row_dots(rows: &[f64], width: usize, pairs: impl Iterator<Item = (usize, usize)>) -> Vec<f64> {
    let pairs: Vec<(usize, usize)> = pairs.collect();
    let row = |i: usize| &rows[i * width..(i + 1) * width];
    let mut out = Vec::with_capacity(pairs.len());
    for four in pairs.chunks(4) {
        // A short last group repeats its first pair (its extra sums are not kept).
        let pick = |l: usize| if l < four.len() { four[l] } else { four[0] };
        let a: [&[f64]; 4] = std::array::from_fn(|l| row(pick(l).0));
        let b: [&[f64]; 4] = std::array::from_fn(|l| row(pick(l).1));
        let mut acc = [-0.0f64; 4];
        for c in 0..width {
            for l in 0..4 {
                acc[l] += a[l][c] * b[l][c];
            }
        }
        out.extend_from_slice(&acc[..four.len()]);
    }
    out
}

/// The correlation length of a smooth error, fitted to the bins of distinct poses.
#[derive(Clone, Debug, PartialEq)]
pub struct LengthScale {
    /// The length `l` of the kernel `exp(-d^2 / (2 l^2))`, rad.
    pub length_rad: f64,
    /// Its 95 % interval (the parametric bootstrap's basic interval in log length), rad.
    pub interval: [f64; 2],
    /// The field's RMS per joint before the fit, rad, and the width of its interval over 2 x 1.96.
    pub level_rad: [f64; 2],
    /// The level's 95 % interval (the bootstrap's percentile interval), rad.
    pub level_interval_rad: [f64; 2],
    /// The bootstrap's basic intervals in log scale (`[v^2 / q97.5, v^2 / q2.5]`, `q` the
    /// replicates' quantiles) of the length and of the level, rad.
    pub basic: [[f64; 2]; 2],
    /// The bootstrap's percentile intervals (`[q2.5, q97.5]`) of the length and of the level, rad.
    pub percentile: [[f64; 2]; 2],
    /// The bootstrap's replicates fitted.
    pub replicates: usize,
    /// Replicates whose best length is the grid's least and its greatest (counted there).
    pub censored: [usize; 2],
}

/// The replicates of [`length_scale`]'s parametric bootstrap.
pub const BOOTSTRAP_REPLICATES: usize = 100;

/// The cosines per joint of a bootstrap replicate's field (a world's field has
/// `robot::learned::FIELD_FEATURES`): the field at a pose costs a cosine per feature and joint,
/// the replicates' whole cost at 3,000 poses; a replicate's covariance departs from the kernel's by
/// about 1 / 8, which widens the intervals a little (docs/generated/twin-length-coverage.md
/// measures their coverage).
pub const BOOTSTRAP_FEATURES: usize = 64;

/// The grid of lengths [`length_scale`] profiles, rad: log-spaced from 0.02 to 20, 10 a decade.
fn length_grid() -> Vec<f64> {
    (0..=30).map(|k| 0.02 * 10f64.powf(k as f64 / 10.0)).collect()
}

/// The random Fourier features of the unit field [`predicted`] uses: per feature, a frequency per
/// joint value (standard normal, divided by the length) and a phase.
type Features = Vec<([f64; crate::robot::JOINTS], f64)>;

fn features() -> Features {
    use rand::RngExt;
    let mut rng = crate::seeds::fixed_stream(crate::seeds::fixed::SMOOTH_FIELD);
    (0..LENGTH_FEATURES)
        .map(|_| {
            let w = std::array::from_fn(|_| rng.sample::<f64, _>(rand_distr::StandardNormal));
            (w, rng.random::<f64>() * std::f64::consts::TAU)
        })
        .collect()
}

/// The features' values at each pose for length `l` (poses x features), scaled to unit variance.
fn feature_values(features: &Features, q: &[crate::robot::Joints], l: f64) -> DMatrix<f64> {
    let amp = (2.0 / features.len() as f64).sqrt();
    DMatrix::from_fn(q.len(), features.len(), |p, k| {
        let (w, b) = &features[k];
        amp * (w.iter().zip(&q[p]).map(|(a, x)| a * x).sum::<f64>() / l + b).cos()
    })
}

/// What [`predicted`] needs of the points that does not depend on the length, summed per pose
/// (`L` the weighted link-angle Jacobian, a row per coordinate of a point, `B` the fit's
/// orthonormal basis over the same rows): so that the field's values at the points (a row
/// `L_r (x) phi_p` per row of pose `p`) and their projection off `B` are never formed.
struct PoseSums {
    /// Points per pose.
    count: Vec<usize>,
    /// Per pose and coordinate `a`, the sum of its rows of `L` (poses x 3, a column per joint).
    l_sum: Vec<[[f64; crate::robot::JOINTS]; 3]>,
    /// Per pose, the sum of the squared entries of its rows of `L`.
    l_sq: Vec<f64>,
    /// Per joint `j`, per pose, the sum over its rows of `L_rj B_r` (basis x poses: a pose's
    /// sums together).
    w: Vec<DMatrix<f64>>,
    /// Per pose and coordinate, the sum of its rows of `B` (basis x 3 poses, column `3 p + a`).
    b_sum: DMatrix<f64>,
    /// The sum of `B_r^T B_r` over the rows of every pose, and over those of the poses of two or
    /// more points (basis x basis each): a pose's own square enters the bins only in these two
    /// sums (the mean square of a point; the pairs within a pose).
    b_outer: [DMatrix<f64>; 2],
}

impl PoseSums {
    fn of(jl: &DMatrix<f64>, pose_of: &[usize], poses: usize, basis: &DMatrix<f64>) -> PoseSums {
        let (joints, k) = (jl.ncols(), basis.ncols());
        let mut s = PoseSums {
            count: vec![0; poses],
            l_sum: vec![[[0.0; crate::robot::JOINTS]; 3]; poses],
            l_sq: vec![0.0; poses],
            w: vec![DMatrix::zeros(k, poses); joints],
            b_sum: DMatrix::zeros(k, 3 * poses),
            b_outer: [basis.tr_mul(basis), DMatrix::zeros(k, k)],
        };
        for &p in pose_of {
            s.count[p] += 1;
        }
        for (i, &p) in pose_of.iter().enumerate() {
            for a in 0..3 {
                let r = 3 * i + a;
                let b = basis.row(r);
                for j in 0..joints {
                    let v = jl[(r, j)];
                    s.l_sum[p][a][j] += v;
                    s.l_sq[p] += v * v;
                    for c in 0..k {
                        s.w[j][(c, p)] += v * b[c];
                    }
                }
                for c in 0..k {
                    s.b_sum[(c, 3 * p + a)] += b[c];
                }
                if s.count[p] >= 2 {
                    let b = b.transpose();
                    s.b_outer[1].ger(1.0, &b, &b, 1.0);
                }
            }
        }
        s
    }
}

/// What a smooth joint-space field of unit RMS per joint and length `l` gives the bins after the
/// fit: per bin the expected mean product of a pair's residuals, and the expected mean squared
/// residual of a point. The field is [`LENGTH_FEATURES`] random Fourier features of the kernel
/// (fixed frequencies scaled by `1 / l`, so that the prediction is smooth in `l`), moved to the
/// points by the weighted link-angle Jacobian `L` (3 rows per point, a column per joint) and
/// projected off the fit's columns (`B`, orthonormal over the same rows): the field's values at
/// row `r` of pose `p` are `G_r = L_r (x) phi_p - B_r C` with `C = B^T (L (x) phi)`, and only
/// the products of their sums per pose and their squares per pose are needed, which [`PoseSums`]
/// gives without forming `G` (`C_j = W_j^T Phi`, `E_j = Phi C_j^T`, `K = sum_j C_j C_j^T`):
/// - the squares `|L_r|^2 |phi_p|^2 - 2 sum_j W_jp . E_jp + <K, sum_r B_r^T B_r>`;
/// - the product of the sums of poses `p` and `s`, with `l_pa` the sum of pose `p`'s rows of
///   coordinate `a` of `L` and `b_pa` those of `B`: `sum_a [ (l_pa . l_sa) (phi_p . phi_s) -
///   b_sa . y_pa - b_pa . y_sa + b_pa K b_sa ]`, `y_pa = sum_j l_paj E_jp`.
fn predicted(c: &Correlation, l: f64, sums: &PoseSums, features: &Features, q: &[crate::robot::Joints], n: usize) -> (Vec<f64>, f64) {
    let joints = sums.w.len();
    let phi = feature_values(features, q, l);
    let k = sums.b_sum.nrows();
    // The features transposed (features x poses: a pose's values together).
    let phi_t = phi.transpose();
    let cj: Vec<DMatrix<f64>> = sums.w.iter().map(|w| w * &phi).collect();
    // E_j transposed (basis x poses: a pose's values together).
    let e: Vec<DMatrix<f64>> = cj.iter().map(|x| x * &phi_t).collect();
    let mut gram = DMatrix::zeros(k, k);
    for x in &cj {
        gram += x * x.transpose();
    }
    // Per pose and coordinate (column 3 p + a): y (sum_j l_paj E_jp) and K b.
    let bk = &gram * &sums.b_sum;
    let mut y = DMatrix::zeros(k, 3 * c.poses);
    let phi_sq: Vec<f64> = (0..c.poses).map(|p| phi_t.column(p).norm_squared()).collect();
    let mut own = vec![0.0f64; c.poses];
    for p in 0..c.poses {
        for a in 0..3 {
            for j in 0..joints {
                let v = sums.l_sum[p][a][j];
                let mut column = y.column_mut(3 * p + a);
                column.axpy(v, &e[j].column(p), 1.0);
            }
        }
        let cross: f64 = (0..joints).map(|j| sums.w[j].column(p).iter().zip(e[j].column(p).iter()).map(|(x, y)| x * y).sum::<f64>()).sum();
        own[p] = sums.l_sq[p] * phi_sq[p] - 2.0 * cross;
    }
    // The squares' last term, `<K, sum_r B_r^T B_r>`, over every pose and over the poses of two
    // or more points.
    let outer = sums.b_outer.each_ref().map(|b| gram.iter().zip(b.iter()).map(|(x, y)| x * y).sum::<f64>());
    let own = Own {
        every: own.iter().sum::<f64>() + outer[0],
        repeated: (0..c.poses).filter(|&p| sums.count[p] >= 2).map(|p| own[p]).sum::<f64>() + outer[1],
    };
    let column_dot = |m: &DMatrix<f64>, r: usize, o: &DMatrix<f64>, s: usize| -> f64 { m.column(r).dot(&o.column(s)) };
    let dot = |p: usize, s: usize| -> f64 {
        let phi_ps = phi_t.column(p).dot(&phi_t.column(s));
        (0..3)
            .map(|a| {
                let (rp, rs) = (3 * p + a, 3 * s + a);
                let ll: f64 = (0..joints).map(|j| sums.l_sum[p][a][j] * sums.l_sum[s][a][j]).sum();
                ll * phi_ps - column_dot(&sums.b_sum, rs, &y, rp) - column_dot(&sums.b_sum, rp, &y, rs)
                    + column_dot(&sums.b_sum, rp, &bk, rs)
            })
            .sum()
    };
    bin_products(c, dot, &own, &sums.count, n)
}

/// The squares of the field's values summed over the points of every pose, and over those of the
/// poses of two or more points.
struct Own {
    every: f64,
    repeated: f64,
}

/// Per bin, the mean product of the field's values over its pairs of points, and the mean squared
/// value of a point: `dot(p, s)` the product of the values summed per pose `p` and those summed
/// per pose `s`, `own` their squares summed, `count` the points per pose, `n` the points.
fn bin_products(c: &Correlation, dot: impl Fn(usize, usize) -> f64, own: &Own, count: &[usize], n: usize) -> (Vec<f64>, f64) {
    let mean_sq = own.every / n.max(1) as f64;
    let products = c
        .bins
        .iter()
        .map(|b| {
            let (product, pairs) = if b.same_pose {
                // The pairs within a pose: half the square of its sum less its squares.
                let (squares, pairs) = (0..c.poses)
                    .filter(|&p| count[p] >= 2)
                    .fold((0.0, 0usize), |(x, n), p| (x + dot(p, p), n + count[p] * (count[p] - 1) / 2));
                (0.5 * (squares - own.repeated), pairs)
            } else {
                b.pair_sample
                    .iter()
                    .fold((0.0, 0usize), |(x, n), &(p, s)| (x + dot(p as usize, s as usize), n + count[p as usize] * count[s as usize]))
            };
            product / pairs.max(1) as f64
        })
        .collect();
    (products, mean_sq)
}

/// Per length of [`length_grid`], what a unit field gives the bins after the fit ([`predicted`]):
/// the expensive part of the fit, which depends only on the poses, the Jacobian and the basis.
struct Predictions {
    grid: Vec<f64>,
    by_length: Vec<(Vec<f64>, f64)>,
}

impl Predictions {
    fn of(c: &Correlation, jl: &DMatrix<f64>, pose_of: &[usize], q: &[crate::robot::Joints], basis: &DMatrix<f64>) -> Predictions {
        use rayon::prelude::*;
        let grid = length_grid();
        let sums = PoseSums::of(jl, pose_of, c.poses, basis);
        let features = features();
        let by_length = grid.par_iter().map(|&l| predicted(c, l, &sums, &features, q, pose_of.len())).collect();
        Predictions { grid, by_length }
    }
}

/// One length of the profile: the length, the level share `a`, the weighted squared misfit and
/// `a`'s least-squares standard error.
type ProfilePoint = (f64, f64, f64, f64);

/// The profile of `c`'s bins against the predictions (`None` with fewer than two bins with an
/// interval).
fn profile(c: &Correlation, p: &Predictions) -> Option<Vec<ProfilePoint>> {
    let usable: Vec<usize> = (0..c.bins.len()).filter(|&b| c.bins[b].interval.iter().all(|v| v.is_finite())).collect();
    if usable.len() < 2 {
        return None;
    }
    let se: Vec<f64> = usable.iter().map(|&b| ((c.bins[b].interval[1] - c.bins[b].interval[0]) / (2.0 * Z95)).max(1e-12)).collect();
    let excess: Vec<f64> = usable.iter().map(|&b| c.bins[b].correlation - c.bins[b].white).collect();
    let points = p
        .grid
        .iter()
        .zip(&p.by_length)
        .map(|(&l, (m, s))| {
            let k: Vec<f64> = usable.iter().map(|&b| m[b] - s * c.bins[b].white).collect();
            let (num, den) =
                (0..k.len()).fold((0.0, 0.0), |(x, y), i| (x + excess[i] * k[i] / se[i].powi(2), y + k[i] * k[i] / se[i].powi(2)));
            let a = if den > 0.0 { (num / den).max(0.0) } else { 0.0 };
            let misfit = (0..k.len()).map(|i| ((excess[i] - a * k[i]) / se[i]).powi(2)).sum();
            (l, a, misfit, if den > 0.0 { 1.0 / den.sqrt() } else { f64::INFINITY })
        })
        .collect();
    Some(points)
}

/// The index of the profile's least misfit.
fn best(profile: &[ProfilePoint]) -> Option<usize> {
    (0..profile.len()).min_by(|&x, &y| profile[x].2.total_cmp(&profile[y].2))
}

/// The correlation length and level of the error left, where a bin of distinct poses is above the
/// fit's value for white residuals (`None` otherwise, with fewer than two bins with an interval, or
/// where the best length is the grid's least, an error independent per pose, or its greatest).
///
/// The residual is modelled as a smooth field of RMS `s` per joint and length `l` plus white noise,
/// both after the fit: a bin's correlation is `c_b = a M_b(l) + (1 - a S(l)) w_b`, with `M_b` and
/// `S` the mean product and mean square a unit field leaves after the fit ([`predicted`]: the fit
/// absorbs the field's slow part, so the bins see less of a long field than the kernel says),
/// `w_b` the bin's value for white residuals and `a = s^2 / mean_sq`. For each `l` of a log grid
/// `a` is the weighted least squares of `c_b - w_b` on `M_b - S w_b` (weights the jackknife
/// variances; kept >= 0), `l` the one of least weighted squared misfit. The intervals come from a
/// parametric bootstrap of that fit ([`bootstrap`]). `jl`, `pose_of`, `q` and `basis` are over the
/// rows and poses the correlation binned, `binning` their binning ([`correlation_binned`]).
pub(crate) fn length_scale(
    binning: &Binning,
    c: &Correlation,
    jl: &DMatrix<f64>,
    pose_of: &[usize],
    q: &[crate::robot::Joints],
    basis: &DMatrix<f64>,
) -> Option<LengthScale> {
    if !c.bins.iter().any(|b| !b.same_pose && b.above_white()) {
        return None;
    }
    let predictions = Predictions::of(c, jl, pose_of, q, basis);
    let profile = profile(c, &predictions)?;
    let b = best(&profile)?;
    // The grid's least length: an error independent per pose; its greatest: a field the fit
    // absorbs all but a trace of, whose length and level the bins cannot tell.
    if b == 0 || b + 1 == profile.len() || profile[b].1 <= 0.0 {
        return None;
    }
    let (length, level) = (profile[b].0, (profile[b].1 * c.mean_sq).sqrt());
    let model = Model { length, level, share: profile[b].1, unit_sq: predictions.by_length[b].1 };
    let fits = bootstrap(binning, c, &model, &predictions, &Rows { jl, pose_of, q, basis });
    let last = predictions.grid.len() - 1;
    let censored = [fits.iter().filter(|f| f.0 == 0).count(), fits.iter().filter(|f| f.0 == last).count()];
    let lengths: Vec<f64> = fits.iter().map(|f| predictions.grid[f.0]).collect();
    let levels: Vec<f64> = fits.iter().map(|f| f.1).collect();
    let (length_basic, length_percentile) = intervals(length, lengths);
    let (level_basic, level_percentile) = intervals(level, levels);
    Some(LengthScale {
        length_rad: length,
        interval: length_basic,
        level_rad: [level, (level_percentile[1] - level_percentile[0]) / (2.0 * Z95)],
        level_interval_rad: level_percentile,
        basic: [length_basic, level_basic],
        percentile: [length_percentile, level_percentile],
        replicates: fits.len(),
        censored,
    })
}

/// The fitted model a bootstrap replicate draws from: the length and level (rad), the level share
/// `a` and the mean square `S` a unit field of that length leaves after the fit.
struct Model {
    length: f64,
    level: f64,
    share: f64,
    unit_sq: f64,
}

/// The rows and poses the correlation binned: the weighted link-angle Jacobian, each point's pose,
/// the poses' joint values and the fit's orthonormal basis.
struct Rows<'a> {
    jl: &'a DMatrix<f64>,
    pose_of: &'a [usize],
    q: &'a [crate::robot::Joints],
    basis: &'a DMatrix<f64>,
}

/// The basic 95 % bootstrap interval of a positive `value` in log scale (`[v^2 / q97.5, v^2 /
/// q2.5]`), and the percentile one (`[q2.5, q97.5]`), of the replicates' values.
fn intervals(value: f64, mut replicates: Vec<f64>) -> ([f64; 2], [f64; 2]) {
    replicates.sort_by(f64::total_cmp);
    let q = |f: f64| -> f64 {
        let x = f * (replicates.len() - 1) as f64;
        let (i, t) = (x.floor() as usize, x - x.floor());
        let next = replicates[(i + 1).min(replicates.len() - 1)];
        replicates[i] + t * (next - replicates[i])
    };
    if replicates.is_empty() {
        return ([f64::NAN; 2], [f64::NAN; 2]);
    }
    let (low, high) = (q(0.025), q(0.975));
    let basic = if low > 0.0 { [value * value / high, value * value / low] } else { [value * value / high, f64::INFINITY] };
    (basic, [low, high])
}

/// The parametric bootstrap of the length fit: [`BOOTSTRAP_REPLICATES`] residuals drawn from the
/// fitted model, each a smooth field of the fitted length and level drawn as a world draws the
/// twin's field (`robot::learned`'s random Fourier features, [`BOOTSTRAP_FEATURES`] per joint,
/// from the replicate's own stream; their cosines by `numeric::cosines`, within a unit in the last
/// place of the library's) carried to the points by the weighted link-angle Jacobian, plus white
/// noise of the model's share of the mean square, projected off the fit's basis, binned as `c` and
/// fitted against the same predictions. Per replicate (in index order, any thread count), the
/// index of its best length on the grid (at the grid's ends where it is there) and its level, rad.
fn bootstrap(binning: &Binning, c: &Correlation, model: &Model, predictions: &Predictions, rows: &Rows<'_>) -> Vec<(usize, f64)> {
    use rand_distr::{Distribution, Normal};
    use rayon::prelude::*;
    let n = rows.pose_of.len();
    // The mean squared white residual of a point per unit variance: 3 less tr H_ii.
    let white_sq = (3.0 * n as f64 - rows.basis.iter().map(|v| v * v).sum::<f64>()) / n as f64;
    let white_sd = ((1.0 - model.share * model.unit_sq).max(0.0) * c.mean_sq / white_sq).sqrt();
    // Each replicate's residual (`None`: no noise of that level).
    let drawn: Vec<Option<DVector<f64>>> = (0..BOOTSTRAP_REPLICATES)
        .into_par_iter()
        .map(|i| {
            let mut rng = crate::seeds::stream(crate::seeds::fixed::LENGTH_BOOTSTRAP, i as u64);
            let field = crate::robot::learned::smooth_field_of(model.level, model.length, BOOTSTRAP_FEATURES, &mut rng);
            // `robot::learned::add_field` at every pose, a feature at a time over the poses (each
            // pose's sum in the features' order) and the cosines many at once.
            let mut e = vec![[0.0; crate::robot::JOINTS]; rows.q.len()];
            let mut x = vec![0.0; rows.q.len()];
            for (j, w, phase, amplitude) in &field {
                for (x, q) in x.iter_mut().zip(rows.q) {
                    *x = w.iter().zip(q).map(|(a, b)| a * b).sum::<f64>() + phase;
                }
                crate::numeric::cosines(&mut x);
                for (e, c) in e.iter_mut().zip(&x) {
                    e[*j] += amplitude * c;
                }
            }
            let noise = Normal::new(0.0, white_sd).ok()?;
            let jl = rows.jl;
            let mut g = DVector::from_fn(jl.nrows(), |r, _| {
                let p = rows.pose_of[r / 3];
                (0..jl.ncols()).map(|j| jl[(r, j)] * e[p][j]).sum::<f64>() + noise.sample(&mut rng)
            });
            if rows.basis.ncols() > 0 {
                g -= rows.basis * rows.basis.tr_mul(&g);
            }
            Some(g)
        })
        .collect();
    let no_traces = vec![0.0; c.bins.len()];
    let fitted = |mut r: Correlation| -> Option<(usize, f64)> {
        for (x, b) in r.bins.iter_mut().zip(&c.bins) {
            x.white = b.white;
        }
        let profile = profile(&r, predictions)?;
        let b = best(&profile)?;
        Some((b, (profile[b].1 * r.mean_sq).sqrt()))
    };
    // The replicates binned [`LANES`] at a time (each block's pairs read once).
    drawn
        .par_chunks(LANES)
        .flat_map_iter(|block| {
            let present: Vec<&DVector<f64>> = block.iter().flatten().collect();
            let mut binned = binning.correlations(&present, &no_traces, white_sq).into_iter();
            block.iter().map(|g| g.as_ref().and_then(|_| fitted(binned.next().expect("a correlation per residual")))).collect::<Vec<_>>()
        })
        .flatten()
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The dense reference of [`predicted`]: the field's values at every row of the points formed
    /// (`jl` 3 rows per point, a column per joint) and projected off `basis`.
    fn predicted_dense(
        c: &Correlation,
        l: f64,
        jl: &DMatrix<f64>,
        pose_of: &[usize],
        q: &[crate::robot::Joints],
        basis: &DMatrix<f64>,
    ) -> (Vec<f64>, f64) {
        let f = LENGTH_FEATURES;
        let joints = jl.ncols();
        let phi = feature_values(&features(), q, l);
        let n = pose_of.len();
        let mut g = DMatrix::from_fn(3 * n, joints * f, |r, col| jl[(r, col / f)] * phi[(pose_of[r / 3], col % f)]);
        if basis.ncols() > 0 {
            g -= basis * (basis.transpose() * &g);
        }
        let width = 3 * joints * f;
        let mut sum = vec![0.0f64; c.poses * width];
        let mut own = vec![0.0f64; c.poses];
        let mut count = vec![0usize; c.poses];
        for (i, &p) in pose_of.iter().enumerate() {
            count[p] += 1;
            for a in 0..3 {
                let row = g.row(3 * i + a);
                for (k, v) in row.iter().enumerate() {
                    sum[p * width + a * joints * f + k] += v;
                    own[p] += v * v;
                }
            }
        }
        let dot = |p: usize, s: usize| -> f64 {
            sum[p * width..(p + 1) * width].iter().zip(&sum[s * width..(s + 1) * width]).map(|(x, y)| x * y).sum()
        };
        let own = Own { every: own.iter().sum(), repeated: (0..c.poses).filter(|&p| count[p] >= 2).map(|p| own[p]).sum() };
        bin_products(c, dot, &own, &count, n)
    }

    /// `poses` random poses (joint values in -2..2 rad) and their points: pose `p` has `1 + p % 3`.
    fn poses_of_one_to_three_points(rng: &mut impl rand::Rng, poses: usize) -> (Vec<crate::robot::Joints>, Vec<usize>) {
        use rand::RngExt;
        let q = (0..poses).map(|_| std::array::from_fn(|_| rng.random_range(-2.0..2.0))).collect();
        (q, (0..poses).flat_map(|p| std::iter::repeat_n(p, 1 + p % 3)).collect())
    }

    /// The per-pose sums give the same prediction as the field formed at every row and projected
    /// off the basis (random Jacobian, basis and poses: 120 poses, 1-3 points each, 7 basis
    /// columns; three lengths), to 1e-9 relative.
    #[test]
    fn the_prediction_by_pose_sums_is_the_dense_one() {
        use rand::RngExt;
        let mut rng = crate::seeds::stream(9, 0);
        let poses = 120;
        let (q, pose_of) = poses_of_one_to_three_points(&mut rng, poses);
        let n = pose_of.len();
        let jl = DMatrix::from_fn(3 * n, 6, |_, _| rng.random_range(-1.0..1.0));
        let basis = DMatrix::from_fn(3 * n, 7, |_, _| rng.random_range(-1.0..1.0)).qr().q();
        let resid = DVector::from_fn(3 * n, |_, _| rng.random_range(-1.0..1.0));
        let c = correlation(&resid, &pose_of, &q, &basis);
        let sums = PoseSums::of(&jl, &pose_of, poses, &basis);
        let features = features();
        for l in [0.3, 1.5, 6.0] {
            let (m, s) = predicted(&c, l, &sums, &features, &q, n);
            let (md, sd) = predicted_dense(&c, l, &jl, &pose_of, &q, &basis);
            let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * b.abs().max(1e-3);
            assert!(close(s, sd), "l {l}: {s} {sd}");
            for (a, b) in m.iter().zip(&md) {
                assert!(close(*a, *b), "l {l}: {m:?} {md:?}");
            }
        }
    }

    /// The bootstrap of a known model (no fit: an empty basis; 150 poses of 2 points, a random
    /// Jacobian; the field's length the grid's 1.00 rad and 80 % of the mean square) draws the
    /// same replicates on 1 and 2 threads, one per replicate.
    #[test]
    fn the_bootstraps_replicates_are_the_same_on_any_thread_count() {
        use rand::RngExt;
        let mut rng = crate::seeds::stream(11, 0);
        let poses = 150;
        let q: Vec<crate::robot::Joints> = (0..poses).map(|_| std::array::from_fn(|_| rng.random_range(-2.0..2.0))).collect();
        let pose_of: Vec<usize> = (0..2 * poses).map(|i| i / 2).collect();
        let n = pose_of.len();
        let jl = DMatrix::from_fn(3 * n, 6, |_, _| rng.random_range(-1.0..1.0));
        let basis = DMatrix::zeros(3 * n, 0);
        let resid = DVector::from_fn(3 * n, |_, _| rng.random_range(-1.0..1.0));
        let c = correlation(&resid, &pose_of, &q, &basis);
        let predictions = Predictions::of(&c, &jl, &pose_of, &q, &basis);
        let k = 17;
        let length = predictions.grid[k];
        let share = 0.8 / predictions.by_length[k].1;
        let model = Model { length, level: (share * c.mean_sq).sqrt(), share, unit_sq: predictions.by_length[k].1 };
        let rows = Rows { jl: &jl, pose_of: &pose_of, q: &q, basis: &basis };
        let on = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| bootstrap(&Binning::of(&pose_of, &q), &c, &model, &predictions, &rows))
        };
        let (one, two) = (on(1), on(2));
        assert_eq!(one, two);
        assert_eq!(one.len(), BOOTSTRAP_REPLICATES);
    }

    /// Residuals drawn as a smooth function of the pose (the same at nearby poses) correlate in the
    /// nearest bins and not in the farthest; white residuals correlate in no bin beyond their
    /// interval (no fit: the hat basis empty, the fit's own value zero).
    #[test]
    fn a_smooth_field_correlates_nearby_poses_and_white_residuals_do_not() {
        use rand::RngExt;
        use rand_distr::{Distribution, Normal};
        let mut rng = crate::seeds::stream(3, 0);
        let poses = 300;
        let q: Vec<crate::robot::Joints> = (0..poses).map(|_| std::array::from_fn(|_| rng.random_range(-2.0..2.0))).collect();
        // Two targets per pose.
        let pose_of: Vec<usize> = (0..2 * poses).map(|i| i / 2).collect();
        let normal = Normal::new(0.0, 1.0).unwrap();
        let white = DVector::from_fn(6 * poses, |_, _| normal.sample(&mut rng));
        let smooth = DVector::from_fn(6 * poses, |r, _| {
            let p = &q[r / 6];
            3.0 * (p[0] + 0.5 * (r % 3) as f64).sin() * p[1].cos() + 0.3 * normal.sample(&mut rng)
        });
        let none = DMatrix::zeros(6 * poses, 0);
        let w = correlation(&white, &pose_of, &q, &none);
        let s = correlation(&smooth, &pose_of, &q, &none);
        assert_eq!(w.bins.len(), 5, "{w:?}");
        for b in &w.bins {
            assert!(b.interval[0] <= 0.0 && 0.0 <= b.interval[1], "{b:?}");
            assert_eq!(b.white, 0.0);
        }
        assert!(s.bins[0].correlation > 0.9, "{:?}", s.bins[0]);
        assert!(s.bins[1].above_white() && s.bins[1].correlation > 0.3, "{:?}", s.bins[1]);
        assert!(s.bins[4].correlation.abs() < 0.1, "{:?}", s.bins[4]);
        // Point pairs: one per pose at distance 0, four per pair of poses.
        assert_eq!(s.bins[0].pairs, poses);
        assert_eq!(s.bins.iter().skip(1).map(|b| b.pairs).sum::<usize>(), 4 * poses * (poses - 1) / 2);
    }

    /// Above `MAX_POSES` poses the bins are those of every k-th pose and its points (k = 3 for
    /// 6,001 poses: 2,001 kept), the same as binning that subset directly; the pairs stay bounded.
    #[test]
    fn above_the_most_poses_every_kth_pose_is_binned() {
        use rand::RngExt;
        let mut rng = crate::seeds::stream(5, 0);
        let poses = 2 * MAX_POSES + 1;
        let q: Vec<crate::robot::Joints> = (0..poses).map(|_| std::array::from_fn(|_| rng.random_range(-2.0..2.0))).collect();
        let pose_of: Vec<usize> = (0..2 * poses).map(|i| i / 2).collect();
        let resid = DVector::from_fn(6 * poses, |_, _| rng.random_range(-1.0..1.0));
        let basis = DMatrix::from_fn(6 * poses, 2, |_, _| rng.random_range(-0.01..0.01));
        let c = correlation(&resid, &pose_of, &q, &basis);
        assert_eq!(c.poses, 2001);
        let kept: Vec<usize> = (0..2 * poses).filter(|&i| pose_of[i].is_multiple_of(3)).collect();
        let rows: Vec<usize> = kept.iter().flat_map(|&i| [3 * i, 3 * i + 1, 3 * i + 2]).collect();
        let sub_q: Vec<crate::robot::Joints> = (0..poses).filter(|p| p.is_multiple_of(3)).map(|p| q[p]).collect();
        let sub_pose: Vec<usize> = kept.iter().map(|&i| pose_of[i] / 3).collect();
        let sub = correlation_of(&resid.select_rows(&rows), &sub_pose, &sub_q, &basis.select_rows(&rows));
        assert_eq!(c, sub);
        assert_eq!(c.bins.iter().skip(1).map(|b| b.pose_pairs).sum::<usize>(), 2001 * 2000 / 2);
    }

    /// The farthest bin's sums taken as every pair's less the nearer bins' (its complement) are
    /// those of its pairs summed one by one: each bin's correlation, jackknife interval and the fit's
    /// own value within 1e-12 (120 poses of 1-3 points, a 5-column basis, three residuals of
    /// nonzero mean).
    #[test]
    fn the_farthest_bin_from_every_pair_is_that_of_its_pairs() {
        use rand::RngExt;
        let mut rng = crate::seeds::stream(17, 0);
        let (q, pose_of) = poses_of_one_to_three_points(&mut rng, 120);
        let n = pose_of.len();
        let basis = DMatrix::from_fn(3 * n, 5, |_, _| rng.random_range(-1.0..1.0)).qr().q();
        let resids: Vec<DVector<f64>> = (0..3).map(|_| DVector::from_fn(3 * n, |_, _| rng.random_range(-0.5..1.0))).collect();
        let binned = |b: Binning| {
            let (traces, white_sq) = b.traces(&basis);
            b.correlations(&resids.iter().collect::<Vec<_>>(), &traces, white_sq)
        };
        let quick = Binning::of(&pose_of, &q);
        assert!(quick.complement().is_some_and(|c| c + 1 == quick.bins.len()));
        let fast = binned(quick);
        let direct = binned(Binning::of(&pose_of, &q).without_complement());
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * a.abs().max(1.0);
        for (f, d) in fast.iter().zip(&direct) {
            assert_eq!(f.bins.len(), d.bins.len());
            for (fb, db) in f.bins.iter().zip(&d.bins) {
                let same = close(fb.correlation, db.correlation)
                    && close(fb.white, db.white)
                    && close(fb.interval[0], db.interval[0])
                    && close(fb.interval[1], db.interval[1]);
                assert!(same, "{fb:?}\n{db:?}");
            }
        }
    }

    /// Residuals binned together ([`Binning::correlations`], 1, 3 and 8 of them) give each the
    /// numbers it has binned alone, bit for bit, and those of the pairs of points summed directly
    /// to 1e-12 (60 poses of 1-3 points, a 4-column basis); four pairs' dot products side by side
    /// ([`row_dots`]) are those of `Iterator::sum`, bit for bit, for 0 to 9 pairs (short last
    /// groups, zeros of either sign).
    #[test]
    fn residuals_binned_together_are_binned_as_alone() {
        use rand::RngExt;
        let mut rng = crate::seeds::stream(13, 0);
        let poses = 60;
        let (q, pose_of) = poses_of_one_to_three_points(&mut rng, poses);
        let n = pose_of.len();
        let binning = Binning::of(&pose_of, &q);
        let basis = DMatrix::from_fn(3 * n, 4, |_, _| rng.random_range(-1.0..1.0)).qr().q();
        let (traces, white_sq) = binning.traces(&basis);
        let resids: Vec<DVector<f64>> = (0..LANES).map(|_| DVector::from_fn(3 * n, |_, _| rng.random_range(-1.0..1.0))).collect();
        for m in [1, 3, LANES] {
            let together = binning.correlations(&resids[..m].iter().collect::<Vec<_>>(), &traces, white_sq);
            assert_eq!(together.len(), m);
            for (c, r) in together.iter().zip(&resids) {
                assert_eq!(*c, binning.correlation(r, &traces, white_sq));
                // The bins of distinct poses against the pairs of points summed directly.
                let mean_sq = r.norm_squared() / n as f64;
                for b in c.bins.iter().filter(|b| !b.same_pose) {
                    let (mut sum, mut pairs) = (0.0, 0usize);
                    for i in 0..n {
                        for j in 0..n {
                            let d = q[pose_of[i]].iter().zip(&q[pose_of[j]]).map(|(x, y)| (x - y).powi(2)).sum::<f64>().sqrt();
                            let inside = d >= b.distance_rad[0] && d <= b.distance_rad[1] && pose_of[i] < pose_of[j];
                            if inside {
                                sum += (0..3).map(|a| r[3 * i + a] * r[3 * j + a]).sum::<f64>();
                                pairs += 1;
                            }
                        }
                    }
                    assert_eq!(pairs, b.pairs, "{}", b.label);
                    let direct = sum / pairs as f64 / mean_sq;
                    assert!((direct - b.correlation).abs() <= 1e-12 * direct.abs().max(1.0), "{}: {direct} {}", b.label, b.correlation);
                }
            }
        }
        let width = 7;
        let mut rows: Vec<f64> = (0..5 * width).map(|_| rng.random_range(-1.0..1.0)).collect();
        rows[3] = -0.0;
        rows[width + 3] = 0.0;
        for count in 0..10 {
            let pairs: Vec<(usize, usize)> = (0..count).map(|i| (i % 5, (3 * i + 1) % 5)).collect();
            let side_by_side = row_dots(&rows, width, pairs.iter().copied());
            let one_at_a_time: Vec<f64> = pairs
                .iter()
                .map(|&(p, s)| rows[p * width..(p + 1) * width].iter().zip(&rows[s * width..(s + 1) * width]).map(|(x, y)| x * y).sum())
                .collect();
            assert_eq!(side_by_side.len(), count);
            for (a, b) in side_by_side.iter().zip(&one_at_a_time) {
                assert_eq!(a.to_bits(), b.to_bits(), "{count} pairs");
            }
        }
    }
}
