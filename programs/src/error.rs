//! What can go wrong in a program.

use std::fmt;

use petrel_ipc::{
    LivenessError, NameError, ReactorError, RecvError, SendError, SetupError, WireError,
};

use crate::call::ArgError;

/// An error of the programs SDK.
///
/// Most errors are reports, not ends: a program logs them and carries on. Only those for which
/// [`is_fatal`](Self::is_fatal) is true (the connection could not be set up, waiting failed) or
/// [`Terminated`](Self::Terminated) (SIGINT or SIGTERM) should stop its loop.
#[derive(Debug)]
pub enum ProgramError {
    /// A vehicle or program name was refused.
    Name(NameError),
    /// [`Program::connect_many`](crate::Program::connect_many) was given no program name.
    NoProgram,
    /// A program name was given twice.
    DuplicateProgram(String),
    /// Joining the vehicle or opening a port failed.
    Setup {
        /// The program being connected.
        program: String,
        /// Why.
        error: Box<SetupError>,
    },
    /// Waiting for calls failed.
    Reactor(ReactorError),
    /// The handling of SIGINT and SIGTERM could not be set up.
    Signals(std::io::Error),
    /// The vehicle's processes could not be listed (to tell whether the player lives). The
    /// event being emitted, if any, was queued.
    Liveness(LivenessError),
    /// A call could not be received or decoded; it is skipped and the next one is received
    /// normally.
    BadCall {
        /// The program it was addressed to.
        program: String,
        /// Why.
        error: Box<RecvError>,
    },
    /// An argument of a call is missing or of the wrong type.
    Arg(ArgError),
    /// A call names a function the program does not have.
    UnknownFunction {
        /// The program called.
        program: String,
        /// The function named.
        function: String,
    },
    /// [`Program::emit_as`](crate::Program::emit_as) named a program this process does not host.
    UnknownProgram {
        /// The name given.
        program: String,
        /// The programs hosted.
        hosted: Vec<String>,
    },
    /// An event can never be sent (it does not encode, or it is larger than the events service
    /// carries). It was not queued.
    Unsendable {
        /// The event's name.
        event: String,
        /// Why.
        error: WireError,
    },
    /// Sending an event failed in a way that retrying cannot mend. It was not queued.
    Send {
        /// The event's name.
        event: String,
        /// Why.
        error: Box<SendError>,
    },
    /// The outbox of events waiting for a player was full: the oldest were dropped to make room
    /// for the newest (which is queued). They are lost;
    /// [`ProgramStats::dropped`](crate::ProgramStats::dropped) counts every one.
    EventsDropped {
        /// Names of the events dropped this time, oldest first.
        events: Vec<String>,
        /// Events dropped since the program connected.
        total: u64,
        /// The outbox's capacity.
        capacity: usize,
    },
    /// A call to another program ([`Program::call`](crate::Program::call)) did not reach it:
    /// no process plays that program now, its buffer was full, or the call could not be
    /// sent. Calls are not queued: a command given late may be worse than none.
    CallUndelivered {
        /// The program called.
        program: String,
        /// The function called.
        function: String,
        /// Why.
        error: Box<SendError>,
    },
    /// The decoded CAN signals could not be read (see
    /// [`Program::signals`](crate::Program::signals)).
    BadSignals(Box<RecvError>),
    /// SIGINT or SIGTERM was received: the program should stop. Every later
    /// [`recv`](crate::Program::recv) returns this too.
    Terminated,
}

impl ProgramError {
    /// True when the program cannot go on: its connection could not be set up or waiting
    /// failed. Termination requests are not fatal errors but also end the loop: see
    /// [`is_termination`](Self::is_termination).
    pub fn is_fatal(&self) -> bool {
        matches!(
            self,
            ProgramError::Name(_)
                | ProgramError::NoProgram
                | ProgramError::DuplicateProgram(_)
                | ProgramError::Setup { .. }
                | ProgramError::Reactor(_)
                | ProgramError::Signals(_)
        )
    }

