//! The calibrated model out of calsim: one identification of a results directory, redone from its
//! scenario and seed (the same stream, so the same set and fit, checked against the results), as a
//! robot file (every value of the identified model, each identified parameter's standard deviation
//! from the fit's covariance) and a YAML overlay of per-joint corrections against the model before
//! calibration.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use polars::prelude::*;
use sha2::Digest;

use crate::identify::observability::parameter_covariance;
use super::Error;
use crate::robot::{ParamId, RobotModel};
use crate::study::prediction::noise_estimate;

/// Which identification of the results to export.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Pick {
    /// Task by index.
    Task(usize),
    /// At a set size (`None`: the scenario's table set size): the task whose validation median is
    /// the median (the lower middle of an even count), the lowest or the highest.
    Median(Option<usize>),
    /// See `Median`.
    Best(Option<usize>),
    /// See `Median`.
    Worst(Option<usize>),
}

/// An identification redone for export.
pub struct Export {
    /// The scenario's name.
    pub scenario: String,
    /// Task index.
    pub task: usize,
    /// Its set size.
    pub set_size: usize,
    /// Validation median of the task, mm.
    pub validation_median_mm: f64,
    /// The model before calibration.
    pub before: RobotModel,
    /// The identified model.
    pub model: RobotModel,
    /// The arm's link capsules (carried into the exported robot files).
    pub links: crate::robot::file::LinkCapsules,
    /// The arm's flange in MDH frame 6 (carried into the exported robot files).
    pub flange: Option<nalgebra::Matrix3<f64>>,
    /// Identified parameters and their standard deviation (internal units).
    pub std: Vec<(ParamId, f64)>,
}

fn err(dir: &Path, what: impl std::fmt::Display) -> Error {
    Error::input(dir.display().to_string(), what.to_string())
}

/// Redoes the identification `pick` of the TriCal results in `dir`.
pub fn identification(dir: &Path, pick: Pick) -> Result<Export, Error> {
    #[derive(serde::Deserialize)]
    struct Manifest {
        scenario_path: PathBuf,
        scenario_sha256: String,
        seed: u64,
        #[serde(default)]
        overrides: Vec<(String, String)>,
    }
    let bytes = crate::io::read_bytes(&dir.join("manifest.json"))
        .map_err(|e| err(dir, format!("manifest.json: {e} (not a results directory of `calsim run`)")))?;
    if serde_json::from_slice::<serde_json::Value>(&bytes).is_ok_and(|v| v.get("sweep").is_some()) {
        return Err(err(
            dir,
            "the results of a sweep, not of a run: export takes a run's results; run one design with `calsim run <sweep results>/best_design.toml`, then export that",
        ));
    }
    let manifest: Manifest = serde_json::from_slice(&bytes).map_err(|e| err(dir, format!("manifest.json: {e}")))?;
    let text = crate::io::read_text(&manifest.scenario_path).map_err(|e| err(dir, format!("{}: {e}", manifest.scenario_path.display())))?;
    if format!("{:x}", sha2::Sha256::digest(text.as_bytes())) != manifest.scenario_sha256 {
        return Err(err(dir, format!("{} changed since these results were written: run it again", manifest.scenario_path.display())));
    }
    let overrides = crate::app::run::Overrides::from_pairs(&manifest.overrides)
        .ok_or_else(|| err(dir, format!("manifest.json: overrides {:?}: not ones calsim writes", manifest.overrides)))?;
    let mut s = crate::device::load(&manifest.scenario_path)?;
    overrides.apply(s.as_mut())?;
    s.header_mut().seed = manifest.seed;
    let tasks = tasks_table(dir)?;
    let index = match pick {
        Pick::Task(t) => t,
        Pick::Median(n) | Pick::Best(n) | Pick::Worst(n) => {
            let n = n.unwrap_or(s.study().table_set_size as usize);
            let mut at: Vec<(f64, usize)> = tasks.iter().filter(|t| t.1 == n && t.2.is_finite()).map(|t| (t.2, t.0)).collect();
            at.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            let k = match pick {
                Pick::Best(_) => 0,
                Pick::Worst(_) => at.len().saturating_sub(1),
                _ => (at.len().saturating_sub(1)) / 2,
            };
            at.get(k).map(|x| x.1).ok_or_else(|| err(dir, format!("--set-size {n}: no identified task of that size in tasks.parquet")))?
        }
    };
    let row = tasks.iter().find(|t| t.0 == index).ok_or_else(|| err(dir, format!("--task {index}: no such task in tasks.parquet")))?;
    let r = s.refit(index).map_err(|e| err(dir, e))?.ok_or_else(|| err(dir, format!("task {index} is not in the scenario's study")))?;
    let model = r.model.ok_or_else(|| err(dir, format!("task {index}: its set could not separate the parameters: no model")))?;
    if r.validation_median_mm.to_bits() != row.2.to_bits() {
        return Err(err(
            dir,
            format!("task {index}: redone it gives a validation median of {} mm, the results say {} mm", r.validation_median_mm, row.2),
        ));
    }
    let (n, m) = (r.observations.len(), r.set.len());
    let sigma = noise_estimate(r.residual_rms_mm, n, m);
    let qs: Vec<_> = r.observations.iter().map(|o| o.q).collect();
    let cov = parameter_covariance(&model, &r.set, &qs, sigma);
    let std = r.set.ids().iter().enumerate().map(|(j, id)| (*id, cov.as_ref().map_or(f64::NAN, |c| c[(j, j)].max(0.0).sqrt()))).collect();
    Ok(Export {
        scenario: s.header().name.clone(),
        task: index,
        set_size: r.set_size,
        validation_median_mm: r.validation_median_mm,
        before: r.before,
        model,
        std,
        links: r.links,
        flange: r.flange,
    })
}

