//! The serial chain of a URDF: the six actuated revolute joints from the root link (fixed joints
//! folded in, passive joints left to their branches), their axes at the zero configuration, and
//! the MDH frames placed on them (see the module above).

use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};

use super::iso;
use crate::robot::model::{Inertial, JOINTS, JointLimit, Link, RobotData, RobotModel, XyzZyx};

/// One actuated joint of the chain at the zero configuration, in the root frame (m).
pub(super) struct Axis {
    /// The joint's name.
    pub name: String,
    /// A point of the axis.
    pub point: Vector3<f64>,
    /// The axis direction (unit).
    pub dir: Vector3<f64>,
    /// The child link's frame at q = 0 (root frame).
    pub child: Isometry3<f64>,
    /// Joint range, rad.
    pub limits: (f64, f64),
}

/// The chain found in a URDF.
pub(super) struct Chain {
    /// The root link.
    pub root: String,
    /// The six actuated joints, joint 1 first.
    pub axes: Vec<Axis>,
    /// The tip link's frame (the flange: the last link of fixed joints after joint 6) at q = 0.
    pub tip: Isometry3<f64>,
}

/// Whether `j` moves without being driven: a joint that mimics another (a balancing cylinder, a
/// parallelogram's second bar).
pub(super) fn passive(j: &urdf_rs::Joint) -> bool {
    j.mimic.is_some() && !matches!(j.joint_type, urdf_rs::JointType::Fixed)
}

/// Whether `j` is driven: neither fixed nor passive.
pub(super) fn actuated(j: &urdf_rs::Joint) -> bool {
    !matches!(j.joint_type, urdf_rs::JointType::Fixed) && !passive(j)
}

/// The root link and the chain of actuated joints from it, read from the checked `tree`; a branch
/// whose joints are all fixed or passive is not a second chain.
pub(super) fn walk(tree: &super::graph::Tree<'_>) -> Result<Chain, String> {
    let root = tree.root;
    let children = |link: &str| tree.children(link).to_vec();
    let mut frame = Isometry3::identity();
    let mut link: String = root.to_string();
    let mut axes: Vec<Axis> = Vec::new();
    loop {
        let next: Vec<&urdf_rs::Joint> = children(&link).into_iter().filter(|j| actuated(j) || tree.drives(&j.child.link)).collect();
        let j = match (next.as_slice(), axes.len()) {
            ([j], _) => *j,
            ([], JOINTS) => {
                // The tool: a unique chain of fixed joints after joint 6, if any.
                let fixed: Vec<_> = children(&link).into_iter().filter(|j| matches!(j.joint_type, urdf_rs::JointType::Fixed)).collect();
                match fixed.as_slice() {
                    [j] => *j,
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
        if passive(j) {
            return Err(format!(
                "joint `{}` mimics `{}` and carries the driven joints after it: calsim's arms have {JOINTS} independent joints in series",
                j.name,
                j.mimic.as_ref().map_or("", |m| m.joint.as_str())
            ));
        }
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
                axes.push(Axis {
                    name: j.name.clone(),
                    point: frame.translation.vector,
                    dir: frame.rotation * a.normalize(),
                    child: frame,
                    limits,
                });
            }
            ref other => return Err(format!("joint `{}` is {other:?}: calsim's arms have revolute joints only", j.name)),
        }
        link = j.child.link.clone();
    }
    if axes.len() != JOINTS {
        return Err(format!("{} revolute joints from `{root}`: calsim's arms have {JOINTS}", axes.len()));
    }
    Ok(Chain { root: root.to_string(), axes, tip: frame })
}

/// The MDH frames {1}..{6} (origin, x, z) of the axes, {0} and the model; with the frames {0}..{6}
/// in the root frame at the zero configuration (m).
///
/// Long by design: the construction of the MDH frames is one sequence (common normals, then the
/// frames, then the parameters read off consecutive frames), each step using the previous.
pub(super) fn from_axes(name: &str, axes: &[Axis], tip: &Vector3<f64>) -> Result<(RobotModel, [Isometry3<f64>; JOINTS + 1]), String> {
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
        // Filled from the links of each body (`bodies::inertials`) once the frames are known.
        links_inertial: [Inertial::NONE; JOINTS],
        payload: Inertial::NONE,
        gravity_base: b.rotation.inverse() * Vector3::new(0.0, 0.0, -9.81),
    };
    let frames = std::array::from_fn(|i| if i == 0 { frame0 } else { mdh(i - 1) });
    Ok((RobotModel::new(data).map_err(|e| e.to_string())?, frames))
}

/// The model's TCP against the URDF chain's tip (`tip`, root frame at q = 0, m) at 200
/// configurations spread over the limits.
pub(super) fn check(model: &RobotModel, axes: &[Axis], tip: &Vector3<f64>) -> Result<(), String> {
    let mut st = crate::robot::KinState::default();
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
        let ours = crate::robot::forward(model, &mut st, &q);
        if (urdf_tip - ours).norm() > 1e-6 {
            return Err(format!("the MDH form misses the URDF's tip by {:.3e} mm at q = {q:?}", (urdf_tip - ours).norm()));
        }
    }
    Ok(())
}
