//! Bad inputs meet a one-line error, never a panic: the corpus of bad recordings and configs in
//! `tests/data/bad/` (each listed in `expected.txt` with its error, `FILE` standing for its
//! path), recordings sampled every 30 s through every analysis command, sample periods no
//! delay line can serve, and inputs made to exhaust memory (gzip bombs, a replay of
//! `/dev/zero` or of a pipe that never ends), refused within a bounded peak memory measured
//! on the child process.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use flate2::write::GzEncoder;
use flate2::Compression;

use crate::common;

fn bin() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_valve-bridge"));
    c.current_dir(env!("CARGO_MANIFEST_DIR"))
        .env("RUST_LOG", "error");
    c
}

/// Runs `args`; returns (exit code, stderr's error line), asserting there was no panic and the
/// error is one line.
fn run(args: &[&str]) -> (i32, String) {
    let out = bin().args(args).output().expect("run valve-bridge");
    let stderr = String::from_utf8_lossy(&out.stderr);
    error_line(args, out.status.code().unwrap_or(-1), &stderr)
}

/// (exit code, stderr's error line) of a run of `args`, asserting there was no panic and the
/// error is one line.
fn error_line(args: &[&str], code: i32, stderr: &str) -> (i32, String) {
    assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
    assert!(code == 0 || code == 1, "{args:?}: exit {code}: {stderr}");
    let errors: Vec<&str> = stderr
        .lines()
        .filter(|l| l.starts_with("valve-bridge: error: "))
        .collect();
    assert!(errors.len() <= 1, "{args:?}: {stderr}");
    let line = errors
        .first()
        .map_or("", |l| &l["valve-bridge: error: ".len()..]);
    (code, line.to_string())
}

#[test]
fn every_bad_file_gets_its_one_line_error() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/bad");
    let list = std::fs::read_to_string(dir.join("expected.txt")).unwrap();
    let mut checked = 0;
    for entry in list.lines().filter(|l| !l.trim().is_empty()) {
        let (name, expected) = entry.split_once('\t').expect("NAME<TAB>ERROR");
        let rel = format!("tests/data/bad/{name}");
        let (code, line) = if name.ends_with(".toml") {
            let log = tempfile::tempdir().unwrap();
            let log = log.path().to_str().unwrap().to_string();
            run(&[
                "run",
                "--config",
                &rel,
                "--duration",
                "0.05",
                "--log-dir",
                &log,
            ])
        } else {
            run(&["steps", &rel])
        };
        assert_eq!(code, 1, "{name}");
        assert_eq!(line, expected.replace("FILE", &rel), "{name}");
        checked += 1;
    }
    assert!(checked >= 40, "{checked} bad files");
    let files = std::fs::read_dir(&dir).unwrap().count();
    // Every file but the list and the year-long replay the config points to is a case.
    assert_eq!(
        files,
        checked + 2,
        "a file in tests/data/bad without an expected error"
    );
}

/// A recording of `n` rows every `dt` seconds: steps of O_P every 5 rows, V_P following one
/// row late.
fn slow_recording(dir: &Path, n: usize, dt: f64) -> PathBuf {
    let mut text = String::from("t_s,op_pct,vp_pct\n");
    let level = |k: usize| 30.0 + 7.0 * ((k / 5) % 6) as f64;
    for k in 0..n {
        text += &format!(
            "{},{},{}\n",
            k as f64 * dt,
            level(k),
            level(k.saturating_sub(1)) + 0.01 * (k % 3) as f64
        );
    }
    let p = dir.join(format!("slow_{n}_{dt}.csv"));
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn recordings_sampled_every_25_to_60_s_give_a_result_or_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let model = "config/models/pincart2.toml";
    for dt in [25.0, 30.0, 60.0] {
        let rec = slow_recording(dir.path(), 240, dt);
        let rec = rec.to_str().unwrap();
        let sim = dir.path().join("sim.csv");
        for args in [
            vec!["identify", rec],
            vec!["steps", rec],
            vec!["diagnose", rec],
            vec![
                "simulate",
                "--model",
                model,
                "--input",
                rec,
                "--out",
                sim.to_str().unwrap(),
            ],
        ] {
            let (code, line) = run(&args);
            assert!(code == 0 || !line.is_empty(), "{args:?}");
        }
    }
}

#[test]
fn a_sample_period_no_delay_line_can_serve_is_refused_by_the_model() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("fast.csv");
    let mut text = String::from("t_s,op_pct,vp_pct\n");
    for k in 0..50 {
        text += &format!("{},{},50\n", k as f64 * 1e-9, 40 + k % 2);
    }
    std::fs::write(&rec, text).unwrap();
    let out = dir.path().join("sim.csv");
    let (code, line) = run(&[
        "simulate",
        "--model",
        "config/models/pincart2.toml",
        "--input",
        rec.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 1);
    assert!(
        line.contains("needs a delay line of 380000000 samples; at most 10000000 fit"),
        "{line}"
    );
}

/// Peak memory a reader may take to refuse an input made to exhaust it: 300 MB, in KiB.
const REFUSAL_PEAK_KIB: i64 = 300_000_000 / 1024;

