//! Stick-slip judged by the character of V_P, not by its phase.
//!
//! A stem whose static friction exceeds its sliding friction, inside a positioner loop, sticks
//! while the positioner's pressure builds, breaks loose, slips past the target and sticks
//! again: a limit cycle (hunting) whose phase is set by the friction and by small
//! disturbances, not by O_P. A simulated stick-slip valve slips at other moments than the real
//! one, so its free-run error is no smaller (usually larger) than a smooth model's, although the
//! smooth model is plainly wrong in character: it never slips. Free-run SSE cannot judge a limit
//! cycle's phase, so when no effect lowers it, stick-slip is judged by a statistic that does not
//! depend on the phase:
//!
//! - **Slips** ([`facts::slips`]): moves of V_P completed within 0.1 s with V_P at rest just
//!   before and after, while the current smooth model's V_P moved less than half as much
//!   anywhere in the half second before; at least five noise sigmas of the compared means,
//!   one and a half sensor steps (a V_P on a lattice steps by one) and 0.1 %. Simulations are
//!   read through a sensor like the recording's (its noise, seeded, and its lattice), so the
//!   few slips noise alone makes count alike everywhere.
//! - **Per piece** (every fit or held-out block cut into pieces of at least 10 s, several
//!   stick-slip periods each), a histogram of slip sizes in octaves from the threshold (soft
//!   binning, so a size near a bin edge does not flip bins). The distance between the measured
//!   and a simulated V_P is the L1 distance of their histograms: slips of the wrong size or
//!   number count, their timing inside a piece does not.
//! - **Fit** on the fit blocks, on a grid seeded from the median size of the slips measured
//!   there: stick-slip inside the positioner loop (pin-cart II breakaway, with the positioner
//!   gain, which sets the hunting period, and a tolerance band, which ends it once a slip lands
//!   inside) and Choudhury's stick-slip on the valve's input (jump and stickband, with a
//!   positioner fast enough to pass a jump on as a jump). The grid point with the smallest
//!   distance on the fit blocks wins; the free-run error only breaks ties.
//! - **A smooth rival**: a stem with Coulomb friction alone slips too where a positioner makes
//!   it wait on a reversal and then catch up within 0.1 s (a pulsing digital positioner does),
//!   and one in a positioner deadband is moved back into the band in one go. A friction band
//!   and a positioner deadband are fitted to the same slips the same way (the band over the
//!   range of positioner gains stick-slip gets, so that neither wins by a faster positioner
//!   alone: linkage play inside a digital positioner's closed loop makes it hunt in quick
//!   steps that stick-slip otherwise matched); when the best of them comes as close to the
//!   measured slips as the best stick-slip, the slips are no evidence of stick-slip and it is
//!   not judged. On the held-out pieces, stick-slip's drops in distance from the rival must
//!   not lean the rival's way (signed-rank p < 0.5): a fast positioner following a noisy
//!   controller output moves in quick steps that stick-slip matches on the fit blocks by
//!   chance as often as the rival. Under a quiet command (O_P's sample-to-sample noise under
//!   half the slip threshold: steps, ramps) that lean is not asked when the valve makes five
//!   times the rival's evident slips (a rival that slips once where the valve hunts 25 times
//!   explains none of it), and neither test is made when it has forty evident slips or more
//!   besides: the rival comes close by slips without rests, which say nothing of a stem that
//!   sticks.
//! - **Judge** on the held-out blocks only. More than chance: the per-piece drops in distance
//!   from the current model to the candidate lean positive (Wilcoxon's signed-rank test,
//!   one-sided p < 0.05). Something real was missing: the current model misses at least ten
//!   slips there. A real share of it is explained: the distance falls by at least a quarter
//!   (with a few slips per piece, counting noise alone keeps even a perfect model's distance
//!   near half of a slip-free model's). The candidate slips like the valve: as often within a
//!   factor of 2.5, by the same size within a factor of 1.5. Or, when the candidate matches
//!   only in part (it still comes closer than the current model), by number: the current
//!   model misses at least fifteen slips a minute in the fit and in the held-out blocks alike,
//!   of a median size worth naming, or at least twenty evident slips (V_P at rest before and
//!   after, half as large again as the threshold) that the current model does not make; and
//!   the measured evident slips are five times as many as the best smooth rival's (a pulsing
//!   positioner following a noisy controller output rests and steps too).
//! - **Sticks, then jumps**: with fewer than ten evident slips stick-slip is not judged at
//!   all, whatever the histograms say, unless the current model misses fifteen slips a
//!   minute in the fit and the held-out blocks alike: a valve that hunts under a noisy
//!   reading slips by too little for one slip to stand out from the noise, but it slips
//!   hundreds of times, and healthy valves under a noisy controller miss a few a minute.
//!   A stem that a fast positioner pushes past its target and turns round within 0.3 s
//!   rests before the slip out and after the slip back, not between them: both count.
//! - **Stuck before it jumps**: in the 0.2 s before each evident slip, a stuck stem stands
//!   still while the smooth model moves on (V_P and the model's V_P uncorrelated, the reading
//!   its noise). When V_P follows the model there (median correlation over the slips 0.25 or
//!   more), the quick moves are those of a valve that was moving all along, such as a pulsing
//!   positioner following a noisy controller output, and stick-slip is not judged, even when
//!   the current model misses fifteen slips a minute as above: that count stands in for
//!   evident slips the noise hides, not for ten or more that show the valve moving along (a
//!   healthy digital valve in a noisy loop read under 0.4 % of noise made 35, V_P following
//!   the model before them at 0.46, and the model missed 75 or more in each half).
//! - **Steps of a band**: beside a deadband (in the current model, or the band that rivals a
//!   stick-slip winner), slips of a quarter of the band or less are a pulsing positioner's
//!   steps back into its tolerance band, and stick-slip is not judged.
//!
//! Quantization (a lattice step is not a slip), sensor spikes (no level change), O_P steps and
//! smooth moves or slewing (no rest before and after) cannot produce slips, so they cannot be
//! taken for stick-slip. Everything here is O(n) per simulation.

