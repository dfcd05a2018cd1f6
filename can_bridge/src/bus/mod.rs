//! The bus: where frames come from and go to. [`Bus`] is what the bridge uses; it does not know
//! which implementation it has.
//!
//! - [`SocketCanBus`]: a Linux SocketCAN interface (`can0`, `vcan0`) through the `socketcan`
//!   crate: classic or CAN FD socket, identifier filters, error frames (error filter set),
//!   kernel receive timestamps, the interface state and its restart through netlink.
//! - [`MemoryBus`]: endpoints of an in-process bus ([`MemoryHub`]), for machines without
//!   SocketCAN and for tests, with fault injection (error frames, bus states, a blocked
//!   transmitter).
//!
//! **Back-pressure.** When the interface cannot take a frame now (SocketCAN's `ENOBUFS` or
//! `EAGAIN`, a memory bus whose transmitter is blocked or off the bus), the frame waits in a
//! bounded queue, in order, and later sends go behind it; [`Bus::flush`] retries. A frame that
//! finds the queue full is refused with [`BusError::QueueFull`], which hands it back: a frame is
//! sent, waiting, or refused to the caller, never dropped unseen ([`BusStats`] counts each).
//!
//! One file per implementation (`memory`, `socketcan`); the trait, its errors and counters, and
//! the transmit queue both implementations share are here.

mod memory;
mod socketcan;

use std::collections::VecDeque;
use std::fmt;
use std::io;
use std::os::fd::RawFd;

use crate::bus_state::BusState;
use crate::frame::{Frame, TimedFrame};

pub use self::memory::{MemoryBus, MemoryHub, DEFAULT_RX_QUEUE};
pub use self::socketcan::{SocketCanBus, SocketCanOptions};

/// Frames a transmit queue holds by default.
pub const DEFAULT_TX_QUEUE: usize = 256;

/// What [`Bus::send`] did with a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sent {
    /// Handed to the interface.
    Now,
    /// Waiting in the transmit queue (which now holds `queued` frames).
    Queued {
        /// Frames waiting, this one included.
        queued: usize,
    },
}

/// Counters of a bus endpoint.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BusStats {
    /// Frames handed to the interface.
    pub sent: u64,
    /// Frames that had to wait in the transmit queue (each counted once).
    pub deferred: u64,
    /// Frames refused because the transmit queue was full.
    pub refused: u64,
    /// Writes that failed otherwise.
    pub write_errors: u64,
    /// Frames received (error frames included).
    pub received: u64,
    /// Frames lost because this endpoint's receive queue was full (memory bus; SocketCAN
    /// counts its own drops in the kernel).
    pub rx_overflow: u64,
    /// Frames read from the socket that no [`Frame`] can hold (a kernel frame out of the CAN
    /// specification): skipped, counted and logged.
    pub unreadable: u64,
}

/// A bus operation failed.
#[derive(Debug)]
pub enum BusError {
    /// A system call failed.
    Io {
        /// What was being done.
        op: &'static str,
        /// The interface.
        interface: String,
        /// The error.
        error: io::Error,
    },
    /// The transmit queue is full: the frame was not sent and is handed back.
    QueueFull {
        /// The refused frame.
        frame: Frame,
        /// The queue's capacity.
        capacity: usize,
    },
    /// This bus cannot do that (send an error frame, a CAN FD frame on a classic socket...).
    Unsupported(String),
    /// The interface refused a netlink request (state, restart).
    Netlink {
        /// The interface.
        interface: String,
        /// What failed.
        error: String,
    },
}

impl fmt::Display for BusError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            BusError::Io {
                op,
                interface,
                error,
            } => {
                write!(f, "{op} on `{interface}` failed: {error}")?;
                if error.raw_os_error() == Some(libc::EAFNOSUPPORT) {
                    f.write_str(" (this kernel has no SocketCAN: use the memory bus, or load can.ko, can-raw.ko and vcan.ko)")?;
                }
                if error.raw_os_error() == Some(libc::ENODEV) {
                    f.write_str(" (no such interface: `ip link add dev vcan0 type vcan && ip link set up vcan0`)")?;
                }
                Ok(())
            }
            BusError::QueueFull { frame, capacity } => write!(
                f,
                "frame {frame} refused: the transmit queue is full ({capacity} frames wait for the interface)"
            ),
            BusError::Unsupported(what) => f.write_str(what),
            BusError::Netlink { interface, error } => {
                write!(f, "netlink request on `{interface}` failed: {error}")
            }
        }
    }
}

