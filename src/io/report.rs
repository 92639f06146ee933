//! The paper's figures computed from a study, side by side with the published ones, and the
//! checks of a scenario's `[expect]` table.

use std::fmt::Write as _;

use crate::io::scenario::{Band, ExpectSpec};
use crate::robot::builtin::{TABLE7_MEANS, TABLE7_STD};
use crate::robot::{ParamId, RobotModel};
use crate::study::StudyResults;
use crate::study::stats::{ErrorStats, iqr, median, pearson};

/// Statistics of one identified parameter over the repetitions at the table set size.
#[derive(Clone, Debug)]
pub struct ParamStats {
    /// Name.
    pub name: String,
    /// Unit shown.
    pub unit: &'static str,
    /// Injected truth.
    pub truth: f64,
    /// Mean, standard deviation, minimum, maximum of the identified values.
    pub mean: f64,
    /// Standard deviation.
    pub std: f64,
    /// Minimum.
    pub min: f64,
    /// Maximum.
    pub max: f64,
    /// Published Table 7 (mean, std) when the paper lists the parameter.
    pub published: Option<(f64, f64)>,
}

impl ParamStats {
    /// Whether the spread is within a factor 3 of the published one (allowing for the printed rounding).
    pub fn std_within_factor3(&self) -> Option<bool> {
        self.published.map(|(_, p)| {
            let (lo, hi) = ((p - 0.0005).max(0.0), p + 0.0005);
            self.std >= lo / 3.0 && self.std <= hi * 3.0
        })
    }

    /// Whether the mean is within 3 published standard deviations of the truth.
    pub fn mean_within_3std(&self) -> Option<bool> {
        self.published.map(|(_, p)| (self.mean - self.truth).abs() <= 3.0 * p.max(0.0005))
    }
}

/// Validation figures per set size (Figs. 8-9).
#[derive(Clone, Debug)]
pub struct SizeStats {
    /// Set size.
    pub n: usize,
    /// Median over repetitions of the mean error, mm.
    pub median_of_means: f64,
    /// Interquartile range over repetitions of the mean error, mm.
    pub iqr_of_means: f64,
    /// Median over repetitions of the error's standard deviation, mm.
    pub median_of_stds: f64,
    /// Identifications that did not converge.
    pub not_converged: usize,
}

/// Everything the summary and the checks need.
#[derive(Clone, Debug)]
pub struct Figures {
    /// Before calibration over the validation poses.
    pub before: ErrorStats,
    /// Set size of Tables 7-8.
    pub table_n: usize,
    /// Medians over repetitions at the table size of: mean, median, std, max error, mm.
    pub after_mean: f64,
    /// Median of per-set medians.
    pub after_median: f64,
    /// Median of per-set standard deviations.
    pub after_std: f64,
    /// Median of per-set maxima.
    pub after_max: f64,
    /// Table 7 statistics.
    pub table7: Vec<ParamStats>,
    /// Per set size.
    pub sizes: Vec<SizeStats>,
    /// Pearson r of error after calibration against distance to the base (Fig. 11).
    pub r_base: f64,
    /// Pearson r against distance to the centre of the calibration zone (Fig. 12).
    pub r_ccz: f64,
}

