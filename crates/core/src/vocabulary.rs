//! The words every output uses for an effect diagnosis names: one table ([`words`]) giving,
//! per effect of the vocabulary, its plain name, what it does to the valve in words with its
//! size and unit ([`does`]), what it does to control ([`Consequence`] and a sentence), and what
//! to do about it. The diagnosis report, the text `diagnose` prints, the fleet's page and rows
//! and the daemon's live page all word a finding through [`Advice::of`], so they say the same
//! thing.
//!
//! **Severity and priority.** A finding's priority is its size over what is worth maintenance
//! (its `worth`, 1 at the threshold) times the weight of its consequence for control
//! ([`Consequence::weight`]): 10 when it makes any loop with integral action cycle (stick-slip),
//! 3 when it makes an integrating loop cycle and delays every reversal (lost motion, a
//! deadband), 1 when it slows the loop or limits it (dead time, slow, uneven or
//! opening-dependent strokes, a minimum speed, a travel stop), 0.3 when only the position
//! reading is affected (its resolution, its calibration). Its severity is high from a priority
//! of 10, medium from 3, low below: a finding just worth maintenance has the severity of its
//! consequence, and a larger one climbs. A valve's priority is the sum over its findings.
//!
//! Not here: finding or sizing effects (`vb_analysis::diagnose`), or the modeller's figures (held-out
//! SSE, shares of the error), which stay in the reports' detail and the JSON.

use serde::{Deserialize, Serialize};

use crate::human::{interval_text, sig3};
use crate::model::composed::{Effect, Size};

/// What an effect does to the control loop, from worst to mildest.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Consequence {
    /// Any loop with integral action cycles around its set-point (a limit cycle).
    Cycles,
    /// An integrating loop (a level) cycles, and every reversal comes late.
    CyclesIntegrating,
    /// The loop is slowed or limited: it must be tuned slower, or loses control past a stop.
    Slows,
    /// Only the position reading is affected.
    Reading,
}

impl Consequence {
    /// Every consequence, worst first.
    pub const ALL: [Consequence; 4] = [
        Consequence::Cycles,
        Consequence::CyclesIntegrating,
        Consequence::Slows,
        Consequence::Reading,
    ];

    /// The weight of a finding's size in its priority.
    pub fn weight(self) -> f64 {
        match self {
            Consequence::Cycles => 10.0,
            Consequence::CyclesIntegrating => 3.0,
            Consequence::Slows => 1.0,
            Consequence::Reading => 0.3,
        }
    }

    /// The consequence in words, for the statement of the ranking rule.
    pub fn words(self) -> &'static str {
        match self {
            Consequence::Cycles => "makes any loop with integral action cycle",
            Consequence::CyclesIntegrating => {
                "makes an integrating loop cycle and delays every reversal"
            }
            Consequence::Slows => "slows or limits the loop",
            Consequence::Reading => "affects the position reading only",
        }
    }
}

/// How urgent a finding is, from its priority.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Severity {
    Low,
    Medium,
    High,
}

/// Priority from which a finding is of high severity.
pub const HIGH_FROM: f64 = 10.0;
/// Priority from which a finding is of medium severity.
pub const MEDIUM_FROM: f64 = 3.0;

impl Severity {
    /// The severity of a finding of `priority`.
    pub fn of(priority: f64) -> Severity {
        if priority >= HIGH_FROM {
            Severity::High
        } else if priority >= MEDIUM_FROM {
            Severity::Medium
        } else {
            Severity::Low
        }
    }

    /// `high`, `medium` or `low`.
    pub fn name(self) -> &'static str {
        match self {
            Severity::High => "high",
            Severity::Medium => "medium",
            Severity::Low => "low",
        }
    }
}

/// One effect of the vocabulary in words.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Words {
    /// What a maintenance planner calls it.
    pub plain: &'static str,
    pub consequence: Consequence,
    /// What it does to control.
    pub control: &'static str,
    /// What to do about it.
    pub action: &'static str,
}

