//! The kit under everything that reads or writes files: bounded reading of inputs, the atomic
//! results directory (`out_dir`), parquet tables and their hashes (`table`), the provenance of a
//! manifest (`manifest`), the plot kit (`plot`) and the recording kit (`record`). It computes no
//! figure and imports no device, study, sweep or budget: each producer computes its own figures
//! and renders them through it.

pub mod manifest;
pub mod out_dir;
pub mod plot;
pub mod record;
pub mod table;

use std::io::Read;
use std::path::Path;

/// Most bytes of a text input (scenario, robot, sweep, URDF and result-directory files): far above
/// any real one (the largest shipped is under 20 KB), low enough that reading and parsing one
/// takes a moment.
pub const MOST_INPUT_BYTES: u64 = 16 << 20;

/// Refuses what is not a regular file (a pipe, socket or device could block a read forever or
/// never end) and, with `most`, a file of more than `most` bytes. Directories pass on to the read,
/// which names them.
pub fn check_input(path: &Path, most: Option<u64>) -> std::io::Result<()> {
    let meta = std::fs::metadata(path)?;
    if !meta.is_file() && !meta.is_dir() {
        return Err(std::io::Error::other("not a regular file (a pipe, socket or device): calsim reads its inputs from files"));
    }
    match most {
        Some(most) if meta.len() > most => Err(too_large(most)),
        _ => Ok(()),
    }
}

fn too_large(most: u64) -> std::io::Error {
    std::io::Error::other(format!("larger than {} MiB, the most an input file may have", most >> 20))
}

/// The text of an input file, checked by [`check_input`] with [`MOST_INPUT_BYTES`] (and read no
/// further than that, should the file grow meanwhile).
pub fn read_text(path: &Path) -> std::io::Result<String> {
    String::from_utf8(read_bytes(path)?)
        .map_err(|_| std::io::Error::new(std::io::ErrorKind::InvalidData, "stream did not contain valid UTF-8"))
}

/// The bytes of an input file, checked as for [`read_text`].
pub fn read_bytes(path: &Path) -> std::io::Result<Vec<u8>> {
    check_input(path, Some(MOST_INPUT_BYTES))?;
    let mut bytes = Vec::new();
    std::fs::File::open(path)?.take(MOST_INPUT_BYTES + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > MOST_INPUT_BYTES {
        return Err(too_large(MOST_INPUT_BYTES));
    }
    Ok(bytes)
}
