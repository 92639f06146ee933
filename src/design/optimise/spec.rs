//! A design file: the base scenario, the design space over its keys (continuous, integer and
//! choice variables, and a set of points: the TriCal datum spheres or the SPMS stations, their
//! count enumerated and each point's position searched within a region), the `[objective]` of
//! the sweeps, and how to search and verify.
//!
//! Every variable maps the unit interval onto its values, so that a design is a point `x` of
//! `[0, 1]^d` for each count of points (decoded by [`super::space`]); a design the geometry rules
//! out (two points closer than the spacing, three that define no frame) is a violation with its
//! margin, never a scenario that fails to load.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::design::sweep::objective::{Objective, ObjectiveFile};
use crate::design::sweep::race::Race;
use crate::design::sweep::spec::{get_dotted, set_dotted};
use crate::device::scenario;

/// A design file that cannot be used: the file, the key, what is wrong.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {key}: {message}")]
pub struct DesignError {
    /// The design file.
    pub path: String,
    /// The key (dotted, as written).
    pub key: String,
    /// What is wrong.
    pub message: String,
}

fn err(path: &Path, key: impl Into<String>, message: impl Into<String>) -> DesignError {
    DesignError { path: path.display().to_string(), key: key.into(), message: message.into() }
}

/// The design file as written.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct DesignFile {
    base: PathBuf,
    #[serde(default)]
    fixed: toml::Table,
    #[serde(default, rename = "variable")]
    variables: Vec<VariableFile>,
    #[serde(default)]
    points: Option<PointsFile>,
    objective: ObjectiveFile,
    #[serde(default)]
    search: SearchFile,
    #[serde(default)]
    verify: VerifyFile,
    #[serde(default)]
    robust: Option<RobustFile>,
}

/// `[robust]`: the error models a design is scored over, and how their scores combine.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RobustFile {
    models: Vec<ModelFile>,
    score: Option<String>,
}

/// One error model: a name and scenario keys set on top of every design.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ModelFile {
    name: String,
    #[serde(default)]
    set: toml::Table,
}

/// One `[[variable]]`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct VariableFile {
    key: String,
    range: Option<[f64; 2]>,
    integer: Option<[i64; 2]>,
    choices: Option<Vec<toml::Value>>,
    start: Option<toml::Value>,
}

/// `[points]`: the datum spheres (TriCal) or stations (SPMS).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PointsFile {
    key: String,
    count: [i64; 2],
    region: String,
    x_mm: [f64; 2],
    y_mm: [f64; 2],
    z_mm: Option<[f64; 2]>,
    height_mm: Option<[f64; 2]>,
    tilt_deg: Option<[f64; 2]>,
    min_spacing_mm: f64,
    start_spacing_mm: Option<f64>,
    start_height_mm: Option<f64>,
    start_tilt_deg: Option<f64>,
    start_offset_mm: Option<[f64; 3]>,
    start: Option<Vec<Vec<f64>>>,
}

#[derive(Clone, Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct SearchFile {
    method: Option<String>,
    evaluations: Option<u32>,
    restarts: Option<u32>,
    worlds: Option<u32>,
    finalists: Option<u32>,
    race: Option<RaceFile>,
    seed: Option<u64>,
    score: Option<String>,
    repair: Option<bool>,
    across_counts: Option<bool>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RaceFile {
    max: u32,
    batch: u32,
}

#[derive(Clone, Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct VerifyFile {
    held_out: Option<u32>,
    #[serde(default)]
    compare: Vec<PathBuf>,
}

/// What a variable ranges over.
#[derive(Clone, Debug, PartialEq)]
pub enum Domain {
    /// A number within `[lo, hi]`.
    Range(f64, f64),
    /// A whole number within `[lo, hi]`.
    Integer(i64, i64),
    /// One of these values.
    Choices(Vec<toml::Value>),
}

/// A variable over a scenario key.
#[derive(Clone, Debug)]
pub struct Variable {
    /// Dotted scenario key.
    pub key: String,
    /// Its values.
    pub domain: Domain,
    /// Its start in `[0, 1]`.
    pub start: f64,
}

impl Variable {
    /// The value at `t` in `[0, 1]`.
    pub fn value(&self, t: f64) -> toml::Value {
        let t = t.clamp(0.0, 1.0);
        match &self.domain {
            Domain::Range(lo, hi) => toml::Value::Float(at_resolution(lo + t * (hi - lo), hi - lo)),
            Domain::Integer(lo, hi) => toml::Value::Integer(lo + (t * (hi - lo + 1) as f64).floor().min((hi - lo) as f64) as i64),
            Domain::Choices(c) => c[((t * c.len() as f64).floor() as usize).min(c.len() - 1)].clone(),
        }
    }

