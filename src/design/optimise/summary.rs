//! The optimiser's summary, rendered from the tables it writes: the answer at each stage
//! (`answer.parquet`), the race (`race.parquet`), every verified design on the held-out worlds
//! (`verified.parquet`), the robust table (`robust.parquet`) and the search (`trace.parquet`).

use polars::prelude::{Column, DataFrame};

use super::results::{Outcome, fitted_values, score_words};
use super::{DesignSpace, RobustVerdict, RowKey, Verdict};
use crate::design::sweep::designs::DesignRow;
use crate::io::results::{Row, Summary, cell};

/// `x` with three decimals, `-` when it is not a number.
fn f3(x: f64) -> String {
    if x.is_finite() { format!("{x:.3}") } else { "-".into() }
}

/// The index of the held-out row `r` in `v.held_out_rows` (the rows of `verified.parquet`).
fn held_out_index(v: &Verdict, r: &DesignRow) -> Option<usize> {
    v.held_out_rows.iter().position(|h| h.design == r.design)
}

/// The columns `verified.parquet` adds to a judged row's: the worlds in which the leader did
/// better and worse than the design (paired on common worlds; null for the leader).
pub fn leader_columns(space: &DesignSpace, v: &Verdict) -> Vec<Column> {
    let paired: Vec<Option<(u32, u32)>> = v
        .held_out_rows
        .iter()
        .map(|r| {
            r.vs_leader.as_ref().map(|p| {
                let (better, worse) =
                    if space.objective.maximises() { (p.test.negative, p.test.positive) } else { (p.test.positive, p.test.negative) };
                (better as u32, worse as u32)
            })
        })
        .collect();
    vec![
        Column::new("leader_better_worlds".into(), paired.iter().map(|p| p.map(|x| x.0)).collect::<Vec<_>>()),
        Column::new("leader_worse_worlds".into(), paired.iter().map(|p| p.map(|x| x.1)).collect::<Vec<_>>()),
    ]
}

/// The answer's rows at each stage (`stage`: `search`, `race`, `held_out`; under `[robust]` the
/// first model's, named in `model`), with the Clopper-Pearson bounds of its P(success) at the
/// objective's confidence (NaN without a threshold); `rows` makes a judged row's columns.
pub fn answer_columns(space: &DesignSpace, o: &Outcome, rows: &dyn Fn(&[DesignRow]) -> Vec<Column>) -> Option<Vec<Column>> {
    use crate::study::interval::{clopper_pearson_lower, clopper_pearson_upper};
    let v = &o.verdict;
    let (i, r) = o.winner.as_ref()?;
    let c = &v.verified[*i];
    let race = v.race_rows.iter().filter(|x| v.finalists[x.design.point].key == c.key && x.design.set_size == r.design.set_size);
    let mut search = v.trace.iter().filter(|e| e.key == c.key);
    let search = search.find_map(|e| e.sizes.iter().find(|z| z.row.design.set_size == r.design.set_size).map(|z| z.row.clone()));
    let mut stages: Vec<(&str, DesignRow)> = search.map(|x| ("search", x)).into_iter().collect();
    stages.extend(race.min_by_key(|x| x.rank).map(|x| ("race", x.clone())));
    stages.push(("held_out", r.clone()));
    let judged: Vec<DesignRow> = stages.iter().map(|s| s.1.clone()).collect();
    let conf = space.objective.confidence;
    let bound = |f: &dyn Fn(f64, f64) -> f64| -> Vec<f64> {
        judged.iter().map(|x| x.success.map_or(f64::NAN, |(p, _)| f(p * f64::from(x.worlds), f64::from(x.worlds)))).collect()
    };
    let model = v.robust.as_ref().map(|x| x.models[0].clone());
    let mut cols = vec![
        Column::new("stage".into(), stages.iter().map(|s| s.0).collect::<Vec<_>>()),
        Column::new("model".into(), vec![model; stages.len()]),
    ];
    cols.extend(rows(&judged));
    cols.push(Column::new("success_lower".into(), bound(&|k, n| clopper_pearson_lower(k, n, conf))));
    cols.push(Column::new("success_upper".into(), bound(&|k, n| clopper_pearson_upper(k, n, conf))));
    Some(cols)
}

