//! The virtual robot: model data, named parameters, kinematics, statics and built-in robots.

pub mod builtin;
pub mod capsule_fit;
pub mod file;
pub mod fk;
pub mod ik;
pub mod kinematics;
#[cfg(target_arch = "x86_64")]
mod kinematics_avx;
mod kinematics_batch;
pub mod mesh;
pub mod model;
pub mod params;
pub mod rotation;
pub mod state;
pub mod statics;
#[cfg(test)]
mod test_models;
pub mod truth;
pub mod urdf;
pub mod virtual_robot;

pub use ik::{IkError, inverse};
pub use kinematics::{forward, tcp_jacobian, tcp_jacobian_matrix, tcp_world, world_from_base, world_from_flange};
pub use kinematics_batch::{tcp_jacobians_transposed, tcps_world};
pub use model::{Inertial, JOINTS, JointLimit, Joints, Link, ModelError, RobotData, RobotModel, XyzZyx};
pub use params::{BaseParam, LinkParam, ParamError, ParamId, ParamSet, Unit};
pub use state::KinState;
pub use statics::gravity_torques;
pub use truth::{DeviationSpec, SpreadSpec, deviate, perturb};
pub use virtual_robot::{UnmodelledSpec, VirtualRobot};
