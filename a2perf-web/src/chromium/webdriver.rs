//! chromedriver's W3C WebDriver protocol (JSON over HTTP) with its Chrome extension
//! `goog/cdp/execute`: one session, navigation, scripts, DevTools commands and screenshots.
//! Failures are sorted into a dead browser ([`WebError::BrowserDied`], the environment restarts
//! it) and a failed command ([`WebError::Browser`]).

use std::path::Path;
use std::time::{Duration, Instant};

use base64::Engine as _;
use base64::engine::{DecodePaddingMode, GeneralPurpose, GeneralPurposeConfig};
use serde_json::{Value as Json, json};

use super::http::HttpClient;
use super::options::{CHROMIUM_FLAGS, browser_name};
use crate::error::WebError;

/// Socket timeout of WebDriver calls (a page script may take long under load).
const CALL_TIMEOUT: Duration = Duration::from_secs(60);
/// Socket timeout when ending the session: a browser that hangs is killed anyway.
const END_TIMEOUT: Duration = Duration::from_secs(10);

/// Standard base64 as WebDriver sends screenshots, padding optional.
const BASE64: GeneralPurpose = GeneralPurpose::new(
    &base64::alphabet::STANDARD,
    GeneralPurposeConfig::new()
        .with_decode_padding_mode(DecodePaddingMode::Indifferent)
        .with_decode_allow_trailing_bits(true),
);

pub(crate) fn died(what: impl std::fmt::Display) -> WebError {
    WebError::BrowserDied(what.to_string())
}

/// A chromedriver on 127.0.0.1 and (after [`start_session`](Self::start_session)) its session.
pub(crate) struct WebDriver {
    http: HttpClient,
    session: String,
}

impl WebDriver {
    pub(crate) fn new(port: u16) -> Self {
        Self {
            http: HttpClient::new(port, CALL_TIMEOUT),
            session: String::new(),
        }
    }

    /// Waits (20 s at most) until chromedriver answers, then starts a browser session with
    /// Chromium `binary`, its profile directory `profile` and the flags `extra` (after
    /// [`CHROMIUM_FLAGS`]).
    pub(crate) fn start_session(
        &mut self,
        binary: &Path,
        profile: &str,
        extra: &[String],
    ) -> Result<(), WebError> {
        let deadline = Instant::now() + Duration::from_secs(20);
        loop {
            match self.http.request("GET", "/status", "") {
                Ok((200, body)) if body.contains("\"ready\":true") => break,
                _ if Instant::now() > deadline => {
                    return Err(died("chromedriver did not become ready within 20 s"));
                }
                _ => std::thread::sleep(Duration::from_millis(50)),
            }
        }
        let mut args: Vec<String> = CHROMIUM_FLAGS.iter().map(|s| s.to_string()).collect();
        args.push(format!("--user-data-dir={profile}"));
        args.push("--window-size=800,600".into());
        args.extend(extra.iter().cloned());
        let caps = json!({
            "capabilities": {
                "alwaysMatch": {
                    "browserName": browser_name(binary),
                    // "none": chromedriver then skips its pending-navigation checks around
                    // every script call (a few ms per step); `load_html` waits for the page itself.
                    "pageLoadStrategy": "none",
                    "goog:chromeOptions": {
                        "binary": binary.display().to_string(),
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

    /// Ends the session, if one was started (errors ignored: the browser is killed next).
    pub(crate) fn end_session(&mut self) {
        if !self.session.is_empty() {
            self.http.timeout = END_TIMEOUT;
            let path = format!("/session/{}", self.session);
            let _ = self.http.request("DELETE", &path, "");
            self.session.clear();
        }
    }

    /// One WebDriver command: its `value`, or the error it reports, classified.
    fn call(&mut self, method: &str, path: &str, body: &str) -> Result<Json, WebError> {
        let (status, text) = self
            .http
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

    /// Starts navigating to `url` (with page-load strategy `none` it returns at once).
    pub(crate) fn navigate(&mut self, url: &str) -> Result<(), WebError> {
        let path = format!("/session/{}/url", self.session);
        self.call("POST", &path, &json!({ "url": url }).to_string())
            .map(drop)
    }

    /// Runs `script` with JSON `args` in the page (`execute/sync`) and returns its result.
    pub(crate) fn execute(&mut self, script: &str, args: &str) -> Result<Json, WebError> {
        let path = format!("/session/{}/execute/sync", self.session);
        let body = format!(
            "{{\"script\":{},\"args\":{args}}}",
            Json::String(script.into())
        );
        self.call("POST", &path, &body)
    }

    /// Runs a Chrome DevTools Protocol command in the page's target (`goog/cdp/execute`).
    pub(crate) fn cdp(&mut self, cmd: &str, params: Json) -> Result<Json, WebError> {
        let path = format!("/session/{}/goog/cdp/execute", self.session);
        self.call(
            "POST",
            &path,
            &json!({"cmd": cmd, "params": params}).to_string(),
        )
    }

    /// A PNG of the viewport.
    pub(crate) fn screenshot_png(&mut self) -> Result<Vec<u8>, WebError> {
        let path = format!("/session/{}/screenshot", self.session);
        let v = self.call("GET", &path, "")?;
        let text = v
            .as_str()
            .ok_or_else(|| WebError::Browser(format!("screenshot: not a string: {v:.100}")))?;
        decode_base64(text).ok_or_else(|| WebError::Browser("screenshot: bad base64".into()))
    }
}

fn decode_base64(text: &str) -> Option<Vec<u8>> {
    BASE64.decode(text).ok()
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
