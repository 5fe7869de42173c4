//! The compensation bench over Modbus, on foreign valves: physical valves with physics the
//! composed model `diagnose` fits does not have ([`physical::foreign`]: static friction above
//! the Coulomb band, a chamber that grows with travel, venting slower than filling, a sensor of
//! 0.05 % noise), each
//! a unit of sim-device on loopback TCP, driven by `valve-bridge run` as a user runs it
//! (per-mille set-points and positions, an 8 ms deadline, one reply in 20 late by 3 ms, one
//! request in 500 unanswered), in real time.
//!
//! Each valve first logs its own small steps ([`LOG_SEED`]; 0.2-2 %, held 2-10 s, staying
//! around 50 % and reversing often: [`SmallSteps::staying`]), and `valve-bridge diagnose`
//! writes its model from that log. Then, all at once (one
//! device serving a unit per run, one daemon driving them all, the same O_P to each):
//!
//! - other small steps (seed 1), each valve without compensation, with it (default guard) and
//!   with it while the guard does not judge (a guard window longer than the run), and the
//!   healthy valve given the 1.5 % valve's model (with the guard, and without its judging);
//! - the sequence 50-49-51-49.5-48-49 % twice, each level held [`SEQUENCE_HOLD_S`], the same
//!   way.
//!
//! Figures are on the stem, not on its sensor: each valve's noise-free copy replays the
//! set-points the log says were sent, rounded to the register's 0.1 % (the device's valve starts
//! at 0 % and steps at 100 Hz from the last set-point received, so the copy is the device's stem
//! but for the phase of its clock, under one sample). The tracking error is the RMS of that
//! stem minus the healthy twin's driven by the controller's O_P, after [`SETTLE_S`]; travel and
//! reversals are the stem's through 0.1 %; the sequence is judged by where the stem is at the
//! end of each hold.
//!
//! Not here: the in-process bench and the tables' layout (`compensation.rs`).

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

use valve_bridge::compensation_trial::{self as trial, TRAVEL_DEADBAND_PCT};
use valve_bridge::diagnose::Effect;
use valve_bridge::metrics;
use valve_bridge::model::{ModelSpec, Valve};
use valve_bridge::recording;
use valve_bridge::synth::excite::SmallSteps;
use valve_bridge::synth::physical;

use super::Error;

/// The loop's period, s.
const DT: f64 = 0.01;
/// Each replay begins with its first O_P held this long (the device's valve starts at 0 %);
/// the figures start after it, s. As long as a hold of the sequence: the settling hold is its
/// first.
const SETTLE_S: f64 = 10.0;
/// Seed of the identification logs' small steps (the runs use seed 1).
pub(crate) const LOG_SEED: u64 = 1000;
/// A guard window longer than any run: the guard never judges.
const NO_JUDGING_WINDOW_S: f64 = 86400.0;
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

/// The foreign valves ([`physical::foreign`]): the healthy physical valve, 1 and 1.5 % Coulomb
/// bands and a 0.6 % positioner deadband.
pub(crate) fn valves() -> Vec<(String, ModelSpec)> {
    let foreign = |v: ModelSpec| physical::foreign(v, 0.0);
    vec![
        ("healthy".into(), foreign(physical::healthy())),
        (
            "1 % band".into(),
            foreign(physical::with_effect(Effect::Backlash, 1.0)),
        ),
        (
            "1.5 % band".into(),
            foreign(physical::with_effect(Effect::Backlash, 1.5)),
        ),
        (
            "0.6 % deadband".into(),
            foreign(physical::with_effect(Effect::Deadband, 0.6)),
        ),
    ]
}

/// How a run compensates.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Variant {
    Without,
    /// With the default guard.
    Guarded,
    /// With compensation, the guard never judging.
    Unguarded,
}

impl Variant {
    pub(crate) const ALL: [Variant; 3] = [Variant::Without, Variant::Guarded, Variant::Unguarded];
}

/// One run of a scenario: a valve, the model compensating it (an index into the valves, whose
/// diagnosed model it is) and how.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Case {
    pub valve: usize,
    pub model: usize,
    pub variant: Variant,
}

