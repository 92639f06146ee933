//! `calsim plan` with a device that measures at configurations of its own (`[instrument] kind =
//! "trical"`: the TriCal centred on datum spheres).
//!
//! ```text
//! plan file ─► parse (the device's scenario, its spheres and pool size set from the plan; the cell)
//!  ─► Scenario::candidate_pool (the device's campaign in realisation 0: the centred
//!     configurations, what each observes, the identification Jacobian rows)
//!  ─► the pool kept within the plan's limits and free of collision (arm, device, the device's
//!     fixtures, the floor, the keep-out boxes)
//!  ─► validation configurations spread over the workspace of interest (farthest-point sampling)
//!  ─► DETMAX on the kept rows  ─► tour (greedy nearest neighbour, moves checked every degree, a
//!     colliding move re-routed through via configurations)
//!  ─► prediction: the device's own observations at the chosen configurations identified (the
//!     pilot), then the plan's worlds: the true arm observed at the chosen configurations with the
//!     pool's observation error, identified, compared with the true arm at the validation
//!     configurations
//! ```
//!
//! Every stream is keyed under the plan's seed (`seeds::plan`): the plan is the same for any
//! thread count.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use nalgebra::Vector3;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;
use serde::Deserialize;

use super::spec::{self, BoxMm, CellKeys, Objective, PlanError, RawCell, RawObjective};
use super::{Candidate, Search, TRAIN, TRAINING, VALIDATION};
use crate::calibrate::plan::Statistic;
use crate::cell::collision::{CapsuleSpec, CollisionWorld, Obstacle};
use crate::device::{CandidatePool, Scenario};
use crate::identify::{Observation, PoolJacobian};
use crate::robot::file::{LinkCapsules, RobotFile};
use crate::robot::{JOINTS, JointLimit, Joints, KinState, ParamSet, RobotModel, forward, uniform_configuration};
use crate::study::ErrorStats;

/// Instruments a plan's `[instrument]` may name: devices that measure at configurations of their own.
pub const KINDS: [&str; 2] = ["trical", "spms"];

/// Candidates drawn per validation configuration kept before the workspace of interest is given
/// up as out of reach.
const MOST_TRIES_PER_VALIDATION: usize = 2_000;

/// Validation configurations the farthest-point sampling chooses from, per one kept.
const VALIDATION_CANDIDATES_PER_POSE: usize = 10;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Raw {
    robot: String,
    poses: Option<usize>,
    pool: usize,
    validation: usize,
    #[serde(default = "one")]
    seed: u64,
    #[serde(default = "thirty")]
    worlds: usize,
    instrument: RawInstrument,
    cell: RawCell,
    objective: Option<RawObjective>,
}

fn one() -> u64 {
    1
}

