//! Rounds: grow the model one effect at a time until nothing more passes.
//!
//! Each round refits every candidate effect not yet found (in parallel), judges each on the
//! held-out blocks, and keeps the best that passes. After each kept effect everything kept so
//! far is refitted together, from the fitted values and from spread starts, so a later effect
//! can take back what an earlier one was stretched to cover; the joint refit is kept only if
//! neither error rises. An effect that removed next to nothing is not tried again. A sensor
//! calibration too small to name but explaining more than the round's winner is put in the
//! model unnamed first, and the round's candidates refitted on top of it.
//!
//! When no effect passes, stick-slip may still be there, judged by its slips
//! ([`super::stickslip`]); a finding there ends the search, since free-run error cannot judge
//! anything after a limit cycle of its own phase.
//!
//! A candidate that explains the recording beyond chance but is too small to be worth
//! maintenance is kept aside as a trace (the last round's, for effects never found).
//!
//! Not here: the candidates ([`super::candidates`]), the tests ([`super::judge`]) or the
//! evidence ([`super::evidence`]).

use rayon::prelude::*;
use serde_json::Value;

use super::candidates;
use super::delay::MAX_DEAD_TIME_S;
use super::diagnosis::{params, Finding, Note, Support, Trace};
use super::evidence::Evidence;
use super::facts::Facts;
use super::judge::{
    best_per_effect, bic_change, floor_alike, floor_alike_untold, offset_alike, pick_nuisance,
    Judge, Trial,
};
use super::locate::Window;
use super::measure::Measure;
use super::refit::{refit_from, spread_starts, starting_at, Free};
use super::scorer::{Errors, Scorer};
use super::size::{self, Size};
use super::stickslip;
use super::tuning::Tuning;
use vb_core::metrics::stats;
use vb_core::model::composed::{self, Effect, Knob};
use vb_core::model::ModelSpec;
use vb_core::recording::RecordingView;

/// Most effects one diagnosis adds.
pub(super) const ROUNDS: usize = 4;
/// An effect whose best refit removed less held-out error than this share of what remains
/// after the round's winner is not tried again: to be kept next round it would have to remove
/// twenty times as much (a tenth of the excess), and each round refits every candidate on the
/// whole recording.
const RETRY_SHARE: f64 = 0.005;
/// A winner that leaves less than this share of the held-out error dominated its round (see
/// [`Search::run`]).
const DOMINANT_LEFT: f64 = 0.5;
/// Share of the fit error the refit of the model's own knobs before a round must remove to be
/// kept (less is rounding, and would only blur what the round's candidates are judged against).
const REST_GAIN: f64 = 1e-3;
/// Where the stop's wind-up restarts, % of travel ([`Search::wind_up`]).
const WINDUP_STARTS: [f64; 7] = [5.0, 20.0, 40.0, 70.0, 100.0, 180.0, 320.0];
/// Share of the best candidate's held-out gain another must reach to win the round by the
/// support of more held-out blocks.
const TIE_SHARE: f64 = 0.95;
/// Share of the winner's held-out gain a look-alike must reach to be named beside it.
const LOOK_ALIKE_SHARE: f64 = 0.8;

/// What a search reads and never changes: the recording, its split, what was measured on it.
#[derive(Clone, Copy)]
pub(crate) struct Data<'a> {
    pub rec: &'a RecordingView<'a>,
    pub scorer: &'a Scorer<'a>,
    pub facts: &'a Facts,
    /// Noise floor of V_P, %.
    pub sigma: f64,
    /// Where the baseline missed (quoted in the evidence).
    pub windows: &'a [Window],
    pub tuning: &'a Tuning,
}

