//! Loading TOML files (model parameters, daemon configs) with errors that point at the key.
//!
//! Every error names the file, the line and the dotted key (`pincart2.c_p`), and says what was
//! wrong in one line, so a user can fix the file without reading a backtrace. This module only
//! parses and locates; what a key may hold is checked by the type that owns it. A check that
//! fails after parsing finds its key's line in a [`Layout`], the parser's spans of the text.

use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;

/// A TOML file that could not be read, parsed or accepted.
#[derive(Debug, thiserror::Error)]
pub enum TomlError {
    /// The file could not be read at all.
    #[error("{path}: cannot read: {source}")]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The file is not valid TOML or does not fit the expected shape.
    #[error("{path}:{line}: {key}: {message}")]
    Invalid {
        path: PathBuf,
        line: usize,
        key: String,
        message: String,
    },
}

/// Reads and parses a TOML file into `T`.
pub fn load<T: DeserializeOwned>(path: &Path) -> Result<(T, String), TomlError> {
    let text = std::fs::read_to_string(path).map_err(|source| TomlError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    let value = parse(&text, path)?;
    Ok((value, text))
}

/// Parses TOML `text` (read from `path`, used in messages) into `T`.
pub fn parse<T: DeserializeOwned>(text: &str, path: &Path) -> Result<T, TomlError> {
    toml::from_str(text).map_err(|e| {
        let offset = e.span().map(|s| s.start).unwrap_or(0).min(text.len());
        let before = &text[..offset];
        let line = line_at(text, offset);
        let line_start = before.rfind('\n').map_or(0, |i| i + 1);
        let key = match (key_at(text, line), inline_key(&before[line_start..])) {
            (Some(top), Some(inner)) => format!("{top}.{inner}"),
            (Some(top), None) => top,
            (None, _) => "(file)".into(),
        };
        TomlError::Invalid {
            path: path.to_path_buf(),
            line,
            key,
            message: reason(e.message(), &text[offset..]),
        }
    })
}

/// The line (1-based) of byte `offset` of `text`, such as the start of a span serde gives
/// ([`toml::Spanned`]); the last line past the end.
pub fn line_at(text: &str, offset: usize) -> usize {
    let before = text.get(..offset).unwrap_or(text);
    before.matches('\n').count() + 1
}

/// The parser's message on one line; where it gives none (a control character, which TOML
/// allows nowhere, not even in a comment), what the character is and what to do.
fn reason(message: &str, from_error: &str) -> String {
    let message = message.trim().replace('\n', " ");
    if !message.is_empty() {
        return message;
    }
    match from_error.chars().next() {
        Some(c) if c.is_control() => format!(
            "control character U+{:04X} is not allowed in TOML, not even in a comment: remove it",
            u32::from(c)
        ),
        _ => "not valid TOML here".into(),
    }
}

/// `line` trimmed, or `""` for a comment line, so a commented-out `key = value` is never
/// taken for the key.
fn code_of(line: &str) -> &str {
    let line = line.trim();
    if line.starts_with('#') {
        ""
    } else {
        line
    }
}

/// An error about `table.key`, located at the line of `lines` that sets it (or line 1).
pub fn invalid(
    lines: Lines<'_>,
    path: &Path,
    table: Option<&str>,
    key: &str,
    message: String,
) -> TomlError {
    let dotted = match table {
        Some(t) if !key.is_empty() => format!("{t}.{key}"),
        Some(t) => t.to_string(),
        None => key.to_string(),
    };
    TomlError::Invalid {
        path: path.to_path_buf(),
        line: lines.of(table, key).unwrap_or(1),
        key: dotted,
        message,
    }
}

/// A TOML text as the parser sees it, for the line a table or a key is written on: the spans of
/// the parser serde reads the file with, so a key is found however it is written (quoted, after
/// a comment that names it, in an array of tables).
#[derive(Debug)]
pub struct Layout<'a> {
    text: &'a str,
    /// None for a text that does not parse (its error comes from [`parse`]).
    doc: Option<toml_edit::ImDocument<&'a str>>,
}

