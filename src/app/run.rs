//! `run` and `check`: a study of any device in the scenario's world, its results written, its
//! published figures compared with their bands; with realisations, the figures judged over many
//! worlds.

use std::path::{Path, PathBuf};
use std::time::Instant;

use super::{Error, Observer, thread_pool, threads_label};
use crate::device::{Scenario, WriteOptions};
use crate::identify::FitOutcome;
use crate::study::check::{Check, CheckReport, DistributionCheck, over_realisations, tally};
use crate::study::engine::Identified;

/// Command-line changes to a scenario: the seed, the set sizes (the table size moves to the
/// nearest given size) and the repetitions.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Overrides {
    /// Seed, replacing the scenario's.
    pub seed: Option<u64>,
    /// Set sizes, replacing the scenario's.
    pub set_sizes: Option<Vec<u32>>,
    /// Repetitions per set size, replacing the scenario's.
    pub repetitions: Option<u32>,
}

impl Overrides {
    /// Applies the overrides to `s` and checks it again (`path` names it in errors).
    pub fn apply(&self, s: &mut dyn Scenario) -> Result<(), Error> {
        if self.is_empty() {
            return Ok(());
        }
        if let Some(seed) = self.seed {
            s.header_mut().seed = seed;
        }
        let st = s.study_mut();
        if let Some(sizes) = &self.set_sizes {
            // An empty list (a manifest edited by hand: the command line cannot give one) is left
            // to the re-check below, which names the key.
            if let Some(&nearest) = sizes.iter().min_by_key(|n| n.abs_diff(st.table_set_size)) {
                st.table_set_size = nearest;
            }
            st.set_sizes = sizes.clone();
        }
        if let Some(r) = self.repetitions {
            st.repetitions = r;
        }
        // Re-check what the overrides changed (sizes against the pool and the parameters).
        s.recheck(&format!("{} (with command-line overrides)", s.header().path.display()))?;
        Ok(())
    }

    /// Whether nothing is overridden.
    pub fn is_empty(&self) -> bool {
        *self == Self::default()
    }

    /// The overrides as `(key, TOML value)` pairs, as a manifest records them.
    pub fn pairs(&self) -> Vec<(String, String)> {
        let mut out = Vec::new();
        if let Some(s) = self.seed {
            out.push(("seed".into(), s.to_string()));
        }
        if let Some(v) = &self.set_sizes {
            out.push(("study.set_sizes".into(), format!("{v:?}")));
        }
        if let Some(r) = self.repetitions {
            out.push(("study.repetitions".into(), r.to_string()));
        }
        out
    }

    /// The overrides from the pairs of a manifest ([`Overrides::pairs`]); `None` for a pair calsim
    /// does not write.
    pub fn from_pairs(pairs: &[(String, String)]) -> Option<Self> {
        let mut o = Self::default();
        for (k, v) in pairs {
            let value: toml::Value = toml::from_str::<toml::Table>(&format!("v = {v}")).ok()?.remove("v")?;
            match k.as_str() {
                "seed" => o.seed = Some(u64::try_from(value.as_integer()?).ok()?),
                "study.set_sizes" => {
                    o.set_sizes = Some(
                        value.as_array()?.iter().map(|x| x.as_integer().and_then(|i| u32::try_from(i).ok())).collect::<Option<Vec<_>>>()?,
                    )
                }
                "study.repetitions" => o.repetitions = Some(u32::try_from(value.as_integer()?).ok()?),
                _ => return None,
            }
        }
        Some(o)
    }
}

/// What `run` and `check` are asked.
#[derive(Clone, Debug)]
pub struct RunSpec {
    /// The scenario file.
    pub scenario: PathBuf,
    /// The directory the results go in (in a subdirectory named after the scenario).
    pub out: PathBuf,
    /// Worker threads (`None`: `RAYON_NUM_THREADS`, else every core).
    pub threads: Option<u32>,
    /// Changes to the scenario.
    pub overrides: Overrides,
    /// Draw the figures.
    pub plots: bool,
    /// Write the Rerun recording.
    pub recording: bool,
    /// Worlds the figures are judged over (1: the scenario's own world only; `None`: one for
    /// `run`, the scenario's `study.check_realisations` for `check`).
    pub realisations: Option<u32>,
    /// The check's false-alarm rate over realisations (`None`: the scenario's
    /// `study.check_false_alarm`).
    pub false_alarm: Option<f64>,
    /// Also write the check's verdict as JUnit XML to this file.
    pub junit: Option<PathBuf>,
    /// Compare with the bands (`check`) rather than only report (`run`).
    pub check: bool,
}

