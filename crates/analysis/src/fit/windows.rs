//! Which samples are fitted and scored: time windows (given with `--windows` or found by
//! leaving out saturation) and the blocked fit / held-out split inside them.
//!
//! The paper scored three windows where the valve was not saturated: a valve sitting on its
//! stop at 0 or 100 % tells nothing about its dynamics and would reward any model that
//! saturates. [`unsaturated`] finds such windows automatically. [`Split`] then cuts the scored
//! samples into consecutive blocks and holds every third one out, so a model is scored on data
//! it was not fitted to, in every operating region of the recording.
//!
//! Not here: the simulation (always over the whole recording, see [`super::cost`]).

use std::str::FromStr;

use serde::Serialize;

use super::FitError;

/// A time window, s (inclusive start, inclusive end).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Window {
    pub start_s: f64,
    pub end_s: f64,
}

/// A list of windows as written on the command line: `12.5-80,130-400`.
#[derive(Debug, Clone, PartialEq)]
pub struct WindowList(pub Vec<Window>);

impl FromStr for WindowList {
    type Err = FitError;

    fn from_str(s: &str) -> Result<Self, FitError> {
        let bad = |item: &str, why: &str| {
            FitError::Windows {
            text: s.to_string(),
            detail: format!("`{item}`: {why}; write START-END in seconds, comma separated, e.g. 12.5-80,130-400"),
        }
        };
        let mut out = Vec::new();
        for item in s.split(',').map(str::trim).filter(|i| !i.is_empty()) {
            let (a, b) = item
                .split_once('-')
                .ok_or_else(|| bad(item, "no `-` between start and end"))?;
            let num = |x: &str| {
                x.trim()
                    .parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| bad(item, &format!("`{}` is not a number of seconds", x.trim())))
            };
            let (start_s, end_s) = (num(a)?, num(b)?);
            if end_s <= start_s {
                return Err(bad(item, "the end must come after the start"));
            }
            out.push(Window { start_s, end_s });
        }
        if out.is_empty() {
            return Err(bad(s, "no window given"));
        }
        Ok(WindowList(out))
    }
}

/// The samples of `t` inside any of `windows`.
pub fn mask(t: &[f64], windows: &[Window]) -> Vec<bool> {
    t.iter()
        .map(|&x| windows.iter().any(|w| x >= w.start_s && x <= w.end_s))
        .collect()
}

/// Distance from a travel stop within which the valve counts as saturated, %.
pub const SATURATION_BAND_PCT: f64 = 0.5;
/// Time after leaving a stop that is still left out (the valve comes off the stop), s.
pub const SATURATION_MARGIN_S: f64 = 2.0;
/// Shortest window kept, s (and never fewer than 20 samples).
pub const MIN_WINDOW_S: f64 = 5.0;

/// Windows where V_P is off its stops (`lo`, `hi`, in %): saturated samples, and
/// [`SATURATION_MARGIN_S`] after each, are left out; runs shorter than [`MIN_WINDOW_S`] are
/// dropped. A recording that never saturates is one window.
pub fn unsaturated(t: &[f64], vp: &[f64], dt: f64, lo: f64, hi: f64) -> Vec<Window> {
    let n = t.len().min(vp.len());
    let margin = (SATURATION_MARGIN_S / dt).ceil() as usize;
    let min_len = ((MIN_WINDOW_S / dt).ceil() as usize).max(20);
    let mut ok = vec![true; n];
    let mut last_sat: Option<usize> = None;
    for k in 0..n {
        if vp[k] <= lo + SATURATION_BAND_PCT || vp[k] >= hi - SATURATION_BAND_PCT {
            last_sat = Some(k);
        }
        if last_sat.is_some_and(|s| k <= s + margin) {
            ok[k] = false;
        }
    }
    let mut out = Vec::new();
    let mut k = 0;
    while k < n {
        if !ok[k] {
            k += 1;
            continue;
        }
        let a = k;
        while k < n && ok[k] {
            k += 1;
        }
        if k - a >= min_len {
            out.push(Window {
                start_s: t[a],
                end_s: t[k - 1],
            });
        }
    }
    out
}

/// The blocked split of the scored samples into fit and held-out parts.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Split {
    /// Number of consecutive blocks the scored samples are cut into (equal sample counts).
    pub blocks: usize,
    /// Every `every`-th block (the last of each group) is held out.
    pub every: usize,
}

