//! The daemon's and sim-device's servers, for the tests that crowd them: a started server and
//! the endpoints it announced (its output read in the background, so a chatty server never
//! blocks on a full pipe), and the clients: a process controller, Modbus readers, idle sockets,
//! a Prometheus scraper, a browser on a kept-alive connection. A client can connect from
//! another loopback address (127.0.0.2, ...): to the server, another host.

use std::io::{BufRead, Read, Write};
use std::net::{IpAddr, SocketAddr, TcpStream};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::thread::JoinHandle;
use std::time::Duration;

use super::sim::BIN;

/// A started server: the addresses of the `name: ADDR` lines it printed first, and the rest of
/// its stdout and its stderr, read in the background.
pub(crate) struct Server {
    child: Child,
    pub ends: Vec<String>,
    stdout: JoinHandle<String>,
    stderr: JoinHandle<String>,
}

/// Reads all of `r` on a thread of its own.
fn drain(mut r: impl Read + Send + 'static) -> JoinHandle<String> {
    std::thread::spawn(move || {
        let mut text = String::new();
        drop(r.read_to_string(&mut text));
        text
    })
}

impl Server {
    /// Starts `cmd` with its output piped; waits for its `n` endpoint lines.
    pub(crate) fn start(cmd: &mut Command, n: usize) -> Server {
        let child = cmd
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        Server::announced(child, n)
    }

    /// A spawned `child` (stdout and stderr piped): waits for its `n` endpoint lines.
    pub(crate) fn announced(mut child: Child, n: usize) -> Server {
        let stderr = drain(child.stderr.take().unwrap());
        let mut out = std::io::BufReader::new(child.stdout.take().unwrap());
        let mut ends = Vec::new();
        for _ in 0..n {
            let mut line = String::new();
            out.read_line(&mut line).unwrap();
            let Some((_, addr)) = line.trim().split_once(": ") else {
                drop(child.kill());
                panic!("no endpoint line: {line:?}\n{}", stderr.join().unwrap());
            };
            ends.push(addr.to_string());
        }
        Server {
            child,
            ends,
            stdout: drain(out),
            stderr,
        }
    }

    /// True while the process runs.
    pub(crate) fn running(&mut self) -> bool {
        self.child.try_wait().unwrap().is_none()
    }

    /// SIGTERM, then the rest of its stdout and its stderr (it must exit 0).
    pub(crate) fn stop(mut self) -> (String, String) {
        super::signal(&self.child, libc::SIGTERM);
        let status = self.child.wait().unwrap();
        let (stdout, stderr) = (self.stdout.join().unwrap(), self.stderr.join().unwrap());
        assert!(status.success(), "{status:?}\n{stderr}");
        (stdout, stderr)
    }
}

/// `valve-bridge run` of `config` (written to `dir`), its logs in `dir/logs`, at log level info.
pub(crate) fn daemon(config: &str, dir: &Path) -> Command {
    let cfg = dir.join("hil.toml");
    std::fs::write(&cfg, config).unwrap();
    let mut cmd = Command::new(BIN);
    cmd.args(["run", "--config"])
        .arg(&cfg)
        .arg("--log-dir")
        .arg(dir.join("logs"))
        .env("RUST_LOG", "info");
    cmd
}

/// The summary's line about the Modbus server.
pub(crate) fn server_line(summary: &str) -> &str {
    summary
        .lines()
        .find(|l| l.starts_with("modbus-server: "))
        .unwrap_or_else(|| panic!("{summary}"))
}

/// A connection to `addr` from the loopback address `from` (another host, to the server), with
/// reads that give up after `timeout`.
pub(crate) fn connect_from(
    from: &str,
    addr: &str,
    timeout: Duration,
) -> std::io::Result<TcpStream> {
    let local: IpAddr = from.parse().unwrap();
    let remote: SocketAddr = addr.parse().unwrap();
    let socket = tokio::net::TcpSocket::new_v4()?;
    socket.bind(SocketAddr::new(local, 0))?;
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_io()
        .build()?;
    let stream = rt.block_on(socket.connect(remote))?.into_std()?;
    stream.set_nonblocking(false)?;
    stream.set_nodelay(true)?;
    stream.set_read_timeout(Some(timeout))?;
    Ok(stream)
}

/// `n` idle connections to `addr` (those the kernel takes; a refused one is left out).
pub(crate) fn crowd(addr: &str, n: usize) -> Vec<TcpStream> {
    (0..n)
        .filter_map(|_| TcpStream::connect(addr).ok())
        .collect()
}

