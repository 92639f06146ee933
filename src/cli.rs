//! Command-line interface: argument parsing and the terminal report. Errors are printed as one
//! line and exit with code 2 (bad input) or 1 (a check that failed).

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};

use crate::app::message::one_line;
use crate::app::{self, Observer};
use crate::study::check::{distribution_table, terminal_table, terminal_table_with_spread};

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
    /// Run a design sweep (grid points x realisations), or one shard of it; unsharded, merge it too.
    Sweep(SweepArgs),
    /// Merge the shard directories of one sweep into its results.
    Merge(MergeArgs),
    /// Search a design file's space (sphere count and positions, plate, set size, any key) for its
    /// objective; race the finalists; verify them on held-out worlds (docs/optimise.md).
    Optimise(OptimiseArgs),
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
    /// Calibrate a real robot from measured data (docs/calibrate.md): robot file, URDF, YAML and a report.
    Calibrate(CalibrateArgs),
    /// Write a simulated measurement file for `calsim calibrate` from a simulation file (a robot
    /// file's [truth] measured in sessions, lines and at targets: docs/calibrate.md).
    SimulateMeasurements(SimulateMeasurementsArgs),
    /// The poses to measure on a real robot with a laser tracker, and the accuracy they will buy
    /// (docs/plan.md): a calibrate measurement file to fill, a joint list, a tour, plan.md.
    Plan(PlanArgs),
    /// The tool frame, gravity torques and joint deflections of a robot file's arm at each row of
    /// a joints CSV (header q1_deg,...,q6_deg).
    Fk(FkArgs),
    /// Every key of a scenario (trical, spms, tracker), sweep or robot file: unit, default, rules,
    /// SOURCED / ASSUMED / FITTED note (docs/reference.md).
    Keys(KeysArgs),
    /// Write a commented starting scenario of a device, every key at its default.
    Init(InitArgs),
    /// Print the completion script of a shell (bash, zsh, fish, elvish, powershell).
    Completions(CompletionsArgs),
}

#[derive(clap::Args, Debug)]
struct KeysArgs {
    /// trical, spms, tracker, sweep or robot (default: every one).
    name: Option<String>,
    /// The whole reference as Markdown (docs/reference.md).
    #[arg(long, conflicts_with = "name")]
    markdown: bool,
}

#[derive(clap::Args, Debug)]
struct InitArgs {
    /// The device: trical, spms or tracker.
    kind: String,
    /// The scenario file to write (default: standard output); an existing file is not replaced.
    file: Option<PathBuf>,
}

#[derive(clap::Args, Debug)]
struct CompletionsArgs {
    /// The shell.
    shell: clap_complete::Shell,
}

