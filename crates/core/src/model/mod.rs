//! Every valve model of the paper, as one discrete-time state machine: [`Valve`].
//!
//! A model is described by a [`ModelSpec`] (a TOML file under `config/models/`, tagged
//! `model = "pincart2"` etc.) and run as a [`Valve`]: `reset`, then `step(O_P) -> V_P` once per
//! sample. Emulation, `sim-device`, simulation and fitting all step this same code. A valve is
//! always the same chain:
//!
//! ```text
//! O_P ──▶ dead time T_d (delay line) ──▶ core dynamics ──▶ travel range clamp ──▶ V_P
//! ```
//!
//! The cores are modelless (V_P = input), FOPDT, the Choudhury stiction model, pin-cart I and
//! pin-cart II. `model = "delayed"` is the delayed modelless model. `model = "physical"` is not
//! one of the paper's models: a first-principles pneumatic valve with positioner, friction,
//! stops and sensor ([`PhysicalParams`]), for emulation and for testing diagnosis against
//! physics it does not share; its sensor reading is reported unclamped. Nothing here does I/O
//! beyond [`ModelSpec::load`]; stepping never allocates. [`composed`] writes any model as
//! pin-cart II plus named effects ([`composed::Effect`]), the valve diagnosis grows.

mod chain;
mod checks;
pub mod composed;
mod delay;
pub mod drift;
mod effects;
mod fopdt;
mod physical;
mod pincart;
mod stiction;

use std::path::Path;

use serde::{Deserialize, Serialize};

pub use delay::DelayLine;
pub use drift::{Drift, DriftSpec};
pub use effects::Effects;
pub use fopdt::FopdtParams;
pub use physical::PhysicalParams;
pub use pincart::{crossing_poly, slower_at, PinCart1Params, PinCart2Params, PinReach};
pub use stiction::StictionParams;

use crate::toml_file::{self, TomlError};
use chain::{chain_step, physical_step, run_chain, PassThrough};
use effects::EffectState;
use fopdt::Fopdt;
use physical::Physical;
use pincart::PinCart;
use stiction::Stiction;

/// Default sample period: 10 ms (100 Hz), as in the paper's recordings.
pub const DEFAULT_SAMPLE_PERIOD_S: f64 = 0.01;

/// Which model a [`ModelSpec`] describes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ModelKind {
    /// V_P = O_P.
    Modelless,
    /// V_P = O_P delayed by T_d.
    Delayed,
    /// First order plus dead time, unity gain.
    Fopdt,
    /// Choudhury et al. (2005) stiction model plus dead time.
    Stiction,
    /// Pin-cart I plus dead time.
    Pincart1,
    /// Pin-cart II plus dead time.
    Pincart2,
    /// A first-principles pneumatic valve (positioner, chamber, stem friction, stops, sensor)
    /// plus dead time; a simulator, not one of the paper's identifiable models.
    Physical,
}

impl ModelKind {
    /// The paper's models, in the order of its Table 1: the kinds identification fits.
    pub const ALL: [ModelKind; 6] = [
        ModelKind::Modelless,
        ModelKind::Delayed,
        ModelKind::Fopdt,
        ModelKind::Stiction,
        ModelKind::Pincart1,
        ModelKind::Pincart2,
    ];

    /// Every kind: the paper's models, then the physical simulator.
    pub const EVERY: [ModelKind; 7] = [
        ModelKind::Modelless,
        ModelKind::Delayed,
        ModelKind::Fopdt,
        ModelKind::Stiction,
        ModelKind::Pincart1,
        ModelKind::Pincart2,
        ModelKind::Physical,
    ];

    /// Whether identification can fit this kind (every kind of the paper; not `physical`).
    pub fn is_identifiable(self) -> bool {
        self != ModelKind::Physical
    }

