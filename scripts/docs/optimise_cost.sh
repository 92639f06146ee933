#!/usr/bin/env bash
# optimise_cost.sh DESIGN [CALSIM]: what one evaluation of a TriCal design file costs and where its
# CPU goes (docs/optimise.md, "What an evaluation costs"). Runs a small variant of DESIGN (one sphere
# count, the 5 spheres of its count range's middle, 12 designs of one restart on the file's own
# search worlds, one finalist, a race of 10 worlds, 10 held-out worlds, no compared sweeps) on one
# thread under `perf record`, and prints the CPU time, the worlds run, the CPU per world, the
# designs a CPU-minute evaluates and the shares of the run's samples by part of a world.
# CALSIM defaults to the release binary of $CARGO_TARGET_DIR (or target/).
set -euo pipefail
design="$(realpath "$1")"
calsim="$(realpath "${2:-${CARGO_TARGET_DIR:-target}/release/calsim}")"
scratch="$(mktemp -d)"
trap 'rm -rf "$scratch"' EXIT
base_dir="$(dirname "$design")"
name="$(basename "$design" .toml)_cost"
sed -e "s|^base = \"\\(.*\\)\"|base = \"$base_dir/\\1\"|" \
    -e 's|^count = \[[0-9], [0-9]\]|count = [5, 5]|' \
    -e 's|^evaluations = [0-9]*|evaluations = 12|' \
    -e 's|^restarts = [0-9]*|restarts = 1|' \
    -e 's|^finalists = [0-9]*|finalists = 1|' \
    -e 's|^race = .*|race = { max = 10, batch = 10 }|' \
    -e 's|^held_out = [0-9]*|held_out = 10|' \
    -e '/^compare = /d' "$design" >"$scratch/$name.toml"
worlds=$(grep -oP '^worlds = \K[0-9]+' "$scratch/$name.toml")
cd "$scratch"
/usr/bin/time -f '%U %S' -o time.txt perf record -q -o perf.data -F 49 --call-graph dwarf,16384 \
    "$calsim" optimise "$name.toml" --out out --threads 1 --no-plots >run.log 2>&1
read -r user sys <time.txt
files=$(find out -name 'r*.json' | wc -l)
designs=$(find out -path '*.evaluations*' -mindepth 3 -maxdepth 3 -type d | wc -l)
# The winner's realisation 0 runs once more beside the per-world files.
per_world=$(python3 -c "print(f'{($user + $sys) / ($files + 1):.3f}')")
echo "calsim optimise $(basename "$design") variant: $designs designs of $worlds search worlds, $files world files and the winner's run"
echo "CPU: ${user} s user, ${sys} s system; ${per_world} s a world; $(python3 -c "print(f'{60 / ($per_world * $worlds):.1f}')") designs a CPU-minute"
perf report -i perf.data --children --no-inline -g none --sort symbol >report.txt 2>/dev/null
share() { awk -v s="$2" -v part="$1" '$4 == s && !seen { print part ": " $1; seen = 1 }' report.txt; }
share "the 20 identifications of a world" calsim::study::engine::select_and_identify
share "  DETMAX's selection" calsim::identify::detmax::detmax
share "    of which the blocks' catch-up" calsim::identify::detmax::State::catch_up
share "  the fits" calsim::identify::least_squares::identify
share "the campaign's measurement" calsim::device::trical::campaign::run
share "  the pool (IK, collision tests, centring)" calsim::device::trical::campaign::measure_pool
share "    collision tests" calsim::cell::collision::CollisionWorld::first_collision
share "    inverse kinematics" calsim::robot::ik::inverse
share "    Algorithm 1's centring" calsim::device::trical::campaign::centring::centre
share "  the validation poses" calsim::device::trical::campaign::measure_random_poses
share "the validation errors after calibration" calsim::device::trical::study::compensated_errors
share "the feasibility candidates" calsim::device::trical::campaign::feasibility
share "the reach margins" calsim::design::optimise::reach::sphere_margins_mm