/// (task, set size, validation median) of every row of `dir/tasks.parquet`.
fn tasks_table(dir: &Path) -> Result<Vec<(usize, usize, f64)>, Error> {
    let path = dir.join("tasks.parquet");
    let file = std::fs::File::open(&path).map_err(|e| err(dir, format!("tasks.parquet: {e}")))?;
    let df = ParquetReader::new(file).finish().map_err(|e| err(dir, format!("tasks.parquet: {e}")))?;
    let col = |name: &str| df.column(name).map_err(|e| err(dir, format!("tasks.parquet: {e}")));
    let task = col("task")?.cast(&DataType::UInt64).map_err(|e| err(dir, e))?;
    let size = col("set_size")?.cast(&DataType::UInt64).map_err(|e| err(dir, e))?;
    let median = col("validation_median_mm")?.cast(&DataType::Float64).map_err(|e| err(dir, e))?;
    let (task, size, median) =
        (task.u64().map_err(|e| err(dir, e))?, size.u64().map_err(|e| err(dir, e))?, median.f64().map_err(|e| err(dir, e))?);
    Ok(task
        .iter()
        .zip(size.iter())
        .zip(median.iter())
        .filter_map(|((t, s), m)| Some((t? as usize, s? as usize, m.unwrap_or(f64::NAN))))
        .collect())
}

