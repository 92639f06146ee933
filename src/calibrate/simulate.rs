//! A simulated measurement file in the layout of [`super::measurements`]: a virtual robot (true
//! parameters, optional effects outside the model, repeatability) measured at random poses in
//! several sessions (each with its own measuring frame) at several targets on the flange, with
//! instrument noise and chosen outliers; joint values written as the controller reports them
//! (through the inverse of a joint coupling). For the tests' round trips and the shipped example;
//! the file says `# simulated = true`.

use nalgebra::Vector3;
use rand_distr::{Distribution, Normal};

use super::measurements::file::MeasurementRow;
use crate::io::table::Frame;
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
    /// Sessions measured along a straight line, after `sessions` (default: none).
    pub lines: Vec<LineSession>,
    /// Targets moved on the flange in a session (a probe re-mounted): session label and the move
    /// in MDH frame 6, mm (default: none).
    pub moved: Vec<(String, Vector3<f64>)>,
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

/// A session whose one target is carried along a straight line at a fixed flange orientation
/// (a linear path, say): its poses from the inverse kinematics of the true robot, so its measured
/// positions lie on a line up to the noise and the effects outside the model.
#[derive(Clone, Debug, PartialEq)]
pub struct LineSession {
    /// Session label.
    pub label: String,
    /// `session_from_base` (eq. 7, mm and rad).
    pub frame: XyzZyx,
    /// The target carried (an index into `targets`).
    pub target: usize,
    /// The model's joint angles of the first pose, rad: the line starts at its target's position
    /// and keeps its flange orientation.
    pub start: Joints,
    /// The move from one pose to the next, in the base frame, mm.
    pub step_mm: Vector3<f64>,
    /// The flange's turn per pose, rad: pose k's flange orientation is the first pose's turned by
    /// `k` times these angles about the base's x, y and z axes (roll, pitch, yaw: about two axes
    /// or more, the axis of the turn varies along the line). Zero: a fixed orientation, under
    /// which the target's position on the flange and the session's translation move the points
    /// alike; about one axis, the target's component along that axis does.
    pub turn_rad: Vector3<f64>,
    /// Poses.
    pub poses: usize,
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
    /// The probe's measured orientation in the session's frame (`None`: not simulated).
    pub orientation: Option<nalgebra::UnitQuaternion<f64>>,
}

/// Orientation readings of six-degree-of-freedom probes: each target's probe frame on the flange
/// and the readings' noise.
#[derive(Clone, Debug, PartialEq)]
pub struct OrientationSim {
    /// Per target (in the order of [`SimulationSpec::targets`]): `flange_from_probe`, its rotation
    /// vector (axis times angle), rad.
    pub probe_rotations: Vec<Vector3<f64>>,
    /// Standard deviation of the reading's error about each axis of the session's frame, rad.
    pub noise_rad: f64,
}

/// The true orientation reading of `row`'s probe: the flange's rotation in the session's frame
/// (`model`: the truth with that session's frame, at the link angles `links`) times the probe's on
/// the flange, with its noise drawn from `rng`.
fn reading(
    o: &OrientationSim,
    model: &RobotModel,
    st: &mut KinState,
    links: &Joints,
    target: usize,
    rng: &mut impl rand::Rng,
) -> nalgebra::UnitQuaternion<f64> {
    let flange = crate::robot::world_from_flange(model, st, links).rotation;
    let probe = nalgebra::UnitQuaternion::from_scaled_axis(o.probe_rotations[target]);
    let noise = Normal::new(0.0, o.noise_rad).expect("a finite noise");
    let e = Vector3::from_fn(|_, _| noise.sample(rng));
    nalgebra::UnitQuaternion::from_scaled_axis(e) * flange * probe
}

/// The rows of `spec`: per session, its poses (drawn within the limits), each measured at every
/// target.
pub fn rows(spec: &SimulationSpec) -> Vec<SimulatedRow> {
    rows_with(spec, None)
}

