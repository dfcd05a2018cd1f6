//! `can.toml`, the project's CAN configuration: its checked form ([`CanConfig`] and the types
//! under it), reading and checking it (`check`: [`check_rules`]) and finding it with its DBC in
//! a project directory (`load`: [`load_project_can`]).
//!
//! Below the rule engine ([`crate::rules`]) and the bus faults ([`crate::faults`]), which run
//! what it describes: it imports neither.
//!
//! ```toml
//! dbc = "auv.dbc"                 # the DBC, relative to the project directory
//!
//! [bus]
//! interface = "can0"              # default interface (the command line may override it)
//! fd = false                      # open it for CAN FD frames
//! state_event = "bus_fault"       # bus_fault(state: text) on every change of bus state
//! restart_after_bus_off = true    # ask the interface to restart after a bus-off
//! [bus.on_state]                  # events without parameters, one per state entered
//! bus_off = "bus_lost"
//!
//! [heartbeat]                     # the supervisor heartbeat the thrusters expect
//! message = "SupervisorHeartbeat"
//! period = "100ms"                # default: the message's GenMsgCycleTime
//! counter = "alive"               # incremented at each frame, wrapping within its range
//! signals = { mode = "mission" }  # the other signals: numbers or value-table names
//!
//! [commands]
//! messages = ["ThrusterCmd"]      # what programs may have the bridge send
//! program = "CAN"                 # receive them as calls CAN.ThrusterCmd(rpm_left, ...)
//!
//! [[rule]]
//! event = "depth_reached"         # a declared event of the project
//! kind = "band"                   # threshold | band | debounce | edge | stale
//! signal = "Depth.depth"          # MESSAGE.signal of the DBC
//! target = "DepthCmd.target"      # a number, or a signal
//! within = 0.5
//! hysteresis = 0.2
//! params = ["Depth.depth"]        # signals, literals, or { text = "..." }
//! ```
//!
//! Fields of a rule:
//!
//! | field | kinds | meaning |
//! |---|---|---|
//! | `event` | all | the event sent (declared in `petrel.toml`) |
//! | `name` | all | the rule's name in logs (default: the event) |
//! | `signal` | all but `stale` (there: or `message`) | `MESSAGE.signal` |
//! | `above`, `below` | threshold, debounce, edge | the condition `signal >= above` / `signal <= below` |
//! | `target`, `within` | band, debounce, edge | the condition `abs(signal - target) <= within` |
//! | `equals` | debounce, edge | the condition `raw == equals` (a number or a value-table name) |
//! | `hysteresis` | with above, below, band | how far back the value must go to end the condition |
//! | `for` | all but stale (required by debounce) | how long a change must last: `200ms`, `2s` |
//! | `edge` | all but stale | `rising` (default), `falling` or `both` |
//! | `message` | stale | the message watched |
//! | `timeout` | stale | the silence that fires: a duration, or else |
//! | `periods`, `period` | stale | `periods` (default 3) times `period` (default: GenMsgCycleTime) |
//! | `params` | all | the event's parameters in order |
//!
//! A parameter is `"MESSAGE.signal"` (its latest value, converted to the declared type), a
//! number or `true`/`false` (a literal), or `{ text = "..." }` (a text literal).
//!
//! Codes: E0701 not valid TOML or an unknown key; E0702 the DBC cannot be read or is invalid;
//! E0703 unknown message or signal; E0704 unknown event; E0705 wrong number of parameters;
//! E0706 a parameter of the wrong type; E0707 a duration that does not read; E0708 a field that
//! does not fit the rule's kind or has an invalid value; E0709 no period known; E0710 a
//! value-table name the signal does not have; W0701 a threshold the signal can never reach.

mod check;
mod load;

pub use check::check_rules;
pub use load::{load_project_can, CAN_TOML};

use petrel_nets::compiled::Value;
use petrel_nets::model::Type;

use crate::bus_state::BusState;
use crate::dbc::{MessageId, SignalRef};

/// Which changes of a condition fire the event.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Edge {
    /// The condition becomes true.
    Rising,
    /// The condition becomes false.
    Falling,
    /// Either.
    Both,
}

/// The target of a band: a fixed value or the latest value of another signal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Target {
    /// A fixed value.
    Value(f64),
    /// The latest value of a signal (received, or sent by the bridge itself).
    Signal(SignalRef),
}

