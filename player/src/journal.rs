//! The flight recorder: an append-only journal of everything the player did.
//!
//! A journal is a directory of segment files `journal-000001.pj`, `journal-000002.pj`, ...
//! (a new segment when one grows past the rotation size). Each segment starts with the magic
//! bytes `PETRELJ1`, then records: a little-endian `u32` length, a little-endian `u32` CRC-32 of
//! the body, and the body, an [`Entry`] encoded with bincode 2. The entries are the engine's
//! inputs (the start, each event submitted, with its time) and its outputs (each step: the event
//! taken, the transitions fired, the actions, the state after, the timers), so a journal can be
//! replayed through the engine and every recorded state checked.
//!
//! A record cut short by a crash (its length runs past the end of the last segment, or its
//! checksum fails and nothing but zero bytes follows it) is *torn*: dropped with a warning. So
//! is a run of zero bytes at the end of the last segment, what a power loss leaves when a file's
//! length reached the disk before its data, and what a player killed while it wrote leaves of
//! the window it had reserved (below). A bad checksum anywhere else is *corruption*: an
//! error that names the segment, the offset and the record. `petrel play --resume` cuts a torn
//! tail off ([`cut_torn_tail`]) before it writes on, so that it never becomes corruption in the
//! middle of the journal.
//!
//! **Writing without a system call.** Under the `record` and interval policies the writer
//! reserves the segment's next megabyte (`fallocate`) and maps it shared
//! ([`petrel_ipc::mapped::MappedWindow`]); a flush copies its records there. The bytes are
//! then in the page cache, as after a `write`: a crash of the player keeps them (a power loss
//! may not, as before; `sync` writes and syncs each record through the file). A full disk is
//! an error of the reservation, and that flush writes through the file as before, keeping what
//! fits. The writer cuts the reserved zeros off when a segment ends (rotation) and when it is
//! dropped; a killed player leaves them, a reader takes them as the end of the journal, and
//! `--resume` cuts them off. The format is unchanged.
//!
//! **Writing, failing, one player per directory.** [`JournalWriter`] queues complete records
//! and writes them at the segment's last good record boundary (a failed write is cut back to
//! it, its records stay queued); `sync`, and file systems without `fallocate`, write through
//! the file (`PETREL_JOURNAL_NO_MAP` forces that, for benchmarks). [`Journal`] is the
//! recorder's state: ok; failing (records wait in memory and are retried at each heartbeat);
//! dropping (past the backlog, until a gap and a checkpoint can be written); each change is
//! raised to the nets (`recorder_failed`, `recorder_restored`). [`JournalLock`] makes a
//! journal directory one player's: a second player is refused, naming the owner; a dead
//! player's lock is taken over with a warning. The player also refuses a new mission a
//! directory that already holds a journal, and `--resume` another vehicle's journal.
//!
//! Decoding is bounded: a record's body is decoded with a bincode limit proportional to its own
//! length ([`decode_entry`]), so a body with a valid checksum that claims a vector of 2^61
//! elements or a string of 2^40 bytes is refused as an undecodable record, never a panic or an
//! allocation the machine cannot make.

use bincode::{Decode, Encode};
use petrel_ipc::mapped::MappedWindow;
use petrel_ipc::RecorderState;
use petrel_nets::compiled::Value;
use std::fs::{File, OpenOptions};
use std::io::{Read, Write};
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

const MAGIC: &[u8; 8] = b"PETRELJ1";

/// How much of a segment the writer reserves and maps at a time ([`MappedWindow`]): a system
/// call (`fallocate`, `mmap`) every few thousand steps instead of a write per round.
const MAP_WINDOW: usize = 1 << 20;

/// When set (to anything), the journal writes every record through `pwrite`, without a mapped
/// window: what the benchmarks compare the window with.
pub const NO_MAP_ENV: &str = "PETREL_JOURNAL_NO_MAP";
/// Largest record written or read (a guard against a corrupt length field). A step of the
/// largest project holds a few kilobytes; events on the wire are at most 64 KiB.
pub const MAX_RECORD: u32 = 16 << 20;

/// How many bytes of memory decoding may claim per byte of a record. bincode claims
/// `len × size_of::<T>()` before it decodes a container; the widest element an entry holds per
/// byte of its encoding is a `String` (24 bytes in memory, 1 byte encoded when empty), so 32
/// accepts every record the writer produces, and bounds what a crafted one can make us
/// allocate to 32 times its own length.
const CLAIM_PER_BYTE: usize = 32;

fn decode_limited<const LIMIT: usize>(
    body: &[u8],
) -> Result<(Entry, usize), bincode::error::DecodeError> {
    bincode::decode_from_slice(body, bincode::config::standard().with_limit::<LIMIT>())
}

/// Decodes one record's body into an [`Entry`], with a bincode limit of
/// `CLAIM_PER_BYTE` times the body's length (rounded up to a power of two, at least 4 KiB):
/// every byte of the body must belong to the entry. bincode's limit is a constant of its
/// configuration type, so the limit is picked from a fixed ladder of powers of two.
pub fn decode_entry(body: &[u8]) -> Result<Entry, String> {
    if body.len() > MAX_RECORD as usize {
        return Err(format!(
            "a record of {} bytes, more than the {MAX_RECORD} a journal holds",
            body.len()
        ));
    }
    let limit = body
        .len()
        .saturating_mul(CLAIM_PER_BYTE)
        .max(4096)
        .next_power_of_two();
    macro_rules! ladder {
        ($($bits:literal)*) => {
            match limit.trailing_zeros() {
                $($bits => decode_limited::<{ 1usize << $bits }>(body),)*
                _ => return Err(format!("a record of {} bytes is too large to decode", body.len())),
            }
        };
    }
    // 2^12 (4 KiB) up to 2^29 (32 × MAX_RECORD).
    let decoded = ladder!(12 13 14 15 16 17 18 19 20 21 22 23 24 25 26 27 28 29);
    match decoded {
        Ok((entry, used)) if used == body.len() => Ok(entry),
        Ok((_, used)) => Err(format!(
            "{} bytes left over after the entry (of {})",
            body.len() - used,
            body.len()
        )),
        Err(bincode::error::DecodeError::LimitExceeded) => Err(format!(
            "undecodable entry: it claims more memory than a record of {} bytes can hold (a corrupt or crafted length)",
            body.len()
        )),
        Err(e) => Err(format!("undecodable entry: {e}")),
    }
}

