//! A small Chrome DevTools Protocol driver for the browser tests: starts
//! headless Chromium, opens one page, collects what went wrong on it (console
//! errors, uncaught exceptions, error log entries, broken images) and takes a
//! full-page screenshot. Tests only.
//!
//! Transport: `--remote-debugging-pipe` (JSON messages ended by a NUL byte,
//! read by Chromium on fd 3 and written on fd 4), not a WebSocket. That needs
//! no new dependency at all (a WebSocket client such as `tungstenite` would add
//! about ten crates to build on CI's two cores, `headless_chrome` many more),
//! no port and no `DevTools listening on` line to parse; and when the test
//! process dies for any reason its end of the pipe closes and Chromium exits
//! by itself. `Drop` kills it as well, so a failing test leaves no browser.
//!
//! Protocol reference: <https://chromedevtools.github.io/devtools-protocol/>.

use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

use base64::Engine;
use serde_json::{Value, json};

/// How long any single wait on Chromium may take.
pub const TIMEOUT: Duration = Duration::from_secs(30);

/// Width of the viewport for screenshots (px); wider than the report's
/// 1100 px column.
pub const VIEWPORT_WIDTH_PX: u32 = 1200;

/// Flags for a quiet, self-contained headless browser. Without the
/// background-networking ones Chromium tries to reach Google's services,
/// which a closed network refuses.
const FLAGS: &[&str] = &[
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--remote-debugging-pipe",
];

/// What went wrong talking to Chromium.
#[derive(Debug, thiserror::Error)]
pub enum CdpError {
    #[error(
        "Chromium is not installed (no `chromium` on PATH). The browser tests need \
         Debian's `chromium` package: `apt-get install -y chromium` (.ci/run installs it)"
    )]
    NotInstalled,
    #[error("could not start Chromium ({}): {source}", path.display())]
    Launch {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error(
        "no answer from Chromium within {} s while waiting for {what}\n--- end of Chromium's log ---\n{log}",
        TIMEOUT.as_secs()
    )]
    Timeout { what: String, log: String },
    #[error(
        "Chromium closed the DevTools pipe while waiting for {what}\n--- end of Chromium's log ---\n{log}"
    )]
    Closed { what: String, log: String },
    #[error("Chromium sent a malformed message: {0}")]
    Malformed(String),
    #[error("{method} failed: {message}")]
    Protocol { method: String, message: String },
    #[error("opening {url} failed: {error}")]
    Navigate { url: String, error: String },
    #[error("{context}: {source}")]
    Io {
        context: String,
        #[source]
        source: std::io::Error,
    },
    #[error("Page.captureScreenshot returned bad base64: {0}")]
    Screenshot(#[from] base64::DecodeError),
}

/// The images of a page.
#[derive(Debug)]
pub struct Images {
    /// Number of `<img>` elements.
    pub total: usize,
    /// The broken ones (not complete, or no natural width), each as
    /// "alt: first characters of src".
    pub broken: Vec<String>,
}

/// A running headless Chromium with one page attached.
pub struct Browser {
    child: Child,
    to_chromium: ChildStdin,
    from_chromium: Receiver<Result<Value, String>>,
    next_id: u64,
    /// The page's flat-mode session.
    session: String,
    /// The page's events since the last `open`, in arrival order.
    events: Vec<Value>,
    /// Holds the profile (`profile/`) and Chromium's stderr (`chromium.log`).
    dir: tempfile::TempDir,
}

