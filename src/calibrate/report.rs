//! The calibration's report directory, written atomically (`io::out_dir::write_atomically`):
//! the calibrated robot file, its URDF and YAML overlay (through `export`'s writers), the model
//! before calibration, the tables (`points`, `models`, `parameters`, `bases`, `tools`,
//! `correlation`, as parquet), the figures and `summary.md`, and `manifest.json` with the inputs'
//! and tables' sha256.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use polars::prelude::Column;
use sha2::Digest;

use super::{Calibration, ModelResult, ParamStatus};
use crate::io::results::{Head, Results};
use crate::study::stats::ErrorStats;

/// The report directory's name for the measurement file `path`: `<stem>.calibration`.
pub fn directory_name(path: &Path) -> String {
    format!("{}.calibration", path.file_stem().map_or_else(|| "measurements".into(), |s| s.to_string_lossy()))
}

/// Writes the report of `c` (with `plan.md` when a plan was simulated) into `out/<name>`, replacing
/// what was there.
pub fn write(out: &Path, name: &str, c: &Calibration, plan: Option<&super::plan::PlanComparison>) -> std::io::Result<PathBuf> {
    let mut r = results(name, c)?;
    if let Some(p) = plan {
        r.file("plan.md", super::plan::markdown(p));
    }
    crate::io::results::write(out, r).map(|w| w.dest)
}

/// Plans made, and those that could not be with why (`plan.md`, when either is not empty).
pub type PlanRows<'a> = (&'a [(super::plan::PlanWith, super::plan::PlanComparison)], &'a [(super::plan::PlanWith, String)]);

/// Writes the report of `c` as [`write`] does, with the twin (`twin.toml` and its section of the
/// summary, or why it could not be fitted) and the plans' table (`plan.md`, with the plans' figure).
pub fn write_with(
    out: &Path,
    name: &str,
    c: &Calibration,
    plans: PlanRows<'_>,
    twin: &Result<super::twin::Twin, String>,
) -> std::io::Result<PathBuf> {
    let mut r = results(name, c)?;
    if !plans.0.is_empty() || !plans.1.is_empty() {
        let mut text = super::plan::markdown_all(plans.0, plans.1);
        if c.options.plots && !plans.0.is_empty() {
            let (stem, caption) = super::plots::PLAN_FIGURE;
            text += &format!("\n![{caption}]({stem}.png)\n\n*{caption}*\n");
            // plan.md shows it: not among the summary's figures.
            r.draw(Box::new(move |dir| super::plots::write_plan(dir, plans.0).map(|_| Vec::new())));
        }
        r.file("plan.md", text);
    }
    if let Ok(t) = twin {
        r.file("twin.toml", twin_text(c, t).map_err(std::io::Error::other)?);
    }
    let section = match twin {
        Ok(t) => super::twin::markdown(t),
        Err(why) => format!("## The twin: what the model misses\n\nNot fitted: {why}\n"),
    };
    r.summary.text("\n").text(section);
    crate::io::results::write(out, r).map(|w| w.dest)
}

/// The report of `c` as results: the robot files, the tables, the manifest's fields, the figures
/// and the summary.
fn results<'a>(name: &str, c: &'a Calibration) -> std::io::Result<Results<'a>> {
    let mut r = Results::new(name, Head::Run(crate::io::manifest::Provenance::of_run(&[])));
    robot_files(c, &mut r)?;
    tables(c, &mut r)?;
    r.fields(fields(c))?;
    if c.options.plots {
        r.draw(Box::new(move |dir| super::plots::write(dir, c)));
    }
    r.summary.text(summary(c)).figures("");
    Ok(r)
}

/// `twin.toml`: the calibrated robot file (as `robot.toml`, with the twin's robot: the chosen
/// model's parameters moved by the joint fit of the kept effects) and its `[learned]` table.
pub fn twin_text(c: &Calibration, t: &super::twin::Twin) -> Result<String, String> {
    #[derive(serde::Serialize)]
    struct Table<'a> {
        learned: &'a crate::robot::learned::LearnedEffects,
    }
    let std: Vec<_> = c.estimates.iter().filter(|e| e.status == ParamStatus::Identified).map(|e| (e.id, e.std)).collect();
    let coupling = c.robot.coupling.as_ref().map_or_else(String::new, |k| format!("\n{}", k.to_text()));
    let source = format!(
        "calsim {} calibrate: the twin of the {} model from {} ({} points)",
        env!("CARGO_PKG_VERSION"),
        c.chosen().name(),
        c.measurements.path.display(),
        c.measurements.points.len()
    );
    let robot = crate::robot::file::to_text(&t.model, &source, &std, c.robot.capsules.as_ref(), c.robot.flange.as_ref()) + &coupling;
    let learned = toml::to_string(&Table { learned: &t.learned }).map_err(|e| e.to_string())?;
    Ok(format!("{robot}\n{learned}"))
}

