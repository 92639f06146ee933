//! A URDF arm into calsim's modified-DH form: the serial chain of six revolute joints from the
//! root link, its joint axes at the zero configuration turned into MDH frames (z along each axis,
//! x along the common normal to the next axis, or their cross product where the axes meet; for
//! parallel axes the normal through the previous frame's foot, so no beta is needed for a nominal
//! geometry), the root-to-{0} transform as the base, the tip (the last link of fixed joints after
//! joint 6) as the tool, and the links' masses and centres of mass in MDH frames. The result is
//! checked against the URDF's own chain at random configurations before it is returned.
//!
//! Collision shapes: each link's `<collision>` cylinders, capsules and spheres become capsules of
//! the same size in the MDH frame of the body the link belongs to (the number of revolute joints
//! between it and the root), a box the capsule that encloses it (its longest edge as the segment,
//! the half-diagonal of the other two as the radius); meshes are left out and named.

use std::collections::HashMap;
use std::path::Path;

use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};

use super::file::{CapsuleSpec, LinkCapsules};
use super::model::{Inertial, JOINTS, JointLimit, Link, RobotData, RobotModel, XyzZyx};

/// Why a URDF cannot be an arm of calsim: the file and what is wrong (joint or link named).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{path}: {message}")]
pub struct UrdfError {
    /// The file.
    pub path: String,
    /// What is wrong.
    pub message: String,
}

/// One movable joint of the chain at the zero configuration, in the root frame (m).
struct Axis {
    name: String,
    point: Vector3<f64>,
    dir: Vector3<f64>,
    /// The child link's frame at q = 0 (root frame).
    child: Isometry3<f64>,
    limits: (f64, f64),
    mass_kg: f64,
    com_root: Vector3<f64>,
}

fn iso(p: &urdf_rs::Pose) -> Isometry3<f64> {
    let (x, y, z) = (p.xyz[0], p.xyz[1], p.xyz[2]);
    Isometry3::from_parts(Translation3::new(x, y, z), UnitQuaternion::from_euler_angles(p.rpy[0], p.rpy[1], p.rpy[2]))
}

/// A converted URDF: the arm, its links' collision capsules (`None`: the URDF has no shape calsim
/// converts) and the collision elements left out (meshes: `link name`).
pub struct Converted {
    /// The arm.
    pub model: RobotModel,
    /// Collision capsules per MDH frame.
    pub capsules: Option<LinkCapsules>,
    /// Collision elements not converted, by link.
    pub skipped: Vec<String>,
    /// The tip link's frame (the flange) in MDH frame 6 where it is not frame 6's orientation.
    pub flange: Option<nalgebra::Matrix3<f64>>,
}

/// Reads `path` and converts it (see the module).
pub fn load(path: &Path) -> Result<RobotModel, UrdfError> {
    load_all(path).map(|c| c.model)
}

/// Reads `path` and converts it with its collision shapes (see the module).
pub fn load_all(path: &Path) -> Result<Converted, UrdfError> {
    let shown = path.display().to_string();
    let fail = |message: String| UrdfError { path: shown.clone(), message };
    let text = crate::io::read_text(path).map_err(|e| fail(e.to_string()))?;
    let robot = urdf_rs::read_from_string(&text).map_err(|e| fail(e.to_string()))?;
    convert(&robot).map_err(fail)
}

