//! The rows of a fleet's table: a valve summed up for maintenance ([`ValveSummary`]: dead time,
//! reversal delay, friction band, stroke speeds, findings and what to do about each), the fleet
//! ranked by consequence for the process ([`Fleet`]) and its `summary.csv`. Plain data, so the
//! fleet's page renders it without depending on the fleet analysis.
//!
//! Not here: how a row is summed up from a diagnosis (`crate::fleet`, which fills these rows).
//!
//! The figures come from the diagnosis: the step delays it measured in the recording, and the
//! figures of its final model ([`vb_analysis::diagnose::Figures`]), the same numbers its report,
//! JSON and the Python package quote under the same names.
//!
//! The rank is by priority ([`vb_core::vocabulary`]): each finding's size over what is worth
//! maintenance, weighted by what it does to control, summed over the valve's findings. Valves of
//! equal priority (the healthy ones) are ordered by the attention score, which adds, to the
//! number of findings, how far each figure lies beyond what a healthy valve shows ([`Limits`]):
//! `max(0, value / limit - 1)`, and for the stroke speed `limit / speed - 1`.

use serde::{Deserialize, Serialize};

use vb_analysis::diagnose::{NOMINAL_DEAD_TIME_S, NOMINAL_MIN_SLEW_PCT_PER_S};
use vb_core::vocabulary::{valve_priority, Advice, Severity};

/// What the ranking takes as healthy.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Limits {
    /// Dead time a healthy positioner has, s (as diagnosis's baseline allows).
    pub dead_time_s: f64,
    /// Mean delay of a step against the previous movement, s.
    pub reversal_delay_s: f64,
    /// Friction band (lost motion on a reversal), %.
    pub friction_band_pct: f64,
    /// Slowest stroke speed of a healthy valve, %/s (as diagnosis's baseline allows).
    pub stroke_speed_pct_per_s: f64,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            dead_time_s: NOMINAL_DEAD_TIME_S,
            reversal_delay_s: 0.5,
            friction_band_pct: 0.5,
            stroke_speed_pct_per_s: NOMINAL_MIN_SLEW_PCT_PER_S,
        }
    }
}

/// One valve of a fleet: what maintenance reads, and how much attention it needs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ValveSummary {
    /// The valve's name (file stem, or tag).
    pub valve: String,
    /// The file, and the tag of a wide export.
    pub source: String,
    pub samples: usize,
    pub duration_s: f64,
    /// Why the valve could not be read, diagnosed or written (then the figures are empty).
    pub error: Option<String>,
    /// Dead time of the final model, s (see [`vb_analysis::diagnose::Figures`]).
    pub dead_time_s: Option<f64>,
    /// Mean measured delay of steps against the previous movement, and in the same direction, s.
    pub reversal_delay_s: Option<f64>,
    pub same_direction_delay_s: Option<f64>,
    /// Friction band of the final model (lost motion on a reversal), %.
    pub friction_band_pct: Option<f64>,
    /// Stroke-speed limit of the final model at half travel, opening and closing, %/s.
    pub stroke_speed_open_pct_per_s: Option<f64>,
    pub stroke_speed_close_pct_per_s: Option<f64>,
    /// The effects diagnosis found, in order.
    pub findings: Vec<String>,
    /// The size of each finding with its 90 % interval, in the same order
    /// (`friction band 1.40 % (1.10-1.80)`).
    #[serde(default)]
    pub sizes: Vec<String>,
    pub verdict: Option<String>,
    pub heldout_sse_before: Option<f64>,
    pub heldout_sse_after: Option<f64>,
    /// Findings plus how far the figures lie beyond [`Limits`]; orders valves of equal priority.
    pub attention: f64,
    /// Each finding in the vocabulary's words, highest priority first.
    #[serde(default)]
    pub advice: Vec<Advice>,
    /// The sum of the findings' priorities; the fleet is ranked by it.
    #[serde(default)]
    pub priority: f64,
    /// The highest severity of the valve's findings (none without one).
    #[serde(default)]
    pub severity: Option<Severity>,
    /// The valve's own report, relative to the fleet's output directory.
    pub report: Option<String>,
}

