//! `calsim plan`: the planned poses are feasible by an independent computation (the arm's frames
//! from the robot file's modified-DH table, the capsules, boxes, the tracker's head, range, field
//! of view, incidence and line of sight computed here), the files are the same bytes for 1 and 2
//! threads, the round trip plan -> simulated measurements -> calibrate lands inside the plan's
//! P10-P90, and bad plan files are refused in one line naming the file and the key.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use calsim::app::plan::{PlanSpec, plan};
use nalgebra::{Matrix3, Rotation3, Vector3};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A test's scratch directory, emptied: under cargo's scratch space for integration tests in the
/// target directory (a run replaces the last run's directory of the same name; `cargo clean`
/// removes them), not the system's temporary directory, which the runs would fill.
fn scratch(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("plan-test-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A small plan of the IRB 120 (the shipped plan's cell, fewer poses and worlds), with `edit`
/// applied to its text.
fn plan_text(edit: impl Fn(String) -> String) -> String {
    let robot = root().join("robots/irb120.toml");
    edit(format!(
        r#"robot = "{}"
model = "compliance"
poses = 40
pool = 300
validation = 8
seed = 3
worlds = 20

[tracker]
position_mm = [1800.0, 0.0, 300.0]
aim_mm = [400.0, 0.0, 400.0]
field_of_view_half_angle_deg = 60.0
min_range_mm = 500.0
max_range_mm = 6000.0
incidence_max_deg = 45.0

[[target]]
name = "SMR1"
flange_mm = [0.0, 0.0, 40.0]

[[target]]
name = "SMR2"
flange_mm = [40.0, 30.0, 30.0]

[cell]
joint_limits_deg = [[-120.0, 120.0], [-90.0, 100.0], [-100.0, 60.0], [-150.0, 150.0], [-115.0, 115.0], [-180.0, 180.0]]
floor_z_mm = 0.0
workspace_min_mm = [250.0, -300.0, 100.0]
workspace_max_mm = [550.0, 300.0, 500.0]

[[cell.keep_out]]
name = "cabinet"
min_mm = [-800.0, -800.0, 0.0]
max_mm = [-400.0, 800.0, 1500.0]
"#,
        robot.display()
    ))
}

struct Run {
    dir: PathBuf,
    report: calsim::app::plan::PlanReport,
    files_1: Vec<(String, Vec<u8>)>,
    files_2: Vec<(String, Vec<u8>)>,
}

fn files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut v: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| {
            let e = e.unwrap();
            (e.file_name().to_string_lossy().into_owned(), std::fs::read(e.path()).unwrap())
        })
        .collect();
    v.sort();
    v
}

/// The small plan run with 1 and with 2 threads (with `--simulate` and the recording).
fn run() -> &'static Run {
    static RUN: OnceLock<Run> = OnceLock::new();
    RUN.get_or_init(|| {
        let dir = scratch("run");
        let file = dir.join("small.toml");
        std::fs::write(&file, plan_text(|t| t)).unwrap();
        let go = |threads: u32| {
            let out = dir.join(format!("out{threads}"));
            let r =
                plan(&PlanSpec { file: file.clone(), out, threads: Some(threads), simulate: true, recording: true }, &calsim::app::Quiet)
                    .unwrap();
            // The recording is compared by its contents (`the_recording_holds_...`): Rerun stamps
            // each file with its own recording id and time.
            let f = files(&r.dir).into_iter().filter(|(n, _)| n != "plan.rrd").collect();
            (r, f)
        };
        let (_, files_1) = go(1);
        let (report, files_2) = go(2);
        Run { dir, report, files_1, files_2 }
    })
}

#[test]
fn one_and_two_threads_write_the_same_bytes() {
    let r = run();
    let names: Vec<&str> = r.files_1.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(
        names,
        [
            "joints.txt",
            "manifest.json",
            "plan.md",
            "plan.parquet",
            "plan_poses.png",
            "plan_poses.svg",
            "poses.csv",
            "simulated.csv",
            "tour.csv",
            "tour_moves.parquet",
            "unidentifiable.parquet",
            "worlds.parquet"
        ]
    );
    assert_eq!(r.files_1, r.files_2);
    assert!(r.dir.exists());
    // The figure: its key names what it shows, one ring per validation pose in each view.
    let svg = String::from_utf8(r.files_1.iter().find(|(n, _)| n == "plan_poses.svg").unwrap().1.clone()).unwrap();
    for label in [
        "training pose",
        "validation pose",
        "tracker",
        "robot base",
        "workspace of interest",
        "top view",
        "side view",
        "line of sight",
        "arm at ",
    ] {
        assert!(svg.contains(label), "{label}");
    }
    assert!(r.files_1.iter().find(|(n, _)| n == "plan_poses.png").unwrap().1.starts_with(b"\x89PNG"));
}

/// The rows of the Markdown table under `heading` in `md`, each as its cells.
fn markdown_rows(md: &str, heading: &str) -> Vec<Vec<String>> {
    let after = &md[md.find(heading).unwrap_or_else(|| panic!("no {heading} in {md}"))..];
    let table = after.lines().skip_while(|l| !l.starts_with('|')).take_while(|l| l.starts_with('|'));
    table.skip(2).map(|l| l.trim_matches('|').split(" | ").map(|c| c.trim().to_string()).collect()).collect()
}

fn frame(path: &Path) -> polars::prelude::DataFrame {
    use polars::prelude::SerReader as _;
    polars::prelude::ParquetReader::new(std::fs::File::open(path).unwrap()).finish().unwrap()
}

/// Column `name` of `f` as numbers (counts and floats alike).
fn numbers(f: &polars::prelude::DataFrame, name: &str) -> Vec<f64> {
    let c = f.column(name).unwrap_or_else(|_| panic!("no column {name}")).cast(&polars::prelude::DataType::Float64).unwrap();
    let c = c.f64().unwrap();
    (0..c.len()).map(|k| c.get(k).unwrap_or(f64::NAN)).collect()
}

/// `x` at `decimals`, as plan.md prints an interval's end (`unbounded` when infinite).
fn shown(x: f64, decimals: usize) -> String {
    if x.is_finite() { format!("{x:.decimals$}") } else { "unbounded".into() }
}

/// Every figure of the tables of the plan.md in `dir` equals its stored parquet value at the
/// printed precision: the predicted held-out error, and when the plan has them the objective's
/// counts and the comparison's selections. Returns the tables checked.
fn plan_md_equals_its_stored_tables(dir: &Path) -> usize {
    let md = std::fs::read_to_string(dir.join("plan.md")).unwrap();
    let plan = frame(&dir.join("plan.parquet"));
    let v = |name: &str| numbers(&plan, name)[0];
    let row = &markdown_rows(&md, "## Predicted held-out error")[0];
    assert_eq!(row[..3], [shown(v("p10_mm"), 4), shown(v("median_mm"), 4), shown(v("p90_mm"), 4)], "{md}");
    if plan.column("instrument").is_ok() {
        assert_eq!(row[3], format!("{}-{}", shown(v("median_lo_mm"), 4), shown(v("median_hi_mm"), 4)));
        assert_eq!(row[4], shown(v("pilot_median_mm"), 4));
    } else {
        assert_eq!(row[3], shown(v("pilot_median_mm"), 4));
        assert_eq!(row[4], plan.column("pilot_chosen").unwrap().str().unwrap().get(0).unwrap());
    }
    let mut checked = 1;
    if dir.join("search.parquet").exists() {
        let search = frame(&dir.join("search.parquet"));
        let rows = markdown_rows(&md, "## Number of poses by objective");
        assert_eq!(rows.len(), search.height(), "{md}");
        let meets = search.column("meets").unwrap().bool().unwrap().clone();
        let meets: Vec<bool> = (0..meets.len()).map(|k| meets.get(k).unwrap()).collect();
        for (k, r) in rows.iter().enumerate() {
            let n = |c: &str| numbers(&search, c)[k];
            assert_eq!(r[0], format!("{}", n("poses")));
            assert_eq!(r[1], format!("{} / {}", n("successes"), n("worlds")));
            assert_eq!((r[2].clone(), r[3].clone()), (shown(n("p_success"), 3), shown(n("lower"), 4)));
            assert_eq!(r[4], if meets[k] { "yes" } else { "no" });
        }
        checked += 1;
    }
    if dir.join("comparison.parquet").exists() {
        let c = frame(&dir.join("comparison.parquet"));
        let rows = markdown_rows(&md, "## DETMAX against random and greedy selection");
        assert_eq!(rows.len(), c.height(), "{md}");
        let names = c.column("selection").unwrap().str().unwrap().clone();
        let names: Vec<String> = (0..names.len()).map(|k| names.get(k).unwrap().to_string()).collect();
        for (k, r) in rows.iter().enumerate() {
            let n = |name: &str| numbers(&c, name)[k];
            let iv = |p: &str| {
                format!(
                    "{} ({}-{})",
                    shown(n(&format!("{p}_mm")), 4),
                    shown(n(&format!("{p}_lo_mm")), 4),
                    shown(n(&format!("{p}_hi_mm")), 4)
                )
            };
            assert_eq!(r[..], [names[k].clone(), shown(n("o1"), 6), iv("median"), iv("p90")]);
        }
        checked += 1;
    }
    checked
}

/// Every figure of plan.md's tables equals its stored parquet value: the tracker plan, the
/// TriCal plan, and a plan with an objective and the comparison (`an_objective_and_...`).
#[test]
fn every_figure_of_plan_md_equals_its_stored_parquet_value() {
    assert_eq!(plan_md_equals_its_stored_tables(&run().report.dir), 1);
    assert_eq!(plan_md_equals_its_stored_tables(&trical_run().report.dir), 1);
    // The frames the report hands on (to Python) are the tables written.
    for (dir, frames) in [(&run().report.dir, &run().report.frames), (&trical_run().report.dir, &trical_run().report.frames)] {
        let written: Vec<String> = files(dir).into_iter().map(|(n, _)| n).filter(|n| n.ends_with(".parquet")).collect();
        let mut names: Vec<String> = frames.iter().map(|(n, _)| n.clone()).collect();
        names.sort();
        assert_eq!(names, written);
        for (name, f) in frames {
            assert!(f.equals_missing(&frame(&dir.join(name))), "{name}");
        }
    }
    let worlds = frame(&run().report.dir.join("worlds.parquet"));
    assert_eq!(
        numbers(&worlds, "heldout_median_mm").iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
        run().report.outcome.prediction.per_world_mm.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
    );
}

