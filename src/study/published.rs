//! The published figures every check compares with, read from the repository's copy of
//! `reference/published-figures.toml` (compiled in, so that the binary stands alone; a test compares
//! the copy with the project's upstream one when that is beside the clone).

use std::collections::BTreeMap;
use std::sync::LazyLock;

use serde::Deserialize;

/// The reference file as compiled in.
pub const TEXT: &str = include_str!("../../reference/published-figures.toml");

/// The figures of both papers that calsim checks.
#[derive(Clone, Debug, Deserialize)]
pub struct Published {
    /// The TriCal paper (2018).
    pub trical_2018: Trical,
    /// The SPMS paper (2023).
    pub spms_2023: Spms,
}

/// Mean and max, mm.
#[derive(Clone, Copy, Debug, Deserialize)]
pub struct MeanMax {
    /// Mean, mm.
    pub mean_mm: f64,
    /// Max, mm.
    pub max_mm: f64,
}

/// One row of the TriCal paper's Table 8.
#[derive(Clone, Debug, Deserialize)]
pub struct Table8Row {
    /// Instrument.
    pub instrument: String,
    /// Median error after calibration, mm.
    pub median_mm: f64,
    /// Standard deviation, mm.
    pub std_mm: f64,
    /// Max, mm.
    pub max_mm: f64,
}

/// The TriCal paper's figures.
#[derive(Clone, Debug, Deserialize)]
pub struct Trical {
    /// Errors before calibration over the 506 validation poses.
    pub before_calibration: MeanMax,
    /// Table 8, one row per instrument.
    pub table8: Vec<Table8Row>,
    /// Table 7 by key (`alpha1_deg`, ...): mean, std, min, max as printed.
    pub table7: BTreeMap<String, [f64; 4]>,
}

impl Trical {
    /// The Table 8 row of `instrument` (`TriCal`, `laser tracker`, `optical CMM`).
    pub fn table8(&self, instrument: &str) -> &Table8Row {
        self.table8
            .iter()
            .find(|r| r.instrument == instrument)
            .unwrap_or_else(|| panic!("published-figures.toml: no Table 8 row {instrument:?}"))
    }

    /// Table 7 (mean, std) of the parameter `name` (calsim's name: `alpha1`, `theta_offs2`, `x0W`),
    /// in the unit the paper prints; `None` when the paper does not list it.
    pub fn table7(&self, name: &str) -> Option<(f64, f64)> {
        ["_deg_per_knm", "_deg", "_mm"].iter().find_map(|unit| self.table7.get(&format!("{name}{unit}"))).map(|v| (v[0], v[1]))
    }
}

/// The SPMS paper's measuring error (Table 3).
#[derive(Clone, Copy, Debug, Deserialize)]
pub struct MeasuringError {
    /// Max, mm.
    pub max_mm: f64,
    /// Mean, mm.
    pub mean_mm: f64,
    /// RMS, mm.
    pub rms_mm: f64,
}

/// The SPMS paper's Table 6.
#[derive(Clone, Debug, Deserialize)]
pub struct Iso9283 {
    /// AP per point before calibration, mm.
    pub ap_before_mm: [f64; 5],
    /// AP per point after calibration, mm.
    pub ap_after_mm: [f64; 5],
    /// Max before, mm.
    pub max_before_mm: f64,
    /// Mean before, mm.
    pub mean_before_mm: f64,
    /// "RMS" before as printed, mm.
    pub rms_before_mm: f64,
    /// Max after, mm.
    pub max_after_mm: f64,
    /// Mean after, mm.
    pub mean_after_mm: f64,
    /// "RMS" after as printed, mm.
    pub rms_after_mm: f64,
}

/// The SPMS paper's figures.
#[derive(Clone, Debug, Deserialize)]
pub struct Spms {
    /// Table 3.
    pub measuring_error: MeasuringError,
    /// Table 6.
    pub iso9283: Iso9283,
}

static PUBLISHED: LazyLock<Published> =
    LazyLock::new(|| crate::io::toml_de::from_str(TEXT).unwrap_or_else(|e| panic!("reference/published-figures.toml: {e}")));

/// The published figures.
pub fn published() -> &'static Published {
    &PUBLISHED
}
