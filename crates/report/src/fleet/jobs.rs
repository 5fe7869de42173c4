//! Which valves a fleet directory holds: [`jobs`] lists every `*.csv` file (one valve each,
//! named after the file), or, with a [`ValveMap`] for wide historian exports, every valve tag
//! of the map in every file. Each valve's name is its folder of the fleet's report: made safe
//! (no path, never `.` or `..`) and unique ignoring case, so no two valves share a folder.
//!
//! Not here: reading the files (a file that is no recording is a valve that fails later).

use std::collections::{BTreeMap, HashSet};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use vb_core::recording::{ColumnMap, ReadOptions};
use vb_core::toml_file::{self, TomlError};

/// A column-mapping file for wide exports: the time column and, per valve tag, its O_P and V_P
/// columns.
///
/// ```toml
/// time = "t_s"            # or "DATE+TIME" for separate date and time columns
/// [valves]
/// FV101 = { op = "FV101_OP", vp = "FV101_PV" }
/// LV205 = { op = "LV205_OP", vp = "LV205_PV" }
/// ```
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ValveMap {
    /// The time column (or `DATE+TIME`).
    pub time: String,
    /// Each valve tag's columns.
    pub valves: BTreeMap<String, TagColumns>,
}

/// The O_P and V_P columns of one valve tag.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TagColumns {
    pub op: String,
    pub vp: String,
}

impl ValveMap {
    /// Loads a mapping file; it must name at least one valve.
    pub fn load(path: &Path) -> Result<Self, FleetError> {
        let (map, _): (ValveMap, _) = toml_file::load(path)?;
        if map.valves.is_empty() {
            return Err(FleetError::NoValves(path.to_path_buf()));
        }
        Ok(map)
    }
}

/// One valve to diagnose: a file, and the columns of its valve when the file holds several.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Job {
    /// The valve's name in the fleet (file stem, tag, or `stem.tag`), safe as a directory name
    /// and, ignoring case, unique in the fleet ([`jobs`]).
    pub valve: String,
    /// The recording file.
    pub path: PathBuf,
    /// The valve tag in a wide export, with its columns.
    pub tag: Option<String>,
    pub columns: Option<Columns>,
}

/// The time, O_P and V_P columns of a valve in a wide export.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Columns {
    pub t: String,
    pub op: String,
    pub vp: String,
}

impl Job {
    /// The reader options for this valve: `base` with the tag's columns.
    pub fn read_options(&self, base: &ReadOptions) -> ReadOptions {
        let mut o = base.clone();
        if let Some(c) = &self.columns {
            o.columns = ColumnMap {
                t: c.t.clone(),
                op: c.op.clone(),
                vp: Some(c.vp.clone()),
            };
            o.timestamps |= o.columns.t_is_date_and_time();
        }
        o
    }

    /// The file, and the tag when there is one: `export.csv [FV101]`.
    pub fn source(&self) -> String {
        match &self.tag {
            Some(t) => format!("{} [{t}]", self.path.display()),
            None => self.path.display().to_string(),
        }
    }
}

