//! What `calsim optimise` writes (through the io kit, atomically): `trace.parquet` (every design
//! the search evaluated, its estimate and interval on the search worlds), `race.parquet` (the
//! finalists on more search worlds), `verified.parquet` (the held-out worlds: the reported
//! figures), `answer.parquet` (the answer at each stage), `best_design.toml` (runnable from any
//! directory), `summary.md` (rendered from the tables, [`super::summary`]) and the figures.

use std::path::{Path, PathBuf};

use polars::prelude::Column;

use super::{Candidate, DesignSpace, Verdict};
use crate::design::sweep::designs::DesignRow;
use crate::io::results::{Head, Results};

/// The optimiser's outcome as the report shows it.
#[derive(Clone, Debug)]
pub struct Outcome {
    /// The verdict.
    pub verdict: Verdict,
    /// The winner: its index in `verdict.verified` and its held-out row.
    pub winner: Option<(usize, DesignRow)>,
    /// The winner's cell as a machinist builds it (TriCal designs).
    pub sheet: Option<super::sheet::CellSheet>,
}

impl Outcome {
    /// The winner: the design, set size and selection the answer rule takes from the race's rows
    /// on the search worlds ([`super::answer_of`]), with its held-out row. The held-out worlds only report it: choosing on them too would
    /// report the luckiest of the verified designs on the worlds that chose it (the winner's
    /// curse), an optimistic figure.
    pub fn of(space: &DesignSpace, verdict: Verdict) -> Self {
        let mut o = Self::chosen(verdict);
        o.sheet = o.winner.as_ref().and_then(|(i, r)| {
            let table = design_table(&o.verdict.verified[*i], r);
            let text = toml::to_string(&table).unwrap_or_default();
            let s = crate::device::from_table(&text, table, &space.path).ok()?;
            super::sheet::CellSheet::of(s.as_ref())
        });
        o
    }

    fn chosen(verdict: Verdict) -> Self {
        if let Some(r) = &verdict.robust {
            // Under [robust], the winner under the combined score (the last choice), with its
            // held-out row of the first model that has one.
            let winner = r.choices.last().and_then(|c| {
                r.held_out.iter().find_map(|rows| {
                    rows.iter()
                        .find(|h| h.design.point == c.verified && h.design.set_size == c.set_size && h.design.selection == c.selection)
                        .map(|h| (c.verified, h.clone()))
                })
            });
            return Self { verdict, winner, sheet: None };
        }
        let winner = verdict.answer.and_then(|(i, _)| verdict.race_rows.get(i)).and_then(|best| {
            let key = &verdict.finalists.get(best.design.point)?.key;
            let v = verdict.verified.iter().position(|c| !c.compared && &c.key == key)?;
            verdict
                .held_out_rows
                .iter()
                .find(|h| h.design.point == v && h.design.set_size == best.design.set_size && h.design.selection == best.design.selection)
                .map(|h| (v, h.clone()))
        });
        Self { verdict, winner, sheet: None }
    }
}

fn f3(x: f64) -> String {
    if x.is_finite() { format!("{x:.3}") } else { "-".into() }
}

/// The scenario table of a verified design with its set size as the study's table (and only
/// selection), for `best_design.toml`.
pub fn design_file(c: &Candidate, r: &DesignRow, head: &str) -> String {
    format!("{head}{}", toml::to_string(&design_table(c, r)).unwrap_or_default())
}

/// The scenario table of a verified design with its set size as the study's table and its
/// selection the only one.
pub fn design_table(c: &Candidate, r: &DesignRow) -> toml::Table {
    let mut table = c.table.clone();
    for (_, v) in table.iter_mut() {
        no_negative_zero(v);
    }
    let study = table.entry("study").or_insert_with(|| toml::Value::Table(toml::Table::new()));
    if let Some(s) = study.as_table_mut() {
        s.insert("table_set_size".into(), toml::Value::Integer(i64::from(r.design.set_size)));
        s.insert("selections".into(), toml::Value::Array(vec![toml::Value::String(r.design.selection.clone())]));
    }
    table
}

