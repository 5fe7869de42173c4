//! The register map of a positioner: where the set-point is written, where the position and the
//! status are read, and how register words convert to percent.
//!
//! The map is configuration (the `[valve.registers]` table), because no public Bürkert Modbus
//! register map exists: the addresses come from the device's manual. The defaults follow
//! Bürkert's fieldbus scaling: set-point CMD as `u16` and position POS as `i16`, both in
//! per-mille (0-1000 = 0-100 %, so `scale = 0.1`); POS may read slightly below 0 or above 1000.
//!
//! ```toml
//! [valve.registers]
//! setpoint = { table = "holding", address = 0, format = "u16", scale = 0.1, offset = 0.0 }
//! position = { table = "holding", address = 1, format = "i16", scale = 0.1, offset = 0.0 }
//! status   = { table = "holding", address = 2, setpoint_error_bit = 0 }   # optional
//! word_order = "big"   # 32-bit formats: "big" = high word first, "little" = low word first
//! fc23 = false         # one Read/Write Multiple Registers transaction per cycle
//! fc6 = false          # write the set-point with Write Single Register (FC 6), not FC 16
//! position_valid_pct = [-10.0, 110.0]   # a position outside is no reading (an error row)
//! ```
//!
//! A position outside `position_valid_pct` is not data: transmitters report "no value" with
//! codes such as -32768 (i16) or 65535 (u16), which would read as -3276.8 % or 6553.5 %.
//!
//! Percent = raw × scale + offset. A key left out takes the default above (or, under a device
//! profile, the profile's value: [`crate::profile`]). This module converts and checks; it
//! does no I/O and knows nothing of function codes beyond which table a register lives in and
//! which write function the set-point takes.

use std::path::Path;

use serde::{Deserialize, Serialize};
use smallvec::{smallvec, SmallVec};

use vb_core::toml_file::{Lines, TomlError};

/// The Modbus table a register lives in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Table {
    /// Holding registers (read FC 3, written FC 6/16, both FC 23).
    Holding,
    /// Input registers (read-only, FC 4).
    Input,
}

impl std::fmt::Display for Table {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Table::Holding => "holding",
            Table::Input => "input",
        })
    }
}

/// The register words of one value: one or two (a 32-bit format), kept inline so that
/// encoding the set-point every cycle allocates nothing.
pub type Words = SmallVec<[u16; 2]>;

/// How a value is stored in one or two registers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    /// Unsigned 16-bit integer, one register.
    U16,
    /// Signed 16-bit integer, one register.
    I16,
    /// Unsigned 32-bit integer, two registers.
    U32,
    /// IEEE 754 single-precision float, two registers.
    F32,
}

impl Format {
    /// Number of 16-bit registers the value takes.
    pub fn width(self) -> u16 {
        match self {
            Format::U16 | Format::I16 => 1,
            Format::U32 | Format::F32 => 2,
        }
    }

    /// The raw values the format can hold (f32: the finite range).
    fn raw_range(self) -> (f64, f64) {
        match self {
            Format::U16 => (0.0, u16::MAX as f64),
            Format::I16 => (i16::MIN as f64, i16::MAX as f64),
            Format::U32 => (0.0, u32::MAX as f64),
            Format::F32 => (f32::MIN as f64, f32::MAX as f64),
        }
    }
}

impl std::fmt::Display for Format {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Format::U16 => "u16",
            Format::I16 => "i16",
            Format::U32 => "u32",
            Format::F32 => "f32",
        })
    }
}

/// Word order of 32-bit values (the bytes inside a register are always big-endian).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum WordOrder {
    /// High word at the lower address (Modbus convention).
    #[default]
    Big,
    /// Low word at the lower address.
    Little,
}

/// One value register: where it is and how raw words convert to percent.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Register {
    /// Holding or input table (default holding).
    #[serde(default = "holding")]
    pub table: Table,
    /// Register address (0-based, as on the wire).
    pub address: u16,
    /// Storage format.
    pub format: Format,
    /// Percent per raw unit (default 0.1: per-mille).
    #[serde(default = "per_mille")]
    pub scale: f64,
    /// Percent at raw 0 (default 0).
    #[serde(default)]
    pub offset: f64,
}

fn holding() -> Table {
    Table::Holding
}

fn per_mille() -> f64 {
    0.1
}

