//! The SPMS study of Gao et al. (Sensors 2023), on the one study engine: the head built and its
//! beams identified (`head`), the ER20-C10 calibrated at SPMS stations and tested per ISO 9283
//! (`calibration`, `iso9283`), random and DETMAX sets compared (`study`), its scenario file
//! (`spec`) and results (`results`, `plots`, `recording`). The device itself (beams, readings,
//! sphere fit, measurement frame, beam identification) is an instrument:
//! [`crate::instrument::spms`], re-exported here.

pub mod calibration;
pub mod head;
pub mod iso9283;
pub mod plots;
pub mod recording;
pub mod results;
pub mod spec;
pub mod study;
pub mod summary;

use std::path::Path;

pub use self::spec::SpmsScenario;
use self::study::{SpmsFigures, SpmsResults};
use super::{Device, DeviceError, ErrorSource, Header, Outcome, Scenario, ScenarioError, TaskFigure, WorldSummary, WriteOptions};
pub use crate::instrument::spms::*;
use crate::study::check::Check;
use crate::study::engine::Identified;
use crate::study::prediction::Prediction;
use crate::study::{ErrorStats, StudySpec};

/// The SPMS device (`kind = "spms"`).
pub struct SpmsDevice;

/// The SPMS's error sources: the sensors, the head, the trackers, the stations, the tool and the
/// robot's repeatability.
const SOURCES: [ErrorSource; 10] = [
    ("sensor linearity", &["head.sensor.linearity_pct_fs"], "% FS"),
    ("sensor repeatability", &["head.sensor.repeatability_um"], "um"),
    ("sensor temperature", &["head.sensor.temperature_delta_c"], "C"),
    ("head assembly", &["head.assembly_error_mm", "head.assembly_error_deg"], "mm, deg"),
    ("tracker, beam experiment", &["beams.tracker_sigma_um"], "um"),
    ("tracker, station frames (A1-A3)", &["station.tracker_sigma_um"], "um"),
    ("station placement", &["station.placement_error_mm", "station.placement_error_deg"], "mm, deg"),
    ("sphere offset on the flange", &["robot.sphere_flange_error_mm"], "mm"),
    ("robot repeatability", &["robot.repeatability_mm"], "mm"),
    ("tracker, ISO 9283 test", &["iso9283.tracker_sigma_um"], "um"),
];

impl Device for SpmsDevice {
    fn kind(&self) -> &'static str {
        "spms"
    }

    fn describe(&self) -> &'static str {
        "SPMS: five laser range sensors measuring a sphere on the flange (Gao et al. 2023)"
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

impl Scenario for SpmsScenario {
    fn header(&self) -> &Header {
        &self.header
    }

    fn header_mut(&mut self) -> &mut Header {
        &mut self.header
    }

    fn study(&self) -> &StudySpec {
        &self.spec.study
    }

    fn study_mut(&mut self) -> &mut StudySpec {
        &mut self.spec.study
    }

    fn robot_effects(&self) -> Option<(crate::robot::UnmodelledSpec, f64)> {
        Some((self.spec.robot.unmodelled.clone(), self.spec.robot.repeatability_mm))
    }

    fn recheck(&self, path: &str) -> Result<(), ScenarioError> {
        spec::check(&self.spec, path)
    }

    fn device(&self) -> &'static dyn Device {
        &SpmsDevice
    }

    fn clone_box(&self) -> Box<dyn Scenario> {
        Box::new(self.clone())
    }

    fn run(&self, seed: u64, progress: &(dyn Fn(usize, usize) + Sync)) -> Result<Box<dyn Outcome>, DeviceError> {
        let results = study::run(&self.spec, seed, progress).map_err(DeviceError::of)?;
        let figures = SpmsFigures::of(&results, self.spec.study.table_set_size as usize);
        Ok(Box::new(SpmsOutcome { scenario: self.clone(), results, figures }))
    }

    fn layout_mm(&self) -> Vec<[f64; 3]> {
        Vec::new()
    }

    fn candidate_pool(&self) -> Option<Result<super::CandidatePool, DeviceError>> {
        Some(candidate_pool(self))
    }
}

