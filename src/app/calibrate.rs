//! `calibrate`: a real robot calibrated from measured data (the options of the CLI made into
//! [`crate::calibrate::Options`]; every bound is checked by [`crate::calibrate::calibrate`]).

use std::path::PathBuf;

use super::Error;
use crate::calibrate::{CalibrateError, CalibrateSpec, CalibrationReport, Options, validation::Split};
use crate::robot::ParamSet;

/// What `calibrate` is asked, as the CLI's options give it.
#[derive(Clone, Debug)]
pub struct CalibrateArgs {
    /// The robot file.
    pub robot: PathBuf,
    /// The measurement file (CSV).
    pub measurements: PathBuf,
    /// The directory the report goes to (in `<measurements stem>.calibration`).
    pub out: PathBuf,
    /// Cross-validation folds.
    pub folds: u32,
    /// How the k-fold cross-validation over every pose groups the poses: `pose` or `session`
    /// (`None`: the default, by pose).
    pub kfold_by: Option<String>,
    /// Fraction of each session's poses held out (`None`: the default, unless a session is held out).
    pub hold_out: Option<f64>,
    /// Hold out every pose of this session instead.
    pub hold_out_session: Option<String>,
    /// Hold out the poses listed in this CSV file (columns `session,pose`).
    pub hold_out_file: Option<PathBuf>,
    /// Seed of the split, the folds and the prediction's draws.
    pub seed: u64,
    /// Robot parameters of the most complete model by name (`None`: the default set).
    pub params: Option<Vec<String>>,
    /// Outlier threshold, robust standard deviations (`None`: the default).
    pub outlier_threshold: Option<f64>,
    /// What flagged points do: `off`, `report` or `reject` (`None`: the default).
    pub outliers: Option<String>,
    /// Worlds of the plan's simulation (0: none).
    pub plan_worlds: u32,
    /// The plan's noise per coordinate, mm.
    pub plan_noise_mm: Option<f64>,
    /// The scenario that planned the calibration.
    pub plan_scenario: Option<PathBuf>,
    /// What the plan's worlds draw: `twin`, `noise`, `residual` or `all` (`None`: the default, twin).
    pub plan_with: Option<String>,
    /// The instrument's noise per coordinate, mm, as the user states it.
    pub instrument_noise_mm: Option<f64>,
    /// Draw the figures.
    pub plots: bool,
    /// A tool per session and target.
    pub tool_per_session: bool,
    /// A lumped payload at the flange, kg (`None`: the robot file's).
    pub payload_kg: Option<f64>,
    /// The payload's centre of mass in the flange frame, mm (three numbers; `None`: 0, 0, 0).
    pub payload_com_mm: Option<Vec<f64>>,
    /// The orientation readings' uncertainty when the file gives none, mdeg (`None`: the default).
    pub orientation_noise_mdeg: Option<f64>,
    /// The positions' uncertainty the rotation residuals are weighted against when the file gives
    /// none, mm (`None`: the default).
    pub position_noise_mm: Option<f64>,
}

impl CalibrateArgs {
    /// The CLI's defaults for `robot` and `measurements`, the report in `out`.
    pub fn new(robot: PathBuf, measurements: PathBuf, out: PathBuf) -> Self {
        let d = Options::default();
        Self {
            robot,
            measurements,
            out,
            folds: d.folds as u32,
            kfold_by: None,
            hold_out: None,
            hold_out_session: None,
            hold_out_file: None,
            seed: d.seed,
            params: None,
            outlier_threshold: None,
            outliers: None,
            plan_worlds: 0,
            plan_noise_mm: None,
            plan_scenario: None,
            plan_with: None,
            instrument_noise_mm: None,
            plots: true,
            tool_per_session: false,
            payload_kg: None,
            payload_com_mm: None,
            orientation_noise_mdeg: None,
            position_noise_mm: None,
        }
    }