use rayon::prelude::*;

use super::facts::{self, Facts, Slip};
use super::measure::Measure;
use super::rests::{Rest, FOLLOWS};
use super::scorer::Scorer;
use super::sensor::Sensor;
use super::size;
use super::tuning::Tuning;
use vb_core::metrics::stats::{self, Differences};
use vb_core::model::composed::{self, Knob};
use vb_core::model::ModelSpec;

/// Slip-size bins: octaves from the slip threshold, the last one open-ended.
const BINS: usize = 4;
/// Fewest slips the current model must miss on the held-out blocks.
const MIN_MISSED: f64 = 10.0;
/// Shortest piece of a block the slips are counted in, s.
const PIECE_S: f64 = 10.0;
/// Largest one-sided p-value (signed-rank test over held-out pieces) that beats chance.
const MAX_P: f64 = 0.05;
/// Largest one-sided p-value of stick-slip's drops in distance from the smooth rival over the
/// held-out pieces: they need not beat chance (the rival was fitted to the same slips), but
/// they must not lean the rival's way (a valve whose quick steps a smooth rival matches
/// better, piece by piece, does not stick and jump however many steps it makes).
const SMOOTH_LEAN_P: f64 = 0.5;
/// Slips a minute the current model must miss in both the fit and the held-out blocks for
/// stick-slip to be named by their number, when the fitted model matches them only in part:
/// healthy valves under a noisy controller output miss a few a minute, a hunting valve tens.
const EVIDENT_PER_MIN: f64 = 15.0;
/// Fewest evident slips the current model must miss over the whole recording, and how many
/// times as many as the model makes (read through the same sensor), for stick-slip to be named
/// by them even where they fall unevenly between the fit and the held-out blocks (a valve that
/// hunts at some openings only). Named by their number (not by a close match of the slip
/// histograms), the measured evident slips must also be that many times what the best smooth
/// rival makes: a pulsing positioner in a closed or noisy loop rests and moves in quick
/// steps too, and a friction band or tolerance band makes those.
const EVIDENT_SLIPS: usize = 20;
const EVIDENT_RATIO: f64 = 5.0;
/// Fewest evident slips that a smooth rival making [`EVIDENT_RATIO`] times fewer cannot veto
/// under a quiet command (it comes close by slips without rests); a healthy pulsing positioner
/// makes a few dozen in ten minutes, following a noisy controller output.
const RIVAL_SLIPS: usize = 2 * EVIDENT_SLIPS;
/// Fewest evident slips of V_P for stick-slip to be judged at all: a stem that sticks and then
/// jumps rests before and after each jump; moves without those rests (a valve following a
/// noisy O_P, slewing, a reading stepping on its lattice) are no evidence of it. Not asked of
/// a valve whose slips the current model misses at [`EVIDENT_PER_MIN`] in the fit and the
/// held-out blocks alike (hunting whose slips the noise hides one by one).
const MIN_EVIDENT: usize = 10;
/// Largest share of a deadband's width (the valve's rest anywhere in a band around its target)
/// that V_P's median step may have for those steps to be the positioner's own: a digital
/// positioner leaves its tolerance band with a pulse, moving the valve a small part of the band
/// and resting again at its edge (a ramp becomes a staircase of equal steps), since steps as
/// large as the band would carry it across and never let it settle. Stick-slip's jump is set by
/// the stem's friction, not by the band, and beside a band it is judged only when it is the
/// larger: steps of a quarter of the band or less are named the band's ([`band_steps`]).
const BAND_STEP_SHARE: f64 = 0.25;

type Histogram = [f64; BINS];

/// The pieces slips are counted in: every block of the scorer cut into equal pieces of at
/// least [`PIECE_S`], so the held-out half gives many pairs to compare, each covering several
/// stick-slip periods (neighbouring counts nearly independent).
struct Pieces {
    block_len: usize,
    per_block: usize,
    count: usize,
    skip: usize,
}

