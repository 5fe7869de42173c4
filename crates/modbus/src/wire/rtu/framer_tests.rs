//! The framer on byte sequences a line can carry: late replies, noise before them, broken
//! frames, held set-points, replies later than the horizon.

use std::time::Duration;

use tokio::time::Instant;

use super::*;
use crate::wire::Window;

/// `body` with its CRC.
fn frame(body: &[u8]) -> Vec<u8> {
    let mut f = body.to_vec();
    f.extend_from_slice(&MODBUS_CRC.checksum(body).to_le_bytes());
    f
}

/// An FC 23 request of unit 1: write `sp` at 0, read 3 registers from 0.
fn fc23(sp: u16) -> Vec<u8> {
    let [h, l] = sp.to_be_bytes();
    frame(&[1, 23, 0, 0, 0, 3, 0, 0, 0, 1, 2, h, l])
}

/// Its reply: set-point `sp`, position `pos`, status 0.
fn fc23_reply(sp: u16, pos: u16) -> Vec<u8> {
    let ([sh, sl], [ph, pl]) = (sp.to_be_bytes(), pos.to_be_bytes());
    frame(&[1, 23, 6, sh, sl, ph, pl, 0, 0])
}

const HORIZON: Duration = Duration::from_millis(100);

/// A framer and a clock the test moves.
struct Line {
    f: Framer,
    state: WireState,
    now: Instant,
}

impl Line {
    fn new() -> Line {
        Line {
            f: Framer::new(HORIZON, HORIZON),
            state: WireState::default(),
            now: Instant::now(),
        }
    }

    fn at(&mut self, ms: u64) -> &mut Line {
        self.now += Duration::from_millis(ms);
        self
    }

    /// What arrives between two requests, then whether `next` may go out now.
    fn settle_for(&mut self, next: &[u8], between: &[&[u8]]) -> Option<(Instant, Held)> {
        self.f.end_window();
        for b in between {
            self.f.received(b, self.now, &self.state);
        }
        self.f.hold(next, self.now, &self.state)
    }

    /// [`Line::settle_for`] a request whose bytes are not known yet.
    fn settle(&mut self, between: &[&[u8]]) -> Option<(Instant, Held)> {
        self.settle_for(&[], between)
    }

    /// Sends `request` (settling first: it must not be held) and feeds `replies`; what is
    /// passed on, and the window's marks.
    fn exchange(&mut self, request: &[u8], replies: &[&[u8]]) -> (Vec<u8>, Window) {
        assert_eq!(self.settle_for(request, &[]), None, "the request is held");
        self.f.begin(&self.state);
        self.state.begin_window();
        // Written in two pieces, as a driver may.
        self.f.wrote(&request[..3], self.now);
        assert!(self.f.writing());
        self.f.wrote(&request[3..], self.now);
        assert!(!self.f.writing());
        for r in replies {
            // Received byte by byte: framing does not depend on how the bytes come.
            for b in r.iter() {
                self.f
                    .received(std::slice::from_ref(b), self.now, &self.state);
            }
        }
        (std::mem::take(&mut self.f.ready), self.state.window())
    }
}

#[test]
fn a_late_reply_is_told_by_the_set_point_it_reads_back() {
    let mut line = Line::new();
    let (got, w) = line.exchange(&fc23(500), &[&fc23_reply(500, 490)]);
    assert_eq!((got, w), (fc23_reply(500, 490), Window::default()));
    // 501 gets no reply in time: its reply arrives while 502 is out (the device was not heard
    // from before, so the line was not held for it).
    let mut fresh = Line::new();
    assert!(fresh.exchange(&fc23(501), &[]).0.is_empty());
    fresh.at(10);
    let (late, current) = (fc23_reply(501, 495), fc23_reply(502, 497));
    let (got, w) = fresh.exchange(&fc23(502), &[&late, &current]);
    assert_eq!(got, current);
    assert_eq!(w.unverified, None);
    assert_eq!(fresh.state.stale_replies(), 1);
    // A set-point the device changed (never written here) is passed on for the client.
    let clamped = fc23_reply(1000, 497);
    assert_eq!(line.at(10).exchange(&fc23(1500), &[&clamped]).0, clamped);
}

