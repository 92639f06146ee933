//! The twin's tables and its section of `summary.md`, every figure read from them: `twin.parquet`
//! (one row: the split, the thresholds, the held-out gain, the `[learned]` levels),
//! `twin_decomposition.parquet` (a row per part of the residual), `twin_notes.parquet` (what
//! cannot be separated or was not estimated), `twin_families.parquet` (a row per family tried),
//! `twin_effects.parquet` (a row per kept coefficient), `twin_confounded.parquet` (a row per
//! pair of families the poses do not tell apart) and `twin_correlation.parquet` (a row per bin of
//! pairs of points: the residual left's correlation by the joint-space distance of their poses).

use polars::prelude::Column;

use super::{Level, Twin};
use crate::io::results::{Head, Results, Row, Summary, cell};

const TWIN: &str = "twin.parquet";

/// The twin's tables and its section of the summary, added to `r`.
pub fn results_into(t: &Twin, r: &mut Results<'_>) -> std::io::Result<()> {
    tables(t, r)?;
    correlation_table(t, r)?;
    section(&mut r.summary);
    correlation_section(&mut r.summary);
    Ok(())
}

/// The twin's section of a summary as `summary.md` shows it, rendered from its tables (or the
/// error that kept it from rendering).
pub fn markdown(t: &Twin) -> String {
    let mut r = Results::new("twin", Head::Run(crate::io::manifest::Provenance::of_run(&[])));
    results_into(t, &mut r).and_then(|()| r.summary_text()).unwrap_or_else(|e| e.to_string())
}

/// The parts of the residual in the summary's order: name, level (`None`: not estimated) and
/// what the summary says then.
fn parts(t: &Twin) -> Vec<(&'static str, Option<&Level>, &'static str)> {
    let d = &t.decomposition;
    let mut rows = vec![("residual (total)", Some(&d.total), ""), ("instrument noise", d.instrument.as_ref(), "not estimated")];
    rows.extend(d.instrument_checks.iter().map(|l| ("instrument noise (check)", Some(l), "")));
    rows.push(("repeatability", d.repeatability.as_ref(), "not estimated"));
    if let Some(l) = &d.together {
        rows.push(("instrument + repeatability (not separable)", Some(l), ""));
    }
    rows.extend([
        ("systematic (model misses)", d.systematic.as_ref(), "not separated from the random part"),
        ("explained by the kept effects", Some(&d.explained), ""),
        ("residual after the kept effects", Some(&d.after), ""),
        ("systematic left (per-pose error)", d.left.as_ref(), "not separated from the random part"),
    ]);
    rows
}

