#!/usr/bin/env bash
# A simulated example of docs/calibrate.md: writes the measurement file of a simulation file with
# `calsim simulate-measurements`, calibrates it with `calsim calibrate` on ROBOT with FLAGS and
# writes the calibration's terminal output and summary.md to docs/generated/<stem>.md (the
# simulation file's stem, `_` as `-`), headed by the commands, the commit and the seconds each
# took. The measurement files are not kept in the repository (the imported arm's is about 19 MB);
# scripts/docs/regenerate.sh runs this for every example of the guide:
#
#   bash scripts/docs/simulated_example.sh docs/calibrate/imported_example.toml \
#       robots/examples/lrmate200ic_coupled.toml --payload-kg 2 --payload-com-mm 0,0,50 --tool-per-session --hold-out-session L
#   bash scripts/docs/simulated_example.sh docs/calibrate/probe_example.toml robots/irb120.toml \
#       --orientation-noise-mdeg 10 --position-noise-mm 0.012 --hold-out-session L --no-plots
#
# Usage: bash scripts/docs/simulated_example.sh SPEC ROBOT [FLAGS...]
set -euo pipefail
cd "$(dirname "$0")/../.."
spec="$1"
robot="$2"
shift 2
flags="$*"
stem="$(basename "$spec" .toml)"
page="docs/generated/${stem//_/-}.md"
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-${HOME:-/root}/.cache/calsim-target}"
cargo build --release --locked --bin calsim
calsim="$CARGO_TARGET_DIR/release/calsim"
commit="$(git rev-parse --short HEAD)$(git diff --quiet HEAD -- src Cargo.toml Cargo.lock robots "$spec" || echo '+local changes')"
scratch="$(mktemp -d)"
trap 'rm -rf "$scratch"' EXIT
mkdir -p docs/generated

start=$SECONDS
"$calsim" simulate-measurements "$spec" --out "$scratch/data"
simulated=$((SECONDS - start))
start=$SECONDS
# shellcheck disable=SC2086
"$calsim" calibrate "$robot" "$scratch/data/$stem.csv" $flags --out "$scratch/out" | tee "$scratch/calibrate.stdout"
calibrated=$((SECONDS - start))
{
    echo "<!-- made by scripts/docs/simulated_example.sh: do not edit -->"
    echo "*Made at commit $commit by \`calsim simulate-measurements $spec --out data\` in $simulated s and \`calsim calibrate $robot data/$stem.csv $flags\` in $calibrated s.*"
    echo
    echo '```text'
    sed "s#$scratch/out#out#g; s#$scratch/data#data#g" "$scratch/calibrate.stdout"
    echo '```'
    echo
    sed "s#$scratch/data#data#g" "$scratch/out/$stem.calibration/summary.md"
} >"$page"
echo "simulated_example: $page"
