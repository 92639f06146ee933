#!/usr/bin/env bash
# Regenerates docs/calibrate/example_report/ (the shipped calibration report that
# tests/calibrate.rs compares byte for byte) from docs/calibrate/example_measurements.csv with
# the release binary of this checkout. Seconds.
#
# Usage: bash scripts/docs/calibrate_example.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-${HOME:-/root}/.cache/calsim-target}"
cargo build --release --locked --bin calsim
scratch="$(mktemp -d)"
trap 'rm -rf "$scratch"' EXIT
"$CARGO_TARGET_DIR/release/calsim" calibrate robots/irb120.toml docs/calibrate/example_measurements.csv --out "$scratch"
rm -rf docs/calibrate/example_report
cp -r "$scratch/example_measurements.calibration" docs/calibrate/example_report
echo "calibrate_example: docs/calibrate/example_report regenerated"
