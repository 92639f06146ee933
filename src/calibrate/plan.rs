//! Plan against outcome: the seam where a planned calibration's simulation meets the measured one.
//!
//! The scenario that planned the calibration simulates the same poses (the measured sessions,
//! targets and joint values of [`Calibration::measurements`], the same instrument noise) in many
//! worlds, runs [`super::run`] on each simulated file, and collects one figure per world: the
//! held-out error after calibration (the same statistic as the measured one). [`compare`] puts the
//! measured figure beside that distribution and says whether it falls inside the simulated
//! P10-P90; the report writes it as `plan.md`.
//!
//! [`simulate`] builds the distribution from the calibration itself (`calsim calibrate
//! --plan-worlds N`): the calibrated robot, the registered sessions and targets taken as the
//! truth, measured at the file's own joint values with isotropic noise, calibrated again the same
//! way in each world; with a planning scenario (`--plan-scenario`), its robot's effects outside the
//! model and its repeatability are drawn in each world too ([`Effects`]). A measured held-out error inside the simulated
//! P10-P90 is what the chosen model and that noise explain; one above it says the robot does
//! something the model does not (or the noise is not independent per point).

use std::fmt::Write as _;

use nalgebra::Vector3;
use polars::prelude::Column;
use rand_distr::{Distribution, Normal};

use super::{CalibrateError, Calibration};
use crate::robot::{KinState, forward};
use crate::study::stats::{ErrorStats, finite_sorted, quantile};

/// Which held-out statistic the comparison is made on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Statistic {
    /// Median of the held-out errors.
    Median,
    /// 95th percentile.
    P95,
    /// Root mean square.
    Rms,
    /// Largest.
    Max,
}

impl Statistic {
    /// Name for tables.
    pub fn name(self) -> &'static str {
        match self {
            Statistic::Median => "median",
            Statistic::P95 => "p95",
            Statistic::Rms => "RMS",
            Statistic::Max => "max",
        }
    }

    /// This statistic of the measured held-out errors of the chosen model, mm.
    pub fn of(self, c: &Calibration) -> Option<f64> {
        Some(self.of_stats(&c.chosen().held_out.as_ref()?.measured))
    }

    /// This statistic of `s`, mm.
    pub fn of_stats(self, s: &ErrorStats) -> f64 {
        match self {
            Statistic::Median => s.median,
            Statistic::P95 => s.p95,
            Statistic::Rms => s.rms,
            Statistic::Max => s.max,
        }
    }
}

/// The planned calibration's simulated outcome at the measured poses.
#[derive(Clone, Debug, PartialEq)]
pub struct SimulatedOutcome {
    /// The scenario that planned the calibration.
    pub scenario: String,
    /// The statistic.
    pub statistic: Statistic,
    /// One value per simulated world, mm.
    pub per_world_mm: Vec<f64>,
}

/// The measured figure beside the simulated distribution.
#[derive(Clone, Debug, PartialEq)]
pub struct PlanComparison {
    /// The scenario.
    pub scenario: String,
    /// The statistic.
    pub statistic: Statistic,
    /// Measured, mm (NaN when the held-out fit gave no model).
    pub measured_mm: f64,
    /// Simulated P10, median, P90, mm.
    pub simulated_mm: [f64; 3],
    /// Worlds with a finite value.
    pub worlds: usize,
    /// The measured figure lies within the simulated P10-P90.
    pub inside: bool,
}

/// Compares the measured calibration `c` with the simulated outcome `sim`.
pub fn compare(c: &Calibration, sim: &SimulatedOutcome) -> PlanComparison {
    PlanComparison {
        scenario: sim.scenario.clone(),
        statistic: sim.statistic,
        ..compare_values(sim.statistic.of(c).unwrap_or(f64::NAN), &sim.per_world_mm)
    }
}