#[derive(clap::Args, Debug)]
struct CalibrateArgs {
    /// The robot file (nominal model, joint limits, optional [[coupling]]).
    robot: PathBuf,
    /// The measurement file (CSV, layout in docs/calibrate.md).
    measurements: PathBuf,
    /// Directory the report goes to (in `<measurements stem>.calibration`).
    #[arg(long, default_value = "results")]
    out: PathBuf,
    /// Cross-validation folds.
    #[arg(long, allow_negative_numbers = true, default_value_t = 5, value_parser = clap::value_parser!(u32).range(2..=20))]
    folds: u32,
    /// How the k-fold cross-validation over every pose (the figure comparable with the
    /// literature's) groups the poses: `pose` (--folds folds of each session's poses) or `session`
    /// (a fold per session).
    #[arg(long, default_value = "pose", value_parser = ["pose", "session"])]
    kfold_by: String,
    /// Fraction of each session's poses held out, drawn at random (default: the file's `split`
    /// column when it has one, else 0.2).
    #[arg(long, allow_negative_numbers = true, conflicts_with_all = ["hold_out_session", "hold_out_file"])]
    hold_out: Option<f64>,
    /// Hold out every pose of this session instead.
    #[arg(long, conflicts_with = "hold_out_file")]
    hold_out_session: Option<String>,
    /// Hold out the poses listed in this CSV file (columns `session,pose`, a row per pose).
    #[arg(long)]
    hold_out_file: Option<PathBuf>,
    /// Seed of the split, the folds and the prediction's draws.
    #[arg(long, allow_negative_numbers = true, default_value_t = 1)]
    seed: u64,
    /// Robot parameters of the most complete model, comma-separated (default: the TriCal set less the base).
    #[arg(long, value_delimiter = ',')]
    params: Option<Vec<String>>,
    /// Outlier threshold, robust standard deviations of a point's residual (default 4.5943).
    #[arg(long, allow_negative_numbers = true)]
    outlier_threshold: Option<f64>,
    /// What flagged points do: `off` (none flagged), `report` (flagged, listed, kept in every fit
    /// and figure) or `reject` (flagged, listed, left out of every fit and figure).
    #[arg(long, default_value = "report", value_parser = ["off", "report", "reject"])]
    outliers: String,
    /// Also simulate the calibration's plan over this many worlds (by default the twin: the
    /// calibrated robot with its learned effects and repeatability, the instrument's noise;
    /// calibrated again each time) and set the measured held-out median beside it (plan.md); 0: none.
    #[arg(long, allow_negative_numbers = true, default_value_t = 0, value_parser = clap::value_parser!(u32).range(0..=crate::calibrate::MOST_PLAN_WORLDS as i64))]
    plan_worlds: u32,
    /// The plan's instrument noise per coordinate, mm, for the twin and noise-only plans (default:
    /// the twin's instrument noise: --instrument-noise-mm, the points' sigma column, or estimated).
    #[arg(long, allow_negative_numbers = true)]
    plan_noise_mm: Option<f64>,
    /// The scenario that planned the calibration: its robot's effects outside the model
    /// ([robot.unmodelled]) and repeatability are drawn in each world of the plan.
    #[arg(long)]
    plan_scenario: Option<PathBuf>,
    /// A lumped payload at the flange, kg (the SMR nest or probe), in place of the robot file's
    /// [payload]: the mass the joint compliances act through (a robot file without masses has no
    /// gravity torque).
    #[arg(long, allow_negative_numbers = true)]
    payload_kg: Option<f64>,
    /// The payload's centre of mass in the flange frame, mm: x,y,z (default 0,0,0; needs --payload-kg).
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true, requires = "payload_kg")]
    payload_com_mm: Option<Vec<f64>>,
    /// The orientation readings' uncertainty about each axis when the file has no sigma_deg column,
    /// mdeg (default 10; six-degree-of-freedom probes: the quat_w..quat_z columns).
    #[arg(long, allow_negative_numbers = true)]
    orientation_noise_mdeg: Option<f64>,
    /// The positions' uncertainty per coordinate the rotation residuals are weighted against when
    /// the file has orientation columns and no sigma_mm column, mm (default 0.025).
    #[arg(long, allow_negative_numbers = true)]
    position_noise_mm: Option<f64>,
    /// A tool per session: each session's targets get their own position on the flange (a probe
    /// or SMR nest re-mounted between sessions); a session held out whole has its tools registered
    /// with its base on its own points.
    #[arg(long)]
    tool_per_session: bool,
    /// What each plan world draws: `twin` (the twin's robot, learned effects, repeatability and
    /// the instrument's noise), `noise` (the instrument's noise alone), `residual` (the fit's
    /// residual as white noise) or `all` (one row each in plan.md).
    #[arg(long, value_parser = crate::calibrate::plan::PlanWith::NAMES)]
    plan_with: Option<String>,
    /// The instrument's noise per coordinate, mm, as stated (default: the points' sigma column,
    /// else estimated from distances between targets measured at one pose).
    #[arg(long, allow_negative_numbers = true)]
    instrument_noise_mm: Option<f64>,
    /// Skip the figures.
    #[arg(long)]
    no_plots: bool,
}

