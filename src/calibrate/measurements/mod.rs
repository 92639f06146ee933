//! Measured data in: the CSV layout of `calsim calibrate` (documented in `docs/calibrate.md`).
//!
//! One row per measured target position: the pose it was measured at (label), the session (a
//! placement of the measuring instrument, each with its own frame), the target (an SMR or probe
//! on the flange, each with its own position in the flange frame), the controller's six joint
//! values and the target's position in the session's frame. Units are in the column names
//! (`q1_deg` or `q1_rad`, `x_mm`, `x_m` or `x_um`); an optional `sigma_<unit>` column gives each
//! point's standard uncertainty per coordinate; optional `quat_w,quat_x,quat_y,quat_z` columns
//! (an instrument's orientation reading, with an optional `sigma_deg` or `sigma_rad` column of its
//! uncertainty) are checked and carried on each point (the fit uses positions only); an optional `split` column
//! (`train` or `holdout`, the same for every row of a pose) fixes the held-out poses. Comment lines before the
//! column names may carry header keys (`# joints = controller`, `# targets = A, B`, `# frame =
//! ...`, `# simulated = true`, `# robot = ...`, `# format = calsim-measurements-1`).
//!
//! Every error names the file, the line and the column (or the header key) and what is wrong.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use nalgebra::Vector3;
use rayon::prelude::*;

pub mod file;
mod header;
mod layout;

pub use header::{Header, JointValues};
use layout::{Layout, Row};

use crate::robot::coupling::JointCoupling;
use crate::robot::file::RobotFile;
use crate::robot::{JOINTS, Joints};

/// The layout's name and version, as a file may give it in `# format = ...`.
pub const FORMAT: &str = "calsim-measurements-1";
/// Fewest poses of a session: its base has 6 unknowns, and every training set of a 5-fold
/// cross-validation keeps 4 of 5 poses (12 coordinates or more).
pub const MIN_POSES_PER_SESSION: usize = 5;
/// Fewest points of a target: its position in the flange frame has 3 unknowns (the same
/// reasoning as for sessions).
pub const MIN_POINTS_PER_TARGET: usize = 5;
/// Most rows a file takes (within the CSV inputs' cap, `io::MOST_CSV_BYTES`).
pub const MAX_ROWS: usize = 1_000_000;

/// Records read before their fields are parsed side by side ([`parse`]).
const PARSE_BATCH: usize = 4096;
/// Joint values of two rows of one pose agree to this, rad (well below any encoder's resolution).
const SAME_POSE_RAD: f64 = 1e-9;

/// A measurement file that cannot be used: the file, where, and what is wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{}: {}{}", .path.display(), location(*.line, .column), .message)]
pub struct MeasurementError {
    /// The file.
    pub path: PathBuf,
    /// Line in the file, 1-based (`None`: the file as a whole).
    pub line: Option<u64>,
    /// The column or header key.
    pub column: Option<String>,
    /// What is wrong.
    pub message: String,
}

fn location(line: Option<u64>, column: &Option<String>) -> String {
    let mut s = String::new();
    if let Some(l) = line {
        s.push_str(&format!("line {l}: "));
    }
    if let Some(c) = column {
        s.push_str(&format!("{c}: "));
    }
    s
}

/// One measured pose: the joint values of one stop of the robot in one session.
#[derive(Clone, Debug, PartialEq)]
pub struct Pose {
    /// The file's label of the pose.
    pub label: String,
    /// Index into [`Measurements::sessions`].
    pub session: usize,
    /// The joint values as the file gives them (controller's or model's), rad.
    pub q_file: Joints,
    /// The model's joint angles (after the coupling), rad.
    pub q: Joints,
    /// The first line of the pose.
    pub line: u64,
    /// The file's split column for this pose: held out (`None`: the file has no split column).
    pub held_out: Option<bool>,
}

/// One measured target position.
#[derive(Clone, Debug, PartialEq)]
pub struct Point {
    /// Line in the file.
    pub line: u64,
    /// Index into [`Measurements::poses`].
    pub pose: usize,
    /// Index into [`Measurements::targets`].
    pub target: usize,
    /// The position in the session's measuring frame, mm.
    pub measured_mm: Vector3<f64>,
    /// Standard uncertainty per coordinate, mm (`None`: the file gives none; all points alike).
    pub sigma_mm: Option<f64>,
    /// The orientation reading of a six-degree-of-freedom probe: the probe's frame in the
    /// session's frame (`None`: the file has no `quat_*` columns).
    pub orientation: Option<nalgebra::UnitQuaternion<f64>>,
    /// The orientation's standard uncertainty, rad (`None`: the file gives none).
    pub sigma_rad: Option<f64>,
}

