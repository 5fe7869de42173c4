//! How a valve of a fleet is summed up: a [`ValveSummary`] from its diagnosis, or from the
//! error that stopped it.
//!
//! Not here: the rows themselves, the ranking and `summary.csv`
//! ([`crate::report::fleet_table`]).

use super::Job;
use crate::diagnose::Diagnosis;
use crate::metrics::steps::Population;
use crate::recording::Recording;
pub use crate::report::fleet_table::{Fleet, Limits, ValveSummary};

/// A finite value, or none.
fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

impl ValveSummary {
    /// A valve that could not be diagnosed.
    pub fn failed(job: &Job, error: String) -> Self {
        ValveSummary {
            valve: job.valve.clone(),
            source: job.source(),
            samples: 0,
            duration_s: 0.0,
            error: Some(error),
            dead_time_s: None,
            reversal_delay_s: None,
            same_direction_delay_s: None,
            friction_band_pct: None,
            stroke_speed_open_pct_per_s: None,
            stroke_speed_close_pct_per_s: None,
            findings: Vec::new(),
            sizes: Vec::new(),
            verdict: None,
            heldout_sse_before: None,
            heldout_sse_after: None,
            attention: 0.0,
            report: None,
        }
    }

    /// The summary of a diagnosed valve.
    pub fn of(job: &Job, rec: &Recording, d: &Diagnosis) -> Self {
        let f = &d.figures;
        let delays = |rev: bool| {
            let x: Vec<f64> = d
                .steps
                .iter()
                .filter(|s| s.reversal == rev)
                .map(|s| s.delay_s)
                .collect();
            let p = Population::of(&x);
            (p.count > 0).then_some(p.mean_s)
        };
        let mut s = ValveSummary {
            samples: rec.len(),
            duration_s: rec.duration(),
            error: None,
            dead_time_s: finite(f.dead_time_s),
            reversal_delay_s: delays(true),
            same_direction_delay_s: delays(false),
            friction_band_pct: finite(f.friction_band_pct),
            stroke_speed_open_pct_per_s: finite(f.opening_speed_pct_per_s),
            stroke_speed_close_pct_per_s: finite(f.closing_speed_pct_per_s),
            findings: d.findings.iter().map(|f| f.effect.name().into()).collect(),
            sizes: (d.findings.iter()).map(|f| f.size.words()).collect(),
            verdict: Some(crate::report::diagnose::verdict(d)),
            heldout_sse_before: finite(d.baseline.heldout_sse),
            heldout_sse_after: finite(d.final_model.heldout_sse),
            ..ValveSummary::failed(job, String::new())
        };
        s.attention = s.attention_under(&Limits::default());
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::fleet_table::CSV_HEADER;

    fn valve(name: &str, findings: usize, dead_time_s: f64) -> ValveSummary {
        let job = Job {
            valve: name.into(),
            path: format!("{name}.csv").into(),
            tag: None,
            columns: None,
        };
        ValveSummary {
            error: None,
            dead_time_s: Some(dead_time_s),
            stroke_speed_open_pct_per_s: Some(80.0),
            stroke_speed_close_pct_per_s: Some(20.0),
            findings: vec!["slew_rate".into(); findings],
            ..ValveSummary::failed(&job, String::new())
        }
    }

    #[test]
    fn attention_counts_findings_and_excess_over_the_limits() {
        let v = valve("a", 1, 0.4);
        // One finding, dead time twice the limit (+1), closing at half the speed limit (+1).
        assert!((v.attention_under(&Limits::default()) - 3.0).abs() < 1e-12);
        let healthy = ValveSummary {
            stroke_speed_close_pct_per_s: Some(60.0),
            ..valve("b", 0, 0.1)
        };
        assert_eq!(healthy.attention_under(&Limits::default()), 0.0);
    }

    #[test]
    fn ranking_puts_the_worst_first_and_failures_last() {
        let mut broken = valve("0-broken", 5, 9.0);
        broken.error = Some("x.csv:1: no column `op_pct`".into());
        let f = Fleet::ranked(vec![
            valve("c", 0, 0.1),
            broken,
            valve("b", 2, 0.1),
            valve("a", 0, 0.1),
        ]);
        let order: Vec<&str> = f.valves.iter().map(|v| v.valve.as_str()).collect();
        assert_eq!(order, ["b", "a", "c", "0-broken"]);
        assert_eq!((f.diagnosed, f.failed), (3, 1));
        let csv = f.csv();
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines[0], CSV_HEADER.join(","));
        assert!(
            lines[1].starts_with("1,b,3.000,slew_rate;slew_rate,0.1000,"),
            "{}",
            lines[1]
        );
        assert!(
            lines[4].ends_with("x.csv:1: no column `op_pct`,"),
            "{}",
            lines[4]
        );
    }
}
