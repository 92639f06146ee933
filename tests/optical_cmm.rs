//! The optical CMM's noise: its 3D RMS is half the volumetric accuracy, growing beyond the calibrated
//! range, and nothing is measured out of the field of view.

mod common;

use calsim::instrument::optical_cmm::{OpticalCmm, OpticalCmmSpec};
use nalgebra::Vector3;

/// RMS of the 3D error over `n` measurements at `p`.
fn rms_3d(cmm: &OpticalCmm, p: &Vector3<f64>, n: usize) -> f64 {
    let mut rng = common::rng(11);
    let sum: f64 = (0..n).map(|_| (cmm.measure(p, &mut rng).expect("in view") - p).norm_squared()).sum();
    (sum / n as f64).sqrt()
}

#[test]
fn rms_error_is_half_the_volumetric_accuracy() {
    let spec = OpticalCmmSpec::default();
    let cmm = OpticalCmm::new(&spec, Vector3::zeros());
    // n = 20,000 points, 60,000 normal draws: the relative standard error of the mean square is
    // sqrt(2 / 60,000) = 0.58 %, of the RMS half that; 2 % is more than 6 standard errors.
    let n = 20_000;
    let inside = rms_3d(&cmm, &Vector3::new(1500.0, 0.0, 0.0), n);
    assert!((inside / (spec.volumetric_accuracy_mm / 2.0) - 1.0).abs() < 0.02, "inside the calibrated range: RMS {inside}");
    let far = Vector3::new(3500.0, 0.0, 0.0);
    let expected = (spec.volumetric_accuracy_mm + spec.accuracy_growth_mm_per_m * 1.0) / 2.0;
    let beyond = rms_3d(&cmm, &far, n);
    assert!((beyond / expected - 1.0).abs() < 0.02, "1 m beyond the calibrated range: RMS {beyond}, expected {expected}");
}

#[test]
fn no_measurement_out_of_view() {
    let cmm = OpticalCmm::new(&OpticalCmmSpec::default(), Vector3::zeros());
    assert!(cmm.measure(&Vector3::new(0.0, 4500.0, 0.0), &mut common::rng(1)).is_none());
}
