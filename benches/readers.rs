//! The tabular readers' growth with their input: `calsim fk`'s joints reader, `calsim compensate`'s
//! targets reader and `calsim calibrate`'s measurement reader, each timed on files of 10k, 100k and
//! 1M rows, with the growth exponent between
//! the smallest and the largest size (1: linear). A scaling measurement, not a timed test:
//! `cargo bench --bench readers`.

use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

/// Rows of the files timed.
const SIZES: [usize; 3] = [10_000, 100_000, 1_000_000];

/// The fastest of `runs` timings of `f`, s.
fn time(runs: usize, mut f: impl FnMut()) -> f64 {
    (0..runs)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min)
}

/// Prints each size's time and the exponent `log(t_last / t_first) / log(n_last / n_first)`.
fn report(name: &str, rows: &[(usize, f64)]) {
    for (n, t) in rows {
        println!("{name}: {n} rows in {t:.3} s ({:.2} us per row)", t / *n as f64 * 1e6);
    }
    let ((n0, t0), (n1, t1)) = (rows[0], rows[rows.len() - 1]);
    println!("{name}: growth exponent {:.3} from {n0} to {n1} rows", (t1 / t0).ln() / (n1 as f64 / n0 as f64).ln());
}

fn joints_file(path: &Path, n: usize) {
    let mut s = String::from("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n");
    for i in 0..n {
        let a = (i % 360) as f64 * 0.5 - 90.0;
        writeln!(s, "{a},{},{},{a},{},{}", a / 3.0, a / 4.0, a / 5.0, a / 6.0).unwrap();
    }
    std::fs::write(path, s).unwrap();
}

fn targets_file(path: &Path, n: usize) {
    let mut s = String::from("x_mm,y_mm,z_mm,alpha_deg,beta_deg,gamma_deg\n");
    for i in 0..n {
        let a = (i % 100) as f64;
        writeln!(s, "{},{},{},0,90,{a}", 300.0 + a, a - 50.0, 400.0 + a / 2.0).unwrap();
    }
    std::fs::write(path, s).unwrap();
}

/// The shipped example's measurements repeated with a fresh pose label per copy, `n` rows at most
/// (`None`: more than the reader's byte bound holds).
fn measurements_file(path: &Path, n: usize) -> Option<()> {
    let text = std::fs::read_to_string("docs/calibrate/example_measurements.csv").unwrap();
    let mut header = String::new();
    let mut body = Vec::new();
    for line in text.lines() {
        if line.starts_with('#') || line.starts_with("pose,") {
            header.push_str(line);
            header.push('\n');
        } else if !line.is_empty() {
            body.push(line);
        }
    }
    let mut s = header;
    let mut k = 0;
    'copies: for copy in 0.. {
        for line in &body {
            if k == n {
                break 'copies;
            }
            let (pose, rest) = line.split_once(',').unwrap();
            writeln!(s, "{pose}c{copy},{rest}").unwrap();
            k += 1;
        }
    }
    if s.len() as u64 > calsim::io::MOST_CSV_BYTES {
        return None;
    }
    std::fs::write(path, s).unwrap();
    Some(())
}

fn main() {
    let dir = tempfile::tempdir().unwrap();
    let mut fk = Vec::new();
    let mut compensate = Vec::new();
    let mut calibrate = Vec::new();
    let robot = calsim::robot::file::RobotFile::load(Path::new("robots/irb120.toml")).unwrap();
    for n in SIZES {
        let runs = if n >= 1_000_000 { 1 } else { 3 };
        let p = dir.path().join(format!("joints-{n}.csv"));
        joints_file(&p, n);
        fk.push((n, time(runs, || assert_eq!(calsim::robot::fk::read_joints(&p).unwrap().len(), n))));
        let p = dir.path().join(format!("targets-{n}.csv"));
        targets_file(&p, n);
        compensate.push((n, time(runs, || assert_eq!(calsim::app::compensate::read_targets(&p).unwrap().len(), n))));
    }
    for n in SIZES {
        let p = dir.path().join(format!("measurements-{n}.csv"));
        match measurements_file(&p, n) {
            Some(()) => calibrate.push((
                n,
                time(if n >= 1_000_000 { 1 } else { 3 }, || {
                    assert_eq!(calsim::calibrate::measurements::read(&p, &robot).unwrap().points.len(), n)
                }),
            )),
            None => println!("calibrate: {n} rows exceed the {} MiB input bound: not timed", calsim::io::MOST_CSV_BYTES >> 20),
        }
    }
    report("fk (joints)", &fk);
    report("compensate (targets)", &compensate);
    if calibrate.len() >= 2 {
        report("calibrate (measurements)", &calibrate);
    }
}
