//! `calsim._calsim`, the native half of the Python package: calsim's application layer
//! (`calsim::app`) called from Python, as the CLI calls it. Each command takes a scenario or sweep
//! path and keyword overrides, runs with the interpreter released (other Python threads go on, a
//! notebook stays responsive), reports progress to a Python callback from the worker threads, and
//! returns a dict the pure-Python half (`calsim/__init__.py`) turns into result objects whose
//! tables are polars DataFrames. Every `calsim::app::Error` becomes a Python exception of the
//! matching class carrying the file (`path`), the key (`key`) and the value where there is one.

use std::path::PathBuf;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use calsim::app::{self, Observer};
use calsim::calibrate::CalibrateError;
use calsim::design::budget::BudgetError as CoreBudgetError;
use calsim::design::sweep::{MergeError as CoreMergeError, SweepError as CoreSweepError};
use calsim::device::ScenarioError as CoreScenarioError;
use calsim::io::out_dir::OutDirError;
use calsim::io::table::Frame;
use calsim::robot::fk::JointsCsvError;
use polars::prelude::{ArrowDataType, ArrowField, CompatLevel};
use polars_arrow::array::{Array, StructArray};
use polars_arrow::ffi::{ArrowArrayStream, export_iterator};
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use pyo3::types::{PyCapsule, PyDict};

pyo3::create_exception!(
    calsim,
    CalsimError,
    PyException,
    "Every error calsim raises: `path` is the file, `key` the key (or line) and `value` the value at fault, where known."
);
pyo3::create_exception!(
    calsim,
    ScenarioError,
    CalsimError,
    "A scenario file is unusable: unreadable, malformed, an unknown key or a value out of its range."
);
pyo3::create_exception!(calsim, SweepError, CalsimError, "A sweep file is unusable, or one of its grid points is not a valid scenario.");
pyo3::create_exception!(calsim, MergeError, CalsimError, "Shard directories cannot be merged.");
pyo3::create_exception!(calsim, BudgetError, CalsimError, "A budget cannot run (no error source of the scenario is set).");
pyo3::create_exception!(calsim, RobotFileError, CalsimError, "A robot file or URDF is unusable.");
pyo3::create_exception!(
    calsim,
    InputError,
    CalsimError,
    "A value given to the command (a keyword, an output directory, a results directory) is unusable."
);
pyo3::create_exception!(calsim, StudyError, CalsimError, "A study could not run: its campaign failed, or no identification gave a model.");
pyo3::create_exception!(calsim, FileError, CalsimError, "A file could not be read or written.");
pyo3::create_exception!(
    calsim,
    DataError,
    CalsimError,
    "A data file (measurements, joint values, targets) is unusable: `path` the file, `key` the line and column, `value` the field."
);

/// What a Python exception carries beside its message.
#[derive(Default)]
struct Fault {
    path: Option<String>,
    key: Option<String>,
    value: Option<String>,
}