/// `robot.toml` (the calibrated arm: the robot file's base, tool, capsules and coupling, the
/// chosen model's parameters with their standard deviations), `before.toml`, `robot.urdf` and
/// `calibration.yaml`.
fn robot_files(c: &Calibration, r: &mut Results<'_>) -> std::io::Result<()> {
    let held = c.chosen().held_out.as_ref().map_or(f64::NAN, |h| h.measured.median);
    let std: Vec<_> = c.estimates.iter().filter(|e| e.status == ParamStatus::Identified).map(|e| (e.id, e.std)).collect();
    let (before_model, flange) = (&c.robot.nominal, c.robot.flange.as_ref());
    let coupling = c.robot.coupling.as_ref().map_or_else(String::new, |k| format!("\n{}", k.to_text()));
    let source = format!(
        "calsim {} calibrate: {} model from {} ({} points; held-out median {:.4} mm)",
        env!("CARGO_PKG_VERSION"),
        c.chosen().name(),
        c.measurements.path.display(),
        c.measurements.points.len(),
        held
    );
    let capsules = c.robot.capsules.as_ref();
    let robot = crate::robot::file::to_text(&c.model, &source, &std, capsules, flange) + &coupling;
    let before_source = format!("the robot file {} before calibration", c.robot.path.display());
    let before = crate::robot::file::to_text(before_model, &before_source, &[], capsules, flange) + &coupling;
    let urdf = crate::robot::export::urdf(before_model, &c.model).map_err(std::io::Error::other)?;
    let provenance = format!("calibrate of {}, {} poses", c.measurements.path.display(), c.measurements.poses.len());
    let yaml = crate::robot::export::yaml_overlay(before_model, &c.model, &provenance);
    r.file("robot.toml", robot).file("before.toml", before).file("robot.urdf", urdf).file("calibration.yaml", yaml);
    Ok(())
}

fn tables(c: &Calibration, r: &mut Results<'_>) -> std::io::Result<()> {
    r.table("points.parquet", point_columns(c))?;
    r.table("models.parquet", model_columns(c))?;
    let est = &c.estimates;
    let unit = |e: &super::Estimate| e.id.unit();
    r.table(
        "parameters.parquet",
        vec![
            Column::new("parameter".into(), est.iter().map(|e| e.id.name()).collect::<Vec<_>>()),
            Column::new("unit".into(), est.iter().map(|e| unit(e).symbol().to_string()).collect::<Vec<_>>()),
            Column::new("nominal".into(), est.iter().map(|e| unit(e).from_internal(e.nominal)).collect::<Vec<_>>()),
            Column::new("calibrated".into(), est.iter().map(|e| unit(e).from_internal(e.value)).collect::<Vec<_>>()),
            Column::new("std".into(), est.iter().map(|e| unit(e).from_internal(e.std)).collect::<Vec<_>>()),
            Column::new("status".into(), est.iter().map(|e| status(&e.status)).collect::<Vec<_>>()),
        ],
    )?;
    let b = &c.bases;
    let mut base_cols = vec![Column::new("session".into(), b.iter().map(|b| b.session.clone()).collect::<Vec<_>>())];
    let values = |f: &dyn Fn(&super::BaseEstimate) -> f64| b.iter().map(f).collect::<Vec<_>>();
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
    r.table("bases.parquet", base_cols)?;
    let t = &c.tools;
    let mut tool_cols = vec![Column::new("target".into(), t.iter().map(|t| t.target.clone()).collect::<Vec<_>>())];
    for (k, name) in ["x_mm", "y_mm", "z_mm"].iter().enumerate() {
        tool_cols.push(Column::new(format!("flange_{name}").into(), t.iter().map(|t| t.flange_mm[k]).collect::<Vec<_>>()));
        tool_cols.push(Column::new(format!("std_{name}").into(), t.iter().map(|t| t.std_mm[k]).collect::<Vec<_>>()));
    }
    r.table("tools.parquet", tool_cols)?;
    let names: Vec<String> = est.iter().filter(|e| e.status == ParamStatus::Identified).map(|e| e.id.name()).collect();
    let n = names.len();
    r.table(
        "correlation.parquet",
        vec![
            Column::new("parameter_a".into(), (0..n * n).map(|k| names[k / n].clone()).collect::<Vec<_>>()),
            Column::new("parameter_b".into(), (0..n * n).map(|k| names[k % n].clone()).collect::<Vec<_>>()),
            Column::new("correlation".into(), (0..n * n).map(|k| c.correlation[(k / n, k % n)]).collect::<Vec<_>>()),
        ],
    )?;
    Ok(())
}

