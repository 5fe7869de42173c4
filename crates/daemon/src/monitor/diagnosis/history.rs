//! One valve's diagnosis history: each diagnosis as a line of `diagnosis-<valve>.jsonl` (loop
//! time, trigger, verdict, every finding and trace with its size, unit and 90 % interval), the
//! baseline (the first diagnosis) and the alarms against it.
//!
//! The baseline is the first diagnosis of a whole window, and its final model is where every
//! later window's diagnosis starts (as `diagnose --model` does): a finding then is physics the
//! valve did not show at the baseline, or an effect of it that had to be refitted, so look-alike
//! effects that take turns from one window to the next on a healthy valve (a crossing time here,
//! a dead time there) are not found anew. An alarm names its effect: a finding
//! whose effect the baseline did not show at all, not even as a trace (a new effect), or whose
//! size grew out of the baseline's: its interval no longer overlaps the baseline's (requiring
//! the intervals to part, not only the value to leave, keeps a healthy valve's scatter from
//! alarming one window in twenty), towards worse (its weight against what is worth maintenance
//! rose), by a change itself worth maintenance (the weight rose by 1 or more). A size that
//! shrank, a size of another quantity (an effect can be sized by the quantity the recording
//! shows best, see `diagnose::size`) and traces (immaterial) never alarm. An effect
//! past the baseline alarms once the next diagnosis confirms it (since the first): a healthy
//! valve's diagnoses differ from window to window more than their intervals say.
//!
//! Not here: running the diagnosis or writing files ([`super`]).

use serde::Serialize;

use vb_core::human::{sig3, size_label};
use vb_core::model::composed::{Effect, Size};
use vb_core::vocabulary::{self, Advice};

/// One effect in a diagnosis: a finding (material) or a trace.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Entry {
    pub effect: Effect,
    /// Its plain name in the vocabulary (`lost motion (backlash)`).
    pub name: &'static str,
    /// A finding (worth maintenance), not a trace.
    pub finding: bool,
    pub size: Size,
}

impl Entry {
    /// `effect` of `size`, a finding or a trace.
    pub fn new(effect: Effect, finding: bool, size: Size) -> Entry {
        Entry {
            effect,
            name: vocabulary::words(effect).plain,
            finding,
            size,
        }
    }
}

/// One diagnosis, as a line of the history.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Record {
    /// Loop time at the end of the diagnosed window, s (from 0 at each run's start: a history
    /// appended to by several runs goes back to 0 where a run starts).
    pub t_s: f64,
    /// The window's end as UTC wall-clock time, ms (as the log's `utc` column).
    pub utc: String,
    /// The window's length, s.
    pub window_s: f64,
    /// What asked for it: `every_s` or `health alarm`.
    pub trigger: &'static str,
    /// The conclusion in words (as `diagnose` prints it).
    pub verdict: String,
    /// Diagnosed from a reference model (the valve's health baseline model, or the final model of
    /// its first whole window's diagnosis), so what it finds is what differs from that model;
    /// false for the first diagnoses of a valve without a health baseline model.
    pub compared: bool,
    /// This diagnosis is the reference: the valve's first of a whole window.
    pub reference: bool,
    /// Findings first, then traces.
    pub effects: Vec<Entry>,
    /// Each finding in the vocabulary's words, highest priority first.
    pub advice: Vec<Advice>,
    /// The alarms standing after this diagnosis, each naming its effect.
    pub alarms: Vec<String>,
    /// The effect of each standing alarm, in the same order.
    pub alarm_effects: Vec<Effect>,
    /// The full report, relative to the history's directory (none when reports are off or the
    /// diagnosis failed).
    pub report: Option<String>,
    /// Why the window could not be diagnosed (then nothing else is filled in).
    pub error: Option<String>,
}

/// The baseline of a valve and the alarms standing against it.
#[derive(Debug, Default)]
pub struct Baseline {
    /// The first diagnosis's effects (None until there is one).
    effects: Option<Vec<Entry>>,
    /// Each effect past the baseline, with the loop time since which it has been (in alarm
    /// once a second diagnosis in a row has confirmed it).
    since: Vec<(Effect, f64)>,
    /// The effects in alarm after the last diagnosis.
    alarmed: Vec<Effect>,
}

impl Baseline {
    /// A whole window's diagnosis has become the baseline.
    pub fn is_set(&self) -> bool {
        self.effects.is_some()
    }

    /// Compares the effects of the diagnosis at loop time `t_s` with the baseline (the first
    /// of a `whole` window makes them the baseline) and returns the standing alarms and those
    /// newly raised, each with its effect.
    pub fn compare(&mut self, t_s: f64, whole: bool, now: &[Entry]) -> (Alarms, Alarms) {
        let Some(base) = &self.effects else {
            if whole {
                self.effects = Some(now.to_vec());
            }
            return (Vec::new(), Vec::new());
        };
        let (mut standing, mut raised) = (Vec::new(), Vec::new());
        let mut since = Vec::new();
        for e in now.iter().filter(|e| e.finding) {
            let then = base.iter().find(|b| b.effect == e.effect);
            let left = match then {
                None => true,
                Some(b) => grew(&b.size, &e.size),
            };
            if !left {
                continue;
            }
            let old = (self.since.iter()).find(|(x, _)| *x == e.effect);
            since.push((e.effect, old.map_or(t_s, |&(_, s)| s)));
            // Seen once, it waits for the next diagnosis: a window's scatter is not an alarm.
            let Some(&(_, start)) = old else {
                continue;
            };
            let text = message(e, then, start);
            if !self.alarmed.contains(&e.effect) {
                raised.push((e.effect, text.clone()));
            }
            standing.push((e.effect, text));
        }
        self.since = since;
        self.alarmed = standing.iter().map(|a| a.0).collect();
        (standing, raised)
    }
}

