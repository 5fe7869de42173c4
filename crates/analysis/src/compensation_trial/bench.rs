//! The compensation bench's valves in process: each valve's model identified from its own
//! 15-minute log as a user would (`diagnose` on the mixed excitation for physical valves,
//! `identify` on the paper's random steps for pin-cart II and once more for the 1.5 % valve),
//! the compensator of that model, and the table of the valve's trials without and with it.
//! `cargo bench --bench compensation` prints them, and docs/compensation.md quotes them (a
//! generated block its test checks).
//!
//! Not here: the trials themselves ([`super::run`], [`super::figures`]), the bench's Modbus
//! part and its plots (`benches/compensation.rs`).

use super::{figures, nominal, run, Figures, Run, Scenario};
use crate::diagnose::{self, DiagnoseError, Effect};
use crate::fit::{self, FitError, Options};
use crate::synth::{self, physical, Excitation, SynthError};
use vb_core::compensate::{CompensateError, CompensationConfig, Compensator};
use vb_core::model::{bundled, ModelError, ModelKind, ModelSpec};

/// Sample time of the logs and runs, s.
pub const DT: f64 = 0.01;
/// Length of each valve's identification log, s.
pub const LOG_S: f64 = 900.0;
/// Length of each scenario run, s.
pub const RUN_S: f64 = 600.0;
/// Seed of the identification logs (the runs use 1..=seeds).
const LOG_SEED: u64 = 1000;

/// What went wrong making a bench valve or its trials (the causes boxed: a result stays small).
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    #[error("compensation bench, {valve}: its log: {source}")]
    Log {
        valve: String,
        source: Box<SynthError>,
    },
    #[error("compensation bench, {valve}: identify: {source}")]
    Identify {
        valve: String,
        source: Box<FitError>,
    },
    #[error("compensation bench, {valve}: identify gave no pin-cart II model")]
    NoPincart { valve: String },
    #[error("compensation bench, {valve}: diagnose: {source}")]
    Diagnose {
        valve: String,
        source: Box<DiagnoseError>,
    },
    #[error("compensation bench, {valve}: its compensator: {source}")]
    Compensator {
        valve: String,
        source: Box<CompensateError>,
    },
    #[error("compensation bench, {valve}: a trial: {source}")]
    Trial {
        valve: String,
        source: Box<ModelError>,
    },
}

/// A valve of the bench and the compensator of the model identified from its own log.
#[derive(Debug, Clone)]
pub struct BenchValve {
    pub name: String,
    pub valve: ModelSpec,
    pub compensator: Compensator,
}

/// How a bench valve's model is found from its log.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ModelledBy {
    /// `diagnose` on the mixed excitation (small steps, then random steps).
    Diagnose,
    /// `identify`'s pin-cart II on the paper's random steps.
    Identify,
}

/// One valve of the bench: its name, the valve itself and how its model is found.
#[derive(Debug, Clone)]
pub struct LineupValve {
    pub name: String,
    pub valve: ModelSpec,
    pub by: ModelledBy,
}

/// The bench's valves: pin-cart II, the physical valve healthy, with 1, 1.5 and 3 % friction
/// bands and a 0.6 % deadband (modelled by `diagnose`), and the 1.5 % valve once more
/// (modelled by `identify`, as pin-cart II is).
pub fn lineup() -> Vec<LineupValve> {
    let entry = |name: &str, valve, by| LineupValve {
        name: name.to_string(),
        valve,
        by,
    };
    let mut valves = vec![
        entry(
            "pin-cart II",
            bundled(ModelKind::Pincart2),
            ModelledBy::Identify,
        ),
        entry(
            "physical, healthy",
            physical::healthy(),
            ModelledBy::Diagnose,
        ),
    ];
    for band in [1.0, 1.5, 3.0] {
        valves.push(entry(
            &format!("physical, {band} % band"),
            physical::with_effect(Effect::Backlash, band),
            ModelledBy::Diagnose,
        ));
    }
    valves.push(entry(
        "physical, 0.6 % deadband",
        physical::with_effect(Effect::Deadband, 0.6),
        ModelledBy::Diagnose,
    ));
    valves.push(entry(
        "physical, 1.5 % band, identify's pin-cart II",
        physical::with_effect(Effect::Backlash, 1.5),
        ModelledBy::Identify,
    ));
    valves
}