#[derive(clap::Args, Debug)]
struct PlanArgs {
    /// The plan file (TOML, keys in docs/plan.md).
    plan: PathBuf,
    /// Directory the plan goes to (in `<plan stem>.plan`).
    #[arg(long, default_value = "results")]
    out: PathBuf,
    /// Worker threads (default: RAYON_NUM_THREADS, else every core).
    #[arg(long, allow_negative_numbers = true)]
    threads: Option<u32>,
    /// Also write simulated.csv: the poses measured on the robot file's truth with the tracker's
    /// noise (a device plan: the planning world's true arm with the pool's observation error).
    #[arg(long)]
    simulate: bool,
    /// Skip the Rerun recording (plan.rrd).
    #[arg(long)]
    no_recording: bool,
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
struct SimulateMeasurementsArgs {
    /// The simulation file (TOML: robot, seed, poses_per_session, noise_mm, [[session]],
    /// [[target]], [[line]]; docs/calibrate.md).
    spec: PathBuf,
    /// The directory to write `<spec stem>.csv` in (created; an existing file is not replaced).
    #[arg(long)]
    out: PathBuf,
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
    #[arg(long, allow_negative_numbers = true, conflicts_with_all = ["set_size", "pick"])]
    task: Option<usize>,
    /// Set size to pick from (default: the scenario's table set size, 75 in the paper).
    #[arg(long, allow_negative_numbers = true, value_parser = clap::value_parser!(u32).range(1..=100_000))]
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
    #[arg(long, allow_negative_numbers = true, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=10_000))]
    realisations: u32,
    /// Configurations of each external instrument's pool (random in the workspace, in its view).
    #[arg(long, allow_negative_numbers = true, default_value_t = 360, value_parser = clap::value_parser!(u32).range(100..=100_000))]
    pool: u32,
    /// Worker threads (default: all cores).
    #[arg(long, allow_negative_numbers = true, value_parser = clap::value_parser!(u32).range(1..=1024))]
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
    #[arg(long, allow_negative_numbers = true, default_value_t = 20, value_parser = clap::value_parser!(u32).range(1..=10_000))]
    realisations: u32,
    /// What-if factors applied to each source in turn, comma-separated.
    #[arg(long, value_delimiter = ',', default_values_t = [0.5, 2.0], value_parser = parse_factor)]
    factors: Vec<f64>,
    /// Repetitions per configuration and realisation, replacing the scenario's.
    #[arg(long, allow_negative_numbers = true, value_parser = clap::value_parser!(u32).range(1..=crate::study::MAX_REPETITIONS as i64))]
    repetitions: Option<u32>,
    /// Worker threads (default: all cores).
    #[arg(long, allow_negative_numbers = true, value_parser = clap::value_parser!(u32).range(1..=1024))]
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
    #[arg(long, allow_negative_numbers = true, value_parser = clap::value_parser!(u32).range(1..=1024))]
    threads: Option<u32>,
    /// Realisations replacing the file's count (or the most of an adaptive sweep).
    #[arg(long, allow_negative_numbers = true, value_parser = clap::value_parser!(u32).range(1..=10_000))]
    realisations: Option<u32>,
}

#[derive(clap::Args, Debug)]
struct OptimiseArgs {
    /// Design file (TOML), e.g. scenarios/designs/irb120_spheres.toml.
    design: PathBuf,
    /// Directory of the evaluations and of the results.
    #[arg(long, default_value = "results")]
    out: PathBuf,
    /// Run only the restarts r with r % K == k (k/K); then `--merge`.
    #[arg(long, value_parser = parse_shard)]
    shard: Option<(usize, usize)>,
    /// Only merge finished restarts: race the finalists, verify, write the results.
    #[arg(long, conflicts_with = "shard")]
    merge: bool,
    /// Worker threads (default: all cores).
    #[arg(long, allow_negative_numbers = true, value_parser = clap::value_parser!(u32).range(1..=1024))]
    threads: Option<u32>,
    /// Search method replacing the file's: nelder_mead, particle_swarm or cmaes.
    #[arg(long, value_parser = parse_method)]
    method: Option<crate::design::optimise::spec::Method>,
    /// Skip the figures.
    #[arg(long)]
    no_plots: bool,
}

fn parse_method(s: &str) -> Result<crate::design::optimise::spec::Method, String> {
    use crate::design::optimise::spec::Method;
    match s {
        "nelder_mead" => Ok(Method::NelderMead),
        "particle_swarm" => Ok(Method::ParticleSwarm),
        "cmaes" => Ok(Method::Cmaes),
        _ => Err(format!("`{s}`: nelder_mead, particle_swarm or cmaes")),
    }
}

fn optimise(args: &OptimiseArgs) -> Result<ExitCode, String> {
    let spec = app::optimise::OptimiseSpec {
        file: args.design.clone(),
        out: args.out.clone(),
        shard: args.shard,
        merge: args.merge,
        threads: args.threads,
        method: args.method,
        plots: !args.no_plots,
    };
    let r = app::optimise::run(&spec, &Terminal::new()).map_err(|e| e.to_string())?;
    println!(
        "timing: {} restarts, {} designs evaluated in {:.1} s; race and verification {:.1} s",
        r.restarts, r.evaluations, r.search_s, r.finish_s
    );
    if let Some(c) = &r.cost {
        println!("one world of the winner: {c}");
    }
    match (&r.summary, &r.dest) {
        (Some(s), Some(d)) => {
            println!("{s}");
            println!("results in {}", d.display());
        }
        _ => println!(
            "merge the restarts when every shard has run: calsim optimise {} --merge --out {}",
            args.design.display(),
            args.out.display()
        ),
    }
    Ok(ExitCode::SUCCESS)
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
    #[arg(long, allow_negative_numbers = true, value_parser = clap::value_parser!(u32).range(1..=1024))]
    threads: Option<u32>,
    /// Seed, replacing the scenario's.
    #[arg(long, allow_negative_numbers = true)]
    seed: Option<u64>,
    /// Set sizes as start:end:step (inclusive), replacing the scenario's.
    #[arg(long, value_parser = parse_sizes)]
    set_sizes: Option<SetSizes>,
    /// Repetitions per set size, replacing the scenario's.
    #[arg(long, allow_negative_numbers = true, value_parser = clap::value_parser!(u32).range(1..=crate::study::MAX_REPETITIONS as i64))]
    repetitions: Option<u32>,
    /// Skip the figures (PNG and SVG of the paper's Figs. 7-13).
    #[arg(long)]
    no_plots: bool,
    /// Skip the Rerun recording (study.rrd).
    #[arg(long)]
    no_recording: bool,
    /// Judge every figure over this many realisations (worlds) of the scenario, as a test: a figure
    /// misses when the interval of its median over them lies wholly outside its band. Realisation 0
    /// is the run whose results are written [default: 1 for run, the scenario's
    /// study.check_realisations for check].
    #[arg(long, allow_negative_numbers = true, value_parser = clap::value_parser!(u32).range(1..=crate::study::MAX_CHECK_REALISATIONS as i64))]
    realisations: Option<u32>,
    /// The check's false-alarm rate over realisations: the probability that a model whose medians
    /// meet every band fails [default: the scenario's study.check_false_alarm, 0.01].
    #[arg(long, allow_negative_numbers = true)]
    false_alarm: Option<f64>,
    /// Also write the check's verdict as JUnit XML to this file (check.json is always written).
    #[arg(long)]
    junit: Option<PathBuf>,
    /// Also print the figures of realisation 0, the one world whose results are written (`check`
    /// over several worlds prints only the verdict over them without it).
    #[arg(long)]
    single_world: bool,
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

/// Output piped into a reader that stops early (`calsim plan ... | head -n 1`): the print that finds
/// the pipe closed ends the process quietly with the shells' status for SIGPIPE (128 + 13), as a
/// Unix filter does, instead of a panic's backtrace. Every other panic keeps the default report.
fn quiet_on_a_closed_pipe() {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let message = info
            .payload()
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| info.payload().downcast_ref::<&str>().copied())
            .unwrap_or_default();
        if message.starts_with("failed printing to stdout") && message.contains("Broken pipe") {
            std::process::exit(141);
        }
        default(info);
    }));
}