impl Pieces {
    fn new(scorer: &Scorer) -> Self {
        let per_block = ((scorer.block_len as f64 * scorer.dt / PIECE_S) as usize).max(1);
        Pieces {
            block_len: scorer.block_len,
            per_block,
            count: scorer.n_blocks * per_block,
            skip: scorer.skip,
        }
    }

    /// The piece of sample `k` (none in the initial transient).
    fn of(&self, k: usize) -> Option<usize> {
        (k >= self.skip).then(|| {
            k / self.block_len * self.per_block
                + k % self.block_len * self.per_block / self.block_len
        })
    }

    /// True for the pieces of held-out blocks.
    fn held(&self, piece: usize) -> bool {
        (piece / self.per_block) % 2 == 1
    }
}

/// The slip histogram of every piece.
fn histograms(slips: &[Slip], threshold: f64, pieces: &Pieces) -> Vec<Histogram> {
    let mut out = vec![[0.0; BINS]; pieces.count];
    let top = (BINS - 1) as f64;
    for s in slips {
        let x = (s.size_pct.abs() / threshold).log2().clamp(0.0, top);
        let i = x.floor() as usize;
        let f = x - i as f64;
        if let Some(h) = pieces.of(s.k).and_then(|p| out.get_mut(p)) {
            h[i] += 1.0 - f;
            if let Some(next) = h.get_mut(i + 1) {
                *next += f;
            }
        }
    }
    out
}

/// Per piece, the L1 distance between two sets of histograms.
fn distances(a: &[Histogram], b: &[Histogram]) -> Vec<f64> {
    a.iter()
        .zip(b)
        .map(|(x, y)| x.iter().zip(y).map(|(p, q)| (p - q).abs()).sum())
        .collect()
}

/// How a candidate's slips compare with the measured ones on the held-out half, next to the
/// current model's.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Match {
    /// Pieces where the model's slips are closer to the measured ones than the current
    /// model's, and where they are farther.
    pub better: usize,
    pub worse: usize,
    /// One-sided signed-rank p-value of the per-piece drops in distance.
    pub p_value: f64,
    /// Summed distance of the current model and of this one (in slips).
    pub distance_before: f64,
    pub distance_after: f64,
    /// Number and median size (%) of the measured slips and of the model's.
    pub measured: (usize, f64),
    pub simulated: (usize, f64),
}

impl Match {
    /// The held-out half: per piece, the current model's and the candidate's distances
    /// (`before`, `after`), and the measured and the candidate's slips.
    fn new(
        pieces: &Pieces,
        scorer: &Scorer,
        (before, after): (&[f64], &[f64]),
        (measured, simulated): (&[Slip], &[Slip]),
    ) -> Self {
        let held = true;
        let drops = drops(pieces, before, after, Some(held));
        Match {
            better: drops.iter().filter(|g| **g > 1e-9).count(),
            worse: drops.iter().filter(|g| **g < -1e-9).count(),
            p_value: stats::signed_rank_p(&drops),
            distance_before: total(before, pieces, held),
            distance_after: total(after, pieces, held),
            measured: count_and_size(measured, scorer, held),
            simulated: count_and_size(simulated, scorer, held),
        }
    }

    /// More than chance, something real was missing, a real share of it explained, and the
    /// candidate slips like the valve (see the module documentation).
    pub(crate) fn slips_alike(&self) -> bool {
        let ratio = |a: f64, b: f64| a.max(b) / a.min(b).max(f64::MIN_POSITIVE);
        let ((nm, sm), (ns, ss)) = (self.measured, self.simulated);
        self.p_value < MAX_P
            && self.distance_before >= MIN_MISSED
            && self.distance_after <= 0.75 * self.distance_before
            && ratio(nm as f64, ns as f64) <= 2.5
            && ratio(sm, ss) <= 1.5
    }
}

/// V_P's median step and the deadband it lies in (both %), when those steps are the band's
/// ([`band_steps`]), not stick-slip's.
pub(crate) struct BandSteps {
    pub step_pct: f64,
    pub band_pct: f64,
}

/// A stick-slip candidate and how its slips compare with the measured ones.
pub(crate) struct Candidate {
    pub spec: ModelSpec,
    /// The knobs the fit set.
    pub knobs: Vec<Knob>,
    /// The comparison on the held-out blocks.
    pub held: Match,
    /// Slips of the measured V_P, and of the current model's and the candidate's simulated
    /// V_P read by a sensor like the recording's, whole recording.
    pub slips_measured: Vec<Slip>,
    pub slips_before: Vec<Slip>,
    pub slips_after: Vec<Slip>,
    /// Named by the number of slips the current model misses rather than by the match.
    pub by_count: bool,
    /// Summed histogram distance over every piece of the recording, before and after.
    pub distance_all: (f64, f64),
    /// One-sided signed-rank p-value of the per-piece drops in distance from the best smooth
    /// rival to this candidate, on the held-out pieces and on every piece; none when the rival
    /// makes no more evident slips than the current model, or under a quiet command a fifth
    /// of the valve's or fewer ([`EVIDENT_RATIO`]): it is no rival then.
    pub smooth_lean: Option<(f64, f64)>,
}