fn status(s: &ParamStatus) -> String {
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
    let held = c.chosen().held_out.as_ref();
    let test: Vec<usize> = (0..n).filter(|&i| c.assignment.held_out[p[i].pose]).collect();
    let mut held_error = vec![f64::NAN; n];
    if let Some(h) = held {
        for (k, &i) in test.iter().enumerate() {
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
        // The rotation errors (measured minus model, about the robot base's axes) of the chosen
        // model's fit on every point, and at the held-out points of its training fit; NaN where a
        // point has no reading.
        let rot = &after.rotation_base_mdeg;
        let component = |i: usize, k: usize| rot.get(i).copied().flatten().map_or(f64::NAN, |v| v[k]);
        for (k, a) in ["x", "y", "z"].iter().enumerate() {
            cols.push(Column::new(format!("rotation_residual_{a}_mdeg").into(), (0..n).map(|i| component(i, k)).collect::<Vec<_>>()));
        }
        let norm = |i: usize| rot.get(i).copied().flatten().map_or(f64::NAN, |v| v.norm());
        cols.push(Column::new("rotation_error_after_mdeg".into(), (0..n).map(norm).collect::<Vec<_>>()));
        let mut held_rotation = vec![f64::NAN; n];
        if let Some(h) = held {
            for (k, &i) in test.iter().enumerate() {
                held_rotation[i] = h.rotation_errors_mdeg.get(k).copied().unwrap_or(f64::NAN);
            }
        }
        cols.push(Column::new("held_out_rotation_error_mdeg".into(), held_rotation));
    }
    cols
}

/// The statistics' names in table columns.
const STATS: [&str; 5] = ["mean", "median", "p95", "max", "rms"];

fn stat(s: &ErrorStats, k: usize) -> f64 {
    [s.mean, s.median, s.p95, s.max, s.rms][k]
}

/// A row per model (the registration-only "before" first).
fn model_columns(c: &Calibration) -> Vec<Column> {
    let rows: Vec<&ModelResult> = std::iter::once(&c.before).chain(&c.models).collect();
    let nan = ErrorStats { mean: f64::NAN, median: f64::NAN, std: f64::NAN, p95: f64::NAN, max: f64::NAN, rms: f64::NAN };
    let held = |r: &ModelResult, predicted: bool| r.held_out.as_ref().map_or(nan, |h| if predicted { h.predicted } else { h.measured });
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
    for (k, s) in STATS.iter().enumerate() {
        cols.push(Column::new(
            format!("cv_{s}_mm").into(),
            rows.iter().map(|r| if r.cv.points > 0 { stat(&r.cv.stats, k) } else { f64::NAN }).collect::<Vec<_>>(),
        ));
    }
    cols.push(Column::new("kfold_all_points".into(), rows.iter().map(|r| r.cv_all.points as u32).collect::<Vec<_>>()));
    for (k, s) in STATS.iter().enumerate() {
        cols.push(Column::new(
            format!("kfold_all_{s}_mm").into(),
            rows.iter().map(|r| if r.cv_all.points > 0 { stat(&r.cv_all.stats, k) } else { f64::NAN }).collect::<Vec<_>>(),
        ));
    }
    cols.push(Column::new("cv_paired_mse_difference_mm2".into(), rows.iter().map(|r| r.against_chosen.0).collect::<Vec<_>>()));
    cols.push(Column::new("cv_paired_standard_error_mm2".into(), rows.iter().map(|r| r.against_chosen.1).collect::<Vec<_>>()));
    cols.push(Column::new(
        "held_out_points".into(),
        rows.iter().map(|r| r.held_out.as_ref().map_or(0, |h| h.points as u32)).collect::<Vec<_>>(),
    ));
    for (k, s) in STATS.iter().enumerate() {
        cols.push(Column::new(format!("held_out_{s}_mm").into(), rows.iter().map(|r| stat(&held(r, false), k)).collect::<Vec<_>>()));
        cols.push(Column::new(format!("predicted_{s}_mm").into(), rows.iter().map(|r| stat(&held(r, true), k)).collect::<Vec<_>>()));
    }
    for (k, s) in STATS.iter().enumerate() {
        cols.push(Column::new(format!("fit_{s}_mm").into(), rows.iter().map(|r| stat(&r.fit.stats, k)).collect::<Vec<_>>()));
    }
    cols.push(Column::new(
        "fit_outliers".into(),
        rows.iter().map(|r| r.fit.outlier.iter().filter(|o| **o).count() as u32).collect::<Vec<_>>(),
    ));
    cols.push(Column::new("fit_outcome".into(), rows.iter().map(|r| r.fit.outcome.label().to_string()).collect::<Vec<_>>()));
    cols
}

/// The manifest's fields: the inputs with their sha256 and the options.
fn fields(c: &Calibration) -> serde_json::Value {
    let sha = |p: &Path| crate::io::read_bytes(p).map(|b| format!("{:x}", sha2::Sha256::digest(&b))).unwrap_or_default();
    let o = &c.options;
    serde_json::json!({
        "measurements_path": c.measurements.path.display().to_string(),
        "measurements_sha256": sha(&c.measurements.path),
        "robot_path": c.robot.path.display().to_string(),
        "robot_sha256": sha(&c.robot.path),
        "options": {
            "params": o.params.as_ref().map_or_else(|| super::default_params().names(), |p| p.names()),
            "folds": o.folds,
            "kfold_by": o.kfold_by.name(),
            "tool_per_session": o.tool_per_session,
            "payload": o.payload.map(|p| serde_json::json!({ "mass_kg": p.mass_kg, "com_mm": p.com_mm })),
            "split": o.split.describe(),
            "seed": o.seed,
            "outlier_threshold": o.outlier_threshold,
            "prediction_draws": o.prediction_draws,
        },
    })
}

/// What `calsim calibrate` prints: the models' held-out errors, the choice, the outliers, where the
/// report went.
pub fn terminal(c: &Calibration, dir: &Path) -> String {
    let mut s = String::new();
    let m = &c.measurements;
    let _ = writeln!(
        s,
        "calsim calibrate: {} from {}{} ({}, {}, {}, {})",
        c.model.name(),
        m.path.display(),
        if m.header.simulated { " (simulated data)" } else { "" },
        count(m.points.len(), "point"),
        count(m.poses.len(), "pose"),
        count(m.sessions.len(), "session"),
        count(m.targets.len(), "target")
    );
    let _ = writeln!(
        s,
        "{:<18} {:>6} {:>24} {:>34} {:>12} {:>26}",
        "model", "params", "CV held-out RMS / p95 mm", "held-out RMS measured / predicted", "fit RMS mm", "k-fold all poses RMS / p95"
    );
    let cv_cell = |cv: &super::validation::CrossValidation| {
        if cv.points > 0 { format!("{:.4} / {:.4}", cv.stats.rms, cv.stats.p95) } else { "-".into() }
    };
    for r in std::iter::once(&c.before).chain(&c.models) {
        let held = r.held_out.as_ref().map_or_else(|| "no model".into(), |h| format!("{:.4} / {:.4}", h.measured.rms, h.predicted.rms));
        let mark = if r.kind.is_some() && r.kind == c.chosen().kind { "  <- chosen" } else { "" };
        let _ = writeln!(
            s,
            "{:<18} {:>6} {:>24} {:>34} {:>12.4} {:>26}{mark}",
            r.name(),
            r.layout.robot.len(),
            cv_cell(&r.cv),
            held,
            r.fit.stats.rms,
            cv_cell(&r.cv_all)
        );
    }
    if let Some(r) = c.chosen().held_out.as_ref().and_then(|h| h.rotation) {
        let _ = writeln!(s, "held-out rotation error of the chosen model (mdeg): mean {:.2}, max {:.2}, RMS {:.2}", r.mean, r.max, r.rms);
    }
    let _ = writeln!(
        s,
        "CV: {} folds of the training poses (chooses the model); k-fold all poses: {} (comparable with a k-fold CV of the literature)",
        c.options.folds,
        kfold_words(c)
    );
    let unid: Vec<String> = c.chosen().unidentifiable.iter().map(|u| u.name.clone()).collect();
    if !unid.is_empty() {
        let _ =
            writeln!(s, "kept nominal by the chosen model ({}; the poses cannot separate them): {}", c.chosen().name(), unid.join(", "));
    }
    if let Some((_, why)) = c.inert.first() {
        let names: Vec<&str> = c.inert.iter().map(|(n, _)| n.as_str()).collect();
        let _ = writeln!(s, "{}: kept nominal, in no model: {why}", names.join(", "));
    }
    for (name, why) in &c.chosen().undetermined {
        let _ = writeln!(s, "{name}: not determined (kept nominal): {why}");
    }
    let f = &c.chosen().fit;
    let lines: Vec<String> = (0..f.outlier.len()).filter(|&i| f.outlier[i]).map(|i| format!("line {}", m.points[i].line)).collect();
    let shown = match lines.len() {
        0 => String::new(),
        1..=10 => format!(" ({})", lines.join(", ")),
        n => format!(" ({}, and {} more in summary.md)", lines[..10].join(", "), n - 10),
    };
    let mode = match c.options.outliers {
        super::OutlierMode::Off => " (--outliers off: none flagged)",
        super::OutlierMode::Report => "; kept in every figure (--outliers report)",
        super::OutlierMode::Reject => "; left out of every figure (--outliers reject)",
    };
    let _ = writeln!(s, "outliers: {}{shown}{mode}", lines.len());
    if let Some(h) = c.chosen().held_out.as_ref().filter(|h| h.flagged > 0) {
        let _ = writeln!(
            s,
            "held-out RMS of the chosen model: {:.4} mm with the {} flagged, {:.4} mm without",
            h.with_flagged.rms,
            count(h.flagged, "point"),
            h.without_flagged.rms
        );
    }
    let _ = write!(s, "report, robot.toml, robot.urdf and calibration.yaml in {}", dir.display());
    s
}

/// `n` and the noun, plural unless `n` is 1 ("1 session", "3 sessions").
fn count(n: usize, noun: &str) -> String {
    if n == 1 { format!("1 {noun}") } else { format!("{n} {noun}s") }
}

/// The loud line `calsim calibrate` writes to standard error when the outlier rule flags points:
/// how many, what was done with them, and the chosen model's held-out RMS with and without them.
pub fn outlier_warning(c: &Calibration) -> Option<String> {
    let flagged: Vec<usize> = (0..c.flagged.len()).filter(|&i| c.flagged[i]).collect();
    if flagged.is_empty() {
        return None;
    }
    let m = &c.measurements;
    let mut lines: Vec<String> = flagged.iter().take(10).map(|&i| m.points[i].line.to_string()).collect();
    if flagged.len() > 10 {
        lines.push(format!("and {} more", flagged.len() - 10));
    }
    let done = match c.options.outliers {
        super::OutlierMode::Reject => "LEFT OUT of every fit and figure (--outliers reject)",
        _ => "kept in every fit and figure (--outliers report; `reject` leaves them out)",
    };
    let held = c
        .chosen()
        .held_out
        .as_ref()
        .filter(|h| h.flagged > 0)
        .map(|h| {
            format!(
                "; held-out RMS of the chosen model {:.4} mm with the {} flagged, {:.4} mm without",
                h.with_flagged.rms,
                count(h.flagged, "point"),
                h.without_flagged.rms
            )
        })
        .unwrap_or_default();
    Some(format!(
        "calsim calibrate: WARNING: {} of {} flagged as outliers ({} {}), {done}{held}",
        count(flagged.len(), "point"),
        m.points.len(),
        if flagged.len() == 1 { "line" } else { "lines" },
        lines.join(", ")
    ))
}

fn stats_cells(s: &ErrorStats) -> String {
    format!("{:.4} | {:.4} | {:.4} | {:.4} | {:.4}", s.mean, s.median, s.p95, s.max, s.rms)
}

/// `summary.md`: what was measured, the models compared, the held-out errors, the outliers, the
/// parameters, bases and tools, the figures.
pub fn summary(c: &Calibration) -> String {
    let mut s = String::new();
    let m = &c.measurements;
    let _ = writeln!(s, "# Calibration of {} from {}\n", c.model.name(), m.path.display());
    if m.header.simulated {
        let _ = writeln!(s, "**Simulated data**: the measurement file says `# simulated = true`.\n");
    }
    let _ = writeln!(
        s,
        "Robot file {}; {} at {} in {} ({}), {} ({}){}; joints: {}.\n",
        c.robot.path.display(),
        count(m.points.len(), "point"),
        count(m.poses.len(), "pose"),
        count(m.sessions.len(), "session"),
        m.sessions.join(", "),
        count(m.targets.len(), "target"),
        m.targets.join(", "),
        if m.rows_left_out > 0 { format!(", {} rows of other targets left out (`# targets`)", m.rows_left_out) } else { String::new() },
        if m.coupled { "the controller's values, through the robot file's [[coupling]]" } else { "as given (no coupling)" }
    );
    let payload = &c.robot.nominal.data().payload;
    let _ = writeln!(
        s,
        "Payload at the flange: {} (the mass the joint compliances act through with the links' masses).\n",
        match (&c.options.payload, payload.mass_kg > 0.0) {
            (Some(p), _) =>
                format!("{} kg at [{}, {}, {}] mm in the flange frame (--payload-kg)", p.mass_kg, p.com_mm[0], p.com_mm[1], p.com_mm[2]),
            (None, true) => format!("{} kg (the robot file's [payload])", payload.mass_kg),
            (None, false) => "none".into(),
        }
    );
    if let Some((_, why)) = c.inert.first() {
        let names: Vec<&str> = c.inert.iter().map(|(n, _)| n.as_str()).collect();
        let _ = writeln!(s, "**{} kept nominal, in no model**: {why}.\n", names.join(", "));
    }
    if m.orientation_columns {
        orientation_section(&mut s, c);
    }
    models_section(&mut s, c);
    kfold_section(&mut s, c);
    held_out_section(&mut s, c);
    outliers_section(&mut s, c);
    parameters_section(&mut s, c);
    s
}

fn models_section(s: &mut String, c: &Calibration) {
    let _ = writeln!(
        s,
        "## Models compared by held-out error\n\n{}-fold cross-validation over the training poses (each fold's poses predicted by a fit \
         without them); chosen: the least mean squared error, unless a simpler model is within one standard error of it on the \
         paired difference. **Chosen: {}.**\n",
        c.options.folds,
        c.chosen().name()
    );
    let _ = writeln!(
        s,
        "| model | robot parameters | kept nominal (unidentifiable on these poses) | CV points | CV mean | CV median | CV p95 | CV max | CV RMS | paired MSE difference to the chosen (SE), mm^2 | RMS of the fit on every point |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|---|");
    for r in &c.models {
        let unid: Vec<String> = r.unidentifiable.iter().map(|u| format!("{} (with {})", u.name, u.with.join(" "))).collect();
        let paired = if r.kind == c.chosen().kind {
            "(chosen)".to_string()
        } else {
            format!("{:+.2e} ({:.1e})", r.against_chosen.0, r.against_chosen.1)
        };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {paired} | {:.4} |",
            r.name(),
            r.layout.robot.len(),
            if unid.is_empty() { "-".into() } else { unid.join("; ") },
            r.cv.points,
            stats_cells(&r.cv.stats),
            r.fit.stats.rms
        );
        for (f, why) in &r.cv.failed {
            let _ = writeln!(s, "|  | fold {f} gave no model ({why}) | | | | | | | | | |");
        }
    }
    let _ = writeln!(s);
}

