//! The measuring campaign of the TriCal paper (sections 2.2 and 3.1): the semi-automatic steps,
//! the identification pool measured with the TriCal (setup 1) and the validation poses measured
//! with the laser tracker (setup 2). Everything is measured once; studies draw from it.

pub mod centring;

use std::time::Instant;

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use rand::{Rng, RngExt};
use rayon::prelude::*;
use serde::Deserialize;

use crate::cell::Cell;
use crate::cell::collision::{CollisionWorld, LinkCapsules};
use crate::cell::solids::obstacles;
use crate::identify::Observation;
use crate::instrument::laser_tracker::{LaserTracker, rigid_fit};
use crate::instrument::trical::TriCal;
use crate::robot::{JOINTS, Joints, KinState, RobotModel, VirtualRobot, forward, inverse, world_from_base};
use crate::seeds::{campaign as streams, split_seed, stream};
pub use centring::{Approach, CentringError, CentringResult, centre};

pub use crate::robot::uniform_configuration;

/// The campaign as a scenario describes it.
#[derive(Clone, Debug, Deserialize, serde::Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct CampaignSpec {
    /// Identification configurations per datum sphere (the paper: 120, 360 in all).
    pub pool_per_sphere: u32,
    /// Half-angle of the cone of tool axes around the downward vertical of {W}, deg.
    pub approach_cone_deg: f64,
    /// Validation configurations (the paper: 506).
    pub validation_poses: u32,
    /// Margin left at both ends of each joint range for validation configurations (fraction).
    pub validation_margin: f64,
    /// Configurations of the TCP check on sphere 1 (the paper: 4).
    pub tcp_check_configurations: u32,
    /// Distance an operator leaves between TCP and ball centre when jogging, mm.
    pub jog_error_mm: f64,
    /// Tries allowed per kept configuration before the campaign gives up.
    pub max_tries_per_configuration: u32,
    /// Setup 2 without the indicators (as the paper's validation): the tracker's line of sight and
    /// the collision tests of the validation poses see the bracket only.
    pub validation_indicators_removed: bool,
}

impl Default for CampaignSpec {
    fn default() -> Self {
        Self {
            pool_per_sphere: 120,
            approach_cone_deg: 40.0,
            validation_poses: 506,
            validation_margin: 0.05,
            tcp_check_configurations: 4,
            jog_error_mm: 0.5,
            max_tries_per_configuration: 200,
            validation_indicators_removed: false,
        }
    }
}

/// One measured identification configuration.
#[derive(Clone, Debug, PartialEq)]
pub struct PoolEntry {
    /// Datum sphere (0-based).
    pub sphere: usize,
    /// Joint values of the first move, rad.
    pub q_commanded: Joints,
    /// Joint values recorded at the end of the centring, rad.
    pub q: Joints,
    /// Tries this configuration's slot took (1: its first target was reachable, collision-free and
    /// centred); each try draws from streams of its own, so two designs whose slot took the same
    /// tries command the same configuration there.
    pub tries: u32,
    /// Centring iterations (corrections after the first reading).
    pub iterations: u32,
    /// Modelled time to measure this configuration, s.
    pub seconds: f64,
    /// True distance between TCP and ball centre at the end, mm. For diagnosis only: never used by
    /// identification.
    pub true_offset_mm: f64,
    /// The indicator readings of every centring iteration (tool frame), mm; for the recording.
    pub readings: Vec<Vector3<f64>>,
}

/// One validation configuration measured by the laser tracker.
#[derive(Clone, Debug, PartialEq)]
pub struct ValidationPose {
    /// Joint values, rad.
    pub q: Joints,
    /// TCP measured in {W} by the registered tracker, mm.
    pub measured_w: Vector3<f64>,
}

