//! `calsim plan`: the poses to measure on the real robot, and the accuracy they will buy.
//!
//! ```text
//! plan file ─► spec::parse ─► cell::Cell (capsules, SMRs, floor, keep-out boxes, tracker head;
//!                              range, field of view, incidence, line of sight)
//!  ─► select::pool (uniform candidates within the limits, each from its own stream, kept if feasible)
//!  ─► select::validation (spread over the workspace of interest: farthest-point sampling)
//!  ─► select::choose (DETMAX on the identification Jacobian of the model's identifiable
//!     parameters, a base and a tool)      ─► select::tour (greedy nearest neighbour in joint space;
//!     select::reroute: a move through a collision re-routed through via configurations)
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
pub mod device;
pub mod device_summary;
pub mod device_view;
pub mod files;
pub mod plot;
pub mod record;
pub mod select;
pub mod spec;
pub mod summary;

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
    let layout = Layout { robot: set.clone(), sessions: 1, targets, still: vec![] };
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
    /// The worlds and the pilot carry the twin's effects (the robot file's `[learned]` table).
    pub twin: bool,
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
    /// Straight moves of the tour through a collision (positions in the tour).
    pub colliding_moves: Vec<(usize, usize)>,
    /// Those moves re-routed through via configurations, and those that could not be.
    pub routing: select::Routing,
    /// The prediction.
    pub prediction: Prediction,
    /// Training poses planned (the plan's `poses`, or the count its objective's search chose).
    pub poses: usize,
    /// The objective's search (`None`: the count is fixed).
    pub search: Option<Search>,
    /// DETMAX against random and greedy selection (`None`: not asked).
    pub comparison: Option<Comparison>,
}

/// One count of the objective's search, scored on the search's worlds.
#[derive(Clone, Debug, PartialEq)]
pub struct Candidate {
    /// Training poses (DETMAX's set of this size).
    pub n: usize,
    /// Worlds whose statistic is at most the threshold.
    pub successes: usize,
    /// Worlds simulated (a world whose calibration gives no value counts as a failure).
    pub worlds: usize,
    /// One-sided lower Clopper-Pearson bound of P(success) at the objective's confidence.
    pub lower: f64,
    /// The lower bound clears the objective's probability.
    pub meets: bool,
}

/// The objective's search over the count of training poses.
#[derive(Clone, Debug, PartialEq)]
pub struct Search {
    /// Every count scored, in the order of the search (doubling, then bisection).
    pub candidates: Vec<Candidate>,
    /// The smallest count scored that meets the objective (`None`: none does).
    pub chosen: Option<usize>,
    /// The count planned: the chosen one, else the one with the highest lower bound (the smallest
    /// among equals).
    pub planned: usize,
}

impl Search {
    /// The candidates by count.
    pub fn by_count(&self) -> Vec<&Candidate> {
        let mut v: Vec<&Candidate> = self.candidates.iter().collect();
        v.sort_by_key(|c| c.n);
        v
    }
}

/// One selection's predicted held-out error over the prediction's worlds.
#[derive(Clone, Debug, PartialEq)]
pub struct SelectionRow {
    /// `DETMAX`, `random`, `greedy D-optimal`.
    pub name: &'static str,
    /// Its O1 on the pool's Jacobian.
    pub o1: f64,
    /// The held-out median per world, mm (NaN: the world's calibration gave none).
    pub per_world_mm: Vec<f64>,
    /// Median over the worlds and its interval, mm.
    pub median_mm: (f64, f64, f64),
    /// P90 over the worlds and its interval, mm.
    pub p90_mm: (f64, f64, f64),
}

/// DETMAX's set against a random and a greedy set of the same size from the same pool, each
/// simulated on the same worlds (the prediction's: the same truth, world w's noise from the same
/// stream).
#[derive(Clone, Debug, PartialEq)]
pub struct Comparison {
    /// Confidence of the intervals.
    pub confidence: f64,
    /// DETMAX, random, greedy.
    pub rows: Vec<SelectionRow>,
}

/// Confidence of the comparison's intervals when the plan names no objective.
pub const COMPARISON_CONFIDENCE: f64 = 0.9;

