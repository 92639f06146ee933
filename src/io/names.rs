//! The names calsim makes directories from: a scenario's, sweep's or measurement file's stem
//! becomes `out/<name>` (and `out/.<name>.tmp-<pid>` while it is written, `<name>.budget`,
//! `<name>.task-<N>`, `<name>.shard-k-of-K`). A name that is not one plain path component (`.`
//! from `..toml`, `..` from `...toml`, empty, with a separator, a control character or a line
//! break) would put results elsewhere or fail after the work with a raw OS error; it is refused
//! here, before anything runs, naming the file it came from.

use std::path::Path;

/// Most bytes of a name: the file system takes 255 per component, and calsim adds a dot and a
/// suffix of its own (`.tmp-<pid>`, `.shard-k-of-K`, `.task-<N>`, `.calibration`).
pub const MOST_NAME_BYTES: usize = 200;

/// A name that cannot name results.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{file}: the name {shown} cannot name results: {why} (rename the file)")]
pub struct NameError {
    /// The file the name comes from, control characters escaped.
    pub file: String,
    /// The name, quoted, control characters escaped.
    pub shown: String,
    /// The rule it breaks.
    pub why: &'static str,
}

/// The rule `name` breaks as one path component of results, if any.
pub fn rule_broken(name: &str) -> Option<&'static str> {
    if name.is_empty() {
        Some("it is empty")
    } else if name.starts_with('.') {
        Some("it starts with a dot (`.` and `..` are directories already, and calsim's temporary directories start with one)")
    } else if name.contains(['/', '\\']) {
        Some("it holds a path separator")
    } else if name.chars().any(is_line_or_control) {
        Some("it holds a control character or a line break")
    } else if name.len() > MOST_NAME_BYTES {
        Some("it is longer than 200 bytes")
    } else {
        None
    }
}

/// Whether `c` is a control character (C0, DEL, C1) or a Unicode line or paragraph separator:
/// what would break a one-line message or a path.
pub fn is_line_or_control(c: char) -> bool {
    c.is_control() || c == '\u{2028}' || c == '\u{2029}'
}

/// `text` with every control character and line separator written as an escape (`\n`, `\r`, `\t`,
/// `\u{1b}`), so that whatever a path or value holds, it shows on one line.
pub fn escape_controls(text: &str) -> String {
    if !text.chars().any(is_line_or_control) {
        return text.to_string();
    }
    let mut out = String::with_capacity(text.len() + 8);
    for c in text.chars() {
        match c {
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            c if is_line_or_control(c) => out.push_str(&format!("\\u{{{:x}}}", c as u32)),
            c => out.push(c),
        }
    }
    out
}

/// `path` as shown in a message: its display with control characters escaped.
pub fn shown(path: &Path) -> String {
    escape_controls(&path.display().to_string())
}

/// Checks `name` as [`rule_broken`] does; `file` is the file it came from, named in the error.
pub fn check(name: &str, file: &Path) -> Result<(), NameError> {
    match rule_broken(name) {
        None => Ok(()),
        Some(why) => Err(NameError { file: shown(file), shown: format!("\"{}\"", escape_controls(name)), why }),
    }
}

/// The results name of the file `path`: its stem (the name less its last extension), checked.
pub fn of_file(path: &Path) -> Result<String, NameError> {
    let stem = path.file_stem().unwrap_or_default();
    let name = stem.to_str().ok_or_else(|| NameError {
        file: shown(path),
        shown: format!("\"{}\"", escape_controls(&stem.to_string_lossy())),
        why: "it is not valid UTF-8",
    })?;
    check(name, path)?;
    Ok(name.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_plain_path_components_name_results() {
        for good in ["irb120_trical", "ci quick", "a.b", "kr6-r900", "ümlaut"] {
            assert_eq!(rule_broken(good), None, "{good}");
        }
        for bad in ["", ".", "..", "...", ".hidden", "a/b", "a\\b", "a\nb", "a\rb", "a\u{1b}b", "a\u{2028}b", &"x".repeat(201)] {
            assert!(rule_broken(bad).is_some(), "{bad:?}");
        }
    }

    #[test]
    fn the_stem_of_dot_files_and_dotted_files_is_refused_naming_the_file() {
        let e = of_file(Path::new("dir/..toml")).unwrap_err();
        assert_eq!(e.shown, "\".\"");
        assert!(e.to_string().starts_with("dir/..toml: "), "{e}");
        assert_eq!(of_file(Path::new("...toml")).unwrap_err().shown, "\"..\"");
        let e = of_file(Path::new("a\nb.toml")).unwrap_err();
        assert!(!e.to_string().contains('\n'), "one line: {e}");
        assert_eq!(of_file(Path::new("scenarios/irb120_trical.toml")).unwrap(), "irb120_trical");
    }

    #[test]
    fn escaped_text_holds_no_line_break_or_control_character() {
        let s = escape_controls("a\nb\r\tc\u{7}d\u{2029}e\u{85}");
        assert_eq!(s, "a\\nb\\r\\tc\\u{7}d\\u{2029}e\\u{85}");
        assert!(!s.chars().any(is_line_or_control));
    }
}