    fn unit_of(&self, v: &toml::Value) -> Option<f64> {
        let num = v.as_float().or(v.as_integer().map(|i| i as f64));
        match &self.domain {
            Domain::Range(lo, hi) => {
                num.filter(|x| x.is_finite() && *x >= *lo && *x <= *hi).map(|x| if hi > lo { (x - lo) / (hi - lo) } else { 0.5 })
            }
            Domain::Integer(lo, hi) => {
                v.as_integer().filter(|i| i >= lo && i <= hi).map(|i| ((i - lo) as f64 + 0.5) / ((hi - lo + 1) as f64))
            }
            Domain::Choices(c) => c.iter().position(|x| x == v).map(|k| (k as f64 + 0.5) / c.len() as f64),
        }
    }
}

/// `v` rounded to the resolution of a range `width` wide: four decimal digits below its leading
/// one (0.019999999999999997 in a range of 0.025 is 0.02), and never -0.0.
pub fn at_resolution(v: f64, width: f64) -> f64 {
    if !(v.is_finite() && width.is_finite() && width > 0.0) {
        return v;
    }
    let digits = 4 - width.log10().floor() as i32;
    let r = if digits >= 0 {
        let f = 10f64.powi(digits);
        (v * f).round() / f
    } else {
        let f = 10f64.powi(-digits);
        (v / f).round() * f
    };
    r + 0.0
}

/// Where the points may go.
#[derive(Clone, Debug, PartialEq)]
pub enum Region {
    /// On a plate: `x, y` on the plate, the plate raised `height_mm` and tilted `tilt_deg` about
    /// the x axis of the scenario's {W} (ranges, or one value each).
    Plate {
        /// x on the plate, mm.
        x_mm: [f64; 2],
        /// y on the plate, mm.
        y_mm: [f64; 2],
        /// Plate height, mm.
        height_mm: [f64; 2],
        /// Plate tilt, deg.
        tilt_deg: [f64; 2],
    },
    /// Free within a box of the scenario's frame ({W} of the base scenario, or the robot base for
    /// SPMS stations), mm.
    Box {
        /// x range, mm.
        x_mm: [f64; 2],
        /// y range, mm.
        y_mm: [f64; 2],
        /// z range, mm.
        z_mm: [f64; 2],
    },
}

/// The points of a design: the key they go to, how many, where.
#[derive(Clone, Debug)]
pub struct Points {
    /// Scenario key (`cell.spheres_w_mm`: the TriCal datum spheres, which define {W}; any other
    /// key gets the points as they are).
    pub key: String,
    /// Fewest and most points (both searched, one stratum per count).
    pub count: (usize, usize),
    /// The region.
    pub region: Region,
    /// Least distance between two points, mm.
    pub min_spacing_mm: f64,
    /// The start: points on a circle this far apart, mm.
    pub start_spacing_mm: f64,
    /// The start's plate height and tilt (plate region), mm and deg.
    pub start_plate: (f64, f64),
    /// The start circle's first point in the region, mm.
    pub start_offset_mm: [f64; 3],
    /// The start given point by point (`[points] start`), in the region's frame (x, y on the
    /// plate with z = 0, or x, y, z in the box), mm: a search of fewer points starts from the
    /// first ones, a search of more from all of them and then the circle's points of the same
    /// index for the rest. Empty: the circle.
    pub start_points: Vec<[f64; 3]>,
}

/// Which optimiser searches.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    /// argmin's Nelder-Mead simplex, started around the start design.
    NelderMead,
    /// argmin's particle swarm over the unit cube.
    ParticleSwarm,
    /// CMA-ES started at the start design ([`super::search::cmaes`]).
    Cmaes,
}

impl Method {
    /// The name as the file writes it.
    pub fn label(self) -> &'static str {
        match self {
            Method::NelderMead => "nelder_mead",
            Method::ParticleSwarm => "particle_swarm",
            Method::Cmaes => "cmaes",
        }
    }
}

/// What the search minimises for an objective of `maximise = "success"` (the race, the
/// verification and the answer are judged by P(success) whichever it is).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SearchScore {
    /// The empirical quantile over the search worlds, at the target probability
    /// (`success_at_least`, 0.95 without it), of each world's error statistic (its median over
    /// repetitions; a world whose campaign failed counts as [`QUANTILE_CAP`] times the threshold),
    /// divided by the threshold: below 1 where the target is met on those worlds, and still
    /// falling as the errors fall where P(success) has reached 1.
    Quantile,
    /// Minus P(success) over the search worlds (steps of 1 / (worlds x repetitions); flat at -1
    /// once every world succeeds).
    Success,
}

