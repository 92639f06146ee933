//! Times `calibrate::run` and `calibrate::twin::analyse` on a simulated 3,000-point file (the
//! shipped example's arm and sessions, 500 poses per session, 2 targets) written to `$1`.
use std::time::Instant;

fn main() -> std::process::ExitCode {
    // Bad input: one line, `error: ...`, exit 2, as calsim's commands.
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", calsim::app::message::one_line(&e));
            std::process::ExitCode::from(2)
        }
    }
}

fn run() -> Result<(), String> {
    let out = std::path::PathBuf::from(std::env::args().nth(1).ok_or("usage: twin_timing <file.csv>")?);
    let robot = calsim::robot::file::RobotFile::load(std::path::Path::new("robots/irb120.toml")).map_err(|e| e.to_string())?;
    let spec = calsim::calibrate::simulate::SimulationSpec {
        poses_per_session: 450,
        repeats_per_session: 50,
        outliers: vec![],
        ..calsim::calibrate::simulate::example_spec(&robot)?
    };
    std::fs::write(&out, calsim::calibrate::simulate::to_csv(&spec).map_err(|e| e.to_string())?).map_err(|e| e.to_string())?;
    let m = calsim::calibrate::measurements::read(&out, &robot).map_err(|e| e.to_string())?;
    let opts = calsim::calibrate::Options { plots: false, ..Default::default() };
    let t0 = Instant::now();
    let c = calsim::calibrate::run(&robot, &m, &opts).map_err(|e| e.to_string())?;
    let t1 = Instant::now();
    let t = calsim::calibrate::twin::analyse(&c, None).map_err(|e| e.to_string())?;
    let t2 = Instant::now();
    println!(
        "{} points: calibrate::run {:.3} s, twin::analyse {:.3} s; {} families kept",
        m.points.len(),
        (t1 - t0).as_secs_f64(),
        (t2 - t1).as_secs_f64(),
        t.families.iter().filter(|f| f.kept).count()
    );
    Ok(())
}
