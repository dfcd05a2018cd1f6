//! A process taking part in a vehicle: its iceoryx2 node, named after its [`Role`], and the ports
//! it opens.

use std::fmt;
use std::sync::Arc;
use std::thread;
use std::time::Duration;

use iceoryx2::node::NodeCreationFailure;
use iceoryx2::port::listener::ListenerCreateError;
use iceoryx2::port::notifier::NotifierCreateError;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::publisher::PublisherCreateError;
use iceoryx2::port::subscriber::SubscriberCreateError;
use iceoryx2::prelude::{
    ipc, AllocationStrategy, AttributeSpecifier, BackpressureStrategy, CallbackProgression,
    EventId, Node, NodeBuilder, NodeName, PortFactory, SemanticString, ServiceName,
};
use iceoryx2::service::attribute::{AttributeKey, AttributeValue};
use iceoryx2::service::builder::event::{EventOpenError, EventOpenOrCreateError};
use iceoryx2::service::builder::publish_subscribe::{
    PublishSubscribeOpenError, PublishSubscribeOpenOrCreateError,
};
use iceoryx2::service::port_factory::{event, publish_subscribe};

use crate::access::{AccessError, Session};
use crate::mending::Mending;
use crate::naming::{NameError, Role, Vehicle};
use crate::port::{
    CallReceiver, CallSender, EventReceiver, EventSender, HeartbeatPublisher, HeartbeatSubscriber,
    MarkingPublisher, MarkingSubscriber, Receiver, ReloadAnswerPublisher, ReloadAnswerSubscriber,
    ReloadReceiver, ReloadRequester, Sender, ServiceSpec, SignalsPublisher, SignalsSubscriber,
    CALLS, EVENTS, HEARTBEAT, MARKING, RELOAD, RELOAD_ANSWER, SIGNALS, WAKE_MAX, WAKE_SENDER_DIED,
    WAKE_SENDER_JOINED, WAKE_SENDER_LEFT,
};
use crate::wire::{Message, MsgHeader, Origin};

/// Why iceoryx2 could not set up a service or a port.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ServiceFailure {
    /// Opening or creating the publish-subscribe service failed.
    PubSub(PublishSubscribeOpenOrCreateError),
    /// Opening or creating the paired event service failed.
    Event(EventOpenOrCreateError),
    /// Creating the publisher failed.
    Publisher(PublisherCreateError),
    /// Creating the subscriber failed.
    Subscriber(SubscriberCreateError),
    /// Creating the notifier failed.
    Notifier(NotifierCreateError),
    /// Creating the listener failed.
    Listener(ListenerCreateError),
}

impl ServiceFailure {
    fn hint(&self) -> &'static str {
        use PublishSubscribeOpenError as O;
        match self {
            ServiceFailure::PubSub(PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(
                O::IncompatibleTypes | O::IncompatibleOverflowBehavior | O::VersionMismatch,
            )) => "a process built from another version of Petrel uses this service; rebuild every process of the vehicle together",
            // (An opener asks for no number of senders or processes: `open_pubsub`.)
            ServiceFailure::PubSub(PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(
                O::DoesNotSupportRequestedMinBufferSize
                | O::DoesNotSupportRequestedAmountOfSubscribers,
            )) => "a process built with other service settings created this service; rebuild every process of the vehicle together",
            ServiceFailure::PubSub(PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(
                O::ExceedsMaxNumberOfNodes,
            ))
            | ServiceFailure::Event(EventOpenOrCreateError::EventOpenError(
                EventOpenError::ExceedsMaxNumberOfNodes,
            )) => "too many processes use this service",
            ServiceFailure::PubSub(PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(
                O::InsufficientPermissions,
            )) => "another user created this service; run every process of the vehicle as one user",
            ServiceFailure::Subscriber(SubscriberCreateError::ExceedsMaxSupportedSubscribers)
            | ServiceFailure::Listener(ListenerCreateError::ExceedsMaxSupportedListeners) => {
                "the service already has all the receivers it accepts (is a second player or program instance running? `petrel play` cleans up dead ones at start)"
            }
            _ => "check that /dev/shm and the vehicle's directory are writable and not full",
        }
    }
}

