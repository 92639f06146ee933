//! Built-in robots: the ABB IRB 120 of the TriCal paper and the EFORT ER20-C10 of the SPMS paper.
//!
//! Sources: the modified-DH table is Table 3 of the 2018 paper (d6 = 72 mm puts frame 6 on the
//! flange); limits, masses and centres of mass are from `shared/reference/irb120.toml`, which cites
//! the ROS-Industrial URDF for each (CAD estimates without the cable harness). The identified values
//! are the means of the paper's Table 7.

use std::f64::consts::{FRAC_PI_2, PI};

use nalgebra::Vector3;

use super::model::{Inertial, JointLimit, Link, RobotData, RobotModel, XyzZyx};
use super::params::{ParamId, ParamSet};

/// Standard gravity used by the reference torque vectors, m/s^2 (irb120.toml `gravity_m_s2`).
pub const GRAVITY_M_S2: f64 = 9.81;

/// Link masses (kg) and centres of mass in MDH frame i (mm), irb120.toml `[[link]] mdh_com_mm`.
/// Link 6's z is shifted by -72 mm: the file puts frame 6 at the wrist with d6 = 0 and the flange at
/// Tz(72), Table 3 puts frame 6 on the flange with d6 = 72.
const IRB120_INERTIALS: [(f64, [f64; 3]); 6] = [
    (3.067, [0.098, -0.12, -51.59]),
    (3.909, [101.24, 0.78, -2.12]),
    (2.944, [57.91, 22.81, 1.06]),
    (1.328, [0.41, -0.15, -77.3]),
    (0.546, [0.062, -1.09, 0.037]),
    (0.137, [0.001, -0.17, 64.94 - 72.0]),
];

/// Joint limits, deg (irb120.toml `q_min_deg`, `q_max_deg`, from the URDF).
const IRB120_LIMITS_DEG: [(f64, f64); 6] =
    [(-165.0, 165.0), (-110.0, 110.0), (-110.0, 70.0), (-160.0, 160.0), (-120.0, 120.0), (-400.0, 400.0)];

/// Table 3 of the 2018 paper: (alpha_{i-1} deg, a_{i-1} mm, d_i mm, theta_offs_i deg).
const IRB120_MDH: [(f64, f64, f64, f64); 6] = [
    (0.0, 0.0, 290.0, 0.0),
    (-90.0, 0.0, 0.0, -90.0),
    (0.0, 270.0, 0.0, 0.0),
    (-90.0, 70.0, 302.0, 0.0),
    (90.0, 0.0, 0.0, 0.0),
    (-90.0, 0.0, 72.0, 180.0),
];

/// The nominal IRB 120: Table 3, base frame = world frame, TCP on the flange, no payload.
pub fn irb120() -> RobotModel {
    let links = IRB120_MDH.map(|(alpha, a, d, off)| Link {
        alpha: alpha.to_radians(),
        a,
        beta: 0.0,
        theta_offset: off.to_radians(),
        d,
        compliance: 0.0,
    });
    let data = RobotData {
        name: "ABB IRB 120-3/0.58".into(),
        links,
        world_from_base: XyzZyx::default(),
        flange_tcp_mm: Vector3::zeros(),
        limits: IRB120_LIMITS_DEG.map(|(lo, hi)| JointLimit { min: lo.to_radians(), max: hi.to_radians() }),
        links_inertial: IRB120_INERTIALS.map(|(m, c)| Inertial { mass_kg: m, com_mm: Vector3::from(c) }),
        payload: Inertial::NONE,
        gravity_base: Vector3::new(0.0, 0.0, -GRAVITY_M_S2),
    };
    RobotModel::new(data).expect("the built-in IRB 120 is valid")
}

/// TCP of the TriCal device in the flange frame, mm. ASSUMED: the paper measures it on a CMM but
/// does not print it. It is placed off the axis of joint 6 so that theta_offs6, which the paper
/// identifies, moves the TCP (on the axis it would not).
pub const TRICAL_TCP_MM: [f64; 3] = [35.0, 0.0, 125.0];

