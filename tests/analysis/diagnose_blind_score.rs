//! The blind benchmark's coverage table (`benches/blind/score.rs`): of the labelled valves
//! whose finding is sized in the unit of the truth, how many 90 % intervals hold the physical
//! value, and the median of reported over true; a finding quoted in another unit and a missed
//! label count apart. Arithmetic only; no diagnosis runs.

use crate::cases::Truth;
use crate::score::{coverage, Coverage, Outcome};
use valve_bridge::diagnose::{Effect, Size};

fn size(name: &'static str, value: f64, low: f64, high: f64) -> Size {
    Size {
        name,
        unit: "%",
        value,
        low,
        high,
        worth: 2.0,
        worth_low: 1.5,
    }
}

/// A valve labelled with a friction band of `truth` %, and the finding of it, if any.
fn valve(truth: f64, found: Option<Size>) -> Outcome {
    Outcome {
        family: "digital",
        excitation: "ramps",
        labels: vec![Effect::Backlash],
        sizes: vec![(Effect::Backlash, truth)],
        truth: vec![Truth {
            effect: Effect::Backlash,
            name: "friction_band_pct",
            value: truth,
        }],
        findings: found.iter().map(|_| Effect::Backlash).collect(),
        sized: found.into_iter().map(|s| (Effect::Backlash, s)).collect(),
        baseline_heldout_sse: 1.0,
        final_heldout_sse: 0.5,
        seconds: 1.0,
        cpu_seconds: 1.0,
        items: Vec::new(),
    }
}

#[test]
fn coverage_counts_the_intervals_that_hold_the_truth() {
    let all = [
        valve(1.0, Some(size("friction_band_pct", 1.1, 0.9, 1.2))),
        valve(2.0, Some(size("friction_band_pct", 2.6, 2.4, 2.8))),
        // Read off the recording, equal to the drawn value but for the last digits.
        valve(
            2.0,
            Some(size("friction_band_pct", 2.0, 2.0 + 1e-14, 2.0 + 1e-14)),
        ),
        valve(3.0, Some(size("crossing_half_open_s", 0.05, 0.04, 0.06))),
        valve(4.0, None),
    ];
    assert_eq!(
        coverage(&all, Effect::Backlash),
        Some(Coverage {
            name: "friction_band_pct",
            labelled: 5,
            found: 4,
            sized: 3,
            holds: 2,
            ratio: 1.1,
        })
    );
    assert_eq!(coverage(&all, Effect::DeadTime), None);
}
