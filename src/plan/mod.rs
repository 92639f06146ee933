//! `calsim plan`: the poses to measure on the real robot, and the accuracy they will buy.
//!
//! ```text
//! plan file ─► spec::parse ─► cell::Cell (capsules, SMRs, floor, keep-out boxes, tracker head;
//!                              range, field of view, incidence, line of sight)
//!  ─► select::pool (uniform candidates within the limits, each from its own stream, kept if feasible)
//!  ─► select::validation (spread over the workspace of interest: farthest-point sampling)
//!  ─► select::choose (DETMAX on the identification Jacobian of the model's identifiable
//!     parameters, a base and a tool)      ─► select::tour (greedy nearest neighbour in joint space)
//!  ─► predict: a pilot world (the robot file's truth measured at the plan's poses with the
//!     tracker's noise, calibrated by `calibrate::run`) and `calibrate::plan::simulate` over the
//!     plan's worlds: the predicted held-out error, median and P10-P90
//! ```
//!
//! The poses go out as a `calibrate` measurement file (joint columns filled, position columns
//! empty), one session `A`: training poses marked `train` in the `split` column, validation poses
//! marked `holdout`, which `calsim calibrate` holds out without registering anything on them. Every stream is keyed under the plan's seed (`seeds::plan`):
//! the plan is the same for any thread count.

pub mod cell;
pub mod select;
pub mod spec;

use std::fmt::Write as _;
use std::path::Path;

use nalgebra::Vector3;
use rand_distr::{Distribution, Normal};

use crate::calibrate::registration::Unidentifiable;
use crate::calibrate::{Options, plan::Statistic, validation::Split};
use crate::robot::{Joints, KinState, ParamSet, forward};
use cell::Cell;
pub use spec::{Plan, PlanError, parse};

/// Session label of the plan's poses.
pub const TRAINING: &str = "A";
/// The `split` value of the validation poses (`calsim calibrate` holds them out).
pub const VALIDATION: &str = "holdout";
/// The `split` value of the training poses.
pub const TRAIN: &str = "train";

/// Calibrate's identifiability check (`registration::prune`) on the configurations `qs` measured
/// at the first `targets` targets of `plan` in one session: the robot parameters of `set` they separate, and
/// those they cannot, named with the unknowns they move the points alike with.
pub fn identifiable(
    plan: &Plan,
    cell: &Cell,
    qs: &[Joints],
    set: &ParamSet,
    targets: usize,
) -> Result<(ParamSet, Vec<Unidentifiable>), PlanError> {
    use crate::calibrate::problem::{Layout, Obs, Problem};
    let mut st = KinState::default();
    let targets = targets.clamp(1, plan.targets.len());
    let mut obs = Vec::with_capacity(qs.len() * targets);
    for q in qs {
        forward(&cell.model, &mut st, q);
        for k in 0..targets {
            obs.push(Obs { q: *q, measured_mm: cell.target(&st, k).0, session: 0, target: k, sigma: 1.0 });
        }
    }
    let layout = Layout { robot: set.clone(), sessions: 1, targets };
    let mut frames_x = vec![0.0; 6];
    for t in &plan.targets[..targets] {
        frames_x.extend(t.frame6_mm.iter());
    }
    let x0 = crate::calibrate::validation::start_values(&layout, &cell.model, &frames_x);
    let problem = Problem { start: &cell.model, layout, obs: &obs };
    let idx: Vec<usize> = (0..obs.len()).collect();
    let names: Vec<String> = plan.targets[..targets].iter().map(|t| t.name.clone()).collect();
    crate::calibrate::registration::prune(&problem, &x0, &idx, (&[TRAINING.to_string()], &names)).map_err(|e| {
        PlanError::new(
            &plan.path,
            "target",
            format!("the poses cannot fix {}: the targets need poses that turn the flange more", e.names.join(", ")),
        )
    })
}

/// One row of the plan's measurement file: pose label, session, split, model joint angles.
#[derive(Clone, Debug, PartialEq)]
pub struct PoseRow {
    /// Label (`p001`, `v001`).
    pub label: String,
    /// Session (`A`).
    pub session: &'static str,
    /// Its part of the split: `train` or `holdout` (a validation pose).
    pub split: &'static str,
    /// The model's joint angles, rad.
    pub q: Joints,
}

