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
    /// Why the figure lies outside what the model simulates (a figure of another study's
    /// instrument), shown instead of a comparison of one world with the band.
    pub scope: Option<String>,
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
            scope: None,
        }
    }

    /// The figure marked as outside the model's scope, with the reason shown beside it: reported
    /// with its band as written, never judged (it counts neither as checked nor as missed, in one
    /// world or over worlds).
    pub fn outside_scope(mut self, why: &str) -> Self {
        self.scope = Some(why.into());
        self.bound = None;
        self.pass = None;
        self
    }

    /// What one world says of the figure: `in band`, `outside band`, the reason it lies outside
    /// the model's scope, or `-` without a bound. One world is one draw: no verdict.
    pub fn this_world(&self) -> &str {
        match (&self.scope, self.pass) {
            (Some(why), _) => why,
            (None, Some(true)) => "in band",
            (None, Some(false)) => "outside band",
            (None, None) => "-",
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

/// The verdict on one figure over realisations.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// The interval of the median lies within the bound.
    Pass,
    /// The interval straddles the bound's edge: no evidence either way at these realisations
    /// (the gate passes it: it fails only on evidence).
    Open,
    /// The interval lies wholly outside the bound: evidence that the model's median misses it.
    Miss,
    /// Too few worlds gave the figure for a bounded interval at the confidence asked: no evidence
    /// was collected, and the gate fails it (a check that cannot judge must not pass).
    Unresolved,
}

impl Verdict {
    /// The verdict as a word.
    pub fn word(self) -> &'static str {
        match self {
            Verdict::Pass => "pass",
            Verdict::Open => "open",
            Verdict::Miss => "MISS",
            Verdict::Unresolved => "UNRESOLVED",
        }
    }
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
    /// The distribution-free interval of the median at `confidence` (order statistics).
    pub interval: (f64, f64),
    /// The confidence of `interval` (see [`over_realisations`]).
    pub confidence: f64,
    /// Realisations with a finite value.
    pub count: usize,
    /// Worlds asked for that gave no finite value (the study failed, or the figure was not finite).
    pub missing: usize,
    /// The published value (where the paper prints one) within P10-P90 of the realisations:
    /// reported, not part of the verdict.
    pub covers_published: Option<bool>,
    /// The verdict, `None` without a bound.
    pub verdict: Option<Verdict>,
    /// Passed the gate (neither [`Verdict::Miss`] nor [`Verdict::Unresolved`]), `None` without a
    /// bound.
    pub pass: Option<bool>,
}

/// Where the interval `(lo, hi)` lies against `b`.
fn judge(b: &Bound, (lo, hi): (f64, f64)) -> Verdict {
    let (inside, outside) = match *b {
        Bound::Band(band) => {
            let (a, z) = (band.value - band.tolerance * band.value.abs(), band.value + band.tolerance * band.value.abs());
            (lo >= a && hi <= z, hi < a || lo > z)
        }
        Bound::AtLeast(m) => (lo >= m, hi < m),
        Bound::AtMost(m) => (hi <= m, lo > m),
        Bound::Below(m) => (hi < m, lo >= m),
    };
    if outside {
        Verdict::Miss
    } else if inside {
        Verdict::Pass
    } else {
        Verdict::Open
    }
}