/// A participant or one of its ports could not be set up.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SetupError {
    /// A name was refused.
    Name(NameError),
    /// The vehicle's files could not be set up or are not safe to use.
    Access(AccessError),
    /// The iceoryx2 node could not be created.
    Node {
        /// The node's name.
        node: String,
        /// iceoryx2's reason.
        error: NodeCreationFailure,
    },
    /// A service or a port could not be set up.
    Service {
        /// The service.
        service: String,
        /// iceoryx2's reason.
        failure: ServiceFailure,
    },
    /// The service already has every sender it was made for.
    SendersFull {
        /// The service.
        service: String,
        /// The senders it takes.
        max: usize,
    },
    /// Only a program receives calls, on its own service.
    NotAProgram {
        /// The participant's role.
        role: Role,
    },
}

impl fmt::Display for SetupError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SetupError::Name(e) => e.fmt(f),
            SetupError::Access(e) => e.fmt(f),
            SetupError::Node { node, error } => write!(
                f,
                "cannot create the iceoryx2 node `{node}` ({error:?}); check that /dev/shm and the vehicle's directory are writable"
            ),
            SetupError::Service { service, failure } => write!(
                f,
                "cannot set up `{service}` ({failure:?}): {}",
                failure.hint()
            ),
            SetupError::SendersFull { service, max } => write!(
                f,
                "cannot send on `{service}`: it takes {max} senders and all are in use (a player makes the events service for its project's programs plus {EVENT_SENDERS_SPARE}: data servers, tools, restarted programs; a project reloaded with more programs needs the player restarted)"
            ),
            SetupError::NotAProgram { role } => write!(
                f,
                "`{role}` is not a program: only a program receives calls (join with Role::Program)"
            ),
        }
    }
}

impl std::error::Error for SetupError {}

impl From<NameError> for SetupError {
    fn from(e: NameError) -> Self {
        SetupError::Name(e)
    }
}

impl From<AccessError> for SetupError {
    fn from(e: AccessError) -> Self {
        SetupError::Access(e)
    }
}

/// One process of a vehicle: an iceoryx2 node named after its role, from which it opens ports.
///
/// Create one per process (a node's ports are single-threaded: open them on the thread that
/// uses them). Dropping it, and all its ports, removes the process's resources; a process killed
/// before that leaves them for [`cleanup_dead_nodes`](crate::liveness::cleanup_dead_nodes).
#[derive(Debug)]
pub struct Participant {
    vehicle: Vehicle,
    role: Role,
    origin: Origin,
    node: Node<ipc::Service>,
    /// The process's membership of the vehicle: dropped after the node (fields drop in order),
    /// so that the last one out finds nothing of its own in use.
    session: Arc<Session>,
}

/// How many times a service is opened again when another process is creating or removing it at
/// the same moment.
const OPEN_ATTEMPTS: usize = 50;
const OPEN_RETRY_PAUSE: Duration = Duration::from_millis(10);

/// Whether, and when, a failed opening of a service is tried again.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Retry {
    /// Not: the failure is the answer.
    No,
    /// At once: another process created the service between our open and our create.
    AtOnce,
    /// After [`OPEN_RETRY_PAUSE`]: another process is creating or removing it.
    AfterPause,
}

fn pubsub_retry(e: &PublishSubscribeOpenOrCreateError) -> Retry {
    use iceoryx2::service::builder::publish_subscribe::PublishSubscribeCreateError as C;
    use PublishSubscribeOpenError as O;
    match e {
        PublishSubscribeOpenOrCreateError::PublishSubscribeCreateError(C::AlreadyExists) => {
            Retry::AtOnce
        }
        PublishSubscribeOpenOrCreateError::SystemInFlux
        | PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(
            O::IsMarkedForDestruction | O::HangsInCreation | O::DoesNotExist,
        )
        | PublishSubscribeOpenOrCreateError::PublishSubscribeCreateError(
            C::IsBeingCreatedByAnotherInstance,
        ) => Retry::AfterPause,
        _ => Retry::No,
    }
}

fn event_retry(e: &EventOpenOrCreateError) -> Retry {
    use iceoryx2::service::builder::event::EventCreateError as C;
    match e {
        EventOpenOrCreateError::EventCreateError(C::AlreadyExists) => Retry::AtOnce,
        EventOpenOrCreateError::SystemInFlux
        | EventOpenOrCreateError::EventOpenError(
            EventOpenError::IsMarkedForDestruction
            | EventOpenError::HangsInCreation
            | EventOpenError::DoesNotExist,
        )
        | EventOpenOrCreateError::EventCreateError(C::IsBeingCreatedByAnotherInstance) => {
            Retry::AfterPause
        }
        _ => Retry::No,
    }
}