/// Mass of the TriCal device (conical aluminium bracket, three ID-C112XB indicators with their
/// U-WAVE-T transmitters), kg, and its centre of mass in the flange frame, mm. ASSUMED: the paper
/// prints neither; the centre of mass is off the axis of joint 6, which is what gives c6 a torque
/// to act on (the paper identifies c6 = -44.6 mdeg/(N m) with a 7 % spread).
pub const TRICAL_PAYLOAD: (f64, [f64; 3]) = (1.0, [20.0, 0.0, 60.0]);

/// `world_from_base` before calibration: the "Nominal" column of Table 7 (mm, deg).
pub const TRICAL_NOMINAL_BASE: [f64; 6] = [160.211, -255.727, -220.548, 91.603, 0.496, -1.384];

/// Table 7 means, in the units of [`ParamId::unit`] (mm, deg, mdeg/(N m)), in Table 7 order.
pub const TABLE7_MEANS: [(&str, f64); 31] = [
    ("alpha1", -90.034),
    ("alpha2", -0.045),
    ("alpha3", -90.011),
    ("alpha4", 89.998),
    ("alpha5", -89.990),
    ("a1", 0.013),
    ("a2", 270.146),
    ("a3", 70.120),
    ("a4", -0.075),
    ("a5", -0.012),
    ("d3", -0.094),
    ("d4", 302.296),
    ("d5", 0.019),
    ("d6", 72.163),
    ("theta_offs2", -89.910),
    ("theta_offs3", 0.097),
    ("theta_offs4", -0.013),
    ("theta_offs5", 0.062),
    ("theta_offs6", 180.259),
    ("c2", -2.060),
    ("c3", -5.522),
    ("c4", -33.738),
    ("c5", -30.448),
    ("c6", -44.555),
    ("beta2", 0.039),
    ("x0W", 158.865),
    ("y0W", -253.835),
    ("z0W", -219.170),
    ("alpha0W", 91.677),
    ("beta0W", 0.148),
    ("gamma0W", -1.380),
];

/// The IRB 120 as the controller believes it before calibration in the TriCal cell: Table 3, the
/// nominal base of Table 7, the TriCal device as tool and payload (assumed values, see above).
pub fn trical_2018_nominal() -> RobotModel {
    irb120()
        .edited(|d| {
            d.world_from_base = XyzZyx::from_mm_deg(TRICAL_NOMINAL_BASE);
            d.flange_tcp_mm = Vector3::from(TRICAL_TCP_MM);
            d.payload = Inertial { mass_kg: TRICAL_PAYLOAD.0, com_mm: Vector3::from(TRICAL_PAYLOAD.1) };
        })
        .expect("valid")
}

/// The IRB 120 the paper measured: [`trical_2018_nominal`] with the 31 parameters set to the
/// Table 7 means (compliance included).
pub fn trical_2018_table7() -> RobotModel {
    let set = ParamSet::trical_31();
    let values: Vec<f64> =
        TABLE7_MEANS.iter().map(|(name, v)| ParamId::parse(name).expect("Table 7 names are valid").unit().to_internal(*v)).collect();
    debug_assert_eq!(set.names(), TABLE7_MEANS.iter().map(|(n, _)| n.to_string()).collect::<Vec<_>>());
    set.unpack(&trical_2018_nominal(), &values).expect("valid")
}

/// Table 7 standard deviations over 30 optimised sets of 75, in the order and units of
/// [`TABLE7_MEANS`] (printed to three decimals: 0.000 means below 0.0005).
pub const TABLE7_STD: [f64; 31] = [
    0.001, 0.001, 0.001, 0.000, 0.001, 0.008, 0.004, 0.007, 0.001, 0.003, 0.004, 0.011, 0.002, 0.003, 0.004, 0.002, 0.001, 0.001, 0.001,
    0.099, 0.149, 0.611, 0.527, 3.047, 0.001, 0.006, 0.013, 0.017, 0.001, 0.003, 0.000,
];