/// The arm's frames 0..6 from the robot file's modified-DH table (alpha_{i-1}, a_{i-1}, theta_i +
/// offset, d_i; no Hayati beta in this file's nominal), computed here.
fn frames(joints: &[toml::Value], q: &[f64; 6]) -> Vec<(Matrix3<f64>, Vector3<f64>)> {
    let mut r = Matrix3::identity();
    let mut p = Vector3::zeros();
    let mut out = vec![(r, p)];
    for (i, j) in joints.iter().enumerate() {
        let g = |k: &str| j.get(k).and_then(|v| v.as_float()).unwrap_or(0.0);
        assert_eq!(g("beta_deg"), 0.0);
        let rx = *Rotation3::from_axis_angle(&Vector3::x_axis(), g("alpha_deg").to_radians()).matrix();
        let rz = *Rotation3::from_axis_angle(&Vector3::z_axis(), q[i] + g("theta_offset_deg").to_radians()).matrix();
        p += r * Vector3::new(g("a_mm"), 0.0, 0.0);
        r *= rx;
        p += r * rz * Vector3::new(0.0, 0.0, g("d_mm"));
        r *= rz;
        out.push((r, p));
    }
    out
}

fn point_segment(x: &Vector3<f64>, a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    let d = b - a;
    let t = if d.norm_squared() > 0.0 { ((x - a).dot(&d) / d.norm_squared()).clamp(0.0, 1.0) } else { 0.0 };
    (x - (a + d * t)).norm()
}

/// Points along a segment every `step` mm (ends included).
fn along(a: &Vector3<f64>, b: &Vector3<f64>, step: f64) -> Vec<Vector3<f64>> {
    let n = ((b - a).norm() / step).ceil().max(1.0) as usize;
    (0..=n).map(|k| a + (b - a) * (k as f64 / n as f64)).collect()
}

fn point_box(x: &Vector3<f64>, lo: &Vector3<f64>, hi: &Vector3<f64>) -> f64 {
    Vector3::from_fn(|i, _| (lo[i] - x[i]).max(0.0).max(x[i] - hi[i])).norm()
}

/// Sampling step along a segment, mm: a sampled distance exceeds the true one by at most half of it.
const STEP: f64 = 0.5;
const SAMPLED: f64 = STEP / 2.0;

/// A body of the independent computation: its link (7: an SMR), its ends and radius, mm.
type Body = (usize, Vector3<f64>, Vector3<f64>, f64);

/// The joint limits of the IRB 120 plans' cells, deg.
const IRB120_LIMITS_DEG: [[f64; 2]; 6] =
    [[-120.0, 120.0], [-90.0, 100.0], [-100.0, 60.0], [-150.0, 150.0], [-115.0, 115.0], [-180.0, 180.0]];

/// The IRB 120's robot file read here: its `[[joint]]` table and its capsules (link, ends in the
/// link's frame, radius).
fn irb120_capsules() -> (Vec<toml::Value>, Vec<Body>) {
    let robot: toml::Table = std::fs::read_to_string(root().join("robots/irb120.toml")).unwrap().parse().unwrap();
    let caps = robot["collision"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| {
            let v = |k: &str| {
                let a = c[k].as_array().unwrap();
                Vector3::new(a[0].as_float().unwrap(), a[1].as_float().unwrap(), a[2].as_float().unwrap())
            };
            (c["link"].as_integer().unwrap() as usize, v("a_mm"), v("b_mm"), c["radius_mm"].as_float().unwrap())
        })
        .collect();
    (robot["joint"].as_array().unwrap().clone(), caps)
}

/// `tour.csv`'s stops in `dir`: pose, split and the joints (rad) from column `first_joint`.
fn tour_stops(dir: &Path, first_joint: usize) -> Vec<(String, String, [f64; 6])> {
    std::fs::read_to_string(dir.join("tour.csv"))
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            (f[1].to_string(), f[2].to_string(), std::array::from_fn(|i| f[first_joint + i].parse::<f64>().unwrap().to_radians()))
        })
        .collect()
}

/// Walks every move between `stops` at 1 deg of the joint that moves most, both ends included:
/// each configuration inside [`IRB120_LIMITS_DEG`] and `free`. Returns the configurations checked.
fn walk_tour(stops: &[(String, String, [f64; 6])], free: impl Fn(&[f64; 6]) -> Result<(), String>) -> usize {
    let mut checked = 0;
    for w in stops.windows(2) {
        let (a, b) = (&w[0].2, &w[1].2);
        let most = (0..6).map(|i| (a[i] - b[i]).abs()).fold(0.0, f64::max);
        let n = (most / 1f64.to_radians()).ceil().max(1.0) as usize;
        for s in 0..=n {
            let q: [f64; 6] = std::array::from_fn(|i| a[i] + (b[i] - a[i]) * s as f64 / n as f64);
            for (i, l) in IRB120_LIMITS_DEG.iter().enumerate() {
                assert!(q[i].to_degrees() >= l[0] - 1e-6 && q[i].to_degrees() <= l[1] + 1e-6, "joint {}", i + 1);
            }
            if let Err(e) = free(&q) {
                panic!("{} -> {} at step {s} of {n}: {e}", w[0].0, w[1].0);
            }
            checked += 1;
        }
    }
    checked
}

/// The via configurations a recording draws: its `/plan/vias/...` entities, and the rows of its
/// `/plan/robot` (one per stop of the tour).
fn recorded_vias(path: &Path) -> (Vec<String>, usize) {
    let e = recording_entities(path);
    let vias = e.keys().filter(|k| k.starts_with("/plan/vias/")).map(|k| k["/plan/vias/".len()..].to_string()).collect();
    (vias, e.get("/plan/robot").map_or(0, |x| x.0))
}

#[test]
fn every_planned_pose_is_feasible_by_an_independent_computation() {
    let r = run();
    let (joints, caps) = irb120_capsules();
    let joints = &joints;
    let limits = IRB120_LIMITS_DEG;
    let tracker = Vector3::new(1800.0, 0.0, 300.0);
    let aim = (Vector3::new(400.0, 0.0, 400.0) - tracker).normalize();
    let targets = [Vector3::new(0.0, 0.0, 40.0), Vector3::new(40.0, 30.0, 30.0)];
    let smr_r = 38.1 / 2.0;
    let (lo, hi) = (Vector3::new(-800.0, -800.0, 0.0), Vector3::new(-400.0, 800.0, 1500.0));
    // Capsules in the base frame at q: (body, a, b, radius); body 7 is the SMRs on the flange.
    let bodies = |q: &[f64; 6]| -> Vec<(usize, Vector3<f64>, Vector3<f64>, f64)> {
        let f = frames(joints, q);
        let mut v: Vec<_> = caps.iter().map(|(l, a, b, rad)| (*l, f[*l].1 + f[*l].0 * a, f[*l].1 + f[*l].0 * b, *rad)).collect();
        for t in &targets {
            let p = f[6].1 + f[6].0 * t;
            v.push((7, p, p, smr_r));
        }
        v
    };
    let capsule_gap = |x: &(usize, Vector3<f64>, Vector3<f64>, f64), y: &(usize, Vector3<f64>, Vector3<f64>, f64)| -> f64 {
        along(&x.1, &x.2, STEP).iter().map(|p| point_segment(p, &y.1, &y.2)).fold(f64::INFINITY, f64::min) - x.3 - y.3
    };
    // Pairs of bodies two or more apart that touch at the home pose are allowed (as the planner's
    // allowed-collision rule), the SMRs against links 5 and 6 too.
    let home = bodies(&[0.0; 6]);
    let allowed = |i: usize, j: usize| -> bool {
        let (i, j) = (i.min(j), i.max(j));
        j < i + 2
            || (j == 7 && i >= 5)
            || home.iter().filter(|x| x.0 == i).any(|x| home.iter().filter(|y| y.0 == j).any(|y| capsule_gap(x, y) < 0.0))
    };
    let csv = std::fs::read_to_string(r.report.dir.join("poses.csv")).unwrap();
    let mut poses = 0;
    for line in csv.lines().filter(|l| !l.starts_with('#') && !l.starts_with("pose,")).step_by(2) {
        let f: Vec<&str> = line.split(',').collect();
        assert_eq!(&f[10..13], ["", "", ""], "{line}: position columns empty");
        assert!(f[3] == "train" || f[3] == "holdout", "{line}: split column");
        let q: [f64; 6] = std::array::from_fn(|i| f[4 + i].parse::<f64>().unwrap().to_radians());
        for i in 0..6 {
            assert!(q[i] >= limits[i][0].to_radians() - 1e-12 && q[i] <= limits[i][1].to_radians() + 1e-12, "{line}: joint {}", i + 1);
        }
        let b = bodies(&q);
        for x in b.iter().filter(|x| x.0 >= 1) {
            assert!(x.1.z.min(x.2.z) - x.3 >= 0.0, "{line}: body {} below the floor", x.0);
            assert!(along(&x.1, &x.2, STEP).iter().all(|p| point_box(p, &lo, &hi) >= x.3 - SAMPLED), "{line}: body {} in the cabinet", x.0);
            assert!(point_segment(&tracker, &x.1, &x.2) >= x.3 + 150.0, "{line}: body {} meets the tracker head", x.0);
        }
        for (k, x) in b.iter().enumerate() {
            for y in &b[k + 1..] {
                if !allowed(x.0, y.0) {
                    assert!(capsule_gap(x, y) >= -SAMPLED, "{line}: bodies {} and {} collide", x.0, y.0);
                }
            }
        }
        let fr = frames(joints, &q);
        for t in &targets {
            let p = fr[6].1 + fr[6].0 * t;
            let axis = fr[6].0 * Vector3::z();
            let d = (tracker - p).norm();
            assert!((500.0..=6000.0).contains(&d), "{line}: range {d}");
            let u = (tracker - p) / d;
            assert!((-u).dot(&aim).acos().to_degrees() <= 60.0 + 1e-9, "{line}: outside the field of view");
            assert!(axis.dot(&u).acos().to_degrees() <= 45.0 + 1e-9, "{line}: incidence {}", axis.dot(&u).acos().to_degrees());
            // Line of sight: from the head to the SMR's surface, clear of every body but the SMR itself.
            let end = p + u * (smr_r + 0.5);
            for x in &b {
                if x.0 == 7 && (x.1 - p).norm() < 1e-9 {
                    continue;
                }
                let gap = along(&tracker, &end, STEP).iter().map(|s| point_segment(s, &x.1, &x.2)).fold(f64::INFINITY, f64::min) - x.3;
                assert!(gap >= -SAMPLED, "{line}: line of sight to {t:?} crosses body {}", x.0);
            }
        }
        poses += 1;
    }
    assert_eq!(poses, 48, "40 training and 8 validation poses");
}

/// Rows and timelines per entity path of a Rerun recording, read with Rerun's own decoder.
fn recording_entities(path: &Path) -> std::collections::BTreeMap<String, (usize, Vec<String>)> {
    use re_log_types::{LogMsg, StoreKind};
    let file = std::io::BufReader::new(std::fs::File::open(path).unwrap());
    let mut out: std::collections::BTreeMap<String, (usize, Vec<String>)> = Default::default();
    for msg in re_log_encoding::DecoderApp::decode_eager(file).unwrap() {
        if let LogMsg::ArrowMsg(store, arrow) = &msg.unwrap()
            && store.kind() == StoreKind::Recording
        {
            let chunk = re_chunk::Chunk::from_arrow_msg(arrow).unwrap();
            let e = out.entry(chunk.entity_path().to_string()).or_default();
            e.0 += chunk.num_rows();
            for t in chunk.timelines().keys() {
                if !e.1.contains(&t.to_string()) {
                    e.1.push(t.to_string());
                }
            }
        }
    }
    out
}

