//! Real headless Chromium driven through chromedriver's W3C WebDriver JSON protocol.
//!
//! Everything is hand-written on `std::net`: a keep-alive HTTP/1.1 client for chromedriver and a
//! tiny HTTP server that serves the current episode's page on 127.0.0.1. One call per step
//! (DevTools' `Runtime.callFunctionOn` through chromedriver's `goog/cdp/execute`) runs the
//! page's `a2p.step`, which applies the action and returns the new state.
//!
//! The browser is Debian's `chromium-headless-shell` (the "old headless" build, no full-browser
//! layer) when it is installed, else Debian's full `chromium`; both give identical pages, and
//! the parity tests pass with either. The headless shell with [`LEAN_FLAGS`] keeps a lone
//! environment under 200 MiB (about 160 MiB PSS for chromedriver + browser after the first
//! reset, 169–174 MiB after 1,200 to 10,000 steps); the full browser touches about 235 MiB of
//! its own code alone, so no flag brings it under 200 MB (about 330 MiB with [`LEAN_FLAGS`]'
//! memory flags; it runs with [`FULL_BROWSER_FLAGS`]). [`TreeMemory`] defines the measurement.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{Shutdown, TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use serde_json::{Value as Json, json};

use crate::dom::{ActionKind, DomState, Event, Quirks};
use crate::error::WebError;
use crate::site::{Website, intern, shell_html};

/// Episodes between two navigations to a fresh page shell.
pub const RELOAD_EVERY: u64 = 100;
use crate::vocab::Vocabulary;

/// Chromium flags used for every browser (the reference's list for this machine).
pub const CHROMIUM_FLAGS: [&str; 8] = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
];

/// Extra flags that cut memory without changing what pages compute (the parity, crash-restart
/// and shutdown tests run with them). Measured one by one on a lone environment (PSS of
/// chromedriver + browser, see [`TreeMemory`]; the table is in the crate README):
///
/// - `--single-process`, `--no-zygote`: browser, renderer, GPU and network service in one
///   process. Chromium's normal model (5–10 processes) costs 35–80 MiB more; it is a debugging
///   mode upstream, but one page on 127.0.0.1 is all it runs here.
/// - `--disable-software-rasterizer`: no SwiftShader GPU emulation (≈ 15 MiB).
/// - `--enable-low-end-device-mode`: Chromium's memory-saving caches and heap settings (≈ 7 MiB).
/// - `--enable-begin-frame-control` (headless shell): frames are produced only on request, and
///   nobody requests one, so nothing is painted or rastered; layout still runs whenever the
///   step script reads geometry (≈ 5 MiB, and a faster step).
/// - `--window-size=400,300`: the 375 px page fits; smaller compositor surfaces.
/// - `--js-flags`: 1 MiB semi-spaces and a 32 MiB old generation (the page's JS heap uses about
///   6 MB). Without a cap the heap grows when the machine is loaded and garbage collection lags
///   (217 MiB instead of ≈ 175 MiB after 1,200 steps with 64 MiB at load average 12); with
///   16 MiB the browser crashed (most likely out of JS heap; reported as interrupted) in 2 of 4
///   parity runs at load average 14–20, with 32 MiB in none of 5.
/// - `--disable-extensions`: nothing to load.
///
/// `A2PERF_CHROMIUM_ARGS` replaces this list (whitespace-separated, quotes group a value with
/// spaces, see [`split_args`]); `A2PERF_CHROMIUM_ARGS=""` gives Chromium's normal process model.
pub const LEAN_FLAGS: [&str; 8] = [
    "--single-process",
    "--no-zygote",
    "--disable-extensions",
    "--disable-software-rasterizer",
    "--enable-low-end-device-mode",
    "--enable-begin-frame-control",
    "--window-size=400,300",
    "--js-flags=--max-old-space-size=32 --max-semi-space-size=1",
];

/// The default extra flags for the full `chromium` browser (the headless shell gets
/// [`LEAN_FLAGS`]). The full browser cannot get under 200 MB with any flag (its own code is
/// ≈ 235 MiB), and its single-process V8 heap also holds its built-in pages (15 MB in use, it
/// crashed with a 16 MiB old generation); it keeps this longer-tested set (≈ 360 MiB for a lone
/// environment).
pub const FULL_BROWSER_FLAGS: [&str; 4] = [
    "--single-process",
    "--no-zygote",
    "--disable-extensions",
    "--js-flags=--max-old-space-size=64",
];

/// The default extra flags for the browser `binary`: [`LEAN_FLAGS`] for a headless shell,
/// [`FULL_BROWSER_FLAGS`] for a full browser.
///
/// ```
/// use a2perf_web::chromium::{FULL_BROWSER_FLAGS, LEAN_FLAGS, lean_flags};
/// use std::path::Path;
/// assert_eq!(lean_flags(Path::new("/usr/lib/chromium/chromium-headless-shell")), LEAN_FLAGS);
/// assert_eq!(lean_flags(Path::new("/usr/bin/chromium")), FULL_BROWSER_FLAGS);
/// ```
pub fn lean_flags(binary: &Path) -> Vec<String> {
    let flags: &[&str] = if browser_name(binary) == "chrome" {
        &FULL_BROWSER_FLAGS
    } else {
        &LEAN_FLAGS
    };
    flags.iter().map(|f| f.to_string()).collect()
}

/// Where the browser and driver binaries are.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ChromiumOptions {
    /// The Chromium binary (a file name containing `headless`, such as
    /// `chromium-headless-shell`, is driven as chromedriver's `chrome-headless-shell`).
    pub chromium: PathBuf,
    /// The chromedriver binary.
    pub chromedriver: PathBuf,
    /// Flags added after [`CHROMIUM_FLAGS`] (default [`lean_flags`]; `A2PERF_CHROMIUM_ARGS`,
    /// split by [`split_args`], replaces them). Where a flag repeats, the last one counts.
    pub extra_args: Vec<String>,
}

