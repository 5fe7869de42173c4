//! The response test as the loop's O_P source: walks a plan's [`Move`]s, holding each step until
//! V_P has settled (at least the plan's shortest hold, at most its longest) and ramping the
//! signature at its rate. It sees each cycle's row ([`Schedule::feedback`]) to judge the valve
//! still: the mean of V_P over one `still_s` against the mean over the one before, from measured
//! rows only (a row without V_P is neither still nor moving), within `still_pct` or four
//! standard errors of the difference, whichever is larger (so a noisy V_P is not taken for a
//! moving one).
//!
//! Asking and feeding back never allocate: the moves are laid out once, the stillness is kept
//! in running sums. Not here: the plan's checks ([`super::plan`]), the clamp to the source's
//! range (the daemon's `vb_daemon::runtime::source::Source`).

use super::{HoldRule, Move, Plan};
use crate::recording::log_format::{Sample, Status};

/// A plan being walked.
#[derive(Debug)]
pub struct Schedule {
    moves: Vec<Move>,
    hold: HoldRule,
    /// The move under way (`moves.len()` once done).
    at: usize,
    /// When it started, s of loop time.
    started_s: f64,
    /// The O_P it started from (where a ramp starts).
    from_pct: f64,
    /// The loop period, s.
    period_s: f64,
    still: Still,
}

/// Running sums of V_P over the current stillness window and the verdict of the last two.
#[derive(Debug, Default)]
struct Still {
    window_start_s: f64,
    n: f64,
    sum: f64,
    sum_sq: f64,
    /// Mean and count of the window before, when it had enough rows.
    previous: Option<(f64, f64)>,
    /// Whether the last two windows agreed.
    settled: bool,
}

/// Share of a window's rows that must hold a V_P for it to be judged.
const MEASURED_SHARE: f64 = 0.5;
/// Slack on loop times, so a hold of 5 s at 100 Hz ends after 500 slots, not 501.
const TIME_EPS: f64 = 1e-9;

impl Schedule {
    /// A schedule of `plan` for a loop of period `period_s`.
    pub fn new(plan: &Plan, period_s: f64) -> Schedule {
        let moves = plan.moves();
        let first = match moves.first() {
            Some(Move::Hold { op_pct, .. }) => *op_pct,
            _ => 0.0,
        };
        Schedule {
            moves,
            hold: plan.hold,
            at: 0,
            started_s: 0.0,
            from_pct: first,
            period_s,
            still: Still::default(),
        }
    }

    /// The O_P at loop time `t_s` (non-decreasing); `None` once the plan is done.
    pub fn op_at(&mut self, t_s: f64) -> Option<f64> {
        loop {
            let op = match *self.moves.get(self.at)? {
                Move::Hold { op_pct, .. } => {
                    let held = t_s - self.started_s;
                    let done = held >= self.hold.max_s - TIME_EPS
                        || (held >= self.hold.min_s - TIME_EPS && self.still.settled);
                    (!done).then_some(op_pct)
                }
                Move::Ramp {
                    to_pct,
                    rate_pct_per_s,
                } => {
                    let dir = (to_pct - self.from_pct).signum();
                    let x = self.from_pct + dir * rate_pct_per_s * (t_s - self.started_s);
                    ((x - to_pct) * dir < 0.0).then_some(x)
                }
            };
            match op {
                Some(op) => return Some(op),
                None => self.next(t_s),
            }
        }
    }

    /// Starts the next move at `t_s`, from where the last one ended.
    fn next(&mut self, t_s: f64) {
        self.from_pct = match self.moves[self.at] {
            Move::Hold { op_pct, .. } => op_pct,
            Move::Ramp { to_pct, .. } => to_pct,
        };
        self.at += 1;
        self.started_s = t_s;
        self.still = Still {
            window_start_s: t_s,
            ..Still::default()
        };
    }