/// The journal format this Petrel writes (the header's `version`): 2 added [`Entry::Gap`] and
/// [`Entry::Checkpoint`], 3 [`Entry::Reload`], 4 [`Entry::ProgramStopped`]. Journals of
/// earlier versions read the same.
pub const FORMAT_VERSION: u32 = 4;

/// One journal entry.
#[derive(Clone, Debug, PartialEq, Encode, Decode)]
pub enum Entry {
    /// The first entry of every segment: what was recorded, and with which project.
    Header {
        /// Format version ([`FORMAT_VERSION`]).
        version: u32,
        /// Project name.
        project: String,
        /// The project directory, as given to `petrel play`.
        project_dir: String,
        /// A digest of the compiled project: replay refuses another project.
        digest: u64,
        /// The vehicle.
        vehicle: String,
        /// Wall-clock start of the recording, milliseconds since the Unix epoch.
        started_unix_ms: u64,
    },
    /// The mission started (initial activation and fixpoint done) at `time`.
    Start {
        /// Mission time, microseconds.
        time: u64,
        /// The state after the start.
        state: Vec<u64>,
    },
    /// The player resumed from this journal at `time` (after a crash).
    Resume {
        /// Mission time at which it resumed, microseconds.
        time: u64,
    },
    /// An event was accepted into the engine's queue.
    Submit {
        /// Mission time, microseconds.
        time: u64,
        /// Event name.
        event: String,
        /// Its parameters.
        params: Vec<Value>,
        /// Who sent it (`program/DEC`, `tool/send123`, `player` for built-ins).
        origin: String,
        /// The sender's sequence number (0 for built-ins).
        seq: u64,
    },
    /// A message was refused before the engine (unknown event, wrong parameters...).
    Refused {
        /// Mission time, microseconds.
        time: u64,
        /// What was refused.
        what: String,
        /// Why.
        reason: String,
        /// Who sent it.
        origin: String,
    },
    /// The engine took an event and processed it.
    Step {
        /// Mission time, microseconds.
        time: u64,
        /// The event taken.
        event: String,
        /// Its parameters.
        params: Vec<Value>,
        /// `processed`, `unused` or `refused`.
        outcome: String,
        /// `NET.transition` fired, in order.
        fired: Vec<String>,
        /// Actions, as text (calls with their arguments, timers, activations).
        actions: Vec<String>,
        /// The state after the step.
        state: Vec<u64>,
        /// Running timers' deadlines after the step (microseconds), by timer.
        deadlines: Vec<Option<u64>>,
    },
    /// The flight recorder could not keep `lost` entries (it could not write them, and no
    /// longer had room in memory for them): the journal goes on from the [`Entry::Checkpoint`]
    /// that follows.
    Gap {
        /// Mission time when the recorder could write again, microseconds.
        time: u64,
        /// Entries dropped.
        lost: u64,
        /// Why they could not be written.
        reason: String,
    },
    /// The whole state of the engine between two steps (its queue empty): after a
    /// [`Entry::Gap`], replay and `--resume` start over from it.
    Checkpoint {
        /// Mission time, microseconds.
        time: u64,
        /// The state.
        state: Vec<u64>,
        /// Running timers' deadlines (microseconds), by timer.
        deadlines: Vec<Option<u64>>,
    },
    /// The project was reloaded (`petrel reload`) between two steps: from here on the new
    /// version runs. Its files are kept beside the journal, in `project-<source_hash>/`
    /// (written before this entry); replay maps the state again and checks it against
    /// `state`, and `--resume` after it resumes on the new version. (Last of the variants:
    /// bincode numbers them, and the entries of earlier versions keep their encoding.)
    Reload {
        /// Mission time, microseconds.
        time: u64,
        /// The new version's directory, as requested (for people: the journal keeps a copy).
        dir: String,
        /// The content hash of its files: the name of the copy beside the journal.
        source_hash: String,
        /// The digest of the new compiled project.
        digest: u64,
        /// The mapping file's text (empty: none).
        mapping: String,
        /// The mapped state the new version starts from.
        state: Vec<u64>,
        /// The running timers' deadlines after the mapping (microseconds), by new timer.
        deadlines: Vec<Option<u64>>,
        /// The events queued at the reload, carried over to the new version in this order:
        /// name, parameters, the net it is addressed to (`--resume` from this entry queues
        /// them again; their submissions are before it).
        queued: Vec<(String, Vec<Value>, Option<String>)>,
    },
    /// A program's process went after it said it leaves in good order: a stop, not a loss (no
    /// `program_lost`). Not an input: replay passes over it. (After [`Entry::Reload`]: the
    /// entries of earlier versions keep their encoding.)
    ProgramStopped {
        /// Mission time, microseconds.
        time: u64,
        /// The program.
        program: String,
    },
}

impl Entry {
    /// The mission time of the entry, if it has one.
    pub fn time(&self) -> Option<u64> {
        match self {
            Entry::Header { .. } => None,
            Entry::Start { time, .. }
            | Entry::Resume { time }
            | Entry::Submit { time, .. }
            | Entry::Refused { time, .. }
            | Entry::Step { time, .. }
            | Entry::Gap { time, .. }
            | Entry::Reload { time, .. }
            | Entry::ProgramStopped { time, .. }
            | Entry::Checkpoint { time, .. } => Some(*time),
        }
    }
}

/// When records reach the disk.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FlushPolicy {
    /// Written to the operating system after every record (survives a crash of the player, not
    /// of the machine); the player writes the records of one round of work together, before it
    /// sleeps, or within [`BATCH_DELAY`] while it spins ([`Journal::batch_records`]).
    EveryRecord,
    /// Written and synced to the disk (fdatasync) after every record: survives a power loss,
    /// costs a disk round trip per record.
    Sync,
    /// Written to the operating system at most every given interval (and before every
    /// acknowledgement): the cheapest, a crash loses at most that much.
    Interval(Duration),
}

impl std::str::FromStr for FlushPolicy {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "record" => Ok(FlushPolicy::EveryRecord),
            "sync" => Ok(FlushPolicy::Sync),
            _ => s
                .strip_suffix("ms")
                .and_then(|n| n.parse::<u64>().ok())
                .map(|ms| FlushPolicy::Interval(Duration::from_millis(ms)))
                .ok_or_else(|| {
                    format!("unknown flush policy `{s}`: use record, sync or a period such as 50ms")
                }),
        }
    }
}

