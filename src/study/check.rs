//! One band and one check row for every published figure of every study.

use serde::Deserialize;

/// A figure with its published value and the relative band the reproduction must fall in.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
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

impl Check {
    /// A figure compared with its published value within an optional relative band.
    pub fn band(figure: &str, published: f64, value: f64, band: Option<Band>) -> Self {
        Self {
            figure: figure.into(),
            published: format!("{published:.3}"),
            reproduced: format!("{value:.3}"),
            band: band.map(|b| format!("{:.3} +-{:.0} %", b.value, b.tolerance * 100.0)).unwrap_or_else(|| "-".into()),
            pass: band.map(|b| b.contains(value)),
        }
    }

    /// A figure checked by a rule: `rule` describes the bound when one is set, `pass` applies it.
    pub fn rule<T: Copy>(
        figure: &str,
        published: &str,
        reproduced: String,
        bound: Option<T>,
        describe: impl Fn(T) -> String,
        pass: impl Fn(T) -> bool,
    ) -> Self {
        Self {
            figure: figure.into(),
            published: published.into(),
            reproduced,
            band: bound.map(&describe).unwrap_or_else(|| "-".into()),
            pass: bound.map(pass),
        }
    }

    /// A figure reported without a check.
    pub fn report(figure: &str, published: &str, reproduced: String) -> Self {
        Self { figure: figure.into(), published: published.into(), reproduced, band: "-".into(), pass: None }
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
