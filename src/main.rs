//! The `calsim` command line.

use std::process::ExitCode;

fn main() -> ExitCode {
    calsim::cli::main()
}
