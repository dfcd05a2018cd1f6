//! Names and isolation: which iceoryx2 services and nodes belong to one vehicle.
//!
//! A [`Vehicle`] names every service of one vehicle, and its prefix keeps its files apart from
//! every other vehicle's (and every other test run's) on the same machine: the prefix names
//! the vehicle's own directory and session (see [`access`](crate::access), which also says who
//! may use them). A [`Role`] names the node a process creates, so that liveness questions ("is
//! program PLN alive?") can be answered from the node list.

use std::fmt;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{SystemTime, UNIX_EPOCH};

use iceoryx2::config::Config;
use iceoryx2::prelude::{FileName, SemanticString};

use crate::access::{AccessError, Group, Session};

/// Longest vehicle name accepted.
pub const MAX_VEHICLE_NAME_LEN: usize = 32;
/// Longest program or tool name accepted (the node name `program/NAME` must fit in the
/// 32-byte origin field of every message header).
pub const MAX_PROGRAM_NAME_LEN: usize = petrel_value::MAX_PROGRAM_NAME_LEN;
/// Longest file prefix accepted.
pub const MAX_PREFIX_LEN: usize = 64;

/// A name given to this crate was refused.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum NameError {
    /// The name is empty.
    Empty {
        /// What the name was for ("vehicle", "program", "prefix", ...).
        what: &'static str,
    },
    /// The name is longer than allowed.
    TooLong {
        /// What the name was for.
        what: &'static str,
        /// The name as given.
        name: String,
        /// The longest length accepted.
        max: usize,
    },
    /// The name holds a character outside `A-Z a-z 0-9 _ -` (and `.` for prefixes).
    InvalidCharacter {
        /// What the name was for.
        what: &'static str,
        /// The name as given.
        name: String,
        /// The first refused character.
        character: char,
    },
    /// iceoryx2 refused the name (as a file prefix, node name or service name).
    Refused {
        /// What the name was for.
        what: &'static str,
        /// The name as given.
        name: String,
    },
}

impl fmt::Display for NameError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            NameError::Empty { what } => write!(f, "the {what} name is empty; give it a name"),
            NameError::TooLong { what, name, max } => write!(
                f,
                "the {what} name `{name}` is {} characters long; use at most {max}",
                name.chars().count()
            ),
            NameError::InvalidCharacter {
                what,
                name,
                character,
            } => write!(
                f,
                "the {what} name `{name}` contains {character:?}; use only letters, digits, `_` and `-`"
            ),
            NameError::Refused { what, name } => write!(
                f,
                "iceoryx2 refuses `{name}` as a {what} name; use letters, digits, `_`, `-` and `.`, and fewer characters"
            ),
        }
    }
}

impl std::error::Error for NameError {}

fn check_name(what: &'static str, name: &str, max: usize, extra: &[char]) -> Result<(), NameError> {
    if name.is_empty() {
        return Err(NameError::Empty { what });
    }
    if let Some(character) = name
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || *c == '_' || *c == '-' || extra.contains(c)))
    {
        return Err(NameError::InvalidCharacter {
            what,
            name: name.to_owned(),
            character,
        });
    }
    if name.len() > max {
        return Err(NameError::TooLong {
            what,
            name: name.to_owned(),
            max,
        });
    }
    Ok(())
}

/// Checks a program name (`PLN`, `GUI`, `can_bridge`...): 1 to 24 characters among
/// `A-Z a-z 0-9 _ -`.
pub fn check_program_name(name: &str) -> Result<(), NameError> {
    // The rule is the one every crate holds program names to; the details say what is wrong.
    if petrel_value::is_program_name(name) {
        return Ok(());
    }
    check_name("program", name, MAX_PROGRAM_NAME_LEN, &[])?;
    Err(NameError::Refused {
        what: "program",
        name: name.to_owned(),
    })
}

/// One vehicle: its name, the file prefix that isolates it, and every service name it uses.
///
/// Every process of one vehicle must build its `Vehicle` with the same name and prefix; two
/// vehicles (or two test runs) with different prefixes never see each other's services or nodes,
/// even when their names are equal.
///
/// Building one does nothing on disk. The first use (joining, listing nodes) opens the
/// vehicle's session ([`access`](crate::access)): its directory, its shared-memory prefix, and
/// a lock saying this process is in; clones share it, and the last handle of the last process
/// of the vehicle to go removes the vehicle's files.
#[derive(Debug, Clone)]
pub struct Vehicle {
    name: String,
    prefix: String,
    config: Config,
    group: Option<Group>,
    session: Arc<Mutex<Option<Arc<Session>>>>,
}

static ISOLATED_COUNTER: AtomicU32 = AtomicU32::new(0);

impl Vehicle {
    /// The vehicle `name` with the default prefix `petrel_<name>_`.
    pub fn new(name: &str) -> Result<Self, NameError> {
        Self::with_prefix(name, &format!("petrel_{name}_"))
    }

