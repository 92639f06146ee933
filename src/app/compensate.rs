//! What a user does with a calibration: the joint targets that put the real TCP on each target,
//! from the identified model with its compliance (inverse kinematics refined by Newton's method on
//! the full model), and, for a controller that only knows its nominal model, the Cartesian targets
//! to command instead (the nominal model's TCP pose at those joint values).
//!
//! Targets: a CSV file with the header `x_mm,y_mm,z_mm,alpha_deg,beta_deg,gamma_deg`, the TCP pose
//! in {W} (eq. 7: translation, then rotations about z, y and x; the TCP frame carries the flange's
//! orientation). Out: per target the joint values in degrees, the model's TCP error at them, and
//! the corrected Cartesian target when a nominal model is given.

use std::path::Path;

use nalgebra::{Isometry3, Translation3};

use crate::robot::{Joints, KinState, RobotModel, XyzZyx, inverse, world_from_flange};

/// The columns of a targets file.
pub const TARGET_COLUMNS: [&str; 6] = ["x_mm", "y_mm", "z_mm", "alpha_deg", "beta_deg", "gamma_deg"];

/// Most targets a file takes.
pub const MAX_TARGETS: usize = 1_000_000;

/// Reads the targets of `path`; an error names the file, the line and the column.
pub fn read_targets(path: &Path) -> Result<Vec<Isometry3<f64>>, String> {
    let at = |line: u64, what: String| format!("{}: line {line}: {what}", path.display());
    crate::io::check_input(path, None).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut r = csv::ReaderBuilder::new().trim(csv::Trim::All).from_path(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let header: Vec<String> = r.headers().map_err(|e| at(1, e.to_string()))?.iter().map(str::to_string).collect();
    if header != TARGET_COLUMNS {
        return Err(at(1, format!("header {:?}: expected {}", header.join(","), TARGET_COLUMNS.join(","))));
    }
    let mut out = Vec::new();
    for rec in r.records() {
        let rec = rec.map_err(|e| at(e.position().map_or(0, |p| p.line()), e.to_string()))?;
        let line = rec.position().map_or(0, |p| p.line());
        if out.len() == MAX_TARGETS {
            return Err(at(line, format!("more than {MAX_TARGETS} targets")));
        }
        let mut v = [0.0; 6];
        for (k, (field, name)) in rec.iter().zip(TARGET_COLUMNS).enumerate() {
            let x: f64 = field.parse().map_err(|_| at(line, format!("{name} = {field:?}: not a number")))?;
            let limit = if k < 3 { 1e5 } else { 360.0 };
            if !(x.is_finite() && x.abs() <= limit) {
                return Err(at(line, format!("{name} = {field}: a finite number within +-{limit}")));
            }
            v[k] = x;
        }
        out.push(XyzZyx::from_mm_deg(v).isometry());
    }
    if out.is_empty() {
        return Err(format!("{}: no targets", path.display()));
    }
    Ok(out)
}

/// One compensated target.
#[derive(Clone, Debug, PartialEq)]
pub struct Compensated {
    /// Joint values, rad (`None`: the model cannot reach the target).
    pub q: Option<Joints>,
    /// TCP position error of the model at `q`, mm.
    pub error_mm: f64,
    /// The nominal model's TCP pose at `q` (what to command a controller that only knows it).
    pub nominal_target: Option<XyzZyx>,
}

/// Compensates `targets` on `model`; each solution seeds the next.
pub fn compensate(model: &RobotModel, nominal: Option<&RobotModel>, targets: &[Isometry3<f64>]) -> Vec<Compensated> {
    let mut seed: Joints = [0.0, 0.3, 0.3, 0.0, 1.0, 0.0];
    let mut st = KinState::default();
    targets
        .iter()
        .map(|t| {
            let Ok(q) = inverse(model, t, &seed) else {
                return Compensated { q: None, error_mm: f64::NAN, nominal_target: None };
            };
            seed = q;
            let error_mm = (crate::robot::forward(model, &mut st, &q) - t.translation.vector).norm();
            let nominal_target = nominal.map(|n| {
                let f = world_from_flange(n, &mut st, &q);
                let tcp = f * nalgebra::Point3::from(n.data().flange_tcp_mm);
                XyzZyx::from_isometry(&Isometry3::from_parts(Translation3::from(tcp.coords), f.rotation))
            });
            Compensated { q: Some(q), error_mm, nominal_target }
        })
        .collect()
}

/// The CSV text of `rows`: joint values in degrees, the model's TCP error, the nominal target.
pub fn to_csv(rows: &[Compensated]) -> Result<String, String> {
    let mut w = csv::Writer::from_writer(Vec::new());
    let mut header: Vec<String> = (1..=6).map(|i| format!("q{i}_deg")).collect();
    header.push("model_error_mm".into());
    header.extend(TARGET_COLUMNS.iter().map(|c| format!("nominal_{c}")));
    w.write_record(&header).map_err(|e| e.to_string())?;
    for r in rows {
        let mut rec: Vec<String> = match r.q {
            Some(q) => q.iter().map(|v| format!("{}", v.to_degrees())).collect(),
            None => vec!["unreachable".into(); 6],
        };
        rec.push(format!("{:e}", r.error_mm));
        match &r.nominal_target {
            Some(t) => {
                rec.extend([t.x, t.y, t.z, t.alpha.to_degrees(), t.beta.to_degrees(), t.gamma.to_degrees()].iter().map(|v| format!("{v}")))
            }
            None => rec.extend(std::iter::repeat_n(String::new(), 6)),
        }
        w.write_record(&rec).map_err(|e| e.to_string())?;
    }
    String::from_utf8(w.into_inner().map_err(|e| e.to_string())?).map_err(|e| e.to_string())
}
