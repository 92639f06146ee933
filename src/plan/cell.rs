//! The plan's cell: the arm's capsules, an SMR sphere per target on the flange, the floor, the
//! keep-out boxes and the tracker's head as obstacles; what makes a configuration feasible.

use nalgebra::{Isometry3, Vector3};

use super::spec::{Plan, PlanError};
use crate::cell::collision::{CapsuleSpec, CollisionWorld, Obstacle};
use crate::robot::{JOINTS, Joints, KinState, RobotModel, forward};

/// Half extent of the floor slab and of its thickness, mm.
const FLOOR_HALF_MM: f64 = 100_000.0;
const FLOOR_THICKNESS_HALF_MM: f64 = 500.0;

/// Why a configuration is not kept.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Refusal {
    /// Outside the joint limits.
    Limits,
    /// A collision (self, obstacle, floor, tracker head).
    Collision,
    /// A target outside the tracker's range band.
    Range,
    /// A target outside the field of view.
    FieldOfView,
    /// An SMR turned away beyond the incidence limit.
    Incidence,
    /// The line of sight crosses the arm or an obstacle.
    LineOfSight,
}

impl Refusal {
    /// Every refusal, in the order they are tested.
    pub const ALL: [Refusal; 6] =
        [Refusal::Limits, Refusal::Collision, Refusal::Range, Refusal::FieldOfView, Refusal::Incidence, Refusal::LineOfSight];

    /// Name for the report.
    pub fn name(self) -> &'static str {
        match self {
            Refusal::Limits => "joint limits",
            Refusal::Collision => "collision",
            Refusal::Range => "tracker range",
            Refusal::FieldOfView => "field of view",
            Refusal::Incidence => "SMR incidence",
            Refusal::LineOfSight => "line of sight",
        }
    }
}

/// The cell, ready for queries.
pub struct Cell {
    /// The nominal arm (base at the origin, tool on the flange).
    pub model: RobotModel,
    collide: CollisionWorld,
    sight: CollisionWorld,
    /// Tracker position, mm.
    tracker: Vector3<f64>,
    aim: Vector3<f64>,
    fov_cos: f64,
    incidence_cos: f64,
    range: (f64, f64),
    clearance: f64,
    limits: [crate::robot::JointLimit; JOINTS],
    targets: Vec<(Vector3<f64>, Vector3<f64>)>,
}

fn obstacles(plan: &Plan) -> Vec<Obstacle> {
    let mut out = Vec::new();
    if let Some(f) = plan.floor_z_mm {
        let centre = Isometry3::translation(0.0, 0.0, f - FLOOR_THICKNESS_HALF_MM);
        out.push(Obstacle::cuboid("floor", Vector3::new(FLOOR_HALF_MM, FLOOR_HALF_MM, FLOOR_THICKNESS_HALF_MM), &centre));
    }
    for b in &plan.keep_out {
        let centre = Isometry3::translation((b.min.x + b.max.x) / 2.0, (b.min.y + b.max.y) / 2.0, (b.min.z + b.max.z) / 2.0);
        out.push(Obstacle::cuboid(&format!("keep-out {}", b.name), (b.max - b.min) / 2.0, &centre));
    }
    out
}

