//! Writes the shipped example measurement file of `calsim calibrate`
//! (`docs/calibrate/example_measurements.csv`, simulated: see its header) from
//! `calsim::calibrate::simulate::example_spec`.

use std::path::Path;

fn main() -> std::process::ExitCode {
    // Bad input: one line, `error: ...`, exit 2, as calsim's commands.
    calsim::app::message::exit_code(run())
}

fn run() -> Result<(), String> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let robot = calsim::robot::file::RobotFile::load(&root.join("robots/irb120.toml")).map_err(|e| e.to_string())?;
    let spec = calsim::calibrate::simulate::example_spec(&robot)?;
    let out = root.join("docs/calibrate/example_measurements.csv");
    std::fs::create_dir_all(out.parent().expect("a parent")).map_err(|e| e.to_string())?;
    let text = calsim::calibrate::simulate::to_csv(&spec).map_err(|e| format!("{}: {e}", out.display()))?;
    std::fs::write(&out, text).map_err(|e| format!("{}: {e}", out.display()))?;
    println!("wrote {}", out.display());
    Ok(())
}
