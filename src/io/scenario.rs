//! Scenario files: TOML with the unit in every key, unknown keys rejected, every value
//! range-checked. Errors name the file, the key and what is wrong, on one line.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::campaign::CampaignSpec;
use crate::cell::CellSpec;
use crate::experiment::{ExperimentSpec, RobotSpec};
use crate::instrument::laser_tracker::LaserTrackerSpec;
use crate::instrument::trical::TriCalSpec;
use crate::study::StudySpec;

/// A figure with its published value and the relative band the reproduction must fall in.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Band {
    /// Published value.
    pub value: f64,
    /// Allowed relative deviation (0.2 = +-20 %).
    pub tolerance: f64,
}

impl Band {
    /// Whether `x` lies in the band.
    pub fn contains(&self, x: f64) -> bool {
        (x - self.value).abs() <= self.tolerance * self.value.abs()
    }
}

/// The `[expect]` table: the published figures a study is checked against.
#[derive(Clone, Debug, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct ExpectSpec {
    /// Mean error over the validation poses before calibration, mm.
    pub before_mean_mm: Option<Band>,
    /// Largest error before calibration, mm.
    pub before_max_mm: Option<Band>,
    /// Median error after calibration with sets of the table size (median over repetitions), mm.
    pub after_median_mm: Option<Band>,
    /// Standard deviation of the error after calibration (median over repetitions), mm.
    pub after_std_mm: Option<Band>,
    /// Largest error after calibration (median over repetitions), mm.
    pub after_max_mm: Option<Band>,
    /// Least number of Table 7 parameters whose spread is within a factor 3 of the published one.
    pub table7_std_within_factor3_min: Option<u32>,
    /// Least number of Table 7 parameters whose mean is within 3 published std of the truth.
    pub table7_mean_within_3std_min: Option<u32>,
    /// Largest rise allowed between consecutive set sizes of the median of the mean error
    /// (Fig. 8: the median does not rise with n), relative.
    pub fig8_max_rise: Option<f64>,
    /// Least ratio of the spread (IQR) of the mean error at the smallest over the largest set size.
    pub fig9_spread_ratio_min: Option<f64>,
    /// Largest |Pearson r| between error and distance to the centre of the calibration zone (Fig. 12).
    pub fig12_abs_r_max: Option<f64>,
}

/// A scenario file as written.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ScenarioFile {
    seed: u64,
    #[serde(default)]
    study: StudySpec,
    #[serde(default)]
    robot: RobotSpec,
    #[serde(default)]
    cell: CellSpec,
    #[serde(default)]
    trical: TriCalSpec,
    #[serde(default)]
    tracker: LaserTrackerSpec,
    #[serde(default)]
    campaign: CampaignSpec,
    #[serde(default)]
    expect: ExpectSpec,
}

/// A loaded, checked scenario.
#[derive(Clone, Debug)]
pub struct Scenario {
    /// Name (the file stem).
    pub name: String,
    /// Where it was read from.
    pub path: PathBuf,
    /// Its text (hashed into the manifest).
    pub text: String,
    /// Seed of every random stream.
    pub seed: u64,
    /// The virtual experiment.
    pub experiment: ExperimentSpec,
    /// The study.
    pub study: StudySpec,
    /// Figures to check.
    pub expect: ExpectSpec,
}

/// A scenario that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    /// The file cannot be read.
    #[error("{path}: cannot read: {message}")]
    Read {
        /// File.
        path: String,
        /// OS error.
        message: String,
    },
    /// The TOML is malformed or a key is unknown or of the wrong type.
    #[error("{path}: {key}: {message}")]
    Parse {
        /// File.
        path: String,
        /// Dotted key path (or the position in the file).
        key: String,
        /// What is wrong.
        message: String,
    },
    /// A value is out of its range.
    #[error("{path}: [{section}] {key} = {value}: {why}")]
    Range {
        /// File.
        path: String,
        /// Table.
        section: String,
        /// Key.
        key: String,
        /// Value as written.
        value: String,
        /// The rule.
        why: String,
    },
}

/// Reads and checks a scenario file.
pub fn load(path: &Path) -> Result<Scenario, ScenarioError> {
    let shown = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| ScenarioError::Read { path: shown.clone(), message: e.to_string() })?;
    parse(&text, path)
}

