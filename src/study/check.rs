//! One band and one check row for every published figure of every study.

use std::fmt::Write as _;

use serde::Deserialize;

/// A figure with its published value and the relative band the reproduction must fall in.
#[derive(Clone, Copy, Debug, Deserialize, serde::Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Band {
    /// Published value.
    pub value: f64,
    /// Allowed relative deviation (0.2 = +-20 %).
    pub tolerance: f64,
}

impl Band {
    /// Whether `x` lies in the band.
    pub fn contains(&self, x: f64) -> bool {
        (x - self.value).abs() <= self.tolerance * self.value.abs()
    }
}

/// What a figure must satisfy.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Bound {
    /// Within a relative band of the published value.
    Band(Band),
    /// At least this.
    AtLeast(f64),
    /// At most this.
    AtMost(f64),
    /// Strictly below this.
    Below(f64),
}

impl Bound {
    /// Whether `x` satisfies the bound.
    pub fn holds(&self, x: f64) -> bool {
        match *self {
            Bound::Band(b) => b.contains(x),
            Bound::AtLeast(m) => x >= m,
            Bound::AtMost(m) => x <= m,
            Bound::Below(m) => x < m,
        }
    }
}

/// How a rule's bound reads in a table.
pub fn describe(b: &Bound) -> String {
    match b {
        Bound::Band(b) => format!("{:.3} +-{:.0} %", b.value, b.tolerance * 100.0),
        Bound::AtLeast(m) => format!(">= {m}"),
        Bound::AtMost(m) => format!("<= {m}"),
        Bound::Below(m) => format!("< {m}"),
    }
}

/// One line of the published-versus-reproduced comparison.
#[derive(Clone, Debug)]
pub struct Check {
    /// Figure.
    pub figure: String,
    /// Published value (or rule).
    pub published: String,
    /// The published value as a number, where the paper prints one.
    pub published_value: Option<f64>,
    /// Reproduced value.
    pub reproduced: String,
    /// The reproduced value as a number (the quantity the bound applies to).
    pub value: f64,
    /// Band or rule.
    pub band: String,
    /// The bound the scenario sets, if any.
    pub bound: Option<Bound>,
    /// Passed, or `None` when the scenario sets no band for it.
    pub pass: Option<bool>,
}

impl Check {
    /// A figure compared with its published value within an optional relative band.
    pub fn band(figure: &str, published: f64, value: f64, band: Option<Band>) -> Self {
        Self {
            published: format!("{published:.3}"),
            published_value: Some(published),
            ..Self::rule(figure, "", value, format!("{value:.3}"), band.map(Bound::Band), |b| match b {
                Bound::Band(b) => format!("{:.3} +-{:.0} %", b.value, b.tolerance * 100.0),
                other => format!("{other:?}"),
            })
        }
    }

    /// A figure checked by a rule: `describe` writes the bound when one is set.
    pub fn rule(
        figure: &str,
        published: &str,
        value: f64,
        reproduced: String,
        bound: Option<Bound>,
        describe: impl Fn(&Bound) -> String,
    ) -> Self {
        Self {
            figure: figure.into(),
            published: published.into(),
            published_value: None,
            reproduced,
            value,
            band: bound.as_ref().map(&describe).unwrap_or_else(|| "-".into()),
            bound,
            pass: bound.map(|b| b.holds(value)),
        }
    }

    /// A figure reported without a check.
    pub fn report(figure: &str, published: &str, value: f64, reproduced: String) -> Self {
        Self::rule(figure, published, value, reproduced, None, |_| String::new())
    }

    /// The verdict as a word: `pass`, `miss` or `-`.
    pub fn verdict(&self) -> &'static str {
        match self.pass {
            Some(true) => "pass",
            Some(false) => "miss",
            None => "-",
        }
    }
}