/// A run's figures.
#[derive(Debug, Clone)]
pub(crate) struct Figures {
    /// RMS of the stem minus the healthy twin's, %.
    pub tracking_pct: f64,
    /// The stem's travel and reversals.
    pub travel: metrics::Travel,
    /// Rows that read a V_P, of all.
    pub read: (usize, usize),
    /// The stem minus the target at the end of each hold of the sequence, % (sequence only).
    pub ends: Vec<f64>,
    /// When the guard switched compensation off, s, and why (the daemon's summary).
    pub switched_off: Option<(f64, String)>,
}

/// What the Modbus part found.
pub(crate) struct Outcome {
    pub names: Vec<String>,
    /// What each valve's diagnosed model compensates.
    pub described: Vec<String>,
    pub cases: Vec<Case>,
    /// Per case: the small steps, then the sequence.
    pub small: Vec<Figures>,
    pub sequence: Vec<Figures>,
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
        .args(["build", "--release", "--locked", "-p", "sim-device"])
        .status()?;
    if !status.success() {
        return Err("cargo build --release -p sim-device failed".into());
    }
    let sim = vb.with_file_name("sim-device");
    Ok((vb, sim))
}

/// Small steps staying around 50 % for `secs`, `seed`.
fn small_steps(secs: f64, seed: u64) -> Vec<f64> {
    let mut s = SmallSteps::staying(50.0, seed);
    (0..(secs / DT).round() as usize)
        .map(|k| s.op_at(k as f64 * DT))
        .collect()
}

/// The sequence of the deadband test after its first hold (the settling hold is that): each
/// level of [`trial::SEQUENCE`] twice, held [`trial::SEQUENCE_HOLD_S`].
fn sequence() -> Vec<f64> {
    let n = (2 * trial::SEQUENCE.len()) as f64 * trial::SEQUENCE_HOLD_S / DT;
    (0..n.round() as usize)
        .map(|k| trial::sequence_at(trial::SEQUENCE_HOLD_S + k as f64 * DT))
        .collect()
}

/// One unit of a daemon run: its name, the valve's spec file and its `[valve.compensation]`
/// table (empty: none).
struct Unit {
    name: String,
    spec: PathBuf,
    compensation: String,
}

/// `[[valve]]` tables for the device at `endpoint`, unit ids from 1, each replaying `replay`.
fn daemon_config(endpoint: &str, units: &[Unit], replay: &Path) -> String {
    // The shipped config's link and map, as one valve's tables.
    let shipped = TCP_CONFIG
        .split_once("[valve.modbus-tcp]")
        .map_or("", |p| p.1);
    let mut out = String::new();
    for (i, u) in units.iter().enumerate() {
        let link = shipped
            .replace("127.0.0.1:5502", endpoint)
            .replace("unit_id = 1", &format!("unit_id = {}", i + 1));
        out += &format!(
            "[[valve]]\nname = \"{}\"\nkind = \"modbus-tcp\"\n[valve.modbus-tcp]{link}\n{}",
            u.name, u.compensation
        );
        out += &format!(
            "[valve.source]\nkind = \"replay\"\n[valve.source.replay]\nfile = {:?}\n\n",
            replay.display().to_string()
        );
    }
    out
}

