//! A measurement file as calsim writes one (`calsim simulate-measurements`, a plan's `poses.csv`
//! and `simulated.csv`): its table and its text, written from the table by [`csv_text`].

use polars::prelude::Column;

use crate::io::table::{CsvFormat, FieldFormat, Frame, csv_text};
use crate::robot::JOINTS;
use crate::robot::fk::JOINT_COLUMNS;

/// A row of a measurement file: a target at a pose.
#[derive(Clone, Debug)]
pub struct MeasurementRow<'a> {
    /// The pose's label.
    pub pose: &'a str,
    /// The session.
    pub session: &'a str,
    /// The target.
    pub target: &'a str,
    /// `train` or `holdout` (`None`: the file has no `split` column).
    pub split: Option<&'a str>,
    /// The controller's joint values, deg.
    pub q_deg: [f64; JOINTS],
    /// The position, mm (`None`: to be measured).
    pub xyz_mm: Option<[f64; 3]>,
    /// The probe's orientation reading `w, x, y, z` (`None`: the file has no `quat_*` columns).
    pub quat: Option<[f64; 4]>,
}

/// The measurement file of `rows`: its table (the labels `pose`, `session`, `target` and, where a
/// row gives one, `split` as strings; `q1_deg` ... `q6_deg`, `x_mm`, `y_mm`, `z_mm` and, where a
/// row gives a reading, `quat_w` ... `quat_z` as floats; a missing value null) and its text: a
/// `# ` line per entry of `header`, then the table as CSV (every number in the shortest decimal
/// that reads back to the same bits, a null an empty field).
pub fn measurement_file<'a>(header: &[String], rows: &[MeasurementRow<'a>]) -> std::io::Result<(Frame, String)> {
    let label = |name: &str, v: fn(&MeasurementRow<'a>) -> &'a str| Column::new(name.into(), rows.iter().map(v).collect::<Vec<&str>>());
    let number = |name: &str, v: &dyn Fn(&MeasurementRow<'a>) -> Option<f64>| {
        Column::new(name.into(), rows.iter().map(v).collect::<Vec<Option<f64>>>())
    };
    let mut columns = vec![label("pose", |r| r.pose), label("session", |r| r.session), label("target", |r| r.target)];
    if rows.iter().any(|r| r.split.is_some()) {
        columns.push(Column::new("split".into(), rows.iter().map(|r| r.split).collect::<Vec<Option<&str>>>()));
    }
    columns.extend((0..JOINTS).map(|i| number(JOINT_COLUMNS[i], &|r| Some(r.q_deg[i]))));
    columns.extend(["x_mm", "y_mm", "z_mm"].iter().enumerate().map(|(k, c)| number(c, &|r| r.xyz_mm.map(|p| p[k]))));
    if rows.iter().any(|r| r.quat.is_some()) {
        let quat = ["quat_w", "quat_x", "quat_y", "quat_z"];
        columns.extend(quat.iter().enumerate().map(|(k, c)| number(c, &|r| r.quat.map(|o| o[k]))));
    }
    let table = crate::io::table::frame("measurements", columns)?;
    let mut text: String = header.iter().map(|c| format!("# {c}\n")).collect();
    text.push_str(&csv_text(&table, &CsvFormat::new(FieldFormat::decimal("")))?);
    Ok((table, text))
}