impl Candidate {
    /// Slips like the valve on the held-out blocks (or are far too many for a smooth valve),
    /// no worse than the smooth rival where it is judged ([`Self::distance`]), big enough to
    /// matter (0.1 %), and bring the slip histograms closer to the measured ones.
    pub(crate) fn passes(&self) -> bool {
        let size = [Knob::Breakaway, Knob::Stickband]
            .iter()
            .map(|&k| composed::get(&self.spec, k))
            .fold(0.0, f64::max);
        let Measure::SlipDistance {
            heldout,
            before,
            after,
        } = self.distance()
        else {
            return false;
        };
        let lean = (self.smooth_lean).map_or(0.0, |(h, all)| if heldout { h } else { all });
        (self.held.slips_alike() || self.by_count)
            && lean < SMOOTH_LEAN_P
            && size >= 0.1
            && after < before
    }

    /// The measure it improves ([`Measure::SlipDistance`]): on the held-out pieces when it
    /// does there, else over the whole recording (a valve that hunts at some openings only
    /// may slip mostly in the fit blocks).
    pub(crate) fn distance(&self) -> Measure {
        let (before, after) = (self.held.distance_before, self.held.distance_after);
        if after < before {
            Measure::SlipDistance {
                heldout: true,
                before,
                after,
            }
        } else {
            Measure::SlipDistance {
                heldout: false,
                before: self.distance_all.0,
                after: self.distance_all.1,
            }
        }
    }

    /// Median size of the measured slips, %, with its 90 % interval over resamples of the
    /// scorer's blocks (a block bootstrap).
    pub(crate) fn slip_size(&self, scorer: &Scorer) -> (f64, f64, f64) {
        use rand::{Rng, SeedableRng};
        let mut per_block: Vec<Vec<f64>> = vec![Vec::new(); scorer.n_blocks];
        for s in &self.slips_measured {
            if let Some(b) = per_block.get_mut(s.k / scorer.block_len) {
                b.push(s.size_pct.abs());
            }
        }
        let mut all: Vec<f64> = per_block.concat();
        let median = stats::quantile(&mut all, 0.5);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0x511b5);
        let n = per_block.len();
        let mut medians: Vec<f64> = (0..400)
            .filter_map(|_| {
                let mut x: Vec<f64> = (0..n)
                    .flat_map(|_| per_block[rng.gen_range(0..n)].iter().copied())
                    .collect();
                (!x.is_empty()).then(|| stats::quantile(&mut x, 0.5))
            })
            .collect();
        let (lo, hi) = (
            stats::quantile(&mut medians, 0.05),
            stats::quantile(&mut medians, 0.95),
        );
        (median, lo.min(median), hi.max(median))
    }
}

/// Sum of `per_piece` over the pieces of the fit or of the held-out blocks.
fn total(per_piece: &[f64], pieces: &Pieces, held: bool) -> f64 {
    per_piece
        .iter()
        .enumerate()
        .filter(|&(p, _)| pieces.held(p) == held)
        .map(|(_, d)| d)
        .sum()
}

/// Per piece of the held-out blocks (`Some(true)`), of the fit blocks or of all (`None`), the
/// drop in distance from `from` to `to`.
fn drops(pieces: &Pieces, from: &[f64], to: &[f64], held: Option<bool>) -> Vec<f64> {
    (from.iter().zip(to).enumerate())
        .filter(|&(p, _)| held.is_none_or(|h| pieces.held(p) == h))
        .map(|(_, (d0, d1))| d0 - d1)
        .collect()
}

/// Median size of the `slips` in the fit blocks (`fit_only`), or in the whole recording.
fn median_slip(slips: &[Slip], scorer: &Scorer, fit_only: bool) -> f64 {
    if fit_only {
        return count_and_size(slips, scorer, false).1;
    }
    let mut all: Vec<f64> = slips.iter().map(|s| s.size_pct.abs()).collect();
    stats::quantile(&mut all, 0.5)
}

/// Number and median size of the slips in the fit (`held` false) or held-out blocks.
fn count_and_size(slips: &[Slip], scorer: &Scorer, held: bool) -> (usize, f64) {
    let mut sizes: Vec<f64> = slips
        .iter()
        .filter(|s| s.k >= scorer.skip && scorer.held(s.k) == held)
        .map(|s| s.size_pct.abs())
        .collect();
    (sizes.len(), stats::quantile(&mut sizes, 0.5))
}

