//! What a calibration gives: every model's results (cross-validation, held-out errors, the fit on
//! every point) and the chosen model's estimates (robot parameters with their covariance, bases,
//! tools), assembled from its fit on every point.

use nalgebra::{DMatrix, Matrix3, Vector3};

use super::measurements::Measurements;
use super::problem::{Fit, Layout, Oriented};
use super::registration::Unidentifiable;
use super::robust::RobustFit;
use super::validation::{Assignment, CrossValidation, HeldOut, free_columns};
use super::{CalibrateError, ModelKind, Options, Setup};
use crate::identify::FitOutcome;
use crate::robot::file::RobotFile;
use crate::robot::{ParamId, ParamSet, RobotModel, XyzZyx};
use crate::study::stats::ErrorStats;

/// A robot parameter of the most complete model, as the final fit leaves it.
#[derive(Clone, Debug, PartialEq)]
pub enum ParamStatus {
    /// Identified by the chosen model.
    Identified,
    /// Not freed by the chosen model (kept nominal).
    NotInModel,
    /// The poses cannot separate it from these unknowns (kept nominal).
    Unidentifiable(Vec<String>),
    /// Freed, but its fit broke [`super::DETERMINED`]'s rule (kept nominal, the model refitted
    /// without it): the reason.
    NotDetermined(String),
    /// A joint compliance with no gravity torque to act through (kept nominal, in no model): the
    /// reason.
    NoTorque(String),
}

/// A robot parameter's estimate, internal units.
#[derive(Clone, Debug, PartialEq)]
pub struct Estimate {
    /// The parameter.
    pub id: ParamId,
    /// Its value in the robot file.
    pub nominal: f64,
    /// Its calibrated value.
    pub value: f64,
    /// Its standard deviation (NaN unless identified).
    pub std: f64,
    /// How the fit left it.
    pub status: ParamStatus,
}

/// A session's base: the measuring frame from the robot's base.
#[derive(Clone, Debug, PartialEq)]
pub struct BaseEstimate {
    /// The session.
    pub session: String,
    /// `session_from_base` (eq. 7), mm and rad.
    pub session_from_base: XyzZyx,
    /// Standard deviations of its translation along the base's axes (mm) and of its small
    /// rotations about the base's z, y, x axes (rad).
    pub std: [f64; 6],
}

/// A target's position on the flange.
#[derive(Clone, Debug, PartialEq)]
pub struct ToolEstimate {
    /// The target.
    pub target: String,
    /// Position in the flange frame, mm.
    pub flange_mm: Vector3<f64>,
    /// Standard deviations of its coordinates, mm.
    pub std_mm: [f64; 3],
}

/// A fit on every point.
#[derive(Clone, Debug)]
pub struct PointFit {
    /// How it ended.
    pub outcome: FitOutcome,
    /// Per point: its error, mm.
    pub errors_mm: Vec<f64>,
    /// Per point: its residual (measured minus model) in the robot's base frame, mm.
    pub residual_base_mm: Vec<Vector3<f64>>,
    /// Per point: residual norm over the robust scale.
    pub normalized: Vec<f64>,
    /// Per point: flagged by the outlier rule (left out of the fit under `--outliers reject`).
    pub outlier: Vec<bool>,
    /// Statistics of the errors of the points the fit used (every point but the rejected ones), mm.
    pub stats: ErrorStats,
    /// The a-posteriori noise per coordinate of unit weight (mm without per-point uncertainties).
    pub sigma_hat: f64,
    /// Per point: its rotation error `log(R_measured R_model^T)` about the robot base's axes,
    /// mdeg (`None`: the point has no orientation reading; empty when the file has none).
    pub rotation_base_mdeg: Vec<Option<Vector3<f64>>>,
}