/// Parses and checks scenario text; `path` names it in errors.
pub fn parse(text: &str, path: &Path) -> Result<Scenario, ScenarioError> {
    let shown = path.display().to_string();
    let file: ScenarioFile = deserialize(text, &shown)?;
    check(&file, &shown)?;
    let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "scenario".into());
    Ok(Scenario {
        name,
        path: path.to_path_buf(),
        text: text.to_string(),
        seed: file.seed,
        experiment: ExperimentSpec { robot: file.robot, cell: file.cell, trical: file.trical, tracker: file.tracker, campaign: file.campaign },
        study: file.study,
        expect: file.expect,
    })
}

/// Checks a scenario again after command-line overrides.
pub fn check_overrides(s: &Scenario) -> Result<(), ScenarioError> {
    let file = ScenarioFile {
        seed: s.seed,
        study: s.study.clone(),
        robot: s.experiment.robot.clone(),
        cell: s.experiment.cell.clone(),
        trical: s.experiment.trical.clone(),
        tracker: s.experiment.tracker.clone(),
        campaign: s.experiment.campaign.clone(),
        expect: s.expect.clone(),
    };
    check(&file, &format!("{} (with command-line overrides)", s.path.display()))
}

/// Deserializes scenario text, naming the offending key (or line) in the error.
fn deserialize<T: serde::de::DeserializeOwned>(text: &str, shown: &str) -> Result<T, ScenarioError> {
    let de = toml::Deserializer::parse(text).map_err(|e| ScenarioError::Parse { path: shown.into(), key: position(text, e.span()), message: e.message().to_string() })?;
    serde_path_to_error::deserialize(de).map_err(|e| {
        let key = e.path().to_string();
        let inner = e.into_inner();
        ScenarioError::Parse { path: shown.into(), key: if key == "." { position(text, inner.span()) } else { key }, message: inner.message().to_string() }
    })
}

fn position(text: &str, span: Option<std::ops::Range<usize>>) -> String {
    match span {
        Some(s) => {
            let line = text[..s.start.min(text.len())].lines().count().max(1);
            format!("line {line}")
        }
        None => "(file)".into(),
    }
}

struct Checker<'a> {
    path: &'a str,
}

impl Checker<'_> {
    fn fail(&self, section: &str, key: &str, value: impl ToString, why: &str) -> ScenarioError {
        ScenarioError::Range { path: self.path.into(), section: section.into(), key: key.into(), value: value.to_string(), why: why.into() }
    }

    fn positive(&self, section: &str, key: &str, v: f64, what: &str) -> Result<(), ScenarioError> {
        if v.is_finite() && v > 0.0 { Ok(()) } else { Err(self.fail(section, key, v, &format!("must be > 0 ({what})"))) }
    }

    fn non_negative(&self, section: &str, key: &str, v: f64, what: &str) -> Result<(), ScenarioError> {
        if v.is_finite() && v >= 0.0 { Ok(()) } else { Err(self.fail(section, key, v, &format!("must be >= 0 ({what})"))) }
    }

    /// The `[robot.unmodelled]` table, the same in both kinds of scenario.
    fn unmodelled(&self, u: &crate::robot::UnmodelledSpec) -> Result<(), ScenarioError> {
        self.non_negative("robot.unmodelled", "transmission_low_mdeg", u.transmission_low_mdeg, "amplitude")?;
        self.non_negative("robot.unmodelled", "transmission_high_mdeg", u.transmission_high_mdeg, "amplitude")?;
        self.non_negative("robot.unmodelled", "backlash_mdeg", u.backlash_mdeg, "backlash width")?;
        self.within("robot.unmodelled", "thermal_drift_ppm", u.thermal_drift_ppm, -1000.0, 1000.0, "link growth")?;
        if let Some([lo, hi]) = u.transmission_high_orders
            && (lo == 0 || lo > hi)
        {
            return Err(self.fail("robot.unmodelled", "transmission_high_orders", format!("[{lo}, {hi}]"), "must be [min, max] with 1 <= min <= max"));
        }
        Ok(())
    }

    fn within(&self, section: &str, key: &str, v: f64, lo: f64, hi: f64, what: &str) -> Result<(), ScenarioError> {
        if v.is_finite() && v >= lo && v <= hi { Ok(()) } else { Err(self.fail(section, key, v, &format!("must be within [{lo}, {hi}] ({what})"))) }
    }
}

