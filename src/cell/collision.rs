//! The collision world (parry's geometry): the robot's links as capsules
//! (`shared/reference/irb120.toml`), the measuring device attached to the flange, the ball plate,
//! its risers and pedestal, and the table. Static queries only: intersection tests for collisions
//! and ray casts for line of sight.

use nalgebra::{Isometry3, Rotation3, UnitQuaternion, Vector3};
use parry3d_f64::bounding_volume::BoundingVolume;
use parry3d_f64::math::{Pose, Vector};
use parry3d_f64::query::{Ray, RayCast, contact, intersection_test};
use parry3d_f64::shape::{Capsule, Cuboid, Shape};

use crate::robot::{JOINTS, KinState};

pub use crate::robot::file::{CapsuleSpec, LinkCapsules};

const fn cap(a: [f64; 3], b: [f64; 3], radius: f64) -> CapsuleSpec {
    CapsuleSpec { a, b, radius }
}

/// IRB 120 link capsules in MDH frame i (irb120.toml `[collision]`, derived from the ROS-Industrial
/// collision meshes). Link 2 uses the tighter three-capsule split of the file's note (the single
/// capsule touches link 4 at the home pose), rewritten from the URDF link_2 frame into MDH frame 2
/// (x2 = URDF z, y2 = URDF x, z2 = URDF y). Link 6's capsule is moved by -72 mm along z: frame 6 is
/// the flange here (Table 3), the file's frame 6 sits at the wrist.
pub fn irb120_link_capsules() -> LinkCapsules {
    [
        vec![cap([-53.4, 1.0, 11.1], [-53.4, 1.0, 85.1], 167.2)],
        vec![cap([-0.7, 0.9, -119.0], [-0.7, 0.9, -32.9], 116.9)],
        vec![
            cap([10.4, 0.0, -84.4], [10.4, 0.0, 83.9], 83.4),
            cap([79.4, 0.0, -0.3], [162.1, 0.0, -0.3], 109.2),
            cap([255.5, 0.0, -73.7], [255.5, 0.0, 73.2], 62.8),
        ],
        vec![cap([41.5, -31.4, 4.9], [41.5, 100.7, 4.9], 109.5)],
        vec![cap([-0.1, -0.5, -142.5], [-0.1, -0.5, -1.3], 74.3)],
        vec![cap([0.0, -28.6, 0.0], [0.0, 29.5, 0.0], 55.1)],
        vec![cap([0.0, 0.1, 58.7 - 72.0], [0.0, 0.1, 71.3 - 72.0], 21.2)],
    ]
}

/// A fixed obstacle in the robot base frame.
pub struct Obstacle {
    /// Name, for reports.
    pub name: String,
    shape: Box<dyn Shape>,
    pose: Pose,
}

impl Obstacle {
    /// A box with half extents `half_mm` at `base_from_box`.
    pub fn cuboid(name: &str, half_mm: Vector3<f64>, base_from_box: &Isometry3<f64>) -> Self {
        Self { name: name.into(), shape: Box::new(Cuboid::new(vec(&half_mm))), pose: pose(base_from_box) }
    }

    /// A capsule between two points of the base frame.
    pub fn capsule(name: &str, a: Vector3<f64>, b: Vector3<f64>, radius: f64) -> Self {
        Self { name: name.into(), shape: Box::new(Capsule::new(vec(&a), vec(&b), radius)), pose: Pose::IDENTITY }
    }
}

/// Which two bodies collide.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Collision {
    /// First body.
    pub a: String,
    /// Second body.
    pub b: String,
}

/// Links, device and fixtures, ready for queries in the robot base frame.
pub struct CollisionWorld {
    links: Vec<Vec<Capsule>>,
    /// Device capsules in the flange frame.
    device: Vec<Capsule>,
    obstacles: Vec<Obstacle>,
    /// Body pairs left out of the self-collision test: they touch in the default configuration
    /// with these conservative shapes (as an allowed-collision matrix disables "default" pairs).
    allowed: Vec<(usize, usize)>,
}

fn vec(v: &Vector3<f64>) -> Vector {
    Vector::new(v.x, v.y, v.z)
}

fn pose(iso: &Isometry3<f64>) -> Pose {
    let q = iso.rotation.quaternion();
    let t = iso.translation.vector;
    Pose::from_parts(Vector::new(t.x, t.y, t.z), parry3d_f64::math::Rotation::from_xyzw(q.i, q.j, q.k, q.w))
}

/// Frame i of the last forward pass as a parry pose. The rotation is a product of rotations,
/// orthonormal to rounding, so it is converted directly (Shepperd's method) rather than through
/// `UnitQuaternion::from_matrix`'s iterative orthonormalisation (7 frames per collision query).
fn frame_pose(st: &KinState, i: usize) -> Pose {
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(st.rot[i]));
    let t = st.org[i];
    Pose::from_parts(Vector::new(t.x, t.y, t.z), parry3d_f64::math::Rotation::from_xyzw(q.i, q.j, q.k, q.w))
}

