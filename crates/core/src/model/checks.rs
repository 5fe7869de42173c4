//! The range checks of a [`ModelSpec`], one small function per table.
//!
//! [`ModelSpec::violations`] lists every rule a spec breaks, each with its table, key, value and
//! a sentence saying what is allowed; [`ModelSpec::validate`] and the file loaders turn the first
//! one into an error that names the key (and the line, for a file). This module only judges
//! numbers: it does not parse, locate lines or build valves.

use super::{
    Effects, FopdtParams, ModelKind, ModelSpec, PhysicalParams, PinCart1Params, PinCart2Params,
    StictionParams,
};

/// One violated rule: table, key, value and what is allowed.
pub(super) struct Violation {
    pub(super) table: Option<&'static str>,
    pub(super) key: &'static str,
    pub(super) value: f64,
    pub(super) allowed: String,
}

/// Collects the violated rules of one spec, in the order they are checked.
#[derive(Default)]
struct Checks {
    out: Vec<Violation>,
}

impl Checks {
    /// Records a violation unless `ok` holds and `value` is a number (NaN always violates).
    fn need(
        &mut self,
        ok: bool,
        table: Option<&'static str>,
        key: &'static str,
        value: f64,
        allowed: &str,
    ) {
        if !ok || value.is_nan() {
            self.out.push(Violation {
                table,
                key,
                value,
                allowed: allowed.to_string(),
            });
        }
    }
}

impl ModelSpec {
    /// Every rule this spec breaks, first the tables, then each table's parameters.
    pub(super) fn violations(&self) -> Vec<Violation> {
        let mut c = Checks::default();
        tables(&mut c, self);
        dead_time(&mut c, self.model, self.dead_time_s);
        travel(&mut c, self);
        if let Some(p) = &self.fopdt {
            fopdt(&mut c, p);
        }
        if let Some(p) = &self.stiction {
            stiction(&mut c, p);
        }
        if let Some(p) = &self.pincart1 {
            pincart1(&mut c, p);
        }
        if let Some(p) = &self.pincart2 {
            pincart2(&mut c, p);
        }
        if let Some(p) = &self.physical {
            physical(&mut c, p);
        }
        effects(&mut c, &self.effects);
        effects_need_pincart2(&mut c, self.model, &self.effects);
        c.out
    }
}

/// Exactly the table named by `model` is present.
fn tables(c: &mut Checks, spec: &ModelSpec) {
    let kind = spec.model;
    let present = [
        ("fopdt", spec.fopdt.is_some(), ModelKind::Fopdt),
        ("stiction", spec.stiction.is_some(), ModelKind::Stiction),
        ("pincart1", spec.pincart1.is_some(), ModelKind::Pincart1),
        ("pincart2", spec.pincart2.is_some(), ModelKind::Pincart2),
        ("physical", spec.physical.is_some(), ModelKind::Physical),
    ];
    for (table, is_there, owner) in present {
        if is_there && owner != kind {
            c.need(false, Some(table), "", f64::NAN,
                &format!("table [{table}] does not belong to model = \"{kind}\": remove it or set model = \"{table}\""));
        }
        if !is_there && owner == kind {
            c.need(false, None, "model", f64::NAN,
                &format!("model = \"{kind}\" needs a [{table}] table with its parameters (see config/models/{table}.toml)"));
        }
    }
    if kind == ModelKind::Physical && !spec.effects.is_none() {
        c.need(false, Some("effects"), "", f64::NAN,
            "[effects] belongs to the composed pin-cart valve; model = \"physical\" has its physics in [physical] (deadband_pct, coulomb_band_pct, static_band_pct, sensor_resolution_pct, ...): remove [effects]");
    }
}

fn dead_time(c: &mut Checks, kind: ModelKind, td: f64) {
    c.need(
        td.is_finite() && td >= 0.0,
        None,
        "dead_time_s",
        td,
        "a dead time in seconds, >= 0",
    );
    c.need(td <= 60.0, None, "dead_time_s", td, "at most 60 s");
    if kind == ModelKind::Modelless {
        c.need(
            td == 0.0,
            None,
            "dead_time_s",
            td,
            "modelless has no dead time: use model = \"delayed\"",
        );
    }
}

