//! The command blocks of README.md and of every page of docs/ (`docs/*.md`), run as written,
//! so the walk-throughs cannot drift from the code.
//!
//! Blocks are the indented (four spaces after a blank line) and fenced (untagged, `sh`, `bash`,
//! `console`, `shell`) code blocks. A command is a line (with `\` continuations joined); a
//! trailing `# ...` is a comment, and ``# prints `TEXT` `` says what its first line of output
//! is (`N` stands for a number). Each block runs in order (README's first, then the pages of
//! docs/ by name), in one scratch directory laid out like the checkout (its entries linked),
//! with `valve-bridge` and `sim-device` on PATH as the built binaries and
//! `cargo run [--release] [-p sim-device] --` meaning them, through `bash -c`; the paths a page
//! gives under `/tmp/` are taken under the scratch directory's `tmp/` (a test writes in its own
//! directories only), but for the pseudo-terminal links `/tmp/vb-*` that the shipped configs
//! name:
//!
//! - `valve-bridge`, `sim-device`, `mbpoll`, `curl`, `python3` and `for` loops run to the end
//!   and must exit 0 (within [`FOREGROUND_LIMIT`]); a `valve-bridge run` with `--duration`
//!   must have at least 90 % of its cycles ok;
//! - `valve-bridge run` without `--duration`, `sim-device` and `while` loops run in the
//!   background for the rest of their block (after their first line, or [`SETTLE`]); at the
//!   block's end they get SIGTERM, last started first, and a daemon must exit 0 with its
//!   summary. A block with a `while` loop feeding the daemon's Modbus server must end without
//!   a watchdog trip (the loop is there to hold the set-point);
//! - `cargo test`/`bench`/`build`/`install`, `cargo run --example` (the pages' generator), `pip`,
//!   `maturin`, `pytest`, `apt-get`, `sudo`, `systemctl`, `journalctl`, `python3 -m venv` and
//!   `.`/`source` are not run (listed, with the reason); ```python blocks are
//!   text here and run by `python/tests/test_readme.py`;
//! - a block whose first command is none of the above is text (the model diagram, say); an
//!   unknown program later in a command block fails the test, so a new kind of command gets a
//!   rule here rather than being skipped unnoticed.
//!
//! A command needing mbpoll, curl or python3 that is not installed is a visible skip of the
//! rest of its block, or a failure under `VB_REQUIRE_TOOLS=1` (`tests/common/tools.rs`).
//! `cargo test --test docs readme:: -- --nocapture` lists what happened to each block.

use std::io::{BufRead, BufReader, Read};
use std::path::Path;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::common;

use crate::common::sim::{sim_device_bin, BIN};
use crate::common::tools;

/// The longest a foreground command may take.
const FOREGROUND_LIMIT: Duration = Duration::from_secs(300);
/// How long a background command runs before the next command when it announces nothing.
const SETTLE: Duration = Duration::from_millis(1500);
/// How long a background command may take to print its first line, or to stop.
const BACKGROUND_LIMIT: Duration = Duration::from_secs(30);

/// One command of a block.
#[derive(Debug, Clone)]
struct Cmd {
    /// Its page (`README.md`, `docs/NAME.md`).
    page: String,
    /// Its line in the page.
    line: usize,
    /// The command, continuations joined, comment removed.
    text: String,
    /// What its first line of output is, from a ``# prints `...` `` comment.
    prints: Option<String>,
}

/// How a command is run.
#[derive(Debug, Clone, PartialEq)]
enum How {
    Foreground,
    Background,
    NotRun(&'static str),
    Unknown,
}

/// The code blocks of `text`, the text of `page`, each as its commands.
fn blocks(page: &str, text: &str) -> Vec<Vec<Cmd>> {
    let lines: Vec<&str> = text.lines().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        let fence = lines[i].trim_start().strip_prefix("```");
        if let Some(tag) = fence {
            let start = i + 1;
            i += 1;
            while i < lines.len() && !lines[i].trim_start().starts_with("```") {
                i += 1;
            }
            if ["", "sh", "bash", "console", "shell"].contains(&tag.trim()) {
                out.push(commands(page, &lines[start..i.min(lines.len())], start));
            }
        } else if lines[i].starts_with("    ") && (i == 0 || lines[i - 1].trim().is_empty()) {
            let start = i;
            while i < lines.len() && (lines[i].starts_with("    ") || lines[i].trim().is_empty()) {
                i += 1;
            }
            out.push(commands(page, &lines[start..i], start));
            continue;
        }
        i += 1;
    }
    out.retain(|b| !b.is_empty());
    out
}