/// The stick-slip variants to try on top of a model with positioner gain `gain`, seeded from
/// the median measured slip `size`: stick-slip inside the positioner loop (the breakaway is
/// about the slip; a slower positioner hunts with a longer period), alone or, unless a
/// deadband is already named (`band_named`: it stays as named), with a positioner tolerance
/// band of half or all of the breakaway, and Choudhury's stick-slip on the input (the jump J
/// is about the slip, S from J to 4 J; a fast positioner passes the jump on as a jump). Slip
/// sizes from half to twice the median. Without a band the loop hunts at every set-point it
/// sticks short of; a valve whose positioner rests once a slip lands inside its band hunts at
/// some set-points and not at others (seed 50's physical valve 45: 87 evident slips, where
/// stick-slip without a band made over 300 at its own gain).
fn grid(size: f64, gain: f64, band_named: bool) -> Vec<Vec<(Knob, f64)>> {
    let sizes = || (0..=8).map(move |i| size * 2f64.powf(i as f64 / 4.0 - 1.0));
    let breakaway = sizes().flat_map(|b| {
        [None, Some(0.5), Some(1.0)]
            .into_iter()
            .filter(move |band| band.is_none() || !band_named)
            .flat_map(move |band| {
                (-4..=3).map(move |j| {
                    let mut knobs = vec![(Knob::Breakaway, b), (Knob::Gain, gain * 2f64.powi(j))];
                    if let Some(share) = band {
                        knobs.push((Knob::PositionerDeadband, share * b));
                    }
                    knobs
                })
            })
    });
    let input = sizes().flat_map(|jump| {
        [1.0, 0.5, 0.25].into_iter().flat_map(move |fraction| {
            [1.0, 4.0, 16.0].into_iter().map(move |g| {
                vec![
                    (Knob::Stickband, jump / fraction),
                    (Knob::JumpFraction, fraction),
                    (Knob::Gain, gain * g),
                ]
            })
        })
    });
    breakaway.chain(input).collect()
}

/// Smooth valves that make slips too, seeded like [`grid`]: a friction band crossed at the
/// positioner's speed (a stem that waits on a reversal while the pressure crosses the band,
/// then catches up with the target within 0.1 s, as a pulsing positioner makes it) from half
/// to four times the median slip, with the positioner gains [`grid`] gives stick-slip (1/16 to
/// 16 times the model's: with fewer, a fast positioner's catch-up after linkage play is left
/// to stick-slip alone), and a positioner deadband from one to four times it (a positioner
/// that acts only outside its band moves the stem back into it in one go).
fn smooth_grid(size: f64, gain: f64) -> Vec<Vec<(Knob, f64)>> {
    let band = (0..=12).flat_map(|i| {
        (-4..=4).map(move |j| {
            vec![
                (Knob::FrictionBand, size * 2f64.powf(i as f64 / 4.0 - 1.0)),
                (Knob::Gain, gain * 2f64.powi(j)),
            ]
        })
    });
    let deadband =
        (0..=8).map(|i| vec![(Knob::PositionerDeadband, size * 2f64.powf(i as f64 / 4.0))]);
    band.chain(deadband).collect()
}