    /// The tag used in model files (`model = "..."`).
    pub fn tag(self) -> &'static str {
        match self {
            ModelKind::Modelless => "modelless",
            ModelKind::Delayed => "delayed",
            ModelKind::Fopdt => "fopdt",
            ModelKind::Stiction => "stiction",
            ModelKind::Pincart1 => "pincart1",
            ModelKind::Pincart2 => "pincart2",
            ModelKind::Physical => "physical",
        }
    }

    /// The name used in the paper's tables.
    pub fn display_name(self) -> &'static str {
        match self {
            ModelKind::Modelless => "Modelless",
            ModelKind::Delayed => "Delayed modelless",
            ModelKind::Fopdt => "FOPDT",
            ModelKind::Stiction => "Stiction",
            ModelKind::Pincart1 => "Pin-cart I",
            ModelKind::Pincart2 => "Pin-cart II",
            ModelKind::Physical => "Physical",
        }
    }
}

impl std::fmt::Display for ModelKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.tag())
    }
}

impl std::str::FromStr for ModelKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        ModelKind::EVERY
            .into_iter()
            .find(|k| k.tag() == s)
            .ok_or_else(|| {
                let all: Vec<&str> = ModelKind::EVERY.iter().map(|k| k.tag()).collect();
                format!("unknown model `{s}`: expected one of {}", all.join(", "))
            })
    }
}

/// The valve's travel range in percent; V_P is clamped to it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Travel {
    /// Lowest position, % (default 0).
    #[serde(default)]
    pub min_pct: f64,
    /// Highest position, % (default 100).
    #[serde(default = "hundred")]
    pub max_pct: f64,
}

fn hundred() -> f64 {
    100.0
}

impl Default for Travel {
    fn default() -> Self {
        Travel {
            min_pct: 0.0,
            max_pct: 100.0,
        }
    }
}

/// A model and its parameters in physical units, as stored in a model TOML file.
///
/// ```toml
/// model = "pincart2"
/// dead_time_s = 0.3
/// [pincart2]
/// p_gain_per_s = 2.5
/// # ...
/// ```
/// Exactly the table named by `model` must be present (none for `modelless` and `delayed`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelSpec {
    /// Which model this is.
    pub model: ModelKind,
    /// Dead time T_d in seconds (>= 0); must be 0 for `modelless`.
    #[serde(default)]
    pub dead_time_s: f64,
    /// The stroke speed (`dy_max_pct_per_s`, and a closing one) is not determined: no move of
    /// the log the model was identified from asked the valve for it, so any limit above what
    /// they asked fits alike. Simulations step the number written; a compensator does not use
    /// it. Written only when true.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub stroke_speed_undetermined: bool,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fopdt: Option<FopdtParams>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stiction: Option<StictionParams>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pincart1: Option<PinCart1Params>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pincart2: Option<PinCart2Params>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub physical: Option<PhysicalParams>,
    /// Travel range (default 0-100 %).
    #[serde(default)]
    pub travel: Travel,
    /// Extra physics around the core (all off by default).
    #[serde(default, skip_serializing_if = "Effects::is_none")]
    pub effects: Effects,
}

/// A model that cannot be built: bad file, missing table or a parameter out of range.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    /// The model file could not be read or parsed, or a value is out of range.
    #[error(transparent)]
    File(#[from] TomlError),
    /// A parameter is out of its allowed range (model built in memory).
    #[error("model `{model}`: {key} = {value}: {allowed}")]
    Param {
        model: ModelKind,
        key: String,
        value: f64,
        allowed: String,
    },
    /// The sample period is not a positive number.
    #[error("sample period {0} s: must be a positive number of seconds")]
    SamplePeriod(f64),
    /// The dead time spans more samples than a delay line holds.
    #[error("dead time {} s at a sample period of {} s needs a delay line of {} samples; at most {} fit (a sample period this short is not a recording's)", crate::human::num(*dead_time_s), crate::human::num(*sample_period_s), crate::human::num(*samples), crate::human::num(MAX_DELAY_SAMPLES))]
    DelayTooLong {
        /// T_d, s.
        dead_time_s: f64,
        /// The sample period, s.
        sample_period_s: f64,
        /// Samples the line would need.
        samples: f64,
    },
}

/// Most samples a dead-time delay line holds (80 MB): 10 s of dead time at 1 µs.
pub const MAX_DELAY_SAMPLES: f64 = 1e7;

