"""calsim from Python: simulation and Monte Carlo studies of industrial-robot calibration.

Each command of the ``calsim`` CLI is a function here, on the same scenario and sweep files and
with the same results directories; a study runs in calsim's native code with the interpreter
released, and its tables come back as polars DataFrames::

    import calsim

    r = calsim.run("scenarios/irb120_trical.toml", set_sizes=[20, 50, 75], repetitions=5)
    r.checks                    # the published figures beside calsim's (DataFrame)
    r.tables["tasks"]           # one row per identification (DataFrame)
    r.figures                   # the PNG figures written

The real-robot path as well: :func:`import_urdf` (an arm's URDF as a robot file), :func:`calibrate`
(measurements from a CSV file or a polars DataFrame), :func:`compensate` (targets from a CSV file
or a DataFrame), :func:`fk` and :func:`simulate_measurements` (a measurement file of a
simulation file, to try the path before the robot is measured); and :func:`optimise` and :func:`table8`.

Errors are :class:`CalsimError` subclasses whose message is the CLI's one line, with the file
(``path``), the key (``key``) and the value (``value``) as attributes where known.
"""

from __future__ import annotations

import operator
import os
import re
import shutil
import tempfile
import warnings
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import polars as pl

from . import _calsim
from ._calsim import (
    BudgetError,
    CalsimError,
    DataError,
    FileError,
    InputError,
    MergeError,
    RobotFileError,
    ScenarioError,
    StudyError,
    SweepError,
)
from ._progress import Progress, observer
from ._results import (
    BudgetResult,
    CalibrationResult,
    CompensateResult,
    ExportResult,
    FkResult,
    ImportResult,
    OptimiseResult,
    PlanResult,
    Results,
    RunResult,
    SimulatedMeasurements,
    SweepResult,
    Table8Result,
)

__version__ = _calsim.__version__

__all__ = [
    "run",
    "check",
    "sweep",
    "merge",
    "budget",
    "export",
    "calibrate",
    "plan",
    "optimise",
    "compensate",
    "table8",
    "import_urdf",
    "fk",
    "simulate_measurements",
    "keys",
    "init",
    "Results",
    "RunResult",
    "SweepResult",
    "BudgetResult",
    "ExportResult",
    "CalibrationResult",
    "OptimiseResult",
    "PlanResult",
    "CompensateResult",
    "Table8Result",
    "ImportResult",
    "FkResult",
    "SimulatedMeasurements",
    "Progress",
    "CalsimError",
    "CalsimWarning",
    "ScenarioError",
    "SweepError",
    "MergeError",
    "BudgetError",
    "RobotFileError",
    "InputError",
    "StudyError",
    "FileError",
    "DataError",
]

PathLike = str | os.PathLike[str]


def _whole(key: str, v: object, lo: int, hi: int) -> int:
    """``v`` as a whole number within [lo, hi] (the type's range: the command checks the rule),
    else an InputError naming ``key``."""
    try:
        n = operator.index(v)  # type: ignore[call-overload, arg-type, unused-ignore]
    except TypeError:
        raise _input(key, f"{v!r} is not a whole number") from None
    if not lo <= n <= hi:
        raise _input(key, f"{n} is not within [{lo}, {hi}]")
    return n


_U32 = 2**32 - 1
_U64 = 2**64 - 1


def _optional(key: str, v: object, hi: int) -> int | None:
    return None if v is None else _whole(key, v, 0, hi)


def _sizes(set_sizes: Iterable[int] | None) -> list[int] | None:
    if set_sizes is None:
        return None
    if isinstance(set_sizes, str | bytes):
        raise _input("set_sizes", f"{set_sizes!r}: a sequence of whole numbers, e.g. range(20, 101, 5)")
    return [_whole("set_sizes", n, 0, _U32) for n in set_sizes]


def _input(key: str, why: str) -> InputError:
    e = InputError(f"{key}: {why}")
    e.key = key
    return e


# Every calsim exception has the three attributes; None where the error names no such thing.
for _name in ("path", "key", "value"):
    setattr(CalsimError, _name, None)


