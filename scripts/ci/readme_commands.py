#!/usr/bin/env python3
"""Runs every command README.md shows (its ```sh blocks), as CI's step that keeps the README true.

Usage: python3 scripts/ci/readme_commands.py <calsim binary>

Each line of a ```sh block is run with bash in a scratch directory that holds the repository's
inputs (scenarios/, robots/, docs/, reference/, python/ linked in) and a fresh results/, in the
README's order (later commands use earlier results), with `calsim` on the path as the given binary
and `cargo run --release --` read as that binary (the release build is what it runs). A line that
is not a calsim command must be one .ci/run itself runs (the test suite, the Python package, CI
itself): this script checks that .ci/run contains it. Any other line, or a command that fails,
fails the step.
"""

import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
INPUTS = ["scenarios", "robots", "docs", "reference", "python"]
# Lines .ci/run runs itself, by the text .ci/run must contain for each.
RUN_BY_CI = {
    "cargo test --locked": "cargo test --locked",
    "bash .ci/run": "",  # CI itself
    # The package as pip builds it from the clone (maturin, its build backend) is the wheel that
    # .ci/run builds with maturin and installs into a fresh venv without Rust.
    'pip install "./python[progress]"': 'bin/maturin" build --release --strip',
    "pip install maturin && (cd python && maturin build --release --strip --out ../dist)": 'bin/maturin" build --release --strip',
    'pip install "$(ls dist/calsim-*.whl)[progress]"': 'bin/pip" install --quiet --disable-pip-version-check "$wheel[progress]"',
}


def commands(readme: str) -> list[str]:
    """The lines of the ```sh blocks, without their trailing comments."""
    out = []
    for block in re.findall(r"```sh\n(.*?)```", readme, flags=re.S):
        for line in block.splitlines():
            line = re.sub(r"\s+#\s.*$", "", line).strip()
            if line and not line.startswith("#"):
                out.append(line)
    return out


def main() -> int:
    calsim = Path(sys.argv[1]).resolve()
    ci = (REPO / ".ci" / "run").read_text()
    with tempfile.TemporaryDirectory(prefix="calsim-readme-") as scratch:
        work = Path(scratch) / "work"
        bin_dir = Path(scratch) / "bin"
        work.mkdir()
        bin_dir.mkdir()
        (bin_dir / "calsim").symlink_to(calsim)
        for name in INPUTS:
            (work / name).symlink_to(REPO / name)
        env = dict(os.environ, PATH=f"{bin_dir}:{os.environ['PATH']}", RUST_LIB_BACKTRACE="0")
        ran = 0
        for line in commands((REPO / "README.md").read_text()):
            if line in RUN_BY_CI:
                needed = RUN_BY_CI[line]
                if needed not in ci:
                    print(f"readme: {line!r}: .ci/run does not run it", file=sys.stderr)
                    return 1
                print(f"readme: {line}: run by .ci/run", flush=True)
                continue
            line = line.replace("cargo run --release --", "calsim", 1)
            if not line.startswith("calsim "):
                print(f"readme: {line!r}: neither a calsim command nor one .ci/run runs", file=sys.stderr)
                return 1
            start = time.monotonic()
            r = subprocess.run(["bash", "-c", line], cwd=work, env=env, capture_output=True, text=True)
            took = time.monotonic() - start
            if r.returncode != 0:
                print(f"readme: {line}: exit {r.returncode}\n{r.stdout[-2000:]}{r.stderr[-2000:]}", file=sys.stderr)
                return 1
            print(f"readme: {line}: ok in {took:.1f} s", flush=True)
            ran += 1
    print(f"readme: {ran} commands of README.md ran")
    return 0


if __name__ == "__main__":
    sys.exit(main())
