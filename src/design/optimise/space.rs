//! The design space as the search sees it: the unit cube of a count of points, decoded into a
//! scenario table (the TriCal spheres with the {W} they define and the plate's pose) or into the
//! geometric violation that rules the design out, with its margin.

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};

use super::spec::{DesignSpace, Points, Region};
use crate::design::sweep::spec::{circle_layout, set_dotted};

/// A design decoded: its scenario table, or why the geometry rules it out (with the margin, mm).
#[derive(Clone, Debug)]
pub struct Decoded {
    /// The scenario table.
    pub table: toml::Table,
    /// The values as `key = value` for tables and summaries.
    pub values: Vec<(String, String)>,
    /// The points in the region's frame, mm (empty without points).
    pub points_mm: Vec<[f64; 3]>,
    /// A geometric violation: what, and by how much (mm).
    pub violation: Option<(String, f64)>,
}

impl DesignSpace {
    /// The counts of points searched (one stratum each; `[0]` without points).
    pub fn counts(&self) -> Vec<usize> {
        match &self.points {
            Some(p) => (p.count.0..=p.count.1).collect(),
            None => vec![0],
        }
    }

    /// Dimensions of the unit cube for `count` points.
    pub fn dimensions(&self, count: usize) -> usize {
        let per = match self.points.as_ref().map(|p| &p.region) {
            Some(Region::Plate { .. }) => 2,
            Some(Region::Box { .. }) => 3,
            None => 0,
        };
        let plate = match self.points.as_ref().map(|p| &p.region) {
            Some(Region::Plate { .. }) => 2,
            _ => 0,
        };
        self.variables.len() + plate + per * count
    }

    /// The start design of `count` points in the unit cube.
    pub fn start(&self, count: usize) -> Vec<f64> {
        let mut x: Vec<f64> = self.variables.iter().map(|v| v.start).collect();
        if let Some(p) = &self.points {
            // The start's points as given, then the circle's points of the same index for the
            // rest (the circle of `count` points, moved by the offset).
            let o = p.start_offset_mm;
            let circle: Vec<[f64; 3]> = circle_layout(count.max(3), p.start_spacing_mm)
                .into_iter()
                .enumerate()
                .map(|(k, c)| p.start_points.get(k).copied().unwrap_or([c[0] + o[0], c[1] + o[1], c[2] + o[2]]))
                .collect();
            let unit = |v: f64, r: [f64; 2]| if r[1] > r[0] { ((v - r[0]) / (r[1] - r[0])).clamp(0.0, 1.0) } else { 0.5 };
            match &p.region {
                Region::Plate { x_mm, y_mm, height_mm, tilt_deg } => {
                    x.push(unit(p.start_plate.0, *height_mm));
                    x.push(unit(p.start_plate.1, *tilt_deg));
                    for c in circle.iter().take(count) {
                        x.push(unit(c[0], *x_mm));
                        x.push(unit(c[1], *y_mm));
                    }
                }
                Region::Box { x_mm, y_mm, z_mm } => {
                    for c in circle.iter().take(count) {
                        x.push(unit(c[0], *x_mm));
                        x.push(unit(c[1], *y_mm));
                        x.push(unit(c[2], *z_mm));
                    }
                }
            }
        }
        x
    }

