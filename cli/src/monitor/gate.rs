//! Who may ask the monitor, and what every answer carries.
//!
//! A browser is the monitor's client, and a browser also runs other sites' pages. Two checks
//! keep those pages out:
//!
//! - **Host.** A page of `http://evil.example:7878/` whose name the attacker re-points to
//!   127.0.0.1 (DNS rebinding) talks to the monitor as its own origin, and reads it; its
//!   requests carry `Host: evil.example:7878`. The monitor answers only the names it is known
//!   by: `localhost`, a loopback address, the address the connection came in on (the listen
//!   address), and the hosts of `--allow-origin`. The port is not checked: an SSH tunnel or a
//!   proxy forwards from another port, and a rebinding attack cannot choose the host.
//! - **Origin.** A page of another origin (another site, or another port of this computer)
//!   sends its `Origin` with every POST and every cross-origin fetch. The monitor takes a
//!   request with an `Origin` only when that origin is its own (`http://` + the `Host` the
//!   browser used) or listed with `--allow-origin` (a ground station's name, a proxy's
//!   `https://` address). Clients that are not browsers send no `Origin` and are not limited:
//!   they cannot act for anyone but their user.
//!
//! A request refused says why: 421 for a host the monitor does not answer to, 403 for a
//! foreign origin, 400 for no `Host` at all (HTTP/1.1 requires one; every browser sends it).
//!
//! Every answer carries headers that keep the page from being framed (clickjacking), its
//! address from leaking in `Referer`, its JSON from being cached or sniffed as something else,
//! and limit the page to its own script, style and connections (the Content Security Policy
//! the embedded page works under: no inline script or style).

use axum::http::{header, HeaderMap, HeaderValue, StatusCode};
use axum::response::Response;
use std::net::{IpAddr, SocketAddr};

/// The Content Security Policy of every answer: only the page's own script, style and
/// connections, no plugin, no base or form target elsewhere, never in a frame.
pub const CSP: &str = "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self'; \
    connect-src 'self'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'";

/// The names and origins the monitor answers to, beside its own.
#[derive(Clone, Debug, Default)]
pub struct Gate {
    /// Origins allowed with `--allow-origin`, normalised (`scheme://host[:port]`, lower case).
    origins: Vec<String>,
    /// Their hosts, without port, lower case.
    hosts: Vec<String>,
}

/// A request the gate refuses: its status and why.
#[derive(Debug, PartialEq, Eq)]
pub struct Refusal {
    /// 400, 403 or 421.
    pub status: StatusCode,
    /// What to tell the client.
    pub message: String,
}

impl Gate {
    /// The gate of a monitor started with these `--allow-origin` values; a value that is not
    /// an origin (`http://name[:port]` or `https://...`, nothing after) is refused, saying why.
    pub fn new(allowed: &[String]) -> Result<Gate, String> {
        let mut gate = Gate::default();
        for a in allowed {
            let origin = a.trim_end_matches('/').to_ascii_lowercase();
            let Some(rest) = origin
                .strip_prefix("http://")
                .or_else(|| origin.strip_prefix("https://"))
            else {
                return Err(format!(
                    "--allow-origin {a}: an origin starts with http:// or https:// (for instance http://ground-station:7878)"
                ));
            };
            if rest.is_empty() || rest.contains(['/', '?', '#', '@']) {
                return Err(format!(
                    "--allow-origin {a}: an origin is a scheme, a host and a port, no path (for instance http://ground-station:7878)"
                ));
            }
            gate.hosts.push(host_of(rest).to_string());
            gate.origins.push(origin);
        }
        Ok(gate)
    }

    /// Whether the request may be served; `local` is the address its connection came in on.
    pub fn check(&self, headers: &HeaderMap, local: SocketAddr) -> Result<(), Refusal> {
        let refuse = |status, message: String| Err(Refusal { status, message });
        let Some(host) = headers.get(header::HOST).and_then(|h| h.to_str().ok()) else {
            return refuse(
                StatusCode::BAD_REQUEST,
                "the request has no Host header (HTTP/1.1 requires one)".into(),
            );
        };
        let host = host.trim().to_ascii_lowercase();
        if !self.answers_to(host_of(&host), local) {
            return refuse(
                StatusCode::MISDIRECTED_REQUEST,
                format!(
                    "this monitor does not answer to the host `{host}`: use http://127.0.0.1 or http://localhost (a tunnel's port is fine), or start it with --allow-origin http://{host}"
                ),
            );
        }
        let Some(origin) = headers.get(header::ORIGIN) else {
            return Ok(());
        };
        let origin = origin
            .to_str()
            .unwrap_or("(not text)")
            .trim_end_matches('/')
            .to_ascii_lowercase();
        if origin == format!("http://{host}") || self.origins.contains(&origin) {
            return Ok(());
        }
        refuse(
            StatusCode::FORBIDDEN,
            format!(
                "a request from a page of another origin ({origin}) is refused: only this monitor's own page may use it (start it with --allow-origin ORIGIN to allow another)"
            ),
        )
    }

    /// Whether `host` (no port, lower case) names this monitor.
    fn answers_to(&self, host: &str, local: SocketAddr) -> bool {
        if host == "localhost" || self.hosts.iter().any(|h| h == host) {
            return true;
        }
        let ip = host.trim_start_matches('[').trim_end_matches(']');
        match ip.parse::<IpAddr>() {
            Ok(ip) => ip.is_loopback() || ip == local.ip() || Some(ip) == v4_of(local.ip()),
            Err(_) => false,
        }
    }
}