impl ValveSummary {
    /// Number of findings plus how far each figure lies beyond `limits` (see the module doc).
    pub fn attention_under(&self, limits: &Limits) -> f64 {
        let over = |v: Option<f64>, limit: f64| v.map_or(0.0, |v| (v / limit - 1.0).max(0.0));
        let slowest = match (
            self.stroke_speed_open_pct_per_s,
            self.stroke_speed_close_pct_per_s,
        ) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        };
        let slow = slowest.map_or(0.0, |v| {
            (limits.stroke_speed_pct_per_s / v.max(1e-9) - 1.0).max(0.0)
        });
        self.findings.len() as f64
            + over(self.dead_time_s, limits.dead_time_s)
            + over(self.reversal_delay_s, limits.reversal_delay_s)
            + over(self.friction_band_pct, limits.friction_band_pct)
            + slow
    }
}

/// A fleet's valves, ranked: most attention first, valves that failed last.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Fleet {
    pub limits: Limits,
    /// Valves diagnosed, and valves that failed.
    pub diagnosed: usize,
    pub failed: usize,
    pub valves: Vec<ValveSummary>,
}

/// The columns of `summary.csv`, in order.
pub(crate) const CSV_HEADER: [&str; 20] = [
    "rank",
    "valve",
    "attention",
    "findings",
    "dead_time_s",
    "reversal_delay_s",
    "same_direction_delay_s",
    "friction_band_pct",
    "stroke_speed_open_pct_per_s",
    "stroke_speed_close_pct_per_s",
    "heldout_sse_before",
    "heldout_sse_after",
    "samples",
    "source",
    "report",
    "error",
    "sizes",
    "priority",
    "severity",
    "advice",
];

impl Fleet {
    /// Ranks `valves`: by priority (from their advice), then attention (from the default
    /// [`Limits`]), then name; valves that failed last.
    pub fn ranked(mut valves: Vec<ValveSummary>) -> Self {
        let limits = Limits::default();
        for v in &mut valves {
            if v.error.is_some() {
                (v.attention, v.priority, v.severity) = (0.0, 0.0, None);
            } else {
                v.attention = v.attention_under(&limits);
                (v.priority, v.severity) = valve_priority(&v.advice);
            }
        }
        valves.sort_by(|a, b| {
            (a.error.is_some().cmp(&b.error.is_some()))
                .then(b.priority.total_cmp(&a.priority))
                .then(b.attention.total_cmp(&a.attention))
                .then(a.valve.cmp(&b.valve))
        });
        let failed = valves.iter().filter(|v| v.error.is_some()).count();
        Fleet {
            limits,
            diagnosed: valves.len() - failed,
            failed,
            valves,
        }
    }

    /// `summary.csv`: one row per valve in rank order ([`CSV_HEADER`]), findings joined by `;`.
    pub fn csv(&self) -> String {
        // Writing to memory cannot fail: csv's errors are the writer's I/O and serialisation,
        // and every field here is already a string.
        self.write_csv().unwrap_or_default()
    }

    fn write_csv(&self) -> Result<String, Box<dyn std::error::Error>> {
        let num = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.4}"));
        let mut w = csv::Writer::from_writer(Vec::new());
        w.write_record(CSV_HEADER)?;
        for (i, v) in self.valves.iter().enumerate() {
            w.write_record([
                (i + 1).to_string(),
                v.valve.clone(),
                format!("{:.3}", v.attention),
                v.findings.join(";"),
                num(v.dead_time_s),
                num(v.reversal_delay_s),
                num(v.same_direction_delay_s),
                num(v.friction_band_pct),
                num(v.stroke_speed_open_pct_per_s),
                num(v.stroke_speed_close_pct_per_s),
                num(v.heldout_sse_before),
                num(v.heldout_sse_after),
                v.samples.to_string(),
                v.source.clone(),
                v.report.clone().unwrap_or_default(),
                v.error.clone().unwrap_or_default(),
                v.sizes.join(";"),
                format!("{:.3}", v.priority),
                v.severity.map_or("", Severity::name).to_string(),
                (v.advice.iter().map(Advice::sentence))
                    .collect::<Vec<_>>()
                    .join(" "),
            ])?;
        }
        Ok(String::from_utf8(w.into_inner()?)?)
    }
}
