//! Devices: each measuring device is one folder behind one interface, the way an argmin solver
//! implements `Solver` and one executor runs any of them.
//!
//! A [`Device`] names its scenario `kind`, loads and checks its scenario files into a
//! [`Scenario`], and lists its error sources for the budget. A [`Scenario`] runs its study in one
//! physical world (a seed) and gives an [`Outcome`]: the published figures it checks, the summary a
//! sweep keeps of a world, the linear prediction, and the results directory it writes. The
//! application layer (`run`, `check`, realisations) and the design studies (sweeps, merges,
//! budgets) are written once over these traits; [`REGISTRY`] is the one place that knows which
//! devices exist.
//!
//! Adding a device: a folder here implementing the three traits, and one line in [`REGISTRY`].

pub mod keys;
pub mod scenario;
pub mod spms;
pub mod tracker;
pub mod trical;

use std::path::Path;

use crate::robot::RobotModel;
use crate::study::check::Check;
use crate::study::engine::{Identified, Selection};
use crate::study::prediction::Prediction;
use crate::study::{ErrorStats, StudySpec};
pub use scenario::{Header, ScenarioError};

/// Every device calsim knows, by the `kind` its scenario files give (the first is the default of
/// a file without `kind`).
pub static REGISTRY: &[&dyn Device] = &[&trical::TricalDevice, &spms::SpmsDevice, &tracker::TrackerDevice];

/// A measuring device: its scenario files and its error sources.
pub trait Device: Sync {
    /// The scenario's `kind` (`trical`, `spms`).
    fn kind(&self) -> &'static str;

    /// What the device is, in one line (for listings and errors).
    fn describe(&self) -> &'static str;

    /// Loads and checks a scenario of this device from its TOML table; `text` is what the
    /// manifest hashes, `path` names it in errors and anchors the robot file.
    fn load(&self, text: &str, table: toml::Table, path: &Path) -> Result<Box<dyn Scenario>, ScenarioError>;

    /// The device's error sources for the budget, each a label, the dotted scenario keys it scales
    /// together and their unit (the robot's unmodelled effects are the budget's own).
    fn error_sources(&self) -> &'static [ErrorSource];

    /// Its scenario file with every key at the default the loader fills in (the file
    /// [`keys::minimal`] read and written back as TOML; optional keys without a default absent).
    fn defaults(&self) -> toml::Table;

    /// The notes (SOURCED, ASSUMED, FITTED) of its keys: TOML tables of `"dotted.key" = "note"`,
    /// kept beside its specs ([`keys`]).
    fn notes(&self) -> &'static [&'static str];
}

/// The notes of the sections every device shares (`[study]`, `[robot.spread]`, `[robot.unmodelled]`).
pub const SHARED_NOTES: &str = include_str!("keys.toml");

