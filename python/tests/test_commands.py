"""Tests of the real-robot and design commands from Python (calibrate, compensate, fk,
import_urdf, optimise, plan, table8): each result beside the CLI's output for the same inputs (bit for
bit where the CLI writes a file or a table), frames in and out, and bad arguments as the package's
exceptions naming the file, the key and the value."""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path

import polars as pl
import pytest

import calsim

REPO = Path(__file__).resolve().parents[2]
ROBOT = REPO / "robots" / "irb120.toml"
MEASUREMENTS = REPO / "docs" / "calibrate" / "example_measurements.csv"
TARGETS = REPO / "docs" / "examples" / "targets.csv"
URDF = REPO / "robots" / "kr6r900sixx.urdf"
QUICK = REPO / "scenarios" / "ci_quick.toml"


def cli_binary() -> str:
    cli = os.environ.get("CALSIM_BIN") or shutil.which("calsim")
    if cli is None:
        pytest.skip("no calsim binary (set CALSIM_BIN)")
    return cli


def cli(*args: str | Path) -> subprocess.CompletedProcess[bytes]:
    return subprocess.run([cli_binary(), *map(str, args)], check=True, capture_output=True)


def measurement_frame() -> pl.DataFrame:
    return pl.read_csv(MEASUREMENTS, comment_prefix="#")


def header_of(path: Path) -> dict[str, str]:
    """The `# key = value` lines of a measurement file (its free comments left out)."""
    keys = {}
    for line in path.read_text().splitlines():
        if not line.startswith("#"):
            break
        key, sep, value = line[1:].partition("=")
        if sep and key.strip().isidentifier():
            keys[key.strip()] = value.strip()
    return keys


@pytest.fixture(scope="module")
def calibration(tmp_path_factory: pytest.TempPathFactory) -> calsim.CalibrationResult:
    return calsim.calibrate(ROBOT, MEASUREMENTS, out=tmp_path_factory.mktemp("cal"), plots=False)


def tables_sha256(dest: Path) -> dict[str, str]:
    hashes: dict[str, str] = json.loads((dest / "manifest.json").read_text())["tables_sha256"]
    return hashes


def test_calibrate_from_a_file_writes_the_cli_tables(calibration: calsim.CalibrationResult, tmp_path: Path) -> None:
    c = calibration
    assert c.dest.name == "example_measurements.calibration"
    assert {"points", "models", "parameters", "bases", "tools", "correlation"} <= set(c.tables)
    assert c.tables["points"].height == 240
    assert c.model in c.tables["models"]["model"].to_list()
    assert c.robot_file.is_file() and "[std]" in c.robot_file.read_text()
    assert "chosen" in c.report and c.plan is None
    cli("calibrate", ROBOT, MEASUREMENTS, "--out", tmp_path, "--no-plots")
    assert tables_sha256(c.dest) == tables_sha256(tmp_path / "example_measurements.calibration")
    for name in ("robot.toml", "calibration.yaml"):
        assert (c.dest / name).read_bytes() == (tmp_path / "example_measurements.calibration" / name).read_bytes()


def test_calibrate_from_a_dataframe_gives_the_same_tables_as_the_file(calibration: calsim.CalibrationResult, tmp_path: Path) -> None:
    frame = measurement_frame()
    assert frame.height == 240
    c = calsim.calibrate(ROBOT, frame, out=tmp_path, name="tracker_log", header=header_of(MEASUREMENTS), plots=False)
    assert c.dest == tmp_path / "tracker_log.calibration"
    # Every table bit for bit but the points' file lines (the frame's CSV has the header keys
    # without the file's free comment lines, so each point sits that many lines higher) and the
    # run's table, which names the file calibrated (the frame's CSV in the report).
    ours, theirs = tables_sha256(c.dest), tables_sha256(calibration.dest)
    named = {"points.parquet", "calibration.parquet"}
    assert {k: v for k, v in ours.items() if k not in named} == {k: v for k, v in theirs.items() if k not in named}
    run, file_run = c.tables["calibration"], calibration.tables["calibration"]
    assert run["measurements"].to_list() != file_run["measurements"].to_list()
    assert run.drop("measurements").equals(file_run.drop("measurements"))
    free_comments = sum(1 for line in MEASUREMENTS.read_text().splitlines() if line.startswith("#")) - len(header_of(MEASUREMENTS))
    assert free_comments == 2
    points, file_points = c.tables["points"], calibration.tables["points"]
    assert points.drop("line").equals(file_points.drop("line"))
    assert (file_points["line"] - points["line"]).unique().to_list() == [free_comments]
    # The frame is kept in the report, as the CSV that was calibrated.
    kept = pl.read_csv(c.dest / "measurements.csv", comment_prefix="#")
    assert kept.equals(frame)


