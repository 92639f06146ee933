"""What the commands return: a results directory with its tables as polars DataFrames (read from
the parquet files calsim wrote), its figures and summary, and what the command reported."""

from __future__ import annotations

import json
from functools import cached_property
from pathlib import Path
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import polars as pl

if TYPE_CHECKING:
    from ._calsim import (
        ArrowFrame,
        BudgetReport,
        CalibrateReport,
        CompensateReport,
        ExportReport,
        FkReport,
        ImportReport,
        MergeReport,
        OptimiseReport,
        PlanReport,
        Prediction,
        RunReport,
        SimulateReport,
        SweepReport,
        Table8Report,
    )

# The Rerun version of the recordings calsim writes (the `rerun` crate of Cargo.toml); a viewer of
# another version may not read them.
RERUN_VERSION = "0.36.3"


class Results:
    """A results directory: ``tables`` (every ``*.parquet`` by its stem, as DataFrames, read once),
    ``figures`` (the PNG files), ``summary`` (``summary.md``) and ``manifest`` (``manifest.json``)."""

    def __init__(self, dest: str | Path | None) -> None:
        self.dest: Path | None = None if dest is None else Path(dest)

    @cached_property
    def tables(self) -> dict[str, pl.DataFrame]:
        """Every table of the directory by name (``tasks``, ``parameters``, ``points``, ...)."""
        if self.dest is None:
            return {}
        return {p.stem: pl.read_parquet(p) for p in sorted(self.dest.glob("*.parquet"))}

    def table(self, name: str) -> pl.DataFrame:
        """One table by name; a KeyError lists the tables there are."""
        try:
            return self.tables[name]
        except KeyError:
            raise KeyError(f"{name!r}: no such table in {self.dest} (there are: {', '.join(self.tables)})") from None

    @property
    def figures(self) -> list[Path]:
        """The figures written (PNG; an SVG of each lies beside it)."""
        return [] if self.dest is None else sorted(self.dest.glob("*.png"))

    @property
    def summary(self) -> str:
        """``summary.md``, the tables and figures in Markdown ("" when there is none)."""
        path = None if self.dest is None else self.dest / "summary.md"
        return path.read_text() if path is not None and path.is_file() else ""

    @property
    def manifest(self) -> dict[str, Any]:
        """``manifest.json``: scenario and its hash, seed, version, overrides, table hashes, timings."""
        path = None if self.dest is None else self.dest / "manifest.json"
        if path is None or not path.is_file():
            return {}
        manifest: dict[str, Any] = json.loads(path.read_text())
        return manifest

    @property
    def recording(self) -> Path | None:
        """The Rerun recording of the run (``study.rrd``), or None when it wrote none."""
        path = None if self.dest is None else self.dest / "study.rrd"
        return path if path is not None and path.is_file() else None

    def show_recording(self, width: int = 900, height: int = 520) -> Any:
        """Shows the Rerun recording inline in a notebook and returns the viewer widget. Needs the
        viewer of the Rerun version calsim writes with: ``pip install "calsim[notebook]"``."""
        if self.recording is None:
            raise FileNotFoundError(f"{self.dest}: no study.rrd (the run was made with recording=False, or wrote none)")
        try:
            import rerun as rr
            from rerun.notebook import Viewer
        except ImportError:
            raise ImportError('showing a recording needs rerun-sdk with its notebook viewer: pip install "calsim[notebook]"') from None
        if rr.__version__ != RERUN_VERSION:
            raise ImportError(
                f"{self.recording} was written by Rerun {RERUN_VERSION}; rerun-sdk {rr.__version__} is installed: "
                f'pip install "rerun-sdk[notebook]=={RERUN_VERSION}"'
            )
        stream = rr.RecordingStream(f"calsim {self.dest.name if self.dest else ''}".strip())
        stream.log_file_from_path(self.recording)
        viewer = Viewer(recording=stream, width=width, height=height)
        viewer.display()
        return viewer

    def __repr__(self) -> str:
        names = ", ".join(self.tables) if self.dest is not None else "none"
        return f"{type(self).__name__}(dest={str(self.dest)!r}, tables=[{names}], figures={len(self.figures)})"


def _frames(frames: Mapping[str, ArrowFrame]) -> dict[str, pl.DataFrame]:
    """A report's result frames by name, each handed over through the Arrow PyCapsule interface
    (its schema travels with it: no column is named between calsim and here)."""
    return {name: pl.DataFrame(frame) for name, frame in frames.items()}