/// The measured figure `measured_mm` beside the worlds' values `per_world_mm` (NaN: a world
/// without a value): their P10, median and P90, and whether it lies within the P10-P90 (the
/// scenario's name is left empty and the statistic is the median).
pub fn compare_values(measured_mm: f64, per_world_mm: &[f64]) -> PlanComparison {
    let sorted = finite_sorted(per_world_mm);
    let q = |p: f64| quantile(&sorted, p);
    let simulated = [q(0.1), q(0.5), q(0.9)];
    PlanComparison {
        scenario: String::new(),
        statistic: Statistic::Median,
        measured_mm,
        simulated_mm: simulated,
        worlds: sorted.len(),
        inside: measured_mm >= simulated[0] && measured_mm <= simulated[2],
    }
}

/// What a plan against the outcome draws in each world (`--plan-with`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PlanWith {
    /// The twin: its robot and learned effects (repeatability, per-pose error, drift) and the
    /// instrument's noise.
    #[default]
    Twin,
    /// The instrument's noise alone (the calibrated robot as the model describes it).
    Noise,
    /// The fit's residual level as white noise.
    Residual,
    /// The three, one row each.
    All,
}

impl PlanWith {
    /// The option's values.
    pub const NAMES: [&'static str; 4] = ["twin", "noise", "residual", "all"];

    /// Parses an option value.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "twin" => Some(Self::Twin),
            "noise" => Some(Self::Noise),
            "residual" => Some(Self::Residual),
            "all" => Some(Self::All),
            _ => None,
        }
    }

    /// The plans it asks for, in the order of the table.
    pub fn plans(self) -> Vec<PlanWith> {
        match self {
            Self::All => vec![Self::Noise, Self::Twin, Self::Residual],
            k => vec![k],
        }
    }

    /// Short name of a plan.
    pub fn name(self) -> &'static str {
        match self {
            Self::Twin => "twin",
            Self::Noise => "noise only",
            Self::Residual => "residual as noise",
            Self::All => "all",
        }
    }
}

/// The plans beside the measured figure as a table, a row per plan in the order of `plan.md`'s:
/// `plan` (its name), `scenario` (what each world draws), `statistic`, `measured_mm`,
/// `simulated_p10_mm`, `simulated_mm` (the median), `simulated_p90_mm`, `worlds` (with a finite
/// value) and `inside` (the measured figure within the simulated P10-P90).
pub fn table(plans: &[(PlanWith, PlanComparison)]) -> std::io::Result<crate::io::table::Frame> {
    crate::io::table::frame("plan", columns(plans))
}

/// The columns of [`table`] (`plans.parquet` in the report).
pub fn columns(plans: &[(PlanWith, PlanComparison)]) -> Vec<Column> {
    let text =
        |name: &str, v: fn(&(PlanWith, PlanComparison)) -> &str| Column::new(name.into(), plans.iter().map(v).collect::<Vec<&str>>());
    let number =
        |name: &str, v: fn(&PlanComparison) -> f64| Column::new(name.into(), plans.iter().map(|(_, p)| v(p)).collect::<Vec<f64>>());
    vec![
        text("plan", |(k, _)| k.name()),
        text("scenario", |(_, p)| &p.scenario),
        text("statistic", |(_, p)| p.statistic.name()),
        number("measured_mm", |p| p.measured_mm),
        number("simulated_p10_mm", |p| p.simulated_mm[0]),
        number("simulated_mm", |p| p.simulated_mm[1]),
        number("simulated_p90_mm", |p| p.simulated_mm[2]),
        Column::new("worlds".into(), plans.iter().map(|(_, p)| p.worlds as u64).collect::<Vec<u64>>()),
        Column::new("inside".into(), plans.iter().map(|(_, p)| p.inside).collect::<Vec<bool>>()),
    ]
}