/// Where a failed world's error is put in the quantile score, in thresholds.
pub const QUANTILE_CAP: f64 = 10.0;

impl SearchScore {
    /// The name as the file writes it.
    pub fn label(self) -> &'static str {
        match self {
            SearchScore::Quantile => "quantile",
            SearchScore::Success => "success",
        }
    }
}

/// How the search runs.
#[derive(Clone, Debug)]
pub struct Search {
    /// The optimiser.
    pub method: Method,
    /// Designs evaluated per restart (the budget).
    pub evaluations: u32,
    /// Restarts per count of points.
    pub restarts: u32,
    /// Common worlds every search evaluation runs (realisations `0..worlds`).
    pub worlds: u32,
    /// Designs taken from the search into the race.
    pub finalists: u32,
    /// The race of the finalists on more search worlds.
    pub race: Race,
    /// Seed of the optimisers' own draws (the swarm's).
    pub seed: u64,
    /// What the search minimises for `maximise = "success"` (`[search] score`).
    pub score: SearchScore,
    /// `[search] repair` (default true): a design whose points break the spacing rule, whose
    /// first three spheres are nearly on one line or turn clockwise seen from above is moved to a
    /// valid design near it ([`DesignSpace::repair`]) and that design evaluated, rather than
    /// ruled out.
    pub repair: bool,
    /// `[search] across_counts` (default true): the second repetition of every count starts from
    /// the best design the first repetitions found at any count, brought to its count
    /// ([`DesignSpace::recount`]); false: from the Latin hypercube as the later repetitions.
    pub across_counts: bool,
}

/// An error model of a robust design: scenario keys set on top of every design.
#[derive(Clone, Debug, PartialEq)]
pub struct Model {
    /// Its name, as the file writes it.
    pub name: String,
    /// The keys it sets (dotted) and their values, in the file's order.
    pub set: Vec<(String, toml::Value)>,
}

/// How a robust design's per-model scores combine.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Combine {
    /// Their mean.
    Mean,
    /// The worst of them (the largest score).
    Worst,
}

impl Combine {
    /// The name as the file writes it.
    pub fn label(self) -> &'static str {
        match self {
            Combine::Mean => "mean",
            Combine::Worst => "worst",
        }
    }

    /// The combined score of per-model scores (lower is better).
    pub fn of(self, scores: &[f64]) -> f64 {
        match self {
            Combine::Mean => scores.iter().sum::<f64>() / scores.len().max(1) as f64,
            Combine::Worst => scores.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        }
    }
}

/// `[robust]`: a design scored over several error models on the same worlds.
#[derive(Clone, Debug, PartialEq)]
pub struct Robust {
    /// The models, in the file's order.
    pub models: Vec<Model>,
    /// How their scores combine.
    pub combine: Combine,
}

/// Most error models of a robust design.
pub const MOST_MODELS: usize = 16;

/// A loaded, checked design file.
#[derive(Clone, Debug)]
pub struct DesignSpace {
    /// Name (the file's stem).
    pub name: String,
    /// The design file.
    pub path: PathBuf,
    /// The base scenario with `[fixed]` applied.
    pub base: toml::Table,
    /// sha256 of the design file and its base scenario.
    pub identity: String,
    /// What a world's numbers depend on beyond its scenario's text: the objective's thresholds,
    /// the bytes of the robot file it names and calsim's version (the first 16 hex digits of
    /// their sha256). The per-world files are kept under it, so that an edited threshold or robot
    /// file runs its worlds again instead of judging the old ones.
    pub world_context: String,
    /// The variables.
    pub variables: Vec<Variable>,
    /// The points, if the design moves any.
    pub points: Option<Points>,
    /// The objective.
    pub objective: Objective,
    /// The search.
    pub search: Search,
    /// Held-out worlds of the verification.
    pub held_out: u32,
    /// Sweep files whose designs are verified beside the winner.
    pub compare: Vec<PathBuf>,
    /// The error models a design is scored over (`[robust]`), if any.
    pub robust: Option<Robust>,
}

impl DesignSpace {
    /// `table` under model `m` of `[robust]` (the table itself without `[robust]`).
    pub fn with_model(&self, table: &toml::Table, m: usize) -> toml::Table {
        let mut t = table.clone();
        if let Some(r) = &self.robust {
            for (k, v) in &r.models[m].set {
                set_dotted(&mut t, k, v.clone()).expect("checked when the file was loaded");
            }
        }
        t
    }

