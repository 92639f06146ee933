//! The inputs of a command, from the one place every input passes: while a [`Ledger`] is open,
//! each file read through the kit's readers ([`crate::io::read_text`], [`crate::io::read_bytes`],
//! [`crate::io::read_bytes_at_most`]) on the thread that opened it is recorded, by its resolved
//! path (symbolic links and `..` followed) and the sha256 of the bytes read. A loaded scenario,
//! sweep, design or measurement file has thereby told the ledger every file it read (the base
//! scenarios, the robot file its `robot.file` names, the files its keys name), and the writer
//! ([`crate::io::out_dir`]) refuses to replace any of them, or any directory holding one; the
//! manifest's provenance lists them ([`crate::io::manifest::Provenance`]).
//!
//! Every command of `app` (and `calibrate`) opens a ledger at its start, on the thread that loads
//! its inputs (the worker threads of its study read none). A ledger belongs to its thread, so two
//! commands running at once in one process (tests, a Python program) keep their inputs apart.

use std::cell::RefCell;
use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

/// A file a command read: its resolved path and the sha256 of the bytes read.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub struct Input {
    /// The file, absolute, symbolic links resolved.
    pub path: PathBuf,
    /// The sha256 of the bytes read, lowercase hex.
    pub sha256: String,
}

thread_local! {
    /// This thread's open ledgers: an id and the inputs recorded since it opened.
    static OPEN: RefCell<Vec<(u64, Vec<Input>)>> = const { RefCell::new(Vec::new()) };
}
static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

fn with_open<T>(f: impl FnOnce(&mut Vec<(u64, Vec<Input>)>) -> T) -> T {
    OPEN.with(|o| f(&mut o.borrow_mut()))
}

/// The record of the files read while it is open (closed when dropped).
#[must_use = "the ledger records only while it is held"]
pub struct Ledger {
    id: u64,
    /// A ledger stays on the thread whose reads it records.
    _thread: std::marker::PhantomData<*const ()>,
}

impl Ledger {
    /// Opens a ledger: from now on every file this thread reads is recorded in it.
    pub fn open() -> Self {
        let id = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        with_open(|o| o.push((id, Vec::new())));
        Self { id, _thread: std::marker::PhantomData }
    }

    /// The files recorded in this ledger, in the order first read.
    pub fn inputs(&self) -> Vec<Input> {
        with_open(|o| o.iter().find(|(id, _)| *id == self.id).map(|(_, i)| i.clone()).unwrap_or_default())
    }
}

impl Drop for Ledger {
    fn drop(&mut self) {
        with_open(|o| o.retain(|(id, _)| *id != self.id));
    }
}

/// Records the read of `path` that gave `bytes` in every ledger open on this thread (nothing when
/// none is). A file read twice keeps its first record.
pub(crate) fn record(path: &Path, bytes: &[u8]) {
    with_open(|open| {
        if open.is_empty() {
            return;
        }
        let path = resolved(path);
        let mut sha256 = None;
        for (_, inputs) in open.iter_mut() {
            if !inputs.iter().any(|i| i.path == path) {
                let sha256 = sha256.get_or_insert_with(|| format!("{:x}", Sha256::digest(bytes))).clone();
                inputs.push(Input { path: path.clone(), sha256 });
            }
        }
    })
}

/// Every file read on this thread while a ledger is open, in the order first read (the union of
/// its open ledgers: what the writer must never replace).
pub fn read_so_far() -> Vec<Input> {
    with_open(|open| {
        let mut out: Vec<Input> = Vec::new();
        for (_, inputs) in open.iter() {
            for i in inputs {
                if !out.iter().any(|o| o.path == i.path) {
                    out.push(i.clone());
                }
            }
        }
        out
    })
}

/// The inputs a manifest lists: [`read_so_far`] less calsim's own intermediate files (the work
/// units of a sweep's shards, an optimisation's evaluations, the tables of the results being
/// written), which are results of this or an earlier run rather than what the user gave; sorted
/// by path.
pub fn of_run() -> Vec<Input> {
    let mut out: Vec<Input> = read_so_far().into_iter().filter(|i| !is_own(&i.path)).collect();
    out.sort_by(|a, b| a.path.cmp(&b.path));
    out
}

