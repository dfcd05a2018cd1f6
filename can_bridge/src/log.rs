//! The `candump -L` log format: recording the bus and reading a recording back.
//!
//! ```text
//! (1700000000.123456) vcan0 123#DEADBEEF          classic data frame, standard identifier
//! (1700000000.123789) vcan0 18FF0100#0102         extended identifier (eight digits)
//! (1700000000.124000) vcan0 123##1AABBCCDD        CAN FD: flags nibble (BRS 1, ESI 2, FD 4), data
//! (1700000000.125000) vcan0 123#R                 remote frame (`#R3`: requesting 3 bytes)
//! (1700000000.126000) vcan0 20000040#0000000000000000   error frame (the 0x20000000 flag)
//! (1700000000.127000) vcan0 123#1122334455667788_C      8-byte frame with a len8 DLC
//! ```
//!
//! The grammar is can-utils' (`lib.h`, `parse_canframe`): three hex digits are a standard
//! identifier, eight an extended one or, with the `0x20000000` flag, an error frame; the
//! timestamp has exactly six decimals; `candump -x` may append a direction, `R` or `T`. Blank
//! lines are skipped; anything else that does not read is an error with its line number, never
//! a skipped line.

use std::fmt::{self, Write as _};
use std::io::{self, BufRead, Write};

use crate::frame::{err, CanId, Frame, FrameKind, CANFD_MAX_LEN, CAN_MAX_LEN, EFF_MAX};

/// Which way a logged frame went (`candump -x`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Direction {
    /// Received (`R`).
    Received,
    /// Transmitted (`T`).
    Transmitted,
}

/// One line of a log.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LogRecord {
    /// Microseconds since the Unix epoch (or whatever clock the recorder used).
    pub time_us: u64,
    /// The interface name (`vcan0`, `can0`, `mem0`).
    pub interface: String,
    /// The frame.
    pub frame: Frame,
    /// The direction, if the line has one.
    pub direction: Option<Direction>,
}

/// What is wrong with a log line.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum LogLineError {
    /// The line does not start with `(seconds.microseconds)`.
    Timestamp(String),
    /// No interface name after the timestamp.
    MissingInterface,
    /// No frame after the interface name.
    MissingFrame,
    /// Something after the frame other than `R` or `T`.
    TrailingText(String),
    /// The frame has no `#`.
    MissingSeparator(String),
    /// The identifier is not 3 or 8 hex digits, or does not fit its width.
    Identifier(String),
    /// The data is not an even number of hex digits, or too long for the frame.
    Data(String),
    /// A remote frame's DLC is not one hex digit from 0 to 8.
    RemoteDlc(String),
    /// A CAN FD frame's flags are not one hex digit, or its length is not a CAN FD length.
    Fd(String),
    /// A `_X` len8 DLC that is not 9 to F, or on a frame that is not 8 bytes of data.
    Len8Dlc(String),
}

impl fmt::Display for LogLineError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LogLineError::Timestamp(t) => write!(
                f,
                "`{t}` is not a timestamp; a line starts with (seconds.microseconds), six decimals"
            ),
            LogLineError::MissingInterface => {
                f.write_str("no interface name after the timestamp")
            }
            LogLineError::MissingFrame => f.write_str("no frame after the interface name"),
            LogLineError::TrailingText(t) => write!(
                f,
                "unexpected `{t}` after the frame; only a direction R or T may follow"
            ),
            LogLineError::MissingSeparator(t) => {
                write!(f, "`{t}` is not a frame: ID#DATA, ID##FLAGSDATA or ID#R")
            }
            LogLineError::Identifier(t) => write!(
                f,
                "`{t}` is not an identifier: 3 hex digits (standard) or 8 (extended or error)"
            ),
            LogLineError::Data(t) => write!(
                f,
                "`{t}` is not frame data: pairs of hex digits, at most 8 bytes (64 for CAN FD)"
            ),
            LogLineError::RemoteDlc(t) => {
                write!(f, "`{t}` is not a remote frame's length: one digit, 0 to 8")
            }
            LogLineError::Fd(t) => write!(
                f,
                "`{t}` is not CAN FD data: one flags digit, then 0 to 8, 12, 16, 20, 24, 32, 48 or 64 bytes"
            ),
            LogLineError::Len8Dlc(t) => write!(
                f,
                "`{t}` is not a len8 DLC: `_9` to `_F`, after exactly 8 bytes of data"
            ),
        }
    }
}

/// A log could not be read.
#[derive(Debug)]
pub enum LogError {
    /// Line `line` (1-based) is malformed.
    Line {
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        error: LogLineError,
    },
    /// Reading failed.
    Io(io::Error),
}

impl fmt::Display for LogError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LogError::Line { line, error } => write!(f, "line {line}: {error}"),
            LogError::Io(e) => write!(f, "cannot read the log: {e}"),
        }
    }
}

impl std::error::Error for LogError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            LogError::Io(e) => Some(e),
            LogError::Line { .. } => None,
        }
    }
}

