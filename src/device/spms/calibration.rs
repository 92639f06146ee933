//! Kinematic calibration of the ER20-C10 with the SPMS (paper section 5.3) and its ISO 9283 test.
//!
//! The head stands in front of the robot; the robot carries the reference sphere on its flange into
//! the beams in many orientations. The identification's world frame is the head frame {S}: it
//! identifies the kinematic parameters, the base-to-SPMS transform (`world_from_base`) and the
//! flange-to-sphere offset (the tool) from the sphere centres the SPMS measures with its identified
//! beams. Pose sets are drawn at random from a pool (the paper) or chosen by DETMAX on O1 (the
//! paper's future work). Each identified model is then tested as the paper tests it: a 400 mm cube,
//! P1-P5 on its diagonal plane, n cycles, AP and RP per point, measured by a laser tracker in the
//! robot's base frame.

use nalgebra::{Isometry3, Point3, Rotation3, Translation3, Unit, UnitQuaternion, Vector3};
use rand::RngExt;
use rand_distr::{Distribution, Normal};
use serde::Deserialize;

use super::head::IdentifiedHead;
use super::{Spms, iso9283};
use crate::identify::least_squares::{FitOptions, Observation, identify};
use crate::instrument::laser_tracker::AxisNoise;
use crate::robot::builtin::{er20c10_table4, er20c10_table5};
use crate::robot::ik::refine;
use crate::robot::{Joints, KinState, ParamSet, RobotModel, UnmodelledSpec, VirtualRobot, XyzZyx, forward};
use crate::seeds::{spms_cell as streams, stream};

/// The robot, as a scenario describes it.
#[derive(Clone, Debug, Deserialize, serde::Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct ArmSpec {
    /// The true geometry.
    pub truth: TruthTable,
    /// Nominal reference-sphere centre in the flange frame, mm.
    pub sphere_flange_mm: [f64; 3],
    /// Error of the true sphere centre from the nominal, per axis (normal std), mm.
    pub sphere_flange_error_mm: f64,
    /// ISO 9283 position repeatability RP of the robot, mm.
    pub repeatability_mm: f64,
    /// Joint values at which the repeatability is scaled, deg.
    pub repeatability_reference_q_deg: [f64; 6],
    /// Effects outside the kinematic model.
    pub unmodelled: UnmodelledSpec,
    /// Spread of the true parameters around the truth table, drawn per world (zero: the table).
    pub spread: crate::robot::SpreadSpec,
    /// The arm's robot file, relative to the scenario (absent: the built-in ER20-C10, Tables 4-5).
    pub file: Option<std::path::PathBuf>,
    /// Factor on every amplitude and spread of the learned effects of a twin (a robot file with a
    /// `[learned]` table): 0 leaves them out; a robot file without that table takes only 1.
    pub learned_scale: f64,
    /// The loaded robot file (filled by the scenario loader).
    #[serde(skip)]
    pub arm: Option<crate::robot::file::Arm>,
    /// The twin's learned effects as the worlds draw them, `learned_scale` applied (filled by the
    /// scenario loader; `None`: the robot file has no `[learned]` table).
    #[serde(skip)]
    pub learned: Option<crate::robot::learned::LearnedEffects>,
}

impl Default for ArmSpec {
    fn default() -> Self {
        Self {
            truth: TruthTable::Table5WithoutDtheta2,
            sphere_flange_mm: [40.0, 0.0, 150.0],
            sphere_flange_error_mm: 0.2,
            repeatability_mm: 0.05,
            repeatability_reference_q_deg: [0.0, 30.0, 30.0, 0.0, 30.0, 0.0],
            unmodelled: UnmodelledSpec::default(),
            spread: crate::robot::SpreadSpec::default(),
            file: None,
            learned_scale: 1.0,
            arm: None,
            learned: None,
        }
    }
}

/// Which published table the true ER20-C10 geometry is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum TruthTable {
    /// Table 5 (the robot file's truth) with delta theta_2 left out.
    #[serde(rename = "table5_without_dtheta2")]
    Table5WithoutDtheta2,
    /// All of Table 5 (the robot file's truth).
    Table5,
    /// Table 4 (the robot file's nominal): only unmodelled effects remain.
    Table4,
}

