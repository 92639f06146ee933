//! The least-squares problem of a calibration from measured data: the robot's free parameters, a
//! base per session and a tool per target, fitted to measured target positions.
//!
//! **Unknowns** (the vector `x`, internal units): the robot parameters of a [`ParamSet`], then per
//! session the six numbers of eq. 7 (`x, y, z` mm, `alpha, beta, gamma` rad) of the session's base
//! *relative to its initial registration* (the measured points are expressed in that registered
//! frame, so the angles stay small and eq. 7's parameters stay far from their singularity at
//! `beta = +-90 deg`), then per target its position in MDH frame 6 (mm).
//!
//! **Residuals**: per point, measured minus predicted position, divided by the point's
//! uncertainty (1 when the file gives none). The Jacobian is the identification Jacobian of the
//! robot kernels (`robot::tcp_jacobians_transposed`, analytic, compliance included) of the model
//! each point sees, its base and tool columns scattered into that session's and target's blocks;
//! a test checks every column against central differences.

use nalgebra::{DMatrix, DVector, Matrix3, Rotation3, Vector3};

use crate::identify::FitOutcome;
use crate::identify::damping::Damping;
use crate::robot::{
    AngleSines, BaseParam, Joints, ParamId, ParamSet, RobotModel, angle_sines, tcp_jacobians_transposed, tcp_jacobians_transposed_by,
};

/// The six base parameters of eq. 7, in the order of a session's block.
pub const BASE_PARAMS: [BaseParam; 6] = [BaseParam::X, BaseParam::Y, BaseParam::Z, BaseParam::Alpha, BaseParam::Beta, BaseParam::Gamma];

/// Where each unknown sits in `x`.
#[derive(Clone, Debug, PartialEq)]
pub struct Layout {
    /// The robot's free parameters (no base or tool parameter: those are per session and target).
    pub robot: ParamSet,
    /// Sessions (a base each).
    pub sessions: usize,
    /// Targets (a tool each).
    pub targets: usize,
    /// Per session, the columns of its base block its points do not fix (a line or a point of
    /// measured positions, `registration::Span::still`): kept at the registration, in no fit.
    /// Empty: every column of every base is free.
    pub still: Vec<[bool; 6]>,
}

impl Layout {
    /// The columns of session `s`'s base block a fit frees (those not [`Self::still`]).
    pub fn base_columns(&self, s: usize) -> impl Iterator<Item = usize> + '_ {
        let b = self.base(s);
        (0..6).filter(move |&k| !self.still.get(s).is_some_and(|st| st[k])).map(move |k| b + k)
    }

    /// Number of unknowns.
    pub fn len(&self) -> usize {
        self.robot.len() + 6 * self.sessions + 3 * self.targets
    }

    /// Whether there is no unknown.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// First column of session `s`'s base block.
    pub fn base(&self, s: usize) -> usize {
        self.robot.len() + 6 * s
    }

    /// First column of target `t`'s tool block.
    pub fn tool(&self, t: usize) -> usize {
        self.robot.len() + 6 * self.sessions + 3 * t
    }

    /// Session `s`'s base relative to its registration (eq. 7) in `x`.
    pub fn base_delta(&self, x: &[f64], s: usize) -> crate::robot::XyzZyx {
        let b = self.base(s);
        crate::robot::XyzZyx { x: x[b], y: x[b + 1], z: x[b + 2], alpha: x[b + 3], beta: x[b + 4], gamma: x[b + 5] }
    }

    /// The columns of the base and tool blocks.
    pub fn frames(&self) -> std::ops::Range<usize> {
        self.robot.len()..self.len()
    }

    /// A name per unknown: the robot's parameter names, `base[<session>].x` .. `.gamma`,
    /// `tool[<target>].x` .. `.z`.
    pub fn names(&self, sessions: &[String], targets: &[String]) -> Vec<String> {
        let mut v = self.robot.names();
        for s in sessions {
            v.extend(["x", "y", "z", "alpha", "beta", "gamma"].iter().map(|k| format!("base[{s}].{k}")));
        }
        for t in targets {
            v.extend(["x", "y", "z"].iter().map(|k| format!("tool[{t}].{k}")));
        }
        v
    }

    /// `x` of layout `from` carried over to this layout: robot parameters by identity (those new
    /// to this layout from `start`), the base and tool blocks as they are.
    pub fn carry(&self, from: &Layout, x: &[f64], start: &RobotModel) -> Vec<f64> {
        let mut out: Vec<f64> =
            self.robot.ids().iter().map(|id| from.robot.position(*id).map_or_else(|| id.get(start.data()), |k| x[k])).collect();
        out.extend_from_slice(&x[from.frames()]);
        out
    }

    /// The column of `x` that column `c` of a point's set ([`Self::point_set`]) is, for a point of
    /// session `s` and target `t`: the robot block, session `s`'s base block or target `t`'s tool
    /// block.
    fn column_of(&self, c: usize, s: usize, t: usize) -> usize {
        let pr = self.robot.len();
        if c < pr {
            c
        } else if c < pr + 6 {
            self.base(s) + c - pr
        } else {
            self.tool(t) + c - pr - 6
        }
    }

    /// The parameters of the model one point sees: the robot's, the base's, the tool's.
    fn point_set(&self) -> ParamSet {
        let mut ids = self.robot.ids().to_vec();
        ids.extend(BASE_PARAMS.iter().map(|b| ParamId::Base(*b)));
        ids.extend((0..3).map(ParamId::Tool));
        ParamSet::new(ids).expect("the robot set holds no base or tool parameter")
    }
}

/// One measured point as the problem sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Obs {
    /// The model's joint angles, rad.
    pub q: Joints,
    /// The measured position in the session's registered frame, mm.
    pub measured_mm: Vector3<f64>,
    /// Session index.
    pub session: usize,
    /// Target index.
    pub target: usize,
    /// Uncertainty per coordinate, mm (1 when the file gives none: residuals are then in mm).
    pub sigma: f64,
}

/// The problem: the model that supplies every parameter outside the unknowns, the layout, the points.
#[derive(Clone, Debug)]
pub struct Problem<'a> {
    /// Start model (its base and tool are replaced per point).
    pub start: &'a RobotModel,
    /// The unknowns.
    pub layout: Layout,
    /// Every point.
    pub obs: &'a [Obs],
}

/// (session, target) and its members as (row in `idx`, point index).
type Group = ((usize, usize), Vec<(usize, usize)>);

/// Groups [`groups`] finds by looking through them rather than in its map.
const FEW_GROUPS: usize = 16;

/// The points of `idx` grouped by (session, target): each group sees one model. Groups in the order
/// of their first point, members in the order of `idx`.
fn groups(obs: &[Obs], idx: &[usize]) -> Vec<Group> {
    let mut out: Vec<Group> = Vec::new();
    let mut at: std::collections::HashMap<(usize, usize), usize> = std::collections::HashMap::new();
    // The last point's group first (points come in runs of one group, or a pose's targets in
    // turn), then the groups themselves while they are few, else the map.
    let mut last: Option<((usize, usize), usize)> = None;
    for (row, &i) in idx.iter().enumerate() {
        let key = (obs[i].session, obs[i].target);
        let k = match last {
            Some((l, k)) if l == key => k,
            _ => match (out.len() <= FEW_GROUPS).then(|| out.iter().position(|(g, _)| *g == key)).flatten() {
                Some(k) => k,
                None => *at.entry(key).or_insert_with(|| {
                    out.push((key, Vec::new()));
                    out.len() - 1
                }),
            },
        };
        last = Some((key, k));
        out[k].1.push((row, i));
    }
    out
}

