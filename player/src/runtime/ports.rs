//! The player's ports on the vehicle's services, and the built-in events it raises itself.

use petrel_ipc::{
    CallSender, EventReceiver, HeartbeatPublisher, MarkingPublisher, Participant,
    ReloadAnswerPublisher, ReloadReceiver,
};
use petrel_nets::compiled::{CompiledProject, EventId};

/// The ports of the player on the vehicle's services.
pub(super) struct Ports {
    pub(super) events: EventReceiver,
    pub(super) calls: Vec<CallSender>,
    pub(super) marking: MarkingPublisher,
    pub(super) heartbeat: HeartbeatPublisher,
    pub(super) reload: ReloadReceiver,
    pub(super) reload_answers: ReloadAnswerPublisher,
    /// The node: dropped last, after its ports.
    pub(super) _me: Participant,
}

/// The built-in events the player raises itself.
pub(super) struct Builtins {
    pub(super) program_lost: Option<EventId>,
    pub(super) call_failed: Option<EventId>,
    pub(super) bad_message: Option<EventId>,
    pub(super) recorder_failed: Option<EventId>,
    pub(super) recorder_restored: Option<EventId>,
}

impl Builtins {
    /// The built-in events of `project`.
    pub(super) fn of(project: &CompiledProject) -> Self {
        Builtins {
            program_lost: project.event_id("program_lost"),
            call_failed: project.event_id("call_failed"),
            bad_message: project.event_id("bad_message"),
            recorder_failed: project.event_id("recorder_failed"),
            recorder_restored: project.event_id("recorder_restored"),
        }
    }
}