/// Converts a parsed URDF (see the module).
pub fn convert(robot: &urdf_rs::Robot) -> Result<Converted, String> {
    let mut by_child: HashMap<&str, &urdf_rs::Joint> = HashMap::new();
    for j in &robot.joints {
        if by_child.insert(j.child.link.as_str(), j).is_some() {
            return Err(format!("link `{}` is the child of two joints: not a serial chain", j.child.link));
        }
    }
    let roots: Vec<&str> = robot.links.iter().map(|l| l.name.as_str()).filter(|l| !by_child.contains_key(l)).collect();
    let [root] = roots.as_slice() else {
        return Err(format!("{} root links ({}): not one tree", roots.len(), roots.join(", ")));
    };
    let children = |link: &str| robot.joints.iter().filter(move |j| j.parent.link == link).collect::<Vec<_>>();
    let movable = |j: &urdf_rs::Joint| !matches!(j.joint_type, urdf_rs::JointType::Fixed);
    // Whether the subtree below `link` holds a movable joint.
    fn moves(robot: &urdf_rs::Robot, link: &str, depth: usize) -> bool {
        depth < 1000
            && robot
                .joints
                .iter()
                .filter(|j| j.parent.link == link)
                .any(|j| !matches!(j.joint_type, urdf_rs::JointType::Fixed) || moves(robot, &j.child.link, depth + 1))
    }
    let inertial = |name: &str| robot.links.iter().find(|l| l.name == name).map(|l| (l.inertial.mass.value, iso(&l.inertial.origin)));
    let mut frame = Isometry3::identity();
    let mut link: String = root.to_string();
    let mut axes: Vec<Axis> = Vec::new();
    loop {
        let next: Vec<&urdf_rs::Joint> = children(&link).into_iter().filter(|j| moves(robot, &j.child.link, 0) || movable(j)).collect();
        let j = match (next.as_slice(), axes.len()) {
            ([j], _) => *j,
            ([], JOINTS) => {
                // The tool: a unique chain of fixed joints after joint 6, if any.
                let fixed = children(&link);
                match fixed.as_slice() {
                    [j] if !movable(j) => *j,
                    _ => break,
                }
            }
            ([], n) => return Err(format!("{n} revolute joints from `{root}`: calsim's arms have {JOINTS}")),
            (many, _) => {
                return Err(format!(
                    "link `{link}` branches into {} moving chains ({}): not a serial chain",
                    many.len(),
                    many.iter().map(|j| j.name.as_str()).collect::<Vec<_>>().join(", ")
                ));
            }
        };
        let (xyz, rpy) = (j.origin.xyz.0, j.origin.rpy.0);
        if !(xyz.iter().all(|v| v.is_finite() && v.abs() <= 100.0) && rpy.iter().all(|v| v.is_finite() && v.abs() <= 100.0)) {
            return Err(format!("joint `{}`: origin xyz {xyz:?} m, rpy {rpy:?} rad: finite numbers within +-100", j.name));
        }
        frame *= iso(&j.origin);
        match j.joint_type {
            urdf_rs::JointType::Fixed => {}
            urdf_rs::JointType::Revolute | urdf_rs::JointType::Continuous => {
                if axes.len() == JOINTS {
                    return Err(format!("joint `{}`: more than {JOINTS} revolute joints", j.name));
                }
                let a = Vector3::new(j.axis.xyz[0], j.axis.xyz[1], j.axis.xyz[2]);
                if !(a.norm() > 1e-9 && a.iter().all(|v| v.is_finite())) {
                    return Err(format!("joint `{}`: axis {:?} is not a direction", j.name, j.axis.xyz.0));
                }
                let limits = if matches!(j.joint_type, urdf_rs::JointType::Continuous) {
                    (-2.0 * std::f64::consts::PI, 2.0 * std::f64::consts::PI)
                } else {
                    (j.limit.lower, j.limit.upper)
                };
                let bound = 6.0 * std::f64::consts::PI;
                if !(limits.0.is_finite() && limits.1.is_finite() && limits.0 < limits.1 && limits.0 >= -bound && limits.1 <= bound) {
                    return Err(format!("joint `{}`: limits [{}, {}] rad are not a range within +-6 pi", j.name, limits.0, limits.1));
                }
                let (mass_kg, com) = inertial(&j.child.link).unwrap_or((0.0, Isometry3::identity()));
                axes.push(Axis {
                    name: j.name.clone(),
                    point: frame.translation.vector,
                    dir: frame.rotation * a.normalize(),
                    child: frame,
                    limits,
                    mass_kg,
                    com_root: (frame * com).translation.vector,
                });
            }
            ref other => return Err(format!("joint `{}` is {other:?}: calsim's arms have revolute joints only", j.name)),
        }
        link = j.child.link.clone();
    }
    if axes.len() != JOINTS {
        return Err(format!("{} revolute joints from `{root}`: calsim's arms have {JOINTS}", axes.len()));
    }
    let tip = frame.translation.vector;
    let (model, frames) = from_axes(&robot.name, &axes, &tip)?;
    check(&model, &axes, &tip)?;
    let (capsules, skipped) = capsules(robot, root, &frames)?;
    // The tip's orientation in frame 6: where the URDF's last axis points into the arm, frame 6's z
    // does too, and the flange (the tip) is turned from it.
    let r = (frames[JOINTS].rotation.inverse() * frame.rotation).to_rotation_matrix().into_inner();
    let flange = ((r - nalgebra::Matrix3::identity()).amax() > 1e-12).then_some(r);
    Ok(Converted { model, capsules, skipped, flange })
}

