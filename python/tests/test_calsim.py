"""Tests of the Python package: the commands on the shipped scenarios (reduced by keyword
overrides), their results as DataFrames, errors as exceptions naming file and key, progress, the
interpreter released while a study runs, and the same tables as the CLI."""

from __future__ import annotations

import json
import os
import shutil
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import polars as pl
import pytest

import calsim

REPO = Path(__file__).resolve().parents[2]
QUICK = REPO / "scenarios" / "ci_quick.toml"
SPMS = REPO / "scenarios" / "er20c10_spms.toml"

# A study small enough for a debug build: 2 set sizes x 3 repetitions of the CI scenario.
SMALL: dict[str, Any] = dict(set_sizes=[40, 75], repetitions=3, threads=2, recording=False, progress=False)


def bits(frame: pl.DataFrame) -> list[tuple[object, ...]]:
    """Every cell of the frame, a float as its 8 bytes (signed zeros and NaNs told apart)."""
    return [tuple(struct.pack("<d", v) if isinstance(v, float) else v for v in row) for row in frame.iter_rows()]


@pytest.fixture(scope="module")
def small_run(tmp_path_factory: pytest.TempPathFactory) -> calsim.RunResult:
    return calsim.run(QUICK, out=tmp_path_factory.mktemp("run"), **SMALL)


def test_run_returns_every_table_as_a_dataframe_with_the_overrides_applied(small_run: calsim.RunResult) -> None:
    r = small_run
    assert r.name == "ci_quick" and r.kind == "trical" and r.seed == 2018
    assert set(r.tables) == {
        "tasks",
        "parameters",
        "validation_errors",
        "compensated",
        "checks",
        "errors",
        "set_sizes",
        "table7",
        "correlations",
    }
    # The checks the run hands over are the table it wrote, schema and every value bit for bit.
    assert r.checks.schema == r.tables["checks"].schema and bits(r.checks) == bits(r.tables["checks"])
    tasks = r.tables["tasks"]
    assert isinstance(tasks, pl.DataFrame)
    # One DETMAX identification per set size and repetition, in task order.
    assert tasks.height == 2 * 3
    assert tasks["set_size"].to_list() == [40, 40, 40, 75, 75, 75]
    assert tasks["repetition"].to_list() == [0, 1, 2, 0, 1, 2]
    # The 31 parameters of Table 7 per identification, long form.
    assert r.tables["parameters"].height == 6 * 31
    assert r.manifest["seed"] == 2018
    assert ["study.set_sizes", "[40, 75]"] in r.manifest["overrides"]


def test_run_checks_are_a_dataframe_of_the_published_figures(small_run: calsim.RunResult) -> None:
    checks = small_run.checks
    assert checks.columns == ["figure", "published", "published_value", "calsim", "value", "band", "result", "scope"]
    assert set(checks["result"].unique()) <= {"pass", "miss", "-"}
    before = checks.filter(pl.col("figure").str.starts_with("before calibration: mean error"))
    assert before.height == 1 and before["published_value"][0] == pytest.approx(2.628)
    assert small_run.distribution is None


def test_a_run_of_one_world_judges_nothing_as_the_cli(small_run: calsim.RunResult) -> None:
    # The CLI shows one world's figures as draws, without a verdict or a tally.
    r = small_run
    assert not r.judged and r.passed is None and r.checked is None and r.missed is None
    assert "judged over worlds by check" in repr(r) and "within their bands" not in repr(r)


def test_a_check_of_one_world_judges_its_values_as_the_cli(tmp_path: Path) -> None:
    r = calsim.check(QUICK, out=tmp_path, realisations=1, plots=False, **{**SMALL, "set_sizes": [75]})
    assert r.judged and r.distribution is None
    # The checked and missed counts agree with the rows, and with the CLI's tally and exit code.
    banded = r.checks.filter(pl.col("result") != "-")
    missed = banded.filter(pl.col("result") == "miss").height
    assert r.checked == banded.height and r.missed == missed and r.passed == (missed == 0)
    assert f"{banded.height - missed} of {banded.height} figures within their bands" in repr(r)
    cli = os.environ.get("CALSIM_BIN") or shutil.which("calsim")
    if cli is None:
        pytest.skip("no calsim binary (set CALSIM_BIN)")
    args = ["check", str(QUICK), "--out", str(tmp_path / "cli"), "--realisations", "1", "--set-sizes", "75", "--repetitions", "3"]
    done = subprocess.run([cli, *args, "--threads", "2", "--no-plots", "--no-recording"], capture_output=True, text=True)
    assert f"check: {banded.height - missed} of {banded.height} figures within their bands" in done.stdout
    assert done.returncode == (1 if missed else 0)


