//! The virtual TriCal experiment assembled from its specifications: cell, physical robot, device,
//! tracker and campaign, each drawn from its own seeded stream.

use nalgebra::{Point3, Vector3};
use serde::Deserialize;

use crate::cell::world_frame::WorldFrameError;
use crate::cell::{Cell, CellSpec};
use crate::device::trical::campaign::{self, Campaign, CampaignError, CampaignSpec, Setup};
use crate::instrument::laser_tracker::{LaserTracker, LaserTrackerSpec};
use crate::instrument::trical::{TriCal, TriCalSpec};
use crate::robot::builtin::{TRICAL_PAYLOAD, TRICAL_TCP_MM, irb120, trical_2018_table7};
use crate::robot::file::Arm;
use crate::robot::{Inertial, RobotModel, UnmodelledSpec, VirtualRobot, world_from_base};
use crate::seeds::{self, split_seed, stream};

/// The physical robot as a scenario describes it.
#[derive(Clone, Debug, Deserialize, serde::Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct RobotSpec {
    /// ISO 9283 position repeatability RP, mm (the paper: 0.010 mm).
    pub repeatability_mm: f64,
    /// Configuration at which the joint noise is scaled to that repeatability, deg.
    pub repeatability_reference_q_deg: [f64; 6],
    /// TCP of the device in the flange frame, mm (not printed in the paper: assumed).
    pub tcp_mm: [f64; 3],
    /// Mass of the device, kg (assumed).
    pub payload_kg: f64,
    /// Centre of mass of the device in the flange frame, mm (assumed).
    pub payload_com_mm: [f64; 3],
    /// Effects outside the identified model.
    pub unmodelled: UnmodelledSpec,
    /// Spread of the true parameters around Table 7, drawn per world (zero: Table 7 itself).
    pub spread: crate::robot::SpreadSpec,
    /// `world_from_base` of the model before calibration, `[x, y, z]` mm then `[alpha, beta, gamma]`
    /// deg (eq. 7). Absent: the base the semi-automatic steps fit to the located spheres.
    pub nominal_base_mm_deg: Option<[f64; 6]>,
    /// Change of the mass on the flange from identification to validation (setup 2: the
    /// indicators removed, the calibrator with its SMR locked on), kg, at the device's centre of
    /// mass; the identified model keeps `payload_kg`. Absent: no change.
    pub validation_payload_change_kg: Option<f64>,
    /// The arm's robot file, relative to the scenario (absent: the built-in IRB 120 with Table 7).
    pub file: Option<std::path::PathBuf>,
    /// Factor on every amplitude and spread of the learned effects of a twin (a robot file with a
    /// `[learned]` table): 0 leaves them out; a robot file without that table takes only 1.
    pub learned_scale: f64,
    /// The loaded robot file (filled by the scenario loader).
    #[serde(skip)]
    pub arm: Option<Arm>,
    /// The twin's learned effects as the worlds draw them, `learned_scale` applied (filled by the
    /// scenario loader; `None`: the robot file has no `[learned]` table).
    #[serde(skip)]
    pub learned: Option<crate::robot::learned::LearnedEffects>,
}

impl Default for RobotSpec {
    fn default() -> Self {
        Self {
            repeatability_mm: 0.010,
            repeatability_reference_q_deg: [0.0, 20.0, 20.0, 0.0, 50.0, 0.0],
            tcp_mm: TRICAL_TCP_MM,
            payload_kg: TRICAL_PAYLOAD.0,
            payload_com_mm: TRICAL_PAYLOAD.1,
            unmodelled: UnmodelledSpec::default(),
            spread: crate::robot::SpreadSpec::default(),
            nominal_base_mm_deg: Some(crate::robot::builtin::TRICAL_NOMINAL_BASE),
            validation_payload_change_kg: None,
            file: None,
            learned_scale: 1.0,
            arm: None,
            learned: None,
        }
    }
}

/// Everything the virtual TriCal experiment needs.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ExperimentSpec {
    /// The physical robot.
    pub robot: RobotSpec,
    /// The cell.
    pub cell: CellSpec,
    /// The device.
    pub trical: TriCalSpec,
    /// The validation tracker.
    pub tracker: LaserTrackerSpec,
    /// The campaign.
    pub campaign: CampaignSpec,
}

/// A built experiment: the physical world and what the campaign measured in it.
pub struct Experiment {
    /// The cell.
    pub cell: Cell,
    /// The physical robot during identification.
    pub robot: VirtualRobot,
    /// The physical robot during validation (thermal drift applied).
    pub robot_validation: VirtualRobot,
    /// The device.
    pub trical: TriCal,
    /// The tracker.
    pub tracker: LaserTracker,
    /// The campaign's measurements and models.
    pub campaign: Campaign,
    /// The arm's link capsules.
    pub links: crate::cell::collision::LinkCapsules,
}