def test_calibrate_with_a_plan_sets_the_measured_median_beside_the_simulated(tmp_path: Path) -> None:
    c = calsim.calibrate(ROBOT, MEASUREMENTS, out=tmp_path, plan_worlds=2, plan_noise_mm=0.012, plan_with="all", plots=False)
    assert c.plan is not None and c.plan["plan"].to_list() == ["noise only", "twin", "residual as noise"]
    shown = (c.dest / "plan.md").read_text()
    assert c.plan["measured_mm"].n_unique() == 1 and f"measured ({c.plan['measured_mm'][0]:.4f} mm)" in shown
    for row in c.plan.iter_rows(named=True):
        assert row["worlds"] == 2 and row["statistic"] == "median"
        assert row["simulated_p10_mm"] <= row["simulated_mm"] <= row["simulated_p90_mm"]
        assert row["inside"] == (row["simulated_p10_mm"] <= row["measured_mm"] <= row["simulated_p90_mm"])
        # The row as plan.md shows it.
        p10, p50, p90 = row["simulated_p10_mm"], row["simulated_mm"], row["simulated_p90_mm"]
        inside = "yes" if row["inside"] else "no"
        assert f"| {row['plan']} | {row['scenario']} | 2 | {p10:.4f} | {p50:.4f} | {p90:.4f} | {inside} |" in shown, row
    alone = calsim.calibrate(ROBOT, MEASUREMENTS, out=tmp_path / "alone", plan_worlds=2, plan_noise_mm=0.012, plots=False)
    assert alone.plan is not None and alone.plan["plan"].to_list() == ["twin"]


@pytest.mark.parametrize(
    "keywords, key, value",
    [
        (dict(folds=1), "folds", "1: within 2 to 20"),
        (dict(hold_out=0.9), "hold_out", "0.9: a fraction above 0 and at most 0.5"),
        (dict(hold_out=0.2, hold_out_session="A"), "hold_out", "either a fraction or a session"),
        (dict(outlier_threshold=math.inf), "outlier_threshold", "inf: within 2 to 100"),
        (dict(params=["a2", "zz"]), "params", "zz"),
        (dict(plan_worlds=5000), "plan_worlds", "5000: at most"),
        (dict(plan_noise_mm=-1), "plan_noise_mm", "-1: within 0 to 100 mm"),
        (dict(seed=-1), "seed", "-1 is not within"),
        (dict(plan_worlds=2, plan_with="bogus"), "plan_with", "bogus"),
        (dict(plan_with="twin"), "plan_with", "a plan needs"),
        (dict(instrument_noise_mm=-0.5), "instrument_noise_mm", "-0.5"),
    ],
)
def test_a_bad_calibrate_keyword_is_an_input_error_naming_it(tmp_path: Path, keywords: dict[str, object], key: str, value: str) -> None:
    with pytest.raises(calsim.InputError) as e:
        calsim.calibrate(ROBOT, MEASUREMENTS, out=tmp_path, plots=False, **keywords)  # type: ignore[arg-type]
    assert e.value.key == key and str(e.value).startswith(f"{key}: ") and value in str(e.value)
    assert "\n" not in str(e.value)
    assert list(tmp_path.iterdir()) == []


def test_a_bad_measurement_frame_is_a_data_error_naming_line_column_and_file(tmp_path: Path) -> None:
    frame = measurement_frame().with_columns(
        pl.when(pl.int_range(pl.len()) == 3).then(float("nan")).otherwise(pl.col("x_mm")).alias("x_mm")
    )
    with pytest.raises(calsim.DataError) as e:
        calsim.calibrate(ROBOT, frame, out=tmp_path, name="bad", plots=False)
    # Row 3 of the frame is line 5 of its CSV (the column names on line 1).
    assert e.value.path is not None and e.value.path.endswith("bad.csv")
    assert e.value.key is not None and "line 5" in e.value.key and "x_mm" in e.value.key
    with pytest.raises(calsim.InputError) as e2:
        calsim.calibrate(ROBOT, measurement_frame(), out=tmp_path, name="../escape", plots=False)
    assert e2.value.key == "name"
    with pytest.raises(calsim.RobotFileError) as e3:
        calsim.calibrate(tmp_path / "missing.toml", MEASUREMENTS, out=tmp_path, plots=False)
    assert e3.value.path == str(tmp_path / "missing.toml")


