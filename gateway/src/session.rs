//! The gateway's zenoh session: where it listens and connects, and how the link is secured.
//!
//! By default ([`Security::Tls`]) every link is QUIC, TLS 1.3 with mutual authentication
//! against the vehicle's own certificate authority ([`crate::keys`]), on the UDP port of the
//! address the vehicle file gives: a peer without a certificate of the
//! vehicle cannot open a session, so it reads nothing and sends nothing. On top of it, zenoh's
//! access control binds each computer's name to its certificate: a peer whose certificate names
//! computer `B` may put on `petrel/<vehicle>/link/B` and nowhere else, and only the vehicle's
//! computers (by certificate) hear this computer's key. The gateway then checks that a
//! message's `from` is its key's computer, so no computer of the vehicle speaks for another.
//!
//! QUIC, not zenoh 1.10's `tls` link over TCP: that link reads and writes one rustls stream from
//! two tasks at once (zenoh issue 2557); under load its writes fail ("handshake not
//! complete"), the link drops and what it carried is lost. QUIC's streams (quinn) have a
//! sending and a receiving half of their own. zenoh configures both from
//! `transport/link/tls`.
//!
//! zenoh's QUIC client checks the server's chain but not its name
//! (`verify_name_on_connect: false`): the name that matters is the certificate's computer,
//! which the access control binds, not the address a computer happens to have. (That client
//! also trusts the public web authorities; what they certify names no computer of the vehicle,
//! so the access control gives it nothing.)
//!
//! [`Security::None`] is a lab bench's explicit choice: plain TCP, no identity, and a warning.

use crate::keys::ComputerKeys;
use crate::link::{key_all, key_of};
use crate::runtime::{GatewayError, Settings};

/// How the link between the vehicle's computers is secured.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Security {
    /// Mutual TLS (QUIC) with this computer's keys, each peer bound to its certificate's
    /// computer.
    Tls(ComputerKeys),
    /// Plain TCP: neither encrypted nor authenticated (a lab bench's explicit opt-out).
    None,
}

impl Security {
    /// A line for status and logs.
    pub fn describe(&self) -> String {
        match self {
            Security::Tls(k) => format!(
                "mutual TLS (QUIC), the vehicle's keys in {}",
                k.dir.display()
            ),
            Security::None => "NONE: neither encrypted nor authenticated".into(),
        }
    }
}

/// What a lab bench's gateway logs at start, and `petrel check` says of its vehicle file.
pub const INSECURE_WARNING: &str = "the link between the vehicle's computers is neither encrypted nor authenticated ([link] security = \"none\"): anyone who reaches a gateway's port can read the vehicle's news and send it events and calls; for a lab bench only";

/// The endpoint zenoh is given for `endpoint` as the vehicle file or the command line writes
/// it (`tcp/HOST:PORT`, or `quic/HOST:PORT`): `quic/HOST:PORT` when the link is secured (the
/// same address and port number, in UDP), `tcp/HOST:PORT` for a lab bench's plain link.
pub fn endpoint(endpoint: &str, security: &Security) -> Result<String, GatewayError> {
    let (scheme, rest) = endpoint.split_once('/').unwrap_or(("", endpoint));
    match (scheme, security) {
        ("tcp" | "quic", Security::Tls(_)) => Ok(format!("quic/{rest}")),
        ("tcp", Security::None) => Ok(endpoint.to_owned()),
        ("quic", Security::None) => Err(GatewayError(format!(
            "`{endpoint}`: QUIC is always encrypted, and [link] security = \"none\" asks for a plain link: write tcp/"
        ))),
        _ => Err(GatewayError(format!(
            "`{endpoint}` is not a gateway endpoint: write `tcp/ADDRESS:PORT`"
        ))),
    }
}

/// Whether an endpoint (`tcp/127.0.0.1:7447`, `tcp/localhost:7447`, `tcp/[::1]:7447`) is on
/// this machine's loopback: a vehicle whose endpoints all are runs on one machine.
pub fn is_loopback(endpoint: &str) -> bool {
    let rest = endpoint.split_once('/').map_or(endpoint, |(_, r)| r);
    let address = rest.split(['?', '#']).next().unwrap_or("");
    let Some((host, _port)) = address.rsplit_once(':') else {
        return false;
    };
    let host = host.trim_start_matches('[').trim_end_matches(']');
    host == "localhost"
        || host
            .parse::<std::net::IpAddr>()
            .is_ok_and(|ip| ip.is_loopback())
}

fn base64(bytes: &[u8]) -> String {
    use base64::Engine;
    base64::engine::general_purpose::STANDARD.encode(bytes)
}

