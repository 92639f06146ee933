//! Before the fit: where each session's measuring frame is and where each target sits on the
//! flange (the start values of the bases and tools), and which robot parameters the measured
//! poses can separate from them (the rest are named and kept at their nominal values).

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};

use super::problem::{Fit, Layout};
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
    /// The session's points do not fix a rigid transform (fewer than 3 points).
    Session(usize),
    /// The target has no point.
    Target(usize),
}

/// Each session's `session_from_base`, each target's position in MDH frame 6 (mm) and what each
/// session's points fix of its frame.
pub type Frames = (Vec<Isometry3<f64>>, Vec<Vector3<f64>>, Vec<Span>);

/// A direction counts as spanned by a session's points when their RMS spread along it is at least
/// this share of the arm's length (`robot::plausible::arm_length_mm`): 1 %, about 5 to 20 mm on
/// arms of 0.5 to 2 m, far above a tracker's noise and a robot's errors before calibration (a
/// line measured on an uncalibrated arm wanders by those) and far below any volume or plane a
/// calibration measures.
pub const SPAN_SHARE: f64 = 0.01;

/// What a session's measured points fix of its frame (the rotation of the measuring frame from
/// the robot's base): the points' spread, by [`SPAN_SHARE`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Span {
    /// Spread in two directions or more: the whole frame.
    Full,
    /// On a line (its unit direction in the session's measuring frame): no rotation about it
    /// (turning the frame about the line moves none of its points).
    Line(Vector3<f64>),
    /// At one position: no rotation at all (turning the frame about the position moves nothing).
    Point,
}

impl Span {
    /// The columns of a session's base block (eq. 7's order: `x, y, z, alpha` about z, `beta`
    /// about y, `gamma` about x) its points do not fix, kept at the registration: none for
    /// [`Span::Full`]; for a line, the rotation about the base axis nearest the line's direction
    /// (with it fixed, no turn about the line is left, and no other turn is lost); for a point,
    /// the three rotations. `session_from_base` is the session's registration.
    pub fn still(self, session_from_base: &Isometry3<f64>) -> [bool; 6] {
        match self {
            Span::Full => [false; 6],
            Span::Point => [false, false, false, true, true, true],
            Span::Line(d) => {
                let d = session_from_base.rotation.inverse_transform_vector(&d);
                // Base axis x, y, z: the rotations gamma (column 5), beta (4), alpha (3).
                let axis = (0..3).max_by(|&a, &b| d[a].abs().total_cmp(&d[b].abs())).unwrap_or(2);
                let mut still = [false; 6];
                still[5 - axis] = true;
                still
            }
        }
    }

    /// What the points fix, in words (for reports and errors).
    pub fn describe(self) -> &'static str {
        match self {
            Span::Full => "its points fix its frame",
            Span::Line(_) => "its points lie on a line: the rotation about the line is not fixed",
            Span::Point => "its points are at one position: no rotation is fixed",
        }
    }
}

/// What the points `b` (measured, in one session's frame) fix of a frame: their RMS spreads along
/// their principal directions against `least_mm`.
pub fn span(b: &[Vector3<f64>], least_mm: f64) -> Span {
    if b.is_empty() {
        return Span::Point;
    }
    let n = b.len() as f64;
    let c = b.iter().sum::<Vector3<f64>>() / n;
    let scatter: Matrix3<f64> = b.iter().map(|p| (p - c) * (p - c).transpose()).sum::<Matrix3<f64>>() / n;
    let eig = scatter.symmetric_eigen();
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let spread = |k: usize| eig.eigenvalues[order[k]].max(0.0).sqrt();
    if spread(0) < least_mm {
        Span::Point
    } else if spread(1) < least_mm {
        Span::Line(eig.eigenvectors.column(order[0]).into_owned().normalize())
    } else {
        Span::Full
    }
}