/// A judged row of `answer.parquet`, `race.parquet` or `verified.parquet` in words:
/// `0.950 (0.900-0.980) over 100 worlds, n = 75, campaign 2.100 h, feasible`.
fn row_words(r: &Row<'_>) -> String {
    format!(
        "{} ({}-{}) over {} worlds, n = {}, campaign {} h, {}",
        f3(r.f64("estimate")),
        f3(r.f64("lower")),
        f3(r.f64("upper")),
        r.u64("worlds"),
        r.u64("set_size"),
        f3(r.f64("campaign_h")),
        r.str("feasibility")
    )
}

/// The summary: the objective and the search, the answer at each stage and why, the cell sheet,
/// the robust table, every verified design on the held-out worlds, then the search.
pub fn summary<'a>(space: &'a DesignSpace, o: &'a Outcome, parts: &mut Summary<'a>) {
    let v = &o.verdict;
    parts.text(format!(
        "# {}: {}\n\nObjective: {}{}. Search: {} ({} designs at most per restart, {} restarts) on {} common worlds; \
         race of the finalists up to {} worlds; verification on {} held-out worlds (realisations from {}).\n\n",
        space.name,
        space.path.display(),
        space.objective.describe(),
        space.objective.constraints().iter().map(|c| format!("; {c}")).collect::<String>(),
        space.search.method.label(),
        space.search.evaluations,
        super::restarts(space).len(),
        space.search.worlds,
        space.search.race.max,
        space.held_out,
        super::HELD_OUT_BASE
    ));
    match &o.winner {
        Some((i, r)) => answer(space, v, &v.verified[*i], r, parts),
        None => {
            parts.text("## No answer\n\nNo design of the search ran in any world.\n\n");
        }
    }
    if let Some(sheet) = &o.sheet {
        parts.text(sheet.markdown());
    }
    if let Some(r) = &v.robust {
        robust(space, v, r, parts);
    }
    held_out(parts);
    search(v, parts);
}

/// The answer: its rows at each stage from `answer.parquet`, its status, how the rule chose it and
/// what its figures rest on.
fn answer<'a>(space: &'a DesignSpace, v: &'a Verdict, c: &super::Candidate, r: &DesignRow, parts: &mut Summary<'a>) {
    parts.text_from("answer.parquet", |row| {
        let held = row.at(row.height() - 1);
        format!("## The answer\n\n{} ({} sets of {}).\n\n", held.str("design"), held.str("selection"), held.u64("set_size"))
    });
    let stage = |row: &Row<'_>| {
        let under = Some(row.str("model")).filter(|m| !m.is_empty()).map_or(String::new(), |m| format!(", under {m}"));
        match row.str("stage").as_str() {
            "search" => format!("search worlds{under}"),
            "race" => format!("race (search worlds){under}"),
            _ => format!("**held-out worlds (reported)**{under}"),
        }
    };
    let words = |row: &Row<'_>| if row.str("stage") == "held_out" { format!("**{}**", row_words(row)) } else { row_words(row) };
    parts.table("answer.parquet", Summary::all_rows(), vec![cell("stage", stage), cell("estimate (interval)", words)]);
    parts.text(format!("Points as searched (the region's frame, mm): {:?}\n\n", c.points_mm));
    parts.text_from("answer.parquet", move |row| {
        let status = status_words(space, &row.at(row.height() - 1));
        if status.is_empty() { status } else { format!("Status on the held-out worlds: {status}.\n\n") }
    });
    answer_words(space, v, r, parts);
    let fitted = fitted_values(space);
    let models = match &v.robust {
        Some(x) => format!("the {} error models of `[robust]` ({})", x.models.len(), x.models.join(", ")),
        None => "one error model, the base scenario's (`[robust]` scores a design over several)".to_string(),
    };
    parts.text(format!(
        "Error model: the figures rest on {models}{}.\n\nSearch score: {}.\n\n",
        if fitted.is_empty() { String::new() } else { format!("; its FITTED values: {}", fitted.join(", ")) },
        score_words(space)
    ));
}

