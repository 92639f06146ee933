#!/usr/bin/env bash
# Instruction counts of the study's hot loop (examples/study_hot_loop.rs: the default campaign and
# 10 tasks at n = 75 on one thread) under callgrind: the count repeats exactly on one machine, so a
# regression shows in one run. Prints the total and the ten most expensive functions.
# Usage: scripts/bench/instructions.sh   (needs valgrind)
set -euo pipefail
here="$(cd "$(dirname "$0")/../.." && pwd)"
command -v valgrind >/dev/null || { echo "instructions: valgrind is not installed" >&2; exit 2; }
cd "$here"
cargo build --release --locked --quiet --example study_hot_loop
bin="${CARGO_TARGET_DIR:-$here/target}/release/examples/study_hot_loop"
out="$(mktemp)"
trap 'rm -f "$out"' EXIT
RAYON_NUM_THREADS=1 valgrind --tool=callgrind --callgrind-out-file="$out" "$bin" 2>/dev/null
total="$(sed -n 's/^summary: *//p' "$out")"
echo "instructions (Ir): $total"
callgrind_annotate --threshold=100 "$out" 2>/dev/null | grep -E '^ *[0-9,]+ \(' | head -11
