//! Times `calibrate::run` and `calibrate::twin::analyse` on a simulated file written to `$1`: the
//! shipped example's arm, sessions and 2 targets, 450 random poses and 50 repeats per session
//! (3,000 points), or `$2` random poses per session and no repeats (`$2` 23340: 140,040 points).
//! With `$3`, the arm's link angles also carry a smooth per-pose field of 20 mdeg per joint and
//! that length, rad (drawn as a world draws `[learned]` `pose_error_length_rad`), which the twin
//! fits a length and level to (with their bootstrap); `$2` 500 with it: 3,000 points.
//!
//! `cargo run --release --example twin_timing -- FILE [POSES_PER_SESSION [LENGTH_RAD]]`, from the
//! repository root.
use std::time::Instant;

use rand::SeedableRng;

fn main() -> std::process::ExitCode {
    // Bad input: one line, `error: ...`, exit 2, as calsim's commands.
    calsim::app::message::exit_code(run())
}

fn run() -> Result<(), String> {
    let out = std::path::PathBuf::from(std::env::args().nth(1).ok_or("usage: twin_timing <file.csv> [poses per session [length, rad]]")?);
    let robot = calsim::robot::file::RobotFile::load(std::path::Path::new("robots/irb120.toml")).map_err(|e| e.to_string())?;
    // Bounds: the measurement reader's 1,000,000 rows (3 sessions x 2 targets per pose); a field
    // length within the lengths the twin profiles (0.02-20 rad).
    let poses = match std::env::args().nth(2) {
        None => None,
        Some(a) => Some(
            a.parse::<usize>()
                .ok()
                .filter(|v| (1..=150_000).contains(v))
                .ok_or(format!("poses per session: {a} is not a whole number from 1 to 150000"))?,
        ),
    };
    let length = match std::env::args().nth(3) {
        None => None,
        Some(a) => Some(
            a.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite() && (0.02..=20.0).contains(v))
                .ok_or(format!("length: {a} is not a number from 0.02 to 20 rad"))?,
        ),
    };
    let spec = calsim::calibrate::simulate::SimulationSpec {
        poses_per_session: poses.unwrap_or(450),
        repeats_per_session: if poses.is_some() { 0 } else { 50 },
        outliers: vec![],
        ..calsim::calibrate::simulate::example_spec(&robot)?
    };
    let text = match length {
        None => calsim::calibrate::simulate::to_csv(&spec).map_err(|e| e.to_string())?,
        Some(l) => {
            let field = calsim::robot::LearnedEffects { pose_error_mdeg: 20.0, pose_error_length_rad: l, ..Default::default() };
            let drawn = field.draw(&spec.truth, &mut rand_chacha::ChaCha8Rng::seed_from_u64(spec.seed));
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(spec.seed);
            calsim::calibrate::simulate::joint_error_csv(&spec, &mut rng, |q, _| drawn.joint_errors(q, q))
        }
    };
    // A file that exists is not replaced.
    let mut file = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&out)
        .map_err(|e| format!("{}: {e} (an existing file is not replaced)", out.display()))?;
    std::io::Write::write_all(&mut file, text.as_bytes()).map_err(|e| format!("{}: {e}", out.display()))?;
    let m = calsim::calibrate::measurements::read(&out, &robot).map_err(|e| e.to_string())?;
    let opts = calsim::calibrate::Options { plots: false, ..Default::default() };
    let t0 = Instant::now();
    let c = calsim::calibrate::run(&robot, &m, &opts).map_err(|e| e.to_string())?;
    let t1 = Instant::now();
    let t = calsim::calibrate::twin::analyse(&c, None).map_err(|e| e.to_string())?;
    let t2 = Instant::now();
    println!(
        "{} points: calibrate::run {:.3} s, twin::analyse {:.3} s; {} families kept; smooth field: {}",
        m.points.len(),
        (t1 - t0).as_secs_f64(),
        (t2 - t1).as_secs_f64(),
        t.families.iter().filter(|f| f.kept).count(),
        t.length.as_ref().map_or("none fitted".to_string(), |s| format!(
            "length {:.2} rad, level {:.2} mdeg",
            s.length_rad,
            s.level_rad[0].to_degrees() * 1e3
        ))
    );
    Ok(())
}
