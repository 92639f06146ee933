//! A tracker plan's tables and `plan.md` rendered from them by the results' one renderer
//! ([`crate::io::results::Summary`]), so a figure printed and a figure stored cannot differ:
//! `plan.parquet` (one row: the plan's inputs and every figure of its text), `tour_moves.parquet`
//! (a row per straight move of the tour through a collision), `worlds.parquet` (the predicted
//! held-out median per world), `unidentifiable.parquet` (a row per parameter the poses cannot
//! fix), and with an objective `objective.parquet` (one row) and `search.parquet` (a row per
//! count scored), with the comparison `comparison.parquet` (a row per selection).

use polars::prelude::{Column, DataFrame};

use super::select::{TourMove, tour_moves, tour_words};
use super::{Comparison, Outcome, Plan, Search, TRAINING, VALIDATION, plot, record, spec};
use crate::io::results::{Head, Results, Row, Summary, cell, read_row};

/// The plan's one-row table.
pub const PLAN: &str = "plan.parquet";
/// The tour's colliding moves.
pub const TOUR_MOVES: &str = "tour_moves.parquet";
/// The predicted held-out median per world.
pub const WORLDS: &str = "worlds.parquet";
/// The parameters the poses cannot fix.
pub const UNIDENTIFIABLE: &str = "unidentifiable.parquet";
/// The objective (one row).
pub const OBJECTIVE: &str = "objective.parquet";
/// The objective's search: a row per count scored.
pub const SEARCH: &str = "search.parquet";
/// DETMAX against random and greedy selection.
pub const COMPARISON: &str = "comparison.parquet";

