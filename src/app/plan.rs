//! `calsim plan`: reads a plan file, plans on the worker pool, writes `<out>/<plan stem>.plan/`
//! (`poses.csv`, `joints.txt`, `tour.csv`, the tables (`plan.parquet` ..., see
//! [`crate::plan::summary`]) and `plan.md` rendered from them, the figure `plan_poses.png`/`.svg`,
//! the Rerun recording `plan.rrd`, and `simulated.csv` with `--simulate`).

use std::path::{Path, PathBuf};

use super::{Error, Observer};
use crate::io::table::Frame;
use crate::plan::{Outcome, Plan};

/// What `calsim plan` is asked.
#[derive(Clone, Debug)]
pub struct PlanSpec {
    /// The plan file.
    pub file: PathBuf,
    /// The directory the plan goes in (`<out>/<plan stem>.plan`).
    pub out: PathBuf,
    /// Worker threads (`None`: `RAYON_NUM_THREADS`, else every core).
    pub threads: Option<u32>,
    /// Also write `simulated.csv`: the poses measured on the robot file's truth with the tracker's noise.
    pub simulate: bool,
    /// Also write the Rerun recording `plan.rrd`.
    pub recording: bool,
}

/// What `calsim plan` returns.
#[derive(Debug)]
pub struct PlanReport {
    /// The checked plan.
    pub plan: Plan,
    /// What it computed.
    pub outcome: Outcome,
    /// The directory written.
    pub dir: PathBuf,
    /// Wall-clock seconds of the planning (pool, DETMAX, tour) and of the prediction together.
    pub seconds: f64,
    /// The tables written, by file name (`plan.parquet` ..., [`crate::plan::summary`]).
    pub frames: Vec<(String, Frame)>,
    /// The tables of `poses.csv`, `tour.csv` and `simulated.csv`.
    pub files: PlanFiles,
}

/// The tables of a plan's files, each as its CSV states it.
#[derive(Clone, Debug)]
pub struct PlanFiles {
    /// `poses.csv`: the measurement file to fill ([`crate::plan::files::measurement_file`]).
    pub poses: Frame,
    /// `tour.csv`: the order to visit the poses in ([`crate::plan::files::tour_file`]).
    pub tour: Frame,
    /// `simulated.csv` (`--simulate`): the measurement file filled in a simulated world.
    pub simulated: Option<Frame>,
}

/// Reads and checks a plan file.
pub fn load(file: &Path) -> Result<Plan, Error> {
    let text = crate::io::read_text(file).map_err(|e| Error::input(file.display().to_string(), e.to_string()))?;
    if crate::plan::device::is_device_plan(&text) {
        return Err(Error::input(
            format!("{}: instrument", file.display()),
            "a device plan ([instrument]): `calsim plan` runs it through plan_device, not as a tracker plan".to_string(),
        ));
    }
    crate::plan::parse(file, &text).map_err(|e| Error::input(format!("{}: {}", e.path, e.key), e.message))
}

