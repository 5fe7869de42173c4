//! Register profiles of real devices: the shipped `config/profiles/*.toml`, embedded in the
//! binaries. Each is a device's register map as its manual documents it (the manual named in the
//! file), the manual's names of the mapped registers and how it numbers them, the further
//! registers `probe` reads (override, command, device type, ...) with the meanings of their
//! values, and the function codes the device answers (what `sim-device --profile` answers).
//!
//! A `[valve]` picks one with `profile = "NAME"`. Its `[valve.registers]` may still give any key
//! of the map: a key given there replaces the profile's value of that key as a whole (a register
//! is given whole: table, address, format, scale, offset); the keys it leaves out are the
//! profile's. Every error names the file and line of the key at fault: the config's for a key the
//! config gives, the profile's otherwise.
//!
//! ```toml
//! [profile]
//! device = "..."            # what the map is of
//! source = "..."            # the manual: title, edition, the register table
//! first_number = 1          # the manual's number of wire address 0 (0: it gives addresses)
//! functions = [3, 6]        # function codes the device answers (default: any)
//! example = false           # true: an illustrative map, not a device's documented one
//! [registers]               # the map, as [valve.registers]
//! [names]                   # manual names: setpoint, position, status
//! [[read]]                  # further registers probe reads: name, table, address, meanings
//! ```
//!
//! Not here: the map's rules and conversions ([`super::map`]), reading registers
//! ([`super::probe`]), serving them ([`super::server`]).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::map::{RegisterKeys, RegisterMap, Table};
use vb_core::toml_file::{self, Layout, Lines, TomlError};

/// The shipped profiles, by name (each `config/profiles/NAME.toml`).
const SHIPPED: [(&str, &str); 4] = [
    (
        "belimo-uk24mod",
        include_str!("../../../config/profiles/belimo-uk24mod.toml"),
    ),
    (
        "belimo-vav-compact-mod",
        include_str!("../../../config/profiles/belimo-vav-compact-mod.toml"),
    ),
    (
        "burkert-mfc-float",
        include_str!("../../../config/profiles/burkert-mfc-float.toml"),
    ),
    (
        "burkert-style-example",
        include_str!("../../../config/profiles/burkert-style-example.toml"),
    ),
];

/// `[profile]`: what the map is of and where it comes from.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct About {
    /// The device (and which of its registers, for a gateway).
    pub device: String,
    /// The manual: title, edition or date, the register table.
    pub source: String,
    /// The manual's number of wire address 0: 1 when "register 1" is address 0, 0 when the
    /// manual gives addresses.
    pub first_number: u32,
    /// The function codes the device answers (empty: not documented, any).
    #[serde(default)]
    pub functions: Vec<u8>,
    /// An illustrative map, not a device's documented one.
    #[serde(default)]
    pub example: bool,
}

/// `[names]`: the manual's names of the mapped registers.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Names {
    pub setpoint: Option<String>,
    pub position: Option<String>,
    pub status: Option<String>,
}

/// A `[[read]]` register: one word `probe` reads and shows by its manual name.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Other {
    /// Its name in the manual.
    pub name: String,
    /// Holding (default) or input.
    #[serde(default = "holding")]
    pub table: Table,
    /// Its address on the wire.
    pub address: u16,
    /// What its values mean, by value (`0 = "None"`).
    #[serde(default)]
    pub meanings: BTreeMap<String, String>,
}

fn holding() -> Table {
    Table::Holding
}

impl Other {
    /// What `word` means, if the manual names it.
    pub fn meaning(&self, word: u16) -> Option<&str> {
        self.meanings.get(&word.to_string()).map(String::as_str)
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    profile: About,
    registers: RegisterKeys,
    #[serde(default)]
    names: Names,
    #[serde(default, rename = "read")]
    others: Vec<Other>,
}

/// A shipped profile, checked.
#[derive(Debug, Clone, PartialEq)]
pub struct Profile {
    /// Its name (`profile = "NAME"`).
    pub name: &'static str,
    /// `config/profiles/NAME.toml`, as messages name it.
    pub path: PathBuf,
    text: &'static str,
    /// `[profile]`.
    pub about: About,
    /// The map of `[registers]` (over the default map).
    pub map: RegisterMap,
    /// `[names]`.
    pub names: Names,
    /// `[[read]]`, in file order.
    pub others: Vec<Other>,
}

/// The names of the shipped profiles.
pub fn names() -> Vec<&'static str> {
    SHIPPED.iter().map(|(n, _)| *n).collect()
}

/// What to say of a profile name that is not shipped.
pub fn unknown(name: &str) -> String {
    format!(
        "no profile `{name}`: the shipped profiles (config/profiles/) are {}",
        names().join(", ")
    )
}

