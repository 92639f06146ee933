//! The tables a TriCal or tracker summary shows beside the study's own, and the summary rendered
//! from them: `errors.parquet` (before and after calibration at the table set size),
//! `set_sizes.parquet` (Figs. 8-9), and for the TriCal study `table7.parquet` (the identified
//! parameters beside the paper's) and `correlations.parquet` (Figs. 11-12).

use polars::prelude::Column;

use super::figures::Figures;
use super::spec::TricalScenario;
use super::study::StudyResults;
use crate::io::results::{Results, Row, Rows, Summary, cell};
use crate::study::published::published;

/// `x` with three decimals, `-` when it is not a number.
fn f3(x: f64) -> String {
    if x.is_finite() { format!("{x:.3}") } else { "-".into() }
}

/// `errors.parquet` and `set_sizes.parquet`; `paper`: with the published figures beside them
/// (before calibration and Table 8's TriCal row).
pub fn figure_tables(r: &StudyResults, f: &Figures, paper: bool, out: &mut Results<'_>) -> std::io::Result<()> {
    out.table("errors.parquet", error_columns(r, f, paper))?;
    let z = &f.sizes;
    let c = |name: &str, v: Vec<f64>| Column::new(name.into(), v);
    out.table(
        "set_sizes.parquet",
        vec![
            Column::new("set_size".into(), z.iter().map(|z| z.n as u32).collect::<Vec<_>>()),
            c("median_of_means_mm", z.iter().map(|z| z.median_of_means).collect()),
            c("iqr_of_means_mm", z.iter().map(|z| z.iqr_of_means).collect()),
            c("median_of_stds_mm", z.iter().map(|z| z.median_of_stds).collect()),
            Column::new("not_converged".into(), z.iter().map(|z| z.not_converged as u32).collect::<Vec<_>>()),
        ],
    )?;
    Ok(())
}

