//! A device plan's tables and `plan.md` rendered from them by the results' one renderer
//! ([`crate::io::results::Summary`]): `plan.parquet` (one row: the plan's inputs and every figure
//! of its text), `spheres.parquet` (a row per datum sphere: its nominal centre in {W} and the
//! training configurations centred on it), `tour_moves.parquet`, `worlds.parquet`,
//! `unidentifiable.parquet`, and with an objective `objective.parquet` and `search.parquet`
//! (as a tracker plan's, [`super::summary`]). An SPMS plan's groups are the head's stations
//! (`spheres.parquet`: each station's convergence point in {W}).

use polars::prelude::Column;

use super::device::{DeviceOutcome, DevicePlan};
use super::select::tour_moves;
use super::summary::{
    OBJECTIVE, PLAN, TOUR_MOVES, Table, UNIDENTIFIABLE, WORLDS, counts, file_name, moves_columns, objective_tables, pct, render,
    tour_sentence, worlds_columns,
};
use super::{TRAINING, VALIDATION, plot, record};
use crate::io::results::{Row, Summary, cell};

/// The datum spheres.
pub const SPHERES: &str = "spheres.parquet";

/// Every table of a device plan.
pub fn tables(plan: &DevicePlan, o: &DeviceOutcome) -> Vec<Table> {
    let mut t = vec![(PLAN, plan_columns(plan, o))];
    let g = &o.groups_w_mm;
    let on = |k: usize| o.rows.iter().filter(|r| r.group == Some(k)).count() as u32;
    t.push((
        SPHERES,
        vec![
            Column::new("sphere".into(), (1..=g.len() as u32).collect::<Vec<u32>>()),
            Column::new("x_w_mm".into(), g.iter().map(|c| c[0]).collect::<Vec<f64>>()),
            Column::new("y_w_mm".into(), g.iter().map(|c| c[1]).collect::<Vec<f64>>()),
            Column::new("z_w_mm".into(), g.iter().map(|c| c[2]).collect::<Vec<f64>>()),
            Column::new("training".into(), (0..g.len()).map(on).collect::<Vec<u32>>()),
        ],
    ));
    t.push((TOUR_MOVES, moves_columns(&tour_moves(&o.colliding_moves, &o.routing, |k| o.rows[o.tour.0[k]].label.clone()))));
    t.push((WORLDS, worlds_columns(&o.prediction.per_world_mm)));
    t.push((UNIDENTIFIABLE, vec![Column::new("parameter".into(), o.prediction.unidentifiable.clone())]));
    if let (Some(obj), Some(search)) = (&o.objective, &o.search) {
        t.extend(objective_tables(obj, search, plan.worlds));
    }
    t
}

/// The first line `calsim plan` prints of a device plan (`r`: `plan.parquet`'s row; `seconds`:
/// the planning's wall time).
pub fn terminal_line(seconds: f64) -> impl Fn(&Row<'_>) -> String {
    move |r| {
        let (chosen, pool) =
            if r.str("instrument") == "spms" { ("measured", "the spms head's pool") } else { ("centred", "the trical centring") };
        format!(
            "calsim plan: {} {chosen} + {} validation configurations, {pool} {} ({} kept); {}",
            r.u64("training"),
            r.u64("validation"),
            r.u64("pool_centred"),
            r.u64("pool_kept"),
            super::summary::prediction_clause(r, seconds)
        )
    }
}

/// `plan.parquet`'s columns.
fn plan_columns(plan: &DevicePlan, o: &DeviceOutcome) -> Vec<Column> {
    let p = &o.prediction;
    let s = |name: &str, v: String| Column::new(name.into(), [v]);
    let n = |name: &str, v: usize| Column::new(name.into(), [v as u32]);
    let x = |name: &str, v: f64| Column::new(name.into(), [v]);
    let spheres = o.groups_w_mm.len();
    vec![
        s("plan_file", file_name(&plan.path)),
        s("robot", plan.robot_name.clone()),
        s("robot_model", plan.robot.nominal.data().name.clone()),
        s("instrument", plan.kind.to_string()),
        s("scenario", plan.scenario_file.clone().unwrap_or_default()),
        s("params", o.params.join(", ")),
        n("param_count", o.params.len()),
        n("pool_centred", o.candidates),
        n("pool_per_sphere", o.candidates / spheres.max(1)),
        n("pool_kept", o.candidates - o.refused[0] - o.refused[1]),
        n("refused_limits", o.refused[0]),
        n("refused_collision", o.refused[1]),
        n("training", o.poses),
        n("validation", plan.validation),
        n("validation_tried", o.validation_tried),
        x("o1", o.o1.0),
        x("o1_random", o.o1.1),
        x("observed_off_max_mm", o.centring_mm.iter().copied().fold(0.0, f64::max)),
        x("tour_deg", o.tour.1.to_degrees()),
        x("tour_path_deg", o.routing.length_rad.to_degrees()),
        n("worlds", plan.worlds),
        n("worlds_with_value", p.worlds),
        x("noise_mm", p.noise_mm),
        x("p10_mm", p.quantiles_mm[0]),
        x("median_mm", p.quantiles_mm[1]),
        x("p90_mm", p.quantiles_mm[2]),
        x("median_lo_mm", p.median_interval_mm.0),
        x("median_hi_mm", p.median_interval_mm.1),
        x("pilot_median_mm", p.pilot_median_mm),
    ]
}