/// The objective's verdict on the answer's held-out row of `answer.parquet` in words: each
/// constraint met (its confidence bound on the right side of the target), not met (on the wrong
/// side) or not shown (the interval holds the target: more worlds would decide).
fn status_words(space: &DesignSpace, r: &Row<'_>) -> String {
    let o = &space.objective;
    let mut out = Vec::new();
    let (p, worlds, lo, hi) = (r.f64("success"), r.u64("worlds"), r.f64("success_lower"), r.f64("success_upper"));
    if let (Some(target), false) = (o.success_at_least, p.is_nan()) {
        let what = format!(
            "P({} <= {} mm) >= {target} at {} % confidence",
            o.statistic.label(),
            o.threshold_mm.unwrap_or(f64::NAN),
            o.confidence * 100.0
        );
        let (p, lo, hi) = (f3(p), f3(lo), f3(hi));
        out.push(if r.f64("success_lower") >= target {
            format!("{what}: **met** (P = {p} over {worlds} worlds, its lower bound {lo} >= {target})")
        } else if r.f64("success_upper") < target {
            format!("{what}: **not met** (P = {p} over {worlds} worlds, its upper bound {hi} < {target})")
        } else {
            format!("{what}: **not shown** (P = {p} over {worlds} worlds, bounds {lo}-{hi} hold {target}: more worlds would decide)")
        });
    }
    if let Some(h) = o.campaign_h_at_most {
        let campaign = r.f64("campaign_h");
        out.push(format!("campaign {} h <= {h} h: **{}**", f3(campaign), if campaign <= h { "met" } else { "not met" }));
    }
    if let Some(n) = o.set_size_at_most {
        let size = r.u64("set_size");
        out.push(format!("set size {size} <= {n}: **{}**", if size <= u64::from(n) { "met" } else { "not met" }));
    }
    out.join("; ")
}

/// The answer rule in words, how it chose the answer `r` (a held-out row), and, when the held-out
/// table does not rank the answer first, why each design above it is not the answer (its figures
/// from `race.parquet` and `verified.parquet`).
fn answer_words<'a>(space: &'a DesignSpace, v: &'a Verdict, r: &DesignRow, parts: &mut Summary<'a>) {
    use super::AnswerBasis;
    if v.robust.is_some() {
        parts.text(
            "Answer rule: the winner under the combined score of `[robust]` on the race's worlds (the table below). The held-out \
             worlds report the answer and do not choose it.\n\n",
        );
        return;
    }
    let o = &space.objective;
    let meet_rule = o.goal == crate::design::sweep::objective::Goal::MaximiseSuccess && o.success_at_least.is_some();
    parts.text(rule_words(meet_rule));
    if meet_rule {
        let smallest = v.answer.map(|a| a.1) == Some(AnswerBasis::SmallestMeeting);
        let worlds = v.race_worlds;
        parts.text_from("race.parquet", move |race| match smallest {
            true => format!(
                "Here: {} of the race's rows meet every constraint at the confidence; the answer is the one with the smallest \
                 campaign.\n\n",
                race.count("feasibility", "feasible")
            ),
            false => race_first_words(space, worlds),
        });
    }
    let Some(k) = held_out_index(v, r) else { return };
    parts.text_from("verified.parquet", move |held| above_words(v, k, held));
}

/// The answer rule in words (`meet_rule`: the smallest campaign meeting every constraint).
fn rule_words(meet_rule: bool) -> String {
    let mut s = String::from("Answer rule: ");
    if meet_rule {
        s += "of the race's rows (every finalist, set size and selection on the search worlds, `race.parquet`), those that meet \
              every constraint at the confidence; of them the smallest campaign, ties broken by the smaller set size, then the \
              higher P, then the race's order. Without such a row, the race's first (rank 1: the undecided designs before those \
              that fail a constraint, the highest P within each). ";
    } else {
        s += "the race's first on the search worlds (`race.parquet` rank 1): the designs meeting every constraint at the confidence \
              first, then those the worlds leave undecided, then the rest; within each the best objective estimate; ties by the \
              finalists' order (count, then search score), then selection, then the smaller set size. ";
    }
    s + "The held-out worlds report the answer and do not choose it (chosen on them, the figure would be the luckiest of the \
         verified designs on the worlds that chose it).\n\n"
}

/// Why the answer is the race's first when no row meets every constraint, and whether the race's
/// `worlds` could show it at all.
fn race_first_words(space: &DesignSpace, worlds: u32) -> String {
    let o = &space.objective;
    let n = f64::from(worlds);
    let best = crate::study::interval::clopper_pearson_lower(n, n, o.confidence);
    let target = o.success_at_least.unwrap_or(0.0);
    let cannot = if best < target {
        format!(
            " (even {worlds} successes of {worlds} bound P below by {} < {target}: the race cannot show P >= {target} at this \
             confidence)",
            f3(best)
        )
    } else {
        String::new()
    };
    format!(
        "Here: no row of the race meets every constraint at {} % confidence on its {worlds} worlds{cannot}; the answer is the \
         race's first.\n\n",
        o.confidence * 100.0
    )
}