/// What the semi-automatic steps found.
#[derive(Clone, Debug)]
pub struct SemiAutomatic {
    /// TCP in the flange frame from the TCP check with the nominal model, mm.
    pub tcp_check_mm: Vector3<f64>,
    /// TCP in the flange frame measured on the CMM (the one identification uses), mm.
    pub tcp_cmm_mm: Vector3<f64>,
    /// Sphere centres located in the base frame with the nominal model, mm.
    pub spheres_base: Vec<Vector3<f64>>,
    /// Configurations recorded on each sphere while locating it.
    pub located_q: Vec<Joints>,
}

/// Everything the campaign measured, and the models it built.
pub struct Campaign {
    /// The controller's model before calibration: Table 3, the base fitted to the located
    /// spheres, the TCP from the CMM.
    pub nominal: RobotModel,
    /// The semi-automatic steps.
    pub semi_automatic: SemiAutomatic,
    /// The identification pool (setup 1).
    pub pool: Vec<PoolEntry>,
    /// The validation poses (setup 2).
    pub validation: Vec<ValidationPose>,
    /// Wall time spent generating and measuring the pool, s.
    pub pool_wall_s: f64,
    /// Configurations rejected while building the pool because they were unreachable or colliding.
    pub pool_rejected: u32,
    /// Configurations whose centring failed (no reading, or the iteration cap), not kept.
    pub centring_failures: u32,
    /// Configurations rejected while building the validation set.
    pub validation_rejected: u32,
}

impl Campaign {
    /// The observation of a pool entry: its recorded joints and its sphere's centre in {W} as the
    /// ballbar gave it.
    pub fn observation(&self, cell: &Cell, entry: &PoolEntry) -> Observation {
        Observation { q: entry.q, tcp_world_mm: cell.spheres_w_measured[entry.sphere] }
    }
}

/// Why a campaign could not be completed.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CampaignError {
    /// The robot cannot reach a datum sphere with the device.
    #[error("sphere {sphere}: {reason}")]
    Sphere {
        /// Sphere number, 1-based.
        sphere: usize,
        /// What went wrong.
        reason: String,
    },
    /// Too many tries without a valid configuration.
    #[error("{what}: no valid configuration after {tries} tries (cone, limits or collisions too tight)")]
    Exhausted {
        /// Which set.
        what: String,
        /// Tries made.
        tries: u64,
    },
}

/// The collision world of a cell for a model: fixtures placed with `truth_base` (where they are).
/// Self-collision pairs that touch at the zero configuration are allowed (see [`CollisionWorld`]).
pub fn collision_world(
    cell: &Cell,
    links: &LinkCapsules,
    model: &RobotModel,
    truth_base: &Isometry3<f64>,
    tcp: &Vector3<f64>,
    trical: &TriCal,
) -> CollisionWorld {
    let up = -model.data().gravity_base.normalize();
    let device = trical.capsules(tcp);
    let mut world = CollisionWorld::new(links, &device, obstacles(cell, &truth_base.inverse(), &up));
    let mut st = KinState::default();
    forward(model, &mut st, &[0.0; JOINTS]);
    world.allow_pairs_touching_at(&st);
    world
}

/// `world_from_tcp` with the TCP at `p_w` and the flange axis along `axis_w` (pointing from the
/// flange to the TCP), spun by `spin` about it.
pub fn tcp_pose(p_w: &Vector3<f64>, axis_w: &Vector3<f64>, spin: f64) -> Isometry3<f64> {
    let z = axis_w.normalize();
    let helper = if z.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
    let x0 = (helper - z * z.dot(&helper)).normalize();
    let y0 = z.cross(&x0);
    let (s, c) = spin.sin_cos();
    let x = x0 * c + y0 * s;
    let y = z.cross(&x);
    let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, z])));
    Isometry3::from_parts(Translation3::from(*p_w), rot)
}

/// A direction drawn uniformly in the cone of half-angle `half_angle` around `axis`.
fn cone_direction<R: Rng + ?Sized>(axis: &Vector3<f64>, half_angle: f64, rng: &mut R) -> Vector3<f64> {
    let cos_min = half_angle.cos();
    let cz = rng.random_range(cos_min..=1.0);
    let phi = rng.random_range(0.0..std::f64::consts::TAU);
    let sz = (1.0 - cz * cz).max(0.0).sqrt();
    let a = axis.normalize();
    let helper = if a.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
    let u = a.cross(&helper).normalize();
    let v = a.cross(&u);
    a * cz + (u * phi.cos() + v * phi.sin()) * sz
}

