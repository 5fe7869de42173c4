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
use std::io::{self, BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};

use flate2::read::MultiGzDecoder;
use flate2::write::GzEncoder;
use flate2::Compression;

/// The two bytes every gzip member starts with.
const MAGIC: [u8; 2] = [0x1f, 0x8b];

/// Opens `path` for reading, decompressing it on the fly when it is gzip.
pub fn open(path: &Path) -> io::Result<Box<dyn Read + Send>> {
    let mut file = BufReader::new(File::open(path)?);
    let mut head = [0u8; 2];
    let n = peek(&mut file, &mut head)?;
    if n == 2 && head == MAGIC {
        Ok(Box::new(BufReader::new(MultiGzDecoder::new(file))))
    } else {
        Ok(Box::new(file))
    }
}

/// Fills `head` from the reader's buffer without consuming it; the number of bytes available.
fn peek(file: &mut BufReader<File>, head: &mut [u8; 2]) -> io::Result<usize> {
    use std::io::BufRead;
    let buf = file.fill_buf()?;
    let n = buf.len().min(2);
    head[..n].copy_from_slice(&buf[..n]);
    Ok(n)
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

    #[test]
    fn names_and_stems() {
        assert!(is_recording_name("a.csv") && is_recording_name("A.CSV.GZ"));
        assert!(!is_recording_name("a.csv.gz.part") && !is_recording_name("a.gz"));
        assert_eq!(stem("vb-x.csv.gz"), "vb-x");
        assert_eq!(stem("vb-x.CSV"), "vb-x");
    }
}