/// The distribution checks of the same rows computed in several realisations (`runs[r][i]` is row
/// i of realisation r; every realisation has the rows of the first), out of `worlds` asked for (a
/// world whose study failed has no row), judged as a test whose false-alarm rate is at most
/// `false_alarm`.
///
/// Each bounded figure's median over the worlds gets its distribution-free interval; a figure
/// misses only when that interval lies wholly outside its bound. With k bounded figures and
/// `a = false_alarm`, a one-sided bound's interval has confidence `1 - 2a/k`: when the model's
/// true median satisfies the bound, the interval lies beyond it with probability at most `a/k`. A
/// band can be missed on either side, `a/k` each at that confidence, so a band's interval has
/// confidence `1 - a/k`. Over the k figures a false alarm has probability at most `a`
/// (Bonferroni), for any seed and any number of worlds.
///
/// A world without a finite value (its study failed, or the figure is NaN or infinite in it) is
/// not left out, which would judge only the worlds that went well: the interval's lower end is
/// taken with such worlds below every value, its upper end with them above every value, so they
/// can neither produce a miss nor a pass. An interval left unbounded (too few worlds for the
/// confidence, or too many without a value) is [`Verdict::Unresolved`], a failure of the gate.
pub fn over_realisations(runs: &[Vec<Check>], worlds: usize, false_alarm: f64) -> Vec<DistributionCheck> {
    let Some(first) = runs.first() else { return Vec::new() };
    let k = first.iter().filter(|r| r.bound.is_some()).count().max(1);
    let worlds = worlds.max(runs.len());
    first
        .iter()
        .enumerate()
        .map(|(i, row)| {
            let values: Vec<f64> = runs.iter().filter_map(|r| r.get(i)).map(|c| c.value).collect();
            let sorted = crate::study::stats::finite_sorted(&values);
            let missing = worlds - sorted.len();
            let q = |p: f64| crate::study::stats::quantile(&sorted, p);
            let (median, p10, p90) = (q(0.5), q(0.1), q(0.9));
            let confidence = confidence_of(row.bound.as_ref(), k, false_alarm);
            let interval = interval_with_missing(&sorted, missing, confidence);
            let covers_published = match (row.bound, row.published_value) {
                (Some(Bound::Band(_)), Some(p)) => Some(p10 <= p && p <= p90),
                _ => None,
            };
            let bounded = interval.0.is_finite() && interval.1.is_finite();
            let verdict = row.bound.map(|b| if bounded { judge(&b, interval) } else { Verdict::Unresolved });
            let pass = verdict.map(|v| !matches!(v, Verdict::Miss | Verdict::Unresolved));
            DistributionCheck {
                row: row.clone(),
                median,
                p10,
                p90,
                interval,
                confidence,
                count: sorted.len(),
                missing,
                covers_published,
                verdict,
                pass,
            }
        })
        .collect()
}

/// The confidence of a figure's interval among `k` bounded figures at `false_alarm` (see
/// [`over_realisations`]): `1 - a/k` for a band, `1 - 2a/k` for a one-sided bound.
pub fn confidence_of(bound: Option<&Bound>, k: usize, false_alarm: f64) -> f64 {
    let k = k.max(1) as f64;
    match bound {
        Some(Bound::Band(_)) => 1.0 - false_alarm / k,
        _ => 1.0 - 2.0 * false_alarm / k,
    }
}

/// The fewest worlds that give a bounded interval to every figure of `rows` at `false_alarm` (when
/// every world gives every figure a value).
pub fn fewest_worlds(rows: &[Check], false_alarm: f64) -> usize {
    let k = rows.iter().filter(|r| r.bound.is_some()).count();
    let strictest = rows.iter().filter(|r| r.bound.is_some()).map(|r| confidence_of(r.bound.as_ref(), k, false_alarm)).fold(0.0, f64::max);
    (1..=4096).find(|&n| crate::study::interval::median_ranks(n, strictest).is_some()).unwrap_or(4096)
}

/// The median interval of `sorted` (finite, ascending) with `missing` further worlds of unknown
/// value: the lower end with them below every value, the upper end with them above.
fn interval_with_missing(sorted: &[f64], missing: usize, confidence: f64) -> (f64, f64) {
    let n = sorted.len() + missing;
    match crate::study::interval::median_ranks(n, confidence) {
        Some((j, k)) => {
            let lo = if j > missing { sorted[j - 1 - missing] } else { f64::NEG_INFINITY };
            let hi = sorted.get(k - 1).copied().unwrap_or(f64::INFINITY);
            (lo, hi)
        }
        None => (f64::NEG_INFINITY, f64::INFINITY),
    }
}

