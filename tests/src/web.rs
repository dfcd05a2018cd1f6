//! The web side of the tests: a small HTTP/1.1 client, a `petrel monitor` process, and a real
//! headless Chromium driven over WebDriver (Debian's `chromium` and `chromium-driver`), so that
//! the monitor's page is tested as a user sees it: after its JavaScript ran.

use serde_json::{json, Value};
use std::io::{BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// An HTTP response: status, headers and body.
#[derive(Debug)]
pub struct Response {
    /// The status code.
    pub status: u16,
    /// The headers, names in lower case, in order.
    pub headers: Vec<(String, String)>,
    /// The body (chunks joined).
    pub body: String,
}

impl Response {
    /// The body as JSON (`Null` when it is not).
    pub fn json(&self) -> Value {
        serde_json::from_str(&self.body).unwrap_or(Value::Null)
    }

    /// The value of header `name` (lower case), if it has one.
    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_str())
    }
}

/// One HTTP/1.1 request (`Connection: close`), with extra headers and a body.
pub fn http(
    addr: SocketAddr,
    method: &str,
    path: &str,
    headers: &[(&str, &str)],
    body: &str,
) -> std::io::Result<Response> {
    http_to_host(addr, &addr.to_string(), method, path, headers, body)
}

/// [`http`] with the `Host` header given: the name a browser would have used for `addr`.
pub fn http_to_host(
    addr: SocketAddr,
    host: &str,
    method: &str,
    path: &str,
    headers: &[(&str, &str)],
    body: &str,
) -> std::io::Result<Response> {
    let mut s = TcpStream::connect_timeout(&addr, Duration::from_secs(30))?;
    s.set_read_timeout(Some(Duration::from_secs(60)))?;
    let mut req = format!(
        "{method} {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\nContent-Length: {}\r\n",
        body.len()
    );
    for (k, v) in headers {
        req.push_str(&format!("{k}: {v}\r\n"));
    }
    req.push_str("\r\n");
    req.push_str(body);
    s.write_all(req.as_bytes())?;
    // Read the head, then the body by its length (a server may keep the connection open).
    let mut raw = Vec::new();
    let mut buf = [0u8; 8192];
    let head_end = loop {
        if let Some(i) = find(&raw, b"\r\n\r\n") {
            break i + 4;
        }
        let n = s.read(&mut buf)?;
        if n == 0 {
            break raw.len();
        }
        raw.extend_from_slice(&buf[..n]);
    };
    let head_text = String::from_utf8_lossy(&raw[..head_end]).into_owned();
    let headers: Vec<(String, String)> = head_text
        .lines()
        .skip(1)
        .filter_map(|l| l.split_once(':'))
        .map(|(n, v)| (n.trim().to_ascii_lowercase(), v.trim().to_string()))
        .collect();
    let head = head_text.to_ascii_lowercase();
    let status = head
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or(0);
    let length: Option<usize> = head
        .lines()
        .find_map(|l| l.strip_prefix("content-length:"))
        .and_then(|v| v.trim().parse().ok());
    let chunked = head.contains("transfer-encoding: chunked");
    loop {
        let body = &raw[head_end..];
        let done = match length {
            Some(n) => body.len() >= n,
            None if chunked => find(body, b"0\r\n\r\n").is_some(),
            None => false,
        };
        if done {
            break;
        }
        let n = s.read(&mut buf)?;
        if n == 0 {
            break;
        }
        raw.extend_from_slice(&buf[..n]);
    }
    let rest = String::from_utf8_lossy(&raw[head_end..]).into_owned();
    let body = if chunked { dechunk(&rest) } else { rest };
    Ok(Response {
        status,
        headers,
        body,
    })
}

fn find(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).position(|w| w == needle)
}

fn dechunk(mut rest: &str) -> String {
    let mut out = String::new();
    while let Some((size, tail)) = rest.split_once("\r\n") {
        let n = usize::from_str_radix(size.trim(), 16).unwrap_or(0);
        if n == 0 || tail.len() < n {
            break;
        }
        out.push_str(&tail[..n]);
        rest = tail[n..].trim_start_matches("\r\n");
    }
    out
}

/// A `petrel monitor` process on a free port of 127.0.0.1, stopped (SIGTERM) when dropped.
pub struct Monitor {
    child: Child,
    /// Where it serves.
    pub addr: SocketAddr,
    /// The operator token, when started with `--operator`.
    pub token: Option<String>,
    /// Where an operator monitor writes its token (its standard output, a pipe, never has it).
    _token_dir: Option<tempfile::TempDir>,
}

impl Monitor {
    /// Starts `petrel monitor ARGS --listen 127.0.0.1:0` (with `--operator`, its token written
    /// to a file of a temporary directory, as `--token-file` does) and waits for its address.
    pub fn start(args: &[&str]) -> Monitor {
        Monitor::start_with(&crate::petrel_bin(), args)
    }

