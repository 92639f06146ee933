//! Embeds the git commit calsim is built from as `CALSIM_GIT_COMMIT`, so that a manifest records
//! the build its binary came from, not the checkout the user runs it in:
//!
//! - `CALSIM_GIT_COMMIT` set in the build's environment wins (a packager building from a source
//!   archive states the commit it was cut from);
//! - else, in a git checkout of calsim, the commit of `HEAD` (40 hex digits), followed by
//!   `-dirty` when a file the crate is built from ([`BUILT_FROM`]) differs from that commit or is
//!   not yet in it;
//! - else `unknown` (a crate without its `.git`: a source archive, a vendored copy, a wheel built
//!   from an sdist, or a copy lying inside some other repository).
//!
//! The script runs again when `HEAD` moves or a file the crate is built from changes: both
//! rebuild the crate anyway, so the commit costs no build of its own.

use std::path::{Path, PathBuf};
use std::process::Command;

/// What the crate is compiled from, relative to its root (the `include_str!`/`include_bytes!`
/// files among them): a change to one of them makes the build `-dirty`. Kept equal to
/// `tests/provenance.rs`'s list.
const BUILT_FROM: [&str; 8] = [
    "src",
    "build.rs",
    "Cargo.toml",
    "Cargo.lock",
    "README.md",
    "docs/library.md",
    "assets/DejaVuSans.ttf",
    "reference/published-figures.toml",
];

fn git(root: &Path, args: &[&str]) -> Option<String> {
    let out = Command::new("git").args(["--no-optional-locks", "-C"]).arg(root).args(args).output().ok().filter(|o| o.status.success())?;
    Some(String::from_utf8(out.stdout).ok()?.trim().to_string())
}

/// The commit of `HEAD` when `root` is a git checkout of this crate (its `build.rs` tracked, so
/// a copy inside another repository does not take that repository's commit), with `-dirty` when
/// [`BUILT_FROM`] differs from it.
fn commit(root: &Path) -> Option<String> {
    git(root, &["ls-files", "--error-unmatch", "build.rs"])?;
    let head = git(root, &["rev-parse", "HEAD"]).filter(|c| c.len() == 40 && c.bytes().all(|b| b.is_ascii_hexdigit()))?;
    let mut status = vec!["status", "--porcelain", "--untracked-files=normal", "--"];
    status.extend(BUILT_FROM);
    let changes = git(root, &status)?;
    Some(if changes.is_empty() { head } else { format!("{head}-dirty") })
}

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-env-changed=CALSIM_GIT_COMMIT");
    let root = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let stated = std::env::var("CALSIM_GIT_COMMIT").ok().map(|c| c.trim().to_string()).filter(|c| !c.is_empty());
    let found = if stated.is_some() { None } else { commit(&root) };
    if found.is_some() {
        // Run again when HEAD moves (HEAD itself, in a linked worktree its own; the branch it
        // names and the packed refs, shared by every worktree) or a file the crate is built from
        // changes (the dirty mark).
        let git_dir = git(&root, &["rev-parse", "--absolute-git-dir"]).map(|d| vec![root.join(d).join("HEAD")]);
        let common = git(&root, &["rev-parse", "--git-common-dir"]).map(|d| {
            let d = root.join(d);
            let branch = git(&root, &["symbolic-ref", "-q", "HEAD"]);
            ["packed-refs".to_string()].into_iter().chain(branch).map(|f| d.join(f)).collect::<Vec<_>>()
        });
        for f in git_dir.into_iter().chain(common).flatten().filter(|f| f.exists()) {
            println!("cargo:rerun-if-changed={}", f.display());
        }
        for p in BUILT_FROM {
            println!("cargo:rerun-if-changed={}", root.join(p).display());
        }
    }
    println!("cargo:rustc-env=CALSIM_GIT_COMMIT={}", stated.or(found).as_deref().unwrap_or("unknown"));
}
