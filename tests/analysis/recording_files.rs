//! Real recordings through the recording reader: the DAMADICS valve hour (1 Hz, other column
//! names) and two industrial loop files (BOM, newest row first, date and time columns, `NULL`
//! cells, no valve position). Each is loaded with the right options, and the one-line error it
//! gives without them is checked. The files and their provenance are in `tests/data/real/`.
//! Rotated logs join; gzip files read as gzip(1) reads them; the row limit holds for a set.

use std::io::Write;
use std::path::{Path, PathBuf};

use flate2::write::GzEncoder;
use flate2::Compression;
use valve_bridge::recording::{read, read_all, ReadOptions, Recording};

fn data(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/real")
        .join(rel)
}

fn options(columns: &str) -> ReadOptions {
    ReadOptions {
        columns: columns.parse().unwrap(),
        ..ReadOptions::default()
    }
}

/// The error message, checked to be one line that starts with the file's path.
fn error(path: &Path, opts: &ReadOptions) -> String {
    let e = read(path, opts).unwrap_err().to_string();
    assert!(!e.contains('\n'), "{e}");
    let rest = e.strip_prefix(&path.display().to_string()).unwrap();
    rest.to_string()
}

fn range(x: &[f64]) -> (f64, f64) {
    x.iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        })
}

const DAMADICS: &str = "damadics-actuator3-1h/actuator3_2001-10-11_1h_1Hz.csv";
const FIC211: &str = "plant-fic211-lic106/FIC-211_excerpt_lines_2402-4401.csv";
const LIC106: &str = "plant-fic211-lic106/LIC-106_head_1000.csv";

#[test]
fn damadics_hour_loads_with_a_column_mapping() {
    let path = data(DAMADICS);
    let e = error(&path, &ReadOptions::default());
    assert!(
        e.starts_with(":1: no column `op_pct`, `vp_pct`; the header has `t_s`, `P74_00_kPa`,"),
        "{e}"
    );
    assert!(
        e.ends_with(
            "name the columns with --columns t=TIME,op=OP,vp=VP (vp= for a file without V_P)"
        ),
        "{e}"
    );

    let r = read(&path, &options("t=t_s,op=LC74_20CV_pct,vp=LC74_20X_pct")).unwrap();
    assert_eq!(r.len(), 3600);
    assert_eq!(r.sample_period, 1.0);
    assert_eq!(r.duration(), 3599.0);
    assert!(r.warnings.is_empty(), "{:?}", r.warnings);
    // The ranges SOURCE.md states.
    assert_eq!(range(&r.op), (39.1, 78.6));
    assert_eq!(range(&r.vp), (48.7, 77.5));
    assert_eq!((r.op[0], r.vp[0]), (68.6, 68.3));
}

#[test]
fn plant_loop_errors_say_which_option_fixes_them() {
    let path = data(FIC211);
    let e = error(&path, &ReadOptions::default());
    assert_eq!(
        e,
        ":1: no column `t_s`, `op_pct`, `vp_pct`; the header has `id`, `date`, `time`, `FT_211`, \
         `FV_211`; name the columns with --columns t=TIME,op=OP,vp=VP (vp= for a file without V_P)"
    );
    let e = error(&path, &options("t=time,op=FV_211,vp="));
    assert_eq!(
        e,
        ":2: column `time`: `07:59:00` is not a finite number; it looks like a date or clock time: \
         --timestamps reads wall-clock times (t=DATE+TIME joins separate date and time columns)"
    );
    let e = error(&path, &options("t=date+time,op=FV_211,vp="));
    assert_eq!(
        e,
        ": times decrease on every row (newest row first); --reverse reads the file oldest first"
    );
}