def test_run_lists_its_figures_and_summary(small_run: calsim.RunResult) -> None:
    names = {p.name for p in small_run.figures}
    assert "fig08_mean_error_by_set_size.png" in names and "fig13_error_histograms.png" in names
    assert all(p.is_file() and p.with_suffix(".svg").is_file() for p in small_run.figures)
    assert "Table 7" in small_run.summary


@pytest.fixture(scope="module")
def recorded_run(tmp_path_factory: pytest.TempPathFactory) -> calsim.RunResult:
    return calsim.run(QUICK, out=tmp_path_factory.mktemp("recorded"), **{**SMALL, "recording": True})


def test_a_run_with_its_recording_shows_it_in_a_notebook_viewer(recorded_run: calsim.RunResult) -> None:
    # CI installs the notebook extra; a plain install has no viewer (the next test).
    rerun = pytest.importorskip("rerun")
    from rerun.notebook import Viewer

    r = recorded_run
    assert r.dest is not None and r.recording is not None
    assert r.recording == r.dest / "study.rrd" and r.recording.stat().st_size > 0
    assert rerun.__version__ == calsim._results.RERUN_VERSION
    assert isinstance(r.show_recording(width=400, height=300), Viewer)


def test_without_the_viewer_showing_a_recording_names_the_install(recorded_run: calsim.RunResult, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "rerun", None)  # `import rerun` raises ImportError
    with pytest.raises(ImportError, match=r"pip install \"calsim\[notebook\]\""):
        recorded_run.show_recording()


def test_a_run_without_its_recording_has_none_to_show(small_run: calsim.RunResult) -> None:
    assert small_run.recording is None
    with pytest.raises(FileNotFoundError, match="recording=False"):
        small_run.show_recording()


def test_check_with_realisations_judges_every_figure_over_the_worlds(tmp_path: Path) -> None:
    # 5 worlds give every figure a bounded interval at a false-alarm rate of 0.5 (not at 0.01).
    r = calsim.check(QUICK, out=tmp_path, realisations=5, false_alarm=0.5, plots=False, **{**SMALL, "set_sizes": [75]})
    assert r.realisations == 5
    d = r.distribution
    assert d is not None and d.height == r.checks.height
    assert d["figure"].to_list() == r.checks["figure"].to_list()
    assert (d["count"] <= 5).all()
    # The distribution handed over is the table written, every value bit for bit.
    written = r.tables["checks_over_worlds"]
    assert d.schema == written.schema and bits(d) == bits(written)
    assert r.judged and r.passed == (d.filter(pl.col("result").is_in(["miss", "unresolved"])).height == 0)


def test_a_check_over_too_few_worlds_to_judge_is_refused(tmp_path: Path) -> None:
    with pytest.raises(calsim.InputError) as e:
        calsim.check(QUICK, out=tmp_path, realisations=2, plots=False, **{**SMALL, "set_sizes": [75]})
    assert e.value.key == "realisations" and str(e.value).startswith("realisations: 2: ") and "at least" in str(e.value)


def test_an_out_of_range_override_is_a_scenario_error_naming_file_key_and_value(tmp_path: Path) -> None:
    with pytest.raises(calsim.ScenarioError) as e:
        calsim.run(QUICK, out=tmp_path, repetitions=0, progress=False)
    assert e.value.path == str(QUICK)
    assert e.value.key == "study.repetitions" and e.value.value == "0"
    assert "[study] repetitions = 0" in str(e.value) and "\n" not in str(e.value)


def test_an_exception_says_what_the_cli_says(tmp_path: Path) -> None:
    """An exception's message is the CLI's error line: a path longer than 200 characters without
    a space shortened in its middle, the TOML parser's line breaks escaped, whoever calls."""
    deep = tmp_path / ("d" * 120) / ("e" * 120)
    deep.mkdir(parents=True)
    bad = deep / "bad.toml"
    bad.write_text("seed = \n")
    with pytest.raises(calsim.ScenarioError) as e:
        calsim.run(bad, out=tmp_path / "out", progress=False)
    message = str(e.value)
    assert "characters]..." in message and "\n" not in message and str(bad) not in message
    cli = os.environ.get("CALSIM_BIN") or shutil.which("calsim")
    if cli is not None:
        p = subprocess.run([cli, "run", str(bad), "--out", str(tmp_path / "out")], capture_output=True, text=True)
        assert p.returncode == 2 and p.stderr == f"error: {message}\n"


