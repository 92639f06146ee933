#!/usr/bin/env python3
"""The numbers of README.md and docs/ that cheap commands make, checked against those commands.

Usage: python3 scripts/ci/doc_numbers.py <calsim binary> [--write] [--only NAME]

Each excerpt below names the command that makes it, the page it is on and how its text is made
from the command's output. In a page an excerpt sits between two markers,

    <!-- doc_numbers: NAME -->
    ...
    <!-- /doc_numbers: NAME -->

and is the text made from the command, byte for byte. Without --write, each command is run (in a
scratch directory holding the repository's inputs) and every excerpt compared with its page: a
page whose excerpt differs fails the step, with both texts shown (CI runs it: .ci/run). With
--write, the excerpts are written into their pages. The commands take about a minute in all with
the release binary on 2 cores; the expensive figures of the docs are made by
scripts/docs/regenerate.sh instead.
"""

import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
INPUTS = ["scenarios", "robots", "docs", "reference", "python"]

CHECK_30 = "calsim check scenarios/irb120_trical.toml --realisations 30 --no-plots --no-recording"
BUDGET = "calsim budget scenarios/irb120_trical.toml --realisations 20"
SWEEP = "calsim sweep scenarios/sweeps/sphere_layout.toml"


def row(output: str, starts: str) -> str:
    """The line of `output` that starts with `starts` (one, or the step fails)."""
    lines = [l for l in output.splitlines() if l.startswith(starts)]
    if len(lines) != 1:
        raise SystemExit(f"doc_numbers: {len(lines)} lines of the output start with {starts!r}")
    return lines[0]


def cells(line: str) -> list[str]:
    """The cells of a markdown table row."""
    return [c.strip() for c in line.strip().strip("|").split("|")]


def readme_check(out: str) -> str:
    # figure, published, run 0, median, interval (confidence), P10-P90, band, result
    line = row(out, "after, sets of 75: median error, mm (Table 8)")
    parts = re.split(r"\s{2,}", line.strip())
    median, interval, p10_p90, verdict = parts[3], parts[4].split(" ")[0], parts[5], parts[7]
    return (
        "One world is one draw of every figure; the verdict is `calsim check`'s, over worlds. Over 30 worlds\n"
        f"(`{CHECK_30.replace(' --no-plots --no-recording', '')}`) the after-calibration median is\n"
        f"{median} mm (P10-P90 {p10_p90}), the interval of that median {interval} against the band 0.177-0.239\n"
        f"({verdict}); the Table 8 tracker and optical-CMM rows come from the authors' earlier study, whose setup the\n"
        "virtual cell does not simulate ([docs/findings.md](docs/findings.md#table-8-the-same-robot-calibrated-with-three-instruments)).\n"
    )


def budget_rows(out: str) -> list[list[str]]:
    head = row(out, "| source | value | share")
    lines = out.splitlines()
    i = lines.index(head) + 2
    rows = []
    while i < len(lines) and lines[i].startswith("|"):
        rows.append(cells(lines[i]))
        i += 1
    return rows


def readme_budget(out: str) -> str:
    rows = {r[0]: r for r in budget_rows(out)}
    t = rows["transmission errors, high orders"]
    ind = rows["indicator accuracy"]
    m = re.match(r"(\S+) \((.*)\)(, noise)?$", ind[6])
    said = "not told from none" if m.group(3) else "told from none"
    return (
        "In the default TriCal cell the unmodelled transmission errors take a share of\n"
        f"{t[2]} of the budget (95 % interval); a twice as good indicator changes the p95 by\n"
        f"{m.group(1)} mm ({m.group(2)} mm, paired per world: {said}).\n"
    )


def guide_budget(out: str) -> str:
    head = row(out, "| source | value | share")
    lines = out.splitlines()
    i = lines.index(head)
    j = i
    while j < len(lines) and lines[j].startswith("|"):
        j += 1
    floor = re.search(r"median over realisations: (\S+) mm with every source, (\S+) mm with none", out)
    return (
        f"p95 after calibration {floor.group(1)} mm with every source, {floor.group(2)} mm with none (`{BUDGET}`):\n\n"
        + "\n".join(lines[i:j])
        + "\n"
    )


