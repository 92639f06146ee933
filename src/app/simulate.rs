//! `simulate-measurements`: a measurement file for `calibrate`, simulated from a simulation file
//! (a robot file's truth measured at random poses with an instrument's noise; docs/calibrate.md).

use std::path::{Path, PathBuf};

use super::Error;
use crate::calibrate::simulate::{measurement_file, read_spec};
use crate::io::table::Frame;

/// What `simulate-measurements` made.
#[derive(Clone, Debug)]
pub struct Simulated {
    /// The measurement table, a row per target measured at a pose (columns in
    /// [`crate::calibrate::measurements::file::measurement_file`]).
    pub table: Frame,
    /// The measurement file's text (the `calibrate` CSV layout): its `#` header lines, then the
    /// table.
    pub csv: String,
    /// Data rows (one per target measured at a pose).
    pub rows: usize,
    /// The file written (`<out>/<spec stem>.csv`), when a directory was given.
    pub written: Option<PathBuf>,
}

/// `simulate-measurements`: reads the simulation file `spec` and simulates its measurements; with
/// `out`, writes them to `<out>/<spec stem>.csv` (the directory created; an existing file is
/// refused, not replaced; the file appears whole or not at all).
pub fn run(spec: &Path, out: Option<&Path>) -> Result<Simulated, Error> {
    let _inputs = crate::io::inputs::Ledger::open();
    let stem = crate::io::names::of_file(spec)?;
    let s = read_spec(spec).map_err(|e| spec_error(spec, &e))?;
    let (table, csv) = measurement_file(&s.spec, s.orientation.as_ref()).map_err(Error::io(spec))?;
    let rows = table.height();
    let written = match out {
        Some(out) => {
            std::fs::create_dir_all(out).map_err(|e| Error::input(format!("{}: --out", out.display()), e.to_string()))?;
            let path = out.join(format!("{stem}.csv"));
            crate::io::out_dir::vet_file(&path, &[spec])?;
            crate::io::out_dir::write_output_file("--out", &path, csv.as_bytes())?;
            Some(path)
        }
        None => None,
    };
    Ok(Simulated { table, csv, rows, written })
}

/// The simulation file's one-line error (`<file>: <key>: <what is wrong>`) as an input error naming
/// the file and the key.
fn spec_error(spec: &Path, line: &str) -> Error {
    let rest = line.strip_prefix(&format!("{}: ", spec.display())).unwrap_or(line);
    match rest.split_once(": ") {
        Some((key, why)) if !key.contains(' ') || key.starts_with("line ") || key == "(file)" => {
            Error::input(format!("{}: {key}", spec.display()), why)
        }
        _ => Error::input(spec.display().to_string(), rest),
    }
}
