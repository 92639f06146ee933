//! A simulated measurement file in the layout of [`super::measurements`]: a virtual robot (true
//! parameters, optional effects outside the model, repeatability) measured at random poses in
//! several sessions (each with its own measuring frame) at several targets on the flange, with
//! instrument noise and chosen outliers; joint values written as the controller reports them
//! (through the inverse of a joint coupling). For the tests' round trips and the shipped example;
//! the file says `# simulated = true`.

use nalgebra::Vector3;
use rand_distr::{Distribution, Normal};

use crate::robot::coupling::JointCoupling;
use crate::robot::{Joints, KinState, RobotModel, UnmodelledSpec, VirtualRobot, XyzZyx, forward};

/// What to simulate.
#[derive(Clone, Debug)]
pub struct SimulationSpec {
    /// The true robot (its base and tool are replaced by each session's and target's).
    pub truth: RobotModel,
    /// Effects outside the model (default: none).
    pub unmodelled: UnmodelledSpec,
    /// ISO 9283 repeatability of the moves, mm (0: none).
    pub repeatability_mm: f64,
    /// Effects a twin carries (`[learned]`: harmonics, backlash, sag, per-pose error, a drift of
    /// the base over each session's poses), drawn once with their standard deviations (`None`: none).
    pub learned: Option<crate::robot::learned::LearnedEffects>,
    /// Poses each session visits again after its `poses_per_session`: its first ones, in order,
    /// at the same joint values (0: none).
    pub repeats_per_session: usize,
    /// The controller's coupling (`None`: it reports the model's joint angles).
    pub coupling: Option<JointCoupling>,
    /// Sessions: label and `session_from_base` (eq. 7, mm and rad).
    pub sessions: Vec<(String, XyzZyx)>,
    /// Targets: label and position in MDH frame 6, mm.
    pub targets: Vec<(String, Vector3<f64>)>,
    /// Poses per session.
    pub poses_per_session: usize,
    /// Fraction of each joint range kept clear at both ends.
    pub margin: f64,
    /// Instrument noise per coordinate, mm.
    pub noise_mm: f64,
    /// Outliers: row index (0-based, file order) and the error added, mm.
    pub outliers: Vec<(usize, Vector3<f64>)>,
    /// Seed of the poses and noise streams.
    pub seed: u64,
    /// Comment lines of the header (without `#`), after `# simulated = true`.
    pub comments: Vec<String>,
}

/// One simulated row.
#[derive(Clone, Debug, PartialEq)]
pub struct SimulatedRow {
    /// Pose label.
    pub pose: String,
    /// Session label.
    pub session: String,
    /// Target label.
    pub target: String,
    /// The controller's joint values, rad.
    pub q_controller: Joints,
    /// The measured position in the session's frame, mm.
    pub measured_mm: Vector3<f64>,
}

/// The rows of `spec`: per session, its poses (drawn within the limits), each measured at every
/// target.
pub fn rows(spec: &SimulationSpec) -> Vec<SimulatedRow> {
    let mut poses = crate::seeds::stream(spec.seed, crate::seeds::calibrate::SIMULATED_POSES);
    let mut noise_rng = crate::seeds::stream(spec.seed, crate::seeds::calibrate::SIMULATED_NOISE);
    let reference: Joints = std::array::from_fn(|i| {
        let l = spec.truth.limits()[i];
        0.5 * (l.min + l.max)
    });
    let robot = VirtualRobot::new(spec.truth.clone(), &spec.unmodelled, spec.repeatability_mm, &reference, &mut noise_rng)
        .with_learned(spec.learned.as_ref(), &mut noise_rng);
    let drift = robot.learned.as_ref().map_or([0.0; 3], |l| l.drift_mm_per_pose);
    let noise = Normal::new(0.0, spec.noise_mm).expect("a finite noise");
    let mut st = KinState::default();
    let mut out = Vec::new();
    let mut from = reference;
    let per_session = spec.poses_per_session + spec.repeats_per_session;
    for (s, (session, frame)) in spec.sessions.iter().enumerate() {
        let mut visited: Vec<Joints> = Vec::with_capacity(spec.poses_per_session);
        for k in 0..per_session {
            let q = if k < spec.poses_per_session {
                let q = crate::robot::uniform_configuration(&spec.truth, spec.margin, &mut poses);
                visited.push(q);
                q
            } else {
                visited[(k - spec.poses_per_session) % visited.len().max(1)]
            };
            let links = robot.link_angles(&q, &from, &mut noise_rng);
            from = q;
            // The base's drift over the session, in the session's frame.
            let shifted = drift.iter().any(|&d| d != 0.0).then(|| frame.isometry().rotation * (Vector3::from(drift) * k as f64));
            for (target, tool) in &spec.targets {
                let model = spec.truth.edited(|d| {
                    d.world_from_base = *frame;
                    d.flange_tcp_mm = *tool;
                });
                let mut p = forward(&model.expect("the truth with a session's frame and a target"), &mut st, &links);
                if let Some(d) = shifted {
                    p += d;
                }
                let e = Vector3::from_fn(|_, _| noise.sample(&mut noise_rng));
                out.push(SimulatedRow {
                    pose: format!("p{:03}", s * per_session + k + 1),
                    session: session.clone(),
                    target: target.clone(),
                    q_controller: spec.coupling.as_ref().map_or(q, |c| c.controller_from_model(&q)),
                    measured_mm: p + e,
                });
            }
        }
    }
    for (row, error) in &spec.outliers {
        if let Some(r) = out.get_mut(*row) {
            r.measured_mm += error;
        }
    }
    out
}

