//! Intervals over realisations, the unit of independence (one physical world each): how sure an
//! answer is, so that a user can tell P = 0.95 from 0.91.
//!
//! - A probability over R worlds gets a Clopper-Pearson interval ([`clopper_pearson`]), exact for
//!   binary outcomes at any count. Where each world contributes the fraction of its repetitions
//!   that succeed (the repetitions of one world share its robot and pool: they are not independent
//!   draws), the interval is taken with R trials and R times the mean fraction successes: a fraction
//!   in [0, 1] with mean p has a variance of at most p (1 - p), so this is at worst the binary case.
//! - A median over worlds gets the distribution-free order-statistic interval ([`median_interval`]):
//!   the j-th and k-th smallest values, with j and k from Binomial(R, 1/2), exact for any continuous
//!   distribution, where a percentile bootstrap of a median has no such guarantee at small R.
//! - Two designs are compared on common worlds by their paired differences ([`Paired`]): the sign
//!   test (exact, distribution-free) decides whether they differ, and its inversion gives the
//!   interval of the median difference; the correlation of the pairs and the variance the pairing
//!   saves are reported beside it.
//! - A ratio of means over worlds with no exact interval (a budget's shares) gets a bootstrap-t
//!   interval over worlds ([`bootstrap_t`], [`ratio_of_means`]), second-order accurate where a
//!   percentile interval is first-order; its coverage of a skewed, correlated share is measured in
//!   tests/interval_coverage.rs.

use rand::RngExt;

/// `ln Gamma(x)` for `x > 0` (Lanczos, g = 7, 9 terms: relative error below 1e-15).
pub fn ln_gamma(x: f64) -> f64 {
    const G: f64 = 7.0;
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        // Reflection: Gamma(x) Gamma(1 - x) = pi / sin(pi x).
        return (std::f64::consts::PI / (std::f64::consts::PI * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut a = C[0];
    let t = x + G + 0.5;
    for (i, c) in C.iter().enumerate().skip(1) {
        a += c / (x + i as f64);
    }
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
}

/// The regularized incomplete beta function `I_x(a, b)` for `a, b > 0`, `0 <= x <= 1` (the
/// continued fraction of Numerical Recipes 6.4, by the modified Lentz method, on the side where it
/// converges fast).
pub fn incomplete_beta(a: f64, b: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    if x >= 1.0 {
        return 1.0;
    }
    let front = (ln_gamma(a + b) - ln_gamma(a) - ln_gamma(b) + a * x.ln() + b * (1.0 - x).ln()).exp();
    if x < (a + 1.0) / (a + b + 2.0) { front * beta_fraction(a, b, x) / a } else { 1.0 - front * beta_fraction(b, a, 1.0 - x) / b }
}

/// The continued fraction of [`incomplete_beta`].
fn beta_fraction(a: f64, b: f64, x: f64) -> f64 {
    const TINY: f64 = 1e-300;
    let (qab, qap, qam) = (a + b, a + 1.0, a - 1.0);
    let mut c = 1.0;
    let mut d = 1.0 - qab * x / qap;
    if d.abs() < TINY {
        d = TINY;
    }
    d = 1.0 / d;
    let mut h = d;
    for m in 1..10_000 {
        let m = m as f64;
        let m2 = 2.0 * m;
        for aa in [m * (b - m) * x / ((qam + m2) * (a + m2)), -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2))] {
            d = 1.0 + aa * d;
            if d.abs() < TINY {
                d = TINY;
            }
            c = 1.0 + aa / c;
            if c.abs() < TINY {
                c = TINY;
            }
            d = 1.0 / d;
            h *= d * c;
        }
        if (d * c - 1.0).abs() < 1e-16 {
            break;
        }
    }
    h
}

/// The `p` quantile of the Beta(a, b) distribution: the `x` with `I_x(a, b) = p`, by bisection to
/// the last bit (the incomplete beta is monotone in `x`).
pub fn beta_quantile(a: f64, b: f64, p: f64) -> f64 {
    let (mut lo, mut hi) = (0.0_f64, 1.0_f64);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        if incomplete_beta(a, b, mid) < p { lo = mid } else { hi = mid }
    }
    0.5 * (lo + hi)
}

/// `P(X <= k)` for `X ~ Binomial(n, p)`, `0 <= k`.
pub fn binomial_cdf(k: u64, n: u64, p: f64) -> f64 {
    if k >= n {
        return 1.0;
    }
    incomplete_beta((n - k) as f64, k as f64 + 1.0, 1.0 - p)
}