/// A row of `errors.parquet`: calibration, set size, mean, median, std, p95 and max, targets failed.
type ErrorRow = (&'static str, Option<u32>, [Option<f64>; 5], Option<u32>);

/// The columns of `errors.parquet`: one row before calibration, one after at the table set size
/// (medians over the repetitions), one for the compensated targets when the study ran them.
fn error_columns(r: &StudyResults, f: &Figures, paper: bool) -> Vec<Column> {
    let comp: Vec<&super::study::Compensated> = r.tasks.iter().filter_map(|x| x.compensated.as_ref()).collect();
    let med = |g: fn(&crate::study::ErrorStats) -> f64| crate::study::stats::median(&comp.iter().map(|c| g(&c.stats)).collect::<Vec<_>>());
    let b = &f.before;
    let mut rows: Vec<ErrorRow> = vec![
        ("before", None, [Some(b.mean), Some(b.median), Some(b.std), Some(b.p95), Some(b.max)], None),
        ("after", Some(f.table_n as u32), [Some(f.after_mean), Some(f.after_median), Some(f.after_std), None, Some(f.after_max)], None),
    ];
    if !comp.is_empty() {
        let stats = [med(|s| s.mean), med(|s| s.median), med(|s| s.std), med(|s| s.p95), med(|s| s.max)].map(Some);
        rows.push(("after_compensated", Some(f.table_n as u32), stats, Some(comp.iter().map(|c| c.failed as u32).sum())));
    }
    let stat = |name: &str, k: usize| Column::new(name.into(), rows.iter().map(|x| x.2[k]).collect::<Vec<_>>());
    let mut cols = vec![
        Column::new("calibration".into(), rows.iter().map(|x| x.0).collect::<Vec<_>>()),
        Column::new("set_size".into(), rows.iter().map(|x| x.1).collect::<Vec<_>>()),
        stat("mean_mm", 0),
        stat("median_mm", 1),
        stat("std_mm", 2),
        stat("p95_mm", 3),
        stat("max_mm", 4),
        Column::new("targets_failed".into(), rows.iter().map(|x| x.3).collect::<Vec<_>>()),
    ];
    if paper {
        // The paper's figures: before calibration (mean, max) and Table 8's TriCal row (median, std, max).
        let (pb, t8) = (&published().trical_2018.before_calibration, published().trical_2018.table8("TriCal"));
        let at = |before: Option<f64>, after: Option<f64>| rows.iter().map(|x| if x.0 == "before" { before } else { after }).collect();
        let p = |name: &str, v: Vec<Option<f64>>| Column::new(name.into(), v);
        cols.push(p("published_mean_mm", at(Some(pb.mean_mm), None)));
        cols.push(p("published_median_mm", at(None, Some(t8.median_mm))));
        cols.push(p("published_std_mm", at(None, Some(t8.std_mm))));
        cols.push(p("published_max_mm", at(Some(pb.max_mm), Some(t8.max_mm))));
    }
    cols
}

/// `table7.parquet` and `correlations.parquet` of the TriCal study.
pub fn trical_tables(scenario: &TricalScenario, r: &StudyResults, f: &Figures, out: &mut Results<'_>) -> std::io::Result<()> {
    let p = &f.table7;
    let fit = fit_std(scenario, r, f.table_n);
    let fit_of = |j: usize| fit.as_ref().and_then(|v| v.get(j).copied());
    // Not determined: the interval of 2 fit standard deviations about the mean holds zero.
    let determined = |j: usize| !fit_of(j).map(|sd| 2.0 * sd).is_some_and(|half| half.is_nan() || half >= p[j].mean.abs());
    let c = |name: &str, g: fn(&super::figures::ParamStats) -> f64| Column::new(name.into(), p.iter().map(g).collect::<Vec<_>>());
    let o = |name: &str, v: Vec<Option<f64>>| Column::new(name.into(), v);
    let b = |name: &str, v: Vec<Option<bool>>| Column::new(name.into(), v);
    out.table(
        "table7.parquet",
        vec![
            Column::new("parameter".into(), p.iter().map(|x| x.name.clone()).collect::<Vec<_>>()),
            Column::new("unit".into(), p.iter().map(|x| x.unit).collect::<Vec<_>>()),
            c("truth", |x| x.truth),
            c("mean", |x| x.mean),
            c("std", |x| x.std),
            c("min", |x| x.min),
            c("max", |x| x.max),
            o("published_mean", p.iter().map(|x| x.published.map(|p| p.0)).collect()),
            o("published_std", p.iter().map(|x| x.published.map(|p| p.1)).collect()),
            o("fit_std", (0..p.len()).map(fit_of).collect()),
            Column::new("determined".into(), (0..p.len()).map(determined).collect::<Vec<_>>()),
            b("std_within_factor3", p.iter().map(|x| x.std_within_factor3()).collect()),
            b("mean_within_3std", p.iter().map(|x| x.mean_within_3std()).collect()),
        ],
    )?;
    out.table(
        "correlations.parquet",
        vec![
            Column::new("sets".into(), vec!["representative", "pooled"]),
            Column::new("r_distance_to_base".into(), vec![f.r_base, f.r_base_pooled]),
            Column::new("r_distance_to_ccz".into(), vec![f.r_ccz, f.r_ccz_pooled]),
        ],
    )?;
    Ok(())
}

/// Each identified parameter's standard deviation (in the unit Table 7 shows) from the fit of the
/// representative set at `n`: `sigma^2 (J^T J)^-1` with sigma from the fit's residuals, as `calsim
/// export` writes it. `None` when that set cannot be refitted or its covariance is singular.
fn fit_std(scenario: &TricalScenario, r: &StudyResults, n: usize) -> Option<Vec<f64>> {
    use crate::device::Scenario as _;
    let (index, _) = super::figures::representative(r, n)?;
    let refit = scenario.refit(index).ok()??;
    let model = refit.model?;
    let (count, m) = (refit.observations.len(), refit.set.len());
    let sigma = crate::study::prediction::noise_estimate(refit.residual_rms_mm, count, m);
    let qs: Vec<_> = refit.observations.iter().map(|o| o.q).collect();
    let cov = crate::identify::observability::parameter_covariance(&model, &refit.set, &qs, sigma)?;
    Some(refit.set.ids().iter().enumerate().map(|(j, id)| id.unit().from_internal(cov[(j, j)].max(0.0).sqrt())).collect())
}

/// The summary of a TriCal study: the paper's Tables 7 and 8 and before/after figures next to
/// calsim's, every figure read from the tables.
pub fn trical(scenario: &TricalScenario, checks: bool, parts: &mut Summary<'_>) {
    let (seed, sizes, reps) = (scenario.header.seed, scenario.study.set_sizes.len(), scenario.study.repetitions);
    let pool = scenario.experiment.campaign.pool_per_sphere as usize * scenario.experiment.cell.spheres_w_mm.len();
    parts.text(format!("# {}: calsim against the published figures\n\n", scenario.header.name));
    parts.text_from("tasks.parquet", move |r| {
        format!(
            "Seed {seed}, {} identifications ({sizes} set sizes x {reps} repetitions), DETMAX on O1 over a pool of {pool}, \
             validation on {} poses.\n\n",
            r.height(),
            r.of("validation_errors.parquet", 0).count("calibration", "before")
        )
    });
    if checks {
        crate::study::check::checks_summary("Published versus reproduced", parts);
    }
    parts.text_from("errors.parquet", move |r| {
        format!(
            "After-calibration figures are medians over the {reps} repetitions at n = {} of each identification's statistic \
             over the validation poses.\n\n## Errors before and after calibration (mm)\n\n",
            r.at(1).u64("set_size")
        )
    });
    errors(parts, Summary::all_rows(), |r| match r.str("calibration").as_str() {
        "before" => format!("before (paper: mean {}, max {})", r.f64("published_mean_mm"), r.f64("published_max_mm")),
        "after" => format!(
            "after, n = {} (median over repetitions; paper Table 8: median {}, std {}, max {})",
            r.u64("set_size"),
            r.f64("published_median_mm"),
            r.f64("published_std_mm"),
            r.f64("published_max_mm")
        ),
        _ => compensated_label(r),
    });
    parts.text_from("errors.parquet", |r| {
        if r.count("calibration", "after_compensated") == 0 {
            return String::new();
        }
        "Compensated targets: each validation TCP of the model before calibration as a Cartesian target, the joint values \
         that put the identified model there, the robot moved there and measured by the tracker (`compensated.parquet`).\n\n"
            .to_string()
    });
    table7(parts);
    size_table(parts, true);
    correlations(parts);
}

/// The label of the compensated row of `errors.parquet`.
fn compensated_label(r: &Row<'_>) -> String {
    format!(
        "after, n = {}, compensated targets (median over repetitions; {} targets without joint values)",
        r.u64("set_size"),
        r.u64("targets_failed")
    )
}

/// The table of the rows `rows` picks of `errors.parquet`, each under its `label`.
pub fn errors<'a>(parts: &mut Summary<'a>, rows: Rows<'a>, label: impl Fn(&Row<'_>) -> String + 'a) {
    let stat = |name: &'static str| move |r: &Row<'_>| f3(r.f64(name));
    parts.table(
        "errors.parquet",
        rows,
        vec![
            cell("", label),
            cell("mean", stat("mean_mm")),
            cell("median", stat("median_mm")),
            cell("std", stat("std_mm")),
            cell("p95", stat("p95_mm")),
            cell("max", stat("max_mm")),
        ],
    );
}

