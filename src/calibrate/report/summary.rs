//! `summary.md` of a calibration as [`Summary`] parts, every figure read from the tables of
//! [`super::tables`]: what was measured, the models compared, the k-fold over every pose, the
//! orientation readings, the held-out errors, the outliers, the parameters, bases and tools.

use polars::prelude::DataFrame;

use super::count;
use super::tables::STATS;
use crate::io::results::{Cell, Row, Rows, Summary, cell};

const RUN: &str = "calibration.parquet";
const MODELS: &str = "models.parquet";
const ERRORS: &str = "model_errors.parquet";

/// The summary's parts (the figures follow them).
pub fn summary(parts: &mut Summary<'_>) {
    header(parts);
    orientation(parts);
    models(parts);
    kfold(parts);
    held_out(parts);
    every_point(parts);
    outliers(parts);
    parameters(parts);
    frames(parts);
}

/// The statistics of the columns `{prefix}_{stat}_mm` of `r`, as Markdown cells.
fn stats_cells(r: &Row<'_>, prefix: &str) -> String {
    STATS.iter().map(|s| format!("{:.4}", r.f64(&format!("{prefix}_{s}_mm")))).collect::<Vec<_>>().join(" | ")
}

/// The rows of `table` (read through `r`) whose column `name` holds `value`.
fn rows_where<'r>(r: &'r Row<'_>, table: &str, name: &str, value: &str) -> Vec<Row<'r>> {
    (0..r.of(table, 0).height()).map(|i| r.of(table, i)).filter(|x| x.str(name) == value).collect()
}

/// The index of the chosen model's row of `models.parquet`.
fn chosen(r: &Row<'_>) -> usize {
    let m = r.of(MODELS, 0);
    (0..m.height()).find(|&i| m.at(i).bool("chosen")).unwrap_or(0)
}

