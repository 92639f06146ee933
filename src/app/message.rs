//! The one line an error or warning is shown as, the same from the CLI and from Python.

/// The last step of every line calsim shows (the CLI's standard error, the Python package's
/// exceptions): whatever a path or value holds,
/// the line stays one readable line: control characters and line breaks escaped
/// ([`crate::io::names::escape_controls`]), long numbers in exponent form ([`compact_numbers`]),
/// then a run of more than 200 characters without a space (a 100,000-part key, a file name of a
/// megabyte) shortened in its middle.
pub fn one_line(msg: &str) -> String {
    shorten_long_words(&compact_numbers(&crate::io::names::escape_controls(msg)))
}

/// How a program over calsim's library ends (the examples), as calsim's commands end: exit code 0
/// on success; on an error, `error: ` and its [`one_line`] on standard error, and exit code 2.
pub fn exit_code(result: Result<(), impl std::fmt::Display>) -> std::process::ExitCode {
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", one_line(&e.to_string()));
            std::process::ExitCode::from(2)
        }
    }
}

/// Most characters of a run without a space that a message shows whole.
const MOST_WORD_CHARS: usize = 200;

/// `msg` with every run of more than [`MOST_WORD_CHARS`] characters without a space shown as its
/// first 120 and last 40 characters around `...[N characters]...`.
fn shorten_long_words(msg: &str) -> String {
    if msg.len() <= MOST_WORD_CHARS {
        return msg.to_string();
    }
    let mut out = String::with_capacity(msg.len().min(4096));
    for (i, word) in msg.split(' ').enumerate() {
        if i > 0 {
            out.push(' ');
        }
        let n = word.chars().count();
        if n > MOST_WORD_CHARS {
            let head: String = word.chars().take(120).collect();
            let tail: String = word.chars().skip(n - 40).collect();
            out.push_str(&format!("{head}...[{} characters]...{tail}", n - 160));
        } else {
            out.push_str(word);
        }
    }
    out
}

/// The message with every number written out in more than 24 characters (Rust prints `1e300` as
/// 301 digits and `1e-300` as 302 characters) in exponent form, so that an error about a huge or
/// tiny value stays one readable line. Digits that are part of a word or a path stay as written.
fn compact_numbers(msg: &str) -> String {
    let word = |c: Option<char>| c.is_some_and(|c| c.is_ascii_alphanumeric() || c == '_' || c == '/');
    let mut out = String::with_capacity(msg.len());
    let mut rest = msg;
    while let Some(start) = rest.find(|c: char| c.is_ascii_digit()) {
        let len = rest[start..].find(|c: char| !(c.is_ascii_digit() || c == '.')).unwrap_or(rest.len() - start);
        let token = &rest[start..start + len];
        let alone = !word(rest[..start].chars().last().or_else(|| out.chars().last())) && !word(rest[start + len..].chars().next());
        out.push_str(&rest[..start]);
        match token.parse::<f64>() {
            Ok(x) if len > 24 && alone => out.push_str(&format!("{x:e}")),
            _ => out.push_str(token),
        }
        rest = &rest[start + len..];
    }
    out.push_str(rest);
    out
}

#[cfg(test)]
mod tests {
    use super::{compact_numbers, exit_code, one_line};

    #[test]
    fn an_error_line_stays_one_line_whatever_its_paths_and_values_hold() {
        let msg = format!("a\nb.toml: axis[0] ({}): value {}: x\r\u{2028}y", "a.".repeat(100_000), 1e300_f64);
        let line = one_line(&msg);
        assert_eq!(line.lines().count(), 1, "{line}");
        assert!(line.starts_with("a\\nb.toml: axis[0] (a.a.a."), "{line}");
        assert!(line.contains("characters]...") && line.len() < 1000, "{line}");
        assert!(line.ends_with("value 1e300: x\\r\\u{2028}y"), "{line}");
    }

    #[test]
    fn an_error_ends_with_exit_code_2_and_success_with_0() {
        assert_eq!(exit_code(Ok::<(), String>(())), std::process::ExitCode::SUCCESS);
        assert_eq!(exit_code(Err("x.toml: seed: not a number")), std::process::ExitCode::from(2));
    }

    #[test]
    fn long_numbers_are_written_with_an_exponent() {
        let huge = format!("[robot] payload_kg = {}: must be <= 1000", 1e300_f64);
        assert_eq!(compact_numbers(&huge), "[robot] payload_kg = 1e300: must be <= 1000");
        let tiny = format!("x = -{} mm", 1.5e-300_f64);
        assert_eq!(compact_numbers(&tiny), "x = -1.5e-300 mm");
        // Numbers of ordinary length, versions and whole numbers of u64 stay as written.
        let plain = "m.toml: axis[0] (study.repetitions) = 18446744073709551615, 0.208 mm, calsim 0.1.0";
        assert_eq!(compact_numbers(plain), plain);
        // Long digit runs inside a path or a word are not numbers.
        let path = "/tmp/run12345678901234567890123456789/a.toml: x = 2";
        assert_eq!(compact_numbers(path), path);
    }
}
