//! DBC: what the vehicle's frames hold, and decoding and encoding them.
//!
//! [`Dbc::parse`] reads a DBC file with the `can-dbc` crate and checks it (every signal fits in
//! its frame, sizes of 1 to 64 bits, a non-zero factor, unique identifiers and names, simple
//! multiplexing only); what the file means is then ours, with the semantics of cantools:
//!
//! - **Bit layout.** A little-endian (Intel, `@1`) signal's start bit is its least significant
//!   bit, bit `i` of the frame being bit `i % 8` of byte `i / 8`. A big-endian (Motorola, `@0`)
//!   signal's start bit is its **most** significant bit in that same numbering; its following
//!   bits run down to bit 0 of the byte, then on from bit 7 of the next byte.
//! - **Values.** `physical = raw * factor + offset` (for integer signals rounded to the decimal
//!   places of the factor and offset, so that 549 * 0.01 - 5 reads 0.49), `raw` read as unsigned, or as two's
//!   complement when the signal is signed (`-`), or as an IEEE float (`SIG_VALTYPE_`).
//! - **Ranges.** Encoding refuses a physical value outside `[min, max]` and a raw value that
//!   does not fit in the signal's bits: an error naming the signal, never a clamp. A range of
//!   `[0|0]` means "none given" (as DBC editors write it); the raw bits still bound the value.
//! - **Value tables** (`VAL_`) name raw values ([`Signal::label`], [`Signal::value_of`]).
//! - **Multiplexing.** A message may have one multiplexor switch (`M`); a signal `mN` is in the
//!   frame only when the switch holds `N`.
//! - **Cycle time.** The `GenMsgCycleTime` attribute of a message (or its default), in
//!   milliseconds; 0 or absent means the message is not periodic.
//!
//! Decoding never fails on a frame: an identifier the DBC does not know, a length other than
//! the DBC's, a remote or error frame are [`DecodeOutcome`]s for the caller to count and log.

use std::collections::HashMap;
use std::fmt;
use std::path::Path;

use can_dbc::{AttributeValue, MultiplexIndicator, NumericValue, SignalExtendedValueType};

use crate::frame::{is_fd_len, CanId, Frame, FrameError, FrameKind, CANFD_MAX_LEN, CAN_MAX_LEN};

/// Index of a message in [`Dbc::messages`].
pub type MessageId = usize;

/// A signal: its message and its index in [`Message::signals`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct SignalRef {
    /// Index of the message in [`Dbc::messages`].
    pub message: MessageId,
    /// Index of the signal in the message's [`Message::signals`].
    pub signal: usize,
}

/// Byte order of a signal.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ByteOrder {
    /// Intel (`@1`): the start bit is the least significant bit.
    LittleEndian,
    /// Motorola (`@0`): the start bit is the most significant bit.
    BigEndian,
}

/// How a signal's raw bits are read.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ValueKind {
    /// An unsigned integer (`+`).
    Unsigned,
    /// A two's complement integer (`-`).
    Signed,
    /// An IEEE 754 single (`SIG_VALTYPE_ ... : 1`, 32 bits).
    Float32,
    /// An IEEE 754 double (`SIG_VALTYPE_ ... : 2`, 64 bits).
    Float64,
}

/// A signal's part in multiplexing.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Mux {
    /// Always in the frame.
    Plain,
    /// The multiplexor switch (`M`).
    Switch,
    /// In the frame only when the switch holds this value (`mN`).
    Multiplexed(u64),
}

/// A signal of a message.
#[derive(Clone, Debug, PartialEq)]
pub struct Signal {
    /// Name, unique in its message.
    pub name: String,
    /// Start bit (see the module documentation for the two byte orders).
    pub start_bit: u32,
    /// Size in bits, 1 to 64.
    pub size: u32,
    /// Byte order.
    pub byte_order: ByteOrder,
    /// How the raw bits are read.
    pub kind: ValueKind,
    /// Scale of the raw value; never zero.
    pub factor: f64,
    /// Offset of the physical value.
    pub offset: f64,
    /// Smallest physical value, if the DBC gives a range (not `[0|0]`).
    pub min: Option<f64>,
    /// Largest physical value, if the DBC gives a range.
    pub max: Option<f64>,
    /// Unit, as written.
    pub unit: String,
    /// Multiplexing.
    pub mux: Mux,
    /// Value table: raw value and its name, in written order.
    pub choices: Vec<(i64, String)>,
    /// Physical value of the `GenSigStartValue` attribute (given raw in the DBC), if any.
    pub start_value: Option<f64>,
    /// Bit positions in the frame, in the linear numbering of the layout (see [`Self::bits`]).
    first_bit: u32,
    /// `10^d` for the `d` decimal places of the physical values of an integer signal (those
    /// of its factor and offset, when they have some), to which they are rounded: 549 * 0.01
    /// - 5 is 0.49, not 0.4900000000000002. Computed once, at load.
    round_scale: Option<f64>,
}

