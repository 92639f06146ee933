//! Result tables: parquet files written through polars, and the sha256 of every table of a
//! results directory (tables carry no wall-clock value, so equal hashes mean equal results).

use std::fs;
use std::path::Path;

use polars::prelude::{Column, DataFrame, ParquetWriter};
use sha2::{Digest, Sha256};

/// An error of the table library as an I/O error.
pub fn err(e: impl std::fmt::Display) -> std::io::Error {
    std::io::Error::other(e.to_string())
}

/// Writes `columns` as the parquet table `dir/name`.
pub fn parquet(dir: &Path, name: &str, columns: Vec<Column>) -> std::io::Result<()> {
    let mut df = DataFrame::new_infer_height(columns).map_err(err)?;
    let file = fs::File::create(dir.join(name))?;
    ParquetWriter::new(file).finish(&mut df).map_err(err)?;
    Ok(())
}

/// The sha256 of every result table (`*.parquet`) in `dir`, by file name: two runs gave the same
/// results when these agree (the tables carry no wall-clock value).
pub fn table_hashes(dir: &Path) -> std::io::Result<std::collections::BTreeMap<String, String>> {
    let mut out = std::collections::BTreeMap::new();
    for entry in fs::read_dir(dir)? {
        let path = entry?.path();
        if path.extension().is_some_and(|e| e == "parquet") {
            let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            out.insert(name, format!("{:x}", Sha256::digest(fs::read(&path)?)));
        }
    }
    Ok(out)
}