/// [`rows`] with the probes' orientation readings of `orientation` (drawn from a stream of their
/// own: the positions are those of [`rows`]).
pub fn rows_with(spec: &SimulationSpec, orientation: Option<&OrientationSim>) -> Vec<SimulatedRow> {
    let mut orientation_rng = crate::seeds::stream(spec.seed, crate::seeds::calibrate::SIMULATED_ORIENTATION);
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
            let moved = spec.moved.iter().find(|(l, _)| l == session).map_or_else(Vector3::zeros, |(_, v)| *v);
            for (t, (target, tool)) in spec.targets.iter().enumerate() {
                let model = spec.truth.edited(|d| {
                    d.world_from_base = *frame;
                    d.flange_tcp_mm = tool + moved;
                });
                let model = model.expect("the truth with a session's frame and a target");
                let mut p = forward(&model, &mut st, &links);
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
                    orientation: orientation.map(|o| reading(o, &model, &mut st, &links, t, &mut orientation_rng)),
                });
            }
        }
    }
    let mut pose = spec.sessions.len() * per_session;
    for line in &spec.lines {
        let (target, tool) = &spec.targets[line.target];
        let placed = spec.truth.edited(|d| {
            d.world_from_base = XyzZyx::default();
            d.flange_tcp_mm = *tool;
        });
        let in_session = spec.truth.edited(|d| {
            d.world_from_base = line.frame;
            d.flange_tcp_mm = *tool;
        });
        let (Ok(placed), Ok(in_session)) = (placed, in_session) else { continue };
        let first = crate::robot::world_from_flange(&placed, &mut st, &line.start);
        let origin = first.transform_point(&(*tool).into()).coords;
        let mut seed = line.start;
        for k in 0..line.poses {
            let t = line.turn_rad * k as f64;
            let turn = nalgebra::UnitQuaternion::from_euler_angles(t.x, t.y, t.z);
            let at = nalgebra::Isometry3::from_parts((origin + line.step_mm * k as f64).into(), turn * first.rotation);
            // A pose beyond the arm's reach or limits ends the line.
            let Ok(q) = crate::robot::inverse(&placed, &at, &seed) else { break };
            if q.iter().zip(spec.truth.limits()).any(|(v, l)| *v < l.min || *v > l.max) {
                break;
            }
            seed = q;
            let links = robot.link_angles(&q, &from, &mut noise_rng);
            from = q;
            let p = forward(&in_session, &mut st, &links);
            let e = Vector3::from_fn(|_, _| noise.sample(&mut noise_rng));
            pose += 1;
            out.push(SimulatedRow {
                pose: format!("p{pose:03}"),
                session: line.label.clone(),
                target: target.clone(),
                q_controller: spec.coupling.as_ref().map_or(q, |c| c.controller_from_model(&q)),
                measured_mm: p + e,
                orientation: orientation.map(|o| reading(o, &in_session, &mut st, &links, line.target, &mut orientation_rng)),
            });
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
pub fn to_csv(spec: &SimulationSpec) -> std::io::Result<String> {
    to_csv_with(spec, None)
}

/// [`to_csv`] with the columns `quat_w, quat_x, quat_y, quat_z` of `orientation`'s readings.
pub fn to_csv_with(spec: &SimulationSpec, orientation: Option<&OrientationSim>) -> std::io::Result<String> {
    measurement_file(spec, orientation).map(|(_, text)| text)
}

/// The measurement file of `spec` (with `orientation`'s readings): its table and its text
/// ([`super::measurements::file::measurement_file`] of [`rows_with`]'s rows), the header lines
/// (`# simulated = true`, the format, the spec's comments) and then the table as CSV.
pub fn measurement_file(spec: &SimulationSpec, orientation: Option<&OrientationSim>) -> std::io::Result<(Frame, String)> {
    let mut header = vec!["simulated = true".to_string(), format!("format = {}", super::measurements::FORMAT)];
    header.extend(spec.comments.iter().cloned());
    let rows = rows_with(spec, orientation);
    let rows: Vec<MeasurementRow<'_>> = rows
        .iter()
        .map(|r| MeasurementRow {
            pose: &r.pose,
            session: &r.session,
            target: &r.target,
            split: None,
            q_deg: r.q_controller.map(f64::to_degrees),
            xyz_mm: Some(r.measured_mm.into()),
            quat: r.orientation.map(|o| [o.w, o.i, o.j, o.k]),
        })
        .collect();
    super::measurements::file::measurement_file(&header, &rows)
}

/// The measurement file's text of `spec`'s sessions and targets at `spec.poses_per_session` random
/// poses per session (the poses' stream keyed by `spec.seed`), every pose's link angles moved by
/// `error(q, rng)` (rad per joint, shared by the targets of a pose) and every coordinate by a
/// normal noise of `spec.noise_mm`, both drawn from `rng`; no repeats, outliers, effects or
/// coupling. The twin's round trips of a per-pose joint error (tests and examples).
#[doc(hidden)]
pub fn joint_error_csv<R: rand::Rng>(spec: &SimulationSpec, rng: &mut R, error: impl Fn(&Joints, &mut R) -> Joints) -> String {
    let mut poses = crate::seeds::stream(spec.seed, crate::seeds::calibrate::SIMULATED_POSES);
    let noise = Normal::new(0.0, spec.noise_mm).expect("a finite noise");
    let mut st = KinState::default();
    let mut text = format!("# simulated = true\n# format = {}\n", super::measurements::FORMAT);
    for c in &spec.comments {
        text += &format!("# {c}\n");
    }
    text += "pose,session,target,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,x_mm,y_mm,z_mm\n";
    for (s, (session, frame)) in spec.sessions.iter().enumerate() {
        for k in 0..spec.poses_per_session {
            let q = crate::robot::uniform_configuration(&spec.truth, spec.margin, &mut poses);
            let e = error(&q, rng);
            let links: Joints = std::array::from_fn(|j| q[j] + e[j]);
            for (target, tool) in &spec.targets {
                let model = spec
                    .truth
                    .edited(|d| {
                        d.world_from_base = *frame;
                        d.flange_tcp_mm = *tool;
                    })
                    .expect("the truth in a session's frame");
                let p = forward(&model, &mut st, &links) + Vector3::from_fn(|_, _| noise.sample(rng));
                let qd: Vec<String> = q.iter().map(|v| format!("{}", v.to_degrees())).collect();
                text +=
                    &format!("p{:03},{session},{target},{},{},{},{}\n", s * spec.poses_per_session + k + 1, qd.join(","), p.x, p.y, p.z);
            }
        }
    }
    text
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
        lines: vec![],
        moved: vec![],
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

/// A simulation file (`calsim simulate-measurements`, docs/calibrate.md): TOML, every key checked.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSpec {
    robot: String,
    seed: u64,
    poses_per_session: usize,
    #[serde(default = "default_margin")]
    margin: f64,
    noise_mm: f64,
    #[serde(default)]
    repeatability_mm: f64,
    #[serde(default)]
    payload_kg: f64,
    #[serde(default)]
    payload_com_mm: [f64; 3],
    #[serde(default)]
    comments: Vec<String>,
    #[serde(default)]
    session: Vec<RawSession>,
    #[serde(default)]
    target: Vec<RawTarget>,
    #[serde(default)]
    line: Vec<RawLine>,
    #[serde(default)]
    orientation: bool,
    #[serde(default)]
    orientation_noise_mdeg: f64,
}

fn default_margin() -> f64 {
    0.15
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSession {
    label: String,
    frame_mm_deg: [f64; 6],
    #[serde(default)]
    tool_moved_mm: [f64; 3],
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTarget {
    label: String,
    flange_mm: [f64; 3],
    #[serde(default)]
    probe_rotation_deg: [f64; 3],
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLine {
    label: String,
    frame_mm_deg: [f64; 6],
    target: String,
    start_deg: [f64; 6],
    step_mm: [f64; 3],
    #[serde(default)]
    turn_deg: [f64; 3],
    poses: usize,
}

/// Largest coordinate of a simulation file, mm (the measurement layout's own cap).
const MOST_SPEC_MM: f64 = 1e5;

/// A simulation file read: what to simulate and the robot file it measures.
#[derive(Clone, Debug)]
pub struct SpecFile {
    /// The simulation.
    pub spec: SimulationSpec,
    /// The robot file (its `[truth]`, with the file's payload, is the robot measured).
    pub robot: crate::robot::file::RobotFile,
    /// The probes' orientation readings (`orientation = true`; `None`: positions only).
    pub orientation: Option<OrientationSim>,
}

/// Reads the simulation file `path`; an error is one line naming the file, the key and what is
/// wrong.
pub fn read_spec(path: &std::path::Path) -> Result<SpecFile, String> {
    let err = |key: &str, message: String| format!("{}: {key}: {message}", path.display());
    let bytes = crate::io::read_bytes(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let text = String::from_utf8(bytes).map_err(|_| format!("{}: not UTF-8 text", path.display()))?;
    let raw: RawSpec =
        crate::io::toml_de::from_str(&text).map_err(|e| err(&crate::io::toml_position(&text, e.span()), e.message().replace('\n', " ")))?;
    let finite = |key: &str, v: &[f64], most: f64| -> Result<(), String> {
        match v.iter().find(|x| !(x.is_finite() && x.abs() <= most)) {
            Some(x) => Err(err(key, format!("{x}: a finite number within +-{most}"))),
            None => Ok(()),
        }
    };
    let label = |key: &str, l: &str| -> Result<String, String> {
        if l.is_empty() || l.chars().count() > 64 || l.chars().any(|c| c.is_control() || c == ',') {
            return Err(err(key, format!("{l:?}: a label of 1 to 64 printable characters, no comma")));
        }
        Ok(l.to_string())
    };
    let file = crate::device::scenario::relative_to(path, std::path::Path::new(&raw.robot));
    let robot = crate::robot::file::RobotFile::load(&file).map_err(|e| err("robot", e.to_string().replace('\n', " ")))?;
    finite("noise_mm", &[raw.noise_mm], 100.0)?;
    finite("repeatability_mm", &[raw.repeatability_mm], 100.0)?;
    if raw.noise_mm < 0.0 || raw.repeatability_mm < 0.0 {
        return Err(err("noise_mm", "noise and repeatability are at least 0".into()));
    }
    if !(raw.margin.is_finite() && (0.0..0.5).contains(&raw.margin)) {
        return Err(err("margin", format!("{}: a share of each joint range within [0, 0.5)", raw.margin)));
    }
    if !(raw.payload_kg.is_finite() && (0.0..=super::MOST_PAYLOAD_KG).contains(&raw.payload_kg)) {
        return Err(err("payload_kg", format!("{}: within 0 to {} kg", raw.payload_kg, super::MOST_PAYLOAD_KG)));
    }
    finite("payload_com_mm", &raw.payload_com_mm, super::MOST_PAYLOAD_COM_MM)?;
    if raw.comments.iter().any(|c| c.contains('\n') || c.contains('=') || c.chars().count() > 200) {
        return Err(err("comments", "a comment is one line of at most 200 characters without `=`".into()));
    }
    if raw.target.is_empty() {
        return Err(err("target", "no [[target]] (a label and its flange_mm per target on the flange)".into()));
    }
    if raw.session.is_empty() && raw.line.is_empty() {
        return Err(err("session", "no [[session]] and no [[line]]".into()));
    }
    let flange = |v: [f64; 3]| robot.flange.map_or(Vector3::from(v), |r| r * Vector3::from(v));
    let mut labels: Vec<String> = Vec::new();
    let mut targets = Vec::new();
    for (k, t) in raw.target.iter().enumerate() {
        let l = label(&format!("target[{}].label", k + 1), &t.label)?;
        finite(&format!("target[{}].flange_mm", k + 1), &t.flange_mm, MOST_SPEC_MM)?;
        if targets.iter().any(|(o, _)| *o == l) {
            return Err(err(&format!("target[{}].label", k + 1), format!("{l}: given twice")));
        }
        finite(&format!("target[{}].probe_rotation_deg", k + 1), &t.probe_rotation_deg, 360.0)?;
        targets.push((l, flange(t.flange_mm)));
    }
    if !raw.orientation && (raw.orientation_noise_mdeg != 0.0 || raw.target.iter().any(|t| t.probe_rotation_deg != [0.0; 3])) {
        return Err(err("orientation", "orientation_noise_mdeg and probe_rotation_deg need `orientation = true`".into()));
    }
    if !(raw.orientation_noise_mdeg.is_finite() && (0.0..=1e4).contains(&raw.orientation_noise_mdeg)) {
        return Err(err("orientation_noise_mdeg", format!("{}: within 0 to 10000 mdeg", raw.orientation_noise_mdeg)));
    }
    let orientation = raw.orientation.then(|| OrientationSim {
        probe_rotations: raw.target.iter().map(|t| flange_rotation(&robot, t.probe_rotation_deg)).collect(),
        noise_rad: (raw.orientation_noise_mdeg * 1e-3).to_radians(),
    });
    let frame = |key: &str, v: [f64; 6]| -> Result<XyzZyx, String> {
        finite(key, &v[..3], MOST_SPEC_MM)?;
        finite(key, &v[3..], 360.0)?;
        Ok(XyzZyx::from_mm_deg(v))
    };
    let mut sessions = Vec::new();
    let mut moved = Vec::new();
    for (k, s) in raw.session.iter().enumerate() {
        let key = |f: &str| format!("session[{}].{f}", k + 1);
        let l = label(&key("label"), &s.label)?;
        finite(&key("tool_moved_mm"), &s.tool_moved_mm, 1000.0)?;
        if labels.contains(&l) {
            return Err(err(&key("label"), format!("{l}: given twice")));
        }
        labels.push(l.clone());
        sessions.push((l.clone(), frame(&key("frame_mm_deg"), s.frame_mm_deg)?));
        if s.tool_moved_mm != [0.0; 3] {
            moved.push((l, flange(s.tool_moved_mm)));
        }
    }
    let mut lines = Vec::new();
    for (k, s) in raw.line.iter().enumerate() {
        let key = |f: &str| format!("line[{}].{f}", k + 1);
        let l = label(&key("label"), &s.label)?;
        if labels.contains(&l) {
            return Err(err(&key("label"), format!("{l}: given twice (sessions and lines)")));
        }
        labels.push(l.clone());
        let target = targets
            .iter()
            .position(|(t, _)| *t == s.target)
            .ok_or_else(|| err(&key("target"), format!("{}: not a [[target]] label", s.target)))?;
        finite(&key("start_deg"), &s.start_deg, 1080.0)?;
        finite(&key("step_mm"), &s.step_mm, 1000.0)?;
        finite(&key("turn_deg"), &s.turn_deg, 30.0)?;
        if !(super::measurements::MIN_POSES_PER_SESSION..=100_000).contains(&s.poses) {
            return Err(err(&key("poses"), format!("{}: within {} to 100000", s.poses, super::measurements::MIN_POSES_PER_SESSION)));
        }
        lines.push(LineSession {
            label: l,
            frame: frame(&key("frame_mm_deg"), s.frame_mm_deg)?,
            target,
            start: s.start_deg.map(f64::to_radians),
            step_mm: Vector3::from(s.step_mm),
            turn_rad: Vector3::from(s.turn_deg.map(f64::to_radians)),
            poses: s.poses,
        });
    }
    let rows =
        raw.poses_per_session.saturating_mul(sessions.len()).saturating_mul(targets.len()) + lines.iter().map(|l| l.poses).sum::<usize>();
    if (!sessions.is_empty() && raw.poses_per_session < super::measurements::MIN_POSES_PER_SESSION) || rows > super::measurements::MAX_ROWS
    {
        return Err(err(
            "poses_per_session",
            format!(
                "{}: at least {} per session and at most {} rows in all",
                raw.poses_per_session,
                super::measurements::MIN_POSES_PER_SESSION,
                super::measurements::MAX_ROWS
            ),
        ));
    }
    let truth = robot.truth_on(&robot.nominal).map_err(|e| err("robot", format!("its [truth]: {e}")))?;
    let com6 = flange(raw.payload_com_mm);
    let truth = truth
        .edited(|d| d.payload = crate::robot::Inertial { mass_kg: raw.payload_kg, com_mm: com6 })
        .map_err(|e| err("payload_kg", e.to_string()))?;
    let mut comments = vec![format!("joints = {}", if robot.coupling.is_some() { "controller" } else { "model" })];
    comments.extend(raw.comments.iter().map(|c| format!("SIMULATED: {c}")));
    let spec = SimulationSpec {
        truth,
        unmodelled: crate::robot::UnmodelledSpec::default(),
        repeatability_mm: raw.repeatability_mm,
        learned: None,
        repeats_per_session: 0,
        coupling: robot.coupling.clone(),
        sessions,
        targets,
        lines,
        moved,
        poses_per_session: raw.poses_per_session,
        margin: raw.margin,
        noise_mm: raw.noise_mm,
        outliers: vec![],
        seed: raw.seed,
        comments,
    };
    Ok(SpecFile { spec, robot, orientation })
}

/// The probe's rotation on the flange, given as the rotation vector `v` (deg) of `flange_from_probe`
/// in the robot file's flange frame, as `frame6_from_probe`'s rotation vector, rad.
fn flange_rotation(robot: &crate::robot::file::RobotFile, v: [f64; 3]) -> Vector3<f64> {
    let r = nalgebra::Rotation3::new(Vector3::from(v.map(f64::to_radians)));
    robot.flange.map_or(r, |f| nalgebra::Rotation3::from_matrix_unchecked(f * r.matrix())).scaled_axis()
}
