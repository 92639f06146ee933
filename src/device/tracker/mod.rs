//! The laser tracker (or the optical CMM) as the calibration instrument of a full dispersion
//! study: Table 8's other rows of the TriCal paper as studies of their own.
//!
//! The world is the TriCal cell's (`device::trical`): the same robot, unmodelled effects, datum
//! spheres defining {W}, tracker placement and registration, and the same 506 validation poses,
//! drawn from the same streams, so a tracker study and a TriCal study of one seed calibrate the same
//! robot and are validated on the same poses (common random numbers). What differs is the
//! identification pool: random configurations of the whole workspace in the instrument's view,
//! measured by the instrument (`External`), from which DETMAX chooses sets of every size,
//! repetitions, validation, realisations, sweeps and budgets as for any device.

pub mod spec;

use std::path::Path;
use std::time::Instant;

use rerun::{Points3D, RecordingStream, Scalars};

use self::spec::TrackerScenario;
use super::trical::experiment::Experiment;
use super::trical::figures::Figures;
use super::trical::study::StudyResults;
use super::trical::{plots, results, table8};
use super::{Device, DeviceError, ErrorSource, Header, Outcome, Scenario, ScenarioError, TaskFigure, WorldSummary, WriteOptions};
use crate::identify::Observation;
use crate::io::manifest::ScenarioHead;
use crate::io::record::{RecordError, Rr, heat, p3};

use crate::robot::Joints;
use crate::study::check::Check;
use crate::study::engine::Identified;
use crate::study::prediction::Prediction;
use crate::study::published::published;
use crate::study::{ErrorStats, StudySpec};

/// The tracker device (`kind = "tracker"`).
pub struct TrackerDevice;

/// The tracker's error sources: the instrument's noise and the robot's repeatability.
const SOURCES: [ErrorSource; 3] = [
    (
        "laser tracker",
        &["tracker.range_sigma_um", "tracker.range_sigma_um_per_m", "tracker.transverse_sigma_um", "tracker.transverse_sigma_um_per_m"],
        "um",
    ),
    ("optical CMM", &["optical_cmm.volumetric_accuracy_mm"], "mm"),
    ("robot repeatability", &["robot.repeatability_mm"], "mm"),
];

impl Device for TrackerDevice {
    fn kind(&self) -> &'static str {
        "tracker"
    }

    fn describe(&self) -> &'static str {
        "a laser tracker or an optical CMM measuring the TCP over the workspace (Table 8 of the TriCal paper)"
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
        &[crate::device::SHARED_NOTES, crate::device::trical::spec::NOTES, spec::NOTES]
    }
}

impl Scenario for TrackerScenario {
    fn header(&self) -> &Header {
        &self.cell.header
    }

    fn header_mut(&mut self) -> &mut Header {
        &mut self.cell.header
    }

    fn study(&self) -> &StudySpec {
        &self.cell.study
    }

    fn study_mut(&mut self) -> &mut StudySpec {
        &mut self.cell.study
    }

    fn robot_effects(&self) -> Option<(crate::robot::UnmodelledSpec, f64)> {
        Some((self.cell.experiment.robot.unmodelled.clone(), self.cell.experiment.robot.repeatability_mm))
    }

    fn recheck(&self, path: &str) -> Result<(), ScenarioError> {
        self.cell.recheck(path)?;
        spec::check(self, path)
    }

    fn device(&self) -> &'static dyn Device {
        &TrackerDevice
    }

    fn clone_box(&self) -> Box<dyn Scenario> {
        Box::new(self.clone())
    }

    fn run(&self, seed: u64, progress: &(dyn Fn(usize, usize) + Sync)) -> Result<Box<dyn Outcome>, DeviceError> {
        Ok(Box::new(TrackerOutcome::run(self, seed, progress)?))
    }

    fn layout_mm(&self) -> Vec<[f64; 3]> {
        self.cell.layout_mm()
    }

    fn robot_in_cell(&self) -> Option<crate::device::RobotInCell> {
        self.cell.robot_in_cell()
    }
}

/// A tracker study in one world.
pub struct TrackerOutcome {
    scenario: TrackerScenario,
    experiment: Experiment,
    pool: Vec<Observation>,
    results: StudyResults,
    figures: Figures,
    /// Wall times: the world (TriCal campaign included), the instrument's pool, the identifications, s.
    timings: [f64; 3],
}