fn travel(c: &mut Checks, spec: &ModelSpec) {
    let tr = spec.travel;
    c.need(
        tr.min_pct.is_finite() && tr.max_pct.is_finite() && tr.min_pct < tr.max_pct,
        Some("travel"),
        "max_pct",
        tr.max_pct,
        "travel.min_pct < travel.max_pct, both finite",
    );
}

fn fopdt(c: &mut Checks, p: &FopdtParams) {
    c.need(
        p.time_constant_s.is_finite() && p.time_constant_s > 0.0,
        Some("fopdt"),
        "time_constant_s",
        p.time_constant_s,
        "a time constant in seconds, > 0",
    );
}

fn stiction(c: &mut Checks, p: &StictionParams) {
    c.need(
        p.stickband_pct.is_finite() && p.stickband_pct >= 0.0,
        Some("stiction"),
        "stickband_pct",
        p.stickband_pct,
        "S in % of travel, >= 0",
    );
    c.need(
        p.jumpband_pct >= 0.0 && p.jumpband_pct <= p.stickband_pct,
        Some("stiction"),
        "jumpband_pct",
        p.jumpband_pct,
        "J in % of travel, 0 <= J <= stickband_pct",
    );
}

fn pincart1(c: &mut Checks, p: &PinCart1Params) {
    c.need(
        p.backlash_pct.is_finite() && p.backlash_pct >= 0.0,
        Some("pincart1"),
        "backlash_pct",
        p.backlash_pct,
        "B_L in % of travel, >= 0",
    );
    c.need(
        p.p_gain_per_s.is_finite() && p.p_gain_per_s > 0.0,
        Some("pincart1"),
        "p_gain_per_s",
        p.p_gain_per_s,
        "P_k in 1/s, > 0",
    );
}

fn pincart2(c: &mut Checks, p: &PinCart2Params) {
    let t = Some("pincart2");
    c.need(
        p.p_gain_per_s.is_finite() && p.p_gain_per_s > 0.0,
        t,
        "p_gain_per_s",
        p.p_gain_per_s,
        "P_k in 1/s, > 0",
    );
    c.need(
        p.dy_max_pct_per_s.is_finite() && p.dy_max_pct_per_s > 0.0,
        t,
        "dy_max_pct_per_s",
        p.dy_max_pct_per_s,
        "maximum speed in %/s, > 0",
    );
    c.need(
        p.dy_min_pct_per_s >= 0.0 && p.dy_min_pct_per_s <= p.dy_max_pct_per_s,
        t,
        "dy_min_pct_per_s",
        p.dy_min_pct_per_s,
        "minimum speed in %/s, 0 <= dy_min <= dy_max",
    );
    c.need(
        p.backlash_pct.is_finite() && p.backlash_pct >= 0.0,
        t,
        "backlash_pct",
        p.backlash_pct,
        "B_L in % of travel, >= 0",
    );
    pincart2_crossing(c, p);
}

/// The cart-crossing time polynomial must not dip below zero over the travel.
fn pincart2_crossing(c: &mut Checks, p: &PinCart2Params) {
    let worst = [0.0, 25.0, 50.0, 75.0, 100.0, -p.b_p / (2.0 * p.a_p)]
        .into_iter()
        .filter(|v| (0.0..=100.0).contains(v))
        .map(|v| p.crossing_time_s(v))
        .fold(f64::INFINITY, f64::min);
    c.need(
        worst >= 0.0 && p.a_p.is_finite() && p.b_p.is_finite() && p.c_p.is_finite(),
        Some("pincart2"),
        "c_p",
        p.c_p,
        "a_p*V^2 + b_p*V + c_p (cart-crossing time, s) must stay >= 0 for V in 0-100 %",
    );
}

