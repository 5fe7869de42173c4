//! Who gives way when a server is full: the choice [`serve`](super::serve) makes for each new
//! connection, from what it knows of the open ones.
//!
//! Every connection has a [`Standing`]. A process controller's (a configured controller's
//! address, or a connection that has had a set-point write accepted) is never closed for
//! another client's connection. When the server is full, the connection closed for the new one
//! is taken from the host (IP address) holding the most connections that are not a
//! controller's, so a host that floods the server loses its own first; within that host an
//! ordinary connection goes before a preferred one (a Prometheus scraper's); a socket that has
//! sent no request for [`NEWCOMER_GRACE`] since it opened goes before one that did, and one
//! that did before a newcomer still within that grace (its first request is on its way: a
//! client that reconnects is not pushed out before it can say who it is); then the one idle
//! longest. Configured controllers also have slots kept for them: the other connections hold
//! at most `max_connections` minus their number. With every slot held by controllers, a
//! configured controller's new connection takes the place of the idle-longest one of its own
//! host (it reconnected), and anyone else's is refused.
//!
//! Not here: closing or counting anything, logging (see [`super::serve`]).

use std::collections::HashMap;
use std::net::IpAddr;
use std::time::Duration;

/// Time a new connection has to send its first request before it counts as one that never
/// does (a client on a network sends it within milliseconds of connecting).
pub(super) const NEWCOMER_GRACE: Duration = Duration::from_millis(100);

/// How firmly a connection keeps its place when the server is full (ordered: a higher standing
/// gives way later).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
#[repr(u8)]
pub enum Standing {
    /// Any client.
    Ordinary = 0,
    /// A client worth keeping before others of its host: a Prometheus scraper (any client may
    /// ask for `/metrics`, so this orders connections within a host and shields from nothing).
    Preferred = 1,
    /// A process controller: never closed for another client's connection.
    Controller = 2,
}

impl Standing {
    /// The standing stored as `v` ([`Standing::Ordinary`] for anything else).
    pub(super) fn from_u8(v: u8) -> Standing {
        match v {
            2 => Standing::Controller,
            1 => Standing::Preferred,
            _ => Standing::Ordinary,
        }
    }
}

/// What [`room`] knows of an open connection.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Held {
    /// Its peer's address (its host).
    pub ip: IpAddr,
    pub standing: Standing,
    /// True when it has sent no request yet.
    pub silent: bool,
    /// Time since its last request (since it opened, before the first).
    pub idle: Duration,
}

/// What to do for a new connection.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Room {
    /// There is a free slot.
    Free,
    /// Close the open connection at this index of the list given, then take the new one.
    Close(usize),
    /// Close the new connection at once.
    Refuse,
}

/// What to do for a new connection from `ip` with standing `standing` (a configured
/// controller's, or an ordinary one), when `open` are open, at most `max` may be and `reserved`
/// slots are kept for the configured controllers (see the module documentation).
pub(super) fn room(
    open: &[Held],
    (ip, standing): (IpAddr, Standing),
    max: usize,
    reserved: usize,
) -> Room {
    let others = open
        .iter()
        .filter(|c| c.standing != Standing::Controller)
        .count();
    let full = open.len() >= max
        || (standing != Standing::Controller && others >= max.saturating_sub(reserved));
    if !full {
        return Room::Free;
    }
    if others > 0 {
        return Room::Close(giving_way(open));
    }
    if standing != Standing::Controller {
        return Room::Refuse;
    }
    // Every slot is a controller's: a configured controller that reconnected replaces its own
    // connection idle longest.
    (open.iter().enumerate())
        .filter(|(_, c)| c.ip == ip)
        .max_by_key(|(_, c)| (c.silent, c.idle))
        .map_or(Room::Refuse, |(i, _)| Room::Close(i))
}

/// The index of the connection that is not a controller's to close: of the host holding the
/// most such connections, the lowest standing, a silent one past its grace before one that
/// talked and one that talked before a newcomer, then idle longest. `open` must hold one.
fn giving_way(open: &[Held]) -> usize {
    let mut per_host: HashMap<IpAddr, usize> = HashMap::new();
    for c in open.iter().filter(|c| c.standing != Standing::Controller) {
        *per_host.entry(c.ip).or_default() += 1;
    }
    (open.iter().enumerate())
        .filter(|(_, c)| c.standing != Standing::Controller)
        .max_by_key(|(_, c)| {
            let held = per_host.get(&c.ip).copied().unwrap_or(0);
            (held, std::cmp::Reverse(c.standing), doubt(c), c.idle)
        })
        .map_or(0, |(i, _)| i)
}

