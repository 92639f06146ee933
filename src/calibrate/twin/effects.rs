//! The candidate effect families of a twin as columns of the calibration's least squares: each
//! family's columns are the position change (weighted as the residuals are) that a unit of each of
//! its coefficients makes at every point.
//!
//! A joint-angle effect `delta theta_j = a f(q)` moves a point by `a f(q) dp/dtheta_j`, with
//! `dp/dtheta_j` the position Jacobian w.r.t. link angle `j` (the Jacobian of the joint offset
//! `theta_offs_j`); the drift is a base translation `a_k * (pose index within the session)`.
//!
//! Harmonics of orders above [`ORDERS`] (a gear stage's mesh, a reducer's input cycles) are
//! searched rather than all tried: per joint, [`scan`] picks the order of [`SCANNED_ORDERS`] that
//! explains most of the residual, and that one order becomes a family
//! ([`Family::Harmonic`]), kept only past the stricter [`KEEP_SE_SCANNED`].

use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

use crate::robot::JOINTS;

/// A family of candidate effects.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Family {
    /// Transmission harmonics of joint `j` (0-based), orders 1..=[`ORDERS`], sin and cos.
    Harmonics(usize),
    /// One transmission harmonic of joint `j` (0-based) at the order (above [`ORDERS`]) that
    /// [`scan`] found strongest in the residual, sin and cos.
    Harmonic(usize, usize),
    /// Backlash of every joint by the approach direction (full width).
    Backlash,
    /// Gravity sag per joint by the lever arm of a mass at the TCP.
    Sag,
    /// A base translation linear in the pose index within each session (the same rate in every session).
    Drift,
}

/// Orders of the harmonics fitted per joint.
pub const ORDERS: usize = 3;

/// Orders [`scan`] searches per joint (periods per turn), above [`ORDERS`].
pub const SCANNED_ORDERS: std::ops::RangeInclusive<usize> = ORDERS + 1..=120;

/// A family is kept when its held-out gain exceeds this many paired standard errors: the
/// one-sided normal quantile of 5 % shared by the nine families of [`Family::all`] (Bonferroni,
/// 0.05 / 9).
pub const KEEP_SE: f64 = 2.54;

/// [`KEEP_SE`] for a [`Family::Harmonic`]: its order was picked from the residual among
/// [`SCANNED_ORDERS`], so the 5 % is shared by every order of every joint it could have been
/// (Bonferroni, 0.05 / (6 x 117): the one-sided normal quantile 3.80). A picked order passes by
/// chance no more often than one of the 702 would, whichever was picked.
pub const KEEP_SE_SCANNED: f64 = 3.80;

impl Family {
    /// Every family, in the order they are tried.
    pub fn all() -> Vec<Family> {
        let mut v: Vec<Family> = (0..JOINTS).map(Family::Harmonics).collect();
        v.extend([Family::Backlash, Family::Sag, Family::Drift]);
        v
    }

    /// The paired standard errors its held-out gain must exceed to be kept.
    pub fn keep_se(self) -> f64 {
        match self {
            Family::Harmonic(..) => KEEP_SE_SCANNED,
            _ => KEEP_SE,
        }
    }

    /// Name for tables.
    pub fn name(self) -> String {
        match self {
            Family::Harmonics(j) => format!("harmonics of joint {} (orders 1-{ORDERS})", j + 1),
            Family::Harmonic(j, k) => format!(
                "harmonic of joint {} order {k} (the strongest of orders {}-{})",
                j + 1,
                SCANNED_ORDERS.start(),
                SCANNED_ORDERS.end()
            ),
            Family::Backlash => "backlash by approach direction".into(),
            Family::Sag => "gravity sag by lever arm".into(),
            Family::Drift => "drift of the base over pose order".into(),
        }
    }
}

/// What every point contributes to the columns (indexed by point of the problem).
pub struct PointData {
    /// Link angles, rad.
    pub q: Vec<crate::robot::Joints>,
    /// Approach direction per joint: +1 coming from below, -1 from above, 0 unknown or not moved.
    pub direction: Vec<[f64; JOINTS]>,
    /// Lever arm of a unit TCP mass per joint, m (zeros without gravity).
    pub lever_m: Vec<[f64; JOINTS]>,
    /// Index of the point's pose within its session (0-based).
    pub pose_index: Vec<f64>,
    /// The point's uncertainty per coordinate (1 without the file's column).
    pub sigma: Vec<f64>,
}

/// One effect coefficient: its family, name, and how its internal value shows (unit, scale).
#[derive(Clone, Debug, PartialEq)]
pub struct Coefficient {
    /// The family.
    pub family: Family,
    /// Joint (0-based) for joint effects.
    pub joint: Option<usize>,
    /// Harmonic order and whether it is the sine (true) or cosine coefficient.
    pub harmonic: Option<(usize, bool)>,
    /// Axis (0-2) of a drift.
    pub axis: Option<usize>,
    /// Name for tables.
    pub name: String,
}

fn mdeg(rad: f64) -> f64 {
    rad.to_degrees() * 1e3
}

impl Coefficient {
    /// The value in the table's unit from the internal one (rad, rad/m, mm per pose).
    pub fn shown(&self, v: f64) -> f64 {
        match self.family {
            Family::Drift => v,
            _ => mdeg(v),
        }
    }

    /// The table's unit.
    pub fn unit(&self) -> &'static str {
        match self.family {
            Family::Harmonics(_) | Family::Harmonic(..) | Family::Backlash => "mdeg",
            Family::Sag => "mdeg/m",
            Family::Drift => "mm/pose",
        }
    }
}