/// The k-fold cross-validation over every pose in words.
fn kfold_words(c: &Calibration) -> String {
    match c.options.kfold_by {
        super::KFoldBy::Pose => format!("{} folds of every pose, held-out ones included (`--kfold-by pose`)", c.assignment.folds_all),
        super::KFoldBy::Session => format!(
            "a fold per session, {} folds (`--kfold-by session`: each session's base registered on its own points)",
            c.assignment.folds_all
        ),
    }
}

fn kfold_section(s: &mut String, c: &Calibration) {
    let _ = writeln!(
        s,
        "### k-fold cross-validation over every pose (mm)\n\n{}: every pose predicted once, by a fit without its fold. This is \
         the figure to compare with a k-fold cross-validation of the literature; the CV above (training poses only) chooses the \
         model, so that the held-out poses below stay out of the choice.\n",
        kfold_words(c)
    );
    let _ = writeln!(s, "| model | points | mean | median | p95 | max | RMS |\n|---|---|---|---|---|---|---|");
    for r in &c.models {
        let _ = writeln!(s, "| {} | {} | {} |", r.name(), r.cv_all.points, stats_cells(&r.cv_all.stats));
        for (f, why) in &r.cv_all.failed {
            let _ = writeln!(s, "|  | fold {f} gave no model ({why}) | | | | | |");
        }
    }
    let _ = writeln!(s);
}

