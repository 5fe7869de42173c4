//! A response test's plan: the openings, the step sizes and the pattern each size is stepped in,
//! how long a step is held, and the signature's ramp; read from TOML (`config/response-plans/`,
//! embedded as `standard` and `quick`) and checked against the source's range, so the test never
//! sends an O_P outside `op_min_pct..op_max_pct`. [`Plan::moves`] lays it out as the sequence of
//! holds and ramps the [`super::Schedule`] walks and the analysis reads the log by.
//!
//! Not here: when a hold ends (the schedule decides on the run), measuring anything.

mod schedule;

pub use schedule::Schedule;

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::recording::log_format::round_pct;
use crate::toml_file::{self, Layout, TomlError};

/// The standard plan, `config/response-plans/standard.toml`.
pub const STANDARD: &str = include_str!("../../../../config/response-plans/standard.toml");
/// The quick plan, `config/response-plans/quick.toml`.
pub const QUICK: &str = include_str!("../../../../config/response-plans/quick.toml");

/// A response test's plan, as its TOML file holds it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Plan {
    /// The openings the steps are taken around, %, in order.
    pub openings_pct: Vec<f64>,
    /// The step sizes, %.
    pub sizes_pct: Vec<f64>,
    /// The steps taken at each size, in multiples of it (+ opens); the level moves by each in
    /// turn.
    pub pattern: Vec<i32>,
    /// How long a step is held.
    pub hold: HoldRule,
    /// The slow ramp out and back, if any.
    pub signature: Option<SignaturePlan>,
}

/// How long a step is held: at least `min_s`, at most `max_s`, and in between until V_P is
/// still (the mean over `still_s` moved less than `still_pct`, or than its noise explains,
/// from the mean over the `still_s` before).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HoldRule {
    /// Shortest hold, s.
    pub min_s: f64,
    /// Longest hold, s.
    pub max_s: f64,
    /// The time over which V_P is averaged to judge it still, s.
    pub still_s: f64,
    /// The most the mean of V_P may move between two such times, %.
    pub still_pct: f64,
}

/// The signature: from `opening_pct` a ramp at `rate_pct_per_s` out to opening + span, down to
/// opening - span and back to the opening.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SignaturePlan {
    /// Where the ramp starts and ends, %.
    pub opening_pct: f64,
    /// How far it goes either way, %.
    pub span_pct: f64,
    /// Its speed, %/s.
    pub rate_pct_per_s: f64,
}

/// One move of a plan, in the order the test makes them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Move {
    /// O_P jumps to `op_pct` and is held; `step` says which planned step it is (`None` for an
    /// approach to an opening).
    Hold { op_pct: f64, step: Option<Step> },
    /// O_P moves from where it is to `to_pct` at `rate_pct_per_s`.
    Ramp { to_pct: f64, rate_pct_per_s: f64 },
}

/// A planned step: its size (%, positive), its multiple in the pattern (signed) and the opening
/// it is taken around.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Step {
    pub opening_pct: f64,
    pub size_pct: f64,
    pub multiple: i32,
}

impl Plan {
    /// The plan `name`: `standard`, `quick` or a TOML file; checked, with every level it
    /// visits inside `range` (the source's `op_min_pct..op_max_pct`).
    pub fn load(name: &str, range: (f64, f64)) -> Result<Plan, TomlError> {
        let (text, label) = match name {
            "standard" => (
                STANDARD.to_string(),
                "config/response-plans/standard.toml (embedded)",
            ),
            "quick" => (
                QUICK.to_string(),
                "config/response-plans/quick.toml (embedded)",
            ),
            file => {
                let text = std::fs::read_to_string(file).map_err(|source| TomlError::Read {
                    path: file.into(),
                    source,
                })?;
                return Plan::from_toml(&text, Path::new(file), range);
            }
        };
        Plan::from_toml(&text, Path::new(label), range)
    }

    /// Parses and checks a plan's TOML `text` (`path` names it in messages).
    pub fn from_toml(text: &str, path: &Path, range: (f64, f64)) -> Result<Plan, TomlError> {
        let plan: Plan = toml_file::parse(text, path)?;
        let layout = Layout::parse(text);
        let bad = |table: Option<&str>, key: &str, message: String| {
            toml_file::invalid(layout.lines(), path, table, key, message)
        };
        plan.check_values(&bad)?;
        plan.check_range(range, &bad)?;
        Ok(plan)
    }