/// The recording holds the cell, the arm and its lines of sight at every pose of the tour, and
/// the predicted held-out median of every world; the arm the figure and the recording draw is
/// the robot file's capsules, the frames' origins and the targets where the modified-DH frames
/// computed here put them.
#[test]
fn the_recording_and_the_figure_draw_the_arm_and_its_lines_of_sight_at_the_planned_poses() {
    let r = run();
    let e = recording_entities(&r.report.dir.join("plan.rrd"));
    let rows = |p: &str| e.get(p).map(|x| x.0).unwrap_or_else(|| panic!("{p} missing from {:?}", e.keys().collect::<Vec<_>>()));
    let on = |p: &str, t: &str| e.get(p).is_some_and(|x| x.1.iter().any(|n| n == t));
    for p in
        ["/cell/tracker", "/cell/workspace", "/cell/keep_out", "/cell/floor", "/cell/frames/base", "/plan/targets", "/plan/shown/robot"]
    {
        assert!(rows(p) >= 1, "{p}");
    }
    let poses = r.report.outcome.rows.len();
    assert_eq!(poses, 48);
    let stops = tour_stops(&r.report.dir, 3).len();
    for p in ["/plan/robot", "/plan/sight"] {
        assert_eq!(rows(p), stops, "{p}: one row per stop of the tour (poses and via configurations)");
        assert!(on(p, "tour_step"), "{p}");
    }
    assert_eq!(rows("/tour/largest_move_deg"), stops + 1, "one value per stop and the series' style");
    let worlds = r.report.outcome.prediction.per_world_mm.iter().filter(|m| m.is_finite()).count();
    assert!(worlds >= 15, "{worlds} worlds with a value");
    assert_eq!(rows("/study/heldout_median_mm"), worlds + 1);
    assert!(on("/study/heldout_median_mm", "world"));

    let robot: toml::Table = std::fs::read_to_string(root().join("robots/irb120.toml")).unwrap().parse().unwrap();
    let joints = robot["joint"].as_array().unwrap();
    let collision = robot["collision"].as_array().unwrap();
    let plan = &r.report.plan;
    let cell = calsim::plan::cell::Cell::new(plan).unwrap();
    let shown = calsim::plan::plot::shown(&r.report.outcome);
    assert_eq!(shown.len(), calsim::plan::plot::SHOWN);
    let mut st = calsim::robot::KinState::default();
    for i in shown {
        let q = r.report.outcome.rows[i].q;
        let v = calsim::plan::plot::arm_at(plan, &cell, &q, &mut st);
        let f = frames(joints, &q);
        assert_eq!(v.capsules.len(), collision.len() + 2, "every link capsule and an SMR per target");
        for (c, (a, b, rad)) in collision.iter().zip(&v.capsules) {
            let l = c["link"].as_integer().unwrap() as usize;
            let x = |k: &str| {
                let p = c[k].as_array().unwrap();
                f[l].1 + f[l].0 * Vector3::new(p[0].as_float().unwrap(), p[1].as_float().unwrap(), p[2].as_float().unwrap())
            };
            assert!((x("a_mm") - a).norm() < 1e-9 && (x("b_mm") - b).norm() < 1e-9, "link {l}");
            assert_eq!(*rad, c["radius_mm"].as_float().unwrap());
        }
        assert_eq!(v.skeleton.len(), 7);
        for (k, o) in v.skeleton.iter().enumerate() {
            assert!((f[k].1 - o).norm() < 1e-9, "frame {k}'s origin");
        }
        for (t, p) in [Vector3::new(0.0, 0.0, 40.0), Vector3::new(40.0, 30.0, 30.0)].iter().zip(&v.targets) {
            assert!((f[6].1 + f[6].0 * t - p).norm() < 1e-9, "target {t:?}");
        }
    }
}

/// The round trip plan -> simulated measurements -> calibrate over 10 seeds of the small plan: the
/// calibrated held-out median lands inside the plan's P10-P90 (an 80 % band) in at least 5 of the
/// 10 (for a band that holds 80 %, fewer than 5 happen with probability 0.0064, Binomial(10, 0.8)).
/// Seed 3 is the small plan of [`run`] (2 threads, `--simulate`, as the other seeds here).
#[test]
fn plan_simulate_calibrate_lands_inside_the_plans_p10_p90() {
    let dir = scratch("round-trip");
    let mut inside = Vec::new();
    for seed in 1..=10u64 {
        let planned;
        let r = if seed == 3 {
            &run().report
        } else {
            let file = dir.join(format!("seed{seed}.toml"));
            std::fs::write(&file, plan_text(|t| t.replace("seed = 3", &format!("seed = {seed}")))).unwrap();
            let spec = PlanSpec { file, out: dir.join(format!("out{seed}")), threads: Some(2), simulate: true, recording: false };
            planned = plan(&spec, &calsim::app::Quiet).unwrap();
            &planned
        };
        let spec = calsim::calibrate::CalibrateSpec {
            robot_file: root().join("robots/irb120.toml"),
            measurements: r.dir.join("simulated.csv"),
            out: dir.join(format!("calibration{seed}")),
            options: calsim::plan::calibrate_options(&r.plan),
            plan_worlds: 0,
            plan_noise_mm: None,
            plan_scenario: None,
            plan_with: Default::default(),
            instrument_noise_mm: None,
        };
        let c = calsim::calibrate::calibrate(&spec).unwrap();
        let measured = calsim::calibrate::plan::Statistic::Median.of(&c.calibration).unwrap();
        let [p10, _, p90] = r.outcome.prediction.quantiles_mm;
        assert_eq!(r.outcome.prediction.worlds, 20);
        inside.push((seed, p10 <= measured && measured <= p90, measured, p10, p90));
    }
    let count = inside.iter().filter(|x| x.1).count();
    eprintln!("round trip: inside the plan's P10-P90 in {count} of 10 seeds");
    assert!(count >= 5, "inside the plan's P10-P90 in {count} of 10 seeds: {inside:?}");
}

fn refused(edit: impl Fn(String) -> String, key: &str) -> String {
    let dir = scratch(&format!("bad-{}", key.replace(['.', '[', ']'], "_")));
    let file = dir.join("bad.toml");
    std::fs::write(&file, plan_text(edit)).unwrap();
    let e = plan(
        &PlanSpec { file: file.clone(), out: dir.join("out"), threads: Some(2), simulate: false, recording: false },
        &calsim::app::Quiet,
    )
    .expect_err("a bad plan is refused")
    .to_string();
    assert!(e.starts_with(&file.display().to_string()), "{e}: names the file");
    assert!(e.contains(key), "{e}: names {key}");
    assert!(!e.contains('\n'), "{e}: one line");
    assert!(!dir.join("out").join("bad.plan").exists());
    e
}

#[test]
fn bad_plan_files_are_refused_naming_the_file_and_the_key() {
    let e = refused(|t| t.replace("seed = 3", "seed = 3\nsede = 4"), "sede");
    assert!(e.contains("unknown field"), "{e}");
    refused(|t| t.replace("floor_z_mm = 0.0", "floor_z_mm = nan"), "cell.floor_z_mm");
    refused(|t| t.replace("aim_mm = [400.0, 0.0, 400.0]", "aim_mm = [400.0, inf, 400.0]"), "tracker.aim_mm");
    let e = refused(|t| t.replace("poses = 40", "poses = 20"), "poses");
    assert!(e.contains("below the 34 parameters"), "{e}");
    let e = refused(|t| t.replace("position_mm = [1800.0, 0.0, 300.0]", "position_mm = [0.0, 0.0, 400.0]"), "tracker.position_mm");
    assert!(e.contains("inside the arm"), "{e}");
    let e = refused(|t| t.replace("min_range_mm = 500.0", "min_range_mm = 5900.0"), "tracker");
    assert!(e.contains("no feasible pose"), "{e}");
    refused(|t| t.replace("model = \"compliance\"", "model = \"geometrik\""), "model");
    refused(|t| t.replace("[-120.0, 120.0], [-90.0", "[-170.0, 120.0], [-90.0"), "cell.joint_limits_deg");
}

#[test]
fn the_command_exits_2_with_one_line_on_a_bad_plan() {
    let dir = scratch("cli");
    let file = dir.join("bad.toml");
    std::fs::write(&file, plan_text(|t| t.replace("incidence_max_deg = 45.0", "incidence_max_deg = -inf"))).unwrap();
    let o =
        std::process::Command::new(env!("CARGO_BIN_EXE_calsim")).arg("plan").arg(&file).arg("--out").arg(dir.join("out")).output().unwrap();
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8(o.stderr).unwrap();
    let lines: Vec<&str> = err.lines().collect();
    assert_eq!(lines.len(), 1, "{err}");
    assert!(lines[0].contains("tracker.incidence_max_deg") && lines[0].contains("bad.toml"), "{err}");
}

#[test]
fn the_shipped_plan_file_is_accepted() {
    let file = root().join("scenarios/plans/irb120_tracker.toml");
    let p = calsim::app::plan::load(&file).unwrap();
    assert_eq!((p.poses, p.pool, p.validation), (60, 2000, 20));
}

/// A plan's directory is a calsim results directory (its manifest carries the provenance block and
/// names the plan file among its inputs): the same plan runs again into the same `--out`. (The
/// small plan with 2 worlds: the directory's making does not depend on their number.)
#[test]
fn a_plan_runs_again_into_its_own_results_directory() {
    let dir = scratch("again");
    let file = dir.join("small.toml");
    std::fs::write(&file, plan_text(|t| t.replace("worlds = 20", "worlds = 2"))).unwrap();
    let spec = PlanSpec { file: file.clone(), out: dir.join("out"), threads: Some(2), simulate: false, recording: false };
    let first = plan(&spec, &calsim::app::Quiet).unwrap();
    let manifest: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(first.dir.join("manifest.json")).unwrap()).unwrap();
    let inputs = manifest["inputs"].as_array().unwrap();
    assert!(inputs.iter().any(|i| i["path"].as_str().unwrap().ends_with("small.toml")), "{manifest}");
    assert!(manifest["git_commit"].is_string());
    let again = plan(&spec, &calsim::app::Quiet).unwrap();
    assert_eq!(std::fs::read(first.dir.join("poses.csv")).unwrap(), std::fs::read(again.dir.join("poses.csv")).unwrap());
}

/// The rows of the objective's table in `plan.md`: (poses, successes, worlds, lower bound, meets).
fn objective_table(md: &str) -> Vec<(usize, usize, usize, f64, bool)> {
    let start = md.find("| poses | successes / worlds |").expect("the objective's table");
    md[start..]
        .lines()
        .skip(2)
        .take_while(|l| l.starts_with('|'))
        .map(|l| {
            let f: Vec<&str> = l.trim_matches('|').split('|').map(str::trim).collect();
            let (k, w) = f[1].split_once(" / ").unwrap();
            (f[0].parse().unwrap(), k.parse().unwrap(), w.parse().unwrap(), f[3].parse().unwrap(), f[4] == "yes")
        })
        .collect()
}