    /// A cycle's row: its V_P, when it has one, counts towards the stillness of a hold.
    pub fn feedback(&mut self, row: &Sample) {
        if !matches!(self.moves.get(self.at), Some(Move::Hold { .. })) {
            return;
        }
        let s = &mut self.still;
        if row.t_s - s.window_start_s >= self.hold.still_s - TIME_EPS {
            let expected = self.hold.still_s / self.period_s;
            let judged = (s.n >= MEASURED_SHARE * expected).then(|| {
                let mean = s.sum / s.n;
                let var = (s.sum_sq / s.n - mean * mean).max(0.0);
                (mean, var, s.n)
            });
            s.settled = match (judged, s.previous) {
                (Some((mean, var, n)), Some((before, n_before))) => {
                    let chance = 4.0 * (var / n + var / n_before).sqrt();
                    (mean - before).abs() <= self.hold.still_pct.max(chance)
                }
                _ => false,
            };
            s.previous = judged.map(|(mean, _, n)| (mean, n));
            (s.n, s.sum, s.sum_sq) = (0.0, 0.0, 0.0);
            s.window_start_s = row.t_s;
        }
        if let (Status::Ok, Some(vp)) = (row.status, row.vp_pct) {
            s.n += 1.0;
            s.sum += vp;
            s.sum_sq += vp * vp;
        }
    }

