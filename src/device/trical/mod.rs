//! The TriCal device (Gaudreault, Joubair and Bonev 2018): a flange-mounted device of three
//! digital indicators centred on datum spheres. Its virtual experiment (`experiment`, `campaign`),
//! its dispersion study (`study`), the paper's figures and checks (`figures`, `table8`), its
//! scenario file (`spec`) and its results (`results`, `plots`, `recording`).

pub mod campaign;
pub mod experiment;
pub mod figures;
pub mod plots;
pub mod recording;
pub mod results;
pub mod spec;
pub mod study;
pub mod summary;
pub mod table8;

use crate::io::results::Results;
use std::path::Path;
use std::sync::OnceLock;
use std::time::Instant;

use self::experiment::Experiment;
use self::figures::Figures;
use self::results::Timings;
pub use self::spec::TricalScenario;
use self::study::StudyResults;
use super::{Device, DeviceError, ErrorSource, Header, Outcome, Refit, Scenario, ScenarioError, TaskFigure, WorldSummary, WriteOptions};
use crate::robot::RobotModel;
use crate::study::check::Check;
use crate::study::engine::Identified;
use crate::study::prediction::Prediction;
use crate::study::{ErrorStats, StudySpec};

/// The TriCal device (`kind = "trical"`, or no `kind`).
pub struct TricalDevice;

/// The TriCal's error sources: the indicators, the cell's calibration, the robot's repeatability
/// and the validation tracker.
const SOURCES: [ErrorSource; 8] = [
    ("indicator accuracy", &["trical.indicator_accuracy_um"], "um"),
    ("indicator resolution", &["trical.indicator_resolution_um"], "um"),
    ("indicator misalignment", &["trical.indicator_misalignment_deg"], "deg"),
    ("ball diameter tolerance", &["cell.ball_diameter_tolerance_um"], "um"),
    ("ballbar", &["cell.ballbar_sigma_um"], "um"),
    ("CMM (TCP)", &["trical.cmm_sigma_um"], "um"),
    ("robot repeatability", &["robot.repeatability_mm"], "mm"),
    (
        "laser tracker (validation)",
        &["tracker.range_sigma_um", "tracker.range_sigma_um_per_m", "tracker.transverse_sigma_um", "tracker.transverse_sigma_um_per_m"],
        "um",
    ),
];

impl Device for TricalDevice {
    fn kind(&self) -> &'static str {
        "trical"
    }

    fn describe(&self) -> &'static str {
        "TriCal: three indicators centred on datum spheres (Gaudreault et al. 2018)"
    }

    fn load(&self, text: &str, table: toml::Table, path: &Path) -> Result<Box<dyn Scenario>, ScenarioError> {
        Ok(Box::new(spec::parse_table(text, table, path)?))
    }

    fn error_sources(&self) -> &'static [ErrorSource] {
        &SOURCES
    }

    fn defaults(&self) -> toml::Table {
        spec::defaults()
    }

    fn notes(&self) -> &'static [&'static str] {
        &[crate::device::SHARED_NOTES, spec::NOTES]
    }
}

impl Scenario for TricalScenario {
    fn header(&self) -> &Header {
        &self.header
    }

    fn header_mut(&mut self) -> &mut Header {
        &mut self.header
    }

    fn study(&self) -> &StudySpec {
        &self.study
    }

    fn study_mut(&mut self) -> &mut StudySpec {
        &mut self.study
    }

    fn robot_effects(&self) -> Option<(crate::robot::UnmodelledSpec, f64)> {
        Some((self.experiment.robot.unmodelled.clone(), self.experiment.robot.repeatability_mm))
    }

    fn recheck(&self, path: &str) -> Result<(), ScenarioError> {
        spec::check_overrides(self, path)
    }

