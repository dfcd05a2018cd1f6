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

use std::collections::VecDeque;
use std::fmt;
use std::io::{self, Read, Write};
use std::os::fd::{AsRawFd, RawFd};
use std::os::unix::net::UnixStream;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::UNIX_EPOCH;

use socketcan::{
    CanAnyFrame, CanDataFrame, CanFdFrame, CanFdSocket, CanFrame, CanInterface, CanRemoteFrame,
    CanSocket, EmbeddedFrame, ExtendedId, Id, Socket, SocketOptions, StandardId,
};

use socketcan::id::FdFlags;

use crate::clock::Clock;
use crate::faults::BusState;
use crate::frame::{err, CanId, Frame, FrameKind, TimedFrame};

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

// ---------------------------------------------------------------------------------------------
// Memory bus

#[derive(Debug)]
struct Endpoint {
    name: String,
    queue: VecDeque<TimedFrame>,
    wake: UnixStream,
    open: bool,
    overflow: u64,
}

#[derive(Debug)]
struct Hub {
    endpoints: Vec<Endpoint>,
    state: BusState,
    tx_blocked: bool,
    rx_capacity: usize,
    clock: Arc<dyn Clock>,
    log: Option<Vec<TimedFrame>>,
}

impl Hub {
    /// Delivers a frame to every open endpoint but `from`.
    fn deliver(&mut self, from: Option<usize>, frame: Frame) {
        let time_us = self.clock.now_us();
        let tf = TimedFrame { time_us, frame };
        if let Some(log) = &mut self.log {
            log.push(tf);
        }
        for (i, e) in self.endpoints.iter_mut().enumerate() {
            if Some(i) == from || !e.open {
                continue;
            }
            if e.queue.len() >= self.rx_capacity {
                e.overflow += 1;
                continue;
            }
            e.queue.push_back(tf);
            // A full wake stream is readable anyway: the byte is not needed.
            let _ = e.wake.write(&[1]);
        }
    }

    fn set_state(&mut self, state: BusState) {
        if state == self.state {
            return;
        }
        let old = self.state;
        self.state = state;
        let frame = match state {
            BusState::BusOff => Frame::error(err::BUSOFF, [0; 8]),
            BusState::ErrorPassive => Frame::error(
                err::CRTL,
                [
                    0,
                    err::CRTL_RX_PASSIVE | err::CRTL_TX_PASSIVE,
                    0,
                    0,
                    0,
                    0,
                    0,
                    0,
                ],
            ),
            BusState::ErrorWarning => Frame::error(
                err::CRTL,
                [
                    0,
                    err::CRTL_RX_WARNING | err::CRTL_TX_WARNING,
                    0,
                    0,
                    0,
                    0,
                    0,
                    0,
                ],
            ),
            BusState::ErrorActive if old == BusState::BusOff => {
                Frame::error(err::RESTARTED, [0; 8])
            }
            BusState::ErrorActive => {
                Frame::error(err::CRTL, [0, err::CRTL_ACTIVE, 0, 0, 0, 0, 0, 0])
            }
            BusState::Stopped | BusState::Sleeping => return,
        };
        if let Ok(f) = frame {
            self.deliver(None, f);
        }
    }
}

/// An in-process CAN bus: every frame an endpoint sends reaches every other endpoint, stamped
/// with the hub's clock. Clones share the bus.
#[derive(Clone, Debug)]
pub struct MemoryHub {
    hub: Arc<Mutex<Hub>>,
}

/// Frames an endpoint's receive queue holds by default; more are counted as overflow.
pub const DEFAULT_RX_QUEUE: usize = 4096;

impl MemoryHub {
    /// A bus stamping frames with `clock`.
    pub fn new(clock: Arc<dyn Clock>) -> Self {
        MemoryHub {
            hub: Arc::new(Mutex::new(Hub {
                endpoints: Vec::new(),
                state: BusState::ErrorActive,
                tx_blocked: false,
                rx_capacity: DEFAULT_RX_QUEUE,
                clock,
                log: None,
            })),
        }
    }

    fn lock(&self) -> MutexGuard<'_, Hub> {
        // A panic elsewhere while holding the lock leaves plain data: go on with it.
        self.hub.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// A new endpoint named `name` (its interface name in logs).
    pub fn endpoint(&self, name: &str) -> io::Result<MemoryBus> {
        let (wake_tx, wake_rx) = UnixStream::pair()?;
        wake_tx.set_nonblocking(true)?;
        wake_rx.set_nonblocking(true)?;
        let mut hub = self.lock();
        let index = hub.endpoints.len();
        hub.endpoints.push(Endpoint {
            name: name.to_owned(),
            queue: VecDeque::new(),
            wake: wake_tx,
            open: true,
            overflow: 0,
        });
        Ok(MemoryBus {
            hub: self.clone(),
            index,
            name: name.to_owned(),
            wake: wake_rx,
            tx: TxQueue::new(DEFAULT_TX_QUEUE),
            stats: BusStats::default(),
        })
    }

    /// Two endpoints of a new bus.
    pub fn pair(clock: Arc<dyn Clock>, a: &str, b: &str) -> io::Result<(MemoryBus, MemoryBus)> {
        let hub = MemoryHub::new(clock);
        Ok((hub.endpoint(a)?, hub.endpoint(b)?))
    }