    /// The error models' names (one unnamed model without `[robust]`).
    pub fn model_names(&self) -> Vec<String> {
        match &self.robust {
            Some(r) => r.models.iter().map(|m| m.name.clone()).collect(),
            None => vec![String::new()],
        }
    }
}

/// Most points of a design.
pub const MOST_POINTS: usize = 12;

/// Most designs evaluated per restart, most restarts, worlds.
const MOST_EVALUATIONS: u32 = 100_000;

/// Reads and checks a design file.
pub fn load(path: &Path) -> Result<DesignSpace, DesignError> {
    let text = crate::io::read_text(path).map_err(|e| err(path, "(file)", format!("cannot read: {e}")))?;
    let file: DesignFile = crate::io::toml_de::from_str_keyed(&text).map_err(|(key, message)| err(path, key, message))?;
    let objective = file.objective.clone().check().map_err(|(k, m)| err(path, k, m))?;
    let base_path = path.parent().unwrap_or(Path::new(".")).join(&file.base);
    let (base_text, mut base) = scenario::read_table(&base_path).map_err(|e| err(path, "base", e.to_string()))?;
    let device = crate::device::device_of(&base, &base_path).map_err(|e| err(path, "base", e.to_string()))?;
    let defaults = device.defaults();
    let original = base.clone();
    let known = |key: &str| get_dotted(&defaults, key).is_some() || get_dotted(&original, key).is_some();
    for (k, v) in &file.fixed {
        if !known(k) {
            return Err(err(path, format!("fixed.{k}"), format!("not a key of a {} scenario (`calsim keys` lists them)", device.kind())));
        }
        set_dotted(&mut base, k, v.clone()).map_err(|m| err(path, format!("fixed.{k}"), m))?;
    }
    let mut variables = Vec::new();
    for (i, v) in file.variables.iter().enumerate() {
        let at = |k: &str| format!("variable[{i}] ({}).{k}", v.key);
        if !known(&v.key) {
            return Err(err(path, at("key"), format!("not a key of a {} scenario (`calsim keys` lists them)", device.kind())));
        }
        if file.variables[..i].iter().any(|w| w.key == v.key) {
            return Err(err(path, at("key"), "the key of an earlier variable: each key once"));
        }
        let domain = match (&v.range, &v.integer, &v.choices) {
            (Some([lo, hi]), None, None) => {
                if !(lo.is_finite() && hi.is_finite()) {
                    return Err(err(path, at("range"), format!("[{lo}, {hi}]: finite bounds")));
                }
                if lo >= hi {
                    return Err(err(
                        path,
                        at("range"),
                        format!("[{lo}, {hi}]: empty or reversed (the lower bound first, below the upper)"),
                    ));
                }
                Domain::Range(*lo, *hi)
            }
            (None, Some([lo, hi]), None) => {
                if lo > hi {
                    return Err(err(path, at("integer"), format!("[{lo}, {hi}]: reversed (the lower bound first)")));
                }
                // The values are taken through a float: bounds where every integer is one.
                const MOST_INTEGER: i64 = 1 << 53;
                if !(-MOST_INTEGER..=MOST_INTEGER).contains(lo) || !(-MOST_INTEGER..=MOST_INTEGER).contains(hi) {
                    return Err(err(path, at("integer"), format!("[{lo}, {hi}]: bounds within +-{MOST_INTEGER} (2^53)")));
                }
                Domain::Integer(*lo, *hi)
            }
            (None, None, Some(c)) => {
                if c.is_empty() {
                    return Err(err(path, at("choices"), "empty: at least one value"));
                }
                Domain::Choices(c.clone())
            }
            _ => return Err(err(path, at("range"), "give one of range = [lo, hi], integer = [lo, hi], choices = [...]")),
        };
        let mut var = Variable { key: v.key.clone(), domain, start: 0.5 };
        if let Some(s) = &v.start {
            var.start = var.unit_of(s).ok_or_else(|| err(path, at("start"), format!("{s}: not one of the variable's values")))?;
        } else if let Some(current) = get_dotted(&base, &v.key).or_else(|| get_dotted(&defaults, &v.key))
            && let Some(u) = var.unit_of(current)
        {
            var.start = u;
        }
        variables.push(var);
    }
    // Every value of a variable must make a scenario of its kind: its ends and its start, the other
    // variables at their starts (the design the search starts from; a set size above the base
    // scenario's pool is a design of a larger pool).
    let mut start_design = base.clone();
    for var in &variables {
        set_dotted(&mut start_design, &var.key, var.value(var.start)).map_err(|m| err(path, "variable", m))?;
    }
    for (i, var) in variables.iter().enumerate() {
        let at = |k: &str| format!("variable[{i}] ({}).{k}", var.key);
        for t in [0.0, 1.0, var.start] {
            let mut probe = start_design.clone();
            set_dotted(&mut probe, &var.key, var.value(t)).map_err(|m| err(path, at("key"), m))?;
            if let Some(s) = check_table(&probe, &base_path) {
                return Err(err(path, at("key"), format!("value {}: {s}", var.value(t))));
            }
        }
    }
    let points = file.points.as_ref().map(|p| points(path, p)).transpose()?;
    if let Some(p) = &points {
        // The key the points go to: a key of the scenario that holds a list of points.
        match get_dotted(&base, &p.key).or_else(|| get_dotted(&defaults, &p.key)) {
            None => {
                return Err(err(
                    path,
                    "points.key",
                    format!("{:?}: not a key of a {} scenario (`calsim keys` lists them)", p.key, device.kind()),
                ));
            }
            Some(toml::Value::Array(_)) => {}
            Some(v) => {
                return Err(err(
                    path,
                    "points.key",
                    format!(
                        "{:?}: a {} in the scenario, not a list of points (the points go to a key holding [[x, y, z], ...])",
                        p.key,
                        v.type_str()
                    ),
                ));
            }
        }
    }
    let robust = file
        .robust
        .as_ref()
        .map(|r| robust(path, r, &base, &base_path, &known, &variables, points.as_ref().map(|p| p.key.as_str())))
        .transpose()?;
    let search = search(path, &file.search)?;
    let held_out = file.verify.held_out.unwrap_or(100);
    if !(1..=10_000).contains(&held_out) {
        return Err(err(path, "verify.held_out", format!("{held_out}: within [1, 10000] held-out worlds")));
    }
    let compare: Vec<PathBuf> = file.verify.compare.iter().map(|c| path.parent().unwrap_or(Path::new(".")).join(c)).collect();
    for (i, c) in compare.iter().enumerate() {
        if !c.is_file() {
            return Err(err(path, format!("verify.compare[{i}]"), format!("{}: no such sweep file", c.display())));
        }
    }
    let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "design".into());
    use sha2::Digest;
    let identity = format!("{:x}", sha2::Sha256::digest(format!("{text}\u{0}{base_text}")));
    let robot_bytes = get_dotted(&base, "robot.file")
        .and_then(|v| v.as_str().map(PathBuf::from))
        .map(|f| crate::io::read_bytes(&f).map_err(|e| err(path, "robot.file", format!("{}: {e}", f.display()))))
        .transpose()?
        .unwrap_or_default();
    let world_context = {
        let mut h = sha2::Sha256::new();
        h.update(format!("{:?}\u{0}{}\u{0}", objective.threshold_mm, env!("CARGO_PKG_VERSION")));
        h.update(&robot_bytes);
        format!("{:x}", h.finalize())[..16].to_string()
    };
    let space = DesignSpace {
        name,
        path: path.to_path_buf(),
        base,
        identity,
        world_context,
        variables,
        points,
        objective,
        search,
        held_out,
        compare,
        robust,
    };
    feasible_somewhere(path, &space)?;
    Ok(space)
}

