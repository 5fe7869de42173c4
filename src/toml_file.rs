//! Loading TOML files (model parameters, daemon configs) with errors that point at the key.
//!
//! Every error names the file, the line and the dotted key (`pincart2.c_p`), and says what was
//! wrong in one line, so a user can fix the file without reading a backtrace. This module only
//! parses and locates; what a key may hold is checked by the type that owns it.

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

/// An error about `table.key` in `text`, located at the line that sets it (or line 1).
pub fn invalid(
    text: &str,
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
        line: line_of(text, table, key).unwrap_or(1),
        key: dotted,
        message,
    }
}

/// The line (1-based) where `key` is set inside `[table]` (or at the top when `table` is None).
/// A table itself is found by its header when `key` is empty.
pub fn line_of(text: &str, table: Option<&str>, key: &str) -> Option<usize> {
    let mut current: Option<String> = None;
    for (i, raw) in text.lines().enumerate() {
        let line = code_of(raw);
        if let Some(name) = header(line) {
            if key.is_empty() && Some(name.as_str()) == table {
                return Some(i + 1);
            }
            current = Some(name);
            continue;
        }
        if current.as_deref() == table {
            if let Some((k, _)) = line.split_once('=') {
                if k.trim().trim_matches('"') == key {
                    return Some(i + 1);
                }
            }
        }
    }
    None
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
pub fn header(line: &str) -> Option<String> {
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
        assert_eq!(
            line_of("# rate_hz = 2\nrate_hz = 1", None, "rate_hz"),
            Some(2)
        );
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
    fn line_of_finds_keys_in_tables() {
        let text = "a = 1\n[t]\na = 2\n";
        assert_eq!(line_of(text, None, "a"), Some(1));
        assert_eq!(line_of(text, Some("t"), "a"), Some(3));
        assert_eq!(line_of(text, Some("t"), ""), Some(2));
        assert_eq!(line_of(text, Some("u"), "a"), None);
    }
}