/// Entry point of the binary.
pub fn main() -> ExitCode {
    quiet_on_a_closed_pipe();
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
            eprintln!("{}", if said.is_empty() { "error: bad command line".to_string() } else { one_line(&said.join(" ")) });
            return ExitCode::from(2);
        }
    };
    let result = match &cli.command {
        Command::Run(args) => run(args, false),
        Command::Check(args) => run(args, true),
        Command::Sweep(args) => sweep(args),
        Command::Merge(args) => merge(&args.shards, &args.out),
        Command::Optimise(args) => optimise(args),
        Command::Budget(args) => budget(args),
        Command::Table8(args) => table8(args),
        Command::Export(args) => export(args),
        Command::Compensate(args) => compensate(args),
        Command::ImportUrdf(args) => import_urdf(args),
        Command::Calibrate(args) => calibrate(args),
        Command::SimulateMeasurements(args) => simulate_measurements(args),
        Command::Plan(args) => plan(args),
        Command::Fk(args) => fk(args),
        Command::Keys(args) => keys(args),
        Command::Init(args) => init(args),
        Command::Completions(args) => {
            use clap::CommandFactory;
            clap_complete::generate(args.shell, &mut Cli::command(), "calsim", &mut std::io::stdout());
            Ok(ExitCode::SUCCESS)
        }
    };
    match result {
        Ok(code) => code,
        Err(msg) => {
            eprintln!("error: {}", one_line(&msg));
            ExitCode::from(2)
        }
    }
}