fn tables(t: &Twin, r: &mut Results<'_>) -> std::io::Result<()> {
    r.table(TWIN, twin_columns(t))?;
    let p = parts(t);
    let level = |f: fn(&Level) -> f64| p.iter().map(|x| x.1.map(f)).collect::<Vec<_>>();
    r.table(
        "twin_decomposition.parquet",
        vec![
            Column::new("part".into(), p.iter().map(|x| x.0).collect::<Vec<_>>()),
            Column::new("estimated".into(), p.iter().map(|x| x.1.is_some()).collect::<Vec<_>>()),
            Column::new("sigma_mm".into(), level(|l| l.sigma_mm)),
            Column::new("interval_low_mm".into(), level(|l| l.interval_mm[0])),
            Column::new("interval_high_mm".into(), level(|l| l.interval_mm[1])),
            Column::new("estimated_by".into(), p.iter().map(|x| x.1.map_or_else(|| x.2.to_string(), |l| l.by.clone())).collect::<Vec<_>>()),
        ],
    )?;
    r.table("twin_notes.parquet", vec![Column::new("note".into(), t.decomposition.notes.clone())])?;
    let f = &t.families;
    r.table(
        "twin_families.parquet",
        vec![
            Column::new("family".into(), f.iter().map(|x| x.family.name()).collect::<Vec<_>>()),
            Column::new("coefficients".into(), f.iter().map(|x| x.columns as u32).collect::<Vec<_>>()),
            Column::new("gain_per_pose".into(), f.iter().map(|x| x.gain.0).collect::<Vec<_>>()),
            Column::new("gain_se".into(), f.iter().map(|x| x.gain.1).collect::<Vec<_>>()),
            Column::new("kept".into(), f.iter().map(|x| x.kept).collect::<Vec<_>>()),
            Column::new("absorbed".into(), f.iter().map(|x| x.absorbed.join(", ")).collect::<Vec<_>>()),
        ],
    )?;
    let e = &t.effects;
    let half = |x: &super::Effect| super::Z95 * x.std;
    r.table(
        "twin_effects.parquet",
        vec![
            Column::new("family".into(), e.iter().map(|x| x.coefficient.family.name()).collect::<Vec<_>>()),
            Column::new("coefficient".into(), e.iter().map(|x| x.coefficient.name.clone()).collect::<Vec<_>>()),
            Column::new("value".into(), e.iter().map(|x| x.value).collect::<Vec<_>>()),
            Column::new("std".into(), e.iter().map(|x| x.std).collect::<Vec<_>>()),
            Column::new("low_95".into(), e.iter().map(|x| x.value - half(x)).collect::<Vec<_>>()),
            Column::new("high_95".into(), e.iter().map(|x| x.value + half(x)).collect::<Vec<_>>()),
            Column::new("unit".into(), e.iter().map(|x| x.coefficient.unit()).collect::<Vec<_>>()),
        ],
    )?;
    let c = &t.confounded;
    r.table(
        "twin_confounded.parquet",
        vec![
            Column::new("family_a".into(), c.iter().map(|x| x.0.clone()).collect::<Vec<_>>()),
            Column::new("family_b".into(), c.iter().map(|x| x.1.clone()).collect::<Vec<_>>()),
            Column::new("cosine".into(), c.iter().map(|x| x.2).collect::<Vec<_>>()),
        ],
    )?;
    Ok(())
}

/// `twin.parquet`'s one row.
fn twin_columns(t: &Twin) -> Vec<Column> {
    let (d, l) = (&t.decomposition, &t.learned);
    let whole = |name: &str, v: usize| Column::new(name.into(), vec![v as u32]);
    let number = |name: &str, v: f64| Column::new(name.into(), vec![v]);
    vec![
        whole("points", d.points),
        whole("poses", d.poses),
        whole("cv_poses", t.cv_poses),
        number("keep_se", super::KEEP_SE),
        number("keep_se_scanned", super::KEEP_SE_SCANNED),
        whole("held_out_poses", t.held_out_poses),
        Column::new("held_out_judged".into(), vec![t.held_out_gain.is_some()]),
        Column::new("held_out_gain_per_pose".into(), vec![t.held_out_gain.map(|g| g.0)]),
        Column::new("held_out_gain_se".into(), vec![t.held_out_gain.map(|g| g.1)]),
        number("confounded_cos", super::CONFOUNDED_COS),
        number("repeatability_mm", l.repeatability_mm),
        number("repeatability_std_mm", l.repeatability_std_mm),
        number("pose_error_mdeg", l.pose_error_mdeg),
        number("pose_error_std_mdeg", l.pose_error_std_mdeg),
        whole("harmonics", l.harmonic.len()),
        number("pose_error_length_rad", l.pose_error_length_rad),
        number("pose_error_length_std_rad", l.pose_error_length_std_rad),
        Column::new("length_fitted".into(), vec![t.length.is_some()]),
        Column::new("length_low_rad".into(), vec![t.length.as_ref().map(|x| x.interval[0])]),
        Column::new("length_high_rad".into(), vec![t.length.as_ref().map(|x| x.interval[1])]),
        Column::new("length_replicates".into(), vec![t.length.as_ref().map(|x| x.replicates as u64)]),
        Column::new("length_censored_low".into(), vec![t.length.as_ref().map(|x| x.censored[0] as u64)]),
        Column::new("length_censored_high".into(), vec![t.length.as_ref().map(|x| x.censored[1] as u64)]),
    ]
}

