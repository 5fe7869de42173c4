//! `valve-bridge probe`: reads every register of a config's map once from the device (see
//! `valve_bridge::modbus::probe`) and prints a table; writes only with `--write-test`. Argument
//! checks and printing only: the probe itself is the library's.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::{bail, Context as _};
use valve_bridge::daemon::config::ValveSpec;
use valve_bridge::daemon::Config;
use valve_bridge::modbus::client::{Link, ModbusValve};
use valve_bridge::modbus::{probe, profile};

/// Arguments of `valve-bridge probe`.
#[derive(clap::Args)]
pub(crate) struct Args {
    /// Daemon config (TOML) with `[valve] kind = "modbus-tcp"` or `"modbus-rtu"`: its link and
    /// its register map (`[valve.registers]`, over its `profile`) are probed; a profile's
    /// registers show their manual names and numbers, and its further registers are read too.
    #[arg(long, value_name = "FILE")]
    config: PathBuf,
    /// Also write this set-point once (%), then read every register again. Nothing is written
    /// without it.
    #[arg(long, value_name = "PCT")]
    write_test: Option<f64>,
    /// Deadline of each request, ms (a probe waits longer than a loop cycle would).
    #[arg(long, value_name = "MS", default_value_t = 1000.0)]
    timeout_ms: f64,
    /// The valve to probe, by `name`, in a config with several `[[valve]]` tables.
    #[arg(long, value_name = "NAME")]
    valve: Option<String>,
}

/// Connects, probes and prints the table; fails if a register could not be read.
pub(crate) fn run(args: Args) -> anyhow::Result<()> {
    if !(args.timeout_ms.is_finite() && (1.0..=60_000.0).contains(&args.timeout_ms)) {
        bail!(
            "--timeout-ms {}: a deadline in ms, 1-60000",
            args.timeout_ms
        );
    }
    if let Some(pct) = args.write_test {
        if !(pct.is_finite() && (0.0..=100.0).contains(&pct)) {
            bail!("--write-test {pct}: a set-point in %, 0-100");
        }
    }
    let config = Config::load(Some(&args.config))?;
    let valve =
        (config.valve(args.valve.as_deref())).with_context(|| args.config.display().to_string())?;
    let (link, device) = match &valve.backend {
        ValveSpec::ModbusTcp(link, device) => (Link::Tcp(link.clone()), device),
        ValveSpec::ModbusRtu(link, device) => (Link::Rtu(link.clone()), device),
        ValveSpec::Emulated(_) => bail!(
            "{}: [valve] kind = \"emulated\" has no device to probe: use a config with kind = \
             \"modbus-tcp\" or \"modbus-rtu\" (e.g. config/sim-device-tcp.toml)",
            args.config.display()
        ),
    };
    let profile = match device.profile.as_deref().map(profile::find) {
        Some(Some(found)) => Some(found?),
        // The config's checks refused an unknown name already.
        Some(None) | None => None,
    };
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("cannot start the async runtime")?;
    let report = rt.block_on(async {
        let mut valve = ModbusValve::new(link, device.registers, config.loop_.period_s())?;
        if let Some(b) = valve.budget() {
            outln!("bus budget of the loop: {}", b.describe())?;
        }
        valve.set_timeout(Duration::from_secs_f64(args.timeout_ms / 1000.0));
        valve.connect_now().await?;
        anyhow::Ok(probe::probe(&mut valve, args.write_test, profile.as_ref()).await)
    })?;
    out!("{report}")?;
    match report.failures() {
        0 => Ok(()),
        n => bail!("{n} of the probe's requests failed (see the table)"),
    }
}
