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
--write, the excerpts are written into their pages. An excerpt is made from the command's standard
output or from the summary.md it writes (`Output.summary`), wall times and scratch paths left out.
The commands take about two minutes of CPU time in all with the release binary; the expensive
figures of the docs are made by scripts/docs/regenerate.sh instead.
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
RUN_TRICAL = "calsim run scenarios/irb120_trical.toml --no-plots --no-recording"
RUN_SPMS = "calsim run scenarios/er20c10_spms.toml --no-plots --no-recording"
CHECK_SPMS = "calsim check scenarios/er20c10_spms.toml --realisations 20 --no-plots --no-recording"
TABLE8 = "calsim table8 scenarios/irb120_trical.toml --realisations 20"
# Commands that print only (no results directory, no --out).
PRINT_ONLY = ("calsim table8 ",)


class Output(str):
    """A command's standard output; `summary` is the summary.md it wrote ("" when none), `plan`
    the plan.md of a `calsim plan` ("" when none)."""

    summary = ""
    plan = ""


def row(output: str, starts: str) -> str:
    """The line of `output` that starts with `starts` (one, or the step fails)."""
    lines = [l for l in output.splitlines() if l.startswith(starts)]
    if len(lines) != 1:
        raise SystemExit(f"doc_numbers: {len(lines)} lines of the output start with {starts!r}")
    return lines[0]


def cells(line: str) -> list[str]:
    """The cells of a markdown table row."""
    return [c.strip() for c in line.strip().strip("|").split("|")]


def fenced(lines: list[str]) -> str:
    return "```text\n" + "\n".join(lines) + "\n```\n"


def terminal_table(out: str, starts: str) -> list[str]:
    """The first terminal table of `out` whose header starts with `starts`, to the next blank line."""
    lines = out.splitlines()
    heads = [i for i, l in enumerate(lines) if l.startswith(starts)]
    if not heads:
        raise SystemExit(f"doc_numbers: no line of the output starts with {starts!r}")
    i = heads[0]
    j = i
    while j < len(lines) and lines[j].strip():
        j += 1
    return lines[i:j]


def md_table(text: str, head: str) -> list[str]:
    """The markdown table of `text` whose header row starts with `head` (one, or the step fails)."""
    lines = text.splitlines()
    i = lines.index(row(text, head))
    j = i
    while j < len(lines) and lines[j].startswith("|"):
        j += 1
    return lines[i:j]


def check_table(out: str) -> str:
    """The figures of a check over worlds, as the terminal prints them."""
    verdict = row(out, "check: ").split("; verdict in ")[0]
    return fenced(terminal_table(out, "figure ") + ["", verdict])