/// The predicted held-out error of the plan.
#[derive(Clone, Debug, PartialEq)]
pub struct Prediction {
    /// The model calibrate chose in the pilot world.
    pub pilot_chosen: &'static str,
    /// The pilot world's held-out median, mm.
    pub pilot_median_mm: f64,
    /// Noise per coordinate of the simulated worlds (the tracker's, pooled over the plan's points), mm.
    pub noise_mm: f64,
    /// Held-out median per world, mm.
    pub per_world_mm: Vec<f64>,
    /// P10, median, P90 over the worlds with a value, mm.
    pub quantiles_mm: [f64; 3],
    /// Worlds with a value.
    pub worlds: usize,
    /// The plan's model's parameters calibrate keeps nominal on these poses.
    pub unidentifiable: Vec<Unidentifiable>,
}

/// What `calsim plan` computed.
#[derive(Clone, Debug)]
pub struct Outcome {
    /// The pool.
    pub pool: select::Pool,
    /// Training then validation rows.
    pub rows: Vec<PoseRow>,
    /// O1 of DETMAX's set on the pool's Jacobian, and of a random set of the same size.
    pub o1: (f64, f64),
    /// Parameters (columns) DETMAX scored.
    pub detmax_params: Vec<String>,
    /// Tour: positions in `rows`, and its length in joint space, rad.
    pub tour: (Vec<usize>, f64),
    /// Moves of the tour through a collision (positions in the tour).
    pub colliding_moves: Vec<(usize, usize)>,
    /// The prediction.
    pub prediction: Prediction,
}

/// Runs the plan (on the caller's rayon pool).
pub fn run(plan: &Plan) -> Result<Outcome, PlanError> {
    let cell = Cell::new(plan)?;
    let want = plan.pool + plan.validation;
    let pool = select::pool(plan, &cell, want)?;
    if pool.qs.len() < want {
        return Err(PlanError::new(
            &plan.path,
            "pool",
            format!(
                "only {} feasible poses in {} candidates, fewer than pool + validation = {want} (refused: {})",
                pool.qs.len(),
                pool.tried,
                select::refusals(&pool)
            ),
        ));
    }
    let val = select::validation(plan, &cell, &pool.qs, plan.validation)?;
    let training: Vec<Joints> =
        pool.qs.iter().enumerate().filter(|(i, _)| val.binary_search(i).is_err()).map(|(_, q)| *q).take(plan.pool).collect();
    let set = select::detmax_set(plan, &cell, &training)?;
    let jac = select::pool_jacobian(plan, &cell, &training, &set)?;
    let (chosen, o1) = select::choose(plan, &jac, plan.poses)?;
    let random = {
        let mut rng = crate::seeds::stream(plan.seed, crate::seeds::plan::RANDOM);
        let mut s = rand::seq::index::sample(&mut rng, training.len(), plan.poses).into_vec();
        s.sort_unstable();
        crate::identify::detmax::o1_of(&jac, &s)
    };
    let mut rows: Vec<PoseRow> = chosen
        .iter()
        .enumerate()
        .map(|(k, &i)| PoseRow { label: format!("p{:03}", k + 1), session: TRAINING, split: TRAIN, q: training[i] })
        .collect();
    rows.extend(val.iter().enumerate().map(|(k, &i)| PoseRow {
        label: format!("v{:03}", k + 1),
        session: TRAINING,
        split: VALIDATION,
        q: pool.qs[i],
    }));
    let qs: Vec<Joints> = rows.iter().map(|r| r.q).collect();
    let tour = select::tour(&cell, &qs);
    let colliding_moves = select::colliding_moves(&cell, &qs, &tour.0);
    let prediction = predict(plan, &cell, &rows)?;
    Ok(Outcome { pool, rows, o1: (o1, random), detmax_params: set.names(), tour, colliding_moves, prediction })
}

