//! The SPMS scenario file (`kind = "spms"`): the head, the beam identification, the robot, the
//! stations, the ISO 9283 test, the common `[study]` (with the SPMS defaults) and `[expect]`.

use std::path::Path;

use serde::Deserialize;

use crate::device::scenario::{Checker, Header, ScenarioError, deserialize, load_arm, sets_repeatability, table, twin, with_defaults};
use crate::study::StudySpec;

/// The largest repeatability a scenario's robot takes, mm (its own key's or a twin's).
const MOST_REPEATABILITY_MM: f64 = 1.0;

/// An SPMS scenario file as written.
#[derive(Clone, Debug, Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
struct SpmsFile {
    #[allow(dead_code)]
    kind: String,
    seed: u64,
    #[serde(default)]
    head: super::head::HeadSpec,
    #[serde(default)]
    beams: super::head::BeamIdSpec,
    #[serde(default)]
    robot: super::calibration::ArmSpec,
    #[serde(default)]
    station: super::calibration::StationSpec,
    #[serde(default)]
    iso9283: super::calibration::IsoSpec,
    #[serde(default)]
    study: StudySpec,
    #[serde(default)]
    expect: super::study::SpmsExpect,
}

/// The notes of the keys of an SPMS scenario (SOURCED / ASSUMED / FITTED), for `calsim keys`.
pub const NOTES: &str = include_str!("keys.toml");

/// An SPMS scenario with every key at its default (the SPMS `[study]` defaults included), as TOML.
pub fn defaults() -> toml::Table {
    let t = table(&crate::device::keys::minimal("spms"), "defaults").expect("TOML");
    let file: SpmsFile =
        deserialize(with_defaults(t, "study", super::study::STUDY_DEFAULTS), "defaults").expect("the defaults deserialize");
    toml::Table::try_from(&file).expect("a scenario serializes")
}

/// A loaded, checked SPMS scenario.
#[derive(Clone, Debug)]
pub struct SpmsScenario {
    /// Name, path, text and seed.
    pub header: Header,
    /// The study's inputs.
    pub spec: super::study::SpmsSpec,
    /// Figures to check.
    pub expect: super::study::SpmsExpect,
}

/// Reads and checks an SPMS scenario file.
pub fn load(path: &Path) -> Result<SpmsScenario, ScenarioError> {
    crate::io::names::of_file(path)?;
    let shown = path.display().to_string();
    let text = crate::io::read_text(path).map_err(|e| ScenarioError::Read { path: shown, message: e.to_string() })?;
    parse(&text, path)
}

/// Parses and checks SPMS scenario text; `path` names it in errors.
pub fn parse(text: &str, path: &Path) -> Result<SpmsScenario, ScenarioError> {
    parse_table(text, table(text, &path.display().to_string())?, path)
}

/// Loads and checks an SPMS scenario from its TOML table.
pub fn parse_table(text: &str, t: toml::Table, path: &Path) -> Result<SpmsScenario, ScenarioError> {
    let shown = path.display().to_string();
    let sets_rp = sets_repeatability(&t);
    let mut file: SpmsFile = deserialize(with_defaults(t, "study", super::study::STUDY_DEFAULTS), &shown)?;
    file.robot.arm = load_arm(path, file.robot.file.as_deref())?;
    let spec = super::study::SpmsSpec {
        head: file.head,
        beams: file.beams,
        robot: file.robot,
        station: file.station,
        iso9283: file.iso9283,
        study: file.study,
    };
    check(&spec, &shown)?;
    expect(&Checker { path: &shown }, &file.expect)?;
    let (learned, repeatability) = twin(sets_rp, spec.robot.arm.as_ref(), spec.robot.learned_scale, MOST_REPEATABILITY_MM, &shown)?;
    let mut spec = spec;
    spec.robot.learned = learned;
    if let Some(rp) = repeatability {
        spec.robot.repeatability_mm = rp;
    }
    Ok(SpmsScenario { header: Header::new(path, text, file.seed), spec, expect: file.expect })
}

