//! Headless Chromium driven over WebDriver: chromedriver on a free loopback port, one session
//! with a fresh profile. Everything it started is killed on drop, on a panic too.

use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use fantoccini::{Client, ClientBuilder, Locator};

/// The Chromium switches of every session: headless, nothing fetched from outside, a laptop's
/// window.
const CHROMIUM_ARGS: [&str; 9] = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--window-size=1280,900",
];

/// Chromium and chromedriver, as `ROOMLIGHT_CHROMIUM` and `ROOMLIGHT_CHROMEDRIVER` or Debian
/// installs them; `None` (after saying why) when one is missing outside CI. In CI (`CI` set)
/// a missing one fails the test: CI installs both.
pub fn find_browser() -> Option<(PathBuf, PathBuf)> {
    let path = |var: &str, default: &str| {
        std::env::var_os(var).map_or_else(|| PathBuf::from(default), PathBuf::from)
    };
    let chromium = path("ROOMLIGHT_CHROMIUM", "/usr/bin/chromium");
    let driver = path("ROOMLIGHT_CHROMEDRIVER", "/usr/bin/chromedriver");
    let missing: Vec<String> = [&chromium, &driver]
        .into_iter()
        .filter(|p| !p.is_file())
        .map(|p| p.display().to_string())
        .collect();
    if missing.is_empty() {
        return Some((chromium, driver));
    }
    let why = format!(
        "{} not found (apt-get install chromium chromium-driver, or set ROOMLIGHT_CHROMIUM / ROOMLIGHT_CHROMEDRIVER)",
        missing.join(" and ")
    );
    assert!(std::env::var_os("CI").is_none(), "{why}");
    println!("SKIPPED: {why}");
    None
}

/// A WebDriver session in headless Chromium. The session is dropped before its driver.
pub struct Browser {
    pub client: Client,
    _driver: Driver,
}

/// chromedriver and the profile its Chromium writes in.
struct Driver {
    process: Child,
    profile: tempfile::TempDir,
}

impl Drop for Driver {
    fn drop(&mut self) {
        // chromedriver leads a process group of its own; Chromium and its helpers are in it.
        let _ = Command::new("kill")
            .args(["-KILL", "--", &format!("-{}", self.process.id())])
            .stderr(Stdio::null())
            .status();
        let _ = self.process.wait();
        // A helper that left the group (none is known to) still names the profile.
        for pid in processes_naming(self.profile.path()) {
            let _ = Command::new("kill")
                .args(["-KILL", &pid.to_string()])
                .stderr(Stdio::null())
                .status();
        }
    }
}

/// Processes whose command line names `path`.
fn processes_naming(path: &Path) -> Vec<u32> {
    let needle = path.to_string_lossy().into_owned();
    let Ok(entries) = std::fs::read_dir("/proc") else {
        return Vec::new();
    };
    entries
        .filter_map(|e| e.ok()?.file_name().to_str()?.parse::<u32>().ok())
        .filter(|pid| {
            std::fs::read(format!("/proc/{pid}/cmdline"))
                .is_ok_and(|c| String::from_utf8_lossy(&c).contains(&needle))
        })
        .collect()
}

impl Browser {
    /// Starts chromedriver on a free port, waits (at most 20 s) until its `/status` says ready,
    /// and opens a session of `chromium` with a fresh profile.
    pub async fn start(chromium: &Path, chromedriver: &Path) -> Self {
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .expect("a free port")
            .port();
        let profile = tempfile::tempdir().expect("profile dir");
        let child = Command::new(chromedriver)
            .arg(format!("--port={port}"))
            .process_group(0)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap_or_else(|e| panic!("starting {}: {e}", chromedriver.display()));
        // Owned from here on, so that a failure below still kills it.
        let driver = Driver {
            process: child,
            profile,
        };
        let address = format!("127.0.0.1:{port}");
        // Nothing tells when chromedriver is ready but its answer: asked every 50 ms.
        let mut tick = tokio::time::interval(Duration::from_millis(50));
        let wake = async || {
            tick.tick().await;
        };
        until_woken(
            "chromedriver ready",
            Duration::from_secs(20),
            wake,
            async || {
                let answer = super::http::request(&address, "GET", "/status", None, None)
                    .map_err(|e| e.to_string())?;
                let ready = answer.json("chromedriver status")["value"]["ready"] == true;
                ready.then_some(()).ok_or(answer.body)
            },
        )
        .await;
        let mut args: Vec<String> = CHROMIUM_ARGS.iter().map(|a| a.to_string()).collect();
        args.push(format!(
            "--user-data-dir={}",
            driver.profile.path().display()
        ));
        let capabilities = serde_json::json!({
            "browserName": "chrome",
            "goog:chromeOptions": { "binary": chromium, "args": args },
        });
        let serde_json::Value::Object(capabilities) = capabilities else {
            unreachable!("an object")
        };
        let client = ClientBuilder::new(hyper_util::client::legacy::connect::HttpConnector::new())
            .capabilities(capabilities)
            .connect(&format!("http://{address}"))
            .await
            .expect("a Chromium session");
        Browser {
            client,
            _driver: driver,
        }
    }