/// How little a connection has shown it is wanted, within its standing: 2 for a socket silent
/// past [`NEWCOMER_GRACE`], 1 for one that sent a request, 0 for a newcomer within the grace.
fn doubt(c: &Held) -> u8 {
    match (c.silent, c.idle >= NEWCOMER_GRACE) {
        (true, true) => 2,
        (false, _) => 1,
        (true, false) => 0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn ip(last: u8) -> IpAddr {
        IpAddr::from([10, 0, 0, last])
    }

    fn held(host: u8, standing: Standing, silent: bool, idle_ms: u64) -> Held {
        Held {
            ip: ip(host),
            standing,
            silent,
            idle: Duration::from_millis(idle_ms),
        }
    }

    use Standing::{Controller, Ordinary, Preferred};

    #[test]
    fn below_the_limit_there_is_room() {
        let open = [held(1, Ordinary, false, 5); 3];
        assert_eq!(room(&open, (ip(2), Ordinary), 4, 0), Room::Free);
        assert_eq!(room(&open, (ip(2), Ordinary), 3, 0), Room::Close(2));
    }

    #[test]
    fn the_host_holding_the_most_gives_way_first_its_lowest_standing_first() {
        let open = [
            held(1, Ordinary, false, 900),
            held(2, Preferred, false, 1),
            held(2, Preferred, false, 3),
            held(2, Ordinary, false, 2),
            held(3, Controller, false, 5000),
        ];
        // Host 2 holds three: its ordinary connection goes, though host 1's waited longer.
        assert_eq!(room(&open, (ip(4), Ordinary), 5, 0), Room::Close(3));
        // Without it, host 2's preferred one idle longest goes.
        let open = [open[0], open[1], open[2], open[4]];
        assert_eq!(room(&open, (ip(4), Ordinary), 4, 0), Room::Close(2));
        // Hosts 1 and 2 holding one each: host 1's ordinary one goes before the preferred.
        let open = [open[0], open[1], open[3]];
        assert_eq!(room(&open, (ip(4), Ordinary), 3, 0), Room::Close(0));
    }

    #[test]
    fn a_socket_that_never_sent_a_request_goes_before_a_busy_one() {
        let open = [held(1, Ordinary, false, 50), held(1, Ordinary, true, 150)];
        assert_eq!(room(&open, (ip(1), Ordinary), 2, 0), Room::Close(1));
    }

    #[test]
    fn a_newcomer_gets_its_first_request_in_before_it_can_be_closed() {
        // Just opened, its request on the way: the busy one idle longest goes instead, and a
        // newcomer goes only for an older newcomer, or once silent past its grace.
        let open = [
            held(1, Ordinary, false, 2),
            held(1, Ordinary, true, 1),
            held(1, Ordinary, false, 3),
        ];
        assert_eq!(room(&open, (ip(1), Ordinary), 3, 0), Room::Close(2));
        let open = [held(1, Ordinary, true, 1), held(1, Ordinary, true, 30)];
        assert_eq!(room(&open, (ip(1), Ordinary), 2, 0), Room::Close(1));
        let open = [held(1, Ordinary, false, 2), held(1, Ordinary, true, 100)];
        assert_eq!(room(&open, (ip(1), Ordinary), 2, 0), Room::Close(1));
    }

    #[test]
    fn controllers_keep_their_slots_and_are_never_closed_for_others() {
        // Eight slots, one kept for a configured controller: seven ordinary connections fill
        // what the others may hold, so an eighth replaces one of them.
        let mut open = vec![held(1, Ordinary, false, 1); 7];
        assert_eq!(room(&open, (ip(1), Ordinary), 8, 1), Room::Close(6));
        // The controller finds its slot free.
        assert_eq!(room(&open, (ip(9), Controller), 8, 1), Room::Free);
        open.push(held(9, Controller, false, 99_000));
        assert_eq!(room(&open, (ip(1), Ordinary), 8, 1), Room::Close(6));
        // Every slot a controller's: a newcomer from elsewhere is refused, the controller's
        // own new connection replaces its connection idle longest.
        let open = [
            held(9, Controller, false, 10),
            held(9, Controller, false, 20),
        ];
        assert_eq!(room(&open, (ip(1), Ordinary), 2, 1), Room::Refuse);
        assert_eq!(room(&open, (ip(9), Controller), 2, 1), Room::Close(1));
        assert_eq!(room(&open, (ip(8), Controller), 2, 1), Room::Refuse);
    }

    fn any_held() -> impl Strategy<Value = Held> {
        (0u8..4, 0u8..3, any::<bool>(), 0u64..1000)
            .prop_map(|(host, s, silent, idle)| held(host, Standing::from_u8(s), silent, idle))
    }

    proptest! {
        /// Whatever is open, a controller's connection is closed only for a configured
        /// controller of its host, the server never goes over its limit, and a connection that
        /// is not a controller's is turned away only when every open one is a controller's.
        #[test]
        fn controllers_stay_and_the_limit_holds(
            open in proptest::collection::vec(any_held(), 0..12),
            host in 0u8..4,
            controller in any::<bool>(),
            max in 1usize..12,
            reserved in 0usize..3,
        ) {
            prop_assume!(open.len() <= max && reserved < max);
            let standing = if controller { Controller } else { Ordinary };
            let after = match room(&open, (ip(host), standing), max, reserved) {
                Room::Free => open.len() + 1,
                Room::Close(i) => {
                    let gone = open[i];
                    prop_assert!(
                        gone.standing != Controller || (controller && gone.ip == ip(host)),
                        "{gone:?}"
                    );
                    open.len()
                }
                Room::Refuse => {
                    prop_assert!(open.iter().all(|c| c.standing == Controller));
                    open.len()
                }
            };
            prop_assert!(after <= max);
        }
    }
}