/// An error source of a budget: a label, the scenario keys it scales together, their unit.
pub type ErrorSource = (&'static str, &'static [&'static str], &'static str);

/// A loaded, checked scenario of some device.
pub trait Scenario: Send + Sync + std::fmt::Debug {
    /// Name, path, text and seed.
    fn header(&self) -> &Header;

    /// The same, to change the seed (a command-line override).
    fn header_mut(&mut self) -> &mut Header;

    /// The `[study]` table.
    fn study(&self) -> &StudySpec;

    /// The same, to change it (command-line overrides, a sweep's unit).
    fn study_mut(&mut self) -> &mut StudySpec;

    /// Checks the scenario again after its study or seed were changed; `path` names it in errors.
    fn recheck(&self, path: &str) -> Result<(), ScenarioError>;

    /// The device.
    fn device(&self) -> &'static dyn Device;

    /// A copy of this scenario.
    fn clone_box(&self) -> Box<dyn Scenario>;

    /// Runs the study in the physical world seeded `seed` (realisation 0 is the scenario's own
    /// seed), calling `progress(done, total)` after each identification (from any thread).
    fn run(&self, seed: u64, progress: &(dyn Fn(usize, usize) + Sync)) -> Result<Box<dyn Outcome>, DeviceError>;

    /// Points of the cell's layout in its world frame, mm (the TriCal datum spheres), for the
    /// figures of a sweep that moves them; empty where the device has none.
    fn layout_mm(&self) -> Vec<[f64; 3]>;

    /// The robot's effects outside its kinematic model and its ISO 9283 repeatability (mm), as the
    /// scenario draws them in every world: what a calibration's plan (`calsim calibrate
    /// --plan-scenario`) adds to the calibrated robot. `None` where the device has no robot.
    fn robot_effects(&self) -> Option<(crate::robot::UnmodelledSpec, f64)> {
        None
    }

    /// Where the robot stands in the cell's world frame, for the same figures; `None` where the
    /// device draws no cell.
    fn robot_in_cell(&self) -> Option<RobotInCell> {
        None
    }

    /// Redoes identification `index` of the study in realisation 0 for export; `Ok(None)` when the
    /// study has no such task. A device without an exportable model says so.
    fn refit(&self, index: usize) -> Result<Option<Refit>, DeviceError> {
        let _ = index;
        Err(DeviceError::new(format!(
            "{}: export takes TriCal results (this device's calibration is not exported yet)",
            self.device().kind()
        )))
    }

    /// The arm that carries the device as this scenario's world draws it, and the cone around the
    /// vertical its campaign approaches in: what the optimiser samples to tell how far a design's
    /// cell is from reach. `None` where the device is not carried by the arm into a cell.
    fn carried_reach(&self) -> Option<CarriedReach> {
        None
    }

    /// How near the scenario's campaign is to one that can run, from candidate poses fixed for
    /// every design (the optimiser's measure of a design whose campaigns fail); `None` where the
    /// device has no such measure.
    fn campaign_feasibility(&self) -> Option<trical::campaign::Feasibility> {
        None
    }

    /// The cell of datum spheres on a plate the scenario measures, as a machinist builds it (the
    /// optimiser's build sheet); `None` where the device has none.
    fn datum_cell(&self) -> Option<DatumCell> {
        None
    }

    /// The configurations the device measures at in realisation 0, where it measures only at
    /// configurations of its own (the TriCal: centred on a datum sphere), with the identification
    /// Jacobian rows of its parameter set: the pool `calsim plan` chooses the poses from. `None`
    /// where the device takes any pose its instrument sees.
    fn candidate_pool(&self) -> Option<Result<CandidatePool, DeviceError>> {
        None
    }
}

/// A device's own pool of configurations, for [`Scenario::candidate_pool`].
pub struct CandidatePool {
    /// What a configuration of the pool is (`centred on a datum sphere`).
    pub what: &'static str,
    /// What a group of the pool is (`datum sphere`).
    pub group: &'static str,
    /// The configurations and what each measures: the recorded joint values and the point the
    /// device puts the TCP at in {W} as the cell's calibration gives it, mm.
    pub observations: Vec<crate::identify::Observation>,
    /// The group of each configuration (the datum sphere, 0-based).
    pub group_of: Vec<usize>,
    /// Each group's nominal point in {W} (the sphere centres as the scenario places them), mm.
    pub groups_w_mm: Vec<[f64; 3]>,
    /// The model every identification starts from (before calibration, in {W}, the device's TCP).
    pub start: RobotModel,
    /// The true arm of realisation 0 (its unmodelled effects are not in it).
    pub truth: RobotModel,
    /// The identified parameters.
    pub set: crate::robot::ParamSet,
    /// The pool's scaled identification Jacobian for `set` at `start`.
    pub jacobian: crate::identify::PoolJacobian,
    /// The identification's options and DETMAX's.
    pub fit: crate::identify::FitOptions,
    /// DETMAX's options.
    pub detmax: crate::identify::DetmaxOptions,
    /// The arm's link capsules.
    pub links: crate::robot::file::LinkCapsules,
    /// The device's capsules in MDH frame 6.
    pub device: Vec<crate::cell::collision::CapsuleSpec>,
    /// The device's fixtures (plate, risers, balls) in the robot base frame.
    pub fixtures: Vec<crate::cell::collision::Obstacle>,
}

/// The arm that carries a device, for [`Scenario::carried_reach`].
#[derive(Clone, Debug)]
pub struct CarriedReach {
    /// The true arm, placed in the cell's world frame {W}.
    pub truth: RobotModel,
    /// Half-angle of the cone around the vertical the device's axis (flange to TCP) stays in, deg.
    pub approach_cone_deg: f64,
    /// The device's flange in frame 6, the rotation the inverse kinematics of a device pose takes
    /// (`None`: the device's frame is frame 6).
    pub flange: Option<nalgebra::Matrix3<f64>>,
}

/// A cell of datum spheres on a plate, for [`Scenario::datum_cell`].
#[derive(Clone, Debug, PartialEq)]
pub struct DatumCell {
    /// The sphere centres in {W}, mm.
    pub spheres_w_mm: Vec<[f64; 3]>,
    /// Where the robot base stands in {W}: the scenario's nominal base (the true arm's where it
    /// gives none), as the study places it.
    pub world_from_base: crate::robot::XyzZyx,
    /// The plate's pose relative to the base scenario's cell (mm, deg).
    pub plate_offset_mm_deg: [f64; 6],
    /// How far the plate extends beyond the outermost sphere centres, mm.
    pub plate_margin_mm: f64,
    /// Height of a sphere's riser above the plate, mm.
    pub riser_height_mm: f64,
    /// Diameter of a datum ball, mm.
    pub ball_diameter_mm: f64,
}

impl Clone for Box<dyn Scenario> {
    fn clone(&self) -> Self {
        self.clone_box()
    }
}

/// What a study in one world gave, for whatever the caller does next.
pub trait Outcome: Send + Sync {
    /// The published figures of this world compared with the scenario's bands (computing what the
    /// checks need beyond the study, such as Table 8's external instruments, when asked).
    fn checks(&self) -> Result<Vec<Check>, DeviceError>;

    /// Every identification's record, in task order (for the fit-health line).
    fn fits(&self) -> Vec<&Identified>;

    /// What a sweep keeps of this world.
    fn world(&self) -> WorldSummary;

    /// The linear prediction beside the Monte Carlo at the table set size (`seed` keys its draws).
    fn prediction(&self, seed: u64) -> Option<Prediction>;

    /// The results of this world (tables, manifest fields, summary, figures, recording) as a value
    /// for [`crate::io::results::write`]; `checks` are this world's rows.
    fn results<'a>(&'a self, checks: &'a [Check], options: &'a WriteOptions) -> Result<crate::io::results::Results<'a>, DeviceError>;

    /// The timing line of the study (what took how long), without the writing.
    fn timing(&self) -> String;
}

