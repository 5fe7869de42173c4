//! `valve-bridge probe`: one look at a positioner through the register map, before a loop runs.
//!
//! [`probe`] reads every mapped register once (set-point, position, status) with the link's
//! own client, and writes only when asked (`--write-test PCT`: the set-point once, then every
//! register again). Each row of the [`Report`] holds the register's place and format, the raw
//! words and what they mean in %, the round trip, or the fault in words (for an exception:
//! its code, its name and what to check). With a device profile ([`super::profile`]) each row
//! also carries the manual's name and number of the register, and the profile's further
//! registers (override, command, ...) are read too, their values named. The report prints as a
//! table.
//!
//! Not here: connecting (the caller opens the [`ModbusValve`]), the loop, the bus budget verdict.

use std::fmt;
use std::time::Instant;

use super::client::{Fault, ModbusValve};
use super::map::{Format, Register, StatusRegister, Table};
use super::profile::Profile;

/// One register read.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    /// `set-point`, `position` or `status`; `other` for a profile's further register.
    pub name: &'static str,
    /// The manual's name and number of the register (with a profile).
    pub manual: Option<(String, u32)>,
    /// Its table.
    pub table: Table,
    /// Its first address, 0-based as on the wire.
    pub address: u16,
    /// Its format (`u16` for the status word).
    pub format: Format,
    /// The words and their meaning, or what went wrong.
    pub result: Result<Value, String>,
    /// Round trip, ms.
    pub ms: f64,
}

/// Register words and what they mean.
#[derive(Debug, Clone, PartialEq)]
pub struct Value {
    /// The words read.
    pub words: Vec<u16>,
    /// What they mean: `42.0 %`, or the status bits.
    pub meaning: String,
}

/// The set-point written by `--write-test`.
#[derive(Debug, Clone, PartialEq)]
pub struct WriteTest {
    /// The O_P asked for, %.
    pub asked_pct: f64,
    /// The value the device received (after scaling and rounding), %, or why it failed.
    pub result: Result<f64, String>,
}

/// What a probe found.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    /// The link, described.
    pub link: String,
    /// The deadline of each request, ms.
    pub timeout_ms: f64,
    /// Every mapped register, read before any write.
    pub before: Vec<Row>,
    /// The write test and the registers read after it.
    pub write: Option<(WriteTest, Vec<Row>)>,
    /// The profile's name and what it says of itself, if the map is a profile's.
    pub profile: Option<(String, String)>,
}

impl Report {
    /// How many register reads failed.
    pub fn failures(&self) -> usize {
        let after = self.write.iter().flat_map(|(_, rows)| rows);
        let failed_write = self.write.iter().filter(|(w, _)| w.result.is_err()).count();
        self.before
            .iter()
            .chain(after)
            .filter(|r| r.result.is_err())
            .count()
            + failed_write
    }
}

/// Reads every register of `valve`'s map (and of `profile`, the profile the map is from), and
/// with `write_test` writes that set-point once and reads them all again.
pub async fn probe(
    valve: &mut ModbusValve,
    write_test: Option<f64>,
    profile: Option<&Profile>,
) -> Report {
    let before = read_all(valve, profile).await;
    let write = match write_test {
        Some(pct) => {
            let result = valve.write_setpoint(pct).await.map_err(|f| fault(&f));
            let test = WriteTest {
                asked_pct: pct,
                result,
            };
            Some((test, read_all(valve, profile).await))
        }
        None => None,
    };
    Report {
        link: valve.describe(),
        timeout_ms: valve.timeout().as_secs_f64() * 1e3,
        before,
        write,
        profile: profile.map(|p| (p.name.to_string(), describe(p))),
    }
}

/// What a profile says of itself, in one line.
fn describe(p: &Profile) -> String {
    let numbers = match p.about.first_number {
        0 => "the manual's numbers are the addresses".to_string(),
        n => format!("manual no. = address + {n}"),
    };
    let kind = if p.about.example {
        "EXAMPLE map, not a device's documented one"
    } else {
        "source"
    };
    format!("{} ({kind}: {}; {numbers})", p.about.device, p.about.source)
}