/// The twin's section: the decomposition, the families with their cross-validated evidence, the
/// kept effects, what cannot be told apart, the `[learned]` levels.
fn section(parts: &mut Summary<'_>) {
    parts.text_from(TWIN, |r| {
        format!(
            "## The twin: what the model misses\n\nThe chosen model refitted on the calibration split ({} points at {} poses, outliers \
             left out); its residual per coordinate, decomposed (95 % intervals). `twin.toml` is the calibrated robot file with the \
             `[learned]` table below.\n\n",
            r.u64("points"),
            r.u64("poses")
        )
    });
    let known = |show: fn(&Row<'_>) -> String| move |r: &Row<'_>| if r.bool("estimated") { show(r) } else { "-".to_string() };
    let cells = vec![
        cell("part", |r| r.str("part")),
        cell("per coordinate, mm", known(|r| format!("{:.4}", r.f64("sigma_mm")))),
        cell("95 % interval", known(|r| format!("{:.4}-{:.4}", r.f64("interval_low_mm"), r.f64("interval_high_mm")))),
        cell("estimated by", |r| r.str("estimated_by")),
    ];
    parts.table("twin_decomposition.parquet", Summary::all_rows(), cells);
    parts.text_from(TWIN, |r| {
        let notes = r.of("twin_notes.parquet", 0);
        let mut pieces: Vec<String> = (0..notes.height()).map(|i| format!("- {}\n", notes.at(i).str("note"))).collect();
        pieces.push(format!(
            "### Effect families\n\nEach fitted jointly with the model (its columns projected off the model's Jacobian) on the calibration \
             split only, judged by cross-validation over its folds ({} poses): kept, one at a time, while adding it lowers the \
             cross-validated squared error per pose by more than {} paired standard errors (5 % shared by the nine families; {} for a \
             joint's harmonic of the order, among {}-{}, that explains most of the residual: 5 % shared by every order of every joint \
             it could have been). Columns the model's parameters absorb are left out (the calibrated robot carries them).\n\n",
            r.u64("cv_poses"),
            r.f64("keep_se"),
            r.f64("keep_se_scanned"),
            super::effects::SCANNED_ORDERS.start(),
            super::effects::SCANNED_ORDERS.end()
        ));
        pieces.join("\n")
    });
    let cells = vec![
        cell("family", |r| r.str("family")),
        cell("coefficients", |r| r.u64("coefficients").to_string()),
        cell("cross-validated gain per pose", |r| format!("{:.3e}", r.f64("gain_per_pose"))),
        cell("paired s.e.", |r| format!("{:.3e}", r.f64("gain_se"))),
        cell("kept", |r| if r.bool("kept") { "yes" } else { "no" }.to_string()),
        cell("absorbed by the model", |r| Some(r.str("absorbed")).filter(|a| !a.is_empty()).unwrap_or_else(|| "-".into())),
    ];
    parts.table("twin_families.parquet", Summary::all_rows(), cells);
    parts.text_from(TWIN, |r| {
        let text = effects(r) + &confounded(r) + &learned(r);
        // The families' table ends with the empty line that the first paragraph starts with.
        text.strip_prefix('\n').unwrap_or(&text).to_string()
    });
}

/// The kept effects with their intervals and their gain on the held-out poses.
fn effects(r: &Row<'_>) -> String {
    let e = r.of("twin_effects.parquet", 0);
    if e.height() == 0 {
        return "\nNo effect family kept.\n".into();
    }
    let mut s = "\n| kept effect | value | 95 % interval | unit |\n|---|---|---|---|\n".to_string();
    for x in (0..e.height()).map(|i| e.at(i)) {
        let f = |name: &str| x.f64(name);
        s += &format!(
            "| {}: {} | {:.4} | {:.4} to {:.4} | {} |\n",
            x.str("family"),
            x.str("coefficient"),
            f("value"),
            f("low_95"),
            f("high_95"),
            x.str("unit")
        );
    }
    if r.bool("held_out_judged") {
        s += &format!(
            "\nOn the {} held-out poses (not used to choose), the kept effects lower the squared error per pose by {:.3e} \
             (paired s.e. {:.3e}).\n",
            r.u64("held_out_poses"),
            r.f64("held_out_gain_per_pose"),
            r.f64("held_out_gain_se")
        );
    }
    s
}

/// The pairs of families the poses do not tell apart.
fn confounded(r: &Row<'_>) -> String {
    let c = r.of("twin_confounded.parquet", 0);
    if c.height() == 0 {
        return format!(
            "\nEvery pair of families is told apart (cosine of the smallest principal angle at most {}).\n",
            r.f64("confounded_cos")
        );
    }
    let mut s =
        "\nNot told apart by these poses (cosine of the smallest principal angle of their columns after the model):\n\n".to_string();
    for x in (0..c.height()).map(|i| c.at(i)) {
        s += &format!("- {} and {}: {:.3}\n", x.str("family_a"), x.str("family_b"), x.f64("cosine"));
    }
    s
}

/// The `[learned]` levels.
fn learned(r: &Row<'_>) -> String {
    let smooth = if r.bool("length_fitted") {
        format!(
            " The per-pose error is a smooth field: pose_error_length_rad = {:.3} (pose_error_length_std_rad = {:.3}), its level \
             above as the fit of the correlation by pose distance gives it.",
            r.f64("pose_error_length_rad"),
            r.f64("pose_error_length_std_rad")
        )
    } else {
        String::new()
    };
    format!(
        "\n`[learned]`: repeatability_mm = {:.4} (ISO 9283 RP of the repeatability per coordinate; repeatability_std_mm = {:.4}, \
         from its 95 % interval: a plan draws the level per world), pose_error_mdeg = {:.3} \
         (pose_error_std_mdeg = {:.3}, from its 95 % interval: a plan draws the level per world), {} harmonics.{smooth}\n",
        r.f64("repeatability_mm"),
        r.f64("repeatability_std_mm"),
        r.f64("pose_error_mdeg"),
        r.f64("pose_error_std_mdeg"),
        r.u64("harmonics")
    )
}

const CORRELATION: &str = "twin_correlation.parquet";

/// The smooth field's length as the fit of the bins gives it, or why there is none.
fn fitted_length(r: &Row<'_>) -> String {
    if !r.bool("length_fitted") {
        return "The bins do not resolve a length (too few bins with an interval, the best fit at the end of the lengths tried, or no \
                level left): the twin keeps the error independent per pose."
            .to_string();
    }
    format!(
        "Fitted as a smooth joint-space field (the bins' correlations against what such a field leaves after the fit): length \
         {:.2} rad (95 % {:.2}-{:.2}), RMS per joint {:.3} mdeg; intervals from {} bootstrap replicates of the fit ({} at the \
         least length tried, {} at the greatest).",
        r.f64("pose_error_length_rad"),
        r.f64("length_low_rad"),
        r.f64("length_high_rad"),
        r.f64("pose_error_mdeg"),
        r.u64("length_replicates"),
        r.u64("length_censored_low"),
        r.u64("length_censored_high")
    )
}

/// `twin_correlation.parquet`: a row per bin of pairs ([`super::shape::correlation`]).
fn correlation_table(t: &Twin, r: &mut Results<'_>) -> std::io::Result<()> {
    let b = &t.correlation.bins;
    let f = |g: fn(&super::shape::CorrelationBin) -> f64| b.iter().map(g).collect::<Vec<_>>();
    r.table(
        CORRELATION,
        vec![
            Column::new("bin".into(), b.iter().map(|x| x.label.clone()).collect::<Vec<_>>()),
            Column::new("same_pose".into(), b.iter().map(|x| x.same_pose).collect::<Vec<_>>()),
            Column::new("distance_low_rad".into(), f(|x| x.distance_rad[0])),
            Column::new("distance_high_rad".into(), f(|x| x.distance_rad[1])),
            Column::new("point_pairs".into(), b.iter().map(|x| x.pairs as u64).collect::<Vec<_>>()),
            Column::new("pose_pairs".into(), b.iter().map(|x| x.pose_pairs as u64).collect::<Vec<_>>()),
            Column::new("correlation".into(), f(|x| x.correlation)),
            Column::new("low_95".into(), f(|x| x.interval[0])),
            Column::new("high_95".into(), f(|x| x.interval[1])),
            Column::new("white".into(), f(|x| x.white)),
            Column::new("above_white".into(), b.iter().map(|x| x.above_white()).collect::<Vec<_>>()),
        ],
    )?;
    Ok(())
}

/// The residual left's shape: its correlation between points by the distance of their poses, and
/// the line that says whether it is smooth or independent per pose.
fn correlation_section(parts: &mut Summary<'_>) {
    parts.text_from(TWIN, |_| {
        format!(
            "### The error left between poses\n\nThe residual after the kept effects on the calibration split (weighted by the points' \
         uncertainties), its correlation between two points (the mean product of their residuals over the mean squared residual of \
         a point) by the distance of their poses in joint space (Euclidean over the six joint values): the other targets at one pose, \
         then the pairs of distinct poses by the rank of their distance. 95 % intervals by the delete-one jackknife over poses; \
         beside them, the value the fit itself gives white residuals (minus the hat matrix's share of the pair). Above {max} \
         training poses, every k-th pose and its points (the least k that leaves at most {max}: the pairs grow as the square of \
         the poses).\n\n",
            max = super::shape::MAX_POSES
        )
    });
    let cells = vec![
        cell("pairs of points", |r| r.str("bin")),
        cell("distance, rad", |r| format!("{:.2}-{:.2}", r.f64("distance_low_rad"), r.f64("distance_high_rad"))),
        cell("point pairs (pose pairs)", |r| format!("{} ({})", r.u64("point_pairs"), r.u64("pose_pairs"))),
        cell("correlation", |r| format!("{:.3}", r.f64("correlation"))),
        cell("95 % interval", |r| format!("{:.3} to {:.3}", r.f64("low_95"), r.f64("high_95"))),
        cell("white residuals", |r| format!("{:.3}", r.f64("white"))),
    ];
    parts.table(CORRELATION, Summary::all_rows(), cells);
    parts.text_from(TWIN, |r| {
        let c = r.of(CORRELATION, 0);
        let rows: Vec<Row<'_>> = (0..c.height()).map(|i| c.at(i)).collect();
        let distinct: Vec<&Row<'_>> = rows.iter().filter(|x| !x.bool("same_pose")).collect();
        let Some(nearest) = distinct.first() else {
            return "Fewer than two poses: the shape of the error left is not estimated.\n".to_string();
        };
        let above: Vec<&&Row<'_>> = distinct.iter().filter(|x| x.bool("above_white")).collect();
        let shown = |x: &Row<'_>| {
            format!(
                "{:.3} ({:.3} to {:.3}) against {:.3} for white residuals, at {:.2}-{:.2} rad",
                x.f64("correlation"),
                x.f64("low_95"),
                x.f64("high_95"),
                x.f64("white"),
                x.f64("distance_low_rad"),
                x.f64("distance_high_rad")
            )
        };
        let line = match above.last() {
            Some(far) => format!(
                "**Smooth**: the error left is correlated between distinct poses up to {:.2} rad apart (nearest pairs: {}). {}",
                far.f64("distance_high_rad"),
                shown(nearest),
                fitted_length(r)
            ),
            None => format!(
                "**Independent per pose**: no bin of distinct poses is correlated beyond what the fit gives white residuals (nearest \
                 pairs: {}).",
                shown(nearest)
            ),
        };
        let same = rows
            .iter()
            .find(|x| x.bool("same_pose"))
            .map(|x| {
                format!(
                    " At one pose, the targets' residuals correlate {:.3} ({:.3} to {:.3}): the share of the residual a pose's targets \
                     have in common.",
                    x.f64("correlation"),
                    x.f64("low_95"),
                    x.f64("high_95")
                )
            })
            .unwrap_or_default();
        format!("{line}{same}\n")
    });
}