/// Checks a scenario table as its device would load it; `Some(why)` when it would refuse it.
pub fn check_table(t: &toml::Table, base_path: &Path) -> Option<String> {
    let text = toml::to_string(t).unwrap_or_default();
    crate::device::from_table(&text, t.clone(), base_path).err().map(|e| e.to_string())
}

fn points(path: &Path, p: &PointsFile) -> Result<Points, DesignError> {
    let range = |k: &str, r: [f64; 2]| -> Result<[f64; 2], DesignError> {
        if !(r[0].is_finite() && r[1].is_finite()) || r[0] > r[1] || r[0].abs() > 5000.0 || r[1].abs() > 5000.0 {
            return Err(err(path, format!("points.{k}"), format!("[{}, {}]: finite bounds within +-5000, the lower first", r[0], r[1])));
        }
        Ok(r)
    };
    let [lo, hi] = p.count;
    if lo > hi || lo < 1 || hi as usize > MOST_POINTS {
        return Err(err(path, "points.count", format!("[{lo}, {hi}]: from 1 to {MOST_POINTS} points, the lower first")));
    }
    if p.key == "cell.spheres_w_mm" && lo < 3 {
        return Err(err(path, "points.count", format!("[{lo}, {hi}]: three datum spheres at least (they define {{W}})")));
    }
    let region = match p.region.as_str() {
        "plate" => {
            let angle = |k: &str, r: [f64; 2]| -> Result<[f64; 2], DesignError> {
                let r = range(k, r)?;
                if r[0] < -60.0 || r[1] > 60.0 {
                    return Err(err(path, format!("points.{k}"), format!("[{}, {}]: within [-60, 60] deg", r[0], r[1])));
                }
                Ok(r)
            };
            Region::Plate {
                x_mm: range("x_mm", p.x_mm)?,
                y_mm: range("y_mm", p.y_mm)?,
                height_mm: range("height_mm", p.height_mm.unwrap_or([0.0, 0.0]))?,
                tilt_deg: angle("tilt_deg", p.tilt_deg.unwrap_or([0.0, 0.0]))?,
            }
        }
        "box" => Region::Box {
            x_mm: range("x_mm", p.x_mm)?,
            y_mm: range("y_mm", p.y_mm)?,
            z_mm: range("z_mm", p.z_mm.ok_or_else(|| err(path, "points.z_mm", "a box needs z_mm = [lo, hi]"))?)?,
        },
        other => return Err(err(path, "points.region", format!("{other:?}: \"plate\" or \"box\""))),
    };
    if !(p.min_spacing_mm.is_finite() && p.min_spacing_mm >= 0.0 && p.min_spacing_mm <= 5000.0) {
        return Err(err(path, "points.min_spacing_mm", format!("{}: a distance within [0, 5000] mm", p.min_spacing_mm)));
    }
    let spacing = p.start_spacing_mm.unwrap_or(p.min_spacing_mm.max(100.0) * 1.5);
    if !(spacing.is_finite() && spacing > 0.0) {
        return Err(err(path, "points.start_spacing_mm", format!("{spacing}: a distance > 0 mm")));
    }
    let finite =
        |k: &str, v: f64| if v.is_finite() { Ok(v) } else { Err(err(path, format!("points.{k}"), format!("{v}: a finite number"))) };
    let offset = p.start_offset_mm.unwrap_or([0.0; 3]);
    for v in offset {
        finite("start_offset_mm", v)?;
    }
    let start_points = match &p.start {
        None => Vec::new(),
        Some(list) => start_points(path, p, list, &region, (lo as usize, hi as usize))?,
    };
    Ok(Points {
        key: p.key.clone(),
        count: (lo as usize, hi as usize),
        start_points,
        region,
        min_spacing_mm: p.min_spacing_mm,
        start_spacing_mm: spacing,
        start_plate: (
            finite("start_height_mm", p.start_height_mm.unwrap_or(0.0))?,
            finite("start_tilt_deg", p.start_tilt_deg.unwrap_or(0.0))?,
        ),
        start_offset_mm: offset,
    })
}

