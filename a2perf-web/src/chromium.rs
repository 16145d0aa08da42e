//! Real headless Chromium driven through chromedriver's W3C WebDriver JSON protocol.
//!
//! Everything is hand-written on `std::net`: a keep-alive HTTP/1.1 client for chromedriver and a
//! tiny HTTP server that serves the current episode's page on 127.0.0.1. One `execute/sync` call
//! per step runs the page's `a2p.step`, which applies the action and returns the new state.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{Shutdown, TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use serde_json::{Value as Json, json};

use crate::dom::{ActionKind, DomState, Event};
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

/// Extra flags that cut memory (renderer, GPU and network service in the browser process; no
/// extensions; a small JS heap limit) without changing what pages compute. Measured on 4
/// environments: about 190 MiB PSS per environment instead of about 300 MiB with 10 processes.
/// `--single-process` is a Chromium debugging mode; the parity, crash and shutdown tests run with
/// it. Set `A2PERF_CHROMIUM_ARGS=""` to use Chromium's normal process model.
pub const LEAN_FLAGS: [&str; 4] = [
    "--single-process",
    "--no-zygote",
    "--disable-extensions",
    "--js-flags=--max-old-space-size=64",
];

/// Where the browser and driver binaries are.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ChromiumOptions {
    /// The Chromium binary.
    pub chromium: PathBuf,
    /// The chromedriver binary.
    pub chromedriver: PathBuf,
    /// Flags added after [`CHROMIUM_FLAGS`] (default [`LEAN_FLAGS`]; `A2PERF_CHROMIUM_ARGS`,
    /// space-separated, replaces them).
    pub extra_args: Vec<String>,
}

impl ChromiumOptions {
    /// `A2PERF_CHROMIUM` / `A2PERF_CHROMEDRIVER`, else Debian's `/usr/bin/chromium` and
    /// `/usr/bin/chromedriver`.
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
        Self {
            chromium: pick(
                "A2PERF_CHROMIUM",
                &[
                    "/usr/bin/chromium",
                    "/usr/bin/chromium-browser",
                    "/usr/bin/google-chrome",
                ],
            ),
            chromedriver: pick(
                "A2PERF_CHROMEDRIVER",
                &["/usr/bin/chromedriver", "/usr/lib/chromium/chromedriver"],
            ),
            extra_args: match std::env::var("A2PERF_CHROMIUM_ARGS") {
                Ok(s) => s.split_whitespace().map(String::from).collect(),
                Err(_) => LEAN_FLAGS.iter().map(|s| s.to_string()).collect(),
            },
        }
    }

    /// `Ok` when both binaries exist, else the reason.
    pub fn check(&self) -> Result<(), WebError> {
        for p in [&self.chromium, &self.chromedriver] {
            if !p.exists() {
                return Err(WebError::BrowserUnavailable(format!(
                    "{} not found (install Debian's chromium and chromium-driver, or set \
                     A2PERF_CHROMIUM / A2PERF_CHROMEDRIVER)",
                    p.display()
                )));
            }
        }
        Ok(())
    }
}