impl ArmSpec {
    /// The true model for the truth named in the spec (base and tool not yet placed).
    pub fn truth_model(&self) -> RobotModel {
        let Some(crate::robot::file::Arm(arm)) = &self.arm else {
            return match self.truth {
                TruthTable::Table5WithoutDtheta2 => er20c10_table5(false),
                TruthTable::Table5 => er20c10_table5(true),
                TruthTable::Table4 => er20c10_table4(),
            };
        };
        let full = || arm.truth_on(&arm.nominal).expect("checked when the robot file was loaded");
        match self.truth {
            TruthTable::Table5WithoutDtheta2 => {
                let nominal_offset = arm.nominal.data().links[1].theta_offset;
                full().edited(|d| d.links[1].theta_offset = nominal_offset).expect("valid")
            }
            TruthTable::Table5 => full(),
            TruthTable::Table4 => arm.nominal.clone(),
        }
    }

    /// The arm as its controller believes it before calibration (base and tool not yet placed).
    pub fn nominal_model(&self) -> RobotModel {
        self.arm.as_ref().map_or_else(er20c10_table4, |crate::robot::file::Arm(a)| a.nominal.clone())
    }
}

/// Where the head stands and how the robot presents the sphere, as a scenario describes it.
#[derive(Clone, Debug, Deserialize, serde::Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct StationSpec {
    /// The points where the beams converge, one per placement of the head (station), robot base
    /// frame, mm. Each head faces the robot: its beams (head +y) point back towards the base axis.
    pub sphere_points_base_mm: Vec<[f64; 3]>,
    /// Where the beams converge, head frame, mm (the beam experiment's sphere centre).
    pub sphere_centre_head_mm: [f64; 3],
    /// How well each head's placement is known before it is measured, per axis (normal std), mm.
    pub placement_error_mm: f64,
    /// How well each head's orientation is known, per axis (normal std), deg.
    pub placement_error_deg: f64,
    /// Laser tracker noise per axis on the head's frame points A1-A3, um (several stations only).
    pub tracker_sigma_um: f64,
    /// Largest angle between the flange axis and the direction from the sphere to the head, deg.
    pub approach_cone_deg: f64,
    /// Largest rotation about the flange axis from the reference pose, +- deg.
    pub spin_deg: f64,
    /// Sphere travel in the head frame from the convergence point, +- mm per axis (x, y, z).
    pub sphere_travel_mm: [f64; 3],
    /// Candidate configurations measured, in all (shared evenly among the stations).
    pub pool: usize,
}

impl Default for StationSpec {
    fn default() -> Self {
        Self {
            sphere_points_base_mm: vec![[1300.0, 0.0, 600.0]],
            sphere_centre_head_mm: [52.0, 180.0, 132.0],
            placement_error_mm: 2.0,
            placement_error_deg: 1.0,
            tracker_sigma_um: 10.0,
            approach_cone_deg: 40.0,
            spin_deg: 90.0,
            sphere_travel_mm: [2.0, 15.0, 2.0],
            pool: 300,
        }
    }
}

/// The ISO 9283 test, as a scenario describes it.
#[derive(Clone, Debug, Deserialize, serde::Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct IsoSpec {
    /// Cube centre, robot base frame, mm.
    pub cube_centre_base_mm: [f64; 3],
    /// Cube side, mm (the paper: 400).
    pub cube_mm: f64,
    /// Distance of P2-P5 from the corners, fraction of the diagonal (ISO 9283: 0.1).
    pub corner_fraction: f64,
    /// Cycles (ISO 9283 and the paper: 30).
    pub cycles: usize,
    /// Laser tracker noise per axis, um.
    pub tracker_sigma_um: f64,
}

impl Default for IsoSpec {
    fn default() -> Self {
        Self { cube_centre_base_mm: [1000.0, 0.0, 800.0], cube_mm: 400.0, corner_fraction: 0.1, cycles: 30, tracker_sigma_um: 10.0 }
    }
}