/// Why a fleet cannot be listed.
#[derive(Debug, thiserror::Error)]
pub enum FleetError {
    #[error("{}: cannot list the directory: {source}; give a directory of recordings (*.csv)", dir.display())]
    List {
        dir: PathBuf,
        source: std::io::Error,
    },
    #[error("{}: no *.csv recordings in this directory; give the directory that holds them", .0.display())]
    Empty(PathBuf),
    #[error("{}: no valves under [valves]; add one per tag, e.g. FV101 = {{ op = \"FV101_OP\", vp = \"FV101_PV\" }}", .0.display())]
    NoValves(PathBuf),
    #[error(transparent)]
    Map(#[from] TomlError),
}

/// A name safe as one directory: letters, digits, `.`, `-` and `_` kept, anything else `_`
/// (`FV/101` and `/etc` name no path); a name of dots only (`.`, `..`) or empty gets a leading
/// `_`, so that it never names the directory it is in, or that one's parent.
pub(super) fn safe(name: &str) -> String {
    let kept: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "._-".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect();
    if kept.chars().all(|c| c == '.') {
        format!("_{kept}")
    } else {
        kept
    }
}

/// `names` made unique ignoring case, as a case-insensitive file system sees them (`FV 101`,
/// `FV/101` and `fv 101` are all `FV_101` but for case): the first of each keeps its name,
/// each later one gets the first free `-2`, `-3`, ...
fn unique(names: Vec<String>) -> Vec<String> {
    let mut taken: HashSet<String> = names.iter().map(|n| n.to_ascii_lowercase()).collect();
    let mut kept = HashSet::new();
    names
        .into_iter()
        .map(|name| {
            if kept.insert(name.to_ascii_lowercase()) {
                return name;
            }
            let mut k = 2;
            while taken.contains(&format!("{name}-{k}").to_ascii_lowercase()) {
                k += 1;
            }
            let free = format!("{name}-{k}");
            taken.insert(free.to_ascii_lowercase());
            free
        })
        .collect()
}

/// The valves of `dir`: every `*.csv` (or `*.csv.gz`) file (sorted by name) as one valve, or
/// with `map` every tag of the map in every file (named by the tag, or `stem.tag` when there
/// are several files). Names are made [`safe`] and unique, ignoring case.
pub fn jobs(dir: &Path, map: Option<&ValveMap>) -> Result<Vec<Job>, FleetError> {
    let list = |source| FleetError::List {
        dir: dir.to_path_buf(),
        source,
    };
    let mut files: Vec<PathBuf> = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(list)? {
        let path = entry.map_err(list)?.path();
        let name = path.file_name().unwrap_or_default().to_string_lossy();
        if path.is_file() && vb_core::recording::gzip::is_recording_name(&name) {
            files.push(path);
        }
    }
    if files.is_empty() {
        return Err(FleetError::Empty(dir.to_path_buf()));
    }
    files.sort();
    let stem = |p: &Path| {
        let name = p.file_name().unwrap_or_default().to_string_lossy();
        vb_core::recording::gzip::stem(&name).to_string()
    };
    let mut jobs: Vec<Job> = match map {
        None => files
            .iter()
            .map(|p| Job {
                valve: stem(p),
                path: p.clone(),
                tag: None,
                columns: None,
            })
            .collect(),
        Some(map) => {
            let several = files.len() > 1;
            files
                .iter()
                .flat_map(|p| {
                    map.valves.iter().map(move |(tag, c)| Job {
                        valve: if several {
                            format!("{}.{tag}", stem(p))
                        } else {
                            tag.clone()
                        },
                        path: p.clone(),
                        tag: Some(tag.clone()),
                        columns: Some(Columns {
                            t: map.time.clone(),
                            op: c.op.clone(),
                            vp: c.vp.clone(),
                        }),
                    })
                })
                .collect()
        }
    };
    let names = unique(jobs.iter().map(|j| safe(&j.valve)).collect());
    for (job, name) in jobs.iter_mut().zip(names) {
        job.valve = name;
    }
    Ok(jobs)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn files_or_tags_become_valves() {
        let dir = tempfile::tempdir().unwrap();
        for f in ["b.csv", "a v.csv", "notes.txt"] {
            std::fs::write(dir.path().join(f), "t_s,op_pct,vp_pct\n").unwrap();
        }
        let j = jobs(dir.path(), None).unwrap();
        let names: Vec<&str> = j.iter().map(|j| j.valve.as_str()).collect();
        assert_eq!(names, ["a_v", "b"]);
        assert_eq!(
            j[0].read_options(&ReadOptions::default()),
            ReadOptions::default()
        );

        let map_file = dir.path().join("map.toml");
        std::fs::write(
            &map_file,
            "time = \"Date+Time\"\n[valves]\nFV1 = { op = \"F1\", vp = \"P1\" }\n",
        )
        .unwrap();
        let map = ValveMap::load(&map_file).unwrap();
        let j = jobs(dir.path(), Some(&map)).unwrap();
        assert_eq!(j.len(), 2);
        assert_eq!(j[1].valve, "b.FV1");
        assert_eq!(j[1].source(), format!("{} [FV1]", j[1].path.display()));
        let o = j[1].read_options(&ReadOptions::default());
        assert!(o.timestamps);
        assert_eq!(o.columns.op, "F1");
    }

    #[test]
    fn tags_that_collide_or_name_paths_get_unique_safe_names() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("export.csv"), "t\n").unwrap();
        let map_file = dir.path().join("map.toml");
        let tags = [
            "FV 101", "FV/101", "fv 101", "FV_101-2", "..", ".", "", "/etc",
        ];
        let mut toml = String::from("time = \"t\"\n[valves]\n");
        for t in tags {
            toml += &format!("{t:?} = {{ op = \"o\", vp = \"v\" }}\n");
        }
        std::fs::write(&map_file, toml).unwrap();
        let map = ValveMap::load(&map_file).unwrap();
        let j = jobs(dir.path(), Some(&map)).unwrap();
        let named: Vec<(&str, &str)> = j
            .iter()
            .map(|j| (j.tag.as_deref().unwrap(), j.valve.as_str()))
            .collect();
        // In the map's order of tags; the first of each name keeps it.
        assert_eq!(
            named,
            [
                ("", "_"),
                (".", "_."),
                ("..", "_.."),
                ("/etc", "_etc"),
                ("FV 101", "FV_101"),
                ("FV/101", "FV_101-3"),
                ("FV_101-2", "FV_101-2"),
                ("fv 101", "fv_101-4"),
            ]
        );
    }

    #[test]
    fn listing_errors_say_what_to_do() {
        let dir = tempfile::tempdir().unwrap();
        let e = jobs(dir.path(), None).unwrap_err().to_string();
        assert!(e.contains("no *.csv recordings"), "{e}");
        let e = jobs(&dir.path().join("nowhere"), None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("cannot list the directory"), "{e}");
        let f = dir.path().join("m.toml");
        std::fs::write(&f, "time = \"t\"\n[valves]\n").unwrap();
        let e = ValveMap::load(&f).unwrap_err().to_string();
        assert!(e.contains("no valves under [valves]"), "{e}");
        std::fs::write(&f, "time = \"t\"\n[valves]\nX = { op = \"a\" }\n").unwrap();
        let e = ValveMap::load(&f).unwrap_err().to_string();
        assert!(e.starts_with(&format!("{}:3:", f.display())), "{e}");
    }
}