#[test]
fn the_line_is_held_until_the_late_reply_came() {
    let mut line = Line::new();
    line.exchange(&fc23(500), &[&fc23_reply(500, 490)]);
    // 501 goes unanswered: the device answers, so the next request waits for its reply.
    line.at(10).exchange(&fc23(501), &[]);
    let (until, held) = line.at(10).settle(&[]).expect("held");
    assert_eq!(until, line.now - Duration::from_millis(10) + HORIZON);
    assert_eq!((held.unit, held.fc, held.sent_ms_ago), (1, 23, 10));
    // Its reply comes 25 ms late after a stray byte: dropped, counted, the line is free.
    let late = [&[0u8][..], &fc23_reply(501, 495)].concat();
    assert_eq!(line.at(15).settle(&[&late]), None);
    assert_eq!(line.state.stale_replies(), 1);
    assert_eq!(line.state.noise_bytes(), 1);
    // A request that a late reply cannot be mistaken for is not held at all.
    line.exchange(&fc23(502), &[]);
    assert!(line.at(10).settle_for(&fc23(502), &[]).is_some());
    assert_eq!(line.settle_for(&fc23(503), &[]), None);
    line.at(100).settle(&[]);
    // And the next request, on the same set-point, is answered without a doubt.
    let (got, w) = line.exchange(&fc23(501), &[&fc23_reply(501, 496)]);
    assert_eq!((got, w.unverified), (fc23_reply(501, 496), None));
}

#[test]
fn a_reply_that_never_comes_holds_the_line_for_the_horizon_only() {
    let mut line = Line::new();
    line.exchange(&fc23(500), &[&fc23_reply(500, 490)]);
    line.at(10).exchange(&fc23(500), &[]);
    assert!(line.at(99).settle(&[]).is_some());
    // After the horizon the request is taken as lost; a device silent for longer than a
    // second holds the line for nothing at all.
    assert_eq!(line.at(1).settle(&[]), None);
    line.at(2000).exchange(&fc23(500), &[]);
    assert_eq!(line.at(10).settle(&[]), None);
}

#[test]
fn noise_and_broken_frames_are_never_passed_on() {
    let mut line = Line::new();
    // A stray byte before the reply, a broken frame after it.
    let mut broken = fc23_reply(500, 490);
    broken[4] ^= 0xFF;
    let noisy = [&[0u8, 0xFF][..], &fc23_reply(500, 490), &broken].concat();
    let (got, _) = line.exchange(&fc23(500), &[&noisy]);
    assert_eq!(got, fc23_reply(500, 490));
    // A broken reply alone: nothing passes, and the bytes are kept for the fault message.
    let (got, _) = line.at(10).exchange(&fc23(501), &[&broken]);
    assert!(got.is_empty());
    assert_eq!(line.state.received(), broken);
}

#[test]
fn a_reply_like_an_earlier_unanswered_ones_answers_that_one_first() {
    let mut line = Line::new();
    // Another unit on the bus, never heard from: the line is not held for it, but a reply
    // that looks like its late one is taken for it (a slave answers in order).
    line.exchange(&fc23(500), &[]);
    let (got, w) = line.at(10).exchange(&fc23(500), &[&fc23_reply(500, 490)]);
    assert!(got.is_empty());
    assert_eq!(w.unverified, None);
    assert_eq!(line.state.stale_replies(), 1);
    // The second request's own reply follows it, while the line is held for it.
    assert!(line.at(10).settle(&[]).is_some());
    assert_eq!(line.settle(&[&fc23_reply(500, 491)]), None);
    let (got, _) = line.exchange(&fc23(500), &[&fc23_reply(500, 492)]);
    assert_eq!(got, fc23_reply(500, 492));
    // Past the horizon of an unanswered request, the same reply is its own again.
    line.at(10).exchange(&fc23(500), &[]);
    let (got, _) = line.at(100).exchange(&fc23(500), &[&fc23_reply(500, 493)]);
    assert_eq!(got, fc23_reply(500, 493));
}

#[test]
fn a_reply_later_than_the_horizon_raises_it() {
    let mut line = Line::new();
    line.exchange(&fc23(500), &[&fc23_reply(500, 490)]);
    line.at(10).exchange(&fc23(501), &[]);
    // The device stays silent past the horizon; then the ramp goes on.
    line.at(110);
    let (late, current) = (fc23_reply(501, 495), fc23_reply(502, 497));
    // 205 ms after its request, the late reply reads back 501: dropped, and the horizon grows
    // to cover it.
    let (got, w) = line.at(95).exchange(&fc23(502), &[&late, &current]);
    assert_eq!((got, w.unverified), (current, None));
    assert_eq!(line.state.stale_replies(), 1);
    assert_eq!(line.f.horizon(), Duration::from_millis(256));
    assert_eq!(
        line.state.raised_horizon(),
        Some(Duration::from_millis(256))
    );
}