def run(
    scenario: PathLike,
    *,
    out: PathLike = "results",
    seed: int | None = None,
    set_sizes: Iterable[int] | None = None,
    repetitions: int | None = None,
    threads: int | None = None,
    realisations: int = 1,
    plots: bool = True,
    recording: bool = True,
    progress: Progress = True,
) -> RunResult:
    """Runs the study of a scenario of any device (``calsim run``) and returns its results.

    ``seed``, ``set_sizes`` and ``repetitions`` replace the scenario's; ``threads`` defaults to
    ``RAYON_NUM_THREADS``, else every core; with ``realisations`` > 1 every figure is also judged
    over that many worlds (``result.distribution``). The results go to ``out/<scenario name>``.
    ``progress``: True (a tqdm bar when tqdm is installed, else a line per stage), False, or a
    callable ``f(event, text, done, total)``.
    """
    return _run(scenario, False, out, seed, set_sizes, repetitions, threads, realisations, None, plots, recording, progress)


def check(
    scenario: PathLike,
    *,
    out: PathLike = "results",
    seed: int | None = None,
    set_sizes: Iterable[int] | None = None,
    repetitions: int | None = None,
    threads: int | None = None,
    realisations: int | None = None,
    false_alarm: float | None = None,
    plots: bool = True,
    recording: bool = True,
    progress: Progress = True,
) -> RunResult:
    """Runs the study and judges its figures against the scenario's ``[expect]`` bands (``calsim check``).

    The same as :func:`run`; over ``realisations`` worlds (default: the scenario's
    ``study.check_realisations``) a figure misses when the interval of its median lies wholly
    outside its band, at the false-alarm rate ``false_alarm`` (default: the scenario's
    ``study.check_false_alarm``). ``result.passed`` says whether no figure missed (the CLI's exit
    code 0), ``result.missed`` how many did; the verdict is also in ``check.json`` of the results.
    """
    return _run(scenario, True, out, seed, set_sizes, repetitions, threads, realisations, false_alarm, plots, recording, progress)


def _run(
    scenario: PathLike,
    check_: bool,
    out: PathLike,
    seed: int | None,
    set_sizes: Iterable[int] | None,
    repetitions: int | None,
    threads: int | None,
    realisations: int | None,
    false_alarm: float | None,
    plots: bool,
    recording: bool,
    progress: Progress,
) -> RunResult:
    with observer(progress) as callback:
        report = _calsim.run(
            Path(scenario),
            out=Path(out),
            check=check_,
            seed=_optional("seed", seed, _U64),
            set_sizes=_sizes(set_sizes),
            repetitions=_optional("repetitions", repetitions, _U32),
            threads=_optional("threads", threads, _U32),
            realisations=_optional("realisations", realisations, _U32),
            false_alarm=None if false_alarm is None else float(false_alarm),
            plots=plots,
            recording=recording,
            progress=callback,
        )
    _warn(report)
    return RunResult(report)


def _warn(report: Mapping[str, Any]) -> None:
    # Warnings reach Python's warnings machinery from the calling thread, after the command.
    for line in report.get("warnings", []):
        warnings.warn(line, CalsimWarning, stacklevel=3)


class CalsimWarning(UserWarning):
    """A warning of a command: identifications without a model, realisations left out."""


def sweep(
    file: PathLike,
    *,
    out: PathLike = "results",
    shard: tuple[int, int] | None = None,
    threads: int | None = None,
    realisations: int | None = None,
    progress: Progress = True,
) -> SweepResult:
    """Runs a design sweep (``calsim sweep``): every work unit, then merged into ``out/<sweep>``;
    with ``shard=(k, K)`` only every K-th unit from k, left for :func:`merge`; ``realisations``
    replaces the file's count (the most, for an adaptive sweep)."""
    with observer(progress) as callback:
        report = _calsim.sweep(
            Path(file),
            out=Path(out),
            shard=_shard(shard),
            threads=_optional("threads", threads, _U32),
            realisations=_optional("realisations", realisations, _U32),
            progress=callback,
        )
    _warn(report)
    return SweepResult(report)


