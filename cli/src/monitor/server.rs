//! The web server: the page and its assets, the drawing, the JSON API and the event stream.
//!
//! | route                  | what                                                          |
//! |------------------------|---------------------------------------------------------------|
//! | `GET /`                | the page (`assets/index.html`, `monitor.js`, `monitor.css`)   |
//! | `GET /api/model`       | the project as the page needs it, the mode, whether it may send |
//! | `GET /api/nets.svg`    | the nets, laid out by Graphviz                                |
//! | `GET /api/tree.svg`    | the tree of nets                                              |
//! | `GET /api/net.svg?name=NET` | one net alone, its global places as ports                |
//! | `GET /api/map.svg?w=W&h=H` | the map (map.toml), as drawn now; replay: `&t=T` at a time |
//! | `GET /api/events`      | live: Server-Sent Events (a snapshot, then steps and status)  |
//! | `GET /api/marking`     | live: the current marking as JSON                             |
//! | `GET /api/replay`      | replay: the journal's timeline                                |
//! | `POST /api/send`       | `--operator` only, with the token: `{"event": "name(args)"}`  |
//!
//! Every error is JSON, `{"error": "..."}`, with 400 (a request that cannot mean anything),
//! 403 (read-only monitor, missing or wrong token, a foreign origin), 404 (no such route, or
//! not in this mode), 408 (a body too slow to come), 413 (a body too large), 421 (a host
//! the monitor does not answer to), 502 (the player did not take the event) or 503 (too many
//! pages open).
//!
//! The requests go through [`conns`](super::conns) (the connection cap, the idle deadline)
//! and [`gate`](super::gate) (Host, Origin, the headers of every answer) before they reach
//! the routes.

use super::conns::{self, Limits};
use super::gate::Gate;
use super::layout::Drawing;
use super::live::{self, Live};
use super::names::Names;
use super::operator;
use crate::common::Outcome;
use crate::map::{feed::MapState, Map};
use axum::extract::{RawQuery, State};
use axum::http::{header, HeaderMap, StatusCode};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::Router;
use futures_util::stream::{Stream, StreamExt};
use petrel_nets::compiled::CompiledProject;
use serde_json::{json, Value as Json};
use std::convert::Infallible;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{mpsc, Arc, Mutex};
use std::time::Duration;

const INDEX_HTML: &str = include_str!("assets/index.html");
const MONITOR_JS: &str = include_str!("assets/monitor.js");
const MONITOR_CSS: &str = include_str!("assets/monitor.css");

/// The largest body of a request (an event's text is a few hundred bytes).
const BODY_LIMIT: usize = 64 * 1024;
/// How long a request's body may take to come.
const BODY_TIMEOUT: Duration = Duration::from_secs(10);

/// What the monitor shows.
pub enum Mode {
    /// A running vehicle.
    Live {
        /// The vehicle followed.
        vehicle: Box<petrel_ipc::Vehicle>,
        /// Whether the page may send events, and where the token goes.
        sending: Sending,
    },
    /// A recorded mission: its timeline, and its map when the project has one.
    Replay(Json, Option<Box<(Map, MapState)>>),
}

/// Whether the page may send events (`--operator`), and where the token is shown.
pub enum Sending {
    /// No: the monitor only reads.
    ReadOnly,
    /// Yes, the token printed on the standard output, a terminal.
    Terminal,
    /// Yes, the token written to this file, owner-only (`--token-file`).
    TokenFile(PathBuf),
}

/// Where and how the monitor serves.
pub struct Web {
    /// The address it listens on.
    pub listen: SocketAddr,
    /// Who may ask.
    pub gate: Gate,
    /// How many connections, how long idle.
    pub limits: Limits,
}

/// A drawing of the map, by the version of what it shows and its width and height.
type DrawnMap = ((u64, u32, u32), Arc<str>);

/// The server's state, shared by every request.
struct App {
    project: Arc<CompiledProject>,
    drawing: Drawing,
    model: Json,
    live: Option<Arc<Live>>,
    replay: Option<Json>,
    /// A replay's map: everything the run showed, cut at the page's time.
    replay_map: Option<Box<(Map, MapState)>>,
    /// The map's latest drawing, by (version, width, height): pages that ask together get
    /// it drawn once.
    map_drawn: Mutex<Option<DrawnMap>>,
    /// The operator's token and the queue of the thread that sends, with `--operator`.
    operator: Option<(String, Mutex<mpsc::Sender<operator::Request>>)>,
    /// Event streams open, and the most allowed: half the connections, so that a page can
    /// always load whatever the streams hold.
    streams: Arc<AtomicUsize>,
    max_streams: usize,
}

