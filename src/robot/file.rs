//! Robots as data: a robot file (TOML) with the modified-DH table (plus a Hayati beta where two
//! consecutive axes are parallel), joint limits, link masses and centres of mass, and the truth a
//! study simulates as named parameter values. `robots/irb120.toml` and `robots/er20c10.toml` are the
//! two built-in arms as files (a test checks them against [`super::builtin`] bit for bit).
//!
//! Units at the edge: mm, deg, kg, mdeg/(N m) for compliance; a `[truth]` entry is in its
//! parameter's unit (mm, deg, mdeg/(N m), as Table 7 prints them), or in rad when its name ends
//! in `_rad` (`theta_offs2_rad`), for values given in radians by their source.
//!
//! ```toml
//! name = "ABB IRB 120-3/0.58"
//! source = "TriCal paper Table 3; limits and masses from the ROS-Industrial URDF"
//! gravity_m_s2 = 9.81
//! # flange_rpy_deg = [0.0, 180.0, 0.0]   # the flange in MDH frame 6 where it is not frame 6
//! # tool_mm = [0.0, 0.0, 0.0]            # the TCP in the flange frame
//!
//! [[joint]]            # one per joint, 6, joint 1 first
//! alpha_deg = 0.0      # alpha_{i-1}
//! a_mm = 0.0           # a_{i-1}
//! beta_deg = 0.0       # beta_{i-1} (Hayati), only where alpha_{i-1} is 0 or 180 deg
//! theta_offset_deg = 0.0
//! d_mm = 290.0
//! compliance_mdeg_per_nm = 0.0
//! limits_deg = [-165.0, 165.0]
//! mass_kg = 3.067
//! com_mm = [0.098, -0.12, -51.59]   # in MDH frame i
//!
//! [[collision]]        # capsules of the links, in MDH frame `link` (0 the base, 6 the flange)
//! link = 1
//! a_mm = [-0.7, 0.9, -119.0]
//! b_mm = [-0.7, 0.9, -32.9]
//! radius_mm = 116.9
//!
//! [truth]              # the robot a study simulates: named values (absent: the nominal)
//! a2 = 270.146
//!
//! [[coupling]]         # optional: a joint the controller reports coupled (see `coupling`)
//! joint = 3
//! controller = [0.0, -1.0, 1.0, 0.0, 0.0, 0.0]
//! ```

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Rotation3, Vector3};
use serde::{Deserialize, Serialize};

use super::model::{Inertial, JOINTS, JointLimit, Link, RobotData, RobotModel, XyzZyx};
use super::params::{ParamId, ParamSet, Unit};

/// Largest length a robot file takes, mm (and bound of every other value in its units).
const LENGTH_MM: f64 = 1e5;
/// Largest mass a robot file takes, kg.
const MASS_KG: f64 = 1e4;

/// A robot file that cannot be used: the file, the field, what is wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{path}: {field}: {message}")]
pub struct RobotFileError {
    /// The file.
    pub path: PathBuf,
    /// The field (`joint[3].limits_deg`, `truth.a2`).
    pub field: String,
    /// What is wrong.
    pub message: String,
}

#[derive(Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
struct File {
    name: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    source: Option<String>,
    gravity_m_s2: f64,
    /// Gravity in the base frame {0}, m/s^2, where it is not along -z of {0} (a URDF whose first
    /// axis points down gives a {0} upside down); `gravity_m_s2` is then its norm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    gravity_base_m_s2: Option<[f64; 3]>,
    /// `world_from_base` (eq. 7): `[x, y, z]` mm, `[alpha, beta, gamma]` deg about z, y, x.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    base_mm_deg: Option<[f64; 6]>,
    /// The flange frame in MDH frame 6 (roll, pitch, yaw about fixed x, y, z as in a URDF origin),
    /// where it is not frame 6 itself (a last joint axis pointing into the arm).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    flange_rpy_deg: Option<[f64; 3]>,
    /// TCP in the flange frame, mm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    tool_mm: Option<[f64; 3]>,
    /// Payload in the flange frame: kg, then its centre of mass in mm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    payload: Option<Payload>,
    joint: Vec<JointRow>,
    /// Collision capsules of the links (absent: the arm cannot run a TriCal campaign).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    collision: Vec<CollisionRow>,
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    truth: BTreeMap<String, f64>,
    /// Standard deviation of identified parameters, in their units (an exported calibration).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    std: BTreeMap<String, f64>,
    /// Joints the controller reports coupled (see [`super::coupling`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    coupling: Vec<super::coupling::CouplingRow>,
    /// What a calibration learned beyond the model (a twin; see [`super::learned`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    learned: Option<super::learned::LearnedEffects>,
}

