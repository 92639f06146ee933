//! The ER20-C10 calibration with the SPMS: the built-in robot against Tables 4 and 5, a noise-free
//! round trip through the calibration, determinism across thread counts, and the scenario on the
//! command line (the check CI runs, bad input).

mod common;

use calsim::device::spms::calibration::{ArmSpec, IsoSpec, StationSpec, build, default_parameters, identify_from, iso_test};
use calsim::device::spms::head::{self, BeamIdSpec, HeadSpec};
use calsim::device::spms::study::{self, SpmsSpec};
use calsim::identify::least_squares::{FitOptions, FitOutcome};
use calsim::robot::builtin::{ER20C10_TABLE5, ER20C10_ZERO_RAD, er20c10_table4, er20c10_table5};
use calsim::robot::{ParamId, UnmodelledSpec};
use calsim::study::engine::random_selection;

use common::{calsim, repo, scratch};

/// A small beam experiment: enough to identify the head, quick in the test build.
fn quick_beams() -> BeamIdSpec {
    BeamIdSpec { pso_population: 300, pso_iterations: 20, ..BeamIdSpec::default() }
}

#[test]
fn the_built_in_er20c10_carries_tables_4_and_5() {
    let t4 = er20c10_table4();
    let t5 = er20c10_table5(true);
    let links4 = t4.links();
    let links5 = t5.links();
    // Table 4 as printed, row 1 to 5.
    let a4 = [0.0, 166.605, -782.270, 138.826, 0.0];
    let d4 = [504.0, 0.0, 0.0, 761.350, 0.0];
    for i in 0..5 {
        assert_eq!(links4[i].a, a4[i], "a{}", i);
        assert_eq!(links4[i].d, d4[i], "d{}", i + 1);
        assert_eq!(links4[i].theta_offset, ER20C10_ZERO_RAD[i]);
        let (a, d, dt) = ER20C10_TABLE5[i];
        assert_eq!(links5[i].a, a);
        assert_eq!(links5[i].d, d);
        assert!((links5[i].theta_offset - ER20C10_ZERO_RAD[i] - dt).abs() < 1e-15, "delta theta {}", i + 1);
    }
    // Without delta theta_2 only that entry differs.
    let t5b = er20c10_table5(false);
    assert_eq!(t5b.links()[1].theta_offset, ER20C10_ZERO_RAD[1]);
    assert_eq!(t5b.links()[2], links5[2]);
    // q = 0 is the home pose: upper arm vertical, wrist centre at shoulder height + a2, in front.
    let mut st = calsim::robot::KinState::default();
    calsim::robot::forward(&t4, &mut st, &[0.0; 6]);
    let wrist = st.base_from_frame(4).translation.vector;
    assert!((wrist.x - (166.605 + 761.350)).abs() < 1e-9 && (wrist.z - (504.0 + 782.270 + 138.826)).abs() < 1e-9, "{wrist:?}");
}

/// With exact measurements, no joint noise and no unmodelled effects, identification from the
/// SPMS stations recovers the true ER20-C10 (Table 5), the head placement and the sphere offset,
/// and the ISO 9283 test of the identified model finds no error.
#[test]
fn a_noise_free_round_trip_recovers_the_true_robot() {
    let h = head::run(&HeadSpec::default(), &quick_beams(), 5).unwrap();
    let arm = ArmSpec { repeatability_mm: 0.0, unmodelled: UnmodelledSpec::default(), ..ArmSpec::default() };
    let station = StationSpec {
        sphere_points_base_mm: vec![[1200.0, -400.0, 500.0], [1200.0, 400.0, 500.0], [900.0, 0.0, 1100.0]],
        tracker_sigma_um: 0.0,
        pool: 120,
        ..StationSpec::default()
    };
    let mut cell = build(&arm, &station, &h.spms, &h.paper, 5).unwrap();
    for p in &mut cell.pool {
        p.measured_world_mm = p.true_world_mm;
    }
    let set = default_parameters();
    let chosen = random_selection(cell.pool.len(), 60, &mut calsim::seeds::stream(5, 1));
    let fit = identify_from(&cell, &set, &chosen, &FitOptions::default());
    assert!(matches!(fit.outcome, FitOutcome::Converged { .. }), "{:?}", fit.outcome);
    let model = fit.model.unwrap();
    let truth = set.pack(&cell.robot.truth);
    let got = set.pack(&model);
    for (j, id) in set.ids().iter().enumerate() {
        let tol = match id.unit() {
            calsim::robot::Unit::Mm => 1e-6,
            _ => 1e-9,
        };
        assert!((got[j] - truth[j]).abs() < tol, "{}: {} vs truth {}", id.name(), got[j], truth[j]);
    }
    // The identified values moved off the nominal: the test is not trivially at the start.
    let nominal = set.pack(&cell.nominal);
    let a2 = set.position(ParamId::parse("a2").unwrap()).unwrap();
    assert!((got[a2] - nominal[a2]).abs() > 1.0, "a2 moved by {}", got[a2] - nominal[a2]);
    let iso = IsoSpec { tracker_sigma_um: 0.0, ..IsoSpec::default() };
    let before = iso_test(&cell, &cell.nominal, &iso, 5).unwrap();
    let after = iso_test(&cell, &model, &iso, 5).unwrap();
    assert!(before.ap_summary().1 > 0.3, "before {:?}", before.ap_mm);
    assert!(after.ap_mm.iter().all(|a| *a < 1e-6), "after {:?}", after.ap_mm);
    assert!(after.rp_mm.iter().all(|r| *r < 1e-9), "no joint noise: RP {:?}", after.rp_mm);
}

