//! What a user does with a calibration: the joint targets that put the real TCP on each target,
//! from the identified model with its compliance (inverse kinematics refined by Newton's method on
//! the full model), and, for a controller that only knows its nominal model, the Cartesian targets
//! to command instead (the nominal model's TCP pose at those joint values).
//!
//! Targets: a CSV file with the header `x_mm,y_mm,z_mm,alpha_deg,beta_deg,gamma_deg`, the tool
//! frame in {W} (eq. 7: translation, then rotations about z, y and x): the TCP position with the
//! flange's orientation, the flange being the robot file's `flange_rpy_deg` frame in MDH frame 6
//! (frame 6 itself where the file has none; a URDF's `tool0`). Out: per target the joint values in
//! degrees, the model's position and orientation errors at them, and the corrected Cartesian
//! target (in the same tool frame) when a nominal model is given.
//!
//! [`run`] is the command: outputs vetted, both robot files loaded, the nominal checked to be the
//! same arm as the model, the targets compensated and written. A target the model cannot reach
//! gets a row of `unreachable`; the report counts them and the command's exit code says so (1 when
//! some are unreachable, an error when none can be reached: nothing is written then).

use std::path::{Path, PathBuf};

use super::Error;

use nalgebra::{Isometry3, Matrix3, Translation3};
use polars::prelude::Column;

use crate::io::table::{CsvFormat, FieldFormat, Frame};
use crate::robot::file::RobotFile;
use crate::robot::fk::JOINT_COLUMNS;
use crate::robot::ik::pose_error;
use crate::robot::{JOINTS, Joints, KinState, RobotModel, XyzZyx, inverse, world_from_flange};

/// The columns of a targets file.
pub const TARGET_COLUMNS: [&str; 6] = ["x_mm", "y_mm", "z_mm", "alpha_deg", "beta_deg", "gamma_deg"];

/// Most targets a file takes.
pub const MAX_TARGETS: usize = 1_000_000;

/// Reads the targets of `path`; an error names the file, the line and the column.
pub fn read_targets(path: &Path) -> Result<Vec<Isometry3<f64>>, Error> {
    let at = |line: u64, what: String| Error::input(format!("{}: line {line}", path.display()), what);
    let bytes = crate::io::read_bytes_at_most(path, crate::io::MOST_CSV_BYTES).map_err(Error::io(path))?;
    let mut r = csv::ReaderBuilder::new().trim(csv::Trim::All).from_reader(bytes.as_slice());
    let header: Vec<String> = r.headers().map_err(|e| at(1, e.to_string()))?.iter().map(str::to_string).collect();
    if header != TARGET_COLUMNS {
        return Err(at(1, format!("header {:?}: expected {}", header.join(","), TARGET_COLUMNS.join(","))));
    }
    let mut out = Vec::new();
    let mut lines = crate::io::Lines::default();
    for rec in r.records() {
        let rec = rec.map_err(|e| at(crate::robot::fk::line_at(&mut lines, &bytes, e.position()), e.to_string()))?;
        let line = crate::robot::fk::line_at(&mut lines, &bytes, rec.position());
        if out.len() == MAX_TARGETS {
            return Err(at(line, format!("more than {MAX_TARGETS} targets")));
        }
        let mut v = [0.0; 6];
        for (k, (field, name)) in rec.iter().zip(TARGET_COLUMNS).enumerate() {
            let x: f64 = field.parse().map_err(|_| at(line, format!("{name} = {field:?}: not a number")))?;
            let limit = if k < 3 { 1e5 } else { 360.0 };
            if !(x.is_finite() && x.abs() <= limit) {
                return Err(at(line, format!("{name} = {field}: a finite number within +-{limit}")));
            }
            v[k] = x;
        }
        out.push(XyzZyx::from_mm_deg(v).isometry());
    }
    if out.is_empty() {
        return Err(Error::input(path.display().to_string(), "no targets"));
    }
    Ok(out)
}

/// What `compensate` is asked.
#[derive(Clone, Debug)]
pub struct CompensateSpec {
    /// The calibrated model: a robot file.
    pub model: PathBuf,
    /// The TCP targets (CSV).
    pub targets: PathBuf,
    /// The controller's nominal model, for the corrected Cartesian targets.
    pub nominal: Option<PathBuf>,
    /// The output CSV (`None`: the report carries the text).
    pub out: Option<PathBuf>,
}

/// What `compensate` did.
#[derive(Clone, Debug)]
pub struct CompensateReport {
    /// The table, a row per target (columns in [`frame`]).
    pub table: Frame,
    /// The CSV text of the table (written to `out` when one was given).
    pub csv: String,
    /// Targets read.
    pub targets: usize,
    /// Targets the model cannot reach, 1-based in file order.
    pub unreachable: Vec<usize>,
}