/// Table 7 from `table7.parquet`: a parameter the sets do not determine shown as such.
fn table7(parts: &mut Summary<'_>) {
    parts.text_from("errors.parquet", |r| format!("## Table 7: identified parameters over the sets of {}\n\n", r.at(1).u64("set_size")));
    parts.text_from("table7.parquet", |r| {
        if !(0..r.height()).any(|i| r.at(i).f64("fit_std").is_finite()) {
            return String::new();
        }
        "A parameter whose interval (its mean +- 2 standard deviations of the representative set's fit, sigma^2 (J^T J)^-1 \
         with sigma from the fit's residuals) holds zero, 2 standard deviations larger than its value, is not determined by \
         the sets: it is shown as such, not compared with the truth.\n\n"
            .to_string()
    });
    let f4 = |name: &'static str| move |r: &Row<'_>| format!("{:.4}", r.f64(name));
    let published = |name: &'static str| move |r: &Row<'_>| f3(r.f64(name));
    // A rule's answer, `-` where the sets do not determine the parameter or the paper lists none.
    let rule = |name: &'static str| {
        move |r: &Row<'_>| match r.opt_bool(name).filter(|_| r.bool("determined")) {
            Some(true) => "yes".to_string(),
            Some(false) => "no".to_string(),
            None => "-".to_string(),
        }
    };
    let mean = |r: &Row<'_>| match r.bool("determined") {
        true => format!("{:.4}", r.f64("mean")),
        false => format!("not determined ({:.4} +- {:.4})", r.f64("mean"), 2.0 * r.f64("fit_std")),
    };
    let cells = vec![
        cell("parameter", |r| r.str("parameter")),
        cell("unit", |r| r.str("unit")),
        cell("truth", f4("truth")),
        cell("mean", mean),
        cell("std", f4("std")),
        cell("min", f4("min")),
        cell("max", f4("max")),
        cell("paper mean", published("published_mean")),
        cell("paper std", published("published_std")),
        cell("std within x3", rule("std_within_factor3")),
        cell("mean within 3 std", rule("mean_within_3std")),
    ];
    parts.table("table7.parquet", Summary::all_rows(), cells);
}