/// The two-sided Clopper-Pearson interval at `confidence` of a probability estimated as
/// `successes / trials` (`successes` may be fractional: see the module docs).
pub fn clopper_pearson(successes: f64, trials: f64, confidence: f64) -> (f64, f64) {
    let alpha = 1.0 - confidence;
    (clopper_pearson_lower(successes, trials, 1.0 - alpha / 2.0), clopper_pearson_upper(successes, trials, 1.0 - alpha / 2.0))
}

/// The one-sided lower Clopper-Pearson bound at `confidence` (`P >= bound` at that confidence).
pub fn clopper_pearson_lower(successes: f64, trials: f64, confidence: f64) -> f64 {
    if !(trials > 0.0) || successes <= 0.0 {
        return 0.0;
    }
    beta_quantile(successes, trials - successes + 1.0, 1.0 - confidence)
}

/// The one-sided upper Clopper-Pearson bound at `confidence`.
pub fn clopper_pearson_upper(successes: f64, trials: f64, confidence: f64) -> f64 {
    if !(trials > 0.0) {
        return 1.0;
    }
    if successes >= trials {
        return 1.0;
    }
    beta_quantile(successes + 1.0, trials - successes, confidence)
}

/// The ranks `(j, k)` (1-based, j <= k) of the order statistics that bound the median of `n`
/// values at `confidence` or more: the largest j with `P(Binomial(n, 1/2) < j) <= alpha / 2`, and
/// `k = n + 1 - j`. `None` when no such pair exists (n < 6 at 95 %: the interval is unbounded).
pub fn median_ranks(n: usize, confidence: f64) -> Option<(usize, usize)> {
    let alpha = 1.0 - confidence;
    let n64 = n as u64;
    // P(X <= j - 1) <= alpha / 2, the largest such j.
    let mut j = 0;
    while j < n && binomial_cdf(j as u64, n64, 0.5) <= alpha / 2.0 {
        j += 1;
    }
    (j >= 1).then_some((j, n + 1 - j))
}

/// The distribution-free interval of the median of `values` at `confidence` or more (finite
/// values only; `(-inf, inf)` when there are too few of them).
pub fn median_interval(values: &[f64], confidence: f64) -> (f64, f64) {
    let s = super::stats::finite_sorted(values);
    match median_ranks(s.len(), confidence) {
        Some((j, k)) => (s[j - 1], s[k - 1]),
        None => (f64::NEG_INFINITY, f64::INFINITY),
    }
}

/// The exact two-sided sign test of the differences `d` (zeros and NaN left out; an infinite
/// difference counts by its sign):
/// the counts of positive and negative differences and the p-value of "a positive and a negative
/// difference are equally likely".
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SignTest {
    /// Differences above zero.
    pub positive: usize,
    /// Differences below zero.
    pub negative: usize,
    /// Two-sided p-value.
    pub p_value: f64,
}

/// The sign test of `d` (see [`SignTest`]).
pub fn sign_test(d: &[f64]) -> SignTest {
    let positive = d.iter().filter(|x| **x > 0.0).count();
    let negative = d.iter().filter(|x| **x < 0.0).count();
    let n = (positive + negative) as u64;
    let p_value = if n == 0 { 1.0 } else { (2.0 * binomial_cdf(positive.min(negative) as u64, n, 0.5)).min(1.0) };
    SignTest { positive, negative, p_value }
}

/// Two designs compared on common worlds: `a - b` per world where both have a value (not NaN).
/// An infinite value is a value: a world a design fails in, scored +inf where smaller is better,
/// is its worst world, and it is compared as one (+inf against a finite value is a difference of
/// +inf, two infinities of one sign a tie); leaving such worlds out would compare a design that
/// fails in most worlds on the few it survives.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Paired {
    /// Worlds compared.
    pub n: usize,
    /// Mean difference over the worlds where both values are finite.
    pub mean: f64,
    /// Median difference and its interval at the confidence asked (the sign test inverted), over
    /// every world compared (either may be infinite).
    pub median: f64,
    /// See `median`.
    pub interval: (f64, f64),
    /// The sign test of the differences.
    pub test: SignTest,
    /// Pearson correlation of the pairs where both values are finite.
    pub correlation: f64,
    /// The variance the pairing saves: `1 - var(a - b) / (var(a) + var(b))` (0: no gain; near 1:
    /// the common worlds cancel almost all of the spread).
    pub variance_saving: f64,
}

