//! The SPMS study (paper section 5): the head's beams identified and its accuracy tested, then the
//! ER20-C10 calibrated from SPMS measurements with pose sets drawn at random (the paper) or chosen
//! by DETMAX on O1, repeated per set size, every identified model tested per ISO 9283.
//!
//! Every task seeds its own stream from the scenario seed and its index, so the results are the
//! same for any number of threads.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use rayon::prelude::*;
use serde::Deserialize;

use super::calibration::{ArmSpec, Cell, CellError, IsoResult, IsoSpec, StationSpec, default_parameters, identify_from, iso_test, random_selection};
use super::head::{BeamIdSpec, HeadError, HeadExperiment, HeadSpec};
use crate::experiment::{split_seed, stream};
use crate::identify::detmax::{DetmaxOptions, detmax};
use crate::identify::least_squares::{FitOptions, FitOutcome};
use crate::identify::observability::{Observability, PoolJacobian};
use crate::io::scenario::Band;
use crate::robot::{ParamError, ParamSet};

/// How pose sets are chosen.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Selection {
    /// Drawn uniformly from the pool (the paper).
    Random,
    /// DETMAX on O1 from a random start.
    Detmax,
}

impl Selection {
    /// Label for tables.
    pub fn label(self) -> &'static str {
        match self {
            Selection::Random => "random",
            Selection::Detmax => "detmax",
        }
    }
}

/// The `[study]` table of an SPMS scenario.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct SpmsStudySpec {
    /// Set sizes.
    pub set_sizes: Vec<u32>,
    /// Identifications per set size and selection.
    pub repetitions: u32,
    /// Set size compared with Table 6.
    pub table_set_size: u32,
    /// Selections compared: `random`, `detmax`.
    pub selections: Vec<String>,
    /// Longest DETMAX excursion.
    pub detmax_max_excursion: u32,
    /// Identified parameters by name; absent: [`default_parameters`].
    pub parameters: Option<Vec<String>>,
    /// Relative singular-value threshold of the identification.
    pub rank_rtol: f64,
    /// Leave directions below the threshold at the nominal values instead of refusing the fit.
    pub truncate: bool,
}

impl Default for SpmsStudySpec {
    fn default() -> Self {
        Self {
            set_sizes: vec![20, 30, 50, 75, 100],
            repetitions: 30,
            table_set_size: 50,
            selections: vec!["random".into(), "detmax".into()],
            detmax_max_excursion: 3,
            parameters: None,
            rank_rtol: 1e-6,
            truncate: false,
        }
    }
}

impl SpmsStudySpec {
    /// The identified parameter set.
    pub fn parameter_set(&self) -> Result<ParamSet, ParamError> {
        match &self.parameters {
            Some(names) => ParamSet::from_names(names),
            None => Ok(default_parameters()),
        }
    }

    /// The selections, parsed; `None` names an unknown one.
    pub fn parsed_selections(&self) -> Result<Vec<Selection>, String> {
        self.selections
            .iter()
            .map(|s| match s.as_str() {
                "random" => Ok(Selection::Random),
                "detmax" => Ok(Selection::Detmax),
                other => Err(other.to_string()),
            })
            .collect()
    }
}

/// The `[expect]` table of an SPMS scenario: published figures with their bands.
#[derive(Clone, Debug, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct SpmsExpect {
    /// Table 3: largest measuring error, mm.
    pub measuring_max_mm: Option<Band>,
    /// Table 3: mean measuring error, mm.
    pub measuring_mean_mm: Option<Band>,
    /// Table 3: RMS measuring error, mm.
    pub measuring_rms_mm: Option<Band>,
    /// Fig. 5: least fraction of sphere-fit residuals below 0.03 mm.
    pub fit_residual_below_003_min: Option<f64>,
    /// Table 6 before calibration: max, mean, RMS of AP over P1-P5, mm.
    pub ap_before_max_mm: Option<Band>,
    /// See `ap_before_max_mm`.
    pub ap_before_mean_mm: Option<Band>,
    /// See `ap_before_max_mm`.
    pub ap_before_rms_mm: Option<Band>,
    /// Table 6 after calibration (random sets of the table size, median over repetitions).
    pub ap_after_max_mm: Option<Band>,
    /// See `ap_after_max_mm`.
    pub ap_after_mean_mm: Option<Band>,
    /// See `ap_after_max_mm`.
    pub ap_after_rms_mm: Option<Band>,
}

