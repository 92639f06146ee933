//! The SPMS study (paper section 5): the head's beams identified and its accuracy tested, then the
//! ER20-C10 calibrated from SPMS measurements with pose sets drawn at random (the paper) or chosen
//! by DETMAX on O1, repeated per set size, every identified model tested per ISO 9283.
//!
//! Every task seeds its own stream from the scenario seed and its index, so the results are the
//! same for any number of threads.

use std::time::Instant;

use serde::Deserialize;

use super::calibration::{ArmSpec, Cell, CellError, IsoResult, IsoSpec, StationSpec, default_parameters, identify_from, iso_test};
use super::head::{BeamIdSpec, HeadError, HeadExperiment, HeadSpec};
use crate::identify::PoolJacobian;
use crate::robot::{ParamError, ParamSet};
use crate::study::StudySpec;
use crate::study::check::{Band, Bound, Check};
use crate::study::engine::{self, Identified, Selection, Task};
use crate::study::published::published;
use crate::study::stats::median;

/// The SPMS default of the `[study]` table (as TOML, under what a scenario gives): set sizes of
/// the ISO 9283 comparison, the paper's random sets beside DETMAX sets, the ER20-C10 parameters.
pub const STUDY_DEFAULTS: &str = r#"
set_sizes = [20, 30, 50, 75, 100]
table_set_size = 50
selections = ["random", "detmax"]
"#;

/// The `[expect]` table of an SPMS scenario: published figures with their bands.
#[derive(Clone, Debug, Default, Deserialize, serde::Serialize, PartialEq)]
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

/// One identification of the study and its ISO 9283 test.
#[derive(Clone, Debug, PartialEq)]
pub struct SpmsTask {
    /// The task.
    pub task: Task,
    /// The chosen set and the fit.
    pub id: Identified,
    /// ISO 9283 test of the identified model (`None` when no model was identified).
    pub iso: Option<IsoResult>,
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
    pub study: StudySpec,
}

/// Runs the whole study; `progress` is called after each finished task.
pub fn run(spec: &SpmsSpec, seed: u64, progress: &(dyn Fn(usize, usize) + Sync)) -> Result<SpmsResults, SpmsError> {
    let t0 = Instant::now();
    let set = spec.study.parameter_set(default_parameters)?;
    let head = super::head::run(&spec.head, &spec.beams, seed)?;
    let head_s = t0.elapsed().as_secs_f64();
    let form = spec.beams.calibration_form;
    let t1 = Instant::now();
    let cell = super::calibration::build(&spec.robot, &spec.station, &head.spms, head.identified(form), seed)?;
    let before = iso_test(&cell, &cell.nominal, &spec.iso9283, seed)?;
    let cell_s = t1.elapsed().as_secs_f64();
    let t2 = Instant::now();
    let qs: Vec<_> = cell.pool.iter().map(|p| p.q).collect();
    let pool = PoolJacobian::new(&cell.nominal, &set, &qs);
    let pool_jacobian_s = t2.elapsed().as_secs_f64();
    let (opts, dopts) = (spec.study.fit_options(), spec.study.detmax_options());
    let t3 = Instant::now();
    let tasks = engine::run_tasks(&spec.study.tasks(), seed, crate::seeds::study::SPMS, progress, |task, rng| {
        let (id, model) = engine::select_and_identify(task, &pool, &dopts, rng, |chosen| identify_from(&cell, &set, chosen, &opts));
        let iso = model.as_ref().and_then(|m| iso_test(&cell, m, &spec.iso9283, seed).ok());
        SpmsTask { task: task.clone(), id, iso }
    });
    let tasks_s = t3.elapsed().as_secs_f64();
    let timings = SpmsTimings { head_s, cell_s, pool_jacobian_s, tasks_s, study_s: t0.elapsed().as_secs_f64() };
    Ok(SpmsResults { head, cell, set, before, tasks, timings })
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
        let below =
            h.paper.fit_residual_max_mm.iter().filter(|x| **x < 0.03).count() as f64 / h.paper.fit_residual_max_mm.len().max(1) as f64;
        let mut sels: Vec<Selection> = r.tasks.iter().map(|t| t.task.selection).collect();
        sels.sort();
        sels.dedup();
        let after = sels
            .into_iter()
            .map(|sel| {
                let isos: Vec<&IsoResult> = r
                    .tasks
                    .iter()
                    .filter(|t| t.task.selection == sel && t.task.set_size == table_n)
                    .filter_map(|t| t.iso.as_ref())
                    .collect();
                let ap: [f64; 5] = std::array::from_fn(|k| median(&isos.iter().map(|i| i.ap_mm[k]).collect::<Vec<_>>()));
                let s: Vec<(f64, f64, f64)> = isos.iter().map(|i| i.ap_summary()).collect();
                let summary = (
                    median(&s.iter().map(|x| x.0).collect::<Vec<_>>()),
                    median(&s.iter().map(|x| x.1).collect::<Vec<_>>()),
                    median(&s.iter().map(|x| x.2).collect::<Vec<_>>()),
                );
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

/// The comparison rows for an SPMS scenario's `[expect]` table.
pub fn checks(f: &SpmsFigures, e: &SpmsExpect) -> Vec<Check> {
    let (m, b) = (f.measuring, f.before.1);
    let (t3, t6) = (&published().spms_2023.measuring_error, &published().spms_2023.iso9283);
    let mut rows = vec![
        Check::band("Table 3: max measuring error, mm", t3.max_mm, m.0, e.measuring_max_mm),
        Check::band("Table 3: mean measuring error, mm", t3.mean_mm, m.1, e.measuring_mean_mm),
        Check::band("Table 3: RMS measuring error, mm", t3.rms_mm, m.2, e.measuring_rms_mm),
        Check::rule(
            "Fig. 5: share of fits with residuals < 0.03 mm",
            "nearly all",
            f.residual_below_003,
            format!("{:.0} %", 100.0 * f.residual_below_003),
            e.fit_residual_below_003_min.map(Bound::AtLeast),
            |b| match b {
                Bound::AtLeast(v) => format!(">= {:.0} %", 100.0 * v),
                other => crate::study::check::describe(other),
            },
        ),
        Check::band("Table 6 before: max AP, mm", t6.max_before_mm, b.0, e.ap_before_max_mm),
        Check::band("Table 6 before: mean AP, mm", t6.mean_before_mm, b.1, e.ap_before_mean_mm),
        Check::band("Table 6 before: RMS AP, mm", t6.rms_before_mm, b.2, e.ap_before_rms_mm),
    ];
    for a in &f.after {
        // The paper's sets are random: the DETMAX rows are reported beside them, with no published
        // value (the paper has none for DETMAX sets) and not checked.
        let l = format!("{} sets of {}", a.selection.label(), f.table_n);
        let after = [
            ("max", t6.max_after_mm, a.summary.0, e.ap_after_max_mm),
            ("mean", t6.mean_after_mm, a.summary.1, e.ap_after_mean_mm),
            ("RMS", t6.rms_after_mm, a.summary.2, e.ap_after_rms_mm),
        ];
        for (what, published, value, band) in after {
            let figure = format!("Table 6 after ({l}): {what} AP, mm");
            rows.push(match a.selection {
                Selection::Random => Check::band(&figure, published, value, band),
                _ => Check::report(&figure, "-", value, format!("{value:.3}")),
            });
        }
    }
    rows
}