/// The decimal places of `x` when it has at most nine.
fn decimal_places(x: f64) -> Option<i32> {
    (0..=9).find(|&d| {
        let scaled = x * 10f64.powi(d);
        (scaled - scaled.round()).abs() <= 1e-9 * scaled.abs().max(1.0)
    })
}

impl Signal {
    /// The name of raw value `raw` in the signal's value table.
    pub fn label(&self, raw: i128) -> Option<&str> {
        self.choices
            .iter()
            .find(|(v, _)| i128::from(*v) == raw)
            .map(|(_, n)| n.as_str())
    }

    /// The physical value of the value-table entry `label`.
    pub fn value_of(&self, label: &str) -> Option<f64> {
        self.choices
            .iter()
            .find(|(_, n)| n == label)
            .map(|(v, _)| *v as f64 * self.factor + self.offset)
    }

    /// The raw value of the value-table entry `label`.
    pub fn raw_of(&self, label: &str) -> Option<i64> {
        self.choices
            .iter()
            .find(|(_, n)| n == label)
            .map(|(v, _)| *v)
    }

    /// True for an integer signal whose physical values are all integers (integral factor and
    /// offset): its value can be an `int` parameter.
    pub fn is_integral(&self) -> bool {
        matches!(self.kind, ValueKind::Signed | ValueKind::Unsigned)
            && self.factor.fract() == 0.0
            && self.offset.fract() == 0.0
    }

    /// The smallest and largest raw values the bits hold (for floats, the float's range).
    pub fn raw_bounds(&self) -> (f64, f64) {
        match self.kind {
            ValueKind::Unsigned => (0.0, (2f64).powi(self.size as i32) - 1.0),
            ValueKind::Signed => {
                let half = (2f64).powi(self.size as i32 - 1);
                (-half, half - 1.0)
            }
            ValueKind::Float32 => (f64::from(f32::MIN), f64::from(f32::MAX)),
            ValueKind::Float64 => (f64::MIN, f64::MAX),
        }
    }

    /// The range of physical values the signal can take: the DBC's `[min, max]` if given,
    /// else what the raw bits hold.
    pub fn physical_bounds(&self) -> (f64, f64) {
        if let (Some(lo), Some(hi)) = (self.min, self.max) {
            return (lo, hi);
        }
        let (lo, hi) = self.raw_bounds();
        let (a, b) = (
            lo * self.factor + self.offset,
            hi * self.factor + self.offset,
        );
        (a.min(b), a.max(b))
    }

    /// The positions of the signal's bits, most significant first, as (byte, bit in byte).
    pub fn bits(&self) -> impl Iterator<Item = (usize, u8)> + '_ {
        let size = self.size;
        let first = self.first_bit;
        let order = self.byte_order;
        (0..size).map(move |i| match order {
            // Linear numbering from the least significant bit: position first + (size-1-i).
            ByteOrder::LittleEndian => {
                let p = first + (size - 1 - i);
                ((p / 8) as usize, (p % 8) as u8)
            }
            // Linear numbering from bit 7 of byte 0: position first + i.
            ByteOrder::BigEndian => {
                let p = first + i;
                ((p / 8) as usize, (7 - p % 8) as u8)
            }
        })
    }

    /// The bytes the signal needs: one past the last byte it touches.
    pub fn bytes_needed(&self) -> usize {
        self.bits().map(|(b, _)| b + 1).max().unwrap_or(0)
    }

    /// Reads the raw bits from `data`, zero-extended (bits beyond `data` read as 0).
    pub fn extract_bits(&self, data: &[u8]) -> u64 {
        self.bits().fold(0u64, |acc, (byte, bit)| {
            let b = data.get(byte).map_or(0, |v| (v >> bit) & 1);
            (acc << 1) | u64::from(b)
        })
    }

    /// Writes the low `size` bits of `raw` into `data` (bits beyond `data` are ignored).
    pub fn insert_bits(&self, data: &mut [u8], raw: u64) {
        let size = self.size;
        for (i, (byte, bit)) in self.bits().enumerate() {
            let v = raw.checked_shr(size - 1 - i as u32).unwrap_or(0) & 1;
            if let Some(b) = data.get_mut(byte) {
                *b = (*b & !(1 << bit)) | ((v as u8) << bit);
            }
        }
    }

    /// The raw value of the bits: sign-extended for a signed signal; the bits themselves for a
    /// float.
    pub fn raw_from_bits(&self, bits: u64) -> i128 {
        match self.kind {
            ValueKind::Signed if (1..64).contains(&self.size) => {
                let shift = 64 - self.size;
                i128::from(((bits << shift) as i64) >> shift)
            }
            ValueKind::Signed => i128::from(bits as i64),
            _ => i128::from(bits),
        }
    }

    /// The physical value of raw bits.
    pub fn physical_from_bits(&self, bits: u64) -> f64 {
        let base = match self.kind {
            ValueKind::Unsigned => bits as f64,
            ValueKind::Signed => self.raw_from_bits(bits) as f64,
            ValueKind::Float32 => f64::from(f32::from_bits(bits as u32)),
            ValueKind::Float64 => f64::from_bits(bits),
        };
        let value = base * self.factor + self.offset;
        match self.round_scale {
            // Beyond 2^53 / scale the rounding would lose more than it fixes.
            Some(scale) if (value * scale).abs() < 9.0e15 => (value * scale).round() / scale,
            _ => value,
        }
    }

    /// The raw bits of a physical value, or why it cannot be encoded (range, representation).
    pub fn bits_from_physical(&self, value: f64) -> Result<u64, ValueError> {
        if !value.is_finite() {
            return Err(ValueError::NotFinite);
        }
        if let (Some(lo), Some(hi)) = (self.min, self.max) {
            let tol = 1e-9 * lo.abs().max(hi.abs()).max(1.0);
            if value < lo - tol || value > hi + tol {
                return Err(ValueError::OutOfRange { min: lo, max: hi });
            }
        }
        let scaled = (value - self.offset) / self.factor;
        match self.kind {
            ValueKind::Float32 => {
                let f = scaled as f32;
                if !f.is_finite() {
                    return Err(ValueError::NotRepresentable { raw: scaled });
                }
                Ok(u64::from(f.to_bits()))
            }
            ValueKind::Float64 => {
                if !scaled.is_finite() {
                    return Err(ValueError::NotRepresentable { raw: scaled });
                }
                Ok(scaled.to_bits())
            }
            ValueKind::Unsigned | ValueKind::Signed => {
                let raw = scaled.round();
                let (lo, hi) = self.raw_bounds();
                if !raw.is_finite() || raw < lo || raw > hi {
                    return Err(ValueError::NotRepresentable { raw });
                }
                // In range: the conversion is exact for |raw| < 2^63, and saturates only at
                // the 64-bit bounds themselves.
                let bits = if self.kind == ValueKind::Signed {
                    raw as i64 as u64
                } else {
                    raw as u64
                };
                Ok(match 1u64.checked_shl(self.size) {
                    Some(top) if self.size < 64 => bits & (top - 1),
                    _ => bits,
                })
            }
        }
    }
}

