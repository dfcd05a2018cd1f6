//! A Linux SocketCAN interface (`can0`, `vcan0`) through the `socketcan` crate: classic or
//! CAN FD socket, identifier filters, error frames, kernel receive timestamps, and the
//! interface's state and restart through netlink.

use std::io;
use std::os::fd::{AsRawFd, RawFd};
use std::time::UNIX_EPOCH;

use socketcan::id::FdFlags;
use socketcan::{
    CanAnyFrame, CanDataFrame, CanFdFrame, CanFdSocket, CanFrame, CanInterface, CanRemoteFrame,
    CanSocket, EmbeddedFrame, ExtendedId, Id, Socket, SocketOptions, StandardId,
};

use super::{is_down_errno, Bus, BusError, BusStats, Sent, TxQueue, Write1, DEFAULT_TX_QUEUE};
use crate::bus_state::BusState;
use crate::frame::{CanId, Frame, FrameKind, TimedFrame};

/// How to open a SocketCAN interface.
#[derive(Clone, Debug)]
pub struct SocketCanOptions {
    /// Open a CAN FD socket (classic frames still come and go).
    pub fd: bool,
    /// Receive only frames matching one of these (identifier, mask) pairs; empty: all frames
    /// (the bridge then counts frames the DBC does not know).
    pub filters: Vec<(u32, u32)>,
    /// Receive error frames (all classes).
    pub error_frames: bool,
    /// Frames the transmit queue holds while the interface pushes back.
    pub tx_queue: usize,
}

impl Default for SocketCanOptions {
    fn default() -> Self {
        SocketCanOptions {
            fd: false,
            filters: Vec::new(),
            error_frames: true,
            tx_queue: DEFAULT_TX_QUEUE,
        }
    }
}

#[derive(Debug)]
enum Sock {
    Classic(CanSocket),
    Fd(CanFdSocket),
}

/// Whether the interface is there and up, as the bus last saw it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Link {
    Up,
    /// Set down (`ip link set … down`): the socket stays bound and works again once it is up.
    Down,
    /// Removed: the socket lost its binding; a new one is opened when the interface is back.
    Gone,
}

/// A SocketCAN interface.
///
/// The interface may go down, or away, under the bridge: reading then fails once with
/// [`BusError::is_interface_down`], frames to send wait (as with a full transmit queue), and
/// [`Bus::state`] says [`BusState::Stopped`] until the interface is up again, then its state
/// (error-active on a vcan), after opening a new socket if the interface was re-created.
#[derive(Debug)]
pub struct SocketCanBus {
    interface: String,
    opts: SocketCanOptions,
    sock: Sock,
    netlink: Option<CanInterface>,
    link: Link,
    /// The newest receive time handed out: times never go back (see [`Bus::recv`]).
    last_time_us: u64,
    tx: TxQueue,
    stats: BusStats,
}

fn hal_id(id: CanId) -> Option<Id> {
    match id {
        CanId::Standard(i) => StandardId::new(i).map(Id::Standard),
        CanId::Extended(i) => ExtendedId::new(i).map(Id::Extended),
    }
}

fn from_hal_id(id: Id) -> CanId {
    match id {
        Id::Standard(s) => CanId::Standard(s.as_raw()),
        Id::Extended(e) => CanId::Extended(e.as_raw()),
    }
}

/// Converts a frame read from a socket.
fn from_any(frame: CanAnyFrame) -> Option<Frame> {
    match frame {
        CanAnyFrame::Normal(d) => Frame::data(from_hal_id(d.id()), d.data()).ok(),
        CanAnyFrame::Remote(r) => {
            Frame::remote(from_hal_id(r.id()), u8::try_from(r.dlc()).ok()?).ok()
        }
        CanAnyFrame::Error(e) => {
            let mut detail = [0u8; 8];
            let d = e.data();
            let n = d.len().min(8);
            detail[..n].copy_from_slice(&d[..n]);
            Frame::error(e.error_bits(), detail).ok()
        }
        CanAnyFrame::Fd(fd) => Frame::fd(from_hal_id(fd.id()), fd.data(), fd.flags().bits()).ok(),
    }
}

fn from_classic(frame: CanFrame) -> Option<Frame> {
    from_any(CanAnyFrame::from(frame))
}

/// Error frames, filters and timestamps on a freshly opened socket.
fn configure<S: SocketOptions>(
    s: &S,
    opts: &SocketCanOptions,
    interface: &str,
) -> Result<(), BusError> {
    let io = |op: &'static str| {
        move |error: io::Error| BusError::Io {
            op,
            interface: interface.to_owned(),
            error,
        }
    };
    if opts.error_frames {
        s.set_error_filter_accept_all()
            .map_err(io("enabling error frames"))?;
    }
    if !opts.filters.is_empty() {
        s.set_filters(&opts.filters)
            .map_err(io("setting identifier filters"))?;
    }
    s.set_recv_timestamp(true)
        .map_err(io("enabling receive timestamps"))
}

