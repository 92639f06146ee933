//! Result tables: parquet files written through polars, and the sha256 of every table of a
//! results directory (tables carry no wall-clock value, so equal hashes mean equal results).

use std::fs;
use std::path::Path;

use polars::prelude::{AnyValue, Column, DataFrame, ParquetWriter};
use sha2::{Digest, Sha256};

/// A result table in memory.
pub type Frame = DataFrame;

/// An error of the table library as an I/O error.
pub fn err(e: impl std::fmt::Display) -> std::io::Error {
    std::io::Error::other(e.to_string())
}

/// Writes `columns` as the parquet table `dir/name`; an error names the table (and the column,
/// for two columns of one name).
pub fn parquet(dir: &Path, name: &str, columns: Vec<Column>) -> std::io::Result<()> {
    write_frame(dir, name, frame(name, columns)?)
}

/// The frame of the table `name` from its columns; an error names the table (and the column, for
/// two columns of one name, or columns of different lengths).
pub fn frame(name: &str, columns: Vec<Column>) -> std::io::Result<DataFrame> {
    let in_table = |e: &dyn std::fmt::Display| std::io::Error::other(format!("{name}: {e}"));
    let mut seen = std::collections::HashSet::new();
    if let Some(twice) = columns.iter().map(|c| c.name().as_str()).find(|n| !seen.insert(*n)) {
        return Err(in_table(&format!("two columns named `{twice}`")));
    }
    DataFrame::new_infer_height(columns).map_err(|e| in_table(&e))
}

/// How [`csv_text`] writes the fields of one column: the text of a null, and the notation of a
/// float.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FieldFormat {
    /// The text of a null field.
    pub null: &'static str,
    /// The notation of a float.
    pub notation: Notation,
}

/// The notation [`csv_text`] writes a float in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Notation {
    /// Rust's shortest decimal that reads back to the same bits (`{}`: `1500000`, `0.3`).
    Shortest,
    /// Rust's shortest scientific notation that reads back to the same bits (`{:e}`: `1.5e6`,
    /// `3e-1`).
    Scientific,
    /// This many decimals (`{:.N}`: `0.300000`); the value the text states is [`rounded`]'s.
    Fixed(usize),
}

impl FieldFormat {
    /// Floats in the shortest decimal, a null written as the text `null` given.
    pub const fn decimal(null: &'static str) -> Self {
        Self { null, notation: Notation::Shortest }
    }

    /// Floats in the shortest scientific notation, a null written as the text `null` given.
    pub const fn scientific(null: &'static str) -> Self {
        Self { null, notation: Notation::Scientific }
    }

    /// Floats with `decimals` decimals, a null written as the text `null` given.
    pub const fn fixed(null: &'static str, decimals: usize) -> Self {
        Self { null, notation: Notation::Fixed(decimals) }
    }
}

/// `v` rounded to `decimals` decimals: the value its text with that many decimals reads back as
/// (that text again when written with as many), so that a frame holds what its CSV states.
pub fn rounded(v: f64, decimals: usize) -> f64 {
    format!("{v:.decimals$}").parse().unwrap_or(v)
}

/// The CSV layout of a frame, passed beside it to [`csv_text`]: one [`FieldFormat`] for every
/// column, and columns named with formats of their own.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CsvFormat {
    every: FieldFormat,
    columns: Vec<(String, FieldFormat)>,
}

impl CsvFormat {
    /// Every column in `every`.
    pub fn new(every: FieldFormat) -> Self {
        Self { every, columns: Vec::new() }
    }

    /// `self` with the columns `names` in `format`.
    pub fn with<S: Into<String>>(mut self, names: impl IntoIterator<Item = S>, format: FieldFormat) -> Self {
        self.columns.extend(names.into_iter().map(|n| (n.into(), format)));
        self
    }

    /// The format of the column `name`.
    fn of(&self, name: &str) -> FieldFormat {
        self.columns.iter().rev().find(|(n, _)| n == name).map_or(self.every, |(_, f)| *f)
    }
}

