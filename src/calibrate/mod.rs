//! Calibrating a real robot from measured data (`calsim calibrate`): the same model,
//! identifiability check, least squares and export as the simulations, on a measurement file.
//!
//! ```text
//! robot file ─┐
//!             ├─► measurements::read ─► registration::register ─► registration::prune ─► validation::assign
//! measurements┘   (checked, coupled     (each session's frame,     (per model: the robot      (held-out poses,
//!                  joints)               each target's tool)        parameters the poses       folds)
//!                                                                   separate; the rest named)
//!  ─► robust::robust_fit (most complete model, every point: the outliers, once)
//!  ─► per model: validation::cross_validate, a fit on the training poses and validation::held_out
//!  ─► validation::select (by held-out error) ─► results::finish (the chosen model on every point)
//!  ─► report::write (robot file, URDF, YAML, tables, figures, summary.md)
//! ```
//!
//! The unknowns ([`problem`]) are the robot's parameters (a [`ParamSet`]: by default the TriCal
//! paper's 31 less the base, which is per session here), a base per session (6 numbers, eq. 7)
//! and a tool per target (3 numbers in MDH frame 6). Three models are compared: joint offsets
//! only, the full geometric set, and geometric with joint compliance. The comparison with the
//! plan that a scenario simulated is [`plan`]'s seam.

pub mod diagnose;
pub mod measurements;
pub mod orientation;
pub mod plan;
mod plots;
pub mod problem;
pub mod registration;
pub mod report;
pub mod results;
pub mod robust;
pub mod simulate;
pub mod twin;
pub mod validation;

use std::path::{Path, PathBuf};

use nalgebra::Isometry3;

use crate::robot::file::{RobotFile, RobotFileError};
use crate::robot::{LinkParam, ParamId, ParamSet};
use measurements::{MeasurementError, Measurements};
use problem::{Layout, Obs, Oriented, Problem, Reading, SolveOptions};
use registration::{Raw, Unidentifiable, Unplaced};
pub use results::ReadingFlags;
pub use robust::OutlierMode;
use robust::{RobustFit, fit_without, robust_fit_and_first};
pub use validation::KFoldBy;
use validation::{HeldOutSpec, Split, SplitError, free_columns};

pub use results::{BaseEstimate, Calibration, Estimate, ModelResult, ParamStatus, PointFit, ProbeRotation, ToolEstimate};
use results::{Parts, finish, point_fit};

/// The models compared, simplest first.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModelKind {
    /// Joint-zero offsets only (`theta_offs`).
    Offsets,
    /// Every kinematic parameter of the set (alpha, a, beta, theta_offs, d).
    Geometric,
    /// The kinematic parameters and the joint compliances.
    Compliance,
}

impl ModelKind {
    /// The three, simplest first.
    pub const ALL: [ModelKind; 3] = [ModelKind::Offsets, ModelKind::Geometric, ModelKind::Compliance];

    /// Short name for tables.
    pub fn name(self) -> &'static str {
        match self {
            ModelKind::Offsets => "offsets",
            ModelKind::Geometric => "geometric",
            ModelKind::Compliance => "compliance",
        }
    }

    /// The parameters of `full` this model frees.
    pub fn subset(self, full: &ParamSet) -> ParamSet {
        let keep = |id: &ParamId| match (self, id) {
            (ModelKind::Offsets, ParamId::Link { kind, .. }) => *kind == LinkParam::ThetaOffset,
            (ModelKind::Geometric, ParamId::Link { kind, .. }) => *kind != LinkParam::Compliance,
            (ModelKind::Compliance, _) => true,
            _ => false,
        };
        ParamSet::new(full.ids().iter().copied().filter(keep).collect()).expect("a subset of a set")
    }
}

/// How to calibrate.
#[derive(Clone, Debug, PartialEq)]
pub struct Options {
    /// The robot parameters of the most complete model (`None`: the TriCal paper's 31 less the
    /// base: alpha1..5, a1..5, d3..6, theta_offs2..6, c2..6, beta2).
    pub params: Option<ParamSet>,
    /// Cross-validation folds, 2..=20 (of the training poses, and of every pose when grouped by pose).
    pub folds: usize,
    /// How the k-fold cross-validation over every pose groups the poses (by pose: `folds` folds;
    /// by session: a fold per session).
    pub kfold_by: KFoldBy,
    /// The held-out split.
    pub split: Split,
    /// Seed of the split, the folds and the prediction's draws.
    pub seed: u64,
    /// Outlier threshold in robust standard deviations of a point's residual norm.
    pub outlier_threshold: f64,
    /// What the flagged points do: nothing flagged, flagged and kept, flagged and left out.
    pub outliers: OutlierMode,
    /// Parameter-error draws of the predicted held-out errors.
    pub prediction_draws: usize,
    /// Draw the figures.
    pub plots: bool,
    /// A tool per session and target (`--tool-per-session`): each session's targets placed on the
    /// flange anew (a probe re-mounted between sessions).
    pub tool_per_session: bool,
    /// A lumped payload at the flange in place of the robot file's `[payload]` (`--payload-kg`):
    /// the mass the joint compliances act through when the robot file gives no masses.
    pub payload: Option<Payload>,
    /// The orientation readings' uncertainty when the file gives no `sigma_deg` column, mdeg
    /// (`--orientation-noise-mdeg`).
    pub orientation_noise_mdeg: f64,
    /// The positions' uncertainty per coordinate the rotation residuals are weighted against when
    /// the file has no `sigma_mm` column, mm (`--position-noise-mm`).
    pub position_noise_mm: f64,
}

impl Options {
    /// The weights of the orientation readings.
    fn noise(&self) -> orientation::Noise {
        orientation::Noise { orientation_rad: (self.orientation_noise_mdeg * 1e-3).to_radians(), position_mm: self.position_noise_mm }
    }
}

/// A lumped payload at the flange: the SMR nest, probe or tool the arm holds while measured.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Payload {
    /// Mass, kg.
    pub mass_kg: f64,
    /// Centre of mass in the flange frame, mm.
    pub com_mm: [f64; 3],
}

/// Largest payload `--payload-kg` takes, kg (well above any arm's rated payload).
pub const MOST_PAYLOAD_KG: f64 = 2000.0;
/// Largest coordinate of `--payload-com-mm`, mm.
pub const MOST_PAYLOAD_COM_MM: f64 = 5000.0;
/// A holding torque at or below this at every measured pose is none, N m: a compliance of that
/// joint cannot act.
const NO_TORQUE_NM: f64 = 1e-9;

