//! The columns of a measurement file (their quantities and units, from their names) and the values
//! of one row in internal units.

use nalgebra::Vector3;

use crate::robot::{JOINTS, Joints};

/// Largest coordinate or uncertainty a file takes, mm (100 m: beyond any tracker's range).
const MOST_MM: f64 = 1e5;
/// Largest controller joint value a file takes, deg (three turns).
const MOST_JOINT_DEG: f64 = 1080.0;
/// Longest label (pose, session, target), characters.
const MOST_LABEL: usize = 64;

/// What a column holds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Column {
    Pose,
    Session,
    Target,
    /// Joint k (0-based), and the factor to rad.
    Joint(usize, f64),
    /// Coordinate k (0 = x), and the factor to mm.
    Coordinate(usize, f64),
    /// Per-point uncertainty, and the factor to mm.
    Sigma(f64),
    /// Quaternion component (w, x, y, z) of an orientation reading.
    Quaternion(usize),
    /// The orientation reading's uncertainty (a rotation about any axis), and the factor to rad.
    SigmaAngle(f64),
    /// The pose's part in a fixed split: `train` or `holdout`.
    Split,
}

impl Column {
    /// The slot of the column among the layout's columns (two columns of one slot are a duplicate).
    fn slot(self) -> usize {
        match self {
            Column::Pose => 0,
            Column::Session => 1,
            Column::Target => 2,
            Column::Joint(k, _) => 3 + k,
            Column::Coordinate(k, _) => 9 + k,
            Column::Sigma(_) => 12,
            Column::Quaternion(k) => 13 + k,
            Column::Split => 17,
            Column::SigmaAngle(_) => 18,
        }
    }
}

/// The names a missing slot is asked for by.
const SLOT_NAMES: [&str; SLOTS] = [
    "pose",
    "session",
    "target",
    "q1_deg",
    "q2_deg",
    "q3_deg",
    "q4_deg",
    "q5_deg",
    "q6_deg",
    "x_mm",
    "y_mm",
    "z_mm",
    "sigma_mm",
    "quat_w",
    "quat_x",
    "quat_y",
    "quat_z",
    "split",
    "sigma_deg",
];
/// Number of quantities a file's columns can hold.
const SLOTS: usize = 19;
/// The split column's value of a pose the fit uses.
pub const TRAIN: &str = "train";
/// The split column's value of a held-out pose.
pub const HOLDOUT: &str = "holdout";

fn length_unit(unit: &str) -> Option<f64> {
    match unit {
        "mm" => Some(1.0),
        "m" => Some(1e3),
        "um" => Some(1e-3),
        _ => None,
    }
}

fn angle_unit(unit: &str) -> Option<f64> {
    match unit {
        "deg" => Some(std::f64::consts::PI / 180.0),
        "rad" => Some(1.0),
        _ => None,
    }
}

/// The column `name` holds; an error says what is wrong with the name.
fn column(name: &str) -> Result<Column, String> {
    match name {
        "pose" => return Ok(Column::Pose),
        "session" => return Ok(Column::Session),
        "target" => return Ok(Column::Target),
        "quat_w" => return Ok(Column::Quaternion(0)),
        "quat_x" => return Ok(Column::Quaternion(1)),
        "quat_y" => return Ok(Column::Quaternion(2)),
        "quat_z" => return Ok(Column::Quaternion(3)),
        "split" => return Ok(Column::Split),
        _ => {}
    }
    let (quantity, unit) = name.split_once('_').unwrap_or((name, ""));
    let joint = quantity.strip_prefix('q').and_then(|k| k.parse::<usize>().ok()).filter(|k| (1..=JOINTS).contains(k));
    let coordinate = ["x", "y", "z"].iter().position(|c| *c == quantity);
    let length = |f: &dyn Fn(f64) -> Column| {
        length_unit(unit).map(f).ok_or_else(|| {
            if unit.is_empty() {
                format!("a length column needs its unit: {quantity}_mm, {quantity}_m or {quantity}_um")
            } else {
                format!("unknown unit `{unit}` (lengths: mm, m, um)")
            }
        })
    };
    if let Some(k) = joint {
        return angle_unit(unit).map(|f| Column::Joint(k - 1, f)).ok_or_else(|| {
            if unit.is_empty() {
                format!("a joint column needs its unit: {quantity}_deg or {quantity}_rad")
            } else {
                format!("unknown unit `{unit}` (angles: deg, rad)")
            }
        });
    }
    if let Some(k) = coordinate {
        return length(&|f| Column::Coordinate(k, f));
    }
    if quantity == "sigma" {
        if let Some(f) = angle_unit(unit) {
            return Ok(Column::SigmaAngle(f));
        }
        return length(&|f| Column::Sigma(f)).map_err(|m| format!("{m}; an orientation's uncertainty: sigma_deg or sigma_rad"));
    }
    Err("unknown column (the layout's columns: pose, session, target, q1_deg..q6_deg, x_mm, y_mm, z_mm; optional sigma_mm, \
         quat_w, quat_x, quat_y, quat_z, sigma_deg and split)"
        .into())
}