/// The terminal's observer: the start line and warnings on standard error, a progress bar per stage
/// on a terminal; where standard error is not a terminal (a log, a pipe, CI), a plain progress line
/// every `PLAIN_EVERY` at most, none for a stage shorter than that.
struct Terminal {
    bar: Mutex<Option<ProgressBar>>,
    /// `Some` where standard error is not a terminal: when the stage began and when it last printed.
    plain: Option<Mutex<Option<(Instant, Instant)>>>,
}

/// The least time between two plain progress lines, and before the first.
const PLAIN_EVERY: Duration = Duration::from_secs(10);

impl Terminal {
    fn new() -> Self {
        let plain = (!std::io::stderr().is_terminal()).then(|| Mutex::new(None));
        Self { bar: Mutex::new(None), plain }
    }
}

/// A plain progress line: `done/total what, elapsed`.
fn plain_progress(done: usize, total: usize, what: &str, elapsed: Duration) -> String {
    let s = elapsed.as_secs();
    let shown = if s >= 60 { format!("{} min {:02} s", s / 60, s % 60) } else { format!("{s} s") };
    format!("{done}/{total} {what}, {shown} elapsed")
}

impl Observer for Terminal {
    fn started(&self, line: &str) {
        eprintln!("{}", one_line(line));
    }

    fn progress(&self, done: usize, total: usize, what: &str) {
        if let Some(plain) = &self.plain {
            let now = Instant::now();
            let mut state = plain.lock().unwrap_or_else(|e| e.into_inner());
            let (began, last) = state.get_or_insert((now, now));
            if now.duration_since(*last) >= PLAIN_EVERY {
                *last = now;
                eprintln!("{}", plain_progress(done, total, what, now.duration_since(*began)));
            }
            return;
        }
        let mut bar = self.bar.lock().unwrap_or_else(|e| e.into_inner());
        let b = bar.get_or_insert_with(|| {
            let b = ProgressBar::new(total as u64);
            let template = format!("{{bar:40}} {{pos}}/{{len}} {what}, {{elapsed}} elapsed, ETA {{eta}}");
            b.set_style(ProgressStyle::with_template(&template).unwrap_or_else(|_| ProgressStyle::default_bar()));
            b
        });
        b.set_length(total as u64);
        b.set_position(done as u64);
    }

    fn stage_done(&self) {
        if let Some(plain) = &self.plain {
            *plain.lock().unwrap_or_else(|e| e.into_inner()) = None;
        }
        if let Some(b) = self.bar.lock().unwrap_or_else(|e| e.into_inner()).take() {
            b.finish_and_clear();
        }
    }

    fn warning(&self, line: &str) {
        self.stage_done();
        eprintln!("warning: {}", one_line(line));
    }
}

/// `run` / `check` of a scenario of any device.
fn run(args: &RunArgs, check: bool) -> Result<ExitCode, String> {
    let spec = app::run::RunSpec {
        scenario: args.scenario.clone(),
        out: args.out.clone(),
        threads: args.threads,
        overrides: app::run::Overrides {
            seed: args.seed,
            set_sizes: args.set_sizes.as_ref().map(|s| s.0.clone()),
            repetitions: args.repetitions,
        },
        plots: !args.no_plots,
        recording: !args.no_recording,
        realisations: args.realisations,
        false_alarm: args.false_alarm,
        junit: args.junit.clone(),
        check,
    };
    let r = app::run::run(&spec, &Terminal::new()).map_err(|e| e.to_string())?;
    let timing =
        format!("timing: {}, results written in {:.3} s (recording {:.3} s) to {}", r.timing, r.write_s, r.recording_s, r.dest.display());
    match &r.distribution {
        Some(d) => {
            println!(
                "over {} realisations: a figure misses when the interval of its median lies wholly outside its band, open when it \
                 straddles an edge, unresolved (a failure) when too few worlds gave it a value for a bounded interval; false-alarm \
                 rate {} over the figures checked",
                r.realisations_run, r.false_alarm
            );
            println!("{}", distribution_table(d));
            if args.single_world || !check {
                println!("realisation 0, the world whose results are written (one draw of each figure):");
                println!("{}", terminal_table(&r.checks, false));
            }
        }
        // A check over one world judges that world's values; a run shows them as one draw.
        None if check => println!("{}", terminal_table(&r.checks, true)),
        None => {
            match &r.cached_spread {
                Some((worlds, spread)) => println!("{}", terminal_table_with_spread(&r.checks, *worlds, spread)),
                None => println!("{}", terminal_table(&r.checks, false)),
            }
            println!("One simulated world: one draw of each figure. Whether the model reproduces a figure is judged over worlds:");
            // The scenario's own check when it judges over worlds; otherwise the worlds to ask for.
            let worlds = match r.check_worlds {
                (n, _) if n > 1 => String::new(),
                (_, fewest) => format!(" --realisations {}", fewest.max(30)),
            };
            println!("`calsim check {}{worlds}`.", args.scenario.display());
        }
    }
    println!("{timing}");
    if !check {
        return Ok(ExitCode::SUCCESS);
    }
    let (checked, missed) = r.tally();
    if checked == 0 {
        // A check that judges nothing must not pass (a CI gate on it would pass vacuously).
        return Err(format!(
            "{}: [expect]: the scenario sets no band, so check has nothing to judge (its run is in {}); `calsim keys {}` lists the \
             [expect] keys, `calsim run` runs a scenario without them",
            args.scenario.display(),
            r.dest.display(),
            r.kind
        ));
    }
    match r.distribution {
        Some(_) => println!(
            "check: {} of {checked} figures not missed over {} realisations (false-alarm rate {}); verdict in {}",
            checked - missed,
            r.realisations_run,
            r.false_alarm,
            r.dest.join("check.json").display()
        ),
        None => println!("check: {} of {checked} figures within their bands", checked - missed),
    }
    Ok(if missed > 0 { ExitCode::from(1) } else { ExitCode::SUCCESS })
}

