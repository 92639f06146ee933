//! The virtual robot's truth: a model with deviations from the nominal.
//!
//! Deviations come from a table (the paper's Table 7, [`crate::robot::builtin::trical_2018_table7`])
//! or are drawn per parameter type for populations of robots ([`DeviationSpec`]).

use rand::Rng;
use rand_distr::{Distribution, Normal};
use serde::Deserialize;

use super::model::RobotModel;
use super::params::{LinkParam, ParamId, ParamSet, Unit};

/// Standard deviations of random deviations per parameter type, in the units at the edges.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DeviationSpec {
    /// Lengths (a, d, base x y z, tool), mm.
    pub length_mm: f64,
    /// Angles (alpha, beta, theta_offs, base angles), deg.
    pub angle_deg: f64,
    /// Joint compliances, mdeg/(N m). Drawn as `-|N(0, s)|`: a physical stiffness gives a
    /// negative compliance in calsim's sign convention (see [`crate::robot::kinematics::statics`]).
    pub compliance_mdeg_per_nm: f64,
}

impl DeviationSpec {
    /// The magnitudes used for robot populations in the core tests: 0.2 mm, 0.05 deg, 20 mdeg/(N m).
    pub const TYPICAL: DeviationSpec = DeviationSpec { length_mm: 0.2, angle_deg: 0.05, compliance_mdeg_per_nm: 20.0 };
}

/// `nominal` with every parameter of `set` moved by a random deviation drawn from `spec`.
pub fn deviate<R: Rng + ?Sized>(nominal: &RobotModel, set: &ParamSet, spec: &DeviationSpec, rng: &mut R) -> RobotModel {
    moved(nominal, set, rng, |id, z| match (id, id.unit()) {
        (ParamId::Link { kind: LinkParam::Compliance, .. }, _) => Unit::MdegPerNm.to_internal(-(z * spec.compliance_mdeg_per_nm).abs()),
        (_, Unit::Mm) => z * spec.length_mm,
        (_, Unit::Deg) => Unit::Deg.to_internal(z * spec.angle_deg),
        (_, Unit::MdegPerNm) => Unit::MdegPerNm.to_internal(z * spec.compliance_mdeg_per_nm),
    })
}

/// `model` with every parameter of `set` moved by `delta(parameter, z)`, `z` a standard normal
/// draw per parameter in the order of the set.
fn moved<R: Rng + ?Sized>(model: &RobotModel, set: &ParamSet, rng: &mut R, delta: impl Fn(&ParamId, f64) -> f64) -> RobotModel {
    let std = Normal::new(0.0, 1.0).expect("unit normal");
    let values: Vec<f64> = set
        .ids()
        .iter()
        .map(|id| {
            let z: f64 = std.sample(rng);
            id.get(model.data()) + delta(id, z)
        })
        .collect();
    set.unpack(model, &values).expect("finite deviations keep the model valid")
}

/// The spread of a robot's parameters around the scenario's truth, one standard deviation per
/// parameter type (`[robot.spread]`): each world (realisation) of a study draws its own robot.
/// Zero everywhere (the default) keeps the scenario's truth.
#[derive(Clone, Copy, Debug, Default, Deserialize, serde::Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct SpreadSpec {
    /// Lengths (a, d, base x y z, tool), mm.
    pub length_mm: f64,
    /// Angles (alpha, beta, theta_offs, base angles), deg.
    pub angle_deg: f64,
    /// Joint compliances, mdeg/(N m).
    pub compliance_mdeg_per_nm: f64,
}

impl SpreadSpec {
    /// Whether every spread is zero.
    pub fn is_zero(&self) -> bool {
        self.length_mm == 0.0 && self.angle_deg == 0.0 && self.compliance_mdeg_per_nm == 0.0
    }
}

/// `truth` with every parameter of `set` moved by a zero-mean normal draw of its type's spread
/// (symmetric, unlike [`deviate`], which builds populations away from a nominal); `truth` itself
/// when the spread is zero, without drawing.
pub fn perturb<R: Rng + ?Sized>(truth: &RobotModel, set: &ParamSet, spread: &SpreadSpec, rng: &mut R) -> RobotModel {
    if spread.is_zero() {
        return truth.clone();
    }
    moved(truth, set, rng, |id, z| match (id, id.unit()) {
        (ParamId::Link { kind: LinkParam::Compliance, .. }, _) | (_, Unit::MdegPerNm) => {
            Unit::MdegPerNm.to_internal(z * spread.compliance_mdeg_per_nm)
        }
        (_, Unit::Mm) => z * spread.length_mm,
        (_, Unit::Deg) => Unit::Deg.to_internal(z * spread.angle_deg),
    })
}
