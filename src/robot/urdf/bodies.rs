//! The links of a URDF sorted into the arm's bodies (MDH frames 0 to 6: a link belongs to the body
//! of the last actuated joint between it and the root), with their masses folded into one
//! inertial per body and their collision geometry turned into capsules in the body's MDH frame.
//!
//! Passive joints (`<mimic>`: a balancing cylinder, a parallelogram's second bar) do not move the
//! chain; their links stay with the body they hang from. For collision they are followed: their
//! geometry is swept over the range the mimic relation gives them (`multiplier * q + offset`, q
//! over its master's limits, at most 1 deg a step, the chord's sagitta added to the radius), so the
//! capsule holds them at every configuration. Their masses are folded in at the zero configuration
//! (calsim's links carry one fixed centre of mass each).

use std::collections::HashMap;
use std::path::Path;

use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};

use super::chain::{Chain, actuated, passive};
use super::{ImportOptions, iso};
use crate::robot::capsule_fit::bounding_capsule;
use crate::robot::file::{CapsuleSpec, LinkCapsules};
use crate::robot::mesh::{self, MeshError};
use crate::robot::model::{Inertial, JOINTS};

/// A passive joint of the URDF and what became of it.
#[derive(Clone, Debug, PartialEq)]
pub struct PassiveJoint {
    /// The joint's name.
    pub name: String,
    /// The actuated joint it follows.
    pub master: String,
    /// `angle = multiplier * q_master + offset`.
    pub multiplier: f64,
    /// Offset, rad.
    pub offset: f64,
    /// The MDH frame (body) its links hang from.
    pub body: usize,
}

/// One passive joint on a link's path from the root: where it turns and by how much a sampling
/// step.
#[derive(Clone, Copy)]
struct Sweep {
    /// A point of its axis at the zero configuration, root frame, m.
    origin: Vector3<f64>,
    /// The angle between two samples, rad.
    step: f64,
}

/// A link placed at the zero configuration.
struct Placed<'a> {
    link: &'a urdf_rs::Link,
    body: usize,
    /// `root_from_link` with every joint at zero (passive ones at their mimic offset).
    zero: Isometry3<f64>,
    /// `root_from_link` at each sample of its passive joints' ranges (just `zero` when none).
    swept: Vec<Isometry3<f64>>,
    sweeps: Vec<Sweep>,
}

/// The actuated joint a passive one follows, composed through passive masters:
/// `(master name, multiplier, offset)`.
fn master_of(robot: &urdf_rs::Robot, j: &urdf_rs::Joint) -> Result<(String, f64, f64), String> {
    let (mut m, mut off, mut at) = (1.0, 0.0, j);
    for _ in 0..16 {
        let Some(mimic) = &at.mimic else { return Ok((at.name.clone(), m, off)) };
        let (k, o) = (mimic.multiplier.unwrap_or(1.0), mimic.offset.unwrap_or(0.0));
        if !(k.is_finite() && o.is_finite() && k.abs() <= 100.0 && o.abs() <= 100.0) {
            return Err(format!("joint `{}`: mimic multiplier {k}, offset {o}: finite numbers within +-100", at.name));
        }
        (m, off) = (m * k, m * o + off);
        at = robot
            .joints
            .iter()
            .find(|x| x.name == mimic.joint)
            .ok_or_else(|| format!("joint `{}` mimics `{}`, which the URDF does not have", at.name, mimic.joint))?;
    }
    Err(format!("joint `{}`: its mimic masters go round in a loop", j.name))
}