fn sweep(args: &SweepArgs) -> Result<ExitCode, String> {
    let spec = app::sweep::SweepSpec {
        file: args.sweep.clone(),
        out: args.out.clone(),
        shard: args.shard,
        threads: args.threads,
        realisations: args.realisations,
    };
    let r = app::sweep::run(&spec, &Terminal::new()).map_err(|e| e.to_string())?;
    let (k, count) = r.shard;
    // A whole sweep's shard directory is removed once merged: the merge's line names the results.
    let written = if r.merged.is_some() { String::new() } else { format!(" to {}", r.shard_dir.display()) };
    println!(
        "timing: {} work units of shard {k}/{count} in {:.3} s ({:.3} s per unit){written}",
        r.units,
        r.run_s,
        r.run_s / r.units.max(1) as f64,
    );
    match &r.merged {
        None if r.plan.complete => println!(
            "merge the shards with: calsim merge {}/{}.shard-*-of-{count} --out {}",
            args.out.display(),
            r.name,
            args.out.display()
        ),
        None if !r.adaptive => println!(
            "sweep incomplete: {} work units of other shards still to run; when every shard has run, merge the shards with: \
             calsim merge {}/{}.shard-*-of-{count} --out {}",
            r.plan.missing.len(),
            args.out.display(),
            r.name,
            args.out.display()
        ),
        None => println!(
            "adaptive sweep at stage {}: {} work units still to run in this stage (this shard's and others'); when every shard \
             of this stage has run, run every shard again for the next stage, then merge",
            r.plan.stage,
            r.plan.missing.len()
        ),
        Some(m) => print_merge(m),
    }
    Ok(ExitCode::SUCCESS)
}

fn print_merge(m: &app::sweep::MergeReport) {
    println!("{}", m.summary);
    println!("merged {} work units ({} failed) into {}", m.units, m.failed, m.dest.display());
}

fn merge(shards: &[PathBuf], out: &Path) -> Result<ExitCode, String> {
    let m = app::sweep::merge(shards, out).map_err(|e| e.to_string())?;
    print_merge(&m);
    Ok(ExitCode::SUCCESS)
}

fn import_urdf(args: &ImportUrdfArgs) -> Result<ExitCode, String> {
    let options = app::import_urdf::ImportOptions { package_root: args.package_root.clone(), visual_fallback: args.visual_meshes };
    let r = app::import_urdf::run(&args.urdf, &args.out, &options).map_err(|e| e.to_string())?;
    for line in &r.lines {
        println!("{line}");
    }
    Ok(ExitCode::SUCCESS)
}

fn simulate_measurements(args: &SimulateMeasurementsArgs) -> Result<ExitCode, String> {
    let r = app::simulate::run(&args.spec, Some(&args.out)).map_err(|e| e.to_string())?;
    if let Some(path) = &r.written {
        println!("simulate-measurements: {} ({} rows)", path.display(), r.rows);
    }
    Ok(ExitCode::SUCCESS)
}

