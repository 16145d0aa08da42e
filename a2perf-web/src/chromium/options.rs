//! Which browser and driver run, with which flags, and whether they are installed.

use std::path::{Path, PathBuf};

use crate::error::WebError;

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
/// chromedriver + browser, see [`TreeMemory`](super::TreeMemory); the table is in the crate README):
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
pub(crate) fn browser_name(binary: &Path) -> &'static str {
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