    /// The design at `x` (unit cube, `count` points): its scenario table, or its violation.
    pub fn decode(&self, count: usize, x: &[f64]) -> Decoded {
        let mut table = self.base.clone();
        let mut values = Vec::new();
        for (v, t) in self.variables.iter().zip(x) {
            let value = v.value(*t);
            values.push((v.key.clone(), value.to_string()));
            set_dotted(&mut table, &v.key, value).expect("checked when the file was loaded");
        }
        let mut out = Decoded { table, values, points_mm: Vec::new(), violation: None };
        let Some(p) = &self.points else { return out };
        let rest = &x[self.variables.len()..];
        let at = |t: f64, r: [f64; 2]| r[0] + t.clamp(0.0, 1.0) * (r[1] - r[0]);
        let (points, plate): (Vec<Vector3<f64>>, Option<(f64, f64)>) = match &p.region {
            Region::Plate { x_mm, y_mm, height_mm, tilt_deg } => {
                let (h, tilt) = (at(rest[0], *height_mm), at(rest[1], *tilt_deg));
                let lift = Isometry3::from_parts(
                    Translation3::new(0.0, 0.0, h),
                    UnitQuaternion::from_axis_angle(&Vector3::x_axis(), tilt.to_radians()),
                );
                let pts = (0..count)
                    .map(|k| lift * nalgebra::Point3::new(at(rest[2 + 2 * k], *x_mm), at(rest[3 + 2 * k], *y_mm), 0.0))
                    .map(|q| q.coords)
                    .collect();
                (pts, Some((h, tilt)))
            }
            Region::Box { x_mm, y_mm, z_mm } => (
                (0..count).map(|k| Vector3::new(at(rest[3 * k], *x_mm), at(rest[3 * k + 1], *y_mm), at(rest[3 * k + 2], *z_mm))).collect(),
                None,
            ),
        };
        let round = |v: f64| (v * 1e3).round() / 1e3;
        out.points_mm = points.iter().map(|q| [round(q.x), round(q.y), round(q.z)]).collect();
        if let Some((h, t)) = plate {
            out.values.push(("plate.height_mm".into(), format!("{:.1}", h)));
            out.values.push(("plate.tilt_deg".into(), format!("{:.2}", t)));
        }
        out.values.push((format!("{}.count", p.key), count.to_string()));
        out.values.push((p.key.clone(), format!("{:?}", out.points_mm)));
        // Spacing: the closest pair, short by how much.
        let mut closest = (f64::INFINITY, 0, 0);
        for i in 0..points.len() {
            for j in 0..i {
                let d = (points[i] - points[j]).norm();
                if d < closest.0 {
                    closest = (d, j, i);
                }
            }
        }
        if closest.0 < p.min_spacing_mm {
            out.violation = Some((
                format!(
                    "points {} and {} are {:.1} mm apart, under min_spacing_mm = {}",
                    closest.1 + 1,
                    closest.2 + 1,
                    closest.0,
                    p.min_spacing_mm
                ),
                p.min_spacing_mm - closest.0,
            ));
            return out;
        }
        let floats = |v: &[f64]| toml::Value::Array(v.iter().map(|x| toml::Value::Float(*x)).collect());
        if p.key == "cell.spheres_w_mm" {
            // {W} from the first three spheres (eqs. 1-5): origin at 1, x towards 2, z normal to
            // the plane of 1, 2, 3 (3 on the +y side). The plate offset is W0_from_W.
            let (a, b, c) = (points[0], points[1], points[2]);
            let ex = (b - a).normalize();
            let n = ex.cross(&(c - a));
            let sine = n.norm() / (c - a).norm();
            if sine < 0.2 {
                out.violation = Some((
                    format!("spheres 1, 2 and 3 are nearly on one line (sine of their angle {sine:.3} < 0.2): they define no {{W}}"),
                    (0.2 - sine) * (c - a).norm(),
                ));
                return out;
            }
            if n.z <= 0.0 {
                // {W}'s z axis would point down: the plate offset's turn about x beyond 90 degrees,
                // which the scenario refuses. The margin: how far sphere 3 is on the wrong side.
                out.violation = Some((
                    "spheres 1, 2 and 3 turn clockwise seen from above: {W}'s z axis would point down".into(),
                    -n.z / (b - a).norm(),
                ));
                return out;
            }
            let ez = n.normalize();
            let ey = ez.cross(&ex);
            let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[ex, ey, ez])));
            let w0_from_w = Isometry3::from_parts(Translation3::from(a), rot);
            let in_w: Vec<toml::Value> = points
                .iter()
                .enumerate()
                .map(|(k, q)| {
                    let w = w0_from_w.inverse() * nalgebra::Point3::from(*q);
                    // {W}'s own rules, exact: sphere 1 at the origin, 2 on +x, 3 in the xy plane.
                    let mut v = [round(w.x), round(w.y), round(w.z)];
                    if k == 0 {
                        v = [0.0; 3];
                    }
                    if k == 1 {
                        v[1] = 0.0;
                        v[2] = 0.0;
                    }
                    if k == 2 {
                        v[2] = 0.0;
                    }
                    floats(&v)
                })
                .collect();
            let pose = crate::robot::XyzZyx::from_isometry(&w0_from_w);
            let offset = [pose.x, pose.y, pose.z, pose.alpha.to_degrees(), pose.beta.to_degrees(), pose.gamma.to_degrees()]
                .map(|v| (v * 1e6).round() / 1e6);
            set_dotted(&mut out.table, "cell.spheres_w_mm", toml::Value::Array(in_w)).expect("a table");
            set_dotted(&mut out.table, "cell.plate_offset_mm_deg", floats(&offset)).expect("a table");
        } else {
            let pts: Vec<toml::Value> = out.points_mm.iter().map(|q| floats(q)).collect();
            set_dotted(&mut out.table, &p.key, toml::Value::Array(pts)).expect("a table");
        }
        out
    }
}

