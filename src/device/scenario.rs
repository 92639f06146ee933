//! What every scenario file shares, whatever its device: TOML with the unit in every key, unknown
//! keys rejected, every number finite and range-checked, a robot file named relative to the
//! scenario, the common `[study]`, `[robot.spread]` and `[robot.unmodelled]` tables. Errors name
//! the file, the key and what is wrong, on one line ([`Checker`]). Each device parses and checks its
//! own sections with these pieces (`device::<kind>::spec`).

use std::cell::RefCell;
use std::path::{Path, PathBuf};

use crate::study::StudySpec;
use crate::study::check::Band;

/// The parts of a loaded scenario every device has.
#[derive(Clone, Debug, PartialEq)]
pub struct Header {
    /// Name (the file stem).
    pub name: String,
    /// Where it was read from.
    pub path: PathBuf,
    /// Its text (hashed into the manifest).
    pub text: String,
    /// Seed of every random stream.
    pub seed: u64,
}

impl Header {
    /// The header of a scenario read from `path` with `text` and `seed` (its name the file's stem,
    /// checked by [`crate::io::names::of_file`] when the file was read).
    pub fn new(path: &Path, text: &str, seed: u64) -> Self {
        let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "scenario".into());
        Self { name, path: path.to_path_buf(), text: text.to_string(), seed }
    }
}

/// A scenario that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    /// The file cannot be read.
    #[error("{path}: cannot read: {message}")]
    Read {
        /// File.
        path: String,
        /// OS error.
        message: String,
    },
    /// The TOML is malformed or a key is unknown or of the wrong type.
    #[error("{path}: {key}: {message}")]
    Parse {
        /// File.
        path: String,
        /// Dotted key path (or the position in the file).
        key: String,
        /// What is wrong.
        message: String,
    },
    /// The file's name cannot name its results (`..toml`, a line break in it).
    #[error(transparent)]
    Name(#[from] crate::io::names::NameError),
    /// A value is out of its range.
    #[error("{path}: [{section}] {key} = {value}: {why}")]
    Range {
        /// File.
        path: String,
        /// Table.
        section: String,
        /// Key.
        key: String,
        /// Value as written.
        value: String,
        /// The rule.
        why: String,
    },
}

/// Parses scenario text into its TOML table, naming the line of a syntax error.
pub fn table(text: &str, shown: &str) -> Result<toml::Table, ScenarioError> {
    toml::from_str::<toml::Table>(text).map_err(|e: toml::de::Error| ScenarioError::Parse {
        path: shown.into(),
        key: crate::io::toml_position(text, e.span()),
        message: e.message().to_string(),
    })
}

/// Refuses a non-finite float anywhere under `v`, naming its dotted key (`cell.spheres_w_mm[3][0]`).
fn finite(v: &toml::Value, path: &mut Vec<String>, shown: &str) -> Result<(), ScenarioError> {
    match v {
        toml::Value::Float(x) if !x.is_finite() => {
            let (key, section) = path.split_last().map(|(k, s)| (k.clone(), s.join("."))).unwrap_or_default();
            Err(ScenarioError::Range { path: shown.into(), section, key, value: x.to_string(), why: "must be a finite number".into() })
        }
        toml::Value::Table(t) => t.iter().try_for_each(|(k, v)| {
            path.push(k.clone());
            let r = finite(v, path, shown);
            path.pop();
            r
        }),
        toml::Value::Array(a) => a.iter().enumerate().try_for_each(|(i, v)| {
            let last = path.pop().unwrap_or_default();
            path.push(format!("{last}[{i}]"));
            let r = finite(v, path, shown);
            path.pop();
            path.push(last);
            r
        }),
        _ => Ok(()),
    }
}

/// Fills the keys of `section` that `t` leaves out from `defaults` (TOML text): how a device gives
/// a common section its own defaults.
pub fn with_defaults(mut t: toml::Table, section: &str, defaults: &str) -> toml::Table {
    let defaults = toml::from_str::<toml::Table>(defaults).expect("device defaults are valid TOML");
    let entry = t.entry(section.to_string()).or_insert_with(|| toml::Value::Table(toml::Table::new()));
    if let toml::Value::Table(given) = entry {
        for (k, v) in defaults {
            given.entry(k).or_insert(v);
        }
    }
    t
}

/// Deserializes a scenario table, naming the offending key in the error. Every number in it must be
/// finite first (TOML allows `nan` and `inf`, which no key of calsim takes).
pub fn deserialize<T: serde::de::DeserializeOwned>(t: toml::Table, shown: &str) -> Result<T, ScenarioError> {
    for (k, v) in &t {
        finite(v, &mut vec![k.clone()], shown)?;
    }
    crate::io::toml_de::from_table(t).map_err(|(key, message)| ScenarioError::Parse { path: shown.into(), key, message })
}