impl Figures {
    /// Computes the figures of a study; `truth` gives the injected values.
    pub fn of(results: &StudyResults, truth: &RobotModel, table_n: usize) -> Self {
        let at_n: Vec<_> = results.tasks.iter().filter(|t| t.task.set_size == table_n && t.outcome != "rank_deficient").collect();
        let med = |f: &dyn Fn(&crate::study::TaskResult) -> f64| median(&at_n.iter().map(|t| f(t)).collect::<Vec<_>>());
        let table7 = results
            .set
            .ids()
            .iter()
            .enumerate()
            .map(|(j, id)| {
                let unit = id.unit();
                let vals: Vec<f64> = at_n.iter().filter_map(|t| t.values[j]).map(|v| unit.from_internal(v)).collect();
                let s = ErrorStats::of(&vals);
                let k = TABLE7_MEANS.iter().position(|(n, _)| *n == id.name());
                ParamStats {
                    name: id.name(),
                    unit: unit.symbol(),
                    truth: unit.from_internal(id.get(truth.data())),
                    mean: s.mean,
                    std: s.std,
                    min: vals.iter().copied().fold(f64::INFINITY, f64::min),
                    max: s.max,
                    published: k.map(|k| (TABLE7_MEANS[k].1, TABLE7_STD[k])),
                }
            })
            .collect();
        let mut ns: Vec<usize> = results.tasks.iter().map(|t| t.task.set_size).collect();
        ns.dedup();
        let sizes = ns
            .iter()
            .map(|&n| {
                let ts: Vec<_> = results.tasks.iter().filter(|t| t.task.set_size == n).collect();
                let means: Vec<f64> = ts.iter().filter(|t| t.outcome != "rank_deficient").map(|t| t.validation.mean).collect();
                let stds: Vec<f64> = ts.iter().filter(|t| t.outcome != "rank_deficient").map(|t| t.validation.std).collect();
                SizeStats { n, median_of_means: median(&means), iqr_of_means: iqr(&means), median_of_stds: median(&stds), not_converged: ts.iter().filter(|t| t.outcome != "converged").count() }
            })
            .collect();
        let (mut e, mut db, mut dc) = (Vec::new(), Vec::new(), Vec::new());
        for t in &at_n {
            if let Some(errs) = &t.errors {
                e.extend_from_slice(errs);
                db.extend_from_slice(&results.distance_to_base_mm);
                dc.extend_from_slice(&results.distance_to_ccz_mm);
            }
        }
        Self {
            before: ErrorStats::of(&results.before_errors),
            table_n,
            after_mean: med(&|t| t.validation.mean),
            after_median: med(&|t| t.validation.median),
            after_std: med(&|t| t.validation.std),
            after_max: med(&|t| t.validation.max),
            table7,
            sizes,
            r_base: pearson(&db, &e),
            r_ccz: pearson(&dc, &e),
        }
    }

    /// Table 7 parameters with a published spread, and how many pass each rule.
    pub fn table7_counts(&self) -> (u32, u32, u32) {
        let listed = self.table7.iter().filter(|p| p.published.is_some()).count() as u32;
        let std_ok = self.table7.iter().filter(|p| p.std_within_factor3() == Some(true)).count() as u32;
        let mean_ok = self.table7.iter().filter(|p| p.mean_within_3std() == Some(true)).count() as u32;
        (listed, std_ok, mean_ok)
    }

    /// Largest relative rise of the median of mean errors between consecutive set sizes.
    pub fn fig8_max_rise(&self) -> f64 {
        self.sizes.windows(2).map(|w| (w[1].median_of_means - w[0].median_of_means) / w[0].median_of_means).fold(f64::NEG_INFINITY, f64::max)
    }

    /// Spread of the mean error at the smallest set size over that at the largest.
    pub fn fig9_spread_ratio(&self) -> f64 {
        match (self.sizes.first(), self.sizes.last()) {
            (Some(a), Some(b)) => a.iqr_of_means / b.iqr_of_means,
            _ => f64::NAN,
        }
    }
}

/// One line of the published-versus-reproduced comparison.
#[derive(Clone, Debug)]
pub struct Check {
    /// Figure.
    pub figure: String,
    /// Published value (or rule).
    pub published: String,
    /// Reproduced value.
    pub reproduced: String,
    /// Band or rule.
    pub band: String,
    /// Passed, or `None` when the scenario sets no band for it.
    pub pass: Option<bool>,
}

pub(crate) fn band_row(figure: &str, published: f64, value: f64, band: Option<Band>) -> Check {
    Check {
        figure: figure.into(),
        published: format!("{published:.3}"),
        reproduced: format!("{value:.3}"),
        band: band.map(|b| format!("{:.3} +-{:.0} %", b.value, b.tolerance * 100.0)).unwrap_or_else(|| "-".into()),
        pass: band.map(|b| b.contains(value)),
    }
}

