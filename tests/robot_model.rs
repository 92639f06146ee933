//! The virtual IRB 120: forward kinematics, gravity torques against the reference vectors, the
//! analytic Jacobian against central differences, and the named parameter sets.

mod common;

use calsim::robot::builtin::{TABLE7_MEANS, irb120, trical_2018_nominal, trical_2018_table7};
use calsim::robot::{
    DeviationSpec, Inertial, JOINTS, KinState, ParamId, ParamSet, RobotModel, deviate, gravity_torques, tcp_jacobian, tcp_world,
    world_from_flange,
};
use nalgebra::Vector3;
use rand::RngExt;
use serde::Deserialize;

#[test]
fn nominal_irb120_at_zero_puts_the_flange_at_374_0_630() {
    let model = irb120();
    let p = tcp_world(&model, &[0.0; JOINTS]);
    assert!((p - Vector3::new(374.0, 0.0, 630.0)).norm() < 1e-12, "flange at {p}");
    // ABB tool0 orientation at home: x_flange = -z_base, z_flange = +x_base (irb120.toml).
    let f = world_from_flange(&model, &mut KinState::default(), &[0.0; JOINTS]);
    let r = f.rotation.to_rotation_matrix();
    assert!((r * Vector3::x() - Vector3::new(0.0, 0.0, -1.0)).norm() < 1e-12);
    assert!((r * Vector3::z() - Vector3::new(1.0, 0.0, 0.0)).norm() < 1e-12);
}

#[derive(Deserialize)]
struct Reference {
    gravity_test: Vec<GravityTest>,
}

#[derive(Deserialize)]
struct GravityTest {
    q_deg: [f64; 6],
    #[serde(rename = "tau_Nm")]
    tau: [f64; 6],
    #[serde(rename = "tau_payload1kg_Nm")]
    tau_payload: [f64; 6],
}

#[test]
fn gravity_torques_match_the_reference_vectors_to_1e5_nm() {
    let text = std::fs::read_to_string(common::reference("irb120.toml")).expect("reference/irb120.toml");
    let reference: Reference = toml::from_str(&text).expect("reference file parses");
    assert_eq!(reference.gravity_test.len(), 5);
    let bare = irb120();
    // The reference payload: 1 kg at (0, 0, 122) mm in its frame 6, which sits 72 mm below the
    // flange; frame 6 here is the flange (Table 3, d6 = 72), so the same point is (0, 0, 50).
    let loaded = bare.edited(|d| d.payload = Inertial { mass_kg: 1.0, com_mm: Vector3::new(0.0, 0.0, 50.0) }).unwrap();
    for case in &reference.gravity_test {
        let q = case.q_deg.map(f64::to_radians);
        for (model, expected) in [(&bare, &case.tau), (&loaded, &case.tau_payload)] {
            let tau = gravity_torques(model, &q);
            for i in 0..JOINTS {
                assert!((tau[i] - expected[i]).abs() < 1e-5, "q = {:?} deg, joint {}: {} vs {}", case.q_deg, i + 1, tau[i], expected[i]);
            }
        }
    }
}

#[test]
fn compliance_deflects_joints_along_the_gravity_load() {
    // Negative c (Table 7) and the holding-torque convention: the arm sags.
    let rigid = trical_2018_nominal();
    let soft = rigid.edited(|d| d.links[1].compliance = -1e-3).unwrap();
    let q = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    assert!(tcp_world(&soft, &q).z < tcp_world(&rigid, &q).z - 1e-3);
}

/// Central-difference derivative of the TCP in {W} with respect to one parameter.
fn central_difference(model: &RobotModel, id: ParamId, q: &[f64; 6]) -> Vector3<f64> {
    let h = match id.unit() {
        calsim::robot::Unit::Mm => 1e-4,
        calsim::robot::Unit::Deg => 1e-6,
        // 0.57 mdeg/(N m): round-off stays below 1e-8 relative on the small c6 column, truncation too.
        calsim::robot::Unit::MdegPerNm => 1e-5,
    };
    let x = id.get(model.data());
    let at = |v: f64| tcp_world(&model.edited(|d| id.set(d, v)).unwrap(), q);
    (at(x + h) - at(x - h)) / (2.0 * h)
}