#[test]
fn plant_loop_loads_oldest_first_as_op_only_or_with_the_flow() {
    let path = data(FIC211);
    let op_only = ReadOptions {
        reverse_sorted: true,
        ..options("t=date+time,op=FV_211,vp=")
    };
    let r = read(&path, &op_only).unwrap();
    assert_eq!(r.len(), 2000);
    assert!(r.vp.is_empty());
    assert_eq!(r.sample_period, 60.0);
    assert_eq!(r.duration(), 1999.0 * 60.0);
    assert!(r.warnings.is_empty(), "{:?}", r.warnings);
    // Oldest row (2024-11-24 22:40) first, newest (2024-11-26 07:59) last.
    assert_eq!(r.t[0], 0.0);
    assert_eq!(r.op[0], 34.4977989196777);
    assert_eq!(r.op[1999], 34.0732078552246);

    // The flow as a stand-in for the position: its 93 NULL cells keep their rows, without a
    // value, counted in one warning; the grid stays whole.
    let flow = ReadOptions {
        reverse_sorted: true,
        ..options("t=date+time,op=FV_211,vp=FT_211")
    };
    let r = read(&path, &flow).unwrap();
    assert_eq!(r.len(), 2000);
    assert_eq!(r.vp.iter().filter(|v| v.is_nan()).count(), 93);
    assert_eq!(r.sample_period, 60.0);
    assert!(r.restarts.is_empty());
    assert_eq!(r.warnings.len(), 1, "{:?}", r.warnings);
    assert!(
        r.warnings[0].starts_with("93 row(s) have no V_P"),
        "{:?}",
        r.warnings
    );
}

#[test]
fn second_plant_file_loads_the_same_way() {
    let opts = ReadOptions {
        reverse_sorted: true,
        ..options("t=date+time,op=LV_106,vp=")
    };
    let r: Recording = read(&data(LIC106), &opts).unwrap();
    assert_eq!(r.len(), 1000);
    assert_eq!((r.t[999], r.sample_period), (999.0 * 60.0, 60.0));
    assert_eq!(r.op[0], 45.9901733398438);
    assert_eq!(r.op[999], 44.9806976318359);
    assert_eq!(r.source, data(LIC106).display().to_string());
}