/// The parameters identified by default: the TriCal set's kinematic part without d6 and
/// theta_offs6 (the flange-to-sphere offset, identified, takes their place), plus the tool.
pub fn default_parameters() -> ParamSet {
    let mut names: Vec<String> = Vec::new();
    names.extend((1..=5).map(|i| format!("alpha{i}")));
    names.extend((1..=5).map(|i| format!("a{i}")));
    names.extend((3..=5).map(|i| format!("d{i}")));
    names.extend((2..=5).map(|i| format!("theta_offs{i}")));
    names.push("beta2".into());
    names.extend(["x0W", "y0W", "z0W", "alpha0W", "beta0W", "gamma0W", "xT6", "yT6", "zT6"].map(String::from));
    ParamSet::from_names(&names).expect("valid names")
}

/// One measured candidate configuration.
#[derive(Clone, Debug, PartialEq)]
pub struct PoolPose {
    /// Station index.
    pub station: usize,
    /// Commanded joints, rad.
    pub q: Joints,
    /// Sphere centre the SPMS measured, in the identification's world frame, mm.
    pub measured_world_mm: Vector3<f64>,
    /// True sphere centre, world frame, mm.
    pub true_world_mm: Vector3<f64>,
}

/// One placement of the head.
#[derive(Clone, Debug, PartialEq)]
pub struct Station {
    /// `base_from_head`, true.
    pub base_from_head: Isometry3<f64>,
    /// `world_from_head` as measured (identity for the first station: its head frame is the world).
    pub world_from_head: Isometry3<f64>,
    /// The configuration the station's candidates are solved from (the taught pose).
    pub q: Joints,
    /// Correction of the commanded point found by teaching, head frame, mm: candidates aim at
    /// `c - taught_shift_mm` to put the sphere at `c`.
    pub taught_shift_mm: Vector3<f64>,
}

/// The calibration cell: robot, heads, pool.
///
/// The identification's world frame {S} is the head frame of the first station (the paper's
/// base-to-SPMS transform is `world_from_base`). With several stations the laser tracker measures
/// every head's frame points A1-A3 (eqs. 4-7) and the others are expressed in the first.
#[derive(Clone, Debug)]
pub struct Cell {
    /// The controller's model before calibration, world = {S}.
    pub nominal: RobotModel,
    /// The physical robot, world = {S}.
    pub robot: VirtualRobot,
    /// The stations.
    pub stations: Vec<Station>,
    /// Measured candidates.
    pub pool: Vec<PoolPose>,
    /// Candidates drawn whose IK failed or whose readings failed.
    pub rejected: usize,
}

/// Why the cell cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CellError {
    /// The station pose cannot be reached.
    #[error("the sphere point {0:?} cannot be reached with the flange facing the head")]
    Station([f64; 3]),
    /// Too few candidates could be measured.
    #[error("only {got} of {wanted} candidate configurations could be reached and measured")]
    Pool {
        /// Measured.
        got: usize,
        /// Asked for.
        wanted: usize,
    },
    /// A cube point cannot be reached.
    #[error("ISO 9283 point {point} cannot be reached")]
    Iso {
        /// P1..P5.
        point: String,
    },
}

/// The flange orientation that faces the head, spun and tilted.
fn presentation(axis: &Vector3<f64>, tilt: f64, tilt_dir: f64, spin: f64) -> UnitQuaternion<f64> {
    // Reference: flange z along `axis`, flange x as close to +z of the frame as possible (the
    // wrist in the middle of joint 4's range for a head facing the robot).
    let z = axis.normalize();
    let x0 = (Vector3::z() - z * z.z).try_normalize(1e-9).unwrap_or_else(Vector3::x);
    let y0 = z.cross(&x0);
    let base = UnitQuaternion::from_rotation_matrix(&Rotation3::from_basis_unchecked(&[x0, y0, z]));
    let tilt_axis = Unit::new_normalize(x0 * tilt_dir.cos() + y0 * tilt_dir.sin());
    UnitQuaternion::from_axis_angle(&tilt_axis, tilt) * base * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), spin)
}