/// The exception of an application error: its class, its one-line message, and the file, key and
/// value it names.
fn to_py(py: Python<'_>, e: app::Error) -> PyErr {
    // The CLI's line: the same shortening of long words and numbers, controls escaped.
    let message = app::message::one_line(&e.to_string());
    let (err, fault) = match e {
        app::Error::Scenario(s) | app::Error::Budget(CoreBudgetError::Scenario(s)) => {
            (PyErr::new::<ScenarioError, _>(message), scenario_fault(&s))
        }
        app::Error::Sweep(s) | app::Error::Budget(CoreBudgetError::Sweep(s)) => (PyErr::new::<SweepError, _>(message), sweep_fault(&s)),
        app::Error::Budget(CoreBudgetError::NoSource(path)) => {
            (PyErr::new::<BudgetError, _>(message), Fault { path: Some(path), ..Fault::default() })
        }
        app::Error::Merge(CoreMergeError::Shard { path, .. } | CoreMergeError::Record { path, .. }) => {
            (PyErr::new::<MergeError, _>(message), Fault { path: Some(path), ..Fault::default() })
        }
        app::Error::Urdf(u) => (PyErr::new::<RobotFileError, _>(message), Fault { path: Some(u.path), ..Fault::default() }),
        app::Error::RobotFile(r) | app::Error::Calibrate(CalibrateError::Robot(r)) => {
            (PyErr::new::<RobotFileError, _>(message), robot_fault(&r))
        }
        app::Error::Joints(j) => (PyErr::new::<DataError, _>(message), joints_fault(&j)),
        app::Error::Calibrate(CalibrateError::Measurements(m)) => {
            let key = [m.line.map(|l| format!("line {l}")), m.column.clone()].into_iter().flatten().collect::<Vec<_>>().join(": ");
            let fault = Fault { path: Some(m.path.display().to_string()), key: (!key.is_empty()).then_some(key), value: None };
            (PyErr::new::<DataError, _>(message), fault)
        }
        app::Error::Calibrate(CalibrateError::Option { key, message: why }) => {
            let keyword = key.replace('-', "_");
            (
                PyErr::new::<InputError, _>(app::message::one_line(&format!("{keyword}: {why}"))),
                Fault { key: Some(keyword), ..Fault::default() },
            )
        }
        app::Error::Calibrate(CalibrateError::NoModel { path, model, .. }) => (
            PyErr::new::<StudyError, _>(message),
            Fault { path: Some(path.display().to_string()), key: Some(model.to_string()), ..Fault::default() },
        ),
        app::Error::Calibrate(CalibrateError::OutDir(OutDirError::InTheWay { path, .. })) => {
            (PyErr::new::<InputError, _>(message), Fault { path: Some(path), key: Some("out".into()), ..Fault::default() })
        }
        app::Error::Calibrate(CalibrateError::OutDir(OutDirError::Io { path, .. })) => {
            (PyErr::new::<FileError, _>(message), Fault { path: Some(path), ..Fault::default() })
        }
        app::Error::Calibrate(CalibrateError::Io { path, .. }) => {
            (PyErr::new::<FileError, _>(message), Fault { path: Some(path.display().to_string()), ..Fault::default() })
        }
        app::Error::Calibrate(CalibrateError::Name(n)) => {
            (PyErr::new::<InputError, _>(message), Fault { path: Some(n.file), ..Fault::default() })
        }
        app::Error::OutDir(OutDirError::Refused { flag, path, .. })
        | app::Error::Calibrate(CalibrateError::OutDir(OutDirError::Refused { flag, path, .. })) => {
            let keyword = flag.trim_start_matches('-').replace('-', "_");
            (PyErr::new::<InputError, _>(message), Fault { path: Some(path), key: Some(keyword), ..Fault::default() })
        }
        app::Error::OutDir(OutDirError::InTheWay { path, .. }) => {
            (PyErr::new::<InputError, _>(message), Fault { path: Some(path), key: Some("out".into()), ..Fault::default() })
        }
        app::Error::OutDir(OutDirError::Io { path, .. }) | app::Error::Io { path, .. } => {
            (PyErr::new::<FileError, _>(message), Fault { path: Some(path), ..Fault::default() })
        }
        app::Error::Device { path, .. } => (PyErr::new::<StudyError, _>(message), Fault { path: Some(path), ..Fault::default() }),
        app::Error::NoModel { scenario, .. } => {
            (PyErr::new::<StudyError, _>(message), Fault { path: Some(scenario), key: Some("study.parameters".into()), ..Fault::default() })
        }
        app::Error::Input { what, why } => input_fault(what, why, message),
        app::Error::Name(n) => (PyErr::new::<InputError, _>(message), Fault { path: Some(n.file), ..Fault::default() }),
    };
    let value = err.value(py);
    for (name, v) in [("path", fault.path.map(|p| file_of(&p))), ("key", fault.key), ("value", fault.value)] {
        // Setting an attribute on a fresh exception instance cannot fail but for memory.
        let _ = value.setattr(name, v);
    }
    err
}

/// The exception of an input error: an option (`--threads`) becomes the keyword (`threads`) in
/// the message and the key; `file: line 3` becomes the file and the key (the line).
fn input_fault(what: String, why: String, message: String) -> (PyErr, Fault) {
    if let Some(option) = what.strip_prefix("--") {
        let keyword = option.replace('-', "_");
        return (
            PyErr::new::<InputError, _>(app::message::one_line(&format!("{keyword}: {why}"))),
            Fault { key: Some(keyword), ..Fault::default() },
        );
    }
    let fault = match what.split_once(": ") {
        Some((file, key)) if std::path::Path::new(file).exists() => {
            Fault { path: Some(file.to_string()), key: Some(key.to_string()), ..Fault::default() }
        }
        _ => Fault { path: Some(what), ..Fault::default() },
    };
    (PyErr::new::<InputError, _>(message), fault)
}

/// The file and field of a robot file's error.
fn robot_fault(e: &calsim::robot::file::RobotFileError) -> Fault {
    Fault { path: Some(e.path.display().to_string()), key: Some(e.field.clone()), value: None }
}

/// The file, line (and column) and value of a joints file's error.
fn joints_fault(e: &JointsCsvError) -> Fault {
    let path = |p: &std::path::Path| Some(p.display().to_string());
    match e {
        JointsCsvError::File { path: p, .. } | JointsCsvError::Rows { path: p, .. } => Fault { path: path(p), ..Fault::default() },
        JointsCsvError::Header { path: p, found } => Fault { path: path(p), key: Some("line 1".into()), value: Some(found.clone()) },
        JointsCsvError::Fields { path: p, line, .. } => Fault { path: path(p), key: Some(format!("line {line}")), value: None },
        JointsCsvError::Value { path: p, line, name, value, .. } => {
            Fault { path: path(p), key: Some(format!("line {line}: {name}")), value: Some(value.clone()) }
        }
    }
}

/// The file a path of an error names, without a note the message adds to it (" (with
/// command-line overrides)").
fn file_of(shown: &str) -> String {
    match shown.rsplit_once(" (") {
        Some((file, note)) if note.ends_with(')') && std::path::Path::new(file).exists() => file.to_string(),
        _ => shown.to_string(),
    }
}