/// `plan.md` of a device plan, rendered from its tables.
pub fn markdown(tables: &[Table]) -> std::io::Result<String> {
    render(tables, |s, names| {
        head(s);
        if names.contains(&OBJECTIVE) {
            objective(s);
        }
        prediction(s);
        files(s);
    })
}

/// The title, the plan's inputs and its poses.
fn head(s: &mut Summary<'_>) {
    s.text_from(PLAN, |r| {
        let stations = r.of(SPHERES, 0).height();
        let scenario = r.str("scenario");
        let scenario = if scenario.is_empty() { "the device's default scenario".to_string() } else { format!("scenario {scenario}") };
        let (device, pool) = if r.str("instrument") == "spms" {
            (
                format!("the SPMS head (five laser range sensors measuring a sphere on the flange) at {stations} stations ({scenario})"),
                format!(
                    "the head measured the sphere at {} configurations at the {stations} stations ({} per station, the flange within its approach cone, the sphere within the sensors' range); {} kept within the plan's limits and free of collision with the floor and the keep-out boxes",
                    r.u64("pool_centred"),
                    r.u64("pool_per_sphere"),
                    r.u64("pool_kept")
                ),
            )
        } else {
            (
                format!("the TriCal device centred on {stations} datum spheres ({scenario})"),
                format!(
                    "the device's campaign centred {} configurations on the {stations} spheres ({} per sphere, tool axes within its approach cone); {} kept within the plan's limits and free of collision with the floor, the keep-out boxes and the device's fixtures",
                    r.u64("pool_centred"),
                    r.u64("pool_per_sphere"),
                    r.u64("pool_kept")
                ),
            )
        };
        format!(
            "# Calibration plan: {}\n\nRobot {} ({}), {device}, the device's {} parameters ({}).\n\n## Poses\n\n- Pool: {pool} (refused: joint limits {}, collision {}).\n",
            r.str("plan_file"),
            r.str("robot"),
            r.str("robot_model"),
            r.u64("param_count"),
            r.str("params"),
            r.u64("refused_limits"),
            r.u64("refused_collision")
        )
    });
    s.text_from(PLAN, |r| {
        let spms = r.str("instrument") == "spms";
        let g = r.of(SPHERES, 0);
        let on = if spms { "at station" } else { "on sphere" };
        let per: Vec<String> = (0..g.height()).map(|k| format!("{} {on} {}", g.at(k).u64("training"), g.at(k).u64("sphere"))).collect();
        let (measured_by, off) = if spms {
            ("the SPMS cannot measure them, a laser tracker registered to {W} on the first station's A1-A3 can", format!("- Measurement: at every chosen configuration the true sphere centre lies within {:.4} mm of the head's measurement of it (the identified beams, the sensors' noise and linearity, the station's frame as the tracker measured it, the arm's repeatability and effects outside its model in the planning world).", r.f64("observed_off_max_mm")))
        } else {
            ("the TriCal cannot measure them, a laser tracker registered to {W} on the sphere nests can", format!("- Centring: at every chosen configuration the true arm's TCP lies within {:.4} mm of its sphere's located centre (the device's centring loop, the arm's repeatability and effects outside its model in the planning world).", r.f64("observed_off_max_mm")))
        };
        format!(
            "- Training: {} configurations chosen by DETMAX ({}), session {TRAINING} in `poses.csv`.\n- Validation: {} configurations spread over the workspace of interest (of {} drawn within the limits), marked `{VALIDATION}`: the prediction's held-out points; {measured_by}.\n- O1 of the chosen set: {:.6} (a random set of the same size from the same pool: {:.6}).\n{off}\n{}\n\n",
            r.u64("training"),
            per.join(", "),
            r.u64("validation"),
            r.u64("validation_tried"),
            r.f64("o1"),
            r.f64("o1_random"),
            tour_sentence(r)
        )
    });
}

