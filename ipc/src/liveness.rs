//! Which processes of a vehicle are alive, which died, and cleaning up after the dead.
//!
//! Every [`Participant`](crate::Participant) is an iceoryx2 node named after its role
//! (`player`, `program/PLN`, ...). A process killed without warning (SIGKILL, a crash) leaves
//! its node's files in `/dev/shm` and the vehicle's directory; iceoryx2 sees that the node's
//! owner is gone (its file lock was released) and reports it dead until someone removes the
//! stale resources. `petrel play` calls [`cleanup_dead_nodes`] at start; the player turns a
//! program whose process went into a `program_lost(name)` event (or, when the program said it
//! leaves in good order, a stop) with a [`ProgramWatch`], which also tells a program that
//! receives its calls (ready) from one whose node lives without (joining).
//!
//! Only nodes of the given [`Vehicle`] are seen: its directory and session keep the others
//! apart ([`access`](crate::access)).

use std::fmt;
use std::time::Duration;

use iceoryx2::node::{NodeCleanupFailure, NodeListFailure, NodeView};
use iceoryx2::prelude::{ipc, CallbackProgression, Node, NodeState};

use crate::naming::{program_node_name, Vehicle};
use crate::participant::{CallsView, Participant, SetupError};

/// Whether a node's process lives.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum NodeStatus {
    /// The process runs.
    Alive,
    /// The process died without removing its resources.
    Dead,
    /// This process may not inspect the node (another user's).
    Inaccessible,
    /// The node's files are incomplete or inconsistent (being created or removed).
    Undefined,
}

/// A node of the vehicle.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NodeInfo {
    /// iceoryx2's unique id of the node.
    pub id: u128,
    /// The node's name (`player`, `program/PLN`...); empty when its details are unreadable.
    pub name: String,
    /// The owning process, when known.
    pub pid: Option<i32>,
    /// The owning process's executable, when known.
    pub executable: Option<String>,
    /// Alive or not.
    pub status: NodeStatus,
}

/// The node list could not be read, or files could not be removed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LivenessError {
    /// Listing the nodes failed.
    List {
        /// The vehicle.
        vehicle: String,
        /// iceoryx2's reason.
        error: NodeListFailure,
    },
    /// [`remove_vehicle_files`] found nodes of the vehicle.
    InUse {
        /// The vehicle.
        vehicle: String,
        /// Names of its nodes.
        nodes: Vec<String>,
    },
    /// The vehicle's files could not be reached (see [`access`](crate::access)).
    Access(crate::AccessError),
    /// A file could not be removed.
    Io {
        /// The file.
        path: String,
        /// The system's reason.
        error: String,
    },
}

impl fmt::Display for LivenessError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LivenessError::List { vehicle, error } => write!(
                f,
                "cannot list the processes of vehicle `{vehicle}` ({error:?}); check the permissions of its directory (`{}` set, or the default)",
                crate::RUNTIME_DIR_ENV
            ),
            LivenessError::Access(e) => e.fmt(f),
            LivenessError::InUse { vehicle, nodes } => write!(
                f,
                "vehicle `{vehicle}` still has nodes ({}); stop its processes and clean up dead ones first",
                nodes.join(", ")
            ),
            LivenessError::Io { path, error } => write!(f, "cannot remove `{path}`: {error}"),
        }
    }
}

impl std::error::Error for LivenessError {}

impl From<crate::AccessError> for LivenessError {
    fn from(e: crate::AccessError) -> Self {
        LivenessError::Access(e)
    }
}

fn info_of<V: NodeView>(view: &V, status: NodeStatus) -> NodeInfo {
    let details = view.details().as_ref();
    NodeInfo {
        id: view.id().value(),
        name: details
            .map(|d| d.name().as_str().to_owned())
            .unwrap_or_default(),
        pid: details.map(|d| d.process_id().value()),
        executable: details.map(|d| d.executable().to_string()),
        status,
    }
}

