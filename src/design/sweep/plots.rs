//! A sweep's figures: the p95 after calibration per design with its interval, the success
//! probability per design (or per set size) with its interval and the target, the layouts to scale
//! in {W} with the robot base and its reach. Designs are named by what they are (the axis values
//! in words, with the selection and set size where those differ), never by grid index.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use super::designs::DesignRow;
use super::objective::Goal;
use super::{PointRow, ShardInfo};
use crate::device::RobotInCell;
use crate::io::plot::{
    DrawResult, FAMILY, Mark, PlotError, Side, Written, both, e2s, interval_bar, interval_bar_h, keyed, range_of, register_font, whole,
};

/// One design's estimate with its interval and the spread of the worlds, for a figure.
struct Estimate {
    /// The design in words.
    label: String,
    /// The axis value where the sweep has one numeric axis.
    x: Option<f64>,
    /// The estimate (NaN: no value, e.g. every campaign failed).
    value: f64,
    /// Its interval at the sweep's confidence.
    interval: (f64, f64),
    /// The P10-P90 range of the worlds, where the figure shows it.
    spread: Option<(f64, f64)>,
}

/// One axis value in words: a layout as `5 spheres 150 mm apart, plate +100 mm, tilted 20 deg`,
/// a number as `epsilon 0.005 mm`, a list as `3 sphere points base`.
pub fn value_words(key: &str, value: &str) -> String {
    let last = key.rsplit('.').next().unwrap_or(key);
    let (name, unit) = ["_mm", "_deg", "_um", "_s", "_h", "_kg"]
        .iter()
        .find_map(|u| last.strip_suffix(u).map(|n| (n, &u[1..])))
        .map_or((last, ""), |(n, u)| (n, u));
    let name = name.replace('_', " ");
    let parsed: Option<toml::Value> = format!("v = {value}").parse::<toml::Table>().ok().and_then(|t| t.get("v").cloned());
    let num = |t: &toml::Table, k: &str| t.get(k).and_then(|v| v.as_float().or(v.as_integer().map(|i| i as f64)));
    match parsed {
        Some(toml::Value::Table(t)) if last == "layout" => {
            let mut s = format!("{} spheres {} mm apart", num(&t, "n").unwrap_or(f64::NAN), num(&t, "spacing_mm").unwrap_or(f64::NAN));
            if t.get("shape").and_then(|v| v.as_str()) == Some("line") {
                s.push_str(" in a line");
            }
            if let Some(h) = num(&t, "height_mm").filter(|h| *h != 0.0) {
                s.push_str(&format!(", plate {h:+} mm"));
            }
            if let Some(a) = num(&t, "tilt_deg").filter(|a| *a != 0.0) {
                s.push_str(&format!(", tilted {a} deg"));
            }
            s
        }
        Some(toml::Value::Array(a)) => format!("{} {name}", a.len()),
        Some(toml::Value::Float(_) | toml::Value::Integer(_)) => format!("{name} {value} {unit}").trim_end().to_string(),
        _ => format!("{name} = {value}"),
    }
}

/// The names of the designs: the axis values in words, with the selection and the set size when
/// they differ between designs; and what they share, for titles (`detmax sets of 75`).
struct Names<'a> {
    info: &'a ShardInfo,
    selections_differ: bool,
    sizes_differ: bool,
    shared: String,
}

impl<'a> Names<'a> {
    fn new(info: &'a ShardInfo, points: &[PointRow]) -> Self {
        let table: Vec<&PointRow> = points.iter().filter(|p| p.table).collect();
        let differ = |f: &dyn Fn(&PointRow) -> String| table.iter().any(|p| f(p) != f(table[0]));
        let selections_differ = differ(&|p| p.selection.clone());
        let sizes_differ = differ(&|p| p.set_size.to_string());
        let shared = match (table.first(), selections_differ, sizes_differ) {
            (Some(p), false, false) => format!("{} sets of {}", p.selection, p.set_size),
            (Some(p), false, true) => format!("{} sets", p.selection),
            (Some(p), true, false) => format!("sets of {}", p.set_size),
            _ => String::new(),
        };
        Self { info, selections_differ, sizes_differ, shared }
    }

