//! Uncertainty budget by ablation with common random numbers: which error source limits the
//! calibrated accuracy, and what a better (or worse) one buys.
//!
//! The sources are the scenario's own error terms: of the device's noise and effect keys, those the
//! scenario sets to a non-zero value. A budget is a sweep whose grid points are configurations of
//! scale factors on the sources (every source on; every source off, the solver's floor; each source
//! alone; each source off; each source scaled by each what-if factor), run over the same
//! realisations (the same worlds and draws for every configuration), at the scenario's table set
//! size. The p95 of the validation error after calibration (median over realisations) is the
//! figure of merit; a source's share is the square of what it adds alone over the floor, and,
//! beside it, the square of what removing it saves from the whole; the two disagree when sources
//! interact.

pub mod plots;
pub mod results;

use std::path::Path;

use crate::design::sweep::spec::{Sweep, SweepError, from_tables, get_dotted, set_dotted};
use crate::device::ErrorSource;
use crate::device::scenario::{self, ScenarioError};

/// An error source: a label, the scenario keys it scales together, their unit.
#[derive(Clone, Debug, PartialEq)]
pub struct Source {
    /// Name in the budget.
    pub label: &'static str,
    /// Dotted keys scaled together.
    pub keys: &'static [&'static str],
    /// Unit of the first key.
    pub unit: &'static str,
    /// The scenario's values of the keys.
    pub values: Vec<f64>,
}

/// The robot's unmodelled effects (and the payload change between the setups, and a twin's learned
/// effects), sources of every device whose scenario sets them.
const UNMODELLED: [ErrorSource; 7] = [
    ("transmission errors, high orders", &["robot.unmodelled.transmission_high_mdeg"], "mdeg"),
    ("encoder interpolation", &["robot.unmodelled.encoder_mdeg"], "mdeg"),
    ("payload change, setup 1 to setup 2", &["robot.validation_payload_change_kg"], "kg"),
    ("transmission errors, low orders", &["robot.unmodelled.transmission_low_mdeg"], "mdeg"),
    ("backlash", &["robot.unmodelled.backlash_mdeg"], "mdeg"),
    ("thermal drift", &["robot.unmodelled.thermal_drift_ppm"], "ppm"),
    ("the twin's learned effects", &["robot.learned_scale"], "-"),
];

fn number(v: &toml::Value) -> Option<f64> {
    v.as_float().or_else(|| v.as_integer().map(|i| i as f64))
}

/// The sources of a scenario table: its device's error keys, then the robot's unmodelled effects,
/// that the scenario sets non-zero.
pub fn sources(device: &dyn crate::device::Device, t: &toml::Table) -> Vec<Source> {
    device
        .error_sources()
        .iter()
        .chain(UNMODELLED.iter())
        .filter_map(|&(label, keys, unit)| {
            let values: Vec<f64> = keys.iter().map(|k| get_dotted(t, k).and_then(number).unwrap_or(0.0)).collect();
            values.iter().any(|v| *v != 0.0).then_some(Source { label, keys, unit, values })
        })
        .collect()
}

/// Puts the sources of a twin (a robot file with a `[learned]` table) into the scenario table
/// `t` where the scenario leaves them to the twin, at the values its worlds draw: the scale of the
/// learned effects (1) and the twin's learned repeatability. Whether the robot file has learned
/// effects (other than its repeatability).
fn with_twin(t: &mut toml::Table, path: &Path) -> Result<bool, ScenarioError> {
    let file = get_dotted(t, "robot.file").and_then(toml::Value::as_str).map(std::path::PathBuf::from);
    let Some(arm) = scenario::load_arm(path, file.as_deref())? else { return Ok(false) };
    let Some(learned) = arm.0.learned.as_ref() else { return Ok(false) };
    let effects = crate::robot::learned::LearnedEffects { repeatability_mm: 0.0, ..learned.clone() };
    if !effects.is_none() && get_dotted(t, "robot.learned_scale").is_none() {
        let _ = set_dotted(t, "robot.learned_scale", toml::Value::Float(1.0));
    }
    // A repeatability beyond a scenario's range is left to the loader, which names the twin's key.
    let rp = learned.repeatability_mm;
    if rp > 0.0 && rp <= 1.0 && !scenario::sets_repeatability(t) {
        let _ = set_dotted(t, "robot.repeatability_mm", toml::Value::Float(rp));
    }
    Ok(!effects.is_none())
}