/// Appends entries to a journal directory.
///
/// Entries are encoded into a queue of complete records, and written from it
/// ([`flush`](Self::flush), which each [`append`](Self::append) does according to the policy) at the
/// segment's last good record boundary. A write that fails (a full disk) is cut back to that
/// boundary, so a partial record never stays in the file, and the records stay queued: the next
/// flush writes them again. Nothing queued is lost while the writer lives.
pub struct JournalWriter {
    dir: PathBuf,
    policy: FlushPolicy,
    rotate_bytes: u64,
    header: Entry,
    file: File,
    segment: u32,
    /// Bytes of the current segment on record: the end of its last good record.
    written: u64,
    /// The magic and the header: a segment holding only these takes any record.
    floor: u64,
    /// The file may hold bytes past `written` (a failed write whose cut failed too, or the
    /// zeros of a reserved window): cut them off before the next write through the file, at a
    /// rotation and when the writer is dropped.
    tail_dirty: bool,
    /// Under [`FlushPolicy::EveryRecord`] and [`FlushPolicy::Interval`], records are copied
    /// into a shared mapping of the segment's tail ([`MappedWindow`]): in the page cache at
    /// once, as after a write, without a system call per flush. `None` until the first flush,
    /// after a rotation, or when a window could not be reserved (then this flush writes
    /// through the file).
    window: Option<MappedWindow>,
    /// False under [`FlushPolicy::Sync`] (which syncs each write) or once the file system said
    /// it cannot reserve (`fallocate` unsupported): every record goes through `pwrite`.
    mapping: bool,
    /// Encoded records not yet written, and the length of each.
    queued: Vec<u8>,
    lengths: Vec<usize>,
    last_flush: Instant,
    buf: Vec<u8>,
    /// Records written.
    pub records: u64,
    /// Time spent writing the encoded records (copying or writing them, syncing); encoding
    /// them (about 0.1 µs a record) is not timed.
    pub busy: Duration,
}

/// Creates journal directory `dir` (and the directories on the way) owner-only, as every file
/// of a journal is: it is the mission's whole record, for the vehicle's user alone. A directory
/// that is already there keeps its mode.
pub fn create_dir(dir: &Path) -> std::io::Result<()> {
    use std::os::unix::fs::DirBuilderExt;
    std::fs::DirBuilder::new()
        .recursive(true)
        .mode(0o700)
        .create(dir)
}

/// Opens a journal file the journal creates: owner-only (`0600`) from its creation.
fn private_file() -> OpenOptions {
    use std::os::unix::fs::OpenOptionsExt;
    let mut o = OpenOptions::new();
    o.mode(0o600);
    o
}

fn segment_path(dir: &Path, n: u32) -> PathBuf {
    dir.join(format!("journal-{n:06}.pj"))
}

/// The segment files of a journal directory, in order.
pub fn segments(dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    // An entry that cannot be read is an error, not a segment silently left out of a replay.
    let entries = std::fs::read_dir(dir)?.collect::<std::io::Result<Vec<_>>>()?;
    let mut files: Vec<PathBuf> = entries
        .into_iter()
        .map(|e| e.path())
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("journal-") && n.ends_with(".pj"))
        })
        .collect();
    files.sort();
    Ok(files)
}

/// [`Entry::Submit`], borrowed: the same bytes (bincode writes an enum's variant index as a
/// `u32`, then its fields; a `&str` as a `String`, a slice as a `Vec`), so that the player
/// journals each event it takes without copying its name, parameters and origin. A test
/// checks that both encode alike.
#[derive(Encode)]
struct SubmitRecord<'a> {
    variant: u32,
    time: u64,
    event: &'a str,
    params: &'a [Value],
    origin: &'a str,
    seq: u64,
}

/// The index of [`Entry::Submit`] among the entry's variants.
const SUBMIT_VARIANT: u32 = 3;

/// [`Entry::Step`], borrowed from the engine and the step's record, for
/// [`Journal::append_step`]: its fields are the entry's, in the entry's order, and `fired`
/// is anything that encodes as the entry's `Vec<String>` of `NET.transition` (the record's
/// [`FiredNames`](crate::record::FiredNames) writes them without building them). The player
/// journals every step this way, without copying the step.
#[derive(Encode)]
pub struct StepParts<'a, F: Encode> {
    /// Mission time, microseconds.
    pub time: u64,
    /// The event taken.
    pub event: &'a str,
    /// Its parameters.
    pub params: &'a [Value],
    /// `processed`, `unused` or `refused`.
    pub outcome: &'a str,
    /// `NET.transition` fired, in order.
    pub fired: F,
    /// Actions, as text.
    pub actions: &'a [String],
    /// The state after the step.
    pub state: &'a [u64],
    /// Running timers' deadlines after the step (microseconds), by timer.
    pub deadlines: &'a [Option<u64>],
}

/// The index of [`Entry::Step`] among the entry's variants.
const STEP_VARIANT: u32 = 5;

/// Encodes `entry` as one record (length, CRC-32, body) at the end of `out`.
fn encode_record<E: Encode>(
    entry: &E,
    body: &mut Vec<u8>,
    out: &mut Vec<u8>,
) -> std::io::Result<()> {
    body.clear();
    bincode::encode_into_std_write(entry, body, bincode::config::standard())
        .map_err(std::io::Error::other)?;
    if body.len() > MAX_RECORD as usize {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!(
                "a journal entry of {} bytes, more than the {MAX_RECORD} a record holds",
                body.len()
            ),
        ));
    }
    out.extend_from_slice(&(body.len() as u32).to_le_bytes());
    out.extend_from_slice(&crc32fast::hash(body).to_le_bytes());
    out.extend_from_slice(body);
    Ok(())
}

impl JournalWriter {
    /// Starts a journal in `dir` (created if needed), after any segments already there, and
    /// writes `header` first.
    pub fn open(
        dir: &Path,
        header: Entry,
        policy: FlushPolicy,
        rotate_bytes: u64,
    ) -> std::io::Result<JournalWriter> {
        create_dir(dir)?;
        let next = segments(dir)?
            .last()
            .and_then(|p| {
                p.file_stem()?
                    .to_str()?
                    .strip_prefix("journal-")?
                    .parse::<u32>()
                    .ok()
            })
            .map_or(1, |n| n + 1);
        let (file, floor) = Self::new_segment(dir, next, &header, policy)?;
        Ok(JournalWriter {
            dir: dir.to_path_buf(),
            policy,
            rotate_bytes: rotate_bytes.max(4096),
            header,
            file,
            segment: next,
            written: floor,
            floor,
            tail_dirty: false,
            window: None,
            mapping: policy != FlushPolicy::Sync && std::env::var_os(NO_MAP_ENV).is_none(),
            queued: Vec::with_capacity(4096),
            lengths: Vec::new(),
            last_flush: Instant::now(),
            buf: Vec::with_capacity(4096),
            records: 1,
            busy: Duration::ZERO,
        })
    }