/// Whether `path` lies in one of calsim's work directories: a shard's `units`, a
/// `<name>.evaluations` directory, or the temporary directory of results being written
/// (`.<name>.tmp-<pid>`).
fn is_own(path: &Path) -> bool {
    let names: Vec<String> = path.components().map(|c| c.as_os_str().to_string_lossy().into_owned()).collect();
    names.iter().enumerate().any(|(i, n)| {
        n.ends_with(".evaluations")
            || (n.starts_with('.') && n.contains(".tmp-"))
            || (n == "units" && i > 0 && is_shard_name(&names[i - 1]))
    })
}

/// Whether `name` is a shard directory's name (`<sweep>.shard-<k>-of-<K>`).
fn is_shard_name(name: &str) -> bool {
    name.rsplit_once(".shard-").and_then(|(_, rest)| rest.split_once("-of-")).is_some_and(|(k, n)| {
        !k.is_empty() && !n.is_empty() && k.bytes().all(|b| b.is_ascii_digit()) && n.bytes().all(|b| b.is_ascii_digit())
    })
}

/// `path` made absolute with its existing part resolved (symbolic links, `..`).
pub fn resolved(path: &Path) -> PathBuf {
    let absolute = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    let mut existing = absolute.as_path();
    let mut rest = Vec::new();
    loop {
        if let Ok(real) = std::fs::canonicalize(existing) {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_open_ledger_records_each_file_read_once_with_its_hash_and_none_read_before_it_opened() {
        let tmp = tempfile::Builder::new().prefix("calsim-inputs-").tempdir().unwrap();
        let a = tmp.path().join("a.toml");
        std::fs::write(&a, "x = 1\n").unwrap();
        let link = tmp.path().join("link.toml");
        std::os::unix::fs::symlink(&a, &link).unwrap();
        let ledger = Ledger::open();
        crate::io::read_text(&a).unwrap();
        crate::io::read_text(&link).unwrap();
        let mine: Vec<Input> = ledger.inputs().into_iter().filter(|i| i.path.starts_with(resolved(tmp.path()))).collect();
        assert_eq!(mine.len(), 1, "{mine:?}");
        assert_eq!(mine[0].path, std::fs::canonicalize(&a).unwrap());
        // sha256 of "x = 1\n".
        assert_eq!(mine[0].sha256, format!("{:x}", Sha256::digest(b"x = 1\n")));
        assert!(read_so_far().iter().any(|i| i.path == mine[0].path));
        drop(ledger);
        let b = tmp.path().join("b.toml");
        std::fs::write(&b, "y").unwrap();
        crate::io::read_text(&b).unwrap();
        assert!(read_so_far().is_empty(), "no ledger open on this thread");
        let later = Ledger::open();
        assert!(later.inputs().iter().all(|i| i.path != std::fs::canonicalize(&b).unwrap()));
        // A read on another thread is not this thread's command's.
        let c = tmp.path().join("c.toml");
        std::fs::write(&c, "z").unwrap();
        std::thread::scope(|s| s.spawn(|| crate::io::read_text(&c).unwrap()).join().unwrap());
        assert!(later.inputs().is_empty());
    }

    #[test]
    fn calsims_own_work_files_are_not_listed_as_inputs() {
        for own in ["/r/s.shard-0-of-4/units/u0000001.json", "/r/o.evaluations/w.json", "/r/.s.tmp-12/tasks.parquet"] {
            assert!(is_own(Path::new(own)), "{own}");
        }
        for user in ["/r/s.shard-0-of-4/sweep.json", "/r/units/a.csv", "/r/scenarios/s.toml", "/r/x.shard-a-of-2/units/u.json"] {
            assert!(!is_own(Path::new(user)), "{user}");
        }
    }
}