/// The published-versus-reproduced table of a summary (one world), under a heading, rendered from
/// `checks.parquet` ([`check_columns`], which a run adds to its world's results): each figure of
/// this world beside its band, without a verdict (one world is one draw; `calsim check` judges the
/// figures over worlds).
pub fn checks_summary(heading: &str, parts: &mut crate::io::results::Summary<'_>) {
    use crate::io::results::{Summary, cell};
    parts.text(format!(
        "## {heading}\n\nOne simulated world, one draw of each figure; whether the model reproduces a figure is judged over \
         worlds by `calsim check`.\n\n"
    ));
    parts.table(
        "checks.parquet",
        Summary::all_rows(),
        vec![
            cell("figure", |r| r.str("figure")),
            cell("published", |r| r.str("published")),
            cell("calsim (this world)", |r| r.str("calsim")),
            cell("band", |r| r.str("band")),
            // What this world says of the figure, as [`Check::this_world`].
            cell("this world", |r| match (r.str("scope"), r.str("result").as_str()) {
                (scope, _) if !scope.is_empty() => scope,
                (_, "pass") => "in band".to_string(),
                (_, "miss") => "outside band".to_string(),
                _ => "-".to_string(),
            }),
        ],
    );
}

/// The comparison as a text table for the terminal (columns as wide as their widest cell). With
/// `verdict`, the last column is the check's verdict on these values (`pass`, `MISS`); without,
/// what this one world says of each figure ([`Check::this_world`]).
pub fn terminal_table(rows: &[Check], verdict: bool) -> String {
    let width = |head: &str, f: &dyn Fn(&Check) -> usize| rows.iter().map(f).max().unwrap_or(0).max(head.len());
    let (head_c, head_v) = if verdict { ("calsim", "result") } else { ("this world", "this world") };
    let wf = width("figure", &|r| r.figure.chars().count());
    let wp = width("published", &|r| r.published.chars().count());
    let wc = width(head_c, &|r| r.reproduced.chars().count()).max(10);
    let wb = width("band", &|r| r.band.chars().count());
    let mut s = String::new();
    let _ = writeln!(s, "{:<wf$}  {:>wp$}  {:>wc$}  {:>wb$}  {head_v}", "figure", "published", head_c, "band");
    for r in rows {
        let last = match (verdict, r.pass) {
            (true, Some(false)) => "MISS",
            (true, _) => r.verdict(),
            (false, _) => r.this_world(),
        };
        let last = match (&r.scope, verdict) {
            (Some(why), true) => format!("not judged ({why})"),
            _ => last.to_string(),
        };
        let _ = writeln!(s, "{:<wf$}  {:>wp$}  {:>wc$}  {:>wb$}  {last}", r.figure, r.published, r.reproduced, r.band);
    }
    s
}

