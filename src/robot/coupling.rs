//! Joint coupling: a controller that reports a joint's angle as a combination of the arm's joint
//! angles (FANUC reports J3 against the horizon, so the arm's joint 3 is J3 minus J2). The robot
//! file's optional `[[coupling]]` rows give the model's joint angle as a linear combination of the
//! controller's joint values; joints without a row are the controller's value itself.
//!
//! ```toml
//! [[coupling]]
//! joint = 3                                   # the model's (MDH) joint, 1..6
//! controller = [0.0, -1.0, 1.0, 0.0, 0.0, 0.0]  # theta_3 = -q2 + q3 (controller values)
//! ```
//!
//! The combination is dimensionless (degrees of the model per degree of the controller); the
//! joint-zero offsets stay in the modified-DH table (`theta_offset_deg`), after the coupling.

use nalgebra::Matrix6;
use serde::{Deserialize, Serialize};

use super::model::{JOINTS, Joints};

/// Largest coupling coefficient a robot file takes (a gear ratio between joints of a serial arm
/// is of order 1).
const MOST_COEFFICIENT: f64 = 10.0;

/// Smallest `|det|` of the coupling matrix: below it the controller's values do not determine the
/// arm's angles to the precision a calibration needs.
const LEAST_DETERMINANT: f64 = 1e-6;

/// One `[[coupling]]` row of a robot file.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CouplingRow {
    /// The model's joint, 1-based.
    pub joint: usize,
    /// Coefficients of the controller's joint values 1..6, deg per deg.
    pub controller: [f64; JOINTS],
}

/// The linear map from the controller's joint values to the model's joint angles.
#[derive(Clone, Debug, PartialEq)]
pub struct JointCoupling {
    /// `theta = model_from_controller * q`.
    model_from_controller: Matrix6<f64>,
    /// Its inverse.
    controller_from_model: Matrix6<f64>,
    /// The rows as the file gave them (written back into exported robot files).
    rows: Vec<CouplingRow>,
}

impl JointCoupling {
    /// The coupling of `rows` (the robot file's `[[coupling]]`); an error names the row's field.
    pub fn from_rows(rows: &[CouplingRow]) -> Result<Self, (String, String)> {
        let mut m = Matrix6::identity();
        let mut seen = [false; JOINTS];
        for (k, row) in rows.iter().enumerate() {
            let at = |key: &str| format!("coupling[{}].{key}", k + 1);
            if !(1..=JOINTS).contains(&row.joint) {
                return Err((at("joint"), format!("{}: the model's joints are 1 to {JOINTS}", row.joint)));
            }
            if std::mem::replace(&mut seen[row.joint - 1], true) {
                return Err((at("joint"), format!("joint {} has a coupling row already", row.joint)));
            }
            for (j, c) in row.controller.iter().enumerate() {
                if !(c.is_finite() && c.abs() <= MOST_COEFFICIENT) {
                    return Err((format!("{}[{j}]", at("controller")), format!("{c}: a finite number within +-{MOST_COEFFICIENT}")));
                }
            }
            for (j, c) in row.controller.iter().enumerate() {
                m[(row.joint - 1, j)] = *c;
            }
        }
        let det = m.determinant();
        if det.abs() < LEAST_DETERMINANT {
            return Err((
                "coupling".into(),
                format!("the rows make a singular map (determinant {det:e}): the controller's values would not determine the joint angles"),
            ));
        }
        let inverse = m.try_inverse().ok_or_else(|| ("coupling".to_string(), "the rows make a singular map".to_string()))?;
        Ok(Self { model_from_controller: m, controller_from_model: inverse, rows: rows.to_vec() })
    }

    /// The model's joint angles (rad) from the controller's joint values (rad).
    pub fn model_from_controller(&self, q: &Joints) -> Joints {
        let v = self.model_from_controller * nalgebra::Vector6::from_column_slice(q);
        std::array::from_fn(|i| v[i])
    }

    /// The controller's joint values (rad) that give the model's joint angles `theta` (rad).
    pub fn controller_from_model(&self, theta: &Joints) -> Joints {
        let v = self.controller_from_model * nalgebra::Vector6::from_column_slice(theta);
        std::array::from_fn(|i| v[i])
    }

    /// The controller's joints (0-based) that the model's joint `joint` (0-based) depends on.
    pub fn inputs_of(&self, joint: usize) -> Vec<usize> {
        (0..JOINTS).filter(|&j| self.model_from_controller[(joint, j)] != 0.0).collect()
    }

    /// The rows, as a robot file gives them.
    pub fn rows(&self) -> &[CouplingRow] {
        &self.rows
    }

    /// The `[[coupling]]` tables of a robot file for these rows (appended to a robot file's text).
    pub fn to_text(&self) -> String {
        #[derive(Serialize)]
        struct Rows<'a> {
            coupling: &'a [CouplingRow],
        }
        toml::to_string(&Rows { coupling: &self.rows }).unwrap_or_default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fanuc_style_coupling_round_trips_between_controller_and_model() {
        let c = JointCoupling::from_rows(&[CouplingRow { joint: 3, controller: [0.0, -1.0, 1.0, 0.0, 0.0, 0.0] }]).unwrap();
        let q = [0.1, 0.4, -0.3, 0.2, -0.5, 1.0];
        let theta = c.model_from_controller(&q);
        assert_eq!(theta[2], -0.4 + -0.3);
        assert_eq!([theta[0], theta[1], theta[3], theta[4], theta[5]], [q[0], q[1], q[3], q[4], q[5]]);
        let back = c.controller_from_model(&theta);
        for i in 0..JOINTS {
            assert!((back[i] - q[i]).abs() < 1e-15, "joint {}", i + 1);
        }
        assert_eq!(c.inputs_of(2), vec![1, 2]);
    }

    #[test]
    fn singular_repeated_or_absurd_coupling_rows_are_refused_naming_the_field() {
        let row = |joint, controller| CouplingRow { joint, controller };
        let singular = JointCoupling::from_rows(&[row(3, [0.0, 1.0, 0.0, 0.0, 0.0, 0.0])]).unwrap_err();
        assert_eq!(singular.0, "coupling");
        let twice = JointCoupling::from_rows(&[row(3, [0.0, 1.0, 1.0, 0.0, 0.0, 0.0]), row(3, [0.0; 6])]).unwrap_err();
        assert_eq!(twice.0, "coupling[2].joint");
        let absurd = JointCoupling::from_rows(&[row(2, [0.0, 1.0, f64::NAN, 0.0, 0.0, 0.0])]).unwrap_err();
        assert_eq!(absurd.0, "coupling[1].controller[2]");
        let joint = JointCoupling::from_rows(&[row(7, [0.0; 6])]).unwrap_err();
        assert_eq!(joint.0, "coupling[1].joint");
    }
}
