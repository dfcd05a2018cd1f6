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
//! length reached the disk before its data. A bad checksum anywhere else is *corruption*: an
//! error that names the segment, the offset and the record. `petrel play --resume` cuts a torn
//! tail off ([`cut_torn_tail`]) before it writes on, so that it never becomes corruption in the
//! middle of the journal.
//!
//! Decoding is bounded: a record's body is decoded with a bincode limit proportional to its own
//! length ([`decode_entry`]), so a body with a valid checksum that claims a vector of 2^61
//! elements or a string of 2^40 bytes is refused as an undecodable record, never a panic or an
//! allocation the machine cannot make.

use bincode::{Decode, Encode};
use petrel_nets::compiled::Value;
use std::fs::{File, OpenOptions};
use std::io::{BufWriter, Read, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

const MAGIC: &[u8; 8] = b"PETRELJ1";
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
/// [`CLAIM_PER_BYTE`] times the body's length (rounded up to a power of two, at least 4 KiB):
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

/// One journal entry.
#[derive(Clone, Debug, PartialEq, Encode, Decode)]
pub enum Entry {
    /// The first entry of every segment: what was recorded, and with which project.
    Header {
        /// Format version (1).
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
            | Entry::Step { time, .. } => Some(*time),
        }
    }
}

/// When records reach the disk.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FlushPolicy {
    /// Written to the operating system after every record (survives a crash of the player, not
    /// of the machine).
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
pub struct JournalWriter {
    dir: PathBuf,
    policy: FlushPolicy,
    rotate_bytes: u64,
    header: Entry,
    out: BufWriter<File>,
    segment: u32,
    segment_bytes: u64,
    last_flush: Instant,
    dirty: bool,
    buf: Vec<u8>,
    /// Records written.
    pub records: u64,
    /// Time spent writing (encoding, checksumming, writing, flushing).
    pub busy: Duration,
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

impl JournalWriter {
    /// Starts a journal in `dir` (created if needed), after any segments already there, and
    /// writes `header` first.
    pub fn open(
        dir: &Path,
        header: Entry,
        policy: FlushPolicy,
        rotate_bytes: u64,
    ) -> std::io::Result<JournalWriter> {
        std::fs::create_dir_all(dir)?;
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
        let out = Self::new_segment(dir, next)?;
        let mut w = JournalWriter {
            dir: dir.to_path_buf(),
            policy,
            rotate_bytes: rotate_bytes.max(4096),
            header: header.clone(),
            out,
            segment: next,
            segment_bytes: MAGIC.len() as u64,
            last_flush: Instant::now(),
            dirty: false,
            buf: Vec::with_capacity(4096),
            records: 0,
            busy: Duration::ZERO,
        };
        w.append(&header)?;
        w.flush()?;
        Ok(w)
    }

    fn new_segment(dir: &Path, n: u32) -> std::io::Result<BufWriter<File>> {
        let file = OpenOptions::new()
            .create_new(true)
            .write(true)
            .open(segment_path(dir, n))?;
        let mut out = BufWriter::with_capacity(64 << 10, file);
        out.write_all(MAGIC)?;
        Ok(out)
    }

    /// Appends one entry and flushes according to the policy.
    pub fn append(&mut self, entry: &Entry) -> std::io::Result<()> {
        let started = Instant::now();
        self.buf.clear();
        bincode::encode_into_std_write(entry, &mut self.buf, bincode::config::standard())
            .map_err(std::io::Error::other)?;
        if self.segment_bytes + 8 + self.buf.len() as u64 > self.rotate_bytes
            && !matches!(entry, Entry::Header { .. })
        {
            self.rotate()?;
            // Re-encode: rotate() used the buffer for the new segment's header.
            self.buf.clear();
            bincode::encode_into_std_write(entry, &mut self.buf, bincode::config::standard())
                .map_err(std::io::Error::other)?;
        }
        let crc = crc32fast::hash(&self.buf);
        self.out.write_all(&(self.buf.len() as u32).to_le_bytes())?;
        self.out.write_all(&crc.to_le_bytes())?;
        self.out.write_all(&self.buf)?;
        self.segment_bytes += 8 + self.buf.len() as u64;
        self.records += 1;
        self.dirty = true;
        match self.policy {
            FlushPolicy::EveryRecord => self.flush()?,
            FlushPolicy::Sync => {
                self.flush()?;
                self.out.get_ref().sync_data()?;
            }
            FlushPolicy::Interval(p) => {
                if self.last_flush.elapsed() >= p {
                    self.flush()?;
                }
            }
        }
        self.busy += started.elapsed();
        Ok(())
    }

    /// Hands everything written so far to the operating system.
    pub fn flush(&mut self) -> std::io::Result<()> {
        if self.dirty {
            self.out.flush()?;
            self.dirty = false;
        }
        self.last_flush = Instant::now();
        Ok(())
    }

    fn rotate(&mut self) -> std::io::Result<()> {
        self.flush()?;
        if self.policy == FlushPolicy::Sync {
            self.out.get_ref().sync_data()?;
        }
        self.segment += 1;
        self.out = Self::new_segment(&self.dir, self.segment)?;
        self.segment_bytes = MAGIC.len() as u64;
        let header = self.header.clone();
        self.append(&header)
    }

    /// The directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }
}

/// The journal of a running player: a writer, or none (`--no-journal`). A failure to write is
/// logged loudly and counted but never stops the player: a vehicle must keep flying.
pub struct Journal {
    writer: Option<JournalWriter>,
    /// Entries that could not be written or flushed.
    pub failures: u64,
    /// Whether an entry failed since the last [`flush`](Self::flush).
    missed: bool,
}

impl Journal {
    /// A journal writing through `writer`, if any.
    pub fn new(writer: Option<JournalWriter>) -> Self {
        Journal {
            writer,
            failures: 0,
            missed: false,
        }
    }

    /// Appends one entry (if there is a journal).
    pub fn append(&mut self, entry: &Entry) {
        if let Some(w) = self.writer.as_mut() {
            if let Err(e) = w.append(entry) {
                self.failures += 1;
                self.missed = true;
                tracing::error!(error = %e, "journal write failed: the flight recorder is missing this entry");
            }
        }
    }

    /// Hands everything written to the operating system; true when everything appended since
    /// the last flush is on record (or there is no journal).
    pub fn flush(&mut self) -> bool {
        if let Some(w) = self.writer.as_mut() {
            if let Err(e) = w.flush() {
                self.failures += 1;
                self.missed = true;
                tracing::error!(error = %e, "journal flush failed");
            }
        }
        !std::mem::take(&mut self.missed)
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
                    "{rest} zero bytes at the end of the segment (a power loss before the data reached the disk)"
                )));
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