fn check(f: &ScenarioFile, path: &str) -> Result<(), ScenarioError> {
    let c = Checker { path };
    let s = &f.study;
    if s.set_sizes.is_empty() {
        return Err(c.fail("study", "set_sizes", "[]", "needs at least one set size"));
    }
    let pool = f.campaign.pool_per_sphere as usize * f.cell.spheres_w_mm.len();
    let m = s.parameter_set().map_err(|e| c.fail("study", "parameters", format!("{:?}", s.parameters.clone().unwrap_or_default()), &e.to_string()))?.len();
    for &n in &s.set_sizes {
        if (n as usize) * 3 < m || n as usize >= pool {
            return Err(c.fail("study", "set_sizes", n, &format!("each size must give at least {m} equations (3 per configuration) and stay below the pool of {pool}")));
        }
    }
    if s.repetitions == 0 {
        return Err(c.fail("study", "repetitions", 0, "must be >= 1"));
    }
    if !s.set_sizes.contains(&s.table_set_size) {
        return Err(c.fail("study", "table_set_size", s.table_set_size, "must be one of set_sizes"));
    }
    if s.solver != "gauss_newton" && s.solver != "levenberg_marquardt" {
        return Err(c.fail("study", "solver", &s.solver, "must be \"gauss_newton\" or \"levenberg_marquardt\""));
    }
    c.within("study", "detmax_max_excursion", s.detmax_max_excursion as f64, 1.0, 10.0, "excursion length")?;

    let r = &f.robot;
    c.non_negative("robot", "repeatability_mm", r.repeatability_mm, "ISO 9283 RP")?;
    c.within("robot", "repeatability_mm", r.repeatability_mm, 0.0, 1.0, "ISO 9283 RP")?;
    c.non_negative("robot", "payload_kg", r.payload_kg, "device mass")?;
    for (k, v) in r.tcp_mm.iter().chain(&r.payload_com_mm).chain(&r.repeatability_reference_q_deg).enumerate() {
        if !v.is_finite() {
            return Err(c.fail("robot", "tcp_mm / payload_com_mm / repeatability_reference_q_deg", v, &format!("entry {k} must be finite")));
        }
    }
    c.unmodelled(&r.unmodelled)?;

    let cell = &f.cell;
    if cell.spheres_w_mm.len() < 3 {
        return Err(c.fail("cell", "spheres_w_mm", cell.spheres_w_mm.len(), "at least three datum spheres define {W}"));
    }
    let p = &cell.spheres_w_mm;
    if p[0] != [0.0, 0.0, 0.0] || p[1][1] != 0.0 || p[1][2] != 0.0 || p[1][0] <= 0.0 || p[2][2] != 0.0 || p[2][1] <= 0.0 {
        return Err(c.fail("cell", "spheres_w_mm", format!("{:?}", &p[..3]), "the first three define {W} (eqs. 1-5): [0,0,0], then [d12,0,0] with d12 > 0, then [x,y,0] with y > 0"));
    }
    c.positive("cell", "ball_diameter_mm", cell.ball_diameter_mm, "datum ball")?;
    c.non_negative("cell", "ball_diameter_tolerance_um", cell.ball_diameter_tolerance_um, "tolerance")?;
    c.positive("cell", "riser_height_mm", cell.riser_height_mm, "riser")?;
    c.positive("cell", "riser_radius_mm", cell.riser_radius_mm, "riser")?;
    c.positive("cell", "plate_thickness_mm", cell.plate_thickness_mm, "plate")?;
    c.non_negative("cell", "plate_margin_mm", cell.plate_margin_mm, "plate")?;
    c.non_negative("cell", "ballbar_sigma_um", cell.ballbar_sigma_um, "ballbar noise")?;

    let t = &f.trical;
    c.non_negative("trical", "indicator_accuracy_um", t.indicator_accuracy_um, "indicator")?;
    c.non_negative("trical", "indicator_resolution_um", t.indicator_resolution_um, "indicator")?;
    c.within("trical", "indicator_misalignment_deg", t.indicator_misalignment_deg, 0.0, 10.0, "axis tilt")?;
    c.positive("trical", "indicator_range_mm", t.indicator_range_mm, "stroke")?;
    c.non_negative("trical", "tip_radius_mm", t.tip_radius_mm, "contact tip")?;
    c.positive("trical", "epsilon_mm", t.epsilon_mm, "the centring tolerance")?;
    if t.max_iterations == 0 {
        return Err(c.fail("trical", "max_iterations", 0, "must be >= 1"));
    }
    c.non_negative("trical", "wait_s", t.wait_s, "time")?;
    c.non_negative("trical", "correction_move_s", t.correction_move_s, "time")?;
    c.non_negative("trical", "approach_move_s", t.approach_move_s, "time")?;
    c.non_negative("trical", "cmm_sigma_um", t.cmm_sigma_um, "CMM noise")?;

    let tr = &f.tracker;
    c.positive("tracker", "distance_from_sphere3_mm", tr.distance_from_sphere3_mm, "placement")?;
    for (k, v) in [
        ("range_sigma_um", tr.range_sigma_um),
        ("range_sigma_um_per_m", tr.range_sigma_um_per_m),
        ("transverse_sigma_um", tr.transverse_sigma_um),
        ("transverse_sigma_um_per_m", tr.transverse_sigma_um_per_m),
    ] {
        c.non_negative("tracker", k, v, "noise")?;
    }
    c.positive("tracker", "max_range_mm", tr.max_range_mm, "range")?;
    c.within("tracker", "smr_acceptance_deg", tr.smr_acceptance_deg, 0.0, 90.0, "SMR acceptance half-angle")?;
    if tr.registration_samples == 0 {
        return Err(c.fail("tracker", "registration_samples", 0, "must be >= 1"));
    }

    let cp = &f.campaign;
    if cp.pool_per_sphere == 0 {
        return Err(c.fail("campaign", "pool_per_sphere", 0, "must be >= 1"));
    }
    c.within("campaign", "approach_cone_deg", cp.approach_cone_deg, 0.0, 90.0, "half-angle around the vertical")?;
    if cp.validation_poses == 0 {
        return Err(c.fail("campaign", "validation_poses", 0, "must be >= 1"));
    }
    c.within("campaign", "validation_margin", cp.validation_margin, 0.0, 0.45, "fraction of each joint range")?;
    c.non_negative("campaign", "jog_error_mm", cp.jog_error_mm, "jog distance")?;
    if cp.max_tries_per_configuration == 0 {
        return Err(c.fail("campaign", "max_tries_per_configuration", 0, "must be >= 1"));
    }
    Ok(())
}

