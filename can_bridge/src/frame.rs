//! CAN frames as plain data: what every layer above the bus works on.
//!
//! A [`Frame`] is a value (`Copy`, no allocation): an identifier, a kind (data, remote, error,
//! CAN FD) and up to 64 bytes. It does not depend on SocketCAN, so the DBC codec, the rules, the
//! `candump -L` log and the in-memory bus run on any machine; [`crate::bus::SocketCanBus`]
//! converts at the socket.

use std::fmt;

/// Largest payload of a classic CAN frame.
pub const CAN_MAX_LEN: usize = 8;
/// Largest payload of a CAN FD frame.
pub const CANFD_MAX_LEN: usize = 64;
/// Largest standard (11-bit) identifier.
pub const SFF_MAX: u32 = 0x7FF;
/// Largest extended (29-bit) identifier.
pub const EFF_MAX: u32 = 0x1FFF_FFFF;

/// Error class bits of an error frame's identifier (linux/can/error.h).
pub mod err {
    /// TX timeout (by the netdevice driver).
    pub const TX_TIMEOUT: u32 = 0x0001;
    /// Lost arbitration (`data[0]`: the bit).
    pub const LOSTARB: u32 = 0x0002;
    /// Controller problems (`data[1]`).
    pub const CRTL: u32 = 0x0004;
    /// Protocol violations (`data[2]`, `data[3]`).
    pub const PROT: u32 = 0x0008;
    /// Transceiver status (`data[4]`).
    pub const TRX: u32 = 0x0010;
    /// No acknowledgement on transmission.
    pub const ACK: u32 = 0x0020;
    /// Bus off.
    pub const BUSOFF: u32 = 0x0040;
    /// Bus error.
    pub const BUSERROR: u32 = 0x0080;
    /// The controller restarted.
    pub const RESTARTED: u32 = 0x0100;
    /// TX and RX error counters (`data[6]`, `data[7]`).
    pub const CNT: u32 = 0x0200;
    /// The error-frame flag of a SocketCAN identifier.
    pub const FLAG: u32 = 0x2000_0000;

    /// `data[1]` of a controller error: RX buffer overflow.
    pub const CRTL_RX_OVERFLOW: u8 = 0x01;
    /// `data[1]`: TX buffer overflow.
    pub const CRTL_TX_OVERFLOW: u8 = 0x02;
    /// `data[1]`: reached the warning level for RX errors.
    pub const CRTL_RX_WARNING: u8 = 0x04;
    /// `data[1]`: reached the warning level for TX errors.
    pub const CRTL_TX_WARNING: u8 = 0x08;
    /// `data[1]`: reached the error-passive level for RX errors.
    pub const CRTL_RX_PASSIVE: u8 = 0x10;
    /// `data[1]`: reached the error-passive level for TX errors.
    pub const CRTL_TX_PASSIVE: u8 = 0x20;
    /// `data[1]`: recovered to error-active.
    pub const CRTL_ACTIVE: u8 = 0x40;
}

/// A CAN identifier: 11-bit standard or 29-bit extended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum CanId {
    /// An 11-bit identifier (at most [`SFF_MAX`]).
    Standard(u16),
    /// A 29-bit identifier (at most [`EFF_MAX`]).
    Extended(u32),
}

impl CanId {
    /// A standard identifier, if `id` fits in 11 bits.
    pub fn standard(id: u32) -> Option<Self> {
        u16::try_from(id)
            .ok()
            .filter(|&i| u32::from(i) <= SFF_MAX)
            .map(CanId::Standard)
    }

    /// An extended identifier, if `id` fits in 29 bits.
    pub fn extended(id: u32) -> Option<Self> {
        (id <= EFF_MAX).then_some(CanId::Extended(id))
    }

    /// The identifier's number, without format flag.
    pub fn raw(self) -> u32 {
        match self {
            CanId::Standard(i) => u32::from(i),
            CanId::Extended(i) => i,
        }
    }

    /// True for a 29-bit identifier.
    pub fn is_extended(self) -> bool {
        matches!(self, CanId::Extended(_))
    }
}

impl fmt::Display for CanId {
    /// `123` for a standard identifier, `12345678` (eight digits) for an extended one, as
    /// candump writes them.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CanId::Standard(i) => write!(f, "{i:03X}"),
            CanId::Extended(i) => write!(f, "{i:08X}"),
        }
    }
}

/// What a frame is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum FrameKind {
    /// A classic data frame (0 to 8 bytes).
    Data,
    /// A remote transmission request; the frame's length is the requested DLC, its data zero.
    Remote,
    /// An error frame reported by the controller; the identifier holds the error class bits
    /// ([`err`]), the data 8 bytes of detail.
    Error,
    /// A CAN FD data frame (0 to 64 bytes) with its flags (`0x1` bit-rate switch, `0x2` error
    /// state indicator, `0x4` FD frame), kept as read so that logs round-trip.
    Fd {
        /// The `canfd_frame.flags` byte.
        flags: u8,
    },
}

/// A CAN frame, as a value.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct Frame {
    id: CanId,
    kind: FrameKind,
    len: u8,
    /// The "len8 DLC" of a classic 8-byte frame (9 to 15) when one was given, else 0.
    len8_dlc: u8,
    data: [u8; CANFD_MAX_LEN],
}