/// The optional mode/status register (always one `u16`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StatusRegister {
    /// Holding or input table (default holding).
    #[serde(default = "holding")]
    pub table: Table,
    /// Register address.
    pub address: u16,
    /// Bit the device sets when it refused a set-point as out of range (default 0).
    #[serde(default)]
    pub setpoint_error_bit: u8,
}

/// Bit of the status word the daemon serves a process controller (`modbus-server` source) set
/// while the valve gives no V_P.
pub const VALVE_FAULT_BIT: u8 = 1;
/// Status word bit set while the watchdog holds the safe O_P.
pub const WATCHDOG_BIT: u8 = 2;
/// Status word bit set while the valve's health is in alarm (with `[health]`).
pub const HEALTH_ALARM_BIT: u8 = 3;

impl StatusRegister {
    /// The mask of the set-point error bit.
    pub fn error_mask(&self) -> u16 {
        1u16.checked_shl(u32::from(self.setpoint_error_bit))
            .unwrap_or(0)
    }
}

/// The register map of one positioner (see the module documentation). Read from TOML through
/// [`RegisterKeys`]: a key left out keeps its [`Default`].
///
/// ```
/// use vb_modbus::map::RegisterMap;
///
/// // The default map: O_P written and V_P read in per mille of travel.
/// let map = RegisterMap::default();
/// let words = map.encode_setpoint(45.67)?;
/// assert_eq!(*words, [457]);
/// assert!((map.decode_position(&[457])? - 45.7).abs() < 1e-9);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(from = "RegisterKeys")]
pub struct RegisterMap {
    /// Where O_P is written (holding table).
    pub setpoint: Register,
    /// Where V_P is read.
    pub position: Register,
    /// Optional mode/status register, read each cycle when present.
    pub status: Option<StatusRegister>,
    /// Word order of 32-bit formats.
    pub word_order: WordOrder,
    /// Use one Read/Write Multiple Registers (FC 23) transaction per cycle.
    pub fc23: bool,
    /// Write the set-point with Write Single Register (FC 6) instead of Write Multiple Registers
    /// (FC 16), for devices that know only FC 3 and 6.
    pub fc6: bool,
    /// The positions a reading can have, %: one outside is an error, not a V_P.
    pub position_valid_pct: [f64; 2],
}

/// The keys of a `[valve.registers]` table as written: each one given or not. Laid over a base
/// map ([`RegisterKeys::over`]): the default map, or a device profile's.
#[derive(Debug, Clone, Copy, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegisterKeys {
    pub setpoint: Option<Register>,
    pub position: Option<Register>,
    pub status: Option<StatusRegister>,
    pub word_order: Option<WordOrder>,
    pub fc23: Option<bool>,
    pub fc6: Option<bool>,
    pub position_valid_pct: Option<[f64; 2]>,
}

impl RegisterKeys {
    /// `base` with every given key replaced as a whole (a register is given whole).
    pub fn over(&self, base: RegisterMap) -> RegisterMap {
        RegisterMap {
            setpoint: self.setpoint.unwrap_or(base.setpoint),
            position: self.position.unwrap_or(base.position),
            status: self.status.or(base.status),
            word_order: self.word_order.unwrap_or(base.word_order),
            fc23: self.fc23.unwrap_or(base.fc23),
            fc6: self.fc6.unwrap_or(base.fc6),
            position_valid_pct: self.position_valid_pct.unwrap_or(base.position_valid_pct),
        }
    }

    /// True when the key `top` (`setpoint`, `fc23`, ...) is given.
    pub fn gives(&self, top: &str) -> bool {
        match top {
            "setpoint" => self.setpoint.is_some(),
            "position" => self.position.is_some(),
            "status" => self.status.is_some(),
            "word_order" => self.word_order.is_some(),
            "fc23" => self.fc23.is_some(),
            "fc6" => self.fc6.is_some(),
            "position_valid_pct" => self.position_valid_pct.is_some(),
            _ => false,
        }
    }
}

impl From<RegisterKeys> for RegisterMap {
    fn from(keys: RegisterKeys) -> RegisterMap {
        keys.over(RegisterMap::default())
    }
}

fn default_setpoint() -> Register {
    Register {
        table: Table::Holding,
        address: 0,
        format: Format::U16,
        scale: 0.1,
        offset: 0.0,
    }
}

fn default_position() -> Register {
    Register {
        table: Table::Holding,
        address: 1,
        format: Format::I16,
        scale: 0.1,
        offset: 0.0,
    }
}

