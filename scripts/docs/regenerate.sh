#!/usr/bin/env bash
# Re-runs the commands behind the docs' expensive figures (minutes each, too long for CI) and
# writes each one's summary.md to docs/generated/<name>.md, headed by the command and the commit
# that made it. The cheap figures are kept by scripts/ci/doc_numbers.py (CI); this script ends
# by running it with --write, so that every number of the docs is remade.
#
# Usage: bash scripts/docs/regenerate.sh [NAME...]   (no name: all of them)
set -euo pipefail
cd "$(dirname "$0")/../.."
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-${HOME:-/root}/.cache/calsim-target}"
cargo build --release --locked --bin calsim
calsim="$CARGO_TARGET_DIR/release/calsim"
commit="$(git rev-parse --short HEAD)$(git diff --quiet HEAD -- src examples Cargo.toml Cargo.lock scenarios robots reference || echo '+local changes')"
scratch="$(mktemp -d)"
trap 'rm -rf "$scratch"' EXIT
mkdir -p docs/generated

# page NAME MADE [NOTE]: docs/generated/NAME.md from the standard input, headed by the warning,
# MADE (what made it, Markdown), the commit and the seconds since $start (NOTE in brackets after).
page() {
    {
        echo "<!-- made by scripts/docs/regenerate.sh: do not edit -->"
        echo "*Made by $2 at commit $commit in $((SECONDS - start)) s${3:+ ($3)}.*"
        echo
        cat
    } >"docs/generated/$1.md"
    echo "regenerate: $1: docs/generated/$1.md"
}
# fenced FILE: FILE's text in a text block (its trailing blank lines dropped).
fenced() {
    printf '%s\n%s\n%s\n' '```text' "$(cat "$1")" '```'
}