/// Fits stick-slip to the measured slips and compares it with `current` (whose deadband, if
/// `band_named`, is a finding the fit leaves as it is) on the held-out blocks; an error when
/// the current model misses too few slips to fit anything, when they are steps of the current
/// model's deadband ([`band_steps`]: the error then says how large), or when a smooth valve
/// ([`smooth_grid`]) makes slips at least as like the measured ones as the best stick-slip
/// does: slips alone are then no evidence of stick-slip.
///
/// Slips are counted against the current (smooth) model's V_P. Every simulation gets the same
/// seeded sensor noise (and lattice) the recording has, so the slips that noise alone makes
/// count alike in the measurement and in every model. The grid point whose slips are closest
/// to the measured ones on the fit blocks wins (the free-run error only breaks ties: it cannot
/// judge a limit cycle).
pub(crate) fn fit(
    scorer: &Scorer,
    (current, band_named): (&ModelSpec, bool),
    facts: &Facts,
    sigma: f64,
    tuning: &Tuning,
) -> Result<Candidate, Option<BandSteps>> {
    let scale = &facts.slip_scale;
    let threshold = scale.threshold_pct;
    let pieces = Pieces::new(scorer);
    let reference = scorer.simulate(current);
    let measured_slips = facts::slips(&reference, scorer.vp, scale);
    let measured = histograms(&measured_slips, threshold, &pieces);
    let sensor = Sensor::new(scorer.vp, sigma, facts.lattice_pct);
    // A simulated V_P as the sensor reads it, its slips, their per-piece distances and its
    // fit error.
    let score = |y: &[f64]| {
        let read = sensor.read(y);
        let slips = facts::slips(&reference, &read, scale);
        let d = distances(&measured, &histograms(&slips, threshold, &pieces));
        (read, slips, d, scorer.errors_of(y).fit)
    };
    let (read_before, slips_before, before, _) = score(&reference);
    let missed = (
        total(&before, &pieces, false),
        total(&before, &pieces, true),
    );
    let rest = Rest::new(scale, sigma, scorer.skip, tuning);
    let (evident, evident_model) = (
        rest.evident(&measured_slips, scorer.vp),
        rest.evident(&slips_before, &read_before),
    );
    let by_evidence =
        evident >= EVIDENT_SLIPS && evident as f64 >= EVIDENT_RATIO * evident_model.max(1) as f64;
    let follows = rest.follows(&measured_slips, scorer.vp, &reference);
    tracing::debug!(?missed, evident, evident_model, follows, "slips of V_P");
    let both_halves = missed.0 >= MIN_MISSED && missed.1 >= MIN_MISSED;
    let per_min = EVIDENT_PER_MIN * scorer.n_fit() as f64 * scorer.dt / 60.0;
    let hunting = missed.0.min(missed.1) >= per_min;
    if !worth_judging(evident, follows, hunting) || !(both_halves || by_evidence) {
        return Err(None);
    }
    // Fitted on the fit blocks; on all of them when those hold too few slips to fit.
    let fit_on = |d: &[f64]| {
        if missed.0 >= MIN_MISSED {
            total(d, &pieces, false)
        } else {
            d.iter().sum()
        }
    };
    let size = median_slip(&measured_slips, scorer, missed.0 >= MIN_MISSED);
    if let Some(steps) = band_steps(size, current) {
        return Err(Some(steps));
    }
    let gain = composed::get(current, Knob::Gain);
    let closest = |grid: Vec<Vec<(Knob, f64)>>| {
        grid.par_iter()
            .map(|knobs| {
                let spec = with_knobs(current, knobs);
                let (_, _, d, sse) = score(&scorer.simulate(&spec));
                let free: Vec<Knob> = knobs.iter().map(|&(k, _)| k).collect();
                (spec, free, fit_on(&d), sse)
            })
            .min_by(|a, b| a.2.total_cmp(&b.2).then(a.3.total_cmp(&b.3)))
    };
    let (spec, knobs, stick_distance, _) = closest(grid(size, gain, band_named)).ok_or(None)?;
    let (smooth_spec, _, smooth_distance, _) = closest(smooth_grid(size, gain)).ok_or(None)?;
    let (read_smooth, slips_smooth, smooth, _) = score(&scorer.simulate(&smooth_spec));
    let evident_smooth = rest.evident(&slips_smooth, &read_smooth);
    tracing::debug!(
        stick_distance,
        smooth_distance,
        evident_smooth,
        "stick-slip against smooth friction"
    );
    let beyond_smooth =
        evident as f64 >= EVIDENT_RATIO * evident_model.max(evident_smooth).max(1) as f64;
    let quiet = 2.0 * stats::noise_sd(scorer.op, Differences::First) < threshold;
    // Under a quiet command, a rival the valve outnumbers five times over explains none of its
    // slips (no lean is asked of it); when the valve is also named by evidence with
    // [`RIVAL_SLIPS`] evident slips or more, the rival vetoes nothing.
    let outnumbered = quiet && beyond_smooth;
    let no_rival = outnumbered && by_evidence && evident >= RIVAL_SLIPS;
    if smooth_distance <= stick_distance && !no_rival {
        return Err(None);
    }
    let (_, slips_after, after, _) = score(&scorer.simulate(&spec));
    let held = Match::new(
        &pieces,
        scorer,
        (&before, &after),
        (&measured_slips, &slips_after),
    );
    let by_count = beyond_smooth
        && (by_evidence
            || (hunting
                && size >= tuning.worth.slip_pct.max(1.5 * sigma)
                && held.distance_after < held.distance_before));
    let candidate = Candidate {
        distance_all: (before.iter().sum(), after.iter().sum()),
        smooth_lean: (evident_smooth > evident_model && !outnumbered).then(|| {
            let lean = |held| stats::signed_rank_p(&drops(&pieces, &smooth, &after, held));
            (lean(Some(true)), lean(None))
        }),
        held,
        by_count,
        spec,
        knobs,
        slips_measured: measured_slips,
        slips_before,
        slips_after,
    };
    tracing::debug!(
        params = ?candidate.knobs.iter().map(|&k| (k.label(), composed::get(&candidate.spec, k))).collect::<Vec<_>>(),
        held = ?candidate.held,
        passes = candidate.passes(),
        "stick-slip by slip statistics"
    );
    Ok(candidate)
}

