//! Whether the recording pins each fitted parameter down: a parameter resting at a bound of
//! its search box, or one the error hardly changes along, is *undetermined*, and Table 2, the
//! report and the JSON say so instead of letting its value pass for a measurement.
//!
//! Flat: moving the parameter by [`PROBE`] of its box (on its own scale) either way, the
//! others held, changes the error by less than what chance would (the likelihood-ratio test of
//! one parameter at 95 %: n_eff ln(SSE' / SSE) < 3.84, counting independent samples, the
//! scored samples over the residual's correlation length).
//!
//! Not here: fitting ([`super::search`]) or printing (`report::identify`).

use serde::Serialize;

use super::cost::Problem;
use super::params::Layout;

/// How far a parameter is moved either way, as a share of its box on its own scale.
pub const PROBE: f64 = 0.15;
/// 95 % point of the chi-squared distribution with one degree of freedom.
const CHI2_95: f64 = 3.84;
/// Share of the box within which a parameter counts as at its bound.
const AT_BOUND: f64 = 0.005;

/// Why a parameter is undetermined.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Why {
    /// It rests at a bound of its search box: the data pushed it there, or do not hold it.
    AtBound,
    /// The error hardly changes along it.
    Flat,
}

/// A fitted parameter the recording does not pin down.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Undetermined {
    /// The parameter's name in the search layout (`dead_time_s`, `crossing_50_s`, ...).
    pub name: &'static str,
    pub value: f64,
    pub why: Why,
}

/// The parameters of `x` (the physical vector of `layout`) that `problem` does not pin down,
/// where `x` scores `sse` over `n_eff` independent samples.
pub fn undetermined(
    layout: &Layout,
    x: &[f64],
    problem: &Problem,
    sse: f64,
    n_eff: f64,
) -> Vec<Undetermined> {
    let u = layout.to_unit(x);
    (layout.defs.iter().enumerate())
        .filter_map(|(i, def)| {
            let at_bound = !(AT_BOUND..=1.0 - AT_BOUND).contains(&u[i]);
            let rise = |shift: f64| {
                let mut moved = u.clone();
                moved[i] = (u[i] + shift).clamp(0.0, 1.0);
                let other = problem.sse(&layout.spec(&layout.from_unit(&moved)));
                n_eff * (other / sse.max(1e-12)).ln()
            };
            let why = if at_bound {
                Why::AtBound
            } else if rise(-PROBE).max(rise(PROBE)) < CHI2_95 {
                Why::Flat
            } else {
                return None;
            };
            Some(Undetermined {
                name: def.name,
                value: x[i],
                why,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::params::Limits;
    use vb_core::model::{bundled, ModelKind};
    use vb_core::testkit::{answer, ripple, steps};

    #[test]
    fn a_parameter_the_data_cannot_see_is_flagged() {
        // An FOPDT valve on slow steps: the dead time (0.38 s) and the time constant are
        // pinned down; a pure delay fitted to it finds its dead time too.
        let dt = 0.01;
        let op = steps(20000, 700, &[40.0, 50.0, 60.0]);
        let truth = bundled(ModelKind::Fopdt);
        let vp = answer(&truth, &op, dt);
        let noisy: Vec<f64> = (vp.iter().enumerate())
            .map(|(k, v)| v + ripple(k, 0.05))
            .collect();
        let all = vec![true; op.len()];
        let problem = Problem::new(&op, &noisy, &all, dt);
        let layout = Layout::new(ModelKind::Fopdt, Limits::for_recording(dt, 0.4));
        let x = layout.vector(&truth);
        let sse = problem.sse(&truth);
        assert!(undetermined(&layout, &x, &problem, sse, 2000.0).is_empty());
        // At a bound: a dead time of zero.
        let mut at_zero = x.clone();
        at_zero[0] = 0.0;
        let flags = undetermined(
            &layout,
            &at_zero,
            &problem,
            problem.sse(&layout.spec(&at_zero)),
            2000.0,
        );
        assert_eq!(flags[0].why, Why::AtBound);
        assert_eq!(flags[0].name, "dead_time_s");
        // Flat: a recording that never moves cannot tell any time constant from another.
        let still = vec![40.0; op.len()];
        let flat = Problem::new(&still, &still, &all, dt);
        let flags = undetermined(&layout, &x, &flat, 1e-6, 2000.0);
        assert!(
            flags
                .iter()
                .any(|f| f.name == "time_constant_s" && f.why == Why::Flat),
            "{flags:?}"
        );
    }
}