/// Range checks that name the file, section, key, value and rule of what fails. Every rule a
/// checker applies is also noted where [`rules_applied`] asks for them: the key reference
/// (`calsim keys`) shows the rules the loader itself checks.
pub struct Checker<'a> {
    /// The file as shown in errors.
    pub path: &'a str,
}

/// A rule a [`Checker`] applied to a key (`key` with its indices: `tcp_mm[0]`).
#[derive(Clone, Debug, PartialEq)]
pub struct Rule {
    /// Table.
    pub section: String,
    /// Key.
    pub key: String,
    /// The rule, as an error states it (`within [0, 1] (ISO 9283 RP)`).
    pub rule: String,
}

thread_local! {
    static RULES: RefCell<Option<Vec<Rule>>> = const { RefCell::new(None) };
}

/// Runs `f` and returns, with its value, every rule the checkers applied on this thread meanwhile
/// (in the order they were applied; a check that failed stops the rest).
pub fn rules_applied<T>(f: impl FnOnce() -> T) -> (T, Vec<Rule>) {
    let outer = RULES.with(|r| r.replace(Some(Vec::new())));
    let value = f();
    let rules = RULES.with(|r| r.replace(outer)).unwrap_or_default();
    (value, rules)
}

impl Checker<'_> {
    /// The error for `section.key = value` breaking `why`.
    pub fn fail(&self, section: &str, key: &str, value: impl ToString, why: &str) -> ScenarioError {
        ScenarioError::Range { path: self.path.into(), section: section.into(), key: key.into(), value: value.to_string(), why: why.into() }
    }

    /// Notes that `rule` applies to `section.key` (only while [`rules_applied`] listens): for a
    /// check written out beside the checker's own.
    pub fn rule(&self, section: &str, key: &str, rule: &str) {
        self.note(section, key, || rule.to_string());
    }

    fn note(&self, section: &str, key: &str, rule: impl FnOnce() -> String) {
        RULES.with(|r| {
            if let Some(rules) = r.borrow_mut().as_mut() {
                rules.push(Rule { section: section.into(), key: key.into(), rule: rule() });
            }
        });
    }

    /// The rule `why` on `section.key`: the error for `value` when `holds` is false.
    pub fn require(&self, section: &str, key: &str, holds: bool, value: impl ToString, why: &str) -> Result<(), ScenarioError> {
        self.note(section, key, || why.to_string());
        if holds { Ok(()) } else { Err(self.fail(section, key, value, why)) }
    }

    /// A finite number >= 0.
    pub fn non_negative(&self, section: &str, key: &str, v: f64, what: &str) -> Result<(), ScenarioError> {
        let why = format!("must be >= 0 ({what})");
        self.require(section, key, v.is_finite() && v >= 0.0, v, &why)
    }

    /// The `[robot.spread]` table, the same in both kinds of scenario.
    pub fn spread(&self, s: &crate::robot::SpreadSpec) -> Result<(), ScenarioError> {
        self.within("robot.spread", "length_mm", s.length_mm, 0.0, 10.0, "one standard deviation of every length")?;
        self.within("robot.spread", "angle_deg", s.angle_deg, 0.0, 5.0, "one standard deviation of every angle")?;
        self.within(
            "robot.spread",
            "compliance_mdeg_per_nm",
            s.compliance_mdeg_per_nm,
            0.0,
            100.0,
            "one standard deviation of every compliance",
        )
    }

    /// The `[robot.unmodelled]` table, the same in both kinds of scenario.
    pub fn unmodelled(&self, u: &crate::robot::UnmodelledSpec) -> Result<(), ScenarioError> {
        self.non_negative("robot.unmodelled", "transmission_low_mdeg", u.transmission_low_mdeg, "amplitude")?;
        self.non_negative("robot.unmodelled", "transmission_high_mdeg", u.transmission_high_mdeg, "amplitude")?;
        self.non_negative("robot.unmodelled", "backlash_mdeg", u.backlash_mdeg, "backlash width")?;
        self.within("robot.unmodelled", "thermal_drift_ppm", u.thermal_drift_ppm, -1000.0, 1000.0, "link growth")?;
        self.within("robot.unmodelled", "encoder_mdeg", u.encoder_mdeg, 0.0, 1000.0, "amplitude of the encoder error")?;
        let n = u.transmission_high_count;
        let count_ok = n.is_none_or(|n| (1..=100).contains(&n));
        self.require("robot.unmodelled", "transmission_high_count", count_ok, n.unwrap_or(0), "must be 1 to 100 harmonics per joint")?;
        for (key, orders) in [("transmission_high_orders", u.transmission_high_orders), ("encoder_orders", u.encoder_orders)] {
            let ok = orders.is_none_or(|[lo, hi]| lo >= 1 && lo <= hi && hi <= 1_000_000);
            let shown = orders.map_or_else(String::new, |[lo, hi]| format!("[{lo}, {hi}]"));
            self.require("robot.unmodelled", key, ok, shown, "must be [min, max] with 1 <= min <= max <= 1000000")?;
        }
        Ok(())
    }

    /// The `[study]` table, the same for every device: `pool` configurations to choose from and the
    /// device's default parameter set.
    pub fn study(&self, s: &StudySpec, pool: usize, default_set: fn() -> crate::robot::ParamSet) -> Result<(), ScenarioError> {
        let set = s.parameter_set(default_set);
        let shown = || format!("{:?}", s.parameters.clone().unwrap_or_default());
        let why = set
            .as_ref()
            .err()
            .map_or_else(|| "names of parameters the device can identify (absent: its default set)".into(), |e| e.to_string());
        self.require("study", "parameters", set.is_ok(), shown(), &why)?;
        let m = set.map(|set| set.len()).unwrap_or_default();
        self.require("study", "parameters", m > 0, "[]", "needs at least one parameter (absent: the device's default set)")?;
        self.require("study", "set_sizes", !s.set_sizes.is_empty(), "[]", "needs at least one set size")?;
        let most = crate::study::MAX_SET_SIZES;
        self.require("study", "set_sizes", s.set_sizes.len() <= most, s.set_sizes.len(), &format!("at most {most} set sizes"))?;
        let why = format!("each size must give at least {m} equations (3 per configuration) and stay below the pool of {pool}");
        let bad = s.set_sizes.iter().find(|&&n| (n as usize) * 3 < m || n as usize >= pool);
        self.require("study", "set_sizes", bad.is_none(), bad.copied().unwrap_or_default(), &why)?;
        self.count("study", "repetitions", s.repetitions.into(), 1, crate::study::MAX_REPETITIONS.into(), "identifications per set size")?;
        self.require("study", "table_set_size", s.set_sizes.contains(&s.table_set_size), s.table_set_size, "must be one of set_sizes")?;
        let selections_ok = !s.selections.is_empty() && s.selections.len() <= 2;
        self.require(
            "study",
            "selections",
            selections_ok,
            format!("{:?}", s.selections),
            "needs one or both of \"random\" and \"detmax\"",
        )?;
        let tasks = s.selections.len() as u64 * s.set_sizes.len() as u64 * u64::from(s.repetitions);
        let most = crate::study::MAX_TASKS;
        self.require(
            "study",
            "repetitions",
            tasks <= most,
            s.repetitions,
            &format!("at most {most} identifications in all (selections x set sizes x repetitions)"),
        )?;
        self.within("study", "detmax_max_excursion", s.detmax_max_excursion as f64, 1.0, 10.0, "excursion length")?;
        self.within("study", "rank_rtol", s.rank_rtol, 1e-7, 0.1, "relative singular-value threshold")?;
        let most = crate::study::MAX_CHECK_REALISATIONS;
        self.count("study", "check_realisations", s.check_realisations.into(), 1, most.into(), "worlds a check judges over")?;
        self.within("study", "check_false_alarm", s.check_false_alarm, 1e-6, 0.5, "false-alarm rate of a check")?;
        Ok(())
    }

    /// A count within `[lo, hi]`: the upper bound keeps every run within memory and time.
    pub fn count(&self, section: &str, key: &str, v: u64, lo: u64, hi: u64, what: &str) -> Result<(), ScenarioError> {
        self.require(section, key, (lo..=hi).contains(&v), v, &format!("must be within [{lo}, {hi}] ({what})"))
    }

    /// A band of `[expect]` (every one is an error in mm): a published value of a robot's size,
    /// 1 nm to 10 m, and a tolerance in [0, 10].
    pub fn band(&self, key: &str, b: &Option<Band>) -> Result<(), ScenarioError> {
        let (value, tolerance) = b.map_or((1.0, 0.0), |b| (b.value, b.tolerance));
        let why = "must be the published value in mm, within [1e-6, 1e4]";
        self.require("expect", &format!("{key}.value"), value.is_finite() && (1e-6..=1e4).contains(&value), value, why)?;
        let why = "must be a relative tolerance within [0, 10] (0.2 = +-20 %)";
        self.require("expect", &format!("{key}.tolerance"), tolerance.is_finite() && (0.0..=10.0).contains(&tolerance), tolerance, why)
    }

    /// A bound of `[expect]` that is a plain number: finite and within `[lo, hi]`.
    pub fn bound(&self, key: &str, v: Option<f64>, lo: f64, hi: f64) -> Result<(), ScenarioError> {
        self.within_optional("expect", key, v, lo, hi, "bound of the check")
    }

    /// Every parameter of the identified set must be separable on `model` by some set of
    /// configurations: a parameter with a zero column (theta_offs6 with the TCP on the joint-6 axis)
    /// or a redundancy (theta_offs1 with the base's alpha) is refused here, not found 510 times.
    pub fn identifiable(
        &self,
        model: &crate::robot::RobotModel,
        set: &crate::robot::ParamSet,
        tool_key: &str,
    ) -> Result<(), ScenarioError> {
        self.note("study", "parameters", || "every parameter separable by some set of configurations on this robot and tool".into());
        let hidden = unidentifiable_memo(model, set);
        if hidden.is_empty() {
            return Ok(());
        }
        let fix = if hidden.iter().any(|n| n == "theta_offs6") {
            format!("theta_offs6 moves nothing while {tool_key} lies on the joint-6 axis: move the tool off the axis or fix theta_offs6")
        } else {
            format!(
                "they move the tool alike in every configuration with this tool ({tool_key}): fix all but one of them, or move the tool"
            )
        };
        Err(self.fail(
            "study",
            "parameters",
            hidden.join(" "),
            &format!("no set of configurations can separate these on this robot; {fix}"),
        ))
    }

    /// A finite number within `[lo, hi]`.
    pub fn within(&self, section: &str, key: &str, v: f64, lo: f64, hi: f64, what: &str) -> Result<(), ScenarioError> {
        self.require(section, key, v.is_finite() && v >= lo && v <= hi, v, &format!("must be within [{lo}, {hi}] ({what})"))
    }

    /// An optional number: finite and within `[lo, hi]` when given.
    pub fn within_optional(&self, section: &str, key: &str, v: Option<f64>, lo: f64, hi: f64, what: &str) -> Result<(), ScenarioError> {
        match v {
            Some(v) => self.within(section, key, v, lo, hi, what),
            None => {
                self.note(section, key, || format!("must be within [{lo}, {hi}] ({what})"));
                Ok(())
            }
        }
    }
}

