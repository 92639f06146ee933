//! A producer's results as a value ([`Results`]) and the one writer that turns any such value into
//! a results directory ([`write`]).
//!
//! A producer (a device's run, a sweep, a budget, an optimisation, an export, a plan, a
//! calibration) computes its figures and returns them: its tables as polars frames, the other
//! files it hands the user (a robot file, a design file, a CSV), its drawings and recording as
//! work to do into a path the writer gives, its summary as [`Summary`] parts (text, tables
//! rendered from the result tables themselves, the figures), the fields of its manifest and the
//! provenance head. It writes nothing. [`write`] then, inside the atomic swap of
//! [`crate::io::out_dir::write_atomically`] (whose rule alone decides what may be replaced):
//!
//! 1. writes every table (parquet, through [`crate::io::table`]) and every file;
//! 2. hashes the tables and writes `manifest.json`: the producer's fields, `tables_sha256` and the
//!    provenance block ([`crate::io::manifest`]), the same for every producer;
//! 3. records the Rerun recording (`study.rrd`) and draws the figures;
//! 4. renders `summary.md` from its parts: a table part reads the frame written in step 1, so a
//!    figure printed and a figure stored cannot differ.

use std::cell::RefCell;
use std::path::{Path, PathBuf};

use polars::prelude::{AnyValue, Column, DataFrame};

use crate::io::plot::{PlotError, Written};
use crate::io::record::RecordError;

/// Draws figures into the directory it is given and names them (stem and caption).
pub type Draw<'a> = Box<dyn FnOnce(&Path) -> Result<Vec<Written>, PlotError> + Send + 'a>;

/// Writes a recording to the path it is given.
pub type Record<'a> = Box<dyn FnOnce(&Path) -> Result<(), RecordError> + 'a>;

/// One row of a result table, read by column name ([`Summary::table`]). A column the table does
/// not have, or of another type, reads as NaN, 0 or "" and makes the rendering fail naming it.
pub struct Row<'f> {
    tables: &'f [(String, DataFrame)],
    frame: &'f DataFrame,
    index: usize,
    missing: &'f RefCell<Option<String>>,
}

impl Row<'_> {
    fn value(&self, name: &str) -> Option<AnyValue<'_>> {
        let v = self.frame.column(name).ok().and_then(|c| c.get(self.index).ok());
        if v.is_none() {
            self.missing.borrow_mut().get_or_insert_with(|| name.to_string());
        }
        v
    }

    /// Row `index` of the same table.
    pub fn at(&self, index: usize) -> Row<'_> {
        Row { tables: self.tables, frame: self.frame, index, missing: self.missing }
    }

    /// Row `index` of the result table `table` (a table the results do not hold reads as an empty
    /// one and makes the rendering fail naming it).
    pub fn of(&self, table: &str, index: usize) -> Row<'_> {
        static EMPTY: std::sync::LazyLock<DataFrame> = std::sync::LazyLock::new(DataFrame::empty);
        let frame = self.tables.iter().find(|(n, _)| n == table).map(|(_, f)| f).unwrap_or_else(|| {
            self.missing.borrow_mut().get_or_insert_with(|| format!("(the table {table} is not among the results)"));
            &EMPTY
        });
        Row { tables: self.tables, frame, index, missing: self.missing }
    }

    /// The row's index in its table.
    pub fn index(&self) -> usize {
        self.index
    }

    /// The number of rows of its table.
    pub fn height(&self) -> usize {
        self.frame.height()
    }

    /// The rows of its table whose column `name` holds the text `value`.
    pub fn count(&self, name: &str, value: &str) -> usize {
        (0..self.height()).filter(|&i| self.at(i).str(name) == value).count()
    }

    /// A number (floating or integer column; a null is NaN).
    pub fn f64(&self, name: &str) -> f64 {
        match self.value(name) {
            Some(AnyValue::Null) => f64::NAN,
            Some(v) => v.extract::<f64>().unwrap_or_else(|| self.wrong(name, f64::NAN)),
            None => f64::NAN,
        }
    }

    /// A count or index (an unsigned or integer column).
    pub fn u64(&self, name: &str) -> u64 {
        match self.value(name) {
            Some(v) => v.extract::<u64>().unwrap_or_else(|| self.wrong(name, 0)),
            None => 0,
        }
    }

    /// A flag.
    pub fn bool(&self, name: &str) -> bool {
        match self.value(name) {
            Some(AnyValue::Boolean(b)) => b,
            Some(_) => self.wrong(name, false),
            None => false,
        }
    }

    /// A flag that may be absent (null).
    pub fn opt_bool(&self, name: &str) -> Option<bool> {
        match self.value(name) {
            Some(AnyValue::Boolean(b)) => Some(b),
            Some(AnyValue::Null) => None,
            Some(_) => self.wrong(name, None),
            None => None,
        }
    }

    /// A text (a null is "").
    pub fn str(&self, name: &str) -> String {
        match self.value(name) {
            Some(AnyValue::String(s)) => s.to_string(),
            Some(AnyValue::StringOwned(s)) => s.to_string(),
            Some(AnyValue::Null) => String::new(),
            Some(_) => self.wrong(name, String::new()),
            None => String::new(),
        }
    }

    fn wrong<T>(&self, name: &str, fallback: T) -> T {
        self.missing.borrow_mut().get_or_insert_with(|| format!("{name} (of another type)"));
        fallback
    }
}