/// One identification of the study.
#[derive(Clone, Debug, PartialEq)]
pub struct SpmsTask {
    /// Position in the study, the seed index.
    pub index: usize,
    /// How the set was chosen.
    pub selection: Selection,
    /// Set size.
    pub set_size: usize,
    /// Repetition, 0-based.
    pub repetition: usize,
    /// Chosen pool indices.
    pub chosen: Vec<usize>,
    /// Observability of the chosen set (pool column scaling).
    pub observability: Observability,
    /// Outcome label.
    pub outcome: String,
    /// Parameters the set could not separate.
    pub unidentifiable: Vec<String>,
    /// Condition number of the column-scaled identification Jacobian.
    pub condition_number: f64,
    /// Residual RMS of the identification, mm.
    pub residual_rms_mm: f64,
    /// Identified values, internal units, in the order of the parameter set.
    pub values: Vec<Option<f64>>,
    /// ISO 9283 test of the identified model (`None` when no model was identified).
    pub iso: Option<IsoResult>,
    /// Wall time, s (the only field that differs between runs).
    pub seconds: f64,
}

/// Everything an SPMS study produced.
#[derive(Clone, Debug)]
pub struct SpmsResults {
    /// The head experiment.
    pub head: HeadExperiment,
    /// The calibration cell and its pool.
    pub cell: Cell,
    /// Identified parameter set.
    pub set: ParamSet,
    /// ISO 9283 test of the controller before calibration.
    pub before: IsoResult,
    /// The tasks, in order.
    pub tasks: Vec<SpmsTask>,
    /// Wall times, s.
    pub timings: SpmsTimings,
}

/// Wall times of an SPMS study, s.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct SpmsTimings {
    /// Head built, beams identified (PSO + LM, LM alone on both forms), accuracy tested.
    pub head_s: f64,
    /// Cell built and pool measured.
    pub cell_s: f64,
    /// Pool Jacobian for DETMAX.
    pub pool_jacobian_s: f64,
    /// All identifications and ISO tests.
    pub tasks_s: f64,
    /// The whole study.
    pub study_s: f64,
}