/// An IPv4 address a v4-mapped IPv6 address stands for (a dual-stack listener's).
fn v4_of(ip: IpAddr) -> Option<IpAddr> {
    match ip {
        IpAddr::V6(v6) => v6.to_ipv4_mapped().map(IpAddr::V4),
        IpAddr::V4(_) => None,
    }
}

/// The host of `host[:port]` or `[v6]:port`.
fn host_of(authority: &str) -> &str {
    if authority.starts_with('[') {
        return authority.find(']').map_or(authority, |i| &authority[..=i]);
    }
    authority.rsplit_once(':').map_or(authority, |(h, _)| h)
}

/// Adds the headers every answer carries; `api`: the answer is data (never cached) rather than
/// the page's files (revalidated).
pub fn secure(response: &mut Response, api: bool) {
    let h = response.headers_mut();
    let set = |h: &mut HeaderMap, name, value: &'static str| {
        h.insert(name, HeaderValue::from_static(value));
    };
    set(h, header::CONTENT_SECURITY_POLICY, CSP);
    set(h, header::X_FRAME_OPTIONS, "DENY");
    set(h, header::REFERRER_POLICY, "no-referrer");
    set(h, header::X_CONTENT_TYPE_OPTIONS, "nosniff");
    set(
        h,
        header::HeaderName::from_static("cross-origin-resource-policy"),
        "same-origin",
    );
    set(
        h,
        header::HeaderName::from_static("cross-origin-opener-policy"),
        "same-origin",
    );
    set(
        h,
        header::CACHE_CONTROL,
        if api { "no-store" } else { "no-cache" },
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    fn headers(host: Option<&str>, origin: Option<&str>) -> HeaderMap {
        let mut h = HeaderMap::new();
        if let Some(v) = host {
            h.insert(header::HOST, v.parse().unwrap());
        }
        if let Some(v) = origin {
            h.insert(header::ORIGIN, v.parse().unwrap());
        }
        h
    }

    fn status(g: &Gate, host: Option<&str>, origin: Option<&str>, local: &str) -> u16 {
        match g.check(&headers(host, origin), local.parse().unwrap()) {
            Ok(()) => 200,
            Err(r) => r.status.as_u16(),
        }
    }

    #[test]
    fn the_monitor_answers_to_its_own_names_only() {
        let g = Gate::default();
        let lo = "127.0.0.1:7878";
        for host in [
            "127.0.0.1:7878",
            "localhost:7878",
            "LOCALHOST",
            "127.0.0.1:9000",
            "[::1]:7878",
            "127.0.0.2",
        ] {
            assert_eq!(status(&g, Some(host), None, lo), 200, "{host}");
        }
        for host in [
            "evil.example:7878",
            "localhost.evil.example",
            "10.0.0.5:7878",
            "",
        ] {
            assert_eq!(status(&g, Some(host), None, lo), 421, "{host}");
        }
        assert_eq!(status(&g, None, None, lo), 400);
        // Listening on every address: the one the connection came in on.
        assert_eq!(
            status(&g, Some("10.0.0.5:7878"), None, "10.0.0.5:7878"),
            200
        );
        assert_eq!(
            status(&g, Some("10.0.0.5:7878"), None, "[::ffff:10.0.0.5]:7878"),
            200
        );
        assert_eq!(
            status(&g, Some("10.0.0.6:7878"), None, "10.0.0.5:7878"),
            421
        );
    }

    #[test]
    fn only_the_pages_own_origin_and_the_allowed_ones_are_taken() {
        let g = Gate::new(&["http://Ground:7878/".into(), "https://proxy.example".into()]).unwrap();
        let lo = "127.0.0.1:7878";
        let ok = [
            ("127.0.0.1:7878", "http://127.0.0.1:7878"),
            ("localhost:9000", "http://localhost:9000"),
            ("ground:7878", "http://ground:7878"),
            ("proxy.example", "https://proxy.example"),
        ];
        for (host, origin) in ok {
            assert_eq!(status(&g, Some(host), Some(origin), lo), 200, "{origin}");
        }
        let refused = [
            ("127.0.0.1:7878", "http://evil.example"),
            ("127.0.0.1:7878", "http://127.0.0.1:8080"),
            ("127.0.0.1:7878", "https://127.0.0.1:7878"),
            ("127.0.0.1:7878", "null"),
            ("ground:7878", "http://ground:7879"),
        ];
        for (host, origin) in refused {
            assert_eq!(status(&g, Some(host), Some(origin), lo), 403, "{origin}");
        }
        let r = g
            .check(
                &headers(Some("127.0.0.1:7878"), Some("http://evil.example")),
                lo.parse().unwrap(),
            )
            .unwrap_err();
        assert!(r.message.contains("http://evil.example"), "{}", r.message);
    }

    #[test]
    fn allowed_origins_must_be_origins() {
        for bad in [
            "ground",
            "ftp://ground",
            "http://",
            "http://ground/page",
            "http://a@b",
        ] {
            let e = Gate::new(&[bad.to_string()]).unwrap_err();
            assert!(e.contains("--allow-origin"), "{bad}: {e}");
        }
        assert!(Gate::new(&["http://[fd00::1]:7878".into()]).is_ok());
    }
}