/// One model's results.
#[derive(Clone, Debug)]
pub struct ModelResult {
    /// Which model (`None`: registration only, the robot as its file gives it).
    pub kind: Option<ModelKind>,
    /// Its unknowns (robot parameters after the identifiability check).
    pub layout: Layout,
    /// Robot parameters the poses cannot separate, kept nominal.
    pub unidentifiable: Vec<Unidentifiable>,
    /// Robot parameters whose fit on every point broke [`super::DETERMINED`]'s rule, kept nominal
    /// and the model refitted without them: name and reason.
    pub undetermined: Vec<(String, String)>,
    /// Cross-validation on the training poses (the figure the model is chosen by: the held-out
    /// poses stay out of the choice).
    pub cv: CrossValidation,
    /// k-fold cross-validation over every pose, held-out ones included (the figure comparable
    /// with a k-fold cross-validation of the literature; not used for the choice).
    pub cv_all: CrossValidation,
    /// Errors at the held-out points of a fit on the training points (`None`: that fit failed).
    pub held_out: Option<HeldOut>,
    /// Why the fit on the training points gave no model (`None` when it gave one).
    pub held_out_why: Option<String>,
    /// The fit on every point.
    pub fit: PointFit,
    /// Paired difference of cross-validated squared errors against the chosen model: mean (mm^2),
    /// standard error, points.
    pub against_chosen: (f64, f64, usize),
}

/// A calibration: every model's results, the chosen one's estimates.
#[derive(Clone, Debug)]
pub struct Calibration {
    /// The robot file.
    pub robot: RobotFile,
    /// The measurements.
    pub measurements: Measurements,
    /// The options.
    pub options: Options,
    /// Held-out split and folds.
    pub assignment: Assignment,
    /// Registration only (nominal robot, fitted bases and tools): the errors before calibration.
    pub before: ModelResult,
    /// The models compared, simplest first.
    pub models: Vec<ModelResult>,
    /// The chosen model (index into `models`).
    pub chosen: usize,
    /// The calibrated robot (the robot file's base and tool, the chosen model's parameters).
    pub model: RobotModel,
    /// Every parameter of the most complete model.
    pub estimates: Vec<Estimate>,
    /// Correlations of the identified robot parameters (order of the identified estimates).
    pub correlation: DMatrix<f64>,
    /// The bases, per session.
    pub bases: Vec<BaseEstimate>,
    /// The tools, per target.
    pub tools: Vec<ToolEstimate>,
    /// Per point: the measured position in the robot's base frame of the final fit, mm.
    pub points_base_mm: Vec<Vector3<f64>>,
    /// The model whose robust fit on every point decided the outliers (the most complete).
    pub outliers_by: &'static str,
    /// Per point: flagged by the outlier rule (left out only under `--outliers reject`).
    pub flagged: Vec<bool>,
    /// The outlier rule's verdict on the orientation readings.
    pub readings_flagged: ReadingFlags,
    /// Joint compliances with no gravity torque to act through (kept nominal, in no model): name
    /// and reason.
    pub inert: Vec<(String, String)>,
    /// Per target: its probe's rotation on the flange (`None`: the target has no orientation
    /// reading).
    pub probe_rotations: Vec<Option<ProbeRotation>>,
}

/// A six-degree-of-freedom probe's rotation on the flange.
#[derive(Clone, Debug, PartialEq)]
pub struct ProbeRotation {
    /// `flange_from_probe` (in the robot file's flange frame).
    pub flange_from_probe: nalgebra::Rotation3<f64>,
    /// Standard deviations of its small rotations about the flange's x, y, z axes, mdeg.
    pub std_mdeg: [f64; 3],
}

impl ModelResult {
    /// The model's name in tables.
    pub fn name(&self) -> &'static str {
        self.kind.map_or("before (nominal)", ModelKind::name)
    }
}

impl Calibration {
    /// The chosen model's results.
    pub fn chosen(&self) -> &ModelResult {
        &self.models[self.chosen]
    }
}

