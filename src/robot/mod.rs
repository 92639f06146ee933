//! The virtual robot: model data, named parameters, kinematics, statics and built-in robots.

pub mod builtin;
pub mod capsule_fit;
pub mod coupling;
pub mod export;
pub mod file;
pub mod fk;
pub mod ik;
pub mod kinematics;
pub mod learned;
pub mod mesh;
pub mod model;
pub mod params;
pub mod plausible;
pub mod rotation;
#[cfg(test)]
mod test_models;
pub mod truth;
pub mod urdf;
pub mod virtual_robot;

pub use ik::{IkError, inverse};
pub use kinematics::{
    AngleSines, KinState, angle_sines, forward, gravity_torques, tcp_jacobian, tcp_jacobian_matrix, tcp_jacobians_transposed,
    tcp_jacobians_transposed_by, tcp_world, tcps_world, tcps_world_by, world_from_base, world_from_flange,
};
pub use learned::{LearnedEffects, LearnedHarmonic};
pub use model::{Inertial, JOINTS, JointLimit, Joints, Link, ModelError, RobotData, RobotModel, XyzZyx, uniform_configuration};
pub use params::{BaseParam, LinkParam, ParamError, ParamId, ParamSet, Unit};
pub use truth::{DeviationSpec, SpreadSpec, deviate, perturb};
pub use virtual_robot::{UnmodelledSpec, VirtualRobot};