impl ChromiumOptions {
    /// `A2PERF_CHROMIUM` / `A2PERF_CHROMEDRIVER`, else Debian's headless shell
    /// (`/usr/lib/chromium/chromium-headless-shell`, package `chromium-headless-shell`), else
    /// `/usr/bin/chromium`, and `/usr/bin/chromedriver`.
    pub fn from_env() -> Self {
        let pick = |var: &str, candidates: &[&str]| {
            std::env::var_os(var).map(PathBuf::from).unwrap_or_else(|| {
                candidates
                    .iter()
                    .map(PathBuf::from)
                    .find(|p| p.exists())
                    .unwrap_or_else(|| PathBuf::from(candidates[0]))
            })
        };
        let chromium = pick(
            "A2PERF_CHROMIUM",
            &[
                "/usr/lib/chromium/chromium-headless-shell",
                "/usr/bin/chromium-headless-shell",
                "/usr/bin/chromium",
                "/usr/bin/chromium-browser",
                "/usr/bin/google-chrome",
            ],
        );
        Self {
            chromedriver: pick(
                "A2PERF_CHROMEDRIVER",
                &["/usr/bin/chromedriver", "/usr/lib/chromium/chromedriver"],
            ),
            extra_args: match std::env::var("A2PERF_CHROMIUM_ARGS") {
                Ok(s) => split_args(&s),
                Err(_) => lean_flags(&chromium),
            },
            chromium,
        }
    }

    /// `Ok` when both binaries exist, else the reason.
    pub fn check(&self) -> Result<(), WebError> {
        for p in [&self.chromium, &self.chromedriver] {
            if !p.exists() {
                return Err(WebError::BrowserUnavailable(format!(
                    "{} not found (install Debian's chromium-driver and chromium-headless-shell \
                     or chromium, or set A2PERF_CHROMIUM / A2PERF_CHROMEDRIVER)",
                    p.display()
                )));
            }
        }
        Ok(())
    }
}

/// Splits a flag list at whitespace outside quotes (`'…'` or `"…"`, quotes removed), so that a
/// value with spaces such as `--js-flags="--a=1 --b=2"` stays one argument.
///
/// ```
/// use a2perf_web::chromium::split_args;
/// assert_eq!(
///     split_args(r#"--x  --js-flags="--a=1 --b=2" 'c d'"#),
///     ["--x", "--js-flags=--a=1 --b=2", "c d"]
/// );
/// ```
pub fn split_args(s: &str) -> Vec<String> {
    let (mut out, mut cur, mut quote, mut open) = (Vec::new(), String::new(), None, false);
    for c in s.chars() {
        match (quote, c) {
            (Some(q), c) if c == q => quote = None,
            (Some(_), c) => cur.push(c),
            (None, '"' | '\'') => {
                quote = Some(c);
                open = true;
            }
            (None, c) if c.is_whitespace() => {
                if open {
                    out.push(std::mem::take(&mut cur));
                    open = false;
                }
            }
            (None, c) => {
                cur.push(c);
                open = true;
            }
        }
    }
    if open {
        out.push(cur);
    }
    out
}

/// chromedriver's name for the browser behind `binary`: the headless shell opens no page at
/// start and chromedriver only waits for one when told it is not the full browser.
fn browser_name(binary: &Path) -> &'static str {
    let name = binary.file_name().map(|n| n.to_string_lossy().into_owned());
    if name.is_some_and(|n| n.contains("headless")) {
        "chrome-headless-shell"
    } else {
        "chrome"
    }
}

/// Whether Chromium and chromedriver are installed (`Err` gives the reason).
pub fn chromium_available() -> Result<(), WebError> {
    ChromiumOptions::from_env().check()
}

/// The rule of every browser test suite: `Ok(true)` when Chromium can be used; otherwise the
/// reason is printed (`SKIP: …`) and `Ok(false)` returned, unless `A2PERF_REQUIRE_CHROME=1`
/// (set by CI), where a missing browser is the `Err`.
pub fn chromium_for_tests() -> Result<bool, WebError> {
    match chromium_available() {
        Ok(()) => Ok(true),
        Err(e) if std::env::var("A2PERF_REQUIRE_CHROME").as_deref() == Ok("1") => Err(e),
        Err(e) => {
            println!("SKIP: {e}");
            Ok(false)
        }
    }
}

fn died(what: impl std::fmt::Display) -> WebError {
    WebError::BrowserDied(what.to_string())
}

/// A keep-alive HTTP/1.1 connection to one server on 127.0.0.1.
struct HttpConn {
    port: u16,
    reader: Option<BufReader<TcpStream>>,
    timeout: Duration,
}

impl HttpConn {
    fn new(port: u16, timeout: Duration) -> Self {
        Self {
            port,
            reader: None,
            timeout,
        }
    }

    fn connect(&mut self) -> std::io::Result<&mut BufReader<TcpStream>> {
        if self.reader.is_none() {
            let s = TcpStream::connect(("127.0.0.1", self.port))?;
            s.set_nodelay(true)?;
            s.set_read_timeout(Some(self.timeout))?;
            s.set_write_timeout(Some(self.timeout))?;
            self.reader = Some(BufReader::new(s));
        }
        self.reader
            .as_mut()
            .ok_or_else(|| std::io::Error::other("no connection"))
    }

    fn request(&mut self, method: &str, path: &str, body: &str) -> std::io::Result<(u16, String)> {
        let reused = self.reader.is_some();
        match self.request_once(method, path, body) {
            // A kept-alive connection the server had closed: the request was not processed, so
            // retrying on a fresh connection cannot apply an action twice. Timeouts are not
            // retried.
            Err(e)
                if reused
                    && matches!(
                        e.kind(),
                        std::io::ErrorKind::UnexpectedEof
                            | std::io::ErrorKind::ConnectionReset
                            | std::io::ErrorKind::ConnectionAborted
                            | std::io::ErrorKind::BrokenPipe
                    ) =>
            {
                self.reader = None;
                self.request_once(method, path, body)
            }
            Err(e) => {
                self.reader = None;
                Err(e)
            }
            ok => ok,
        }
    }