/// The head frame of a station facing the robot: origin so that the convergence point `c_head`
/// lands on `sphere_base`, head +y pointing back towards the base z axis.
fn facing_head(sphere_base: &Vector3<f64>, c_head: &Vector3<f64>) -> Isometry3<f64> {
    let yaw = sphere_base.x.atan2(-sphere_base.y);
    let rot = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw);
    Isometry3::from_parts(Translation3::from(sphere_base - rot * c_head), rot)
}

/// Builds the cell and measures the pool with `head` (the identified beams) on `spms` (the
/// physical head).
///
/// Long by design: one pass in the order the cell is set up (stations placed and measured, the tool
/// and the robot drawn, the pool measured station by station). Each piece draws from a stream of its
/// own ([`streams`]: each station, the tool, the robot, each pool candidate), so that designs with
/// another number of stations are compared on the same robot and tool (common random numbers).
pub fn build(arm: &ArmSpec, station: &StationSpec, spms: &Spms, head: &IdentifiedHead, seed: u64) -> Result<Cell, CellError> {
    let truth0 = crate::robot::perturb(&arm.truth_model(), &default_parameters(), &arm.spread, &mut stream(seed, streams::SPREAD));
    let normal = Normal::new(0.0, 1.0).expect("unit normal");
    let tracker = AxisNoise::new(station.tracker_sigma_um);
    let c_head = Vector3::from(station.sphere_centre_head_mm);
    let mut nominal_heads = Vec::new();
    let mut true_heads = Vec::new();
    // The tracker measures every head's A1-A3 in its own frame; the heads' frames are then
    // expressed in the first one's as measured.
    let mut measured_tracker_from_head = Vec::new();
    for (k, p) in station.sphere_points_base_mm.iter().enumerate() {
        let rng = &mut stream(seed, streams::STATION + k as u64);
        let nominal = facing_head(&Vector3::from(*p), &c_head);
        let dp = Vector3::from_fn(|_, _| normal.sample(rng) * station.placement_error_mm);
        let da = Vector3::from_fn(|_, _| normal.sample(rng) * station.placement_error_deg.to_radians());
        let true_head = Isometry3::from_parts(
            Translation3::from(nominal.translation.vector + dp),
            UnitQuaternion::from_scaled_axis(da) * nominal.rotation,
        );
        measured_tracker_from_head.push(super::measured_frame(&true_head, &tracker, rng).expect("A1-A3 are not collinear"));
        true_heads.push(true_head);
        nominal_heads.push(nominal);
    }
    let world_from_tracker = measured_tracker_from_head[0].inverse();
    let tool_nominal = Vector3::from(arm.sphere_flange_mm);
    let tool_rng = &mut stream(seed, streams::TOOL);
    let tool_true = tool_nominal + Vector3::from_fn(|_, _| normal.sample(tool_rng) * arm.sphere_flange_error_mm);
    let nominal = arm
        .nominal_model()
        .edited(|d| {
            d.world_from_base = crate::robot::XyzZyx::from_isometry(&nominal_heads[0].inverse());
            d.flange_tcp_mm = tool_nominal;
        })
        .expect("valid");
    let truth = truth0
        .edited(|d| {
            d.world_from_base = crate::robot::XyzZyx::from_isometry(&true_heads[0].inverse());
            d.flange_tcp_mm = tool_true;
        })
        .expect("valid");
    let reference_q: Joints = arm.repeatability_reference_q_deg.map(f64::to_radians);
    // The twin's learned effects are drawn after the scenario's own, from the same stream.
    let robot_rng = &mut stream(seed, streams::ROBOT);
    let robot = VirtualRobot::new(truth, &arm.unmodelled, arm.repeatability_mm, &reference_q, robot_rng)
        .with_learned(arm.learned.as_ref(), robot_rng)
        .with_learned_repeatability(arm.learned.as_ref(), arm.repeatability_mm, &reference_q, robot_rng);
    // The controller plans in {S} of the nominal layout.
    let nominal_s_from_base = nominal_heads[0].inverse();

    let mut stations = Vec::new();
    for (k, (nom, tru)) in nominal_heads.iter().zip(&true_heads).enumerate() {
        let target = nominal_s_from_base * nom * Translation3::from(c_head);
        let facing = target.rotation * -Vector3::y();
        let reference = Isometry3::from_parts(target.translation, presentation(&facing, 0.0, 0.0, 0.0));
        let q = [[0.0, 0.3, 0.3, 0.0, 0.6, 0.0], [0.0, 0.0, 0.0, 0.0, 0.0, 0.0], [0.0, 0.6, 0.0, 0.0, 0.3, 0.0]]
            .iter()
            .map(|s| {
                let mut s = *s;
                s[0] = station.sphere_points_base_mm[k][1].atan2(station.sphere_points_base_mm[k][0]);
                s
            })
            .find_map(|seed| refine(&nominal, &reference, &seed).ok().filter(|q| nominal.within_limits(q)))
            .ok_or(CellError::Station(station.sphere_points_base_mm[k]))?;
        // Teaching the station: the operator jogs until the SPMS sees the sphere at the convergence
        // point (three corrections of the commanded point by what the head reads, noise-free).
        let true_head_from_s = (true_heads[0].inverse() * tru).inverse();
        let mut shift = Vector3::zeros();
        let mut q = q;
        for _ in 0..3 {
            let seen = true_head_from_s.transform_point(&Point3::from(forward(&robot.truth, &mut KinState::default(), &q))).coords;
            shift += seen - c_head;
            let corrected =
                Isometry3::from_parts(Translation3::from(nominal_s_from_base * nom * Point3::from(c_head - shift)), reference.rotation);
            q = refine(&nominal, &corrected, &q)
                .ok()
                .filter(|q| nominal.within_limits(q))
                .ok_or(CellError::Station(station.sphere_points_base_mm[k]))?;
        }
        let world_from_head = world_from_tracker * measured_tracker_from_head[k];
        stations.push(Station { base_from_head: *tru, world_from_head, q, taught_shift_mm: shift });
    }

    let mut pool = Vec::with_capacity(station.pool);
    let mut rejected = 0;
    let mut st = KinState::default();
    let cone = station.approach_cone_deg.to_radians();
    let spin = station.spin_deg.to_radians();
    let per_station = station.pool.div_ceil(stations.len().max(1));
    // {S} of the true layout from the true head k: where the robot really puts the sphere.
    let true_s_from_base = true_heads[0].inverse();
    for (k, stn) in stations.iter().enumerate() {
        let nominal_s_from_head = nominal_s_from_base * nominal_heads[k];
        let true_head_from_s = (true_s_from_base * true_heads[k]).inverse();
        let mut got = 0;
        let mut index = 0u64;
        while got < per_station && pool.len() < station.pool && index < 50 * per_station.max(1) as u64 {
            let mut r = stream(seed, streams::pool(k, index));
            index += 1;
            // Uniform over the spherical cap of the cone.
            let cos_t = 1.0 - r.random::<f64>() * (1.0 - cone.cos());
            let tilt = cos_t.clamp(-1.0, 1.0).acos();
            let facing = nominal_s_from_head.rotation * -Vector3::y();
            let orient = presentation(
                &facing,
                tilt,
                r.random_range(0.0..std::f64::consts::TAU),
                if spin > 0.0 { r.random_range(-spin..spin) } else { 0.0 },
            );
            let t = station.sphere_travel_mm;
            let jitter = |r: &mut rand_chacha::ChaCha8Rng, h: f64| {
                if h > 0.0 { r.random_range(-h..h) } else { 0.0 }
            };
            let c = c_head + Vector3::new(jitter(&mut r, t[0]), jitter(&mut r, t[1]), jitter(&mut r, t[2]));
            let aim = c - stn.taught_shift_mm;
            let Ok(q) =
                refine(&nominal, &Isometry3::from_parts(Translation3::from(nominal_s_from_head * Point3::from(aim)), orient), &stn.q)
            else {
                rejected += 1;
                continue;
            };
            if !nominal.within_limits(&q) {
                rejected += 1;
                continue;
            }
            let true_s = robot.tcp_after_move(&mut st, &q, &stn.q, &mut r);
            let true_c = true_head_from_s.transform_point(&Point3::from(true_s)).coords;
            let Ok(l) = spms.read(&true_c, Some(&mut r)) else {
                rejected += 1;
                continue;
            };
            let Some((measured, _)) = head.centre(&l, spms.sphere_radius_mm) else {
                rejected += 1;
                continue;
            };
            let measured_world = stn.world_from_head.transform_point(&Point3::from(measured)).coords;
            pool.push(PoolPose { station: k, q, measured_world_mm: measured_world, true_world_mm: true_s });
            got += 1;
        }
    }
    if pool.len() < station.pool {
        return Err(CellError::Pool { got: pool.len(), wanted: station.pool });
    }
    Ok(Cell { nominal, robot, stations, pool, rejected })
}