impl Default for Split {
    /// Twelve blocks, every third held out: two thirds fitted, one third scored only.
    fn default() -> Self {
        Split {
            blocks: 12,
            every: 3,
        }
    }
}

impl Split {
    /// `(fit, held_out)` masks cut from `scored`.
    pub fn masks(&self, scored: &[bool]) -> (Vec<bool>, Vec<bool>) {
        let total = scored.iter().filter(|&&m| m).count();
        let per_block = total.div_ceil(self.blocks.max(1)).max(1);
        let mut fit = vec![false; scored.len()];
        let mut held = vec![false; scored.len()];
        let mut i = 0;
        for (k, &m) in scored.iter().enumerate() {
            if !m {
                continue;
            }
            let block = i / per_block;
            if block % self.every.max(1) == self.every.max(1) - 1 {
                held[k] = true;
            } else {
                fit[k] = true;
            }
            i += 1;
        }
        (fit, held)
    }

    /// A one-line description, e.g. for reports.
    pub fn describe(&self) -> String {
        format!(
            "the scored samples cut into {} consecutive blocks; every {} block held out (fitted on {} of {}, scored on the rest)",
            self.blocks,
            match self.every {
                2 => "second".to_string(),
                3 => "third".to_string(),
                n => format!("{n}th"),
            },
            self.blocks - self.blocks / self.every.max(1),
            self.blocks
        )
    }
}

/// `(fit, held_out)` masks over `n` samples cut into consecutive blocks of `block_len`
/// samples from the first, alternately fitted and held out (the first block fitted), so both
/// halves cover every operating region; the first `skip` samples (an initial transient) are in
/// neither.
pub fn alternating(n: usize, block_len: usize, skip: usize) -> (Vec<bool>, Vec<bool>) {
    let block_len = block_len.max(1);
    (0..n)
        .map(|k| {
            let held = (k / block_len) % 2 == 1;
            (k >= skip && !held, k >= skip && held)
        })
        .unzip()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn window_lists_parse_and_bad_ones_say_why() {
        let w: WindowList = "12.5-80, 130-400".parse().unwrap();
        assert_eq!(w.0.len(), 2);
        assert_eq!(
            w.0[0],
            Window {
                start_s: 12.5,
                end_s: 80.0
            }
        );
        let e = "12-x".parse::<WindowList>().unwrap_err().to_string();
        assert!(e.contains("`x` is not a number"), "{e}");
        let e = "80-12".parse::<WindowList>().unwrap_err().to_string();
        assert!(e.contains("after the start"), "{e}");
    }

    #[test]
    fn saturation_is_left_out_with_a_margin() {
        let dt = 0.1;
        let t: Vec<f64> = (0..1000).map(|k| k as f64 * dt).collect();
        // Saturated at 100 % from 30 s to 40 s.
        let vp: Vec<f64> = t
            .iter()
            .map(|&x| {
                if (30.0..40.0).contains(&x) {
                    100.0
                } else {
                    50.0
                }
            })
            .collect();
        let w = unsaturated(&t, &vp, dt, 0.0, 100.0);
        assert_eq!(w.len(), 2);
        assert!((w[0].end_s - 29.9).abs() < 1e-9);
        assert!((w[1].start_s - 42.0).abs() < 0.11, "{w:?}");
        let m = mask(&t, &w);
        assert!(!m[350] && m[100] && m[900]);
    }

    #[test]
    fn alternating_blocks_skip_the_start() {
        let (fit, held) = alternating(10, 3, 1);
        let on = |m: &[bool]| m.iter().map(|&b| b as u8).collect::<Vec<_>>();
        assert_eq!(on(&fit), [0, 1, 1, 0, 0, 0, 1, 1, 1, 0]);
        assert_eq!(on(&held), [0, 0, 0, 1, 1, 1, 0, 0, 0, 1]);
    }

    #[test]
    fn split_holds_out_every_third_block() {
        let scored = vec![true; 1200];
        let (fit, held) = Split::default().masks(&scored);
        assert_eq!(held.iter().filter(|&&h| h).count(), 400);
        assert!(fit[0] && !held[0] && held[200] && fit[300]);
        assert!(fit.iter().zip(&held).all(|(a, b)| a != b));
    }
}