def test_compensate_gives_the_cli_csv_from_a_file_or_a_frame(calibration: calsim.CalibrationResult, tmp_path: Path) -> None:
    out = tmp_path / "py.csv"
    r = calsim.compensate(calibration, TARGETS, nominal=calibration, out=out)
    cli("compensate", calibration.robot_file, TARGETS, "--nominal", calibration.dest / "before.toml", "--out", tmp_path / "cli.csv")
    assert out.read_bytes() == (tmp_path / "cli.csv").read_bytes() == r.csv.encode()
    targets = pl.read_csv(TARGETS)
    assert r.targets == targets.height and r.unreachable == []
    assert r.joints.height == targets.height and r.joints.columns[:6] == [f"q{i}_deg" for i in range(1, 7)]
    assert (r.joints["model_error_mm"] < 1e-6).all()
    from_frame = calsim.compensate(calibration.robot_file, targets, nominal=calibration.dest / "before.toml")
    assert from_frame.csv == r.csv and from_frame.joints.equals(r.joints)


def test_an_unreachable_target_is_a_row_of_nulls_and_a_warning(calibration: calsim.CalibrationResult) -> None:
    targets = pl.read_csv(TARGETS).head(2).with_columns(pl.Series("x_mm", [142.537, 5000.0]))
    with pytest.warns(calsim.CalsimWarning, match="1 of 2 targets cannot be reached"):
        r = calsim.compensate(calibration, targets)
    assert r.unreachable == [2]
    assert r.joints["q1_deg"].is_null().to_list() == [False, True]


def test_compensate_frame_equals_the_file_the_cli_writes(calibration: calsim.CalibrationResult, tmp_path: Path) -> None:
    targets = pl.read_csv(TARGETS).head(3)
    targets = targets.with_columns(pl.Series("x_mm", [targets["x_mm"][0], 5000.0, targets["x_mm"][2]]))
    path = tmp_path / "targets.csv"
    targets.write_csv(path)
    for k, nominal in enumerate([calibration.dest / "before.toml", None]):
        with pytest.warns(calsim.CalsimWarning, match="1 of 3 targets cannot be reached"):
            r = calsim.compensate(calibration.robot_file, path, nominal=nominal)
        written = tmp_path / f"cli{k}.csv"
        extra = [] if nominal is None else ["--nominal", str(nominal)]
        args = [cli_binary(), "compensate", str(calibration.robot_file), str(path), *extra, "--out", str(written)]
        assert subprocess.run(args, capture_output=True).returncode == 1
        assert written.read_text() == r.csv
        # Read by polars with the documented dtypes: every column a float, `unreachable` and an
        # empty field null, the model's errors NaN where the target cannot be reached.
        schema = {c: pl.Float64 for c in r.joints.columns}
        assert r.joints.schema == pl.Schema(schema)
        assert r.joints.equals(pl.read_csv(written, schema=schema, null_values=["unreachable", ""]))
        assert r.joints["q6_deg"].is_null().to_list() == [False, True, False]
        assert r.joints["model_error_deg"].is_nan().to_list() == [False, True, False]
        assert r.joints["nominal_z_mm"].is_null().to_list() == ([False, True, False] if nominal else [True] * 3)


def test_bad_compensate_arguments_name_the_file_key_and_value(calibration: calsim.CalibrationResult, tmp_path: Path) -> None:
    bad = tmp_path / "targets.csv"
    bad.write_text("x_mm,y_mm,z_mm,alpha_deg,beta_deg,gamma_deg\n1,2,abc,0,0,0\n")
    with pytest.raises(calsim.InputError) as e:
        calsim.compensate(calibration, bad)
    assert (e.value.path, e.value.key) == (str(bad), "line 2") and 'z_mm = "abc"' in str(e.value)
    with pytest.raises(calsim.InputError) as e:
        calsim.compensate(calibration, pl.DataFrame({"x_mm": [1.0]}))
    assert e.value.key == "targets" and "y_mm" in str(e.value)
    with pytest.raises(calsim.InputError) as e:
        calsim.compensate(calibration, TARGETS, nominal=REPO / "robots" / "er20c10.toml")
    assert "not the nominal model of this arm" in str(e.value)


