//! Command-line interface: argument parsing and the terminal report. Errors are printed as one
//! line and exit with code 2 (bad input) or 1 (a check that failed).

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};

use clap::{Parser, Subcommand, ValueEnum};

use crate::io::plots::PlotInputs;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use crate::campaign::uniform_configuration;
use crate::identify::FitOutcome;
use crate::identify::{FitOptions, Observation, Solver, identify};
use crate::io::report;
use crate::io::results::Timings;
use crate::io::scenario;
use crate::robot::builtin::{trical_2018_nominal, trical_2018_table7};
use crate::robot::{KinState, ParamSet, forward};
use crate::study::Identified;
use crate::study::check::{Check, tally};
use crate::study::figures::{self, Figures};

/// calsim: simulation and Monte Carlo studies of robot calibration with low-cost 3D measuring devices.
#[derive(Parser, Debug)]
#[command(name = "calsim", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Run a study: campaign, DETMAX, identifications, validation; write the results.
    Run(RunArgs),
    /// Run a study and compare it with the bands of the scenario's [expect] table (exit 1 on a miss).
    Check(RunArgs),
    /// Identify the paper's IRB 120 (Table 7 truth) from simulated TCP positions and validate it.
    Demo(DemoArgs),
    /// Run a design sweep (grid points x realisations), or one shard of it; unsharded, merge it too.
    Sweep(SweepArgs),
    /// Merge the shard directories of one sweep into its results.
    Merge(MergeArgs),
    /// Uncertainty budget: every error source of the scenario alone, off and scaled, over realisations.
    Budget(BudgetArgs),
    /// Table 8 of the TriCal paper: the same robot calibrated with the TriCal, a laser tracker and an optical CMM.
    Table8(Table8Args),
    /// Export an identified model of a TriCal results directory: a robot file, a URDF and a YAML overlay.
    Export(ExportArgs),
    /// Joint targets (and corrected Cartesian targets for a nominal-only controller) for TCP targets.
    Compensate(CompensateArgs),
    /// Convert a URDF arm (a serial chain of six revolute joints) into a calsim robot file.
    ImportUrdf(ImportUrdfArgs),
    /// The tool frame, gravity torques and joint deflections of a robot file's arm at each row of
    /// a joints CSV (header q1_deg,...,q6_deg).
    Fk(FkArgs),
}

#[derive(clap::Args, Debug)]
struct FkArgs {
    /// The arm: a robot file.
    robot: PathBuf,
    /// Joint values: CSV with the header q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg.
    joints: PathBuf,
    /// Output CSV (default: standard output).
    #[arg(long)]
    out: Option<PathBuf>,
}

#[derive(clap::Args, Debug)]
struct ImportUrdfArgs {
    /// The URDF file.
    urdf: PathBuf,
    /// The robot file to write.
    #[arg(long)]
    out: PathBuf,
    /// The folder holding the packages that `package://NAME/...` mesh names point into.
    #[arg(long)]
    package_root: Option<PathBuf>,
    /// Fit a link's capsule to its visual meshes where it has no collision geometry.
    #[arg(long)]
    visual_meshes: bool,
}

#[derive(clap::Args, Debug)]
struct CompensateArgs {
    /// The calibrated model: a robot file (e.g. robot.toml of `calsim export`).
    model: PathBuf,
    /// TCP targets in {W}: CSV with the header x_mm,y_mm,z_mm,alpha_deg,beta_deg,gamma_deg.
    targets: PathBuf,
    /// The controller's nominal model (e.g. before.toml of `calsim export`): also write the
    /// Cartesian targets to command it.
    #[arg(long)]
    nominal: Option<PathBuf>,
    /// Output CSV (default: standard output).
    #[arg(long)]
    out: Option<PathBuf>,
}

#[derive(clap::Args, Debug)]
struct ExportArgs {
    /// A results directory of `calsim run` (with its manifest.json and tasks.parquet).
    results: PathBuf,
    /// The task to export, by index (see tasks.parquet).
    #[arg(long, conflicts_with_all = ["set_size", "pick"])]
    task: Option<usize>,
    /// Set size to pick from (default: the scenario's table set size, 75 in the paper).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=100_000))]
    set_size: Option<u32>,
    /// Which task of that set size: the median, best or worst validation median.
    #[arg(long, value_enum, default_value_t = PickArg::Median)]
    pick: PickArg,
    /// Directory the export goes to (in `<scenario>.task-<N>`; default: beside the results).
    #[arg(long)]
    out: Option<PathBuf>,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq)]
enum PickArg {
    Median,
    Best,
    Worst,
}

#[derive(clap::Args, Debug)]
struct Table8Args {
    /// A TriCal scenario file.
    scenario: PathBuf,
    /// Realisations (worlds): the medians over them, with P10-P90, beside the published rows.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=10_000))]
    realisations: u32,
    /// Configurations of each external instrument's pool (random in the workspace, in its view).
    #[arg(long, default_value_t = 360, value_parser = clap::value_parser!(u32).range(100..=100_000))]
    pool: u32,
    /// Worker threads (default: all cores).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=1024))]
    threads: Option<u32>,
}

#[derive(clap::Args, Debug)]
struct BudgetArgs {
    /// Scenario file (TOML) of either device.
    scenario: PathBuf,
    /// Directory the budget goes to (in `<scenario>.budget`).
    #[arg(long, default_value = "results")]
    out: PathBuf,
    /// Realisations (worlds) per configuration.
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u32).range(1..=10_000))]
    realisations: u32,
    /// What-if factors applied to each source in turn, comma-separated.
    #[arg(long, value_delimiter = ',', default_values_t = [0.5, 2.0], value_parser = parse_factor)]
    factors: Vec<f64>,
    /// Repetitions per configuration and realisation, replacing the scenario's.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=crate::study::MAX_REPETITIONS as i64))]
    repetitions: Option<u32>,
    /// Worker threads (default: all cores).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=1024))]
    threads: Option<u32>,
}

