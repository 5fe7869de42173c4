//! The valves sim-device plays: one per unit id (RTU slave address), each with its own model,
//! noise and wear, its own register bank and its own stepping task.
//!
//! `--unit ID` serves one valve of `--model` at that address; `--unit ID=MODEL[,KEY=VALUE...]`
//! gives the unit its own model (a bundled name or a model file) and settings, with the keys
//! `noise_pct` and the drift keys of [`DriftSpec`] (`dead_time_drift_s_per_h`,
//! `dead_time_drift_max_s`, `friction_band_drift_pct_per_h`, `friction_band_drift_max_pct`);
//! what a unit does not set comes from the options of the same names. `--unit` may be repeated:
//! several valves on one bus (or behind one TCP address, told apart by the MBAP unit id).
//!
//! Each valve is stepped at 100 Hz in real time from its bank's set-point through the same
//! [`Drift`] as the daemon's emulated valve, with time counted in model steps from the start.
//! Not here: serving (the banks are answered by [`crate::rtu`] and [`crate::tcp`]).

use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use anyhow::{bail, Context as _};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use vb_core::model::{self, Drift, DriftSpec, ModelKind, ModelSpec, Valve};
use vb_modbus::map::{RegisterMap, Table};
use vb_modbus::profile::Profile;
use vb_modbus::server::{OutOfRange, RegisterBank};

/// The model's step, 10 ms (100 Hz).
pub(crate) const MODEL_DT: f64 = model::DEFAULT_SAMPLE_PERIOD_S;

/// One `--unit` argument: the address, and what it sets of its own.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct UnitArg {
    /// Slave address / unit id, 1-247.
    pub id: u8,
    /// Its model, when it has its own.
    pub model: Option<String>,
    /// Its own settings, `KEY=VALUE`.
    pub settings: Vec<(String, f64)>,
}

/// Parses `ID` or `ID=MODEL[,KEY=VALUE...]`.
pub(crate) fn parse_unit(s: &str) -> Result<UnitArg, String> {
    let (id, rest) = match s.split_once('=') {
        Some((id, rest)) => (id, Some(rest)),
        None => (s, None),
    };
    let id: u8 = match id.trim().parse() {
        Ok(n) if (1..=247).contains(&n) => n,
        _ => {
            return Err(format!(
                "`{id}`: a unit id is 1-247 (write ID or ID=MODEL[,KEY=VALUE...])"
            ))
        }
    };
    let Some(rest) = rest else {
        return Ok(UnitArg {
            id,
            model: None,
            settings: Vec::new(),
        });
    };
    let mut parts = rest.split(',');
    let model = parts
        .next()
        .map(str::trim)
        .filter(|m| !m.is_empty())
        .map(String::from);
    let mut settings = Vec::new();
    for part in parts {
        let Some((key, value)) = part.split_once('=') else {
            return Err(format!(
                "`{part}`: a unit's setting is KEY=VALUE, e.g. friction_band_drift_pct_per_h=2"
            ));
        };
        let key = key.trim();
        if !KEYS.contains(&key) {
            return Err(format!(
                "`{key}`: unknown unit setting (one of {})",
                KEYS.join(", ")
            ));
        }
        let value: f64 = value
            .trim()
            .parse()
            .map_err(|_| format!("{key}=`{value}`: not a number"))?;
        settings.push((key.to_string(), value));
    }
    Ok(UnitArg {
        id,
        model,
        settings,
    })
}

/// The settings a unit may have of its own.
const KEYS: [&str; 5] = [
    "noise_pct",
    "dead_time_drift_s_per_h",
    "dead_time_drift_max_s",
    "friction_band_drift_pct_per_h",
    "friction_band_drift_max_pct",
];

/// The registers every unit serves: a map, and (from a device profile) further registers, read
/// as 0, and the only function codes answered (empty: all).
#[derive(Debug, Clone, Default)]
pub(crate) struct Served {
    pub map: RegisterMap,
    pub others: Vec<(Table, u16)>,
    pub functions: Vec<u8>,
}

impl Served {
    /// Just `map`.
    pub(crate) fn map(map: RegisterMap) -> Served {
        Served {
            map,
            ..Served::default()
        }
    }

    /// `map` (the profile's, or a config's over it) with `profile`'s registers and functions.
    pub(crate) fn profile(map: RegisterMap, profile: &Profile) -> Served {
        Served {
            map,
            others: (profile.others.iter())
                .map(|o| (o.table, o.address))
                .collect(),
            functions: profile.about.functions.clone(),
        }
    }
}

/// What every unit gets unless it says otherwise (the command line's options).
#[derive(Debug, Clone)]
pub(crate) struct Defaults {
    pub model: String,
    pub noise_pct: f64,
    pub drift: DriftSpec,
    pub seed: u64,
}

/// A unit ready to serve: its address and registers, and its valve until it is started.
pub(crate) struct Unit {
    pub id: u8,
    pub bank: Arc<RegisterBank>,
    valve: Valve,
    drift: Option<Drift>,
    noise: Option<Normal<f64>>,
    seed: u64,
}