impl Paired {
    /// The comparison of `a` and `b` (one value per world, in world order) at `confidence`.
    pub fn of(a: &[f64], b: &[f64], confidence: f64) -> Self {
        // Every world with two values; the difference of two equal infinities is a tie.
        let mut all: Vec<f64> =
            a.iter().zip(b).filter(|(x, y)| !x.is_nan() && !y.is_nan()).map(|(x, y)| if x == y { 0.0 } else { x - y }).collect();
        all.sort_by(f64::total_cmp);
        let n = all.len();
        let (median, interval) = match n {
            0 => (f64::NAN, (f64::NEG_INFINITY, f64::INFINITY)),
            _ => {
                let mid = if n % 2 == 1 { all[n / 2] } else { 0.5 * (all[n / 2 - 1] + all[n / 2]) };
                let ci = median_ranks(n, confidence).map_or((f64::NEG_INFINITY, f64::INFINITY), |(j, k)| (all[j - 1], all[k - 1]));
                (if mid.is_nan() { all[n / 2] } else { mid }, ci)
            }
        };
        let pairs: Vec<(f64, f64)> = a.iter().zip(b).filter(|(x, y)| x.is_finite() && y.is_finite()).map(|(x, y)| (*x, *y)).collect();
        let d: Vec<f64> = pairs.iter().map(|(x, y)| x - y).collect();
        let mean = if d.is_empty() { f64::NAN } else { d.iter().sum::<f64>() / d.len() as f64 };
        let nf = d.len();
        let var = |v: &[f64]| {
            let m = v.iter().sum::<f64>() / v.len() as f64;
            v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (v.len() as f64 - 1.0)
        };
        let (xa, xb): (Vec<f64>, Vec<f64>) = pairs.iter().copied().unzip();
        let (va, vb) = (var(&xa), var(&xb));
        let variance_saving = if nf > 1 && va + vb > 0.0 { 1.0 - var(&d) / (va + vb) } else { f64::NAN };
        let correlation = if nf > 1 { super::stats::pearson(&xa, &xb) } else { f64::NAN };
        Self { n, mean, median, interval, test: sign_test(&all), correlation, variance_saving }
    }

    /// Whether the two designs differ at `confidence` (the sign test rejects equality).
    pub fn separated(&self, confidence: f64) -> bool {
        self.test.p_value < 1.0 - confidence
    }
}

/// The bootstrap-t (studentized) interval at `confidence` of a statistic of `n` worlds whose
/// standard error can be estimated from the sample itself: `stat` takes the indices of a resample
/// and returns the estimate and its standard error (for a ratio of means, from the influence
/// values: see [`ratio_of_means`]). Second-order accurate where the percentile and BCa intervals
/// of a skewed ratio are only first-order accurate (coverage measured in tests/interval_coverage.rs).
pub fn bootstrap_t<R: rand::Rng + ?Sized>(
    n: usize,
    stat: impl Fn(&[usize]) -> (f64, f64),
    resamples: usize,
    confidence: f64,
    rng: &mut R,
) -> (f64, f64) {
    if n < 2 {
        return (f64::NEG_INFINITY, f64::INFINITY);
    }
    let all: Vec<usize> = (0..n).collect();
    let (theta, se) = stat(&all);
    if !(theta.is_finite() && se.is_finite()) {
        return (f64::NEG_INFINITY, f64::INFINITY);
    }
    let mut idx = vec![0; n];
    let mut t: Vec<f64> = (0..resamples)
        .filter_map(|_| {
            idx.iter_mut().for_each(|i| *i = rng.random_range(0..n));
            let (th, s) = stat(&idx);
            (th.is_finite() && s > 0.0).then(|| (th - theta) / s)
        })
        .collect();
    if t.len() < 10 {
        return (f64::NEG_INFINITY, f64::INFINITY);
    }
    t.sort_by(f64::total_cmp);
    let alpha = 1.0 - confidence;
    (theta - crate::numeric::quantile(&t, 1.0 - alpha / 2.0) * se, theta - crate::numeric::quantile(&t, alpha / 2.0) * se)
}