    fn point(&self, p: usize) -> String {
        if self.info.keys.is_empty() {
            return "the scenario".into();
        }
        self.info.keys.iter().zip(&self.info.points[p]).map(|(k, v)| value_words(k, v)).collect::<Vec<_>>().join(", ")
    }

    fn design(&self, p: usize, selection: &str, set_size: u32) -> String {
        let mut s = self.point(p);
        if self.selections_differ {
            s.push_str(&format!(", {selection}"));
        }
        if self.sizes_differ {
            s.push_str(&format!(", n = {set_size}"));
        }
        s
    }
}

/// Writes the sweep's figures into `dir`.
///
/// Long by design: the list of the sweep's figures, each a short block (its data, its file, its
/// caption) drawn in the order summary.md shows them.
pub fn write(dir: &Path, info: &ShardInfo, points: &[PointRow], designs: &[DesignRow]) -> Result<Vec<Written>, PlotError> {
    register_font();
    let names = Names::new(info, points);
    let numeric: Option<Vec<f64>> =
        if info.keys.len() == 1 { info.points.iter().map(|v| v[0].parse::<f64>().ok()).collect() } else { None };
    let x_of = |p: usize| numeric.as_ref().map(|v| v[p]);
    let xlabel = numeric.as_ref().map(|_| info.keys[0].clone());
    let conf = info.objective.confidence * 100.0;
    let mut out = Vec::new();

    // The p95 after calibration at each point's table set size.
    let mut p95: Vec<Estimate> = points
        .iter()
        .filter(|p| p.table)
        .map(|p| Estimate {
            label: names.design(p.point, &p.selection, p.set_size),
            x: x_of(p.point),
            value: p.after[1][0],
            interval: (p.after_ci[1][0], p.after_ci[1][1]),
            spread: Some((p.after[1][1], p.after[1][2])),
        })
        .collect();
    for p in (0..info.points.len()).filter(|p| !points.iter().any(|r| r.point == *p && r.table)) {
        p95.push(Estimate {
            label: format!("{}: campaign failed", names.point(p)),
            x: x_of(p),
            value: f64::NAN,
            interval: (f64::NAN, f64::NAN),
            spread: None,
        });
    }
    let title = format!(
        "p95 of the validation error after calibration{}",
        if names.shared.is_empty() { String::new() } else { format!(", {}", names.shared) }
    );
    let figure = Figure {
        title: &title,
        value_label: "p95 error after calibration (mm)",
        xlabel: xlabel.as_deref(),
        conf,
        target: None,
        probability: false,
    };
    both!(dir, "sweep_p95_by_design", |root| estimates(root, &figure, &p95));
    out.push(Written {
        svg: true,
        stem: "sweep_p95_by_design".into(),
        caption: format!(
            "p95 of the validation error after calibration at the table set size per design: dot, median over realisations; \
             thick bar with caps, its {conf} % interval; thin line, P10-P90 of the worlds"
        ),
    });

    if !info.layouts.is_empty()
        && info.layouts.len() == info.points.len()
        && info.keys.iter().any(|k| k == "cell.layout" || k == "cell.spheres_w_mm")
    {
        let panels: Vec<Panel> = (0..info.points.len())
            .map(|p| {
                let at = points.iter().filter(|r| r.point == p && r.table).min_by(|a, b| a.after[1][0].total_cmp(&b.after[1][0]));
                let note = at.map_or("campaign failed".to_string(), |r| format!("p95 {:.3} mm", r.after[1][0]));
                Panel {
                    title: format!("{}: {note}", names.point(p)),
                    spheres: info.layouts[p].clone(),
                    robot: (if info.robots.len() == 1 { info.robots.first() } else { info.robots.get(p) }).cloned().flatten(),
                    ran: at.is_some(),
                }
            })
            .collect();
        // From the side too when the designs raise, lower or tilt the robot relative to the spheres.
        let side_view = panels.windows(2).any(|w| match (&w[0].robot, &w[1].robot) {
            (Some(a), Some(b)) => {
                (a.base_w_mm[2] - b.base_w_mm[2]).abs() > 1e-6 || (0..3).any(|k| (a.base_up_w[k] - b.base_up_w[k]).abs() > 1e-9)
            }
            _ => false,
        });
        let cols = (panels.len() as f64).sqrt().ceil().max(1.0) as usize;
        let rows = panels.len().div_ceil(cols);
        let size = ((cols as u32 * if side_view { 520 } else { 300 }).max(900), (rows as u32 * 300 + 60).max(600));
        both!(dir, "sweep_layouts", size, |root| layouts(root, &panels, side_view));
        out.push(Written {
            svg: true,
            stem: "sweep_layouts".into(),
            caption: format!(
                "Each design's cell to scale in {{W}} (sphere 1 at the origin, mm){}: datum spheres (grey: the campaign could not \
                 measure them), the robot base (triangle{}) and its reach (from above: the farthest the TCP gets from the base's axis; \
                 from the side: from the shoulder); \
                 title: the median p95 after calibration",
                if side_view {
                    ", from above and from the side (seen along x, the line of spheres 1 and 2 the plate tilts about)"
                } else {
                    ", from above"
                },
                if side_view { " and line: the base's z axis, 200 mm" } else { "" }
            ),
        });
    }

    let (success, threshold, statistic) = success_estimates(info, points, designs, &names);
    if !success.is_empty() {
        let target = info.objective.success_at_least.map(|p| (p, format!("target: P >= {p}")));
        let one_size = points.iter().all(|p| Some(p.set_size) == points.first().map(|q| q.set_size));
        let shared = match (one_size, names.selections_differ, points.first()) {
            (true, _, _) if !names.shared.is_empty() => format!(", {}", names.shared),
            (false, false, Some(p)) => format!(", {} sets", p.selection),
            _ => String::new(),
        };
        let title = format!("P({statistic} error <= {threshold} mm){shared}");
        let vlabel = format!("P({statistic} error <= {threshold} mm)");
        let sizes: Vec<u32> = {
            let mut v: Vec<u32> = success.iter().map(|s| s.1).collect();
            v.sort_unstable();
            v.dedup();
            v
        };
        if sizes.len() > 1 {
            both!(dir, "sweep_success_by_set_size", |root| success_curves(root, &title, &vlabel, &success, target.as_ref(), conf));
        } else {
            let rows: Vec<Estimate> = success.into_iter().map(|s| s.0).collect();
            let figure =
                Figure { title: &title, value_label: &vlabel, xlabel: xlabel.as_deref(), conf, target: target.clone(), probability: true };
            both!(dir, "sweep_success_by_set_size", |root| estimates(root, &figure, &rows));
        }
        out.push(Written {
            svg: true,
            stem: "sweep_success_by_set_size".into(),
            caption: format!(
                "P({statistic} error <= {threshold} mm) per design{}: the fraction of successful calibrations over realisations x \
                 repetitions, with its {conf} % interval over realisations (Clopper-Pearson){}",
                if sizes.len() > 1 { " and set size" } else { "" },
                target.map_or(String::new(), |t| format!("; dashed: the objective's {}", t.1))
            ),
        });
    }
    Ok(out)
}

