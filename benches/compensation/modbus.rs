//! The compensation bench over Modbus: each physical valve as a unit of sim-device on loopback
//! TCP, driven by `valve-bridge run` as a user runs it (per-mille set-points and positions, an
//! 8 ms deadline, one reply in 20 late by 3 ms, one request in 500 unanswered), its model
//! diagnosed by `valve-bridge diagnose` from the log that run wrote, then compensated.
//!
//! sim-device runs in real time, so the runs are short and every valve runs at once: one
//! device serves a unit per valve (two in the compensated runs: one with `[valve.compensation]`,
//! one without, driven by the same O_P), one daemon drives them all. The O_P comes from the
//! replayed sequences of the in-process bench (its mixed excitation for the log, its small and
//! random steps for the runs, seed 1); the level loop needs the valve in the loop and is not
//! run here. Figures are the V_P read (noise and 0.1 % resolution included; rows without one
//! are skipped): its RMS against the healthy twin driven by the controller's O_P, and its
//! travel and reversals through [`DEADBAND_PCT`].
//!
//! Not here: the in-process bench and the table's layout (`compensation.rs`).

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

use valve_bridge::compensate::trial::{self, Scenario};
use valve_bridge::metrics;
use valve_bridge::model::{ModelSpec, Valve};
use valve_bridge::recording;
use valve_bridge::signal::{RandomSteps, RandomStepsParams};
use valve_bridge::synth::excite::SmallSteps;
use valve_bridge::synth::{self, physical, Excitation};

use super::Error;

/// The loop's period, s.
const DT: f64 = 0.01;
/// Each replay begins with its first O_P held this long (the device's valve starts at 0 %);
/// the figures start after it, s.
const SETTLE_S: f64 = 10.0;
/// Deadband of the travel count on the V_P read, %: two steps of its 0.1 % resolution.
pub(crate) const DEADBAND_PCT: f64 = 0.2;
/// sim-device's faults: late replies and lost requests, as a busy device and network give.
const FAULTS: [&str; 6] = [
    "--delay-ms",
    "3",
    "--delay-every",
    "20",
    "--drop-prob",
    "0.002",
];
/// The shipped daemon config for sim-device over TCP: its map, link and deadline.
const TCP_CONFIG: &str = include_str!("../../config/sim-device-tcp.toml");

/// One valve's figures over Modbus, without and with compensation.
pub(crate) struct Outcome {
    pub name: String,
    pub scenario: Scenario,
    /// What the diagnosed model compensates.
    pub described: String,
    pub without: Figures,
    pub with: Figures,
    /// When the guard switched compensation off, s.
    pub switched_off_s: Option<f64>,
}

/// Figures of one logged run.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Figures {
    /// RMS of the V_P read minus the healthy twin's, %.
    pub tracking_pct: f64,
    pub travel: metrics::Travel,
    /// Rows that read a V_P, of all.
    pub read: (usize, usize),
}

/// A running sim-device; killed when dropped.
struct Device {
    child: Child,
    endpoint: String,
}

impl Device {
    /// sim-device with one unit per model file, unit ids from 1.
    fn start(bin: &Path, models: &[PathBuf]) -> Result<Device, Error> {
        let mut cmd = Command::new(bin);
        cmd.args(["--tcp", "127.0.0.1:0"]).args(FAULTS);
        for (i, m) in models.iter().enumerate() {
            cmd.arg("--unit").arg(format!("{}={}", i + 1, m.display()));
        }
        let mut child = cmd.stdout(Stdio::piped()).stderr(Stdio::null()).spawn()?;
        let mut line = String::new();
        let stdout = child.stdout.take().ok_or("sim-device gave no stdout")?;
        BufReader::new(stdout).read_line(&mut line)?;
        let endpoint = line.trim().strip_prefix("tcp: ").map(str::to_string);
        match endpoint {
            Some(endpoint) => Ok(Device { child, endpoint }),
            None => Err(format!(
                "sim-device announced `{}`, not its TCP endpoint",
                line.trim()
            )
            .into()),
        }
    }
}

impl Drop for Device {
    fn drop(&mut self) {
        drop(self.child.kill());
        drop(self.child.wait());
    }
}

/// The binaries: valve-bridge as built for this bench, and sim-device built next to it.
fn binaries() -> Result<(PathBuf, PathBuf), Error> {
    let vb = PathBuf::from(env!("CARGO_BIN_EXE_valve-bridge"));
    let status = Command::new(env!("CARGO"))
        .args(["build", "--release", "-p", "sim-device"])
        .status()?;
    if !status.success() {
        return Err("cargo build --release -p sim-device failed".into());
    }
    let sim = vb.with_file_name("sim-device");
    Ok((vb, sim))
}

