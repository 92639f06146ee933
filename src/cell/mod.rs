//! The calibration cell: datum spheres on risers over a plate, the table, and the world frame {W}
//! the spheres define.

pub mod collision;
pub mod solids;
pub mod world_frame;

use nalgebra::{DMatrix, Vector3};
use rand::Rng;
use rand_distr::{Distribution, Normal, Uniform};
use serde::Deserialize;

/// The cell as a scenario describes it (units in the names).
#[derive(Clone, Debug, Deserialize, serde::Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct CellSpec {
    /// Datum-sphere centres in {W}, mm: the first at the origin, the second on +x, the third in the
    /// xy-plane with y > 0 (that is how eqs. 1-5 define {W}); any further ones anywhere.
    pub spheres_w_mm: Vec<[f64; 3]>,
    /// Nominal ball diameter, mm (12.7 mm in the paper).
    pub ball_diameter_mm: f64,
    /// Tolerance on the ball diameter, um (Table 1: 2.5 um); each ball's diameter is drawn uniformly
    /// within +- this.
    pub ball_diameter_tolerance_um: f64,
    /// Height of the riser from the plate's top to the ball's centre, mm.
    pub riser_height_mm: f64,
    /// Radius of a riser, mm.
    pub riser_radius_mm: f64,
    /// Thickness of the ball plate, mm.
    pub plate_thickness_mm: f64,
    /// Margin of the plate around the sphere centres, mm.
    pub plate_margin_mm: f64,
    /// Height of the table top in the robot base frame, mm (0: the robot stands on the table).
    pub table_z_base_mm: f64,
    /// Standard deviation of a ballbar distance, um (Table 2: 3.7 um).
    pub ballbar_sigma_um: f64,
    /// Where the plate (and {W} with it) stands relative to the scenario's cell: `[x, y, z]` mm
    /// then `[alpha, beta, gamma]` deg about z, y, x of {W} (eq. 7), e.g. `[0, 0, 100, 0, 0, 10]`
    /// raises the spheres 100 mm and tilts the plate 10 deg about the line of spheres 1 and 2. The
    /// robot's true and nominal bases in {W} move by the inverse; zero: the scenario's cell.
    pub plate_offset_mm_deg: [f64; 6],
}

impl Default for CellSpec {
    fn default() -> Self {
        // Three nests about 300 mm apart (paper section 2.1), equilateral.
        Self {
            spheres_w_mm: vec![[0.0, 0.0, 0.0], [300.0, 0.0, 0.0], [150.0, 259.807_621_135_331_6, 0.0]],
            ball_diameter_mm: 12.7,
            ball_diameter_tolerance_um: 2.5,
            riser_height_mm: 60.0,
            riser_radius_mm: 6.0,
            plate_thickness_mm: 12.0,
            plate_margin_mm: 40.0,
            table_z_base_mm: 0.0,
            ballbar_sigma_um: 3.7,
            plate_offset_mm_deg: [0.0; 6],
        }
    }
}

impl CellSpec {
    /// `world_from_base` of a robot whose base sat at `base` in the scenario's {W}, once the plate
    /// has moved by `plate_offset_mm_deg` (unchanged when the offset is zero).
    pub fn base_in_moved_world(&self, base: crate::robot::XyzZyx) -> crate::robot::XyzZyx {
        if self.plate_offset_mm_deg == [0.0; 6] {
            return base;
        }
        let plate = crate::robot::XyzZyx::from_mm_deg(self.plate_offset_mm_deg);
        crate::robot::XyzZyx::from_isometry(&(plate.isometry().inverse() * base.isometry()))
    }
}

/// A built cell: the true sphere centres and diameters, and what the ballbar measured of them.
#[derive(Clone, Debug)]
pub struct Cell {
    /// The specification it was built from.
    pub spec: CellSpec,
    /// True sphere centres in {W}, mm.
    pub spheres_w: Vec<Vector3<f64>>,
    /// True ball diameters, mm.
    pub ball_diameters_mm: Vec<f64>,
    /// Sphere centres in {W} from the measured ballbar distances (what identification uses), mm.
    pub spheres_w_measured: Vec<Vector3<f64>>,
}