/// A scenario of either kind.
#[derive(Clone, Debug)]
pub enum Loaded {
    /// A TriCal study (no `kind` key, or `kind = "trical"`).
    Trical(Box<Scenario>),
    /// An SPMS study (`kind = "spms"`).
    Spms(Box<SpmsScenario>),
}

/// Reads a scenario file once and loads it as the kind its top-level `kind` key names.
pub fn load_any(path: &Path) -> Result<Loaded, ScenarioError> {
    let shown = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| ScenarioError::Read { path: shown.clone(), message: e.to_string() })?;
    let table: toml::Table = toml::from_str(&text).map_err(|e| ScenarioError::Parse { path: shown.clone(), key: position(&text, e.span()), message: e.message().to_string() })?;
    match table.get("kind") {
        None => parse(&text, path).map(|s| Loaded::Trical(Box::new(s))),
        Some(toml::Value::String(k)) if k == "trical" => parse(&text, path).map(|s| Loaded::Trical(Box::new(s))),
        Some(toml::Value::String(k)) if k == "spms" => parse_spms(&text, path).map(|s| Loaded::Spms(Box::new(s))),
        Some(v) => Err(ScenarioError::Parse { path: shown, key: "kind".into(), message: format!("{v} is not a study kind (\"trical\" or \"spms\")") }),
    }
}

/// An SPMS scenario file as written.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SpmsFile {
    #[allow(dead_code)]
    kind: String,
    seed: u64,
    #[serde(default)]
    head: crate::spms::head::HeadSpec,
    #[serde(default)]
    beams: crate::spms::head::BeamIdSpec,
    #[serde(default)]
    robot: crate::spms::calibration::ArmSpec,
    #[serde(default)]
    station: crate::spms::calibration::StationSpec,
    #[serde(default)]
    iso9283: crate::spms::calibration::IsoSpec,
    #[serde(default)]
    study: crate::spms::study::SpmsStudySpec,
    #[serde(default)]
    expect: crate::spms::study::SpmsExpect,
}