/// `attempt` until it succeeds, `retry` says its failure is the answer, or [`OPEN_ATTEMPTS`]
/// attempts were made.
fn retrying<T, E>(
    mut attempt: impl FnMut() -> Result<T, E>,
    retry: impl Fn(&E) -> Retry,
) -> Result<T, E> {
    let mut attempts = 1;
    loop {
        match attempt() {
            Err(e) if attempts < OPEN_ATTEMPTS && retry(&e) != Retry::No => {
                attempts += 1;
                if retry(&e) == Retry::AfterPause {
                    thread::sleep(OPEN_RETRY_PAUSE);
                }
            }
            result => return result,
        }
    }
}

impl Participant {
    /// Joins `vehicle` as `role`: creates the process's iceoryx2 node, named after the role.
    ///
    /// A program's receivers keep the connections of [`PROGRAM_SENDERS_GONE`] senders gone
    /// with samples not yet read; other roles iceoryx2's default, 128 (a player sized from its
    /// project joins with [`join_player`](Self::join_player)).
    pub fn join(vehicle: &Vehicle, role: Role) -> Result<Self, SetupError> {
        let gone = match role {
            Role::Program(_) => Some(PROGRAM_SENDERS_GONE),
            _ => None,
        };
        Self::join_keeping(vehicle, role, gone)
    }

    /// Joins `vehicle` as the player of a project of `programs` programs: its receivers keep
    /// the connections of as many senders gone with events not yet read as its events service
    /// takes senders ([`event_senders`]), twice, 32 at least.
    pub fn join_player(vehicle: &Vehicle, programs: usize) -> Result<Self, SetupError> {
        let gone = event_senders(programs).saturating_mul(2).max(32);
        Self::join_keeping(vehicle, Role::Player, Some(gone))
    }

    /// Joins with receivers that keep the connections of `gone` senders gone with samples
    /// not yet read (iceoryx2's `subscriber_expired_connection_buffer`; `None`: its default).
    ///
    /// Why not the default: iceoryx2 0.10's receiver walks these slots with its live ones at
    /// every look for a sample, and the default 128 made them most of the player's walk. What
    /// the number bounds: a sender that leaves (a tool that emits and exits) before its samples
    /// are read keeps a slot until they are; beyond `gone` such senders at once, iceoryx2
    /// drops the oldest connection's unread samples (and says so in its log).
    fn join_keeping(
        vehicle: &Vehicle,
        role: Role,
        gone: Option<usize>,
    ) -> Result<Self, SetupError> {
        role.check()?;
        let node_name = role.node_name();
        let name = NodeName::new(&node_name).map_err(|_| {
            SetupError::Name(NameError::Refused {
                what: "node",
                name: node_name.clone(),
            })
        })?;
        let session = vehicle.session()?;
        let mut config = session.config().clone();
        if let Some(gone) = gone {
            // Never below the samples a receiver holds at once (iceoryx2 raises it to that).
            config
                .defaults
                .publish_subscribe
                .subscriber_expired_connection_buffer = gone.max(2);
        }
        let node = NodeBuilder::new()
            .name(&name)
            .config(&config)
            .create::<ipc::Service>()
            .map_err(|error| SetupError::Node {
                node: node_name.clone(),
                error,
            })?;
        // iceoryx2 leaves the vehicle's node counter open to every user: make it the
        // vehicle's alone before going on.
        session.secure()?;
        Ok(Participant {
            vehicle: vehicle.clone(),
            origin: Origin::new(&node_name),
            role,
            node,
            session,
        })
    }

    /// The vehicle joined.
    pub fn vehicle(&self) -> &Vehicle {
        &self.vehicle
    }

    /// The role this process plays.
    pub fn role(&self) -> &Role {
        &self.role
    }

    /// The iceoryx2 node, for what this crate does not wrap.
    pub fn node(&self) -> &Node<ipc::Service> {
        &self.node
    }

    /// A sender of events to the player, with the service's default samples: they grow by
    /// powers of two from 512 bytes up to [`EVENTS`]`.max_body_len`, which costs this process
    /// about 2 KiB per sample, 4 MB in all (see [`EVENTS`]), and its events not yet read are
    /// lost if it leaves before the player reads them (iceoryx2 removes its segments). A
    /// program wants [`event_sender_sized`](Self::event_sender_sized).
    pub fn event_sender(&self) -> Result<EventSender, SetupError> {
        self.sender(self.vehicle.events_service(), EVENTS)
    }

