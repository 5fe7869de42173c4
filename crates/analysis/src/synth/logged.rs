//! What the daemon's log makes of a recording: set-point and position in per mille of travel
//! (a positioner's registers), and rows without V_P where a reply was lost (status `timeout`,
//! an empty cell), in bursts of one to three rows. For tests and benchmarks that check an
//! analysis gives on such a log what it gives on the intact recording.
//!
//! Not here: the daemon's logger itself (`daemon::runtime::logger`), or reading logs (`recording`).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use vb_core::recording::Recording;

/// Resolution of a register holding a position in per mille of travel, %.
pub const PER_MILLE_PCT: f64 = 0.1;

/// `rec` as the daemon would log it: O_P and V_P rounded to [`PER_MILLE_PCT`], and V_P missing
/// (NaN, status `timeout`) on `missing_share` of the rows, in bursts of 1-3 rows placed at
/// random (seeded by `seed`); the other rows get status `ok`. Times, restarts and the sample
/// period are kept.
pub fn as_logged(rec: &Recording, missing_share: f64, seed: u64) -> Recording {
    let round = |x: &f64| (x / PER_MILLE_PCT).round() * PER_MILLE_PCT;
    let n = rec.len();
    let mut vp: Vec<f64> = rec.vp.iter().map(round).collect();
    let mut missing = vec![false; n];
    let want = (missing_share.clamp(0.0, 0.5) * n as f64).round() as usize;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut count = 0;
    while count < want && !vp.is_empty() {
        let at = rng.gen_range(0..n);
        let burst: usize = rng.gen_range(1..=3);
        for k in at..(at + burst).min(n) {
            if !missing[k] && count < want {
                missing[k] = true;
                vp[k] = f64::NAN;
                count += 1;
            }
        }
    }
    let status = (0..n)
        .map(|k| if missing[k] { "timeout" } else { "ok" }.to_string())
        .collect();
    Recording {
        op: rec.op.iter().map(round).collect(),
        vp,
        status,
        warnings: Vec::new(),
        ..rec.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_log_rounds_to_per_mille_and_loses_replies_in_bursts() {
        let n = 20000;
        let t: Vec<f64> = (0..n).map(|k| k as f64 * 0.01).collect();
        let x: Vec<f64> = (0..n).map(|k| 50.0 + 0.0137 * (k % 700) as f64).collect();
        let rec = Recording::from_vectors(t, x.clone(), x).unwrap();
        let log = as_logged(&rec, 0.005, 7);
        assert_eq!(log.len(), n);
        let lost: Vec<usize> = (0..n).filter(|&k| log.vp[k].is_nan()).collect();
        assert_eq!(lost.len(), 100);
        assert!(lost.iter().all(|&k| log.status[k] == "timeout"));
        assert_eq!(log.status.iter().filter(|s| *s == "ok").count(), n - 100);
        // Bursts of at most three rows (two bursts may touch).
        let longest = lost.windows(4).filter(|w| w[3] - w[0] == 3).count();
        assert!(longest <= 2, "{longest}");
        for (k, (&a, &b)) in rec.op.iter().zip(&log.op).enumerate() {
            assert!((a - b).abs() <= 0.05 + 1e-9, "{k}");
            assert!(((b / 0.1).round() * 0.1 - b).abs() < 1e-9, "{k}");
        }
        // Deterministic for a seed (NaN is not equal to itself: compare the statuses).
        assert!(as_logged(&rec, 0.005, 7).status == log.status);
        assert!(as_logged(&rec, 0.005, 8).status != log.status);
    }
}