#[derive(Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
struct Payload {
    mass_kg: f64,
    com_mm: [f64; 3],
}

#[derive(Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
struct JointRow {
    alpha_deg: f64,
    a_mm: f64,
    #[serde(default)]
    beta_deg: f64,
    theta_offset_deg: f64,
    d_mm: f64,
    #[serde(default)]
    compliance_mdeg_per_nm: f64,
    limits_deg: [f64; 2],
    #[serde(default)]
    mass_kg: f64,
    #[serde(default)]
    com_mm: [f64; 3],
}

#[derive(Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
struct CollisionRow {
    link: usize,
    a_mm: [f64; 3],
    b_mm: [f64; 3],
    radius_mm: f64,
}

/// A capsule given by its end points and radius, in the frame it is attached to, mm.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CapsuleSpec {
    /// First end, mm.
    pub a: [f64; 3],
    /// Second end, mm.
    pub b: [f64; 3],
    /// Radius, mm.
    pub radius: f64,
}

/// The capsules of each link, per MDH frame 0 (the base) to 6 (the flange).
pub type LinkCapsules = [Vec<CapsuleSpec>; JOINTS + 1];

/// A loaded robot file: the nominal arm (base at the world origin, TCP on the flange, no payload)
/// and the truth as named values.
#[derive(Clone, Debug)]
pub struct RobotFile {
    /// The file it came from.
    pub path: PathBuf,
    /// Where its values come from.
    pub source: Option<String>,
    /// The nominal arm.
    pub nominal: RobotModel,
    /// The truth: parameter and its value in internal units, by name.
    pub truth: Vec<(ParamId, f64)>,
    /// Standard deviations of an exported calibration, in each parameter's unit, by name.
    pub std: Vec<(ParamId, f64)>,
    /// The links' collision capsules (`None`: the file gives none).
    pub capsules: Option<LinkCapsules>,
    /// The flange frame in MDH frame 6 (`None`: frame 6 is the flange).
    pub flange: Option<Matrix3<f64>>,
    /// The controller's joint coupling (`None`: the controller reports the model's joint angles).
    pub coupling: Option<super::coupling::JointCoupling>,
    /// What a calibration learned beyond the model (`None`: the file has no `[learned]` table).
    pub learned: Option<super::learned::LearnedEffects>,
}

/// A loaded robot file shared by the copies of a scenario (equal when read from the same path).
#[derive(Clone, Debug)]
pub struct Arm(pub std::sync::Arc<RobotFile>);

impl PartialEq for Arm {
    fn eq(&self, other: &Self) -> bool {
        self.0.path == other.0.path
    }
}

/// The robot file text of `model` (every value of its data: the joints, base, tool and payload),
/// with `std` (parameter and standard deviation in internal units), the links' `capsules` and the
/// `flange` frame in frame 6 if known, and `source` as provenance.
pub fn to_text(
    model: &RobotModel,
    source: &str,
    std: &[(ParamId, f64)],
    capsules: Option<&LinkCapsules>,
    flange: Option<&Matrix3<f64>>,
) -> String {
    let body = toml::to_string(&file_of(model, source, std, capsules, flange)).unwrap_or_default();
    format!("{HEADER}{body}")
}

/// The first line of every robot file calsim writes.
const HEADER: &str = "# A calsim robot file (format: src/robot/file.rs); units mm, deg, kg, mdeg/(N m).\n";