/// A JSON error response.
fn error(status: StatusCode, message: impl Into<String>) -> Response {
    (status, axum::Json(json!({ "error": message.into() }))).into_response()
}

/// Serves the monitor as `web` says until Ctrl-C or `run_for`.
pub fn serve(
    project: CompiledProject,
    names: Names,
    drawing: Drawing,
    (mode, map): (Mode, Option<Map>),
    web: Web,
    run_for: Option<Duration>,
) -> Outcome {
    let project = Arc::new(project);
    let names = Arc::new(names);
    let mut model = names.model.clone();
    let mut token_file = None;
    let mut replay_map = None;
    let (live, replay, operator, vehicle) = match mode {
        Mode::Live { vehicle, sending } => {
            model["mode"] = json!("live");
            model["vehicle"] = json!(vehicle.name());
            model["operator"] = json!(!matches!(sending, Sending::ReadOnly));
            if let Sending::TokenFile(f) = &sending {
                token_file = Some(f.clone());
            }
            let op = if !matches!(sending, Sending::ReadOnly) {
                let token = match operator::new_token() {
                    Ok(t) => t,
                    Err(e) => return Outcome::Usage(e),
                };
                let (tx, rx) = mpsc::channel();
                let v = (*vehicle).clone();
                std::thread::spawn(move || operator::serve(v, rx));
                Some((token, Mutex::new(tx)))
            } else {
                None
            };
            model["map"] = json!(map.as_ref().map(|m| m.title.clone()));
            (Some(Live::new(map)), None, op, Some(*vehicle))
        }
        Mode::Replay(t, m) => {
            model["mode"] = json!("replay");
            model["operator"] = json!(false);
            model["map"] = json!(m.as_deref().map(|(m, _)| m.title.clone()));
            replay_map = m;
            (None, Some(t), None, None)
        }
    };
    let token = operator.as_ref().map(|(t, _)| t.clone());
    let app = Arc::new(App {
        project: project.clone(),
        drawing,
        model,
        live: live.clone(),
        replay,
        replay_map,
        map_drawn: Mutex::new(None),
        operator,
        streams: Arc::new(AtomicUsize::new(0)),
        max_streams: (web.limits.max_connections / 2).max(1),
    });
    let follower = match (&live, vehicle) {
        (Some(live), Some(vehicle)) => {
            let (live, project, names) = (live.clone(), project.clone(), names.clone());
            Some(std::thread::spawn(move || {
                if let Err(e) = live::follow(&project, &names, &vehicle, &live) {
                    tracing::error!(error = %e, "the monitor cannot follow the vehicle");
                    live.fail(format!("the monitor cannot follow the vehicle: {e}"));
                }
            }))
        }
        _ => None,
    };
    let runtime = match tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
    {
        Ok(r) => r,
        Err(e) => return Outcome::Usage(format!("cannot start the web server: {e}")),
    };
    let Web {
        listen,
        gate,
        limits,
    } = web;
    let outcome = runtime.block_on(async move {
        let listener = match conns::bind(listen) {
            Ok(l) => l,
            Err(e) => return Outcome::Usage(format!("cannot listen on {listen}: {e}")),
        };
        let addr = listener.local_addr().unwrap_or(listen);
        // Kept while the monitor serves; removed when it ends.
        let _token_file = match (&token, &token_file) {
            (Some(t), Some(path)) => match operator::TokenFile::write(path, t) {
                Ok(f) => Some(f),
                Err(e) => return Outcome::Usage(e),
            },
            _ => None,
        };
        crate::common::out(&format!("petrel monitor: listening on http://{addr}/\n"));
        match (&token, &token_file) {
            (Some(_), Some(path)) => crate::common::out(&format!(
                "operator token: in {} (owner-only); open http://{addr}/#token=TOKEN to send events from the page\n",
                path.display()
            )),
            (Some(t), None) => crate::common::out(&format!(
                "operator token: {t}\nopen http://{addr}/#token={t} to send events from the page\n"
            )),
            _ => {}
        }
        let router = Router::new()
            .route("/", get(index))
            .route("/monitor.js", get(script))
            .route("/monitor.css", get(style))
            .route("/api/model", get(model_route))
            .route("/api/nets.svg", get(nets_svg))
            .route("/api/tree.svg", get(tree_svg))
            .route("/api/net.svg", get(net_svg))
            .route("/api/map.svg", get(map_svg))
            .route("/api/events", get(events))
            .route("/api/marking", get(marking))
            .route("/api/replay", get(replay_route))
            .route("/api/send", post(send))
            .fallback(not_found)
            .method_not_allowed_fallback(not_allowed)
            .with_state(app);
        let shutdown = async move {
            match run_for {
                Some(d) => {
                    tokio::select! {
                        _ = tokio::time::sleep(d) => {}
                        _ = tokio::signal::ctrl_c() => {}
                        _ = terminate() => {}
                    }
                }
                None => {
                    tokio::select! {
                        _ = tokio::signal::ctrl_c() => {}
                        _ = terminate() => {}
                    }
                }
            }
        };
        conns::serve(listener, router, Arc::new(gate), limits, shutdown).await;
        Outcome::Clean
    });
    // Open event streams would hold the graceful shutdown forever: the runtime's end drops them.
    runtime.shutdown_timeout(Duration::from_millis(200));
    if let Some(live) = &live {
        live.stop.store(true, std::sync::atomic::Ordering::Relaxed);
    }
    if let Some(f) = follower {
        let _ = f.join();
    }
    outcome
}

