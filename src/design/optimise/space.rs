//! The design space as the search sees it: the unit cube of a count of points, decoded into a
//! scenario table (the TriCal spheres with the {W} they define and the plate's pose) or into the
//! geometric violation that rules the design out, with its margin.

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};

use super::spec::{DesignSpace, Region};
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