    fn device(&self) -> &'static dyn Device {
        &TricalDevice
    }

    fn clone_box(&self) -> Box<dyn Scenario> {
        Box::new(self.clone())
    }

    fn run(&self, seed: u64, progress: &(dyn Fn(usize, usize) + Sync)) -> Result<Box<dyn Outcome>, DeviceError> {
        Ok(Box::new(TricalOutcome::run(self, seed, progress)?))
    }

    fn layout_mm(&self) -> Vec<[f64; 3]> {
        self.experiment.cell.spheres_w_mm.clone()
    }

    fn robot_in_cell(&self) -> Option<super::RobotInCell> {
        Some(super::RobotInCell::of(&self.experiment.truth()))
    }

    fn refit(&self, index: usize) -> Result<Option<Refit>, DeviceError> {
        let e = self.experiment.build(self.header.seed).map_err(|e| DeviceError::new(format!("campaign: {e}")))?;
        let before = self.experiment.before_model(&e.campaign);
        let Some(r) = study::recompute_task(&e, &before, &self.study, self.header.seed, index).map_err(DeviceError::of)? else {
            return Ok(None);
        };
        Ok(Some(Refit {
            task: index,
            set_size: r.result.task.set_size,
            validation_median_mm: r.result.validation.median,
            residual_rms_mm: r.result.id.residual_rms_mm,
            before,
            model: r.model,
            set: r.set,
            observations: r.observations,
            links: e.links.clone(),
            flange: self.experiment.flange(),
        }))
    }

    fn carried_reach(&self) -> Option<super::CarriedReach> {
        Some(super::CarriedReach {
            truth: self.experiment.truth(),
            approach_cone_deg: self.experiment.campaign.approach_cone_deg,
            flange: self.experiment.flange(),
        })
    }

    fn campaign_feasibility(&self) -> Option<campaign::Feasibility> {
        self.experiment.feasibility()
    }

    fn datum_cell(&self) -> Option<super::DatumCell> {
        let e = &self.experiment;
        let c = &e.cell;
        let world_from_base = match e.robot.nominal_base_mm_deg {
            Some(b) => c.base_in_moved_world(crate::robot::XyzZyx::from_mm_deg(b)),
            None => e.truth().data().world_from_base,
        };
        Some(super::DatumCell {
            spheres_w_mm: c.spheres_w_mm.clone(),
            world_from_base,
            plate_offset_mm_deg: c.plate_offset_mm_deg,
            plate_margin_mm: c.plate_margin_mm,
            riser_height_mm: c.riser_height_mm,
            ball_diameter_mm: c.ball_diameter_mm,
        })
    }

    fn candidate_pool(&self) -> Option<Result<super::CandidatePool, DeviceError>> {
        Some(candidate_pool(self))
    }
}

/// The TriCal's pool of realisation 0: the campaign's configurations centred on the datum
/// spheres, each observing its sphere's centre as the ballbar located it.
fn candidate_pool(s: &TricalScenario) -> Result<super::CandidatePool, DeviceError> {
    let spec = &s.experiment;
    let e = spec.build(s.header.seed).map_err(|e| DeviceError::new(format!("campaign: {e}")))?;
    let start = spec.before_model(&e.campaign);
    let set = s.study.parameter_set(crate::robot::ParamSet::trical_31).map_err(DeviceError::of)?;
    let observations: Vec<_> = e.campaign.pool.iter().map(|p| e.campaign.observation(&e.cell, p)).collect();
    let qs: Vec<_> = observations.iter().map(|o: &crate::identify::Observation| o.q).collect();
    let jacobian = crate::identify::PoolJacobian::new(&start, &set, &qs);
    let truth_base = crate::robot::world_from_base(&e.robot.truth);
    let up = -start.data().gravity_base.normalize();
    Ok(super::CandidatePool {
        what: "centred on a datum sphere",
        group: "datum sphere",
        group_of: e.campaign.pool.iter().map(|p| p.sphere).collect(),
        groups_w_mm: spec.cell.spheres_w_mm.clone(),
        observations,
        truth: e.robot.truth.clone(),
        set,
        jacobian,
        fit: s.study.fit_options(),
        detmax: s.study.detmax_options(),
        device: e.trical.capsules(&e.campaign.semi_automatic.tcp_cmm_mm),
        fixtures: crate::cell::solids::obstacles(&e.cell, &truth_base.inverse(), &up),
        links: e.links,
        start,
    })
}

/// A TriCal study in one world: the experiment, the model before calibration, every
/// identification and the paper's figures.
pub struct TricalOutcome {
    scenario: TricalScenario,
    seed: u64,
    experiment: Experiment,
    before: RobotModel,
    results: StudyResults,
    figures: Figures,
    timings: Timings,
    /// Wall time of Table 8's external instruments, when the checks ran them, s.
    table8_s: OnceLock<f64>,
}

impl TricalOutcome {
    /// Builds the experiment of world `seed`, runs the campaign and the study.
    pub fn run(s: &TricalScenario, seed: u64, progress: &(dyn Fn(usize, usize) + Sync)) -> Result<Self, DeviceError> {
        let t0 = Instant::now();
        let spec = &s.experiment;
        let experiment = spec.build(seed).map_err(|e| DeviceError::new(format!("campaign: {e}")))?;
        let campaign_s = t0.elapsed().as_secs_f64();
        let before = spec.before_model(&experiment.campaign);
        let results =
            study::run(&experiment, &before, &s.study, seed, progress).map_err(|e| DeviceError::new(format!("[study] parameters: {e}")))?;
        let timings = Timings {
            campaign_s,
            pool_s: experiment.campaign.pool_wall_s,
            pool_jacobian_s: results.pool_jacobian_s,
            tasks_s: results.tasks_s,
            study_s: t0.elapsed().as_secs_f64(),
        };
        let figures = Figures::of(&results, &experiment.robot.truth, s.study.table_set_size as usize);
        Ok(Self { scenario: s.clone(), seed, experiment, before, results, figures, timings, table8_s: OnceLock::new() })
    }

