//! The one writer of results and its one safety rule. The results directory `out/<name>` is
//! checked before a study starts, replaced atomically when it ends, and cleared of what killed runs
//! left; every output path is vetted before the work starts ([`prepare`], [`vet_dir`],
//! [`vet_output_file`]).
//!
//! The rule, the same for every command: calsim replaces or deletes only what it made.
//! - A directory it would replace (`out/<name>`) must be absent, empty, or a calsim results
//!   directory (recognised by its `manifest.json`, [`is_results_dir`]); a work directory
//!   (a sweep's shard) must be absent, empty or hold its marker file ([`prepare_work`]); a cache
//!   that calsim only adds to ([`prepare_cache`]) is never deleted.
//! - Never one that holds, or is, an input of the run: every file the command read so far
//!   ([`crate::io::inputs`]: the scenario, the design or sweep file, their base scenarios, the robot
//!   file a scenario names, measurements, targets, files named by keys).
//! - Never an output file (`--junit`, the `--out` of one file) that is one of those inputs, a
//!   device, a pipe or a directory, nor one inside the results of another run.
//! - Symbolic links are resolved: a link into any of these is refused as they are.
//!
//! A refusal is one line naming the flag, the path and why, found before anything runs; the
//! atomic swap checks the rule again, so that nothing the rule protects is ever replaced.
//!
//! Single files go in place the same way: an output file through `<file>.partial`
//! ([`write_file_atomically`]), a file of a cache that a worker pool and shards fill at once
//! through a temporary of its process and thread ([`write_cache_file`]); no other module renames
//! a file into place.
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
    /// The rule refuses an output of a command: the flag, the path and why.
    #[error("{flag} {path}: {why}")]
    Refused {
        /// The option that named the output (`--out`, `--junit`).
        flag: String,
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

fn resolved(path: &Path) -> PathBuf {
    crate::io::inputs::resolved(path)
}

fn refused(flag: &str, path: &Path, why: impl Into<String>) -> OutDirError {
    OutDirError::Refused { flag: flag.to_string(), path: shown(path), why: why.into() }
}

/// Whether `dir` holds the `manifest.json` of a calsim result (a run, sweep, budget, optimisation,
/// export or calibration): a JSON object with calsim's `crate_version` (its provenance block,
/// [`crate::io::manifest::Provenance`]).
pub fn is_results_dir(dir: &Path) -> bool {
    let manifest = dir.join("manifest.json");
    if !manifest.is_file() {
        return false;
    }
    crate::io::read_own(&manifest, crate::io::MOST_INPUT_BYTES)
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

/// [`vet_output_file`] of the output file named by `--out`.
pub fn vet_file(out: &Path, inputs: &[&Path]) -> Result<(), OutDirError> {
    vet_output_file("--out", out, inputs)
}

/// Why an output file is refused where a file (or a link, even a dangling one) already is.
const EXISTS: &str = "the file exists: an output file is always a new one (calsim cannot tell a file it wrote from a user's, so it replaces none); remove it or choose another name (it is left as it is)";

/// Refuses, before any work, an output file `out` (named by the option `flag`) that cannot be
/// written: an existing object that is not a regular file (a device, a pipe, a socket, a
/// directory), an input of the command (one of `inputs` or any file it read so far,
/// [`crate::io::inputs`]; the same file under any name, through any link), any other file or link
/// already there (calsim's single-file outputs are new files: [`write_output_file`]), a file inside
/// the results of another run ([`vet_dir`]), or a file whose directory does not exist.
pub fn vet_output_file(flag: &str, out: &Path, inputs: &[&Path]) -> Result<(), OutDirError> {
    use std::os::unix::fs::MetadataExt;
    if fs::symlink_metadata(out).is_ok() && fs::metadata(out).is_err() {
        return Err(refused(flag, out, EXISTS));
    }
    if let Ok(meta) = fs::metadata(out) {
        if !meta.is_file() {
            return Err(refused(flag, out, format!("is {}: {flag} names a regular file calsim writes (it is left as it is)", kind(&meta))));
        }
        let read = crate::io::inputs::read_so_far();
        let all = inputs.iter().map(|p| p.to_path_buf()).chain(read.into_iter().map(|i| i.path));
        for input in all {
            if let Ok(m) = fs::metadata(&input)
                && (m.dev(), m.ino()) == (meta.dev(), meta.ino())
            {
                return Err(refused(
                    flag,
                    out,
                    format!(
                        "is the input {} of this run: writing it would replace it; choose another {flag} (it is left as it is)",
                        shown(&input)
                    ),
                ));
            }
        }
        if !written_by_calsim(out) {
            return Err(refused(flag, out, EXISTS));
        }
    }
    let real = resolved(out);
    let parent = real.parent().map(Path::to_path_buf).unwrap_or_default();
    if !parent.is_dir() {
        return Err(refused(flag, out, format!("its directory {} does not exist", shown(&parent))));
    }
    inside_results(out, &real)
}

/// Why calsim may not replace or delete the directory `dest` (named through the option `flag`),
/// by the rule of this module: it exists and is not a directory (a file, a symbolic link), it is
/// a directory with contents that is not calsim's (`is_ours` says what is), or it holds an input
/// of the command ([`crate::io::inputs::read_so_far`]). `None`: it may be replaced.
fn may_not_replace(flag: &str, dest: &Path, is_ours: &dyn Fn(&Path) -> bool, what: &str) -> Option<OutDirError> {
    let meta = fs::symlink_metadata(dest).ok()?;
    if !meta.is_dir() {
        return Some(refused(flag, dest, "exists and is not a directory: move it away or choose another --out (it is left as it is)"));
    }
    let real = resolved(dest);
    if let Some(i) = crate::io::inputs::read_so_far().into_iter().find(|i| i.path.starts_with(&real)) {
        return Some(refused(
            flag,
            dest,
            format!(
                "holds {}, an input of this run: writing the results there would replace it; choose another {flag} (it is left as it is)",
                shown(&i.path)
            ),
        ));
    }
    let empty = fs::read_dir(dest).map(|mut d| d.next().is_none()).unwrap_or(false);
    (!empty && !is_ours(dest)).then(|| {
        refused(
            flag,
            dest,
            format!(
                "is not {what} (calsim replaces only directories it made): move it away or choose another {flag} (it is left as it is)"
            ),
        )
    })
}

/// [`prepare`] for the results directory `out/<name>`: it may be replaced when it is absent,
/// empty, or a calsim results directory holding no input of the run and nothing but what calsim
/// wrote there (the files its manifest lists, [`listing`]).
fn results_in_the_way(dest: &Path) -> Option<OutDirError> {
    may_not_replace("--out", dest, &is_results_dir, "a calsim results directory (it has no calsim manifest.json)")
        .or_else(|| not_written_by_calsim(dest).map(|why| refused("--out", dest, why)))
}

/// Why the calsim results directory `dest` holds something calsim did not write there: an entry
/// its manifest's `files` does not list (a file a user added), or no such list. `None` when every
/// entry is listed (or `dest` is absent or empty).
fn not_written_by_calsim(dest: &Path) -> Option<String> {
    let present = listing(dest).ok()?;
    if present.is_empty() {
        return None;
    }
    let listed: Option<Vec<String>> = crate::io::read_own(&dest.join("manifest.json"), crate::io::MOST_INPUT_BYTES)
        .ok()
        .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok())
        .and_then(|v| serde_json::from_value(v.get("files")?.clone()).ok());
    let Some(listed) = listed else {
        return Some(
            "is a calsim results directory whose manifest.json lists no files (written by an earlier calsim), so calsim cannot \
             tell its files from others: move it away or choose another --out (it is left as it is)"
                .into(),
        );
    };
    let listed: std::collections::BTreeSet<&str> = listed.iter().map(String::as_str).collect();
    present.iter().find(|p| !listed.contains(p.as_str())).map(|extra| {
        format!(
            "holds {extra}, which calsim did not write there (calsim replaces only what it made): move it away or choose \
             another --out (it is left as it is)"
        )
    })
}

/// Every entry under `dir` (files, links and directories, depth first; links not followed), as
/// paths relative to it joined by `/`, a directory's ending in `/`, sorted; `manifest.json` at
/// the top left out. What a results directory's manifest lists as `files`.
pub fn listing(dir: &Path) -> io::Result<Vec<String>> {
    fn walk(dir: &Path, prefix: &str, out: &mut Vec<String>) -> io::Result<()> {
        for entry in fs::read_dir(dir)? {
            let entry = entry?;
            let name = crate::io::names::escape_controls(&entry.file_name().to_string_lossy());
            let path = format!("{prefix}{name}");
            if entry.file_type()?.is_dir() {
                out.push(format!("{path}/"));
                walk(&entry.path(), &format!("{path}/"), out)?;
            } else if path != "manifest.json" {
                out.push(path);
            }
        }
        Ok(())
    }
    let mut out = Vec::new();
    walk(dir, "", &mut out)?;
    out.sort();
    Ok(out)
}

/// Checks, before anything runs, that the results of `name` can be written under `out`: `name` is
/// one plain path component ([`crate::io::names`]), `out` is (or can be made) a writable directory
/// outside other results ([`vet_dir`]) and `out/<name>` may be replaced by the rule of this module
/// (absent, empty, or calsim's results holding no input of the run). Removes the temporary
/// directories of runs that no longer exist. Returns `out/<name>`.
pub fn prepare(out: &Path, name: &str) -> Result<PathBuf, OutDirError> {
    prepare_with(out, name, &results_in_the_way)
}

/// [`prepare`] for a work directory `out/<name>` that calsim fills and deletes itself (a sweep's
/// shard): absent, empty, or holding the file `marker` (`sweep.json`) that calsim writes first,
/// and no input of the run.
pub fn prepare_work(out: &Path, name: &str, marker: &str) -> Result<PathBuf, OutDirError> {
    let ours = |d: &Path| d.join(marker).is_file();
    let what = format!("a calsim work directory (it has no {marker})");
    prepare_with(out, name, &|dest| may_not_replace("--out", dest, &ours, &what))
}

/// [`prepare`] for a cache directory `out/<name>` that calsim only adds its own records to and
/// never deletes (an optimisation's evaluations, which later runs reuse): any directory holding no
/// input of the run.
pub fn prepare_cache(out: &Path, name: &str) -> Result<PathBuf, OutDirError> {
    prepare_with(out, name, &|dest| may_not_replace("--out", dest, &|_| true, "a calsim cache directory"))
}

fn prepare_with(out: &Path, name: &str, in_the_way_at: &dyn Fn(&Path) -> Option<OutDirError>) -> Result<PathBuf, OutDirError> {
    if let Some(why) = crate::io::names::rule_broken(name) {
        return Err(bad_name(out, name, why));
    }
    vet_dir(out)?;
    if out.exists() && !out.is_dir() {
        return Err(in_the_way(out, "is not a directory (--out names the directory the results go in)"));
    }
    let dest = out.join(name);
    if let Some(e) = in_the_way_at(&dest) {
        return Err(e);
    }
    fs::create_dir_all(out).map_err(io_err(out))?;
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
/// [`write_file`]). `name` and `out` are vetted as by [`prepare`] first, and `out/<name>` again
/// just before the swap: only results calsim made, holding no input, are ever replaced.
pub fn write_atomically(out: &Path, name: &str, fill: impl FnOnce(&Path) -> io::Result<()>) -> io::Result<PathBuf> {
    if let Some(why) = crate::io::names::rule_broken(name) {
        return Err(io::Error::new(io::ErrorKind::InvalidInput, bad_name(out, name, why).to_string()));
    }
    let refused = |e: OutDirError| io::Error::new(io::ErrorKind::InvalidInput, e.to_string());
    vet_dir(out).map_err(refused)?;
    let dest = out.join(name);
    if let Some(e) = results_in_the_way(&dest) {
        return Err(refused(e));
    }
    fs::create_dir_all(out)?;
    let tmp = temporary(out, name);
    if tmp.exists() {
        fs::remove_dir_all(&tmp)?;
    }
    fs::create_dir_all(&tmp)?;
    if let Err(e) = fill(&tmp) {
        let _ = fs::remove_dir_all(&tmp);
        return Err(io::Error::new(e.kind(), format!("{}: {e}", crate::io::names::escape_controls(name))));
    }
    // The rule once more at the swap: what is there now may be replaced.
    if let Some(e) = results_in_the_way(&dest) {
        let _ = fs::remove_dir_all(&tmp);
        return Err(refused(e));
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
pub fn write_file_atomically(path: &Path, text: impl AsRef<[u8]>) -> io::Result<()> {
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
        .and_then(|mut f| std::io::Write::write_all(&mut f, text.as_ref()))
        .and_then(|()| fs::rename(&tmp, &path));
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    result
}

/// How a JUnit report of `calsim check` begins (the check report writes it so).
pub const JUNIT_HEAD: &str = "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<testsuites><testsuite name=\"calsim check ";

/// Whether the regular file `path` is one calsim wrote and may write again: a JUnit report of
/// `calsim check` (a CI job's `--junit` of every run), recognised by its first bytes. Other
/// single-file outputs (a robot file, joint tables) may have been edited since, so they are new
/// files only.
fn written_by_calsim(path: &Path) -> bool {
    let mut head = vec![0u8; JUNIT_HEAD.len()];
    fs::symlink_metadata(path).is_ok_and(|m| m.is_file())
        && fs::File::open(path).and_then(|mut f| std::io::Read::read_exact(&mut f, &mut head)).is_ok()
        && head == JUNIT_HEAD.as_bytes()
}

/// Writes the output file `out` named by the option `flag` (vetted by [`vet_output_file`]): in
/// place of a file calsim wrote ([`written_by_calsim`]) atomically, otherwise as a new file
/// ([`write_new_file`]), so that a file that appeared there since is refused and left as it is.
pub fn write_output_file(flag: &str, out: &Path, bytes: &[u8]) -> Result<(), OutDirError> {
    if written_by_calsim(out) {
        return write_file_atomically(out, bytes).map_err(io_err(out));
    }
    write_new_file(out, bytes).map_err(|e| match e.kind() {
        io::ErrorKind::AlreadyExists => refused(flag, out, EXISTS),
        _ => io_err(out)(e),
    })
}

/// Writes `bytes` to the new file `path`, which must not exist: through a temporary beside it
/// (`<name>.partial-<pid>`, created afresh) linked into place, so that `path` appears whole or not
/// at all and a file that appeared there meanwhile is never replaced (`AlreadyExists`); the
/// temporary is removed in every case.
pub fn write_new_file(path: &Path, bytes: &[u8]) -> io::Result<()> {
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(format!(".partial-{}", std::process::id()));
    let tmp = path.with_file_name(name);
    let mut file = fs::OpenOptions::new().write(true).create_new(true).open(&tmp)?;
    let written = std::io::Write::write_all(&mut file, bytes).and_then(|()| file.sync_all()).and_then(|()| fs::hard_link(&tmp, path));
    let _ = fs::remove_file(&tmp);
    written
}

/// Writes `bytes` to the file `path` of a cache that several threads or processes may fill at once
/// with the same contents (an optimisation's per-world files and restart records, written from a
/// worker pool and from shards): through a temporary beside it named by the process and the thread
/// (`<stem>.tmp-<pid>-<thread>`), renamed into place, so that no two writers share a temporary and
/// `path` holds a whole file or none; a failing write removes its temporary. The temporaries of a
/// killed process are removed by [`remove_stale_cache_temporaries`].
pub fn write_cache_file(path: &Path, bytes: &[u8]) -> io::Result<()> {
    let tmp = path.with_extension(format!("tmp-{}-{:?}", std::process::id(), std::thread::current().id()).replace(['(', ')'], ""));
    let written = fs::write(&tmp, bytes).and_then(|()| fs::rename(&tmp, path));
    if written.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    written
}

/// The process id in the name of a temporary of [`write_cache_file`], if `name` is one.
fn cache_temporary_pid(name: &str) -> Option<u32> {
    let (_, rest) = name.split_once(".tmp-")?;
    rest.split('-').next()?.parse().ok()
}

/// Removes from the directory `dir` the temporaries of [`write_cache_file`] (regular files) whose
/// process is gone; a directory that does not exist has none. Returns how many it removed.
pub fn remove_stale_cache_temporaries(dir: &Path) -> Result<usize, OutDirError> {
    let entries = match fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(0),
        Err(e) => return Err(io_err(dir)(e)),
    };
    let mut removed = 0;
    for entry in entries {
        let entry = entry.map_err(io_err(dir))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        if let Some(pid) = cache_temporary_pid(&name)
            && pid != std::process::id()
            && !alive(pid)
            && entry.file_type().map_err(io_err(dir))?.is_file()
        {
            fs::remove_file(entry.path()).map_err(io_err(&entry.path()))?;
            removed += 1;
        }
    }
    Ok(removed)
}

/// The names of the temporaries of [`write_cache_file`] in `dir` (every entry whose name holds
/// `.tmp-`), sorted: what the tests of a cache's writers look for.
#[cfg(test)]
pub fn cache_temporaries(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> =
        fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).filter(|n| n.contains(".tmp-")).collect();
    names.sort();
    names
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_new_file_never_replaces_one_and_leaves_no_temporary() {
        let tmp = scratch();
        let path = tmp.path().join("m.csv");
        write_new_file(&path, b"first").unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"first");
        let e = write_new_file(&path, b"second").unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::AlreadyExists);
        assert_eq!(fs::read(&path).unwrap(), b"first", "the file there is kept");
        let names: Vec<_> = fs::read_dir(tmp.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names, ["m.csv"], "no temporary left");
    }

    #[test]
    fn a_failing_cache_write_leaves_no_temporary() {
        let tmp = scratch();
        // The rename cannot replace a directory that holds a file.
        let target = tmp.path().join("r0000000.json");
        fs::create_dir(&target).unwrap();
        fs::write(target.join("x"), b"x").unwrap();
        assert!(write_cache_file(&target, b"{}").is_err());
        assert!(cache_temporaries(tmp.path()).is_empty(), "{:?}", cache_temporaries(tmp.path()));
        // And a written file leaves none either.
        let ok = tmp.path().join("r0000001.json");
        write_cache_file(&ok, b"{}").unwrap();
        assert_eq!(fs::read(&ok).unwrap(), b"{}");
        assert!(cache_temporaries(tmp.path()).is_empty());
    }

    #[test]
    fn cache_temporaries_of_gone_processes_are_removed_and_a_live_ones_kept() {
        let tmp = scratch();
        let mine = format!("r0000000.tmp-{}-ThreadId2", std::process::id());
        for name in ["r0000001.tmp-999999999-ThreadId7", mine.as_str(), "r0000002.json"] {
            fs::write(tmp.path().join(name), b"x").unwrap();
        }
        fs::create_dir(tmp.path().join("d.tmp-999999999-ThreadId1")).unwrap();
        assert_eq!(remove_stale_cache_temporaries(tmp.path()).unwrap(), 1);
        assert_eq!(cache_temporaries(tmp.path()), vec!["d.tmp-999999999-ThreadId1".to_string(), mine]);
        assert!(tmp.path().join("r0000002.json").exists(), "a cache file is not a temporary");
        assert_eq!(remove_stale_cache_temporaries(&tmp.path().join("none")).unwrap(), 0);
    }

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