/// The columns of `family` over the points `idx` (3 rows per point, weighted as the residuals),
/// from the weighted link-angle Jacobian `jl` (3 |idx| x 6, rows in the order of `idx`); columns
/// that are zero at every point (a joint that never moves, the sag of a vertical axis) are left out.
pub fn columns(family: Family, idx: &[usize], jl: &DMatrix<f64>, d: &PointData) -> (DMatrix<f64>, Vec<Coefficient>) {
    let n = idx.len();
    let mut cols: Vec<Vec<f64>> = Vec::new();
    let mut coefs: Vec<Coefficient> = Vec::new();
    let mut joint_column = |j: usize, f: &dyn Fn(usize) -> f64, coef: Coefficient| {
        let mut c = vec![0.0; 3 * n];
        for (row, &i) in idx.iter().enumerate() {
            let w = f(i);
            for a in 0..3 {
                c[3 * row + a] = w * jl[(3 * row + a, j)];
            }
        }
        if c.iter().any(|v| *v != 0.0) {
            cols.push(c);
            coefs.push(coef);
        }
    };
    let base = |joint: Option<usize>, name: String| Coefficient { family, joint, harmonic: None, axis: None, name };
    match family {
        Family::Harmonics(j) | Family::Harmonic(j, _) => {
            let orders = if let Family::Harmonic(_, k) = family { k..=k } else { 1..=ORDERS };
            for order in orders {
                for sine in [true, false] {
                    let k = order as f64;
                    let f = move |i: usize| if sine { (k * d.q[i][j]).sin() } else { (k * d.q[i][j]).cos() };
                    let name = format!("joint {} order {order} {}", j + 1, if sine { "sin" } else { "cos" });
                    joint_column(j, &f, Coefficient { harmonic: Some((order, sine)), ..base(Some(j), name) });
                }
            }
        }
        Family::Backlash => {
            for j in 0..JOINTS {
                // The link lags half the width behind the motion: -w/2 coming from below.
                let f = move |i: usize| -0.5 * d.direction[i][j];
                joint_column(j, &f, base(Some(j), format!("joint {} width", j + 1)));
            }
        }
        Family::Sag => {
            for j in 0..JOINTS {
                let f = move |i: usize| d.lever_m[i][j];
                joint_column(j, &f, base(Some(j), format!("joint {} per metre of lever arm", j + 1)));
            }
        }
        Family::Drift => {
            for axis in 0..3 {
                let mut c = vec![0.0; 3 * n];
                for (row, &i) in idx.iter().enumerate() {
                    c[3 * row + axis] = d.pose_index[i] / d.sigma[i];
                }
                if c.iter().any(|v| *v != 0.0) {
                    cols.push(c);
                    coefs.push(Coefficient { axis: Some(axis), ..base(None, format!("base {} per pose", ["x", "y", "z"][axis])) });
                }
            }
        }
    }
    let m = DMatrix::from_fn(3 * n, cols.len(), |r, c| cols[c][r]);
    (m, coefs)
}

/// Per joint that moves, the order of [`SCANNED_ORDERS`] whose sine and cosine columns explain
/// most of the residual `r` (weighted as the columns, 3 rows per point of `idx`): the sum over
/// the two columns of `(c . r)^2 / (c . c)`, a periodogram of the joint's error along its
/// Jacobian. The orders' sines and cosines come from the angle-addition recurrence (a search,
/// not a fit: the family's columns are computed afresh by [`columns`]).
pub fn scan(idx: &[usize], jl: &DMatrix<f64>, d: &PointData, r: &DVector<f64>) -> Vec<Family> {
    let (lo, hi) = (*SCANNED_ORDERS.start(), *SCANNED_ORDERS.end());
    // The joints side by side, gathered in their order (the same for any thread count).
    (0..JOINTS)
        .into_par_iter()
        .filter_map(|j| {
            // Per point: the residual along the joint's Jacobian and the Jacobian's square.
            let (mut a, mut b) = (Vec::with_capacity(idx.len()), Vec::with_capacity(idx.len()));
            for row in 0..idx.len() {
                a.push((0..3).map(|k| r[3 * row + k] * jl[(3 * row + k, j)]).sum::<f64>());
                b.push((0..3).map(|k| jl[(3 * row + k, j)].powi(2)).sum::<f64>());
            }
            if b.iter().all(|v| *v == 0.0) {
                return None;
            }
            let mut sums = vec![[0.0; 4]; hi + 1];
            for (row, &i) in idx.iter().enumerate() {
                let (s1, c1) = d.q[i][j].sin_cos();
                let (mut s, mut c) = (s1, c1);
                for (k, sum) in sums.iter_mut().enumerate().skip(1) {
                    if k >= lo {
                        sum[0] += a[row] * s;
                        sum[1] += b[row] * s * s;
                        sum[2] += a[row] * c;
                        sum[3] += b[row] * c * c;
                    }
                    (s, c) = (s * c1 + c * s1, c * c1 - s * s1);
                }
            }
            let power = |v: &[f64; 4]| {
                let part = |num: f64, den: f64| if den > 0.0 { num * num / den } else { 0.0 };
                part(v[0], v[1]) + part(v[2], v[3])
            };
            // The strongest order; the lowest among equals.
            let best = (lo..=hi).fold(lo, |best, k| if power(&sums[k]) > power(&sums[best]) { k } else { best });
            Some(Family::Harmonic(j, best))
        })
        .collect()
}