def sweep_table(out: str) -> str:
    rank = {}
    for line in out.splitlines():
        m = re.match(r"\| \d+ \| (\d+) cell\.layout = .* \| (\d+\.\d+) \| 20 \|$", line)
        if m:
            rank[m.group(1)] = m.group(2)
    body = []
    for line in out.splitlines():
        m = re.match(r"\| (\d+) \| cell\.layout = \{ n = (\d+), spacing_mm = (\d+) \} \| detmax \| 75 \| (.*)", line)
        if not m or m.group(1) not in rank:
            continue
        c = cells(m.group(4))
        span = lambda s: re.sub(r"^(\S+) \(.*P10-P90 (\S+)\)$", r"\1 (\2)", s)
        name = f"{m.group(2)} spheres {m.group(3)} mm apart" + (" (the paper's)" if (m.group(2), m.group(3)) == ("3", "300") else "")
        body.append(f"| {name} | {span(c[1])} | {span(c[2])} | {c[4]} | {c[5]} | {rank[m.group(1)]} |")
    return (
        f"Made by `{SWEEP}` (checked by CI: `scripts/ci/doc_numbers.py`); P(max <= t) with its 90 % interval:\n\n"
        "| layout (circle, sphere 1 where the paper's is) | p95, mm | max, mm | P(max <= 0.5 mm) | P(max <= 1 mm) | campaign, h |\n"
        "|---|---|---|---|---|---|\n" + "\n".join(body) + "\n"
    )


def run_block(out: str) -> str:
    """The terminal output of a run, its last line (the wall times) written as `timing: ...`."""
    lines = out.rstrip("\n").split("\n")
    if not lines[-1].startswith("timing: "):
        raise SystemExit(f"doc_numbers: the run's last line is not its timing: {lines[-1]!r}")
    return "```text\n" + "\n".join(lines[:-1]) + "\ntiming: ...\n```\n"


# name: (page, command, how the excerpt is made from the command's stdout)
EXCERPTS = {
    "readme-check": ("README.md", CHECK_30, readme_check),
    "readme-budget": ("README.md", BUDGET, readme_budget),
    "guide-budget": ("docs/guide-budget.md", BUDGET, guide_budget),
    "guide-sweeps-layout": ("docs/guide-sweeps.md", SWEEP, sweep_table),
    "guide-reproduce-trical": ("docs/guide-reproduce.md", "calsim run scenarios/irb120_trical.toml --no-plots --no-recording", run_block),
    "guide-reproduce-spms": ("docs/guide-reproduce.md", "calsim run scenarios/er20c10_spms.toml --no-plots --no-recording", run_block),
}


def block(name: str) -> re.Pattern:
    return re.compile(rf"(<!-- doc_numbers: {re.escape(name)} -->\n)(.*?)(<!-- /doc_numbers: {re.escape(name)} -->)", re.S)


def main() -> int:
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    write = "--write" in sys.argv
    only = sys.argv[sys.argv.index("--only") + 1] if "--only" in sys.argv else None
    calsim = Path(args[0]).resolve()
    outputs: dict[str, str] = {}
    failed = 0
    with tempfile.TemporaryDirectory(prefix="calsim-docnumbers-") as scratch:
        work = Path(scratch) / "work"
        work.mkdir()
        for name in INPUTS:
            (work / name).symlink_to(REPO / name)
        for name, (page, command, make) in EXCERPTS.items():
            if only and name != only:
                continue
            if command not in outputs:
                argv = command.split()
                # Each command its own results directory: a run beside an earlier check of its world
                # would print that check's spread.
                out = work / f"results-{len(outputs)}"
                r = subprocess.run([str(calsim), *argv[1:], "--out", str(out)], cwd=work, capture_output=True, text=True,
                                   env=dict(os.environ, RUST_LIB_BACKTRACE="0"))
                if r.returncode not in (0, 1):
                    print(f"doc_numbers: {command}: exit {r.returncode}\n{r.stderr[-2000:]}", file=sys.stderr)
                    return 1
                outputs[command] = r.stdout
            text = make(outputs[command])
            path = REPO / page
            doc = path.read_text()
            m = block(name).search(doc)
            if not m:
                print(f"doc_numbers: {page}: no block {name!r} (<!-- doc_numbers: {name} --> ... <!-- /doc_numbers: {name} -->)", file=sys.stderr)
                failed += 1
                continue
            if m.group(2) == text:
                print(f"doc_numbers: {page}: {name}: as `{command}` prints", flush=True)
                continue
            if write:
                path.write_text(doc[: m.start(2)] + text + doc[m.end(2):])
                print(f"doc_numbers: {page}: {name}: written from `{command}`")
                continue
            print(f"doc_numbers: {page}: {name}: differs from what `{command}` makes.\n--- page\n{m.group(2)}--- command\n{text}", file=sys.stderr)
            failed += 1
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