/// A condition on one signal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Condition {
    /// True from `value >= threshold`; false again below `threshold - hysteresis`.
    Above {
        /// The signal.
        signal: SignalRef,
        /// The threshold (physical).
        threshold: f64,
        /// The hysteresis, at least 0.
        hysteresis: f64,
    },
    /// True from `value <= threshold`; false again above `threshold + hysteresis`.
    Below {
        /// The signal.
        signal: SignalRef,
        /// The threshold (physical).
        threshold: f64,
        /// The hysteresis, at least 0.
        hysteresis: f64,
    },
    /// True from `|value - target| <= within`; false again beyond `within + hysteresis`.
    Band {
        /// The signal.
        signal: SignalRef,
        /// The target.
        target: Target,
        /// Half-width of the band, above 0.
        within: f64,
        /// The hysteresis, at least 0.
        hysteresis: f64,
    },
    /// True when the raw value equals `raw` (a bit, a value-table entry).
    Equals {
        /// The signal.
        signal: SignalRef,
        /// The raw value.
        raw: i64,
    },
}

impl Condition {
    /// The signal the condition watches.
    pub fn signal(&self) -> SignalRef {
        match *self {
            Condition::Above { signal, .. }
            | Condition::Below { signal, .. }
            | Condition::Band { signal, .. }
            | Condition::Equals { signal, .. } => signal,
        }
    }

    /// The target signal of a band, if it has one.
    pub fn target_signal(&self) -> Option<SignalRef> {
        match *self {
            Condition::Band {
                target: Target::Signal(s),
                ..
            } => Some(s),
            _ => None,
        }
    }
}

/// What a rule watches.
#[derive(Clone, Debug, PartialEq)]
pub enum RuleKind {
    /// A condition on a signal (kinds `threshold`, `band`, `debounce`, `edge`).
    Condition {
        /// The condition.
        condition: Condition,
        /// Which changes fire.
        edge: Edge,
        /// How long a change must last to count, in microseconds (0: at once).
        hold_us: u64,
    },
    /// A message that stops arriving (kind `stale`).
    Stale {
        /// The message.
        message: MessageId,
        /// Silence after which the event fires, in microseconds.
        timeout_us: u64,
    },
}

/// Where an event parameter comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum ParamSource {
    /// The latest value of a signal, as the declared type: `float` the physical value, `int`
    /// the physical value of an integral signal, `bool` whether it is not zero, `text` its
    /// value-table name (or the number when the value has no name).
    ///
    /// A signal never received gives NaN, 0, false or the empty text.
    Signal {
        /// The signal.
        signal: SignalRef,
        /// The declared type of the parameter.
        ty: Type,
    },
    /// A literal written in the rule.
    Literal(Value),
}

/// A checked rule.
#[derive(Clone, Debug, PartialEq)]
pub struct Rule {
    /// The rule's name (its `name`, else its event's).
    pub name: String,
    /// The event it sends, by name.
    pub event: String,
    /// What it watches.
    pub kind: RuleKind,
    /// The event's parameters, in declaration order.
    pub params: Vec<ParamSource>,
}

/// Events for changes of the bus state (`[bus]` of `can.toml`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BusEvents {
    /// An event with one `text` parameter, sent on every change of state with the state's
    /// name (`error_active`, `error_warning`, `error_passive`, `bus_off`, `stopped`,
    /// `sleeping`).
    pub state_event: Option<String>,
    /// Events without parameters, one per state entered.
    pub on_state: Vec<(BusState, String)>,
    /// Ask the interface to restart after a bus-off (SocketCAN; needs the privilege, and
    /// is refused by interfaces that restart by themselves).
    pub restart_after_bus_off: bool,
}

/// The supervisor heartbeat the thrusters expect (`[heartbeat]`).
#[derive(Clone, Debug, PartialEq)]
pub struct HeartbeatSpec {
    /// The message sent.
    pub message: MessageId,
    /// Its period, in microseconds.
    pub period_us: u64,
    /// A signal of the message incremented at each frame, wrapping within its range.
    pub counter: Option<usize>,
    /// Physical values of the other signals, by index in the message.
    pub values: Vec<(usize, f64)>,
}

/// What programs may command (`[commands]`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CommandSpec {
    /// Messages programs may have the bridge send.
    pub messages: Vec<MessageId>,
    /// The program name under which the bridge receives commands as calls (a function per
    /// message, the signals as arguments in DBC order), if any.
    pub program: Option<String>,
}

/// A checked `can.toml`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CanConfig {
    /// The DBC file, as written (relative to the project directory).
    pub dbc_path: Option<String>,
    /// The interface to open when none is given on the command line.
    pub interface: Option<String>,
    /// Open the interface for CAN FD frames.
    pub fd: bool,
    /// `[bus] receive = "dbc"`: the socket's identifier filters pass only the DBC's messages
    /// (and error frames), so that a busy bus costs the bridge only what it decodes.
    pub receive_only_dbc: bool,
    /// The rules, in written order (the order their simultaneous events come out).
    pub rules: Vec<Rule>,
    /// Bus fault events.
    pub bus: BusEvents,
    /// The heartbeat, if any.
    pub heartbeat: Option<HeartbeatSpec>,
    /// Commands.
    pub commands: CommandSpec,
}