    /// The vehicle `name` with an explicit file prefix.
    pub fn with_prefix(name: &str, prefix: &str) -> Result<Self, NameError> {
        Self::with_config(name, prefix, Config::default())
    }

    /// The vehicle `name` with an explicit prefix, starting from an iceoryx2 configuration (for
    /// instance one read with `Config::from_file`); its `global.prefix` is replaced by `prefix`,
    /// and its root path and prefix by the session's when the vehicle is used.
    pub fn with_config(name: &str, prefix: &str, mut config: Config) -> Result<Self, NameError> {
        check_name("vehicle", name, MAX_VEHICLE_NAME_LEN, &[])?;
        check_name("prefix", prefix, MAX_PREFIX_LEN, &['.'])?;
        config.global.prefix =
            FileName::new(prefix.as_bytes()).map_err(|_| NameError::Refused {
                what: "prefix",
                name: prefix.to_owned(),
            })?;
        Ok(Vehicle {
            name: name.to_owned(),
            prefix: prefix.to_owned(),
            config,
            group: None,
            session: Arc::new(Mutex::new(None)),
        })
    }

    /// The same vehicle, its files shared with `group` (for operator accounts): see
    /// [`access`](crate::access). Without it, a process takes the group of `PETREL_GROUP`, or
    /// the one the vehicle's directory already has. Give it before the vehicle is first used.
    pub fn with_group(mut self, group: Group) -> Self {
        self.group = Some(group);
        self
    }

    /// The group given with [`with_group`](Self::with_group).
    pub fn group(&self) -> Option<&Group> {
        self.group.as_ref()
    }

    /// This process's membership of the vehicle, opened on first use.
    pub(crate) fn session(&self) -> Result<Arc<Session>, AccessError> {
        let mut slot = self.session.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(s) = slot.as_ref() {
            return Ok(s.clone());
        }
        let session = Arc::new(Session::open(self)?);
        *slot = Some(session.clone());
        Ok(session)
    }

    /// The iceoryx2 configuration every node of this vehicle uses: [`config`](Self::config)
    /// with the vehicle's directory as its root path and the session's prefix. Opens the
    /// session.
    pub fn effective_config(&self) -> Result<Config, AccessError> {
        Ok(self.session()?.config().clone())
    }

    /// The vehicle's directory (iceoryx2's root path). Opens the session.
    pub fn runtime_dir(&self) -> Result<PathBuf, AccessError> {
        Ok(self.session()?.dir().to_path_buf())
    }

    /// The prefix of the session's files in `/dev/shm` (`pt<12 hex>_`). Opens the session.
    pub fn shm_prefix(&self) -> Result<String, AccessError> {
        Ok(self.session()?.shm_prefix().to_owned())
    }

    /// The group the vehicle's files are shared with, as the session found or made it. Opens
    /// the session.
    pub fn shared_gid(&self) -> Result<Option<u32>, AccessError> {
        Ok(self.session()?.group())
    }

    /// A vehicle with a prefix unique to this call (process id, a per-process counter and the
    /// clock), for tests: two tests, or two runs of one test, never meet. Child processes of a
    /// test must be given the same name and [`prefix`](Self::prefix) and use
    /// [`with_prefix`](Self::with_prefix).
    pub fn isolated(name: &str) -> Result<Self, NameError> {
        let n = ISOLATED_COUNTER.fetch_add(1, Ordering::Relaxed);
        let nanos = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map(|d| d.subsec_nanos())
            .unwrap_or(0);
        let prefix = format!("pt{}_{n}_{nanos:x}_", std::process::id());
        Self::with_prefix(name, &prefix)
    }

    /// The vehicle's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The file prefix that isolates this vehicle.
    pub fn prefix(&self) -> &str {
        &self.prefix
    }

    /// The iceoryx2 configuration the vehicle was built with, before its session gives it its
    /// directory and prefix ([`effective_config`](Self::effective_config)).
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// Events into the player (publish-subscribe), `petrel/<vehicle>/events`. The paired event
    /// service that wakes the player has the same name.
    pub fn events_service(&self) -> String {
        format!("petrel/{}/events", self.name)
    }

    /// Calls from the player to one program, `petrel/<vehicle>/calls/<PROGRAM>`, and the paired
    /// event service of the same name.
    pub fn calls_service(&self, program: &str) -> Result<String, NameError> {
        check_program_name(program)?;
        Ok(format!("petrel/{}/calls/{program}", self.name))
    }

    /// Marking deltas out of the player, `petrel/<vehicle>/marking`, and the paired event
    /// service of the same name.
    pub fn marking_service(&self) -> String {
        format!("petrel/{}/marking", self.name)
    }

    /// CAN signals, `petrel/<vehicle>/signals`, and the paired event service of the same name.
    pub fn signals_service(&self) -> String {
        format!("petrel/{}/signals", self.name)
    }

    /// Reload requests into the player, `petrel/<vehicle>/reload`, and the paired event
    /// service of the same name.
    pub fn reload_service(&self) -> String {
        format!("petrel/{}/reload", self.name)
    }

