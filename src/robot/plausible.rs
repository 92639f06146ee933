//! Cross-key plausibility of a robot file: values each within its own range that together describe
//! no arm (a 10-tonne link on a one-metre arm, a centre of mass 100 m from its link, a compliance
//! that bends a joint by degrees under the arm's own weight). Each error names every key involved;
//! the bounds are far outside any real arm, so that they catch typos and unit slips, never a
//! design.

use super::file::RobotFile;
use super::model::{JOINTS, Joints, RobotModel};

/// Density of steel, kg/m^3 (SOURCED: the usual engineering value for carbon steel, 7850).
const STEEL_KG_M3: f64 = 7850.0;

/// Largest gravity deflection of a joint, deg (ASSUMED: ten times the largest of the shipped arms'
/// truths, about 0.1 deg; calsim's compliance `theta += c tau` is a small-angle model).
pub const MOST_DEFLECTION_DEG: f64 = 1.0;

/// Configurations the deflection is evaluated at: spread over the joint limits (each joint within
/// +-180 deg) by a fixed pattern, so the check does not depend on a random stream.
const CONFIGURATIONS: usize = 97;

/// The length of the arm of `model`: the sum of its link lengths and offsets and its tool, mm, at
/// least 100 mm. No point of the arm's skeleton is farther than this from any other.
pub fn arm_length_mm(model: &RobotModel) -> f64 {
    let d = model.data();
    (d.links.iter().map(|l| l.a.abs() + l.d.abs()).sum::<f64>() + d.flange_tcp_mm.norm()).max(100.0)
}

/// The keys the arm's length comes from, as an error names them.
const LENGTH_KEYS: &str = "joint[1..6].a_mm and d_mm and tool_mm";

/// Checks the file's masses, centres of mass and compliances against each other and the arm's
/// size; the error is `(keys, what is wrong)`.
pub fn check(file: &RobotFile) -> Result<(), (String, String)> {
    let model = &file.nominal;
    let d = model.data();
    let length = arm_length_mm(model);
    // A centre of mass lies on its link: within the arm's length of its frame, and twice that
    // leaves room for the links' girth.
    for (i, inertial) in d.links_inertial.iter().enumerate() {
        let r = inertial.com_mm.norm();
        if inertial.mass_kg > 0.0 && r > 2.0 * length {
            return Err((
                format!("joint[{}].com_mm", i + 1),
                format!(
                    "{:?} is {r:.1} mm from the origin of MDH frame {}, more than twice the arm's length ({length:.1} mm from {LENGTH_KEYS}): \
                     a centre of mass lies on its link",
                    inertial.com_mm.as_slice(),
                    i + 1
                ),
            ));
        }
    }
    if d.payload.mass_kg > 0.0 && d.payload.com_mm.norm() > 2.0 * length {
        return Err((
            "payload.com_mm".into(),
            format!(
                "{:.1} mm from the flange, more than twice the arm's length ({length:.1} mm from {LENGTH_KEYS})",
                d.payload.com_mm.norm()
            ),
        ));
    }
    // No arm outweighs a solid steel block of its own length on each side.
    let total: f64 = d.links_inertial.iter().map(|i| i.mass_kg).sum::<f64>() + d.payload.mass_kg;
    let most = STEEL_KG_M3 * (length * 1e-3).powi(3);
    if total > most {
        let heaviest = (0..JOINTS).max_by(|&a, &b| d.links_inertial[a].mass_kg.total_cmp(&d.links_inertial[b].mass_kg)).unwrap_or(0);
        return Err((
            format!("joint[{}].mass_kg", heaviest + 1),
            format!(
                "{} kg: the links (joint[1..6].mass_kg) and payload weigh {total:.1} kg, more than a solid steel cube as long as the arm \
                 ({length:.1} mm from {LENGTH_KEYS}: {most:.1} kg)",
                d.links_inertial[heaviest].mass_kg
            ),
        ));
    }
    deflection(model, "joint[{}].compliance_mdeg_per_nm")?;
    if file.truth.iter().any(|(id, _)| id.name().starts_with('c')) {
        let truth = file.truth_on(model).map_err(|e| ("truth".to_string(), e))?;
        deflection(&truth, "truth.c{}")?;
    }
    Ok(())
}

/// The configurations of the deflection check (see [`CONFIGURATIONS`]).
fn configurations(model: &RobotModel) -> impl Iterator<Item = Joints> + '_ {
    (0..CONFIGURATIONS).map(move |k| {
        std::array::from_fn(|i| {
            let l = model.limits()[i];
            let (lo, hi) = (l.min.max(-std::f64::consts::PI), l.max.min(std::f64::consts::PI));
            lo + (hi - lo) * (((k * (7 + 2 * i) + i * 13) % 61) as f64 / 60.0)
        })
    })
}

/// Refuses a compliance of `model` that bends its joint by more than [`MOST_DEFLECTION_DEG`] under
/// gravity; `key` is the compliance's key with `{}` for the joint.
fn deflection(model: &RobotModel, key: &str) -> Result<(), (String, String)> {
    let d = model.data();
    if d.links.iter().all(|l| l.compliance == 0.0) {
        return Ok(());
    }
    let mut worst = (0.0, 0, [0.0; JOINTS]);
    for q in configurations(model) {
        let tau = super::gravity_torques(model, &q);
        for i in 0..JOINTS {
            let bend = (d.links[i].compliance * tau[i]).abs().to_degrees();
            // A NaN bend (a compliance times an infinite torque) is the worst of all.
            if bend.is_nan() || bend > worst.0 {
                worst = (bend, i, q);
            }
        }
    }
    let (bend, i, q) = worst;
    if bend <= MOST_DEFLECTION_DEG {
        return Ok(());
    }
    let field = key.replace("{}", &(i + 1).to_string());
    let c = super::Unit::MdegPerNm.from_internal(d.links[i].compliance);
    let q_deg: Vec<String> = q.iter().map(|v| format!("{:.0}", v.to_degrees())).collect();
    let payload = if d.payload.mass_kg > 0.0 { " and payload.mass_kg" } else { "" };
    Err((
        field,
        format!(
            "{c} mdeg/(N m) with the masses it holds up (joint[{}..6].mass_kg and com_mm{payload}) bends joint {} by {bend:.2} deg \
             at q = [{}] deg: at most {MOST_DEFLECTION_DEG} deg (calsim's joint compliance is a small-angle model)",
            i + 1,
            i + 1,
            q_deg.join(", ")
        ),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pattern_spreads_every_joint_over_its_range() {
        let model = crate::robot::builtin::irb120();
        for i in 0..JOINTS {
            let l = model.limits()[i];
            let v: Vec<f64> = configurations(&model).map(|q| q[i]).collect();
            let (lo, hi) = (v.iter().copied().fold(f64::INFINITY, f64::min), v.iter().copied().fold(f64::NEG_INFINITY, f64::max));
            assert!(
                (lo - l.min.max(-std::f64::consts::PI)).abs() < 1e-12 && (hi - l.max.min(std::f64::consts::PI)).abs() < 1e-12,
                "joint {i}"
            );
        }
    }
}
