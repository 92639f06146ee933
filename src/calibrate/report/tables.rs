//! The calibration's tables: `points`, `models`, `parameters`, `bases`, `tools`, `correlation`,
//! and the tables `summary.md` reads beside them: `calibration` (one row: the run's inputs, counts
//! and options), `model_errors` (a row per model: the noise estimate, the held-out fit's failure,
//! the held-out errors with and without the flagged points, the rotation errors),
//! `unidentifiable` (a row per model and parameter the poses cannot separate), `failed_folds`
//! (a row per fold that gave no model) and, with orientation readings, `probe_rotations`.

use polars::prelude::Column;

use crate::calibrate::{Calibration, ModelResult, ParamStatus};
use crate::io::results::Results;
use crate::study::stats::ErrorStats;

/// Every table of the calibration `c`.
pub fn tables(c: &Calibration, r: &mut Results<'_>) -> std::io::Result<()> {
    r.table("points.parquet", point_columns(c))?;
    r.table("models.parquet", model_columns(c))?;
    r.table("parameters.parquet", parameter_columns(c))?;
    r.table("bases.parquet", base_columns(c))?;
    r.table("tools.parquet", tool_columns(c))?;
    r.table("correlation.parquet", correlation_columns(c))?;
    r.table("calibration.parquet", run_columns(c))?;
    r.table("model_errors.parquet", model_error_columns(c))?;
    r.table("unidentifiable.parquet", unidentifiable_columns(c))?;
    r.table("failed_folds.parquet", failed_fold_columns(c))?;
    if c.measurements.orientation_columns {
        r.table("probe_rotations.parquet", probe_rotation_columns(c))?;
    }
    Ok(())
}

/// A row per parameter of the most complete model, in its unit.
fn parameter_columns(c: &Calibration) -> Vec<Column> {
    let est = &c.estimates;
    let unit = |e: &crate::calibrate::Estimate| e.id.unit();
    vec![
        Column::new("parameter".into(), est.iter().map(|e| e.id.name()).collect::<Vec<_>>()),
        Column::new("unit".into(), est.iter().map(|e| unit(e).symbol().to_string()).collect::<Vec<_>>()),
        Column::new("nominal".into(), est.iter().map(|e| unit(e).from_internal(e.nominal)).collect::<Vec<_>>()),
        Column::new("calibrated".into(), est.iter().map(|e| unit(e).from_internal(e.value)).collect::<Vec<_>>()),
        Column::new("std".into(), est.iter().map(|e| unit(e).from_internal(e.std)).collect::<Vec<_>>()),
        Column::new("status".into(), est.iter().map(|e| status(&e.status)).collect::<Vec<_>>()),
    ]
}

/// A row per session: its base and standard deviations.
fn base_columns(c: &Calibration) -> Vec<Column> {
    let b = &c.bases;
    let mut base_cols = vec![Column::new("session".into(), b.iter().map(|b| b.session.clone()).collect::<Vec<_>>())];
    let values = |f: &dyn Fn(&crate::calibrate::BaseEstimate) -> f64| b.iter().map(f).collect::<Vec<_>>();
    base_cols.extend([
        Column::new("x_mm".into(), values(&|b| b.session_from_base.x)),
        Column::new("y_mm".into(), values(&|b| b.session_from_base.y)),
        Column::new("z_mm".into(), values(&|b| b.session_from_base.z)),
        Column::new("alpha_deg".into(), values(&|b| b.session_from_base.alpha.to_degrees())),
        Column::new("beta_deg".into(), values(&|b| b.session_from_base.beta.to_degrees())),
        Column::new("gamma_deg".into(), values(&|b| b.session_from_base.gamma.to_degrees())),
    ]);
    for (k, name) in ["x_mm", "y_mm", "z_mm", "alpha_deg", "beta_deg", "gamma_deg"].iter().enumerate() {
        let scale = if k < 3 { 1.0 } else { 180.0 / std::f64::consts::PI };
        base_cols.push(Column::new(format!("std_{name}").into(), values(&|b| b.std[k] * scale)));
    }
    base_cols
}