/// [`terminal_table`] without verdict, with a last column: each figure's P10-P90 over `worlds`
/// worlds of an earlier check (`spread`, by figure name; `-` for a figure it does not give), in
/// the form of the row's value.
pub fn terminal_table_with_spread(rows: &[Check], worlds: usize, spread: &std::collections::BTreeMap<String, [f64; 2]>) -> String {
    let head = format!("P10-P90 over {worlds} worlds");
    let cells: Vec<String> = rows
        .iter()
        .map(|r| {
            spread
                .get(&r.figure)
                .map_or("-".to_string(), |[a, b]| format!("{} to {}", in_the_form_of(&r.reproduced, *a), in_the_form_of(&r.reproduced, *b)))
        })
        .collect();
    let table = terminal_table(rows, false);
    let lines: Vec<&str> = table.lines().collect();
    let w = lines.iter().map(|l| l.chars().count()).max().unwrap_or(0);
    let mut s = String::new();
    for (k, line) in lines.iter().enumerate() {
        let cell = if k == 0 { head.as_str() } else { cells.get(k - 1).map_or("", String::as_str) };
        let _ = writeln!(s, "{line:<w$}  {cell}");
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
    let cells: Vec<[String; 7]> = rows
        .iter()
        .map(|d| {
            let like = &d.row.reproduced;
            // One suffix for a range: `29-30 of 31`, `+21.8 to +48.9 %`.
            let range = |a: f64, b: f64| {
                if !(a.is_finite() && b.is_finite()) {
                    return "unbounded".to_string();
                }
                let (lo, hi) = (in_the_form_of(like, a), in_the_form_of(like, b));
                let suffix = |s: &str| s.find(' ').map_or(String::new(), |i| s[i..].to_string());
                let number = |s: &str| s.split(' ').next().unwrap_or("").to_string();
                let sep = if number(&lo).starts_with('+') || number(&hi).starts_with('-') { " to " } else { "-" };
                format!("{}{sep}{}{}", number(&lo), number(&hi), suffix(&hi))
            };
            [
                d.row.figure.clone(),
                d.row.published_value.map_or_else(|| d.row.published.clone(), |v| format!("{v:.3}")),
                like.clone(),
                in_the_form_of(like, d.median),
                format!("{} ({:.2} %)", range(d.interval.0, d.interval.1), 100.0 * d.confidence),
                range(d.p10, d.p90),
                d.row.band.clone(),
            ]
        })
        .collect();
    // Bands and one-sided bounds have intervals at different confidences: each cell says its own.
    let head = ["figure", "published", "run 0", "median", "interval of the median (confidence)", "P10-P90", "band"];
    let w: Vec<usize> = (0..7).map(|k| cells.iter().map(|c| c[k].chars().count()).max().unwrap_or(0).max(head[k].len())).collect();
    let line = |c: [&str; 7], verdict: &str| {
        format!(
            "{:<a$}  {:>b$}  {:>c$}  {:>d$}  {:>e$}  {:>f$}  {:>g$}  {verdict}\n",
            c[0],
            c[1],
            c[2],
            c[3],
            c[4],
            c[5],
            c[6],
            a = w[0],
            b = w[1],
            c = w[2],
            d = w[3],
            e = w[4],
            f = w[5],
            g = w[6]
        )
    };
    let mut s = line(head, "result");
    for (d, c) in rows.iter().zip(&cells) {
        let verdict = d.verdict.map_or("-", Verdict::word);
        let verdict = d.row.scope.as_ref().map_or_else(|| verdict.to_string(), |why| format!("not judged ({why})"));
        s.push_str(&line([&c[0], &c[1], &c[2], &c[3], &c[4], &c[5], &c[6]], &verdict));
    }
    s
}

/// The machine-readable verdict of a check (`check.json`): every figure with its published value,
/// calsim's value, its interval over realisations, its bound and verdict.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CheckReport {
    /// Scenario name.
    pub scenario: String,
    /// Seed of realisation 0.
    pub seed: u64,
    /// Realisations asked for, the figures judged over them (1: the plain run's values, judged as
    /// they are); a world whose study failed counts, as a world without values.
    pub realisations: usize,
    /// The test's false-alarm rate (over realisations), the probability of a miss when the model's
    /// medians satisfy every bound.
    pub false_alarm: Option<f64>,
    /// Every figure passed the gate.
    pub pass: bool,
    /// Figures with a bound, and of them missed.
    pub checked: usize,
    /// See `checked`.
    pub missed: usize,
    /// One row per figure.
    pub figures: Vec<CheckRow>,
}

/// One figure of [`CheckReport`].
#[derive(Clone, Debug, serde::Serialize)]
pub struct CheckRow {
    /// Figure.
    pub figure: String,
    /// Published value as a number, where the paper prints one.
    pub published_value: Option<f64>,
    /// Published value or rule as the paper gives it.
    pub published: String,
    /// calsim's value: the median over realisations (or the plain run's value).
    pub value: f64,
    /// The interval of the median over realisations (absent for one realisation or too few).
    pub interval: Option<[f64; 2]>,
    /// Confidence of `interval`.
    pub confidence: Option<f64>,
    /// P10 and P90 over realisations.
    pub p10_p90: Option<[f64; 2]>,
    /// The published value within P10-P90 (reported, not judged).
    pub covers_published: Option<bool>,
    /// The bound as written (`-` for a figure reported without one).
    pub band: String,
    /// `pass`, `open` (over realisations: no evidence either way), `miss`, `unresolved` (over
    /// realisations: too few worlds with a value to judge; a failure) or `report` (no bound).
    pub verdict: String,
    /// Worlds asked for that gave the figure no finite value.
    pub missing: usize,
}

