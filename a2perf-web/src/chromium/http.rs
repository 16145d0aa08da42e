//! HTTP on 127.0.0.1: a keep-alive client for chromedriver ([`ureq`], no TLS) and the server of
//! the current episode's page ([`tiny_http`]).

use std::net::TcpListener;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use crate::error::WebError;

/// A keep-alive HTTP/1.1 client of one server on 127.0.0.1.
pub(crate) struct HttpClient {
    agent: ureq::Agent,
    base: String,
    /// Limit of each socket read and write (not of the whole exchange: a slow page script may
    /// take long, a silent driver may not).
    pub(crate) timeout: Duration,
}

impl HttpClient {
    pub(crate) fn new(port: u16, timeout: Duration) -> Self {
        let agent = ureq::Agent::config_builder()
            // chromedriver's errors come as JSON bodies with 4xx/5xx statuses.
            .http_status_as_error(false)
            // A proxy from the environment must not see, or break, traffic to 127.0.0.1.
            .proxy(None)
            .build()
            .new_agent();
        Self {
            agent,
            base: format!("http://127.0.0.1:{port}"),
            timeout,
        }
    }

    /// Sends `body` (JSON, or nothing when empty) with `method` to `path` and returns the status
    /// and the body (invalid UTF-8 replaced). A pooled connection that the server had closed is
    /// noticed before it is used (ureq probes it), so the request is never sent twice.
    pub(crate) fn request(
        &self,
        method: &str,
        path: &str,
        body: &str,
    ) -> Result<(u16, String), ureq::Error> {
        let request = ureq::http::Request::builder()
            .method(method)
            .uri(format!("{}{path}", self.base))
            .header("Content-Type", "application/json; charset=utf-8")
            .body(body.to_owned())?;
        let request = self
            .agent
            .configure_request(request)
            .timeout_per_read(Some(self.timeout))
            .timeout_per_write(Some(self.timeout))
            .build();
        let mut response = self.agent.run(request)?;
        let status = response.status().as_u16();
        let text = response
            .body_mut()
            .with_config()
            .limit(u64::MAX)
            .lossy_utf8(true)
            .read_to_string()?;
        Ok((status, text))
    }
}

/// Serves the current page on 127.0.0.1 (any `GET /ep/...`; other paths get 404).
pub(crate) struct PageServer {
    pub(crate) port: u16,
    page: Arc<Mutex<String>>,
    server: Arc<tiny_http::Server>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl PageServer {
    pub(crate) fn start() -> Result<Self, WebError> {
        let server = tiny_http::Server::http(("127.0.0.1", 0))
            .map_err(|e| WebError::Browser(format!("cannot bind the page server: {e}")))?;
        let port = server
            .server_addr()
            .to_ip()
            .map(|a| a.port())
            .ok_or_else(|| WebError::Browser("the page server has no IP address".into()))?;
        let server = Arc::new(server);
        let page = Arc::new(Mutex::new(String::new()));
        let stop = Arc::new(AtomicBool::new(false));
        let (server2, page2, stop2) = (server.clone(), page.clone(), stop.clone());
        let thread = std::thread::Builder::new()
            .name("a2perf-web-pages".into())
            .spawn(move || {
                loop {
                    match server2.recv() {
                        Ok(request) => {
                            let _ = respond(request, &page2);
                        }
                        // `recv` fails when unblocked by `stop`, and on a failed accept.
                        Err(_) if stop2.load(Ordering::SeqCst) => break,
                        Err(_) => {}
                    }
                }
            })
            .map_err(|e| WebError::Browser(e.to_string()))?;
        Ok(Self {
            port,
            page,
            server,
            stop,
            thread: Some(thread),
        })
    }

    pub(crate) fn set(&self, html: String) {
        if let Ok(mut p) = self.page.lock() {
            *p = html;
        }
    }

    pub(crate) fn stop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        self.server.unblock();
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

fn respond(request: tiny_http::Request, page: &Mutex<String>) -> std::io::Result<()> {
    let (status, body) = if request.url().starts_with("/ep/") {
        (200, page.lock().map(|p| p.clone()).unwrap_or_default())
    } else {
        (404, String::from("not found"))
    };
    let header = |k: &str, v: &str| {
        tiny_http::Header::from_bytes(k.as_bytes(), v.as_bytes())
            .map_err(|()| std::io::Error::other(format!("bad header {k}")))
    };
    let response = tiny_http::Response::from_string(body)
        .with_status_code(status)
        .with_header(header("Content-Type", "text/html; charset=utf-8")?)
        .with_header(header("Cache-Control", "no-store")?);
    request.respond(response)
}

/// A port on 127.0.0.1 that was free a moment ago (for chromedriver's `--port`).
pub(crate) fn free_port() -> Result<u16, WebError> {
    let l = TcpListener::bind(("127.0.0.1", 0)).map_err(|e| WebError::Browser(e.to_string()))?;
    l.local_addr()
        .map(|a| a.port())
        .map_err(|e| WebError::Browser(e.to_string()))
}