/// SIGTERM, as `petrel up` and test harnesses stop processes.
async fn terminate() {
    match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
        Ok(mut s) => {
            s.recv().await;
        }
        Err(_) => std::future::pending::<()>().await,
    }
}

async fn index() -> Response {
    (
        [(header::CONTENT_TYPE, "text/html; charset=utf-8")],
        INDEX_HTML,
    )
        .into_response()
}

async fn script() -> Response {
    (
        [(header::CONTENT_TYPE, "text/javascript; charset=utf-8")],
        MONITOR_JS,
    )
        .into_response()
}

async fn style() -> Response {
    (
        [(header::CONTENT_TYPE, "text/css; charset=utf-8")],
        MONITOR_CSS,
    )
        .into_response()
}

async fn model_route(State(app): State<Arc<App>>) -> Response {
    axum::Json(app.model.clone()).into_response()
}

async fn nets_svg(State(app): State<Arc<App>>) -> Response {
    (
        [(header::CONTENT_TYPE, "image/svg+xml")],
        app.drawing.nets.clone(),
    )
        .into_response()
}

async fn tree_svg(State(app): State<Arc<App>>) -> Response {
    (
        [(header::CONTENT_TYPE, "image/svg+xml")],
        app.drawing.tree.clone(),
    )
        .into_response()
}

/// The value of `key` in a query string (`a=1&b=x%2Fy`), percent-decoded.
fn query_value(query: &str, key: &str) -> Option<String> {
    query.split('&').find_map(|kv| {
        let (k, v) = kv.split_once('=').unwrap_or((kv, ""));
        (k == key).then(|| percent_decode(v))
    })
}