impl TrackerOutcome {
    /// Builds the world `seed`, measures the instrument's pool and runs the study on it.
    pub fn run(s: &TrackerScenario, seed: u64, progress: &(dyn Fn(usize, usize) + Sync)) -> Result<Self, DeviceError> {
        let t0 = Instant::now();
        let spec = &s.cell.experiment;
        let experiment = spec.build(seed).map_err(|e| DeviceError::new(format!("campaign: {e}")))?;
        let world_s = t0.elapsed().as_secs_f64();
        let before = spec.before_model(&experiment.campaign);
        let t1 = Instant::now();
        let instrument = s.external();
        let pool = table8::external_pool(spec, &experiment, seed, s.instrument.pool, &instrument)
            .map_err(|e| DeviceError::new(format!("{} pool: {e}", instrument.label())))?;
        let pool_s = t1.elapsed().as_secs_f64();
        let t2 = Instant::now();
        let results = super::trical::study::run_on_pool(&experiment, &before, &s.cell.study, seed, &pool, progress)
            .map_err(|e| DeviceError::new(format!("[study] parameters: {e}")))?;
        let figures = Figures::of(&results, &experiment.robot.truth, s.cell.study.table_set_size as usize);
        Ok(Self { scenario: s.clone(), experiment, pool, results, figures, timings: [world_s, pool_s, t2.elapsed().as_secs_f64()] })
    }

    /// The study's results.
    pub fn results(&self) -> &StudyResults {
        &self.results
    }

    /// The paper's figures of this world (Table 8's are `after_median`, `after_std`, `after_max`).
    pub fn figures(&self) -> &Figures {
        &self.figures
    }
}

impl Outcome for TrackerOutcome {
    fn checks(&self) -> Result<Vec<Check>, DeviceError> {
        let (s, f) = (&self.scenario, &self.figures);
        let label = s.external().label();
        let row = published().trical_2018.table8(label);
        let e = &s.expect;
        let n = f.table_n;
        Ok(vec![
            Check::band(&format!("{label}, sets of {n}: median error, mm (Table 8)"), row.median_mm, f.after_median, e.after_median_mm),
            Check::band(&format!("{label}, sets of {n}: std of error, mm (Table 8)"), row.std_mm, f.after_std, e.after_std_mm),
            Check::band(&format!("{label}, sets of {n}: max error, mm (Table 8)"), row.max_mm, f.after_max, e.after_max_mm),
        ])
    }

    fn fits(&self) -> Vec<&Identified> {
        self.results.tasks.iter().map(|t| &t.id).collect()
    }

    fn world(&self) -> WorldSummary {
        WorldSummary {
            before: ErrorStats::of(&self.results.before_errors),
            campaign_s: 0.0,
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
        let pool: Vec<Joints> = self.pool.iter().map(|o| o.q).collect();
        let validation: Vec<Joints> = self.experiment.campaign.validation.iter().map(|v| v.q).collect();
        super::trical::study::predict(&self.results, &pool, &validation, self.scenario.cell.study.table_set_size as usize, seed)
    }

    fn results<'a>(&'a self, checks: &'a [Check], options: &'a WriteOptions) -> Result<crate::io::results::Results<'a>, DeviceError> {
        let h = &self.scenario.cell.header;
        let head = ScenarioHead::new(&h.name, &h.path, &h.text, h.seed, &options.overrides);
        let mut out = crate::io::results::Results::new(h.name.clone(), crate::io::results::Head::Scenario(head));
        results::tables(&self.results, &mut out).map_err(DeviceError::of)?;
        #[derive(serde::Serialize)]
        struct Fields {
            kind: &'static str,
            instrument: &'static str,
            pool: usize,
            tasks: usize,
            timings_s: [f64; 3],
        }
        out.fields(Fields {
            kind: "tracker",
            instrument: self.scenario.external().label(),
            pool: self.pool.len(),
            tasks: self.results.tasks.len(),
            timings_s: self.timings,
        })
        .map_err(DeviceError::of)?;
        if options.plots {
            let e = &self.experiment;
            let inputs = plots::PlotInputs {
                validation_w: e.campaign.validation.iter().map(|v| v.measured_w).collect(),
                spheres_w: e.cell.spheres_w.clone(),
                base_w: crate::robot::world_from_base(&e.robot.truth).translation.vector,
                table_n: self.figures.table_n,
            };
            out.draw(Box::new(move |dir| plots::write_all(dir, &self.results, &inputs)));
        }
        super::trical::summary::figure_tables(&self.results, &self.figures, false, &mut out).map_err(DeviceError::of)?;
        self.summary(!checks.is_empty(), &mut out.summary);
        out.summary.figures("## Figures\n\nEach as PNG (shown) and SVG beside this file.\n\n");
        if options.recording {
            out.record(Box::new(move |path: &Path| self.record(path)));
        }
        Ok(out)
    }

    fn timing(&self) -> String {
        let [w, p, t] = self.timings;
        format!(
            "study {:.3} s (world and TriCal campaign {w:.3} s; {} pool of {} configurations {p:.3} s; {} identifications {t:.3} s)",
            w + p + t,
            self.scenario.external().label(),
            self.pool.len(),
            self.results.tasks.len()
        )
    }
}