/// The distribution-free interval of the `p` quantile of `sorted` (finite, ascending) at
/// `confidence` or more: the j-th and k-th smallest values with j and k from Binomial(n, p)
/// (each tail at most (1 - confidence) / 2); an end no rank reaches is infinite.
pub fn quantile_interval(sorted: &[f64], p: f64, confidence: f64) -> (f64, f64) {
    use crate::study::interval::binomial_cdf;
    let n = sorted.len();
    let tail = (1.0 - confidence) / 2.0;
    // Lower: the largest j with P(X <= j - 1) <= tail, X ~ Binomial(n, p) the values below the quantile.
    let mut j = 0;
    while j < n && binomial_cdf(j as u64, n as u64, p) <= tail {
        j += 1;
    }
    // Upper: the smallest k with P(X <= k - 1) >= 1 - tail.
    let k = (1..=n).find(|&k| binomial_cdf(k as u64 - 1, n as u64, p) >= 1.0 - tail);
    (if j >= 1 { sorted[j - 1] } else { f64::NEG_INFINITY }, k.map_or(f64::INFINITY, |k| sorted[k - 1]))
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
    let validation_rows: Vec<PoseRow> = val
        .iter()
        .enumerate()
        .map(|(k, &i)| PoseRow { label: format!("v{:03}", k + 1), session: TRAINING, split: VALIDATION, q: pool.qs[i] })
        .collect();
    let rows_of = |chosen: &[usize]| -> Vec<PoseRow> {
        let mut rows: Vec<PoseRow> = chosen
            .iter()
            .enumerate()
            .map(|(k, &i)| PoseRow { label: format!("p{:03}", k + 1), session: TRAINING, split: TRAIN, q: training[i] })
            .collect();
        rows.extend(validation_rows.iter().cloned());
        rows
    };
    let search = match &plan.objective {
        None => None,
        Some(o) => {
            let mut every = rows_of(&(0..training.len()).collect::<Vec<_>>());
            for (k, r) in every.iter_mut().enumerate().take(training.len()) {
                r.label = format!("q{:04}", k + 1);
            }
            let (reference, noise_mm) = pilot(plan, &cell, &every)?;
            let score = |n: usize| -> Result<Candidate, PlanError> {
                let (chosen, _) = select::choose(plan, &jac, n)?;
                let stats = worlds_at(plan, &reference, noise_mm, &rows_of(&chosen))?;
                let successes = stats.iter().filter(|s| s.is_some_and(|s| o.statistic.of_stats(&s) <= o.threshold_mm)).count();
                let lower = crate::study::interval::clopper_pearson_lower(successes as f64, stats.len() as f64, o.confidence);
                Ok(Candidate { n, successes, worlds: stats.len(), lower, meets: lower >= o.success_at_least })
            };
            Some(search(o, score)?)
        }
    };
    let poses = search.as_ref().map_or(plan.poses, |s| s.planned);
    let (chosen, o1) = select::choose(plan, &jac, poses)?;
    let random_set = {
        let mut rng = crate::seeds::stream(plan.seed, crate::seeds::plan::RANDOM);
        let mut s = rand::seq::index::sample(&mut rng, training.len(), poses).into_vec();
        s.sort_unstable();
        s
    };
    let random = crate::identify::detmax::o1_of(&jac, &random_set);
    let rows = rows_of(&chosen);
    let qs: Vec<Joints> = rows.iter().map(|r| r.q).collect();
    let tour = select::tour(&cell, &qs);
    let colliding_moves = select::colliding_moves(&cell, &qs, &tour.0);
    let routing = select::reroute(&qs, &tour.0, &colliding_moves, &pool.qs, cell.model.limits(), |st, q| {
        forward(&cell.model, st, q);
        cell.collides(st)
    });
    let (prediction, pilot_c) = predict_with_pilot(plan, &cell, &rows)?;
    let comparison = if plan.compare {
        let confidence = plan.objective.as_ref().map_or(COMPARISON_CONFIDENCE, |o| o.confidence);
        let greedy = select::greedy(&jac, poses);
        let row = |name: &'static str, o1: f64, per_world_mm: Vec<f64>| {
            let sorted = crate::study::stats::finite_sorted(&per_world_mm);
            let (m0, m1) = quantile_interval(&sorted, 0.5, confidence);
            let (p0, p1) = quantile_interval(&sorted, 0.9, confidence);
            let q = |p: f64| crate::numeric::quantile(&sorted, p);
            SelectionRow { name, o1, per_world_mm, median_mm: (q(0.5), m0, m1), p90_mm: (q(0.9), p0, p1) }
        };
        let medians = |set: &[usize]| -> Result<Vec<f64>, PlanError> {
            Ok(worlds_at(plan, &pilot_c, prediction.noise_mm, &rows_of(set))?.iter().map(|s| s.map_or(f64::NAN, |s| s.median)).collect())
        };
        Some(Comparison {
            confidence,
            rows: vec![
                row("DETMAX", o1, medians(&chosen)?),
                row("random", random, medians(&random_set)?),
                row("greedy D-optimal", crate::identify::detmax::o1_of(&jac, &greedy), medians(&greedy)?),
            ],
        })
    } else {
        None
    };
    Ok(Outcome {
        pool,
        rows,
        o1: (o1, random),
        detmax_params: set.names(),
        tour,
        colliding_moves,
        routing,
        prediction,
        poses,
        search,
        comparison,
    })
}