    fn request_once(
        &mut self,
        method: &str,
        path: &str,
        body: &str,
    ) -> std::io::Result<(u16, String)> {
        let port = self.port;
        let reader = self.connect()?;
        let head = format!(
            "{method} {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nContent-Type: application/json; charset=utf-8\r\nContent-Length: {}\r\nConnection: keep-alive\r\n\r\n",
            body.len()
        );
        {
            let s = reader.get_mut();
            let mut buf = Vec::with_capacity(head.len() + body.len());
            buf.extend_from_slice(head.as_bytes());
            buf.extend_from_slice(body.as_bytes());
            s.write_all(&buf)?;
        }
        let mut line = String::new();
        if reader.read_line(&mut line)? == 0 {
            self.reader = None;
            return Err(std::io::Error::new(
                std::io::ErrorKind::UnexpectedEof,
                "connection closed",
            ));
        }
        let status: u16 = line
            .split_whitespace()
            .nth(1)
            .and_then(|s| s.parse().ok())
            .ok_or_else(|| std::io::Error::other(format!("bad status line {line:?}")))?;
        let mut length: Option<usize> = None;
        let mut chunked = false;
        let mut close = false;
        loop {
            line.clear();
            if reader.read_line(&mut line)? == 0 {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::UnexpectedEof,
                    "eof in headers",
                ));
            }
            let l = line.trim_end();
            if l.is_empty() {
                break;
            }
            if let Some((k, v)) = l.split_once(':') {
                let (k, v) = (k.trim().to_ascii_lowercase(), v.trim());
                match k.as_str() {
                    "content-length" => length = v.parse().ok(),
                    "transfer-encoding" => chunked = v.eq_ignore_ascii_case("chunked"),
                    "connection" => close = v.eq_ignore_ascii_case("close"),
                    _ => {}
                }
            }
        }
        let mut body = Vec::new();
        if chunked {
            loop {
                line.clear();
                reader.read_line(&mut line)?;
                let n = usize::from_str_radix(line.trim().split(';').next().unwrap_or("0"), 16)
                    .map_err(|e| std::io::Error::other(e.to_string()))?;
                if n == 0 {
                    line.clear();
                    reader.read_line(&mut line)?;
                    break;
                }
                let start = body.len();
                body.resize(start + n, 0);
                reader.read_exact(&mut body[start..])?;
                line.clear();
                reader.read_line(&mut line)?;
            }
        } else if let Some(n) = length {
            body.resize(n, 0);
            reader.read_exact(&mut body)?;
        } else {
            reader.read_to_end(&mut body)?;
            close = true;
        }
        if close {
            self.reader = None;
        }
        Ok((status, String::from_utf8_lossy(&body).into_owned()))
    }
}

/// Serves the current page on 127.0.0.1 (any `GET /ep/...`).
struct PageServer {
    port: u16,
    page: Arc<Mutex<String>>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

fn serve(mut s: TcpStream, page: &Mutex<String>) -> std::io::Result<()> {
    s.set_read_timeout(Some(Duration::from_secs(5)))?;
    let mut reader = BufReader::new(s.try_clone()?);
    let mut first = String::new();
    reader.read_line(&mut first)?;
    let mut line = String::new();
    loop {
        line.clear();
        if reader.read_line(&mut line)? == 0 || line.trim_end().is_empty() {
            break;
        }
    }
    let path = first.split_whitespace().nth(1).unwrap_or("/");
    let (status, body) = if path.starts_with("/ep/") {
        let html = page.lock().map(|p| p.clone()).unwrap_or_default();
        ("200 OK", html)
    } else {
        ("404 Not Found", String::from("not found"))
    };
    let head = format!(
        "HTTP/1.1 {status}\r\nContent-Type: text/html; charset=utf-8\r\nContent-Length: {}\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n",
        body.len()
    );
    s.write_all(head.as_bytes())?;
    s.write_all(body.as_bytes())?;
    s.flush()?;
    let _ = s.shutdown(Shutdown::Write);
    Ok(())
}

impl PageServer {
    fn start() -> Result<Self, WebError> {
        let listener = TcpListener::bind(("127.0.0.1", 0))
            .map_err(|e| WebError::Browser(format!("cannot bind the page server: {e}")))?;
        let port = listener
            .local_addr()
            .map_err(|e| WebError::Browser(e.to_string()))?
            .port();
        let page = Arc::new(Mutex::new(String::new()));
        let stop = Arc::new(AtomicBool::new(false));
        let (p2, s2) = (page.clone(), stop.clone());
        let thread = std::thread::Builder::new()
            .name("a2perf-web-pages".into())
            .spawn(move || {
                for conn in listener.incoming() {
                    if s2.load(Ordering::SeqCst) {
                        break;
                    }
                    if let Ok(c) = conn {
                        let _ = serve(c, &p2);
                    }
                }
            })
            .map_err(|e| WebError::Browser(e.to_string()))?;
        Ok(Self {
            port,
            page,
            stop,
            thread: Some(thread),
        })
    }

    fn set(&self, html: String) {
        if let Ok(mut p) = self.page.lock() {
            *p = html;
        }
    }

