//! The module graph of `src/` runs one way: every `crate::<module>` a file names is a module below
//! its own in the layer order of ARCHITECTURE.md, a device names no other device (but the one it
//! is built on), and the kernels (kinematics, identification) name no file, random-number,
//! table or recording library. A new arrow upwards or sideways fails here, naming the file.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The top-level modules, lowest first: a module may name only modules before it.
const LAYERS: [&str; 14] =
    ["numeric", "seeds", "io", "robot", "identify", "cell", "instrument", "study", "device", "design", "calibrate", "plan", "app", "cli"];

/// Devices built on another device's world (tracker on the TriCal cell), by folder.
const BUILT_ON: [(&str, &str); 1] = [("tracker", "trical")];

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The code of a file without its unit tests (tests may reach anywhere).
fn code(p: &Path) -> String {
    let text = std::fs::read_to_string(p).unwrap();
    match text.find("\n#[cfg(test)]") {
        Some(i) => text[..i].to_string(),
        None => text,
    }
}

/// Every source file outside `src/io` (by its path under `src/`) with its code ([`code`]).
fn code_outside_io() -> Vec<(PathBuf, String)> {
    let src = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    files.iter().map(|f| (f.strip_prefix(&src).unwrap().to_path_buf(), code(f))).filter(|(rel, _)| !rel.starts_with("io")).collect()
}

/// Every `crate::a` and `crate::a::b` the text names, as (a, b).
fn named(text: &str) -> Vec<(String, Option<String>)> {
    let mut out = Vec::new();
    let mut rest = text;
    while let Some(i) = rest.find("crate::") {
        rest = &rest[i + 7..];
        let word = |s: &str| s.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect::<String>();
        let a = word(rest);
        let after = &rest[a.len()..];
        let b = after.strip_prefix("::").map(word).filter(|w| !w.is_empty());
        out.push((a, b));
    }
    out
}

#[test]
fn every_module_names_only_modules_below_it_and_no_device_names_another() {
    let src = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let layer: BTreeMap<&str, usize> = LAYERS.iter().enumerate().map(|(i, m)| (*m, i)).collect();
    let mut wrong = Vec::new();
    for f in &files {
        let rel = f.strip_prefix(&src).unwrap();
        let parts: Vec<String> = rel.iter().map(|s| s.to_string_lossy().trim_end_matches(".rs").to_string()).collect();
        let top = parts[0].as_str();
        if top == "lib" || top == "main" {
            continue;
        }
        let own = *layer.get(top).unwrap_or_else(|| panic!("src/{}: a top-level module missing from LAYERS", rel.display()));
        let device = (top == "device" && parts.len() > 2).then(|| parts[1].clone());
        for (a, b) in named(&code(f)) {
            if a == top {
                // Inside a module: a device folder names no other device folder.
                if let (Some(d), Some(b)) = (&device, &b) {
                    let other_device = b != d && b != "scenario" && f.parent().unwrap().parent().unwrap().join(b).is_dir();
                    if other_device && !BUILT_ON.contains(&(d.as_str(), b.as_str())) {
                        wrong.push(format!("src/{}: names crate::device::{b} (a device names no other device)", rel.display()));
                    }
                }
                continue;
            }
            match layer.get(a.as_str()) {
                Some(&l) if l < own => {}
                Some(_) => wrong.push(format!("src/{}: names crate::{a}, a module at or above {top}", rel.display())),
                None => wrong.push(format!("src/{}: names crate::{a}, a module not in LAYERS", rel.display())),
            }
        }
    }
    assert!(wrong.is_empty(), "{} arrows against the layer order:\n{}", wrong.len(), wrong.join("\n"));
}

#[test]
fn the_kernels_name_no_io_randomness_tables_or_recording() {
    let src = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src.join("robot/kinematics"), &mut files);
    rust_files(&src.join("identify"), &mut files);
    let mut wrong = Vec::new();
    for f in &files {
        let text = code(f);
        for forbidden in ["crate::io", "std::fs", "polars", "rerun", "plotters", "rand_chacha", "crate::seeds"] {
            // The identification's load-time check draws its configurations from one fixed stream.
            let allowed = forbidden == "crate::seeds" && f.ends_with("identify/observability.rs");
            if text.contains(forbidden) && !allowed {
                wrong.push(format!("{}: names {forbidden}", f.strip_prefix(&src).unwrap().display()));
            }
        }
    }
    assert!(wrong.is_empty(), "kernels reaching out:\n{}", wrong.join("\n"));
}

/// One writer puts files in place: renaming a file over another (the atomic step of a results
/// directory, an output file or a cache file) happens in `io` alone (`io::out_dir`), so that every
/// command writes through the one rule of what may be replaced.
#[test]
fn only_io_renames_files_into_place() {
    let mut wrong = Vec::new();
    for (rel, text) in code_outside_io() {
        for forbidden in ["fs::rename", "renameat"] {
            if text.contains(forbidden) {
                wrong.push(format!("{}: names {forbidden}", rel.display()));
            }
        }
    }
    assert!(wrong.is_empty(), "writers beside io::out_dir:\n{}", wrong.join("\n"));
}