    /// The player's reload answers, `petrel/<vehicle>/reload/answer`, and the paired event
    /// service of the same name.
    pub fn reload_answer_service(&self) -> String {
        format!("petrel/{}/reload/answer", self.name)
    }

    /// Heartbeats, `petrel/<vehicle>/heartbeat`, and the paired event service of the same name.
    pub fn heartbeat_service(&self) -> String {
        format!("petrel/{}/heartbeat", self.name)
    }
}

/// What a process is to the vehicle. It names the process's iceoryx2 node, and so answers
/// liveness questions, and it is the origin written in every message the process sends.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum Role {
    /// The player (node `player`).
    Player,
    /// A software program (node `program/<NAME>`).
    Program(String),
    /// The CAN data server (node `can_bridge`).
    CanBridge,
    /// Anything else: operator tool, monitor, test driver (node `tool/<NAME>`).
    Tool(String),
}

impl Role {
    /// A program role, checked.
    pub fn program(name: &str) -> Result<Self, NameError> {
        check_program_name(name)?;
        Ok(Role::Program(name.to_owned()))
    }

    /// A tool role, checked.
    pub fn tool(name: &str) -> Result<Self, NameError> {
        check_name("tool", name, MAX_PROGRAM_NAME_LEN, &[])?;
        Ok(Role::Tool(name.to_owned()))
    }

    /// The role of the `petrel gateway` of computer `computer` (node `tool/gw-<COMPUTER>`).
    pub fn gateway(computer: &str) -> Result<Self, NameError> {
        Role::tool(&format!("gw-{computer}"))
    }

    /// Whether `node` (a node name, or a message's origin) is a `petrel gateway`'s: it stands in
    /// for the senders and callers of other computers, and gives the verdict on the events it
    /// could not carry to the player (docs/gateway.md).
    pub fn is_gateway_node(node: &str) -> bool {
        node.starts_with("tool/gw-")
    }

    /// Checks the names a role holds.
    pub fn check(&self) -> Result<(), NameError> {
        match self {
            Role::Player | Role::CanBridge => Ok(()),
            Role::Program(name) => check_program_name(name),
            Role::Tool(name) => check_name("tool", name, MAX_PROGRAM_NAME_LEN, &[]),
        }
    }

    /// The iceoryx2 node name of this role: `player`, `program/<NAME>`, `can_bridge` or
    /// `tool/<NAME>`.
    pub fn node_name(&self) -> String {
        match self {
            Role::Player => "player".to_owned(),
            Role::Program(name) => program_node_name(name),
            Role::CanBridge => "can_bridge".to_owned(),
            Role::Tool(name) => format!("tool/{name}"),
        }
    }
}

impl fmt::Display for Role {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.node_name())
    }
}

/// The node name of program `name`.
pub fn program_node_name(name: &str) -> String {
    format!("program/{name}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn service_names() {
        let v = Vehicle::new("redermor").unwrap();
        assert_eq!(v.prefix(), "petrel_redermor_");
        assert_eq!(v.events_service(), "petrel/redermor/events");
        assert_eq!(v.calls_service("PLN").unwrap(), "petrel/redermor/calls/PLN");
        assert_eq!(v.marking_service(), "petrel/redermor/marking");
        assert_eq!(v.heartbeat_service(), "petrel/redermor/heartbeat");
        assert_eq!(v.config().global.prefix.to_string(), "petrel_redermor_");
    }

    #[test]
    fn bad_names_are_refused() {
        assert!(matches!(
            Vehicle::new(""),
            Err(NameError::Empty { what: "vehicle" })
        ));
        assert!(matches!(
            Vehicle::new("a/b"),
            Err(NameError::InvalidCharacter { character: '/', .. })
        ));
        assert!(matches!(
            Vehicle::new(&"x".repeat(33)),
            Err(NameError::TooLong { max: 32, .. })
        ));
        assert!(Role::program("P N").is_err());
        assert!(Role::program(&"P".repeat(25)).is_err());
        assert!(Vehicle::new("auv").unwrap().calls_service("../x").is_err());
        let e = Vehicle::with_prefix("auv", "a b").unwrap_err();
        assert!(e.to_string().contains("contains ' '"), "{e}");
    }

    #[test]
    fn isolated_prefixes_are_unique() {
        let a = Vehicle::isolated("auv").unwrap();
        let b = Vehicle::isolated("auv").unwrap();
        assert_ne!(a.prefix(), b.prefix());
        assert_eq!(a.events_service(), b.events_service());
    }

    #[test]
    fn node_names() {
        assert_eq!(Role::Player.node_name(), "player");
        assert_eq!(Role::program("PLN").unwrap().node_name(), "program/PLN");
        assert_eq!(Role::CanBridge.node_name(), "can_bridge");
        assert_eq!(Role::tool("op").unwrap().node_name(), "tool/op");
    }
}