/// The objective's search: DETMAX's set of each count scored by `score`; counts doubled from the
/// fewest until one meets the objective (or the most is reached), then bisected between the
/// largest count that failed and the smallest that met it, down to adjacent counts.
pub fn search(o: &spec::Objective, mut score: impl FnMut(usize) -> Result<Candidate, PlanError>) -> Result<Search, PlanError> {
    let mut candidates: Vec<Candidate> = Vec::new();
    let mut failed: Option<usize> = None;
    let mut met: Option<usize> = None;
    let mut n = o.fewest_poses;
    loop {
        let c = score(n)?;
        let ok = c.meets;
        candidates.push(c);
        if ok {
            met = Some(n);
            break;
        }
        failed = Some(n);
        if n >= o.most_poses {
            break;
        }
        n = (2 * n).min(o.most_poses);
    }
    if let (Some(mut lo), Some(mut hi)) = (failed, met) {
        while hi - lo > 1 {
            let mid = lo + (hi - lo) / 2;
            let c = score(mid)?;
            if c.meets {
                hi = mid;
            } else {
                lo = mid;
            }
            candidates.push(c);
        }
        met = Some(hi);
    }
    let planned = met.unwrap_or_else(|| {
        candidates.iter().max_by(|a, b| a.lower.total_cmp(&b.lower).then(b.n.cmp(&a.n))).expect("one candidate at least").n
    });
    Ok(Search { candidates, chosen: met, planned })
}

/// The held-out statistics per world of `rows` simulated on `reference`'s calibrated robot (the
/// plan's worlds, seed and noise; the twin's effects where the robot file has them).
fn worlds_at(
    plan: &Plan,
    reference: &crate::calibrate::Calibration,
    noise_mm: f64,
    rows: &[PoseRow],
) -> Result<Vec<Option<crate::study::stats::ErrorStats>>, PlanError> {
    let fail = |e: String| PlanError::new(&plan.path, "poses", format!("the plan's poses cannot be calibrated: {e}"));
    // Positions are placeholders: every world replaces them.
    let zeros: Vec<Vec<Vector3<f64>>> = rows.iter().map(|_| vec![Vector3::zeros(); plan.targets.len()]).collect();
    let text = csv(plan, rows, &zeros)?;
    let m = crate::calibrate::measurements::parse(Path::new("(a candidate set of the plan)"), &text, &plan.robot)
        .map_err(|e| fail(e.to_string()))?;
    let effects = twin_effects(plan);
    let basis = fixed_noise(noise_mm, effects.as_ref());
    crate::calibrate::plan::simulate_at(reference, &m, plan.worlds, crate::seeds::split_seed(plan.seed, crate::seeds::plan::WORLDS), &basis)
        .map(|(_, s)| s)
        .map_err(|e| fail(e.to_string()))
}

/// A plan's worlds: the instrument's noise `noise_mm` at every point and the twin's `effects`.
fn fixed_noise(noise_mm: f64, effects: Option<&crate::calibrate::plan::Effects>) -> crate::calibrate::plan::Basis<'_> {
    crate::calibrate::plan::Basis { noise: crate::calibrate::plan::Noise::Fixed(noise_mm), effects, twin: None, label: None }
}

