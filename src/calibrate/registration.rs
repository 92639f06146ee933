//! Before the fit: where each session's measuring frame is and where each target sits on the
//! flange (the start values of the bases and tools), and which robot parameters the measured
//! poses can separate from them (the rest are named and kept at their nominal values).

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};

use super::problem::{Layout, Problem};
use crate::robot::{KinState, RobotModel, world_from_flange};

/// Alternations of registration and tool estimate at most (each is a few microseconds per point).
const MOST_ALTERNATIONS: usize = 200;
/// The alternation stops when no tool moves by more than this, mm.
const TOOL_TOL_MM: f64 = 1e-9;
/// A singular value of the column-scaled Jacobian below this fraction of the largest counts as
/// zero: the rank tolerance of the identification's least squares (`FitOptions::rank_rtol`).
pub const RANK_RTOL: f64 = 1e-6;
/// A parameter takes part in a null direction when at least this share of its unit vector lies in
/// the null space (the rule of `identify::observability::structurally_unidentifiable`).
const NULL_SHARE: f64 = 0.01;

/// A measured point for the registration: the model's joint angles, the position in its
/// session's frame (mm), its session and target.
#[derive(Clone, Copy, Debug)]
pub struct Raw {
    /// Joint angles, rad.
    pub q: crate::robot::Joints,
    /// Measured position in the session's frame, mm.
    pub measured_mm: Vector3<f64>,
    /// Session index.
    pub session: usize,
    /// Target index.
    pub target: usize,
}

/// A session or target the registration cannot place.
#[derive(Clone, Debug, PartialEq)]
pub enum Unplaced {
    /// The session's points do not fix a rigid transform (fewer than 3 distinct, or collinear).
    Session(usize),
    /// The target has no point.
    Target(usize),
}

/// Each session's `session_from_base` and each target's position in MDH frame 6 (mm).
pub type Frames = (Vec<Isometry3<f64>>, Vec<Vector3<f64>>);

/// The start values of the frames: `session_from_base` per session (the measuring frame from the
/// robot's base) and each target's position in MDH frame 6 (mm), by alternating a rigid
/// registration of every session (Kabsch, SVD of the cross-covariance) and the tools' linear
/// least squares, from `tool0` for every target, on the model `nominal` (its base ignored).
pub fn register(nominal: &RobotModel, points: &[Raw], sessions: usize, targets: usize, tool0: Vector3<f64>) -> Result<Frames, Unplaced> {
    let at_origin = nominal.edited(|d| d.world_from_base = Default::default()).expect("the nominal model with its base at the origin");
    let mut st = KinState::default();
    let flanges: Vec<Isometry3<f64>> = points.iter().map(|p| world_from_flange(&at_origin, &mut st, &p.q)).collect();
    let mut tools = vec![tool0; targets];
    let mut frames = vec![Isometry3::identity(); sessions];
    for _ in 0..MOST_ALTERNATIONS {
        for (s, frame) in frames.iter_mut().enumerate() {
            let pairs: Vec<(Vector3<f64>, Vector3<f64>)> = points
                .iter()
                .zip(&flanges)
                .filter(|(p, _)| p.session == s)
                .map(|(p, f)| ((f * nalgebra::Point3::from(tools[p.target])).coords, p.measured_mm))
                .collect();
            *frame = kabsch(&pairs).ok_or(Unplaced::Session(s))?;
        }
        let mut moved: f64 = 0.0;
        for (t, tool) in tools.iter_mut().enumerate() {
            // measured = R_s (R_f tool + o_f) + t_s, so tool = R_f^T (R_s^T (measured - t_s) - o_f),
            // averaged over the target's points (every R_f^T R_s^T is a rotation).
            let mut sum = Vector3::zeros();
            let mut n = 0.0;
            for (p, f) in points.iter().zip(&flanges).filter(|(p, _)| p.target == t) {
                let in_base = frames[p.session].inverse_transform_point(&p.measured_mm.into()).coords;
                sum += f.rotation.inverse_transform_vector(&(in_base - f.translation.vector));
                n += 1.0;
            }
            if n == 0.0 {
                return Err(Unplaced::Target(t));
            }
            let new = sum / n;
            moved = moved.max((new - *tool).norm());
            *tool = new;
        }
        if moved < TOOL_TOL_MM {
            break;
        }
    }
    Ok((frames, tools))
}