/// The success estimates: per design (the objective's statistic and threshold where it has one,
/// else P(max <= the first threshold) of `points`), with its set size; the threshold and statistic.
fn success_estimates(
    info: &ShardInfo,
    points: &[PointRow],
    designs: &[DesignRow],
    names: &Names<'_>,
) -> (Vec<(Estimate, u32, String)>, f64, &'static str) {
    let o = &info.objective;
    let key = |p: usize, sel: &str| format!("{p} {sel}");
    if let Some(t) = o.threshold_mm
        && (o.goal == Goal::MaximiseSuccess || o.success_at_least.is_some())
    {
        let v = designs
            .iter()
            .filter_map(|d| {
                let (p, ci) = d.success?;
                let e = Estimate {
                    label: names.design(d.design.point, &d.design.selection, d.design.set_size),
                    x: None,
                    value: p,
                    interval: ci,
                    spread: None,
                };
                Some((e, d.design.set_size, key(d.design.point, &d.design.selection)))
            })
            .collect();
        return (v, t, o.statistic.label());
    }
    let Some(&t) = info.thresholds_mm.first() else { return (Vec::new(), f64::NAN, "max") };
    let v = points
        .iter()
        .map(|p| {
            let ci = p.success_ci.first().map_or((f64::NAN, f64::NAN), |c| (c[0], c[1]));
            let e = Estimate {
                label: names.design(p.point, &p.selection, p.set_size),
                x: None,
                value: p.success[0].0,
                interval: ci,
                spread: None,
            };
            (e, p.set_size, key(p.point, &p.selection))
        })
        .collect();
    (v, t, "max")
}