fn parse_factor(s: &str) -> Result<f64, String> {
    let f: f64 = s.trim().parse().map_err(|_| format!("`{s}` is not a number"))?;
    if f.is_finite() && (0.0..=100.0).contains(&f) { Ok(f) } else { Err(format!("{s}: a factor within [0, 100]")) }
}

#[derive(clap::Args, Debug)]
struct SweepArgs {
    /// Sweep file (TOML), e.g. scenarios/sweeps/epsilon_time.toml.
    sweep: PathBuf,
    /// Directory of the shard directories and of the merged results.
    #[arg(long, default_value = "results")]
    out: PathBuf,
    /// Run only every K-th work unit starting at k (k/K, 0 <= k < K); merge the shards afterwards.
    #[arg(long, value_parser = parse_shard)]
    shard: Option<(usize, usize)>,
    /// Worker threads (default: all cores).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=1024))]
    threads: Option<u32>,
}

#[derive(clap::Args, Debug)]
struct MergeArgs {
    /// Shard directories of one sweep (`<out>/<sweep>.shard-k-of-K`).
    #[arg(required = true)]
    shards: Vec<PathBuf>,
    /// Directory the merged results go in (a subdirectory named after the sweep).
    #[arg(long, default_value = "results")]
    out: PathBuf,
}

fn parse_shard(s: &str) -> Result<(usize, usize), String> {
    let (k, n) = s.split_once('/').ok_or("expected k/K, e.g. 0/4")?;
    let k: usize = k.trim().parse().map_err(|_| format!("`{k}` is not a whole number"))?;
    let n: usize = n.trim().parse().map_err(|_| format!("`{n}` is not a whole number"))?;
    if n == 0 || n > 100_000 {
        return Err(format!("{s}: K must be within [1, 100000]"));
    }
    if k >= n {
        return Err(format!("{s}: k must be below K (shards are numbered 0 to K-1)"));
    }
    Ok((k, n))
}

#[derive(clap::Args, Debug)]
struct RunArgs {
    /// Scenario file (TOML), e.g. scenarios/irb120_trical.toml.
    scenario: PathBuf,
    /// Directory the results go to (in a subdirectory named after the scenario).
    #[arg(long, default_value = "results")]
    out: PathBuf,
    /// Worker threads (default: all cores).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=1024))]
    threads: Option<u32>,
    /// Seed, replacing the scenario's.
    #[arg(long)]
    seed: Option<u64>,
    /// Set sizes as start:end:step (inclusive), replacing the scenario's.
    #[arg(long, value_parser = parse_sizes)]
    set_sizes: Option<SetSizes>,
    /// Repetitions per set size, replacing the scenario's.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=crate::study::MAX_REPETITIONS as i64))]
    repetitions: Option<u32>,
    /// Skip the figures (PNG and SVG of the paper's Figs. 7-13).
    #[arg(long)]
    no_plots: bool,
    /// Skip the Rerun recording (study.rrd).
    #[arg(long)]
    no_recording: bool,
    /// Judge every figure over this many realisations (worlds) of the scenario: a figure passes
    /// when its median over them is within the band and the published value within their P10-P90.
    /// Realisation 0 is the run whose results are written.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=10_000))]
    realisations: u32,
}

/// Set sizes given on the command line.
#[derive(Clone, Debug)]
struct SetSizes(Vec<u32>);

fn parse_sizes(s: &str) -> Result<SetSizes, String> {
    let parts: Vec<&str> = s.split(':').collect();
    let num = |x: &str| x.trim().parse::<u32>().map_err(|_| format!("`{x}` is not a whole number"));
    let (a, b, step) = match parts.as_slice() {
        [a] => (num(a)?, num(a)?, 1),
        [a, b] => (num(a)?, num(b)?, 1),
        [a, b, c] => (num(a)?, num(b)?, num(c)?),
        _ => return Err("expected start:end:step, e.g. 20:100:5".into()),
    };
    if step == 0 || a > b {
        return Err(format!("{s}: needs start <= end and a step > 0"));
    }
    if ((b - a) / step) as usize >= crate::study::MAX_SET_SIZES {
        return Err(format!("{s}: more than {} set sizes", crate::study::MAX_SET_SIZES));
    }
    Ok(SetSizes((a..=b).step_by(step as usize).collect()))
}

#[derive(ValueEnum, Clone, Copy, Debug)]
enum SolverArg {
    /// Gauss-Newton with the pseudo-inverse step (paper eqs. 14-15).
    Gn,
    /// Levenberg-Marquardt.
    Lm,
}

#[derive(clap::Args, Debug)]
struct DemoArgs {
    /// Configurations used for identification (random, inside the joint limits).
    #[arg(long, default_value_t = 75, value_parser = clap::value_parser!(u32).range(1..=100_000))]
    configurations: u32,
    /// Validation configurations.
    #[arg(long, default_value_t = 506, value_parser = clap::value_parser!(u32).range(1..=1_000_000))]
    validation: u32,
    /// Standard deviation of the position noise on each measured coordinate, um.
    #[arg(long, default_value_t = 10.0)]
    noise_um: f64,
    /// Seed of the random streams.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Solver.
    #[arg(long, value_enum, default_value_t = SolverArg::Gn)]
    solver: SolverArg,
}

/// Most worker threads a command takes (`--threads` and `RAYON_NUM_THREADS`).
const MOST_THREADS: u32 = 1024;

