//! The key reference of the scenario files (`calsim keys`, `docs/reference.md`), made from the
//! definitions the loader checks, so that it cannot go stale:
//!
//! - **which keys**: asked of the loader itself. Every table of a scenario file is a struct with
//!   `deny_unknown_fields`; a probe key put in a table makes the loader refuse it with serde's
//!   "unknown field `__probe__`, expected one of ..." naming every field the table has. Each field
//!   is probed in turn: a table answers with its own fields, a value with a type error. A key
//!   added to a spec is therefore in the reference the moment the loader takes it.
//! - **defaults**: the device's scenario with every key left out, deserialized as the loader does
//!   and written back as TOML (the specs' `Default` impls).
//! - **ranges and rules**: every rule a [`Checker`](super::scenario::Checker) applies while the
//!   defaults are loaded ([`rules_applied`]).
//! - **notes**: SOURCED / ASSUMED / FITTED, from the notes tables kept beside the specs
//!   (`device/keys.toml` for the sections every device shares, `device/<kind>/keys.toml`); a test
//!   fails on a key without a note and on a note without a key.

use std::collections::BTreeMap;
use std::path::Path;

use super::scenario::{Rule, rules_applied};
use super::{Device, ScenarioError};

/// The key no struct of calsim has, put in a table to make its loader list the table's fields.
pub const PROBE: &str = "__probe__";

/// One key of a reference.
#[derive(Clone, Debug, PartialEq)]
pub struct KeyRow {
    /// Dotted key (`robot.unmodelled.transmission_high_mdeg`; `axis[].key` for an array of tables).
    pub key: String,
    /// Unit, from the key's name (`-` where it has none).
    pub unit: &'static str,
    /// Default as TOML (`absent`: the key is optional and has none).
    pub default: String,
    /// The rules the loader checks, `;`-separated (`-` where it checks only the type).
    pub rule: String,
    /// SOURCED / ASSUMED / FITTED note, or what the key is for.
    pub note: String,
}

/// What a loader says of a probed table: the error's key and message, or `None` when it took the
/// file.
pub type Refusal = Option<(String, String)>;

/// The dotted keys a loader accepts, found by probing from `base` (a file it takes).
pub fn accepted_keys(base: &toml::Table, load: &dyn Fn(toml::Table) -> Refusal, also: &[String]) -> Vec<String> {
    let mut out = Vec::new();
    let mut top = fields_at(base, load, &[]).unwrap_or_default();
    for k in also {
        if !top.contains(k) {
            top.push(k.clone());
        }
    }
    for f in top {
        walk(base, load, vec![f], &mut out);
    }
    out
}

fn walk(base: &toml::Table, load: &dyn Fn(toml::Table) -> Refusal, path: Vec<String>, out: &mut Vec<String>) {
    let (fields, path) = match fields_at(base, load, &path) {
        Some(f) => (f, path),
        None => {
            // An array of tables (`[[axis]]`): its fields, probed in its first element.
            let mut element = path.clone();
            let last = element.pop().expect("a path of at least one key");
            element.push(format!("{last}[]"));
            match fields_at(base, load, &element) {
                Some(f) => (f, element),
                None => return out.push(path.join(".")),
            }
        }
    };
    for f in fields {
        let mut p = path.clone();
        p.push(f);
        walk(base, load, p, out);
    }
}

/// The fields the loader lists when `path` holds a probe (`None`: `path` is no table).
fn fields_at(base: &toml::Table, load: &dyn Fn(toml::Table) -> Refusal, path: &[String]) -> Option<Vec<String>> {
    let mut probe = toml::Table::new();
    probe.insert(PROBE.into(), toml::Value::Integer(0));
    let mut t = base.clone();
    put(&mut t, path, toml::Value::Table(probe));
    let (_, message) = load(t)?;
    let rest = message.strip_prefix(&format!("unknown field `{PROBE}`"))?;
    if rest.contains("there are no fields") {
        return Some(Vec::new());
    }
    let expected = rest.split_once("expected")?.1;
    Some(expected.split('`').skip(1).step_by(2).map(str::to_string).collect())
}

/// Puts `v` at `path` in `t`, replacing what is in the way (`name[]` is the first element of an
/// array of tables).
fn put(t: &mut toml::Table, path: &[String], v: toml::Value) {
    let Some((first, rest)) = path.split_first() else {
        if let toml::Value::Table(v) = v {
            t.extend(v);
        }
        return;
    };
    let (name, array) = match first.strip_suffix("[]") {
        Some(n) => (n, true),
        None => (first.as_str(), false),
    };
    let mut inner = match t.remove(name) {
        Some(toml::Value::Table(inner)) if !array => inner,
        _ => toml::Table::new(),
    };
    put(&mut inner, rest, v);
    let value = if array { toml::Value::Array(vec![toml::Value::Table(inner)]) } else { toml::Value::Table(inner) };
    t.insert(name.to_string(), value);
}