/// The allowed range of every number of `[physical]`: key, value, lowest, highest, meaning.
#[rustfmt::skip]
fn physical_ranges(p: &PhysicalParams) -> [(&'static str, f64, f64, f64, &'static str); 15] {
    let slowest = p.fill_rate_pct_per_s.min(p.vent_rate_pct_per_s);
    [
        ("positioner_gain_per_s", p.positioner_gain_per_s, 1e-3, 100.0, "the positioner gain K in 1/s (chamber flow per % of error)"),
        ("deadband_pct", p.deadband_pct, 0.0, 10.0, "a positioner deadband in % (0 = none)"),
        ("fill_rate_pct_per_s", p.fill_rate_pct_per_s, 0.1, 1000.0, "the largest filling (opening) flow in %/s"),
        ("vent_rate_pct_per_s", p.vent_rate_pct_per_s, 0.1, 1000.0, "the largest venting (closing) flow in %/s"),
        ("min_rate_pct_per_s", p.min_rate_pct_per_s, 0.0, slowest, "a minimum flow in %/s (0 = none), at most the smaller of fill_rate_pct_per_s and vent_rate_pct_per_s"),
        ("volume_growth", p.volume_growth, 0.0, 20.0, "the chamber volume growth g over the stroke (fully open is 1 + g times slower; 0 = none)"),
        ("natural_freq_hz", p.natural_freq_hz, 1.0, 100.0, "the natural frequency of spring and stem in Hz"),
        ("damping_ratio", p.damping_ratio, 0.3, 5.0, "the stem's damping ratio"),
        ("coulomb_band_pct", p.coulomb_band_pct, 0.0, 20.0, "the Coulomb friction band in % of travel (lost motion on a reversal)"),
        ("static_band_pct", p.static_band_pct, p.coulomb_band_pct.max(0.0), 20.0, "the static friction band in % of travel, at least coulomb_band_pct (above it: stick-slip)"),
        ("sensor_gain", p.sensor_gain, 0.5, 1.5, "the sensor gain (1 = calibrated)"),
        ("sensor_offset_pct", p.sensor_offset_pct, -10.0, 10.0, "the sensor offset in % (0 = calibrated)"),
        ("sensor_noise_pct", p.sensor_noise_pct, 0.0, 5.0, "the standard deviation of the sensor noise in %"),
        ("sensor_resolution_pct", p.sensor_resolution_pct, 0.0, 10.0, "the sensor resolution in % (0 = continuous)"),
        ("internal_step_s", p.internal_step_s, 1e-5, 0.01, "the longest internal integration step in s"),
    ]
}

/// The physical valve: every number in its range, then the two stability limits.
fn physical(c: &mut Checks, p: &PhysicalParams) {
    for (key, value, lo, hi, what) in physical_ranges(p) {
        c.need(
            value.is_finite() && (lo..=hi).contains(&value),
            Some("physical"),
            key,
            value,
            &format!("{what}, {lo} to {hi}"),
        );
    }
    let damped = p.damping_ratio * std::f64::consts::TAU * p.natural_freq_hz;
    c.need(
        p.positioner_gain_per_s <= damped,
        Some("physical"),
        "positioner_gain_per_s",
        p.positioner_gain_per_s,
        &format!("at most damping_ratio * 2 pi * natural_freq_hz = {damped:.3} 1/s, or the positioner oscillates with the stem: lower the gain or raise natural_freq_hz or damping_ratio"),
    );
    c.need(
        p.noise_seed <= i64::MAX as u64,
        Some("physical"),
        "noise_seed",
        p.noise_seed as f64,
        "a seed from 0 to 9223372036854775807 (a TOML integer)",
    );
    let stable = 0.08 / p.natural_freq_hz;
    c.need(
        p.internal_step_s <= stable,
        Some("physical"),
        "internal_step_s",
        p.internal_step_s,
        &format!(
            "at most 0.08 / natural_freq_hz = {stable} s, or the stem's integration is unstable"
        ),
    );
}

/// Calibration, deadband, stiction and quantization: the effects around any core.
fn effects(c: &mut Checks, e: &Effects) {
    let t = Some("effects");
    c.need(
        e.calibration_gain.is_finite() && e.calibration_gain > 0.0,
        t,
        "calibration_gain",
        e.calibration_gain,
        "a positive gain (1 = none)",
    );
    c.need(
        e.calibration_offset_pct.abs() <= 100.0,
        t,
        "calibration_offset_pct",
        e.calibration_offset_pct,
        "an offset in %, between -100 and 100",
    );
    c.need(
        (0.0..=50.0).contains(&e.deadband_pct),
        t,
        "deadband_pct",
        e.deadband_pct,
        "a band in %, 0-50 (0 = none)",
    );
    effects_friction_and_sensor(c, e);
}

