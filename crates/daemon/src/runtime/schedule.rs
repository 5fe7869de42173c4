//! The loop's schedule: an absolute grid of deadlines `t0 + k * period`, on a real or virtual clock.
//!
//! On the real clock each slot waits until its deadline by sleeping to `deadline - spin` and then
//! busy-waiting the rest (a plain sleep overshoots by the timer slack and the wake-up latency,
//! tens to hundreds of µs; `tokio::time::interval` rounds to 1 ms). Deadlines are computed from
//! the slot number, never from the previous wake-up, so errors never accumulate. A slot that
//! cannot start within half a period of its deadline (the previous cycle overran) is returned as
//! [`Slot::Skipped`]: the schedule stays on its grid, runs no catch-up burst, and the caller logs
//! each skipped slot. On the virtual clock slots follow each other immediately, on time.
//!
//! This module only decides when; it knows nothing of valves, sources or logs.

use std::time::{Duration, Instant, SystemTime};

/// One slot of the grid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Slot {
    /// Run the cycle of slot `k` now; it started `lateness` after its deadline.
    Run { k: u64, lateness: Duration },
    /// Slot `k` was missed (its cycle would start more than half a period late).
    Skipped { k: u64 },
}

impl Slot {
    /// The slot number.
    pub fn k(&self) -> u64 {
        match *self {
            Slot::Run { k, .. } | Slot::Skipped { k } => k,
        }
    }
}

/// Which clock the schedule follows.
#[derive(Debug, Clone, Copy)]
enum Clock {
    /// The monotonic wall clock, grid origin `t0`.
    Real { t0: Instant, spin: Duration },
    /// No waiting: every slot is on time.
    Virtual,
}

/// The grid of deadlines and the number of the next slot.
#[derive(Debug)]
pub struct Schedule {
    period_ns: u64,
    next_k: u64,
    clock: Clock,
    /// Wall-clock time of slot 0.
    wall0: SystemTime,
}

impl Schedule {
    /// A real-clock grid whose slot 0 is one period from now; `spin` is the busy-wait margin.
    pub fn real(period: Duration, spin: Duration) -> Self {
        Schedule {
            period_ns: period.as_nanos() as u64,
            next_k: 0,
            clock: Clock::Real {
                t0: Instant::now() + period,
                spin,
            },
            wall0: SystemTime::now() + period,
        }
    }

    /// A virtual-clock grid: slots follow each other without waiting.
    pub fn virtual_clock(period: Duration) -> Self {
        Schedule {
            period_ns: period.as_nanos() as u64,
            next_k: 0,
            clock: Clock::Virtual,
            wall0: SystemTime::now(),
        }
    }

    /// The scheduled time of slot `k`, seconds from slot 0.
    pub fn t_s(&self, k: u64) -> f64 {
        // Integer nanoseconds, then one division: k/100 at 100 Hz is the correctly rounded value.
        (k as f64 * self.period_ns as f64) / 1e9
    }

    /// The scheduled time of slot `k` as wall-clock time: the wall clock read when the grid
    /// was laid, plus `k` periods (so it never jumps when the system clock is set).
    pub fn wall(&self, k: u64) -> SystemTime {
        self.wall0 + Duration::from_nanos(k.saturating_mul(self.period_ns))
    }

    /// Waits for the next slot (real clock) and returns it, or reports it as skipped.
    pub fn next_slot(&mut self) -> Slot {
        let k = self.next_k;
        self.next_k += 1;
        let Clock::Real { t0, spin } = self.clock else {
            return Slot::Run {
                k,
                lateness: Duration::ZERO,
            };
        };
        let deadline = t0 + Duration::from_nanos(k * self.period_ns);
        let now = Instant::now();
        if now > deadline + Duration::from_nanos(self.period_ns / 2) {
            return Slot::Skipped { k };
        }
        if let Some(rest) = deadline.checked_duration_since(now + spin) {
            std::thread::sleep(rest);
        }
        let mut now = Instant::now();
        while now < deadline {
            std::hint::spin_loop();
            now = Instant::now();
        }
        Slot::Run {
            k,
            lateness: now - deadline,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn virtual_clock_runs_every_slot_on_time() {
        let mut s = Schedule::virtual_clock(Duration::from_millis(10));
        for k in 0..5 {
            assert_eq!(
                s.next_slot(),
                Slot::Run {
                    k,
                    lateness: Duration::ZERO
                }
            );
        }
        assert_eq!(s.t_s(7), 0.07);
        assert_eq!(s.t_s(300), 3.0);
    }

    #[test]
    fn real_clock_keeps_the_grid_and_skips_overrun_slots() {
        let period = Duration::from_millis(10);
        let before = Instant::now();
        // Slot 0's deadline is one period after the schedule starts, slot k's k periods later.
        let mut s = Schedule::real(period, Duration::from_micros(200));
        let Slot::Run { k: 0, .. } = s.next_slot() else {
            panic!("slot 0 must run")
        };
        // Overrun: 25 ms of work puts slots 1 and 2 more than half a period late (a sleep never
        // ends early); a machine that stalls the thread too may make it more.
        std::thread::sleep(Duration::from_millis(25));
        assert_eq!(s.next_slot(), Slot::Skipped { k: 1 });
        assert_eq!(s.next_slot(), Slot::Skipped { k: 2 });
        let mut k = 3;
        loop {
            match s.next_slot() {
                Slot::Skipped { k: j } => assert_eq!(j, k),
                Slot::Run { k: j, .. } => {
                    assert_eq!(j, k);
                    break;
                }
            }
            k += 1;
        }
        // The slot that runs is on the grid: never before its own deadline, and not one period
        // after the overrun (which would have labelled it slot 1).
        let at = before.elapsed();
        assert!(at >= period * (k as u32 + 1), "slot {k} ran at {at:?}");
    }
}
