//! The optimiser's search score on a synthetic problem with a known optimum, through the same
//! interface as a device's worlds (`design::optimise::WorldSource`): where every design near the
//! start succeeds in every world, P(success) is flat at 1 and the search cannot move; the quantile
//! score (`[search] score = "quantile"`, the default) keeps falling towards the optimum and the
//! search reaches it.

mod common;

use calsim::design::optimise::{self, Context, Evaluated, WorldSource, spec};
use calsim::design::sweep::record::PointStudy;
use calsim::design::sweep::spec::get_dotted;
use calsim::design::sweep::{Sweep, Unit, UnitRow};
use common::{repo, scratch};

/// The optimum in the unit square of the two variables.
const OPTIMUM: [f64; 2] = [0.3, 0.7];

/// A synthetic world: the largest error of every calibration in world `r` of the design at `t`
/// (unit coordinates) is `0.1 + 0.6 |t - OPTIMUM|^2 + 0.005 (r mod 10)` mm, within the 0.5 mm
/// threshold over most of the square (P(success) = 1 there), least at the optimum.
struct Bowl;

fn unit_of(value: f64, lo: f64, hi: f64) -> f64 {
    (value - lo) / (hi - lo)
}

impl WorldSource for Bowl {
    fn run(&self, sweep: &Sweep, point: usize, realisation: u32) -> Unit {
        let s = sweep.points[point].scenario.as_ref();
        let table: toml::Table = s.header().text.parse().expect("a scenario's text");
        let get = |k: &str| get_dotted(&table, k).and_then(|v| v.as_float()).expect(k);
        let t = [unit_of(get("trical.wait_s"), 0.5, 2.0), unit_of(get("trical.approach_move_s"), 2.0, 6.0)];
        let d2: f64 = t.iter().zip(OPTIMUM).map(|(a, b)| (a - b).powi(2)).sum();
        unit_with_error(sweep, point, realisation, 0.1 + 0.6 * d2 + 0.005 * f64::from(realisation % 10))
    }
}

/// A synthetic world's unit whose every calibration's largest error is `e` mm.
fn unit_with_error(sweep: &Sweep, point: usize, realisation: u32, e: f64) -> Unit {
    let s = sweep.points[point].scenario.as_ref();
    let study = PointStudy::of(s);
    let within = |th: &f64| if e <= *th { study.repetitions } else { 0 };
    let counts: Vec<u32> = sweep.thresholds_mm.iter().map(within).collect();
    let rows = study
        .selections
        .iter()
        .flat_map(|sel| {
            let counts = counts.clone();
            study.set_sizes.iter().map(move |&n| UnitRow {
                selection: sel.to_string(),
                set_size: n,
                table: n == study.table_set_size,
                repetitions: study.repetitions,
                no_model: 0,
                after_median_mm: e / 2.0,
                after_p95_mm: e * 0.9,
                after_max_mm: e,
                after_mean_mm: e / 2.0,
                max_within: counts.clone(),
                mean_within: counts.clone(),
                p95_within: counts.clone(),
                median_within: counts.clone(),
                o1_median: f64::NAN,
            })
        })
        .collect();
    Unit {
        unit: point * sweep.realisations as usize + realisation as usize,
        point,
        realisation,
        error: None,
        before_mm: [1.0, 2.0, 3.0],
        campaign_s: 3600.0,
        rows,
        prediction: None,
        design: None,
        digest: None,
    }
}

/// The design file: two variables (their start away from the optimum), P(max <= 0.5 mm) >= 0.9
/// maximised, `score` the search's score (absent: the default).
fn space(dir: &std::path::Path, score: Option<&str>) -> spec::DesignSpace {
    let base = repo().join("scenarios/ci_quick.toml");
    let score = score.map_or(String::new(), |s| format!("score = \"{s}\"\n"));
    let text = format!(
        "base = {:?}\n[fixed]\n\"study.set_sizes\" = [20]\n\"study.table_set_size\" = 20\n\"study.repetitions\" = 2\n\n\
         [[variable]]\nkey = \"trical.wait_s\"\nrange = [0.5, 2.0]\nstart = 1.4\n\n\
         [[variable]]\nkey = \"trical.approach_move_s\"\nrange = [2.0, 6.0]\nstart = 3.6\n\n\
         [objective]\nmaximise = \"success\"\nstatistic = \"max\"\nthreshold_mm = 0.5\nconfidence = 0.9\nsuccess_at_least = 0.9\n\n\
         [search]\nmethod = \"nelder_mead\"\nevaluations = 60\nworlds = 10\n{score}",
        base.display().to_string()
    );
    let name = format!("bowl-{}.toml", score.len());
    let f = dir.join(name);
    std::fs::write(&f, text).unwrap();
    spec::load(&f).unwrap()
}