    /// Creates segment `n` with the magic and the header, written (and synced under
    /// [`FlushPolicy::Sync`]); a segment that could not be completed is removed.
    fn new_segment(
        dir: &Path,
        n: u32,
        header: &Entry,
        policy: FlushPolicy,
    ) -> std::io::Result<(File, u64)> {
        let path = segment_path(dir, n);
        let mut file = private_file()
            .create_new(true)
            .read(true)
            .write(true)
            .open(&path)?;
        let mut bytes = MAGIC.to_vec();
        encode_record(header, &mut Vec::new(), &mut bytes)?;
        let done = file.write_all(&bytes).and_then(|()| {
            if policy == FlushPolicy::Sync {
                file.sync_data()
            } else {
                Ok(())
            }
        });
        if let Err(e) = done {
            drop(file);
            let _ = std::fs::remove_file(&path);
            return Err(e);
        }
        Ok((file, bytes.len() as u64))
    }

    /// Queues one entry without writing it (see [`flush`](Self::flush)). Fails only when the
    /// entry cannot be encoded as a record (larger than [`MAX_RECORD`]).
    pub fn push(&mut self, entry: &Entry) -> std::io::Result<()> {
        self.push_encoded(entry)
    }

    /// [`push`](Self::push) of an entry's encoding (an [`Entry`] or a borrowed mirror of one).
    fn push_encoded<E: Encode>(&mut self, entry: &E) -> std::io::Result<()> {
        // Not timed: two clock reads would cost about as much as encoding a step's record.
        let before = self.queued.len();
        encode_record(entry, &mut self.buf, &mut self.queued)?;
        self.lengths.push(self.queued.len() - before);
        Ok(())
    }

    /// Queues one entry and writes according to the policy. On an error the entry stays
    /// queued (unless it could not be encoded at all), and the next flush tries again.
    pub fn append(&mut self, entry: &Entry) -> std::io::Result<()> {
        self.push(entry)?;
        match self.policy {
            FlushPolicy::EveryRecord | FlushPolicy::Sync => self.flush(),
            FlushPolicy::Interval(p) => {
                if self.last_flush.elapsed() >= p {
                    self.flush()
                } else {
                    Ok(())
                }
            }
        }
    }

    /// Writes every queued record to the operating system (and syncs it to the disk under
    /// [`FlushPolicy::Sync`]), starting new segments past the rotation size. On an error, what
    /// was written stays written, the rest stays queued, and the segment ends at its last good
    /// record.
    pub fn flush(&mut self) -> std::io::Result<()> {
        let started = Instant::now();
        let result = self.write_queued();
        let ended = Instant::now();
        if result.is_ok() {
            self.last_flush = ended;
        }
        self.busy += ended - started;
        result
    }

    /// Cuts the segment back to its last good record: the window (whose end must not be cut
    /// under it) is dropped first.
    fn cut_tail(&mut self) -> std::io::Result<()> {
        self.window = None;
        self.file.set_len(self.written)?;
        self.tail_dirty = false;
        Ok(())
    }

    /// Copies `bytes` (whole records) into the mapped window at the segment's end, reserving a
    /// new window when they do not fit in the one there is. False when they could not be
    /// mapped: the caller writes them through the file.
    fn write_mapped(&mut self, bytes: &[u8]) -> bool {
        if !self.mapping {
            return false;
        }
        let at = self.written;
        if !self
            .window
            .as_ref()
            .is_some_and(|w| w.covers(at, bytes.len()))
        {
            // The old window is dropped before the new one is made: at most one at a time.
            self.window = None;
            // Up to the rotation size: the window's zeros are cut off when the segment ends.
            let room = usize::try_from(self.rotate_bytes.saturating_sub(at)).unwrap_or(MAP_WINDOW);
            let len = bytes.len().max(MAP_WINDOW.min(room));
            match MappedWindow::reserve(&self.file, at, len) {
                Ok(w) => {
                    self.window = Some(w);
                    self.tail_dirty = true;
                }
                Err(e) => {
                    if petrel_ipc::mapped::cannot_reserve(&e) {
                        tracing::debug!(error = %e, "the journal's file system cannot reserve space: records are written through the file");
                        self.mapping = false;
                    }
                    // A full disk, among others: this flush writes through the file, which
                    // takes what fits and says what did not, as without a window.
                    return false;
                }
            }
        }
        match self.window.as_mut() {
            Some(w) => w.write_at(at, bytes).is_ok(),
            None => false,
        }
    }

    fn write_queued(&mut self) -> std::io::Result<()> {
        if self.tail_dirty && self.window.is_none() {
            self.cut_tail()?;
        }
        let (mut done, mut k) = (0usize, 0usize);
        let result = loop {
            if k == self.lengths.len() {
                break Ok(());
            }
            // The records that fit in this segment (any one record fits in a fresh segment).
            let (mut end, mut j) = (done, k);
            while j < self.lengths.len() {
                let len = self.lengths[j];
                let fresh = self.written == self.floor && end == done;
                if !fresh && self.written + (end - done + len) as u64 > self.rotate_bytes {
                    break;
                }
                end += len;
                j += 1;
            }
            if end > done && self.write_mapped_range(done, end) {
                self.written += (end - done) as u64;
                self.records += (j - k) as u64;
                done = end;
                k = j;
            } else if end > done {
                if self.tail_dirty {
                    // The window's reserved zeros: cut before writing through the file, which
                    // does not know of them.
                    if let Err(e) = self.cut_tail() {
                        break Err(e);
                    }
                }
                let bytes = &self.queued[done..end];
                if let Err((e, wrote)) = write_at_tracked(&self.file, bytes, self.written) {
                    // Keep the complete records that reached the file (not under `Sync`: they
                    // are not on the disk), and cut the rest: no partial record stays.
                    if self.policy != FlushPolicy::Sync {
                        let mut kept = 0;
                        while k < j && kept + self.lengths[k] <= wrote {
                            kept += self.lengths[k];
                            k += 1;
                            self.records += 1;
                        }
                        self.written += kept as u64;
                        done += kept;
                    }
                    self.tail_dirty = self.file.set_len(self.written).is_err();
                    break Err(e);
                }
                if self.policy == FlushPolicy::Sync {
                    // Not synced, not on record: written again (the same bytes) next time.
                    if let Err(e) = self.file.sync_data() {
                        break Err(e);
                    }
                }
                self.written += (end - done) as u64;
                self.records += (j - k) as u64;
                done = end;
                k = j;
            }
            if k < self.lengths.len() {
                if let Err(e) = self.rotate() {
                    break Err(e);
                }
            }
        };
        self.queued.drain(..done);
        self.lengths.drain(..k);
        result
    }