def merge(shards: Sequence[PathLike], *, out: PathLike = "results") -> SweepResult:
    """Merges the shard directories of one sweep into ``out/<sweep>`` (``calsim merge``)."""
    if isinstance(shards, str | os.PathLike):
        shards = [shards]
    merged = _calsim.merge([Path(s) for s in shards], out=Path(out))
    return SweepResult(None, merged)


def budget(
    scenario: PathLike,
    *,
    out: PathLike = "results",
    realisations: int = 20,
    factors: Sequence[float] = (0.5, 2.0),
    repetitions: int | None = None,
    threads: int | None = None,
    progress: Progress = True,
) -> BudgetResult:
    """The uncertainty budget of a scenario (``calsim budget``): every error source alone, off
    and scaled by each factor, over the same realisations; results in ``out/<scenario>.budget``."""
    with observer(progress) as callback:
        report = _calsim.budget(
            Path(scenario),
            out=Path(out),
            realisations=_whole("realisations", realisations, 0, _U32),
            factors=[float(f) for f in factors],
            repetitions=_optional("repetitions", repetitions, _U32),
            threads=_optional("threads", threads, _U32),
            progress=callback,
        )
    _warn(report)
    return BudgetResult(report)


def export(
    results: PathLike | Results,
    *,
    task: int | None = None,
    set_size: int | None = None,
    pick: str = "median",
    out: PathLike | None = None,
) -> ExportResult:
    """Exports one identification of a TriCal results directory (``calsim export``): the robot
    file with each parameter's standard deviation, the model before calibration, a URDF and a YAML
    overlay, in ``<out>/<scenario>.task-<N>`` (``out`` defaults to beside the results)."""
    path = results.dest if isinstance(results, Results) else Path(results)
    if path is None:
        raise _input("results", f"{results!r}: results with no directory (one shard of a sweep)")
    report = _calsim.export(
        path,
        task=_optional("task", task, 2**63),
        set_size=_optional("set_size", set_size, 2**63),
        pick=pick,
        out=None if out is None else Path(out),
    )
    return ExportResult(report)


def _shard(shard: tuple[int, int] | None) -> tuple[int, int] | None:
    if shard is None:
        return None
    if isinstance(shard, str | bytes) or len(shard) != 2:
        raise _input("shard", f"{shard!r}: a pair (k, K) of whole numbers")
    return (_whole("shard", shard[0], 0, 2**63), _whole("shard", shard[1], 0, 2**63))


def _real(key: str, v: object) -> float | None:
    """``v`` as a float (None stays None), else an InputError naming ``key``; the command checks
    its range."""
    if v is None:
        return None
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise _input(key, f"{v!r} is not a number")
    return float(v)


_STEM = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,99}")


def _frame_csv(frame: pl.DataFrame, key: str, name: str, columns: Sequence[str] | None, header: Mapping[str, str] | None, dir: Path) -> Path:
    """Writes ``frame`` as ``dir/<name>.csv`` (``columns`` in that order, when given; ``header``
    as ``# key = value`` lines before the column names). Floats are written to round-trip: the
    command reads the frame's values bit for bit."""
    if not _STEM.fullmatch(name):
        raise _input("name", f"{name!r}: a file name of letters, digits, '.', '_' and '-'")
    if columns is not None:
        missing = [c for c in columns if c not in frame.columns]
        if missing:
            raise _input(key, f"the frame has no column {', '.join(missing)} (it needs {','.join(columns)})")
        frame = frame.select(columns)
    path = dir / f"{name}.csv"
    with open(path, "w", newline="") as f:
        for k, v in (header or {}).items():
            if "\n" in f"{k}{v}" or "=" in k:
                raise _input("header", f"{k!r} = {v!r}: a key and a value of one line each")
            f.write(f"# {k} = {v}\n")
        frame.write_csv(f)
    return path