/// Why a physical value cannot be put in a signal.
#[derive(Clone, Debug, PartialEq)]
pub enum ValueError {
    /// NaN or infinite.
    NotFinite,
    /// Outside the DBC's `[min, max]`.
    OutOfRange {
        /// The DBC's minimum.
        min: f64,
        /// The DBC's maximum.
        max: f64,
    },
    /// The raw value `(value - offset) / factor` does not fit in the signal's bits.
    NotRepresentable {
        /// The raw value it would need.
        raw: f64,
    },
}

/// A message (frame layout) of the DBC.
#[derive(Clone, Debug, PartialEq)]
pub struct Message {
    /// Name, unique in the DBC.
    pub name: String,
    /// Identifier.
    pub id: CanId,
    /// Payload length in bytes (the DLC's length); frames of another length are refused.
    pub size: usize,
    /// The sending node, if named.
    pub transmitter: Option<String>,
    /// `GenMsgCycleTime` in milliseconds, if the message is periodic.
    pub cycle_time_ms: Option<u64>,
    /// Signals, in written order.
    pub signals: Vec<Signal>,
    /// Index of the multiplexor switch in `signals`, if any.
    pub multiplexor: Option<usize>,
}

impl Message {
    /// The signal named `name`.
    pub fn signal_index(&self, name: &str) -> Option<usize> {
        self.signals.iter().position(|s| s.name == name)
    }

    /// True when frames of this message are CAN FD frames (more than 8 bytes).
    pub fn is_fd(&self) -> bool {
        self.size > CAN_MAX_LEN
    }
}

/// A DBC file could not be read or is not usable.
#[derive(Clone, Debug, PartialEq)]
pub struct DbcError {
    /// What is wrong.
    pub kind: DbcErrorKind,
    /// Byte offset in the DBC text the error is about, when known.
    pub offset: Option<usize>,
}

/// What is wrong with a DBC file.
#[derive(Clone, Debug, PartialEq)]
pub enum DbcErrorKind {
    /// The file could not be read.
    Io(String),
    /// can-dbc could not parse the text.
    Syntax(String),
    /// A message longer than 64 bytes.
    MessageTooLong {
        /// The message.
        message: String,
        /// Its size.
        size: u64,
    },
    /// Two messages with one identifier.
    DuplicateId {
        /// The identifier.
        id: CanId,
        /// The first message.
        first: String,
        /// The second.
        second: String,
    },
    /// Two messages with one name.
    DuplicateMessage(String),
    /// Two signals of a message with one name.
    DuplicateSignal {
        /// The message.
        message: String,
        /// The signal.
        signal: String,
    },
    /// A signal of 0 or more than 64 bits, or a float signal of another size than 32 or 64.
    BadSize {
        /// The message.
        message: String,
        /// The signal.
        signal: String,
        /// Its size.
        size: u64,
    },
    /// A signal with a factor of zero (or not finite), which no value can be encoded with.
    BadFactor {
        /// The message.
        message: String,
        /// The signal.
        signal: String,
    },
    /// A signal whose bits do not all lie in its message's bytes.
    OutsideFrame {
        /// The message.
        message: String,
        /// The signal.
        signal: String,
        /// Bytes the signal needs.
        needs: usize,
        /// Bytes of the message.
        size: usize,
    },
    /// Extended multiplexing (several switches, `SG_MUL_VAL_`, `mNM`), or a multiplexed
    /// signal in a message without a switch.
    UnsupportedMultiplexing {
        /// The message.
        message: String,
    },
}