/// A design moved to a valid one by [`DesignSpace::repair`].
#[derive(Clone, Debug, PartialEq)]
pub struct Repaired {
    /// The valid design, in the unit cube.
    pub x: Vec<f64>,
    /// The rule the design broke (its violation, as [`DesignSpace::decode`] words it).
    pub broke: String,
    /// How far its points moved, mm (summed over the points; a renumbering moves none).
    pub moved_mm: f64,
}

/// Passes of [`DesignSpace::repair`]'s pushes at most.
pub const REPAIR_PASSES: usize = 200;

/// What [`DesignSpace::repair`] adds to the spacing and to the sine of the first three spheres'
/// angle, so that the repaired design clears the rules after rounding (mm, and sine).
const REPAIR_CLEARANCE: f64 = 1e-3;

/// The points of a design (`rest`: its coordinates after the variables and the plate) in the region's own frame (the plate's x, y with z = 0, or the box's
/// x, y, z), mm, with each coordinate's range.
fn region_points(p: &Points, rest: &[f64], count: usize) -> (Vec<Vector3<f64>>, [[f64; 2]; 3]) {
    let at = |t: f64, r: [f64; 2]| r[0] + t.clamp(0.0, 1.0) * (r[1] - r[0]);
    match &p.region {
        Region::Plate { x_mm, y_mm, .. } => (
            (0..count).map(|k| Vector3::new(at(rest[2 * k], *x_mm), at(rest[2 * k + 1], *y_mm), 0.0)).collect(),
            [*x_mm, *y_mm, [0.0, 0.0]],
        ),
        Region::Box { x_mm, y_mm, z_mm } => (
            (0..count).map(|k| Vector3::new(at(rest[3 * k], *x_mm), at(rest[3 * k + 1], *y_mm), at(rest[3 * k + 2], *z_mm))).collect(),
            [*x_mm, *y_mm, *z_mm],
        ),
    }
}

/// The unit-cube coordinates of region points (the inverse of [`region_points`]; a range of
/// one value gives 0.5).
fn region_unit(p: &Points, points: &[Vector3<f64>], ranges: &[[f64; 2]; 3]) -> Vec<f64> {
    let unit = |v: f64, r: [f64; 2]| if r[1] > r[0] { ((v - r[0]) / (r[1] - r[0])).clamp(0.0, 1.0) } else { 0.5 };
    let per = match p.region {
        Region::Plate { .. } => 2,
        Region::Box { .. } => 3,
    };
    points.iter().flat_map(|q| (0..per).map(move |i| unit(q[i], ranges[i]))).collect()
}

fn clamp_into(q: &mut Vector3<f64>, ranges: &[[f64; 2]; 3]) {
    for i in 0..3 {
        q[i] = q[i].clamp(ranges[i][0], ranges[i][1]);
    }
}