/// The rigid transform `T` minimising `sum |T a - b|^2` over the pairs `(a, b)` (Kabsch); `None`
/// when the points `a` are fewer than 3 or collinear.
pub fn kabsch(pairs: &[(Vector3<f64>, Vector3<f64>)]) -> Option<Isometry3<f64>> {
    if pairs.len() < 3 {
        return None;
    }
    let n = pairs.len() as f64;
    let ca = pairs.iter().map(|p| p.0).sum::<Vector3<f64>>() / n;
    let cb = pairs.iter().map(|p| p.1).sum::<Vector3<f64>>() / n;
    let h: Matrix3<f64> = pairs.iter().map(|(a, b)| (a - ca) * (b - cb).transpose()).sum();
    let svd = crate::numeric::svd3(h)?;
    let (u, v_t) = (svd.u?, svd.v_t?);
    let s = &svd.singular_values;
    // Collinear points leave two singular values at zero: no rotation about their line is fixed.
    let mut sorted = [s[0], s[1], s[2]];
    sorted.sort_by(|a, b| b.total_cmp(a));
    if !(sorted[0] > 0.0 && sorted[1] > 1e-9 * sorted[0]) {
        return None;
    }
    let d = (v_t.transpose() * u.transpose()).determinant().signum();
    let r = v_t.transpose() * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * u.transpose();
    let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    let t = cb - rotation * ca;
    Some(Isometry3::from_parts(Translation3::from(t), rotation))
}

/// A robot parameter the poses cannot separate, and the unknowns it moves the points alike with.
#[derive(Clone, Debug, PartialEq)]
pub struct Unidentifiable {
    /// The parameter.
    pub name: String,
    /// The other unknowns in its null direction (robot parameters, `base[...]`, `tool[...]`).
    pub with: Vec<String>,
}

/// Why the frames cannot be fitted.
#[derive(Clone, Debug, PartialEq)]
pub struct FramesUnidentifiable {
    /// The base and tool unknowns in the null space (e.g. `base[B].gamma`).
    pub names: Vec<String>,
}

/// The robot parameters of `layout` the points `idx` can separate, at `x`, from each other and
/// from the bases and tools: the column-scaled Jacobian's null space (singular values below
/// [`RANK_RTOL`] of the largest) is emptied greedily by fixing, each time, the robot parameter with
/// the largest share in it. Returns the kept set and the parameters fixed; an error when the null
/// space holds base or tool unknowns only (a session or target the poses do not fix).
pub fn prune(
    problem: &Problem<'_>,
    x: &[f64],
    idx: &[usize],
    labels: (&[String], &[String]),
) -> Result<(crate::robot::ParamSet, Vec<Unidentifiable>), FramesUnidentifiable> {
    let layout = &problem.layout;
    let names = layout.names(labels.0, labels.1);
    let Some((_, j)) = problem.linearise(x, idx) else {
        return Err(FramesUnidentifiable { names: vec!["(the start model gives no finite prediction)".into()] });
    };
    let mut kept: Vec<usize> = (0..layout.len()).collect();
    let mut fixed = Vec::new();
    loop {
        let mut js = j.select_columns(&kept);
        for mut c in js.column_iter_mut() {
            let n = c.norm();
            if n > 0.0 {
                c.unscale_mut(n);
            }
        }
        let shares = crate::identify::observability::null_space_shares(js, RANK_RTOL)
            .ok_or_else(|| FramesUnidentifiable { names: vec!["(the SVD of the calibration Jacobian did not converge)".into()] })?;
        let involved: Vec<usize> = (0..kept.len()).filter(|&k| shares[k] >= NULL_SHARE).collect();
        if involved.is_empty() {
            break;
        }
        let robot = layout.robot.len();
        let Some(&worst) = involved.iter().filter(|&&k| kept[k] < robot).max_by(|&&a, &&b| shares[a].total_cmp(&shares[b]).then(a.cmp(&b)))
        else {
            return Err(FramesUnidentifiable { names: involved.iter().map(|&k| names[kept[k]].clone()).collect() });
        };
        let with = involved.iter().filter(|&&k| k != worst).map(|&k| names[kept[k]].clone()).collect();
        fixed.push(Unidentifiable { name: names[kept[worst]].clone(), with });
        kept.remove(worst);
    }
    let ids = kept.iter().filter(|&&c| c < layout.robot.len()).map(|&c| layout.robot.ids()[c]).collect();
    Ok((crate::robot::ParamSet::new(ids).expect("a subset of a set"), fixed))
}

/// The layout with the robot set `robot` (same sessions and targets).
pub fn with_robot(layout: &Layout, robot: crate::robot::ParamSet) -> Layout {
    Layout { robot, ..layout.clone() }
}