impl std::error::Error for BusError {}

impl BusError {
    /// True when the error says the interface went down or away (`ENETDOWN`, `ENODEV`,
    /// `ENXIO`) rather than that the bridge failed: the bus may come back, and the bridge
    /// reports the interface as stopped and waits for it.
    pub fn is_interface_down(&self) -> bool {
        matches!(self, BusError::Io { error, .. } if is_down_errno(error))
    }
}

fn is_down_errno(error: &io::Error) -> bool {
    matches!(
        error.raw_os_error(),
        Some(libc::ENETDOWN | libc::ENODEV | libc::ENXIO)
    )
}

/// A CAN bus endpoint.
pub trait Bus {
    /// The interface's name (`vcan0`, `mem0`), as written in logs.
    fn interface(&self) -> &str;

    /// Sends a frame now, or queues it behind those waiting (see the module documentation).
    fn send(&mut self, frame: &Frame) -> Result<Sent, BusError>;

    /// Retries the frames waiting; returns how many still wait.
    fn flush(&mut self) -> Result<usize, BusError>;

    /// Frames waiting in the transmit queue.
    fn queued(&self) -> usize;

    /// The next received frame with its timestamp, if one is there (never blocks).
    fn recv(&mut self) -> Result<Option<TimedFrame>, BusError>;

    /// A file descriptor that becomes readable when a frame may be there, to wait on with
    /// [`petrel_ipc::FdSource`] in a reactor.
    fn wait_fd(&self) -> Option<RawFd>;

    /// The controller's state, when the interface reports one (a vcan does not).
    fn state(&mut self) -> Result<Option<BusState>, BusError>;

    /// Restarts the controller after a bus-off.
    fn restart(&mut self) -> Result<(), BusError>;

    /// Counters.
    fn stats(&self) -> BusStats;
}

/// The result of one write attempt.
enum Write1 {
    Done,
    Busy,
    Failed(BusError),
}

/// The bounded transmit queue shared by the implementations.
#[derive(Debug)]
struct TxQueue {
    queue: VecDeque<Frame>,
    capacity: usize,
}

impl TxQueue {
    fn new(capacity: usize) -> Self {
        TxQueue {
            queue: VecDeque::new(),
            capacity: capacity.max(1),
        }
    }

    fn flush(
        &mut self,
        stats: &mut BusStats,
        mut write: impl FnMut(&Frame) -> Write1,
    ) -> Result<usize, BusError> {
        while let Some(frame) = self.queue.front() {
            match write(frame) {
                Write1::Done => {
                    stats.sent += 1;
                    self.queue.pop_front();
                }
                Write1::Busy => break,
                Write1::Failed(e) => {
                    stats.write_errors += 1;
                    return Err(e);
                }
            }
        }
        Ok(self.queue.len())
    }

    fn send(
        &mut self,
        frame: &Frame,
        stats: &mut BusStats,
        mut write: impl FnMut(&Frame) -> Write1,
    ) -> Result<Sent, BusError> {
        let waiting = self.flush(stats, &mut write)?;
        if waiting == 0 {
            match write(frame) {
                Write1::Done => {
                    stats.sent += 1;
                    return Ok(Sent::Now);
                }
                Write1::Busy => {}
                Write1::Failed(e) => {
                    stats.write_errors += 1;
                    return Err(e);
                }
            }
        }
        if self.queue.len() >= self.capacity {
            stats.refused += 1;
            return Err(BusError::QueueFull {
                frame: *frame,
                capacity: self.capacity,
            });
        }
        self.queue.push_back(*frame);
        stats.deferred += 1;
        Ok(Sent::Queued {
            queued: self.queue.len(),
        })
    }
}
