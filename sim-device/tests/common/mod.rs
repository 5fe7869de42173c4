//! Starting and stopping the real sim-device binary for the integration tests and the benches
//! (which include this file with `#[path]`).
#![allow(dead_code)] // each test file and bench uses a different part of this helper

#[path = "../../../tests/common/tools.rs"]
pub(crate) mod tools;

use std::io::{BufRead, BufReader, Read};
use std::process::{Child, ChildStdout, Command, Stdio};

/// A running sim-device, killed when dropped.
pub(crate) struct Sim {
    child: Child,
    _stdout: BufReader<ChildStdout>,
    /// `host:port` announced for --tcp.
    pub tcp: Option<String>,
    /// Client-end path announced for --pty.
    pub pty: Option<String>,
}

impl Sim {
    /// Starts sim-device with `args` and waits for its endpoint lines.
    pub(crate) fn start(args: &[&str]) -> Sim {
        let mut child = Command::new(env!("CARGO_BIN_EXE_sim-device"))
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("sim-device starts");
        let mut stdout = BufReader::new(child.stdout.take().expect("piped stdout"));
        let want = usize::from(args.contains(&"--tcp")) + usize::from(args.contains(&"--pty"));
        let (mut tcp, mut pty) = (None, None);
        for _ in 0..want {
            let mut line = String::new();
            if stdout.read_line(&mut line).unwrap_or(0) == 0 {
                let mut err = String::new();
                if let Some(mut e) = child.stderr.take() {
                    drop(e.read_to_string(&mut err));
                }
                panic!("sim-device {args:?} ended before announcing its endpoints: {err}");
            }
            if let Some(a) = line.trim().strip_prefix("tcp: ") {
                tcp = Some(a.to_string());
            } else if let Some(p) = line.trim().strip_prefix("pty: ") {
                pty = Some(p.to_string());
            }
        }
        Sim {
            child,
            _stdout: stdout,
            tcp,
            pty,
        }
    }

    /// Kills the device now.
    pub(crate) fn kill(&mut self) {
        drop(self.child.kill());
        drop(self.child.wait());
    }
}

impl Drop for Sim {
    fn drop(&mut self) {
        self.kill();
    }
}

/// Runs sim-device to completion and returns (exit success, stderr without info logs).
pub(crate) fn run_to_end(args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_sim-device"))
        .args(args)
        .env("RUST_LOG", "warn")
        .output()
        .expect("sim-device runs");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// A TCP port that was free a moment ago, below the ephemeral ports the kernel hands out (from
/// 32768 on Linux): a device killed and restarted on it cannot lose it meanwhile to another
/// test's device listening on port 0, or to a client's own end of a connection. Each call
/// starts its search one port further than the last, so two tests asking at once do not get
/// the same one.
pub(crate) fn free_port() -> u16 {
    use std::sync::atomic::{AtomicU32, Ordering};
    static NEXT: AtomicU32 = AtomicU32::new(0);
    const LOW: u32 = 20_000;
    const SPAN: u32 = 12_000;
    let from = std::process::id().wrapping_add(NEXT.fetch_add(1, Ordering::Relaxed));
    (0..SPAN)
        .map(|k| (LOW + from.wrapping_add(k) % SPAN) as u16)
        .find(|&port| std::net::TcpListener::bind(("127.0.0.1", port)).is_ok())
        .expect("a free port below the ephemeral range")
}

/// The value at quantile `q` (0-1) of ascending `sorted` values (nearest rank); 0 when empty.
pub(crate) fn percentile(sorted: &[f64], q: f64) -> f64 {
    match sorted.len() {
        0 => 0.0,
        n => sorted[((n - 1) as f64 * q.clamp(0.0, 1.0)).round() as usize],
    }
}