impl Cell {
    /// The cell of `plan`; an error when the tracker's head is inside the arm (it meets a link at
    /// the middle of the joint limits, or the base's vertical column).
    pub fn new(plan: &Plan) -> Result<Self, PlanError> {
        let links = plan.robot.capsules.clone().expect("a plan's robot has capsules (checked)");
        let r = plan.tracker.smr_diameter_mm / 2.0;
        let device: Vec<CapsuleSpec> =
            plan.targets.iter().map(|t| CapsuleSpec { a: t.frame6_mm.into(), b: t.frame6_mm.into(), radius: r }).collect();
        let head = plan.tracker.position_mm;
        let mut with_head = obstacles(plan);
        with_head.push(Obstacle::capsule("tracker head", head, head, plan.tracker.head_radius_mm));
        let mut collide = CollisionWorld::new(&links, &device, with_head);
        let mut sight = CollisionWorld::new(&links, &device, obstacles(plan));
        let model = plan
            .robot
            .nominal
            .edited(|d| {
                d.world_from_base = crate::robot::XyzZyx::default();
                d.flange_tcp_mm = Vector3::zeros();
                d.limits = plan.limits;
            })
            .map_err(|e| PlanError::new(&plan.path, "robot", e.to_string()))?;
        // The pairs of bodies that touch at the home pose (every joint at zero, within the limits)
        // are left out of the self-collision test, as an allowed-collision matrix leaves them out.
        let home: Joints = std::array::from_fn(|i| 0.0_f64.clamp(plan.limits[i].min, plan.limits[i].max));
        let mut st = KinState::default();
        forward(&model, &mut st, &home);
        collide.allow_pairs_touching_at(&st);
        sight.allow_pairs_touching_at(&st);
        let t = &plan.tracker;
        let cell = Self {
            model,
            collide,
            sight,
            tracker: head,
            aim: (t.aim_mm - head).normalize(),
            fov_cos: t.field_of_view_half_rad.cos(),
            incidence_cos: t.incidence_max_rad.cos(),
            range: t.range_mm,
            clearance: r + 0.5,
            limits: plan.limits,
            targets: plan.targets.iter().map(|t| (t.frame6_mm, t.axis6)).collect(),
        };
        // The tracker inside the arm: its head meets a link with the arm at the middle of its limits.
        let mid: Joints = std::array::from_fn(|i| 0.5 * (plan.limits[i].min + plan.limits[i].max));
        let mut st = KinState::default();
        forward(&cell.model, &mut st, &mid);
        let lone = CollisionWorld::new(&links, &[], vec![Obstacle::capsule("tracker head", head, head, t.head_radius_mm)]);
        if let Some(c) = lone.first_collision(&st)
            && c.b == "tracker head"
        {
            return Err(PlanError::new(
                &plan.path,
                "tracker.position_mm",
                format!(
                    "the tracker is inside the arm: its head (radius {} mm) meets {} at the middle of the joint limits",
                    t.head_radius_mm, c.a
                ),
            ));
        }
        Ok(cell)
    }

    /// Target `k`'s position and SMR axis in the base frame after a forward pass in `st`.
    pub fn target(&self, st: &KinState, k: usize) -> (Vector3<f64>, Vector3<f64>) {
        let (p6, a6) = &self.targets[k];
        (st.org[JOINTS] + st.rot[JOINTS] * p6, st.rot[JOINTS] * a6)
    }

    /// Whether `q` is kept: within the limits, free of collision, every target within the range
    /// band and the field of view, its SMR turned to the tracker within the incidence limit, the
    /// line of sight clear. `st` is scratch.
    pub fn check(&self, q: &Joints, st: &mut KinState) -> Result<(), Refusal> {
        if q.iter().zip(&self.limits).any(|(v, l)| !(*v >= l.min && *v <= l.max)) {
            return Err(Refusal::Limits);
        }
        forward(&self.model, st, q);
        if self.collide.first_collision(st).is_some() {
            return Err(Refusal::Collision);
        }
        for k in 0..self.targets.len() {
            let (p, axis) = self.target(st, k);
            let to_tracker = self.tracker - p;
            let d = to_tracker.norm();
            if !(d >= self.range.0 && d <= self.range.1) {
                return Err(Refusal::Range);
            }
            let u = to_tracker / d;
            if (-u).dot(&self.aim) < self.fov_cos {
                return Err(Refusal::FieldOfView);
            }
            if axis.dot(&u) < self.incidence_cos {
                return Err(Refusal::Incidence);
            }
        }
        for k in 0..self.targets.len() {
            let (p, _) = self.target(st, k);
            if !self.sight.line_of_sight(st, &self.tracker, &p, self.clearance) {
                return Err(Refusal::LineOfSight);
            }
        }
        Ok(())
    }

    /// Whether the configuration in `st` (after a forward pass) collides.
    pub fn collides(&self, st: &KinState) -> bool {
        self.collide.first_collision(st).is_some()
    }

    /// The tracker's position, mm.
    pub fn tracker(&self) -> Vector3<f64> {
        self.tracker
    }
}