/// What a results directory gets beside its tables.
#[derive(Clone, Debug, Default)]
pub struct WriteOptions {
    /// Worker threads the run used (recorded in the manifest).
    pub threads: usize,
    /// Draw the figures.
    pub plots: bool,
    /// Write the Rerun recording.
    pub recording: bool,
    /// Command-line overrides applied to the scenario, as `key = value` (recorded in the manifest).
    pub overrides: Vec<(String, String)>,
}

/// What a sweep keeps of a world: the error before calibration, the modelled campaign time, and
/// per identification its place in the grid, its figure of merit after calibration and its O1.
#[derive(Clone, Debug)]
pub struct WorldSummary {
    /// The error before calibration (TriCal: over the validation poses; SPMS: ISO 9283 AP), mm.
    pub before: ErrorStats,
    /// Modelled campaign time, s (0 where the device does not model it).
    pub campaign_s: f64,
    /// Per identification, in task order.
    pub tasks: Vec<TaskFigure>,
}

/// One identification in a [`WorldSummary`].
#[derive(Clone, Debug)]
pub struct TaskFigure {
    /// How its set was chosen.
    pub selection: Selection,
    /// Its set size.
    pub set_size: usize,
    /// The error after calibration (`None`: no model was identified), mm.
    pub after: Option<ErrorStats>,
    /// O1 of its set.
    pub o1: f64,
}