fn visit(
    vehicle: &Vehicle,
    mut f: impl FnMut(NodeState<ipc::Service>),
) -> Result<(), LivenessError> {
    let session = vehicle.session()?;
    Node::<ipc::Service>::list(session.config(), |state| {
        f(state);
        CallbackProgression::Continue
    })
    .map_err(|error| LivenessError::List {
        vehicle: vehicle.name().to_owned(),
        error,
    })
}

fn info(state: &NodeState<ipc::Service>) -> NodeInfo {
    match state {
        NodeState::Alive(view) => info_of(view, NodeStatus::Alive),
        NodeState::Dead(view) => info_of(view, NodeStatus::Dead),
        NodeState::Inaccessible(id) => NodeInfo {
            id: id.value(),
            name: String::new(),
            pid: None,
            executable: None,
            status: NodeStatus::Inaccessible,
        },
        NodeState::Undefined(id) => NodeInfo {
            id: id.value(),
            name: String::new(),
            pid: None,
            executable: None,
            status: NodeStatus::Undefined,
        },
    }
}

/// Every node of the vehicle, alive or not, sorted by name.
pub fn list_nodes(vehicle: &Vehicle) -> Result<Vec<NodeInfo>, LivenessError> {
    let mut nodes = Vec::new();
    visit(vehicle, |state| nodes.push(info(&state)))?;
    nodes.sort_by(|a, b| (&a.name, a.id).cmp(&(&b.name, b.id)));
    Ok(nodes)
}

/// The nodes of the vehicle whose process died without cleaning up.
pub fn dead_nodes(vehicle: &Vehicle) -> Result<Vec<NodeInfo>, LivenessError> {
    Ok(list_nodes(vehicle)?
        .into_iter()
        .filter(|n| n.status == NodeStatus::Dead)
        .collect())
}

/// What [`cleanup_dead_nodes`] did.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct CleanupReport {
    /// Dead nodes whose resources were removed.
    pub cleaned: Vec<NodeInfo>,
    /// Dead nodes that could not be cleaned, with iceoryx2's reason.
    pub failed: Vec<(NodeInfo, NodeCleanupFailure)>,
}

/// Removes the resources of every dead node of the vehicle (what `petrel play` does at start).
///
/// A node another process is already cleaning is waited for up to `timeout`. Receivers of
/// services the dead node sent on are woken with a "sender died" notification
/// ([`Wakeups::senders_died`](crate::port::Wakeups::senders_died)).
pub fn cleanup_dead_nodes(
    vehicle: &Vehicle,
    timeout: Duration,
) -> Result<CleanupReport, LivenessError> {
    let mut dead = Vec::new();
    visit(vehicle, |state| {
        if let NodeState::Dead(view) = state {
            dead.push(view);
        }
    })?;
    let mut report = CleanupReport::default();
    for view in dead {
        let info = info_of(&view, NodeStatus::Dead);
        match view.blocking_remove_stale_resources(timeout) {
            Ok(()) | Err(NodeCleanupFailure::ResourcesAlreadyCleanedUp) => {
                report.cleaned.push(info)
            }
            Err(error) => report.failed.push((info, error)),
        }
    }
    // The doorbells of the nodes that are gone (cleaned now, or earlier by iceoryx2 itself),
    // and news for the receivers asleep on theirs (crate::doorbell).
    if let Ok(prefix) = vehicle.shm_prefix() {
        let remaining = || {
            let mut ids = Vec::new();
            visit(vehicle, |state| ids.push(info(&state).id))
                .ok()
                .map(|()| ids)
        };
        crate::doorbell::after_cleanup(&prefix, remaining, !report.cleaned.is_empty());
    }
    Ok(report)
}

/// Whether a program runs, and whether it receives its calls.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ProgramStatus {
    /// A node of the program is alive. Seen by a [`ProgramWatch`], more: a live node of the
    /// program has its calls receiver connected, so a call sent now reaches it (the program
    /// is ready). [`program_status`], which lists the nodes only, says `Alive` as soon as a
    /// node lives.
    Alive,
    /// A node of the program is alive but receives no calls yet (it is joining: its node is
    /// made before its calls receiver) or any more (it is leaving). Only a [`ProgramWatch`]
    /// tells it from [`Alive`](Self::Alive); the player holds the calls it makes to such a
    /// program until it receives them (docs/semantics.md, "Held calls").
    Joining,
    /// The program's node is dead (killed, crashed) and not yet cleaned up.
    Dead,
    /// No node of the program exists: never started, stopped in good order, or cleaned up.
    Absent,
}