/// Several plans beside the measured figure, as markdown: one row per plan, and lines for the
/// plans that could not be made (`missing`).
pub fn markdown_all(plans: &[(PlanWith, PlanComparison)], missing: &[(PlanWith, String)]) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# Plan against outcome\n");
    let Some((_, first)) = plans.first() else {
        for (k, why) in missing {
            let _ = writeln!(s, "- {}: {why}", k.name());
        }
        return s;
    };
    let _ = writeln!(
        s,
        "The held-out {} error after calibration, measured ({:.4} mm), beside simulations of the same poses: in each world the \
         robot below is measured at the file's joint values with the noise below and calibrated again the same way.\n",
        first.statistic.name(),
        first.measured_mm
    );
    let _ = writeln!(
        s,
        "| plan | each world draws | worlds | simulated P10 | median | P90 | measured inside P10-P90 |\n|---|---|---|---|---|---|---|"
    );
    let _ = writeln!(s, "| measured | the measurement file | - | - | {:.4} | - | - |", first.measured_mm);
    for (k, p) in plans {
        let [a, b, c] = p.simulated_mm;
        let _ = writeln!(
            s,
            "| {} | {} | {} | {a:.4} | {b:.4} | {c:.4} | {} |",
            k.name(),
            p.scenario,
            p.worlds,
            if p.inside { "yes" } else { "no" }
        );
    }
    for (k, why) in missing {
        let _ = writeln!(s, "\n- {}: not simulated: {why}", k.name());
    }
    let _ = writeln!(
        s,
        "\nInside with noise only: the chosen model and the instrument explain the outcome. Inside with the twin only: what the \
         model misses (the twin's effects, repeatability and per-pose error, learned on the calibration split) explains it. \
         The residual-as-noise plan takes whatever the model misses for white noise: it tests the fit and the poses, not the model."
    );
    s
}

/// The comparison as markdown.
pub fn markdown(p: &PlanComparison) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# Plan against outcome\n");
    let _ = writeln!(
        s,
        "The held-out {} error after calibration, measured, beside scenario {}'s simulation of the same poses ({} worlds).\n",
        p.statistic.name(),
        p.scenario,
        p.worlds
    );
    let _ = writeln!(s, "| measured, mm | simulated P10 | median | P90 | inside P10-P90 |\n|---|---|---|---|---|");
    let [a, b, c] = p.simulated_mm;
    let _ = writeln!(s, "| {:.4} | {a:.4} | {b:.4} | {c:.4} | {} |", p.measured_mm, if p.inside { "yes" } else { "no" });
    s
}

/// The noise per coordinate of the simulated worlds, mm: the chosen model's residual RMS over the
/// points it kept (its fit on every point), over sqrt(3) (three coordinates), or, where the file
/// gives per-point uncertainties, each point's own.
pub fn residual_noise_mm(c: &Calibration) -> f64 {
    let fit = &c.chosen().fit;
    let kept: Vec<f64> = fit.errors_mm.iter().zip(&fit.outlier).filter(|(e, o)| !**o && e.is_finite()).map(|(e, _)| *e).collect();
    if kept.is_empty() {
        return f64::NAN;
    }
    (kept.iter().map(|e| e * e).sum::<f64>() / kept.len() as f64 / 3.0).sqrt()
}

/// The calibration's plan by simulation over `worlds` worlds (see the module's doc): per world,
/// the measurement file's points replaced by the calibrated robot's positions at the same joint
/// values (in each session's registered frame, at each target's registered position) plus
/// noise, calibrated with the same options (no figures), and the chosen model's held-out
/// `statistic` taken. The noise per coordinate is `noise_mm` (the instrument's, when known: the
/// plan then says what a robot the model describes completely would give), else a point's own
/// uncertainty, else the fit's residual level ([`residual_noise_mm`], which takes whatever the
/// model misses for noise: that plan tests the fit and the poses, not the model's completeness). World `w`'s noise is the stream of `split_seed(seed, w)`: the plan is a
/// function of the data and the seed, the same for any thread count.
pub fn simulate(
    c: &Calibration,
    worlds: usize,
    statistic: Statistic,
    seed: u64,
    noise_mm: Option<f64>,
    effects: Option<&Effects>,
) -> Result<SimulatedOutcome, CalibrateError> {
    let sigma = noise_mm.unwrap_or_else(|| residual_noise_mm(c));
    let noise = match noise_mm {
        Some(s) => Noise::Fixed(s),
        None => Noise::PointsElse(sigma),
    };
    let basis = Basis { noise, effects, twin: None, label: None };
    simulate_basis(c, worlds, statistic, seed, &basis)
}

/// The noise of a plan's worlds per coordinate, mm.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Noise {
    /// The same for every point.
    Fixed(f64),
    /// Each point's own uncertainty, else this.
    PointsElse(f64),
}