/// One identification redone for export.
pub struct Refit {
    /// Task index.
    pub task: usize,
    /// Its set size.
    pub set_size: usize,
    /// Its validation median, mm.
    pub validation_median_mm: f64,
    /// The fit's residual RMS per configuration, mm.
    pub residual_rms_mm: f64,
    /// The model before calibration (the start of the fit).
    pub before: RobotModel,
    /// The identified model (`None`: the set could not separate the parameters).
    pub model: Option<RobotModel>,
    /// The identified parameter set.
    pub set: crate::robot::ParamSet,
    /// The chosen set's observations.
    pub observations: Vec<crate::identify::Observation>,
    /// The arm's link capsules.
    pub links: crate::robot::file::LinkCapsules,
    /// The arm's flange in MDH frame 6.
    pub flange: Option<nalgebra::Matrix3<f64>>,
}

/// Why a device's study could not run, in its own words (the campaign, a parameter set, a file).
#[derive(Debug, thiserror::Error)]
#[error(transparent)]
pub struct DeviceError(Box<dyn std::error::Error + Send + Sync>);

impl DeviceError {
    /// An error with this message.
    pub fn new(message: impl Into<String>) -> Self {
        Self(message.into().into())
    }

    /// Wraps a device's own error.
    pub fn of(e: impl std::error::Error + Send + Sync + 'static) -> Self {
        Self(Box::new(e))
    }
}

/// The device of a scenario table's `kind` (absent: the first of [`REGISTRY`]).
pub fn device_of(table: &toml::Table, path: &Path) -> Result<&'static dyn Device, ScenarioError> {
    let kind = match table.get("kind") {
        None => return Ok(REGISTRY[0]),
        Some(toml::Value::String(k)) => Some(k.as_str()),
        Some(_) => None,
    };
    kind.and_then(|k| REGISTRY.iter().copied().find(|d| d.kind() == k)).ok_or_else(|| ScenarioError::Parse {
        path: path.display().to_string(),
        key: "kind".into(),
        message: format!(
            "{} is not a study kind ({})",
            table["kind"],
            REGISTRY.iter().map(|d| format!("\"{}\"", d.kind())).collect::<Vec<_>>().join(", ")
        ),
    })
}

/// Loads and checks a scenario of any device from its TOML table.
pub fn from_table(text: &str, table: toml::Table, path: &Path) -> Result<Box<dyn Scenario>, ScenarioError> {
    device_of(&table, path)?.load(text, table, path)
}

/// Reads a scenario file once and loads it as the device its `kind` names.
pub fn load(path: &Path) -> Result<Box<dyn Scenario>, ScenarioError> {
    crate::io::names::of_file(path)?;
    let shown = path.display().to_string();
    let text = crate::io::read_text(path).map_err(|e| ScenarioError::Read { path: shown.clone(), message: e.to_string() })?;
    let table = scenario::table(&text, &shown)?;
    from_table(&text, table, path)
}

/// Where a cell's robot stands in the cell's world frame {W}, for figures drawn to scale.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RobotInCell {
    /// Origin of the true robot's base frame in {W}, mm.
    pub base_w_mm: [f64; 3],
    /// The base frame's z axis (up) in {W}, a unit vector.
    pub base_up_w: [f64; 3],
    /// The shoulder in {W}: the point of the base's z axis at the height of joint 2's axis, mm.
    pub shoulder_w_mm: [f64; 3],
    /// The farthest the TCP gets from the shoulder, mm (over a grid of joints 2, 3 and 5 within
    /// their limits, the others at zero).
    pub reach_mm: f64,
    /// The farthest the TCP gets from the base's z axis, mm (the same grid).
    pub horizontal_reach_mm: f64,
}

