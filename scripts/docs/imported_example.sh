#!/usr/bin/env bash
# The imported-arm example of docs/calibrate.md: writes the measurement file of
# docs/calibrate/imported_example.toml (102,030 rows, about 19 MB: not kept in the repository) with
# `calsim simulate-measurements`, calibrates it with `calsim calibrate` and writes its summary.md
# to docs/generated/imported-example.md, headed by the commands, the commit and the seconds each
# took. Minutes (too long for CI; scripts/docs/regenerate.sh runs it).
#
# Usage: bash scripts/docs/imported_example.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-${HOME:-/root}/.cache/calsim-target}"
cargo build --release --locked --bin calsim
calsim="$CARGO_TARGET_DIR/release/calsim"
commit="$(git rev-parse --short HEAD)$(git diff --quiet HEAD -- src Cargo.toml Cargo.lock robots docs/calibrate/imported_example.toml || echo '+local changes')"
scratch="$(mktemp -d)"
trap 'rm -rf "$scratch"' EXIT
mkdir -p docs/generated

simulate="simulate-measurements docs/calibrate/imported_example.toml --out $scratch/data"
start=$SECONDS
# shellcheck disable=SC2086
"$calsim" $simulate
simulated=$((SECONDS - start))
flags="--payload-kg 2 --payload-com-mm 0,0,50 --tool-per-session --hold-out-session L"
calibrate="calibrate robots/examples/lrmate200ic_coupled.toml $scratch/data/imported_example.csv $flags"
start=$SECONDS
# shellcheck disable=SC2086
"$calsim" $calibrate --out "$scratch/out" | tee "$scratch/calibrate.stdout"
calibrated=$((SECONDS - start))
{
    echo "<!-- made by scripts/docs/imported_example.sh: do not edit -->"
    echo "*Made at commit $commit by \`calsim simulate-measurements docs/calibrate/imported_example.toml --out data\` in $simulated s and \`calsim calibrate robots/examples/lrmate200ic_coupled.toml data/imported_example.csv $flags\` in $calibrated s.*"
    echo
    echo '```text'
    cat "$scratch/calibrate.stdout"
    echo '```'
    echo
    cat "$scratch/out/imported_example.calibration/summary.md"
} >docs/generated/imported-example.md
echo "imported_example: docs/generated/imported-example.md"