#[cfg(test)]
thread_local! {
    /// [`Problem::shared_angles`] gives none on this thread (the reference its tests compare with).
    static NOT_SHARED: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Points per piece of the loops over a group's points that run side by side (each point's
/// kinematics is its own: a piece's results are those of its points whatever the pieces; sums over
/// pieces are taken in their order, so that every result is the same for any thread count).
const PIECE: usize = 1024;

/// The pieces of `groups`: (group, range of its members), groups in order, each in runs of [`PIECE`].
fn pieces(groups: &[Group]) -> Vec<(usize, std::ops::Range<usize>)> {
    groups.iter().enumerate().flat_map(|(g, (_, m))| (0..m.len()).step_by(PIECE).map(move |s| (g, s..(s + PIECE).min(m.len())))).collect()
}

impl Problem<'_> {
    /// The model point group (session `s`, target `t`) sees at `x`; `None` when `x` makes no model.
    pub fn model_at(&self, x: &[f64], s: usize, t: usize) -> Option<RobotModel> {
        let l = &self.layout;
        let mut values = x[..l.robot.len()].to_vec();
        values.extend_from_slice(&x[l.base(s)..l.base(s) + 6]);
        values.extend_from_slice(&x[l.tool(t)..l.tool(t) + 3]);
        l.point_set().unpack(self.start, &values).ok()
    }

    /// Unweighted position errors (measured minus predicted, mm, in the session's registered
    /// frame) of the points `idx` at `x`; `None` when `x` makes no model.
    pub fn errors(&self, x: &[f64], idx: &[usize]) -> Option<Vec<Vector3<f64>>> {
        use rayon::prelude::*;
        let groups = groups(self.obs, idx);
        let models = self.models(x, &groups)?;
        let pieces = pieces(&groups);
        let shared = self.shared_angles(&models, idx);
        let tcps: Vec<Vec<Vector3<f64>>> = pieces
            .par_iter()
            .map(|(g, r)| {
                let members = &groups[*g].1[r.clone()];
                crate::robot::tcps_world_by(&models[*g], members.len(), |k| self.member_angles(&models[*g], members[k], shared.as_deref()))
            })
            .collect();
        let mut out = vec![Vector3::zeros(); idx.len()];
        for ((g, r), tcps) in pieces.iter().zip(tcps) {
            for ((row, i), p) in groups[*g].1[r.clone()].iter().zip(tcps) {
                out[*row] = self.obs[*i].measured_mm - p;
            }
        }
        out.iter().all(|e| e.iter().all(|v| v.is_finite())).then_some(out)
    }

    /// The model of each group at `x`; `None` when `x` makes no model.
    fn models(&self, x: &[f64], groups: &[Group]) -> Option<Vec<RobotModel>> {
        groups.iter().map(|((s, t), _)| self.model_at(x, *s, *t)).collect()
    }

    /// Per row of `idx`, the [`AngleSines`] of its point's joints at `models`' joint offsets, taken
    /// once per run of rows at one configuration (a pose's targets in turn, each target a group
    /// of its own): `None` where runs are rare (a point per pose), or where the models' offsets
    /// differ (they do not: the robot's unknowns are every group's). The kernels take them as
    /// they would compute them (the same bits).
    fn shared_angles(&self, models: &[RobotModel], idx: &[usize]) -> Option<Vec<AngleSines>> {
        use rayon::prelude::*;
        #[cfg(test)]
        if NOT_SHARED.with(|c| c.get()) {
            return None;
        }
        let first = models.first()?;
        let offsets = |m: &RobotModel| m.data().links.iter().map(|l| l.theta_offset.to_bits()).collect::<Vec<u64>>();
        let same = |a: usize, b: usize| self.obs[a].q.iter().zip(&self.obs[b].q).all(|(x, y)| x.to_bits() == y.to_bits());
        let repeated = idx.windows(2).filter(|w| same(w[0], w[1])).count();
        let reference = offsets(first);
        if 4 * repeated < idx.len() || models.iter().any(|m| offsets(m) != reference) {
            return None;
        }
        Some(
            idx.par_chunks(4 * PIECE)
                .flat_map_iter(|chunk| {
                    let mut out: Vec<AngleSines> = Vec::with_capacity(chunk.len());
                    for (k, &i) in chunk.iter().enumerate() {
                        let sines = match out.last() {
                            Some(last) if same(chunk[k - 1], i) => *last,
                            _ => angle_sines(first, &self.obs[i].q),
                        };
                        out.push(sines);
                    }
                    out
                })
                .collect(),
        )
    }

    /// The identification Jacobians (transposed, [`tcp_jacobians_transposed`]) and predicted
    /// positions of the members `(row, point)` of a group at its `model`, their angles from
    /// `shared` (by row, [`Self::shared_angles`]) where given.
    fn piece_jacobians(
        &self,
        set: &ParamSet,
        model: &RobotModel,
        members: &[(usize, usize)],
        shared: Option<&[AngleSines]>,
    ) -> (Vec<f64>, Vec<Vector3<f64>>) {
        let mut jt = vec![0.0; set.len() * 3 * members.len()];
        let mut tcps = vec![Vector3::zeros(); members.len()];
        tcp_jacobians_transposed_by(model, set, members.len(), |k| self.member_angles(model, members[k], shared), &mut jt, &mut tcps);
        (jt, tcps)
    }

    /// The [`AngleSines`] of the member `(row, point)` at `model`: the row's in `shared` where
    /// given, else its point's own (the same bits).
    fn member_angles(&self, model: &RobotModel, (row, point): (usize, usize), shared: Option<&[AngleSines]>) -> AngleSines {
        match shared {
            Some(sines) => sines[row],
            None => angle_sines(model, &self.obs[point].q),
        }
    }

    /// Weighted residuals `r` (3 per point of `idx`) and the weighted Jacobian `J = d pred / dx`
    /// (3 |idx| x layout.len()) at `x`, so that a Gauss-Newton step solves `J dx = r`.
    pub fn linearise(&self, x: &[f64], idx: &[usize]) -> Option<(DVector<f64>, DMatrix<f64>)> {
        use rayon::prelude::*;
        let l = &self.layout;
        let set = l.point_set();
        let p = set.len();
        let mut r = DVector::zeros(3 * idx.len());
        let mut j = DMatrix::zeros(3 * idx.len(), l.len());
        let groups = groups(self.obs, idx);
        let models = self.models(x, &groups)?;
        let pieces = pieces(&groups);
        let shared = self.shared_angles(&models, idx);
        // A few pieces at a time (their Jacobians side by side), each scattered into `r` and `J`.
        for batch in pieces.chunks(16) {
            let done: Vec<(Vec<f64>, Vec<Vector3<f64>>)> = batch
                .par_iter()
                .map(|(g, rg)| self.piece_jacobians(&set, &models[*g], &groups[*g].1[rg.clone()], shared.as_deref()))
                .collect();
            for ((g, rg), (jt, tcps)) in batch.iter().zip(done) {
                let ((s, t), members) = &groups[*g];
                // Column c of the point's set goes to: the robot block, session s's base block or
                // target t's tool block.
                let target_col = |c: usize| l.column_of(c, *s, *t);
                for (k, ((row, i), tcp)) in members[rg.clone()].iter().zip(&tcps).enumerate() {
                    let o = &self.obs[*i];
                    let e = (o.measured_mm - tcp) / o.sigma;
                    for a in 0..3 {
                        r[3 * row + a] = e[a];
                        let jrow = &jt[(3 * k + a) * p..(3 * k + a + 1) * p];
                        for (c, v) in jrow.iter().enumerate() {
                            j[(3 * row + a, target_col(c))] = v / o.sigma;
                        }
                    }
                }
            }
        }
        (r.iter().all(|v| v.is_finite()) && j.iter().all(|v| v.is_finite())).then_some((r, j))
    }

    /// The triangular factor `R` of the weighted Jacobian of [`Self::linearise`] over the points
    /// `idx` at `x` (`J = Q R`, `Q` with orthonormal columns; at most `layout.len()` rows): each
    /// piece's rows reduced to its own factor on its few nonzero columns, the factors stacked in
    /// order and reduced again. `R` has the singular values and right singular vectors of `J` (and
    /// of any selection of its columns, `R`'s same columns), without `J`'s rows in memory. `None`
    /// when `x` makes no model or a value is not finite.
    pub fn r_factor(&self, x: &[f64], idx: &[usize]) -> Option<DMatrix<f64>> {
        use rayon::prelude::*;
        let l = &self.layout;
        let set = l.point_set();
        let p = set.len();
        let groups = groups(self.obs, idx);
        let models = self.models(x, &groups)?;
        let pieces = pieces(&groups);
        let shared = self.shared_angles(&models, idx);
        let factors: Vec<Option<DMatrix<f64>>> = pieces
            .par_iter()
            .map(|(g, rg)| {
                let ((s, t), members) = &groups[*g];
                let members = &members[rg.clone()];
                let (jt, _) = self.piece_jacobians(&set, &models[*g], members, shared.as_deref());
                let mut block = DMatrix::zeros(3 * members.len(), p);
                for (k, (_, i)) in members.iter().enumerate() {
                    let sigma = self.obs[*i].sigma;
                    for a in 0..3 {
                        for c in 0..p {
                            block[(3 * k + a, c)] = jt[(3 * k + a) * p + c] / sigma;
                        }
                    }
                }
                if !block.iter().all(|v| v.is_finite()) {
                    return None;
                }
                let r = reduce(block);
                let mut out = DMatrix::zeros(r.nrows(), l.len());
                for c in 0..p {
                    out.column_mut(l.column_of(c, *s, *t)).copy_from(&r.column(c));
                }
                Some(out)
            })
            .collect();
        let factors: Vec<DMatrix<f64>> = factors.into_iter().collect::<Option<_>>()?;
        let rows: usize = factors.iter().map(|f| f.nrows()).sum();
        let mut stacked = DMatrix::zeros(rows, l.len());
        let mut at = 0;
        for f in &factors {
            stacked.rows_mut(at, f.nrows()).copy_from(f);
            at += f.nrows();
        }
        Some(reduce(stacked))
    }

    /// The normal equations of the columns `cols` over the points `idx` at `x`: `N = J_c^T J_c`
    /// and `b = J_c^T r` with `J` and `r` of [`Self::linearise`], accumulated point by point from
    /// each point's few nonzero columns (its robot parameters, its session's base, its target's
    /// tool), so that their cost grows with the points, not with points times unknowns.
    pub fn normal_equations(&self, x: &[f64], idx: &[usize], cols: &[usize]) -> Option<(DMatrix<f64>, DVector<f64>)> {
        self.normal_equations_and_cost(x, idx, cols).map(|(n, b, _)| (n, b))
    }

    /// [`Self::normal_equations`] and [`Self::cost`] at `x` from one pass over the points (the
    /// residuals of the normal equations are the cost's, summed in the order of `idx`: the same
    /// bits as [`Self::cost`]). `None` where [`Self::normal_equations`] gives none.
    pub fn normal_equations_and_cost(&self, x: &[f64], idx: &[usize], cols: &[usize]) -> Option<(DMatrix<f64>, DVector<f64>, f64)> {
        self.normal_equations_and_cost_from(x, idx, cols, None)
    }

    /// Every point's Jacobian and predicted position at `x` ([`Start`]); `None` when `x` makes no
    /// model.
    pub fn start_at(&self, x: &[f64]) -> Option<Start> {
        use rayon::prelude::*;
        let set = self.layout.point_set();
        let p = set.len();
        let all: Vec<usize> = (0..self.obs.len()).collect();
        let groups = groups(self.obs, &all);
        let models = self.models(x, &groups)?;
        let pieces = pieces(&groups);
        let shared = self.shared_angles(&models, &all);
        let done: Vec<(Vec<f64>, Vec<Vector3<f64>>)> =
            pieces.par_iter().map(|(g, r)| self.piece_jacobians(&set, &models[*g], &groups[*g].1[r.clone()], shared.as_deref())).collect();
        let mut start = Start { x: x.to_vec(), p, jt: vec![0.0; 3 * p * all.len()], tcps: vec![Vector3::zeros(); all.len()] };
        for ((g, r), (jt, tcps)) in pieces.iter().zip(done) {
            for (k, (_, i)) in groups[*g].1[r.clone()].iter().enumerate() {
                start.jt[3 * p * i..3 * p * (i + 1)].copy_from_slice(&jt[3 * p * k..3 * p * (k + 1)]);
                start.tcps[*i] = tcps[k];
            }
        }
        Some(start)
    }

    /// [`Self::normal_equations_and_cost`], the points' Jacobians and positions taken from
    /// `start` when it is at `x` (the same numbers).
    fn normal_equations_and_cost_from(
        &self,
        x: &[f64],
        idx: &[usize],
        cols: &[usize],
        start: Option<&Start>,
    ) -> Option<(DMatrix<f64>, DVector<f64>, f64)> {
        use rayon::prelude::*;
        let start = start.filter(|s| s.x.len() == x.len() && s.x.iter().zip(x).all(|(a, b)| a.to_bits() == b.to_bits()));
        let l = &self.layout;
        let set = l.point_set();
        let p = set.len();
        // Columns past the layout's (a fit's own, [`Fit`]) get nothing from the positions.
        let mut at = vec![usize::MAX; l.len()];
        for (k, &c) in cols.iter().enumerate() {
            if let Some(a) = at.get_mut(c) {
                *a = k;
            }
        }
        let m = cols.len();
        let mut n = DMatrix::zeros(m, m);
        let mut b = DVector::zeros(m);
        let groups = groups(self.obs, idx);
        let models = self.models(x, &groups)?;
        // Per group, the free columns of the point's set (`slot`) and where they sit in `cols`.
        let free: Vec<(Vec<usize>, Vec<usize>)> = groups
            .iter()
            .map(|((s, t), _)| (0..p).map(|c| (c, at[l.column_of(c, *s, *t)])).filter(|(_, a)| *a != usize::MAX).unzip())
            .collect();
        // Each piece's dense block (rows x free columns of the point's set, then the residuals as
        // one more column) multiplied out, side by side; the products summed per group in order
        // and scattered into N and b.
        let pieces = pieces(&groups);
        let shared = if start.is_some() { None } else { self.shared_angles(&models, idx) };
        // Per piece, its product and each member's squared weighted residual.
        type Product = Option<(Vec<f64>, Vec<f64>)>;
        let products: Vec<Product> = pieces
            .par_iter()
            .map(|(g, rg)| {
                let members = &groups[*g].1[rg.clone()];
                let slot = &free[*g].0;
                let used = slot.len();
                let (jt, tcps) = match start {
                    Some(s) => s.piece(members),
                    None => self.piece_jacobians(&set, &models[*g], members, shared.as_deref()),
                };
                let rows = 3 * members.len();
                // In groups of eight rows ([`gram`]'s layout); the residuals are column `used`.
                let mut block = vec![0.0; rows.div_ceil(8) * 8 * (used + 1)];
                let mut squares = Vec::with_capacity(members.len());
                for (k, (_, i)) in members.iter().enumerate() {
                    let o = &self.obs[*i];
                    let e = (o.measured_mm - tcps[k]) / o.sigma;
                    squares.push(e.norm_squared());
                    for a in 0..3 {
                        let row = 3 * k + a;
                        let (group, lane) = (row / 8, row % 8);
                        let at = group * (used + 1) * 8 + lane;
                        block[at + used * 8] = e[a];
                        let jrow = &jt[(3 * k + a) * p..(3 * k + a + 1) * p];
                        if o.sigma == 1.0 {
                            for (u, &c) in slot.iter().enumerate() {
                                block[at + u * 8] = jrow[c];
                            }
                        } else {
                            for (u, &c) in slot.iter().enumerate() {
                                block[at + u * 8] = jrow[c] / o.sigma;
                            }
                        }
                    }
                }
                if !block.iter().all(|v| v.is_finite()) {
                    return None;
                }
                let (mut products, mut acc) = (Vec::new(), Vec::new());
                gram(&block, rows, used + 1, &mut acc, &mut products);
                Some((products, squares))
            })
            .collect();
        let mut products = products.into_iter();
        let mut squares = vec![0.0; idx.len()];
        let mut pieces = pieces.iter().peekable();
        for (g, (_, targets)) in free.iter().enumerate() {
            let used = targets.len();
            let mut local = vec![0.0; (used + 1) * (used + 1)];
            while let Some((_, rg)) = pieces.next_if(|(h, _)| *h == g) {
                let (product, piece_squares) = products.next().expect("a product per piece")?;
                for (l, v) in local.iter_mut().zip(&product) {
                    *l += v;
                }
                for ((row, _), v) in groups[g].1[rg.clone()].iter().zip(piece_squares) {
                    squares[*row] = v;
                }
            }
            let (local_n, local_b) = (|u: usize, w: usize| local[u * (used + 1) + w], |u: usize| local[u * (used + 1) + used]);
            for u in 0..used {
                b[targets[u]] += local_b(u);
                for w in 0..used {
                    n[(targets[u], targets[w])] += local_n(u, w);
                }
            }
        }
        // In the order of `idx`, as [`Self::cost`] sums them.
        let cost = squares.iter().sum::<f64>();
        Some((n, b, cost))
    }

    /// Weighted sum of squared residuals of `idx` at `x`; infinite when `x` makes no model.
    pub fn cost(&self, x: &[f64], idx: &[usize]) -> f64 {
        self.cost_and_errors(x, idx).0
    }

    /// [`Self::cost`] and the errors it sums ([`Self::errors`]), from one pass.
    pub fn cost_and_errors(&self, x: &[f64], idx: &[usize]) -> (f64, Option<Vec<Vector3<f64>>>) {
        let errors = self.errors(x, idx);
        let cost = errors.as_ref().map_or(f64::INFINITY, |e| e.iter().zip(idx).map(|(e, &i)| (e / self.obs[i].sigma).norm_squared()).sum());
        (cost, errors)
    }
}

/// A matrix with the Gram matrix `B^T B` of `b`: `b` itself when it has no more rows than columns,
/// else the triangular factor of its QR factorisation.
fn reduce(b: DMatrix<f64>) -> DMatrix<f64> {
    if b.nrows() <= b.ncols() { b } else { b.qr().r() }
}

