//! The browser session an environment drives: chromedriver and Chromium started with a fresh
//! profile, pages loaded and actions applied through the page script, the process tree ended on
//! shutdown.

use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::{Value as Json, json};

use super::http::{PageServer, free_port};
use super::options::ChromiumOptions;
use super::procmem::{TreeMemory, proc_stat, processes_with, with_descendants};
use super::webdriver::{WebDriver, died};
use crate::dom::{ActionKind, DomState, Event, Quirks};
use crate::error::WebError;
use crate::site::{Website, intern, shell_html};
use crate::vocab::Vocabulary;

/// Episodes between two navigations to a fresh page shell.
pub const RELOAD_EVERY: u64 = 100;

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
    webdriver: WebDriver,
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
            webdriver: WebDriver::new(driver_port),
            server,
            profile_dir: Some(profile_dir),
            profile_tag,
            episode: 0,
            since_navigation: RELOAD_EVERY,
            window: None,
        };
        let started = me
            .webdriver
            .start_session(&opts.chromium, &me.profile_tag, &opts.extra_args);
        if let Err(e) = started {
            me.shutdown();
            return Err(e);
        }
        Ok(me)
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
        self.webdriver.navigate(&url)?;
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
        self.webdriver.navigate(url)?;
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
        self.webdriver.screenshot_png()
    }

    /// Runs `script` with JSON `args` in the page (one round trip) and returns its result.
    pub fn execute(&mut self, script: &str, args: &str) -> Result<Json, WebError> {
        self.webdriver.execute(script, args)
    }

    /// Runs a Chrome DevTools Protocol command in the page's target through chromedriver
    /// (`goog/cdp/execute`) and returns its result (for diagnostics such as
    /// `Memory.getDOMCounters` or `Runtime.getHeapUsage`).
    pub fn cdp(&mut self, cmd: &str, params: Json) -> Result<Json, WebError> {
        self.webdriver.cdp(cmd, params)
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
        self.webdriver.end_session();
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
