//! The one place that knows iceoryx2: service names for a vehicle, the wire format of the
//! messages, the ports that carry them through shared memory, waiting for them, and the
//! liveness of the vehicle's processes.
//!
//! ```text
//!  programs, CAN bridge, tools --EventMsg--> petrel/<vehicle>/events ----------> player
//!  player --CallMsg--> petrel/<vehicle>/calls/<PROGRAM> ------------------------> program
//!  player --MarkingMsg--> petrel/<vehicle>/marking -----------------------------> monitors
//!  anyone --Heartbeat--> petrel/<vehicle>/heartbeat ----------------------------> anyone
//!  CAN bridge --SignalsMsg--> petrel/<vehicle>/signals -------------------------> programs
//!  petrel reload --ReloadRequest--> petrel/<vehicle>/reload --------------------> player
//!  player --ReloadAnswer--> petrel/<vehicle>/reload/answer ---------> petrel reload, shadows
//! ```
//!
//! Each arrow is an iceoryx2 publish-subscribe service on `[u8]` (a bincode body, see
//! [`wire`]) with a fixed [`wire::MsgHeader`] (sender, sequence number), paired with an event
//! service of the same name whose notifications wake the receiver.
//!
//! - [`naming`] holds [`Vehicle`] (service names, the file prefix that isolates a vehicle or a test)
//!   and [`Role`] (the node name of a process).
//! - [`wire`] holds [`Value`], [`EventMsg`], [`CallMsg`], [`MarkingMsg`], [`Heartbeat`], the header,
//!   encoding straight into loaned shared memory.
//! - [`Participant`] is one process of a vehicle; it opens the ports.
//! - [`port`] holds [`Sender`] and [`Receiver`] (aliased as [`EventSender`], [`EventReceiver`],
//!   [`CallSender`], [`CallReceiver`], [`MarkingPublisher`], [`MarkingSubscriber`],
//!   [`HeartbeatPublisher`], [`HeartbeatSubscriber`]), buffer sizes, accounting of every message.
//! - [`reactor`] holds [`Reactor`] and [`WaitStrategy`] (block, spin, spin then block).
//! - [`doorbell`] lets a sender wake a receiver asleep on a futex word, and skip waking one
//!   that is awake; iceoryx2's notifications remain for receivers asleep on epoll.
//! - [`liveness`] tells nodes alive and dead, cleanup of dead ones, program status.
//! - [`mapped`] maps a window of a file for appending without a system call per record (the
//!   player's flight recorder).
//! - [`access`] puts a vehicle's files where only its user (and an optional group) can reach
//!   them, and removes them when its last process leaves.
//!
//! ```no_run
//! use petrel_ipc::{EventMsg, Participant, Reactor, Role, Value, Vehicle, WaitStrategy};
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let vehicle = Vehicle::new("redermor")?;
//! // In the player:
//! let player = Participant::join(&vehicle, Role::Player)?;
//! let events = player.event_receiver()?;
//! // In a program:
//! let pln = Participant::join(&vehicle, Role::program("PLN")?)?;
//! let to_player = pln.event_sender()?;
//! to_player.send(&EventMsg::new("waypoint", vec![Value::FloatList(vec![43.1, 5.9])]))?;
//! // Back in the player:
//! let reactor = Reactor::new(WaitStrategy::Block)?;
//! let ready = reactor.wait(&[&events], None)?;
//! if ready.is_ready(0) {
//!     events.drain(|event| println!("{event:?}"))?;
//! }
//! # Ok(())
//! # }
//! ```
//!
//! Every process of a vehicle must be built with the same `petrel-ipc` (and so the same
//! iceoryx2, pinned at `=0.10.0`: the shared-memory layout is versioned).

#![warn(missing_docs)]

pub mod access;
pub mod doorbell;
mod epoll;
pub mod liveness;
pub mod mapped;
pub mod mending;
pub mod naming;
mod participant;
pub mod port;
pub mod reactor;
pub mod wire;

/// The iceoryx2 this crate is built on, for what it does not wrap (use this path rather than a
/// dependency of your own, so that every crate of Petrel agrees on the version).
pub use iceoryx2;

pub use access::{AccessError, Group, GROUP_ENV, RUNTIME_DIR_ENV};
pub use liveness::{
    cleanup_dead_nodes, dead_nodes, is_program_alive, list_nodes, program_status,
    remove_vehicle_files, wait_acknowledged, Acknowledgement, CleanupReport, IsolatedVehicle,
    LivenessError, NodeInfo, NodeStatus, ProgramChange, ProgramStatus, ProgramWatch,
};
pub use naming::{NameError, Role, Vehicle};
pub use participant::{
    event_senders, CallsView, Participant, ServiceFailure, SetupError, EVENT_SENDERS_SPARE,
    MIN_FIXED_LEN, PROGRAM_SENDERS_GONE,
};
pub use port::{
    CallReceiver, CallSender, Drained, EventReceiver, EventSender, HeartbeatPublisher,
    HeartbeatSubscriber, MarkingPublisher, MarkingSubscriber, Received, Receiver, ReceiverStats,
    RecvError, ReloadAnswerPublisher, ReloadAnswerSubscriber, ReloadReceiver, ReloadRequester,
    SendError, Sender, SenderAccount, SenderStats, Sent, ServiceSpec, SignalsPublisher,
    SignalsSubscriber, Wakeups, SPIN_WAKEUP_PERIOD,
};
pub use reactor::{
    FdSource, Reactor, ReactorError, ReactorStats, Ready, Source, SourceKey, WaitStrategy,
};
pub use wire::{
    Ack, AckRefusal, CallMsg, CallRef, EventMsg, Heartbeat, MarkingMsg, Origin, Recorder,
    RecorderState, ReloadAnswer, ReloadRequest, SignalsMsg, Value, WireError,
};