/// Writes a recording at 10 Hz from `t0` for `n` rows, with O_P stepping every 2 s.
fn rotated(dir: &Path, name: &str, t0: f64, n: usize) -> PathBuf {
    let mut text = String::from("t_s,op_pct,vp_pct\n");
    for k in 0..n {
        let op = 40.0 + 10.0 * ((k / 20) % 2) as f64;
        text.push_str(&format!("{:.1},{op},{op}\n", t0 + k as f64 * 0.1));
    }
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn rotated_logs_join_in_time_order_with_their_gap_kept() {
    let dir = tempfile::tempdir().unwrap();
    // Given newest first: joined oldest first; the 10 s between them stays a gap (a restart).
    let a = rotated(dir.path(), "vb-1.csv", 0.0, 100);
    let b = rotated(dir.path(), "vb-2.csv", 20.0, 100);
    let opts = ReadOptions::default();
    let rec = read_all(&[b.clone(), a.clone()], &opts).unwrap();
    assert_eq!(rec.t.len(), 200);
    assert_eq!((rec.t[99], rec.t[100]), (9.9, 20.0));
    assert_eq!(rec.restarts, vec![100]);
    assert!((rec.sample_period - 0.1).abs() < 1e-9);
    assert!(
        rec.source.ends_with("vb-1.csv (+1 files)"),
        "{}",
        rec.source
    );
    // A directory stands for its .csv files.
    assert_eq!(
        read_all(&[dir.path().to_path_buf()], &opts).unwrap().t,
        rec.t
    );
    // Files that overlap in time are refused, naming both.
    let c = rotated(dir.path(), "vb-3.csv", 5.0, 10);
    let e = read_all(&[a, c], &opts).unwrap_err().to_string();
    assert!(e.contains("vb-1.csv") && e.contains("vb-3.csv"), "{e}");
    assert!(e.contains("must not overlap"), "{e}");
    let empty = tempfile::tempdir().unwrap();
    let e = read_all(&[empty.path().to_path_buf()], &opts)
        .unwrap_err()
        .to_string();
    assert!(e.contains("no .csv file"), "{e}");
}

#[test]
fn a_set_may_end_with_a_short_file() {
    let dir = tempfile::tempdir().unwrap();
    let opts = ReadOptions::default();
    let a = rotated(dir.path(), "vb-1.csv", 0.0, 100);
    // The last file of a rotated set with one row; a file with none (a restart that wrote
    // only the header) or nothing at all (a crash right after a rotation) is skipped, with a
    // warning.
    let b = rotated(dir.path(), "vb-2.csv", 10.0, 1);
    let c = rotated(dir.path(), "vb-3.csv", 10.5, 0);
    let d = dir.path().join("vb-4.csv");
    std::fs::write(&d, "").unwrap();
    let rec = read_all(&[a, b.clone(), c, d], &opts).unwrap();
    assert_eq!(rec.t.len(), 101);
    for skipped in [
        "vb-3.csv: no data rows, skipped",
        "vb-4.csv: no data rows (empty file, not even a header), skipped",
    ] {
        assert!(
            rec.warnings.iter().any(|w| w.ends_with(skipped)),
            "{skipped}: {:?}",
            rec.warnings
        );
    }
    // Alone, a one-row file is no recording.
    let e = read_all(&[b], &opts).unwrap_err().to_string();
    assert!(
        e.ends_with("1 usable data row(s); a recording needs at least 2"),
        "{e}"
    );
}

/// `text` as one gzip member.
fn member(text: &str) -> Vec<u8> {
    let mut e = GzEncoder::new(Vec::new(), Compression::default());
    e.write_all(text.as_bytes()).unwrap();
    e.finish().unwrap()
}

#[test]
fn a_csv_gz_reads_as_gzip_reads_it() {
    let dir = tempfile::tempdir().unwrap();
    let opts = ReadOptions::default();
    let plain = rotated(dir.path(), "plain.csv", 0.0, 100);
    let text = std::fs::read_to_string(&plain).unwrap();
    let want = read(&plain, &opts).unwrap();
    let cut = text.match_indices('\n').nth(50).unwrap().0 + 1;
    let gz = |name: &str, bytes: &[u8]| {
        let path = dir.path().join(name);
        std::fs::write(&path, bytes).unwrap();
        path
    };
    // Two members, as `cat a.gz b.gz` makes them: one recording.
    let two = gz(
        "two.csv.gz",
        &[member(&text[..cut]), member(&text[cut..])].concat(),
    );
    let rec = read(&two, &opts).unwrap();
    assert_eq!((&rec.t, &rec.op, &rec.vp), (&want.t, &want.op, &want.vp));
    assert!(rec.warnings.is_empty(), "{:?}", rec.warnings);
    // The zero padding a crash can leave after the data, and garbage: ignored, with a warning.
    let padded = gz("padded.csv.gz", &[member(&text), vec![0; 8192]].concat());
    let rec = read(&padded, &opts).unwrap();
    assert_eq!(rec.t, want.t);
    assert_eq!(
        rec.warnings,
        ["8192 zero bytes after the last gzip member ignored (padding; gzip(1) ignores it too)"]
    );
    let garbage = gz(
        "garbage.csv.gz",
        &[member(&text), b"\0\0\0garbage\n".to_vec()].concat(),
    );
    let rec = read(&garbage, &opts).unwrap();
    assert_eq!(rec.t, want.t);
    assert!(
        rec.warnings[0].contains("trailing garbage"),
        "{:?}",
        rec.warnings
    );
    // In a set, the warning names the file.
    let later = rotated(dir.path(), "later.csv", 20.0, 10);
    let rec = read_all(&[padded.clone(), later], &opts).unwrap();
    assert!(
        rec.warnings
            .iter()
            .any(|w| w.starts_with(&format!("{}: 8192 zero bytes", padded.display()))),
        "{:?}",
        rec.warnings
    );
}

#[test]
fn the_row_limit_counts_every_file_of_a_set() {
    let dir = tempfile::tempdir().unwrap();
    let a = rotated(dir.path(), "vb-1.csv", 0.0, 100);
    let b = rotated(dir.path(), "vb-2.csv", 20.0, 100);
    let limit = |max_rows| ReadOptions {
        max_rows,
        ..ReadOptions::default()
    };
    assert_eq!(
        read_all(&[a.clone(), b.clone()], &limit(200))
            .unwrap()
            .len(),
        200
    );
    let e = read_all(&[a, b.clone()], &limit(150))
        .unwrap_err()
        .to_string();
    assert_eq!(
        e,
        format!(
            "{}:52: more than 150 rows on the time grid (0.000416667 h at 100 Hz), the most a \
             recording holds: cut the file, or read fewer files",
            b.display()
        )
    );
}
