//! Algorithm 1 of the TriCal paper: read the three indicators, move the TCP by the reading,
//! repeat until the norm of the reading is below epsilon.
//!
//! The controller computes each correction with the model it believes (its IK refined on its own
//! model, the device axes taken as nominal); the physical robot lands with its own geometry,
//! compliance, unmodelled effects and a fresh draw of its repeatability noise.

use nalgebra::{Isometry3, Translation3, Vector3};
use rand::Rng;

use crate::cell::Cell;
use crate::instrument::trical::{ReadingError, TriCal};
use crate::robot::ik::{IkError, refine};
use crate::robot::{JOINTS, Joints, KinState, RobotModel, VirtualRobot, forward, world_from_flange};

/// A centred configuration.
#[derive(Clone, Debug, PartialEq)]
pub struct CentringResult {
    /// Joint values recorded at the end, rad.
    pub q: Joints,
    /// Corrections made after the first reading.
    pub iterations: u32,
    /// Modelled duration: approach, then one wait and one correction per iteration, s.
    pub seconds: f64,
    /// True distance between the TCP and the ball centre at the end, mm (diagnosis only).
    pub true_offset_mm: f64,
    /// Every reading taken, in order (tool frame), mm.
    pub readings: Vec<Vector3<f64>>,
}

/// Why a configuration could not be centred.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CentringError {
    /// The device gave no reading.
    #[error(transparent)]
    Reading(#[from] ReadingError),
    /// The controller found no joint values for a correction.
    #[error(transparent)]
    Ik(#[from] IkError),
    /// The iteration cap was reached with the reading still above epsilon.
    #[error("not centred after {0} iterations")]
    IterationCap(u32),
}

/// Where a centring starts: the sphere, the commanded configuration `q0` and the one it is reached from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Approach {
    /// Index of the datum sphere.
    pub sphere: usize,
    /// The first commanded configuration.
    pub q0: Joints,
    /// The configuration the robot comes from (its approach direction).
    pub from: Joints,
}

/// Centres the TCP on the sphere of `approach`, the controller believing `controller`.
pub fn centre<R: Rng + ?Sized>(
    controller: &RobotModel,
    robot: &VirtualRobot,
    trical: &TriCal,
    cell: &Cell,
    approach: Approach,
    rng: &mut R,
) -> Result<CentringResult, CentringError> {
    let Approach { sphere, q0, from } = approach;
    let spec = &trical.spec;
    let r6t = trical.frame6_from_tool();
    let centre_w = cell.spheres_w[sphere];
    let radius = cell.ball_diameters_mm[sphere] / 2.0;
    let truth_rot = robot.truth.base_rot;
    let mut st = KinState::default();
    let mut q = q0;
    let mut prev = from;
    let mut seconds = spec.approach_move_s + spec.wait_s;
    let mut iterations = 0;
    let mut readings = Vec::new();
    loop {
        // The physical robot lands; the device reads the ball centre in its own frame.
        let links = robot.link_angles(&q, &prev, rng);
        let tcp_w = forward(&robot.truth, &mut st, &links);
        let world_from_tool = truth_rot * st.rot[JOINTS] * r6t;
        let c = world_from_tool.transpose() * (centre_w - tcp_w);
        let r = trical.read(&c, radius, rng)?;
        readings.push(r);
        if r.norm() < spec.epsilon_mm {
            return Ok(CentringResult { q, iterations, seconds, true_offset_mm: c.norm(), readings });
        }
        if iterations >= spec.max_iterations {
            return Err(CentringError::IterationCap(iterations));
        }
        // The controller moves its TCP by the reading, along the device axes it believes.
        let believed = world_from_flange(controller, &mut st, &q);
        let tcp_b = st.tcp_world();
        let step = believed.rotation * (r6t * r);
        let target = Isometry3::from_parts(Translation3::from(tcp_b + step), believed.rotation);
        let next = refine(controller, &target, &q)?;
        prev = q;
        q = next;
        iterations += 1;
        seconds += spec.correction_move_s + spec.wait_s;
    }
}
