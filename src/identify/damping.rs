//! The one Levenberg-Marquardt damping rule of calsim, used by the robot identification and the
//! SPMS beam identification alike: Nielsen's update (Madsen, Nielsen and Tingleff 2004, the SPMS
//! paper's eqs. 17-23). The damping starts at `tau` times the largest diagonal entry of `J^T J`;
//! after a step with gain ratio `rho > 0` it shrinks by `max(1/3, 1 - (2 rho - 1)^3)`, after a
//! failed step it grows by `nu`, which doubles at each failure in a row.

/// The damping state of one Levenberg-Marquardt solve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Damping {
    /// The damping added to the diagonal of the normal equations.
    pub mu: f64,
    nu: f64,
}

impl Damping {
    /// Damping `tau * max_diagonal` (the largest diagonal entry of `J^T J`).
    pub fn start(tau: f64, max_diagonal: f64) -> Self {
        Self { mu: tau * max_diagonal, nu: 2.0 }
    }

    /// No damping (Gauss-Newton).
    pub fn none() -> Self {
        Self { mu: 0.0, nu: 2.0 }
    }

    /// Updates after a step of gain ratio `rho` (actual over predicted decrease); returns whether
    /// the step is accepted (`rho > 0`).
    pub fn update(&mut self, rho: f64) -> bool {
        if rho > 0.0 {
            self.mu *= f64::max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0).powi(3));
            self.nu = 2.0;
            true
        } else {
            self.reject();
            false
        }
    }

    /// Grows the damping after a step that could not be taken or lowered nothing.
    pub fn reject(&mut self) {
        self.mu *= self.nu;
        self.nu *= 2.0;
    }
}