impl TrackerOutcome {
    /// The Rerun recording (`study.rrd`, mm in {W}): `cell/spheres` and `cell/tracker` (static),
    /// `pool/tcp` (the instrument's pool, measured), `validation/before` and `validation/after`
    /// (the validation poses coloured by the error of the model before calibration and of the
    /// representative identification at the table set size), `study/validation_median_mm` on the
    /// `task` timeline.
    fn record(&self, path: &Path) -> Result<(), RecordError> {
        let e = &self.experiment;
        let r = &self.results;
        let log = |rec: &RecordingStream| -> Rr {
            rec.log_static("/", &rerun::ViewCoordinates::RIGHT_HAND_Z_UP())?;
            rec.log_static("cell/spheres", &Points3D::new(e.cell.spheres_w.iter().map(p3)).with_radii([8.0f32]))?;
            rec.log_static(
                "cell/tracker",
                &Points3D::new([p3(&e.tracker.position_w)]).with_radii([40.0f32]).with_labels([self.scenario.external().label()]),
            )?;
            rec.log_static("pool/tcp", &Points3D::new(self.pool.iter().map(|o| p3(&o.tcp_world_mm))).with_radii([3.0f32]))?;
            let points: Vec<[f32; 3]> = e.campaign.validation.iter().map(|v| p3(&v.measured_w)).collect();
            let coloured = |errors: &[f64], what: &str| {
                let top = errors.iter().copied().fold(f64::MIN_POSITIVE, f64::max);
                Points3D::new(points.clone())
                    .with_radii([5.0f32])
                    .with_colors(errors.iter().map(|x| heat(x / top)))
                    .with_labels(errors.iter().map(|x| format!("{x:.3} mm {what}")))
            };
            rec.log_static("validation/before", &coloured(&r.before_errors, "before"))?;
            if let Some((_, after)) = super::trical::figures::representative(r, self.figures.table_n) {
                rec.log_static("validation/after", &coloured(after, "after"))?;
            }
            for t in &r.tasks {
                rec.set_time_sequence("task", t.task.index as i64);
                rec.log("study/validation_median_mm", &Scalars::new([t.validation.median]))?;
            }
            rec.reset_time();
            Ok(())
        };
        crate::io::record::save(
            path,
            &self.scenario.cell.header.name,
            log,
            &["/cell/**", "/pool/**", "/validation/**"],
            ("validation median per task", "/study"),
            "study: validation median per task (timeline `task`)",
        )
    }

    /// `summary.md`: Table 8's row beside calsim's, the errors before and after calibration, and
    /// the median error per set size, read from `errors.parquet` and `set_sizes.parquet`.
    fn summary(&self, checks: bool, parts: &mut crate::io::results::Summary<'_>) {
        let s = &self.scenario;
        let (sizes, reps) = (s.cell.study.set_sizes.len(), s.cell.study.repetitions);
        parts.text(format!(
            "# {}: the robot calibrated with the {} (seed {})\n\nA pool of {} random workspace configurations measured by the \
             instrument, DETMAX on O1, ",
            s.cell.header.name,
            s.external().label(),
            s.cell.header.seed,
            self.pool.len(),
        ));
        parts.text_from("tasks.parquet", move |r| {
            format!(
                "{} identifications ({sizes} set sizes x {reps} repetitions), validation on the TriCal cell's {} tracker poses \
                 (the same robot and poses as the TriCal study of this seed).\n\n",
                r.height(),
                r.of("validation_errors.parquet", 0).count("calibration", "before")
            )
        });
        if checks {
            crate::study::check::checks_summary("Table 8, published versus reproduced", parts);
        }
        parts.text("## Errors before and after calibration (mm)\n\n");
        // Before and after calibration (the compensated validation's row is in the table only).
        let rows = Box::new(|f: &polars::prelude::DataFrame| (0..f.height().min(2)).collect());
        super::trical::summary::errors(parts, rows, |r| match r.str("calibration").as_str() {
            "before" => "before".to_string(),
            _ => format!("after, n = {} (medians over repetitions)", r.u64("set_size")),
        });
        super::trical::summary::size_table(parts, false);
    }
}