/// The greatest smallest distance of `n` points in the unit square, `n` = 2 to 12 (Schaer, Nurmela
/// and Ostergard; the proven optima of the packing literature).
const SQUARE_SPREAD: [f64; 11] = [
    std::f64::consts::SQRT_2,
    1.035276,
    1.0,
    std::f64::consts::FRAC_1_SQRT_2,
    0.600925,
    0.535898,
    0.517638,
    0.5,
    0.421280,
    0.398207,
    0.388730,
];

/// Whether `n` points at least `s` apart may fit a box of `sides` (mm, a plate's third 0): false
/// only where a bound proves they cannot: a segment holds `L / s + 1`; a rectangle at most Oler's
/// `2 A / (sqrt 3 s^2) + P / (2 s) + 1`, and no more than the square of its longer side holds
/// (the table's optima, with a margin of 1e-3); a box no more than its volume grown by `s` holds
/// balls of diameter `s`.
pub fn may_fit(n: usize, sides: [f64; 3], s: f64) -> bool {
    if n <= 1 || s <= 0.0 {
        return true;
    }
    let mut d = sides.map(|x| x.max(0.0) / s);
    d.sort_by(|a, b| b.total_cmp(a));
    let n_f = n as f64;
    if d[1] == 0.0 {
        return n_f <= (d[0] + 1e-9).floor() + 1.0;
    }
    if d[2] == 0.0 {
        let oler = 2.0 / 3f64.sqrt() * d[0] * d[1] + (d[0] + d[1]) + 1.0;
        if n_f > oler + 1e-9 {
            return false;
        }
        return !(n <= 12 && d[0] * SQUARE_SPREAD[n - 2] * (1.0 + 1e-3) < 1.0);
    }
    n_f <= (d[0] + 1.0) * (d[1] + 1.0) * (d[2] + 1.0) / (std::f64::consts::PI / 6.0)
}