/// The YAML overlay: the identified model's corrections against the model before calibration, per
/// joint (the joint-zero offset first, as drivers apply it), then the base and the tool. Lengths
/// in metres and angles in radians (ROS conventions).
pub fn yaml_overlay(e: &Export) -> String {
    let (b, m) = (e.before.data(), e.model.data());
    let mut y = String::new();
    let _ = writeln!(y, "# calsim calibration of {} (scenario {}, task {}, n = {}).", m.name, e.scenario, e.task, e.set_size);
    let _ = writeln!(y, "# Identified minus before calibration, modified DH (alpha_{{i-1}}, a_{{i-1}}, beta_{{i-1}}, theta_i, d_i);");
    let _ = writeln!(y, "# offset: add to each joint's zero. Metres, radians, rad/(N m). The full model: robot.toml.");
    let _ = writeln!(y, "joints:");
    for (i, (lb, lm)) in b.links.iter().zip(&m.links).enumerate() {
        let _ = writeln!(y, "  joint_{}:", i + 1);
        let _ = writeln!(y, "    offset: {:e}", lm.theta_offset - lb.theta_offset);
        let _ = writeln!(y, "    alpha: {:e}", lm.alpha - lb.alpha);
        let _ = writeln!(y, "    a: {:e}", (lm.a - lb.a) * 1e-3);
        let _ = writeln!(y, "    beta: {:e}", lm.beta - lb.beta);
        let _ = writeln!(y, "    d: {:e}", (lm.d - lb.d) * 1e-3);
        let _ = writeln!(y, "    compliance: {:e}", lm.compliance - lb.compliance);
    }
    let (wb, wm) = (b.world_from_base, m.world_from_base);
    let _ = writeln!(y, "base:   # world_from_base, eq. 7: translation, then rotations about z, y, x");
    for (k, v) in [("x", wm.x - wb.x), ("y", wm.y - wb.y), ("z", wm.z - wb.z)] {
        let _ = writeln!(y, "  {k}: {:e}", v * 1e-3);
    }
    for (k, v) in [("yaw", wm.alpha - wb.alpha), ("pitch", wm.beta - wb.beta), ("roll", wm.gamma - wb.gamma)] {
        let _ = writeln!(y, "  {k}: {v:e}");
    }
    let _ = writeln!(y, "tool:   # TCP in the flange frame");
    for (k, v) in ["x", "y", "z"].iter().zip((m.flange_tcp_mm - b.flange_tcp_mm).iter()) {
        let _ = writeln!(y, "  {k}: {:e}", v * 1e-3);
    }
    y
}

/// Writes `robot.toml`, `before.toml` (the model before calibration), `robot.urdf` and
/// `calibration.yaml` of `e` into `out/<name>` atomically.
pub fn write(out: &Path, name: &str, e: &Export) -> std::io::Result<PathBuf> {
    let source = format!(
        "calsim {} export: scenario {}, task {} (n = {}), validation median {:.4} mm",
        env!("CARGO_PKG_VERSION"),
        e.scenario,
        e.task,
        e.set_size,
        e.validation_median_mm
    );
    let robot = crate::robot::file::to_text(&e.model, &source, &e.std, Some(&e.links), e.flange.as_ref());
    let yaml = yaml_overlay(e);
    let urdf = urdf(e).map_err(std::io::Error::other)?;
    let before = crate::robot::file::to_text(
        &e.before,
        &format!("the model before calibration of {}", e.scenario),
        &[],
        Some(&e.links),
        e.flange.as_ref(),
    );
    crate::io::out_dir::write_atomically(out, name, |dir| {
        std::fs::write(dir.join("robot.toml"), &robot)?;
        std::fs::write(dir.join("before.toml"), &before)?;
        std::fs::write(dir.join("robot.urdf"), &urdf)?;
        std::fs::write(dir.join("calibration.yaml"), &yaml)
    })
}

