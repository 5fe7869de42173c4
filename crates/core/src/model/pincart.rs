//! The pin-cart models of the paper (Bram et al.), eqs. (1)-(7).
//!
//! A pin (the positioner's drive, position `y`) moves inside a cart (the valve stem, position
//! `V_P`) of width `B_L`. The cart only moves while the pin pushes against one of its sides, so
//! a reversal of the pin first costs the time it needs to cross the cart: the apparent backlash.
//!
//! - Pin-cart I: the pin moves at `P_k * e` with `e = O_P - V_P` (eqs. 1-3), at most by `e`
//!   in one sample.
//! - Pin-cart II: while the pin pushes the cart it moves at `sgn(e) * max(P_k |e|, dy_min)`,
//!   saturated at `dy_max` (eqs. 4-6); while it crosses the cart it moves at a speed set by the
//!   opening (eq. 7), which makes the reversal delay depend on the opening. `B_L` is 1 %.
//!
//! Reading of the paper used here (the paper leaves these open):
//! - Speeds are in physical units: `P_k` in 1/s, `dy_max` and `dy_min` in %/s; one sample moves
//!   the pin by the speed times the sample period.
//! - Eq. (7) applies whenever the pin is *not* pushing the cart in the direction of `e` (it is
//!   inside the cart, or leaving the side it last pushed). Eqs. (4)-(5) apply while it pushes.
//! - `a_p V^2 + b_p V + c_p` is the time in seconds the pin needs to cross the whole cart at
//!   opening `V` (in %): the extra delay a reversal costs, Fig. 7's polynomial minus the delay a
//!   same-direction step has. The pin speed of eq. (7) is then `B_L` divided by that time.
//! - While pushing, one sample never carries the cart past O_P: `dy_min` closes small errors at
//!   a constant rate and stops on the target instead of overshooting into a hunting cycle.

use serde::{Deserialize, Serialize};

use super::Effects;

/// Pin-cart I parameters (Table 2: B_L, P_k; dead time lives in the valve).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PinCart1Params {
    /// B_L: cart width (apparent backlash), % of travel (>= 0).
    pub backlash_pct: f64,
    /// P_k: proportional gain of the pin speed, 1/s (> 0).
    pub p_gain_per_s: f64,
}

/// Pin-cart II parameters (Table 2: P_k, dy_max, dy_min, a_p, b_p, c_p; B_L = 1 %).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PinCart2Params {
    /// P_k: proportional gain of the pin speed while pushing, 1/s (> 0).
    pub p_gain_per_s: f64,
    /// dy_max: maximum travel speed (slew rate), %/s (> 0).
    pub dy_max_pct_per_s: f64,
    /// dy_min: minimum pin speed while pushing, %/s (>= 0).
    pub dy_min_pct_per_s: f64,
    /// a_p: cart-crossing time coefficient, s/%^2.
    pub a_p: f64,
    /// b_p: cart-crossing time coefficient, s/%.
    pub b_p: f64,
    /// c_p: cart-crossing time at V_P = 0, s (>= 0; 0 = no apparent backlash).
    pub c_p: f64,
    /// B_L: cart width, % of travel. Fixed at 1 by the paper (redundant with eq. 7).
    #[serde(default = "one")]
    pub backlash_pct: f64,
}

fn one() -> f64 {
    1.0
}

impl PinCart2Params {
    /// Time in seconds the pin needs to cross the cart at opening `v` (eq. 7's polynomial).
    #[inline]
    pub fn crossing_time_s(&self, v: f64) -> f64 {
        (self.a_p * v + self.b_p) * v + self.c_p
    }
}

/// How the pin moves: pin-cart I's proportional law or pin-cart II's eqs. (4)-(7).
#[derive(Debug, Clone, Copy)]
enum PinLaw {
    Proportional {
        k: f64,
    },
    StateDependent {
        p: PinCart2Params,
        /// Slew rate while closing, %/s (equal to `dy_max` unless asymmetric).
        close_max: f64,
        /// Opening-dependent slowdown r: the proportional gain scales by 1 / (1 + r V / 100).
        slowdown: f64,
        /// The cart is a friction band crossed at the pushing speed, not in eq. (7)'s time.
        band: bool,
        /// Half the positioner's deadband, %: no pin movement while |e| is within it.
        hold: f64,
    },
}