/// The Gram matrix `G = B^T B` of the block `b` (`rows` x `cols`) into `out` (row-major, `cols` x
/// `cols`), each entry summed as nalgebra's `tr_mul` sums it (eight running sums over the rows in
/// steps of eight, combined pairwise, then the rows left over), so that `G` is bit for bit `B^T B`
/// of nalgebra; each pair of columns is summed once (the products are symmetric). The block is
/// stored in groups of eight rows: `b[(g * cols + c) * 8 + l]` is row `8 g + l` of column `c`
/// (a group's rows of every column sit together, in the cache), zero past the last row. `acc`:
/// scratch.
///
/// The running sums are taken a few pairs of columns at a time over a run of groups ([`tile`]),
/// held in registers across the run; each running sum still adds its rows' products in the order
/// of the rows, so the bits are those of one pair and one group at a time.
fn gram(b: &[f64], rows: usize, cols: usize, acc: &mut Vec<[f64; 8]>, out: &mut Vec<f64>) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx512f") {
        // SAFETY: the CPU was just found to support AVX-512F, the only requirement of
        // `gram_avx512`.
        #[allow(unsafe_code)]
        unsafe {
            gram_avx512(b, rows, cols, acc, out)
        };
        return;
    }
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU was just found to support AVX2, the only requirement of `gram_avx2`.
        #[allow(unsafe_code)]
        unsafe {
            gram_avx2(b, rows, cols, acc, out)
        };
        return;
    }
    gram_body::<2, 2>(b, rows, cols, acc, out);
}

/// [`gram`] compiled for AVX-512F (a running sum of eight lanes in one register; the same
/// separate products and sums, no fused multiply-add: the same bits).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
fn gram_avx512(b: &[f64], rows: usize, cols: usize, acc: &mut Vec<[f64; 8]>, out: &mut Vec<f64>) {
    gram_body::<2, 4>(b, rows, cols, acc, out);
}

/// [`gram`] compiled for AVX2 (the eight running sums in wider vectors; the same separate
/// products and sums, no fused multiply-add: the same bits).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn gram_avx2(b: &[f64], rows: usize, cols: usize, acc: &mut Vec<[f64; 8]>, out: &mut Vec<f64>) {
    gram_body::<2, 2>(b, rows, cols, acc, out);
}

/// Groups of eight rows per run of [`tile`] (a run of a block of 28 columns: 28 KB, in the cache).
const TILE_GROUPS: usize = 16;

/// The running sums of the pairs (`u0 + i`, `w0 + j`), `i < U`, `j < W`, over the groups `groups`
/// of `b` ([`gram`]'s layout), added to `acc` (`cols` x `cols`, row-major): each pair's eight sums
/// held in registers over the groups, each adding its groups' products in their order.
#[inline(always)]
fn tile<const U: usize, const W: usize>(
    b: &[f64],
    cols: usize,
    groups: std::ops::Range<usize>,
    u0: usize,
    w0: usize,
    acc: &mut [[f64; 8]],
) {
    let mut a = [[[0.0f64; 8]; W]; U];
    for i in 0..U {
        for j in 0..W {
            a[i][j] = acc[(u0 + i) * cols + w0 + j];
        }
    }
    for g in groups {
        let group = &b[g * cols * 8..(g + 1) * cols * 8];
        for i in 0..U {
            let x: &[f64; 8] = group[8 * (u0 + i)..8 * (u0 + i) + 8].try_into().expect("eight rows");
            for j in 0..W {
                let y: &[f64; 8] = group[8 * (w0 + j)..8 * (w0 + j) + 8].try_into().expect("eight rows");
                for l in 0..8 {
                    a[i][j][l] += x[l] * y[l];
                }
            }
        }
    }
    for i in 0..U {
        for j in 0..W {
            acc[(u0 + i) * cols + w0 + j] = a[i][j];
        }
    }
}

#[inline(always)]
fn gram_body<const U: usize, const W: usize>(b: &[f64], rows: usize, cols: usize, acc: &mut Vec<[f64; 8]>, out: &mut Vec<f64>) {
    // Every pair (u, w) with w >= u is summed; a tile on the diagonal also sums a few pairs below
    // it (w < u), which are not read.
    acc.clear();
    acc.resize(cols * cols, [0.0; 8]);
    let full = rows / 8;
    let mut start = 0;
    while start < full {
        let groups = start..(start + TILE_GROUPS).min(full);
        let mut u0 = 0;
        while u0 < cols {
            if u0 + U <= cols {
                let mut w0 = u0;
                while w0 + W <= cols {
                    tile::<U, W>(b, cols, groups.clone(), u0, w0, acc);
                    w0 += W;
                }
                while w0 < cols {
                    tile::<U, 1>(b, cols, groups.clone(), u0, w0, acc);
                    w0 += 1;
                }
                u0 += U;
            } else {
                for w0 in u0..cols {
                    tile::<1, 1>(b, cols, groups.clone(), u0, w0, acc);
                }
                u0 += 1;
            }
        }
        start = groups.end;
    }
    out.clear();
    out.resize(cols * cols, 0.0);
    for u in 0..cols {
        for w in u..cols {
            let a = &acc[u * cols + w];
            let mut res = 0.0;
            res += a[0] + a[4];
            res += a[1] + a[5];
            res += a[2] + a[6];
            res += a[3] + a[7];
            for r in 8 * full..rows {
                let at = full * cols * 8 + r - 8 * full;
                res += b[at + u * 8] * b[at + w * 8];
            }
            out[u * cols + w] = res;
            out[w * cols + u] = res;
        }
    }
}

/// Rows of `A` per task of [`mul`].
const MUL_ROWS: usize = 8192;

/// `A X` as nalgebra's product gives it, bit for bit (each entry's sum over the columns of `A` is
/// that of its row alone), blocks of rows of `A` side by side: the tall products of the twin (a
/// row per coordinate of every point) on every core.
pub(crate) fn mul(a: &DMatrix<f64>, x: &DMatrix<f64>) -> DMatrix<f64> {
    use rayon::prelude::*;
    assert_eq!(a.ncols(), x.nrows(), "A X of matching sizes");
    let (n, c) = (a.nrows(), x.ncols());
    if n <= MUL_ROWS {
        return a * x;
    }
    let blocks: Vec<DMatrix<f64>> =
        (0..n).step_by(MUL_ROWS).collect::<Vec<_>>().par_iter().map(|&r0| a.rows(r0, MUL_ROWS.min(n - r0)) * x).collect();
    let mut out = DMatrix::zeros(n, c);
    for (b, r0) in blocks.iter().zip((0..n).step_by(MUL_ROWS)) {
        out.rows_mut(r0, b.nrows()).copy_from(b);
    }
    out
}

/// Rows of `A` per task of [`mul_vectors`] (with eight vectors, their results' rows and a column
/// of `A`'s sit in the first-level cache).
const MUL_VECTORS_ROWS: usize = 512;

/// `A x` for each `x` of `xs` as nalgebra's product of a matrix and a vector gives it, bit for bit
/// (its `gemv`: the first column's products, then each further column's added in order), with `A`
/// read once for all of them: blocks of rows side by side (each entry its row's own sum: the same
/// for any thread count). The prediction's draws multiply one tall Jacobian by a few vectors each.
pub(crate) fn mul_vectors(a: &DMatrix<f64>, xs: &[DVector<f64>]) -> Vec<DVector<f64>> {
    use rayon::prelude::*;
    let (n, p) = a.shape();
    assert!(xs.iter().all(|x| x.len() == p), "A x of matching sizes");
    if p == 0 || xs.is_empty() {
        return xs.iter().map(|x| a * x).collect();
    }
    let m = xs.len();
    // Each block's results, vector by vector.
    let blocks: Vec<Vec<f64>> = (0..n)
        .into_par_iter()
        .step_by(MUL_VECTORS_ROWS)
        .map(|r0| {
            let len = MUL_VECTORS_ROWS.min(n - r0);
            let mut out = vec![0.0; m * len];
            let col = |k: usize| &a.as_slice()[k * n + r0..k * n + r0 + len];
            for (o, x) in out.chunks_exact_mut(len).zip(xs) {
                for (y, v) in o.iter_mut().zip(col(0)) {
                    *y = v * x[0];
                }
            }
            for k in 1..p {
                let c = col(k);
                for (o, x) in out.chunks_exact_mut(len).zip(xs) {
                    let xk = x[k];
                    for (y, v) in o.iter_mut().zip(c) {
                        *y += v * xk;
                    }
                }
            }
            out
        })
        .collect();
    let mut out: Vec<DVector<f64>> = (0..m).map(|_| DVector::zeros(n)).collect();
    for (b, r0) in blocks.iter().zip((0..n).step_by(MUL_VECTORS_ROWS)) {
        let len = MUL_VECTORS_ROWS.min(n - r0);
        for (o, part) in out.iter_mut().zip(b.chunks_exact(len)) {
            o.rows_mut(r0, len).copy_from_slice(part);
        }
    }
    out
}

/// Rows per run of [`tr_mul`]: a run's rows of every column of `A` and of a task's columns of `B`
/// sit in the cache.
const TR_MUL_RUN: usize = 256;

/// Columns of `B` per task of [`tr_mul`] at most.
const TR_MUL_COLUMNS: usize = 64;

/// `A^T B` bit for bit as nalgebra's `tr_mul` sums it (each entry the dot product of a column of
/// `a` and one of `b`: eight running sums over the rows in steps of eight, combined pairwise, then
/// the rows left over), a few entries at a time over runs of [`TR_MUL_RUN`] rows, their running
/// sums held in registers across a run (each still adds its rows' products in the order of the
/// rows). Blocks of columns of the result are computed side by side (each entry on its own: the
/// same bits for any thread count). `A^T A` (`b` of `None`) sums each pair of columns once.
pub(crate) fn tr_mul(a: &DMatrix<f64>, b: Option<&DMatrix<f64>>) -> DMatrix<f64> {
    use rayon::prelude::*;
    let (n, ca) = a.shape();
    let sym = b.is_none();
    let b = b.unwrap_or(a);
    assert_eq!(b.nrows(), n, "A^T B of as many rows");
    let cb = b.ncols();
    let (sa, sb) = (a.as_slice(), b.as_slice());
    // Two blocks at least (both cores busy), at most TR_MUL_COLUMNS columns each.
    let width = cb.div_ceil(2).clamp(1, TR_MUL_COLUMNS);
    let block = |w0: usize| -> Vec<f64> {
        let ws = w0..(w0 + width).min(cb);
        let mut out = Vec::new();
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx512f") {
            // SAFETY: the CPU was just found to support AVX-512F, the only requirement.
            #[allow(unsafe_code)]
            unsafe {
                tr_mul_avx512(sa, sb, n, ca, ws, sym, &mut out)
            };
            return out;
        }
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU was just found to support AVX2, the only requirement.
            #[allow(unsafe_code)]
            unsafe {
                tr_mul_avx2(sa, sb, n, ca, ws, sym, &mut out)
            };
            return out;
        }
        tr_mul_body::<2, 2>(sa, sb, n, ca, ws, sym, &mut out);
        out
    };
    let starts: Vec<usize> = (0..cb).step_by(width).collect();
    let blocks: Vec<Vec<f64>> = starts.par_iter().map(|&w0| block(w0)).collect();
    let mut out = DMatrix::zeros(ca, cb);
    for (&w0, values) in starts.iter().zip(blocks) {
        let ws = w0..(w0 + width).min(cb);
        for u in 0..ca {
            for w in ws.clone() {
                if sym && w < u {
                    continue;
                }
                let v = values[u * ws.len() + w - w0];
                out[(u, w)] = v;
                if sym {
                    out[(w, u)] = v;
                }
            }
        }
    }
    out
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
fn tr_mul_avx512(a: &[f64], b: &[f64], n: usize, ca: usize, ws: std::ops::Range<usize>, sym: bool, out: &mut Vec<f64>) {
    tr_mul_body::<2, 4>(a, b, n, ca, ws, sym, out);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn tr_mul_avx2(a: &[f64], b: &[f64], n: usize, ca: usize, ws: std::ops::Range<usize>, sym: bool, out: &mut Vec<f64>) {
    tr_mul_body::<2, 2>(a, b, n, ca, ws, sym, out);
}

/// The columns `ws` of `A^T B` (`a` of `ca` columns, `b`, column-major with `n` rows) into `out`,
/// row-major (`ca` x `ws.len()`); when `sym` (`B = A`) the entries below the diagonal are left at
/// zero or summed and not meant to be read.
#[inline(always)]
fn tr_mul_body<const U: usize, const W: usize>(
    a: &[f64],
    b: &[f64],
    n: usize,
    ca: usize,
    ws: std::ops::Range<usize>,
    sym: bool,
    out: &mut Vec<f64>,
) {
    let width = ws.len();
    // Running sums of row u and column w (of `ws`): acc[u * width + w - ws.start].
    let mut acc = vec![[0.0f64; 8]; ca * width];
    let full = n / 8;
    // The rows of the result a tile at columns from w0 needs (below the diagonal: none when sym).
    let rows_to = |w_end: usize| if sym { ca.min(w_end) } else { ca };
    let mut start = 0;
    while start < full {
        let groups = start..(start + TR_MUL_RUN / 8).min(full);
        let mut w0 = ws.start;
        while w0 < ws.end {
            let ww = if w0 + W <= ws.end { W } else { 1 };
            let u_end = rows_to(w0 + ww);
            let mut u0 = 0;
            while u0 < u_end {
                let uu = if u0 + U <= u_end { U } else { 1 };
                let t = Tile { a, b, n, width, groups: groups.clone(), u0, w0, ws_start: ws.start };
                match (uu, ww) {
                    (1, 1) => t.add::<1, 1>(&mut acc),
                    (1, _) => t.add::<1, W>(&mut acc),
                    (_, 1) => t.add::<U, 1>(&mut acc),
                    _ => t.add::<U, W>(&mut acc),
                }
                u0 += uu;
            }
            w0 += ww;
        }
        start = groups.end;
    }
    out.clear();
    out.resize(ca * width, 0.0);
    for u in 0..ca {
        let x = &a[u * n..(u + 1) * n];
        for w in ws.clone() {
            if sym && w < u {
                continue;
            }
            let y = &b[w * n..(w + 1) * n];
            let s = &acc[u * width + w - ws.start];
            let mut res = 0.0;
            res += s[0] + s[4];
            res += s[1] + s[5];
            res += s[2] + s[6];
            res += s[3] + s[7];
            for r in 8 * full..n {
                res += x[r] * y[r];
            }
            out[u * width + w - ws.start] = res;
        }
    }
}

/// A tile of [`tr_mul_body`]: the entries (`u0 + i`, `w0 + j`) over the groups of eight rows
/// `groups`.
struct Tile<'a> {
    a: &'a [f64],
    b: &'a [f64],
    n: usize,
    width: usize,
    groups: std::ops::Range<usize>,
    u0: usize,
    w0: usize,
    ws_start: usize,
}