/// The search's designs on the synthetic worlds, and the best (lowest score, the first of ties).
fn search(space: &spec::DesignSpace, dir: &std::path::Path) -> (Vec<Evaluated>, Vec<f64>) {
    let ctx = Context::with_worlds(space, dir.join(format!("{}.evaluations", space.name)), &Bowl);
    let trace = optimise::run_restart(&ctx, 0, &|_| {}).unwrap();
    let best =
        trace.iter().min_by(|a, b| a.score.total_cmp(&b.score).then(a.asked.index.cmp(&b.asked.index))).expect("evaluated").asked.x.clone();
    (trace, best)
}

fn distance(x: &[f64]) -> f64 {
    x.iter().zip(OPTIMUM).map(|(a, b)| (a - b).powi(2)).sum::<f64>().sqrt()
}

#[test]
fn the_quantile_score_reaches_a_known_optimum_where_p_success_saturates_and_stops_the_search() {
    let tmp = scratch("optimise-bowl");
    let quantile = space(tmp.path(), None);
    assert_eq!(quantile.search.score, spec::SearchScore::Quantile, "the default");
    let success = space(tmp.path(), Some("success"));
    let start = quantile.start(0);
    assert!(distance(&start) > 0.4, "the start {start:?} is away from the optimum");

    // P(success): every design the search asks succeeds in every world (score -1), so the simplex
    // has nothing to follow and the best design is the start.
    let (trace, best) = search(&success, tmp.path());
    assert!(trace.iter().all(|e| e.score == -1.0), "saturated: {:?}", trace.iter().map(|e| e.score).collect::<Vec<_>>());
    assert!(distance(&best) > 0.4, "P(success) left the start {start:?} for {best:?}");

    // The quantile: the search follows the errors down to the optimum.
    let (trace, best) = search(&quantile, tmp.path());
    assert!(trace.len() <= 60);
    assert!(distance(&best) < 0.03, "the quantile score's best {best:?} against the optimum {OPTIMUM:?}");
    // Its score at the best design is the 0.9 quantile of the ten worlds' largest errors over the
    // threshold: (0.1 + 0.6 d^2 + 0.005 x 8.1) / 0.5 (order statistics 9 and 10 of 0..9 x 0.005).
    let at_best = trace.iter().map(|e| e.score).fold(f64::INFINITY, f64::min);
    // (at the design as decoded: its values rounded to the resolution of their ranges)
    let d = quantile.decode(0, &best);
    let get = |k: &str| get_dotted(&d.table, k).and_then(|v| v.as_float()).unwrap();
    let t = [unit_of(get("trical.wait_s"), 0.5, 2.0), unit_of(get("trical.approach_move_s"), 2.0, 6.0)];
    let expected = (0.1 + 0.6 * distance(&t).powi(2) + 0.005 * 8.1) / 0.5;
    assert!((at_best - expected).abs() < 1e-9, "score {at_best} against {expected}");
}

#[test]
fn the_search_score_key_is_checked_naming_it() {
    let tmp = scratch("optimise-score-key");
    let base = repo().join("scenarios/ci_quick.toml");
    let f = tmp.path().join("bad.toml");
    std::fs::write(
        &f,
        format!(
            "base = {:?}\n[objective]\nmaximise = \"success\"\nthreshold_mm = 0.5\n[search]\nscore = \"p95\"\n",
            base.display().to_string()
        ),
    )
    .unwrap();
    let e = spec::load(&f).unwrap_err();
    assert_eq!(e.key, "search.score");
    assert!(e.message.contains("\"quantile\" or \"success\""), "{}", e.message);
}