/// Every `-0.0` in `v` written `0.0` (the same number, tidy in a file).
fn no_negative_zero(v: &mut toml::Value) {
    match v {
        toml::Value::Float(x) if *x == 0.0 => *x = 0.0,
        toml::Value::Array(a) => a.iter_mut().for_each(no_negative_zero),
        toml::Value::Table(t) => t.iter_mut().for_each(|(_, x)| no_negative_zero(x)),
        _ => {}
    }
}

/// The FITTED values of the base scenario (`section.key = value`, from its text's comments), the
/// error model a design's figures rest on; empty when the file cannot be read or has none.
pub fn fitted_values(space: &DesignSpace) -> Vec<String> {
    let base = crate::io::read_text(&space.path)
        .ok()
        .and_then(|t| t.parse::<toml::Table>().ok())
        .and_then(|t| t.get("base").and_then(|b| b.as_str()).map(PathBuf::from));
    let Some(base) = base else { return Vec::new() };
    let Ok(text) = crate::io::read_text(&space.path.parent().unwrap_or(Path::new(".")).join(base)) else { return Vec::new() };
    let mut section = String::new();
    let mut out = Vec::new();
    for line in text.lines() {
        let l = line.trim();
        if l.starts_with('[') {
            section = l.trim_matches(|c| c == '[' || c == ']').to_string();
        } else if let Some((kv, note)) = l.split_once('#')
            && note.contains("FITTED")
            && let Some((k, v)) = kv.split_once('=')
        {
            let key = if section.is_empty() { k.trim().to_string() } else { format!("{section}.{}", k.trim()) };
            out.push(format!("`{key} = {}`", v.trim()));
        }
    }
    out
}

/// What the search minimises, in words.
pub fn score_words(space: &DesignSpace) -> String {
    let o = &space.objective;
    let shortfalls = "plus 10 times the constraints' relative shortfalls";
    match (o.goal, space.search.score) {
        (crate::design::sweep::objective::Goal::MaximiseSuccess, super::spec::SearchScore::Quantile) => format!(
            "the {} quantile over the search worlds of each world's {} error over the threshold (`[search] score = \"quantile\"`), \
             {shortfalls}; the race and the answer are judged by P(success)",
            o.success_at_least.unwrap_or(0.95),
            o.statistic.label()
        ),
        (crate::design::sweep::objective::Goal::MaximiseSuccess, super::spec::SearchScore::Success) => {
            format!("minus P(success) over the search worlds (`[search] score = \"success\"`), {shortfalls}")
        }
        _ => format!("the objective's estimate over the search worlds ({}), {shortfalls}", o.describe()),
    }
}

/// A held-out or race row in words: `0.950 (0.900-0.980) over 100 worlds, n = 75, campaign 2.100 h,
/// feasible` (the head of `best_design.toml`).
pub fn row_words(r: &DesignRow) -> String {
    format!(
        "{} ({}-{}) over {} worlds, n = {}, campaign {} h, {}",
        f3(r.estimate),
        f3(r.interval.0),
        f3(r.interval.1),
        r.worlds,
        r.design.set_size,
        f3(r.campaign_h),
        r.feasibility.label()
    )
}

/// A row of `robust.parquet`: a stage, a model (or the combination), a design's judged row.
struct RobustRow {
    stage: String,
    model: String,
    design: String,
    /// The judged row (none for the combination).
    row: Option<DesignRow>,
    key: super::RowKey,
    score: f64,
}