/// The commands of a block's lines in `page` (`first` is the 0-based index of the first line).
fn commands(page: &str, lines: &[&str], first: usize) -> Vec<Cmd> {
    let mut out = Vec::new();
    let mut pending: Option<(usize, String)> = None;
    for (j, raw) in lines.iter().enumerate() {
        let line = raw.trim();
        if line.is_empty() || (pending.is_none() && line.starts_with('#')) {
            continue;
        }
        let (code, comment) = split_comment(line);
        let (start, mut text) = pending.take().unwrap_or((first + j + 1, String::new()));
        if let Some(rest) = code.trim_end().strip_suffix('\\') {
            text.push_str(rest.trim());
            text.push(' ');
            pending = Some((start, text));
            continue;
        }
        text.push_str(code.trim());
        let prints = comment.and_then(|c| {
            let c = c.trim().strip_prefix("prints `")?;
            Some(c[..c.find('`')?].to_string())
        });
        out.push(Cmd {
            page: page.to_string(),
            line: start,
            text,
            prints,
        });
    }
    out
}

/// The code and the comment of a line (a `#` outside quotes, at the start or after a space).
fn split_comment(line: &str) -> (&str, Option<&str>) {
    let (mut single, mut double) = (false, false);
    let mut prev = ' ';
    for (i, c) in line.char_indices() {
        match c {
            '\'' if !double => single = !single,
            '"' if !single => double = !double,
            '#' if !single && !double && prev.is_whitespace() => {
                return (&line[..i], Some(&line[i + 1..]));
            }
            _ => {}
        }
        prev = c;
    }
    (line, None)
}

/// The command's words after leading `VAR=value` settings.
fn words(text: &str) -> Vec<&str> {
    text.split_whitespace()
        .skip_while(|w| w.contains('=') && !w.starts_with('-'))
        .collect()
}

/// How `cmd` is run (see the module documentation).
fn how(cmd: &Cmd) -> How {
    let w = words(&cmd.text);
    let run_without_duration =
        |args: &[&str]| args.first() == Some(&"run") && !args.contains(&"--duration");
    match w.as_slice() {
        ["valve-bridge", args @ ..] if run_without_duration(args) => How::Background,
        ["valve-bridge", ..] => How::Foreground,
        ["sim-device", ..] | ["while", ..] => How::Background,
        ["python3", "-m", "venv", ..] | ["." | "source", ..] => {
            How::NotRun("makes or enters a virtual environment")
        }
        ["mbpoll" | "curl" | "python3" | "for", ..] => How::Foreground,
        ["cargo", "run", "--example", ..] => {
            How::NotRun("rewrites the pages' generated blocks (the tests compare their figures)")
        }
        ["cargo", "run", ..] => match mapped(&cmd.text) {
            Some(m) => how(&Cmd {
                text: m,
                ..cmd.clone()
            }),
            None => How::Unknown,
        },
        ["cargo", "test", ..] => How::NotRun("the test suite itself"),
        ["cargo", "bench", ..] => How::NotRun("a benchmark (minutes; run by hand)"),
        ["cargo", "build" | "install" | "fmt" | "clippy", ..] => How::NotRun("a build step"),
        ["pip" | "pip3" | "apt-get" | "apt", ..] => How::NotRun("installs packages"),
        ["maturin", ..] => How::NotRun("builds the Python package (minutes; .ci/run builds it)"),
        ["pytest", ..] => How::NotRun("the Python tests (.ci/run runs them)"),
        ["sudo", ..] => How::NotRun("needs root and systemd"),
        ["systemctl" | "journalctl", ..] => How::NotRun("needs systemd"),
        _ => How::Unknown,
    }
}

/// `cargo run [--release] [-p sim-device] -- ARGS` as `valve-bridge ARGS` or `sim-device ARGS`.
fn mapped(text: &str) -> Option<String> {
    let (head, args) = match text.split_once(" -- ") {
        Some((h, a)) => (h, a),
        None => (text, ""),
    };
    let program = if head.split_whitespace().any(|w| w == "sim-device") {
        "sim-device"
    } else {
        "valve-bridge"
    };
    head.starts_with("cargo run")
        .then(|| format!("{program} {args}").trim_end().to_string())
}