/// Alarms, each with the effect it names.
pub type Alarms = Vec<(Effect, String)>;

/// `now` grew out of `then`: the same quantity, the intervals parted, towards worse, by a
/// change worth maintenance.
fn grew(then: &Size, now: &Size) -> bool {
    let parted = now.low > then.high || now.high < then.low;
    then.name == now.name && parted && now.worth - then.worth >= 1.0
}

/// `lost motion (backlash): friction band 0.40 % → 1.30 % since 1:32 h`, or for an effect the
/// baseline did not show, `lost motion (backlash): new, friction band 1.30 % (1.10-1.50) since
/// 1:32 h`.
fn message(e: &Entry, then: Option<&Entry>, since_s: f64) -> String {
    let (what, unit) = size_label(e.size.name);
    let since = clock(since_s);
    match then {
        Some(b) => format!(
            "{}: {what} {}{unit} → {}{unit} since {since}",
            e.name,
            sig3(b.size.value),
            sig3(e.size.value)
        ),
        None => format!("{}: new, {} since {since}", e.name, e.size.words()),
    }
}

/// Loop time as `h:mm h`.
fn clock(t_s: f64) -> String {
    let m = (t_s / 60.0).floor() as u64;
    format!("{}:{:02} h", m / 60, m % 60)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn band(value: f64, low: f64, high: f64, finding: bool) -> Entry {
        Entry::new(
            Effect::Backlash,
            finding,
            Size {
                name: "friction_band_pct",
                unit: "%",
                value,
                low,
                high,
                worth: value / 0.3,
                worth_low: low / 0.3,
            },
        )
    }

    #[test]
    fn a_band_that_leaves_its_interval_alarms_with_its_name_once() {
        let mut b = Baseline::default();
        assert_eq!(
            b.compare(1800.0, true, &[band(0.4, 0.3, 0.5, true)]),
            (vec![], vec![])
        );
        // Still overlapping: no alarm, though the value is past the baseline's interval.
        let (standing, _) = b.compare(3600.0, true, &[band(0.6, 0.45, 0.8, true)]);
        assert!(standing.is_empty(), "{standing:?}");
        // Past it once: waiting for the next diagnosis to confirm.
        let once = b.compare(5520.0, true, &[band(1.3, 1.1, 1.5, true)]);
        assert_eq!(once, (vec![], vec![]));
        let (standing, raised) = b.compare(7200.0, true, &[band(1.6, 1.4, 1.8, true)]);
        let text = "lost motion (backlash): friction band 0.40 % → 1.60 % since 1:32 h";
        let alarm = vec![(Effect::Backlash, text.to_string())];
        assert_eq!((standing, raised), (alarm.clone(), alarm));
        // Standing, not raised again, with its first time.
        let (standing, raised) = b.compare(7800.0, true, &[band(1.3, 1.1, 1.5, true)]);
        assert_eq!(
            standing,
            vec![(
                Effect::Backlash,
                "lost motion (backlash): friction band 0.40 % → 1.30 % since 1:32 h".to_string()
            )]
        );
        assert!(raised.is_empty());
        // Shrunk far below: no alarm, and the standing one clears.
        assert_eq!(
            b.compare(9000.0, true, &[band(0.1, 0.05, 0.15, true)]),
            (vec![], vec![])
        );
        // Parted, but by less than is worth maintenance (0.3 % of band): no alarm.
        for t in [9600.0, 10200.0] {
            let r = b.compare(t, true, &[band(0.65, 0.55, 0.75, true)]);
            assert_eq!(r, (vec![], vec![]));
        }
    }

    #[test]
    fn a_new_finding_alarms_and_traces_never_do() {
        let mut b = Baseline::default();
        // A part window (a health alarm before the first whole one) is no baseline.
        b.compare(600.0, false, &[band(1.3, 1.1, 1.5, true)]);
        b.compare(1800.0, true, &[]);
        let (standing, _) = b.compare(3600.0, true, &[band(5.0, 1.0, 9.0, false)]);
        assert!(standing.is_empty());
        // A finding in one window only (the scatter of a healthy valve) raises nothing.
        assert_eq!(
            b.compare(3660.0, true, &[band(1.3, 1.1, 1.5, true)]),
            (vec![], vec![])
        );
        assert_eq!(b.compare(3720.0, true, &[]), (vec![], vec![]));
        b.compare(3720.0, true, &[band(1.3, 1.1, 1.5, true)]);
        let (_, raised) = b.compare(3780.0, true, &[band(1.4, 1.1, 1.5, true)]);
        assert_eq!(
            raised,
            vec![(
                Effect::Backlash,
                "lost motion (backlash): new, friction band 1.40 % (1.10-1.50) since 1:02 h"
                    .to_string()
            )]
        );
    }
}
