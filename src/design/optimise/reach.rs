//! How far a TriCal design's datum spheres are from what the arm can reach with the device in its
//! approach cone: the margin of a design whose campaign cannot run.
//!
//! The arm's tool points are sampled within its joint limits (a fixed stream: every design sees
//! the same configurations), those whose device axis (flange to TCP) lies within the campaign's
//! approach cone around the vertical are kept, and each sphere's distance to the nearest of them
//! is its margin. A sample spacing of a few tens of mm means that a margin under that spacing
//! says "about within reach", not "reachable": the campaign decides that; a margin of hundreds of
//! mm says by how much the design is out of reach.

use nalgebra::Vector3;
use rand::RngExt;

use crate::device::Scenario;
use crate::robot::{JOINTS, KinState, forward};

/// Configurations sampled.
const SAMPLES: usize = 20_000;

/// The tool points of a TriCal scenario's true arm, sampled within its joint limits, whose device
/// axis lies within the campaign's approach cone around the vertical, in the scenario's {W}, mm
/// (`None`: not a TriCal scenario).
pub fn tool_points_w(s: &dyn Scenario) -> Option<Vec<Vector3<f64>>> {
    let arm = s.carried_reach()?;
    let model = arm.truth;
    let cone = arm.approach_cone_deg.to_radians().cos();
    let limits = *model.limits();
    let mut rng = crate::seeds::fixed_stream(crate::seeds::fixed::REACH);
    let mut st = KinState::default();
    let mut points: Vec<Vector3<f64>> = Vec::new();
    for _ in 0..SAMPLES {
        let q: [f64; JOINTS] = std::array::from_fn(|j| rng.random_range(limits[j].min..=limits[j].max));
        let tcp = forward(&model, &mut st, &q);
        let flange = crate::robot::kinematics::world_from_flange(&model, &mut st, &q).translation.vector;
        let axis = (tcp - flange).normalize();
        if -axis.z >= cone {
            points.push(tcp);
        }
    }
    Some(points)
}

/// Per datum sphere of a TriCal scenario, the distance from its centre to the nearest sampled
/// tool point the arm reaches with the device within the approach cone ([`tool_points_w`]), mm
/// (`None`: not a TriCal scenario).
pub fn sphere_margins_mm(s: &dyn Scenario) -> Option<Vec<f64>> {
    let points = tool_points_w(s)?;
    let spheres = &s.datum_cell()?.spheres_w_mm;
    Some(
        spheres
            .iter()
            .map(|p| {
                let c = Vector3::from(*p);
                points.iter().map(|q| (q - c).norm()).fold(f64::INFINITY, f64::min)
            })
            .collect(),
    )
}