/// The collision shapes of every link as capsules in its body's MDH frame (`frames`: {0}..{6} in
/// the root frame at the zero configuration, m), and the elements left out.
fn capsules(
    robot: &urdf_rs::Robot,
    root: &str,
    frames: &[Isometry3<f64>; JOINTS + 1],
) -> Result<(Option<LinkCapsules>, Vec<String>), String> {
    let mut caps: LinkCapsules = Default::default();
    let mut skipped = Vec::new();
    let mut any = false;
    // Links from the root at q = 0: (name, root_from_link, body).
    let mut stack = vec![(root.to_string(), Isometry3::identity(), 0usize)];
    let mut seen = 0;
    while let Some((name, pose, body)) = stack.pop() {
        seen += 1;
        if seen > 10_000 {
            return Err("more than 10,000 links: not an arm".into());
        }
        let Some(link) = robot.links.iter().find(|l| l.name == name) else { continue };
        for c in &link.collision {
            let at = pose * iso(&c.origin);
            let seg = |half: f64, r: f64| (Vector3::new(0.0, 0.0, -half), Vector3::new(0.0, 0.0, half), r);
            let (a, b, r) = match &c.geometry {
                urdf_rs::Geometry::Cylinder { radius, length } | urdf_rs::Geometry::Capsule { radius, length } => {
                    seg(length / 2.0, *radius)
                }
                urdf_rs::Geometry::Sphere { radius } => seg(0.0, *radius),
                urdf_rs::Geometry::Box { size } => {
                    let h = [size[0] / 2.0, size[1] / 2.0, size[2] / 2.0];
                    let k = (0..3).max_by(|&i, &j| h[i].total_cmp(&h[j])).unwrap_or(2);
                    let mut e = Vector3::zeros();
                    e[k] = h[k];
                    (-e, e, h[(k + 1) % 3].hypot(h[(k + 2) % 3]))
                }
                urdf_rs::Geometry::Mesh { .. } => {
                    skipped.push(format!("{name} (mesh)"));
                    continue;
                }
            };
            let to_body = frames[body].inverse() * at;
            let (pa, pb) = (to_body * Point3::from(a), to_body * Point3::from(b));
            let ok = pa.iter().chain(pb.iter()).all(|v| v.is_finite() && v.abs() <= 100.0) && r.is_finite() && r > 0.0 && r <= 100.0;
            if !ok {
                return Err(format!(
                    "link `{name}`: collision shape of radius {r} m at {:?} m: needs a radius above 0 and finite points, within 100 m",
                    at.translation.vector
                ));
            }
            caps[body].push(CapsuleSpec { a: (pa.coords * 1e3).into(), b: (pb.coords * 1e3).into(), radius: r * 1e3 });
            any = true;
        }
        for j in robot.joints.iter().filter(|j| j.parent.link == name) {
            let moving = !matches!(j.joint_type, urdf_rs::JointType::Fixed);
            stack.push((j.child.link.clone(), pose * iso(&j.origin), (body + usize::from(moving)).min(JOINTS)));
        }
    }
    Ok((any.then_some(caps), skipped))
}