#[test]
fn the_quantile_score_is_the_empirical_quantile_over_the_threshold_with_failed_worlds_capped() {
    let v = [0.1, 0.2, 0.3, 0.4, f64::INFINITY, f64::NAN];
    // Five values (NaN left out): at (5 - 1) x 0.5 = 2, the third: 0.3 / 0.5.
    assert!((optimise::quantile_score(&v, 0.5, 0.5) - 0.6).abs() < 1e-12);
    // At 0.95: between 0.4 / 0.5 = 0.8 and the failed world's cap of 10 thresholds, 0.8 of the way.
    assert!((optimise::quantile_score(&v, 0.95, 0.5) - (0.8 + 0.8 * (10.0 - 0.8))).abs() < 1e-12);
    assert!(optimise::quantile_score(&[f64::NAN], 0.9, 0.5).is_nan());
}

/// A range variable's value is rounded to four digits below the range's leading one, never -0.0:
/// the shipped TriCal file's epsilon start is 0.02 exactly.
#[test]
fn range_values_are_tidy_at_the_resolution_of_their_range() {
    assert_eq!(spec::at_resolution(0.019999999999999997, 0.025), 0.02);
    assert_eq!(spec::at_resolution(123.456789, 400.0), 123.46);
    assert!(spec::at_resolution(-1e-9, 400.0).is_sign_positive());
    let space = spec::load(&repo().join("scenarios/designs/irb120_spheres.toml")).unwrap();
    let d = space.decode(5, &space.start(5));
    let epsilon = get_dotted(&d.table, "trical.epsilon_mm").and_then(|v| v.as_float()).unwrap();
    assert_eq!(epsilon.to_string(), "0.02");
}

/// A world in which every campaign fails (a design out of the arm's reach).
struct Unreachable;

impl WorldSource for Unreachable {
    fn run(&self, sweep: &Sweep, point: usize, realisation: u32) -> Unit {
        Unit {
            unit: point * sweep.realisations as usize + realisation as usize,
            point,
            realisation,
            error: Some("campaign: sphere 4: the device cannot be centred on it".into()),
            before_mm: [f64::NAN; 3],
            campaign_s: f64::NAN,
            rows: Vec::new(),
            prediction: None,
            design: None,
            digest: None,
        }
    }
}

/// The per-sphere distances from the arm's reach of the design at `x` (`count` spheres).
fn margins(space: &spec::DesignSpace, count: usize, x: &[f64]) -> Vec<f64> {
    let d = space.decode(count, x);
    assert!(d.violation.is_none(), "{:?}", d.violation);
    let text = toml::to_string(&d.table).unwrap();
    let s = calsim::device::from_table(&text, d.table.clone(), &space.path).unwrap();
    optimise::reach::sphere_margins_mm(s.as_ref()).expect("a TriCal design")
}

/// The paper's cell with five spheres (the shipped file's start from the paper) puts sphere 4
/// out of the arm's reach, and sphere 5 at the box's far corner is out too: a design whose every
/// world fails scores [`optimise::FAILED`] plus the sum of its spheres' distances from the reach
/// / 100 plus its campaign's shortfall ([`optimise::failed_score`]), so that moving either sphere towards
/// the arm lowers it; and the start brought into reach (`optimise::into_reach`, no world run)
/// has every sphere's centring pose reached.
#[test]
fn a_design_out_of_reach_scores_by_every_spheres_distance_and_its_start_is_brought_into_reach() {
    let tmp = scratch("optimise-reach");
    let space = spec::load(&repo().join("scenarios/designs/irb120_spheres_from_paper.toml")).unwrap();
    let paper = space.start(5);
    let m = margins(&space, 5, &paper);
    assert_eq!(m[..3], [0.0, 0.0, 0.0], "the paper's three spheres are within reach: {m:?}");
    assert!(m[3] > 20.0, "sphere 4 out of reach: {m:?}");
    // Sphere 5 moved to the box's far corner (x = y = 450 mm), out of reach too.
    let v = space.variables.len() + 2;
    let mut start = paper.clone();
    start[v + 8] = 1.0;
    start[v + 9] = 1.0;
    let m = margins(&space, 5, &start);
    assert!(m[3] > 20.0 && m[4] > m[3], "spheres 4 and 5 out of reach, 5 the farther: {m:?}");
    let ctx = Context::with_worlds(&space, tmp.path().join("w"), &Unreachable);
    let score = |x: &[f64]| {
        let e = ctx.evaluate(optimise::Asked { restart: 0, index: 0, count: 5, x: x.to_vec() }).unwrap();
        assert_eq!(e.failed, e.worlds);
        e.score
    };
    let at_start = score(&start);
    let shortfall = feasibility(&space, 5, &start).total();
    assert!((at_start - (optimise::FAILED + m.iter().sum::<f64>() / 100.0 + shortfall)).abs() < 1e-9, "{at_start} from {m:?}, {shortfall}");
    // Each of spheres 4 and 5 moved a tenth of the way towards sphere 1 (which the arm reaches):
    // nearer the reach, a lower score (not only the farthest sphere counts).
    for k in [3, 4] {
        let mut x = start.clone();
        for j in 0..2 {
            x[v + 2 * k + j] += 0.1 * (start[v + j] - start[v + 2 * k + j]);
        }
        let moved = margins(&space, 5, &x);
        assert!(moved[k] < m[k], "sphere {} nearer: {moved:?} against {m:?}", k + 1);
        let s = score(&x);
        assert!(s < at_start && s >= optimise::FAILED, "sphere {} moved: {s} against {at_start}", k + 1);
    }
    let repaired = optimise::into_reach(&ctx, 5, start.clone());
    assert_ne!(repaired, start);
    assert_eq!(margins(&space, 5, &repaired), vec![0.0; 5], "brought into reach");
    // A start in reach is kept as it is.
    assert_eq!(optimise::into_reach(&ctx, 5, repaired.clone()), repaired);
}