impl Default for RegisterMap {
    fn default() -> Self {
        RegisterMap {
            setpoint: default_setpoint(),
            position: default_position(),
            status: None,
            word_order: WordOrder::Big,
            fc23: false,
            fc6: false,
            position_valid_pct: [-10.0, 110.0],
        }
    }
}

impl RegisterMap {
    /// The default map with a status word in holding register 2 (set-point error in bit 0): the
    /// map of the shipped sim-device configs, what sim-device serves without `--config`, and
    /// what the daemon's Modbus server for a process controller serves by default.
    pub fn device_default() -> RegisterMap {
        RegisterMap {
            status: Some(StatusRegister {
                table: Table::Holding,
                address: 2,
                setpoint_error_bit: 0,
            }),
            ..RegisterMap::default()
        }
    }
}

/// A rule of the map that is broken: the key inside the map section and what is allowed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{key}: {message}")]
pub struct MapViolation {
    /// Key relative to the map section, e.g. `position.address`.
    pub key: String,
    /// What is wrong and what is allowed.
    pub message: String,
}

/// A value that does not fit a register.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ValueError {
    /// The percent value converts to a raw value the format cannot hold.
    #[error("{what} {pct} % is raw {raw} at scale {scale}, offset {offset}: outside {format} ({lo} to {hi})")]
    OutOfFormat {
        what: &'static str,
        pct: f64,
        raw: f64,
        scale: f64,
        offset: f64,
        format: Format,
        lo: f64,
        hi: f64,
    },
    /// The position read is outside `position_valid_pct` (a "no value" code, most often).
    #[error("{what} reads {words:04X?} = {pct} %, outside its valid range {lo} to {hi} % (position_valid_pct): a transmitter's no-value code, or a wrong scale")]
    Invalid {
        what: &'static str,
        words: Vec<u16>,
        pct: f64,
        lo: f64,
        hi: f64,
    },
    /// The register words are not a number (f32 NaN or infinity) or too few words arrived.
    #[error("{what}: registers {words:04X?} do not hold a finite {format} value")]
    NotANumber {
        what: &'static str,
        words: Vec<u16>,
        format: Format,
    },
}

impl Register {
    /// The register addresses `address .. address + width` as a half-open range of u32.
    pub fn span(&self) -> std::ops::Range<u32> {
        let a = u32::from(self.address);
        a..a + u32::from(self.format.width())
    }

    /// Converts `pct` to register words; integers are rounded to the nearest raw unit.
    pub fn encode(
        &self,
        what: &'static str,
        pct: f64,
        order: WordOrder,
    ) -> Result<Words, ValueError> {
        let raw = (pct - self.offset) / self.scale;
        let raw = if self.format == Format::F32 {
            raw
        } else {
            raw.round()
        };
        let (lo, hi) = self.format.raw_range();
        if !(raw >= lo && raw <= hi) {
            return Err(ValueError::OutOfFormat {
                what,
                pct,
                raw,
                scale: self.scale,
                offset: self.offset,
                format: self.format,
                lo,
                hi,
            });
        }
        Ok(self.raw_to_words(raw, order))
    }

    /// Like [`Register::encode`] but saturates at the format's limits (a device reporting a
    /// position never fails; NaN reads as 0).
    pub fn encode_saturating(&self, pct: f64, order: WordOrder) -> Words {
        let raw = (pct - self.offset) / self.scale;
        let raw = if self.format == Format::F32 {
            raw
        } else {
            raw.round()
        };
        let (lo, hi) = self.format.raw_range();
        let raw = if raw.is_nan() { 0.0 } else { raw.clamp(lo, hi) };
        self.raw_to_words(raw, order)
    }

    fn raw_to_words(&self, raw: f64, order: WordOrder) -> Words {
        // `raw` is inside the format's range here, so the casts are exact (or f32 rounding).
        let pair = |v: u32| -> Words {
            let (hi, lo) = ((v >> 16) as u16, v as u16);
            match order {
                WordOrder::Big => smallvec![hi, lo],
                WordOrder::Little => smallvec![lo, hi],
            }
        };
        match self.format {
            Format::U16 => smallvec![raw as u16],
            Format::I16 => smallvec![raw as i16 as u16],
            Format::U32 => pair(raw as u32),
            Format::F32 => pair((raw as f32).to_bits()),
        }
    }

