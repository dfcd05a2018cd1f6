//! The vehicle path: a sensor frame on the bus -> data server rule -> event -> transition ->
//! call to CAN -> command frame on the bus, timed by a node on the bus (the probe), the way a
//! thruster node would see it; against a bare echo of the same frame on the same bus.
//!
//! On the in-memory bus the probe is a thread of the data server's process (the bus lives in
//! that process); on SocketCAN (vcan0, in the VM) the probe, the echo, the data server
//! and the player are processes of their own.

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use petrel_can_bridge::bus::{Bus, SocketCanOptions};
use petrel_can_bridge::{
    BridgeCore, CanConfig, CanId, Clock, Dbc, Frame, MemoryHub, SocketCanBus, SystemClock,
};
use petrel_ipc::{FdSource, Reactor, Vehicle, WaitStrategy};

use crate::measure::{clear_vehicle, vehicle_name, Kid, Settings};
use crate::project::{ping_payload, pong_seq, PING_ID, PONG_ID};
use crate::roles::{err, Res};
use crate::stats::Latencies;

/// Reads the vehicle project's can.toml and DBC.
pub fn load_can(dir: &Path) -> Res<(CanConfig, Dbc)> {
    let (mut loaded, compiled, mut diags) =
        petrel_nets::project::load_and_check(dir).map_err(|e| format!("{e:?}"))?;
    let compiled = compiled.ok_or_else(|| format!("project errors: {diags:?}"))?;
    let can = petrel_can_bridge::load_project_can(dir, &compiled, &mut loaded.sources, &mut diags)
        .map_err(|e| e.to_string())?;
    if diags.has_errors() {
        return Err(format!("can.toml errors: {diags:?}"));
    }
    can.ok_or_else(|| "no can.toml".to_owned())
}

fn frame(id: u32, payload: &[u8]) -> Res<Frame> {
    let id = CanId::standard(id).ok_or("bad CAN id")?;
    Frame::data(id, payload).map_err(err("frame"))
}

/// Waits for the frame with `id` carrying `seq` (any sequence number with `seq` None) on
/// `bus`, sleeping on its descriptor.
fn await_frame<B: Bus>(
    bus: &mut B,
    reactor: &Reactor,
    fd: &FdSource,
    id: u32,
    seq: Option<u32>,
    deadline: Instant,
) -> Res<()> {
    loop {
        while let Some(f) = bus.recv().map_err(err("bus read"))? {
            if f.frame.id().raw() == id && (seq.is_none() || pong_seq(f.frame.payload()) == seq) {
                return Ok(());
            }
        }
        let now = Instant::now();
        if now > deadline {
            return Err(format!("no frame {id:#x} for round {seq:?} on the bus"));
        }
        reactor
            .wait(
                &[fd],
                Some((deadline - now).min(Duration::from_millis(100))),
            )
            .map_err(|e| e.to_string())?;
    }
}

/// The probe: writes Ping(seq) and times the Pong(seq) that comes back.
pub fn probe<B: Bus>(bus: &mut B, s: &Settings) -> Res<Latencies> {
    let reactor =
        Reactor::without_signal_handling(WaitStrategy::Block).map_err(|e| e.to_string())?;
    let fd = FdSource::new(bus.wait_fd().ok_or("the bus has no descriptor")?)
        .map_err(|e| e.to_string())?;
    // Until the other side answers (a data server and a player starting up miss frames),
    // a Ping every half second, each an edge for the rule.
    let mut base = 0u32;
    let synced = Instant::now();
    loop {
        bus.send(&frame(PING_ID, &ping_payload(base))?)
            .map_err(err("bus write"))?;
        bus.flush().map_err(err("bus flush"))?;
        base += 1;
        let wait = Instant::now() + Duration::from_millis(500);
        match await_frame(bus, &reactor, &fd, PONG_ID, None, wait) {
            Ok(()) => break,
            Err(_) if synced.elapsed() < Duration::from_secs(60) => {}
            Err(_) => return Err("nothing answered the probe's Ping frames in 60 s".to_owned()),
        }
    }
    let mut lat = Latencies::new();
    let start = Instant::now();
    let mut done = 0;
    for i in 0..(s.warmup + s.rounds) as u32 {
        if i as usize >= s.warmup && start.elapsed() > s.max {
            break;
        }
        let seq = base + i;
        let t = Instant::now();
        bus.send(&frame(PING_ID, &ping_payload(seq))?)
            .map_err(err("bus write"))?;
        bus.flush().map_err(err("bus flush"))?;
        await_frame(
            bus,
            &reactor,
            &fd,
            PONG_ID,
            Some(seq),
            t + Duration::from_secs(10),
        )?;
        if i as usize >= s.warmup {
            lat.record(t.elapsed());
            done += 1;
        }
    }
    lat.cut_short = (s.rounds - done) as u64;
    Ok(lat)
}