def calibrate(
    robot: PathLike,
    measurements: PathLike | pl.DataFrame,
    *,
    out: PathLike = "results",
    name: str = "measurements",
    header: Mapping[str, str] | None = None,
    folds: int = 5,
    hold_out: float | None = None,
    hold_out_session: str | None = None,
    hold_out_file: PathLike | None = None,
    seed: int = 1,
    params: Sequence[str] | None = None,
    outlier_threshold: float | None = None,
    outliers: str | None = None,
    plan_worlds: int = 0,
    plan_noise_mm: float | None = None,
    plan_scenario: PathLike | None = None,
    plots: bool = True,
    kfold_by: str | None = None,
    tool_per_session: bool = False,
    payload_kg: float | None = None,
    payload_com_mm: Sequence[float] | None = None,
    plan_with: str | None = None,
    instrument_noise_mm: float | None = None,
) -> CalibrationResult:
    """Calibrates a real robot from measured data (``calsim calibrate``): the report, the
    calibrated ``robot.toml``, URDF and YAML in ``out/<measurements stem>.calibration``.

    ``measurements`` is a CSV file in the layout of docs/calibrate.md, or a polars DataFrame with
    the same columns (``pose``, ``session``, ``target``, ``q1_deg`` ... ``q6_deg``, ``x_mm``,
    ``y_mm``, ``z_mm``, optional ``sigma_mm``; the units in the names as in the file): a joined
    tracker export and joint log, say. A frame is written as ``<name>.csv`` (with ``header`` as
    its ``# key = value`` lines, e.g. ``{"joints": "model"}``) to a temporary directory,
    calibrated as the CLI calibrates that file (the same tables, bit for bit), and kept in the
    report as ``measurements.csv``; the report goes to ``out/<name>.calibration``.
    """
    keywords: dict[str, Any] = dict(
        out=Path(out),
        folds=_whole("folds", folds, 0, _U32),
        hold_out=_real("hold_out", hold_out),
        hold_out_session=hold_out_session,
        hold_out_file=None if hold_out_file is None else Path(hold_out_file),
        seed=_whole("seed", seed, 0, _U64),
        params=None if params is None else _names("params", params),
        outlier_threshold=_real("outlier_threshold", outlier_threshold),
        outliers=outliers,
        plan_worlds=_whole("plan_worlds", plan_worlds, 0, _U32),
        plan_noise_mm=_real("plan_noise_mm", plan_noise_mm),
        plan_scenario=None if plan_scenario is None else Path(plan_scenario),
        plots=plots,
        kfold_by=kfold_by,
        tool_per_session=tool_per_session,
        payload_kg=_real("payload_kg", payload_kg),
        payload_com_mm=None if payload_com_mm is None else [_real("payload_com_mm", v) for v in payload_com_mm],
        plan_with=plan_with,
        instrument_noise_mm=_real("instrument_noise_mm", instrument_noise_mm),
    )
    if not isinstance(measurements, pl.DataFrame):
        if header is not None:
            raise _input("header", "for a DataFrame of measurements: a file carries its own header lines")
        return CalibrationResult(_calsim.calibrate(Path(robot), Path(measurements), **keywords))
    with tempfile.TemporaryDirectory(prefix="calsim-measurements-") as tmp:
        csv = _frame_csv(measurements, "measurements", name, None, header, Path(tmp))
        report = _calsim.calibrate(Path(robot), csv, **keywords)
        shutil.copyfile(csv, Path(report["dest"]) / "measurements.csv")
    return CalibrationResult(report)


def _names(key: str, names: Sequence[str]) -> list[str]:
    if isinstance(names, str):
        names = names.split(",")
    out = [n.strip() for n in names]
    if not all(isinstance(n, str) for n in out):
        raise _input(key, f"{names!r}: names of parameters (e.g. ['a2', 'd4'])")
    return out


def optimise(
    file: PathLike,
    *,
    out: PathLike = "results",
    shard: tuple[int, int] | None = None,
    merge: bool = False,
    threads: int | None = None,
    method: str | None = None,
    plots: bool = True,
    progress: Progress = True,
) -> OptimiseResult:
    """Searches a design file's space for its objective, races the finalists and verifies them on
    held-out worlds (``calsim optimise``); results in ``out/<design>``. With ``shard=(k, K)``
    only the restarts r with r % K == k run (no results: then ``merge=True``); ``method``
    (``"nelder_mead"``, ``"particle_swarm"`` or ``"cmaes"``) replaces the file's."""
    with observer(progress) as callback:
        report = _calsim.optimise(
            Path(file),
            out=Path(out),
            shard=_shard(shard),
            merge=merge,
            threads=_optional("threads", threads, _U32),
            method=method,
            plots=plots,
            progress=callback,
        )
    _warn(report)
    return OptimiseResult(report)