/// A ratio of means `mean(x[k][first]) / mean(sum_j x[k][j])` over the worlds `idx` of per-world
/// vectors `x` (the share of component `first`), with its standard error from the influence
/// values `(x_first - r s) / S` of each world.
pub fn ratio_of_means(x: &[Vec<f64>], first: usize, idx: &[usize]) -> (f64, f64) {
    let n = idx.len() as f64;
    let (mut m0, mut ms) = (0.0, 0.0);
    for &i in idx {
        m0 += x[i][first];
        ms += x[i].iter().sum::<f64>();
    }
    let (m0, ms) = (m0 / n, ms / n);
    let r = m0 / ms;
    let var = idx
        .iter()
        .map(|&i| {
            let v = (x[i][first] - r * x[i].iter().sum::<f64>()) / ms;
            v * v
        })
        .sum::<f64>()
        / (n * (n - 1.0));
    (r, var.sqrt())
}

/// The standard normal distribution function, `Phi(x) = erfc(-x / sqrt 2) / 2`.
pub fn normal_cdf(x: f64) -> f64 {
    0.5 * erfc(-x / std::f64::consts::SQRT_2)
}

/// The complementary error function by the Chebyshev expansion of Numerical Recipes (3rd ed.,
/// section 6.2.2, `erfccheb`: 28 coefficients, near full double precision).
fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 2.0 / (2.0 + z);
    let ty = 4.0 * t - 2.0;
    const COF: [f64; 28] = [
        -1.3026537197817094,
        6.4196979235649026e-1,
        1.9476473204185836e-2,
        -9.561514786808631e-3,
        -9.46595344482036e-4,
        3.66839497852761e-4,
        4.2523324806907e-5,
        -2.0278578112534e-5,
        -1.624290004647e-6,
        1.303655835580e-6,
        1.5626441722e-8,
        -8.5238095915e-8,
        6.529054439e-9,
        5.059343495e-9,
        -9.91364156e-10,
        -2.27365122e-10,
        9.6467911e-11,
        2.394038e-12,
        -6.886027e-12,
        8.94487e-13,
        3.13092e-13,
        -1.12708e-13,
        3.81e-16,
        7.106e-15,
        -1.523e-15,
        -9.4e-17,
        1.21e-16,
        -2.8e-17,
    ];
    let (mut d, mut dd) = (0.0, 0.0);
    for &c in COF.iter().skip(1).rev() {
        let tmp = d;
        d = ty * d - dd + c;
        dd = tmp;
    }
    let r = t * (-z * z + 0.5 * (COF[0] + ty * d) - dd).exp();
    if x >= 0.0 { r } else { 2.0 - r }
}