/// The per-point view of a fit on every point.
pub(super) fn point_fit(oriented: &Oriented<'_>, fit: &RobustFit, flagged: &[bool]) -> PointFit {
    let problem = &oriented.problem;
    let n = problem.obs.len();
    let errors = problem.errors(&fit.solved.x, &fit.idx).unwrap_or_else(|| vec![Vector3::repeat(f64::NAN); n]);
    let residual_base_mm: Vec<Vector3<f64>> = errors
        .iter()
        .zip(problem.obs)
        .map(|(e, o)| problem.layout.base_delta(&fit.solved.x, o.session).isometry().inverse_transform_vector(e))
        .collect();
    let errors_mm: Vec<f64> = errors.iter().map(|e| e.norm()).collect();
    let kept: Vec<f64> = errors_mm.iter().zip(&fit.outlier).filter(|(_, o)| !**o).map(|(e, _)| *e).collect();
    let rotation_base_mdeg = match oriented.rotation_errors(&fit.solved.x, &fit.idx) {
        Some(r) => r
            .iter()
            .zip(problem.obs)
            .map(|(e, o)| {
                e.map(|e| {
                    problem
                        .layout
                        .base_delta(&fit.solved.x, o.session)
                        .isometry()
                        .inverse_transform_vector(&e)
                        .map(|v| v.to_degrees() * 1e3)
                })
            })
            .collect(),
        None => Vec::new(),
    };
    PointFit {
        rotation_base_mdeg,
        outcome: fit.solved.outcome.clone(),
        stats: ErrorStats::of(&kept),
        errors_mm,
        residual_base_mm,
        normalized: fit.normalized.clone(),
        outlier: flagged.to_vec(),
        sigma_hat: fit.sigma_hat,
    }
}

/// The outlier rule's verdict on the orientation readings.
#[derive(Clone, Debug, PartialEq)]
pub struct ReadingFlags {
    /// Per point: its orientation reading flagged as an outlier (left out of every fit under
    /// `--outliers reject`; false for a point without a reading).
    pub flagged: Vec<bool>,
    /// Per point: its reading's weighted rotation residual over the readings' robust scale in the
    /// fit that decided the outliers (NaN without a reading or under `--outliers off`).
    pub normalized: Vec<f64>,
}

/// What [`finish`] assembles.
pub(super) struct Parts<'a> {
    pub(super) robot: &'a RobotFile,
    pub(super) m: &'a Measurements,
    pub(super) opts: &'a Options,
    pub(super) s: Setup,
    pub(super) assignment: Assignment,
    pub(super) before: ModelResult,
    pub(super) models: Vec<ModelResult>,
    pub(super) chosen: usize,
    pub(super) full: &'a ParamSet,
    pub(super) inert: Vec<(String, String)>,
    pub(super) outliers_by: &'static str,
    pub(super) flagged: Vec<bool>,
    pub(super) readings_flagged: ReadingFlags,
}