/// What an estimates figure shows.
struct Figure<'a> {
    title: &'a str,
    value_label: &'a str,
    /// The numeric axis: designs along x at their values; else one row per design.
    xlabel: Option<&'a str>,
    conf: f64,
    target: Option<(f64, String)>,
    /// Values are probabilities (0 to 1).
    probability: bool,
}

fn estimate_key(f: &Figure<'_>, spread: bool, intervals: bool) -> Vec<(String, Mark)> {
    let mut key = vec![
        (if f.probability { "estimate" } else { "median over realisations" }.to_string(), Mark::Dot(RED)),
        (
            if intervals { format!("its {} % interval", f.conf) } else { format!("(too few realisations for a {} % interval)", f.conf) },
            Mark::Interval(BLACK),
        ),
    ];
    if spread {
        key.push(("P10-P90 of the worlds".into(), Mark::Line(RGBColor(150, 150, 200))));
    }
    if let Some((_, t)) = &f.target {
        key.push((t.clone(), Mark::Dashed(RGBColor(0, 140, 60))));
    }
    key
}

fn value_range(f: &Figure<'_>, rows: &[Estimate]) -> std::ops::Range<f64> {
    if f.probability {
        return 0.0..1.05;
    }
    let r = range_of(
        rows.iter()
            .flat_map(|e| [e.value, e.interval.0, e.interval.1, e.spread.map_or(f64::NAN, |s| s.0), e.spread.map_or(f64::NAN, |s| s.1)])
            .filter(|v| v.is_finite()),
        0.08,
    );
    0f64.min(r.start)..r.end
}