fn hex_digit(c: u8) -> Option<u8> {
    match c {
        b'0'..=b'9' => Some(c - b'0'),
        b'a'..=b'f' => Some(c - b'a' + 10),
        b'A'..=b'F' => Some(c - b'A' + 10),
        _ => None,
    }
}

fn hex_bytes(s: &str, max: usize) -> Option<Vec<u8>> {
    let b = s.as_bytes();
    if !b.len().is_multiple_of(2) || b.len() / 2 > max {
        return None;
    }
    b.chunks(2)
        .map(|p| Some(hex_digit(p[0])? << 4 | hex_digit(p[1])?))
        .collect()
}

fn parse_timestamp(t: &str) -> Option<u64> {
    let inner = t.strip_prefix('(')?.strip_suffix(')')?;
    let (secs, micros) = inner.split_once('.')?;
    if secs.is_empty()
        || micros.len() != 6
        || !secs.bytes().all(|c| c.is_ascii_digit())
        || !micros.bytes().all(|c| c.is_ascii_digit())
    {
        return None;
    }
    let secs: u64 = secs.parse().ok()?;
    let micros: u64 = micros.parse().ok()?;
    secs.checked_mul(1_000_000)?.checked_add(micros)
}

/// Parses the frame part of a line (`123#DEADBEEF`, `123##1AABB`, `123#R`...).
pub fn parse_frame(s: &str) -> Result<Frame, LogLineError> {
    let (id_text, rest) = s
        .split_once('#')
        .ok_or_else(|| LogLineError::MissingSeparator(s.to_owned()))?;
    let id_err = || LogLineError::Identifier(id_text.to_owned());
    if !id_text.bytes().all(|c| hex_digit(c).is_some()) {
        return Err(id_err());
    }
    let value = u32::from_str_radix(id_text, 16).map_err(|_| id_err())?;
    let id = match id_text.len() {
        3 => CanId::standard(value).ok_or_else(id_err)?,
        8 if value & err::FLAG != 0 => {
            // An error frame: the class bits; the data are its 8 detail bytes.
            let class = value & !err::FLAG;
            if class > EFF_MAX {
                return Err(id_err());
            }
            let data =
                hex_bytes(rest, CAN_MAX_LEN).ok_or_else(|| LogLineError::Data(rest.to_owned()))?;
            let mut detail = [0u8; 8];
            detail[..data.len()].copy_from_slice(&data);
            return Frame::error(class, detail).map_err(|_| id_err());
        }
        8 => CanId::extended(value).ok_or_else(id_err)?,
        _ => return Err(id_err()),
    };
    if let Some(fd) = rest.strip_prefix('#') {
        let fd_err = || LogLineError::Fd(fd.to_owned());
        let mut chars = fd.bytes();
        let flags = chars.next().and_then(hex_digit).ok_or_else(fd_err)?;
        let data = hex_bytes(&fd[1..], CANFD_MAX_LEN).ok_or_else(fd_err)?;
        return Frame::fd(id, &data, flags).map_err(|_| fd_err());
    }
    if let Some(dlc) = rest.strip_prefix('R') {
        let dlc_err = || LogLineError::RemoteDlc(dlc.to_owned());
        let n = match dlc.as_bytes() {
            [] => 0,
            [c] => hex_digit(*c).filter(|d| *d <= 8).ok_or_else(dlc_err)?,
            _ => return Err(dlc_err()),
        };
        return Frame::remote(id, n).map_err(|_| dlc_err());
    }
    let (data_text, len8) = match rest.split_once('_') {
        Some((d, l)) => (d, Some(l)),
        None => (rest, None),
    };
    let data =
        hex_bytes(data_text, CAN_MAX_LEN).ok_or_else(|| LogLineError::Data(rest.to_owned()))?;
    let frame = Frame::data(id, &data).map_err(|_| LogLineError::Data(rest.to_owned()))?;
    match len8 {
        None => Ok(frame),
        Some(l) => {
            let l_err = || LogLineError::Len8Dlc(l.to_owned());
            let dlc = match l.as_bytes() {
                [c] => hex_digit(*c).filter(|d| *d >= 9).ok_or_else(l_err)?,
                _ => return Err(l_err()),
            };
            if data.len() != 8 {
                return Err(l_err());
            }
            Ok(frame.with_len8_dlc(dlc))
        }
    }
}

/// Parses one line of a `candump -L` log.
pub fn parse_line(line: &str) -> Result<LogRecord, LogLineError> {
    let mut fields = line.split_whitespace();
    let ts = fields.next().unwrap_or("");
    let time_us = parse_timestamp(ts).ok_or_else(|| LogLineError::Timestamp(ts.to_owned()))?;
    let interface = fields.next().ok_or(LogLineError::MissingInterface)?;
    let frame = parse_frame(fields.next().ok_or(LogLineError::MissingFrame)?)?;
    let direction = match fields.next() {
        None => None,
        Some("R" | "r") => Some(Direction::Received),
        Some("T" | "t") => Some(Direction::Transmitted),
        Some(other) => return Err(LogLineError::TrailingText(other.to_owned())),
    };
    if let Some(extra) = fields.next() {
        return Err(LogLineError::TrailingText(extra.to_owned()));
    }
    Ok(LogRecord {
        time_us,
        interface: interface.to_owned(),
        frame,
        direction,
    })
}

