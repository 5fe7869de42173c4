//! Whether the valve strokes slower than a valve in good order, measured on the recording
//! rather than read off a model.
//!
//! A planner needs to hear that a valve is slow whether or not the model needed a new term
//! for it: a baseline whose time constant stretches to the valve's slowness fits a
//! rate-limited valve well enough that no speed limit is worth adding, and its figures then
//! say nothing about the stroke. The recording says it directly when O_P asked for speed: a
//! step of [`ASKED_STEP_PCT`] or more asks a valve in good order (positioner gain 2 /s or
//! more) for at least the stroke speed worth maintenance, so V_P's fastest move in that
//! direction ([`Facts::open_speed`], noise taken out) is the valve's stroke speed or less.
//!
//! Not here: the speed limits a model is given (`candidates`) or judged by (`judge`).

use super::diagnosis::Note;
use super::facts::Facts;

/// Smallest O_P step, %, that asks a valve in good order for the stroke speed worth
/// maintenance: the slowest healthy positioner gain (2 /s) times this is 40 %/s.
pub(super) const ASKED_STEP_PCT: f64 = 20.0;

/// The note that the valve strokes slower than `worth_pct_per_s` in a direction some step of
/// the recording asked it to go fast in, with the fastest speed measured each way (`None`
/// where no step asked); `None` when no asked direction is slow.
pub(super) fn slow_strokes(facts: &Facts, worth_pct_per_s: f64) -> Option<Note> {
    let largest = |sign: f64| {
        (facts.steps.iter())
            .map(|s| sign * s.size_pct)
            .fold(0.0f64, f64::max)
    };
    let (up, down) = (largest(1.0), largest(-1.0));
    let asked = |step: f64, speed: f64| (step >= ASKED_STEP_PCT).then_some(speed);
    let opening = asked(up, facts.open_speed);
    let closing = asked(down, facts.close_speed);
    let slow = |s: Option<f64>| s.is_some_and(|v| v < worth_pct_per_s);
    (slow(opening) || slow(closing)).then_some(Note::SlowStrokes {
        opening_pct_per_s: opening,
        closing_pct_per_s: closing,
        largest_step_pct: up.max(down),
        worth_pct_per_s,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::facts;
    use vb_core::testkit::{noise, steps, Columns};

    const DT: f64 = 0.01;

    /// V_P of a valve following `op` at `gain` /s, no faster than `limit` %/s, read with
    /// 0.1 % of noise: a rate limiter written here, apart from the project's models.
    fn follow(op: &[f64], gain: f64, limit: f64) -> Vec<f64> {
        let e = noise(op.len(), 0.1);
        let mut x = op[0];
        (op.iter().zip(e))
            .map(|(&u, e)| {
                x += (gain * (u - x)).clamp(-limit, limit) * DT;
                x + e
            })
            .collect()
    }

    fn note(levels: &[f64], gain: f64, limit: f64) -> Option<Note> {
        let op = steps(12_000, 1_000, levels);
        let rec = Columns::new(op.clone(), follow(&op, gain, limit), DT);
        let f = facts::measure(&rec.view(), 0.1, 0.0);
        slow_strokes(&f, 40.0)
    }

    #[test]
    fn a_valve_asked_for_speed_and_stroking_slowly_is_slow_each_way_it_was_asked() {
        // Steps of 30 % both ways at 8 %/s: slow, at about 8 %/s each way.
        let Some(Note::SlowStrokes {
            opening_pct_per_s: Some(open),
            closing_pct_per_s: Some(close),
            largest_step_pct,
            worth_pct_per_s,
        }) = note(&[30.0, 60.0], 10.0, 8.0)
        else {
            panic!("a valve stroking at 8 %/s on 30 % steps is slow");
        };
        assert!((open - 8.0).abs() < 0.8, "{open}");
        assert!((close - 8.0).abs() < 0.8, "{close}");
        assert!((largest_step_pct - 30.0).abs() < 1e-9);
        assert_eq!(worth_pct_per_s, 40.0);
        // Opening by 25 % but closing in 5 % steps: only the opening speed is measured.
        let up = note(&[50.0, 75.0, 70.0, 65.0, 60.0, 55.0, 50.0], 10.0, 8.0);
        assert!(
            matches!(
                up,
                Some(Note::SlowStrokes {
                    opening_pct_per_s: Some(_),
                    closing_pct_per_s: None,
                    ..
                })
            ),
            "{up:?}"
        );
    }

    #[test]
    fn a_fast_valve_or_one_never_asked_for_speed_is_not_slow() {
        // 30 % steps at 60 %/s.
        assert_eq!(note(&[30.0, 60.0], 10.0, 60.0), None);
        // 5 % steps never ask for 40 %/s: a slow valve is not told from a healthy one.
        assert_eq!(note(&[50.0, 55.0], 10.0, 8.0), None);
    }
}