/// What each world of a plan draws besides the calibrated robot's positions.
#[derive(Clone, Debug)]
pub struct Basis<'a> {
    /// The noise per coordinate.
    pub noise: Noise,
    /// A planning scenario's robot effects and repeatability.
    pub effects: Option<&'a Effects>,
    /// A twin: its robot (the truth of each world instead of the calibrated one) and its learned
    /// effects (drawn per world: coefficients, repeatability, per-pose error, drift over each
    /// session's poses).
    pub twin: Option<(&'a crate::robot::RobotModel, &'a crate::robot::learned::LearnedEffects)>,
    /// The plan's name in the report (`None`: the calibrated robot and its noise).
    pub label: Option<String>,
}

/// The calibration's plan by simulation over `worlds` worlds with what `basis` draws (see
/// [`simulate`]).
pub fn simulate_basis(
    c: &Calibration,
    worlds: usize,
    statistic: Statistic,
    seed: u64,
    basis: &Basis<'_>,
) -> Result<SimulatedOutcome, CalibrateError> {
    let (scenario, stats) = simulate_at(c, &c.measurements, worlds, seed, basis)?;
    let per_world_mm = stats.iter().map(|s| s.as_ref().map_or(f64::NAN, |s| statistic.of_stats(s))).collect();
    Ok(SimulatedOutcome { scenario, statistic, per_world_mm })
}

/// [`simulate_basis`] at the poses of `m` (the sessions and targets of `c`'s file, other poses or
/// points): per world, the held-out statistics of the chosen model (`None` when the world's
/// calibration gave none), and the plan in words. World `w` draws from the same stream whatever
/// the poses, so two sets of poses simulated with the same seed meet the same worlds' robots.
pub fn simulate_at(
    c: &Calibration,
    m: &super::measurements::Measurements,
    worlds: usize,
    seed: u64,
    basis: &Basis<'_>,
) -> Result<(String, Vec<Option<ErrorStats>>), CalibrateError> {
    use rayon::prelude::*;
    let sigma = match basis.noise {
        Noise::Fixed(s) | Noise::PointsElse(s) => s,
    };
    let prepared = Prepared::new(c, m, basis)?;
    let mut opts = c.options.clone();
    opts.plots = false;
    let per_world: Vec<Option<ErrorStats>> = (0..worlds)
        .into_par_iter()
        .map(|w| {
            let mw = prepared.world(c, m, basis, seed, w);
            super::run(&c.robot, &mw, &opts).ok().and_then(|cw| cw.chosen().held_out.as_ref().map(|h| h.measured))
        })
        .collect();
    let scenario = basis.label.clone().unwrap_or_else(|| {
        let with = basis.effects.map_or_else(String::new, |e| format!(" with the effects and repeatability of {}", e.source));
        format!("the calibrated robot{with}, noise {sigma:.4} mm per coordinate")
    });
    Ok((scenario, per_world))
}

/// World `w`'s measurement file of a plan with `basis` at seed `seed` (see [`simulate`]): the
/// calibration's own file with every point replaced by what that world's robot gives there
/// (before its calibration).
pub fn world_file(c: &Calibration, basis: &Basis<'_>, seed: u64, w: usize) -> Result<super::measurements::Measurements, CalibrateError> {
    Ok(Prepared::new(c, &c.measurements, basis)?.world(c, &c.measurements, basis, seed, w))
}

/// What every world of a plan at the poses of one file shares.
struct Prepared {
    /// The truth per session and target ([`placed_of`]).
    placed: Vec<crate::robot::RobotModel>,
    /// Per point, the offset carried at a flagged point ([`carried_at`]).
    carried: Vec<Option<Vector3<f64>>>,
    /// Each pose's index within its session (the drift's clock).
    pose_index: Vec<f64>,
}