impl SocketCanBus {
    /// Opens `interface` (non-blocking, with kernel receive timestamps).
    ///
    /// Open it just before reading: the kernel stamps frames on arrival only a moment after
    /// the first socket asks for timestamps, and frames that wait in the socket meanwhile are
    /// stamped when read.
    pub fn open(interface: &str, opts: &SocketCanOptions) -> Result<Self, BusError> {
        Ok(SocketCanBus {
            interface: interface.to_owned(),
            opts: opts.clone(),
            sock: Self::open_socket(interface, opts)?,
            netlink: CanInterface::open(interface).ok(),
            link: Link::Up,
            last_time_us: 0,
            tx: TxQueue::new(opts.tx_queue),
            stats: BusStats::default(),
        })
    }

    fn open_socket(interface: &str, opts: &SocketCanOptions) -> Result<Sock, BusError> {
        let io = |op: &'static str| {
            move |error: io::Error| BusError::Io {
                op,
                interface: interface.to_owned(),
                error,
            }
        };
        let sock = if opts.fd {
            Sock::Fd(CanFdSocket::open(interface).map_err(io("opening a CAN FD socket"))?)
        } else {
            Sock::Classic(CanSocket::open(interface).map_err(io("opening a CAN socket"))?)
        };
        match &sock {
            Sock::Classic(s) => configure(s, opts, interface),
            Sock::Fd(s) => configure(s, opts, interface),
        }?;
        match &sock {
            Sock::Classic(s) => s.set_nonblocking(true),
            Sock::Fd(s) => s.set_nonblocking(true),
        }
        .map_err(io("making the socket non-blocking"))?;
        Ok(sock)
    }

    /// The interface's link: gone (no such interface), down, or up. Where sysfs cannot tell
    /// (not mounted), the link is taken as up and the controller state decides.
    fn read_link(&self) -> Link {
        if CanInterface::open(&self.interface).is_err() {
            return Link::Gone;
        }
        let flags = std::fs::read_to_string(format!("/sys/class/net/{}/flags", self.interface))
            .ok()
            .and_then(|t| u32::from_str_radix(t.trim().trim_start_matches("0x"), 16).ok());
        match flags {
            Some(f) if f & 1 == 0 => Link::Down, // IFF_UP
            _ => Link::Up,
        }
    }

    /// Notes from an error that the interface went down or away.
    fn note_link_error(&mut self, error: &io::Error) {
        match error.raw_os_error() {
            Some(libc::ENODEV | libc::ENXIO) => self.link = Link::Gone,
            Some(libc::ENETDOWN) if self.link == Link::Up => self.link = Link::Down,
            _ => {}
        }
    }

    fn write(sock: &Sock, interface: &str, frame: &Frame) -> Write1 {
        let unsupported = |what: &str| Write1::Failed(BusError::Unsupported(what.to_owned()));
        let Some(id) = hal_id(frame.id()) else {
            return unsupported("identifier out of range");
        };
        let result = match (frame.kind(), sock) {
            (FrameKind::Error, _) => {
                return unsupported("error frames are reported by controllers, not sent")
            }
            (FrameKind::Fd { .. }, Sock::Classic(_)) => {
                return unsupported(
                    "a CAN FD frame on a classic socket: set `fd = true` in [bus] of can.toml",
                )
            }
            (FrameKind::Data, s) => match CanDataFrame::new(id, frame.payload()) {
                Some(d) => match s {
                    Sock::Classic(c) => c.write_frame(&CanFrame::Data(d)),
                    Sock::Fd(c) => c.write_frame(&CanAnyFrame::Normal(d)),
                },
                None => return unsupported("data frame longer than 8 bytes"),
            },
            (FrameKind::Remote, s) => match CanRemoteFrame::new_remote(id, frame.len()) {
                Some(r) => match s {
                    Sock::Classic(c) => c.write_frame(&CanFrame::Remote(r)),
                    Sock::Fd(c) => c.write_frame(&CanAnyFrame::Remote(r)),
                },
                None => return unsupported("remote frame longer than 8 bytes"),
            },
            (FrameKind::Fd { flags }, Sock::Fd(c)) => {
                match CanFdFrame::with_flags(
                    id,
                    frame.payload(),
                    FdFlags::from_bits_truncate(flags),
                ) {
                    Some(f) => c.write_frame(&CanAnyFrame::Fd(f)),
                    None => return unsupported("CAN FD frame longer than 64 bytes"),
                }
            }
        };
        match result {
            Ok(()) => Write1::Done,
            // A full interface queue, or an interface down or away: the frame waits (see
            // the module documentation); `state` reports the interface stopped meanwhile.
            Err(e)
                if e.kind() == io::ErrorKind::WouldBlock
                    || e.raw_os_error() == Some(libc::ENOBUFS)
                    || is_down_errno(&e) =>
            {
                Write1::Busy
            }
            Err(error) => Write1::Failed(BusError::Io {
                op: "sending a frame",
                interface: interface.to_owned(),
                error,
            }),
        }
    }

    fn netlink(&self) -> Result<&CanInterface, BusError> {
        self.netlink.as_ref().ok_or_else(|| BusError::Netlink {
            interface: self.interface.clone(),
            error: "the interface could not be opened through netlink".to_owned(),
        })
    }
}