/// The orientation readings: how they are weighted, each probe's rotation on the flange, and the
/// chosen model's rotation errors (fit on every point, held out).
fn orientation_section(s: &mut String, c: &Calibration) {
    let m = &c.measurements;
    let read = m.points.iter().filter(|p| p.orientation.is_some()).count();
    let sigma = if m.points.iter().any(|p| p.sigma_rad.is_some()) {
        "the file's sigma_deg".to_string()
    } else {
        format!("{} mdeg about each axis (--orientation-noise-mdeg)", c.options.orientation_noise_mdeg)
    };
    let against = if m.points.iter().any(|p| p.sigma_mm.is_some()) {
        "the file's sigma_mm".to_string()
    } else {
        format!("{} mm per coordinate (--position-noise-mm)", c.options.position_noise_mm)
    };
    let _ = writeln!(
        s,
        "## Orientation readings\n\n{} with an orientation reading (quat_w .. quat_z: the probe's frame in the session's frame). Each \
         gives three rotation residuals `log(R_measured R_model^T)` beside its position's, weighted by {sigma} against the positions' \
         {against}; each target with readings has its probe's rotation on the flange among the unknowns.\n",
        count(read, "point")
    );
    let _ = writeln!(s, "| target | flange_from_probe: rotation vector (deg) | std about x, y, z (mdeg) |\n|---|---|---|");
    for (t, r) in c.probe_rotations.iter().enumerate() {
        if let Some(r) = r {
            let v = r.flange_from_probe.scaled_axis().map(f64::to_degrees);
            let _ = writeln!(
                s,
                "| {} | {:.5}, {:.5}, {:.5} | {:.2}, {:.2}, {:.2} |",
                m.targets[t], v.x, v.y, v.z, r.std_mdeg[0], r.std_mdeg[1], r.std_mdeg[2]
            );
        }
    }
    let fit: Vec<f64> = c.chosen().fit.rotation_base_mdeg.iter().flatten().map(|v| v.norm()).collect();
    let f = ErrorStats::of(&fit);
    let _ = writeln!(
        s,
        "\nRotation errors of the chosen model ({}), mdeg: fit on every point mean {:.2}, max {:.2}, RMS {:.2}.",
        c.chosen().name(),
        f.mean,
        f.max,
        f.rms
    );
    if let Some(r) = c.chosen().held_out.as_ref().and_then(|h| h.rotation) {
        let _ = writeln!(s, "Held-out points: mean {:.2}, max {:.2}, RMS {:.2}.", r.mean, r.max, r.rms);
    }
    let _ = writeln!(s);
}

