//! The calibration's report directory, written atomically (`io::out_dir::write_atomically`):
//! the calibrated robot file, its URDF and YAML overlay (through `export`'s writers), the model
//! before calibration, the tables (`points`, `models`, `parameters`, `bases`, `tools`,
//! `correlation`, as parquet), the figures and `summary.md`, and `manifest.json` with the inputs'
//! and tables' sha256.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use sha2::Digest;

use super::{Calibration, ParamStatus};
use crate::io::results::{Head, Results};

mod summary;
mod tables;

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
        if !plans.0.is_empty() {
            r.table("plans.parquet", super::plan::columns(plans.0))?;
        }
    }
    if let Ok(t) = twin {
        r.file("twin.toml", twin_text(c, t).map_err(std::io::Error::other)?);
    }
    r.summary.text("\n");
    match twin {
        Ok(t) => super::twin::results_into(t, &mut r)?,
        Err(why) => {
            r.summary.text(format!("## The twin: what the model misses\n\nNot fitted: {why}\n"));
        }
    }
    crate::io::results::write(out, r).map(|w| w.dest)
}

/// The report of `c` as results: the robot files, the tables, the manifest's fields, the figures
/// and the summary.
fn results<'a>(name: &str, c: &'a Calibration) -> std::io::Result<Results<'a>> {
    let mut r = Results::new(name, Head::Run(crate::io::manifest::Provenance::of_run(&[])));
    robot_files(c, &mut r)?;
    tables::tables(c, &mut r)?;
    r.fields(fields(c))?;
    if c.options.plots {
        r.draw(Box::new(move |dir| super::plots::write(dir, c)));
    }
    summary::summary(&mut r.summary);
    r.summary.figures("");
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
    models_lines(c, &mut s);
    let _ = writeln!(
        s,
        "CV: {} folds of the training poses (chooses the model); k-fold all poses: {} (comparable with a k-fold CV of the literature)",
        c.options.folds,
        summary::kfold_words(c.options.kfold_by.name(), c.assignment.folds_all as u64)
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
    let lines = flagged_lines(&c.chosen().fit.outlier, m);
    let shown = shown_lines(&lines);
    let mode = match c.options.outliers {
        super::OutlierMode::Off => " (--outliers off: none flagged)",
        super::OutlierMode::Report => "; kept in every figure (--outliers report)",
        super::OutlierMode::Reject => "; left out of every figure (--outliers reject)",
    };
    let _ = writeln!(s, "outliers: {}{shown}{mode}", lines.len());
    if c.measurements.orientation_columns {
        let flagged = flagged_lines(&c.readings_flagged.flagged, m);
        let _ = writeln!(s, "orientation outliers: {}{}{mode}", flagged.len(), shown_lines(&flagged));
    }
    if let Some(h) = c.chosen().held_out.as_ref().filter(|h| h.readings_flagged > 0 && c.options.outliers == super::OutlierMode::Report) {
        let (with, without) = (h.rotation.unwrap_or_default(), h.rotation_without_flagged.unwrap_or_default());
        let _ = writeln!(
            s,
            "held-out rotation RMS of the chosen model: {:.2} mdeg with the {} flagged, {:.2} mdeg without",
            with.rms,
            count(h.readings_flagged, "reading"),
            without.rms
        );
    }
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

/// The terminal's table of the models (CV, held-out and fit errors, the choice) and the chosen
/// model's held-out rotation error.
fn models_lines(c: &Calibration, s: &mut String) {
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
}

/// The file lines of the points flagged in `flags` ("line 12").
fn flagged_lines(flags: &[bool], m: &super::measurements::Measurements) -> Vec<String> {
    (0..flags.len()).filter(|&i| flags[i]).map(|i| format!("line {}", m.points[i].line)).collect()
}

/// The first ten of `lines` in parentheses, the rest counted.
fn shown_lines(lines: &[String]) -> String {
    match lines.len() {
        0 => String::new(),
        1..=10 => format!(" ({})", lines.join(", ")),
        n => format!(" ({}, and {} more in summary.md)", lines[..10].join(", "), n - 10),
    }
}

/// `n` and the noun, plural unless `n` is 1 ("1 session", "3 sessions").
fn count(n: usize, noun: &str) -> String {
    if n == 1 { format!("1 {noun}") } else { format!("{n} {noun}s") }
}

/// The loud line `calsim calibrate` writes to standard error when the outlier rule flags points:
/// how many, what was done with them, and the chosen model's held-out RMS with and without them.
pub fn outlier_warning(c: &Calibration) -> Option<String> {
    let warnings: Vec<String> = [point_warning(c), reading_warning(c)].into_iter().flatten().collect();
    (!warnings.is_empty()).then(|| warnings.join("\n"))
}

/// The warning line of [`outlier_warning`] for the orientation readings.
fn reading_warning(c: &Calibration) -> Option<String> {
    let flags = &c.readings_flagged.flagged;
    let flagged: Vec<usize> = (0..flags.len()).filter(|&i| flags[i]).collect();
    if flagged.is_empty() {
        return None;
    }
    let m = &c.measurements;
    let lines: Vec<String> = flagged.iter().map(|&i| m.points[i].line.to_string()).collect();
    let done = match c.options.outliers {
        super::OutlierMode::Reject => "LEFT OUT of every fit (--outliers reject; their positions kept)",
        _ => "kept in every fit and figure (--outliers report; `reject` leaves them out)",
    };
    let read = m.points.iter().filter(|p| p.orientation.is_some()).count();
    Some(format!(
        "calsim calibrate: WARNING: {} of {read} flagged as outliers ({} {}), {done}",
        count(flagged.len(), "orientation reading"),
        if flagged.len() == 1 { "line" } else { "lines" },
        shown(&lines)
    ))
}

/// The first ten of `lines` joined, the rest counted.
fn shown(lines: &[String]) -> String {
    let mut out: Vec<String> = lines.iter().take(10).cloned().collect();
    if lines.len() > 10 {
        out.push(format!("and {} more", lines.len() - 10));
    }
    out.join(", ")
}

/// The warning line of [`outlier_warning`] for the points.
fn point_warning(c: &Calibration) -> Option<String> {
    let flagged: Vec<usize> = (0..c.flagged.len()).filter(|&i| c.flagged[i]).collect();
    if flagged.is_empty() {
        return None;
    }
    let m = &c.measurements;
    let lines: Vec<String> = flagged.iter().map(|&i| m.points[i].line.to_string()).collect();
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
        shown(&lines)
    ))
}
