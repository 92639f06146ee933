#!/usr/bin/env python3
"""The CI check as a test: its pass rate with the model unchanged and its detection rate of injected
regressions, each over many seeds (every seed a check of its own: `study.check_realisations`
worlds, judged at `study.check_false_alarm`).

    python3 scripts/ci/check_power.py [CALSIM_BIN] [--seeds 200] [--regression-seeds 50] [--first-seed 1]

(CALSIM_BIN defaults to the environment's CALSIM, as scripts/docs/regenerate.sh gives it.)

(`--regression-seeds 0` runs the unchanged model only, e.g. to extend its seeds with --first-seed.)

The regressions are written as variants of scenarios/ci_quick.toml and robots/irb120.toml in a
temporary directory: the compliance term's sign flipped (the [truth] compliances c2-c6 negated),
the harmonic amplitude doubled (robot.unmodelled.transmission_high_mdeg x 2), joint 2's offset off
by 0.01 deg (the [truth] theta_offs2 + 0.01). Prints one table row per case: seeds, passes,
the rate with its 95 % Clopper-Pearson interval, and the median wall time of one check.
"""

import argparse
import math
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def binom_cdf(k: int, n: int, p: float) -> float:
    if k < 0:
        return 0.0
    if k >= n:
        return 1.0
    return sum(math.comb(n, i) * p**i * (1 - p) ** (n - i) for i in range(k + 1))


def clopper_pearson(x: int, n: int, conf: float = 0.95) -> tuple[float, float]:
    """Two-sided Clopper-Pearson interval of x successes in n trials (bisection on the binomial sum)."""
    a = (1 - conf) / 2

    def solve(f, lo=0.0, hi=1.0):
        for _ in range(100):
            mid = (lo + hi) / 2
            if f(mid):
                hi = mid
            else:
                lo = mid
        return (lo + hi) / 2

    lower = 0.0 if x == 0 else solve(lambda p: 1 - binom_cdf(x - 1, n, p) >= a)
    upper = 1.0 if x == n else solve(lambda p: binom_cdf(x, n, p) <= a)
    return lower, upper


def variant(tmp: Path, name: str, scenario_edit, robot_edit) -> Path:
    d = tmp / name
    (d / "scenarios").mkdir(parents=True)
    (d / "robots").mkdir()
    robot = (REPO / "robots" / "irb120.toml").read_text()
    (d / "robots" / "irb120.toml").write_text(robot_edit(robot))
    scen = (REPO / "scenarios" / "ci_quick.toml").read_text()
    (d / "scenarios" / "ci_quick.toml").write_text(scenario_edit(scen))
    return d / "scenarios" / "ci_quick.toml"


def truth_edit(robot: str, key: str, f) -> str:
    head, truth = robot.split("[truth]", 1)

    def one(m):
        return f"{m.group(1)}{f(float(m.group(2))):.6f}"

    truth, n = re.subn(rf"(?m)^({key} = )(-?[0-9.]+)", one, truth)
    assert n == 1, f"{key} not found once in [truth]"
    return head + "[truth]" + truth


def flip_compliances(robot: str) -> str:
    for c in ["c2", "c3", "c4", "c5", "c6"]:
        robot = truth_edit(robot, c, lambda v: -v)
    return robot


def double_harmonics(scen: str) -> str:
    out, n = re.subn(r"(?m)^(transmission_high_mdeg = )([0-9.]+)", lambda m: f"{m.group(1)}{2 * float(m.group(2))}", scen)
    assert n == 1
    return out


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("calsim", nargs="?", default=os.environ.get("CALSIM"))
    ap.add_argument("--seeds", type=int, default=200)
    ap.add_argument("--regression-seeds", type=int, default=50)
    ap.add_argument("--first-seed", type=int, default=1)
    args = ap.parse_args()
    if not args.calsim:
        ap.error("no calsim binary: give CALSIM_BIN or set CALSIM")
    same = lambda t: t  # noqa: E731
    tmp = Path(tempfile.mkdtemp(prefix="calsim-check-power-"))
    try:
        cases = [
            ("model unchanged", variant(tmp, "unchanged", same, same), args.seeds, "pass"),
            ("compliance sign flipped", variant(tmp, "compliance", same, flip_compliances), args.regression_seeds, "fail"),
            ("harmonic amplitude doubled", variant(tmp, "harmonics", double_harmonics, same), args.regression_seeds, "fail"),
            ("joint 2 offset +0.01 deg", variant(tmp, "offset", same, lambda r: truth_edit(r, "theta_offs2", lambda v: v + 0.01)), args.regression_seeds, "fail"),
        ]
        print("| case | seeds | counted | rate (95 % interval) | median s per check |")
        print("|---|---|---|---|---|")
        for label, scenario, seeds, counted in cases:
            if seeds == 0:
                continue
            hits, times = 0, []
            for s in range(args.first_seed, args.first_seed + seeds):
                out = tmp / "out"
                t0 = time.monotonic()
                r = subprocess.run(
                    [args.calsim, "check", str(scenario), "--seed", str(s), "--no-plots", "--no-recording", "--out", str(out)],
                    capture_output=True,
                    text=True,
                )
                times.append(time.monotonic() - t0)
                shutil.rmtree(out, ignore_errors=True)
                if r.returncode not in (0, 1):
                    print(f"{label}, seed {s}: exit {r.returncode}: {r.stderr.strip()}", file=sys.stderr)
                    return 2
                passed = r.returncode == 0
                hits += passed if counted == "pass" else (not passed)
            lo, hi = clopper_pearson(hits, seeds)
            what = "passed" if counted == "pass" else "detected"
            print(f"| {label} | {seeds} | {hits} {what} | {hits / seeds:.3f} ({lo:.3f}-{hi:.3f}) | {statistics.median(times):.1f} |", flush=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