/// The file, dotted key and value of a scenario error.
fn scenario_fault(e: &CoreScenarioError) -> Fault {
    match e {
        CoreScenarioError::Read { path, .. } => Fault { path: Some(path.clone()), ..Fault::default() },
        CoreScenarioError::Parse { path, key, .. } => Fault { path: Some(path.clone()), key: Some(key.clone()), value: None },
        CoreScenarioError::Range { path, section, key, value, .. } => Fault {
            path: Some(path.clone()),
            key: Some(if section.is_empty() { key.clone() } else { format!("{section}.{key}") }),
            value: Some(value.clone()),
        },
        CoreScenarioError::Name(n) => Fault { path: Some(n.file.clone()), ..Fault::default() },
    }
}

/// The file and key of a sweep error (a grid point's: the scenario key at fault).
fn sweep_fault(e: &CoreSweepError) -> Fault {
    match e {
        CoreSweepError::File { path, key, .. } => Fault { path: Some(path.clone()), key: Some(key.clone()), value: None },
        CoreSweepError::Point { path, error, .. } => Fault { path: Some(path.clone()), ..scenario_fault(error) },
    }
}

/// An input error naming the keyword (its `key`).
fn input(py: Python<'_>, keyword: &str, why: impl Into<String>) -> PyErr {
    let err = PyErr::new::<InputError, _>(format!("{keyword}: {}", why.into()));
    let value = err.value(py);
    for (name, v) in [("path", None), ("key", Some(keyword)), ("value", None)] {
        let _ = value.setattr(name, v);
    }
    err
}

/// Shortest time between two progress calls into Python of one stage: the bar moves smoothly and
/// the workers rarely wait for the interpreter.
const PROGRESS_EVERY: Duration = Duration::from_millis(100);

/// An observer that calls a Python callable `callback(event, text, done, total)` with `event` one
/// of `started`, `progress`, `stage_done`, `warning`; progress is thinned to one call per
/// [`PROGRESS_EVERY`] (and the last of a stage). It keeps the warnings for the result, and the
/// first exception the callback raised (the callback is not called again after it).
struct PyObserver {
    callback: Option<Py<PyAny>>,
    throttle: Mutex<Throttle>,
    warnings: Mutex<Vec<String>>,
    error: Mutex<Option<PyErr>>,
}

#[derive(Default)]
struct Throttle {
    last: Option<Instant>,
    what: String,
    done: usize,
}

impl PyObserver {
    fn new(callback: Option<Py<PyAny>>) -> Self {
        Self { callback, throttle: Mutex::default(), warnings: Mutex::default(), error: Mutex::default() }
    }

    fn call(&self, event: &str, text: &str, done: usize, total: usize) {
        let Some(callback) = &self.callback else { return };
        if lock(&self.error).is_some() {
            return;
        }
        Python::attach(|py| {
            if let Err(e) = callback.call1(py, (event, text, done, total)) {
                lock(&self.error).get_or_insert(e);
            }
        });
    }