impl Prepared {
    fn new(c: &Calibration, m: &super::measurements::Measurements, basis: &Basis<'_>) -> Result<Self, CalibrateError> {
        let sigma = match basis.noise {
            Noise::Fixed(s) | Noise::PointsElse(s) => s,
        };
        if !(sigma.is_finite() && (0.0..=100.0).contains(&sigma)) {
            return Err(CalibrateError::Option { key: "plan-noise-mm".into(), message: format!("{sigma}: within 0 to 100 mm") });
        }
        let truth_model = basis.twin.map_or(&c.model, |(model, _)| model);
        let placed = placed_of(c, truth_model)?;
        let carried = carried_at(c, m, basis, &placed)?;
        Ok(Self { placed, carried, pose_index: pose_index_of(c, m) })
    }

    /// World `w`'s file: the truth at the link angles of this world's robot, plus noise (a
    /// flagged point: plus its carried offset, no noise).
    fn world(
        &self,
        c: &Calibration,
        m: &super::measurements::Measurements,
        basis: &Basis<'_>,
        seed: u64,
        w: usize,
    ) -> super::measurements::Measurements {
        let truth_model = basis.twin.map_or(&c.model, |(model, _)| model);
        let targets = c.tools.len();
        let mut rng = crate::seeds::stream(crate::seeds::split_seed(seed, w as u64), crate::seeds::calibrate::PLAN_NOISE);
        // The link angles of every pose, in the file's order of poses: the joint values
        // themselves, or the robot of the planning scenario or the twin with its effects drawn in this world.
        let mut drift = [0.0; 3];
        let links: Vec<crate::robot::Joints> = match (basis.effects, basis.twin) {
            (None, None) => m.poses.iter().map(|p| p.q).collect(),
            (effects, twin) => {
                let reference = reference_of(c);
                let unmodelled = effects.map_or_else(crate::robot::UnmodelledSpec::default, |e| e.unmodelled.clone());
                // Both present: their joint noises add in quadrature.
                let repeatability = match (effects, twin) {
                    (Some(e), Some((_, l))) => e.repeatability_mm.hypot(l.repeatability_mm),
                    (Some(e), None) => e.repeatability_mm,
                    (None, Some((_, l))) => l.repeatability_mm,
                    (None, None) => 0.0,
                };
                let mut robot = crate::robot::VirtualRobot::new(truth_model.clone(), &unmodelled, repeatability, &reference, &mut rng)
                    .with_learned(learned_of(basis), &mut rng);
                // The twin's repeatability level drawn for this world from its estimate's standard
                // deviation, after every other draw of the robot (a table without one draws nothing).
                if let Some((_, l)) = basis.twin.filter(|(_, l)| l.repeatability_std_mm > 0.0) {
                    let drawn = l.drawn_repeatability_mm(&mut rng);
                    robot = robot.with_repeatability(effects.map_or(drawn, |e| e.repeatability_mm.hypot(drawn)), &reference);
                }
                drift = robot.learned.as_ref().map_or([0.0; 3], |l| l.drift_mm_per_pose);
                let mut from = reference;
                m.poses
                    .iter()
                    .map(|p| {
                        let l = robot.link_angles(&p.q, &from, &mut rng);
                        from = p.q;
                        l
                    })
                    .collect()
            }
        };
        let drifts = drift.iter().any(|&d| d != 0.0);
        let mut st = KinState::default();
        let truth: Vec<Vector3<f64>> = m
            .points
            .iter()
            .map(|p| {
                let session = m.poses[p.pose].session;
                let at = forward(&self.placed[session * targets + p.target], &mut st, &links[p.pose]);
                if drifts {
                    let shift = Vector3::from(drift) * self.pose_index[p.pose];
                    at + c.bases[session].session_from_base.isometry().rotation * shift
                } else {
                    at
                }
            })
            .collect();
        let mut mw = m.clone();
        for ((p, t), carried) in mw.points.iter_mut().zip(&truth).zip(&self.carried) {
            if let Some(off) = carried {
                p.measured_mm = t + off;
                continue;
            }
            let s = match basis.noise {
                Noise::Fixed(s) => s,
                Noise::PointsElse(s) => p.sigma_mm.unwrap_or(s),
            };
            let noise = Normal::new(0.0, s).map_or(Vector3::zeros(), |n| Vector3::from_fn(|_, _| n.sample(&mut rng)));
            p.measured_mm = t + noise;
        }
        mw
    }
}

