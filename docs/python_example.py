"""calsim from Python: a worked example (CI runs it as `python docs/python_example.py`).

Runs a reduced TriCal study (the 2018 paper's cell and robot, 3 set sizes x 5 repetitions),
looks at its published figures and tables as polars DataFrames, exports the calibrated model,
runs a two-point design sweep over realisations, calibrates a robot from measurements held in a
polars DataFrame and compensates targets with it, and shows an error as Python sees it. Install
the package first (a wheel: `pip install calsim-*.whl`; or `pip install "./python[progress]"` from
the repository's root). Results go to the directory given as the first argument (default: a new
temporary directory), never to the repository's `results/`.
"""

import sys
import tempfile
from pathlib import Path

import polars as pl

import calsim

REPO = Path(__file__).resolve().parents[1]
SCENARIO = REPO / "scenarios" / "irb120_trical.toml"
out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp(prefix="calsim-example-"))

# 1. The study, reduced by keyword overrides (the CLI's --set-sizes and --repetitions). A progress
#    bar shows while it runs (tqdm's widget in a notebook); the interpreter is free meanwhile.
r = calsim.run(SCENARIO, out=out, set_sizes=[20, 50, 75], repetitions=5, recording=False)
print(r)
print(r.checks.select("figure", "published", "calsim", "band", "result"))

# 2. The tables are DataFrames: the error after calibration per set size, over the repetitions.
per_size = (
    r.tables["tasks"]
    .group_by("set_size")
    .agg(
        pl.col("validation_median_mm").median().alias("median error, mm"),
        pl.col("validation_max_mm").max().alias("largest max error, mm"),
        pl.col("o1").median().alias("median O1"),
    )
    .sort("set_size")
)
print(per_size)

# Before and after calibration at the validation poses (the sets of the table size, 75).
errors = r.tables["validation_errors"]
print(errors.group_by("calibration").agg(pl.col("error_mm").median().alias("median error, mm")).sort("calibration"))
print("figures:", ", ".join(p.name for p in r.figures))

# 3. The calibrated model out: the median identification at n = 75 as a robot file (with each
#    parameter's standard deviation), a URDF and a YAML overlay.
model = calsim.export(r, out=out)
print(model)

# 4. A design question over realisations: does a 20 um centring tolerance cost accuracy? The same
#    two worlds at both tolerances (common random numbers), sets of 75, 3 repetitions.
sweep_file = out / "epsilon_example.toml"
sweep_file.write_text(
    f'base = "{SCENARIO}"\nrealisations = 2\nthresholds_mm = [0.5, 1.0]\n\n'
    '[fixed]\n"study.set_sizes" = [75]\n"study.repetitions" = 3\n\n'
    '[[axis]]\nkey = "trical.epsilon_mm"\nvalues = [0.010, 0.020]\n'
)
s = calsim.sweep(sweep_file, out=out)
print(s.tables["points"])

# 5. A real robot: measurements as a DataFrame (a tracker export joined with a joint log would give
#    the same columns), calibrated as the CLI calibrates the file; then the joint values that put
#    the calibrated TCP on each target, and the Cartesian targets for a nominal-only controller.
measurements = pl.read_csv(REPO / "docs" / "calibrate" / "example_measurements.csv", comment_prefix="#")
cal = calsim.calibrate(REPO / "robots" / "irb120.toml", measurements, out=out, name="example", header={"joints": "controller"})
print(cal)
print(cal.tables["models"].select("model", "parameters", "chosen", "held_out_rms_mm").sort("parameters"))
comp = calsim.compensate(cal, pl.read_csv(REPO / "docs" / "examples" / "targets.csv"), nominal=cal)
print(comp.joints.select("q1_deg", "q2_deg", "q3_deg", "model_error_mm", "nominal_x_mm"))

# 6. Errors are exceptions naming the file, the key and the value.
try:
    calsim.run(SCENARIO, out=out, repetitions=0, progress=False)
except calsim.ScenarioError as e:
    print(f"{type(e).__name__}: {e}")
    print(f"  file {e.path}, key {e.key}, value {e.value}")
