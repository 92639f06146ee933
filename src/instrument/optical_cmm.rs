//! The optical CMM of the TriCal paper's Table 8: a Creaform C-Track dual-camera tracker measuring a
//! half-sphere retroreflective target on the flange (section 3.2, ref. 9).
//!
//! Noise model: an isotropic Gaussian error per axis whose 3D size at two standard deviations is
//! the data sheet's volumetric accuracy, growing linearly with the distance from the tracker beyond
//! the calibrated volume. ASSUMED: the paper gives no accuracy for it; the defaults are those of
//! the C-Track 780 data sheet as the project recalls it (volumetric accuracy 0.065 mm in its
//! 7.8 m^3 volume, 0.085 mm in 16.6 m^3), not checked against a copy here. A target outside the
//! field of view (beyond `max_range_mm`) gives no measurement.

use nalgebra::Vector3;
use rand::Rng;
use rand_distr::{Distribution, Normal};
use serde::Deserialize;

/// The optical CMM as a scenario describes it.
#[derive(Clone, Debug, Deserialize, serde::Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct OpticalCmmSpec {
    /// Volumetric accuracy (2 sigma of the 3D error) inside the calibrated volume, mm. ASSUMED.
    pub volumetric_accuracy_mm: f64,
    /// Distance from the tracker up to which `volumetric_accuracy_mm` holds, mm. ASSUMED.
    pub calibrated_range_mm: f64,
    /// Growth of the volumetric accuracy per metre beyond the calibrated range, mm/m. ASSUMED
    /// (0.065 mm at 2.5 m to 0.085 mm at about 4 m on the data sheet).
    pub accuracy_growth_mm_per_m: f64,
    /// Farthest target the cameras see, mm. ASSUMED.
    pub max_range_mm: f64,
}

impl Default for OpticalCmmSpec {
    fn default() -> Self {
        Self { volumetric_accuracy_mm: 0.065, calibrated_range_mm: 2500.0, accuracy_growth_mm_per_m: 0.013, max_range_mm: 4000.0 }
    }
}

/// An optical CMM at a place in {W}.
#[derive(Clone, Debug)]
pub struct OpticalCmm {
    /// Its specification.
    pub spec: OpticalCmmSpec,
    /// Where its cameras stand in {W}, mm.
    pub position_w: Vector3<f64>,
}

impl OpticalCmm {
    /// A C-Track at `position_w`.
    pub fn new(spec: &OpticalCmmSpec, position_w: Vector3<f64>) -> Self {
        Self { spec: spec.clone(), position_w }
    }

    /// Standard deviation per axis of a measurement at `p_w`, mm. The volumetric accuracy at that
    /// distance is taken as twice the RMS of the 3D error, and an isotropic Gaussian of per-axis
    /// sigma `s` has a 3D RMS of `s sqrt 3`, so `s = accuracy / (2 sqrt 3)`.
    pub fn sigma_mm(&self, p_w: &Vector3<f64>) -> f64 {
        let d = (p_w - self.position_w).norm();
        let beyond_m = ((d - self.spec.calibrated_range_mm) * 1e-3).max(0.0);
        (self.spec.volumetric_accuracy_mm + self.spec.accuracy_growth_mm_per_m * beyond_m) / (2.0 * 3f64.sqrt())
    }

    /// The target at `p_w` as the CMM measures it, or `None` out of its field of view.
    pub fn measure<R: Rng + ?Sized>(&self, p_w: &Vector3<f64>, rng: &mut R) -> Option<Vector3<f64>> {
        if (p_w - self.position_w).norm() > self.spec.max_range_mm {
            return None;
        }
        let n = Normal::new(0.0, self.sigma_mm(p_w)).ok()?;
        Some(p_w + Vector3::from_fn(|_, _| n.sample(rng)))
    }
}