/// `%XX` and `+` decoded (a net's name has `/` in it); bytes that are not UTF-8 are replaced.
fn percent_decode(s: &str) -> String {
    let hex = |c: u8| (c as char).to_digit(16).map(|d| d as u8);
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        let pair = (b[i] == b'%')
            .then(|| Some((hex(*b.get(i + 1)?)?, hex(*b.get(i + 2)?)?)))
            .flatten();
        match (b[i], pair) {
            (_, Some((hi, lo))) => {
                out.push(hi * 16 + lo);
                i += 3;
                continue;
            }
            (b'+', _) => out.push(b' '),
            (c, _) => out.push(c),
        }
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

async fn net_svg(State(app): State<Arc<App>>, RawQuery(query): RawQuery) -> Response {
    let Some(name) = query_value(query.as_deref().unwrap_or(""), "name") else {
        return error(
            StatusCode::BAD_REQUEST,
            "give the net: /api/net.svg?name=NET",
        );
    };
    let laid = tokio::task::spawn_blocking(move || app.drawing.each.get(&name)).await;
    match laid {
        Ok(Ok(svg)) => ([(header::CONTENT_TYPE, "image/svg+xml")], svg.to_string()).into_response(),
        Ok(Err(e)) => error(StatusCode::NOT_FOUND, e),
        Err(e) => error(
            StatusCode::INTERNAL_SERVER_ERROR,
            format!("the layout failed: {e}"),
        ),
    }
}

/// The map as drawn now (live), or at `t` (replay), `w` x `h` px: the page asks for its
/// canvas's size, so that the text is drawn at its size.
async fn map_svg(State(app): State<Arc<App>>, RawQuery(query): RawQuery) -> Response {
    let q = query.unwrap_or_default();
    let px = |k: &str, default: u32| {
        query_value(&q, k)
            .and_then(|v| v.parse::<f64>().ok())
            .filter(|v| v.is_finite())
            .map_or(default, |v| v.clamp(320.0, 8000.0) as u32)
    };
    let (w, h) = (px("w", 1000), px("h", 800));
    let svg: Arc<str> = if let Some((map, state)) = app.replay_map.as_deref() {
        let t = query_value(&q, "t")
            .and_then(|v| v.parse::<f64>().ok())
            .filter(|t| t.is_finite());
        let (shown, note) = match t {
            Some(t) => (state.until(t), Some(format!("mission time {t:.1} s"))),
            None => (state.clone(), None),
        };
        crate::map::svg::map_svg(map, &shown, w, h, note.as_deref()).into()
    } else if let Some((map, state)) = app.live.as_ref().and_then(|l| l.map_state()) {
        let key = (state.version, w, h);
        let mut drawn = app.map_drawn.lock().unwrap_or_else(|e| e.into_inner());
        match drawn.as_ref() {
            Some((k, svg)) if *k == key => svg.clone(),
            _ => {
                let svg: Arc<str> = crate::map::svg::map_svg(map, &state, w, h, None).into();
                *drawn = Some((key, svg.clone()));
                svg
            }
        }
    } else {
        return error(
            StatusCode::NOT_FOUND,
            "this project has no map: write its map.toml (docs/monitor.md, \"The map\")",
        );
    };
    ([(header::CONTENT_TYPE, "image/svg+xml")], svg.to_string()).into_response()
}

async fn not_found(uri: axum::http::Uri) -> Response {
    error(
        StatusCode::NOT_FOUND,
        format!("no such page: {}", uri.path()),
    )
}

async fn not_allowed(method: axum::http::Method, uri: axum::http::Uri) -> Response {
    error(
        StatusCode::METHOD_NOT_ALLOWED,
        format!("{method} is not allowed on {}", uri.path()),
    )
}

async fn marking(State(app): State<Arc<App>>) -> Response {
    match &app.live {
        Some(live) => axum::Json(live.marking()).into_response(),
        None => error(
            StatusCode::NOT_FOUND,
            "this monitor replays a journal: its marking is in /api/replay",
        ),
    }
}

async fn replay_route(State(app): State<Arc<App>>) -> Response {
    match &app.replay {
        Some(t) => axum::Json(t.clone()).into_response(),
        None => error(
            StatusCode::NOT_FOUND,
            "this monitor follows a live vehicle: start it with --journal DIR to replay one",
        ),
    }
}

/// The live stream: what a page starts from, then every change; a page that fell behind by
/// more than the channel holds gets the latest marking, with how much it skipped.
async fn events(State(app): State<Arc<App>>) -> Response {
    let Some(live) = app.live.clone() else {
        return error(
            StatusCode::NOT_FOUND,
            "this monitor replays a journal: there is no live stream",
        );
    };
    let Some(slot) = StreamSlot::take(&app.streams, app.max_streams) else {
        return error(
            StatusCode::SERVICE_UNAVAILABLE,
            format!(
                "{} pages are following this monitor already, as many as it serves: close one",
                app.max_streams
            ),
        );
    };
    let s: std::pin::Pin<Box<dyn Stream<Item = Result<Event, Infallible>> + Send>> =
        Box::pin(live::page_stream(live).map(move |m| {
            // The stream owns its slot: given back when the page goes.
            let _ = &slot;
            Ok(Event::default().data(&*m))
        }));
    Sse::new(s).keep_alive(KeepAlive::default()).into_response()
}

/// One of the event streams a monitor serves; given back when dropped.
struct StreamSlot(Arc<AtomicUsize>);

impl StreamSlot {
    /// A slot, if fewer than `max` streams are open.
    fn take(open: &Arc<AtomicUsize>, max: usize) -> Option<StreamSlot> {
        open.fetch_update(Ordering::AcqRel, Ordering::Acquire, |n| {
            (n < max).then_some(n + 1)
        })
        .ok()
        .map(|_| StreamSlot(open.clone()))
    }
}

impl Drop for StreamSlot {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::AcqRel);
    }
}