/// One configuration of a budget: a label and a factor per source.
#[derive(Clone, Debug, PartialEq)]
pub struct Config {
    /// `all on`, `all off`, `<source> alone`, `<source> off`, `<source> x0.5`.
    pub label: String,
    /// The source it is about (`None` for all on / all off).
    pub source: Option<usize>,
    /// `all`, `none`, `alone`, `off` or `scaled`.
    pub mode: &'static str,
    /// The factor of the source it is about (1 for all on, 0 for all off).
    pub factor: f64,
    /// Factor per source.
    pub factors: Vec<f64>,
}

/// The configurations for `n` sources and the what-if factors.
pub fn configs(sources: &[Source], what_if: &[f64]) -> Vec<Config> {
    let n = sources.len();
    let mut out = vec![
        Config { label: "all on".into(), source: None, mode: "all", factor: 1.0, factors: vec![1.0; n] },
        Config { label: "all off".into(), source: None, mode: "none", factor: 0.0, factors: vec![0.0; n] },
    ];
    for (s, src) in sources.iter().enumerate() {
        let unit = |f: f64| (0..n).map(|k| if k == s { f } else { 1.0 }).collect::<Vec<_>>();
        out.push(Config {
            label: format!("{} alone", src.label),
            source: Some(s),
            mode: "alone",
            factor: 1.0,
            factors: (0..n).map(|k| if k == s { 1.0 } else { 0.0 }).collect(),
        });
        out.push(Config { label: format!("{} off", src.label), source: Some(s), mode: "off", factor: 0.0, factors: unit(0.0) });
        for &f in what_if {
            out.push(Config { label: format!("{} x{f}", src.label), source: Some(s), mode: "scaled", factor: f, factors: unit(f) });
        }
    }
    out
}