fn fk(args: &FkArgs) -> Result<ExitCode, String> {
    let spec = app::fk::FkSpec { robot: args.robot.clone(), joints: args.joints.clone(), out: args.out.clone() };
    let r = app::fk::run(&spec).map_err(|e| e.to_string())?;
    if args.out.is_none() {
        print!("{}", r.csv);
    }
    Ok(ExitCode::SUCCESS)
}

fn keys(args: &KeysArgs) -> Result<ExitCode, String> {
    if args.markdown {
        print!("{}", app::keys::markdown().map_err(|e| e.to_string())?);
        return Ok(ExitCode::SUCCESS);
    }
    let names = match &args.name {
        Some(n) => vec![n.as_str()],
        None => app::keys::names(),
    };
    let texts: Vec<String> = names.iter().map(|n| app::keys::text(n)).collect::<Result<_, _>>().map_err(|e| e.to_string())?;
    print!("{}", texts.join("\n"));
    Ok(ExitCode::SUCCESS)
}

fn init(args: &InitArgs) -> Result<ExitCode, String> {
    let text = app::keys::init_file(&args.kind, args.file.as_deref()).map_err(|e| e.to_string())?;
    match &args.file {
        None => print!("{text}"),
        Some(f) => eprintln!("calsim init: wrote {} (run it with `calsim run {}`)", f.display(), f.display()),
    }
    Ok(ExitCode::SUCCESS)
}

fn plan_device(spec: &app::plan::PlanSpec) -> Result<ExitCode, String> {
    let r = app::plan::plan_device(spec, &Terminal::new()).map_err(|e| e.to_string())?;
    print_plan(&r.frames, crate::plan::device_summary::terminal_line(r.seconds), "kept at their values before calibration")?;
    println!(
        "poses.csv, joints.txt, tour.csv, plan.md, plan_poses.png{}{} in {}",
        if spec.simulate { ", simulated.csv" } else { "" },
        if spec.recording { " and the recording plan.rrd" } else { "" },
        r.dir.display()
    );
    Ok(ExitCode::SUCCESS)
}