    /// [`write_mapped`](Self::write_mapped) of the queued bytes `[from, to)`.
    fn write_mapped_range(&mut self, from: usize, to: usize) -> bool {
        let queued = std::mem::take(&mut self.queued);
        let done = self.write_mapped(&queued[from..to]);
        self.queued = queued;
        done
    }

    fn rotate(&mut self) -> std::io::Result<()> {
        // The segment that ends must end at its last record: zeros past it would read as
        // corruption in a segment that is not the last.
        if self.tail_dirty {
            self.cut_tail()?;
        }
        let (file, floor) =
            Self::new_segment(&self.dir, self.segment + 1, &self.header, self.policy)?;
        self.file = file;
        self.segment += 1;
        self.written = floor;
        self.floor = floor;
        self.records += 1;
        Ok(())
    }

    /// Records queued and not yet written.
    pub fn queued_records(&self) -> usize {
        self.lengths.len()
    }

    /// Bytes queued and not yet written.
    pub fn queued_bytes(&self) -> usize {
        self.queued.len()
    }

    /// Drops every queued record (the recorder gives up on them); returns how many.
    pub fn discard_queued(&mut self) -> usize {
        let n = self.lengths.len();
        self.queued.clear();
        self.lengths.clear();
        n
    }

    /// The directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }
}

impl Drop for JournalWriter {
    fn drop(&mut self) {
        // A segment that stops here ends at its last record, not in a window's zeros (a crash
        // leaves them: a reader takes them as the end, `--resume` cuts them off).
        if self.tail_dirty {
            if let Err(e) = self.cut_tail() {
                // Nothing is lost: a reader takes the zeros as the end, `--resume` cuts them.
                tracing::warn!(dir = %self.dir.display(), error = %e, "cannot cut the journal's reserved zeros off its last segment");
            }
        }
    }
}

/// Writes all of `bytes` at `offset`; on an error, also says how many bytes were written
/// before it (a full disk takes what it has room for).
fn write_at_tracked(file: &File, bytes: &[u8], offset: u64) -> Result<(), (std::io::Error, usize)> {
    let mut done = 0;
    while done < bytes.len() {
        match file.write_at(&bytes[done..], offset + done as u64) {
            Ok(0) => {
                return Err((
                    std::io::Error::new(std::io::ErrorKind::WriteZero, "the file took no byte"),
                    done,
                ))
            }
            Ok(n) => done += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err((e, done)),
        }
    }
    Ok(())
}

/// What the journal's [`flush`](Journal::flush) means for the events taken since the last one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Settlement {
    /// Everything appended is on record (or there is no journal): settled.
    Recorded,
    /// Not written yet (the recorder is failing and keeps them): not settled.
    Pending,
    /// Dropped by the recorder: settled as unrecorded.
    Lost,
}

/// A change of the recorder's state, for the player to raise as a built-in event.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum RecorderChange {
    /// It could not write (`recorder_failed(reason)`).
    Failed(String),
    /// It wrote everything again (`recorder_restored`).
    Restored,
}

/// Default of [`Journal::with_backlog`]: what a failing recorder keeps in memory before it
/// drops records (a minute of a busy vehicle's steps, and more).
pub const DEFAULT_BACKLOG: usize = 32 << 20;

/// Under a spinning wait strategy, how long the player may hold a round's records before it
/// writes them ([`Journal::batch_records`]): the write (a system call of several
/// microseconds) is then not on the path of the next event of a quick exchange, and a busy
/// exchange writes once per this delay instead of once per event. Acknowledgements still wait
/// for the write, so a crash of the player loses only events it never acknowledged.
pub const BATCH_DELAY: Duration = Duration::from_millis(1);

/// The journal of a running player: a writer, or none (`--no-journal`), and the recorder's
/// state.
///
/// A failure to write never stops the player (a vehicle must keep flying). The recorder goes
/// **failing**: records stay queued in memory, the events they hold are not acknowledged
/// ([`Settlement::Pending`]), and every [`flush`](Self::flush) (each heartbeat) tries again;
/// when one succeeds it is **ok** again and everything is on record. Past the backlog it goes
/// **dropping**: the queued records are dropped and counted, and so is every later one
/// ([`Settlement::Lost`]), until a [`checkpoint`](Self::checkpoint) (an [`Entry::Gap`] and an
/// [`Entry::Checkpoint`] of the engine) can be written, from which replay and `--resume` go
/// on. Each change is said once in the log (not once per record) and handed to the player
/// ([`take_changes`](Self::take_changes)) to raise `recorder_failed` or `recorder_restored`.
pub struct Journal {
    writer: Option<JournalWriter>,
    state: RecorderState,
    reason: String,
    backlog: usize,
    since: Instant,
    changes: Vec<RecorderChange>,
    /// Write or flush attempts that failed.
    pub failures: u64,
    /// Entries the recorder dropped.
    pub lost: u64,
    /// Of them, those a [`Entry::Gap`] on record accounts for.
    lost_in_gaps: u64,
    /// Under `record` and `sync`, records wait for [`write_batch`](Self::write_batch) instead
    /// of being written one by one.
    batched: bool,
    /// When the oldest record held for [`write_batch`](Self::write_batch) was appended.
    batch_since: Option<Instant>,
}

impl Journal {
    /// A journal writing through `writer`, if any, with the default backlog.
    pub fn new(writer: Option<JournalWriter>) -> Self {
        Self::with_backlog(writer, DEFAULT_BACKLOG)
    }

    /// A journal that keeps up to `backlog` bytes of records in memory while it cannot write.
    pub fn with_backlog(writer: Option<JournalWriter>, backlog: usize) -> Self {
        Journal {
            state: if writer.is_some() {
                RecorderState::Ok
            } else {
                RecorderState::None
            },
            writer,
            reason: String::new(),
            backlog,
            since: Instant::now(),
            changes: Vec::new(),
            failures: 0,
            lost: 0,
            lost_in_gaps: 0,
            batched: false,
            batch_since: None,
        }
    }

    /// Under the `record` and `sync` policies, holds the records until
    /// [`write_batch`](Self::write_batch) instead of writing each at once. The player's loop
    /// calls it before it sleeps, and under a spinning wait strategy at most
    /// [`BATCH_DELAY`] after the oldest record held: the records of one round of work (an
    /// event taken, the steps it caused), or of the rounds of a quick exchange, then reach the
    /// operating system in one system call, after the calls they made went out rather than
    /// before, and always before any acknowledgement (which [`flush`](Self::flush) precedes).
    pub fn batch_records(&mut self) {
        self.batched = true;
    }