/// A valve of [`lineup`] with the compensator (default settings but `kick_share`) of the
/// model found from its own log.
pub fn bench_valve(entry: LineupValve, kick_share: f64) -> Result<BenchValve, BenchError> {
    let LineupValve { name, valve, by } = entry;
    let excitation = match by {
        ModelledBy::Diagnose => Excitation::Mixed { low_pct: 40.0 },
        ModelledBy::Identify => Excitation::RandomSteps,
    };
    let named = || name.clone();
    let rec = synth::generate(&valve, excitation, LOG_S, DT, 0.0, LOG_SEED).map_err(|source| {
        BenchError::Log {
            valve: named(),
            source: Box::new(source),
        }
    })?;
    let model = if by == ModelledBy::Diagnose {
        diagnose::diagnose(&rec.view(), None, &|_, _| {})
            .map_err(|source| BenchError::Diagnose {
                valve: named(),
                source: Box::new(source),
            })?
            .final_model
            .spec
    } else {
        let options = Options::for_models(&[ModelKind::Pincart2]);
        let id = fit::identify(&rec.view(), &options, &|_, _| {}).map_err(|source| {
            BenchError::Identify {
                valve: named(),
                source: Box::new(source),
            }
        })?;
        (id.rows.into_iter())
            .find(|r| r.kind == ModelKind::Pincart2)
            .ok_or_else(|| BenchError::NoPincart { valve: named() })?
            .spec
    };
    let cfg = CompensationConfig {
        model_file: Some("model.toml".into()),
        kick_share,
        ..CompensationConfig::default()
    };
    let compensator = Compensator::new(&cfg, &model, DT, (0.0, 100.0)).map_err(|source| {
        BenchError::Compensator {
            valve: named(),
            source: Box::new(source),
        }
    })?;
    Ok(BenchValve {
        name,
        valve,
        compensator,
    })
}

/// The list of the models found and what each compensates, one line per valve.
pub fn models(valves: &[BenchValve]) -> String {
    let mut lines = vec![
        "Models identified from each valve's own 15-minute log, and what they compensate:"
            .to_string(),
    ];
    lines.extend((valves.iter()).map(|b| format!("- {}: {}", b.name, b.compensator.describe())));
    lines.join("\n")
}

/// The table of every valve in every scenario of [`Scenario::ALL`], without and with
/// compensation, over the seeds 1..=`seeds`: each cell the mean over the seeds, then the mean
/// of the per-seed changes and their range.
pub fn table(valves: &[BenchValve], seeds: u64) -> Result<String, BenchError> {
    let mut lines = vec![
        "| valve | scenario | level IAE, %·s | tracking error, % RMS | O_P - V_P, % RMS | travel, % | reversals | added, % RMS | compensation |".to_string(),
        "|---|---|---|---|---|---|---|---|---|".to_string(),
    ];
    for b in valves {
        for scenario in Scenario::ALL {
            let results = trials(b, scenario, seeds).map_err(|source| BenchError::Trial {
                valve: b.name.clone(),
                source: Box::new(source),
            })?;
            lines.push(row(b, scenario, &results));
        }
    }
    Ok(lines.join("\n"))
}

/// Without and with compensation, per seed.
fn trials(
    b: &BenchValve,
    scenario: Scenario,
    seeds: u64,
) -> Result<Vec<(Figures, Figures, Run)>, ModelError> {
    let nominal = nominal(&b.valve);
    (1..=seeds)
        .map(|seed| {
            let plain = run(&b.valve, None, scenario, RUN_S, DT, seed)?;
            let comped = run(
                &b.valve,
                Some(b.compensator.clone()),
                scenario,
                RUN_S,
                DT,
                seed,
            )?;
            Ok((
                figures(&plain, &nominal, DT)?,
                figures(&comped, &nominal, DT)?,
                comped,
            ))
        })
        .collect()
}

fn mean(x: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = x.fold((0.0, 0), |(s, n), v| (s + v, n + 1));
    s / f64::from(n.max(1))
}

/// `a → b (±c %)`, the change as the mean of the per-seed changes and their range.
fn change(pairs: &[(f64, f64)], decimals: usize) -> String {
    let a = mean(pairs.iter().map(|p| p.0));
    let b = mean(pairs.iter().map(|p| p.1));
    let ch: Vec<f64> = pairs
        .iter()
        .map(|(x, y)| if *x > 0.0 { 100.0 * (y / x - 1.0) } else { 0.0 })
        .collect();
    let lo = ch.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = ch.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    format!(
        "{a:.decimals$} → {b:.decimals$} ({:+.0} %, {lo:+.0}..{hi:+.0})",
        mean(ch.iter().copied())
    )
}

fn row(b: &BenchValve, scenario: Scenario, results: &[(Figures, Figures, Run)]) -> String {
    let pick = |f: &dyn Fn(&Figures) -> f64| -> Vec<(f64, f64)> {
        results.iter().map(|(a, c, _)| (f(a), f(c))).collect()
    };
    let iae = if scenario == Scenario::LevelLoop {
        change(&pick(&|f| f.pv_iae.unwrap_or(0.0)), 0)
    } else {
        "—".into()
    };
    let offs = results
        .iter()
        .filter_map(|r| r.2.switched_off_s)
        .map(|t| format!("{t:.0} s"))
        .collect::<Vec<_>>();
    let added = mean(results.iter().map(|r| {
        let run = &r.2;
        let sq: f64 = run
            .sent
            .iter()
            .zip(&run.op)
            .map(|(s, o)| (s - o).powi(2))
            .sum();
        (sq / run.op.len().max(1) as f64).sqrt()
    }));
    format!(
        "| {} | {} | {iae} | {} | {} | {} | {} | {added:.3} | {} |",
        b.name,
        scenario.name(),
        change(&pick(&|f| f.tracking_pct), 3),
        change(&pick(&|f| f.raw_pct), 3),
        change(&pick(&|f| f.travel.travel_pct), 0),
        change(&pick(&|f| f.travel.reversals as f64), 0),
        if offs.is_empty() {
            "on".into()
        } else {
            format!("off at {}", offs.join(", "))
        },
    )
}
