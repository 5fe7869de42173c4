//! Facts measured straight from a recording, without any model: step delays by direction,
//! travel speeds, steady-state offsets and the sensor lattice.
//!
//! Diagnosis quotes these as evidence a person can check against the plots, and uses a few to
//! seed refits (a speed limit starts from the fastest observed speed). Nothing here fits.

use crate::fit::steps::{self, StepOptions};

/// One step of O_P and how V_P answered it.
#[derive(Debug, Clone, Copy)]
pub struct StepResponse {
    pub t_s: f64,
    /// V_P when the step came, %.
    pub from_pct: f64,
    pub size_pct: f64,
    /// True when the step goes against the valve's previous movement.
    pub reversal: bool,
    /// Time until V_P moved a tenth of the step (at least four noise sigmas), s.
    pub delay_s: f64,
}

/// A hold of O_P long enough for the valve to settle.
#[derive(Debug, Clone, Copy)]
pub struct Hold {
    pub op_pct: f64,
    /// Mean V_P over the last second of the hold, %.
    pub vp_pct: f64,
    /// +1 when the valve came from below (opening), -1 from above.
    pub approach: f64,
    /// Largest jump of V_P inside the settled part of the hold, %.
    pub max_jump_pct: f64,
}

/// Everything measured from the recording.
#[derive(Debug, Clone, Default)]
pub struct Facts {
    pub steps: Vec<StepResponse>,
    pub holds: Vec<Hold>,
    /// 99.5th percentile of the opening and closing speed of V_P, %/s.
    pub open_speed: f64,
    pub close_speed: f64,
    /// Spacing of the V_P lattice, % (0 when V_P is not on a lattice).
    pub lattice_pct: f64,
    /// Number of direction reversals of O_P.
    pub reversals: usize,
}

/// Measures the facts of a recording sampled every `dt`.
pub fn measure(op: &[f64], vp: &[f64], dt: f64) -> Facts {
    let (open_speed, close_speed) = speeds(vp, dt);
    Facts {
        reversals: count_reversals(op),
        steps: step_responses(op, vp, dt),
        holds: holds(op, vp, dt),
        open_speed,
        close_speed,
        lattice_pct: lattice(vp),
    }
}

fn count_reversals(op: &[f64]) -> usize {
    let mut last = 0.0;
    let mut n = 0;
    for w in op.windows(2) {
        let d = w[1] - w[0];
        if d.abs() > 0.02 {
            let s = d.signum();
            if last != 0.0 && s != last {
                n += 1;
            }
            last = s;
        }
    }
    n
}

/// The step delays of the step analysis (`fit::steps`), for steps of at least 0.3 % held for
/// a second that V_P answered.
fn step_responses(op: &[f64], vp: &[f64], dt: f64) -> Vec<StepResponse> {
    let opts = StepOptions {
        min_size_pct: 0.3,
        fraction: 0.1,
        min_hold_s: 1.0,
    };
    steps::analyse(op, vp, dt, &opts)
        .steps
        .into_iter()
        .filter_map(|s| {
            s.delay_s.map(|delay_s| StepResponse {
                t_s: s.t_s,
                from_pct: s.from_pct,
                size_pct: s.size_pct,
                reversal: s.reversal == Some(true),
                delay_s,
            })
        })
        .collect()
}

/// Stretches of constant O_P of at least 3 s, with the settled V_P of their last second.
fn holds(op: &[f64], vp: &[f64], dt: f64) -> Vec<Hold> {
    let n = op.len();
    let min_hold = (3.0 / dt) as usize;
    let settle = (1.0 / dt) as usize;
    let mut holds = Vec::new();
    let mut a = 0;
    for b in 1..=n {
        if b < n && (op[b] - op[b - 1]).abs() <= 1e-9 {
            continue;
        }
        if b - a >= min_hold && a > 0 {
            let tail = &vp[b - settle..b];
            let mean = tail.iter().sum::<f64>() / tail.len() as f64;
            let max_jump = vp[a + settle..b]
                .windows(2)
                .map(|w| (w[1] - w[0]).abs())
                .fold(0.0, f64::max);
            holds.push(Hold {
                op_pct: op[a],
                vp_pct: mean,
                approach: (op[a] - op[a - 1]).signum(),
                max_jump_pct: max_jump,
            });
        }
        a = b;
    }
    holds
}