/// Where a pin-cart's cart is and how far its pin is from pushing it one way.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PinReach {
    /// The cart's (valve's) position, %.
    pub cart_pct: f64,
    /// How far the pin must still travel before it pushes the cart that way, % (0: it pushes).
    pub to_side_pct: f64,
    /// The cart's width, %: the whole way a reversal must cross.
    pub band_pct: f64,
}

/// Running state of a pin-cart core.
#[derive(Debug, Clone)]
pub(crate) struct PinCart {
    law: PinLaw,
    half: f64,
    /// The half-width the cart was built with; eq. (7) crosses it in the crossing time, so a
    /// wider cart (a drifting friction band) takes longer in proportion.
    half0: f64,
    /// Stick-slip: how far beyond a side the pin must push a cart that has stopped, %.
    breakaway: f64,
    /// How far beyond the cart the pin may go on while a travel stop holds the cart, %.
    windup: f64,
    /// The cart stopped or crawled in the last sample (only tracked with a breakaway).
    stuck: bool,
    dt: f64,
    /// Pin position.
    y: f64,
    /// Cart position (valve position).
    v: f64,
    /// The opening-dependent slowdown at the cart position `slowed_at` (NaN before the first):
    /// `1 + r V / 100` and its inverse. A cart at rest keeps them, so the two divisions are
    /// made only when it has moved.
    slowed_at: f64,
    grow: f64,
    slow: f64,
}

impl PinCart {
    pub(crate) fn one(p: &PinCart1Params, dt: f64) -> Self {
        Self::with_law(
            PinLaw::Proportional { k: p.p_gain_per_s },
            p.backlash_pct,
            dt,
        )
    }

    /// Pin-cart II with the core-level effects of `fx`: `closing_slew_pct_per_s` > 0 gives
    /// closing its own slew rate (asymmetry); `open_slowdown` r > 0 makes the proportional pin
    /// speed and the slew limit fall with opening as `1 / (1 + r V / 100)` (a pneumatic chamber
    /// that grows with opening: slower response and slower stroke); `breakaway_pct` > 0 makes the cart stick
    /// whenever it stops, until the pin pushes that much beyond the side, then slip;
    /// `friction_band_pct` > 0 makes the cart that wide and crossed at the pushing speed;
    /// `positioner_deadband_pct` > 0 stops the pin while the error is within half of it.
    pub(crate) fn two(p: &PinCart2Params, fx: &Effects, dt: f64) -> Self {
        let close_max = if fx.closing_slew_pct_per_s > 0.0 {
            fx.closing_slew_pct_per_s
        } else {
            p.dy_max_pct_per_s
        };
        let band = fx.friction_band_pct > 0.0;
        let law = PinLaw::StateDependent {
            p: *p,
            close_max,
            slowdown: fx.open_slowdown,
            band,
            hold: fx.positioner_deadband_pct / 2.0,
        };
        let width = if band {
            fx.friction_band_pct
        } else {
            p.backlash_pct
        };
        PinCart {
            breakaway: fx.breakaway_pct,
            windup: fx.stop_windup_pct,
            ..Self::with_law(law, width, dt)
        }
    }

    fn with_law(law: PinLaw, backlash: f64, dt: f64) -> Self {
        PinCart {
            law,
            half: backlash / 2.0,
            half0: backlash / 2.0,
            breakaway: 0.0,
            windup: 0.0,
            stuck: false,
            dt,
            y: 0.0,
            v: 0.0,
            slowed_at: f64::NAN,
            grow: 1.0,
            slow: 1.0,
        }
    }

    /// Starts at rest with the pin centred in the cart.
    pub(crate) fn reset(&mut self, vp0: f64) {
        self.v = vp0;
        self.y = vp0;
        self.half = self.half0;
        self.stuck = false;
    }

    // Always inlined: [`super::Valve::run`] steps it in a loop that keeps its state in registers.
    #[inline(always)]
    pub(crate) fn step(&mut self, u: f64) -> f64 {
        let e = u - self.v; // eq. (1)
        let dy = match self.law {
            // eq. (2); one sample never carries the pin past the target, which keeps slow
            // sampling (P_k dt > 1, e.g. 1 Hz data) stable and changes nothing at 100 Hz.
            PinLaw::Proportional { k } => (k * self.dt).min(1.0) * e,
            PinLaw::StateDependent {
                p,
                close_max,
                slowdown,
                band,
                hold,
            } => {
                if e.abs() <= hold {
                    0.0
                } else {
                    self.pin_step_two(&p, close_max, slowdown, band, e)
                }
            }
        };
        self.y += dy;
        // eq. (3): the cart follows only when the pin pushes a side; a stuck cart only once the
        // pin has pushed `breakaway` beyond it, and then it slips the whole way at once.
        let reach = if self.stuck {
            self.half + self.breakaway
        } else {
            self.half
        };
        let before = self.v;
        if self.y - self.v >= reach {
            self.v = self.y - self.half;
        } else if self.y - self.v <= -reach {
            self.v = self.y + self.half;
        }
        // It sticks once it crawls slower than the breakaway distance per second (static
        // friction takes over from sliding friction).
        self.stuck = self.breakaway > 0.0 && (self.v - before).abs() < self.breakaway * self.dt;
        self.v
    }