/// ER20-C10 modified-DH rows 1-5 as printed in Table 4 of the SPMS paper (before calibration):
/// (alpha_{i-1} rad, a_{i-1} mm, d_i mm). Row 6 is not printed: see [`ER20C10_ROW6`].
const ER20C10_TABLE4: [(f64, f64, f64); 5] =
    [(0.0, 0.0, 504.0), (-FRAC_PI_2, 166.605, 0.0), (0.0, -782.270, 0.0), (-FRAC_PI_2, 138.826, 761.350), (FRAC_PI_2, 0.0, 0.0)];

/// Row 6 of the ER20-C10 (alpha5 rad, a5 mm, d6 mm). ASSUMED: the paper prints joints 1-5 only;
/// alpha5 = -pi/2 completes the usual spherical wrist and d6 = 100 mm puts frame 6 on the flange
/// (not published; any value serves, the flange-to-sphere offset is identified with it).
pub const ER20C10_ROW6: (f64, f64, f64) = (-FRAC_PI_2, 0.0, 100.0);

/// Table 5 (after calibration): a_{i-1} mm, d_i mm and delta theta_i rad of joints 1-5.
pub const ER20C10_TABLE5: [(f64, f64, f64); 5] =
    [(0.0, 504.0, 0.0), (167.648, 0.0, 1.39e-2), (-780.753, 0.0, 1.92e-4), (139.918, 759.330, 3.84e-4), (0.0, 0.0, 6.63e-4)];

/// Joint zero of the ER20-C10, rad: theta_i = q_i + offset_i + delta theta_i. ASSUMED: Table 4 prints
/// only the deviations delta theta (zero before calibration), not the zero convention; with these
/// offsets q = 0 is the usual home (upper arm vertical, forearm horizontal, flange facing forward).
pub const ER20C10_ZERO_RAD: [f64; 6] = [0.0, FRAC_PI_2, PI, 0.0, 0.0, 0.0];

/// ER20-C10 joint limits, deg, from q = 0 at [`ER20C10_ZERO_RAD`]. ASSUMED: the paper prints none;
/// typical of 20 kg, 1.7 m arms.
const ER20C10_LIMITS_DEG: [(f64, f64); 6] =
    [(-170.0, 170.0), (-90.0, 150.0), (-80.0, 170.0), (-180.0, 180.0), (-125.0, 125.0), (-360.0, 360.0)];

/// The ER20-C10 as its controller believes it before calibration: Table 4, joint 6 completed by
/// [`ER20C10_ROW6`]. Rigid (no compliance), no masses: the SPMS paper identifies kinematics only,
/// so link masses play no part and are left at zero (ASSUMED).
pub fn er20c10_table4() -> RobotModel {
    let mut rows = [(0.0, 0.0, 0.0); 6];
    rows[..5].copy_from_slice(&ER20C10_TABLE4);
    rows[5] = ER20C10_ROW6;
    let data = RobotData {
        name: "EFORT ER20-C10".into(),
        links: std::array::from_fn(|i| {
            let (alpha, a, d) = rows[i];
            Link { alpha, a, beta: 0.0, theta_offset: ER20C10_ZERO_RAD[i], d, compliance: 0.0 }
        }),
        world_from_base: XyzZyx::default(),
        flange_tcp_mm: Vector3::zeros(),
        limits: ER20C10_LIMITS_DEG.map(|(lo, hi)| JointLimit { min: lo.to_radians(), max: hi.to_radians() }),
        links_inertial: [Inertial::NONE; 6],
        payload: Inertial::NONE,
        gravity_base: Vector3::new(0.0, 0.0, -GRAVITY_M_S2),
    };
    RobotModel::new(data).expect("the built-in ER20-C10 is valid")
}

/// [`er20c10_table4`] with a, d and delta theta of joints 1-5 set to Table 5. `with_dtheta2 = false`
/// leaves delta theta_2 (1.39e-2 rad) out: see the SPMS scenario for why.
pub fn er20c10_table5(with_dtheta2: bool) -> RobotModel {
    er20c10_table4()
        .edited(|d| {
            for (i, (link, &(a, dd, dt))) in d.links.iter_mut().zip(&ER20C10_TABLE5).enumerate() {
                link.a = a;
                link.d = dd;
                link.theta_offset = ER20C10_ZERO_RAD[i] + if i == 1 && !with_dtheta2 { 0.0 } else { dt };
            }
        })
        .expect("valid")
}