def readme_check(out: str) -> str:
    # figure, published, run 0, median, interval (confidence), P10-P90, band, result
    line = row(out, "after, sets of 75: median error, mm (Table 8)")
    parts = re.split(r"\s{2,}", line.strip())
    median, interval, p10_p90, verdict = parts[3], parts[4].split(" ")[0], parts[5], parts[7]
    missed = [re.split(r"\s{2,}", l.strip())[0] for l in out.splitlines() if l.rstrip().endswith("  MISS")]
    tally = re.search(r"^check: (\d+) of (\d+) figures not missed", out, flags=re.M)
    judged = int(tally.group(2))
    return (
        "One world is one draw of every figure; the verdict is `calsim check`'s, over worlds. Over 30 worlds\n"
        f"(`{CHECK_30.replace(' --no-plots --no-recording', '')}`) the after-calibration median is\n"
        f"{median} mm (P10-P90 {p10_p90}), the interval of that median {interval} against the band 0.177-0.239\n"
        + (
            f"({verdict}). The check exits 1: {len(missed)} of the {judged} figures it judges miss ({'; '.join(missed)}),\n"
            if missed
            else f"({verdict}). The check passes: none of the {judged} figures it judges misses,\n"
        )
        + "as [docs/findings.md](docs/findings.md) explains; the Table 8 tracker and optical-CMM rows (another study's setup) are not judged.\n"
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


def sweep_points(out: str) -> list[dict]:
    """The rows of a sweep's table of errors after calibration, in the order it prints them."""
    rows = []
    for line in md_table(out, "| point | design | selection | n | after median")[2:]:
        c = cells(line)
        span = lambda s: re.sub(r"^(\S+) \(.*P10-P90 (\S+)\)$", r"\1 (\2)", s)
        rows.append({"design": c[1], "selection": c[2], "n": c[3], "median": span(c[4]), "p95": span(c[5]),
                     "max": span(c[6]), "p05": c[8], "p1": c[9], "campaign_s": c[10]})
    return rows


def layout_keys(design: str) -> dict:
    return dict(re.findall(r"(\w+) = (-?[\d.]+)", design))


def sweep_height(out: str) -> str:
    body = []
    for r in sweep_points(out):
        k = layout_keys(r["design"])
        h = int(k.get("height_mm", "0"))
        words = ([f"{abs(h)} mm {'higher' if h > 0 else 'lower'}"] if h else []) + ([f"tilted {k['tilt_deg']} deg"] if "tilt_deg" in k else [])
        name = ", ".join(words) or "the paper's"
        body.append(f"| {name} | {r['p95']} | {r['max']} | {r['p05']} | {r['p1']} |")
    return (
        "| plate (relative to the paper's) | p95, mm | max, mm | P(max <= 0.5 mm) | P(max <= 1 mm) |\n"
        "|---|---|---|---|---|\n" + "\n".join(body) + "\n"
    )


def summary_errors(out: Output) -> str:
    """summary.md's table of the errors before and after calibration."""
    return "\n".join(md_table(out.summary, "| | mean | median |")) + "\n"


def spms_beams(out: Output) -> str:
    """summary.md's beam identification (Table 2) and its PSO line, without the wall times."""
    table = [cells(l) for l in md_table(out.summary, "| solver | unknowns |")]
    t = table[0].index("time, s")
    lines = ["|" + "|".join(f" {x} " if x != "---" else x for x in c[:t] + c[t + 1:]) + "|" for c in table]
    return "\n".join(lines + ["", re.sub(r" in [\d.]+ s\.", ".", row(out.summary, "PSO alone"))]) + "\n"


def spms_sets(out: Output) -> str:
    """summary.md's random and DETMAX sets per set size."""
    return "\n".join(md_table(out.summary, "| selection | n | identified |")) + "\n"


def printed(out: str) -> str:
    """The whole terminal output, its wall times written as `timing: ...`."""
    return fenced(["timing: ..." if l.startswith("timing: ") else l for l in out.rstrip("\n").split("\n")])


def worlds_table(out: str) -> str:
    """The figures over worlds of `run --realisations N`, as the terminal prints them."""
    return fenced(terminal_table(out, "figure "))


def sweep_set_sizes(out: str) -> str:
    """P(max <= t) per set size, one row per threshold."""
    rows = []
    for t in ("0.5", "1"):
        section = out.split(f"## P(max error <= {t} mm) by set size")[1].split("\n## ")[0]
        table = md_table(section, "| point | selection | n = ")
        head = [c.removeprefix("n = ") for c in cells(table[0])[2:]]
        rows.append(f"| P(max <= {t} mm) | " + " | ".join(cells(table[2])[2:]) + " |")
    return "| n | " + " | ".join(head) + " |\n" + "|---" * (len(head) + 1) + "|\n" + "\n".join(rows) + "\n"


def sweep_epsilon(out: str) -> str:
    """The errors and campaign time per epsilon, in the order of epsilon."""
    points = sorted(sweep_points(out), key=lambda r: float(layout_keys(r["design"])["epsilon_mm"]))
    eps = [f"{float(layout_keys(r['design'])['epsilon_mm']) * 1000:g}" for r in points]
    line = lambda name, key: f"| {name} | " + " | ".join(r[key] for r in points) + " |"
    return (
        "| epsilon, um | " + " | ".join(eps) + " |\n" + "|---" * (len(eps) + 1) + "|\n"
        + line("p95 after, mm (median over realisations, P10-P90)", "p95") + "\n"
        + line("P(max <= 0.5 mm)", "p05") + "\n"
        + line("P(max <= 1 mm)", "p1") + "\n"
        + "| modelled campaign time (centring the pool), h | " + " | ".join(f"{float(r['campaign_s']) / 3600:.1f}" for r in points) + " |\n"
    )


def sweep_spms_stations(out: str) -> str:
    body = []
    for r in sweep_points(out):
        stations = r["design"].count("[") - 1
        body.append(f"| {stations} | {'DETMAX' if r['selection'] == 'detmax' else r['selection']} | {r['median']} | {r['p05']} |")
    return (
        "| stations | selection | median AP over P1-P5 after, n = 50, mm (median, P10-P90) | P(max AP <= 0.5 mm), n = 50 |\n"
        "|---|---|---|---|\n" + "\n".join(body) + "\n"
    )


def sweep_pairing(out: Output) -> str:
    """The ranking of a two-design sweep: each design's objective, its paired difference with the
    leader and the pairing's correlation and variance saved, from summary.md."""
    table = md_table(out.summary, "| rank | design |")
    head = cells(table[0])
    pick = [head.index(c) for c in ("design", "objective (95 % interval)", "this design - leader (paired on common worlds)", "pairing: r, variance saved")]
    rows = ["| design | p95 after, mm (95 % interval) | this design - the leader, paired on common worlds | pairing: r, variance saved |", "|---|---|---|---|"]
    for line in table[2:]:
        c = cells(line)
        rows.append("| " + " | ".join(c[i] for i in pick) + " |")
    return "\n".join(rows) + "\n"


def budget_prediction(out: Output) -> str:
    """summary.md's linear prediction against the Monte Carlo."""
    return "\n".join(md_table(out.summary, "| configuration | identifications |")) + "\n"


def run_block(out: str) -> str:
    """The terminal output of a run, its last line (the wall times) written as `timing: ...`."""
    lines = out.rstrip("\n").split("\n")
    if not lines[-1].startswith("timing: "):
        raise SystemExit(f"doc_numbers: the run's last line is not its timing: {lines[-1]!r}")
    return "```text\n" + "\n".join(lines[:-1]) + "\ntiming: ...\n```\n"


PLAN_IRB120 = "calsim plan scenarios/plans/irb120_tracker.toml"
PLAN_LRMATE = "calsim plan scenarios/plans/lrmate200ic_tracker.toml"
PLAN_OBJECTIVE = "calsim plan scenarios/plans/irb120_tracker_objective.toml"
PLAN_TRICAL = "calsim plan scenarios/plans/irb120_trical.toml"
PLAN_TRICAL_OBJECTIVE = "calsim plan scenarios/plans/irb120_trical_objective.toml"
PLAN_SPMS = "calsim plan scenarios/plans/er20c10_spms.toml"


def plan_printed(out: str) -> str:
    """What `calsim plan` prints, its wall time written as `... s` (docs/generated/plan-speed-*.md
    keeps it) and its scratch directory as the guide's `results/`."""
    lines = [re.sub(r" in \S*/results-\d+/", " in results/", re.sub(r"; [\d.]+ s$", "; ... s", l)) for l in out.rstrip("\n").split("\n")]
    return fenced(lines)


TOUR = re.compile(
    r"(\S+) deg of joint-space path; straight moves through a collision \(checked every (\S+) deg of the joint that moves most\): (none|.*?)"
    r"(?:\. Re-routed through (\d+) via configurations? .*?, (\S+) deg of path in all)?(?:; no via path found for (.*?): move around it by hand)?\.\n"
)


def tour_row(md: str, moves: int) -> str:
    """The tour's row of a plan's table: its length, its straight moves through a collision, their via paths."""
    t = TOUR.search(md)
    colliding = [] if t.group(3) == "none" else t.group(3).split(", ")
    unrouted = [] if t.group(6) is None else t.group(6).split(", ")
    row = f"| tour | {float(t.group(1)):,.1f} deg of joint-space path; {len(colliding)} of its {moves} straight moves pass through a collision (checked every {t.group(2)} deg)"
    if t.group(4):
        row += f", re-routed through {t.group(4)} via configuration{'' if t.group(4) == '1' else 's'} ({float(t.group(5)):,.1f} deg of path in all)"
    if colliding:
        row += f"; not re-routed: {len(unrouted)}"
    return row + " |\n"


CALIBRATE_EXAMPLE = "calsim calibrate robots/irb120.toml docs/calibrate/example_measurements.csv"


def calibrate_printed(out: str) -> str:
    """What `calsim calibrate` prints, its scratch directory written as the guide's `results/`."""
    return fenced([re.sub(r" in \S*/results-\d+/", " in results/", l) for l in out.rstrip("\n").split("\n")])


def plan_figures(md: str) -> dict:
    """The figures of a plan.md."""
    pool = re.search(r"- Pool: (\d+) feasible configurations of (\d+) drawn within the limits \(refused: (.*)\)\.", md)
    o1 = re.search(r"- O1 of the chosen set: (\S+) \(a random set of the same size from the same pool: (\S+)\)", md)
    noise = re.search(r"measured again with (\S+) mm per coordinate", md)
    worlds = re.search(r"The held-out median error after calibration over (\d+) simulated worlds", md)
    training = re.search(r"- Training: (\d+) poses", md)
    validation = re.search(r"- Validation: (\d+) poses", md)
    pred = cells(md_table(md, "| P10, mm | median, mm")[2])
    refused = re.sub(r"(\d+)", lambda m: f"{int(m.group(1)):,}", pool.group(3))
    return {"feasible": int(pool.group(1)), "drawn": int(pool.group(2)), "refused": refused, "o1": o1.group(1),
            "o1_random": o1.group(2),
            "noise": noise.group(1), "worlds": int(worlds.group(1)), "p10": pred[0], "median": pred[1], "p90": pred[2],
            "pilot": pred[3], "poses": int(training.group(1)), "validation": int(validation.group(1))}


def plan_table(out: Output) -> str:
    """The table of a plan's figures, from its plan.md, and where its pilot world lies."""
    f = plan_figures(out.plan)
    moves = f["poses"] + f["validation"] - 1
    where = ("below the worlds' P10" if float(f["pilot"]) < float(f["p10"]) else
             "above the worlds' P90" if float(f["pilot"]) > float(f["p90"]) else "inside the worlds' P10-P90")
    return (
        "| figure | value |\n|---|---|\n"
        f"| candidates drawn for {f['feasible']:,} feasible poses | {f['drawn']:,} (refused: {f['refused']}) |\n"
        f"| O1 of DETMAX's {f['poses']} poses / of a random {f['poses']} from the same pool | {f['o1']} / {f['o1_random']} |\n"
        f"| predicted held-out median, P10 / median / P90 ({f['worlds']} worlds, {f['noise']} mm per coordinate) | {f['p10']} / {f['median']} / {f['p90']} mm |\n"
        f"| the pilot world's held-out median (the file's truth) | {f['pilot']} mm |\n"
        + tour_row(out.plan, moves) +
        f"\nThe pilot world lies {where} here (see Limits for how often a simulated outcome falls in the band).\n"
    )


def plan_objective(out: Output) -> str:
    """A plan's objective: what it prints, the table of P(success) against the count, the rule."""
    md = out.plan
    table = md_table(md, "| poses | successes / worlds |")
    chosen = row(md, "Chosen: ") if "\nChosen: " in md else row(md, "Not met: ")
    rows = [cells(l) for l in table[2:]]
    ok = [int(r[1].split(" / ")[0]) for r in rows]
    worlds = rows[0][1].split(" / ")[1]
    return (
        plan_printed(out) + "\nand its `plan.md` gives:\n\n" + "\n".join(table) + "\n\n" + chosen + "\n\n"
        f"Over {rows[0][0]} to {rows[-1][0]} poses the successes lie between {min(ok)} and {max(ok)} of {worlds} worlds.\n"
    )


def plan_trical_table(out: Output) -> str:
    """The figures of a TriCal plan's plan.md: its pool, its set, the prediction and the pilot, the tour."""
    md = out.plan
    pool = re.search(r"- Pool: the device's campaign centred (\d+) configurations on the (\d+) spheres .*; (\d+) kept .* \(refused: (.*)\)\.", md)
    training = re.search(r"- Training: (\d+) configurations chosen by DETMAX \((.*)\)", md)
    o1 = re.search(r"- O1 of the chosen set: (\S+) \(a random set of the same size from the same pool: (\S+)\)", md)
    centring = re.search(r"lies within (\S+) mm of its sphere's located centre", md)
    noise = re.search(r"observed at the chosen configurations with (\S+) mm per coordinate", md)
    worlds = re.search(r"at the validation configurations over (\d+) simulated worlds", md)
    unid = re.search(r"## Parameters the plan cannot identify\n\n(.*)\n", md).group(1)
    pred = cells(md_table(md, "| P10, mm | median, mm")[2])
    n = int(training.group(1))
    where = ("below the worlds' P10" if float(pred[4]) < float(pred[0]) else
             "above the worlds' P90" if float(pred[4]) > float(pred[2]) else "inside the worlds' P10-P90")
    moves = n + int(re.search(r"- Validation: (\d+) configurations", md).group(1)) - 1
    return (
        "| figure | value |\n|---|---|\n"
        f"| configurations centred by the device's campaign / kept | {int(pool.group(1)):,} on {pool.group(2)} spheres / {int(pool.group(3)):,} (refused: {pool.group(4)}) |\n"
        f"| chosen by DETMAX | {n} ({training.group(2)}) |\n"
        f"| O1 of DETMAX's {n} / of a random {n} from the same pool | {o1.group(1)} / {o1.group(2)} |\n"
        f"| the true arm's TCP from its sphere's located centre, at most | {centring.group(1)} mm |\n"
        f"| predicted held-out median, P10 / median / P90 ({worlds.group(1)} worlds, {noise.group(1)} mm per coordinate) | {pred[0]} / {pred[1]} / {pred[2]} mm (median's 90 % interval {pred[3]} mm) |\n"
        f"| the pilot's held-out median (the device's own observations) | {pred[4]} mm |\n"
        f"| parameters the plan cannot identify | {unid} |\n"
        + tour_row(md, moves) +
        f"\nThe pilot lies {where} here.\n"
    )


def plan_spms_table(out: Output) -> str:
    """The figures of an SPMS plan's plan.md: its pool, its set, the prediction and the pilot, the tour."""
    md = out.plan
    pool = re.search(r"- Pool: the head measured the sphere at (\d+) configurations at the (\d+) stations .*; (\d+) kept .* \(refused: (.*)\)\.", md)
    training = re.search(r"- Training: (\d+) configurations chosen by DETMAX \((.*)\)", md)
    o1 = re.search(r"- O1 of the chosen set: (\S+) \(a random set of the same size from the same pool: (\S+)\)", md)
    off = re.search(r"the true sphere centre lies within (\S+) mm of the head's measurement", md)
    noise = re.search(r"observed at the chosen configurations with (\S+) mm per coordinate", md)
    worlds = re.search(r"at the validation configurations over (\d+) simulated worlds", md)
    unid = re.search(r"## Parameters the plan cannot identify\n\n(.*)\n", md).group(1)
    pred = cells(md_table(md, "| P10, mm | median, mm")[2])
    n = int(training.group(1))
    where = ("below the worlds' P10" if float(pred[4]) < float(pred[0]) else
             "above the worlds' P90" if float(pred[4]) > float(pred[2]) else "inside the worlds' P10-P90")
    moves = n + int(re.search(r"- Validation: (\d+) configurations", md).group(1)) - 1
    return (
        "| figure | value |\n|---|---|\n"
        f"| configurations the head measured / kept | {int(pool.group(1)):,} at {pool.group(2)} stations / {int(pool.group(3)):,} (refused: {pool.group(4)}) |\n"
        f"| chosen by DETMAX | {n} ({training.group(2)}) |\n"
        f"| O1 of DETMAX's {n} / of a random {n} from the same pool | {o1.group(1)} / {o1.group(2)} |\n"
        f"| the true sphere centre from the head's measurement of it, at most | {off.group(1)} mm |\n"
        f"| predicted held-out median, P10 / median / P90 ({worlds.group(1)} worlds, {noise.group(1)} mm per coordinate) | {pred[0]} / {pred[1]} / {pred[2]} mm (median's 90 % interval {pred[3]} mm) |\n"
        f"| the pilot's held-out median (the head's own measurements) | {pred[4]} mm |\n"
        f"| parameters the plan cannot identify | {unid} |\n"
        + tour_row(md, moves) +
        f"\nThe pilot lies {where} here.\n"
    )


def plan_comparison(out: Output) -> str:
    """The comparison's table of a plan.md and what it shows."""
    table = md_table(out.plan, "| selection | O1 |")
    rows = [cells(l) for l in table[2:]]
    best = max(rows, key=lambda r: float(r[1]))[0]

    def median(r):
        m = re.match(r"(\S+) \((\S+)-(\S+)\)", r[2])
        return float(m.group(1)), float(m.group(2)) if m.group(2) != "unbounded" else float("-inf"), float(m.group(3)) if m.group(3) != "unbounded" else float("inf")

    meds = [median(r) for r in rows]
    inside = all(b[1] <= a[0] <= b[2] for a in meds for b in meds)
    said = ("the three sets' medians over worlds each lie inside every other set's interval" if inside
            else "the three sets' medians over worlds do not all lie inside each other's intervals")
    return "\n".join(table) + f"\n\n{best}'s set has the highest O1; {said}.\n"


# name: (page, command, how the excerpt is made from the command's stdout)
EXCERPTS = {
    "readme-check": ("README.md", CHECK_30, readme_check),
    "readme-budget": ("README.md", BUDGET, readme_budget),
    "guide-budget": ("docs/guide-budget.md", BUDGET, guide_budget),
    "guide-sweeps-layout": ("docs/guide-sweeps.md", SWEEP, sweep_table),
    "guide-reproduce-trical": ("docs/guide-reproduce.md", RUN_TRICAL, run_block),
    "guide-reproduce-spms": ("docs/guide-reproduce.md", RUN_SPMS, run_block),
    "guide-reproduce-spms-beams": ("docs/guide-reproduce.md", RUN_SPMS, spms_beams),
    "guide-reproduce-spms-sets": ("docs/guide-reproduce.md", RUN_SPMS, spms_sets),
    "guide-reproduce-spms-one-station": ("docs/guide-reproduce.md", "calsim run scenarios/er20c10_spms_one_station.toml --no-plots --no-recording", spms_sets),
    "guide-sweeps-height": ("docs/guide-sweeps.md", "calsim sweep scenarios/sweeps/sphere_height.toml", sweep_height),
    "guide-sweeps-set-size": ("docs/guide-sweeps.md", "calsim sweep scenarios/sweeps/set_size_success.toml", sweep_set_sizes),
    "guide-sweeps-epsilon": ("docs/guide-sweeps.md", "calsim sweep scenarios/sweeps/epsilon_time.toml", sweep_epsilon),
    "guide-sweeps-spms-stations": ("docs/guide-sweeps.md", "calsim sweep scenarios/sweeps/spms_stations.toml", sweep_spms_stations),
    "guide-sweeps-pairing-detmax": ("docs/guide-sweeps.md", "calsim sweep scenarios/sweeps/pairing_detmax.toml", sweep_pairing),
    "guide-sweeps-pairing-random": ("docs/guide-sweeps.md", "calsim sweep scenarios/sweeps/pairing_random.toml", sweep_pairing),
    "guide-budget-prediction": ("docs/guide-budget.md", BUDGET, budget_prediction),
    "guide-model-out-kr6": ("docs/guide-model-out.md", "calsim run scenarios/kr6r900sixx_trical.toml --no-plots --no-recording", summary_errors),
    "guide-model-out-trical": ("docs/guide-model-out.md", RUN_TRICAL, summary_errors),
    "findings-trical": ("docs/findings.md", CHECK_30, check_table),
    "findings-spms": ("docs/findings.md", CHECK_SPMS, check_table),
    "findings-table8": ("docs/findings.md", TABLE8, printed),
    "robots-lrmate": ("docs/robots.md", "calsim run scenarios/lrmate200ic_trical.toml --no-plots --no-recording", summary_errors),
    "plan-irb120-printed": ("docs/plan.md", PLAN_IRB120, plan_printed),
    "plan-irb120-table": ("docs/plan.md", PLAN_IRB120, plan_table),
    "plan-lrmate-printed": ("docs/plan.md", PLAN_LRMATE, plan_printed),
    "plan-objective": ("docs/plan.md", PLAN_OBJECTIVE, plan_objective),
    "plan-comparison": ("docs/plan.md", PLAN_OBJECTIVE, plan_comparison),
    "plan-trical-printed": ("docs/plan.md", PLAN_TRICAL, plan_printed),
    "plan-trical-table": ("docs/plan.md", PLAN_TRICAL, plan_trical_table),
    "plan-trical-objective": ("docs/plan.md", PLAN_TRICAL_OBJECTIVE, plan_objective),
    "plan-spms-printed": ("docs/plan.md", PLAN_SPMS, plan_printed),
    "plan-spms-table": ("docs/plan.md", PLAN_SPMS, plan_spms_table),
    "calibrate-example-printed": ("docs/calibrate.md", CALIBRATE_EXAMPLE, calibrate_printed),
    "tracker-worlds": ("docs/tracker.md", "calsim run scenarios/irb120_tracker.toml --realisations 10 --no-plots --no-recording", worlds_table),
}


def block(name: str) -> re.Pattern:
    return re.compile(rf"(<!-- doc_numbers: {re.escape(name)} -->\n)(.*?)(<!-- /doc_numbers: {re.escape(name)} -->)", re.S)


USAGE = "usage: python3 scripts/ci/doc_numbers.py <calsim binary> [--write] [--only NAME]"


def parse_args(argv: list[str]) -> tuple[Path, bool, str | None] | str:
    """The binary, --write and --only NAME; or what is wrong with the command line."""
    write, only, binary = False, None, []
    rest = iter(argv)
    for a in rest:
        if a == "--write":
            write = True
        elif a == "--only":
            only = next(rest, None)
            if only not in EXCERPTS:
                return f"--only {only}: not an excerpt; the excerpts: {', '.join(EXCERPTS)}"
        elif a.startswith("-"):
            return f"{a}: not an option"
        else:
            binary.append(a)
    if len(binary) != 1:
        return "one calsim binary expected" + (f", got {len(binary)}: {' '.join(binary)}" if binary else "")
    calsim = Path(binary[0]).resolve()
    if not (calsim.is_file() and os.access(calsim, os.X_OK)):
        return f"{binary[0]}: not an executable file"
    return calsim, write, only


def main() -> int:
    if "-h" in sys.argv[1:] or "--help" in sys.argv[1:]:
        print(__doc__)
        return 0
    parsed = parse_args(sys.argv[1:])
    if isinstance(parsed, str):
        print(f"doc_numbers: {parsed}\n{USAGE}", file=sys.stderr)
        return 2
    calsim, write, only = parsed
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
                where = [] if command.startswith(PRINT_ONLY) else ["--out", str(out)]
                r = subprocess.run([str(calsim), *argv[1:], *where], cwd=work, capture_output=True, text=True,
                                   env=dict(os.environ, RUST_LIB_BACKTRACE="0"))
                if r.returncode not in (0, 1):
                    print(f"doc_numbers: {command}: exit {r.returncode}\n{r.stderr[-2000:]}", file=sys.stderr)
                    return 1
                outputs[command] = Output(r.stdout)
                summaries = sorted(out.glob("*/summary.md")) if out.is_dir() else []
                if summaries:
                    outputs[command].summary = summaries[0].read_text()
                plans = sorted(out.glob("*.plan/plan.md")) if out.is_dir() else []
                if plans:
                    outputs[command].plan = plans[0].read_text()
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