/// The growing model and what was found so far.
pub(crate) struct Search<'a> {
    data: Data<'a>,
    /// What noise alone leaves on the held-out blocks, %².
    held_noise: f64,
    /// The model so far and its errors.
    pub current: ModelSpec,
    pub cur: Errors,
    /// Correlation length of the current residual, samples.
    corr_len: f64,
    /// Bound of the dead time of effects other than `dead_time`, s.
    td_max: f64,
    pub findings: Vec<Finding>,
    /// Effects shown beyond chance but too small to be worth maintenance.
    pub traces: Vec<Trace>,
    pub notes: Vec<Note>,
    /// Set when stiction was kept by the slips of V_P rather than by the free-run error.
    pub by_slips: bool,
    /// The knobs the kept effects freed, with their boxes.
    freed: Vec<Free>,
}

impl<'a> Search<'a> {
    /// A search from `start`, whose residual has correlation length `corr_len`; effects other
    /// than `dead_time` may use a dead time up to `td_max`.
    pub(super) fn new(data: Data<'a>, start: ModelSpec, corr_len: f64, td_max: f64) -> Self {
        Search {
            held_noise: data.scorer.n_held() as f64 * data.sigma * data.sigma,
            cur: data.scorer.errors(&start),
            data,
            current: start,
            corr_len,
            td_max,
            findings: Vec::new(),
            traces: Vec::new(),
            notes: Vec::new(),
            by_slips: false,
            freed: Vec::new(),
        }
    }

    /// What noise alone leaves on the held-out blocks, %².
    pub(super) fn held_noise(&self) -> f64 {
        self.held_noise
    }

    /// Correlation length of the current residual, samples.
    pub(super) fn corr_len(&self) -> f64 {
        self.corr_len
    }

    /// Runs the rounds; `progress(done, total)` after each.
    pub(super) fn run(&mut self, progress: &(dyn Fn(usize, usize) + Sync)) {
        self.sensor_lattice();
        let total = Effect::ALL.len() * ROUNDS;
        // Effects worth trying this round: all at first, then those that helped enough before.
        let mut worth: Vec<Effect> = Effect::ALL.to_vec();
        for round in 0..ROUNDS {
            self.refit_rest();
            let mut trials = self.trials(&worth);
            progress(((round + 1) * Effect::ALL.len()).min(total), total);
            while let Some(nuisance) = self.nuisance(&best_per_effect(&trials)) {
                self.absorb(nuisance);
                trials = self.trials(&worth);
            }
            let best = best_per_effect(&trials);
            for t in &best {
                let fitted = Value::Object(params(&t.spec, t.free.iter().map(|f| f.knob)));
                tracing::debug!(
                    effect = t.effect.name(),
                    held_before = self.cur.held,
                    held_after = t.errors.held,
                    t_stat = t.t_stat,
                    excess_share = t.excess_share,
                    heldout_share = t.heldout_share,
                    delta_bic = t.delta_bic,
                    size = t.size.value,
                    worth = t.size.worth,
                    plausible = t.plausible,
                    material = t.material,
                    params = %fitted,
                    "candidate"
                );
                if t.trace() {
                    self.trace(t);
                }
            }
            let Some(winner) = self.winner(&best) else {
                self.stick_slip();
                break;
            };
            // After a winner that took most of the error, what the others did was judged
            // against a model that missed something far larger: all are tried again.
            let dominant = winner.errors.held < DOMINANT_LEFT * self.cur.held;
            worth = best
                .iter()
                .filter(|t| {
                    dominant || self.cur.held - t.errors.held >= RETRY_SHARE * winner.errors.held
                })
                .map(|t| t.effect)
                .collect();
            // A trace of this round that removed nearly as much as the winner stood in for the
            // winner's error, not for an imperfection of its own.
            let stood_in: Vec<Effect> = (best.iter())
                .filter(|t| t.trace() && t.heldout_share >= LOOK_ALIKE_SHARE * winner.heldout_share)
                .map(|t| t.effect)
                .collect();
            self.traces.retain(|x| !stood_in.contains(&x.effect));
            let alternatives = self.look_alikes(winner, &best);
            self.keep(winner, &alternatives, round > 0);
        }
        let found: Vec<Effect> = self.findings.iter().map(|f| f.effect).collect();
        self.traces.retain(|t| !found.contains(&t.effect));
        if self.findings.is_empty() && self.data.facts.reversals < 10 {
            self.notes.push(Note::FewReversals {
                reversals: self.data.facts.reversals,
            });
        }
    }