    /// The warnings, and the callback's exception if it raised one.
    fn finish(self) -> (Vec<String>, Option<PyErr>) {
        let warnings = self.warnings.into_inner().unwrap_or_else(|e| e.into_inner());
        (warnings, self.error.into_inner().unwrap_or_else(|e| e.into_inner()))
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

impl Observer for PyObserver {
    fn started(&self, line: &str) {
        self.call("started", line, 0, 0);
    }

    fn progress(&self, done: usize, total: usize, what: &str) {
        {
            let now = Instant::now();
            let mut t = lock(&self.throttle);
            let new_stage = t.what != what;
            // Workers finish out of order: a smaller count than one already shown is skipped.
            let due = new_stage || (done > t.done && (done == total || t.last.is_none_or(|l| now - l >= PROGRESS_EVERY)));
            if !due {
                return;
            }
            *t = Throttle { last: Some(now), what: what.to_string(), done };
        }
        self.call("progress", what, done, total);
    }

    fn stage_done(&self) {
        *lock(&self.throttle) = Throttle::default();
        self.call("stage_done", "", 0, 0);
    }

    fn warning(&self, line: &str) {
        lock(&self.warnings).push(line.to_string());
        self.call("warning", line, 0, 0);
    }
}

/// Runs `f` with the interpreter released and `progress` as its observer; the application error
/// becomes its exception, an exception of the callback is raised after the command.
fn detached<T: Send>(
    py: Python<'_>,
    progress: Option<Py<PyAny>>,
    f: impl FnOnce(&dyn Observer) -> Result<T, app::Error> + Send,
) -> PyResult<(T, Vec<String>)> {
    let observer = PyObserver::new(progress);
    let result = py.detach(|| f(&observer));
    let (warnings, callback_error) = observer.finish();
    let value = result.map_err(|e| to_py(py, e))?;
    match callback_error {
        Some(e) => Err(e),
        None => Ok((value, warnings)),
    }
}

/// Runs (or checks) the study of a scenario of any device: `calsim run` / `calsim check`.
#[pyfunction]
#[pyo3(signature = (scenario, *, out, check, seed=None, set_sizes=None, repetitions=None, threads=None, realisations=None, false_alarm=None, plots=true, recording=true, progress=None))]
#[allow(clippy::too_many_arguments)]
fn run<'py>(
    py: Python<'py>,
    scenario: PathBuf,
    out: PathBuf,
    check: bool,
    seed: Option<u64>,
    set_sizes: Option<Vec<u32>>,
    repetitions: Option<u32>,
    threads: Option<u32>,
    realisations: Option<u32>,
    false_alarm: Option<f64>,
    plots: bool,
    recording: bool,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    if let Some(sizes) = &set_sizes
        && sizes.is_empty()
    {
        return Err(input(py, "set_sizes", "[]: needs at least one set size"));
    }
    let spec = app::run::RunSpec {
        scenario,
        out,
        threads,
        overrides: app::run::Overrides { seed, set_sizes, repetitions },
        plots,
        recording,
        realisations,
        false_alarm,
        junit: None,
        check,
    };
    let (r, warnings) = detached(py, progress, |o| app::run::run(&spec, o))?;
    let d = PyDict::new(py);
    d.set_item("name", &r.name)?;
    d.set_item("kind", r.kind)?;
    d.set_item("seed", r.seed)?;
    d.set_item("threads", r.threads)?;
    d.set_item("dest", &r.dest)?;
    d.set_item("timing", &r.timing)?;
    d.set_item("write_s", r.write_s)?;
    d.set_item("recording_s", r.recording_s)?;
    d.set_item("realisations", r.realisations_run)?;
    d.set_item("false_alarm", r.false_alarm)?;
    // As the CLI: a check judges its figures, over one world or several; a run shows one world's
    // figures as draws (no verdict), and judges them only over realisations.
    let judged = check || r.distribution.is_some();
    let (checked, missed) = r.tally();
    d.set_item("judged", judged)?;
    d.set_item("checked", judged.then_some(checked))?;
    d.set_item("missed", judged.then_some(missed))?;
    d.set_item("frames", frames(py, r.frames)?)?;
    d.set_item("warnings", warnings)?;
    Ok(d)
}

/// Result frames by name, each an [`ArrowFrame`] (read on the Python side with
/// `polars.DataFrame(frame)`: the schema travels with the values, no column is named here).
fn frames(py: Python<'_>, frames: Vec<(String, Frame)>) -> PyResult<Bound<'_, PyDict>> {
    let d = PyDict::new(py);
    for (name, frame) in frames {
        d.set_item(name, ArrowFrame(frame))?;
    }
    Ok(d)
}

/// A result frame handed to Python through the Arrow PyCapsule interface: `__arrow_c_stream__`
/// exports its record batches over the Arrow C stream interface, sharing the frame's buffers (no
/// value is copied or converted; polars' own Arrow types, string views included).
#[pyclass(frozen, module = "calsim._calsim")]
struct ArrowFrame(Frame);

#[pymethods]
impl ArrowFrame {
    /// The frame as an `arrow_array_stream` capsule of struct arrays, one per record batch.
    /// `requested_schema` is not honoured (the interface lets a producer export its own schema).
    #[pyo3(signature = (requested_schema=None))]
    fn __arrow_c_stream__<'py>(&self, py: Python<'py>, requested_schema: Option<Bound<'py, PyAny>>) -> PyResult<Bound<'py, PyCapsule>> {
        let _ = requested_schema;
        PyCapsule::new_with_value(py, arrow_stream(&self.0), c"arrow_array_stream")
    }

    /// Rows and columns, as polars gives them.
    #[getter]
    fn shape(&self) -> (usize, usize) {
        self.0.shape()
    }
}

/// The Arrow C stream of `frame`: its record batches as struct arrays of polars' newest Arrow
/// types, the columns' buffers shared (the capsule's consumer releases them).
fn arrow_stream(frame: &Frame) -> ArrowArrayStream {
    let level = CompatLevel::newest();
    let mut frame = frame.clone();
    frame.rechunk_mut();
    let fields: Vec<ArrowField> = frame.columns().iter().map(|c| c.field().to_arrow(level)).collect();
    let dtype = ArrowDataType::Struct(fields);
    let batches: Vec<Box<dyn Array>> = frame
        .iter_chunks(level, false)
        .map(|batch| Box::new(StructArray::new(dtype.clone(), batch.height(), batch.into_arrays(), None)) as Box<dyn Array>)
        .collect();
    export_iterator(Box::new(batches.into_iter().map(Ok)), ArrowField::new("".into(), dtype, false))
}

/// The merge report as a dict.
fn merge_dict<'py>(py: Python<'py>, m: &app::sweep::MergeReport) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("dest", &m.dest)?;
    d.set_item("units", m.units)?;
    d.set_item("failed", m.failed)?;
    d.set_item("summary", &m.summary)?;
    Ok(d)
}