/// A budget that cannot run.
#[derive(Debug, thiserror::Error)]
pub enum BudgetError {
    /// The scenario cannot be read.
    #[error(transparent)]
    Scenario(#[from] ScenarioError),
    /// A configuration is not a valid scenario.
    #[error(transparent)]
    Sweep(#[from] SweepError),
    /// Nothing to budget.
    #[error("{0}: no error source of the device is set non-zero in the scenario")]
    NoSource(String),
}

/// The budget's sweep: every configuration of `what_if` over `realisations`, at the table set size
/// with `repetitions` (the scenario's when `None`).
pub fn plan(
    path: &Path,
    realisations: u32,
    what_if: &[f64],
    repetitions: Option<u32>,
) -> Result<(Vec<Source>, Vec<Config>, Sweep), BudgetError> {
    let (text, mut base) = scenario::read_table(path)?;
    let device = crate::device::device_of(&base, path)?;
    let twin = with_twin(&mut base, path)?;
    let mut sources = sources(device, &base);
    // A scale on learned effects is a source only where the robot file has them.
    sources.retain(|s| twin || s.keys != ["robot.learned_scale"]);
    if sources.is_empty() {
        return Err(BudgetError::NoSource(path.display().to_string()));
    }
    let configs = configs(&sources, what_if);
    // The table set size alone (checked with the scenario).
    let table_n = get_dotted(&base, "study.table_set_size").cloned();
    let mut points = Vec::with_capacity(configs.len());
    for c in &configs {
        let mut t = base.clone();
        if let Some(n) = &table_n {
            let _ = set_dotted(&mut t, "study.set_sizes", toml::Value::Array(vec![n.clone()]));
        }
        if let Some(r) = repetitions {
            let _ = set_dotted(&mut t, "study.repetitions", toml::Value::Integer(i64::from(r)));
        }
        for (s, src) in sources.iter().enumerate() {
            for (k, v) in src.keys.iter().zip(&src.values) {
                let _ = set_dotted(&mut t, k, toml::Value::Float(v * c.factors[s]));
            }
        }
        points.push((vec![("configuration".to_string(), c.label.clone())], t));
    }
    use sha2::Digest;
    let identity = format!("{:x}", sha2::Sha256::digest(format!("budget\u{0}{text}\u{0}{what_if:?}\u{0}{repetitions:?}")));
    let name = format!("{}.budget", path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "scenario".into()));
    let sweep = from_tables(&name, identity, realisations, vec![0.5, 1.0], vec!["configuration".into()], points)?;
    Ok((sources, configs, sweep))
}

/// One source's line of the budget.
#[derive(Clone, Debug, PartialEq)]
pub struct Line {
    /// Index of the source.
    pub source: usize,
    /// Its share of the after-calibration p95 from what it adds alone over the floor.
    pub share_alone: f64,
    /// Its share from what removing it saves from the whole.
    pub share_removed: f64,
    /// p95 (median over realisations) with the source alone, off, mm.
    pub alone_mm: f64,
    /// See `alone_mm`.
    pub off_mm: f64,
    /// p95 at each what-if factor, mm.
    pub scaled_mm: Vec<(f64, f64)>,
}

/// The budget lines, sorted by share (largest first), from the p95 of each configuration (median
/// over realisations, mm; NaN where the configuration could not run).
pub fn lines(sources: &[Source], configs: &[Config], p95: &[f64]) -> (f64, f64, Vec<Line>) {
    let find = |mode: &str, s: Option<usize>, f: Option<f64>| {
        configs.iter().position(|c| c.mode == mode && c.source == s && f.is_none_or(|f| c.factor == f)).map_or(f64::NAN, |i| p95[i])
    };
    let (all, none) = (find("all", None, None), find("none", None, None));
    let added: Vec<f64> = (0..sources.len()).map(|s| (find("alone", Some(s), None).powi(2) - none.powi(2)).max(0.0)).collect();
    let saved: Vec<f64> = (0..sources.len()).map(|s| (all.powi(2) - find("off", Some(s), None).powi(2)).max(0.0)).collect();
    let (sa, ss) = (added.iter().sum::<f64>(), saved.iter().sum::<f64>());
    let mut out: Vec<Line> = (0..sources.len())
        .map(|s| Line {
            source: s,
            share_alone: if sa > 0.0 { added[s] / sa } else { f64::NAN },
            share_removed: if ss > 0.0 { saved[s] / ss } else { f64::NAN },
            alone_mm: find("alone", Some(s), None),
            off_mm: find("off", Some(s), None),
            scaled_mm: configs
                .iter()
                .zip(p95)
                .filter(|(c, _)| c.mode == "scaled" && c.source == Some(s))
                .map(|(c, v)| (c.factor, *v))
                .collect(),
        })
        .collect();
    out.sort_by(|a, b| b.share_alone.total_cmp(&a.share_alone).then(a.source.cmp(&b.source)));
    (all, none, out)
}

/// Confidence of the budget's intervals and tests.
pub const CONFIDENCE: f64 = 0.95;

/// Bootstrap resamples of a share's interval.
const RESAMPLES: usize = 2000;

/// A source's share over the worlds, with its interval, and what the worlds resolve.
#[derive(Clone, Debug)]
pub struct Share {
    /// Index of the source.
    pub source: usize,
    /// The share of the source alone: the mean over worlds of the square it adds to the floor's
    /// p95, over the mean of the sum of those squares (a ratio of means: worlds are the unit of
    /// independence, and the squares add where medians do not), clamped to [0, 1].
    pub share: f64,
    /// Its bootstrap-t interval at [`CONFIDENCE`] over worlds.
    pub interval: (f64, f64),
    /// The p95 with the source alone against the floor's, paired per world, mm.
    pub effect: Paired,
    /// The effect is resolved: the sign test over worlds rejects "no effect" at [`CONFIDENCE`].
    pub resolved: bool,
    /// The per-world added squares of this source against the next in the order (paired), and
    /// whether the worlds tell the two apart; `None` for the last source.
    pub above_next: Option<(Paired, bool)>,
}

use crate::study::interval::{Paired, bootstrap_t, ratio_of_means};

/// The per-world p95 of every configuration (`per_world[config][world]`, NaN where the world could
/// not run it) turned into the sources' shares with intervals, largest share first.
pub fn shares(sources: &[Source], configs: &[Config], per_world: &[Vec<f64>]) -> Vec<Share> {
    let find = |mode: &str, s: Option<usize>| configs.iter().position(|c| c.mode == mode && c.source == s);
    let (Some(none), n) = (find("none", None), sources.len()) else { return Vec::new() };
    let alone: Vec<Option<usize>> = (0..n).map(|s| find("alone", Some(s))).collect();
    let worlds = per_world.first().map_or(0, Vec::len);
    // Per world, the square each source adds alone over the floor; worlds where any is missing left
    // out. Not clamped at zero per world: a source without effect adds noise of either sign, whose
    // mean is zero only unclamped (clamped, it would get a positive share with an interval above
    // zero, taken from the others); the share and its interval are clamped to [0, 1] at the end.
    let added: Vec<Vec<f64>> = (0..worlds)
        .filter_map(|r| {
            let floor = per_world[none][r];
            let row: Vec<f64> = alone.iter().map(|a| a.map_or(f64::NAN, |a| per_world[a][r].powi(2) - floor.powi(2))).collect();
            (floor.is_finite() && row.iter().all(|x| x.is_finite())).then_some(row)
        })
        .collect();
    let all: Vec<usize> = (0..added.len()).collect();
    let mut out: Vec<Share> = (0..n)
        .map(|s| {
            // A fixed stream per source: the interval is a function of the results alone.
            let mut rng = crate::seeds::fixed_stream(crate::seeds::fixed::BUDGET_SHARE + s as u64);
            let clamp = |x: f64| x.clamp(0.0, 1.0);
            let share = if added.len() > 1 { clamp(ratio_of_means(&added, s, &all).0) } else { f64::NAN };
            let interval = bootstrap_t(added.len(), |idx| ratio_of_means(&added, s, idx), RESAMPLES, CONFIDENCE, &mut rng);
            let effect =
                alone[s].map_or_else(|| Paired::of(&[], &[], CONFIDENCE), |a| Paired::of(&per_world[a], &per_world[none], CONFIDENCE));
            let resolved = effect.separated(CONFIDENCE) && effect.median > 0.0;
            Share { source: s, share, interval: (clamp(interval.0), clamp(interval.1)), effect, resolved, above_next: None }
        })
        .collect();
    out.sort_by(|a, b| b.share.total_cmp(&a.share).then(a.source.cmp(&b.source)));
    for i in 0..out.len().saturating_sub(1) {
        let (a, b) = (out[i].source, out[i + 1].source);
        let x: Vec<f64> = added.iter().map(|w| w[a]).collect();
        let y: Vec<f64> = added.iter().map(|w| w[b]).collect();
        let p = Paired::of(&x, &y, CONFIDENCE);
        out[i].above_next = Some((p, p.separated(CONFIDENCE) && p.median > 0.0));
    }
    out
}

/// Every configuration against every source on, paired per world (p95, mm): what a what-if
/// changes, with its interval; `None` for every source on itself.
pub fn against_all_on(configs: &[Config], per_world: &[Vec<f64>]) -> Vec<Option<Paired>> {
    let all = configs.iter().position(|c| c.mode == "all");
    configs
        .iter()
        .enumerate()
        .map(|(i, _)| match all {
            Some(a) if a != i => Some(Paired::of(&per_world[i], &per_world[a], CONFIDENCE)),
            _ => None,
        })
        .collect()
}

/// Warnings on what the worlds cannot tell: the leading sources not ranked, effects within the
/// noise.
pub fn warnings(sources: &[Source], shares: &[Share], realisations: u32) -> Vec<String> {
    let mut w = Vec::new();
    if let Some(first) = shares.first()
        && let Some((p, false)) = first.above_next
        && let Some(second) = shares.get(1)
    {
        w.push(format!(
            "the {} worlds that ran every configuration (of {realisations} realisations) cannot rank the leading sources: {} and {} (the first adds more in {} of the {} worlds where they differ, sign test p = {:.3}); run with more --realisations",
            p.n,
            sources[first.source].label,
            sources[second.source].label,
            p.test.positive,
            p.test.positive + p.test.negative,
            p.test.p_value
        ));
    }
    let noise: Vec<&str> = shares.iter().filter(|s| !s.resolved).map(|s| sources[s.source].label).collect();
    if !noise.is_empty() {
        w.push(format!("within the noise of {realisations} realisations (alone, no effect on the p95 resolved): {}", noise.join(", ")));
    }
    w
}