impl ProgramStatus {
    /// A live process of the program, ready or not.
    pub fn is_running(self) -> bool {
        matches!(self, ProgramStatus::Alive | ProgramStatus::Joining)
    }
}

/// The status of program `name` from its nodes alone: alive if any of its nodes is alive, else
/// dead if one is dead. Whether it receives its calls is [`ProgramWatch`]'s to say.
pub fn program_status(vehicle: &Vehicle, name: &str) -> Result<ProgramStatus, LivenessError> {
    node_status(vehicle, &program_node_name(name))
}

/// The status of the node named `node_name` (`player`, `can_bridge`, `program/PLN`...).
pub fn node_status(vehicle: &Vehicle, node_name: &str) -> Result<ProgramStatus, LivenessError> {
    let mut nodes = Vec::new();
    visit(vehicle, |state| nodes.push(info(&state)))?;
    Ok(status_among(&nodes, node_name, None))
}

/// The status of the nodes named `node_name` among `nodes`; with `receivers` (the nodes that
/// receive the program's calls), [`ProgramStatus::Alive`] only when one of the live ones is
/// among them.
fn status_among(nodes: &[NodeInfo], node_name: &str, receivers: Option<&[u128]>) -> ProgramStatus {
    let mut status = ProgramStatus::Absent;
    for n in nodes.iter().filter(|n| n.name == node_name) {
        match n.status {
            NodeStatus::Alive => {
                let receives = receivers.is_none_or(|r| r.contains(&n.id));
                if receives {
                    return ProgramStatus::Alive;
                }
                status = ProgramStatus::Joining;
            }
            NodeStatus::Dead if status == ProgramStatus::Absent => status = ProgramStatus::Dead,
            _ => {}
        }
    }
    status
}

/// Whether program `name` has a live node.
pub fn is_program_alive(vehicle: &Vehicle, name: &str) -> Result<bool, LivenessError> {
    Ok(program_status(vehicle, name)? == ProgramStatus::Alive)
}

/// A change of a program's status, seen by [`ProgramWatch::check`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ProgramChange {
    /// The program.
    pub program: String,
    /// Its status at the previous check.
    pub from: ProgramStatus,
    /// Its status now.
    pub to: ProgramStatus,
}

impl ProgramChange {
    /// The program's process was running (ready or not) and is not any more: it died, or it
    /// left (the player's `program_lost`, unless the program said it leaves in good order).
    pub fn is_lost(&self) -> bool {
        self.from.is_running() && !self.to.is_running()
    }
}

/// Watches the status of a set of programs, one node listing per [`check`](Self::check): a
/// program is [`Alive`](ProgramStatus::Alive) (ready) once a live node of it receives its
/// calls, [`Joining`](ProgramStatus::Joining) while its node lives without (iceoryx2 makes a
/// node before its ports: a program's node is seen a moment before its calls receiver).
///
/// iceoryx2 does not watch processes by itself: a dead node is noticed when someone lists the
/// nodes. The player checks on an interval of its reactor, and whenever a receiver reports
/// [`senders_died`](crate::port::Wakeups::senders_died); `petrel up` at each round while a
/// program starts.
#[derive(Debug)]
pub struct ProgramWatch {
    vehicle: Vehicle,
    known: std::collections::BTreeMap<String, Watched>,
}

/// What a [`ProgramWatch`] knows of one program.
#[derive(Debug)]
struct Watched {
    status: ProgramStatus,
    /// The ids of its live nodes at the last check: a program whose processes all went and
    /// came back between two checks (killed and restarted at once) is a new one.
    live: Vec<u128>,
    view: CallsView,
}

