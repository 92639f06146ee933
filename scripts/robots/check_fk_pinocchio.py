#!/usr/bin/env python3
"""Check a robot file's forward kinematics and gravity torques against pinocchio on its URDF.

Usage: scripts/robots/check_fk_pinocchio.py URDF ROBOT_TOML [--configs 500] [--tip tool0]
           [--calsim target/release/calsim] [--seed 1] [--constant-rotation]
       (needs python3 >= 3.11 with pinocchio (PyPI `pin`) and numpy)

Draws --configs joint vectors uniformly within the robot file's limits, runs `calsim fk` on them,
and compares per configuration the tool frame (the URDF's --tip link: position mm, orientation
rad) and the gravity holding torques (N m, pinocchio's computeGeneralizedGravity) with pinocchio's.
Passive (mimic) joints are set from their masters. Prints the largest differences; exit 0, or 2
on bad input with one line naming it.

--constant-rotation: the robot file's tool frame and the tip are turned from each other by a fixed
rotation (a robot file not made from this URDF, e.g. the built-in IRB 120 of the paper's Table 3
against abb_experimental's link_6): that rotation is taken at the first configuration, its angle
printed, and the orientation difference measured after it (so a rotation that varies with the
joints still shows).
"""
import argparse
import csv
import math
import subprocess
import sys
import tempfile
import tomllib
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin


def rot_zyx(alpha: float, beta: float, gamma: float) -> np.ndarray:
    """Rz(alpha) Ry(beta) Rx(gamma), rad (eq. 7 of the TriCal paper, calsim's XyzZyx)."""
    ca, sa, cb, sb, cg, sg = math.cos(alpha), math.sin(alpha), math.cos(beta), math.sin(beta), math.cos(gamma), math.sin(gamma)
    rz = np.array([[ca, -sa, 0], [sa, ca, 0], [0, 0, 1]])
    ry = np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])
    rx = np.array([[1, 0, 0], [0, cg, -sg], [0, sg, cg]])
    return rz @ ry @ rx


def main() -> int:
    ap = argparse.ArgumentParser(add_help=True)
    ap.add_argument("urdf", type=Path)
    ap.add_argument("robot", type=Path)
    ap.add_argument("--configs", type=int, default=500)
    ap.add_argument("--tip", default="tool0")
    ap.add_argument("--calsim", default="target/release/calsim")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--constant-rotation", action="store_true")
    a = ap.parse_args()
    try:
        robot = tomllib.loads(a.robot.read_text())
        xml = ET.parse(a.urdf).getroot()
        model = pin.buildModelFromUrdf(str(a.urdf))
    except Exception as e:  # one line naming the input
        print(f"check_fk_pinocchio: {e}".splitlines()[0], file=sys.stderr)
        return 2
    if not 1 <= a.configs <= 100_000:
        print(f"check_fk_pinocchio: --configs {a.configs}: 1 to 100,000", file=sys.stderr)
        return 2
    mimic = {}
    for j in xml.iter("joint"):
        m = j.find("mimic")
        if m is not None:
            mimic[j.get("name")] = (m.get("joint"), float(m.get("multiplier", 1.0)), float(m.get("offset", 0.0)))
    names = [model.names[i] for i in range(1, model.njoints)]
    chain = [n for n in names if n not in mimic]
    limits = [j["limits_deg"] for j in robot["joint"]]
    if len(chain) != 6:
        print(f"check_fk_pinocchio: {a.urdf}: {len(chain)} driven joints, expected 6", file=sys.stderr)
        return 2
    rng = np.random.default_rng(a.seed)
    qs = np.array([[rng.uniform(lo, hi) for lo, hi in limits] for _ in range(a.configs)])
    data = model.createData()
    tip = model.getFrameId(a.tip)
    if tip >= len(model.frames):
        print(f"check_fk_pinocchio: {a.urdf}: no frame {a.tip}", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as tmp:
        joints = Path(tmp) / "joints.csv"
        with joints.open("w", newline="") as f:
            w = csv.writer(f)
            w.writerow([f"q{i}_deg" for i in range(1, 7)])
            w.writerows([[repr(float(v)) for v in q] for q in qs])
        out = Path(tmp) / "fk.csv"
        r = subprocess.run([a.calsim, "fk", str(a.robot), str(joints), "--out", str(out)], capture_output=True, text=True)
        if r.returncode != 0:
            print(f"check_fk_pinocchio: calsim fk: {r.stderr.strip()}", file=sys.stderr)
            return 2
        rows = list(csv.DictReader(out.open()))
    dp = dr = dt = 0.0
    offset = None
    for q_deg, row in zip(qs, rows):
        value = dict(zip(chain, np.radians(q_deg)))
        for n in names:
            if n in mimic:
                master, k, off = mimic[n]
                while master in mimic:  # a mimic of a mimic: compose
                    m2, k2, off2 = mimic[master]
                    master, k, off = m2, k * k2, k * off2 + off
                value[n] = k * value[master] + off
        q = np.zeros(model.nq)
        for i, n in enumerate(names, start=1):
            q[model.joints[i].idx_q] = value[n]
        pin.framesForwardKinematics(model, data, q)
        f = data.oMf[tip]
        p = np.array([float(row[c]) for c in ("x_mm", "y_mm", "z_mm")])
        rot = rot_zyx(*(math.radians(float(row[c])) for c in ("alpha_deg", "beta_deg", "gamma_deg")))
        dp = max(dp, float(np.linalg.norm(f.translation * 1e3 - p)))
        rel = f.rotation.T @ rot
        if a.constant_rotation:
            if offset is None:
                offset = rel
            rel = rel @ offset.T
        dr = max(dr, float(np.linalg.norm(pin.log3(rel))))
        g = pin.computeGeneralizedGravity(model, data, q)
        ours = np.array([float(row[f"tau{i}_nm"]) for i in range(1, 7)])
        theirs = np.array([g[model.joints[names.index(n) + 1].idx_v] for n in chain])
        dt = max(dt, float(np.abs(ours - theirs).max()))
    constant = ""
    if offset is not None:
        constant = f" (after a constant rotation of {math.degrees(float(np.linalg.norm(pin.log3(offset)))):.3f} deg)"
    print(f"{a.robot} against pinocchio {pin.__version__} on {a.urdf} ({a.tip}), {a.configs} configurations: "
          f"position {dp:.3e} mm, orientation {dr:.3e} rad{constant}, gravity torque {dt:.3e} N m")
    return 0


if __name__ == "__main__":
    sys.exit(main())