/// Whether Chromium and chromedriver are installed (`Err` gives the reason).
pub fn chromium_available() -> Result<(), WebError> {
    ChromiumOptions::from_env().check()
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

/// Live processes whose command line contains `needle` (zombies have none).
fn processes_with(needle: &str) -> Vec<u32> {
    let mut out = Vec::new();
    let Ok(dir) = std::fs::read_dir("/proc") else {
        return out;
    };
    for e in dir.flatten() {
        let Some(pid) = e.file_name().to_str().and_then(|s| s.parse::<u32>().ok()) else {
            continue;
        };
        if let Ok(cmd) = std::fs::read(format!("/proc/{pid}/cmdline"))
            && String::from_utf8_lossy(&cmd).contains(needle)
        {
            out.push(pid);
        }
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

fn smaps_kb(pid: u32, keys: &[&str]) -> u64 {
    std::fs::read_to_string(format!("/proc/{pid}/smaps_rollup"))
        .map(|s| {
            s.lines()
                .filter(|l| keys.iter().any(|k| l.starts_with(k)))
                .filter_map(|l| {
                    l.split_whitespace()
                        .nth(1)
                        .and_then(|v| v.parse::<u64>().ok())
                })
                .sum()
        })
        .unwrap_or(0)
}

/// Memory of a browser process tree.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TreeMemory {
    /// Number of processes (chromedriver + Chromium's).
    pub processes: usize,
    /// Sum of resident set sizes, bytes (counts shared pages once per process).
    pub rss_bytes: u64,
    /// Sum of proportional set sizes, bytes (shared pages split between sharers).
    pub pss_bytes: u64,
    /// Sum of unique (private clean + dirty) set sizes, bytes: what this session alone holds;
    /// the browser's code pages are shared with other sessions and excluded.
    pub uss_bytes: u64,
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
    step_body: String,
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
            step_body: String::with_capacity(256),
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
                    "browserName": "chrome",
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
    /// which bounds the renderer's memory); each episode then replaces the website's elements in
    /// one script call.
    pub fn load(&mut self, site: &mut Website, state: &mut DomState) -> Result<(), WebError> {
        if self.since_navigation >= RELOAD_EVERY {
            self.load_html(shell_html("", ""))?;
            self.since_navigation = 0;
        }
        self.since_navigation += 1;
        let args = Json::Array(vec![
            Json::String(site.root_html(false)),
            Json::String(site.profile_text()),
        ]);
        let v = self.execute(
            "return a2pLoad(arguments[0], arguments[1]);",
            &args.to_string(),
        )?;
        ingest(&v, site, state)
    }

    /// Serves `html` (a page with the [`crate::site::SCRIPT`] API), navigates the browser to it,
    /// waits until it is live and returns its `a2p.state()`.
    pub fn load_html(&mut self, html: String) -> Result<Json, WebError> {
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
        loop {
            match self.execute(&probe, "[]") {
                Ok(Json::Null) | Err(WebError::Browser(_)) if Instant::now() < deadline => {
                    std::thread::sleep(Duration::from_millis(2));
                }
                Ok(Json::Null) => return Err(died("the page did not load within 30 s")),
                other => return other,
            }
        }
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

    /// Applies one action in the browser and reads the new state (one round trip).
    pub fn step(
        &mut self,
        site: &mut Website,
        state: &mut DomState,
        node: usize,
        kind: ActionKind,
    ) -> Result<(), WebError> {
        use std::fmt::Write as _;
        let (k, val) = match kind {
            ActionKind::Click => (0, Json::Null),
            ActionKind::Type(v) => (
                1,
                Json::String(site.strings.get(v as usize).cloned().unwrap_or_default()),
            ),
        };
        self.step_body.clear();
        let _ = write!(
            self.step_body,
            "{{\"script\":\"return a2p.step(arguments[0],arguments[1],arguments[2]);\",\"args\":[{k},{node},{val}]}}"
        );
        let path = format!("/session/{}/execute/sync", self.session);
        let body = std::mem::take(&mut self.step_body);
        let r = self.call("POST", &path, &body);
        self.step_body = body;
        ingest(&r?, site, state)
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

    /// Process ids of chromedriver and the browsers it started.
    pub fn pids(&self) -> Vec<u32> {
        let mut out: Vec<u32> = self.driver.as_ref().map(Child::id).into_iter().collect();
        for p in processes_with(&self.profile_tag) {
            if !out.contains(&p) {
                out.push(p);
            }
        }
        out
    }

    /// The unique string in every browser process's command line (its profile directory).
    pub fn profile_tag(&self) -> &str {
        &self.profile_tag
    }

    /// Memory of chromedriver plus every Chromium process of this session.
    pub fn memory(&self) -> TreeMemory {
        let pids = self.pids();
        TreeMemory {
            processes: pids.len(),
            rss_bytes: pids
                .iter()
                .map(|&p| proc_status_kb(p, "VmRSS:") * 1024)
                .sum(),
            pss_bytes: pids.iter().map(|&p| smaps_kb(p, &["Pss:"]) * 1024).sum(),
            uss_bytes: pids
                .iter()
                .map(|&p| smaps_kb(p, &["Private_Clean:", "Private_Dirty:"]) * 1024)
                .sum(),
        }
    }

    /// Ends the session, stops chromedriver and kills any remaining process of this browser.
    /// Idempotent.
    pub fn shutdown(&mut self) {
        if self.driver.is_none() && self.profile_dir.is_none() {
            return;
        }
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
        // path; end exactly those, by pid.
        let deadline = Instant::now() + Duration::from_secs(5);
        loop {
            let left = processes_with(&self.profile_tag);
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
