//! The TriCal scenario file: its sections (`[robot]`, `[cell]`, `[trical]`, `[tracker]`,
//! `[campaign]`, the common `[study]`, `[expect]`) and the checks of every key.

use std::path::Path;

use serde::Deserialize;

use super::campaign::CampaignSpec;
use super::experiment::{ExperimentSpec, RobotSpec};
use super::figures::ExpectSpec;
use crate::cell::CellSpec;
use crate::device::scenario::{Checker, Header, ScenarioError, deserialize, load_arm, sets_repeatability, table, twin};
use crate::instrument::laser_tracker::LaserTrackerSpec;
use crate::instrument::trical::TriCalSpec;
use crate::study::StudySpec;

/// The largest repeatability a scenario's robot takes, mm (its own key's or a twin's).
const MOST_REPEATABILITY_MM: f64 = 1.0;

/// A scenario file as written.
#[derive(Clone, Debug, Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
struct ScenarioFile {
    /// `"trical"` or absent (checked by [`crate::device::device_of`]).
    #[serde(default)]
    #[allow(dead_code)]
    kind: Option<String>,
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

/// The notes of the keys of a TriCal scenario (SOURCED / ASSUMED / FITTED), for `calsim keys`.
pub const NOTES: &str = include_str!("keys.toml");

/// A TriCal scenario with every key at its default, as TOML.
pub fn defaults() -> toml::Table {
    let text = crate::device::keys::minimal("trical");
    let file: ScenarioFile = deserialize(table(&text, "defaults").expect("TOML"), "defaults").expect("the defaults deserialize");
    toml::Table::try_from(&file).expect("a scenario serializes")
}

/// A loaded, checked TriCal scenario.
#[derive(Clone, Debug)]
pub struct TricalScenario {
    /// Name, path, text and seed.
    pub header: Header,
    /// The virtual experiment.
    pub experiment: ExperimentSpec,
    /// The study.
    pub study: StudySpec,
    /// Figures to check.
    pub expect: ExpectSpec,
}

/// Reads and checks a TriCal scenario file (a file of another kind is refused, naming `kind`).
pub fn load(path: &Path) -> Result<TricalScenario, ScenarioError> {
    crate::io::names::of_file(path)?;
    let shown = path.display().to_string();
    let text = crate::io::read_text(path).map_err(|e| ScenarioError::Read { path: shown.clone(), message: e.to_string() })?;
    parse(&text, path)
}

/// Parses and checks TriCal scenario text; `path` names it in errors.
pub fn parse(text: &str, path: &Path) -> Result<TricalScenario, ScenarioError> {
    let t = table(text, &path.display().to_string())?;
    let device = crate::device::device_of(&t, path)?;
    if device.kind() != "trical" {
        return Err(ScenarioError::Parse {
            path: path.display().to_string(),
            key: "kind".into(),
            message: format!("\"{}\": a TriCal scenario is needed here", device.kind()),
        });
    }
    parse_table(text, t, path)
}

/// Loads and checks a TriCal scenario from its TOML table.
pub fn parse_table(text: &str, t: toml::Table, path: &Path) -> Result<TricalScenario, ScenarioError> {
    let shown = path.display().to_string();
    let sets_rp = sets_repeatability(&t);
    let mut file: ScenarioFile = deserialize(t, &shown)?;
    file.robot.arm = load_arm(path, file.robot.file.as_deref())?;
    if let Some(crate::robot::file::Arm(arm)) = &file.robot.arm
        && arm.capsules.is_none()
    {
        return Err(ScenarioError::Parse {
            path: shown,
            key: "robot.file".into(),
            message: format!(
                "{}: collision: no [[collision]] capsules; a TriCal campaign tests every configuration against the links' shapes",
                arm.path.display()
            ),
        });
    }
    check(&file, &shown)?;
    let (learned, repeatability) = twin(sets_rp, file.robot.arm.as_ref(), file.robot.learned_scale, MOST_REPEATABILITY_MM, &shown)?;
    file.robot.learned = learned;
    if let Some(rp) = repeatability {
        file.robot.repeatability_mm = rp;
    }
    Ok(TricalScenario {
        header: Header::new(path, text, file.seed),
        experiment: ExperimentSpec {
            robot: file.robot,
            cell: file.cell,
            trical: file.trical,
            tracker: file.tracker,
            campaign: file.campaign,
        },
        study: file.study,
        expect: file.expect,
    })
}

/// Checks a scenario again after command-line overrides; `path` names it in errors.
pub fn check_overrides(s: &TricalScenario, path: &str) -> Result<(), ScenarioError> {
    let file = ScenarioFile {
        kind: None,
        seed: s.header.seed,
        study: s.study.clone(),
        robot: s.experiment.robot.clone(),
        cell: s.experiment.cell.clone(),
        trical: s.experiment.trical.clone(),
        tracker: s.experiment.tracker.clone(),
        campaign: s.experiment.campaign.clone(),
        expect: s.expect.clone(),
    };
    check(&file, path)
}

/// Checks a TriCal scenario file.
///
/// Long by design: one line per key of the scenario, section by section, as the file reads.
fn check(f: &ScenarioFile, path: &str) -> Result<(), ScenarioError> {
    let c = Checker { path };
    let r = &f.robot;
    c.within("robot", "repeatability_mm", r.repeatability_mm, 0.0, MOST_REPEATABILITY_MM, "ISO 9283 RP")?;
    c.within("robot", "learned_scale", r.learned_scale, 0.0, 100.0, "factor on a twin's learned effects")?;
    c.within("robot", "payload_kg", r.payload_kg, 0.0, 3.0, "device mass; the IRB 120 carries 3 kg")?;
    c.within_optional(
        "robot",
        "validation_payload_change_kg",
        r.validation_payload_change_kg,
        -r.payload_kg,
        3.0 - r.payload_kg,
        "setup 2's mass on the flange within 0-3 kg",
    )?;
    for (k, v) in r.tcp_mm.iter().enumerate() {
        c.within("robot", &format!("tcp_mm[{k}]"), *v, -500.0, 500.0, "TCP in the flange frame")?;
    }
    for (k, v) in r.payload_com_mm.iter().enumerate() {
        c.within("robot", &format!("payload_com_mm[{k}]"), *v, -500.0, 500.0, "centre of mass in the flange frame")?;
    }
    for (k, v) in r.repeatability_reference_q_deg.iter().enumerate() {
        c.within("robot", &format!("repeatability_reference_q_deg[{k}]"), *v, -400.0, 400.0, "joint angle")?;
    }
    for k in 0..6 {
        let (lo, hi) = if k < 3 { (-5000.0, 5000.0) } else { (-360.0, 360.0) };
        let v = r.nominal_base_mm_deg.map(|base| base[k]);
        c.within_optional("robot", &format!("nominal_base_mm_deg[{k}]"), v, lo, hi, "x, y, z in mm then alpha, beta, gamma in deg")?;
    }
    c.unmodelled(&r.unmodelled)?;
    c.spread(&r.spread)?;

    let cell = &f.cell;
    let n = cell.spheres_w_mm.len();
    c.require("cell", "spheres_w_mm", (3..=12).contains(&n), n, "three to twelve datum spheres (the first three define {W})")?;
    let p = &cell.spheres_w_mm;
    let frame_ok = p[0] == [0.0, 0.0, 0.0] && p[1][1] == 0.0 && p[1][2] == 0.0 && p[1][0] > 0.0 && p[2][2] == 0.0 && p[2][1] > 0.0;
    c.require(
        "cell",
        "spheres_w_mm",
        frame_ok,
        format!("{:?}", &p[..3]),
        "the first three define {W} (eqs. 1-5): [0,0,0], then [d12,0,0] with d12 > 0, then [x,y,0] with y > 0",
    )?;
    c.within("cell", "ball_diameter_mm", cell.ball_diameter_mm, 1.0, 100.0, "datum ball")?;
    for (i, a) in p.iter().enumerate() {
        for (k, v) in a.iter().enumerate() {
            c.within("cell", &format!("spheres_w_mm[{i}][{k}]"), *v, -2000.0, 2000.0, "sphere centre in {W}, within the robot's reach")?;
        }
        for (j, b) in p.iter().enumerate().take(i) {
            c.rule("cell", "spheres_w_mm", "datum spheres on their risers at least two ball diameters plus a riser apart");
            let d = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
            if d < 2.0 * cell.ball_diameter_mm + 2.0 * cell.riser_radius_mm {
                return Err(c.fail(
                    "cell",
                    "spheres_w_mm",
                    format!("{:?} and {:?}", b, a),
                    &format!(
                        "spheres {} and {} are {d:.1} mm apart: datum spheres on their risers need at least two ball \
                         diameters plus a riser between them",
                        j + 1,
                        i + 1
                    ),
                ));
            }
        }
    }
    c.within("cell", "ball_diameter_tolerance_um", cell.ball_diameter_tolerance_um, 0.0, 100.0, "tolerance")?;
    c.within("cell", "riser_height_mm", cell.riser_height_mm, 1.0, 1000.0, "riser")?;
    c.within("cell", "riser_radius_mm", cell.riser_radius_mm, 0.5, 100.0, "riser")?;
    c.within("cell", "plate_thickness_mm", cell.plate_thickness_mm, 1.0, 200.0, "plate")?;
    c.within("cell", "plate_margin_mm", cell.plate_margin_mm, 0.0, 500.0, "plate")?;
    c.within("cell", "ballbar_sigma_um", cell.ballbar_sigma_um, 0.0, 1000.0, "ballbar noise")?;
    c.within("cell", "table_z_base_mm", cell.table_z_base_mm, -2000.0, 0.0, "table height below the base")?;
    for (k, v) in cell.plate_offset_mm_deg.iter().enumerate() {
        let (lo, hi, what) = if k < 3 { (-2000.0, 2000.0, "plate displacement, mm") } else { (-90.0, 90.0, "plate rotation, deg") };
        c.within("cell", &format!("plate_offset_mm_deg[{k}]"), *v, lo, hi, what)?;
    }

    let t = &f.trical;
    c.within("trical", "indicator_accuracy_um", t.indicator_accuracy_um, 0.0, 1000.0, "indicator")?;
    c.within("trical", "indicator_resolution_um", t.indicator_resolution_um, 0.0, 1000.0, "indicator")?;
    c.within("trical", "indicator_misalignment_deg", t.indicator_misalignment_deg, 0.0, 10.0, "axis tilt")?;
    c.within("trical", "indicator_range_mm", t.indicator_range_mm, 0.1, 100.0, "stroke")?;
    c.within("trical", "tip_radius_mm", t.tip_radius_mm, 0.0, 10.0, "contact tip")?;
    c.within(
        "trical",
        "epsilon_mm",
        t.epsilon_mm,
        1e-4,
        0.5,
        "the centring tolerance: the paper uses 0.010 mm; above 0.5 mm the device no longer centres",
    )?;
    c.count("trical", "max_iterations", t.max_iterations.into(), 1, 1000, "centring iterations")?;
    c.within("trical", "wait_s", t.wait_s, 0.0, 3600.0, "time")?;
    c.within("trical", "correction_move_s", t.correction_move_s, 0.0, 3600.0, "time")?;
    c.within("trical", "approach_move_s", t.approach_move_s, 0.0, 3600.0, "time")?;
    c.within("trical", "cmm_sigma_um", t.cmm_sigma_um, 0.0, 1000.0, "CMM noise")?;

    let tr = &f.tracker;
    c.within("tracker", "distance_from_sphere3_mm", tr.distance_from_sphere3_mm, 100.0, 20_000.0, "placement")?;
    c.within("tracker", "height_above_spheres_mm", tr.height_above_spheres_mm, -2000.0, 5000.0, "placement")?;
    for (k, v) in [
        ("range_sigma_um", tr.range_sigma_um),
        ("range_sigma_um_per_m", tr.range_sigma_um_per_m),
        ("transverse_sigma_um", tr.transverse_sigma_um),
        ("transverse_sigma_um_per_m", tr.transverse_sigma_um_per_m),
    ] {
        c.within("tracker", k, v, 0.0, 10_000.0, "noise")?;
    }
    c.within("tracker", "max_range_mm", tr.max_range_mm, 100.0, 100_000.0, "range")?;
    c.within("tracker", "smr_acceptance_deg", tr.smr_acceptance_deg, 0.0, 90.0, "SMR acceptance half-angle")?;
    c.count("tracker", "registration_samples", tr.registration_samples.into(), 1, 10_000, "samples per nest")?;

    let cp = &f.campaign;
    c.count("campaign", "pool_per_sphere", cp.pool_per_sphere.into(), 1, 10_000, "identification configurations per datum sphere")?;
    c.within("campaign", "approach_cone_deg", cp.approach_cone_deg, 0.0, 90.0, "half-angle around the vertical")?;
    c.count("campaign", "validation_poses", cp.validation_poses.into(), 1, 100_000, "validation configurations")?;
    c.within("campaign", "validation_margin", cp.validation_margin, 0.0, 0.45, "fraction of each joint range")?;
    c.count(
        "campaign",
        "tcp_check_configurations",
        cp.tcp_check_configurations.into(),
        2,
        100,
        "the TCP check needs two orientations at least",
    )?;
    c.within("campaign", "jog_error_mm", cp.jog_error_mm, 0.0, 5.0, "jog distance: the indicators must touch the ball")?;
    c.count("campaign", "max_tries_per_configuration", cp.max_tries_per_configuration.into(), 1, 100_000, "tries per kept configuration")?;

    centring_plausible(&c, t, cp)?;

    let pool = cp.pool_per_sphere as usize * cell.spheres_w_mm.len();
    c.study(&f.study, pool, crate::robot::ParamSet::trical_31)?;
    let set = f.study.parameter_set(crate::robot::ParamSet::trical_31).expect("checked by study()");
    let spec = ExperimentSpec { robot: r.clone(), cell: cell.clone(), trical: t.clone(), tracker: tr.clone(), campaign: cp.clone() };
    c.identifiable(&spec.nominal(), &set, "robot.tcp_mm")?;
    expect(&c, &f.expect)
}

/// The keys of the centring that only make sense together: epsilon against what the indicators
/// can show (their resolution) and hold (half their stroke: they are zeroed at mid-stroke), and the
/// first contact's error against that half stroke. Each error names both keys.
fn centring_plausible(c: &Checker<'_>, t: &TriCalSpec, cp: &CampaignSpec) -> Result<(), ScenarioError> {
    let half_stroke = t.indicator_range_mm / 2.0;
    if t.epsilon_mm * 1e3 < t.indicator_resolution_um {
        return Err(c.fail(
            "trical",
            "epsilon_mm",
            t.epsilon_mm,
            &format!(
                "below [trical] indicator_resolution_um = {} (the indicators show steps of {} mm): the tolerance must be one \
                 they can see",
                t.indicator_resolution_um,
                t.indicator_resolution_um * 1e-3
            ),
        ));
    }
    if t.epsilon_mm >= half_stroke {
        return Err(c.fail(
            "trical",
            "epsilon_mm",
            t.epsilon_mm,
            &format!(
                "not below half of [trical] indicator_range_mm = {} (zeroed at mid-stroke, an indicator reads at most {half_stroke} mm)",
                t.indicator_range_mm
            ),
        ));
    }
    if cp.jog_error_mm >= half_stroke {
        return Err(c.fail(
            "campaign",
            "jog_error_mm",
            cp.jog_error_mm,
            &format!(
                "not below half of [trical] indicator_range_mm = {} (the first contact must lie within the indicators' {half_stroke} mm)",
                t.indicator_range_mm
            ),
        ));
    }
    Ok(())
}

/// The `[expect]` table of a TriCal scenario.
fn expect(c: &Checker<'_>, e: &ExpectSpec) -> Result<(), ScenarioError> {
    for (k, b) in [
        ("before_mean_mm", &e.before_mean_mm),
        ("before_max_mm", &e.before_max_mm),
        ("after_median_mm", &e.after_median_mm),
        ("after_std_mm", &e.after_std_mm),
        ("after_max_mm", &e.after_max_mm),
        ("table8_tracker_median_mm", &e.table8_tracker_median_mm),
        ("table8_cmm_median_mm", &e.table8_cmm_median_mm),
    ] {
        c.band(k, b)?;
    }
    c.bound("table7_std_within_factor3_min", e.table7_std_within_factor3_min.map(f64::from), 0.0, 31.0)?;
    c.bound("table7_mean_within_3std_min", e.table7_mean_within_3std_min.map(f64::from), 0.0, 31.0)?;
    c.bound("table7_compliance_signs_min", e.table7_compliance_signs_min.map(f64::from), 0.0, 5.0)?;
    c.bound("table7_offsets_near_published_min", e.table7_offsets_near_published_min.map(f64::from), 0.0, 5.0)?;
    c.bound("fig8_max_rise", e.fig8_max_rise, -1.0, 10.0)?;
    c.bound("fig9_spread_ratio_min", e.fig9_spread_ratio_min, 0.0, 1000.0)?;
    c.bound("fig12_abs_r_max", e.fig12_abs_r_max, 0.0, 1.0)
}