impl ProgramWatch {
    /// Watches `programs` through `participant` (which opens, or makes, their calls services
    /// to see who receives them), all taken as [`ProgramStatus::Absent`] until the first check.
    pub fn new<I, S>(participant: &Participant, programs: I) -> Result<Self, SetupError>
    where
        I: IntoIterator<Item = S>,
        S: Into<String>,
    {
        let mut known = std::collections::BTreeMap::new();
        for p in programs {
            let p = p.into();
            let view = participant.calls_view(&p)?;
            let watched = Watched {
                status: ProgramStatus::Absent,
                live: Vec::new(),
                view,
            };
            known.insert(p, watched);
        }
        Ok(ProgramWatch {
            vehicle: participant.vehicle().clone(),
            known,
        })
    }

    /// The status of `program` at the last check.
    pub fn status(&self, program: &str) -> Option<ProgramStatus> {
        self.known.get(program).map(|w| w.status)
    }

    /// The status of `program` now (one node listing), without changing what the next
    /// [`check`](Self::check) compares with; `None` for a program not watched.
    pub fn probe(&self, program: &str) -> Result<Option<ProgramStatus>, LivenessError> {
        let Some(watched) = self.known.get(program) else {
            return Ok(None);
        };
        let nodes = list_nodes(&self.vehicle)?;
        let receivers = watched.view.receiver_nodes();
        Ok(Some(status_among(
            &nodes,
            &program_node_name(program),
            Some(&receivers),
        )))
    }

    /// Lists the nodes once and returns the programs whose status changed, in name order. A
    /// program whose every process went and came back since the last check (killed and
    /// restarted within a period) changes twice: it went ([`Absent`](ProgramStatus::Absent)),
    /// then it came back.
    pub fn check(&mut self) -> Result<Vec<ProgramChange>, LivenessError> {
        let nodes = list_nodes(&self.vehicle)?;
        let mut changes = Vec::new();
        for (program, watched) in self.known.iter_mut() {
            let node_name = program_node_name(program);
            let receivers = watched.view.receiver_nodes();
            let now = status_among(&nodes, &node_name, Some(&receivers));
            let live: Vec<u128> = nodes
                .iter()
                .filter(|n| n.name == node_name && n.status == NodeStatus::Alive)
                .map(|n| n.id)
                .collect();
            let mut change = |from, to| {
                changes.push(ProgramChange {
                    program: program.clone(),
                    from,
                    to,
                })
            };
            let replaced = watched.status.is_running()
                && now.is_running()
                && !watched.live.iter().any(|id| live.contains(id));
            if replaced {
                change(watched.status, ProgramStatus::Absent);
                change(ProgramStatus::Absent, now);
            } else if now != watched.status {
                change(watched.status, now);
            }
            watched.status = now;
            watched.live = live;
        }
        Ok(changes)
    }
}

/// Removes what iceoryx2 left of the vehicle (its shared memory in `/dev/shm`, its part of the
/// vehicle's directory, the node counter iceoryx2 never removes) once no node of the vehicle
/// exists. The vehicle's last process does as much when it leaves ([`access`](crate::access));
/// this is for tests and tools that want it done now. Returns the number of files and
/// directories removed.
///
/// Refuses with [`LivenessError::InUse`] while any node of the vehicle, alive or dead, exists.
/// Do not call it while a process of the vehicle may be starting.
pub fn remove_vehicle_files(vehicle: &Vehicle) -> Result<usize, LivenessError> {
    let nodes = list_nodes(vehicle)?;
    if !nodes.is_empty() {
        return Err(LivenessError::InUse {
            vehicle: vehicle.name().to_owned(),
            nodes: nodes.into_iter().map(|n| n.name).collect(),
        });
    }
    Ok(vehicle.session()?.clear())
}

/// A vehicle with a file prefix of its own ([`Vehicle::isolated`]) whose files are removed when
/// it is dropped, pass or fail: for tests and throw-away tools, so that nothing is left in
/// `/dev/shm` or the vehicle's directory. Drop it after the processes that use it are gone.
#[derive(Debug)]
pub struct IsolatedVehicle(Vehicle);

impl IsolatedVehicle {
    /// A new isolated vehicle named `name`.
    pub fn new(name: &str) -> Result<Self, crate::NameError> {
        Ok(IsolatedVehicle(Vehicle::isolated(name)?))
    }
}