    /// Writes the records held by [`batch_records`](Self::batch_records) (nothing to do
    /// otherwise, or under an interval policy, or while the recorder is not ok: the heartbeat's
    /// [`flush`](Self::flush) retries).
    pub fn write_batch(&mut self) {
        let Some(w) = self.writer.as_mut() else {
            return;
        };
        let due = self.batched
            && self.state == RecorderState::Ok
            && w.queued_records() > 0
            && matches!(w.policy, FlushPolicy::EveryRecord | FlushPolicy::Sync);
        if due {
            if let Err(e) = w.flush() {
                self.fail(&e);
            }
        }
        self.batch_since = None;
    }

    /// When the oldest record held for [`write_batch`](Self::write_batch) was appended (`None`:
    /// nothing held, or the recorder is not ok and the heartbeat's flush retries).
    pub fn batch_since(&self) -> Option<Instant> {
        self.batch_since
    }

    /// The recorder's state.
    pub fn state(&self) -> RecorderState {
        self.state
    }

    /// Why it last failed (empty when it is ok).
    pub fn reason(&self) -> &str {
        &self.reason
    }

    /// Records and bytes waiting in memory.
    pub fn backlog(&self) -> (usize, usize) {
        self.writer
            .as_ref()
            .map_or((0, 0), |w| (w.queued_records(), w.queued_bytes()))
    }

    /// The state changes since the last call, oldest first.
    pub fn take_changes(&mut self) -> Vec<RecorderChange> {
        std::mem::take(&mut self.changes)
    }

    /// True when a change waits for [`take_changes`](Self::take_changes).
    pub fn has_changes(&self) -> bool {
        !self.changes.is_empty()
    }

    fn fail(&mut self, e: &std::io::Error) {
        self.batch_since = None;
        self.failures += 1;
        self.reason = e.to_string();
        if self.state == RecorderState::Ok {
            self.state = RecorderState::Failing;
            self.since = Instant::now();
            tracing::error!(error = %e, "the flight recorder cannot write: its records wait in memory and the events they hold are not acknowledged until it can; raising recorder_failed");
            self.changes
                .push(RecorderChange::Failed(self.reason.clone()));
        } else {
            tracing::debug!(error = %e, "the flight recorder still cannot write");
        }
    }

    fn start_dropping(&mut self, why: String) {
        self.batch_since = None;
        let dropped = self
            .writer
            .as_mut()
            .map_or(0, JournalWriter::discard_queued);
        self.lost += dropped as u64;
        if self.state == RecorderState::Ok {
            self.changes.push(RecorderChange::Failed(why.clone()));
        }
        self.state = RecorderState::Dropping;
        self.reason = why;
        tracing::error!(dropped, reason = %self.reason, "the flight recorder drops records: the journal will go on from a checkpoint of the state once it can write");
    }

    /// Appends one entry (if there is a journal): written now or later, or dropped (and
    /// counted) while the recorder is dropping.
    pub fn append(&mut self, entry: &Entry) {
        self.append_encoded(entry);
    }

    /// Appends an [`Entry::Submit`] of these parts, as [`append`](Self::append) would, without
    /// making the entry.
    pub fn append_submit(
        &mut self,
        time: u64,
        event: &str,
        params: &[Value],
        origin: &str,
        seq: u64,
    ) {
        self.append_encoded(&SubmitRecord {
            variant: SUBMIT_VARIANT,
            time,
            event,
            params,
            origin,
            seq,
        });
    }

    /// Appends an [`Entry::Step`] of these parts, as [`append`](Self::append) would, without
    /// making the entry (bincode writes an enum's variant index, then its fields: a tuple of
    /// the index and the parts is the entry's bytes).
    pub fn append_step<F: Encode>(&mut self, step: &StepParts<'_, F>) {
        self.append_encoded(&(STEP_VARIANT, step));
    }

    fn append_encoded<E: Encode>(&mut self, entry: &E) {
        let Some(w) = self.writer.as_mut() else {
            return;
        };
        match self.state {
            RecorderState::Dropping => self.lost += 1,
            RecorderState::Ok => match w.push_encoded(entry) {
                Err(e) => self.start_dropping(format!("an entry cannot be recorded: {e}")),
                Ok(()) => {
                    let due = match w.policy {
                        FlushPolicy::EveryRecord | FlushPolicy::Sync => {
                            if self.batched && self.batch_since.is_none() {
                                self.batch_since = Some(Instant::now());
                            }
                            !self.batched
                        }
                        FlushPolicy::Interval(p) => w.last_flush.elapsed() >= p,
                    };
                    if due {
                        if let Err(e) = w.flush() {
                            self.fail(&e);
                        }
                    }
                }
            },
            // Retried at the next flush, not at every record.
            _ => match w.push_encoded(entry) {
                Err(e) => self.start_dropping(format!("an entry cannot be recorded: {e}")),
                Ok(()) if w.queued_bytes() > self.backlog => {
                    let why = format!(
                        "{} (and more than {} bytes of records waited in memory)",
                        self.reason, self.backlog
                    );
                    self.start_dropping(why);
                }
                Ok(()) => {}
            },
        }
    }

    /// Writes what waits (each heartbeat calls it, before the acknowledgements go out) and
    /// says what that means for the events taken since the last flush.
    pub fn flush(&mut self) -> Settlement {
        let Some(w) = self.writer.as_mut() else {
            return Settlement::Recorded;
        };
        match self.state {
            RecorderState::Dropping => Settlement::Lost,
            _ => match w.flush() {
                Ok(()) => {
                    self.batch_since = None;
                    if self.state == RecorderState::Failing {
                        tracing::warn!(
                            after_s = self.since.elapsed().as_secs_f64(),
                            "the flight recorder writes again: every record waiting in memory is written; raising recorder_restored"
                        );
                        self.state = RecorderState::Ok;
                        self.reason.clear();
                        self.changes.push(RecorderChange::Restored);
                    }
                    Settlement::Recorded
                }
                Err(e) => {
                    self.fail(&e);
                    Settlement::Pending
                }
            },
        }
    }

    /// True when the recorder is dropping and waits for a checkpoint to go on.
    pub fn wants_checkpoint(&self) -> bool {
        self.state == RecorderState::Dropping
    }