    /// Every key's own check.
    fn check_values(&self, bad: &Bad<'_>) -> Result<(), TomlError> {
        let positive = |table, key, v: f64, hi: f64, what: &str| {
            if v.is_finite() && v > 0.0 && v <= hi {
                Ok(())
            } else {
                Err(bad(
                    table,
                    key,
                    format!("{v} is out of range: {what}, above 0 and at most {hi}"),
                ))
            }
        };
        if self.openings_pct.is_empty() && self.signature.is_none() {
            return Err(bad(
                None,
                "openings_pct",
                "the plan has no opening and no [signature]: give at least one".into(),
            ));
        }
        if !self.openings_pct.is_empty() && (self.sizes_pct.is_empty() || self.pattern.is_empty()) {
            return Err(bad(None, "sizes_pct", "steps need at least one size and a pattern, e.g. sizes_pct = [1.0], pattern = [1, -1]".into()));
        }
        for &s in &self.sizes_pct {
            positive(None, "sizes_pct", s, 50.0, "a step size in %")?;
        }
        if self.pattern.iter().any(|&m| m == 0 || m.abs() > 10) {
            return Err(bad(
                None,
                "pattern",
                "multiples of the size from -10 to 10, none 0 (e.g. [1, 1, -1, -1])".into(),
            ));
        }
        let h = &self.hold;
        positive(Some("hold"), "min_s", h.min_s, 3600.0, "a hold in s")?;
        positive(Some("hold"), "max_s", h.max_s, 3600.0, "a hold in s")?;
        positive(
            Some("hold"),
            "still_s",
            h.still_s,
            h.min_s / 2.0,
            "a time in s, at most half of min_s (two of them judge a hold)",
        )?;
        positive(
            Some("hold"),
            "still_pct",
            h.still_pct,
            10.0,
            "a move of V_P in %",
        )?;
        if h.max_s < h.min_s {
            return Err(bad(
                Some("hold"),
                "max_s",
                format!("{} s is shorter than min_s = {} s", h.max_s, h.min_s),
            ));
        }
        if let Some(s) = &self.signature {
            positive(
                Some("signature"),
                "span_pct",
                s.span_pct,
                50.0,
                "a ramp's reach in %",
            )?;
            positive(
                Some("signature"),
                "rate_pct_per_s",
                s.rate_pct_per_s,
                100.0,
                "a ramp's speed in %/s",
            )?;
        }
        Ok(())
    }

    /// Every level the plan visits lies inside `range`; the first one outside names the key
    /// that sends it there.
    fn check_range(&self, (lo, hi): (f64, f64), bad: &Bad<'_>) -> Result<(), TomlError> {
        let outside = |v: f64| !(lo..=hi).contains(&round_pct(v));
        let fix = "the test never leaves the valve's range: lower it or the largest size, or widen [source] op_min_pct..op_max_pct in the config";
        for &o in &self.openings_pct {
            if outside(o) {
                return Err(bad(
                    None,
                    "openings_pct",
                    format!("{o} % lies outside [source] op_min_pct..op_max_pct = {lo}..{hi} %"),
                ));
            }
            for &s in &self.sizes_pct {
                let mut level = o;
                for &m in &self.pattern {
                    level += f64::from(m) * s;
                    if outside(level) {
                        return Err(bad(
                            None,
                            "sizes_pct",
                            format!(
                                "steps of {s} % at {o} % reach {} %, outside {lo}..{hi} %: {fix}",
                                round_pct(level)
                            ),
                        ));
                    }
                }
            }
        }
        if let Some(sig) = &self.signature {
            let (a, b) = (
                sig.opening_pct - sig.span_pct,
                sig.opening_pct + sig.span_pct,
            );
            if outside(a) || outside(b) {
                return Err(bad(
                    Some("signature"),
                    "span_pct",
                    format!(
                        "the ramp from {} % reaches {} to {} %, outside {lo}..{hi} %: {fix}",
                        sig.opening_pct,
                        round_pct(a),
                        round_pct(b)
                    ),
                ));
            }
        }
        Ok(())
    }

    /// The moves of the test in order: for each opening an approach and its steps, then the
    /// signature's approach and its three ramps. Levels are rounded as the log writes them.
    pub fn moves(&self) -> Vec<Move> {
        let mut out = Vec::new();
        for &o in &self.openings_pct {
            out.push(Move::Hold {
                op_pct: round_pct(o),
                step: None,
            });
            for &size_pct in &self.sizes_pct {
                let mut at = 0;
                for &multiple in &self.pattern {
                    at += multiple;
                    out.push(Move::Hold {
                        op_pct: round_pct(o + f64::from(at) * size_pct),
                        step: Some(Step {
                            opening_pct: o,
                            size_pct,
                            multiple,
                        }),
                    });
                }
            }
        }
        if let Some(s) = &self.signature {
            let rate_pct_per_s = s.rate_pct_per_s;
            out.push(Move::Hold {
                op_pct: round_pct(s.opening_pct),
                step: None,
            });
            for to in [s.span_pct, -s.span_pct, 0.0] {
                out.push(Move::Ramp {
                    to_pct: round_pct(s.opening_pct + to),
                    rate_pct_per_s,
                });
            }
        }
        out
    }

