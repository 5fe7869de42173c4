//! Sources of the wanted opening O_P: random steps, steps, ramp, sine, PRBS, replay, constant,
//! and a process controller writing over Modbus (`modbus-server`, see [`crate::serve::hil`]).
//!
//! A [`Source`] is asked `op_at(t_s)` once per cycle with non-decreasing loop times and answers
//! the clamped O_P, or `None` when it has nothing more to give (only a replay ends). Random
//! sources are seeded (ChaCha8) and depend on the time only, not on how often they are asked, so a
//! skipped cycle does not change what later cycles get. Asking never allocates.
//!
//! A source is built from a checked [`SourceConfig`], whose [`SourceSpec`] holds the settings of
//! its kind only. The generators themselves live in [`vb_core::signal`] (offline generation uses
//! them too); a source adds the clamp to `[source]`'s range. Generated sources do not know about valves or
//! timing.
//! Two sources see each cycle's row ([`Source::feedback`]): the `modbus-server` source publishes
//! V_P to the controller (its set-points were range-checked when written; its safe O_P, like the
//! stop action's, is not clamped), and a response test's [`Schedule`] ends a step's hold once V_P
//! has settled.

use std::sync::Arc;

use crate::config::{SafetyConfig, SourceConfig, SourceSpec};
use crate::serve::hil::Controller;
use vb_core::recording::log_format::Sample;
use vb_core::response_plan::Schedule;
use vb_core::signal::{Prbs, RandomSteps, Signal};
use vb_modbus::server::RegisterBank;

/// An O_P source with its clamp range.
#[derive(Debug)]
pub struct Source {
    kind: Kind,
    min_pct: f64,
    max_pct: f64,
}

#[derive(Debug)]
enum Kind {
    /// A time-only generator of [`vb_core::signal`] (boxed once: its random generator is large).
    Generated(Box<Signal>),
    Controller(Controller),
    /// A response test's plan, walked as V_P settles.
    Plan(Box<Schedule>),
}

impl Source {
    /// The source `[source]` describes, for a loop of period `period_s` (`[safety]` gives the
    /// safe O_P of the controller's watchdog).
    pub fn new(cfg: &SourceConfig, safety: &SafetyConfig, period_s: f64) -> Source {
        let generated = |signal| Kind::Generated(Box::new(signal));
        let kind = match &cfg.spec {
            SourceSpec::RandomSteps(p) => generated(Signal::RandomSteps(RandomSteps::new(p))),
            SourceSpec::Steps(p) => generated(Signal::Steps(p.clone())),
            SourceSpec::Ramp(p) => generated(Signal::Ramp(p.clone())),
            SourceSpec::Sine(p) => generated(Signal::Sine(p.clone())),
            SourceSpec::Prbs(p) => generated(Signal::Prbs(Prbs::new(p))),
            SourceSpec::Replay(r) => generated(Signal::Replay {
                op: r.op_pct.clone(),
                period_s,
            }),
            SourceSpec::Constant(p) => generated(Signal::Constant(p.op_pct)),
            SourceSpec::ModbusServer(server) => {
                Kind::Controller(Controller::new(server, cfg.op_range(), safety))
            }
            SourceSpec::ResponseTest(plan) => Kind::Plan(Box::new(Schedule::new(plan, period_s))),
        };
        Source {
            kind,
            min_pct: cfg.op_min_pct,
            max_pct: cfg.op_max_pct,
        }
    }

    /// The same source for the valve `name` (a controller names it in its messages).
    pub fn named(self, name: &str) -> Source {
        match self.kind {
            Kind::Controller(c) => Source {
                kind: Kind::Controller(c.named(name)),
                ..self
            },
            _ => self,
        }
    }

    /// The O_P at loop time `t_s` (s from the first cycle), clamped; `None` once a replay or a
    /// response test is over.
    pub fn op_at(&mut self, t_s: f64) -> Option<f64> {
        let raw = match &mut self.kind {
            Kind::Generated(g) => g.op_at(t_s)?,
            Kind::Controller(c) => return Some(c.op_at(t_s)),
            Kind::Plan(p) => p.op_at(t_s)?,
        };
        Some(raw.clamp(self.min_pct, self.max_pct))
    }

    /// The register bank a process controller writes into (`modbus-server` only).
    pub fn served_bank(&self) -> Option<&Arc<RegisterBank>> {
        match &self.kind {
            Kind::Controller(c) => Some(c.bank()),
            _ => None,
        }
    }

    /// True while the controller's watchdog holds the safe O_P (`modbus-server` only).
    pub fn watchdog_tripped(&self) -> bool {
        matches!(&self.kind, Kind::Controller(c) if c.tripped())
    }

    /// How often the controller's watchdog has fired (0 for other sources).
    pub fn watchdog_trips(&self) -> u64 {
        match &self.kind {
            Kind::Controller(c) => c.trips(),
            _ => 0,
        }
    }

    /// Hands a cycle's row to the source (the controller publishes its V_P and status, a
    /// response test judges whether the valve has settled).
    pub fn feedback(&mut self, row: &Sample) {
        match &mut self.kind {
            Kind::Controller(c) => c.feedback(row),
            Kind::Plan(p) => p.feedback(row),
            Kind::Generated(_) => {}
        }
    }