/// The vocabulary's words for `effect`.
pub fn words(effect: Effect) -> Words {
    let e = |plain, consequence, control, action| Words {
        plain,
        consequence,
        control,
        action,
    };
    match effect {
        Effect::DeadTime => e(
            "slow to respond (dead time)",
            Consequence::Slows,
            "every correction comes late: the loop must be tuned slower, or it oscillates",
            "check the air supply pressure and the positioner's tuning; look for a sticking pilot relay or long, narrow air tubing",
        ),
        Effect::Backlash => e(
            "lost motion (backlash)",
            Consequence::CyclesIntegrating,
            "a level or other integrating loop cycles around its set-point, and every reversal of the controller comes late",
            "check the packing and the linkage (stem connector, positioner feedback arm) for play; tighten or replace worn parts",
        ),
        Effect::StateDependentDelay => e(
            "slower the more open (opening-dependent delay)",
            Consequence::Slows,
            "a loop tuned at one opening is sluggish or oscillates at another",
            "check the actuator's diaphragm and seals for leaks and the supply pressure; a volume booster may be needed",
        ),
        Effect::SlewRate => e(
            "slow stroke",
            Consequence::Slows,
            "large corrections take long: after a large upset the loop lags and its integral action winds up",
            "check the supply pressure, the pilot relay (or booster) and the air tubing for restrictions",
        ),
        Effect::Asymmetry => e(
            "uneven stroke speeds",
            Consequence::Slows,
            "the loop answers faster one way than the other: tuned for one direction, it overshoots or lags in the other",
            "check the exhaust (vent) path and the pilot relay, and the actuator's spring and diaphragm",
        ),
        Effect::MinSpeed => e(
            "creeps on small moves (minimum speed)",
            Consequence::Slows,
            "small corrections take as long as larger ones: the loop settles slowly near its set-point",
            "check the positioner's tuning (its gain and minimum output) and the pilot relay",
        ),
        Effect::Stiction => e(
            "stick-slip (stiction)",
            Consequence::Cycles,
            "the loop hunts: any loop with integral action cycles around its set-point (a limit cycle), wearing the valve",
            "check the packing (too tight, worn or dry) and the stem for damage; until it is repaired, widening the positioner's tolerance band can stop the hunting",
        ),
        Effect::Deadband => e(
            "deadband",
            Consequence::CyclesIntegrating,
            "small corrections are lost: an integrating loop cycles, and the process settles off its set-point",
            "narrow the positioner's tolerance band (dead band), then check the feedback linkage for play",
        ),
        Effect::Saturation => e(
            "travel stop",
            Consequence::Slows,
            "past the stop the loop has no more valve to use, and its integral action winds up",
            "check the travel stops, the positioner's travel limits and its end-position calibration",
        ),
        Effect::Quantization => e(
            "coarse position reading",
            Consequence::Reading,
            "the position read moves in steps; a controller or display using it jitters between them",
            "use a finer position reading (the transmitter's or the register's resolution)",
        ),
        Effect::Calibration => e(
            "position reading off (calibration)",
            Consequence::Reading,
            "the opening is misread: what relies on it (a cascade, feed-forward, flow from position) is off; the loop itself corrects the process",
            "recalibrate the position transmitter (zero and span)",
        ),
    }
}

/// The size's value in `unit` with its interval: `1.42 % (1.38-1.46)`, or the value alone
/// when no interval was computed.
fn sized(s: &Size, unit: &str) -> String {
    format!("{} {unit}{}", sig3(s.value), interval_text(s.low, s.high))
}

