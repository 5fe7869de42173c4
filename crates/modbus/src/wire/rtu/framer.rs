//! The RTU wire's reckoning, without I/O: which request each frame on the line answers.
//!
//! The [`Framer`] remembers every request it saw go out (the last [`RING`]: when, what its reply
//! looks like, the set-point it wrote, whether a reply came) and frames the received bytes:
//! wherever a byte run with a good CRC has the size its function code gives, that is a frame,
//! and the bytes before it are line noise (a stray byte, a broken frame), counted and dropped,
//! never passed on. Each frame is then given to the one request it can answer:
//! - within the current request's window, a frame that fits it (unit, function code or its
//!   exception, size, the set-point read back) is its reply and the only thing passed on,
//!   unless an earlier request of the last `late_reply_ms` went unanswered whose reply would be
//!   byte for byte the same (a held set-point): a slave answers in order, so the frame is that
//!   reply, and the current one's is still to come;
//! - any other frame, and every frame between two requests, goes to the oldest unanswered
//!   request it fits that was sent after the unit's newest answered one (a late reply:
//!   counted, dropped; a slave answers in order, so an older one was dropped for good) or,
//!   fitting none, is unexpected: counted,
//!   and when it follows a reply passed on in the same window, that reply is marked
//!   *unverified* ([`Unverified`]): it may have been a reply later than `late_reply_ms`.
//!
//! The line is held before a request ([`Framer::hold`]) while an earlier request of a device
//! that answers is unanswered and younger than `late_reply_ms`: its reply, if it comes, then
//! arrives while no other request is out and cannot be taken for another's. A device heard
//! from within the last `max(late_reply_ms, 1 s)` answers; one silent longer (switched off,
//! another unit on the bus) does not hold the line. A reply later than `late_reply_ms` that the
//! wire recognises (by the set-point it reads back, or as a frame no request is waiting for)
//! raises `late_reply_ms` to what was seen, up to [`MAX_HORIZON`], with a warning.
//!
//! Not here: reading or writing the port, timers ([`super::RtuWire`]).

use std::time::Duration;

use tokio::time::Instant;

use super::request::{self, Expect, Fit, Written};
use super::MAX_FRAME;
use crate::wire::{Held, Unverified, WireState, MODBUS_CRC};

/// Requests remembered (several seconds at 100 Hz with two transactions a cycle).
const RING: usize = 1024;
/// The longest the line is held for a late reply, whatever was seen.
pub const MAX_HORIZON: Duration = Duration::from_secs(2);
/// A raised horizon goes back to `late_reply_ms` after this long without a reply later than
/// that.
const RELAX_AFTER: Duration = Duration::from_secs(60);
/// A device heard from within this long (or `late_reply_ms`, if longer) answers: its
/// unanswered requests hold the line.
const PRESENT_FOR: Duration = Duration::from_secs(1);

/// A request as it went out.
#[derive(Debug, Clone, Copy)]
struct Sent {
    at: Instant,
    expect: Expect,
    wrote: Option<Written>,
    answered: bool,
}

/// Where the current request is.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    /// Between two requests: the last one's window is over.
    Between,
    /// Being written.
    Writing,
    /// Sent: its entry in the ring, or None for a function the wire cannot read (its reply
    /// passes unframed).
    Sent(Option<usize>),
}

/// The framing of one link's replies (see the module documentation).
#[derive(Debug)]
pub(super) struct Framer {
    request: [u8; MAX_FRAME],
    request_len: usize,
    phase: Phase,
    ring: Box<[Option<Sent>]>,
    next: usize,
    /// When each unit was last heard from.
    heard: Box<[Option<Instant>]>,
    /// How long an unanswered request's reply is waited for now.
    horizon: Duration,
    /// `late_reply_ms`, what the horizon goes back to.
    configured: Duration,
    /// When a reply later than `late_reply_ms` was last seen.
    last_very_late: Option<Instant>,
    /// A frame was passed on in the current window.
    passed: bool,
    /// Received bytes not framed yet.
    rx: Vec<u8>,
    /// Bytes passed on, not yet handed to tokio-modbus.
    pub(super) ready: Vec<u8>,
}

impl Framer {
    /// A framer that waits `horizon` for a late reply (`late_reply_ms`, or more while a later
    /// reply was seen within [`RELAX_AFTER`]), and at least `configured`.
    pub(super) fn new(configured: Duration, horizon: Duration) -> Framer {
        Framer {
            request: [0; MAX_FRAME],
            request_len: 0,
            phase: Phase::Between,
            ring: vec![None; RING].into_boxed_slice(),
            next: 0,
            heard: vec![None; 256].into_boxed_slice(),
            horizon: horizon.max(configured).min(MAX_HORIZON),
            configured: configured.min(MAX_HORIZON),
            last_very_late: (horizon > configured).then(Instant::now),
            passed: false,
            rx: Vec::with_capacity(2 * MAX_FRAME),
            ready: Vec::with_capacity(2 * MAX_FRAME),
        }
    }

