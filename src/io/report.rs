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