    /// The library's spec of these options (a parameter name that is none is an error of `params`).
    pub fn spec(&self) -> Result<CalibrateSpec, Error> {
        let defaults = Options::default();
        let option = |key: &str, message: String| Error::Calibrate(CalibrateError::Option { key: key.into(), message });
        let params = match &self.params {
            Some(names) => Some(ParamSet::from_names(names).map_err(|e| option("params", e.to_string()))?),
            None => None,
        };
        let split = match (&self.hold_out_session, self.hold_out, &self.hold_out_file) {
            (Some(_), Some(f), _) => return Err(option("hold-out", format!("{f}: either a fraction or a session held out, not both"))),
            (_, Some(f), Some(_)) => {
                return Err(option("hold-out", format!("{f}: either a fraction or a file of held-out poses, not both")));
            }
            (Some(_), None, Some(_)) => {
                return Err(option("hold-out-file", "either a session or a file of held-out poses, not both".into()));
            }
            (Some(session), None, None) => Split::Session(session.clone()),
            (None, Some(fraction), None) => Split::Poses { fraction },
            (None, None, Some(file)) => Split::Listed {
                source: file.display().to_string(),
                poses: crate::calibrate::measurements::read_pose_list(file).map_err(|e| option("hold-out-file", e.to_string()))?,
            },
            (None, None, None) => defaults.split.clone(),
        };
        let outliers = match &self.outliers {
            None => defaults.outliers,
            Some(name) => crate::calibrate::OutlierMode::parse(name)
                .ok_or_else(|| option("outliers", format!("{name:?}: one of \"off\", \"report\", \"reject\"")))?,
        };
        let kfold_by = match &self.kfold_by {
            None => defaults.kfold_by,
            Some(name) => crate::calibrate::KFoldBy::parse(name)
                .ok_or_else(|| option("kfold-by", format!("{name:?}: one of \"pose\", \"session\"")))?,
        };
        let payload = match (self.payload_kg, &self.payload_com_mm) {
            (None, None) => None,
            (None, Some(_)) => return Err(option("payload-com-mm", "a centre of mass needs --payload-kg".into())),
            (Some(mass_kg), None) => Some(crate::calibrate::Payload { mass_kg, com_mm: [0.0; 3] }),
            (Some(mass_kg), Some(v)) => {
                let com_mm: [f64; 3] =
                    v.as_slice().try_into().map_err(|_| option("payload-com-mm", format!("{} numbers: give three, x,y,z mm", v.len())))?;
                Some(crate::calibrate::Payload { mass_kg, com_mm })
            }
        };
        if self.plan_with.is_some() && self.plan_worlds == 0 {
            return Err(option("plan-with", "a plan needs --plan-worlds N (N >= 1)".into()));
        }
        let plan_with = match &self.plan_with {
            None => crate::calibrate::plan::PlanWith::default(),
            Some(name) => crate::calibrate::plan::PlanWith::parse(name)
                .ok_or_else(|| option("plan-with", format!("{name:?}: one of \"twin\", \"noise\", \"residual\", \"all\"")))?,
        };
        let options = Options {
            params,
            payload,
            tool_per_session: self.tool_per_session,
            folds: self.folds as usize,
            kfold_by,
            split,
            seed: self.seed,
            outlier_threshold: self.outlier_threshold.unwrap_or(defaults.outlier_threshold),
            outliers,
            plots: self.plots,
            orientation_noise_mdeg: self.orientation_noise_mdeg.unwrap_or(defaults.orientation_noise_mdeg),
            position_noise_mm: self.position_noise_mm.unwrap_or(defaults.position_noise_mm),
            ..defaults
        };
        Ok(CalibrateSpec {
            robot_file: self.robot.clone(),
            measurements: self.measurements.clone(),
            out: self.out.clone(),
            options,
            plan_worlds: self.plan_worlds as usize,
            plan_noise_mm: self.plan_noise_mm,
            plan_scenario: self.plan_scenario.clone(),
            plan_with,
            instrument_noise_mm: self.instrument_noise_mm,
        })
    }
}

/// Calibrates and writes the report (`<out>/<measurements stem>.calibration`).
pub fn run(args: &CalibrateArgs) -> Result<CalibrationReport, Error> {
    Ok(crate::calibrate::calibrate(&args.spec()?)?)
}