/// Reads a scenario file into its TOML table, for callers that edit keys
/// before loading it with [`from_table`] (sweeps).
pub fn read_table(path: &Path) -> Result<(String, toml::Table), ScenarioError> {
    let shown = path.display().to_string();
    let text = crate::io::read_text(path).map_err(|e| ScenarioError::Read { path: shown.clone(), message: e.to_string() })?;
    let mut t = table(&text, &shown)?;
    // A robot file is named relative to its scenario; the table may be loaded under another name
    // (a sweep point), so it carries the path from here on.
    if let Some(toml::Value::Table(robot)) = t.get_mut("robot")
        && let Some(toml::Value::String(f)) = robot.get("file")
    {
        // Absolute, so that a point's scenario written out (a sweep's best design) runs from any
        // working directory.
        let file = relative_to(path, Path::new(f));
        let resolved = std::path::absolute(&file).unwrap_or(file).display().to_string();
        robot.insert("file".into(), toml::Value::String(resolved));
    }
    Ok((text, t))
}

/// The robot file a scenario at `scenario` names (`None`: the built-in arm); an error names the
/// scenario, `robot.file`, the robot file and its field.
pub fn load_arm(scenario: &Path, file: Option<&Path>) -> Result<Option<crate::robot::file::Arm>, ScenarioError> {
    let Some(f) = file else { return Ok(None) };
    let arm = crate::robot::file::RobotFile::load(&relative_to(scenario, f)).map_err(|e| ScenarioError::Parse {
        path: scenario.display().to_string(),
        key: "robot.file".into(),
        message: e.to_string(),
    })?;
    Ok(Some(crate::robot::file::Arm(std::sync::Arc::new(arm))))
}