    /// The largest step the plan makes, % (0 without steps).
    pub fn largest_step_pct(&self) -> f64 {
        let m = self
            .pattern
            .iter()
            .map(|m| m.unsigned_abs())
            .max()
            .unwrap_or(0);
        let s = self.sizes_pct.iter().copied().fold(0.0, f64::max);
        f64::from(m) * s
    }
}

/// An error about `table.key` of the plan, at its line.
type Bad<'a> = dyn Fn(Option<&str>, &str, String) -> TomlError + 'a;

#[cfg(test)]
mod tests {
    use super::*;

    fn err(text: &str, range: (f64, f64)) -> String {
        Plan::from_toml(text, Path::new("p.toml"), range)
            .unwrap_err()
            .to_string()
    }

    const SMALL: &str = "openings_pct = [50.0]\nsizes_pct = [1.0, 5.0]\npattern = [1, 1, -1, -1]\n\
        [hold]\nmin_s = 5.0\nmax_s = 30.0\nstill_s = 1.0\nstill_pct = 0.05\n\
        [signature]\nopening_pct = 50.0\nspan_pct = 2.0\nrate_pct_per_s = 0.5\n";

    #[test]
    fn the_shipped_plans_load_and_lay_out_their_moves() {
        let standard = Plan::load("standard", (0.0, 100.0)).unwrap();
        let moves = standard.moves();
        let steps = moves
            .iter()
            .filter(|m| matches!(m, Move::Hold { step: Some(_), .. }))
            .count();
        assert_eq!(steps, 3 * 6 * 4);
        assert_eq!(moves.len(), 3 + 72 + 1 + 3);
        assert_eq!(standard.largest_step_pct(), 10.0);
        let quick = Plan::load("quick", (0.0, 100.0)).unwrap();
        assert_eq!(quick.openings_pct, [50.0]);
        assert_eq!(quick.sizes_pct, standard.sizes_pct);
        for (name, text) in [("standard", STANDARD), ("quick", QUICK)] {
            let file = format!(
                "{}/config/response-plans/{name}.toml",
                concat!(env!("CARGO_MANIFEST_DIR"), "/../..")
            );
            assert_eq!(std::fs::read_to_string(file).unwrap(), text);
        }
    }

    #[test]
    fn moves_step_up_twice_back_twice_and_ramp_out_and_back() {
        let p = Plan::from_toml(SMALL, Path::new("p.toml"), (0.0, 100.0)).unwrap();
        let levels: Vec<f64> = p
            .moves()
            .iter()
            .map(|m| match m {
                Move::Hold { op_pct, .. } => *op_pct,
                Move::Ramp { to_pct, .. } => *to_pct,
            })
            .collect();
        assert_eq!(
            levels,
            [50.0, 51.0, 52.0, 51.0, 50.0, 55.0, 60.0, 55.0, 50.0, 50.0, 52.0, 48.0, 50.0]
        );
        match p.moves()[6] {
            Move::Hold { step: Some(s), .. } => {
                assert_eq!((s.size_pct, s.multiple, s.opening_pct), (5.0, 1, 50.0))
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_plan_that_would_leave_the_range_is_refused_at_its_key() {
        let e = err(SMALL, (0.0, 58.0));
        assert!(
            e.starts_with("p.toml:2: sizes_pct: steps of 5 % at 50 % reach 60 %, outside 0..58 %"),
            "{e}"
        );
        assert!(e.contains("widen [source] op_min_pct..op_max_pct"), "{e}");
        let e = err(SMALL, (49.0, 100.0));
        assert!(
            e.starts_with("p.toml:11: signature.span_pct: the ramp from 50 % reaches 48 to 52 %"),
            "{e}"
        );
        let e = err(SMALL, (55.0, 100.0));
        assert!(
            e.starts_with("p.toml:1: openings_pct: 50 % lies outside"),
            "{e}"
        );
    }

    #[test]
    fn bad_values_name_their_key() {
        let e = err(&SMALL.replace("max_s = 30.0", "max_s = 3.0"), (0.0, 100.0));
        assert!(
            e.starts_with("p.toml:6: hold.max_s: 3 s is shorter than min_s = 5 s"),
            "{e}"
        );
        let e = err(&SMALL.replace("[1, 1, -1, -1]", "[1, 0]"), (0.0, 100.0));
        assert!(e.starts_with("p.toml:3: pattern:"), "{e}");
        let e = err(
            &SMALL.replace("still_s = 1.0", "still_s = 3.0"),
            (0.0, 100.0),
        );
        assert!(e.contains("hold.still_s: 3 is out of range"), "{e}");
        let e = err(
            &SMALL.replace("sizes_pct = [1.0, 5.0]", "sizes_pct = [-1.0]"),
            (0.0, 100.0),
        );
        assert!(
            e.starts_with("p.toml:2: sizes_pct: -1 is out of range"),
            "{e}"
        );
        let e = err("openings_pct = [50.0]\n", (0.0, 100.0));
        assert!(e.contains("missing field"), "{e}");
    }
}
