//! One capsule that contains a cloud of points (a link's mesh vertices in its MDH frame): for each
//! of a few axis directions, the smallest circle around the points seen along it (Welzl) gives the
//! radius and the axis line, and the ends of the segment are pushed only as far as the points
//! beyond them need; the capsule of least volume among the directions wins.
//!
//! The directions are the frame's x, y and z (links are usually drawn along them) and a long
//! chord of the cloud (its ends found by alternating farthest-point searches from the point of
//! largest x). Every choice depends on extreme points only, so the convex hull of a mesh gives the
//! same capsule as the mesh itself (to rounding).
//!
//! Containment is by construction, not by tolerance: the radius is the largest distance of a point
//! from the chosen axis, each end lies where the farthest point beyond it still touches the
//! sphere, and the result is widened by 1e-9 relative plus 1e-9 mm for rounding.

use nalgebra::{Vector2, Vector3};

use super::file::CapsuleSpec;

/// A capsule: segment ends and radius, in the points' frame and unit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Capsule {
    /// First end.
    pub a: Vector3<f64>,
    /// Second end.
    pub b: Vector3<f64>,
    /// Radius.
    pub radius: f64,
}

impl Capsule {
    /// The capsule as a robot file writes it.
    pub fn spec(&self) -> CapsuleSpec {
        CapsuleSpec { a: self.a.into(), b: self.b.into(), radius: self.radius }
    }

    /// Distance from `p` to the capsule's segment.
    pub fn axis_distance(&self, p: &Vector3<f64>) -> f64 {
        let ab = self.b - self.a;
        let len2 = ab.norm_squared();
        let t = if len2 > 0.0 { ((p - self.a).dot(&ab) / len2).clamp(0.0, 1.0) } else { 0.0 };
        (p - (self.a + ab * t)).norm()
    }

    /// Whether `p` lies inside (or on) the capsule.
    pub fn contains(&self, p: &Vector3<f64>) -> bool {
        self.axis_distance(p) <= self.radius
    }

    /// Volume of the capsule.
    pub fn volume(&self) -> f64 {
        let r = self.radius;
        std::f64::consts::PI * r * r * ((self.b - self.a).norm() + 4.0 / 3.0 * r)
    }
}

/// The capsule of least volume that [`fit_along`] finds among the frame's axes and a long chord
/// of `points`; `None` without points or with a point that is not finite.
pub fn bounding_capsule(points: &[Vector3<f64>]) -> Option<Capsule> {
    if points.is_empty() || !points.iter().all(|p| p.iter().all(|v| v.is_finite())) {
        return None;
    }
    let mut directions = vec![Vector3::x(), Vector3::y(), Vector3::z()];
    if let Some(d) = long_chord(points) {
        directions.push(d);
    }
    directions.iter().map(|u| fit_along(points, u)).min_by(|a, b| a.volume().total_cmp(&b.volume()))
}

/// The direction of a long chord of `points`: from the point of largest x (ties by y, z), the
/// farthest point, then the farthest from that, three times; `None` if all points coincide.
fn long_chord(points: &[Vector3<f64>]) -> Option<Vector3<f64>> {
    let start = points.iter().max_by(|p, q| p.x.total_cmp(&q.x).then(p.y.total_cmp(&q.y)).then(p.z.total_cmp(&q.z)))?;
    let farthest = |from: &Vector3<f64>| {
        points.iter().max_by(|p, q| (*p - from).norm_squared().total_cmp(&(*q - from).norm_squared())).copied().unwrap_or(*from)
    };
    let (mut a, mut b) = (*start, farthest(start));
    for _ in 0..3 {
        let c = farthest(&b);
        if (c - b).norm_squared() <= (b - a).norm_squared() {
            break;
        }
        (a, b) = (b, c);
    }
    let d = b - a;
    (d.norm() > 0.0).then(|| d.normalize())
}

/// The capsule around `points` with its axis along the unit vector `u`: the smallest circle of
/// the points projected on the plane normal to `u`, its largest point distance as the radius, the
/// ends as near each other as the points beyond them allow.
pub fn fit_along(points: &[Vector3<f64>], u: &Vector3<f64>) -> Capsule {
    let u = u.normalize();
    let e1 = if u.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
    let e1 = (e1 - u * u.dot(&e1)).normalize();
    let e2 = u.cross(&e1);
    let flat: Vec<Vector2<f64>> = points.iter().map(|p| Vector2::new(p.dot(&e1), p.dot(&e2))).collect();
    let centre = smallest_circle_centre(&flat);
    let radius = flat.iter().map(|q| (q - centre).norm()).fold(0.0, f64::max);
    // A point at height t along u and distance rho from the axis lies in the sphere of an end at
    // s when |s - t| <= sqrt(r^2 - rho^2) = w: the low end may rise to min(t + w), the high end
    // fall to max(t - w).
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for (p, q) in points.iter().zip(&flat) {
        let t = p.dot(&u);
        let w = (radius * radius - (q - centre).norm_squared()).max(0.0).sqrt();
        lo = lo.min(t + w);
        hi = hi.max(t - w);
    }
    // lo > hi: one sphere holds every point; any centre between them does.
    let (lo, hi) = if lo <= hi { (lo, hi) } else { ((lo + hi) / 2.0, (lo + hi) / 2.0) };
    let axis = e1 * centre.x + e2 * centre.y;
    let scale = points.iter().map(|p| p.amax()).fold(0.0, f64::max);
    Capsule { a: axis + u * lo, b: axis + u * hi, radius: radius * (1.0 + 1e-9) + 1e-9 * scale.max(1.0) }
}