/// Where the held-out table ranks the answer (row `k` of `verified.parquet`, read through `held`)
/// and why each design above it is not the answer.
fn above_words(v: &Verdict, k: usize, held: &Row<'_>) -> String {
    let answer = held.at(k);
    let above: Vec<usize> = (0..held.height()).filter(|&j| held.at(j).u64("rank") < answer.u64("rank")).collect();
    if above.is_empty() {
        return "The held-out table below ranks the answer first.\n\n".to_string();
    }
    let answer_race = v.answer.map(|(i, _)| held.of("race.parquet", i));
    let smallest = v.answer.map(|a| a.1) == Some(super::AnswerBasis::SmallestMeeting);
    let why = |j: usize| {
        let (h, row) = (&v.held_out_rows[j], held.at(j));
        let c = &v.verified[h.design.point];
        let head = format!("{} ({} sets of {}: {})", row.str("design"), row.str("selection"), row.u64("set_size"), f3(row.f64("estimate")));
        if c.compared {
            return format!("{head}: a compared design (a sweep file's), not a finalist the rule chooses from");
        }
        let raced = v.race_rows.iter().position(|x| {
            v.finalists[x.design.point].key == c.key && x.design.selection == h.design.selection && x.design.set_size == h.design.set_size
        });
        match (raced.map(|i| held.of("race.parquet", i)), &answer_race) {
            (Some(x), Some(a)) if smallest => smallest_words(&head, &x, a),
            (Some(x), Some(a)) => format!(
                "{head}: the race ranks it {} (P = {} over {} worlds, {}) below the answer (P = {}, {})",
                x.u64("rank"),
                f3(x.f64("estimate")),
                x.u64("worlds"),
                x.str("feasibility"),
                f3(a.f64("estimate")),
                a.str("feasibility")
            ),
            _ => format!("{head}: not a row of the race"),
        }
    };
    format!(
        "The held-out table below ranks the answer {} of {}; above it: {}. The held-out worlds report these figures and choose \
         nothing: the paired column (worlds the leader did better / worse) says whether they separate the designs.\n\n",
        answer.u64("rank"),
        held.height(),
        above.into_iter().map(why).collect::<Vec<_>>().join("; ")
    )
}

/// Why a design `x` above the answer `a` (rows of `race.parquet`) is not the answer under the rule
/// of the smallest campaign meeting every constraint.
fn smallest_words(head: &str, x: &Row<'_>, a: &Row<'_>) -> String {
    if x.str("feasibility") != "feasible" {
        format!("{head}: on the race's worlds it does not meet every constraint at the confidence ({})", x.str("feasibility"))
    } else if x.f64("campaign_h") > a.f64("campaign_h") {
        format!("{head}: it meets them too, with a longer campaign ({} h against {} h)", f3(x.f64("campaign_h")), f3(a.f64("campaign_h")))
    } else {
        format!("{head}: it meets them too, at the same campaign with a larger set or lower P on the race's worlds")
    }
}

/// Every verified design on the held-out worlds from `verified.parquet`, by rank.
fn held_out(parts: &mut Summary<'_>) {
    parts.text("## Held-out worlds: every verified design\n\n");
    let by_rank = Box::new(|f: &DataFrame| {
        let rank = f.column("rank").ok().and_then(|c| c.u32().ok().cloned());
        let mut rows: Vec<usize> = (0..f.height()).collect();
        rows.sort_by_key(|&i| rank.as_ref().and_then(|r| r.get(i)));
        rows
    });
    let cells = vec![
        cell("rank", |r| r.u64("rank").to_string()),
        cell("design", |r| r.str("design")),
        cell("selection", |r| r.str("selection")),
        cell("n", |r| r.u64("set_size").to_string()),
        cell("estimate", |r| f3(r.f64("estimate"))),
        cell("interval", |r| format!("{}-{}", f3(r.f64("lower")), f3(r.f64("upper")))),
        cell("P(success)", |r| f3(r.f64("success"))),
        cell("campaign, h", |r| f3(r.f64("campaign_h"))),
        cell("worlds", |r| r.u64("worlds").to_string()),
        cell("failed", |r| r.u64("failed_worlds").to_string()),
        cell("feasibility", |r| r.str("feasibility")),
        // Worlds in which the leader did better / worse than this design (paired on common worlds).
        cell("worlds the leader did better / worse", |r| match r.f64("leader_better_worlds") {
            x if x.is_nan() => "leader".to_string(),
            _ => format!("{} / {}", r.u64("leader_better_worlds"), r.u64("leader_worse_worlds")),
        }),
    ];
    parts.table("verified.parquet", by_rank, cells);
}