/// Inputs of a campaign.
pub struct Setup<'a> {
    /// The cell (true spheres, ballbar measurements).
    pub cell: &'a Cell,
    /// The physical robot.
    pub robot: &'a VirtualRobot,
    /// The physical robot during validation (thermal drift).
    pub robot_validation: &'a VirtualRobot,
    /// The TriCal device.
    pub trical: &'a TriCal,
    /// The laser tracker.
    pub tracker: &'a LaserTracker,
    /// The nominal model (Table 3, payload), before the semi-automatic steps.
    pub nominal: &'a RobotModel,
    /// The arm's link capsules (collision tests and lines of sight).
    pub links: &'a LinkCapsules,
    /// What to measure.
    pub spec: &'a CampaignSpec,
}

/// Runs the semi-automatic steps, measures the pool and the validation set.
///
/// Random streams of the campaign: each step draws from its own stream, keyed by what it is (the
/// sphere, the attempt, the pose index; [`crate::seeds::campaign`]), never from one shared
/// sequence: a centring loop that takes one iteration more in a what-if scenario then changes that
/// configuration only, and two scenarios that differ in one amplitude are compared on the same
/// targets, noise and validation poses (common random numbers).
pub fn run(setup: &Setup<'_>, seed: u64) -> Result<Campaign, CampaignError> {
    let truth_base = world_from_base(&setup.robot.truth);
    let tcp_cmm = setup.trical.cmm_tcp(&setup.robot.truth.data().flange_tcp_mm, &mut stream(seed, streams::CMM));
    let world = collision_world(setup.cell, setup.links, setup.nominal, &truth_base, &tcp_cmm, setup.trical);
    let (semi_automatic, nominal_model) = semi_automatic(setup, &tcp_cmm, seed)?;
    let setup2 = setup.spec.validation_indicators_removed.then(|| {
        let mut w = collision_world(setup.cell, setup.links, setup.nominal, &truth_base, &tcp_cmm, setup.trical);
        w.keep_device_parts(1);
        w
    });
    // The pool and the validation set draw on their own streams: measured side by side.
    let (pool, validation) = rayon::join(
        || {
            let t0 = Instant::now();
            measure_pool(setup, &world, &nominal_model, &semi_automatic.located_q, seed).map(|p| (p, t0.elapsed().as_secs_f64()))
        },
        || measure_validation(setup, setup2.as_ref().unwrap_or(&world), &nominal_model, semi_automatic.located_q[0], seed),
    );
    let ((pool, pool_rejected, centring_failures), pool_wall_s) = pool?;
    let (validation, validation_rejected) = validation?;
    Ok(Campaign {
        nominal: nominal_model,
        semi_automatic,
        pool,
        validation,
        pool_wall_s,
        pool_rejected,
        centring_failures,
        validation_rejected,
    })
}