    /// Pin movement of pin-cart II for one sample, eqs. (4)-(7); with a friction `band`, the
    /// crossing of the cart at the pushing speed too.
    #[inline(always)]
    fn pin_step_two(
        &mut self,
        p: &PinCart2Params,
        close_max: f64,
        slowdown: f64,
        band: bool,
        e: f64,
    ) -> f64 {
        if e == 0.0 {
            return 0.0;
        }
        // The direction of travel: `along(x)` is `x` signed like `e` (a sign flip, not a
        // multiplication, which keeps this serial chain of the simulation short).
        let opening = e > 0.0;
        let along = |x: f64| if opening { x } else { -x };
        let rel = self.y - self.v;
        let pushing = along(rel) >= self.half - 1e-12;
        // Beyond the far side of a stuck cart (breakaway), the pin is the positioner's pressure
        // loading the stem: it unloads at the pushing speed, back to the side, before it
        // crosses the cart.
        let unload = -along(rel) - self.half;
        if pushing || unload > 1e-12 || band {
            let slow = if slowdown == 0.0 {
                1.0
            } else {
                self.slowed().1
            };
            let speed = push_speed(p, close_max, slowdown, slow, e);
            let step = at_most(speed * self.dt, e.abs()); // eq. (5)
            along(if pushing {
                step
            } else if unload > 1e-12 {
                step.min(unload)
            } else {
                // Crossing the friction band at the pushing speed, up to its far side.
                (speed * self.dt).min(self.half - along(rel))
            })
        } else {
            // eq. (7): cross the cart in `crossing_time_s` (at least one sample), never beyond
            // its far side. A crossing time of 0 means no apparent backlash. The slower chamber
            // of an opening-dependent slowdown also takes longer to cross the friction band.
            let t = (p.crossing_time_s(self.v) * self.slowed().0).max(self.dt);
            along((2.0 * self.half0 * self.dt / t).min(self.half - along(rel)))
        }
    }

    /// Widens the cart (the friction band) by `extra_pct` over its built width. A pin that
    /// pushes a side stays on it (the pressure that holds the stem against the larger friction),
    /// so the valve does not move; the wider band shows on the next reversal.
    #[inline]
    pub(crate) fn widen(&mut self, extra_pct: f64) {
        let half = self.half0 + extra_pct.max(0.0) / 2.0;
        let rel = self.y - self.v;
        if rel.abs() >= self.half - 1e-12 {
            self.y = self.v + half.copysign(rel);
        }
        self.half = half;
    }

    /// `1 + r V / 100` at the cart's opening and its inverse (see [`slowdown_at`]), kept while
    /// the cart stays where they were computed.
    #[inline(always)]
    fn slowed(&mut self) -> (f64, f64) {
        // A NaN position never equals itself: computed afresh, as before the first.
        if self.v != self.slowed_at {
            let slowdown = match self.law {
                PinLaw::StateDependent { slowdown, .. } => slowdown,
                PinLaw::Proportional { .. } => 0.0,
            };
            (self.grow, self.slow) = slowdown_at(slowdown, self.v);
            self.slowed_at = self.v;
        }
        (self.grow, self.slow)
    }

    /// Where the cart is and how far the pin still has to go before it pushes the cart
    /// towards `dir` (+1 opening, -1 closing), for a compensator: 0 while it pushes that side.
    pub(crate) fn reach(&self, dir: f64) -> PinReach {
        let rel = self.y - self.v;
        PinReach {
            cart_pct: self.v,
            to_side_pct: (self.half - dir * rel).max(0.0),
            band_pct: 2.0 * self.half,
        }
    }

