//! `fk`: the tool frame, gravity torques and joint deflections of a robot file's arm at each row of
//! a joints CSV (header `q1_deg,...,q6_deg`).

use std::path::PathBuf;

use polars::prelude::Column;

use super::Error;
use crate::io::table::{CsvFormat, FieldFormat, Frame};
use crate::robot::JOINTS;
use crate::robot::file::RobotFile;
use crate::robot::fk::{self, FkRow};

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
    /// The table, a row per joints row (columns in [`frame`]).
    pub table: Frame,
    /// The CSV text of the table (written to `out` when one was given).
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
    let table = frame(&fk::fk_rows(&file, &joints)).map_err(Error::io(&spec.joints))?;
    let csv = crate::io::table::csv_text(&table, &CsvFormat::new(FieldFormat::decimal("null"))).map_err(Error::io(&spec.joints))?;
    if let Some(out) = &spec.out {
        crate::io::out_dir::write_output_file("--out", out, csv.as_bytes())?;
    }
    Ok(FkReport { table, csv, rows: joints.len() })
}

/// The table of `rows`: the joint values `q1_deg` ... `q6_deg`, the tool frame `x_mm`, `y_mm`,
/// `z_mm`, `alpha_deg`, `beta_deg`, `gamma_deg` in {W}, the gravity torques `tau1_nm` ...
/// (a zero torque written `0`, never `-0`), the deflections `deflection1_mdeg` ... and
/// `within_limits`.
pub fn frame(rows: &[FkRow]) -> std::io::Result<Frame> {
    let number = |name: String, v: &dyn Fn(&FkRow) -> f64| Column::new(name.into(), rows.iter().map(v).collect::<Vec<f64>>());
    let mut columns: Vec<Column> = (0..JOINTS).map(|i| number(fk::JOINT_COLUMNS[i].into(), &|r| r.q[i].to_degrees())).collect();
    let tool: [(&str, fn(&FkRow) -> f64); 6] = [
        ("x_mm", |r| r.tool.x),
        ("y_mm", |r| r.tool.y),
        ("z_mm", |r| r.tool.z),
        ("alpha_deg", |r| r.tool.alpha.to_degrees()),
        ("beta_deg", |r| r.tool.beta.to_degrees()),
        ("gamma_deg", |r| r.tool.gamma.to_degrees()),
    ];
    columns.extend(tool.iter().map(|(name, v)| number(name.to_string(), v)));
    columns.extend((0..JOINTS).map(|i| number(format!("tau{}_nm", i + 1), &|r| r.torque_nm[i] + 0.0)));
    columns.extend((0..JOINTS).map(|i| number(format!("deflection{}_mdeg", i + 1), &|r| r.deflection_rad[i].to_degrees() * 1e3)));
    columns.push(Column::new("within_limits".into(), rows.iter().map(|r| r.within_limits).collect::<Vec<bool>>()));
    crate::io::table::frame("fk", columns)
}
