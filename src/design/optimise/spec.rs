//! A design file: the base scenario, the design space over its keys (continuous, integer and
//! choice variables, and a set of points: the TriCal datum spheres or the SPMS stations, their
//! count enumerated and each point's position searched within a region), the `[objective]` of
//! the sweeps, and how to search and verify.
//!
//! Every variable maps the unit interval onto its values, so that a design is a point `x` of
//! `[0, 1]^d` for each count of points ([`Space::decode`]); a design the geometry rules out (two
//! points closer than the spacing, three that define no frame) is a violation with its margin,
//! never a scenario that fails to load.

use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use serde::Deserialize;

use crate::design::sweep::objective::{Objective, ObjectiveFile};
use crate::design::sweep::race::Race;
use crate::design::sweep::spec::{circle_layout, get_dotted, set_dotted};
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
            Domain::Range(lo, hi) => toml::Value::Float(lo + t * (hi - lo)),
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
}

/// Which optimiser searches.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    /// argmin's Nelder-Mead simplex, started around the start design.
    NelderMead,
    /// argmin's particle swarm over the unit cube.
    ParticleSwarm,
}

impl Method {
    /// The name as the file writes it.
    pub fn label(self) -> &'static str {
        match self {
            Method::NelderMead => "nelder_mead",
            Method::ParticleSwarm => "particle_swarm",
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
}

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
}

/// A design decoded: its scenario table, or why the geometry rules it out (with the margin, mm).
#[derive(Clone, Debug)]
pub struct Decoded {
    /// The scenario table.
    pub table: toml::Table,
    /// The values as `key = value` for tables and summaries.
    pub values: Vec<(String, String)>,
    /// The points in the region's frame, mm (empty without points).
    pub points_mm: Vec<[f64; 3]>,
    /// A geometric violation: what, and by how much (mm).
    pub violation: Option<(String, f64)>,
}

/// Most points of a design.
pub const MOST_POINTS: usize = 12;

impl DesignSpace {
    /// The counts of points searched (one stratum each; `[0]` without points).
    pub fn counts(&self) -> Vec<usize> {
        match &self.points {
            Some(p) => (p.count.0..=p.count.1).collect(),
            None => vec![0],
        }
    }

    /// Dimensions of the unit cube for `count` points.
    pub fn dimensions(&self, count: usize) -> usize {
        let per = match self.points.as_ref().map(|p| &p.region) {
            Some(Region::Plate { .. }) => 2,
            Some(Region::Box { .. }) => 3,
            None => 0,
        };
        let plate = match self.points.as_ref().map(|p| &p.region) {
            Some(Region::Plate { .. }) => 2,
            _ => 0,
        };
        self.variables.len() + plate + per * count
    }

    /// The start design of `count` points in the unit cube.
    pub fn start(&self, count: usize) -> Vec<f64> {
        let mut x: Vec<f64> = self.variables.iter().map(|v| v.start).collect();
        if let Some(p) = &self.points {
            let circle = circle_layout(count.max(3), p.start_spacing_mm);
            let unit = |v: f64, r: [f64; 2]| if r[1] > r[0] { ((v - r[0]) / (r[1] - r[0])).clamp(0.0, 1.0) } else { 0.5 };
            let o = p.start_offset_mm;
            match &p.region {
                Region::Plate { x_mm, y_mm, height_mm, tilt_deg } => {
                    x.push(unit(p.start_plate.0, *height_mm));
                    x.push(unit(p.start_plate.1, *tilt_deg));
                    for c in circle.iter().take(count) {
                        x.push(unit(c[0] + o[0], *x_mm));
                        x.push(unit(c[1] + o[1], *y_mm));
                    }
                }
                Region::Box { x_mm, y_mm, z_mm } => {
                    for c in circle.iter().take(count) {
                        x.push(unit(c[0] + o[0], *x_mm));
                        x.push(unit(c[1] + o[1], *y_mm));
                        x.push(unit(c[2] + o[2], *z_mm));
                    }
                }
            }
        }
        x
    }