/// Runs a design sweep, whole (then merged) or one shard of it: `calsim sweep`.
#[pyfunction]
#[pyo3(signature = (file, *, out, shard=None, threads=None, realisations=None, progress=None))]
fn sweep<'py>(
    py: Python<'py>,
    file: PathBuf,
    out: PathBuf,
    shard: Option<(usize, usize)>,
    threads: Option<u32>,
    realisations: Option<u32>,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let spec = app::sweep::SweepSpec { file, out, shard, threads, realisations };
    let (r, warnings) = detached(py, progress, |o| app::sweep::run(&spec, o))?;
    let d = PyDict::new(py);
    d.set_item("name", &r.name)?;
    d.set_item("units", r.units)?;
    d.set_item("run_s", r.run_s)?;
    d.set_item("shard_dir", &r.shard_dir)?;
    d.set_item("shard", r.shard)?;
    match &r.merged {
        Some(m) => d.set_item("merged", merge_dict(py, m)?)?,
        None => d.set_item("merged", py.None())?,
    }
    d.set_item("warnings", warnings)?;
    Ok(d)
}

/// Merges the shard directories of one sweep: `calsim merge`.
#[pyfunction]
#[pyo3(signature = (shards, *, out))]
fn merge<'py>(py: Python<'py>, shards: Vec<PathBuf>, out: PathBuf) -> PyResult<Bound<'py, PyDict>> {
    if shards.is_empty() {
        return Err(input(py, "shards", "[]: at least one shard directory"));
    }
    let (m, _) = detached(py, None, |_| app::sweep::merge(&shards, &out))?;
    merge_dict(py, &m)
}

/// Runs the uncertainty budget of a scenario: `calsim budget`.
#[pyfunction]
#[pyo3(signature = (scenario, *, out, realisations=20, factors=vec![0.5, 2.0], repetitions=None, threads=None, progress=None))]
#[allow(clippy::too_many_arguments)]
fn budget<'py>(
    py: Python<'py>,
    scenario: PathBuf,
    out: PathBuf,
    realisations: u32,
    factors: Vec<f64>,
    repetitions: Option<u32>,
    threads: Option<u32>,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let spec = app::budget::BudgetSpec { scenario, out, realisations, factors, repetitions, threads };
    let (r, warnings) = detached(py, progress, |o| app::budget::run(&spec, o))?;
    let d = PyDict::new(py);
    d.set_item("dest", &r.dest)?;
    d.set_item("units", r.units)?;
    d.set_item("run_s", r.run_s)?;
    d.set_item("summary", &r.summary)?;
    d.set_item("warnings", warnings)?;
    Ok(d)
}

/// Exports one identification of a TriCal results directory as a robot file, a URDF and a YAML
/// overlay: `calsim export`.
#[pyfunction]
#[pyo3(signature = (results, *, task=None, set_size=None, pick="median", out=None))]
fn export<'py>(
    py: Python<'py>,
    results: PathBuf,
    task: Option<usize>,
    set_size: Option<usize>,
    pick: &str,
    out: Option<PathBuf>,
) -> PyResult<Bound<'py, PyDict>> {
    use app::export::Pick;
    let pick = match (task, pick) {
        (Some(_), _) if set_size.is_some() => {
            return Err(input(py, "task", "task and set_size exclude each other: a task has its set size"));
        }
        (Some(t), _) => Pick::Task(t),
        (None, "median") => Pick::Median(set_size),
        (None, "best") => Pick::Best(set_size),
        (None, "worst") => Pick::Worst(set_size),
        (None, other) => return Err(input(py, "pick", format!("{other:?}: one of \"median\", \"best\", \"worst\""))),
    };
    let ((e, dest), _) = detached(py, None, |_| app::export::run(&results, pick, out.as_deref()))?;
    let d = PyDict::new(py);
    d.set_item("dest", &dest)?;
    d.set_item("scenario", &e.scenario)?;
    d.set_item("task", e.task)?;
    d.set_item("set_size", e.set_size)?;
    d.set_item("validation_median_mm", e.validation_median_mm)?;
    d.set_item("files", ["robot.toml", "before.toml", "robot.urdf", "calibration.yaml"])?;
    Ok(d)
}