    /// While dropping: tries to write an [`Entry::Gap`] (what was lost) and `checkpoint` (an
    /// [`Entry::Checkpoint`] of the engine now). True when they are on record: the recorder is
    /// ok again, and the journal goes on from the checkpoint.
    pub fn checkpoint(&mut self, checkpoint: &Entry) -> bool {
        let Some(w) = self.writer.as_mut() else {
            return false;
        };
        if self.state != RecorderState::Dropping {
            return false;
        }
        let gap = Entry::Gap {
            time: checkpoint.time().unwrap_or(0),
            lost: self.lost - self.lost_in_gaps,
            reason: self.reason.clone(),
        };
        let written = w
            .push(&gap)
            .and_then(|()| w.push(checkpoint))
            .and_then(|()| w.flush());
        if w.queued_records() < 2 {
            // The gap is on record, with or without its checkpoint.
            self.lost_in_gaps = self.lost;
        }
        match written {
            Ok(()) => {
                tracing::warn!(
                    lost = self.lost,
                    after_s = self.since.elapsed().as_secs_f64(),
                    "the flight recorder writes again, from a checkpoint of the state; raising recorder_restored"
                );
                self.state = RecorderState::Ok;
                self.reason.clear();
                self.changes.push(RecorderChange::Restored);
                true
            }
            Err(e) => {
                w.discard_queued();
                self.failures += 1;
                self.reason = e.to_string();
                false
            }
        }
    }

    /// Records written and time spent writing them, if there is a journal.
    pub fn written(&self) -> Option<(u64, Duration)> {
        self.writer.as_ref().map(|w| (w.records, w.busy))
    }
}

/// Where a journal stopped being readable.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Damage {
    /// The segment.
    pub segment: PathBuf,
    /// Byte offset of the bad record in the segment.
    pub offset: u64,
    /// Index of the bad record in the whole journal (0-based).
    pub record: u64,
    /// What is wrong.
    pub what: String,
}

impl std::fmt::Display for Damage {
    /// `record N of SEGMENT (byte B): WHAT`, the way every command names a damaged record.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "record {} of {} (byte {}): {}",
            self.record,
            self.segment.display(),
            self.offset,
            self.what
        )
    }
}

/// A journal as read: its entries, and what could not be read.
#[derive(Clone, Debug, Default)]
pub struct JournalRead {
    /// Entries in order.
    pub entries: Vec<Entry>,
    /// A last record cut short by a crash, dropped.
    pub torn: Option<Damage>,
    /// The torn tail is only zeros: space a player reserved and had not written yet (it still
    /// runs, or it was killed), or a power loss before the data reached the disk. Every record
    /// before them was read; no record was cut short.
    pub unwritten: bool,
    /// A bad record in the middle: the journal was damaged; entries stop before it.
    pub corrupt: Option<Damage>,
}

/// Why a journal could not be read at all.
#[derive(Debug)]
pub enum JournalError {
    /// I/O.
    Io(PathBuf, std::io::Error),
    /// No segment in the directory.
    Empty(PathBuf),
    /// A segment does not start with the magic bytes.
    NotAJournal(PathBuf),
}

impl std::fmt::Display for JournalError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            JournalError::Io(p, e) => write!(f, "cannot read {}: {e}", p.display()),
            JournalError::Empty(p) => write!(
                f,
                "{} holds no journal segment (journal-NNNNNN.pj)",
                p.display()
            ),
            JournalError::NotAJournal(p) => write!(
                f,
                "{} is not a Petrel journal (it does not start with PETRELJ1)",
                p.display()
            ),
        }
    }
}

impl std::error::Error for JournalError {}

/// Reads a journal: a directory of segments, or one segment file.
pub fn read_journal(path: &Path) -> Result<JournalRead, JournalError> {
    let files = if path.is_dir() {
        segments(path).map_err(|e| JournalError::Io(path.to_path_buf(), e))?
    } else {
        vec![path.to_path_buf()]
    };
    if files.is_empty() {
        return Err(JournalError::Empty(path.to_path_buf()));
    }
    let mut read = JournalRead::default();
    let mut record = 0u64;
    for (fi, file) in files.iter().enumerate() {
        let last_file = fi + 1 == files.len();
        let mut bytes = Vec::new();
        File::open(file)
            .and_then(|mut f| f.read_to_end(&mut bytes))
            .map_err(|e| JournalError::Io(file.clone(), e))?;
        if bytes.len() < MAGIC.len() || &bytes[..MAGIC.len()] != MAGIC {
            if last_file && bytes.len() < MAGIC.len() && MAGIC.starts_with(&bytes) {
                // The crash came while the segment was being created.
                read.torn = Some(Damage {
                    segment: file.clone(),
                    offset: 0,
                    record,
                    what: "segment cut short before its first record".into(),
                });
                break;
            }
            return Err(JournalError::NotAJournal(file.clone()));
        }
        let mut pos = MAGIC.len();
        while pos < bytes.len() {
            let damage = |what: String| Damage {
                segment: file.clone(),
                offset: pos as u64,
                record,
                what,
            };
            let rest = bytes.len() - pos;
            if last_file && all_zero(&bytes[pos..]) {
                // A power loss after the file grew but before its data reached the disk.
                read.torn = Some(damage(format!(
                    "{rest} zero bytes at the end of the segment (space a player reserved and had not written: it still runs, or did not stop in good order; or a power loss before the data reached the disk)"
                )));
                read.unwritten = true;
                return Ok(read);
            }
            if rest < 8 {
                let d = damage(format!("{rest} bytes left, less than a record header"));
                if last_file {
                    read.torn = Some(d);
                } else {
                    read.corrupt = Some(d);
                }
                return Ok(read);
            }
            let len = u32::from_le_bytes(bytes[pos..pos + 4].try_into().unwrap_or_default());
            let crc = u32::from_le_bytes(bytes[pos + 4..pos + 8].try_into().unwrap_or_default());
            let end = pos + 8 + len as usize;
            if len > MAX_RECORD || end > bytes.len() {
                let d = damage(format!(
                    "record of {len} bytes runs past the end of the segment ({} bytes left)",
                    rest - 8
                ));
                if last_file {
                    read.torn = Some(d);
                } else {
                    read.corrupt = Some(d);
                }
                return Ok(read);
            }
            let body = &bytes[pos + 8..end];
            if crc32fast::hash(body) != crc {
                let d = damage("checksum mismatch".into());
                // The last record written, or one whose data only partly reached the disk
                // before a power loss (zeros after it): torn, not damage.
                if last_file && all_zero(&bytes[end..]) {
                    read.torn = Some(d);
                } else {
                    read.corrupt = Some(d);
                }
                return Ok(read);
            }
            match decode_entry(body) {
                Ok(entry) => read.entries.push(entry),
                Err(what) => {
                    read.corrupt = Some(damage(what));
                    return Ok(read);
                }
            }
            pos = end;
            record += 1;
        }
    }
    Ok(read)
}

