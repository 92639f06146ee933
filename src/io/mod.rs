//! The kit under everything that reads or writes files: bounded reading of inputs (here; every
//! input calsim reads goes through [`read_text`], [`read_bytes`] or [`read_bytes_at_most`], a test
//! keeps it so), the shape of an XML input checked before it is parsed (`xml`), the names calsim
//! makes directories from (`names`), the atomic results directory and the vetting of output paths
//! (`out_dir`: the one writer and its safety rule), parquet tables and their hashes (`table`), TOML
//! read into calsim's types with every array held to its length (`toml_de`), the ledger of the
//! files a command read (`inputs`), the provenance block of every manifest (`manifest`), the plot
//! kit (`plot`) and the recording kit (`record`). It computes no figure and imports no device,
//! study, sweep or budget: each producer computes its own figures and renders them through it.

pub mod inputs;
pub mod manifest;
pub mod names;
pub mod out_dir;
pub mod plot;
pub mod record;
pub mod results;
pub mod table;
pub mod toml_de;
pub mod xml;

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

/// Where a TOML parse error points, for a one-line message: `line N` of the error's byte range,
/// with the key assigned on that line and its table (`line 35, [study] repetitions`) when the line
/// assigns one; `(file)` when the error has no range.
pub fn toml_position(text: &str, span: Option<std::ops::Range<usize>>) -> String {
    let Some(span) = span else { return "(file)".into() };
    let before = text.get(..span.start).unwrap_or(text);
    let line = before.matches('\n').count() + 1;
    let key = text.lines().nth(line - 1).and_then(|l| assigned_key(l.split('#').next().unwrap_or("")));
    let table = text.lines().take(line - 1).filter_map(|l| table_header(l.trim())).last();
    match (key, table) {
        (Some(k), Some(t)) => format!("line {line}, [{t}] {k}"),
        (Some(k), None) => format!("line {line}, {k}"),
        _ => format!("line {line}"),
    }
}

/// A TOML key as written: bare, dotted or quoted.
fn is_key(key: &str) -> bool {
    !key.is_empty() && key.chars().all(|c| c.is_ascii_alphanumeric() || "_-.\" '".contains(c))
}

/// The key a TOML line assigns (`key = ...`).
fn assigned_key(line: &str) -> Option<&str> {
    let (key, _) = line.split_once('=')?;
    let key = key.trim();
    is_key(key).then_some(key)
}

/// The table a header line opens (`[cell]`, `[[session]]`); none for an array's row (`[1, 2],`).
fn table_header(line: &str) -> Option<&str> {
    let line = line.split('#').next().unwrap_or("").trim();
    let inner = line.strip_prefix("[[").and_then(|l| l.strip_suffix("]]"));
    let inner = inner.or_else(|| line.strip_prefix('[').and_then(|l| l.strip_suffix(']')))?.trim();
    is_key(inner).then_some(inner)
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
    read_bytes_at_most(path, MOST_INPUT_BYTES)
}

/// Most bytes of a result table read back (a `tasks.parquet` of the most identifications a study
/// may have is far smaller).
pub const MOST_TABLE_BYTES: u64 = 1 << 30;

/// Most bytes of a CSV input of `calsim fk` (joints) and `calsim compensate` (targets), and of a
/// mesh: a million rows of six values with room to spare.
pub const MOST_CSV_BYTES: u64 = 256 << 20;

/// The 1-based lines of positions in one text, asked in increasing order (a reader's records):
/// each answer counts the line breaks since the last, so that a file's lines cost one pass over
/// it, however many records it has (a position before the last one asked is counted from the
/// start again).
#[derive(Debug, Default)]
pub struct Lines {
    /// The byte counted up to.
    at: usize,
    /// Line breaks before `at`.
    breaks: u64,
}

impl Lines {
    /// The line at which a record starting at byte `pos` of `bytes` lies. After a CRLF a reader's
    /// record offset can point at the line break before the record: line breaks are skipped.
    pub fn line_at(&mut self, bytes: &[u8], pos: u64) -> u64 {
        let mut start = (pos as usize).min(bytes.len());
        while start < bytes.len() && matches!(bytes[start], b'\r' | b'\n') {
            start += 1;
        }
        if start < self.at {
            *self = Self::default();
        }
        self.breaks += bytes[self.at..start].iter().filter(|b| **b == b'\n').count() as u64;
        self.at = start;
        1 + self.breaks
    }
}

/// The bytes of an input file of at most `most` bytes (a CSV of a million rows, a mesh, a result
/// table), checked by [`check_input`] and read no further than that.
pub fn read_bytes_at_most(path: &Path, most: u64) -> std::io::Result<Vec<u8>> {
    let bytes = read_own(path, most)?;
    inputs::record(path, &bytes);
    Ok(bytes)
}

/// The bytes of a file calsim wrote and reads back as its own (a results directory's manifest
/// when it decides whether it may replace it, the tables it hashes): checked as for
/// [`read_bytes_at_most`] but not recorded as an input of the command ([`inputs`]).
pub(crate) fn read_own(path: &Path, most: u64) -> std::io::Result<Vec<u8>> {
    check_input(path, Some(most))?;
    let mut bytes = Vec::new();
    std::fs::File::open(path)?.take(most + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > most {
        return Err(too_large(most));
    }
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::toml_position;

    /// The position of the error toml itself reports for `text`.
    fn at(text: &str) -> String {
        let e = toml::from_str::<toml::Table>(text).map(|_| ()).expect_err("the text is not valid TOML");
        toml_position(text, e.span())
    }

    #[test]
    fn a_toml_error_names_its_line_and_the_key_assigned_there() {
        let text = "seed = 1\n\n[study]\n# a comment\nrepetitions = 99999999999999999999  # too large\n";
        assert_eq!(at(text), "line 5, [study] repetitions");
        assert_eq!(at("a = 1\nb = \n"), "line 2, b");
        assert_eq!(at("[[session]]\nname = \"A\"\n\"quoted key\" = [1, \n"), "line 3, [session] \"quoted key\"");
        // A row of a multi-line array is not a table header; a line assigning nothing gives its number.
        assert_eq!(at("[cell]\nxs = [\n  [1, 2]\n]\ny = \n"), "line 5, [cell] y");
        assert_eq!(at("[cell]\nxs = [\n  [1, 2]\n]\n]\n"), "line 5");
        assert_eq!(toml_position("a = 1", None), "(file)");
    }

    #[test]
    fn an_error_at_the_start_of_a_line_is_on_that_line() {
        let text = "a = 1\nb = 2\n";
        let start = text.find('b').unwrap();
        assert_eq!(toml_position(text, Some(start..start + 1)), "line 2, b");
    }
}