def _model_path(model: PathLike | ExportResult | CalibrationResult) -> Path:
    if isinstance(model, ExportResult | CalibrationResult):
        return model.robot_file
    return Path(model)


_TARGETS = ["x_mm", "y_mm", "z_mm", "alpha_deg", "beta_deg", "gamma_deg"]
_JOINTS = ["q1_deg", "q2_deg", "q3_deg", "q4_deg", "q5_deg", "q6_deg"]


def compensate(
    model: PathLike | ExportResult | CalibrationResult,
    targets: PathLike | pl.DataFrame,
    *,
    nominal: PathLike | ExportResult | CalibrationResult | None = None,
    out: PathLike | None = None,
) -> CompensateResult:
    """The joint values that put the calibrated model's TCP on each target, and with ``nominal``
    the Cartesian targets to command a controller that knows only its nominal model
    (``calsim compensate``). ``model`` is a robot file, or the result of :func:`export` or
    :func:`calibrate` (its ``robot.toml``; for ``nominal`` its ``before.toml``). ``targets``: a
    CSV file or a DataFrame with the columns ``x_mm, y_mm, z_mm, alpha_deg, beta_deg,
    gamma_deg`` (the tool frame in {W}). ``out``: also write the CSV there. A target the model
    cannot reach has nulls in its row (``unreachable`` in the CSV) and a CalsimWarning."""
    nominal_path: Path | None
    if isinstance(nominal, ExportResult | CalibrationResult):
        nominal_path = nominal.dest / "before.toml"
    else:
        nominal_path = None if nominal is None else Path(nominal)
    keywords: dict[str, Any] = dict(nominal=nominal_path, out=None if out is None else Path(out))
    if isinstance(targets, pl.DataFrame):
        with tempfile.TemporaryDirectory(prefix="calsim-targets-") as tmp:
            csv = _frame_csv(targets, "targets", "targets", _TARGETS, None, Path(tmp))
            report = _calsim.compensate(_model_path(model), csv, **keywords)
    else:
        report = _calsim.compensate(_model_path(model), Path(targets), **keywords)
    _warn(report)
    return CompensateResult(report, None if out is None else Path(out))


def table8(
    scenario: PathLike,
    *,
    realisations: int = 1,
    pool: int = 360,
    threads: int | None = None,
    progress: Progress = True,
) -> Table8Result:
    """Table 8 of the TriCal paper (``calsim table8``): the robot of a TriCal scenario calibrated
    with the TriCal, a laser tracker and an optical CMM in each of ``realisations`` worlds, the
    medians beside the published rows; ``pool`` configurations per external instrument."""
    with observer(progress) as callback:
        report = _calsim.table8(
            Path(scenario),
            realisations=_whole("realisations", realisations, 0, _U32),
            pool=_whole("pool", pool, 0, _U32),
            threads=_optional("threads", threads, _U32),
            progress=callback,
        )
    _warn(report)
    return Table8Result(report)


def plan(
    file: PathLike,
    *,
    out: PathLike = "results",
    threads: int | None = None,
    simulate: bool = False,
    progress: Progress = True,
) -> PlanResult:
    """Plans a calibration (``calsim plan``): the poses to measure on a real robot, feasible in
    its cell, chosen by DETMAX, with the held-out error predicted over simulated worlds, written
    to ``out/<plan stem>.plan`` (``poses.csv`` to fill, ``joints.txt``, ``tour.csv``, ``plan.md``,
    the figure, the Rerun recording ``plan.rrd``); ``simulate`` also writes ``simulated.csv`` (the
    poses measured on the robot file's truth; a device plan: on its planning world's true arm).
    A plan file with ``[tracker]`` plans for a laser tracker, one with ``[instrument] kind =
    "trical"`` for the TriCal device on datum spheres. The plan file's keys: docs/plan.md
    (``[objective]`` for the number of poses by objective, ``compare = true`` for DETMAX against
    random and greedy selection)."""
    with observer(progress) as callback:
        report = _calsim.plan(
            Path(file),
            out=Path(out),
            threads=_optional("threads", threads, _U32),
            simulate=simulate,
            progress=callback,
        )
    _warn(report)
    return PlanResult(report)