impl ModelSpec {
    /// A spec of `kind` with no parameter tables yet (fill the one for the kind).
    pub fn bare(kind: ModelKind, dead_time_s: f64) -> Self {
        ModelSpec {
            model: kind,
            dead_time_s,
            stroke_speed_undetermined: false,
            fopdt: None,
            stiction: None,
            pincart1: None,
            pincart2: None,
            physical: None,
            travel: Travel::default(),
            effects: Effects::default(),
        }
    }

    /// Loads and checks a model file; errors name the file, line and key.
    pub fn load(path: &Path) -> Result<Self, ModelError> {
        let (spec, text): (ModelSpec, String) = toml_file::load(path)?;
        spec.check_in(&text, path)?;
        Ok(spec)
    }

    /// Parses and checks a model from TOML text (`label` names it in errors).
    pub fn from_toml(text: &str, label: &Path) -> Result<Self, ModelError> {
        let spec: ModelSpec = toml_file::parse(text, label)?;
        spec.check_in(text, label)?;
        Ok(spec)
    }

    /// The spec as TOML text, loadable by [`ModelSpec::load`].
    pub fn to_toml(&self) -> String {
        // A ModelSpec holds only numbers, enums and tables, which TOML represents once the
        // checks hold (a seed fits a TOML integer); an unchecked one is said to be so.
        toml::to_string_pretty(self)
            .unwrap_or_else(|e| format!("# not representable in TOML: {e}\n"))
    }

    /// Checks every parameter against its allowed range.
    pub fn validate(&self) -> Result<(), ModelError> {
        match self.violations().into_iter().next() {
            None => Ok(()),
            Some(v) => Err(ModelError::Param {
                model: self.model,
                key: match v.table {
                    Some(t) => format!("{t}.{}", v.key),
                    None => v.key.to_string(),
                },
                value: v.value,
                allowed: v.allowed,
            }),
        }
    }

    fn check_in(&self, text: &str, path: &Path) -> Result<(), ModelError> {
        match self.violations().into_iter().next() {
            None => Ok(()),
            Some(v) => Err(toml_file::invalid(
                toml_file::Layout::parse(text).lines(),
                path,
                v.table,
                v.key,
                if v.value.is_nan() {
                    v.allowed
                } else {
                    format!("{} is not allowed: {}", v.value, v.allowed)
                },
            )
            .into()),
        }
    }
}

/// The dynamics between the delay line and the travel clamp.
#[derive(Debug, Clone)]
enum Core {
    PassThrough,
    Fopdt(Fopdt),
    Stiction(Stiction),
    PinCart(PinCart),
    /// Boxed: its noise generator is large, and the other cores stay small.
    Physical(Box<Physical>),
}

/// A runnable valve model: `reset`, then `step(O_P) -> V_P` once per sample.
///
/// ```
/// use vb_core::model::{bundled, ModelKind, Valve};
///
/// // The paper's pin-cart II valve with its bundled parameters, stepped at 100 Hz.
/// let mut valve = Valve::new(&bundled(ModelKind::Pincart2), 0.01)?;
/// valve.reset(40.0, 40.0);
/// let vp: Vec<f64> = (0..1000).map(|_| valve.step(60.0)).collect();
/// assert!(vp[999] > 50.0 && vp[999] <= 60.5, "V_P follows the O_P step: {}", vp[999]);
/// # Ok::<(), vb_core::model::ModelError>(())
/// ```
#[derive(Debug, Clone)]
pub struct Valve {
    spec: ModelSpec,
    sample_period_s: f64,
    delay: DelayLine,
    core: Core,
    effects: EffectState,
}