impl Browser {
    /// Start Chromium with a new empty profile, attach to a new blank page
    /// and enable the Runtime, Log and Page domains on it.
    pub fn launch() -> Result<Self, CdpError> {
        let chromium = find_on_path("chromium").ok_or(CdpError::NotInstalled)?;
        let dir = tempfile::tempdir().map_err(|source| CdpError::Io {
            context: "a folder for Chromium's profile".into(),
            source,
        })?;
        let log_path = dir.path().join("chromium.log");
        let log = std::fs::File::create(&log_path).map_err(|source| CdpError::Io {
            context: log_path.display().to_string(),
            source,
        })?;
        // std's Command sets only fds 0-2, so a shell moves our two pipes to
        // fds 3 and 4 before it execs Chromium (no unsafe pre_exec needed).
        // Debian's /usr/bin/chromium is itself a script that execs the
        // browser, so the child's pid is the browser's.
        let mut child = Command::new("sh")
            .arg("-c")
            .arg(r#"exec "$0" "$@" 3<&0 4>&1 0</dev/null 1>&2"#)
            .arg(&chromium)
            .args(FLAGS)
            .arg(format!(
                "--user-data-dir={}",
                dir.path().join("profile").display()
            ))
            .arg("about:blank")
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(log)
            .spawn()
            .map_err(|source| CdpError::Launch {
                path: chromium.clone(),
                source,
            })?;
        let to_chromium = child.stdin.take().expect("stdin is piped");
        let stdout = child.stdout.take().expect("stdout is piped");
        let (tx, from_chromium) = mpsc::channel();
        // A reader thread turns the byte stream into messages, so every wait
        // can time out (`recv_timeout`). It ends when Chromium closes fd 4.
        std::thread::spawn(move || {
            let mut reader = BufReader::new(stdout);
            let mut buf = Vec::new();
            loop {
                buf.clear();
                match reader.read_until(0, &mut buf) {
                    Ok(0) | Err(_) => return,
                    Ok(_) => {
                        if buf.last() == Some(&0) {
                            buf.pop();
                        }
                        let msg = serde_json::from_slice::<Value>(&buf).map_err(|e| {
                            format!(
                                "{e}: {}",
                                String::from_utf8_lossy(&buf[..buf.len().min(200)])
                            )
                        });
                        if tx.send(msg).is_err() {
                            return;
                        }
                    }
                }
            }
        });
        let mut browser = Self {
            child,
            to_chromium,
            from_chromium,
            next_id: 0,
            session: String::new(),
            events: Vec::new(),
            dir,
        };
        let target = browser.send("Target.createTarget", json!({"url": "about:blank"}), None)?;
        let target_id = target["targetId"].as_str().unwrap_or_default().to_string();
        let attached = browser.send(
            "Target.attachToTarget",
            json!({"targetId": target_id, "flatten": true}),
            None,
        )?;
        browser.session = attached["sessionId"]
            .as_str()
            .ok_or_else(|| CdpError::Malformed(format!("attachToTarget gave {attached}")))?
            .to_string();
        for domain in ["Runtime", "Log", "Page"] {
            browser.call(&format!("{domain}.enable"), json!({}))?;
        }
        Ok(browser)
    }

    /// Send a command to the page and wait for its result.
    pub fn call(&mut self, method: &str, params: Value) -> Result<Value, CdpError> {
        let session = self.session.clone();
        self.send(method, params, Some(&session))
    }

    /// Send a command (to the page's session, or to the browser when
    /// `session` is `None`) and wait for its result, keeping the page's
    /// events that arrive meanwhile.
    fn send(
        &mut self,
        method: &str,
        params: Value,
        session: Option<&str>,
    ) -> Result<Value, CdpError> {
        self.next_id += 1;
        let id = self.next_id;
        let mut msg = json!({"id": id, "method": method, "params": params});
        if let Some(s) = session {
            msg["sessionId"] = json!(s);
        }
        let mut bytes = serde_json::to_vec(&msg).expect("a JSON value serialises");
        bytes.push(0);
        self.to_chromium
            .write_all(&bytes)
            .and_then(|()| self.to_chromium.flush())
            .map_err(|source| CdpError::Io {
                context: format!("sending {method} to Chromium"),
                source,
            })?;
        let what = format!("the answer to {method}");
        let deadline = Instant::now() + TIMEOUT;
        loop {
            let msg = self.next_message(&what, deadline)?;
            if msg["id"].as_u64() == Some(id) {
                if let Some(err) = msg.get("error") {
                    return Err(CdpError::Protocol {
                        method: method.to_string(),
                        message: err["message"].as_str().unwrap_or_default().to_string(),
                    });
                }
                return Ok(msg["result"].clone());
            }
        }
    }

    /// The next message from Chromium before `deadline`; the page's events
    /// are recorded on the way.
    fn next_message(&mut self, what: &str, deadline: Instant) -> Result<Value, CdpError> {
        let left = deadline.saturating_duration_since(Instant::now());
        match self.from_chromium.recv_timeout(left) {
            Ok(Ok(msg)) => {
                if msg.get("method").is_some()
                    && msg["sessionId"].as_str() == Some(self.session.as_str())
                {
                    self.events.push(msg.clone());
                }
                Ok(msg)
            }
            Ok(Err(bad)) => Err(CdpError::Malformed(bad)),
            Err(RecvTimeoutError::Timeout) => Err(CdpError::Timeout {
                what: what.to_string(),
                log: self.log_tail(),
            }),
            Err(RecvTimeoutError::Disconnected) => Err(CdpError::Closed {
                what: what.to_string(),
                log: self.log_tail(),
            }),
        }
    }

    /// Open a local file and wait for its load event. Forgets the events of
    /// the page before.
    pub fn open(&mut self, path: &Path) -> Result<(), CdpError> {
        let path = path.canonicalize().map_err(|source| CdpError::Io {
            context: path.display().to_string(),
            source,
        })?;
        let url = file_url(&path);
        self.events.clear();
        let nav = self.call("Page.navigate", json!({"url": url}))?;
        if let Some(error) = nav["errorText"].as_str() {
            return Err(CdpError::Navigate {
                url,
                error: error.to_string(),
            });
        }
        let what = format!("the load event of {url}");
        let deadline = Instant::now() + TIMEOUT;
        while !self
            .events
            .iter()
            .any(|e| e["method"] == "Page.loadEventFired")
        {
            self.next_message(&what, deadline)?;
        }
        Ok(())
    }

    /// Everything reported as an error since `open`: console.error and
    /// console.assert calls, uncaught exceptions, and error entries of the
    /// browser's log (failed resource loads, for one).
    pub fn errors(&mut self) -> Result<Vec<String>, CdpError> {
        // A round trip first: the page's events are delivered in order, so
        // everything it reported before this answer has then arrived.
        self.evaluate("0")?;
        Ok(self.events.iter().filter_map(describe_error).collect())
    }

    /// Evaluate a JavaScript expression on the page and return its value.
    pub fn evaluate(&mut self, expression: &str) -> Result<Value, CdpError> {
        let r = self.call(
            "Runtime.evaluate",
            json!({"expression": expression, "returnByValue": true}),
        )?;
        if let Some(ex) = r.get("exceptionDetails") {
            return Err(CdpError::Protocol {
                method: format!("Runtime.evaluate({expression})"),
                message: ex["exception"]["description"]
                    .as_str()
                    .or(ex["text"].as_str())
                    .unwrap_or_default()
                    .to_string(),
            });
        }
        Ok(r["result"]["value"].clone())
    }

    /// Count the page's images and list the broken ones: an image that
    /// failed to decode is `complete` with `naturalWidth` 0.
    pub fn images(&mut self) -> Result<Images, CdpError> {
        let v = self.evaluate(
            "(() => { const all = Array.from(document.images); return { total: all.length, \
             broken: all.filter(i => !i.complete || i.naturalWidth === 0).map(i => \
             (i.alt ? i.alt + ': ' : '') + (i.getAttribute('src') || '').slice(0, 40)) }; })()",
        )?;
        let broken = v["broken"]
            .as_array()
            .map(|a| {
                a.iter()
                    .map(|s| s.as_str().unwrap_or_default().to_string())
                    .collect()
            })
            .unwrap_or_default();
        Ok(Images {
            total: v["total"].as_u64().unwrap_or_default() as usize,
            broken,
        })
    }

    /// Save a PNG of the whole page at `VIEWPORT_WIDTH_PX` wide: the
    /// viewport is first made as tall as the page's layout at that width.
    /// Returns the page size (width, height) in px.
    pub fn screenshot(&mut self, path: &Path) -> Result<(u32, u32), CdpError> {
        let metrics = |height: u32| {
            json!({"width": VIEWPORT_WIDTH_PX, "height": height,
                   "deviceScaleFactor": 1, "mobile": false})
        };
        self.call("Emulation.setDeviceMetricsOverride", metrics(800))?;
        let height = self
            .evaluate("Math.ceil(document.documentElement.scrollHeight)")?
            .as_u64()
            .unwrap_or(800)
            .max(1) as u32;
        self.call("Emulation.setDeviceMetricsOverride", metrics(height))?;
        let shot = self.call(
            "Page.captureScreenshot",
            json!({"format": "png", "captureBeyondViewport": true}),
        )?;
        let png = base64::engine::general_purpose::STANDARD
            .decode(shot["data"].as_str().unwrap_or_default())?;
        std::fs::write(path, png).map_err(|source| CdpError::Io {
            context: path.display().to_string(),
            source,
        })?;
        Ok((VIEWPORT_WIDTH_PX, height))
    }

    /// Ask Chromium to quit and wait for it to exit.
    pub fn close(mut self) -> Result<(), CdpError> {
        match self.send("Browser.close", json!({}), None) {
            // Quitting may close the pipe before the answer is written.
            Ok(_) | Err(CdpError::Closed { .. }) => {}
            Err(e) => return Err(e),
        }
        let deadline = Instant::now() + TIMEOUT;
        loop {
            let exited = self.child.try_wait().map_err(|source| CdpError::Io {
                context: "waiting for Chromium to exit".into(),
                source,
            })?;
            if exited.is_some() {
                return Ok(());
            }
            if Instant::now() > deadline {
                return Err(CdpError::Timeout {
                    what: "Chromium to exit after Browser.close".into(),
                    log: self.log_tail(),
                });
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// The last lines Chromium wrote to stderr, for error messages.
    fn log_tail(&self) -> String {
        let text =
            std::fs::read_to_string(self.dir.path().join("chromium.log")).unwrap_or_default();
        let lines: Vec<&str> = text.lines().collect();
        lines[lines.len().saturating_sub(20)..].join("\n")
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        // Already gone after `close`; otherwise (a failed test) kill it. Its
        // helper processes exit when the browser process does.
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// One line for an event that reports an error, `None` for any other.
fn describe_error(event: &Value) -> Option<String> {
    let p = &event["params"];
    match event["method"].as_str()? {
        "Runtime.consoleAPICalled" => {
            let kind = p["type"].as_str()?;
            if kind != "error" && kind != "assert" {
                return None;
            }
            let args: Vec<String> = p["args"]
                .as_array()
                .map(|a| a.iter().map(remote_object_text).collect())
                .unwrap_or_default();
            let at = p["stackTrace"]["callFrames"]
                .get(0)
                .map(location)
                .unwrap_or_default();
            Some(format!("console.{kind}: {}{at}", args.join(" ")))
        }
        "Runtime.exceptionThrown" => {
            let d = &p["exceptionDetails"];
            let text = d["exception"]["description"]
                .as_str()
                .or(d["text"].as_str())
                .unwrap_or("?");
            Some(format!("uncaught exception: {text}{}", location(d)))
        }
        "Log.entryAdded" => {
            let e = &p["entry"];
            if e["level"] != "error" {
                return None;
            }
            let url = e["url"]
                .as_str()
                .map(|u| format!(" ({u})"))
                .unwrap_or_default();
            Some(format!(
                "log ({}): {}{url}",
                e["source"].as_str().unwrap_or("?"),
                e["text"].as_str().unwrap_or("?")
            ))
        }
        _ => None,
    }
}

/// A console argument as the console would print it.
fn remote_object_text(o: &Value) -> String {
    match (&o["value"], o["description"].as_str()) {
        (Value::String(s), _) => s.clone(),
        (_, Some(d)) => d.to_string(),
        (Value::Null, None) => o["type"].as_str().unwrap_or("?").to_string(),
        (v, None) => v.to_string(),
    }
}

/// " (url:line)" of a call frame or exception, with the line 1-based.
fn location(v: &Value) -> String {
    match (v["url"].as_str(), v["lineNumber"].as_u64()) {
        (Some(url), Some(line)) if !url.is_empty() => format!(" ({url}:{})", line + 1),
        _ => String::new(),
    }
}

/// A `file://` URL for an absolute path, percent-encoding all but the
/// characters RFC 3986 leaves unreserved (and the slashes).
fn file_url(path: &Path) -> String {
    let mut url = String::from("file://");
    for b in path.to_string_lossy().bytes() {
        if b.is_ascii_alphanumeric() || b"/-._~".contains(&b) {
            url.push(b as char);
        } else {
            url.push_str(&format!("%{b:02X}"));
        }
    }
    url
}

/// The first executable file called `name` in PATH.
fn find_on_path(name: &str) -> Option<PathBuf> {
    use std::os::unix::fs::PermissionsExt;
    std::env::split_paths(&std::env::var_os("PATH")?)
        .map(|dir| dir.join(name))
        .find(|p| {
            p.metadata()
                .is_ok_and(|m| m.is_file() && m.permissions().mode() & 0o111 != 0)
        })
}
