#!/usr/bin/env bash
# Times the README's quick start as a newcomer meets it: a fresh clone of HEAD, an empty target
# directory (the dependencies compiled too; the crates themselves are taken from cargo's download
# cache or the registry), then the quick start's two commands. Writes docs/generated/first-hour.md
# with the machine's core count and load, so that the figures read for what they are.
#
# Usage: bash scripts/docs/first_hour.sh [--tests]   (--tests: the test suite too, its build included)
# With FIRST_HOUR_TARGET_DIR set to a directory that does not exist yet, the builds go there and
# are kept afterwards (a new machine's build cache, warmed by the timing itself).
set -euo pipefail
cd "$(dirname "$0")/../.."
repo="$(pwd)"
tests=0
[ "${1:-}" = "--tests" ] && tests=1
scratch="$(mktemp -d)"
trap 'rm -rf "$scratch"' EXIT
git clone -q "$repo" "$scratch/calsim"
# The tests read the papers' data from ../shared beside the clone, as CI lays it out.
[ -d "$repo/../shared" ] && ln -s "$(cd "$repo/../shared" && pwd)" "$scratch/shared"
commit="$(git -C "$scratch/calsim" rev-parse --short HEAD)"
export CARGO_TARGET_DIR="$scratch/target"
if [ -n "${FIRST_HOUR_TARGET_DIR:-}" ]; then
    [ -e "$FIRST_HOUR_TARGET_DIR" ] && {
        echo "first-hour: FIRST_HOUR_TARGET_DIR=$FIRST_HOUR_TARGET_DIR exists: the build would not be a first one" >&2
        exit 2
    }
    export CARGO_TARGET_DIR="$FIRST_HOUR_TARGET_DIR"
fi
load_before="$(cut -d' ' -f1-3 /proc/loadavg)"

# Runs "$@" in the clone under /usr/bin/time; prints "wall user system peak-RSS-MB".
timed() {
    local log="$scratch/time.$RANDOM"
    (cd "$scratch/calsim" && /usr/bin/time -f '%e %U %S %M' -o "$log" "$@" >"$scratch/out.log" 2>&1) || {
        tail -n 20 "$scratch/out.log" >&2
        return 1
    }
    awk '{ printf "%.1f %.0f %.0f %.0f", $1, $2, $3, $4 / 1024 }' "$log"
}
row() { # name, command, "wall user system rss"
    read -r wall user sys rss <<<"$3"
    local shown="$wall s"
    local whole="${wall%.*}"
    [ "$whole" -ge 60 ] && shown="$((whole / 60)) min $(printf '%02d' $((whole % 60))) s"
    printf '| `%s` | %s | %s | %d s | %d s | %d |\n' "$1" "$2" "$shown" "$user" "$sys" "$rss"
}

echo "first-hour: cold build of $commit in $scratch"
build="$(timed cargo build --release --locked)"
run="$(timed "$CARGO_TARGET_DIR/release/calsim" run scenarios/irb120_trical.toml)"
if [ "$tests" = 1 ]; then
    echo "first-hour: cargo test --locked"
    test="$(timed cargo test --locked)"
fi
{
    echo "<!-- made by scripts/docs/first_hour.sh: do not edit -->"
    echo "*Made by \`bash scripts/docs/first_hour.sh${1:+ $1}\` at commit $commit on $(nproc) cores,"
    echo "load average $load_before before the start.*"
    echo
    echo "The README's quick start from a fresh clone with an empty target directory (the crates"
    echo "already downloaded): the first build compiles every dependency."
    echo
    echo "| step | command | wall | user | system | peak RSS, MB |"
    echo "|---|---|---|---|---|---|"
    row "cargo build --release --locked" "the first build" "$build"
    row "calsim run scenarios/irb120_trical.toml" "the TriCal study" "$run"
    [ "$tests" = 1 ] && row "cargo test --locked" "the test suite, its build included" "$test"
    true
} >docs/generated/first-hour.md
echo "first-hour: docs/generated/first-hour.md"