class RunResult(Results):
    """What ``run`` and ``check`` did: the results directory, and ``checks`` (the published
    figures beside calsim's, with band and ``result`` ``pass``, ``miss`` or ``-``: whether realisation
    0's value lies in its band), ``distribution`` (the same over realisations, or None: each
    figure's median with its interval and confidence, the worlds without a value, and ``pass``,
    ``open``, ``miss`` or ``unresolved``, the last a failure: too few worlds to judge), ``judged``,
    ``passed`` / ``checked`` / ``missed``, ``timing``, ``warnings``.

    As the CLI: a check judges its figures (over one world, that world's values; over several, the
    distribution); a run over one world shows one draw of each figure and judges nothing
    (``judged`` False, ``passed``, ``checked`` and ``missed`` None: whether the model reproduces a
    figure is judged over worlds, by ``check``); a run over realisations judges the distribution."""

    def __init__(self, report: RunReport) -> None:
        super().__init__(report["dest"])
        self.name: str = report["name"]
        self.kind: str = report["kind"]
        self.seed: int = report["seed"]
        self.threads: int = report["threads"]
        self.timing: str = report["timing"]
        self.realisations: int = report["realisations"]
        self.judged: bool = report["judged"]
        self.checked: int | None = report["checked"]
        self.missed: int | None = report["missed"]
        self.warnings: list[str] = list(report["warnings"])
        frames = _frames(report["frames"])
        self.checks: pl.DataFrame = frames["checks"]
        self.distribution: pl.DataFrame | None = frames.get("distribution")

    @property
    def passed(self) -> bool | None:
        """Every banded figure within its band (over the realisations when several ran; the CLI's
        exit code 0 of a check), or None when nothing was judged (a run of one world)."""
        return None if self.missed is None else self.missed == 0

    def __repr__(self) -> str:
        if self.checked is None or self.missed is None:
            verdict = "one world: one draw of each figure, judged over worlds by check"
        elif self.distribution is not None:
            verdict = f"{self.checked - self.missed} of {self.checked} figures not missed over {self.realisations} realisations"
        else:
            verdict = f"{self.checked - self.missed} of {self.checked} figures within their bands"
        return f"RunResult({self.name!r}, kind={self.kind!r}, seed={self.seed}, {verdict}, dest={str(self.dest)!r})"


class SweepResult(Results):
    """What a sweep or a merge did: the merged results (``tables['points']``, ``tables['sweep']``,
    the figures), the work units and how many failed; for one shard, ``shard_dir`` and no tables."""

    def __init__(self, report: SweepReport | None, merged: MergeReport | None = None) -> None:
        """A sweep's report (its merge within, or none for one shard), or a merge's alone."""
        if report is not None:
            merged = report["merged"]
        super().__init__(None if merged is None else merged["dest"])
        if report is None:
            assert merged is not None, "a sweep's report or a merge's"
            self.name: str = Path(merged["dest"]).name
        else:
            self.name = report["name"]
        self.units: int = merged["units"] if merged else report["units"] if report else 0
        self.failed: int = merged["failed"] if merged else 0
        self.run_s: float | None = None if report is None else report["run_s"]
        self.shard: tuple[int, int] | None = None if report is None else (report["shard"][0], report["shard"][1])
        self.shard_dir: Path | None = None if report is None else Path(report["shard_dir"])
        self.warnings: list[str] = [] if report is None else list(report["warnings"])
        self._summary: str = merged["summary"] if merged else ""

    @property
    def summary(self) -> str:
        return self._summary


class BudgetResult(Results):
    """What a budget did: ``tables['budget']`` (per source and configuration),
    ``tables['prediction']`` (the linear prediction beside the Monte Carlo), the figures and the
    budget table as text (``summary``)."""

    def __init__(self, report: BudgetReport) -> None:
        super().__init__(report["dest"])
        self.units: int = report["units"]
        self.run_s: float = report["run_s"]
        self.warnings: list[str] = list(report["warnings"])
        self._summary: str = report["summary"]

    @property
    def summary(self) -> str:
        return self._summary


class ExportResult:
    """An exported identification: ``dest`` holds ``robot.toml`` (the identified model with each
    parameter's standard deviation), ``before.toml``, ``robot.urdf`` and ``calibration.yaml``."""

    def __init__(self, report: ExportReport) -> None:
        self.dest: Path = Path(report["dest"])
        self.scenario: str = report["scenario"]
        self.task: int = report["task"]
        self.set_size: int = report["set_size"]
        self.validation_median_mm: float = report["validation_median_mm"]
        self.files: list[Path] = [self.dest / f for f in report["files"]]

    @property
    def robot_file(self) -> Path:
        """The calibrated model as a robot file (``calsim compensate`` takes it)."""
        return self.dest / "robot.toml"

    def __repr__(self) -> str:
        return (
            f"ExportResult(task={self.task}, set_size={self.set_size}, "
            f"validation_median_mm={self.validation_median_mm:.4f}, dest={str(self.dest)!r})"
        )


