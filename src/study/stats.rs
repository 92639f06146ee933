//! Descriptive statistics of error samples.

/// Statistics of a sample of absolute position errors, mm.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct ErrorStats {
    /// Mean, mm.
    pub mean: f64,
    /// Median, mm.
    pub median: f64,
    /// Sample standard deviation, mm.
    pub std: f64,
    /// 95th percentile (linear interpolation), mm.
    pub p95: f64,
    /// Maximum, mm.
    pub max: f64,
    /// Root mean square, mm.
    pub rms: f64,
}

impl ErrorStats {
    /// Statistics of `values` (empty: all zero).
    pub fn of(values: &[f64]) -> Self {
        if values.is_empty() {
            return Self::default();
        }
        let n = values.len() as f64;
        let mean = values.iter().sum::<f64>() / n;
        let var = if values.len() > 1 { values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0) } else { 0.0 };
        // The order statistics by selection (those of the sorted sample, in linear time: a
        // prediction pools millions of draws).
        let mut scratch = values.to_vec();
        Self {
            mean,
            median: crate::numeric::quantile_selected(&mut scratch, 0.5),
            std: var.sqrt(),
            p95: crate::numeric::quantile_selected(&mut scratch, 0.95),
            max: values.iter().copied().max_by(f64::total_cmp).expect("a value"),
            rms: (values.iter().map(|v| v * v).sum::<f64>() / n).sqrt(),
        }
    }
}

pub use crate::numeric::quantile;

/// The finite values of a sample, ascending: the sample every order statistic below is taken of.
/// A value that is NaN or infinite (a condition number of a rank-deficient fit, a figure of a run
/// that produced none) is not a draw of the quantity and is left out.
pub fn finite_sorted(values: &[f64]) -> Vec<f64> {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    v
}

/// Median of the finite values of an unsorted sample (mean of the middle two for even sizes);
/// NaN when there are none.
pub fn median(values: &[f64]) -> f64 {
    quantile(&finite_sorted(values), 0.5)
}

/// Interquartile range of the finite values of an unsorted sample; NaN when there are none.
pub fn iqr(values: &[f64]) -> f64 {
    let v = finite_sorted(values);
    quantile(&v, 0.75) - quantile(&v, 0.25)
}

/// Pearson correlation coefficient.
pub fn pearson(x: &[f64], y: &[f64]) -> f64 {
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for (a, b) in x.iter().zip(y) {
        sxy += (a - mx) * (b - my);
        sxx += (a - mx) * (a - mx);
        syy += (b - my) * (b - my);
    }
    sxy / (sxx * syy).sqrt()
}

/// Least-squares line `y = a + b x`: (a, b).
pub fn regression(x: &[f64], y: &[f64]) -> (f64, f64) {
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let sxy: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
    let sxx: f64 = x.iter().map(|a| (a - mx) * (a - mx)).sum();
    let b = sxy / sxx;
    (my - b * mx, b)
}