    /// [`Monitor::start`] with another `petrel` binary (a benchmark's baseline).
    pub fn start_with(petrel: &Path, args: &[&str]) -> Monitor {
        let operator = args.contains(&"--operator");
        let token_dir = operator.then(|| {
            tempfile::Builder::new()
                .prefix("petrel-test-token-")
                .tempdir()
                .expect("a directory for the token")
        });
        let token_file = token_dir.as_ref().map(|d| d.path().join("token"));
        let mut cmd = Command::new(petrel);
        cmd.arg("monitor")
            .args(args)
            .args(["--listen", "127.0.0.1:0"]);
        if let Some(f) = &token_file {
            cmd.arg("--token-file").arg(f);
        }
        let mut child = cmd
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("petrel monitor starts");
        let out = child.stdout.take().expect("its standard output");
        let mut lines = BufReader::new(out).lines();
        let mut addr = None;
        for line in lines.by_ref() {
            let Ok(line) = line else { break };
            if let Some(a) = line.strip_prefix("petrel monitor: listening on http://") {
                addr = a.trim_end_matches('/').parse().ok();
                break;
            }
        }
        // Written before the address is printed.
        let token = token_file
            .as_ref()
            .and_then(|f| std::fs::read_to_string(f).ok())
            .map(|t| t.trim().to_string());
        // Keep reading its output, so that it never blocks on a full pipe.
        std::thread::spawn(move || for _ in lines {});
        let Some(addr) = addr else {
            let _ = child.kill();
            let status = child.wait();
            panic!("petrel monitor did not start: {status:?}");
        };
        Monitor {
            child,
            addr,
            token,
            _token_dir: token_dir,
        }
    }

    /// The process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// The page's address, `http://127.0.0.1:PORT/` plus `path_and_query`.
    pub fn url(&self, path_and_query: &str) -> String {
        format!("http://{}{path_and_query}", self.addr)
    }

    /// `GET path`, as JSON.
    pub fn get(&self, path: &str) -> Response {
        http(self.addr, "GET", path, &[], "").expect("the monitor answers")
    }
}

impl Drop for Monitor {
    fn drop(&mut self) {
        let _ = Command::new("kill")
            .args(["-TERM", &self.child.id().to_string()])
            .status();
        let deadline = Instant::now() + Duration::from_secs(5);
        while matches!(self.child.try_wait(), Ok(None)) && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(10));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The WebDriver server of Debian's `chromium-driver`.
const CHROMEDRIVER: &str = "/usr/bin/chromedriver";
/// Debian's Chromium.
const CHROMIUM: &str = "/usr/bin/chromium";

/// A headless Chromium under chromedriver, its profile in a temporary directory; both stopped
/// and removed when dropped.
pub struct Browser {
    driver: Child,
    addr: SocketAddr,
    session: String,
    _profile: tempfile::TempDir,
}

/// Whether this machine has Chromium and its WebDriver; when it has not, says why. The test
/// command (scripts/test.sh) installs them and sets `PETREL_REQUIRE_BROWSER=1`, so that there
/// a missing browser fails rather than skips.
pub fn browser_available() -> bool {
    let ok = Path::new(CHROMEDRIVER).exists() && Path::new(CHROMIUM).exists();
    if !ok {
        assert!(
            std::env::var("PETREL_REQUIRE_BROWSER").is_err(),
            "PETREL_REQUIRE_BROWSER is set but {CHROMIUM} or {CHROMEDRIVER} is missing"
        );
        eprintln!(
            "SKIPPED: the browser tests need Debian's chromium and chromium-driver ({CHROMIUM}, {CHROMEDRIVER}): apt-get install chromium chromium-driver (scripts/test.sh does)"
        );
    }
    ok
}

impl Browser {
    /// Starts chromedriver and a headless Chromium session, its window 1600 x 900.
    pub fn start() -> Browser {
        Browser::start_sized(1600, 900)
    }

    /// Starts chromedriver and a headless Chromium session, its window `width` x `height`.
    pub fn start_sized(width: u32, height: u32) -> Browser {
        let port = {
            let l = std::net::TcpListener::bind("127.0.0.1:0").expect("a free port");
            l.local_addr().expect("its address").port()
        };
        let profile = tempfile::Builder::new()
            .prefix("petrel-test-chromium-")
            .tempdir()
            .expect("a profile directory");
        // Chromium's scratch directories go with the profile, not into /tmp.
        let driver = Command::new(CHROMEDRIVER)
            .arg(format!("--port={port}"))
            .env("TMPDIR", profile.path())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("chromedriver starts");
        let addr: SocketAddr = format!("127.0.0.1:{port}").parse().expect("an address");
        let deadline = Instant::now() + Duration::from_secs(30);
        loop {
            if let Ok(r) = http(addr, "GET", "/status", &[], "") {
                if r.json()["value"]["ready"] == true {
                    break;
                }
            }
            assert!(Instant::now() < deadline, "chromedriver did not start");
            std::thread::sleep(Duration::from_millis(50));
        }
        let caps = json!({"capabilities": {"alwaysMatch": {
            "browserName": "chrome",
            "goog:chromeOptions": {
                "binary": CHROMIUM,
                "args": ["--headless", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                         format!("--window-size={width},{height}"),
                         format!("--user-data-dir={}", profile.path().display()),
                         format!("--disk-cache-dir={}", profile.path().join("cache").display())],
            }
        }}});
        let mut b = Browser {
            driver,
            addr,
            session: String::new(),
            _profile: profile,
        };
        let r = b.call("POST", "/session", &caps);
        b.session = r["sessionId"]
            .as_str()
            .unwrap_or_else(|| panic!("no WebDriver session: {r}"))
            .to_string();
        // The page's own area is the size asked for (a headless window's chrome would take
        // some of it): what a page measures and a screenshot shows.
        b.call(
            "POST",
            &format!("/session/{}/goog/cdp/execute", b.session),
            &json!({"cmd": "Emulation.setDeviceMetricsOverride", "params": {
                "width": width, "height": height, "deviceScaleFactor": 1, "mobile": false}}),
        );
        b
    }