/// One row per mapped register, then one per further register of the profile.
async fn read_all(valve: &mut ModbusValve, profile: Option<&Profile>) -> Vec<Row> {
    let map = *valve.map();
    let manual = |name: Option<&String>, address: u16| {
        profile.map(|p| (name.cloned().unwrap_or_default(), p.number(address)))
    };
    let names = profile.map(|p| p.names.clone()).unwrap_or_default();
    let mut rows = Vec::with_capacity(3);
    for (name, reg, called) in [
        ("set-point", map.setpoint, names.setpoint.as_ref()),
        ("position", map.position, names.position.as_ref()),
    ] {
        let (result, ms) = timed(valve, reg.table, reg.address, reg.format.width()).await;
        let result = result.map(|words| {
            let meaning = percent(&reg, &words, map.word_order);
            Value { words, meaning }
        });
        rows.push(Row {
            name,
            manual: manual(called, reg.address),
            table: reg.table,
            address: reg.address,
            format: reg.format,
            result,
            ms,
        });
    }
    if let Some(st) = map.status {
        let (result, ms) = timed(valve, st.table, st.address, 1).await;
        let result = result.map(|words| {
            let meaning = status_bits(&st, words.first().copied().unwrap_or(0));
            Value { words, meaning }
        });
        rows.push(Row {
            name: "status",
            manual: manual(names.status.as_ref(), st.address),
            table: st.table,
            address: st.address,
            format: Format::U16,
            result,
            ms,
        });
    }
    for other in profile.map(|p| p.others.as_slice()).unwrap_or_default() {
        let (result, ms) = timed(valve, other.table, other.address, 1).await;
        let result = result.map(|words| {
            let w = words.first().copied().unwrap_or(0);
            let meaning = other.meaning(w).unwrap_or("").to_string();
            Value { words, meaning }
        });
        rows.push(Row {
            name: "other",
            manual: manual(Some(&other.name), other.address),
            table: other.table,
            address: other.address,
            format: Format::U16,
            result,
            ms,
        });
    }
    rows
}

/// Reads `count` registers and times the round trip.
async fn timed(
    valve: &mut ModbusValve,
    table: Table,
    address: u16,
    count: u16,
) -> (Result<Vec<u16>, String>, f64) {
    let started = Instant::now();
    let result = valve.read_registers(table, address, count).await;
    let ms = started.elapsed().as_secs_f64() * 1e3;
    (result.map_err(|f| fault(&f)), ms)
}

fn fault(f: &Fault) -> String {
    f.to_string()
}

/// `42.0 %`, or why the words are no number.
fn percent(reg: &Register, words: &[u16], order: super::map::WordOrder) -> String {
    match reg.decode("value", words, order) {
        Ok(pct) => format!("{pct:.2} %"),
        Err(e) => e.to_string(),
    }
}

/// The bits set in a status word, the set-point error bit named.
fn status_bits(st: &StatusRegister, word: u16) -> String {
    if word == 0 {
        return "no bit set".into();
    }
    let bits: Vec<String> = (0..16)
        .filter(|b| word & (1 << b) != 0)
        .map(|b| {
            if b == st.setpoint_error_bit {
                format!("bit {b} (set-point refused)")
            } else {
                format!("bit {b}")
            }
        })
        .collect();
    bits.join(", ")
}

/// `0x01A4`-style words, decimal first: `420 (0x01A4)`.
fn words(w: &[u16]) -> String {
    let hex: Vec<String> = w.iter().map(|v| format!("0x{v:04X}")).collect();
    let dec: Vec<String> = w.iter().map(|v| v.to_string()).collect();
    format!("{} ({})", dec.join(" "), hex.join(" "))
}

fn table(f: &mut fmt::Formatter<'_>, rows: &[Row]) -> fmt::Result {
    let width = (rows.iter())
        .filter_map(|r| r.manual.as_ref().map(|(n, _)| n.chars().count()))
        .max();
    let manual = |name: &str, no: &str| match width {
        Some(w) => format!(" {name:<w$} {no:>4}"),
        None => String::new(),
    };
    writeln!(
        f,
        "  {:<10}{} {:<8} {:>7}  {:<6} {:<16} {:<18} {:>8}",
        "register",
        manual("manual name", "no."),
        "table",
        "address",
        "format",
        "raw",
        "value",
        "time"
    )?;
    for r in rows {
        let (name, no) = match &r.manual {
            Some((n, no)) => (n.as_str(), no.to_string()),
            None => ("", String::new()),
        };
        let head = format!(
            "  {:<10}{} {:<8} {:>7}  {:<6}",
            r.name,
            manual(name, &no),
            r.table.to_string(),
            r.address,
            r.format.to_string()
        );
        match &r.result {
            Ok(v) => writeln!(
                f,
                "{head} {:<16} {:<18} {:>5.1} ms",
                words(&v.words),
                v.meaning,
                r.ms
            )?,
            Err(e) => writeln!(f, "{head} {e}")?,
        }
    }
    Ok(())
}

impl fmt::Display for Report {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "probe: {} (each request within {:.0} ms; addresses 0-based, as on the wire)",
            self.link, self.timeout_ms
        )?;
        if let Some((name, about)) = &self.profile {
            writeln!(f, "profile {name}: {about}")?;
        }
        table(f, &self.before)?;
        match &self.write {
            None => writeln!(f, "nothing written (--write-test PCT writes one set-point)"),
            Some((w, after)) => {
                match &w.result {
                    Ok(got) => writeln!(
                        f,
                        "write test: set-point {:.2} % written; the device received {got:.2} %",
                        w.asked_pct
                    )?,
                    Err(e) => writeln!(f, "write test: set-point {:.2} %: {e}", w.asked_pct)?,
                }
                writeln!(f, "after the write:")?;
                table(f, after)
            }
        }
    }
}
