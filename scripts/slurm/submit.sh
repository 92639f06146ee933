#!/usr/bin/env bash
# Runs a calsim sweep on a Slurm cluster: a job array of SHARDS tasks, then a merge job that
# starts when every task has succeeded (afterok). Prints the two job ids.
#
#   scripts/slurm/submit.sh <calsim binary> <sweep file> <output directory> <shards> [sbatch options...]
set -euo pipefail
if [ $# -lt 4 ]; then
    echo "usage: $0 <calsim binary> <sweep file> <output directory> <shards> [sbatch options...]" >&2
    exit 2
fi
calsim=$(realpath "$1"); sweep=$(realpath "$2"); out=$(realpath -m "$3"); shards=$4; shift 4
case "$shards" in ''|*[!0-9]*) echo "shards: $shards is not a whole number" >&2; exit 2 ;; esac
[ "$shards" -ge 1 ] || { echo "shards: at least 1" >&2; exit 2; }
name=$(basename "$sweep" .toml)
here=$(cd "$(dirname "$0")" && pwd)
mkdir -p "$out"
array=$(CALSIM=$calsim SWEEP=$sweep OUT=$out sbatch --parsable --export=ALL --chdir="$out" --array="0-$((shards - 1))" "$@" "$here/sweep.sbatch")
array=${array%%;*}
merge=$(CALSIM=$calsim OUT=$out NAME=$name SHARDS=$shards sbatch --parsable --export=ALL --chdir="$out" --dependency="afterok:$array" "$@" "$here/merge.sbatch")
echo "$array $merge"