/// The worker pool of a command and its size: `--threads`, else `RAYON_NUM_THREADS` (rayon's own
/// variable, read here because rayon ignores a value it cannot read; 0 means every core, as in
/// rayon; set but empty counts as unset), else every core.
fn thread_pool(threads: Option<u32>) -> Result<(rayon::ThreadPool, Threads), String> {
    let asked = match threads {
        Some(t) => t,
        None => match std::env::var_os("RAYON_NUM_THREADS").filter(|v| !v.is_empty()) {
            None => 0,
            Some(v) => v.to_str().and_then(|s| s.trim().parse::<u32>().ok()).filter(|n| *n <= MOST_THREADS).ok_or_else(|| {
                format!(
                    "environment: RAYON_NUM_THREADS = {:?} is not a number of threads (1 to {MOST_THREADS}, or 0 for every core)",
                    v.to_string_lossy()
                )
            })?,
        },
    };
    let threads = if asked == 0 { std::thread::available_parallelism().map_or(1, usize::from) } else { asked as usize };
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().map_err(|e| e.to_string())?;
    Ok((pool, Threads(threads)))
}

/// A thread count, displayed as "1 thread" or "n threads".
#[derive(Clone, Copy, Debug)]
struct Threads(usize);

impl std::fmt::Display for Threads {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.0 == 1 { write!(f, "1 thread") } else { write!(f, "{} threads", self.0) }
    }
}

/// Entry point of the binary.
pub fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => {
            if !e.use_stderr() {
                // --help and --version.
                let _ = e.print();
                return ExitCode::SUCCESS;
            }
            // Bad command line: the one line that says what is wrong (clap adds a usage hint below it).
            let text = e.render().to_string();
            let said: Vec<&str> = text
                .lines()
                .take_while(|l| !l.starts_with("Usage:") && !l.starts_with("For more information"))
                .map(str::trim)
                .filter(|l| !l.is_empty() && !l.starts_with("tip:"))
                .collect();
            eprintln!("{}", if said.is_empty() { "error: bad command line".to_string() } else { compact_numbers(&said.join(" ")) });
            return ExitCode::from(2);
        }
    };
    let result = match &cli.command {
        Command::Run(args) => study(args, false),
        Command::Check(args) => study(args, true),
        Command::Demo(args) => demo(args).map(|()| ExitCode::SUCCESS),
        Command::Sweep(args) => sweep(args),
        Command::Merge(args) => merge(&args.shards, &args.out),
        Command::Budget(args) => budget(args),
        Command::Table8(args) => table8(args),
        Command::Export(args) => export(args),
        Command::Compensate(args) => compensate(args),
        Command::ImportUrdf(args) => import_urdf(args),
        Command::Fk(args) => fk(args),
    };
    match result {
        Ok(code) => code,
        Err(msg) => {
            eprintln!("error: {}", compact_numbers(&msg));
            ExitCode::from(2)
        }
    }
}

/// The message with every number written out in more than 24 characters (Rust prints `1e300` as
/// 301 digits and `1e-300` as 302 characters) in exponent form, so that an error about a huge or
/// tiny value stays one readable line. Digits that are part of a word or a path stay as written.
fn compact_numbers(msg: &str) -> String {
    let word = |c: Option<char>| c.is_some_and(|c| c.is_ascii_alphanumeric() || c == '_' || c == '/');
    let mut out = String::with_capacity(msg.len());
    let mut rest = msg;
    while let Some(start) = rest.find(|c: char| c.is_ascii_digit()) {
        let len = rest[start..].find(|c: char| !(c.is_ascii_digit() || c == '.')).unwrap_or(rest.len() - start);
        let token = &rest[start..start + len];
        let alone = !word(rest[..start].chars().last().or_else(|| out.chars().last())) && !word(rest[start + len..].chars().next());
        out.push_str(&rest[..start]);
        match token.parse::<f64>() {
            Ok(x) if len > 24 && alone => out.push_str(&format!("{x:e}")),
            _ => out.push_str(token),
        }
        rest = &rest[start + len..];
    }
    out.push_str(rest);
    out
}

/// The command-line overrides of the seed, the set sizes (the table size moves to the nearest
/// given size) and the repetitions.
fn apply_overrides(args: &RunArgs, seed: &mut u64, set_sizes: &mut Vec<u32>, table_set_size: &mut u32, repetitions: &mut u32) {
    if let Some(s) = args.seed {
        *seed = s;
    }
    if let Some(SetSizes(sizes)) = &args.set_sizes {
        *set_sizes = sizes.clone();
        if !sizes.contains(table_set_size) {
            *table_set_size = *sizes.iter().min_by_key(|n| n.abs_diff(*table_set_size)).expect("non-empty");
        }
    }
    if let Some(r) = args.repetitions {
        *repetitions = r;
    }
}