impl Bus for SocketCanBus {
    fn interface(&self) -> &str {
        &self.interface
    }

    fn send(&mut self, frame: &Frame) -> Result<Sent, BusError> {
        let (sock, iface) = (&self.sock, self.interface.as_str());
        self.tx
            .send(frame, &mut self.stats, |f| Self::write(sock, iface, f))
    }

    fn flush(&mut self) -> Result<usize, BusError> {
        let (sock, iface) = (&self.sock, self.interface.as_str());
        self.tx
            .flush(&mut self.stats, |f| Self::write(sock, iface, f))
    }

    fn queued(&self) -> usize {
        self.tx.queue.len()
    }

    fn recv(&mut self) -> Result<Option<TimedFrame>, BusError> {
        loop {
            let read = match &self.sock {
                Sock::Classic(s) => s
                    .read_frame_with_timestamps()
                    .map(|(f, ts)| (from_classic(f), ts)),
                Sock::Fd(s) => s
                    .read_frame_with_timestamps()
                    .map(|(f, ts)| (from_any(f), ts)),
            };
            match read {
                Ok((Some(frame), ts)) => {
                    self.stats.received += 1;
                    let at = ts.socket.unwrap_or_else(std::time::SystemTime::now);
                    let time_us = at
                        .duration_since(UNIX_EPOCH)
                        .map_or(0, |d| u64::try_from(d.as_micros()).unwrap_or(u64::MAX));
                    // A frame that arrived before the kernel stamped on arrival is stamped when
                    // read, later than the frames behind it: hold the time, never go back.
                    self.last_time_us = self.last_time_us.max(time_us);
                    return Ok(Some(TimedFrame {
                        time_us: self.last_time_us,
                        frame,
                    }));
                }
                // A frame our type cannot hold (never for a well-formed kernel frame): next.
                Ok((None, _)) => {
                    self.stats.unreadable += 1;
                    tracing::warn!(
                        "a frame on `{}` is not a valid CAN frame: skipped ({} so far)",
                        self.interface,
                        self.stats.unreadable
                    );
                    continue;
                }
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => return Ok(None),
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(error) => {
                    self.note_link_error(&error);
                    return Err(BusError::Io {
                        op: "receiving a frame",
                        interface: self.interface.clone(),
                        error,
                    });
                }
            }
        }
    }

    fn wait_fd(&self) -> Option<RawFd> {
        Some(match &self.sock {
            Sock::Classic(s) => s.as_raw_fd(),
            Sock::Fd(s) => s.as_raw_fd(),
        })
    }

    fn state(&mut self) -> Result<Option<BusState>, BusError> {
        let link = self.read_link();
        if link != Link::Up {
            if self.link != Link::Gone {
                self.link = link;
            }
            return Ok(Some(BusState::Stopped));
        }
        if self.link == Link::Gone {
            // Re-created: a new socket (opened before the old one closes, so its descriptor
            // differs and the reactor waits on the right one) and a new interface index.
            self.sock = Self::open_socket(&self.interface, &self.opts)?;
            self.netlink = CanInterface::open(&self.interface).ok();
            tracing::info!("`{}` is back: socket opened again", self.interface);
        }
        let was_down = self.link != Link::Up;
        self.link = Link::Up;
        let state = match self.netlink()?.state() {
            Ok(state) => state,
            // Back, but not answering yet: its state comes with the next poll.
            Err(_) if was_down => return Ok(Some(BusState::ErrorActive)),
            Err(e) => {
                return Err(BusError::Netlink {
                    interface: self.interface.clone(),
                    error: e.to_string(),
                })
            }
        };
        Ok(match state {
            Some(s) => Some(match s {
                socketcan::nl::CanState::ErrorActive => BusState::ErrorActive,
                socketcan::nl::CanState::ErrorWarning => BusState::ErrorWarning,
                socketcan::nl::CanState::ErrorPassive => BusState::ErrorPassive,
                socketcan::nl::CanState::BusOff => BusState::BusOff,
                socketcan::nl::CanState::Stopped => BusState::Stopped,
                socketcan::nl::CanState::Sleeping => BusState::Sleeping,
            }),
            // A virtual interface has no controller state: up again is active again.
            None if was_down => Some(BusState::ErrorActive),
            None => None,
        })
    }

    fn restart(&mut self) -> Result<(), BusError> {
        self.netlink()?.restart().map_err(|e| BusError::Netlink {
            interface: self.interface.clone(),
            error: format!(
                "{e} (restarting needs CAP_NET_ADMIN, a bus-off interface, and no automatic restart-ms)"
            ),
        })
    }

    fn stats(&self) -> BusStats {
        self.stats
    }
}