/// The order of the search scores: a design that ran in some world (any score, [`optimise::ran`])
/// below one whose every world failed ([`optimise::FAILED`] and its reach), below one the geometry
/// rules out (10 x 10 and more); within each, the order kept.
#[test]
fn a_design_that_ran_beats_one_that_failed_everywhere_which_beats_one_ruled_out() {
    let scores = [-1.0, 0.0, 5.0, 19.9, 20.0, 25.0, 40.0, 1e3, 1e9, f64::INFINITY];
    let ran: Vec<f64> = scores.iter().map(|s| optimise::ran(*s)).collect();
    assert_eq!(ran[..5], scores[..5], "the score itself up to 20");
    assert!(ran.windows(2).all(|w| w[0] < w[1]), "increasing: {ran:?}");
    assert!(ran.iter().all(|s| *s < optimise::FAILED), "under the failures': {ran:?}");
    assert!(optimise::ran(f64::NAN) < optimise::FAILED);
    let reach = [0.0, 10.0, 250.0, 1e4, f64::INFINITY];
    let failed: Vec<f64> = reach.iter().map(|d| optimise::FAILED + optimise::reach_score(&[*d, 30.0])).collect();
    assert!(failed.windows(2).all(|w| w[0] <= w[1]), "{failed:?}");
    assert!(failed[0] > optimise::FAILED && failed[2] > failed[1], "{failed:?}");
    assert!(failed.iter().all(|s| *s < 100.0), "under a geometric violation's 100: {failed:?}");
}

/// The campaign's feasibility of the design at `x` (`count` spheres).
fn feasibility(space: &spec::DesignSpace, count: usize, x: &[f64]) -> calsim::device::trical::campaign::Feasibility {
    let d = space.decode(count, x);
    assert!(d.violation.is_none(), "{:?}", d.violation);
    let text = toml::to_string(&d.table).unwrap();
    let s = calsim::device::from_table(&text, d.table.clone(), &space.path).unwrap();
    s.campaign_feasibility().expect("a TriCal design")
}