/// A column of a summary table: its header and how a row shows in it.
pub type Cell<'a> = (String, Box<dyn Fn(&Row<'_>) -> String + 'a>);

/// A cell of a summary table from its header and how a row shows in it.
pub fn cell<'a>(header: impl Into<String>, show: impl Fn(&Row<'_>) -> String + 'a) -> Cell<'a> {
    (header.into(), Box::new(show))
}

/// Text read from a result table (its first row, and any other row or table through it).
pub type Read<'a> = Box<dyn Fn(&Row<'_>) -> String + 'a>;

/// Which rows of a table a summary shows, in which order (the frame is the written table).
pub type Rows<'a> = Box<dyn Fn(&DataFrame) -> Vec<usize> + 'a>;

enum Part<'a> {
    Text(String),
    TextFrom { table: String, read: Read<'a> },
    Table { table: String, rows: Rows<'a>, cells: Vec<Cell<'a>>, if_rows: bool },
    Figures(String),
}

/// The summary of a results directory as parts, rendered by [`write`] into `summary.md`.
#[derive(Default)]
pub struct Summary<'a> {
    parts: Vec<Part<'a>>,
}

impl<'a> Summary<'a> {
    /// Text, as Markdown.
    pub fn text(&mut self, text: impl Into<String>) -> &mut Self {
        self.parts.push(Part::Text(text.into()));
        self
    }

    /// Text whose figures are read from the result table `table` (a name of [`Results::table`]):
    /// `read` is given its first row (an empty table reads as missing values and makes the
    /// rendering fail naming the column).
    pub fn text_from(&mut self, table: &str, read: impl Fn(&Row<'_>) -> String + 'a) -> &mut Self {
        self.parts.push(Part::TextFrom { table: table.to_string(), read: Box::new(read) });
        self
    }

    /// A Markdown table rendered from the result table `table` (a name of [`Results::table`]):
    /// the rows `rows` picks, in its order, and one column per cell (followed by an empty line).
    pub fn table(&mut self, table: &str, rows: Rows<'a>, cells: Vec<Cell<'a>>) -> &mut Self {
        self.parts.push(Part::Table { table: table.to_string(), rows, cells, if_rows: false });
        self
    }

    /// As [`Summary::table`], but nothing at all (no header) when `rows` picks no row.
    pub fn table_if_rows(&mut self, table: &str, rows: Rows<'a>, cells: Vec<Cell<'a>>) -> &mut Self {
        self.parts.push(Part::Table { table: table.to_string(), rows, cells, if_rows: true });
        self
    }

    /// Every row of `table`, in its order ([`Summary::table`]).
    pub fn all_rows() -> Rows<'a> {
        Box::new(|f: &DataFrame| (0..f.height()).collect())
    }