/// `run` / `check` of a TriCal scenario (an SPMS one goes to [`spms_study`]).
///
/// Long by design: the run in the order the terminal shows it (campaign, identifications, checks,
/// results written, the comparison and the timing line, then the other realisations).
fn study(args: &RunArgs, check: bool) -> Result<ExitCode, String> {
    let t0 = Instant::now();
    let mut scenario = match scenario::load_any(&args.scenario).map_err(|e| e.to_string())? {
        scenario::Loaded::Trical(s) => *s,
        scenario::Loaded::Spms(s) => return spms_study(args, *s, check),
    };
    let st = &mut scenario.study;
    apply_overrides(args, &mut scenario.seed, &mut st.set_sizes, &mut st.table_set_size, &mut st.repetitions);
    // Re-check what the overrides changed (sizes against the pool and the parameters).
    let text = scenario.text.clone();
    scenario::check_overrides(&scenario).map_err(|e| e.to_string())?;
    crate::io::out_dir::prepare(&args.out, &scenario.name).map_err(|e| e.to_string())?;
    let (pool, threads) = thread_pool(args.threads)?;

    eprintln!("calsim {}: {} (seed {}), {threads}", if check { "check" } else { "run" }, scenario.name, scenario.seed);
    let spec = &scenario.experiment;
    let experiment = spec.build(scenario.seed).map_err(|e| format!("{}: campaign: {e}", args.scenario.display()))?;
    let campaign_s = t0.elapsed().as_secs_f64();
    let before = spec.before_model(&experiment.campaign);
    let n_tasks = scenario.study.tasks().len();
    let bar = ProgressBar::new(n_tasks as u64);
    bar.set_style(ProgressStyle::with_template("{bar:40} {pos}/{len} identifications, {elapsed} elapsed, ETA {eta}").expect("template"));
    let results = pool
        .install(|| crate::study::run(&experiment, &before, &scenario.study, scenario.seed, &|done, _| bar.set_position(done as u64)))
        .map_err(|e| format!("{}: [study] parameters: {e}", args.scenario.display()))?;
    bar.finish_and_clear();
    let study_s = t0.elapsed().as_secs_f64();
    let figures = Figures::of(&results, &experiment.robot.truth, scenario.study.table_set_size as usize);
    let t_table8 = Instant::now();
    let rows = trical_checks(&scenario, &experiment, &before, &figures, scenario.seed, &pool)
        .map_err(|e| format!("{}: Table 8: {e}", args.scenario.display()))?;
    let table8_s = t_table8.elapsed().as_secs_f64();
    let t_write = Instant::now();
    let timings = Timings {
        campaign_s,
        pool_s: experiment.campaign.pool_wall_s,
        pool_jacobian_s: results.pool_jacobian_s,
        tasks_s: results.tasks_s,
        study_s,
    };
    let plot_inputs = (!args.no_plots).then(|| PlotInputs {
        validation_w: experiment.campaign.validation.iter().map(|v| v.measured_w).collect(),
        spheres_w: experiment.cell.spheres_w.clone(),
        base_w: crate::robot::world_from_base(&experiment.robot.truth).translation.vector,
        table_n: scenario.study.table_set_size as usize,
    });
    let representative = figures::representative(&results, scenario.study.table_set_size as usize).map(|(task, _)| task);
    let record_s = std::cell::Cell::new(0.0);
    let record = |path: &std::path::Path| {
        let t = Instant::now();
        let r = crate::io::recording::write(path, &scenario.name, &experiment, &before, &results, representative);
        record_s.set(t.elapsed().as_secs_f64());
        r
    };
    let extras =
        crate::io::results::Extras { plots: plot_inputs.as_ref(), recording: if args.no_recording { None } else { Some(&record) } };
    let report = crate::io::results::Report { figures: &figures, checks: &rows, threads: threads.0, timings: &timings, extras };
    let dest = crate::io::results::write(&args.out, &scenario, &results, &report).map_err(|e| format!("{}: {e}", args.out.display()))?;
    let write_s = t_write.elapsed().as_secs_f64();
    debug_assert_eq!(text, scenario.text);

    println!("{}", report::terminal_table(&rows));
    fit_health(&args.scenario, results.tasks.iter().map(|t| &t.id))?;
    println!(
        "timing: study {:.3} s (campaign {:.3} s, of which pool {:.3} s; {} identifications {:.3} s){}, results \
             written in {:.3} s (recording {:.3} s) to {}",
        study_s,
        campaign_s,
        experiment.campaign.pool_wall_s,
        n_tasks,
        results.tasks_s,
        if scenario.expect.wants_table8() {
            format!("; Table 8's tracker and optical CMM calibrations {table8_s:.3} s")
        } else {
            String::new()
        },
        write_s,
        record_s.get(),
        dest.display()
    );
    if args.realisations > 1 {
        let others = realisations(args.realisations, |r| {
            let seed = crate::sweep::realisation_seed(scenario.seed, r);
            let e = spec.build(seed).map_err(|e| format!("campaign: {e}"))?;
            let b = spec.before_model(&e.campaign);
            let res = pool.install(|| crate::study::run(&e, &b, &scenario.study, seed, &|_, _| {})).map_err(|e| e.to_string())?;
            trical_checks(&scenario, &e, &b, &Figures::of(&res, &e.robot.truth, scenario.study.table_set_size as usize), seed, &pool)
        });
        return Ok(distribution_verdict(rows, others, check));
    }
    Ok(verdict(&rows, check))
}

/// The checks of one TriCal world: the paper's figures, and Table 8's external instruments when
/// the scenario checks them.
fn trical_checks(
    s: &scenario::Scenario,
    e: &crate::experiment::Experiment,
    before: &crate::robot::RobotModel,
    f: &Figures,
    seed: u64,
    pool: &rayon::ThreadPool,
) -> Result<Vec<Check>, String> {
    let mut rows = figures::checks(f, &s.expect);
    // Another arm than the paper's: its figures are the IRB 120's, shown for scale, not compared.
    if s.experiment.nominal().data().name != crate::robot::builtin::irb120().data().name {
        for r in &mut rows {
            if r.published_value.take().is_some() {
                r.published = format!("IRB 120: {}", r.published);
            }
        }
    }
    if s.expect.wants_table8() {
        let [tracker, cmm] = pool.install(|| crate::study::external_instruments(&s.experiment, e, before, &s.study, seed, 360))?;
        rows.extend(figures::table8_checks(tracker, cmm, &s.expect));
    }
    Ok(rows)
}

/// One line at the terminal when identifications failed: how many gave no model (and which
/// parameters they could not separate), how many stopped at the iteration cap. A study in which
/// no identification gave a model is an error of its scenario's parameter set.
fn fit_health<'a>(scenario: &Path, ids: impl Iterator<Item = &'a Identified>) -> Result<(), String> {
    let (mut total, mut no_model, mut capped) = (0, 0, 0);
    let mut names: Vec<&str> = Vec::new();
    for id in ids {
        total += 1;
        match &id.outcome {
            FitOutcome::RankDeficient { .. } | FitOutcome::NotFinite => no_model += 1,
            FitOutcome::IterationCap { .. } => capped += 1,
            _ => {}
        }
        for n in id.outcome.unidentifiable() {
            if !names.contains(&n.as_str()) {
                names.push(n);
            }
        }
    }
    let hidden = if names.is_empty() { String::new() } else { format!(" (could not separate: {})", names.join(" ")) };
    if no_model == total && total > 0 {
        return Err(format!(
            "{}: [study] parameters: every one of the {total} identifications failed{hidden}: no set of the pool identifies this parameter set",
            scenario.display()
        ));
    }
    if no_model > 0 || capped > 0 {
        eprintln!("warning: {no_model} of {total} identifications gave no model{hidden}; {capped} stopped at the iteration cap");
    }
    Ok(())
}