/// The seeded random start of the TriCal question (`irb120_spheres_from_random.toml`, 4 spheres)
/// has every sphere's centring pose within the arm's reach, yet its campaign fails: its cell
/// stands in the arm's way, so that no pool or validation candidate is free of collision. Its
/// score, where every world fails, is [`optimise::FAILED`] plus the campaign's shortfall (the sets'
/// nearest candidates' penetration depths; the reach alone would give a flat 30); brought to a
/// campaign that can run (`optimise::into_reach`, no world run), the shortfall is 0, candidates
/// of every set are accepted, and the campaign of a real world runs.
#[test]
fn a_design_in_reach_whose_cell_blocks_the_arm_scores_by_its_collisions_and_its_start_is_brought_to_a_campaign_that_runs() {
    let tmp = scratch("optimise-feasible");
    let space = spec::load(&repo().join("scenarios/designs/irb120_spheres_from_random.toml")).unwrap();
    let start = space.start(4);
    assert_eq!(margins(&space, 4, &start), vec![0.0; 4], "every centring pose reached");
    let f = feasibility(&space, 4, &start);
    assert!(f.pool_share.iter().all(|s| *s == 0.0) && f.validation_share == 0.0, "{f:?}");
    assert!(f.shortfall.iter().all(|s| *s > 0.0 && *s < 1.0), "colliding, not unreachable: {f:?}");
    let run = |x: &[f64]| {
        let d = space.decode(4, x);
        let text = toml::to_string(&d.table).unwrap();
        let s = calsim::device::from_table(&text, d.table.clone(), &space.path).unwrap();
        s.run(s.header().seed, &|_, _| {}).err().map(|e| e.to_string())
    };
    // The candidates are tried in parallel and gathered in order: the same figures on 1 and 2 threads.
    let on = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| feasibility(&space, 4, &start))
    };
    assert_eq!(on(1), on(2));
    assert_eq!(on(1), f);
    let why = run(&start).expect("the start's campaign fails");
    assert!(why.contains("no valid configuration"), "{why}");
    let ctx = Context::with_worlds(&space, tmp.path().join("w"), &Unreachable);
    let score = |x: &[f64]| {
        let e = ctx.evaluate(optimise::Asked { restart: 0, index: 0, count: 4, x: x.to_vec() }).unwrap();
        assert_eq!(e.failed, e.worlds);
        (e.score, e.shortfall)
    };
    let (at_start, shortfall) = score(&start);
    assert!((shortfall - f.total()).abs() < 1e-12 && (at_start - (optimise::FAILED + f.total())).abs() < 1e-9, "{at_start} {f:?}");
    let repaired = optimise::into_reach(&ctx, 4, start.clone());
    assert_ne!(repaired, start);
    let g = feasibility(&space, 4, &repaired);
    assert_eq!(g.total(), 0.0, "{g:?}");
    assert!(g.pool_share.iter().all(|s| *s > 0.0) && g.validation_share > 0.0, "{g:?}");
    assert_eq!(margins(&space, 4, &repaired), vec![0.0; 4]);
    assert_eq!(score(&repaired).0, optimise::FAILED, "nothing short but the worlds this source fails");
    assert!(at_start > optimise::FAILED + 1.0, "{at_start}");
    assert_eq!(run(&repaired), None, "the campaign of world 0 runs");
}

/// The paper's cell of the TriCal question with `count` spheres, in the unit cube, and the
/// offset of the spheres' coordinates in it.
fn paper(count: usize) -> (spec::DesignSpace, Vec<f64>, usize) {
    let space = spec::load(&repo().join("scenarios/designs/irb120_spheres_from_paper.toml")).unwrap();
    let x = space.start(count);
    let v = space.variables.len() + 2;
    (space, x, v)
}

fn closest_pair_mm(points: &[[f64; 3]]) -> f64 {
    let mut d = f64::INFINITY;
    for i in 0..points.len() {
        for j in 0..i {
            d = d.min((0..3).map(|k| (points[i][k] - points[j][k]).powi(2)).sum::<f64>().sqrt());
        }
    }
    d
}