impl fmt::Display for DbcError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use DbcErrorKind as K;
        match &self.kind {
            K::Io(e) => write!(f, "cannot read the DBC file: {e}"),
            K::Syntax(e) => write!(f, "the DBC file does not parse: {e}"),
            K::MessageTooLong { message, size } => write!(
                f,
                "message `{message}` is {size} bytes long; a CAN frame holds at most 64"
            ),
            K::DuplicateId { id, first, second } => write!(
                f,
                "messages `{first}` and `{second}` have the same identifier {id}"
            ),
            K::DuplicateMessage(m) => write!(f, "two messages are named `{m}`"),
            K::DuplicateSignal { message, signal } => {
                write!(f, "message `{message}` has two signals named `{signal}`")
            }
            K::BadSize {
                message,
                signal,
                size,
            } => write!(
                f,
                "signal `{message}.{signal}` is {size} bits long; integers take 1 to 64 bits, floats 32 or 64"
            ),
            K::BadFactor { message, signal } => write!(
                f,
                "signal `{message}.{signal}` has a factor of zero: no value can be encoded"
            ),
            K::OutsideFrame {
                message,
                signal,
                needs,
                size,
            } => write!(
                f,
                "signal `{message}.{signal}` needs {needs} bytes but message `{message}` has {size}"
            ),
            K::UnsupportedMultiplexing { message } => write!(
                f,
                "message `{message}` uses multiplexing other than one switch (`M`) and signals `mN`"
            ),
        }
    }
}

impl std::error::Error for DbcError {}

/// A checked DBC.
#[derive(Clone, Debug, PartialEq)]
pub struct Dbc {
    messages: Vec<Message>,
    by_id: HashMap<CanId, MessageId>,
    by_name: HashMap<String, MessageId>,
}

fn numeric(v: &NumericValue) -> f64 {
    match v {
        NumericValue::Uint(u) => *u as f64,
        NumericValue::Int(i) => *i as f64,
        NumericValue::Double(d) => *d,
    }
}

fn attr_number(v: &AttributeValue) -> Option<f64> {
    match v {
        AttributeValue::Uint(u) => Some(*u as f64),
        AttributeValue::Int(i) => Some(*i as f64),
        AttributeValue::Double(d) => Some(*d),
        AttributeValue::String(_) => None,
    }
}

/// Finds `needle` in `text` after `from`, as a whole word.
fn find_word(text: &str, from: usize, needle: &str) -> Option<usize> {
    let mut at = from;
    while let Some(i) = text.get(at..)?.find(needle) {
        let start = at + i;
        let end = start + needle.len();
        let before = text[..start].chars().next_back();
        let after = text[end..].chars().next();
        let word = |c: Option<char>| c.is_some_and(|c| c.is_alphanumeric() || c == '_');
        if !word(before) && !word(after) {
            return Some(start);
        }
        at = end;
    }
    None
}

/// Where message `raw_id` is declared (`BO_ <id> <name>`), and optionally one of its signals.
fn locate(text: &str, raw_id: u32, name: &str, signal: Option<&str>) -> Option<usize> {
    let mut at = 0;
    loop {
        let bo = find_word(text, at, "BO_")?;
        let rest = &text[bo + 3..];
        let mut words = rest.split_whitespace();
        let id_ok = words.next().and_then(|w| w.parse::<u64>().ok()) == Some(u64::from(raw_id));
        let name_ok = words.next().map(|w| w.trim_end_matches(':')) == Some(name);
        if id_ok && name_ok {
            return match signal {
                None => Some(bo),
                Some(s) => {
                    let sg = find_word(text, bo, s)?;
                    Some(sg)
                }
            };
        }
        at = bo + 3;
    }
}

impl Dbc {
    /// A DBC without messages.
    pub fn empty() -> Dbc {
        Dbc {
            messages: Vec::new(),
            by_id: HashMap::new(),
            by_name: HashMap::new(),
        }
    }

    /// Reads and checks the DBC file at `path` (UTF-8, or else read as Latin-1).
    pub fn load(path: &Path) -> Result<Dbc, DbcError> {
        let bytes = std::fs::read(path).map_err(|e| DbcError {
            kind: DbcErrorKind::Io(format!("{}: {e}", path.display())),
            offset: None,
        })?;
        Dbc::parse(&decode_text(bytes))
    }

