//! The plan file (`calsim plan <plan.toml>`): the arm, the laser tracker and its placement, the
//! targets on the flange, the cell, the model to identify and the sizes; every key checked, every
//! fault one line naming the file and the key.

use std::path::{Path, PathBuf};

use nalgebra::Vector3;
use serde::Deserialize;

use crate::calibrate::ModelKind;
use crate::calibrate::plan::Statistic;
use crate::instrument::laser_tracker::LaserTrackerSpec;
use crate::robot::file::RobotFile;
use crate::robot::{JOINTS, JointLimit, ParamSet};

/// A plan file's fault: the file, the key, what is wrong.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{path}: {key}: {message}")]
pub struct PlanError {
    /// The plan file.
    pub path: String,
    /// The key (`tracker.position_mm`, `poses`, `(file)`).
    pub key: String,
    /// What is wrong.
    pub message: String,
}

impl PlanError {
    pub(crate) fn new(path: &Path, key: impl Into<String>, message: impl Into<String>) -> Self {
        Self { path: path.display().to_string(), key: key.into(), message: message.into() }
    }
}

/// Most poses, pool configurations, validation poses and simulated worlds a plan takes.
pub const MOST_POSES: usize = 2_000;
/// Most pool configurations.
pub const MOST_POOL: usize = 100_000;
/// Most simulated worlds (each a whole calibration).
pub const MOST_WORLDS: usize = crate::calibrate::MOST_PLAN_WORLDS;
/// Fewest validation poses when there are any (calibrate's rule for a session).
pub const FEWEST_VALIDATION: usize = 5;
/// Largest coordinate accepted anywhere, mm (100 m).
const MOST_MM: f64 = 100_000.0;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Raw {
    robot: String,
    model: String,
    poses: Option<usize>,
    pool: usize,
    #[serde(default)]
    validation: usize,
    #[serde(default = "one")]
    seed: u64,
    #[serde(default = "thirty")]
    worlds: usize,
    tracker: RawTracker,
    target: Vec<RawTarget>,
    cell: RawCell,
    objective: Option<RawObjective>,
    #[serde(default)]
    compare: bool,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawObjective {
    statistic: String,
    threshold_mm: f64,
    success_at_least: f64,
    #[serde(default = "ninety")]
    confidence: f64,
    most_poses: Option<usize>,
}

fn ninety() -> f64 {
    0.9
}

fn one() -> u64 {
    1
}

fn thirty() -> usize {
    30
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTracker {
    position_mm: [f64; 3],
    aim_mm: [f64; 3],
    field_of_view_half_angle_deg: f64,
    min_range_mm: f64,
    max_range_mm: f64,
    incidence_max_deg: f64,
    #[serde(default = "head_radius")]
    head_radius_mm: f64,
    #[serde(default = "smr_diameter")]
    smr_diameter_mm: f64,
    range_sigma_um: Option<f64>,
    range_sigma_um_per_m: Option<f64>,
    transverse_sigma_um: Option<f64>,
    transverse_sigma_um_per_m: Option<f64>,
}

fn head_radius() -> f64 {
    // ASSUMED: a tracker head about 300 mm across (FARO ION / Leica AT960 class).
    150.0
}

fn smr_diameter() -> f64 {
    // ASSUMED: the common 1.5 in SMR.
    38.1
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTarget {
    name: String,
    flange_mm: [f64; 3],
    #[serde(default = "z_axis")]
    axis: [f64; 3],
}

fn z_axis() -> [f64; 3] {
    [0.0, 0.0, 1.0]
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawCell {
    joint_limits_deg: Option<Vec<[f64; 2]>>,
    floor_z_mm: Option<f64>,
    #[serde(default)]
    keep_out: Vec<RawBox>,
    workspace_min_mm: [f64; 3],
    workspace_max_mm: [f64; 3],
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBox {
    name: String,
    min_mm: [f64; 3],
    max_mm: [f64; 3],
}

/// The laser tracker of a plan, in the robot base frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Tracker {
    /// Head position, mm.
    pub position_mm: Vector3<f64>,
    /// The point the tracker faces (the axis of its field of view), mm.
    pub aim_mm: Vector3<f64>,
    /// Half-angle of the field of view around the aim, rad.
    pub field_of_view_half_rad: f64,
    /// Range band, mm.
    pub range_mm: (f64, f64),
    /// Largest angle between an SMR's axis and the line to the tracker, rad.
    pub incidence_max_rad: f64,
    /// Radius of the head (a keep-out sphere for the arm), mm.
    pub head_radius_mm: f64,
    /// SMR diameter (a sphere on the flange for collisions; the last radius of a line of sight), mm.
    pub smr_diameter_mm: f64,
    /// Noise: range constant (um), range per metre (um/m), transverse constant (um), transverse per metre (um/m).
    pub noise_um: [f64; 4],
}

impl Tracker {
    /// Isotropic noise per coordinate at distance `d_mm`, mm: the range and the two transverse
    /// standard deviations pooled, `sqrt((s_r^2 + 2 s_t^2) / 3)`.
    pub fn sigma_mm(&self, d_mm: f64) -> f64 {
        let d_m = d_mm * 1e-3;
        let [a_r, b_r, a_t, b_t] = self.noise_um;
        let sr = (a_r + b_r * d_m) * 1e-3;
        let st = (a_t + b_t * d_m) * 1e-3;
        ((sr * sr + 2.0 * st * st) / 3.0).sqrt()
    }
}

/// A target on the flange.
#[derive(Clone, Debug, PartialEq)]
pub struct Target {
    /// Label (the CSV's `target`).
    pub name: String,
    /// Position in MDH frame 6 (the robot file's flange rotation applied), mm.
    pub frame6_mm: Vector3<f64>,
    /// The SMR's axis in MDH frame 6, unit.
    pub axis6: Vector3<f64>,
}

/// An axis-aligned box in the base frame.
#[derive(Clone, Debug, PartialEq)]
pub struct BoxMm {
    /// Name.
    pub name: String,
    /// Lower corner, mm.
    pub min: Vector3<f64>,
    /// Upper corner, mm.
    pub max: Vector3<f64>,
}

impl BoxMm {
    /// Whether `p` lies inside (boundary included).
    pub fn contains(&self, p: &Vector3<f64>) -> bool {
        (0..3).all(|i| p[i] >= self.min[i] && p[i] <= self.max[i])
    }
}

/// The number of poses by objective: the smallest count whose worlds show
/// `P(statistic <= threshold_mm) >= success_at_least` at `confidence` (the one-sided lower
/// Clopper-Pearson bound over the worlds).
#[derive(Clone, Debug, PartialEq)]
pub struct Objective {
    /// The held-out statistic of a world.
    pub statistic: Statistic,
    /// A world succeeds when its statistic is at most this, mm.
    pub threshold_mm: f64,
    /// The probability of success the lower bound must reach.
    pub success_at_least: f64,
    /// Confidence of the lower bound.
    pub confidence: f64,
    /// The fewest poses tried (the model's parameters with a base and a tool).
    pub fewest_poses: usize,
    /// The most poses tried.
    pub most_poses: usize,
}

/// The held-out statistics an objective may name.
pub const OBJECTIVE_STATISTICS: [Statistic; 4] = [Statistic::Max, Statistic::P95, Statistic::Median, Statistic::Rms];

/// Most a threshold may be, mm.
const MOST_THRESHOLD_MM: f64 = 1000.0;

/// A checked plan.
#[derive(Clone, Debug)]
pub struct Plan {
    /// The plan file.
    pub path: PathBuf,
    /// The robot as the plan names it.
    pub robot_name: String,
    /// The robot file.
    pub robot: RobotFile,
    /// The joint limits the poses keep to (the robot file's, narrowed by the plan), rad.
    pub limits: [JointLimit; JOINTS],
    /// The calibrate model whose parameters the poses are chosen for.
    pub model: ModelKind,
    /// Training poses (with an objective: the fewest its search tries).
    pub poses: usize,
    /// The number of poses by objective (`None`: `poses` fixed).
    pub objective: Option<Objective>,
    /// Also compare DETMAX's set with a random and a greedy one on the same worlds.
    pub compare: bool,
    /// Feasible configurations DETMAX chooses from.
    pub pool: usize,
    /// Validation poses (0: none).
    pub validation: usize,
    /// Seed of every stream of the plan.
    pub seed: u64,
    /// Simulated worlds of the predicted held-out error.
    pub worlds: usize,
    /// The tracker.
    pub tracker: Tracker,
    /// The targets.
    pub targets: Vec<Target>,
    /// Floor height, mm (`None`: no floor).
    pub floor_z_mm: Option<f64>,
    /// Keep-out boxes.
    pub keep_out: Vec<BoxMm>,
    /// The workspace of interest (validation poses are spread over it).
    pub workspace: BoxMm,
}

/// The robot parameters of `kind` among calibrate's default set (its most complete model).
pub fn model_params(kind: ModelKind) -> ParamSet {
    kind.subset(&crate::calibrate::default_params())
}

/// Unknowns of the one-target identification DETMAX scores: the model's robot parameters, a base
/// (6) and a tool (3).
pub fn unknowns(kind: ModelKind) -> usize {
    model_params(kind).len() + 9
}

/// The built-in arms a plan may name instead of a file.
pub const BUILTIN: [&str; 1] = ["irb120"];

fn builtin(name: &str) -> Option<RobotFile> {
    match name {
        "irb120" => {
            let caps = crate::cell::collision::irb120_link_capsules();
            let text = crate::robot::file::to_text(&crate::robot::builtin::irb120(), "built-in irb120", &[], Some(&caps), None);
            RobotFile::from_text(Path::new("irb120 (built-in)"), &text).ok()
        }
        _ => None,
    }
}

/// The plan's robot: a built-in arm by name, or a robot file relative to the plan; it must have
/// collision capsules.
pub(crate) fn load_robot(path: &Path, name: &str) -> Result<RobotFile, PlanError> {
    let err = |key: &str, message: String| PlanError::new(path, key, message);
    let robot = match builtin(name) {
        Some(r) => r,
        None => {
            let file = crate::device::scenario::relative_to(path, Path::new(name));
            RobotFile::load(&file).map_err(|e| {
                err(
                    "robot",
                    format!(
                        "{} (a robot file relative to the plan, or a built-in arm: {})",
                        e.to_string().replace('\n', " "),
                        BUILTIN.join(", ")
                    ),
                )
            })?
        }
    };
    if robot.capsules.is_none() {
        return Err(err("robot", format!("{} has no [[collision]] capsules: a plan needs them to keep the poses free of collision", name)));
    }
    Ok(robot)
}

/// The checked `[cell]` of a plan.
#[derive(Clone, Debug, PartialEq)]
pub struct CellKeys {
    /// The joint limits (the robot file's, narrowed), rad.
    pub limits: [JointLimit; JOINTS],
    /// Floor height, mm (`None`: no floor).
    pub floor_z_mm: Option<f64>,
    /// Keep-out boxes.
    pub keep_out: Vec<BoxMm>,
    /// The workspace of interest.
    pub workspace: BoxMm,
}

/// Checks a plan's `[cell]` against its robot file.
pub(crate) fn cell(path: &Path, c: &RawCell, robot: &RobotFile) -> Result<CellKeys, PlanError> {
    let err = |key: &str, message: String| PlanError::new(path, key, message);
    let finite = |key: &str, v: &[f64]| -> Result<(), PlanError> {
        match v.iter().find(|x| !x.is_finite() || x.abs() > MOST_MM) {
            Some(x) => Err(err(key, format!("{x} is not a finite number within +-{MOST_MM} "))),
            None => Ok(()),
        }
    };
    let mut limits = *robot.nominal.limits();
    if let Some(l) = &c.joint_limits_deg {
        if l.len() != JOINTS {
            return Err(err("cell.joint_limits_deg", format!("{} pairs: one [min, max] per joint, {JOINTS}", l.len())));
        }
        for (i, [lo, hi]) in l.iter().enumerate() {
            let file = robot.nominal.limits()[i];
            let (lo_r, hi_r) = (lo.to_radians(), hi.to_radians());
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(err("cell.joint_limits_deg", format!("joint {}: [{lo}, {hi}] is not an interval", i + 1)));
            }
            if lo_r < file.min - 1e-12 || hi_r > file.max + 1e-12 {
                return Err(err(
                    "cell.joint_limits_deg",
                    format!(
                        "joint {}: [{lo}, {hi}] deg leaves the robot file's limits [{:.3}, {:.3}] deg (narrow them, do not widen them)",
                        i + 1,
                        file.min.to_degrees(),
                        file.max.to_degrees()
                    ),
                ));
            }
            limits[i] = JointLimit { min: lo_r.max(file.min), max: hi_r.min(file.max) };
        }
    }
    if let Some(f) = c.floor_z_mm {
        finite("cell.floor_z_mm", &[f])?;
    }
    let mut keep_out = Vec::new();
    for (k, b) in c.keep_out.iter().enumerate() {
        let key = |f: &str| format!("cell.keep_out[{}].{f}", k + 1);
        finite(&key("min_mm"), &b.min_mm)?;
        finite(&key("max_mm"), &b.max_mm)?;
        if (0..3).any(|i| b.min_mm[i] >= b.max_mm[i]) {
            return Err(err(&key("max_mm"), "every coordinate above min_mm's".into()));
        }
        keep_out.push(BoxMm { name: b.name.clone(), min: vec3(b.min_mm), max: vec3(b.max_mm) });
    }
    finite("cell.workspace_min_mm", &c.workspace_min_mm)?;
    finite("cell.workspace_max_mm", &c.workspace_max_mm)?;
    if (0..3).any(|i| c.workspace_min_mm[i] >= c.workspace_max_mm[i]) {
        return Err(err("cell.workspace_max_mm", "every coordinate above workspace_min_mm's".into()));
    }
    let workspace = BoxMm { name: "workspace of interest".into(), min: vec3(c.workspace_min_mm), max: vec3(c.workspace_max_mm) };
    Ok(CellKeys { limits, floor_z_mm: c.floor_z_mm, keep_out, workspace })
}

fn vec3(v: [f64; 3]) -> Vector3<f64> {
    Vector3::new(v[0], v[1], v[2])
}

/// Checks a plan file's text (`path` names it in errors; a robot file is found relative to it).
pub fn parse(path: &Path, text: &str) -> Result<Plan, PlanError> {
    let err = |key: &str, message: String| PlanError::new(path, key, message);
    let raw: Raw =
        crate::io::toml_de::from_str(text).map_err(|e| err(&crate::io::toml_position(text, e.span()), e.message().replace('\n', " ")))?;
    let finite = |key: &str, v: &[f64]| -> Result<(), PlanError> {
        match v.iter().find(|x| !x.is_finite() || x.abs() > MOST_MM) {
            Some(x) => Err(err(key, format!("{x} is not a finite number within +-{MOST_MM} "))),
            None => Ok(()),
        }
    };
    // Robot.
    let robot = load_robot(path, &raw.robot)?;
    let model = ModelKind::ALL
        .into_iter()
        .find(|k| k.name() == raw.model)
        .ok_or_else(|| err("model", format!("\"{}\" is not a calibrate model (offsets, geometric, compliance)", raw.model)))?;
    // Sizes.
    let m = unknowns(model);
    if !(1..=MOST_WORLDS).contains(&raw.worlds) {
        return Err(err("worlds", format!("{}: 1 to {MOST_WORLDS}", raw.worlds)));
    }
    let objective = match &raw.objective {
        None => None,
        Some(o) => Some(objective(path, o, raw.poses, raw.pool, raw.worlds, m)?),
    };
    let poses = match (raw.poses, &objective) {
        (Some(n), None) => n,
        (None, Some(o)) => o.fewest_poses,
        (None, None) => return Err(err("poses", "missing: a count of training poses, or an [objective] that sets it".into())),
        (Some(_), Some(_)) => {
            return Err(err("poses", "and [objective] both set the count of training poses: give one of them".into()));
        }
    };
    let raw_poses = poses;
    if raw_poses < m {
        return Err(err(
            "poses",
            format!(
                "{} is below the {m} parameters of the {} model with a base and a tool (its robot parameters, 6, 3)",
                raw_poses,
                model.name()
            ),
        ));
    }
    if raw_poses > MOST_POSES {
        return Err(err("poses", format!("{} is above {MOST_POSES}", raw_poses)));
    }
    if raw.validation != 0 && !(FEWEST_VALIDATION..=MOST_POSES).contains(&raw.validation) {
        return Err(err(
            "validation",
            format!("{}: 0 (none) or {FEWEST_VALIDATION} to {MOST_POSES} (a held-out session fixes its own frame)", raw.validation),
        ));
    }
    if objective.is_some() && raw.validation == 0 {
        return Err(err(
            "validation",
            "0: an [objective] is judged on the held-out errors of the validation poses (the workspace of interest); set validation".into(),
        ));
    }
    if raw.pool <= raw_poses || raw.pool > MOST_POOL {
        return Err(err("pool", format!("{}: more than the {} poses, at most {MOST_POOL}", raw.pool, raw_poses)));
    }
    // Tracker.
    let t = &raw.tracker;
    finite("tracker.position_mm", &t.position_mm)?;
    finite("tracker.aim_mm", &t.aim_mm)?;
    let angle = |key: &str, v: f64, most: f64| -> Result<f64, PlanError> {
        if v.is_finite() && v > 0.0 && v <= most { Ok(v.to_radians()) } else { Err(err(key, format!("{v}: within (0, {most}] deg"))) }
    };
    let fov = angle("tracker.field_of_view_half_angle_deg", t.field_of_view_half_angle_deg, 180.0)?;
    let incidence = angle("tracker.incidence_max_deg", t.incidence_max_deg, 90.0)?;
    finite("tracker.min_range_mm", &[t.min_range_mm])?;
    finite("tracker.max_range_mm", &[t.max_range_mm])?;
    if !(t.min_range_mm >= 0.0 && t.max_range_mm > t.min_range_mm) {
        return Err(err(
            "tracker.max_range_mm",
            format!("{}: above min_range_mm ({}) and min_range_mm >= 0", t.max_range_mm, t.min_range_mm),
        ));
    }
    for (key, v) in [("tracker.head_radius_mm", t.head_radius_mm), ("tracker.smr_diameter_mm", t.smr_diameter_mm)] {
        if !(v.is_finite() && v > 0.0 && v <= 2000.0) {
            return Err(err(key, format!("{v}: within (0, 2000] mm")));
        }
    }
    if (vec3(t.aim_mm) - vec3(t.position_mm)).norm() < 1.0 {
        return Err(err("tracker.aim_mm", "is the tracker's own position: it names the direction the tracker faces".into()));
    }
    let d = LaserTrackerSpec::default();
    let mut noise_um = [d.range_sigma_um, d.range_sigma_um_per_m, d.transverse_sigma_um, d.transverse_sigma_um_per_m];
    for (k, (key, v)) in [
        ("tracker.range_sigma_um", t.range_sigma_um),
        ("tracker.range_sigma_um_per_m", t.range_sigma_um_per_m),
        ("tracker.transverse_sigma_um", t.transverse_sigma_um),
        ("tracker.transverse_sigma_um_per_m", t.transverse_sigma_um_per_m),
    ]
    .into_iter()
    .enumerate()
    {
        if let Some(v) = v {
            if !(v.is_finite() && (0.0..=10_000.0).contains(&v)) {
                return Err(err(key, format!("{v}: within 0 to 10,000 um")));
            }
            noise_um[k] = v;
        }
    }
    let tracker = Tracker {
        position_mm: vec3(t.position_mm),
        aim_mm: vec3(t.aim_mm),
        field_of_view_half_rad: fov,
        range_mm: (t.min_range_mm, t.max_range_mm),
        incidence_max_rad: incidence,
        head_radius_mm: t.head_radius_mm,
        smr_diameter_mm: t.smr_diameter_mm,
        noise_um,
    };
    // Targets.
    if raw.target.is_empty() {
        return Err(err("target", "no [[target]]: name at least one target on the flange".into()));
    }
    let flange = robot.flange.unwrap_or_else(nalgebra::Matrix3::identity);
    let mut targets: Vec<Target> = Vec::new();
    for (k, rt) in raw.target.iter().enumerate() {
        let key = |f: &str| format!("target[{}].{f}", k + 1);
        if rt.name.is_empty() || rt.name.len() > 64 || !rt.name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-') {
            return Err(err(&key("name"), format!("\"{}\": 1 to 64 letters, digits, '_' or '-'", rt.name.escape_default())));
        }
        if targets.iter().any(|o| o.name == rt.name) {
            return Err(err(&key("name"), format!("\"{}\" names two targets", rt.name)));
        }
        finite(&key("flange_mm"), &rt.flange_mm)?;
        finite(&key("axis"), &rt.axis)?;
        let axis = vec3(rt.axis);
        if axis.norm() < 1e-9 {
            return Err(err(&key("axis"), "is zero: the direction the SMR opens towards, in the flange frame".into()));
        }
        targets.push(Target { name: rt.name.clone(), frame6_mm: flange * vec3(rt.flange_mm), axis6: flange * axis.normalize() });
    }
    // Cell.
    let CellKeys { limits, floor_z_mm, keep_out, workspace } = cell(path, &raw.cell, &robot)?;
    if let Some(f) = floor_z_mm
        && tracker.position_mm.z < f
    {
        return Err(err("tracker.position_mm", format!("is below the floor (z {} < floor_z_mm {f})", tracker.position_mm.z)));
    }
    if let Some(b) = keep_out.iter().find(|b| b.contains(&tracker.position_mm)) {
        return Err(err("tracker.position_mm", format!("is inside the keep-out box {}", b.name)));
    }
    Ok(Plan {
        path: path.to_path_buf(),
        robot_name: raw.robot,
        robot,
        limits,
        model,
        poses,
        objective,
        compare: raw.compare,
        pool: raw.pool,
        validation: raw.validation,
        seed: raw.seed,
        worlds: raw.worlds,
        tracker,
        targets,
        floor_z_mm,
        keep_out,
        workspace,
    })
}

/// Checks `[objective]`: a statistic by name, a threshold within (0, 1000] mm, a probability
/// below 1 that `worlds` worlds can show at the confidence, a confidence within [0.5, 0.999], a
/// most poses between the model's count and the pool's.
pub(crate) fn objective(
    path: &Path,
    o: &RawObjective,
    poses: Option<usize>,
    pool: usize,
    worlds: usize,
    m: usize,
) -> Result<Objective, PlanError> {
    let err = |key: &str, message: String| PlanError::new(path, key, message);
    let names: Vec<&str> = OBJECTIVE_STATISTICS.iter().map(|s| s.name()).collect();
    let statistic = OBJECTIVE_STATISTICS.into_iter().find(|s| s.name() == o.statistic).ok_or_else(|| {
        err("objective.statistic", format!("\"{}\" is not a held-out statistic ({})", o.statistic.escape_default(), names.join(", ")))
    })?;
    if !(o.threshold_mm.is_finite() && o.threshold_mm > 0.0 && o.threshold_mm <= MOST_THRESHOLD_MM) {
        return Err(err("objective.threshold_mm", format!("{}: within (0, {MOST_THRESHOLD_MM}] mm", o.threshold_mm)));
    }
    if !(o.confidence.is_finite() && (0.5..=0.999).contains(&o.confidence)) {
        return Err(err("objective.confidence", format!("{}: within [0.5, 0.999]", o.confidence)));
    }
    if !(o.success_at_least.is_finite() && o.success_at_least > 0.0 && o.success_at_least < 1.0) {
        return Err(err("objective.success_at_least", format!("{}: a probability within (0, 1)", o.success_at_least)));
    }
    // Every world a success gives the lower bound (1 - confidence)^(1 / worlds), the most it can show.
    let most = crate::study::interval::clopper_pearson_lower(worlds as f64, worlds as f64, o.confidence);
    if o.success_at_least > most {
        let need = ((1.0 - o.confidence).ln() / o.success_at_least.ln()).ceil();
        return Err(err(
            "objective.success_at_least",
            format!(
                "{} cannot be shown by {worlds} worlds at {} confidence (all {worlds} succeeding show at most {most:.4}): set worlds to {need} or more",
                o.success_at_least, o.confidence
            ),
        ));
    }
    if poses.is_some() {
        return Err(err("poses", "and [objective] both set the count of training poses: give one of them".into()));
    }
    let most_poses = o.most_poses.unwrap_or_else(|| pool.saturating_sub(1).min(MOST_POSES));
    if most_poses < m || most_poses >= pool || most_poses > MOST_POSES {
        return Err(err(
            "objective.most_poses",
            format!("{most_poses}: at least the model's {m} parameters, below the pool ({pool}), at most {MOST_POSES}"),
        ));
    }
    Ok(Objective {
        statistic,
        threshold_mm: o.threshold_mm,
        success_at_least: o.success_at_least,
        confidence: o.confidence,
        fewest_poses: m,
        most_poses,
    })
}