def test_a_bad_scenario_file_is_a_scenario_error_naming_its_key(tmp_path: Path) -> None:
    text = QUICK.read_text().replace("../robots/irb120.toml", str(REPO / "robots" / "irb120.toml"))
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace("epsilon_mm = 0.010", "epsilon_mm = -0.01", 1))
    assert "epsilon_mm = -0.01" in bad.read_text()
    with pytest.raises(calsim.ScenarioError) as e:
        calsim.run(bad, out=tmp_path / "out", progress=False)
    assert (e.value.path, e.value.key, e.value.value) == (str(bad), "trical.epsilon_mm", "-0.01")

    bad.write_text(text.replace("[trical]", "[trical]\nepsilon_um = 10", 1))
    with pytest.raises(calsim.ScenarioError) as e:
        calsim.run(bad, out=tmp_path / "out", progress=False)
    assert e.value.key == "trical.epsilon_um" and "unknown field `epsilon_um`" in str(e.value)

    with pytest.raises(calsim.ScenarioError) as e:
        calsim.run(tmp_path / "missing.toml", out=tmp_path / "out", progress=False)
    assert e.value.path == str(tmp_path / "missing.toml") and e.value.key is None


@pytest.mark.parametrize(
    "keywords, key",
    [
        (dict(threads=0), "threads"),
        (dict(threads=5000), "threads"),
        (dict(realisations=0), "realisations"),
        (dict(set_sizes=[]), "set_sizes"),
        (dict(set_sizes="20:100:5"), "set_sizes"),
        (dict(set_sizes=[75.5]), "set_sizes"),
        (dict(set_sizes=[-20]), "set_sizes"),
    ],
)
def test_a_bad_keyword_is_an_input_error_naming_it(tmp_path: Path, keywords: dict[str, Any], key: str) -> None:
    with pytest.raises(calsim.InputError) as e:
        calsim.run(QUICK, out=tmp_path, progress=False, **keywords)
    assert str(e.value).startswith(f"{key}: ")
    assert (tmp_path / "ci_quick").exists() is False


@pytest.mark.parametrize(
    "keywords, key",
    [(dict(seed=-1), "seed"), (dict(seed=2**64), "seed"), (dict(repetitions=2.5), "repetitions"), (dict(threads="2"), "threads")],
)
def test_a_keyword_of_the_wrong_type_or_size_is_an_input_error_naming_it(tmp_path: Path, keywords: dict[str, Any], key: str) -> None:
    with pytest.raises(calsim.InputError) as e:
        calsim.run(QUICK, out=tmp_path, progress=False, **keywords)
    assert str(e.value).startswith(f"{key}: ") and e.value.key == key


def test_an_out_that_is_a_file_is_an_input_error(tmp_path: Path) -> None:
    f = tmp_path / "file"
    f.write_text("")
    with pytest.raises(calsim.InputError) as e:
        calsim.run(QUICK, out=f, progress=False)
    assert e.value.path == str(f) and e.value.key == "out"


def test_progress_reaches_the_callback_from_start_to_the_last_identification(tmp_path: Path) -> None:
    events = []
    calsim.run(QUICK, out=tmp_path, **{**SMALL, "progress": lambda *a: events.append(a)})
    assert events[0][0] == "started" and "ci_quick" in events[0][1]
    progress = [(done, total) for ev, what, done, total in events if ev == "progress" and what == "identifications"]
    assert progress[-1] == (6, 6)
    assert [d for d, _ in progress] == sorted(d for d, _ in progress)
    assert ("stage_done", "", 0, 0) in events


def test_an_exception_in_the_callback_is_raised_after_the_study(tmp_path: Path) -> None:
    def callback(event: str, text: str, done: int, total: int) -> None:
        raise RuntimeError("callback failed")

    with pytest.raises(RuntimeError, match="callback failed"):
        calsim.run(QUICK, out=tmp_path, **{**SMALL, "progress": callback})
    # The study itself ran and wrote its results.
    assert (tmp_path / "ci_quick" / "tasks.parquet").is_file()