    /// A response test's moves done and in all (`None` for other sources).
    pub fn progress(&self) -> Option<(usize, usize)> {
        match &self.kind {
            Kind::Plan(p) => Some(p.progress()),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Config;
    use std::path::Path;

    fn source(toml: &str) -> Source {
        let cfg = Config::from_toml(toml, Path::new("t.toml")).unwrap();
        Source::new(&cfg.source, &cfg.safety, cfg.loop_.period_s())
    }

    fn series(s: &mut Source, n: usize) -> Vec<f64> {
        (0..n).map(|k| s.op_at(k as f64 / 100.0).unwrap()).collect()
    }

    #[test]
    fn random_steps_are_seeded_in_range_and_hold() {
        let toml = "[source.random-steps]\nseed = 7\n";
        let a = series(&mut source(toml), 60_000);
        let b = series(&mut source(toml), 60_000);
        assert_eq!(a, b);
        assert!(a.iter().all(|v| (20.0..=97.0).contains(v)));
        let changes = a.windows(2).filter(|w| w[0] != w[1]).count();
        // 600 s with holds averaging 10 s: about 60 steps.
        assert!((30..=100).contains(&changes), "{changes}");
        let c = series(&mut source("[source.random-steps]\nseed = 8\n"), 60_000);
        assert_ne!(a, c);
    }

    #[test]
    fn steps_ramp_sine_constant_follow_their_definitions() {
        let mut s = source(
            "[source]\nkind = \"steps\"\n[source.steps]\nlevels_pct = [10.0, 20.0]\nhold_s = 0.1\n",
        );
        let v = series(&mut s, 40);
        assert_eq!(&v[..10], &[10.0; 10]);
        assert_eq!(&v[10..20], &[20.0; 10]);
        assert_eq!(&v[20..30], &[10.0; 10]);

        let mut s = source("[source]\nkind = \"ramp\"\n[source.ramp]\nfrom_pct = 0.0\nto_pct = 50.0\nduration_s = 1.0\nrepeat = true\n");
        assert!((s.op_at(0.5).unwrap() - 25.0).abs() < 1e-9);
        assert!((s.op_at(1.5).unwrap() - 25.0).abs() < 1e-9);
        assert!((s.op_at(2.0).unwrap() - 0.0).abs() < 1e-9);

        let mut s = source("[source]\nkind = \"sine\"\n[source.sine]\nmean_pct = 50.0\namplitude_pct = 10.0\nperiod_s = 4.0\n");
        assert!((s.op_at(1.0).unwrap() - 60.0).abs() < 1e-9);
        assert!((s.op_at(3.0).unwrap() - 40.0).abs() < 1e-9);

        let mut s = source(
            "[source]\nkind = \"constant\"\nop_max_pct = 40.0\n[source.constant]\nop_pct = 55.0\n",
        );
        assert_eq!(s.op_at(0.0), Some(40.0), "clamped to op_max_pct");
    }

    #[test]
    fn prbs_has_two_levels_on_its_bit_clock() {
        let mut s = source("[source]\nkind = \"prbs\"\n[source.prbs]\nmean_pct = 50.0\namplitude_pct = 5.0\nband_hz = 5.0\n");
        let v = series(&mut s, 2000);
        assert!(v.iter().all(|&x| x == 45.0 || x == 55.0));
        // Bits last 1/(2*5) s = 10 cycles: levels change only on multiples of 10.
        for (k, w) in v.windows(2).enumerate() {
            if w[0] != w[1] {
                assert_eq!((k + 1) % 10, 0, "change at cycle {}", k + 1);
            }
        }
        assert!(v.windows(2).filter(|w| w[0] != w[1]).count() > 50);
        // Skipping cycles does not change the sequence.
        let mut t = source("[source]\nkind = \"prbs\"\n[source.prbs]\nmean_pct = 50.0\namplitude_pct = 5.0\nband_hz = 5.0\n");
        assert_eq!(t.op_at(13.37), Some(v[1337]));
    }

    #[test]
    fn replay_holds_each_sample_and_ends_with_the_recording() {
        let dir = tempfile::tempdir().unwrap();
        let rec = dir.path().join("rec.csv");
        // A 1 Hz recording with absolute times and no V_P cells where the loop failed.
        std::fs::write(&rec, "t_s,op_pct,vp_pct\n100,10,\n101,20,19\n102,30,\n").unwrap();
        let toml = format!(
            "[loop]\nrate_hz = 4.0\n[source]\nkind = \"replay\"\nop_max_pct = 25.0\n[source.replay]\nfile = {:?}\n",
            rec.display().to_string()
        );
        let mut s = source(&toml);
        let got: Vec<Option<f64>> = (0..11).map(|k| s.op_at(k as f64 * 0.25)).collect();
        let mut want = vec![Some(10.0); 4];
        want.extend([Some(20.0); 4]);
        want.push(Some(25.0)); // clamped to op_max_pct
        want.extend([None, None]);
        assert_eq!(got, want);
    }

    #[test]
    fn replay_of_a_missing_file_names_the_key() {
        let e = Config::from_toml(
            "[source]\nkind = \"replay\"\n[source.replay]\nfile = \"nope.csv\"\n",
            Path::new("t.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.starts_with("t.toml:4: source.replay.file: cannot replay `nope.csv`"),
            "{e}"
        );
    }
}