def import_urdf(
    urdf: PathLike,
    *,
    out: PathLike,
    package_root: PathLike | None = None,
    visual_meshes: bool = False,
) -> ImportResult:
    """Converts a URDF arm (a serial chain of six revolute joints) into the calsim robot file
    ``out`` (``calsim import-urdf``); ``package_root`` holds the packages ``package://`` mesh
    names point into; ``visual_meshes`` fits a link's capsule to its visual meshes where it has no
    collision geometry. An existing file is not replaced unless calsim wrote it."""
    report = _calsim.import_urdf(
        Path(urdf),
        out=Path(out),
        package_root=None if package_root is None else Path(package_root),
        visual_meshes=visual_meshes,
    )
    return ImportResult(report)


def fk(
    robot: PathLike | ExportResult | CalibrationResult,
    joints: PathLike | pl.DataFrame,
    *,
    out: PathLike | None = None,
) -> FkResult:
    """The tool frame, gravity torques and joint deflections of a robot file's arm at each row of
    ``joints`` (``calsim fk``): a CSV file or a DataFrame with the columns ``q1_deg`` ...
    ``q6_deg``. ``out``: also write the CSV there."""
    keywords: dict[str, Any] = dict(out=None if out is None else Path(out))
    if isinstance(joints, pl.DataFrame):
        with tempfile.TemporaryDirectory(prefix="calsim-joints-") as tmp:
            csv = _frame_csv(joints, "joints", "joints", _JOINTS, None, Path(tmp))
            report = _calsim.fk(_model_path(robot), csv, **keywords)
    else:
        report = _calsim.fk(_model_path(robot), Path(joints), **keywords)
    return FkResult(report)


def simulate_measurements(spec: PathLike, *, out: PathLike | None = None) -> SimulatedMeasurements:
    """A measurement file for :func:`calibrate` simulated from the simulation file ``spec``
    (``calsim simulate-measurements``; its keys in docs/calibrate.md): the robot file's truth
    measured at random poses of its sessions and lines with the instrument's noise. ``out``: also
    write ``<out>/<spec stem>.csv`` (the directory created; an existing file is refused, never
    replaced)."""
    report = _calsim.simulate_measurements(Path(spec), out=None if out is None else Path(out))
    return SimulatedMeasurements(report)


def _named(e: InputError, command: str, keyword: str, value: str) -> InputError:
    """The library's refusal of a name for ``command`` as an error of the keyword it came in."""
    if e.path == command:
        e.path, e.key, e.value = None, keyword, value
    return e


def keys(name: str) -> pl.DataFrame:
    """Every key of a scenario file of a device (``"trical"``, ``"spms"``, ``"tracker"``), of a
    sweep file (``"sweep"``) or of a robot file (``"robot"``), as ``calsim keys`` lists it: one row
    per key with its ``unit``, ``default``, ``rule`` and ``note`` (SOURCED / ASSUMED / FITTED),
    made from the loaders themselves."""
    try:
        report = _calsim.keys(name)
    except InputError as e:
        raise _named(e, "keys", "name", name) from None
    return pl.DataFrame(report["table"])


def init(kind: str, file: PathLike | None = None) -> str:
    """A commented starting scenario of a device (``calsim init``), every key at its default: the
    text, also written to ``file`` when given (never replacing an existing file)."""
    path = None if file is None else Path(file)
    try:
        text = _calsim.init(kind, path)
    except InputError as e:
        if e.path == "init":
            raise _named(e, "init", "kind", kind) from None
        # The file exists (calsim init never replaces one): an error of the keyword it came in.
        e.path, e.key = os.fspath(file) if file is not None else e.path, "file"
        raise e from None
    return text