/// The baseline's other side: echoes every Ping(seq) as Pong(seq), sleeping on the bus's
/// descriptor, until `stop`.
pub fn echo<B: Bus>(bus: &mut B, stop: &AtomicBool) -> Res<()> {
    let reactor =
        Reactor::without_signal_handling(WaitStrategy::Block).map_err(|e| e.to_string())?;
    let fd = FdSource::new(bus.wait_fd().ok_or("the bus has no descriptor")?)
        .map_err(|e| e.to_string())?;
    while !stop.load(Ordering::Relaxed) {
        while let Some(f) = bus.recv().map_err(err("bus read"))? {
            if f.frame.id().raw() == PING_ID {
                if let Some(seq) = pong_seq(f.frame.payload()) {
                    bus.send(&frame(PONG_ID, &ping_payload(seq))?)
                        .map_err(err("bus write"))?;
                    bus.flush().map_err(err("bus flush"))?;
                }
            }
        }
        reactor
            .wait(&[&fd], Some(Duration::from_millis(50)))
            .map_err(|e| e.to_string())?;
    }
    Ok(())
}

/// The bare echo on the in-memory bus: probe and echo threads on one hub.
pub fn memory_baseline(s: &Settings) -> Res<Latencies> {
    let clock: Arc<dyn Clock> = Arc::new(SystemClock);
    let hub = MemoryHub::new(clock);
    let mut probe_bus = hub.endpoint("probe").map_err(err("endpoint"))?;
    let mut echo_bus = hub.endpoint("echo").map_err(err("endpoint"))?;
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    let echoer = std::thread::spawn(move || echo(&mut echo_bus, &flag));
    let r = probe(&mut probe_bus, s);
    stop.store(true, Ordering::Relaxed);
    let e = echoer
        .join()
        .map_err(|_| "the echo thread panicked".to_owned())?;
    e?;
    r
}

/// The whole path on the in-memory bus: the player a process of its own, the data server and
/// the probe threads of this process, with `wait` in the player and the data server.
pub fn memory_path(s: &Settings, wait: WaitStrategy) -> Res<Latencies> {
    let dir = tempfile::tempdir().map_err(err("tempdir"))?;
    crate::project::write_vehicle(dir.path(), "vcan0").map_err(err("project"))?;
    let (config, dbc) = load_can(dir.path())?;
    let vehicle = vehicle_name("vm");
    let wait_s = wait.to_string();
    let player = Kid::role(&[
        "player",
        "--dir",
        &dir.path().display().to_string(),
        "--vehicle",
        &vehicle,
        "--wait",
        &wait_s,
        "--journal",
        &dir.path().join("journal").display().to_string(),
    ])?;
    let clock: Arc<dyn Clock> = Arc::new(SystemClock);
    let hub = MemoryHub::new(clock.clone());
    let bridge_bus = hub.endpoint("bridge").map_err(err("endpoint"))?;
    let mut probe_bus = hub.endpoint("probe").map_err(err("endpoint"))?;
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    let v = Vehicle::new(&vehicle).map_err(|e| e.to_string())?;
    let bridge = std::thread::spawn(move || {
        let core = BridgeCore::new(Arc::new(dbc), config, clock.now_us());
        let opts = petrel_can_bridge::runtime::RuntimeOptions {
            wait,
            handle_signals: false,
            ack_grace: Duration::from_millis(200),
            ..Default::default()
        };
        petrel_can_bridge::runtime::run(core, move || Ok(bridge_bus), clock, &v, opts, &flag)
            .map(|_| ())
            .map_err(|e| e.to_string())
    });
    let r = probe(&mut probe_bus, s);
    stop.store(true, Ordering::Relaxed);
    let b = bridge
        .join()
        .map_err(|_| "the data server's thread panicked".to_owned())?;
    let _ = player.terminate(Duration::from_secs(5));
    clear_vehicle(&vehicle);
    b?;
    r
}