    /// The clock that stamps this bus's frames.
    pub fn clock(&self) -> Arc<dyn Clock> {
        self.lock().clock.clone()
    }

    /// The names of the endpoints still open.
    pub fn endpoint_names(&self) -> Vec<String> {
        self.lock()
            .endpoints
            .iter()
            .filter(|e| e.open)
            .map(|e| e.name.clone())
            .collect()
    }

    /// Sets how many frames each endpoint's receive queue holds (existing frames stay).
    pub fn set_rx_capacity(&self, frames: usize) {
        self.lock().rx_capacity = frames.max(1);
    }

    /// Delivers an error frame to every endpoint (fault injection).
    pub fn inject_error_frame(&self, class: u32, detail: [u8; 8]) {
        if let Ok(f) = Frame::error(class, detail) {
            self.lock().deliver(None, f);
        }
    }

    /// Delivers any frame to every endpoint, as if a node outside the bridge sent it.
    pub fn inject(&self, frame: Frame) {
        self.lock().deliver(None, frame);
    }

    /// Puts the controller in `state`, and delivers the error frame SocketCAN would (bus-off,
    /// controller passive or warning, restarted, back to active). Off the bus, transmitters
    /// queue their frames.
    pub fn set_state(&self, state: BusState) {
        self.lock().set_state(state);
    }

    /// The controller's state.
    pub fn state(&self) -> BusState {
        self.lock().state
    }

    /// Blocks or unblocks every transmitter, as a full interface queue would (`ENOBUFS`).
    pub fn set_tx_blocked(&self, blocked: bool) {
        self.lock().tx_blocked = blocked;
    }

    /// Starts recording every frame on the bus (a tap, for tests and logs).
    pub fn start_recording(&self) {
        self.lock().log = Some(Vec::new());
    }

    /// The frames recorded since [`start_recording`](Self::start_recording), which goes on.
    pub fn take_recording(&self) -> Vec<TimedFrame> {
        self.lock()
            .log
            .as_mut()
            .map(std::mem::take)
            .unwrap_or_default()
    }
}

/// One endpoint of a [`MemoryHub`].
#[derive(Debug)]
pub struct MemoryBus {
    hub: MemoryHub,
    index: usize,
    name: String,
    wake: UnixStream,
    tx: TxQueue,
    stats: BusStats,
}

impl MemoryBus {
    /// The bus this endpoint is on, for fault injection.
    pub fn hub(&self) -> &MemoryHub {
        &self.hub
    }

    /// Sets the transmit queue's capacity (at least 1).
    pub fn set_tx_capacity(&mut self, frames: usize) {
        self.tx.capacity = frames.max(1);
    }

    fn write(hub: &mut Hub, index: usize, frame: &Frame) -> Write1 {
        if frame.is_error() {
            return Write1::Failed(BusError::Unsupported(
                "error frames are reported by controllers, not sent".to_owned(),
            ));
        }
        if hub.tx_blocked || !hub.state.is_on_bus() {
            return Write1::Busy;
        }
        hub.deliver(Some(index), *frame);
        Write1::Done
    }
}

impl Drop for MemoryBus {
    fn drop(&mut self) {
        let mut hub = self.hub.lock();
        if let Some(e) = hub.endpoints.get_mut(self.index) {
            e.open = false;
            e.queue.clear();
        }
    }
}

impl Bus for MemoryBus {
    fn interface(&self) -> &str {
        &self.name
    }

    fn send(&mut self, frame: &Frame) -> Result<Sent, BusError> {
        let mut hub = self.hub.lock();
        let index = self.index;
        self.tx
            .send(frame, &mut self.stats, |f| Self::write(&mut hub, index, f))
    }

    fn flush(&mut self) -> Result<usize, BusError> {
        let mut hub = self.hub.lock();
        let index = self.index;
        self.tx
            .flush(&mut self.stats, |f| Self::write(&mut hub, index, f))
    }

    fn queued(&self) -> usize {
        self.tx.queue.len()
    }

    fn recv(&mut self) -> Result<Option<TimedFrame>, BusError> {
        let mut hub = self.hub.lock();
        let Some(e) = hub.endpoints.get_mut(self.index) else {
            return Ok(None);
        };
        self.stats.rx_overflow = e.overflow;
        let frame = e.queue.pop_front();
        if e.queue.is_empty() {
            // Consume the wake-ups under the lock: a sender writes its byte under it too.
            let mut buf = [0u8; 256];
            while matches!((&self.wake).read(&mut buf), Ok(n) if n > 0) {}
        }
        if frame.is_some() {
            self.stats.received += 1;
        }
        Ok(frame)
    }

    fn wait_fd(&self) -> Option<RawFd> {
        Some(self.wake.as_raw_fd())
    }

    fn state(&mut self) -> Result<Option<BusState>, BusError> {
        Ok(Some(self.hub.state()))
    }

    fn restart(&mut self) -> Result<(), BusError> {
        let mut hub = self.hub.lock();
        if hub.state == BusState::BusOff {
            hub.set_state(BusState::ErrorActive);
        }
        Ok(())
    }

    fn stats(&self) -> BusStats {
        self.stats
    }
}

// ---------------------------------------------------------------------------------------------
// SocketCAN

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