    /// True for [`ProgramError::Terminated`].
    pub fn is_termination(&self) -> bool {
        matches!(self, ProgramError::Terminated)
    }
}

impl fmt::Display for ProgramError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ProgramError::Name(e) => e.fmt(f),
            ProgramError::NoProgram => {
                f.write_str("no program name given; connect as at least one program")
            }
            ProgramError::DuplicateProgram(name) => write!(
                f,
                "program `{name}` is given twice; a process hosts each program once"
            ),
            ProgramError::Setup { program, error } => {
                write!(f, "cannot connect program `{program}`: {error}")
            }
            ProgramError::Reactor(e) => write!(f, "cannot wait for calls: {e}"),
            ProgramError::Signals(e) => write!(
                f,
                "cannot set up the handling of SIGINT and SIGTERM: {e}; turn it off with \
                 ProgramConfig::handle_signals = false"
            ),
            ProgramError::Liveness(e) => write!(
                f,
                "cannot tell whether the player runs: {e}; events are kept until it can be told"
            ),
            ProgramError::BadCall { program, error } => {
                write!(f, "a call to {program} was refused and skipped: {error}")
            }
            ProgramError::Arg(e) => e.fmt(f),
            ProgramError::UnknownFunction { program, function } => write!(
                f,
                "{program} has no function `{function}`; the call is ignored (is the manifest's \
                 [programs.{program}.functions] in step with the program?)"
            ),
            ProgramError::UnknownProgram { program, hosted } => write!(
                f,
                "this process does not host program `{program}` (it hosts {}); emit as one of them",
                hosted.join(", ")
            ),
            ProgramError::Unsendable { event, error } => {
                write!(f, "event `{event}` cannot be sent: {error}")
            }
            ProgramError::Send { event, error } => {
                write!(f, "event `{event}` could not be sent: {error}")
            }
            ProgramError::CallUndelivered {
                program,
                function,
                error,
            } => write!(f, "call {program}.{function} not delivered: {error}"),
            ProgramError::BadSignals(e) => write!(f, "the CAN signals could not be read: {e}"),
            ProgramError::EventsDropped {
                events,
                total,
                capacity,
            } => write!(
                f,
                "no player has received events for a while and the outbox holds {capacity}: \
                 the oldest, {}, {} dropped ({total} dropped since the start); is the player \
                 running?",
                events.join(", "),
                if events.len() == 1 { "was" } else { "were" }
            ),
            ProgramError::Terminated => f.write_str("termination requested (SIGINT or SIGTERM)"),
        }
    }
}

impl std::error::Error for ProgramError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            ProgramError::Name(e) => Some(e),
            ProgramError::Setup { error, .. } => Some(error.as_ref()),
            ProgramError::Reactor(e) => Some(e),
            ProgramError::Signals(e) => Some(e),
            ProgramError::Liveness(e) => Some(e),
            ProgramError::BadCall { error, .. } => Some(error.as_ref()),
            ProgramError::Arg(e) => Some(e),
            ProgramError::Unsendable { error, .. } => Some(error),
            ProgramError::Send { error, .. } => Some(error.as_ref()),
            ProgramError::CallUndelivered { error, .. } => Some(error.as_ref()),
            ProgramError::BadSignals(e) => Some(e.as_ref()),
            _ => None,
        }
    }
}

impl From<ArgError> for ProgramError {
    fn from(e: ArgError) -> Self {
        ProgramError::Arg(e)
    }
}

impl From<NameError> for ProgramError {
    fn from(e: NameError) -> Self {
        ProgramError::Name(e)
    }
}

impl From<ReactorError> for ProgramError {
    fn from(e: ReactorError) -> Self {
        ProgramError::Reactor(e)
    }
}

impl From<LivenessError> for ProgramError {
    fn from(e: LivenessError) -> Self {
        ProgramError::Liveness(e)
    }
}