def test_fk_gives_the_cli_csv_and_a_typed_frame(tmp_path: Path) -> None:
    joints = pl.DataFrame({f"q{i}_deg": [0.0, 10.0, -20.5] for i in range(1, 7)})
    r = calsim.fk(ROBOT, joints)
    path = tmp_path / "joints.csv"
    joints.write_csv(path)
    assert cli("fk", ROBOT, path).stdout == r.csv.encode()
    assert r.rows == 3 and r.table.height == 3
    assert r.table["within_limits"].dtype == pl.Boolean and r.table["x_mm"].dtype == pl.Float64
    # The frame holds the CSV's numbers bit for bit.
    first = r.csv.splitlines()[1].split(",")
    assert r.table["x_mm"][0] == float(first[6]) and r.table["tau2_nm"][0] == float(first[13])
    out = tmp_path / "fk.csv"
    assert calsim.fk(ROBOT, path, out=out).csv == out.read_text() == r.csv
    # The frame equals the file the CLI writes, read by polars with the documented dtypes.
    written = tmp_path / "cli_fk.csv"
    cli("fk", ROBOT, path, "--out", written)
    schema = {c: (pl.Boolean if c == "within_limits" else pl.Float64) for c in r.table.columns}
    assert r.table.equals(pl.read_csv(written, schema=schema))


def test_bad_fk_arguments_name_the_file_key_and_value(tmp_path: Path) -> None:
    bad = tmp_path / "joints.csv"
    bad.write_text("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n0,0,0,0,0,0\n0,1e9,0,0,0,0\n")
    with pytest.raises(calsim.DataError) as e:
        calsim.fk(ROBOT, bad)
    assert (e.value.path, e.value.key, e.value.value) == (str(bad), "line 3: q2_deg", "1e9")
    with pytest.raises(calsim.InputError) as e2:
        calsim.fk(ROBOT, bad, out=bad)
    assert e2.value.path == str(bad) and e2.value.key == "out"
    assert bad.read_text().endswith("1e9,0,0,0,0\n")


def test_import_urdf_writes_the_cli_robot_file(tmp_path: Path) -> None:
    for d in ("py", "cli"):
        (tmp_path / d).mkdir()
    r = calsim.import_urdf(URDF, out=tmp_path / "py" / "kr6.toml")
    cli("import-urdf", URDF, "--out", tmp_path / "cli" / "kr6.toml")
    assert r.robot_file == tmp_path / "py" / "kr6.toml"
    # The same bytes but for the command line the file records (its own path in it).
    ours = r.robot_file.read_text().replace(str(r.robot_file), "OUT")
    theirs = (tmp_path / "cli" / "kr6.toml").read_text().replace(str(tmp_path / "cli" / "kr6.toml"), "OUT")
    assert f"import-urdf {URDF} --out OUT" in ours
    assert ours == theirs
    assert r.lines and any("capsule" in line for line in r.lines)
    # The robot file works: the arm's tool frame at zero joints.
    assert calsim.fk(r.robot_file, pl.DataFrame({f"q{i}_deg": [0.0] for i in range(1, 7)})).rows == 1


def test_bad_import_urdf_arguments_name_the_file(tmp_path: Path) -> None:
    with pytest.raises(calsim.RobotFileError) as e:
        calsim.import_urdf(tmp_path / "missing.urdf", out=tmp_path / "x.toml")
    assert e.value.path == str(tmp_path / "missing.urdf")
    with pytest.raises(calsim.InputError) as e2:
        calsim.import_urdf(URDF, out=URDF)
    assert e2.value.path == str(URDF) and e2.value.key == "out"


OBJECTIVE = '[objective]\nmaximise = "success"\nstatistic = "max"\nthreshold_mm = 0.5\nconfidence = 0.9\n'
SMALL_DESIGN = (
    '[fixed]\n"study.set_sizes" = [20, 30]\n"study.table_set_size" = 30\n"study.repetitions" = 2\n'
    '"campaign.validation_poses" = 60\n"campaign.pool_per_sphere" = 20\n\n'
    '[points]\nkey = "cell.spheres_w_mm"\ncount = [3, 3]\nregion = "plate"\nx_mm = [0.0, 300.0]\ny_mm = [0.0, 300.0]\n'
    "height_mm = [0.0, 100.0]\ntilt_deg = [0.0, 20.0]\nmin_spacing_mm = 150.0\nstart_spacing_mm = 300.0\n\n"
    "[search]\nevaluations = 2\nrestarts = 2\nworlds = 2\nfinalists = 1\nrace = { max = 2, batch = 1 }\n\n[verify]\nheld_out = 2\n"
)


@pytest.fixture()
def design(tmp_path: Path) -> Iterator[Path]:
    f = tmp_path / "q.toml"
    f.write_text(f'base = "{QUICK}"\n{SMALL_DESIGN}{OBJECTIVE}')
    yield f


