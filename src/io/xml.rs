//! The shape of an XML input (a URDF, a COLLADA mesh) checked before any parser sees it: the
//! parsers calsim reads XML with build their trees by recursion, so a file of ten thousand nested
//! elements overflows the stack and one of two hundred thousand takes minutes. One pass over the
//! bytes, without recursion or allocation, counts the nesting and the elements and refuses a file
//! beyond the bounds, naming the line and column. What is malformed otherwise is left to the
//! parser, which names it.

/// Most nested elements: a URDF nests five deep (`robot/link/collision/geometry/mesh`), COLLADA
/// about ten; 64 leaves room for any real file and keeps every parser's recursion short.
pub const MOST_DEPTH: usize = 64;

/// Most elements: a URDF of a whole humanoid has a few thousand.
pub const MOST_ELEMENTS: usize = 100_000;

/// An XML input beyond the shape calsim reads.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ShapeError {
    /// Elements nested deeper than [`MOST_DEPTH`].
    #[error("line {line}, column {column}: elements nested more than {MOST_DEPTH} deep: not a file calsim reads")]
    TooDeep {
        /// Line of the element that goes too deep, 1-based.
        line: usize,
        /// Its column (in bytes), 1-based.
        column: usize,
    },
    /// A closing tag that closes no open element, or another than the innermost.
    #[error("line {line}, column {column}: </{name}> {closes}")]
    Mismatched {
        /// Where the closing tag starts.
        line: usize,
        /// See `line`.
        column: usize,
        /// Its element name.
        name: String,
        /// What it closes instead (`closes <link> opened on line 12`, `closes no open element`).
        closes: String,
    },
    /// An element still open at the end of the file.
    #[error("line {line}, column {column}: <{name}> is never closed")]
    Unclosed {
        /// Where its opening tag starts.
        line: usize,
        /// See `line`.
        column: usize,
        /// Its element name.
        name: String,
    },
    /// More elements than [`MOST_ELEMENTS`].
    #[error("line {line}, column {column}: more than {MOST_ELEMENTS} elements: not a file calsim reads")]
    TooMany {
        /// Line of the element over the bound, 1-based.
        line: usize,
        /// Its column (in bytes), 1-based.
        column: usize,
    },
}

/// Line and column (1-based, bytes) of byte `at` of `b`.
fn position(b: &[u8], at: usize) -> (usize, usize) {
    let before = &b[..at.min(b.len())];
    let line = 1 + before.iter().filter(|&&c| c == b'\n').count();
    let column = 1 + before.iter().rev().take_while(|&&c| c != b'\n').count();
    (line, column)
}

/// The index just past the first `end` in `b` from `from` (`b.len()` when there is none).
fn past(b: &[u8], from: usize, end: &[u8]) -> usize {
    b.get(from..).and_then(|r| r.windows(end.len()).position(|w| w == end)).map_or(b.len(), |i| from + i + end.len())
}

/// The index just past the `>` closing a tag that starts at `from`, quotes and (for a `<!`
/// declaration) brackets honoured; and whether the tag closes itself (`/>`).
fn tag_end(b: &[u8], from: usize) -> (usize, bool) {
    let (mut quote, mut brackets, mut i) = (None, 0usize, from);
    while i < b.len() {
        let c = b[i];
        match quote {
            Some(q) if c == q => quote = None,
            Some(_) => {}
            None => match c {
                b'"' | b'\'' => quote = Some(c),
                b'[' => brackets += 1,
                b']' => brackets = brackets.saturating_sub(1),
                b'>' if brackets == 0 => return (i + 1, i > from && b[i - 1] == b'/'),
                _ => {}
            },
        }
        i += 1;
    }
    (b.len(), false)
}

/// Checks the nesting depth and the element count of the XML `text` (see the module).
pub fn check_shape(text: &str) -> Result<(), ShapeError> {
    check_shape_bytes(text.as_bytes())
}

/// Whether `bytes` look like XML (after a byte-order mark and white space, a `<`): a mesh file
/// of a format that is XML (COLLADA) rather than binary (STL) or lines of text (OBJ).
pub fn looks_like_xml(bytes: &[u8]) -> bool {
    let b = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    b.iter().find(|c| !c.is_ascii_whitespace()) == Some(&b'<')
}