/// The URDF of the identified model: `world` -> fixed `base` joint (world_from_base) -> `base_link`
/// -> revolute `joint_1`..`joint_6` -> `link_6` -> fixed `tcp` joint -> `tcp`. Each revolute joint's
/// origin is the identified modified-DH transform `Tx(a) Rx(alpha) Ry(beta) Tz(d) Rz(theta_offset)`
/// (rotating about z by q after it gives MDH frame i, so `link_i` is MDH frame i and its inertial
/// origin the centre of mass): **the origins carry the joint offsets**; `<calibration rising>`
/// repeats each offset's correction against the model before calibration, for tools that keep
/// corrections apart. The joint compliance, which URDF has no element for, is written as
/// `<calsim_compliance joint="joint_i" rad_per_nm="..."/>` elements (ignored by URDF parsers).
/// Metres and radians.
pub fn urdf(e: &Export) -> Result<String, Error> {
    use nalgebra::{Isometry3, Vector3};
    use urdf_rs::{Axis, Calibration, Joint, JointLimit, JointType, Link, LinkName, Pose, Robot, Vec3};
    let (b, m) = (e.before.data(), e.model.data());
    let pose = |t: &Isometry3<f64>| {
        let (r, p, y) = t.rotation.euler_angles();
        let v = t.translation.vector * 1e-3;
        Pose { xyz: Vec3([v.x, v.y, v.z]), rpy: Vec3([r, p, y]) }
    };
    let link = |name: &str, inertial: Option<&crate::robot::Inertial>| {
        let mut l = Link { name: name.into(), inertial: urdf_rs::Inertial::default(), visual: Vec::new(), collision: Vec::new() };
        if let Some(i) = inertial {
            let c = i.com_mm * 1e-3;
            l.inertial.mass.value = i.mass_kg;
            l.inertial.origin = Pose { xyz: Vec3([c.x, c.y, c.z]), rpy: Vec3([0.0; 3]) };
        }
        l
    };
    let fixed = |name: &str, parent: &str, child: &str, origin: Pose| Joint {
        name: name.into(),
        joint_type: JointType::Fixed,
        origin,
        parent: LinkName { link: parent.into() },
        child: LinkName { link: child.into() },
        axis: Axis::default(),
        limit: JointLimit::default(),
        calibration: None,
        dynamics: None,
        mimic: None,
        safety_controller: None,
    };
    let base = m.world_from_base.isometry();
    let mut links = vec![link("world", None), link("base_link", None)];
    let mut joints = vec![fixed("base", "world", "base_link", pose(&base))];
    for (i, (l, lb)) in m.links.iter().zip(&b.links).enumerate() {
        let t = Isometry3::translation(l.a, 0.0, 0.0)
            * Isometry3::rotation(Vector3::x() * l.alpha)
            * Isometry3::rotation(Vector3::y() * l.beta)
            * Isometry3::translation(0.0, 0.0, l.d)
            * Isometry3::rotation(Vector3::z() * l.theta_offset);
        let parent = if i == 0 { "base_link".to_string() } else { format!("link_{i}") };
        let child = format!("link_{}", i + 1);
        links.push(link(&child, Some(&m.links_inertial[i])));
        let lim = m.limits[i];
        joints.push(Joint {
            joint_type: JointType::Revolute,
            axis: Axis { xyz: Vec3([0.0, 0.0, 1.0]) },
            limit: JointLimit { lower: lim.min, upper: lim.max, effort: 0.0, velocity: 1.0, ..JointLimit::default() },
            calibration: Some(Calibration { rising: Some(l.theta_offset - lb.theta_offset), falling: None }),
            ..fixed(&format!("joint_{}", i + 1), &parent, &child, pose(&t))
        });
    }
    let tcp = m.flange_tcp_mm * 1e-3;
    links.push(link("tcp", None));
    joints.push(fixed("tcp", "link_6", "tcp", Pose { xyz: Vec3([tcp.x, tcp.y, tcp.z]), rpy: Vec3([0.0; 3]) }));
    let robot = Robot { name: m.name.clone(), version: None, links, joints, materials: Vec::new() };
    let text = urdf_rs::write_to_string(&robot).map_err(|err| Error::input("URDF", err.to_string()))?;
    let extension: String = m
        .links
        .iter()
        .enumerate()
        .map(|(i, l)| format!("  <calsim_compliance joint=\"joint_{}\" rad_per_nm=\"{:e}\"/>\n", i + 1, l.compliance))
        .collect();
    let close = text.rfind("</robot>").ok_or_else(|| Error::input("URDF", "no closing </robot>"))?;
    Ok(format!(
        "{}  <!-- calsim: joint compliance (rad/(N m)), theta = q + offset + c tau; not part of URDF -->\n{extension}{}",
        &text[..close],
        &text[close..]
    ))
}