def test_optimise_writes_the_cli_tables_and_shards_merge_to_them(design: Path, tmp_path: Path) -> None:
    r = calsim.optimise(design, out=tmp_path / "py", threads=2, plots=False, progress=False)
    assert r.name == "q" and r.restarts == 2 and 0 < r.evaluations <= 4
    assert r.dest == tmp_path / "py" / "q"
    assert {"trace", "race", "verified"} <= set(r.tables) and "held-out" in r.summary
    cli("optimise", design, "--out", tmp_path / "cli", "--threads", "1", "--no-plots")
    for name in ("trace.parquet", "race.parquet", "verified.parquet", "best_design.toml"):
        assert (r.dest / name).read_bytes() == (tmp_path / "cli" / "q" / name).read_bytes()
    shards = [calsim.optimise(design, out=tmp_path / "sh", shard=(k, 2), threads=1, plots=False, progress=False) for k in range(2)]
    assert all(s.dest is None and s.restarts == 1 for s in shards)
    merged = calsim.optimise(design, out=tmp_path / "sh", merge=True, plots=False, progress=False)
    assert merged.dest is not None
    assert merged.tables["verified"].equals(r.tables["verified"])


def test_bad_optimise_arguments_name_the_key(design: Path, tmp_path: Path) -> None:
    for keywords, key in [(dict(method="simplex"), "method"), (dict(shard=(2, 2)), "shard"), (dict(threads=0), "threads")]:
        with pytest.raises(calsim.InputError) as e:
            calsim.optimise(design, out=tmp_path, progress=False, **keywords)  # type: ignore[arg-type]
        assert e.value.key == key and str(e.value).startswith(f"{key}: ")
    with pytest.raises(calsim.InputError) as e:
        calsim.optimise(design, out=tmp_path, shard=(0, 2), merge=True, progress=False)
    assert e.value.key == "merge"
    bad = tmp_path / "bad.toml"
    bad.write_text(design.read_text().replace("evaluations = 2", "evaluations = 0"))
    with pytest.raises(calsim.InputError) as e:
        calsim.optimise(bad, out=tmp_path, progress=False)
    assert e.value.path == str(bad) and e.value.key is not None and "evaluations" in e.value.key


def test_table8_gives_the_cli_rows(tmp_path: Path) -> None:
    r = calsim.table8(QUICK, pool=100, threads=2, progress=False)
    assert r.worlds == 1 and r.table["instrument"].to_list() == ["TriCal", "laser tracker", "optical CMM"]
    assert r.table.columns[1:3] == ["published_median_mm", "calsim_median_mm"] and r.table.dtypes[1:] == [pl.Float64] * 8
    assert (r.table["published_median_mm"] > 0).all() and r.warnings == []
    text = cli("table8", QUICK, "--pool", "100", "--threads", "1").stdout.decode()
    rows = {line[:16].strip(): line[16:] for line in text.splitlines()[1:4]}
    for row in r.table.iter_rows(named=True):
        c = [row["calsim_median_mm"], row["calsim_std_mm"], row["calsim_max_mm"]]
        assert f"{c[0]:.3f} / {c[1]:.3f} / {c[2]:.3f}  ({row['median_p10_mm']:.3f}-{row['median_p90_mm']:.3f})" in rows[row["instrument"]]


@pytest.mark.parametrize(
    "keywords, key", [(dict(pool=5), "pool"), (dict(realisations=0), "realisations"), (dict(threads=2000), "threads")]
)
def test_bad_table8_arguments_name_the_key(keywords: dict[str, int], key: str) -> None:
    with pytest.raises(calsim.InputError) as e:
        calsim.table8(QUICK, progress=False, **keywords)
    assert e.value.key == key and str(e.value).startswith(f"{key}: ")
    with pytest.raises(calsim.ScenarioError) as e2:
        calsim.table8(REPO / "scenarios" / "missing.toml", progress=False)
    assert e2.value.path == str(REPO / "scenarios" / "missing.toml")


def test_keys_gives_the_cli_reference_as_a_frame() -> None:
    for name in ("trical", "sweep", "robot"):
        frame = calsim.keys(name)
        assert frame.columns == ["key", "unit", "default", "rule", "note"] and frame.height > 5
        text = cli("keys", name).stdout.decode()
        # Every key of the frame starts a line of the CLI's list, in the same order.
        lines = text.splitlines()
        positions = [next((i for i, line in enumerate(lines) if line.startswith(f"{k} ")), -1) for k in frame["key"].to_list()]
        assert -1 not in positions and positions == sorted(positions)
    assert "trical.epsilon_mm" in calsim.keys("trical")["key"].to_list()
    with pytest.raises(calsim.InputError) as e:
        calsim.keys("tricall")
    assert (e.value.key, e.value.value) == ("name", "tricall") and "one of" in str(e.value)