def test_the_default_progress_draws_a_line_per_stage_without_tqdm(capsys: pytest.CaptureFixture[str]) -> None:
    bars = calsim._progress.Bars()
    bars._tqdm = None
    bars("started", "calsim run: x", 0, 0)
    bars("progress", "identifications", 3, 6)
    bars("progress", "identifications", 6, 6)
    bars("stage_done", "", 0, 0)
    assert capsys.readouterr().err.splitlines() == ["calsim run: x", "6/6 identifications"]


def test_the_interpreter_runs_other_threads_while_a_study_runs(tmp_path: Path) -> None:
    # The study runs on a thread of its own; the main thread counts its own steps meanwhile. With
    # the interpreter held by the study, no step of the main thread could fall inside the study.
    span = {}

    def study() -> None:
        span["start"] = time.monotonic()
        calsim.run(QUICK, out=tmp_path, **{**SMALL, "repetitions": 10})
        span["end"] = time.monotonic()

    t = threading.Thread(target=study)
    steps = []
    t.start()
    while t.is_alive():
        steps.append(time.monotonic())
        time.sleep(0.001)
    t.join()
    inside = [s for s in steps if span["start"] < s < span["end"]]
    assert span["end"] - span["start"] > 0.05
    assert len(inside) >= 10


def test_python_and_cli_write_the_same_tables() -> None:
    cli = os.environ.get("CALSIM_BIN") or shutil.which("calsim")
    if cli is None:
        pytest.skip("no calsim binary (set CALSIM_BIN)")
    out = Path(os.environ.get("TMPDIR", "/tmp")) / f"calsim-pytest-{os.getpid()}"
    try:
        py = calsim.run(QUICK, out=out / "py", **SMALL)
        args = ["run", str(QUICK), "--out", str(out / "cli"), "--set-sizes", "40:75:35", "--repetitions", "3"]
        subprocess.run([cli, *args, "--threads", "1", "--no-recording"], check=True, capture_output=True)
        cli_manifest = json.loads((out / "cli" / "ci_quick" / "manifest.json").read_text())
        assert py.manifest["tables_sha256"] == cli_manifest["tables_sha256"]
    finally:
        shutil.rmtree(out, ignore_errors=True)


def test_an_spms_study_runs_the_same_way(tmp_path: Path) -> None:
    r = calsim.run(SPMS, out=tmp_path, set_sizes=[50], repetitions=2, plots=False, recording=False, progress=False)
    assert r.kind == "spms"
    assert {"beams", "measurements", "tasks", "parameters", "iso9283_before"} <= set(r.tables)
    assert r.tables["tasks"].height == 2 * 2  # random and DETMAX sets


def small_sweep(tmp_path: Path) -> Path:
    f = tmp_path / "eps.toml"
    f.write_text(
        f'base = "{QUICK}"\nrealisations = 2\nthresholds_mm = [0.5, 1.0]\n\n'
        '[fixed]\n"study.set_sizes" = [75]\n"study.repetitions" = 2\n\n'
        '[[axis]]\nkey = "trical.epsilon_mm"\nvalues = [0.010, 0.020]\n'
    )
    return f


def test_a_sweep_returns_its_points_and_shards_merge_to_the_same_tables(tmp_path: Path) -> None:
    f = small_sweep(tmp_path)
    whole = calsim.sweep(f, out=tmp_path / "whole", threads=2, progress=False)
    assert whole.units == 2 * 2 and whole.failed == 0
    points = whole.tables["points"]
    assert sorted(set(points["point"].to_list())) == [0, 1]
    # The axis's values are numbers, as the sweep file writes them.
    assert points["trical.epsilon_mm"].dtype == pl.Float64
    assert sorted(set(points["trical.epsilon_mm"].to_list())) == [0.01, 0.02]
    assert "P(max" in whole.summary or "p95" in whole.summary
    shards = [calsim.sweep(f, out=tmp_path / "sharded", shard=(k, 2), threads=1, progress=False) for k in range(2)]
    assert all(s.dest is None and s.tables == {} for s in shards)
    merged = calsim.merge([s.shard_dir for s in shards if s.shard_dir is not None], out=tmp_path / "sharded")
    for name in ("points", "sweep"):
        assert merged.tables[name].equals(whole.tables[name])