impl Cell {
    /// Builds the cell: draws the ball diameters and measures the ballbar distances.
    pub fn build<R: Rng + ?Sized>(spec: &CellSpec, rng: &mut R) -> Result<Self, world_frame::WorldFrameError> {
        let spheres_w: Vec<Vector3<f64>> = spec.spheres_w_mm.iter().map(|p| Vector3::from(*p)).collect();
        let tol = spec.ball_diameter_tolerance_um * 1e-3;
        let ball_diameters_mm = spheres_w
            .iter()
            .map(|_| {
                if tol > 0.0 {
                    spec.ball_diameter_mm + Uniform::new_inclusive(-tol, tol).expect("tolerance").sample(rng)
                } else {
                    spec.ball_diameter_mm
                }
            })
            .collect();
        let noise = Normal::new(0.0, spec.ballbar_sigma_um * 1e-3).expect("finite sigma");
        let exact = world_frame::distance_matrix(&spheres_w);
        let n = spheres_w.len();
        let mut measured = DMatrix::zeros(n, n);
        for i in 0..n {
            for j in i + 1..n {
                let d = exact[(i, j)] + noise.sample(rng);
                measured[(i, j)] = d;
                measured[(j, i)] = d;
            }
        }
        let spheres_w_measured = world_frame::sphere_centres(&measured, &spheres_w)?;
        Ok(Self { spec: spec.clone(), spheres_w, ball_diameters_mm, spheres_w_measured })
    }

    /// Centre of the calibration zone: the centroid of the sphere centres in {W}, mm (paper 3.2).
    pub fn calibration_zone_centre(&self) -> Vector3<f64> {
        self.spheres_w.iter().sum::<Vector3<f64>>() / self.spheres_w.len() as f64
    }
}

#[cfg(test)]
mod plate_offset_tests {
    use super::CellSpec;
    use crate::robot::XyzZyx;

    fn base() -> XyzZyx {
        XyzZyx { x: 160.2, y: -255.7, z: -220.5, alpha: 91.6_f64.to_radians(), beta: 0.5_f64.to_radians(), gamma: -1.4_f64.to_radians() }
    }

    #[test]
    fn zero_offset_leaves_the_base_as_it_was() {
        assert_eq!(CellSpec::default().base_in_moved_world(base()), base());
    }

    /// Raising the plate 100 mm lowers the base 100 mm in {W}; tilting it about x and back, or
    /// moving it and moving it back, returns the base (to rounding).
    #[test]
    fn the_base_moves_by_the_inverse_of_the_plate() {
        let raised = CellSpec { plate_offset_mm_deg: [0.0, 0.0, 100.0, 0.0, 0.0, 0.0], ..CellSpec::default() }.base_in_moved_world(base());
        assert!((raised.z - (base().z - 100.0)).abs() < 1e-9 && (raised.x - base().x).abs() < 1e-9);
        assert!((raised.alpha - base().alpha).abs() < 1e-12 && (raised.gamma - base().gamma).abs() < 1e-12);
        let offset = [30.0, -20.0, 100.0, 5.0, -3.0, 10.0];
        let moved = CellSpec { plate_offset_mm_deg: offset, ..CellSpec::default() }.base_in_moved_world(base());
        let iso = |t: &XyzZyx| {
            nalgebra::Isometry3::from_parts(
                nalgebra::Translation3::new(t.x, t.y, t.z),
                nalgebra::UnitQuaternion::from_euler_angles(t.gamma, t.beta, t.alpha),
            )
        };
        let [x, y, z, a, b, g] = offset;
        let plate = XyzZyx { x, y, z, alpha: a.to_radians(), beta: b.to_radians(), gamma: g.to_radians() };
        let back = XyzZyx::from_isometry(&(iso(&plate) * iso(&moved)));
        for (u, v) in [(back.x, base().x), (back.y, base().y), (back.z, base().z)] {
            assert!((u - v).abs() < 1e-9, "{u} vs {v}");
        }
        for (u, v) in [(back.alpha, base().alpha), (back.beta, base().beta), (back.gamma, base().gamma)] {
            assert!((u - v).abs() < 1e-12, "{u} vs {v}");
        }
    }
}