    fn stop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        let _ = TcpStream::connect(("127.0.0.1", self.port));
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for PageServer {
    fn drop(&mut self) {
        self.stop();
    }
}

fn free_port() -> Result<u16, WebError> {
    let l = TcpListener::bind(("127.0.0.1", 0)).map_err(|e| WebError::Browser(e.to_string()))?;
    l.local_addr()
        .map(|a| a.port())
        .map_err(|e| WebError::Browser(e.to_string()))
}

/// The pids listed in `/proc` (none where it is missing).
fn all_pids() -> impl Iterator<Item = u32> {
    std::fs::read_dir("/proc")
        .into_iter()
        .flatten()
        .flatten()
        .filter_map(|e| e.file_name().to_str().and_then(|s| s.parse::<u32>().ok()))
}

/// Live processes whose command line contains `needle` (zombies have none).
fn processes_with(needle: &str) -> Vec<u32> {
    let mut out = Vec::new();
    for pid in all_pids() {
        if let Ok(cmd) = std::fs::read(format!("/proc/{pid}/cmdline"))
            && String::from_utf8_lossy(&cmd).contains(needle)
        {
            out.push(pid);
        }
    }
    out
}

/// Parent pid and start time (clock ticks after boot) of a live process; `None` for zombies and
/// processes that are gone.
fn proc_stat(pid: u32) -> Option<(u32, u64)> {
    let s = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // Fields after the parenthesised command name: state, ppid, ..., starttime (20th).
    let mut f = s.rsplit_once(')')?.1.split_whitespace();
    if matches!(f.next(), Some("Z" | "X") | None) {
        return None;
    }
    let ppid = f.next()?.parse().ok()?;
    let start = f.nth(17)?.parse().ok()?;
    Some((ppid, start))
}

/// `roots` and every live descendant of theirs. The process tree matters because not every
/// Chromium child carries the profile directory on its command line (the headless shell's
/// renderer and GPU processes do not).
fn with_descendants(roots: &[u32]) -> Vec<u32> {
    let mut table: Vec<(u32, u32)> = Vec::new();
    if let Ok(dir) = std::fs::read_dir("/proc") {
        for e in dir.flatten() {
            if let Some(pid) = e.file_name().to_str().and_then(|s| s.parse::<u32>().ok())
                && let Some((ppid, _)) = proc_stat(pid)
            {
                table.push((pid, ppid));
            }
        }
    }
    let mut out: Vec<u32> = roots
        .iter()
        .copied()
        .filter(|&r| table.iter().any(|&(p, _)| p == r))
        .collect();
    let mut k = 0;
    while k < out.len() {
        let parent = out[k];
        for &(p, pp) in &table {
            if pp == parent && !out.contains(&p) {
                out.push(p);
            }
        }
        k += 1;
    }
    out
}

fn proc_status_kb(pid: u32, key: &str) -> u64 {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with(key))
                .and_then(|l| l.split_whitespace().nth(1).and_then(|v| v.parse().ok()))
        })
        .unwrap_or(0)
}

/// The `smaps_rollup` fields of one process, in kB.
#[derive(Clone, Copy, Default)]
struct Rollup {
    pss: u64,
    pss_anon: u64,
    pss_file: u64,
    pss_shmem: u64,
    private: u64,
}

fn rollup(pid: u32) -> Rollup {
    let mut r = Rollup::default();
    let Ok(text) = std::fs::read_to_string(format!("/proc/{pid}/smaps_rollup")) else {
        return r;
    };
    for l in text.lines() {
        let mut it = l.split_whitespace();
        let (Some(key), Some(v)) = (it.next(), it.next().and_then(|v| v.parse::<u64>().ok()))
        else {
            continue;
        };
        match key {
            "Pss:" => r.pss += v,
            "Pss_Anon:" => r.pss_anon += v,
            "Pss_File:" => r.pss_file += v,
            "Pss_Shmem:" => r.pss_shmem += v,
            "Private_Clean:" | "Private_Dirty:" => r.private += v,
            _ => {}
        }
    }
    r
}

/// Memory of one environment's browser: chromedriver plus every Chromium process of its
/// session, read from `/proc/<pid>/status` and `/proc/<pid>/smaps_rollup`.
///
/// **The figure we report as "RAM of an environment" is [`pss_bytes`](Self::pss_bytes)**: the
/// proportional set size summed over that whole process tree. A page mapped by k processes counts
/// 1/k in each, so the sum over the tree is what the tree holds, with the pages it shares with
/// processes *outside* the tree (other environments' Chromium code, libc) split fairly. For a
/// **lone** environment — the case of a user running one — nothing else maps Chromium's binary,
/// so the tree pays for every code page it touched; that is the figure the < 200 MB target is
/// about. With N environments side by side, the binary's pages are split N ways and the
/// per-environment PSS is lower. [`uss_bytes`](Self::uss_bytes) (private pages only) is a lower
/// bound that stays the same however many environments run; summed RSS counts a page once per
/// process that maps it and overstates the tree. The breakdown into anonymous (heaps, JS),
/// file-backed (mostly the Chromium binary's code and data) and shared-memory pages says where
/// the memory goes. Measure only when no unrelated Chromium runs on the machine
/// ([`other_browser_processes`]), else the lone figure comes out too low.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TreeMemory {
    /// Number of processes (chromedriver + Chromium's).
    pub processes: usize,
    /// Sum of resident set sizes, bytes (counts shared pages once per process).
    pub rss_bytes: u64,
    /// Sum of proportional set sizes, bytes (shared pages split between sharers): the reported
    /// "RAM of the environment".
    pub pss_bytes: u64,
    /// Anonymous part of [`pss_bytes`](Self::pss_bytes) (heaps, JS, stacks).
    pub pss_anon_bytes: u64,
    /// File-backed part of [`pss_bytes`](Self::pss_bytes) (binary and library pages).
    pub pss_file_bytes: u64,
    /// Shared-memory part of [`pss_bytes`](Self::pss_bytes) (Chromium's IPC buffers between
    /// its processes).
    pub pss_shmem_bytes: u64,
    /// Sum of unique (private clean + dirty) set sizes, bytes: what this session alone holds;
    /// pages shared with any other process, inside or outside the tree, are excluded.
    pub uss_bytes: u64,
}

impl TreeMemory {
    /// The per-environment average of several environments' figures (integer division; the
    /// default for an empty slice).
    ///
    /// ```
    /// use a2perf_web::TreeMemory;
    /// let a = TreeMemory { processes: 2, pss_bytes: 100, ..TreeMemory::default() };
    /// let b = TreeMemory { processes: 2, pss_bytes: 300, ..TreeMemory::default() };
    /// assert_eq!(TreeMemory::mean(&[a, b]).pss_bytes, 200);
    /// ```
    pub fn mean(all: &[TreeMemory]) -> Self {
        let n = all.len().max(1);
        let per = |f: fn(&TreeMemory) -> u64| all.iter().map(f).sum::<u64>() / n as u64;
        TreeMemory {
            processes: all.iter().map(|m| m.processes).sum::<usize>() / n,
            rss_bytes: per(|m| m.rss_bytes),
            pss_bytes: per(|m| m.pss_bytes),
            pss_anon_bytes: per(|m| m.pss_anon_bytes),
            pss_file_bytes: per(|m| m.pss_file_bytes),
            pss_shmem_bytes: per(|m| m.pss_shmem_bytes),
            uss_bytes: per(|m| m.uss_bytes),
        }
    }