impl<'a> Layout<'a> {
    /// The layout of `text`.
    pub fn parse(text: &'a str) -> Layout<'a> {
        Layout {
            text,
            doc: toml_edit::ImDocument::parse(text).ok(),
        }
    }

    /// Its lines, in the first table of every array of tables.
    pub fn lines(&self) -> Lines<'_> {
        Lines {
            layout: self,
            nth: 0,
        }
    }
}

/// Where the tables and keys of a [`Layout`] are written, taking one table of each array of
/// tables (the `nth`: the third `[[valve]]` and its sub-tables).
#[derive(Debug, Clone, Copy)]
pub struct Lines<'a> {
    layout: &'a Layout<'a>,
    nth: usize,
}

impl<'a> Lines<'a> {
    /// The same lines in the `nth` (0-based) table of each array of tables.
    pub fn nth(self, nth: usize) -> Lines<'a> {
        Lines { nth, ..self }
    }

    /// The line (1-based) where `key = ...` is set in `[table]` (dotted from the top, None for
    /// the top level), or where `[table]` is headed when `key` is empty. None when the text does
    /// not write it: a `[table.key]` table is not `key = ...`, and a table only implied by its
    /// sub-tables has no header.
    pub fn of(&self, table: Option<&str>, key: &str) -> Option<usize> {
        let doc = self.layout.doc.as_ref()?;
        let mut t = doc.as_table();
        for name in table.into_iter().flat_map(|t| t.split('.')) {
            t = match t.get(name)? {
                toml_edit::Item::Table(inner) => inner,
                toml_edit::Item::ArrayOfTables(array) => array.get(self.nth)?,
                _ => return None,
            };
        }
        let span = if key.is_empty() {
            t.span()
        } else {
            let (k, item) = t.get_key_value(key)?;
            item.is_value().then(|| k.span())?
        }?;
        Some(line_at(self.layout.text, span.start))
    }
}

/// The dotted key set on `line` (1-based), with its table, if that line sets one.
fn key_at(text: &str, line: usize) -> Option<String> {
    let mut table: Option<String> = None;
    for (i, raw) in text.lines().enumerate() {
        let l = code_of(raw);
        if let Some(name) = header(l) {
            table = Some(name);
        }
        if i + 1 == line {
            if let Some((k, _)) = l.split_once('=') {
                let k = k.trim().trim_matches('"');
                return Some(match &table {
                    Some(t) => format!("{t}.{k}"),
                    None => k.to_string(),
                });
            }
            return table;
        }
    }
    table
}

/// The key of the inline-table entry whose value starts where `line_head` (a line up to an
/// error) ends: `format` for `position = { address = 1, format = `. None outside inline tables.
fn inline_key(line_head: &str) -> Option<&str> {
    let (_, inner) = line_head.split_once('{')?;
    let (entry, _) = inner.rsplit_once('=')?;
    let key = entry.rsplit([',', '{']).next()?.trim().trim_matches('"');
    (!key.is_empty()).then_some(key)
}

