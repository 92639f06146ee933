//! `import-urdf`: a URDF arm (a serial chain of six revolute joints) as a calsim robot file.

use std::path::{Path, PathBuf};

use super::Error;

/// What an import wrote.
#[derive(Clone, Debug)]
pub struct Imported {
    /// The arm's name.
    pub name: String,
    /// Per joint the modified-DH a_{i-1} and d_i, mm.
    pub a_mm: Vec<f64>,
    /// See `a_mm`.
    pub d_mm: Vec<f64>,
    /// The robot file written.
    pub out: PathBuf,
    /// Collision capsules converted from the links' shapes (`None`: the URDF has none calsim reads).
    pub capsules: Option<usize>,
    /// Collision shapes left out (meshes), named.
    pub skipped: Vec<String>,
}

/// Converts `urdf` into the robot file `out`; nothing is written unless calsim can load the
/// result.
pub fn run(urdf: &Path, out: &Path) -> Result<Imported, Error> {
    let converted = crate::robot::urdf::load_all(urdf)?;
    let model = &converted.model;
    let source = format!("converted by calsim {} from {}", env!("CARGO_PKG_VERSION"), urdf.display());
    let text = crate::robot::file::to_text(model, &source, &[], converted.capsules.as_ref(), converted.flange.as_ref());
    // The robot file must be one calsim can load: a URDF value outside its ranges is the URDF's
    // error, and nothing is written.
    crate::robot::file::RobotFile::from_text(out, &text).map_err(|e| {
        Error::input(urdf.display().to_string(), format!("the robot file it converts to cannot be used: {}: {}", e.field, e.message))
    })?;
    crate::io::out_dir::write_file_atomically(out, &text).map_err(Error::io(out))?;
    let l = &model.data().links;
    Ok(Imported {
        name: model.data().name.clone(),
        a_mm: l.iter().map(|l| l.a).collect(),
        d_mm: l.iter().map(|l| l.d).collect(),
        out: out.to_path_buf(),
        capsules: converted.capsules.as_ref().map(|c| c.iter().map(Vec::len).sum()),
        skipped: converted.skipped.clone(),
    })
}