/// The semi-automatic steps: the operator jogs the device onto each ball (simulated with the true
/// robot), then Algorithm 1 centres it, the controller believing the nominal model with the base
/// frame at the world origin and the CMM tool; then the TCP check and the nominal base fitted to
/// the located spheres. Returns the steps and the model before calibration.
fn semi_automatic(setup: &Setup<'_>, tcp_cmm: &Vector3<f64>, seed: u64) -> Result<(SemiAutomatic, RobotModel), CampaignError> {
    let Setup { cell, robot, trical, nominal, spec, .. } = *setup;
    // Each configuration's approach axis, each try's jog and spin and each try's centring draw from
    // streams of their own ([`streams::semi_automatic_step`]): a centring that takes one iteration
    // more in another design leaves every later sphere's located configuration (the pool's IK
    // seeds) where it was.
    let targets = split_seed(seed, streams::SEMI_AUTOMATIC);
    let centrings = split_seed(seed, streams::SEMI_AUTOMATIC_CENTRING);
    let down = -Vector3::z();
    let jogging = nominal.edited(|d| d.flange_tcp_mm = *tcp_cmm).expect("valid");
    let mut located_q = Vec::new();
    let mut check_q = Vec::new();
    let mut last_q = [0.0; JOINTS];
    for (k, sphere_w) in cell.spheres_w.iter().enumerate() {
        let configs = if k == 0 { spec.tcp_check_configurations.max(1) } else { 1 };
        for j in 0..configs {
            let key = |t: u32| streams::semi_automatic_step(k, j, t);
            let axis =
                if j == 0 { down } else { cone_direction(&down, spec.approach_cone_deg.to_radians() * 0.8, &mut stream(targets, key(0))) };
            let mut done = None;
            for t in 1..=spec.max_tries_per_configuration {
                let rng = &mut stream(targets, key(t));
                let jog = Vector3::from_fn(|_, _| rng.random_range(-1.0..1.0)).normalize() * spec.jog_error_mm;
                let target = trical.frame6_pose(tcp_pose(&(sphere_w + jog), &axis, rng.random_range(0.0..std::f64::consts::TAU)));
                let Ok(q) = inverse(&robot.truth, &target, &last_q) else {
                    continue;
                };
                let approach = Approach { sphere: k, q0: q, from: last_q };
                if let Ok(res) = centre(&jogging, robot, trical, cell, approach, &mut stream(centrings, key(t))) {
                    done = Some(res);
                    break;
                }
            }
            let res = done.ok_or_else(|| CampaignError::Sphere { sphere: k + 1, reason: "the device cannot be centred on it".into() })?;
            last_q = res.q;
            if j == 0 {
                located_q.push(res.q);
            }
            if k == 0 {
                check_q.push(res.q);
            }
        }
    }
    // TCP check: the flange poses of the nominal model and one unknown sphere centre, least squares.
    let flange_only = nominal.edited(|d| {
        d.flange_tcp_mm = Vector3::zeros();
        d.world_from_base = Default::default();
    });
    let flange_only = flange_only.expect("valid");
    let tcp_check_mm = tcp_check(&flange_only, &check_q).unwrap_or(*tcp_cmm);
    let base_model = flange_only.edited(|d| d.flange_tcp_mm = tcp_check_mm).expect("valid");
    let spheres_base: Vec<Vector3<f64>> = located_q.iter().map(|q| forward(&base_model, &mut KinState::default(), q)).collect();
    // The nominal base: the rigid transform that maps the located spheres onto their {W} coordinates.
    let world_from_base_fit = rigid_fit(&spheres_base, &cell.spheres_w_measured)
        .ok_or_else(|| CampaignError::Sphere { sphere: 1, reason: "the located spheres give no finite base frame".into() })?;
    let nominal_model = nominal
        .edited(|d| {
            d.flange_tcp_mm = *tcp_cmm;
            d.world_from_base = crate::robot::XyzZyx::from_isometry(&world_from_base_fit);
        })
        .expect("valid");
    Ok((SemiAutomatic { tcp_check_mm, tcp_cmm_mm: *tcp_cmm, spheres_base, located_q }, nominal_model))
}

/// The identification pool: per sphere, targets in the approach cone, IK on the nominal model, no
/// collision, then Algorithm 1 centring. Returns the pool, the candidates rejected (IK or
/// collision) and the centring failures.
/// One sphere's pool: its entries, the candidates rejected and the centring failures.
type SpherePool = (Vec<PoolEntry>, u32, u32);