impl CompensateReport {
    /// The line that says how many targets cannot be reached (`None`: every one can).
    pub fn unreachable_line(&self) -> Option<String> {
        if self.unreachable.is_empty() {
            return None;
        }
        let mut shown: Vec<String> = self.unreachable.iter().take(10).map(usize::to_string).collect();
        if self.unreachable.len() > 10 {
            shown.push(format!("and {} more", self.unreachable.len() - 10));
        }
        Some(format!(
            "{} of {} targets cannot be reached by the model (targets {}; their rows say `unreachable`)",
            self.unreachable.len(),
            self.targets,
            shown.join(", ")
        ))
    }
}

/// Largest difference of a length (mm) and of an angle (deg) between a calibrated model and its
/// nominal: a calibration moves a length by well under a millimetre and an angle by a fraction of
/// a degree; ten and five times the largest of those is another arm (ASSUMED).
const SAME_ARM_MM: f64 = 10.0;
/// See [`SAME_ARM_MM`].
const SAME_ARM_DEG: f64 = 5.0;

/// Refuses a `nominal` that is not the nominal model of the arm of `model`: every modified-DH
/// value of each joint within [`SAME_ARM_MM`] or [`SAME_ARM_DEG`] of the model's. The error names
/// both files and the key.
pub fn same_arm(model: &RobotFile, nominal: &RobotFile) -> Result<(), Error> {
    let (m, n) = (model.nominal.data(), nominal.nominal.data());
    for (i, (a, b)) in m.links.iter().zip(&n.links).enumerate() {
        let values = [
            ("alpha_deg", a.alpha.to_degrees(), b.alpha.to_degrees(), SAME_ARM_DEG),
            ("a_mm", a.a, b.a, SAME_ARM_MM),
            ("beta_deg", a.beta.to_degrees(), b.beta.to_degrees(), SAME_ARM_DEG),
            ("theta_offset_deg", a.theta_offset.to_degrees(), b.theta_offset.to_degrees(), SAME_ARM_DEG),
            ("d_mm", a.d, b.d, SAME_ARM_MM),
        ];
        for (key, x, y, most) in values {
            if (x - y).abs() > most {
                return Err(Error::input(
                    format!("--nominal {}", nominal.path.display()),
                    format!(
                        "joint[{}].{key} = {y} against {x} in {}: not the nominal model of this arm (a calibration moves a \
                         length by less than {SAME_ARM_MM} mm and an angle by less than {SAME_ARM_DEG} deg)",
                        i + 1,
                        model.path.display()
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// The length of the arm of `model`: the sum of its link lengths and offsets and its tool, mm
/// (no point of the arm is farther than this from its base).
fn arm_length_mm(model: &RobotModel) -> f64 {
    let d = model.data();
    d.links.iter().map(|l| l.a.abs() + l.d.abs()).sum::<f64>() + d.flange_tcp_mm.norm()
}

/// `compensate`: the joint targets (and, with a nominal model, the corrected Cartesian targets)
/// for the targets of `spec`, written to `spec.out`. The output is vetted before anything is read
/// ([`crate::io::out_dir::vet_file`]); when no target can be reached, nothing is written and the
/// error says how far the nearest target is.
pub fn run(spec: &CompensateSpec) -> Result<CompensateReport, Error> {
    let _inputs = crate::io::inputs::Ledger::open();
    let mut inputs: Vec<&Path> = vec![&spec.model, &spec.targets];
    inputs.extend(spec.nominal.as_deref());
    if let Some(out) = &spec.out {
        crate::io::out_dir::vet_file(out, &inputs)?;
    }
    let model = RobotFile::load(&spec.model)?;
    let nominal = spec.nominal.as_deref().map(RobotFile::load).transpose()?;
    if let Some(n) = &nominal {
        same_arm(&model, n)?;
    }
    let targets = read_targets(&spec.targets)?;
    let rows = compensate(&model, nominal.as_ref(), &targets);
    let unreachable: Vec<usize> = rows.iter().enumerate().filter(|(_, r)| r.q.is_none()).map(|(k, _)| k + 1).collect();
    if unreachable.len() == rows.len() {
        let base = crate::robot::world_from_base(&model.nominal).translation.vector;
        let nearest = targets.iter().map(|t| (t.translation.vector - base).norm()).fold(f64::INFINITY, f64::min);
        return Err(Error::input(
            spec.targets.display().to_string(),
            format!(
                "none of the {} targets can be reached by the arm of {} (the nearest is {nearest:.1} mm from its base; its links \
                 add up to {:.1} mm): nothing written",
                rows.len(),
                spec.model.display(),
                arm_length_mm(&model.nominal)
            ),
        ));
    }
    let table = frame(&rows).map_err(Error::io(&spec.targets))?;
    let csv = crate::io::table::csv_text(&table, &csv_format()).map_err(Error::io(&spec.targets))?;
    if let Some(out) = &spec.out {
        crate::io::out_dir::write_output_file("--out", out, csv.as_bytes())?;
    }
    Ok(CompensateReport { table, csv, targets: rows.len(), unreachable })
}

/// One compensated target.
#[derive(Clone, Debug, PartialEq)]
pub struct Compensated {
    /// Joint values, rad (`None`: the model cannot reach the target).
    pub q: Option<Joints>,
    /// TCP position error of the model at `q`, mm.
    pub error_mm: f64,
    /// Angle between the model's tool frame at `q` and the target's, deg.
    pub error_deg: f64,
    /// The nominal model's tool frame at `q` (what to command a controller that only knows it).
    pub nominal_target: Option<XyzZyx>,
}

/// `world_from_frame6` with the frame-6 origin moved to the TCP, for a tool frame `world_from_tool`
/// on an arm whose flange is `frame6_from_flange` in frame 6: the pose [`inverse`] takes.
fn frame6_at_tcp(world_from_tool: &Isometry3<f64>, frame6_from_flange: Option<&Matrix3<f64>>) -> Isometry3<f64> {
    match frame6_from_flange {
        None => *world_from_tool,
        Some(r) => Isometry3::from_parts(
            world_from_tool.translation,
            world_from_tool.rotation * crate::robot::rotation::quaternion(&r.transpose()),
        ),
    }
}

/// The tool frame (TCP position, flange orientation) of `model` at `q` in {W}.
fn tool_frame(model: &RobotModel, frame6_from_flange: Option<&Matrix3<f64>>, st: &mut KinState, q: &Joints) -> Isometry3<f64> {
    let f = world_from_flange(model, st, q);
    let tcp = f * nalgebra::Point3::from(model.data().flange_tcp_mm);
    let rotation = frame6_from_flange.map_or(f.rotation, |r| f.rotation * crate::robot::rotation::quaternion(r));
    Isometry3::from_parts(Translation3::from(tcp.coords), rotation)
}

/// Compensates `targets` (tool frames in {W}) on the arm of `model` (its `nominal` is the
/// calibrated model, its `flange` the tool frame's orientation); each solution seeds the next.
/// With `nominal`, also the Cartesian targets to command a controller that only knows it.
pub fn compensate(model: &RobotFile, nominal: Option<&RobotFile>, targets: &[Isometry3<f64>]) -> Vec<Compensated> {
    let mut seed: Joints = [0.0, 0.3, 0.3, 0.0, 1.0, 0.0];
    let mut st = KinState::default();
    let flange = model.flange.as_ref();
    targets
        .iter()
        .map(|t| {
            let goal = frame6_at_tcp(t, flange);
            let Ok(q) = inverse(&model.nominal, &goal, &seed) else {
                return Compensated { q: None, error_mm: f64::NAN, error_deg: f64::NAN, nominal_target: None };
            };
            seed = q;
            let e = pose_error(&model.nominal, &q, &goal);
            let nominal_target = nominal.map(|n| XyzZyx::from_isometry(&tool_frame(&n.nominal, n.flange.as_ref(), &mut st, &q)));
            Compensated { q: Some(q), error_mm: e.position_mm, error_deg: e.orientation_rad.to_degrees(), nominal_target }
        })
        .collect()
}

/// The table of `rows`: the joint values `q1_deg` ... `q6_deg` (null where the model cannot reach
/// the target), the model's errors `model_error_mm` and `model_error_deg` at them (NaN there), and
/// the nominal model's tool frame `nominal_x_mm` ... `nominal_gamma_deg` (null without a nominal
/// model or a reached target).
pub fn frame(rows: &[Compensated]) -> std::io::Result<Frame> {
    let optional = |name: String, v: &dyn Fn(&Compensated) -> Option<f64>| Column::new(name.into(), rows.iter().map(v).collect::<Vec<_>>());
    let mut columns: Vec<Column> = (0..JOINTS).map(|i| optional(JOINT_COLUMNS[i].into(), &|r| r.q.map(|q| q[i].to_degrees()))).collect();
    let number = |name: &str, v: fn(&Compensated) -> f64| Column::new(name.into(), rows.iter().map(v).collect::<Vec<f64>>());
    columns.extend([number("model_error_mm", |r| r.error_mm), number("model_error_deg", |r| r.error_deg)]);
    let nominal = |r: &Compensated| {
        r.nominal_target.as_ref().map(|t| [t.x, t.y, t.z, t.alpha.to_degrees(), t.beta.to_degrees(), t.gamma.to_degrees()])
    };
    columns.extend(TARGET_COLUMNS.iter().enumerate().map(|(k, c)| optional(format!("nominal_{c}"), &|r| nominal(r).map(|v| v[k]))));
    crate::io::table::frame("compensate", columns)
}

/// How the table of [`frame`] is written as CSV: a joint value the model cannot reach as
/// `unreachable`, the model's errors in scientific notation, a missing nominal target as an empty
/// field.
pub fn csv_format() -> CsvFormat {
    CsvFormat::new(FieldFormat::decimal(""))
        .with(JOINT_COLUMNS, FieldFormat::decimal("unreachable"))
        .with(["model_error_mm", "model_error_deg"], FieldFormat::scientific(""))
}