/// The columns of a file: what each holds, and which column holds each quantity.
pub(super) struct Layout {
    /// The column names, as the file gives them.
    pub(super) names: Vec<String>,
    columns: Vec<Column>,
    slots: [Option<usize>; SLOTS],
}

impl Layout {
    /// The layout of the column names `names`; an error names the column and what is wrong.
    pub(super) fn new(names: Vec<String>) -> Result<Self, (String, String)> {
        let mut columns: Vec<Column> = Vec::with_capacity(names.len());
        let mut slots: [Option<usize>; SLOTS] = [None; SLOTS];
        for (i, name) in names.iter().enumerate() {
            let c = column(name).map_err(|m| (name.clone(), m))?;
            if let Some(first) = slots[c.slot()].replace(i) {
                return Err((name.clone(), format!("the same quantity as column `{}`", names[first])));
            }
            columns.push(c);
        }
        for (slot, name) in SLOT_NAMES.iter().enumerate().take(12) {
            if slots[slot].is_none() {
                return Err((
                    missing_name(slot, name, &names, &slots),
                    "missing column (the layout needs pose, session, target, q1..q6 and x, y, z, each with its unit)".into(),
                ));
            }
        }
        let quaternion = slots[13..17].iter().filter(|s| s.is_some()).count();
        if quaternion != 0 && quaternion != 4 {
            let missing = (13..17).find(|&s| slots[s].is_none()).map_or("quat_w", |s| SLOT_NAMES[s]);
            return Err((missing.to_string(), "missing column: the quaternion takes quat_w, quat_x, quat_y and quat_z".into()));
        }
        if slots[18].is_some() && quaternion == 0 {
            return Err((
                names[slots[18].unwrap_or(0)].clone(),
                "an orientation's uncertainty without the quat_w .. quat_z columns".into(),
            ));
        }
        Ok(Self { names, columns, slots })
    }

    /// The file has the orientation columns (`quat_w` .. `quat_z`).
    pub(super) fn has_orientation(&self) -> bool {
        self.slots[13].is_some()
    }

    /// The file has a split column.
    pub(super) fn has_split(&self) -> bool {
        self.slots[17].is_some()
    }

    /// The file's name of joint column `k` (0-based).
    pub(super) fn joint(&self, k: usize) -> &str {
        &self.names[self.slots[3 + k].unwrap_or(0)]
    }
}

/// The name of missing column `slot` (`standard`: its name in mm and deg) with the unit the file
/// gives its siblings (a file in metres misses `z_m`, not `z_mm`).
fn missing_name(slot: usize, standard: &str, names: &[String], slots: &[Option<usize>; SLOTS]) -> String {
    let siblings = match slot {
        3..=8 => 3..9,
        9..=11 => 9..12,
        _ => return standard.to_string(),
    };
    let quantity = standard.split_once('_').map_or(standard, |(q, _)| q);
    siblings
        .filter_map(|s| slots[s])
        .find_map(|i| names[i].split_once('_').map(|(_, unit)| format!("{quantity}_{unit}")))
        .unwrap_or_else(|| standard.to_string())
}

/// `value` as the file gives it, with the unit of column `name` where the bound it breaks is in
/// another unit (`bound_unit`): `200 m` against a bound in mm.
fn with_unit(value: &str, name: &str, bound_unit: &str) -> String {
    match name.split_once('_') {
        Some((_, unit)) if unit != bound_unit => format!("{value} {unit}"),
        _ => value.to_string(),
    }
}

/// The values of one row, in internal units.
pub(super) struct Row {
    pub(super) pose: String,
    pub(super) session: String,
    pub(super) target: String,
    /// Joint values as the file gives them, rad.
    pub(super) q: Joints,
    /// Position, mm.
    pub(super) xyz: Vector3<f64>,
    /// Uncertainty per coordinate, mm.
    pub(super) sigma: Option<f64>,
    /// The split column's value: held out (`None`: no such column).
    pub(super) held_out: Option<bool>,
    /// The orientation reading, normalised (`None`: no quaternion columns).
    pub(super) orientation: Option<nalgebra::UnitQuaternion<f64>>,
    /// The orientation's uncertainty, rad (`None`: no such column).
    pub(super) sigma_rad: Option<f64>,
}