/// The one-sided lower Clopper-Pearson bound, computed here by bisection on the binomial tail:
/// the p with P(X >= k | n, p) = 1 - confidence.
fn beta_lower(k: usize, n: usize, confidence: f64) -> f64 {
    if k == 0 {
        return 0.0;
    }
    let tail = |p: f64| -> f64 {
        // P(X >= k) = 1 - P(X <= k - 1), by the terms of the binomial.
        let mut below = 0.0;
        let mut term = (1.0 - p).powi(n as i32);
        for i in 0..k {
            below += term;
            term *= (n - i) as f64 / (i + 1) as f64 * p / (1.0 - p);
        }
        1.0 - below
    };
    let (mut lo, mut hi) = (0.0, 1.0);
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if tail(mid) < 1.0 - confidence {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

#[test]
fn bad_objectives_are_refused_naming_the_file_and_the_key() {
    let with = |o: &'static str| move |t: String| t.replace("poses = 40\n", "") + "\n[objective]\n" + o;
    let ok = "statistic = \"max\"\nthreshold_mm = 0.5\nsuccess_at_least = 0.95\n";
    refused(with("statistic = \"maximum\"\nthreshold_mm = 0.5\nsuccess_at_least = 0.95\n"), "objective.statistic");
    refused(with("statistic = \"max\"\nthreshold_mm = nan\nsuccess_at_least = 0.95\n"), "objective.threshold_mm");
    refused(with("statistic = \"max\"\nthreshold_mm = -1.0\nsuccess_at_least = 0.95\n"), "objective.threshold_mm");
    refused(with("statistic = \"max\"\nthreshold_mm = 0.5\nsuccess_at_least = 1.0\n"), "objective.success_at_least");
    // 20 worlds all succeeding show at most 0.891 at 90 %: 0.95 cannot be shown.
    let e = refused(with(ok), "objective.success_at_least");
    assert!(e.contains("cannot be shown by 20 worlds") && e.contains("set worlds to 45 or more"), "{e}");
    let ok45 = |extra: &'static str| {
        move |t: String| t.replace("poses = 40\n", "").replace("worlds = 20", "worlds = 45") + "\n[objective]\n" + ok + extra
    };
    refused(ok45("confidence = 1.5\n"), "objective.confidence");
    refused(ok45("most_poses = 20\n"), "objective.most_poses");
    refused(ok45("most_poses = 300\n"), "objective.most_poses");
    refused(ok45("thresold = 1.0\n"), "thresold");
    refused(|t: String| t.replace("worlds = 20", "worlds = 45") + "\n[objective]\n" + ok, "poses");
    refused(|t: String| t.replace("poses = 40\n", ""), "poses");
    refused(
        |t: String| {
            t.replace("poses = 40\n", "").replace("worlds = 20", "worlds = 45").replace("validation = 8", "validation = 0")
                + "\n[objective]\n"
                + ok
        },
        "validation",
    );
}

#[test]
fn the_command_exits_2_with_one_line_on_a_bad_objective() {
    let dir = scratch("cli-objective");
    let file = dir.join("bad.toml");
    std::fs::write(
        &file,
        plan_text(|t| t.replace("poses = 40\n", "") + "\n[objective]\nstatistic = \"max\"\nthreshold_mm = inf\nsuccess_at_least = 0.5\n"),
    )
    .unwrap();
    let o =
        std::process::Command::new(env!("CARGO_BIN_EXE_calsim")).arg("plan").arg(&file).arg("--out").arg(dir.join("out")).output().unwrap();
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8(o.stderr).unwrap();
    let lines: Vec<&str> = err.lines().collect();
    assert_eq!(lines.len(), 1, "{err}");
    assert!(lines[0].contains("objective.threshold_mm") && lines[0].contains("bad.toml"), "{err}");
}

/// `compare = true`: DETMAX's, a random and a greedy set of the same size, each simulated on the
/// same worlds. DETMAX's row, simulated through the comparison's own path (its poses written and
/// read again), is the prediction's per-world figures to the bit: the same worlds. (The small plan
/// with 8 worlds: each row holds the plan's worlds whatever their number.)
#[test]
fn the_comparison_has_its_rows_on_the_same_worlds() {
    let dir = scratch("compare");
    let file = dir.join("compare.toml");
    std::fs::write(&file, plan_text(|t| t.replace("worlds = 20", "worlds = 8\ncompare = true"))).unwrap();
    let r =
        plan(&PlanSpec { file, out: dir.join("out"), threads: Some(2), simulate: false, recording: false }, &calsim::app::Quiet).unwrap();
    let c = r.outcome.comparison.as_ref().expect("a comparison");
    let names: Vec<&str> = c.rows.iter().map(|r| r.name).collect();
    assert_eq!(names, ["DETMAX", "random", "greedy D-optimal"]);
    let same_bits = |a: &[f64], b: &[f64]| a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits());
    assert!(
        same_bits(&c.rows[0].per_world_mm, &r.outcome.prediction.per_world_mm),
        "{:?} {:?}",
        c.rows[0].per_world_mm,
        r.outcome.prediction.per_world_mm
    );
    assert_eq!(c.rows[1].o1, r.outcome.o1.1, "the random set is the one whose O1 the plan reports");
    for row in &c.rows {
        assert_eq!(row.per_world_mm.len(), 8);
        assert!(row.per_world_mm.iter().all(|v| v.is_finite() && *v > 0.0), "{row:?}");
        let (m, lo, hi) = row.median_mm;
        assert!(lo <= m && m <= hi, "{row:?}");
        assert!(row.o1 > 0.0);
    }
    // Greedy D-optimal maximises the determinant step by step: its O1 is above a random set's.
    assert!(c.rows[2].o1 > c.rows[1].o1, "{:?}", c.rows.iter().map(|r| r.o1).collect::<Vec<_>>());
    let md = std::fs::read_to_string(r.dir.join("plan.md")).unwrap();
    for name in names {
        assert!(md.lines().any(|l| l.starts_with(&format!("| {name} | "))), "{md}");
    }
}

/// A twin (the robot file with a `[learned]` table) is the robot of the pilot world and of every
/// world: the plan predicts a larger held-out error than with the same file without the table
/// (the small plan of [`run`], 2 threads and `--simulate` as here, on robots/irb120.toml), and
/// says so in plan.md.
#[test]
fn a_twin_predicts_a_larger_held_out_error_than_its_file_without_the_table() {
    let dir = scratch("twin");
    let robot = std::fs::read_to_string(root().join("robots/irb120.toml")).unwrap();
    std::fs::write(
        dir.join("twin.toml"),
        robot
            + "\n[learned]\nsource = \"a test twin\"\nrepeatability_mm = 0.01\npose_error_mdeg = 3.0\nbacklash_mdeg = [0.0, 6.0, 4.0, 0.0, 0.0, 0.0]\n\n[[learned.harmonic]]\njoint = 2\norder = 1.0\nsin_mdeg = 10.0\ncos_mdeg = -4.0\nstd_mdeg = 2.0\n",
    )
    .unwrap();
    let file = dir.join("twin-plan.toml");
    let robot_path = dir.join("twin.toml");
    std::fs::write(
        &file,
        plan_text(|t| t.replace(&root().join("robots/irb120.toml").display().to_string(), &robot_path.display().to_string())),
    )
    .unwrap();
    let twin = plan(&PlanSpec { file, out: dir.join("out-twin"), threads: Some(2), simulate: true, recording: false }, &calsim::app::Quiet)
        .unwrap();
    let plain = &run().report;
    // The same poses (the table moves no pose), the same worlds' seeds.
    assert_eq!(plain.outcome.rows, twin.outcome.rows);
    assert!(!plain.outcome.prediction.twin && twin.outcome.prediction.twin);
    let [p10, p50, p90] = plain.outcome.prediction.quantiles_mm;
    let [t10, t50, t90] = twin.outcome.prediction.quantiles_mm;
    eprintln!("plain {p10:.4} {p50:.4} {p90:.4}; twin {t10:.4} {t50:.4} {t90:.4}");
    assert!(t50 > p90, "the twin's median {t50} above the plain file's P90 {p90}");
    assert!(twin.outcome.prediction.pilot_median_mm > plain.outcome.prediction.pilot_median_mm);
    let md = std::fs::read_to_string(twin.dir.join("plan.md")).unwrap();
    assert!(md.contains("The robot file is a twin"), "{md}");
    // --simulate measures the twin too: its file differs from the plain one's.
    assert_ne!(std::fs::read(plain.dir.join("simulated.csv")).unwrap(), std::fs::read(twin.dir.join("simulated.csv")).unwrap());
}

/// A shipped plan file's text with shorter settings, in `dir`, its robot file path made absolute.
fn shipped_short(dir: &Path, name: &str, edit: impl Fn(String) -> String) -> PathBuf {
    let text = std::fs::read_to_string(root().join("scenarios/plans").join(name)).unwrap();
    let robot_line = text.lines().find(|l| l.starts_with("robot = ")).unwrap();
    let robot = robot_line.split('"').nth(1).unwrap();
    let absolute = root().join("scenarios/plans").join(robot);
    let file = dir.join(name);
    std::fs::write(&file, edit(text.replace(robot_line, &format!("robot = \"{}\"", absolute.display())))).unwrap();
    file
}

/// The imported arm's shipped plan (the LR Mate 200iC from its URDF) runs, short: its poses are in
/// the plan's limits, training and validation as asked.
#[test]
fn the_shipped_imported_arm_plan_runs() {
    let dir = scratch("lrmate");
    let file = shipped_short(&dir, "lrmate200ic_tracker.toml", |t| {
        t.replace("poses = 50 ", "poses = 40 ")
            .replace("pool = 2000", "pool = 300")
            .replace("worlds = 30", "worlds = 8")
            .replace("validation = 20", "validation = 8")
    });
    let r =
        plan(&PlanSpec { file, out: dir.join("out"), threads: Some(2), simulate: true, recording: false }, &calsim::app::Quiet).unwrap();
    assert_eq!(r.plan.robot.nominal.data().name, "fanuc_lrmate200ic");
    assert_eq!(r.outcome.rows.iter().filter(|x| x.split == "train").count(), 40);
    assert_eq!(r.outcome.rows.iter().filter(|x| x.split == "holdout").count(), 8);
    for row in &r.outcome.rows {
        for (q, l) in row.q.iter().zip(&r.plan.limits) {
            assert!(*q >= l.min && *q <= l.max, "{row:?}");
        }
    }
    let [p10, p50, p90] = r.outcome.prediction.quantiles_mm;
    assert!(p10 > 0.0 && p10 <= p50 && p50 <= p90 && p90 < 1.0, "{:?}", r.outcome.prediction);
    assert!(r.dir.join("simulated.csv").exists());
}