/// The MDH frames {1}..{6} (origin, x, z) of the axes, {0} and the model; with the frames {0}..{6}
/// in the root frame at the zero configuration (m).
fn from_axes(name: &str, axes: &[Axis], tip: &Vector3<f64>) -> Result<(RobotModel, [Isometry3<f64>; JOINTS + 1]), String> {
    let z: Vec<Vector3<f64>> = axes.iter().map(|a| a.dir).collect();
    let mut origin = [Vector3::zeros(); JOINTS];
    let mut x = [Vector3::zeros(); JOINTS];
    let perp = |v: Vector3<f64>, n: &Vector3<f64>| v - n * n.dot(&v);
    let any_perp = |n: &Vector3<f64>| {
        let t = if n.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
        perp(t, n).normalize()
    };
    for i in 0..JOINTS {
        let (p, a) = (axes[i].point, z[i]);
        if i + 1 < JOINTS {
            let (q, b) = (axes[i + 1].point, z[i + 1]);
            let n = a.cross(&b);
            if n.norm() > 1e-9 {
                // Closest points of the two axis lines.
                let w0 = p - q;
                let (bb, d, e) = (a.dot(&b), a.dot(&w0), b.dot(&w0));
                let den = 1.0 - bb * bb;
                let (s, t) = ((bb * e - d) / den, (e - bb * d) / den);
                let (ci, cj) = (p + a * s, q + b * t);
                origin[i] = ci;
                let v = cj - ci;
                x[i] = if v.norm() > 1e-6 { v.normalize() } else { n.normalize() };
            } else {
                // Parallel axes: through the foot of the previous origin (d = 0 there).
                let prev = if i == 0 { p } else { origin[i - 1] };
                origin[i] = p + a * a.dot(&(prev - p));
                let v = perp(q - origin[i], &a);
                x[i] = if v.norm() > 1e-6 {
                    v.normalize()
                } else if i > 0 {
                    perp(x[i - 1], &a).normalize()
                } else {
                    any_perp(&a)
                };
            }
        } else {
            // Frame 6: on the axis where the tip projects, x as the previous x where it can be.
            origin[i] = p + a * a.dot(&(tip - p));
            let v = perp(x[i - 1], &a);
            x[i] = if v.norm() > 1e-6 { v.normalize() } else { any_perp(&a) };
        }
        if !x[i].iter().all(|v| v.is_finite()) {
            return Err(format!("joint `{}`: no frame can be placed on its axis", axes[i].name));
        }
    }
    // {0}: z along axis 1, at the foot of the root origin on it, x the root's x where it can be.
    let z0 = z[0];
    let o0 = axes[0].point + z0 * z0.dot(&(-axes[0].point));
    let x0 = {
        let v = perp(Vector3::x(), &z0);
        if v.norm() > 1e-6 { v.normalize() } else { any_perp(&z0) }
    };
    let rot = |x: &Vector3<f64>, z: &Vector3<f64>| nalgebra::Rotation3::from_basis_unchecked(&[*x, z.cross(x), *z]);
    let frame0 = Isometry3::from_parts(Translation3::from(o0), UnitQuaternion::from_rotation_matrix(&rot(&x0, &z0)));
    let angle = |from: &Vector3<f64>, to: &Vector3<f64>, about: &Vector3<f64>| from.cross(to).dot(about).atan2(from.dot(to));
    let mut links = [Link { alpha: 0.0, a: 0.0, beta: 0.0, theta_offset: 0.0, d: 0.0, compliance: 0.0 }; JOINTS];
    let (mut po, mut px, mut pz) = (o0, x0, z0);
    for i in 0..JOINTS {
        let alpha = angle(&pz, &z[i], &px);
        let a = (origin[i] - po).dot(&px);
        let foot = po + px * a;
        let d = (origin[i] - foot).dot(&z[i]);
        if (origin[i] - foot - z[i] * d).norm() > 1e-6 {
            return Err(format!("joint `{}`: its frame is off the common normal (MDH cannot hold this geometry)", axes[i].name));
        }
        links[i] = Link { alpha, a: a * 1e3, beta: 0.0, theta_offset: angle(&px, &x[i], &z[i]), d: d * 1e3, compliance: 0.0 };
        (po, px, pz) = (origin[i], x[i], z[i]);
    }
    let mdh = |i: usize| Isometry3::from_parts(Translation3::from(origin[i]), UnitQuaternion::from_rotation_matrix(&rot(&x[i], &z[i])));
    let tool = mdh(JOINTS - 1).inverse_transform_point(&Point3::from(*tip)).coords * 1e3;
    let b = frame0;
    let base = XyzZyx::from_isometry(&Isometry3::from_parts(Translation3::from(b.translation.vector * 1e3), b.rotation));
    let data = RobotData {
        name: name.to_string(),
        links,
        world_from_base: base,
        flange_tcp_mm: tool,
        limits: std::array::from_fn(|i| JointLimit { min: axes[i].limits.0, max: axes[i].limits.1 }),
        links_inertial: std::array::from_fn(|i| Inertial {
            mass_kg: axes[i].mass_kg,
            com_mm: mdh(i).inverse_transform_point(&Point3::from(axes[i].com_root)).coords * 1e3,
        }),
        payload: Inertial::NONE,
        gravity_base: b.rotation.inverse() * Vector3::new(0.0, 0.0, -9.81),
    };
    let frames = std::array::from_fn(|i| if i == 0 { frame0 } else { mdh(i - 1) });
    Ok((RobotModel::new(data).map_err(|e| e.to_string())?, frames))
}

/// The model's TCP against the URDF chain's tip (`tip`, root frame at q = 0, m) at 200
/// configurations spread over the limits.
fn check(model: &RobotModel, axes: &[Axis], tip: &Vector3<f64>) -> Result<(), String> {
    let mut st = super::KinState::default();
    let tip_in_last = axes[JOINTS - 1].child.inverse_transform_point(&Point3::from(*tip)).coords;
    for k in 0..200 {
        let q: [f64; JOINTS] = std::array::from_fn(|i| {
            let (lo, hi) = (axes[i].limits.0.max(-3.0), axes[i].limits.1.min(3.0));
            lo + (hi - lo) * (((k * 7 + i * 13) % 97) as f64 / 96.0)
        });
        // The URDF chain: each joint's frame at q = 0 relative to the previous one, then the
        // rotation by q about its axis.
        let mut t = Isometry3::identity();
        let mut prev = Isometry3::identity();
        for (i, a) in axes.iter().enumerate() {
            let axis_local = Unit::new_normalize(a.child.rotation.inverse() * a.dir);
            t = t
                * (prev.inverse() * a.child)
                * Isometry3::from_parts(Translation3::identity(), UnitQuaternion::from_axis_angle(&axis_local, q[i]));
            prev = a.child;
        }
        let urdf_tip = (t * Point3::from(tip_in_last)).coords * 1e3;
        let ours = super::forward(model, &mut st, &q);
        if (urdf_tip - ours).norm() > 1e-6 {
            return Err(format!("the MDH form misses the URDF's tip by {:.3e} mm at q = {q:?}", (urdf_tip - ours).norm()));
        }
    }
    Ok(())
}