fn all_zero(bytes: &[u8]) -> bool {
    bytes.iter().all(|&b| b == 0)
}

/// Cuts a torn tail off its segment, so that the journal ends at its last good record before a
/// player writes on (a torn record in a segment that is no longer the last would read as
/// corruption). A segment torn before its first record is removed.
pub fn cut_torn_tail(torn: &Damage) -> std::io::Result<()> {
    if torn.offset < MAGIC.len() as u64 {
        return std::fs::remove_file(&torn.segment);
    }
    let file = OpenOptions::new().write(true).open(&torn.segment)?;
    file.set_len(torn.offset)?;
    file.sync_all()
}

/// The lock file of a journal directory: held (an exclusive `flock`) by the one player that
/// writes there, and holding its vehicle's name and process id.
pub const LOCK_FILE: &str = "petrel.lock";

/// Who holds (or held) a journal directory's lock.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LockOwner {
    /// The vehicle.
    pub vehicle: String,
    /// The player's process id.
    pub pid: u32,
}

impl LockOwner {
    fn parse(text: &str) -> Option<LockOwner> {
        let mut vehicle = None;
        let mut pid = None;
        for line in text.lines() {
            if let Some(v) = line.strip_prefix("vehicle=") {
                vehicle = Some(v.to_string());
            } else if let Some(p) = line.strip_prefix("pid=") {
                pid = p.parse().ok();
            }
        }
        Some(LockOwner {
            vehicle: vehicle?,
            pid: pid?,
        })
    }
}

/// A journal directory could not be locked.
#[derive(Debug)]
pub enum LockError {
    /// Another player writes there.
    InUse {
        /// The journal directory.
        dir: PathBuf,
        /// Who, if its lock file says.
        owner: Option<LockOwner>,
    },
    /// The directory or the lock file could not be created, read or locked.
    Io(PathBuf, std::io::Error),
}

impl std::fmt::Display for LockError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LockError::InUse { dir, owner } => {
                write!(f, "the journal directory {} is in use by ", dir.display())?;
                match owner {
                    Some(o) => write!(f, "the player of vehicle `{}` (pid {})", o.vehicle, o.pid)?,
                    None => write!(f, "another player")?,
                }
                write!(
                    f,
                    ": a journal directory holds one vehicle's mission; give this player another --journal"
                )
            }
            LockError::Io(p, e) => write!(f, "cannot lock {}: {e}", p.display()),
        }
    }
}

impl std::error::Error for LockError {}

/// The exclusive hold of a player on its journal directory ([`LOCK_FILE`]).
///
/// The lock is an `flock` on the lock file, which the kernel releases when the process dies,
/// however it dies; the file itself stays. It names the vehicle and the process once
/// [`claimed`](Self::claim), and is emptied when the hold is dropped in good order: a lock file
/// that still names someone when it is acquired was left by a process that died (a stale
/// lock, [`stale_owner`](Self::stale_owner)).
#[derive(Debug)]
pub struct JournalLock {
    file: File,
    path: PathBuf,
    stale: Option<LockOwner>,
    claimed: bool,
}

impl JournalLock {
    /// Locks journal directory `dir` (created if needed), or says who holds it.
    pub fn acquire(dir: &Path) -> Result<JournalLock, LockError> {
        let io = |e: std::io::Error| LockError::Io(dir.to_path_buf(), e);
        create_dir(dir).map_err(io)?;
        let path = dir.join(LOCK_FILE);
        let mut file = private_file()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(io)?;
        let mut text = String::new();
        match file.try_lock() {
            Ok(()) => {}
            Err(std::fs::TryLockError::WouldBlock) => {
                let _ = file.read_to_string(&mut text);
                return Err(LockError::InUse {
                    dir: dir.to_path_buf(),
                    owner: LockOwner::parse(&text),
                });
            }
            Err(std::fs::TryLockError::Error(e)) => return Err(io(e)),
        }
        // Unreadable content is as good as none: the lock is ours.
        let _ = file.read_to_string(&mut text);
        Ok(JournalLock {
            file,
            path,
            stale: LockOwner::parse(&text),
            claimed: false,
        })
    }

    /// The owner named by a lock file found unlocked: a player that died holding it.
    pub fn stale_owner(&self) -> Option<&LockOwner> {
        self.stale.as_ref()
    }

    /// Writes this process's vehicle and pid into the lock file (until then, a refused player
    /// leaves what the file said untouched).
    pub fn claim(&mut self, vehicle: &str) -> std::io::Result<()> {
        let text = format!("vehicle={vehicle}\npid={}\n", std::process::id());
        self.file.set_len(0)?;
        self.file.write_all_at(text.as_bytes(), 0)?;
        self.file.sync_data()?;
        self.claimed = true;
        Ok(())
    }

    /// The lock file.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for JournalLock {
    fn drop(&mut self) {
        if self.claimed {
            // Released in good order: an empty lock file is nobody's.
            let _ = self.file.set_len(0);
        }
    }
}

/// The header of a journal directory's first segment, if it has one that reads.
pub fn first_header(dir: &Path) -> Option<Entry> {
    let first = segments(dir).ok()?.into_iter().next()?;
    let mut file = File::open(first).ok()?;
    let mut head = [0u8; 16];
    file.read_exact(&mut head).ok()?;
    if &head[..8] != MAGIC {
        return None;
    }
    let len = u32::from_le_bytes(head[8..12].try_into().ok()?);
    if len > MAX_RECORD {
        return None;
    }
    let crc = u32::from_le_bytes(head[12..16].try_into().ok()?);
    let mut body = vec![0u8; len as usize];
    file.read_exact(&mut body).ok()?;
    if crc32fast::hash(&body) != crc {
        return None;
    }
    match decode_entry(&body) {
        Ok(header @ Entry::Header { .. }) => Some(header),
        _ => None,
    }
}

/// A stable digest of a compiled project (FNV-1a over its debug text), so a journal is only
/// replayed with the project it recorded.
pub fn project_digest(p: &petrel_nets::compiled::CompiledProject) -> u64 {
    let text = format!("{p:?}");
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in text.bytes() {
        h ^= b as u64;
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    h
}

#[cfg(test)]
mod tests;