/// The shipped plan with an objective is accepted as shipped and, short, searches and compares.
#[test]
fn the_shipped_objective_plan_runs() {
    let p = calsim::app::plan::load(&root().join("scenarios/plans/irb120_tracker_objective.toml")).unwrap();
    let o = p.objective.as_ref().unwrap();
    assert_eq!((o.threshold_mm, o.success_at_least, o.confidence, o.most_poses, p.worlds, p.compare), (0.045, 0.9, 0.9, 400, 60, true));
    let dir = scratch("objective-shipped");
    let file = shipped_short(&dir, "irb120_tracker_objective.toml", |t| {
        t.replace("pool = 2000", "pool = 300")
            .replace("validation = 20", "validation = 8")
            .replace("most_poses = 400", "most_poses = 40")
            .replace("worlds = 60 ", "worlds = 24 ")
    });
    let r =
        plan(&PlanSpec { file, out: dir.join("out"), threads: Some(2), simulate: false, recording: false }, &calsim::app::Quiet).unwrap();
    let search = r.outcome.search.as_ref().unwrap();
    assert_eq!(search.candidates[0].n, 34);
    assert!(search.candidates.iter().all(|c| c.worlds == 24), "the file's worlds, shortened: {:?}", search.candidates);
    assert_eq!(r.outcome.comparison.as_ref().unwrap().rows.len(), 3);
}

/// A plan with an objective and the comparison writes the same bytes for 1 and 2 threads, and
/// plans the smallest count its own table shows meeting the objective: the test recomputes each
/// row's lower bound (Clopper-Pearson, one-sided, 90 %) from its counts, checks the rule against
/// the target, and that the count below the chosen one was scored and failed.
#[test]
fn an_objective_picks_the_smallest_count_meeting_it_and_writes_the_same_bytes_for_1_and_2_threads() {
    let dir = scratch("objective-threads");
    let file = dir.join("objective.toml");
    // A held-out median near the tracker's noise floor (0.019 mm at 60 % over 12 worlds), which
    // this cell's worlds reach only with more poses than the fewest. At most 40 poses: the search
    // goes from the fewest (34) to the most and bisects between them, the counts it scores kept
    // near the fewest.
    std::fs::write(
        &file,
        plan_text(|t| {
            t.replace("poses = 40\n", "").replace("worlds = 20", "worlds = 12\ncompare = true")
                + "\n[objective]\nstatistic = \"median\"\nthreshold_mm = 0.019\nsuccess_at_least = 0.6\nconfidence = 0.9\nmost_poses = 40\n"
        }),
    )
    .unwrap();
    let go = |threads: u32| {
        let r = plan(
            &PlanSpec {
                file: file.clone(),
                out: dir.join(format!("out{threads}")),
                threads: Some(threads),
                simulate: false,
                recording: false,
            },
            &calsim::app::Quiet,
        )
        .unwrap();
        assert!(r.outcome.search.as_ref().unwrap().candidates.len() >= 2, "{:?}", r.outcome.search);
        assert_eq!(plan_md_equals_its_stored_tables(&r.dir), 3, "the prediction, the objective and the comparison");
        let files = files(&r.dir).into_iter().filter(|(n, _)| n != "manifest.json").collect::<Vec<_>>();
        (r, files)
    };
    let (_, one) = go(1);
    let (r, two) = go(2);
    assert_eq!(one, two);

    let md = std::fs::read_to_string(r.dir.join("plan.md")).unwrap();
    let table = objective_table(&md);
    eprintln!("{table:?}");
    // What `calsim plan` prints is read from the same tables: its line, the objective's.
    let (printed, _) = calsim::plan::summary::terminal(&r.frames, calsim::plan::summary::terminal_line(1.5), "kept nominal").unwrap();
    let lines: Vec<&str> = printed.lines().collect();
    let (o, p) = (&r.outcome, &r.outcome.prediction);
    assert_eq!(
        lines[0],
        format!(
            "calsim plan: {} training + {} validation poses from {} feasible of {} drawn; O1 {:.6} (random set {:.6}); predicted held-out median {:.4} mm (P10-P90 {:.4}-{:.4}) over {} worlds; 1.50 s",
            o.poses,
            r.plan.validation,
            o.pool.qs.len(),
            o.pool.tried,
            o.o1.0,
            o.o1.1,
            p.quantiles_mm[1],
            p.quantiles_mm[0],
            p.quantiles_mm[2],
            p.worlds
        )
    );
    let smallest_met = table.iter().filter(|r| r.4).map(|r| r.0).min().expect("a count meets the objective");
    assert_eq!(
        lines[1],
        format!(
            "objective P(held-out median <= 0.019 mm) >= 0.6 at 0.9 confidence: met at {smallest_met} poses, the smallest of {} counts scored (table in plan.md)",
            table.len()
        )
    );
    assert!(table.len() >= 2, "{md}");
    for (n, k, w, lower, meets) in &table {
        assert_eq!(*w, 12, "every count on the 12 worlds");
        let bound = beta_lower(*k, *w, 0.9);
        assert!((bound - lower).abs() < 1e-4, "n {n}: lower bound {lower} against {bound} recomputed");
        assert_eq!(*meets, *lower >= 0.6, "n {n}");
    }
    let smallest = table.iter().filter(|r| r.4).map(|r| r.0).min().expect("a count meets the objective in this cell");
    assert_eq!(r.outcome.poses, smallest);
    assert!(md.contains(&format!("Chosen: {smallest} poses, the smallest count in the table whose lower bound clears 0.6")), "{md}");
    assert!(table.iter().any(|r| r.0 == smallest - 1 && !r.4) || smallest == 34, "the count below was scored and failed: {table:?}");
    assert!(table.iter().any(|r| !r.4), "a count that fails: the search is not trivial here: {table:?}");
    let poses = std::fs::read_to_string(r.dir.join("poses.csv")).unwrap();
    let training = poses.lines().filter(|l| l.contains(",train,")).count();
    assert_eq!(training, 2 * smallest, "two targets per pose");
    // The comparison is made at the chosen count.
    assert!(md.contains(&format!("The same {smallest} training poses chosen three ways")), "{md}");
}

/// The shipped TriCal plan with its files named absolutely (it may run from a scratch directory)
/// and `edit` applied to its text.
fn trical_text(edit: impl Fn(String) -> String) -> String {
    let t = std::fs::read_to_string(root().join("scenarios/plans/irb120_trical.toml")).unwrap();
    let t = t
        .replace("\"../../robots/irb120.toml\"", &format!("\"{}\"", root().join("robots/irb120.toml").display()))
        .replace("\"../irb120_trical.toml\"", &format!("\"{}\"", root().join("scenarios/irb120_trical.toml").display()));
    edit(t)
}

struct DeviceRun {
    report: calsim::app::plan::DevicePlanReport,
    files_1: Vec<(String, Vec<u8>)>,
    files_2: Vec<(String, Vec<u8>)>,
}

/// A device plan file's text (in a scratch directory of its own) run with 1 and with 2 threads.
fn device_run(name: &str, text: String, simulate: bool) -> DeviceRun {
    let dir = scratch(name);
    let file = dir.join(format!("{name}.toml"));
    std::fs::write(&file, text).unwrap();
    let go = |threads: u32| {
        let spec =
            PlanSpec { file: file.clone(), out: dir.join(format!("out{threads}")), threads: Some(threads), simulate, recording: true };
        let r = calsim::app::plan::plan_device(&spec, &calsim::app::Quiet).unwrap();
        let f = files(&r.dir).into_iter().filter(|(n, _)| n != "plan.rrd").collect();
        (r, f)
    };
    let (_, files_1) = go(1);
    let (report, files_2) = go(2);
    DeviceRun { report, files_1, files_2 }
}

/// The shipped TriCal plan (fewer worlds) run with 1 and with 2 threads.
fn trical_run() -> &'static DeviceRun {
    static RUN: OnceLock<DeviceRun> = OnceLock::new();
    RUN.get_or_init(|| device_run("trical", trical_text(|t| t.replace("worlds = 30", "worlds = 12")), false))
}

#[test]
fn a_trical_plan_writes_the_same_bytes_for_1_and_2_threads() {
    let r = trical_run();
    let names: Vec<&str> = r.files_1.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(
        names,
        [
            "joints.txt",
            "manifest.json",
            "plan.md",
            "plan.parquet",
            "plan_poses.png",
            "plan_poses.svg",
            "poses.csv",
            "spheres.parquet",
            "tour.csv",
            "tour_moves.parquet",
            "unidentifiable.parquet",
            "worlds.parquet"
        ]
    );
    assert_eq!(r.files_1, r.files_2);
    assert!(r.report.dir.join("plan.rrd").exists());
    let svg = String::from_utf8(r.files_1.iter().find(|(n, _)| n == "plan_poses.svg").unwrap().1.clone()).unwrap();
    for label in
        ["centred on sphere 1", "centred on sphere 3", "validation configuration", "workspace of interest", "top view", "side view"]
    {
        assert!(svg.contains(label), "{label}");
    }
    let o = &r.report.outcome;
    assert_eq!(o.poses, 75);
    assert_eq!(o.rows.len(), 75 + 30);
    assert!(o.o1.0 > o.o1.1, "DETMAX's O1 {} above a random set's {}", o.o1.0, o.o1.1);
    let p = &o.prediction;
    assert_eq!(p.per_world_mm.len(), 12);
    assert!(p.quantiles_mm[0] <= p.quantiles_mm[1] && p.quantiles_mm[1] <= p.quantiles_mm[2], "{:?}", p.quantiles_mm);
    assert!(p.quantiles_mm[1] > 0.0 && p.quantiles_mm[2] < 1.0, "{:?}", p.quantiles_mm);
}

