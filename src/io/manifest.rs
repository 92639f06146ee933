//! The provenance block every `manifest.json` carries, the same for every producer (a run of any
//! device, a sweep, a budget, an optimisation, an export): the calsim version and the git commit
//! the binary was built from (embedded at build time by `build.rs`: `-dirty` after it when a file
//! the crate is compiled from differed from that commit, `unknown` for a build outside a git
//! checkout of calsim), the command line, every input file with its sha256 ([`crate::io::inputs`]) and
//! the overrides. Threads are not recorded: no result depends on them.
//!
//! A run of a scenario adds its head ([`ScenarioHead`]): the scenario's name, absolute path,
//! sha256 and seed, everything needed to redo any of its tasks.

use std::path::Path;

use serde::Serialize;
use sha2::{Digest, Sha256};

use crate::io::inputs::Input;

/// The git commit calsim was built from: 40 hex digits, followed by `-dirty` when a file the crate
/// is compiled from differed from it; `unknown` when built outside a git checkout of calsim
/// (`build.rs`).
pub const GIT_COMMIT: &str = env!("CALSIM_GIT_COMMIT");

/// The block every manifest carries (flattened into it: `crate_version`, `git_commit`,
/// `command_line`, `inputs`, `overrides`).
#[derive(Clone, Debug, Serialize)]
pub struct Provenance {
    crate_version: &'static str,
    git_commit: &'static str,
    command_line: Vec<String>,
    inputs: Vec<Input>,
    overrides: Vec<(String, String)>,
}

impl Provenance {
    /// The provenance of the command running in this process, with `overrides` (`key`, TOML
    /// value): its command line and the inputs its ledger recorded so far
    /// ([`crate::io::inputs::of_run`]).
    pub fn of_run(overrides: &[(String, String)]) -> Self {
        Self {
            crate_version: env!("CARGO_PKG_VERSION"),
            git_commit: GIT_COMMIT,
            command_line: std::env::args_os().map(|a| a.to_string_lossy().into_owned()).collect(),
            inputs: crate::io::inputs::of_run(),
            overrides: overrides.to_vec(),
        }
    }

    /// `manifest`, a JSON object of a producer's own fields, with the block's fields added (the
    /// same fields and serialisation as a manifest struct that flattens the block).
    pub fn joined(self, manifest: serde_json::Value) -> Result<serde_json::Value, serde_json::Error> {
        let serde_json::Value::Object(mut fields) = manifest else {
            return Err(serde::ser::Error::custom("a manifest is a JSON object"));
        };
        let serde_json::Value::Object(block) = serde_json::to_value(self)? else {
            return Err(serde::ser::Error::custom("the provenance block is a JSON object"));
        };
        fields.extend(block);
        Ok(serde_json::Value::Object(fields))
    }
}

/// The head of a run's manifest: which scenario (name, absolute path, sha256) and seed, and the
/// provenance block.
#[derive(Serialize)]
pub struct ScenarioHead<'a> {
    scenario: &'a str,
    scenario_path: String,
    scenario_sha256: String,
    seed: u64,
    #[serde(flatten)]
    provenance: Provenance,
}

impl<'a> ScenarioHead<'a> {
    /// The head of a run of the scenario `name` read from `path` with `text`, with `overrides`
    /// (`key`, `value`) applied; the path is made absolute so that the results can be used from
    /// any directory.
    pub fn new(name: &'a str, path: &Path, text: &str, seed: u64, overrides: &[(String, String)]) -> Self {
        let absolute = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
        Self {
            scenario: name,
            scenario_path: absolute.display().to_string(),
            scenario_sha256: format!("{:x}", Sha256::digest(text.as_bytes())),
            seed,
            provenance: Provenance::of_run(overrides),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_block_has_the_version_the_built_commit_the_command_line_the_inputs_and_no_threads() {
        let tmp = tempfile::Builder::new().prefix("calsim-manifest-").tempdir().unwrap();
        let input = tmp.path().join("s.toml");
        std::fs::write(&input, "seed = 1\n").unwrap();
        let _ledger = crate::io::inputs::Ledger::open();
        crate::io::read_text(&input).unwrap();
        let v = serde_json::to_value(ScenarioHead::new("s", &input, "seed = 1\n", 1, &[("seed".into(), "1".into())])).unwrap();
        assert_eq!(v["crate_version"], env!("CARGO_PKG_VERSION"));
        let commit = v["git_commit"].as_str().unwrap();
        let hex = commit.strip_suffix("-dirty").unwrap_or(commit);
        assert!(commit == "unknown" || (hex.len() == 40 && hex.bytes().all(|b| b.is_ascii_hexdigit())), "{commit}");
        assert!(v["command_line"].as_array().is_some_and(|a| !a.is_empty()));
        let real = std::fs::canonicalize(&input).unwrap().display().to_string();
        let listed = v["inputs"].as_array().unwrap().iter().find(|i| i["path"] == real.as_str()).expect("the input listed");
        assert_eq!(listed["sha256"], format!("{:x}", Sha256::digest(b"seed = 1\n")));
        assert_eq!(v["overrides"], serde_json::json!([["seed", "1"]]));
        assert_eq!(v["scenario_sha256"], listed["sha256"]);
        assert!(v.get("threads").is_none());
    }
}
