//! Which CSV columns hold time, O_P and V_P: the `--columns t=...,op=...,vp=...` mapping.
//!
//! Only names are kept here; finding them in a header is the reader's job.

use std::fmt;
use std::str::FromStr;

/// Column names of the time, O_P and V_P signals in a recording file.
///
/// Parsed from `t=NAME,op=NAME,vp=NAME` ([`FromStr`]); keys left out keep their defaults
/// `t_s`, `op_pct` and `vp_pct`. Two special forms:
/// - `t=DATE+TIME` names two columns (a date and a clock time) joined with a space into one
///   timestamp; this implies [`ReadOptions::timestamps`](super::ReadOptions::timestamps).
/// - `vp=` (empty) reads a file without V_P; the recording's `vp` is then empty.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ColumnMap {
    /// Time column, or `DATE+TIME`.
    pub t: String,
    /// Wanted opening O_P, %.
    pub op: String,
    /// Valve position V_P, %; `None` for a file that has only O_P.
    pub vp: Option<String>,
}

impl Default for ColumnMap {
    fn default() -> Self {
        ColumnMap {
            t: "t_s".into(),
            op: "op_pct".into(),
            vp: Some("vp_pct".into()),
        }
    }
}

impl ColumnMap {
    /// The header columns the time is read from: one name, or two for `DATE+TIME`.
    pub fn t_columns(&self) -> impl Iterator<Item = &str> {
        self.t.split('+')
    }

    /// Whether `t` names a separate date and time column (`DATE+TIME`).
    pub fn t_is_date_and_time(&self) -> bool {
        self.t.contains('+')
    }
}

impl fmt::Display for ColumnMap {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "t={},op={},vp={}",
            self.t,
            self.op,
            self.vp.as_deref().unwrap_or("")
        )
    }
}

/// A `--columns` value that cannot be understood.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ColumnMapError {
    /// An entry without `=`.
    #[error("--columns: `{entry}` is not KEY=NAME; expected e.g. t=t_s,op=op_pct,vp=vp_pct")]
    Syntax {
        /// The entry as written.
        entry: String,
    },
    /// A key other than `t`, `op`, `vp`.
    #[error(
        "--columns: unknown key `{key}`; the keys are t, op and vp (e.g. t=time,op=CV,vp=POS)"
    )]
    UnknownKey {
        /// The key as written.
        key: String,
    },
    /// The same key twice.
    #[error("--columns: key `{key}` is given twice")]
    Duplicate {
        /// The repeated key.
        key: String,
    },
    /// `t=` or `op=` without a name, or a malformed `DATE+TIME`.
    #[error("--columns: `{entry}` needs a column name (only vp= may be empty, for a file without V_P; t may be DATE+TIME)")]
    EmptyName {
        /// The entry as written.
        entry: String,
    },
}

impl FromStr for ColumnMap {
    type Err = ColumnMapError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let mut map = ColumnMap::default();
        let mut seen = [false; 3];
        for entry in s.split(',').map(str::trim).filter(|e| !e.is_empty()) {
            let (key, name) = entry
                .split_once('=')
                .ok_or_else(|| ColumnMapError::Syntax {
                    entry: entry.into(),
                })?;
            let (key, name) = (key.trim(), name.trim());
            let slot = match key {
                "t" => 0,
                "op" => 1,
                "vp" => 2,
                _ => return Err(ColumnMapError::UnknownKey { key: key.into() }),
            };
            if std::mem::replace(&mut seen[slot], true) {
                return Err(ColumnMapError::Duplicate { key: key.into() });
            }
            let empty = || ColumnMapError::EmptyName {
                entry: entry.into(),
            };
            match slot {
                0 => {
                    let parts: Vec<&str> = name.split('+').map(str::trim).collect();
                    if parts.len() > 2 || parts.iter().any(|p| p.is_empty()) {
                        return Err(empty());
                    }
                    map.t = parts.join("+");
                }
                1 if name.is_empty() => return Err(empty()),
                1 => map.op = name.into(),
                _ => map.vp = (!name.is_empty()).then(|| name.into()),
            }
        }
        Ok(map)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(s: &str) -> Result<ColumnMap, ColumnMapError> {
        s.parse()
    }

    #[test]
    fn full_partial_and_special_forms() {
        let m = parse("t=t_s,op=LC74_20CV_pct,vp=LC74_20X_pct").unwrap();
        assert_eq!(m.op, "LC74_20CV_pct");
        assert_eq!(m.vp.as_deref(), Some("LC74_20X_pct"));
        let m = parse(" vp = pos ").unwrap();
        assert_eq!((m.t.as_str(), m.op.as_str()), ("t_s", "op_pct"));
        assert_eq!(m.vp.as_deref(), Some("pos"));
        let m = parse("t=date + time,op=FV_211,vp=").unwrap();
        assert!(m.t_is_date_and_time());
        assert_eq!(m.t_columns().collect::<Vec<_>>(), ["date", "time"]);
        assert_eq!(m.vp, None);
        assert_eq!(m.to_string(), "t=date+time,op=FV_211,vp=");
        assert_eq!(parse("").unwrap(), ColumnMap::default());
    }

    #[test]
    fn bad_syntax_unknown_keys_and_duplicates_are_refused() {
        assert!(matches!(parse("t_s"), Err(ColumnMapError::Syntax { .. })));
        let e = parse("t=a,pos=b").unwrap_err();
        assert_eq!(e, ColumnMapError::UnknownKey { key: "pos".into() });
        assert!(e.to_string().contains("the keys are t, op and vp"));
        assert!(matches!(
            parse("op=a,op=b"),
            Err(ColumnMapError::Duplicate { .. })
        ));
        for bad in ["t=", "op=", "t=a+", "t=a+b+c"] {
            assert!(
                matches!(parse(bad), Err(ColumnMapError::EmptyName { .. })),
                "{bad}"
            );
        }
    }
}
