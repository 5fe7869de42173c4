//! Gzip-compressed recordings: the daemon compresses each log file it has closed, and every
//! reader takes `.csv.gz` files as they are.
//!
//! A file is compressed into `NAME.csv.gz.part`, synced, renamed to `NAME.csv.gz`, and only then
//! is `NAME.csv` removed, so a crash at any point leaves a complete file under one of the two
//! names (when both are left, readers take the plain one, see [`super::join`]). Reading detects
//! gzip by its magic bytes, not by the name. flate2 (its pure-Rust backends) does the work.
//!
//! Not here: which files are compressed and when (the daemon's logger), other formats.

use std::fs::File;
use std::io::{self, BufRead, BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};

use flate2::bufread::GzDecoder;
use flate2::write::GzEncoder;
use flate2::Compression;

/// The two bytes every gzip member starts with.
const MAGIC: [u8; 2] = [0x1f, 0x8b];

/// A recording file opened for reading: as it is, or decompressed as it is read when it is
/// gzip.
#[derive(Debug)]
pub struct Input(Inner);

#[derive(Debug)]
enum Inner {
    Plain(BufReader<File>),
    Gzip(Members<BufReader<File>>),
}

/// Opens `path` for reading, decompressing it on the fly when it is gzip.
pub fn open(path: &Path) -> io::Result<Input> {
    let mut file = BufReader::new(File::open(path)?);
    if file.fill_buf()?.starts_with(&MAGIC) {
        Ok(Input(Inner::Gzip(Members::new(file))))
    } else {
        Ok(Input(Inner::Plain(file)))
    }
}

impl Read for Input {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        match &mut self.0 {
            Inner::Plain(r) => r.read(buf),
            Inner::Gzip(r) => r.read(buf),
        }
    }
}

impl Input {
    /// What was tolerated in what has been read: data after the last gzip member.
    pub fn warning(&self) -> Option<String> {
        match &self.0 {
            Inner::Gzip(m) => m.warning(),
            Inner::Plain(_) => None,
        }
    }
}

/// Every member of a gzip stream in turn, as gzip(1) reads them (`cat a.gz b.gz` holds two);
/// what follows the last complete member and is none (the zero padding a crash can leave at the
/// end of a file, garbage) ends the data, with a warning, as gzip(1) ends it. A member that
/// starts but is damaged or cut short is an error.
///
/// Written here because flate2's `MultiGzDecoder` fails on anything after the last member
/// ("invalid gzip header"), so a file gzip(1) reads would not be read.
#[derive(Debug)]
struct Members<R> {
    member: Option<GzDecoder<R>>,
    tail: Tail,
}

/// What followed the last member.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Tail {
    Nothing,
    /// This many zero bytes.
    Zeros(u64),
    /// Bytes that are not all zero and start no gzip member.
    Garbage,
}

impl<R: BufRead> Members<R> {
    fn new(r: R) -> Self {
        Members {
            member: Some(GzDecoder::new(r)),
            tail: Tail::Nothing,
        }
    }

    fn warning(&self) -> Option<String> {
        match self.tail {
            Tail::Nothing => None,
            Tail::Zeros(n) => Some(format!(
                "{} after the last gzip member ignored (padding; gzip(1) ignores it too)",
                crate::human::count(n, "zero byte")
            )),
            Tail::Garbage => Some(
                "data after the last gzip member that starts no member ignored (gzip(1) ignores \
                 such trailing garbage too)"
                    .into(),
            ),
        }
    }
}

impl<R: BufRead> Read for Members<R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        while let Some(member) = &mut self.member {
            let n = member.read(buf)?;
            if n > 0 || buf.is_empty() {
                return Ok(n);
            }
            // The member is complete and its checksum right: another one, the end, or a tail.
            let Some(done) = self.member.take() else {
                break;
            };
            let mut rest = done.into_inner();
            match rest.fill_buf()?.first() {
                None => {}
                Some(&b) if b == MAGIC[0] => {
                    let next = GzDecoder::new(rest);
                    if next.header().is_some() {
                        self.member = Some(next);
                    } else {
                        self.tail = Tail::Garbage;
                    }
                }
                Some(_) => self.tail = tail(&mut rest)?,
            }
        }
        Ok(0)
    }
}

/// Reads the bytes after the last member: all zero (how many), or garbage (read no further).
fn tail<R: BufRead>(rest: &mut R) -> io::Result<Tail> {
    let mut zeros = 0u64;
    loop {
        let buf = rest.fill_buf()?;
        if buf.is_empty() {
            return Ok(Tail::Zeros(zeros));
        }
        if buf.iter().any(|&b| b != 0) {
            return Ok(Tail::Garbage);
        }
        let n = buf.len();
        zeros += n as u64;
        rest.consume(n);
    }
}

/// Whether `name` is a recording file by its name: `.csv` or `.csv.gz` (any case).
pub fn is_recording_name(name: &str) -> bool {
    let lower = name.to_ascii_lowercase();
    lower.ends_with(".csv") || lower.ends_with(".csv.gz")
}

/// `name` without its `.csv` or `.csv.gz` ending.
pub fn stem(name: &str) -> &str {
    let lower = name.to_ascii_lowercase();
    for end in [".csv.gz", ".csv"] {
        if lower.ends_with(end) {
            return &name[..name.len() - end.len()];
        }
    }
    name
}

