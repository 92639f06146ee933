#!/usr/bin/env python3
"""The arm table of docs/robots.md for every arm calsim was checked on, in one command.

Usage: scripts/robots/arm_table.py [--abb DIR] [--abb-experimental DIR] [--fanuc DIR]
           [--universal-robot DIR] [--calsim target/release/calsim] [--configs 500]
           [--targets 200] [--no-study]
       (run from the repository's root; needs python3 >= 3.11 with pinocchio (PyPI `pin`), numpy
        and, for the arms described in xacro, xacro (PyPI `xacro`))

The ROS-Industrial repositories are NOT part of calsim: fetch them yourself
(github.com/ros-industrial/abb, abb_experimental, fanuc, universal_robot) and give their checked-out
roots; an arm whose repository is not given is left out (a line says so). The shipped arms (KR 6,
LR Mate 200iC) need nothing but this repository. Xacro files are expanded with `xacro`, its
`$(find PKG)` resolved against the given roots (no ROS installation needed).

For each arm:
  import   `calsim import-urdf URDF --package-root ROOT` into a temporary folder: its exit code
           and what it says (capsules, masses, passive joints). The import itself checks the
           converted arm against the URDF's chain at 200 configurations (1e-6 mm) and the written
           file against the converted arm at 200 more; it refuses otherwise.
  FK       scripts/robots/check_fk_pinocchio.py: `calsim fk` of the robot file (the shipped one for
           the shipped arms, the import's output for the others) against pinocchio on the URDF at
           --configs random configurations within the limits: largest position difference (mm),
           orientation difference (rad) and gravity-torque difference (N m).
  IK       `calsim compensate` of the file on the tool frames (`calsim fk`) of --targets random
           configurations within the limits: how many are reached, the largest model error (mm,
           deg) of those reached.
  study    `calsim run` of the arm's TriCal scenario where the repository has one (IRB 120, KR 6,
           LR Mate): validation errors before calibration (median, p95, max) and after, sets of
           75 (medians over the repetitions of median and max), compensated targets too. A line
           under the table, not a column: CI checks these summaries in the docs.

Prints the Markdown table of docs/robots.md ("Every arm"), verbatim, then the lines behind it.
Exit 0; 2 on bad input (one line naming it).
"""
import argparse
import csv
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent

# name, repository key (None: this repository), URDF or xacro path in it, package root relative to
# the repository (None: the repository's root), the robot file to check (None: the import's
# output), FK tip, constant rotation between the file's tool frame and the tip, scenario.
ARMS = [
    dict(name="ABB IRB 120 (built-in, robots/irb120.toml, Table 3)", repo="abb_experimental",
         src="abb_irb120_support/urdf/irb120_3_58.xacro", robot="robots/irb120.toml", tip="link_6",
         constant=True, scenario="scenarios/irb120_trical.toml", do_import=False),
    dict(name="ABB IRB 120 (abb_experimental, imported)", repo="abb_experimental",
         src="abb_irb120_support/urdf/irb120_3_58.xacro"),
    dict(name="KUKA KR 6 R900 sixx (shipped)", repo=None, src="robots/kr6r900sixx.urdf",
         robot="robots/kr6r900sixx.toml", scenario="scenarios/kr6r900sixx_trical.toml"),
    dict(name="FANUC LR Mate 200iC (shipped)", repo=None, src="robots/lrmate200ic/lrmate200ic.urdf",
         root="robots/lrmate200ic", robot="robots/lrmate200ic.toml", scenario="scenarios/lrmate200ic_trical.toml"),
    dict(name="ABB IRB 2400 (imported)", repo="abb", src="abb_irb2400_support/urdf/irb2400.urdf"),
    dict(name="ABB IRB 4400L (imported)", repo="abb", src="abb_irb4400_support/urdf/irb4400l_30_243.xacro"),
    dict(name="ABB IRB 6640 (imported, two mimic joints)", repo="abb", src="abb_irb6640_support/urdf/irb6640_185_280.urdf"),
    dict(name="FANUC M-10iA (imported)", repo="fanuc", src="fanuc_m10ia_support/urdf/m10ia.xacro"),
    dict(name="UR5 (imported)", repo="universal_robot", src="ur_description/urdf/ur5.xacro"),
]