# name | command (given --out, except table8, which prints only)
runs=(
    "optimise-irb120-spheres|optimise scenarios/designs/irb120_spheres.toml"
    "optimise-irb120-spheres-from-paper|optimise scenarios/designs/irb120_spheres_from_paper.toml"
    "optimise-irb120-spheres-from-random|optimise scenarios/designs/irb120_spheres_from_random.toml"
    "optimise-irb120-spheres-cmaes|optimise scenarios/designs/irb120_spheres.toml --method cmaes"
    "optimise-irb120-spheres-from-paper-cmaes|optimise scenarios/designs/irb120_spheres_from_paper.toml --method cmaes"
    "optimise-irb120-spheres-from-random-cmaes|optimise scenarios/designs/irb120_spheres_from_random.toml --method cmaes"
    "optimise-spms-stations|optimise scenarios/designs/spms_stations.toml"
    "optimise-spms-stations-three|optimise scenarios/designs/spms_stations_three.toml"
    "optimise-irb120-spheres-robust|optimise scenarios/designs/irb120_spheres_robust.toml"
    "table8|table8 scenarios/irb120_trical.toml --realisations 20"
    "budget-spms|budget scenarios/er20c10_spms.toml --realisations 20"
    "sweep-twin-scale|sweep scenarios/sweeps/twin_scale.toml"
)
for run in "${runs[@]}"; do
    IFS='|' read -r name command <<<"$run"
    if [ $# -gt 0 ] && [[ " $* " != *" $name "* ]]; then
        continue
    fi
    echo "regenerate: $name: calsim $command"
    start=$SECONDS
    out=(--out "$scratch/$name")
    [[ $command == table8* ]] && out=()
    # shellcheck disable=SC2086
    "$calsim" $command "${out[@]}" >"$scratch/$name.stdout"
    summary="$(find "$scratch/$name" -maxdepth 2 -name summary.md 2>/dev/null | head -n 1)"
    if [ -n "$summary" ]; then
        cat "$summary"
    else
        fenced "$scratch/$name.stdout"
    fi | page "$name" "\`calsim $command\`"
done

# The docs' three-start table (docs/optimise-results.md, "Does the answer depend on the start?"):
# the shipped TriCal file and its two start variants, each run as above (reused where this call
# ran it), their tables read by scripts/docs/three_starts.py.
if [ $# -eq 0 ] || [[ " $* " == *" optimise-three-starts "* ]]; then
    start=$SECONDS
    dirs=()
    for pair in "hand-found cell|optimise-irb120-spheres|irb120_spheres" "the paper's cell|optimise-irb120-spheres-from-paper|irb120_spheres_from_paper" \
        "seeded random start|optimise-irb120-spheres-from-random|irb120_spheres_from_random"; do
        IFS='|' read -r label name file <<<"$pair"
        if [ ! -d "$scratch/$name" ]; then
            echo "regenerate: optimise-three-starts: calsim optimise scenarios/designs/$file.toml"
            "$calsim" optimise "scenarios/designs/$file.toml" --out "$scratch/$name" >"$scratch/$name.stdout"
        fi
        dirs+=("$label=$scratch/$name")
    done
    python3 scripts/docs/three_starts.py "${dirs[@]}" | page optimise-three-starts \
        "\`calsim optimise scenarios/designs/<file>.toml\` for irb120_spheres, irb120_spheres_from_paper and irb120_spheres_from_random, read by \`python3 scripts/docs/three_starts.py\`," \
        "the runs' own time where this call made them"
fi

# The findings' candidate error models, the CI gate's figures over 400 worlds, the sizing
# sweep's ranking, the plans' wall clock on 2 threads, an optimiser evaluation's CPU and its
# split, and the CI check's power over seeds (docs/findings.md, docs/guide-reproduce.md,
# docs/guide-sweeps.md, docs/plan.md, docs/optimise.md).
more=(
    "sweep-cell-sizing|sweep scenarios/sweeps/cell_sizing.toml"
    "check-ci-quick-400|check scenarios/ci_quick.toml --realisations 400 --no-plots --no-recording"
    "candidates|python3 scripts/fidelity/candidates.py --realisations 20"
    "fit-transmission-100|python3 scripts/fidelity/candidates.py --fit-default --realisations 100"
    "plan-speed-irb120|plan scenarios/plans/irb120_tracker.toml --threads 2"
    "plan-speed-objective|plan scenarios/plans/irb120_tracker_objective.toml --threads 2"
    "plan-speed-trical|plan scenarios/plans/irb120_trical.toml --threads 2"
    "plan-speed-trical-objective|plan scenarios/plans/irb120_trical_objective.toml --threads 2"
    "plan-speed-spms|plan scenarios/plans/er20c10_spms.toml --threads 2"
    "optimise-cost-hand|bash scripts/docs/optimise_cost.sh scenarios/designs/irb120_spheres.toml"
    "optimise-cost-paper|bash scripts/docs/optimise_cost.sh scenarios/designs/irb120_spheres_from_paper.toml"
    "check-power|python3 scripts/ci/check_power.py"
)
for run in "${more[@]}"; do
    IFS='|' read -r name command <<<"$run"
    if [ $# -gt 0 ] && [[ " $* " != *" $name "* ]]; then
        continue
    fi
    echo "regenerate: $name: $command"
    start=$SECONDS
    if [[ $command == python3* || $command == bash* ]]; then
        # shellcheck disable=SC2086
        CALSIM="$calsim" $command >"$scratch/$name.stdout"
        made="\`$command\`"
    else
        # shellcheck disable=SC2086
        "$calsim" $command --out "$scratch/$name" >"$scratch/$name.stdout" || [ $? -eq 1 ]
        made="\`calsim $command\`"
    fi
    if [[ $command == sweep* ]]; then
        printf '%s\n' "$(cat "$scratch/$name"/*/summary.md)"
    elif [[ $command == python3* ]]; then
        printf '%s\n' "$(cat "$scratch/$name.stdout")"
    else
        fenced "$scratch/$name.stdout"
    fi | page "$name" "$made"
done

# The plan against the outcome on the shipped example (docs/calibrate.md, "Plan against outcome"):
# the three plans of --plan-with all, plan.md as the page.
if [ $# -eq 0 ] || [[ " $* " == *" calibrate-example-plan "* ]]; then
    command="calibrate robots/irb120.toml docs/calibrate/example_measurements.csv --no-plots --plan-worlds 100 --plan-with all"
    echo "regenerate: calibrate-example-plan: calsim $command"
    start=$SECONDS
    # shellcheck disable=SC2086
    "$calsim" $command --out "$scratch/calibrate-example-plan" >"$scratch/calibrate-example-plan.stdout"
    page calibrate-example-plan "\`calsim $command\`" "plan.md of the report" \
        <"$scratch/calibrate-example-plan/example_measurements.calibration/plan.md"
fi

# The plan against the outcome over files of the example's own generating process
# (docs/calibrate.md, "Plan against outcome"): examples/twin_plan_check.rs, seeds, worlds, variant
# and plans as its doc says.
checks=(
    "twin-plan-check-pure|1 40 0 pure"
    "twin-plan-check-no-outlier|1 40 0 no-outlier"
    "twin-plan-check-as-shipped|1 40 0 as-shipped"
    "twin-plan-check-causes|1 30 30 as-shipped process,true-effects,effects-4x20,twin,noise,residual"
    "twin-plan-check-process|1 100 30 as-shipped process"
    "twin-plan-check-process-world|1 100 30 as-shipped@world process"
)
built=""
for run in "${checks[@]}"; do
    IFS='|' read -r name arguments <<<"$run"
    if [ $# -gt 0 ] && [[ " $* " != *" $name "* ]]; then
        continue
    fi
    if [ -z "$built" ]; then
        cargo build --release --locked --example twin_plan_check
        built=yes
    fi
    command="cargo run --release --example twin_plan_check -- $arguments"
    echo "regenerate: $name: $command"
    start=$SECONDS
    # shellcheck disable=SC2086
    "$CARGO_TARGET_DIR/release/examples/twin_plan_check" $arguments >"$scratch/$name.stdout"
    fenced "$scratch/$name.stdout" | page "$name" "\`$command\`"
done

# DETMAX warm-started from a neighbouring design's set against its random start
# (docs/optimise.md, "What an evaluation costs"): examples/detmax_warm.rs, 200 designs of 300 from
# a pool of 3 x 251 with sphere 2 moved 5, 20 and 100 mm.
if [ $# -eq 0 ] || [[ " $* " == *" detmax-warm "* ]]; then
    cargo build --release --locked --example detmax_warm
    command="cargo run --release --example detmax_warm -- 200 300 251 SHIFT"
    echo "regenerate: detmax-warm: $command"
    start=$SECONDS
    for shift in 5 20 100; do
        echo "sphere 2 moved $shift mm:"
        "$CARGO_TARGET_DIR/release/examples/detmax_warm" 200 300 251 "$shift"
        echo
    done >"$scratch/detmax-warm.stdout"
    fenced "$scratch/detmax-warm.stdout" | page detmax-warm "\`$command\` for SHIFT 5, 20 and 100"
fi

# The simulated examples of docs/calibrate.md (their measurement files are made, not kept).
if [ $# -eq 0 ] || [[ " $* " == *" imported-example "* ]]; then
    bash scripts/docs/simulated_example.sh docs/calibrate/imported_example.toml robots/examples/lrmate200ic_coupled.toml \
        --payload-kg 2 --payload-com-mm 0,0,50 --tool-per-session --hold-out-session L
fi
if [ $# -eq 0 ] || [[ " $* " == *" probe-example "* ]]; then
    bash scripts/docs/simulated_example.sh docs/calibrate/probe_example.toml robots/irb120.toml \
        --orientation-noise-mdeg 10 --position-noise-mm 0.012 --hold-out-session L --no-plots
fi

# The plan's round trip over 20 seeds (docs/plan.md, "How far to trust the band").
if [ $# -eq 0 ] || [[ " $* " == *" plan-round-trip "* ]]; then
    echo "regenerate: plan-round-trip: bash scripts/docs/plan_round_trip.sh <calsim> 20"
    start=$SECONDS
    bash scripts/docs/plan_round_trip.sh "$calsim" 20 >"$scratch/plan-round-trip.stdout"
    page plan-round-trip "\`bash scripts/docs/plan_round_trip.sh target/release/calsim 20\`" <"$scratch/plan-round-trip.stdout"
fi

# Coverage of the twin's smooth-field length and level intervals (docs/twin.md, "A smooth per-pose
# error"): examples/twin_length_coverage.rs, 40 worlds per true length.
if [ $# -eq 0 ] || [[ " $* " == *" twin-length-coverage "* ]]; then
    cargo build --release --locked --example twin_length_coverage
    command="cargo run --release --example twin_length_coverage -- 40 0.5,1.5,4.0"
    echo "regenerate: twin-length-coverage: $command"
    start=$SECONDS
    "$CARGO_TARGET_DIR/release/examples/twin_length_coverage" 40 0.5,1.5,4.0 >"$scratch/twin-length-coverage.stdout"
    page twin-length-coverage "\`$command\`" <"$scratch/twin-length-coverage.stdout"
fi

# Where the ISO 9283 cube would have to stand for Table 6's before row (docs/guide-reproduce.md).
if [ $# -eq 0 ] || [[ " $* " == *" table6-placement "* ]]; then
    cargo build --release --locked --example table6_placement
    echo "regenerate: table6-placement: cargo run --release --example table6_placement"
    start=$SECONDS
    "$CARGO_TARGET_DIR/release/examples/table6_placement" >"$scratch/table6-placement.stdout"
    page table6-placement "\`cargo run --release --example table6_placement\`" <"$scratch/table6-placement.stdout"
fi

# The speed figures of docs/benchmarks.md: the kernels' criterion medians and two whole studies,
# with the machine and its load (speed figures hold for that machine and load only).
if [ $# -eq 0 ] || [[ " $* " == *" benchmarks "* ]]; then
    echo "regenerate: benchmarks: cargo bench --bench core; calsim run (TriCal, SPMS)"
    start=$SECONDS
    load_before="$(cut -d' ' -f1-3 /proc/loadavg)"
    cargo bench --locked --bench core 2>/dev/null | grep -E '^[^ ]|time:' >"$scratch/bench-core.stdout"
    for scenario in irb120_trical er20c10_spms; do
        /usr/bin/time -f "$scenario: %e s wall, %U s user, %S s system, %M KB peak RSS" \
            "$calsim" run "scenarios/$scenario.toml" --no-plots --no-recording --out "$scratch/bench-$scenario" \
            >"$scratch/bench-$scenario.stdout" 2>>"$scratch/bench-commands.txt" || [ $? -eq 1 ]
        tail -n 1 "$scratch/bench-$scenario.stdout" >>"$scratch/bench-commands.txt"
    done
    {
        echo "<!-- made by scripts/docs/regenerate.sh: do not edit -->"
        echo "*Made by \`cargo bench --bench core\` and \`/usr/bin/time calsim run scenarios/<scenario>.toml --no-plots --no-recording\` at commit $commit in $((SECONDS - start)) s.*"
        echo
        echo "Machine: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //'), $(nproc) cores; load average (1, 5, 15 min) before: $load_before, after: $(cut -d' ' -f1-3 /proc/loadavg)."
        echo
        echo "## Kernels (criterion: lower bound, median, upper bound)"
        echo
        echo '```text'
        cat "$scratch/bench-core.stdout"
        echo '```'
        echo
        echo "## Whole studies (release build, default threads; the study's own timing line after each)"
        echo
        echo '```text'
        cat "$scratch/bench-commands.txt"
        echo '```'
    } >"docs/generated/benchmarks.md"
    echo "regenerate: benchmarks: docs/generated/benchmarks.md"
fi

# The README's quick start timed from a fresh clone and an empty target directory (a cold build).
if [ $# -eq 0 ] || [[ " $* " == *" first-hour "* ]]; then
    bash scripts/docs/first_hour.sh
fi

python3 scripts/ci/doc_numbers.py "$calsim" --write