/// A result table: its name and columns.
pub type Table = (&'static str, Vec<Column>);

fn text(name: &str, v: impl IntoIterator<Item = String>) -> Column {
    Column::new(name.into(), v.into_iter().collect::<Vec<String>>())
}

fn count(name: &str, v: impl IntoIterator<Item = usize>) -> Column {
    Column::new(name.into(), v.into_iter().map(|x| x as u32).collect::<Vec<u32>>())
}

fn number(name: &str, v: impl IntoIterator<Item = f64>) -> Column {
    Column::new(name.into(), v.into_iter().collect::<Vec<f64>>())
}

fn flag(name: &str, v: impl IntoIterator<Item = bool>) -> Column {
    Column::new(name.into(), v.into_iter().collect::<Vec<bool>>())
}

/// What `calsim plan` prints of a plan, read from its frames (`frames`: the tables by file name,
/// as written): the line `line` makes of `plan.parquet`'s row, the objective's line (with one),
/// the parameters the poses cannot identify (`kept`: what becomes of them) and the tour's moves
/// re-routed around a collision; and the warning of the moves no via path was found for.
pub fn terminal(
    frames: &[(String, DataFrame)],
    line: impl Fn(&Row<'_>) -> String,
    kept: &str,
) -> std::io::Result<(String, Option<String>)> {
    let mut out = read_row(frames, PLAN, |r| line(r) + "\n")?;
    if frames.iter().any(|(n, _)| n == OBJECTIVE) {
        out += &read_row(frames, OBJECTIVE, objective_line)?;
    }
    out += &read_row(frames, UNIDENTIFIABLE, |u| {
        let names: Vec<String> = (0..u.height()).map(|k| u.at(k).str("parameter")).collect();
        if names.is_empty() { String::new() } else { format!("cannot identify ({kept}): {}\n", names.join(", ")) }
    })?;
    let moves = read_row(frames, PLAN, |r| (r.u64("training") + r.u64("validation")).saturating_sub(1))?;
    let (routed, unrouted) = read_row(frames, TOUR_MOVES, |m| {
        let routed = (0..m.height()).filter(|&k| m.at(k).bool("routed")).count();
        (routed, m.height() - routed)
    })?;
    if routed > 0 {
        out += &format!(
            "tour: {routed} of {moves} moves re-routed around a collision through via configurations (tour.csv rows marked via, not measured)\n"
        );
    }
    let warning = (unrouted > 0).then(|| {
        format!(
            "tour: {unrouted} of {moves} moves pass through a collision and no via path was found (named in plan.md): do not drive them as straight moves"
        )
    });
    Ok((out, warning))
}

/// The line of a plan's objective (`r`: `objective.parquet`'s row): the count that met it, or the
/// best found.
fn objective_line(r: &Row<'_>) -> String {
    let rule = format!(
        "objective P(held-out {} <= {} mm) >= {} at {} confidence",
        r.str("statistic"),
        r.f64("threshold_mm"),
        r.f64("success_at_least"),
        r.f64("confidence")
    );
    if r.bool("met") {
        format!(
            "{rule}: met at {} poses, the smallest of {} counts scored (table in plan.md)\n",
            r.u64("planned"),
            r.of(SEARCH, 0).height()
        )
    } else {
        format!(
            "{rule}: NOT met up to {} poses; planned with the best found, {} poses (table in plan.md)\n",
            r.u64("most_poses"),
            r.u64("planned")
        )
    }
}

/// The first line `calsim plan` prints of a tracker plan (`r`: `plan.parquet`'s row; `seconds`:
/// the planning's wall time).
pub fn terminal_line(seconds: f64) -> impl Fn(&Row<'_>) -> String {
    move |r| {
        format!(
            "calsim plan: {} training + {} validation poses from {} feasible of {} drawn; {}",
            r.u64("training"),
            r.u64("validation"),
            r.u64("pool_feasible"),
            r.u64("pool_tried"),
            prediction_clause(r, seconds)
        )
    }
}

/// The end of a plan's first line, the same for every instrument (`r`: `plan.parquet`'s row): O1
/// against a random set's, the predicted held-out median over the worlds and the wall time.
pub fn prediction_clause(r: &Row<'_>, seconds: f64) -> String {
    format!(
        "O1 {:.6} (random set {:.6}); predicted held-out median {:.4} mm (P10-P90 {:.4}-{:.4}) over {} worlds; {seconds:.2} s",
        r.f64("o1"),
        r.f64("o1_random"),
        r.f64("median_mm"),
        r.f64("p10_mm"),
        r.f64("p90_mm"),
        r.u64("worlds_with_value")
    )
}

/// The plan file's name.
pub fn file_name(path: &std::path::Path) -> String {
    path.file_name().map_or_else(String::new, |f| f.to_string_lossy().into_owned())
}

/// Every table of a tracker plan.
pub fn tables(plan: &Plan, o: &Outcome) -> Vec<Table> {
    let mut t = vec![(PLAN, plan_columns(plan, o))];
    t.push((TOUR_MOVES, moves_columns(&tour_moves(&o.colliding_moves, &o.routing, |k| o.rows[o.tour.0[k]].label.clone()))));
    t.push((WORLDS, worlds_columns(&o.prediction.per_world_mm)));
    let u = &o.prediction.unidentifiable;
    t.push((
        UNIDENTIFIABLE,
        vec![text("parameter", u.iter().map(|u| u.name.clone())), text("moves_with", u.iter().map(|u| u.with.join(", ")))],
    ));
    if let (Some(obj), Some(search)) = (&plan.objective, &o.search) {
        t.extend(objective_tables(obj, search, plan.worlds));
    }
    if let Some(c) = &o.comparison {
        t.push((COMPARISON, comparison_columns(c)));
    }
    t
}

/// `plan.parquet`'s columns.
fn plan_columns(plan: &Plan, o: &Outcome) -> Vec<Column> {
    let p = &o.prediction;
    let one = |name: &str, v: f64| number(name, [v]);
    let at = plan.tracker.position_mm;
    vec![
        text("plan_file", [file_name(&plan.path)]),
        text("robot", [plan.robot_name.clone()]),
        text("robot_model", [plan.robot.nominal.data().name.clone()]),
        flag("robot_truth", [!plan.robot.truth.is_empty()]),
        one("tracker_x_mm", at.x),
        one("tracker_y_mm", at.y),
        one("tracker_z_mm", at.z),
        text("targets", [plan.targets.iter().map(|t| t.name.as_str()).collect::<Vec<_>>().join(", ")]),
        count("target_count", [plan.targets.len()]),
        text("model", [plan.model.name().to_string()]),
        count("pool_feasible", [o.pool.qs.len()]),
        count("pool_tried", [o.pool.tried]),
        text("pool_refused", [super::select::refusals(&o.pool)]),
        count("pool", [plan.pool]),
        count("training", [o.poses]),
        count("validation", [plan.validation]),
        one("o1", o.o1.0),
        one("o1_random", o.o1.1),
        text("detmax_params", [o.detmax_params.join(", ")]),
        count("detmax_columns", [o.detmax_params.len()]),
        one("tour_deg", o.tour.1.to_degrees()),
        one("tour_path_deg", o.routing.length_rad.to_degrees()),
        count("worlds", [plan.worlds]),
        count("worlds_with_value", [p.worlds]),
        one("noise_mm", p.noise_mm),
        one("p10_mm", p.quantiles_mm[0]),
        one("median_mm", p.quantiles_mm[1]),
        one("p90_mm", p.quantiles_mm[2]),
        one("pilot_median_mm", p.pilot_median_mm),
        text("pilot_chosen", [p.pilot_chosen.to_string()]),
        flag("twin", [p.twin]),
    ]
}

/// `tour_moves.parquet`'s columns.
pub fn moves_columns(moves: &[TourMove]) -> Vec<Column> {
    vec![
        text("from", moves.iter().map(|m| m.from.clone())),
        text("to", moves.iter().map(|m| m.to.clone())),
        count("vias", moves.iter().map(|m| m.vias)),
        flag("routed", moves.iter().map(|m| m.routed)),
    ]
}

/// `worlds.parquet`'s columns: the world (from 0) and its held-out median, mm (NaN: none).
pub fn worlds_columns(per_world_mm: &[f64]) -> Vec<Column> {
    vec![count("world", 0..per_world_mm.len()), number("heldout_median_mm", per_world_mm.iter().copied())]
}

/// `objective.parquet` and `search.parquet` (the counts in increasing order, `searched` their
/// order in the search from 1).
pub fn objective_tables(obj: &spec::Objective, search: &Search, worlds: usize) -> [Table; 2] {
    let c = search.by_count();
    let order = |n: usize| search.candidates.iter().position(|x| x.n == n).map_or(0, |k| k + 1);
    [
        (
            OBJECTIVE,
            vec![
                text("statistic", [obj.statistic.name().to_string()]),
                number("threshold_mm", [obj.threshold_mm]),
                number("success_at_least", [obj.success_at_least]),
                number("confidence", [obj.confidence]),
                count("fewest_poses", [obj.fewest_poses]),
                count("most_poses", [obj.most_poses]),
                count("worlds", [worlds]),
                flag("met", [search.chosen.is_some()]),
                count("planned", [search.planned]),
            ],
        ),
        (
            SEARCH,
            vec![
                count("poses", c.iter().map(|c| c.n)),
                count("successes", c.iter().map(|c| c.successes)),
                count("worlds", c.iter().map(|c| c.worlds)),
                number("p_success", c.iter().map(|c| c.successes as f64 / c.worlds.max(1) as f64)),
                number("lower", c.iter().map(|c| c.lower)),
                flag("meets", c.iter().map(|c| c.meets)),
                count("searched", c.iter().map(|c| order(c.n))),
            ],
        ),
    ]
}

/// `comparison.parquet`'s columns.
fn comparison_columns(c: &Comparison) -> Vec<Column> {
    let r = &c.rows;
    vec![
        text("selection", r.iter().map(|r| r.name.to_string())),
        number("o1", r.iter().map(|r| r.o1)),
        number("median_mm", r.iter().map(|r| r.median_mm.0)),
        number("median_lo_mm", r.iter().map(|r| r.median_mm.1)),
        number("median_hi_mm", r.iter().map(|r| r.median_mm.2)),
        number("p90_mm", r.iter().map(|r| r.p90_mm.0)),
        number("p90_lo_mm", r.iter().map(|r| r.p90_mm.1)),
        number("p90_hi_mm", r.iter().map(|r| r.p90_mm.2)),
        number("confidence", r.iter().map(|_| c.confidence)),
    ]
}

/// The Markdown `section` renders from `tables` (the summary as printed: `plan.md`).
pub fn render(tables: &[Table], section: impl FnOnce(&mut Summary<'_>, &[&str])) -> std::io::Result<String> {
    let mut r = Results::new("plan", Head::Run(crate::io::manifest::Provenance::of_run(&[])));
    for (name, columns) in tables {
        r.table(name, columns.clone())?;
    }
    let names: Vec<&str> = tables.iter().map(|t| t.0).collect();
    section(&mut r.summary, &names);
    r.summary_text()
}

/// `plan.md` of a tracker plan, rendered from its tables.
pub fn markdown(tables: &[Table]) -> std::io::Result<String> {
    render(tables, |s, names| {
        head(s);
        if names.contains(&OBJECTIVE) {
            objective(s, " More worlds, a lower threshold's demand, a larger `most_poses` or another instrument placement may reach it.");
        }
        if names.contains(&COMPARISON) {
            comparison(s);
        }
        prediction(s);
        files(s);
    })
}

/// The tour's sentence from `tour_moves.parquet` and the lengths of `plan.parquet` (`r` its row).
pub fn tour_sentence(r: &Row<'_>) -> String {
    let m = r.of(TOUR_MOVES, 0);
    let moves: Vec<TourMove> = (0..m.height())
        .map(|k| {
            let m = m.at(k);
            TourMove { from: m.str("from"), to: m.str("to"), vias: m.u64("vias") as usize, routed: m.bool("routed") }
        })
        .collect();
    tour_words(r.f64("tour_deg"), r.f64("tour_path_deg"), &moves)
}

/// The title, the plan's inputs and its poses.
fn head(s: &mut Summary<'_>) {
    s.text_from(PLAN, |r| {
        format!(
            "# Calibration plan: {}\n\nRobot {} ({}), laser tracker at ({:.1}, {:.1}, {:.1}) mm in the base frame, {} target(s) ({}), the {} model.\n\n## Poses\n\n",
            r.str("plan_file"),
            r.str("robot"),
            r.str("robot_model"),
            r.f64("tracker_x_mm"),
            r.f64("tracker_y_mm"),
            r.f64("tracker_z_mm"),
            r.u64("target_count"),
            r.str("targets"),
            r.str("model")
        )
    });
    s.text_from(PLAN, |r| {
        format!(
            "- Pool: {} feasible configurations of {} drawn within the limits (refused: {}).\n- Training: {} poses chosen by DETMAX from {} (session {TRAINING} in `poses.csv`).\n- Validation: {} poses spread over the workspace of interest (marked `{VALIDATION}` in the `split` column of `poses.csv`: `calsim calibrate` holds them out).\n- O1 of the chosen set: {:.6} (a random set of the same size from the same pool: {:.6}); {} columns: {}.\n{}\n\n",
            r.u64("pool_feasible"),
            r.u64("pool_tried"),
            r.str("pool_refused"),
            r.u64("training"),
            r.u64("pool"),
            r.u64("validation"),
            r.f64("o1"),
            r.f64("o1_random"),
            r.u64("detmax_columns"),
            r.str("detmax_params"),
            tour_sentence(r)
        )
    });
}

/// A fraction as a percentage with one decimal at most (0.9 -> 90).
pub fn pct(x: f64) -> String {
    format!("{}", (x * 1000.0).round() / 10.0)
}

/// The objective's section: its rule, P(success) against the count of poses, the verdict.
fn objective(s: &mut Summary<'_>, hint: &'static str) {
    s.text_from(OBJECTIVE, |r| {
        format!(
            "## Number of poses by objective\n\nObjective: P(held-out {} <= {} mm) >= {} at {} % confidence, a world's held-out {} taken over the validation poses (the workspace of interest). P(success) is bounded below by the one-sided Clopper-Pearson bound over {} simulated worlds (a world whose calibration gives no value counts as a failure). Every count is DETMAX's set of that size from the same pool, scored on the same worlds: the robot file's truth measured at the whole pool (training and validation poses) and calibrated is every world's truth, and world w's noise comes from the same stream for every count. Counts doubled from {} (the model's parameters with a base and a tool) up to at most {}, then bisected between the largest that failed and the smallest that met it.\n\n",
            r.str("statistic"),
            r.f64("threshold_mm"),
            r.f64("success_at_least"),
            pct(r.f64("confidence")),
            r.str("statistic"),
            r.u64("worlds"),
            r.u64("fewest_poses"),
            r.u64("most_poses")
        )
    });
    counts(s, hint);
}

/// The objective's table (P(success) against the count of poses) and its verdict: the count
/// chosen, or the best found with `hint` (what may reach the objective) after it.
pub fn counts(s: &mut Summary<'_>, hint: &'static str) {
    s.text_from(OBJECTIVE, move |r| {
        let mut t = format!(
            "| poses | successes / worlds | P(success) | lower bound ({} %) | meets |\n|---|---|---|---|---|\n",
            pct(r.f64("confidence"))
        );
        let c = r.of(SEARCH, 0);
        for k in 0..c.height() {
            let c = c.at(k);
            t += &format!(
                "| {} | {} / {} | {:.3} | {:.4} | {} |\n",
                c.u64("poses"),
                c.u64("successes"),
                c.u64("worlds"),
                c.f64("p_success"),
                c.f64("lower"),
                if c.bool("meets") { "yes" } else { "no" }
            );
        }
        let planned = r.u64("planned");
        if r.bool("met") {
            t + &format!(
                "\nChosen: {planned} poses, the smallest count in the table whose lower bound clears {}.\n\n",
                r.f64("success_at_least")
            )
        } else {
            let best = (0..c.height()).map(|k| c.at(k)).find(|c| c.u64("poses") == planned).map_or(f64::NAN, |c| c.f64("lower"));
            t + &format!(
                "\nNot met: no count up to {} clears {}; planned with the best found, {planned} poses (lower bound {best:.4}).{hint}\n\n",
                r.u64("most_poses"),
                r.f64("success_at_least")
            )
        }
    });
}

/// The comparison's section.
fn comparison(s: &mut Summary<'_>) {
    s.text_from(PLAN, |p| {
        let c = p.of(COMPARISON, 0);
        let pct = pct(c.f64("confidence"));
        let mut t = format!(
            "## DETMAX against random and greedy selection\n\nThe same {} training poses chosen three ways from the same pool of {}, each with the same validation poses and simulated on the same {} worlds (the pilot world's calibrated robot as every world's truth, world w's noise from the same stream): DETMAX, a uniform random set, and a greedy D-optimal set (each step adds the pose that raises the determinant of the information matrix most). The figures are over the worlds of each world's held-out median, with distribution-free {pct} % intervals (order statistics).\n\n| selection | O1 | median over worlds, mm ({pct} % interval) | P90 over worlds, mm ({pct} % interval) |\n|---|---|---|---|\n",
            p.u64("training"),
            p.u64("pool"),
            p.u64("worlds")
        );
        let end = |x: f64| if x.is_finite() { format!("{x:.4}") } else { "unbounded".to_string() };
        for k in 0..c.height() {
            let r = c.at(k);
            let iv = |v: &str| format!("{:.4} ({}-{})", r.f64(&format!("{v}_mm")), end(r.f64(&format!("{v}_lo_mm"))), end(r.f64(&format!("{v}_hi_mm"))));
            t += &format!("| {} | {:.6} | {} | {} |\n", r.str("selection"), r.f64("o1"), iv("median"), iv("p90"));
        }
        t + "\n"
    });
}

/// The parameters the plan cannot identify and the predicted held-out error.
fn prediction(s: &mut Summary<'_>) {
    s.text_from(PLAN, |r| {
        let u = r.of(UNIDENTIFIABLE, 0);
        let mut t = String::from("## Parameters the plan cannot identify\n\n");
        if u.height() == 0 {
            t += &format!("None of the {} model's parameters.\n\n", r.str("model"));
        } else {
            for k in 0..u.height() {
                let with = u.at(k).str("moves_with");
                t += &format!("- {} (moves the points as {} do): kept nominal\n", u.at(k).str("parameter"), if with.is_empty() { "nothing else" } else { &with });
            }
            t.push('\n');
        }
        t + &format!(
            "## Predicted held-out error\n\nThe held-out median error after calibration over {} simulated worlds (calibrate's plan simulation: a pilot world, the robot file's truth measured at these poses with the tracker's noise and calibrated; its calibrated robot then taken as the truth in every world, measured again with {:.4} mm per coordinate, the tracker's noise pooled over the plan's points, and calibrated again):\n\n",
            r.u64("worlds_with_value"),
            r.f64("noise_mm")
        )
    });
    let f4 = |header: &str, c: &'static str| cell(header, move |r: &Row<'_>| format!("{:.4}", r.f64(c)));
    s.table(
        PLAN,
        Summary::all_rows(),
        vec![
            f4("P10, mm", "p10_mm"),
            f4("median, mm", "median_mm"),
            f4("P90, mm", "p90_mm"),
            f4("pilot world, mm", "pilot_median_mm"),
            cell("model chosen in the pilot", |r| r.str("pilot_chosen")),
        ],
    );
    s.text_from(PLAN, |r| {
        let above = r.f64("pilot_median_mm") > r.f64("p90_mm");
        let mut t = String::new();
        if above && !r.bool("robot_truth") && !r.bool("twin") {
            t += "The pilot world lies above P90: the robot file gives no `[truth]`, so the pilot measured its nominal, which the model describes completely; the pilot is one noise draw, and one in ten lies above P90.\n\n";
        } else if above {
            t += &format!("The pilot world lies above P90: the robot file's truth holds what the {} model does not describe (its calibrated robot, the worlds' truth, does not): a richer model would calibrate that robot better.\n\n", r.str("model"));
        }
        t + if r.bool("twin") {
            "The robot file is a twin: its `[learned]` table's effects (drawn once per world from their fitted spread) are in the pilot world and in every world, so the figures carry what its calibration learned beyond the model.\n\n"
        } else {
            "A robot the model describes completely, measured with this noise, calibrates to this. Effects outside the model (gear harmonics, backlash, temperature) add to it: `calsim calibrate --plan-worlds N` on the measured file says whether the robot does.\n\n"
        }
    });
}

/// The files of a tracker plan.
fn files(s: &mut Summary<'_>) {
    s.text(format!(
        "## Files\n\n- `poses.csv`: the calibrate measurement file, joint columns filled, position columns to fill with the tracker's readings.\n- `joints.txt`: the same poses as a plain joint list.\n- `tour.csv`: the order to visit them.\n- `{0}.png`, `{0}.svg`: the first target at every pose in the base frame (top and side views), the validation poses ringed, the arm at {1} of the poses with the lines of sight from the tracker to their targets, the tracker, the robot's base and the workspace of interest.\n- `{2}` (unless `--no-recording`): the Rerun recording, the arm at every pose in the order of the tour with its lines of sight, the cell, and the predicted held-out median per world.\n",
        plot::STEM,
        plot::SHOWN,
        record::FILE
    ));
}