    /// How long an unanswered request's reply is waited for now.
    #[cfg(test)]
    fn horizon(&self) -> Duration {
        self.horizon
    }

    /// True while a request is being written (begun, not complete).
    pub(super) fn writing(&self) -> bool {
        self.phase == Phase::Writing && self.request_len > 0
    }

    /// The current request's window is over (the client has its reply or gave up): what
    /// arrives now answers an earlier request, if any.
    pub(super) fn end_window(&mut self) {
        if !self.writing() {
            self.phase = Phase::Between;
        }
    }

    /// A new request starts: nothing received so far answers it.
    pub(super) fn begin(&mut self, state: &WireState) {
        state.count_noise(self.rx.len());
        self.request_len = 0;
        self.phase = Phase::Writing;
        self.passed = false;
        self.rx.clear();
        self.ready.clear();
    }

    /// Follows the bytes of the request being written, sent at `now`.
    pub(super) fn wrote(&mut self, bytes: &[u8], now: Instant) {
        let room = MAX_FRAME - self.request_len;
        let n = bytes.len().min(room);
        self.request[self.request_len..self.request_len + n].copy_from_slice(&bytes[..n]);
        self.request_len += n;
        if self.phase != Phase::Writing {
            return;
        }
        let complete = match request::request_len(&self.request[..self.request_len]) {
            Some(len) => self.request_len >= len,
            // Longer than any frame: not a request the wire can read.
            None => self.request_len == MAX_FRAME,
        };
        if complete {
            self.phase = Phase::Sent(self.remember(now));
        }
    }

    /// Records the complete request; its entry, if the wire can read it.
    fn remember(&mut self, now: Instant) -> Option<usize> {
        let r = &self.request[..self.request_len];
        let fits = request::request_len(r).is_some_and(|len| len == r.len() && len >= 8);
        if !fits {
            return None;
        }
        let parsed = request::parse(r, |unit| self.latest_written(unit));
        let expect = parsed.expect?;
        let at = self.next;
        self.ring[at] = Some(Sent {
            at: now,
            expect,
            wrote: parsed.wrote,
            answered: false,
        });
        self.next = (self.next + 1) % RING;
        Some(at)
    }