    /// A sender of events to the player sized from the project the player runs. When the
    /// player created the events service, it recorded there the longest event its project
    /// foresees ([`max_event_len`](Self::max_event_len)); the sender's samples are one fixed
    /// segment of that length, [`MIN_FIXED_LEN`] at least: a few bytes of this process's
    /// memory per sample instead of about 2 KiB (4 MB less). A longer event (a text or a list
    /// beyond the project's allowance, a project reloaded with longer events) still goes, in
    /// pieces of that length that the player joins ([`wire::FRAGMENT`](crate::wire::FRAGMENT)):
    /// the bound saves memory, it never refuses an event.
    ///
    /// When the service has no bound (this process created it, before the player started),
    /// the samples are [`MIN_FIXED_LEN`] long. Never the growing samples of
    /// [`event_sender`](Self::event_sender): iceoryx2 removes a growing sender's segments
    /// when it leaves, and with them the events the player had not read yet; a fixed
    /// segment's samples stay readable.
    pub fn event_sender_sized(&self) -> Result<EventSender, SetupError> {
        let service = self.vehicle.events_service();
        let factory = self.open_pubsub(&service, &EVENTS, None)?;
        let len = bound_of(&factory).map_or(MIN_FIXED_LEN, |bound| {
            bound.clamp(MIN_FIXED_LEN, EVENTS.max_body_len)
        });
        let spec = ServiceSpec {
            initial_slice_len: len,
            ..EVENTS
        };
        self.sender_with(service, spec, AllocationStrategy::Static)
    }

    /// The longest event the events service was created for
    /// ([`event_receiver_sized`](Self::event_receiver_sized)), if the process that created it recorded one.
    pub fn max_event_len(&self) -> Result<Option<usize>, SetupError> {
        let factory = self.open_pubsub(&self.vehicle.events_service(), &EVENTS, None)?;
        Ok(bound_of(&factory))
    }

    /// The player's receiver of events. The events service accepts one receiver.
    pub fn event_receiver(&self) -> Result<EventReceiver, SetupError> {
        self.receiver(self.vehicle.events_service(), EVENTS, None)
    }

    /// The player's receiver of events, sizing the events service, when it creates it, from
    /// its project: `max_event_len`, the longest event (encoded [`EventMsg`](crate::EventMsg))
    /// its project lets a process send, from which every
    /// [`event_sender_sized`](Self::event_sender_sized) sizes its samples; and `programs`, the
    /// number of programs it declares: the service takes that many senders plus
    /// [`EVENT_SENDERS_SPARE`] (see there why it is worth sizing).
    ///
    /// A service that already exists (a program created it first, or a previous player) keeps
    /// what it was created with: iceoryx2 fixes a service's attributes at its creation.
    pub fn event_receiver_sized(
        &self,
        max_event_len: usize,
        programs: usize,
    ) -> Result<EventReceiver, SetupError> {
        let max_publishers = event_senders(programs);
        let spec = ServiceSpec {
            max_publishers,
            // Every sender's process, the receiver and the processes that only look.
            max_nodes: EVENTS
                .max_nodes
                .max(max_publishers.saturating_add(EVENTS.max_nodes - EVENTS.max_publishers)),
            ..EVENTS
        };
        self.receiver(
            self.vehicle.events_service(),
            spec,
            Some(max_event_len.clamp(1, EVENTS.max_body_len)),
        )
    }

    /// A sender of calls to `program`.
    pub fn call_sender(&self, program: &str) -> Result<CallSender, SetupError> {
        self.sender(self.vehicle.calls_service(program)?, CALLS)
    }

