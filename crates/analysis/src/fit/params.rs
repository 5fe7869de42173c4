//! Parameter vectors of each model kind: names, units, bounds, and the mapping between a
//! [`ModelSpec`] and the plain `Vec<f64>` an optimiser moves.
//!
//! Every kind has a fixed list of free parameters ([`ParamDef`]), in physical units, each with
//! a physically sensible box and a scale ([`Scale::Log`] for gains, time constants and speeds,
//! which are searched in proportions; [`Scale::Linear`] for dead times, bands and the
//! crossing times). [`Layout::spec`] turns a vector into a valid spec and [`Layout::vector`] reads
//! one back, so fitting, diagnosis and reports share one definition of "the parameters".
//!
//! Pin-cart II's eq. (7) polynomial is searched as its crossing times at 0, 50 and 100 %
//! opening (three well-scaled numbers of seconds) rather than as `a_p, b_p, c_p`, whose scales
//! differ by four orders of magnitude; [`crossing_poly`](vb_core::model::crossing_poly) converts. Stiction's jump band is
//! searched as a share of the stickband, so `J <= S` holds everywhere in the box.
//!
//! Not here: the cost function or the search ([`super::cost`], [`super::search`]).

use vb_core::model::{
    crossing_poly, FopdtParams, ModelKind, ModelSpec, PinCart1Params, PinCart2Params,
    StictionParams,
};

/// How a parameter is searched.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scale {
    /// Moves in absolute steps (dead times, bands, crossing times).
    Linear,
    /// Moves in proportions (gains, time constants, speeds); bounds must be > 0.
    Log,
}

impl Scale {
    /// The scale a box calls for: logarithmic when it spans more than a factor of 20 on the
    /// positive axis (gains, times and speeds, where a simplex must move in proportions or its
    /// steps are coarse for small values), linear otherwise.
    pub fn for_box(lo: f64, hi: f64) -> Self {
        if lo > 0.0 && hi / lo > 20.0 {
            Scale::Log
        } else {
            Scale::Linear
        }
    }
}

/// One free parameter: what it is called, its unit, its box and scale.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParamDef {
    /// Key in reports and JSON, e.g. `dead_time_s`.
    pub name: &'static str,
    /// Unit as printed, e.g. `s`, `%`, `1/s`, `%/s`.
    pub unit: &'static str,
    /// Lower bound, physical units.
    pub lo: f64,
    /// Upper bound, physical units.
    pub hi: f64,
    /// Search scale.
    pub scale: Scale,
}

impl ParamDef {
    /// A parameter searched in `lo..=hi` on the scale that box calls for ([`Scale::for_box`]).
    pub fn new(name: &'static str, unit: &'static str, lo: f64, hi: f64) -> Self {
        ParamDef {
            name,
            unit,
            lo,
            hi,
            scale: Scale::for_box(lo, hi),
        }
    }

    /// Maps a physical value to the unit interval of the search box (clamped).
    pub fn to_unit(&self, v: f64) -> f64 {
        let u = match self.scale {
            Scale::Linear => (v - self.lo) / (self.hi - self.lo),
            Scale::Log => (v.max(self.lo).ln() - self.lo.ln()) / (self.hi.ln() - self.lo.ln()),
        };
        if u.is_finite() {
            u.clamp(0.0, 1.0)
        } else {
            0.0
        }
    }

    /// Maps a point of the unit interval to the physical value (clamped into the box).
    pub fn from_unit(&self, u: f64) -> f64 {
        let u = u.clamp(0.0, 1.0);
        let v = match self.scale {
            Scale::Linear => self.lo + u * (self.hi - self.lo),
            Scale::Log => (self.lo.ln() + u * (self.hi.ln() - self.lo.ln())).exp(),
        };
        // The exponential can land a rounding step outside the box.
        v.clamp(self.lo, self.hi)
    }
}

/// Limits that depend on the recording: the longest dead time worth searching and the
/// sample period (which bounds the fastest dynamics that can be seen).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Upper bound of the dead time, s.
    pub max_dead_time_s: f64,
    /// Sample period, s.
    pub sample_period_s: f64,
}

impl Limits {
    /// Bounds for a recording sampled every `dt` seconds whose dead time is thought to be
    /// about `td_guess`: up to three times the guess plus ten samples, at least 1.5 s, at most
    /// the model's 60 s.
    pub fn for_recording(dt: f64, td_guess: f64) -> Self {
        Limits {
            max_dead_time_s: (3.0 * td_guess + 10.0 * dt).clamp(1.5, 60.0),
            sample_period_s: dt,
        }
    }
}

/// The free parameters of one model kind under given [`Limits`], and the spec mapping.
#[derive(Debug, Clone, PartialEq)]
pub struct Layout {
    /// The model kind.
    pub kind: ModelKind,
    /// Its free parameters in vector order.
    pub defs: Vec<ParamDef>,
}

/// Shortest crossing / time constant the search considers, as a multiple of the sample period.
const FASTEST_IN_SAMPLES: f64 = 0.5;

