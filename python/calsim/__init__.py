"""calsim from Python: simulation and Monte Carlo studies of industrial-robot calibration.

Each command of the ``calsim`` CLI is a function here, on the same scenario and sweep files and
with the same results directories; a study runs in calsim's native code with the interpreter
released, and its tables come back as polars DataFrames::

    import calsim

    r = calsim.run("scenarios/irb120_trical.toml", set_sizes=[20, 50, 75], repetitions=5)
    r.checks                    # the published figures beside calsim's (DataFrame)
    r.tables["tasks"]           # one row per identification (DataFrame)
    r.figures                   # the PNG figures written

Errors are :class:`CalsimError` subclasses whose message is the CLI's one line, with the file
(``path``), the key (``key``) and the value (``value``) as attributes where known.
"""

from __future__ import annotations

import operator
import os
import warnings
from collections.abc import Iterable, Sequence
from pathlib import Path

from . import _calsim
from ._calsim import (
    BudgetError,
    CalsimError,
    FileError,
    InputError,
    MergeError,
    RobotFileError,
    ScenarioError,
    StudyError,
    SweepError,
)
from ._progress import Progress, observer
from ._results import BudgetResult, ExportResult, Results, RunResult, SweepResult

__version__ = _calsim.__version__

__all__ = [
    "run",
    "check",
    "sweep",
    "merge",
    "budget",
    "export",
    "Results",
    "RunResult",
    "SweepResult",
    "BudgetResult",
    "ExportResult",
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
]

PathLike = str | os.PathLike


def _whole(key: str, v: object, lo: int, hi: int) -> int:
    """``v`` as a whole number within [lo, hi] (the type's range: the command checks the rule),
    else an InputError naming ``key``."""
    try:
        n = operator.index(v)
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


def _run(scenario, check_, out, seed, set_sizes, repetitions, threads, realisations, false_alarm, plots, recording, progress) -> RunResult:
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


def _warn(report: dict) -> None:
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
            shard=None if shard is None else tuple(_whole("shard", k, 0, 2**63) for k in shard),
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
    return SweepResult({"name": Path(merged["dest"]).name, "merged": merged, "warnings": []})


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
    if isinstance(results, Results):
        results = results.dest
    report = _calsim.export(
        Path(results),
        task=_optional("task", task, 2**63),
        set_size=_optional("set_size", set_size, 2**63),
        pick=pick, out=None if out is None else Path(out)
    )
    return ExportResult(report)
