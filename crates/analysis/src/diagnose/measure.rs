//! [`Measure`]: the measure in which a finding showed the fit improve (free-run error on the
//! held-out blocks, or the distance between slip-size histograms).
//!
//! Not here: how either is computed ([`super::scorer`], [`super::stickslip`]).

use serde::Serialize;

/// How a finding showed the fit improve.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Measure {
    /// The free-run squared error on the held-out blocks, %², before and after.
    HeldoutSse { before: f64, after: f64 },
    /// The distance between the slip-size histograms of the model and of the recording,
    /// summed over 10 s pieces (in slips), before and after: over the held-out pieces, or over
    /// the whole recording. What free-run error cannot judge (a limit cycle's phase), this can.
    SlipDistance {
        heldout: bool,
        before: f64,
        after: f64,
    },
}