/// The results of an optimisation: the trace, the race, the verified designs and (for several
/// error models) the robust table; the answer as a design file and the spheres' sheet; the
/// manifest's `fields` (a JSON object) with the provenance of `overrides`; the summary and
/// figures (`plots` are their inputs); the winner's realisation 0 as `winner/`.
pub fn results<'a>(
    space: &'a DesignSpace,
    o: &'a Outcome,
    plots: Option<super::plots::OptimisePlotInputs>,
    fields: serde_json::Value,
    overrides: &[(String, String)],
    winner: Option<Results<'a>>,
) -> std::io::Result<Results<'a>> {
    let v = &o.verdict;
    let mut out = Results::new(space.name.clone(), Head::Run(crate::io::manifest::Provenance::of_run(overrides)));
    out.table("trace.parquet", trace_columns(space, v))?;
    out.table("race.parquet", row_columns(&v.race_rows, &|p| v.finalists[p].label.clone()))?;
    let mut verified = row_columns(&v.held_out_rows, &|p| v.verified[p].label.clone());
    verified.extend(super::summary::leader_columns(space, v));
    out.table("verified.parquet", verified)?;
    if let Some(r) = &v.robust {
        out.table("robust.parquet", robust_columns(space, v, r))?;
    }
    if let Some((i, r)) = &o.winner {
        let head = format!(
            "# {}: the optimiser's answer, {} ({} sets of {}): held-out {}.\n# `calsim run best_design.toml` redoes its realisation 0 with the figures and the Rerun recording (from any directory).\n",
            space.name,
            v.verified[*i].label,
            r.design.selection,
            r.design.set_size,
            row_words(r)
        );
        out.file("best_design.toml", design_file(&v.verified[*i], r, &head));
    }
    if let Some(sheet) = &o.sheet {
        out.file("spheres.csv", sheet.csv());
    }
    out.fields(fields)?;
    if let Some((i, _)) = &o.winner {
        let label = v.verified[*i].label.clone();
        let answer = super::summary::answer_columns(space, o, &|rows| row_columns(rows, &|_| label.clone()));
        out.table("answer.parquet", answer.unwrap_or_default())?;
    }
    super::summary::summary(space, o, &mut out.summary);
    if let Some(w) = winner {
        out.nested("winner", w);
        out.summary.text(
            "\n`winner/`: the winner's realisation 0 as `calsim run` writes it (tables, figures, the Rerun recording `study.rrd`).\n",
        );
    }
    if let Some(p) = plots {
        out.draw(Box::new(move |dir| super::plots::write(dir, &p)));
        out.summary.figures("\n## Figures\n\n");
    }
    Ok(out)
}

/// `trace.parquet`: one row per evaluation.
fn trace_columns(space: &DesignSpace, v: &Verdict) -> Vec<Column> {
    let f = |n: &str, x: Vec<f64>| Column::new(n.into(), x);
    let u = |n: &str, x: Vec<u32>| Column::new(n.into(), x);
    let s = |n: &str, x: Vec<String>| Column::new(n.into(), x);
    let best: Vec<Option<&super::SizeScore>> = v.trace.iter().map(|e| e.best()).collect();
    let bf = |g: &dyn Fn(&DesignRow) -> f64| best.iter().map(|b| b.map_or(f64::NAN, |b| g(&b.row))).collect::<Vec<_>>();
    vec![
        u("restart", v.trace.iter().map(|e| e.asked.restart).collect()),
        u("evaluation", v.trace.iter().map(|e| e.asked.index).collect()),
        u("count", v.trace.iter().map(|e| e.asked.count as u32).collect()),
        s("design", v.trace.iter().map(|e| e.key.clone()).collect()),
        s("values", v.trace.iter().map(|e| e.values.iter().map(|(k, x)| format!("{k} = {x}")).collect::<Vec<_>>().join("; ")).collect()),
        s("x", v.trace.iter().map(|e| format!("{:?}", e.asked.x)).collect()),
        s("violation", v.trace.iter().map(|e| e.violation.as_ref().map(|x| x.0.clone()).unwrap_or_default()).collect()),
        f("violation_margin", v.trace.iter().map(|e| e.violation.as_ref().map_or(0.0, |x| x.1)).collect()),
        s("repaired", v.trace.iter().map(|e| e.repaired.as_ref().map(|r| r.broke.clone()).unwrap_or_default()).collect()),
        f("repaired_mm", v.trace.iter().map(|e| e.repaired.as_ref().map_or(0.0, |r| r.moved_mm)).collect()),
        u("worlds", v.trace.iter().map(|e| e.worlds).collect()),
        u("failed_worlds", v.trace.iter().map(|e| e.failed).collect()),
        s("first_error", v.trace.iter().map(|e| e.first_error.clone().unwrap_or_default()).collect()),
        f("reach_margin_mm", v.trace.iter().map(|e| e.reach_mm.iter().copied().fold(f64::NAN, f64::max)).collect()),
        f("campaign_shortfall", v.trace.iter().map(|e| if e.failed > 0 { e.shortfall } else { f64::NAN }).collect()),
        u("set_size", best.iter().map(|b| b.map_or(0, |b| b.row.design.set_size)).collect()),
        f("estimate", bf(&|r| r.estimate)),
        f("lower", bf(&|r| r.interval.0)),
        f("upper", bf(&|r| r.interval.1)),
        f("campaign_h", bf(&|r| r.campaign_h)),
        f("score", v.trace.iter().map(|e| e.score).collect()),
        s(
            "model_scores",
            v.trace
                .iter()
                .map(|e| {
                    let names = space.model_names();
                    e.models.iter().zip(&names).map(|(m, n)| format!("{n} = {}", m.score)).collect::<Vec<_>>().join("; ")
                })
                .collect(),
        ),
    ]
}