    /// The memory of the processes `pids` (those that have exited count 0).
    pub fn of(pids: &[u32]) -> Self {
        let mut m = TreeMemory {
            processes: pids.len(),
            ..Self::default()
        };
        for &p in pids {
            let r = rollup(p);
            m.rss_bytes += proc_status_kb(p, "VmRSS:") * 1024;
            m.pss_bytes += r.pss * 1024;
            m.pss_anon_bytes += r.pss_anon * 1024;
            m.pss_file_bytes += r.pss_file * 1024;
            m.pss_shmem_bytes += r.pss_shmem * 1024;
            m.uss_bytes += r.private * 1024;
        }
        m
    }
}

/// Live Chromium or chromedriver processes on this machine (their pids), whichever session they
/// belong to. Used to warn that a lone environment's PSS is being measured next to other
/// browsers that share its code pages.
pub fn other_browser_processes() -> Vec<u32> {
    let me = std::process::id();
    let mut out = Vec::new();
    for pid in all_pids() {
        if pid == me {
            continue;
        }
        if let Ok(exe) = std::fs::read_link(format!("/proc/{pid}/exe")) {
            let name = exe
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            if name.starts_with("chrom") || name == "headless_shell" {
                out.push(pid);
            }
        }
    }
    out
}

/// A visible element as the browser reports it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SnapshotElement {
    /// Element index (`data-n`).
    pub index: usize,
    /// Tag token (`input_text`, `div`, …).
    pub tag: String,
    /// Text of leaf elements.
    pub text: String,
    /// `placeholder` attribute.
    pub placeholder: String,
    /// `class` attribute.
    pub classes: String,
}

/// A headless Chromium session with its chromedriver and page server.
pub struct ChromiumBackend {
    driver: Option<Child>,
    driver_port: u16,
    conn: HttpConn,
    session: String,
    server: PageServer,
    profile_dir: Option<tempfile::TempDir>,
    profile_tag: String,
    episode: u64,
    since_navigation: u64,
    /// DevTools handle of the current document's `window` (see [`Self::call_in_page`]).
    window: Option<String>,
}

impl ChromiumBackend {
    /// Starts chromedriver and a headless Chromium with a fresh profile directory.
    pub fn launch(opts: &ChromiumOptions) -> Result<Self, WebError> {
        opts.check()?;
        let profile_dir = tempfile::Builder::new()
            .prefix("a2perf-web-chromium-")
            .tempdir()
            .map_err(|e| WebError::Browser(format!("cannot create a profile directory: {e}")))?;
        let profile_tag = profile_dir.path().display().to_string();
        let server = PageServer::start()?;
        let driver_port = free_port()?;
        let driver = Command::new(&opts.chromedriver)
            .arg(format!("--port={driver_port}"))
            .arg("--allowed-ips=127.0.0.1")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .map_err(|e| {
                WebError::BrowserUnavailable(format!(
                    "cannot start {}: {e}",
                    opts.chromedriver.display()
                ))
            })?;
        let mut me = Self {
            driver: Some(driver),
            driver_port,
            conn: HttpConn::new(driver_port, Duration::from_secs(60)),
            session: String::new(),
            server,
            profile_dir: Some(profile_dir),
            profile_tag,
            episode: 0,
            since_navigation: RELOAD_EVERY,
            window: None,
        };
        if let Err(e) = me.start_session(&opts.chromium, &opts.extra_args) {
            me.shutdown();
            return Err(e);
        }
        Ok(me)
    }

    fn start_session(&mut self, chromium: &Path, extra: &[String]) -> Result<(), WebError> {
        let deadline = Instant::now() + Duration::from_secs(20);
        loop {
            match self.conn.request("GET", "/status", "") {
                Ok((200, body)) if body.contains("\"ready\":true") => break,
                _ if Instant::now() > deadline => {
                    return Err(died("chromedriver did not become ready within 20 s"));
                }
                _ => std::thread::sleep(Duration::from_millis(50)),
            }
        }
        let mut args: Vec<String> = CHROMIUM_FLAGS.iter().map(|s| s.to_string()).collect();
        args.push(format!("--user-data-dir={}", self.profile_tag));
        args.push("--window-size=800,600".into());
        args.extend(extra.iter().cloned());
        let caps = json!({
            "capabilities": {
                "alwaysMatch": {
                    "browserName": browser_name(chromium),
                    // "none": chromedriver then skips its pending-navigation checks around
                    // every script call (a few ms per step); `load_html` waits for the page itself.
                    "pageLoadStrategy": "none",
                    "goog:chromeOptions": {
                        "binary": chromium.display().to_string(),
                        "args": args,
                    }
                }
            }
        });
        let v = self.call("POST", "/session", &caps.to_string())?;
        self.session = v
            .get("sessionId")
            .and_then(Json::as_str)
            .ok_or_else(|| WebError::Browser(format!("no session id in {v}")))?
            .to_string();
        Ok(())
    }

    fn call(&mut self, method: &str, path: &str, body: &str) -> Result<Json, WebError> {
        let (status, text) = self
            .conn
            .request(method, path, body)
            .map_err(|e| died(format!("chromedriver connection: {e}")))?;
        let v: Json = serde_json::from_str(&text)
            .map_err(|e| WebError::Browser(format!("bad chromedriver reply ({e}): {text:.200}")))?;
        let value = v.get("value").cloned().unwrap_or(Json::Null);
        if status != 200 {
            let err = value.get("error").and_then(Json::as_str).unwrap_or("");
            let msg = value.get("message").and_then(Json::as_str).unwrap_or("");
            let fatal = matches!(
                err,
                "invalid session id" | "session not created" | "no such window"
            ) || msg.contains("not reachable")
                || msg.contains("disconnected")
                || msg.contains("session deleted")
                || msg.contains("target window already closed")
                || msg.contains("crashed");
            let text = format!("{err}: {}", msg.lines().next().unwrap_or(""));
            return Err(if fatal {
                died(text)
            } else {
                WebError::Browser(text)
            });
        }
        Ok(value)
    }