/// What an effect of size `s` does to the valve, in words with the size, its unit and its
/// interval: `loses 1.42 % (1.38-1.46) of travel on every reversal`.
pub fn does(s: &Size) -> String {
    let v = |unit: &str| sized(s, unit);
    match s.name {
        "dead_time_s" => format!("answers every move only after {}", v("s")),
        "friction_band_pct" => format!("loses {} of travel on every reversal", v("%")),
        "crossing_half_open_s" => {
            format!(
                "stands still for {} after every reversal at half travel",
                v("s")
            )
        }
        "open_vs_closed" => format!("moves {} slower fully open than closed", v("times")),
        "crossing_open_s" => format!(
            "stands still for {} after a reversal when fully open",
            v("s")
        ),
        "stroke_speed_pct_per_s" => format!(
            "strokes at only {} at half travel (a full stroke in about {:.0} s)",
            v("%/s"),
            100.0 / s.value.max(1e-9)
        ),
        "speed_ratio" => format!("moves {} faster one way than the other", v("times")),
        "min_speed_pct_per_s" => format!(
            "closes small errors at a constant {}, not in proportion to them",
            v("%/s")
        ),
        "slip_pct" => format!("sticks, then jumps by {} at a time", v("%")),
        "deadband_pct" => format!(
            "stops short of its set-point anywhere in a band of {}",
            v("%")
        ),
        "stop_pct" => format!("cannot travel past {}", v("%")),
        "lattice_pct" => format!("reports its position in steps of {}", v("%")),
        "reading_error_pct" => format!("reads its position {} away from where it is", v("%")),
        _ => format!("has a size of {}", v(s.unit)),
    }
}

/// A finding in the words of the vocabulary, as every output gives it: what is wrong, what it
/// does to the valve and to control, how sure, how urgent, what to do.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Advice {
    /// The vocabulary name (`backlash`), for scripts.
    pub effect: String,
    /// The plain name (`lost motion (backlash)`).
    pub name: String,
    /// What it does to the valve, with its size, interval and unit.
    pub does: String,
    /// How sure the recording is that it is worth maintenance.
    pub sure: String,
    /// What it does to control.
    pub control: String,
    /// What to do.
    pub action: String,
    pub severity: Severity,
    /// Its size over what is worth maintenance times its consequence's weight.
    pub priority: f64,
}

impl Advice {
    /// The advice for a finding of `effect` sized `size`.
    pub fn of(effect: Effect, size: &Size) -> Advice {
        let e = words(effect);
        let priority = e.consequence.weight() * size.worth.max(0.0);
        Advice {
            effect: effect.name().into(),
            name: e.plain.into(),
            does: does(size),
            sure: format!(
                "{} times what is worth maintenance, at least {} times on the recording's evidence (95 % of resamples of its held-out blocks)",
                sig3(size.worth),
                sig3(size.worth_low)
            ),
            control: e.control.into(),
            action: e.action.into(),
            severity: Severity::of(priority),
            priority,
        }
    }

    /// The advice in one paragraph: `High: lost motion (backlash) loses 1.42 % ... For control:
    /// .... To do: ....`
    pub fn sentence(&self) -> String {
        format!(
            "{}: {} {} ({}). For control: {}. To do: {}.",
            capitalised(self.severity.name()),
            self.name,
            self.does,
            self.sure,
            self.control,
            self.action
        )
    }

    /// What is wrong in a line: `lost motion (backlash): loses 1.42 % (1.38-1.46) of travel on
    /// every reversal`.
    pub fn headline(&self) -> String {
        format!("{}: {}", self.name, self.does)
    }
}

/// Every finding's advice, highest priority first.
pub fn advice<'a>(findings: impl IntoIterator<Item = (Effect, &'a Size)>) -> Vec<Advice> {
    let mut list: Vec<Advice> = (findings.into_iter())
        .map(|(e, s)| Advice::of(e, s))
        .collect();
    list.sort_by(|a, b| b.priority.total_cmp(&a.priority));
    list
}

/// A valve's priority (the sum over its findings) and severity (the highest of its findings';
/// none without a finding).
pub fn valve_priority(advice: &[Advice]) -> (f64, Option<Severity>) {
    // Folded from +0: an empty f64 sum is -0.
    let sum = advice.iter().fold(0.0, |sum, a| sum + a.priority);
    (sum, advice.iter().map(|a| a.severity).max())
}

/// The rule the ranking follows, in words (the fleet's page states it).
pub fn rule() -> String {
    let weights: Vec<String> = (Consequence::ALL.iter())
        .map(|c| {
            let effects: Vec<&str> = (Effect::ALL.iter())
                .filter(|&&e| words(e).consequence == *c)
                .map(|&e| words(e).plain)
                .collect();
            format!(
                "{} when it {} ({})",
                c.weight(),
                c.words(),
                effects.join(", ")
            )
        })
        .collect();
    format!(
        "Each finding's priority is its size over what is worth maintenance times what it does \
         to control: {}. A finding is of high severity from a priority of {HIGH_FROM}, medium \
         from {MEDIUM_FROM}, low below; a valve's priority is the sum over its findings, and \
         valves of equal priority are ordered by how far their figures lie beyond a healthy \
         valve's (attention).",
        weights.join("; ")
    )
}