/// Each pose's index within its session, in the file's order of poses.
fn pose_index_of(c: &Calibration, m: &super::measurements::Measurements) -> Vec<f64> {
    let mut counts = vec![0usize; c.bases.len()];
    m.poses
        .iter()
        .map(|p| {
            counts[p.session] += 1;
            (counts[p.session] - 1) as f64
        })
        .collect()
}

/// Per session and target, `truth` placed in the session's frame with the target as its tool:
/// its forward kinematics is the position the session's instrument reads.
fn placed_of(c: &Calibration, truth: &crate::robot::RobotModel) -> Result<Vec<crate::robot::RobotModel>, CalibrateError> {
    let mut placed = Vec::with_capacity(c.bases.len() * c.tools.len());
    for b in &c.bases {
        for t in &c.tools {
            placed.push(truth.edited(|d| {
                d.world_from_base = b.session_from_base;
                d.flange_tcp_mm = t.flange_mm;
            }));
        }
    }
    placed.into_iter().collect::<Result<_, _>>().map_err(|e| CalibrateError::Option {
        key: "plan-worlds".into(),
        message: format!("the calibrated robot cannot be placed in a session's frame: {e}"),
    })
}

/// The commanded joints a plan's first move of every world comes from: mid-range of each joint.
fn reference_of(c: &Calibration) -> crate::robot::Joints {
    std::array::from_fn(|i| {
        let l = c.model.limits()[i];
        0.5 * (l.min + l.max)
    })
}

/// The learned effects a plan's worlds draw (the twin's, else the planning scenario's robot's).
fn learned_of<'a>(basis: &Basis<'a>) -> Option<&'a crate::robot::learned::LearnedEffects> {
    basis.twin.map(|(_, l)| l).or(basis.effects.and_then(|e| e.learned.as_ref()))
}

/// Per point of `m`, what a plan with `basis` carries into every world at a point flagged as an
/// outlier that the fits keep (`--outliers report`; `None` elsewhere, and everywhere unless `m` is
/// the calibration's own file): the measured point less the basis's robot at it, so that each
/// world measures it off its own robot by that much. The basis's robot at a point is its truth
/// (the twin's robot, else the calibrated one) at the link angles its learned effects give at
/// their fitted values (harmonics, backlash by the approach direction in the file's order of
/// poses, sag) and shifted by its drift: what varies from world to world (repeatability, the
/// per-pose error, the noise) stays in the carried offset, the learned effects do not (each world
/// adds its own). `placed`: the truth per session and target ([`placed_of`]).
fn carried_at(
    c: &Calibration,
    m: &super::measurements::Measurements,
    basis: &Basis<'_>,
    placed: &[crate::robot::RobotModel],
) -> Result<Vec<Option<Vector3<f64>>>, CalibrateError> {
    let flagged = |i: usize| c.flagged.get(i).copied().unwrap_or(false);
    if !(std::ptr::eq(m, &c.measurements) && c.options.outliers == super::OutlierMode::Report && (0..m.points.len()).any(flagged)) {
        return Ok(vec![None; m.points.len()]);
    }
    let pull = flagged_pull_mm(c)?;
    let truth_model = basis.twin.map_or(&c.model, |(model, _)| model);
    // The learned effects at their fitted values: every spread, the repeatability and the
    // per-pose error set to zero, so that the draw takes nothing from its stream but the fixed
    // values.
    let fixed = learned_of(basis).map(|l| {
        let mut f = crate::robot::learned::LearnedEffects {
            repeatability_mm: 0.0,
            repeatability_std_mm: 0.0,
            pose_error_mdeg: 0.0,
            pose_error_std_mdeg: 0.0,
            backlash_std_mdeg: [0.0; crate::robot::JOINTS],
            sag_std_mdeg_per_m: [0.0; crate::robot::JOINTS],
            drift_std_mm_per_pose: [0.0; 3],
            ..l.clone()
        };
        for h in &mut f.harmonic {
            h.std_mdeg = 0.0;
        }
        f.draw(truth_model, &mut crate::seeds::stream(crate::seeds::calibrate::FITTED_EFFECTS, crate::seeds::calibrate::PLAN_NOISE))
    });
    let mut from = reference_of(c);
    let links: Vec<crate::robot::Joints> = m
        .poses
        .iter()
        .map(|p| {
            let e = fixed.as_ref().map_or([0.0; crate::robot::JOINTS], |d| d.joint_errors(&p.q, &from));
            from = p.q;
            if fixed.is_some() { std::array::from_fn(|i| p.q[i] + e[i]) } else { p.q }
        })
        .collect();
    let drift = fixed.as_ref().map_or([0.0; 3], |d| d.drift_mm_per_pose);
    let pose_index = pose_index_of(c, m);
    let targets = c.tools.len();
    let mut st = KinState::default();
    Ok(m.points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            flagged(i).then(|| {
                let session = m.poses[p.pose].session;
                let mut at = forward(&placed[session * targets + p.target], &mut st, &links[p.pose]);
                if drift.iter().any(|&d| d != 0.0) {
                    at += c.bases[session].session_from_base.isometry().rotation * (Vector3::from(drift) * pose_index[p.pose]);
                }
                p.measured_mm - at + pull[i]
            })
        })
        .collect())
}