def test_a_bad_sweep_file_is_a_sweep_error_naming_the_key(tmp_path: Path) -> None:
    f = tmp_path / "bad.toml"
    f.write_text(f'base = "{QUICK}"\nrealisations = 2\n[[axis]]\nkey = "trical.epsilon_mm"\nvalues = [-1.0]\n')
    with pytest.raises(calsim.SweepError) as e:
        calsim.sweep(f, out=tmp_path, progress=False)
    assert e.value.path == str(f) and e.value.key == "trical.epsilon_mm"


@pytest.mark.parametrize("keywords, key", [(dict(shard=(2, 2)), "shard"), (dict(shard=(0, 0)), "shard"), (dict(realisations=0), "realisations")])
def test_a_bad_sweep_keyword_is_an_input_error_naming_it(tmp_path: Path, keywords: dict[str, Any], key: str) -> None:
    with pytest.raises(calsim.InputError) as e:
        calsim.sweep(small_sweep(tmp_path), out=tmp_path / "out", progress=False, **keywords)
    assert e.value.key == key and str(e.value).startswith(f"{key}: ")
    assert not (tmp_path / "out").exists()


def test_a_merge_of_a_directory_that_is_no_shard_is_a_merge_error(tmp_path: Path) -> None:
    with pytest.raises(calsim.MergeError) as e:
        calsim.merge([tmp_path], out=tmp_path / "out")
    assert e.value.path == str(tmp_path)


def test_a_budget_returns_its_table_and_prediction(tmp_path: Path) -> None:
    r = calsim.budget(QUICK, out=tmp_path, realisations=1, factors=[2.0], repetitions=1, threads=2, progress=False)
    assert r.dest == tmp_path / "ci_quick.budget"
    budget, prediction = r.tables["budget"], r.tables["prediction"]
    assert budget.height > 0 and prediction.height > 0
    assert "transmission errors" in r.summary
    for keywords, key in [(dict(factors=[float("nan")]), "factors"), (dict(realisations=0), "realisations"), (dict(repetitions=0), "repetitions")]:
        with pytest.raises(calsim.InputError) as e:
            calsim.budget(QUICK, out=tmp_path / "bad", progress=False, **keywords)  # type: ignore[arg-type]
        assert e.value.key == key and str(e.value).startswith(f"{key}: ")
    assert not (tmp_path / "bad").exists()


def test_export_redoes_the_median_identification_and_writes_the_model(small_run: calsim.RunResult, tmp_path: Path) -> None:
    e = calsim.export(small_run, out=tmp_path)
    tasks = small_run.tables["tasks"].filter(pl.col("task") == e.task)
    assert e.set_size == 75 and tasks["set_size"][0] == 75
    assert e.validation_median_mm == tasks["validation_median_mm"][0]
    assert [f.name for f in e.files] == ["robot.toml", "before.toml", "robot.urdf", "calibration.yaml"]
    assert all(f.is_file() for f in e.files)
    assert "[std]" in e.robot_file.read_text()
    with pytest.raises(calsim.InputError) as err:
        calsim.export(small_run, task=10_000, out=tmp_path)
    assert err.value.path == str(small_run.dest)


def test_the_readme_python_recipe_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import re

    blocks = re.findall(r"```python\n(.*?)```", (REPO / "README.md").read_text(), flags=re.S)
    assert blocks
    for name in ("scenarios", "robots"):
        (tmp_path / name).symlink_to(REPO / name)
    monkeypatch.chdir(tmp_path)
    for block in blocks:
        exec(compile(block, "README.md", "exec"), {})
    # Wherever the recipe puts its results: the study's tables and the exported model.
    assert list((tmp_path / "results").rglob("irb120_trical/tasks.parquet"))
    assert list((tmp_path / "results").rglob("irb120_trical.task-*/robot.toml"))


def test_an_out_that_holds_the_scenario_is_refused_and_nothing_changes(tmp_path: Path) -> None:
    scenario = tmp_path / "ci_quick" / "ci_quick.toml"
    scenario.parent.mkdir()
    shutil.copy(QUICK, scenario)
    (tmp_path / "robots").mkdir()
    shutil.copy(REPO / "robots" / "irb120.toml", tmp_path / "robots" / "irb120.toml")  # the scenario's robot.file
    before = scenario.read_bytes()
    with pytest.raises(calsim.InputError) as e:
        calsim.run(scenario, out=tmp_path, **SMALL)
    assert e.value.key == "out" and "input of this run" in str(e.value)
    assert scenario.read_bytes() == before
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["ci_quick", "ci_quick.toml", "irb120.toml", "robots"]