/// The measurement file of `rows` at every target: `positions` (per row, per target, mm) or
/// empty position columns. The joint columns are the controller's values (the robot file's
/// coupling inverted where it has one), in degrees written to round-trip.
pub fn csv(plan: &Plan, rows: &[PoseRow], positions: Option<&[Vec<Vector3<f64>>]>, comments: &[String]) -> String {
    let mut s = String::new();
    if positions.is_some() {
        s.push_str("# simulated = true\n");
    }
    let _ = writeln!(s, "# format = {}", crate::calibrate::measurements::FORMAT);
    s.push_str("# joints = controller\n");
    let _ = writeln!(s, "# robot = {}", plan.robot_name);
    s.push_str("# frame = laser tracker frame\n");
    for c in comments {
        let _ = writeln!(s, "# {c}");
    }
    s.push_str("pose,session,target,split,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,x_mm,y_mm,z_mm\n");
    for (r, row) in rows.iter().enumerate() {
        let qc = plan.robot.coupling.as_ref().map_or(row.q, |c| c.controller_from_model(&row.q));
        let q: Vec<String> = qc.iter().map(|v| format!("{}", v.to_degrees())).collect();
        for (k, t) in plan.targets.iter().enumerate() {
            let xyz = positions.map_or_else(|| ",,".to_string(), |p| format!("{},{},{}", p[r][k].x, p[r][k].y, p[r][k].z));
            let _ = writeln!(s, "{},{},{},{},{},{xyz}", row.label, row.session, t.name, row.split, q.join(","));
        }
    }
    s
}

/// The robot file's truth (its nominal where it gives none) measured at `rows` at every target,
/// in the base frame, with the tracker's noise at each point's distance (pooled per coordinate,
/// [`spec::Tracker::sigma_mm`]) drawn from the stream `key` of the plan's seed. Returns the
/// positions and the noise per point.
pub fn measure(plan: &Plan, cell: &Cell, rows: &[PoseRow], key: u64) -> Result<(Vec<Vec<Vector3<f64>>>, Vec<f64>), PlanError> {
    let truth = plan.robot.truth_on(&plan.robot.nominal).map_err(|e| PlanError::new(&plan.path, "robot", format!("its [truth]: {e}")))?;
    let placed: Vec<_> = plan
        .targets
        .iter()
        .map(|t| {
            truth.edited(|d| {
                d.world_from_base = crate::robot::XyzZyx::default();
                d.flange_tcp_mm = t.frame6_mm;
            })
        })
        .collect::<Result<_, _>>()
        .map_err(|e| PlanError::new(&plan.path, "robot", e.to_string()))?;
    let mut rng = crate::seeds::stream(plan.seed, key);
    let unit = Normal::new(0.0, 1.0).expect("unit normal");
    let mut st = KinState::default();
    let mut sigmas = Vec::new();
    let positions = rows
        .iter()
        .map(|r| {
            placed
                .iter()
                .map(|m| {
                    let p = forward(m, &mut st, &r.q);
                    let s = plan.tracker.sigma_mm((cell.tracker() - p).norm());
                    sigmas.push(s);
                    p + Vector3::from_fn(|_, _| s * unit.sample(&mut rng))
                })
                .collect()
        })
        .collect();
    Ok((positions, sigmas))
}

/// The calibrate options of the plan: the model's parameters as the most complete model, the
/// validation poses held out by the file's `split` column (else a fifth of the poses), no figures.
pub fn calibrate_options(plan: &Plan) -> Options {
    Options {
        params: Some(spec::model_params(plan.model)),
        split: if plan.validation > 0 { Split::Column } else { Split::Poses { fraction: 0.2 } },
        seed: plan.seed,
        plots: false,
        ..Options::default()
    }
}