    /// The remembered requests, oldest first, with their places in the ring.
    fn sent(&self) -> impl Iterator<Item = (usize, &Sent)> + '_ {
        (0..RING)
            .map(move |k| (self.next + k) % RING)
            .filter_map(move |i| self.ring[i].as_ref().map(|s| (i, s)))
    }

    /// The set-point written last to `unit`.
    fn latest_written(&self, unit: u8) -> Option<Written> {
        self.sent()
            .filter_map(|(_, s)| s.wrote)
            .filter(|w| w.unit == unit)
            .last()
    }

    /// True when `got` is a set-point this wire wrote to `w`'s unit and register.
    fn written_here(&self, w: &Written, got: &[u8]) -> bool {
        self.sent()
            .filter_map(|(_, s)| s.wrote)
            .any(|o| o.unit == w.unit && o.address == w.address && o.data() == got)
    }

    /// Takes in bytes received at `now`, in or between request windows.
    pub(super) fn received(&mut self, bytes: &[u8], now: Instant, state: &WireState) {
        if self.phase == Phase::Sent(None) {
            // A request the wire cannot read: its reply passes as it comes.
            self.ready.extend_from_slice(bytes);
            return;
        }
        self.rx.extend_from_slice(bytes);
        self.scan(now, state);
    }

    /// Frames what is in `rx`: frames are given to their requests, the bytes before each are
    /// noise; a tail that may still begin a frame is kept.
    fn scan(&mut self, now: Instant, state: &WireState) {
        let mut done = 0;
        let mut i = 0;
        let mut frame = [0u8; MAX_FRAME];
        while i + 3 <= self.rx.len() {
            let Some(len) = self.complete_at(i) else {
                i += 1;
                continue;
            };
            if !self.intact(i, len) {
                // A broken frame shaped like an awaited reply answers it (the device did),
                // unless an intact frame begins inside it.
                let whole = (i + 1..i + len)
                    .all(|j| !self.complete_at(j).is_some_and(|l| self.intact(j, l)));
                if whole && self.broken_reply(i, len, now, state) {
                    state.count_noise(i + len - done);
                    i += len;
                    done = i;
                } else {
                    i += 1;
                }
                continue;
            }
            state.count_noise(i - done);
            frame[..len].copy_from_slice(&self.rx[i..i + len]);
            self.on_frame(&frame[..len], now, state);
            i += len;
            done = i;
        }
        let keep_from = done.max(self.rx.len().saturating_sub(MAX_FRAME - 1));
        state.count_noise(keep_from - done);
        self.rx.drain(..keep_from);
        self.note_partial(state);
    }

    /// The size of the frame that begins at `rx[i]`, if it can be one and is all there.
    fn complete_at(&self, i: usize) -> Option<usize> {
        request::reply_len(&self.rx[i..]).filter(|len| i + len <= self.rx.len())
    }

    /// True when the `len` bytes at `rx[i]` end with their CRC.
    fn intact(&self, i: usize, len: usize) -> bool {
        let (body, crc) = self.rx[i..i + len].split_at(len - 2);
        MODBUS_CRC.checksum(body).to_le_bytes() == [crc[0], crc[1]]
    }

    /// The current request's expected reply, while it waits for one.
    fn waiting(&self) -> Option<Expect> {
        match self.phase {
            Phase::Sent(Some(i)) if !self.passed => self.ring[i].map(|s| s.expect),
            _ => None,
        }
    }

    /// Gives the broken frame of `len` bytes at `rx[at]` to the request whose reply it is
    /// shaped like (the current one's, kept for its fault message, or the oldest unanswered);
    /// false when it is shaped like none.
    fn broken_reply(&mut self, at: usize, len: usize, now: Instant, state: &WireState) -> bool {
        let f = &self.rx[at..at + len];
        let shaped = |e: &Expect| {
            f[0] == e.unit && ((f[1] == e.fc && len == e.len) || (f[1] == e.fc | 0x80 && len == 5))
        };
        if let (Some(e), Phase::Sent(Some(current))) = (self.waiting(), self.phase) {
            if shaped(&e) {
                state.restart_rx(f);
                if let Some(s) = self.ring[current].as_mut() {
                    s.answered = true;
                }
                return true;
            }
        }
        let unit = f[0];
        let Some(i) = self.awaiting(unit, shaped) else {
            return false;
        };
        self.answer(i, unit, now, state);
        true
    }

    /// Keeps the beginning of the awaited reply, for the fault message.
    fn note_partial(&self, state: &WireState) {
        let Some(e) = self.waiting() else { return };
        let start = (0..self.rx.len().saturating_sub(1))
            .find(|&i| self.rx[i] == e.unit && self.rx[i + 1] & 0x7F == e.fc);
        if let Some(i) = start {
            state.restart_rx(&self.rx[i..]);
        }
    }

    /// A complete, intact frame received at `now`.
    fn on_frame(&mut self, frame: &[u8], now: Instant, state: &WireState) {
        let Phase::Sent(Some(current)) = self.phase else {
            self.late(frame, now, state);
            return;
        };
        let Some(cur) = self.ring[current] else {
            return;
        };
        let fit = cur.expect.fit(frame, |w, got| self.written_here(w, got));
        if matches!(fit, Fit::No(_)) {
            self.late(frame, now, state);
            return;
        }
        if self.passed {
            // A second reply in one window: the first may have been the reply, later than the
            // horizon, of an earlier request, the one this one is then given to.
            state.set_unverified(Unverified {
                unit: cur.expect.unit,
                fc: cur.expect.fc,
            });
            self.late(frame, now, state);
            return;
        }
        if let Some(earlier) = self.unanswered_like(&cur.expect, current, now) {
            // An earlier request went unanswered whose reply reads the same: a slave answers in
            // order, so this is that reply, and the current one's is still to come.
            self.answer(earlier, frame[0], now, state);
            return;
        }
        if let Some(s) = self.ring[current].as_mut() {
            s.answered = true;
        }
        self.heard[usize::from(frame[0])] = Some(now);
        self.passed = true;
        self.ready.extend_from_slice(frame);
    }

    /// The oldest unanswered request younger than the horizon, other than `current`, whose
    /// reply would look exactly like `e`'s.
    fn unanswered_like(&self, e: &Expect, current: usize, now: Instant) -> Option<usize> {
        self.sent()
            .find(|&(i, s)| {
                i != current
                    && !s.answered
                    && now < s.at + self.horizon
                    && s.expect.same_reply_as(e)
            })
            .map(|(i, _)| i)
    }

    /// The oldest unanswered request of `unit` that a frame `fits` may answer: one sent after
    /// the unit's newest answered request. A slave answers in order, so an older one went
    /// unanswered for good (a dropped request), and a late reply given to it would read as
    /// far later than it is.
    fn awaiting(&self, unit: u8, fits: impl Fn(&Expect) -> bool) -> Option<usize> {
        let after = (self.sent().enumerate())
            .filter(|(_, (_, s))| s.answered && s.expect.unit == unit)
            .map(|(k, _)| k + 1)
            .last()
            .unwrap_or(0);
        (self.sent().skip(after))
            .find(|(_, s)| !s.answered && s.expect.unit == unit && fits(&s.expect))
            .map(|(i, _)| i)
    }

    /// The request at `i` of `unit` got its reply at `now`, late: counted, and the horizon grows
    /// if it was later than that.
    fn answer(&mut self, i: usize, unit: u8, now: Instant, state: &WireState) {
        let Some(s) = self.ring[i].as_mut() else {
            return;
        };
        s.answered = true;
        let lateness = now - s.at;
        self.heard[usize::from(unit)] = Some(now);
        state.count_stale();
        tracing::debug!(
            "RTU: discarded a reply of unit {unit} {} ms after its request",
            lateness.as_millis()
        );
        if lateness > self.configured {
            self.last_very_late = Some(now);
        }
        if lateness > self.horizon {
            self.raise(lateness + lateness / 4, lateness, state);
        }
    }

    /// A frame that answers no current request: the reply to the oldest unanswered request it
    /// fits, or unexpected.
    fn late(&mut self, frame: &[u8], now: Instant, state: &WireState) {
        let fits = |e: &Expect| matches!(e.fit(frame, |_, _| true), Fit::Yes);
        match self.awaiting(frame[0], fits) {
            Some(i) => self.answer(i, frame[0], now, state),
            None => self.unexpected(frame, now, state),
        }
    }

    /// A frame no request is waiting for: a reply later than the horizon may have been taken
    /// for another request's.
    fn unexpected(&mut self, frame: &[u8], now: Instant, state: &WireState) {
        self.heard[usize::from(frame[0])] = Some(now);
        self.last_very_late = Some(now);
        state.count_unexpected();
        tracing::debug!("RTU: a frame no request was waiting for ({frame:02X?})");
        self.raise(self.horizon * 2, self.horizon, state);
    }

    /// Waits up to `to` for late replies from now on, having seen one at least `seen` late.
    fn raise(&mut self, to: Duration, seen: Duration, state: &WireState) {
        // Whole milliseconds, as the setting is given.
        let to = Duration::from_millis(to.min(MAX_HORIZON).as_millis() as u64);
        if to <= self.horizon {
            return;
        }
        tracing::warn!(
            "Modbus RTU: a reply came at least {} ms after its request, later than the {} ms \
             the line was held for late replies; it is now held up to {} ms (set \
             late_reply_ms to the device's slowest answer)",
            seen.as_millis(),
            self.horizon.as_millis(),
            to.as_millis()
        );
        self.horizon = to;
        state.set_horizon(Some(to));
    }

    /// Until when the line must stay quiet before the request `next` (its bytes as far as they
    /// are written), and for which earlier request: the latest end of the horizon of an
    /// unanswered request of a device that answers whose reply would read exactly as `next`'s
    /// (any, when `next` cannot be read). A late reply that reads otherwise is told by its bytes
    /// whenever it comes: no need to wait for it. A raised horizon goes back to
    /// `late_reply_ms` here once no reply later than that was seen for [`RELAX_AFTER`].
    pub(super) fn hold(
        &mut self,
        next: &[u8],
        now: Instant,
        state: &WireState,
    ) -> Option<(Instant, Held)> {
        if self.horizon > self.configured
            && self.last_very_late.is_none_or(|t| now - t > RELAX_AFTER)
        {
            tracing::info!(
                "Modbus RTU: no reply later than late_reply_ms = {} ms for {} s: late replies are \
                 waited for that long again (was {} ms)",
                self.configured.as_millis(),
                RELAX_AFTER.as_secs(),
                self.horizon.as_millis()
            );
            self.horizon = self.configured;
            state.set_horizon(None);
        }
        let present_for = self.horizon.max(PRESENT_FOR);
        let next = (request::request_len(next))
            .filter(|&len| len >= 8 && len <= next.len())
            .and_then(|len| request::parse(&next[..len], |unit| self.latest_written(unit)).expect);
        self.sent()
            .filter(|(_, s)| !s.answered && now < s.at + self.horizon)
            .filter(|(_, s)| next.is_none_or(|e| e.same_reply_as(&s.expect)))
            .filter(|(_, s)| {
                self.heard[usize::from(s.expect.unit)]
                    .is_some_and(|h| s.at.saturating_duration_since(h) <= present_for)
            })
            .map(|(_, s)| {
                let held = Held {
                    unit: s.expect.unit,
                    fc: s.expect.fc,
                    sent_ms_ago: millis(now - s.at),
                    horizon_ms: millis(self.horizon),
                };
                (s.at + self.horizon, held)
            })
            .max_by_key(|(until, _)| *until)
    }
}

/// `d` in whole milliseconds (the hold is at most [`MAX_HORIZON`]).
fn millis(d: Duration) -> u32 {
    u32::try_from(d.as_millis()).unwrap_or(u32::MAX)
}

#[cfg(test)]
#[path = "framer_tests.rs"]
mod tests;