/// Per point of the calibration's file, how far the chosen model's fit on every point was drawn
/// towards it by the flagged points it kept, at the flagged points (zero elsewhere), in the point's
/// session frame, mm: the point's residual in the fit on every point but the flagged ones less its
/// residual in the fit on every point. A flagged point's residual in the fit that kept it is its
/// offset shrunk by its own leverage (the fit moved towards it); its offset from the robot the
/// other points describe is the residual of the fit without it, and that is what a plan's world
/// carries (the offset off the plan's robot plus this), so that each world's fit is drawn towards
/// it as the measured fit was.
pub fn flagged_pull_mm(c: &Calibration) -> Result<Vec<Vector3<f64>>, CalibrateError> {
    let m = &c.measurements;
    let n = m.points.len();
    let chosen = c.chosen();
    let s = super::setup(&c.robot, m)?;
    let problem = super::problem::Problem { start: &c.robot.nominal, layout: chosen.layout.clone(), obs: &s.obs };
    let all: Vec<usize> = (0..n).collect();
    let x0 = super::validation::start_values(&problem.layout, &c.robot.nominal, &s.frames_x);
    let free = super::validation::free_columns(&problem, &all, !problem.layout.robot.is_empty());
    let flagged: Vec<bool> = (0..n).map(|i| c.flagged.get(i).copied().unwrap_or(false)).collect();
    let without = super::robust::fit_without(&problem, &x0, &free, &all, &flagged, &super::problem::SolveOptions::default());
    let at: Vec<usize> = (0..n).filter(|&i| flagged[i]).collect();
    let errors = without.solved.outcome.is_converged().then(|| problem.errors(&without.solved.x, &at)).flatten().ok_or_else(|| {
        CalibrateError::Option {
            key: "plan-worlds".into(),
            message: format!("the {} model's fit without the flagged points gave no model", chosen.name()),
        }
    })?;
    let mut pull = vec![Vector3::zeros(); n];
    for (&i, e) in at.iter().zip(&errors) {
        let session = s.obs[i].session;
        let base = problem.layout.base_delta(&without.solved.x, session).isometry().inverse_transform_vector(e);
        pull[i] = c.bases[session].session_from_base.isometry().rotation * (base - chosen.fit.residual_base_mm[i]);
    }
    Ok(pull)
}

/// What a planning scenario adds to the calibrated robot in each world of a plan: its effects
/// outside the kinematic model (drawn per world: harmonics' phases and orders, backlash, encoder
/// errors) and its ISO 9283 repeatability.
#[derive(Clone, Debug, PartialEq)]
pub struct Effects {
    /// The scenario they come from (for the report).
    pub source: String,
    /// The effects outside the model.
    pub unmodelled: crate::robot::UnmodelledSpec,
    /// ISO 9283 RP, mm.
    pub repeatability_mm: f64,
    /// A twin's learned effects (its robot file's `[learned]` table), drawn per world after the
    /// effects above (`None`: none, and no draw).
    pub learned: Option<crate::robot::learned::LearnedEffects>,
}