/// Calibrates a real robot from a measurement file: `calsim calibrate`.
#[pyfunction]
#[pyo3(signature = (robot, measurements, *, out, folds=5, hold_out=None, hold_out_session=None, hold_out_file=None, seed=1, params=None, outlier_threshold=None, outliers=None, plan_worlds=0, plan_noise_mm=None, plan_scenario=None, plots=true, kfold_by=None, tool_per_session=false, payload_kg=None, payload_com_mm=None, plan_with=None, instrument_noise_mm=None))]
#[allow(clippy::too_many_arguments)]
fn calibrate<'py>(
    py: Python<'py>,
    robot: PathBuf,
    measurements: PathBuf,
    out: PathBuf,
    folds: u32,
    hold_out: Option<f64>,
    hold_out_session: Option<String>,
    hold_out_file: Option<PathBuf>,
    seed: u64,
    params: Option<Vec<String>>,
    outlier_threshold: Option<f64>,
    outliers: Option<String>,
    plan_worlds: u32,
    plan_noise_mm: Option<f64>,
    plan_scenario: Option<PathBuf>,
    plots: bool,
    kfold_by: Option<String>,
    tool_per_session: bool,
    payload_kg: Option<f64>,
    payload_com_mm: Option<Vec<f64>>,
    plan_with: Option<String>,
    instrument_noise_mm: Option<f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let args = app::calibrate::CalibrateArgs {
        plan_with,
        instrument_noise_mm,
        kfold_by,
        tool_per_session,
        payload_kg,
        payload_com_mm,
        folds,
        hold_out,
        hold_out_session,
        hold_out_file,
        seed,
        params,
        outlier_threshold,
        outliers,
        plan_worlds,
        plan_noise_mm,
        plan_scenario,
        plots,
        ..app::calibrate::CalibrateArgs::new(robot, measurements, out)
    };
    let (r, _) = detached(py, None, |_| app::calibrate::run(&args))?;
    let c = &r.calibration;
    let d = PyDict::new(py);
    d.set_item("dest", &r.dir)?;
    d.set_item("model", c.models[c.chosen].kind.map_or("before", |k| k.name()))?;
    d.set_item("report", calsim::calibrate::report::terminal(c, &r.dir))?;
    d.set_item("plan", r.plan_table.map(ArrowFrame))?;
    Ok(d)
}

/// Searches a design file's space, races and verifies the finalists: `calsim optimise`.
#[pyfunction]
#[pyo3(signature = (file, *, out, shard=None, merge=false, threads=None, method=None, plots=true, progress=None))]
#[allow(clippy::too_many_arguments)]
fn optimise<'py>(
    py: Python<'py>,
    file: PathBuf,
    out: PathBuf,
    shard: Option<(usize, usize)>,
    merge: bool,
    threads: Option<u32>,
    method: Option<String>,
    plots: bool,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    use calsim::design::optimise::spec::Method;
    let method = match method.as_deref() {
        None => None,
        Some("nelder_mead") => Some(Method::NelderMead),
        Some("particle_swarm") => Some(Method::ParticleSwarm),
        Some("cmaes") => Some(Method::Cmaes),
        Some(other) => return Err(input(py, "method", format!("{other:?}: \"nelder_mead\", \"particle_swarm\" or \"cmaes\""))),
    };
    let spec = app::optimise::OptimiseSpec { file, out, shard, merge, threads, method, plots };
    let (r, warnings) = detached(py, progress, |o| app::optimise::run(&spec, o))?;
    let d = PyDict::new(py);
    d.set_item("name", &r.name)?;
    d.set_item("restarts", r.restarts)?;
    d.set_item("evaluations", r.evaluations)?;
    d.set_item("search_s", r.search_s)?;
    d.set_item("finish_s", r.finish_s)?;
    d.set_item("dest", &r.dest)?;
    d.set_item("summary", &r.summary)?;
    d.set_item("cost", &r.cost)?;
    d.set_item("warnings", warnings)?;
    Ok(d)
}

/// The joint targets (and corrected Cartesian targets) of TCP targets: `calsim compensate`.
#[pyfunction]
#[pyo3(signature = (model, targets, *, nominal=None, out=None))]
fn compensate<'py>(
    py: Python<'py>,
    model: PathBuf,
    targets: PathBuf,
    nominal: Option<PathBuf>,
    out: Option<PathBuf>,
) -> PyResult<Bound<'py, PyDict>> {
    let spec = app::compensate::CompensateSpec { model, targets, nominal, out };
    let (r, _) = detached(py, None, |_| app::compensate::run(&spec))?;
    let d = PyDict::new(py);
    d.set_item("csv", &r.csv)?;
    d.set_item("targets", r.targets)?;
    d.set_item("unreachable", &r.unreachable)?;
    d.set_item("warnings", r.unreachable_line().into_iter().collect::<Vec<_>>())?;
    d.set_item("table", ArrowFrame(r.table))?;
    Ok(d)
}

/// Table 8 of the TriCal paper over realisations: `calsim table8`.
#[pyfunction]
#[pyo3(signature = (scenario, *, realisations=1, pool=360, threads=None, progress=None))]
fn table8<'py>(
    py: Python<'py>,
    scenario: PathBuf,
    realisations: u32,
    pool: u32,
    threads: Option<u32>,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let spec = app::table8::Table8Spec { scenario, realisations, pool, threads };
    let (r, warnings) = detached(py, progress, |o| app::table8::run(&spec, o))?;
    let d = PyDict::new(py);
    d.set_item("table", ArrowFrame(r.table))?;
    d.set_item("worlds", r.worlds)?;
    d.set_item("run_s", r.run_s)?;
    d.set_item("warnings", warnings)?;
    Ok(d)
}

