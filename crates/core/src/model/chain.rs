//! The chain every valve steps, one sample at a time: dead time, the effects on the input, the
//! core, the travel clamp and the sensor (see [`super::Valve`]). [`super::Valve::step`] and
//! [`super::Valve::run`] both step it; `run` chooses the core once for a whole slice.

use super::effects::EffectState;
use super::fopdt::Fopdt;
use super::physical::Physical;
use super::pincart::PinCart;
use super::stiction::Stiction;
use super::{DelayLine, Travel};

/// A core between the delay line (and the input effects) and the travel clamp, stepped by
/// [`chain_step`]; every core but the physical valve, whose stops act inside it.
pub(super) trait ClampedCore: Clone {
    /// Advances one sample with input `u`, returning the unclamped position, %.
    fn step(&mut self, u: f64) -> f64;
    /// Overrides the position after the travel range clamped it.
    fn set_position(&mut self, v: f64);
}

/// The modelless core: V_P is its input.
#[derive(Debug, Clone, Copy)]
pub(super) struct PassThrough;

impl ClampedCore for PassThrough {
    #[inline(always)]
    fn step(&mut self, u: f64) -> f64 {
        u
    }
    #[inline(always)]
    fn set_position(&mut self, _: f64) {}
}

/// The cores that step and set themselves: each trait method is the core's own.
macro_rules! own_core {
    ($($core:ty),*) => {$(
        impl ClampedCore for $core {
            #[inline(always)]
            fn step(&mut self, u: f64) -> f64 {
                <$core>::step(self, u)
            }
            #[inline(always)]
            fn set_position(&mut self, v: f64) {
                <$core>::set_position(self, v)
            }
        }
    )*};
}

own_core!(Fopdt, Stiction, PinCart);

/// One sample of the chain: dead time, input effects, `core`, travel clamp, sensor.
#[inline(always)]
pub(super) fn chain_step<C: ClampedCore>(
    delay: &mut DelayLine,
    effects: &mut EffectState,
    core: &mut C,
    travel: Travel,
    op: f64,
) -> f64 {
    let u = effects.input(delay.push(op));
    let v = core.step(u);
    let (lo, hi) = (travel.min_pct, travel.max_pct);
    if v >= lo && v <= hi {
        return effects.output(v);
    }
    let clamped = v.clamp(lo, hi);
    core.set_position(clamped);
    effects.output(clamped)
}

/// One sample of the physical valve: its stops act on the stem, and its sensor reading is
/// reported as it is (no travel clamp).
#[inline(always)]
pub(super) fn physical_step(
    delay: &mut DelayLine,
    effects: &mut EffectState,
    core: &mut Physical,
    op: f64,
) -> f64 {
    core.step(effects.input(delay.push(op)))
}

/// [`chain_step`] over every sample of `op`, on copies of the core and the effects that the
/// compiler can keep in registers (they hold no heap memory, so copying allocates nothing),
/// written back at the end.
#[inline(always)]
pub(super) fn run_chain<C: ClampedCore>(
    delay: &mut DelayLine,
    effects: &mut EffectState,
    core: &mut C,
    travel: Travel,
    op: &[f64],
    mut each: impl FnMut(f64),
) {
    let (mut c, mut fx) = (core.clone(), effects.clone());
    for &u in op {
        each(chain_step(delay, &mut fx, &mut c, travel, u));
    }
    *core = c;
    *effects = fx;
}