/// Results directories are made by one writer: a producer returns its results as a value
/// (`io::results::Results`) and `io::results::write` writes them; no module outside `io` opens
/// the atomic swap or writes a file into a results directory itself.
#[test]
fn only_io_results_writes_a_results_directory() {
    let mut wrong = Vec::new();
    for (rel, text) in code_outside_io() {
        for forbidden in ["write_atomically(", "out_dir::write_file(", "table::parquet(", "table::write_frame("] {
            if text.contains(forbidden) {
                wrong.push(format!("{}: calls {forbidden}", rel.display()));
            }
        }
    }
    assert!(wrong.is_empty(), "results written beside io::results:\n{}", wrong.join("\n"));
}

/// TOML reaches calsim's types through `io::toml_de` alone, which holds every fixed-length array
/// to its length (toml's own reader takes the first values of a longer one): elsewhere TOML text
/// is parsed only into a `toml::Table`, and no deserializer of toml's is driven directly.
#[test]
fn toml_reaches_calsims_types_only_through_io_toml_de() {
    let mut wrong = Vec::new();
    for (rel, text) in code_outside_io() {
        let joined: String = text.split_whitespace().collect();
        if joined.matches("toml::from_str").count() > joined.matches("toml::from_str::<toml::Table>").count() {
            wrong.push(format!("{}: toml::from_str into something other than a toml::Table", rel.display()));
        }
        for forbidden in ["toml::Deserializer", "ValueDeserializer", "serde_path_to_error::deserialize(toml::"] {
            if joined.contains(forbidden) {
                wrong.push(format!("{}: names {forbidden}", rel.display()));
            }
        }
    }
    assert!(wrong.is_empty(), "TOML read beside io::toml_de:\n{}", wrong.join("\n"));
}

/// No escape hatch around the device interface: no module reaches a device's own types through
/// `Any` (a command that needs something of a device asks the [`calsim::device::Scenario`] trait's
/// hooks). The CLI's panic hook reads a panic's payload, the one downcast there is.
#[test]
fn no_module_downcasts_a_scenario() {
    let src = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let mut wrong = Vec::new();
    for f in &files {
        let rel = f.strip_prefix(&src).unwrap();
        let text = code(f);
        for forbidden in ["as_any", "std::any", "dyn Any"] {
            if text.contains(forbidden) {
                wrong.push(format!("{}: names {forbidden}", rel.display()));
            }
        }
        let joined: String = text.split_whitespace().collect();
        let downcasts = joined.matches("downcast").count();
        let payloads = joined.matches("payload().downcast_ref").count();
        if downcasts > payloads {
            wrong.push(format!("{}: downcasts something other than a panic's payload", rel.display()));
        }
    }
    assert!(wrong.is_empty(), "downcasts:\n{}", wrong.join("\n"));
}

/// Every seed is derived in `seeds`: elsewhere a generator's seed, a split or a stream is keyed
/// by a constant or function of `seeds`, never by a number written in place (which would collide
/// with another stream unseen).
#[test]
fn every_seed_is_keyed_in_seeds() {
    let src = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let mut wrong = Vec::new();
    for f in &files {
        let rel = f.strip_prefix(&src).unwrap();
        if rel == Path::new("seeds.rs") {
            continue;
        }
        let text = code(f);
        for call in ["seed_from_u64(", "split_seed(", "stream(", "fixed_stream(", "from_seed("] {
            let mut rest = text.as_str();
            while let Some(i) = rest.find(call) {
                rest = &rest[i + call.len()..];
                // The arguments, to the parenthesis that closes the call.
                let mut depth = 1;
                let end = rest
                    .char_indices()
                    .find(|&(_, c)| {
                        depth += match c {
                            '(' => 1,
                            ')' => -1,
                            _ => 0,
                        };
                        depth == 0
                    })
                    .map_or(rest.len(), |(k, _)| k);
                let args = &rest[..end];
                // A number among the arguments themselves (grouping parentheses included); one
                // passed to a function of `seeds` inside them is that function's.
                let mut calls: Vec<bool> = Vec::new();
                let mut token = String::new();
                let mut literal = false;
                let mut last = ' ';
                // The character before the token: a tuple's field (`keys.0`) is no number.
                let mut before = ' ';
                for c in args.chars().chain([' ']) {
                    if c.is_ascii_alphanumeric() || c == '_' {
                        if token.is_empty() {
                            before = last;
                        }
                        token.push(c);
                    } else {
                        literal |= token.starts_with(|d: char| d.is_ascii_digit()) && before != '.' && !calls.contains(&true);
                        token.clear();
                        match c {
                            '(' => calls.push(last.is_ascii_alphanumeric() || last == '_'),
                            ')' => {
                                calls.pop();
                            }
                            _ => {}
                        }
                    }
                    if !c.is_whitespace() {
                        last = c;
                    }
                }
                if literal {
                    wrong.push(format!("{}: {call}{args})", rel.display()));
                }
            }
        }
    }
    assert!(wrong.is_empty(), "seeds written in place:\n{}", wrong.join("\n"));
}
