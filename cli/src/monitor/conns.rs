//! The monitor's connections: how many it holds, which it lets go first, and the gate and
//! headers of every request.
//!
//! A connection costs a file descriptor and some memory whatever it does, so a client that
//! opens thousands and sends nothing would, unchecked, take every descriptor the process may
//! have, and the monitor would stop answering (the issue saw 20,000 idle connections do it).
//! Here:
//!
//! - the monitor holds at most `max_connections` ([`Limits`]; fewer if the descriptor limit is
//!   lower, after raising its soft limit to the hard one);
//! - a connection is **idle** when no request of it is being answered: it is opening, sending
//!   its request's head, waiting between requests (keep-alive), or reading an answer slowly.
//!   A connection idle for `idle` is closed: that is also the deadline to send a request's
//!   head (a slow one, byte by byte, is closed like a silent one);
//! - when the cap is reached, a new connection takes the place of the **oldest idle** one;
//!   busy ones (a request being answered, a page's event stream) are never shed. If every
//!   connection is busy, the new one is answered 503 at once and closed;
//! - running out of descriptors all the same (other processes' connections count too) sheds
//!   the oldest idle connection before accepting again.
//!
//! So a flood of idle or slow connections costs the monitor at most the cap, and a legitimate
//! request, which is idle only for the moment it takes to send its head, is still answered.
//! The core ([`Table`]) is a plain data structure with the time given, tested alone.

use super::gate::{self, Gate};
use axum::body::Body;
use axum::http::Request;
use axum::response::{IntoResponse, Response};
use axum::Router;
use std::collections::BTreeMap;
use std::convert::Infallible;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::Notify;

/// Descriptors kept for everything but connections (the vehicle's shared memory and sockets,
/// the runtime, the standard streams).
const RESERVED_FDS: u64 = 128;

/// How many connections, and how long one may stay idle.
#[derive(Clone, Copy, Debug)]
pub struct Limits {
    /// The most connections held at once.
    pub max_connections: usize,
    /// How long a connection may be idle (no request being answered) before it is closed.
    pub idle: Duration,
}

impl Limits {
    /// The limits for this process: `max_connections`, lowered to what its descriptor limit
    /// allows once the soft limit is raised to the hard one.
    pub fn for_this_process(max_connections: usize, idle: Duration) -> Limits {
        let fds = raise_fd_limit();
        let allowed = fds.saturating_sub(RESERVED_FDS).max(8);
        Limits {
            max_connections: max_connections.min(usize::try_from(allowed).unwrap_or(usize::MAX)),
            idle,
        }
    }
}

/// Raises the soft limit on open files to the hard one; returns the soft limit in force.
fn raise_fd_limit() -> u64 {
    use nix::sys::resource::{getrlimit, setrlimit, Resource};
    match getrlimit(Resource::RLIMIT_NOFILE) {
        Ok((soft, hard)) if soft < hard => match setrlimit(Resource::RLIMIT_NOFILE, hard, hard) {
            Ok(()) => hard,
            Err(_) => soft,
        },
        Ok((soft, _)) => soft,
        Err(_) => 1024,
    }
}

/// One connection as the table sees it; shared with the task that serves it.
#[derive(Debug, Default)]
pub struct Conn {
    /// Requests being answered (a page's event stream stays one for as long as it is open).
    in_flight: AtomicUsize,
    /// When it last became idle, in milliseconds from the table's epoch.
    idle_since: AtomicU64,
    /// Told when the table lets it go.
    close: Notify,
}

impl Conn {
    fn is_idle(&self) -> bool {
        self.in_flight.load(Ordering::Acquire) == 0
    }
}

/// What happens to a new connection.
#[derive(Debug)]
pub enum Admit {
    /// Taken with this id; the connections listed were let go to make room.
    Taken(u64, Arc<Conn>, Vec<Arc<Conn>>),
    /// Every connection is busy: the new one is refused.
    Full,
}

/// The connections held, oldest first (ids grow with time).
#[derive(Debug, Default)]
pub struct Table {
    conns: BTreeMap<u64, Arc<Conn>>,
    next: u64,
}

impl Table {
    /// Lets the oldest idle connection go, if there is one.
    pub fn shed_oldest_idle(&mut self) -> Option<Arc<Conn>> {
        let id = self
            .conns
            .iter()
            .find(|(_, c)| c.is_idle())
            .map(|(id, _)| *id)?;
        self.conns.remove(&id)
    }

    /// A new connection at `now_ms`, under a cap of `max` connections.
    pub fn admit(&mut self, now_ms: u64, max: usize) -> Admit {
        let mut shed = Vec::new();
        while self.conns.len() >= max {
            match self.shed_oldest_idle() {
                Some(c) => shed.push(c),
                None => return Admit::Full,
            }
        }
        let id = self.next;
        self.next += 1;
        let conn = Arc::new(Conn::default());
        conn.idle_since.store(now_ms, Ordering::Release);
        self.conns.insert(id, conn.clone());
        Admit::Taken(id, conn, shed)
    }