/// Compresses the closed file `path` into `path.gz` and removes `path`; the new path.
pub fn compress(path: &Path) -> io::Result<PathBuf> {
    let mut gz_name = path.as_os_str().to_owned();
    gz_name.push(".gz");
    let gz = PathBuf::from(gz_name);
    let mut part_name = gz.as_os_str().to_owned();
    part_name.push(".part");
    let part = PathBuf::from(part_name);
    let result = (|| {
        let mut input = File::open(path)?;
        let out = File::options().write(true).create_new(true).open(&part)?;
        let mut encoder = GzEncoder::new(BufWriter::new(out), Compression::default());
        io::copy(&mut input, &mut encoder)?;
        let out = encoder.finish()?.into_inner().map_err(|e| e.into_error())?;
        out.sync_all()?;
        std::fs::rename(&part, &gz)?;
        std::fs::remove_file(path)
    })();
    if result.is_err() {
        // Best effort: a half-written part is no use to anyone; the plain file is kept.
        std::fs::remove_file(&part).ok();
    }
    result.map(|()| gz)
}

/// Writes `bytes` gzip-compressed to `path` (tests and tools that make compressed recordings).
pub fn write(path: &Path, bytes: &[u8]) -> io::Result<()> {
    let mut encoder = GzEncoder::new(File::create(path)?, Compression::default());
    encoder.write_all(bytes)?;
    encoder.finish()?.sync_all()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_compressed_file_reads_back_as_the_plain_one_and_replaces_it() {
        let dir = tempfile::tempdir().unwrap();
        let plain = dir.path().join("vb-20261125T101500Z.csv");
        let text = "t_s,op_pct,vp_pct\n0.0,1.0,2.0\n0.01,1.0,2.5\n".repeat(50);
        std::fs::write(&plain, &text).unwrap();
        let gz = compress(&plain).unwrap();
        assert_eq!(gz, dir.path().join("vb-20261125T101500Z.csv.gz"));
        assert!(!plain.exists() && gz.exists());
        assert!(std::fs::metadata(&gz).unwrap().len() < text.len() as u64 / 4);
        let mut back = String::new();
        open(&gz).unwrap().read_to_string(&mut back).unwrap();
        assert_eq!(back, text);
        // A plain file is read as it is, whatever its name.
        std::fs::write(&plain, "t").unwrap();
        let mut back = String::new();
        open(&plain).unwrap().read_to_string(&mut back).unwrap();
        assert_eq!(back, "t");
    }

    /// `text` compressed as one gzip member.
    fn member(text: &str) -> Vec<u8> {
        let mut e = GzEncoder::new(Vec::new(), Compression::default());
        e.write_all(text.as_bytes()).unwrap();
        e.finish().unwrap()
    }

    /// Reads `bytes` written to a `.csv.gz` file: the text, or the error, and the warning.
    fn read_as_file(bytes: &[u8]) -> (Result<String, String>, Option<String>) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("rec.csv.gz");
        std::fs::write(&path, bytes).unwrap();
        let mut input = open(&path).unwrap();
        let mut text = String::new();
        let r = input.read_to_string(&mut text).map_err(|e| e.to_string());
        (r.map(|_| text), input.warning())
    }

    #[test]
    fn every_member_is_read_and_what_follows_the_last_is_ignored_with_a_warning() {
        let (a, b) = (member("t_s,op_pct\n0,1\n"), member("1,2\n"));
        let two = [a.clone(), b.clone()].concat();
        assert_eq!(
            read_as_file(&two),
            (Ok("t_s,op_pct\n0,1\n1,2\n".into()), None)
        );

        let mut padded = two.clone();
        padded.extend([0u8; 4096]);
        let (text, warning) = read_as_file(&padded);
        assert_eq!(text.unwrap(), "t_s,op_pct\n0,1\n1,2\n");
        assert_eq!(
            warning.unwrap(),
            "4096 zero bytes after the last gzip member ignored (padding; gzip(1) ignores it too)"
        );
        for garbage in [&b"\0\0junk"[..], b"\x1f not a member", b"\x1f"] {
            let (text, warning) = read_as_file(&[a.as_slice(), garbage].concat());
            assert_eq!(text.unwrap(), "t_s,op_pct\n0,1\n", "{garbage:?}");
            assert!(warning.unwrap().contains("trailing garbage"), "{garbage:?}");
        }
        // A member that starts but is cut short or damaged is an error, as for gzip(1).
        let (text, _) = read_as_file(&[a.as_slice(), &b[..b.len() - 3]].concat());
        assert!(text.is_err(), "{text:?}");
        let mut damaged = b.clone();
        let at = damaged.len() - 6;
        damaged[at] ^= 0xff;
        let (text, _) = read_as_file(&[a.as_slice(), &damaged].concat());
        assert!(text.is_err(), "{text:?}");
    }

    #[test]
    fn names_and_stems() {
        assert!(is_recording_name("a.csv") && is_recording_name("A.CSV.GZ"));
        assert!(!is_recording_name("a.csv.gz.part") && !is_recording_name("a.gz"));
        assert_eq!(stem("vb-x.csv.gz"), "vb-x");
        assert_eq!(stem("vb-x.CSV"), "vb-x");
    }
}
