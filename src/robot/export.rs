//! A model out of calsim for other tools: the URDF of an identified model (its joint origins carry
//! the identified geometry and offsets) and a YAML overlay of per-joint corrections against the
//! model before calibration. Metres and radians, as ROS takes them.

use std::fmt::Write as _;

use super::RobotModel;

/// The URDF could not be written.
#[derive(Debug, thiserror::Error)]
#[error("URDF: {0}")]
pub struct UrdfWriteError(pub String);

/// The YAML overlay: `model`'s corrections against the model before calibration, per
/// joint (the joint-zero offset first, as drivers apply it), then the base and the tool. Lengths
/// in metres and angles in radians (ROS conventions).
pub fn yaml_overlay(before: &RobotModel, model: &RobotModel, provenance: &str) -> String {
    let (b, m) = (before.data(), model.data());
    let mut y = String::new();
    let _ = writeln!(y, "# calsim calibration of {} ({provenance}).", m.name);
    let _ = writeln!(y, "# Identified minus before calibration, modified DH (alpha_{{i-1}}, a_{{i-1}}, beta_{{i-1}}, theta_i, d_i);");
    let _ = writeln!(y, "# offset: add to each joint's zero. Metres, radians, rad/(N m). The full model: robot.toml.");
    let _ = writeln!(y, "joints:");
    for (i, (lb, lm)) in b.links.iter().zip(&m.links).enumerate() {
        let _ = writeln!(y, "  joint_{}:", i + 1);
        let _ = writeln!(y, "    offset: {:e}", lm.theta_offset - lb.theta_offset);
        let _ = writeln!(y, "    alpha: {:e}", lm.alpha - lb.alpha);
        let _ = writeln!(y, "    a: {:e}", (lm.a - lb.a) * 1e-3);
        let _ = writeln!(y, "    beta: {:e}", lm.beta - lb.beta);
        let _ = writeln!(y, "    d: {:e}", (lm.d - lb.d) * 1e-3);
        let _ = writeln!(y, "    compliance: {:e}", lm.compliance - lb.compliance);
    }
    let (wb, wm) = (b.world_from_base, m.world_from_base);
    let _ = writeln!(y, "base:   # world_from_base, eq. 7: translation, then rotations about z, y, x");
    for (k, v) in [("x", wm.x - wb.x), ("y", wm.y - wb.y), ("z", wm.z - wb.z)] {
        let _ = writeln!(y, "  {k}: {:e}", v * 1e-3);
    }
    for (k, v) in [("yaw", wm.alpha - wb.alpha), ("pitch", wm.beta - wb.beta), ("roll", wm.gamma - wb.gamma)] {
        let _ = writeln!(y, "  {k}: {v:e}");
    }
    let _ = writeln!(y, "tool:   # TCP in the flange frame");
    for (k, v) in ["x", "y", "z"].iter().zip((m.flange_tcp_mm - b.flange_tcp_mm).iter()) {
        let _ = writeln!(y, "  {k}: {:e}", v * 1e-3);
    }
    y
}