/// Every link from the root with its body and poses, and the passive joints met.
fn place<'a>(robot: &'a urdf_rs::Robot, chain: &Chain) -> Result<(Vec<Placed<'a>>, Vec<PassiveJoint>), String> {
    let limits: HashMap<&str, (f64, f64)> = chain.axes.iter().map(|a| (a.name.as_str(), a.limits)).collect();
    let mut out = Vec::new();
    let mut passives = Vec::new();
    let root = robot.links.iter().find(|l| l.name == chain.root).ok_or("the root link is missing")?;
    let mut stack = vec![Placed { link: root, body: 0, zero: Isometry3::identity(), swept: vec![Isometry3::identity()], sweeps: vec![] }];
    while let Some(p) = stack.pop() {
        if out.len() > 10_000 {
            return Err("more than 10,000 links: not an arm".into());
        }
        for j in robot.joints.iter().filter(|j| j.parent.link == p.link.name) {
            let child = robot
                .links
                .iter()
                .find(|l| l.name == j.child.link)
                .ok_or_else(|| format!("joint `{}`: no link `{}`", j.name, j.child.link))?;
            let origin = iso(&j.origin);
            let axis = Unit::new_normalize(Vector3::new(j.axis.xyz[0], j.axis.xyz[1], j.axis.xyz[2]));
            let turned =
                |angle: f64| origin * Isometry3::from_parts(Translation3::identity(), UnitQuaternion::from_axis_angle(&axis, angle));
            let next = if passive(j) {
                let (master, k, off) = master_of(robot, j)?;
                let &(lo, hi) = limits
                    .get(master.as_str())
                    .ok_or_else(|| format!("joint `{}` mimics `{master}`, which is not one of the arm's {JOINTS} joints", j.name))?;
                let norm = Vector3::new(j.axis.xyz[0], j.axis.xyz[1], j.axis.xyz[2]).norm();
                if norm.is_nan() || norm <= 1e-9 {
                    return Err(format!("joint `{}`: axis {:?} is not a direction", j.name, j.axis.xyz.0));
                }
                passives.push(PassiveJoint { name: j.name.clone(), master, multiplier: k, offset: off, body: p.body });
                // At most 1 deg a step over the range it turns through.
                let range = (k * (hi - lo)).abs();
                let samples = ((range.to_degrees()).ceil() as usize + 1).clamp(2, 721);
                let at = |t: f64| k * (lo + t * (hi - lo)) + off;
                let swept = (0..samples)
                    .map(|s| {
                        let t = s as f64 / (samples - 1) as f64;
                        let parent = p.swept[((t * (p.swept.len() - 1) as f64).round() as usize).min(p.swept.len() - 1)];
                        parent * turned(at(t))
                    })
                    .collect();
                let mut sweeps = p.sweeps.clone();
                sweeps.push(Sweep { origin: (p.zero * origin).translation.vector, step: range / (samples - 1) as f64 });
                Placed { link: child, body: p.body, zero: p.zero * turned(off), swept, sweeps }
            } else {
                let body = if actuated(j) { (p.body + 1).min(JOINTS) } else { p.body };
                Placed {
                    link: child,
                    body,
                    zero: p.zero * origin,
                    swept: p.swept.iter().map(|s| s * origin).collect(),
                    sweeps: p.sweeps.clone(),
                }
            };
            stack.push(next);
        }
        out.push(p);
    }
    Ok((out, passives))
}

/// What the links' geometry and masses became.
pub(super) struct Bodies {
    /// Mass and centre of mass per MDH frame 1..6 (frame i's link i).
    pub inertials: [Inertial; JOINTS],
    /// The capsules per MDH frame (`None`: no geometry calsim could use).
    pub capsules: Option<LinkCapsules>,
    /// Collision elements left out, by link, with the reason.
    pub skipped: Vec<String>,
    /// Mesh files read, and their vertices.
    pub meshes: Vec<(String, usize)>,
    /// The passive joints met.
    pub passive: Vec<PassiveJoint>,
    /// Links whose visual geometry stood in for missing collision geometry.
    pub from_visual: Vec<String>,
}

