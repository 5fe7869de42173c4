//! A response test's spec (`--spec FILE.toml`): upper limits on the steps' figures by step size
//! (`[[limit]]` tables: `min_size_pct`, optional `max_size_pct`, and any of `dead_time_s`,
//! `t63_s`, `t86_s`, `overshoot_pct`) and on the signature's (`[signature]`: `dead_band_pct`,
//! `resolution_pct`), each checked into a [`Line`] that passes or fails. A limit that no
//! measured step can be held to (none of that size, or a step that never reached the figure)
//! fails: a spec passes only on what the test showed.
//!
//! Not here: the words of the lines (`vb_report::response`).

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::{ResponseTest, StepResult};
use vb_core::toml_file::{self, Layout, TomlError};

/// A spec as its file holds it.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Spec {
    /// Limits on the steps, by size.
    #[serde(default, rename = "limit")]
    pub limits: Vec<Limit>,
    /// Limits on the signature.
    #[serde(default)]
    pub signature: SignatureLimits,
}

/// Upper limits on the figures of the steps from `min_size_pct` to `max_size_pct`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Limit {
    pub min_size_pct: f64,
    pub max_size_pct: Option<f64>,
    pub dead_time_s: Option<f64>,
    pub t63_s: Option<f64>,
    pub t86_s: Option<f64>,
    pub overshoot_pct: Option<f64>,
}

/// Upper limits on the signature.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SignatureLimits {
    pub dead_band_pct: Option<f64>,
    pub resolution_pct: Option<f64>,
}

/// A step's figure, read from it.
type Figure = fn(&StepResult) -> Option<f64>;

/// One line of a spec checked.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Line {
    /// The figure (`dead_time_s`, ..., `resolution_pct`).
    pub figure: &'static str,
    /// The step sizes it covers, %, for a `[[limit]]`.
    pub sizes_pct: Option<(f64, Option<f64>)>,
    /// The limit.
    pub limit: f64,
    /// The worst value measured (`None`: none could be).
    pub worst: Option<f64>,
    /// The step it was measured on, when it was a step's.
    pub step: Option<usize>,
    /// Steps the line covers.
    pub steps: usize,
    pub pass: bool,
}

impl Spec {
    /// Reads and checks the spec file `path`.
    pub fn load(path: &Path) -> Result<Spec, TomlError> {
        let (spec, text): (Spec, String) = toml_file::load(path)?;
        let layout = Layout::parse(&text);
        for (i, l) in spec.limits.iter().enumerate() {
            let lines = layout.lines().nth(i);
            let bad = |key: &str, message: String| {
                toml_file::invalid(lines, path, Some("limit"), key, message)
            };
            let figures = [
                ("dead_time_s", l.dead_time_s),
                ("t63_s", l.t63_s),
                ("t86_s", l.t86_s),
                ("overshoot_pct", l.overshoot_pct),
                ("max_size_pct", l.max_size_pct),
            ];
            if !(l.min_size_pct.is_finite() && l.min_size_pct >= 0.0) {
                return Err(bad(
                    "min_size_pct",
                    format!("{}: a step size in %, 0 or more", l.min_size_pct),
                ));
            }
            for (key, v) in figures {
                if v.is_some_and(|v| !(v.is_finite() && v >= 0.0)) {
                    return Err(bad(key, "a limit, 0 or more".into()));
                }
            }
            if l.max_size_pct.is_some_and(|m| m < l.min_size_pct) {
                return Err(bad(
                    "max_size_pct",
                    format!("below min_size_pct = {}", l.min_size_pct),
                ));
            }
            if figures[..4].iter().all(|(_, v)| v.is_none()) {
                return Err(bad(
                    "",
                    "a [[limit]] needs at least one of dead_time_s, t63_s, t86_s, overshoot_pct"
                        .into(),
                ));
            }
        }
        let s = &spec.signature;
        for (key, v) in [
            ("dead_band_pct", s.dead_band_pct),
            ("resolution_pct", s.resolution_pct),
        ] {
            if v.is_some_and(|v| !(v.is_finite() && v >= 0.0)) {
                return Err(toml_file::invalid(
                    layout.lines(),
                    path,
                    Some("signature"),
                    key,
                    "a limit in %, 0 or more".into(),
                ));
            }
        }
        Ok(spec)
    }

    /// Every line of the spec checked against `r`.
    pub fn check(&self, r: &ResponseTest) -> Vec<Line> {
        let mut out = Vec::new();
        for l in &self.limits {
            let covered = |s: &&StepResult| {
                s.measured
                    && s.size_pct >= l.min_size_pct
                    && l.max_size_pct.is_none_or(|m| s.size_pct <= m)
            };
            let steps: Vec<usize> = (r.steps.iter().enumerate())
                .filter(|(_, s)| covered(s))
                .map(|(i, _)| i)
                .collect();
            let figures: [(&'static str, Option<f64>, Figure); 4] = [
                ("dead_time_s", l.dead_time_s, |s| s.dead_time_s),
                ("t63_s", l.t63_s, |s| s.t63_s),
                ("t86_s", l.t86_s, |s| s.t86_s),
                ("overshoot_pct", l.overshoot_pct, |s| s.overshoot_pct),
            ];
            for (figure, limit, get) in figures {
                let Some(limit) = limit else { continue };
                // A step that never reached the figure is the worst of all.
                let never = steps.iter().copied().find(|&i| get(&r.steps[i]).is_none());
                let worst = (steps.iter().copied())
                    .filter_map(|i| get(&r.steps[i]).map(|v| (i, v)))
                    .max_by(|a, b| a.1.total_cmp(&b.1));
                let (step, worst) = match never {
                    Some(i) => (Some(i), None),
                    None => (worst.map(|w| w.0), worst.map(|w| w.1)),
                };
                out.push(Line {
                    figure,
                    sizes_pct: Some((l.min_size_pct, l.max_size_pct)),
                    limit,
                    worst,
                    step,
                    steps: steps.len(),
                    pass: worst.is_some_and(|w| w <= limit),
                });
            }
        }
        let sig = &r.signature;
        for (figure, limit, value) in [
            (
                "dead_band_pct",
                self.signature.dead_band_pct,
                sig.dead_band_pct,
            ),
            (
                "resolution_pct",
                self.signature.resolution_pct,
                sig.resolution_pct,
            ),
        ] {
            if let Some(limit) = limit {
                out.push(Line {
                    figure,
                    sizes_pct: None,
                    limit,
                    worst: value,
                    step: None,
                    steps: 0,
                    pass: value.is_some_and(|v| v <= limit),
                });
            }
        }
        out
    }
}