/// Checks an SPMS spec (also after command-line overrides); `path` names it in errors.
///
/// Long by design: one line per key of the scenario, section by section, as the file reads.
pub fn check(f: &super::study::SpmsSpec, path: &str) -> Result<(), ScenarioError> {
    let c = Checker { path };
    let h = &f.head;
    c.within("head", "sphere_diameter_mm", h.sphere_diameter_mm, 5.0, 200.0, "reference sphere")?;
    c.within("head", "assembly_error_mm", h.assembly_error_mm, 0.0, 5.0, "beam point error")?;
    c.within("head", "assembly_error_deg", h.assembly_error_deg, 0.0, 5.0, "beam direction error")?;
    let s = &h.sensor;
    c.within("head.sensor", "range_min_mm", s.range_min_mm, 1.0, 1000.0, "sensor range")?;
    c.within("head.sensor", "range_max_mm", s.range_max_mm, s.range_min_mm + 1.0, 2000.0, "above range_min_mm")?;
    c.within("head.sensor", "linearity_pct_fs", s.linearity_pct_fs, 0.0, 5.0, "% of full scale")?;
    c.within("head.sensor", "repeatability_um", s.repeatability_um, 0.0, 1000.0, "one standard deviation")?;
    c.within("head.sensor", "temperature_pct_fs_per_c", s.temperature_pct_fs_per_c, 0.0, 1.0, "% of full scale per degree")?;
    c.within("head.sensor", "temperature_delta_c", s.temperature_delta_c, -50.0, 50.0, "degrees from the identification")?;

    let b = &f.beams;
    // The paper's form has 6K + 3 unknowns and each pose gives K equations.
    c.count("beams", "poses", b.poses as u64, 8, 10_000, "6K + 3 unknowns, K equations per pose")?;
    c.count("beams", "accuracy_samples", b.accuracy_samples as u64, 1, 100_000, "accuracy measurements")?;
    c.within("beams", "head_tilt_deg", b.head_tilt_deg, 0.0, 45.0, "tilt of the head")?;
    c.within("beams", "sphere_across_mm", b.sphere_across_mm, 0.0, 20.0, "travel across the beams")?;
    c.within("beams", "sphere_along_mm", b.sphere_along_mm, 0.0, 50.0, "travel along the beams")?;
    for (k, v) in b.sphere_centre_head_mm.iter().enumerate() {
        c.within("beams", &format!("sphere_centre_head_mm[{k}]"), *v, -1000.0, 1000.0, "sphere centre in the head frame")?;
    }
    c.within("beams", "tracker_sigma_um", b.tracker_sigma_um, 0.0, 1000.0, "tracker noise")?;
    c.count("beams", "pso_population", b.pso_population as u64, 2, 100_000, "particles")?;
    c.count("beams", "pso_iterations", b.pso_iterations as u64, 1, 10_000, "iterations")?;
    let evaluations = b.pso_population as u64 * b.pso_iterations as u64;
    c.require(
        "beams",
        "pso_iterations",
        evaluations <= 100_000_000,
        b.pso_iterations,
        "at most 1e8 swarm evaluations (pso_population x pso_iterations)",
    )?;
    c.within("beams", "pso_half_width_mm", b.pso_half_width_mm, 1e-6, 100.0, "search box")?;
    c.within("beams", "pso_half_width_dir", b.pso_half_width_dir, 1e-9, 1.0, "search box")?;
    c.within("beams", "pso_half_width_centre_mm", b.pso_half_width_centre_mm, 1e-6, 100.0, "search box")?;
    c.within("beams", "rough_centre_error_mm", b.rough_centre_error_mm, 0.0, 50.0, "start error")?;
    c.within("beams", "lm_tau", b.lm_tau, 1e-15, 1e3, "LM damping")?;
    c.count("beams", "lm_max_iterations", b.lm_max_iterations as u64, 1, 100_000, "LM iterations")?;

    let r = &f.robot;
    for (k, v) in r.sphere_flange_mm.iter().enumerate() {
        c.within("robot", &format!("sphere_flange_mm[{k}]"), *v, -500.0, 500.0, "sphere centre in the flange frame")?;
    }
    c.within("robot", "sphere_flange_error_mm", r.sphere_flange_error_mm, 0.0, 10.0, "tool error")?;
    c.within("robot", "repeatability_mm", r.repeatability_mm, 0.0, MOST_REPEATABILITY_MM, "ISO 9283 RP")?;
    c.within("robot", "learned_scale", r.learned_scale, 0.0, 100.0, "factor on a twin's learned effects")?;
    for (k, v) in r.repeatability_reference_q_deg.iter().enumerate() {
        c.within("robot", &format!("repeatability_reference_q_deg[{k}]"), *v, -400.0, 400.0, "joint angle")?;
    }
    c.unmodelled(&r.unmodelled)?;
    c.spread(&r.spread)?;

    let st = &f.station;
    let n = st.sphere_points_base_mm.len();
    c.require("station", "sphere_points_base_mm", (1..=20).contains(&n), n, "one to twenty stations")?;
    for (i, p) in st.sphere_points_base_mm.iter().enumerate() {
        for (k, v) in p.iter().enumerate() {
            c.within("station", &format!("sphere_points_base_mm[{i}][{k}]"), *v, -3000.0, 3000.0, "within the ER20-C10's reach")?;
        }
        let why = "a station must stand at least 300 mm from the base axis";
        c.require("station", "sphere_points_base_mm", p[0].hypot(p[1]) >= 300.0, format!("{p:?}"), why)?;
    }
    for (k, v) in st.sphere_centre_head_mm.iter().enumerate() {
        c.within("station", &format!("sphere_centre_head_mm[{k}]"), *v, -1000.0, 1000.0, "sphere centre in the head frame")?;
    }
    c.within("station", "placement_error_mm", st.placement_error_mm, 0.0, 50.0, "placement")?;
    c.within("station", "placement_error_deg", st.placement_error_deg, 0.0, 10.0, "placement")?;
    c.within("station", "tracker_sigma_um", st.tracker_sigma_um, 0.0, 1000.0, "tracker noise")?;
    c.within("station", "approach_cone_deg", st.approach_cone_deg, 0.0, 80.0, "half-angle")?;
    c.within("station", "spin_deg", st.spin_deg, 0.0, 180.0, "rotation about the flange axis")?;
    for (k, v) in st.sphere_travel_mm.iter().enumerate() {
        c.within("station", &format!("sphere_travel_mm[{k}]"), *v, 0.0, 30.0, "travel in the head")?;
    }
    c.count("station", "pool", st.pool as u64, 1, 100_000, "candidate configurations")?;

    let iso = &f.iso9283;
    for (k, v) in iso.cube_centre_base_mm.iter().enumerate() {
        c.within("iso9283", &format!("cube_centre_base_mm[{k}]"), *v, -3000.0, 3000.0, "within the ER20-C10's reach")?;
    }
    c.within("iso9283", "cube_mm", iso.cube_mm, 1.0, 2000.0, "cube side")?;
    c.within("iso9283", "corner_fraction", iso.corner_fraction, 0.0, 0.5, "fraction of the diagonal")?;
    c.count("iso9283", "cycles", iso.cycles as u64, 1, 10_000, "cycles")?;
    c.within("iso9283", "tracker_sigma_um", iso.tracker_sigma_um, 0.0, 1000.0, "tracker noise")?;

    c.study(&f.study, st.pool, super::calibration::default_parameters)?;
    let set = f.study.parameter_set(super::calibration::default_parameters).expect("checked by study()");
    let tool = nalgebra::Vector3::from(r.sphere_flange_mm);
    let nominal = f.robot.nominal_model().edited(|d| d.flange_tcp_mm = tool).expect("a finite tool");
    c.identifiable(&nominal, &set, "robot.sphere_flange_mm")
}

/// The `[expect]` table of an SPMS scenario.
fn expect(c: &Checker<'_>, e: &super::study::SpmsExpect) -> Result<(), ScenarioError> {
    for (k, b) in [
        ("measuring_max_mm", &e.measuring_max_mm),
        ("measuring_mean_mm", &e.measuring_mean_mm),
        ("measuring_rms_mm", &e.measuring_rms_mm),
        ("ap_before_max_mm", &e.ap_before_max_mm),
        ("ap_before_mean_mm", &e.ap_before_mean_mm),
        ("ap_before_rms_mm", &e.ap_before_rms_mm),
        ("ap_after_max_mm", &e.ap_after_max_mm),
        ("ap_after_mean_mm", &e.ap_after_mean_mm),
        ("ap_after_rms_mm", &e.ap_after_rms_mm),
    ] {
        c.band(k, b)?;
    }
    c.bound("fit_residual_below_003_min", e.fit_residual_below_003_min, 0.0, 1.0)
}
