#!/usr/bin/env bash
# The round trip of docs/plan.md over seeds: for each seed, the shipped IRB 120 plan (its seed set,
# 20 worlds) with --simulate, then `calsim calibrate` of its simulated measurements with the same
# seed; prints the plan's predicted P10-P90 of the held-out median beside the chosen model's
# measured held-out median, and how many land inside.
# Usage: scripts/docs/plan_round_trip.sh [calsim binary] [seeds, default 8]
set -euo pipefail
cd "$(dirname "$0")/../.."
calsim="${1:-target/release/calsim}"
seeds="${2:-8}"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
robot="$(pwd)/robots/irb120.toml"
inside=0
echo "| seed | predicted P10-P90, mm | measured held-out median, mm | inside |"
echo "|---|---|---|---|"
for s in $(seq 1 "$seeds"); do
    sed -e "s|^robot = .*|robot = \"$robot\"|" -e "s|^seed = .*|seed = $s|" -e "s|^worlds = .*|worlds = 20|" \
        scenarios/plans/irb120_tracker.toml > "$work/rt$s.toml"
    line="$("$calsim" plan "$work/rt$s.toml" --out "$work" --simulate 2>/dev/null | grep '^calsim plan: ')"
    band="$(sed -E 's/.*\(P10-P90 ([0-9.]+)-([0-9.]+)\).*/\1 \2/' <<< "$line")"
    read -r lo hi <<< "$band"
    out="$("$calsim" calibrate robots/irb120.toml "$work/rt$s.plan/simulated.csv" --seed "$s" --no-plots --out "$work" 2>/dev/null)"
    chosen="$(grep -- '<- chosen' <<< "$out" | awk '{print $1}')"
    # The measured held-out median: the chosen model's row of summary.md's held-out table.
    median="$(sed -n '/^## Held-out errors, measured and predicted/,/^#/p' "$work/simulated.calibration/summary.md" |
        grep -E "^\| $chosen \| [0-9]+ \|" | awk -F'|' '{gsub(/ /,"",$5); print $5}')"
    [ -n "$median" ] || { echo "plan_round_trip: seed $s: no held-out median of $chosen in summary.md" >&2; exit 1; }
    ok="$(awk -v m="$median" -v a="$lo" -v b="$hi" 'BEGIN { print (m >= a && m <= b) ? "yes" : "no" }')"
    [ "$ok" = yes ] && inside=$((inside + 1))
    echo "| $s | $lo-$hi | $median | $ok |"
done
echo
echo "inside the plan's P10-P90: $inside of $seeds"
