//! The in-process bus: endpoints of a [`MemoryHub`] that see each other's frames, for machines
//! without SocketCAN and for tests, with fault injection (error frames, bus states, a blocked
//! transmitter).

use std::collections::VecDeque;
use std::io::{self, Read, Write};
use std::os::fd::{AsRawFd, RawFd};
use std::os::unix::net::UnixStream;
use std::sync::{Arc, Mutex, MutexGuard};

use super::{Bus, BusError, BusStats, Sent, TxQueue, Write1, DEFAULT_TX_QUEUE};
use crate::bus_state::BusState;
use crate::clock::Clock;
use crate::frame::{err, Frame, TimedFrame};

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