impl Tile<'_> {
    /// The tile's `U` x `W` running sums over its groups, added to `acc`, each held in registers.
    #[inline(always)]
    fn add<const U: usize, const W: usize>(&self, acc: &mut [[f64; 8]]) {
        let at = |i: usize, j: usize| (self.u0 + i) * self.width + self.w0 + j - self.ws_start;
        let mut s = [[[0.0f64; 8]; W]; U];
        for i in 0..U {
            for j in 0..W {
                s[i][j] = acc[at(i, j)];
            }
        }
        let lo = 8 * self.groups.start;
        let hi = 8 * self.groups.end;
        let xs: [&[f64]; U] = std::array::from_fn(|i| &self.a[(self.u0 + i) * self.n + lo..(self.u0 + i) * self.n + hi]);
        let ys: [&[f64]; W] = std::array::from_fn(|j| &self.b[(self.w0 + j) * self.n + lo..(self.w0 + j) * self.n + hi]);
        for g in 0..self.groups.len() {
            for i in 0..U {
                let x: &[f64; 8] = xs[i][8 * g..8 * g + 8].try_into().expect("eight rows");
                for j in 0..W {
                    let y: &[f64; 8] = ys[j][8 * g..8 * g + 8].try_into().expect("eight rows");
                    for l in 0..8 {
                        s[i][j][l] += x[l] * y[l];
                    }
                }
            }
        }
        for i in 0..U {
            for j in 0..W {
                acc[at(i, j)] = s[i][j];
            }
        }
    }
}

/// Stopping rules of [`solve`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SolveOptions {
    /// Iteration cap (Jacobian evaluations).
    pub max_iterations: usize,
    /// Converged when an accepted step changes the weighted residuals by less than this RMS (mm
    /// when the points carry no uncertainty, else in units of it).
    pub step_tol: f64,
    /// Converged when an accepted step changes the cost by less than this fraction of it.
    pub cost_rtol: f64,
}

impl Default for SolveOptions {
    fn default() -> Self {
        Self { max_iterations: 100, step_tol: 1e-9, cost_rtol: 1e-12 }
    }
}

/// The end of one [`solve`].
#[derive(Clone, Debug)]
pub struct Solved {
    /// The unknowns (every column; those not free are as given).
    pub x: Vec<f64>,
    /// How it ended.
    pub outcome: FitOutcome,
    /// Weighted sum of squared residuals at `x`.
    pub cost: f64,
    /// The points' position errors at `x` (those of [`Problem::errors`] over the points solved),
    /// when the fit's last pass computed them (its last step's cost alone): a caller that wants
    /// them takes them instead of computing them again.
    pub errors: Option<Vec<Vector3<f64>>>,
}

/// Levenberg-Marquardt on the free columns `free` over the points `idx` from `x0`: column-scaled
/// normal equations, Cholesky steps, Nielsen's damping (`identify::damping`, the one rule of
/// calsim) from 1e-12 of the scaled diagonal (Gauss-Newton unless a step fails). A step Cholesky refuses raises the damping; damping beyond 1e16 means the free
/// columns are not separable on these points ([`FitOutcome::RankDeficient`]).
pub fn solve<P: Fit + ?Sized>(problem: &P, x0: &[f64], free: &[usize], idx: &[usize], opts: &SolveOptions) -> Solved {
    let mut x = x0.to_vec();
    let mut damping = Damping::none();
    // The normal equations at each accepted point come with its cost (one pass over the points);
    // a step whose change of the residuals already meets the step rule gets its cost alone.
    let (mut cost, mut next) = equations_and_cost(problem, &x, free, idx);
    let rows = (3 * idx.len()).max(1) as f64;
    for iteration in 1..=opts.max_iterations {
        let Some((n, b)) = next.take() else {
            return Solved { x, outcome: FitOutcome::NotFinite, cost: f64::NAN, errors: None };
        };
        let norms: Vec<f64> = (0..free.len()).map(|c| n[(c, c)].sqrt()).collect();
        let inv: Vec<f64> = norms.iter().map(|v| if *v > 0.0 { 1.0 / v } else { 0.0 }).collect();
        let ns = DMatrix::from_fn(free.len(), free.len(), |a, c| n[(a, c)] * inv[a] * inv[c]);
        let bs = DVector::from_fn(free.len(), |a, _| b[a] * inv[a]);
        if iteration == 1 {
            // Gauss-Newton until a step fails: the start (registered frames, the robot file's
            // values) is close, and a damping above the smallest eigenvalue of the scaled normal
            // matrix (1e-12 for a compliance of a lightly loaded wrist) would stall the weakly
            // identified directions and stop the fit on the step rule before they converge.
            damping = Damping::start(1e-12, 1.0);
        }
        loop {
            let mut m = ns.clone();
            for a in 0..free.len() {
                m[(a, a)] += damping.mu;
            }
            let Some(step) = m.cholesky().map(|c| c.solve(&bs)) else {
                damping.reject();
                if damping.mu > 1e16 {
                    return Solved { x, outcome: rank_deficient(problem, free), cost, errors: None };
                }
                continue;
            };
            let mut trial = x.clone();
            for (a, &c) in free.iter().enumerate() {
                trial[c] += step[a] * inv[a];
            }
            let moved = (step.dot(&(&ns * &step))).max(0.0).sqrt() / rows.sqrt();
            let gain = 2.0 * step.dot(&bs) - step.dot(&(&ns * &step));
            // A step whose predicted change of the cost is within reach of the cost rule most
            // likely ends the fit: its cost alone first (a pass of the positions, not of their
            // Jacobians), the normal equations there only if the fit goes on. The same iterates
            // and the same bits either way (the cost is the same from both passes).
            let ending = moved < opts.step_tol || gain <= LIKELY_LAST * opts.cost_rtol * cost;
            let (trial_cost, pending, trial_errors) = if ending {
                let (cost, errors) = problem.cost_and_errors(&trial, idx);
                (cost, None, errors)
            } else {
                let (cost, pending) = equations_and_cost(problem, &trial, free, idx);
                (cost, pending, None)
            };
            let rho = if gain > 0.0 && trial_cost.is_finite() { (cost - trial_cost) / gain } else { -1.0 };
            if damping.update(rho) {
                let change = (cost - trial_cost).abs();
                x = trial;
                cost = trial_cost;
                if moved < opts.step_tol || change <= opts.cost_rtol * cost {
                    return Solved { x, outcome: FitOutcome::Converged { iterations: iteration }, cost, errors: trial_errors };
                }
                next = if ending { equations_and_cost(problem, &x, free, idx).1 } else { pending };
                break;
            }
            // No step lowers the cost: this iterate is the minimum to the precision of the cost.
            // So too when the step's predicted decrease is already within the cost rule: the
            // smaller steps of more damping predict less, and whether one of them lowers the cost
            // by that little is decided by the rounding of the cost, not by the model.
            if damping.mu > 1e16 || gain <= opts.cost_rtol * cost {
                return Solved { x, outcome: FitOutcome::Converged { iterations: iteration }, cost, errors: None };
            }
        }
    }
    Solved { x, outcome: FitOutcome::IterationCap { iterations: opts.max_iterations }, cost, errors: None }
}

/// A step predicted to change the cost by at most this many times the cost rule's tolerance
/// (`cost_rtol` of the cost) is taken as the fit's last: its cost is computed before its normal
/// equations (Gauss-Newton's predicted change is the actual one to a few percent near the minimum,
/// so ten times covers it; a wrong guess costs one pass of the positions).
const LIKELY_LAST: f64 = 10.0;

/// The normal equations of a step, when there are.
type Equations = Option<(DMatrix<f64>, DVector<f64>)>;

/// The cost at `x` and the normal equations of the columns `free` there (`None` where they give
/// none: the cost then on its own, as [`Fit::cost`] gives it).
fn equations_and_cost<P: Fit + ?Sized>(problem: &P, x: &[f64], free: &[usize], idx: &[usize]) -> (f64, Equations) {
    match problem.normal_equations_and_cost(x, idx, free) {
        Some((n, b, cost)) => (cost, Some((n, b))),
        None => (problem.cost(x, idx), None),
    }
}

fn rank_deficient<P: Fit + ?Sized>(problem: &P, free: &[usize]) -> FitOutcome {
    let mut names = problem.positions().layout.names(&[], &[]);
    names.extend(problem.own_names(&[]));
    FitOutcome::RankDeficient { unidentifiable: free.iter().filter_map(|&c| names.get(c).cloned()).collect() }
}

/// Every point's Jacobian (the columns of its set, transposed as [`tcp_jacobians_transposed`]
/// gives them) and predicted position at one `x` ([`Problem::start_at`]). Fits that all start at
/// `x` (the folds of a cross-validation start at the fit on every point) take their first normal
/// equations from it instead of each computing its points' kinematics again: the same numbers, a
/// point's kinematics being its own.
#[derive(Debug)]
pub struct Start {
    x: Vec<f64>,
    p: usize,
    jt: Vec<f64>,
    tcps: Vec<Vector3<f64>>,
}

impl Start {
    /// The start of `fit`'s points at `x`, when the fit takes its normal equations from its
    /// positions alone (`None` for a fit with unknowns of its own, as orientation readings bring,
    /// which [`Started`] would not use; or when `x` makes no model).
    pub fn for_fit<P: Fit + ?Sized>(fit: &P, x: &[f64]) -> Option<Start> {
        positions_alone(fit).then(|| fit.positions().start_at(x)).flatten()
    }

    /// The Jacobians and positions of `members` (row, point), as [`Problem::piece_jacobians`] gives
    /// them.
    fn piece(&self, members: &[(usize, usize)]) -> (Vec<f64>, Vec<Vector3<f64>>) {
        let p3 = 3 * self.p;
        let mut jt = Vec::with_capacity(p3 * members.len());
        for (_, i) in members {
            jt.extend_from_slice(&self.jt[p3 * i..p3 * (i + 1)]);
        }
        (jt, members.iter().map(|(_, i)| self.tcps[*i]).collect())
    }
}

/// A fit whose unknowns are its positions' problem's alone (no orientation unknowns of its own):
/// its normal equations are that problem's.
fn positions_alone<P: Fit + ?Sized>(fit: &P) -> bool {
    fit.unknowns() == fit.positions().layout.len()
}

/// A fit whose normal equations at [`Start`]'s `x` come from it (a fit with orientation unknowns of
/// its own computes them as it does).
pub struct Started<'a, P: Fit + ?Sized> {
    /// The fit.
    pub fit: &'a P,
    /// Its points at the start.
    pub start: &'a Start,
}