/// A checked measurement file.
#[derive(Clone, Debug, PartialEq)]
pub struct Measurements {
    /// The file.
    pub path: PathBuf,
    /// Its header keys.
    pub header: Header,
    /// Session labels, in order of first appearance.
    pub sessions: Vec<String>,
    /// Target labels, in order of first appearance.
    pub targets: Vec<String>,
    /// Poses, in order of first appearance.
    pub poses: Vec<Pose>,
    /// Points, in file order.
    pub points: Vec<Point>,
    /// Rows left out because their target is not among `# targets`.
    pub rows_left_out: usize,
    /// The coupling was applied to the joint columns.
    pub coupled: bool,
    /// The file has a split column (`train` or `holdout` per pose).
    pub split_column: bool,
    /// The file has orientation columns (`quat_w` .. `quat_z`): each reading adds three rotation
    /// residuals to the fit.
    pub orientation_columns: bool,
}

/// Reads and checks the measurement file `path` for the arm of `robot` (its joint limits, and its
/// coupling unless the file says `# joints = model`).
pub fn read(path: &Path, robot: &RobotFile) -> Result<Measurements, MeasurementError> {
    let fail = |line: Option<u64>, message: String| MeasurementError { path: path.into(), line, column: None, message };
    let bytes = crate::io::read_own(path, crate::io::MOST_CSV_BYTES).map_err(|e| fail(None, e.to_string()))?;
    // The file is read as `io::read_bytes_at_most` reads it; it is recorded as an input (its
    // sha256, on this thread: the ledger's) while it is parsed on another.
    let checked = || {
        let text = std::str::from_utf8(&bytes).map_err(|e| {
            let line = bytes[..e.valid_up_to()].iter().filter(|b| **b == b'\n').count() as u64 + 1;
            fail(Some(line), "not UTF-8 text".into())
        })?;
        parse(path, text, robot)
    };
    std::thread::scope(|scope| {
        let parsing = scope.spawn(checked);
        crate::io::inputs::record(path, &bytes);
        parsing.join().unwrap_or_else(|panic| std::panic::resume_unwind(panic))
    })
}

/// Checks the text of a measurement file as [`read`] checks a file (`path` is named in errors).
pub fn parse(path: &Path, text: &str, robot: &RobotFile) -> Result<Measurements, MeasurementError> {
    let fail = |line: Option<u64>, column: Option<&str>, message: String| MeasurementError {
        path: path.into(),
        line,
        column: column.map(str::to_string),
        message,
    };
    let (header, header_line, keys) = header::read(text).map_err(|(line, key, msg)| fail(line, key.as_deref(), msg))?;
    let mut reader = csv::ReaderBuilder::new().comment(Some(b'#')).trim(csv::Trim::All).from_reader(text.as_bytes());
    let names: Vec<String> =
        reader.headers().map_err(|e| fail(Some(header_line), None, e.to_string()))?.iter().map(str::to_string).collect();
    let layout = Layout::new(names).map_err(|(col, msg)| fail(Some(header_line), Some(&col), msg))?;
    let coupling = match header.joints {
        JointValues::Controller => robot.coupling.as_ref(),
        JointValues::Model => None,
    };
    let mut m = Measurements {
        path: path.into(),
        header,
        sessions: Vec::new(),
        targets: Vec::new(),
        poses: Vec::new(),
        points: Vec::new(),
        rows_left_out: 0,
        coupled: coupling.is_some(),
        split_column: layout.has_split(),
        orientation_columns: layout.has_orientation(),
    };
    let mut index = Index::default();
    let joints = JointReader { layout: &layout, robot, coupling };
    let mut records = reader.records();
    loop {
        // The next records in order, up to a CSV error; their fields parsed side by side, the
        // rows then checked and added in order (the first error in the file's order is the one
        // named, as row by row).
        let mut batch: Vec<csv::StringRecord> = Vec::with_capacity(PARSE_BATCH);
        let mut broken = None;
        let mut ended = false;
        while batch.len() < PARSE_BATCH {
            match records.next() {
                Some(Ok(record)) => batch.push(record),
                Some(Err(e)) => {
                    broken = Some(e);
                    break;
                }
                None => {
                    ended = true;
                    break;
                }
            }
        }
        let rows: Vec<Result<Row, (String, String)>> = batch.par_iter().map(|record| Row::parse(record, &layout)).collect();
        for (record, row) in batch.iter().zip(rows) {
            let line = record.position().map_or(0, |p| p.line());
            if m.points.len() + m.rows_left_out >= MAX_ROWS {
                return Err(fail(Some(line), None, format!("more than {MAX_ROWS} rows")));
            }
            let row = row.map_err(|(col, msg)| fail(Some(line), Some(&col), msg))?;
            m.add(row, line, &joints, &mut index).map_err(|(col, msg)| fail(Some(line), Some(&col), msg))?;
        }
        if let Some(e) = broken {
            return Err(fail(e.position().map(|p| p.line()), None, csv_message(&e)));
        }
        if ended {
            break;
        }
    }
    if let Some(wanted) = &m.header.targets
        && let Some(absent) = wanted.iter().find(|t| !m.targets.contains(t))
    {
        return Err(fail(Some(keys.targets), Some("targets"), format!("target {absent} has no row in the file")));
    }
    if m.points.is_empty() {
        return Err(fail(None, None, "no measurements (a row per measured target position after the column names)".into()));
    }
    check_counts(&m).map_err(|(line, col, msg)| fail(Some(line), Some(col), msg))?;
    Ok(m)
}