/// The O_P of `scenario` (or the mixed excitation of the log, `None`) for `secs`, seed 1.
fn op_sequence(scenario: Option<Scenario>, secs: f64, log_seed: u64) -> Result<Vec<f64>, Error> {
    let n = (secs / DT).round() as usize;
    let t = (0..n).map(|k| k as f64 * DT);
    Ok(match scenario {
        None => {
            let ex = Excitation::Mixed { low_pct: 40.0 };
            synth::generate(&physical::healthy(), ex, secs, DT, 0.0, log_seed)?.op
        }
        Some(Scenario::SmallSteps) => {
            let mut s = SmallSteps::new(40.0, 1);
            t.map(|t| s.op_at(t)).collect()
        }
        Some(_) => {
            let mut s = RandomSteps::new(&RandomStepsParams {
                seed: 1,
                ..RandomStepsParams::default()
            });
            t.map(|t| s.op_at(t)).collect()
        }
    })
}

/// `[[valve]]` tables for the device at `endpoint`: one per `(name, compensation model)`,
/// unit ids from 1, each replaying `replay`.
fn daemon_config(endpoint: &str, valves: &[(String, Option<PathBuf>)], replay: &Path) -> String {
    // The shipped config's link and map, as one valve's tables.
    let shipped = TCP_CONFIG
        .split_once("[valve.modbus-tcp]")
        .map_or("", |p| p.1);
    let mut out = String::new();
    for (i, (name, model)) in valves.iter().enumerate() {
        let link = shipped
            .replace("127.0.0.1:5502", endpoint)
            .replace("unit_id = 1", &format!("unit_id = {}", i + 1));
        out += &format!(
            "[[valve]]\nname = \"{name}\"\nkind = \"modbus-tcp\"\n[valve.modbus-tcp]{link}\n"
        );
        if let Some(m) = model {
            out += &format!(
                "[valve.compensation]\nmodel_file = {:?}\n",
                m.display().to_string()
            );
        }
        out += &format!(
            "[valve.source]\nkind = \"replay\"\n[valve.source.replay]\nfile = {:?}\n\n",
            replay.display().to_string()
        );
    }
    out
}

/// Runs the daemon on `valves` (with the models their files name) for `secs`, replaying
/// `op`, in `dir` (emptied first); returns its stdout and each valve's log directory.
fn logged_run(
    (vb, sim): (&Path, &Path),
    dir: &Path,
    valves: &[(String, PathBuf, Option<PathBuf>)],
    op: &[f64],
) -> Result<(String, Vec<PathBuf>), Error> {
    if dir.exists() {
        std::fs::remove_dir_all(dir)?;
    }
    std::fs::create_dir_all(dir)?;
    let replay = dir.join("op.csv");
    let settle = (SETTLE_S / DT).round() as usize;
    let op: Vec<f64> = std::iter::repeat_n(op.first().copied().unwrap_or(0.0), settle)
        .chain(op.iter().copied())
        .collect();
    let t: Vec<f64> = (0..op.len()).map(|k| k as f64 * DT).collect();
    recording::write_columns(&replay, &["t_s", "op_pct"], &[&t, &op])?;
    let models: Vec<PathBuf> = valves.iter().map(|v| v.1.clone()).collect();
    let device = Device::start(sim, &models)?;
    let named: Vec<(String, Option<PathBuf>)> =
        valves.iter().map(|v| (v.0.clone(), v.2.clone())).collect();
    let cfg = dir.join("daemon.toml");
    std::fs::write(&cfg, daemon_config(&device.endpoint, &named, &replay))?;
    let logs = dir.join("logs");
    let out = Command::new(vb)
        .args(["run", "--config"])
        .arg(&cfg)
        .arg("--duration")
        .arg(format!("{}", op.len() as f64 * DT))
        .arg("--log-dir")
        .arg(&logs)
        .env_remove("RUST_LOG")
        .output()?;
    drop(device);
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    if !out.status.success() {
        return Err(format!(
            "valve-bridge run failed:\n{stdout}\n{}",
            String::from_utf8_lossy(&out.stderr)
        )
        .into());
    }
    // Each valve's files (`vb-NAME-STAMP.csv`, more if the log rotated) in a directory of its own.
    let mut dirs = Vec::new();
    for v in valves {
        let own = dir.join(format!("log-{}", v.0));
        std::fs::create_dir_all(&own)?;
        let prefix = format!("vb-{}-", v.0);
        for entry in std::fs::read_dir(&logs)? {
            let path = entry?.path();
            let name = path.file_name().and_then(|f| f.to_str()).unwrap_or("");
            let stamped = name.strip_prefix(&prefix).and_then(|r| r.chars().next());
            if stamped.is_some_and(|c| c.is_ascii_digit()) {
                std::fs::rename(&path, own.join(name))?;
            }
        }
        dirs.push(own);
    }
    Ok((stdout, dirs))
}

/// `valve-bridge diagnose LOG --out DIR`; the model it wrote.
fn diagnose(vb: &Path, log: &Path, out: &Path) -> Result<PathBuf, Error> {
    if out.exists() {
        std::fs::remove_dir_all(out)?;
    }
    let run = Command::new(vb)
        .arg("diagnose")
        .arg(log)
        .arg("--out")
        .arg(out)
        .env_remove("RUST_LOG")
        .output()?;
    if !run.status.success() {
        return Err(format!(
            "valve-bridge diagnose {} failed: {}",
            log.display(),
            String::from_utf8_lossy(&run.stderr)
        )
        .into());
    }
    Ok(out.join("model.toml"))
}

