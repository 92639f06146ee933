//! The results directory `out/<name>`: checked before a study starts, replaced atomically when it
//! ends, and cleared of what killed runs left; and every output path vetted before the work
//! starts ([`vet_dir`], [`vet_file`]): an output is never an input, a device, a pipe or a socket,
//! and never lies inside the results of another run.
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
    move |source| OutDirError::Io { path: shown(path), source }
}

fn in_the_way(path: &Path, why: impl Into<String>) -> OutDirError {
    OutDirError::InTheWay { path: shown(path), why: why.into() }
}

/// `path` made absolute with its existing part resolved (symbolic links, `..`), so that its
/// ancestors are the directories it really lies in.
fn resolved(path: &Path) -> PathBuf {
    let absolute = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    let mut existing = absolute.as_path();
    let mut rest = Vec::new();
    loop {
        if let Ok(real) = fs::canonicalize(existing) {
            return rest.iter().rev().fold(real, |p, c| p.join(c));
        }
        match (existing.parent(), existing.file_name()) {
            (Some(parent), Some(name)) => {
                rest.push(name.to_os_string());
                existing = parent;
            }
            _ => return absolute,
        }
    }
}

/// Whether `dir` holds the `manifest.json` of a calsim result (a run, sweep, budget, export or
/// calibration): a JSON object with calsim's `crate_version`.
pub fn is_results_dir(dir: &Path) -> bool {
    let manifest = dir.join("manifest.json");
    if !manifest.is_file() {
        return false;
    }
    crate::io::read_bytes(&manifest)
        .ok()
        .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok())
        .is_some_and(|v| v.get("crate_version").is_some())
}

/// Refuses an output directory `out` that is, or lies inside, the results directory of another
/// run (one holding calsim's `manifest.json`): results written there would mix with those, and a
/// later run of that directory's own scenario would remove them. Checked before any work.
pub fn vet_dir(out: &Path) -> Result<(), OutDirError> {
    inside_results(out, &resolved(out))
}

/// The error for `out` when `real` (its resolved path) lies in a results directory.
fn inside_results(out: &Path, real: &Path) -> Result<(), OutDirError> {
    match real.ancestors().find(|d| is_results_dir(d)) {
        None => Ok(()),
        Some(results) if results == real => Err(in_the_way(
            out,
            "is the results directory of another run (it holds a calsim manifest.json): choose an --out outside other results",
        )),
        Some(results) => Err(in_the_way(
            out,
            format!(
                "lies inside the results directory {} (it holds a calsim manifest.json): choose an --out outside other results",
                shown(results)
            ),
        )),
    }
}

/// What kind of file system object `meta` is, when it is not a regular file.
fn kind(meta: &fs::Metadata) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    let t = meta.file_type();
    if t.is_dir() {
        "a directory"
    } else if t.is_char_device() || t.is_block_device() {
        "a device"
    } else if t.is_fifo() {
        "a pipe (FIFO)"
    } else if t.is_socket() {
        "a socket"
    } else {
        "not a regular file"
    }
}

/// Refuses, before any work, an output file `out` that cannot be written in place of what is
/// there: an existing object that is not a regular file (a device, a pipe, a socket, a directory),
/// one of the command's `inputs` (the same file under any name), a file inside the results of
/// another run ([`vet_dir`]), or a file whose directory does not exist.
pub fn vet_file(out: &Path, inputs: &[&Path]) -> Result<(), OutDirError> {
    use std::os::unix::fs::MetadataExt;
    if let Ok(meta) = fs::metadata(out) {
        if !meta.is_file() {
            return Err(in_the_way(out, format!("is {}: --out names a regular file calsim writes (it is left as it is)", kind(&meta))));
        }
        for input in inputs {
            if let Ok(m) = fs::metadata(input)
                && (m.dev(), m.ino()) == (meta.dev(), meta.ino())
            {
                return Err(in_the_way(
                    out,
                    format!("is the input {}: writing it would replace it; choose another --out (it is left as it is)", shown(input)),
                ));
            }
        }
    }
    let real = resolved(out);
    let parent = real.parent().map(Path::to_path_buf).unwrap_or_default();
    if !parent.is_dir() {
        return Err(in_the_way(out, format!("its directory {} does not exist", shown(&parent))));
    }
    inside_results(out, &real)
}