impl Valve {
    /// Builds the valve of `spec` stepping every `sample_period_s` seconds, at rest at 0 %.
    pub fn new(spec: &ModelSpec, sample_period_s: f64) -> Result<Self, ModelError> {
        if !(sample_period_s.is_finite() && sample_period_s > 0.0) {
            return Err(ModelError::SamplePeriod(sample_period_s));
        }
        spec.validate()?;
        let dt = sample_period_s;
        let samples = spec.dead_time_s.max(0.0) / dt;
        if samples > MAX_DELAY_SAMPLES {
            return Err(ModelError::DelayTooLong {
                dead_time_s: spec.dead_time_s,
                sample_period_s: dt,
                samples,
            });
        }
        let missing = || ModelError::Param {
            model: spec.model,
            key: spec.model.tag().into(),
            value: f64::NAN,
            allowed: "the model's parameter table is missing".into(),
        };
        let core = match spec.model {
            ModelKind::Modelless | ModelKind::Delayed => Core::PassThrough,
            ModelKind::Fopdt => {
                Core::Fopdt(Fopdt::new(spec.fopdt.as_ref().ok_or_else(missing)?, dt))
            }
            ModelKind::Stiction => {
                Core::Stiction(Stiction::new(spec.stiction.as_ref().ok_or_else(missing)?))
            }
            ModelKind::Pincart1 => Core::PinCart(PinCart::one(
                spec.pincart1.as_ref().ok_or_else(missing)?,
                dt,
            )),
            ModelKind::Pincart2 => Core::PinCart(PinCart::two(
                spec.pincart2.as_ref().ok_or_else(missing)?,
                &spec.effects,
                dt,
            )),
            ModelKind::Physical => Core::Physical(Box::new(Physical::new(
                spec.physical.as_ref().ok_or_else(missing)?,
                &spec.travel,
                dt,
            ))),
        };
        let mut valve = Valve {
            spec: spec.clone(),
            sample_period_s,
            delay: DelayLine::new(spec.dead_time_s, dt),
            core,
            effects: EffectState::new(&spec.effects),
        };
        valve.reset(0.0, 0.0);
        Ok(valve)
    }

    /// The spec this valve was built from.
    pub fn spec(&self) -> &ModelSpec {
        &self.spec
    }

    /// The sample period in seconds.
    pub fn sample_period_s(&self) -> f64 {
        self.sample_period_s
    }

    /// Puts the valve at rest: position `vp0`, and O_P having been `op0` for ever. (A physical
    /// valve starts where its sensor would read `vp0`.)
    pub fn reset(&mut self, op0: f64, vp0: f64) {
        let reported = vp0;
        let vp0 = vp0.clamp(self.spec.travel.min_pct, self.spec.travel.max_pct);
        self.delay.reset(op0);
        self.effects.reset(op0, vp0);
        match &mut self.core {
            Core::PassThrough => {}
            Core::Fopdt(c) => c.reset(vp0),
            Core::Stiction(c) => c.reset(op0, vp0),
            Core::PinCart(c) => c.reset(vp0),
            Core::Physical(c) => c.reset(reported),
        }
    }

    /// Advances one sample with wanted opening `op` (%) and returns the valve position V_P (%).
    // Always inlined: loops that step one sample at a time (the emulator, a compensator) keep
    // the valve's state close; a loop over a slice known in advance is [`Valve::run`].
    #[inline(always)]
    pub fn step(&mut self, op: f64) -> f64 {
        let travel = self.spec.travel;
        let (delay, effects) = (&mut self.delay, &mut self.effects);
        match &mut self.core {
            Core::PassThrough => chain_step(delay, effects, &mut PassThrough, travel, op),
            Core::Fopdt(c) => chain_step(delay, effects, c, travel, op),
            Core::Stiction(c) => chain_step(delay, effects, c, travel, op),
            Core::PinCart(c) => chain_step(delay, effects, c, travel, op),
            Core::Physical(c) => physical_step(delay, effects, c, op),
        }
    }

    /// Steps the valve once per sample of `op`, in order, handing each V_P to `each`: the
    /// same as calling [`Valve::step`] on every sample, with the choice of core made once for
    /// the whole slice, so that the loop keeps the core's state in registers (fits spend
    /// nearly all their time here).
    #[inline]
    pub fn run(&mut self, op: &[f64], mut each: impl FnMut(f64)) {
        let travel = self.spec.travel;
        let (delay, effects) = (&mut self.delay, &mut self.effects);
        match &mut self.core {
            Core::PassThrough => run_chain(delay, effects, &mut PassThrough, travel, op, each),
            Core::Fopdt(c) => run_chain(delay, effects, c, travel, op, each),
            Core::Stiction(c) => run_chain(delay, effects, c, travel, op, each),
            Core::PinCart(c) => run_chain(delay, effects, c, travel, op, each),
            Core::Physical(c) => op
                .iter()
                .for_each(|&u| each(physical_step(delay, effects, c, u))),
        }
    }

