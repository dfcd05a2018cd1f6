//! `petrel up` under systemd (`Type=notify`): the service manager's notification protocol
//! (sd_notify(3)), written here because it is one datagram.
//!
//! systemd passes the address of its notification socket in `NOTIFY_SOCKET` (a path, or an
//! abstract name written with a leading `@`), and the watchdog's period in `WATCHDOG_USEC` (for
//! the process `WATCHDOG_PID` names, when set). `petrel up` sends:
//! - `READY=1` once the vehicle is up (every process ready), so that units ordered after
//!   `petrel-up@….service` start only then and `systemctl start` returns only then;
//! - `WATCHDOG=1` from its supervision loop, at half the period systemd asks for: a supervisor
//!   stuck for a whole period is killed and restarted by systemd (`WatchdogSec=`);
//! - `STATUS=…` (what `systemctl status` shows) and `STOPPING=1` when it brings the vehicle
//!   down.
//!
//! Without `NOTIFY_SOCKET` every call does nothing. The processes `petrel up` starts do not
//! inherit these variables ([`VARIABLES`]): the notifications are the supervisor's alone.

use std::os::unix::net::{SocketAddr, UnixDatagram};
use std::time::{Duration, Instant};

/// The variables systemd sets for the service's main process.
pub const VARIABLES: [&str; 3] = ["NOTIFY_SOCKET", "WATCHDOG_USEC", "WATCHDOG_PID"];

/// The notifications of one `petrel up`.
pub struct Notifier {
    /// An unbound datagram socket and the service manager's address.
    socket: Option<(UnixDatagram, SocketAddr)>,
    /// How often to feed the watchdog (half its period), if systemd watches this process.
    ping_every: Option<Duration>,
    last_ping: Option<Instant>,
    /// A failed send is reported once, not every round.
    warned: bool,
}

impl Notifier {
    /// From the environment systemd gave this process; inert without `NOTIFY_SOCKET`.
    pub fn from_env() -> Notifier {
        let var = |k: &str| std::env::var(k).ok().filter(|v| !v.is_empty());
        let watchdog = var("WATCHDOG_USEC").and_then(|usec| {
            let for_us = var("WATCHDOG_PID")
                .is_none_or(|pid| pid.parse::<u32>().ok() == Some(std::process::id()));
            for_us.then(|| usec.parse::<u64>().ok()).flatten()
        });
        Notifier::new(var("NOTIFY_SOCKET").as_deref(), watchdog)
    }

    /// To the socket `address` (a path, or `@name` for an abstract one), with a watchdog of
    /// `watchdog_usec` microseconds (none, or 0: no watchdog).
    pub fn new(address: Option<&str>, watchdog_usec: Option<u64>) -> Notifier {
        let socket = address.and_then(|a| match open(a) {
            Ok(s) => Some(s),
            Err(e) => {
                eprintln!("warning: NOTIFY_SOCKET={a}: {e}; systemd will not hear from petrel up");
                None
            }
        });
        Notifier {
            ping_every: watchdog_usec
                .filter(|&u| u > 0 && socket.is_some())
                .map(|u| Duration::from_micros(u) / 2),
            socket,
            last_ping: None,
            warned: false,
        }
    }

    /// The vehicle is up.
    pub fn ready(&mut self, status: &str) {
        self.send(&format!("READY=1\nSTATUS={status}"));
    }

    /// What `systemctl status` shows.
    pub fn status(&mut self, status: &str) {
        self.send(&format!("STATUS={status}"));
    }

    /// The vehicle is coming down.
    pub fn stopping(&mut self, status: &str) {
        self.send(&format!("STOPPING=1\nSTATUS={status}"));
    }

    /// Feeds the watchdog if half its period has passed since the last time: called every
    /// round of the supervision loop, which is what it watches.
    pub fn watchdog(&mut self, now: Instant) {
        let Some(every) = self.ping_every else {
            return;
        };
        if self
            .last_ping
            .is_some_and(|t| now.duration_since(t) < every)
        {
            return;
        }
        self.last_ping = Some(now);
        self.send("WATCHDOG=1");
    }

    fn send(&mut self, message: &str) {
        let Some((socket, address)) = &self.socket else {
            return;
        };
        if let Err(e) = socket.send_to_addr(message.as_bytes(), address) {
            if !self.warned {
                eprintln!("warning: cannot notify systemd: {e}");
                self.warned = true;
            }
        }
    }
}

/// An unbound datagram socket and the address `text` names.
fn open(text: &str) -> std::io::Result<(UnixDatagram, SocketAddr)> {
    let address = match text.strip_prefix('@') {
        Some(name) => {
            use std::os::linux::net::SocketAddrExt;
            SocketAddr::from_abstract_name(name.as_bytes())?
        }
        None if text.starts_with('/') => SocketAddr::from_pathname(text)?,
        None => {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                "not an absolute path nor an abstract socket name (@NAME)",
            ))
        }
    };
    Ok((UnixDatagram::unbound()?, address))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn receive(socket: &UnixDatagram) -> String {
        let mut buf = [0u8; 512];
        let n = socket.recv(&mut buf).expect("a notification");
        String::from_utf8_lossy(&buf[..n]).into_owned()
    }

    #[test]
    fn an_abstract_socket_receives_the_notifications() {
        use std::os::linux::net::SocketAddrExt;
        let name = format!("petrel-notify-test-{}", std::process::id());
        let manager =
            UnixDatagram::bind_addr(&SocketAddr::from_abstract_name(name.as_bytes()).unwrap())
                .unwrap();
        manager
            .set_read_timeout(Some(Duration::from_secs(5)))
            .unwrap();
        let mut n = Notifier::new(Some(&format!("@{name}")), Some(1_000_000));
        n.ready("vehicle up");
        assert_eq!(receive(&manager), "READY=1\nSTATUS=vehicle up");
        // Half the period apart: one ping at once, none 100 ms later, one at 500 ms.
        let t = Instant::now();
        n.watchdog(t);
        n.watchdog(t + Duration::from_millis(100));
        n.watchdog(t + Duration::from_millis(500));
        n.stopping("down");
        assert_eq!(receive(&manager), "WATCHDOG=1");
        assert_eq!(receive(&manager), "WATCHDOG=1");
        assert_eq!(receive(&manager), "STOPPING=1\nSTATUS=down");
    }

    #[test]
    fn without_a_socket_or_a_watchdog_nothing_is_sent() {
        let mut n = Notifier::new(None, Some(1_000_000));
        n.ready("up");
        n.watchdog(Instant::now());
        assert!(n.ping_every.is_none());
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("notify");
        let manager = UnixDatagram::bind(&path).unwrap();
        manager.set_nonblocking(true).unwrap();
        let mut n = Notifier::new(Some(path.to_str().unwrap()), None);
        n.watchdog(Instant::now());
        n.status("starting");
        assert_eq!(receive(&manager), "STATUS=starting");
        assert!(
            manager.recv(&mut [0u8; 64]).is_err(),
            "no watchdog asked for"
        );
        assert!(open("relative/path").is_err());
    }
}
