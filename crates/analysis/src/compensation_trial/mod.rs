//! Trials of compensation: a valve driven through a scenario with and without a
//! [`Compensator`], and the figures that judge it (the compensation bench, and its tests).
//!
//! Scenarios: the paper's level loop (the PI controller and tank of [`crate::synth::level`]),
//! the paper's random-step experiment, small steps (0.2-2 %, [`SmallSteps`]) and a sequence of
//! moves of 1-2 % held 10 s (where a deadband valve comes to rest). The valve is
//! stepped exactly as the daemon's emulated valve is: the compensator gets the controller's
//! O_P, the valve the set-point, and the compensator the V_P read.
//!
//! Figures (see [`Figures`]): the integrated absolute error of the process variable (the
//! level loop only), the tracking error of the stem against the valve's nominal healthy twin,
//! the raw RMS of O_P - V_P, and the stem's travel and reversals (wear). The stem is what a
//! copy of the valve with a noise-free sensor (same gain and offset) reads, driven by the same
//! set-points: compensation cannot change a sensor's noise, so the figures that judge it
//! leave the noise out, while the loop and the compensator see the noisy V_P a valve gives.
//!
//! [`bench`]: the compensation bench's valves, each with the model identified from its own
//! log, and the table of their trials.

pub mod bench;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::synth::excite::SmallSteps;
use crate::synth::{physical, LevelLoop};
use vb_core::compensate::Compensator;
use vb_core::metrics::{self, Travel};
use vb_core::model::{ModelError, ModelKind, ModelSpec, Valve};
use vb_core::signal::{RandomSteps, RandomStepsParams};

/// Deadband of the travel count, %: five standard deviations of a healthy sensor's noise.
pub const TRAVEL_DEADBAND_PCT: f64 = 0.1;
/// The levels of [`Scenario::Sequence`], %: closing and opening moves of 1-2 %.
pub const SEQUENCE: [f64; 6] = [50.0, 49.0, 51.0, 49.5, 48.0, 49.0];
/// How long each level of [`Scenario::Sequence`] is held, s.
pub const SEQUENCE_HOLD_S: f64 = 10.0;
/// A hold of [`Scenario::Sequence`] ends at its level when the stem is within this of it, %.
pub const SEQUENCE_TOLERANCE_PCT: f64 = 0.15;

/// What drives the valve.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scenario {
    /// The PI level loop around 50 % level (O_P carries the level sensor's noise).
    LevelLoop,
    /// The paper's experiment: levels uniform in 20-97 %, held 0-20 s.
    RandomSteps,
    /// Steps of 0.2-2 % held 2-10 s around 40 %, often reversing.
    SmallSteps,
    /// [`SEQUENCE`] twice, each level held [`SEQUENCE_HOLD_S`], after a hold at its last level
    /// (so each level is a move): where a deadband valve comes to rest ([`sequence_at`]).
    Sequence,
}

impl Scenario {
    /// Every scenario, in the bench's order.
    pub const ALL: [Scenario; 3] = [
        Scenario::LevelLoop,
        Scenario::RandomSteps,
        Scenario::SmallSteps,
    ];

    /// The name in tables.
    pub fn name(self) -> &'static str {
        match self {
            Scenario::LevelLoop => "level loop",
            Scenario::RandomSteps => "random steps",
            Scenario::SmallSteps => "small steps",
            Scenario::Sequence => "sequence",
        }
    }
}

/// One run: the controller's O_P, the set-points sent, the V_P read and the stem, per sample.
#[derive(Debug, Clone)]
pub struct Run {
    pub op: Vec<f64>,
    pub sent: Vec<f64>,
    pub vp: Vec<f64>,
    /// The stem: what a noise-free sensor of the same calibration reads, %.
    pub stem: Vec<f64>,
    /// ∫ |level - set-point| dt, %·s (level loop only).
    pub pv_iae: Option<f64>,
    /// When the guard switched compensation off, s.
    pub switched_off_s: Option<f64>,
}