/// A unit direction in the region for two points at the same place: fixed by their indices
/// (the golden angle), in the plate's plane or the box's horizontal plane.
fn apart_direction(i: usize, j: usize) -> Vector3<f64> {
    let a = (i * 7 + j) as f64 * 2.399_963_229_728_653;
    Vector3::new(a.cos(), a.sin(), 0.0)
}

impl DesignSpace {
    /// The offset in `x` of the points' coordinates (after the variables and the plate's two).
    fn points_offset(&self) -> usize {
        let plate = match self.points.as_ref().map(|p| &p.region) {
            Some(Region::Plate { .. }) => 2,
            _ => 0,
        };
        self.variables.len() + plate
    }

    /// A design the geometry rules out (`x`, `count` points) moved to a valid design near it:
    /// - **spacing**: every pair of points closer than `min_spacing_mm` pushed apart along the
    ///   line through them, each by half the shortfall (the whole of it when the other is held
    ///   by the region's bounds), in passes over the pairs in order until none is too close
    ///   (at most [`REPAIR_PASSES`]); two points at one place part along a direction fixed by
    ///   their indices;
    /// - **{W}** (the TriCal spheres): sphere 3 moved straight away from the line through
    ///   spheres 1 and 2, on its own side, until the sine of their angle is 0.2 (in the same
    ///   passes); spheres 1, 2 and 3 turning clockwise seen from above are renumbered (2 and 3
    ///   swapped: the same places, {W}'s z axis up).
    ///
    /// The plate's height and tilt and the other variables are kept. `None` where the design is
    /// valid, or where the pushes end with a rule still broken (the region too small for the
    /// points): it stays ruled out. Deterministic: the same design, the same repair.
    pub fn repair(&self, count: usize, x: &[f64]) -> Option<Repaired> {
        let p = self.points.as_ref()?;
        let broke = self.decode(count, x).violation?.0;
        let off = self.points_offset();
        let (start, ranges) = region_points(p, &x[off..], count);
        let mut pts = start.clone();
        let spheres = p.key == "cell.spheres_w_mm" && count >= 3;
        let spacing = p.min_spacing_mm + REPAIR_CLEARANCE;
        for _ in 0..REPAIR_PASSES {
            let mut moved = false;
            for i in 0..pts.len() {
                for j in 0..i {
                    let d = (pts[i] - pts[j]).norm();
                    if d >= spacing - REPAIR_CLEARANCE / 2.0 {
                        continue;
                    }
                    let u = if d > 1e-9 { (pts[i] - pts[j]) / d } else { apart_direction(i, j) };
                    pts[j] -= u * (spacing - d) / 2.0;
                    clamp_into(&mut pts[j], &ranges);
                    // The rest of the shortfall (all of it where j is held by a bound) moves i.
                    let gap = (pts[i] - pts[j]).dot(&u);
                    pts[i] += u * (spacing - gap).max(0.0);
                    clamp_into(&mut pts[i], &ranges);
                    moved = true;
                }
            }
            if spheres {
                let (a, b, c) = (pts[0], pts[1], pts[2]);
                let ab = b - a;
                if ab.norm() > 1e-9 {
                    let ex = ab.normalize();
                    let along = (c - a).dot(&ex);
                    let perp = (c - a) - ex * along;
                    let sine = perp.norm() / (c - a).norm().max(1e-9);
                    let goal = 0.2 + REPAIR_CLEARANCE;
                    if sine < 0.2 + REPAIR_CLEARANCE / 2.0 {
                        let side = if perp.norm() > 1e-9 {
                            perp.normalize()
                        } else {
                            let s = Vector3::z().cross(&ex);
                            if s.norm() > 1e-9 { s.normalize() } else { Vector3::y() }
                        };
                        let height = goal * along.abs().max(1.0) / (1.0 - goal * goal).sqrt();
                        pts[2] = a + ex * along + side * height;
                        clamp_into(&mut pts[2], &ranges);
                        moved = true;
                    }
                }
            }
            if !moved {
                break;
            }
        }
        let moved_mm: f64 = pts.iter().zip(&start).map(|(a, b)| (a - b).norm()).sum();
        // Points that did not move keep their coordinates as they were (no round trip through mm).
        let per = region_unit(p, &pts[..1], &ranges).len();
        let mut y = x.to_vec();
        for (k, q) in pts.iter().enumerate() {
            if *q != start[k] {
                y.splice(off + per * k..off + per * (k + 1), region_unit(p, std::slice::from_ref(q), &ranges));
            }
        }
        let d = self.decode(count, &y);
        let y = match d.violation {
            None => y,
            Some((why, _)) if spheres && why.contains("clockwise") => {
                // Spheres 2 and 3 renumbered: the same places, turning counter-clockwise.
                let mut z = y.clone();
                for i in 0..per {
                    z.swap(off + per + i, off + 2 * per + i);
                }
                z
            }
            Some(_) => return None,
        };
        self.decode(count, &y).violation.is_none().then_some(Repaired { x: y, broke, moved_mm })
    }