/// Figures checked and figures missed.
pub fn tally(rows: &[Check]) -> (usize, usize) {
    (rows.iter().filter(|r| r.pass.is_some()).count(), rows.iter().filter(|r| r.pass == Some(false)).count())
}

/// One figure over realisations: the rule of a distribution check.
#[derive(Clone, Debug)]
pub struct DistributionCheck {
    /// The row of realisation 0 (the plain run): figure, published value, bound.
    pub row: Check,
    /// Median, P10 and P90 of the figure over the realisations.
    pub median: f64,
    /// See `median`.
    pub p10: f64,
    /// See `median`.
    pub p90: f64,
    /// Realisations with a finite value.
    pub count: usize,
    /// Passed: the median within the bound, and the published value (where the paper prints one
    /// and the row has a band) within P10-P90; `None` without a bound.
    pub pass: Option<bool>,
}

/// The distribution checks of the same rows computed in several realisations (`runs[r][i]` is row
/// i of realisation r; every realisation has the rows of the first).
pub fn over_realisations(runs: &[Vec<Check>]) -> Vec<DistributionCheck> {
    let Some(first) = runs.first() else { return Vec::new() };
    first
        .iter()
        .enumerate()
        .map(|(i, row)| {
            let values: Vec<f64> = runs.iter().filter_map(|r| r.get(i)).map(|c| c.value).collect();
            let sorted = crate::study::stats::finite_sorted(&values);
            let q = |p: f64| crate::study::stats::quantile(&sorted, p);
            let (median, p10, p90) = (q(0.5), q(0.1), q(0.9));
            let pass = row.bound.map(|b| {
                let covered = match (b, row.published_value) {
                    (Bound::Band(_), Some(p)) => p10 <= p && p <= p90,
                    _ => true,
                };
                b.holds(median) && covered
            });
            DistributionCheck { row: row.clone(), median, p10, p90, count: sorted.len(), pass }
        })
        .collect()
}

/// The published-versus-reproduced table of a summary, under a heading.
pub fn checks_markdown(heading: &str, checks: &[Check]) -> String {
    let mut s = format!("## {heading}\n\n| figure | published | calsim | band | result |\n|---|---|---|---|---|\n");
    for c in checks {
        let v = if c.pass == Some(false) { "**miss**" } else { c.verdict() };
        let _ = writeln!(s, "| {} | {} | {} | {} | {} |", c.figure, c.published, c.reproduced, c.band, v);
    }
    s
}

/// The comparison as a text table for the terminal (columns as wide as their widest cell).
pub fn terminal_table(rows: &[Check]) -> String {
    let width = |head: &str, f: &dyn Fn(&Check) -> usize| rows.iter().map(f).max().unwrap_or(0).max(head.len());
    let wf = width("figure", &|r| r.figure.chars().count());
    let wp = width("published", &|r| r.published.chars().count());
    let wc = width("calsim", &|r| r.reproduced.chars().count()).max(10);
    let wb = width("band", &|r| r.band.chars().count());
    let mut s = String::new();
    let _ = writeln!(s, "{:<wf$}  {:>wp$}  {:>wc$}  {:>wb$}  result", "figure", "published", "calsim", "band");
    for r in rows {
        let verdict = if r.pass == Some(false) { "MISS" } else { r.verdict() };
        let _ = writeln!(s, "{:<wf$}  {:>wp$}  {:>wc$}  {:>wb$}  {verdict}", r.figure, r.published, r.reproduced, r.band);
    }
    s
}