/// The CSV text of `frame` laid out by `format`: a header line of its column names, then a line
/// per row; a float is written in its column's [`Notation`], a boolean `true`/`false`, a null as its column's null text, a string as
/// itself, quoted as RFC 4180 asks when it holds a comma, a double quote or a line break (the
/// frame's column types decide every field; the format names no column the frame lacks). A column
/// name is quoted by the same rule.
pub fn csv_text(frame: &DataFrame, format: &CsvFormat) -> std::io::Result<String> {
    if let Some((name, _)) = format.columns.iter().find(|(n, _)| frame.column(n).is_err()) {
        return Err(err(format!("the CSV format names the column `{name}`, which the table does not have")));
    }
    let fields: Vec<Vec<String>> =
        frame.columns().iter().map(|c| column_text(c, format.of(c.name().as_str()))).collect::<std::io::Result<_>>()?;
    let mut out = frame.get_column_names().iter().map(|n| quoted(n.as_str())).collect::<Vec<_>>().join(",");
    out.push('\n');
    for row in 0..frame.height() {
        let line: Vec<&str> = fields.iter().map(|f| f[row].as_str()).collect();
        out.push_str(&line.join(","));
        out.push('\n');
    }
    Ok(out)
}

/// Each field of `column` as CSV text in `format` (see [`csv_text`]).
fn column_text(column: &Column, format: FieldFormat) -> std::io::Result<Vec<String>> {
    let column = column.as_materialized_series();
    (0..column.len())
        .map(|i| match column.get(i).map_err(err)? {
            AnyValue::Null => Ok(format.null.to_string()),
            AnyValue::Float64(v) => Ok(match format.notation {
                Notation::Shortest => format!("{v}"),
                Notation::Scientific => format!("{v:e}"),
                Notation::Fixed(decimals) => format!("{v:.decimals$}"),
            }),
            AnyValue::Boolean(v) => Ok(v.to_string()),
            AnyValue::String(v) => Ok(quoted(v)),
            AnyValue::Int64(v) => Ok(v.to_string()),
            AnyValue::UInt32(v) => Ok(v.to_string()),
            AnyValue::UInt64(v) => Ok(v.to_string()),
            other => Err(err(format!("column `{}`: no CSV text for {}", column.name(), other.dtype()))),
        })
        .collect()
}

/// `field` as one CSV field (RFC 4180): as itself, or between double quotes with each double quote
/// doubled when it holds a comma, a double quote, a carriage return or a line feed.
fn quoted(field: &str) -> String {
    if field.contains([',', '"', '\r', '\n']) { format!("\"{}\"", field.replace('"', "\"\"")) } else { field.to_string() }
}

/// Writes `frame` as the parquet table `dir/name`.
pub fn write_frame(dir: &Path, name: &str, frame: DataFrame) -> std::io::Result<()> {
    // Encoded in memory and written in one go, so that a write error is the file system's own
    // (`No space left on device`), naming the table.
    crate::io::out_dir::write_file(&dir.join(name), parquet_bytes(name, frame)?)
}

/// The parquet encoding of the table `name` (the bytes of its file).
pub fn parquet_bytes(name: &str, mut frame: DataFrame) -> std::io::Result<Vec<u8>> {
    let mut bytes = Vec::new();
    ParquetWriter::new(&mut bytes).finish(&mut frame).map_err(|e| std::io::Error::other(format!("{name}: {e}")))?;
    Ok(bytes)
}