    /// Moves done and moves in all.
    pub fn progress(&self) -> (usize, usize) {
        (self.at, self.moves.len())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    use std::path::Path;
    use std::time::SystemTime;

    const DT: f64 = 0.01;

    fn plan(hold: &str, signature: &str) -> Plan {
        let text = format!(
            "openings_pct = [50.0]\nsizes_pct = [1.0]\npattern = [1, -1]\n[hold]\n{hold}\n{signature}"
        );
        Plan::from_toml(&text, Path::new("p.toml"), (0.0, 100.0)).unwrap()
    }

    const HOLD: &str = "min_s = 5.0\nmax_s = 40.0\nstill_s = 1.0\nstill_pct = 0.05";

    fn row(t_s: f64, vp: Option<f64>) -> Sample {
        Sample {
            t_s,
            op_pct: None,
            vp_pct: vp,
            status: if vp.is_some() {
                Status::Ok
            } else {
                Status::Timeout
            },
            lateness_us: None,
            latency_us: None,
            op_sent_pct: None,
            utc: SystemTime::UNIX_EPOCH,
            op_controller_pct: None,
        }
    }

    /// Runs `s` against a first-order valve of time constant `tau_s` with noise `noise` on V_P
    /// (`lost(k)`: slot k's reply is lost), and returns the slots at which O_P changed and the
    /// O_P of every slot.
    fn drive(
        s: &mut Schedule,
        tau_s: f64,
        noise: f64,
        lost: impl Fn(usize) -> bool,
    ) -> (Vec<usize>, Vec<f64>) {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let normal = Normal::new(0.0, noise.max(1e-12)).unwrap();
        let (mut x, mut ops, mut changes) = (50.0, Vec::new(), Vec::new());
        for k in 0.. {
            let t = k as f64 * DT;
            let Some(op) = s.op_at(t) else { break };
            if ops.last().is_some_and(|&last| last != op) {
                changes.push(k);
            }
            ops.push(op);
            x += (op - x) * (1.0 - (-DT / tau_s).exp());
            let vp = x + if noise > 0.0 {
                normal.sample(&mut rng)
            } else {
                0.0
            };
            s.feedback(&row(t, (!lost(k)).then_some(vp)));
        }
        (changes, ops)
    }

    #[test]
    fn a_quick_valve_is_held_the_shortest_hold_a_slow_one_until_it_settles() {
        let p = plan(HOLD, "");
        let (quick, _) = drive(&mut Schedule::new(&p, DT), 0.2, 0.0, |_| false);
        // The approach, then each step, held 5 s (the valve settled long before).
        assert_eq!(quick, [500, 1000]);
        // After a 1 % step a valve with a 3 s time constant moves the mean of a second by
        // 3 (1 - e^-1/3)² e^-a/3 % from the second starting at a s to the next: under 0.05 % from
        // a = 4.7 s, judged at the end of the next second.
        let (slow, _) = drive(&mut Schedule::new(&p, DT), 3.0, 0.0, |_| false);
        assert_eq!(slow[0], 500, "the approach to where it rests");
        let held = (slow[1] - slow[0]) as f64 * DT;
        assert!((5.5..=8.0).contains(&held), "{held}");
    }

    #[test]
    fn noise_is_not_motion_and_missing_rows_are_not_stillness() {
        let p = plan(HOLD, "");
        // 0.2 % of noise on a valve at rest: each window's mean moves by chance only.
        let (noisy, _) = drive(&mut Schedule::new(&p, DT), 0.2, 0.2, |_| false);
        assert_eq!(noisy, [500, 1000]);
        // Every third reply lost: still judged (half the rows of a window are enough).
        let (holed, _) = drive(&mut Schedule::new(&p, DT), 0.2, 0.0, |k| k % 3 == 0);
        assert_eq!(holed, [500, 1000]);
        // No V_P at all: never judged still, each hold runs to its longest.
        let (blind, _) = drive(&mut Schedule::new(&p, DT), 0.2, 0.0, |_| true);
        assert_eq!(blind, [4000, 8000]);
    }

    #[test]
    fn the_signature_ramps_out_and_back_at_its_rate_then_the_plan_ends() {
        let p = plan(
            HOLD,
            "[signature]\nopening_pct = 50.0\nspan_pct = 1.0\nrate_pct_per_s = 0.5",
        );
        let mut s = Schedule::new(&p, DT);
        let (_, ops) = drive(&mut s, 0.2, 0.0, |_| false);
        assert_eq!(s.progress(), (7, 7));
        // The approach and two steps held 5 s each, the approach to the signature's opening (no
        // jump: O_P is there) 5 s, then 1 + 2 + 1 % at 0.5 %/s: 8 s.
        assert!((2799..=2801).contains(&ops.len()), "{}", ops.len());
        let ramp = &ops[2000..];
        assert!(
            (ramp[0] - 50.0).abs() < 1e-9 && (ramp[200] - 51.0).abs() < 1e-6,
            "{}",
            ramp[200]
        );
        assert!((ramp[600] - 49.0).abs() < 1e-6 && (ramp[790] - 49.95).abs() < 1e-6);
        let top = ramp.iter().copied().fold(f64::MIN, f64::max);
        assert!(top <= 51.0, "the ramp never passes its end: {top}");
        assert_eq!(s.op_at(100.0), None);
    }

    proptest::proptest! {
        /// Any plan the checks accept, whatever V_P the valve reports (rows lost among them),
        /// sends only levels inside the range and ends within its longest holds and ramps.
        #[test]
        fn an_accepted_plan_stays_in_range_and_ends(
            lo in 0.0f64..40.0,
            width in 5.0f64..60.0,
            opening in 0.0f64..1.0,
            sizes in proptest::collection::vec(0.05f64..8.0, 1..4),
            pattern in proptest::collection::vec(-3i32..=3, 1..5),
            span in 0.1f64..5.0,
            reports in proptest::collection::vec(proptest::option::of(-5.0f64..105.0), 50..200),
        ) {
            let hi = (lo + width).min(100.0);
            let o = lo + opening * (hi - lo);
            let text = format!(
                "openings_pct = [{o}]\nsizes_pct = {sizes:?}\npattern = {pattern:?}\n\
                 [hold]\nmin_s = 0.2\nmax_s = 0.5\nstill_s = 0.1\nstill_pct = 0.05\n\
                 [signature]\nopening_pct = {o}\nspan_pct = {span}\nrate_pct_per_s = 5.0\n"
            );
            let Ok(p) = Plan::from_toml(&text, Path::new("p.toml"), (lo, hi)) else {
                return Ok(());
            };
            let mut s = Schedule::new(&p, DT);
            let longest = p.moves().len() as f64 * 0.5 + 4.0 * span / 5.0 + 1.0;
            let mut k = 0;
            while let Some(op) = s.op_at(k as f64 * DT) {
                let level = crate::recording::log_format::round_pct(op);
                proptest::prop_assert!((lo..=hi).contains(&level), "{op} outside {lo}..{hi}");
                s.feedback(&row(k as f64 * DT, reports[k % reports.len()]));
                k += 1;
                proptest::prop_assert!((k as f64 * DT) < longest, "no end after {k} slots");
            }
        }
    }
}