/// The tools `cmd` needs that may be missing, each with a probe and how to install it.
fn needs(cmd: &Cmd) -> Vec<(&'static str, &'static [&'static str], &'static str)> {
    let w: Vec<&str> = cmd.text.split_whitespace().collect();
    let mut out = Vec::new();
    if w.contains(&"mbpoll") {
        out.push(("mbpoll", &["-V"][..], tools::MBPOLL_INSTALL));
    }
    if w.contains(&"curl") {
        out.push(("curl", &["--version"][..], "apt-get install curl"));
    }
    if w.contains(&"python3") {
        out.push(("python3", &["--version"][..], "apt-get install python3"));
    }
    out
}

/// Lines matched: `expected` with `N` standing for a run of digits.
fn matches(expected: &str, actual: &str) -> bool {
    let (e, a) = (expected.as_bytes(), actual.trim_end().as_bytes());
    let (mut i, mut j) = (0, 0);
    while i < e.len() {
        if e[i] == b'N' && a.get(j).is_some_and(u8::is_ascii_digit) {
            while a.get(j).is_some_and(u8::is_ascii_digit) {
                j += 1;
            }
        } else if a.get(j) == Some(&e[i]) {
            j += 1;
        } else {
            return false;
        }
        i += 1;
    }
    j == a.len()
}

/// A scratch directory laid out like the checkout, and a PATH with the built binaries first.
struct Scratch {
    dir: tempfile::TempDir,
    path: String,
    _bin: tempfile::TempDir,
}

impl Scratch {
    fn new() -> Scratch {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let dir = tempfile::tempdir().unwrap();
        for entry in std::fs::read_dir(root).unwrap() {
            let entry = entry.unwrap();
            let name = entry.file_name();
            if [".git", "target", "logs"].contains(&name.to_string_lossy().as_ref()) {
                continue;
            }
            std::os::unix::fs::symlink(entry.path(), dir.path().join(&name)).unwrap();
        }
        std::fs::create_dir(dir.path().join("tmp")).unwrap();
        let bin = tempfile::tempdir().unwrap();
        std::os::unix::fs::symlink(BIN, bin.path().join("valve-bridge")).unwrap();
        std::os::unix::fs::symlink(sim_device_bin(), bin.path().join("sim-device")).unwrap();
        let path = format!(
            "{}:{}",
            bin.path().display(),
            std::env::var("PATH").unwrap_or_default()
        );
        Scratch {
            dir,
            path,
            _bin: bin,
        }
    }

    /// `text` with a page's `/tmp/` paths under the scratch directory (see the module
    /// documentation).
    fn local(&self, text: &str) -> String {
        let tmp = self.dir.path().join("tmp");
        let tmp = format!("{}/", tmp.display());
        text.replace("/tmp/", &tmp)
            .replace(&format!("{tmp}vb-"), "/tmp/vb-")
    }

    /// `bash -c TEXT` in the scratch directory, in a process group of its own.
    fn command(&self, text: &str) -> Command {
        use std::os::unix::process::CommandExt;
        let mut c = Command::new("bash");
        c.arg("-c")
            .arg(self.local(text))
            .current_dir(self.dir.path())
            .env("PATH", &self.path)
            .env_remove("RUST_LOG")
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .process_group(0);
        c
    }
}

/// A started command: its process, the first line of its stdout, all of its output.
struct Started {
    cmd: Cmd,
    child: Child,
    first: mpsc::Receiver<String>,
    stdout: JoinHandle<String>,
    stderr: JoinHandle<String>,
}

fn start(scratch: &Scratch, cmd: &Cmd, text: &str) -> Started {
    let mut child = scratch.command(text).spawn().unwrap();
    let (tx, first) = mpsc::channel();
    let out = child.stdout.take().unwrap();
    let stdout = std::thread::spawn(move || {
        let mut all = String::new();
        for line in BufReader::new(out).lines().map_while(Result::ok) {
            if all.is_empty() {
                drop(tx.send(line.clone()));
            }
            all.push_str(&line);
            all.push('\n');
        }
        all
    });
    let mut err = child.stderr.take().unwrap();
    let stderr = std::thread::spawn(move || {
        let mut s = String::new();
        drop(err.read_to_string(&mut s));
        s
    });
    Started {
        cmd: cmd.clone(),
        child,
        first,
        stdout,
        stderr,
    }
}

/// `exit 0`, `signal 15`, or `still running`.
fn said(status: Option<ExitStatus>) -> String {
    use std::os::unix::process::ExitStatusExt;
    match status {
        Some(s) => match (s.code(), s.signal()) {
            (Some(c), _) => format!("exit {c}"),
            (None, Some(sig)) => format!("signal {sig}"),
            _ => format!("{s}"),
        },
        None => "still running".into(),
    }
}

fn wait(child: &mut Child, limit: Duration) -> Option<ExitStatus> {
    let until = Instant::now() + limit;
    while Instant::now() < until {
        if let Some(status) = child.try_wait().unwrap() {
            return Some(status);
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    None
}

/// Ends a started command and returns (status, stdout, stderr); None if it would not stop.
fn end(mut s: Started, sig: Option<libc::c_int>) -> (Option<ExitStatus>, String, String) {
    if let Some(sig) = sig {
        common::signal_group(&s.child, sig);
    }
    let limit = if sig.is_some() {
        BACKGROUND_LIMIT
    } else {
        FOREGROUND_LIMIT
    };
    let status = wait(&mut s.child, limit);
    if status.is_none() {
        common::signal_group(&s.child, libc::SIGKILL);
        drop(s.child.wait());
    }
    let out = s.stdout.join().unwrap_or_default();
    let err = s.stderr.join().unwrap_or_default();
    (status, out, err)
}

/// Checks the first output line against the ``# prints`` comment, if any.
fn check_prints(s: &Started, problems: &mut Vec<String>) {
    let Some(want) = &s.cmd.prints else {
        std::thread::sleep(SETTLE);
        return;
    };
    match s.first.recv_timeout(BACKGROUND_LIMIT) {
        Ok(line) if matches(want, &line) => {}
        Ok(line) => problems.push(format!(
            "{}:{}: `{}` printed `{line}`, not `{want}`",
            s.cmd.page, s.cmd.line, s.cmd.text
        )),
        Err(_) => problems.push(format!(
            "{}:{}: `{}` printed nothing within {} s",
            s.cmd.page,
            s.cmd.line,
            s.cmd.text,
            BACKGROUND_LIMIT.as_secs()
        )),
    }
}

/// The share of ok cycles in a `run` summary (`samples: N (M ok, ...`), the lowest of its
/// valves'.
fn ok_share(summary: &str) -> Option<f64> {
    let shares: Option<Vec<f64>> = (summary.lines())
        .filter_map(|l| l.trim_start().strip_prefix("samples: "))
        .map(|rest| {
            let (n, rest) = rest.split_once(" (")?;
            let ok = rest.split_whitespace().next()?;
            Some(ok.parse::<f64>().ok()? / n.parse::<f64>().ok()?.max(1.0))
        })
        .collect();
    shares?.into_iter().reduce(f64::min)
}

/// Runs one block; returns what happened to each command, adding problems found.
fn run_block(scratch: &Scratch, block: &[Cmd], problems: &mut Vec<String>) -> Vec<String> {
    let mut report = Vec::new();
    if how(&block[0]) == How::Unknown {
        return vec![format!("{}:{}: text", block[0].page, block[0].line)];
    }
    let mut background: Vec<Started> = Vec::new();
    let holds_set_point = block.iter().any(|c| c.text.starts_with("while mbpoll"));
    for cmd in block {
        let h = how(cmd);
        let text = mapped(&cmd.text).unwrap_or_else(|| cmd.text.clone());
        let at = format!("{}:{}: `{}`", cmd.page, cmd.line, cmd.text);
        if let How::NotRun(why) = h {
            report.push(format!("{at}: not run ({why})"));
            continue;
        }
        if h == How::Unknown {
            problems.push(format!(
                "{at}: tests/docs/readme.rs has no rule for this program: run it or list it as not run"
            ));
            continue;
        }
        if let Some((tool, _, install)) = needs(cmd)
            .into_iter()
            .find(|(t, probe, install)| !tools::have(t, probe, install))
        {
            // A later command of the block may depend on this one: the block ends here.
            report.push(format!("{at}: SKIPPED, needs {tool} ({install})"));
            break;
        }
        let started = start(scratch, cmd, &text);
        if h == How::Background {
            check_prints(&started, problems);
            report.push(format!("{at}: started in the background"));
            background.push(started);
            continue;
        }
        let (status, out, err) = end(started, None);
        report.push(format!("{at}: ran, {}", said(status)));
        if !status.is_some_and(|s| s.success()) {
            problems.push(format!("{at}: {}\n{out}{err}", said(status)));
            continue;
        }
        if let Some(want) = &cmd.prints {
            let first = out.lines().next().unwrap_or("");
            if !matches(want, first) {
                problems.push(format!("{at}: printed `{first}`, not `{want}`"));
            }
        }
        if words(&text).starts_with(&["valve-bridge", "run"]) {
            let share = ok_share(&out).unwrap_or(0.0);
            if share < 0.9 {
                problems.push(format!(
                    "{at}: {:.0} % of the cycles ok\n{out}",
                    share * 100.0
                ));
            }
        }
    }
    while let Some(s) = background.pop() {
        let daemon = words(&mapped(&s.cmd.text).unwrap_or_else(|| s.cmd.text.clone()))
            .starts_with(&["valve-bridge", "run"]);
        let at = format!("{}:{}: `{}`", s.cmd.page, s.cmd.line, s.cmd.text);
        let (status, out, err) = end(s, Some(libc::SIGTERM));
        if status.is_none() {
            problems.push(format!("{at}: did not stop on SIGTERM\n{err}"));
        } else if daemon {
            if !status.is_some_and(|s| s.success())
                || !out.contains("\nrun: ") && !out.starts_with("run: ")
            {
                problems.push(format!("{at}: after SIGTERM {}\n{out}{err}", said(status)));
            }
            if holds_set_point && out.contains("watchdog: ") {
                problems.push(format!(
                    "{at}: the watchdog fired while the loop held the set-point\n{out}{err}"
                ));
            }
        }
        report.push(format!("{at}: stopped by SIGTERM, {}", said(status)));
    }
    report
}

/// README.md, then the pages of docs/ by name, each as (its path in the checkout, its text).
fn pages() -> Vec<(String, String)> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut names: Vec<String> = (std::fs::read_dir(root.join("docs")).expect("docs/ lists"))
        .map(|e| {
            e.expect("docs/ entry")
                .file_name()
                .to_string_lossy()
                .into_owned()
        })
        .filter(|n| n.ends_with(".md"))
        .map(|n| format!("docs/{n}"))
        .collect();
    names.sort();
    names.insert(0, "README.md".to_string());
    (names.into_iter())
        .map(|n| {
            let text = std::fs::read_to_string(root.join(&n)).expect("page reads");
            (n, text)
        })
        .collect()
}

#[test]
fn command_blocks_of_readme_and_docs_run_as_written() {
    let scratch = Scratch::new();
    let mut problems = Vec::new();
    let mut ran = 0;
    let pages = pages();
    for block in (pages.iter()).flat_map(|(page, text)| blocks(page, text)) {
        let report = run_block(&scratch, &block, &mut problems);
        ran += report
            .iter()
            .filter(|r| r.contains(": ran") || r.contains(": started"))
            .count();
        for line in report {
            println!("{line}");
        }
    }
    assert!(ran >= 10, "only {ran} commands of README and docs/ ran");
    assert!(problems.is_empty(), "{}", problems.join("\n\n"));
}

#[test]
fn set_up_builds_what_was_tested_and_says_each_step_once() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let pages = pages();
    // `cargo install` without `--locked` resolves every dependency anew, past the lock file
    // the tests ran with, and fails offline.
    for (page, text) in &pages {
        for (n, line) in text.lines().enumerate() {
            for (at, _) in line.match_indices("cargo install") {
                let command = line[at..].split(['`', '&', ';', '(']).next().unwrap_or("");
                assert!(
                    command.contains("--locked"),
                    "{page}:{}: `{command}` without --locked",
                    n + 1
                );
            }
        }
    }
    // README's test command is the one CI runs, as written.
    let readme = &pages[0].1;
    let test_command = (readme.lines())
        .map(str::trim)
        .find(|l| l.starts_with("cargo test --workspace"))
        .expect("README's set-up gives the test command");
    let ci = std::fs::read_to_string(root.join(".ci/run")).unwrap();
    assert!(
        ci.lines().any(|l| l.trim() == test_command),
        "`.ci/run` does not run README's test command `{test_command}`"
    );
    // The Python package is installed one way, in one place (README's set-up).
    let all: String = pages.iter().map(|(_, text)| text.as_str()).collect();
    let installs: Vec<&str> = ["maturin develop", "maturin build", "pip install dist"]
        .into_iter()
        .filter(|how| all.contains(how))
        .collect();
    let places: usize = installs.iter().map(|how| all.matches(how).count()).sum();
    assert_eq!(
        (installs.as_slice(), places),
        (&["maturin develop"][..], 1),
        "README and docs/ install the Python package in more than one way or place"
    );
    assert!(
        pages[0].1.contains("maturin develop"),
        "README's set-up installs it"
    );
    // What README's commands leave in the checkout is ignored by git.
    let ignore = std::fs::read_to_string(root.join(".gitignore")).unwrap();
    for written in ["/.venv/", "/demo-concealed.csv"] {
        assert!(
            ignore.lines().any(|l| l.trim() == written),
            ".gitignore does not ignore {written}"
        );
    }
}

#[test]
fn blocks_and_rules() {
    let text = "intro\n\n    valve-bridge run --config x.toml   # prints `modbus-server: 1.2.3.4:5`\n    mbpoll -a 1 \\\n        -r 2 host   # read\n\n```toml\nkey = 1\n```\n\n```sh\ncargo run --release -p sim-device -- --pty   # prints `pty: /dev/pts/N`\nsudo systemctl enable x\n```\n\n    O_P ──▶ V_P\n";
    let b = blocks("t.md", text);
    assert_eq!(b.len(), 3, "{b:?}");
    assert_eq!(b[0][0].prints.as_deref(), Some("modbus-server: 1.2.3.4:5"));
    assert_eq!(how(&b[0][0]), How::Background);
    assert_eq!(b[0][1].text, "mbpoll -a 1 -r 2 host");
    assert_eq!(b[0][1].line, 4);
    assert_eq!(how(&b[1][0]), How::Background);
    assert_eq!(mapped(&b[1][0].text).as_deref(), Some("sim-device --pty"));
    assert!(matches("pty: /dev/pts/N", "pty: /dev/pts/12"));
    assert!(!matches("pty: /dev/pts/N", "pty: /dev/ttyS1"));
    assert!(matches!(how(&b[1][1]), How::NotRun(_)));
    assert_eq!(how(&b[2][0]), How::Unknown, "the diagram is text");
    let run = |t: &str| {
        how(&Cmd {
            page: "t.md".into(),
            line: 1,
            text: t.into(),
            prints: None,
        })
    };
    assert_eq!(run("valve-bridge run --duration 5"), How::Foreground);
    assert_eq!(
        run("VB_BENCH_SECS=600 cargo bench --bench x"),
        How::NotRun("a benchmark (minutes; run by hand)")
    );
    assert_eq!(run("cargo run --release -- run"), How::Background);
    assert_eq!(split_comment("a 'b # c' # d").1, Some(" d"));
    assert!(matches!(
        run("maturin build --release -m python/Cargo.toml"),
        How::NotRun(_)
    ));
}

/// Every file of the checkout that README.md or a page of docs/ names in backticks
/// (`src/...`, `crates/...`, `tests/...`, `config/...`, `benches/...`, `docs/...`, `sim-device/...`,
/// `python/...`, `contrib/...`; a pattern such as `config/sim-device-NAME.toml` aside) exists:
/// a moved file leaves no stale path behind.
#[test]
fn files_the_documents_name_exist() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut pages = vec![root.join("README.md")];
    for entry in std::fs::read_dir(root.join("docs")).expect("docs/ lists") {
        let path = entry.expect("docs/ entry").path();
        if path.extension().is_some_and(|e| e == "md") {
            pages.push(path);
        }
    }
    let tops = [
        "src/",
        "crates/",
        "tests/",
        "config/",
        "benches/",
        "docs/",
        "sim-device/",
        "python/",
        "contrib/",
    ];
    let mut missing = Vec::new();
    for page in &pages {
        let text = std::fs::read_to_string(page).expect("page reads");
        // The spans between backticks, on every line.
        for (n, line) in text.lines().enumerate() {
            for quoted in line.split('`').skip(1).step_by(2) {
                let path = quoted.split([' ', ':', '#']).next().unwrap_or("");
                let named = tops.iter().any(|t| path.starts_with(t))
                    && !path.contains(['*', '<', '>', '{', '$'])
                    && !path.contains("NAME")
                    && path.len() > 4;
                if named && !root.join(path).exists() {
                    missing.push(format!("{}:{}: `{path}`", page.display(), n + 1));
                }
            }
        }
    }
    assert!(
        missing.is_empty(),
        "files named but not in the checkout:\n{}",
        missing.join("\n")
    );
}
