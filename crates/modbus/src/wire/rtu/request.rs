//! What an RTU request asks for, read from its bytes: the unit, the function code, the size of
//! its reply, the set-point it writes and where its reply reads a set-point back; and whether a
//! frame could be that reply ([`Expect::fit`]).
//!
//! Not here: remembering requests or deciding what a frame answers ([`super::framer`]).

use super::MAX_FRAME;

/// The most set-point bytes remembered per write (a 32-bit set-point takes 4).
const WRITTEN_BYTES: usize = 8;

/// A set-point written: the unit, the register address and the data bytes as sent.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(super) struct Written {
    pub(super) unit: u8,
    pub(super) address: u16,
    bytes: [u8; WRITTEN_BYTES],
    len: usize,
}

impl Written {
    fn new(unit: u8, address: u16, data: &[u8]) -> Option<Written> {
        if data.len() > WRITTEN_BYTES || !data.len().is_multiple_of(2) {
            return None;
        }
        let mut w = Written {
            unit,
            address,
            bytes: [0; WRITTEN_BYTES],
            len: data.len(),
        };
        w.bytes[..data.len()].copy_from_slice(data);
        Some(w)
    }

    pub(super) fn data(&self) -> &[u8] {
        &self.bytes[..self.len]
    }

    /// The byte offset of these registers in the data of a read of `count` from `start`.
    fn offset_in(&self, start: u16, count: u16) -> Option<usize> {
        let end = u32::from(start) + u32::from(count);
        let own_end = u32::from(self.address) + (self.len / 2) as u32;
        (self.address >= start && own_end <= end).then(|| 2 * usize::from(self.address - start))
    }
}

/// What the reply to a request must look like.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Expect {
    pub(super) unit: u8,
    pub(super) fc: u8,
    /// Frame size of a normal reply, bytes.
    pub(super) len: usize,
    /// Where the reply's frame holds the set-point registers (byte offset), and what they must
    /// read.
    pub(super) readback: Option<(usize, Written)>,
}

/// Whether a complete, intact frame can be the reply a request expects.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Fit {
    /// It can: the unit, function code (or its exception), size and read-back set-point fit.
    Yes,
    /// It reads back a set-point this wire never wrote (the device clamped or refused it):
    /// only the client can judge it.
    Foreign,
    /// It cannot, for this reason.
    No(Misfit),
}

/// Why a frame is not a request's reply.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Misfit {
    Unit(u8),
    Function(u8),
    Size(usize),
    /// It reads back another set-point written here.
    EarlierSetpoint,
}

impl Expect {
    /// Whether `frame` can be this reply; `written_here` tells whether a set-point read back
    /// was written by this wire.
    pub(super) fn fit(&self, frame: &[u8], written_here: impl Fn(&Written, &[u8]) -> bool) -> Fit {
        let (unit, fc) = (frame[0], frame[1]);
        if unit != self.unit {
            return Fit::No(Misfit::Unit(unit));
        }
        if fc == self.fc | 0x80 {
            return Fit::Yes;
        }
        if fc != self.fc {
            return Fit::No(Misfit::Function(fc));
        }
        if frame.len() != self.len {
            return Fit::No(Misfit::Size(frame.len()));
        }
        let Some((off, w)) = self.readback else {
            return Fit::Yes;
        };
        let got = &frame[off..off + w.data().len()];
        if got == w.data() {
            Fit::Yes
        } else if written_here(&w, got) {
            Fit::No(Misfit::EarlierSetpoint)
        } else {
            Fit::Foreign
        }
    }

    /// True when a reply to `other` would be byte for byte a reply to this request.
    pub(super) fn same_reply_as(&self, other: &Expect) -> bool {
        let readback = |e: &Expect| e.readback.map(|(off, w)| (off, w.bytes, w.len));
        self.unit == other.unit
            && self.fc == other.fc
            && self.len == other.len
            && readback(self) == readback(other)
    }
}

/// A complete request as sent: what its reply must look like (None for a function the wire does
/// not know, whose reply passes unframed) and the set-point it writes.
pub(super) fn parse(r: &[u8], latest: impl Fn(u8) -> Option<Written>) -> Parsed {
    let word = |i: usize| u16::from_be_bytes([r[i], r[i + 1]]);
    let (unit, fc) = (r[0], r[1]);
    match fc {
        3 | 4 => {
            let (start, count) = (word(2), word(4));
            let readback = (fc == 3)
                .then(|| latest(unit))
                .flatten()
                .and_then(|w| w.offset_in(start, count).map(|off| (3 + off, w)));
            Parsed {
                expect: Some(Expect {
                    unit,
                    fc,
                    len: 5 + 2 * usize::from(count),
                    readback,
                }),
                wrote: None,
            }
        }
        6 | 16 => {
            let data = match fc {
                6 => &r[4..6],
                _ => &r[7..7 + usize::from(r[6])],
            };
            Parsed {
                expect: Some(Expect {
                    unit,
                    fc,
                    len: 8,
                    readback: None,
                }),
                wrote: Written::new(unit, word(2), data),
            }
        }
        23 => {
            let (start, count, address) = (word(2), word(4), word(6));
            let wrote = Written::new(unit, address, &r[11..11 + usize::from(r[10])]);
            let readback = wrote.and_then(|w| w.offset_in(start, count).map(|off| (3 + off, w)));
            Parsed {
                expect: Some(Expect {
                    unit,
                    fc,
                    len: 5 + 2 * usize::from(count),
                    readback,
                }),
                wrote,
            }
        }
        _ => Parsed {
            expect: None,
            wrote: None,
        },
    }
}

/// What [`parse`] read.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Parsed {
    pub(super) expect: Option<Expect>,
    pub(super) wrote: Option<Written>,
}

/// The size of a request from its first bytes, once they tell it.
pub(super) fn request_len(r: &[u8]) -> Option<usize> {
    match *r.get(1)? {
        16 => Some(9 + usize::from(*r.get(6)?)),
        23 => Some(13 + usize::from(*r.get(10)?)),
        // FC 3, 4 and every function the wire does not read: 8 bytes (address, FC, 4, CRC).
        _ => Some(8),
    }
}

/// The size of a reply frame beginning at `rx[0]`, once its first three bytes tell it; None
/// when they cannot begin a reply (a function code whose replies the wire does not know, a
/// byte count no frame can hold, a unit that is no slave address).
pub(super) fn reply_len(rx: &[u8]) -> Option<usize> {
    let (&unit, &fc, &count) = (rx.first()?, rx.get(1)?, rx.get(2)?);
    if !(1..=247).contains(&unit) {
        return None;
    }
    let len = match fc {
        fc if fc & 0x80 != 0 && matches!(fc & 0x7F, 3 | 4 | 6 | 16 | 23) => 5,
        3 | 4 | 23 if count.is_multiple_of(2) => 5 + usize::from(count),
        6 | 16 => 8,
        _ => return None,
    };
    (len <= MAX_FRAME).then_some(len)
}