/// Whether the scenario table `t`, as written, sets `robot.repeatability_mm`.
pub fn sets_repeatability(t: &toml::Table) -> bool {
    t.get("robot").and_then(toml::Value::as_table).is_some_and(|r| r.contains_key("repeatability_mm"))
}

/// The robot a scenario draws from a twin (a robot file with a `[learned]` table, see
/// [`crate::robot::learned`]): the learned effects, each amplitude and spread times the scenario's
/// `robot.learned_scale`, drawn in every world on top of the scenario's own `[robot.unmodelled]`
/// effects; and the repeatability of its moves: the twin's learned `repeatability_mm` where it is
/// above zero and the scenario does not set `robot.repeatability_mm` (`sets_repeatability`, see
/// [`sets_repeatability`]: a scenario that sets it runs a what-if on the measured robot), drawn in
/// each world about that level where the twin gives its standard deviation
/// ([`crate::robot::VirtualRobot::with_learned_repeatability`]). `most_rp_mm` is the scenario's
/// bound on a repeatability; a twin's above it is refused, naming the scenario, `robot.file`, the
/// robot file and `learned.repeatability_mm`. A scale other than 1 without a twin is refused.
pub fn twin(
    sets_repeatability: bool,
    arm: Option<&crate::robot::file::Arm>,
    scale: f64,
    most_rp_mm: f64,
    shown: &str,
) -> Result<(Option<crate::robot::learned::LearnedEffects>, Option<f64>), ScenarioError> {
    let learned = arm.and_then(|a| a.0.learned.as_ref().map(|l| (a, l)));
    let Some((arm, l)) = learned else {
        if scale != 1.0 {
            return Err(ScenarioError::Parse {
                path: shown.into(),
                key: "robot.learned_scale".into(),
                message: format!("{scale}: the robot has no learned effects to scale (its robot file has no [learned] table)"),
            });
        }
        return Ok((None, None));
    };
    let repeatability = (!sets_repeatability && l.repeatability_mm > 0.0).then_some(l.repeatability_mm);
    if let Some(rp) = repeatability.filter(|&rp| rp > most_rp_mm) {
        return Err(ScenarioError::Parse {
            path: shown.into(),
            key: "robot.file".into(),
            message: format!(
                "{}: learned.repeatability_mm: {rp} mm: above the {most_rp_mm} mm a scenario's robot takes",
                arm.0.path.display()
            ),
        });
    }
    let mut effects = l.clone();
    // The repeatability is the scenario's robot's own (above), its level drawn per world from the
    // twin's spread only when it is the twin's level; the rest scales.
    effects.repeatability_mm = 0.0;
    if repeatability.is_none() {
        effects.repeatability_std_mm = 0.0;
    }
    effects.pose_error_mdeg *= scale;
    effects.pose_error_std_mdeg *= scale;
    for v in [&mut effects.backlash_mdeg, &mut effects.backlash_std_mdeg, &mut effects.sag_mdeg_per_m, &mut effects.sag_std_mdeg_per_m] {
        for x in v.iter_mut() {
            *x *= scale;
        }
    }
    for h in &mut effects.harmonic {
        h.sin_mdeg *= scale;
        h.cos_mdeg *= scale;
        h.std_mdeg *= scale;
    }
    Ok((Some(effects), repeatability))
}