/// The predicted held-out error: a pilot world (the truth measured at the plan's poses,
/// calibrated by `calibrate::run`), then `calibrate::plan::simulate` over the plan's worlds with
/// the tracker's noise (the calibrated pilot robot taken as the truth in each world).
pub fn predict(plan: &Plan, cell: &Cell, rows: &[PoseRow]) -> Result<Prediction, PlanError> {
    let (positions, sigmas) = measure(plan, cell, rows, crate::seeds::plan::PILOT)?;
    let text = csv(plan, rows, Some(&positions), &[]);
    let pilot_path = Path::new("(the plan's pilot world)");
    let fail = |e: String| PlanError::new(&plan.path, "poses", format!("the plan's poses cannot be calibrated: {e}"));
    let m = crate::calibrate::measurements::parse(pilot_path, &text, &plan.robot).map_err(|e| fail(e.to_string()))?;
    let c = crate::calibrate::run(&plan.robot, &m, &calibrate_options(plan)).map_err(|e| fail(e.to_string()))?;
    let noise_mm = (sigmas.iter().map(|s| s * s).sum::<f64>() / sigmas.len() as f64).sqrt();
    let sim = crate::calibrate::plan::simulate(
        &c,
        plan.worlds,
        Statistic::Median,
        crate::seeds::split_seed(plan.seed, crate::seeds::plan::WORLDS),
        Some(noise_mm),
        None,
    )
    .map_err(|e| fail(e.to_string()))?;
    let sorted = crate::study::stats::finite_sorted(&sim.per_world_mm);
    let q = |p: f64| crate::numeric::quantile(&sorted, p);
    let unidentifiable = c.models.iter().rev().find(|r| r.kind.is_some()).map(|r| r.unidentifiable.clone()).unwrap_or_default();
    Ok(Prediction {
        pilot_chosen: c.chosen().kind.map_or("before", |k| k.name()),
        pilot_median_mm: Statistic::Median.of(&c).unwrap_or(f64::NAN),
        noise_mm,
        worlds: sorted.len(),
        quantiles_mm: [q(0.1), q(0.5), q(0.9)],
        per_world_mm: sim.per_world_mm,
        unidentifiable,
    })
}

/// The plain joint list: one line per pose, label, split and the controller's joint values in
/// degrees (6 decimals).
pub fn joint_list(plan: &Plan, rows: &[PoseRow]) -> String {
    let mut s = String::from("# pose split q1_deg q2_deg q3_deg q4_deg q5_deg q6_deg (controller values)\n");
    for r in rows {
        let qc = plan.robot.coupling.as_ref().map_or(r.q, |c| c.controller_from_model(&r.q));
        let q: Vec<String> = qc.iter().map(|v| format!("{:.6}", v.to_degrees())).collect();
        let _ = writeln!(s, "{} {} {}", r.label, r.split, q.join(" "));
    }
    s
}

/// The tour as CSV: step, pose, split, joint values (deg, controller), the move to it (largest
/// joint change, deg).
pub fn tour_csv(plan: &Plan, o: &Outcome) -> String {
    let mut s = String::from("step,pose,split,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,largest_joint_move_deg\n");
    let mut prev: Option<Joints> = None;
    for (k, &i) in o.tour.0.iter().enumerate() {
        let r = &o.rows[i];
        let qc = plan.robot.coupling.as_ref().map_or(r.q, |c| c.controller_from_model(&r.q));
        let q: Vec<String> = qc.iter().map(|v| format!("{:.6}", v.to_degrees())).collect();
        let step = prev.map_or(0.0, |p| p.iter().zip(&r.q).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max).to_degrees());
        let _ = writeln!(s, "{},{},{},{},{step:.3}", k + 1, r.label, r.split, q.join(","));
        prev = Some(r.q);
    }
    s
}

