//! The SPMS paper's figures (Figs. 5-6, Table 6) and the AP per set size, as PNG and SVG.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::io::plot::{BySize, DrawResult, FAMILY, Mark, PlotError, Side, Written, both, boxplots, e2s, keyed, register_font, whole};

/// What the SPMS figures show.
pub struct SpmsPlotInputs<'a> {
    /// Per accuracy sample, largest sphere-fit residual: paper's form, minimal form, mm.
    pub residuals: [&'a [f64]; 2],
    /// Per accuracy sample, measuring error: paper's form, minimal form, mm.
    pub measuring: [&'a [f64]; 2],
    /// Table 6 per point: published before, calsim before, published after, and calsim after per
    /// selection (label, values), mm.
    pub ap_published: [[f64; 5]; 2],
    /// calsim before calibration, per point, mm.
    pub ap_before: [f64; 5],
    /// calsim after calibration per selection, per point, mm.
    pub ap_after: Vec<(String, [f64; 5])>,
    /// Mean AP after calibration per identification, per selection and set size.
    pub ap_mean_by_size: Vec<(String, BySize)>,
    /// Set size of the Table 6 comparison.
    pub table_n: usize,
}

/// Writes the SPMS figures into `dir`; returns what was written.
pub fn write(dir: &Path, p: &SpmsPlotInputs<'_>) -> Result<Vec<Written>, PlotError> {
    register_font();
    let mut out = Vec::new();
    both!(dir, "spms_fig05_fit_residuals", |root| per_sample(
        root,
        &p.residuals,
        "Fig. 5: sphere-fit residuals per measurement",
        "largest |residual| of the fit (mm)",
        Some((0.03, "0.03 mm (paper: nearly all below)"))
    ));
    out.push(Written {
        svg: true,
        stem: "spms_fig05_fit_residuals".into(),
        caption: "Fig. 5: largest sphere-fit residual of each accuracy measurement, head identified by PSO + LM \
             (paper's form) and by LM on the minimal form"
            .into(),
    });
    both!(dir, "spms_fig06_measuring_error", |root| per_sample(
        root,
        &p.measuring,
        "Fig. 6: measuring error of the SPMS against the laser tracker",
        "|SPMS - tracker| (mm)",
        Some((0.034, "paper mean 0.034 mm"))
    ));
    out.push(Written {
        svg: true,
        stem: "spms_fig06_measuring_error".into(),
        caption: "Fig. 6: measuring error of each sphere measurement against the laser tracker (Table 3)".into(),
    });
    both!(dir, "spms_table6_ap_per_point", |root| ap_bars(root, p));
    out.push(Written {
        svg: true,
        stem: "spms_table6_ap_per_point".into(),
        caption: format!(
            "Table 6: ISO 9283 AP per test point before and after calibration, published and calsim (after: \
             median over the repetitions with sets of {})",
            p.table_n
        ),
    });
    let colours = [BLUE, RGBColor(230, 120, 0), RGBColor(0, 140, 60)];
    let series: Vec<(&str, RGBColor, BySize)> =
        p.ap_mean_by_size.iter().enumerate().map(|(i, (l, d))| (l.as_str(), colours[i % 3], d.clone())).collect();
    both!(dir, "spms_ap_by_set_size", |root| boxplots(
        root,
        &series,
        "Mean AP over P1-P5 after calibration per identification",
        "mean AP after calibration (mm)"
    ));
    out.push(Written {
        svg: true,
        stem: "spms_ap_by_set_size".into(),
        caption: "Mean ISO 9283 AP over P1-P5 after each identification, per set size: random sets (the paper) and DETMAX sets on O1"
            .into(),
    });
    Ok(out)
}

fn per_sample<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    v: &[&[f64]; 2],
    title: &str,
    ylabel: &str,
    line: Option<(f64, &str)>,
) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let forms = [("PSO + LM, paper's 6K+3 form", BLUE), ("LM, minimal 5K+3 form", RGBColor(230, 120, 0))];
    let mut key: Vec<(String, Mark)> = forms.iter().map(|(l, c)| (l.to_string(), Mark::Dot(*c))).collect();
    if let Some((_, label)) = line {
        key.push((label.to_string(), Mark::Line(BLACK)));
    }
    let root = &keyed(root, &key, Side::Bottom)?;
    let n = v[0].len().max(v[1].len()).max(1);
    let top = v.iter().flat_map(|s| s.iter().copied()).chain(line.map(|l| l.0)).fold(0.0, f64::max) * 1.15;
    let mut chart = ChartBuilder::on(root)
        .caption(title, (FAMILY, 22))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(65)
        .build_cartesian_2d(0.0..(n as f64 + 1.0), 0.0..top.max(1e-6))
        .map_err(e2s)?;
    chart
        .configure_mesh()
        .x_desc("measurement")
        .y_desc(ylabel)
        .x_label_formatter(&whole)
        .light_line_style(WHITE)
        .label_style((FAMILY, 13))
        .draw()
        .map_err(e2s)?;
    for (s, (_, colour)) in v.iter().zip(forms) {
        chart.draw_series(s.iter().enumerate().map(|(i, y)| Circle::new((i as f64 + 1.0, *y), 4, colour.filled()))).map_err(e2s)?;
    }
    if let Some((y, _)) = line {
        chart.draw_series(std::iter::once(PathElement::new(vec![(0.0, y), (n as f64 + 1.0, y)], BLACK.stroke_width(1)))).map_err(e2s)?;
    }
    Ok(())
}

fn ap_bars<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, p: &SpmsPlotInputs<'_>) -> DrawResult {
    root.fill(&WHITE).map_err(e2s)?;
    let mut bars: Vec<(String, RGBColor, [f64; 5])> = vec![
        ("published, before".into(), RGBColor(150, 150, 150), p.ap_published[0]),
        ("calsim, before".into(), RGBColor(200, 60, 60), p.ap_before),
        ("published, after".into(), RGBColor(90, 90, 90), p.ap_published[1]),
    ];
    let colours = [BLUE, RGBColor(0, 140, 60)];
    for (i, (l, v)) in p.ap_after.iter().enumerate() {
        bars.push((format!("calsim, after ({l})"), colours[i % 2], *v));
    }
    let key: Vec<(String, Mark)> = bars.iter().map(|b| (b.0.clone(), Mark::Bar(b.1))).collect();
    let root = &keyed(root, &key, Side::Bottom)?;
    let top = bars.iter().flat_map(|b| b.2).filter(|x| x.is_finite()).fold(0.0, f64::max) * 1.1;
    let mut chart = ChartBuilder::on(root)
        .caption("Table 6: ISO 9283 AP per test point", (FAMILY, 22))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(65)
        .build_cartesian_2d(0.5..5.5, 0.0..top.max(1e-6))
        .map_err(e2s)?;
    chart
        .configure_mesh()
        .x_desc("test point")
        .y_desc("AP (mm)")
        .x_labels(5)
        .x_label_formatter(&|x| format!("P{x:.0}"))
        .light_line_style(WHITE)
        .label_style((FAMILY, 13))
        .draw()
        .map_err(e2s)?;
    let w = 0.8 / bars.len() as f64;
    for (i, (_, colour, v)) in bars.iter().enumerate() {
        let c = *colour;
        chart
            .draw_series(v.iter().enumerate().filter(|(_, y)| y.is_finite()).map(|(k, y)| {
                let x0 = k as f64 + 1.0 - 0.4 + i as f64 * w;
                Rectangle::new([(x0, 0.0), (x0 + w * 0.9, *y)], c.filled())
            }))
            .map_err(e2s)?;
    }
    Ok(())
}