/// Each design's estimate with its interval (and the worlds' spread): along x at the axis value
/// for a numeric axis, else one labelled row per design, best first.
fn estimates<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, f: &Figure<'_>, rows: &[Estimate]) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let spread = rows.iter().any(|e| e.spread.is_some());
    let intervals = rows.iter().any(|e| e.interval.0.is_finite() && e.interval.1.is_finite());
    let root = &keyed(root, &estimate_key(f, spread, intervals), Side::Bottom)?;
    let vr = value_range(f, rows);
    let pale = RGBColor(150, 150, 200);
    let green = RGBColor(0, 140, 60);
    if let (Some(xlabel), true) = (f.xlabel, rows.iter().all(|e| e.x.is_some())) {
        let xr = range_of(rows.iter().filter_map(|e| e.x), 0.08);
        let half = (xr.end - xr.start) * 0.008;
        let mut chart = ChartBuilder::on(root)
            .caption(f.title, (FAMILY, 18))
            .margin(15)
            .x_label_area_size(45)
            .y_label_area_size(65)
            .build_cartesian_2d(xr.clone(), vr)
            .map_err(e2s)?;
        chart.configure_mesh().x_desc(xlabel).y_desc(f.value_label).label_style((FAMILY, 13)).draw().map_err(e2s)?;
        for e in rows {
            let x = e.x.unwrap_or(f64::NAN);
            if let Some(s) = e.spread {
                chart.draw_series(interval_bar(x, s, 0.0, pale.stroke_width(1))).map_err(e2s)?;
            }
            chart.draw_series(interval_bar(x, e.interval, half, BLACK.stroke_width(2))).map_err(e2s)?;
            if e.value.is_finite() {
                chart.draw_series(std::iter::once(Circle::new((x, e.value), 4, RED.filled()))).map_err(e2s)?;
            }
        }
        if let Some((t, _)) = &f.target {
            chart.draw_series(DashedLineSeries::new([(xr.start, *t), (xr.end, *t)], 8, 5, green.stroke_width(2))).map_err(e2s)?;
        }
        return Ok(());
    }
    // One row per design, the best at the top (missing values last).
    let mut order: Vec<&Estimate> = rows.iter().collect();
    let better = |a: f64, b: f64| if f.probability { b.total_cmp(&a) } else { a.total_cmp(&b) };
    order.sort_by(|a, b| (!a.value.is_finite()).cmp(&!b.value.is_finite()).then(better(a.value, b.value)));
    let n = order.len().max(1);
    let labels: Vec<String> = order.iter().map(|e| e.label.clone()).collect();
    let font: TextStyle = (FAMILY, 12).into_font().into();
    let longest = labels.iter().filter_map(|l| root.estimate_text_size(l, &font).ok()).map(|s| s.0).max().unwrap_or(0);
    let (w, _) = root.dim_in_pixel();
    let mut chart = ChartBuilder::on(root)
        .caption(f.title, (FAMILY, 18))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size((longest + 12).min(w / 2))
        .build_cartesian_2d(vr.clone(), -0.5..(n as f64 - 0.5))
        .map_err(e2s)?;
    chart
        .configure_mesh()
        .disable_y_mesh()
        .y_labels(n.min(60))
        .y_label_formatter(&|y| {
            let k = y.round();
            if (y - k).abs() < 1e-6 && k >= 0.0 { labels.get(n - 1 - k as usize).cloned().unwrap_or_default() } else { String::new() }
        })
        .x_desc(f.value_label)
        .label_style((FAMILY, 12))
        .draw()
        .map_err(e2s)?;
    let y = |k: usize| (n - 1 - k) as f64;
    for (k, e) in order.iter().enumerate() {
        if let Some(s) = e.spread {
            chart.draw_series(interval_bar_h(y(k), s, 0.0, pale.stroke_width(1))).map_err(e2s)?;
        }
        chart.draw_series(interval_bar_h(y(k), e.interval, 0.18, BLACK.stroke_width(2))).map_err(e2s)?;
        if e.value.is_finite() {
            chart.draw_series(std::iter::once(Circle::new((e.value, y(k)), 4, RED.filled()))).map_err(e2s)?;
        }
    }
    if let Some((t, _)) = &f.target {
        chart.draw_series(DashedLineSeries::new([(*t, -0.5), (*t, n as f64 - 0.5)], 8, 5, green.stroke_width(2))).map_err(e2s)?;
    }
    Ok(())
}