    /// The speed at which the pin moves for an error `e` at the cart while it pushes or crosses
    /// a friction band (pin-cart II), %/s; None for pin-cart I, and for pin-cart II's eq. (7)
    /// crossing, whose speed no error changes.
    pub(crate) fn pin_speed(&self, e: f64) -> Option<f64> {
        match &self.law {
            PinLaw::StateDependent {
                p,
                close_max,
                slowdown,
                band: true,
                ..
            } if e != 0.0 => Some(push_speed(
                p,
                *close_max,
                *slowdown,
                slowdown_at(*slowdown, self.v).1,
                e,
            )),
            _ => None,
        }
    }

    /// Overrides the cart position after the travel range clamped it; keeps the pin in the cart,
    /// or wound up to `windup` beyond it on the side of the stop.
    #[inline(always)]
    pub(crate) fn set_position(&mut self, v: f64) {
        self.v = v;
        let reach = self.half + self.breakaway;
        let (below, above) = if self.y > v {
            (reach, reach + self.windup)
        } else {
            (reach + self.windup, reach)
        };
        self.y = self.y.clamp(v - below, v + above);
    }

    /// Pin position relative to the cart centre (for invariant tests).
    #[cfg(test)]
    pub(crate) fn pin_offset(&self) -> f64 {
        self.y - self.v
    }
}

/// How many times slower than closed the opening-dependent slowdown `slowdown` (r) makes the
/// valve at opening `v` %: `1 + r V / 100`, the chamber's volume there over its volume closed.
#[inline]
pub fn slower_at(slowdown: f64, v: f64) -> f64 {
    1.0 + slowdown * v / 100.0
}

/// The opening-dependent slowdown `r` at opening `v`: [`slower_at`], and its inverse. Never
/// inlined: inlined into [`PinCart::slowed`], the compiler makes the two divisions on every
/// sample and selects, and the simulation waits for them even while the cart rests.
#[inline(never)]
fn slowdown_at(slowdown: f64, v: f64) -> (f64, f64) {
    let grow = slower_at(slowdown, v);
    (grow, 1.0 / grow)
}

/// Pin-cart II's pushing speed for the error `e` (non-zero) at an opening where the slowdown
/// `slowdown` gives the factor `slow` (from [`slowdown_at`]), %/s: eq. (4) saturated by eq.
/// (5). A chamber that grows with opening fills and vents more slowly: the response and the
/// stroke speed fall alike (dy_min, the positioner's creep, does not).
#[inline(always)]
fn push_speed(p: &PinCart2Params, close_max: f64, slowdown: f64, slow: f64, e: f64) -> f64 {
    let max = if e > 0.0 {
        p.dy_max_pct_per_s
    } else {
        close_max
    };
    let (gain, max) = if slowdown == 0.0 {
        (p.p_gain_per_s, max)
    } else {
        (slow * p.p_gain_per_s, slow * max)
    };
    let speed = gain * e.abs();
    // eq. (4)-(5): at least dy_min (also for an error that is not a number), at most `max`.
    let speed = if speed > p.dy_min_pct_per_s {
        speed
    } else {
        p.dy_min_pct_per_s
    };
    if speed < max {
        speed
    } else {
        max
    }
}

/// `x.min(limit)` for a limit that may be NaN (then `x`) and an `x` that is not: as `f64::min`
/// there, written as one comparison. `f64::min` also checks `x` for NaN, which lengthens the
/// serial chain of a simulation by a few cycles a sample.
#[inline(always)]
fn at_most(x: f64, limit: f64) -> f64 {
    if limit < x {
        limit
    } else {
        x
    }
}

/// `a_p, b_p, c_p` of the quadratic through the crossing times `t0`, `t50`, `t100` (s) at 0,
/// 50 and 100 % opening. If it dips below zero inside 0-100 % it is lifted until its minimum
/// there is zero, so the spec stays valid (crossing times are never negative).
pub fn crossing_poly(t0: f64, t50: f64, t100: f64) -> (f64, f64, f64) {
    let a = (t100 - 2.0 * t50 + t0) / 5000.0;
    let b = (t50 - t0) / 50.0 - 50.0 * a;
    let mut c = t0;
    if a > 0.0 {
        let v = -b / (2.0 * a);
        if (0.0..=100.0).contains(&v) {
            let min = (a * v + b) * v + c;
            if min < 0.0 {
                c -= min;
            }
        }
    }
    (a, b, c)
}

#[cfg(test)]
#[path = "pincart_tests.rs"]
mod tests;