fn thirty() -> usize {
    30
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawInstrument {
    kind: String,
    scenario: Option<String>,
    spheres_w_mm: Option<Vec<[f64; 3]>>,
}

/// A checked plan whose instrument is a device with a pool of its own.
#[derive(Clone, Debug)]
pub struct DevicePlan {
    /// The plan file.
    pub path: PathBuf,
    /// The robot as the plan names it.
    pub robot_name: String,
    /// The robot file.
    pub robot: RobotFile,
    /// The joint limits the poses keep to, rad.
    pub limits: [JointLimit; JOINTS],
    /// Training poses (with an objective: the fewest its search tries).
    pub poses: usize,
    /// The number of poses by objective (`None`: `poses` fixed).
    pub objective: Option<Objective>,
    /// Configurations the device's campaign centres (split evenly over its spheres).
    pub pool: usize,
    /// Validation configurations over the workspace of interest.
    pub validation: usize,
    /// Seed of every stream of the plan (and of the device's realisation).
    pub seed: u64,
    /// Simulated worlds of the predicted held-out error.
    pub worlds: usize,
    /// The instrument's kind (`trical`).
    pub kind: &'static str,
    /// The device's scenario file as the plan names it (`None`: the device's defaults).
    pub scenario_file: Option<String>,
    /// The device's scenario, the plan's spheres, pool size, robot and seed set in it.
    pub scenario: Box<dyn Scenario>,
    /// The parameters the device identifies.
    pub set: ParamSet,
    /// Floor height, mm (`None`: no floor).
    pub floor_z_mm: Option<f64>,
    /// Keep-out boxes.
    pub keep_out: Vec<BoxMm>,
    /// The workspace of interest.
    pub workspace: BoxMm,
}

/// Whether the plan text names an `[instrument]` (a device plan) rather than a `[tracker]`.
pub fn is_device_plan(text: &str) -> bool {
    toml::from_str::<toml::Table>(text).is_ok_and(|t| t.contains_key("instrument"))
}

/// The fewest training poses of a set of `m` parameters: three equations per configuration.
pub fn fewest_poses(m: usize) -> usize {
    m.div_ceil(3)
}

/// Checks a device plan's text (`path` names it in errors; files are found relative to it).
pub fn parse(path: &Path, text: &str) -> Result<DevicePlan, PlanError> {
    let err = |key: &str, message: String| PlanError::new(path, key, message);
    let raw: Raw =
        crate::io::toml_de::from_str(text).map_err(|e| err(&crate::io::toml_position(text, e.span()), e.message().replace('\n', " ")))?;
    let robot = spec::load_robot(path, &raw.robot)?;
    let kind = KINDS.into_iter().find(|k| *k == raw.instrument.kind).ok_or_else(|| {
        err(
            "instrument.kind",
            format!(
                "\"{}\" is not a device with a pool of its own ({}; a laser tracker or optical CMM is a [tracker] table)",
                raw.instrument.kind.escape_default(),
                KINDS.map(|k| format!("\"{k}\"")).join(", ")
            ),
        )
    })?;
    let device = crate::device::REGISTRY.iter().copied().find(|d| d.kind() == kind).expect("every plan instrument is a device");
    let (anchor, mut table) = match &raw.instrument.scenario {
        Some(f) => {
            let file = crate::device::scenario::relative_to(path, Path::new(f));
            let shown = file.display().to_string();
            let text = crate::io::read_text(&file).map_err(|e| err("instrument.scenario", format!("{shown}: {e}")))?;
            let t = crate::device::scenario::table(&text, &shown).map_err(|e| err("instrument.scenario", e.to_string()))?;
            (file, t)
        }
        None => (path.to_path_buf(), device.defaults()),
    };
    if let Some(k) = table.get("kind")
        && k.as_str() != Some(kind)
    {
        return Err(err("instrument.scenario", format!("is a {k} scenario, not a {kind} one")));
    }
    table.insert("kind".into(), kind.into());
    if kind == "spms" {
        spms_table(path, &mut table, &raw)?;
    } else {
        trical_table(path, &mut table, &raw)?;
    }
    let scenario_text = toml::to_string(&table).map_err(|e| err("instrument.scenario", e.to_string()))?;
    let mut scenario = device.load(&scenario_text, table, &anchor).map_err(|e| err("instrument.scenario", e.to_string()))?;
    scenario.header_mut().seed = raw.seed;
    let default_set = if kind == "spms" { crate::device::spms::calibration::default_parameters } else { ParamSet::trical_31 };
    let set = scenario.study().parameter_set(default_set).map_err(|e| err("instrument.scenario", e.to_string()))?;
    let m = fewest_poses(set.len());
    if !(1..=spec::MOST_WORLDS).contains(&raw.worlds) {
        return Err(err("worlds", format!("{}: 1 to {}", raw.worlds, spec::MOST_WORLDS)));
    }
    let objective = match &raw.objective {
        None => None,
        Some(o) => Some(spec::objective(path, o, raw.poses, raw.pool, raw.worlds, m)?),
    };
    let poses = match (raw.poses, &objective) {
        (Some(n), None) => n,
        (None, Some(o)) => o.fewest_poses,
        (None, None) => return Err(err("poses", "missing: a count of training poses, or an [objective] that sets it".into())),
        (Some(_), Some(_)) => return Err(err("poses", "and [objective] both set the count of training poses: give one of them".into())),
    };
    if poses < m {
        return Err(err("poses", format!("{poses} is below {m}: the {} parameters of the device need 3 equations each", set.len())));
    }
    if poses > spec::MOST_POSES {
        return Err(err("poses", format!("{poses} is above {}", spec::MOST_POSES)));
    }
    if !(spec::FEWEST_VALIDATION..=spec::MOST_POSES).contains(&raw.validation) {
        return Err(err(
            "validation",
            format!(
                "{}: {} to {} (the configurations over the workspace of interest the prediction is judged on)",
                raw.validation,
                spec::FEWEST_VALIDATION,
                spec::MOST_POSES
            ),
        ));
    }
    if raw.pool <= poses || raw.pool > spec::MOST_POOL {
        return Err(err("pool", format!("{}: more than the {poses} poses, at most {}", raw.pool, spec::MOST_POOL)));
    }
    let CellKeys { limits, floor_z_mm, keep_out, workspace } = spec::cell(path, &raw.cell, &robot)?;
    Ok(DevicePlan {
        path: path.to_path_buf(),
        robot_name: raw.robot,
        robot,
        limits,
        poses,
        objective,
        pool: raw.pool,
        validation: raw.validation,
        seed: raw.seed,
        worlds: raw.worlds,
        kind,
        scenario_file: raw.instrument.scenario,
        scenario,
        set,
        floor_z_mm,
        keep_out,
        workspace,
    })
}

/// Sets the plan's spheres, pool size and robot in a TriCal scenario's table. The campaign's own tracker validation is cut to one pose: the plan's validation
/// configurations replace it.
fn trical_table(path: &Path, table: &mut toml::Table, raw: &Raw) -> Result<(), PlanError> {
    let err = |key: &str, message: String| PlanError::new(path, key, message);
    let mut cell = section(table, "cell");
    if let Some(s) = &raw.instrument.spheres_w_mm {
        if let Some(x) = s.iter().flatten().find(|x| !x.is_finite()) {
            return Err(err("instrument.spheres_w_mm", format!("{x} is not a finite number")));
        }
        let arr: Vec<toml::Value> = s.iter().map(|p| toml::Value::Array(p.iter().map(|v| toml::Value::Float(*v)).collect())).collect();
        cell.insert("spheres_w_mm".into(), toml::Value::Array(arr));
    }
    let spheres = match cell.get("spheres_w_mm") {
        Some(toml::Value::Array(a)) => a.len(),
        _ => crate::cell::CellSpec::default().spheres_w_mm.len(),
    };
    table.insert("cell".into(), toml::Value::Table(cell));
    if spheres == 0 || !raw.pool.is_multiple_of(spheres) {
        return Err(err(
            "pool",
            format!("{}: a multiple of the {spheres} datum spheres (each sphere centres pool / spheres configurations)", raw.pool),
        ));
    }
    let per_sphere = i64::try_from(raw.pool / spheres).unwrap_or(i64::MAX);
    let mut campaign = section(table, "campaign");
    campaign.insert("pool_per_sphere".into(), per_sphere.into());
    campaign.insert("validation_poses".into(), 1i64.into());
    table.insert("campaign".into(), toml::Value::Table(campaign));
    let mut r = section(table, "robot");
    if spec::BUILTIN.contains(&raw.robot.as_str()) {
        r.remove("file");
    } else {
        r.insert("file".into(), absolute_robot(path, raw)?.into());
    }
    table.insert("robot".into(), toml::Value::Table(r));
    Ok(())
}

/// The table `name` of `table`, taken out of it (empty when it has none).
fn section(table: &mut toml::Table, name: &str) -> toml::Table {
    match table.remove(name) {
        Some(toml::Value::Table(t)) => t,
        _ => toml::Table::new(),
    }
}

/// The plan's robot file, absolute (the scenario's loader reads it relative to the scenario).
fn absolute_robot(path: &Path, raw: &Raw) -> Result<String, PlanError> {
    let file = crate::device::scenario::relative_to(path, Path::new(&raw.robot));
    let file = std::path::absolute(&file).map_err(|e| PlanError::new(path, "robot", e.to_string()))?;
    Ok(file.display().to_string())
}

/// Sets the plan's pool size (shared evenly among the stations) and robot file in an SPMS
/// scenario's table. The stations are the scenario's `[station]` table.
fn spms_table(path: &Path, table: &mut toml::Table, raw: &Raw) -> Result<(), PlanError> {
    let err = |key: &str, message: &str| PlanError::new(path, key, message.to_string());
    if raw.instrument.spheres_w_mm.is_some() {
        return Err(err(
            "instrument.spheres_w_mm",
            "the TriCal's datum spheres: an SPMS plan's stations are its scenario's [station] table",
        ));
    }
    if spec::BUILTIN.contains(&raw.robot.as_str()) {
        return Err(err("robot", "an SPMS plan names the arm's robot file (the built-in arms are the TriCal's)"));
    }
    let mut station = section(table, "station");
    station.insert("pool".into(), i64::try_from(raw.pool).unwrap_or(i64::MAX).into());
    table.insert("station".into(), toml::Value::Table(station));
    let mut r = section(table, "robot");
    r.insert("file".into(), absolute_robot(path, raw)?.into());
    table.insert("robot".into(), toml::Value::Table(r));
    Ok(())
}

/// One row of a device plan: a training configuration centred on its group (sphere), or a
/// validation configuration.
#[derive(Clone, Debug, PartialEq)]
pub struct DeviceRow {
    /// Label (`p001_s1`, `v001`).
    pub label: String,
    /// `train` or `holdout`.
    pub split: &'static str,
    /// The datum sphere of a training row (0-based).
    pub group: Option<usize>,
    /// The model's joint angles, rad.
    pub q: Joints,
}

/// A device plan's predicted held-out error.
#[derive(Clone, Debug, PartialEq)]
pub struct DevicePrediction {
    /// The pool's observation error per coordinate (the device's observations of realisation 0
    /// against the true arm's model, pooled), mm.
    pub noise_mm: f64,
    /// Held-out median per world over the validation configurations, mm (NaN: no model).
    pub per_world_mm: Vec<f64>,
    /// P10, median, P90 over the worlds with a value, mm.
    pub quantiles_mm: [f64; 3],
    /// The distribution-free 90 % interval of the median over the worlds, mm.
    pub median_interval_mm: (f64, f64),
    /// Worlds with a value.
    pub worlds: usize,
    /// The pilot: the device's own observations at the chosen configurations identified, its
    /// held-out median against the true arm, mm.
    pub pilot_median_mm: f64,
    /// Parameters the chosen configurations cannot separate (kept at their start values).
    pub unidentifiable: Vec<String>,
}

/// What a device plan computed.
#[derive(Clone, Debug)]
pub struct DeviceOutcome {
    /// The device's pool: configurations centred.
    pub candidates: usize,
    /// Refused: outside the plan's limits, in collision.
    pub refused: [usize; 2],
    /// Validation candidates drawn.
    pub validation_tried: usize,
    /// Training then validation rows.
    pub rows: Vec<DeviceRow>,
    /// Each training row's observed point in {W} (the sphere centre as the ballbar located it), mm.
    pub observed_w_mm: Vec<Vector3<f64>>,
    /// Each training row's distance between the true arm's TCP and its observed point, mm.
    pub centring_mm: Vec<f64>,
    /// The nominal sphere centres in {W}, mm.
    pub groups_w_mm: Vec<[f64; 3]>,
    /// O1 of DETMAX's set and of a random set of the same size.
    pub o1: (f64, f64),
    /// Parameters (columns) DETMAX scored.
    pub params: Vec<String>,
    /// Tour: positions in `rows`, and its length, rad.
    pub tour: (Vec<usize>, f64),
    /// Straight moves of the tour through a collision (positions in the tour).
    pub colliding_moves: Vec<(usize, usize)>,
    /// Those moves re-routed through via configurations, and those that could not be.
    pub routing: super::select::Routing,
    /// The prediction.
    pub prediction: DevicePrediction,
    /// Training poses planned.
    pub poses: usize,
    /// The objective's search (`None`: the count is fixed).
    pub search: Option<Search>,
    /// The objective as searched (its most poses below the pool kept).
    pub objective: Option<Objective>,
    /// The model before calibration (in {W}, the device's TCP).
    pub start: RobotModel,
    /// The true arm of the planning world (in {W}, the device's TCP; its effects outside the
    /// model not in it).
    pub truth: RobotModel,
    /// The identification's options (the device's study).
    pub fit: crate::identify::FitOptions,
    /// The arm's link capsules.
    pub links: LinkCapsules,
    /// The device's capsules in MDH frame 6.
    pub device: Vec<CapsuleSpec>,
}

/// The plan's collision world: the arm, the device, its fixtures, the floor and the keep-out boxes.
pub fn collision_world(
    plan: &DevicePlan,
    pool_links: &LinkCapsules,
    device: &[CapsuleSpec],
    fixtures: Vec<Obstacle>,
    start: &RobotModel,
) -> CollisionWorld {
    let mut obstacles = fixtures;
    if let Some(f) = plan.floor_z_mm {
        let centre = nalgebra::Isometry3::translation(0.0, 0.0, f - 500.0);
        obstacles.push(Obstacle::cuboid("floor", Vector3::new(100_000.0, 100_000.0, 500.0), &centre));
    }
    for b in &plan.keep_out {
        let centre = nalgebra::Isometry3::translation((b.min.x + b.max.x) / 2.0, (b.min.y + b.max.y) / 2.0, (b.min.z + b.max.z) / 2.0);
        obstacles.push(Obstacle::cuboid(&format!("keep-out {}", b.name), (b.max - b.min) / 2.0, &centre));
    }
    let mut world = CollisionWorld::new(pool_links, device, obstacles);
    let mut st = KinState::default();
    forward(start, &mut st, &[0.0; JOINTS]);
    world.allow_pairs_touching_at(&st);
    world
}

/// Runs a device plan (on the caller's rayon pool).
pub fn run(plan: &DevicePlan) -> Result<DeviceOutcome, PlanError> {
    let err = |key: &str, message: String| PlanError::new(&plan.path, key, message);
    let pool: CandidatePool = plan
        .scenario
        .candidate_pool()
        .ok_or_else(|| err("instrument.kind", format!("{} has no pool of its own", plan.kind)))?
        .map_err(|e| err("instrument", format!("the device's campaign: {e}")))?;
    let CandidatePool {
        observations, group_of, groups_w_mm, start, truth, set, jacobian, fit, detmax: dopts, links, device, fixtures, ..
    } = pool;
    let world = collision_world(plan, &links, &device, fixtures, &start);
    // The pool kept within the plan's limits and free of collision.
    let checks: Vec<Result<(), usize>> = observations
        .par_iter()
        .map_init(KinState::default, |st, o| {
            if o.q.iter().zip(&plan.limits).any(|(v, l)| !(*v >= l.min && *v <= l.max)) {
                return Err(0);
            }
            forward(&start, st, &o.q);
            if world.first_collision(st).is_some() { Err(1) } else { Ok(()) }
        })
        .collect();
    let mut refused = [0usize; 2];
    let mut kept = Vec::new();
    for (i, c) in checks.iter().enumerate() {
        match c {
            Ok(()) => kept.push(i),
            Err(k) => refused[*k] += 1,
        }
    }
    if kept.len() <= plan.poses {
        return Err(err(
            "cell.joint_limits_deg",
            format!(
                "{} of the device's {} configurations are within the limits and free of collision (refused: joint limits {}, collision {}): not more than the {} poses",
                kept.len(),
                observations.len(),
                refused[0],
                refused[1],
                plan.poses
            ),
        ));
    }
    let m = jacobian.m;
    let mut rows_j = nalgebra::DMatrix::zeros(3 * kept.len(), m);
    for (r, &i) in kept.iter().enumerate() {
        rows_j.rows_mut(3 * r, 3).copy_from(&jacobian.j.rows(3 * i, 3));
    }
    let jac = PoolJacobian::from_scaled(rows_j, jacobian.scale.clone());
    // Validation configurations over the workspace of interest.
    let limited = start.edited(|d| d.limits = plan.limits).map_err(|e| err("cell.joint_limits_deg", e.to_string()))?;
    let (validation, validation_tried) = validation_configurations(plan, &limited, &world)?;
    let mut st = KinState::default();
    let truth_val: Vec<Vector3<f64>> = validation.iter().map(|q| forward(&truth, &mut st, q)).collect();
    let kept_obs: Vec<Observation> = kept.iter().map(|&i| observations[i]).collect();
    let noise_mm = {
        let ss: f64 = kept_obs.iter().map(|o| (forward(&truth, &mut st, &o.q) - o.tcp_world_mm).norm_squared()).sum();
        (ss / (3 * kept_obs.len()) as f64).sqrt()
    };
    let cx = Worlds { plan, start: &start, truth: &truth, set: &set, fit: &fit, validation: &validation, truth_val: &truth_val, noise_mm };
    let choose = |n: usize| -> Result<(Vec<usize>, f64), PlanError> {
        let mut rng = crate::seeds::stream(plan.seed, crate::seeds::plan::DETMAX);
        let d = crate::identify::detmax(&jac, n, &dopts, &mut rng).map_err(|e| err("poses", e.to_string()))?;
        let o1 = crate::identify::detmax::o1_of(&jac, &d.selection);
        Ok((d.selection, o1))
    };
    // The search's most poses: below the pool kept.
    let objective = plan.objective.clone().map(|o| Objective { most_poses: o.most_poses.min(kept.len() - 1), ..o });
    let search = match &objective {
        None => None,
        Some(o) => {
            let score = |n: usize| -> Result<Candidate, PlanError> {
                let (chosen, _) = choose(n)?;
                let qs: Vec<Joints> = chosen.iter().map(|&k| kept_obs[k].q).collect();
                let stats = cx.at(&qs);
                let successes = stats.iter().filter(|s| s.is_some_and(|s| o.statistic.of_stats(&s) <= o.threshold_mm)).count();
                let lower = crate::study::interval::clopper_pearson_lower(successes as f64, stats.len() as f64, o.confidence);
                Ok(Candidate { n, successes, worlds: stats.len(), lower, meets: lower >= o.success_at_least })
            };
            Some(super::search(o, score)?)
        }
    };
    let poses = search.as_ref().map_or(plan.poses, |s| s.planned);
    let (chosen, o1) = choose(poses)?;
    let random = {
        let mut rng = crate::seeds::stream(plan.seed, crate::seeds::plan::RANDOM);
        let mut s = rand::seq::index::sample(&mut rng, kept.len(), poses).into_vec();
        s.sort_unstable();
        crate::identify::detmax::o1_of(&jac, &s)
    };
    // Rows: training by sphere, then validation.
    let mut order: Vec<usize> = chosen.clone();
    order.sort_by_key(|&k| (group_of[kept[k]], k));
    let mut rows: Vec<DeviceRow> = Vec::with_capacity(order.len() + validation.len());
    let mut observed_w_mm = Vec::new();
    let mut centring_mm = Vec::new();
    for (n, &k) in order.iter().enumerate() {
        let g = group_of[kept[k]];
        rows.push(DeviceRow { label: format!("p{:03}_s{}", n + 1, g + 1), split: TRAIN, group: Some(g), q: kept_obs[k].q });
        observed_w_mm.push(kept_obs[k].tcp_world_mm);
        centring_mm.push((forward(&truth, &mut st, &kept_obs[k].q) - kept_obs[k].tcp_world_mm).norm());
    }
    for (k, q) in validation.iter().enumerate() {
        rows.push(DeviceRow { label: format!("v{:03}", k + 1), split: VALIDATION, group: None, q: *q });
    }
    let qs: Vec<Joints> = rows.iter().map(|r| r.q).collect();
    let mid: Joints = std::array::from_fn(|i| 0.5 * (plan.limits[i].min + plan.limits[i].max));
    let tour = super::select::tour_from(&mid, &qs);
    let collides = |st: &mut KinState, q: &Joints| {
        forward(&start, st, q);
        world.first_collision(st).is_some()
    };
    let colliding_moves = super::select::colliding_moves_with(&qs, &tour.0, collides);
    // Via candidates: the pool kept and the validation configurations (free of collision).
    let free: Vec<Joints> = kept_obs.iter().map(|o| o.q).chain(validation.iter().copied()).collect();
    let routing = super::select::reroute(&qs, &tour.0, &colliding_moves, &free, &plan.limits, collides);
    // The prediction: the pilot on the device's own observations, then the worlds.
    let chosen_obs: Vec<Observation> = order.iter().map(|&k| kept_obs[k]).collect();
    let pilot = crate::identify::identify(&start, &set, &chosen_obs, &crate::identify::FitOptions { truncate: true, ..fit });
    let unidentifiable: Vec<String> = set.names().into_iter().zip(&pilot.values).filter(|(_, v)| v.is_none()).map(|(n, _)| n).collect();
    let pilot_median_mm = pilot.model.as_ref().map_or(f64::NAN, |model| Statistic::Median.of_stats(&cx.errors(model)));
    let stats = cx.at(&chosen_obs.iter().map(|o| o.q).collect::<Vec<_>>());
    let per_world_mm: Vec<f64> = stats.iter().map(|s| s.map_or(f64::NAN, |s| Statistic::Median.of_stats(&s))).collect();
    let sorted = crate::study::stats::finite_sorted(&per_world_mm);
    let q = |p: f64| crate::numeric::quantile(&sorted, p);
    let prediction = DevicePrediction {
        noise_mm,
        quantiles_mm: [q(0.1), q(0.5), q(0.9)],
        median_interval_mm: super::quantile_interval(&sorted, 0.5, super::COMPARISON_CONFIDENCE),
        worlds: sorted.len(),
        per_world_mm,
        pilot_median_mm,
        unidentifiable,
    };
    Ok(DeviceOutcome {
        candidates: observations.len(),
        refused,
        validation_tried,
        rows,
        observed_w_mm,
        centring_mm,
        groups_w_mm,
        o1: (o1, random),
        params: set.names(),
        tour,
        colliding_moves,
        routing,
        prediction,
        poses,
        search,
        objective,
        start,
        truth,
        fit,
        links,
        device,
    })
}

/// The simulated worlds of a device plan: the true arm observed at a set of configurations with
/// the pool's observation error (world w's noise from its own stream), identified from the model
/// before calibration, and compared with the true arm at the validation configurations.
struct Worlds<'a> {
    plan: &'a DevicePlan,
    start: &'a RobotModel,
    truth: &'a RobotModel,
    set: &'a ParamSet,
    fit: &'a crate::identify::FitOptions,
    validation: &'a [Joints],
    truth_val: &'a [Vector3<f64>],
    noise_mm: f64,
}

