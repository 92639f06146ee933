//! Identification of the beams of an SPMS head (paper sections 3.3 and 4) from m poses of the head
//! around a fixed reference sphere, each pose known through the measurement frame `T_i`
//! (tracker_from_head) and giving K readings.
//!
//! Two parametrisations of the same residuals `|T_i (P_k + gamma_k L_ki) - P_Bw| - R` (eq. 14):
//! - [`Form::Paper`]: the paper's 6K + 3 unknowns, `P_k` and `gamma_k` free (gamma is not kept
//!   unit: its norm acts as a gain of the reading), plus the sphere centre `P_Bw`;
//! - [`Form::Minimal`]: 5K + 3 unknowns, `P_k` (3: the line's 2 and the reading offset along it)
//!   and `gamma_k` as two angles (unit by construction), plus `P_Bw`.
//!
//! Solvers: Levenberg-Marquardt with the damping rule of the paper (eqs. 17-23: `lambda_0 = tau
//! max diag(J^T J)`, gain ratio `rho`, `lambda *= max(1/3, 1 - (2 rho - 1)^3)` on success, `lambda
//! *= nu, nu *= 2` on failure), and particle swarm optimisation (eqs. 15-16) for a start.

use crate::identify::damping::Damping;
use nalgebra::{DMatrix, DVector, Isometry3, Point3, Vector3};
use rand::{Rng, RngExt};

use super::Beam;

/// The parametrisation of the beams.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Form {
    /// The paper's `P_k`, `gamma_k` (6 per beam), sphere centre.
    Paper,
    /// `P_k` and two direction angles (5 per beam), sphere centre.
    Minimal,
}

impl Form {
    /// Label for tables (`paper`, `minimal`), as a scenario names it.
    pub fn label(self) -> &'static str {
        match self {
            Self::Paper => "paper",
            Self::Minimal => "minimal",
        }
    }

    /// Unknowns per beam.
    pub fn per_beam(self) -> usize {
        match self {
            Self::Paper => 6,
            Self::Minimal => 5,
        }
    }

    /// Number of unknowns for `k` beams.
    pub fn len(self, k: usize) -> usize {
        self.per_beam() * k + 3
    }

    /// Packs beams (and the sphere centre) into a parameter vector.
    pub fn pack(self, beams: &[Beam], centre: &Vector3<f64>) -> DVector<f64> {
        let mut x = Vec::with_capacity(self.len(beams.len()));
        for b in beams {
            x.extend_from_slice(b.p.as_slice());
            let g = b.dir.into_inner();
            match self {
                Self::Paper => x.extend_from_slice(g.as_slice()),
                Self::Minimal => x.extend_from_slice(&[g.z.clamp(-1.0, 1.0).acos(), g.y.atan2(g.x)]),
            }
        }
        x.extend_from_slice(centre.as_slice());
        DVector::from_vec(x)
    }

    /// The beam `k` of a parameter vector: origin and (for the paper's form, unnormalised) direction.
    pub fn beam(self, x: &DVector<f64>, k: usize) -> (Vector3<f64>, Vector3<f64>) {
        let o = self.per_beam() * k;
        let p = Vector3::new(x[o], x[o + 1], x[o + 2]);
        let g = match self {
            Self::Paper => Vector3::new(x[o + 3], x[o + 4], x[o + 5]),
            Self::Minimal => {
                let (t, f) = (x[o + 3], x[o + 4]);
                Vector3::new(t.sin() * f.cos(), t.sin() * f.sin(), t.cos())
            }
        };
        (p, g)
    }

    /// The sphere centre of a parameter vector.
    pub fn centre(self, x: &DVector<f64>) -> Vector3<f64> {
        let n = x.len();
        Vector3::new(x[n - 3], x[n - 2], x[n - 1])
    }

    /// Unpacks the beams with unit directions. In the paper's form a direction that is not unit
    /// also scales the readings: that gain is reported by [`Form::gains`], and a reading `L` of
    /// beam k measures the point `p + dir * gains[k] * L`.
    pub fn unpack(self, x: &DVector<f64>, k: usize) -> Vec<Beam> {
        (0..k)
            .map(|j| {
                let (p, g) = self.beam(x, j);
                Beam { p, dir: nalgebra::Unit::new_normalize(g) }
            })
            .collect()
    }

    /// Norms of the directions (1 for the minimal form): the reading gain the paper's form implies.
    pub fn gains(self, x: &DVector<f64>, k: usize) -> Vec<f64> {
        (0..k).map(|j| self.beam(x, j).1.norm()).collect()
    }
}