impl Unit {
    /// The unit `arg` describes, serving `served`, with `defaults` for what it does not set.
    pub(crate) fn new(arg: &UnitArg, defaults: &Defaults, served: &Served) -> anyhow::Result<Unit> {
        let name = arg.model.as_deref().unwrap_or(&defaults.model);
        let spec = load_model(name).with_context(|| format!("unit {}: model `{name}`", arg.id))?;
        let mut noise_pct = defaults.noise_pct;
        let mut drift = defaults.drift;
        for (key, value) in &arg.settings {
            let slot = match key.as_str() {
                "noise_pct" => &mut noise_pct,
                "dead_time_drift_s_per_h" => &mut drift.dead_time_drift_s_per_h,
                "dead_time_drift_max_s" => &mut drift.dead_time_drift_max_s,
                "friction_band_drift_pct_per_h" => &mut drift.friction_band_drift_pct_per_h,
                _ => &mut drift.friction_band_drift_max_pct,
            };
            *slot = *value;
        }
        if !(noise_pct.is_finite() && noise_pct >= 0.0) {
            bail!(
                "unit {}: noise_pct {noise_pct}: a standard deviation in %, >= 0",
                arg.id
            );
        }
        let valve = Valve::new(&spec, MODEL_DT)?;
        let drift = Drift::new(&drift, &valve).with_context(|| format!("unit {}", arg.id))?;
        Ok(Unit {
            id: arg.id,
            bank: Arc::new(
                RegisterBank::new(served.map, 0.0, 100.0, OutOfRange::KeepAndFlag)
                    .serving(&served.others, &served.functions),
            ),
            noise: (noise_pct > 0.0)
                .then(|| Normal::new(0.0, noise_pct))
                .transpose()?,
            valve,
            drift,
            seed: defaults.seed ^ u64::from(arg.id),
        })
    }

    /// A line for the log.
    pub(crate) fn describe(&self) -> String {
        let worn = if self.drift.is_some() {
            ", drifting"
        } else {
            ""
        };
        format!(
            "unit {}: {} valve{worn}",
            self.id,
            self.valve.spec().model.display_name()
        )
    }

    /// Steps the valve at 100 Hz in real time from the bank's set-point and reports its
    /// position, forever (abort the task to stop).
    pub(crate) async fn step(mut self) {
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        let op0 = self.bank.setpoint_pct();
        self.valve.reset(op0, 0.0);
        if let Some(d) = &mut self.drift {
            d.reset(op0);
        }
        let mut tick = tokio::time::interval(Duration::from_secs_f64(MODEL_DT));
        // Burst: after a stall the model catches up, so it never falls behind the clock.
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Burst);
        for k in 0u64.. {
            tick.tick().await;
            let op = self.bank.setpoint_pct();
            let vp = match &mut self.drift {
                Some(d) => d.step(&mut self.valve, op, k),
                None => self.valve.step(op),
            };
            let n = self.noise.map(|d| d.sample(&mut rng)).unwrap_or(0.0);
            self.bank.set_position_pct(vp + n);
        }
    }
}

/// The banks of the units by address, as the servers look them up.
#[derive(Debug, Clone)]
pub(crate) struct Banks(Vec<(u8, Arc<RegisterBank>)>);

impl Banks {
    /// The banks of `units`.
    pub(crate) fn of(units: &[Unit]) -> Banks {
        Banks(units.iter().map(|u| (u.id, Arc::clone(&u.bank))).collect())
    }

    /// The bank at RTU address `id`, if a unit is there.
    pub(crate) fn at(&self, id: u8) -> Option<&RegisterBank> {
        self.0
            .iter()
            .find(|(i, _)| *i == id)
            .map(|(_, b)| b.as_ref())
    }

    /// Every bank (a broadcast reaches them all).
    pub(crate) fn all(&self) -> impl Iterator<Item = &RegisterBank> {
        self.0.iter().map(|(_, b)| b.as_ref())
    }

    /// The bank for Modbus TCP unit id `id`: with one unit, that unit whatever the id (a
    /// device answering on its own address); with several, the unit of that id.
    pub(crate) fn for_tcp(&self, id: u8) -> Option<&RegisterBank> {
        match self.0.as_slice() {
            [(_, only)] => Some(only.as_ref()),
            _ => self.at(id),
        }
    }
}

/// A bundled model by name, or a model file.
pub(crate) fn load_model(name: &str) -> anyhow::Result<ModelSpec> {
    match name.parse::<ModelKind>() {
        Ok(kind) => Ok(model::bundled(kind)),
        Err(_) => Ok(ModelSpec::load(Path::new(name))?),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unit_arguments() {
        assert_eq!(
            parse_unit("3"),
            Ok(UnitArg {
                id: 3,
                model: None,
                settings: vec![]
            })
        );
        assert_eq!(
            parse_unit("2=physical,friction_band_drift_pct_per_h=2,noise_pct=0.1"),
            Ok(UnitArg {
                id: 2,
                model: Some("physical".into()),
                settings: vec![
                    ("friction_band_drift_pct_per_h".into(), 2.0),
                    ("noise_pct".into(), 0.1)
                ],
            })
        );
        assert!(parse_unit("0=pincart2").unwrap_err().contains("1-247"));
        assert!(parse_unit("1=pincart2,wear=3")
            .unwrap_err()
            .contains("unknown unit setting"));
        assert!(parse_unit("1=pincart2,noise_pct")
            .unwrap_err()
            .contains("KEY=VALUE"));
    }

    #[test]
    fn a_unit_without_a_band_refuses_band_drift() {
        let d = Defaults {
            model: "pincart2".into(),
            noise_pct: 0.0,
            drift: DriftSpec::default(),
            seed: 1,
        };
        let arg = parse_unit("4=fopdt,friction_band_drift_pct_per_h=1").unwrap();
        let served = Served::map(RegisterMap::device_default());
        let e = Unit::new(&arg, &d, &served).err().unwrap();
        assert!(format!("{e:#}").contains("only a pin-cart model"), "{e:#}");
        assert!(Unit::new(
            &parse_unit("4=pincart1,friction_band_drift_pct_per_h=1").unwrap(),
            &d,
            &served
        )
        .is_ok());
    }
}