impl<P: Fit + ?Sized> Fit for Started<'_, P> {
    fn positions(&self) -> &Problem<'_> {
        self.fit.positions()
    }
    fn unknowns(&self) -> usize {
        self.fit.unknowns()
    }
    fn cost(&self, x: &[f64], idx: &[usize]) -> f64 {
        self.fit.cost(x, idx)
    }
    fn cost_and_errors(&self, x: &[f64], idx: &[usize]) -> (f64, Option<Vec<Vector3<f64>>>) {
        self.fit.cost_and_errors(x, idx)
    }
    fn normal_equations(&self, x: &[f64], idx: &[usize], cols: &[usize]) -> Option<(DMatrix<f64>, DVector<f64>)> {
        self.fit.normal_equations(x, idx, cols)
    }
    fn normal_equations_and_cost(&self, x: &[f64], idx: &[usize], cols: &[usize]) -> Option<(DMatrix<f64>, DVector<f64>, f64)> {
        if positions_alone(self.fit) {
            self.fit.positions().normal_equations_and_cost_from(x, idx, cols, Some(self.start))
        } else {
            self.fit.normal_equations_and_cost(x, idx, cols)
        }
    }
    fn linearise(&self, x: &[f64], idx: &[usize]) -> Option<(DVector<f64>, DMatrix<f64>)> {
        self.fit.linearise(x, idx)
    }
    fn r_factor(&self, x: &[f64], idx: &[usize]) -> Option<DMatrix<f64>> {
        self.fit.r_factor(x, idx)
    }
    fn own_columns(&self, idx: &[usize]) -> Vec<usize> {
        self.fit.own_columns(idx)
    }
    fn own_names(&self, targets: &[String]) -> Vec<String> {
        self.fit.own_names(targets)
    }
    fn own_rows(&self, idx: &[usize]) -> usize {
        self.fit.own_rows(idx)
    }
    fn rotation_errors(&self, x: &[f64], idx: &[usize]) -> Option<Vec<Option<Vector3<f64>>>> {
        self.fit.rotation_errors(x, idx)
    }
    fn reading_sigma(&self, i: usize) -> Option<f64> {
        self.fit.reading_sigma(i)
    }
}

/// What a fit works on: a [`Problem`]'s positions, and orientation readings where a problem
/// carries them ([`Oriented`]). The solver, the robust fit, the cross-validation and the reports
/// take any of them.
pub trait Fit: Sync {
    /// The positions' problem.
    fn positions(&self) -> &Problem<'_>;
    /// Number of unknowns (the layout's, then any of the fit's own).
    fn unknowns(&self) -> usize;
    /// Weighted sum of squared residuals of `idx` at `x`; infinite when `x` makes no model.
    fn cost(&self, x: &[f64], idx: &[usize]) -> f64;
    /// [`Fit::cost`] and, where the fit has them from the same pass, the positions' errors
    /// ([`Problem::errors`] of `idx` at `x`; `None` where that gives none): the same bits as each.
    fn cost_and_errors(&self, x: &[f64], idx: &[usize]) -> (f64, Option<Vec<Vector3<f64>>>) {
        (self.cost(x, idx), None)
    }
    /// `N = J_c^T J_c` and `b = J_c^T r` of the columns `cols` over the points `idx` at `x`.
    fn normal_equations(&self, x: &[f64], idx: &[usize], cols: &[usize]) -> Option<(DMatrix<f64>, DVector<f64>)>;
    /// [`Fit::normal_equations`] and [`Fit::cost`] at `x` (`None` where the normal equations give
    /// none); a fit may take both from one pass over the points, with the same bits.
    fn normal_equations_and_cost(&self, x: &[f64], idx: &[usize], cols: &[usize]) -> Option<(DMatrix<f64>, DVector<f64>, f64)> {
        let (n, b) = self.normal_equations(x, idx, cols)?;
        Some((n, b, self.cost(x, idx)))
    }
    /// Weighted residuals and Jacobian: the positions' rows (3 per point of `idx`, in its order)
    /// first, then any rows of the fit's own.
    fn linearise(&self, x: &[f64], idx: &[usize]) -> Option<(DVector<f64>, DMatrix<f64>)>;
    /// The triangular factor of the weighted Jacobian of [`Fit::linearise`].
    fn r_factor(&self, x: &[f64], idx: &[usize]) -> Option<DMatrix<f64>>;
    /// The unknowns past the layout's that the points `idx` fix (free in a fit over them).
    fn own_columns(&self, idx: &[usize]) -> Vec<usize>;
    /// The names of the unknowns past the layout's (`targets`: the targets' labels).
    fn own_names(&self, targets: &[String]) -> Vec<String>;
    /// Residuals of the points `idx` past their positions' 3 each.
    fn own_rows(&self, idx: &[usize]) -> usize;
    /// Per point of `idx`: its rotation error `log(R_measured R_model^T)` (rad; `None` for a point
    /// without a reading); `None` when the fit has no readings or `x` makes no model.
    fn rotation_errors(&self, x: &[f64], idx: &[usize]) -> Option<Vec<Option<Vector3<f64>>>>;
    /// Point `i`'s reading's uncertainty, rad (`None`: the point has no reading).
    fn reading_sigma(&self, _i: usize) -> Option<f64> {
        None
    }
}

impl Fit for Problem<'_> {
    fn positions(&self) -> &Problem<'_> {
        self
    }
    fn unknowns(&self) -> usize {
        self.layout.len()
    }
    fn cost(&self, x: &[f64], idx: &[usize]) -> f64 {
        Problem::cost(self, x, idx)
    }
    fn cost_and_errors(&self, x: &[f64], idx: &[usize]) -> (f64, Option<Vec<Vector3<f64>>>) {
        Problem::cost_and_errors(self, x, idx)
    }
    fn normal_equations(&self, x: &[f64], idx: &[usize], cols: &[usize]) -> Option<(DMatrix<f64>, DVector<f64>)> {
        Problem::normal_equations(self, x, idx, cols)
    }
    fn normal_equations_and_cost(&self, x: &[f64], idx: &[usize], cols: &[usize]) -> Option<(DMatrix<f64>, DVector<f64>, f64)> {
        Problem::normal_equations_and_cost(self, x, idx, cols)
    }
    fn linearise(&self, x: &[f64], idx: &[usize]) -> Option<(DVector<f64>, DMatrix<f64>)> {
        Problem::linearise(self, x, idx)
    }
    fn r_factor(&self, x: &[f64], idx: &[usize]) -> Option<DMatrix<f64>> {
        Problem::r_factor(self, x, idx)
    }
    fn own_columns(&self, _idx: &[usize]) -> Vec<usize> {
        Vec::new()
    }
    fn own_rows(&self, _idx: &[usize]) -> usize {
        0
    }
    fn own_names(&self, _targets: &[String]) -> Vec<String> {
        Vec::new()
    }
    fn rotation_errors(&self, _x: &[f64], _idx: &[usize]) -> Option<Vec<Option<Vector3<f64>>>> {
        None
    }
}

/// The orientation reading of a six-degree-of-freedom probe at one point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Reading {
    /// The probe's frame in the session's registered frame.
    pub measured: Rotation3<f64>,
    /// Its standard uncertainty (a rotation about any axis), rad.
    pub sigma_rad: f64,
}

/// A problem's positions and its points' orientation readings.
///
/// **Unknowns**: the layout's, then per target with readings the three numbers `delta` of its
/// probe's rotation on the flange, `flange_from_probe = exp([delta]) R0` (rad, about the flange's
/// axes; `R0` its start value), in the order of the targets.
///
/// **Residuals**: the positions' (the problem's), then per point with a reading the rotation
/// `e = log(R_measured R_model^T)` (the rotation vector taking the model's probe frame to the
/// measured one, about the session's axes, rad) over the reading's uncertainty, `R_model` the
/// point's flange rotation in the session's frame times `flange_from_probe`. The flange's rotation
/// and its derivatives with respect to the robot's and the base's parameters come from the
/// analytic position Jacobians of three points on the flange ([`flange_rotations`]).
#[derive(Clone, Debug)]
pub struct Oriented<'a> {
    /// The positions.
    pub problem: Problem<'a>,
    /// Per point of the problem: its reading (`None`: the point has none).
    pub readings: &'a [Option<Reading>],
    /// Per target: the start value `R0` of its probe's rotation on the flange (`None`: the target
    /// has no reading; no unknowns).
    pub tool_rotations: &'a [Option<Rotation3<f64>>],
}

/// Length of the three flange axes whose end points give the flange's rotation, mm (the arm's
/// scale: their differences keep the positions' relative precision).
const AXIS_MM: f64 = 1000.0;

/// The skew-symmetric matrix of `v`.
fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// The inverse of SO(3)'s right Jacobian at `e`: `log(exp(e) exp(d)) = e + J_r^-1(e) d` to first order.
pub fn right_jacobian_inverse(e: &Vector3<f64>) -> Matrix3<f64> {
    let t = e.norm();
    let k = skew(e);
    let c = if t < 1e-4 { 1.0 / 12.0 + t * t / 720.0 } else { 1.0 / (t * t) - (1.0 + t.cos()) / (2.0 * t * t.sin()) };
    Matrix3::identity() + 0.5 * k + c * k * k
}

/// SO(3)'s left Jacobian at `d`: `exp(d + h) = exp(J_l(d) h) exp(d)` to first order.
pub fn left_jacobian(d: &Vector3<f64>) -> Matrix3<f64> {
    let t = d.norm();
    let k = skew(d);
    let (a, b) =
        if t < 1e-4 { (0.5 - t * t / 24.0, 1.0 / 6.0 - t * t / 120.0) } else { ((1.0 - t.cos()) / (t * t), (t - t.sin()) / (t * t * t)) };
    Matrix3::identity() + a * k + b * k * k
}

/// The rotation vector of `r` (its logarithm), rad: from its quaternion (Shepperd's method) by
/// `2 atan2(|v|, w) v / |v|`, accurate at every angle (an angle from `acos` of the trace loses
/// half the digits near zero, where the fit's residuals end).
pub fn log(r: &Rotation3<f64>) -> Vector3<f64> {
    let q = nalgebra::UnitQuaternion::from_rotation_matrix(r);
    let (w, v) = if q.w < 0.0 { (-q.w, -q.imag()) } else { (q.w, q.imag()) };
    let n = v.norm();
    if n == 0.0 { Vector3::zeros() } else { v * (2.0 * n.atan2(w) / n) }
}

/// Per configuration of `qs` at `model`: the flange's rotation in the model's world frame and, if
/// `set` is given, its derivatives as rotation vectors about the world's axes (3 x p, column per
/// parameter of `set`): from the positions and analytic Jacobians of the flange's origin and of
/// three points [`AXIS_MM`] along its axes.
pub fn flange_rotations(model: &RobotModel, set: Option<&ParamSet>, qs: &[Joints]) -> Option<Vec<(Rotation3<f64>, DMatrix<f64>)>> {
    let at = |tcp: Vector3<f64>| model.edited(|d| d.flange_tcp_mm = tcp).ok();
    let points = [Vector3::zeros(), Vector3::x() * AXIS_MM, Vector3::y() * AXIS_MM, Vector3::z() * AXIS_MM];
    let p = set.map_or(0, ParamSet::len);
    let mut tcps = Vec::with_capacity(4);
    let mut jts = Vec::with_capacity(4);
    for tcp in points {
        let m = at(tcp)?;
        match set {
            Some(set) => {
                let mut jt = vec![0.0; p * 3 * qs.len()];
                let mut t = vec![Vector3::zeros(); qs.len()];
                tcp_jacobians_transposed(&m, set, qs, &mut jt, &mut t);
                tcps.push(t);
                jts.push(jt);
            }
            None => tcps.push(crate::robot::tcps_world(&m, qs.iter())),
        }
    }
    let mut out = Vec::with_capacity(qs.len());
    for k in 0..qs.len() {
        let cols = Matrix3::from_columns(&[1, 2, 3].map(|a| (tcps[a][k] - tcps[0][k]) / AXIS_MM));
        // The columns are orthonormal up to rounding.
        let r = Rotation3::from_matrix_unchecked(cols);
        let mut d = DMatrix::zeros(3, p);
        for c in 0..p {
            let dr = Matrix3::from_fn(|i, a| (jts[a + 1][(3 * k + i) * p + c] - jts[0][(3 * k + i) * p + c]) / AXIS_MM);
            // dR = [w] R: [w] = dR R^T.
            let w = dr * r.matrix().transpose();
            d.column_mut(c).copy_from(&Vector3::new(
                0.5 * (w[(2, 1)] - w[(1, 2)]),
                0.5 * (w[(0, 2)] - w[(2, 0)]),
                0.5 * (w[(1, 0)] - w[(0, 1)]),
            ));
        }
        out.push((r, d));
    }
    if !out.iter().all(|(r, d)| r.matrix().iter().chain(d.iter()).all(|v| v.is_finite())) {
        return None;
    }
    Some(out)
}