#[test]
fn every_trical_pose_is_centred_on_its_sphere_and_feasible_by_an_independent_computation() {
    let r = trical_run();
    let (joints, caps) = irb120_capsules();
    let joints = &joints;
    let limits = IRB120_LIMITS_DEG;
    // The scenario's TCP in the flange frame (frame 6 is the flange in this robot file).
    let tcp = Vector3::new(35.0, 0.0, 125.0);
    let (lo, hi) = (Vector3::new(-800.0, -800.0, 0.0), Vector3::new(-400.0, 800.0, 1500.0));
    let (w_lo, w_hi) = (Vector3::new(200.0, -250.0, 250.0), Vector3::new(500.0, 250.0, 500.0));
    let bodies = |q: &[f64; 6]| -> Vec<(usize, Vector3<f64>, Vector3<f64>, f64)> {
        let f = frames(joints, q);
        caps.iter().map(|(l, a, b, rad)| (*l, f[*l].1 + f[*l].0 * a, f[*l].1 + f[*l].0 * b, *rad)).collect()
    };
    let capsule_gap = |x: &(usize, Vector3<f64>, Vector3<f64>, f64), y: &(usize, Vector3<f64>, Vector3<f64>, f64)| -> f64 {
        along(&x.1, &x.2, STEP).iter().map(|p| point_segment(p, &y.1, &y.2)).fold(f64::INFINITY, f64::min) - x.3 - y.3
    };
    let home = bodies(&[0.0; 6]);
    let allowed = |i: usize, j: usize| -> bool {
        let (i, j) = (i.min(j), i.max(j));
        j < i + 2 || home.iter().filter(|x| x.0 == i).any(|x| home.iter().filter(|y| y.0 == j).any(|y| capsule_gap(x, y) < 0.0))
    };
    let csv = std::fs::read_to_string(r.report.dir.join("poses.csv")).unwrap();
    // The nominal arm's TCP per sphere (base frame), and the sphere's centre the row gives ({W}).
    let mut clusters: Vec<Vec<Vector3<f64>>> = vec![Vec::new(); 3];
    let mut centres: Vec<Option<Vector3<f64>>> = vec![None; 3];
    let (mut train, mut holdout) = (0, 0);
    for line in csv.lines().filter(|l| !l.starts_with('#') && !l.starts_with("pose,")) {
        let f: Vec<&str> = line.split(',').collect();
        assert_eq!(f.len(), 13, "{line}");
        let q: [f64; 6] = std::array::from_fn(|i| f[4 + i].parse::<f64>().unwrap().to_radians());
        for i in 0..6 {
            assert!(q[i] >= limits[i][0].to_radians() - 1e-12 && q[i] <= limits[i][1].to_radians() + 1e-12, "{line}: joint {}", i + 1);
        }
        let b = bodies(&q);
        for x in b.iter().filter(|x| x.0 >= 1) {
            assert!(x.1.z.min(x.2.z) - x.3 >= 0.0, "{line}: body {} below the table", x.0);
            assert!(along(&x.1, &x.2, STEP).iter().all(|p| point_box(p, &lo, &hi) >= x.3 - SAMPLED), "{line}: body {} in the cabinet", x.0);
        }
        for (k, x) in b.iter().enumerate() {
            for y in &b[k + 1..] {
                if !allowed(x.0, y.0) {
                    assert!(capsule_gap(x, y) >= -SAMPLED, "{line}: bodies {} and {} collide", x.0, y.0);
                }
            }
        }
        let fr = frames(joints, &q);
        let p = fr[6].1 + fr[6].0 * tcp;
        match f[3] {
            "train" => {
                let s: usize = f[0].rsplit("_s").next().unwrap().parse().unwrap();
                let c = Vector3::new(f[10].parse().unwrap(), f[11].parse().unwrap(), f[12].parse().unwrap());
                assert!(centres[s - 1].is_none_or(|o| o == c), "{line}: one centre per sphere");
                centres[s - 1] = Some(c);
                clusters[s - 1].push(p);
                train += 1;
            }
            "holdout" => {
                assert_eq!(&f[10..13], ["", "", ""], "{line}: a validation row's position is the tracker's to fill");
                assert!(point_box(&p, &w_lo, &w_hi) < 0.01, "{line}: the TCP {p:?} outside the workspace of interest");
                holdout += 1;
            }
            other => panic!("{line}: split {other}"),
        }
    }
    assert_eq!((train, holdout), (75, 30));
    // Centred: every configuration of a sphere puts the nominal arm's TCP at one point, up to the
    // nominal arm's error before calibration (the paper's largest, Fig. 13: 6.3 mm), and the points
    // of the spheres lie as far apart as the spheres' centres.
    const BEFORE_MM: f64 = 6.3;
    let mean = |v: &[Vector3<f64>]| v.iter().sum::<Vector3<f64>>() / v.len() as f64;
    for (s, v) in clusters.iter().enumerate() {
        assert!(!v.is_empty(), "sphere {}: no configuration", s + 1);
        let m = mean(v);
        let far = v.iter().map(|p| (p - m).norm()).fold(0.0, f64::max);
        assert!(far < BEFORE_MM, "sphere {}: a TCP {far} mm from the others' mean", s + 1);
    }
    for a in 0..3 {
        for b in a + 1..3 {
            let planned = (mean(&clusters[a]) - mean(&clusters[b])).norm();
            let spheres = (centres[a].unwrap() - centres[b].unwrap()).norm();
            assert!((planned - spheres).abs() < BEFORE_MM, "spheres {} and {}: {planned} mm apart, centres {spheres}", a + 1, b + 1);
        }
    }
    // And the true arm of the planning world: within the centring of the device (its indicators to
    // 10 um, the arm's repeatability and its effects outside the model) of the located centre.
    assert!(r.report.outcome.centring_mm.iter().all(|d| *d < 0.1), "{:?}", r.report.outcome.centring_mm);
}

fn trical_refused(edit: impl Fn(String) -> String, key: &str) -> String {
    let dir = scratch(&format!("trical-bad-{}", key.replace(['.', '[', ']', ' '], "_")));
    let file = dir.join("bad.toml");
    std::fs::write(&file, trical_text(edit)).unwrap();
    let spec = PlanSpec { file: file.clone(), out: dir.join("out"), threads: Some(2), simulate: false, recording: false };
    let e = calsim::app::plan::plan_device(&spec, &calsim::app::Quiet).expect_err("a bad plan is refused").to_string();
    assert!(e.starts_with(&file.display().to_string()), "{e}: names the file");
    assert!(e.contains(key), "{e}: names {key}");
    assert!(!e.contains('\n'), "{e}: one line");
    assert!(!dir.join("out").join("bad.plan").exists());
    e
}

#[test]
fn bad_trical_plan_files_are_refused_naming_the_file_and_the_key() {
    let e = trical_refused(|t| t.replace("kind = \"trical\"", "kind = \"trical\"\nsphere_count = 3"), "sphere_count");
    assert!(e.contains("unknown field"), "{e}");
    let e = trical_refused(|t| t.replace("kind = \"trical\"", "kind = \"tracker\""), "instrument.kind");
    assert!(e.contains("not a device with a pool of its own"), "{e}");
    let e = trical_refused(|t| t.replace("kind = \"trical\"", "kind = \"spms\""), "instrument.spheres_w_mm");
    assert!(e.contains("an SPMS plan's stations"), "{e}");
    let e = trical_refused(|t| t.replace("pool = 360", "pool = 361"), "pool");
    assert!(e.contains("multiple of the 3 datum spheres"), "{e}");
    trical_refused(|t| t.replace("[300.0, 0.0, 0.0]", "[300.0, nan, 0.0]"), "instrument.spheres_w_mm");
    let e = trical_refused(|t| t.replace("poses = 75", "poses = 8"), "poses");
    assert!(e.contains("below 11"), "{e}");
    trical_refused(|t| t.replace("validation = 30", "validation = 0"), "validation");
    trical_refused(|t| t.replace("irb120_trical.toml\"", "irb120_tricall.toml\""), "instrument.scenario");
    // Spheres the arm cannot reach with the device: the device's campaign says which.
    let e = trical_refused(|t| t.replace("[150.0, 259.8076, 0.0]]", "[150.0, 1900.0, 0.0]]"), "instrument");
    assert!(e.contains("sphere"), "{e}");
    trical_refused(|t| t.replace("floor_z_mm = 0.0", "floor_z_mm = inf"), "cell.floor_z_mm");
}

/// Bad SPMS plan files: one line naming the file and the key.
#[test]
fn bad_spms_plan_files_are_refused_naming_the_file_and_the_key() {
    let refused = |edit: &dyn Fn(String) -> String, key: &str| -> String {
        let dir = scratch(&format!("spms-bad-{}", key.replace(['.', '[', ']', ' '], "_")));
        let file = dir.join("bad.toml");
        std::fs::write(&file, spms_text(edit)).unwrap();
        let spec = PlanSpec { file: file.clone(), out: dir.join("out"), threads: Some(2), simulate: false, recording: false };
        let e = calsim::app::plan::plan_device(&spec, &calsim::app::Quiet).expect_err("a bad plan is refused").to_string();
        assert!(e.starts_with(&file.display().to_string()) && e.contains(key) && !e.contains('\n'), "{e}: the file, {key}, one line");
        assert!(!dir.join("out").join("bad.plan").exists());
        e
    };
    let e = refused(&|t| t.replace("kind = \"spms\"", "kind = \"spms\"\nspheres_w_mm = [[0.0, 0.0, 0.0]]"), "instrument.spheres_w_mm");
    assert!(e.contains("[station]"), "{e}");
    let e = refused(&|t| t.replace(&t.lines().find(|l| l.starts_with("robot = ")).unwrap().to_string(), "robot = \"irb120\""), "robot");
    assert!(e.contains("robot file"), "{e}");
    refused(&|t| t.replace("er20c10_spms.toml\"", "irb120_trical.toml\""), "instrument.scenario");
    let e = refused(&|t| t.replace("poses = 50", "poses = 5"), "poses");
    assert!(e.contains("below 9"), "{e}");
}

#[test]
fn the_command_exits_2_with_one_line_on_a_bad_trical_plan() {
    let dir = scratch("trical-cli");
    let file = dir.join("bad.toml");
    std::fs::write(&file, trical_text(|t| t.replace("pool = 360", "pool = 100"))).unwrap();
    let o =
        std::process::Command::new(env!("CARGO_BIN_EXE_calsim")).arg("plan").arg(&file).arg("--out").arg(dir.join("out")).output().unwrap();
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8(o.stderr).unwrap();
    let lines: Vec<&str> = err.lines().collect();
    assert_eq!(lines.len(), 1, "{err}");
    assert!(lines[0].contains("pool") && lines[0].contains("bad.toml"), "{err}");
}

#[test]
fn the_trical_scenario_yields_its_pool() {
    let s = calsim::device::load(&root().join("scenarios/irb120_trical.toml")).unwrap();
    let pool = s.candidate_pool().expect("the TriCal has a pool of its own").unwrap();
    assert_eq!(pool.observations.len(), 360);
    assert_eq!(pool.group_of.len(), 360);
    assert_eq!((0..3).map(|g| pool.group_of.iter().filter(|x| **x == g).count()).collect::<Vec<_>>(), [120, 120, 120]);
    assert_eq!((pool.jacobian.len, pool.jacobian.m), (360, pool.set.len()));
    assert_eq!(pool.set.len(), 31);
    // Every configuration of a sphere observes the one centre the ballbar located, near the nominal.
    for g in 0..3 {
        let seen: Vec<_> = pool.observations.iter().zip(&pool.group_of).filter(|(_, x)| **x == g).map(|(o, _)| o.tcp_world_mm).collect();
        assert!(seen.iter().all(|p| *p == seen[0]), "sphere {}", g + 1);
        assert!((seen[0] - Vector3::from(pool.groups_w_mm[g])).norm() < 0.1, "sphere {}: {:?}", g + 1, seen[0]);
    }
}