/// The poses to measure on a real robot and the accuracy they buy: `calsim plan`.
#[pyfunction]
#[pyo3(signature = (file, *, out, threads=None, simulate=false, progress=None))]
fn plan<'py>(
    py: Python<'py>,
    file: PathBuf,
    out: PathBuf,
    threads: Option<u32>,
    simulate: bool,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let spec = app::plan::PlanSpec { file, out, threads, simulate, recording: true };
    if app::plan::is_device_plan(&spec.file).map_err(|e| to_py(py, e))? {
        return plan_device(py, &spec, progress);
    }
    let (r, warnings) = detached(py, progress, |o| app::plan::plan(&spec, o))?;
    let (o, p) = (&r.outcome, &r.outcome.prediction);
    let shared = PlanShared {
        instrument: "tracker",
        dest: &r.dir,
        poses: o.poses,
        validation: r.plan.validation,
        pool: o.pool.qs.len(),
        drawn: o.pool.tried,
        o1: o.o1,
        quantiles_mm: p.quantiles_mm,
        worlds: p.worlds,
        pilot_mm: p.pilot_median_mm,
        twin: p.twin,
        seconds: r.seconds,
    };
    let d = shared.dict(py, r.frames, r.files, warnings)?;
    d.set_item("unidentifiable", p.unidentifiable.iter().map(|u| u.name.clone()).collect::<Vec<_>>())?;
    Ok(d)
}

/// What the report of a tracker plan and of a device plan share.
struct PlanShared<'a> {
    instrument: &'a str,
    dest: &'a std::path::Path,
    poses: usize,
    validation: usize,
    pool: usize,
    drawn: usize,
    o1: (f64, f64),
    quantiles_mm: [f64; 3],
    worlds: usize,
    pilot_mm: f64,
    twin: bool,
    seconds: f64,
}

impl PlanShared<'_> {
    /// The plan's report with these keys, its tables (`frames`: `plan`, `search`, `comparison`
    /// ..., the tables written, by stem), the tables of its files (`table`: `poses.csv`, `tour`,
    /// `simulated` or None) and `warnings`.
    fn dict<'py>(
        &self,
        py: Python<'py>,
        tables: Vec<(String, Frame)>,
        files: app::plan::PlanFiles,
        warnings: Vec<String>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        d.set_item("instrument", self.instrument)?;
        d.set_item("dest", self.dest)?;
        d.set_item("poses", self.poses)?;
        d.set_item("validation", self.validation)?;
        d.set_item("pool", self.pool)?;
        d.set_item("drawn", self.drawn)?;
        d.set_item("o1", self.o1.0)?;
        d.set_item("o1_random", self.o1.1)?;
        let prediction = PyDict::new(py);
        for (name, value) in [("p10_mm", self.quantiles_mm[0]), ("median_mm", self.quantiles_mm[1]), ("p90_mm", self.quantiles_mm[2])] {
            prediction.set_item(name, value)?;
        }
        prediction.set_item("worlds", self.worlds)?;
        prediction.set_item("pilot_mm", self.pilot_mm)?;
        prediction.set_item("twin", self.twin)?;
        d.set_item("prediction", prediction)?;
        d.set_item("frames", frames(py, by_stem(tables))?)?;
        d.set_item("table", ArrowFrame(files.poses))?;
        d.set_item("tour", ArrowFrame(files.tour))?;
        d.set_item("simulated", files.simulated.map(ArrowFrame))?;
        d.set_item("seconds", self.seconds)?;
        d.set_item("warnings", warnings)?;
        Ok(d)
    }
}

/// Tables named by file (`plan.parquet`) named by stem (`plan`), as Python's results name them.
fn by_stem(tables: Vec<(String, Frame)>) -> Vec<(String, Frame)> {
    tables.into_iter().map(|(name, frame)| (name.strip_suffix(".parquet").map_or_else(|| name.clone(), str::to_string), frame)).collect()
}

/// `calsim plan` of a device plan (`[instrument]`): the tracker plan's report, the device's
/// figures in its keys.
fn plan_device<'py>(py: Python<'py>, spec: &app::plan::PlanSpec, progress: Option<Py<PyAny>>) -> PyResult<Bound<'py, PyDict>> {
    let (r, warnings) = detached(py, progress, |o| app::plan::plan_device(spec, o))?;
    let (o, p) = (&r.outcome, &r.outcome.prediction);
    let shared = PlanShared {
        instrument: r.plan.kind,
        dest: &r.dir,
        poses: o.poses,
        validation: r.plan.validation,
        pool: o.candidates - o.refused[0] - o.refused[1],
        drawn: o.candidates,
        o1: o.o1,
        quantiles_mm: p.quantiles_mm,
        worlds: p.worlds,
        pilot_mm: p.pilot_median_mm,
        twin: false,
        seconds: r.seconds,
    };
    let d = shared.dict(py, r.frames, r.files, warnings)?;
    d.set_item("unidentifiable", p.unidentifiable.clone())?;
    Ok(d)
}

/// A URDF arm as a calsim robot file: `calsim import-urdf`.
#[pyfunction]
#[pyo3(signature = (urdf, *, out, package_root=None, visual_meshes=false))]
fn import_urdf<'py>(
    py: Python<'py>,
    urdf: PathBuf,
    out: PathBuf,
    package_root: Option<PathBuf>,
    visual_meshes: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let options = app::import_urdf::ImportOptions { package_root, visual_fallback: visual_meshes };
    let (r, _) = detached(py, None, |_| app::import_urdf::run(&urdf, &out, &options))?;
    let d = PyDict::new(py);
    d.set_item("out", &r.out)?;
    d.set_item("lines", &r.lines)?;
    Ok(d)
}