/// Whether V_P sticks, then jumps, against the current model `current`: at least
/// [`MIN_EVIDENT`] evident slips, with the stem stuck before them ([`Rest::follows`] below
/// [`FOLLOWS`]), and, beside a smooth model `smooth` (a deadband that removes nearly as much
/// held-out error as stiction), [`EVIDENT_RATIO`] times those of `smooth` read through a
/// sensor like the recording's. A valve in a deadband rests anywhere in the band around its
/// target and is moved back into it at the positioner's speed, and a valve following a noisy
/// command moves all along; stick-slip sticks, then jumps. Asked of stick-slip that wins a
/// round by the held-out error (its slips are judged in [`fit`]).
pub(crate) fn jumps(
    scorer: &Scorer,
    (current, smooth): (&ModelSpec, Option<&ModelSpec>),
    facts: &Facts,
    sigma: f64,
    tuning: &Tuning,
) -> bool {
    let scale = &facts.slip_scale;
    let reference = scorer.simulate(current);
    let rest = Rest::new(scale, sigma, scorer.skip, tuning);
    let slips = facts::slips(&reference, scorer.vp, scale);
    let (evident, follows) = (
        rest.evident(&slips, scorer.vp),
        rest.follows(&slips, scorer.vp, &reference),
    );
    let evident_smooth = smooth.map_or(0, |smooth| {
        let read = Sensor::new(scorer.vp, sigma, facts.lattice_pct).read(&scorer.simulate(smooth));
        rest.evident(&facts::slips(&reference, &read, scale), &read)
    });
    tracing::debug!(evident, follows, evident_smooth, "jumps of V_P");
    let in_band = smooth
        .is_some_and(|smooth| band_steps(median_slip(&slips, scorer, false), smooth).is_some());
    stuck_then_jumps(evident, follows)
        && evident as f64 >= EVIDENT_RATIO * evident_smooth.max(1) as f64
        && !in_band
}

/// V_P's median step `slip` (%) with the deadband of `spec`, when the step is no more than
/// [`BAND_STEP_SHARE`] of it: a pulsing positioner's steps at the edge of its band, not
/// stick-slip. Which it is cannot be told from V_P when a stem sticks inside a wide band;
/// narrowing the band tells them apart (stick-slip keeps its jumps, the steps shrink with the
/// band).
fn band_steps(slip: f64, spec: &ModelSpec) -> Option<BandSteps> {
    let band = size::deadband(spec);
    (slip <= BAND_STEP_SHARE * band).then(|| {
        tracing::debug!(slip, band, "steps of V_P within its deadband");
        BandSteps {
            step_pct: slip,
            band_pct: band,
        }
    })
}

/// A stem that sticks, then jumps: at least [`MIN_EVIDENT`] evident slips, and V_P stuck
/// before them rather than following the model ([`Rest::follows`] below [`FOLLOWS`]).
fn stuck_then_jumps(evident: usize, follows: f64) -> bool {
    evident >= MIN_EVIDENT && follows < FOLLOWS
}

/// Whether the slips are worth judging: the stem sticks, then jumps ([`stuck_then_jumps`]), or
/// the current model misses slips as a hunting valve's (`hunting`) while the noise hides them
/// one by one (fewer than [`MIN_EVIDENT`] evident). Ten or more evident slips before which V_P
/// follows the model are a valve moving all along, whatever the count.
fn worth_judging(evident: usize, follows: f64, hunting: bool) -> bool {
    stuck_then_jumps(evident, follows) || (hunting && evident < MIN_EVIDENT)
}

/// `current` with the `knobs` set.
fn with_knobs(current: &ModelSpec, knobs: &[(Knob, f64)]) -> ModelSpec {
    let mut spec = current.clone();
    for &(k, v) in knobs {
        composed::set(&mut spec, k, v);
    }
    spec
}

#[cfg(test)]
mod tests {
    use super::*;
    use vb_core::model::{bundled, ModelKind};

    #[test]
    fn steps_of_a_quarter_of_a_deadband_or_less_are_the_bands() {
        let smooth = composed::compose(&bundled(ModelKind::Fopdt), 0.01);
        assert!(band_steps(0.3, &smooth).is_none(), "no band, no band steps");
        for knob in [Knob::Deadband, Knob::PositionerDeadband] {
            let band = with_knobs(&smooth, &[(knob, 2.4)]);
            let steps = |slip| band_steps(slip, &band).map(|b| (b.step_pct, b.band_pct));
            assert_eq!(steps(0.3), Some((0.3, 2.4)), "{knob:?}");
            assert_eq!(steps(0.6), Some((0.6, 2.4)), "{knob:?}");
            assert_eq!(steps(0.7), None, "{knob:?}");
        }
    }

    #[test]
    fn stick_slip_in_the_loop_is_tried_with_a_band_unless_a_deadband_is_named() {
        let banded = |named| {
            let g = grid(0.4, 4.0, named);
            let with_band =
                |k: &Vec<(Knob, f64)>| k.iter().any(|&(k, _)| k == Knob::PositionerDeadband);
            let breakaways = g.iter().filter(|k| k[0].0 == Knob::Breakaway).count();
            (breakaways, g.iter().filter(|k| with_band(k)).count())
        };
        // Nine breakaways from 0.2 to 0.8 %, eight gains each, alone and with a band of half
        // and all of the breakaway; with a deadband named, alone only.
        assert_eq!(banded(false), (9 * 8 * 3, 9 * 8 * 2));
        assert_eq!(banded(true), (9 * 8, 0));
        let halves = grid(0.4, 4.0, false)
            .into_iter()
            .filter(|k| k.len() == 3 && k[2].0 == Knob::PositionerDeadband)
            .all(|k| {
                [0.5, 1.0]
                    .iter()
                    .any(|s| (k[2].1 - s * k[0].1).abs() < 1e-12)
            });
        assert!(halves);
    }

