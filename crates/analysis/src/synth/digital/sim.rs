//! The running digital valve: positioner, pneumatic line, chamber, stem and feedback stepped
//! through each sample in internal steps (the physics is in the parent module's doc). Only
//! stepping; no parameter is chosen here.

use std::collections::VecDeque;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use super::{flow_factor, DigitalError, DigitalParams, ATMOSPHERE_BAR};
use crate::synth::Actuator;

/// Offset of the travel sensor's noise seed from the feedback's, so each has its own stream.
const TRAVEL_SEED: u64 = 0x7a5e1;

/// A solenoid pulse as the chamber sees it (after the line delay), s since the reset.
#[derive(Debug, Clone, Copy)]
struct Pulse {
    from: f64,
    to: f64,
    fill: bool,
}

/// A digital valve being run at a fixed sample period.
#[derive(Debug, Clone)]
pub struct DigitalValve {
    p: DigitalParams,
    dt: f64,
    steps: usize,
    h: f64,
    w2: f64,
    span_bar: f64,
    supply_abs: f64,
    /// O_P of the samples still inside the input delay, newest last.
    ops: VecDeque<f64>,
    pulses: VecDeque<Pulse>,
    /// Samples since the reset; time of the next positioner sample.
    sample: u64,
    next_read: f64,
    last_error: f64,
    pressure: f64,
    x: f64,
    v: f64,
    z: f64,
    arm: f64,
    feedback_rng: ChaCha8Rng,
    travel_rng: ChaCha8Rng,
}

fn on_lattice(x: f64, q: f64) -> f64 {
    if q > 0.0 {
        (x / q).round() * q
    } else {
        x
    }
}

impl DigitalValve {
    /// The valve of `params`, recorded every `dt` s, at rest closed (see [`Actuator::reset`]).
    pub fn new(params: &DigitalParams, dt: f64) -> Result<Self, DigitalError> {
        params.validate()?;
        if !(dt.is_finite() && dt > 0.0) {
            return Err(DigitalError {
                name: "sample period",
                value: dt,
                range: "above 0 s",
            });
        }
        let steps = (dt / params.internal_step_s).ceil().max(1.0) as usize;
        let mut valve = DigitalValve {
            p: *params,
            dt,
            steps,
            h: dt / steps as f64,
            w2: (std::f64::consts::TAU * params.natural_freq_hz).powi(2),
            span_bar: params.spring_end_bar - params.spring_start_bar,
            supply_abs: ATMOSPHERE_BAR + params.supply_bar,
            ops: VecDeque::new(),
            pulses: VecDeque::new(),
            sample: 0,
            next_read: 0.0,
            last_error: 0.0,
            pressure: ATMOSPHERE_BAR,
            x: 0.0,
            v: 0.0,
            z: 0.0,
            arm: 0.0,
            feedback_rng: ChaCha8Rng::seed_from_u64(params.noise_seed),
            travel_rng: ChaCha8Rng::seed_from_u64(params.noise_seed.wrapping_add(TRAVEL_SEED)),
        };
        valve.reset(0.0, 0.0);
        Ok(valve)
    }

    /// The stem's position, % (no linkage, no sensor).
    pub fn stem_pct(&self) -> f64 {
        self.x
    }

    /// Runs O_P `op` from rest at `vp0`: the stem's positions when `stem`, else V_P.
    pub fn simulate(&mut self, op: &[f64], vp0: f64, stem: bool) -> Vec<f64> {
        self.reset(op.first().copied().unwrap_or(vp0), vp0);
        op.iter()
            .map(|&u| {
                let vp = self.step(u);
                if stem {
                    self.x
                } else {
                    vp
                }
            })
            .collect()
    }

    /// The set-point the positioner sees at `t` s: O_P `input_delay_s` before.
    fn set_point(&self, t: f64) -> f64 {
        let back = ((self.p.input_delay_s - (t - self.sample as f64 * self.dt)) / self.dt)
            .ceil()
            .max(0.0) as usize;
        let newest = self.ops.len().saturating_sub(1);
        self.ops
            .get(newest.saturating_sub(back))
            .copied()
            .unwrap_or(0.0)
    }

    /// The positioner's sample at `t`: reads the travel sensor and fires a pulse or none.
    fn read(&mut self, t: f64) {
        let noise: f64 = StandardNormal.sample(&mut self.travel_rng);
        let reading = on_lattice(
            self.arm + self.p.travel_noise_pct * noise,
            self.p.travel_lattice_pct,
        );
        let ts = self.p.sample_s;
        let e = self.set_point(t) - reading;
        let d = self.p.duty_per_pct * (e + self.p.derivative_s * (e - self.last_error) / ts);
        self.last_error = e;
        if e.abs() <= self.p.tolerance_pct || d * e <= 0.0 {
            return;
        }
        let width = (d.abs() * ts).clamp(self.p.min_pulse_s, ts);
        let from = t + self.p.line_delay_s;
        self.pulses.push_back(Pulse {
            from,
            to: from + width,
            fill: e > 0.0,
        });
    }