impl CheckReport {
    /// The report of the plain run's `checks` (one realisation).
    pub fn single(scenario: &str, seed: u64, checks: &[Check]) -> Self {
        let figures = checks
            .iter()
            .map(|c| CheckRow {
                figure: c.figure.clone(),
                published_value: c.published_value,
                published: c.published.clone(),
                value: c.value,
                interval: None,
                confidence: None,
                p10_p90: None,
                covers_published: None,
                band: c.band.clone(),
                verdict: c.pass.map_or("report", |p| if p { "pass" } else { "miss" }).to_string(),
                missing: usize::from(!c.value.is_finite()),
            })
            .collect();
        let (checked, missed) = tally(checks);
        Self { scenario: scenario.into(), seed, realisations: 1, false_alarm: None, pass: missed == 0, checked, missed, figures }
    }

    /// The report of figures judged over realisations.
    pub fn over(scenario: &str, seed: u64, realisations: usize, false_alarm: f64, rows: &[DistributionCheck]) -> Self {
        let finite = |(a, b): (f64, f64)| (a.is_finite() && b.is_finite()).then_some([a, b]);
        let figures = rows
            .iter()
            .map(|d| CheckRow {
                figure: d.row.figure.clone(),
                published_value: d.row.published_value,
                published: d.row.published.clone(),
                value: d.median,
                interval: finite(d.interval),
                confidence: Some(d.confidence),
                p10_p90: finite((d.p10, d.p90)),
                covers_published: d.covers_published,
                band: d.row.band.clone(),
                verdict: d
                    .verdict
                    .map_or("report", |v| match v {
                        Verdict::Pass => "pass",
                        Verdict::Open => "open",
                        Verdict::Miss => "miss",
                        Verdict::Unresolved => "unresolved",
                    })
                    .to_string(),
                missing: d.missing,
            })
            .collect();
        let checked = rows.iter().filter(|d| d.pass.is_some()).count();
        let missed = rows.iter().filter(|d| d.pass == Some(false)).count();
        Self { scenario: scenario.into(), seed, realisations, false_alarm: Some(false_alarm), pass: missed == 0, checked, missed, figures }
    }

    /// The report as JUnit XML (one test suite, one test case per figure with a bound; a miss is a
    /// failure, a figure without a bound is skipped), for CI systems.
    pub fn junit(&self) -> String {
        let esc = |t: &str| t.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;");
        let skipped = self.figures.iter().filter(|f| f.verdict == "report").count();
        let mut s = String::from(crate::io::out_dir::JUNIT_HEAD);
        let _ = writeln!(
            s,
            "{}\" tests=\"{}\" failures=\"{}\" skipped=\"{skipped}\">",
            esc(&self.scenario),
            self.figures.len(),
            self.missed
        );
        for f in &self.figures {
            let interval = f.interval.map_or(String::new(), |[a, b]| format!(", interval {a:.4}-{b:.4}"));
            let what = format!("calsim {:.4}{interval}, published {}, band {}", f.value, f.published, f.band);
            let _ = write!(s, "  <testcase classname=\"{}\" name=\"{}\">", esc(&self.scenario), esc(&f.figure));
            match f.verdict.as_str() {
                "miss" => {
                    let _ = write!(s, "<failure message=\"{}\"/>", esc(&what));
                }
                "unresolved" => {
                    let why = format!("too few worlds with a value for a bounded interval ({} without one): {what}", f.missing);
                    let _ = write!(s, "<failure message=\"{}\"/>", esc(&why));
                }
                "report" => {
                    let _ = write!(s, "<skipped message=\"reported without a bound: {}\"/>", esc(&what));
                }
                _ => {
                    let _ = write!(s, "<system-out>{} ({})</system-out>", esc(&what), f.verdict);
                }
            }
            s.push_str("</testcase>\n");
        }
        s.push_str("</testsuite></testsuites>\n");
        s
    }
}

#[cfg(test)]
mod form_tests {
    use super::in_the_form_of;