/// Masses and collision capsules of every body, in the MDH frames `frames` ({0}..{6} in the root
/// frame at the zero configuration, m); mesh files resolved from the URDF's folder `urdf_dir` and
/// the options.
pub(super) fn bodies(
    robot: &urdf_rs::Robot,
    chain: &Chain,
    frames: &[Isometry3<f64>; JOINTS + 1],
    urdf_dir: &Path,
    options: &ImportOptions,
) -> Result<Bodies, String> {
    let (placed, passive) = place(robot, chain)?;
    let inertials = inertials(&placed, frames)?;
    let mut caps: LinkCapsules = Default::default();
    // Mesh vertices per body (mm, MDH frame) and the radius each needs for its sweep's sagitta.
    let mut clouds: [Vec<Vector3<f64>>; JOINTS + 1] = Default::default();
    let mut margins = [0.0f64; JOINTS + 1];
    let mut skipped = Vec::new();
    let mut meshes: Vec<(String, usize)> = Vec::new();
    let mut cache: HashMap<std::path::PathBuf, Vec<Vector3<f64>>> = HashMap::new();
    let mut from_visual = Vec::new();
    for p in &placed {
        let visual_stand_in = options.visual_fallback && p.link.collision.is_empty() && !p.link.visual.is_empty();
        let elements: Vec<(&urdf_rs::Pose, &urdf_rs::Geometry)> = if visual_stand_in {
            from_visual.push(p.link.name.clone());
            p.link.visual.iter().map(|v| (&v.origin, &v.geometry)).collect()
        } else {
            p.link.collision.iter().map(|c| (&c.origin, &c.geometry)).collect()
        };
        let to_body = frames[p.body].inverse();
        let in_body = |pose: &Isometry3<f64>, local: &Vector3<f64>| (to_body * pose * Point3::from(*local)).coords * 1e3;
        for (origin, geometry) in elements {
            let at = iso(origin);
            let name = &p.link.name;
            let points: Vec<Vector3<f64>> = match geometry {
                urdf_rs::Geometry::Mesh { filename, scale } => {
                    let scale = scale.map_or([1.0; 3], |s| [s[0], s[1], s[2]]);
                    let path = match mesh::resolve(filename, urdf_dir, options.package_root.as_deref()) {
                        Ok(path) => path,
                        Err(e @ MeshError::NoPackageRoot { .. }) => {
                            skipped.push(format!("{name} (mesh {e})"));
                            continue;
                        }
                        Err(e) => return Err(format!("link `{name}`: {e}")),
                    };
                    if !cache.contains_key(&path) {
                        let v = mesh::vertices(&path, filename, scale).map_err(|e| format!("link `{name}`: {e}"))?;
                        meshes.push((path.display().to_string(), v.len()));
                        cache.insert(path.clone(), dedup(v));
                    }
                    cache[&path].iter().map(|v| at * Point3::from(*v)).map(|v| v.coords).collect()
                }
                primitive => {
                    let Some((a, b, r)) = segment(primitive) else { continue };
                    let ok = r.is_finite() && r > 0.0 && r <= 100.0;
                    if !ok {
                        return Err(format!(
                            "link `{name}`: collision shape of radius {r} m at {:?} m: needs a radius above 0 and finite points, within 100 m",
                            (p.zero * at).translation.vector
                        ));
                    }
                    let ends = [(at * Point3::from(a)).coords, (at * Point3::from(b)).coords];
                    if p.sweeps.is_empty() {
                        let (pa, pb) = (in_body(&p.zero, &ends[0]), in_body(&p.zero, &ends[1]));
                        check_points(name, &[pa, pb])?;
                        caps[p.body].push(CapsuleSpec { a: pa.into(), b: pb.into(), radius: r * 1e3 });
                        continue;
                    }
                    // A swept primitive: the capsule around its segment's positions, widened by
                    // its radius (a capsule is convex: it holds every segment between them).
                    let swept: Vec<Vector3<f64>> = p.swept.iter().flat_map(|pose| ends.iter().map(move |e| in_body(pose, e))).collect();
                    check_points(name, &swept)?;
                    let sag = sagitta(&p.sweeps, &ends.map(|e| (p.zero * Point3::from(e)).coords));
                    let c = bounding_capsule(&swept).ok_or_else(|| format!("link `{name}`: its shape gives no capsule"))?;
                    caps[p.body].push(CapsuleSpec { a: c.a.into(), b: c.b.into(), radius: c.radius + (r + sag) * 1e3 });
                    continue;
                }
            };
            let cloud: Vec<Vector3<f64>> = p.swept.iter().flat_map(|pose| points.iter().map(move |v| in_body(pose, v))).collect();
            check_points(&p.link.name, &cloud)?;
            margins[p.body] = margins[p.body]
                .max(sagitta(&p.sweeps, &points.iter().map(|v| (p.zero * Point3::from(*v)).coords).collect::<Vec<_>>()) * 1e3);
            clouds[p.body].extend(cloud);
        }
    }
    for (body, cloud) in clouds.iter().enumerate() {
        if let Some(c) = bounding_capsule(cloud) {
            caps[body].push(CapsuleSpec { a: c.a.into(), b: c.b.into(), radius: c.radius + margins[body] });
        }
    }
    let any = caps.iter().any(|c| !c.is_empty());
    Ok(Bodies { inertials, capsules: any.then_some(caps), skipped, meshes, passive, from_visual })
}