/// `[points] start`: one point per entry, inside the region, as many as the most points
/// searched at most, no two closer than the spacing.
fn start_points(
    path: &Path,
    p: &PointsFile,
    list: &[Vec<f64>],
    region: &Region,
    count: (usize, usize),
) -> Result<Vec<[f64; 3]>, DesignError> {
    if list.is_empty() {
        return Err(err(path, "points.start", "empty: one point per entry, or leave the key out (the circle)"));
    }
    if list.len() > count.1 {
        return Err(err(
            path,
            "points.start",
            format!("{} points: more than the most searched (points.count = [{}, {}])", list.len(), count.0, count.1),
        ));
    }
    let inside = |v: f64, r: [f64; 2]| v >= r[0] && v <= r[1];
    let mut out = Vec::with_capacity(list.len());
    for (k, q) in list.iter().enumerate() {
        let at = format!("points.start[{k}]");
        let (point, fits, ranges) = match region {
            Region::Plate { x_mm, y_mm, .. } => {
                if q.len() != 2 {
                    return Err(err(path, at, format!("{q:?}: x, y on the plate (2 numbers, mm)")));
                }
                ([q[0], q[1], 0.0], inside(q[0], *x_mm) && inside(q[1], *y_mm), format!("x_mm = {x_mm:?}, y_mm = {y_mm:?}"))
            }
            Region::Box { x_mm, y_mm, z_mm } => {
                if q.len() != 3 {
                    return Err(err(path, at, format!("{q:?}: x, y, z in the box (3 numbers, mm)")));
                }
                (
                    [q[0], q[1], q[2]],
                    inside(q[0], *x_mm) && inside(q[1], *y_mm) && inside(q[2], *z_mm),
                    format!("x_mm = {x_mm:?}, y_mm = {y_mm:?}, z_mm = {z_mm:?}"),
                )
            }
        };
        if point.iter().any(|v| !v.is_finite()) {
            return Err(err(path, at, format!("{q:?}: finite numbers")));
        }
        if !fits {
            return Err(err(path, at, format!("{q:?}: outside the region ({ranges})")));
        }
        out.push(point);
    }
    for i in 0..out.len() {
        for j in 0..i {
            let d = (0..3).map(|c| (out[i][c] - out[j][c]).powi(2)).sum::<f64>().sqrt();
            if d < p.min_spacing_mm {
                return Err(err(
                    path,
                    "points.start",
                    format!("points {} and {} are {d:.1} mm apart, under min_spacing_mm = {}", j + 1, i + 1, p.min_spacing_mm),
                ));
            }
        }
    }
    Ok(out)
}

/// `[robust]`: two or more models with distinct names, each setting scenario keys that no
/// variable or the points move, every model's base scenario one its device accepts.
fn robust(
    path: &Path,
    r: &RobustFile,
    base: &toml::Table,
    base_path: &Path,
    known: &dyn Fn(&str) -> bool,
    variables: &[Variable],
    points_key: Option<&str>,
) -> Result<Robust, DesignError> {
    let combine = match r.score.as_deref() {
        None | Some("mean") => Combine::Mean,
        Some("worst") => Combine::Worst,
        Some(s) => return Err(err(path, "robust.score", format!("{s:?}: \"mean\" or \"worst\""))),
    };
    if r.models.len() < 2 || r.models.len() > MOST_MODELS {
        return Err(err(
            path,
            "robust.models",
            format!("{} models: from 2 to {MOST_MODELS} (one model is a design file without [robust])", r.models.len()),
        ));
    }
    let mut models = Vec::new();
    for (i, m) in r.models.iter().enumerate() {
        let at = |k: &str| format!("robust.models[{i}] ({}).{k}", m.name);
        if m.name.trim().is_empty() || m.name.len() > 80 || m.name.chars().any(char::is_control) {
            return Err(err(path, at("name"), "a name of 1 to 80 printable characters"));
        }
        if r.models[..i].iter().any(|o| o.name == m.name) {
            return Err(err(path, at("name"), "the name of an earlier model: each name once"));
        }
        let mut probe = base.clone();
        let mut set = Vec::new();
        for (k, v) in &m.set {
            let key = at(&format!("set.{k}"));
            if !known(k) {
                return Err(err(path, key, "not a key of the base scenario's device (`calsim keys` lists them)"));
            }
            let moved = points_key == Some(k.as_str()) || (points_key == Some("cell.spheres_w_mm") && k == "cell.plate_offset_mm_deg");
            if variables.iter().any(|x| &x.key == k) || moved {
                return Err(err(path, key, "a key the design moves: a model sets physics, not the design"));
            }
            set_dotted(&mut probe, k, v.clone()).map_err(|e| err(path, key.clone(), e))?;
            set.push((k.clone(), v.clone()));
        }
        if let Some(why) = check_table(&probe, base_path) {
            return Err(err(path, at("set"), format!("the base scenario under this model is refused: {why}")));
        }
        models.push(Model { name: m.name.clone(), set });
    }
    Ok(Robust { models, combine })
}