/// P(success) against the set size, one curve per (point, selection) with its intervals, and the
/// target.
fn success_curves<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: &str,
    vlabel: &str,
    success: &[(Estimate, u32, String)],
    target: Option<&(f64, String)>,
    conf: f64,
) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let mut curves: Vec<(String, Vec<(f64, &Estimate)>)> = Vec::new();
    for (e, n, key) in success {
        match curves.iter_mut().find(|c| c.0 == *key) {
            Some(c) => c.1.push((f64::from(*n), e)),
            None => curves.push((key.clone(), vec![(f64::from(*n), e)])),
        }
    }
    for c in &mut curves {
        c.1.sort_by(|a, b| a.0.total_cmp(&b.0));
    }
    let colour = |i: usize| Palette99::pick(i).to_rgba();
    let solid = |i: usize| {
        let c = colour(i);
        RGBColor(c.0, c.1, c.2)
    };
    // A curve's name: its design's without the set size.
    let name = |c: &(String, Vec<(f64, &Estimate)>)| {
        let l = &c.1[0].1.label;
        l.rsplit_once(", n = ").map_or(l.clone(), |(a, _)| a.to_string())
    };
    let mut key: Vec<(String, Mark)> = curves.iter().enumerate().map(|(i, c)| (name(c), Mark::Line(solid(i)))).collect();
    key.push((format!("{conf} % interval"), Mark::Interval(BLACK)));
    if let Some((_, t)) = target {
        key.push((t.clone(), Mark::Dashed(RGBColor(0, 140, 60))));
    }
    let root = &keyed(root, &key, Side::Right)?;
    let xr = range_of(success.iter().map(|s| f64::from(s.1)), 0.05);
    let step = (xr.end - xr.start) / 150.0;
    let mut chart = ChartBuilder::on(root)
        .caption(title, (FAMILY, 18))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(65)
        .build_cartesian_2d(xr.clone(), 0f64..1.05)
        .map_err(e2s)?;
    chart
        .configure_mesh()
        .x_desc("set size n (configurations)")
        .y_desc(vlabel)
        .x_label_formatter(&whole)
        .label_style((FAMILY, 13))
        .draw()
        .map_err(e2s)?;
    let k = curves.len() as f64;
    for (i, c) in curves.iter().enumerate() {
        // Curves side by side at each set size, so that their intervals do not hide each other.
        let dx = (i as f64 - (k - 1.0) / 2.0) * step;
        let col = colour(i);
        chart.draw_series(LineSeries::new(c.1.iter().map(|(n, e)| (n + dx, e.value)), col.stroke_width(2)).point_size(3)).map_err(e2s)?;
        for (n, e) in &c.1 {
            chart.draw_series(interval_bar(n + dx, e.interval, step * 0.6, col.stroke_width(1))).map_err(e2s)?;
        }
    }
    if let Some((t, _)) = target {
        chart
            .draw_series(DashedLineSeries::new([(xr.start, *t), (xr.end, *t)], 8, 5, RGBColor(0, 140, 60).stroke_width(2)))
            .map_err(e2s)?;
    }
    Ok(())
}

/// One design's cell for the layouts figure.
struct Panel {
    title: String,
    spheres: Vec<[f64; 3]>,
    robot: Option<RobotInCell>,
    ran: bool,
}

/// Widens `(x, y)` ranges so that one mm is as many pixels along both (`w` x `h` pixels).
fn to_scale(x: std::ops::Range<f64>, y: std::ops::Range<f64>, (w, h): (f64, f64)) -> (std::ops::Range<f64>, std::ops::Range<f64>) {
    let (sx, sy) = ((x.end - x.start) / w, (y.end - y.start) / h);
    let s = sx.max(sy);
    let grow = |r: std::ops::Range<f64>, px: f64| {
        let c = (r.start + r.end) / 2.0;
        (c - s * px / 2.0)..(c + s * px / 2.0)
    };
    (grow(x, w), grow(y, h))
}