/// The search from `trace.parquet`: designs evaluated and ruled out, and the campaigns that failed.
fn search(v: &Verdict, parts: &mut Summary<'_>) {
    let (finalists, worlds) = (v.finalists.len(), v.race_worlds);
    parts.text_from("trace.parquet", move |t| {
        let rows: Vec<Row<'_>> = (0..t.height()).map(|i| t.at(i)).collect();
        let ruled = rows.iter().filter(|r| !r.str("violation").is_empty()).count();
        let repaired = rows.iter().filter(|r| !r.str("repaired").is_empty()).count();
        let mut s = format!(
            "## Search\n\n{} designs evaluated ({ruled} ruled out by their geometry or refused, not run; {repaired} broke a \
             geometric rule and were moved to a valid design near them, which ran: `trace.parquet` columns repaired, \
             repaired_mm); {finalists} finalists raced over up to {worlds} worlds.\n",
            rows.len()
        );
        let failing: Vec<&Row<'_>> = rows.iter().filter(|r| r.u64("failed_worlds") > 0).collect();
        if !failing.is_empty() {
            let all = failing.iter().filter(|r| r.u64("failed_worlds") == r.u64("worlds")).count();
            let margins: Vec<f64> = failing.iter().map(|r| r.f64("reach_margin_mm")).filter(|m| m.is_finite()).collect();
            let short: Vec<f64> = failing.iter().map(|r| r.f64("campaign_shortfall")).collect();
            let (max, min) =
                (|v: &[f64]| v.iter().copied().fold(f64::NAN, f64::max), |v: &[f64]| v.iter().copied().fold(f64::NAN, f64::min));
            s += &format!(
                "\n{} designs' campaigns failed in some worlds ({all} in every world: constraint violations, scored by the sum over \
                 their points of each one's distance from the arm's reach, the centre with the device axis along {{W}}'s -z, and by \
                 their campaign's shortfall of candidate poses reachable without collision; their farthest point {} mm from it at \
                 most, {} mm at least; shortfall {} at most, {} at least; `trace.parquet` columns failed_worlds, first_error, \
                 reach_margin_mm (the farthest point's), campaign_shortfall).\n",
                failing.len(),
                f3(max(&margins)),
                f3(min(&margins)),
                f3(max(&short)),
                f3(min(&short)),
            );
        }
        s
    });
}

/// The rows of `robust.parquet` in its order: stage, model (none for the combined score), design.
fn robust_order(space: &DesignSpace, r: &RobustVerdict) -> Vec<(&'static str, Option<usize>, RowKey)> {
    let mut out = Vec::new();
    for (stage, by_model) in [("race", &r.race), ("held_out", &r.held_out)] {
        for (m, rows) in by_model.iter().enumerate() {
            out.extend(rows.iter().map(|x| (stage, Some(m), (x.design.point, x.design.selection.clone(), x.design.set_size))));
        }
        out.extend(super::combined(space, by_model).into_iter().map(|c| (stage, None, c.key)));
    }
    out
}

/// A robust choice's rows of `robust.parquet`: its race score's, its held-out row under each
/// model, its combined held-out score's.
type ChoiceRows = (Option<usize>, Vec<Option<usize>>, Option<usize>);