impl Layout {
    /// The layout of `kind`. Modelless has no parameters; every other kind starts with the
    /// dead time `dead_time_s`.
    pub fn new(kind: ModelKind, lim: Limits) -> Self {
        let dt = lim.sample_period_s;
        let td = ParamDef {
            name: "dead_time_s",
            unit: "s",
            lo: 0.0,
            hi: lim.max_dead_time_s,
            scale: Scale::Linear,
        };
        let fast = FASTEST_IN_SAMPLES * dt;
        // A pin that closes the error within one sample (P_k dt = 1, the model's cap), or
        // faster than 50 /s (20 ms), looks the same as an instant one.
        let max_gain = (1.0 / dt).min(50.0);
        let log = |name, unit, lo: f64, hi: f64| ParamDef {
            name,
            unit,
            lo,
            hi: hi.max(lo * 10.0),
            scale: Scale::Log,
        };
        let lin = |name, unit, lo, hi| ParamDef {
            name,
            unit,
            lo,
            hi,
            scale: Scale::Linear,
        };
        let defs = match kind {
            ModelKind::Modelless => vec![],
            ModelKind::Delayed => vec![td],
            ModelKind::Fopdt => vec![td, log("time_constant_s", "s", fast.min(0.005), 60.0)],
            ModelKind::Stiction => vec![
                td,
                lin("stickband_pct", "%", 0.0, 10.0),
                lin("jump_share", "of S", 0.0, 1.0),
            ],
            ModelKind::Pincart1 => vec![
                td,
                lin("backlash_pct", "%", 0.0, 10.0),
                log("p_gain_per_s", "1/s", 0.02, max_gain),
            ],
            ModelKind::Pincart2 => vec![
                td,
                log("p_gain_per_s", "1/s", 0.02, max_gain),
                log("dy_max_pct_per_s", "%/s", 0.5, 100.0 / dt),
                lin("dy_min_pct_per_s", "%/s", 0.0, 5.0),
                lin("crossing_0_s", "s", 0.0, 5.0),
                lin("crossing_50_s", "s", 0.0, 5.0),
                lin("crossing_100_s", "s", 0.0, 5.0),
            ],
            // Not identifiable: `identify` refuses it before a layout is built.
            ModelKind::Physical => vec![],
        };
        Layout { kind, defs }
    }

    /// Number of free parameters (Table 2's count).
    pub fn len(&self) -> usize {
        self.defs.len()
    }

    /// True for modelless (nothing to fit).
    pub fn is_empty(&self) -> bool {
        self.defs.is_empty()
    }

    /// The spec for the physical vector `x` (values outside the box are clamped into it).
    /// Pin-cart II's crossing times become `a_p, b_p, c_p`; a polynomial that would dip below
    /// zero between the three points is lifted so its minimum on 0-100 % is zero.
    pub fn spec(&self, x: &[f64]) -> ModelSpec {
        let v = |i: usize| {
            x.get(i)
                .copied()
                .unwrap_or(self.defs[i].lo)
                .clamp(self.defs[i].lo, self.defs[i].hi)
        };
        match self.kind {
            ModelKind::Modelless => ModelSpec::bare(ModelKind::Modelless, 0.0),
            ModelKind::Delayed => ModelSpec::bare(ModelKind::Delayed, v(0)),
            ModelKind::Fopdt => ModelSpec {
                fopdt: Some(FopdtParams {
                    time_constant_s: v(1),
                }),
                ..ModelSpec::bare(ModelKind::Fopdt, v(0))
            },
            ModelKind::Stiction => ModelSpec {
                stiction: Some(StictionParams {
                    stickband_pct: v(1),
                    jumpband_pct: v(1) * v(2),
                }),
                ..ModelSpec::bare(ModelKind::Stiction, v(0))
            },
            ModelKind::Pincart1 => ModelSpec {
                pincart1: Some(PinCart1Params {
                    backlash_pct: v(1),
                    p_gain_per_s: v(2),
                }),
                ..ModelSpec::bare(ModelKind::Pincart1, v(0))
            },
            ModelKind::Pincart2 => {
                let (a_p, b_p, c_p) = crossing_poly(v(4), v(5), v(6));
                let dy_max = v(2);
                ModelSpec {
                    pincart2: Some(PinCart2Params {
                        p_gain_per_s: v(1),
                        dy_max_pct_per_s: dy_max,
                        dy_min_pct_per_s: v(3).min(dy_max),
                        a_p,
                        b_p,
                        c_p,
                        backlash_pct: 1.0,
                    }),
                    ..ModelSpec::bare(ModelKind::Pincart2, v(0))
                }
            }
            ModelKind::Physical => vb_core::model::bundled(ModelKind::Physical),
        }
    }