/// The rows of a frame whose boolean column `name` is true.
fn flagged(name: &'static str) -> Rows<'static> {
    Box::new(move |f: &DataFrame| {
        let column = f.column(name).ok().and_then(|c| c.bool().ok());
        column.map_or_else(Vec::new, |b| (0..b.len()).filter(|&i| b.get(i) == Some(true)).collect())
    })
}

/// The k-fold cross-validation over every pose in words (`by`: `--kfold-by`; `folds`: its folds).
pub fn kfold_words(by: &str, folds: u64) -> String {
    match by {
        "session" => {
            format!("a fold per session, {folds} folds (`--kfold-by session`: each session's base registered on its own points)")
        }
        _ => format!("{folds} folds of every pose, held-out ones included (`--kfold-by pose`)"),
    }
}

/// The payload at the flange in words.
fn payload(r: &Row<'_>) -> String {
    match r.str("payload_from").as_str() {
        "--payload-kg" => format!(
            "{} kg at [{}, {}, {}] mm in the flange frame (--payload-kg)",
            r.f64("payload_kg"),
            r.f64("payload_com_x_mm"),
            r.f64("payload_com_y_mm"),
            r.f64("payload_com_z_mm")
        ),
        "robot file" => format!("{} kg (the robot file's [payload])", r.f64("payload_kg")),
        _ => "none".into(),
    }
}

/// The title, the files, what was measured, the payload, the compliances in no model.
fn header(parts: &mut Summary<'_>) {
    parts.text_from(RUN, |r| {
        let mut s = format!("# Calibration of {} from {}\n\n", r.str("robot"), r.str("measurements"));
        if r.bool("simulated") {
            s += "**Simulated data**: the measurement file says `# simulated = true`.\n\n";
        }
        let (bases, tools) = (r.of("bases.parquet", 0), r.of("tools.parquet", 0));
        let names = |t: &Row<'_>, column: &str| (0..t.height()).map(|i| t.at(i).str(column)).collect::<Vec<_>>().join(", ");
        let left = r.u64("rows_left_out");
        s += &format!(
            "Robot file {}; {} at {} in {} ({}), {} ({}){}; joints: {}.\n\n",
            r.str("robot_file"),
            count(r.of("points.parquet", 0).height(), "point"),
            count(r.u64("poses") as usize, "pose"),
            count(bases.height(), "session"),
            names(&bases, "session"),
            count(tools.height(), "target"),
            names(&tools, "target"),
            if left > 0 { format!(", {left} rows of other targets left out (`# targets`)") } else { String::new() },
            if r.bool("coupled") { "the controller's values, through the robot file's [[coupling]]" } else { "as given (no coupling)" }
        );
        s += &format!("Payload at the flange: {} (the mass the joint compliances act through with the links' masses).\n\n", payload(r));
        let inert = r.str("inert");
        if !inert.is_empty() {
            s += &format!("**{inert} kept nominal, in no model**: {}.\n\n", r.str("inert_reason"));
        }
        s
    });
}

/// The rows "fold f gave no model (why)" of the model `model` in the cross-validation `which`,
/// each with `empty` empty cells after it.
fn failed_folds(r: &Row<'_>, model: &str, which: &str, empty: usize) -> String {
    rows_where(r, "failed_folds.parquet", "model", model)
        .iter()
        .filter(|f| f.str("cross_validation") == which)
        .map(|f| format!("|  | fold {} gave no model ({}) |{}\n", f.u64("fold"), f.str("reason"), " |".repeat(empty)))
        .collect()
}

fn models(parts: &mut Summary<'_>) {
    parts.text_from(RUN, |r| {
        let mut s = format!(
            "## Models compared by held-out error\n\n{}-fold cross-validation over the training poses (each fold's poses predicted by a fit \
             without them); chosen: the least mean squared error, unless a simpler model is within one standard error of it on the \
             paired difference. **Chosen: {}.**\n\n",
            r.u64("folds"),
            r.str("chosen")
        );
        s += "| model | robot parameters | kept nominal (unidentifiable on these poses) | CV points | CV mean | CV median | CV p95 | CV max | CV RMS | paired MSE difference to the chosen (SE), mm^2 | RMS of the fit on every point |\n";
        s += "|---|---|---|---|---|---|---|---|---|---|---|\n";
        let models = r.of(MODELS, 0);
        for m in (1..models.height()).map(|i| models.at(i)) {
            let name = m.str("model");
            let unid: Vec<String> = rows_where(r, "unidentifiable.parquet", "model", &name)
                .iter()
                .map(|u| format!("{} (with {})", u.str("parameter"), u.str("with")))
                .collect();
            let paired = if m.bool("chosen") {
                "(chosen)".to_string()
            } else {
                format!("{:+.2e} ({:.1e})", m.f64("cv_paired_mse_difference_mm2"), m.f64("cv_paired_standard_error_mm2"))
            };
            s += &format!(
                "| {name} | {} | {} | {} | {} | {paired} | {:.4} |\n",
                m.u64("parameters"),
                if unid.is_empty() { "-".into() } else { unid.join("; ") },
                m.u64("cv_points"),
                stats_cells(&m, "cv"),
                m.f64("fit_rms_mm")
            );
            s += &failed_folds(r, &name, "training poses", 9);
        }
        s + "\n"
    });
}

fn kfold(parts: &mut Summary<'_>) {
    parts.text_from(RUN, |r| {
        let mut s = format!(
            "### k-fold cross-validation over every pose (mm)\n\n{}: every pose predicted once, by a fit without its fold. This is \
             the figure to compare with a k-fold cross-validation of the literature; the CV above (training poses only) chooses the \
             model, so that the held-out poses below stay out of the choice.\n\n",
            kfold_words(&r.str("kfold_by"), r.u64("kfold_all_folds"))
        );
        s += "| model | points | mean | median | p95 | max | RMS |\n|---|---|---|---|---|---|---|\n";
        let models = r.of(MODELS, 0);
        for m in (1..models.height()).map(|i| models.at(i)) {
            let name = m.str("model");
            s += &format!("| {name} | {} | {} |\n", m.u64("kfold_all_points"), stats_cells(&m, "kfold_all"));
            s += &failed_folds(r, &name, "every pose", 5);
        }
        s + "\n"
    });
}

/// The orientation readings: how they are weighted, each probe's rotation on the flange, and the
/// chosen model's rotation errors (fit on every point, held out).
fn orientation(parts: &mut Summary<'_>) {
    parts.text_from(RUN, |r| {
        if !r.bool("orientation_columns") {
            return String::new();
        }
        let sigma = match r.f64("orientation_noise_mdeg") {
            v if v.is_nan() => "the file's sigma_deg".to_string(),
            v => format!("{v} mdeg about each axis (--orientation-noise-mdeg)"),
        };
        let against = match r.f64("position_noise_mm") {
            v if v.is_nan() => "the file's sigma_mm".to_string(),
            v => format!("{v} mm per coordinate (--position-noise-mm)"),
        };
        let mut s = format!(
            "## Orientation readings\n\n{} with an orientation reading (quat_w .. quat_z: the probe's frame in the session's frame). Each \
             gives three rotation residuals `log(R_measured R_model^T)` beside its position's, weighted by {sigma} against the positions' \
             {against}; each target with readings has its probe's rotation on the flange among the unknowns.\n\n",
            count(r.u64("orientation_points") as usize, "point")
        );
        s += "| target | flange_from_probe: rotation vector (deg) | std about x, y, z (mdeg) |\n|---|---|---|\n";
        let probes = r.of("probe_rotations.parquet", 0);
        for p in (0..probes.height()).map(|i| probes.at(i)) {
            let f = |name: &str| p.f64(name);
            s += &format!(
                "| {} | {:.5}, {:.5}, {:.5} | {:.2}, {:.2}, {:.2} |\n",
                p.str("target"),
                f("rotation_x_deg"),
                f("rotation_y_deg"),
                f("rotation_z_deg"),
                f("std_x_mdeg"),
                f("std_y_mdeg"),
                f("std_z_mdeg")
            );
        }
        let e = r.of(ERRORS, chosen(r));
        s += &format!(
            "\nRotation errors of the chosen model ({}), mdeg: fit on every point mean {:.2}, max {:.2}, RMS {:.2}.\n",
            r.str("chosen"),
            e.f64("rotation_fit_mean_mdeg"),
            e.f64("rotation_fit_max_mdeg"),
            e.f64("rotation_fit_rms_mdeg")
        );
        if e.bool("held_out_rotation") {
            let f = |name: &str| e.f64(name);
            s += &format!(
                "Held-out points: mean {:.2}, max {:.2}, RMS {:.2}.\n",
                f("held_out_rotation_mean_mdeg"),
                f("held_out_rotation_max_mdeg"),
                f("held_out_rotation_rms_mdeg")
            );
        }
        s + "\n"
    });
}

fn held_out(parts: &mut Summary<'_>) {
    parts.text_from(RUN, |r| {
        let (held, train) = (r.u64("held_out_poses"), r.u64("training_poses"));
        let mut s = format!(
            "## Held-out errors, measured and predicted (mm)\n\nHeld out: {} ({held} of {} poses); every model fitted on the other {train} poses. \
             Predicted: the training fit's covariance `sigma^2 (J^T J)^-1` and noise estimate propagated to the held-out points ({} draws; \
             max: the median over the draws of the largest). A measured error well above the prediction is an error the model does not \
             hold (or a noise estimate too small).\n\n",
            r.str("split"),
            held + train,
            r.u64("prediction_draws")
        );
        s += "| model | points | measured mean | median | p95 | max | RMS | predicted mean | median | p95 | max | RMS |\n";
        s += "|---|---|---|---|---|---|---|---|---|---|---|---|\n";
        let rows: Vec<(Row<'_>, Row<'_>)> = (0..r.of(MODELS, 0).height()).map(|i| (r.of(MODELS, i), r.of(ERRORS, i))).collect();
        for (m, e) in &rows {
            if e.bool("held_out_fitted") {
                let cells = (stats_cells(m, "held_out"), stats_cells(m, "predicted"));
                s += &format!("| {} | {} | {} | {} |\n", m.str("model"), m.u64("held_out_points"), cells.0, cells.1);
            } else {
                let why = Some(e.str("held_out_failure")).filter(|w| !w.is_empty()).unwrap_or_else(|| "-".into());
                s += &format!("| {} | - | the training fit gave no model ({why}) | | | | | | | | | |\n", m.str("model"));
            }
        }
        let flagged = r.of(ERRORS, chosen(r)).u64("held_out_flagged") as usize;
        if flagged > 0 {
            s += &format!(
                "\nWith and without the {} flagged as outliers (measured; mean | median | p95 | max | RMS):\n\n| model | with | without |\n|---|---|---|\n",
                count(flagged, "held-out point")
            );
            for (_, e) in rows.iter().filter(|(_, e)| e.bool("held_out_fitted")) {
                let cells = (stats_cells(e, "held_out_with_flagged"), stats_cells(e, "held_out_without_flagged"));
                s += &format!("| {} | {} | {} |\n", e.str("model"), cells.0, cells.1);
            }
        }
        s
    });
}

/// The fit on every point before calibration and of the chosen model.
fn every_point(parts: &mut Summary<'_>) {
    parts.text("\n### Every point, fitted on every point (mm)\n\n");
    let label = |r: &Row<'_>| if r.index() == 0 { "before (nominal robot, fitted bases and tools)".to_string() } else { r.str("model") };
    let stat = |s: &'static str| move |r: &Row<'_>| format!("{:.4}", r.f64(&format!("fit_{s}_mm")));
    let rows = Box::new(|f: &DataFrame| std::iter::once(0).chain(flagged("chosen")(f)).collect());
    let cells = vec![
        cell("", label),
        cell("mean", stat("mean")),
        cell("median", stat("median")),
        cell("p95", stat("p95")),
        cell("max", stat("max")),
        cell("RMS", stat("rms")),
        cell("outliers", |r| r.u64("fit_outliers").to_string()),
        cell("noise estimate per coordinate", |r| format!("{:.4}", r.of(ERRORS, r.index()).f64("noise_estimate_mm"))),
    ];
    parts.table(MODELS, rows, cells);
}

/// The outlier rule, what was done with the flagged points, and the flagged points.
fn outliers(parts: &mut Summary<'_>) {
    parts.text_from(RUN, |r| {
        let points = r.of("points.parquet", 0);
        let (flagged, total) = ((0..points.height()).filter(|&i| points.at(i).bool("outlier")).count(), points.height());
        let done = match r.str("outliers").as_str() {
            "off" => "`--outliers off`: no point is flagged; every fit and statistic of this report uses every point.",
            "report" => {
                "`--outliers report`: the flagged points are listed here and kept in every fit and statistic of this report \
                 (`--outliers reject` leaves them out); the held-out errors are given with and without them below."
            }
            _ => {
                "`--outliers reject`: every fit and statistic of this report leaves out the flagged points; the held-out errors are \
                 given with and without them below."
            }
        };
        let mut s = format!(
            "## Outliers\n\nOutliers are decided once, by the {} model's robust fit on every point: a point whose residual exceeds {} \
             robust standard deviations (a Gaussian point does so with probability {:.1e}) is flagged, the fit repeated without the \
             flagged points until the flags settle. {done} {flagged} of {total} points flagged.\n\n",
            r.str("outliers_by"),
            r.f64("outlier_threshold"),
            r.f64("outlier_false_alarm"),
        );
        if flagged * 20 > total {
            s += "**More than 5 % of the points are flagged**: more than measurement faults usually explain. The model may miss an \
                  effect (see the residuals per joint), or the file may mix robots, tools or joint conventions.\n\n";
        }
        s
    });
    let mut cells = where_cells();
    cells.extend([
        cell("error after, mm", |r| format!("{:.4}", r.f64("error_after_mm"))),
        cell("robust standard deviations", |r| format!("{:.1}", r.f64("normalized_residual"))),
    ]);
    parts.table_if_rows("points.parquet", flagged("outlier"), cells);
    reading_outliers(parts);
}

/// A flagged point's line, pose, session and target (points.parquet's columns).
fn where_cells() -> Vec<Cell<'static>> {
    vec![
        cell("line", |r| r.u64("line").to_string()),
        cell("pose", |r| r.str("pose")),
        cell("session", |r| r.str("session")),
        cell("target", |r| r.str("target")),
    ]
}

