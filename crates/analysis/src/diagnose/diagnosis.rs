//! What a diagnosis concludes, in the shape of `--json`: the [`Diagnosis`] with its
//! [`Finding`]s, [`Trace`]s, [`Note`]s, [`Outcome`] and the final model's [`Figures`], and a
//! model's knobs as they are quoted ([`params`]).
//!
//! Not here: how they are reached (the parent module and [`super::rounds`]) or worded
//! (`report::diagnose`).

use serde::Serialize;
use serde_json::{Map, Value};

use super::evidence::Evidence;
use super::facts;
use super::locate::Window;
use super::measure::Measure;
use super::size::Size;
use vb_core::metrics::Scores;
use vb_core::model::composed::{self, Effect, Knob};
use vb_core::model::ModelSpec;

/// The starting point, scored.
#[derive(Debug, Clone, Serialize)]
pub struct Baseline {
    pub model: String,
    pub heldout_sse: f64,
    pub sse: f64,
    #[serde(skip)]
    pub spec: ModelSpec,
}

/// One effect found and kept.
#[derive(Debug, Clone, Serialize)]
pub struct Finding {
    pub effect: Effect,
    /// What the recording and the fit show (rendered as `evidence` in `--json`).
    pub facts: Evidence,
    /// The fitted values of the knobs the effect freed, by label.
    pub params: serde_json::Map<String, serde_json::Value>,
    /// Look-alikes that explain the recording nearly as well (within a fifth of the held-out
    /// error this effect removes): the recording cannot tell them apart (see the notes for the
    /// experiment that would).
    pub alternatives: Vec<Effect>,
    pub heldout_sse_before: f64,
    pub heldout_sse_after: f64,
    pub delta_bic: f64,
    /// How strongly the held-out blocks support it: the share of the error above the noise
    /// floor it removes, and the number of blocks it helps beyond noise (see `judge`); `None`
    /// for effects named from their evidence rather than the free-run error.
    pub support: Option<Support>,
    /// Its size in engineering units, in the final model, with its interval.
    pub size: Size,
    /// The measure in which adding it improved the model.
    pub measure: Measure,
    /// The knobs of `params`.
    #[serde(skip)]
    pub knobs: Vec<composed::Knob>,
}

/// An effect the recording shows beyond chance, too small to be worth maintenance (by its size
/// or by the share of the held-out error it removes): reported, never a finding.
#[derive(Debug, Clone, Serialize)]
pub struct Trace {
    pub effect: Effect,
    /// Its size with its interval.
    pub size: Size,
    /// Share of the held-out error it would remove.
    pub heldout_share: f64,
    pub params: serde_json::Map<String, serde_json::Value>,
    #[serde(skip)]
    pub spec: ModelSpec,
}

/// The figures of the final model every output quotes under these names (report, JSON, fleet,
/// Python): one value per quantity.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Figures {
    /// Dead time T_d, s.
    pub dead_time_s: f64,
    /// Friction band (lost motion on a reversal), %: the model's band, or its crossing time
    /// converted to the band it means in this recording ([`size::friction_band`]); 0 without
    /// either; NaN (`null` in JSON) when the recording shows a crossing time but not its band.
    pub friction_band_pct: f64,
    /// Stroke-speed limit opening and closing at half travel, %/s; NaN (`null` in JSON) when
    /// no move of the recording asked the valve for it (the model's speed is not determined).
    pub opening_speed_pct_per_s: f64,
    pub closing_speed_pct_per_s: f64,
}

/// How strongly the held-out blocks support a finding.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Support {
    pub excess_share: f64,
    pub blocks_helped: f64,
}

/// The model diagnosis ends with.
#[derive(Debug, Clone, Serialize)]
pub struct Final {
    pub model: String,
    pub heldout_sse: f64,
    pub params: serde_json::Value,
    #[serde(skip)]
    pub spec: ModelSpec,
}

/// Table 1 rows on the held-out blocks, before and after.
#[derive(Debug, Clone)]
pub struct Comparison {
    pub before: Scores,
    pub after: Scores,
}