    /// Loads `site` (fresh page) and reads its initial state into `state`.
    ///
    /// The page shell is loaded by navigation once (and again every [`RELOAD_EVERY`] episodes,
    /// which bounds the renderer's memory, followed by a memory-pressure signal that empties
    /// V8's caches); each episode then replaces the website's elements in one script call.
    pub fn load(&mut self, site: &mut Website, state: &mut DomState) -> Result<(), WebError> {
        if self.since_navigation >= RELOAD_EVERY {
            self.load_html(shell_html("", ""))?;
            self.since_navigation = 0;
            self.release_caches()?;
        }
        self.since_navigation += 1;
        let args = [site.root_html(false), site.profile_text()].map(Json::String);
        let v = self.call_in_page("function(h,p){return this.a2pLoad(h,p);}", &args)?;
        ingest(&v, site, state)
    }

    /// Tells the browser it is under critical memory pressure, which makes V8 run a
    /// memory-reducing full GC and drop its caches (Blink purges its caches too).
    ///
    /// chromedriver wraps every script call in a fresh function whose source text embeds its
    /// helper library and the call's JSON arguments, so each step and reset compiles a new,
    /// unique script of several kB. An ordinary full GC (`gc()` with `--expose-gc`) frees none
    /// of what accumulates, a memory-reducing one does (most likely V8's compilation cache of
    /// those scripts): without it the page's JS heap grew from 6 to ≈ 20 MB over 10,000 steps
    /// and a lone environment from 174 to ≈ 190 MiB PSS. Running this at each page reload
    /// ([`RELOAD_EVERY`] episodes, ≈ 9 ms) kept it at ≈ 171 MiB, ≈ 169 MiB together with
    /// [`call_in_page`](Self::call_in_page). A browser or driver without the command is left as
    /// it is; only a dead browser is an error.
    fn release_caches(&mut self) -> Result<(), WebError> {
        match self.cdp(
            "Memory.simulatePressureNotification",
            json!({ "level": "critical" }),
        ) {
            Err(e @ WebError::BrowserDied(_)) => Err(e),
            _ => Ok(()),
        }
    }

    /// Serves `html` (a page with the [`crate::site::SCRIPT`] API), navigates the browser to it,
    /// waits until it is live and returns its `a2p.state()`.
    pub fn load_html(&mut self, html: String) -> Result<Json, WebError> {
        self.window = None;
        self.episode += 1;
        let ep = self.episode;
        // The episode number tells the new document from the previous one while navigating.
        let marker = format!("<script>window.a2pEpisode={ep};</script>\n<div id=\"a2p-root\">");
        self.server
            .set(html.replacen("<div id=\"a2p-root\">", &marker, 1));
        let url = format!("http://127.0.0.1:{}/ep/{ep}", self.server.port);
        let path = format!("/session/{}/url", self.session);
        self.call("POST", &path, &json!({ "url": url }).to_string())?;
        let probe = format!(
            "return (window.a2pEpisode === {ep} && window.a2p && document.readyState !== 'loading') ? a2p.state() : null;"
        );
        let deadline = Instant::now() + Duration::from_secs(30);
        let state = loop {
            match self.execute(&probe, "[]") {
                Ok(Json::Null) | Err(WebError::Browser(_)) if Instant::now() < deadline => {
                    std::thread::sleep(Duration::from_millis(2));
                }
                Ok(Json::Null) => return Err(died("the page did not load within 30 s")),
                other => break other?,
            }
        };
        self.window = match self.cdp(
            "Runtime.evaluate",
            json!({ "expression": "window", "objectGroup": "a2perf" }),
        ) {
            Ok(v) => v
                .pointer("/result/objectId")
                .and_then(Json::as_str)
                .map(String::from),
            Err(e @ WebError::BrowserDied(_)) => return Err(e),
            Err(_) => None,
        };
        Ok(state)
    }

    /// Calls `function` (a constant JS function declaration, `this` = the page's `window`) with
    /// `args` through DevTools' `Runtime.callFunctionOn`; when the current document has no
    /// DevTools handle, through [`execute`](Self::execute) instead (same function, same result).
    ///
    /// chromedriver's `execute/sync` wraps every call in a new function whose source embeds its
    /// helper library and the call's JSON arguments, so each step compiled a unique script of
    /// several kB: ≈ 1 ms per step, and ≈ 10 MiB more per lone environment over 10,000 steps
    /// (most likely V8 keeps such scripts in its compilation cache until memory pressure). Here
    /// the source is the same on every call and the arguments travel as values.
    fn call_in_page(&mut self, function: &str, args: &[Json]) -> Result<Json, WebError> {
        let Some(window) = &self.window else {
            let script = format!("return ({function}).apply(window, arguments);");
            return self.execute(&script, &Json::Array(args.to_vec()).to_string());
        };
        let params = json!({
            "objectId": window,
            "functionDeclaration": function,
            "arguments": Json::Array(args.iter().map(|a| json!({ "value": a })).collect()),
            "returnByValue": true,
        });
        let mut r = self.cdp("Runtime.callFunctionOn", params)?;
        if let Some(ex) = r.get("exceptionDetails") {
            let text = ex
                .pointer("/exception/description")
                .or_else(|| ex.get("text"))
                .and_then(Json::as_str)
                .unwrap_or("exception");
            return Err(WebError::Browser(format!("page script: {text}")));
        }
        Ok(r.pointer_mut("/result/value")
            .map(Json::take)
            .unwrap_or(Json::Null))
    }

    /// Navigates to `url` (any page, e.g. a `file://` report) and waits until its document has
    /// loaded (`document.readyState` is `complete`). The next [`load`](Self::load) starts from
    /// a fresh page shell.
    pub fn navigate(&mut self, url: &str) -> Result<(), WebError> {
        self.window = None;
        self.since_navigation = RELOAD_EVERY;
        let path = format!("/session/{}/url", self.session);
        self.call("POST", &path, &json!({ "url": url }).to_string())?;
        let probe = "return document.readyState === 'complete' && location.href === new URL(arguments[0]).href;";
        let args = Json::Array(vec![Json::String(url.into())]).to_string();
        let deadline = Instant::now() + Duration::from_secs(30);
        loop {
            match self.execute(probe, &args) {
                Ok(Json::Bool(true)) => return Ok(()),
                Ok(_) | Err(WebError::Browser(_)) if Instant::now() < deadline => {
                    std::thread::sleep(Duration::from_millis(10));
                }
                Ok(_) => return Err(died(format!("{url} did not load within 30 s"))),
                Err(e) => return Err(e),
            }
        }
    }

