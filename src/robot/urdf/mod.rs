//! A URDF arm into calsim's modified-DH form: the serial chain of six revolute joints from the
//! root link (`chain`), its joint axes at the zero configuration turned into MDH frames (z along
//! each axis, x along the common normal to the next axis, or their cross product where the axes
//! meet; for parallel axes the normal through the previous frame's foot, so no beta is needed for
//! a nominal geometry), the root-to-{0} transform as the base, the tip (the last link of fixed
//! joints after joint 6) as the tool and the flange. The result is checked against the URDF's own
//! chain at 200 configurations before it is returned.
//!
//! The links and joints are checked as one tree before anything else (`graph`: names given once,
//! links defined, one root, no detached cycle).
//!
//! The links' masses, collision geometry and passive joints (`bodies`): every link belongs to the
//! body of the last actuated joint before it; each body gets the sum of its links' masses at their
//! common centre of mass, primitive shapes as capsules of the same size, and one capsule around
//! the vertices of all its meshes (STL, COLLADA, OBJ; `package://` names found under a package
//! root), passive (`<mimic>`) joints' links swept over their range.

use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Translation3, UnitQuaternion};

use super::file::LinkCapsules;
use super::model::{JOINTS, RobotModel};

mod bodies;
mod chain;
mod graph;
mod import;

pub use graph::MOST_LINKS;

pub use bodies::PassiveJoint;
pub use import::{ImportReport, import};

/// How meshes are found and used.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ImportOptions {
    /// The folder holding the packages `package://NAME/...` names (`NAME/...` under it).
    pub package_root: Option<PathBuf>,
    /// A link without `<collision>` elements takes its `<visual>` ones instead.
    pub visual_fallback: bool,
}

/// Why a URDF cannot be an arm of calsim: the file and what is wrong (joint or link named).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{path}: {message}")]
pub struct UrdfError {
    /// The file.
    pub path: String,
    /// What is wrong.
    pub message: String,
}

/// A converted URDF: the arm, its links' collision capsules, and what the conversion did with
/// the rest.
pub struct Converted {
    /// The arm, with its links' masses and centres of mass.
    pub model: RobotModel,
    /// Collision capsules per MDH frame (`None`: the URDF has no geometry calsim could use).
    pub capsules: Option<LinkCapsules>,
    /// Collision elements left out, by link, with the reason.
    pub skipped: Vec<String>,
    /// The tip link's frame (the flange) in MDH frame 6 where it is not frame 6's orientation.
    pub flange: Option<nalgebra::Matrix3<f64>>,
    /// Mesh files read and their vertex counts.
    pub meshes: Vec<(String, usize)>,
    /// Passive joints: their links' geometry followed over the mimic range, masses folded in.
    pub passive: Vec<PassiveJoint>,
    /// Links whose visual geometry stood in for missing collision geometry.
    pub from_visual: Vec<String>,
}

/// Reads `path` and converts it (see the module; meshes beside it or left out).
pub fn load(path: &Path) -> Result<RobotModel, UrdfError> {
    load_all(path, &ImportOptions::default()).map(|c| c.model)
}

/// Reads `path` and converts it with its collision geometry (see the module).
pub fn load_all(path: &Path, options: &ImportOptions) -> Result<Converted, UrdfError> {
    let shown = path.display().to_string();
    let fail = |message: String| UrdfError { path: shown.clone(), message };
    let text = crate::io::read_text(path).map_err(|e| fail(e.to_string()))?;
    // The XML parser recurses once per nested element: the shape is checked before it runs.
    crate::io::xml::check_shape(&text).map_err(|e| fail(e.to_string()))?;
    let robot = urdf_rs::read_from_string(&text).map_err(|e| fail(parser_words(&e.to_string())))?;
    let dir = path.parent().unwrap_or(Path::new("."));
    convert(&robot, dir, options).map_err(fail)
}

/// The URDF parser's error in calsim's words: on one line, without the deserializer's `custom: `
/// prefix, a repeated element named as such (`duplicate field `axis``: an element given twice
/// where the URDF takes one).
fn parser_words(message: &str) -> String {
    let m = message.trim().strip_prefix("custom: ").unwrap_or(message.trim());
    let m = match m.strip_prefix("duplicate field ") {
        Some(name) => format!("<{}> given twice in one element, where the URDF takes one", name.trim_matches('`')),
        None => m.to_string(),
    };
    crate::io::names::escape_controls(&m)
}

/// Converts a parsed URDF (see the module), its mesh files named relative to `urdf_dir`: its links
/// and joints are checked as one tree first (`graph`).
pub fn convert(robot: &urdf_rs::Robot, urdf_dir: &Path, options: &ImportOptions) -> Result<Converted, String> {
    let tree = graph::tree(robot)?;
    let chain = chain::walk(&tree)?;
    let tip = chain.tip.translation.vector;
    let (model, frames) = chain::from_axes(&robot.name, &chain.axes, &tip)?;
    chain::check(&model, &chain.axes, &tip)?;
    let b = bodies::bodies(robot, &chain, &frames, urdf_dir, options)?;
    let model = model.edited(|d| d.links_inertial = b.inertials).map_err(|e| e.to_string())?;
    // The tip's orientation in frame 6: where the URDF's last axis points into the arm, frame 6's z
    // does too, and the flange (the tip) is turned from it.
    let r = (frames[JOINTS].rotation.inverse() * chain.tip.rotation).to_rotation_matrix().into_inner();
    let flange = ((r - nalgebra::Matrix3::identity()).amax() > 1e-12).then_some(r);
    Ok(Converted {
        model,
        capsules: b.capsules,
        skipped: b.skipped,
        flange,
        meshes: b.meshes,
        passive: b.passive,
        from_visual: b.from_visual,
    })
}

/// The rigid transform of a URDF origin (`xyz` m, `rpy` rad about fixed x, y, z).
pub(super) fn iso(p: &urdf_rs::Pose) -> Isometry3<f64> {
    let (x, y, z) = (p.xyz[0], p.xyz[1], p.xyz[2]);
    Isometry3::from_parts(Translation3::new(x, y, z), UnitQuaternion::from_euler_angles(p.rpy[0], p.rpy[1], p.rpy[2]))
}
