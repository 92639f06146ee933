//! The provenance every `manifest.json` starts with: which scenario (name, absolute path,
//! sha256), seed, the command-line overrides applied to it, threads, crate version and git commit:
//! everything needed to redo any of its tasks.

use std::path::Path;

use serde::Serialize;
use sha2::{Digest, Sha256};

/// Where a result came from: the head of every `manifest.json`.
#[derive(Serialize)]
pub struct Provenance<'a> {
    scenario: &'a str,
    scenario_path: String,
    scenario_sha256: String,
    seed: u64,
    overrides: Vec<(String, String)>,
    threads: usize,
    crate_version: &'static str,
    git_commit: String,
}

impl<'a> Provenance<'a> {
    /// The provenance of a run of the scenario `name` read from `path` with `text`, with
    /// `overrides` (`key`, `value`) applied; the path is made absolute so that the results can be
    /// used from any directory.
    pub fn new(name: &'a str, path: &Path, text: &str, seed: u64, overrides: &[(String, String)], threads: usize) -> Self {
        let absolute = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
        Self {
            scenario: name,
            scenario_path: absolute.display().to_string(),
            scenario_sha256: format!("{:x}", Sha256::digest(text.as_bytes())),
            seed,
            overrides: overrides.to_vec(),
            threads,
            crate_version: env!("CARGO_PKG_VERSION"),
            git_commit: git_commit(),
        }
    }
}

/// The git commit calsim was built from (`unknown` outside a checkout).
pub fn git_commit() -> String {
    std::process::Command::new("git")
        .args(["rev-parse", "HEAD"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .unwrap_or_else(|| "unknown".into())
}