    fn call(&self, method: &str, path: &str, body: &Value) -> Value {
        let r = http(
            self.addr,
            method,
            path,
            &[("Content-Type", "application/json")],
            &if body.is_null() {
                String::new()
            } else {
                body.to_string()
            },
        )
        .expect("chromedriver answers");
        let v = r.json();
        assert!(r.status == 200, "WebDriver {method} {path}: {}", r.body);
        v["value"].clone()
    }

    /// Opens `url` in the session's window.
    pub fn open(&self, url: &str) {
        self.call(
            "POST",
            &format!("/session/{}/url", self.session),
            &json!({ "url": url }),
        );
    }

    /// Runs `script` (a function body; `return` gives the value) in the page.
    pub fn eval(&self, script: &str) -> Value {
        self.call(
            "POST",
            &format!("/session/{}/execute/sync", self.session),
            &json!({ "script": script, "args": [] }),
        )
    }

    /// Waits up to `secs` until `pred` holds on `eval(script)`; returns the last value.
    pub fn wait_for(&self, secs: f64, script: &str, pred: impl Fn(&Value) -> bool) -> Value {
        let deadline = Instant::now() + Duration::from_secs_f64(secs);
        loop {
            let v = self.eval(script);
            if pred(&v) || Instant::now() >= deadline {
                return v;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// The places the page shows marked (its DOM: the nodes of class `marked`), sorted.
    pub fn marked(&self) -> Vec<String> {
        let v = self.eval(
            "return Array.from(document.querySelectorAll('g.node.place.marked')).map(n => n.dataset.name).sort()",
        );
        strings(&v)
    }

    /// Waits until the page has its drawing in.
    pub fn wait_ready(&self) {
        let v = self.wait_for(
            60.0,
            "return document.body.dataset.ready + '|' + (document.body.dataset.error || '')",
            |v| v.as_str().is_some_and(|s| s.starts_with("true")),
        );
        assert!(
            v.as_str().is_some_and(|s| s.starts_with("true")),
            "the page did not load: {v}"
        );
    }

    /// A PNG screenshot of the window, written to `path`.
    pub fn screenshot(&self, path: &PathBuf) {
        let v = self.call(
            "GET",
            &format!("/session/{}/screenshot", self.session),
            &Value::Null,
        );
        let data = decode_base64(v.as_str().unwrap_or(""));
        std::fs::write(path, data).expect("the screenshot is written");
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        if !self.session.is_empty() {
            let _ = http(
                self.addr,
                "DELETE",
                &format!("/session/{}", self.session),
                &[],
                "",
            );
        }
        let _ = self.driver.kill();
        let _ = self.driver.wait();
    }
}

/// The strings of a JSON array, in order.
pub fn strings(v: &Value) -> Vec<String> {
    v.as_array()
        .map(|a| {
            a.iter()
                .filter_map(|s| s.as_str().map(String::from))
                .collect()
        })
        .unwrap_or_default()
}

fn decode_base64(s: &str) -> Vec<u8> {
    let val = |c: u8| -> Option<u32> {
        Some(match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            _ => return None,
        } as u32)
    };
    let mut out = Vec::new();
    let (mut acc, mut bits) = (0u32, 0);
    for c in s.bytes().filter_map(val) {
        acc = (acc << 6) | c;
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    out
}

/// The marking of a status JSON (`petrel status --json`) as the drawing's place ids, sorted:
/// `NET.place`, `global.place`, and `NET.done.CHILD` for completion places.
pub fn status_places(status: &Value) -> Vec<String> {
    let mut out = Vec::new();
    if let Some(m) = status["marking"].as_object() {
        for (net, places) in m {
            for p in places.as_array().into_iter().flatten() {
                if let Some(p) = p.as_str() {
                    out.push(match p.strip_suffix(".done") {
                        Some(child) if net != "global" => format!("{net}.done.{child}"),
                        _ => format!("{net}.{p}"),
                    });
                }
            }
        }
    }
    out.sort();
    out
}