fn held_out_section(s: &mut String, c: &Calibration) {
    let train = c.assignment.held_out.iter().filter(|h| !**h).count();
    let _ = writeln!(
        s,
        "## Held-out errors, measured and predicted (mm)\n\nHeld out: {} ({} of {} poses); every model fitted on the other {} poses. \
         Predicted: the training fit's covariance `sigma^2 (J^T J)^-1` and noise estimate propagated to the held-out points ({} draws; \
         max: the median over the draws of the largest). A measured error well above the prediction is an error the model does not \
         hold (or a noise estimate too small).\n",
        c.options.split.describe(),
        c.assignment.held_out.len() - train,
        c.assignment.held_out.len(),
        train,
        c.options.prediction_draws
    );
    let _ = writeln!(s, "| model | points | measured mean | median | p95 | max | RMS | predicted mean | median | p95 | max | RMS |");
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|---|---|");
    for r in std::iter::once(&c.before).chain(&c.models) {
        match &r.held_out {
            Some(h) => {
                let _ = writeln!(s, "| {} | {} | {} | {} |", r.name(), h.points, stats_cells(&h.measured), stats_cells(&h.predicted));
            }
            None => {
                let why = r.held_out_why.as_deref().unwrap_or("-");
                let _ = writeln!(s, "| {} | - | the training fit gave no model ({why}) | | | | | | | | | |", r.name());
            }
        }
    }
    let flagged_held = c.chosen().held_out.as_ref().map_or(0, |h| h.flagged);
    if flagged_held > 0 {
        let _ = writeln!(
            s,
            "\nWith and without the {} flagged as outliers (measured; mean | median | p95 | max | RMS):\n\n| model | with | without |\n|---|---|---|",
            count(flagged_held, "held-out point")
        );
        for r in std::iter::once(&c.before).chain(&c.models) {
            if let Some(h) = &r.held_out {
                let _ = writeln!(s, "| {} | {} | {} |", r.name(), stats_cells(&h.with_flagged), stats_cells(&h.without_flagged));
            }
        }
    }
    let (b, a) = (&c.before.fit, &c.chosen().fit);
    let _ = writeln!(
        s,
        "\n### Every point, fitted on every point (mm)\n\n| | mean | median | p95 | max | RMS | outliers | noise estimate per coordinate |\n|---|---|---|---|---|---|---|---|"
    );
    for (name, f) in [("before (nominal robot, fitted bases and tools)", b), (c.chosen().name(), a)] {
        let outliers = f.outlier.iter().filter(|o| **o).count();
        let _ = writeln!(s, "| {name} | {} | {outliers} | {:.4} |", stats_cells(&f.stats), f.sigma_hat);
    }
    let _ = writeln!(s);
}