def test_init_gives_the_cli_scenario_and_never_replaces_a_file(tmp_path: Path) -> None:
    text = calsim.init("trical", tmp_path / "cell.toml")
    assert text.encode() == cli("init", "trical").stdout == (tmp_path / "cell.toml").read_bytes()
    r = calsim.run(tmp_path / "cell.toml", out=tmp_path, set_sizes=[30], repetitions=1, plots=False, recording=False, progress=False)
    assert r.kind == "trical" and r.tables["tasks"].height == 1
    with pytest.raises(calsim.InputError) as e:
        calsim.init("trical", tmp_path / "cell.toml")
    assert e.value.key == "file" and e.value.path == str(tmp_path / "cell.toml")
    with pytest.raises(calsim.InputError) as e:
        calsim.init("laser", tmp_path / "other.toml")
    assert (e.value.key, e.value.value) == ("kind", "laser") and not (tmp_path / "other.toml").exists()


def small_plan(tmp_path: Path, extra: str = "") -> Path:
    """The shipped IRB 120 plan, short (pool 300, 40 poses, 8 validation poses, 8 worlds)."""
    text = (REPO / "scenarios" / "plans" / "irb120_tracker.toml").read_text()
    text = text.replace('robot = "../../robots/irb120.toml"', f'robot = "{ROBOT}"')
    for old, new in [("poses = 60 ", "poses = 40 "), ("pool = 2000", "pool = 300"), ("validation = 20", "validation = 8"), ("worlds = 30", "worlds = 8")]:
        assert old in text
        text = text.replace(old, new)
    f = tmp_path / "small.toml"
    f.write_text(text + extra)
    return f


def plan_file(path: Path, frame: pl.DataFrame) -> pl.DataFrame:
    """A plan's CSV file written by the CLI, read by polars with the documented dtypes (the labels
    as text, ``step`` and a device plan's ``sphere`` or ``station`` as integers, every other column
    as floats), its columns those of ``frame``."""
    text, integer = ("pose", "session", "target", "split"), ("step", "sphere", "station")
    schema = pl.Schema({c: pl.String if c in text else pl.Int64 if c in integer else pl.Float64 for c in frame.columns})
    assert frame.schema == schema, path
    return pl.read_csv(path, comment_prefix="#", schema=schema)


def test_plan_writes_the_cli_files(tmp_path: Path) -> None:
    f = small_plan(tmp_path)
    r = calsim.plan(f, out=tmp_path / "py", threads=2, simulate=True, progress=False)
    assert r.poses == 40 and r.validation == 8
    assert r.table.height == 2 * 48  # two targets per pose
    assert r.table["split"].value_counts().sort("split")["count"].to_list() == [16, 80]
    assert r.table["x_mm"].is_null().all()
    assert r.prediction["worlds"] == 8
    assert 0 < r.prediction["p10_mm"] <= r.prediction["median_mm"] <= r.prediction["p90_mm"]
    assert r.figure.exists() and r.objective is None and r.comparison is None
    cli("plan", f, "--out", tmp_path / "cli", "--threads", "2", "--simulate")
    dest = tmp_path / "cli" / "small.plan"
    for name in ["poses.csv", "joints.txt", "tour.csv", "plan.md", "plan_poses.png", "simulated.csv"]:
        assert (r.dest / name).read_bytes() == (dest / name).read_bytes(), name
    # The frames equal the CLI's files read by polars.
    assert r.simulated is not None and r.simulated["x_mm"].is_not_null().all()
    for frame, name in [(r.table, "poses.csv"), (r.tour, "tour.csv"), (r.simulated, "simulated.csv")]:
        assert frame.equals(plan_file(dest / name, frame)), name
    assert r.tour.filter(pl.col("split") != "via")["pose"].sort().equals(r.table["pose"].unique().sort())


def test_plan_comparison_as_a_frame(tmp_path: Path) -> None:
    f = small_plan(tmp_path)
    text = f.read_text().replace("worlds = 8", "worlds = 8\ncompare = true")
    f.write_text(text)
    r = calsim.plan(f, out=tmp_path / "py", threads=2, progress=False)
    assert r.comparison is not None
    assert r.comparison["selection"].to_list() == ["DETMAX", "random", "greedy D-optimal"]
    assert r.comparison["o1"][0] == r.o1 and r.comparison["o1"][1] == r.o1_random
    # The frames are the tables plan.md is rendered from, as written.
    assert set(r.tables) == {"plan", "tour_moves", "worlds", "unidentifiable", "comparison"}
    for name, stored in r.tables.items():
        assert stored.equals(pl.read_parquet(r.dest / f"{name}.parquet")), name
    assert r.tables["plan"]["median_mm"][0] == r.prediction["median_mm"] and r.tables["plan"]["training"][0] == r.poses