/// The URDF of the identified model: `world` -> fixed `base` joint (world_from_base) -> `base_link`
/// -> revolute `joint_1`..`joint_6` -> `link_6` -> fixed `tcp` joint -> `tcp`. Each revolute joint's
/// origin is the identified modified-DH transform `Tx(a) Rx(alpha) Ry(beta) Tz(d) Rz(theta_offset)`
/// (rotating about z by q after it gives MDH frame i, so `link_i` is MDH frame i and its inertial
/// origin the centre of mass): **the origins carry the joint offsets**; `<calibration rising>`
/// repeats each offset's correction against the model before calibration, for tools that keep
/// corrections apart. The joint compliance, which URDF has no element for, is written as
/// `<calsim_compliance joint="joint_i" rad_per_nm="..."/>` elements (ignored by URDF parsers).
/// Metres and radians.
pub fn urdf(before: &RobotModel, model: &RobotModel) -> Result<String, UrdfWriteError> {
    use nalgebra::{Isometry3, Vector3};
    use urdf_rs::{Axis, Calibration, Joint, JointLimit, JointType, Link, LinkName, Pose, Robot, Vec3};
    let (b, m) = (before.data(), model.data());
    let pose = |t: &Isometry3<f64>| {
        let (r, p, y) = t.rotation.euler_angles();
        let v = t.translation.vector * 1e-3;
        Pose { xyz: Vec3([v.x, v.y, v.z]), rpy: Vec3([r, p, y]) }
    };
    let link = |name: &str, inertial: Option<&crate::robot::Inertial>| {
        let mut l = Link { name: name.into(), inertial: urdf_rs::Inertial::default(), visual: Vec::new(), collision: Vec::new() };
        if let Some(i) = inertial {
            let c = i.com_mm * 1e-3;
            l.inertial.mass.value = i.mass_kg;
            l.inertial.origin = Pose { xyz: Vec3([c.x, c.y, c.z]), rpy: Vec3([0.0; 3]) };
        }
        l
    };
    let fixed = |name: &str, parent: &str, child: &str, origin: Pose| Joint {
        name: name.into(),
        joint_type: JointType::Fixed,
        origin,
        parent: LinkName { link: parent.into() },
        child: LinkName { link: child.into() },
        axis: Axis::default(),
        limit: JointLimit::default(),
        calibration: None,
        dynamics: None,
        mimic: None,
        safety_controller: None,
    };
    let base = m.world_from_base.isometry();
    let mut links = vec![link("world", None), link("base_link", None)];
    let mut joints = vec![fixed("base", "world", "base_link", pose(&base))];
    for (i, (l, lb)) in m.links.iter().zip(&b.links).enumerate() {
        let t = Isometry3::translation(l.a, 0.0, 0.0)
            * Isometry3::rotation(Vector3::x() * l.alpha)
            * Isometry3::rotation(Vector3::y() * l.beta)
            * Isometry3::translation(0.0, 0.0, l.d)
            * Isometry3::rotation(Vector3::z() * l.theta_offset);
        let parent = if i == 0 { "base_link".to_string() } else { format!("link_{i}") };
        let child = format!("link_{}", i + 1);
        links.push(link(&child, Some(&m.links_inertial[i])));
        let lim = m.limits[i];
        joints.push(Joint {
            joint_type: JointType::Revolute,
            axis: Axis { xyz: Vec3([0.0, 0.0, 1.0]) },
            limit: JointLimit { lower: lim.min, upper: lim.max, effort: 0.0, velocity: 1.0, ..JointLimit::default() },
            calibration: Some(Calibration { rising: Some(l.theta_offset - lb.theta_offset), falling: None }),
            ..fixed(&format!("joint_{}", i + 1), &parent, &child, pose(&t))
        });
    }
    let tcp = m.flange_tcp_mm * 1e-3;
    links.push(link("tcp", None));
    joints.push(fixed("tcp", "link_6", "tcp", Pose { xyz: Vec3([tcp.x, tcp.y, tcp.z]), rpy: Vec3([0.0; 3]) }));
    let robot = Robot { name: m.name.clone(), version: None, links, joints, materials: Vec::new() };
    let text = urdf_rs::write_to_string(&robot).map_err(|err| UrdfWriteError(err.to_string()))?;
    let extension: String = m
        .links
        .iter()
        .enumerate()
        .map(|(i, l)| format!("  <calsim_compliance joint=\"joint_{}\" rad_per_nm=\"{:e}\"/>\n", i + 1, l.compliance))
        .collect();
    let close = text.rfind("</robot>").ok_or_else(|| UrdfWriteError("no closing </robot>".into()))?;
    Ok(format!(
        "{}  <!-- calsim: joint compliance (rad/(N m)), theta = q + offset + c tau; not part of URDF -->\n{extension}{}",
        &text[..close],
        &text[close..]
    ))
}
