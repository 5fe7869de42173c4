//! The daemon's HTTP server on `[metrics] listen`: hyper (HTTP/1.1, keep-alive) on the network
//! thread, over a [`vb_modbus::net`] server that keeps the connections (accept errors retried, at
//! most `max_connections` open, one closed to make room for a new one: first from the host
//! holding the most). A connection that has asked for `/metrics` is a scraper's: within its
//! host it gives way after the others ([`Standing::Preferred`]). It serves
//! - `GET /metrics`: the Prometheus text format ([`crate::serve::exporter`]);
//! - `GET /`: the live page ([`crate::serve::page`]); `GET /api/live[?since=T]`: its figures, with each
//!   valve's trace after loop time `T`; `GET /api/diagnoses/NAME`: a valve's diagnosis history
//!   (the last lines of its file);
//! - `GET /reports/diagnosis-NAME/T/FILE`: the files of a diagnosis report beside the logs, for
//!   a valve of the config, a report's name (`20261122T101500Z`, `-N` when taken; whole seconds
//!   of loop time for the reports of earlier versions) and a file a report has, never through a
//!   symbolic link, so that nothing else on the disk can be read.
//!
//! `GET /favicon.ico` gets 204 (no icon), other paths 404, other methods 405, a request that is
//! not HTTP 400 (hyper's). A connection that sends no request head within the idle timeout
//! ([`HEAD_TIMEOUT`] for the daemon), its first or the next after an answer, is closed and
//! counted as closed idle.
//!
//! Not here: the metrics ([`crate::serve::exporter`]), what the page shows ([`crate::serve::page`]).

use std::convert::Infallible;
use std::io::Read;
use std::sync::Arc;
use std::time::Duration;

use http_body_util::Full;
use hyper::body::{Bytes, Incoming};
use hyper::header::{HeaderValue, ALLOW, CACHE_CONTROL, CONTENT_TYPE};
use hyper::server::conn::http1;
use hyper::service::service_fn;
use hyper::{Method, Request, Response, StatusCode};
use hyper_util::rt::{TokioIo, TokioTimer};
use tokio::net::TcpListener;

use crate::runtime::files;
use crate::serve::exporter::LoopMetrics;
use crate::serve::page::{self, board::Board};
use vb_modbus::net::{self, Health, Limits, Standing};

/// Time a client of the daemon gets to send a request head: its first, or the next after an
/// answer (its connection is closed after it).
pub(crate) const HEAD_TIMEOUT: Duration = Duration::from_secs(5);

/// The files of a diagnosis report (as the diagnosis thread writes them), with their types.
const REPORT_FILES: [(&str, &str); 3] = [
    ("report.html", HTML),
    ("model.toml", TEXT),
    ("diagnosis.json", JSON),
];
const TEXT: &str = "text/plain; charset=utf-8";
const HTML: &str = "text/html; charset=utf-8";
const JSON: &str = "application/json";

type Reply = Response<Full<Bytes>>;

