//! The terminal rendering of a study's checks.

use std::fmt::Write as _;

use crate::robot::ParamId;
use crate::study::check::Check;

/// The comparison as a text table for the terminal.
pub fn terminal_table(rows: &[Check]) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "{:<58} {:>20} {:>12} {:>16}  result", "figure", "published", "calsim", "band");
    for r in rows {
        let verdict = if r.pass == Some(false) { "MISS" } else { r.verdict() };
        let _ = writeln!(s, "{:<58} {:>20} {:>12} {:>16}  {verdict}", r.figure, r.published, r.reproduced, r.band);
    }
    s
}

/// The paper's name of a parameter, for tables.
pub fn display_name(name: &str) -> String {
    ParamId::parse(name).map(|id| id.name()).unwrap_or_else(|| name.to_string())
}

/// The figures over realisations as a text table for the terminal.
pub fn distribution_table(rows: &[crate::study::check::DistributionCheck]) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "{:<58} {:>14} {:>10} {:>10} {:>17} {:>16}  result", "figure", "published", "run 0", "median", "P10-P90", "band");
    for d in rows {
        let verdict = match d.pass {
            Some(true) => "pass",
            Some(false) => "MISS",
            None => "-",
        };
        let published = d.row.published_value.map_or_else(|| d.row.published.clone(), |v| format!("{v:.3}"));
        let _ = writeln!(
            s,
            "{:<58} {:>14} {:>10} {:>10.3} {:>17} {:>16}  {verdict}",
            d.row.figure,
            published.chars().take(14).collect::<String>(),
            d.row.reproduced,
            d.median,
            format!("{:.3}-{:.3}", d.p10, d.p90),
            d.row.band
        );
    }
    s
}