fn measure_pool(
    setup: &Setup<'_>,
    world: &CollisionWorld,
    nominal_model: &RobotModel,
    located_q: &[Joints],
    seed: u64,
) -> Result<(Vec<PoolEntry>, u32, u32), CampaignError> {
    let Setup { cell, robot, trical, spec, .. } = *setup;
    let down = -Vector3::z();
    // The spheres' pools are independent (each its own streams), so they are measured in
    // parallel and joined in sphere order: the same pool for any thread count. Each kept
    // configuration (slot) draws its tries from streams of its own ([`streams::pool_step`]): a try
    // that fails in one design (a centring that reaches the iteration cap) changes that slot only,
    // and every other slot holds the same commanded configuration in every design.
    let targets = split_seed(seed, streams::POOL_TARGETS);
    let centrings = split_seed(seed, streams::POOL_CENTRING);
    let per_sphere: Vec<Result<SpherePool, CampaignError>> = located_q
        .par_iter()
        .enumerate()
        .map(|(k, seed_q)| {
            let mut pool = Vec::new();
            let mut rejected = 0;
            let mut centring_failures = 0;
            let mut st = KinState::default();
            let target_w = cell.spheres_w_measured[k];
            let mut last = *seed_q;
            let mut tries = 0u64;
            let limit = u64::from(spec.max_tries_per_configuration) * u64::from(spec.pool_per_sphere);
            for slot in 0..spec.pool_per_sphere {
                for t in 0u32.. {
                    tries += 1;
                    if tries > limit {
                        return Err(CampaignError::Exhausted { what: format!("pool of sphere {}", k + 1), tries });
                    }
                    let key = streams::pool_step(k, slot, t);
                    let rng = &mut stream(targets, key);
                    let axis = cone_direction(&down, spec.approach_cone_deg.to_radians(), rng);
                    let pose = trical.frame6_pose(tcp_pose(&target_w, &axis, rng.random_range(0.0..std::f64::consts::TAU)));
                    let Ok(q) = inverse(nominal_model, &pose, seed_q) else {
                        rejected += 1;
                        continue;
                    };
                    forward(nominal_model, &mut st, &q);
                    if world.first_collision(&st).is_some() {
                        rejected += 1;
                        continue;
                    }
                    let approach = Approach { sphere: k, q0: q, from: last };
                    match centre(nominal_model, robot, trical, cell, approach, &mut stream(centrings, key)) {
                        Ok(res) => {
                            last = res.q;
                            pool.push(PoolEntry {
                                sphere: k,
                                q_commanded: q,
                                q: res.q,
                                tries: t + 1,
                                iterations: res.iterations,
                                seconds: res.seconds,
                                true_offset_mm: res.true_offset_mm,
                                readings: res.readings,
                            });
                            break;
                        }
                        Err(_) => centring_failures += 1,
                    }
                }
            }
            Ok((pool, rejected, centring_failures))
        })
        .collect();
    let mut pool = Vec::new();
    let (mut rejected, mut centring_failures) = (0, 0);
    for sphere in per_sphere {
        let (p, r, c) = sphere?;
        pool.extend(p);
        rejected += r;
        centring_failures += c;
    }
    Ok((pool, rejected, centring_failures))
}

/// The validation set: random configurations, collision-free, the SMR in sight of the tracker,
/// measured by the tracker on the robot of setup 2. Returns the poses and the candidates rejected.
fn measure_validation(
    setup: &Setup<'_>,
    world: &CollisionWorld,
    nominal_model: &RobotModel,
    start: Joints,
    seed: u64,
) -> Result<(Vec<ValidationPose>, u32), CampaignError> {
    let poses = RandomPoses {
        what: "validation set",
        count: setup.spec.validation_poses,
        robot: setup.robot_validation,
        keys: (streams::VALIDATION_POSES, streams::VALIDATION_NOISE),
    };
    measure_random_poses(setup, world, nominal_model, start, seed, &poses, &|p, rng| Some(setup.tracker.measure(p, rng)))
}

/// An instrument measuring a true point in {W} with a stream of its own; `None` when the point is
/// out of its view.
pub type Measure<'a> = &'a dyn Fn(&Vector3<f64>, &mut rand_chacha::ChaCha8Rng) -> Option<Vector3<f64>>;