    /// A coarse sensor lattice is named from its evidence (every value of V_P on it) and put in
    /// the model before the rounds, not judged by the free-run error: rounding the model's
    /// output changes little next to the error of its dynamics, and the rounds then compare
    /// models that read like the sensor.
    fn sensor_lattice(&mut self) {
        let q = self.data.facts.lattice_pct;
        let least = self.data.tuning.worth.lattice_pct * self.data.tuning.materiality;
        if q < least || composed::get(&self.current, Knob::Quantum) > 0.0 {
            return;
        }
        let mut spec = self.current.clone();
        composed::set(&mut spec, Knob::Quantum, q);
        let errors = self.data.scorer.errors(&spec);
        let facts = Evidence::of(
            Effect::Quantization,
            &spec,
            &self.current,
            self.data.facts,
            self.data.windows,
            self.data.sigma,
        );
        self.findings.push(Finding {
            effect: Effect::Quantization,
            facts,
            params: params(&spec, [Knob::Quantum].into_iter()),
            knobs: vec![Knob::Quantum],
            alternatives: Vec::new(),
            heldout_sse_before: self.cur.held,
            heldout_sse_after: errors.held,
            delta_bic: bic_change(
                &self.cur,
                &errors,
                0,
                self.data.scorer.n_scored(),
                self.corr_len,
            ),
            support: None,
            size: self.size_of(Effect::Quantization, &spec),
            measure: Measure::HeldoutSse {
                before: self.cur.held,
                after: errors.held,
            },
        });
        self.current = spec;
        self.cur = errors;
    }

    /// Every candidate of the effects in `worth` not yet found, refitted and judged.
    fn trials(&self, worth: &[Effect]) -> Vec<Trial> {
        let effects: Vec<Effect> = worth
            .iter()
            .copied()
            .filter(|e| !self.findings.iter().any(|f| f.effect == *e) && !self.absorbed(*e))
            .collect();
        let jobs = candidates::jobs(
            &effects,
            &self.current,
            self.data.facts,
            self.data.rec.dt,
            self.td_max,
        );
        tracing::debug!(
            candidates = jobs.len(),
            starts = jobs.iter().map(|j| j.starts.len()).sum::<usize>(),
            "trying effects"
        );
        let current_sim = self.data.scorer.simulate(&self.current);
        let judge = Judge {
            scorer: self.data.scorer,
            facts: self.data.facts,
            tuning: self.data.tuning,
            sigma: self.data.sigma,
            held_noise: self.held_noise,
            current: &self.current,
            current_sim: &current_sim,
            cur: self.cur,
            corr_len: self.corr_len,
        };
        jobs.par_iter()
            .map(|job| {
                let (spec, errors) = refit_from(self.data.scorer, &self.current, &job.starts);
                judge.judge(job.effect, spec, errors, job.starts[0].clone(), job.own)
            })
            .collect()
    }

