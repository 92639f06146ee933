//! The tracker device: the laser tracker (or the optical CMM) as the calibration instrument of a
//! full dispersion study on the TriCal cell's world. It is Table 8's external-instrument
//! calibration generalised to every set size, it shares the TriCal study's worlds, and it runs
//! through the commands written once for every device (run, sweep, budget).

mod common;

use calsim::device::tracker::TrackerOutcome;
use calsim::device::tracker::spec::{TrackerScenario, parse_table};
use calsim::device::trical::TricalOutcome;
use common::{repo, scratch};

/// The shipped tracker scenario with `edit` applied to its table.
fn tracker(edit: impl Fn(&mut toml::Table)) -> TrackerScenario {
    let (text, mut t) = calsim::device::scenario::read_table(&repo().join("scenarios/irb120_tracker.toml")).unwrap();
    edit(&mut t);
    parse_table(&text, t, &repo().join("scenarios/irb120_tracker.toml")).unwrap()
}

fn set(t: &mut toml::Table, key: &str, v: toml::Value) {
    calsim::design::sweep::spec::set_dotted(t, key, v).unwrap();
}

fn small(t: &mut toml::Table) {
    set(t, "study.set_sizes", toml::Value::Array(vec![toml::Value::Integer(75)]));
    set(t, "study.repetitions", toml::Value::Integer(4));
    set(t, "study.compensated_validation", toml::Value::Boolean(false));
}

/// At the table set size, the tracker device gives Table 8's laser-tracker and optical-CMM rows of
/// the TriCal scenario to the bit (same world, same pool, same sets, same fits): 4 repetitions of
/// sets of 75 from a pool of 360.
#[test]
fn at_the_table_size_the_tracker_device_is_table8s_external_rows_bit_for_bit() {
    let trical = calsim::device::trical::spec::load(&repo().join("scenarios/irb120_trical.toml")).unwrap();
    let mut study = trical.study.clone();
    study.repetitions = 4;
    let seed = trical.header.seed;
    let e = trical.experiment.build(seed).unwrap();
    let before = trical.experiment.before_model(&e.campaign);
    let rows = calsim::device::trical::table8::external_instruments(&trical.experiment, &e, &before, &study, seed, 360).unwrap();
    for (k, kind) in ["laser_tracker", "optical_cmm"].iter().enumerate() {
        let s = tracker(|t| {
            small(t);
            set(t, "instrument.kind", toml::Value::String(kind.to_string()));
        });
        // The same world (the robot file named by another path to the same file).
        let (mut a, mut b) = (s.cell.experiment.clone(), trical.experiment.clone());
        (a.robot.file, b.robot.file) = (None, None);
        assert_eq!(a, b, "the tracker scenario's world is the TriCal scenario's");
        let o = TrackerOutcome::run(&s, seed, &|_, _| {}).unwrap();
        let f = o.figures();
        assert_eq!([f.after_median, f.after_std, f.after_max], rows[k], "{kind}");
    }
}

/// A tracker study and a TriCal study of one seed calibrate the same robot and are validated on the
/// same poses: the errors before calibration are the same numbers, and with another seed they are
/// not (common random numbers across devices).
#[test]
fn tracker_and_trical_studies_of_one_seed_share_the_robot_and_the_validation_poses() {
    let s = tracker(small);
    let mut trical = calsim::device::trical::spec::load(&repo().join("scenarios/ci_quick.toml")).unwrap();
    trical.experiment = s.cell.experiment.clone();
    trical.study.set_sizes = vec![30];
    trical.study.table_set_size = 30;
    trical.study.repetitions = 1;
    let seed = s.cell.header.seed;
    let a = TrackerOutcome::run(&s, seed, &|_, _| {}).unwrap();
    let b = TricalOutcome::run(&trical, seed, &|_, _| {}).unwrap();
    assert_eq!(a.results().before_errors, b.results().before_errors);
    let c = TrackerOutcome::run(&s, seed + 1, &|_, _| {}).unwrap();
    assert_ne!(a.results().before_errors, c.results().before_errors);
    // The tracker calibrates the workspace it measures: far below the error before calibration.
    assert!(a.figures().after_median < 0.1 * a.figures().before.median, "{} vs {}", a.figures().after_median, a.figures().before.median);
}

/// The commands written once over the devices take the tracker: a sweep over the instrument
/// (realisations as work units, the same worlds for both instruments), and the budget's sources.
#[test]
fn a_sweep_over_the_instrument_and_the_budget_sources_take_the_tracker_device() {
    let tmp = scratch("tracker-sweep");
    let dir = tmp.path();
    let base = repo().join("scenarios/irb120_tracker.toml");
    let file = dir.join("instruments.toml");
    std::fs::write(
        &file,
        format!(
            "base = {:?}\nrealisations = 2\nthresholds_mm = [0.1]\n\n[fixed]\n\"study.set_sizes\" = [30]\n\"study.table_set_size\" = 30\n\
             \"study.repetitions\" = 2\n\n[[axis]]\nkey = \"instrument.kind\"\nvalues = [\"laser_tracker\", \"optical_cmm\"]\n",
            base.display().to_string()
        ),
    )
    .unwrap();
    let spec = calsim::app::sweep::SweepSpec { file, out: dir.to_path_buf(), shard: None, threads: Some(2), realisations: None };
    let merged = calsim::app::sweep::run(&spec, &calsim::app::Quiet).unwrap().merged.unwrap();
    assert_eq!((merged.units, merged.failed), (4, 0));
    assert!(merged.summary.contains("optical_cmm") && merged.summary.contains("laser_tracker"), "{}", merged.summary);

    let (_, t) = calsim::device::scenario::read_table(&base).unwrap();
    let device = calsim::device::device_of(&t, &base).unwrap();
    assert_eq!(device.kind(), "tracker");
    let labels: Vec<&str> = calsim::design::budget::sources(device, &t).iter().map(|s| s.label).collect();
    assert!(labels.contains(&"laser tracker") && labels.contains(&"robot repeatability"), "{labels:?}");
    assert!(labels.contains(&"transmission errors, high orders"), "the robot's unmodelled effects are every device's: {labels:?}");
}

/// Bad tracker sections are one line naming the file, the section and the key.
#[test]
fn bad_tracker_sections_name_the_file_and_the_key() {
    let base = repo().join("scenarios/irb120_tracker.toml");
    let (text, t) = calsim::device::scenario::read_table(&base).unwrap();
    let cases: [(&str, toml::Value, &str); 4] = [
        ("instrument.pool", toml::Value::Integer(10), "[instrument] pool = 10"),
        ("instrument.kind", toml::Value::String("theodolite".into()), "instrument.kind"),
        ("optical_cmm.volumetric_accuracy_mm", toml::Value::Float(-1.0), "[optical_cmm] volumetric_accuracy_mm = -1"),
        ("expect.after_median_mm.value", toml::Value::Float(1e9), "after_median_mm.value"),
    ];
    for (key, value, expected) in cases {
        let mut t = t.clone();
        set(&mut t, key, value);
        let msg = calsim::device::from_table(&text, t, &base).unwrap_err().to_string();
        assert!(msg.starts_with(&base.display().to_string()) && msg.contains(expected) && !msg.contains('\n'), "{key}: {msg}");
    }
}
