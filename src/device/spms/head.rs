//! The SPMS head as built and identified (paper sections 5.1-5.2): a head whose beams carry
//! assembly errors, its beams identified from poses around a fixed sphere (PSO then LM on the
//! paper's 6K + 3 form, and LM alone on the minimal 5K + 3 form), and its measuring accuracy
//! against a laser tracker.
//!
//! The head's poses vary the sphere's place among the beams (what the readings see) and the head's
//! orientation (what the frame from A1-A3 sees); the tracker measures A1-A3 and the sphere centre
//! with its own noise.

use std::time::Instant;

use nalgebra::{DVector, Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rand::{Rng, RngExt};
use serde::Deserialize;

use super::{Beam, ReadingError, SensorSpec, Spms, fit_centre, table2_beams};
use crate::instrument::laser_tracker::AxisNoise;
use crate::instrument::spms::beams::{BeamData, Form, PsoOptions, levenberg_marquardt, pso};
use crate::seeds::{spms_head as streams, stream};

/// The head and its reference sphere, as a scenario describes them.
#[derive(Clone, Debug, Deserialize, serde::Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct HeadSpec {
    /// Reference sphere diameter, mm (the paper: 50.8143).
    pub sphere_diameter_mm: f64,
    /// Assembly error of each beam's point (uniform, per axis, +-), mm: the true beams are Table 2's
    /// moved by it.
    pub assembly_error_mm: f64,
    /// Assembly error of each beam's direction (uniform, per axis, +-), deg.
    pub assembly_error_deg: f64,
    /// The laser range sensors.
    pub sensor: SensorSpec,
}

impl Default for HeadSpec {
    fn default() -> Self {
        Self { sphere_diameter_mm: 50.8143, assembly_error_mm: 0.5, assembly_error_deg: 0.5, sensor: SensorSpec::default() }
    }
}

/// The beam identification and accuracy experiment, as a scenario describes it.
#[derive(Clone, Debug, Deserialize, serde::Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct BeamIdSpec {
    /// Poses of the head around the fixed sphere (the paper: 55).
    pub poses: usize,
    /// Measurements of the accuracy test (the paper: 55).
    pub accuracy_samples: usize,
    /// Largest tilt of the head, deg.
    pub head_tilt_deg: f64,
    /// Sphere travel across the beams (x and z of the head), +- mm.
    pub sphere_across_mm: f64,
    /// Sphere travel along the beams (y of the head), +- mm.
    pub sphere_along_mm: f64,
    /// Where the beams converge: the sphere centre the poses are spread around, head frame, mm.
    pub sphere_centre_head_mm: [f64; 3],
    /// Laser tracker noise per axis on A1-A3 and on the sphere centre, um.
    pub tracker_sigma_um: f64,
    /// PSO population (the paper: 5000).
    pub pso_population: usize,
    /// PSO iterations.
    pub pso_iterations: usize,
    /// PSO search half-width around the nominal beams: point, mm.
    pub pso_half_width_mm: f64,
    /// PSO search half-width around the nominal beams: direction components.
    pub pso_half_width_dir: f64,
    /// PSO search half-width around the rough sphere centre, mm.
    pub pso_half_width_centre_mm: f64,
    /// Error of the rough sphere centre both solvers start from, per axis, mm.
    pub rough_centre_error_mm: f64,
    /// LM initial damping factor tau (the paper: 1e-8).
    pub lm_tau: f64,
    /// LM iteration cap.
    pub lm_max_iterations: usize,
    /// Which identified head the robot calibration measures with: `paper` or `minimal`.
    pub calibration_form: Form,
}

impl Default for BeamIdSpec {
    fn default() -> Self {
        Self {
            poses: 55,
            accuracy_samples: 55,
            head_tilt_deg: 15.0,
            sphere_across_mm: 3.0,
            sphere_along_mm: 20.0,
            sphere_centre_head_mm: [52.0, 180.0, 132.0],
            tracker_sigma_um: 10.0,
            pso_population: 5000,
            pso_iterations: 60,
            pso_half_width_mm: 2.0,
            pso_half_width_dir: 0.02,
            pso_half_width_centre_mm: 10.0,
            rough_centre_error_mm: 4.0,
            lm_tau: 1e-8,
            lm_max_iterations: 500,
            calibration_form: Form::Paper,
        }
    }
}

/// The head as identified by one solver.
#[derive(Clone, Debug)]
pub struct IdentifiedHead {
    /// The form solved.
    pub form: Form,
    /// Solver label.
    pub label: &'static str,
    /// Identified beams.
    pub beams: Vec<Beam>,
    /// Reading gains (the norm of gamma in the paper's form; 1 in the minimal form).
    pub gains: Vec<f64>,
    /// RMS residual of the identification, mm.
    pub rms_mm: f64,
    /// LM iterations.
    pub iterations: usize,
    /// Wall time, s (PSO included for the paper's form).
    pub seconds: f64,
    /// Condition number of the identification Jacobian at the solution.
    pub condition: f64,
    /// Per beam: distance between identified and true beam at the standard distance 100 mm, mm.
    pub point_error_mm: Vec<f64>,
    /// Per beam: angle between identified and true direction, deg.
    pub angle_error_deg: Vec<f64>,
    /// Accuracy test: per sample, |SPMS centre - tracker centre| in the tracker frame, mm.
    pub measuring_error_mm: Vec<f64>,
    /// Accuracy test: per sample, the largest sphere-fit residual, mm.
    pub fit_residual_max_mm: Vec<f64>,
}

