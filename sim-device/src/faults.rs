//! Fault injection: which requests sim-device answers late, wrongly or not at all.
//!
//! Requests are numbered from 1 across the device's life (per connection for
//! `--disconnect-after`). The rules are deterministic (`every N`) or seeded (`drop-prob`), so a
//! test knows which requests fail. This module only decides; the servers carry the decision out.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;
use std::time::Duration;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// The fault options of the command line.
#[derive(Debug, Clone, Default)]
pub(crate) struct FaultConfig {
    /// Extra delay before a response (every one, or those of `delay_every`).
    pub delay: Duration,
    /// Delay only the responses to requests whose number is a multiple of this.
    pub delay_every: Option<u64>,
    /// Answer no request whose number is a multiple of this.
    pub drop_every: Option<u64>,
    /// Answer no request with this probability.
    pub drop_prob: f64,
    /// Send a wrong CRC for requests whose number is a multiple of this (RTU only).
    pub corrupt_crc_every: Option<u64>,
    /// Answer exception 04 (server device failure) to requests whose number is a multiple of this.
    pub exception_every: Option<u64>,
    /// Answer with one byte too many (a read's byte count off by one) to requests whose number
    /// is a multiple of this.
    pub bad_byte_count_every: Option<u64>,
    /// Answer with an MBAP length of 0 (TCP only) to requests whose number is a multiple of this.
    pub broken_frame_every: Option<u64>,
    /// Close a TCP connection on its N-th request, unanswered.
    pub disconnect_after: Option<u64>,
    /// Seed of `drop_prob`.
    pub seed: u64,
}

/// The fate of one request: what to answer, and how late.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Decision {
    /// What to answer.
    pub action: Action,
    /// Extra delay before answering.
    pub delay: Duration,
}

/// What to do with one request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Action {
    /// Answer normally.
    Answer,
    /// Send nothing.
    Drop,
    /// Answer exception 04.
    Exception,
    /// Answer with a corrupted CRC.
    CorruptCrc,
    /// Answer with one byte too many.
    BadByteCount,
    /// Answer with an MBAP length of 0.
    BrokenFrame,
}

/// The shared fault state of one device.
#[derive(Debug)]
pub(crate) struct Faults {
    cfg: FaultConfig,
    count: AtomicU64,
    rng: Mutex<ChaCha8Rng>,
}

fn hits(every: Option<u64>, n: u64) -> bool {
    matches!(every, Some(e) if e > 0 && n.is_multiple_of(e))
}

impl Faults {
    /// Fault state for `cfg`, no request seen yet.
    pub(crate) fn new(cfg: FaultConfig) -> Self {
        let rng = Mutex::new(ChaCha8Rng::seed_from_u64(cfg.seed));
        Faults {
            cfg,
            count: AtomicU64::new(0),
            rng,
        }
    }

    /// The request count after which a TCP connection is closed.
    pub(crate) fn disconnect_after(&self) -> Option<u64> {
        self.cfg.disconnect_after
    }

    /// Numbers the next request and decides its fate.
    pub(crate) fn next(&self) -> Decision {
        let n = self.count.fetch_add(1, Ordering::Relaxed) + 1;
        let late = self.cfg.delay_every.is_none() || hits(self.cfg.delay_every, n);
        Decision {
            action: self.action(n),
            delay: if late { self.cfg.delay } else { Duration::ZERO },
        }
    }

    /// The answer to request `n`.
    fn action(&self, n: u64) -> Action {
        let random_drop = self.cfg.drop_prob > 0.0
            && self
                .rng
                .lock()
                .unwrap_or_else(|p| p.into_inner())
                .gen_bool(self.cfg.drop_prob.min(1.0));
        if hits(self.cfg.drop_every, n) || random_drop {
            Action::Drop
        } else if hits(self.cfg.exception_every, n) {
            Action::Exception
        } else if hits(self.cfg.corrupt_crc_every, n) {
            Action::CorruptCrc
        } else if hits(self.cfg.bad_byte_count_every, n) {
            Action::BadByteCount
        } else if hits(self.cfg.broken_frame_every, n) {
            Action::BrokenFrame
        } else {
            Action::Answer
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn delays_apply_to_every_or_every_nth_request() {
        let ms = Duration::from_millis(15);
        let f = Faults::new(FaultConfig {
            delay: ms,
            delay_every: Some(3),
            ..FaultConfig::default()
        });
        let got: Vec<Duration> = (0..6).map(|_| f.next().delay).collect();
        let z = Duration::ZERO;
        assert_eq!(got, vec![z, z, ms, z, z, ms]);
        let f = Faults::new(FaultConfig {
            delay: ms,
            ..FaultConfig::default()
        });
        assert!((0..3).all(|_| f.next().delay == ms));
    }

    #[test]
    fn every_n_rules_and_precedence() {
        let f = Faults::new(FaultConfig {
            drop_every: Some(3),
            exception_every: Some(2),
            corrupt_crc_every: Some(5),
            ..FaultConfig::default()
        });
        let got: Vec<Action> = (0..6).map(|_| f.next().action).collect();
        use Action::*;
        assert_eq!(
            got,
            vec![Answer, Exception, Drop, Exception, CorruptCrc, Drop]
        );
    }

    #[test]
    fn drop_probability_is_seeded() {
        let run = |seed| {
            let f = Faults::new(FaultConfig {
                drop_prob: 0.25,
                seed,
                ..FaultConfig::default()
            });
            (0..4000).map(|_| f.next().action).collect::<Vec<_>>()
        };
        let a = run(7);
        assert_eq!(a, run(7));
        let drops = a.iter().filter(|x| **x == Action::Drop).count();
        assert!((900..1100).contains(&drops), "{drops}");
    }
}