/// The data of a beam identification: per pose, `tracker_from_head` and the K readings.
#[derive(Clone, Debug, Default)]
pub struct BeamData {
    /// Measurement frames, one per pose.
    pub frames: Vec<Isometry3<f64>>,
    /// Readings per pose, mm.
    pub readings: Vec<Vec<f64>>,
    /// Reference sphere radius, mm.
    pub radius_mm: f64,
}

impl BeamData {
    /// Residuals `|T_i (P_k + gamma_k L_ki) - P_Bw| - R`, pose-major.
    pub fn residuals(&self, form: Form, x: &DVector<f64>) -> DVector<f64> {
        let k = self.readings.first().map(|r| r.len()).unwrap_or(0);
        let c = form.centre(x);
        let beams: Vec<_> = (0..k).map(|j| form.beam(x, j)).collect();
        let mut out = Vec::with_capacity(self.frames.len() * k);
        for (t, ls) in self.frames.iter().zip(&self.readings) {
            for ((p, g), l) in beams.iter().zip(ls) {
                let f = t * Point3::from(p + g * *l);
                out.push((f.coords - c).norm() - self.radius_mm);
            }
        }
        DVector::from_vec(out)
    }

    /// Sum of squared residuals.
    pub fn cost(&self, form: Form, x: &DVector<f64>) -> f64 {
        self.residuals(form, x).norm_squared()
    }

    /// Jacobian of the residuals by central differences (step 1e-6 of the parameter scale).
    pub fn jacobian(&self, form: Form, x: &DVector<f64>) -> DMatrix<f64> {
        let r0 = self.residuals(form, x);
        let mut j = DMatrix::zeros(r0.len(), x.len());
        let mut xp = x.clone();
        for c in 0..x.len() {
            let h = 1e-6 * x[c].abs().max(1.0);
            xp[c] = x[c] + h;
            let rp = self.residuals(form, &xp);
            xp[c] = x[c] - h;
            let rm = self.residuals(form, &xp);
            xp[c] = x[c];
            j.set_column(c, &((rp - rm) / (2.0 * h)));
        }
        j
    }
}

/// What a solver reached.
#[derive(Clone, Debug)]
pub struct Solution {
    /// Parameters.
    pub x: DVector<f64>,
    /// Iterations made.
    pub iterations: usize,
    /// Root mean square of the residuals, mm.
    pub rms_mm: f64,
    /// Singular values of the Jacobian at the solution (LM only; empty for PSO).
    pub singular_values: Vec<f64>,
}

/// Levenberg-Marquardt from `x0` with the paper's damping rule; `tau` sets `lambda_0`.
pub fn levenberg_marquardt(data: &BeamData, form: Form, x0: &DVector<f64>, tau: f64, max_iterations: usize) -> Solution {
    let mut x = x0.clone();
    let mut r = data.residuals(form, &x);
    let mut j = data.jacobian(form, &x);
    let mut a = j.transpose() * &j;
    let mut g = j.transpose() * &r;
    let mut damping = Damping::start(tau, a.diagonal().max());
    let mut iterations = 0;
    while iterations < max_iterations {
        iterations += 1;
        let mut damped = a.clone();
        for i in 0..damped.nrows() {
            damped[(i, i)] += damping.mu;
        }
        let Some(step) = damped.cholesky().map(|c| c.solve(&(-&g))) else {
            damping.reject();
            continue;
        };
        if step.norm() <= 1e-12 * (x.norm() + 1e-12) {
            break;
        }
        let xn = &x + &step;
        let rn = data.residuals(form, &xn);
        // Gain ratio: actual over predicted decrease (eq. 21).
        let predicted = step.dot(&(damping.mu * &step - &g)) / 2.0;
        let rho = (r.norm_squared() - rn.norm_squared()) / 2.0 / predicted.max(f64::MIN_POSITIVE);
        if damping.update(rho) {
            x = xn;
            r = rn;
            j = data.jacobian(form, &x);
            a = j.transpose() * &j;
            g = j.transpose() * &r;
            if g.amax() < 1e-14 {
                break;
            }
        }
    }
    let singular_values = crate::numeric::svd(j.clone(), false, false).map(|s| s.singular_values.as_slice().to_vec()).unwrap_or_default();
    Solution { rms_mm: (r.norm_squared() / r.len().max(1) as f64).sqrt(), x, iterations, singular_values }
}