    /// A sender of calls to `program` sized from the project: `max_body_len` is the longest
    /// call the project can make to it, encoded, when its functions take only fixed-size
    /// parameters (`None`: some take text or lists, the default sender of
    /// [`call_sender`](Self::call_sender), whose samples grow by powers of two up to
    /// [`CALLS`]`.max_body_len`).
    ///
    /// With a bound, the sender's shared memory is one fixed segment of samples of exactly
    /// that size, and it keeps about 8 bytes of its own memory per sample instead of about
    /// 2 KiB (iceoryx2 0.10 keeps a counter per sample for each of the 255 segments a growing
    /// sender may map). A longer call (a bound that was wrong) is refused like any call too
    /// large ([`SendError::Wire`](crate::SendError::Wire)).
    pub fn call_sender_sized(
        &self,
        program: &str,
        max_body_len: Option<usize>,
    ) -> Result<CallSender, SetupError> {
        let Some(bound) = max_body_len else {
            return self.call_sender(program);
        };
        let bound = bound.clamp(1, CALLS.max_body_len);
        let spec = ServiceSpec {
            max_body_len: bound,
            initial_slice_len: bound,
            ..CALLS
        };
        self.sender_with(
            self.vehicle.calls_service(program)?,
            spec,
            AllocationStrategy::Static,
        )
    }

    /// A view of program `program`'s calls service, opened (or made, as the player makes it)
    /// without a port: who receives the program's calls ([`CallsView::receiver_nodes`]). A
    /// program is ready when one of its live nodes does: what [`ProgramWatch`](crate::ProgramWatch)
    /// checks, for the player and for `petrel up`.
    pub fn calls_view(&self, program: &str) -> Result<CallsView, SetupError> {
        let factory = self.open_pubsub(&self.vehicle.calls_service(program)?, &CALLS, None)?;
        Ok(CallsView { factory })
    }

    /// The receiver of this program's calls. Only a [`Role::Program`] has one.
    pub fn call_receiver(&self) -> Result<CallReceiver, SetupError> {
        match &self.role {
            Role::Program(name) => self.receiver(self.vehicle.calls_service(name)?, CALLS, None),
            role => Err(SetupError::NotAProgram { role: role.clone() }),
        }
    }

    /// A publisher of the latest CAN signal values (the CAN data server).
    pub fn signals_publisher(&self) -> Result<SignalsPublisher, SetupError> {
        self.sender(self.vehicle.signals_service(), SIGNALS)
    }

    /// A subscriber to the latest CAN signal values.
    pub fn signals_subscriber(&self) -> Result<SignalsSubscriber, SetupError> {
        self.receiver(self.vehicle.signals_service(), SIGNALS, None)
    }

    /// A publisher of marking deltas.
    pub fn marking_publisher(&self) -> Result<MarkingPublisher, SetupError> {
        self.sender(self.vehicle.marking_service(), MARKING)
    }

    /// A publisher of marking deltas whose samples are one fixed segment of `fixed_len` bytes
    /// ([`MIN_FIXED_LEN`] at least; the player's: what its project's snapshots take), a few
    /// bytes of this process's memory per sample instead of about 2 KiB. A longer message (a
    /// step with long actions or parameters) still goes, in pieces the monitors join
    /// ([`wire::FRAGMENT`](crate::wire::FRAGMENT)).
    pub fn marking_publisher_sized(
        &self,
        fixed_len: usize,
    ) -> Result<MarkingPublisher, SetupError> {
        let fixed_len = fixed_len.clamp(MIN_FIXED_LEN, MARKING.max_body_len);
        let spec = ServiceSpec {
            initial_slice_len: fixed_len,
            ..MARKING
        };
        self.sender_with(
            self.vehicle.marking_service(),
            spec,
            AllocationStrategy::Static,
        )
    }

    /// A subscriber to marking deltas.
    pub fn marking_subscriber(&self) -> Result<MarkingSubscriber, SetupError> {
        self.receiver(self.vehicle.marking_service(), MARKING, None)
    }

    /// A sender of reload requests to the player (`petrel reload`).
    pub fn reload_requester(&self) -> Result<ReloadRequester, SetupError> {
        self.sender(self.vehicle.reload_service(), RELOAD)
    }

    /// The player's receiver of reload requests (one player receives).
    pub fn reload_receiver(&self) -> Result<ReloadReceiver, SetupError> {
        self.receiver(self.vehicle.reload_service(), RELOAD, None)
    }

    /// The player's publisher of reload answers.
    pub fn reload_answer_publisher(&self) -> Result<ReloadAnswerPublisher, SetupError> {
        self.sender(self.vehicle.reload_answer_service(), RELOAD_ANSWER)
    }

    /// A subscriber to the player's reload answers.
    pub fn reload_answer_subscriber(&self) -> Result<ReloadAnswerSubscriber, SetupError> {
        self.receiver(self.vehicle.reload_answer_service(), RELOAD_ANSWER, None)
    }