/// What `calsim plan` prints of a plan, read from its tables ([`crate::plan::summary::terminal`]):
/// its line (`line`), its objective, the parameters it cannot identify (`kept`: what becomes of
/// them) and its tour's re-routed moves; moves no via path was found for as a warning.
fn print_plan(
    frames: &[(String, crate::io::table::Frame)],
    line: impl Fn(&crate::io::results::Row<'_>) -> String,
    kept: &str,
) -> Result<(), String> {
    let (out, warning) = crate::plan::summary::terminal(frames, line, kept).map_err(|e| e.to_string())?;
    print!("{out}");
    if let Some(w) = warning {
        eprintln!("warning: {w}");
    }
    Ok(())
}

fn plan(args: &PlanArgs) -> Result<ExitCode, String> {
    let spec = app::plan::PlanSpec {
        file: args.plan.clone(),
        out: args.out.clone(),
        threads: args.threads,
        simulate: args.simulate,
        recording: !args.no_recording,
    };
    if app::plan::is_device_plan(&spec.file).map_err(|e| e.to_string())? {
        return plan_device(&spec);
    }
    let r = app::plan::plan(&spec, &Terminal::new()).map_err(|e| e.to_string())?;
    print_plan(&r.frames, crate::plan::summary::terminal_line(r.seconds), "kept nominal")?;
    println!(
        "poses.csv, joints.txt, tour.csv, plan.md, plan_poses.png{}{} in {}",
        if args.simulate { ", simulated.csv" } else { "" },
        if args.no_recording { "" } else { " and the recording plan.rrd" },
        r.dir.display()
    );
    Ok(ExitCode::SUCCESS)
}

fn calibrate(args: &CalibrateArgs) -> Result<ExitCode, String> {
    let spec = app::calibrate::CalibrateArgs {
        folds: args.folds,
        kfold_by: Some(args.kfold_by.clone()),
        hold_out: args.hold_out,
        hold_out_session: args.hold_out_session.clone(),
        hold_out_file: args.hold_out_file.clone(),
        seed: args.seed,
        params: args.params.clone(),
        outlier_threshold: args.outlier_threshold,
        outliers: Some(args.outliers.clone()),
        plan_worlds: args.plan_worlds,
        plan_noise_mm: args.plan_noise_mm,
        plan_scenario: args.plan_scenario.clone(),
        plan_with: args.plan_with.clone(),
        instrument_noise_mm: args.instrument_noise_mm,
        plots: !args.no_plots,
        tool_per_session: args.tool_per_session,
        payload_kg: args.payload_kg,
        payload_com_mm: args.payload_com_mm.clone(),
        orientation_noise_mdeg: args.orientation_noise_mdeg,
        position_noise_mm: args.position_noise_mm,
        ..app::calibrate::CalibrateArgs::new(args.robot.clone(), args.measurements.clone(), args.out.clone())
    };
    let report = app::calibrate::run(&spec).map_err(|e| e.to_string())?;
    if let Some(line) = crate::calibrate::report::outlier_warning(&report.calibration) {
        eprintln!("{line}");
    }
    println!("{}", crate::calibrate::report::terminal(&report.calibration, &report.dir));
    for (kind, p) in &report.plans {
        let [a, b, c] = p.simulated_mm;
        println!(
            "plan ({}): held-out {} {:.4} mm measured; simulated from {} over {} worlds: {b:.4} mm (P10-P90 {a:.4}-{c:.4}), {} (plan.md)",
            kind.name(),
            p.statistic.name(),
            p.measured_mm,
            p.scenario,
            p.worlds,
            if p.inside { "inside" } else { "OUTSIDE: the robot does something this plan does not draw" }
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// `compensate`: exit 0 when every target is reached, 1 when some cannot be (their rows say
/// `unreachable`, a line on standard error counts them), 2 when none can (nothing written).
fn compensate(args: &CompensateArgs) -> Result<ExitCode, String> {
    let spec = app::compensate::CompensateSpec {
        model: args.model.clone(),
        targets: args.targets.clone(),
        nominal: args.nominal.clone(),
        out: args.out.clone(),
    };
    let r = app::compensate::run(&spec).map_err(|e| e.to_string())?;
    match &args.out {
        None => print!("{}", r.csv),
        Some(out) => {
            eprintln!("calsim compensate: {} targets, {} reached, written to {}", r.targets, r.targets - r.unreachable.len(), out.display())
        }
    }
    Ok(match r.unreachable_line() {
        Some(line) => {
            eprintln!("calsim compensate: {}", one_line(&line));
            ExitCode::from(1)
        }
        None => ExitCode::SUCCESS,
    })
}

fn export(args: &ExportArgs) -> Result<ExitCode, String> {
    use crate::app::export::Pick;
    let n = args.set_size.map(|n| n as usize);
    let pick = match (args.task, args.pick) {
        (Some(t), _) => Pick::Task(t),
        (None, PickArg::Median) => Pick::Median(n),
        (None, PickArg::Best) => Pick::Best(n),
        (None, PickArg::Worst) => Pick::Worst(n),
    };
    let (e, dest) = app::export::run(&args.results, pick, args.out.as_deref()).map_err(|e| e.to_string())?;
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
    let spec = app::budget::BudgetSpec {
        scenario: args.scenario.clone(),
        out: args.out.clone(),
        realisations: args.realisations,
        factors: args.factors.clone(),
        repetitions: args.repetitions,
        threads: args.threads,
    };
    let r = app::budget::run(&spec, &Terminal::new()).map_err(|e| e.to_string())?;
    println!("{}", r.summary);
    println!("timing: budget {:.3} s ({} work units) to {}", r.run_s, r.units, r.dest.display());
    Ok(ExitCode::SUCCESS)
}

fn table8(args: &Table8Args) -> Result<ExitCode, String> {
    let spec = app::table8::Table8Spec {
        scenario: args.scenario.clone(),
        realisations: args.realisations,
        pool: args.pool,
        threads: args.threads,
    };
    let r = app::table8::run(&spec, &Terminal::new()).map_err(|e| e.to_string())?;
    print!("{}", app::table8::terminal(&r.table, r.worlds).map_err(|e| e.to_string())?);
    println!("timing: {:.3} s", r.run_s);
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_plain_progress_line_counts_and_tells_the_elapsed_time_in_minutes_past_one() {
        assert_eq!(plain_progress(3, 10, "designs", Duration::from_secs(75)), "3/10 designs, 1 min 15 s elapsed");
        assert_eq!(plain_progress(0, 4, "worlds", Duration::from_millis(10_900)), "0/4 worlds, 10 s elapsed");
    }
}