fn body_name(i: usize) -> String {
    if i == JOINTS + 1 { "device".to_string() } else { format!("link {i}") }
}

/// Separation (mm) of two shapes' bounding boxes beyond which they are not tested further: far
/// above GJK's tolerance, so only pairs that are certainly apart are skipped.
const AABB_MARGIN_MM: f64 = 1.0;

fn to_capsule(c: &CapsuleSpec) -> Capsule {
    Capsule::new(Vector::from_array(c.a), Vector::from_array(c.b), c.radius)
}

impl CollisionWorld {
    /// A world of the given link capsules (per MDH frame 0..=6), device capsules (flange frame)
    /// and obstacles (base frame).
    pub fn new(links: &LinkCapsules, device: &[CapsuleSpec], obstacles: Vec<Obstacle>) -> Self {
        Self {
            links: links.iter().map(|l| l.iter().map(to_capsule).collect()).collect(),
            device: device.iter().map(to_capsule).collect(),
            obstacles,
            allowed: Vec::new(),
        }
    }

    /// Keeps the first `n` capsules of the device (the TriCal's bracket without its indicators).
    pub fn keep_device_parts(&mut self, n: usize) {
        self.device.truncate(n);
    }

    /// Leaves out of the self-collision test every pair of bodies that touch in the configuration
    /// whose frames are in `st` (the default pose); returns their names.
    pub fn allow_pairs_touching_at(&mut self, st: &KinState) -> Vec<(String, String)> {
        self.allowed.clear();
        let mut names = Vec::new();
        while let Some((i, j)) = self.first_self_collision(st) {
            self.allowed.push((i, j));
            names.push((body_name(i), body_name(j)));
        }
        names
    }

    fn bodies<'a>(&'a self, frames: &'a [Pose]) -> Vec<(&'a [Capsule], &'a Pose)> {
        self.links
            .iter()
            .enumerate()
            .map(|(i, c)| (c.as_slice(), &frames[i]))
            .chain(std::iter::once((self.device.as_slice(), &frames[JOINTS])))
            .collect()
    }

    fn first_self_collision(&self, st: &KinState) -> Option<(usize, usize)> {
        let frames: Vec<Pose> = (0..=JOINTS).map(|i| frame_pose(st, i)).collect();
        let bodies = self.bodies(&frames);
        for i in 0..bodies.len() {
            for j in i + 2..bodies.len() {
                // The device sits on link 6: it is adjacent to links 5 and 6.
                if (j == JOINTS + 1 && i >= JOINTS - 1) || self.allowed.contains(&(i, j)) {
                    continue;
                }
                let ((ci, pi), (cj, pj)) = (bodies[i], bodies[j]);
                if ci.iter().any(|a| cj.iter().any(|b| Self::hits(a, pi, b, pj))) {
                    return Some((i, j));
                }
            }
        }
        None
    }

    /// Whether two shapes intersect: parry's test, after its bounding boxes have ruled out the
    /// pairs more than `AABB_MARGIN_MM` apart (which the exact test finds apart too, so the
    /// answer is the same, without running GJK for them).
    fn hits(a: &Capsule, pa: &Pose, b: &dyn Shape, pb: &Pose) -> bool {
        if !a.compute_aabb(pa).loosened(AABB_MARGIN_MM).intersects(&b.compute_aabb(pb)) {
            return false;
        }
        intersection_test(pa, a, pb, b).map(|r| r.intersecting).unwrap_or(true)
    }

    /// The first collision at the configuration whose frames are in `st` (after a forward pass):
    /// links 1..6 and the device against the obstacles, then bodies two or more apart (the device
    /// counts as the body after link 6) except the allowed pairs. `None` when the configuration is free.
    pub fn first_collision(&self, st: &KinState) -> Option<Collision> {
        let frames: Vec<Pose> = (0..=JOINTS).map(|i| frame_pose(st, i)).collect();
        for (i, (caps, p)) in self.bodies(&frames).iter().enumerate().skip(1) {
            for o in &self.obstacles {
                if caps.iter().any(|c| Self::hits(c, p, o.shape.as_ref(), &o.pose)) {
                    return Some(Collision { a: body_name(i), b: o.name.clone() });
                }
            }
        }
        self.first_self_collision(st).map(|(i, j)| Collision { a: body_name(i), b: body_name(j) })
    }

    /// How deep the configuration whose frames are in `st` collides, mm: the largest penetration
    /// depth over the pairs [`Self::first_collision`] tests (links 1..6 and the device against the
    /// obstacles, bodies two or more apart but the allowed pairs); 0 when the configuration is
    /// free, above 0 exactly where [`Self::first_collision`] finds one. Continuous in the obstacles' placement, so that a search can move a cell out of the
    /// arm's way where every configuration it tries collides.
    pub fn penetration_mm(&self, st: &KinState) -> f64 {
        let depth = |a: &Capsule, pa: &Pose, b: &dyn Shape, pb: &Pose| -> f64 {
            if !Self::hits(a, pa, b, pb) {
                return 0.0;
            }
            // Intersecting: at least a hair deep (a touch counts, as it does for `first_collision`).
            match contact(pa, a, pb, b, 0.0) {
                Ok(Some(c)) => (-c.dist).max(1e-6),
                _ => 1e-6,
            }
        };
        let frames: Vec<Pose> = (0..=JOINTS).map(|i| frame_pose(st, i)).collect();
        let bodies = self.bodies(&frames);
        let mut deepest = 0.0f64;
        for (caps, p) in bodies.iter().skip(1) {
            for o in &self.obstacles {
                for c in caps.iter() {
                    deepest = deepest.max(depth(c, p, o.shape.as_ref(), &o.pose));
                }
            }
        }
        for i in 0..bodies.len() {
            for j in i + 2..bodies.len() {
                if (j == JOINTS + 1 && i >= JOINTS - 1) || self.allowed.contains(&(i, j)) {
                    continue;
                }
                let ((ci, pi), (cj, pj)) = (bodies[i], bodies[j]);
                for a in ci {
                    for b in cj {
                        deepest = deepest.max(depth(a, pi, b, pj));
                    }
                }
            }
        }
        deepest
    }

    /// Whether the segment from `from` to `to` (base frame, mm) crosses no link, device part or
    /// obstacle, leaving out the last `clearance_mm` before `to` (the target's own mount).
    pub fn line_of_sight(&self, st: &KinState, from: &Vector3<f64>, to: &Vector3<f64>, clearance_mm: f64) -> bool {
        let d = to - from;
        let len = d.norm();
        let ray = Ray::new(vec(from), vec(&(d / len)));
        let max = (len - clearance_mm).max(0.0);
        let frames: Vec<Pose> = (0..=JOINTS).map(|i| frame_pose(st, i)).collect();
        let blocked_by_links =
            self.links.iter().enumerate().any(|(i, caps)| caps.iter().any(|c| c.cast_ray(&frames[i], &ray, max, true).is_some()));
        let blocked_by_device = self.device.iter().any(|c| c.cast_ray(&frames[JOINTS], &ray, max, true).is_some());
        let blocked_by_fixtures = self.obstacles.iter().any(|o| o.shape.cast_ray(&o.pose, &ray, max, true).is_some());
        !(blocked_by_links || blocked_by_device || blocked_by_fixtures)
    }
}