    /// The physical vector of `spec` (its kind must be this layout's; missing tables give the
    /// lower bounds). The inverse of [`Layout::spec`] inside the box.
    pub fn vector(&self, spec: &ModelSpec) -> Vec<f64> {
        let td = spec.dead_time_s;
        let mut x = match self.kind {
            ModelKind::Modelless => vec![],
            ModelKind::Delayed => vec![td],
            ModelKind::Fopdt => vec![td, spec.fopdt.map_or(1.0, |p| p.time_constant_s)],
            ModelKind::Stiction => {
                let (s, j) = spec
                    .stiction
                    .map_or((0.0, 0.0), |p| (p.stickband_pct, p.jumpband_pct));
                vec![td, s, if s > 0.0 { j / s } else { 0.0 }]
            }
            ModelKind::Pincart1 => {
                let p = spec.pincart1.unwrap_or(PinCart1Params {
                    backlash_pct: 0.0,
                    p_gain_per_s: 1.0,
                });
                vec![td, p.backlash_pct, p.p_gain_per_s]
            }
            ModelKind::Pincart2 => match spec.pincart2 {
                Some(p) => vec![
                    td,
                    p.p_gain_per_s,
                    p.dy_max_pct_per_s,
                    p.dy_min_pct_per_s,
                    p.crossing_time_s(0.0),
                    p.crossing_time_s(50.0),
                    p.crossing_time_s(100.0),
                ],
                None => self.defs.iter().map(|d| d.lo).collect(),
            },
            ModelKind::Physical => vec![],
        };
        for (v, d) in x.iter_mut().zip(&self.defs) {
            *v = v.clamp(d.lo, d.hi);
        }
        x
    }

    /// `x` in the unit cube of the search box.
    pub fn to_unit(&self, x: &[f64]) -> Vec<f64> {
        x.iter()
            .zip(&self.defs)
            .map(|(&v, d)| d.to_unit(v))
            .collect()
    }

    /// A unit-cube point back in physical units.
    pub fn from_unit(&self, u: &[f64]) -> Vec<f64> {
        u.iter()
            .zip(&self.defs)
            .map(|(&v, d)| d.from_unit(v))
            .collect()
    }
}

/// The physical parameters of a fitted spec as Table 2 lists them: `(name, value, unit)`,
/// dead time first. Pin-cart II reports `a_p, b_p, c_p` (the paper's parameters), stiction
/// the jump band in %.
pub fn table2(spec: &ModelSpec) -> Vec<(&'static str, f64, &'static str)> {
    let mut out = Vec::new();
    if spec.model != ModelKind::Modelless {
        out.push(("dead_time_s", spec.dead_time_s, "s"));
    }
    if let Some(p) = &spec.fopdt {
        out.push(("time_constant_s", p.time_constant_s, "s"));
    }
    if let Some(p) = &spec.stiction {
        out.push(("stickband_pct", p.stickband_pct, "%"));
        out.push(("jumpband_pct", p.jumpband_pct, "%"));
    }
    if let Some(p) = &spec.pincart1 {
        out.push(("backlash_pct", p.backlash_pct, "%"));
        out.push(("p_gain_per_s", p.p_gain_per_s, "1/s"));
    }
    if let Some(p) = &spec.pincart2 {
        out.push(("p_gain_per_s", p.p_gain_per_s, "1/s"));
        out.push(("dy_max_pct_per_s", p.dy_max_pct_per_s, "%/s"));
        out.push(("dy_min_pct_per_s", p.dy_min_pct_per_s, "%/s"));
        out.push(("a_p", p.a_p, "s/%²"));
        out.push(("b_p", p.b_p, "s/%"));
        out.push(("c_p", p.c_p, "s"));
    }
    out
}

/// Serialises a spec as its Table 2 parameters, `{name: value}` (for `--json`).
pub fn serialize_table2<S: serde::Serializer>(spec: &ModelSpec, s: S) -> Result<S::Ok, S::Error> {
    use serde::ser::SerializeMap;
    let params = table2(spec);
    let mut map = s.serialize_map(Some(params.len()))?;
    for (name, value, _) in params {
        map.serialize_entry(name, &value)?;
    }
    map.end()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lim() -> Limits {
        Limits::for_recording(0.01, 0.3)
    }

    #[test]
    fn every_spec_in_the_box_is_valid_and_round_trips() {
        for kind in ModelKind::ALL {
            let l = Layout::new(kind, lim());
            for corner in [0.0, 0.3, 0.77, 1.0] {
                let u = vec![corner; l.len()];
                let x = l.from_unit(&u);
                let spec = l.spec(&x);
                assert!(spec.validate().is_ok(), "{kind} at {corner}: {spec:?}");
                let back = l.vector(&spec);
                if kind != ModelKind::Pincart2 || corner > 0.0 {
                    let same = l.spec(&back);
                    assert_eq!(same, spec, "{kind}");
                }
            }
        }
    }

    #[test]
    fn unit_mapping_is_inverse() {
        let l = Layout::new(ModelKind::Pincart2, lim());
        let x = vec![0.4, 3.0, 20.0, 0.3, 0.3, 0.5, 0.8];
        let back = l.from_unit(&l.to_unit(&x));
        for (a, b) in x.iter().zip(&back) {
            assert!((a - b).abs() < 1e-9 * a.abs().max(1.0), "{x:?} {back:?}");
        }
    }
}