/// Sends an operator event: `--operator` only, with the token in the header `X-Petrel-Token`
/// (never in the address: it would stay in the browser's history, and a form of another site
/// could send it), a body `{"event": "name(args)"}` read as `petrel send` reads its argument.
async fn send(
    State(app): State<Arc<App>>,
    RawQuery(query): RawQuery,
    headers: HeaderMap,
    body: axum::body::Body,
) -> Response {
    let Some((token, queue)) = &app.operator else {
        return error(
            StatusCode::FORBIDDEN,
            "this monitor is read-only: start it with --operator to send events",
        );
    };
    let given = headers.get("x-petrel-token").and_then(|v| v.to_str().ok());
    match given {
        None if query_has_token(query.as_deref().unwrap_or("")) => {
            return error(
                StatusCode::FORBIDDEN,
                "the operator token goes in the header X-Petrel-Token, not in the address (open the page at /#token=TOKEN)",
            )
        }
        None => {
            return error(
                StatusCode::FORBIDDEN,
                "sending events needs the operator token (header X-Petrel-Token) that petrel monitor showed or wrote to its --token-file",
            )
        }
        Some(g) if !operator::same_token(g, token) => {
            return error(StatusCode::FORBIDDEN, "wrong operator token")
        }
        Some(_) => {}
    }
    let body = match tokio::time::timeout(BODY_TIMEOUT, axum::body::to_bytes(body, BODY_LIMIT))
        .await
    {
        Ok(Ok(b)) => b,
        Ok(Err(e)) => {
            let too_large = std::error::Error::source(&e)
                .is_some_and(|s| s.is::<http_body_util::LengthLimitError>());
            return if too_large {
                error(
                    StatusCode::PAYLOAD_TOO_LARGE,
                    format!("the body is larger than the {BODY_LIMIT} bytes a request may hold"),
                )
            } else {
                error(
                    StatusCode::BAD_REQUEST,
                    format!("the body could not be read: {e}"),
                )
            };
        }
        Err(_) => {
            return error(
                StatusCode::REQUEST_TIMEOUT,
                format!("the body did not come within {} s", BODY_TIMEOUT.as_secs()),
            )
        }
    };
    let doc: Json = match serde_json::from_slice(&body) {
        Ok(d) => d,
        Err(e) => {
            return error(
                StatusCode::BAD_REQUEST,
                format!("the body is not JSON ({e}): send {{\"event\": \"name(args)\"}}"),
            )
        }
    };
    let Some(text) = doc.get("event").and_then(Json::as_str) else {
        return error(
            StatusCode::BAD_REQUEST,
            "the body has no `event` text: send {\"event\": \"name(args)\"}",
        );
    };
    let (name, params) = match crate::common::operator_event(text, &app.project) {
        Ok(e) => e,
        Err(e) => return error(StatusCode::BAD_REQUEST, e),
    };
    let (reply, verdict) = tokio::sync::oneshot::channel();
    let queued = queue
        .lock()
        .map(|q| {
            q.send(operator::Request {
                name,
                params,
                reply,
            })
            .is_ok()
        })
        .unwrap_or(false);
    if !queued {
        return error(
            StatusCode::INTERNAL_SERVER_ERROR,
            "the monitor's sending thread has stopped",
        );
    }
    match verdict.await {
        Ok(Ok(v)) if v["taken"] == true => axum::Json(v).into_response(),
        Ok(Ok(v)) => (StatusCode::BAD_GATEWAY, axum::Json(v)).into_response(),
        Ok(Err(e)) => error(StatusCode::BAD_GATEWAY, e),
        Err(_) => error(
            StatusCode::INTERNAL_SERVER_ERROR,
            "the monitor's sending thread has stopped",
        ),
    }
}

/// Whether a query string carries a `token` (as addresses printed before did).
fn query_has_token(query: &str) -> bool {
    query
        .split('&')
        .any(|kv| kv.split_once('=').map_or(kv, |(k, _)| k) == "token")
}

#[cfg(test)]
mod tests {
    #[test]
    fn query_values_are_decoded() {
        let q = "name=MISSION%2FPHASES&t=1.5&x=%zz%4&y=a+b";
        assert_eq!(
            super::query_value(q, "name").as_deref(),
            Some("MISSION/PHASES")
        );
        assert_eq!(super::query_value(q, "t").as_deref(), Some("1.5"));
        assert_eq!(super::query_value(q, "x").as_deref(), Some("%zz%4"));
        assert_eq!(super::query_value(q, "y").as_deref(), Some("a b"));
        assert_eq!(super::query_value(q, "z"), None);
        assert_eq!(super::percent_decode("%C3%A9%e9"), "\u{e9}\u{fffd}");
    }
}