    /// Widens a pin-cart model's cart, its friction band, by `extra_pct` % of travel over the
    /// model's (see [`drift`]); other models have no band and are left alone.
    #[inline]
    pub fn widen_band(&mut self, extra_pct: f64) {
        if let Core::PinCart(c) = &mut self.core {
            c.widen(extra_pct);
        }
    }

    /// For a pin-cart core: where the cart is and how far the pin is from pushing it towards
    /// `dir` (+1 opening, -1 closing); None for the other cores. A compensator reads it to know
    /// whether a reversal still has a band to cross.
    pub fn pin_reach(&self, dir: f64) -> Option<PinReach> {
        match &self.core {
            Core::PinCart(c) => Some(c.reach(dir)),
            _ => None,
        }
    }

    /// The pin's speed for an error `e` at the core (pin-cart II with a friction band), %/s,
    /// pushing or crossing the band; None where no error changes it.
    pub fn pin_speed(&self, e: f64) -> Option<f64> {
        match &self.core {
            Core::PinCart(c) => c.pin_speed(e),
            _ => None,
        }
    }

    /// The deadband's target: the input the core is driven with once calibration and deadband
    /// have acted, % (kept only while the model has either).
    pub fn input_target(&self) -> f64 {
        self.effects.target()
    }

    /// Runs the whole O_P sequence from rest at (`op[0]`, `vp0`), writing V_P into `out`.
    ///
    /// `out[k]` is the position after the input `op[k]` has been applied for one sample.
    /// `out` must be as long as `op`; extra entries are left alone.
    pub fn simulate_into(&mut self, op: &[f64], vp0: f64, out: &mut [f64]) {
        self.reset(op.first().copied().unwrap_or(vp0), vp0);
        let n = op.len().min(out.len());
        let mut slots = out.iter_mut();
        self.run(&op[..n], |v| {
            if let Some(o) = slots.next() {
                *o = v;
            }
        });
    }

    /// Like [`Valve::simulate_into`] but returns a new vector.
    pub fn simulate(&mut self, op: &[f64], vp0: f64) -> Vec<f64> {
        let mut out = vec![0.0; op.len()];
        self.simulate_into(op, vp0, &mut out);
        out
    }
}

/// The model files shipped in `config/models/`, embedded so the binary runs with no files.
const BUNDLED: [(ModelKind, &str); 7] = [
    (
        ModelKind::Modelless,
        include_str!("../../../../config/models/modelless.toml"),
    ),
    (
        ModelKind::Delayed,
        include_str!("../../../../config/models/delayed.toml"),
    ),
    (
        ModelKind::Fopdt,
        include_str!("../../../../config/models/fopdt.toml"),
    ),
    (
        ModelKind::Stiction,
        include_str!("../../../../config/models/stiction.toml"),
    ),
    (
        ModelKind::Pincart1,
        include_str!("../../../../config/models/pincart1.toml"),
    ),
    (
        ModelKind::Pincart2,
        include_str!("../../../../config/models/pincart2.toml"),
    ),
    (
        ModelKind::Physical,
        include_str!("../../../../config/models/physical.toml"),
    ),
];

/// The default parameters of `kind`, as shipped in `config/models/<kind>.toml`.
pub fn bundled(kind: ModelKind) -> ModelSpec {
    let text = BUNDLED
        .iter()
        .find(|(k, _)| *k == kind)
        .map(|(_, t)| *t)
        .unwrap_or_default();
    let label = format!("config/models/{}.toml", kind.tag());
    // The bundled files are checked by the unit tests; a broken one is a build defect.
    ModelSpec::from_toml(text, Path::new(&label))
        .unwrap_or_else(|e| panic!("bundled model file is invalid: {e}"))
}

#[cfg(test)]
mod tests;