#[test]
fn analytic_jacobian_matches_central_differences_for_every_parameter() {
    let all = ParamSet::new(ParamId::all()).unwrap();
    let mut rng = common::rng(11);
    let mut worst = 0.0_f64;
    let mut checked = 0;
    for trial in 0..6 {
        // A perturbed IRB 120 with a payload and every parameter moved, compliance included.
        let base = trical_2018_nominal();
        let model = deviate(&base, &all, &DeviationSpec { length_mm: 0.5, angle_deg: 0.2, compliance_mdeg_per_nm: 30.0 }, &mut rng);
        let model = if trial % 2 == 1 { model.edited(|d| d.gravity_base = Vector3::new(0.3, -0.2, -9.8)).unwrap() } else { model };
        for q in common::random_configs(&model, 8, &mut rng) {
            let mut cols = vec![Vector3::zeros(); all.len()];
            tcp_jacobian(&model, &mut KinState::default(), &q, &all, &mut cols);
            for (id, col) in all.ids().iter().zip(&cols) {
                let fd = central_difference(&model, *id, &q);
                let rel = (col - fd).norm() / fd.norm().max(1e-6);
                worst = worst.max(rel);
                checked += 1;
                assert!(rel < 1e-6, "{id} at q = {q:?}: analytic {col} vs central {fd} (relative {rel:e})");
            }
        }
    }
    assert_eq!(checked, 6 * 8 * 45);
    eprintln!("worst relative difference over {checked} columns: {worst:e}");
}

#[test]
fn jacobian_columns_follow_the_order_of_the_set() {
    let model = trical_2018_table7();
    let set = ParamSet::trical_31();
    let reversed = ParamSet::new(set.ids().iter().rev().copied().collect()).unwrap();
    let q = [0.3, 0.2, -0.4, 1.0, 0.7, -2.0];
    let (_, a) = calsim::robot::tcp_jacobian_matrix(&model, &q, &set);
    let (_, b) = calsim::robot::tcp_jacobian_matrix(&model, &q, &reversed);
    for j in 0..set.len() {
        assert_eq!(a.column(j), b.column(set.len() - 1 - j));
    }
}

#[test]
fn the_default_set_is_table7_in_order_and_packs_and_unpacks() {
    let set = ParamSet::trical_31();
    assert_eq!(set.len(), 31);
    let expected: Vec<String> = TABLE7_MEANS.iter().map(|(n, _)| n.to_string()).collect();
    assert_eq!(set.names(), expected);
    let truth = trical_2018_table7();
    let packed = set.pack(&truth);
    for ((name, mean), v) in TABLE7_MEANS.iter().zip(packed.iter()) {
        let id = ParamId::parse(name).unwrap();
        assert!((id.unit().from_internal(*v) - mean).abs() < 1e-12, "{name}");
    }
    let back = set.unpack(&trical_2018_nominal(), packed.as_slice()).unwrap();
    assert_eq!(back.data(), truth.data());
    assert!(set.unpack(&truth, &[0.0; 3]).is_err());
}

#[test]
fn any_parameter_can_be_freed_or_fixed_by_name() {
    for id in ParamId::all() {
        assert_eq!(ParamId::parse(&id.name()), Some(id), "{id}");
    }
    let set = ParamSet::trical_31().freed(ParamId::parse("d2").unwrap()).freed(ParamId::parse("xT6").unwrap());
    assert_eq!(set.len(), 33);
    assert_eq!(set.clone().fixed(ParamId::parse("c6").unwrap()).len(), 32);
    assert!(ParamSet::from_names(&["a1", "a1"]).is_err());
    assert!(matches!(ParamSet::from_names(&["a9"]), Err(calsim::robot::ParamError::Unknown(_))));
    assert!(ParamId::parse("theta_offs0").is_none());
}

#[test]
fn one_model_serves_many_threads() {
    let model = trical_2018_table7();
    let mut rng = common::rng(3);
    let qs = common::random_configs(&model, 64, &mut rng);
    let serial: Vec<_> = qs.iter().map(|q| tcp_world(&model, q)).collect();
    let parallel: Vec<_> = std::thread::scope(|s| {
        let handles: Vec<_> = qs.chunks(16).map(|c| s.spawn(|| c.iter().map(|q| tcp_world(&model, q)).collect::<Vec<_>>())).collect();
        handles.into_iter().flat_map(|h| h.join().unwrap()).collect()
    });
    assert_eq!(serial, parallel);
    let _: f64 = rng.random();
}
