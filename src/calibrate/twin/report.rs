//! The twin's section of `summary.md`.

use std::fmt::Write as _;

use super::{Level, Twin};

fn row(s: &mut String, part: &str, l: Option<&Level>, none: &str) {
    match l {
        Some(l) => {
            let _ = writeln!(s, "| {part} | {:.4} | {:.4}-{:.4} | {} |", l.sigma_mm, l.interval_mm[0], l.interval_mm[1], l.by);
        }
        None => {
            let _ = writeln!(s, "| {part} | - | - | {none} |");
        }
    }
}

/// The twin as a section of the summary: the decomposition, the families with their held-out
/// evidence, the kept effects, what cannot be told apart.
pub fn markdown(t: &Twin) -> String {
    let d = &t.decomposition;
    let mut s = String::new();
    let _ = writeln!(s, "## The twin: what the model misses\n");
    let _ = writeln!(
        s,
        "The chosen model refitted on the calibration split ({} points at {} poses, outliers left out); its residual \
         per coordinate, decomposed (95 % intervals). `twin.toml` is the calibrated robot file with the `[learned]` table below.\n",
        d.points, d.poses
    );
    let _ = writeln!(s, "| part | per coordinate, mm | 95 % interval | estimated by |\n|---|---|---|---|");
    row(&mut s, "residual (total)", Some(&d.total), "");
    row(&mut s, "instrument noise", d.instrument.as_ref(), "not estimated");
    for l in &d.instrument_checks {
        row(&mut s, "instrument noise (check)", Some(l), "");
    }
    row(&mut s, "repeatability", d.repeatability.as_ref(), "not estimated");
    if let Some(l) = &d.together {
        row(&mut s, "instrument + repeatability (not separable)", Some(l), "");
    }
    row(&mut s, "systematic (model misses)", d.systematic.as_ref(), "not separated from the random part");
    row(&mut s, "explained by the kept effects", Some(&d.explained), "");
    row(&mut s, "residual after the kept effects", Some(&d.after), "");
    row(&mut s, "systematic left (per-pose error)", d.left.as_ref(), "not separated from the random part");
    for n in &d.notes {
        let _ = writeln!(s, "\n- {n}");
    }
    let _ = writeln!(
        s,
        "\n### Effect families\n\nEach fitted jointly with the model (its columns projected off the model's Jacobian) on the calibration \
         split only, judged by cross-validation over its folds ({} poses): kept, one at a time, while adding it lowers the \
         cross-validated squared error per pose by more than {} paired standard errors (5 % shared by the nine families). Columns \
         the model's parameters absorb are left out (the calibrated robot carries them).\n",
        t.cv_poses,
        super::KEEP_SE
    );
    let _ = writeln!(
        s,
        "| family | coefficients | cross-validated gain per pose | paired s.e. | kept | absorbed by the model |\n|---|---|---|---|---|---|"
    );
    for f in &t.families {
        let absorbed = if f.absorbed.is_empty() { "-".to_string() } else { f.absorbed.join(", ") };
        let _ = writeln!(
            s,
            "| {} | {} | {:.3e} | {:.3e} | {} | {absorbed} |",
            f.family.name(),
            f.columns,
            f.gain.0,
            f.gain.1,
            if f.kept { "yes" } else { "no" }
        );
    }
    if t.effects.is_empty() {
        let _ = writeln!(s, "\nNo effect family kept.");
    } else {
        let _ = writeln!(s, "\n| kept effect | value | 95 % interval | unit |\n|---|---|---|---|");
        for e in &t.effects {
            let h = super::Z95 * e.std;
            let _ = writeln!(
                s,
                "| {}: {} | {:.4} | {:.4} to {:.4} | {} |",
                e.coefficient.family.name(),
                e.coefficient.name,
                e.value,
                e.value - h,
                e.value + h,
                e.coefficient.unit()
            );
        }
    }
    if let (Some((g, se)), false) = (t.held_out_gain, t.effects.is_empty()) {
        let _ = writeln!(
            s,
            "\nOn the {} held-out poses (not used to choose), the kept effects lower the squared error per pose by {g:.3e} \
             (paired s.e. {se:.3e}).",
            t.held_out_poses
        );
    }
    if t.confounded.is_empty() {
        let _ = writeln!(
            s,
            "\nEvery pair of families is told apart (cosine of the smallest principal angle at most {}).",
            super::CONFOUNDED_COS
        );
    } else {
        let _ = writeln!(s, "\nNot told apart by these poses (cosine of the smallest principal angle of their columns after the model):\n");
        for (a, b, cos) in &t.confounded {
            let _ = writeln!(s, "- {a} and {b}: {cos:.3}");
        }
    }
    let l = &t.learned;
    let _ = writeln!(
        s,
        "\n`[learned]`: repeatability_mm = {:.4} (ISO 9283 RP of the repeatability per coordinate; repeatability_std_mm = {:.4}, \
         from its 95 % interval: a plan draws the level per world), pose_error_mdeg = {:.3} \
         (pose_error_std_mdeg = {:.3}, from its 95 % interval: a plan draws the level per world), {} harmonics.",
        l.repeatability_mm,
        l.repeatability_std_mm,
        l.pose_error_mdeg,
        l.pose_error_std_mdeg,
        l.harmonic.len()
    );
    s
}
