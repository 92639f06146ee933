//! The cell to build: a TriCal design's datum spheres, plate and robot base in {W} (the frame the
//! first three spheres define, eqs. 1-5) and in the robot's base frame, with the tool points the
//! arm reaches with the device in its approach cone. The spheres' table (`spheres.csv`, the
//! summary's table) and the drawing (`optimise_cell.png`) are made from this one value.

use nalgebra::{Isometry3, Point3, Vector3};

use crate::device::Scenario;
use crate::robot::XyzZyx;

/// A TriCal design's cell as a machinist builds it.
#[derive(Clone, Debug, PartialEq)]
pub struct CellSheet {
    /// The datum-sphere centres in {W}, mm (the scenario's `cell.spheres_w_mm`).
    pub spheres_w_mm: Vec<[f64; 3]>,
    /// Where the robot base stands in {W}: the scenario's nominal base
    /// (`robot.nominal_base_mm_deg`, or the true arm's where it gives none) moved by the inverse of
    /// the plate's pose (`cell.plate_offset_mm_deg`), as the study places it.
    pub world_from_base: XyzZyx,
    /// The plate's pose relative to the base scenario's cell (`cell.plate_offset_mm_deg`: mm, deg).
    pub plate_offset_mm_deg: [f64; 6],
    /// The corners of the plate's top face in {W}, mm (counter-clockwise from its -x, -y corner):
    /// the spheres' extent grown by the plate's margin, a riser and a ball's radius below the
    /// centres (the collision world's plate, `cell::solids`).
    pub plate_top_w_mm: [[f64; 3]; 4],
    /// The height of a sphere's centre above the plate's top, mm (riser and ball's radius).
    pub centre_above_plate_mm: f64,
    /// Tool points the true arm reaches with the device within the approach cone, in {W}, mm
    /// ([`super::reach::tool_points_w`]).
    pub reach_w_mm: Vec<[f64; 3]>,
}

impl CellSheet {
    /// The sheet of a TriCal scenario (`None`: another device).
    pub fn of(s: &dyn Scenario) -> Option<Self> {
        let c = s.datum_cell()?;
        let world_from_base = c.world_from_base;
        let spheres_w_mm = c.spheres_w_mm.clone();
        let below = c.riser_height_mm + c.ball_diameter_mm / 2.0;
        let lo = |k: usize| spheres_w_mm.iter().map(|p| p[k]).fold(f64::INFINITY, f64::min) - c.plate_margin_mm;
        let hi = |k: usize| spheres_w_mm.iter().map(|p| p[k]).fold(f64::NEG_INFINITY, f64::max) + c.plate_margin_mm;
        let z = -below;
        let plate_top_w_mm = [[lo(0), lo(1), z], [hi(0), lo(1), z], [hi(0), hi(1), z], [lo(0), hi(1), z]];
        let reach_w_mm = super::reach::tool_points_w(s)?.iter().map(|p| [p.x, p.y, p.z]).collect();
        Some(Self {
            spheres_w_mm,
            world_from_base,
            plate_offset_mm_deg: c.plate_offset_mm_deg,
            plate_top_w_mm,
            centre_above_plate_mm: below,
            reach_w_mm,
        })
    }

    /// `world_from_base` as a rigid transform.
    pub fn world_from_base_iso(&self) -> Isometry3<f64> {
        self.world_from_base.isometry()
    }

    /// A point of {W} in the base frame, mm.
    pub fn to_base(&self, p: [f64; 3]) -> [f64; 3] {
        let q = self.world_from_base_iso().inverse() * Point3::from(Vector3::from(p));
        [q.x, q.y, q.z]
    }

    /// The spheres in the base frame, mm.
    pub fn spheres_base_mm(&self) -> Vec<[f64; 3]> {
        self.spheres_w_mm.iter().map(|p| self.to_base(*p)).collect()
    }

    /// The base's origin in {W}, mm.
    pub fn base_origin_w_mm(&self) -> [f64; 3] {
        [self.world_from_base.x, self.world_from_base.y, self.world_from_base.z]
    }

    /// `spheres.csv`: per sphere its centre in {W} and in the base frame, mm (0.001 mm).
    pub fn csv(&self) -> String {
        let mut s = String::from("sphere,x_w_mm,y_w_mm,z_w_mm,x_base_mm,y_base_mm,z_base_mm\n");
        for (k, (w, b)) in self.spheres_w_mm.iter().zip(self.spheres_base_mm()).enumerate() {
            let cells: Vec<String> = w.iter().chain(b.iter()).map(|v| tidy(*v, 3)).collect();
            s += &format!("{},{}\n", k + 1, cells.join(","));
        }
        s
    }

    /// The summary's section: the base's and the plate's poses and the spheres' table (0.1 mm).
    pub fn markdown(&self) -> String {
        let b = &self.world_from_base;
        let deg = |r: f64| tidy(r.to_degrees(), 2);
        let mut s = format!(
            "## The cell to build\n\n{{W}} is the frame the spheres define (eqs. 1-5): origin at sphere 1, x towards sphere 2, \
             sphere 3 in the xy plane (y > 0), z up from the plate. The robot base stands in {{W}} at x, y, z = {}, {}, {} mm, \
             turned alpha, beta, gamma = {}, {}, {} deg (eq. 7: translation, then Rz(alpha) Ry(beta) Rx(gamma)); the plate's top is \
             {} mm below the sphere centres, {} x {} mm (the spheres' extent and the plate margin); the plate stands at \
             `cell.plate_offset_mm_deg` = {:?} from the base scenario's cell. Sphere centres, mm (`spheres.csv` to 0.001 mm; \
             drawn to scale in `optimise_cell.png` with the tool points the arm reaches with the device in its approach cone):\n\n\
             | sphere | x in {{W}} | y in {{W}} | z in {{W}} | x in base | y in base | z in base (height above the base) |\n|---|---|---|---|---|---|---|\n",
            tidy(b.x, 1),
            tidy(b.y, 1),
            tidy(b.z, 1),
            deg(b.alpha),
            deg(b.beta),
            deg(b.gamma),
            tidy(self.centre_above_plate_mm, 1),
            tidy(self.plate_top_w_mm[1][0] - self.plate_top_w_mm[0][0], 1),
            tidy(self.plate_top_w_mm[2][1] - self.plate_top_w_mm[1][1], 1),
            self.plate_offset_mm_deg.map(|v| tidy(v, 3).parse::<f64>().unwrap_or(v)),
        );
        for (k, (w, b)) in self.spheres_w_mm.iter().zip(self.spheres_base_mm()).enumerate() {
            s += &format!(
                "| {} | {} | {} | {} | {} | {} | {} |\n",
                k + 1,
                tidy(w[0], 1),
                tidy(w[1], 1),
                tidy(w[2], 1),
                tidy(b[0], 1),
                tidy(b[1], 1),
                tidy(b[2], 1)
            );
        }
        s + "\n"
    }
}

/// `v` with `decimals` decimals, never `-0.0...`.
pub fn tidy(v: f64, decimals: usize) -> String {
    let s = format!("{v:.decimals$}");
    if s.starts_with('-') && s[1..].chars().all(|c| c == '0' || c == '.') { s[1..].to_string() } else { s }
}