/// The SPMS scenario's pool: the configurations the head measured at its three stations (shared
/// evenly), each observing the sphere centre within the sphere's travel in the head (+-2, 15, 2
/// mm) and the head's measuring error of its station's convergence point.
#[test]
fn the_spms_scenario_yields_its_pool_of_the_stations() {
    let s = calsim::device::load(&root().join("scenarios/er20c10_spms.toml")).unwrap();
    let pool = s.candidate_pool().expect("the SPMS has a pool of its own").unwrap();
    assert_eq!(pool.observations.len(), 300);
    assert_eq!((0..3).map(|g| pool.group_of.iter().filter(|x| **x == g).count()).collect::<Vec<_>>(), [100, 100, 100]);
    assert_eq!((pool.jacobian.len, pool.jacobian.m), (300, pool.set.len()));
    assert_eq!(pool.groups_w_mm.len(), 3);
    let travel = Vector3::new(2.0, 15.0, 2.0).norm();
    for (o, g) in pool.observations.iter().zip(&pool.group_of) {
        let off = (o.tcp_world_mm - Vector3::from(pool.groups_w_mm[*g])).norm();
        assert!(off < travel + 0.5, "station {}: {off} mm from its convergence point", g + 1);
    }
}

#[test]
fn the_tracker_planner_refuses_a_device_plan_in_one_line() {
    let dir = scratch("trical-as-tracker");
    let file = dir.join("trical.toml");
    std::fs::write(&file, trical_text(|t| t)).unwrap();
    let spec = PlanSpec { file: file.clone(), out: dir.join("out"), threads: Some(1), simulate: false, recording: false };
    let e = plan(&spec, &calsim::app::Quiet).expect_err("a device plan is not a tracker plan").to_string();
    assert!(e.starts_with(&file.display().to_string()) && e.contains("instrument") && !e.contains('\n'), "{e}");
}

/// The closest distance between segments p1-q1 and p2-q2 (Ericson, Real-Time Collision
/// Detection, 5.1.9), computed here.
fn segment_segment(p1: &Vector3<f64>, q1: &Vector3<f64>, p2: &Vector3<f64>, q2: &Vector3<f64>) -> f64 {
    let (d1, d2, r) = (q1 - p1, q2 - p2, p1 - p2);
    let (a, e, f) = (d1.dot(&d1), d2.dot(&d2), d2.dot(&r));
    let (s, t) = if a <= 1e-12 && e <= 1e-12 {
        (0.0, 0.0)
    } else if a <= 1e-12 {
        (0.0, (f / e).clamp(0.0, 1.0))
    } else {
        let c = d1.dot(&r);
        if e <= 1e-12 {
            ((-c / a).clamp(0.0, 1.0), 0.0)
        } else {
            let b = d1.dot(&d2);
            let denom = a * e - b * b;
            let mut s = if denom > 1e-12 { ((b * f - c * e) / denom).clamp(0.0, 1.0) } else { 0.0 };
            let mut t = (b * s + f) / e;
            if t < 0.0 {
                t = 0.0;
                s = (-c / a).clamp(0.0, 1.0);
            } else if t > 1.0 {
                t = 1.0;
                s = ((b - c) / a).clamp(0.0, 1.0);
            }
            (s, t)
        }
    };
    ((p1 + d1 * s) - (p2 + d2 * t)).norm()
}

/// An independent collision check of the IRB 120 in the shipped plans' cell: the robot file's
/// capsules on the modified-DH frames computed here, and `targets` on the flange (spheres of
/// `target_r` mm, body 7), against each other (pairs touching at the home pose allowed, and the
/// targets with links 5 and 6), `ground` at z = 0, the cabinet and, where given, a tracker head
/// (150 mm). Free: what the planner's checks see within the 6-decimal rounding of tour.csv's
/// degrees; the error names what collides.
fn irb120_cell_check(
    targets: &[Vector3<f64>],
    target_r: f64,
    ground: &'static str,
    tracker: Option<Vector3<f64>>,
) -> impl Fn(&[f64; 6]) -> Result<(), String> {
    const ROUNDED_MM: f64 = 0.01;
    let (joints, caps) = irb120_capsules();
    let targets = targets.to_vec();
    let bodies = move |q: &[f64; 6]| -> Vec<(usize, Vector3<f64>, Vector3<f64>, f64)> {
        let f = frames(&joints, q);
        let mut v: Vec<_> = caps.iter().map(|(l, a, b, rad)| (*l, f[*l].1 + f[*l].0 * a, f[*l].1 + f[*l].0 * b, *rad)).collect();
        for t in &targets {
            let p = f[6].1 + f[6].0 * t;
            v.push((7, p, p, target_r));
        }
        v
    };
    let home = bodies(&[0.0; 6]);
    let touching = move |i: usize, j: usize| {
        home.iter()
            .filter(|x| x.0 == i)
            .any(|x| home.iter().filter(|y| y.0 == j).any(|y| segment_segment(&x.1, &x.2, &y.1, &y.2) < x.3 + y.3))
    };
    let allowed = move |i: usize, j: usize| -> bool {
        let (i, j) = (i.min(j), i.max(j));
        j < i + 2 || (j == 7 && i >= 5) || touching(i, j)
    };
    let (lo, hi) = (Vector3::new(-800.0, -800.0, 0.0), Vector3::new(-400.0, 800.0, 1500.0));
    move |q: &[f64; 6]| -> Result<(), String> {
        let b = bodies(q);
        for x in b.iter().filter(|x| x.0 >= 1) {
            if x.1.z.min(x.2.z) - x.3 < -ROUNDED_MM {
                return Err(format!("body {} below {ground}", x.0));
            }
            if along(&x.1, &x.2, STEP).iter().any(|p| point_box(p, &lo, &hi) < x.3 - SAMPLED) {
                return Err(format!("body {} in the cabinet", x.0));
            }
            if let Some(t) = &tracker
                && point_segment(t, &x.1, &x.2) < x.3 + 150.0 - ROUNDED_MM
            {
                return Err(format!("body {} meets the tracker head", x.0));
            }
        }
        for (k, x) in b.iter().enumerate() {
            for y in &b[k + 1..] {
                if !allowed(x.0, y.0) && segment_segment(&x.1, &x.2, &y.1, &y.2) < x.3 + y.3 - ROUNDED_MM {
                    return Err(format!("bodies {} and {} collide", x.0, y.0));
                }
            }
        }
        Ok(())
    }
}

/// The tour of the TriCal plan: its straight moves through a collision are re-routed through via
/// configurations (rows `via` of `tour.csv`, in no other file), and every move of the tour, via
/// paths included, is free at the stated step (1 deg of the joint that moves most) by a computation
/// here: the robot file's capsules on the modified-DH frames computed here, against each other
/// (pairs touching at the home pose allowed), the table and the cabinet. (The device's capsules and
/// its fixtures are the planner's alone.)
#[test]
fn the_trical_tour_re_routes_its_colliding_moves_and_every_step_is_free_by_an_independent_computation() {
    let r = trical_run();
    let o = &r.report.outcome;
    assert!(!o.colliding_moves.is_empty(), "the shipped TriCal plan's tour has a straight move through a collision");
    assert!(o.routing.unrouted.is_empty(), "{:?}", o.routing.unrouted);
    assert_eq!(o.routing.vias.iter().map(|v| v.between).collect::<Vec<_>>(), o.colliding_moves);
    let free = irb120_cell_check(&[], 0.0, "the table", None);
    let stops = tour_stops(&r.report.dir, 4);
    let vias = stops.iter().filter(|s| s.1 == "via").count();
    assert_eq!(vias, o.routing.vias.iter().map(|v| v.qs.len()).sum::<usize>());
    assert_eq!(stops.len(), o.rows.len() + vias);
    assert!(stops.iter().filter(|s| s.1 == "via").all(|s| s.0.starts_with("via")));
    let poses = std::fs::read_to_string(r.report.dir.join("poses.csv")).unwrap();
    assert!(!poses.contains("via"), "a via configuration is not measured");
    let checked = walk_tour(&stops, &free);
    // The recording draws the arm at every via configuration of tour.csv, and at every stop.
    let (drawn, robot_rows) = recorded_vias(&r.report.dir.join("plan.rrd"));
    assert_eq!(drawn, stops.iter().filter(|s| s.1 == "via").map(|s| s.0.clone()).collect::<Vec<_>>());
    assert_eq!(robot_rows, stops.len());
    eprintln!("tour: {} stops ({vias} via), {checked} configurations checked", stops.len());
}

/// The round trip of a TriCal plan: plan -> `simulated.csv` (`--simulate`) -> read as `calsim
/// calibrate` reads it -> the device study's identification -> the held-out median at the
/// validation rows, over 10 seeds of the shipped plan (fewer poses and worlds): inside the plan's
/// P10-P90 (an 80 % band) in at least 5 of the 10 (fewer than 5 happen with probability 0.0064,
/// Binomial(10, 0.8)).
#[test]
fn a_trical_plan_simulate_identify_lands_inside_the_plans_p10_p90() {
    let dir = scratch("trical-round-trip");
    let mut inside = Vec::new();
    for seed in 1..=10u64 {
        let file = dir.join(format!("seed{seed}.toml"));
        let text = trical_text(|t| t.replace("seed = 2018", &format!("seed = {seed}")).replace("worlds = 30", "worlds = 20"));
        std::fs::write(&file, text).unwrap();
        let spec = PlanSpec { file, out: dir.join(format!("out{seed}")), threads: Some(2), simulate: true, recording: false };
        let r = calsim::app::plan::plan_device(&spec, &calsim::app::Quiet).unwrap();
        let path = r.dir.join("simulated.csv");
        let m = calsim::calibrate::measurements::read(&path, &r.plan.robot).unwrap();
        assert_eq!(m.points.len(), r.outcome.rows.len());
        // The file's joints are the planned configurations, its training points the true arm's
        // TCP within a few times the pool's observation error, its validation points exactly.
        let mut st = calsim::robot::KinState::default();
        for (p, row) in m.points.iter().zip(&r.outcome.rows) {
            let pose = &m.poses[p.pose];
            assert_eq!(pose.label, row.label);
            assert!((0..6).all(|i| (pose.q[i] - row.q[i]).abs() < 1e-12), "{}", row.label);
            let truth = calsim::robot::forward(&r.outcome.truth, &mut st, &row.q);
            let off = (truth - p.measured_mm).norm();
            match row.group {
                Some(_) => assert!(off < 6.0 * r.outcome.prediction.noise_mm, "{}: {off} mm", row.label),
                None => assert!(off < 1e-9, "{}: {off} mm", row.label),
            }
        }
        let stats = calsim::plan::device::identify_measured(&r.plan, &r.outcome, &m).unwrap().expect("a model");
        let measured = calsim::calibrate::plan::Statistic::Median.of_stats(&stats);
        let [p10, _, p90] = r.outcome.prediction.quantiles_mm;
        assert_eq!(r.outcome.prediction.worlds, 20);
        inside.push((seed, p10 <= measured && measured <= p90, measured, p10, p90));
    }
    let count = inside.iter().filter(|x| x.1).count();
    eprintln!("TriCal round trip: inside the plan's P10-P90 in {count} of 10 seeds: {inside:?}");
    assert!(count >= 5, "inside the plan's P10-P90 in {count} of 10 seeds: {inside:?}");
}