/// zenoh's `transport/link/tls` settings (QUIC's too) for mutual TLS with a computer's keys,
/// both when it listens and when it connects. The keys go in as values, not paths: they were read and
/// checked owner-only by [`crate::keys::load`].
pub fn tls_config(k: &ComputerKeys) -> serde_json::Value {
    serde_json::json!({
        "root_ca_certificate_base64": base64(k.ca.as_bytes()),
        "listen_certificate_base64": base64(k.certificate.as_bytes()),
        "listen_private_key_base64": base64(k.key.as_bytes()),
        "connect_certificate_base64": base64(k.certificate.as_bytes()),
        "connect_private_key_base64": base64(k.key.as_bytes()),
        "enable_mtls": true,
        "verify_name_on_connect": false,
    })
}

/// zenoh's access control for the link: each peer computer, known by its certificate's name,
/// may put on its own key only and subscribe to the link; this gateway puts its own key to
/// them. Everything else (any other key, any peer without a vehicle certificate) is denied.
fn access_control(s: &Settings) -> serde_json::Value {
    let vehicle = s.vehicle.name();
    let me = &s.plan.computer;
    let mut rules = vec![
        serde_json::json!({
            "id": "subscribe", "messages": ["declare_subscriber"],
            "flows": ["ingress", "egress"], "permission": "allow",
            "key_exprs": [key_all(vehicle)],
        }),
        serde_json::json!({
            "id": "put-own", "messages": ["put"], "flows": ["egress"],
            "permission": "allow", "key_exprs": [key_of(vehicle, me)],
        }),
    ];
    let mut subjects = Vec::new();
    let mut policies = Vec::new();
    for peer in &s.plan.peers {
        rules.push(serde_json::json!({
            "id": format!("put-{peer}"), "messages": ["put"], "flows": ["ingress"],
            "permission": "allow", "key_exprs": [key_of(vehicle, peer)],
        }));
        subjects.push(serde_json::json!({ "id": peer, "cert_common_names": [peer] }));
        policies.push(serde_json::json!({
            "rules": ["subscribe", "put-own", format!("put-{peer}")],
            "subjects": [peer],
        }));
    }
    serde_json::json!({
        "enabled": true,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    })
}

/// The zenoh configuration of a gateway: peer mode, no multicast scouting (the peers are the
/// vehicle file's, and tests on one host must not find each other), quick reconnection, and
/// the link's security.
pub fn zenoh_config(s: &Settings) -> Result<zenoh::Config, GatewayError> {
    let endpoints = |list: &[String]| -> Result<Vec<String>, GatewayError> {
        list.iter().map(|e| endpoint(e, &s.security)).collect()
    };
    let mut doc = serde_json::json!({
        "mode": "peer",
        "listen": { "endpoints": endpoints(&s.listen)? },
        "connect": {
            "endpoints": endpoints(&s.connect)?,
            "retry": { "period_init_ms": 100, "period_max_ms": 1000, "period_increase_factor": 2.0 }
        },
        "scouting": { "multicast": { "enabled": false }, "gossip": { "enabled": false } },
        "transport": {},
    });
    if let Security::Tls(k) = &s.security {
        doc["transport"]["link"] = serde_json::json!({ "tls": tls_config(k) });
        doc["access_control"] = access_control(s);
    }
    if let Some(c) = &s.credentials {
        doc["transport"]["auth"] = serde_json::json!({ "usrpwd": {
            "user": c.user,
            "password": c.password,
            "dictionary_file": c.dictionary.to_string_lossy(),
        } });
    }
    zenoh::Config::from_json5(&doc.to_string())
        .map_err(|e| GatewayError(format!("the zenoh configuration: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn endpoints_follow_the_security() {
        let tls = Security::Tls(ComputerKeys {
            dir: "/k".into(),
            ca: String::new(),
            certificate: String::new(),
            key: String::new(),
        });
        assert_eq!(
            endpoint("tcp/10.0.0.1:7447", &tls).unwrap(),
            "quic/10.0.0.1:7447"
        );
        assert_eq!(
            endpoint("quic/10.0.0.1:7447", &tls).unwrap(),
            "quic/10.0.0.1:7447"
        );
        assert_eq!(
            endpoint("tcp/10.0.0.1:7447", &Security::None).unwrap(),
            "tcp/10.0.0.1:7447"
        );
        assert!(endpoint("quic/h:1", &Security::None).is_err());
        assert!(
            endpoint("tls/h:1", &tls).is_err(),
            "zenoh's tls link is not used"
        );
        assert!(is_loopback("tcp/127.0.0.1:7447") && is_loopback("tcp/[::1]:7"));
        assert!(is_loopback("tcp/localhost:7447") && is_loopback("tcp/127.3.0.1:1"));
        assert!(!is_loopback("tcp/10.0.0.1:7447") && !is_loopback("tcp/0.0.0.0:7447"));
        assert!(!is_loopback("nonsense"));
    }
}