/// The start values of the frames: `session_from_base` per session (the measuring frame from the
/// robot's base) and each target's position in MDH frame 6 (mm), by alternating a rigid
/// registration of every session (Kabsch, SVD of the cross-covariance; [`place`] for a session
/// whose points fix no whole frame) and the tools' linear least squares, from `tool0` for every
/// target, on the model `nominal` (its base ignored); with each session's [`Span`].
pub fn register(nominal: &RobotModel, points: &[Raw], sessions: usize, targets: usize, tool0: Vector3<f64>) -> Result<Frames, Unplaced> {
    use rayon::prelude::*;
    let at_origin = nominal.edited(|d| d.world_from_base = Default::default()).expect("the nominal model with its base at the origin");
    let flanges: Vec<Isometry3<f64>> =
        points.par_iter().map_init(KinState::default, |st, p| world_from_flange(&at_origin, st, &p.q)).collect();
    // Each session's and each target's points, in the order of `points`.
    let (mut of_session, mut of_target) = (vec![Vec::new(); sessions], vec![Vec::new(); targets]);
    for (i, p) in points.iter().enumerate() {
        of_session[p.session].push(i);
        of_target[p.target].push(i);
    }
    let least_mm = SPAN_SHARE * crate::robot::plausible::arm_length_mm(nominal);
    let spans: Vec<Span> =
        of_session.par_iter().map(|idx| span(&idx.iter().map(|&i| points[i].measured_mm).collect::<Vec<_>>(), least_mm)).collect();
    let mut tools = vec![tool0; targets];
    let mut frames = vec![Isometry3::identity(); sessions];
    for _ in 0..MOST_ALTERNATIONS {
        let placed: Vec<Option<Isometry3<f64>>> = of_session
            .par_iter()
            .zip(&spans)
            .map(|(idx, span)| {
                let pairs: Vec<(Vector3<f64>, Vector3<f64>)> = idx
                    .iter()
                    .map(|&i| ((flanges[i] * nalgebra::Point3::from(tools[points[i].target])).coords, points[i].measured_mm))
                    .collect();
                place(&pairs, *span)
            })
            .collect();
        for (s, (frame, new)) in frames.iter_mut().zip(placed).enumerate() {
            *frame = new.ok_or(Unplaced::Session(s))?;
        }
        // measured = R_s (R_f tool + o_f) + t_s, so tool = R_f^T (R_s^T (measured - t_s) - o_f),
        // averaged over the target's points (every R_f^T R_s^T is a rotation).
        let estimates: Vec<Option<Vector3<f64>>> = of_target
            .par_iter()
            .map(|idx| {
                let mut sum = Vector3::zeros();
                let mut n = 0.0;
                for &i in idx {
                    let (p, f) = (&points[i], &flanges[i]);
                    let in_base = frames[p.session].inverse_transform_point(&p.measured_mm.into()).coords;
                    sum += f.rotation.inverse_transform_vector(&(in_base - f.translation.vector));
                    n += 1.0;
                }
                (n != 0.0).then(|| sum / n)
            })
            .collect();
        let mut moved: f64 = 0.0;
        for (t, (tool, new)) in tools.iter_mut().zip(estimates).enumerate() {
            let new = new.ok_or(Unplaced::Target(t))?;
            moved = moved.max((new - *tool).norm());
            *tool = new;
        }
        if moved < TOOL_TOL_MM {
            break;
        }
    }
    Ok((frames, tools, spans))
}

/// The rigid transform `T` minimising `sum |T a - b|^2` over the pairs `(a, b)` as far as the
/// points `b` fix it (`span`): Kabsch for a whole frame; for a line, the smallest rotation that
/// turns the principal direction of the `a` onto that of the `b`, then the translation; for a
/// point, no rotation, the translation of the centroids. `None` for no pair, or a Kabsch of
/// fewer than 3 or collinear `a`.
pub fn place(pairs: &[(Vector3<f64>, Vector3<f64>)], span: Span) -> Option<Isometry3<f64>> {
    if pairs.is_empty() {
        return None;
    }
    let n = pairs.len() as f64;
    let ca = pairs.iter().map(|p| p.0).sum::<Vector3<f64>>() / n;
    let cb = pairs.iter().map(|p| p.1).sum::<Vector3<f64>>() / n;
    let rotation = match span {
        Span::Full => return kabsch(pairs),
        Span::Point => UnitQuaternion::identity(),
        Span::Line(db) => {
            let scatter: Matrix3<f64> = pairs.iter().map(|(a, _)| (a - ca) * (a - ca).transpose()).sum();
            let eig = scatter.symmetric_eigen();
            let k = (0..3).max_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b])).unwrap_or(0);
            let da = eig.eigenvectors.column(k).into_owned();
            // The sign of the measured direction that goes with the predicted one.
            let along: f64 = pairs.iter().map(|(a, b)| (a - ca).dot(&da) * (b - cb).dot(&db)).sum();
            let db = if along < 0.0 { -db } else { db };
            UnitQuaternion::rotation_between(&da, &db).unwrap_or_else(|| {
                // Opposite directions: half a turn about any axis across them.
                let across = da.cross(&Vector3::x()).try_normalize(1e-6).unwrap_or_else(|| da.cross(&Vector3::y()).normalize());
                UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_unchecked(across), std::f64::consts::PI)
            })
        }
    };
    Some(Isometry3::from_parts(Translation3::from(cb - rotation * ca), rotation))
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