    /// Parses and checks DBC text.
    pub fn parse(text: &str) -> Result<Dbc, DbcError> {
        let parsed = can_dbc::Dbc::try_from(text).map_err(|e| {
            let offset = match &e {
                can_dbc::DbcError::Pest(p) => Some(match p.location {
                    pest::error::InputLocation::Pos(p) => p,
                    pest::error::InputLocation::Span((s, _)) => s,
                }),
                _ => None,
            };
            let msg = match &e {
                can_dbc::DbcError::Pest(p) => {
                    let (line, col) = match p.line_col {
                        pest::error::LineColLocation::Pos(lc) => lc,
                        pest::error::LineColLocation::Span(lc, _) => lc,
                    };
                    format!("line {line}, column {col}: {}", p.variant.message())
                }
                other => other.to_string(),
            };
            DbcError {
                kind: DbcErrorKind::Syntax(msg),
                offset,
            }
        })?;
        Self::from_parsed(text, &parsed)
    }

    fn from_parsed(text: &str, dbc: &can_dbc::Dbc) -> Result<Dbc, DbcError> {
        let mut messages = Vec::new();
        let mut by_id = HashMap::new();
        let mut by_name = HashMap::new();
        for m in &dbc.messages {
            let raw_id = m.id.raw();
            let err = |kind, signal: Option<&str>| DbcError {
                kind,
                offset: locate(text, raw_id, &m.name, signal),
            };
            let id = match m.id {
                can_dbc::MessageId::Standard(i) => CanId::standard(u32::from(i)),
                can_dbc::MessageId::Extended(i) => CanId::extended(i),
            };
            let Some(id) = id else {
                return Err(err(
                    DbcErrorKind::Syntax(format!(
                        "message `{}` has identifier {raw_id}, outside the 11-bit range (add 0x80000000 for a 29-bit identifier)",
                        m.name
                    )),
                    None,
                ));
            };
            let size_bytes = usize::try_from(m.size).unwrap_or(usize::MAX);
            if size_bytes > CANFD_MAX_LEN {
                return Err(err(
                    DbcErrorKind::MessageTooLong {
                        message: m.name.clone(),
                        size: m.size,
                    },
                    None,
                ));
            }
            if let Some(&first) = by_id.get(&id) {
                let first: &Message = &messages[first];
                return Err(err(
                    DbcErrorKind::DuplicateId {
                        id,
                        first: first.name.clone(),
                        second: m.name.clone(),
                    },
                    None,
                ));
            }
            if by_name.contains_key(&m.name) {
                return Err(err(DbcErrorKind::DuplicateMessage(m.name.clone()), None));
            }
            let extended_mux = dbc.extended_multiplex.iter().any(|x| x.message_id == m.id);
            let switches = m
                .signals
                .iter()
                .filter(|s| s.multiplexer_indicator == MultiplexIndicator::Multiplexor)
                .count();
            let nested = m.signals.iter().any(|s| {
                matches!(
                    s.multiplexer_indicator,
                    MultiplexIndicator::MultiplexorAndMultiplexedSignal(_)
                )
            });
            let muxed = m.signals.iter().any(|s| {
                matches!(
                    s.multiplexer_indicator,
                    MultiplexIndicator::MultiplexedSignal(_)
                )
            });
            if extended_mux || switches > 1 || nested || (muxed && switches == 0) {
                return Err(err(
                    DbcErrorKind::UnsupportedMultiplexing {
                        message: m.name.clone(),
                    },
                    None,
                ));
            }
            let cycle_time_ms = dbc
                .resolved_message_attribute(m.id, "GenMsgCycleTime")
                .and_then(attr_number)
                .filter(|v| v.is_finite() && *v >= 1.0)
                .map(|v| v as u64);
            let mut signals: Vec<Signal> = Vec::new();
            let mut multiplexor = None;
            for s in &m.signals {
                let serr = |kind| err(kind, Some(&s.name));
                if signals.iter().any(|o| o.name == s.name) {
                    return Err(serr(DbcErrorKind::DuplicateSignal {
                        message: m.name.clone(),
                        signal: s.name.clone(),
                    }));
                }
                let kind = match dbc.extended_value_type_for_signal(m.id, &s.name) {
                    Some(SignalExtendedValueType::IEEEfloat32Bit) => ValueKind::Float32,
                    Some(SignalExtendedValueType::IEEEdouble64bit) => ValueKind::Float64,
                    _ => match s.value_type {
                        can_dbc::ValueType::Signed => ValueKind::Signed,
                        can_dbc::ValueType::Unsigned => ValueKind::Unsigned,
                    },
                };
                let size_ok = match kind {
                    ValueKind::Float32 => s.size == 32,
                    ValueKind::Float64 => s.size == 64,
                    _ => (1..=64).contains(&s.size),
                };
                if !size_ok || s.start_bit >= 8 * CANFD_MAX_LEN as u64 {
                    return Err(serr(DbcErrorKind::BadSize {
                        message: m.name.clone(),
                        signal: s.name.clone(),
                        size: s.size,
                    }));
                }
                if s.factor == 0.0 || !s.factor.is_finite() || !s.offset.is_finite() {
                    return Err(serr(DbcErrorKind::BadFactor {
                        message: m.name.clone(),
                        signal: s.name.clone(),
                    }));
                }
                let start_bit = s.start_bit as u32;
                let size = s.size as u32;
                let (byte_order, first_bit) = match s.byte_order {
                    can_dbc::ByteOrder::LittleEndian => (ByteOrder::LittleEndian, start_bit),
                    can_dbc::ByteOrder::BigEndian => (
                        ByteOrder::BigEndian,
                        8 * (start_bit / 8) + 7 - start_bit % 8,
                    ),
                };
                let (min, max) = (numeric(&s.min), numeric(&s.max));
                let (min, max) = if min == 0.0 && max == 0.0 {
                    (None, None)
                } else {
                    (Some(min.min(max)), Some(min.max(max)))
                };
                let mux = match s.multiplexer_indicator {
                    MultiplexIndicator::Multiplexor => {
                        multiplexor = Some(signals.len());
                        Mux::Switch
                    }
                    MultiplexIndicator::MultiplexedSignal(v) => Mux::Multiplexed(v),
                    _ => Mux::Plain,
                };
                let choices = dbc
                    .value_descriptions_for_signal(m.id, &s.name)
                    .map(|v| {
                        v.iter()
                            .map(|d| (d.id, d.description.clone()))
                            .collect::<Vec<_>>()
                    })
                    .unwrap_or_default();
                let start_value = dbc
                    .signal_attribute(m.id, &s.name, "GenSigStartValue")
                    .and_then(attr_number)
                    .map(|raw| raw * s.factor + s.offset);
                let sig = Signal {
                    name: s.name.clone(),
                    start_bit,
                    size,
                    byte_order,
                    kind,
                    factor: s.factor,
                    offset: s.offset,
                    min,
                    max,
                    unit: s.unit.clone(),
                    mux,
                    choices,
                    start_value,
                    first_bit,
                    round_scale: match kind {
                        ValueKind::Signed | ValueKind::Unsigned => {
                            match (decimal_places(s.factor), decimal_places(s.offset)) {
                                (Some(a), Some(b)) if a.max(b) > 0 => Some(10f64.powi(a.max(b))),
                                _ => None,
                            }
                        }
                        ValueKind::Float32 | ValueKind::Float64 => None,
                    },
                };
                // In both numberings the signal occupies positions first_bit..first_bit+size.
                let end_bit = u64::from(first_bit) + u64::from(size);
                if end_bit > 8 * size_bytes as u64 {
                    return Err(serr(DbcErrorKind::OutsideFrame {
                        message: m.name.clone(),
                        signal: s.name.clone(),
                        needs: end_bit.div_ceil(8) as usize,
                        size: size_bytes,
                    }));
                }
                signals.push(sig);
            }
            by_id.insert(id, messages.len());
            by_name.insert(m.name.clone(), messages.len());
            messages.push(Message {
                name: m.name.clone(),
                id,
                size: size_bytes,
                transmitter: m.transmitter.clone(),
                cycle_time_ms,
                signals,
                multiplexor,
            });
        }
        Ok(Dbc {
            messages,
            by_id,
            by_name,
        })
    }
}

