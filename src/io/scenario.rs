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
use crate::study::check::Band;
use crate::study::figures::ExpectSpec;

/// A scenario file as written.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ScenarioFile {
    /// `"trical"` or absent (checked by [`load_any`]).
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
    let text = crate::io::read_text(path).map_err(|e| ScenarioError::Read { path: shown.clone(), message: e.to_string() })?;
    parse(&text, path)
}

/// Parses and checks scenario text; `path` names it in errors.
pub fn parse(text: &str, path: &Path) -> Result<Scenario, ScenarioError> {
    parse_table(text, table(text, &path.display().to_string())?, path)
}

fn parse_table(text: &str, t: toml::Table, path: &Path) -> Result<Scenario, ScenarioError> {
    let shown = path.display().to_string();
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
    let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "scenario".into());
    Ok(Scenario {
        name,
        path: path.to_path_buf(),
        text: text.to_string(),
        seed: file.seed,
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

/// Checks a scenario again after command-line overrides.
pub fn check_overrides(s: &Scenario) -> Result<(), ScenarioError> {
    let file = ScenarioFile {
        kind: None,
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

/// Parses scenario text into its TOML table, naming the line of a syntax error.
fn table(text: &str, shown: &str) -> Result<toml::Table, ScenarioError> {
    toml::from_str(text).map_err(|e: toml::de::Error| ScenarioError::Parse {
        path: shown.into(),
        key: position(text, e.span()),
        message: e.message().to_string(),
    })
}

/// Refuses a non-finite float anywhere under `v`, naming its dotted key (`cell.spheres_w_mm[3][0]`).
fn finite(v: &toml::Value, path: &mut Vec<String>, shown: &str) -> Result<(), ScenarioError> {
    match v {
        toml::Value::Float(x) if !x.is_finite() => {
            let (key, section) = path.split_last().map(|(k, s)| (k.clone(), s.join("."))).unwrap_or_default();
            Err(ScenarioError::Range { path: shown.into(), section, key, value: x.to_string(), why: "must be a finite number".into() })
        }
        toml::Value::Table(t) => t.iter().try_for_each(|(k, v)| {
            path.push(k.clone());
            let r = finite(v, path, shown);
            path.pop();
            r
        }),
        toml::Value::Array(a) => a.iter().enumerate().try_for_each(|(i, v)| {
            let last = path.pop().unwrap_or_default();
            path.push(format!("{last}[{i}]"));
            let r = finite(v, path, shown);
            path.pop();
            path.push(last);
            r
        }),
        _ => Ok(()),
    }
}

/// Fills the keys of `section` that `t` leaves out from `defaults` (TOML text): how a device gives
/// a common section its own defaults.
fn with_defaults(mut t: toml::Table, section: &str, defaults: &str) -> toml::Table {
    let defaults: toml::Table = toml::from_str(defaults).expect("device defaults are valid TOML");
    let entry = t.entry(section.to_string()).or_insert_with(|| toml::Value::Table(toml::Table::new()));
    if let toml::Value::Table(given) = entry {
        for (k, v) in defaults {
            given.entry(k).or_insert(v);
        }
    }
    t
}

/// Deserializes a scenario table, naming the offending key in the error. Every number in it must be
/// finite first (TOML allows `nan` and `inf`, which no key of calsim takes).
fn deserialize<T: serde::de::DeserializeOwned>(t: toml::Table, shown: &str) -> Result<T, ScenarioError> {
    for (k, v) in &t {
        finite(v, &mut vec![k.clone()], shown)?;
    }
    serde_path_to_error::deserialize(toml::Value::Table(t)).map_err(|e| {
        let key = e.path().to_string();
        ScenarioError::Parse {
            path: shown.into(),
            key: if key == "." { "(file)".into() } else { key },
            message: e.into_inner().message().to_string(),
        }
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

    fn non_negative(&self, section: &str, key: &str, v: f64, what: &str) -> Result<(), ScenarioError> {
        if v.is_finite() && v >= 0.0 { Ok(()) } else { Err(self.fail(section, key, v, &format!("must be >= 0 ({what})"))) }
    }

    /// The `[robot.spread]` table, the same in both kinds of scenario.
    fn spread(&self, s: &crate::robot::SpreadSpec) -> Result<(), ScenarioError> {
        self.within("robot.spread", "length_mm", s.length_mm, 0.0, 10.0, "one standard deviation of every length")?;
        self.within("robot.spread", "angle_deg", s.angle_deg, 0.0, 5.0, "one standard deviation of every angle")?;
        self.within(
            "robot.spread",
            "compliance_mdeg_per_nm",
            s.compliance_mdeg_per_nm,
            0.0,
            100.0,
            "one standard deviation of every compliance",
        )
    }

    /// The `[robot.unmodelled]` table, the same in both kinds of scenario.
    fn unmodelled(&self, u: &crate::robot::UnmodelledSpec) -> Result<(), ScenarioError> {
        self.non_negative("robot.unmodelled", "transmission_low_mdeg", u.transmission_low_mdeg, "amplitude")?;
        self.non_negative("robot.unmodelled", "transmission_high_mdeg", u.transmission_high_mdeg, "amplitude")?;
        self.non_negative("robot.unmodelled", "backlash_mdeg", u.backlash_mdeg, "backlash width")?;
        self.within("robot.unmodelled", "thermal_drift_ppm", u.thermal_drift_ppm, -1000.0, 1000.0, "link growth")?;
        self.within("robot.unmodelled", "encoder_mdeg", u.encoder_mdeg, 0.0, 1000.0, "amplitude of the encoder error")?;
        if let Some(n) = u.transmission_high_count
            && !(1..=100).contains(&n)
        {
            return Err(self.fail("robot.unmodelled", "transmission_high_count", n, "must be 1 to 100 harmonics per joint"));
        }
        for (key, orders) in [("transmission_high_orders", u.transmission_high_orders), ("encoder_orders", u.encoder_orders)] {
            if let Some([lo, hi]) = orders
                && (lo == 0 || lo > hi || hi > 1_000_000)
            {
                return Err(self.fail(
                    "robot.unmodelled",
                    key,
                    format!("[{lo}, {hi}]"),
                    "must be [min, max] with 1 <= min <= max <= 1000000",
                ));
            }
        }
        Ok(())
    }

    /// The `[study]` table, the same for every device: `pool` configurations to choose from and the
    /// device's default parameter set.
    fn study(&self, s: &StudySpec, pool: usize, default_set: fn() -> crate::robot::ParamSet) -> Result<(), ScenarioError> {
        let set = s
            .parameter_set(default_set)
            .map_err(|e| self.fail("study", "parameters", format!("{:?}", s.parameters.clone().unwrap_or_default()), &e.to_string()))?;
        let m = set.len();
        if m == 0 {
            return Err(self.fail("study", "parameters", "[]", "needs at least one parameter (absent: the device's default set)"));
        }
        if s.set_sizes.is_empty() {
            return Err(self.fail("study", "set_sizes", "[]", "needs at least one set size"));
        }
        if s.set_sizes.len() > crate::study::MAX_SET_SIZES {
            return Err(self.fail("study", "set_sizes", s.set_sizes.len(), &format!("at most {} set sizes", crate::study::MAX_SET_SIZES)));
        }
        for &n in &s.set_sizes {
            if (n as usize) * 3 < m || n as usize >= pool {
                return Err(self.fail(
                    "study",
                    "set_sizes",
                    n,
                    &format!("each size must give at least {m} equations (3 per configuration) and stay below the pool of {pool}"),
                ));
            }
        }
        self.count("study", "repetitions", s.repetitions.into(), 1, crate::study::MAX_REPETITIONS.into(), "identifications per set size")?;
        if !s.set_sizes.contains(&s.table_set_size) {
            return Err(self.fail("study", "table_set_size", s.table_set_size, "must be one of set_sizes"));
        }
        if s.selections.is_empty() || s.selections.len() > 2 {
            return Err(self.fail("study", "selections", format!("{:?}", s.selections), "needs one or both of \"random\" and \"detmax\""));
        }
        let tasks = s.selections.len() as u64 * s.set_sizes.len() as u64 * u64::from(s.repetitions);
        if tasks > crate::study::MAX_TASKS {
            return Err(self.fail(
                "study",
                "repetitions",
                s.repetitions,
                &format!("{tasks} identifications in all: at most {}", crate::study::MAX_TASKS),
            ));
        }
        self.within("study", "detmax_max_excursion", s.detmax_max_excursion as f64, 1.0, 10.0, "excursion length")?;
        self.within("study", "rank_rtol", s.rank_rtol, 1e-7, 0.1, "relative singular-value threshold")?;
        Ok(())
    }

    /// A count within `[lo, hi]`: the upper bound keeps every run within memory and time.
    fn count(&self, section: &str, key: &str, v: u64, lo: u64, hi: u64, what: &str) -> Result<(), ScenarioError> {
        if (lo..=hi).contains(&v) { Ok(()) } else { Err(self.fail(section, key, v, &format!("must be within [{lo}, {hi}] ({what})"))) }
    }

    /// A band of `[expect]` (every one is an error in mm): a published value of a robot's size,
    /// 1 nm to 10 m, and a tolerance in [0, 10].
    fn band(&self, key: &str, b: &Option<Band>) -> Result<(), ScenarioError> {
        if let Some(b) = b {
            if !(b.value.is_finite() && (1e-6..=1e4).contains(&b.value)) {
                return Err(self.fail("expect", &format!("{key}.value"), b.value, "must be the published value in mm, within [1e-6, 1e4]"));
            }
            if !(b.tolerance.is_finite() && (0.0..=10.0).contains(&b.tolerance)) {
                return Err(self.fail(
                    "expect",
                    &format!("{key}.tolerance"),
                    b.tolerance,
                    "must be a relative tolerance within [0, 10] (0.2 = +-20 %)",
                ));
            }
        }
        Ok(())
    }

    /// A bound of `[expect]` that is a plain number: finite and within `[lo, hi]`.
    fn bound(&self, key: &str, v: Option<f64>, lo: f64, hi: f64) -> Result<(), ScenarioError> {
        v.map_or(Ok(()), |v| self.within("expect", key, v, lo, hi, "bound of the check"))
    }

    /// Every parameter of the identified set must be separable on `model` by some set of
    /// configurations: a parameter with a zero column (theta_offs6 with the TCP on the joint-6 axis)
    /// or a redundancy (theta_offs1 with the base's alpha) is refused here, not found 510 times.
    fn identifiable(&self, model: &crate::robot::RobotModel, set: &crate::robot::ParamSet, tool_key: &str) -> Result<(), ScenarioError> {
        let hidden = crate::identify::observability::structurally_unidentifiable(model, set);
        if hidden.is_empty() {
            return Ok(());
        }
        let fix = if hidden.iter().any(|n| n == "theta_offs6") {
            format!("theta_offs6 moves nothing while {tool_key} lies on the joint-6 axis: move the tool off the axis or fix theta_offs6")
        } else {
            format!(
                "they move the tool alike in every configuration with this tool ({tool_key}): fix all but one of them, or move the tool"
            )
        };
        Err(self.fail(
            "study",
            "parameters",
            hidden.join(" "),
            &format!("no set of configurations can separate these on this robot; {fix}"),
        ))
    }

    fn within(&self, section: &str, key: &str, v: f64, lo: f64, hi: f64, what: &str) -> Result<(), ScenarioError> {
        if v.is_finite() && v >= lo && v <= hi {
            Ok(())
        } else {
            Err(self.fail(section, key, v, &format!("must be within [{lo}, {hi}] ({what})")))
        }
    }
}

/// Checks a TriCal scenario file.
///
/// Long by design: one line per key of the scenario, section by section, as the file reads.
fn check(f: &ScenarioFile, path: &str) -> Result<(), ScenarioError> {
    let c = Checker { path };
    let r = &f.robot;
    c.within("robot", "repeatability_mm", r.repeatability_mm, 0.0, 1.0, "ISO 9283 RP")?;
    c.within("robot", "payload_kg", r.payload_kg, 0.0, 3.0, "device mass; the IRB 120 carries 3 kg")?;
    if let Some(dm) = r.validation_payload_change_kg {
        c.within(
            "robot",
            "validation_payload_change_kg",
            dm,
            -r.payload_kg,
            3.0 - r.payload_kg,
            "setup 2's mass on the flange within 0-3 kg",
        )?;
    }
    for (k, v) in r.tcp_mm.iter().enumerate() {
        c.within("robot", &format!("tcp_mm[{k}]"), *v, -500.0, 500.0, "TCP in the flange frame")?;
    }
    for (k, v) in r.payload_com_mm.iter().enumerate() {
        c.within("robot", &format!("payload_com_mm[{k}]"), *v, -500.0, 500.0, "centre of mass in the flange frame")?;
    }
    for (k, v) in r.repeatability_reference_q_deg.iter().enumerate() {
        c.within("robot", &format!("repeatability_reference_q_deg[{k}]"), *v, -400.0, 400.0, "joint angle")?;
    }
    if let Some(base) = r.nominal_base_mm_deg {
        for (k, v) in base.iter().enumerate() {
            let (lo, hi) = if k < 3 { (-5000.0, 5000.0) } else { (-360.0, 360.0) };
            c.within("robot", &format!("nominal_base_mm_deg[{k}]"), *v, lo, hi, "x, y, z in mm then alpha, beta, gamma in deg")?;
        }
    }
    c.unmodelled(&r.unmodelled)?;
    c.spread(&r.spread)?;

    let cell = &f.cell;
    if !(3..=12).contains(&cell.spheres_w_mm.len()) {
        return Err(c.fail("cell", "spheres_w_mm", cell.spheres_w_mm.len(), "three to twelve datum spheres (the first three define {W})"));
    }
    let p = &cell.spheres_w_mm;
    if p[0] != [0.0, 0.0, 0.0] || p[1][1] != 0.0 || p[1][2] != 0.0 || p[1][0] <= 0.0 || p[2][2] != 0.0 || p[2][1] <= 0.0 {
        return Err(c.fail(
            "cell",
            "spheres_w_mm",
            format!("{:?}", &p[..3]),
            "the first three define {W} (eqs. 1-5): [0,0,0], then [d12,0,0] with d12 > 0, then [x,y,0] with y > 0",
        ));
    }
    c.within("cell", "ball_diameter_mm", cell.ball_diameter_mm, 1.0, 100.0, "datum ball")?;
    for (i, a) in p.iter().enumerate() {
        for (k, v) in a.iter().enumerate() {
            c.within("cell", &format!("spheres_w_mm[{i}][{k}]"), *v, -2000.0, 2000.0, "sphere centre in {W}, within the robot's reach")?;
        }
        for (j, b) in p.iter().enumerate().take(i) {
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

    let pool = cp.pool_per_sphere as usize * cell.spheres_w_mm.len();
    c.study(&f.study, pool, crate::robot::ParamSet::trical_31)?;
    let set = f.study.parameter_set(crate::robot::ParamSet::trical_31).expect("checked by study()");
    let spec = ExperimentSpec { robot: r.clone(), cell: cell.clone(), trical: t.clone(), tracker: tr.clone(), campaign: cp.clone() };
    c.identifiable(&spec.nominal(), &set, "robot.tcp_mm")?;
    expect(&c, &f.expect)
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
    c.bound("fig8_max_rise", e.fig8_max_rise, -1.0, 10.0)?;
    c.bound("fig9_spread_ratio_min", e.fig9_spread_ratio_min, 0.0, 1000.0)?;
    c.bound("fig12_abs_r_max", e.fig12_abs_r_max, 0.0, 1.0)
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
    let text = crate::io::read_text(path).map_err(|e| ScenarioError::Read { path: shown.clone(), message: e.to_string() })?;
    let table = table(&text, &shown)?;
    from_table(&text, table, path)
}

/// Reads a scenario file into its TOML table, for callers that edit keys
/// before loading it with [`from_table`] (sweeps).
pub fn read_table(path: &Path) -> Result<(String, toml::Table), ScenarioError> {
    let shown = path.display().to_string();
    let text = crate::io::read_text(path).map_err(|e| ScenarioError::Read { path: shown.clone(), message: e.to_string() })?;
    let mut t = table(&text, &shown)?;
    // A robot file is named relative to its scenario; the table may be loaded under another name
    // (a sweep point), so it carries the path from here on.
    if let Some(toml::Value::Table(robot)) = t.get_mut("robot")
        && let Some(toml::Value::String(f)) = robot.get("file")
    {
        let resolved = relative_to(path, Path::new(f)).display().to_string();
        robot.insert("file".into(), toml::Value::String(resolved));
    }
    Ok((text, t))
}

/// The robot file a scenario at `scenario` names (`None`: the built-in arm); an error names the
/// scenario, `robot.file`, the robot file and its field.
fn load_arm(scenario: &Path, file: Option<&Path>) -> Result<Option<crate::robot::file::Arm>, ScenarioError> {
    let Some(f) = file else { return Ok(None) };
    let arm = crate::robot::file::RobotFile::load(&relative_to(scenario, f)).map_err(|e| ScenarioError::Parse {
        path: scenario.display().to_string(),
        key: "robot.file".into(),
        message: e.to_string(),
    })?;
    Ok(Some(crate::robot::file::Arm(std::sync::Arc::new(arm))))
}

/// `file` as named in the scenario at `scenario`: relative paths from the scenario's directory.
fn relative_to(scenario: &Path, file: &Path) -> PathBuf {
    if file.is_absolute() { file.to_path_buf() } else { scenario.parent().unwrap_or(Path::new("")).join(file) }
}

/// Loads and checks a scenario of either kind from its TOML table; `text` is what the manifest
/// hashes, `path` names it in errors.
pub fn from_table(text: &str, table: toml::Table, path: &Path) -> Result<Loaded, ScenarioError> {
    let shown = path.display().to_string();
    match table.get("kind") {
        None => parse_table(text, table, path).map(|s| Loaded::Trical(Box::new(s))),
        Some(toml::Value::String(k)) if k == "trical" => parse_table(text, table, path).map(|s| Loaded::Trical(Box::new(s))),
        Some(toml::Value::String(k)) if k == "spms" => parse_spms_table(text, table, path).map(|s| Loaded::Spms(Box::new(s))),
        Some(v) => Err(ScenarioError::Parse {
            path: shown,
            key: "kind".into(),
            message: format!("{v} is not a study kind (\"trical\" or \"spms\")"),
        }),
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
    study: StudySpec,
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
    let text = crate::io::read_text(path).map_err(|e| ScenarioError::Read { path: shown, message: e.to_string() })?;
    parse_spms(&text, path)
}

/// Parses and checks SPMS scenario text; `path` names it in errors.
pub fn parse_spms(text: &str, path: &Path) -> Result<SpmsScenario, ScenarioError> {
    parse_spms_table(text, table(text, &path.display().to_string())?, path)
}

fn parse_spms_table(text: &str, t: toml::Table, path: &Path) -> Result<SpmsScenario, ScenarioError> {
    let shown = path.display().to_string();
    let mut file: SpmsFile = deserialize(with_defaults(t, "study", crate::spms::study::STUDY_DEFAULTS), &shown)?;
    file.robot.arm = load_arm(path, file.robot.file.as_deref())?;
    let spec = crate::spms::study::SpmsSpec {
        head: file.head,
        beams: file.beams,
        robot: file.robot,
        station: file.station,
        iso9283: file.iso9283,
        study: file.study,
    };
    check_spms(&spec, &shown)?;
    expect_spms(&Checker { path: &shown }, &file.expect)?;
    let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "scenario".into());
    Ok(SpmsScenario { name, path: path.to_path_buf(), text: text.to_string(), seed: file.seed, spec, expect: file.expect })
}

/// Checks an SPMS spec (also after command-line overrides); `path` names it in errors.
///
/// Long by design: one line per key of the scenario, section by section, as the file reads.
pub fn check_spms(f: &crate::spms::study::SpmsSpec, path: &str) -> Result<(), ScenarioError> {
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
    if evaluations > 100_000_000 {
        return Err(c.fail(
            "beams",
            "pso_iterations",
            b.pso_iterations,
            &format!("{evaluations} swarm evaluations: at most 1e8 (population x iterations)"),
        ));
    }
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
    c.within("robot", "repeatability_mm", r.repeatability_mm, 0.0, 1.0, "ISO 9283 RP")?;
    for (k, v) in r.repeatability_reference_q_deg.iter().enumerate() {
        c.within("robot", &format!("repeatability_reference_q_deg[{k}]"), *v, -400.0, 400.0, "joint angle")?;
    }
    c.unmodelled(&r.unmodelled)?;
    c.spread(&r.spread)?;

    let st = &f.station;
    if !(1..=20).contains(&st.sphere_points_base_mm.len()) {
        return Err(c.fail("station", "sphere_points_base_mm", st.sphere_points_base_mm.len(), "one to twenty stations"));
    }
    for (i, p) in st.sphere_points_base_mm.iter().enumerate() {
        for (k, v) in p.iter().enumerate() {
            c.within("station", &format!("sphere_points_base_mm[{i}][{k}]"), *v, -3000.0, 3000.0, "within the ER20-C10's reach")?;
        }
        if p[0].hypot(p[1]) < 300.0 {
            return Err(c.fail(
                "station",
                "sphere_points_base_mm",
                format!("{p:?}"),
                "a station must stand at least 300 mm from the base axis",
            ));
        }
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

    c.study(&f.study, st.pool, crate::spms::calibration::default_parameters)?;
    let set = f.study.parameter_set(crate::spms::calibration::default_parameters).expect("checked by study()");
    let tool = nalgebra::Vector3::from(r.sphere_flange_mm);
    let nominal = f.robot.nominal_model().edited(|d| d.flange_tcp_mm = tool).expect("a finite tool");
    c.identifiable(&nominal, &set, "robot.sphere_flange_mm")
}

/// The `[expect]` table of an SPMS scenario.
fn expect_spms(c: &Checker<'_>, e: &crate::spms::study::SpmsExpect) -> Result<(), ScenarioError> {
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