impl Worlds<'_> {
    /// The held-out errors of `model` at the validation configurations.
    fn errors(&self, model: &RobotModel) -> ErrorStats {
        let mut st = KinState::default();
        let e: Vec<f64> = self.validation.iter().zip(self.truth_val).map(|(q, t)| (forward(model, &mut st, q) - t).norm()).collect();
        ErrorStats::of(&e)
    }

    /// Each world's held-out statistics at the training configurations `qs` (`None`: the world's
    /// identification gave no model).
    fn at(&self, qs: &[Joints]) -> Vec<Option<ErrorStats>> {
        let seed = crate::seeds::split_seed(self.plan.seed, crate::seeds::plan::WORLDS);
        let unit = Normal::new(0.0, 1.0).expect("unit normal");
        (0..self.plan.worlds)
            .into_par_iter()
            .map(|w| {
                let mut rng = crate::seeds::stream(seed, w as u64);
                let mut st = KinState::default();
                let obs: Vec<Observation> = qs
                    .iter()
                    .map(|q| {
                        let p = forward(self.truth, &mut st, q);
                        Observation { q: *q, tcp_world_mm: p + Vector3::from_fn(|_, _| self.noise_mm * unit.sample(&mut rng)) }
                    })
                    .collect();
                let fit = crate::identify::identify(self.start, self.set, &obs, self.fit);
                fit.model.map(|m| self.errors(&m))
            })
            .collect()
    }
}

