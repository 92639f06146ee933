//! The key reference (`calsim keys`, docs/reference.md), `calsim init` and the shell completions:
//! the reference lists every key the loaders take, each with a note, docs/reference.md is its
//! current output, and a started scenario loads.

mod common;

use std::collections::BTreeSet;

use calsim::app::keys;
use calsim::device::REGISTRY;

/// Every leaf key of a TOML table, dotted, arrays of tables as `name[]`.
fn leaf_keys(t: &toml::Table, prefix: &str, out: &mut BTreeSet<String>) {
    for (k, v) in t {
        let key = if prefix.is_empty() { k.clone() } else { format!("{prefix}.{k}") };
        match v {
            toml::Value::Table(inner) => leaf_keys(inner, &key, out),
            toml::Value::Array(a) if a.iter().all(|x| x.is_table()) && !a.is_empty() => {
                for x in a {
                    leaf_keys(x.as_table().expect("a table"), &format!("{key}[]"), out);
                }
            }
            _ => {
                out.insert(key);
            }
        }
    }
}

fn reference_keys(name: &str) -> BTreeSet<String> {
    keys::reference(name).expect("a reference").into_iter().map(|r| r.key).collect()
}

#[test]
fn every_key_of_every_file_has_a_note_and_every_note_names_a_key() {
    for name in keys::names() {
        let (without, stray) = keys::unmatched_notes(name).expect("a reference");
        assert!(without.is_empty(), "{name}: keys without a note in their notes table: {without:?}");
        assert!(stray.is_empty(), "{name}: notes that name no key: {stray:?}");
    }
    assert!(keys::stray_shared_notes().is_empty(), "src/device/keys.toml names no key: {:?}", keys::stray_shared_notes());
}

#[test]
fn the_reference_holds_every_key_the_defaults_and_the_shipped_scenarios_set() {
    let shipped = [
        ("trical", vec!["irb120_trical.toml", "ci_quick.toml", "kr6r900sixx_trical.toml", "lrmate200ic_trical.toml", "irb120_twin.toml"]),
        ("spms", vec!["er20c10_spms.toml", "er20c10_spms_one_station.toml"]),
        ("tracker", vec!["irb120_tracker.toml"]),
    ];
    for (kind, files) in shipped {
        let device = REGISTRY.iter().find(|d| d.kind() == kind).expect("a device");
        let known = reference_keys(kind);
        let mut set = BTreeSet::new();
        leaf_keys(&device.defaults(), "", &mut set);
        for f in files {
            let text = std::fs::read_to_string(common::repo().join("scenarios").join(f)).expect("a shipped scenario");
            leaf_keys(&text.parse().expect("TOML"), "", &mut set);
        }
        let missing: Vec<_> = set.difference(&known).collect();
        assert!(missing.is_empty(), "{kind}: keys set by the defaults or a shipped scenario but not in the reference: {missing:?}");
    }
    let mut set = BTreeSet::new();
    for entry in std::fs::read_dir(common::repo().join("scenarios/sweeps")).expect("the sweeps") {
        let text = std::fs::read_to_string(entry.expect("an entry").path()).expect("a sweep file");
        let mut t: toml::Table = text.parse().expect("TOML");
        // `fixed` holds scenario keys, not sweep keys; an axis' values are scenario values (a
        // layout is a table).
        t.remove("fixed");
        let mut here = BTreeSet::new();
        leaf_keys(&t, "", &mut here);
        set.extend(here.into_iter().map(|k| if k.starts_with("axis[].values") { "axis[].values".to_string() } else { k }));
    }
    let known = reference_keys("sweep");
    let missing: Vec<_> = set.iter().filter(|k| !known.contains(*k)).collect();
    assert!(missing.is_empty(), "sweep keys not in the reference: {missing:?}");
    let mut set = BTreeSet::new();
    for f in ["irb120.toml", "er20c10.toml", "kr6r900sixx.toml", "lrmate200ic.toml", "examples/irb120_twin.toml"] {
        let text = std::fs::read_to_string(common::repo().join("robots").join(f)).expect("a robot file");
        let mut t: toml::Table = text.parse().expect("TOML");
        // [truth] and [std] hold parameter names, not keys of the file.
        t.remove("truth");
        t.remove("std");
        leaf_keys(&t, "", &mut set);
    }
    let known = reference_keys("robot");
    let missing: Vec<_> = set.iter().filter(|k| !known.contains(*k)).collect();
    assert!(missing.is_empty(), "robot file keys not in the reference: {missing:?}");
}

#[test]
fn a_range_checked_key_shows_its_rule_and_a_fitted_key_says_so() {
    let trical = keys::reference("trical").expect("a reference");
    let eps = trical.iter().find(|r| r.key == "trical.epsilon_mm").expect("epsilon");
    assert_eq!((eps.unit, eps.default.as_str()), ("mm", "0.01"));
    assert_eq!(
        eps.rule,
        "within [0.0001, 0.5] (the centring tolerance: the paper uses 0.010 mm; above 0.5 mm the device no longer centres)"
    );
    assert!(eps.note.starts_with("the centring tolerance of Algorithm 1. SOURCED"));
    let harmonic = trical.iter().find(|r| r.key == "robot.unmodelled.transmission_high_mdeg").expect("a key");
    assert!(harmonic.note.contains("FITTED"), "{}", harmonic.note);
    let plate = trical.iter().find(|r| r.key == "cell.plate_offset_mm_deg").expect("a key");
    assert!(
        plate.rule.starts_with("[0, 1, 2]: within [-2000, 2000]") && plate.rule.contains("[3, 4, 5]: within [-90, 90]"),
        "{}",
        plate.rule
    );
    // The SPMS defaults of the shared [study] table are its own.
    let spms = keys::reference("spms").expect("a reference");
    let sizes = spms.iter().find(|r| r.key == "study.set_sizes").expect("a key");
    assert_eq!(sizes.default, "[20, 30, 50, 75, 100]");
}