/// What `run` and `check` did.
#[derive(Clone, Debug)]
pub struct RunReport {
    /// The scenario's name.
    pub name: String,
    /// Its device's kind.
    pub kind: &'static str,
    /// The seed of realisation 0.
    pub seed: u64,
    /// Worker threads.
    pub threads: usize,
    /// The published figures of realisation 0 beside calsim's.
    pub checks: Vec<Check>,
    /// The run's tables for a caller that takes frames (Python): `checks` (`checks.parquet`) and,
    /// over realisations, `distribution` (`checks_over_worlds.parquet`).
    pub frames: Vec<(String, polars::prelude::DataFrame)>,
    /// The study's timing line.
    pub timing: String,
    /// Wall time of writing the results, and of the recording within it, s.
    pub write_s: f64,
    /// See `write_s`.
    pub recording_s: f64,
    /// Where the results are.
    pub dest: PathBuf,
    /// The figures over realisations, when more than one was asked.
    pub distribution: Option<Vec<DistributionCheck>>,
    /// Realisations that ran (realisation 0 included).
    pub realisations_run: usize,
    /// The false-alarm rate the figures were judged at over realisations.
    pub false_alarm: f64,
    /// The verdict as written to `check.json` (a check only).
    pub check_report: Option<CheckReport>,
    /// Each figure's P10-P90 over worlds from an earlier `check` of the same world (its
    /// realisation 0's tables byte-identical to this run's, in the same results directory), by
    /// figure name, with the number of worlds; kept in the results as `check.json`.
    pub cached_spread: Option<(usize, std::collections::BTreeMap<String, [f64; 2]>)>,
    /// The scenario's `study.check_realisations` (the worlds `check` judges over by default), and
    /// the fewest worlds that judge every figure at the scenario's false-alarm rate.
    pub check_worlds: (u32, usize),
}

impl RunReport {
    /// Figures checked and figures missed, by the rule the run used (over realisations when it ran
    /// several).
    pub fn tally(&self) -> (usize, usize) {
        match &self.distribution {
            Some(d) => (d.iter().filter(|d| d.pass.is_some()).count(), d.iter().filter(|d| d.pass == Some(false)).count()),
            None => tally(&self.checks),
        }
    }
}

/// Loads a scenario of any device, with overrides applied; a sweep file given here is refused,
/// saying what to run instead.
pub fn load(path: &Path, overrides: &Overrides) -> Result<Box<dyn Scenario>, Error> {
    let mut s = crate::device::load(path).map_err(|e| wrong_command(path, e))?;
    overrides.apply(s.as_mut())?;
    Ok(s)
}

/// A scenario error, or, when the file is a sweep file (it has `base` and `[[axis]]`), the command
/// to run instead.
fn wrong_command(path: &Path, e: crate::device::ScenarioError) -> Error {
    let looks_like_sweep = crate::io::read_text(path)
        .ok()
        .and_then(|t| t.parse::<toml::Table>().ok())
        .is_some_and(|t| t.contains_key("base") && (t.contains_key("axis") || t.contains_key("fixed")));
    if looks_like_sweep {
        return Error::input(path.display().to_string(), format!("a sweep file, not a scenario: run `calsim sweep {}`", path.display()));
    }
    e.into()
}

