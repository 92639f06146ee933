//! Embeds the git commit calsim is built from as `CALSIM_GIT_COMMIT` (`unknown` when the source is
//! not a git checkout or git is absent, e.g. a build from a tarball), so that a manifest records
//! the build its binary came from, not the checkout the user runs it in.

use std::path::PathBuf;
use std::process::Command;

fn git(args: &[&str]) -> Option<String> {
    let out = Command::new("git").args(args).output().ok().filter(|o| o.status.success())?;
    let text = String::from_utf8(out.stdout).ok()?.trim().to_string();
    (!text.is_empty()).then_some(text)
}

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    let commit = git(&["rev-parse", "HEAD"]).filter(|c| c.len() == 40 && c.bytes().all(|b| b.is_ascii_hexdigit()));
    if commit.is_some() {
        // Built again when HEAD moves: HEAD itself, the branch it names, the packed refs.
        for dir in [git(&["rev-parse", "--git-dir"]), git(&["rev-parse", "--git-common-dir"])].into_iter().flatten() {
            let dir = PathBuf::from(dir);
            for f in ["HEAD", "packed-refs"] {
                if dir.join(f).exists() {
                    println!("cargo:rerun-if-changed={}", dir.join(f).display());
                }
            }
            if let Some(branch) = git(&["symbolic-ref", "-q", "HEAD"])
                && dir.join(&branch).exists()
            {
                println!("cargo:rerun-if-changed={}", dir.join(&branch).display());
            }
        }
    }
    println!("cargo:rustc-env=CALSIM_GIT_COMMIT={}", commit.as_deref().unwrap_or("unknown"));
}