    /// A trace to put in the model unnamed (each effect once): real beyond chance but too small
    /// to name. A healthy valve's small imperfections (an open valve a little slower than a
    /// closed one) are real; judged against a model without them, an effect that is there can
    /// help less than the imperfection it does not describe, and the search would end there.
    /// So when no candidate passes, the trace that removes the most held-out error is put in
    /// the model and the round tried again; which trace, and when one goes in before a winner
    /// (the reading's calibration, or a small effect that removes far more), is
    /// [`pick_nuisance`]'s rule; a limit a floor fits nearly as well is one
    /// ([`floor_alike_untold`]).
    fn nuisance(&self, best: &[&Trial]) -> Option<Trial> {
        let winner = self.winner(best);
        let tuning = self.data.tuning;
        let dead_zone = |t: &Trial| size::dead_zone_worth(t.effect, &t.spec, tuning);
        let absorbed = |e| self.absorbed(e);
        let held = (self.cur.held, tuning.min_heldout_share);
        let told = floor_alike_untold(best, self.data.facts, held, LOOK_ALIKE_SHARE);
        let best: Vec<&Trial> = told.iter().collect();
        pick_nuisance(
            &best,
            winner,
            self.cur.held,
            tuning.materiality,
            dead_zone,
            absorbed,
        )
        .cloned()
    }

    /// Whether `effect` was put in the model as a nuisance.
    fn absorbed(&self, effect: Effect) -> bool {
        self.notes.iter().any(|n| match n {
            Note::SensorCalibration { .. } => effect == Effect::Calibration,
            Note::BelowWorth { effect: e, .. } => *e == effect,
            _ => false,
        })
    }

    /// Puts the nuisance `t` in the current model, unnamed, with a note (an effect stays a
    /// trace; the calibration's note gives its figures); it is not tried again, its knobs are
    /// refitted with the model's own.
    fn absorb(&mut self, t: Trial) {
        let (before, after) = (self.cur.held, t.errors.held);
        let note = match t.effect {
            Effect::Calibration => Note::SensorCalibration {
                gain: composed::get(&t.spec, Knob::CalGain),
                offset_pct: composed::get(&t.spec, Knob::CalOffset),
                heldout_sse_before: before,
                heldout_sse_after: after,
            },
            effect => {
                self.trace(&t);
                Note::BelowWorth {
                    effect,
                    size: t.size,
                    heldout_sse_before: before,
                    heldout_sse_after: after,
                }
            }
        };
        self.notes.push(note);
        tracing::debug!(
            effect = t.effect.name(),
            held_after = after,
            "trace put in the model unnamed"
        );
        self.free(&t.free);
        self.current = t.spec;
        self.cur = t.errors;
    }

    /// Adds `free` to the knobs refitted together, with their boxes.
    fn free(&mut self, free: &[Free]) {
        for f in free {
            match self.freed.iter_mut().find(|g| g.knob == f.knob) {
                Some(g) => *g = *f,
                None => self.freed.push(*f),
            }
        }
    }