/// DBC files are often written in Windows-1252: text that is not UTF-8 is read as Latin-1,
/// which agrees with Windows-1252 on every character a DBC's names and units use.
fn decode_text(bytes: Vec<u8>) -> String {
    match String::from_utf8(bytes) {
        Ok(s) => s,
        Err(e) => e.into_bytes().iter().map(|&b| char::from(b)).collect(),
    }
}

/// One decoded signal of a frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DecodedSignal {
    /// The signal.
    pub signal: SignalRef,
    /// The raw value: sign-extended for a signed signal, the bits of a float signal.
    pub raw: i128,
    /// `raw * factor + offset`.
    pub physical: f64,
}

/// The signals of one frame.
#[derive(Clone, Debug, PartialEq)]
pub struct DecodedMessage {
    /// The message.
    pub message: MessageId,
    /// The signals present in the frame (the switch's signals only, for a multiplexed
    /// message), in the DBC's order.
    pub signals: Vec<DecodedSignal>,
}

impl DecodedMessage {
    /// The physical value of the signal named `signal`, if this frame carries it (`dbc`: the
    /// DBC that decoded it). For the simulators, which read a few signals of a few messages.
    pub fn value(&self, dbc: &Dbc, signal: &str) -> Option<f64> {
        let m = dbc.message(self.message)?;
        self.signals
            .iter()
            .find(|s| {
                m.signals
                    .get(s.signal.signal)
                    .is_some_and(|g| g.name == signal)
            })
            .map(|s| s.physical)
    }
}