def test_bad_plan_files_name_the_file_and_the_key(tmp_path: Path) -> None:
    f = small_plan(tmp_path)
    f.write_text(f.read_text().replace("poses = 40 ", "poses = 10 "))
    with pytest.raises(calsim.InputError, match="poses"):
        calsim.plan(f, out=tmp_path / "py", progress=False)


def small_trical_plan(tmp_path: Path) -> Path:
    """The shipped TriCal plan (``[instrument] kind = "trical"``), its files named absolutely, 8 worlds."""
    text = (REPO / "scenarios" / "plans" / "irb120_trical.toml").read_text()
    scenario = REPO / "scenarios" / "irb120_trical.toml"
    for old, new in [('"../../robots/irb120.toml"', f'"{ROBOT}"'), ('"../irb120_trical.toml"', f'"{scenario}"'), ("worlds = 30 ", "worlds = 8 ")]:
        assert old in text
        text = text.replace(old, new)
    f = tmp_path / "trical.toml"
    f.write_text(text)
    return f


def test_a_trical_plan_gives_the_cli_files_and_its_tables_as_frames(tmp_path: Path) -> None:
    f = small_trical_plan(tmp_path)
    r = calsim.plan(f, out=tmp_path / "py", threads=2, simulate=True, progress=False)
    assert (r.instrument, r.poses, r.validation, r.drawn) == ("trical", 75, 30, 360)
    assert 75 < r.pool <= 360 and r.comparison is None and r.objective is None and r.search is None
    assert set(r.tables) == {"plan", "spheres", "tour_moves", "worlds", "unidentifiable"}
    for name, stored in r.tables.items():
        assert stored.equals(pl.read_parquet(r.dest / f"{name}.parquet")), name
    assert r.table["split"].value_counts().sort("split")["count"].to_list() == [30, 75]
    assert r.prediction["worlds"] == 8
    assert 0 < r.prediction["p10_mm"] <= r.prediction["median_mm"] <= r.prediction["p90_mm"]
    cli("plan", f, "--out", tmp_path / "cli", "--threads", "2", "--simulate")
    dest = tmp_path / "cli" / "trical.plan"
    for name in ["poses.csv", "joints.txt", "tour.csv", "plan.md", "plan_poses.png", "simulated.csv"]:
        assert (r.dest / name).read_bytes() == (dest / name).read_bytes(), name
    # The frames are the CLI's tables, every number bit for bit.
    for frame, name in [(r.table, "poses.csv"), (r.simulated, "simulated.csv"), (r.tour, "tour.csv")]:
        assert frame is not None
        lines = [line.split(",") for line in (dest / name).read_text().splitlines() if not line.startswith("#")]
        assert frame.columns == lines[0] and frame.height == len(lines) - 1, name
        for column, dtype in zip(frame.columns, frame.dtypes):
            k = lines[0].index(column)
            for value, row in zip(frame[column].to_list(), lines[1:]):
                text = row[k]
                if dtype == pl.String:
                    assert value == text, (name, column)
                elif text == "":
                    assert value is None, (name, column)
                else:
                    assert value == float(text) and not (dtype.is_integer() and "." in text), (name, column, value, text)
    assert r.tour.filter(pl.col("split") != "via").height == 105
    for frame, name in [(r.table, "poses.csv"), (r.simulated, "simulated.csv"), (r.tour, "tour.csv")]:
        assert frame is not None and frame.equals(plan_file(dest / name, frame)), name
    assert r.simulated is not None and r.simulated["x_mm"].is_not_null().all()
    assert (r.table.filter(pl.col("split") == "holdout")["x_mm"].is_null()).all()
    # The predicted median as plan.md rounds it.
    assert f"| {r.prediction['p10_mm']:.4f} | {r.prediction['median_mm']:.4f} | {r.prediction['p90_mm']:.4f} |" in (dest / "plan.md").read_text()