/// A frame could not be built.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum FrameError {
    /// More bytes than the kind of frame carries.
    TooLong {
        /// Bytes given.
        len: usize,
        /// Most accepted.
        max: usize,
    },
    /// A CAN FD length that is not one of 0..=8, 12, 16, 20, 24, 32, 48, 64.
    InvalidFdLength(usize),
    /// An error frame's class bits outside the 29 bits of an identifier.
    InvalidErrorClass(u32),
}

impl fmt::Display for FrameError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FrameError::TooLong { len, max } => {
                write!(
                    f,
                    "{len} bytes do not fit in a frame of at most {max} bytes"
                )
            }
            FrameError::InvalidFdLength(len) => write!(
                f,
                "{len} bytes is not a CAN FD length (0 to 8, 12, 16, 20, 24, 32, 48 or 64)"
            ),
            FrameError::InvalidErrorClass(bits) => {
                write!(f, "error class bits {bits:#x} do not fit in 29 bits")
            }
        }
    }
}

impl std::error::Error for FrameError {}

/// True for a length a CAN FD frame can have.
pub fn is_fd_len(len: usize) -> bool {
    matches!(len, 0..=8 | 12 | 16 | 20 | 24 | 32 | 48 | 64)
}

impl Frame {
    fn build(id: CanId, kind: FrameKind, bytes: &[u8], max: usize) -> Result<Self, FrameError> {
        if bytes.len() > max {
            return Err(FrameError::TooLong {
                len: bytes.len(),
                max,
            });
        }
        let mut data = [0u8; CANFD_MAX_LEN];
        data[..bytes.len()].copy_from_slice(bytes);
        Ok(Frame {
            id,
            kind,
            len: bytes.len() as u8,
            len8_dlc: 0,
            data,
        })
    }

    /// A classic data frame of up to 8 bytes.
    pub fn data(id: CanId, bytes: &[u8]) -> Result<Self, FrameError> {
        Self::build(id, FrameKind::Data, bytes, CAN_MAX_LEN)
    }

    /// A CAN FD frame with `flags` (see [`FrameKind::Fd`]); the length must be a CAN FD length.
    pub fn fd(id: CanId, bytes: &[u8], flags: u8) -> Result<Self, FrameError> {
        if !is_fd_len(bytes.len()) {
            return Err(FrameError::InvalidFdLength(bytes.len()));
        }
        Self::build(id, FrameKind::Fd { flags }, bytes, CANFD_MAX_LEN)
    }

    /// A remote frame requesting `dlc` bytes (at most 8; more is refused).
    pub fn remote(id: CanId, dlc: u8) -> Result<Self, FrameError> {
        if usize::from(dlc) > CAN_MAX_LEN {
            return Err(FrameError::TooLong {
                len: usize::from(dlc),
                max: CAN_MAX_LEN,
            });
        }
        Ok(Frame {
            id,
            kind: FrameKind::Remote,
            len: dlc,
            len8_dlc: 0,
            data: [0; CANFD_MAX_LEN],
        })
    }

    /// An error frame with error class bits `class` ([`err`]) and its 8 bytes of detail.
    pub fn error(class: u32, detail: [u8; 8]) -> Result<Self, FrameError> {
        if class > EFF_MAX {
            return Err(FrameError::InvalidErrorClass(class));
        }
        Self::build(
            CanId::Extended(class),
            FrameKind::Error,
            &detail,
            CAN_MAX_LEN,
        )
    }

    /// The same frame with a "len8 DLC" (9 to 15) for a classic 8-byte data frame; any other
    /// value, or another frame, leaves it without one.
    pub fn with_len8_dlc(mut self, dlc: u8) -> Self {
        self.len8_dlc = if self.kind == FrameKind::Data && self.len == 8 && (9..=15).contains(&dlc)
        {
            dlc
        } else {
            0
        };
        self
    }

    /// The identifier (for an error frame, the error class bits as an extended identifier).
    pub fn id(&self) -> CanId {
        self.id
    }

    /// The kind of frame.
    pub fn kind(&self) -> FrameKind {
        self.kind
    }

    /// The payload (empty for a remote frame).
    pub fn payload(&self) -> &[u8] {
        match self.kind {
            FrameKind::Remote => &[],
            _ => &self.data[..usize::from(self.len)],
        }
    }

    /// The length: payload bytes, or the requested DLC of a remote frame.
    pub fn len(&self) -> usize {
        usize::from(self.len)
    }

    /// True when the frame carries no byte.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The "len8 DLC" of a classic 8-byte frame, if one was given.
    pub fn len8_dlc(&self) -> Option<u8> {
        (self.len8_dlc != 0).then_some(self.len8_dlc)
    }

    /// True for an error frame.
    pub fn is_error(&self) -> bool {
        self.kind == FrameKind::Error
    }

    /// The error class bits of an error frame ([`err`]), 0 for any other frame.
    pub fn error_class(&self) -> u32 {
        match self.kind {
            FrameKind::Error => self.id.raw(),
            _ => 0,
        }
    }
}

/// A frame with the time it was received (or sent), in microseconds.
///
/// The time is the bus's clock: kernel receive timestamps (microseconds since the Unix epoch)
/// on SocketCAN, the injected clock on the memory bus, the log's timestamps on replay.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TimedFrame {
    /// Microseconds.
    pub time_us: u64,
    /// The frame.
    pub frame: Frame,
}