/// Checks, before anything runs, that the results of `name` can be written under `out`: `name` is
/// one plain path component ([`crate::io::names`]), `out` is (or can be made) a writable directory
/// outside other results ([`vet_dir`]) and `out/<name>` is absent or a directory. Removes the
/// temporary directories of runs that no longer exist. Returns `out/<name>`.
pub fn prepare(out: &Path, name: &str) -> Result<PathBuf, OutDirError> {
    if let Some(why) = crate::io::names::rule_broken(name) {
        return Err(bad_name(out, name, why));
    }
    vet_dir(out)?;
    if out.exists() && !out.is_dir() {
        return Err(in_the_way(out, "is not a directory (--out names the directory the results go in)"));
    }
    fs::create_dir_all(out).map_err(io_err(out))?;
    let dest = out.join(name);
    if let Ok(meta) = fs::symlink_metadata(&dest)
        && !meta.is_dir()
    {
        return Err(in_the_way(&dest, "exists and is not a directory: move it away or choose another --out (it is left as it is)"));
    }
    remove_stale(out, name).map_err(io_err(out))?;
    // Writable: make and remove this run's temporary directory now, not after the study.
    let probe = temporary(out, name);
    fs::create_dir(&probe).map_err(io_err(&probe))?;
    fs::remove_dir(&probe).map_err(io_err(&probe))?;
    Ok(dest)
}

fn bad_name(out: &Path, name: &str, why: &str) -> OutDirError {
    in_the_way(out, format!("the results name \"{}\" cannot be a directory name: {why}", crate::io::names::escape_controls(name)))
}