/// The sha256 of every result table (`*.parquet`) in `dir`, by file name: two runs gave the same
/// results when these agree (the tables carry no wall-clock value).
pub fn table_hashes(dir: &Path) -> std::io::Result<std::collections::BTreeMap<String, String>> {
    let mut out = std::collections::BTreeMap::new();
    for entry in fs::read_dir(dir)? {
        let path = entry?.path();
        if path.extension().is_some_and(|e| e == "parquet") {
            let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            let bytes = crate::io::read_own(&path, crate::io::MOST_TABLE_BYTES).map_err(crate::io::out_dir::named(&path))?;
            out.insert(name, format!("{:x}", Sha256::digest(bytes)));
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use polars::prelude::Column;

    use super::{CsvFormat, FieldFormat, csv_text, frame, rounded};

    #[test]
    fn csv_text_writes_each_field_by_its_column_type() {
        let columns = vec![
            Column::new("x".into(), [0.1 + 0.2, -0.0, 1.5e6]),
            Column::new("n".into(), [Some(3_i64), None, Some(-7)]),
            Column::new("ok".into(), [true, false, true]),
            Column::new("s".into(), ["a", "b c", ""]),
        ];
        let text = csv_text(&frame("t", columns).unwrap(), &CsvFormat::new(FieldFormat::decimal("null"))).unwrap();
        assert_eq!(text, "x,n,ok,s\n0.30000000000000004,3,true,a\n-0,null,false,b c\n1500000,-7,true,\n");
        // Every float reads back to the bits it was written from.
        let field: f64 = text.lines().nth(1).unwrap().split(',').next().unwrap().parse().unwrap();
        assert_eq!(field.to_bits(), (0.1_f64 + 0.2).to_bits());
    }

    #[test]
    fn csv_text_quotes_a_string_holding_a_comma_quote_or_line_break() {
        let strings = ["plain", "a,b", "say \"hi\"", "two\nlines", "cr\r", ""];
        let columns = vec![Column::new("s".into(), strings), Column::new("n,m".into(), [1_i64, 2, 3, 4, 5, 6])];
        let table = frame("t", columns).unwrap();
        let text = csv_text(&table, &CsvFormat::new(FieldFormat::decimal("null"))).unwrap();
        assert_eq!(text, "s,\"n,m\"\nplain,1\n\"a,b\",2\n\"say \"\"hi\"\"\",3\n\"two\nlines\",4\n\"cr\r\",5\n,6\n");
        // An RFC 4180 reader gives back the header and every string as it was.
        let mut reader = csv::Reader::from_reader(text.as_bytes());
        assert_eq!(reader.headers().unwrap().iter().collect::<Vec<_>>(), ["s", "n,m"]);
        let back: Vec<String> = reader.records().map(|r| r.unwrap()[0].to_string()).collect();
        assert_eq!(back, strings);
    }

    #[test]
    fn csv_text_names_a_column_it_cannot_write() {
        let columns = vec![Column::new("day".into(), [1_i32, 2])];
        let e = csv_text(&frame("t", columns).unwrap(), &CsvFormat::new(FieldFormat::decimal(""))).unwrap_err();
        assert!(e.to_string().contains("column `day`"), "{e}");
    }

    #[test]
    fn csv_text_writes_each_column_in_its_own_format() {
        let columns = vec![
            Column::new("q".into(), [Some(1.5), None, Some(-0.0)]),
            Column::new("e".into(), [1.5e-9, f64::NAN, 0.1 + 0.2]),
            Column::new("n".into(), [None, Some(2.0), None]),
        ];
        let format = CsvFormat::new(FieldFormat::decimal(""))
            .with(["q"], FieldFormat::decimal("unreachable"))
            .with(["e"], FieldFormat::scientific(""));
        let text = csv_text(&frame("t", columns).unwrap(), &format).unwrap();
        assert_eq!(text, "q,e,n\n1.5,1.5e-9,\nunreachable,NaN,2\n-0,3.0000000000000004e-1,\n");
        // A float in scientific notation reads back to the bits it was written from.
        let field: f64 = text.lines().nth(3).unwrap().split(',').nth(1).unwrap().parse().unwrap();
        assert_eq!(field.to_bits(), (0.1_f64 + 0.2).to_bits());
    }

    #[test]
    fn csv_text_refuses_a_format_naming_a_column_the_table_lacks() {
        let columns = vec![Column::new("x".into(), [1.0])];
        let format = CsvFormat::new(FieldFormat::decimal("null")).with(["y"], FieldFormat::scientific(""));
        let e = csv_text(&frame("t", columns).unwrap(), &format).unwrap_err();
        assert!(e.to_string().contains("column `y`"), "{e}");
    }

    #[test]
    fn csv_text_writes_fixed_decimals_and_rounded_values_give_that_text_again() {
        let values = [0.1 + 0.2, -1e-9, 123.4567895, 2.0 / 3.0, -0.0];
        let columns = vec![Column::new("q".into(), values), Column::new("r".into(), values.map(|v| rounded(v, 6)))];
        let text = csv_text(&frame("t", columns).unwrap(), &CsvFormat::new(FieldFormat::fixed("", 6))).unwrap();
        let expected: String = values.iter().map(|v| format!("{v:.6},{v:.6}\n")).collect();
        assert_eq!(text, format!("q,r\n{expected}"));
        assert_eq!(text.lines().nth(1), Some("0.300000,0.300000"));
        // The rounded value is the one its text reads back as.
        for v in values {
            assert_eq!(rounded(v, 6).to_bits(), format!("{v:.6}").parse::<f64>().unwrap().to_bits());
        }
    }
}
