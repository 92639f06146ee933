"""Stubs of the native module ``calsim._calsim``: each command returns a dict the pure-Python half
turns into a result object (the keys are read there, in ``_results.py``)."""

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

__version__: str

Callback = Callable[[str, str, int, int], object]
Report = dict[str, Any]

class ArrowFrame:
    """A result frame through the Arrow PyCapsule interface: ``polars.DataFrame(frame)`` reads it."""

    @property
    def shape(self) -> tuple[int, int]: ...
    def __arrow_c_stream__(self, requested_schema: object | None = None) -> object: ...

class CalsimError(Exception):
    path: str | None
    key: str | None
    value: str | None

class ScenarioError(CalsimError): ...
class SweepError(CalsimError): ...
class MergeError(CalsimError): ...
class BudgetError(CalsimError): ...
class RobotFileError(CalsimError): ...
class InputError(CalsimError): ...
class StudyError(CalsimError): ...
class FileError(CalsimError): ...
class DataError(CalsimError): ...

def run(
    scenario: Path,
    *,
    out: Path,
    check: bool,
    seed: int | None = None,
    set_sizes: Sequence[int] | None = None,
    repetitions: int | None = None,
    threads: int | None = None,
    realisations: int | None = None,
    false_alarm: float | None = None,
    plots: bool = True,
    recording: bool = True,
    progress: Callback | None = None,
) -> Report: ...
def sweep(
    file: Path,
    *,
    out: Path,
    shard: tuple[int, int] | None = None,
    threads: int | None = None,
    realisations: int | None = None,
    progress: Callback | None = None,
) -> Report: ...
def merge(shards: Sequence[Path], *, out: Path) -> Report: ...
def budget(
    scenario: Path,
    *,
    out: Path,
    realisations: int = 20,
    factors: Sequence[float] = ...,
    repetitions: int | None = None,
    threads: int | None = None,
    progress: Callback | None = None,
) -> Report: ...
def export(
    results: Path,
    *,
    task: int | None = None,
    set_size: int | None = None,
    pick: str = "median",
    out: Path | None = None,
) -> Report: ...
def calibrate(
    robot: Path,
    measurements: Path,
    *,
    out: Path,
    folds: int = 5,
    hold_out: float | None = None,
    hold_out_session: str | None = None,
    hold_out_file: Path | None = None,
    seed: int = 1,
    params: Sequence[str] | None = None,
    outlier_threshold: float | None = None,
    outliers: str | None = None,
    plan_worlds: int = 0,
    plan_noise_mm: float | None = None,
    plan_scenario: Path | None = None,
    plots: bool = True,
    kfold_by: str | None = None,
    tool_per_session: bool = False,
    payload_kg: float | None = None,
    payload_com_mm: Sequence[float] | None = None,
    plan_with: str | None = None,
    instrument_noise_mm: float | None = None,
) -> Report: ...
def optimise(
    file: Path,
    *,
    out: Path,
    shard: tuple[int, int] | None = None,
    merge: bool = False,
    threads: int | None = None,
    method: str | None = None,
    plots: bool = True,
    progress: Callback | None = None,
) -> Report: ...
def compensate(model: Path, targets: Path, *, nominal: Path | None = None, out: Path | None = None) -> Report: ...
def table8(
    scenario: Path,
    *,
    realisations: int = 1,
    pool: int = 360,
    threads: int | None = None,
    progress: Callback | None = None,
) -> Report: ...
def plan(
    file: Path,
    *,
    out: Path,
    threads: int | None = None,
    simulate: bool = False,
    progress: Callback | None = None,
) -> Report:
    """``calsim plan`` of a tracker plan (``[tracker]``) or a device plan (``[instrument]``): the
    report's ``instrument`` is ``"tracker"`` or the device's kind (``"trical"``)."""
def import_urdf(urdf: Path, *, out: Path, package_root: Path | None = None, visual_meshes: bool = False) -> Report: ...
def fk(robot: Path, joints: Path, *, out: Path | None = None) -> Report: ...
def simulate_measurements(spec: Path, *, out: Path | None = None) -> Report: ...
def keys(name: str) -> Report: ...
def key_names() -> list[str]: ...
def init(kind: str, file: Path | None = None) -> str: ...