// A frame prints as its candump text, which this module owns; the impls are here so that
// `frame` stays below `log`.
impl fmt::Debug for Frame {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Frame({})", format_frame(self))
    }
}

impl fmt::Display for Frame {
    /// The frame as candump writes it: `123#DEADBEEF`, `123##1AABB`, `123#R`...
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&format_frame(self))
    }
}

/// The frame as candump writes it.
pub fn format_frame(frame: &Frame) -> String {
    let mut s = String::with_capacity(24 + 2 * frame.len());
    let hex = |s: &mut String, data: &[u8]| {
        for b in data {
            let _ = write!(s, "{b:02X}");
        }
    };
    match frame.kind() {
        FrameKind::Error => {
            let _ = write!(s, "{:08X}#", frame.error_class() | err::FLAG);
            hex(&mut s, frame.payload());
        }
        FrameKind::Remote => {
            let _ = write!(s, "{}#R", frame.id());
            if !frame.is_empty() {
                let _ = write!(s, "{}", frame.len());
            }
        }
        FrameKind::Fd { flags } => {
            let _ = write!(s, "{}##{:X}", frame.id(), flags & 0x0F);
            hex(&mut s, frame.payload());
        }
        FrameKind::Data => {
            let _ = write!(s, "{}#", frame.id());
            hex(&mut s, frame.payload());
            if let Some(dlc) = frame.len8_dlc() {
                let _ = write!(s, "_{dlc:X}");
            }
        }
    }
    s
}

/// One record as a log line (without the newline).
pub fn format_record(r: &LogRecord) -> String {
    let mut s = format!(
        "({}.{:06}) {} {}",
        r.time_us / 1_000_000,
        r.time_us % 1_000_000,
        r.interface,
        format_frame(&r.frame)
    );
    match r.direction {
        Some(Direction::Received) => s.push_str(" R"),
        Some(Direction::Transmitted) => s.push_str(" T"),
        None => {}
    }
    s
}

/// Reads a log line by line.
#[derive(Debug)]
pub struct LogReader<R> {
    input: R,
    line: usize,
    buf: String,
}

impl<R: BufRead> LogReader<R> {
    /// Reads from `input`.
    pub fn new(input: R) -> Self {
        LogReader {
            input,
            line: 0,
            buf: String::new(),
        }
    }
}

impl<R> LogReader<R> {
    /// The 1-based number of the line last read (0 before the first).
    pub fn line(&self) -> usize {
        self.line
    }
}

impl<R: BufRead> Iterator for LogReader<R> {
    type Item = Result<LogRecord, LogError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            self.buf.clear();
            match self.input.read_line(&mut self.buf) {
                Ok(0) => return None,
                Ok(_) => {}
                Err(e) => return Some(Err(LogError::Io(e))),
            }
            self.line += 1;
            let text = self.buf.trim();
            if text.is_empty() {
                continue;
            }
            return Some(parse_line(text).map_err(|error| LogError::Line {
                line: self.line,
                error,
            }));
        }
    }
}

/// Reads a whole log held in memory; the first malformed line is the error.
pub fn read_log(text: &str) -> Result<Vec<LogRecord>, LogError> {
    LogReader::new(text.as_bytes()).collect()
}

/// Reads a whole log held in memory, each record with its 1-based line number (for warnings
/// that name the line); the first malformed line is the error.
pub fn read_log_lines(text: &str) -> Result<Vec<(usize, LogRecord)>, LogError> {
    let mut reader = LogReader::new(text.as_bytes());
    let mut out = Vec::new();
    while let Some(r) = reader.next() {
        out.push((reader.line(), r?));
    }
    Ok(out)
}

/// Writes records as log lines.
#[derive(Debug)]
pub struct LogWriter<W> {
    out: W,
    written: u64,
}

impl<W: Write> LogWriter<W> {
    /// Writes to `out` (wrap a file in a `BufWriter`).
    pub fn new(out: W) -> Self {
        LogWriter { out, written: 0 }
    }

    /// Writes one record.
    pub fn write(&mut self, r: &LogRecord) -> io::Result<()> {
        writeln!(self.out, "{}", format_record(r))?;
        self.written += 1;
        Ok(())
    }

    /// Writes a frame received or sent at `time_us` on `interface`.
    pub fn write_frame(&mut self, time_us: u64, interface: &str, frame: &Frame) -> io::Result<()> {
        writeln!(
            self.out,
            "({}.{:06}) {} {}",
            time_us / 1_000_000,
            time_us % 1_000_000,
            interface,
            format_frame(frame)
        )?;
        self.written += 1;
        Ok(())
    }

    /// Records written.
    pub fn written(&self) -> u64 {
        self.written
    }

    /// Flushes the output.
    pub fn flush(&mut self) -> io::Result<()> {
        self.out.flush()
    }

    /// The output back.
    pub fn into_inner(self) -> W {
        self.out
    }
}