    /// A PNG of the browser's viewport as it is now.
    pub fn screenshot_png(&mut self) -> Result<Vec<u8>, WebError> {
        let path = format!("/session/{}/screenshot", self.session);
        let v = self.call("GET", &path, "")?;
        let text = v
            .as_str()
            .ok_or_else(|| WebError::Browser(format!("screenshot: not a string: {v:.100}")))?;
        decode_base64(text).ok_or_else(|| WebError::Browser("screenshot: bad base64".into()))
    }

    /// Runs `script` with JSON `args` in the page (one round trip) and returns its result.
    pub fn execute(&mut self, script: &str, args: &str) -> Result<Json, WebError> {
        let path = format!("/session/{}/execute/sync", self.session);
        let body = format!(
            "{{\"script\":{},\"args\":{args}}}",
            Json::String(script.into())
        );
        self.call("POST", &path, &body)
    }

    /// Runs a Chrome DevTools Protocol command in the page's target through chromedriver
    /// (`goog/cdp/execute`) and returns its result (for diagnostics such as
    /// `Memory.getDOMCounters` or `Runtime.getHeapUsage`).
    pub fn cdp(&mut self, cmd: &str, params: Json) -> Result<Json, WebError> {
        let path = format!("/session/{}/goog/cdp/execute", self.session);
        self.call(
            "POST",
            &path,
            &json!({"cmd": cmd, "params": params}).to_string(),
        )
    }

    /// Applies one action in the browser and reads the new state (one round trip).
    pub fn step(
        &mut self,
        site: &mut Website,
        state: &mut DomState,
        node: usize,
        kind: ActionKind,
        quirks: Quirks,
    ) -> Result<(), WebError> {
        let value =
            |v: u32| Json::String(site.strings.get(v as usize).cloned().unwrap_or_default());
        let (k, val) = match kind {
            ActionKind::Click => (0, Json::Null),
            ActionKind::Type(v) => (1, value(v)),
            ActionKind::Visit(v) => (2, v.map_or(Json::Null, value)),
        };
        // `visitGroup` acts on the element that owns the id (see `Website::id_owner`).
        let node = match kind {
            ActionKind::Visit(_) => site.id_owner.get(node).map_or(node, |&o| o as usize),
            _ => node,
        };
        let args = [json!(k), json!(node), val, json!(quirks.cc_bug)];
        let v = self.call_in_page("function(k,n,v,b){return this.a2p.step(k,n,v,b);}", &args)?;
        ingest(&v, site, state)
    }

    /// Every visible element's tag, text, placeholder and class as the browser reports them
    /// (for checking the static model against the real DOM).
    pub fn snapshot(&mut self) -> Result<Vec<SnapshotElement>, WebError> {
        let script = "var out=[];document.querySelectorAll('#a2p-root [data-n]').forEach(function(e){var b=e.getBoundingClientRect();if(b.width>0||b.height>0){var t=e.tagName.toLowerCase();if(t==='input')t='input_'+e.type;var tx='';if(e.children.length===0&&t!=='select')tx=e.textContent;out.push([+e.dataset.n,t,tx,e.getAttribute('placeholder')||'',e.className]);}});return out;";
        let v = self.execute(script, "[]")?;
        let arr = v
            .as_array()
            .ok_or_else(|| WebError::Browser("snapshot: not an array".into()))?;
        Ok(arr
            .iter()
            .map(|e| {
                let s = |i: usize| e.get(i).and_then(Json::as_str).unwrap_or("").to_string();
                SnapshotElement {
                    index: e.get(0).and_then(Json::as_u64).unwrap_or(u64::MAX) as usize,
                    tag: s(1),
                    text: s(2),
                    placeholder: s(3),
                    classes: s(4),
                }
            })
            .collect())
    }

    /// Process ids of chromedriver and every live process of its browser: chromedriver's
    /// descendants plus any process carrying this session's profile directory (a browser whose
    /// chromedriver died) and its descendants.
    pub fn pids(&self) -> Vec<u32> {
        let mut roots: Vec<u32> = self.driver.as_ref().map(Child::id).into_iter().collect();
        roots.extend(processes_with(&self.profile_tag));
        with_descendants(&roots)
    }

    /// The unique string in every browser process's command line (its profile directory).
    pub fn profile_tag(&self) -> &str {
        &self.profile_tag
    }

    /// Memory of chromedriver plus every Chromium process of this session (see [`TreeMemory`]
    /// for what the figures mean).
    pub fn memory(&self) -> TreeMemory {
        TreeMemory::of(&self.pids())
    }

    /// [`memory`](Self::memory) split by process: pid, role (`chromedriver`, `browser` or
    /// Chromium's `--type=` such as `renderer`, `gpu-process`, `utility`) and its memory.
    pub fn memory_by_process(&self) -> Vec<(u32, String, TreeMemory)> {
        let driver = self.driver.as_ref().map(Child::id);
        self.pids()
            .into_iter()
            .map(|p| {
                let role = if Some(p) == driver {
                    "chromedriver".to_string()
                } else {
                    // Chromium rewrites its children's argv into one space-separated string.
                    std::fs::read(format!("/proc/{p}/cmdline"))
                        .ok()
                        .and_then(|c| {
                            let c = String::from_utf8_lossy(&c).into_owned();
                            c.split(['\0', ' '])
                                .find_map(|a| a.strip_prefix("--type="))
                                .map(String::from)
                        })
                        .unwrap_or_else(|| "browser".into())
                };
                (p, role, TreeMemory::of(&[p]))
            })
            .collect()
    }