/// The poses and points read so far, by their keys.
#[derive(Default)]
struct Index {
    /// (session, pose label) to pose.
    poses: HashMap<(usize, String), usize>,
    /// (pose, target) to the line it was measured on.
    points: HashMap<(usize, usize), u64>,
}

/// What turns a row's joint values into the model's angles and checks them.
struct JointReader<'a> {
    layout: &'a Layout,
    robot: &'a RobotFile,
    coupling: Option<&'a JointCoupling>,
}

impl Measurements {
    /// Adds the row read on `line`; an error names the column and what is wrong.
    fn add(&mut self, row: Row, line: u64, joints: &JointReader<'_>, index: &mut Index) -> Result<(), (String, String)> {
        if let Some(wanted) = &self.header.targets
            && !wanted.contains(&row.target)
        {
            self.rows_left_out += 1;
            return Ok(());
        }
        let session = index_of(&mut self.sessions, &row.session);
        let target = index_of(&mut self.targets, &row.target);
        let pose = match index.poses.get(&(session, row.pose.clone())) {
            Some(&p) => {
                let first = &self.poses[p];
                if let Some(k) = (0..JOINTS).find(|&k| (first.q_file[k] - row.q[k]).abs() > SAME_POSE_RAD) {
                    let message = format!("pose {} of session {} has other joint values on line {}", row.pose, row.session, first.line);
                    return Err((joints.layout.joint(k).to_string(), message));
                }
                if first.held_out != row.held_out {
                    let message =
                        format!("pose {} of session {} is in the other part of the split on line {}", row.pose, row.session, first.line);
                    return Err(("split".into(), message));
                }
                p
            }
            None => {
                let q = joints.coupling.map_or(row.q, |c| c.model_from_controller(&row.q));
                check_limits(joints, &q)?;
                self.poses.push(Pose { label: row.pose.clone(), session, q_file: row.q, q, line, held_out: row.held_out });
                index.poses.insert((session, row.pose.clone()), self.poses.len() - 1);
                self.poses.len() - 1
            }
        };
        if let Some(first) = index.points.insert((pose, target), line) {
            let message =
                format!("target {} of pose {} (session {}) is measured on line {first} already", row.target, row.pose, row.session);
            return Err(("target".into(), message));
        }
        self.points.push(Point {
            line,
            pose,
            target,
            measured_mm: row.xyz,
            sigma_mm: row.sigma,
            orientation: row.orientation,
            sigma_rad: row.sigma_rad,
        });
        Ok(())
    }
}

/// The message of a CSV error without the position the caller names anyway.
fn csv_message(e: &csv::Error) -> String {
    match e.kind() {
        csv::ErrorKind::UnequalLengths { expected_len, len, .. } => format!("{len} fields where the column names give {expected_len}"),
        csv::ErrorKind::Utf8 { .. } => "not UTF-8 text".into(),
        _ => e.to_string(),
    }
}

fn index_of(list: &mut Vec<String>, label: &str) -> usize {
    match list.iter().position(|l| l == label) {
        Some(i) => i,
        None => {
            list.push(label.to_string());
            list.len() - 1
        }
    }
}