impl std::ops::Deref for IsolatedVehicle {
    type Target = Vehicle;
    fn deref(&self) -> &Vehicle {
        &self.0
    }
}

impl Drop for IsolatedVehicle {
    fn drop(&mut self) {
        // Nodes of processes that died (a test that panicked) are cleaned first, so that the
        // vehicle's files can go.
        let _ = cleanup_dead_nodes(&self.0, Duration::from_secs(1));
        if let Err(e) = remove_vehicle_files(&self.0) {
            eprintln!("files of vehicle {} left behind: {e}", self.0.name());
        }
    }
}

/// What the player said of one sender's events, as [`wait_acknowledged`] last heard it.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Acknowledgement {
    /// The player's latest account of the sender; `None` when no heartbeat of the player
    /// named it (no player, or one that never took anything from this sender).
    pub ack: Option<crate::wire::Ack>,
    /// The state of the player's flight recorder, as its latest heartbeat said.
    pub recorder: crate::wire::Recorder,
    /// Whether any heartbeat of the player was heard.
    pub heard: bool,
}

impl Acknowledgement {
    /// True when every message of the sender up to `seq` is settled: refused, or taken and on
    /// the flight record, or counted as unrecorded.
    pub fn settled(&self, seq: u64) -> bool {
        self.ack.as_ref().is_some_and(|a| a.settles(seq))
    }

    /// True when every message up to `seq` is settled and the flight recorder lost none of the
    /// sender's events: what the player took survives a crash of the player.
    pub fn is_safe(&self, seq: u64) -> bool {
        self.settled(seq) && self.ack.as_ref().is_some_and(|a| a.unrecorded == 0)
    }
}

/// Waits up to `grace` until the player's heartbeat says that every message of sender
/// `sender` (its [`Sender::sender_id`](crate::Sender::sender_id)) up to `seq` is settled, and
/// returns what it last said.
///
/// A sender's shared memory goes with its process: a message the player has not taken yet is
/// lost if its sender exits. Every sender that leaves (`petrel send`, a program's
/// `Program::close`, the CAN data server) waits here first. The acknowledgement is the typed
/// [`Ack`](crate::wire::Ack) the player's heartbeat carries for each sender, and a message is
/// settled only once the player's flight recorder holds it (or, when the recorder had to drop
/// it, counts it as unrecorded): [`Acknowledgement::is_safe`] tells the two apart.
///
/// On a computer without the player, the events go through the computer's `petrel gateway`,
/// and the player never hears of those the link gave up: for a sender with such events, the
/// gateway's own heartbeat carries its verdict, the player's acknowledgement (as the gateway
/// heard it) with the gateway's refusals merged in. That one is then the verdict.
pub fn wait_acknowledged(
    beats: &crate::HeartbeatSubscriber,
    sender: u64,
    seq: u64,
    grace: Duration,
) -> Acknowledgement {
    let deadline = std::time::Instant::now() + grace;
    let mut heard = Acknowledgement::default();
    let (mut player, mut gateway): (Option<crate::wire::Ack>, Option<crate::wire::Ack>) =
        (None, None);
    loop {
        // A heartbeat that cannot be read is one acknowledgement fewer: the next one comes
        // 100 ms later.
        let _ = beats.drain(|r| {
            if let Ok(rcv) = r {
                let origin = rcv.origin.as_str();
                if origin == "player" {
                    heard.heard = true;
                    heard.recorder = rcv.msg.recorder.clone();
                    if let Some(a) = rcv.msg.ack_for(sender) {
                        player = Some(a.clone());
                    }
                } else if crate::Role::is_gateway_node(origin) {
                    if let Some(a) = rcv.msg.ack_for(sender) {
                        gateway = Some(a.clone());
                    }
                }
            }
        });
        // The gateway's verdict, once it has one, includes the player's: wait for it to settle
        // (it lags the player's by one of its heartbeats at most).
        let settled = match &gateway {
            Some(g) => g.settles(seq),
            None => player.as_ref().is_some_and(|p| p.settles(seq)),
        };
        heard.ack = gateway.clone().or_else(|| player.clone());
        if settled || std::time::Instant::now() >= deadline {
            return heard;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}