/// Runs the study of `spec.scenario`, writes its results, compares its figures (and, with
/// realisations, judges them over that many worlds).
pub fn run(spec: &RunSpec, observer: &dyn Observer) -> Result<RunReport, Error> {
    let _inputs = crate::io::inputs::Ledger::open();
    let scenario = load(&spec.scenario, &spec.overrides)?;
    let h = scenario.header();
    let study = scenario.study();
    let count = spec.realisations.unwrap_or(if spec.check { study.check_realisations } else { 1 });
    let false_alarm = spec.false_alarm.unwrap_or(study.check_false_alarm);
    if !(1e-6..=0.5).contains(&false_alarm) {
        return Err(Error::input("--false-alarm", format!("{false_alarm}: within [1e-6, 0.5]")));
    }
    if let Some(r) = spec.realisations
        && !(1..=crate::study::MAX_CHECK_REALISATIONS).contains(&r)
    {
        return Err(Error::input("--realisations", format!("{r}: within [1, {}]", crate::study::MAX_CHECK_REALISATIONS)));
    }
    if let Some(j) = &spec.junit {
        if !spec.check {
            return Err(Error::input("--junit", "the verdict of a check: run `calsim check` to write it"));
        }
        crate::io::out_dir::vet_output_file("--junit", j, &[&spec.scenario])?;
    }
    crate::io::out_dir::prepare(&spec.out, &h.name)?;
    let (pool, threads) = thread_pool(spec.threads)?;
    let kind = scenario.device().kind();
    let shown_kind = if kind == crate::device::REGISTRY[0].kind() { String::new() } else { format!("{}, ", kind.to_uppercase()) };
    observer.started(&format!(
        "calsim {}: {} ({shown_kind}seed {}), {}",
        if spec.check { "check" } else { "run" },
        h.name,
        h.seed,
        threads_label(threads)
    ));
    let device_err = |source| Error::Device { path: spec.scenario.display().to_string(), source };
    let outcome =
        pool.install(|| scenario.run(h.seed, &|done, total| observer.progress(done, total, "identifications"))).map_err(device_err)?;
    observer.stage_done();
    let checks = pool.install(|| outcome.checks()).map_err(device_err)?;
    let mut distribution = None;
    let mut realisations_run = 1;
    if count > 1 {
        // Fewer worlds than give a bounded interval could judge nothing: refused before they run.
        let fewest = crate::study::check::fewest_worlds(&checks, false_alarm);
        if (count as usize) < fewest {
            let key = if spec.realisations.is_some() {
                "--realisations".to_string()
            } else {
                format!("{}: study.check_realisations", spec.scenario.display())
            };
            return Err(Error::input(
                key,
                format!(
                    "{count}: judging its figures at a false-alarm rate of {false_alarm} takes at least {fewest} realisations (1 runs the plain check)"
                ),
            ));
        }
        let others = realisations(count, observer, |r| {
            let seed = crate::seeds::realisation_seed(h.seed, r);
            pool.install(|| scenario.run(seed, &|_, _| {}).and_then(|o| o.checks())).map_err(|e| e.to_string())
        });
        let mut runs = vec![checks.clone()];
        runs.extend(others);
        realisations_run = runs.len();
        distribution = Some(over_realisations(&runs, count as usize, false_alarm));
    }
    let check_report = spec.check.then(|| match &distribution {
        Some(d) => CheckReport::over(&h.name, h.seed, count as usize, false_alarm, d),
        None => CheckReport::single(&h.name, h.seed, &checks),
    });
    // A plain run keeps an earlier check over worlds of the same results directory when its world
    // turns out to be this one (checked below on the tables' hashes).
    let earlier = (!spec.check && count == 1).then(|| earlier_check(&spec.out.join(&h.name))).flatten();
    let t_write = Instant::now();
    let options = WriteOptions { threads, plots: spec.plots, recording: spec.recording, overrides: spec.overrides.pairs() };
    let mut results = outcome.results(&checks, &options).map_err(device_err)?;
    let table_err = |e: std::io::Error| Error::io(&spec.out)(e);
    let mut frames = vec![(
        "checks".to_string(),
        results.table("checks.parquet", crate::study::check::check_columns(&checks)).map_err(table_err)?.clone(),
    )];
    if let Some(d) = &distribution {
        let frame = results.table("checks_over_worlds.parquet", crate::study::check::distribution_columns(d)).map_err(table_err)?;
        frames.push(("distribution".to_string(), frame.clone()));
    }
    if let Some(c) = &check_report {
        let json = serde_json::to_string_pretty(c).map_err(|e| Error::input("check.json", e.to_string()))?;
        results.file("check.json", json + "\n");
    }
    // A plain run keeps the earlier check over worlds when its world is this one (the same
    // tables): its check.json goes into the new results with them.
    let mut cached_spread = None;
    if let Some((tables, text, spread)) = earlier {
        let ours = serde_json::to_value(results.tables_sha256().map_err(Error::io(&spec.out))?).ok();
        if ours.as_ref() == Some(&tables) {
            results.file("check.json", text);
            cached_spread = Some(spread);
        }
    }
    let written = crate::io::results::write(&spec.out, results).map_err(Error::io(&spec.out))?;
    let dest = written.dest.clone();
    if let (Some(j), Some(c)) = (&spec.junit, &check_report) {
        crate::io::out_dir::write_output_file("--junit", j, c.junit().as_bytes())?;
    }
    let write_s = t_write.elapsed().as_secs_f64();
    if let Some(w) = fit_health(&spec.scenario, outcome.fits())? {
        observer.warning(&w);
    }
    let check_worlds = (study.check_realisations, crate::study::check::fewest_worlds(&checks, study.check_false_alarm));
    Ok(RunReport {
        name: h.name.clone(),
        kind,
        seed: h.seed,
        threads,
        checks,
        frames,
        timing: outcome.timing(),
        write_s,
        recording_s: written.recording_s,
        dest,
        distribution,
        realisations_run,
        false_alarm,
        check_report,
        check_worlds,
        cached_spread,
    })
}