/// A row per target: its position on the flange and standard deviations.
fn tool_columns(c: &Calibration) -> Vec<Column> {
    let t = &c.tools;
    let mut tool_cols = vec![Column::new("target".into(), t.iter().map(|t| t.target.clone()).collect::<Vec<_>>())];
    for (k, name) in ["x_mm", "y_mm", "z_mm"].iter().enumerate() {
        tool_cols.push(Column::new(format!("flange_{name}").into(), t.iter().map(|t| t.flange_mm[k]).collect::<Vec<_>>()));
        tool_cols.push(Column::new(format!("std_{name}").into(), t.iter().map(|t| t.std_mm[k]).collect::<Vec<_>>()));
    }
    tool_cols
}

/// A row per pair of identified parameters (row-major over the identified estimates).
fn correlation_columns(c: &Calibration) -> Vec<Column> {
    let names: Vec<String> = c.estimates.iter().filter(|e| e.status == ParamStatus::Identified).map(|e| e.id.name()).collect();
    let n = names.len();
    vec![
        Column::new("parameter_a".into(), (0..n * n).map(|k| names[k / n].clone()).collect::<Vec<_>>()),
        Column::new("parameter_b".into(), (0..n * n).map(|k| names[k % n].clone()).collect::<Vec<_>>()),
        Column::new("correlation".into(), (0..n * n).map(|k| c.correlation[(k / n, k % n)]).collect::<Vec<_>>()),
    ]
}

/// A parameter's status in words (`parameters.parquet`).
pub fn status(s: &ParamStatus) -> String {
    match s {
        ParamStatus::Identified => "identified".into(),
        ParamStatus::NotInModel => "not in the model".into(),
        ParamStatus::Unidentifiable(with) => format!("unidentifiable (with {})", with.join(" ")),
        ParamStatus::NotDetermined(why) => format!("not determined (kept nominal): {why}"),
        ParamStatus::NoTorque(why) => format!("kept nominal, in no model: {why}"),
    }
}

/// A row per point: where it is from, its joints, its errors before and after, its fold and
/// held-out error.
fn point_columns(c: &Calibration) -> Vec<Column> {
    let m = &c.measurements;
    let p = &m.points;
    let pose = |i: usize| &m.poses[p[i].pose];
    let n = p.len();
    let (before, after) = (&c.before.fit, &c.chosen().fit);
    let mut held_error = vec![f64::NAN; n];
    if let Some(h) = c.chosen().held_out.as_ref() {
        for (k, &i) in held_out_points(c).iter().enumerate() {
            held_error[i] = h.errors_mm[k];
        }
    }
    let mut cols = vec![
        Column::new("line".into(), p.iter().map(|x| x.line).collect::<Vec<_>>()),
        Column::new("pose".into(), (0..n).map(|i| pose(i).label.clone()).collect::<Vec<_>>()),
        Column::new("session".into(), (0..n).map(|i| m.sessions[pose(i).session].clone()).collect::<Vec<_>>()),
        Column::new("target".into(), p.iter().map(|x| m.targets[x.target].clone()).collect::<Vec<_>>()),
    ];
    for j in 0..crate::robot::JOINTS {
        cols.push(Column::new(format!("theta{}_deg", j + 1).into(), (0..n).map(|i| pose(i).q[j].to_degrees()).collect::<Vec<_>>()));
    }
    for (k, a) in ["x", "y", "z"].iter().enumerate() {
        cols.push(Column::new(format!("base_{a}_mm").into(), c.points_base_mm.iter().map(|v| v[k]).collect::<Vec<_>>()));
    }
    for (k, a) in ["x", "y", "z"].iter().enumerate() {
        cols.push(Column::new(format!("residual_{a}_mm").into(), after.residual_base_mm.iter().map(|v| v[k]).collect::<Vec<_>>()));
    }
    cols.extend([
        Column::new("error_before_mm".into(), before.errors_mm.clone()),
        Column::new("error_after_mm".into(), after.errors_mm.clone()),
        Column::new("normalized_residual".into(), after.normalized.clone()),
        Column::new("outlier".into(), after.outlier.clone()),
        Column::new("held_out".into(), (0..n).map(|i| c.assignment.held_out[p[i].pose]).collect::<Vec<_>>()),
        Column::new("fold".into(), (0..n).map(|i| c.assignment.fold[p[i].pose].map(|f| f as u32)).collect::<Vec<_>>()),
        Column::new("held_out_error_mm".into(), held_error),
        Column::new("kfold_all_fold".into(), p.iter().map(|x| c.assignment.fold_all[x.pose] as u32).collect::<Vec<_>>()),
        Column::new("kfold_all_error_mm".into(), c.chosen().cv_all.errors_mm.clone()),
    ]);
    if m.orientation_columns {
        cols.extend(rotation_point_columns(c));
    }
    cols
}

