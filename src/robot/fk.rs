//! `calsim fk`: an arm's forward kinematics and statics at given joints, row by row: the tool frame
//! in {W} (the TCP with the flange's orientation, the frame `calsim compensate` takes targets in),
//! the gravity holding torques and the joint deflections they cause.
//!
//! Joints in: a CSV file with the header `q1_deg,...,q6_deg`, one configuration a row (joint values
//! in the controller's convention, as the robot file's limits). Out: per row the joints, the tool
//! frame (`x_mm,y_mm,z_mm,alpha_deg,beta_deg,gamma_deg`, eq. 7 as `compensate`'s targets), the
//! torques `tau1_nm..tau6_nm` (sign as [`crate::robot::kinematics::statics`]), the deflections
//! `deflection1_mdeg..deflection6_mdeg` (`c_i tau_i`) and whether the joints are within the limits.

use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Translation3};

use super::file::RobotFile;
use super::kinematics::KinState;
use super::model::{JOINTS, Joints, XyzZyx};

/// Most rows a joints file takes.
pub const MAX_ROWS: usize = 1_000_000;

/// Largest joint value a joints file takes, deg (three turns).
const MOST_DEG: f64 = 1080.0;

/// The columns of a joints file.
pub const JOINT_COLUMNS: [&str; JOINTS] = ["q1_deg", "q2_deg", "q3_deg", "q4_deg", "q5_deg", "q6_deg"];

/// Why a joints file cannot be used: the file, and the line and column where that applies.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum JointsCsvError {
    /// The file cannot be read.
    #[error("{path}: {reason}")]
    File {
        /// The file.
        path: PathBuf,
        /// What the reader said.
        reason: String,
    },
    /// The header is not `q1_deg,...,q6_deg`.
    #[error("{path}: line 1: header {found:?}: expected {}", JOINT_COLUMNS.join(","))]
    Header {
        /// The file.
        path: PathBuf,
        /// The header found.
        found: String,
    },
    /// A row has another number of fields than the header.
    #[error("{path}: line {line}: {fields} fields, expected {JOINTS}")]
    Fields {
        /// The file.
        path: PathBuf,
        /// Line, 1-based.
        line: u64,
        /// Fields found.
        fields: usize,
    },
    /// A value is not a finite joint value.
    #[error("{path}: line {line}, column {column} ({name}): {value:?}: {reason}")]
    Value {
        /// The file.
        path: PathBuf,
        /// Line, 1-based.
        line: u64,
        /// Column, 1-based.
        column: usize,
        /// The column's name.
        name: &'static str,
        /// The field as written.
        value: String,
        /// What is wrong.
        reason: String,
    },
    /// The file holds no row, or too many.
    #[error("{path}: {reason}")]
    Rows {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
}

/// The 1-based line of a record at `pos` of `bytes` (counted by `lines`: the csv crate's own line
/// count misses the line break of a CRLF header); 0 without a position.
pub(crate) fn line_at(lines: &mut crate::io::Lines, bytes: &[u8], pos: Option<&csv::Position>) -> u64 {
    pos.map_or(0, |p| lines.line_at(bytes, p.byte()))
}

/// Reads the joint values (rad) of `path`.
pub fn read_joints(path: &Path) -> Result<Vec<Joints>, JointsCsvError> {
    let p = || path.to_path_buf();
    let file_error = |e: &dyn std::fmt::Display| JointsCsvError::File { path: p(), reason: e.to_string() };
    let bytes = crate::io::read_bytes_at_most(path, crate::io::MOST_CSV_BYTES).map_err(|e| file_error(&e))?;
    let mut r = csv::ReaderBuilder::new().trim(csv::Trim::All).flexible(true).from_reader(bytes.as_slice());
    let header: Vec<String> = r.headers().map_err(|e| file_error(&e))?.iter().map(str::to_string).collect();
    if header != JOINT_COLUMNS {
        return Err(JointsCsvError::Header { path: p(), found: header.join(",") });
    }
    let mut out = Vec::new();
    let mut lines = crate::io::Lines::default();
    for rec in r.records() {
        let rec = rec.map_err(|e| file_error(&e))?;
        let line = line_at(&mut lines, &bytes, rec.position());
        if out.len() == MAX_ROWS {
            return Err(JointsCsvError::Rows { path: p(), reason: format!("more than {MAX_ROWS} rows") });
        }
        if rec.len() != JOINTS {
            return Err(JointsCsvError::Fields { path: p(), line, fields: rec.len() });
        }
        let mut q = [0.0; JOINTS];
        for (k, field) in rec.iter().enumerate() {
            let bad = |reason: &str| JointsCsvError::Value {
                path: p(),
                line,
                column: k + 1,
                name: JOINT_COLUMNS[k],
                value: field.to_string(),
                reason: reason.to_string(),
            };
            let v: f64 = field.parse().map_err(|_| bad("not a number"))?;
            if !(v.is_finite() && v.abs() <= MOST_DEG) {
                return Err(bad(&format!("a finite joint value within +-{MOST_DEG} deg")));
            }
            q[k] = v.to_radians();
        }
        out.push(q);
    }
    if out.is_empty() {
        return Err(JointsCsvError::Rows { path: p(), reason: "no rows".into() });
    }
    Ok(out)
}

/// The arm's state at one configuration.
#[derive(Clone, Debug, PartialEq)]
pub struct FkRow {
    /// Joint values, rad.
    pub q: Joints,
    /// `world_from_tool`: the TCP with the flange's orientation, in {W} (eq. 7), deflected.
    pub tool: XyzZyx,
    /// Gravity holding torques, N m.
    pub torque_nm: Joints,
    /// Joint deflections `c_i tau_i`, rad.
    pub deflection_rad: Joints,
    /// Whether every joint is within its limits.
    pub within_limits: bool,
}

/// The tool frame of `model` in the last evaluation of `st` (see [`FkRow::tool`]).
fn tool_frame(file: &RobotFile, st: &KinState, model: &super::RobotModel) -> Isometry3<f64> {
    let world_from_flange = super::kinematics::world_from_base(model) * st.base_from_frame(JOINTS);
    let rotation = file.flange.as_ref().map_or(world_from_flange.rotation, |r| world_from_flange.rotation * super::rotation::quaternion(r));
    Isometry3::from_parts(Translation3::from(st.tcp_world()), rotation)
}

/// The rows of the nominal arm of `file` at each of `joints`.
pub fn fk_rows(file: &RobotFile, joints: &[Joints]) -> Vec<FkRow> {
    let model = &file.nominal;
    let mut st = KinState::default();
    joints
        .iter()
        .map(|q_row| {
            // The rows are the controller's values: the robot file's [[coupling]] turns them into
            // the model's joint angles.
            let q_model = file.coupling.as_ref().map_or(*q_row, |c| c.model_from_controller(q_row));
            let q = &q_model;
            super::kinematics::forward(model, &mut st, q);
            let offsets: Joints = std::array::from_fn(|i| q[i] + model.links()[i].theta_offset);
            FkRow {
                q: *q_row,
                tool: XyzZyx::from_isometry(&tool_frame(file, &st, model)),
                torque_nm: st.tau,
                deflection_rad: std::array::from_fn(|i| st.theta()[i] - offsets[i]),
                within_limits: model.within_limits(q),
            }
        })
        .collect()
}