/// AP and RP of one ISO 9283 test.
#[derive(Clone, Debug, PartialEq)]
pub struct IsoResult {
    /// AP per point P1..P5, mm.
    pub ap_mm: [f64; 5],
    /// RP per point, mm.
    pub rp_mm: [f64; 5],
}

impl IsoResult {
    /// Max, mean and RMS of the five AP values, mm.
    pub fn ap_summary(&self) -> (f64, f64, f64) {
        iso9283::summary(&self.ap_mm)
    }
}

/// The ISO 9283 test points, base frame.
pub fn iso_points(iso: &IsoSpec) -> [Vector3<f64>; 5] {
    iso9283::test_points(&Vector3::from(iso.cube_centre_base_mm), iso.cube_mm, iso.corner_fraction)
}

/// Runs the ISO 9283 test of `controller` (any world frame: the test commands in its base frame)
/// on the physical robot of `cell`. The tracker measures in the robot's base frame (registration
/// taken as exact); every controller sees the same noise (one stream per scenario).
pub fn iso_test(cell: &Cell, controller: &RobotModel, iso: &IsoSpec, seed: u64) -> Result<IsoResult, CellError> {
    let ctrl = controller.edited(|d| d.world_from_base = XyzZyx::default()).expect("valid");
    let truth = cell.robot.truth.edited(|d| d.world_from_base = XyzZyx::default()).expect("valid");
    let robot = VirtualRobot { truth, ..cell.robot.clone() };
    let points = iso_points(iso);
    // Flange pointing down, as a tracker target on the flange is usually presented.
    let down = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), std::f64::consts::PI);
    let mut seed_q: Joints = [0.0, 0.3, 0.3, 0.0, 1.0, 0.0];
    let mut qs = Vec::with_capacity(5);
    for (k, p) in points.iter().enumerate() {
        let q = refine(&ctrl, &Isometry3::from_parts(Translation3::from(*p), down), &seed_q)
            .ok()
            .filter(|q| ctrl.within_limits(q))
            .ok_or(CellError::Iso { point: format!("P{}", k + 1) })?;
        seed_q = q;
        qs.push(q);
    }
    let mut rng = stream(seed, streams::ISO);
    let tracker = AxisNoise::new(iso.tracker_sigma_um);
    let mut attained: [Vec<Vector3<f64>>; 5] = Default::default();
    let mut st = KinState::default();
    let mut from = qs[4];
    for _ in 0..iso.cycles {
        for (k, q) in qs.iter().enumerate() {
            let p = robot.tcp_after_move(&mut st, q, &from, &mut rng);
            attained[k].push(tracker.measure(&p, &mut rng));
            from = *q;
        }
    }
    Ok(IsoResult {
        ap_mm: std::array::from_fn(|k| iso9283::ap(&points[k], &attained[k])),
        rp_mm: std::array::from_fn(|k| iso9283::rp(&attained[k])),
    })
}

/// One identification from the pool entries `selection`, world = head frame.
pub fn identify_from(cell: &Cell, set: &ParamSet, selection: &[usize], opts: &FitOptions) -> crate::identify::least_squares::Fit {
    let obs: Vec<Observation> =
        selection.iter().map(|&i| Observation { q: cell.pool[i].q, tcp_world_mm: cell.pool[i].measured_world_mm }).collect();
    identify(&cell.nominal, set, &obs, opts)
}