/// Why a study could not run.
#[derive(Debug, thiserror::Error)]
pub enum SpmsError {
    /// The head experiment failed.
    #[error("[beams]: {0}")]
    Head(#[from] HeadError),
    /// The cell failed.
    #[error("[station]/[iso9283]: {0}")]
    Cell(#[from] CellError),
    /// A parameter name is wrong.
    #[error("[study] parameters: {0}")]
    Params(#[from] ParamError),
    /// A selection name is wrong.
    #[error("[study] selections: unknown selection {0:?} (random, detmax)")]
    Selection(String),
}

/// Every input of an SPMS study.
#[derive(Clone, Debug, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SpmsSpec {
    /// The head.
    #[serde(default)]
    pub head: HeadSpec,
    /// The beam identification and accuracy experiment.
    #[serde(default)]
    pub beams: BeamIdSpec,
    /// The robot.
    #[serde(default)]
    pub robot: ArmSpec,
    /// The head's stations.
    #[serde(default)]
    pub station: StationSpec,
    /// The ISO 9283 test.
    #[serde(default)]
    pub iso9283: IsoSpec,
    /// The study.
    #[serde(default)]
    pub study: SpmsStudySpec,
}

const TASK_STREAM: u64 = 0x5350_4d53_5441_534b;

/// Runs the whole study; `progress` is called after each finished task.
pub fn run(spec: &SpmsSpec, seed: u64, progress: &(dyn Fn(usize, usize) + Sync)) -> Result<SpmsResults, SpmsError> {
    let t0 = Instant::now();
    let set = spec.study.parameter_set()?;
    let selections = spec.study.parsed_selections().map_err(SpmsError::Selection)?;
    let head = super::head::run(&spec.head, &spec.beams, seed)?;
    let head_s = t0.elapsed().as_secs_f64();
    let form = spec.beams.form().unwrap_or(super::identify::Form::Paper);
    let t1 = Instant::now();
    let cell = super::calibration::build(&spec.robot, &spec.station, &head.spms, head.identified(form), seed)?;
    let before = iso_test(&cell, &cell.nominal, &spec.iso9283, seed)?;
    let cell_s = t1.elapsed().as_secs_f64();
    let t2 = Instant::now();
    let qs: Vec<_> = cell.pool.iter().map(|p| p.q).collect();
    let pool = PoolJacobian::new(&cell.nominal, &set, &qs);
    let pool_jacobian_s = t2.elapsed().as_secs_f64();
    let opts = FitOptions { rank_rtol: spec.study.rank_rtol, truncate: spec.study.truncate, ..FitOptions::default() };
    let dopts = DetmaxOptions { max_excursion: spec.study.detmax_max_excursion.max(1) as usize, ..DetmaxOptions::default() };
    let mut grid = Vec::new();
    for &sel in &selections {
        for &n in &spec.study.set_sizes {
            for r in 0..spec.study.repetitions as usize {
                grid.push((grid.len(), sel, n as usize, r));
            }
        }
    }
    let done = AtomicUsize::new(0);
    let t3 = Instant::now();
    let tasks: Vec<SpmsTask> = grid
        .par_iter()
        .map(|&(index, selection, n, repetition)| {
            let t = Instant::now();
            let mut rng = stream(split_seed(seed, TASK_STREAM), index as u64);
            let chosen = match selection {
                Selection::Random => random_selection(cell.pool.len(), n, &mut rng),
                Selection::Detmax => detmax(&pool, n, &dopts, &mut rng).map(|d| d.selection).unwrap_or_default(),
            };
            let observability = Observability::from_information(&pool.information(&chosen), n.max(1));
            let fit = identify_from(&cell, &set, &chosen, &opts);
            let unidentifiable = match &fit.outcome {
                FitOutcome::RankDeficient { unidentifiable } | FitOutcome::Truncated { unidentifiable, .. } => unidentifiable.clone(),
                _ => Vec::new(),
            };
            let iso = fit.model.as_ref().and_then(|m| iso_test(&cell, m, &spec.iso9283, seed).ok());
            let out = SpmsTask {
                index,
                selection,
                set_size: n,
                repetition,
                chosen,
                observability,
                outcome: fit.outcome.label().to_string(),
                unidentifiable,
                condition_number: fit.condition_number,
                residual_rms_mm: fit.residual_rms_mm,
                values: fit.values,
                iso,
                seconds: t.elapsed().as_secs_f64(),
            };
            progress(done.fetch_add(1, Ordering::Relaxed) + 1, grid.len());
            out
        })
        .collect();
    let tasks_s = t3.elapsed().as_secs_f64();
    let timings = SpmsTimings { head_s, cell_s, pool_jacobian_s, tasks_s, study_s: t0.elapsed().as_secs_f64() };
    Ok(SpmsResults { head, cell, set, before, tasks, timings })
}

/// Median of a sample (mean of the middle two for even sizes); NaN when empty.
pub fn median(v: &[f64]) -> f64 {
    let mut s: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if s.is_empty() {
        return f64::NAN;
    }
    s.sort_by(f64::total_cmp);
    let m = s.len() / 2;
    if s.len() % 2 == 1 { s[m] } else { 0.5 * (s[m - 1] + s[m]) }
}

/// The figures the summary and the checks compare with the paper.
#[derive(Clone, Debug, PartialEq)]
pub struct SpmsFigures {
    /// Table 3 of the head identified with the paper's method: max, mean, RMS, mm.
    pub measuring: (f64, f64, f64),
    /// Same, minimal form.
    pub measuring_minimal: (f64, f64, f64),
    /// Fraction of sphere-fit residuals (largest per sample) below 0.03 mm, paper's form.
    pub residual_below_003: f64,
    /// Table 6 before: AP per point and max, mean, RMS.
    pub before: ([f64; 5], (f64, f64, f64)),
    /// Table 6 after, per selection: AP per point and max, mean, RMS, each the median over the
    /// repetitions at the table set size.
    pub after: Vec<AfterFigures>,
    /// Table set size.
    pub table_n: usize,
}

impl SpmsFigures {
    /// Computes the figures of `r`.
    pub fn of(r: &SpmsResults, table_n: usize) -> Self {
        let h = &r.head;
        let below = h.paper.fit_residual_max_mm.iter().filter(|x| **x < 0.03).count() as f64 / h.paper.fit_residual_max_mm.len().max(1) as f64;
        let mut sels: Vec<Selection> = r.tasks.iter().map(|t| t.selection).collect();
        sels.sort();
        sels.dedup();
        let after = sels
            .into_iter()
            .map(|sel| {
                let isos: Vec<&IsoResult> = r.tasks.iter().filter(|t| t.selection == sel && t.set_size == table_n).filter_map(|t| t.iso.as_ref()).collect();
                let ap: [f64; 5] = std::array::from_fn(|k| median(&isos.iter().map(|i| i.ap_mm[k]).collect::<Vec<_>>()));
                let s: Vec<(f64, f64, f64)> = isos.iter().map(|i| i.ap_summary()).collect();
                let summary = (median(&s.iter().map(|x| x.0).collect::<Vec<_>>()), median(&s.iter().map(|x| x.1).collect::<Vec<_>>()), median(&s.iter().map(|x| x.2).collect::<Vec<_>>()));
                AfterFigures { selection: sel, ap_mm: ap, summary, count: isos.len() }
            })
            .collect();
        Self {
            measuring: super::iso9283::summary(&h.paper.measuring_error_mm),
            measuring_minimal: super::iso9283::summary(&h.minimal.measuring_error_mm),
            residual_below_003: below,
            before: (r.before.ap_mm, r.before.ap_summary()),
            after,
            table_n,
        }
    }

    /// The after figures of `sel`, if that selection ran.
    pub fn after_of(&self, sel: Selection) -> Option<&AfterFigures> {
        self.after.iter().find(|a| a.selection == sel)
    }
}

/// Table 6 after calibration for one selection: medians over the repetitions at the table size.
#[derive(Clone, Debug, PartialEq)]
pub struct AfterFigures {
    /// The selection.
    pub selection: Selection,
    /// AP per point P1..P5, mm.
    pub ap_mm: [f64; 5],
    /// Max, mean and RMS of the five AP values, mm.
    pub summary: (f64, f64, f64),
    /// Identifications with a model at the table size.
    pub count: usize,
}