class CalibrationResult(Results):
    """What a calibration did: the report directory (``tables['points']``, ``models``,
    ``parameters``, ``bases``, ``tools``, ``correlation``, the figures, ``summary.md``), the model
    chosen by its held-out error (``model``: ``offsets``, ``geometric`` or ``compliance``), the
    CLI's report (``report``) and, with ``plan_worlds``, the plans' comparison (``plan``: a row
    per plan in the order of ``plan.md``'s table: ``plan``, ``scenario`` (what each world draws),
    ``statistic``, the measured held-out figure ``measured_mm`` beside the simulated
    ``simulated_p10_mm``, ``simulated_mm`` (the median) and ``simulated_p90_mm`` over ``worlds``,
    and ``inside``; None without a plan)."""

    def __init__(self, report: CalibrateReport) -> None:
        super().__init__(report["dest"])
        self.dest: Path = Path(report["dest"])
        self.model: str = report["model"]
        self.report: str = report["report"]
        plan = report["plan"]
        self.plan: pl.DataFrame | None = None if plan is None else pl.DataFrame(plan)

    @property
    def robot_file(self) -> Path:
        """The calibrated model as a robot file (``calsim compensate`` takes it)."""
        return self.dest / "robot.toml"

    def __repr__(self) -> str:
        return f"CalibrationResult(model={self.model!r}, dest={str(self.dest)!r}, figures={len(self.figures)})"


class OptimiseResult(Results):
    """What an optimisation did: the results directory (None for one shard of the restarts),
    the restarts and designs this run evaluated, the timings, the summary and the winner's timing
    line (``cost``)."""

    def __init__(self, report: OptimiseReport) -> None:
        super().__init__(report["dest"])
        self.name: str = report["name"]
        self.restarts: int = report["restarts"]
        self.evaluations: int = report["evaluations"]
        self.search_s: float = report["search_s"]
        self.finish_s: float = report["finish_s"]
        self.cost: str | None = report["cost"]
        self.warnings: list[str] = list(report["warnings"])
        self._summary: str = report["summary"] or ""

    @property
    def summary(self) -> str:
        return self._summary


class CompensateResult:
    """The compensated targets: ``joints`` (per target ``q1_deg`` ... ``q6_deg``, the model's
    ``model_error_mm`` and ``model_error_deg`` at them and, with a nominal model, the
    ``nominal_*`` Cartesian target to command, every column a float; where the model cannot reach
    the target, null joint values and nominal target and NaN errors),
    ``csv`` (the CLI's text), ``unreachable`` (1-based target numbers) and ``out`` (the CSV
    written, or None)."""

    def __init__(self, report: CompensateReport, out: Path | None) -> None:
        self.csv: str = report["csv"]
        self.targets: int = report["targets"]
        self.unreachable: list[int] = list(report["unreachable"])
        self.warnings: list[str] = list(report["warnings"])
        self.out = out
        self.joints: pl.DataFrame = pl.DataFrame(report["table"])

    def __repr__(self) -> str:
        return f"CompensateResult(targets={self.targets}, unreachable={len(self.unreachable)})"


class Table8Result:
    """Table 8: ``table`` (the table ``calsim table8`` prints: per instrument, TriCal, laser
    tracker and optical CMM, the published median, std and max after calibration beside calsim's,
    each the median over the worlds, with the P10-P90 of the median over them), ``worlds``
    calibrated, ``run_s``, ``warnings``."""

    def __init__(self, report: Table8Report) -> None:
        self.table: pl.DataFrame = pl.DataFrame(report["table"])
        self.worlds: int = report["worlds"]
        self.run_s: float = report["run_s"]
        self.warnings: list[str] = list(report["warnings"])

    def __repr__(self) -> str:
        return f"Table8Result(worlds={self.worlds}, instruments={self.table['instrument'].to_list()})"


