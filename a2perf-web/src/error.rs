//! Errors of the web-navigation crate.

use a2perf_core::EnvError;

/// Errors raised while loading designs, building websites or driving a browser.
#[derive(Debug, thiserror::Error)]
pub enum WebError {
    /// A design file could not be used.
    #[error("{path}: {reason}")]
    BadFile {
        /// The file.
        path: String,
        /// What is wrong with it.
        reason: String,
    },
    /// A configuration value is out of range.
    #[error("invalid configuration `{name}`: {reason}")]
    Config {
        /// Parameter name.
        name: String,
        /// What is wrong with it.
        reason: String,
    },
    /// Chromium or chromedriver is not installed where expected.
    #[error("browser unavailable: {0}")]
    BrowserUnavailable(String),
    /// The browser or its driver failed (the session may still be usable).
    #[error("browser failure: {0}")]
    Browser(String),
    /// The browser or its driver died or lost its session; a restart is needed.
    #[error("browser died: {0}")]
    BrowserDied(String),
    /// The browser's state disagrees with the website model (a parity violation).
    #[error("browser state disagrees with the website model: {0}")]
    Divergence(String),
}

impl WebError {
    /// Whether the browser must be restarted.
    pub fn is_browser_death(&self) -> bool {
        matches!(self, WebError::BrowserDied(_))
    }
}

impl From<WebError> for EnvError {
    fn from(e: WebError) -> Self {
        match e {
            WebError::BadFile { path, reason } => EnvError::BadFile { path, reason },
            WebError::Config { name, reason } => EnvError::InvalidParameter { name, reason },
            other => EnvError::Backend(other.to_string()),
        }
    }
}