/// The outlier rule on the orientation readings and the flagged readings (a file with
/// orientation columns).
fn reading_outliers(parts: &mut Summary<'_>) {
    parts.text_from(RUN, |r| {
        if !r.bool("orientation_columns") || r.str("outliers") == "off" {
            return String::new();
        }
        let points = r.of("points.parquet", 0);
        let flagged = (0..points.height()).filter(|&i| points.at(i).bool("reading_outlier")).count();
        let done = if r.str("outliers") == "reject" {
            "left out of every fit (their points' positions kept: the fits are those of the file without these readings)"
        } else {
            "kept in every fit and statistic"
        };
        let mut s = format!(
            "The orientation readings go through the same rule on their own robust scale: a reading whose weighted rotation \
             residual exceeds {} robust standard deviations of the readings' is flagged, independently of its point's position; \
             flagged readings are {done}. {} of {} flagged.\n\n",
            r.f64("outlier_threshold"),
            flagged,
            count(r.u64("orientation_points") as usize, "reading"),
        );
        let errors = r.of(ERRORS, chosen(r));
        let with = errors.f64("held_out_rotation_rms_mdeg");
        let without = errors.f64("held_out_rotation_without_flagged_rms_mdeg");
        let held = errors.u64("held_out_readings_flagged") as usize;
        if held > 0 && r.str("outliers") == "report" {
            s += &format!(
                "Held-out rotation RMS of the chosen model: {with:.2} mdeg with the {} flagged, {without:.2} mdeg without.\n\n",
                count(held, "held-out reading")
            );
        }
        s
    });
    let mut cells = where_cells();
    cells.push(cell("robust standard deviations (readings)", |r| format!("{:.1}", r.f64("reading_normalized_residual"))));
    parts.table_if_rows("points.parquet", flagged("reading_outlier"), cells);
}