/// A loaded, checked SPMS scenario.
#[derive(Clone, Debug)]
pub struct SpmsScenario {
    /// Name (the file stem).
    pub name: String,
    /// Where it was read from.
    pub path: PathBuf,
    /// Its text (hashed into the manifest).
    pub text: String,
    /// Seed of every random stream.
    pub seed: u64,
    /// The study's inputs.
    pub spec: crate::spms::study::SpmsSpec,
    /// Figures to check.
    pub expect: crate::spms::study::SpmsExpect,
}

/// Reads and checks an SPMS scenario file.
pub fn load_spms(path: &Path) -> Result<SpmsScenario, ScenarioError> {
    let shown = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| ScenarioError::Read { path: shown, message: e.to_string() })?;
    parse_spms(&text, path)
}

/// Parses and checks SPMS scenario text; `path` names it in errors.
pub fn parse_spms(text: &str, path: &Path) -> Result<SpmsScenario, ScenarioError> {
    let shown = path.display().to_string();
    let file: SpmsFile = deserialize(text, &shown)?;
    let spec = crate::spms::study::SpmsSpec { head: file.head, beams: file.beams, robot: file.robot, station: file.station, iso9283: file.iso9283, study: file.study };
    check_spms(&spec, &shown)?;
    let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "scenario".into());
    Ok(SpmsScenario { name, path: path.to_path_buf(), text: text.to_string(), seed: file.seed, spec, expect: file.expect })
}