impl IdentifiedHead {
    /// Sphere centre in the head frame from raw readings, mm.
    pub fn centre(&self, readings: &[f64], radius_mm: f64) -> Option<(Vector3<f64>, Vec<f64>)> {
        let scaled: Vec<f64> = readings.iter().zip(&self.gains).map(|(l, g)| l * g).collect();
        fit_centre(&self.beams, &scaled, radius_mm)
    }
}

/// The head experiment's outcome.
#[derive(Clone, Debug)]
pub struct HeadExperiment {
    /// The physical head (true beams, linearity curves).
    pub spms: Spms,
    /// PSO alone: RMS residual, mm, and wall time, s.
    pub pso_rms_mm: f64,
    /// PSO wall time, s.
    pub pso_s: f64,
    /// PSO then LM on the paper's form.
    pub paper: IdentifiedHead,
    /// LM alone on the paper's form from the same rough start (what PSO is there to avoid).
    pub paper_lm_only: IdentifiedHead,
    /// LM alone on the minimal form.
    pub minimal: IdentifiedHead,
}

impl HeadExperiment {
    /// The identified head of `form`.
    pub fn identified(&self, form: Form) -> &IdentifiedHead {
        match form {
            Form::Paper => &self.paper,
            Form::Minimal => &self.minimal,
        }
    }
}

/// Stream parts of the head experiment.
/// Where the tracker and head stand in the accuracy and identification experiments, tracker frame.
const SPHERE_TRACKER_MM: [f64; 3] = [1500.0, 200.0, 800.0];

/// Builds the physical head from Table 2 and the assembly errors.
pub fn build_head(spec: &HeadSpec, seed: u64) -> Spms {
    let mut rng = stream(seed, streams::BUILD);
    let (e, a) = (spec.assembly_error_mm, spec.assembly_error_deg.to_radians());
    let truth: Vec<Beam> = table2_beams()
        .iter()
        .map(|b| {
            let dp = Vector3::from_fn(|_, _| if e > 0.0 { rng.random_range(-e..e) } else { 0.0 });
            let dd = Vector3::from_fn(|_, _| if a > 0.0 { rng.random_range(-a..a) } else { 0.0 });
            Beam::new((b.p + dp).into(), (b.dir.into_inner() + dd).into())
        })
        .collect();
    Spms::new(&truth, spec.sensor.clone(), spec.sphere_diameter_mm / 2.0, &mut rng)
}

/// `n` poses of the head around the fixed sphere: readings and the head frame as the tracker
/// measures it. A pose whose readings fail (a miss, out of range) is drawn again.
fn poses<R: Rng + ?Sized>(spms: &Spms, id: &BeamIdSpec, n: usize, rng: &mut R) -> BeamData {
    let tracker = AxisNoise::new(id.tracker_sigma_um);
    let c_head = Vector3::from(id.sphere_centre_head_mm);
    let sphere = Vector3::from(SPHERE_TRACKER_MM);
    let tilt = id.head_tilt_deg.to_radians();
    let mut data = BeamData { radius_mm: spms.sphere_radius_mm, ..Default::default() };
    let mut tries = 0;
    while data.frames.len() < n && tries < 100 * n.max(1) {
        tries += 1;
        let rot = UnitQuaternion::from_scaled_axis(Vector3::from_fn(|_, _| if tilt > 0.0 { rng.random_range(-tilt..tilt) } else { 0.0 }));
        let (ax, al) = (id.sphere_across_mm, id.sphere_along_mm);
        let jitter = |r: &mut R, h: f64| if h > 0.0 { r.random_range(-h..h) } else { 0.0 };
        let c = c_head + Vector3::new(jitter(rng, ax), jitter(rng, al), jitter(rng, ax));
        let t = Isometry3::from_parts(Translation3::from(sphere - rot * c), rot);
        let Ok(l) = spms.read(&c, Some(&mut *rng)) else {
            continue;
        };
        let Some(measured) = super::measured_frame(&t, &tracker, rng) else {
            continue;
        };
        data.frames.push(measured);
        data.readings.push(l);
    }
    data
}

/// Why the head experiment failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum HeadError {
    /// Fewer poses than asked gave readings.
    #[error("only {got} of {wanted} head poses gave five readings: the sphere travel leaves the beams or their range")]
    Poses {
        /// Poses with readings.
        got: usize,
        /// Poses asked for.
        wanted: usize,
    },
    /// A reading failed where the experiment needs one.
    #[error(transparent)]
    Reading(#[from] ReadingError),
}