    /// Net flow into the chamber at `t`, bar/s at the closed volume.
    fn flow(&mut self, t: f64) -> f64 {
        while self.pulses.front().is_some_and(|q| q.to <= t) {
            self.pulses.pop_front();
        }
        let Some(pulse) = self.pulses.front().filter(|q| q.from <= t) else {
            return 0.0;
        };
        let (p, b) = (self.pressure, self.p.critical_ratio);
        if pulse.fill {
            self.p.fill_per_s * self.supply_abs * flow_factor(p / self.supply_abs, b)
        } else {
            -self.p.vent_per_s * p * flow_factor(ATMOSPHERE_BAR / p, b)
        }
    }

    /// One internal step ending at `t`.
    fn advance(&mut self, t: f64) {
        let h = self.h;
        let p = &self.p;
        let force = 100.0 * (self.pressure - ATMOSPHERE_BAR - p.spring_start_bar) / self.span_bar;
        // The Stribeck factor at a speed, and the friction level it gives.
        let stribeck = |v: f64| (-(v / p.stribeck_pct_per_s).powi(2)).exp();
        let level = |s: f64| p.coulomb_pct + (p.static_pct - p.coulomb_pct) * s;
        let before = stribeck(self.v);
        // The bristles' damping acts while they stick (as a constant one, it would damp a
        // sliding stem many times over).
        let (s0, s1) = (p.bristle_stiffness, p.bristle_damping_s * before);
        let pull = s0 * self.v.abs() * self.z / level(before);
        let v = (self.v + h * self.w2 * (force - self.x - s0 * self.z + s1 * pull))
            / (1.0 + h * self.w2 * (s1 + p.viscous_s));
        let z = (self.z + h * v) / (1.0 + h * s0 * v.abs() / level(stribeck(v)));
        let mut x = self.x + h * v;
        let mut v = v;
        if x > p.stop_high_pct || x < p.stop_low_pct {
            x = x.clamp(p.stop_low_pct, p.stop_high_pct);
            v = 0.0;
        }
        let growth = p.volume_growth;
        let volume = 1.0 + growth * x.clamp(0.0, 100.0) / 100.0;
        let flow = self.flow(t);
        let swept = growth * (x - self.x) / 100.0 / h;
        self.pressure = (self.pressure + h * (flow - self.pressure * swept) / volume)
            .clamp(ATMOSPHERE_BAR, self.supply_abs);
        (self.x, self.v, self.z) = (x, v, z);
        let half = self.p.play_pct / 2.0;
        self.arm = self.arm.clamp(self.x - half, self.x + half);
    }
}

impl Actuator for DigitalValve {
    /// At rest at `vp_pct` (the stem there, the pressure balancing it, the linkage's arm
    /// centred), with `op_pct` as every set-point so far; both sensors' noise re-seeded.
    fn reset(&mut self, op_pct: f64, vp_pct: f64) {
        let p = &self.p;
        self.x = vp_pct.clamp(p.stop_low_pct, p.stop_high_pct);
        (self.v, self.z, self.arm) = (0.0, 0.0, self.x);
        self.pressure = (ATMOSPHERE_BAR + p.spring_start_bar + self.span_bar * self.x / 100.0)
            .clamp(ATMOSPHERE_BAR, self.supply_abs);
        let held = (p.input_delay_s / self.dt).ceil() as usize + 2;
        self.ops = std::iter::repeat_n(op_pct, held).collect();
        self.pulses.clear();
        (self.sample, self.next_read, self.last_error) = (0, 0.0, 0.0);
        self.feedback_rng = ChaCha8Rng::seed_from_u64(p.noise_seed);
        self.travel_rng = ChaCha8Rng::seed_from_u64(p.noise_seed.wrapping_add(TRAVEL_SEED));
    }

    fn step(&mut self, op_pct: f64) -> f64 {
        self.ops.pop_front();
        self.ops.push_back(op_pct);
        let t0 = self.sample as f64 * self.dt;
        for k in 0..self.steps {
            let t = t0 + k as f64 * self.h;
            while self.next_read <= t + 1e-12 {
                let at = self.next_read;
                self.read(at);
                self.next_read += self.p.sample_s;
            }
            self.advance(t + self.h);
        }
        self.sample += 1;
        let noise: f64 = StandardNormal.sample(&mut self.feedback_rng);
        on_lattice(
            self.p.gain * self.arm + self.p.offset_pct + self.p.noise_pct * noise,
            self.p.lattice_pct,
        )
    }
}