/// The chosen model's estimates and covariance from its fit on every point.
pub(super) fn finish(parts: Parts<'_>, fit: RobustFit) -> Result<Calibration, CalibrateError> {
    let Parts { robot, m, opts, s, assignment, before, models, chosen, full, inert, outliers_by, flagged, readings_flagged } = parts;
    let r = &models[chosen];
    let layout = &r.layout;
    let problem = s.fit(&robot.nominal, layout.clone());
    let all: Vec<usize> = (0..s.obs.len()).collect();
    let free = free_columns(&problem, &all, true);
    let lines: Vec<u64> = m.points.iter().map(|p| p.line).collect();
    let rejected: Vec<bool> = match opts.outliers {
        super::OutlierMode::Reject => flagged.clone(),
        super::OutlierMode::Off | super::OutlierMode::Report => vec![false; flagged.len()],
    };
    let labels = super::diagnose::Labels { sessions: &m.sessions, targets: &m.targets, lines: &lines, outliers: &rejected };
    let no_model = |outcome: &str| CalibrateError::NoModel {
        path: m.path.clone(),
        model: r.name(),
        outcome: format!("{outcome}: {}", super::diagnose::why(&problem, &fit.solved.x, &free, &fit.inliers(), &labels)),
    };
    if !fit.solved.outcome.is_converged() {
        return Err(no_model(fit.solved.outcome.label()));
    }
    // `free` holds every column (every session and target has points) but the bases' columns kept
    // at their registration (`Layout::still`): cov in layout order, none for those.
    let cov_free = super::robust::covariance(&problem, &fit, &free).ok_or_else(|| no_model("singular normal matrix"))?;
    let mut cov = DMatrix::zeros(problem.unknowns(), problem.unknowns());
    for (a, &ca) in free.iter().enumerate() {
        for (b, &cb) in free.iter().enumerate() {
            cov[(ca, cb)] = cov_free[(a, b)];
        }
    }
    let x = &fit.solved.x;
    let pr = layout.robot.len();
    let model = layout.robot.unpack(&robot.nominal, &x[..pr]).map_err(|e| no_model(&e.to_string()))?;
    let mut estimates = estimates(full, r, &robot.nominal, x, &cov);
    for e in &mut estimates {
        if let Some((_, why)) = inert.iter().find(|(n, _)| *n == e.id.name()) {
            e.status = ParamStatus::NoTorque(why.clone());
        }
    }
    let correlation = DMatrix::from_fn(pr, pr, |a, b| cov[(a, b)] / (cov[(a, a)] * cov[(b, b)]).sqrt());
    let std_of = |c: usize| cov[(c, c)].max(0.0).sqrt();
    let bases = (0..m.sessions.len())
        .map(|k| BaseEstimate {
            session: m.sessions[k].clone(),
            session_from_base: XyzZyx::from_isometry(&(s.frames[k] * layout.base_delta(x, k).isometry())),
            std: std::array::from_fn(|i| std_of(layout.base(k) + i)),
        })
        .collect();
    let tools = (0..m.targets.len()).map(|t| tool(&m.targets[t], layout.tool(t), x, &cov, robot.flange.as_ref())).collect();
    let r6 = robot.flange.unwrap_or_else(Matrix3::identity);
    let probe_rotations = (0..m.targets.len())
        .map(|t| {
            let c = problem.rotation_column(t)?;
            let r = problem.tool_rotation(x, t)?;
            let in_flange = r6.transpose() * cov.fixed_view::<3, 3>(c, c) * r6;
            Some(ProbeRotation {
                flange_from_probe: nalgebra::Rotation3::from_matrix_unchecked(r6.transpose() * r.matrix()),
                std_mdeg: std::array::from_fn(|i| in_flange[(i, i)].max(0.0).sqrt().to_degrees() * 1e3),
            })
        })
        .collect();
    let points_base_mm =
        s.obs.iter().map(|o| layout.base_delta(x, o.session).isometry().inverse_transform_point(&o.measured_mm.into()).coords).collect();
    Ok(Calibration {
        robot: robot.clone(),
        measurements: m.clone(),
        options: opts.clone(),
        assignment,
        before,
        models,
        chosen,
        model,
        estimates,
        correlation,
        bases,
        tools,
        points_base_mm,
        outliers_by,
        flagged,
        readings_flagged,
        inert,
        probe_rotations,
    })
}

/// Every parameter of `full`: identified by `r` (its value and standard deviation from `x` and
/// `cov`), or kept at `nominal`'s value with the reason.
fn estimates(full: &ParamSet, r: &ModelResult, nominal: &RobotModel, x: &[f64], cov: &DMatrix<f64>) -> Vec<Estimate> {
    full.ids()
        .iter()
        .map(|id| {
            let value0 = id.get(nominal.data());
            match r.layout.robot.position(*id) {
                Some(k) => {
                    Estimate { id: *id, nominal: value0, value: x[k], std: cov[(k, k)].max(0.0).sqrt(), status: ParamStatus::Identified }
                }
                None => {
                    let name = id.name();
                    let status = match r.undetermined.iter().find(|(n, _)| *n == name) {
                        Some((_, why)) => ParamStatus::NotDetermined(why.clone()),
                        None => r
                            .unidentifiable
                            .iter()
                            .find(|u| u.name == name)
                            .map_or(ParamStatus::NotInModel, |u| ParamStatus::Unidentifiable(u.with.clone())),
                    };
                    Estimate { id: *id, nominal: value0, value: value0, std: f64::NAN, status }
                }
            }
        })
        .collect()
}

/// The target whose tool block starts at column `c`, in the flange frame (`flange`: the flange in
/// MDH frame 6, when they differ), with its covariance turned the same way.
fn tool(label: &str, c: usize, x: &[f64], cov: &DMatrix<f64>, flange: Option<&Matrix3<f64>>) -> ToolEstimate {
    let r6 = flange.copied().unwrap_or_else(Matrix3::identity);
    let in_flange = r6.transpose() * cov.fixed_view::<3, 3>(c, c) * r6;
    ToolEstimate {
        target: label.to_string(),
        flange_mm: r6.transpose() * Vector3::new(x[c], x[c + 1], x[c + 2]),
        std_mm: std::array::from_fn(|i| in_flange[(i, i)].max(0.0).sqrt()),
    }
}