class PlanResult:
    """A calibration plan (``calsim plan``), of a laser tracker (``instrument`` ``"tracker"``) or
    of a device with configurations of its own (``"trical"``): ``dest`` (its directory),
    ``poses`` (the training poses planned: the plan's count or its objective's), ``pool`` (the
    feasible poses chosen from) and ``drawn`` (the candidates drawn; a device plan: the
    configurations its campaign centred), ``table`` (``poses.csv``'s rows: the measurement file to
    fill, its labels as text, its joint values and positions as floats, a position to measure
    null), ``tour`` (``tour.csv``'s: the order to visit them, via configurations of re-routed moves
    split ``via``, the values as the file states them), ``simulated`` (``simulated.csv``'s with
    ``simulate``, else ``None``),
    ``prediction`` (the predicted held-out median: ``p10_mm``, ``median_mm``, ``p90_mm``,
    ``worlds``, ``pilot_mm``, ``twin``), ``unidentifiable``, ``tables`` (the tables ``plan.md``
    is rendered from, as written: ``plan`` (one row: the plan's inputs and figures),
    ``tour_moves``, ``worlds``, ``unidentifiable``, ...), ``objective`` (``None``, or the
    objective's table: its rule, ``met`` and the count ``planned``) with ``search`` (P(success)
    and its ``lower`` bound against the number of poses), ``comparison`` (``None``, or DETMAX,
    random and greedy selection; a tracker plan's), ``figure`` (``plan_poses.png``) and
    ``seconds``."""

    def __init__(self, report: PlanReport) -> None:
        self.instrument: str = report["instrument"]
        self.dest: Path = Path(report["dest"])
        self.pool: int = report["pool"]
        self.drawn: int = report["drawn"]
        self.poses: int = report["poses"]
        self.validation: int = report["validation"]
        self.o1: float = report["o1"]
        self.o1_random: float = report["o1_random"]
        self.prediction: Prediction = report["prediction"]
        self.unidentifiable: list[str] = list(report["unidentifiable"])
        self.tables: dict[str, pl.DataFrame] = _frames(report["frames"])
        self.objective: pl.DataFrame | None = self.tables.get("objective")
        self.search: pl.DataFrame | None = self.tables.get("search")
        self.comparison: pl.DataFrame | None = self.tables.get("comparison")
        self.table: pl.DataFrame = pl.DataFrame(report["table"])
        self.tour: pl.DataFrame = pl.DataFrame(report["tour"])
        simulated = report["simulated"]
        self.simulated: pl.DataFrame | None = None if simulated is None else pl.DataFrame(simulated)
        self.figure: Path = self.dest / "plan_poses.png"
        self.seconds: float = report["seconds"]

    def __repr__(self) -> str:
        return (
            f"PlanResult(instrument={self.instrument!r}, dest={str(self.dest)!r}, poses={self.poses}, "
            f"predicted_median_mm={self.prediction['median_mm']:.4f})"
        )


class ImportResult:
    """An imported URDF: ``robot_file`` (the robot file written) and ``lines`` (what became of
    the geometry, masses, meshes and passive joints)."""

    def __init__(self, report: ImportReport) -> None:
        self.robot_file: Path = Path(report["out"])
        self.lines: list[str] = list(report["lines"])

    def __repr__(self) -> str:
        return f"ImportResult(robot_file={str(self.robot_file)!r})"


class FkResult:
    """The arm at each row of the joints: ``table`` (the joint values, the tool frame ``x_mm``
    ... ``gamma_deg`` in {W}, gravity torques ``tau*_nm``, deflections ``deflection*_mdeg`` and
    ``within_limits``) and ``csv`` (the CLI's text)."""

    def __init__(self, report: FkReport) -> None:
        self.csv: str = report["csv"]
        self.rows: int = report["rows"]
        self.table: pl.DataFrame = pl.DataFrame(report["table"])

    def __repr__(self) -> str:
        return f"FkResult(rows={self.rows})"


class SimulatedMeasurements:
    """A simulated measurement file for :func:`calibrate`: ``csv`` (the file's text, its ``#``
    header lines included), ``table`` (its rows: ``pose``, ``session`` and ``target`` as text, the
    joint values, positions and any orientation readings as the floats the file's text was written
    from), ``rows`` and ``path`` (the file written, or None)."""

    def __init__(self, report: SimulateReport) -> None:
        self.csv: str = report["csv"]
        self.rows: int = report["rows"]
        self.path: Path | None = None if report["written"] is None else Path(report["written"])
        self.table: pl.DataFrame = pl.DataFrame(report["table"])

    def __repr__(self) -> str:
        return f"SimulatedMeasurements(rows={self.rows}, path={None if self.path is None else str(self.path)!r})"