/// A SocketCAN interface as the probe or the echo uses it.
pub fn socketcan(iface: &str) -> Res<SocketCanBus> {
    SocketCanBus::open(iface, &SocketCanOptions::default()).map_err(|e| format!("{iface}: {e}"))
}

/// The vcan measurements, run where vcan0 exists (in the VM): the bare echo, then the whole
/// path per strategy, each printed as `BENCHHIST name` and the histogram's text, ended by
/// `BENCHEND`.
pub fn vcan_all(s: &Settings, iface: &str) -> Res<()> {
    let print = |name: &str, r: Res<Latencies>| match r {
        Ok(l) => {
            println!("BENCHHIST {name}");
            print!("{}", l.to_text());
            println!("BENCHEND");
        }
        Err(e) => println!("BENCHERR {name} {e}"),
    };
    print("echo", vcan_baseline(s, iface));
    for wait in crate::measure::strategies() {
        print(&wait.to_string(), vcan_path(s, iface, wait));
    }
    Ok(())
}

/// The bare SocketCAN echo: this process probes, another echoes.
pub fn vcan_baseline(s: &Settings, iface: &str) -> Res<Latencies> {
    let mut bus = socketcan(iface)?;
    let mut echo = Kid::role(&["can-echo", "--iface", iface])?;
    echo.ready()?;
    let r = probe(&mut bus, s);
    let _ = echo.finish();
    r
}

/// The whole path on SocketCAN: player and data server processes, this process probes.
pub fn vcan_path(s: &Settings, iface: &str, wait: WaitStrategy) -> Res<Latencies> {
    let dir = tempfile::tempdir().map_err(err("tempdir"))?;
    crate::project::write_vehicle(dir.path(), iface).map_err(err("project"))?;
    let vehicle = vehicle_name("vc");
    let wait_s = wait.to_string();
    let d = dir.path().display().to_string();
    let mut bus = socketcan(iface)?;
    let player = Kid::role(&[
        "player",
        "--dir",
        &d,
        "--vehicle",
        &vehicle,
        "--wait",
        &wait_s,
        "--journal",
        &dir.path().join("journal").display().to_string(),
    ])?;
    let bridge = Kid::role(&[
        "bridge",
        "--dir",
        &d,
        "--vehicle",
        &vehicle,
        "--iface",
        iface,
        "--wait",
        &wait_s,
    ])?;
    let r = probe(&mut bus, s);
    let _ = bridge.terminate(Duration::from_secs(5));
    let _ = player.terminate(Duration::from_secs(5));
    clear_vehicle(&vehicle);
    r
}

/// The data server on a SocketCAN interface (what `petrel bridge --bus IFACE` runs).
pub fn bridge_role(dir: &Path, vehicle: &str, iface: &str, wait: WaitStrategy) -> Res<()> {
    let (config, dbc) = load_can(dir)?;
    let v = Vehicle::new(vehicle).map_err(|e| e.to_string())?;
    let opts = petrel_can_bridge::serve::ServeOptions {
        bus: Some(iface.to_owned()),
        record: None,
        wait,
        plant: None,
    };
    petrel_can_bridge::serve::serve(&v, config, dbc, opts).map_err(|e| e.to_string())?;
    Ok(())
}

/// The echo of the SocketCAN baseline, until standard input closes.
pub fn can_echo_role(iface: &str) -> Res<()> {
    let stop = crate::roles::stop_on_stdin_eof();
    let mut bus = socketcan(iface)?;
    crate::roles::ready();
    echo(&mut bus, &stop)
}

/// Parses what [`vcan_all`] printed (within any other output).
pub fn parse_vcan(text: &str) -> Vec<(String, Res<Latencies>)> {
    let mut out = Vec::new();
    let mut lines = text.lines();
    while let Some(line) = lines.next() {
        let line = line.trim();
        if let Some(name) = line.strip_prefix("BENCHHIST ") {
            let mut body = String::new();
            for l in lines.by_ref() {
                if l.trim() == "BENCHEND" {
                    break;
                }
                body.push_str(l.trim());
                body.push('\n');
            }
            out.push((name.to_owned(), Latencies::from_text(&body)));
        } else if let Some(rest) = line.strip_prefix("BENCHERR ") {
            let (name, why) = rest.split_once(' ').unwrap_or((rest, ""));
            out.push((name.to_owned(), Err(why.to_owned())));
        }
    }
    out
}