/// Checks an SPMS spec (also after command-line overrides); `path` names it in errors.
pub fn check_spms(f: &crate::spms::study::SpmsSpec, path: &str) -> Result<(), ScenarioError> {
    let c = Checker { path };
    let h = &f.head;
    c.positive("head", "sphere_diameter_mm", h.sphere_diameter_mm, "reference sphere")?;
    c.within("head", "assembly_error_mm", h.assembly_error_mm, 0.0, 5.0, "beam point error")?;
    c.within("head", "assembly_error_deg", h.assembly_error_deg, 0.0, 5.0, "beam direction error")?;
    let s = &h.sensor;
    c.positive("head.sensor", "range_min_mm", s.range_min_mm, "sensor range")?;
    if s.range_max_mm.is_nan() || s.range_max_mm <= s.range_min_mm {
        return Err(c.fail("head.sensor", "range_max_mm", s.range_max_mm, "must be above range_min_mm"));
    }
    c.within("head.sensor", "linearity_pct_fs", s.linearity_pct_fs, 0.0, 5.0, "% of full scale")?;
    c.within("head.sensor", "repeatability_um", s.repeatability_um, 0.0, 1000.0, "one standard deviation")?;
    c.within("head.sensor", "temperature_pct_fs_per_c", s.temperature_pct_fs_per_c, 0.0, 1.0, "% of full scale per degree")?;
    c.within("head.sensor", "temperature_delta_c", s.temperature_delta_c, -50.0, 50.0, "degrees from the identification")?;

    let b = &f.beams;
    // The paper's form has 6K + 3 unknowns and each pose gives K equations.
    if b.poses < 8 {
        return Err(c.fail("beams", "poses", b.poses, "must be >= 8 (6K + 3 unknowns, K equations per pose)"));
    }
    if b.accuracy_samples == 0 {
        return Err(c.fail("beams", "accuracy_samples", 0, "must be >= 1"));
    }
    c.within("beams", "head_tilt_deg", b.head_tilt_deg, 0.0, 45.0, "tilt of the head")?;
    c.within("beams", "sphere_across_mm", b.sphere_across_mm, 0.0, 20.0, "travel across the beams")?;
    c.within("beams", "sphere_along_mm", b.sphere_along_mm, 0.0, 50.0, "travel along the beams")?;
    c.non_negative("beams", "tracker_sigma_um", b.tracker_sigma_um, "tracker noise")?;
    if b.pso_population < 2 || b.pso_iterations == 0 {
        return Err(c.fail("beams", "pso_population / pso_iterations", format!("{} / {}", b.pso_population, b.pso_iterations), "need a population >= 2 and >= 1 iteration"));
    }
    c.positive("beams", "pso_half_width_mm", b.pso_half_width_mm, "search box")?;
    c.positive("beams", "pso_half_width_dir", b.pso_half_width_dir, "search box")?;
    c.positive("beams", "pso_half_width_centre_mm", b.pso_half_width_centre_mm, "search box")?;
    c.non_negative("beams", "rough_centre_error_mm", b.rough_centre_error_mm, "start error")?;
    c.positive("beams", "lm_tau", b.lm_tau, "LM damping")?;
    if b.lm_max_iterations == 0 {
        return Err(c.fail("beams", "lm_max_iterations", 0, "must be >= 1"));
    }
    if b.form().is_none() {
        return Err(c.fail("beams", "calibration_form", &b.calibration_form, "must be \"paper\" or \"minimal\""));
    }

    let r = &f.robot;
    if r.truth_model().is_none() {
        return Err(c.fail("robot", "truth", &r.truth, "must be \"table5_without_dtheta2\", \"table5\" or \"table4\""));
    }
    c.within("robot", "sphere_flange_error_mm", r.sphere_flange_error_mm, 0.0, 10.0, "tool error")?;
    c.within("robot", "repeatability_mm", r.repeatability_mm, 0.0, 1.0, "ISO 9283 RP")?;
    c.unmodelled(&r.unmodelled)?;

    let st = &f.station;
    if st.sphere_points_base_mm.is_empty() {
        return Err(c.fail("station", "sphere_points_base_mm", "[]", "needs at least one station"));
    }
    for p in &st.sphere_points_base_mm {
        if p[0].hypot(p[1]) < 300.0 {
            return Err(c.fail("station", "sphere_points_base_mm", format!("{p:?}"), "a station must stand at least 300 mm from the base axis"));
        }
    }
    c.within("station", "placement_error_mm", st.placement_error_mm, 0.0, 50.0, "placement")?;
    c.within("station", "placement_error_deg", st.placement_error_deg, 0.0, 10.0, "placement")?;
    c.non_negative("station", "tracker_sigma_um", st.tracker_sigma_um, "tracker noise")?;
    c.within("station", "approach_cone_deg", st.approach_cone_deg, 0.0, 80.0, "half-angle")?;
    c.within("station", "spin_deg", st.spin_deg, 0.0, 180.0, "rotation about the flange axis")?;
    for v in st.sphere_travel_mm {
        c.within("station", "sphere_travel_mm", v, 0.0, 30.0, "travel in the head")?;
    }
    let sd = &f.study;
    let m = sd.parameter_set().map_err(|e| c.fail("study", "parameters", format!("{:?}", sd.parameters.clone().unwrap_or_default()), &e.to_string()))?.len();
    if sd.set_sizes.is_empty() {
        return Err(c.fail("study", "set_sizes", "[]", "needs at least one set size"));
    }
    for &n in &sd.set_sizes {
        if (n as usize) * 3 < m || n as usize > st.pool {
            return Err(c.fail("study", "set_sizes", n, &format!("each size must give at least {m} equations (3 per configuration) and not exceed the pool of {}", st.pool)));
        }
    }
    if sd.repetitions == 0 {
        return Err(c.fail("study", "repetitions", 0, "must be >= 1"));
    }
    if !sd.set_sizes.contains(&sd.table_set_size) {
        return Err(c.fail("study", "table_set_size", sd.table_set_size, "must be one of set_sizes"));
    }
    if let Err(bad) = sd.parsed_selections() {
        return Err(c.fail("study", "selections", bad, "must be \"random\" or \"detmax\""));
    }
    if sd.selections.is_empty() {
        return Err(c.fail("study", "selections", "[]", "needs at least one selection"));
    }
    c.within("study", "detmax_max_excursion", sd.detmax_max_excursion as f64, 1.0, 10.0, "excursion length")?;
    c.within("study", "rank_rtol", sd.rank_rtol, 1e-7, 0.1, "relative singular-value threshold")?;

    let iso = &f.iso9283;
    c.positive("iso9283", "cube_mm", iso.cube_mm, "cube side")?;
    c.within("iso9283", "corner_fraction", iso.corner_fraction, 0.0, 0.5, "fraction of the diagonal")?;
    if iso.cycles == 0 {
        return Err(c.fail("iso9283", "cycles", 0, "must be >= 1"));
    }
    c.non_negative("iso9283", "tracker_sigma_um", iso.tracker_sigma_um, "tracker noise")?;
    Ok(())
}