/// `plan.validation` configurations within the limits, free of collision, the device's TCP in the
/// workspace of interest, spread by farthest-point sampling of the TCP (the first nearest the
/// box's centre) among candidates drawn from their own streams (`seeds::plan::POOL`, i). Returns
/// them and the candidates drawn.
fn validation_configurations(plan: &DevicePlan, limited: &RobotModel, world: &CollisionWorld) -> Result<(Vec<Joints>, usize), PlanError> {
    let seed = crate::seeds::split_seed(plan.seed, crate::seeds::plan::POOL);
    let want = plan.validation * VALIDATION_CANDIDATES_PER_POSE;
    let most = want.saturating_mul(MOST_TRIES_PER_VALIDATION);
    let mut inside: Vec<(Joints, Vector3<f64>)> = Vec::with_capacity(want);
    let mut tried = 0;
    let mut chunk = (4 * want).max(256);
    while inside.len() < want && tried < most {
        let end = (tried + chunk).min(most);
        let found: Vec<Option<(Joints, Vector3<f64>)>> = (tried..end)
            .into_par_iter()
            .map_init(KinState::default, |st, i| {
                let q = uniform_configuration(limited, 0.0, &mut crate::seeds::stream(seed, i as u64));
                forward(limited, st, &q);
                let p = st.tcp_base;
                (plan.workspace.contains(&p) && world.first_collision(st).is_none()).then_some((q, p))
            })
            .collect();
        for f in found {
            tried += 1;
            if let Some(x) = f {
                inside.push(x);
                if inside.len() == want {
                    break;
                }
            }
        }
        chunk *= 2;
    }
    if inside.len() < plan.validation {
        return Err(PlanError::new(
            &plan.path,
            "cell.workspace_min_mm",
            format!(
                "{} of {tried} configurations drawn within the limits put the device's TCP in the workspace of interest free of collision: fewer than validation = {}",
                inside.len(),
                plan.validation
            ),
        ));
    }
    let centre = (plan.workspace.min + plan.workspace.max) / 2.0;
    let first =
        (0..inside.len()).min_by(|&a, &b| (inside[a].1 - centre).norm().total_cmp(&(inside[b].1 - centre).norm())).expect("not empty");
    let mut chosen = vec![first];
    let mut nearest: Vec<f64> = inside.iter().map(|(_, p)| (p - inside[first].1).norm()).collect();
    while chosen.len() < plan.validation {
        let next = (0..inside.len()).max_by(|&a, &b| nearest[a].total_cmp(&nearest[b]).then(b.cmp(&a))).expect("not empty");
        chosen.push(next);
        for (k, (_, p)) in inside.iter().enumerate() {
            nearest[k] = nearest[k].min((p - inside[next].1).norm());
        }
    }
    chosen.sort_unstable();
    Ok((chosen.into_iter().map(|k| inside[k].0).collect(), tried))
}