    /// The design at `x` (unit cube, `count` points): its scenario table, or its violation.
    pub fn decode(&self, count: usize, x: &[f64]) -> Decoded {
        let mut table = self.base.clone();
        let mut values = Vec::new();
        for (v, t) in self.variables.iter().zip(x) {
            let value = v.value(*t);
            values.push((v.key.clone(), value.to_string()));
            set_dotted(&mut table, &v.key, value).expect("checked when the file was loaded");
        }
        let mut out = Decoded { table, values, points_mm: Vec::new(), violation: None };
        let Some(p) = &self.points else { return out };
        let rest = &x[self.variables.len()..];
        let at = |t: f64, r: [f64; 2]| r[0] + t.clamp(0.0, 1.0) * (r[1] - r[0]);
        let (points, plate): (Vec<Vector3<f64>>, Option<(f64, f64)>) = match &p.region {
            Region::Plate { x_mm, y_mm, height_mm, tilt_deg } => {
                let (h, tilt) = (at(rest[0], *height_mm), at(rest[1], *tilt_deg));
                let lift = Isometry3::from_parts(
                    Translation3::new(0.0, 0.0, h),
                    UnitQuaternion::from_axis_angle(&Vector3::x_axis(), tilt.to_radians()),
                );
                let pts = (0..count)
                    .map(|k| lift * nalgebra::Point3::new(at(rest[2 + 2 * k], *x_mm), at(rest[3 + 2 * k], *y_mm), 0.0))
                    .map(|q| q.coords)
                    .collect();
                (pts, Some((h, tilt)))
            }
            Region::Box { x_mm, y_mm, z_mm } => (
                (0..count).map(|k| Vector3::new(at(rest[3 * k], *x_mm), at(rest[3 * k + 1], *y_mm), at(rest[3 * k + 2], *z_mm))).collect(),
                None,
            ),
        };
        let round = |v: f64| (v * 1e3).round() / 1e3;
        out.points_mm = points.iter().map(|q| [round(q.x), round(q.y), round(q.z)]).collect();
        if let Some((h, t)) = plate {
            out.values.push(("plate.height_mm".into(), format!("{:.1}", h)));
            out.values.push(("plate.tilt_deg".into(), format!("{:.2}", t)));
        }
        out.values.push((format!("{}.count", p.key), count.to_string()));
        out.values.push((p.key.clone(), format!("{:?}", out.points_mm)));
        // Spacing: the closest pair, short by how much.
        let mut closest = (f64::INFINITY, 0, 0);
        for i in 0..points.len() {
            for j in 0..i {
                let d = (points[i] - points[j]).norm();
                if d < closest.0 {
                    closest = (d, j, i);
                }
            }
        }
        if closest.0 < p.min_spacing_mm {
            out.violation = Some((
                format!(
                    "points {} and {} are {:.1} mm apart, under min_spacing_mm = {}",
                    closest.1 + 1,
                    closest.2 + 1,
                    closest.0,
                    p.min_spacing_mm
                ),
                p.min_spacing_mm - closest.0,
            ));
            return out;
        }
        let floats = |v: &[f64]| toml::Value::Array(v.iter().map(|x| toml::Value::Float(*x)).collect());
        if p.key == "cell.spheres_w_mm" {
            // {W} from the first three spheres (eqs. 1-5): origin at 1, x towards 2, z normal to
            // the plane of 1, 2, 3 (3 on the +y side). The plate offset is W0_from_W.
            let (a, b, c) = (points[0], points[1], points[2]);
            let ex = (b - a).normalize();
            let n = ex.cross(&(c - a));
            let sine = n.norm() / (c - a).norm();
            if sine < 0.2 {
                out.violation = Some((
                    format!("spheres 1, 2 and 3 are nearly on one line (sine of their angle {sine:.3} < 0.2): they define no {{W}}"),
                    (0.2 - sine) * (c - a).norm(),
                ));
                return out;
            }
            let ez = n.normalize();
            let ey = ez.cross(&ex);
            let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[ex, ey, ez])));
            let w0_from_w = Isometry3::from_parts(Translation3::from(a), rot);
            let in_w: Vec<toml::Value> = points
                .iter()
                .enumerate()
                .map(|(k, q)| {
                    let w = w0_from_w.inverse() * nalgebra::Point3::from(*q);
                    // {W}'s own rules, exact: sphere 1 at the origin, 2 on +x, 3 in the xy plane.
                    let mut v = [round(w.x), round(w.y), round(w.z)];
                    if k == 0 {
                        v = [0.0; 3];
                    }
                    if k == 1 {
                        v[1] = 0.0;
                        v[2] = 0.0;
                    }
                    if k == 2 {
                        v[2] = 0.0;
                    }
                    floats(&v)
                })
                .collect();
            let pose = crate::robot::XyzZyx::from_isometry(&w0_from_w);
            let offset = [pose.x, pose.y, pose.z, pose.alpha.to_degrees(), pose.beta.to_degrees(), pose.gamma.to_degrees()]
                .map(|v| (v * 1e6).round() / 1e6);
            set_dotted(&mut out.table, "cell.spheres_w_mm", toml::Value::Array(in_w)).expect("a table");
            set_dotted(&mut out.table, "cell.plate_offset_mm_deg", floats(&offset)).expect("a table");
        } else {
            let pts: Vec<toml::Value> = out.points_mm.iter().map(|q| floats(q)).collect();
            set_dotted(&mut out.table, &p.key, toml::Value::Array(pts)).expect("a table");
        }
        out
    }
}