    /// The figures drawn, after `heading` (when any was drawn), each as its PNG with the caption
    /// and a link to its SVG. The summary a command prints leaves them out.
    pub fn figures(&mut self, heading: impl Into<String>) -> &mut Self {
        self.parts.push(Part::Figures(heading.into()));
        self
    }

    /// The summary as written (`summary.md`) and as printed (without the figures).
    fn render(self, tables: &[(String, DataFrame)], drawn: &[Written]) -> std::io::Result<(String, String)> {
        let (mut file, mut shown) = (String::new(), String::new());
        for part in self.parts {
            match part {
                Part::Text(t) => {
                    file.push_str(&t);
                    shown.push_str(&t);
                }
                Part::Figures(heading) => {
                    if !drawn.is_empty() {
                        file.push_str(&heading);
                    }
                    for w in drawn {
                        if w.svg {
                            file.push_str(&format!("![{}]({}.png)\n\n*{}* ([SVG]({}.svg))\n\n", w.caption, w.stem, w.caption, w.stem));
                        } else {
                            file.push_str(&format!(
                                "![{}]({}.png)\n\n*{}* (no SVG: more than {} marks)\n\n",
                                w.caption,
                                w.stem,
                                w.caption,
                                crate::io::plot::MOST_SVG_MARKS
                            ));
                        }
                    }
                }
                Part::TextFrom { table, read } => {
                    let t = read_text(tables, &table, &read)?;
                    file.push_str(&t);
                    shown.push_str(&t);
                }
                Part::Table { table, rows, cells, if_rows } => {
                    let frame = find(tables, &table)?;
                    if if_rows && rows(frame).is_empty() {
                        continue;
                    }
                    let t = markdown_table(tables, &table, frame, &rows, &cells)?;
                    file.push_str(&t);
                    shown.push_str(&t);
                }
            }
        }
        Ok((file, shown))
    }
}

/// The result table `name` of `tables`.
fn find<'f>(tables: &'f [(String, DataFrame)], name: &str) -> std::io::Result<&'f DataFrame> {
    tables
        .iter()
        .find(|(n, _)| n == name)
        .map(|(_, f)| f)
        .ok_or_else(|| std::io::Error::other(format!("summary.md: the summary shows the table {name}, which the results do not hold")))
}

/// What `read` makes of the first row of the table `name` of `tables`.
fn read_text(tables: &[(String, DataFrame)], name: &str, read: &Read<'_>) -> std::io::Result<String> {
    read_row(tables, name, |r| read(r))
}