/// `path` as shown in a message (control characters escaped).
fn shown(path: &Path) -> String {
    crate::io::names::shown(path)
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
/// `out/<name>` atomically; on failure the temporary directory is removed, `out/<name>` is left
/// as it was and the error names `<name>` (and the file, when `fill` wrote through
/// [`write_file`]). `name` and `out` are vetted as by [`prepare`] first.
pub fn write_atomically(out: &Path, name: &str, fill: impl FnOnce(&Path) -> io::Result<()>) -> io::Result<PathBuf> {
    if let Some(why) = crate::io::names::rule_broken(name) {
        return Err(io::Error::new(io::ErrorKind::InvalidInput, bad_name(out, name, why).to_string()));
    }
    vet_dir(out).map_err(|e| io::Error::new(io::ErrorKind::InvalidInput, e.to_string()))?;
    fs::create_dir_all(out)?;
    let dest = out.join(name);
    let tmp = temporary(out, name);
    if tmp.exists() {
        fs::remove_dir_all(&tmp)?;
    }
    fs::create_dir_all(&tmp)?;
    if let Err(e) = fill(&tmp) {
        let _ = fs::remove_dir_all(&tmp);
        return Err(io::Error::new(e.kind(), format!("{}: {e}", crate::io::names::escape_controls(name))));
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

/// Writes `contents` to the file `path`; an error names the file (`summary.md: No space left on
/// device`), so that a failure inside a results directory says where.
pub fn write_file(path: &Path, contents: impl AsRef<[u8]>) -> io::Result<()> {
    fs::write(path, contents).map_err(named(path))
}

/// An I/O error at `path` as one that names the file (its name only: the directory is named by
/// whoever called).
pub fn named(path: &Path) -> impl FnOnce(io::Error) -> io::Error + '_ {
    move |e| {
        let file = path.file_name().map_or_else(|| shown(path), |n| crate::io::names::escape_controls(&n.to_string_lossy()));
        io::Error::new(e.kind(), format!("{file}: {e}"))
    }
}

/// Writes `text` to `path` through `<path>.partial` renamed into place: `path` holds the old or
/// the new text, never a part; on failure the partial file is removed. A `path` that exists and is
/// not a regular file (a device, a pipe) is refused and left as it is; a symbolic link to a file
/// keeps pointing at it, the file replaced.
pub fn write_file_atomically(path: &Path, text: &str) -> io::Result<()> {
    let path = match fs::metadata(path) {
        Ok(meta) if !meta.is_file() => {
            return Err(io::Error::new(io::ErrorKind::InvalidInput, format!("is {}: calsim writes regular files only", kind(&meta))));
        }
        Ok(_) if fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_symlink()) => fs::canonicalize(path)?,
        _ => path.to_path_buf(),
    };
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(".partial");
    let tmp = path.with_file_name(name);
    // A partial file of a killed run, or anything else under that name, goes first; the new one is
    // created afresh (never opened through what was there).
    if fs::symlink_metadata(&tmp).is_ok_and(|m| !m.is_dir()) {
        fs::remove_file(&tmp)?;
    }
    let result = fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&tmp)
        .and_then(|mut f| std::io::Write::write_all(&mut f, text.as_bytes()))
        .and_then(|()| fs::rename(&tmp, &path));
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch() -> tempfile::TempDir {
        tempfile::Builder::new().prefix("calsim-out-dir-").tempdir().unwrap()
    }

    #[test]
    fn an_output_file_that_is_an_input_a_device_or_a_pipe_is_refused() {
        let tmp = scratch();
        let input = tmp.path().join("arm.urdf");
        fs::write(&input, "x").unwrap();
        let other_name = tmp.path().join("./sub/../arm.urdf");
        fs::create_dir(tmp.path().join("sub")).unwrap();
        for (out, says) in [(&input, "is the input"), (&other_name, "is the input")] {
            let e = vet_file(out, &[&input]).unwrap_err().to_string();
            assert!(e.contains(says), "{e}");
        }
        assert!(vet_file(Path::new("/dev/null"), &[&input]).unwrap_err().to_string().contains("is a device"));
        let fifo = tmp.path().join("fifo.toml");
        rustix::fs::mknodat(rustix::fs::CWD, &fifo, rustix::fs::FileType::Fifo, rustix::fs::Mode::RUSR | rustix::fs::Mode::WUSR, 0)
            .unwrap();
        assert!(vet_file(&fifo, &[&input]).unwrap_err().to_string().contains("pipe"));
        assert!(vet_file(&tmp.path().join("no/such/dir/x.toml"), &[]).unwrap_err().to_string().contains("does not exist"));
        assert!(vet_file(&tmp.path().join("new.toml"), &[&input]).is_ok());
        // The kit's writer refuses a device itself, whoever calls it.
        assert!(write_file_atomically(Path::new("/dev/null"), "x").is_err());
    }

    #[test]
    fn outputs_inside_the_results_of_another_run_are_refused() {
        let tmp = scratch();
        let results = tmp.path().join("results/ci_quick");
        fs::create_dir_all(&results).unwrap();
        fs::write(results.join("manifest.json"), r#"{"scenario": "ci_quick", "crate_version": "0.1.0"}"#).unwrap();
        for out in [results.clone(), results.join("deeper"), results.join("a/b/c")] {
            assert!(vet_dir(&out).unwrap_err().to_string().contains("manifest.json"), "{}", out.display());
        }
        assert!(vet_file(&results.join("x.csv"), &[]).unwrap_err().to_string().contains("inside the results directory"));
        assert!(prepare(&results, "other").is_err());
        // Beside the results, and a manifest.json that is not calsim's, are fine.
        assert!(vet_dir(&tmp.path().join("results")).is_ok());
        let foreign = tmp.path().join("foreign");
        fs::create_dir(&foreign).unwrap();
        fs::write(foreign.join("manifest.json"), r#"{"name": "a web app"}"#).unwrap();
        assert!(vet_dir(&foreign).is_ok());
    }

    #[test]
    fn a_write_error_names_the_file_and_a_full_disk_says_so() {
        let e = write_file(Path::new("/dev/full"), "x".repeat(1 << 16)).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::StorageFull);
        assert!(e.to_string().starts_with("full: No space left on device"), "{e}");
        // Through write_atomically, the results' name and the file.
        let tmp = scratch();
        let e = write_atomically(tmp.path(), "run", |_| write_file(Path::new("/dev/full"), "x")).unwrap_err();
        assert!(e.to_string().starts_with("run: full: No space left"), "{e}");
        assert_eq!(fs::read_dir(tmp.path()).unwrap().count(), 0, "no temporary directory left");
    }

    #[test]
    fn a_symbolic_link_to_the_output_keeps_pointing_at_the_new_file() {
        let tmp = scratch();
        let target = tmp.path().join("target.csv");
        let link = tmp.path().join("link.csv");
        fs::write(&target, "old").unwrap();
        std::os::unix::fs::symlink(&target, &link).unwrap();
        write_file_atomically(&link, "new").unwrap();
        assert!(fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
        assert_eq!(fs::read_to_string(&target).unwrap(), "new");
    }

    #[test]
    fn names_that_are_not_one_path_component_make_no_directory() {
        let tmp = scratch();
        for name in [".", "..", "", "a/b", "a\nb"] {
            assert!(prepare(tmp.path(), name).is_err(), "{name:?}");
            assert!(write_atomically(tmp.path(), name, |_| Ok(())).is_err(), "{name:?}");
        }
        assert_eq!(fs::read_dir(tmp.path()).unwrap().count(), 0);
    }
}