    /// Ends the session, stops chromedriver and kills any remaining process of this browser.
    /// Idempotent.
    pub fn shutdown(&mut self) {
        if self.driver.is_none() && self.profile_dir.is_none() {
            return;
        }
        // Remembered with start times so that a recycled pid is never killed.
        let tree: Vec<(u32, u64)> = self
            .pids()
            .into_iter()
            .filter_map(|p| proc_stat(p).map(|(_, start)| (p, start)))
            .collect();
        if !self.session.is_empty() {
            self.conn.timeout = Duration::from_secs(10);
            let path = format!("/session/{}", self.session);
            let _ = self.conn.request("DELETE", &path, "");
            self.session.clear();
        }
        self.conn.reader = None;
        if let Some(mut d) = self.driver.take() {
            let _ = d.kill();
            let _ = d.wait();
        }
        // Chromium processes left behind (e.g. after chromedriver died) carry our unique profile
        // path or were in the tree; end exactly those, by pid.
        let deadline = Instant::now() + Duration::from_secs(5);
        loop {
            let mut left = processes_with(&self.profile_tag);
            for &(p, start) in &tree {
                if proc_stat(p).is_some_and(|(_, s)| s == start) && !left.contains(&p) {
                    left.push(p);
                }
            }
            if left.is_empty() || Instant::now() > deadline {
                break;
            }
            for pid in left {
                let _ = Command::new("kill")
                    .arg("-9")
                    .arg(pid.to_string())
                    .stdout(Stdio::null())
                    .stderr(Stdio::null())
                    .status();
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        self.server.stop();
        if let Some(d) = self.profile_dir.take() {
            let _ = d.close();
        }
    }

    /// Port of chromedriver (for diagnostics).
    pub fn driver_port(&self) -> u16 {
        self.driver_port
    }
}

impl Drop for ChromiumBackend {
    fn drop(&mut self) {
        self.shutdown();
    }
}

/// Standard base64 (padding optional, no line breaks), as WebDriver sends screenshots.
fn decode_base64(text: &str) -> Option<Vec<u8>> {
    let digit = |c: u8| -> Option<u32> {
        Some(match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            _ => return None,
        } as u32)
    };
    let bytes = text.trim_end_matches('=').as_bytes();
    let mut out = Vec::with_capacity(bytes.len() * 3 / 4);
    for chunk in bytes.chunks(4) {
        if chunk.len() == 1 {
            return None;
        }
        let mut acc = 0u32;
        for (i, &c) in chunk.iter().enumerate() {
            acc |= digit(c)? << (18 - 6 * i);
        }
        out.extend_from_slice(&acc.to_be_bytes()[1..chunk.len()]);
    }
    Some(out)
}

/// Reads the page script's state object into `state`, checking it against the model.
fn ingest(v: &Json, site: &mut Website, state: &mut DomState) -> Result<(), WebError> {
    let bad = |what: &str| WebError::Browser(format!("malformed page state: {what}"));
    let vis = v
        .get("v")
        .and_then(Json::as_array)
        .ok_or_else(|| bad("v"))?;
    let cls = v
        .get("c")
        .and_then(Json::as_array)
        .ok_or_else(|| bad("c"))?;
    let vals = v
        .get("x")
        .and_then(Json::as_array)
        .ok_or_else(|| bad("x"))?;
    let visited = v
        .get("w")
        .and_then(Json::as_array)
        .ok_or_else(|| bad("w"))?;
    if vis.len() != cls.len() * 5
        || vals.len() != site.controls.len()
        || visited.len() != vals.len()
    {
        return Err(bad("lengths"));
    }
    let n = site.nodes.len();
    state.visible.iter_mut().for_each(|x| *x = false);
    state.order.clear();
    for (k, c) in cls.iter().enumerate() {
        let f = |j: usize| vis[k * 5 + j].as_f64().unwrap_or(f64::NAN) as f32;
        let i = vis[k * 5].as_u64().map_or(usize::MAX, |x| x as usize);
        if i >= n {
            return Err(bad("element index"));
        }
        state.visible[i] = true;
        state.order.push(i as u32);
        state.rect[i] = [f(1), f(2), f(3), f(4)];
        let c = c.as_str().unwrap_or("");
        let mut is_visited = false;
        let mut rest = c.split_whitespace().filter(|w| {
            if *w == "visited" {
                is_visited = true;
                false
            } else {
                true
            }
        });
        let model = &site.nodes[i].classes;
        if !rest.by_ref().eq(model.split_whitespace()) {
            return Err(WebError::Divergence(format!(
                "element {i}: class `{c}` in the browser, `{model}` in the model"
            )));
        }
        state.visited[i] = is_visited;
    }
    for (k, &ci) in site.controls.iter().enumerate() {
        let ci = ci as usize;
        let s = vals[k].as_str().unwrap_or("");
        if site.nodes[ci].tag.is_toggle() {
            state.checked[ci] = s == "true";
        } else {
            let id = match site.strings.iter().position(|x| x == s) {
                Some(p) => p as u32,
                None => {
                    let id = intern(&mut site.strings, s);
                    site.string_tokens.push(Vocabulary::standard().encode(s));
                    id
                }
            };
            state.value[ci] = id;
        }
        state.visited[ci] = visited[k].as_u64() == Some(1);
    }
    state.focused = v
        .get("f")
        .and_then(Json::as_i64)
        .filter(|&f| f >= 0 && (f as usize) < n)
        .map(|f| f as u32);
    state.page = v.get("p").and_then(Json::as_u64).unwrap_or(0) as u16;
    state.event = match v.get("e").and_then(Json::as_str) {
        Some("distractor") => Event::Distractor,
        Some("submit") => Event::Submit,
        _ => Event::None,
    };
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::decode_base64;

    #[test]
    fn base64_decodes_with_and_without_padding() {
        assert_eq!(decode_base64("aGVsbG8=").as_deref(), Some(&b"hello"[..]));
        assert_eq!(decode_base64("aGVsbG8").as_deref(), Some(&b"hello"[..]));
        assert_eq!(decode_base64("aGk+Pz8/").as_deref(), Some(&b"hi>???"[..]));
        assert_eq!(decode_base64("").as_deref(), Some(&b""[..]));
        assert_eq!(decode_base64("a$=="), None);
        assert_eq!(decode_base64("aGVsb"), None);
    }
}