impl RobotInCell {
    /// The robot `arm` where its `world_from_base` puts it, and its reach. The points of a sweep
    /// mostly share their arm: the last few arms' answers are kept per thread and returned for an
    /// equal arm (the same bits as computing them again).
    pub fn of(arm: &RobotModel) -> Self {
        const KEPT: usize = 8;
        thread_local! {
            static RECENT: std::cell::RefCell<Vec<(crate::robot::RobotData, RobotInCell)>> = const { std::cell::RefCell::new(Vec::new()) };
        }
        if let Some(hit) = RECENT.with(|r| r.borrow().iter().find(|(d, _)| d == arm.data()).map(|(_, c)| c.clone())) {
            return hit;
        }
        let computed = Self::compute(arm);
        RECENT.with(|r| {
            let mut r = r.borrow_mut();
            if r.len() == KEPT {
                r.remove(0);
            }
            r.push((arm.data().clone(), computed.clone()));
        });
        computed
    }

    fn compute(arm: &RobotModel) -> Self {
        let world_from_base = crate::robot::world_from_base(arm);
        let up = world_from_base.rotation * nalgebra::Vector3::z();
        let base = world_from_base.translation.vector;
        let mut state = crate::robot::KinState::default();
        crate::robot::forward(arm, &mut state, &[0.0; 6]);
        let shoulder = base + up * state.base_from_frame(2).translation.vector.z;
        let lim = arm.limits();
        let grid = |j: usize, k: usize, n: usize| lim[j].min + (lim[j].max - lim[j].min) * k as f64 / (n - 1) as f64;
        let (mut reach, mut horizontal): (f64, f64) = (0.0, 0.0);
        for a in 0..41 {
            for b in 0..41 {
                for c in 0..5 {
                    let q = [0.0, grid(1, a, 41), grid(2, b, 41), 0.0, grid(4, c, 5), 0.0];
                    let tcp = crate::robot::forward(arm, &mut state, &q);
                    reach = reach.max((tcp - shoulder).norm());
                    let d = tcp - base;
                    horizontal = horizontal.max((d - up * d.dot(&up)).norm());
                }
            }
        }
        // Rounded (1e-6 mm, 1e-12 for the unit vector) so that a shard's record reads back from
        // JSON to the same bits (few digits parse exactly) and a resumed shard recognises its sweep.
        let round = |x: f64, q: f64| (x * q).round() / q;
        let xyz = |v: nalgebra::Vector3<f64>, q: f64| [round(v.x, q), round(v.y, q), round(v.z, q)];
        Self {
            base_w_mm: xyz(base, 1e6),
            base_up_w: xyz(up, 1e12),
            shoulder_w_mm: xyz(shoulder, 1e6),
            reach_mm: round(reach, 1e6),
            horizontal_reach_mm: round(horizontal, 1e6),
        }
    }
}

#[cfg(test)]
mod robot_in_cell_tests {
    use super::RobotInCell;

    /// The IRB 120 without a tool: its wrist-centre reach from the shoulder is 270 + sqrt(302^2 +
    /// 70^2) = 580.006 mm (ABB: 0.58 m), so the reach of frame 6 lies between that and that plus
    /// the 72 mm flange; a base moved 100 mm down in {W} moves the shoulder with it and leaves
    /// the reach as it was.
    #[test]
    fn the_irb120_reaches_as_far_as_its_geometry_and_moves_with_its_base() {
        let arm = crate::robot::builtin::irb120();
        let r = RobotInCell::of(&arm);
        assert!(r.reach_mm > 580.0 && r.reach_mm <= 580.01 + 72.0 + 1e-6, "reach {}", r.reach_mm);
        let lowered = arm.edited(|d| d.world_from_base.z -= 100.0).expect("a base");
        let l = RobotInCell::of(&lowered);
        assert!((l.base_w_mm[2] - r.base_w_mm[2] + 100.0).abs() < 1e-9);
        assert!((l.shoulder_w_mm[2] - r.shoulder_w_mm[2] + 100.0).abs() < 1e-9);
        assert!((l.reach_mm - r.reach_mm).abs() < 1e-9);
    }
}