/// The checks of realisations 1..count (realisation 0 is the plain run), with a progress bar; a
/// realisation whose campaign fails is left out with a warning line.
fn realisations(count: u32, one: impl Fn(u32) -> Result<Vec<Check>, String>) -> Vec<Vec<Check>> {
    let bar = ProgressBar::new(u64::from(count - 1));
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} further realisations, {elapsed} elapsed, ETA {eta}").expect("template"),
    );
    let mut out = Vec::new();
    let mut failed = Vec::new();
    for r in 1..count {
        match one(r) {
            Ok(rows) => out.push(rows),
            Err(e) => failed.push(format!("{r}: {e}")),
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    if !failed.is_empty() {
        eprintln!("warning: {} realisations left out ({})", failed.len(), failed.join("; "));
    }
    out
}

/// The figures over realisations (realisation 0 first) as a table, and the exit code of `run`
/// (success) or `check` (1 when a figure misses the distribution rule).
fn distribution_verdict(first: Vec<Check>, others: Vec<Vec<Check>>, check: bool) -> ExitCode {
    let mut runs = vec![first];
    runs.extend(others);
    let dist = crate::study::check::over_realisations(&runs);
    println!(
        "\nover {} realisations (realisation 0 is the run above; pass: the median within the band, the published value within P10-P90):",
        runs.len()
    );
    println!("{}", report::distribution_table(&dist));
    if !check {
        return ExitCode::SUCCESS;
    }
    let checked = dist.iter().filter(|d| d.pass.is_some()).count();
    let missed = dist.iter().filter(|d| d.pass == Some(false)).count();
    println!("check: {} of {checked} figures within their bands over {} realisations", checked - missed, runs.len());
    if missed > 0 { ExitCode::from(1) } else { ExitCode::SUCCESS }
}

/// The exit code of `run` (success) or `check` (1 when a figure misses its band), with the
/// check's one-line verdict.
fn verdict(rows: &[Check], check: bool) -> ExitCode {
    if !check {
        return ExitCode::SUCCESS;
    }
    let (checked, missed) = tally(rows);
    println!("check: {} of {checked} figures within their bands", checked - missed);
    if missed > 0 { ExitCode::from(1) } else { ExitCode::SUCCESS }
}

/// `run` / `check` of an SPMS scenario (`kind = "spms"`).
fn spms_study(args: &RunArgs, mut sc: scenario::SpmsScenario, check: bool) -> Result<ExitCode, String> {
    let st = &mut sc.spec.study;
    apply_overrides(args, &mut sc.seed, &mut st.set_sizes, &mut st.table_set_size, &mut st.repetitions);
    scenario::check_spms(&sc.spec, &format!("{} (with command-line overrides)", args.scenario.display())).map_err(|e| e.to_string())?;
    crate::io::out_dir::prepare(&args.out, &sc.name).map_err(|e| e.to_string())?;
    let (pool, threads) = thread_pool(args.threads)?;
    eprintln!("calsim {}: {} (SPMS, seed {}), {threads}", if check { "check" } else { "run" }, sc.name, sc.seed);
    let bar = ProgressBar::new(0);
    bar.set_style(ProgressStyle::with_template("{bar:40} {pos}/{len} identifications, {elapsed} elapsed, ETA {eta}").expect("template"));
    let results = pool
        .install(|| {
            crate::spms::study::run(&sc.spec, sc.seed, &|done, total| {
                bar.set_length(total as u64);
                bar.set_position(done as u64)
            })
        })
        .map_err(|e| format!("{}: {e}", args.scenario.display()))?;
    bar.finish_and_clear();
    let figures = crate::spms::study::SpmsFigures::of(&results, sc.spec.study.table_set_size as usize);
    let rows = crate::spms::study::checks(&figures, &sc.expect);
    let t_write = Instant::now();
    let record_s = std::cell::Cell::new(0.0);
    let record = |path: &std::path::Path| {
        let t = Instant::now();
        let r = crate::io::recording::write_spms(path, &sc.name, &sc.spec, &results);
        record_s.set(t.elapsed().as_secs_f64());
        r
    };
    let extras =
        crate::io::spms_results::SpmsExtras { plots: !args.no_plots, recording: if args.no_recording { None } else { Some(&record) } };
    let dest = crate::io::spms_results::write(&args.out, &sc, &results, &figures, &rows, threads.0, &extras)
        .map_err(|e| format!("{}: {e}", args.out.display()))?;
    let write_s = t_write.elapsed().as_secs_f64();
    println!("{}", report::terminal_table(&rows));
    fit_health(&args.scenario, results.tasks.iter().map(|t| &t.id))?;
    let t = &results.timings;
    println!(
        "timing: study {:.3} s (head {:.3} s, cell and pool {:.3} s, {} identifications with ISO 9283 tests \
             {:.3} s), results written in {:.3} s (recording {:.3} s) to {}",
        t.study_s,
        t.head_s,
        t.cell_s,
        results.tasks.len(),
        t.tasks_s,
        write_s,
        record_s.get(),
        dest.display()
    );
    if args.realisations > 1 {
        let table_n = sc.spec.study.table_set_size as usize;
        let others = realisations(args.realisations, |r| {
            let seed = crate::sweep::realisation_seed(sc.seed, r);
            let res = pool.install(|| crate::spms::study::run(&sc.spec, seed, &|_, _| {})).map_err(|e| e.to_string())?;
            Ok(crate::spms::study::checks(&crate::spms::study::SpmsFigures::of(&res, table_n), &sc.expect))
        });
        return Ok(distribution_verdict(rows, others, check));
    }
    Ok(verdict(&rows, check))
}

fn sweep(args: &SweepArgs) -> Result<ExitCode, String> {
    let t0 = Instant::now();
    let sweep = crate::sweep::spec::load(&args.sweep).map_err(|e| e.to_string())?;
    let (k, count) = args.shard.unwrap_or((0, 1));
    crate::io::out_dir::prepare(&args.out, &crate::sweep::shard_dir(Path::new(""), &sweep.name, k, count).display().to_string())
        .map_err(|e| e.to_string())?;
    if args.shard.is_none() {
        crate::io::out_dir::prepare(&args.out, &sweep.name).map_err(|e| e.to_string())?;
    }
    let (pool, threads) = thread_pool(args.threads)?;
    let units = sweep.points.len() * sweep.realisations as usize;
    eprintln!(
        "calsim sweep: {} ({} grid points x {} realisations = {units} work units{}), {threads}",
        sweep.name,
        sweep.points.len(),
        sweep.realisations,
        if count > 1 { format!(", shard {k} of {count}") } else { String::new() }
    );
    let bar = ProgressBar::new(0);
    bar.set_style(ProgressStyle::with_template("{bar:40} {pos}/{len} work units, {elapsed} elapsed, ETA {eta}").expect("template"));
    let dir = pool
        .install(|| {
            crate::sweep::run_shard(&sweep, &args.out, k, count, &|done, total| {
                bar.set_length(total as u64);
                bar.set_position(done as u64)
            })
        })
        .map_err(|e| format!("{}: {e}", args.out.display()))?;
    bar.finish_and_clear();
    let run_s = t0.elapsed().as_secs_f64();
    println!(
        "timing: {} work units of shard {k}/{count} in {run_s:.3} s ({:.3} s per unit) to {}",
        units.div_ceil(count),
        run_s / units.div_ceil(count).max(1) as f64,
        dir.display()
    );
    if args.shard.is_some() {
        println!(
            "merge the shards with: calsim merge {}/{}.shard-*-of-{count} --out {}",
            args.out.display(),
            sweep.name,
            args.out.display()
        );
        return Ok(ExitCode::SUCCESS);
    }
    let code = merge(std::slice::from_ref(&dir), &args.out)?;
    std::fs::remove_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    Ok(code)
}

fn merge(shards: &[PathBuf], out: &Path) -> Result<ExitCode, String> {
    let (info, units) = crate::sweep::read_shards(shards).map_err(|e| e.to_string())?;
    crate::io::out_dir::prepare(out, &info.name).map_err(|e| e.to_string())?;
    let points = crate::sweep::aggregate(&info, &units);
    let dest = crate::io::sweep_results::write(out, &info, &units, &points).map_err(|e| format!("{}: {e}", out.display()))?;
    let failed = units.iter().filter(|u| u.error.is_some()).count();
    println!("{}", crate::io::sweep_results::summary(&info, &units, &points));
    println!("merged {} work units ({failed} failed) into {}", units.len(), dest.display());
    if failed == units.len() {
        return Err(format!("{}: every work unit failed (see {}/summary.md)", info.name, dest.display()));
    }
    Ok(ExitCode::SUCCESS)
}

fn import_urdf(args: &ImportUrdfArgs) -> Result<ExitCode, String> {
    let options = crate::robot::urdf::ImportOptions { package_root: args.package_root.clone(), visual_fallback: args.visual_meshes };
    let report = crate::robot::urdf::import(&args.urdf, &args.out, &options).map_err(|e| e.to_string())?;
    for line in report.lines(&args.urdf, &args.out) {
        println!("{line}");
    }
    Ok(ExitCode::SUCCESS)
}

fn fk(args: &FkArgs) -> Result<ExitCode, String> {
    let file = crate::robot::file::RobotFile::load(&args.robot).map_err(|e| e.to_string())?;
    let joints = crate::robot::fk::read_joints(&args.joints).map_err(|e| e.to_string())?;
    let text = crate::robot::fk::to_csv(&crate::robot::fk::fk_rows(&file, &joints));
    match &args.out {
        Some(out) => crate::io::out_dir::write_file_atomically(out, &text).map_err(|e| format!("{}: {e}", out.display()))?,
        None => print!("{text}"),
    }
    Ok(ExitCode::SUCCESS)
}

fn compensate(args: &CompensateArgs) -> Result<ExitCode, String> {
    let load = |p: &Path| crate::robot::file::RobotFile::load(p).map_err(|e| e.to_string());
    let model = load(&args.model)?;
    let nominal = args.nominal.as_deref().map(load).transpose()?;
    let targets = crate::compensate::read_targets(&args.targets)?;
    let rows = crate::compensate::compensate(&model, nominal.as_ref(), &targets);
    let text = crate::compensate::to_csv(&rows)?;
    match &args.out {
        Some(out) => crate::io::out_dir::write_file_atomically(out, &text).map_err(|e| format!("{}: {e}", out.display()))?,
        None => print!("{text}"),
    }
    let unreachable = rows.iter().filter(|r| r.q.is_none()).count();
    if unreachable > 0 {
        eprintln!("calsim compensate: {unreachable} of {} targets cannot be reached by the model", rows.len());
    }
    Ok(ExitCode::SUCCESS)
}

fn export(args: &ExportArgs) -> Result<ExitCode, String> {
    use crate::export::Pick;
    let n = args.set_size.map(|n| n as usize);
    let pick = match (args.task, args.pick) {
        (Some(t), _) => Pick::Task(t),
        (None, PickArg::Median) => Pick::Median(n),
        (None, PickArg::Best) => Pick::Best(n),
        (None, PickArg::Worst) => Pick::Worst(n),
    };
    let e = crate::export::identification(&args.results, pick)?;
    let out = args.out.clone().unwrap_or_else(|| args.results.parent().map(Path::to_path_buf).unwrap_or_default());
    let name = format!("{}.task-{}", e.scenario, e.task);
    let dest = crate::export::write(&out, &name, &e).map_err(|err| format!("{}: {err}", out.display()))?;
    println!(
        "exported task {} (n = {}, validation median {:.4} mm) to {}: robot.toml, robot.urdf, calibration.yaml, before.toml",
        e.task,
        e.set_size,
        e.validation_median_mm,
        dest.display()
    );
    Ok(ExitCode::SUCCESS)
}

fn budget(args: &BudgetArgs) -> Result<ExitCode, String> {
    let t0 = Instant::now();
    if args.factors.len() > 8 {
        return Err(format!("--factors: {} factors, at most 8", args.factors.len()));
    }
    let (sources, configs, mut sweep) =
        crate::budget::plan(&args.scenario, args.realisations, &args.factors, args.repetitions).map_err(|e| e.to_string())?;
    sweep.predict = true;
    crate::io::out_dir::prepare(&args.out, &sweep.name).map_err(|e| e.to_string())?;
    crate::io::out_dir::prepare(&args.out, &crate::sweep::shard_dir(Path::new(""), &sweep.name, 0, 1).display().to_string())
        .map_err(|e| e.to_string())?;
    let (pool, threads) = thread_pool(args.threads)?;
    eprintln!(
        "calsim budget: {} ({} sources, {} configurations x {} realisations), {threads}",
        sweep.name,
        sources.len(),
        configs.len(),
        args.realisations
    );
    let bar = ProgressBar::new(0);
    bar.set_style(ProgressStyle::with_template("{bar:40} {pos}/{len} work units, {elapsed} elapsed, ETA {eta}").expect("template"));
    let dir = pool
        .install(|| {
            crate::sweep::run_shard(&sweep, &args.out, 0, 1, &|done, total| {
                bar.set_length(total as u64);
                bar.set_position(done as u64)
            })
        })
        .map_err(|e| format!("{}: {e}", args.out.display()))?;
    bar.finish_and_clear();
    let (info, units) = crate::sweep::read_shards(std::slice::from_ref(&dir)).map_err(|e| e.to_string())?;
    let points = crate::sweep::aggregate(&info, &units);
    let rows: Vec<Option<&crate::sweep::PointRow>> = (0..configs.len()).map(|i| points.iter().find(|p| p.point == i && p.table)).collect();
    let p95: Vec<f64> = rows.iter().map(|r| r.map_or(f64::NAN, |r| r.after[1][0])).collect();
    let (all_mm, none_mm, lines) = crate::budget::lines(&sources, &configs, &p95);
    // The linear prediction per configuration, merged over realisations in unit order.
    let predictions: Vec<Option<crate::study::prediction::Prediction>> = (0..configs.len())
        .map(|i| {
            units.iter().filter(|u| u.point == i).filter_map(|u| u.prediction.as_ref()).fold(None, |acc, p| {
                let mut acc: crate::study::prediction::Prediction = acc.unwrap_or_default();
                acc.merge(p);
                Some(acc)
            })
        })
        .collect();
    let report = crate::io::budget_results::BudgetReport {
        name: &sweep.name,
        realisations: args.realisations,
        sources: &sources,
        configs: &configs,
        rows,
        all_mm,
        none_mm,
        lines: &lines,
        predictions: &predictions,
    };
    let dest = crate::io::budget_results::write(&args.out, &report).map_err(|e| format!("{}: {e}", args.out.display()))?;
    std::fs::remove_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    println!("{}", crate::io::budget_results::summary(&report));
    println!("timing: budget {:.3} s ({} work units) to {}", t0.elapsed().as_secs_f64(), units.len(), dest.display());
    Ok(ExitCode::SUCCESS)
}

/// Median, std and max after calibration (medians over the repetitions at the table set size) of
/// the TriCal, the laser tracker and the optical CMM in one world.
fn table8_world(s: &scenario::Scenario, seed: u64, pool_size: u32) -> Result<[[f64; 3]; 3], String> {
    let spec = &s.experiment;
    let e = spec.build(seed).map_err(|e| format!("campaign: {e}"))?;
    let before = spec.before_model(&e.campaign);
    let mut study = s.study.clone();
    study.set_sizes = vec![study.table_set_size];
    let trical = crate::study::run(&e, &before, &study, seed, &|_, _| {}).map_err(|e| e.to_string())?;
    let f = Figures::of(&trical, &e.robot.truth, study.table_set_size as usize);
    let [tracker, cmm] = crate::study::external_instruments(spec, &e, &before, &s.study, seed, pool_size)?;
    Ok([[f.after_median, f.after_std, f.after_max], tracker, cmm])
}

fn table8(args: &Table8Args) -> Result<ExitCode, String> {
    let t0 = Instant::now();
    let s = match scenario::load_any(&args.scenario).map_err(|e| e.to_string())? {
        scenario::Loaded::Trical(s) => *s,
        scenario::Loaded::Spms(_) => {
            return Err(format!("{}: kind: Table 8 is the TriCal paper's (a TriCal scenario)", args.scenario.display()));
        }
    };
    let (pool, threads) = thread_pool(args.threads)?;
    eprintln!("calsim table8: {} (seed {}), {} realisations, {threads}", s.name, s.seed, args.realisations);
    let bar = ProgressBar::new(u64::from(args.realisations));
    bar.set_style(ProgressStyle::with_template("{bar:40} {pos}/{len} realisations, {elapsed} elapsed, ETA {eta}").expect("template"));
    let mut worlds = Vec::new();
    for r in 0..args.realisations {
        match pool.install(|| table8_world(&s, crate::sweep::realisation_seed(s.seed, r), args.pool)) {
            Ok(w) => worlds.push(w),
            Err(e) => eprintln!("warning: realisation {r} left out: {e}"),
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    if worlds.is_empty() {
        return Err(format!("{}: no realisation could be calibrated", args.scenario.display()));
    }
    let p = &crate::study::published::published().trical_2018;
    println!(
        "{:<16} {:>26} {:>44}",
        "instrument",
        "published median / std / max",
        format!("calsim median / std / max (median of {} worlds; P10-P90 of the median)", worlds.len())
    );
    for (k, name) in ["TriCal", "laser tracker", "optical CMM"].iter().enumerate() {
        let row = p.table8(name);
        let col = |m: usize| crate::study::stats::median(&worlds.iter().map(|w| w[k][m]).collect::<Vec<_>>());
        let meds = crate::study::stats::finite_sorted(&worlds.iter().map(|w| w[k][0]).collect::<Vec<_>>());
        let q = |x: f64| crate::study::stats::quantile(&meds, x);
        println!(
            "{name:<16} {:>10.3} / {:.3} / {:.3} {:>14.3} / {:.3} / {:.3}  ({:.3}-{:.3})",
            row.median_mm,
            row.std_mm,
            row.max_mm,
            col(0),
            col(1),
            col(2),
            q(0.1),
            q(0.9)
        );
    }
    println!("timing: {:.3} s", t0.elapsed().as_secs_f64());
    Ok(ExitCode::SUCCESS)
}

fn demo(args: &DemoArgs) -> Result<(), String> {
    if !(args.noise_um.is_finite() && args.noise_um >= 0.0) {
        return Err(format!("--noise-um {}: must be a finite number >= 0", args.noise_um));
    }
    let t0 = Instant::now();
    let truth = trical_2018_table7();
    let nominal = trical_2018_nominal();
    let set = ParamSet::trical_31();
    let mut rng = ChaCha8Rng::seed_from_u64(args.seed);
    let noise = Normal::new(0.0, args.noise_um * 1e-3).map_err(|e| e.to_string())?;
    let mut st = KinState::default();
    let obs: Vec<Observation> = (0..args.configurations)
        .map(|_| {
            let q = uniform_configuration(&truth, 0.1, &mut rng);
            let mut p = forward(&truth, &mut st, &q);
            for k in 0..3 {
                p[k] += noise.sample(&mut rng);
            }
            Observation { q, tcp_world_mm: p }
        })
        .collect();
    let solver = match args.solver {
        SolverArg::Gn => Solver::GaussNewton,
        SolverArg::Lm => Solver::LevenbergMarquardt { tau: 1e-3 },
    };
    let t_fit = Instant::now();
    let fit = identify(&nominal, &set, &obs, &FitOptions { solver, ..FitOptions::default() });
    let fit_s = t_fit.elapsed().as_secs_f64();

    println!(
        "calsim demo: {} ({} configurations, noise {} um per axis, seed {})",
        truth.name(),
        args.configurations,
        args.noise_um,
        args.seed
    );
    println!(
        "outcome {}, {} iterations, condition number {:.1}, residual RMS {:.4} mm, {:.0} us",
        fit.outcome.label(),
        fit.iterations,
        fit.condition_number,
        fit.residual_rms_mm,
        fit_s * 1e6
    );
    println!("\n{:<12} {:>11} {:>12} {:>12} {:>12}  unit", "parameter", "nominal", "truth", "identified", "error");
    for (id, v) in set.ids().iter().zip(&fit.values) {
        let u = id.unit();
        let nom = u.from_internal(id.get(nominal.data()));
        let tru = u.from_internal(id.get(truth.data()));
        match v {
            Some(v) => {
                let v = u.from_internal(*v);
                println!("{:<12} {:>11.3} {:>12.4} {:>12.4} {:>12.5}  {}", id.name(), nom, tru, v, v - tru, u.symbol());
            }
            None => println!("{:<12} {:>11.3} {:>12.4} {:>12} {:>12}  {}", id.name(), nom, tru, "-", "-", u.symbol()),
        }
    }
    let validation: Vec<_> = (0..args.validation).map(|_| uniform_configuration(&truth, 0.0, &mut rng)).collect();
    let stats = |model: &crate::robot::RobotModel| {
        let mut st = KinState::default();
        let mut st2 = KinState::default();
        let errs: Vec<f64> = validation.iter().map(|q| (forward(model, &mut st, q) - forward(&truth, &mut st2, q)).norm()).collect();
        let mean = errs.iter().sum::<f64>() / errs.len() as f64;
        let max = errs.iter().copied().fold(0.0, f64::max);
        (mean, max)
    };
    let (b_mean, b_max) = stats(&nominal);
    println!("\nvalidation over {} random configurations (position error against the truth):", args.validation);
    println!("  before calibration: mean {b_mean:.3} mm, max {b_max:.3} mm");
    if let Some(model) = &fit.model {
        let (a_mean, a_max) = stats(model);
        println!("  after calibration:  mean {a_mean:.4} mm, max {a_max:.4} mm");
    }
    println!("total {:.3} s", t0.elapsed().as_secs_f64());
    Ok(())
}

#[cfg(test)]
mod compact_tests {
    use super::compact_numbers;

    #[test]
    fn long_numbers_are_written_with_an_exponent() {
        let huge = format!("[robot] payload_kg = {}: must be <= 1000", 1e300_f64);
        assert_eq!(compact_numbers(&huge), "[robot] payload_kg = 1e300: must be <= 1000");
        let tiny = format!("x = -{} mm", 1.5e-300_f64);
        assert_eq!(compact_numbers(&tiny), "x = -1.5e-300 mm");
        // Numbers of ordinary length, versions and whole numbers of u64 stay as written.
        let plain = "m.toml: axis[0] (study.repetitions) = 18446744073709551615, 0.208 mm, calsim 0.1.0";
        assert_eq!(compact_numbers(plain), plain);
        // Long digit runs inside a path or a word are not numbers.
        let path = "/tmp/run12345678901234567890123456789/a.toml: x = 2";
        assert_eq!(compact_numbers(path), path);
    }
}
