//! Plan against outcome: the seam where a planned calibration's simulation meets the measured one.
//!
//! The scenario that planned the calibration simulates the same poses (the measured sessions,
//! targets and joint values of [`Calibration::measurements`], the same instrument noise) in many
//! worlds, runs [`super::run`] on each simulated file, and collects one figure per world: the
//! held-out error after calibration (the same statistic as the measured one). [`compare`] puts the
//! measured figure beside that distribution and says whether it falls inside the simulated
//! P10-P90; [`write`] adds `plan.md` to a report directory. Building the [`SimulatedOutcome`] is
//! the scenario layer's part.

use std::fmt::Write as _;
use std::path::Path;

use super::Calibration;
use crate::study::stats::{finite_sorted, quantile};

/// Which held-out statistic the comparison is made on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Statistic {
    /// Median of the held-out errors.
    Median,
    /// 95th percentile.
    P95,
    /// Root mean square.
    Rms,
}

impl Statistic {
    /// Name for tables.
    pub fn name(self) -> &'static str {
        match self {
            Statistic::Median => "median",
            Statistic::P95 => "p95",
            Statistic::Rms => "RMS",
        }
    }

    /// This statistic of the measured held-out errors of the chosen model, mm.
    pub fn of(self, c: &Calibration) -> Option<f64> {
        let h = c.chosen().held_out.as_ref()?;
        Some(match self {
            Statistic::Median => h.measured.median,
            Statistic::P95 => h.measured.p95,
            Statistic::Rms => h.measured.rms,
        })
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

/// Writes `plan.md` into the report directory `dir`.
pub fn write(dir: &Path, p: &PlanComparison) -> std::io::Result<()> {
    crate::io::out_dir::write_file_atomically(&dir.join("plan.md"), &markdown(p))
}