/// The shipped profile `name`, None if there is none of that name.
pub fn find(name: &str) -> Option<Result<Profile, TomlError>> {
    let &(name, text) = SHIPPED.iter().find(|(n, _)| *n == name)?;
    Some(Profile::parse(
        name,
        text,
        &Path::new("config/profiles").join(format!("{name}.toml")),
    ))
}

impl Profile {
    /// The profile `name` from its `text` (read from `path`), checked.
    fn parse(name: &'static str, text: &'static str, path: &Path) -> Result<Profile, TomlError> {
        let file: File = toml_file::parse(text, path)?;
        let layout = Layout::parse(text);
        let lines = layout.lines();
        let map = RegisterMap::from(file.registers);
        map.check_in(lines, path, "registers")?;
        let bad = |key: &str, message: String| {
            toml_file::invalid(lines, path, Some("profile"), key, message)
        };
        if file.profile.first_number > 1 {
            return Err(bad("first_number", format!("{} is not allowed: 1 when the manual's register 1 is address 0, 0 when it gives addresses", file.profile.first_number)));
        }
        for (nth, o) in file.others.iter().enumerate() {
            if let Some(k) = o.meanings.keys().find(|k| k.parse::<u16>().is_err()) {
                return Err(toml_file::invalid(
                    lines.nth(nth),
                    path,
                    Some("read"),
                    "meanings",
                    format!(
                        "`{k}` in the meanings of `{}` is not a register value (0-65535)",
                        o.name
                    ),
                ));
            }
        }
        Ok(Profile {
            name,
            path: path.to_path_buf(),
            text,
            about: file.profile,
            map,
            names: file.names,
            others: file.others,
        })
    }

    /// The manual's number of wire address `address`.
    pub fn number(&self, address: u16) -> u32 {
        u32::from(address) + self.about.first_number
    }