/// `v` written in the form of `like`, a row's reproduced value: `+54.1 %` (a fraction shown in
/// percent, sign kept), `29 of 31` (a count: whole, or one decimal for a quantile between counts),
/// `6.54` (as many decimals); a value with no such form as `0.123`.
pub fn in_the_form_of(like: &str, v: f64) -> String {
    if !v.is_finite() {
        return "-".into();
    }
    let t = like.trim();
    let number_end = t.find(|c: char| !(c.is_ascii_digit() || c == '.' || c == '+' || c == '-')).unwrap_or(t.len());
    let (number, suffix) = t.split_at(number_end);
    if number.parse::<f64>().is_err() {
        return format!("{v:.3}");
    }
    let decimals = number.split_once('.').map_or(0, |(_, d)| d.len());
    let signed = number.starts_with('+');
    let (x, decimals) = if suffix.trim_start().starts_with('%') {
        (100.0 * v, decimals)
    } else if suffix.trim_start().starts_with("of ") && decimals == 0 && (v - v.round()).abs() > 1e-9 {
        (v, 1)
    } else {
        (v, decimals)
    };
    let n = if signed { format!("{x:+.decimals$}") } else { format!("{x:.decimals$}") };
    format!("{n}{suffix}")
}

/// The figures over realisations as a text table for the terminal: the median and P10-P90 in the
/// form of the run-0 value (percent, counts, decimals), columns as wide as their widest cell.
pub fn distribution_table(rows: &[DistributionCheck]) -> String {
    let cells: Vec<[String; 6]> = rows
        .iter()
        .map(|d| {
            let like = &d.row.reproduced;
            let (lo, hi) = (in_the_form_of(like, d.p10), in_the_form_of(like, d.p90));
            // One suffix for the range: `29-30 of 31`, `+21.8 to +48.9 %`.
            let suffix = |s: &str| s.find(' ').map_or(String::new(), |i| s[i..].to_string());
            let number = |s: &str| s.split(' ').next().unwrap_or("").to_string();
            let sep = if number(&lo).starts_with('+') || number(&hi).starts_with('-') { " to " } else { "-" };
            let range = format!("{}{sep}{}{}", number(&lo), number(&hi), suffix(&hi));
            [
                d.row.figure.clone(),
                d.row.published_value.map_or_else(|| d.row.published.clone(), |v| format!("{v:.3}")),
                like.clone(),
                in_the_form_of(like, d.median),
                range,
                d.row.band.clone(),
            ]
        })
        .collect();
    let head = ["figure", "published", "run 0", "median", "P10-P90", "band"];
    let w: Vec<usize> = (0..6).map(|k| cells.iter().map(|c| c[k].chars().count()).max().unwrap_or(0).max(head[k].len())).collect();
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{:<a$}  {:>b$}  {:>c$}  {:>d$}  {:>e$}  {:>f$}  result",
        head[0],
        head[1],
        head[2],
        head[3],
        head[4],
        head[5],
        a = w[0],
        b = w[1],
        c = w[2],
        d = w[3],
        e = w[4],
        f = w[5]
    );
    for (d, c) in rows.iter().zip(&cells) {
        let verdict = match d.pass {
            Some(true) => "pass",
            Some(false) => "MISS",
            None => "-",
        };
        let _ = writeln!(
            s,
            "{:<a$}  {:>b$}  {:>c$}  {:>d$}  {:>e$}  {:>f$}  {verdict}",
            c[0],
            c[1],
            c[2],
            c[3],
            c[4],
            c[5],
            a = w[0],
            b = w[1],
            c = w[2],
            d = w[3],
            e = w[4],
            f = w[5]
        );
    }
    s
}

#[cfg(test)]
mod form_tests {
    use super::in_the_form_of;

    #[test]
    fn values_over_realisations_are_written_in_the_form_of_run_0() {
        assert_eq!(in_the_form_of("+54.1 %", 0.281), "+28.1 %");
        assert_eq!(in_the_form_of("100 %", 0.99), "99 %");
        assert_eq!(in_the_form_of("29 of 31", 30.0), "30 of 31");
        assert_eq!(in_the_form_of("29 of 31", 29.2), "29.2 of 31");
        assert_eq!(in_the_form_of("6.54", 4.0931), "4.09");
        assert_eq!(in_the_form_of("0.646", 0.5481), "0.548");
        assert_eq!(in_the_form_of("fails", 0.5), "0.500");
    }
}