STUB = '''import os
class PackageNotFoundError(KeyError):
    pass
def get_package_share_directory(name):
    for root in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep):
        if root and os.path.isdir(os.path.join(root, name)):
            return os.path.join(root, name)
    raise PackageNotFoundError(name)
'''


def fail(msg: str) -> int:
    print(f"arm_table: {msg}".splitlines()[0], file=sys.stderr)
    return 2


def expand(src: Path, roots: list[Path], tmp: Path, out: Path) -> None:
    """`src` as a URDF at `out` (xacro expanded with $(find) against `roots`)."""
    if src.suffix != ".xacro":
        out.write_bytes(src.read_bytes())
        return
    stub = tmp / "stub" / "ament_index_python"
    stub.mkdir(parents=True, exist_ok=True)
    (stub / "__init__.py").write_text("")
    (stub / "packages.py").write_text(STUB)
    env = dict(os.environ, PYTHONPATH=str(tmp / "stub"), ROS_PACKAGE_PATH=os.pathsep.join(map(str, roots)))
    code = "import sys, xacro; sys.argv = ['xacro', sys.argv[1]]; xacro.main()"
    r = subprocess.run([sys.executable, "-c", code, str(src)], capture_output=True, text=True, env=env)
    if r.returncode != 0 or "<robot" not in r.stdout:
        raise RuntimeError(f"{src}: xacro failed: {r.stderr.strip()}")
    out.write_text(r.stdout)


def fk_check(calsim: str, urdf: Path, robot: Path, arm: dict, configs: int) -> str:
    cmd = [sys.executable, str(HERE / "check_fk_pinocchio.py"), str(urdf), str(robot), "--configs", str(configs),
           "--calsim", calsim, "--tip", arm.get("tip", "tool0")]
    if arm.get("constant"):
        cmd.append("--constant-rotation")
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"check_fk_pinocchio: {r.stderr.strip()}")
    return r.stdout.strip()


def ik_check(calsim: str, robot: Path, tmp: Path, n: int, seed: int = 32) -> tuple[int, int, float, float]:
    """Reached, targets, largest model error mm and deg of `compensate` on tool frames of `n`
    random configurations within the limits."""
    import tomllib
    limits = [j["limits_deg"] for j in tomllib.loads(robot.read_text())["joint"]]
    rng = np.random.default_rng(seed)
    joints = tmp / "ik_joints.csv"
    with joints.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow([f"q{i}_deg" for i in range(1, 7)])
        w.writerows([[repr(float(rng.uniform(lo, hi))) for lo, hi in limits] for _ in range(n)])
    fk = tmp / "ik_fk.csv"
    r = subprocess.run([calsim, "fk", str(robot), str(joints), "--out", str(fk)], capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"calsim fk: {r.stderr.strip()}")
    cols = ["x_mm", "y_mm", "z_mm", "alpha_deg", "beta_deg", "gamma_deg"]
    targets = tmp / "ik_targets.csv"
    with targets.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(cols)
        w.writerows([[row[c] for c in cols] for row in csv.DictReader(fk.open())])
    out = tmp / "ik_out.csv"
    r = subprocess.run([calsim, "compensate", str(robot), str(targets), "--out", str(out)], capture_output=True, text=True)
    if r.returncode not in (0, 1):
        raise RuntimeError(f"calsim compensate: {r.stderr.strip()}")
    rows = list(csv.DictReader(out.open()))
    done = [row for row in rows if row["model_error_mm"] not in ("", "unreachable")]
    emm = max((float(row["model_error_mm"]) for row in done), default=float("nan"))
    edeg = max((float(row["model_error_deg"]) for row in done), default=float("nan"))
    return len(done), len(rows), emm, edeg


def study(calsim: str, scenario: str, tmp: Path) -> str:
    out = tmp / "study"
    r = subprocess.run([calsim, "run", scenario, "--out", str(out)], capture_output=True, text=True)
    if r.returncode not in (0, 1):
        raise RuntimeError(f"calsim run {scenario}: {r.stderr.strip()}")
    summary = next(out.glob("*/summary.md")).read_text()
    rows = {}
    for line in summary.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 6 and cells[0].startswith(("before", "after, n = 75")):
            key = "comp" if "compensated" in cells[0] else cells[0].split(" (")[0]
            rows[key] = cells
    b, a, c = rows["before"], rows["after, n = 75"], rows.get("comp")
    text = f"before {b[2]} / {b[4]} / {b[5]}; after {a[2]} / max {a[5]}"
    if c:
        missing = re.search(r"(\d+) targets without", c[0])
        text += f"; compensated {c[2]} / max {c[5]}" + (f" ({missing.group(1)} targets without joint values)" if missing else "")
    return text