/// A parameter's correction over its standard deviation.
fn t(r: &Row<'_>) -> f64 {
    (r.f64("calibrated") - r.f64("nominal")) / r.f64("std")
}

/// The parameters of the calibrated robot, and those the data do not tell from the nominal.
fn parameters(parts: &mut Summary<'_>) {
    parts.text_from(RUN, |r| {
        format!(
            "## Parameters of the calibrated robot ({} model)\n\nStandard deviations from the fit's covariance on every point. The \
             calibrated robot file is `robot.toml` (the robot file's base and tool; the bases and tools below are those of the \
             measurements), with `robot.urdf` and `calibration.yaml`.\n\n",
            r.str("chosen")
        )
    });
    let f = |d: usize, name: &'static str| move |r: &Row<'_>| format!("{:.d$}", r.f64(name));
    let cells = vec![
        cell("parameter", |r| r.str("parameter")),
        cell("unit", |r| r.str("unit")),
        cell("nominal", f(4, "nominal")),
        cell("calibrated", f(5, "calibrated")),
        cell("correction", |r| format!("{:+.5}", r.f64("calibrated") - r.f64("nominal"))),
        cell("std", f(5, "std")),
        cell("correction / std", |r| format!("{:+.1}", t(r))),
        cell("status", |r| r.str("status")),
    ];
    parts.table("parameters.parquet", Summary::all_rows(), cells);
    parts.text_from(RUN, |r| {
        let p = r.of("parameters.parquet", 0);
        let weak: Vec<String> = (0..p.height())
            .map(|i| p.at(i))
            .filter(|e| e.str("status") == "identified" && t(e).abs() < 2.0)
            .map(|e| e.str("parameter"))
            .collect();
        format!(
            "Corrections within two standard deviations of zero (the data do not tell them from the nominal; fix them with \
             `--params` and compare the held-out errors): {}.\n\n",
            if weak.is_empty() { "none".into() } else { weak.join(", ") }
        )
    });
}