/// `race.parquet` and `verified.parquet`: one row per judged design, `label` naming its point.
fn row_columns(rows: &[DesignRow], label: &dyn Fn(usize) -> String) -> Vec<Column> {
    let f = |n: &str, x: Vec<f64>| Column::new(n.into(), x);
    let u = |n: &str, x: Vec<u32>| Column::new(n.into(), x);
    let s = |n: &str, x: Vec<String>| Column::new(n.into(), x);
    vec![
        s("design", rows.iter().map(|r| label(r.design.point)).collect()),
        s("selection", rows.iter().map(|r| r.design.selection.clone()).collect()),
        u("set_size", rows.iter().map(|r| r.design.set_size).collect()),
        u("worlds", rows.iter().map(|r| r.worlds).collect()),
        u("failed_worlds", rows.iter().map(|r| r.failed_worlds).collect()),
        f("estimate", rows.iter().map(|r| r.estimate).collect()),
        f("lower", rows.iter().map(|r| r.interval.0).collect()),
        f("upper", rows.iter().map(|r| r.interval.1).collect()),
        f("success", rows.iter().map(|r| r.success.map_or(f64::NAN, |x| x.0)).collect()),
        f("campaign_h", rows.iter().map(|r| r.campaign_h).collect()),
        s("feasibility", rows.iter().map(|r| r.feasibility.label().to_string()).collect()),
        u("rank", rows.iter().map(|r| r.rank as u32).collect()),
        Column::new("tied".into(), rows.iter().map(|r| r.tied).collect::<Vec<_>>()),
        s("eliminated", rows.iter().map(|r| r.eliminated.as_ref().map(|e| e.1.clone()).unwrap_or_default()).collect()),
    ]
}