/// Centre of the smallest circle around `points` (Welzl's algorithm, iterative, the points taken
/// in a fixed pseudo-random order so that no input order is a worst case).
fn smallest_circle_centre(points: &[Vector2<f64>]) -> Vector2<f64> {
    let n = points.len();
    let mut order: Vec<usize> = (0..n).collect();
    // Fisher-Yates with a xorshift sequence: deterministic, no random-number crate in a kernel.
    let mut state = 0x9E37_79B9_7F4A_7C15u64 ^ n as u64;
    for i in (1..n).rev() {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        order.swap(i, (state % (i as u64 + 1)) as usize);
    }
    let p: Vec<Vector2<f64>> = order.iter().map(|&i| points[i]).collect();
    let outside = |c: &Vector2<f64>, r2: f64, q: &Vector2<f64>| (q - c).norm_squared() > r2 * (1.0 + 1e-12) + 1e-300;
    let (mut c, mut r2) = (p[0], 0.0);
    for i in 1..n {
        if !outside(&c, r2, &p[i]) {
            continue;
        }
        (c, r2) = (p[i], 0.0);
        for j in 0..i {
            if !outside(&c, r2, &p[j]) {
                continue;
            }
            c = (p[i] + p[j]) / 2.0;
            r2 = (p[i] - c).norm_squared();
            for k in 0..j {
                if outside(&c, r2, &p[k]) {
                    c = circumcentre(&p[i], &p[j], &p[k]).unwrap_or(c);
                    r2 = [p[i], p[j], p[k]].iter().map(|q| (q - c).norm_squared()).fold(0.0, f64::max);
                }
            }
        }
    }
    c
}

/// The centre of the circle through three points; for (nearly) collinear ones, the middle of the
/// two farthest apart.
fn circumcentre(a: &Vector2<f64>, b: &Vector2<f64>, c: &Vector2<f64>) -> Option<Vector2<f64>> {
    let (ab, ac) = (b - a, c - a);
    let d = 2.0 * (ab.x * ac.y - ab.y * ac.x);
    let scale = ab.norm_squared().max(ac.norm_squared());
    if d.abs() <= 1e-12 * scale {
        let pairs = [(a, b), (a, c), (b, c)];
        let (p, q) = pairs.iter().max_by(|x, y| (x.0 - x.1).norm_squared().total_cmp(&(y.0 - y.1).norm_squared()))?;
        return Some((*p + *q) / 2.0);
    }
    let (b2, c2) = (ab.norm_squared(), ac.norm_squared());
    Some(a + Vector2::new(ac.y * b2 - ab.y * c2, ab.x * c2 - ac.x * b2) / d)
}

#[cfg(test)]
mod tests {
    use nalgebra::{Rotation3, Vector3};
    use rand::{RngExt, SeedableRng};

    use super::{bounding_capsule, fit_along};

    /// Every point of 300 random clouds (boxes, rods, blobs, single points and pairs, turned
    /// anyhow, 1 to 3,000 points) lies in the capsule fitted to it.
    #[test]
    fn the_fitted_capsule_contains_every_point() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
        for case in 0..300 {
            let n = [1, 2, 3, 50, 3000][case % 5];
            let size = Vector3::new(rng.random_range(0.0..500.0), rng.random_range(0.0..80.0), rng.random_range(0.0..80.0));
            let turn = Rotation3::from_euler_angles(rng.random_range(-3.0..3.0), rng.random_range(-3.0..3.0), rng.random_range(-3.0..3.0));
            let shift = Vector3::from_fn(|_, _| rng.random_range(-400.0..400.0));
            let pts: Vec<Vector3<f64>> =
                (0..n).map(|_| turn * Vector3::from_fn(|k, _| rng.random_range(-1.0..1.0) * size[k]) + shift).collect();
            let cap = bounding_capsule(&pts).expect("a capsule");
            for p in &pts {
                assert!(cap.contains(p), "case {case}: {p} is {} from the axis, radius {}", cap.axis_distance(p), cap.radius);
            }
        }
    }

    /// Noise-free recovery: the points of a capsule's surface (radius 40 mm, segment 300 mm along a
    /// tilted axis) give that capsule back along its own axis, to 1e-6 mm.
    #[test]
    fn the_points_of_a_capsule_give_it_back() {
        let axis = Vector3::new(1.0, 2.0, 0.5).normalize();
        let (a, b, r) = (Vector3::new(10.0, -20.0, 30.0), Vector3::new(10.0, -20.0, 30.0) + axis * 300.0, 40.0);
        let e1 = axis.cross(&Vector3::z()).normalize();
        let e2 = axis.cross(&e1);
        let mut pts = Vec::new();
        for k in 0..72 {
            let phi = f64::from(k) * 5f64.to_radians();
            let radial = e1 * phi.cos() + e2 * phi.sin();
            for t in [0.0, 0.5, 1.0] {
                pts.push(a + (b - a) * t + radial * r);
            }
            pts.push(a - axis * r);
            pts.push(b + axis * r);
        }
        let cap = fit_along(&pts, &axis);
        let ends = if (cap.a - a).norm() < (cap.b - a).norm() { (cap.a, cap.b) } else { (cap.b, cap.a) };
        assert!((ends.0 - a).norm() < 1e-6 && (ends.1 - b).norm() < 1e-6 && (cap.radius - r).abs() < 1e-6, "{cap:?}");
        let best = bounding_capsule(&pts).unwrap();
        assert!(best.volume() <= cap.volume() * (1.0 + 1e-9), "the search finds the capsule's own axis or better");
    }
}
