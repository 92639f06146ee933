//! What a sweep decides: the user's objective over its designs, stated in the sweep file.
//!
//! ```toml
//! [objective]
//! maximise = "success"        # P(statistic <= threshold_mm) over worlds; or minimise = "p95" | "max"
//!                             # | "median" | "mean" (the error after calibration, median over worlds)
//!                             # | "campaign_h" | "set_size"
//! statistic = "max"           # the error statistic a calibration's success is judged on
//! threshold_mm = 0.5
//! confidence = 0.9            # of every interval, tie and constraint
//! success_at_least = 0.95     # constraint: P >= this at the confidence (lower Clopper-Pearson bound)
//! campaign_h_at_most = 3.0    # constraint: modelled campaign time, median over worlds, hours
//! set_size_at_most = 75       # constraint
//! ```
//!
//! A design is one grid point with one selection and one set size: the set size is a design
//! choice too. Without `[objective]` a sweep minimises the p95 at its table set size, as before.

use serde::{Deserialize, Serialize};

/// An error statistic of one calibration over its validation poses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Statistic {
    /// Median error.
    Median,
    /// Mean error.
    Mean,
    /// 95th percentile.
    P95,
    /// Largest error.
    Max,
}

impl Statistic {
    /// The name as a file writes it.
    pub fn label(self) -> &'static str {
        match self {
            Statistic::Median => "median",
            Statistic::Mean => "mean",
            Statistic::P95 => "p95",
            Statistic::Max => "max",
        }
    }

    fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "median" => Statistic::Median,
            "mean" => Statistic::Mean,
            "p95" => Statistic::P95,
            "max" => Statistic::Max,
            _ => return None,
        })
    }
}

/// What a design is judged by.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Goal {
    /// Minimise an error statistic after calibration (its median over worlds).
    MinimiseError(Statistic),
    /// Minimise the modelled campaign time, hours (median over worlds).
    MinimiseCampaignHours,
    /// Minimise the set size.
    MinimiseSetSize,
    /// Maximise P(statistic <= threshold) over worlds.
    MaximiseSuccess,
}

/// The objective of a sweep.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Objective {
    /// What is optimised.
    pub goal: Goal,
    /// The statistic a calibration's success is judged on.
    pub statistic: Statistic,
    /// The success threshold, mm (success goal or constraint).
    pub threshold_mm: Option<f64>,
    /// Confidence of every interval, tie and constraint.
    pub confidence: f64,
    /// Least P(success) at the confidence.
    pub success_at_least: Option<f64>,
    /// Most campaign hours.
    pub campaign_h_at_most: Option<f64>,
    /// Largest set size.
    pub set_size_at_most: Option<u32>,
}

impl Default for Objective {
    fn default() -> Self {
        Self {
            goal: Goal::MinimiseError(Statistic::P95),
            statistic: Statistic::Max,
            threshold_mm: None,
            confidence: 0.95,
            success_at_least: None,
            campaign_h_at_most: None,
            set_size_at_most: None,
        }
    }
}

/// The `[objective]` table as written.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObjectiveFile {
    maximise: Option<String>,
    minimise: Option<String>,
    statistic: Option<String>,
    threshold_mm: Option<f64>,
    confidence: Option<f64>,
    success_at_least: Option<f64>,
    campaign_h_at_most: Option<f64>,
    set_size_at_most: Option<u32>,
}