/// The SPMS's pool of realisation 0: the head built and its beams identified, the stations placed
/// and the pool measured (as the study does), each configuration observing the sphere centre as
/// the identified head located it, in {W} (the first station's head frame as the tracker measured
/// it). The groups are the stations, each at its convergence point.
fn candidate_pool(s: &SpmsScenario) -> Result<super::CandidatePool, DeviceError> {
    use nalgebra::{Point3, Vector3};
    let (spec, seed) = (&s.spec, s.header.seed);
    let set = spec.study.parameter_set(calibration::default_parameters).map_err(DeviceError::of)?;
    let head = head::run(&spec.head, &spec.beams, seed).map_err(DeviceError::of)?;
    let cell = calibration::build(&spec.robot, &spec.station, &head.spms, head.identified(spec.beams.calibration_form), seed)
        .map_err(DeviceError::of)?;
    let observations: Vec<crate::identify::Observation> =
        cell.pool.iter().map(|p| crate::identify::Observation { q: p.q, tcp_world_mm: p.measured_world_mm }).collect();
    let qs: Vec<_> = observations.iter().map(|o| o.q).collect();
    let jacobian = crate::identify::PoolJacobian::new(&cell.nominal, &set, &qs);
    let c_head = Point3::from(Vector3::from(spec.station.sphere_centre_head_mm));
    Ok(super::CandidatePool {
        what: "measured by the head at a station",
        group: "station",
        group_of: cell.pool.iter().map(|p| p.station).collect(),
        groups_w_mm: cell.stations.iter().map(|st| (st.world_from_head * c_head).coords.into()).collect(),
        observations,
        truth: cell.robot.truth.clone(),
        set,
        jacobian,
        fit: spec.study.fit_options(),
        detmax: spec.study.detmax_options(),
        links: spec.robot.arm.as_ref().and_then(|a| a.0.capsules.clone()).unwrap_or_default(),
        device: Vec::new(),
        fixtures: Vec::new(),
        start: cell.nominal,
    })
}

/// An SPMS study in one world.
pub struct SpmsOutcome {
    scenario: SpmsScenario,
    results: SpmsResults,
    figures: SpmsFigures,
}

impl SpmsOutcome {
    /// The study's results.
    pub fn results(&self) -> &SpmsResults {
        &self.results
    }

    /// The paper's figures of this world.
    pub fn figures(&self) -> &SpmsFigures {
        &self.figures
    }
}

impl Outcome for SpmsOutcome {
    fn checks(&self) -> Result<Vec<Check>, DeviceError> {
        Ok(study::checks(&self.figures, &self.scenario.expect))
    }

    fn fits(&self) -> Vec<&Identified> {
        self.results.tasks.iter().map(|t| &t.id).collect()
    }

    fn world(&self) -> WorldSummary {
        WorldSummary {
            before: ErrorStats::of(&self.results.before.ap_mm),
            campaign_s: 0.0,
            tasks: self
                .results
                .tasks
                .iter()
                .map(|t| TaskFigure {
                    selection: t.task.selection,
                    set_size: t.task.set_size,
                    after: t.iso.as_ref().map(|i| ErrorStats::of(&i.ap_mm)),
                    o1: t.id.observability.o1,
                })
                .collect(),
        }
    }

    fn prediction(&self, seed: u64) -> Option<Prediction> {
        use crate::study::prediction::{TaskView, predict_tasks};
        let r = &self.results;
        let pool: Vec<_> = r.cell.pool.iter().map(|p| p.q).collect();
        let n = self.scenario.spec.study.table_set_size as usize;
        let tasks = r.tasks.iter().filter(|t| t.task.set_size == n && !t.id.outcome.is_rank_deficient()).filter_map(|t| {
            let ap = ErrorStats::of(&t.iso.as_ref()?.ap_mm);
            Some(TaskView {
                index: t.task.index,
                chosen: &t.id.chosen,
                values: &t.id.values,
                residual_rms_mm: t.id.residual_rms_mm,
                simulated_mm: [ap.median, ap.p95],
            })
        });
        // The figure of merit (ISO 9283 AP after the controller's inverse kinematics, in the base
        // frame) is not predicted: the parameters only.
        predict_tasks(&r.set, &r.cell.robot.truth, tasks, &pool, &[], seed)
    }

    fn results<'a>(&'a self, checks: &'a [Check], options: &'a WriteOptions) -> Result<crate::io::results::Results<'a>, DeviceError> {
        let s = &self.scenario;
        let record: crate::io::results::Record<'a> =
            Box::new(move |path: &Path| recording::write(path, &s.header.name, &s.spec, &self.results));
        let extras = results::SpmsExtras {
            plots: options.plots,
            recording: options.recording.then_some(record),
            threads: options.threads,
            overrides: &options.overrides,
        };
        results::results(s, &self.results, &self.figures, checks, extras).map_err(DeviceError::of)
    }

    fn timing(&self) -> String {
        let t = &self.results.timings;
        format!(
            "study {:.3} s (head {:.3} s, cell and pool {:.3} s, {} identifications with ISO 9283 tests {:.3} s)",
            t.study_s,
            t.head_s,
            t.cell_s,
            self.results.tasks.len(),
            t.tasks_s
        )
    }
}