/// Runs `valve` through `scenario` for `duration_s` at `dt`, through `comp` when given.
/// Deterministic for a seed; the same seed gives the same disturbances with or without.
pub fn run(
    valve: &ModelSpec,
    mut comp: Option<Compensator>,
    scenario: Scenario,
    duration_s: f64,
    dt: f64,
    seed: u64,
) -> Result<Run, ModelError> {
    let n = (duration_s / dt).round() as usize;
    let mut v = Valve::new(valve, dt)?;
    let mut stem = Valve::new(&noise_free(valve), dt)?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut plant = LevelLoop::new(50.0);
    let mut steps = RandomSteps::new(&RandomStepsParams {
        seed,
        ..RandomStepsParams::default()
    });
    let mut small = SmallSteps::new(40.0, seed);
    let mut out = Run {
        op: Vec::with_capacity(n),
        sent: Vec::with_capacity(n),
        vp: Vec::with_capacity(n),
        stem: Vec::with_capacity(n),
        pv_iae: (scenario == Scenario::LevelLoop).then_some(0.0),
        switched_off_s: None,
    };
    for k in 0..n {
        let t = k as f64 * dt;
        let op = match scenario {
            Scenario::LevelLoop => plant.controller(t, dt, &mut rng),
            Scenario::RandomSteps => steps.op_at(t),
            Scenario::SmallSteps => small.op_at(t),
            Scenario::Sequence => sequence_at(t),
        };
        if k == 0 {
            v.reset(op, op);
            stem.reset(op, op);
        }
        let sent = comp.as_mut().map_or(op, |c| c.setpoint(op, t));
        let vp = v.step(sent);
        if let Some(c) = comp.as_mut() {
            c.observe(Some(vp));
            if !c.active() && out.switched_off_s.is_none() {
                out.switched_off_s = Some(t);
            }
        }
        if let Some(iae) = out.pv_iae.as_mut() {
            plant.tank(vp, dt);
            *iae += plant.error_pct().abs() * dt;
        }
        out.op.push(op);
        out.sent.push(sent);
        out.vp.push(vp);
        out.stem.push(stem.step(sent));
    }
    Ok(out)
}

/// The O_P of [`Scenario::Sequence`] at `t_s`: its last level for the first hold, then its
/// levels twice, the last held on.
pub fn sequence_at(t_s: f64) -> f64 {
    let hold = (t_s / SEQUENCE_HOLD_S).floor() as usize;
    let n = SEQUENCE.len();
    match hold {
        0 => SEQUENCE[n - 1],
        h => SEQUENCE[(h - 1).min(2 * n - 1) % n],
    }
}

/// Where the `stem` ends each hold of [`Scenario::Sequence`] (driven by `op`, both sampled
/// every `dt` from its start), minus its level, %.
pub fn sequence_ends(stem: &[f64], op: &[f64], dt: f64) -> Vec<f64> {
    let hold = (SEQUENCE_HOLD_S / dt).round() as usize;
    (1..=2 * SEQUENCE.len())
        .filter_map(|h| {
            let end = (h + 1) * hold - 1;
            Some(stem.get(end)? - op.get(end)?)
        })
        .collect()
}

/// The figures of a run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Figures {
    /// ∫ |level - set-point| dt, %·s (level loop only).
    pub pv_iae: Option<f64>,
    /// RMS of the stem minus the nominal twin's stem for the controller's O_P, %: what the
    /// valve's imperfections (and compensation) change in its answer to the controller.
    pub tracking_pct: f64,
    /// RMS of the controller's O_P minus V_P, %: dead time, speed and noise included.
    pub raw_pct: f64,
    /// The stem's travel and reversals through [`TRAVEL_DEADBAND_PCT`].
    pub travel: Travel,
}

/// The figures of `run` at `dt`, its tracking error against `nominal` (see [`nominal`]).
pub fn figures(run: &Run, nominal: &ModelSpec, dt: f64) -> Result<Figures, ModelError> {
    let reference =
        Valve::new(nominal, dt)?.simulate(&run.op, run.op.first().copied().unwrap_or(0.0));
    let rms = |a: &[f64], b: &[f64]| {
        (a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / a.len().max(1) as f64).sqrt()
    };
    Ok(Figures {
        pv_iae: run.pv_iae,
        tracking_pct: rms(&run.stem, &reference),
        raw_pct: rms(&run.op, &run.vp),
        travel: metrics::travel(&run.stem, TRAVEL_DEADBAND_PCT),
    })
}