/// The twin's effects drawn in every world of a prediction: the robot file's `[learned]` table
/// (`None` when it has none or no effect).
pub fn twin_effects(plan: &Plan) -> Option<crate::calibrate::plan::Effects> {
    let l = plan.robot.learned.as_ref().filter(|l| !l.is_none())?;
    Some(crate::calibrate::plan::Effects {
        source: format!("the [learned] table of {}", plan.robot_name),
        unmodelled: crate::robot::UnmodelledSpec::default(),
        repeatability_mm: l.repeatability_mm,
        learned: Some(l.clone()),
    })
}

/// The measurement file of `rows` at every target: `positions` (per row, per target, mm) or
/// empty position columns, with `comments` among its `#` lines. The joint columns are the
/// controller's values (the robot file's coupling inverted where it has one), in degrees written
/// to round-trip. Its table ([`crate::calibrate::measurements::file::measurement_file`]) and its text.
pub fn measurement_file(
    plan: &Plan,
    rows: &[PoseRow],
    positions: Option<&[Vec<Vector3<f64>>]>,
    comments: &[String],
) -> std::io::Result<(crate::io::table::Frame, String)> {
    let mut lines: Vec<String> = positions.map(|_| "simulated = true".to_string()).into_iter().collect();
    lines.push(format!("format = {}", crate::calibrate::measurements::FORMAT));
    lines.push("joints = controller".into());
    lines.push(format!("robot = {}", plan.robot_name));
    lines.push("frame = laser tracker frame".into());
    lines.extend(comments.iter().cloned());
    let mut table = Vec::with_capacity(rows.len() * plan.targets.len());
    for (r, row) in rows.iter().enumerate() {
        let qc = plan.robot.coupling.as_ref().map_or(row.q, |c| c.controller_from_model(&row.q));
        for (k, t) in plan.targets.iter().enumerate() {
            table.push(crate::calibrate::measurements::file::MeasurementRow {
                pose: &row.label,
                session: row.session,
                target: &t.name,
                split: Some(row.split),
                q_deg: qc.map(f64::to_degrees),
                xyz_mm: positions.map(|p| p[r][k].into()),
                quat: None,
            });
        }
    }
    crate::calibrate::measurements::file::measurement_file(&lines, &table)
}

/// The text of [`measurement_file`], for `calibrate`'s reader.
fn csv(plan: &Plan, rows: &[PoseRow], positions: &[Vec<Vector3<f64>>]) -> Result<String, PlanError> {
    measurement_file(plan, rows, Some(positions), &[]).map(|(_, text)| text).map_err(|e| PlanError::new(&plan.path, "poses", e.to_string()))
}

/// What [`measure`] gives: the positions per row and target, mm, and the noise per point, mm.
pub type Measured = (Vec<Vec<Vector3<f64>>>, Vec<f64>);