    /// Converts register words (exactly `width` of them, more are ignored) to percent.
    pub fn decode(
        &self,
        what: &'static str,
        words: &[u16],
        order: WordOrder,
    ) -> Result<f64, ValueError> {
        let bad = || ValueError::NotANumber {
            what,
            words: words.to_vec(),
            format: self.format,
        };
        let joined = || -> Option<u32> {
            let (a, b) = (*words.first()?, *words.get(1)?);
            let (hi, lo) = match order {
                WordOrder::Big => (a, b),
                WordOrder::Little => (b, a),
            };
            Some((u32::from(hi) << 16) | u32::from(lo))
        };
        let raw = match self.format {
            Format::U16 => f64::from(*words.first().ok_or_else(bad)?),
            Format::I16 => f64::from(*words.first().ok_or_else(bad)? as i16),
            Format::U32 => f64::from(joined().ok_or_else(bad)?),
            Format::F32 => f64::from(f32::from_bits(joined().ok_or_else(bad)?)),
        };
        let pct = raw * self.scale + self.offset;
        if pct.is_finite() {
            Ok(pct)
        } else {
            Err(bad())
        }
    }
}

impl RegisterMap {
    /// Every broken rule, first the most basic.
    pub fn violations(&self) -> Vec<MapViolation> {
        let mut out = Vec::new();
        let mut bad = |key: &str, message: String| {
            out.push(MapViolation {
                key: key.to_string(),
                message,
            })
        };
        for (name, r) in [("setpoint", &self.setpoint), ("position", &self.position)] {
            if !(r.scale.is_finite() && r.scale != 0.0) {
                bad(&format!("{name}.scale"), format!("{} is not allowed: percent per raw unit, finite and not 0 (0.1 for per-mille)", r.scale));
            }
            if !r.offset.is_finite() {
                bad(
                    &format!("{name}.offset"),
                    format!("{} is not allowed: percent at raw 0, finite", r.offset),
                );
            }
            if r.span().end > 0x1_0000 {
                bad(&format!("{name}.address"), format!("{} is not allowed: a {} takes {} registers, so the address must be at most {}",
                    r.address, r.format, r.format.width(), 0x1_0000 - u32::from(r.format.width())));
            }
        }
        let [lo, hi] = self.position_valid_pct;
        if !(lo.is_finite() && hi.is_finite() && lo < hi) {
            bad(
                "position_valid_pct",
                format!("[{lo}, {hi}] is not allowed: two finite percentages, the lower first (default [-10.0, 110.0])"),
            );
        }
        if self.setpoint.table != Table::Holding {
            bad("setpoint.table", "\"input\" is not allowed: input registers are read-only; the set-point must be a holding register".into());
        }
        if self.fc6 && (self.fc23 || self.setpoint.format.width() != 1) {
            bad("fc6", format!("true needs a one-register set-point (u16 or i16, not {}) and fc23 = false: FC 6 writes one register", self.setpoint.format));
        }
        if self.fc23 && self.position.table != Table::Holding {
            bad("fc23", "true needs position.table = \"holding\": FC 23 reads holding registers only (or set fc23 = false)".into());
        }
        let mut spans: Vec<(&str, Table, std::ops::Range<u32>)> = vec![
            ("setpoint", self.setpoint.table, self.setpoint.span()),
            ("position", self.position.table, self.position.span()),
        ];
        if let Some(s) = &self.status {
            if s.setpoint_error_bit > 15 {
                bad(
                    "status.setpoint_error_bit",
                    format!("{} is not allowed: a bit number 0-15", s.setpoint_error_bit),
                );
            }
            let a = u32::from(s.address);
            spans.push(("status", s.table, a..a + 1));
        }
        for (i, (name_a, table_a, a)) in spans.iter().enumerate() {
            for (name_b, table_b, b) in &spans[i + 1..] {
                if table_a == table_b && a.start < b.end && b.start < a.end {
                    bad(&format!("{name_b}.address"), format!(
                        "{} overlaps {name_a} ({table_a} registers {}-{}): give each value its own registers",
                        b.start, a.start, a.end - 1));
                }
            }
        }
        out
    }

    /// Checks the map; the error names the key inside the map section.
    pub fn validate(&self) -> Result<(), MapViolation> {
        match self.violations().into_iter().next() {
            None => Ok(()),
            Some(v) => Err(v),
        }
    }

    /// Checks a map read from file `path` (laid out in `lines`) under `[section]`, e.g.
    /// `valve.registers`: the error names the file, the line and the full dotted key.
    pub fn check_in(&self, lines: Lines<'_>, path: &Path, section: &str) -> Result<(), TomlError> {
        match self.validate() {
            Ok(()) => Ok(()),
            Err(v) => Err(v.located(lines, path, section)),
        }
    }
}

