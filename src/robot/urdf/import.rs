//! `calsim import-urdf`: a URDF converted, checked once more as the robot file it becomes, and
//! written; the report says what became of its masses, meshes and passive joints.

use std::path::Path;

use super::{Converted, ImportOptions, UrdfError, load_all};
use crate::robot::file::{RobotFile, imported_text};
use crate::robot::model::JOINTS;

/// What an import wrote and did.
pub struct ImportReport {
    /// The conversion.
    pub converted: Converted,
    /// The robot file's text as written.
    pub text: String,
    /// Largest TCP distance between the written file's arm and the converted one over 200
    /// configurations, mm (the tidy writing moves no value by more than 1e-9 of its unit).
    pub file_difference_mm: f64,
}

/// The leading XML comment of a URDF (its provenance, where it has one), line by line.
fn preamble(text: &str) -> Vec<String> {
    let head = text.split("<robot").next().unwrap_or("");
    match (head.find("<!--"), head.find("-->")) {
        (Some(a), Some(b)) if a < b => {
            head[a + 4..b].lines().map(str::trim).filter(|l| !l.is_empty()).map(crate::io::names::escape_controls).collect()
        }
        _ => Vec::new(),
    }
}

/// Converts the URDF at `urdf` and writes it as a robot file at `out` (atomically; nothing is
/// written when the conversion or the check of the written file fails).
pub fn import(urdf: &Path, out: &Path, options: &ImportOptions) -> Result<ImportReport, UrdfError> {
    let fail = |message: String| UrdfError { path: urdf.display().to_string(), message };
    let converted = load_all(urdf, options)?;
    let urdf_text = crate::io::read_text(urdf).map_err(|e| fail(e.to_string()))?;
    let mut lines = preamble(&urdf_text);
    let mut command = format!("calsim import-urdf {}", urdf.display());
    if let Some(root) = &options.package_root {
        command.push_str(&format!(" --package-root {}", root.display()));
    }
    if options.visual_fallback {
        command.push_str(" --visual-meshes");
    }
    // Comment lines of the robot file: a path's line break would end the comment.
    lines.push(crate::io::names::escape_controls(&format!("converted by `{command} --out {}`", out.display())));
    let source = format!("converted by calsim {} from {}", env!("CARGO_PKG_VERSION"), urdf.display());
    let text = imported_text(&converted.model, &source, converted.capsules.as_ref(), converted.flange.as_ref(), &lines);
    // The robot file must be one calsim can load: a URDF value outside its ranges is the URDF's
    // error, and nothing is written.
    let file = RobotFile::from_text(out, &text)
        .map_err(|e| fail(format!("the robot file it converts to cannot be used: {}: {}", e.field, e.message)))?;
    let mut worst: f64 = 0.0;
    let (mut a, mut b) = (crate::robot::KinState::default(), crate::robot::KinState::default());
    let model = &converted.model;
    for k in 0..200 {
        let q: [f64; JOINTS] = std::array::from_fn(|i| {
            let l = model.limits()[i];
            let (lo, hi) = (l.min.max(-3.0), l.max.min(3.0));
            lo + (hi - lo) * (((k * 11 + i * 17) % 89) as f64 / 88.0)
        });
        worst = worst.max((crate::robot::forward(model, &mut a, &q) - crate::robot::forward(&file.nominal, &mut b, &q)).norm());
    }
    if worst > 1e-6 {
        return Err(fail(format!("the robot file written misses the converted arm by {worst:e} mm")));
    }
    // The output is none of the files read (the URDF, its meshes) and no device or pipe.
    let meshes: Vec<std::path::PathBuf> = converted.meshes.iter().map(|(m, _)| m.into()).collect();
    let inputs: Vec<&Path> = std::iter::once(urdf).chain(meshes.iter().map(|m| m.as_path())).collect();
    crate::io::out_dir::vet_file(out, &inputs).map_err(|e| fail(e.to_string()))?;
    crate::io::out_dir::write_output_file("--out", out, text.as_bytes()).map_err(|e| fail(e.to_string()))?;
    Ok(ImportReport { converted, text, file_difference_mm: worst })
}

impl ImportReport {
    /// The lines `calsim import-urdf` prints: the geometry, the masses, the collision capsules and
    /// where they came from, what was left out, and what became of passive joints.
    pub fn lines(&self, urdf: &Path, out: &Path) -> Vec<String> {
        let c = &self.converted;
        let d = c.model.data();
        let mut v = vec![format!(
            "{}: {} as modified DH (a_i-1 mm: {}; d_i mm: {}) to {}",
            urdf.display(),
            d.name,
            d.links.iter().map(|l| format!("{:.3}", (l.a * 1e3).round() / 1e3 + 0.0)).collect::<Vec<_>>().join(", "),
            d.links.iter().map(|l| format!("{:.3}", (l.d * 1e3).round() / 1e3 + 0.0)).collect::<Vec<_>>().join(", "),
            out.display()
        )];
        let mass: f64 = d.links_inertial.iter().map(|i| i.mass_kg).sum();
        v.push(if mass > 0.0 {
            format!("masses: {mass:.3} kg over links 1-6 (the links of each body summed at their common centre of mass)")
        } else {
            "masses: none in the URDF (gravity torques and deflections are zero until masses are given)".to_string()
        });
        for p in &c.passive {
            v.push(format!(
                "passive joint {} (mimics {} x {} {:+} rad): followed over {}'s range for link {}'s collision capsule, its links' masses folded into link {} at q = 0",
                p.name, p.master, p.multiplier, p.offset, p.master, p.body, p.body
            ));
        }
        match &c.capsules {
            Some(caps) => {
                let n: usize = caps.iter().map(Vec::len).sum();
                let verts: usize = c.meshes.iter().map(|(_, n)| n).sum();
                v.push(format!("collision: {n} capsules in MDH frames 0-{JOINTS} ({} mesh files, {verts} vertices, one bounding capsule per frame)", c.meshes.len()));
            }
            None => v.push(
                "collision: none (no shape calsim could use): pass --package-root for package:// meshes, or add [[collision]] capsules for a TriCal study"
                    .to_string(),
            ),
        }
        if !c.from_visual.is_empty() {
            v.push(format!("visual geometry stands in for collision geometry on: {}", c.from_visual.join(", ")));
        }
        if !c.skipped.is_empty() {
            v.push(format!("collision shapes left out: {}", c.skipped.join(", ")));
        }
        v
    }
}
