//! Valves on one serial bus: `[[valve]]` tables of kind `modbus-rtu` that name the same `port`
//! share one link. At load they must agree on the line (baud, parity, data and stop bits),
//! have distinct slave ids, fit the bus budget together (the sum of their cycles' wire times
//! within the loop period) and leave each other their share of the period as deadlines
//! ([`BusBudget::deadlines`]). A refusal names the port and what to change.
//!
//! Checking only: opening the shared link is [`crate::runtime::valve`]'s job.

use super::{Check, LoopConfig, ValveConfig, ValveSpec};
use vb_core::toml_file::TomlError;
use vb_modbus::budget::{Budget, BusBudget};
use vb_modbus::link::RtuLink;
use vb_modbus::map::RegisterMap;
use vb_modbus::plan::Plan;

/// The serial buses with more than one valve: each port and its valves' indices, in order.
pub fn buses(valves: &[ValveConfig]) -> Vec<(String, Vec<usize>)> {
    let mut out: Vec<(String, Vec<usize>)> = Vec::new();
    for (i, v) in valves.iter().enumerate() {
        let Some((l, _)) = rtu(v) else { continue };
        match out.iter_mut().find(|(port, _)| *port == l.port) {
            Some((_, members)) => members.push(i),
            None => out.push((l.port.clone(), vec![i])),
        }
    }
    out.retain(|(_, members)| members.len() > 1);
    out
}

/// The link and the register map of an RTU valve.
fn rtu(v: &ValveConfig) -> Option<(&RtuLink, &RegisterMap)> {
    match &v.backend {
        ValveSpec::ModbusRtu(link, device) => Some((link, &device.registers)),
        _ => None,
    }
}

/// The `timeout_ms` of the valves `members`, in order.
pub fn timeouts(valves: &[ValveConfig], members: &[usize]) -> Vec<Option<f64>> {
    (members.iter())
        .map(|&i| rtu(&valves[i]).and_then(|(l, _)| l.timeout_ms))
        .collect()
}

/// The budget of the bus on `port` whose valves are `members`, for a loop of `period_s`.
pub fn budget(valves: &[ValveConfig], port: &str, members: &[usize], period_s: f64) -> BusBudget {
    let parts = (members.iter())
        .filter_map(|&i| {
            let v = &valves[i];
            rtu(v).map(|(l, registers)| {
                let b = Budget::rtu(l, &Plan::rtu(registers), period_s);
                (v.label().to_string(), b)
            })
        })
        .collect();
    BusBudget::new(port, parts)
}

/// The checks of every shared bus; `check_of(i)` points at valve `i`'s part of the file.
pub(super) fn check<'a>(
    valves: &[ValveConfig],
    check_of: impl Fn(usize) -> Check<'a>,
    timing: &LoopConfig,
) -> Result<(), TomlError> {
    let t = "valve.modbus-rtu";
    for (port, members) in buses(valves) {
        let first = &valves[members[0]];
        let Some((line, _)) = rtu(first) else {
            continue;
        };
        for &i in &members[1..] {
            let v = &valves[i];
            let Some((l, _)) = rtu(v) else { continue };
            let c = check_of(i);
            let same = (l.baud, l.parity, l.data_bits, l.stop_bits)
                == (line.baud, line.parity, line.data_bits, line.stop_bits);
            if !same {
                return Err(c.bad(t, "port", format!("{port} is also valve `{}`'s port, with other line settings: one serial line has one baud rate, parity, data and stop bits; give both the same", first.label())));
            }
            if let Some(&j) = (members.iter())
                .find(|&&j| j < i && rtu(&valves[j]).is_some_and(|(o, _)| o.slave_id == l.slave_id))
            {
                return Err(c.bad(t, "slave_id", format!("{} is also valve `{}`'s slave id on {port}: each device on a bus has its own address", l.slave_id, valves[j].label())));
            }
        }
        let last = check_of(*members.last().unwrap_or(&0));
        let bus = budget(valves, &port, &members, timing.period_s());
        if bus.usage() > 1.0 {
            let message = match bus.check() {
                Err(e) => e.to_string(),
                Ok(_) => continue,
            };
            return Err(last.bad(t, "port", message));
        }
        if let Err(message) = bus.deadlines(&timeouts(valves, &members)) {
            return Err(last.bad(t, "timeout_ms", message));
        }
    }
    Ok(())
}