/// The table name of a `[table]` or `[[array]]` header line.
fn header(line: &str) -> Option<String> {
    let inner = line.strip_prefix('[')?;
    let end = inner.find(']')?;
    Some(inner[..end].trim_matches(['[', ']', ' ']).to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Inner {
        rate_hz: f64,
    }

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Outer {
        name: String,
        loop_: Option<Inner>,
        inner: Inner,
    }

    #[test]
    fn a_control_character_in_a_comment_is_named() {
        let text = "name = \"x\"\n# bad \u{0} byte\n[inner]\nrate_hz = 1.0\n";
        let err = parse::<Outer>(text, Path::new("c.toml"))
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("c.toml:2: "), "{err}");
        assert!(err.contains("control character U+0000"), "{err}");
    }

    #[test]
    fn a_comment_is_never_a_key() {
        let text = "# name = \"x\" is what this needs\n[inner]\nrate_hz = 1.0\n";
        let err = parse::<Outer>(text, Path::new("c.toml"))
            .unwrap_err()
            .to_string();
        assert_eq!(err, "c.toml:1: (file): missing field `name`");
        let layout = Layout::parse("# rate_hz = 2\nrate_hz = 1");
        assert_eq!(layout.lines().of(None, "rate_hz"), Some(2));
    }

    #[test]
    fn wrong_type_names_the_key_and_line() {
        let text = "name = \"x\"\n\n[inner]\nrate_hz = \"fast\"\n";
        let err = parse::<Outer>(text, Path::new("c.toml"))
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("c.toml:4: inner.rate_hz:"), "{err}");
        assert!(!err.contains('\n'));
    }

    #[test]
    fn unknown_key_is_named() {
        let text = "name = \"x\"\n[inner]\nrate_hz = 1.0\nrate = 2\n";
        let err = parse::<Outer>(text, Path::new("c.toml"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("c.toml:4: inner.rate:"), "{err}");
        assert!(err.contains("unknown field `rate`"), "{err}");
    }

    #[test]
    fn keys_inside_inline_tables_are_named() {
        #[derive(Debug, serde::Deserialize)]
        #[serde(deny_unknown_fields)]
        #[allow(dead_code)]
        struct Doc {
            t: std::collections::BTreeMap<String, Inner>,
        }
        let text = "[t]\nx = { rate_hz = \"fast\" }\n";
        let err = parse::<Doc>(text, Path::new("c.toml"))
            .unwrap_err()
            .to_string();
        assert!(
            err.starts_with("c.toml:2: t.x.rate_hz: invalid type"),
            "{err}"
        );
        assert_eq!(inline_key("a = { b = 1, c = "), Some("c"));
        assert_eq!(inline_key("a = "), None);
    }

    #[test]
    fn lines_find_keys_and_headers_in_tables() {
        let text = "a = 1\n[t]\na = 2\n\"b c\" = 3\n[u.v]\nw = 4\n";
        let layout = Layout::parse(text);
        let lines = layout.lines();
        assert_eq!(lines.of(None, "a"), Some(1));
        assert_eq!(lines.of(Some("t"), "a"), Some(3));
        assert_eq!(lines.of(Some("t"), "b c"), Some(4));
        assert_eq!(lines.of(Some("t"), ""), Some(2));
        assert_eq!(lines.of(Some("u.v"), "w"), Some(6));
        assert_eq!(lines.of(Some("u.v"), ""), Some(5));
        // `v` is a table of `u`, not a key set in it.
        assert_eq!(lines.of(Some("u"), "v"), None);
        // `[u]` is only implied by `[u.v]`: it has no header.
        assert_eq!(lines.of(Some("u"), ""), None);
        assert_eq!(lines.of(Some("x"), "a"), None);
        assert_eq!(lines.of(Some("t"), "x"), None);
    }

    #[test]
    fn lines_take_the_nth_table_of_an_array() {
        let text = "[[v]]\nname = \"a\"\n[[v]]\n[v.s]\nk = 1\n\n[[v]]\nname = \"c\"\n";
        let layout = Layout::parse(text);
        let lines = layout.lines();
        assert_eq!(lines.of(Some("v"), "name"), Some(2));
        assert_eq!(lines.nth(1).of(Some("v"), ""), Some(3));
        assert_eq!(lines.nth(1).of(Some("v"), "name"), None);
        assert_eq!(lines.nth(1).of(Some("v.s"), "k"), Some(5));
        assert_eq!(lines.nth(2).of(Some("v"), "name"), Some(8));
        assert_eq!(lines.nth(3).of(Some("v"), ""), None);
    }
}