/// Figs. 8-9 from `set_sizes.parquet`; `std`: with the median of the standard deviations (the
/// TriCal study's), under its heading.
pub fn size_table(parts: &mut Summary<'_>, std: bool) {
    let f4 = |name: &'static str| move |r: &Row<'_>| format!("{:.4}", r.f64(name));
    let mut cells = vec![cell("n", |r| r.u64("set_size").to_string())];
    if std {
        parts.text("## Figs. 8-9: validation error per set size\n\n");
        cells.push(cell("median of mean (mm)", f4("median_of_means_mm")));
        cells.push(cell("IQR of mean (mm)", f4("iqr_of_means_mm")));
        cells.push(cell("median of std (mm)", f4("median_of_stds_mm")));
    } else {
        parts.text("## Median of the mean error per set size (mm)\n\n");
        cells.push(cell("median of means", f4("median_of_means_mm")));
        cells.push(cell("IQR", f4("iqr_of_means_mm")));
    }
    cells.push(cell("not converged", |r| r.u64("not_converged").to_string()));
    parts.table("set_sizes.parquet", Summary::all_rows(), cells);
}

/// Figs. 11-12's Pearson r from `correlations.parquet`.
fn correlations(parts: &mut Summary<'_>) {
    parts.text_from("correlations.parquet", |r| {
        let pooled = r.at(1);
        format!(
            "Pearson r of the error after calibration over the representative set of {n} (the paper's Figs. 11-12 show one \
             set): against the distance to the base (Fig. 11) {:.3}, against the distance to the centre of the calibration \
             zone (Fig. 12) {:.3}. Over every set of {n} pooled: {:.3} and {:.3}.\n",
            r.f64("r_distance_to_base"),
            r.f64("r_distance_to_ccz"),
            pooled.f64("r_distance_to_base"),
            pooled.f64("r_distance_to_ccz"),
            n = r.of("errors.parquet", 1).u64("set_size")
        )
    });
}