/// The points of the held-out poses, in file order (the order of a held-out fit's errors).
fn held_out_points(c: &Calibration) -> Vec<usize> {
    let p = &c.measurements.points;
    (0..p.len()).filter(|&i| c.assignment.held_out[p[i].pose]).collect()
}

/// The rotation errors (measured minus model, about the robot base's axes) of the chosen model's
/// fit on every point, and at the held-out points of its training fit; NaN where a point has no
/// reading.
fn rotation_point_columns(c: &Calibration) -> Vec<Column> {
    let n = c.measurements.points.len();
    let rot = &c.chosen().fit.rotation_base_mdeg;
    let component = |i: usize, k: usize| rot.get(i).copied().flatten().map_or(f64::NAN, |v| v[k]);
    let mut cols = Vec::new();
    for (k, a) in ["x", "y", "z"].iter().enumerate() {
        cols.push(Column::new(format!("rotation_residual_{a}_mdeg").into(), (0..n).map(|i| component(i, k)).collect::<Vec<_>>()));
    }
    let norm = |i: usize| rot.get(i).copied().flatten().map_or(f64::NAN, |v| v.norm());
    cols.push(Column::new("rotation_error_after_mdeg".into(), (0..n).map(norm).collect::<Vec<_>>()));
    let mut held_rotation = vec![f64::NAN; n];
    if let Some(h) = c.chosen().held_out.as_ref() {
        for (k, &i) in held_out_points(c).iter().enumerate() {
            held_rotation[i] = h.rotation_errors_mdeg.get(k).copied().unwrap_or(f64::NAN);
        }
    }
    cols.push(Column::new("held_out_rotation_error_mdeg".into(), held_rotation));
    cols.push(Column::new("reading_normalized_residual".into(), c.readings_flagged.normalized.clone()));
    cols.push(Column::new("reading_outlier".into(), c.readings_flagged.flagged.clone()));
    cols
}

/// The statistics' names in table columns.
pub const STATS: [&str; 5] = ["mean", "median", "p95", "max", "rms"];

fn stat(s: &ErrorStats, k: usize) -> f64 {
    [s.mean, s.median, s.p95, s.max, s.rms][k]
}

/// The models' rows: the registration-only "before" first, then the models compared.
fn model_rows(c: &Calibration) -> Vec<&ModelResult> {
    std::iter::once(&c.before).chain(&c.models).collect()
}

/// A column per statistic, `{prefix}_{stat}_mm`, of each row's statistics.
fn stat_columns(prefix: &str, rows: &[&ModelResult], of: impl Fn(&ModelResult) -> ErrorStats) -> Vec<Column> {
    let stats: Vec<ErrorStats> = rows.iter().map(|r| of(r)).collect();
    STATS
        .iter()
        .enumerate()
        .map(|(k, s)| Column::new(format!("{prefix}_{s}_mm").into(), stats.iter().map(|x| stat(x, k)).collect::<Vec<_>>()))
        .collect()
}

const NAN_STATS: ErrorStats = ErrorStats { mean: f64::NAN, median: f64::NAN, std: f64::NAN, p95: f64::NAN, max: f64::NAN, rms: f64::NAN };

/// A cross-validation's statistics (NaN without a point).
fn cv_stats(cv: &crate::calibrate::validation::CrossValidation) -> ErrorStats {
    if cv.points > 0 { cv.stats } else { NAN_STATS }
}