/// `s` with its first letter in upper case.
pub fn capitalised(s: &str) -> String {
    let mut c = s.chars();
    c.next()
        .map_or(String::new(), |f| f.to_uppercase().chain(c).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every size an effect can be given in, with a value and an interval.
    fn sizes(effect: Effect) -> Vec<Size> {
        let names: &[(&'static str, &'static str)] = match effect {
            Effect::DeadTime => &[("dead_time_s", "s")],
            Effect::Backlash => &[("friction_band_pct", "%"), ("crossing_half_open_s", "s")],
            Effect::StateDependentDelay => &[("open_vs_closed", "times"), ("crossing_open_s", "s")],
            Effect::SlewRate => &[("stroke_speed_pct_per_s", "%/s")],
            Effect::Asymmetry => &[("speed_ratio", "times")],
            Effect::MinSpeed => &[("min_speed_pct_per_s", "%/s")],
            Effect::Stiction => &[("slip_pct", "%")],
            Effect::Deadband => &[("deadband_pct", "%")],
            Effect::Saturation => &[("stop_pct", "%")],
            Effect::Quantization => &[("lattice_pct", "%")],
            Effect::Calibration => &[("reading_error_pct", "%")],
        };
        (names.iter())
            .map(|&(name, unit)| Size {
                name,
                unit,
                value: 1.42,
                low: 1.17,
                high: 1.83,
                worth: 4.0,
                worth_low: 3.0,
            })
            .collect()
    }

    #[test]
    fn every_effect_is_worded_with_its_size_and_unit() {
        for effect in Effect::ALL {
            let e = words(effect);
            for s in sizes(effect) {
                let a = Advice::of(effect, &s);
                let text = a.sentence();
                assert!(
                    a.does.contains(&format!(" 1.42 {} (1.17-1.83)", s.unit)),
                    "{effect:?} {}: {}",
                    s.name,
                    a.does
                );
                assert!(text.contains(e.plain) && text.contains(e.control));
                assert!(text.contains(e.action), "{text}");
                assert!(!text.contains('_') && !text.contains("%²"), "{text}");
                assert!(!e.plain.contains('_') && !e.action.is_empty());
            }
        }
    }

    #[test]
    fn severity_climbs_with_the_size_and_the_consequence() {
        let size = |worth| Size {
            name: "slip_pct",
            unit: "%",
            value: 0.5,
            low: 0.4,
            high: 0.6,
            worth,
            worth_low: worth,
        };
        // Just worth maintenance: the consequence decides.
        assert_eq!(
            Advice::of(Effect::Stiction, &size(1.0)).severity,
            Severity::High
        );
        assert_eq!(
            Advice::of(Effect::Backlash, &size(1.0)).severity,
            Severity::Medium
        );
        assert_eq!(
            Advice::of(Effect::DeadTime, &size(1.0)).severity,
            Severity::Low
        );
        assert_eq!(
            Advice::of(Effect::Quantization, &size(1.0)).severity,
            Severity::Low
        );
        // Larger, it climbs: a band of four times what is worth maintenance, a dead time of ten.
        assert_eq!(
            Advice::of(Effect::Backlash, &size(4.0)).severity,
            Severity::High
        );
        assert_eq!(
            Advice::of(Effect::DeadTime, &size(10.0)).severity,
            Severity::High
        );
        let list = advice([
            (Effect::DeadTime, &size(5.0)),
            (Effect::Stiction, &size(1.0)),
        ]);
        assert_eq!(list[0].effect, "stiction");
        assert_eq!(valve_priority(&list), (15.0, Some(Severity::High)));
        assert_eq!(valve_priority(&[]), (0.0, None));
        let rule = rule();
        for c in Consequence::ALL {
            assert!(rule.contains(c.words()), "{rule}");
        }
        assert!(rule.contains("stick-slip (stiction)") && !rule.contains('_'));
    }
}