/// The objective's section.
fn objective(s: &mut Summary<'_>) {
    s.text_from(OBJECTIVE, |r| {
        format!(
            "## Number of poses by objective\n\nObjective: P(held-out {} <= {} mm) >= {} at {} % confidence, a world's held-out {} taken over the validation configurations (the workspace of interest). P(success) is bounded below by the one-sided Clopper-Pearson bound over {} simulated worlds (a world whose identification gives no model counts as a failure). Every count is DETMAX's set of that size from the same pool, on the same worlds. Counts doubled from {} (a third of the device's parameters) up to at most {}, then bisected.\n\n",
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
    counts(s, "");
}

/// The parameters the plan cannot identify and the predicted held-out error.
fn prediction(s: &mut Summary<'_>) {
    s.text_from(PLAN, |r| {
        let u = r.of(UNIDENTIFIABLE, 0);
        let names: Vec<String> = (0..u.height()).map(|k| u.at(k).str("parameter")).collect();
        let mut t = String::from("## Parameters the plan cannot identify\n\n");
        if names.is_empty() {
            t += &format!("None of the device's {} parameters.\n\n", r.u64("param_count"));
        } else {
            t += &format!("{}: kept at their values before calibration.\n\n", names.join(", "));
        }
        let sources = if r.str("instrument") == "spms" {
            "the head's measurement of the sphere, the stations' frames, repeatability"
        } else {
            "centring, repeatability, the ballbar's location of the spheres"
        };
        t + &format!(
            "## Predicted held-out error\n\nThe held-out median error after calibration at the validation configurations over {} simulated worlds: the true arm of the planning world observed at the chosen configurations with {:.4} mm per coordinate (the device's observations in the planning world against the true arm's model, pooled over the pool kept: {sources} and the arm's effects outside its model), identified from the model before calibration, compared with the true arm at the validation configurations. The pilot identifies the device's own observations at the chosen configurations.\n\n",
            r.u64("worlds_with_value"),
            r.f64("noise_mm")
        )
    });
    let f4 = |header: &str, c: &'static str| cell(header, move |r: &Row<'_>| format!("{:.4}", r.f64(c)));
    let end = |x: f64| if x.is_finite() { format!("{x:.4}") } else { "unbounded".to_string() };
    s.table(
        PLAN,
        Summary::all_rows(),
        vec![
            f4("P10, mm", "p10_mm"),
            f4("median, mm", "median_mm"),
            f4("P90, mm", "p90_mm"),
            cell("median's 90 % interval, mm", move |r| format!("{}-{}", end(r.f64("median_lo_mm")), end(r.f64("median_hi_mm")))),
            f4("pilot, mm", "pilot_median_mm"),
        ],
    );
    s.text_from(PLAN, |r| {
        let mut t = String::new();
        if r.f64("pilot_median_mm") > r.f64("p90_mm") {
            t += "The pilot lies above P90: the device's own observations carry what the worlds leave out (below), so the worlds' figures are a lower bound of what this plan buys on this arm.\n\n";
        }
        let shared = if r.str("instrument") == "spms" {
            "the SPMS's errors are partly shared by the configurations of one station (its frame as the tracker measured it, the beams as identified)"
        } else {
            "the TriCal's errors are partly shared by the configurations of one sphere (the ballbar's location of its centre)"
        };
        t + &format!("The worlds draw the observation error independently at every configuration; {shared} and the arm's effects outside its model are systematic: `calsim run` on the device's scenario simulates them whole.\n\n")
    });
}

/// The files of a device plan.
fn files(s: &mut Summary<'_>) {
    s.text_from(PLAN, |r| {
        let (rows, list, figure, recording) = if r.str("instrument") == "spms" {
            (
                "each training row a configuration measured at the station its label ends with (`_s1` ...), that station's convergence point in {W} as its position",
                "station",
                "the sphere centre at every configuration in the base frame (top and side views), the stations' convergence points",
                "the arm at every configuration in the order of the tour, the stations",
            )
        } else {
            (
                "each training row a configuration centred on the sphere its label ends with (`_s1` ...), its sphere's nominal centre in {W} as its position",
                "sphere",
                "the device's TCP at every configuration in the base frame (top and side views), the spheres",
                "the arm and the device at every configuration in the order of the tour, the spheres",
            )
        };
        format!(
            "## Files\n\n- `poses.csv`: the calibrate measurement file: {rows}; the validation rows with empty positions.\n- `joints.txt`: the same configurations as a plain joint list, with their {list}.\n- `tour.csv`: the order to visit them.\n- `{0}.png`, `{0}.svg`: {figure}, the validation configurations ringed, the arm at {1} of them and the workspace of interest.\n- `{2}` (unless `--no-recording`): the Rerun recording, {recording} and the cell, and the predicted held-out median per world.\n",
            plot::STEM,
            plot::SHOWN,
            record::FILE
        )
    });
}