/// A measurement file for `calibrate` simulated from a simulation file: `calsim
/// simulate-measurements` (with `out`, also written to `<out>/<spec stem>.csv`).
#[pyfunction]
#[pyo3(signature = (spec, *, out=None))]
fn simulate_measurements<'py>(py: Python<'py>, spec: PathBuf, out: Option<PathBuf>) -> PyResult<Bound<'py, PyDict>> {
    let (r, _) = detached(py, None, |_| app::simulate::run(&spec, out.as_deref()))?;
    let d = PyDict::new(py);
    d.set_item("table", ArrowFrame(r.table))?;
    d.set_item("csv", &r.csv)?;
    d.set_item("rows", r.rows)?;
    d.set_item("written", &r.written)?;
    Ok(d)
}

/// The tool frame, gravity torques and deflections at joint values: `calsim fk`.
#[pyfunction]
#[pyo3(signature = (robot, joints, *, out=None))]
fn fk<'py>(py: Python<'py>, robot: PathBuf, joints: PathBuf, out: Option<PathBuf>) -> PyResult<Bound<'py, PyDict>> {
    let spec = app::fk::FkSpec { robot, joints, out };
    let (r, _) = detached(py, None, |_| app::fk::run(&spec))?;
    let d = PyDict::new(py);
    d.set_item("table", ArrowFrame(r.table))?;
    d.set_item("csv", &r.csv)?;
    d.set_item("rows", r.rows)?;
    Ok(d)
}

/// The reference of every key of a scenario (a device's kind), sweep or robot file: `calsim keys`.
/// Its table (a row per key: the key, its unit, default, rules and note) and the CLI's text of it.
#[pyfunction]
#[pyo3(signature = (name))]
fn keys<'py>(py: Python<'py>, name: &str) -> PyResult<Bound<'py, PyDict>> {
    let name = name.to_string();
    let ((table, text), _) = detached(py, None, |_| {
        let table = app::keys::table(&name)?;
        let text = app::keys::text_of(&name, &table)?;
        Ok((table, text))
    })?;
    let d = PyDict::new(py);
    d.set_item("table", ArrowFrame(table))?;
    d.set_item("text", text)?;
    Ok(d)
}

/// The names `keys` takes: the devices' kinds, `sweep` and `robot`.
#[pyfunction]
fn key_names() -> Vec<&'static str> {
    app::keys::names()
}

/// A commented starting scenario of a device, every key at its default, also written to `file`
/// when given (never replacing one): `calsim init`.
#[pyfunction]
#[pyo3(signature = (kind, file=None))]
fn init(py: Python<'_>, kind: &str, file: Option<PathBuf>) -> PyResult<String> {
    let kind = kind.to_string();
    let (text, _) = detached(py, None, |_| app::keys::init_file(&kind, file.as_deref()))?;
    Ok(text)
}

/// The native module.
#[pymodule]
fn _calsim(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("__version__", calsim_version())?;
    m.add("CalsimError", py.get_type::<CalsimError>())?;
    m.add("ScenarioError", py.get_type::<ScenarioError>())?;
    m.add("SweepError", py.get_type::<SweepError>())?;
    m.add("MergeError", py.get_type::<MergeError>())?;
    m.add("BudgetError", py.get_type::<BudgetError>())?;
    m.add("RobotFileError", py.get_type::<RobotFileError>())?;
    m.add("InputError", py.get_type::<InputError>())?;
    m.add("StudyError", py.get_type::<StudyError>())?;
    m.add("FileError", py.get_type::<FileError>())?;
    m.add("DataError", py.get_type::<DataError>())?;
    m.add_class::<ArrowFrame>()?;
    m.add_function(wrap_pyfunction!(run, m)?)?;
    m.add_function(wrap_pyfunction!(sweep, m)?)?;
    m.add_function(wrap_pyfunction!(merge, m)?)?;
    m.add_function(wrap_pyfunction!(budget, m)?)?;
    m.add_function(wrap_pyfunction!(export, m)?)?;
    m.add_function(wrap_pyfunction!(calibrate, m)?)?;
    m.add_function(wrap_pyfunction!(plan, m)?)?;
    m.add_function(wrap_pyfunction!(optimise, m)?)?;
    m.add_function(wrap_pyfunction!(compensate, m)?)?;
    m.add_function(wrap_pyfunction!(table8, m)?)?;
    m.add_function(wrap_pyfunction!(import_urdf, m)?)?;
    m.add_function(wrap_pyfunction!(fk, m)?)?;
    m.add_function(wrap_pyfunction!(simulate_measurements, m)?)?;
    m.add_function(wrap_pyfunction!(keys, m)?)?;
    m.add_function(wrap_pyfunction!(key_names, m)?)?;
    m.add_function(wrap_pyfunction!(init, m)?)?;
    Ok(())
}

/// The version of the calsim crate this module was built from.
fn calsim_version() -> &'static str {
    env!("CARGO_PKG_VERSION")
}