/// Runs the daemon on `units` for the length of `op` after the settling hold at `settle_at`,
/// replaying it, in `dir` (emptied first); returns its stdout and each unit's log directory.
fn logged_run(
    (vb, sim): (&Path, &Path),
    dir: &Path,
    units: &[Unit],
    (settle_at, op): (f64, &[f64]),
) -> Result<(String, Vec<PathBuf>), Error> {
    if dir.exists() {
        std::fs::remove_dir_all(dir)?;
    }
    std::fs::create_dir_all(dir)?;
    let replay = dir.join("op.csv");
    let settle = (SETTLE_S / DT).round() as usize;
    let op: Vec<f64> = std::iter::repeat_n(settle_at, settle)
        .chain(op.iter().copied())
        .collect();
    let t: Vec<f64> = (0..op.len()).map(|k| k as f64 * DT).collect();
    recording::write_columns(&replay, &["t_s", "op_pct"], &[&t, &op])?;
    let specs: Vec<PathBuf> = units.iter().map(|u| u.spec.clone()).collect();
    let device = Device::start(sim, &specs)?;
    let cfg = dir.join("daemon.toml");
    std::fs::write(&cfg, daemon_config(&device.endpoint, units, &replay))?;
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
    // Each unit's files (`vb-NAME-STAMP.csv`, more if the log rotated) in a directory of its own.
    let mut dirs = Vec::new();
    for u in units {
        let own = dir.join(format!("log-{}", u.name));
        std::fs::create_dir_all(&own)?;
        let prefix = format!("vb-{}-", u.name);
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

/// The rows of the log in `dir` after the settling hold (the device's valve strokes from 0 %
/// to the first O_P in it, which no small-step log has), as one file in `out`.
fn settled(dir: &Path, out: &Path) -> Result<PathBuf, Error> {
    let mut files: Vec<PathBuf> = (std::fs::read_dir(dir)?)
        .map(|e| e.map(|e| e.path()))
        .collect::<Result<_, _>>()?;
    // Stamped names: in time order.
    files.sort();
    let mut text = String::new();
    for file in files {
        let file = std::fs::read_to_string(file)?;
        let mut lines = file.lines();
        let header = lines.next().unwrap_or_default();
        if text.is_empty() {
            text = format!("{header}\n");
        }
        for line in lines {
            let t: f64 = line.split(',').next().unwrap_or_default().parse()?;
            if t >= SETTLE_S - 1e-9 {
                text += line;
                text.push('\n');
            }
        }
    }
    if out.exists() {
        std::fs::remove_dir_all(out)?;
    }
    std::fs::create_dir_all(out)?;
    let path = out.join("small-steps.csv");
    std::fs::write(&path, text)?;
    Ok(path)
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

/// The rows of the logs in `dir`, in time order.
fn rows(dir: &Path) -> Result<Vec<Row>, Error> {
    let mut rows: Vec<Row> = Vec::new();
    for entry in std::fs::read_dir(dir)? {
        let mut r = csv::Reader::from_path(entry?.path())?;
        for row in r.deserialize() {
            rows.push(row?);
        }
    }
    rows.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    Ok(rows)
}

/// `x` as a per-mille register holds it, %.
fn per_mille(x: f64) -> f64 {
    (x * 10.0).round() / 10.0
}

/// The figures of `valve`'s logs in `dir`: its stem (the set-points sent, replayed through its
/// noise-free copy from 0 %) against the healthy twin driven by the controller's O_P, after
/// the settling hold; with `sequence`, where the stem ends each hold of the sequence.
fn figures(valve: &ModelSpec, dir: &Path, sequence: bool) -> Result<Figures, Error> {
    let rows = rows(dir)?;
    let sent: Vec<f64> = rows.iter().map(|r| per_mille(r.op_pct)).collect();
    let op: Vec<f64> = rows
        .iter()
        .map(|r| per_mille(r.op_controller_pct.unwrap_or(r.op_pct)))
        .collect();
    let simulate = |spec: &ModelSpec, u: &[f64]| -> Result<Vec<f64>, Error> {
        let mut v = Valve::new(spec, DT)?;
        v.reset(0.0, 0.0);
        Ok(u.iter().map(|&x| v.step(x)).collect())
    };
    let stem_all = simulate(&trial::noise_free(valve), &sent)?;
    let twin = simulate(&trial::nominal(valve), &op)?;
    let from = rows.partition_point(|r| r.t_s < SETTLE_S - 1e-9);
    let (stem, twin) = (&stem_all[from..], &twin[from..]);
    let sq: f64 = stem.iter().zip(twin).map(|(s, t)| (s - t).powi(2)).sum();
    // The settling hold is the sequence's first.
    let ends = if sequence {
        trial::sequence_ends(&stem_all, &op, DT)
    } else {
        Vec::new()
    };
    Ok(Figures {
        tracking_pct: (sq / stem.len().max(1) as f64).sqrt(),
        travel: metrics::travel(stem, TRAVEL_DEADBAND_PCT),
        read: (
            rows[from..].iter().filter(|r| r.vp_pct.is_some()).count(),
            rows.len() - from,
        ),
        ends,
        switched_off: None,
    })
}

/// When and why the summary says the guard switched `name`'s compensation off.
fn switched_off(summary: &str, name: &str) -> Option<(f64, String)> {
    let header = format!("valve {name}:");
    let section = summary.split_once(&header)?.1;
    let section = section.split("\nvalve ").next().unwrap_or(section);
    let at = section.split_once("switched off by its guard at ")?.1;
    let t = at.split(' ').next()?.parse().ok()?;
    let why = at
        .split_once(" s (")
        .and_then(|(_, r)| r.split_once(')'))
        .map_or(String::new(), |(w, _)| w.to_string());
    Some((t, why))
}

/// The cases every scenario runs: each valve without, with and with unjudged compensation by
/// its own model, then the healthy valve given the 1.5 % valve's model, judged and not.
fn cases(names: &[String]) -> Vec<Case> {
    let mut out = Vec::new();
    for valve in 0..names.len() {
        for variant in Variant::ALL {
            out.push(Case {
                valve,
                model: valve,
                variant,
            });
        }
    }
    let band = names.iter().position(|n| n == "1.5 % band").unwrap_or(0);
    for variant in [Variant::Guarded, Variant::Unguarded] {
        out.push(Case {
            valve: 0,
            model: band,
            variant,
        });
    }
    out
}

/// Runs the Modbus part under `work`: a log of `log_s` per valve, diagnosed, then `run_s` of
/// small steps and the sequence, every case at once; `progress` says what is going on.
pub(crate) fn run(
    work: &Path,
    (log_s, run_s): (f64, f64),
    progress: &dyn Fn(&str),
) -> Result<Outcome, Error> {
    let (vb, sim) = binaries()?;
    let bins = (vb.as_path(), sim.as_path());
    let valves = valves();
    let names: Vec<String> = valves.iter().map(|v| v.0.clone()).collect();
    std::fs::create_dir_all(work)?;
    let mut specs = Vec::new();
    for (i, (_, spec)) in valves.iter().enumerate() {
        let path = work.join(format!("valve-{}.toml", i + 1));
        std::fs::write(&path, spec.to_toml())?;
        specs.push(path);
    }
    progress(&format!(
        "Modbus: logging {} valves' small steps for {log_s} s in real time",
        valves.len()
    ));
    let plain: Vec<Unit> = (0..valves.len())
        .map(|i| Unit {
            name: format!("v{}", i + 1),
            spec: specs[i].clone(),
            compensation: String::new(),
        })
        .collect();
    let log_op = small_steps(log_s, LOG_SEED);
    let (_, logs) = logged_run(bins, &work.join("log"), &plain, (log_op[0], &log_op))?;
    let mut models = Vec::new();
    for (i, log) in logs.iter().enumerate() {
        progress(&format!("Modbus: diagnosing {}", names[i]));
        let steps = settled(log, &work.join(format!("log-{}", i + 1)))?;
        models.push(diagnose(
            &vb,
            &steps,
            &work.join(format!("diag-{}", i + 1)),
        )?);
    }
    let described = (models.iter())
        .map(|m| super::compensator(m).map(|c| c.describe()))
        .collect::<Result<_, _>>()?;
    let cases = cases(&names);
    let units: Vec<Unit> = (cases.iter().enumerate())
        .map(|(i, c)| Unit {
            name: format!("c{}", i + 1),
            spec: specs[c.valve].clone(),
            compensation: match c.variant {
                Variant::Without => String::new(),
                Variant::Guarded => format!(
                    "[valve.compensation]\nmodel_file = {:?}\n",
                    models[c.model].display().to_string()
                ),
                Variant::Unguarded => format!(
                    "[valve.compensation]\nmodel_file = {:?}\nguard_window_s = {NO_JUDGING_WINDOW_S}\n",
                    models[c.model].display().to_string()
                ),
            },
        })
        .collect();
    let mut results = Vec::new();
    let small = small_steps(run_s, 1);
    // The sequence settles at its last level, so that each of its levels is a move.
    for (what, settle_at, op, is_sequence) in [
        ("small steps", small[0], small, false),
        ("sequence", trial::sequence_at(0.0), sequence(), true),
    ] {
        progress(&format!(
            "Modbus: {what}, {} runs at once for {:.0} s in real time",
            units.len(),
            op.len() as f64 * DT
        ));
        let dir = work.join(what.replace(' ', "-"));
        let (summary, logs) = logged_run(bins, &dir, &units, (settle_at, &op))?;
        let mut figs = Vec::new();
        for (i, c) in cases.iter().enumerate() {
            let mut f = figures(&valves[c.valve].1, &logs[i], is_sequence)?;
            f.switched_off = switched_off(&summary, &units[i].name);
            figs.push(f);
        }
        results.push(figs);
    }
    let sequence = results.pop().unwrap_or_default();
    let small = results.pop().unwrap_or_default();
    Ok(Outcome {
        names,
        described,
        cases,
        small,
        sequence,
    })
}
