//! The tracker scenario file (`kind = "tracker"`): the TriCal cell's sections (`[robot]`,
//! `[cell]`, `[trical]`, `[tracker]`, `[campaign]`, `[study]`: the same world, built the same way,
//! so a tracker study and a TriCal study of one seed see the same robot, cell and validation poses)
//! plus `[instrument]` (which instrument measures the identification pool, and how many
//! configurations), an optional `[optical_cmm]`, and its own `[expect]` (Table 8's row of the
//! instrument).

use std::path::Path;

use serde::Deserialize;

use crate::device::scenario::{Checker, ScenarioError, deserialize};
use crate::device::trical::TricalScenario;
use crate::device::trical::table8::External;
use crate::instrument::optical_cmm::OpticalCmmSpec;
use crate::study::check::Band;

/// Which instrument measures the identification pool.
#[derive(Clone, Copy, Debug, Default, Deserialize, serde::Serialize, PartialEq)]
#[serde(rename_all = "snake_case")]
pub enum InstrumentKind {
    /// The cell's laser tracker (Table 8, laser tracker row).
    #[default]
    LaserTracker,
    /// An optical CMM where the tracker stands (Table 8, optical CMM row).
    OpticalCmm,
}

/// The `[instrument]` table.
#[derive(Clone, Debug, Deserialize, serde::Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct InstrumentSpec {
    /// The instrument.
    pub kind: InstrumentKind,
    /// Configurations of the identification pool, random in the whole workspace and in the
    /// instrument's view (Table 8's calibrations; ASSUMED 360, the TriCal pool's size).
    pub pool: u32,
}

impl Default for InstrumentSpec {
    fn default() -> Self {
        Self { kind: InstrumentKind::LaserTracker, pool: 360 }
    }
}

/// The `[expect]` table: Table 8's row of the instrument, each figure the median over the
/// repetitions at the table set size of the validation error's statistic, mm.
#[derive(Clone, Debug, Default, Deserialize, serde::Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct TrackerExpect {
    /// Median error after calibration.
    pub after_median_mm: Option<Band>,
    /// Standard deviation of the error after calibration.
    pub after_std_mm: Option<Band>,
    /// Largest error after calibration.
    pub after_max_mm: Option<Band>,
}

/// The sections of a tracker scenario that the TriCal cell does not have.
#[derive(Clone, Debug, Default, Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
struct Own {
    #[serde(default)]
    instrument: InstrumentSpec,
    #[serde(default)]
    optical_cmm: OpticalCmmSpec,
    #[serde(default)]
    expect: TrackerExpect,
}

/// The notes of the tracker's own keys (SOURCED / ASSUMED / FITTED), for `calsim keys`; the
/// cell's keys are the TriCal scenario's.
pub const NOTES: &str = include_str!("keys.toml");

/// A tracker scenario with every key at its default, as TOML: the TriCal cell's keys (the
/// tracker's `[expect]` in place of the TriCal's) and its own sections.
pub fn defaults() -> toml::Table {
    let mut t = crate::device::trical::spec::defaults();
    let own = toml::Table::try_from(Own::default()).expect("the tracker's sections serialize");
    t.extend(own);
    t.insert("kind".into(), toml::Value::String("tracker".into()));
    t
}

/// A loaded, checked tracker scenario.
#[derive(Clone, Debug)]
pub struct TrackerScenario {
    /// The cell, robot and study as a TriCal scenario of the same file (its `[expect]` empty).
    pub cell: TricalScenario,
    /// The pool's instrument.
    pub instrument: InstrumentSpec,
    /// The optical CMM's specification (used when the instrument is the CMM).
    pub optical_cmm: OpticalCmmSpec,
    /// Table 8's bands.
    pub expect: TrackerExpect,
}

impl TrackerScenario {
    /// The instrument as the TriCal cell measures with it.
    pub fn external(&self) -> External {
        match self.instrument.kind {
            InstrumentKind::LaserTracker => External::LaserTracker,
            InstrumentKind::OpticalCmm => External::OpticalCmm(self.optical_cmm.clone()),
        }
    }
}

/// Loads and checks a tracker scenario from its TOML table.
pub fn parse_table(text: &str, mut t: toml::Table, path: &Path) -> Result<TrackerScenario, ScenarioError> {
    let shown = path.display().to_string();
    let mut own = toml::Table::new();
    for key in ["instrument", "optical_cmm", "expect"] {
        if let Some(v) = t.remove(key) {
            own.insert(key.into(), v);
        }
    }
    t.remove("kind");
    let own: Own = deserialize(own, &shown)?;
    let cell = crate::device::trical::spec::parse_table(text, t, path)?;
    let s = TrackerScenario { cell, instrument: own.instrument, optical_cmm: own.optical_cmm, expect: own.expect };
    check(&s, &shown)?;
    Ok(s)
}

/// Checks the tracker's own sections and the set sizes against its pool; `path` names the file.
pub fn check(s: &TrackerScenario, path: &str) -> Result<(), ScenarioError> {
    let c = Checker { path };
    c.count("instrument", "pool", s.instrument.pool.into(), 50, 100_000, "configurations of the identification pool")?;
    let too_big = s.cell.study.set_sizes.iter().find(|&&n| n >= s.instrument.pool);
    let why = format!("each size must stay below the instrument's pool of {}", s.instrument.pool);
    c.require("study", "set_sizes", too_big.is_none(), too_big.copied().unwrap_or_default(), &why)?;
    let o = &s.optical_cmm;
    c.within("optical_cmm", "volumetric_accuracy_mm", o.volumetric_accuracy_mm, 0.0, 10.0, "2 sigma of the 3D error")?;
    c.within("optical_cmm", "calibrated_range_mm", o.calibrated_range_mm, 1.0, 1e5, "range of the calibrated volume")?;
    c.within("optical_cmm", "accuracy_growth_mm_per_m", o.accuracy_growth_mm_per_m, 0.0, 10.0, "growth beyond it")?;
    c.within("optical_cmm", "max_range_mm", o.max_range_mm, o.calibrated_range_mm, 1e5, "farthest target seen")?;
    for (k, b) in
        [("after_median_mm", &s.expect.after_median_mm), ("after_std_mm", &s.expect.after_std_mm), ("after_max_mm", &s.expect.after_max_mm)]
    {
        c.band(k, b)?;
    }
    Ok(())
}
