//! The results directory: problems with --out are found before the study, a non-directory in the
//! way is left alone, a kill -9 at any instant leaves the old or the new complete results, and
//! what killed runs left is removed by the next run.

mod common;

use std::time::{Duration, Instant};

use common::{calsim, scratch};

/// A short run of the reduced scenario into `out`.
fn quick(out: &std::path::Path) -> std::process::Command {
    let mut c = calsim();
    c.args(["run", "scenarios/ci_quick.toml", "--set-sizes", "20:30:10", "--repetitions", "2", "--no-plots", "--no-recording", "--out"])
        .arg(out);
    c
}

fn complete(dir: &std::path::Path) -> bool {
    ["tasks.parquet", "parameters.parquet", "validation_errors.parquet", "manifest.json", "summary.md"]
        .iter()
        .all(|f| std::fs::metadata(dir.join(f)).map(|m| m.len() > 0).unwrap_or(false))
}

#[test]
fn a_file_in_the_way_is_an_error_before_the_study_and_is_left_alone() {
    let tmp = scratch("out-file");
    let dir = tmp.path();
    std::fs::write(dir.join("ci_quick"), b"keep me").unwrap();
    let t = Instant::now();
    let out = quick(dir).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("ci_quick") && err.contains("not a directory"), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert_eq!(std::fs::read(dir.join("ci_quick")).unwrap(), b"keep me");
    // Found before the campaign ran (the campaign alone takes seconds in the test profile).
    assert!(t.elapsed() < Duration::from_secs(20));

    let file_out = dir.join("not_a_dir");
    std::fs::write(&file_out, b"x").unwrap();
    let out = quick(&file_out).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("not_a_dir") && err.contains("is not a directory"), "{err}");
}

#[test]
fn kill_at_any_instant_leaves_old_or_new_results_and_the_next_run_cleans_up() {
    let tmp = scratch("out-kill");
    let dir = tmp.path();
    assert!(quick(dir).status().unwrap().success());
    let dest = dir.join("ci_quick");
    assert!(complete(&dest));
    // Kill runs at staggered instants: before, during and after the write.
    let first = Instant::now();
    assert!(quick(dir).status().unwrap().success());
    let full = first.elapsed();
    for k in 0..8u32 {
        let mut child = quick(dir).stdout(std::process::Stdio::null()).stderr(std::process::Stdio::null()).spawn().unwrap();
        std::thread::sleep(full.mul_f64(0.5 + 0.08 * f64::from(k)));
        let _ = child.kill(); // SIGKILL
        let _ = child.wait();
        assert!(complete(&dest), "after a kill at {k}: {:?}", std::fs::read_dir(&dest).map(|d| d.count()));
    }
    assert!(quick(dir).status().unwrap().success());
    let entries: Vec<String> = std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
    assert_eq!(entries, vec!["ci_quick".to_string()], "what killed runs left is removed: {entries:?}");
}

/// The rows of the Markdown table under `heading` in `summary`, each as its cells.
fn markdown_rows(summary: &str, heading: &str) -> Vec<Vec<String>> {
    let after = &summary[summary.find(heading).unwrap_or_else(|| panic!("no {heading} in {summary}"))..];
    let table = after.lines().skip_while(|l| !l.starts_with('|')).take_while(|l| l.starts_with('|'));
    table.skip(2).map(|l| l.trim_matches('|').split(" | ").map(|c| c.trim().to_string()).collect()).collect()
}

fn frame(path: &std::path::Path) -> polars::prelude::DataFrame {
    use polars::prelude::SerReader as _;
    polars::prelude::ParquetReader::new(std::fs::File::open(path).unwrap()).finish().unwrap()
}

/// A TriCal run's summary prints the figures its tables store: every statistic of the table of
/// errors before and after calibration, and every figure per set size, is the stored value at
/// the printed precision.
#[test]
fn a_trical_summary_prints_the_figures_its_tables_store() {
    let tmp = scratch("summary-figures");
    assert!(quick(tmp.path()).status().unwrap().success());
    let dest = tmp.path().join("ci_quick");
    let summary = std::fs::read_to_string(dest.join("summary.md")).unwrap();
    let close = |printed: &str, stored: f64, decimals: i32| {
        let p: f64 = printed.parse().unwrap_or_else(|_| panic!("{printed} is not a number"));
        assert!((p - stored).abs() <= 0.5 * 10f64.powi(-decimals) + 1e-12, "printed {printed}, stored {stored}");
    };
    let errors = frame(&dest.join("errors.parquet"));
    let rows = markdown_rows(&summary, "## Errors before and after calibration");
    assert_eq!(rows.len(), errors.height(), "{summary}");
    for (k, row) in rows.iter().enumerate() {
        for (c, name) in ["mean_mm", "median_mm", "std_mm", "p95_mm", "max_mm"].iter().enumerate() {
            match errors.column(name).unwrap().f64().unwrap().get(k) {
                Some(v) if v.is_finite() => close(&row[c + 1], v, 3),
                _ => assert_eq!(row[c + 1], "-", "{name} of row {k}: nothing stored, nothing printed"),
            }
        }
    }
    let sizes = frame(&dest.join("set_sizes.parquet"));
    let rows = markdown_rows(&summary, "## Figs. 8-9");
    assert_eq!(rows.len(), sizes.height(), "{summary}");
    for (k, row) in rows.iter().enumerate() {
        assert_eq!(row[0], sizes.column("set_size").unwrap().u32().unwrap().get(k).unwrap().to_string());
        close(&row[1], sizes.column("median_of_means_mm").unwrap().f64().unwrap().get(k).unwrap(), 4);
        close(&row[2], sizes.column("iqr_of_means_mm").unwrap().f64().unwrap().get(k).unwrap(), 4);
    }
    let r = frame(&dest.join("correlations.parquet"));
    let r_ccz = r.column("r_distance_to_ccz").unwrap().f64().unwrap().get(0).unwrap();
    assert!(summary.contains(&format!("(Fig. 12) {r_ccz:.3}")), "{summary}");
}