/// Options of the particle swarm (paper section 4.1).
#[derive(Clone, Debug)]
pub struct PsoOptions {
    /// Particles (5000 in the paper).
    pub population: usize,
    /// Iterations.
    pub iterations: usize,
    /// Cognitive factor (2 in the paper).
    pub c1: f64,
    /// Social factor (2 in the paper).
    pub c2: f64,
    /// Inertia at the first iteration (0.9 in the paper; eq. 16).
    pub w_max: f64,
    /// Inertia at the last iteration (0.4 in the paper).
    pub w_min: f64,
}

impl Default for PsoOptions {
    fn default() -> Self {
        Self { population: 5000, iterations: 100, c1: 2.0, c2: 2.0, w_max: 0.9, w_min: 0.4 }
    }
}

/// Particle swarm over the box `centre +- half_width` (eq. 15), inertia `w_n = w_max - (w_max -
/// w_min) n^2 / g^2` (eq. 16); velocities clamped to the box width.
pub fn pso<R: Rng + ?Sized>(
    data: &BeamData,
    form: Form,
    centre: &DVector<f64>,
    half_width: &DVector<f64>,
    opts: &PsoOptions,
    rng: &mut R,
) -> Solution {
    let d = centre.len();
    let mut xs: Vec<DVector<f64>> =
        (0..opts.population).map(|_| DVector::from_fn(d, |i, _| centre[i] + half_width[i] * rng.random_range(-1.0..=1.0))).collect();
    let mut vs: Vec<DVector<f64>> = (0..opts.population).map(|_| DVector::zeros(d)).collect();
    let mut pbest = xs.clone();
    let mut pcost: Vec<f64> = xs.iter().map(|x| data.cost(form, x)).collect();
    let first = pcost.iter().enumerate().min_by(|a, b| a.1.total_cmp(b.1)).map_or(0, |(i, _)| i);
    let mut gbest = pbest[first].clone();
    let mut gcost = pcost[first];
    let g2 = (opts.iterations.max(1) as f64).powi(2);
    for n in 0..opts.iterations {
        let w = opts.w_max - (opts.w_max - opts.w_min) * (n as f64).powi(2) / g2;
        for p in 0..opts.population {
            for i in 0..d {
                let (r1, r2): (f64, f64) = (rng.random(), rng.random());
                let v = w * vs[p][i] + opts.c1 * r1 * (pbest[p][i] - xs[p][i]) + opts.c2 * r2 * (gbest[i] - xs[p][i]);
                vs[p][i] = v.clamp(-2.0 * half_width[i], 2.0 * half_width[i]);
                xs[p][i] += vs[p][i];
            }
            let c = data.cost(form, &xs[p]);
            if c < pcost[p] {
                pcost[p] = c;
                pbest[p] = xs[p].clone();
                if c < gcost {
                    gcost = c;
                    gbest = xs[p].clone();
                }
            }
        }
    }
    let n = data.frames.len() * data.readings.first().map(|r| r.len()).unwrap_or(0);
    Solution { x: gbest, iterations: opts.iterations, rms_mm: (gcost / n.max(1) as f64).sqrt(), singular_values: Vec::new() }
}
