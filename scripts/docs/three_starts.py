#!/usr/bin/env python3
"""The docs' three-start table: the TriCal question searched from several starts, read from the
tables each `calsim optimise --out DIR` run wrote (trace.parquet, answer.parquet,
verified.parquet, manifest.json) and the design file its manifest names (the campaign budget).

Usage: python3 scripts/docs/three_starts.py LABEL=DIR [LABEL=DIR ...]

Prints a Markdown table, one row per run: the designs its search asked (ruled out by their
geometry / repaired to a valid design and run, `trace.parquet`'s repaired column / failed in
every world), the answer (the answer rule's design, `answer.parquet`) with its held-out
P(success) and 90 % interval and its campaign, the best held-out design within the
budget and the best whatever its campaign; then, for each pair of runs, whether each answer's P
lies within the other's interval.
"""

import glob
import json
import os
import sys
import tomllib

import polars as pl


def results_dir(out: str) -> str:
    """The results directory under an --out directory (the one holding answer.parquet)."""
    found = sorted(glob.glob(os.path.join(out, "*", "answer.parquet")))
    if not found:
        sys.exit(f"{out}: no answer.parquet under it (not a calsim optimise --out directory)")
    return os.path.dirname(found[0])


def budget_h(manifest: dict) -> float | None:
    with open(manifest["design_file"], "rb") as f:
        design = tomllib.load(f)
    return design.get("objective", {}).get("campaign_h_at_most")


def row_text(r: dict) -> str:
    return f"{r['design']}, sets of {r['set_size']}: {r['estimate']:.3f} ({r['lower']:.3f}-{r['upper']:.3f}), {r['campaign_h']:.3f} h"


def best(rows: pl.DataFrame) -> dict | None:
    if rows.height == 0:
        return None
    return rows.sort(["estimate", "lower", "campaign_h"], descending=[True, True, False]).row(0, named=True)


def one_run(label: str, out: str) -> dict:
    d = results_dir(out)
    manifest = json.load(open(os.path.join(d, "manifest.json")))
    trace = pl.read_parquet(os.path.join(d, "trace.parquet"))
    if "repaired" not in trace.columns:
        trace = trace.with_columns(pl.lit("").alias("repaired"))
    designs = trace.select(["restart", "evaluation", "count", "violation", "repaired", "worlds", "failed_worlds"]).unique()
    asked = designs.height
    ruled_out = designs.filter(pl.col("violation") != "").height
    repaired = designs.filter(pl.col("repaired") != "").height
    failed = designs.filter((pl.col("worlds") > 0) & (pl.col("failed_worlds") == pl.col("worlds"))).height
    counts = sorted(designs["count"].unique().to_list())
    answer = pl.read_parquet(os.path.join(d, "answer.parquet")).filter(pl.col("stage") == "held_out").row(0, named=True)
    verified = pl.read_parquet(os.path.join(d, "verified.parquet")).filter(pl.col("worlds") > 0)
    h = budget_h(manifest)
    within = best(verified.filter(pl.col("campaign_h") <= h)) if h is not None else None
    overall = best(verified)
    wall = manifest.get("search_s", 0.0) + manifest.get("finish_s", 0.0)
    return {
        "label": label,
        "counts": counts,
        "asked": asked,
        "ruled_out": ruled_out,
        "repaired": repaired,
        "failed": failed,
        "answer": answer,
        "within": within,
        "overall": overall,
        "budget": h,
        "wall": wall,
        "commit": manifest.get("git_commit", "")[:7],
    }


def main() -> None:
    runs = []
    for arg in sys.argv[1:]:
        label, sep, out = arg.partition("=")
        if not sep:
            sys.exit(f"{arg}: expected LABEL=DIR")
        runs.append(one_run(label, out))
    if not runs:
        sys.exit(__doc__)
    print("| start | counts searched | designs asked: ruled out by geometry / repaired and run / failed in every world | answer (the answer rule) | its held-out P (90 % interval) | campaign, h | best held-out design within the budget | best held-out design | wall, s (search + race and verification) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in runs:
        a = r["answer"]
        counts = f"{r['counts'][0]}-{r['counts'][-1]}" if r["counts"] else "-"
        within = row_text(r["within"]) if r["within"] else "none"
        overall = row_text(r["overall"]) if r["overall"] else "none"
        print(
            f"| {r['label']} | {counts} | {r['asked']}: {r['ruled_out']} / {r['repaired']} / {r['failed']} | {a['design']}, sets of {a['set_size']} "
            f"| {a['estimate']:.3f} ({a['lower']:.3f}-{a['upper']:.3f}) | {a['campaign_h']:.3f} | {within} | {overall} | {r['wall']:.0f} |"
        )
    print()
    budgets = {r["budget"] for r in runs}
    print(f"Budget: campaign <= {', '.join(str(b) for b in sorted(budgets, key=str))} h (the design files' `campaign_h_at_most`); P is the held-out P(success) with its 90 % interval; commits: {', '.join(sorted({r['commit'] for r in runs}))}.")
    print()
    for i, r in enumerate(runs):
        for s in runs[i + 1 :]:
            a, b = r["answer"], s["answer"]
            a_in_b = b["lower"] <= a["estimate"] <= b["upper"]
            b_in_a = a["lower"] <= b["estimate"] <= a["upper"]
            both = "yes" if a_in_b and b_in_a else "no"
            print(
                f"- {r['label']} ({a['estimate']:.3f}) against {s['label']} ({b['estimate']:.3f}): each answer's P within the other's interval: "
                f"**{both}** (difference {a['estimate'] - b['estimate']:+.3f})"
            )


if __name__ == "__main__":
    main()
