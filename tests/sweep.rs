//! Design sweeps: grid expansion, common random numbers, shard/merge identity, resume after a
//! kill, and bad sweep input.

mod common;

use std::path::{Path, PathBuf};

use calsim::design::sweep::spec::{Combine, circle_layout, grid};
use common::{calsim, repo, scratch};

#[test]
fn product_and_zip_grids() {
    let g = grid(&[2, 3], Combine::Product).unwrap();
    assert_eq!(g, vec![vec![0, 0], vec![0, 1], vec![0, 2], vec![1, 0], vec![1, 1], vec![1, 2]]);
    assert_eq!(grid(&[3, 3], Combine::Zip).unwrap(), vec![vec![0, 0], vec![1, 1], vec![2, 2]]);
    assert!(grid(&[2, 3], Combine::Zip).is_err());
    assert!(grid(&[100_000, 100_000], Combine::Product).is_err(), "a grid beyond the bound is refused, not allocated");
    assert_eq!(grid(&[], Combine::Product).unwrap(), vec![Vec::<usize>::new()], "no axis: the base scenario alone");
}

#[test]
fn circle_layouts_define_w_and_keep_their_spacing() {
    for n in 3..=6 {
        let p = circle_layout(n, 300.0);
        assert_eq!(p.len(), n);
        assert_eq!(p[0], [0.0, 0.0, 0.0]);
        assert!(p[1][0] > 0.0 && p[1][1] == 0.0 && p[1][2] == 0.0, "{:?}", p[1]);
        assert!(p[2][1] > 0.0, "sphere 3 on the +y side: {:?}", p[2]);
        for k in 0..n {
            let (a, b) = (p[k], p[(k + 1) % n]);
            let d = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt();
            assert!((d - 300.0).abs() < 1e-9, "n = {n}, neighbours {k}: {d}");
        }
    }
}