    /// Grid points per axis [`DesignSpace::recount`] tries for a point it adds (the plate's or
    /// the box's).
    pub const RECOUNT_GRID: usize = 21;

    /// A design of `from` points (`x`) brought to `to` points: the other variables and the plate
    /// kept; while it has too many points, the one closest to another dropped (the last of equal
    /// ones; spheres 1 to 3, which define {W}, kept while there is another to drop); while too
    /// few, one added at the free place farthest from every point (of a grid of
    /// [`Self::RECOUNT_GRID`] places per axis over the region, the first of equal ones).
    /// Geometric rules of thumb, not measures: the search from the design so brought judges it.
    pub fn recount(&self, from: usize, x: &[f64], to: usize) -> Vec<f64> {
        let Some(p) = self.points.as_ref() else { return x.to_vec() };
        let off = self.points_offset();
        let (pts0, ranges) = region_points(p, &x[off..], from);
        let per = match p.region {
            Region::Plate { .. } => 2,
            Region::Box { .. } => 3,
        };
        // Each point with where it came from (its index in `x`; none: added).
        let mut pts: Vec<(Option<usize>, Vector3<f64>)> = pts0.into_iter().enumerate().map(|(k, q)| (Some(k), q)).collect();
        let keep = if p.key == "cell.spheres_w_mm" { 3 } else { 0 };
        while pts.len() > to {
            let nearest = |k: usize| -> f64 {
                (0..pts.len()).filter(|&j| j != k).map(|j| (pts[k].1 - pts[j].1).norm()).fold(f64::INFINITY, f64::min)
            };
            let lo = if pts.len() > keep { keep } else { 0 };
            let drop = (lo..pts.len()).rev().min_by(|&a, &b| nearest(a).total_cmp(&nearest(b))).expect("a point");
            pts.remove(drop);
        }
        let g = Self::RECOUNT_GRID;
        let axis = |r: [f64; 2]| -> Vec<f64> {
            if r[1] > r[0] { (0..g).map(|i| r[0] + (r[1] - r[0]) * i as f64 / (g - 1) as f64).collect() } else { vec![r[0]] }
        };
        while pts.len() < to {
            let mut best: Option<(f64, Vector3<f64>)> = None;
            for &zx in &axis(ranges[0]) {
                for &zy in &axis(ranges[1]) {
                    for &zz in &axis(ranges[2]) {
                        let q = Vector3::new(zx, zy, zz);
                        let d = pts.iter().map(|o| (q - o.1).norm()).fold(f64::INFINITY, f64::min);
                        if best.as_ref().is_none_or(|b| d > b.0) {
                            best = Some((d, q));
                        }
                    }
                }
            }
            pts.push((None, best.expect("a grid place").1));
        }
        let mut y = x[..off].to_vec();
        for (from, q) in &pts {
            match from {
                Some(k) => y.extend_from_slice(&x[off + per * k..off + per * (k + 1)]),
                None => y.extend(region_unit(p, std::slice::from_ref(q), &ranges)),
            }
        }
        y
    }
}