/// The robust table: the winner under each model and under the combined score, each on the
/// held-out worlds under every model (read from `robust.parquet`), and whether the winner changes
/// with the error model.
fn robust<'a>(space: &'a DesignSpace, v: &'a Verdict, r: &'a RobustVerdict, parts: &mut Summary<'a>) {
    parts.text(format!(
        "## Robust: the winner under each error model\n\nEvery design runs under each of {} error models (`[robust]`: scenario keys set on top of \
         the design) on the same worlds; its score under the file's objective is combined by their {} (lower is better). The race ran every \
         finalist under every model on the search worlds 0-{} (no elimination) and chose the winner of each row below; the held-out worlds \
         (realisations {}-{}) report it under each model. `race.parquet`, `verified.parquet` and the held-out table below hold the first \
         model's rows ({:?}); `robust.parquet` holds every model's.\n\n",
        r.models.len(),
        r.combine.label(),
        v.race_worlds.saturating_sub(1),
        super::HELD_OUT_BASE,
        super::HELD_OUT_BASE + space.held_out - 1,
        r.models[0]
    ));
    let order = robust_order(space, r);
    let at = move |stage: &str, model: Option<usize>, key: &RowKey| order.iter().position(|o| o.0 == stage && o.1 == model && &o.2 == key);
    // Per choice: its race score's row (the finalist under its criterion).
    let rows: Vec<ChoiceRows> = r
        .choices
        .iter()
        .enumerate()
        .map(|(k, c)| {
            let key = (c.verified, c.selection.clone(), c.set_size);
            let finalist = v.finalists.iter().position(|f| f.key == v.verified[c.verified].key);
            let race = finalist.and_then(|p| at("race", (k < r.models.len()).then_some(k), &(p, c.selection.clone(), c.set_size)));
            (race, (0..r.models.len()).map(|m| at("held_out", Some(m), &key)).collect(), at("held_out", None, &key))
        })
        .collect();
    parts.text_from("robust.parquet", move |t| robust_table(v, r, &rows, t));
    parts.text(robust_verdict(v, r));
}

/// The robust table's Markdown from `robust.parquet` (read through `t`) at the rows of each choice.
fn robust_table(v: &Verdict, r: &RobustVerdict, rows: &[ChoiceRows], t: &Row<'_>) -> String {
    let mut s = "| chosen by | design | selection | n | score on the race's worlds |".to_string();
    for m in &r.models {
        s += &format!(" held-out under {m}: estimate (interval) |");
    }
    s += &format!(" held-out score, {} |\n|---|---|---|---|---|{}\n", r.combine.label(), "---|".repeat(r.models.len() + 1));
    for (c, (race, held, combined)) in r.choices.iter().zip(rows) {
        let score = |i: Option<usize>| i.map_or("-".to_string(), |i| f3(t.at(i).f64("score")));
        let design = &v.verified[c.verified].label;
        s += &format!("| {} | {design} | {} | {} | {} |", c.criterion, c.selection, c.set_size, score(*race));
        for h in held {
            s += &match h.map(|i| t.at(i)) {
                Some(h) => format!(
                    " {} ({}-{}), {} worlds, {} failed |",
                    f3(h.f64("estimate")),
                    f3(h.f64("lower")),
                    f3(h.f64("upper")),
                    h.u64("worlds"),
                    h.u64("failed_worlds")
                ),
                None => " every world failed |".to_string(),
            };
        }
        s += &format!(" {} |\n", score(*combined));
    }
    s
}

/// Whether the winner changes with the error model, in words.
fn robust_verdict(v: &Verdict, r: &RobustVerdict) -> String {
    let same = |a: &super::Choice, b: &super::Choice| a.verified == b.verified && a.selection == b.selection && a.set_size == b.set_size;
    let first = &r.choices[0];
    let models: Vec<&super::Choice> = r.choices.iter().take(r.models.len()).collect();
    let robust = r.choices.last().expect("a choice");
    if r.choices.iter().all(|c| same(c, first)) {
        return format!(
            "\n**The winner does not change with the error model**: every model and the {} score choose {} ({} sets of {}).\n\n",
            r.combine.label(),
            v.verified[first.verified].label,
            first.selection,
            first.set_size
        );
    }
    let cells = models.iter().map(|c| c.verified).collect::<std::collections::BTreeSet<_>>().len();
    let differ: Vec<String> = models.iter().filter(|c| !same(c, robust)).map(|c| c.criterion.clone()).collect();
    format!(
        "\n**The winner changes with the error model**: the models choose {} distinct design{} ({}); the {} score's winner differs from the choice of {}.\n\n",
        cells,
        if cells == 1 { " (the same cell, another set size or selection)" } else { "s" },
        models
            .iter()
            .map(|c| format!("{}: {} {} {}", c.criterion, v.verified[c.verified].label, c.selection, c.set_size))
            .collect::<Vec<_>>()
            .join("; "),
        r.combine.label(),
        if differ.is_empty() { "no model".to_string() } else { differ.join(", ") }
    )
}