/// What the server answers from.
#[derive(Debug)]
pub(crate) struct Site {
    metrics: LoopMetrics,
    /// The daemon's servers, whose figures go into the metrics.
    servers: Vec<(&'static str, Arc<Health>)>,
    board: Arc<Board>,
    /// The live page, built once.
    page: Bytes,
}

impl Site {
    /// The metrics with the figures of `servers`, and the live page of `board`.
    pub(crate) fn new(
        metrics: LoopMetrics,
        servers: Vec<(&'static str, Arc<Health>)>,
        board: Arc<Board>,
    ) -> Site {
        Site {
            metrics,
            servers,
            board,
            page: Bytes::from(page::html()),
        }
    }

    /// The answer to one request.
    async fn answer(&self, req: Request<Incoming>) -> Reply {
        if req.method() != Method::GET {
            let mut r = reply(StatusCode::METHOD_NOT_ALLOWED, TEXT, "only GET is served\n");
            r.headers_mut()
                .insert(ALLOW, HeaderValue::from_static("GET"));
            return r;
        }
        let path = req.uri().path();
        match path {
            "/metrics" => self.metrics_text(),
            "/" => fresh(reply(StatusCode::OK, HTML, self.page.clone())),
            // No icon, and no error in a browser's console for the one it asks for.
            "/favicon.ico" => reply(StatusCode::NO_CONTENT, TEXT, ""),
            "/api/live" => {
                let json = self.board.live_json(since(req.uri().query()));
                fresh(reply(StatusCode::OK, JSON, json))
            }
            _ => {
                if let Some(valve) = path.strip_prefix("/api/diagnoses/") {
                    self.diagnoses(valve).await
                } else if let Some(rel) = path.strip_prefix("/reports/") {
                    self.report(rel).await
                } else {
                    not_found()
                }
            }
        }
    }

    fn metrics_text(&self) -> Reply {
        self.metrics.observe_servers(&self.servers);
        match self.metrics.text() {
            Ok(text) => reply(StatusCode::OK, prometheus::TEXT_FORMAT, text),
            Err(e) => reply(
                StatusCode::INTERNAL_SERVER_ERROR,
                TEXT,
                format!("cannot encode the metrics: {e}\n"),
            ),
        }
    }

    /// A valve's diagnosis history, read off the network thread.
    async fn diagnoses(&self, valve: &str) -> Reply {
        let Some((path, from)) = self.board.history(valve) else {
            return not_found();
        };
        let read = tokio::task::spawn_blocking(move || page::history_tail(&path, from)).await;
        match read.map_err(std::io::Error::other).and_then(|r| r) {
            Ok(json) => fresh(reply(StatusCode::OK, JSON, json)),
            Err(e) => reply(
                StatusCode::INTERNAL_SERVER_ERROR,
                TEXT,
                format!("cannot read the diagnosis history of {valve}: {e}\n"),
            ),
        }
    }

    /// A file of a diagnosis report (see [`report_file`]).
    async fn report(&self, rel: &str) -> Reply {
        let Some((parts, content_type)) = report_file(&self.board, rel) else {
            return not_found();
        };
        let dir = self.board.dir().to_path_buf();
        let read = tokio::task::spawn_blocking(move || {
            let parts: Vec<&str> = parts.iter().map(String::as_str).collect();
            let mut body = Vec::new();
            files::open_read(&dir, &parts)?.read_to_end(&mut body)?;
            Ok::<_, std::io::Error>(body)
        });
        match read.await {
            Ok(Ok(body)) => reply(StatusCode::OK, content_type, body),
            _ => not_found(),
        }
    }
}

/// The file `rel` (`diagnosis-NAME/T/FILE`) of the log directory, as the names of its three
/// parts, and its content type: only for a valve of the board, a report's name and a file a
/// report has.
fn report_file(board: &Board, rel: &str) -> Option<([String; 3], &'static str)> {
    let mut parts = rel.split('/');
    let (dir, t, file) = (parts.next()?, parts.next()?, parts.next()?);
    let valve = dir.strip_prefix("diagnosis-")?;
    let named = (1..=24).contains(&t.len())
        && (t.bytes()).all(|b| b.is_ascii_digit() || matches!(b, b'T' | b'Z' | b'-'));
    let &(_, content_type) = REPORT_FILES.iter().find(|(name, _)| *name == file)?;
    (parts.next().is_none() && named && board.has_valve(valve))
        .then(|| ([dir, t, file].map(String::from), content_type))
}

/// The loop time of `?since=T`, when given as a number.
fn since(query: Option<&str>) -> Option<f64> {
    let value = query?.split('&').find_map(|kv| kv.strip_prefix("since="))?;
    value.parse::<f64>().ok().filter(|v| v.is_finite())
}

fn reply(status: StatusCode, content_type: &'static str, body: impl Into<Bytes>) -> Reply {
    let mut r = Response::new(Full::new(body.into()));
    *r.status_mut() = status;
    (r.headers_mut()).insert(CONTENT_TYPE, HeaderValue::from_static(content_type));
    r
}

/// `r`, never to be taken from a cache (it changes every moment).
fn fresh(mut r: Reply) -> Reply {
    (r.headers_mut()).insert(CACHE_CONTROL, HeaderValue::from_static("no-store"));
    r
}

fn not_found() -> Reply {
    reply(
        StatusCode::NOT_FOUND,
        TEXT,
        "not here: the live page is at /, the metrics at /metrics\n",
    )
}

/// Answers HTTP on `listener` within `limits` from `site`, forever (drop the task to stop); a
/// connection without a request head for `limits.idle_timeout` is closed.
pub(crate) async fn serve(listener: TcpListener, site: Site, limits: Limits, health: Arc<Health>) {
    let site = Arc::new(site);
    let counts = Arc::clone(&health);
    let head_timeout = limits.idle_timeout;
    net::serve(
        "metrics endpoint",
        listener,
        limits,
        health,
        move |stream, _, activity| {
            let (site, counts) = (Arc::clone(&site), Arc::clone(&counts));
            async move {
                let service = service_fn(move |req: Request<Incoming>| {
                    activity.request();
                    if req.uri().path() == "/metrics" {
                        activity.raise(Standing::Preferred);
                    }
                    let site = Arc::clone(&site);
                    async move { Ok::<_, Infallible>(site.answer(req).await) }
                });
                let served = http1::Builder::new()
                    .timer(TokioTimer::new())
                    .header_read_timeout(head_timeout)
                    .serve_connection(TokioIo::new(stream), service)
                    .await;
                match served {
                    Err(e) if e.is_timeout() => {
                        counts.idle_closed();
                        Ok(())
                    }
                    other => other.map_err(std::io::Error::other),
                }
            }
        },
    )
    .await
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    use tokio::net::TcpStream;

    /// A server of a board of valve `a` (logs in `dir`) with an idle timeout of 300 ms.
    async fn start(dir: &std::path::Path) -> (String, Arc<Health>) {
        let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap().to_string();
        let metrics = LoopMetrics::new(&["a"], true).unwrap();
        let board = Arc::new(Board::new(&["a"], 100.0, (Some(600.0), Some(1200.0)), dir));
        let health = Arc::new(Health::default());
        let servers = vec![("metrics", Arc::clone(&health))];
        let limits = Limits {
            max_connections: 4,
            idle_timeout: Duration::from_millis(300),
            controllers: Arc::default(),
        };
        let site = Site::new(metrics, servers, board);
        tokio::spawn(serve(listener, site, limits, Arc::clone(&health)));
        (addr, health)
    }

    /// Sends `request` on `s` and reads one answer: its status line, head and body.
    async fn exchange(s: &mut TcpStream, request: &[u8]) -> (String, String, String) {
        s.write_all(request).await.unwrap();
        let mut got = Vec::new();
        let mut chunk = [0u8; 65536];
        loop {
            let n = s.read(&mut chunk).await.unwrap();
            got.extend_from_slice(&chunk[..n]);
            let text = String::from_utf8_lossy(&got).to_string();
            if let Some((head, body)) = text.split_once("\r\n\r\n") {
                let len = (head.lines())
                    .find_map(|l| l.strip_prefix("content-length: "))
                    .and_then(|v| v.parse::<usize>().ok());
                if n == 0 || len.is_some_and(|len| body.len() >= len) {
                    let status = head.lines().next().unwrap_or("").to_string();
                    return (status, head.to_string(), body.to_string());
                }
            }
            assert!(n > 0, "closed before an answer: {text}");
        }
    }

    async fn get(addr: &str, path: &str) -> (String, String, String) {
        let mut s = TcpStream::connect(addr).await.unwrap();
        exchange(
            &mut s,
            format!("GET {path} HTTP/1.1\r\nHost: x\r\n\r\n").as_bytes(),
        )
        .await
    }

    #[tokio::test]
    async fn metrics_page_and_refusals() {
        let dir = tempfile::tempdir().unwrap();
        let (addr, _) = start(dir.path()).await;
        let (status, head, body) = get(&addr, "/metrics?x=1").await;
        assert_eq!(status, "HTTP/1.1 200 OK");
        assert!(head.contains(prometheus::TEXT_FORMAT), "{head}");
        assert!(
            body.contains("valve_bridge_server_connections{server=\"metrics\"} 1"),
            "{body}"
        );
        let (status, head, body) = get(&addr, "/").await;
        assert_eq!(status, "HTTP/1.1 200 OK");
        assert!(
            head.contains("text/html") && head.contains("no-store"),
            "{head}"
        );
        assert!(body.contains("uPlot") && body.contains("/api/live"));
        let (_, _, body) = get(&addr, "/api/live?since=3.5").await;
        let v: serde_json::Value = serde_json::from_str(&body).unwrap();
        assert_eq!(v["valves"][0]["name"], "a");
        assert_eq!(get(&addr, "/nothing").await.0, "HTTP/1.1 404 Not Found");
        let mut s = TcpStream::connect(&addr).await.unwrap();
        let (status, head, _) = exchange(&mut s, b"POST /metrics HTTP/1.1\r\n\r\n").await;
        assert_eq!(status, "HTTP/1.1 405 Method Not Allowed");
        assert!(head.contains("allow: GET"), "{head}");
        let mut s = TcpStream::connect(&addr).await.unwrap();
        let (status, _, _) =
            exchange(&mut s, b"\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03").await;
        assert_eq!(status, "HTTP/1.1 400 Bad Request");
        assert_eq!(since(Some("a=1&since=12.5")), Some(12.5));
        assert_eq!(since(Some("since=NaN")), None);
    }

    #[tokio::test]
    async fn the_history_and_reports_of_the_valves_only() {
        let dir = tempfile::tempdir().unwrap();
        let (addr, _) = start(dir.path()).await;
        // The history before any diagnosis, then with one and a line still being written.
        std::fs::write(dir.path().join("diagnosis-a.jsonl"), "").unwrap();
        assert_eq!(get(&addr, "/api/diagnoses/a").await.2, "[]");
        let line = r#"{"t_s":60.0,"report":"diagnosis-a/60/report.html"}"#;
        std::fs::write(
            dir.path().join("diagnosis-a.jsonl"),
            format!("{line}\n{{\"t_s\":"),
        )
        .unwrap();
        let (_, _, body) = get(&addr, "/api/diagnoses/a").await;
        assert_eq!(body, format!("[{line}]"));
        assert_eq!(
            get(&addr, "/api/diagnoses/b").await.0,
            "HTTP/1.1 404 Not Found"
        );
        let report = dir.path().join("diagnosis-a/60");
        std::fs::create_dir_all(&report).unwrap();
        std::fs::write(report.join("report.html"), "<p>report</p>").unwrap();
        std::fs::write(report.join("secret.txt"), "no").unwrap();
        let (status, head, body) = get(&addr, "/reports/diagnosis-a/60/report.html").await;
        assert_eq!(
            (status.as_str(), body.as_str()),
            ("HTTP/1.1 200 OK", "<p>report</p>")
        );
        assert!(head.contains("text/html"), "{head}");
        for path in [
            "/reports/diagnosis-a/60/secret.txt",
            "/reports/diagnosis-a/60/../60/report.html",
            "/reports/diagnosis-a/../diagnosis-a/60/report.html",
            "/reports/diagnosis-b/60/report.html",
            "/reports/diagnosis-a/6.0/report.html",
            "/reports/diagnosis-a/60/report.html/x",
            "/reports/diagnosis-a/61/report.html",
            "/reports/diagnosis-a/20261122T101500Z/report.html",
        ] {
            assert_eq!(get(&addr, path).await.0, "HTTP/1.1 404 Not Found", "{path}");
        }
        // A report named by its wall-clock time; none through a link planted in the directory.
        let named = dir.path().join("diagnosis-a/20261122T101500Z-1");
        std::fs::create_dir(&named).unwrap();
        std::fs::write(named.join("model.toml"), "model").unwrap();
        let (status, _, body) =
            get(&addr, "/reports/diagnosis-a/20261122T101500Z-1/model.toml").await;
        assert_eq!(
            (status.as_str(), body.as_str()),
            ("HTTP/1.1 200 OK", "model")
        );
        std::os::unix::fs::symlink(&report, dir.path().join("diagnosis-a/70")).unwrap();
        std::os::unix::fs::symlink(report.join("report.html"), named.join("report.html")).unwrap();
        for path in [
            "/reports/diagnosis-a/70/report.html",
            "/reports/diagnosis-a/20261122T101500Z-1/report.html",
        ] {
            assert_eq!(get(&addr, path).await.0, "HTTP/1.1 404 Not Found", "{path}");
        }
    }

    #[tokio::test]
    async fn a_connection_is_kept_for_the_next_request_and_closed_when_idle() {
        let dir = tempfile::tempdir().unwrap();
        let (addr, health) = start(dir.path()).await;
        let request = b"GET /api/live HTTP/1.1\r\nHost: x\r\n\r\n";
        let mut kept = TcpStream::connect(&addr).await.unwrap();
        for _ in 0..3 {
            assert_eq!(exchange(&mut kept, request).await.0, "HTTP/1.1 200 OK");
        }
        let mut silent = TcpStream::connect(&addr).await.unwrap();
        tokio::time::sleep(Duration::from_millis(600)).await;
        for s in [&mut kept, &mut silent] {
            assert_eq!(s.read(&mut [0u8; 1]).await.unwrap(), 0, "still open");
        }
        let v = health.view();
        assert_eq!((v.accepted, v.idle_closed, v.open), (2, 2, 0));
    }
}