/// The measurement file's text of `spec`'s rows (every number written to round-trip exactly).
pub fn to_csv(spec: &SimulationSpec) -> String {
    let mut s = String::from("# simulated = true\n");
    s.push_str(&format!("# format = {}\n", super::measurements::FORMAT));
    for c in &spec.comments {
        s.push_str(&format!("# {c}\n"));
    }
    s.push_str("pose,session,target,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,x_mm,y_mm,z_mm\n");
    for r in rows(spec) {
        let q: Vec<String> = r.q_controller.iter().map(|v| format!("{}", v.to_degrees())).collect();
        s.push_str(&format!(
            "{},{},{},{},{},{},{}\n",
            r.pose,
            r.session,
            r.target,
            q.join(","),
            r.measured_mm.x,
            r.measured_mm.y,
            r.measured_mm.z
        ));
    }
    s
}

/// The shipped example (`docs/calibrate/example_measurements.csv`): the IRB 120 of `irb120` (a
/// loaded `robots/irb120.toml`; its `[truth]`, Table 7, is the robot measured) in three laser
/// tracker placements, two SMRs on the flange, 40 poses per placement, one outlier.
pub fn example_spec(irb120: &crate::robot::file::RobotFile) -> Result<SimulationSpec, String> {
    let truth = irb120.truth_on(&irb120.nominal)?;
    let frame = |x, y, z, a: f64, b: f64, g: f64| XyzZyx { x, y, z, alpha: a.to_radians(), beta: b.to_radians(), gamma: g.to_radians() };
    Ok(SimulationSpec {
        truth,
        // ASSUMED: the TriCal scenario's unmodelled harmonic (2.82 mdeg per joint, FITTED there to
        // Table 8's median) and ISO 9283 repeatability (0.010 mm, SOURCED: the IRB 120 data sheet).
        unmodelled: UnmodelledSpec { transmission_high_mdeg: 2.82, ..UnmodelledSpec::default() },
        repeatability_mm: 0.010,
        learned: None,
        repeats_per_session: 0,
        coupling: None,
        // ASSUMED: three tracker placements about 2 m around the robot, levelled to 0.5 deg.
        sessions: vec![
            ("A".into(), frame(1850.0, -300.0, -400.0, 170.0, 0.3, -0.2)),
            ("B".into(), frame(1200.0, 1500.0, -350.0, -110.0, -0.4, 0.5)),
            ("C".into(), frame(-900.0, -1700.0, -420.0, 60.0, 0.2, 0.1)),
        ],
        // ASSUMED: two SMR nests on a plate on the flange.
        targets: vec![("SMR1".into(), Vector3::new(30.0, 0.0, 40.0)), ("SMR2".into(), Vector3::new(-25.0, 35.0, 45.0))],
        poses_per_session: 40,
        margin: 0.15,
        // ASSUMED: the TriCal scenario's tracker at 2 m (range 8.8 um, transverse 12 um), as 12 um per coordinate.
        noise_mm: 0.012,
        // A point 0.8 mm off (a beam re-acquired on a dusty SMR, say).
        outliers: vec![(57, Vector3::new(0.8, -0.3, 0.2))],
        seed: 35,
        comments: vec![
            "robot = ABB IRB 120-3/0.58 (robots/irb120.toml; the robot measured is its [truth], Table 7 of the TriCal paper)".into(),
            "frame = laser tracker frame of each session (three placements)".into(),
            "joints = controller".into(),
            "SIMULATED by calsim (calibrate::simulate::example_spec, cargo run --example calibrate_example): unmodelled harmonic 2.82 mdeg per joint,".into(),
            "repeatability 0.010 mm, tracker noise 0.012 mm per coordinate, one outlier of 0.88 mm on the 58th row.".into(),
        ],
    })
}