/// What `read` makes of the first row of the result table `name` of `tables` (and of any other row
/// or table it reads through it), as [`Summary::text_from`] reads it: what a command prints from
/// the frames its results hold. An error names the table and the column a row lacked.
pub fn read_row<T>(tables: &[(String, DataFrame)], name: &str, read: impl FnOnce(&Row<'_>) -> T) -> std::io::Result<T> {
    let missing = RefCell::new(None);
    let value = read(&Row { tables, frame: find(tables, name)?, index: 0, missing: &missing });
    checked(name, missing, value)
}

/// `value`, or the error naming the column of the table `name` that a row lacked.
fn checked<T>(name: &str, missing: RefCell<Option<String>>, value: T) -> std::io::Result<T> {
    match missing.into_inner() {
        Some(column) => Err(std::io::Error::other(format!("summary.md: the table {name} has no column {column}"))),
        None => Ok(value),
    }
}

/// The Markdown table of the rows `rows` picks of `frame` (the table `name` of `tables`) with the
/// columns `cells`.
fn markdown_table(
    tables: &[(String, DataFrame)],
    name: &str,
    frame: &DataFrame,
    rows: &Rows<'_>,
    cells: &[Cell<'_>],
) -> std::io::Result<String> {
    let missing = RefCell::new(None);
    // The header: an empty one as `| |`.
    let head: String = cells.iter().map(|c| if c.0.is_empty() { " |".to_string() } else { format!(" {} |", c.0) }).collect();
    let mut s = format!("|{head}\n|{}\n", "---|".repeat(cells.len()));
    for index in rows(frame) {
        let row = Row { tables, frame, index, missing: &missing };
        let shown: Vec<String> = cells.iter().map(|(_, show)| show(&row)).collect();
        s.push_str(&format!("| {} |\n", shown.join(" | ")));
    }
    s.push('\n');
    checked(name, missing, s)
}

/// Where the manifest's provenance comes from: the head of a scenario's run (name, path, sha256,
/// seed, then the block) or the block alone.
pub enum Head<'a> {
    /// A run of one scenario.
    Scenario(crate::io::manifest::ScenarioHead<'a>),
    /// Any other command (its inputs are in the block).
    Run(crate::io::manifest::Provenance),
}

/// A producer's results: everything [`write`] puts in a results directory.
pub struct Results<'a> {
    /// The directory's name under `--out` (one plain path component).
    pub name: String,
    head: Head<'a>,
    fields: serde_json::Map<String, serde_json::Value>,
    tables: Vec<(String, DataFrame)>,
    files: Vec<(String, Vec<u8>)>,
    draw: Vec<Draw<'a>>,
    record: Option<(String, Record<'a>)>,
    nested: Vec<(String, Results<'a>)>,
    /// The summary (`summary.md`); none when it has no part.
    pub summary: Summary<'a>,
}

impl<'a> Results<'a> {
    /// Empty results named `name` with their provenance head.
    pub fn new(name: impl Into<String>, head: Head<'a>) -> Self {
        Self {
            name: name.into(),
            head,
            fields: serde_json::Map::new(),
            tables: Vec::new(),
            files: Vec::new(),
            draw: Vec::new(),
            record: None,
            nested: Vec::new(),
            summary: Summary::default(),
        }
    }

    /// A result table `name` (`tasks.parquet`) from its columns; an error names the table (and
    /// the column, for two columns of one name, or columns of different lengths).
    pub fn table(&mut self, name: &str, columns: Vec<Column>) -> std::io::Result<&DataFrame> {
        let frame = crate::io::table::frame(name, columns)?;
        if self.tables.iter().any(|(n, _)| n == name) {
            return Err(std::io::Error::other(format!("{name}: two tables of one name")));
        }
        self.tables.push((name.to_string(), frame));
        Ok(&self.tables.last().expect("just pushed").1)
    }

    /// A table already made, by name.
    pub fn frame(&self, name: &str) -> Option<&DataFrame> {
        self.tables.iter().find(|(n, _)| n == name).map(|(_, f)| f)
    }

    /// The sha256 of every table as its file will hold it, by file name (what the manifest's
    /// `tables_sha256` records).
    pub fn tables_sha256(&self) -> std::io::Result<std::collections::BTreeMap<String, String>> {
        use sha2::Digest as _;
        let mut out = std::collections::BTreeMap::new();
        for (name, frame) in &self.tables {
            let bytes = crate::io::table::parquet_bytes(name, frame.clone())?;
            out.insert(name.clone(), format!("{:x}", sha2::Sha256::digest(bytes)));
        }
        Ok(out)
    }

    /// The tables, in the order they were added.
    pub fn frames(&self) -> &[(String, DataFrame)] {
        &self.tables
    }

    /// Another file handed to the user (`robot.toml`, `best_design.toml`, `spheres.csv`).
    pub fn file(&mut self, name: &str, contents: impl Into<Vec<u8>>) -> &mut Self {
        self.files.push((name.to_string(), contents.into()));
        self
    }

    /// A field of the manifest (beside `tables_sha256` and the provenance block).
    pub fn field(&mut self, key: &str, value: impl serde::Serialize) -> std::io::Result<&mut Self> {
        self.fields.insert(key.to_string(), serde_json::to_value(value).map_err(crate::io::table::err)?);
        Ok(self)
    }

    /// Every field of `fields` (a struct that serialises to a JSON object) in the manifest.
    pub fn fields(&mut self, fields: impl serde::Serialize) -> std::io::Result<&mut Self> {
        match serde_json::to_value(fields).map_err(crate::io::table::err)? {
            serde_json::Value::Object(m) => self.fields.extend(m),
            _ => return Err(std::io::Error::other("manifest.json: a producer's fields are a JSON object")),
        }
        Ok(self)
    }

    /// Figures to draw (run by [`write`] inside the results directory).
    pub fn draw(&mut self, draw: Draw<'a>) -> &mut Self {
        self.draw.push(draw);
        self
    }

    /// The Rerun recording, written as `study.rrd`.
    pub fn record(&mut self, record: Record<'a>) -> &mut Self {
        self.record_as("study.rrd", record)
    }

    /// The Rerun recording, written as `file`.
    pub fn record_as(&mut self, file: &str, record: Record<'a>) -> &mut Self {
        self.record = Some((file.to_string(), record));
        self
    }

    /// Results of their own in the subdirectory `name` (an optimisation's winning world), written
    /// the same way, with their own manifest.
    pub fn nested(&mut self, name: &str, results: Results<'a>) -> &mut Self {
        self.nested.push((name.to_string(), results));
        self
    }

    /// The summary as a command prints it (without the figures), rendered from the tables; nothing
    /// is written.
    pub fn summary_text(self) -> std::io::Result<String> {
        self.summary.render(&self.tables, &[]).map(|(_, shown)| shown)
    }

    /// Writes everything into `dir`, an empty directory (the order of the module doc); the
    /// summary as printed and the time the recording took, s.
    pub fn write_into(self, dir: &Path) -> std::io::Result<(String, f64)> {
        use crate::io::out_dir::write_file;
        let t = std::time::Instant::now();
        if let Some((file, record)) = self.record {
            record(&dir.join(file)).map_err(std::io::Error::other)?;
        }
        let recording_s = t.elapsed().as_secs_f64();
        // The tables and files, and the figures, side by side (each its own files).
        let (tables, files, draw) = (&self.tables, &self.files, self.draw);
        let (written, drawn) = rayon::join(
            || -> std::io::Result<()> {
                for (name, frame) in tables {
                    crate::io::table::write_frame(dir, name, frame.clone())?;
                }
                for (name, bytes) in files {
                    write_file(&dir.join(name), bytes)?;
                }
                Ok(())
            },
            || -> std::io::Result<Vec<Written>> {
                let mut drawn = Vec::new();
                for draw in draw {
                    drawn.extend(draw(dir).map_err(std::io::Error::other)?);
                }
                Ok(drawn)
            },
        );
        written?;
        let drawn = drawn?;
        for (name, results) in self.nested {
            let sub = dir.join(&name);
            std::fs::create_dir(&sub).map_err(crate::io::out_dir::named(&sub))?;
            results.write_into(&sub)?;
        }
        let mut manifest = self.fields;
        manifest.insert("tables_sha256".into(), serde_json::to_value(crate::io::table::table_hashes(dir)?).map_err(crate::io::table::err)?);
        let head = match self.head {
            Head::Scenario(h) => serde_json::to_value(h),
            Head::Run(p) => serde_json::to_value(p),
        }
        .map_err(crate::io::table::err)?;
        if let serde_json::Value::Object(h) = head {
            manifest.extend(h);
        }
        let mut shown = String::new();
        if !self.summary.parts.is_empty() {
            let (text, printed) = self.summary.render(&self.tables, &drawn)?;
            write_file(&dir.join("summary.md"), text)?;
            shown = printed;
        }
        // Last: the manifest lists every file written, so that a later run replaces only this.
        let files = crate::io::out_dir::listing(dir)?;
        manifest.insert("files".into(), serde_json::to_value(files).map_err(crate::io::table::err)?);
        write_file(&dir.join("manifest.json"), serde_json::to_string_pretty(&manifest).map_err(crate::io::table::err)?)?;
        Ok((shown, recording_s))
    }
}

/// What [`write`] did.
#[derive(Debug)]
pub struct Wrote {
    /// The results directory.
    pub dest: PathBuf,
    /// The summary as a command prints it (`summary.md` without its figures).
    pub summary: String,
    /// Wall time of the recording, s.
    pub recording_s: f64,
}

/// Writes `results` as the results directory `out/<name>`, atomically, by the rule of
/// [`crate::io::out_dir`].
pub fn write(out: &Path, results: Results<'_>) -> std::io::Result<Wrote> {
    let name = results.name.clone();
    let (mut summary, mut recording_s) = (String::new(), 0.0);
    let dest = crate::io::out_dir::write_atomically(out, &name, |dir| {
        (summary, recording_s) = results.write_into(dir)?;
        Ok(())
    })?;
    Ok(Wrote { dest, summary, recording_s })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn results() -> Results<'static> {
        let mut r = Results::new("r", Head::Run(crate::io::manifest::Provenance::of_run(&[])));
        r.table("t.parquet", vec![Column::new("x".into(), vec![1.5f64, f64::NAN]), Column::new("n".into(), vec![3u32, 4])]).unwrap();
        r.field("answer", 42).unwrap();
        r
    }

    #[test]
    fn a_summary_table_shows_the_values_the_written_table_holds() {
        let tmp = tempfile::Builder::new().prefix("calsim-results-").tempdir().unwrap();
        let mut r = results();
        r.summary.text("# t\n\n").table(
            "t.parquet",
            Summary::all_rows(),
            vec![("x".into(), Box::new(|row| format!("{:.2}", row.f64("x")))), ("n".into(), Box::new(|row| row.u64("n").to_string()))],
        );
        let dest = write(tmp.path(), r).unwrap().dest;
        let text = std::fs::read_to_string(dest.join("summary.md")).unwrap();
        assert_eq!(text, "# t\n\n| x | n |\n|---|---|\n| 1.50 | 3 |\n| NaN | 4 |\n\n");
        use polars::prelude::SerReader as _;
        let frame = polars::prelude::ParquetReader::new(std::fs::File::open(dest.join("t.parquet")).unwrap()).finish().unwrap();
        assert_eq!(frame.column("x").unwrap().f64().unwrap().get(0), Some(1.5));
        let manifest: serde_json::Value = serde_json::from_slice(&std::fs::read(dest.join("manifest.json")).unwrap()).unwrap();
        assert_eq!(manifest["answer"], 42);
        assert!(manifest["tables_sha256"]["t.parquet"].as_str().is_some_and(|h| h.len() == 64));
        assert!(manifest["crate_version"].is_string() && manifest["git_commit"].is_string());
    }

    #[test]
    fn a_summary_naming_a_column_the_table_lacks_fails_and_leaves_nothing() {
        let tmp = tempfile::Builder::new().prefix("calsim-results-").tempdir().unwrap();
        let mut r = results();
        r.summary.table("t.parquet", Summary::all_rows(), vec![("y".into(), Box::new(|row| row.f64("y").to_string()))]);
        let e = write(tmp.path(), r).unwrap_err().to_string();
        assert!(e.contains("the table t.parquet has no column y"), "{e}");
        assert_eq!(std::fs::read_dir(tmp.path()).unwrap().count(), 0, "nothing left behind");
    }

    #[test]
    fn text_from_a_table_reads_its_rows_and_fails_on_a_missing_column() {
        let tmp = tempfile::Builder::new().prefix("calsim-results-").tempdir().unwrap();
        let mut r = results();
        r.summary.text_from("t.parquet", |row| format!("{} rows, n = {} then {}.\n", row.height(), row.u64("n"), row.at(1).u64("n")));
        let dest = write(tmp.path(), r).unwrap().dest;
        assert_eq!(std::fs::read_to_string(dest.join("summary.md")).unwrap(), "2 rows, n = 3 then 4.\n");
        let mut r = results();
        r.summary.text_from("t.parquet", |row| row.f64("z").to_string());
        let e = write(tmp.path(), r).unwrap_err().to_string();
        assert!(e.contains("the table t.parquet has no column z"), "{e}");
    }

    #[test]
    fn a_table_if_rows_shows_nothing_without_a_row_and_the_rows_it_picks_otherwise() {
        let x = || -> Vec<Cell<'static>> { vec![cell("x", |row| format!("{:.1}", row.f64("x")))] };
        let mut r = results();
        r.summary.text("a\n").table_if_rows("t.parquet", Box::new(|_| Vec::new()), x()).text("b\n");
        assert_eq!(r.summary_text().unwrap(), "a\nb\n");
        let mut r = results();
        r.summary.table_if_rows("t.parquet", Box::new(|_| vec![1, 0]), x());
        assert_eq!(r.summary_text().unwrap(), "| x |\n|---|\n| NaN |\n| 1.5 |\n\n");
    }

    /// The manifest lists every file written (nested results included); a second run replaces
    /// the directory, but not once a user has added a file or a directory to it, nor one whose
    /// manifest lists no files: refused naming the entry, and every byte left as it was.
    #[test]
    fn results_holding_a_file_calsim_did_not_write_are_not_replaced() {
        let tmp = tempfile::Builder::new().prefix("calsim-results-").tempdir().unwrap();
        let with_nested = || {
            let mut r = results();
            r.file("notes.md", "n").nested("winner", results());
            r
        };
        let dest = write(tmp.path(), with_nested()).unwrap().dest;
        let manifest: serde_json::Value = serde_json::from_slice(&std::fs::read(dest.join("manifest.json")).unwrap()).unwrap();
        let files: Vec<&str> = manifest["files"].as_array().unwrap().iter().map(|v| v.as_str().unwrap()).collect();
        assert_eq!(files, ["notes.md", "t.parquet", "winner/", "winner/manifest.json", "winner/t.parquet"]);
        assert_eq!(write(tmp.path(), with_nested()).unwrap().dest, dest, "calsim's own results are replaced");
        let snapshot = |d: &Path| -> Vec<(String, Vec<u8>)> {
            let mut v: Vec<(String, Vec<u8>)> = crate::io::out_dir::listing(d)
                .unwrap()
                .into_iter()
                .filter(|p| !p.ends_with('/'))
                .chain(["manifest.json".to_string()])
                .map(|p| (p.clone(), std::fs::read(d.join(&p)).unwrap()))
                .collect();
            v.sort();
            v
        };
        for added in ["QA_signoff.txt", "winner/mine.toml", "extra/"] {
            let path = dest.join(added);
            if added.ends_with('/') {
                std::fs::create_dir(&path).unwrap();
            } else {
                std::fs::write(&path, "a user's").unwrap();
            }
            let before = snapshot(&dest);
            let e = write(tmp.path(), with_nested()).unwrap_err().to_string();
            assert!(e.contains(&format!("holds {added}, which calsim did not write there")), "{e}");
            assert_eq!(snapshot(&dest), before, "{added}: nothing changed");
            if added.ends_with('/') { std::fs::remove_dir(&path) } else { std::fs::remove_file(&path) }.unwrap();
        }
        let mut manifest = manifest;
        manifest.as_object_mut().unwrap().remove("files");
        std::fs::write(dest.join("manifest.json"), manifest.to_string()).unwrap();
        let e = write(tmp.path(), with_nested()).unwrap_err().to_string();
        assert!(e.contains("lists no files"), "{e}");
    }

    #[test]
    fn two_tables_of_one_name_are_refused() {
        let mut r = results();
        let e = r.table("t.parquet", vec![Column::new("x".into(), vec![1.0f64])]).unwrap_err().to_string();
        assert!(e.contains("two tables of one name"), "{e}");
    }
}