/// The shipped IRB 120 tracker plan (2 worlds: the tour does not depend on them): its straight
/// moves through a collision are re-routed through via configurations, and every move of
/// `tour.csv`, via paths included, is free at the stated step (1 deg of the joint that moves most)
/// by a computation here: the robot file's capsules and the SMRs on the modified-DH frames
/// computed here, against each other (as the feasibility test allows), the floor, the cabinet and
/// the tracker's head.
#[test]
fn the_tracker_tour_re_routes_its_colliding_moves_and_every_step_is_free_by_an_independent_computation() {
    let dir = scratch("tracker-tour");
    let file = shipped_short(&dir, "irb120_tracker.toml", |t| t.replace("worlds = 30", "worlds = 2"));
    let r =
        plan(&PlanSpec { file, out: dir.join("out"), threads: Some(2), simulate: false, recording: true }, &calsim::app::Quiet).unwrap();
    let o = &r.outcome;
    assert!(!o.colliding_moves.is_empty(), "the shipped tracker plan's tour has a straight move through a collision");
    assert!(o.routing.unrouted.is_empty(), "{:?}", o.routing.unrouted);
    assert_eq!(o.routing.vias.iter().map(|v| v.between).collect::<Vec<_>>(), o.colliding_moves);
    let targets = [Vector3::new(0.0, 0.0, 40.0), Vector3::new(40.0, 30.0, 30.0)];
    let free = irb120_cell_check(&targets, 38.1 / 2.0, "the floor", Some(Vector3::new(1800.0, 0.0, 300.0)));
    let stops = tour_stops(&r.dir, 3);
    let vias = stops.iter().filter(|s| s.1 == "via").count();
    assert_eq!(vias, o.routing.vias.iter().map(|v| v.qs.len()).sum::<usize>());
    assert_eq!(stops.len(), o.rows.len() + vias);
    assert!(!std::fs::read_to_string(r.dir.join("poses.csv")).unwrap().contains("via"), "a via configuration is not measured");
    // The straight moves the plan names collide here too, where they pass a body of this check.
    let mut seen_straight = 0;
    for (a, b) in &o.colliding_moves {
        let (qa, qb) = (o.rows[o.tour.0[*a]].q, o.rows[o.tour.0[*b]].q);
        let most = (0..6).map(|i| (qa[i] - qb[i]).abs()).fold(0.0, f64::max);
        let n = (most / 1f64.to_radians()).ceil() as usize;
        if (1..n).any(|s| free(&std::array::from_fn(|i| qa[i] + (qb[i] - qa[i]) * s as f64 / n as f64)).is_err()) {
            seen_straight += 1;
        }
    }
    assert!(seen_straight >= 1, "no straight colliding move seen colliding here");
    walk_tour(&stops, &free);
    // The recording draws the arm at every via configuration of tour.csv, and at every stop.
    let (drawn, robot_rows) = recorded_vias(&r.dir.join("plan.rrd"));
    assert_eq!(drawn, stops.iter().filter(|s| s.1 == "via").map(|s| s.0.clone()).collect::<Vec<_>>());
    assert_eq!(robot_rows, stops.len());
}

/// The shipped SPMS plan with its files named absolutely and `edit` applied to its text.
fn spms_text(edit: impl Fn(String) -> String) -> String {
    let t = std::fs::read_to_string(root().join("scenarios/plans/er20c10_spms.toml")).unwrap();
    let t = t
        .replace("\"../../robots/er20c10.toml\"", &format!("\"{}\"", root().join("robots/er20c10.toml").display()))
        .replace("\"../er20c10_spms.toml\"", &format!("\"{}\"", root().join("scenarios/er20c10_spms.toml").display()));
    edit(t)
}

/// The shipped SPMS plan (fewer worlds) run with 1 and with 2 threads, its measurements simulated.
fn spms_run() -> &'static DeviceRun {
    static RUN: OnceLock<DeviceRun> = OnceLock::new();
    RUN.get_or_init(|| device_run("spms", spms_text(|t| t.replace("worlds = 30", "worlds = 12")), true))
}

#[test]
fn an_spms_plan_writes_the_same_bytes_for_1_and_2_threads() {
    let r = spms_run();
    assert_eq!(r.files_1, r.files_2);
    let o = &r.report.outcome;
    assert_eq!(o.poses, 50);
    assert_eq!(o.rows.len(), 50 + 20);
    assert_eq!(o.candidates, 300);
    assert!(o.o1.0 > o.o1.1, "DETMAX's O1 {} above a random set's {}", o.o1.0, o.o1.1);
    let p = &o.prediction;
    assert!(p.quantiles_mm[0] <= p.quantiles_mm[1] && p.quantiles_mm[1] <= p.quantiles_mm[2], "{:?}", p.quantiles_mm);
    assert_eq!(plan_md_equals_its_stored_tables(&r.report.dir), 1);
    let md = std::fs::read_to_string(r.report.dir.join("plan.md")).unwrap();
    assert!(md.contains("the SPMS head") && !md.contains("TriCal"), "{md}");
    let (drawn, robot_rows) = recorded_vias(&r.report.dir.join("plan.rrd"));
    assert_eq!(robot_rows, tour_stops(&r.report.dir, 4).len());
    assert_eq!(drawn.len(), o.routing.vias.iter().map(|v| v.qs.len()).sum::<usize>());
}

/// Every configuration of the shipped SPMS plan, by a computation here: within the plan's joint
/// limits; the sphere on the flange (the scenario's [40, 0, 150] mm) at the modified-DH frames of
/// robots/er20c10.toml computed here, in each station's head placed as the scenario's stations
/// face the robot (head +y back towards the base axis, the convergence point [52, 180, 132] mm of
/// the head on the station's point); the flange's axis within the 40 deg approach cone of the
/// line to the head; a station's spheres within its travel (+-2, 15, 2 mm per head axis) of each
/// other; the five beams of the paper's Table 2 meeting the sphere (50.8143 mm) at distances within
/// the sensors' 75-130 mm range, the station's spheres taken about the convergence point (its
/// teaching, by what the head reads, moves the commanded point by the station's placement error
/// and the arm's error there, which the nominal arm and placement here do not see); the validation
/// configurations' sphere inside the workspace of interest.
#[test]
fn every_spms_pose_is_within_its_stations_range_by_an_independent_computation() {
    let r = spms_run();
    let robot: toml::Table = std::fs::read_to_string(root().join("robots/er20c10.toml")).unwrap().parse().unwrap();
    let joints = robot["joint"].as_array().unwrap();
    let limits = [[-170.0, 170.0], [-90.0, 150.0], [-80.0, 170.0], [-180.0, 180.0], [-125.0, 125.0], [-360.0, 360.0]];
    let stations: [Vector3<f64>; 3] = [[1200.0, -400.0, 500.0], [1200.0, 400.0, 500.0], [900.0, 0.0, 1100.0]].map(Vector3::from);
    let c_head = Vector3::new(52.0, 180.0, 132.0);
    let travel = Vector3::new(2.0, 15.0, 2.0);
    let sphere_flange = Vector3::new(40.0, 0.0, 150.0);
    let (w_lo, w_hi) = (Vector3::new(800.0, -200.0, 600.0), Vector3::new(1200.0, 200.0, 1000.0));
    let csv = std::fs::read_to_string(r.report.dir.join("poses.csv")).unwrap();
    let (mut holdout, mut in_head) = (0, vec![Vec::new(); 3]);
    for line in csv.lines().filter(|l| !l.starts_with('#') && !l.starts_with("pose,")) {
        let f: Vec<&str> = line.split(',').collect();
        let q: [f64; 6] = std::array::from_fn(|i| f[4 + i].parse::<f64>().unwrap().to_radians());
        for i in 0..6 {
            let d = q[i].to_degrees();
            assert!(d >= limits[i][0] - 1e-9 && d <= limits[i][1] + 1e-9, "{line}: joint {}", i + 1);
        }
        let fr = frames(joints, &q);
        let sphere = fr[6].1 + fr[6].0 * sphere_flange;
        if f[3] == "holdout" {
            assert!(point_box(&sphere, &w_lo, &w_hi) < 0.01, "{line}: the sphere {sphere:?} outside the workspace of interest");
            holdout += 1;
            continue;
        }
        let k: usize = f[0].rsplit("_s").next().unwrap().parse::<usize>().unwrap() - 1;
        let p = stations[k];
        let rot = Rotation3::from_axis_angle(&Vector3::z_axis(), p.x.atan2(-p.y));
        let cone = fr[6].0.column(2).angle(&(rot * -Vector3::y())).to_degrees();
        assert!(cone <= 40.0 + 1e-6, "{line}: the flange's axis {cone} deg from the line to the head");
        in_head[k].push((f[0].to_string(), rot.inverse() * (sphere - (p - rot * c_head))));
    }
    assert_eq!(holdout, 20);
    assert_eq!(in_head.iter().map(Vec::len).sum::<usize>(), 50);
    let mut readings: Vec<f64> = Vec::new();
    for (k, spheres) in in_head.iter().enumerate() {
        assert!(!spheres.is_empty(), "station {}: no configuration", k + 1);
        let lo = spheres.iter().fold(Vector3::repeat(f64::INFINITY), |a, s| a.inf(&s.1));
        let hi = spheres.iter().fold(Vector3::repeat(f64::NEG_INFINITY), |a, s| a.sup(&s.1));
        // Within the travel of each other, up to the nominal arm's pose-dependent error (1 mm).
        assert!((hi - lo).iter().zip(travel.iter()).all(|(d, t)| *d <= 2.0 * t + 1.0), "station {}: spread {:?}", k + 1, hi - lo);
        let taught = (lo + hi) / 2.0 - c_head;
        for (label, s) in spheres {
            readings.extend(spms_readings(&(s - taught)).unwrap_or_else(|| panic!("{label}: a beam misses the sphere")));
        }
    }
    let (lo, hi) = readings.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), l| (a.min(*l), b.max(*l)));
    eprintln!("SPMS plan: the beams read {lo:.2}-{hi:.2} mm at the planned configurations");
    assert!(lo >= 75.0 && hi <= 130.0, "readings {lo}-{hi} mm outside the sensors' 75-130 mm");
}

/// The distances along the paper's Table 2 beams (head frame) to a 50.8143 mm sphere centred at
/// `c` (`None`: a beam misses it).
fn spms_readings(c: &Vector3<f64>) -> Option<Vec<f64>> {
    let beams: [([f64; 3], [f64; 3]); 5] = [
        ([74.420, 67.247, 97.126], [-0.104, 0.976, 0.189]),
        ([11.612, 69.074, 146.755], [0.210, 0.975, -0.069]),
        ([92.918, 67.986, 142.254], [-0.190, 0.981, -0.031]),
        ([52.951, 69.811, 175.249], [0.018, 0.981, -0.194]),
        ([25.346, 70.181, 97.548], [0.143, 0.982, 0.124]),
    ];
    let radius = 50.8143 / 2.0;
    beams
        .iter()
        .map(|(point, dir)| {
            let (a, u) = (Vector3::from(*point), Vector3::from(*dir).normalize());
            let m = a - c;
            let b = m.dot(&u);
            let disc = b * b - (m.norm_squared() - radius * radius);
            (disc > 0.0).then(|| -b - disc.sqrt())
        })
        .collect()
}
