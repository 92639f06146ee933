//! `import-urdf`: a URDF arm (a serial chain of six revolute joints, passive joints followed or
//! folded) as a calsim robot file, with collision capsules fitted to its shapes and meshes.

use std::path::{Path, PathBuf};

use super::Error;
pub use crate::robot::urdf::ImportOptions;

/// What an import wrote.
pub struct Imported {
    /// The conversion and the text written.
    pub report: crate::robot::urdf::ImportReport,
    /// The lines that say what became of the geometry, masses, meshes and passive joints.
    pub lines: Vec<String>,
    /// The robot file written.
    pub out: PathBuf,
}

/// Converts `urdf` into the robot file `out`; nothing is written unless calsim can load the
/// result and it reproduces the converted arm. `out` is vetted first: never the URDF, a device or
/// a pipe, nor a file inside other results.
pub fn run(urdf: &Path, out: &Path, options: &ImportOptions) -> Result<Imported, Error> {
    let _inputs = crate::io::inputs::Ledger::open();
    crate::io::out_dir::vet_file(out, &[urdf])?;
    let report = crate::robot::urdf::import(urdf, out, options)?;
    let lines = report.lines(urdf, out);
    Ok(Imported { report, lines, out: out.to_path_buf() })
}
