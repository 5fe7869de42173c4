//! Reading a diagnosis in tests: the effects found and a fitted parameter.

use valve_bridge::diagnose::Diagnosis;

/// The effects found, in order.
pub(crate) fn names(d: &Diagnosis) -> Vec<&'static str> {
    d.findings.iter().map(|f| f.effect.name()).collect()
}

/// A fitted parameter by its label, from the first finding that has it (NaN when none does).
pub(crate) fn param(d: &Diagnosis, name: &str) -> f64 {
    d.findings
        .iter()
        .find_map(|f| f.params.get(name))
        .and_then(|v| v.as_f64())
        .unwrap_or(f64::NAN)
}