fn speeds(vp: &[f64], dt: f64) -> (f64, f64) {
    let h = ((0.1 / dt).round() as usize).max(1);
    let mut up: Vec<f64> = Vec::new();
    let mut down: Vec<f64> = Vec::new();
    for k in (h..vp.len()).step_by(h) {
        let s = (vp[k] - vp[k - h]) / (h as f64 * dt);
        if s > 0.0 {
            up.push(s);
        } else {
            down.push(-s);
        }
    }
    (percentile(&mut up, 0.995), percentile(&mut down, 0.995))
}

/// The `q` quantile of `x` (0 for an empty slice).
pub fn percentile(x: &mut [f64], q: f64) -> f64 {
    if x.is_empty() {
        return 0.0;
    }
    let k = ((x.len() - 1) as f64 * q).round() as usize;
    let (_, v, _) = x.select_nth_unstable_by(k, f64::total_cmp);
    *v
}

/// The spacing of the lattice V_P lies on, or 0 when it does not lie on one.
///
/// The smallest nonzero change of V_P that occurs at least three times is the candidate
/// spacing; V_P is on a lattice when at least 95 % of its values sit within 2 % of a spacing of a
/// multiple of it. Spacings below 0.01 % (a file's number formatting) do not count.
fn lattice(vp: &[f64]) -> f64 {
    let mut diffs: Vec<f64> = vp
        .windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .filter(|d| *d > 1e-9)
        .collect();
    if diffs.len() < 20 {
        return 0.0;
    }
    diffs.sort_by(f64::total_cmp);
    let q = diffs
        .windows(3)
        .find(|w| w[2] - w[0] <= 1e-6 * w[0].max(1e-9) + 1e-9)
        .map_or(0.0, |w| w[1]);
    if q < 0.01 {
        return 0.0;
    }
    let near = vp
        .iter()
        .filter(|&&v| {
            let f = v / q - (v / q).round();
            f.abs() < 0.02
        })
        .count();
    if near as f64 >= 0.95 * vp.len() as f64 {
        q
    } else {
        0.0
    }
}

/// Mean and standard deviation of a sample (0, 0 when empty).
pub fn mean_sd(x: impl Iterator<Item = f64>) -> (f64, f64, usize) {
    let v: Vec<f64> = x.collect();
    if v.is_empty() {
        return (0.0, 0.0, 0);
    }
    let m = v.iter().sum::<f64>() / v.len() as f64;
    let s = (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len().max(2) - 1) as f64).sqrt();
    (m, s, v.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lattice_is_found_only_on_a_lattice() {
        let on: Vec<f64> = (0..2000)
            .map(|k| ((50.0 + 3.0 * (k as f64 * 0.01).sin()) / 0.1).round() * 0.1)
            .collect();
        assert!((lattice(&on) - 0.1).abs() < 1e-9);
        let off: Vec<f64> = (0..2000)
            .map(|k| 50.0 + 3.0 * (k as f64 * 0.01).sin())
            .collect();
        assert_eq!(lattice(&off), 0.0);
    }

    #[test]
    fn step_delays_and_reversals_are_measured() {
        let dt = 0.01;
        // O_P: 40 -> 50 at 5 s, -> 45 at 15 s. V_P follows 0.3 s late, 0.8 s late after the reversal.
        let n = 2500;
        let op: Vec<f64> = (0..n)
            .map(|k| {
                if k < 500 {
                    40.0
                } else if k < 1500 {
                    50.0
                } else {
                    45.0
                }
            })
            .collect();
        let vp: Vec<f64> = (0..n)
            .map(|k| {
                if k < 530 {
                    40.0
                } else if k < 1580 {
                    50.0
                } else {
                    45.0
                }
            })
            .collect();
        let f = measure(&op, &vp, dt);
        assert_eq!(f.steps.len(), 2);
        assert!(!f.steps[0].reversal && f.steps[1].reversal);
        assert!((f.steps[0].delay_s - 0.3).abs() < 1e-9 && (f.steps[1].delay_s - 0.8).abs() < 1e-9);
        assert_eq!(f.reversals, 1);
        assert_eq!(f.holds.len(), 2);
        assert_eq!(f.holds[1].approach, -1.0);
    }
}