/// What the data could not settle, or how an effect was judged.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Note {
    /// Two look-alikes explain the mismatch almost equally well (shares of the held-out error
    /// each removes).
    LookAlike {
        effect: Effect,
        other: Effect,
        removed_share: f64,
        other_removed_share: f64,
    },
    /// Stiction was kept by the slips of V_P, not by the free-run error.
    JudgedBySlips {
        heldout_sse_before: f64,
        heldout_sse_after: f64,
    },
    /// V_P steps (median `step_pct`) by a quarter of the model's deadband (`band_pct`) or
    /// less: a pulsing positioner's steps back into its tolerance band, not judged stick-slip
    /// (a stem sticking by that little inside the band looks the same).
    StepsInBand { step_pct: f64, band_pct: f64 },
    /// Too few reversals of O_P to test the effects that show at reversals.
    FewReversals { reversals: usize },
    /// The valve strokes slower than a valve in good order in a direction the recording asked
    /// it to go fast in: its fastest speed each way, measured on the recording (`None` where
    /// nothing asked), whether or not the model needed a speed limit. A step of O_P (up to
    /// `largest_step_pct`) of 20 % or more asks for `worth_pct_per_s` (`asked_pct_per_s` is
    /// then that too); otherwise `asked_pct_per_s` is the fastest a valve in good order moves
    /// on the same O_P (a ramp asks for its own rate).
    SlowStrokes {
        opening_pct_per_s: Option<f64>,
        closing_pct_per_s: Option<f64>,
        largest_step_pct: f64,
        asked_pct_per_s: f64,
        worth_pct_per_s: f64,
    },
    /// The reading's calibration, too small to name, was put in the model before the effects
    /// were judged: it explained more of the held-out error than any effect did.
    SensorCalibration {
        gain: f64,
        offset_pct: f64,
        heldout_sse_before: f64,
        heldout_sse_after: f64,
    },
    /// An effect real beyond chance but too small to be worth maintenance (its trace) was put
    /// in the model before the others were judged: it explained more of the held-out error
    /// than any effect worth maintenance did.
    BelowWorth {
        effect: Effect,
        size: Size,
        heldout_sse_before: f64,
        heldout_sse_after: f64,
    },
}

/// The conclusion of a diagnosis (rendered as `verdict` in `--json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Outcome {
    /// Nothing found, and the residual is consistent with measurement noise.
    Noise,
    /// Nothing found, although `windows` stand above the noise floor.
    NotSignificant { windows: usize },
    /// The model was missing these effects; the held-out SSE before and after adding those
    /// judged by it (stiction judged by its slips improves the slip distance instead, see its
    /// finding's [`Measure`]).
    Missing {
        effects: Vec<Effect>,
        heldout_sse_before: f64,
        heldout_sse_after: f64,
        /// Stiction was judged by the slips of V_P.
        by_slips: bool,
    },
}

/// Everything a diagnosis found, in the shape of `--json`.
#[derive(Debug, Clone, Serialize)]
pub struct Diagnosis {
    pub baseline: Baseline,
    pub noise_floor_pct: f64,
    pub mismatch_windows: Vec<Window>,
    pub findings: Vec<Finding>,
    /// Effects shown beyond chance but not worth maintenance.
    pub traces: Vec<Trace>,
    /// The final model's figures, as every output quotes them.
    pub figures: Figures,
    #[serde(rename = "final")]
    pub final_model: Final,
    pub outcome: Outcome,
    /// What the data could not tell apart, and what experiment would.
    pub notes: Vec<Note>,
    /// Windows left after the final model.
    #[serde(skip)]
    pub windows_after: Vec<Window>,
    #[serde(skip)]
    pub heldout: Option<Comparison>,
    /// Simulated V_P of the baseline and the final model, for plots.
    #[serde(skip)]
    pub sim_before: Vec<f64>,
    #[serde(skip)]
    pub sim_after: Vec<f64>,
    /// The step responses measured in the recording (evidence for delays).
    #[serde(skip)]
    pub steps: Vec<facts::StepResponse>,
}

/// The values of `knobs` in `spec`, by label, rounded to four decimals as reported.
pub(crate) fn params(spec: &ModelSpec, knobs: impl Iterator<Item = Knob>) -> Map<String, Value> {
    knobs
        .map(|k| {
            let v = composed::get(spec, k);
            (
                k.label().to_string(),
                serde_json::json!((v * 1e4).round() / 1e4),
            )
        })
        .collect()
}