    /// The round's winner among the candidates that pass (`best` is sorted by held-out error):
    /// the one that removes the most held-out error, unless another removes nearly as much
    /// ([`TIE_SHARE`]) with the support of more held-out blocks: an effect that explains the
    /// error across the recording is better supported than one that helps a few blocks a lot.
    /// Then the smaller BIC: of two alike, the one with fewer parameters (a tolerance band).
    /// Stiction passes only where V_P sticks, then jumps ([`stickslip::jumps`]); with a
    /// deadband nearly as good ([`LOOK_ALIKE_SHARE`]) it must jump beyond what the deadband
    /// makes, else the deadband wins. An asymmetry a calibration offset fits
    /// about as well ([`offset_alike`]) does not pass: the offset is put in first; nor does a
    /// limit only a busy loop shows that a floor fits nearly as well ([`floor_alike`]).
    fn winner<'t>(&self, best: &[&'t Trial]) -> Option<&'t Trial> {
        let d = &self.data;
        let held_noise = self.held_noise();
        let jumps = |smooth| {
            let current = (&self.current, smooth);
            stickslip::jumps(d.scorer, current, d.facts, d.sigma, d.tuning)
        };
        let sticks = std::cell::OnceCell::new();
        let passes = |t: &Trial| {
            t.passes()
                && !offset_alike(t, best, d.facts, held_noise)
                && !floor_alike(t, best, d.facts, self.cur.held, LOOK_ALIKE_SHARE)
                && (t.effect != Effect::Stiction || *sticks.get_or_init(|| jumps(None)))
        };
        let first = *best.iter().find(|t| passes(t))?;
        let gain = |t: &Trial| self.cur.held - t.errors.held;
        let winner = (best.iter())
            .filter(|t| passes(t) && gain(t) >= TIE_SHARE * gain(first))
            .max_by(|a, b| {
                (a.t_stat.total_cmp(&b.t_stat)).then(b.delta_bic.total_cmp(&a.delta_bic))
            })
            .copied()?;
        let band = (best.iter()).find(|t| {
            t.effect == Effect::Deadband && t.passes() && gain(t) >= LOOK_ALIKE_SHARE * gain(winner)
        });
        match band {
            Some(band) if winner.effect == Effect::Stiction && !jumps(Some(&band.spec)) => {
                Some(band)
            }
            _ => Some(winner),
        }
    }

    /// The look-alikes of the winner that pass too and remove nearly as much held-out error,
    /// each with the share of it that it removes.
    fn look_alikes(&self, winner: &Trial, best: &[&Trial]) -> Vec<(Effect, f64)> {
        let gain = self.cur.held - winner.errors.held;
        best.iter()
            .filter(|o| {
                o.effect != winner.effect
                    && o.passes()
                    && winner.effect.look_alikes().contains(&o.effect)
                    && self.cur.held - o.errors.held >= LOOK_ALIKE_SHARE * gain
            })
            .map(|o| (o.effect, (self.cur.held - o.errors.held) / self.cur.held))
            .collect()
    }

    /// Keeps the round's winner (with the look-alikes the data cannot tell from it), then
    /// (after the first round) refits everything kept so far together.
    fn keep(&mut self, winner: &Trial, alternatives: &[(Effect, f64)], joint: bool) {
        if winner.effect == Effect::DeadTime {
            self.td_max = MAX_DEAD_TIME_S;
        }
        for &(other, other_removed_share) in alternatives {
            self.notes.push(Note::LookAlike {
                effect: winner.effect,
                other,
                removed_share: (self.cur.held - winner.errors.held) / self.cur.held,
                other_removed_share,
            });
        }
        self.findings.push(Finding {
            effect: winner.effect,
            facts: Evidence::of(
                winner.effect,
                &winner.spec,
                &self.current,
                self.data.facts,
                self.data.windows,
                self.data.sigma,
            ),
            params: params(&winner.spec, winner.free.iter().map(|f| f.knob)),
            knobs: winner.free.iter().map(|f| f.knob).collect(),
            alternatives: alternatives.iter().map(|a| a.0).collect(),
            heldout_sse_before: self.cur.held,
            heldout_sse_after: winner.errors.held,
            delta_bic: winner.delta_bic,
            support: Some(Support {
                excess_share: winner.excess_share,
                blocks_helped: winner.t_stat,
            }),
            size: winner.size,
            measure: Measure::HeldoutSse {
                before: self.cur.held,
                after: winner.errors.held,
            },
        });
        self.free(&winner.free);
        self.current = winner.spec.clone();
        self.cur = self.data.scorer.errors(&self.current);
        if joint {
            self.joint_refit();
        }
        if self.freed.iter().any(|f| f.knob == Knob::Windup) {
            self.wind_up();
        }
        let sim = self.data.scorer.simulate(&self.current);
        let residual: Vec<f64> = self
            .data
            .rec
            .vp
            .iter()
            .zip(&sim)
            .map(|(m, s)| m - s)
            .collect();
        self.corr_len = stats::correlation_length(&residual);
        tracing::debug!(corr_len = self.corr_len, "residual after the round");
    }

    /// Every knob freed so far refitted together, from where the rounds left it and afresh
    /// from the starts the rounds began with (effects fitted one at a time can leave the joint
    /// fit in a valley it only finds its way out of from outside); kept only if neither error
    /// rises.
    fn joint_refit(&mut self) {
        let from_here = starting_at(&self.freed, &self.current);
        let mut starts = spread_starts(self.freed.clone());
        starts.push(from_here);
        let (polished, errors) = refit_from(self.data.scorer, &self.current, &starts);
        tracing::debug!(
            held_before = self.cur.held,
            held_after = errors.held,
            "polish"
        );
        if errors.fit < self.cur.fit && errors.held <= self.cur.held {
            self.current = polished;
            self.cur = errors;
        }
    }

    /// The model's own gain, dead time and (healthy) stroke speed refitted before a round,
    /// from where they are, from each moved alone across its box, and with the stroke speed
    /// at the fastest speed the recording shows: every candidate refits them too, so what a
    /// candidate then gains beyond the current model is its own effect's doing, not a better
    /// fit of what the model already had. Kept only if neither error rises.
    fn refit_rest(&mut self) {
        let td = composed::get(&self.current, Knob::DeadTime);
        let rest =
            candidates::rest_of_model(&self.current, self.data.rec.dt, self.td_max.max(td), &[]);
        let facts = self.data.facts;
        let seen = facts.open_speed.max(facts.close_speed);
        let moved = |i: usize, to: f64| {
            let mut start = rest.clone();
            start[i] = start[i].from(to.clamp(start[i].def.lo, start[i].def.hi));
            start
        };
        let mut starts = vec![rest.clone()];
        for (i, f) in rest.iter().enumerate() {
            for share in [0.1, 0.4] {
                starts.push(moved(i, f.def.from_unit(share)));
            }
            if f.knob == Knob::Slew {
                starts.push(moved(i, seen));
            }
        }
        let (refitted, errors) = refit_from(self.data.scorer, &self.current, &starts);
        tracing::debug!(
            held_before = self.cur.held,
            held_after = errors.held,
            "model refitted before the round"
        );
        if errors.fit < (1.0 - REST_GAIN) * self.cur.fit && errors.held <= self.cur.held {
            self.current = refitted;
            self.cur = errors;
        }
    }

    /// The stop's wind-up refitted from starts up to [`candidates::WINDUP_RANGE_PCT`] (its box from then
    /// on), each with the stroke speed where it is and at the fastest speed seen (the other
    /// knobs where they are): the time to leave a stop, set by the wind-up and the speed the
    /// drive unwinds at together, is a narrow valley the round's few starts miss, and later
    /// effects (a slowdown of the open valve) would stretch to cover it. Kept if no error rises.
    fn wind_up(&mut self) {
        let wide = candidates::windup_from(0.0);
        let here = starting_at(&self.freed, &self.current);
        let seen = (self.data.facts.open_speed).max(self.data.facts.close_speed);
        let starts: Vec<Vec<Free>> = (WINDUP_STARTS.iter())
            .flat_map(|&start| [false, true].map(|at_seen| (start, at_seen)))
            .map(|(start, at_seen)| {
                (here.iter())
                    .map(|f| match f.knob {
                        Knob::Windup => wide.from(start),
                        Knob::Slew if at_seen => f.from(seen.clamp(f.def.lo, f.def.hi)),
                        _ => *f,
                    })
                    .collect()
            })
            .collect();
        let (polished, errors) = refit_from(self.data.scorer, &self.current, &starts);
        tracing::debug!(
            held_before = self.cur.held,
            held_after = errors.held,
            windup_pct = composed::get(&polished, Knob::Windup),
            "stop wind-up"
        );
        if errors.fit < self.cur.fit && errors.held <= self.cur.held {
            self.current = polished;
            self.cur = errors;
            self.free(&[wide]);
        }
    }

    /// Stick-slip judged by the slips of V_P, when the model has none yet or only a trace of it.
    /// A trace of stick-slip fitted by the free-run error is no size of it: the phase of a limit
    /// cycle cannot be fitted, and the error is least for slips far smaller than the valve's
    /// (a valve hunting by 0.6 % is fitted a slip of 0.05 %). Its slips are counted against
    /// the model without the trace; the trace stays when they say nothing.
    fn stick_slip(&mut self) {
        let mut smooth = self.current.clone();
        let traced = self.absorbed(Effect::Stiction);
        if traced {
            composed::set(&mut smooth, Knob::Stickband, 0.0);
            composed::set(&mut smooth, Knob::Breakaway, 0.0);
        }
        let stuck = [Knob::Stickband, Knob::Breakaway]
            .iter()
            .any(|&k| composed::get(&smooth, k) > 0.0);
        if stuck {
            return;
        }
        let band_named = self.findings.iter().any(|f| f.effect == Effect::Deadband);
        let c = match stickslip::fit(
            self.data.scorer,
            (&smooth, band_named),
            self.data.facts,
            self.data.sigma,
            self.data.tuning,
        ) {
            Ok(c) if c.passes() => c,
            Ok(_) | Err(None) => return,
            Err(Some(steps)) => {
                self.notes.push(Note::StepsInBand {
                    step_pct: steps.step_pct,
                    band_pct: steps.band_pct,
                });
                return;
            }
        };
        let tuning = self.data.tuning;
        let (value, low, high) = c.slip_size(self.data.scorer);
        let least = tuning.worth.slip_pct.max(1.5 * self.data.sigma);
        let size = Size {
            name: "slip_pct",
            unit: "%",
            value,
            low,
            high,
            worth: value / least,
            worth_low: low / least,
        };
        if size.worth_low < tuning.materiality {
            if traced {
                return;
            }
            self.traces.push(Trace {
                effect: Effect::Stiction,
                size,
                heldout_share: 0.0,
                params: params(&c.spec, c.knobs.iter().copied()),
                spec: c.spec.clone(),
            });
            return;
        }
        let errors = self.data.scorer.errors(&c.spec);
        let k_new = c.knobs.iter().filter(|&&k| k != Knob::Gain).count();
        self.findings.push(Finding {
            effect: Effect::Stiction,
            facts: Evidence::of_slips(&c, self.data.facts, self.data.windows, self.data.scorer.dt),
            params: params(&c.spec, c.knobs.iter().copied()),
            knobs: c.knobs.clone(),
            alternatives: Vec::new(),
            heldout_sse_before: self.cur.held,
            heldout_sse_after: errors.held,
            delta_bic: bic_change(
                &self.cur,
                &errors,
                k_new,
                self.data.scorer.n_scored(),
                self.corr_len,
            ),
            support: None,
            size,
            measure: c.distance(),
        });
        self.notes.retain(|n| {
            !matches!(
                n,
                Note::BelowWorth {
                    effect: Effect::Stiction,
                    ..
                }
            )
        });
        self.notes.push(Note::JudgedBySlips {
            heldout_sse_before: self.cur.held,
            heldout_sse_after: errors.held,
        });
        self.current = c.spec;
        self.by_slips = true;
    }
}

impl Search<'_> {
    /// The size of `effect` in `spec` (no interval yet).
    fn size_of(&self, effect: Effect, spec: &ModelSpec) -> Size {
        let d = &self.data;
        size::size(effect, spec, d.facts, d.rec.op, d.tuning)
    }

    /// Keeps the trace `t` (replacing an earlier one of its effect).
    fn trace(&mut self, t: &Trial) {
        let trace = Trace {
            effect: t.effect,
            size: t.size,
            heldout_share: t.heldout_share,
            params: params(&t.spec, t.free.iter().map(|f| f.knob)),
            spec: t.spec.clone(),
        };
        match self.traces.iter_mut().find(|x| x.effect == t.effect) {
            Some(x) => *x = trace,
            None => self.traces.push(trace),
        }
    }
}