fn small_spec() -> SpmsSpec {
    let mut s = calsim::device::spms::spec::load(&repo().join("scenarios/er20c10_spms.toml")).unwrap().spec;
    s.beams = quick_beams();
    s.station.pool = 90;
    s.study.set_sizes = vec![20, 30];
    s.study.repetitions = 3;
    s.study.table_set_size = 30;
    s
}

#[test]
fn spms_results_are_identical_for_one_and_two_threads() {
    let spec = small_spec();
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap().install(|| study::run(&spec, 7, &|_, _| {}).unwrap())
    };
    let one = run(1);
    let two = run(2);
    assert_eq!(one.tasks.len(), 12);
    assert_eq!(one.before, two.before);
    assert_eq!(one.head.paper.measuring_error_mm, two.head.paper.measuring_error_mm);
    for (a, b) in one.tasks.iter().zip(&two.tasks) {
        // Bit for bit (the tasks carry no wall time).
        assert_eq!(a, b, "task {}", a.task.index);
    }
    assert!(one.tasks.iter().all(|t| t.id.outcome.is_converged() && t.iso.as_ref().is_some_and(|i| i.ap_summary().1 > 0.0)));
}

/// The check CI runs: the default SPMS scenario meets the bands of its [expect] table and writes
/// every result file.
#[test]
fn ci_check_of_the_spms_scenario_passes_and_writes_every_result() {
    let tmp = scratch("spms-check");
    let dir = tmp.path();
    let out = calsim().args(["check", "scenarios/er20c10_spms.toml", "--out"]).arg(dir).output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    assert!(stdout.contains("8 of 8 figures within their bands"), "{stdout}");
    let d = dir.join("er20c10_spms");
    for f in [
        "beams.parquet",
        "measurements.parquet",
        "tasks.parquet",
        "parameters.parquet",
        "iso9283_before.parquet",
        "manifest.json",
        "summary.md",
        "study.rrd",
    ] {
        let len = std::fs::metadata(d.join(f)).map(|m| m.len()).unwrap_or(0);
        assert!(len > 0, "{f} missing or empty");
    }
    let summary = std::fs::read_to_string(d.join("summary.md")).unwrap();
    for stem in ["spms_fig05_fit_residuals", "spms_fig06_measuring_error", "spms_table6_ap_per_point", "spms_ap_by_set_size"] {
        let png = std::fs::read(d.join(format!("{stem}.png"))).unwrap_or_default();
        assert!(png.starts_with(b"\x89PNG\r\n\x1a\n") && png.len() > 10_000, "{stem}.png missing or blank");
        assert!(summary.contains(&format!("]({stem}.png)")), "{stem} not in the summary");
    }
    assert!(summary.contains("| P5 |") && summary.contains("Random sets and DETMAX sets"), "{summary}");
}

#[test]
fn a_bad_spms_scenario_is_a_clear_error() {
    let tmp = scratch("spms-bad");
    let dir = tmp.path();
    let text = common::scenario_text_anywhere("er20c10_spms.toml");
    for (name, edited, expect) in [
        ("unknown_key.toml", text.replace("cycles = 30", "cycles = 30\ncycle_count = 3"), "iso9283.cycle_count"),
        ("range.toml", text.replace("cube_mm = 400.0", "cube_mm = -400.0"), "[iso9283] cube_mm = -400"),
        ("truth.toml", text.replace("truth = \"table5_without_dtheta2\"", "truth = \"table9\""), "robot.truth: unknown variant `table9`"),
        ("kind.toml", text.replace("kind = \"spms\"", "kind = \"laser\""), "kind"),
    ] {
        let p = dir.join(name);
        std::fs::write(&p, edited).unwrap();
        let out = calsim().arg("run").arg(&p).arg("--out").arg(dir).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{name}: {err}");
        assert!(err.contains(name) && err.contains(expect), "{name}: {err}");
        assert!(!err.contains("panicked") && !err.contains("backtrace"), "{err}");
    }
}

#[test]
fn the_one_station_what_if_differs_from_the_default_only_in_its_station() {
    let read = |name: &str| -> toml::Table { std::fs::read_to_string(repo().join("scenarios").join(name)).unwrap().parse().unwrap() };
    let mut full = read("er20c10_spms.toml");
    let mut one = read("er20c10_spms_one_station.toml");
    assert_ne!(full.get("station"), one.get("station"));
    for t in [&mut full, &mut one] {
        t.remove("station");
        t.remove("expect");
    }
    assert_eq!(full, one);
}