fn outliers_section(s: &mut String, c: &Calibration) {
    let f = &c.chosen().fit;
    let m = &c.measurements;
    let flagged: Vec<usize> = (0..f.outlier.len()).filter(|&i| f.outlier[i]).collect();
    let done = match c.options.outliers {
        super::OutlierMode::Off => "`--outliers off`: no point is flagged; every fit and statistic of this report uses every point.",
        super::OutlierMode::Report => {
            "`--outliers report`: the flagged points are listed here and kept in every fit and statistic of this report \
             (`--outliers reject` leaves them out); the held-out errors are given with and without them below."
        }
        super::OutlierMode::Reject => {
            "`--outliers reject`: every fit and statistic of this report leaves out the flagged points; the held-out errors are \
             given with and without them below."
        }
    };
    let _ = writeln!(
        s,
        "## Outliers\n\nOutliers are decided once, by the {} model's robust fit on every point: a point whose residual exceeds {} \
         robust standard deviations (a Gaussian point does so with probability {:.1e}) is flagged, the fit repeated without the \
         flagged points until the flags settle. {done} {} of {} points flagged.\n",
        c.outliers_by,
        c.options.outlier_threshold,
        chi3_tail(c.options.outlier_threshold),
        flagged.len(),
        f.outlier.len()
    );
    if flagged.len() * 20 > f.outlier.len() {
        let _ = writeln!(
            s,
            "**More than 5 % of the points are flagged**: more than measurement faults usually explain. The model may miss an \
             effect (see the residuals per joint), or the file may mix robots, tools or joint conventions.\n"
        );
    }
    if flagged.is_empty() {
        return;
    }
    let _ = writeln!(s, "| line | pose | session | target | error after, mm | robust standard deviations |\n|---|---|---|---|---|---|");
    for i in flagged {
        let p = &m.points[i];
        let pose = &m.poses[p.pose];
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {:.4} | {:.1} |",
            p.line, pose.label, m.sessions[pose.session], m.targets[p.target], f.errors_mm[i], f.normalized[i]
        );
    }
    let _ = writeln!(s);
}