/// The cells to scale: per design, from above (x, y) and, when the designs move the robot's height
/// or tilt, from the side (y, z), with the base and a circle of its reach.
fn layouts<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, panels: &[Panel], side_view: bool) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let key = [
        ("datum sphere".to_string(), Mark::Dot(BLUE)),
        ("robot base".to_string(), Mark::Triangle(BLACK)),
        ("its reach".to_string(), Mark::Ring(RGBColor(120, 120, 120))),
    ];
    let root = keyed(root, &key, Side::Bottom)?;
    let n = panels.len();
    let cols = (n as f64).sqrt().ceil().max(1.0) as usize;
    let rows = n.div_ceil(cols);
    // One scale for every panel: the spheres, the bases and their reach (about the base's axis
    // from above, about the shoulder from the side).
    let extent = |a: usize| {
        let pts = panels.iter().flat_map(|p| {
            let r = p.robot.as_ref();
            let (c, radius) = match r {
                Some(r) if a == 2 || side_view && a == 1 => (r.shoulder_w_mm[a], r.reach_mm),
                Some(r) => (r.base_w_mm[a], r.horizontal_reach_mm),
                None => (f64::NAN, 0.0),
            };
            p.spheres.iter().map(move |s| s[a]).chain(r.map(|_| c - radius)).chain(r.map(|_| c + radius))
        });
        range_of(pts.filter(|v| v.is_finite()), 0.03)
    };
    let views: Vec<(usize, usize, &str)> = if side_view { vec![(0, 1, "from above"), (1, 2, "from the side")] } else { vec![(0, 1, "")] };
    for (area, p) in root.split_evenly((rows, cols)).iter().zip(panels) {
        let area = area.titled(&p.title, (FAMILY, 14)).map_err(e2s)?;
        let sub = area.split_evenly((1, views.len()));
        for (view, &(a, b, name)) in sub.iter().zip(&views) {
            let (w, h) = view.dim_in_pixel();
            let (label_x, label_y) = (24.0, 40.0);
            let (xr, yr) =
                to_scale(extent(a), extent(b), ((f64::from(w) - label_y - 8.0).max(10.0), (f64::from(h) - label_x - 22.0).max(10.0)));
            let mut chart = ChartBuilder::on(view)
                .caption(name, (FAMILY, 12))
                .margin(4)
                .x_label_area_size(label_x as u32)
                .y_label_area_size(label_y as u32)
                .build_cartesian_2d(xr, yr)
                .map_err(e2s)?;
            let axis = ["x", "y", "z"];
            chart
                .configure_mesh()
                .disable_mesh()
                .x_labels(3)
                .y_labels(3)
                .x_desc(format!("{} (mm)", axis[a]))
                .y_desc(format!("{} (mm)", axis[b]))
                .x_label_formatter(&|v| format!("{v:.0}"))
                .y_label_formatter(&|v| format!("{v:.0}"))
                .label_style((FAMILY, 11))
                .axis_desc_style((FAMILY, 11))
                .draw()
                .map_err(e2s)?;
            if let Some(r) = &p.robot {
                // From above: the reach about the base's axis; from the side: about the shoulder.
                let (centre, radius) = if b == 2 { (r.shoulder_w_mm, r.reach_mm) } else { (r.base_w_mm, r.horizontal_reach_mm) };
                let ring: Vec<(f64, f64)> = (0..=120)
                    .map(|k| k as f64 * std::f64::consts::TAU / 120.0)
                    .map(|t| (centre[a] + radius * t.cos(), centre[b] + radius * t.sin()))
                    .collect();
                chart.draw_series(std::iter::once(PathElement::new(ring, RGBColor(120, 120, 120).stroke_width(1)))).map_err(e2s)?;
                let (cx, cy) = (r.base_w_mm[a], r.base_w_mm[b]);
                if b == 2 {
                    let tip = (cx + 200.0 * r.base_up_w[a], cy + 200.0 * r.base_up_w[b]);
                    chart.draw_series(std::iter::once(PathElement::new(vec![(cx, cy), tip], BLACK.stroke_width(2)))).map_err(e2s)?;
                }
                chart.draw_series(std::iter::once(TriangleMarker::new((cx, cy), 6, BLACK.filled()))).map_err(e2s)?;
            }
            let colour = if p.ran { BLUE } else { RGBColor(170, 170, 170) };
            chart.draw_series(p.spheres.iter().map(|s| Circle::new((s[a], s[b]), 3, colour.filled()))).map_err(e2s)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::value_words;

    #[test]
    fn axis_values_read_as_what_the_design_is() {
        assert_eq!(
            value_words("cell.layout", "{ height_mm = 100, n = 5, spacing_mm = 150, tilt_deg = 20 }"),
            "5 spheres 150 mm apart, plate +100 mm, tilted 20 deg"
        );
        assert_eq!(value_words("cell.layout", "{ n = 3, spacing_mm = 300 }"), "3 spheres 300 mm apart");
        assert_eq!(value_words("trical.epsilon_mm", "0.005"), "epsilon 0.005 mm");
        assert_eq!(value_words("station.sphere_points_base_mm", "[[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]"), "2 sphere points base");
        assert_eq!(value_words("study.selection", "\"detmax\""), "selection = \"detmax\"");
    }
}
