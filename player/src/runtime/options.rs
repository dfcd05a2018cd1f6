//! How the player runs ([`PlayOptions`]), why it could not ([`PlayError`]), and what a run did
//! ([`PlayReport`]).

use crate::engine::Stats;
use crate::journal::FlushPolicy;
use petrel_ipc::WaitStrategy;
use std::path::PathBuf;
use std::time::Duration;

/// How to run the player.
#[derive(Clone, Debug)]
pub struct PlayOptions {
    /// The vehicle: its services are `petrel/<vehicle>/...`.
    pub vehicle: String,
    /// How the reactor waits.
    pub wait: WaitStrategy,
    /// Period of the heartbeat (which carries the live status).
    pub heartbeat: Duration,
    /// Period of the check for dead programs (also run whenever a sender is seen dying).
    pub liveness: Duration,
    /// Stop after this long (tests and demos); `None` runs until SIGINT or SIGTERM.
    pub run_for: Option<Duration>,
    /// The journal directory; `None`: no journal.
    pub journal: Option<PathBuf>,
    /// When journal records reach the disk.
    pub flush: FlushPolicy,
    /// Start a new journal segment past this size.
    pub rotate_bytes: u64,
    /// Bytes of journal records kept in memory while the journal cannot be written (a full
    /// disk); past it the recorder drops records and starts over from a checkpoint.
    pub journal_backlog: usize,
    /// Restore the mission from the journal and carry on.
    pub resume: bool,
    /// The project directory, recorded in the journal header.
    pub project_dir: String,
    /// The Unix group (name or number) given the vehicle's files, for operator accounts
    /// (`petrel play --group`); `None`: the user's alone (or `PETREL_GROUP`'s).
    pub group: Option<String>,
}

impl PlayOptions {
    /// Defaults for `vehicle`: block, heartbeat every 100 ms, liveness every 50 ms, no journal.
    pub fn new(vehicle: &str) -> Self {
        PlayOptions {
            vehicle: vehicle.to_string(),
            wait: WaitStrategy::Block,
            heartbeat: Duration::from_millis(100),
            liveness: Duration::from_millis(50),
            run_for: None,
            journal: None,
            flush: FlushPolicy::EveryRecord,
            rotate_bytes: 64 << 20,
            journal_backlog: crate::journal::DEFAULT_BACKLOG,
            resume: false,
            project_dir: String::new(),
            group: None,
        }
    }
}

/// Why the player could not run.
#[derive(Debug)]
pub enum PlayError {
    /// The vehicle name is not usable.
    Vehicle(String),
    /// iceoryx2 could not be set up (another player on the vehicle, say).
    Setup(String),
    /// The journal could not be written or, for `--resume`, read.
    Journal(String),
}

impl std::fmt::Display for PlayError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PlayError::Vehicle(e) => write!(f, "bad vehicle name: {e}"),
            PlayError::Setup(e) => write!(f, "cannot set up the player: {e}"),
            PlayError::Journal(e) => write!(f, "journal: {e}"),
        }
    }
}

impl std::error::Error for PlayError {}

/// What a run of the player did.
#[derive(Clone, Debug, Default)]
pub struct PlayReport {
    /// The engine's counters.
    pub stats: Stats,
    /// Events received from iceoryx2 (decoded or not).
    pub messages: u64,
    /// Messages refused before the engine: undecodable, unknown event, wrong parameters.
    pub bad_messages: u64,
    /// Calls delivered to programs.
    pub calls_sent: u64,
    /// Calls that could not be delivered (each became `call_failed`): to a program with no
    /// live process, held past [`CALL_HOLD`](crate::held::CALL_HOLD), to a program that went while they were held.
    pub calls_failed: u64,
    /// Calls held because their program's process lived but did not receive them yet
    /// (delivered since, or counted in `calls_failed`).
    pub calls_held: u64,
    /// Journal records written.
    pub journal_records: u64,
    /// Attempts to write the journal that failed (a full disk...).
    pub journal_failures: u64,
    /// Journal entries the recorder had to drop.
    pub journal_lost: u64,
    /// Time the reactor thread spent writing the journal.
    pub journal_busy: Duration,
    /// Steps restored from the journal by `--resume`.
    pub resumed_steps: u64,
    /// Heartbeats published.
    pub heartbeats_sent: u64,
    /// Heartbeats that could not be published at all (no shared memory, a bug in their size):
    /// each is logged (the first, then one in a hundred) and counted here.
    pub heartbeats_refused: u64,
    /// Reloads of the project accepted (and swapped).
    pub reloads: u64,
    /// Reload requests refused (or dry runs answered).
    pub reloads_refused: u64,
}
