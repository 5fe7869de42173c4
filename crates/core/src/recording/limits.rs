//! What a reader takes in at most, so that a damaged or hostile input (a small `.csv.gz` that
//! expands to one line of a gigabyte, a gigabyte of blank lines or NUL bytes, a device such as
//! `/dev/zero` that never ends) is refused with a one-line error naming the limit and the file
//! instead of filling memory: a line holds at most [`MAX_LINE_BYTES`], a recording at most
//! [`MAX_ROWS`] rows. [`Capped`] counts the bytes the CSV parser reads since its last row.
//!
//! Both limits lie far beyond any real file: a line of a real recording is under 1 kB (at most
//! 83 bytes in an hour of the daemon's log, 131 in the DAMADICS file), and the longest logs
//! hold days at 100 Hz. Rows added to fill gaps count too ([`super::grid`]).
//!
//! Not here: the memory a recording within the limits takes (it grows with its rows), and the
//! time a large file takes to read.

use std::io::{self, Read};

/// Most bytes of one line, line end included (one CSV record, or a run of blank lines before
/// the next): 1 MiB, a thousand times the 1 kB no line of a real recording reaches.
pub const MAX_LINE_BYTES: usize = 1 << 20;

/// Most rows a recording holds (of all its files together, and with its gaps filled): 10⁸,
/// 11.6 days at 100 Hz.
pub const MAX_ROWS: usize = 100_000_000;

/// Bytes the CSV parser buffers ahead of the row it is on (its `buffer_capacity`).
pub(super) const READ_AHEAD: usize = 64 * 1024;

/// A reader that fails once more than [`MAX_LINE_BYTES`] plus the parser's read-ahead have been
/// read since the last [`Capped::row_done`], and remembers the last byte read.
///
/// Written here because the `csv` crate grows a record's buffer without bound and has no
/// limit of its own. The parser reads at most [`READ_AHEAD`] bytes at a time, so a line of at
/// most [`MAX_LINE_BYTES`] always passes (at most that much of it, and one read beyond it, come
/// after the mark), and one longer than that plus twice the read-ahead always fails, the
/// parser then holding no more than that.
#[derive(Debug)]
pub(super) struct Capped<R> {
    inner: R,
    since_row: usize,
    exceeded: bool,
    last: Option<u8>,
}

impl<R: Read> Capped<R> {
    pub(super) fn new(inner: R) -> Self {
        Capped {
            inner,
            since_row: 0,
            exceeded: false,
            last: None,
        }
    }

    /// The parser has finished a row: the count starts again.
    pub(super) fn row_done(&mut self) {
        self.since_row = 0;
    }

    /// Whether the line limit stopped the reading.
    pub(super) fn exceeded(&self) -> bool {
        self.exceeded
    }

    /// Whether the last byte read ends a line (a CSV that ends with its newline).
    pub(super) fn ends_with_newline(&self) -> bool {
        matches!(self.last, Some(b'\n' | b'\r'))
    }
}

impl<R: Read> Read for Capped<R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.since_row += n;
        if self.since_row > MAX_LINE_BYTES + READ_AHEAD {
            self.exceeded = true;
            return Err(io::Error::new(
                io::ErrorKind::InvalidData,
                format!("a line longer than {MAX_LINE_BYTES} bytes"),
            ));
        }
        if n > 0 {
            self.last = Some(buf[n - 1]);
        }
        Ok(n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::recording::{read_from, ReadOptions, RecordingError};

    fn read(bytes: &[u8], opts: &ReadOptions) -> Result<usize, RecordingError> {
        read_from(bytes, "rec.csv", opts).map(|r| r.len())
    }

    #[test]
    fn a_line_at_the_limit_reads_and_a_longer_one_is_refused_wherever_it_is() {
        // A row whose unmapped cell fills its line to the limit, line end included.
        let mut text = b"t_s,op_pct,vp_pct,note\n0,1,2,x\n".to_vec();
        let row = b"1,2,3,";
        text.extend(row);
        text.extend(vec![b'a'; MAX_LINE_BYTES - row.len() - 1]);
        text.extend(b"\n2,3,4,y\n");
        assert_eq!(read(&text, &ReadOptions::default()).unwrap(), 3);

        // Beyond the limit and the read-ahead: one cell, NUL bytes, blank lines of either end,
        // and a header that never ends.
        let over = MAX_LINE_BYTES + 2 * READ_AHEAD + 1;
        let rows = b"t_s,op_pct,vp_pct\n0,1,2\n";
        for (head, fill, line) in [
            (&b"t_s,op_pct,vp_pct\n0,1,2\n1,2,"[..], b'7', 3),
            (rows, 0, 3),
            (rows, b'\n', 3),
            (rows, b'\r', 3),
            (b"", 0, 1),
        ] {
            let mut text = head.to_vec();
            text.extend(vec![fill; over]);
            let e = read(&text, &ReadOptions::default()).unwrap_err();
            assert!(
                matches!(e, RecordingError::LineTooLong { line: l, limit: MAX_LINE_BYTES, .. } if l == line),
                "{fill}: {e:?}"
            );
            assert!(
                e.to_string().starts_with(&format!(
                    "rec.csv:{line}: no line ends within 1048576 bytes (1 MiB"
                )),
                "{e}"
            );
        }
    }

    /// `t,50` rows for t = 0, 1, 2, ... without end.
    struct Endless(u64, Vec<u8>);

    impl Read for Endless {
        fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
            if self.1.is_empty() {
                self.1 = format!("{},50\n", self.0).into_bytes();
                self.0 += 1;
            }
            let n = buf.len().min(self.1.len());
            buf[..n].copy_from_slice(&self.1[..n]);
            self.1.drain(..n);
            Ok(n)
        }
    }

    #[test]
    fn an_input_that_never_ends_is_refused_at_the_row_limit() {
        let opts = ReadOptions {
            columns: "vp=".parse().unwrap(),
            max_rows: 1000,
            ..ReadOptions::default()
        };
        let input = (&b"t_s,op_pct\n"[..]).chain(Endless(0, Vec::new()));
        let e = read_from(input, "pipe", &opts).unwrap_err();
        assert_eq!(
            e.to_string(),
            "pipe:1002: more than 1000 rows on the time grid (0.00277778 h at 100 Hz), the most \
             a recording holds: cut the file, or read fewer files"
        );
        // Exactly the limit reads.
        let rows: String = (0..1000).map(|k| format!("{k},50\n")).collect();
        assert_eq!(
            read(format!("t_s,op_pct\n{rows}").as_bytes(), &opts).unwrap(),
            1000
        );
    }

    #[test]
    fn the_row_limit_holds_for_the_rows_that_fill_gaps() {
        // 300 rows 10 ms apart but every third interval 0.5 s: each of those 99 gaps is filled
        // with 49 rows.
        let mut text = String::from("t_s,op_pct,vp_pct\n");
        let mut t = 0.0;
        for k in 0..300 {
            text += &format!("{t:.2},50,50\n");
            t += if k % 3 == 2 { 0.5 } else { 0.01 };
        }
        let limit = |max_rows| ReadOptions {
            max_rows,
            ..ReadOptions::default()
        };
        assert_eq!(read(text.as_bytes(), &limit(5151)).unwrap(), 300 + 99 * 49);
        let e = read(text.as_bytes(), &limit(5150)).unwrap_err();
        assert!(
            matches!(
                e,
                RecordingError::TooManyRows {
                    limit: 5150,
                    line: 299,
                    ..
                }
            ),
            "{e:?}"
        );
    }
}