def test_a_bad_trical_plan_raises_naming_the_file_and_the_key(tmp_path: Path) -> None:
    f = small_trical_plan(tmp_path)
    f.write_text(f.read_text().replace("pool = 360 ", "pool = 361 "))
    with pytest.raises(calsim.InputError, match="multiple of the 3 datum spheres") as e:
        calsim.plan(f, out=tmp_path / "py", progress=False)
    assert (e.value.path, e.value.key) == (str(f), "pool")
    assert not (tmp_path / "py" / "trical.plan").exists()
    f.write_text(f.read_text().replace("pool = 361 ", "pool = 360 ").replace('kind = "trical"', 'kind = "trical"\nspheres = 3'))
    with pytest.raises(calsim.InputError, match="unknown field") as e:
        calsim.plan(f, out=tmp_path / "py", progress=False)
    assert e.value.path == str(f) and e.value.key is not None and "line" in e.value.key


def small_simulation(tmp_path: Path, poses: int = 40) -> Path:
    """docs/calibrate/imported_example.toml at ``poses`` poses a session, its robot named absolutely."""
    text = (REPO / "docs" / "calibrate" / "imported_example.toml").read_text()
    robot = REPO / "robots" / "examples" / "lrmate200ic_coupled.toml"
    small = text.replace("poses_per_session = 17000", f"poses_per_session = {poses}").replace(
        '"../../robots/examples/lrmate200ic_coupled.toml"', f'"{robot}"'
    )
    assert small != text
    spec = tmp_path / "imported_example.toml"
    spec.write_text(small)
    return spec


def test_simulate_measurements_gives_the_cli_file_and_calibrates(tmp_path: Path) -> None:
    spec = small_simulation(tmp_path)
    r = calsim.simulate_measurements(spec)
    assert r.path is None and r.rows == 3 * 40 * 2 + 30 == r.table.height
    cli("simulate-measurements", spec, "--out", tmp_path / "cli")
    assert (tmp_path / "cli" / "imported_example.csv").read_text() == r.csv
    written = calsim.simulate_measurements(spec, out=tmp_path / "py")
    assert written.path == tmp_path / "py" / "imported_example.csv" and written.path.read_text() == r.csv
    assert r.table["session"].unique().sort().to_list() == ["A", "B", "C", "L"]
    # The frame holds the file's numbers bit for bit.
    first = next(line for line in r.csv.splitlines() if not line.startswith("#") and not line.startswith("pose"))
    assert r.table["x_mm"][0] == float(first.split(",")[9])
    # The frame equals the file the CLI writes, read by polars with the documented dtypes.
    schema = {c: (pl.String if c in ("pose", "session", "target") else pl.Float64) for c in r.table.columns}
    assert r.table.schema == pl.Schema(schema)
    assert r.table.equals(pl.read_csv(tmp_path / "cli" / "imported_example.csv", comment_prefix="#", schema=schema))
    c = calsim.calibrate(
        REPO / "robots" / "examples" / "lrmate200ic_coupled.toml",
        written.path,
        out=tmp_path / "out",
        plots=False,
        hold_out_session="L",
        tool_per_session=True,
    )
    assert c.tables["points"].height == r.rows


def test_simulated_orientation_readings_are_the_cli_file_columns(tmp_path: Path) -> None:
    spec = REPO / "docs" / "calibrate" / "probe_example.toml"
    r = calsim.simulate_measurements(spec)
    cli("simulate-measurements", spec, "--out", tmp_path)
    written = tmp_path / "probe_example.csv"
    assert written.read_text() == r.csv
    assert r.table.columns[-4:] == ["quat_w", "quat_x", "quat_y", "quat_z"] and r.rows == r.table.height
    schema = {c: (pl.String if c in ("pose", "session", "target") else pl.Float64) for c in r.table.columns}
    assert r.table.equals(pl.read_csv(written, comment_prefix="#", schema=schema))


def test_bad_simulation_files_name_the_file_key_and_value(tmp_path: Path) -> None:
    spec = small_simulation(tmp_path)
    first = calsim.simulate_measurements(spec, out=tmp_path)
    assert first.path is not None
    before = first.path.read_bytes()
    with pytest.raises(calsim.InputError) as e:
        calsim.simulate_measurements(spec, out=tmp_path)
    assert e.value.path == str(first.path) and "the file exists" in str(e.value)
    assert first.path.read_bytes() == before
    bad = tmp_path / "bad.toml"
    bad.write_text(spec.read_text().replace("noise_mm = 0.012", "noise_mm = nan"))
    with pytest.raises(calsim.InputError) as e2:
        calsim.simulate_measurements(bad, out=tmp_path / "never")
    assert (e2.value.path, e2.value.key) == (str(bad), "noise_mm")
    assert not (tmp_path / "never").exists()
    with pytest.raises(calsim.InputError) as e3:
        calsim.simulate_measurements(tmp_path / "missing.toml")
    assert e3.value.path == str(tmp_path / "missing.toml")
