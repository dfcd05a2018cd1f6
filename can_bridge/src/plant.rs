//! A simulated vehicle on the bus, hosted by its data server: the [`Plant`] trait (frames in,
//! frames out, time given), and the host loop that runs one on any bus ([`run_plant`]), or on
//! a [`MemoryHub`] endpoint on its own thread ([`spawn_plant`]).
//!
//! The memory bus lives inside the data server's process, so a vehicle's simulator on it is a
//! plant the server hosts: each vehicle with a simulator builds its own data server on
//! [`crate::command`] with a factory of its plant (the AUV of `vehicles/auv`, `auv-bridge`;
//! Redermor's, `redermor-bridge`). On a SocketCAN bus the same plant runs as a process of its
//! own ([`run_plant`] over a [`crate::bus::SocketCanBus`], as `redermor-sim` does).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use crate::bus::{Bus, MemoryHub};
use crate::clock::Clock;
use crate::dbc::Dbc;
use crate::frame::Frame;

/// A simulated vehicle on a bus, sans-I/O: frames in, frames out, time given (the AUV of
/// `vehicles/auv`, the Redermor simulator of `vehicles/redermor/live`).
pub trait Plant: Send {
    /// Takes a frame seen on the bus at `time_us` (the bus's clock).
    fn on_frame(&mut self, time_us: u64, frame: &Frame);

    /// Advances the vehicle to `time_us` and returns the frames its sensors send.
    fn step(&mut self, time_us: u64) -> Vec<Frame>;

    /// How often [`Plant::step`] is to be called.
    fn period(&self) -> Duration {
        Duration::from_millis(100)
    }
}

/// Makes a vehicle's plant from the project's DBC, or says why it cannot (a file of the
/// simulator's that does not read): what a vehicle's data server gives [`crate::command::main`].
pub type PlantFactory = Box<dyn FnOnce(Arc<Dbc>) -> Result<Box<dyn Plant>, String>>;

/// Runs `plant` on `hub`, stepping it every [`Plant::period`] on the hub's clock, until `stop`
/// is set (or the process ends).
pub fn spawn_plant(
    hub: &MemoryHub,
    mut plant: Box<dyn Plant>,
    stop: Arc<AtomicBool>,
) -> std::io::Result<std::thread::JoinHandle<()>> {
    let mut node = hub.endpoint("sim")?;
    let clock = hub.clock();
    Ok(std::thread::spawn(move || {
        run_plant(&mut node, plant.as_mut(), clock.as_ref(), &stop);
    }))
}

/// The host loop of a plant, whatever the bus: every [`Plant::period`], the frames received
/// since the last tick go into the plant (at their receive times), then the frames of its
/// step go out at `clock`'s time; until `stop` is set. The memory bus's thread
/// ([`spawn_plant`]) and a simulator process on a SocketCAN interface (`redermor-sim`) both run
/// it, so one plant behaves the same on both. `clock` must be the bus's receive clock (the
/// hub's, or [`crate::clock::SystemClock`] for SocketCAN's kernel timestamps).
pub fn run_plant(bus: &mut dyn Bus, plant: &mut dyn Plant, clock: &dyn Clock, stop: &AtomicBool) {
    let period = plant.period();
    while !stop.load(Ordering::Relaxed) {
        // A read error (an interface down) ends this tick's reading: the vehicle's sensors
        // go on, as a real one's would, and the data server sees what the bus lets through.
        while let Ok(Some(tf)) = bus.recv() {
            plant.on_frame(tf.time_us, &tf.frame);
        }
        // Frames still waiting from the last tick go first, in order.
        let _ = bus.flush();
        for frame in plant.step(clock.now_us()) {
            // A full bus only delays the next sample: the plant speaks again next tick.
            let _ = bus.send(&frame);
        }
        std::thread::sleep(period);
    }
}