/// `calsim plan`.
pub fn plan(spec: &PlanSpec, observer: &dyn Observer) -> Result<PlanReport, Error> {
    let _inputs = crate::io::inputs::Ledger::open();
    let plan = load(&spec.file)?;
    let name = format!("{}.plan", crate::io::names::of_file(&spec.file)?);
    crate::io::out_dir::prepare(&spec.out, &name)?;
    let (pool, threads) = super::thread_pool(spec.threads)?;
    let poses = match &plan.objective {
        None => format!("{}", plan.poses),
        Some(o) => format!("{} to {} (by objective)", o.fewest_poses, o.most_poses),
    };
    observer.started(&format!(
        "calsim plan: {} ({poses} poses from a pool of {}, {} validation, {} worlds), {}",
        spec.file.display(),
        plan.pool,
        plan.validation,
        plan.worlds,
        super::threads_label(threads)
    ));
    let t0 = std::time::Instant::now();
    let outcome = pool.install(|| crate::plan::run(&plan)).map_err(|e| Error::input(format!("{}: {}", e.path, e.key), e.message))?;
    let cell = crate::plan::cell::Cell::new(&plan).map_err(|e| Error::input(format!("{}: {}", e.path, e.key), e.message))?;
    let simulated = if spec.simulate { Some(simulated_file(&plan, &cell, &outcome, &spec.out)?) } else { None };
    let seconds = t0.elapsed().as_secs_f64();
    // plan.md is rendered from the tables the directory stores.
    let tables = crate::plan::summary::tables(&plan, &outcome);
    let poses = crate::plan::measurement_file(&plan, &outcome.rows, None, &[]).map_err(Error::io(&spec.out))?;
    let tour = crate::plan::tour_file(&plan, &outcome).map_err(Error::io(&spec.out))?;
    let files = [
        ("poses.csv", poses.1),
        ("joints.txt", crate::plan::joint_list(&plan, &outcome.rows)),
        ("tour.csv", tour.1),
        ("plan.md", crate::plan::summary::markdown(&tables).map_err(Error::io(&spec.out))?),
    ];
    let (simulated, simulated_text) = simulated.unzip();
    let frames;
    let dir = {
        let mut r = crate::io::results::Results::new(&name, crate::io::results::Head::Run(crate::io::manifest::Provenance::of_run(&[])));
        let io = |e: std::io::Error| Error::io(&spec.out)(e);
        r.field("plan", &name).map_err(io)?.field("simulate", spec.simulate).map_err(io)?.field("recording", spec.recording).map_err(io)?;
        frames = add_files(&mut r, tables, files, simulated_text).map_err(io)?;
        // plan.md shows the figure itself.
        r.draw(Box::new(|d| crate::plan::plot::write(d, &plan, &cell, &outcome).map(|()| Vec::new())));
        if spec.recording {
            r.record_as(
                crate::plan::record::FILE,
                Box::new(|path| {
                    crate::plan::record::write(path, &plan, &cell, &outcome).map_err(|e| crate::io::record::RecordError(e.to_string()))
                }),
            );
        }
        crate::io::results::write(&spec.out, r).map_err(Error::io(&spec.out))?.dest
    };
    Ok(PlanReport { plan, outcome, dir, seconds, frames, files: PlanFiles { poses: poses.0, tour: tour.0, simulated } })
}

/// `simulated.csv` of a tracker plan (`--simulate`): the robot file's truth measured at the
/// plan's poses ([`crate::plan::measure`]); its table and its text.
fn simulated_file(plan: &Plan, cell: &crate::plan::cell::Cell, outcome: &Outcome, out: &Path) -> Result<(Frame, String), Error> {
    let (positions, _) = crate::plan::measure(plan, cell, &outcome.rows, crate::seeds::plan::SIMULATE)
        .map_err(|e| Error::input(format!("{}: {}", e.path, e.key), e.message))?;
    let comments = [
        "SIMULATED by calsim plan --simulate: the robot file's truth (its nominal where it gives none) at the plan's poses, positions in the".into(),
        "robot base frame, the tracker's noise at each point's distance; no effect outside the model".into(),
    ];
    crate::plan::measurement_file(plan, &outcome.rows, Some(&positions), &comments).map_err(Error::io(out))
}

/// The plan's tables, its files and `simulated.csv` (with `--simulate`) added to `r`; the tables'
/// frames by file name.
fn add_files(
    r: &mut crate::io::results::Results<'_>,
    tables: Vec<crate::plan::summary::Table>,
    files: [(&str, String); 4],
    simulated: Option<String>,
) -> std::io::Result<Vec<(String, Frame)>> {
    let mut frames = Vec::new();
    for (name, columns) in tables {
        frames.push((name.to_string(), r.table(name, columns)?.clone()));
    }
    for (f, text) in files {
        r.file(f, text);
    }
    if let Some(text) = simulated {
        r.file("simulated.csv", text);
    }
    Ok(frames)
}

/// What `calsim plan` returns for a plan whose instrument is a device with a pool of its own.
#[derive(Debug)]
pub struct DevicePlanReport {
    /// The checked plan.
    pub plan: crate::plan::device::DevicePlan,
    /// What it computed.
    pub outcome: crate::plan::device::DeviceOutcome,
    /// The directory written.
    pub dir: PathBuf,
    /// Wall-clock seconds of the device's pool, the planning and the prediction together.
    pub seconds: f64,
    /// The tables written, by file name (`plan.parquet` ..., [`crate::plan::device_summary`]).
    pub frames: Vec<(String, Frame)>,
    /// The tables of `poses.csv`, `tour.csv` and `simulated.csv`.
    pub files: PlanFiles,
}

