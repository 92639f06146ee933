#!/usr/bin/env python3
"""Compare two calsim results directories table by table, column by column.

Usage: scripts/bench/compare_results.py OLD_DIR NEW_DIR   (needs python3 with polars)

For every parquet table both directories hold: whether it is identical, and per numeric column
the largest absolute difference, the largest relative difference (|a - b| / max(|a|, |b|)) and
the rows that differ; non-numeric columns must be equal. Exit 0 when every table has the same
shape and columns (the numbers may differ), 1 otherwise, 2 on bad input (one line naming it: a
directory that is missing or holds no table, a table that cannot be read).
"""
import sys
from pathlib import Path

import polars as pl


def main(old: Path, new: Path) -> int:
    for d in (old, new):
        if not d.is_dir():
            print(f"compare_results: {d}: not a directory", file=sys.stderr)
            return 2
        if not any(d.glob("*.parquet")):
            print(f"compare_results: {d}: holds no parquet table", file=sys.stderr)
            return 2
    status = 0
    tables = sorted({p.name for p in old.glob("*.parquet")} & {p.name for p in new.glob("*.parquet")})
    only = sorted({p.name for p in old.glob("*.parquet")} ^ {p.name for p in new.glob("*.parquet")})
    for name in only:
        print(f"{name}: in one directory only")
        status = 1
    for name in tables:
        try:
            a, b = pl.read_parquet(old / name), pl.read_parquet(new / name)
        except Exception as e:  # a cut or foreign file: one line, not a traceback
            print(f"compare_results: {name}: cannot be read: {str(e).splitlines()[0] if str(e) else type(e).__name__}", file=sys.stderr)
            return 2
        if a.shape != b.shape or a.columns != b.columns:
            print(f"{name}: shape {a.shape} vs {b.shape}, columns differ: {a.columns != b.columns}")
            status = 1
            continue
        if a.equals(b, null_equal=True):
            print(f"{name}: identical ({a.height} rows)")
            continue
        print(f"{name}: {a.height} rows, differs")
        for c in a.columns:
            x, y = a[c], b[c]
            if x.dtype.is_numeric():
                xf, yf = x.cast(pl.Float64), y.cast(pl.Float64)
                both_null = xf.is_null() & yf.is_null()
                diff = (xf - yf).abs()
                differ = int((~both_null & (diff.fill_null(1.0).fill_nan(1.0) > 0)).sum())
                if differ == 0:
                    continue
                scale = pl.select(pl.max_horizontal(xf.abs(), yf.abs())).to_series()
                rel = (diff / scale).fill_nan(0.0)
                print(f"  {c}: {differ} rows differ, max |diff| {diff.max():.3e}, max relative {rel.max():.3e}")
            elif not x.equals(y, null_equal=True):
                print(f"  {c}: {int((x != y).sum())} values differ (not numeric)")
    return status


if __name__ == "__main__":
    if len(sys.argv) != 3:
        print("compare_results: usage: compare_results.py OLD_DIR NEW_DIR", file=sys.stderr)
        sys.exit(2)
    sys.exit(main(Path(sys.argv[1]), Path(sys.argv[2])))
