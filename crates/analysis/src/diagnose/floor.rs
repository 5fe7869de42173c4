//! Whether a recording shows a positioner's minimum speed (a creep floor: small errors closed
//! at a constant rate instead of in proportion), for the judge of a `min_speed` candidate.
//!
//! Not here: how the step tails are measured (`facts::approach`), how the floor is fitted
//! (`candidates`).

use super::facts::{self, Facts};
use vb_core::model::composed::{self, Knob};
use vb_core::model::ModelSpec;

/// Largest band of errors a minimum speed may cover, %: a floor over several % is a
/// constant-speed valve.
const MAX_SPEED_BAND_PCT: f64 = 5.0;
/// Share of a fitted minimum speed the valve must keep in the tails of its steps, where a
/// proportional positioner would have slowed to a quarter of it or less.
const MIN_FLOOR_SHOWN: f64 = 0.7;
/// How much faster than a minimum speed the valve must be seen moving for the floor to be told
/// from a slew limit.
const FASTER_THAN_FLOOR: f64 = 1.5;
/// Fewest samples of step tails (see [`Facts::approach`]) a recording must have for a
/// minimum speed to be named at all.
const MIN_TAIL_SAMPLES: usize = 30;

/// Whether the recording shows the minimum speed of `spec`. The floor takes over from
/// proportional action below an error of dy_min / P_k, but only for small errors: a floor over
/// several % is a constant-speed valve. Where the recording shows the tails of steps well
/// inside that band (beyond the noise), V_P must still move there at [`MIN_FLOOR_SHOWN`] of
/// the floor as the tails read it, not slow down in proportion. `read` is how the tails of
/// the model with the floor read ([`facts::approach`] of its V_P); without it the floor
/// itself. A reading takes the speed over 0.1 s, which at a fast floor reaches where the stem
/// stops: seed 60's digital valve 324, a floor of 29.8 %/s fitted as 29.3, reads 19.0 %/s
/// 0.26-0.53 % from rest.
/// A recording without step tails (a valve in closed loop answering a noisy controller
/// output) cannot tell a floor from a rate limit or a filter: none is named there; nor can one
/// where the valve never moves clearly faster than the floor (a valve that always moves at one
/// speed is slew-limited, as far as any recording shows).
pub(super) fn floor_shown(spec: &ModelSpec, facts: &Facts, read: Option<&[(f64, f64)]>) -> bool {
    let floor = composed::get(spec, Knob::MinSpeed);
    let band = floor / composed::get(spec, Knob::Gain);
    let lo = (2.5 * facts.noise_pct).max(band / 8.0);
    let reading = read.map_or(Some(floor), |tails| {
        facts::approach_speed(tails, lo, 2.0 * lo)
    });
    let kept = match (
        facts::approach_speed(&facts.approach, lo, 2.0 * lo),
        reading,
    ) {
        (Some(speed), Some(model)) if 2.0 * lo <= band => speed >= MIN_FLOOR_SHOWN * model,
        _ => facts.approach.len() >= MIN_TAIL_SAMPLES,
    };
    let faster = facts.open_speed.max(facts.close_speed) >= FASTER_THAN_FLOOR * floor;
    floor >= 0.1 && band <= MAX_SPEED_BAND_PCT && kept && faster
}