/// [`check_shape`] of XML given as bytes (any encoding that keeps `<`, `>`, quotes and line
/// breaks as ASCII: UTF-8, Latin-1).
pub fn check_shape_bytes(b: &[u8]) -> Result<(), ShapeError> {
    let (mut i, mut depth, mut elements) = (0, 0usize, 0usize);
    // The open elements, innermost last (name and where its tag starts): at most MOST_DEPTH.
    let mut open: Vec<(&[u8], usize)> = Vec::new();
    let name_at = |from: usize| {
        let rest = b.get(from..).unwrap_or_default();
        let n = rest.iter().position(|c| c.is_ascii_whitespace() || matches!(c, b'/' | b'>')).unwrap_or(rest.len());
        &rest[..n]
    };
    let shown = |n: &[u8]| {
        let text = String::from_utf8_lossy(&n[..n.len().min(60)]).into_owned();
        crate::io::names::escape_controls(&text)
    };
    while let Some(lt) = b.get(i..).and_then(|r| r.iter().position(|&c| c == b'<')).map(|k| i + k) {
        let rest = &b[lt..];
        i = if rest.starts_with(b"<!--") {
            past(b, lt + 4, b"-->")
        } else if rest.starts_with(b"<![CDATA[") {
            past(b, lt + 9, b"]]>")
        } else if rest.starts_with(b"<?") {
            past(b, lt + 2, b"?>")
        } else if rest.starts_with(b"<!") {
            tag_end(b, lt + 2).0
        } else if rest.starts_with(b"</") {
            depth = depth.saturating_sub(1);
            let name = name_at(lt + 2);
            match open.pop() {
                Some((n, _)) if n == name => {}
                other => {
                    let (line, column) = position(b, lt);
                    let closes = match other {
                        Some((n, at)) => format!("closes <{}> opened on line {}", shown(n), position(b, at).0),
                        None => "closes no open element".into(),
                    };
                    return Err(ShapeError::Mismatched { line, column, name: shown(name), closes });
                }
            }
            tag_end(b, lt + 2).0
        } else {
            let (end, closed) = tag_end(b, lt + 1);
            elements += 1;
            if elements > MOST_ELEMENTS {
                let (line, column) = position(b, lt);
                return Err(ShapeError::TooMany { line, column });
            }
            if !closed {
                depth += 1;
                if depth > MOST_DEPTH {
                    let (line, column) = position(b, lt);
                    return Err(ShapeError::TooDeep { line, column });
                }
                open.push((name_at(lt + 1), lt));
            }
            end
        };
    }
    match open.last() {
        Some(&(n, at)) => {
            let (line, column) = position(b, at);
            Err(ShapeError::Unclosed { line, column, name: shown(n) })
        }
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn nested(n: usize) -> String {
        format!("<?xml version=\"1.0\"?>\n<robot>\n{}{}</robot>\n", "<x>".repeat(n), "</x>".repeat(n))
    }

    #[test]
    fn nesting_up_to_the_bound_passes_and_beyond_it_is_refused_at_its_line_and_column() {
        assert_eq!(check_shape(&nested(MOST_DEPTH - 1)), Ok(()));
        assert_eq!(check_shape(&nested(MOST_DEPTH)), Err(ShapeError::TooDeep { line: 3, column: 1 + 3 * (MOST_DEPTH - 1) }));
        assert!(matches!(check_shape(&nested(200_000)), Err(ShapeError::TooDeep { line: 3, .. })));
    }

    #[test]
    fn self_closed_elements_comments_and_quoted_brackets_do_not_nest() {
        let flat = format!(
            "<!DOCTYPE robot [ <!ENTITY a \"<b>\"> ]>\n<robot name=\"a>b\" x='</y>'>{}<!-- <a><a><a> --><![CDATA[<a><a>]]></robot>",
            "<link name=\"l\"/>".repeat(10)
        );
        assert_eq!(check_shape(&flat), Ok(()));
        let wide = format!("<robot>{}</robot>", "<x/>".repeat(MOST_ELEMENTS));
        assert!(matches!(check_shape(&wide), Err(ShapeError::TooMany { line: 1, .. })));
    }

    #[test]
    fn a_closing_tag_of_another_element_or_an_element_never_closed_is_named_with_its_line() {
        let e = check_shape("<robot>\n  <link name=\"a\">\n  </joint>\n</robot>").unwrap_err();
        assert_eq!(e.to_string(), "line 3, column 3: </joint> closes <link> opened on line 2");
        let e = check_shape("<robot/>\n</robot>").unwrap_err();
        assert_eq!(e.to_string(), "line 2, column 1: </robot> closes no open element");
        let e = check_shape("<robot>\n<link>").unwrap_err();
        assert_eq!(e.to_string(), "line 2, column 1: <link> is never closed");
        assert_eq!(check_shape("<a><b x=\"</c>\"/><c></c ></a>"), Ok(()));
    }

    #[test]
    fn unterminated_constructs_end_the_scan_without_a_panic() {
        for text in ["<", "<!--", "<![CDATA[", "<?", "<!", "</", "<a \"", "<a '>", "<a/", "<<<>>>", ""] {
            let _ = check_shape(text);
        }
    }
}