/// The controller's joint values of `q` in degrees.
fn controller_deg(plan: &DevicePlan, q: &Joints) -> [f64; JOINTS] {
    let qc = plan.robot.coupling.as_ref().map_or(*q, |c| c.controller_from_model(q));
    qc.map(f64::to_degrees)
}

/// The measurement file of a device plan: the training rows with the joint columns filled (the
/// configuration the device was centred at in the planning world: the robot is brought there and
/// the device's centring loop finishes the job; the recorded joints replace these) and their
/// sphere's nominal centre in {W} in the position columns (the centres the ballbar locates replace
/// them); the validation rows with empty positions (a laser tracker registered to {W} on the
/// sphere nests fills them).
pub fn measurement_file(plan: &DevicePlan, o: &DeviceOutcome) -> std::io::Result<(crate::io::table::Frame, String)> {
    let mut lines = header_lines(plan);
    if plan.kind == "spms" {
        lines.push("SPMS plan (calsim plan): a train row is a configuration measured at station N (its label ends in _sN); its position is that station's convergence point".into());
        lines.push("replace the positions with the sphere centres the head measures; holdout rows: a tracker registered to {W} on the first station's A1-A3".into());
    } else {
        lines.push("TriCal plan (calsim plan): a train row is a configuration centred on datum sphere N (its label ends in _sN); its position is that sphere's nominal centre".into());
        lines.push("replace the joints with those recorded when the centring loop ends and the centres with the ballbar's; holdout rows: a tracker registered to {W} on the nests".into());
    }
    let rows: Vec<_> = o.rows.iter().map(|r| measurement_row(plan, r, r.group.map(|g| o.groups_w_mm[g]))).collect();
    crate::calibrate::measurements::file::measurement_file(&lines, &rows)
}