/// Shares of a null direction within this fraction of the largest are a tie: of robot parameters
/// tied for the largest share, the last in the parameter list is fixed first. Two parameters
/// confounded alike with the frames (the joint-6 offset with each target's rotation about the
/// flange axis, `d6` with each target's height along it: half of each null direction's length
/// each) then are named in the same order whatever the rounding of the factorisation.
pub const TIE_RTOL: f64 = 1e-6;

/// The robot parameters of `layout` the points `idx` can separate, at `x`, from each other and
/// from the bases and tools: the column-scaled Jacobian's null space (singular values below
/// [`RANK_RTOL`] of the largest) is emptied greedily by fixing, each time, the robot parameter with
/// the largest share in it (ties by [`TIE_RTOL`]: the last in the parameter list). The singular
/// values and directions are those of the Jacobian's triangular factor ([`Fit::r_factor`]: the
/// same as the Jacobian's, from a factorisation of its rows done once). Returns the kept set and
/// the parameters fixed; an error when the null space holds base or tool unknowns only (a session
/// or target the poses do not fix).
pub fn prune<P: Fit + ?Sized>(
    problem: &P,
    x: &[f64],
    idx: &[usize],
    labels: (&[String], &[String]),
) -> Result<(crate::robot::ParamSet, Vec<Unidentifiable>), FramesUnidentifiable> {
    let layout = &problem.positions().layout;
    let mut names = layout.names(labels.0, labels.1);
    names.extend(problem.own_names(labels.1));
    let Some(r) = problem.r_factor(x, idx) else {
        return Err(FramesUnidentifiable { names: vec!["(the start model gives no finite prediction)".into()] });
    };
    let still: Vec<usize> = (0..layout.sessions)
        .flat_map(|s| (layout.base(s)..layout.base(s) + 6).filter(move |c| !layout.base_columns(s).any(|f| f == *c)))
        .collect();
    let mut kept: Vec<usize> = (0..problem.unknowns()).filter(|c| !still.contains(c)).collect();
    let mut fixed = Vec::new();
    loop {
        let mut js = r.select_columns(&kept);
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
        let top = involved.iter().filter(|&&k| kept[k] < robot).map(|&k| shares[k]).fold(f64::NEG_INFINITY, f64::max);
        let Some(&worst) = involved.iter().filter(|&&k| kept[k] < robot && shares[k] >= top * (1.0 - TIE_RTOL)).max() else {
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A frame and points measured in it: `pairs` of (position in the base frame, measured).
    fn measured(frame: &Isometry3<f64>, base: &[Vector3<f64>]) -> Vec<(Vector3<f64>, Vector3<f64>)> {
        base.iter().map(|a| (*a, (frame * nalgebra::Point3::from(*a)).coords)).collect()
    }

    /// The joint-6 offset and d6 are confounded alike with a tool per target (half of each null
    /// direction's length each): prune names the joint-6 offset first, then d6, by the tie rule of
    /// [`TIE_RTOL`], and the same with the points in the reverse order (another rounding of the
    /// factorisation); nothing else is named. The rigid IRB 120's geometric set (no compliance: no
    /// deflection that hangs on the tool), 2 sessions, 3 targets, 300 points.
    #[test]
    fn confounded_parameters_tied_for_the_largest_share_are_named_by_the_parameter_list() {
        use crate::robot::{LinkParam, ParamId, ParamSet};
        use rand::SeedableRng;
        let model = crate::robot::builtin::irb120();
        let robot = ParamSet::new(
            ParamSet::trical_31()
                .ids()
                .iter()
                .copied()
                .filter(|id| !matches!(id, ParamId::Base(_) | ParamId::Link { kind: LinkParam::Compliance, .. }))
                .collect(),
        )
        .unwrap();
        let layout = Layout { robot, sessions: 2, targets: 3, still: vec![] };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(38);
        let obs: Vec<crate::calibrate::problem::Obs> = (0..300)
            .map(|k| crate::calibrate::problem::Obs {
                q: crate::robot::uniform_configuration(&model, 0.1, &mut rng),
                measured_mm: Vector3::zeros(),
                session: k % 2,
                target: (k / 2) % 3,
                sigma: 1.0,
            })
            .collect();
        let problem = super::super::problem::Problem { start: &model, layout: layout.clone(), obs: &obs };
        let mut x: Vec<f64> = layout.robot.pack(&model).iter().copied().collect();
        x.extend(std::iter::repeat_n(0.0, 6 * layout.sessions));
        x.extend([30.0, 0.0, 40.0, -25.0, 35.0, 45.0, 10.0, -20.0, 60.0]);
        let labels = (vec!["A".to_string(), "B".to_string()], vec!["s1".to_string(), "s2".to_string(), "s3".to_string()]);
        let forward: Vec<usize> = (0..obs.len()).collect();
        let backward: Vec<usize> = forward.iter().rev().copied().collect();
        for idx in [forward, backward] {
            let (kept, fixed) = prune(&problem, &x, &idx, (&labels.0, &labels.1)).unwrap();
            let names: Vec<&str> = fixed.iter().map(|u| u.name.as_str()).collect();
            assert_eq!(names, ["theta_offs6", "d6"]);
            assert_eq!(kept.len(), layout.robot.len() - 2);
        }
    }

    /// Spread in a plane fixes the frame; along a line, the line's direction; within 1 mm, a point.
    /// Placed by their span, the points of a line and of a point are met exactly (the rotation
    /// they do not fix is the smallest turn, or none), and the line's direction is the frame's.
    #[test]
    fn a_session_is_placed_as_far_as_its_points_fix_its_frame() {
        let frame = Isometry3::from_parts(Translation3::new(1500.0, -200.0, 300.0), UnitQuaternion::from_euler_angles(0.1, -0.2, 2.0));
        let plane: Vec<Vector3<f64>> = (0..12).map(|k| Vector3::new(300.0 + 20.0 * (k % 4) as f64, 50.0 * (k / 4) as f64, 400.0)).collect();
        let line: Vec<Vector3<f64>> = (0..12).map(|k| Vector3::new(300.0, 10.0 * k as f64, 400.0)).collect();
        let point: Vec<Vector3<f64>> = vec![Vector3::new(300.0, 20.0, 400.0); 6];
        let spans: Vec<Span> =
            [&plane, &line, &point].iter().map(|b| span(&measured(&frame, b).iter().map(|p| p.1).collect::<Vec<_>>(), 1.0)).collect();
        assert_eq!(spans[0], Span::Full);
        let Span::Line(d) = spans[1] else { panic!("{:?}", spans[1]) };
        assert!((d.dot(&(frame.rotation * Vector3::y())).abs() - 1.0).abs() < 1e-12, "the line's direction: {d}");
        assert_eq!(spans[2], Span::Point);
        for (b, s) in [(&plane, spans[0]), (&line, spans[1]), (&point, spans[2])] {
            let pairs = measured(&frame, b);
            let t = place(&pairs, s).unwrap();
            let worst = pairs.iter().map(|(a, m)| ((t * nalgebra::Point3::from(*a)).coords - m).norm()).fold(0.0, f64::max);
            assert!(worst < 1e-9, "{s:?}: {worst} mm");
        }
        assert!(place(&measured(&frame, &point), Span::Point).unwrap().rotation.angle() == 0.0, "a point turns nothing");
        // The line's base keeps the rotation about y (beta, column 4); a point all three.
        assert_eq!(spans[1].still(&frame), [false, false, false, false, true, false]);
        assert_eq!(spans[2].still(&frame), [false, false, false, true, true, true]);
        assert_eq!(spans[0].still(&frame), [false; 6]);
    }
}