    /// Lets go of the connections idle for `idle_ms` or more at `now_ms`.
    pub fn expire(&mut self, now_ms: u64, idle_ms: u64) -> Vec<Arc<Conn>> {
        let old: Vec<u64> = self
            .conns
            .iter()
            .filter(|(_, c)| {
                c.is_idle()
                    && now_ms.saturating_sub(c.idle_since.load(Ordering::Acquire)) >= idle_ms
            })
            .map(|(id, _)| *id)
            .collect();
        old.iter().filter_map(|id| self.conns.remove(id)).collect()
    }

    /// Forgets a connection that ended.
    pub fn remove(&mut self, id: u64) {
        self.conns.remove(&id);
    }
}

/// The table, its clock and its limits, shared by the accepting loop, the connections and the
/// sweeper.
struct Connections {
    table: Mutex<Table>,
    epoch: Instant,
    limits: Limits,
}

impl Connections {
    fn now_ms(&self) -> u64 {
        u64::try_from(self.epoch.elapsed().as_millis()).unwrap_or(u64::MAX)
    }

    fn table(&self) -> std::sync::MutexGuard<'_, Table> {
        // The table stays consistent whatever panicked while holding it.
        self.table.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// Lets connections go: each one's task closes it.
fn close(conns: Vec<Arc<Conn>>) {
    for c in conns {
        c.close.notify_one();
    }
}

/// A request being answered: the connection is busy until the answer's body is dropped (sent,
/// or the connection gone).
struct Busy {
    conn: Arc<Conn>,
    all: Arc<Connections>,
}

impl Busy {
    fn new(conn: Arc<Conn>, all: Arc<Connections>) -> Busy {
        conn.in_flight.fetch_add(1, Ordering::AcqRel);
        Busy { conn, all }
    }
}

impl Drop for Busy {
    fn drop(&mut self) {
        self.conn
            .idle_since
            .store(self.all.now_ms(), Ordering::Release);
        self.conn.in_flight.fetch_sub(1, Ordering::AcqRel);
    }
}

/// Listens on `addr` with a queue of pending connections as long as the system allows
/// (`net.core.somaxconn`): a burst of connections waits there to be accepted (and, past the
/// cap, to take an idle one's place) rather than being dropped, which a client feels as a
/// connection that takes a second or more to open.
pub fn bind(addr: SocketAddr) -> std::io::Result<TcpListener> {
    let socket = if addr.is_ipv4() {
        tokio::net::TcpSocket::new_v4()?
    } else {
        tokio::net::TcpSocket::new_v6()?
    };
    socket.set_reuseaddr(true)?;
    socket.bind(addr)?;
    socket.listen(4096)
}

/// Serves `router` on `listener` until `shutdown`, each request through `gate`, within
/// `limits`.
pub async fn serve(
    listener: TcpListener,
    router: Router,
    gate: Arc<Gate>,
    limits: Limits,
    shutdown: impl std::future::Future<Output = ()>,
) {
    let all = Arc::new(Connections {
        table: Mutex::new(Table::default()),
        epoch: Instant::now(),
        limits,
    });
    let sweeper = {
        let all = all.clone();
        tokio::spawn(async move {
            let mut tick = tokio::time::interval((limits.idle / 4).max(Duration::from_millis(50)));
            loop {
                tick.tick().await;
                let now = all.now_ms();
                let idle = u64::try_from(limits.idle.as_millis()).unwrap_or(u64::MAX);
                let expired = all.table().expire(now, idle);
                close(expired);
            }
        })
    };
    tokio::pin!(shutdown);
    loop {
        let accepted = tokio::select! {
            _ = &mut shutdown => break,
            a = listener.accept() => a,
        };
        match accepted {
            Ok((stream, _)) => accept(stream, &router, &gate, &all),
            Err(e) => {
                // Out of descriptors (EMFILE, ENFILE) or memory: make room, and do not spin.
                tracing::warn!(error = %e, "the monitor could not accept a connection");
                let shed = all.table().shed_oldest_idle();
                close(shed.into_iter().collect());
                tokio::time::sleep(Duration::from_millis(10)).await;
            }
        }
    }
    sweeper.abort();
}

/// Takes a new connection (letting idle ones go to make room), or refuses it with 503.
fn accept(stream: TcpStream, router: &Router, gate: &Arc<Gate>, all: &Arc<Connections>) {
    let admitted = all.table().admit(all.now_ms(), all.limits.max_connections);
    let (id, conn) = match admitted {
        Admit::Taken(id, conn, shed) => {
            close(shed);
            (id, conn)
        }
        Admit::Full => {
            // Small enough for the socket's buffer: written at once or not at all.
            let body =
                r#"{"error": "the monitor is serving as many connections as it may: try again"}"#;
            let answer = format!(
                "HTTP/1.1 503 Service Unavailable\r\ncontent-type: application/json\r\ncontent-length: {}\r\nconnection: close\r\n\r\n{body}",
                body.len()
            );
            let _ = stream.try_write(answer.as_bytes());
            return;
        }
    };
    let local = stream
        .local_addr()
        .unwrap_or_else(|_| SocketAddr::from(([127, 0, 0, 1], 0)));
    let (router, gate, all) = (router.clone(), gate.clone(), all.clone());
    tokio::spawn(async move {
        let service = {
            let (conn, all) = (conn.clone(), all.clone());
            hyper::service::service_fn(move |req| {
                let busy = Busy::new(conn.clone(), all.clone());
                answer(req, router.clone(), gate.clone(), local, busy)
            })
        };
        let served = hyper::server::conn::http1::Builder::new()
            .serve_connection(hyper_util::rt::TokioIo::new(stream), service);
        tokio::select! {
            _ = served => {}
            _ = conn.close.notified() => {}
        }
        all.table().remove(id);
    });
}

/// Answers one request: the gate, then the router; the headers every answer carries; the
/// connection busy until the answer's body is dropped.
async fn answer(
    req: Request<hyper::body::Incoming>,
    router: Router,
    gate: Arc<Gate>,
    local: SocketAddr,
    busy: Busy,
) -> Result<Response, Infallible> {
    use tower::ServiceExt;
    let api = req.uri().path().starts_with("/api/");
    let mut response = match gate.check(req.headers(), local) {
        Err(r) => (
            r.status,
            axum::Json(serde_json::json!({ "error": r.message })),
        )
            .into_response(),
        Ok(()) => match router.oneshot(req.map(Body::new)).await {
            Ok(r) => r,
            Err(never) => match never {},
        },
    };
    gate::secure(&mut response, api);
    Ok(response.map(|body| {
        use http_body_util::BodyExt;
        Body::new(body.map_frame(move |frame| {
            // The frame closure owns `busy`: dropped with the body.
            let _ = &busy;
            frame
        }))
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ids(t: &Table) -> Vec<u64> {
        t.conns.keys().copied().collect()
    }

    fn taken(a: Admit) -> (u64, Arc<Conn>, Vec<Arc<Conn>>) {
        match a {
            Admit::Taken(id, c, shed) => (id, c, shed),
            Admit::Full => panic!("refused"),
        }
    }

    #[test]
    fn at_the_cap_the_oldest_idle_connection_makes_room() {
        let mut t = Table::default();
        let (_, first, _) = taken(t.admit(0, 3));
        let (_, second, _) = taken(t.admit(1, 3));
        taken(t.admit(2, 3));
        // The first is busy (a page's event stream): the second, oldest idle, goes.
        first.in_flight.store(1, Ordering::Release);
        let (id, _, shed) = taken(t.admit(3, 3));
        assert_eq!(id, 3);
        assert_eq!(shed.len(), 1);
        assert!(Arc::ptr_eq(&shed[0], &second));
        assert_eq!(ids(&t), [0, 2, 3]);
        // All busy: refused, nothing let go.
        for c in t.conns.values() {
            c.in_flight.store(1, Ordering::Release);
        }
        assert!(matches!(t.admit(4, 3), Admit::Full));
        assert_eq!(t.conns.len(), 3);
        // A lower cap (fewer descriptors) sheds as many as it takes, idle ones only.
        t.conns[&2].in_flight.store(0, Ordering::Release);
        t.conns[&3].in_flight.store(0, Ordering::Release);
        let (_, _, shed) = taken(t.admit(5, 2));
        assert_eq!(shed.len(), 2);
        assert_eq!(ids(&t), [0, 4]);
    }

    #[test]
    fn idle_connections_expire_busy_ones_stay() {
        let mut t = Table::default();
        let (_, stream, _) = taken(t.admit(0, 10));
        taken(t.admit(0, 10));
        let (_, late, _) = taken(t.admit(900, 10));
        stream.in_flight.store(1, Ordering::Release);
        assert!(t.expire(999, 1_000).is_empty());
        let gone = t.expire(1_000, 1_000);
        assert_eq!(gone.len(), 1);
        assert_eq!(ids(&t), [0, 2]);
        // Idle again from when its last answer ended.
        late.idle_since.store(1_500, Ordering::Release);
        assert!(t.expire(2_400, 1_000).is_empty());
        assert_eq!(t.expire(2_500, 1_000).len(), 1);
        assert_eq!(ids(&t), [0]);
        t.remove(0);
        assert_eq!(t.conns.len(), 0);
    }
}