/// The `#` lines a device plan's measurement files begin with: the format, the joints, the robot
/// and the frame.
fn header_lines(plan: &DevicePlan) -> Vec<String> {
    let frame = if plan.kind == "spms" {
        "{W}, the first station's head frame as the tracker measured it"
    } else {
        "{W}, the datum spheres' frame"
    };
    vec![
        format!("format = {}", crate::calibrate::measurements::FORMAT),
        "joints = controller".into(),
        format!("robot = {}", plan.robot_name),
        format!("frame = {frame}"),
    ]
}

/// The measurement file's row of `r`: the TCP in the session `training`, at the controller's
/// joint values, at `xyz_mm` (`None`: to be measured).
fn measurement_row<'a>(
    plan: &DevicePlan,
    r: &'a DeviceRow,
    xyz_mm: Option<[f64; 3]>,
) -> crate::calibrate::measurements::file::MeasurementRow<'a> {
    crate::calibrate::measurements::file::MeasurementRow {
        pose: &r.label,
        session: TRAINING,
        target: "TCP",
        split: Some(r.split),
        q_deg: controller_deg(plan, &r.q),
        xyz_mm,
        quat: None,
    }
}

/// `simulated.csv` of a device plan (`--simulate`): the measurement file with its positions
/// filled in a simulated world. A training row keeps its planned configuration (the planning
/// world's centred one) and gets the true arm's TCP there plus the pool's observation error per
/// coordinate (`DevicePrediction::noise_mm`, the plan's worlds' draw; stream
/// `seeds::plan::SIMULATE`); a validation row gets the true arm's TCP without error (the reference
/// the plan's worlds judge a calibration against).
pub fn simulated_file(plan: &DevicePlan, o: &DeviceOutcome) -> std::io::Result<(crate::io::table::Frame, String)> {
    let mut rng = crate::seeds::stream(plan.seed, crate::seeds::plan::SIMULATE);
    let unit = Normal::new(0.0, 1.0).expect("unit normal");
    let mut st = KinState::default();
    let mut lines = header_lines(plan);
    lines.push("SIMULATED by calsim plan --simulate: the true arm of the plan's planning world at the planned configurations; train rows: its TCP in {W}".into());
    lines.push(format!(
        "with {:.6} mm per coordinate (the pool's observation error, drawn independently per row); holdout rows: its TCP without error",
        o.prediction.noise_mm
    ));
    let mut rows = Vec::with_capacity(o.rows.len());
    for r in &o.rows {
        let mut p = forward(&o.truth, &mut st, &r.q);
        if r.group.is_some() {
            p += Vector3::from_fn(|_, _| o.prediction.noise_mm * unit.sample(&mut rng));
        }
        rows.push(measurement_row(plan, r, Some(p.into())));
    }
    crate::calibrate::measurements::file::measurement_file(&lines, &rows)
}