/// The refusal of a scenario loader: its key and message.
pub fn refusal(e: ScenarioError) -> (String, String) {
    match e {
        ScenarioError::Parse { key, message, .. } => (key, message),
        ScenarioError::Range { section, key, why, .. } => (format!("{section}.{key}"), why),
        ScenarioError::Read { path, message } => (path, message),
        ScenarioError::Name(e) => (String::new(), e.to_string()),
    }
}

/// The text of a device's scenario file that leaves every key at its default.
pub fn minimal(kind: &str) -> String {
    format!("kind = \"{kind}\"\nseed = 0\n")
}

/// The reference of every key of `device`'s scenario files.
pub fn device_reference(device: &dyn Device) -> Vec<KeyRow> {
    let text = minimal(device.kind());
    let path = Path::new("defaults.toml");
    let base: toml::Table = text.parse().expect("the minimal scenario is TOML");
    let load = |t: toml::Table| device.load(&text, t, path).err().map(refusal);
    let defaults = device.defaults();
    let sections: Vec<String> = defaults.keys().cloned().collect();
    let keys = accepted_keys(&base, &load, &sections);
    let (loaded, rules) = rules_applied(|| device.load(&text, base.clone(), path));
    if let Err(e) = loaded {
        // The defaults are checked by the tests; a reference of a device whose defaults its own
        // loader refuses would be wrong, so it says so.
        panic!("{}: its defaults do not load: {e}", device.kind());
    }
    rows(&keys, &defaults, &rules, &notes(device.notes()))
}

/// The rows of `keys` with their defaults, rules and notes.
pub fn rows(keys: &[String], defaults: &toml::Table, rules: &[Rule], notes: &BTreeMap<String, String>) -> Vec<KeyRow> {
    keys.iter()
        .map(|k| KeyRow {
            key: k.clone(),
            unit: unit(k),
            default: lookup(defaults, k).map_or_else(|| "absent".to_string(), inline),
            rule: rule_of(k, rules),
            note: note_of(k, notes).unwrap_or_default(),
        })
        .collect()
}

/// The notes of tables of `dotted key = note` (TOML text each).
pub fn notes(tables: &[&str]) -> BTreeMap<String, String> {
    let mut out = BTreeMap::new();
    for text in tables {
        let t: toml::Table = text.parse().expect("a notes table is TOML");
        for (k, v) in t {
            out.insert(k, v.as_str().expect("a note is a string").to_string());
        }
    }
    out
}

/// The note of `key`, or of the table it belongs to (a band's `value` and `tolerance`).
pub fn note_of(key: &str, notes: &BTreeMap<String, String>) -> Option<String> {
    let mut k = key;
    loop {
        if let Some(n) = notes.get(k) {
            return Some(n.clone());
        }
        k = k.rsplit_once('.')?.0;
    }
}

/// A value as it reads in a TOML file, on one line.
fn inline(v: &toml::Value) -> String {
    match v {
        toml::Value::Table(t) if t.is_empty() => "{}".into(),
        toml::Value::Table(t) => {
            let parts: Vec<String> = t.iter().map(|(k, v)| format!("{k} = {}", inline(v))).collect();
            format!("{{ {} }}", parts.join(", "))
        }
        toml::Value::Array(a) => format!("[{}]", a.iter().map(inline).collect::<Vec<_>>().join(", ")),
        other => other.to_string(),
    }
}

fn lookup<'a>(t: &'a toml::Table, dotted: &str) -> Option<&'a toml::Value> {
    let mut parts = dotted.split('.');
    let mut v = t.get(parts.next()?)?;
    for p in parts {
        v = v.as_table()?.get(p)?;
    }
    Some(v)
}

/// Units by the ending of a key's name, longest first (the project's rule: the unit in the name).
const UNITS: &[(&str, &str)] = &[
    ("_mdeg_per_nm", "mdeg/(N m)"),
    ("_mdeg_per_m", "mdeg/m"),
    ("_mm_per_pose", "mm per pose"),
    ("_pct_fs_per_c", "% of full scale per degC"),
    ("_um_per_m", "um/m"),
    ("_mm_per_m", "mm/m"),
    ("_mm_deg", "mm, deg"),
    ("_pct_fs", "% of full scale"),
    ("_mdeg", "mdeg"),
    ("_deg", "deg"),
    ("_mm", "mm"),
    ("_um", "um"),
    ("_kg", "kg"),
    ("_ppm", "ppm"),
    ("_m_s2", "m/s^2"),
    ("_c", "degC"),
    ("_s", "s"),
];