impl Default for Options {
    fn default() -> Self {
        Self {
            params: None,
            folds: 5,
            kfold_by: KFoldBy::Pose,
            split: Split::Default,
            seed: 1,
            outlier_threshold: robust::DEFAULT_THRESHOLD,
            outliers: OutlierMode::Report,
            prediction_draws: 200,
            plots: true,
            tool_per_session: false,
            payload: None,
            orientation_noise_mdeg: orientation::DEFAULT_ORIENTATION_NOISE_MDEG,
            position_noise_mm: orientation::DEFAULT_POSITION_NOISE_MM,
        }
    }
}

/// Why a calibration cannot run.
#[derive(Debug, thiserror::Error)]
pub enum CalibrateError {
    /// The robot file.
    #[error(transparent)]
    Robot(#[from] RobotFileError),
    /// The measurement file (or what its data cannot fix).
    #[error(transparent)]
    Measurements(#[from] MeasurementError),
    /// An option.
    #[error("--{key}: {message}")]
    Option {
        /// The option, without dashes.
        key: String,
        /// What is wrong.
        message: String,
    },
    /// The final fit gave no model.
    #[error("{path}: the {model} model could not be fitted ({outcome})")]
    NoModel {
        /// The measurement file.
        path: PathBuf,
        /// The model.
        model: &'static str,
        /// How the fit ended.
        outcome: String,
    },
    /// The report directory cannot be written where asked.
    #[error(transparent)]
    OutDir(#[from] crate::io::out_dir::OutDirError),
    /// The measurement file's name cannot name the report directory.
    #[error(transparent)]
    Name(#[from] crate::io::names::NameError),
    /// Writing the report.
    #[error("{path}: {source}")]
    Io {
        /// The directory.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
}

/// What `calsim calibrate` returns: the calibration and where its report went.
#[derive(Debug)]
pub struct CalibrationReport {
    /// The calibration.
    pub calibration: Calibration,
    /// The report directory.
    pub dir: PathBuf,
    /// The measured held-out median beside the plan's simulation of it (`--plan-worlds`): the
    /// first of `plans`.
    pub plan: Option<plan::PlanComparison>,
    /// Every plan asked for (`--plan-with`), in the order of `plan.md`'s table.
    pub plans: Vec<(plan::PlanWith, plan::PlanComparison)>,
    /// `plans` as a table ([`plan::table`]; `None`: no plan made).
    pub plan_table: Option<crate::io::table::Frame>,
    /// The twin ([`twin::analyse`]), or why it could not be fitted.
    pub twin: Result<twin::Twin, String>,
}

/// Where `calsim calibrate` reads and writes.
#[derive(Clone, Debug)]
pub struct CalibrateSpec {
    /// The robot file (nominal model, limits, coupling).
    pub robot_file: PathBuf,
    /// The measurement file.
    pub measurements: PathBuf,
    /// The directory the report goes in (`<out>/<measurements stem>.calibration`).
    pub out: PathBuf,
    /// How to calibrate.
    pub options: Options,
    /// Worlds of the plan's simulation ([`plan::simulate`]; 0: none), at most [`MOST_PLAN_WORLDS`].
    pub plan_worlds: usize,
    /// The plan's noise per coordinate, mm (`None`: the points' own, else the fit's residual).
    pub plan_noise_mm: Option<f64>,
    /// The scenario that planned the calibration: its robot's effects outside the model and its
    /// repeatability are drawn in each world of every plan (`None`: none).
    pub plan_scenario: Option<PathBuf>,
    /// What the plan's worlds draw: the twin (default), the instrument's noise only, the residual
    /// as white noise, or all three.
    pub plan_with: plan::PlanWith,
    /// The instrument's noise per coordinate as the user states it, mm (`None`: the file's sigma
    /// column, else estimated from the data where they allow): the twin's decomposition.
    pub instrument_noise_mm: Option<f64>,
}

/// Most worlds of a plan's simulation (each a whole calibration).
pub const MOST_PLAN_WORLDS: usize = 1000;

/// `calsim calibrate`: reads the robot and measurement files, calibrates, writes the report.
pub fn calibrate(spec: &CalibrateSpec) -> Result<CalibrationReport, CalibrateError> {
    let _inputs = crate::io::inputs::Ledger::open();
    check_options(&spec.options)?;
    if let Some(s) = spec.plan_noise_mm
        && !(s.is_finite() && (0.0..=100.0).contains(&s))
    {
        return Err(CalibrateError::Option { key: "plan-noise-mm".into(), message: format!("{s}: within 0 to 100 mm") });
    }
    // The plan's flags without a plan: refused as --plan-scenario is.
    if spec.plan_noise_mm.is_some() && spec.plan_worlds == 0 {
        return Err(CalibrateError::Option { key: "plan-noise-mm".into(), message: "a plan needs --plan-worlds N (N >= 1)".into() });
    }
    if let Some(s) = spec.instrument_noise_mm
        && !(s.is_finite() && (0.0..=100.0).contains(&s))
    {
        return Err(CalibrateError::Option { key: "instrument-noise-mm".into(), message: format!("{s}: within 0 to 100 mm") });
    }
    if spec.plan_with != plan::PlanWith::default() && spec.plan_worlds == 0 {
        return Err(CalibrateError::Option { key: "plan-with".into(), message: "a plan needs --plan-worlds N (N >= 1)".into() });
    }
    if spec.plan_worlds > MOST_PLAN_WORLDS {
        return Err(CalibrateError::Option {
            key: "plan-worlds".into(),
            message: format!("{}: at most {MOST_PLAN_WORLDS}", spec.plan_worlds),
        });
    }
    let plan_effects = spec.plan_scenario.as_deref().map(|path| plan_effects(path, spec.plan_worlds)).transpose()?;
    // Before any work: the report's name and directory.
    crate::io::names::of_file(&spec.measurements)?;
    crate::io::out_dir::vet_dir(&spec.out)?;
    let robot = RobotFile::load(&spec.robot_file)?;
    let m = measurements::read(&spec.measurements, &robot)?;
    let name = report::directory_name(&spec.measurements);
    crate::io::out_dir::prepare(&spec.out, &name)?;
    let (calibration, kept) = run_keeping(&robot, &m, &spec.options)?;
    let twin = twin::analyse_with(&calibration, spec.instrument_noise_mm, Some(&kept)).map_err(|e| e.to_string());
    drop(kept);
    let (plans, missing) = plans(spec, &calibration, twin.as_ref().ok(), plan_effects.as_ref())?;
    let io = |source| CalibrateError::Io { path: spec.out.join(&name), source };
    let plan_table = (!plans.is_empty()).then(|| plan::table(&plans)).transpose().map_err(io)?;
    let dir = report::write_with(&spec.out, &name, &calibration, (&plans, &missing), &twin).map_err(io)?;
    Ok(CalibrationReport { calibration, dir, plan: plans.first().map(|(_, p)| p.clone()), plans, plan_table, twin })
}

/// Plans asked for that were made, and those that could not be, with why.
type Plans = (Vec<(plan::PlanWith, plan::PlanComparison)>, Vec<(plan::PlanWith, String)>);

/// The plans of `spec.plan_with` over `spec.plan_worlds` worlds (none when 0). The noise of the
/// noise-only and twin plans: `--plan-noise-mm`, else the twin's instrument noise (stated, the
/// file's column point by point, or estimated). A plan asked for alone that cannot be made is an
/// error of `--plan-with`; in `all`, a line of plan.md.
fn plans(
    spec: &CalibrateSpec,
    c: &Calibration,
    twin: Option<&twin::Twin>,
    effects: Option<&plan::Effects>,
) -> Result<Plans, CalibrateError> {
    use plan::{Basis, Noise, PlanWith};
    let (mut made, mut missing) = (Vec::new(), Vec::new());
    if spec.plan_worlds == 0 {
        return Ok((made, missing));
    }
    let sigma_column = c.measurements.points.iter().all(|p| p.sigma_mm.is_some());
    let instrument: Option<(Noise, String)> = match (spec.plan_noise_mm, twin.and_then(|t| t.noise_mm)) {
        (Some(s), _) => Some((Noise::Fixed(s), format!("noise {s:.4} mm per coordinate (--plan-noise-mm)"))),
        (None, Some(s)) if sigma_column && spec.instrument_noise_mm.is_none() => {
            Some((Noise::PointsElse(s), "each point's own sigma (the file's column)".into()))
        }
        (None, Some(s)) => Some((Noise::Fixed(s), format!("instrument noise {s:.4} mm per coordinate (the twin's decomposition)"))),
        (None, None) => None,
    };
    let with = effects.map_or_else(String::new, |e| format!("; the effects and repeatability of {}", e.source));
    let twin_effects = twin.map(|t| (&t.model, t.plan_effects()));
    let alone = spec.plan_with != PlanWith::All;
    for kind in spec.plan_with.plans() {
        let basis = match kind {
            PlanWith::Noise => match &instrument {
                Some((noise, said)) => Ok(Basis { noise: *noise, effects, twin: None, label: Some(format!("the calibrated robot, {said}{with}")) }),
                None => Err("the instrument's noise is not known (no sigma column, no pose with two targets or more): give --plan-noise-mm or --instrument-noise-mm".to_string()),
            },
            PlanWith::Twin => match (twin, &twin_effects) {
                (Some(t), Some((model, learned))) => {
                    let (noise, said) = instrument.clone().unwrap_or((Noise::Fixed(0.0), "no instrument noise known: the residual left is drawn as the twin's repeatability and per-pose error".into()));
                    let label = format!("the twin (its robot, [learned] effects, repeatability {:.4} mm RP, per-pose error {:.3} mdeg), {said}{with}", t.learned.repeatability_mm, t.learned.pose_error_mdeg);
                    Ok(Basis { noise, effects, twin: Some((*model, learned)), label: Some(label) })
                }
                _ => Err("the twin could not be fitted (see summary.md)".to_string()),
            },
            PlanWith::Residual | PlanWith::All => {
                let s = plan::residual_noise_mm(c);
                let label = format!("the calibrated robot, the fit's residual {s:.4} mm per coordinate as white noise{with}");
                Ok(Basis { noise: Noise::PointsElse(s), effects, twin: None, label: Some(label) })
            }
        };
        match basis {
            Ok(b) => {
                let sim = plan::simulate_basis(c, spec.plan_worlds, plan::Statistic::Median, spec.options.seed, &b)?;
                made.push((kind, plan::compare(c, &sim)));
            }
            Err(why) if alone => {
                return Err(CalibrateError::Option { key: "plan-with".into(), message: format!("{}: {why}", kind.name()) });
            }
            Err(why) => missing.push((kind, why)),
        }
    }
    Ok((made, missing))
}

/// The robot effects of the planning scenario at `path` (any device with a robot), for a plan of
/// `worlds` worlds.
fn plan_effects(path: &Path, worlds: usize) -> Result<plan::Effects, CalibrateError> {
    let bad = |message: String| CalibrateError::Option { key: "plan-scenario".into(), message };
    if worlds == 0 {
        return Err(bad("a plan needs --plan-worlds N (N >= 1)".into()));
    }
    let s = crate::device::load(path).map_err(|e| bad(e.to_string()))?;
    let (unmodelled, repeatability_mm) =
        s.robot_effects().ok_or_else(|| bad(format!("{}: its device has no robot to plan with", path.display())))?;
    Ok(plan::Effects { source: path.display().to_string(), unmodelled, repeatability_mm, learned: None })
}

fn check_options(o: &Options) -> Result<(), CalibrateError> {
    let bad = |key: &str, message: String| Err(CalibrateError::Option { key: key.into(), message });
    if !(2..=20).contains(&o.folds) {
        return bad("folds", format!("{}: within 2 to 20", o.folds));
    }
    if let Split::Poses { fraction } = o.split
        && !(fraction > 0.0 && fraction <= 0.5)
    {
        return bad("hold-out", format!("{fraction}: a fraction above 0 and at most 0.5"));
    }
    if let Split::Session(l) = &o.split
        && l.is_empty()
    {
        return bad("hold-out-session", "an empty label".into());
    }
    if !(o.outlier_threshold.is_finite() && (2.0..=100.0).contains(&o.outlier_threshold)) {
        return bad("outlier-threshold", format!("{}: within 2 to 100 robust standard deviations", o.outlier_threshold));
    }
    if !(10..=100_000).contains(&o.prediction_draws) {
        return bad("prediction-draws", format!("{}: within 10 to 100000", o.prediction_draws));
    }
    if let Some(p) = &o.payload {
        if !(p.mass_kg.is_finite() && (0.0..=MOST_PAYLOAD_KG).contains(&p.mass_kg)) {
            return bad("payload-kg", format!("{}: within 0 to {MOST_PAYLOAD_KG} kg", p.mass_kg));
        }
        if let Some(v) = p.com_mm.iter().find(|v| !(v.is_finite() && v.abs() <= MOST_PAYLOAD_COM_MM)) {
            return bad("payload-com-mm", format!("{v}: each coordinate within +-{MOST_PAYLOAD_COM_MM} mm of the flange"));
        }
    }
    if !(o.orientation_noise_mdeg.is_finite()
        && o.orientation_noise_mdeg > 0.0
        && o.orientation_noise_mdeg <= orientation::MOST_ORIENTATION_NOISE_MDEG)
    {
        return bad(
            "orientation-noise-mdeg",
            format!("{}: above 0 and at most {} mdeg", o.orientation_noise_mdeg, orientation::MOST_ORIENTATION_NOISE_MDEG),
        );
    }
    if !(o.position_noise_mm.is_finite() && o.position_noise_mm > 0.0 && o.position_noise_mm <= orientation::MOST_POSITION_NOISE_MM) {
        return bad(
            "position-noise-mm",
            format!("{}: above 0 and at most {} mm", o.position_noise_mm, orientation::MOST_POSITION_NOISE_MM),
        );
    }
    if let Some(p) = &o.params {
        if let Some(id) = p.ids().iter().find(|id| matches!(id, ParamId::Base(_) | ParamId::Tool(_))) {
            return bad("params", format!("{}: the bases and tools are fitted per session and target, not as robot parameters", id.name()));
        }
        if p.is_empty() {
            return bad("params", "no parameter".into());
        }
    }
    Ok(())
}

/// The default robot parameters: the TriCal paper's 31 less the base.
pub fn default_params() -> ParamSet {
    let set = ParamSet::trical_31();
    ParamSet::new(set.ids().iter().copied().filter(|id| !matches!(id, ParamId::Base(_))).collect()).expect("a subset of a set")
}

/// The points in their sessions' registered frames and those frames.
#[derive(Clone)]
struct Setup {
    obs: Vec<Obs>,
    frames: Vec<Isometry3<f64>>,
    /// Start values of the base and tool blocks.
    frames_x: Vec<f64>,
    /// Per session, the base columns its points do not fix ([`Layout::still`]).
    still: Vec<[bool; 6]>,
    /// Per point: its orientation reading in its session's registered frame.
    readings: Vec<Option<Reading>>,
    /// Per target: the start value of its probe's rotation on the flange (`None`: no reading).
    tool_rotations: Vec<Option<nalgebra::Rotation3<f64>>>,
}

impl Setup {
    /// The fit of the model `layout` from `start`: the points' positions and readings.
    fn fit<'a>(&'a self, start: &'a crate::robot::RobotModel, layout: Layout) -> Oriented<'a> {
        Oriented { problem: Problem { start, layout, obs: &self.obs }, readings: &self.readings, tool_rotations: &self.tool_rotations }
    }
}

fn setup(robot: &RobotFile, m: &Measurements) -> Result<Setup, CalibrateError> {
    setup_with(robot, m, &orientation::Noise::default())
}

fn setup_with(robot: &RobotFile, m: &Measurements, noise: &orientation::Noise) -> Result<Setup, CalibrateError> {
    let raw: Vec<Raw> = m
        .points
        .iter()
        .map(|p| {
            let pose = &m.poses[p.pose];
            Raw { q: pose.q, measured_mm: p.measured_mm, session: pose.session, target: p.target }
        })
        .collect();
    let nominal = &robot.nominal;
    let (frames, tools, spans) = registration::register(nominal, &raw, m.sessions.len(), m.targets.len(), nominal.data().flange_tcp_mm)
        .map_err(|u| {
            let (column, label, first) = match u {
                Unplaced::Session(k) => ("session", &m.sessions[k], m.points.iter().find(|p| m.poses[p.pose].session == k)),
                Unplaced::Target(t) => ("target", &m.targets[t], m.points.iter().find(|p| p.target == t)),
            };
            MeasurementError {
                path: m.path.clone(),
                line: first.map(|p| p.line),
                column: Some(column.into()),
                message: format!("{column} {label}: its points do not fix its frame (fewer than 3 distinct positions, or all on a line)"),
            }
        })?;
    let mut frames = frames;
    let mut obs: Vec<Obs> = raw
        .iter()
        .zip(&m.points)
        .map(|(r, p)| Obs {
            q: r.q,
            measured_mm: frames[r.session].inverse_transform_point(&r.measured_mm.into()).coords,
            session: r.session,
            target: r.target,
            sigma: p.sigma_mm.unwrap_or(1.0),
        })
        .collect();
    let mut still: Vec<[bool; 6]> = spans.iter().zip(&frames).map(|(span, f)| span.still(f)).collect();
    let mut readings = orientation::readings(m, &frames, noise);
    for (s, fixed) in orientation::orient_sessions(nominal, &spans, &mut frames, &mut obs, &mut readings).into_iter().enumerate() {
        if fixed {
            still[s] = [false; 6];
        }
    }
    let tool_rotations = orientation::tool_rotations(nominal, &obs, &readings, m.targets.len());
    let mut frames_x = vec![0.0; 6 * m.sessions.len()];
    for t in &tools {
        frames_x.extend(t.iter());
    }
    frames_x.extend(std::iter::repeat_n(0.0, 3 * tool_rotations.iter().filter(|r| r.is_some()).count()));
    let s = Setup { obs, frames, frames_x, still, readings, tool_rotations };
    check_start(robot, m, &s)?;
    check_readings(robot, m, &s)?;
    Ok(s)
}

/// Largest median error of the nominal robot registered on the points, mm: a robot's errors
/// before calibration are millimetres (the IRB 120's 1-3 mm); tens of millimetres are data that
/// do not describe this robot as the file says (units, joint order or convention, coupling, the
/// wrong robot file).
const MOST_START_MEDIAN_MM: f64 = 50.0;

/// The nominal robot, registered, within [`MOST_START_MEDIAN_MM`] of the points (the median,
/// so that outliers do not decide).
fn check_start(robot: &RobotFile, m: &Measurements, s: &Setup) -> Result<(), CalibrateError> {
    let layout = Layout {
        robot: ParamSet::new(vec![]).expect("no parameter"),
        sessions: m.sessions.len(),
        targets: m.targets.len(),
        still: s.still.clone(),
    };
    let problem = Problem { start: &robot.nominal, layout, obs: &s.obs };
    let all: Vec<usize> = (0..s.obs.len()).collect();
    let errors: Vec<f64> = problem.errors(&s.frames_x, &all).map_or_else(|| vec![f64::NAN], |e| e.iter().map(|v| v.norm()).collect());
    let median = crate::study::stats::median(&errors);
    if median <= MOST_START_MEDIAN_MM {
        return Ok(());
    }
    Err(MeasurementError {
        path: m.path.clone(),
        line: None,
        column: None,
        message: format!(
            "the nominal robot of {} registered on these points is {median:.1} mm off them (median; a robot before calibration is \
             millimetres off): check the units in the column names, the joint order and convention (`# joints`, [[coupling]]) and \
             the robot file",
            robot.path.display()
        ),
    }
    .into())
}

/// Largest median angle between the orientation readings and the nominal robot registered on the
/// points with each probe's start rotation, deg: a robot before calibration is a fraction of a
/// degree off; tens of degrees are readings in another convention (the quaternion's order, the
/// inverse rotation, another frame).
const MOST_START_MEDIAN_DEG: f64 = 5.0;

/// The readings, with the nominal robot registered and each probe's start rotation, within
/// [`MOST_START_MEDIAN_DEG`] of the model (the median over every reading, and over the readings of
/// each target in each session, so that a session or a probe written in another convention is
/// caught among right ones); an error names the file, the first line whose reading is that far off,
/// the session and target where only they are, and the quaternion's columns.
fn check_readings(robot: &RobotFile, m: &Measurements, s: &Setup) -> Result<(), CalibrateError> {
    if !m.orientation_columns {
        return Ok(());
    }
    let layout = Layout {
        robot: ParamSet::new(vec![]).expect("no parameter"),
        sessions: m.sessions.len(),
        targets: m.targets.len(),
        still: s.still.clone(),
    };
    let fit = s.fit(&robot.nominal, layout);
    let all: Vec<usize> = (0..s.obs.len()).collect();
    let angles: Vec<f64> = problem::Fit::rotation_errors(&fit, &s.frames_x, &all)
        .map_or_else(|| vec![f64::NAN], |e| e.iter().map(|e| e.map_or(0.0, |v| v.norm().to_degrees())).collect());
    let far = |i: &usize| angles[*i].is_nan() || angles[*i] > MOST_START_MEDIAN_DEG;
    let fail = |median: f64, idx: &[usize], group: String| {
        let first = idx.iter().find(|i| far(i)).map(|&i| m.points[i].line);
        Err(MeasurementError {
            path: m.path.clone(),
            line: first,
            column: Some("quat_w, quat_x, quat_y, quat_z".into()),
            message: format!(
                "the orientation readings{group} are {median:.1} deg off the nominal robot registered on the points (median; a \
                 robot before calibration is a fraction of a degree off): give each reading as the probe's frame in the session's \
                 frame, the quaternion as w, x, y, z"
            ),
        }
        .into())
    };
    let median = crate::study::stats::median(&angles);
    if median > MOST_START_MEDIAN_DEG || angles.len() != m.points.len() {
        return fail(median, &all, String::new());
    }
    let mut groups: Vec<((usize, usize), Vec<usize>)> = Vec::new();
    for (i, p) in m.points.iter().enumerate().filter(|(_, p)| p.orientation.is_some()) {
        let key = (m.poses[p.pose].session, p.target);
        match groups.iter_mut().find(|(k, _)| *k == key) {
            Some((_, idx)) => idx.push(i),
            None => groups.push((key, vec![i])),
        }
    }
    for ((session, target), idx) in &groups {
        let median = crate::study::stats::median(&idx.iter().map(|&i| angles[i]).collect::<Vec<_>>());
        if median > MOST_START_MEDIAN_DEG {
            return fail(median, idx, format!(" of target {} in session {}", m.targets[*target], m.sessions[*session]));
        }
    }
    Ok(())
}

/// The models of `full` after the identifiability check on every point (duplicates left out).
fn candidates(
    robot: &RobotFile,
    m: &Measurements,
    s: &Setup,
    full: &ParamSet,
) -> Result<Vec<(ModelKind, Layout, Vec<Unidentifiable>)>, CalibrateError> {
    let all: Vec<usize> = (0..s.obs.len()).collect();
    let mut out: Vec<(ModelKind, Layout, Vec<Unidentifiable>)> = Vec::new();
    for kind in ModelKind::ALL {
        let set = kind.subset(full);
        if set.is_empty() || out.iter().any(|(k, _, _)| kind.subset(full) == k.subset(full)) {
            continue;
        }
        let layout = Layout { robot: set, sessions: m.sessions.len(), targets: m.targets.len(), still: s.still.clone() };
        let x0 = validation::start_values(&layout, &robot.nominal, &s.frames_x);
        let problem = s.fit(&robot.nominal, layout.clone());
        let (kept, fixed) = registration::prune(&problem, &x0, &all, (&m.sessions, &m.targets)).map_err(|e| MeasurementError {
            path: m.path.clone(),
            line: None,
            column: None,
            message: format!("the poses cannot fix {}: a session or target needs poses that turn the flange more", e.names.join(", ")),
        })?;
        out.push((kind, registration::with_robot(&layout, kept), fixed));
    }
    Ok(out)
}

/// Calibrates the arm of `robot` from `m`: every model cross-validated, the chosen one fitted on
/// every point, nothing written.
pub fn run(robot: &RobotFile, m: &Measurements, opts: &Options) -> Result<Calibration, CalibrateError> {
    run_keeping(robot, m, opts).map(|(c, _)| c)
}

/// What a calibration computed that its twin ([`twin::analyse_with`]) computes again from the
/// calibration: taken as it is where it is the same computation.
pub(crate) struct Kept {
    /// The setup of the points (their registration), when the twin's is the same: a file without
    /// orientation readings (the twin's setup weighs none).
    setup: Option<Setup>,
    /// The chosen model's fit on the training points: the points fitted (outliers left out), its
    /// layout, free columns and solution.
    train_fit: Option<(Vec<usize>, Layout, Vec<usize>, problem::Solved)>,
}

impl Kept {
    /// The setup, when the twin's is this one.
    fn setup(&self) -> Option<&Setup> {
        self.setup.as_ref()
    }

    /// The chosen model's training fit when it is that of the points `idx` on `layout` with the
    /// columns `free`.
    fn train_fit(&self, idx: &[usize], layout: &Layout, free: &[usize]) -> Option<&problem::Solved> {
        let (i, l, f, solved) = self.train_fit.as_ref()?;
        (i == idx && l == layout && f == free).then_some(solved)
    }
}

/// [`run`], and what its twin can take from it ([`Kept`]).
fn run_keeping(robot: &RobotFile, m: &Measurements, opts: &Options) -> Result<(Calibration, Kept), CalibrateError> {
    use rayon::prelude::*;
    check_options(opts)?;
    let with_payload;
    let robot = match &opts.payload {
        None => robot,
        Some(p) => {
            let com6 = robot.flange.map_or(nalgebra::Vector3::from(p.com_mm), |r| r * nalgebra::Vector3::from(p.com_mm));
            let nominal = robot
                .nominal
                .edited(|d| d.payload = crate::robot::Inertial { mass_kg: p.mass_kg, com_mm: com6 })
                .map_err(|e| CalibrateError::Option { key: "payload-kg".into(), message: e.to_string() })?;
            with_payload = RobotFile { nominal, ..robot.clone() };
            &with_payload
        }
    };
    let per_session;
    let m = if opts.tool_per_session {
        per_session = tool_per_session(m);
        &per_session
    } else {
        m
    };
    let listed = opts.params.clone().unwrap_or_else(default_params);
    let inert = inert_compliances(robot, m, &listed);
    let full = ParamSet::new(listed.ids().iter().copied().filter(|id| inert.iter().all(|(n, _)| *n != id.name())).collect())
        .expect("a subset of a set");
    if full.is_empty() {
        let why = inert.first().map_or_else(String::new, |(_, w)| w.clone());
        return Err(CalibrateError::Option {
            key: "params".into(),
            message: format!("every parameter is a joint compliance that cannot act: {why}"),
        });
    }
    let split_error = |e: SplitError| CalibrateError::Option { key: opts.split.option().into(), message: e.message(&m.path) };
    let opts = &Options { split: validation::resolve(m, &opts.split).map_err(split_error)?, ..opts.clone() };
    let mut assignment = validation::assign(m, &opts.split, opts.folds, opts.seed).map_err(split_error)?;
    (assignment.fold_all, assignment.folds_all) = validation::assign_every_pose(m, opts.kfold_by, opts.folds, opts.seed)
        .map_err(|message| CalibrateError::Option { key: "kfold-by".into(), message })?;
    let mut s = setup_with(robot, m, &opts.noise())?;
    let mut cands = candidates(robot, m, &s, &full)?;
    let sopts = SolveOptions::default();
    // Outliers are a property of the data, decided once by the most complete model's robust fit
    // on every point (a simpler model would take its own misfit for outliers). `flagged` are the
    // points the rule flags; `outliers` the points every fit and statistic below leaves out (the
    // flagged ones under `OutlierMode::Reject`, none otherwise).
    // The robust fit's first round (every point, none flagged) is the most complete model's fit on
    // every point when no point is left out: kept, with its layout and columns, for that fit.
    let (flagged, readings_flagged, outliers_by, mut first_round) = {
        let (kind, layout, _) = cands.last().expect("at least one model");
        let problem = s.fit(&robot.nominal, layout.clone());
        let all: Vec<usize> = (0..s.obs.len()).collect();
        let x0 = validation::start_values(layout, &robot.nominal, &s.frames_x);
        let free = free_columns(&problem, &all, true);
        let n = s.obs.len();
        let (flagged, readings, first) = match opts.outliers {
            OutlierMode::Off => (vec![false; n], ReadingFlags { flagged: vec![false; n], normalized: vec![f64::NAN; n] }, None),
            OutlierMode::Report | OutlierMode::Reject => {
                let (fit, first) = robust_fit_and_first(&problem, &x0, &free, &all, opts.outlier_threshold, &sopts);
                (fit.outlier, ReadingFlags { flagged: fit.reading_outlier, normalized: fit.reading_normalized }, Some(first))
            }
        };
        (flagged, readings, kind.name(), first.map(|f| (layout.clone(), free, f)))
    };
    // Rejected readings leave the data: every fit below is that of the file without them (their
    // points' positions stay).
    if opts.outliers == OutlierMode::Reject && readings_flagged.flagged.iter().any(|f| *f) {
        let without = without_readings(m, &readings_flagged.flagged);
        s = setup_with(robot, &without, &opts.noise())?;
        cands = candidates(robot, &without, &s, &full)?;
        first_round = None;
    }
    let outliers = match opts.outliers {
        OutlierMode::Reject => flagged.clone(),
        OutlierMode::Off | OutlierMode::Report => vec![false; s.obs.len()],
    };
    let point_fold: Vec<Option<usize>> = m.points.iter().map(|p| assignment.fold[p.pose]).collect();
    let point_fold_all: Vec<Option<usize>> = m.points.iter().map(|p| Some(assignment.fold_all[p.pose])).collect();
    let held: Vec<usize> = (0..m.points.len()).filter(|&i| assignment.held_out[m.points[i].pose]).collect();
    let train: Vec<usize> = (0..m.points.len()).filter(|&i| !assignment.held_out[m.points[i].pose]).collect();
    // A session held out whole has no base from the training fit: its base is registered on its
    // own points. Every other session's base is the training fit's (the held-out poses fix nothing).
    let register: Vec<usize> = (0..m.sessions.len())
        .filter(|&k| {
            let mut poses = m.poses.iter().enumerate().filter(|(_, p)| p.session == k);
            poses.all(|(p, _)| assignment.held_out[p])
        })
        .collect();
    let register_tools: Vec<usize> = (0..m.targets.len()).filter(|&t| !train.iter().any(|&i| m.points[i].target == t)).collect();
    let all: Vec<usize> = (0..s.obs.len()).collect();
    let lines: Vec<u64> = m.points.iter().map(|p| p.line).collect();
    let labels = diagnose::Labels { sessions: &m.sessions, targets: &m.targets, lines: &lines, outliers: &outliers };
    // Per model: its result, its fit on every point and its training fit (the points fitted, the
    // free columns, the solution).
    type Evaluated = (ModelResult, RobustFit, (Vec<usize>, Vec<usize>, problem::Solved));
    let evaluate = |kind: Option<ModelKind>, mut layout: Layout, fixed: Vec<Unidentifiable>, key: u64| -> Evaluated {
        // The fit on every point first: the parameters it leaves undetermined are kept nominal and
        // the model refitted without them, until every freed parameter meets the rule; the
        // cross-validation and the held-out fit then use the model that remains.
        let mut undetermined_params: Vec<(String, String)> = Vec::new();
        let all_fit = loop {
            let x0 = validation::start_values(&layout, &robot.nominal, &s.frames_x);
            let problem = s.fit(&robot.nominal, layout.clone());
            let free = free_columns(&problem, &all, !layout.robot.is_empty());
            let all_fit = match &first_round {
                Some((l, f, fit)) if *l == layout && *f == free && outliers.iter().all(|o| !o) => fit.clone(),
                _ => fit_without(&problem, &x0, &free, &all, &outliers, &sopts),
            };
            let drop = match kind {
                Some(_) if !layout.robot.is_empty() && all_fit.solved.outcome.is_converged() => undetermined(&problem, &all_fit, &free),
                _ => vec![],
            };
            if drop.is_empty() {
                break all_fit;
            }
            let keep: Vec<ParamId> = layout.robot.ids().iter().copied().filter(|id| drop.iter().all(|(d, _)| d != id)).collect();
            undetermined_params.extend(drop.into_iter().map(|(id, why)| (id.name(), why)));
            layout = registration::with_robot(&layout, ParamSet::new(keep).expect("a subset of a set"));
        };
        let x0 = validation::start_values(&layout, &robot.nominal, &s.frames_x);
        // The cross-validations' folds start from the fit on every point (a fold's minimum lies
        // within its share of the data of it): a step or two fewer per fit than from the nominal
        // robot, the same minimum to the solver's tolerance. The training fit starts from the
        // nominal robot, as the twin's fit of the same points does (the twin takes it as it is).
        let x_folds = if all_fit.solved.outcome.is_converged() { all_fit.solved.x.clone() } else { x0.clone() };
        let problem = s.fit(&robot.nominal, layout.clone());
        let with_robot = !layout.robot.is_empty();
        // Every fold of both starts at `x_folds`: its points' kinematics there computed once.
        let start = kind.and_then(|_| problem::Start::for_fit(&problem, &x_folds));
        let folds_fit = start.as_ref().map(|start| problem::Started { fit: &problem, start });
        let folds_fit: &(dyn problem::Fit + Sync) = match &folds_fit {
            Some(f) => f,
            None => &problem,
        };
        // The two cross-validations and the training fit are independent (run side by side).
        let cv = || match kind {
            Some(_) => validation::cross_validate(folds_fit, &x_folds, &point_fold, opts.folds, &outliers, &sopts, &labels),
            None => validation::CrossValidation::empty(s.obs.len()),
        };
        let cv_all = || match kind {
            Some(_) => validation::cross_validate(folds_fit, &x_folds, &point_fold_all, assignment.folds_all, &outliers, &sopts, &labels),
            None => validation::CrossValidation::empty(s.obs.len()),
        };
        let free = free_columns(&problem, &train, with_robot);
        let mask = |idx: &[usize]| idx.iter().map(|&i| outliers[i]).collect::<Vec<bool>>();
        let train_fit = || fit_without(&problem, &x0, &free, &train, &mask(&train), &sopts);
        let (cv, (cv_all, fit)) = rayon::join(cv, || rayon::join(cv_all, train_fit));
        drop(start);
        let spec = HeldOutSpec {
            test: &held,
            register: &register,
            register_tools: &register_tools,
            outliers: &outliers,
            flagged: &flagged,
            readings_flagged: &readings_flagged.flagged,
            draws: opts.prediction_draws,
            key,
            seed: opts.seed,
        };
        let held_out = fit.solved.outcome.is_converged().then(|| validation::held_out(&problem, &fit, &free, &spec, &sopts));
        let held_out_why = held_out.is_none().then(|| {
            let why = diagnose::why(&problem, &fit.solved.x, &free, &fit.inliers(), &labels);
            format!("{}: {why}", fit.solved.outcome.label())
        });
        let trained = (fit.inliers(), free.clone(), fit.solved.clone());
        let fit = point_fit(&problem, &all_fit, &flagged);
        let r = ModelResult {
            kind,
            layout,
            unidentifiable: fixed,
            undetermined: undetermined_params,
            cv,
            cv_all,
            held_out,
            held_out_why,
            fit,
            against_chosen: (f64::NAN, f64::NAN, 0),
        };
        (r, all_fit, trained)
    };
    let empty = ParamSet::new(vec![]).expect("no parameter");
    // The models are independent of each other (evaluated side by side, gathered in order).
    let before_layout = registration::with_robot(&cands[0].1, empty);
    let (before, evaluated): (_, Vec<Evaluated>) = rayon::join(
        || evaluate(None, before_layout, vec![], 0).0,
        || cands.into_par_iter().enumerate().map(|(k, (kind, layout, fixed))| evaluate(Some(kind), layout, fixed, k as u64 + 1)).collect(),
    );
    let (mut models, mut fits, mut trained) = (Vec::new(), Vec::new(), Vec::new());
    for (r, fit, t) in evaluated {
        models.push(r);
        fits.push(fit);
        trained.push(t);
    }
    let chosen = validation::select(&models.iter().map(|r| Some(&r.cv)).collect::<Vec<_>>()).unwrap_or(models.len() - 1);
    for k in 0..models.len() {
        models[k].against_chosen = validation::paired_difference(&models[k].cv, &models[chosen].cv);
    }
    let fit = fits.into_iter().nth(chosen).expect("a fit per model");
    let (idx, free, solved) = trained.into_iter().nth(chosen).expect("a training fit per model");
    let kept = Kept {
        setup: (!m.orientation_columns).then(|| s.clone()),
        train_fit: (!m.orientation_columns).then(|| (idx, models[chosen].layout.clone(), free, solved)),
    };
    let c = finish(
        Parts {
            robot,
            m,
            opts,
            s,
            assignment,
            before,
            models,
            chosen,
            full: &listed,
            inert,
            outliers_by,
            flagged: flagged.clone(),
            readings_flagged,
        },
        fit,
    )?;
    Ok((c, kept))
}

/// `m` with the orientation readings of the points flagged in `dropped` taken out (their
/// positions kept).
fn without_readings(m: &Measurements, dropped: &[bool]) -> Measurements {
    let mut out = m.clone();
    for (p, _) in out.points.iter_mut().zip(dropped).filter(|(_, d)| **d) {
        p.orientation = None;
        p.sigma_rad = None;
    }
    out
}

/// `m` with a target per session and target (`SMR1@A`): each session's targets get their own
/// position on the flange.
fn tool_per_session(m: &Measurements) -> Measurements {
    let mut out = m.clone();
    out.targets.clear();
    for p in &mut out.points {
        let label = format!("{}@{}", m.targets[p.target], m.sessions[m.poses[p.pose].session]);
        p.target = match out.targets.iter().position(|t| *t == label) {
            Some(k) => k,
            None => {
                out.targets.push(label);
                out.targets.len() - 1
            }
        };
    }
    out
}

/// The joint compliances of `set` that cannot act on the poses of `m`: the gravity torque of their
/// joint is none at every pose (no mass in the robot file at all, or none beyond the joint), with
/// the reason. They are kept nominal and left out of every model.
fn inert_compliances(robot: &RobotFile, m: &Measurements, set: &ParamSet) -> Vec<(String, String)> {
    let d = robot.nominal.data();
    let massless = d.payload.mass_kg == 0.0 && d.links_inertial.iter().all(|b| b.mass_kg == 0.0);
    let mut most = [0.0_f64; crate::robot::JOINTS];
    if !massless {
        for p in &m.poses {
            let tau = crate::robot::gravity_torques(&robot.nominal, &p.q);
            for (j, t) in tau.iter().enumerate() {
                most[j] = most[j].max(t.abs());
            }
        }
    }
    set.ids()
        .iter()
        .filter_map(|id| match id {
            ParamId::Link { joint, kind: LinkParam::Compliance } if massless || most[*joint - 1] <= NO_TORQUE_NM => {
                let why = if massless {
                    format!(
                        "the robot file {} gives no masses (no joint mass_kg, no [payload]): no gravity torque, so a joint compliance \
                         cannot act; give the payload at the flange (--payload-kg M, --payload-com-mm x,y,z, or [payload] in the robot \
                         file) or the links' masses",
                        robot.path.display()
                    )
                } else {
                    format!("no gravity torque at joint {joint} at any measured pose (at most {:.1e} N m)", most[*joint - 1])
                };
                Some((id.name(), why))
            }
            _ => None,
        })
        .collect()
}

/// The rule a freed joint compliance's fit on every point must meet to be exported as identified:
/// its value at least `DETERMINED` standard deviations from zero (an interval of two standard
/// deviations either side narrower than the value), and not positive (the sign of a negative
/// stiffness in `theta = q + theta_offs + c tau`, `tau` the holding torque: see
/// [`crate::robot::kinematics::statics`]). A compliance that breaks it is kept at its nominal value
/// and the model refitted without it. Geometric parameters are not dropped by it: a small true
/// deviation kept nominal biases the others beyond their standard deviations; the summary lists
/// their corrections within two standard deviations of zero.
pub const DETERMINED: f64 = 2.0;

/// The joint compliance of `problem`'s layout that `fit` (on every point, columns `free`) leaves
/// least determined by [`DETERMINED`]'s rule, with the reason (none: every one meets it). One at a
/// time, because the others move once it is fixed: a positive compliance first (the most
/// positive in standard deviations), else the smallest value in standard deviations.
fn undetermined(problem: &Oriented<'_>, fit: &RobustFit, free: &[usize]) -> Vec<(ParamId, String)> {
    if !problem.problem.layout.robot.ids().iter().any(|id| matches!(id, ParamId::Link { kind: LinkParam::Compliance, .. })) {
        return vec![];
    }
    let Some(cov) = robust::covariance(problem, fit, free) else { return vec![] };
    let mut worst: Option<(bool, f64, ParamId, String)> = None;
    for (k, id) in problem.problem.layout.robot.ids().iter().enumerate() {
        let Some(c) = free.iter().position(|&f| f == k) else { continue };
        let (value, std) = (fit.solved.x[k], cov[(c, c)].max(0.0).sqrt());
        let u = id.unit();
        let shown = format!("{} {}", with_uncertainty(u.from_internal(value), u.from_internal(std)), u.symbol());
        let compliance = matches!(id, ParamId::Link { kind: LinkParam::Compliance, .. });
        if !compliance {
            continue;
        }
        let impossible = value > 0.0;
        // NaN (a zero standard deviation at a zero value) counts as undetermined.
        let t = if impossible { -value / std } else { (value / std).abs() };
        let t = if t.is_nan() { f64::NEG_INFINITY } else { t };
        let why = if impossible {
            format!("a positive compliance, a negative stiffness ({shown}; a joint deflects against its holding torque)")
        } else if t < DETERMINED {
            format!("its interval is wider than its value ({shown}: |value| < {DETERMINED} std)")
        } else {
            continue;
        };
        let worse = worst.as_ref().is_none_or(|(n, w, _, _)| (impossible && !*n) || (impossible == *n && t < *w));
        if worse {
            worst = Some((impossible, t, *id, why));
        }
    }
    worst.map(|(_, _, id, why)| (id, why)).into_iter().collect()
}

/// `value +- std` with the standard deviation to two significant digits and the value to the same
/// place (`-21433.4, 31519.5` -> `-21000 +- 32000`; `-0.012748, 0.014261` -> `-0.013 +- 0.014`): an
/// estimate no better than its spread printed without digits it does not have.
fn with_uncertainty(value: f64, std: f64) -> String {
    if !(std.is_finite() && std > 0.0 && value.is_finite()) {
        return format!("{value:.5} +- {std:.5}");
    }
    // The decimal place of the standard deviation's second significant digit.
    let place = std.log10().floor() as i32 - 1;
    if place >= 0 {
        let q = 10f64.powi(place);
        // `+ 0.0`: no `-0`.
        format!("{:.0} +- {:.0}", (value / q).round() * q + 0.0, (std / q).round() * q)
    } else {
        let d = (-place) as usize;
        format!("{:.d$} +- {std:.d$}", value + 0.0)
    }
}

/// The directory `calsim calibrate` writes for the measurement file `path` under `out`.
pub fn report_dir(out: &Path, path: &Path) -> PathBuf {
    out.join(report::directory_name(path))
}

#[cfg(test)]
mod tests {
    use super::with_uncertainty;

    /// An undetermined parameter's estimate is printed to the place of its standard deviation's
    /// second significant digit.
    #[test]
    fn an_estimate_is_printed_to_the_digits_its_spread_allows() {
        assert_eq!(with_uncertainty(-21433.38347, 31519.47188), "-21000 +- 32000");
        assert_eq!(with_uncertainty(-4.61008, 37.97485), "-5 +- 38");
        assert_eq!(with_uncertainty(-70.32639, 62.25961), "-70 +- 62");
        assert_eq!(with_uncertainty(-0.01275, 0.01426), "-0.013 +- 0.014");
        assert_eq!(with_uncertainty(-0.4, 38.0), "0 +- 38");
        assert_eq!(with_uncertainty(1.0, 0.0), "1.00000 +- 0.00000");
    }
}