    /// The study's results.
    pub fn results(&self) -> &StudyResults {
        &self.results
    }

    /// The experiment of this world.
    pub fn experiment(&self) -> &Experiment {
        &self.experiment
    }

    /// The paper's figures of this world.
    pub fn figures(&self) -> &Figures {
        &self.figures
    }
}

impl Outcome for TricalOutcome {
    fn checks(&self) -> Result<Vec<Check>, DeviceError> {
        let s = &self.scenario;
        let mut rows = figures::checks(&self.figures, &s.expect);
        // Another arm than the paper's: its figures are the IRB 120's, shown for scale, not compared.
        if s.experiment.nominal().data().name != crate::robot::builtin::irb120().data().name {
            for r in &mut rows {
                if r.published_value.take().is_some() {
                    r.published = format!("IRB 120: {}", r.published);
                }
            }
        }
        if s.expect.wants_table8() {
            let t = Instant::now();
            let [tracker, cmm] = table8::external_instruments(&s.experiment, &self.experiment, &self.before, &s.study, self.seed, 360)
                .map_err(|e| DeviceError::new(format!("Table 8: {e}")))?;
            let _ = self.table8_s.set(t.elapsed().as_secs_f64());
            rows.extend(figures::table8_checks(tracker, cmm, &s.expect));
        }
        Ok(rows)
    }

    fn fits(&self) -> Vec<&Identified> {
        self.results.tasks.iter().map(|t| &t.id).collect()
    }

    fn world(&self) -> WorldSummary {
        WorldSummary {
            before: ErrorStats::of(&self.results.before_errors),
            campaign_s: self.experiment.campaign.pool.iter().map(|p| p.seconds).sum(),
            tasks: self
                .results
                .tasks
                .iter()
                .map(|t| TaskFigure {
                    selection: t.task.selection,
                    set_size: t.task.set_size,
                    after: (!t.id.outcome.is_rank_deficient()).then_some(t.validation),
                    o1: t.id.observability.o1,
                })
                .collect(),
        }
    }

    fn prediction(&self, seed: u64) -> Option<Prediction> {
        let pool: Vec<_> = self.experiment.campaign.pool.iter().map(|p| p.q).collect();
        let validation: Vec<_> = self.experiment.campaign.validation.iter().map(|v| v.q).collect();
        study::predict(&self.results, &pool, &validation, self.scenario.study.table_set_size as usize, seed)
    }

    fn results<'a>(&'a self, checks: &'a [Check], options: &'a WriteOptions) -> Result<Results<'a>, DeviceError> {
        let s = &self.scenario;
        let e = &self.experiment;
        let table_n = s.study.table_set_size as usize;
        let plots = options.plots.then(|| plots::PlotInputs {
            validation_w: e.campaign.validation.iter().map(|v| v.measured_w).collect(),
            spheres_w: e.cell.spheres_w.clone(),
            base_w: crate::robot::world_from_base(&e.robot.truth).translation.vector,
            table_n,
        });
        let representative = figures::representative(&self.results, table_n).map(|(task, _)| task);
        let record: crate::io::results::Record<'a> =
            Box::new(move |path: &Path| recording::write(path, &s.header.name, e, &self.before, &self.results, representative));
        let extras = results::Extras { plots, recording: options.recording.then_some(record) };
        let report = results::Report {
            figures: &self.figures,
            checks,
            threads: options.threads,
            timings: &self.timings,
            overrides: &options.overrides,
            extras,
        };
        results::results(s, &self.results, report).map_err(DeviceError::of)
    }

    fn timing(&self) -> String {
        let t = &self.timings;
        format!(
            "study {:.3} s (campaign {:.3} s, of which pool {:.3} s; {} identifications {:.3} s){}",
            t.study_s,
            t.campaign_s,
            t.pool_s,
            self.results.tasks.len(),
            t.tasks_s,
            self.table8_s.get().map_or(String::new(), |s| format!("; Table 8's tracker and optical CMM calibrations {s:.3} s"))
        )
    }
}