/// A set of random configurations measured by an instrument: what it is for (in errors), how many,
/// on which physical robot, and the stream keys of its poses and of each pose's noise.
pub struct RandomPoses<'a> {
    /// Name in errors.
    pub what: &'static str,
    /// Poses to keep.
    pub count: u32,
    /// The physical robot measured.
    pub robot: &'a VirtualRobot,
    /// Stream keys: the configurations, then `noise + i` for pose i.
    pub keys: (u64, u64),
}

/// Random configurations within the joint limits (the validation margin), collision-free, the
/// target facing and in sight of the tracker's place, each measured by `measure` (which may refuse
/// a target out of its view). Returns the poses and the candidates rejected.
fn measure_random_poses(
    setup: &Setup<'_>,
    world: &CollisionWorld,
    nominal_model: &RobotModel,
    start: Joints,
    seed: u64,
    poses: &RandomPoses<'_>,
    measure: Measure<'_>,
) -> Result<(Vec<ValidationPose>, u32), CampaignError> {
    let Setup { robot, tracker, spec, .. } = *setup;
    let base_from_world = world_from_base(&robot.truth).inverse();
    let tracker_base = (base_from_world * nalgebra::Point3::from(tracker.position_w)).coords;
    let mut st = KinState::default();
    let mut out = Vec::new();
    let mut rejected = 0;
    let mut from = start;
    let mut tries = 0;
    let accept_cos = tracker.spec.smr_acceptance_deg.to_radians().cos();
    let flange_axis = setup.trical.flange_axis();
    let rng = &mut stream(seed, poses.keys.0);
    // Whether a candidate can be measured: in range, facing the tracker, collision-free, in sight.
    let feasible = |st: &mut KinState, q: &Joints| {
        forward(nominal_model, st, q);
        let tcp = st.tcp_base;
        let sight = tracker_base - tcp;
        let facing = st.rot[JOINTS] * flange_axis;
        sight.norm() <= tracker.spec.max_range_mm
            && facing.dot(&sight.normalize()) >= accept_cos
            && world.first_collision(st).is_none()
            && world.line_of_sight(st, &tracker_base, &tcp, 30.0)
    };
    let limit = u64::from(spec.max_tries_per_configuration) * u64::from(poses.count.max(1));
    // The candidates are drawn from their own stream whatever is accepted, so they are drawn and
    // tested in batches in parallel, then taken in order: the same poses as one by one.
    const BATCH: usize = 128;
    'batches: while out.len() < poses.count as usize {
        let candidates: Vec<Joints> = (0..BATCH).map(|_| uniform_configuration(nominal_model, spec.validation_margin, rng)).collect();
        let ok: Vec<bool> = candidates.par_iter().map_init(KinState::default, |st, q| feasible(st, q)).collect();
        for (q, ok) in candidates.into_iter().zip(ok) {
            tries += 1;
            if tries > limit {
                return Err(CampaignError::Exhausted { what: poses.what.into(), tries });
            }
            if !ok {
                rejected += 1;
                continue;
            }
            let noise = &mut stream(seed, poses.keys.1 + out.len() as u64);
            let true_w = poses.robot.tcp_after_move(&mut st, &q, &from, noise);
            let Some(measured_w) = measure(&true_w, noise) else {
                rejected += 1;
                continue;
            };
            from = q;
            out.push(ValidationPose { q, measured_w });
            if out.len() == poses.count as usize {
                break 'batches;
            }
        }
    }
    Ok((out, rejected))
}

/// Candidate poses per datum sphere and validation configurations a [`feasibility`] tries.
pub const FEASIBILITY_POOL_SAMPLES: usize = 48;
/// See [`FEASIBILITY_POOL_SAMPLES`].
pub const FEASIBILITY_VALIDATION_SAMPLES: usize = 160;
/// Candidates of a set that must be accepted for [`Feasibility::shortfall`] to be 0 (a margin
/// above the one in `max_tries_per_configuration` the campaign needs).
pub const FEASIBILITY_NEEDED: usize = 3;
/// Penetration depth at which a colliding candidate counts as far from accepted as an
/// unreachable one, mm.
pub const FEASIBILITY_DEPTH_MM: f64 = 100.0;

