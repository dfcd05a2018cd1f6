//! Following a running player: the current marking, the latest steps and the status, kept from
//! what the player publishes anyway (marking deltas, heartbeats) and pushed to the pages.
//!
//! The player numbers its deltas (0 is the snapshot of the start) and its heartbeat says how
//! many it has published (`progress`) beside a status holding the whole marking. A monitor that
//! joins late, or that missed deltas, takes the marking of the next heartbeat, then the deltas
//! from its `progress` on: it is in step without the player doing anything for it. The thread
//! never makes the player wait: it only reads; a delta it could not take in time (1,024 behind)
//! shows as a gap, and it takes the next heartbeat's marking again.

use super::names::{self, Names};
use petrel_ipc::{Participant, Reactor, Role, Vehicle, WaitStrategy};
use serde_json::{json, Value as Json};
use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::sync::broadcast;

/// Steps the pages' event log starts with.
const LOG_STEPS: usize = 500;
/// Deltas kept while out of step, to apply after the heartbeat that puts us back in step.
const PENDING_DELTAS: usize = 4_096;
/// Messages a page may fall behind before it gets the latest marking instead.
pub const PAGE_BACKLOG: usize = 1_024;
/// How often the programs' liveness is read and the status pushed (at most).
const STATUS_PERIOD: Duration = Duration::from_millis(500);

/// What the monitor knows of the mission, shared by the follower thread and the pages.
pub struct Live {
    state: Mutex<State>,
    tx: broadcast::Sender<Arc<str>>,
    /// Set to end the follower thread.
    pub stop: AtomicBool,
}

/// The mission as last seen.
#[derive(Default)]
struct State {
    /// In step with the player: the marking is the player's after step `next - 1`.
    synced: bool,
    next: u64,
    time: f64,
    marked: BTreeSet<String>,
    active: BTreeSet<String>,
    over: bool,
    /// The latest steps, as the page reads them.
    log: VecDeque<Arc<str>>,
    /// The latest status message.
    status: Option<Arc<str>>,
    /// Why the monitor is not in step, when it is not.
    notice: Option<String>,
}

