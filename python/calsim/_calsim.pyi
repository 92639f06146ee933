"""Stubs of the native module ``calsim._calsim``: each command returns a report (a dict typed
below, one per command) the pure-Python half turns into a result object (``_results.py``); the
frames a report holds come through the Arrow PyCapsule interface (:class:`ArrowFrame`)."""

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TypedDict

__version__: str

Callback = Callable[[str, str, int, int], object]

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

class RunReport(TypedDict):
    name: str
    kind: str
    seed: int
    threads: int
    dest: Path
    timing: str
    write_s: float
    recording_s: float
    realisations: int
    false_alarm: float
    judged: bool
    checked: int | None
    missed: int | None
    frames: dict[str, ArrowFrame]
    warnings: list[str]

class MergeReport(TypedDict):
    dest: Path
    units: int
    failed: int
    summary: str

class SweepReport(TypedDict):
    name: str
    units: int
    run_s: float
    shard_dir: Path
    shard: tuple[int, int]
    merged: MergeReport | None
    warnings: list[str]

class BudgetReport(TypedDict):
    dest: Path
    units: int
    run_s: float
    summary: str
    warnings: list[str]

class ExportReport(TypedDict):
    dest: Path
    scenario: str
    task: int
    set_size: int
    validation_median_mm: float
    files: list[str]

class CalibrateReport(TypedDict):
    dest: Path
    model: str
    report: str
    plan: ArrowFrame | None

class OptimiseReport(TypedDict):
    name: str
    restarts: int
    evaluations: int
    search_s: float
    finish_s: float
    dest: Path | None
    summary: str | None
    cost: str | None
    warnings: list[str]

class CompensateReport(TypedDict):
    table: ArrowFrame
    csv: str
    targets: int
    unreachable: list[int]
    warnings: list[str]

class Table8Report(TypedDict):
    table: ArrowFrame
    worlds: int
    run_s: float
    warnings: list[str]

class Prediction(TypedDict):
    p10_mm: float
    median_mm: float
    p90_mm: float
    worlds: int
    pilot_mm: float
    twin: bool

class PlanReport(TypedDict):
    instrument: str
    dest: Path
    poses: int
    validation: int
    pool: int
    drawn: int
    o1: float
    o1_random: float
    prediction: Prediction
    frames: dict[str, ArrowFrame]
    table: ArrowFrame
    tour: ArrowFrame
    simulated: ArrowFrame | None
    seconds: float
    warnings: list[str]
    unidentifiable: list[str]

class ImportReport(TypedDict):
    out: Path
    lines: list[str]

class SimulateReport(TypedDict):
    table: ArrowFrame
    csv: str
    rows: int
    written: Path | None

class FkReport(TypedDict):
    table: ArrowFrame
    csv: str
    rows: int

class KeysReport(TypedDict):
    table: ArrowFrame
    text: str

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
) -> RunReport: ...
def sweep(
    file: Path,
    *,
    out: Path,
    shard: tuple[int, int] | None = None,
    threads: int | None = None,
    realisations: int | None = None,
    progress: Callback | None = None,
) -> SweepReport: ...
def merge(shards: Sequence[Path], *, out: Path) -> MergeReport: ...
def budget(
    scenario: Path,
    *,
    out: Path,
    realisations: int = 20,
    factors: Sequence[float] = ...,
    repetitions: int | None = None,
    threads: int | None = None,
    progress: Callback | None = None,
) -> BudgetReport: ...
def export(
    results: Path,
    *,
    task: int | None = None,
    set_size: int | None = None,
    pick: str = "median",
    out: Path | None = None,
) -> ExportReport: ...
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
) -> CalibrateReport: ...
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
) -> OptimiseReport: ...
def compensate(model: Path, targets: Path, *, nominal: Path | None = None, out: Path | None = None) -> CompensateReport: ...
def table8(
    scenario: Path,
    *,
    realisations: int = 1,
    pool: int = 360,
    threads: int | None = None,
    progress: Callback | None = None,
) -> Table8Report: ...
def plan(
    file: Path,
    *,
    out: Path,
    threads: int | None = None,
    simulate: bool = False,
    progress: Callback | None = None,
) -> PlanReport:
    """``calsim plan`` of a tracker plan (``[tracker]``) or a device plan (``[instrument]``): the
    report's ``instrument`` is ``"tracker"`` or the device's kind (``"trical"``)."""
def import_urdf(urdf: Path, *, out: Path, package_root: Path | None = None, visual_meshes: bool = False) -> ImportReport: ...
def fk(robot: Path, joints: Path, *, out: Path | None = None) -> FkReport: ...
def simulate_measurements(spec: Path, *, out: Path | None = None) -> SimulateReport: ...
def keys(name: str) -> KeysReport: ...
def key_names() -> list[str]: ...
def init(kind: str, file: Path | None = None) -> str: ...