/// `robust.parquet`: every model's rows, race then held-out, and the combined scores.
fn robust_columns(space: &DesignSpace, v: &Verdict, r: &super::RobustVerdict) -> Vec<Column> {
    let f = |n: &str, x: Vec<f64>| Column::new(n.into(), x);
    let u = |n: &str, x: Vec<u32>| Column::new(n.into(), x);
    let s = |n: &str, x: Vec<String>| Column::new(n.into(), x);
    // Every model's rows, race then held-out, and the combined scores.
    let mut rows: Vec<RobustRow> = Vec::new();
    let mut add = |stage: &str, by_model: &[Vec<DesignRow>], label: &dyn Fn(usize) -> String| {
        for (m, rs) in by_model.iter().enumerate() {
            rows.extend(rs.iter().map(|x| RobustRow {
                stage: stage.into(),
                model: r.models[m].clone(),
                design: label(x.design.point),
                row: Some(x.clone()),
                key: (x.design.point, x.design.selection.clone(), x.design.set_size),
                score: super::score_of(space, x),
            }));
        }
        for c in super::combined(space, by_model) {
            rows.push(RobustRow {
                stage: stage.into(),
                model: format!("robust ({})", r.combine.label()),
                design: label(c.key.0),
                row: None,
                key: c.key,
                score: c.score,
            });
        }
    };
    add("race", &r.race, &|p| v.finalists[p].label.clone());
    add("held_out", &r.held_out, &|p| v.verified[p].label.clone());
    let num = |g: &dyn Fn(&DesignRow) -> f64| rows.iter().map(|x| x.row.as_ref().map_or(f64::NAN, g)).collect::<Vec<_>>();
    let whole = |g: &dyn Fn(&DesignRow) -> u32| rows.iter().map(|x| x.row.as_ref().map_or(0, g)).collect::<Vec<_>>();
    vec![
        s("stage", rows.iter().map(|x| x.stage.clone()).collect()),
        s("model", rows.iter().map(|x| x.model.clone()).collect()),
        s("design", rows.iter().map(|x| x.design.clone()).collect()),
        s("selection", rows.iter().map(|x| x.key.1.clone()).collect()),
        u("set_size", rows.iter().map(|x| x.key.2).collect()),
        u("worlds", whole(&|x| x.worlds)),
        u("failed_worlds", whole(&|x| x.failed_worlds)),
        f("estimate", num(&|x| x.estimate)),
        f("lower", num(&|x| x.interval.0)),
        f("upper", num(&|x| x.interval.1)),
        f("success", num(&|x| x.success.map_or(f64::NAN, |y| y.0))),
        f("campaign_h", num(&|x| x.campaign_h)),
        f("score", rows.iter().map(|x| x.score).collect()),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::design::sweep::designs::{Design, Feasibility};

    fn space(objective: &str) -> (tempfile::TempDir, DesignSpace) {
        let dir = tempfile::tempdir().unwrap();
        let base = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/ci_quick.toml");
        let f = dir.path().join("q.toml");
        std::fs::write(
            &f,
            format!(
                "base = {:?}\n[[variable]]\nkey = \"trical.epsilon_mm\"\nrange = [0.01, 0.02]\n[objective]\n{objective}",
                base.display().to_string()
            ),
        )
        .unwrap();
        let s = super::super::spec::load(&f).unwrap();
        (dir, s)
    }

    const MEET: &str = "maximise = \"success\"\nstatistic = \"max\"\nthreshold_mm = 0.5\nconfidence = 0.9\nsuccess_at_least = 0.9\n";

    /// A judged row: (finalist, set size, P, campaign h, feasibility, rank).
    fn row(point: usize, set_size: u32, p: f64, h: f64, f: Feasibility, rank: usize) -> DesignRow {
        DesignRow {
            design: Design { point, selection: "detmax".into(), set_size },
            table: false,
            worlds: 40,
            failed_worlds: 0,
            estimate: p,
            interval: (p - 0.05, p.min(1.0)),
            success: Some((p, (p - 0.05, p.min(1.0)))),
            campaign_h: h,
            feasibility: f,
            rank,
            vs_leader: None,
            tied: false,
            eliminated: None,
        }
    }

    fn race() -> Vec<DesignRow> {
        use Feasibility::*;
        vec![
            row(0, 450, 1.0, 3.0, Feasible, 1),
            row(0, 300, 0.975, 3.0, Feasible, 2),
            row(1, 300, 0.96, 2.5, Feasible, 3),
            row(2, 150, 0.9, 2.0, Undecided, 4),
        ]
    }

    #[test]
    fn the_answer_is_the_smallest_campaign_that_meets_the_objective_then_the_smaller_set() {
        use super::super::{AnswerBasis, answer_of};
        let (_d, s) = space(MEET);
        let rows = race();
        assert_eq!(answer_of(&s, &rows), Some((2, AnswerBasis::SmallestMeeting)), "the shortest campaign among those meeting it");
        // Without it: the same campaign at two set sizes, the smaller set (not the higher P).
        assert_eq!(answer_of(&s, &[rows[0].clone(), rows[1].clone(), rows[3].clone()]), Some((1, AnswerBasis::SmallestMeeting)));
        // None meets the objective at the confidence: the race's first.
        let undecided: Vec<DesignRow> = rows.iter().map(|r| DesignRow { feasibility: Feasibility::Undecided, ..r.clone() }).collect();
        assert_eq!(answer_of(&s, &undecided), Some((0, AnswerBasis::RaceFirst)));
        // An objective without a least P to meet: the race's first.
        let (_d, p95) = space("minimise = \"p95\"\nconfidence = 0.9\n");
        assert_eq!(answer_of(&p95, &rows), Some((0, AnswerBasis::RaceFirst)));
    }

    /// The summary of `o` as its results directory holds it (rendered from the tables written).
    fn rendered(s: &DesignSpace, o: &Outcome) -> String {
        let tmp = tempfile::Builder::new().prefix("calsim-optimise-summary-").tempdir().unwrap();
        let r = results(s, o, None, serde_json::json!({}), &[], None).unwrap();
        let dest = crate::io::results::write(tmp.path(), r).unwrap().dest;
        std::fs::read_to_string(dest.join("summary.md")).unwrap()
    }

    #[test]
    fn the_summary_says_why_the_answer_is_not_first_on_the_held_out_worlds() {
        use super::super::{Verdict, answer_of};
        let (_d, s) = space(MEET);
        let rows = race();
        let candidate = |k: usize| Candidate {
            label: format!("{} points, restart {k} #1", 4 + k),
            count: 4 + k,
            table: toml::Table::new(),
            key: format!("key{k}"),
            points_mm: Vec::new(),
            search_score: Some(0.0),
            compared: false,
        };
        let finalists = vec![candidate(0), candidate(1), candidate(2)];
        // Held-out: finalist 0 with sets of 450 first; the answer (finalist 1, sets of 300) second.
        let verified = vec![finalists[0].clone(), finalists[1].clone()];
        let held = vec![row(0, 450, 0.97, 3.0, Feasibility::Undecided, 1), row(1, 300, 0.95, 2.5, Feasibility::Undecided, 2)];
        let v = Verdict {
            trace: Vec::new(),
            finalists,
            race_rows: rows.clone(),
            race_worlds: 40,
            verified,
            held_out_rows: held,
            robust: None,
            answer: answer_of(&s, &rows),
        };
        let o = Outcome::of(&s, v);
        let (i, r) = o.winner.clone().expect("the answer's held-out row");
        assert_eq!((i, r.design.set_size), (1, 300));
        let text = rendered(&s, &o);
        assert!(text.contains("ranks the answer 2 of 2"), "{text}");
        assert!(text.contains("with a longer campaign (3.000 h against 2.500 h)"), "{text}");
        assert!(text.contains("3 of the race's rows meet every constraint"), "{text}");
        // The held-out table shows the rows of verified.parquet, the leader's paired column included.
        assert!(
            text.contains(
                "| 1 | 4 points, restart 0 #1 | detmax | 450 | 0.970 | 0.920-0.970 | 0.970 | 3.000 | 40 | 0 | undecided | leader |"
            ),
            "{text}"
        );
        // No row meets it: the race's first, and the summary says the race's worlds cannot show it.
        let undecided: Vec<DesignRow> = rows.iter().map(|r| DesignRow { feasibility: Feasibility::Undecided, ..r.clone() }).collect();
        let v = Verdict { race_rows: undecided.clone(), answer: answer_of(&s, &undecided), ..o.verdict.clone() };
        let o = Outcome::of(&s, v);
        assert_eq!(o.winner.as_ref().map(|w| (w.0, w.1.design.set_size)), Some((0, 450)));
        let text = rendered(&s, &o);
        assert!(text.contains("no row of the race meets every constraint at 90 % confidence on its 40 worlds"), "{text}");
        assert!(text.contains("The held-out table below ranks the answer first"), "{text}");
    }
}