/// The model's joint angles `q` within the robot's limits; an error names the file's columns the
/// offending joint is made of.
fn check_limits(joints: &JointReader<'_>, q: &Joints) -> Result<(), (String, String)> {
    for (k, (v, lim)) in q.iter().zip(joints.robot.nominal.limits()).enumerate() {
        if *v >= lim.min && *v <= lim.max {
            continue;
        }
        let inputs = joints.coupling.map_or_else(|| vec![k], |c| c.inputs_of(k));
        let cols: Vec<&str> = inputs.iter().map(|&j| joints.layout.joint(j)).collect();
        let made = if inputs == [k] { String::new() } else { format!(" (coupled: from {})", cols.join(", ")) };
        return Err((
            cols.join(", "),
            format!(
                "joint {} at {:.4} deg{made} is outside its limits [{}, {}] deg of {}",
                k + 1,
                v.to_degrees(),
                lim.min.to_degrees(),
                lim.max.to_degrees(),
                joints.robot.path.display()
            ),
        ));
    }
    Ok(())
}

/// Every session has its fewest poses and every target its fewest points; an error names the
/// first line of the offender.
fn check_counts(m: &Measurements) -> Result<(), (u64, &'static str, String)> {
    for (s, label) in m.sessions.iter().enumerate() {
        let poses: Vec<&Pose> = m.poses.iter().filter(|p| p.session == s).collect();
        if poses.len() < MIN_POSES_PER_SESSION {
            return Err((
                poses[0].line,
                "session",
                format!(
                    "session {label} has {} poses; a session needs at least {MIN_POSES_PER_SESSION} (its base has 6 unknowns, and \
                     cross-validation leaves a fifth out)",
                    poses.len()
                ),
            ));
        }
    }
    for (t, label) in m.targets.iter().enumerate() {
        let points: Vec<&Point> = m.points.iter().filter(|p| p.target == t).collect();
        if points.len() < MIN_POINTS_PER_TARGET {
            return Err((
                points[0].line,
                "target",
                format!(
                    "target {label} has {} points; a target needs at least {MIN_POINTS_PER_TARGET} (its position on the flange has 3 \
                     unknowns, and cross-validation leaves a fifth out)",
                    points.len()
                ),
            ));
        }
    }
    Ok(())
}

/// Reads a list of poses (`--hold-out-file`): CSV with the columns `session` and `pose` (in any
/// order; `#` comment lines), one pose per row; every error names the file and the line.
pub fn read_pose_list(path: &Path) -> Result<Vec<(String, String)>, MeasurementError> {
    let fail = |line: Option<u64>, column: Option<&str>, message: String| MeasurementError {
        path: path.into(),
        line,
        column: column.map(str::to_string),
        message,
    };
    let bytes = crate::io::read_bytes(path).map_err(|e| fail(None, None, e.to_string()))?;
    let text = String::from_utf8(bytes).map_err(|_| fail(None, None, "not UTF-8 text".into()))?;
    let mut reader = csv::ReaderBuilder::new().comment(Some(b'#')).trim(csv::Trim::All).from_reader(text.as_bytes());
    let names: Vec<String> = reader.headers().map_err(|e| fail(None, None, csv_message(&e)))?.iter().map(str::to_string).collect();
    let col = |want: &str| {
        names
            .iter()
            .position(|n| n == want)
            .ok_or_else(|| fail(Some(1), Some(want), "missing column (a pose list has the columns session, pose)".into()))
    };
    let (s, p) = (col("session")?, col("pose")?);
    if let Some(other) = names.iter().find(|n| *n != "session" && *n != "pose") {
        return Err(fail(Some(1), Some(other), "unknown column (a pose list has the columns session, pose)".into()));
    }
    let mut out: Vec<(String, String)> = Vec::new();
    let mut seen: std::collections::HashSet<(String, String)> = std::collections::HashSet::new();
    for record in reader.records() {
        let record = record.map_err(|e| fail(e.position().map(|p| p.line()), None, csv_message(&e)))?;
        let line = record.position().map_or(0, |p| p.line());
        let field = |k: usize, name: &str| {
            let v = record.get(k).unwrap_or("");
            if v.is_empty() || v.chars().count() > 64 || v.chars().any(char::is_control) {
                return Err(fail(Some(line), Some(name), "a label of 1 to 64 printable characters".into()));
            }
            Ok(v.to_string())
        };
        let pose = (field(s, "session")?, field(p, "pose")?);
        if !seen.insert(pose.clone()) {
            return Err(fail(Some(line), Some("pose"), format!("pose {} of session {} is listed twice", pose.1, pose.0)));
        }
        if out.len() >= MAX_ROWS {
            return Err(fail(Some(line), None, format!("more than {MAX_ROWS} poses")));
        }
        out.push(pose);
    }
    if out.is_empty() {
        return Err(fail(None, None, "no pose listed (a row `session,pose` per held-out pose)".into()));
    }
    Ok(out)
}