/// What a frame turned out to be.
#[derive(Clone, Debug, PartialEq)]
pub enum DecodeOutcome {
    /// A frame of a known message, decoded.
    Message(DecodedMessage),
    /// A data frame whose identifier the DBC does not know.
    UnknownId(CanId),
    /// A frame of a known message with another length than the DBC's.
    WrongLength {
        /// The message.
        message: MessageId,
        /// The DBC's length.
        expected: usize,
        /// The frame's.
        got: usize,
    },
    /// A remote frame (a request, no data).
    Remote(CanId),
    /// An error frame ([`crate::bus_state::state_from_error_frame`] reads the state it tells).
    Error,
}

/// A frame could not be encoded.
#[derive(Clone, Debug, PartialEq)]
pub enum EncodeError {
    /// No message of that name.
    UnknownMessage(String),
    /// The message has no signal of that name.
    UnknownSignal {
        /// The message.
        message: String,
        /// The name given.
        signal: String,
    },
    /// A signal given twice.
    DuplicateSignal {
        /// The message.
        message: String,
        /// The signal.
        signal: String,
    },
    /// A signal of the frame has no value.
    MissingSignal {
        /// The message.
        message: String,
        /// The signal.
        signal: String,
    },
    /// A multiplexed signal given while the switch selects another one.
    NotSelected {
        /// The message.
        message: String,
        /// The signal.
        signal: String,
        /// The switch value it needs.
        needs: u64,
        /// The switch value given.
        switch: f64,
    },
    /// A value that cannot be put in its signal.
    Value {
        /// The message.
        message: String,
        /// The signal.
        signal: String,
        /// The value given.
        value: f64,
        /// Why.
        error: ValueError,
    },
    /// The message's length cannot be sent (a CAN FD message of 9 to 11 bytes...).
    Frame {
        /// The message.
        message: String,
        /// Why.
        error: FrameError,
    },
}

impl fmt::Display for EncodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            EncodeError::UnknownMessage(m) => write!(f, "the DBC has no message `{m}`"),
            EncodeError::UnknownSignal { message, signal } => {
                write!(f, "message `{message}` has no signal `{signal}`")
            }
            EncodeError::DuplicateSignal { message, signal } => {
                write!(f, "signal `{message}.{signal}` is given twice")
            }
            EncodeError::MissingSignal { message, signal } => write!(
                f,
                "signal `{message}.{signal}` has no value (give every signal of the frame)"
            ),
            EncodeError::NotSelected {
                message,
                signal,
                needs,
                switch,
            } => write!(
                f,
                "signal `{message}.{signal}` is sent only when the switch is {needs}, not {switch}"
            ),
            EncodeError::Value {
                message,
                signal,
                value,
                error,
            } => match error {
                ValueError::NotFinite => {
                    write!(f, "signal `{message}.{signal}`: {value} is not a number")
                }
                ValueError::OutOfRange { min, max } => write!(
                    f,
                    "signal `{message}.{signal}`: {value} is outside its range [{min}, {max}]"
                ),
                ValueError::NotRepresentable { raw } => write!(
                    f,
                    "signal `{message}.{signal}`: {value} needs the raw value {raw}, which its bits cannot hold"
                ),
            },
            EncodeError::Frame { message, error } => {
                write!(f, "message `{message}` cannot be sent: {error}")
            }
        }
    }
}

impl std::error::Error for EncodeError {}

impl Dbc {
    /// Every message, in written order.
    pub fn messages(&self) -> &[Message] {
        &self.messages
    }

    /// The message at `id` (an index from this DBC).
    pub fn message(&self, id: MessageId) -> Option<&Message> {
        self.messages.get(id)
    }

    /// The message with identifier `id`.
    pub fn message_by_can_id(&self, id: CanId) -> Option<MessageId> {
        self.by_id.get(&id).copied()
    }

    /// The message named `name`.
    pub fn message_by_name(&self, name: &str) -> Option<MessageId> {
        self.by_name.get(name).copied()
    }

    /// The signal `r`.
    pub fn signal(&self, r: SignalRef) -> Option<&Signal> {
        self.messages.get(r.message)?.signals.get(r.signal)
    }

    /// The signal written `MESSAGE.signal`.
    pub fn signal_ref(&self, path: &str) -> Option<SignalRef> {
        let (m, s) = path.split_once('.')?;
        let message = self.message_by_name(m)?;
        let signal = self.messages[message].signal_index(s)?;
        Some(SignalRef { message, signal })
    }

    /// `MESSAGE.signal` for `r`.
    pub fn signal_path(&self, r: SignalRef) -> String {
        match (self.messages.get(r.message), self.signal(r)) {
            (Some(m), Some(s)) => format!("{}.{}", m.name, s.name),
            _ => format!("#{}.{}", r.message, r.signal),
        }
    }