/// [`to_text`] of an imported arm, written tidily: a number within 1e-9 of a multiple of 1e-6
/// (in its unit: mm, deg, kg) is written as that multiple, so rounding residues of the conversion
/// (`25.000000000000004`, `2.5e-14`, `-0.0`) do not read as data; capsules are written to the
/// micrometre (their radius grown to hold what the fitted capsule held); `preamble` (provenance,
/// one comment line each) heads the file. A joint, mass or frame value moves by less than 1e-9 of
/// its unit.
pub fn imported_text(
    model: &RobotModel,
    source: &str,
    capsules: Option<&LinkCapsules>,
    flange: Option<&Matrix3<f64>>,
    preamble: &[String],
) -> String {
    let mut f = file_of(model, source, &[], capsules, flange);
    tidy(&mut f);
    let body = toml::to_string(&f).unwrap_or_default();
    let lines: String = preamble.iter().map(|l| format!("# {}\n", l.trim_end())).collect();
    format!("{HEADER}{lines}{body}")
}

/// Every number of `f` tidied as [`imported_text`] says.
fn tidy(f: &mut File) {
    fn t(x: &mut f64) {
        let grid = (*x * 1e6).round() / 1e6;
        if (*x - grid).abs() < 1e-9 {
            *x = grid;
        }
        *x += 0.0;
    }
    t(&mut f.gravity_m_s2);
    let arrays = f.gravity_base_m_s2.iter_mut().chain(&mut f.flange_rpy_deg).chain(&mut f.tool_mm);
    arrays.flat_map(|a| a.iter_mut()).chain(f.base_mm_deg.iter_mut().flatten()).for_each(t);
    if let Some(p) = &mut f.payload {
        t(&mut p.mass_kg);
        p.com_mm.iter_mut().for_each(t);
    }
    for j in &mut f.joint {
        for x in [
            &mut j.alpha_deg,
            &mut j.a_mm,
            &mut j.beta_deg,
            &mut j.theta_offset_deg,
            &mut j.d_mm,
            &mut j.compliance_mdeg_per_nm,
            &mut j.mass_kg,
        ] {
            t(x);
        }
        j.limits_deg.iter_mut().chain(j.com_mm.iter_mut()).for_each(t);
    }
    // Capsules (bounding shapes fitted to meshes of single-precision vertices) to the micrometre:
    // the ends rounded (each moves by at most 0.87 um), the radius rounded up after growing by
    // 1 um, so that a rounded capsule still holds what the fitted one held.
    for c in &mut f.collision {
        c.a_mm.iter_mut().chain(c.b_mm.iter_mut()).for_each(|x| *x = (*x * 1e3).round() / 1e3 + 0.0);
        c.radius_mm = ((c.radius_mm + 1e-3) * 1e3).ceil() / 1e3;
    }
}

/// The file structure of [`to_text`].
fn file_of(
    model: &RobotModel,
    source: &str,
    std: &[(ParamId, f64)],
    capsules: Option<&LinkCapsules>,
    flange: Option<&Matrix3<f64>>,
) -> File {
    let d = model.data();
    let to_flange = |v: &Vector3<f64>| -> [f64; 3] { flange.map_or(*v, |r| r.transpose() * v).into() };
    let b = d.world_from_base;
    File {
        name: d.name.clone(),
        source: Some(source.to_string()),
        gravity_m_s2: d.gravity_base.norm(),
        gravity_base_m_s2: (d.gravity_base.x != 0.0 || d.gravity_base.y != 0.0 || d.gravity_base.z > 0.0).then(|| d.gravity_base.into()),
        base_mm_deg: Some([b.x, b.y, b.z, b.alpha.to_degrees(), b.beta.to_degrees(), b.gamma.to_degrees()]),
        flange_rpy_deg: flange.map(|r| super::rotation::rpy_deg(&Rotation3::from_matrix_unchecked(*r))),
        tool_mm: Some(to_flange(&d.flange_tcp_mm)),
        payload: Some(Payload { mass_kg: d.payload.mass_kg, com_mm: to_flange(&d.payload.com_mm) }),
        joint: (0..JOINTS)
            .map(|i| {
                let (l, lim, m) = (&d.links[i], &d.limits[i], &d.links_inertial[i]);
                JointRow {
                    alpha_deg: l.alpha.to_degrees(),
                    a_mm: l.a,
                    beta_deg: l.beta.to_degrees(),
                    theta_offset_deg: l.theta_offset.to_degrees(),
                    d_mm: l.d,
                    compliance_mdeg_per_nm: Unit::MdegPerNm.from_internal(l.compliance),
                    limits_deg: [lim.min.to_degrees(), lim.max.to_degrees()],
                    mass_kg: m.mass_kg,
                    com_mm: m.com_mm.into(),
                }
            })
            .collect(),
        collision: capsules
            .iter()
            .flat_map(|c| c.iter().enumerate())
            .flat_map(|(link, caps)| caps.iter().map(move |c| CollisionRow { link, a_mm: c.a, b_mm: c.b, radius_mm: c.radius }))
            .collect(),
        truth: BTreeMap::new(),
        std: std.iter().map(|(id, v)| (id.name(), id.unit().from_internal(*v))).collect(),
        coupling: Vec::new(),
        learned: None,
    }
}