#[test]
fn a_late_reply_is_never_given_to_a_request_the_device_dropped() {
    let mut line = Line::new();
    // The device answers, then drops a request; the line is held for it, then the next ones
    // are answered.
    line.exchange(&fc23(500), &[&fc23_reply(500, 489)]);
    line.at(10).exchange(&fc23(500), &[]);
    assert!(line.at(10).settle(&[]).is_some());
    line.at(100).exchange(&fc23(500), &[&fc23_reply(500, 490)]);
    // Two seconds on, a reply comes 15 ms late: it is the last request's, not the dropped
    // one's of two seconds before, and the horizon stays.
    line.at(2000).exchange(&fc23(500), &[&fc23_reply(500, 491)]);
    line.at(10).exchange(&fc23(500), &[]);
    assert_eq!(line.at(15).settle(&[&fc23_reply(500, 492)]), None);
    assert_eq!(line.state.stale_replies(), 1);
    assert_eq!(line.f.horizon(), HORIZON);
    assert_eq!(line.state.raised_horizon(), None);
}

#[test]
fn a_second_reply_in_one_window_marks_the_first() {
    let mut line = Line::new();
    let two = [fc23_reply(500, 490), fc23_reply(500, 491)].concat();
    let (got, w) = line.exchange(&fc23(500), &[&two]);
    assert_eq!(got, fc23_reply(500, 490));
    assert_eq!(w.unverified, Some(Unverified { unit: 1, fc: 23 }));
    assert_eq!(line.state.unexpected_replies(), 1);
    assert_eq!(line.f.horizon(), 2 * HORIZON);
}

#[test]
fn other_units_functions_and_sizes_are_late() {
    let mut line = Line::new();
    // FC 16 of set-point 7 at 0, then FC 3 of registers 0-1 reads it back.
    let write = frame(&[1, 16, 0, 0, 0, 1, 2, 0, 7]);
    let echo = frame(&[1, 16, 0, 0, 0, 1]);
    assert_eq!(line.exchange(&write, &[&echo]).0, echo);
    let read = frame(&[1, 3, 0, 0, 0, 2]);
    let other_unit = frame(&[2, 3, 4, 0, 7, 0, 9]);
    let short = frame(&[1, 3, 2, 0, 7]);
    let reply = frame(&[1, 3, 4, 0, 7, 1, 0xF4]);
    let got = line
        .at(1)
        .exchange(&read, &[&echo, &other_unit, &short, &reply]);
    assert_eq!(got.0, reply);
    assert_eq!(line.state.unexpected_replies(), 3);
    // An exception to the request is its answer.
    let exc = frame(&[1, 0x83, 2]);
    assert_eq!(line.at(1).exchange(&read, &[&exc]).0, exc);
}

#[test]
fn an_fc6_write_is_read_back_like_fc16() {
    let mut line = Line::new();
    let write = frame(&[1, 6, 0, 0, 0, 7]);
    assert_eq!(line.exchange(&write, &[&write]).0, write);
    let read = frame(&[1, 3, 0, 0, 0, 2]);
    let reply = frame(&[1, 3, 4, 0, 7, 1, 0xF4]);
    assert_eq!(line.at(1).exchange(&read, &[&reply]).0, reply);
    // A reply reading back an earlier set-point is dropped as stale.
    line.at(1)
        .exchange(&frame(&[1, 6, 0, 0, 0, 9]), &[&frame(&[1, 6, 0, 0, 0, 9])]);
    let stale = frame(&[1, 3, 4, 0, 7, 1, 0xF0]);
    let current = frame(&[1, 3, 4, 0, 9, 1, 0xF4]);
    assert_eq!(line.at(1).exchange(&read, &[&stale, &current]).0, current);
}

#[test]
fn a_broken_late_reply_ends_the_hold() {
    let mut line = Line::new();
    line.exchange(&fc23(500), &[&fc23_reply(500, 490)]);
    line.at(10).exchange(&fc23(501), &[]);
    assert!(line.at(10).settle(&[]).is_some());
    // The late reply comes with a broken CRC: the device did answer, the line is free.
    let mut broken = fc23_reply(501, 495);
    broken[9] ^= 0x55;
    assert_eq!(line.at(5).settle(&[&broken]), None);
    assert_eq!(line.state.noise_bytes(), broken.len() as u64);
    assert_eq!(line.state.stale_replies(), 1);
}

#[test]
fn a_raised_horizon_goes_back_after_a_minute_without_late_replies() {
    let mut line = Line::new();
    line.exchange(&fc23(500), &[&fc23_reply(500, 490)]);
    line.at(10).exchange(&fc23(501), &[]);
    line.at(150).settle(&[&fc23_reply(501, 495)]);
    assert_eq!(line.f.horizon(), Duration::from_millis(187));
    line.at(59_000).settle(&[]);
    assert_eq!(line.f.horizon(), Duration::from_millis(187));
    line.at(2_000).settle(&[]);
    assert_eq!(line.f.horizon(), HORIZON);
    assert_eq!(line.state.raised_horizon(), None);
}