impl Oriented<'_> {
    /// The first column of target `t`'s rotation block (`None`: the target has no reading).
    pub fn rotation_column(&self, t: usize) -> Option<usize> {
        self.tool_rotations.get(t)?.as_ref()?;
        let before = self.tool_rotations[..t].iter().filter(|r| r.is_some()).count();
        Some(self.problem.layout.len() + 3 * before)
    }

    /// Number of targets with readings.
    fn rotated(&self) -> usize {
        self.tool_rotations.iter().filter(|r| r.is_some()).count()
    }

    /// Target `t`'s probe rotation on the flange at `x`.
    pub fn tool_rotation(&self, x: &[f64], t: usize) -> Option<Rotation3<f64>> {
        let c = self.rotation_column(t)?;
        let r0 = self.tool_rotations[t]?;
        Some(Rotation3::new(Vector3::new(x[c], x[c + 1], x[c + 2])) * r0)
    }

    /// The points of `idx` with a reading.
    fn read(&self, idx: &[usize]) -> Vec<usize> {
        idx.iter().copied().filter(|&i| self.readings.get(i).is_some_and(Option::is_some)).collect()
    }

    /// Per point of `idx` with a reading (in the order of `idx`): the point, its rotation error
    /// `log(R_measured R_model^T)` (rad, unweighted) and, if `jacobian`, the point's rows of the
    /// weighted Jacobian over its columns (3 x (point set + 3): the point's set, then its target's
    /// rotation block). `None` when `x` makes no model.
    #[allow(clippy::type_complexity)]
    fn rotation_rows(&self, x: &[f64], idx: &[usize], jacobian: bool) -> Option<Vec<(usize, Vector3<f64>, Option<DMatrix<f64>>)>> {
        use rayon::prelude::*;
        let read = self.read(idx);
        if read.is_empty() {
            return Some(Vec::new());
        }
        let l = &self.problem.layout;
        let set = l.point_set();
        let groups = groups(self.problem.obs, &read);
        let models = self.problem.models(x, &groups)?;
        let pieces = pieces(&groups);
        let done: Vec<Option<Vec<(usize, Vector3<f64>, Option<DMatrix<f64>>)>>> = pieces
            .par_iter()
            .map(|(g, rg)| {
                let ((_, t), members) = &groups[*g];
                let members = &members[rg.clone()];
                let qs: Vec<Joints> = members.iter().map(|(_, i)| self.problem.obs[*i].q).collect();
                let flanges = flange_rotations(&models[*g], jacobian.then_some(&set), &qs)?;
                let c = self.rotation_column(*t)?;
                let delta = Vector3::new(x[c], x[c + 1], x[c + 2]);
                let tool = self.tool_rotation(x, *t)?;
                let jl = left_jacobian(&delta);
                let mut out = Vec::with_capacity(members.len());
                for ((_, i), (rf, d)) in members.iter().zip(flanges) {
                    let reading = self.readings[*i]?;
                    let model = rf * tool;
                    let e = log(&(reading.measured * model.inverse()));
                    let rows = jacobian.then(|| {
                        let a = right_jacobian_inverse(&e) / reading.sigma_rad;
                        let mut j = DMatrix::zeros(3, set.len() + 3);
                        j.columns_mut(0, set.len()).copy_from(&(a * &d));
                        j.columns_mut(set.len(), 3).copy_from(&(a * rf.matrix() * jl));
                        j
                    });
                    out.push((*i, e, rows));
                }
                Some(out)
            })
            .collect();
        let mut by_point: std::collections::HashMap<usize, (Vector3<f64>, Option<DMatrix<f64>>)> = std::collections::HashMap::new();
        for piece in done {
            for (i, e, j) in piece? {
                by_point.insert(i, (e, j));
            }
        }
        read.iter()
            .map(|i| {
                let (e, j) = by_point.remove(i)?;
                (e.iter().all(|v| v.is_finite()) && j.as_ref().is_none_or(|j| j.iter().all(|v| v.is_finite()))).then_some((*i, e, j))
            })
            .collect()
    }

    /// The column of `x` of column `c` of a rotation row ([`Self::rotation_rows`]) of a point of
    /// session `s` and target `t`.
    fn rotation_column_of(&self, c: usize, s: usize, t: usize) -> usize {
        let p = self.problem.layout.point_set().len();
        if c < p { self.problem.layout.column_of(c, s, t) } else { self.rotation_column(t).expect("a target with readings") + c - p }
    }
}