#[test]
fn docs_reference_md_is_the_current_output_of_calsim_keys_markdown() {
    let current = keys::markdown().expect("the reference");
    let path = common::repo().join("docs/reference.md");
    let written = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        written == current,
        "docs/reference.md is not the current key reference: a key, default, rule or note changed; \
         run `cargo run -- keys --markdown > docs/reference.md`"
    );
}

#[test]
fn calsim_init_writes_a_scenario_of_every_device_that_loads_with_its_defaults() {
    let dir = tempfile::tempdir().expect("a scratch directory");
    for device in REGISTRY {
        let kind = device.kind();
        let file = dir.path().join(format!("{kind}.toml"));
        let out = common::calsim().args(["init", kind]).arg(&file).output().expect("calsim runs");
        assert!(out.status.success(), "{kind}: {}", String::from_utf8_lossy(&out.stderr));
        let loaded = calsim::device::load(&file).unwrap_or_else(|e| panic!("{kind}: the started scenario does not load: {e}"));
        assert_eq!(loaded.device().kind(), kind);
        // Every key it writes is the default: read back, it is the defaults table (less the seed's and kind's place).
        let mut written: toml::Table = std::fs::read_to_string(&file).expect("written").parse().expect("TOML");
        let mut defaults = device.defaults();
        for t in [&mut written, &mut defaults] {
            t.remove("kind");
        }
        assert_eq!(written, defaults, "{kind}: calsim init does not write the defaults");
        // It does not replace a file.
        let again = common::calsim().args(["init", kind]).arg(&file).output().expect("calsim runs");
        assert_eq!(again.status.code(), Some(2));
        assert!(String::from_utf8_lossy(&again.stderr).contains("exists"));
    }
}

#[test]
fn calsim_keys_prints_each_file_and_refuses_an_unknown_one_in_one_line() {
    for name in keys::names() {
        let out = common::calsim().args(["keys", name]).output().expect("calsim runs");
        assert!(out.status.success(), "{name}");
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(text.starts_with(&format!("{name}: ")), "{text}");
    }
    let out = common::calsim().args(["keys", "robots"]).output().expect("calsim runs");
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("\"robots\": one of trical, spms, tracker, sweep, robot"), "{err}");
}

#[test]
fn calsim_completions_writes_a_script_naming_every_command() {
    let out = common::calsim().args(["completions", "bash"]).output().expect("calsim runs");
    assert!(out.status.success());
    let script = String::from_utf8_lossy(&out.stdout);
    for command in ["run", "check", "sweep", "budget", "export", "keys", "init"] {
        assert!(script.contains(command), "{command} is not completed");
    }
    let out = common::calsim().args(["completions", "tcsh"]).output().expect("calsim runs");
    assert_eq!(out.status.code(), Some(2));
}

/// The reference's table holds every row of the reference, column for column, and the terminal's
/// text is rendered from it: each key's line shows its unit and default, its rule and note below.
#[test]
fn the_reference_table_is_the_reference_and_the_text_is_read_from_it() {
    for name in keys::names() {
        let rows = keys::reference(name).expect("a reference");
        let table = keys::table(name).expect("a table");
        assert_eq!(
            table.get_column_names().iter().map(|n| n.as_str()).collect::<Vec<_>>(),
            ["key", "unit", "default", "rule", "note"],
            "{name}"
        );
        assert_eq!(table.height(), rows.len(), "{name}");
        let column = |c: &str| -> Vec<String> {
            let v = table.column(c).unwrap().str().unwrap().clone();
            (0..v.len()).map(|k| v.get(k).expect("no null").to_string()).collect()
        };
        assert_eq!(column("key"), rows.iter().map(|r| r.key.clone()).collect::<Vec<_>>(), "{name}");
        assert_eq!(column("unit"), rows.iter().map(|r| r.unit.to_string()).collect::<Vec<_>>(), "{name}");
        assert_eq!(column("default"), rows.iter().map(|r| r.default.clone()).collect::<Vec<_>>(), "{name}");
        assert_eq!(column("rule"), rows.iter().map(|r| r.rule.clone()).collect::<Vec<_>>(), "{name}");
        assert_eq!(column("note"), rows.iter().map(|r| r.note.clone()).collect::<Vec<_>>(), "{name}");
        let text = keys::text(name).expect("a text");
        assert_eq!(text, keys::text_of(name, &table).expect("a text"));
        let r = &rows[0];
        let unit = if r.unit == "-" { String::new() } else { format!(" ({})", r.unit) };
        assert!(text.contains(&format!("\n\n{}{unit} = {}\n", r.key, r.default)), "{name}: {text}");
        if !r.note.is_empty() {
            assert!(text.contains(&format!("    note: {}\n", r.note)), "{name}");
        }
    }
}