/// A design whose spheres break the spacing rule, lie nearly on one line or turn clockwise is
/// moved to a valid design near it (`DesignSpace::repair`): spacing cleared, {W} defined with its
/// z axis up; the clockwise one by renumbering spheres 2 and 3 alone (no sphere moves).
#[test]
fn a_design_that_breaks_a_geometric_rule_is_repaired_to_a_valid_design_near_it() {
    let (space, start, v) = paper(4);
    assert!(space.search.repair, "the default");
    assert!(space.decode(4, &start).violation.is_none());
    assert!(space.repair(4, &start).is_none(), "a valid design needs no repair");

    // Sphere 4 moved 20 mm from sphere 2 (x = 300 mm, y = 0): under the 100 mm spacing.
    let mut close = start.clone();
    close[v + 6] = start[v + 2] + 20.0 / 600.0;
    close[v + 7] = start[v + 3];
    let broke = space.decode(4, &close).violation.expect("too close").0;
    assert!(broke.contains("points 2 and 4"), "{broke}");
    let r = space.repair(4, &close).expect("repaired");
    assert_eq!(r.broke, broke);
    let d = space.decode(4, &r.x);
    assert!(d.violation.is_none(), "{:?}", d.violation);
    assert!(closest_pair_mm(&d.points_mm) >= 100.0, "{:?}", d.points_mm);
    // The shortfall is 80 mm: the pair is pushed apart by it, nothing else moves.
    assert!((r.moved_mm - 80.0).abs() < 0.01, "{}", r.moved_mm);
    assert_eq!(r.x[..v], close[..v], "the variables and the plate kept");
    assert_eq!(space.repair(4, &close), Some(r), "deterministic");

    // Sphere 3 on the line through spheres 1 and 2 (x = 150 mm, y = 0): no {W}.
    let mut line = start.clone();
    line[v + 5] = start[v + 1];
    let broke = space.decode(4, &line).violation.expect("on one line").0;
    assert!(broke.contains("nearly on one line"), "{broke}");
    let r = space.repair(4, &line).expect("repaired");
    assert!(space.decode(4, &r.x).violation.is_none());
    assert_eq!(r.x[..v + 4], line[..v + 4], "spheres 1 and 2 kept");

    // Spheres 2 and 3 swapped: clockwise seen from above, {W}'s z axis down (a plate offset's turn
    // about x beyond 90 degrees, which the scenario refuses); renumbered, the same places.
    let mut turned = start.clone();
    turned.swap(v + 2, v + 4);
    turned.swap(v + 3, v + 5);
    let broke = space.decode(4, &turned).violation.expect("clockwise").0;
    assert!(broke.contains("clockwise"), "{broke}");
    let r = space.repair(4, &turned).expect("repaired");
    assert_eq!(r.x, start, "renumbered back");
    assert_eq!(r.moved_mm, 0.0);
}

/// The search evaluates the repaired design: its worlds run and its score is theirs plus
/// `REPAIR_PER_MM` per mm moved; with `[search] repair = false` the same design is ruled out,
/// runs nothing and scores its violation (100 and more).
#[test]
fn the_search_runs_a_repaired_design_where_without_repair_it_rules_it_out() {
    let tmp = scratch("optimise-repair");
    let (space, start, v) = paper(4);
    let mut close = start.clone();
    close[v + 6] = start[v + 2] + 20.0 / 600.0;
    close[v + 7] = start[v + 3];
    let asked = optimise::Asked { restart: 0, index: 0, count: 4, x: close.clone() };
    let ctx = Context::with_worlds(&space, tmp.path().join("w"), &Unreachable);
    let e = ctx.evaluate(asked.clone()).unwrap();
    assert!(e.violation.is_none(), "{:?}", e.violation);
    let r = e.repaired.clone().expect("repaired");
    assert_eq!(e.worlds, space.search.worlds);
    assert!(closest_pair_mm(&e.points_mm) >= 100.0, "{:?}", e.points_mm);
    assert_eq!(e.asked.x, close, "the trace keeps what the search asked");
    let at = ctx.evaluate(optimise::Asked { x: r.x.clone(), ..asked.clone() }).unwrap();
    assert!(at.repaired.is_none());
    assert_eq!(at.key, e.key, "the repaired design itself");
    assert!((e.score - (at.score + optimise::REPAIR_PER_MM * r.moved_mm)).abs() < 1e-12, "{} {}", e.score, at.score);
    assert!(e.score < 100.0);

    let mut off = space.clone();
    off.search.repair = false;
    let ctx = Context::with_worlds(&off, tmp.path().join("w"), &Unreachable);
    let e = ctx.evaluate(asked).unwrap();
    assert!(e.violation.is_some() && e.repaired.is_none() && e.worlds == 0);
    assert!(e.score >= 100.0, "{}", e.score);
}

/// A design brought to another count of spheres (`DesignSpace::recount`): spheres 1 to 3 and the
/// variables kept; dropped, the spheres closest to another (never 1 to 3); added, at the free
/// place farthest from every sphere; the result valid.
#[test]
fn a_design_is_brought_to_another_count_keeping_w_and_spreading_the_spheres() {
    let (space, three, v) = paper(3);
    let six = space.recount(3, &three, 6);
    assert_eq!(six.len(), space.dimensions(6));
    assert_eq!(six[..v + 6], three[..], "the variables, the plate and spheres 1 to 3 kept");
    let d = space.decode(6, &six);
    assert!(d.violation.is_none(), "{:?}", d.violation);
    // The 4th sphere at the place farthest from the three: a corner of the box, beyond 300 mm.
    assert!(closest_pair_mm(&d.points_mm) >= 100.0);
    let back = space.recount(6, &six, 3);
    assert_eq!(back, three, "the spheres added are the ones dropped");
    let four = space.recount(6, &six, 4);
    assert_eq!(four[..v + 6], three[..]);
    assert!(space.decode(4, &four).violation.is_none());
    // Of the paper's six (a circle), the closest spheres go first: the count's own start kept at
    // spheres 1 to 3.
    let (_, paper6, _) = paper(6);
    assert_eq!(space.recount(6, &paper6, 3)[..], paper6[..v + 6]);
}

