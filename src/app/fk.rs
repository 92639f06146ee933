//! `fk`: the tool frame, gravity torques and joint deflections of a robot file's arm at each row of
//! a joints CSV (header `q1_deg,...,q6_deg`).

use std::path::PathBuf;

use super::Error;
use crate::robot::file::RobotFile;
use crate::robot::fk;

/// What `fk` is asked.
#[derive(Clone, Debug)]
pub struct FkSpec {
    /// The arm: a robot file.
    pub robot: PathBuf,
    /// The joint values (CSV).
    pub joints: PathBuf,
    /// The output CSV (`None`: the report carries the text).
    pub out: Option<PathBuf>,
}

/// What `fk` did.
#[derive(Clone, Debug)]
pub struct FkReport {
    /// The CSV text (written to `out` when one was given).
    pub csv: String,
    /// Rows computed.
    pub rows: usize,
}

/// `fk`: the output is vetted before anything is read ([`crate::io::out_dir::vet_file`]), then the
/// robot file and the joints are read and the rows written.
pub fn run(spec: &FkSpec) -> Result<FkReport, Error> {
    let _inputs = crate::io::inputs::Ledger::open();
    if let Some(out) = &spec.out {
        crate::io::out_dir::vet_file(out, &[&spec.robot, &spec.joints])?;
    }
    let file = RobotFile::load(&spec.robot)?;
    let joints = fk::read_joints(&spec.joints)?;
    let csv = fk::to_csv(&fk::fk_rows(&file, &joints));
    if let Some(out) = &spec.out {
        crate::io::out_dir::write_output_file("--out", out, csv.as_bytes())?;
    }
    Ok(FkReport { csv, rows: joints.len() })
}