/// A sweep file over the reduced CI scenario (2 set sizes x 2 repetitions) in `dir`.
fn sweep_file(dir: &Path, name: &str, realisations: u32, axes: &str) -> PathBuf {
    let base = repo().join("scenarios/ci_quick.toml");
    let text = format!(
        "base = {base:?}\nrealisations = {realisations}\nthresholds_mm = [0.5, 1.0]\n\n[fixed]\n\"study.set_sizes\" = [20, 30]\n\"study.table_set_size\" = 30\n\"study.repetitions\" = 2\n\n{axes}\n",
        base = base.display().to_string()
    );
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

fn run(args: &[&str], out: &Path) -> std::process::Output {
    let o = calsim().args(args).arg("--out").arg(out).output().unwrap();
    assert!(o.status.success(), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
    o
}

fn tables(dir: &Path) -> Vec<Vec<u8>> {
    ["sweep.parquet", "points.parquet"].iter().map(|f| std::fs::read(dir.join(f)).unwrap()).collect()
}

const AXIS: &str = "[[axis]]\nkey = \"trical.epsilon_mm\"\nvalues = [0.010, 0.020]\n";

/// Runs the sweep `file` (one shard of it with `shard`) through the library, `threads` workers.
fn sweep_lib(file: &Path, out: &Path, shard: Option<(usize, usize)>, threads: u32) -> calsim::app::sweep::SweepReport {
    let spec = calsim::app::sweep::SweepSpec {
        file: file.to_path_buf(),
        out: out.to_path_buf(),
        shard,
        threads: Some(threads),
        realisations: None,
    };
    calsim::app::sweep::run(&spec, &calsim::app::Quiet).unwrap()
}

#[test]
fn sharded_and_threaded_runs_merge_to_the_same_bytes() {
    let tmp = scratch("sweep-shards");
    let dir = tmp.path();
    let f = sweep_file(dir, "s.toml", 3, AXIS);
    let one = dir.join("one");
    let merged = sweep_lib(&f, &one, None, 1).merged.expect("an unsharded sweep merges");
    assert_eq!((merged.units, merged.failed), (6, 0), "2 points x 3 realisations, none failed");
    let two = dir.join("two");
    sweep_lib(&f, &two, None, 2);
    let sharded = dir.join("sharded");
    let shards: Vec<PathBuf> = (0..3).map(|k| sweep_lib(&f, &sharded, Some((k, 3)), 2).shard_dir).collect();
    calsim::app::sweep::merge(&shards, &sharded).unwrap();
    let reference = tables(&one.join("s"));
    assert!(reference[0].len() > 1000, "a sweep.parquet with rows");
    assert_eq!(tables(&two.join("s")), reference, "1 vs 2 threads");
    assert_eq!(tables(&sharded.join("s")), reference, "1 vs 3 shards");
    let manifest = std::fs::read_to_string(one.join("s/manifest.json")).unwrap();
    assert!(manifest.contains("\"units\": 6") && manifest.contains("\"failed_units\": 0"), "{manifest}");
    assert!(!one.join("s.shard-0-of-1").exists(), "the unsharded run removes its shard directory");
}

/// The command line runs the same sweep: a shard, then `merge` of the shard directory.
#[test]
fn the_sweep_and_merge_commands_shard_and_merge() {
    let tmp = scratch("sweep-cli");
    let dir = tmp.path();
    let f = sweep_file(dir, "c.toml", 1, AXIS);
    let fs = f.to_str().unwrap();
    let o = run(&["sweep", fs, "--shard", "0/1"], dir);
    assert!(String::from_utf8_lossy(&o.stdout).contains("merge the shards with: calsim merge"), "{}", String::from_utf8_lossy(&o.stdout));
    let shard = dir.join("c.shard-0-of-1");
    let timing = |o: &std::process::Output| {
        String::from_utf8_lossy(&o.stdout).lines().find(|l| l.starts_with("timing: ")).expect("a timing line").to_string()
    };
    assert!(timing(&o).ends_with(&format!(" to {}", shard.display())), "a shard names its directory: {}", timing(&o));
    let o = run(&["merge", shard.to_str().unwrap()], dir);
    assert!(String::from_utf8_lossy(&o.stdout).contains("merged 2 work units (0 failed)"), "{}", String::from_utf8_lossy(&o.stdout));
    // A whole sweep merges and removes its shard directory: its timing line names no path.
    let whole = dir.join("whole");
    let o = run(&["sweep", fs], &whole);
    assert!(!whole.join("c.shard-0-of-1").exists(), "the whole sweep removes its shard directory");
    assert!(!timing(&o).contains(" to "), "the timing line names a removed directory: {}", timing(&o));
    assert!(
        String::from_utf8_lossy(&o.stdout).contains(&format!("into {}", whole.join("c").display())),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
    // The ranking says which way its comparison with the leader reads: this design minus the leader.
    let summary = std::fs::read_to_string(whole.join("c/summary.md")).unwrap();
    assert!(summary.contains("| this design - leader (paired on common worlds) |"), "{summary}");
    assert!(summary.contains("this design minus the leader in each common realisation"), "{summary}");
    assert!(summary.contains("above 0, the design did worse"), "{summary}");
    // The axis's column holds its values as numbers, as the sweep file writes them.
    use polars::prelude::SerReader;
    let points = polars::prelude::ParquetReader::new(std::fs::File::open(dir.join("c/points.parquet")).unwrap()).finish().unwrap();
    let axis = points.column("trical.epsilon_mm").expect("the axis's column");
    let mut values: Vec<f64> = axis.f64().expect("numbers").into_no_null_iter().collect();
    values.dedup();
    assert_eq!(values, [0.01, 0.02], "one row per point and selection, in point order");
    // The best design file runs from any working directory: here from a directory that holds
    // neither the sweep, its base scenario nor the robot file.
    let elsewhere = scratch("sweep-cli-elsewhere");
    let best = dir.join("c/best_design.toml");
    let o = calsim()
        .current_dir(elsewhere.path())
        .args(["run", best.to_str().unwrap(), "--set-sizes", "20:30:10", "--repetitions", "1", "--no-plots", "--no-recording", "--out"])
        .arg(elsewhere.path().join("out"))
        .output()
        .unwrap();
    assert!(o.status.success(), "best_design.toml from another directory: {}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn a_point_equal_to_the_base_is_the_plain_run_at_realisation_0_and_worlds_are_shared() {
    let tmp = scratch("sweep-crn");
    let dir = tmp.path();
    // Two points that differ in the repetitions only: the same worlds, so the same errors before
    // calibration in each realisation; realisation 0 of point 0 is the plain run.
    let f = sweep_file(dir, "crn.toml", 2, "[[axis]]\nkey = \"study.repetitions\"\nvalues = [2, 3]\n");
    let sweep = calsim::design::sweep::spec::load(&f).unwrap();
    let units: Vec<_> = (0..4).map(|u| calsim::design::sweep::run_unit(&sweep, u)).collect();
    assert_eq!(units[0].before_mm, units[2].before_mm, "realisation 0 of both points: one world");
    assert_eq!(units[1].before_mm, units[3].before_mm, "realisation 1 of both points: one world");
    assert_ne!(units[0].before_mm, units[1].before_mm, "two realisations: two worlds");

    // The base scenario loaded by itself, with the sweep's fixed keys and point 0's repetitions.
    let mut s = calsim::device::trical::spec::load(&repo().join("scenarios/ci_quick.toml")).unwrap();
    (s.study.set_sizes, s.study.table_set_size, s.study.repetitions) = (vec![20, 30], 30, 2);
    assert_eq!(s.header.seed, sweep.points[0].scenario.header().seed);
    let experiment = s.experiment.build(s.header.seed).unwrap();
    let before = s.experiment.before_model(&experiment.campaign);
    let plain = calsim::device::trical::study::run(&experiment, &before, &s.study, s.header.seed, &|_, _| {}).unwrap();
    let b = calsim::study::ErrorStats::of(&plain.before_errors);
    assert_eq!(units[0].before_mm, [b.median, b.p95, b.max]);
    let at30: Vec<_> = plain.tasks.iter().filter(|t| t.task.set_size == 30).collect();
    let med = calsim::study::stats::median(&at30.iter().map(|t| t.validation.median).collect::<Vec<_>>());
    let row = units[0].rows.iter().find(|r| r.set_size == 30).unwrap();
    assert_eq!(row.after_median_mm, med, "the sweep's unit is the plain run, bit for bit");
}

#[test]
fn a_killed_shard_resumes_and_merges_to_the_same_bytes() {
    let tmp = scratch("sweep-resume");
    let dir = tmp.path();
    let f = sweep_file(dir, "r.toml", 4, AXIS);
    let fs = f.to_str().unwrap();
    let whole = dir.join("whole");
    let t = std::time::Instant::now();
    run(&["sweep", fs], &whole);
    let full = t.elapsed();
    let part = dir.join("part");
    let mut child = calsim()
        .args(["sweep", fs, "--shard", "0/1", "--out"])
        .arg(&part)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    std::thread::sleep(full.mul_f64(0.6));
    let _ = child.kill();
    let _ = child.wait();
    let units = part.join("r.shard-0-of-1/units");
    let kept = std::fs::read_dir(&units)
        .map(|d| d.filter(|e| e.as_ref().unwrap().path().extension().is_some_and(|x| x == "json")).count())
        .unwrap_or(0);
    eprintln!("{kept} of 8 units kept after the kill");
    run(&["sweep", fs, "--shard", "0/1"], &part);
    run(&["merge", part.join("r.shard-0-of-1").to_str().unwrap()], &part);
    assert_eq!(tables(&part.join("r")), tables(&whole.join("r")));
}

/// A unit file cut short, edited to absurd numbers or holding another unit is refused by `merge` in
/// one line naming the file and the field; the untouched shard merges (1 point x 2 realisations).
#[test]
fn an_edited_or_misplaced_unit_file_is_refused_by_merge() {
    let tmp = scratch("sweep-units");
    let dir = tmp.path();
    let f = sweep_file(dir, "u.toml", 2, "[[axis]]\nkey = \"trical.epsilon_mm\"\nvalues = [0.010]\n");
    let out = dir.join("out");
    run(&["sweep", f.to_str().unwrap(), "--shard", "0/1"], &out);
    let shard = out.join("u.shard-0-of-1");
    let file = shard.join("units/u0000001.json");
    let good = std::fs::read_to_string(&file).unwrap();
    let unit: serde_json::Value = serde_json::from_str(&good).unwrap();
    let edited = |edit: &dyn Fn(&mut serde_json::Value)| {
        let mut u = unit.clone();
        edit(&mut u);
        u.to_string()
    };
    let merged = dir.join("merged");
    let m = |expect: &[&str]| bad(&["merge", shard.to_str().unwrap(), "--out", merged.to_str().unwrap()], expect);
    for (text, expect) in [
        (good[..good.len() / 2].to_string(), vec!["u0000001.json", "EOF"]),
        (edited(&|u| u["rows"][0]["after_median_mm"] = (-0.1).into()), vec!["u0000001.json", "rows[0].after_median_mm = -0.1"]),
        (edited(&|u| u["rows"][0]["after_p95_mm"] = 1e300.into()), vec!["rows[0].after_p95_mm = 1e300"]),
        (edited(&|u| u["before_mm"][2] = (-3.0).into()), vec!["before_mm[2]"]),
        (edited(&|u| u["rows"][1]["no_model"] = 9.into()), vec!["rows[1].no_model = 9 of 2"]),
        (edited(&|u| u["rows"][0]["max_within"] = serde_json::json!([1])), vec!["rows[0].max_within", "2 thresholds"]),
        (
            edited(&|u| {
                u["unit"] = 0.into();
                u["realisation"] = 0.into();
            }),
            vec!["u0000001.json", "not the unit its name gives"],
        ),
        (edited(&|u| u["realisation"] = 5.into()), vec!["not a unit of this sweep"]),
    ] {
        std::fs::write(&file, text).unwrap();
        m(&expect);
        assert!(!merged.join("u").exists(), "nothing merged");
    }
    std::fs::write(&file, good).unwrap();
    run(&["merge", shard.to_str().unwrap()], &merged);
}

/// `calsim` with `args` must exit 2 with one line containing every one of `expect`.
fn bad(args: &[&str], expect: &[&str]) {
    let o = calsim().args(args).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: one line: {err}");
    assert!(!err.contains("panicked"), "{err}");
    for e in expect {
        assert!(err.contains(e), "{args:?}: {e:?} not in {err}");
    }
}

#[test]
fn bad_sweep_input_is_one_line_and_exit_2() {
    let tmp = scratch("sweep-bad");
    let dir = tmp.path();
    let out = dir.join("out");
    let o = out.to_str().unwrap();
    for (name, axes, expect) in [
        (
            "unknown.toml",
            "[[axis]]\nkey = \"trical.epsilonmm\"\nvalues = [0.01]\n",
            vec!["unknown.toml", "trical.epsilonmm = 0.01", "unknown field"],
        ),
        ("type.toml", "[[axis]]\nkey = \"trical.epsilon_mm\"\nvalues = [\"small\"]\n", vec!["type.toml", "trical.epsilon_mm", "small"]),
        (
            "range.toml",
            "[[axis]]\nkey = \"trical.epsilon_mm\"\nvalues = [0.01, 10.0]\n",
            vec!["range.toml", "trical.epsilon_mm = 10.0", "epsilon_mm"],
        ),
        ("empty.toml", "[[axis]]\nkey = \"trical.epsilon_mm\"\nvalues = []\n", vec!["empty.toml", "axis[0]", "at least one value"]),
        ("layout.toml", "[[axis]]\nkey = \"cell.layout\"\nvalues = [{ n = 9, spacing_mm = 300 }]\n", vec!["layout.toml", "layout.n = 9"]),
        ("nan.toml", "[[axis]]\nkey = \"trical.epsilon_mm\"\nvalues = [nan]\n", vec!["nan.toml", "epsilon_mm", "finite"]),
        (
            "line.toml",
            "[[axis]]\nkey = \"cell.layout\"\nvalues = [{ n = 3, spacing_mm = 300, shape = \"line\" }]\n",
            vec!["line.toml", "shape = \"line\"", "define {W}"],
        ),
        (
            "height.toml",
            "[[axis]]\nkey = \"cell.layout\"\nvalues = [{ n = 3, spacing_mm = 300, height_mm = 5000 }]\n",
            vec!["height.toml", "layout.height_mm = 5000", "within"],
        ),
        (
            "shape.toml",
            "[[axis]]\nkey = \"cell.layout\"\nvalues = [{ n = 3, spacing_mm = 300, shape = \"square\" }]\n",
            vec!["shape.toml", "layout.shape", "circle"],
        ),
    ] {
        let f = sweep_file(dir, name, 1, axes);
        bad(&["sweep", f.to_str().unwrap(), "--out", o], &expect);
    }
    let good = sweep_file(dir, "good.toml", 1, AXIS);
    let g = good.to_str().unwrap();
    bad(&["sweep", g, "--shard", "0/0", "--out", o], &["0/0", "K must be"]);
    bad(&["sweep", g, "--shard", "3/3", "--out", o], &["3/3", "k must be below K"]);
    // Shards of two different sweeps.
    let other = sweep_file(dir, "good2.toml", 1, "[[axis]]\nkey = \"trical.epsilon_mm\"\nvalues = [0.03]\n");
    let s1 = dir.join("s1");
    let s2 = dir.join("s2");
    run(&["sweep", g, "--shard", "0/2"], &s1);
    run(&["sweep", other.to_str().unwrap(), "--shard", "1/2"], &s2);
    bad(
        &["merge", s1.join("good.shard-0-of-2").to_str().unwrap(), s2.join("good2.shard-1-of-2").to_str().unwrap(), "--out", o],
        &["good2.shard-1-of-2", "another sweep"],
    );
    // A missing shard.
    bad(&["merge", s1.join("good.shard-0-of-2").to_str().unwrap(), "--out", o], &["work units missing"]);
}

#[test]
fn a_robot_spread_draws_one_robot_per_world_and_none_without_it() {
    use calsim::robot::{ParamSet, SpreadSpec, perturb};
    let truth = calsim::robot::builtin::trical_2018_table7();
    let set = ParamSet::trical_31();
    let zero = perturb(&truth, &set, &SpreadSpec::default(), &mut common::rng(1));
    assert_eq!(set.pack(&zero), set.pack(&truth), "zero spread: the truth itself");
    let spread = SpreadSpec { length_mm: 0.1, angle_deg: 0.01, compliance_mdeg_per_nm: 1.0 };
    // 31 parameters x 400 worlds = 12,400 draws: the sample std of the scaled deviations is within
    // 3 % of 1 (its standard error is 1 / sqrt(2 x 12,400) = 0.6 %).
    let mut z = Vec::new();
    for seed in 0..400 {
        let a = perturb(&truth, &set, &spread, &mut common::rng(seed));
        for (id, (x, t)) in set.ids().iter().zip(set.pack(&a).iter().zip(set.pack(&truth).iter())) {
            let s = match id.unit() {
                calsim::robot::Unit::Mm => spread.length_mm,
                calsim::robot::Unit::Deg => spread.angle_deg.to_radians(),
                calsim::robot::Unit::MdegPerNm => calsim::robot::Unit::MdegPerNm.to_internal(spread.compliance_mdeg_per_nm),
            };
            z.push((x - t) / s);
        }
    }
    let n = z.len() as f64;
    let mean = z.iter().sum::<f64>() / n;
    let std = (z.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    assert!(mean.abs() < 0.03 && (std - 1.0).abs() < 0.03, "mean {mean}, std {std} over {n} draws");
}

/// An adaptive sweep with an objective: three designs (one set size per point) raced on common worlds.
fn adaptive_file(dir: &Path, name: &str) -> PathBuf {
    let base = repo().join("scenarios/ci_quick.toml");
    let text = format!(
        "base = {base:?}\nrealisations = {{ max = 8, min = 2, batch = 2, confidence = 0.8 }}\nthresholds_mm = [1.0]\n\n\
         [objective]\nminimise = \"p95\"\nconfidence = 0.8\n\n[fixed]\n\"study.set_sizes\" = [30]\n\"study.table_set_size\" = 30\n\
         \"study.repetitions\" = 2\n\n[[axis]]\nkey = \"robot.unmodelled.transmission_high_mdeg\"\nvalues = [0.0, 2.82, 20.0]\n",
        base = base.display().to_string()
    );
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

fn all_tables(dir: &Path) -> Vec<Vec<u8>> {
    ["sweep.parquet", "points.parquet", "designs.parquet"].iter().map(|f| std::fs::read(dir.join(f)).unwrap()).collect()
}

/// An adaptive sweep gives the same bytes for 1 and 2 threads and for 3 shards run stage by stage
/// (each shard once per stage, then merged): the race is a function of the units run.
#[test]
fn adaptive_sweeps_are_identical_for_any_threads_and_shards() {
    let tmp = scratch("sweep-adaptive");
    let dir = tmp.path();
    let f = adaptive_file(dir, "a.toml");
    let one = dir.join("one");
    let report = sweep_lib(&f, &one, None, 1);
    let merged = report.merged.expect("an unsharded sweep runs every stage and merges");
    assert!(report.plan.stages_run >= 1);
    let two = dir.join("two");
    sweep_lib(&f, &two, None, 2);
    let sharded = dir.join("sharded");
    let mut rounds = 0;
    let shards = loop {
        rounds += 1;
        assert!(rounds <= 10, "an adaptive sweep of at most 4 stages needs at most 4 rounds of its shards");
        let runs: Vec<calsim::app::sweep::SweepReport> = (0..3).map(|k| sweep_lib(&f, &sharded, Some((k, 3)), 2)).collect();
        // A shard that ran before the others finished the stage waits: run the round again.
        let last = sweep_lib(&f, &sharded, Some((0, 3)), 2);
        if last.plan.complete && runs.iter().all(|r| r.shard_dir.exists()) {
            break runs.iter().map(|r| r.shard_dir.clone()).collect::<Vec<_>>();
        }
    };
    calsim::app::sweep::merge(&shards, &sharded).unwrap();
    let reference = all_tables(&one.join("a"));
    assert_eq!(all_tables(&two.join("a")), reference, "1 vs 2 threads");
    assert_eq!(all_tables(&sharded.join("a")), reference, "1 vs 3 shards");
    assert!(merged.summary.contains("Designs ranked by the objective"), "{}", merged.summary);
}

/// The racing eliminates designs behind the leader before the most realisations, and runs fewer
/// units than every point in every realisation.
#[test]
fn a_clearly_worse_design_leaves_the_race_early() {
    let tmp = scratch("sweep-race");
    let dir = tmp.path();
    let f = adaptive_file(dir, "r.toml");
    let m = sweep_lib(&f, dir, None, 2).merged.unwrap();
    let section =
        m.summary.split("### Designs that left the race").nth(1).unwrap_or_else(|| panic!("no design left the race:\n{}", m.summary));
    let row = section.lines().find(|l| l.contains("behind the leader")).unwrap_or_else(|| panic!("none behind:\n{}", m.summary));
    let worlds: u32 = row.split('|').nth(2).unwrap().trim().parse().unwrap_or_else(|_| panic!("{row}\n{}", m.summary));
    assert!(worlds < 8, "left with {worlds} of at most 8 realisations: {row}");
    assert!(m.units < 3 * 8, "{} units: the race ran fewer than every point x every realisation", m.units);
}

/// Bad objectives and adaptive realisations are one line naming the file and the key.
#[test]
fn bad_objectives_and_adaptive_realisations_are_one_line_naming_the_key() {
    let tmp = scratch("sweep-objective");
    let dir = tmp.path();
    let base = repo().join("scenarios/ci_quick.toml");
    for (body, key) in [
        ("[objective]\nmaximise = \"p95\"\n", "objective.maximise"),
        ("[objective]\nminimise = \"joy\"\n", "objective.minimise"),
        ("[objective]\nmaximise = \"success\"\n", "objective.threshold_mm"),
        ("[objective]\nminimise = \"p95\"\nconfidence = 1.5\n", "objective.confidence"),
        ("[objective]\nminimise = \"p95\"\nsuccess_at_least = 0.9\n", "objective.threshold_mm"),
        ("[objective]\nminimise = \"p95\"\nmaximise = \"success\"\nthreshold_mm = 0.5\n", "objective.minimise"),
        ("[objective]\nminimise = \"p95\"\nthreshold_mm = nan\n", "objective.threshold_mm"),
        ("realisations = { max = 0 }\n", "realisations.max"),
        ("realisations = { batch = 5 }\n", "realisations.max"),
        ("realisations = { max = 10, min = 20 }\n", "realisations.min"),
        ("realisations = { max = 10, speed = 2 }\n", "realisations.speed"),
        ("realisations = -3\n", "realisations"),
    ] {
        let (head, tail) = if body.starts_with("realisations") { (body, "") } else { ("", body) };
        let p = dir.join("bad.toml");
        std::fs::write(&p, format!("base = {:?}\n{head}\n{tail}", base.display().to_string())).unwrap();
        let e = calsim::design::sweep::spec::load(&p).unwrap_err().to_string();
        assert!(e.contains(key) && !e.contains('\n'), "{body}: {e}");
    }
}

/// A sweep's record is written to `sweep.json` and compared with the sweep file's when the shard
/// is read back, so its numbers must come back to the bit: the 6-sphere circle layout of 600 mm
/// of `sphere_layout.toml` came back one ulp off (serde_json's fast float parser), and the README's
/// sweep was refused as "not the record of the sweep file". Every circle layout of 3 to 6 spheres
/// at 50 to 1,000 mm, and 100,000 random doubles over 12 decades, survive the round trip.
#[test]
fn a_records_numbers_come_back_from_json_to_the_bit() {
    use rand::{RngExt, SeedableRng};
    let mut values: Vec<f64> = Vec::new();
    for n in 3..=6 {
        for s in (50..=1000).step_by(50) {
            values.extend(circle_layout(n, f64::from(s)).into_iter().flatten());
        }
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    values.extend((0..100_000).map(|_| rng.random_range(-1.0..1.0) * 10f64.powi(rng.random_range(-6..6))));
    let text = serde_json::to_string(&values).unwrap();
    let back: Vec<f64> = serde_json::from_str(&text).unwrap();
    let off: Vec<(f64, f64)> =
        values.iter().zip(&back).filter(|(a, b)| a.to_bits() != b.to_bits()).map(|(a, b)| (*a, *b)).take(3).collect();
    assert!(off.is_empty(), "{} values; first off: {off:?}", values.len());
}
