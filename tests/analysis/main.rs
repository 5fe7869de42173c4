//! The offline analysis through the real binary and the library: recordings read,
//! `identify`, `diagnose` (known cases, concealed effects, the physical valve, the blind
//! benchmark's cases and scores), `fleet`, the compensation trial and `response-test`. Here
//! are checked the figures README.md and docs/ quote from identification, diagnosis, the fleet and the
//! response test. One module per subject.

#[path = "../common/mod.rs"]
mod common;

// The blind benchmark's cases and its coverage table, shared with `benches/`.
#[path = "../../benches/blind/cases.rs"]
mod cases;
// Only the coverage of the bench's tables and README's figures from its records are checked here.
#[path = "../../benches/blind/record.rs"]
mod record;
#[allow(dead_code)]
#[path = "../../benches/blind/score.rs"]
mod score;
// The generator of the figures README and docs/ quote: the example's own code, one
// implementation; each module checks the blocks of its subject.
#[allow(dead_code)]
#[path = "../../examples/readme-figures/blocks.rs"]
mod blocks;

mod compensation_trial;
mod diagnose_blind_cases;
mod diagnose_blind_digital;
mod diagnose_blind_readme;
mod diagnose_blind_score;
mod diagnose_cases;
mod diagnose_concealed;
mod diagnose_dead_time;
mod diagnose_linkage_play;
mod diagnose_min_speed;
mod diagnose_physical;
mod diagnose_slow_positioner;
mod diagnose_smooth_slips;
mod diagnose_stiction_or_not;
mod diagnose_stop_windup;
mod diagnose_under_noise;
mod diagnose_uneven_and_slow;
mod fleet_cli;
mod identify_cli;
mod identify_paper;
mod physical_model;
mod recording_files;
mod response_test;
mod short_log;
