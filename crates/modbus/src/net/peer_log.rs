//! Warnings about a peer, at most one line per host a minute: a flood of clients that makes a
//! server close or refuse connections thousands of times a second is told once a minute per
//! host, with how many more there were, not in a line each.
//!
//! Written here because the line must say how many were held back since the last one: rate
//! limiters (governor and the like) answer yes or no and keep no such count.
//!
//! Not here: what is told (the servers write their own lines), the totals (the servers'
//! [`Health`](super::Health) counts every one).

use std::collections::HashMap;
use std::net::IpAddr;
use std::time::{Duration, Instant};

/// The hosts told about lately, and how many lines about each were held back.
#[derive(Debug, Default)]
pub struct PeerLog {
    hosts: HashMap<IpAddr, Told>,
}

#[derive(Debug, Clone, Copy)]
struct Told {
    at: Instant,
    held_back: u64,
}

/// What was held back about a host before a line that goes out: its suffix
/// (`; 2770 more in the 60 s before`, nothing when none was).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HeldBack {
    /// Lines held back since the last one that went out.
    pub count: u64,
    /// Time since that line.
    pub since: Duration,
}

impl std::fmt::Display for HeldBack {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.count > 0 {
            write!(
                f,
                "; {} more in the {:.0} s before (told once a minute per host)",
                self.count,
                self.since.as_secs_f64()
            )?;
        }
        Ok(())
    }
}

impl PeerLog {
    /// A host is told about at most once in this long.
    pub const EVERY: Duration = Duration::from_secs(60);
    /// Hosts remembered before those told about more than [`PeerLog::EVERY`] ago are
    /// forgotten (their held-back lines are in the servers' totals).
    const HOSTS: usize = 4096;

    /// Whether a line about `ip` goes out at `now`: `Some` with what was held back since the
    /// last one, or `None` (held back, and counted).
    pub fn admit(&mut self, ip: IpAddr, now: Instant) -> Option<HeldBack> {
        if let Some(told) = self.hosts.get_mut(&ip) {
            let since = now.saturating_duration_since(told.at);
            if since < Self::EVERY {
                told.held_back += 1;
                return None;
            }
            let held = HeldBack {
                count: told.held_back,
                since,
            };
            *told = Told {
                at: now,
                held_back: 0,
            };
            return Some(held);
        }
        if self.hosts.len() >= Self::HOSTS {
            self.hosts
                .retain(|_, t| now.saturating_duration_since(t.at) < Self::EVERY);
        }
        self.hosts.insert(
            ip,
            Told {
                at: now,
                held_back: 0,
            },
        );
        Some(HeldBack {
            count: 0,
            since: Duration::ZERO,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_line_per_host_a_minute_with_the_count_held_back() {
        let mut log = PeerLog::default();
        let t0 = Instant::now();
        let (a, b) = (IpAddr::from([10, 0, 0, 1]), IpAddr::from([10, 0, 0, 2]));
        let at = |s: u64| t0 + Duration::from_secs(s);
        let first = log.admit(a, at(0)).unwrap();
        assert_eq!((first.count, first.to_string()), (0, String::new()));
        for s in 1..60 {
            assert_eq!(log.admit(a, at(s)), None);
        }
        // Another host is told at once.
        assert!(log.admit(b, at(30)).is_some());
        let next = log.admit(a, at(61)).unwrap();
        assert_eq!(next.count, 59);
        assert_eq!(
            next.to_string(),
            "; 59 more in the 61 s before (told once a minute per host)"
        );
        assert_eq!(log.admit(a, at(62)), None);
    }

    #[test]
    fn a_flood_of_hosts_is_forgotten_a_minute_later() {
        let mut log = PeerLog::default();
        let t0 = Instant::now();
        for k in 0..PeerLog::HOSTS as u32 {
            assert!(log.admit(IpAddr::from(k.to_be_bytes()), t0).is_some());
        }
        let later = t0 + PeerLog::EVERY;
        assert!(log.admit(IpAddr::from([192, 0, 2, 1]), later).is_some());
        assert_eq!(log.hosts.len(), 1);
    }
}