/// P(chi(3) > t), for the summary's statement of the threshold's false-alarm rate.
fn chi3_tail(t: f64) -> f64 {
    // P(chi^2_3 > x) = erfc(sqrt(x/2)) + sqrt(2x/pi) exp(-x/2); erfc by Simpson on its integral.
    let x = t * t;
    let a = (x / 2.0).sqrt();
    let n = 2000;
    let upper = a + 12.0;
    let h = (upper - a) / n as f64;
    let f = |u: f64| (-u * u).exp();
    let mut sum = f(a) + f(upper);
    for k in 1..n {
        sum += f(a + k as f64 * h) * if k % 2 == 1 { 4.0 } else { 2.0 };
    }
    let erfc = 2.0 / std::f64::consts::PI.sqrt() * sum * h / 3.0;
    erfc + (2.0 * x / std::f64::consts::PI).sqrt() * (-x / 2.0).exp()
}

fn parameters_section(s: &mut String, c: &Calibration) {
    let _ = writeln!(
        s,
        "## Parameters of the calibrated robot ({} model)\n\nStandard deviations from the fit's covariance on every point. The \
         calibrated robot file is `robot.toml` (the robot file's base and tool; the bases and tools below are those of the \
         measurements), with `robot.urdf` and `calibration.yaml`.\n",
        c.chosen().name()
    );
    let _ = writeln!(
        s,
        "| parameter | unit | nominal | calibrated | correction | std | correction / std | status |\n|---|---|---|---|---|---|---|---|"
    );
    let mut weak = Vec::new();
    for e in &c.estimates {
        let u = e.id.unit();
        let (n, v) = (u.from_internal(e.nominal), u.from_internal(e.value));
        let t = (e.value - e.nominal) / e.std;
        if e.status == ParamStatus::Identified && t.abs() < 2.0 {
            weak.push(e.id.name());
        }
        let _ = writeln!(
            s,
            "| {} | {} | {:.4} | {:.5} | {:+.5} | {:.5} | {:+.1} | {} |",
            e.id.name(),
            u.symbol(),
            n,
            v,
            v - n,
            u.from_internal(e.std),
            t,
            status(&e.status)
        );
    }
    let _ = writeln!(
        s,
        "\nCorrections within two standard deviations of zero (the data do not tell them from the nominal; fix them with \
         `--params` and compare the held-out errors): {}.",
        if weak.is_empty() { "none".into() } else { weak.join(", ") }
    );
    frames_section(s, c);
    correlations(s, c);
}

fn frames_section(s: &mut String, c: &Calibration) {
    let _ = writeln!(
        s,
        "\n### Bases (measuring frame from the robot's base, eq. 7)\n\n| session | x mm | y mm | z mm | alpha deg | beta deg | gamma deg | std x, y, z mm | std about z, y, x deg |\n|---|---|---|---|---|---|---|---|---|"
    );
    for b in &c.bases {
        let f = &b.session_from_base;
        let d = |v: f64| v.to_degrees();
        let _ = writeln!(
            s,
            "| {} | {:.4} | {:.4} | {:.4} | {:.5} | {:.5} | {:.5} | {:.4}, {:.4}, {:.4} | {:.5}, {:.5}, {:.5} |",
            b.session,
            f.x,
            f.y,
            f.z,
            d(f.alpha),
            d(f.beta),
            d(f.gamma),
            b.std[0],
            b.std[1],
            b.std[2],
            d(b.std[3]),
            d(b.std[4]),
            d(b.std[5])
        );
    }
    let _ = writeln!(
        s,
        "\n### Targets (position in the flange frame)\n\n| target | x mm | y mm | z mm | std x, y, z mm |\n|---|---|---|---|---|"
    );
    for t in &c.tools {
        let _ = writeln!(
            s,
            "| {} | {:.4} | {:.4} | {:.4} | {:.4}, {:.4}, {:.4} |",
            t.target, t.flange_mm.x, t.flange_mm.y, t.flange_mm.z, t.std_mm[0], t.std_mm[1], t.std_mm[2]
        );
    }
}

fn correlations(s: &mut String, c: &Calibration) {
    let ids: Vec<String> = c.estimates.iter().filter(|e| e.status == ParamStatus::Identified).map(|e| e.id.name()).collect();
    let mut strong = Vec::new();
    for a in 0..ids.len() {
        for b in a + 1..ids.len() {
            let r = c.correlation[(a, b)];
            if r.abs() > 0.9 {
                strong.push(format!("{} and {}: {r:+.3}", ids[a], ids[b]));
            }
        }
    }
    let _ = writeln!(
        s,
        "\nCorrelations beyond 0.9 in magnitude (all in `correlation.parquet`): {}.\n",
        if strong.is_empty() { "none".into() } else { strong.join("; ") }
    );
}
