//! Real headless Chromium driven through chromedriver's W3C WebDriver JSON protocol.
//!
//! chromedriver is spoken to with a keep-alive HTTP/1.1 client (`ureq`, without TLS), and a small
//! HTTP server (`tiny_http`) serves the current episode's page on 127.0.0.1. One call per step
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
//!
//! The code is split by concern: `options` (binaries and flags), `backend` (the session an
//! environment drives: launch, pages, steps, shutdown), `webdriver` (chromedriver's protocol),
//! `http` (the HTTP client and page server) and `procmem` (the browser's processes and their
//! memory, from `/proc`).

mod backend;
mod http;
mod options;
mod procmem;
mod webdriver;

pub use backend::{ChromiumBackend, RELOAD_EVERY, SnapshotElement};
pub use options::{
    CHROMIUM_FLAGS, ChromiumOptions, FULL_BROWSER_FLAGS, LEAN_FLAGS, chromium_available,
    chromium_for_tests, lean_flags, split_args,
};
pub use procmem::{TreeMemory, other_browser_processes};