def main() -> int:
    ap = argparse.ArgumentParser()
    for key in ("abb", "abb-experimental", "fanuc", "universal-robot"):
        ap.add_argument(f"--{key}", type=Path, help=f"checkout of github.com/ros-industrial/{key.replace('-', '_')}")
    ap.add_argument("--calsim", default="target/release/calsim")
    ap.add_argument("--configs", type=int, default=500)
    ap.add_argument("--targets", type=int, default=200)
    ap.add_argument("--no-study", action="store_true")
    a = ap.parse_args()
    repos = {"abb": a.abb, "abb_experimental": a.abb_experimental, "fanuc": a.fanuc, "universal_robot": a.universal_robot}
    for key, path in repos.items():
        if path is not None and not path.is_dir():
            return fail(f"--{key.replace('_', '-')} {path}: not a directory")
    if not Path(a.calsim).is_file():
        return fail(f"--calsim {a.calsim}: no such file (cargo build --release --bin calsim)")
    if not 1 <= a.configs <= 100_000 or not 1 <= a.targets <= 10_000:
        return fail("--configs 1 to 100,000, --targets 1 to 10,000")
    roots = [p.resolve() for p in repos.values() if p is not None]
    table = ["| arm | import | FK vs pinocchio: position mm, orientation rad, gravity torque N m | IK (`compensate`): reached, largest model error |",
             "|---|---|---|---|"]
    notes = []
    with tempfile.TemporaryDirectory() as tmpdir:
        for k, arm in enumerate(ARMS):
            tmp = Path(tmpdir) / f"arm{k}"
            tmp.mkdir()
            if arm["repo"] is None:
                base = Path(".")
            elif repos[arm["repo"]] is None:
                notes.append(f"{arm['name']}: left out (no --{arm['repo'].replace('_', '-')})")
                continue
            else:
                base = repos[arm["repo"]]
            try:
                src = base / arm["src"]
                urdf = tmp / (src.stem + ".urdf")
                expand(src, roots, tmp, urdf)
                root = base / arm["root"] if "root" in arm else base
                imported = tmp / "imported.toml"
                if arm.get("do_import", True):
                    r = subprocess.run([a.calsim, "import-urdf", str(urdf), "--package-root", str(root), "--out", str(imported)],
                                       capture_output=True, text=True)
                    said = (r.stdout + r.stderr).strip().splitlines()
                    notes += [f"{arm['name']}: import: {line}" for line in said]
                    caps = next((re.search(r"collision: (\d+) capsules", l) for l in said if l.startswith("collision:")), None)
                    passive = sum(l.startswith("passive joint") for l in said)
                    imp = f"exit {r.returncode}" + (f", {caps.group(1)} capsules" if caps else ", no capsules") + (f", {passive} passive" if passive else "")
                    if r.returncode != 0:
                        table.append(f"| {arm['name']} | {imp} | - | - |")
                        continue
                else:
                    imp = "- (not from a URDF)"
                robot = Path(arm["robot"]) if "robot" in arm else imported
                line = fk_check(a.calsim, urdf, robot, arm, a.configs)
                notes.append(f"{arm['name']}: FK: {line}")
                m = re.search(r"position (\S+) mm, orientation (\S+) rad(.*?), gravity torque (\S+) N m", line)
                constant = " (after a constant 90 deg)" if "constant rotation of 90.000" in m.group(3) else m.group(3)
                fk = f"{m.group(1)}, {m.group(2)}{constant}, {m.group(4)}"
                reached, n, emm, edeg = ik_check(a.calsim, robot, tmp, a.targets)
                ik = f"{reached} of {n}, {emm:.1e} mm, {edeg:.1e} deg"
                table.append(f"| {arm['name']} | {imp} | {fk} | {ik} |")
                if "scenario" in arm and not a.no_study:
                    notes.append(f"{arm['name']}: study, mm: {study(a.calsim, arm['scenario'], tmp)}")
            except (RuntimeError, OSError, KeyError, StopIteration) as e:
                return fail(f"{arm['name']}: {e}")
    print("\n".join(table))
    print()
    print("\n".join(notes))
    return 0


if __name__ == "__main__":
    sys.exit(main())