    /// A figure out of the model's scope (another study's row) keeps its band as written but is
    /// never judged: in one world it counts neither as checked nor as missed, over worlds it has
    /// no verdict and does not widen the other figures' intervals (the Bonferroni count).
    #[test]
    fn a_figure_out_of_scope_is_reported_not_judged() {
        use super::{Band, Check, over_realisations, tally};
        let band = Some(Band { value: 0.146, tolerance: 0.25 });
        let judged = Check::band("judged", 0.208, 0.5, Some(Band { value: 0.208, tolerance: 0.15 }));
        let other = Check::band("another study's", 0.146, 0.035, band).outside_scope("another study, ref. [9]");
        assert_eq!((other.pass, other.bound.is_none(), other.band.as_str()), (None, true, "0.146 +-25 %"));
        assert_eq!(tally(&[judged.clone(), other.clone()]), (1, 1), "the judged figure misses, the other is not counted");
        let runs: Vec<Vec<Check>> = (0..30).map(|_| vec![judged.clone(), other.clone()]).collect();
        let alone: Vec<Vec<Check>> = (0..30).map(|_| vec![judged.clone()]).collect();
        let d = over_realisations(&runs, 30, 0.01);
        assert_eq!((d[1].verdict, d[1].pass), (None, None));
        assert_eq!(d[0].confidence, over_realisations(&alone, 30, 0.01)[0].confidence, "one figure judged");
    }

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

/// A check's verdict as the terminal prints it: `pass`, `miss` or `-` (no band).
pub fn verdict_word(pass: Option<bool>) -> &'static str {
    match pass {
        Some(true) => "pass",
        Some(false) => "miss",
        None => "-",
    }
}

/// `checks.parquet`: the published figures of one world beside calsim's, with band and verdict.
pub fn check_columns(checks: &[Check]) -> Vec<polars::prelude::Column> {
    use polars::prelude::Column;
    let s = |n: &str, v: Vec<String>| Column::new(n.into(), v);
    vec![
        s("figure", checks.iter().map(|c| c.figure.clone()).collect()),
        s("published", checks.iter().map(|c| c.published.clone()).collect()),
        Column::new("published_value".into(), checks.iter().map(|c| c.published_value).collect::<Vec<_>>()),
        s("calsim", checks.iter().map(|c| c.reproduced.clone()).collect()),
        Column::new("value".into(), checks.iter().map(|c| c.value).collect::<Vec<_>>()),
        s("band", checks.iter().map(|c| c.band.clone()).collect()),
        s("result", checks.iter().map(|c| verdict_word(c.pass).to_string()).collect()),
        Column::new("scope".into(), checks.iter().map(|c| c.scope.clone()).collect::<Vec<_>>()),
    ]
}

/// `checks_over_worlds.parquet`: each figure over the realisations, its median with its interval
/// and confidence, the worlds without a value, and the verdict (`pass`, `open`, `miss`,
/// `unresolved` or `-`).
pub fn distribution_columns(d: &[DistributionCheck]) -> Vec<polars::prelude::Column> {
    use polars::prelude::Column;
    let s = |n: &str, v: Vec<String>| Column::new(n.into(), v);
    let f = |n: &str, v: Vec<f64>| Column::new(n.into(), v);
    vec![
        s("figure", d.iter().map(|c| c.row.figure.clone()).collect()),
        s("published", d.iter().map(|c| c.row.published.clone()).collect()),
        Column::new("published_value".into(), d.iter().map(|c| c.row.published_value).collect::<Vec<_>>()),
        f("run0", d.iter().map(|c| c.row.value).collect()),
        f("median", d.iter().map(|c| c.median).collect()),
        f("p10", d.iter().map(|c| c.p10).collect()),
        f("p90", d.iter().map(|c| c.p90).collect()),
        f("interval_lo", d.iter().map(|c| c.interval.0).collect()),
        f("interval_hi", d.iter().map(|c| c.interval.1).collect()),
        f("confidence", d.iter().map(|c| c.confidence).collect()),
        Column::new("count".into(), d.iter().map(|c| c.count as i64).collect::<Vec<_>>()),
        Column::new("missing".into(), d.iter().map(|c| c.missing as i64).collect::<Vec<_>>()),
        s("band", d.iter().map(|c| c.row.band.clone()).collect()),
        s("result", d.iter().map(|c| c.verdict.map_or_else(|| "-".to_string(), |v| v.word().to_lowercase())).collect()),
    ]
}