    /// Checks `check` until it gives `Ok`, at most `within`, waking at each change of the page
    /// (its DOM) instead of on a clock; the last `Err` (what was seen instead) is in the panic.
    pub async fn until<T>(
        &self,
        what: &str,
        within: Duration,
        check: impl AsyncFnMut() -> Result<T, String>,
    ) -> T {
        until_woken(what, within, async || self.next_change().await, check).await
    }

    /// Returns at the page's next DOM change (a `MutationObserver`), or after 250 ms without
    /// one: a plot drawn on a canvas, a file written or an answer of the API change no node.
    /// A page being replaced (navigation) ends the wait too.
    async fn next_change(&self) {
        const SCRIPT: &str = "const done = arguments[arguments.length - 1];\
            const seen = new MutationObserver(() => { seen.disconnect(); done(true); });\
            seen.observe(document, { subtree: true, childList: true, attributes: true, characterData: true });\
            setTimeout(() => { seen.disconnect(); done(false); }, 250);";
        // An error (the page navigated away mid-script) is a change as good as any.
        let _ = self.client.execute_async(SCRIPT, Vec::new()).await;
    }

    /// Runs `script` (a function body: `return ...`) in the page.
    pub async fn js(&self, script: &str) -> serde_json::Value {
        self.client
            .execute(script, Vec::new())
            .await
            .unwrap_or_else(|e| panic!("{e}: running {script}"))
    }

    pub async fn click(&self, css: &str) {
        self.client
            .find(Locator::Css(css))
            .await
            .unwrap_or_else(|e| panic!("finding {css}: {e}"))
            .click()
            .await
            .unwrap_or_else(|e| panic!("clicking {css}: {e}"));
    }

    pub async fn type_into(&self, css: &str, text: &str) {
        let field = self
            .client
            .find(Locator::Css(css))
            .await
            .unwrap_or_else(|e| panic!("finding {css}: {e}"));
        field.clear().await.expect("clear");
        field
            .send_keys(text)
            .await
            .unwrap_or_else(|e| panic!("typing into {css}: {e}"));
    }

    /// A PNG of the window, scrolled to the top, in `dir/NAME.png`; its path.
    pub async fn screenshot(&self, dir: &Path, name: &str) -> PathBuf {
        self.js("window.scrollTo(0, 0); return null").await;
        let png = self.client.screenshot().await.expect("screenshot");
        std::fs::create_dir_all(dir).expect("screenshot dir");
        let path = dir
            .canonicalize()
            .expect("screenshot dir")
            .join(format!("{name}.png"));
        std::fs::write(&path, png).expect("write screenshot");
        println!("screenshot {name}: {}", path.display());
        path
    }
}

/// Checks `check` until it gives `Ok`, at most `within`; the last `Err` (what was seen
/// instead) is in the panic. Between checks it waits for `wake` (the page's next change, or a
/// tick of the clock where nothing in the page tells).
async fn until_woken<T>(
    what: &str,
    within: Duration,
    mut wake: impl AsyncFnMut(),
    mut check: impl AsyncFnMut() -> Result<T, String>,
) -> T {
    let deadline = Instant::now() + within;
    loop {
        match check().await {
            Ok(value) => return value,
            Err(seen) if Instant::now() >= deadline => {
                panic!("{what}: not within {within:?}; last seen: {seen}")
            }
            Err(_) => wake().await,
        }
    }
}