/// The robot file's truth (its nominal where it gives none) measured at `rows` at every target,
/// in the base frame, with the tracker's noise at each point's distance (pooled per coordinate,
/// [`spec::Tracker::sigma_mm`]) drawn from the stream `key` of the plan's seed. Returns the
/// positions and the noise per point.
pub fn measure(plan: &Plan, cell: &Cell, rows: &[PoseRow], key: u64) -> Result<Measured, PlanError> {
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
    // The twin's effects: one robot drawn from the plan's seed (the same for the pilot and
    // `--simulate`), its moves' noise from a stream of `key`; the rows visited in order from the
    // middle of the limits.
    let links: Vec<Joints> = match twin_effects(plan) {
        None => rows.iter().map(|r| r.q).collect(),
        Some(e) => {
            let mid: Joints = std::array::from_fn(|i| 0.5 * (plan.limits[i].min + plan.limits[i].max));
            let mut draw = crate::seeds::stream(plan.seed, crate::seeds::plan::TWIN);
            let robot = crate::robot::VirtualRobot::new(placed[0].clone(), &e.unmodelled, e.repeatability_mm, &mid, &mut draw)
                .with_learned(e.learned.as_ref(), &mut draw);
            let mut moves = crate::seeds::stream(crate::seeds::split_seed(plan.seed, crate::seeds::plan::TWIN), key);
            let mut from = mid;
            rows.iter()
                .map(|r| {
                    let l = robot.link_angles(&r.q, &from, &mut moves);
                    from = r.q;
                    l
                })
                .collect()
        }
    };
    let positions = links
        .iter()
        .map(|l| {
            placed
                .iter()
                .map(|m| {
                    let p = forward(m, &mut st, l);
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
    Ok(predict_with_pilot(plan, cell, rows)?.0)
}

/// The pilot world at `rows`: the robot file's truth (with the twin's effects where it has them)
/// measured with the tracker's noise and calibrated; with the tracker's noise pooled per
/// coordinate, mm.
fn pilot(plan: &Plan, cell: &Cell, rows: &[PoseRow]) -> Result<(crate::calibrate::Calibration, f64), PlanError> {
    let (positions, sigmas) = measure(plan, cell, rows, crate::seeds::plan::PILOT)?;
    let text = csv(plan, rows, &positions)?;
    let pilot_path = Path::new("(the plan's pilot world)");
    let fail = |e: String| PlanError::new(&plan.path, "poses", format!("the plan's poses cannot be calibrated: {e}"));
    let m = crate::calibrate::measurements::parse(pilot_path, &text, &plan.robot).map_err(|e| fail(e.to_string()))?;
    let c = crate::calibrate::run(&plan.robot, &m, &calibrate_options(plan)).map_err(|e| fail(e.to_string()))?;
    let noise_mm = (sigmas.iter().map(|s| s * s).sum::<f64>() / sigmas.len() as f64).sqrt();
    Ok((c, noise_mm))
}

/// [`predict`], with the pilot world's calibration (the truth of every world).
pub fn predict_with_pilot(plan: &Plan, cell: &Cell, rows: &[PoseRow]) -> Result<(Prediction, crate::calibrate::Calibration), PlanError> {
    let (c, noise_mm) = pilot(plan, cell, rows)?;
    let effects = twin_effects(plan);
    let seed = crate::seeds::split_seed(plan.seed, crate::seeds::plan::WORLDS);
    let (_, stats) = crate::calibrate::plan::simulate_at(&c, &c.measurements, plan.worlds, seed, &fixed_noise(noise_mm, effects.as_ref()))
        .map_err(|e| PlanError::new(&plan.path, "poses", format!("the plan's poses cannot be calibrated: {e}")))?;
    let per_world_mm: Vec<f64> = stats.iter().map(|s| s.map_or(f64::NAN, |s| Statistic::Median.of_stats(&s))).collect();
    let sorted = crate::study::stats::finite_sorted(&per_world_mm);
    let q = |p: f64| crate::numeric::quantile(&sorted, p);
    let unidentifiable = c.models.iter().rev().find(|r| r.kind.is_some()).map(|r| r.unidentifiable.clone()).unwrap_or_default();
    let prediction = Prediction {
        pilot_chosen: c.chosen().kind.map_or("before", |k| k.name()),
        pilot_median_mm: Statistic::Median.of(&c).unwrap_or(f64::NAN),
        noise_mm,
        worlds: sorted.len(),
        quantiles_mm: [q(0.1), q(0.5), q(0.9)],
        per_world_mm,
        unidentifiable,
        twin: twin_effects(plan).is_some(),
    };
    Ok((prediction, c))
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

/// The tour: step, pose, split, joint values (deg, controller), the move to it (largest joint
/// change, deg); a via configuration of a re-routed move is a row of its own, split `via`
/// (passed, not measured). Its table ([`files::tour_file`]) and its text.
pub fn tour_file(plan: &Plan, o: &Outcome) -> std::io::Result<(crate::io::table::Frame, String)> {
    let stops = select::stops(&o.tour.0, &o.routing);
    let rows = files::tour_rows(
        &stops,
        |stop| match stop {
            select::Stop::Pose(i) => (o.rows[*i].label.as_str(), o.rows[*i].split, None, o.rows[*i].q),
            select::Stop::Via(label, q) => (label.as_str(), select::VIA, None, *q),
        },
        |q| plan.robot.coupling.as_ref().map_or(*q, |c| c.controller_from_model(q)).map(f64::to_degrees),
    );
    files::tour_file(None, &rows)
}

/// `plan.md`: what was planned and what it will buy, rendered from the plan's tables
/// ([`summary::tables`]) by [`summary::markdown`] (or the error that kept it from rendering).
pub fn markdown(plan: &Plan, o: &Outcome) -> String {
    summary::markdown(&summary::tables(plan, o)).unwrap_or_else(|e| e.to_string())
}
