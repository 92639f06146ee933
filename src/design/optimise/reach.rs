//! How far a TriCal design's datum spheres are from what the arm can reach: the margin of a
//! design whose campaign cannot run, and the search's way back into reach.
//!
//! The arm's tool points are sampled within its joint limits (a fixed stream: every design sees
//! the same configurations), and those whose device axis (flange to TCP) lies within the
//! campaign's approach cone around the vertical are kept ([`tool_points_w`]). A sphere's margin
//! ([`sphere_margins_mm`]) is measured from its centring pose, the pose the campaign first puts
//! the device in (its centre, the device axis along {W}'s -z): 0 where the true arm reaches that
//! pose (inverse kinematics, any of [`SPINS`] turns about the axis), else the distance from the
//! centre to the nearest sampled tool point where the arm reaches that pose. The margin is
//! continuous in the sphere's position (a distance to a fixed set of points), so that a search
//! scored by it moves spheres towards the arm; a sample spacing of a few tens of mm means that a
//! margin under that spacing says "about within reach", not "reachable": the campaign decides
//! that; a margin of hundreds of mm says by how much the design is out of reach.

use nalgebra::Vector3;
use rand::RngExt;

use crate::device::trical::campaign::tcp_pose;
use crate::device::{CarriedReach, Scenario};
use crate::robot::{JOINTS, KinState, RobotData, RobotModel, forward, inverse};

/// Configurations sampled.
const SAMPLES: usize = 20_000;

/// Turns of the device about its axis tried at a centring pose (the campaign draws its turn).
pub const SPINS: usize = 8;

/// Sampled tool points tried per sphere, nearest first, before its margin is the distance to the
/// farthest of them (a sphere that far out is out of reach by at least that much).
const TRIED: usize = 400;

/// The tool points of a TriCal scenario's true arm, sampled within its joint limits, whose device
/// axis lies within the campaign's approach cone around the vertical, in the scenario's {W}, mm
/// (`None`: not a TriCal scenario).
pub fn tool_points_w(s: &dyn Scenario) -> Option<Vec<Vector3<f64>>> {
    let arm = s.carried_reach()?;
    let model = arm.truth;
    let cone = arm.approach_cone_deg.to_radians().cos();
    let world_from_base = crate::robot::world_from_base(&model);
    let samples = samples_in_base(&model);
    Some(
        samples
            .iter()
            .filter(|(_, axis)| -(world_from_base.rotation * axis).z >= cone)
            .map(|(tcp, _)| world_from_base * nalgebra::Point3::from(*tcp))
            .map(|p| p.coords)
            .collect(),
    )
}

/// The sampled configurations' tool points and device axes (unit, flange to TCP) in the base
/// frame of `model` (its arm at the identity base): the same for every design that moves only the
/// cell, so kept for the last arm asked (a search asks one arm again and again).
fn samples_in_base(model: &RobotModel) -> std::sync::Arc<Vec<(Vector3<f64>, Vector3<f64>)>> {
    type Kept = Option<(RobotData, std::sync::Arc<Vec<(Vector3<f64>, Vector3<f64>)>>)>;
    static KEPT: std::sync::Mutex<Kept> = std::sync::Mutex::new(None);
    let arm = model.edited(|d| d.world_from_base = Default::default()).expect("the identity base is valid");
    let mut kept = KEPT.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    if let Some((data, samples)) = kept.as_ref()
        && data == arm.data()
    {
        return samples.clone();
    }
    let limits = *arm.limits();
    let mut rng = crate::seeds::fixed_stream(crate::seeds::fixed::REACH);
    let mut st = KinState::default();
    let samples: Vec<(Vector3<f64>, Vector3<f64>)> = (0..SAMPLES)
        .map(|_| {
            let q: [f64; JOINTS] = std::array::from_fn(|j| rng.random_range(limits[j].min..=limits[j].max));
            let tcp = forward(&arm, &mut st, &q);
            let flange = crate::robot::kinematics::world_from_flange(&arm, &mut st, &q).translation.vector;
            (tcp, (tcp - flange).normalize())
        })
        .collect();
    let samples = std::sync::Arc::new(samples);
    *kept = Some((arm.data().clone(), samples.clone()));
    samples
}

/// Per datum sphere of a TriCal scenario, how far its centring pose is from the arm's reach, mm
/// (the module's margin: 0 where the true arm reaches it; `None`: not a TriCal scenario).
pub fn sphere_margins_mm(s: &dyn Scenario) -> Option<Vec<f64>> {
    let points = tool_points_w(s)?;
    let arm = s.carried_reach()?;
    let spheres = s.datum_cell()?.spheres_w_mm;
    Some(centring_margins_mm(&arm, &spheres, &points))
}

/// [`sphere_margins_mm`] of the spheres `spheres` ({W}, mm) for the arm `arm` with its sampled tool
/// points `points` ({W}, mm).
fn centring_margins_mm(arm: &CarriedReach, spheres: &[[f64; 3]], points: &[Vector3<f64>]) -> Vec<f64> {
    let model = &arm.truth;
    let reaches = |p: &Vector3<f64>| centring_reached(model, arm.flange.as_ref(), p);
    spheres
        .iter()
        .map(|c| {
            let c = Vector3::from(*c);
            if reaches(&c) {
                return 0.0;
            }
            let near: Vec<f64> = points.iter().map(|q| (q - c).norm()).collect();
            let mut order: Vec<usize> = (0..points.len()).collect();
            let by = |a: &usize, b: &usize| near[*a].total_cmp(&near[*b]).then(a.cmp(b));
            if order.len() > TRIED {
                order.select_nth_unstable_by(TRIED, by);
                order.truncate(TRIED);
            }
            order.sort_by(by);
            let tried = &order[..];
            match tried.iter().find(|&&i| reaches(&points[i])) {
                Some(&i) => near[i],
                // None of the nearest reaches it: at least as far as the farthest of them.
                None => tried.last().map_or(f64::INFINITY, |&i| near[i]),
            }
        })
        .collect()
}

/// Whether the true arm `model` reaches the TCP point `p_w` ({W}, mm) with the device axis along
/// {W}'s -z (the campaign's first centring pose) at one of [`SPINS`] turns about the axis;
/// `flange`: the device's flange in frame 6 (the pose the inverse kinematics takes).
fn centring_reached(model: &RobotModel, flange: Option<&nalgebra::Matrix3<f64>>, p_w: &Vector3<f64>) -> bool {
    let down = -Vector3::z();
    (0..SPINS).any(|k| {
        let pose = tcp_pose(p_w, &down, std::f64::consts::TAU * k as f64 / SPINS as f64);
        let pose = match flange {
            None => pose,
            Some(r) => {
                nalgebra::Isometry3::from_parts(pose.translation, pose.rotation * crate::robot::rotation::quaternion(&r.transpose()))
            }
        };
        inverse(model, &pose, &[0.0; JOINTS]).is_ok()
    })
}