    #[test]
    fn histogram_distance_counts_slips_of_the_wrong_size_or_number() {
        let pieces = Pieces {
            block_len: 1000,
            per_block: 1,
            count: 4,
            skip: 0,
        };
        let slip = |k, size_pct| Slip { k, size_pct };
        // Threshold 0.2: 0.4 sits on the second bin, 0.3 between the first two.
        let a = histograms(&[slip(100, 0.4), slip(1500, -0.4)], 0.2, &pieces);
        assert_eq!(a[0], [0.0, 1.0, 0.0, 0.0]);
        let b = histograms(&[slip(900, 0.4), slip(1200, 0.4)], 0.2, &pieces);
        // Timing inside a block does not matter, the sign does not either.
        assert_eq!(distances(&a, &b), vec![0.0, 0.0, 0.0, 0.0]);
        let c = histograms(&[slip(100, 0.3)], 0.2, &pieces);
        let x = 0.3f64 / 0.2;
        let f = x.log2();
        assert!((c[0][0] - (1.0 - f)).abs() < 1e-12 && (c[0][1] - f).abs() < 1e-12);
        assert_eq!(distances(&a, &c)[1], 1.0);
    }

    #[test]
    fn a_hunting_count_stands_in_for_hidden_slips_not_for_slips_that_follow_the_model() {
        // Stuck before its slips: judged, hunting or not.
        assert!(worth_judging(35, 0.0, false));
        // Too few evident slips: judged only when the model misses them by the dozen.
        assert!(!worth_judging(3, 0.0, false));
        assert!(worth_judging(3, 0.6, true));
        // Many evident slips that follow the model: a valve moving all along, whatever the count.
        assert!(!worth_judging(35, 0.46, true));
    }

    #[test]
    fn stick_slip_is_named_by_a_close_match_or_by_an_overwhelming_count() {
        let held = |simulated: usize, distance_after: f64| Match {
            better: 25,
            worse: 5,
            p_value: 0.001,
            distance_before: 500.0,
            distance_after,
            measured: (500, 0.9),
            simulated: (simulated, 0.9),
        };
        let mut spec = vb_core::model::bundled(vb_core::model::ModelKind::Pincart2);
        composed::set(&mut spec, Knob::Breakaway, 0.9);
        let candidate = |held, by_count| Candidate {
            spec: spec.clone(),
            knobs: vec![Knob::Breakaway],
            held,
            slips_measured: vec![],
            slips_before: vec![],
            slips_after: vec![],
            by_count,
            distance_all: (1000.0, 700.0),
            smooth_lean: Some((0.01, 0.01)),
        };
        // Slipping as often and as much, and a third of the distance gone: named.
        assert!(candidate(held(450, 300.0), false).passes());
        // A fifth as often and a fifth of the distance gone: not a match...
        assert!(!held(100, 400.0).slips_alike());
        assert!(!candidate(held(100, 400.0), false).passes());
        // ...but named when the current model misses slips by the hundred (`by_count`).
        assert!(candidate(held(100, 400.0), true).passes());
        // Only when it brings the histograms closer somewhere: the held-out pieces, or else
        // the whole recording.
        assert!(matches!(
            candidate(held(100, 400.0), true).distance(),
            Measure::SlipDistance { heldout: true, .. }
        ));
        let worse = candidate(held(100, 600.0), true);
        assert!(matches!(
            worse.distance(),
            Measure::SlipDistance { heldout: false, after, .. } if after == 700.0
        ));
        assert!(worse.passes());
        let nowhere = Candidate {
            distance_all: (1000.0, 1100.0),
            ..candidate(held(100, 600.0), true)
        };
        assert!(!nowhere.passes());
        // A smooth rival that matches the slips better piece by piece where the candidate is
        // judged (held-out pieces here) sinks it, by match or by number; one that makes no
        // more evident slips than the current model is no rival.
        let rival = |lean| Candidate {
            smooth_lean: lean,
            ..candidate(held(450, 300.0), true)
        };
        assert!(!rival(Some((0.9, 0.1))).passes());
        assert!(rival(Some((0.3, 0.9))).passes());
        assert!(rival(None).passes());
        // Judged on every piece when the held-out ones do not improve.
        let on_all = |lean| Candidate {
            smooth_lean: lean,
            ..candidate(held(100, 600.0), true)
        };
        assert!(on_all(Some((0.9, 0.1))).passes());
        assert!(!on_all(Some((0.1, 0.9))).passes());
    }
}
