//! `keys` and `init`: the reference of every key of a scenario file of each device, of a sweep
//! file and of a robot file (unit, default, rules, SOURCED / ASSUMED / FITTED note), made from the
//! loaders themselves (`device::keys`), as text for the terminal and as `docs/reference.md`; and a
//! commented starting scenario of a device, written from the same reference.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use polars::prelude::Column;

use super::Error;
use crate::device::keys::{KeyRow, Refusal, accepted_keys};
use crate::device::{Device, REGISTRY};
use crate::io::table::Frame;

/// What `calsim keys` takes besides the devices' kinds.
pub const OTHER_FILES: [&str; 2] = ["sweep", "robot"];

/// The notes, defaults and rules of a sweep file's keys (its checks are written out in
/// `design::sweep::spec`, not through the scenario checker).
const SWEEP_NOTES: &str = include_str!("../design/sweep/keys.toml");
/// The same for a robot file (`robot::file`).
const ROBOT_NOTES: &str = include_str!("../robot/keys.toml");

/// Every name `calsim keys` takes: the devices' kinds, `sweep` and `robot`.
pub fn names() -> Vec<&'static str> {
    REGISTRY.iter().map(|d| d.kind()).chain(OTHER_FILES).collect()
}

/// The reference of the keys of `name` (a device's kind, `sweep` or `robot`).
pub fn reference(name: &str) -> Result<Vec<KeyRow>, Error> {
    if let Some(device) = REGISTRY.iter().find(|d| d.kind() == name) {
        return Ok(crate::device::keys::device_reference(*device));
    }
    match name {
        "sweep" => Ok(structured(&sweep_keys()?, SWEEP_NOTES)),
        "robot" => Ok(structured(&robot_keys(), ROBOT_NOTES)),
        _ => Err(Error::input("keys", format!("{name:?}: one of {}", names().join(", ")))),
    }
}

/// Rows of a file whose defaults and rules are kept in its notes table (`[key] default, rule,
/// note`).
fn structured(keys: &[String], notes: &str) -> Vec<KeyRow> {
    let table: toml::Table = notes.parse().expect("a notes table is TOML");
    let field = |k: &str, f: &str| -> Option<String> {
        let mut key = k;
        loop {
            if let Some(v) = table.get(key).and_then(|t| t.get(f)).and_then(toml::Value::as_str) {
                return Some(v.to_string());
            }
            key = key.rsplit_once('.')?.0;
        }
    };
    keys.iter()
        .map(|k| KeyRow {
            key: k.clone(),
            unit: crate::device::keys::unit(k),
            default: field(k, "default").unwrap_or_default(),
            rule: field(k, "rule").unwrap_or_default(),
            note: field(k, "note").unwrap_or_default(),
        })
        .collect()
}

/// The keys of a sweep file, by probing its loader (through files in a scratch directory: the
/// loader reads the sweep and its base scenario from disk).
fn sweep_keys() -> Result<Vec<String>, Error> {
    let dir = scratch_dir("sweep")?;
    let base_scenario = dir.join("base.toml");
    std::fs::write(&base_scenario, crate::device::keys::minimal("trical")).map_err(Error::io(&base_scenario))?;
    let file = dir.join("probe.toml");
    let load = |t: toml::Table| -> Refusal {
        std::fs::write(&file, toml::to_string(&t).ok()?).ok()?;
        match crate::design::sweep::spec::load(&file) {
            Err(crate::design::sweep::SweepError::File { key, message, .. }) => Some((key, message)),
            _ => None,
        }
    };
    let base: toml::Table = "base = \"base.toml\"".parse().expect("TOML");
    let mut keys = accepted_keys(&base, &load, &[]);
    let _ = std::fs::remove_dir_all(&dir);
    // `realisations` is a count or a table (adaptive): the probe finds the table's fields; the
    // count is the key itself.
    if let Some(i) = keys.iter().position(|k| k.starts_with("realisations.")) {
        keys.insert(i, "realisations".to_string());
    }
    if keys.is_empty() {
        return Err(Error::input(
            dir.display().to_string(),
            "the sweep loader could not be asked for its keys (a scratch file could not be written)",
        ));
    }
    Ok(keys)
}

/// The keys of a robot file, by probing its loader on the built-in IRB 120 written as a file.
fn robot_keys() -> Vec<String> {
    let model = crate::robot::builtin::trical_2018_nominal();
    let text = crate::robot::file::to_text(&model, "probe", &[], None, None);
    let base: toml::Table = text.parse().expect("a robot file is TOML");
    let load = |t: toml::Table| -> Refusal {
        let text = toml::to_string(&t).ok()?;
        crate::robot::file::RobotFile::from_text(Path::new("probe.toml"), &text).err().map(|e| (e.field, e.message))
    };
    accepted_keys(&base, &load, &[])
}