/// The unit of a key: from its name, or for a band's `value` from the band's name.
pub fn unit(key: &str) -> &'static str {
    let mut segments = key.rsplit('.');
    let last = segments.next().unwrap_or_default();
    let named = if last == "value" { segments.next().unwrap_or_default() } else { last };
    let named = named.trim_end_matches("[]");
    UNITS.iter().find(|(end, _)| named.ends_with(end)).map_or("-", |(_, u)| u)
}

/// The rules applied to `key` (its elements' rules merged: `tcp_mm[0]`, `tcp_mm[1]`, ...; where
/// elements differ, each rule with the indices it applies to).
fn rule_of(key: &str, rules: &[Rule]) -> String {
    let mut found: Vec<(String, Vec<String>)> = Vec::new();
    let mut all_indices: Vec<String> = Vec::new();
    for r in rules {
        let full = if r.section.is_empty() { r.key.clone() } else { format!("{}.{}", r.section, r.key) };
        let (name, index) = match full.find('[') {
            Some(i) => (&full[..i], full[i..].to_string()),
            None => (full.as_str(), String::new()),
        };
        if name != key {
            continue;
        }
        // The first index names the element ([i][k]: sphere i).
        let first = index.split(']').next().map(|s| s.trim_start_matches('[').to_string()).unwrap_or_default();
        if !first.is_empty() && !all_indices.contains(&first) {
            all_indices.push(first.clone());
        }
        let text = r.rule.strip_prefix("must be ").unwrap_or(&r.rule).to_string();
        match found.iter_mut().find(|(t, _)| *t == text) {
            Some((_, idx)) => {
                if !first.is_empty() && !idx.contains(&first) {
                    idx.push(first)
                }
            }
            None => found.push((text, if first.is_empty() { vec![] } else { vec![first] })),
        }
    }
    if found.is_empty() {
        return "-".into();
    }
    found
        .iter()
        .map(
            |(text, idx)| {
                if idx.is_empty() || idx.len() == all_indices.len() { text.clone() } else { format!("[{}]: {text}", idx.join(", ")) }
            },
        )
        .collect::<Vec<_>>()
        .join("; ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Inner {
        a_mm: f64,
        b: Option<u32>,
    }

    #[derive(serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Outer {
        seed: u64,
        #[serde(default)]
        inner: Option<Inner>,
        #[serde(default)]
        rows: Vec<Inner>,
    }

    fn load(t: toml::Table) -> Refusal {
        crate::device::scenario::deserialize::<Outer>(t, "probe.toml").err().map(refusal)
    }

    #[test]
    fn probing_a_loader_finds_every_field_of_its_tables_and_arrays_of_tables() {
        let base: toml::Table = "seed = 1".parse().unwrap();
        let keys = accepted_keys(&base, &load, &[]);
        assert_eq!(keys, ["seed", "inner.a_mm", "inner.b", "rows[].a_mm", "rows[].b"]);
    }

    #[test]
    fn units_come_from_the_key_names() {
        assert_eq!(unit("robot.unmodelled.transmission_high_mdeg"), "mdeg");
        assert_eq!(unit("robot.spread.compliance_mdeg_per_nm"), "mdeg/(N m)");
        assert_eq!(unit("learned.sag_mdeg_per_m"), "mdeg/m");
        assert_eq!(unit("expect.after_median_mm.value"), "mm");
        assert_eq!(unit("expect.after_median_mm.tolerance"), "-");
        assert_eq!(unit("study.repetitions"), "-");
    }

    #[test]
    fn the_rules_of_an_array_are_merged_and_name_their_elements_where_they_differ() {
        let r = |key: &str, rule: &str| Rule { section: "cell".into(), key: key.into(), rule: rule.into() };
        let rules = [
            r("x_mm_deg[0]", "must be within [-1, 1] (mm)"),
            r("x_mm_deg[1]", "must be within [-2, 2] (deg)"),
            r("y_mm[0]", "a"),
            r("y_mm[1]", "a"),
        ];
        assert_eq!(rule_of("cell.x_mm_deg", &rules), "[0]: within [-1, 1] (mm); [1]: within [-2, 2] (deg)");
        assert_eq!(rule_of("cell.y_mm", &rules), "a");
        assert_eq!(rule_of("cell.z", &rules), "-");
    }
}
