//! Writing recording files: [`write()`] for a [`Recording`], [`write_columns`] for any named
//! columns (e.g. a simulated run's `t_s,op_pct,vp_pct,vp_meas_pct`).
//!
//! Numbers use Rust's shortest round-trip formatting (`{}`), so reading a file back gives the
//! identical `f64` values. A NaN is written as an empty cell (a value that does not exist, as in
//! the daemon's logs), which the reader treats as missing.

use std::fmt::Write as _;
use std::path::Path;

use super::{Recording, RecordingError};

/// Writes `rec` as `t_s,op_pct,vp_pct` (or `t_s,op_pct` when it has no V_P).
pub fn write(path: &Path, rec: &Recording) -> Result<(), RecordingError> {
    if rec.vp.is_empty() {
        write_columns(path, &["t_s", "op_pct"], &[&rec.t, &rec.op])
    } else {
        write_columns(
            path,
            &["t_s", "op_pct", "vp_pct"],
            &[&rec.t, &rec.op, &rec.vp],
        )
    }
}

/// Writes a header of `names` and one row per index of `cols` (all of one length, one per
/// name), creating or truncating `path`.
pub fn write_columns(path: &Path, names: &[&str], cols: &[&[f64]]) -> Result<(), RecordingError> {
    let label = path.display().to_string();
    let rows = cols.first().map_or(0, |c| c.len());
    if names.len() != cols.len() || cols.iter().any(|c| c.len() != rows) {
        let lengths: Vec<String> = cols.iter().map(|c| c.len().to_string()).collect();
        return Err(RecordingError::Invalid {
            file: label,
            detail: format!(
                "cannot write {} names over {} columns of lengths [{}]; they must match",
                names.len(),
                cols.len(),
                lengths.join(", ")
            ),
        });
    }
    let io_error = |e: csv::Error| RecordingError::Io {
        file: label.clone(),
        action: "cannot write",
        source: e.into(),
    };
    let mut csv = csv::Writer::from_path(path).map_err(io_error)?;
    csv.write_record(names).map_err(io_error)?;
    let mut cell = String::new();
    for i in 0..rows {
        for col in cols {
            cell.clear();
            if !col[i].is_nan() {
                // Writing to a String cannot fail.
                let _ = write!(cell, "{}", col[i]);
            }
            csv.write_field(&cell).map_err(io_error)?;
        }
        csv.write_record(None::<&[u8]>).map_err(io_error)?;
    }
    csv.flush().map_err(|e| io_error(e.into()))
}

#[cfg(test)]
mod tests {
    use super::super::{read, ReadOptions};
    use super::*;

    #[test]
    fn round_trip_is_exact_and_nan_is_an_empty_cell() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sim.csv");
        let t: Vec<f64> = (0..5).map(|k| k as f64 * 0.01).collect();
        let op = [0.1 + 0.2, 1.0 / 3.0, 1e-300, 12345.678901234567, 50.0];
        let vp = [999_999.999_999_9, -0.0, 2.0f64.sqrt(), 99.99, 100.0];
        let meas = [1.0, f64::NAN, 3.0, 4.0, 5.0];
        write_columns(
            &path,
            &["t_s", "op_pct", "vp_pct", "vp_meas_pct"],
            &[&t, &op, &vp, &meas],
        )
        .unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.starts_with("t_s,op_pct,vp_pct,vp_meas_pct\n0,0.30000000000000004,"));
        assert_eq!(text.lines().nth(2), Some("0.01,0.3333333333333333,-0,"));
        let r = read(&path, &ReadOptions::default()).unwrap();
        assert_eq!(
            (r.t, r.op.as_slice(), r.vp.as_slice()),
            (t, op.as_slice(), vp.as_slice())
        );

        let rec = Recording::from_vectors(vec![0.0, 1.0], vec![1.0, 2.0], vec![]).unwrap();
        write(&path, &rec).unwrap();
        assert_eq!(
            std::fs::read_to_string(&path).unwrap(),
            "t_s,op_pct\n0,1\n1,2\n"
        );
    }

    #[test]
    fn shape_and_io_errors() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.csv");
        let e = write_columns(&path, &["a", "b"], &[&[1.0, 2.0], &[1.0]]).unwrap_err();
        assert!(
            e.to_string().ends_with(
                "cannot write 2 names over 2 columns of lengths [2, 1]; they must match"
            ),
            "{e}"
        );
        let e = write_columns(&dir.path().join("no/such.csv"), &["a"], &[&[1.0]]).unwrap_err();
        assert!(e.to_string().contains("no/such.csv: cannot write: "), "{e}");
    }
}