/// `plan.md`: what was planned and what it will buy.
pub fn markdown(plan: &Plan, o: &Outcome) -> String {
    let mut s = String::new();
    let p = &o.prediction;
    let _ = writeln!(s, "# Calibration plan: {}\n", plan.path.file_name().map_or_else(String::new, |f| f.to_string_lossy().into_owned()));
    let _ = writeln!(
        s,
        "Robot {} ({}), laser tracker at ({:.1}, {:.1}, {:.1}) mm in the base frame, {} target(s) ({}), the {} model.\n",
        plan.robot_name,
        plan.robot.nominal.data().name,
        plan.tracker.position_mm.x,
        plan.tracker.position_mm.y,
        plan.tracker.position_mm.z,
        plan.targets.len(),
        plan.targets.iter().map(|t| t.name.as_str()).collect::<Vec<_>>().join(", "),
        plan.model.name()
    );
    let _ = writeln!(s, "## Poses\n");
    let _ = writeln!(
        s,
        "- Pool: {} feasible configurations of {} drawn within the limits (refused: {}).",
        o.pool.qs.len(),
        o.pool.tried,
        select::refusals(&o.pool)
    );
    let _ = writeln!(s, "- Training: {} poses chosen by DETMAX from {} (session {TRAINING} in `poses.csv`).", plan.poses, plan.pool);
    let _ = writeln!(
        s,
        "- Validation: {} poses spread over the workspace of interest (marked `{VALIDATION}` in the `split` column of `poses.csv`: `calsim calibrate` holds them out).",
        plan.validation
    );
    let _ = writeln!(
        s,
        "- O1 of the chosen set: {:.6} (a random set of the same size from the same pool: {:.6}); {} columns: {}.",
        o.o1.0,
        o.o1.1,
        o.detmax_params.len(),
        o.detmax_params.join(", ")
    );
    let _ = writeln!(
        s,
        "- Tour (`tour.csv`): greedy nearest neighbour in joint space, {:.1} deg of joint-space path; moves through a collision (checked every {:.0} deg): {}.\n",
        o.tour.1.to_degrees(),
        select::MOVE_STEP_RAD.to_degrees(),
        if o.colliding_moves.is_empty() {
            "none".to_string()
        } else {
            o.colliding_moves
                .iter()
                .map(|(a, b)| format!("{} -> {}", o.rows[o.tour.0[*a]].label, o.rows[o.tour.0[*b]].label))
                .collect::<Vec<_>>()
                .join(", ")
        }
    );
    let _ = writeln!(s, "## Parameters the plan cannot identify\n");
    if p.unidentifiable.is_empty() {
        let _ = writeln!(s, "None of the {} model's parameters.\n", plan.model.name());
    } else {
        for u in &p.unidentifiable {
            let _ = writeln!(
                s,
                "- {} (moves the points as {} do): kept nominal",
                u.name,
                if u.with.is_empty() { "nothing else".into() } else { u.with.join(", ") }
            );
        }
        s.push('\n');
    }
    let _ = writeln!(s, "## Predicted held-out error\n");
    let [a, b, c] = p.quantiles_mm;
    let _ = writeln!(
        s,
        "The held-out median error after calibration over {} simulated worlds (calibrate's plan simulation: a pilot world, the robot file's truth measured at these poses with the tracker's noise and calibrated; its calibrated robot then taken as the truth in every world, measured again with {:.4} mm per coordinate, the tracker's noise pooled over the plan's points, and calibrated again):\n",
        p.worlds, p.noise_mm
    );
    let _ = writeln!(s, "| P10, mm | median, mm | P90, mm | pilot world, mm | model chosen in the pilot |\n|---|---|---|---|---|");
    let _ = writeln!(s, "| {a:.4} | {b:.4} | {c:.4} | {:.4} | {} |\n", p.pilot_median_mm, p.pilot_chosen);
    if p.pilot_median_mm > c {
        let _ = writeln!(
            s,
            "The pilot world lies above P90: the robot file's truth holds what the {} model does not describe (its calibrated robot, the worlds' truth, does not): a richer model would calibrate that robot better.\n",
            plan.model.name()
        );
    }
    let _ = writeln!(
        s,
        "A robot the model describes completely, measured with this noise, calibrates to this. Effects outside the model (gear harmonics, backlash, temperature) add to it: `calsim calibrate --plan-worlds N` on the measured file says whether the robot does.\n"
    );
    let _ = writeln!(s, "## Files\n");
    let _ = writeln!(
        s,
        "- `poses.csv`: the calibrate measurement file, joint columns filled, position columns to fill with the tracker's readings."
    );
    let _ = writeln!(s, "- `joints.txt`: the same poses as a plain joint list.");
    let _ = writeln!(s, "- `tour.csv`: the order to visit them.");
    s
}
