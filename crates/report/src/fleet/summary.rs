//! How a valve of a fleet is summed up: a [`ValveSummary`] from its diagnosis, or from the
//! error that stopped it.
//!
//! Not here: the rows themselves, the ranking and `summary.csv`
//! ([`crate::fleet::table`]).

use super::Job;
pub use crate::fleet::table::{Fleet, Limits, ValveSummary};
use vb_analysis::diagnose::Diagnosis;
use vb_core::metrics::steps::Population;
use vb_core::recording::Recording;

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
            advice: Vec::new(),
            priority: 0.0,
            severity: None,
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
            verdict: Some(crate::diagnose::verdict(d)),
            heldout_sse_before: finite(d.baseline.heldout_sse),
            heldout_sse_after: finite(d.final_model.heldout_sse),
            advice: crate::diagnose::advice(d),
            ..ValveSummary::failed(job, String::new())
        };
        s.attention = s.attention_under(&Limits::default());
        (s.priority, s.severity) = vb_core::vocabulary::valve_priority(&s.advice);
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fleet::table::CSV_HEADER;

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
            lines[4].contains(",x.csv:1: no column `op_pct`,"),
            "{}",
            lines[4]
        );
    }

    #[test]
    fn consequence_for_the_process_ranks_before_attention() {
        use vb_core::model::composed::{Effect, Size};
        use vb_core::vocabulary::{advice, Severity};
        let size = |name, unit, worth| Size {
            name,
            unit,
            value: 1.0,
            low: 0.9,
            high: 1.1,
            worth,
            worth_low: worth,
        };
        // Stick-slip just worth maintenance outranks a slow stroke and a dead time five and
        // three times past it, though the slow valve has more findings and figures beyond a
        // healthy valve's.
        let mut sticky = valve("sticky", 1, 0.1);
        sticky.advice = advice([(Effect::Stiction, &size("slip_pct", "%", 1.0))]);
        let mut slow = valve("slow", 2, 0.9);
        let (speed, dead) = (
            size("stroke_speed_pct_per_s", "%/s", 5.0),
            size("dead_time_s", "s", 3.0),
        );
        slow.advice = advice([(Effect::SlewRate, &speed), (Effect::DeadTime, &dead)]);
        assert!(
            slow.attention_under(&Limits::default()) > sticky.attention_under(&Limits::default())
        );
        let f = Fleet::ranked(vec![slow, sticky]);
        let order: Vec<(&str, f64, Option<Severity>)> = (f.valves.iter())
            .map(|v| (v.valve.as_str(), v.priority, v.severity))
            .collect();
        assert_eq!(
            order,
            [
                ("sticky", 10.0, Some(Severity::High)),
                ("slow", 8.0, Some(Severity::Medium))
            ]
        );
        let csv = f.csv();
        let first = csv.lines().nth(1).unwrap_or_default();
        assert!(first.contains(",10.000,high,\"High: stick-slip (stiction) sticks, then jumps by 1.00 % (0.90-1.10) at a time"), "{first}");
    }
}