impl ObjectiveFile {
    /// The checked objective; an error is `(key, what is wrong)`.
    pub fn check(self) -> Result<Objective, (String, String)> {
        let fail = |k: &str, m: String| Err((format!("objective.{k}"), m));
        let goal = match (self.maximise.as_deref(), self.minimise.as_deref()) {
            (Some("success"), None) => Goal::MaximiseSuccess,
            (Some(x), None) => return fail("maximise", format!("{x:?}: the one quantity maximised is \"success\"")),
            (None, Some("campaign_h")) => Goal::MinimiseCampaignHours,
            (None, Some("set_size")) => Goal::MinimiseSetSize,
            (None, Some(x)) => match Statistic::parse(x) {
                Some(s) => Goal::MinimiseError(s),
                None => {
                    return fail(
                        "minimise",
                        format!(
                            "{x:?}: one of \"median\", \"mean\", \"p95\", \"max\" (error after calibration), \"campaign_h\", \"set_size\""
                        ),
                    );
                }
            },
            (None, None) => return fail("maximise", "give maximise = \"success\" or minimise = \"<quantity>\"".into()),
            (Some(_), Some(_)) => return fail("minimise", "give one of maximise and minimise, not both".into()),
        };
        let statistic = match self.statistic.as_deref() {
            None => Statistic::Max,
            Some(s) => match Statistic::parse(s) {
                Some(s) => s,
                None => return fail("statistic", format!("{s:?}: one of \"median\", \"mean\", \"p95\", \"max\"")),
            },
        };
        if let Some(t) = self.threshold_mm
            && !(t.is_finite() && t > 0.0 && t < 1000.0)
        {
            return fail("threshold_mm", format!("{t}: an error in mm within (0, 1000)"));
        }
        let confidence = self.confidence.unwrap_or(0.95);
        if !(confidence.is_finite() && (0.5..=0.999).contains(&confidence)) {
            return fail("confidence", format!("{confidence}: within [0.5, 0.999]"));
        }
        if let Some(p) = self.success_at_least
            && !(p.is_finite() && p > 0.0 && p < 1.0)
        {
            return fail("success_at_least", format!("{p}: a probability within (0, 1)"));
        }
        if (goal == Goal::MaximiseSuccess || self.success_at_least.is_some()) && self.threshold_mm.is_none() {
            return fail("threshold_mm", "success needs its threshold: threshold_mm = <mm>".into());
        }
        if let Some(h) = self.campaign_h_at_most
            && !(h.is_finite() && h > 0.0 && h <= 1e4)
        {
            return fail("campaign_h_at_most", format!("{h}: hours within (0, 10000]"));
        }
        if self.set_size_at_most == Some(0) {
            return fail("set_size_at_most", "0: a set size of at least 1".into());
        }
        Ok(Objective {
            goal,
            statistic,
            threshold_mm: self.threshold_mm,
            confidence,
            success_at_least: self.success_at_least,
            campaign_h_at_most: self.campaign_h_at_most,
            set_size_at_most: self.set_size_at_most,
        })
    }
}

impl Objective {
    /// Whether larger values of the objective are better.
    pub fn maximises(&self) -> bool {
        self.goal == Goal::MaximiseSuccess
    }

    /// The objective in words, for summaries (`P(max <= 0.5 mm)`, `p95 after calibration, mm`).
    pub fn describe(&self) -> String {
        match self.goal {
            Goal::MaximiseSuccess => format!("maximise P({} <= {} mm)", self.statistic.label(), self.threshold_mm.unwrap_or(f64::NAN)),
            Goal::MinimiseError(s) => format!("minimise the {} error after calibration (median over worlds), mm", s.label()),
            Goal::MinimiseCampaignHours => "minimise the modelled campaign time (median over worlds), h".into(),
            Goal::MinimiseSetSize => "minimise the set size".into(),
        }
    }

    /// The constraints in words (empty when there are none).
    pub fn constraints(&self) -> Vec<String> {
        let mut v = Vec::new();
        if let Some(p) = self.success_at_least {
            v.push(format!(
                "P({} <= {} mm) >= {p} at {} % confidence",
                self.statistic.label(),
                self.threshold_mm.unwrap_or(f64::NAN),
                self.confidence * 100.0
            ));
        }
        if let Some(h) = self.campaign_h_at_most {
            v.push(format!("campaign time <= {h} h"));
        }
        if let Some(n) = self.set_size_at_most {
            v.push(format!("set size <= {n}"));
        }
        v
    }
}