/// A row per model (the registration-only "before" first).
fn model_columns(c: &Calibration) -> Vec<Column> {
    let rows = model_rows(c);
    let held =
        |r: &ModelResult, predicted: bool| r.held_out.as_ref().map_or(NAN_STATS, |h| if predicted { h.predicted } else { h.measured });
    let mut cols = vec![
        Column::new("model".into(), rows.iter().map(|r| r.name().to_string()).collect::<Vec<_>>()),
        Column::new("parameters".into(), rows.iter().map(|r| r.layout.robot.len() as u32).collect::<Vec<_>>()),
        Column::new(
            "unidentifiable".into(),
            rows.iter().map(|r| r.unidentifiable.iter().map(|u| u.name.clone()).collect::<Vec<_>>().join(" ")).collect::<Vec<_>>(),
        ),
        Column::new("chosen".into(), rows.iter().map(|r| r.kind.is_some() && r.kind == c.chosen().kind).collect::<Vec<_>>()),
        Column::new("cv_points".into(), rows.iter().map(|r| r.cv.points as u32).collect::<Vec<_>>()),
    ];
    cols.extend(stat_columns("cv", &rows, |r| cv_stats(&r.cv)));
    cols.push(Column::new("kfold_all_points".into(), rows.iter().map(|r| r.cv_all.points as u32).collect::<Vec<_>>()));
    cols.extend(stat_columns("kfold_all", &rows, |r| cv_stats(&r.cv_all)));
    cols.push(Column::new("cv_paired_mse_difference_mm2".into(), rows.iter().map(|r| r.against_chosen.0).collect::<Vec<_>>()));
    cols.push(Column::new("cv_paired_standard_error_mm2".into(), rows.iter().map(|r| r.against_chosen.1).collect::<Vec<_>>()));
    cols.push(Column::new(
        "held_out_points".into(),
        rows.iter().map(|r| r.held_out.as_ref().map_or(0, |h| h.points as u32)).collect::<Vec<_>>(),
    ));
    let (measured, predicted) = (stat_columns("held_out", &rows, |r| held(r, false)), stat_columns("predicted", &rows, |r| held(r, true)));
    cols.extend(measured.into_iter().zip(predicted).flat_map(|(m, p)| [m, p]));
    cols.extend(stat_columns("fit", &rows, |r| r.fit.stats));
    cols.push(Column::new(
        "fit_outliers".into(),
        rows.iter().map(|r| r.fit.outlier.iter().filter(|o| **o).count() as u32).collect::<Vec<_>>(),
    ));
    cols.push(Column::new("fit_outcome".into(), rows.iter().map(|r| r.fit.outcome.label().to_string()).collect::<Vec<_>>()));
    cols
}