impl RobotFile {
    /// Reads and checks `path`.
    pub fn load(path: &Path) -> Result<Self, RobotFileError> {
        let text = crate::io::read_text(path).map_err(|e| RobotFileError {
            path: path.to_path_buf(),
            field: "(file)".into(),
            message: e.to_string(),
        })?;
        Self::from_text(path, &text)
    }

    /// Checks the text of a robot file as `load` checks a file (`path` is named in the error).
    pub fn from_text(path: &Path, text: &str) -> Result<Self, RobotFileError> {
        Self::parse(path, text).map_err(|(field, message)| RobotFileError { path: path.to_path_buf(), field, message })
    }

    /// Parses and checks a robot file's text: the field and message of the first refusal.
    ///
    /// Long by design: one pass over the file's tables in the order a reader meets them (joints,
    /// flange, collision, truth), each key checked where it is read and named in its error;
    /// pieces would hand the half-built model and the key context back and forth.
    fn parse(path: &Path, text: &str) -> Result<Self, (String, String)> {
        let f: File = crate::io::toml_de::from_str(text).map_err(|e| {
            let msg = e.message().to_string();
            (crate::io::toml_position(text, e.span()), msg)
        })?;
        let finite = |field: String, v: f64| if v.is_finite() { Ok(v) } else { Err((field, format!("{v} is not a finite number"))) };
        let within = |field: String, v: f64, lo: f64, hi: f64| {
            if !v.is_finite() {
                Err((field, format!("{v} is not a finite number")))
            } else if v < lo || v > hi {
                Err((field, format!("{v}: within [{lo}, {hi}]")))
            } else {
                Ok(v)
            }
        };
        finite("gravity_m_s2".into(), f.gravity_m_s2)?;
        if !(0.0..=100.0).contains(&f.gravity_m_s2) {
            return Err(("gravity_m_s2".into(), format!("{}: within [0, 100] m/s^2", f.gravity_m_s2)));
        }
        let gravity = match f.gravity_base_m_s2 {
            None => Vector3::new(0.0, 0.0, -f.gravity_m_s2),
            Some(g) => {
                for (k, v) in g.iter().enumerate() {
                    within(format!("gravity_base_m_s2[{k}]"), *v, -100.0, 100.0)?;
                }
                let g = Vector3::from(g);
                if (g.norm() - f.gravity_m_s2).abs() > 1e-6 * f.gravity_m_s2.max(1.0) {
                    return Err(("gravity_base_m_s2".into(), format!("its norm {} is not gravity_m_s2 = {}", g.norm(), f.gravity_m_s2)));
                }
                g
            }
        };
        if f.joint.len() != JOINTS {
            return Err((
                "joint".into(),
                format!("{} joint rows: calsim's arms are serial with {JOINTS} revolute joints, joint 1 first", f.joint.len()),
            ));
        }
        for (i, j) in f.joint.iter().enumerate() {
            let at = |k: &str| format!("joint[{}].{k}", i + 1);
            for (k, v, lo, hi) in [
                ("alpha_deg", j.alpha_deg, -360.0, 360.0),
                ("a_mm", j.a_mm, -LENGTH_MM, LENGTH_MM),
                ("beta_deg", j.beta_deg, -360.0, 360.0),
                ("theta_offset_deg", j.theta_offset_deg, -720.0, 720.0),
                ("d_mm", j.d_mm, -LENGTH_MM, LENGTH_MM),
                ("compliance_mdeg_per_nm", j.compliance_mdeg_per_nm, -1e5, 1e5),
                ("mass_kg", j.mass_kg, 0.0, MASS_KG),
            ] {
                within(at(k), v, lo, hi)?;
            }
            for (k, v) in j.limits_deg.iter().enumerate() {
                within(format!("{}[{k}]", at("limits_deg")), *v, -1080.0, 1080.0)?;
            }
            for (k, v) in j.com_mm.iter().enumerate() {
                within(format!("{}[{k}]", at("com_mm")), *v, -LENGTH_MM, LENGTH_MM)?;
            }
            if j.limits_deg[0] >= j.limits_deg[1] {
                return Err((at("limits_deg"), format!("{:?}: the lower limit must be below the upper", j.limits_deg)));
            }
            // A Hayati beta turns about the y axis of frame i-1; it is the parameter of choice
            // where the axes of joints i-1 and i are parallel (alpha_{i-1} = 0 or 180 deg), and
            // redundant with alpha, a and d elsewhere.
            let parallel = (j.alpha_deg.rem_euclid(180.0)).min(180.0 - j.alpha_deg.rem_euclid(180.0)) < 1.0;
            if j.beta_deg != 0.0 && !parallel {
                return Err((
                    at("beta_deg"),
                    format!(
                        "{}: a beta needs the axes of joints {} and {} parallel (alpha = 0 or 180 deg), here alpha = {} deg",
                        j.beta_deg,
                        i,
                        i + 1,
                        j.alpha_deg
                    ),
                ));
            }
        }
        let links: [Link; JOINTS] = std::array::from_fn(|i| {
            let j = &f.joint[i];
            Link {
                alpha: j.alpha_deg.to_radians(),
                a: j.a_mm,
                beta: j.beta_deg.to_radians(),
                theta_offset: j.theta_offset_deg.to_radians(),
                d: j.d_mm,
                compliance: Unit::MdegPerNm.to_internal(j.compliance_mdeg_per_nm),
            }
        });
        for (k, v) in f.base_mm_deg.iter().flatten().enumerate() {
            let lim = if k < 3 { LENGTH_MM } else { 360.0 };
            within(format!("base_mm_deg[{k}]"), *v, -lim, lim)?;
        }
        for (k, v) in f.tool_mm.iter().flatten().enumerate() {
            within(format!("tool_mm[{k}]"), *v, -LENGTH_MM, LENGTH_MM)?;
        }
        if let Some(p) = &f.payload {
            within("payload.mass_kg".into(), p.mass_kg, 0.0, MASS_KG)?;
            for (k, v) in p.com_mm.iter().enumerate() {
                within(format!("payload.com_mm[{k}]"), *v, -LENGTH_MM, LENGTH_MM)?;
            }
        }
        for (k, v) in f.flange_rpy_deg.iter().flatten().enumerate() {
            within(format!("flange_rpy_deg[{k}]"), *v, -360.0, 360.0)?;
        }
        // One rotation for every writing of it (see `robot::rotation`).
        let flange = f.flange_rpy_deg.map(|rpy| super::rotation::from_rpy_deg(rpy).into_inner());
        let in_frame6 = |v: Vector3<f64>| flange.map_or(v, |r| r * v);
        let base = f.base_mm_deg.map_or_else(XyzZyx::default, XyzZyx::from_mm_deg);
        let data = RobotData {
            name: f.name.clone(),
            links,
            world_from_base: base,
            flange_tcp_mm: in_frame6(f.tool_mm.map_or_else(Vector3::zeros, Vector3::from)),
            limits: std::array::from_fn(|i| JointLimit {
                min: f.joint[i].limits_deg[0].to_radians(),
                max: f.joint[i].limits_deg[1].to_radians(),
            }),
            links_inertial: std::array::from_fn(|i| Inertial { mass_kg: f.joint[i].mass_kg, com_mm: Vector3::from(f.joint[i].com_mm) }),
            payload: f
                .payload
                .as_ref()
                .map_or(Inertial::NONE, |p| Inertial { mass_kg: p.mass_kg, com_mm: in_frame6(Vector3::from(p.com_mm)) }),
            gravity_base: gravity,
        };
        let nominal = RobotModel::new(data).map_err(|e| ("joint".to_string(), e.to_string()))?;
        let mut truth = Vec::with_capacity(f.truth.len());
        for (name, &v) in &f.truth {
            let field = format!("truth.{name}");
            within(field.clone(), v, -LENGTH_MM, LENGTH_MM)?;
            let (base, rad) = match name.strip_suffix("_rad") {
                Some(b) => (b, true),
                None => (name.as_str(), false),
            };
            let id = ParamId::parse(base).ok_or_else(|| (field.clone(), format!("unknown parameter `{base}`")))?;
            let unit = id.unit();
            if rad && unit != Unit::Deg {
                return Err((field, format!("`_rad` is for angles; {base} is in {}", unit.symbol())));
            }
            truth.push((id, if rad { v } else { unit.to_internal(v) }));
        }
        let mut std = Vec::with_capacity(f.std.len());
        for (name, &v) in &f.std {
            let field = format!("std.{name}");
            within(field.clone(), v, 0.0, LENGTH_MM)?;
            let id = ParamId::parse(name).ok_or_else(|| (field.clone(), format!("unknown parameter `{name}`")))?;
            std.push((id, v));
        }
        let capsules = if f.collision.is_empty() {
            None
        } else {
            let mut caps: LinkCapsules = Default::default();
            for (k, c) in f.collision.iter().enumerate() {
                let at = |key: &str| format!("collision[{}].{key}", k + 1);
                if c.link > JOINTS {
                    return Err((at("link"), format!("{}: MDH frames are 0 (the base) to {JOINTS} (the flange)", c.link)));
                }
                for (key, p) in [("a_mm", &c.a_mm), ("b_mm", &c.b_mm)] {
                    for (i, v) in p.iter().enumerate() {
                        within(format!("{}[{i}]", at(key)), *v, -LENGTH_MM, LENGTH_MM)?;
                    }
                }
                within(at("radius_mm"), c.radius_mm, 0.0, LENGTH_MM)?;
                if c.radius_mm <= 0.0 {
                    return Err((at("radius_mm"), format!("{}: a capsule needs a positive radius", c.radius_mm)));
                }
                caps[c.link].push(CapsuleSpec { a: c.a_mm, b: c.b_mm, radius: c.radius_mm });
            }
            Some(caps)
        };
        let coupling = if f.coupling.is_empty() { None } else { Some(super::coupling::JointCoupling::from_rows(&f.coupling)?) };
        if let Some(l) = &f.learned {
            l.check().map_err(|(key, message)| (format!("learned.{key}"), message))?;
        }
        let file = Self { path: path.to_path_buf(), source: f.source, nominal, truth, std, capsules, flange, coupling, learned: f.learned };
        file.truth_on(&file.nominal).map_err(|e| ("truth".to_string(), e))?;
        // Values each within range that together describe no arm.
        super::plausible::check(&file)?;
        Ok(file)
    }

    /// `model` (this arm with a scenario's base, tool and payload) with the truth's values set.
    pub fn truth_on(&self, model: &RobotModel) -> Result<RobotModel, String> {
        if self.truth.is_empty() {
            return Ok(model.clone());
        }
        let set = ParamSet::new(self.truth.iter().map(|(id, _)| *id).collect()).map_err(|e| e.to_string())?;
        let values: Vec<f64> = self.truth.iter().map(|(_, v)| *v).collect();
        set.unpack(model, &values).map_err(|e| e.to_string())
    }
}