    /// A publisher of heartbeats. Its samples are one fixed segment of
    /// [`HEARTBEAT`]`.max_body_len` bytes: it never sends more, and a growing segment would cost
    /// about 2 KiB of this process's memory per sample for nothing.
    pub fn heartbeat_publisher(&self) -> Result<HeartbeatPublisher, SetupError> {
        let spec = ServiceSpec {
            initial_slice_len: HEARTBEAT.max_body_len,
            ..HEARTBEAT
        };
        self.sender_with(
            self.vehicle.heartbeat_service(),
            spec,
            AllocationStrategy::Static,
        )
    }

    /// Opens a heartbeat publisher that may send bodies of up to `max_body_len` bytes (at most
    /// [`MAX_BODY_LEN`](crate::wire::MAX_BODY_LEN)) rather than the service's default of 1,024:
    /// for the player, whose heartbeat carries its status and acknowledgements, sized from its
    /// project. The limit is the publisher's own: its samples are one fixed segment of that
    /// many bytes (the shared memory is only touched as far as each heartbeat goes, and the
    /// process keeps a few bytes per sample, not the 2 KiB a growing segment costs);
    /// receivers read any body up to [`MAX_BODY_LEN`](crate::wire::MAX_BODY_LEN).
    pub fn heartbeat_publisher_sized(
        &self,
        max_body_len: usize,
    ) -> Result<HeartbeatPublisher, SetupError> {
        let max_body_len = max_body_len.clamp(HEARTBEAT.max_body_len, crate::wire::MAX_BODY_LEN);
        let spec = ServiceSpec {
            max_body_len,
            initial_slice_len: max_body_len,
            ..HEARTBEAT
        };
        self.sender_with(
            self.vehicle.heartbeat_service(),
            spec,
            AllocationStrategy::Static,
        )
    }

    /// A subscriber to heartbeats (from the next heartbeat each sender sends).
    pub fn heartbeat_subscriber(&self) -> Result<HeartbeatSubscriber, SetupError> {
        self.receiver(self.vehicle.heartbeat_service(), HEARTBEAT, None)
    }

    fn service_name(&self, service: &str) -> Result<ServiceName, SetupError> {
        ServiceName::new(service).map_err(|_| {
            SetupError::Name(NameError::Refused {
                what: "service",
                name: service.to_owned(),
            })
        })
    }

    /// Opens the service, or creates it; a creator records `bound` (the longest body its
    /// project lets the senders send, [`BOUND_ATTRIBUTE`]) in the service's attributes. A
    /// service that exists is opened whatever it recorded.
    ///
    /// An existing service is opened whatever capacities (senders, processes) it was created
    /// with: the player makes the events service for its project's programs
    /// ([`event_receiver_sized`](Self::event_receiver_sized)), fewer senders than a program's
    /// default spec asks, and a program must still open it. A port beyond the capacity is
    /// refused when it is made, with its own error ([`SetupError::SendersFull`]).
    fn open_pubsub(
        &self,
        service: &str,
        spec: &ServiceSpec,
        bound: Option<usize>,
    ) -> Result<publish_subscribe::PortFactory<ipc::Service, [u8], MsgHeader>, SetupError> {
        let name = self.service_name(service)?;
        // What an opener requires of a service: the layout of its samples and its buffers.
        let opener = || {
            self.node
                .service_builder(&name)
                .publish_subscribe::<[u8]>()
                .user_header::<MsgHeader>()
                .enable_safe_overflow(spec.safe_overflow)
                .subscriber_max_buffer_size(spec.subscriber_buffer)
                .subscriber_max_borrowed_samples(2)
                .history_size(spec.history)
                .max_subscribers(spec.max_subscribers)
        };
        let recorded = bound.and_then(bound_specifier);
        retrying(
            || match opener().open() {
                Err(PublishSubscribeOpenError::DoesNotExist) => {
                    let creator = opener()
                        .max_publishers(spec.max_publishers)
                        .max_nodes(spec.max_nodes);
                    match &recorded {
                        Some(attributes) => creator.create_with_attributes(attributes),
                        None => creator.create(),
                    }
                    .map_err(PublishSubscribeOpenOrCreateError::PublishSubscribeCreateError)
                }
                other => {
                    other.map_err(PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError)
                }
            },
            pubsub_retry,
        )
        .map_err(|e| SetupError::Service {
            service: service.to_owned(),
            failure: ServiceFailure::PubSub(e),
        })
    }

