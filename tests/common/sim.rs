//! sim-device and `valve-bridge run` for the tests that put real Modbus between them: start
//! the device (its endpoint read from its first line), write a daemon config from a shipped one,
//! run the daemon, read its log.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::{Mutex, MutexGuard};

/// The valve-bridge binary.
pub(crate) const BIN: &str = env!("CARGO_BIN_EXE_valve-bridge");

/// The shipped daemon configs for sim-device and the endpoint each names.
pub(crate) const TCP_CONFIG: (&str, &str) = ("config/sim-device-tcp.toml", "127.0.0.1:5502");
/// See [`TCP_CONFIG`].
pub(crate) const RTU_CONFIG: (&str, &str) = ("config/sim-device-rtu.toml", "/tmp/vb-sim-device");

/// A constant O_P of 40 %.
pub(crate) const CONSTANT: &str =
    "[source]\nkind = \"constant\"\n[source.constant]\nop_pct = 40.0\n";

/// The sim-device binary, next to valve-bridge.
pub(crate) fn sim_device_bin() -> PathBuf {
    let p = Path::new(BIN).with_file_name("sim-device");
    assert!(
        p.exists(),
        "{} not built: run `cargo test --workspace` (or `cargo build -p sim-device`)",
        p.display()
    );
    p
}

/// A running sim-device and the endpoint it printed (`tcp: ADDR` or `pty: PATH`); its stderr
/// (its log) goes to a file, read by [`SimDevice::stop`].
pub(crate) struct SimDevice {
    child: Child,
    /// `host:port` or the pty's path.
    pub endpoint: String,
    /// The shipped config of its link (see [`TCP_CONFIG`]).
    pub shipped: (&'static str, &'static str),
    log: tempfile::NamedTempFile,
}

impl SimDevice {
    /// Starts sim-device with `args` and the shipped config of its link.
    pub(crate) fn start(args: &[&str]) -> SimDevice {
        let shipped = if args.contains(&"--pty") {
            RTU_CONFIG
        } else {
            TCP_CONFIG
        };
        let config = Path::new(env!("CARGO_MANIFEST_DIR")).join(shipped.0);
        let mut all: Vec<&str> = args.to_vec();
        all.extend(["--config", config.to_str().unwrap()]);
        Self::start_bare(&all, shipped)
    }

    /// Starts sim-device with exactly `args` (no config unless given).
    pub(crate) fn start_bare(args: &[&str], shipped: (&'static str, &'static str)) -> SimDevice {
        let log = tempfile::NamedTempFile::new().unwrap();
        let mut child = Command::new(sim_device_bin())
            .args(args)
            .env("RUST_LOG", "info")
            .stdout(Stdio::piped())
            .stderr(log.reopen().unwrap())
            .spawn()
            .unwrap();
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        let Some((_, endpoint)) = line.trim().split_once(": ") else {
            drop(child.kill());
            drop(child.wait());
            let log = std::fs::read_to_string(log.path()).unwrap_or_default();
            panic!("sim-device {args:?} announced no endpoint: {log}");
        };
        SimDevice {
            endpoint: endpoint.to_string(),
            child,
            shipped,
            log,
        }
    }

    /// The process id.
    pub(crate) fn pid(&self) -> u32 {
        self.child.id()
    }

    /// A daemon config for this device: its shipped config pointed at its endpoint, with
    /// `edits` applied and `source` appended.
    pub(crate) fn config(&self, dir: &Path, edits: &[(&str, &str)], source: &str) -> PathBuf {
        let (file, endpoint) = self.shipped;
        let mut all = vec![(endpoint, self.endpoint.as_str())];
        all.extend_from_slice(edits);
        config(dir, file, &all, source)
    }

    /// Kills the device at once (SIGKILL).
    pub(crate) fn kill(&mut self) {
        self.child.kill().unwrap();
        self.child.wait().unwrap();
    }

    /// Sends `signal` to the device.
    pub(crate) fn signal(&self, signal: libc::c_int) {
        assert!(super::signal(&self.child, signal));
    }