/// A scratch directory of its own for `what` (one per call: calls may run side by side).
fn scratch_dir(what: &str) -> Result<PathBuf, Error> {
    static CALLS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let call = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let dir = std::env::temp_dir().join(format!("calsim-keys-{what}-{}-{call}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(Error::io(&dir))?;
    Ok(dir)
}

/// What a file of `name` is, in one line.
fn describe(name: &str) -> String {
    match REGISTRY.iter().find(|d| d.kind() == name) {
        Some(d) => format!("a scenario of the {} device (`kind = \"{}\"`): {}", name, d.kind(), d.describe()),
        None if name == "sweep" => "a sweep file (`calsim sweep`): a base scenario, axes over its keys, realisations".into(),
        None => "a robot file (`[robot] file` of a scenario; `calsim import-urdf` writes one)".into(),
    }
}

/// The name of the reference's table.
pub const TABLE: &str = "keys";

/// The reference of `name` as a table: a row per key with its `unit`, `default`, `rule` and
/// `note`; what the terminal shows ([`text_of`]) and Python receives.
pub fn table(name: &str) -> Result<Frame, Error> {
    let rows = reference(name)?;
    let column = |title: &str, v: &dyn Fn(&KeyRow) -> String| Column::new(title.into(), rows.iter().map(v).collect::<Vec<String>>());
    let columns = vec![
        column("key", &|r| r.key.clone()),
        column("unit", &|r| r.unit.to_string()),
        column("default", &|r| r.default.clone()),
        column("rule", &|r| r.rule.clone()),
        column("note", &|r| r.note.clone()),
    ];
    crate::io::table::frame(TABLE, columns).map_err(|e| Error::input(TABLE, e.to_string()))
}

/// The reference of `name` for the terminal ([`text_of`] its [`table`]).
pub fn text(name: &str) -> Result<String, Error> {
    text_of(name, &table(name)?)
}

/// The reference `table` of `name` for the terminal: each key with its unit and default, then its
/// rules and its note, indented.
pub fn text_of(name: &str, table: &Frame) -> Result<String, Error> {
    let tables = [(TABLE.to_string(), table.clone())];
    crate::io::results::read_row(&tables, TABLE, |r| {
        let mut s = format!("{name}: {}\n", describe(name));
        for k in 0..r.height() {
            let r = r.at(k);
            let (unit, rule, note) = (r.str("unit"), r.str("rule"), r.str("note"));
            let unit = if unit == "-" { String::new() } else { format!(" ({unit})") };
            let _ = writeln!(s, "\n{}{unit} = {}", r.str("key"), r.str("default"));
            if rule != "-" && !rule.is_empty() {
                let _ = writeln!(s, "    rule: {rule}");
            }
            if !note.is_empty() {
                let _ = writeln!(s, "    note: {note}");
            }
        }
        s
    })
    .map_err(|e| Error::input(TABLE, e.to_string()))
}

/// `docs/reference.md`: every file's keys as a Markdown table.
pub fn markdown() -> Result<String, Error> {
    let mut s = String::from(
        "# Key reference\n\n\
         Every key of the scenario files of each device, of a sweep file and of a robot file: its unit\n\
         (from the key's name), its default (absent: optional, no default), the rules the loader checks\n\
         and a note (SOURCED with where, ASSUMED, FITTED with the figure it was fitted to). Generated by\n\
         `calsim keys --markdown` from the loaders themselves; a test fails when a key changes and this\n\
         file does not (run `cargo run -- keys --markdown > docs/reference.md`). The terminal shows the\n\
         same with `calsim keys <name>`; `calsim init <kind>` writes a commented starting scenario.\n",
    );
    for name in names() {
        let _ = write!(s, "\n## {name}\n\n{}.\n\n| key | unit | default | rules | note |\n|---|---|---|---|---|\n", describe(name));
        for r in reference(name)? {
            let cell = |x: &str| x.replace('|', "\\|").replace('\n', " ");
            let _ = writeln!(s, "| `{}` | {} | `{}` | {} | {} |", r.key, cell(r.unit), cell(&r.default), cell(&r.rule), cell(&r.note));
        }
    }
    Ok(s)
}

/// `calsim init`: the starting scenario of `kind` ([`init`]), also written to `file` when given;
/// an existing file (or a link, even a dangling one) is never replaced.
pub fn init_file(kind: &str, file: Option<&std::path::Path>) -> Result<String, Error> {
    let text = init(kind)?;
    if let Some(f) = file {
        if std::fs::symlink_metadata(f).is_ok() {
            return Err(Error::input(f.display().to_string(), "exists; calsim init does not replace a file (nor a link)"));
        }
        crate::io::out_dir::write_file_atomically(f, &text).map_err(Error::io(f))?;
    }
    Ok(text)
}

/// A commented starting scenario of the device `kind`: every key at its default with its unit,
/// rules and note as comments, keys without a default commented out. It loads as it is (a test).
pub fn init(kind: &str) -> Result<String, Error> {
    let device: &dyn Device = *REGISTRY.iter().find(|d| d.kind() == kind).ok_or_else(|| {
        Error::input("init", format!("{kind:?}: one of {}", REGISTRY.iter().map(|d| d.kind()).collect::<Vec<_>>().join(", ")))
    })?;
    let rows = crate::device::keys::device_reference(device);
    // Keys grouped by their table, tables in the order they first appear (a TOML table is written once).
    let mut tables: Vec<(String, Vec<(String, &KeyRow)>)> = Vec::new();
    for r in &rows {
        let (table, key) = table_of(&r.key);
        match tables.iter_mut().find(|(t, _)| *t == table) {
            Some((_, keys)) => keys.push((key, r)),
            None => tables.push((table, vec![(key, r)])),
        }
    }
    let mut s = format!(
        "# A {kind} scenario: {}.\n# Written by `calsim init {kind}`: every key at its default, with its unit, rules and note\n\
         # (docs/reference.md); keys without a default are commented out. Change what your study needs.\n",
        device.describe()
    );
    for (table, keys) in &tables {
        if !table.is_empty() {
            let _ = write!(s, "\n[{table}]\n");
        }
        for (key, r) in keys {
            let mut comment = Vec::new();
            if r.unit != "-" {
                comment.push(r.unit.to_string());
            }
            if r.rule != "-" {
                comment.push(r.rule.clone());
            }
            if !r.note.is_empty() {
                let _ = writeln!(s, "# {}", r.note);
            }
            let comment = if comment.is_empty() { String::new() } else { format!("   # {}", comment.join("; ")) };
            if r.default == "absent" {
                let _ = writeln!(s, "# {key} = ...{comment}");
            } else {
                let _ = writeln!(s, "{key} = {}{comment}", r.default);
            }
        }
    }
    Ok(s)
}

/// The table of a dotted key and the key within it: a band's `value` and `tolerance` stay with
/// their figure (`[expect]` `after_median_mm.value`).
fn table_of(key: &str) -> (String, String) {
    let parts: Vec<&str> = key.split('.').collect();
    let band = matches!(parts.last(), Some(&"value") | Some(&"tolerance")) && parts.first() == Some(&"expect");
    let split = if band { parts.len().saturating_sub(2) } else { parts.len() - 1 };
    (parts[..split].join("."), parts[split..].join("."))
}

/// The keys of `name` that have no note, and the notes that name no key.
pub fn unmatched_notes(name: &str) -> Result<(Vec<String>, Vec<String>), Error> {
    let rows = reference(name)?;
    let without: Vec<String> = rows.iter().filter(|r| r.note.is_empty()).map(|r| r.key.clone()).collect();
    // The notes of this file's own table (a device's, less the shared sections every device has).
    let own: Vec<String> = match REGISTRY.iter().find(|d| d.kind() == name) {
        // A device's own table is the last of its notes; the others are checked with their owners.
        Some(d) => d.notes().last().map(|t| crate::device::keys::notes(&[t]).into_keys().collect()).unwrap_or_default(),
        None => {
            let text = if name == "sweep" { SWEEP_NOTES } else { ROBOT_NOTES };
            text.parse::<toml::Table>().expect("TOML").keys().cloned().collect()
        }
    };
    // A note names a key of the file, or a table of its keys.
    let names_a_key = |rows: &[KeyRow], n: &str| {
        rows.iter().any(|r| r.key == n || r.key.starts_with(&format!("{n}.")) || r.key.starts_with(&format!("{n}[].")))
    };
    let stray = own.into_iter().filter(|n| !names_a_key(&rows, n)).collect();
    Ok((without, stray))
}

/// The shared notes (`device/keys.toml`) that name no key of any device.
pub fn stray_shared_notes() -> Vec<String> {
    let all: Vec<KeyRow> = REGISTRY.iter().flat_map(|d| crate::device::keys::device_reference(*d)).collect();
    crate::device::keys::notes(&[crate::device::SHARED_NOTES])
        .into_keys()
        .filter(|n| !all.iter().any(|r| r.key == *n || r.key.starts_with(&format!("{n}."))))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn init_writes_a_new_file_and_never_replaces_a_file_or_a_link() {
        let tmp = tempfile::Builder::new().prefix("calsim-init-").tempdir().unwrap();
        let file = tmp.path().join("s.toml");
        let text = init_file("trical", Some(&file)).unwrap();
        assert_eq!(std::fs::read_to_string(&file).unwrap(), text);
        assert_eq!(init_file("trical", None).unwrap(), text);
        std::fs::write(&file, "mine").unwrap();
        let dangling = tmp.path().join("link.toml");
        std::os::unix::fs::symlink(tmp.path().join("nowhere.toml"), &dangling).unwrap();
        for f in [&file, &dangling] {
            let e = init_file("trical", Some(f)).unwrap_err().to_string();
            assert_eq!(e, format!("{}: exists; calsim init does not replace a file (nor a link)", f.display()));
        }
        assert_eq!(std::fs::read_to_string(&file).unwrap(), "mine");
        assert!(std::fs::symlink_metadata(tmp.path().join("nowhere.toml")).is_err());
    }
}