fn effects_friction_and_sensor(c: &mut Checks, e: &Effects) {
    let t = Some("effects");
    c.need(
        (0.0..=50.0).contains(&e.stickband_pct),
        t,
        "stickband_pct",
        e.stickband_pct,
        "S in %, 0-50 (0 = none)",
    );
    c.need(
        e.jumpband_pct >= 0.0 && e.jumpband_pct <= e.stickband_pct,
        t,
        "jumpband_pct",
        e.jumpband_pct,
        "J in %, 0 <= J <= stickband_pct",
    );
    c.need(
        (0.0..=10.0).contains(&e.quantization_pct),
        t,
        "quantization_pct",
        e.quantization_pct,
        "a sensor resolution in %, 0-10 (0 = continuous)",
    );
    c.need(
        e.closing_slew_pct_per_s >= 0.0 && e.closing_slew_pct_per_s.is_finite(),
        t,
        "closing_slew_pct_per_s",
        e.closing_slew_pct_per_s,
        "a speed in %/s, >= 0 (0 = same as opening)",
    );
    c.need(
        (0.0..=20.0).contains(&e.open_slowdown),
        t,
        "open_slowdown",
        e.open_slowdown,
        "a slowdown ratio r, 0-20 (fully open is 1 + r times slower; 0 = none)",
    );
    c.need(
        (0.0..=20.0).contains(&e.friction_band_pct),
        t,
        "friction_band_pct",
        e.friction_band_pct,
        "a friction band in %, 0-20 (0 = none)",
    );
    c.need(
        (0.0..=400.0).contains(&e.stop_windup_pct),
        t,
        "stop_windup_pct",
        e.stop_windup_pct,
        "a wind-up past a travel stop in %, 0-400 (0 = none)",
    );
    c.need(
        (0.0..=10.0).contains(&e.positioner_deadband_pct),
        t,
        "positioner_deadband_pct",
        e.positioner_deadband_pct,
        "a positioner deadband in %, 0-10 (0 = none)",
    );
}

/// Asymmetry, slowdown, breakaway, the friction band, the stop wind-up and the positioner
/// deadband live in pin-cart II's core only.
fn effects_need_pincart2(c: &mut Checks, kind: ModelKind, e: &Effects) {
    if kind == ModelKind::Pincart2 {
        return;
    }
    let t = Some("effects");
    c.need(
        e.closing_slew_pct_per_s == 0.0,
        t,
        "closing_slew_pct_per_s",
        e.closing_slew_pct_per_s,
        "asymmetric slew rates need model = \"pincart2\" (the only core with a slew rate)",
    );
    c.need(
        e.open_slowdown == 0.0,
        t,
        "open_slowdown",
        e.open_slowdown,
        "an opening-dependent speed needs model = \"pincart2\" (the only core with a pin speed)",
    );
    c.need(
        e.breakaway_pct == 0.0,
        t,
        "breakaway_pct",
        e.breakaway_pct,
        "stick-slip by breakaway needs model = \"pincart2\" (use stickband_pct with other models)",
    );
    c.need(
        e.friction_band_pct == 0.0,
        t,
        "friction_band_pct",
        e.friction_band_pct,
        "a friction band needs model = \"pincart2\" (pin-cart I's backlash_pct is one crossed at the positioner's speed)",
    );
    c.need(
        e.stop_windup_pct == 0.0,
        t,
        "stop_windup_pct",
        e.stop_windup_pct,
        "a wind-up at the travel stops needs model = \"pincart2\" (the only core with a pin)",
    );
    c.need(
        e.positioner_deadband_pct == 0.0,
        t,
        "positioner_deadband_pct",
        e.positioner_deadband_pct,
        "a positioner deadband needs model = \"pincart2\" (use deadband_pct with other models)",
    );
}