    /// Stops the device with SIGTERM and returns its log.
    pub(crate) fn stop(mut self) -> String {
        self.signal(libc::SIGTERM);
        drop(self.child.wait());
        std::fs::read_to_string(self.log.path()).unwrap_or_default()
    }
}

impl Drop for SimDevice {
    fn drop(&mut self) {
        drop(self.child.kill());
        drop(self.child.wait());
    }
}

/// A port held bound but not listening: connections to it are refused, and no other test's
/// server can take it while the guard lives (a port bound and released at once can be handed
/// to a parallel test's server before the daemon connects).
pub(crate) struct NobodyListening {
    _socket: tokio::net::TcpSocket,
}

/// `127.0.0.1:PORT` with a port nobody listens on (held by the returned guard; drop it to let
/// a device start there), and a daemon config for the shipped TCP config pointed at it (in
/// `dir`, with `source` appended).
pub(crate) fn nobody_listening(dir: &Path, source: &str) -> (String, PathBuf, NobodyListening) {
    let socket = tokio::net::TcpSocket::new_v4().unwrap();
    socket.bind("127.0.0.1:0".parse().unwrap()).unwrap();
    let port = socket.local_addr().unwrap().port();
    let addr = format!("127.0.0.1:{port}");
    let cfg = config(dir, TCP_CONFIG.0, &[(TCP_CONFIG.1, &addr)], source);
    (addr, cfg, NobodyListening { _socket: socket })
}

/// A daemon config `daemon.toml`: the shipped config with each `(from, to)` replaced (each must
/// occur) and `source` appended.
pub(crate) fn config(dir: &Path, shipped: &str, edits: &[(&str, &str)], source: &str) -> PathBuf {
    let mut text =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join(shipped)).unwrap();
    for (from, to) in edits {
        assert!(text.contains(from), "{shipped} has no {from}");
        text = text.replace(from, to);
    }
    let path = dir.join("daemon.toml");
    std::fs::write(&path, format!("{text}\n{source}")).unwrap();
    path
}

/// `valve-bridge probe --config CFG EXTRA...` with the default log level, run to the end.
pub(crate) fn probe(cfg: &Path, extra: &[&str]) -> Output {
    Command::new(BIN)
        .args(["probe", "--config"])
        .arg(cfg)
        .args(extra)
        .env_remove("RUST_LOG")
        .output()
        .unwrap()
}

/// `valve-bridge run` with the default log level (`RUST_LOG` unset).
pub(crate) fn run_cmd(cfg: &Path, log_dir: &Path, duration_s: f64) -> Command {
    let mut cmd = Command::new(BIN);
    cmd.args(["run", "--config"])
        .arg(cfg)
        .arg("--duration")
        .arg(duration_s.to_string())
        .arg("--log-dir")
        .arg(log_dir)
        .env_remove("RUST_LOG");
    cmd
}

/// The rows of the only log file in `dir`.
pub(crate) fn read_log<R: serde::de::DeserializeOwned>(dir: &Path) -> Vec<R> {
    let files: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(files.len(), 1, "{files:?}");
    let mut r = csv::Reader::from_path(&files[0]).unwrap();
    r.deserialize().map(|row| row.unwrap()).collect()
}

/// The stdout of a run that must have succeeded.
pub(crate) fn stdout(out: &Output) -> String {
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "exit {:?}\nstdout:\n{text}\nstderr:\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    text
}

/// Real-time runs take turns: on a small machine, parallel 100 Hz loops (each busy-waits before
/// its deadlines) and their devices would make each other miss cycles.
pub(crate) fn real_time_turn() -> MutexGuard<'static, ()> {
    static REAL_TIME: Mutex<()> = Mutex::new(());
    REAL_TIME.lock().unwrap_or_else(|p| p.into_inner())
}

/// The summary's count after `prefix` (`reconnects: 3` or `reconnects: 3 (...)`).
pub(crate) fn summary_count(summary: &str, prefix: &str) -> u64 {
    summary
        .lines()
        .find_map(|l| l.strip_prefix(prefix))
        .and_then(|rest| rest.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no `{prefix}N` in\n{summary}"))
}