impl Fit for Oriented<'_> {
    fn positions(&self) -> &Problem<'_> {
        &self.problem
    }
    fn unknowns(&self) -> usize {
        self.problem.layout.len() + 3 * self.rotated()
    }
    fn cost(&self, x: &[f64], idx: &[usize]) -> f64 {
        self.cost_and_errors(x, idx).0
    }
    fn cost_and_errors(&self, x: &[f64], idx: &[usize]) -> (f64, Option<Vec<Vector3<f64>>>) {
        let (positions, errors) = self.problem.cost_and_errors(x, idx);
        if self.rotated() == 0 {
            return (positions, errors);
        }
        match self.rotation_rows(x, idx, false) {
            Some(rows) => {
                let rotations =
                    rows.iter().map(|(i, e, _)| (e / self.readings[*i].map_or(1.0, |r| r.sigma_rad)).norm_squared()).sum::<f64>();
                (positions + rotations, errors)
            }
            None => (f64::INFINITY, errors),
        }
    }
    fn normal_equations_and_cost(&self, x: &[f64], idx: &[usize], cols: &[usize]) -> Option<(DMatrix<f64>, DVector<f64>, f64)> {
        if self.rotated() == 0 {
            return self.problem.normal_equations_and_cost(x, idx, cols);
        }
        let (n, b) = self.normal_equations(x, idx, cols)?;
        Some((n, b, self.cost(x, idx)))
    }
    fn normal_equations(&self, x: &[f64], idx: &[usize], cols: &[usize]) -> Option<(DMatrix<f64>, DVector<f64>)> {
        if self.rotated() == 0 {
            return self.problem.normal_equations(x, idx, cols);
        }
        let (mut n, mut b) = self.problem.normal_equations(x, idx, cols)?;
        let mut at = vec![usize::MAX; self.unknowns()];
        for (k, &c) in cols.iter().enumerate() {
            at[c] = k;
        }
        for (i, e, j) in self.rotation_rows(x, idx, true)? {
            let o = &self.problem.obs[i];
            let j = j?;
            let r = e / self.readings[i]?.sigma_rad;
            let used: Vec<(usize, usize)> = (0..j.ncols())
                .map(|c| (c, at[self.rotation_column_of(c, o.session, o.target)]))
                .filter(|(_, a)| *a != usize::MAX)
                .collect();
            for &(u, au) in &used {
                b[au] += j.column(u).dot(&r);
                for &(w, aw) in &used {
                    n[(au, aw)] += j.column(u).dot(&j.column(w));
                }
            }
        }
        Some((n, b))
    }
    fn linearise(&self, x: &[f64], idx: &[usize]) -> Option<(DVector<f64>, DMatrix<f64>)> {
        if self.rotated() == 0 {
            return self.problem.linearise(x, idx);
        }
        let (r, j) = self.problem.linearise(x, idx)?;
        let rows = self.rotation_rows(x, idx, true)?;
        let n = r.len();
        let mut r = r.resize_vertically(n + 3 * rows.len(), 0.0);
        let mut j = j.resize(n + 3 * rows.len(), self.unknowns(), 0.0);
        for (k, (i, e, jr)) in rows.iter().enumerate() {
            let o = &self.problem.obs[*i];
            let jr = jr.as_ref()?;
            let sigma = self.readings[*i]?.sigma_rad;
            for a in 0..3 {
                r[n + 3 * k + a] = e[a] / sigma;
                for c in 0..jr.ncols() {
                    j[(n + 3 * k + a, self.rotation_column_of(c, o.session, o.target))] += jr[(a, c)];
                }
            }
        }
        Some((r, j))
    }
    fn r_factor(&self, x: &[f64], idx: &[usize]) -> Option<DMatrix<f64>> {
        if self.rotated() == 0 {
            return self.problem.r_factor(x, idx);
        }
        let r = self.problem.r_factor(x, idx)?.resize_horizontally(self.unknowns(), 0.0);
        let rows = self.rotation_rows(x, idx, true)?;
        if rows.is_empty() {
            return Some(r);
        }
        // The rotation rows in pieces, each stacked under the factor so far and reduced again.
        let mut r = r;
        for chunk in rows.chunks(PIECE) {
            let at = r.nrows();
            let mut stacked = r.resize_vertically(at + 3 * chunk.len(), 0.0);
            for (k, (i, _, jr)) in chunk.iter().enumerate() {
                let o = &self.problem.obs[*i];
                let jr = jr.as_ref()?;
                for a in 0..3 {
                    for c in 0..jr.ncols() {
                        stacked[(at + 3 * k + a, self.rotation_column_of(c, o.session, o.target))] += jr[(a, c)];
                    }
                }
            }
            r = reduce(stacked);
        }
        Some(r)
    }
    fn own_columns(&self, idx: &[usize]) -> Vec<usize> {
        let mut out = Vec::new();
        for t in 0..self.tool_rotations.len() {
            if let Some(c) = self.rotation_column(t)
                && idx.iter().any(|&i| self.problem.obs[i].target == t && self.readings[i].is_some())
            {
                out.extend(c..c + 3);
            }
        }
        out
    }
    fn own_rows(&self, idx: &[usize]) -> usize {
        if self.rotated() == 0 {
            return 0;
        }
        3 * self.read(idx).len()
    }
    fn own_names(&self, targets: &[String]) -> Vec<String> {
        let mut v = Vec::new();
        for (t, r) in self.tool_rotations.iter().enumerate() {
            if r.is_some() {
                let label = targets.get(t).cloned().unwrap_or_else(|| t.to_string());
                v.extend(["rx", "ry", "rz"].iter().map(|k| format!("tool[{label}].{k}")));
            }
        }
        v
    }
    /// Per point of `idx`: its rotation error `log(R_measured R_model^T)` at `x`, rad (`None` for a
    /// point without a reading); `None` when `x` makes no model.
    fn reading_sigma(&self, i: usize) -> Option<f64> {
        self.readings.get(i).copied().flatten().map(|r| r.sigma_rad)
    }
    fn rotation_errors(&self, x: &[f64], idx: &[usize]) -> Option<Vec<Option<Vector3<f64>>>> {
        if self.rotated() == 0 {
            return None;
        }
        let rows = self.rotation_rows(x, idx, false)?;
        let mut by: std::collections::HashMap<usize, Vector3<f64>> = rows.into_iter().map(|(i, e, _)| (i, e)).collect();
        Some(idx.iter().map(|i| by.remove(i)).collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    /// The IRB 120 with Table 7's compliance, its robot parameters free, 3 sessions and 2 targets,
    /// `count` points drawn from `seed` (weights 0.5-0.8), and a state with session bases at zero
    /// and two tools.
    fn fixture(count: usize, seed: u64) -> (crate::robot::RobotModel, Layout, Vec<Obs>, Vec<f64>) {
        let model = crate::robot::builtin::trical_2018_table7();
        let set = ParamSet::trical_31();
        let robot = ParamSet::new(set.ids().iter().copied().filter(|id| !matches!(id, ParamId::Base(_))).collect()).unwrap();
        let layout = Layout { robot, sessions: 3, targets: 2, still: vec![] };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let obs: Vec<Obs> = (0..count)
            .map(|k| Obs {
                q: crate::robot::uniform_configuration(&model, 0.1, &mut rng),
                measured_mm: Vector3::new(rng.random_range(-500.0..500.0), rng.random_range(-500.0..500.0), rng.random_range(0.0..600.0)),
                session: (k * 7) % 3,
                target: (k / 2) % 2,
                sigma: 0.5 + 0.1 * (k % 4) as f64,
            })
            .collect();
        let mut x: Vec<f64> = layout.robot.pack(&model).iter().copied().collect();
        x.extend(std::iter::repeat_n(0.0, 6 * layout.sessions));
        x.extend([10.0, 20.0, 80.0, -30.0, 5.0, 60.0]);
        (model, layout, obs, x)
    }

    /// Points of one pose at several targets (runs of one to three, each target of a session its
    /// own group) take their joints' sines and cosines once per run: the errors, the residuals and
    /// Jacobian, the normal equations and cost, a start's Jacobians and the triangular factor are
    /// those the kernels give computing every point's, bit for bit. The IRB 120 with Table 7's
    /// compliance, 3 sessions, 3 targets, 1,500 points (pieces of more than one run of lanes).
    #[test]
    fn a_poses_targets_share_its_angles_with_the_same_bits() {
        let (model, mut layout, mut obs, mut x) = fixture(1500, 43);
        layout.targets = 3;
        x.extend([-40.0, 15.0, 70.0]);
        // Runs of 1, 2 and 3 points at one configuration, a target each, in one session.
        let mut k = 0;
        let mut run = 0;
        while k < obs.len() {
            let len = (1 + run % 3).min(obs.len() - k);
            for t in 0..len {
                obs[k + t].q = obs[k].q;
                obs[k + t].session = obs[k].session;
                obs[k + t].target = t;
            }
            k += len;
            run += 1;
        }
        let problem = Problem { start: &model, layout: layout.clone(), obs: &obs };
        let idx: Vec<usize> = (0..obs.len()).collect();
        let every: Vec<usize> = (0..layout.len()).collect();
        let groups = groups(&obs, &idx);
        let models = problem.models(&x, &groups).unwrap();
        assert!(problem.shared_angles(&models, &idx).is_some(), "runs shared");
        assert!(problem.shared_angles(&models, &[0]).is_none(), "one point: nothing shared");
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<u64>>();
        let passes = || {
            let errors: Vec<f64> = problem.errors(&x, &idx).unwrap().iter().flat_map(|e| e.iter().copied()).collect();
            let (r, j) = problem.linearise(&x, &idx).unwrap();
            let (n, b, cost) = problem.normal_equations_and_cost(&x, &idx, &every).unwrap();
            let start = problem.start_at(&x).unwrap();
            let rf = problem.r_factor(&x, &idx).unwrap();
            [
                errors,
                r.as_slice().to_vec(),
                j.as_slice().to_vec(),
                n.as_slice().to_vec(),
                b.as_slice().to_vec(),
                vec![cost],
                start.jt,
                rf.as_slice().to_vec(),
            ]
        };
        let shared = passes();
        NOT_SHARED.with(|c| c.set(true));
        let own = passes();
        NOT_SHARED.with(|c| c.set(false));
        for (a, b) in shared.iter().zip(&own) {
            assert_eq!(bits(a), bits(b));
        }
    }

    /// The normal equations and cost of fits started at a [`Start`] are those computed point by
    /// point, bit for bit: its `x` with subsets of the points (every other one, a fold's share in
    /// reverse order) and of the columns; another `x` ignores it; a fit with unknowns of its own
    /// gets no start. The IRB 120 with Table 7's compliance, 3 sessions, 2 targets, 2,100 points
    /// (pieces of more than one run of lanes).
    #[test]
    fn fits_started_at_a_start_take_the_same_normal_equations() {
        let (model, layout, obs, x) = fixture(2100, 41);
        let problem = Problem { start: &model, layout: layout.clone(), obs: &obs };
        let start = problem.start_at(&x).unwrap();
        let started = Started { fit: &problem, start: &start };
        let mut moved = x.clone();
        moved[0] += 1e-7;
        let bits =
            |(n, b, c): (DMatrix<f64>, DVector<f64>, f64)| (n.iter().chain(b.iter()).map(|v| v.to_bits()).collect::<Vec<_>>(), c.to_bits());
        for idx in [(0..obs.len()).filter(|i| i % 2 == 0).collect::<Vec<_>>(), (0..obs.len()).rev().filter(|i| i % 5 != 3).collect()] {
            for free in [(0..layout.len()).collect::<Vec<_>>(), (0..layout.len()).filter(|c| c % 3 != 1).collect()] {
                for at in [&x, &moved] {
                    let want = bits(problem.normal_equations_and_cost(at, &idx, &free).unwrap());
                    assert_eq!(bits(started.normal_equations_and_cost(at, &idx, &free).unwrap()), want);
                }
            }
        }
        // A fit with unknowns of its own (its probes' rotations on the flange) gets no start (it
        // would not use it); one with orientation readings on no target does.
        let none = vec![None; obs.len()];
        let plain = Oriented { problem: problem.clone(), readings: &none, tool_rotations: &[None, None] };
        assert!(Start::for_fit(&plain, &x).is_some());
        let readings = vec![Some(Reading { measured: Rotation3::identity(), sigma_rad: 0.01 }); obs.len()];
        let rotations = [Some(Rotation3::identity()), Some(Rotation3::identity())];
        let oriented = Oriented { problem: problem.clone(), readings: &readings, tool_rotations: &rotations };
        assert!(oriented.unknowns() > layout.len());
        assert!(Start::for_fit(&oriented, &x).is_none());
    }

    /// A fit started at its own minimum tries one step there and stops: a step whose predicted
    /// decrease is within the cost rule is not retried with more damping (each retry a pass of
    /// the positions whose outcome the rounding of the cost decides). The IRB 120 with Table 7's
    /// compliance, 3 sessions, 2 targets, 60 points measured with frames a little off the start
    /// and 0.01 mm of noise, the bases and tools free; 16 problems, each solved, then solved again
    /// from its solution counting the passes of the cost.
    #[test]
    fn a_fit_started_at_its_minimum_tries_one_step() {
        use std::sync::atomic::{AtomicUsize, Ordering};
        struct Counting<'a> {
            problem: Problem<'a>,
            costs: AtomicUsize,
        }
        impl Fit for Counting<'_> {
            fn positions(&self) -> &Problem<'_> {
                &self.problem
            }
            fn unknowns(&self) -> usize {
                self.problem.unknowns()
            }
            fn cost(&self, x: &[f64], idx: &[usize]) -> f64 {
                self.costs.fetch_add(1, Ordering::Relaxed);
                self.problem.cost(x, idx)
            }
            fn normal_equations(&self, x: &[f64], idx: &[usize], cols: &[usize]) -> Option<(DMatrix<f64>, DVector<f64>)> {
                self.problem.normal_equations(x, idx, cols)
            }
            fn normal_equations_and_cost(&self, x: &[f64], idx: &[usize], cols: &[usize]) -> Option<(DMatrix<f64>, DVector<f64>, f64)> {
                self.problem.normal_equations_and_cost(x, idx, cols)
            }
            fn linearise(&self, x: &[f64], idx: &[usize]) -> Option<(DVector<f64>, DMatrix<f64>)> {
                self.problem.linearise(x, idx)
            }
            fn r_factor(&self, x: &[f64], idx: &[usize]) -> Option<DMatrix<f64>> {
                self.problem.r_factor(x, idx)
            }
            fn own_columns(&self, idx: &[usize]) -> Vec<usize> {
                self.problem.own_columns(idx)
            }
            fn own_names(&self, targets: &[String]) -> Vec<String> {
                self.problem.own_names(targets)
            }
            fn own_rows(&self, idx: &[usize]) -> usize {
                self.problem.own_rows(idx)
            }
            fn rotation_errors(&self, x: &[f64], idx: &[usize]) -> Option<Vec<Option<Vector3<f64>>>> {
                self.problem.rotation_errors(x, idx)
            }
        }
        let opts = SolveOptions::default();
        let mut retried = Vec::new();
        for seed in 0..16 {
            let (model, layout, mut obs, x) = fixture(60, 500 + seed);
            // Positions of frames a little off the start, with 0.01 mm of noise.
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            let mut truth = x.clone();
            for c in layout.frames() {
                truth[c] += rng.random_range(-1e-3..1e-3) * if c < layout.tool(0) { 1.0 } else { 1e3 };
            }
            let zero: Vec<Obs> = obs.iter().map(|o| Obs { measured_mm: Vector3::zeros(), ..*o }).collect();
            let at =
                Problem { start: &model, layout: layout.clone(), obs: &zero }.errors(&truth, &(0..obs.len()).collect::<Vec<_>>()).unwrap();
            for (o, e) in obs.iter_mut().zip(at) {
                o.measured_mm = -e + Vector3::from_fn(|_, _| rng.random_range(-0.01..0.01));
            }
            let fit = Counting { problem: Problem { start: &model, layout: layout.clone(), obs: &obs }, costs: AtomicUsize::new(0) };
            let idx: Vec<usize> = (0..obs.len()).collect();
            let free: Vec<usize> = layout.frames().collect();
            let first = solve(&fit, &x, &free, &idx, &opts);
            assert!(first.outcome.is_converged(), "{seed}: {:?}", first.outcome);
            fit.costs.store(0, Ordering::Relaxed);
            let again = solve(&fit, &first.x, &free, &idx, &opts);
            assert!(again.outcome.is_converged(), "{seed}: {:?}", again.outcome);
            assert!(again.cost <= first.cost * (1.0 + 1e-12), "{seed}: {} after {}", again.cost, first.cost);
            let costs = fit.costs.load(Ordering::Relaxed);
            if costs > 1 {
                retried.push((seed, costs));
            }
        }
        assert!(retried.is_empty(), "(problem, passes of the cost) from the minimum: {retried:?}");
    }

    /// The normal equations accumulated point by point equal `J_f^T J_f` and `J_f^T r` of the dense
    /// Jacobian on a subset of free columns (robot, bases, tools), to 1e-12 of the largest entry:
    /// the IRB 120 with Table 7's compliance, 3 sessions, 2 targets, 30 points.
    #[test]
    fn normal_equations_equal_the_dense_products() {
        let (model, layout, obs, x) = fixture(30, 36);
        let problem = Problem { start: &model, layout: layout.clone(), obs: &obs };
        let idx: Vec<usize> = (0..obs.len()).filter(|i| i % 5 != 3).collect();
        let free: Vec<usize> = (0..layout.len()).filter(|c| c % 4 != 1).collect();
        let (r, j) = problem.linearise(&x, &idx).unwrap();
        let jf = j.select_columns(&free);
        let (n_dense, b_dense) = (jf.tr_mul(&jf), jf.tr_mul(&r));
        let (n, b) = problem.normal_equations(&x, &idx, &free).unwrap();
        let scale = n_dense.amax().max(b_dense.amax());
        assert!((&n - &n_dense).amax() <= 1e-12 * scale, "N differs by {}", (&n - &n_dense).amax());
        assert!((&b - &b_dense).amax() <= 1e-12 * scale, "b differs by {}", (&b - &b_dense).amax());
        assert_eq!(n, n.transpose(), "symmetric");
    }

    /// The normal equations' cost is the cost's to the bit, and its normal equations those of
    /// [`Problem::normal_equations`]: points in an order of their own (not by group), groups of
    /// more than one piece, weights other than one.
    #[test]
    fn normal_equations_and_cost_give_the_cost_bit_for_bit() {
        let (model, layout, obs, x) = fixture(7000, 38);
        let problem = Problem { start: &model, layout: layout.clone(), obs: &obs };
        let idx: Vec<usize> = (0..obs.len()).rev().filter(|i| i % 7 != 2).collect();
        let free: Vec<usize> = (0..layout.len()).filter(|c| c % 3 != 1).collect();
        let (n, b, cost) = problem.normal_equations_and_cost(&x, &idx, &free).unwrap();
        assert_eq!(cost.to_bits(), problem.cost(&x, &idx).to_bits());
        assert!(cost > 0.0 && cost.is_finite());
        assert_eq!((n, b), problem.normal_equations(&x, &idx, &free).unwrap());
    }

    /// The triangular factor has the Gram matrix and the singular values of the dense weighted
    /// Jacobian: `R^T R = J^T J` to 1e-12 of the largest entry, singular values to 1e-9 of the
    /// largest, at most one row per unknown; the IRB 120 with Table 7's compliance, 3 sessions, 2
    /// targets, 240 points (groups of more rows than their columns: each piece factored).
    #[test]
    fn r_factor_has_the_jacobians_gram_matrix_and_singular_values() {
        let (model, layout, obs, x) = fixture(240, 37);
        let problem = Problem { start: &model, layout: layout.clone(), obs: &obs };
        let idx: Vec<usize> = (0..obs.len()).filter(|i| i % 7 != 3).collect();
        let (_, j) = problem.linearise(&x, &idx).unwrap();
        let r = problem.r_factor(&x, &idx).unwrap();
        assert!(r.nrows() <= layout.len(), "{} rows", r.nrows());
        let (want, got) = (j.tr_mul(&j), r.tr_mul(&r));
        assert!((&got - &want).amax() <= 1e-12 * want.amax(), "R^T R differs by {}", (&got - &want).amax());
        let sorted = |m: DMatrix<f64>| {
            let mut s: Vec<f64> = m.singular_values().iter().copied().collect();
            s.sort_by(|a, b| b.total_cmp(a));
            s
        };
        let (sj, sr) = (sorted(j), sorted(r));
        for (a, b) in sj.iter().zip(&sr) {
            assert!((a - b).abs() <= 1e-9 * sj[0], "singular values {a} and {b}");
        }
    }

    /// The product by blocks of rows is nalgebra's `A X` bit for bit: 1 to 40,000 rows (one block,
    /// several, a last one short), 1 to 70 columns of `A`, 1 to 90 of `X`, entries over six decades.
    #[test]
    fn the_product_by_blocks_of_rows_is_nalgebras() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        for (n, k, c) in [(1, 1, 1), (7, 3, 90), (8192, 31, 1), (8193, 5, 7), (20_000, 70, 12), (40_000, 24, 60)] {
            let mut entry = || rng.random_range(-1.0..1.0) * 10f64.powi(rng.random_range(-3..=3));
            let a = DMatrix::from_fn(n, k, |_, _| entry());
            let x = DMatrix::from_fn(k, c, |_, _| entry());
            let (got, want) = (mul(&a, &x), &a * &x);
            assert!(got.iter().zip(want.iter()).all(|(g, w)| g.to_bits() == w.to_bits()), "{n} x {k} times {k} x {c}");
        }
    }

    /// The Gram matrix of a block equals nalgebra's `B^T B` bit for bit (the normal equations of
    /// every fit are summed by it), on every path (the CPU's and each tile shape's): blocks of 1 to
    /// 3,072 rows (rows left over past a multiple of eight and past a run of groups among them), 1 to
    /// 28 columns (tiles left over at the right and at the bottom), entries of mixed sign and
    /// magnitude.
    #[test]
    fn gram_equals_nalgebra_bit_for_bit() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let (mut out, mut acc) = (Vec::new(), Vec::new());
        for (rows, cols) in [(1, 1), (7, 3), (8, 2), (13, 9), (256, 4), (263, 5), (600, 9), (1031, 11), (3072, 28)] {
            let b = DMatrix::<f64>::from_fn(rows, cols, |_, _| rng.random_range(-1.0..1.0) * 10f64.powi(rng.random_range(-6..6)));
            let mut grouped = vec![0.0; rows.div_ceil(8) * 8 * cols];
            for r in 0..rows {
                for c in 0..cols {
                    grouped[(r / 8 * cols + c) * 8 + r % 8] = b[(r, c)];
                }
            }
            gram(&grouped, rows, cols, &mut acc, &mut out);
            let mut paths = vec![("cpu", out.clone())];
            for (name, body) in [
                ("portable 2 x 2", gram_body::<2, 2> as fn(&[f64], usize, usize, &mut Vec<[f64; 8]>, &mut Vec<f64>)),
                ("portable 2 x 4", gram_body::<2, 4>),
                ("portable 1 x 1", gram_body::<1, 1>),
                ("portable 3 x 5", gram_body::<3, 5>),
            ] {
                let mut portable = Vec::new();
                body(&grouped, rows, cols, &mut acc, &mut portable);
                paths.push((name, portable));
            }
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2") {
                let mut wide = Vec::new();
                // SAFETY: the CPU supports AVX2.
                #[allow(unsafe_code)]
                unsafe {
                    gram_avx2(&grouped, rows, cols, &mut acc, &mut wide)
                };
                paths.push(("avx2", wide));
            }
            let want = b.tr_mul(&b);
            for (name, got) in &paths {
                for u in 0..cols {
                    for w in 0..cols {
                        assert_eq!(got[u * cols + w].to_bits(), want[(u, w)].to_bits(), "{name} {rows} x {cols}: ({u}, {w})");
                    }
                }
            }
        }
    }

    /// [`mul_vectors`] equals nalgebra's `A x` for each vector bit for bit: 1 to 2,000 rows (a block
    /// and a short last one), 1 to 60 columns, 1 to 9 vectors; entries of mixed sign and magnitude,
    /// zeros of both signs (a product of -0 starts a sum), infinities and NaN.
    #[test]
    fn mul_vectors_equals_nalgebra_bit_for_bit() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(12);
        for (rows, cols, m) in [(1, 1, 1), (7, 3, 2), (513, 1, 9), (1024, 6, 8), (2000, 60, 3), (517, 11, 5)] {
            let mut value = || match rng.random_range(0..40) {
                0 => -0.0,
                1 => 0.0,
                2 => f64::INFINITY,
                3 => f64::NAN,
                _ => rng.random_range(-1.0..1.0) * 10f64.powi(rng.random_range(-6..6)),
            };
            let a = DMatrix::<f64>::from_fn(rows, cols, |_, _| value());
            let xs: Vec<DVector<f64>> = (0..m).map(|_| DVector::from_fn(cols, |_, _| value())).collect();
            let bits = |v: &DVector<f64>| v.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            for (got, x) in mul_vectors(&a, &xs).iter().zip(&xs) {
                assert_eq!(bits(got), bits(&(&a * x)), "{rows} x {cols}, {m} vectors");
            }
        }
    }

    /// [`tr_mul`] equals nalgebra's `A^T B` and `A^T A` bit for bit: 1 to 2,000 rows (rows left over
    /// past a multiple of eight and past a run), 1 to 11 columns of `A`, 1 to 140 of `B` (tiles and
    /// blocks of columns left over), entries of mixed sign and magnitude.
    #[test]
    fn tr_mul_equals_nalgebra_bit_for_bit() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        for (rows, ca, cb) in [(1, 1, 1), (7, 3, 2), (8, 2, 5), (13, 9, 1), (517, 5, 11), (2000, 11, 7), (300, 3, 140)] {
            let mut draw =
                |c: usize| DMatrix::<f64>::from_fn(rows, c, |_, _| rng.random_range(-1.0..1.0) * 10f64.powi(rng.random_range(-6..6)));
            let (a, b) = (draw(ca), draw(cb));
            let bits = |m: &DMatrix<f64>| m.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&tr_mul(&a, Some(&b))), bits(&a.tr_mul(&b)), "{rows} x {ca} by {cb}");
            assert_eq!(bits(&tr_mul(&a, None)), bits(&a.tr_mul(&a)), "{rows} x {ca}");
            let mut portable = Vec::new();
            tr_mul_body::<3, 2>(a.as_slice(), b.as_slice(), rows, ca, 0..cb, false, &mut portable);
            let want = a.tr_mul(&b);
            for u in 0..ca {
                for w in 0..cb {
                    assert_eq!(portable[u * cb + w].to_bits(), want[(u, w)].to_bits(), "portable {rows} x {ca} by {cb}: ({u}, {w})");
                }
            }
        }
    }

    /// Every column of the calibration Jacobian (robot parameters with compliance, each session's
    /// base, each target's tool) equals the central difference of the predicted positions, on
    /// the IRB 120 with Table 7's compliance, 3 sessions, 2 targets, 24 points; step 1e-6 in
    /// internal units; agreement to 1e-5 of the column's largest entry (plus 1e-7 absolute).
    #[test]
    fn calibration_jacobian_columns_equal_central_differences() {
        let model = crate::robot::builtin::trical_2018_table7();
        let set = ParamSet::trical_31();
        let robot = ParamSet::new(set.ids().iter().copied().filter(|id| !matches!(id, ParamId::Base(_))).collect()).unwrap();
        let layout = Layout { robot, sessions: 3, targets: 2, still: vec![] };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(35);
        let obs: Vec<Obs> = (0..24)
            .map(|k| Obs {
                q: crate::robot::uniform_configuration(&model, 0.1, &mut rng),
                measured_mm: Vector3::zeros(),
                session: k % 3,
                target: (k / 3) % 2,
                sigma: 0.5 + 0.1 * (k % 4) as f64,
            })
            .collect();
        let problem = Problem { start: &model, layout: layout.clone(), obs: &obs };
        let mut x: Vec<f64> = layout.robot.pack(&model).iter().copied().collect();
        for _ in 0..layout.sessions {
            x.extend([12.0, -30.0, 4.0, 0.02, -0.01, 0.03].iter().map(|v| v + rng.random_range(-1.0..1.0) * 1e-3));
        }
        for _ in 0..layout.targets {
            x.extend([rng.random_range(-60.0..60.0), rng.random_range(-60.0..60.0), rng.random_range(20.0..90.0)]);
        }
        let idx: Vec<usize> = (0..obs.len()).collect();
        let (_, j) = problem.linearise(&x, &idx).unwrap();
        let names = layout.names(&["a".into(), "b".into(), "c".into()], &["s1".into(), "s2".into()]);
        let h = 1e-6;
        for c in 0..layout.len() {
            let (mut xp, mut xm) = (x.clone(), x.clone());
            xp[c] += h;
            xm[c] -= h;
            let (ep, em) = (problem.errors(&xp, &idx).unwrap(), problem.errors(&xm, &idx).unwrap());
            let scale = j.column(c).amax();
            for (i, o) in obs.iter().enumerate() {
                // errors are measured minus predicted: d pred = -(d error).
                let fd = -(ep[i] - em[i]) / (2.0 * h) / o.sigma;
                for a in 0..3 {
                    let an = j[(3 * i + a, c)];
                    assert!(
                        (an - fd[a]).abs() <= 1e-5 * scale + 1e-7,
                        "{}: point {i} axis {a}: analytic {an}, central {}",
                        names[c],
                        fd[a]
                    );
                }
            }
        }
    }

    /// The rotation rows of the oriented Jacobian (robot parameters with compliance, each session's
    /// base, each target's tool position and probe rotation) equal the central differences of the
    /// rotation errors: the IRB 120 with Table 7's compliance, 3 sessions, 2 targets, 24 points with
    /// readings far from the model (errors of up to about 0.5 rad, where `log`'s Jacobian is not the
    /// identity) and probe rotations away from their start; step 1e-6 in internal units; agreement
    /// to 1e-5 of the column's largest entry (plus 1e-7 absolute); the position rows are those of
    /// the problem alone.
    #[test]
    fn rotation_rows_equal_central_differences() {
        let model = crate::robot::builtin::trical_2018_table7();
        let set = ParamSet::trical_31();
        let robot = ParamSet::new(set.ids().iter().copied().filter(|id| !matches!(id, ParamId::Base(_))).collect()).unwrap();
        let layout = Layout { robot, sessions: 3, targets: 2, still: vec![] };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(42);
        let mut turn = || Vector3::new(rng.random_range(-0.3..0.3), rng.random_range(-0.3..0.3), rng.random_range(-0.3..0.3));
        let readings: Vec<Option<Reading>> = (0..24)
            .map(|k| (k % 5 != 2).then(|| Reading { measured: Rotation3::new(turn()), sigma_rad: 0.01 + 0.002 * (k % 3) as f64 }))
            .collect();
        let tool_rotations = vec![Some(Rotation3::new(turn())), Some(Rotation3::new(turn()))];
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(43);
        let obs: Vec<Obs> = (0..24)
            .map(|k| Obs {
                q: crate::robot::uniform_configuration(&model, 0.1, &mut rng),
                measured_mm: Vector3::zeros(),
                session: k % 3,
                target: (k / 3) % 2,
                sigma: 0.5,
            })
            .collect();
        let fit = Oriented {
            problem: Problem { start: &model, layout: layout.clone(), obs: &obs },
            readings: &readings,
            tool_rotations: &tool_rotations,
        };
        let mut x: Vec<f64> = layout.robot.pack(&model).iter().copied().collect();
        for _ in 0..layout.sessions {
            x.extend([12.0, -30.0, 4.0, 0.02, -0.01, 0.03].iter().map(|v| v + rng.random_range(-1.0..1.0) * 1e-3));
        }
        for _ in 0..layout.targets {
            x.extend([rng.random_range(-60.0..60.0), rng.random_range(-60.0..60.0), rng.random_range(20.0..90.0)]);
        }
        for _ in 0..2 {
            x.extend([rng.random_range(-0.2..0.2), rng.random_range(-0.2..0.2), rng.random_range(-0.2..0.2)]);
        }
        assert_eq!(x.len(), fit.unknowns());
        let idx: Vec<usize> = (0..obs.len()).collect();
        let read: Vec<usize> = idx.iter().copied().filter(|&i| readings[i].is_some()).collect();
        let (r, j) = fit.linearise(&x, &idx).unwrap();
        let (r0, j0) = fit.problem.linearise(&x, &idx).unwrap();
        assert_eq!(r.len(), 3 * idx.len() + 3 * read.len());
        assert_eq!(r.rows(0, r0.len()), r0.rows(0, r0.len()));
        assert_eq!(j.view((0, 0), (j0.nrows(), j0.ncols())), j0.view((0, 0), (j0.nrows(), j0.ncols())));
        let e0 = fit.rotation_errors(&x, &idx).unwrap();
        assert!(e0.iter().flatten().any(|e| e.norm() > 0.3), "errors far from zero");
        let mut names = layout.names(&["a".into(), "b".into(), "c".into()], &["s1".into(), "s2".into()]);
        names.extend(fit.own_names(&["s1".into(), "s2".into()]));
        let h = 1e-6;
        for c in 0..fit.unknowns() {
            let (mut xp, mut xm) = (x.clone(), x.clone());
            xp[c] += h;
            xm[c] -= h;
            let (ep, em) = (fit.rotation_errors(&xp, &idx).unwrap(), fit.rotation_errors(&xm, &idx).unwrap());
            let scale = j.column(c).amax();
            for (k, &i) in read.iter().enumerate() {
                let fd = -(ep[i].unwrap() - em[i].unwrap()) / (2.0 * h) / readings[i].unwrap().sigma_rad;
                for a in 0..3 {
                    let an = j[(3 * idx.len() + 3 * k + a, c)];
                    assert!(
                        (an - fd[a]).abs() <= 1e-5 * scale + 1e-7,
                        "{}: point {i} axis {a}: analytic {an}, central {}",
                        names[c],
                        fd[a]
                    );
                }
            }
        }
        // The normal equations and the triangular factor hold the same rows.
        let free: Vec<usize> = (0..fit.unknowns()).collect();
        let (n, b) = fit.normal_equations(&x, &idx, &free).unwrap();
        let (nd, bd) = (j.tr_mul(&j), j.tr_mul(&r));
        assert!((&n - &nd).amax() <= 1e-10 * nd.amax(), "N differs by {}", (&n - &nd).amax());
        assert!((&b - &bd).amax() <= 1e-10 * nd.amax().max(bd.amax()), "b differs by {}", (&b - &bd).amax());
        let rf = fit.r_factor(&x, &idx).unwrap();
        assert!((rf.tr_mul(&rf) - &nd).amax() <= 1e-10 * nd.amax());
        assert!((fit.cost(&x, &idx) - r.norm_squared()).abs() <= 1e-12 * r.norm_squared());
    }
}