/// `file` as named in the scenario at `scenario`: relative paths from the scenario's directory.
pub fn relative_to(scenario: &Path, file: &Path) -> PathBuf {
    if file.is_absolute() { file.to_path_buf() } else { scenario.parent().unwrap_or(Path::new("")).join(file) }
}

/// [`crate::identify::observability::structurally_unidentifiable`], remembered by its inputs: the
/// points of a sweep (and a merge re-loading them) share their robot and parameter set, and each
/// answer costs the SVD of 200 configurations (a 9,001-point sweep spent over a minute loading the
/// same answer 9,001 times). The inputs are keyed by their exact `Debug` text (floats print as
/// the shortest text that reads back to the same value); at most 256 answers are kept.
fn unidentifiable_memo(model: &crate::robot::RobotModel, set: &crate::robot::ParamSet) -> Vec<String> {
    use std::collections::HashMap;
    use std::sync::{Mutex, OnceLock};
    static MEMO: OnceLock<Mutex<HashMap<String, Vec<String>>>> = OnceLock::new();
    let key = format!("{model:?}\u{0}{set:?}");
    let memo = MEMO.get_or_init(Default::default);
    if let Some(hidden) = memo.lock().ok().and_then(|m| m.get(&key).cloned()) {
        return hidden;
    }
    let hidden = crate::identify::observability::structurally_unidentifiable(model, set);
    if let Ok(mut m) = memo.lock() {
        if m.len() >= 256 {
            m.clear();
        }
        m.insert(key, hidden.clone());
    }
    hidden
}