/// `valve` with a noise-free sensor of the same calibration (a sensor's noise and lattice do
/// not act back on the valve, so this copy follows the stem exactly).
pub fn noise_free(valve: &ModelSpec) -> ModelSpec {
    let mut clean = valve.clone();
    if let Some(p) = clean.physical.as_mut() {
        p.sensor_noise_pct = 0.0;
        p.sensor_resolution_pct = 0.0;
    }
    clean.effects.quantization_pct = 0.0;
    clean
}

/// The nominal healthy twin of `valve`: the same valve with what compensation answers put
/// right, read by a noise-free sensor. A physical valve gets a healthy valve's friction,
/// deadband and calibration (`config/models/physical.toml`), keeping its positioner, chamber,
/// dead time and travel; a pin-cart II valve loses its crossing time; the effects of a
/// composed valve lose their friction band, deadband, stick-slip and calibration.
pub fn nominal(valve: &ModelSpec) -> ModelSpec {
    let mut twin = noise_free(valve);
    if let (Some(p), Some(h)) = (twin.physical.as_mut(), physical::healthy().physical) {
        p.coulomb_band_pct = h.coulomb_band_pct;
        p.static_band_pct = h.static_band_pct;
        p.deadband_pct = h.deadband_pct;
        p.sensor_gain = h.sensor_gain;
        p.sensor_offset_pct = h.sensor_offset_pct;
    }
    if twin.model == ModelKind::Pincart2 {
        if let Some(p) = twin.pincart2.as_mut() {
            (p.a_p, p.b_p, p.c_p) = (0.0, 0.0, 0.0);
        }
    }
    let e = &mut twin.effects;
    e.friction_band_pct = 0.0;
    e.deadband_pct = 0.0;
    e.positioner_deadband_pct = 0.0;
    e.stickband_pct = 0.0;
    e.jumpband_pct = 0.0;
    e.breakaway_pct = 0.0;
    e.calibration_gain = 1.0;
    e.calibration_offset_pct = 0.0;
    twin
}

#[cfg(test)]
mod tests {
    use super::*;
    use vb_core::model::bundled;
    use vb_core::model::composed::Effect;

    #[test]
    fn the_twin_keeps_the_valve_and_loses_what_compensation_answers() {
        let worn = physical::with_effect(Effect::Backlash, 2.0);
        let mut want = physical::healthy();
        if let Some(p) = want.physical.as_mut() {
            p.sensor_noise_pct = 0.0;
        }
        assert_eq!(nominal(&worn), want);
        let pc2 = nominal(&bundled(ModelKind::Pincart2));
        let p = pc2.pincart2.unwrap();
        assert_eq!((p.a_p, p.b_p, p.c_p), (0.0, 0.0, 0.0));
        assert_eq!(p.p_gain_per_s, 3.0);
    }

    #[test]
    fn figures_of_a_run() {
        let valve = bundled(ModelKind::Pincart2);
        let run = run(&valve, None, Scenario::LevelLoop, 60.0, 0.01, 1).unwrap();
        assert_eq!(run.op.len(), 6000);
        assert_eq!(run.op, run.sent);
        let f = figures(&run, &valve, 0.01).unwrap();
        // Against itself, a noise-free model tracks with no error at all.
        assert_eq!(f.tracking_pct, 0.0);
        assert!(f.pv_iae.unwrap() > 0.0 && f.raw_pct > 0.0 && f.travel.travel_pct > 0.0);
        let steps = super::run(&valve, None, Scenario::RandomSteps, 60.0, 0.01, 1).unwrap();
        assert_eq!(steps.pv_iae, None);
    }

    #[test]
    fn the_figures_read_the_stem_not_the_sensor_s_noise() {
        // A healthy physical valve is its own twin but for its sensor's noise: the V_P read is
        // noisy, the stem is not, and it tracks the twin exactly.
        let valve = physical::healthy();
        let run = run(&valve, None, Scenario::SmallSteps, 60.0, 0.01, 1).unwrap();
        let f = figures(&run, &nominal(&valve), 0.01).unwrap();
        assert_eq!(f.tracking_pct, 0.0);
        assert!(run
            .vp
            .iter()
            .zip(&run.stem)
            .any(|(v, s)| (v - s).abs() > 0.01));
        assert!(f.travel.travel_pct > 5.0, "{f:?}");
    }
}