    /// The event service paired with a publish-subscribe service, opened whatever capacities
    /// it was created with (see [`open_pubsub`](Self::open_pubsub)).
    fn open_event(
        &self,
        service: &str,
        spec: &ServiceSpec,
    ) -> Result<event::PortFactory<ipc::Service>, SetupError> {
        let name = self.service_name(service)?;
        let opener = || {
            self.node
                .service_builder(&name)
                .event()
                .max_listeners(spec.max_subscribers)
                .event_id_max_value(WAKE_MAX)
                .notifier_created_event(EventId::new(WAKE_SENDER_JOINED))
                .notifier_dropped_event(EventId::new(WAKE_SENDER_LEFT))
                .notifier_dead_event(EventId::new(WAKE_SENDER_DIED))
        };
        retrying(
            || match opener().open() {
                Err(EventOpenError::DoesNotExist) => opener()
                    .max_notifiers(spec.max_publishers)
                    .max_nodes(spec.max_nodes)
                    .create()
                    .map_err(EventOpenOrCreateError::EventCreateError),
                other => other.map_err(EventOpenOrCreateError::EventOpenError),
            },
            event_retry,
        )
        .map_err(|e| SetupError::Service {
            service: service.to_owned(),
            failure: ServiceFailure::Event(e),
        })
    }

    fn sender<M: Message>(
        &self,
        service: String,
        spec: ServiceSpec,
    ) -> Result<Sender<M>, SetupError> {
        self.sender_with(service, spec, AllocationStrategy::PowerOfTwo)
    }

    /// A sender whose samples start at `spec.initial_slice_len` bytes. With
    /// `AllocationStrategy::Static` they are one fixed segment of that length, and a longer
    /// body (up to `spec.max_body_len`) goes in pieces.
    fn sender_with<M: Message>(
        &self,
        service: String,
        spec: ServiceSpec,
        allocation: AllocationStrategy,
    ) -> Result<Sender<M>, SetupError> {
        let failed = |failure| SetupError::Service {
            service: service.clone(),
            failure,
        };
        let factory = self.open_pubsub(&service, &spec, None)?;
        let events = self.open_event(&service, &spec)?;
        let full = || SetupError::SendersFull {
            service: service.clone(),
            max: factory.static_config().max_publishers(),
        };
        let publisher = create_publisher(&factory, spec.initial_slice_len, allocation).map_err(
            |e| match e {
                PublisherCreateError::ExceedsMaxSupportedPublishers => full(),
                e => failed(ServiceFailure::Publisher(e)),
            },
        )?;
        let fixed_len =
            matches!(allocation, AllocationStrategy::Static).then_some(spec.initial_slice_len);
        // With a group: the publisher's memory and connections are the group's before the
        // notifier (created next) tells the receivers to connect.
        self.session.share_now();
        let notifier = events.notifier_builder().create().map_err(|e| match e {
            NotifierCreateError::ExceedsMaxSupportedNotifiers => full(),
            e => failed(ServiceFailure::Notifier(e)),
        })?;
        self.session.share_now();
        Ok(Sender::new(
            service.clone(),
            spec,
            self.origin,
            publisher,
            fixed_len,
            notifier,
            factory,
            self.session.clone(),
        ))
    }

    fn receiver<M: Message>(
        &self,
        service: String,
        spec: ServiceSpec,
        bound: Option<usize>,
    ) -> Result<Receiver<M>, SetupError> {
        let failed = |failure| SetupError::Service {
            service: service.clone(),
            failure,
        };
        let factory = self.open_pubsub(&service, &spec, bound)?;
        let events = self.open_event(&service, &spec)?;
        // The listener first: a sender that delivers between the two still wakes us.
        let listener = events
            .listener_builder()
            .create()
            .map_err(|e| failed(ServiceFailure::Listener(e)))?;
        // A connection iceoryx2 could not make is mended by the receiver (crate::mending).
        let mending = Mending::new();
        let subscriber = factory
            .subscriber_builder()
            .buffer_size(spec.subscriber_buffer)
            .set_degradation_handler(mending.handler())
            .create()
            .map_err(|e| failed(ServiceFailure::Subscriber(e)))?;
        self.session.share_now();
        Ok(Receiver::new(
            service.clone(),
            spec,
            subscriber,
            listener,
            factory,
            mending,
            self.session.clone(),
        ))
    }
}