/// Builds the head, identifies its beams with both solvers and tests their measuring accuracy.
///
/// Long by design: the paper's section 5.1-5.2 in order (poses, PSO then LM, LM alone on both
/// forms, the accuracy test), sharing the poses and the tracker between the three identifications.
pub fn run(spec: &HeadSpec, id: &BeamIdSpec, seed: u64) -> Result<HeadExperiment, HeadError> {
    let spms = build_head(spec, seed);
    let mut rng = stream(seed, streams::IDENT_POSES);
    let data = poses(&spms, id, id.poses, &mut rng);
    if data.frames.len() < id.poses {
        return Err(HeadError::Poses { got: data.frames.len(), wanted: id.poses });
    }
    let check = poses(&spms, id, id.accuracy_samples, &mut rng);
    if check.frames.len() < id.accuracy_samples {
        return Err(HeadError::Poses { got: check.frames.len(), wanted: id.accuracy_samples });
    }
    // The rough centre: the sphere's place in the tracker frame known to a few mm.
    let e = id.rough_centre_error_mm;
    let rough = Vector3::from(SPHERE_TRACKER_MM) + Vector3::new(0.75 * e, -0.5 * e, e);

    let nominal = Form::Paper.pack(&table2_beams(), &rough);
    let len = nominal.len();
    let half = DVector::from_fn(len, |i, _| {
        if i >= len - 3 {
            id.pso_half_width_centre_mm
        } else if i % 6 < 3 {
            id.pso_half_width_mm
        } else {
            id.pso_half_width_dir
        }
    });
    let mut pso_rng = stream(seed, streams::PSO);
    let t0 = Instant::now();
    let start = pso(
        &data,
        Form::Paper,
        &nominal,
        &half,
        &PsoOptions { population: id.pso_population, iterations: id.pso_iterations, ..PsoOptions::default() },
        &mut pso_rng,
    );
    let pso_s = t0.elapsed().as_secs_f64();
    let paper = levenberg_marquardt(&data, Form::Paper, &start.x, id.lm_tau, id.lm_max_iterations);
    let paper_s = t0.elapsed().as_secs_f64();
    let t_alone = Instant::now();
    let paper_alone = levenberg_marquardt(&data, Form::Paper, &nominal, id.lm_tau, id.lm_max_iterations);
    let paper_alone_s = t_alone.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let minimal = levenberg_marquardt(&data, Form::Minimal, &Form::Minimal.pack(&table2_beams(), &rough), id.lm_tau, id.lm_max_iterations);
    let minimal_s = t1.elapsed().as_secs_f64();

    let mut acc_rng = stream(seed, streams::ACCURACY);
    let tracker = AxisNoise::new(id.tracker_sigma_um);
    let tracker_centre: Vec<Vector3<f64>> =
        check.frames.iter().map(|_| tracker.measure(&Vector3::from(SPHERE_TRACKER_MM), &mut acc_rng)).collect();
    let k = spms.sensors.len();
    let make = |form: Form, label: &'static str, sol: &crate::instrument::spms::beams::Solution, seconds: f64| {
        let beams = form.unpack(&sol.x, k);
        let gains = form.gains(&sol.x, k);
        let point_error_mm = beams.iter().zip(&spms.sensors).map(|(b, s)| (b.point(100.0) - s.beam.point(100.0)).norm()).collect();
        let angle_error_deg = beams.iter().zip(&spms.sensors).map(|(b, s)| b.dir.angle(&s.beam.dir).to_degrees()).collect();
        let condition = sol.singular_values.first().copied().unwrap_or(0.0) / sol.singular_values.last().copied().unwrap_or(f64::NAN);
        let mut head = IdentifiedHead {
            form,
            label,
            beams,
            gains,
            rms_mm: sol.rms_mm,
            iterations: sol.iterations,
            seconds,
            condition,
            point_error_mm,
            angle_error_deg,
            measuring_error_mm: Vec::new(),
            fit_residual_max_mm: Vec::new(),
        };
        for ((t, l), tc) in check.frames.iter().zip(&check.readings).zip(&tracker_centre) {
            if let Some((c, res)) = head.centre(l, spms.sphere_radius_mm) {
                head.measuring_error_mm.push((t.transform_point(&Point3::from(c)).coords - tc).norm());
                head.fit_residual_max_mm.push(res.iter().fold(0.0, |m: f64, r| m.max(r.abs())));
            }
        }
        head
    };
    let paper = make(Form::Paper, "PSO + LM, paper 6K+3", &paper, paper_s);
    let paper_lm_only = make(Form::Paper, "LM alone, paper 6K+3", &paper_alone, paper_alone_s);
    let minimal = make(Form::Minimal, "LM alone, minimal 5K+3", &minimal, minimal_s);
    Ok(HeadExperiment { spms, pso_rms_mm: start.rms_mm, pso_s, paper, paper_lm_only, minimal })
}