/// How near a cell is to a campaign that can measure it, from fixed candidate poses (the same
/// for every design): per datum sphere, pool candidates (a direction in the approach cone and a
/// turn about it, the true arm's inverse kinematics, collisions of arm, device and fixtures), then
/// validation candidates (configurations within the validation margin: in the tracker's range,
/// facing it, collision-free, in its sight). The campaign fails a set whose share of accepted
/// candidates is under 1 in `max_tries_per_configuration`.
#[derive(Clone, Debug, PartialEq)]
pub struct Feasibility {
    /// Per datum sphere, the share of its pool candidates accepted.
    pub pool_share: Vec<f64>,
    /// The share of validation candidates accepted.
    pub validation_share: f64,
    /// Per set (each sphere's pool, then the validation set), the mean over its
    /// [`FEASIBILITY_NEEDED`] nearest candidates of how far each is from accepted: 0 accepted;
    /// a colliding one its penetration depth / [`FEASIBILITY_DEPTH_MM`] (at most 1); one the arm
    /// cannot reach, or out of the tracker's range or view, 1; one out of its sight 0.5. Each is
    /// 0 where the set has that many accepted candidates, and falls continuously as the fixtures
    /// move out of the arm's way.
    pub shortfall: Vec<f64>,
}

impl Feasibility {
    /// The sets' shortfalls summed (0 to the count of spheres + 1).
    pub fn total(&self) -> f64 {
        self.shortfall.iter().sum()
    }
}

/// The mean of the `FEASIBILITY_NEEDED` smallest of `v`.
fn nearest_needed(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = FEASIBILITY_NEEDED.min(v.len()).max(1);
    v.iter().take(n).sum::<f64>() / n as f64
}

/// The [`Feasibility`] of the cell of `setup` for the arm `truth` (placed in {W}): its candidates
/// drawn from [`crate::seeds::fixed::FEASIBILITY`], tested in parallel and gathered in order (the
/// same figures for any thread count).
pub fn feasibility(setup: &Setup<'_>, truth: &RobotModel) -> Feasibility {
    let Setup { cell, trical, tracker, spec, links, nominal, .. } = *setup;
    let truth_base = world_from_base(truth);
    let tcp = truth.data().flange_tcp_mm;
    let world = collision_world(cell, links, nominal, &truth_base, &tcp, trical);
    let down = -Vector3::z();
    let mut rng = crate::seeds::fixed_stream(crate::seeds::fixed::FEASIBILITY);
    let cones: Vec<(Vector3<f64>, f64)> = (0..FEASIBILITY_POOL_SAMPLES)
        .map(|_| (cone_direction(&down, spec.approach_cone_deg.to_radians(), &mut rng), rng.random_range(0.0..std::f64::consts::TAU)))
        .collect();
    let configurations: Vec<Joints> =
        (0..FEASIBILITY_VALIDATION_SAMPLES).map(|_| uniform_configuration(truth, spec.validation_margin, &mut rng)).collect();
    let away = |st: &KinState| -> f64 { (world.penetration_mm(st) / FEASIBILITY_DEPTH_MM).min(1.0) };
    let per_sphere: Vec<Vec<f64>> = cell
        .spheres_w
        .par_iter()
        .map(|c| {
            let mut st = KinState::default();
            let seed = inverse(truth, &trical.frame6_pose(tcp_pose(c, &down, 0.0)), &[0.0; JOINTS]).unwrap_or([0.0; JOINTS]);
            cones
                .iter()
                .map(|(axis, spin)| match inverse(truth, &trical.frame6_pose(tcp_pose(c, axis, *spin)), &seed) {
                    Err(_) => 1.0,
                    Ok(q) => {
                        forward(truth, &mut st, &q);
                        away(&st)
                    }
                })
                .collect()
        })
        .collect();
    let setup2 = spec.validation_indicators_removed.then(|| {
        let mut w = collision_world(cell, links, nominal, &truth_base, &tcp, trical);
        w.keep_device_parts(1);
        w
    });
    let vworld = setup2.as_ref().unwrap_or(&world);
    let base_from_world = truth_base.inverse();
    let tracker_base = (base_from_world * nalgebra::Point3::from(tracker.position_w)).coords;
    let accept_cos = tracker.spec.smr_acceptance_deg.to_radians().cos();
    let flange_axis = trical.flange_axis();
    let validation: Vec<f64> = configurations
        .par_iter()
        .map_init(KinState::default, |st, q| {
            forward(truth, st, q);
            let tcp = st.tcp_base;
            let sight = tracker_base - tcp;
            let facing = st.rot[JOINTS] * flange_axis;
            if sight.norm() > tracker.spec.max_range_mm || facing.dot(&sight.normalize()) < accept_cos {
                return 1.0;
            }
            let depth = (vworld.penetration_mm(st) / FEASIBILITY_DEPTH_MM).min(1.0);
            if depth > 0.0 {
                return depth;
            }
            if vworld.line_of_sight(st, &tracker_base, &tcp, 30.0) { 0.0 } else { 0.5 }
        })
        .collect();
    let share = |v: &[f64]| v.iter().filter(|x| **x == 0.0).count() as f64 / v.len().max(1) as f64;
    let mut shortfall: Vec<f64> = per_sphere.iter().map(|v| nearest_needed(v.clone())).collect();
    shortfall.push(nearest_needed(validation.clone()));
    Feasibility { pool_share: per_sphere.iter().map(|v| share(v)).collect(), validation_share: share(&validation), shortfall }
}