    /// The map of a config whose `[valve.registers]` (in file `path`, laid out in `lines`,
    /// under `section`) gives `keys`: those keys over this profile's map, checked. An error
    /// names the config's line for a key it gives, the profile's otherwise.
    pub fn under(
        &self,
        keys: &RegisterKeys,
        lines: Lines<'_>,
        path: &Path,
        section: &str,
    ) -> Result<RegisterMap, TomlError> {
        let map = keys.over(self.map);
        let Err(v) = map.validate() else {
            return Ok(map);
        };
        if keys.gives(v.top_key()) {
            let mut e = v.located(lines, path, section);
            if let TomlError::Invalid { message, .. } = &mut e {
                message.push_str(&format!(" (over profile `{}`)", self.name));
            }
            Err(e)
        } else {
            let layout = Layout::parse(self.text);
            let mut e = v.located(layout.lines(), &self.path, "registers");
            if let TomlError::Invalid { message, .. } = &mut e {
                message.push_str(&format!(" (with the [{section}] of {})", path.display()));
            }
            Err(e)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::Format;

    fn shipped(name: &str) -> Profile {
        find(name).unwrap().unwrap()
    }

    #[test]
    fn every_file_in_config_profiles_is_shipped_and_loads() {
        let dir = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../..")).join("config/profiles");
        let mut files: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        files.sort();
        let embedded: Vec<String> = names().iter().map(|n| format!("{n}.toml")).collect();
        assert_eq!(files, embedded, "embed every profile in SHIPPED");
        for n in names() {
            let p = shipped(n);
            assert!(!p.about.source.is_empty() && !p.about.device.is_empty());
            assert!(
                p.names.setpoint.is_some() && p.names.position.is_some(),
                "{n}"
            );
        }
    }

    #[test]
    fn the_belimo_gateway_map_is_in_hundredths_of_a_percent_and_fc6() {
        let p = shipped("belimo-uk24mod");
        assert_eq!((p.map.setpoint.address, p.map.position.address), (0, 3));
        assert_eq!(*p.map.encode_setpoint(42.37).unwrap(), [4237]);
        assert!((p.map.decode_position(&[10_000]).unwrap() - 100.0).abs() < 1e-9);
        assert!(p.map.decode_position(&[10_001]).is_err(), "past 0...10,000");
        assert!(p.map.fc6 && !p.map.fc23);
        assert_eq!(p.about.functions, vec![3, 6]);
        // Manual numbers are 1-based: "Register 4" is address 3.
        assert_eq!(p.number(p.map.position.address), 4);
        let over = &p.others[0];
        assert_eq!(
            (over.name.as_str(), over.meaning(6)),
            ("Override control", Some("Fast_closed"))
        );
        assert_eq!(over.meaning(7), None);
        let mfc = shipped("burkert-mfc-float");
        assert_eq!(mfc.map.setpoint.format, Format::F32);
        assert_eq!(mfc.number(8), 8, "the MFC manual gives addresses");
        assert!(shipped("burkert-style-example").about.example);
    }

    #[test]
    fn config_keys_replace_the_profile_s_whole() {
        let p = shipped("belimo-uk24mod");
        let text =
            "[valve.registers]\nposition = { address = 23, format = \"u16\", scale = 0.01 }\n";
        let keys: RegisterKeys = toml_file::parse::<toml::Table>(text, Path::new("c.toml"))
            .unwrap()["valve"]["registers"]
            .clone()
            .try_into()
            .unwrap();
        let layout = Layout::parse(text);
        let map = p
            .under(
                &keys,
                layout.lines(),
                Path::new("c.toml"),
                "valve.registers",
            )
            .unwrap();
        assert_eq!((map.setpoint.address, map.position.address), (0, 23));
        assert!(map.fc6, "kept from the profile");
        assert_eq!(map.position_valid_pct, [0.0, 100.0]);
        // No keys: the profile's map.
        let none = RegisterKeys::default();
        let empty = Layout::parse("");
        assert_eq!(
            p.under(&none, empty.lines(), Path::new("c.toml"), "valve.registers")
                .unwrap(),
            p.map
        );
    }

    #[test]
    fn a_conflict_is_named_in_the_file_of_the_key_at_fault() {
        let p = shipped("burkert-mfc-float");
        // fc6 with the profile's f32 set-point: the config's key is at fault, at its line (in
        // the second valve's tables).
        let text = "[[valve]]\nname = \"a\"\n[valve.registers]\nfc6 = false\n\n\
                    [[valve]]\nname = \"b\"\nprofile = \"burkert-mfc-float\"\n\
                    [valve.registers]\nfc6 = true\n";
        let keys = RegisterKeys {
            fc6: Some(true),
            ..RegisterKeys::default()
        };
        let layout = Layout::parse(text);
        let e = p
            .under(
                &keys,
                layout.lines().nth(1),
                Path::new("c.toml"),
                "valve.registers",
            )
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("c.toml:10: valve.registers.fc6: true needs a one-register set-point (u16 or i16, not f32)")
                && e.ends_with("(over profile `burkert-mfc-float`)"),
            "{e}"
        );
        let empty = Layout::parse("");
        let err = |keys: RegisterKeys| {
            p.under(&keys, empty.lines(), Path::new("c.toml"), "valve.registers")
                .unwrap_err()
                .to_string()
        };
        // A set-point moved onto the profile's position: the config's setpoint key is at fault.
        let e = err(RegisterKeys {
            setpoint: Some(crate::map::Register {
                table: Table::Input,
                ..p.map.position
            }),
            ..RegisterKeys::default()
        });
        assert!(
            e.starts_with("c.toml:1: valve.registers.setpoint.table"),
            "{e}"
        );
        // A position given over the profile's set-point: the config's position is at fault.
        let e = err(RegisterKeys {
            position: Some(p.map.setpoint),
            ..RegisterKeys::default()
        });
        assert!(
            e.contains("valve.registers.position.address: 8 overlaps setpoint"),
            "{e}"
        );
    }

    #[test]
    fn unknown_names_list_the_shipped_ones() {
        assert!(find("belimo").is_none());
        assert_eq!(
            unknown("belimo"),
            "no profile `belimo`: the shipped profiles (config/profiles/) are belimo-uk24mod, belimo-vav-compact-mod, burkert-mfc-float, burkert-style-example"
        );
    }

    #[test]
    fn a_bad_profile_is_named_at_its_line() {
        let path = Path::new("config/profiles/x.toml");
        let text = "[profile]\ndevice = \"d\"\nsource = \"s\"\nfirst_number = 1\n[registers]\nposition = { address = 0, format = \"u16\" }\n";
        let e = Profile::parse("x", text, path).unwrap_err().to_string();
        assert!(
            e.starts_with(
                "config/profiles/x.toml:6: registers.position.address: 0 overlaps setpoint"
            ),
            "{e}"
        );
        let text = "[profile]\ndevice = \"d\"\nsource = \"s\"\nfirst_number = 2\n[registers]\n";
        let e = Profile::parse("x", text, path).unwrap_err().to_string();
        assert!(
            e.starts_with("config/profiles/x.toml:4: profile.first_number: 2 is not allowed"),
            "{e}"
        );
        let text = "[profile]\ndevice = \"d\"\nsource = \"s\"\nfirst_number = 1\n[registers]\n[[read]]\nname = \"n\"\naddress = 4\nmeanings = { x = \"y\" }\n";
        let e = Profile::parse("x", text, path).unwrap_err().to_string();
        assert!(
            e.starts_with("config/profiles/x.toml:9: read.meanings: `x`"),
            "{e}"
        );
    }
}