#[cfg(test)]
mod tests {
    use parry3d_f64::query::distance;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;

    /// The bounding-box shortcut of `hits` never changes an answer: 20,000 random pairs of a
    /// capsule against a capsule or a box (radii 5-50 mm, lengths and half extents up to 100 mm,
    /// origins within 100 mm, random orientations) give parry's own answer, and the pairs cover
    /// both answers and the band within 3 mm of contact.
    #[test]
    fn bounding_boxes_never_change_an_answer() {
        let mut rng = ChaCha8Rng::seed_from_u64(17);
        let mut point = |s: f64| Vector3::new(rng.random_range(-s..s), rng.random_range(-s..s), rng.random_range(-s..s));
        let (mut hit, mut near) = (0, 0);
        for i in 0..20_000 {
            let a = Capsule::new(vec(&point(50.0)), vec(&point(50.0)), 5.0 + point(22.5).x.abs() * 2.0);
            let b: Box<dyn Shape> = if i % 2 == 0 {
                Box::new(Capsule::new(vec(&point(50.0)), vec(&point(50.0)), 5.0 + point(22.5).y.abs() * 2.0))
            } else {
                Box::new(Cuboid::new(vec(&point(100.0).abs().add_scalar(1.0))))
            };
            let pa = pose(&Isometry3::new(point(100.0), point(3.0)));
            let pb = pose(&Isometry3::new(point(100.0), point(3.0)));
            let exact = intersection_test(&pa, &a, &pb, b.as_ref()).map(|r| r.intersecting).unwrap_or(true);
            assert_eq!(CollisionWorld::hits(&a, &pa, b.as_ref(), &pb), exact, "pair {i}");
            hit += usize::from(exact);
            let d = distance(&pa, &a, &pb, b.as_ref()).expect("distance").distance;
            near += usize::from(d > 0.0 && d < 3.0);
        }
        assert!(hit > 2_000 && hit < 18_000, "{hit} of 20,000 pairs intersect");
        assert!(near > 100, "{near} pairs within 3 mm of contact");
    }
}