/// Most designs evaluated per restart, most restarts, worlds.
const MOST_EVALUATIONS: u32 = 100_000;

/// Reads and checks a design file.
pub fn load(path: &Path) -> Result<DesignSpace, DesignError> {
    let text = crate::io::read_text(path).map_err(|e| err(path, "(file)", format!("cannot read: {e}")))?;
    let file: DesignFile = {
        let de = toml::Deserializer::parse(&text).map_err(|e| err(path, "(file)", e.message()))?;
        serde_path_to_error::deserialize(de).map_err(|e| {
            let key = e.path().to_string();
            err(path, key, e.into_inner().message())
        })?
    };
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
        // Every value of the variable must make a scenario of its kind: the ends and the start.
        for t in [0.0, 1.0, var.start] {
            let mut probe = base.clone();
            set_dotted(&mut probe, &v.key, var.value(t)).map_err(|m| err(path, at("key"), m))?;
            if let Some(s) = check_table(&probe, &base_path) {
                return Err(err(path, at("key"), format!("value {}: {s}", var.value(t))));
            }
        }
        variables.push(var);
    }
    let points = file.points.as_ref().map(|p| points(path, p)).transpose()?;
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
    let space = DesignSpace { name, path: path.to_path_buf(), base, identity, variables, points, objective, search, held_out, compare };
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
    Ok(Points {
        key: p.key.clone(),
        count: (lo as usize, hi as usize),
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

fn search(path: &Path, s: &SearchFile) -> Result<Search, DesignError> {
    let method = match s.method.as_deref() {
        None | Some("nelder_mead") => Method::NelderMead,
        Some("particle_swarm") => Method::ParticleSwarm,
        Some(m) => return Err(err(path, "search.method", format!("{m:?}: \"nelder_mead\" or \"particle_swarm\""))),
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
        None => Race { min: worlds, batch: worlds, max: 4 * worlds, confidence: 0.9 },
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
    // The points must fit: the fewest points at the least spacing inside the region.
    if let Some(p) = &space.points {
        let (span_x, span_y, span_z) = match &p.region {
            Region::Plate { x_mm, y_mm, .. } => (x_mm[1] - x_mm[0], y_mm[1] - y_mm[0], 0.0),
            Region::Box { x_mm, y_mm, z_mm } => (x_mm[1] - x_mm[0], y_mm[1] - y_mm[0], z_mm[1] - z_mm[0]),
        };
        let diagonal = (span_x * span_x + span_y * span_y + span_z * span_z).sqrt();
        if p.count.0 >= 2 && diagonal < p.min_spacing_mm {
            return Err(err(
                path,
                "points.min_spacing_mm",
                format!("{}: no design can meet it: the region's diagonal is {diagonal:.0} mm, too small for two points", p.min_spacing_mm),
            ));
        }
    }
    Ok(())
}