/// Runs `args` with its memory watched (killed past [`REFUSAL_PEAK_KIB`]); the error line and
/// the peak, KiB, asserting it failed with one line and was not killed.
fn refused(args: &[&str]) -> (String, i64) {
    let run = common::run_watched(bin().args(args), REFUSAL_PEAK_KIB, Duration::from_secs(300));
    assert_eq!(run.killed, None, "{args:?}: {}", run.stderr);
    let (code, line) = error_line(args, run.code.unwrap_or(-1), &run.stderr);
    assert_eq!(code, 1, "{args:?}: {}", run.stderr);
    (line, run.peak_kib)
}

/// `bytes` as one gzip member.
fn member(bytes: &[u8]) -> Vec<u8> {
    let mut e = GzEncoder::new(Vec::new(), Compression::best());
    e.write_all(bytes).unwrap();
    e.finish().unwrap()
}

/// A gzip bomb at `path`: `head`, then `gib` GiB of the byte `fill` as the same member of 1 MiB
/// over and over (each about 1 kB), as `cat` of gzip files makes them.
fn bomb(path: &Path, head: &str, fill: u8, gib: usize) {
    let mib = member(&vec![fill; 1 << 20]);
    let mut out = BufWriter::new(File::create(path).unwrap());
    out.write_all(&member(head.as_bytes())).unwrap();
    for _ in 0..gib << 10 {
        out.write_all(&mib).unwrap();
    }
    out.into_inner().unwrap().sync_all().unwrap();
}

#[test]
fn gzip_bombs_are_refused_in_bounded_memory_naming_the_limit_and_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let rows = "t_s,op_pct,vp_pct\n0,1,2\n";
    // One line of 1 GiB (a V_P cell), 1 GiB of NUL bytes, 1 GiB of blank lines.
    for (name, head, fill) in [
        ("line.csv.gz", format!("{rows}1,2,"), b'7'),
        ("nul.csv.gz", rows.to_string(), 0),
        ("blank.csv.gz", rows.to_string(), b'\n'),
    ] {
        let path = dir.path().join(name);
        bomb(&path, &head, fill, 1);
        let size = std::fs::metadata(&path).unwrap().len();
        assert!(size < 2_000_000, "{name}: {size} bytes");
        let file = path.to_str().unwrap();
        let (line, peak) = refused(&["steps", file]);
        assert_eq!(
            line,
            format!(
                "{file}:3: no line ends within 1048576 bytes (1 MiB, the longest line a \
                 recording may have); the file is damaged or no recording (a decompression \
                 bomb, a device such as /dev/zero)"
            )
        );
        println!("{name}: {size} bytes, refused at a peak of {peak} KiB");
    }
}

/// `run` with `[source.replay] file = FILE`, on the virtual clock: the error line and the peak
/// memory, KiB.
fn replay(dir: &Path, file: &Path) -> (String, i64) {
    let config = dir.join("replay.toml");
    std::fs::write(
        &config,
        format!("[source]\nkind = \"replay\"\n[source.replay]\nfile = {file:?}\n"),
    )
    .unwrap();
    let logs = dir.join("logs");
    refused(&[
        "run",
        "--config",
        config.to_str().unwrap(),
        "--as-fast-as-possible",
        "--duration",
        "1",
        "--log-dir",
        logs.to_str().unwrap(),
    ])
}

#[test]
fn a_replay_of_dev_zero_is_refused_in_bounded_memory() {
    let dir = tempfile::tempdir().unwrap();
    let (line, peak) = replay(dir.path(), Path::new("/dev/zero"));
    let config = dir.path().join("replay.toml");
    assert_eq!(
        line,
        format!(
            "{}:4: source.replay.file: cannot replay `/dev/zero`: /dev/zero:1: no line ends \
             within 1048576 bytes (1 MiB, the longest line a recording may have); the file is \
             damaged or no recording (a decompression bomb, a device such as /dev/zero)",
            config.display()
        )
    );
    println!("/dev/zero: refused at a peak of {peak} KiB");
}

#[test]
fn a_replay_of_a_pipe_that_never_ends_is_refused_at_its_row_limit() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("rows.fifo");
    let made = Command::new("mkfifo").arg(&fifo).status().unwrap();
    assert!(made.success());
    // Rows one second apart, without end (until the reader goes away).
    let writer = fifo.clone();
    std::thread::spawn(move || {
        let Ok(file) = std::fs::OpenOptions::new().write(true).open(writer) else {
            return;
        };
        let mut w = BufWriter::with_capacity(1 << 16, file);
        let tails: Vec<String> = (0..10_000).map(|k| format!("{k:04},50\n")).collect();
        let mut ok = w.write_all(b"t_s,op_pct\n").is_ok();
        for block in 1u64.. {
            let head = block.to_string();
            for tail in &tails {
                ok = ok
                    && w.write_all(head.as_bytes()).is_ok()
                    && w.write_all(tail.as_bytes()).is_ok();
            }
            if !ok {
                return;
            }
        }
    });
    let (line, peak) = replay(dir.path(), &fifo);
    let file = fifo.display();
    assert!(
        line.ends_with(&format!(
            "cannot replay `{file}`: {file}:10000002: more than 10000000 rows on the time grid \
             (27.7778 h at 100 Hz), the most a recording holds: cut the file, or read fewer files"
        )),
        "{line}"
    );
    println!("endless pipe: refused at a peak of {peak} KiB");
}
