//! The fixed solids of the cell (risers, plate, pedestal, table) in the robot base frame: the one
//! description the collision world and the recording both draw from.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

use super::Cell;
use super::collision::Obstacle;

/// A solid of the cell in the robot base frame: the one description the collision world and the
/// recording both draw from.
#[derive(Clone, Debug, PartialEq)]
pub enum Solid {
    /// A capsule between two points, mm.
    Capsule {
        /// Name.
        name: &'static str,
        /// First end.
        a: Vector3<f64>,
        /// Second end.
        b: Vector3<f64>,
        /// Radius.
        radius: f64,
    },
    /// A box with half extents at a pose, mm.
    Cuboid {
        /// Name.
        name: &'static str,
        /// Half extents.
        half: Vector3<f64>,
        /// `base_from_box`.
        pose: Isometry3<f64>,
    },
}

/// The fixed solids of the cell (risers, plate, pedestal, table) in the base frame; `up_base` is the
/// vertical in the base frame (against gravity): the table is level, at `table_z_base_mm` along it.
pub fn cell_solids(cell: &Cell, base_from_world: &Isometry3<f64>, up_base: &Vector3<f64>) -> Vec<Solid> {
    let s = &cell.spec;
    let r = s.ball_diameter_mm / 2.0;
    let plate_top = -(s.riser_height_mm + r);
    let mut out = Vec::new();
    let (mut lo, mut hi) = (Vector3::repeat(f64::INFINITY), Vector3::repeat(f64::NEG_INFINITY));
    for p in &cell.spheres_w {
        lo = lo.inf(p);
        hi = hi.sup(p);
        // Riser from the plate to just below the ball.
        let a = base_from_world * nalgebra::Point3::new(p.x, p.y, plate_top);
        let b = base_from_world * nalgebra::Point3::new(p.x, p.y, p.z - r - s.riser_radius_mm);
        out.push(Solid::Capsule { name: "riser", a: a.coords, b: b.coords, radius: s.riser_radius_mm });
    }
    let m = s.plate_margin_mm;
    let half = Vector3::new((hi.x - lo.x) / 2.0 + m, (hi.y - lo.y) / 2.0 + m, s.plate_thickness_mm / 2.0);
    let centre_w = Vector3::new((hi.x + lo.x) / 2.0, (hi.y + lo.y) / 2.0, plate_top - s.plate_thickness_mm / 2.0);
    let plate = base_from_world * Isometry3::from_parts(Translation3::from(centre_w), UnitQuaternion::identity());
    out.push(Solid::Cuboid { name: "plate", half, pose: plate });
    // Pedestal from the table to the plate, table and pedestal in the level frame (the base frame
    // turned so that z is up: itself for an upright base).
    let level_from_base = (*up_base != Vector3::z()).then(|| {
        UnitQuaternion::rotation_between(up_base, &Vector3::z())
            .unwrap_or_else(|| UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI))
    });
    let to_base = |p: Isometry3<f64>| level_from_base.map_or(p, |r| r.inverse() * p);
    let plate_level = level_from_base.map_or(plate, |r| r * plate);
    let plate_bottom_base = plate_level.translation.vector.z - s.plate_thickness_mm / 2.0;
    let ped_h = (plate_bottom_base - s.table_z_base_mm).max(1.0);
    let ped = to_base(Isometry3::translation(
        plate_level.translation.vector.x,
        plate_level.translation.vector.y,
        s.table_z_base_mm + ped_h / 2.0,
    ));
    out.push(Solid::Cuboid { name: "pedestal", half: Vector3::new(50.0, 50.0, ped_h / 2.0 - 0.5), pose: ped });
    let table = to_base(Isometry3::translation(0.0, 0.0, s.table_z_base_mm - 25.0));
    out.push(Solid::Cuboid { name: "table", half: Vector3::new(2000.0, 2000.0, 24.0), pose: table });
    out
}

/// The obstacles of the collision world: the cell's solids.
pub fn obstacles(cell: &Cell, base_from_world: &Isometry3<f64>, up_base: &Vector3<f64>) -> Vec<Obstacle> {
    cell_solids(cell, base_from_world, up_base)
        .into_iter()
        .map(|s| match s {
            Solid::Capsule { name, a, b, radius } => Obstacle::capsule(name, a, b, radius),
            Solid::Cuboid { name, half, pose } => Obstacle::cuboid(name, half, &pose),
        })
        .collect()
}
