//! The plan's tour (`tour.csv`) as a table, its text written from the frame by [`csv_text`] (the
//! measurement files, `poses.csv` and `simulated.csv`, are
//! [`crate::calibrate::measurements::file`]'s).

use polars::prelude::Column;

use super::select::Stop;
use crate::io::table::{CsvFormat, FieldFormat, Frame, csv_text, rounded};
use crate::robot::fk::JOINT_COLUMNS;
use crate::robot::{JOINTS, Joints};

/// Decimals of a tour's joint values, deg.
const TOUR_JOINT_DECIMALS: usize = 6;
/// Decimals of a tour's largest joint move, deg.
const TOUR_MOVE_DECIMALS: usize = 3;

/// A stop of a plan's tour.
#[derive(Clone, Debug)]
pub struct TourRow<'a> {
    /// The pose's label (a via configuration's own).
    pub pose: &'a str,
    /// `train`, `holdout` or `via`.
    pub split: &'a str,
    /// The configuration's group, from 1 (a device plan's sphere or station; `None`: none).
    pub group: Option<usize>,
    /// The controller's joint values, deg.
    pub q_deg: [f64; JOINTS],
    /// The largest joint change of the move to it, deg (0 at the first stop).
    pub move_deg: f64,
}

/// The tour's rows at `stops`: each stop's label, split, group and joints (rad, the model's) by
/// `stop`, its joint values by `controller_deg` (the controller's, deg), and the largest joint
/// change of the move to it.
pub fn tour_rows<'a>(
    stops: &'a [Stop],
    stop: impl Fn(&'a Stop) -> (&'a str, &'a str, Option<usize>, Joints),
    controller_deg: impl Fn(&Joints) -> [f64; JOINTS],
) -> Vec<TourRow<'a>> {
    let mut prev: Option<Joints> = None;
    let mut rows = Vec::with_capacity(stops.len());
    for s in stops {
        let (pose, split, group, q) = stop(s);
        let move_deg = prev.map_or(0.0, |p| p.iter().zip(&q).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max).to_degrees());
        rows.push(TourRow { pose, split, group, q_deg: controller_deg(&q), move_deg });
        prev = Some(q);
    }
    rows
}

/// The tour of `rows`: its table (`step` from 1, the labels `pose` and `split`, with `group` the
/// column of that name (the stops' groups, null where none), `q1_deg` ... `q6_deg` to 6 decimals
/// and `largest_joint_move_deg` to 3, as the text states them) and its text, the table as CSV.
pub fn tour_file(group: Option<&str>, rows: &[TourRow<'_>]) -> std::io::Result<(Frame, String)> {
    let step: Vec<i64> = (1..).take(rows.len()).collect();
    let mut columns = vec![
        Column::new("step".into(), step),
        Column::new("pose".into(), rows.iter().map(|r| r.pose).collect::<Vec<&str>>()),
        Column::new("split".into(), rows.iter().map(|r| r.split).collect::<Vec<&str>>()),
    ];
    if let Some(name) = group {
        let groups: Vec<Option<i64>> = rows.iter().map(|r| r.group.and_then(|g| i64::try_from(g).ok())).collect();
        columns.push(Column::new(name.into(), groups));
    }
    let joint = |i: usize| rows.iter().map(|r| rounded(r.q_deg[i], TOUR_JOINT_DECIMALS)).collect::<Vec<f64>>();
    columns.extend((0..JOINTS).map(|i| Column::new(JOINT_COLUMNS[i].into(), joint(i))));
    let moves: Vec<f64> = rows.iter().map(|r| rounded(r.move_deg, TOUR_MOVE_DECIMALS)).collect();
    columns.push(Column::new("largest_joint_move_deg".into(), moves));
    let table = crate::io::table::frame("tour", columns)?;
    let format = CsvFormat::new(FieldFormat::decimal(""))
        .with(JOINT_COLUMNS, FieldFormat::fixed("", TOUR_JOINT_DECIMALS))
        .with(["largest_joint_move_deg"], FieldFormat::fixed("", TOUR_MOVE_DECIMALS));
    let text = csv_text(&table, &format)?;
    Ok((table, text))
}