/// The device study's own identification on a measured device-plan file (`simulated.csv`, or the
/// plan's `poses.csv` filled on the robot), read as `calsim calibrate` reads it: its training
/// points, the TCP in {W} at the model's joint angles, identified from the plan's model before
/// calibration for the device's parameters with the study's options (the plan's worlds' fit); the
/// errors of the identified model at the validation rows against their positions. `None`: the
/// identification gave no model.
pub fn identify_measured(
    plan: &DevicePlan,
    o: &DeviceOutcome,
    m: &crate::calibrate::measurements::Measurements,
) -> Result<Option<ErrorStats>, PlanError> {
    let err = |message: String| PlanError::new(&m.path, "split", message);
    if !m.split_column {
        return Err(err("no split column: the validation rows are those marked holdout".into()));
    }
    let (mut train, mut held) = (Vec::new(), Vec::new());
    for p in &m.points {
        let pose = &m.poses[p.pose];
        if pose.held_out == Some(true) {
            held.push((pose.q, p.measured_mm));
        } else {
            train.push(Observation { q: pose.q, tcp_world_mm: p.measured_mm });
        }
    }
    if held.is_empty() || train.is_empty() {
        return Err(err(format!("{} training and {} holdout points: both are needed", train.len(), held.len())));
    }
    let fit = crate::identify::identify(&o.start, &plan.set, &train, &o.fit);
    Ok(fit.model.map(|model| {
        let mut st = KinState::default();
        let e: Vec<f64> = held.iter().map(|(q, p)| (forward(&model, &mut st, q) - p).norm()).collect();
        ErrorStats::of(&e)
    }))
}