fn search(path: &Path, s: &SearchFile) -> Result<Search, DesignError> {
    let method = match s.method.as_deref() {
        None | Some("nelder_mead") => Method::NelderMead,
        Some("particle_swarm") => Method::ParticleSwarm,
        Some("cmaes") => Method::Cmaes,
        Some(m) => return Err(err(path, "search.method", format!("{m:?}: \"nelder_mead\", \"particle_swarm\" or \"cmaes\""))),
    };
    let score = match s.score.as_deref() {
        None | Some("quantile") => SearchScore::Quantile,
        Some("success") => SearchScore::Success,
        Some(m) => return Err(err(path, "search.score", format!("{m:?}: \"quantile\" or \"success\""))),
    };
    let count = |k: &str, v: Option<u32>, default: u32, most: u32| -> Result<u32, DesignError> {
        let v = v.unwrap_or(default);
        if !(1..=most).contains(&v) {
            return Err(err(path, format!("search.{k}"), format!("{v}: within [1, {most}]")));
        }
        Ok(v)
    };
    let worlds = count("worlds", s.worlds, 10, 10_000)?;
    let race = match &s.race {
        // At most 10,000 worlds, as a race written out: the search's worlds stay below 10,000.
        None => Race { min: worlds, batch: worlds, max: (4 * worlds).min(10_000).max(worlds), confidence: 0.9 },
        Some(r) => {
            if r.max < worlds || r.batch == 0 || r.max > 10_000 {
                return Err(err(
                    path,
                    "search.race",
                    format!("max = {}, batch = {}: max within [worlds = {worlds}, 10000], batch >= 1", r.max, r.batch),
                ));
            }
            Race { min: worlds, batch: r.batch, max: r.max, confidence: 0.9 }
        }
    };
    Ok(Search {
        method,
        evaluations: count("evaluations", s.evaluations, 40, MOST_EVALUATIONS)?,
        restarts: count("restarts", s.restarts, 1, 100)?,
        worlds,
        finalists: count("finalists", s.finalists, 4, 100)?,
        race,
        seed: s.seed.unwrap_or(2018),
        score,
        repair: s.repair.unwrap_or(true),
        across_counts: s.across_counts.unwrap_or(true),
    })
}

/// Whether some design of the space can meet the objective's constraints as the file states
/// them (the set size budget against the set sizes the study runs): a constraint no design can
/// meet is refused before anything runs.
fn feasible_somewhere(path: &Path, space: &DesignSpace) -> Result<(), DesignError> {
    let sizes: Vec<i64> = get_dotted(&space.base, "study.set_sizes")
        .and_then(|v| v.as_array())
        .map(|a| a.iter().filter_map(toml::Value::as_integer).collect())
        .unwrap_or_default();
    if let Some(most) = space.objective.set_size_at_most
        && !sizes.is_empty()
        && sizes.iter().all(|&n| n > i64::from(most))
    {
        return Err(err(
            path,
            "objective.set_size_at_most",
            format!("{most}: no design can meet it: every set size the study runs (study.set_sizes = {sizes:?}) is larger"),
        ));
    }
    if let (Some(p), Some(h)) = (&space.points, space.objective.campaign_h_at_most) {
        let _ = (p, h);
    }
    // The points must fit: every count searched at the least spacing inside the region.
    if let Some(p) = &space.points {
        let (sides, dims) = match &p.region {
            Region::Plate { x_mm, y_mm, .. } => ([x_mm[1] - x_mm[0], y_mm[1] - y_mm[0], 0.0], 2),
            Region::Box { x_mm, y_mm, z_mm } => ([x_mm[1] - x_mm[0], y_mm[1] - y_mm[0], z_mm[1] - z_mm[0]], 3),
        };
        if !may_fit(p.count.1, sides, p.min_spacing_mm) {
            let shown = sides[..dims].iter().map(|x| format!("{x}")).collect::<Vec<_>>().join(" x ");
            let region = if dims == 2 { "plate" } else { "box" };
            return Err(err(
                path,
                "points.min_spacing_mm",
                format!(
                    "{}: no design of {} points (points.count = [{}, {}]) can meet it: they cannot be that far apart in the {region} of {shown} mm",
                    p.min_spacing_mm, p.count.1, p.count.0, p.count.1
                ),
            ));
        }
    }
    Ok(())
}