/// A row of a daemon log, the columns read here.
#[derive(serde::Deserialize)]
struct Row {
    t_s: f64,
    op_pct: f64,
    vp_pct: Option<f64>,
    op_controller_pct: Option<f64>,
}

/// The figures of `valve`'s logs in `dir` after the settling hold: V_P read against the
/// healthy twin driven by the controller, from rest at the first O_P.
fn figures(valve: &ModelSpec, dir: &Path) -> Result<Figures, Error> {
    let mut rows: Vec<Row> = Vec::new();
    for entry in std::fs::read_dir(dir)? {
        let mut r = csv::Reader::from_path(entry?.path())?;
        for row in r.deserialize() {
            let row: Row = row?;
            if row.t_s >= SETTLE_S {
                rows.push(row);
            }
        }
    }
    rows.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    let op: Vec<f64> = rows
        .iter()
        .map(|r| r.op_controller_pct.unwrap_or(r.op_pct))
        .collect();
    let twin =
        Valve::new(&trial::nominal(valve), DT)?.simulate(&op, op.first().copied().unwrap_or(0.0));
    let read: Vec<(f64, f64)> = rows
        .iter()
        .zip(&twin)
        .filter_map(|(r, t)| r.vp_pct.map(|v| (v, *t)))
        .collect();
    let sq: f64 = read.iter().map(|(v, t)| (v - t).powi(2)).sum();
    let vp: Vec<f64> = read.iter().map(|p| p.0).collect();
    Ok(Figures {
        tracking_pct: (sq / read.len().max(1) as f64).sqrt(),
        travel: metrics::travel(&vp, DEADBAND_PCT),
        read: (read.len(), rows.len()),
    })
}

/// When the summary says the guard switched `name`'s compensation off, s.
fn switched_off(summary: &str, name: &str) -> Option<f64> {
    let header = format!("valve {name}:");
    let section = summary.split_once(&header)?.1;
    let section = section.split("\nvalve ").next().unwrap_or(section);
    let at = section.split_once("switched off by its guard at ")?.1;
    at.split(' ').next()?.parse().ok()
}

/// Runs the Modbus part on `valves` under `work`: a log of `log_s` per valve, diagnosed, then
/// `run_s` of each scenario without and with compensation; `progress` says what is going on.
pub(crate) fn run(
    valves: &[(String, ModelSpec)],
    work: &Path,
    (log_s, run_s, log_seed): (f64, f64, u64),
    progress: &dyn Fn(&str),
) -> Result<Vec<Outcome>, Error> {
    let (vb, sim) = binaries()?;
    let bins = (vb.as_path(), sim.as_path());
    std::fs::create_dir_all(work)?;
    let mut specs = Vec::new();
    for (i, (_, spec)) in valves.iter().enumerate() {
        let path = work.join(format!("valve-{}.toml", i + 1));
        std::fs::write(&path, spec.to_toml())?;
        specs.push(path);
    }
    progress(&format!(
        "Modbus: logging {} valves for {log_s} s in real time",
        valves.len()
    ));
    let plain: Vec<(String, PathBuf, Option<PathBuf>)> = (0..valves.len())
        .map(|i| (format!("v{}", i + 1), specs[i].clone(), None))
        .collect();
    let (_, logs) = logged_run(
        bins,
        &work.join("log"),
        &plain,
        &op_sequence(None, log_s, log_seed)?,
    )?;
    let mut models = Vec::new();
    for (i, log) in logs.iter().enumerate() {
        progress(&format!("Modbus: diagnosing {}", valves[i].0));
        models.push(diagnose(&vb, log, &work.join(format!("diag-{}", i + 1)))?);
    }
    let described: Vec<String> = models
        .iter()
        .map(|m| super::compensator(m).map(|c| c.describe()))
        .collect::<Result<_, _>>()?;
    let mut out = Vec::new();
    for scenario in [Scenario::SmallSteps, Scenario::RandomSteps] {
        progress(&format!(
            "Modbus: {} for {run_s} s in real time",
            scenario.name()
        ));
        let pairs: Vec<(String, PathBuf, Option<PathBuf>)> = (0..valves.len())
            .flat_map(|i| {
                [
                    (format!("v{}-without", i + 1), specs[i].clone(), None),
                    (
                        format!("v{}-with", i + 1),
                        specs[i].clone(),
                        Some(models[i].clone()),
                    ),
                ]
            })
            .collect();
        let dir = work.join(scenario.name().replace(' ', "-"));
        let (summary, logs) = logged_run(
            bins,
            &dir,
            &pairs,
            &op_sequence(Some(scenario), run_s, log_seed)?,
        )?;
        for (i, (name, spec)) in valves.iter().enumerate() {
            out.push(Outcome {
                name: name.clone(),
                scenario,
                described: described[i].clone(),
                without: figures(spec, &logs[2 * i])?,
                with: figures(spec, &logs[2 * i + 1])?,
                switched_off_s: switched_off(&summary, &pairs[2 * i + 1].0),
            });
        }
    }
    Ok(out)
}
