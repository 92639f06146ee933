//! The results directory `out/<name>`: checked before a study starts, replaced atomically when it
//! ends, and cleared of what killed runs left.
//!
//! A run writes everything into `out/.<name>.tmp-<pid>` and then exchanges it with `out/<name>` in
//! one `renameat2(RENAME_EXCHANGE)`: at any instant `out/<name>` is either the old complete
//! results or the new complete results, never a mixture and never missing, even under kill -9.
//! The old results, now under the temporary name, are removed afterwards; if the run is killed
//! first, the next run removes them (a temporary directory whose process is gone is stale).

use std::fs;
use std::io;
use std::path::{Path, PathBuf};

/// Why the results cannot go to `out`.
#[derive(Debug, thiserror::Error)]
pub enum OutDirError {
    /// `out` or `out/<name>` is in the way.
    #[error("{path}: {why}")]
    InTheWay {
        /// The path.
        path: String,
        /// What is wrong and what to do.
        why: String,
    },
    /// The file system refused.
    #[error("{path}: {source}")]
    Io {
        /// The path.
        path: String,
        /// The error.
        source: io::Error,
    },
}

fn io_err(path: &Path) -> impl FnOnce(io::Error) -> OutDirError + '_ {
    move |source| OutDirError::Io { path: path.display().to_string(), source }
}

/// Checks, before anything runs, that the results of `name` can be written under `out`: `out` is
/// (or can be made) a writable directory and `out/<name>` is absent or a directory. Removes the
/// temporary directories of runs that no longer exist. Returns `out/<name>`.
pub fn prepare(out: &Path, name: &str) -> Result<PathBuf, OutDirError> {
    if out.exists() && !out.is_dir() {
        return Err(OutDirError::InTheWay {
            path: out.display().to_string(),
            why: "is not a directory (--out names the directory the results go in)".into(),
        });
    }
    fs::create_dir_all(out).map_err(io_err(out))?;
    let dest = out.join(name);
    if let Ok(meta) = fs::symlink_metadata(&dest)
        && !meta.is_dir()
    {
        return Err(OutDirError::InTheWay {
            path: dest.display().to_string(),
            why: "exists and is not a directory: move it away or choose another --out (it is left as it is)".into(),
        });
    }
    remove_stale(out, name).map_err(io_err(out))?;
    // Writable: make and remove this run's temporary directory now, not after the study.
    let probe = temporary(out, name);
    fs::create_dir(&probe).map_err(io_err(&probe))?;
    fs::remove_dir(&probe).map_err(io_err(&probe))?;
    Ok(dest)
}

/// This process's temporary directory for `name`.
fn temporary(out: &Path, name: &str) -> PathBuf {
    out.join(format!(".{name}.tmp-{}", std::process::id()))
}

/// Removes `out/.<name>.tmp-<pid>` (and the `.old-<pid>` of earlier versions) whose process is gone.
fn remove_stale(out: &Path, name: &str) -> io::Result<()> {
    let prefix = format!(".{name}.");
    for entry in fs::read_dir(out)? {
        let entry = entry?;
        let file = entry.file_name().to_string_lossy().into_owned();
        let Some(rest) = file.strip_prefix(&prefix) else { continue };
        let Some(pid) = rest.strip_prefix("tmp-").or_else(|| rest.strip_prefix("old-")).and_then(|p| p.parse::<u32>().ok()) else {
            continue;
        };
        if pid != std::process::id() && !alive(pid) {
            fs::remove_dir_all(entry.path())?;
        }
    }
    Ok(())
}

/// Whether process `pid` exists (Linux: `/proc/<pid>`; elsewhere every process counts as alive,
/// so nothing of a running process is ever removed).
fn alive(pid: u32) -> bool {
    !Path::new("/proc/self").exists() || Path::new(&format!("/proc/{pid}")).exists()
}

/// Runs `fill` on a fresh temporary directory beside `out/<name>` and puts it in place of
/// `out/<name>` atomically; on failure the temporary directory is removed and `out/<name>` is left
/// as it was.
pub fn write_atomically(out: &Path, name: &str, fill: impl FnOnce(&Path) -> io::Result<()>) -> io::Result<PathBuf> {
    fs::create_dir_all(out)?;
    let dest = out.join(name);
    let tmp = temporary(out, name);
    if tmp.exists() {
        fs::remove_dir_all(&tmp)?;
    }
    fs::create_dir_all(&tmp)?;
    if let Err(e) = fill(&tmp) {
        let _ = fs::remove_dir_all(&tmp);
        return Err(e);
    }
    if dest.is_dir() {
        match rustix::fs::renameat_with(rustix::fs::CWD, &tmp, rustix::fs::CWD, &dest, rustix::fs::RenameFlags::EXCHANGE) {
            Ok(()) => {}
            // A file system without the exchange: the old results go aside first (a window in
            // which out/<name> is missing, the only one, on such file systems alone).
            Err(_) => {
                let old = out.join(format!(".{name}.old-{}", std::process::id()));
                fs::rename(&dest, &old)?;
                fs::rename(&tmp, &dest)?;
                return fs::remove_dir_all(&old).map(|()| dest);
            }
        }
        // `tmp` now holds the old results.
        fs::remove_dir_all(&tmp)?;
    } else {
        fs::rename(&tmp, &dest)?;
    }
    Ok(dest)
}

/// Writes `text` to `path` through `<path>.partial` renamed into place: `path` holds the old or
/// the new text, never a part; on failure the partial file is removed.
pub fn write_file_atomically(path: &Path, text: &str) -> io::Result<()> {
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(".partial");
    let tmp = path.with_file_name(name);
    let result = fs::write(&tmp, text).and_then(|()| fs::rename(&tmp, path));
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    result
}