/// Why an experiment could not be built.
#[derive(Debug, thiserror::Error)]
pub enum ExperimentError {
    /// The sphere layout does not define a frame.
    #[error(transparent)]
    WorldFrame(#[from] WorldFrameError),
    /// The campaign failed.
    #[error(transparent)]
    Campaign(#[from] CampaignError),
    /// The tracker's registration on the sphere nests has no finite fit.
    #[error("the laser tracker's registration on the sphere nests has no finite fit")]
    Registration,
}

impl ExperimentSpec {
    /// The true robot: Table 7 means, with this device as tool and payload.
    pub fn truth(&self) -> RobotModel {
        let table7 = match &self.robot.arm {
            // The file's arm at the scenario's nominal base, then its truth (the device below).
            Some(Arm(arm)) => {
                let placed = arm
                    .nominal
                    .edited(|d| d.world_from_base = crate::robot::XyzZyx::from_mm_deg(self.robot.nominal_base_mm_deg.unwrap_or_default()))
                    .expect("a checked base");
                arm.truth_on(&placed).expect("checked when the robot file was loaded")
            }
            None => trical_2018_table7(),
        };
        table7
            .edited(|d| {
                self.apply_device(d);
                d.world_from_base = self.cell.base_in_moved_world(d.world_from_base);
            })
            .expect("valid device")
    }

    /// The nominal robot: Table 3 with this device (the base is fitted by the campaign).
    pub fn nominal(&self) -> RobotModel {
        let arm = self.robot.arm.as_ref().map_or_else(irb120, |Arm(a)| a.nominal.clone());
        arm.edited(|d| self.apply_device(d)).expect("valid device")
    }

    /// The arm's link capsules: the robot file's, or the built-in IRB 120's (a scenario naming a
    /// robot file without capsules is refused when it is loaded).
    pub fn link_capsules(&self) -> crate::cell::collision::LinkCapsules {
        match &self.robot.arm {
            Some(Arm(arm)) => arm.capsules.clone().unwrap_or_default(),
            None => crate::cell::collision::irb120_link_capsules(),
        }
    }

    /// The arm's flange frame in MDH frame 6 (`None`: frame 6 is the flange).
    pub fn flange(&self) -> Option<nalgebra::Matrix3<f64>> {
        self.robot.arm.as_ref().and_then(|Arm(a)| a.flange)
    }

    /// The device on the flange: its TCP and payload (given in the flange frame) in frame 6.
    fn apply_device(&self, d: &mut crate::robot::RobotData) {
        let flange = self.flange();
        let in_frame6 = |v: [f64; 3]| flange.map_or(Vector3::from(v), |r| r * Vector3::from(v));
        d.flange_tcp_mm = in_frame6(self.robot.tcp_mm);
        d.payload = Inertial { mass_kg: self.robot.payload_kg, com_mm: in_frame6(self.robot.payload_com_mm) };
    }

    /// The model before calibration (the start of every identification): the campaign's nominal
    /// model with the scenario's nominal base if it gives one.
    pub fn before_model(&self, campaign: &Campaign) -> RobotModel {
        match self.robot.nominal_base_mm_deg {
            Some(base) => campaign
                .nominal
                .edited(|d| d.world_from_base = self.cell.base_in_moved_world(crate::robot::XyzZyx::from_mm_deg(base)))
                .expect("finite base"),
            None => campaign.nominal.clone(),
        }
    }

    /// Builds the physical world from `seed` and runs the campaign.
    pub fn build(&self, seed: u64) -> Result<Experiment, ExperimentError> {
        let cell = Cell::build(&self.cell, &mut stream(seed, seeds::experiment::CELL))?;
        let links = self.link_capsules();
        let reference = self.robot.repeatability_reference_q_deg.map(f64::to_radians);
        let truth = crate::robot::perturb(
            &self.truth(),
            &crate::robot::ParamSet::trical_31(),
            &self.robot.spread,
            &mut stream(seed, seeds::experiment::SPREAD),
        );
        // The twin's learned effects are drawn after the scenario's own, from the same stream.
        let robot_rng = &mut stream(seed, seeds::experiment::ROBOT);
        let robot = VirtualRobot::new(truth, &self.robot.unmodelled, self.robot.repeatability_mm, &reference, robot_rng)
            .with_learned(self.robot.learned.as_ref(), robot_rng)
            .with_learned_repeatability(self.robot.learned.as_ref(), self.robot.repeatability_mm, &reference, robot_rng);
        let mut robot_validation = robot.drifted(self.robot.unmodelled.thermal_drift_ppm);
        if let Some(dm) = self.robot.validation_payload_change_kg.filter(|dm| *dm != 0.0) {
            robot_validation.truth = robot_validation.truth.edited(|d| d.payload.mass_kg += dm).expect("a checked mass");
        }
        let mut trical = TriCal::build(&self.trical, self.cell.ball_diameter_mm, &mut stream(seed, seeds::experiment::TRICAL));
        trical.frame6_from_flange = self.flange();
        let base_in_w = world_from_base(&robot.truth).transform_point(&Point3::origin()).coords;
        let sphere3 = cell.spheres_w[2.min(cell.spheres_w.len() - 1)];
        let tracker = LaserTracker::place(
            &self.tracker,
            &sphere3,
            &base_in_w,
            &cell.spheres_w,
            &cell.spheres_w_measured,
            &mut stream(seed, seeds::experiment::TRACKER),
        )
        .ok_or(ExperimentError::Registration)?;
        let setup = Setup {
            cell: &cell,
            robot: &robot,
            robot_validation: &robot_validation,
            trical: &trical,
            tracker: &tracker,
            nominal: &self.nominal(),
            links: &links,
            spec: &self.campaign,
        };
        let campaign = campaign::run(&setup, split_seed(seed, seeds::experiment::CAMPAIGN))?;
        Ok(Experiment { cell, robot, robot_validation, trical, tracker, campaign, links })
    }

    /// How near this cell is to a campaign that can measure it ([`campaign::feasibility`]): the
    /// noise-free cell, device and tracker (drawn from a fixed stream: a function of the scenario
    /// alone), the true arm at its mean parameters. `None`: the spheres define no {W}, or the
    /// tracker has no place.
    pub fn feasibility(&self) -> Option<campaign::Feasibility> {
        let quiet = self.noise_free(self.trical.epsilon_mm);
        let rng = &mut crate::seeds::fixed_stream(seeds::fixed::FEASIBILITY);
        let cell = Cell::build(&quiet.cell, rng).ok()?;
        let links = self.link_capsules();
        let truth = self.truth();
        let mut trical = TriCal::build(&quiet.trical, self.cell.ball_diameter_mm, rng);
        trical.frame6_from_flange = self.flange();
        let base_in_w = world_from_base(&truth).transform_point(&Point3::origin()).coords;
        let sphere3 = cell.spheres_w[2.min(cell.spheres_w.len() - 1)];
        let tracker = LaserTracker::place(&quiet.tracker, &sphere3, &base_in_w, &cell.spheres_w, &cell.spheres_w_measured, rng)?;
        let robot = VirtualRobot::new(truth.clone(), &UnmodelledSpec::default(), 0.0, &[0.0; 6], rng);
        let nominal = self.nominal();
        let setup = Setup {
            cell: &cell,
            robot: &robot,
            robot_validation: &robot,
            trical: &trical,
            tracker: &tracker,
            nominal: &nominal,
            links: &links,
            spec: &self.campaign,
        };
        Some(campaign::feasibility(&setup, &truth))
    }

    /// An identification pool of `count` random configurations measured by an external instrument
    /// (`measure`: the tracker, the optical CMM) on the experiment's robot, for Table 8.
    pub fn instrument_pool(
        &self,
        e: &Experiment,
        seed: u64,
        count: u32,
        measure: crate::device::trical::campaign::Measure<'_>,
    ) -> Result<Vec<crate::device::trical::campaign::ValidationPose>, CampaignError> {
        let nominal = self.nominal();
        let setup = Setup {
            cell: &e.cell,
            robot: &e.robot,
            robot_validation: &e.robot_validation,
            trical: &e.trical,
            tracker: &e.tracker,
            nominal: &nominal,
            links: &e.links,
            spec: &self.campaign,
        };
        campaign::instrument_pool(&setup, &e.campaign, count, split_seed(seed, seeds::experiment::CAMPAIGN), measure)
    }

    /// This experiment without any noise or unmodelled effect, centred to `epsilon_mm`: measurements
    /// are exact up to the centring tolerance.
    pub fn noise_free(&self, epsilon_mm: f64) -> Self {
        let mut s = self.clone();
        s.robot.repeatability_mm = 0.0;
        s.robot.unmodelled = UnmodelledSpec::default();
        s.robot.learned = None;
        s.robot.validation_payload_change_kg = None;
        s.cell.ball_diameter_tolerance_um = 0.0;
        s.cell.ballbar_sigma_um = 0.0;
        s.trical.indicator_accuracy_um = 0.0;
        s.trical.indicator_resolution_um = 0.0;
        s.trical.indicator_misalignment_deg = 0.0;
        s.trical.cmm_sigma_um = 0.0;
        s.trical.epsilon_mm = epsilon_mm;
        s.trical.max_iterations = 60;
        s.tracker.range_sigma_um = 0.0;
        s.tracker.range_sigma_um_per_m = 0.0;
        s.tracker.transverse_sigma_um = 0.0;
        s.tracker.transverse_sigma_um_per_m = 0.0;
        s
    }
}