/// What a group of the device's configurations is, as a column names it: `sphere` (the TriCal's
/// datum sphere) or `station` (the SPMS head's).
pub fn group_word(plan: &DevicePlan) -> &'static str {
    if plan.kind == "spms" { "station" } else { "sphere" }
}

/// The plain joint list: pose, split, sphere (station), controller joint values in degrees.
pub fn joint_list(plan: &DevicePlan, o: &DeviceOutcome) -> String {
    let g = group_word(plan);
    let mut s = format!("# pose split {g} q1_deg q2_deg q3_deg q4_deg q5_deg q6_deg (controller values; {g} - for validation)\n");
    for r in &o.rows {
        let q: Vec<String> = controller_deg(plan, &r.q).iter().map(|v| format!("{v:.6}")).collect();
        let g = r.group.map_or_else(|| "-".to_string(), |g| (g + 1).to_string());
        let _ = writeln!(s, "{} {} {g} {}", r.label, r.split, q.join(" "));
    }
    s
}

/// The tour as CSV: step, pose, split, sphere, joint values (deg, controller), the largest joint
/// move to it (deg); a via configuration of a re-routed move is a row of its own, split `via`
/// (passed, not measured).
pub fn tour_file(plan: &DevicePlan, o: &DeviceOutcome) -> std::io::Result<(crate::io::table::Frame, String)> {
    let stops = super::select::stops(&o.tour.0, &o.routing);
    let rows = super::files::tour_rows(
        &stops,
        |stop| match stop {
            super::select::Stop::Pose(i) => (o.rows[*i].label.as_str(), o.rows[*i].split, o.rows[*i].group.map(|g| g + 1), o.rows[*i].q),
            super::select::Stop::Via(label, q) => (label.as_str(), super::select::VIA, None, *q),
        },
        |q| controller_deg(plan, q),
    );
    super::files::tour_file(Some(group_word(plan)), &rows)
}

/// `plan.md` of a device plan, rendered from its tables ([`super::device_summary::tables`]) by
/// [`super::device_summary::markdown`] (or the error that kept it from rendering).
pub fn markdown(plan: &DevicePlan, o: &DeviceOutcome) -> String {
    super::device_summary::markdown(&super::device_summary::tables(plan, o)).unwrap_or_else(|e| e.to_string())
}