impl Live {
    /// An empty monitor, not in step.
    pub fn new() -> Arc<Self> {
        let (tx, _) = broadcast::channel(PAGE_BACKLOG);
        Arc::new(Live {
            state: Mutex::new(State {
                notice: Some("waiting for the player's first heartbeat".into()),
                ..State::default()
            }),
            tx,
            stop: AtomicBool::new(false),
        })
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, State> {
        // A panic elsewhere while holding the lock leaves a state that is still a marking.
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// What a page opening now starts from (the marking, the latest steps, the status), and
    /// the stream of what follows: taken under one lock, so nothing is missed or repeated.
    pub fn attach(&self) -> (Vec<Arc<str>>, broadcast::Receiver<Arc<str>>) {
        let s = self.lock();
        let rx = self.tx.subscribe();
        let mut first = vec![snapshot(&s, None, true)];
        first.extend(s.status.iter().cloned());
        (first, rx)
    }

    /// The latest marking, for a page that fell `skipped` messages behind.
    pub fn resync(&self, skipped: u64) -> Arc<str> {
        snapshot(&self.lock(), Some(skipped), false)
    }

    /// Says on every page why the monitor cannot follow the vehicle.
    pub fn fail(&self, why: String) {
        let mut s = self.lock();
        s.synced = false;
        s.notice = Some(why);
        s.resynced(&self.tx);
    }

    /// The marking as the test hooks and `/api/marking` give it.
    pub fn marking(&self) -> Json {
        let s = self.lock();
        json!({
            "synced": s.synced,
            "step": s.next,
            "marked": s.marked.iter().map(|p| names::place_id(p)).collect::<Vec<_>>(),
            "active": s.active,
        })
    }
}

/// What one page receives: the marking it starts from, then every change; when it falls more
/// than [`PAGE_BACKLOG`] messages behind, the latest marking (saying how many it skipped)
/// instead of the messages it missed.
pub fn page_stream(live: Arc<Live>) -> impl futures_util::Stream<Item = Arc<str>> + Send {
    use futures_util::StreamExt;
    use tokio::sync::broadcast::error::RecvError;
    let (first, rx) = live.attach();
    let rest = futures_util::stream::unfold((rx, live), |(mut rx, live)| async move {
        let msg = match rx.recv().await {
            Ok(m) => m,
            Err(RecvError::Lagged(n)) => live.resync(n),
            Err(RecvError::Closed) => return None,
        };
        Some((msg, (rx, live)))
    });
    futures_util::stream::iter(first).chain(rest)
}

/// A snapshot message: the whole marking (and, for a page that opens, the latest steps).
fn snapshot(s: &State, skipped: Option<u64>, with_log: bool) -> Arc<str> {
    let log: Vec<Json> = if with_log {
        s.log
            .iter()
            .filter_map(|m| serde_json::from_str(m).ok())
            .collect()
    } else {
        Vec::new()
    };
    json!({
        "type": "snapshot",
        "synced": s.synced,
        "step": s.next,
        "time": s.time,
        "over": s.over,
        "marked": s.marked.iter().map(|p| names::place_id(p)).collect::<Vec<_>>(),
        "active": s.active,
        "notice": s.notice,
        "skipped": skipped,
        "log": log,
    })
    .to_string()
    .into()
}

impl State {
    fn send(&mut self, tx: &broadcast::Sender<Arc<str>>, msg: Arc<str>) {
        // No page open is not an error: the message is only for pages.
        let _ = tx.send(msg);
    }

    fn resynced(&mut self, tx: &broadcast::Sender<Arc<str>>) {
        let msg = snapshot(self, None, false);
        self.send(tx, msg);
    }
}

/// Follows vehicle `vehicle` until `live.stop`: joins it as `tool/monitor<pid>`, reads the
/// player's deltas and heartbeats and the CAN data server's, and keeps `live` up to date.
pub fn follow(
    project: &petrel_nets::compiled::CompiledProject,
    names: &Names,
    vehicle: &Vehicle,
    live: &Live,
) -> Result<(), String> {
    let role = Role::tool(&format!("monitor{}", std::process::id())).map_err(|e| e.to_string())?;
    let me = Participant::join(vehicle, role)
        .map_err(|e| format!("cannot join vehicle `{}`: {e}", vehicle.name()))?;
    let deltas = me.marking_subscriber().map_err(|e| e.to_string())?;
    let beats = me.heartbeat_subscriber().map_err(|e| e.to_string())?;
    let signals = me.signals_subscriber().ok();
    // Ctrl-C is the web server's to handle; this thread is told through `stop`.
    let reactor =
        Reactor::without_signal_handling(WaitStrategy::Block).map_err(|e| e.to_string())?;
    let programs: Vec<String> = project.programs.iter().map(|p| p.name.clone()).collect();
    let mut pending: VecDeque<petrel_ipc::MarkingMsg> = VecDeque::new();
    let mut player_status: Option<Json> = None;
    let mut player_beat: Option<(Instant, u32)> = None;
    let mut player_uptime = 0u64;
    let mut bridge_status: Option<Json> = None;
    let mut latest_signals: Option<petrel_ipc::SignalsMsg> = None;
    let mut next_status = Instant::now();
    let mut last_status_text = String::new();
    while !live.stop.load(Ordering::Relaxed) {
        if let Err(e) = reactor.wait(&[&deltas], Some(Duration::from_millis(100))) {
            tracing::warn!(error = %e, "waiting for the player's steps failed; retrying");
            std::thread::sleep(Duration::from_millis(10));
        }
        // Heartbeats first: a delta that follows one is applied on the marking it gives.
        let mut beat_marking = None;
        let mut restarted = false;
        let _ = beats.drain(|r| {
            let Ok(rcv) = r else { return };
            match rcv.origin.as_str() {
                "player" => {
                    let doc: Json = serde_json::from_str(&rcv.msg.status).unwrap_or_default();
                    player_beat = Some((Instant::now(), rcv.msg.period_ms));
                    // A player younger than the last one heard is a new player (restarted):
                    // its steps count from 0 again.
                    if rcv.msg.uptime_ms < player_uptime {
                        restarted = true;
                    }
                    player_uptime = rcv.msg.uptime_ms;
                    if let Some(m) = names::status_marking(&doc) {
                        beat_marking = Some((
                            rcv.msg.progress,
                            m,
                            doc["time"].as_f64(),
                            doc["over"] == true,
                        ));
                    }
                    player_status = Some(doc);
                }
                "can_bridge" => bridge_status = serde_json::from_str(&rcv.msg.status).ok(),
                _ => {}
            }
        });
        if let Some(sub) = &signals {
            let _ = sub.drain(|r| {
                if let Ok(rcv) = r {
                    latest_signals = Some(rcv.msg);
                }
            });
        }
        let mut received = Vec::new();
        let _ = deltas.drain(|r| match r {
            Ok(rcv) if rcv.origin.as_str() == "player" => received.push(rcv.msg),
            Ok(_) => {}
            Err(e) => tracing::warn!(error = %e, "a marking delta could not be read"),
        });
        {
            let mut s = live.lock();
            if restarted && s.synced {
                s.synced = false;
                s.notice = Some("the player restarted: taking its marking again".into());
            }
            if let Some((progress, (marked, active), time, over)) = beat_marking {
                let beat = Beat {
                    progress,
                    marked,
                    active,
                    time,
                    over,
                };
                heartbeat(&mut s, names, &live.tx, beat, &mut pending);
            }
            for msg in received {
                delta(&mut s, names, &live.tx, msg, &mut pending);
            }
        }
        let now = Instant::now();
        if now >= next_status {
            next_status = now + STATUS_PERIOD;
            let liveness: BTreeMap<&str, &str> = programs
                .iter()
                .map(|p| {
                    let st = match petrel_ipc::program_status(vehicle, p) {
                        Ok(petrel_ipc::ProgramStatus::Alive) => "alive",
                        Ok(petrel_ipc::ProgramStatus::Joining) => "joining",
                        Ok(petrel_ipc::ProgramStatus::Dead) => "dead",
                        Ok(petrel_ipc::ProgramStatus::Absent) => "absent",
                        Err(_) => "unknown",
                    };
                    (p.as_str(), st)
                })
                .collect();
            // The player is silent after three periods without a heartbeat.
            let player = match player_beat {
                Some((at, period))
                    if at.elapsed() < Duration::from_millis(3 * period.max(1) as u64) =>
                {
                    "alive"
                }
                Some(_) => "silent",
                None => "not seen",
            };
            let status = json!({
                "type": "status",
                "player": player,
                "status": player_status,
                "programs": liveness,
                "bridge": bridge_status,
                "signals": latest_signals.as_ref().map(|m| m.values.iter().map(|(n, v, t)| json!([n, v, *t as f64 / 1e6])).collect::<Vec<_>>()),
            });
            // Only a change is pushed (the uptime inside the status changes at every beat,
            // so in flight this is every period).
            let text = status.to_string();
            if text != last_status_text {
                last_status_text = text.clone();
                let msg: Arc<str> = text.into();
                let mut s = live.lock();
                s.status = Some(msg.clone());
                s.send(&live.tx, msg);
            }
        }
    }
    Ok(())
}

/// What a heartbeat of the player says of the marking.
struct Beat {
    /// Deltas published so far: the marking is the one after step `progress - 1`.
    progress: u64,
    marked: BTreeSet<String>,
    active: BTreeSet<String>,
    time: Option<f64>,
    over: bool,
}

/// A heartbeat: when out of step, its marking, then the deltas held since that are newer.
fn heartbeat(
    s: &mut State,
    names: &Names,
    tx: &broadcast::Sender<Arc<str>>,
    beat: Beat,
    pending: &mut VecDeque<petrel_ipc::MarkingMsg>,
) {
    if s.synced {
        return;
    }
    s.marked = beat.marked;
    s.active = beat.active;
    s.next = beat.progress;
    s.time = beat.time.unwrap_or(s.time);
    s.over = beat.over;
    s.synced = true;
    s.notice = None;
    let held: Vec<_> = pending.drain(..).collect();
    for m in held {
        apply(s, names, tx, m);
    }
    s.resynced(tx);
}

/// A delta: applied when in step (step numbers tell a gap exactly: the receiver's own count of
/// missed messages also counts those sent before this monitor joined), held otherwise.
fn delta(
    s: &mut State,
    names: &Names,
    tx: &broadcast::Sender<Arc<str>>,
    msg: petrel_ipc::MarkingMsg,
    pending: &mut VecDeque<petrel_ipc::MarkingMsg>,
) {
    if s.synced || msg.snapshot {
        apply(s, names, tx, msg);
    } else {
        if pending.len() == PENDING_DELTAS {
            pending.pop_front();
        }
        pending.push_back(msg);
    }
}

/// Applies one delta of the player to the state, and pushes it to the pages.
fn apply(
    s: &mut State,
    names: &Names,
    tx: &broadcast::Sender<Arc<str>>,
    msg: petrel_ipc::MarkingMsg,
) {
    if msg.snapshot {
        // The start of a player (a new one, or a restarted one): the whole state.
        s.marked = msg.marked.iter().cloned().collect();
        s.active = msg.activated.iter().cloned().collect();
        s.next = msg.step + 1;
        s.time = msg.time_us as f64 / 1e6;
        s.over = false;
        s.synced = true;
        s.notice = None;
        s.resynced(tx);
        return;
    }
    if msg.step < s.next {
        // Already in the heartbeat's marking.
        return;
    }
    if msg.step > s.next {
        s.synced = false;
        s.notice = Some(format!(
            "missed the player's steps {} to {}: taking its marking again from its next heartbeat",
            s.next,
            msg.step - 1
        ));
        s.resynced(tx);
        return;
    }
    for p in &msg.unmarked {
        s.marked.remove(p);
    }
    s.marked.extend(msg.marked.iter().cloned());
    for n in &msg.deactivated {
        s.active.remove(n);
    }
    s.active.extend(msg.activated.iter().cloned());
    s.next = msg.step + 1;
    s.time = msg.time_us as f64 / 1e6;
    if names.category(msg.event.as_deref().unwrap_or("")) == "catastrophic" {
        s.over = true;
    }
    let step = names.step_json(
        msg.step,
        msg.time_us,
        msg.event.as_deref(),
        &msg.params,
        &msg.fired,
        &msg.actions,
        &msg.marked,
        &msg.unmarked,
        &msg.activated,
        &msg.deactivated,
    );
    let text: Arc<str> = step.to_string().into();
    if s.log.len() == LOG_STEPS {
        s.log.pop_front();
    }
    s.log.push_back(text.clone());
    s.send(tx, text);
}

#[cfg(test)]
mod tests {
    use super::*;
    use futures_util::StreamExt;
    use petrel_ipc::MarkingMsg;

    fn project() -> petrel_nets::compiled::CompiledProject {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../missions/uav");
        let (_, c, d) = petrel_nets::project::load_and_check(&dir).expect("the UAV mission");
        assert!(!d.has_errors());
        c.expect("it compiles")
    }

    fn step(n: u64, marked: &[&str], unmarked: &[&str]) -> MarkingMsg {
        MarkingMsg {
            step: n,
            event: Some("start_mission".into()),
            marked: marked.iter().map(|s| s.to_string()).collect(),
            unmarked: unmarked.iter().map(|s| s.to_string()).collect(),
            ..MarkingMsg::default()
        }
    }

    fn set(items: &[&str]) -> BTreeSet<String> {
        items.iter().map(|s| s.to_string()).collect()
    }

    fn json(m: &str) -> Json {
        serde_json::from_str(m).unwrap()
    }

    #[test]
    fn a_late_monitor_takes_the_heartbeat_then_the_newer_deltas() {
        let p = project();
        let names = Names::new(&p);
        let live = Live::new();
        let mut pending = VecDeque::new();
        let mut s = State::default();
        // Deltas 4 and 5 come before the heartbeat that says 5 were published (0 to 4).
        delta(
            &mut s,
            &names,
            &live.tx,
            step(4, &["MISSION.rolling"], &["MISSION.ready"]),
            &mut pending,
        );
        delta(
            &mut s,
            &names,
            &live.tx,
            step(5, &["MISSION.taking_off"], &["MISSION.rolling"]),
            &mut pending,
        );
        assert!(!s.synced);
        let beat = Beat {
            progress: 5,
            marked: set(&["MISSION.rolling", "EVENTS.watching"]),
            active: set(&["MISSION", "EVENTS"]),
            time: Some(1.0),
            over: false,
        };
        heartbeat(&mut s, &names, &live.tx, beat, &mut pending);
        assert!(s.synced);
        assert_eq!(s.next, 6);
        assert_eq!(s.marked, set(&["EVENTS.watching", "MISSION.taking_off"]));
        // A gap: out of step, said, and in step again at the next heartbeat.
        delta(
            &mut s,
            &names,
            &live.tx,
            step(8, &["MISSION.climbing"], &[]),
            &mut pending,
        );
        assert!(!s.synced);
        assert!(s
            .notice
            .as_deref()
            .unwrap()
            .contains("missed the player's steps 6 to 7"));
        let beat = Beat {
            progress: 9,
            marked: set(&["MISSION.climbing"]),
            active: set(&["MISSION"]),
            time: None,
            over: false,
        };
        heartbeat(&mut s, &names, &live.tx, beat, &mut pending);
        assert!(s.synced && s.notice.is_none());
        assert_eq!(s.marked, set(&["MISSION.climbing"]));
        // A new player's snapshot replaces everything.
        let mut snap = step(0, &["MISSION.ready", "global.on_ground"], &[]);
        snap.snapshot = true;
        snap.activated = vec!["MISSION".into()];
        delta(&mut s, &names, &live.tx, snap, &mut pending);
        assert_eq!((s.next, s.marked.len()), (1, 2));
    }

    #[test]
    fn a_page_that_lags_skips_to_the_latest_marking_and_is_told() {
        let p = project();
        let names = Names::new(&p);
        let live = Live::new();
        {
            let mut s = live.lock();
            s.synced = true;
            s.next = 1;
        }
        let rt = tokio::runtime::Builder::new_current_thread()
            .build()
            .unwrap();
        rt.block_on(async {
            let mut page = Box::pin(page_stream(live.clone()));
            let first = json(&page.next().await.unwrap());
            assert_eq!(first["type"], "snapshot");
            assert_eq!(first["step"], 1);
            // The page reads nothing while 1,500 steps go by.
            let mut pending = VecDeque::new();
            for n in 1..=1_500u64 {
                let (m, u) = if n % 2 == 1 {
                    (["MISSION.rolling"], ["MISSION.ready"])
                } else {
                    (["MISSION.ready"], ["MISSION.rolling"])
                };
                let mut s = live.lock();
                delta(&mut s, &names, &live.tx, step(n, &m, &u), &mut pending);
            }
            let next = json(&page.next().await.unwrap());
            assert_eq!(next["type"], "snapshot", "{next}");
            assert!(
                next["skipped"].as_u64().unwrap() >= 1_500 - PAGE_BACKLOG as u64,
                "{next}"
            );
            assert_eq!(next["step"], 1_501);
            assert_eq!(next["marked"], serde_json::json!(["MISSION.ready"]));
            // Then the steps that followed, one by one.
            let later = json(&page.next().await.unwrap());
            assert_eq!(later["type"], "step");
        });
    }
}
