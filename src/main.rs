//! The `calsim` command line.

use std::process::ExitCode;

fn main() -> ExitCode {
    keep_freed_memory();
    calsim::cli::main()
}

/// glibc's allocator maps a block above its mmap threshold (32 MB at most) afresh and unmaps it
/// when freed, and gives the heap's free top back to the kernel: a large calibration's matrices
/// (a 140,040-row file's Jacobians take 100 MB and more, made and dropped in every fit and in the
/// twin) are then faulted in page by page, and zeroed by the kernel, every time. The command line
/// keeps freed memory for the next block instead: no block is mapped on its own where a heap can
/// hold it (the main thread's heap grows as needed; a worker thread's heap holds up to 64 MB, and
/// glibc still maps a larger block there afresh), and up to 2 GB of free heap top stays. A higher
/// peak resident size, fewer page faults, the same results (the allocator has no part in the
/// arithmetic). The library (and the Python package) leave the process's allocator as they find it.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn keep_freed_memory() {
    // SAFETY: `mallopt` sets parameters of glibc's allocator and touches nothing else; it is
    // called before the program allocates from a second thread (none exists yet).
    #[allow(unsafe_code)]
    unsafe {
        libc::mallopt(libc::M_MMAP_MAX, 0);
        libc::mallopt(libc::M_TRIM_THRESHOLD, libc::c_int::MAX);
        libc::mallopt(libc::M_TOP_PAD, 64 << 20);
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn keep_freed_memory() {}