/// The segment (ends, m, in the shape's frame) and radius of a primitive shape as a capsule: a
/// cylinder, capsule or sphere as itself, a box as the capsule that encloses it (its longest edge
/// as the segment, the half-diagonal of the other two as the radius); `None` for a mesh.
fn segment(g: &urdf_rs::Geometry) -> Option<(Vector3<f64>, Vector3<f64>, f64)> {
    let seg = |half: f64, r: f64| (Vector3::new(0.0, 0.0, -half), Vector3::new(0.0, 0.0, half), r);
    match g {
        urdf_rs::Geometry::Cylinder { radius, length } | urdf_rs::Geometry::Capsule { radius, length } => Some(seg(length / 2.0, *radius)),
        urdf_rs::Geometry::Sphere { radius } => Some(seg(0.0, *radius)),
        urdf_rs::Geometry::Box { size } => {
            let h = [size[0] / 2.0, size[1] / 2.0, size[2] / 2.0];
            let k = (0..3).max_by(|&i, &j| h[i].total_cmp(&h[j])).unwrap_or(2);
            let mut e = Vector3::zeros();
            e[k] = h[k];
            Some((-e, e, h[(k + 1) % 3].hypot(h[(k + 2) % 3])))
        }
        urdf_rs::Geometry::Mesh { .. } => None,
    }
}

/// Refuses points that are not finite or lie beyond 100 m (mm given).
fn check_points(link: &str, points: &[Vector3<f64>]) -> Result<(), String> {
    match points.iter().find(|p| !p.iter().all(|v| v.is_finite() && v.abs() <= 1e5)) {
        Some(p) => Err(format!("link `{link}`: collision geometry at {:?} mm: finite points within 100 m", p.as_slice())),
        None => Ok(()),
    }
}

/// How far a sampled sweep's chords can fall inside the arcs the points (root frame, m, at the
/// zero configuration) travel: `R (1 - cos(step / 2))` per passive joint, R the farthest point's
/// distance from it, summed over the joints on the path; m.
fn sagitta(sweeps: &[Sweep], points: &[Vector3<f64>]) -> f64 {
    sweeps
        .iter()
        .map(|s| {
            let reach = points.iter().map(|p| (p - s.origin).norm()).fold(0.0, f64::max);
            reach * (1.0 - (s.step / 2.0).cos())
        })
        .sum()
}

/// The distinct vertices of a mesh (STL repeats each vertex in every triangle it belongs to).
fn dedup(mut v: Vec<Vector3<f64>>) -> Vec<Vector3<f64>> {
    v.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)).then(a.z.total_cmp(&b.z)));
    v.dedup();
    v
}

/// Mass and centre of mass of each body 1..6 in its MDH frame: the masses of all its links
/// (fixed and passive ones at the zero configuration) and their mass-weighted centre; a body
/// without mass gets its centre at its frame's origin, not wherever its link frames happen to be.
fn inertials(placed: &[Placed], frames: &[Isometry3<f64>; JOINTS + 1]) -> Result<[Inertial; JOINTS], String> {
    let mut mass = [0.0f64; JOINTS + 1];
    let mut moment = [Vector3::zeros(); JOINTS + 1];
    for p in placed {
        let m = p.link.inertial.mass.value;
        let xyz = p.link.inertial.origin.xyz.0;
        if !(m.is_finite() && (0.0..=1e4).contains(&m)) {
            return Err(format!("link `{}`: mass {m} kg: a finite mass within [0, 10,000] kg", p.link.name));
        }
        if !xyz.iter().all(|v| v.is_finite() && v.abs() <= 100.0) {
            return Err(format!("link `{}`: inertial origin {xyz:?} m: finite numbers within +-100", p.link.name));
        }
        if m > 0.0 {
            let com = (frames[p.body].inverse() * p.zero * Point3::from(Vector3::from(xyz))).coords * 1e3;
            mass[p.body] += m;
            moment[p.body] += com * m;
        }
    }
    Ok(std::array::from_fn(|i| {
        let b = i + 1;
        if mass[b] > 0.0 { Inertial { mass_kg: mass[b], com_mm: moment[b] / mass[b] } } else { Inertial::NONE }
    }))
}