impl Row {
    /// The values of `record`; an error names the column and what is wrong.
    pub(super) fn parse(record: &csv::StringRecord, layout: &Layout) -> Result<Self, (String, String)> {
        let (columns, names) = (&layout.columns, &layout.names);
        let mut row = Row {
            pose: String::new(),
            session: String::new(),
            target: String::new(),
            q: [0.0; JOINTS],
            xyz: Vector3::zeros(),
            sigma: None,
            held_out: None,
            orientation: None,
            sigma_rad: None,
        };
        let mut quaternion = [0.0; 4];
        for ((field, c), name) in record.iter().zip(columns).zip(names) {
            let err = |msg: String| (name.clone(), msg);
            match *c {
                Column::Pose => row.pose = label(field).map_err(err)?,
                Column::Session => row.session = label(field).map_err(err)?,
                Column::Target => row.target = label(field).map_err(err)?,
                Column::Joint(k, to_rad) => {
                    let v = number(field).map_err(err)?;
                    if v.abs() * to_rad > MOST_JOINT_DEG.to_radians() {
                        return Err(err(format!("{}: beyond +-{MOST_JOINT_DEG} deg", with_unit(field, name, "deg"))));
                    }
                    row.q[k] = v * to_rad;
                }
                Column::Coordinate(k, to_mm) => {
                    let v = number(field).map_err(err)?;
                    if v.abs() * to_mm > MOST_MM {
                        return Err(err(format!("{}: beyond +-{MOST_MM} mm", with_unit(field, name, "mm"))));
                    }
                    row.xyz[k] = v * to_mm;
                }
                Column::Sigma(to_mm) => {
                    let v = number(field).map_err(err)? * to_mm;
                    if !(v > 0.0 && v <= MOST_MM) {
                        return Err(err(format!(
                            "{}: an uncertainty must be above 0 and at most {MOST_MM} mm",
                            with_unit(field, name, "mm")
                        )));
                    }
                    row.sigma = Some(v);
                }
                Column::Quaternion(k) => {
                    let v = number(field).map_err(err)?;
                    // A unit quaternion's component: a larger one is named by its own column.
                    if v.abs() > 1.0 + QUATERNION_NORM_TOLERANCE {
                        return Err(err(format!("{field}: a unit quaternion's component lies within -1 to 1")));
                    }
                    quaternion[k] = v;
                }
                Column::SigmaAngle(to_rad) => {
                    let v = number(field).map_err(err)? * to_rad;
                    if !(v > 0.0 && v <= std::f64::consts::PI) {
                        return Err(err(format!("{field}: an orientation's uncertainty must be above 0 and at most 180 deg")));
                    }
                    row.sigma_rad = Some(v);
                }
                Column::Split => {
                    row.held_out = Some(match field {
                        TRAIN => false,
                        HOLDOUT => true,
                        _ => return Err(err(format!("{field:?}: `{TRAIN}` (the fit uses the pose) or `{HOLDOUT}` (held out)"))),
                    })
                }
            }
        }
        if columns.iter().any(|c| matches!(c, Column::Quaternion(_))) {
            let norm = quaternion.iter().map(|v| v * v).sum::<f64>().sqrt();
            if (norm - 1.0).abs() > QUATERNION_NORM_TOLERANCE {
                let at = columns.iter().position(|c| matches!(c, Column::Quaternion(0))).unwrap_or(0);
                return Err((names[at].clone(), format!("the quaternion's norm is {norm}, not 1")));
            }
            let [w, x, y, z] = quaternion;
            row.orientation = Some(nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z)));
        }
        Ok(row)
    }
}

/// How far a quaternion's norm may be from 1.
const QUATERNION_NORM_TOLERANCE: f64 = 1e-3;

/// A finite number.
fn number(field: &str) -> Result<f64, String> {
    if field.is_empty() {
        return Err("empty: a number is needed".into());
    }
    let v: f64 = field.parse().map_err(|_| format!("{field:?} is not a number"))?;
    if !v.is_finite() {
        return Err(format!("{field}: not a finite number"));
    }
    Ok(v)
}

/// A label: non-empty, at most [`MOST_LABEL`] characters, no control characters.
fn label(field: &str) -> Result<String, String> {
    if field.is_empty() {
        return Err("empty: a label is needed".into());
    }
    if field.chars().count() > MOST_LABEL || field.chars().any(char::is_control) {
        return Err(format!("a label of at most {MOST_LABEL} printable characters"));
    }
    Ok(field.to_string())
}