/// An identification pool measured by an external instrument (Table 8: the laser tracker with an
/// SMR, the optical CMM with a target at the TCP) on the robot as it carries that target, the
/// robot of setup 2 (the validation's payload and drift), from random configurations of the whole
/// workspace that the instrument sees, not tied to the spheres.
pub fn instrument_pool(
    setup: &Setup<'_>,
    campaign: &Campaign,
    count: u32,
    seed: u64,
    measure: Measure<'_>,
) -> Result<Vec<ValidationPose>, CampaignError> {
    let truth_base = world_from_base(&setup.robot.truth);
    let world = collision_world(setup.cell, setup.links, setup.nominal, &truth_base, &campaign.semi_automatic.tcp_cmm_mm, setup.trical);
    let poses = RandomPoses {
        what: "instrument pool",
        count,
        robot: setup.robot_validation,
        keys: (streams::INSTRUMENT_POSES, streams::INSTRUMENT_NOISE),
    };
    measure_random_poses(setup, &world, &campaign.nominal, campaign.semi_automatic.located_q[0], seed, &poses, measure).map(|(p, _)| p)
}

/// TCP in the flange frame from configurations centred on one ball: least squares on
/// `R_j t - s = -p_j` (t the TCP, s the ball centre, both unknown).
pub fn tcp_check(flange_model: &RobotModel, qs: &[Joints]) -> Option<Vector3<f64>> {
    if qs.len() < 2 {
        return None;
    }
    let mut a = nalgebra::DMatrix::zeros(3 * qs.len(), 6);
    let mut b = nalgebra::DVector::zeros(3 * qs.len());
    let mut st = KinState::default();
    for (j, q) in qs.iter().enumerate() {
        let f = crate::robot::world_from_flange(flange_model, &mut st, q);
        let r = f.rotation.to_rotation_matrix().into_inner();
        for i in 0..3 {
            for c in 0..3 {
                a[(3 * j + i, c)] = r[(i, c)];
            }
            a[(3 * j + i, 3 + i)] = -1.0;
            b[3 * j + i] = -f.translation.vector[i];
        }
    }
    let x = crate::numeric::svd(a, true, true)?.solve(&b, 1e-10).ok()?;
    Some(Vector3::new(x[0], x[1], x[2]))
}