/// The comparison rows for a scenario's `[expect]` table (rows without a band are reported only).
pub fn checks(f: &Figures, expect: &ExpectSpec) -> Vec<Check> {
    let (listed, std_ok, mean_ok) = f.table7_counts();
    let rise = f.fig8_max_rise();
    let ratio = f.fig9_spread_ratio();
    vec![
        band_row("before calibration: mean error, mm", 2.628, f.before.mean, expect.before_mean_mm),
        band_row("before calibration: max error, mm", 6.282, f.before.max, expect.before_max_mm),
        band_row(&format!("after, sets of {}: median error, mm (Table 8)", f.table_n), 0.208, f.after_median, expect.after_median_mm),
        band_row(&format!("after, sets of {}: std of error, mm (Table 8)", f.table_n), 0.084, f.after_std, expect.after_std_mm),
        band_row(&format!("after, sets of {}: max error, mm (Table 8)", f.table_n), 0.482, f.after_max, expect.after_max_mm),
        Check {
            figure: "Table 7: std within a factor 3 of the published".into(),
            published: format!("{listed} parameters"),
            reproduced: format!("{std_ok} of {listed}"),
            band: expect.table7_std_within_factor3_min.map(|m| format!(">= {m}")).unwrap_or_else(|| "-".into()),
            pass: expect.table7_std_within_factor3_min.map(|m| std_ok >= m),
        },
        Check {
            figure: "Table 7: mean within 3 published std of the truth".into(),
            published: format!("{listed} parameters"),
            reproduced: format!("{mean_ok} of {listed}"),
            band: expect.table7_mean_within_3std_min.map(|m| format!(">= {m}")).unwrap_or_else(|| "-".into()),
            pass: expect.table7_mean_within_3std_min.map(|m| mean_ok >= m),
        },
        Check {
            figure: "Fig. 8: largest rise of the median mean error with n".into(),
            published: "does not rise".into(),
            reproduced: format!("{:+.1} %", rise * 100.0),
            band: expect.fig8_max_rise.map(|m| format!("<= {:+.0} %", m * 100.0)).unwrap_or_else(|| "-".into()),
            pass: expect.fig8_max_rise.map(|m| rise <= m),
        },
        Check {
            figure: "Figs. 8-9: spread of the mean error, smallest n / largest n".into(),
            published: "shrinks with n".into(),
            reproduced: format!("{ratio:.2}"),
            band: expect.fig9_spread_ratio_min.map(|m| format!(">= {m}")).unwrap_or_else(|| "-".into()),
            pass: expect.fig9_spread_ratio_min.map(|m| ratio >= m),
        },
        Check {
            figure: "Fig. 12: |r| error vs distance to the CCZ".into(),
            published: "no linear relation".into(),
            reproduced: format!("{:.3}", f.r_ccz.abs()),
            band: expect.fig12_abs_r_max.map(|m| format!("< {m}")).unwrap_or_else(|| "-".into()),
            pass: expect.fig12_abs_r_max.map(|m| f.r_ccz.abs() < m),
        },
        Check { figure: "Fig. 11: r error vs distance to the base".into(), published: "weak relation".into(), reproduced: format!("{:.3}", f.r_base), band: "-".into(), pass: None },
    ]
}

/// The comparison as a text table for the terminal.
pub fn terminal_table(rows: &[Check]) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "{:<58} {:>20} {:>12} {:>16}  result", "figure", "published", "calsim", "band");
    for r in rows {
        let verdict = match r.pass {
            Some(true) => "pass",
            Some(false) => "MISS",
            None => "-",
        };
        let _ = writeln!(s, "{:<58} {:>20} {:>12} {:>16}  {verdict}", r.figure, r.published, r.reproduced, r.band);
    }
    s
}

/// The paper's name of a parameter, for tables.
pub fn display_name(name: &str) -> String {
    ParamId::parse(name).map(|id| id.name()).unwrap_or_else(|| name.to_string())
}
