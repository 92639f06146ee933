#!/usr/bin/env bash
# The full default TriCal study, calsim against the numpy reference (`batch` and `lemma` DETMAX),
# side by side in one run on this machine: calsim 5 times, numpy once, calsim 5 times again.
# Usage: scripts/bench/study_vs_numpy.sh [path to the numpy reference, default ../shared/bench]
# Needs python3 with numpy; takes a few minutes (the numpy study is the long part).
set -euo pipefail
here="$(cd "$(dirname "$0")/../.." && pwd)"
ref="${1:-$here/../shared/bench}"
[[ -f "$ref/bench_numpy.py" ]] || { echo "study_vs_numpy: no numpy reference at $ref (give its path)" >&2; exit 2; }
python3 -c 'import numpy' 2>/dev/null || { echo "study_vs_numpy: python3 has no numpy (pip install numpy)" >&2; exit 2; }
cd "$here"
cargo build --release --locked --quiet
bin="${CARGO_TARGET_DIR:-$here/target}/release/calsim"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
calsim_times() {
    for _ in 1 2 3 4 5; do
        "$bin" run scenarios/irb120_trical.toml --out "$work/out" 2>&1 | sed -n 's/^timing: study \([0-9.]*\) s.*/\1/p'
    done
}
calsim_times >"$work/calsim.txt"
(cd "$ref" && BENCH_OUT="$work" OPENBLAS_NUM_THREADS=1 python3 bench_numpy.py --study-only --study-trials 30 --variants batch,lemma >"$work/numpy.log")
calsim_times >>"$work/calsim.txt"
python3 - "$work" <<'PY'
import json, statistics, sys
work = sys.argv[1]
t = [float(x) for x in open(f"{work}/calsim.txt").read().split()]
numpy = json.load(open(f"{work}/results_numpy_study_K30.json"))["study"]
best, med = min(t), statistics.median(t)
print(f"calsim full study (campaign + 510 DETMAX selections, identifications, validations), 10 runs: "
      f"min {best:.3f} s, median {med:.3f} s, max {max(t):.3f} s")
for v in ("batch", "lemma"):
    w = numpy[v]["wall_s"]
    print(f"numpy `{v}` (single thread, 510 identifications): {w:.1f} s wall; calsim is {w / med:.0f}x faster (median), {w / best:.0f}x (min)")
PY