/// The hashes a results directory's manifest records of the tables of its world (every table but
/// the checks over realisations, which only a check over worlds writes).
fn tables_of(dir: &Path) -> Option<serde_json::Value> {
    let text = own_text(&dir.join("manifest.json"))?;
    let mut tables = serde_json::from_str::<serde_json::Value>(&text).ok()?.get("tables_sha256").cloned()?;
    tables.as_object_mut()?.remove("checks_over_worlds.parquet");
    Some(tables)
}

/// The text of a file of an earlier results directory, read back as calsim's own (not an input of
/// the run: the writer may replace the directory holding it).
fn own_text(path: &Path) -> Option<String> {
    String::from_utf8(crate::io::read_own(path, crate::io::MOST_INPUT_BYTES).ok()?).ok()
}

/// An earlier check over several worlds in `dir`: its manifest's table hashes, the text of its
/// `check.json`, and its worlds with each figure's P10-P90. `None` for anything else (no check, a
/// check of one world, a file calsim cannot read).
#[allow(clippy::type_complexity)]
fn earlier_check(dir: &Path) -> Option<(serde_json::Value, String, (usize, std::collections::BTreeMap<String, [f64; 2]>))> {
    let tables = tables_of(dir)?;
    let text = own_text(&dir.join("check.json"))?;
    let v: serde_json::Value = serde_json::from_str(&text).ok()?;
    let worlds = usize::try_from(v.get("realisations")?.as_u64()?).ok().filter(|&n| n > 1)?;
    let mut spread = std::collections::BTreeMap::new();
    for f in v.get("figures")?.as_array()? {
        if let (Some(name), Some([a, b])) =
            (f.get("figure").and_then(|x| x.as_str()), f.get("p10_p90").and_then(|x| x.as_array()).map(|a| a.as_slice()))
            && let (Some(a), Some(b)) = (a.as_f64(), b.as_f64())
        {
            spread.insert(name.to_string(), [a, b]);
        }
    }
    Some((tables, text, (worlds, spread)))
}

/// One line when identifications failed: how many gave no model (and which parameters they could
/// not separate), how many stopped at the iteration cap. A study in which no identification gave a
/// model is an error of its scenario's parameter set.
pub fn fit_health<'a>(scenario: &Path, ids: impl IntoIterator<Item = &'a Identified>) -> Result<Option<String>, Error> {
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
        return Err(Error::NoModel { scenario: scenario.display().to_string(), total, hidden });
    }
    Ok((no_model > 0 || capped > 0)
        .then(|| format!("{no_model} of {total} identifications gave no model{hidden}; {capped} stopped at the iteration cap")))
}

/// The checks of realisations 1..count (realisation 0 is the plain run), with progress; a
/// realisation whose study fails is left out with a warning.
fn realisations(count: u32, observer: &dyn Observer, one: impl Fn(u32) -> Result<Vec<Check>, String>) -> Vec<Vec<Check>> {
    let mut out = Vec::new();
    let mut failed = Vec::new();
    for r in 1..count {
        match one(r) {
            Ok(rows) => out.push(rows),
            Err(e) => failed.push(format!("{r}: {e}")),
        }
        observer.progress(r as usize, count as usize - 1, "further realisations");
    }
    observer.stage_done();
    if !failed.is_empty() {
        observer.warning(&format!("{} realisations left out ({})", failed.len(), failed.join("; ")));
    }
    out
}