/// The `p` quantile of the standard normal distribution (bisection on [`normal_cdf`]).
pub fn normal_quantile(p: f64) -> f64 {
    let (mut lo, mut hi) = (-40.0_f64, 40.0_f64);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if normal_cdf(mid) < p { lo = mid } else { hi = mid }
    }
    0.5 * (lo + hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The incomplete beta against scipy.special.betainc 1.x (values printed by scipy, as
    /// `repr`), and its symmetry I_x(a, b) = 1 - I_{1-x}(b, a).
    #[test]
    fn incomplete_beta_matches_scipy_and_its_symmetry() {
        for (a, b, x, want) in [
            (2.5, 3.5, 0.4, 0.4869041915261176),
            (30.0, 0.7, 0.97, 0.26612537642784717),
            (0.5, 0.5, 0.01, 0.06376856085851985),
            (1.0, 1.0, 0.3, 0.3),
            (200.0, 3.0, 0.99, 0.6712381710383889),
            (10.7, 0.3, 0.5, 5.824433982537556e-05),
        ] {
            let got = incomplete_beta(a, b, x);
            assert!((got - want).abs() <= 1e-12 * want.max(1e-3), "I_{x}({a}, {b}) = {got}, scipy {want}");
            assert!((got - (1.0 - incomplete_beta(b, a, 1.0 - x))).abs() < 1e-13);
        }
    }

    /// A design that fails (+inf, smaller is better) in 8 of 10 worlds against one that never
    /// fails: its failed worlds are 8 differences of +inf, the sign test over all 10 worlds
    /// separates the two (10 of 10 positive: p = 2 / 1024), and the median difference is +inf.
    /// With the failures left out it would be 2 worlds and no evidence. Two failures in one world
    /// are a tie; a NaN world is left out.
    #[test]
    fn a_paired_comparison_counts_the_worlds_a_design_fails_in() {
        let leader: Vec<f64> = (0..10).map(|i| 0.3 + 0.01 * f64::from(i)).collect();
        let mut other: Vec<f64> = leader.iter().map(|x| x + 0.05).collect();
        for v in other.iter_mut().take(8) {
            *v = f64::INFINITY;
        }
        let p = Paired::of(&other, &leader, 0.95);
        assert_eq!((p.n, p.test.positive, p.test.negative), (10, 10, 0));
        assert!((p.test.p_value - 2.0 / 1024.0).abs() < 1e-15 && p.separated(0.95));
        assert_eq!(p.median, f64::INFINITY);
        assert!((p.mean - 0.05).abs() < 1e-12, "mean over the 2 finite pairs: {}", p.mean);
        let mut both = leader.clone();
        both[0] = f64::INFINITY;
        both[1] = f64::NAN;
        let q = Paired::of(&other, &both, 0.95);
        assert_eq!((q.n, q.test.positive + q.test.negative), (9, 8), "world 0 a tie, world 1 left out");
    }

    /// The binomial distribution function equals the direct sum of the probabilities.
    #[test]
    fn binomial_cdf_is_the_sum_of_the_probabilities() {
        for n in [1u64, 5, 20, 73, 200] {
            for p in [0.03, 0.5, 0.91] {
                let mut sum = 0.0;
                for k in 0..=n {
                    let ln_choose = ln_gamma(n as f64 + 1.0) - ln_gamma(k as f64 + 1.0) - ln_gamma((n - k) as f64 + 1.0);
                    sum += (ln_choose + k as f64 * f64::ln(p) + (n - k) as f64 * f64::ln(1.0 - p)).exp();
                    assert!((binomial_cdf(k, n, p) - sum.min(1.0)).abs() < 1e-11, "n {n} p {p} k {k}");
                }
            }
        }
    }

    /// Clopper-Pearson bounds against scipy.stats.beta.ppf (two-sided 95 %, and a one-sided 90 %
    /// lower bound), fractional successes included.
    #[test]
    fn clopper_pearson_matches_scipy() {
        for (k, n, lo, hi) in [
            (0.0, 10.0, 0.0, 0.3084971078187607),
            (8.0, 10.0, 0.4439045376923585, 0.9747892736731666),
            (10.0, 10.0, 0.6915028921812392, 1.0),
            (19.0, 20.0, 0.7512672372279722, 0.9987349105020502),
            (95.0, 100.0, 0.8871650888945373, 0.9835681208179479),
            (9.7, 10.0, 0.6464326745630133, 0.9999996923137285),
        ] {
            let (a, b) = clopper_pearson(k, n, 0.95);
            assert!((a - lo).abs() < 1e-10 && (b - hi).abs() < 1e-10, "{k}/{n}: ({a}, {b}) against ({lo}, {hi})");
        }
        assert!((clopper_pearson_lower(97.0, 100.0, 0.90) - 0.9344142484971082).abs() < 1e-10);
    }

    /// The normal quantile inverts the distribution function, and Phi(1.959964) = 0.975.
    #[test]
    fn normal_quantile_inverts_the_distribution() {
        assert!((normal_cdf(1.959963984540054) - 0.975).abs() < 1e-7);
        for p in [1e-6, 0.025, 0.3, 0.5, 0.9, 0.999] {
            assert!((normal_cdf(normal_quantile(p)) - p).abs() < 1e-7 * p.max(1e-3), "{p}");
        }
    }

    /// The median's order statistics: 95 % needs six values (ranks 1 and 6), and the ranks of 20
    /// values are 6 and 15 (the binomial table).
    #[test]
    fn median_ranks_follow_the_binomial_table() {
        assert_eq!(median_ranks(5, 0.95), None);
        assert_eq!(median_ranks(6, 0.95), Some((1, 6)));
        assert_eq!(median_ranks(20, 0.95), Some((6, 15)));
        assert_eq!(median_ranks(100, 0.95), Some((40, 61)));
    }

    /// The sign test: 9 of 10 positive is p = 0.0215 (exact), all tied is p = 1.
    #[test]
    fn sign_test_is_exact() {
        let mut d = vec![1.0; 9];
        d.push(-1.0);
        let t = sign_test(&d);
        assert_eq!((t.positive, t.negative), (9, 1));
        assert!((t.p_value - 22.0 / 1024.0).abs() < 1e-12);
        assert_eq!(sign_test(&[0.0, 0.0]).p_value, 1.0);
    }
}