/// A row per model (the rows of `models.parquet`): its noise estimate, whether its training fit
/// gave a model (and why not), the held-out errors with and without the flagged points, and the
/// rotation errors of its fit on every point and at the held-out points (NaN without readings).
fn model_error_columns(c: &Calibration) -> Vec<Column> {
    let rows = model_rows(c);
    let held =
        |r: &ModelResult, with: bool| r.held_out.as_ref().map_or(NAN_STATS, |h| if with { h.with_flagged } else { h.without_flagged });
    let mut cols = vec![
        Column::new("model".into(), rows.iter().map(|r| r.name().to_string()).collect::<Vec<_>>()),
        Column::new("noise_estimate_mm".into(), rows.iter().map(|r| r.fit.sigma_hat).collect::<Vec<_>>()),
        Column::new("held_out_fitted".into(), rows.iter().map(|r| r.held_out.is_some()).collect::<Vec<_>>()),
        Column::new("held_out_failure".into(), rows.iter().map(|r| r.held_out_why.clone()).collect::<Vec<_>>()),
        Column::new(
            "held_out_flagged".into(),
            rows.iter().map(|r| r.held_out.as_ref().map_or(0, |h| h.flagged as u32)).collect::<Vec<_>>(),
        ),
    ];
    cols.extend(stat_columns("held_out_with_flagged", &rows, |r| held(r, true)));
    cols.extend(stat_columns("held_out_without_flagged", &rows, |r| held(r, false)));
    let fit_rotation = |r: &ModelResult| {
        let norms: Vec<f64> = r.fit.rotation_base_mdeg.iter().flatten().map(|v| v.norm()).collect();
        ErrorStats::of(&norms)
    };
    cols.push(Column::new(
        "held_out_rotation".into(),
        rows.iter().map(|r| r.held_out.as_ref().is_some_and(|h| h.rotation.is_some())).collect::<Vec<_>>(),
    ));
    let held_rotation = |r: &ModelResult| r.held_out.as_ref().and_then(|h| h.rotation).unwrap_or(NAN_STATS);
    let held_rotation_without = |r: &ModelResult| r.held_out.as_ref().and_then(|h| h.rotation_without_flagged).unwrap_or(NAN_STATS);
    type Of<'f> = &'f dyn Fn(&ModelResult) -> ErrorStats;
    let mut of_rows: Vec<(&str, Of<'_>)> = vec![("rotation_fit", &fit_rotation), ("held_out_rotation", &held_rotation)];
    // The readings' outliers, with orientation columns.
    if c.measurements.orientation_columns {
        cols.push(Column::new(
            "held_out_readings_flagged".into(),
            rows.iter().map(|r| r.held_out.as_ref().map_or(0, |h| h.readings_flagged as u32)).collect::<Vec<_>>(),
        ));
        of_rows.push(("held_out_rotation_without_flagged", &held_rotation_without));
    }
    for (name, of) in of_rows {
        let stats: Vec<ErrorStats> = rows.iter().map(|r| of(r)).collect();
        for (k, s) in [(0, "mean"), (3, "max"), (4, "rms")] {
            cols.push(Column::new(format!("{name}_{s}_mdeg").into(), stats.iter().map(|x| stat(x, k)).collect::<Vec<_>>()));
        }
    }
    cols
}

/// A row per model and robot parameter the poses cannot separate, with the unknowns it goes with.
fn unidentifiable_columns(c: &Calibration) -> Vec<Column> {
    let rows: Vec<(&str, &crate::calibrate::registration::Unidentifiable)> =
        model_rows(c).into_iter().flat_map(|r| r.unidentifiable.iter().map(move |u| (r.name(), u))).collect();
    vec![
        Column::new("model".into(), rows.iter().map(|(m, _)| m.to_string()).collect::<Vec<_>>()),
        Column::new("parameter".into(), rows.iter().map(|(_, u)| u.name.clone()).collect::<Vec<_>>()),
        Column::new("with".into(), rows.iter().map(|(_, u)| u.with.join(" ")).collect::<Vec<_>>()),
    ]
}

/// A row per fold that gave no model: the model, the cross-validation (`training poses`: the one
/// that chooses the model; `every pose`: the k-fold over every pose), the fold and why.
fn failed_fold_columns(c: &Calibration) -> Vec<Column> {
    let mut rows: Vec<(&str, &str, u32, String)> = Vec::new();
    for r in model_rows(c) {
        for (which, cv) in [("training poses", &r.cv), ("every pose", &r.cv_all)] {
            rows.extend(cv.failed.iter().map(|(f, why)| (r.name(), which, *f as u32, why.clone())));
        }
    }
    vec![
        Column::new("model".into(), rows.iter().map(|x| x.0.to_string()).collect::<Vec<_>>()),
        Column::new("cross_validation".into(), rows.iter().map(|x| x.1.to_string()).collect::<Vec<_>>()),
        Column::new("fold".into(), rows.iter().map(|x| x.2).collect::<Vec<_>>()),
        Column::new("reason".into(), rows.iter().map(|x| x.3.clone()).collect::<Vec<_>>()),
    ]
}

/// A row per target with orientation readings: its probe's rotation on the flange (rotation
/// vector, deg) and the standard deviations of its small rotations about the flange's axes (mdeg).
fn probe_rotation_columns(c: &Calibration) -> Vec<Column> {
    let rows: Vec<(String, nalgebra::Vector3<f64>, [f64; 3])> = (c.probe_rotations.iter().enumerate())
        .filter_map(|(t, r)| {
            r.as_ref().map(|r| (c.measurements.targets[t].clone(), r.flange_from_probe.scaled_axis().map(f64::to_degrees), r.std_mdeg))
        })
        .collect();
    let mut cols = vec![Column::new("target".into(), rows.iter().map(|x| x.0.clone()).collect::<Vec<_>>())];
    for (k, a) in ["x", "y", "z"].iter().enumerate() {
        cols.push(Column::new(format!("rotation_{a}_deg").into(), rows.iter().map(|x| x.1[k]).collect::<Vec<_>>()));
    }
    for (k, a) in ["x", "y", "z"].iter().enumerate() {
        cols.push(Column::new(format!("std_{a}_mdeg").into(), rows.iter().map(|x| x.2[k]).collect::<Vec<_>>()));
    }
    cols
}

/// One row: the robot and measurement files, the counts, the payload, the options and choices the
/// summary states.
fn run_columns(c: &Calibration) -> Vec<Column> {
    let (m, o) = (&c.measurements, &c.options);
    let text = |name: &str, v: String| Column::new(name.into(), vec![v]);
    let number = |name: &str, v: f64| Column::new(name.into(), vec![v]);
    let whole = |name: &str, v: usize| Column::new(name.into(), vec![v as u32]);
    let train = c.assignment.held_out.iter().filter(|h| !**h).count();
    let any = |f: &dyn Fn(&crate::calibrate::measurements::Point) -> bool| m.points.iter().any(f);
    let mut cols = vec![
        text("robot", c.model.name().to_string()),
        text("robot_file", c.robot.path.display().to_string()),
        text("measurements", m.path.display().to_string()),
        Column::new("simulated".into(), vec![m.header.simulated]),
        whole("points", m.points.len()),
        whole("poses", m.poses.len()),
        whole("rows_left_out", m.rows_left_out),
        Column::new("coupled".into(), vec![m.coupled]),
    ];
    cols.extend(payload_columns(c));
    cols.extend([
        text("inert", c.inert.iter().map(|(n, _)| n.as_str()).collect::<Vec<_>>().join(", ")),
        text("inert_reason", c.inert.first().map_or_else(String::new, |(_, why)| why.clone())),
        text("chosen", c.chosen().name().to_string()),
        whole("folds", o.folds),
        text("kfold_by", o.kfold_by.name().to_string()),
        whole("kfold_all_folds", c.assignment.folds_all),
        text("split", o.split.describe()),
        whole("held_out_poses", c.assignment.held_out.len() - train),
        whole("training_poses", train),
        whole("prediction_draws", o.prediction_draws),
        text("outliers", o.outliers.name().to_string()),
        text("outliers_by", c.outliers_by.to_string()),
        number("outlier_threshold", o.outlier_threshold),
        number("outlier_false_alarm", super::summary::chi3_tail(o.outlier_threshold)),
        Column::new("orientation_columns".into(), vec![m.orientation_columns]),
        whole("orientation_points", m.points.iter().filter(|p| p.orientation.is_some()).count()),
        Column::new("orientation_noise_mdeg".into(), vec![(!any(&|p| p.sigma_rad.is_some())).then_some(o.orientation_noise_mdeg)]),
        Column::new("position_noise_mm".into(), vec![(!any(&|p| p.sigma_mm.is_some())).then_some(o.position_noise_mm)]),
    ]);
    cols
}

/// The payload at the flange: given by `--payload-kg`, the robot file's, or none (null mass).
fn payload_columns(c: &Calibration) -> Vec<Column> {
    let file = c.robot.nominal.data().payload.mass_kg;
    let (from, mass, com) = match (&c.options.payload, file > 0.0) {
        (Some(p), _) => ("--payload-kg", Some(p.mass_kg), p.com_mm.map(Some)),
        (None, true) => ("robot file", Some(file), [None; 3]),
        (None, false) => ("none", None, [None; 3]),
    };
    vec![
        Column::new("payload_from".into(), vec![from.to_string()]),
        Column::new("payload_kg".into(), vec![mass]),
        Column::new("payload_com_x_mm".into(), vec![com[0]]),
        Column::new("payload_com_y_mm".into(), vec![com[1]]),
        Column::new("payload_com_z_mm".into(), vec![com[2]]),
    ]
}