/// Writes per-mille `value` into holding register 0 (FC 6) on a new connection and returns the
/// echoed value.
pub(crate) fn write_register(addr: &str, value: u16) -> std::io::Result<u16> {
    let mut s = TcpStream::connect(addr)?;
    s.set_read_timeout(Some(Duration::from_secs(2)))?;
    let v = value.to_be_bytes();
    s.write_all(&[0, 7, 0, 0, 0, 6, 1, 6, 0, 0, v[0], v[1]])?;
    let mut reply = [0u8; 12];
    s.read_exact(&mut reply)?;
    Ok(u16::from_be_bytes([reply[10], reply[11]]))
}

/// A Modbus client on one connection, one request at a time: a process controller writing
/// per-mille set-points into holding register 0 (FC 6), or a reader of holding 0-2 (FC 3).
pub(crate) struct Client {
    stream: TcpStream,
    tid: u16,
}

impl Client {
    /// A client of `addr` from the loopback address `from`.
    pub(crate) fn connect_from(from: &str, addr: &str) -> std::io::Result<Client> {
        let stream = connect_from(from, addr, Duration::from_millis(500))?;
        Ok(Client { stream, tid: 0 })
    }

    /// A client of `addr` from 127.0.0.1.
    pub(crate) fn connect(addr: &str) -> Client {
        Client::connect_from("127.0.0.1", addr).unwrap()
    }

    /// Sends the PDU `pdu` and reads the reply's PDU, `reply_len` bytes: None when the
    /// connection failed or the reply is not this request's.
    fn exchange(&mut self, pdu: &[u8], reply_len: usize) -> Option<Vec<u8>> {
        self.tid = self.tid.wrapping_add(1);
        let t = self.tid.to_be_bytes();
        let len = (pdu.len() as u16 + 1).to_be_bytes();
        let mut request = vec![t[0], t[1], 0, 0, len[0], len[1], 1];
        request.extend_from_slice(pdu);
        self.stream.write_all(&request).ok()?;
        let mut head = [0u8; 7];
        self.stream.read_exact(&mut head).ok()?;
        let n = usize::from(u16::from_be_bytes([head[4], head[5]])).checked_sub(1)?;
        let mut reply = vec![0u8; n];
        self.stream.read_exact(&mut reply).ok()?;
        (head[..2] == t && (n == reply_len || n == 2)).then_some(reply)
    }

    /// Writes `value`; true when the echo came back.
    pub(crate) fn write(&mut self, value: u16) -> bool {
        self.write_reply(value)
            .is_some_and(|r| r[0] == 6 && r[3..] == value.to_be_bytes())
    }

    /// Writes `value`: the reply's PDU (an echo, or an exception: the function code with bit 7
    /// set and its code), None when the connection failed.
    pub(crate) fn write_reply(&mut self, value: u16) -> Option<Vec<u8>> {
        let v = value.to_be_bytes();
        self.exchange(&[6, 0, 0, v[0], v[1]], 5)
    }

    /// Reads holding registers 0-2; true when their values came back.
    pub(crate) fn read(&mut self) -> bool {
        self.exchange(&[3, 0, 0, 0, 3], 8)
            .is_some_and(|r| r[0] == 3)
    }
}

/// The answer to `GET /metrics` on a new connection (read to the end: the request asks the
/// server to close).
pub(crate) fn scrape(addr: &str) -> String {
    scrape_from("127.0.0.1", addr).unwrap()
}

/// `GET /metrics` on a new connection from the loopback address `from`: the whole answer, or
/// the error that cut it short.
pub(crate) fn scrape_from(from: &str, addr: &str) -> std::io::Result<String> {
    let mut s = connect_from(from, addr, Duration::from_secs(5))?;
    write!(
        s,
        "GET /metrics HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n"
    )?;
    let mut reply = String::new();
    s.read_to_string(&mut reply)?;
    Ok(reply)
}

/// Asks for `path` on the kept-alive connection `s`: true when the whole answer came, 200.
pub(crate) fn get_kept(s: &mut TcpStream, path: &str) -> bool {
    let mut head = Vec::new();
    let mut byte = [0u8; 1];
    if write!(s, "GET {path} HTTP/1.1\r\nHost: x\r\n\r\n").is_err() {
        return false;
    }
    while !head.ends_with(b"\r\n\r\n") {
        if !matches!(s.read(&mut byte), Ok(1)) {
            return false;
        }
        head.push(byte[0]);
    }
    let head = String::from_utf8_lossy(&head);
    let len = (head.lines())
        .find_map(|l| l.strip_prefix("content-length: "))
        .and_then(|v| v.trim().parse::<usize>().ok());
    let mut body = vec![0u8; len.unwrap_or(0)];
    head.starts_with("HTTP/1.1 200 OK") && len.is_some() && s.read_exact(&mut body).is_ok()
}

/// The value of the metric line that starts with `name ` in the text `metrics`.
pub(crate) fn metric(metrics: &str, name: &str) -> u64 {
    metrics
        .lines()
        .find_map(|l| l.strip_prefix(name)?.strip_prefix(' '))
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no {name} in {metrics}"))
}