/// Whether the plan file names an `[instrument]` (a device plan, [`plan_device`]) rather than a
/// `[tracker]` ([`plan`]).
pub fn is_device_plan(file: &Path) -> Result<bool, Error> {
    let text = crate::io::read_text(file).map_err(|e| Error::input(file.display().to_string(), e.to_string()))?;
    Ok(crate::plan::device::is_device_plan(&text))
}

/// Reads and checks a device plan file.
pub fn load_device(file: &Path) -> Result<crate::plan::device::DevicePlan, Error> {
    let text = crate::io::read_text(file).map_err(|e| Error::input(file.display().to_string(), e.to_string()))?;
    crate::plan::device::parse(file, &text).map_err(|e| Error::input(format!("{}: {}", e.path, e.key), e.message))
}

/// `calsim plan` of a device plan: writes `<out>/<plan stem>.plan/` (`poses.csv`, `joints.txt`,
/// `tour.csv`, `plan.md`, the figure, the recording, and `simulated.csv` with `--simulate`).
pub fn plan_device(spec: &PlanSpec, observer: &dyn Observer) -> Result<DevicePlanReport, Error> {
    let _inputs = crate::io::inputs::Ledger::open();
    let plan = load_device(&spec.file)?;
    let name = format!("{}.plan", crate::io::names::of_file(&spec.file)?);
    crate::io::out_dir::prepare(&spec.out, &name)?;
    let (pool, threads) = super::thread_pool(spec.threads)?;
    let poses = match &plan.objective {
        None => format!("{}", plan.poses),
        Some(o) => format!("{} to {} (by objective)", o.fewest_poses, o.most_poses),
    };
    observer.started(&format!(
        "calsim plan: {} ({poses} poses from the {} the {} {}, {} validation, {} worlds), {}",
        spec.file.display(),
        plan.pool,
        plan.kind,
        if plan.kind == "spms" { "head measures" } else { "centres" },
        plan.validation,
        plan.worlds,
        super::threads_label(threads)
    ));
    let t0 = std::time::Instant::now();
    let outcome =
        pool.install(|| crate::plan::device::run(&plan)).map_err(|e| Error::input(format!("{}: {}", e.path, e.key), e.message))?;
    let simulated =
        if spec.simulate { Some(crate::plan::device::simulated_file(&plan, &outcome).map_err(Error::io(&spec.out))?) } else { None };
    let seconds = t0.elapsed().as_secs_f64();
    // plan.md is rendered from the tables the directory stores.
    let tables = crate::plan::device_summary::tables(&plan, &outcome);
    let poses = crate::plan::device::measurement_file(&plan, &outcome).map_err(Error::io(&spec.out))?;
    let tour = crate::plan::device::tour_file(&plan, &outcome).map_err(Error::io(&spec.out))?;
    let files = [
        ("poses.csv", poses.1),
        ("joints.txt", crate::plan::device::joint_list(&plan, &outcome)),
        ("tour.csv", tour.1),
        ("plan.md", crate::plan::device_summary::markdown(&tables).map_err(Error::io(&spec.out))?),
    ];
    let (simulated, simulated_text) = simulated.unzip();
    let frames;
    let dir = {
        let mut r = crate::io::results::Results::new(&name, crate::io::results::Head::Run(crate::io::manifest::Provenance::of_run(&[])));
        let io = |e: std::io::Error| Error::io(&spec.out)(e);
        r.field("plan", &name)
            .map_err(io)?
            .field("instrument", plan.kind)
            .map_err(io)?
            .field("simulate", spec.simulate)
            .map_err(io)?
            .field("recording", spec.recording)
            .map_err(io)?;
        frames = add_files(&mut r, tables, files, simulated_text).map_err(io)?;
        r.draw(Box::new(|d| crate::plan::device_view::write_figure(d, &plan, &outcome).map(|()| Vec::new())));
        if spec.recording {
            r.record_as(
                crate::plan::record::FILE,
                Box::new(|path| {
                    crate::plan::device_view::write_recording(path, &plan, &outcome)
                        .map_err(|e| crate::io::record::RecordError(e.to_string()))
                }),
            );
        }
        crate::io::results::write(&spec.out, r).map_err(Error::io(&spec.out))?.dest
    };
    Ok(DevicePlanReport { plan, outcome, dir, seconds, frames, files: PlanFiles { poses: poses.0, tour: tour.0, simulated } })
}