    /// Every signal as `MESSAGE.signal`, for suggestions.
    pub fn signal_paths(&self) -> impl Iterator<Item = String> + '_ {
        self.messages.iter().flat_map(|m| {
            m.signals
                .iter()
                .map(move |s| format!("{}.{}", m.name, s.name))
        })
    }

    /// Decodes a frame. Never fails: what the frame is not is the outcome.
    pub fn decode(&self, frame: &Frame) -> DecodeOutcome {
        match frame.kind() {
            FrameKind::Error => return DecodeOutcome::Error,
            FrameKind::Remote => return DecodeOutcome::Remote(frame.id()),
            FrameKind::Data | FrameKind::Fd { .. } => {}
        }
        let Some(message) = self.message_by_can_id(frame.id()) else {
            return DecodeOutcome::UnknownId(frame.id());
        };
        let m = &self.messages[message];
        let data = frame.payload();
        if data.len() != m.size {
            return DecodeOutcome::WrongLength {
                message,
                expected: m.size,
                got: data.len(),
            };
        }
        let switch = m
            .multiplexor
            .map(|i| m.signals[i].raw_from_bits(m.signals[i].extract_bits(data)));
        let signals = m
            .signals
            .iter()
            .enumerate()
            .filter(|(_, s)| match s.mux {
                Mux::Multiplexed(v) => switch == Some(i128::from(v)),
                _ => true,
            })
            .map(|(i, s)| {
                let bits = s.extract_bits(data);
                DecodedSignal {
                    signal: SignalRef { message, signal: i },
                    raw: s.raw_from_bits(bits),
                    physical: s.physical_from_bits(bits),
                }
            })
            .collect();
        DecodeOutcome::Message(DecodedMessage { message, signals })
    }

    /// SocketCAN identifier filters `(id, mask)` that pass exactly this DBC's messages
    /// (standard and extended identifiers kept apart by the EFF flag).
    pub fn socket_filters(&self) -> Vec<(u32, u32)> {
        const EFF: u32 = 0x8000_0000;
        self.messages()
            .iter()
            .map(|m| match m.id {
                CanId::Standard(id) => (u32::from(id), 0x7FF | EFF),
                CanId::Extended(id) => (id | EFF, 0x1FFF_FFFF | EFF),
            })
            .collect()
    }

    /// Encodes a frame of the message named `message` from physical values by signal name.
    ///
    /// Every signal in the frame must be given: the plain ones, the switch and the signals it
    /// selects (for a multiplexed message). Unused bits are zero.
    pub fn encode(&self, message: &str, values: &[(&str, f64)]) -> Result<Frame, EncodeError> {
        let id = self
            .message_by_name(message)
            .ok_or_else(|| EncodeError::UnknownMessage(message.to_owned()))?;
        self.encode_message(id, values)
    }

    /// Encodes a frame of message `id`; see [`encode`](Self::encode).
    pub fn encode_message(
        &self,
        id: MessageId,
        values: &[(&str, f64)],
    ) -> Result<Frame, EncodeError> {
        let m = self
            .messages
            .get(id)
            .ok_or_else(|| EncodeError::UnknownMessage(format!("#{id}")))?;
        let mut given: Vec<Option<f64>> = vec![None; m.signals.len()];
        for (name, value) in values {
            let i = m
                .signal_index(name)
                .ok_or_else(|| EncodeError::UnknownSignal {
                    message: m.name.clone(),
                    signal: (*name).to_owned(),
                })?;
            if given[i].replace(*value).is_some() {
                return Err(EncodeError::DuplicateSignal {
                    message: m.name.clone(),
                    signal: (*name).to_owned(),
                });
            }
        }
        let switch = match m.multiplexor {
            Some(i) => Some(given[i].ok_or_else(|| EncodeError::MissingSignal {
                message: m.name.clone(),
                signal: m.signals[i].name.clone(),
            })?),
            None => None,
        };
        let mut data = [0u8; CANFD_MAX_LEN];
        for (s, value) in m.signals.iter().zip(&given) {
            if let (Mux::Multiplexed(needs), Some(sw)) = (s.mux, switch) {
                // Compare as the switch's raw value would encode.
                let selected = m.multiplexor.and_then(|i| {
                    let sws = &m.signals[i];
                    sws.bits_from_physical(sw)
                        .ok()
                        .map(|b| sws.raw_from_bits(b) == i128::from(needs))
                });
                if selected != Some(true) {
                    if value.is_some() {
                        return Err(EncodeError::NotSelected {
                            message: m.name.clone(),
                            signal: s.name.clone(),
                            needs,
                            switch: sw,
                        });
                    }
                    continue;
                }
            }
            let value = value.ok_or_else(|| EncodeError::MissingSignal {
                message: m.name.clone(),
                signal: s.name.clone(),
            })?;
            let bits = s
                .bits_from_physical(value)
                .map_err(|error| EncodeError::Value {
                    message: m.name.clone(),
                    signal: s.name.clone(),
                    value,
                    error,
                })?;
            s.insert_bits(&mut data[..m.size], bits);
        }
        let frame = if m.is_fd() {
            if !is_fd_len(m.size) {
                return Err(EncodeError::Frame {
                    message: m.name.clone(),
                    error: FrameError::InvalidFdLength(m.size),
                });
            }
            Frame::fd(m.id, &data[..m.size], 0x04)
        } else {
            Frame::data(m.id, &data[..m.size])
        };
        frame.map_err(|error| EncodeError::Frame {
            message: m.name.clone(),
            error,
        })
    }
}