impl MapViolation {
    /// The key of the map section it is about (`setpoint` for `setpoint.address`).
    pub fn top_key(&self) -> &str {
        self.key.split_once('.').map_or(&self.key, |(top, _)| top)
    }

    /// This violation of a map read from file `path` (laid out in `lines`) under `[section]`,
    /// at the line that sets its key (else the section's header, else line 1).
    pub fn located(self, lines: Lines<'_>, path: &Path, section: &str) -> TomlError {
        // Keys are `name.sub` (an inline table `name = { sub = .. }` or a `[section.name]` table) or `name`.
        let (top, sub) = self.key.split_once('.').unwrap_or((&self.key, ""));
        let line = (lines.of(Some(section), top))
            .or_else(|| lines.of(Some(&format!("{section}.{top}")), sub))
            .or_else(|| lines.of(Some(section), ""))
            .unwrap_or(1);
        TomlError::Invalid {
            path: path.to_path_buf(),
            line,
            key: format!("{section}.{}", self.key),
            message: self.message,
        }
    }
}

impl RegisterMap {
    /// The set-point as register words.
    pub fn encode_setpoint(&self, pct: f64) -> Result<Words, ValueError> {
        self.setpoint.encode("set-point", pct, self.word_order)
    }

    /// The position in percent from its register words; one outside `position_valid_pct` is an
    /// error.
    pub fn decode_position(&self, words: &[u16]) -> Result<f64, ValueError> {
        let pct = self.position.decode("position", words, self.word_order)?;
        let [lo, hi] = self.position_valid_pct;
        if (lo..=hi).contains(&pct) {
            Ok(pct)
        } else {
            let width = usize::from(self.position.format.width()).min(words.len());
            Err(ValueError::Invalid {
                what: "position",
                words: words[..width].to_vec(),
                pct,
                lo,
                hi,
            })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use vb_core::toml_file::{self, Layout};

    fn parse(text: &str) -> Result<RegisterMap, TomlError> {
        #[derive(Deserialize)]
        struct Doc {
            registers: RegisterMap,
        }
        let doc: Doc = toml_file::parse(text, Path::new("m.toml"))?;
        let layout = Layout::parse(text);
        doc.registers
            .check_in(layout.lines(), Path::new("m.toml"), "registers")?;
        Ok(doc.registers)
    }

    #[test]
    fn defaults_are_burkert_per_mille() {
        let m = parse("[registers]\n").unwrap();
        assert_eq!(m, RegisterMap::default());
        assert_eq!(*m.encode_setpoint(50.0).unwrap(), [500]);
        assert_eq!(*m.encode_setpoint(100.0).unwrap(), [1000]);
        assert_eq!(*m.encode_setpoint(12.34).unwrap(), [123]);
        // POS is an INT: slightly below 0 reads as a negative per-mille value.
        assert!((m.decode_position(&[(-3i16) as u16]).unwrap() + 0.3).abs() < 1e-12);
        assert!((m.decode_position(&[1004]).unwrap() - 100.4).abs() < 1e-12);
        // A negative set-point does not fit a u16.
        let err = m.encode_setpoint(-1.0).unwrap_err().to_string();
        assert!(err.contains("outside u16"), "{err}");
        // An i16 transmitter's "no value" is no position.
        let err = m.decode_position(&[0x8000]).unwrap_err().to_string();
        assert_eq!(
            err,
            "position reads [8000] = -3276.8 %, outside its valid range -10 to 110 % \
             (position_valid_pct): a transmitter's no-value code, or a wrong scale"
        );
        assert!(m.decode_position(&[1101]).is_err() && m.decode_position(&[1100]).is_ok());
        let narrow = parse("[registers]\nposition_valid_pct = [0.0, 100.0]\n").unwrap();
        assert!(narrow.decode_position(&[(-3i16) as u16]).is_err());
        let err = parse("[registers]\nposition_valid_pct = [100.0, 0.0]\n").unwrap_err();
        assert!(
            err.to_string()
                .starts_with("m.toml:2: registers.position_valid_pct: [100, 0] is not allowed"),
            "{err}"
        );
    }

    #[test]
    fn thirty_two_bit_formats_honour_word_order() {
        let mut r = Register {
            table: Table::Holding,
            address: 10,
            format: Format::U32,
            scale: 0.001,
            offset: 0.0,
        };
        assert_eq!(
            *r.encode("x", 70.0, WordOrder::Big).unwrap(),
            [0x0001, 0x1170]
        );
        assert_eq!(
            *r.encode("x", 70.0, WordOrder::Little).unwrap(),
            [0x1170, 0x0001]
        );
        assert!((r.decode("x", &[0x1170, 0x0001], WordOrder::Little).unwrap() - 70.0).abs() < 1e-9);
        r.format = Format::F32;
        r.scale = 1.0;
        let w = r.encode("x", 42.5, WordOrder::Big).unwrap();
        assert_eq!(*w, [0x422A, 0x0000]);
        assert_eq!(r.decode("x", &w, WordOrder::Big).unwrap(), 42.5);
        let nan = f32::NAN.to_bits();
        let err = r
            .decode("x", &[(nan >> 16) as u16, nan as u16], WordOrder::Big)
            .unwrap_err();
        assert!(matches!(err, ValueError::NotANumber { .. }));
        assert!(
            r.decode("x", &[1], WordOrder::Big).is_err(),
            "one word is not an f32"
        );
    }

    #[test]
    fn saturating_encode_never_fails() {
        let m = RegisterMap::default();
        assert_eq!(
            *m.position.encode_saturating(-5000.0, WordOrder::Big),
            [i16::MIN as u16]
        );
        assert_eq!(*m.position.encode_saturating(f64::NAN, WordOrder::Big), [0]);
        assert_eq!(*m.setpoint.encode_saturating(-1.0, WordOrder::Big), [0]);
    }

    #[test]
    fn offset_and_scale_are_applied() {
        // 4-20 mA style: raw 0-16000 is 0-100 % with 4000 counts offset.
        let r = Register {
            table: Table::Input,
            address: 0,
            format: Format::U16,
            scale: 100.0 / 16000.0,
            offset: -25.0,
        };
        assert_eq!(*r.encode("x", 0.0, WordOrder::Big).unwrap(), [4000]);
        assert!((r.decode("x", &[20000], WordOrder::Big).unwrap() - 100.0).abs() < 1e-9);
    }

    #[test]
    fn bad_format_is_named_with_line() {
        let text = "[registers]\nposition = { address = 1, format = \"u64\" }\n";
        let err = parse(text).unwrap_err().to_string();
        assert!(
            err.starts_with("m.toml:2: registers.position.format: unknown variant `u64`"),
            "{err}"
        );
        assert!(err.contains("u16"), "{err}");
    }

    #[test]
    fn overlap_is_named_with_line() {
        let text = "[registers]\nsetpoint = { address = 4, format = \"u32\" }\nposition = { address = 5, format = \"i16\" }\n";
        let err = parse(text).unwrap_err().to_string();
        assert!(
            err.starts_with(
                "m.toml:3: registers.position.address: 5 overlaps setpoint (holding registers 4-5)"
            ),
            "{err}"
        );
        // Same addresses in different tables do not overlap.
        let text = "[registers]\nposition = { table = \"input\", address = 0, format = \"i16\" }\n";
        parse(text).unwrap();
    }

    #[test]
    fn other_rules_name_their_key() {
        let cases = [
            (
                "setpoint = { table = \"input\", address = 0, format = \"u16\" }",
                "registers.setpoint.table",
            ),
            (
                "position = { address = 1, format = \"i16\", scale = 0.0 }",
                "registers.position.scale",
            ),
            (
                "position = { address = 65535, format = \"f32\" }",
                "registers.position.address",
            ),
            (
                "status = { address = 9, setpoint_error_bit = 16 }",
                "registers.status.setpoint_error_bit",
            ),
            (
                "fc23 = true\nposition = { table = \"input\", address = 1, format = \"i16\" }",
                "registers.fc23",
            ),
            ("status = { address = 1 }", "registers.status.address"),
        ];
        for (body, key) in cases {
            let err = parse(&format!("[registers]\n{body}\n"))
                .unwrap_err()
                .to_string();
            assert!(err.contains(&format!(": {key}: ")), "{body}: {err}");
            assert!(
                err.starts_with("m.toml:2:") || err.starts_with("m.toml:3:"),
                "{err}"
            );
        }
    }

    #[test]
    fn sub_table_form_is_located() {
        let text =
            "[registers]\nfc23 = false\n[registers.position]\naddress = 0\nformat = \"i16\"\n";
        let err = parse(text).unwrap_err().to_string();
        assert!(
            err.starts_with("m.toml:4: registers.position.address"),
            "{err}"
        );
    }
}