/// A program's calls service seen without a port ([`Participant::calls_view`]).
#[derive(Debug)]
pub struct CallsView {
    factory: publish_subscribe::PortFactory<ipc::Service, [u8], MsgHeader>,
}

impl CallsView {
    /// The iceoryx2 ids of the nodes ([`NodeInfo::id`](crate::NodeInfo::id)) whose receivers
    /// are connected to the program's calls now: a call sent now reaches them. A receiver of a
    /// dead node stays listed until the node is cleaned up.
    pub fn receiver_nodes(&self) -> Vec<u128> {
        let mut nodes = Vec::new();
        self.factory.dynamic_config().list_subscribers(|s| {
            nodes.push(s.node_id.value());
            CallbackProgression::Continue
        });
        nodes
    }
}

/// Senders the player's events service takes beyond one per program of its project
/// ([`Participant::event_receiver_sized`]): the CAN data servers, operator tools (`petrel
/// emit`, monitors), a restarted program while iceoryx2 has not yet removed its dead
/// predecessor, programs a hot reload adds.
///
/// Why size it at all: iceoryx2 0.10's receiver walks every sender slot of its service to find
/// or miss a sample, twice per event the player handles and at every turn of a spinning wait;
/// 128 slots (the default, [`EVENTS`]) cost the player ~4,000 instructions an event,
/// a round trip's tenth (docs/benchmarks.md, "Issue 17: the events service sized").
pub const EVENT_SENDERS_SPARE: usize = 16;

/// The senders the player's events service takes for a project of `programs` programs:
/// one each plus [`EVENT_SENDERS_SPARE`].
pub fn event_senders(programs: usize) -> usize {
    programs.saturating_add(EVENT_SENDERS_SPARE)
}

/// The connections of senders gone with samples not yet read that a program's receivers keep
/// ([`Participant::join`]): a program receives calls from 4 senders at most ([`CALLS`]), and
/// a heartbeat or a signal lost with its sender is replaced by the next.
pub const PROGRAM_SENDERS_GONE: usize = 16;

/// The shortest fixed sample a sized sender takes: a body of 64 KiB goes in 128 pieces at most
/// (a sixteenth of the player's buffer for one sender), and a fixed segment of 512-byte samples
/// costs the process no more memory than a shorter one until they are written.
pub const MIN_FIXED_LEN: usize = 512;

/// The key of the attribute in which the process that creates a service records the longest
/// body its project lets the senders send (the events service: the player's
/// [`Participant::event_receiver_sized`]), in decimal bytes.
pub const BOUND_ATTRIBUTE: &str = "petrel.max_body_len";

fn bound_key() -> Option<AttributeKey> {
    AttributeKey::new(BOUND_ATTRIBUTE.as_bytes()).ok()
}

fn bound_specifier(bound: usize) -> Option<AttributeSpecifier> {
    let value = AttributeValue::new(bound.to_string().as_bytes()).ok()?;
    AttributeSpecifier::new().define(&bound_key()?, &value).ok()
}

/// The bound a service's creator recorded, if any (a value that does not read as a length is
/// no bound: the senders keep the defaults).
fn bound_of(
    factory: &publish_subscribe::PortFactory<ipc::Service, [u8], MsgHeader>,
) -> Option<usize> {
    let value = factory.attributes().key_value(&bound_key()?, 0)?;
    std::str::from_utf8(value.as_bytes())
        .ok()?
        .parse()
        .ok()
        .filter(|&b| b > 0)
}

/// A publisher on `factory` whose samples start at `slice_len` bytes and grow as `allocation`
/// says; full receivers' buffers refuse (never overwrite) unless the service overflows safely.
pub(crate) fn create_publisher(
    factory: &publish_subscribe::PortFactory<ipc::Service, [u8], MsgHeader>,
    slice_len: usize,
    allocation: AllocationStrategy,
) -> Result<Publisher<ipc::Service, [u8], MsgHeader>, PublisherCreateError> {
    factory
        .publisher_builder()
        .initial_max_slice_len(slice_len)
        .allocation_strategy(allocation)
        .backpressure_strategy(BackpressureStrategy::DiscardData)
        .max_loaned_samples(2)
        .create()
}
