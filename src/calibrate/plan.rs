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
    let sorted = finite_sorted(&sim.per_world_mm);
    let q = |p: f64| quantile(&sorted, p);
    let measured = sim.statistic.of(c).unwrap_or(f64::NAN);
    let simulated = [q(0.1), q(0.5), q(0.9)];
    PlanComparison {
        scenario: sim.scenario.clone(),
        statistic: sim.statistic,
        measured_mm: measured,
        simulated_mm: simulated,
        worlds: sorted.len(),
        inside: measured >= simulated[0] && measured <= simulated[2],
    }
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
    let (scenario, stats) = simulate_at(c, &c.measurements, worlds, seed, noise_mm, effects)?;
    let per_world_mm = stats.iter().map(|s| s.as_ref().map_or(f64::NAN, |s| statistic.of_stats(s))).collect();
    Ok(SimulatedOutcome { scenario, statistic, per_world_mm })
}

/// [`simulate`] at the poses of `m` (the sessions and targets of `c`'s file, other poses or
/// points): per world, the held-out statistics of the chosen model (`None` when the world's
/// calibration gave none), and the scenario in words. World `w` draws from the same stream
/// whatever the poses, so two sets of poses simulated with the same seed meet the same worlds'
/// robots.
pub fn simulate_at(
    c: &Calibration,
    m: &super::measurements::Measurements,
    worlds: usize,
    seed: u64,
    noise_mm: Option<f64>,
    effects: Option<&Effects>,
) -> Result<(String, Vec<Option<ErrorStats>>), CalibrateError> {
    use rayon::prelude::*;
    let sigma = noise_mm.unwrap_or_else(|| residual_noise_mm(c));
    if !(sigma.is_finite() && (0.0..=100.0).contains(&sigma)) {
        return Err(CalibrateError::Option { key: "plan-noise-mm".into(), message: format!("{sigma}: within 0 to 100 mm") });
    }
    // Per session and target, the calibrated robot placed in the session's frame with the target
    // as its tool: its forward kinematics is the position the session's instrument reads.
    let mut placed = Vec::with_capacity(c.bases.len() * c.tools.len());
    for b in &c.bases {
        for t in &c.tools {
            placed.push(c.model.edited(|d| {
                d.world_from_base = b.session_from_base;
                d.flange_tcp_mm = t.flange_mm;
            }));
        }
    }
    let placed: Vec<_> = placed.into_iter().collect::<Result<_, _>>().map_err(|e| CalibrateError::Option {
        key: "plan-worlds".into(),
        message: format!("the calibrated robot cannot be placed in a session's frame: {e}"),
    })?;
    let targets = c.tools.len();
    let mut opts = c.options.clone();
    opts.plots = false;
    let per_world: Vec<Option<ErrorStats>> = (0..worlds)
        .into_par_iter()
        .map(|w| {
            let mut rng = crate::seeds::stream(crate::seeds::split_seed(seed, w as u64), crate::seeds::calibrate::PLAN_NOISE);
            // The link angles of every pose, in the file's order of poses: the joint values
            // themselves, or the robot of the planning scenario with its effects drawn in this world.
            let links: Vec<crate::robot::Joints> = match effects {
                None => m.poses.iter().map(|p| p.q).collect(),
                Some(e) => {
                    let reference: crate::robot::Joints = std::array::from_fn(|i| {
                        let l = c.model.limits()[i];
                        0.5 * (l.min + l.max)
                    });
                    let robot = crate::robot::VirtualRobot::new(c.model.clone(), &e.unmodelled, e.repeatability_mm, &reference, &mut rng)
                        .with_learned(e.learned.as_ref(), &mut rng);
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
            let mut st = KinState::default();
            let truth: Vec<Vector3<f64>> =
                m.points.iter().map(|p| forward(&placed[m.poses[p.pose].session * targets + p.target], &mut st, &links[p.pose])).collect();
            let mut mw = m.clone();
            for (p, t) in mw.points.iter_mut().zip(&truth) {
                let s = if noise_mm.is_some() { sigma } else { p.sigma_mm.unwrap_or(sigma) };
                let noise = Normal::new(0.0, s).map_or(Vector3::zeros(), |n| Vector3::from_fn(|_, _| n.sample(&mut rng)));
                p.measured_mm = t + noise;
            }
            super::run(&c.robot, &mw, &opts).ok().and_then(|cw| cw.chosen().held_out.as_ref().map(|h| h.measured))
        })
        .collect();
    let with = effects.map_or_else(String::new, |e| format!(" with the effects and repeatability of {}", e.source));
    Ok((format!("the calibrated robot{with}, noise {sigma:.4} mm per coordinate"), per_world))
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
