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
    let n = pose_of.len();
    let poses = q.len();
    let k = hat_basis.ncols();
    if n == 0 || poses < 2 || resid.len() != 3 * n {
        return Correlation { bins: Vec::new(), poses };
    }
    // Per pose: the sum of its points' residuals, their count, the sum of their squared
    // residuals, the sum of their rows of the hat basis (3 x k) and of tr H_ii.
    let mut r_sum = vec![[0.0f64; 3]; poses];
    let mut count = vec![0usize; poses];
    let mut sq = vec![0.0f64; poses];
    let mut q_sum = vec![0.0f64; poses * 3 * k];
    let mut h_ii = vec![0.0f64; poses];
    for (i, &p) in pose_of.iter().enumerate() {
        count[p] += 1;
        for a in 0..3 {
            let v = resid[3 * i + a];
            r_sum[p][a] += v;
            sq[p] += v * v;
            for c in 0..k {
                let h = hat_basis[(3 * i + a, c)];
                q_sum[(p * 3 + a) * k + c] += h;
                h_ii[p] += h * h;
            }
        }
    }
    let mean_sq = sq.iter().sum::<f64>() / n as f64;
    let white_sq = (3.0 * n as f64 - h_ii.iter().sum::<f64>()) / n as f64;
    let dot_q = |p: usize, s: usize| -> f64 {
        let (a, b) = (&q_sum[p * 3 * k..(p + 1) * 3 * k], &q_sum[s * 3 * k..(s + 1) * 3 * k]);
        a.iter().zip(b).map(|(x, y)| x * y).sum()
    };

    // Bin sums: products, point pairs, tr H_ij; and per pose, the same over the pairs it is in.
    struct Sums {
        label: String,
        same_pose: bool,
        range: [f64; 2],
        product: f64,
        pairs: usize,
        pose_pairs: usize,
        trace: f64,
        per_pose: Vec<(f64, usize)>,
    }
    let new_bin = |label: String, same_pose: bool| Sums {
        label,
        same_pose,
        range: [f64::INFINITY, f64::NEG_INFINITY],
        product: 0.0,
        pairs: 0,
        pose_pairs: 0,
        trace: 0.0,
        per_pose: vec![(0.0, 0); poses],
    };
    let mut bins: Vec<Sums> = Vec::new();
    // The other targets at one pose.
    if count.iter().any(|&c| c >= 2) {
        let mut b = new_bin("other targets at one pose".into(), true);
        for p in (0..poses).filter(|&p| count[p] >= 2) {
            let s = 0.5 * (r_sum[p].iter().map(|v| v * v).sum::<f64>() - sq[p]);
            let pairs = count[p] * (count[p] - 1) / 2;
            b.product += s;
            b.pairs += pairs;
            b.pose_pairs += 1;
            b.trace += 0.5 * (dot_q(p, p) - h_ii[p]);
            b.per_pose[p] = (s, pairs);
            b.range = [0.0, 0.0];
        }
        bins.push(b);
    }
    // Distinct poses, by the rank of their distance.
    let mut pairs: Vec<(f64, u32, u32)> = Vec::with_capacity(poses * (poses - 1) / 2);
    for p in 0..poses {
        for s in p + 1..poses {
            let d = q[p].iter().zip(&q[s]).map(|(a, b)| (a - b).powi(2)).sum::<f64>().sqrt();
            pairs.push((d, p as u32, s as u32));
        }
    }
    pairs.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
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
        let mut b = new_bin(label, false);
        for &(d, p, s) in &pairs[from..to] {
            let (p, s) = (p as usize, s as usize);
            let prod: f64 = (0..3).map(|a| r_sum[p][a] * r_sum[s][a]).sum();
            let n_pairs = count[p] * count[s];
            b.product += prod;
            b.pairs += n_pairs;
            b.pose_pairs += 1;
            b.trace += dot_q(p, s);
            for x in [p, s] {
                b.per_pose[x].0 += prod;
                b.per_pose[x].1 += n_pairs;
            }
            b.range = [b.range[0].min(d), b.range[1].max(d)];
        }
        bins.push(b);
        from = to;
    }

    let total_sq: f64 = sq.iter().sum();
    let bins = bins
        .into_iter()
        .map(|b| {
            let correlation = b.product / b.pairs as f64 / mean_sq;
            // Delete-one jackknife over the poses with points.
            let left_out: Vec<f64> = (0..poses)
                .filter(|&p| count[p] > 0 && b.pairs > b.per_pose[p].1 && n > count[p])
                .map(|p| {
                    let (s, c) = b.per_pose[p];
                    ((b.product - s) / (b.pairs - c) as f64) / ((total_sq - sq[p]) / (n - count[p]) as f64)
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
                label: b.label,
                distance_rad: b.range,
                pairs: b.pairs,
                pose_pairs: b.pose_pairs,
                correlation,
                interval,
                white: -(b.trace / b.pairs as f64) / white_sq,
            }
        })
        .collect();
    Correlation { bins, poses }
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