/// The bases, the tools and the strong correlations.
fn frames(parts: &mut Summary<'_>) {
    let f = |d: usize, name: &'static str| move |r: &Row<'_>| format!("{:.d$}", r.f64(name));
    let three = |d: usize, names: [&'static str; 3]| {
        move |r: &Row<'_>| format!("{:.d$}, {:.d$}, {:.d$}", r.f64(names[0]), r.f64(names[1]), r.f64(names[2]))
    };
    parts.text("### Bases (measuring frame from the robot's base, eq. 7)\n\n");
    let cells = vec![
        cell("session", |r| r.str("session")),
        cell("x mm", f(4, "x_mm")),
        cell("y mm", f(4, "y_mm")),
        cell("z mm", f(4, "z_mm")),
        cell("alpha deg", f(5, "alpha_deg")),
        cell("beta deg", f(5, "beta_deg")),
        cell("gamma deg", f(5, "gamma_deg")),
        cell("std x, y, z mm", three(4, ["std_x_mm", "std_y_mm", "std_z_mm"])),
        cell("std about z, y, x deg", three(5, ["std_alpha_deg", "std_beta_deg", "std_gamma_deg"])),
    ];
    parts.table("bases.parquet", Summary::all_rows(), cells);
    parts.text("### Targets (position in the flange frame)\n\n");
    let cells = vec![
        cell("target", |r| r.str("target")),
        cell("x mm", f(4, "flange_x_mm")),
        cell("y mm", f(4, "flange_y_mm")),
        cell("z mm", f(4, "flange_z_mm")),
        cell("std x, y, z mm", three(4, ["std_x_mm", "std_y_mm", "std_z_mm"])),
    ];
    parts.table("tools.parquet", Summary::all_rows(), cells);
    parts.text_from(RUN, |r| {
        let n = (r.of("correlation.parquet", 0).height() as f64).sqrt().round() as usize;
        let mut strong = Vec::new();
        for (a, b) in (0..n).flat_map(|a| (a + 1..n).map(move |b| (a, b))) {
            let x = r.of("correlation.parquet", a * n + b);
            let v = x.f64("correlation");
            if v.abs() > 0.9 {
                strong.push(format!("{} and {}: {v:+.3}", x.str("parameter_a"), x.str("parameter_b")));
            }
        }
        format!(
            "Correlations beyond 0.9 in magnitude (all in `correlation.parquet`): {}.\n\n",
            if strong.is_empty() { "none".into() } else { strong.join("; ") }
        )
    });
}

/// P(chi(3) > t), for the summary's statement of the threshold's false-alarm rate.
pub fn chi3_tail(t: f64) -> f64 {
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