/// Synthetic SPMS worlds: the largest error falls with the count of stations and with their
/// distance from the box's middle (x = 1100, y = 0, z = 800 mm), so that the best design has
/// three stations spread out.
struct Stations;

impl WorldSource for Stations {
    fn run(&self, sweep: &Sweep, point: usize, realisation: u32) -> Unit {
        let s = sweep.points[point].scenario.as_ref();
        let table: toml::Table = s.header().text.parse().expect("a scenario's text");
        let pts = get_dotted(&table, "station.sphere_points_base_mm").and_then(|v| v.as_array()).expect("stations").clone();
        let spread: f64 = pts
            .iter()
            .map(|p| {
                let c: Vec<f64> = p.as_array().unwrap().iter().map(|v| v.as_float().unwrap()).collect();
                ((c[0] - 1100.0).powi(2) + c[1].powi(2) + (c[2] - 800.0).powi(2)).sqrt()
            })
            .sum();
        let e = 0.9 / pts.len() as f64 + 0.2 / (1.0 + spread / 1000.0) + 0.005 * f64::from(realisation % 10);
        unit_with_error(sweep, point, realisation, e)
    }
}

/// The restarts run the first repetition of every count, then the second of every count; the
/// second starts from the best design of the first ones at any count, brought to its own count
/// (`DesignSpace::recount`, then brought into reach as every start); with `across_counts =
/// false`, from the Latin hypercube.
#[test]
fn the_second_repetition_of_every_count_starts_from_the_best_design_at_any_count() {
    let tmp = scratch("optimise-across");
    let text = std::fs::read_to_string(repo().join("scenarios/designs/spms_stations.toml")).unwrap();
    let base = format!("base = {:?}", repo().join("scenarios/er20c10_spms.toml").display().to_string());
    let text = text.replace("base = \"../er20c10_spms.toml\"", &base);
    let text = text.replace("evaluations = 20", "evaluations = 6\nrestarts = 2").replace("worlds = 6", "worlds = 2");
    let text = text.replace("compare = [\"../sweeps/spms_stations.toml\"]", "");
    let f = tmp.path().join("stations.toml");
    std::fs::write(&f, &text).unwrap();
    let space = spec::load(&f).unwrap();
    assert!(space.search.across_counts, "the default");
    assert_eq!(optimise::restarts(&space), vec![(1, 0), (2, 0), (3, 0), (1, 1), (2, 1), (3, 1)]);
    let ctx = Context::with_worlds(&space, tmp.path().join("w"), &Stations);
    let first: Vec<Evaluated> = (0..3).flat_map(|r| optimise::run_restart(&ctx, r, &|_| {}).unwrap()).collect();
    let best = first.iter().filter(|e| e.worlds > 0).min_by(|a, b| a.score.total_cmp(&b.score)).unwrap();
    assert_eq!(best.asked.count, 3, "three stations are best");
    let best_x = best.repaired.as_ref().map_or(&best.asked.x, |r| &r.x).clone();
    for (r, count) in [(3, 1), (5, 3)] {
        let second = optimise::run_restart(&ctx, r, &|_| {}).unwrap();
        let from = optimise::into_reach(&ctx, count, space.recount(3, &best_x, count));
        assert_eq!(second[0].asked.x, from, "restart {r} ({count} stations) starts from the best brought to its count");
    }
    // The best of count 3 seeds count 3 itself: its second repetition starts at that design.
    assert_eq!(space.recount(3, &best_x, 3), best_x);

    let mut off = space.clone();
    off.search.across_counts = false;
    let ctx = Context::with_worlds(&off, tmp.path().join("w2"), &Stations);
    let second = optimise::run_restart(&ctx, 3, &|_| {}).unwrap();
    let lhs = optimise::spread_starts(off.dimensions(1), 1, off.search.seed, 1).swap_remove(0);
    assert_eq!(second[0].asked.x, optimise::into_reach(&ctx, 1, lhs));
}
