//! SocketCAN: on a kernel with vcan0 (the qemu bench, or `modprobe vcan` and
//! `ip link add dev vcan0 type vcan && ip link set up vcan0`), frames go through a real
//! socket with kernel timestamps; elsewhere, opening fails with an error that says why.

use std::time::{Duration, Instant};

use petrel_can_bridge::bus::{Bus, SocketCanBus, SocketCanOptions};
use petrel_can_bridge::frame::{CanId, Frame};

/// The interface to use: `PETREL_VCAN` or `vcan0`.
fn interface() -> String {
    std::env::var("PETREL_VCAN").unwrap_or_else(|_| "vcan0".to_owned())
}

#[test]
fn socketcan_round_trip_or_a_clear_refusal() {
    let iface = interface();
    let mut a = match SocketCanBus::open(&iface, &SocketCanOptions::default()) {
        Ok(bus) => bus,
        Err(e) => {
            let text = e.to_string();
            eprintln!("no SocketCAN here: {text}");
            assert!(
                text.contains("SocketCAN") || text.contains("no such interface"),
                "the refusal does not say why: {text}"
            );
            if std::env::var_os("PETREL_REQUIRE_VCAN").is_some() {
                panic!("PETREL_REQUIRE_VCAN is set but {iface} cannot be opened: {text}");
            }
            return;
        }
    };
    let mut b = SocketCanBus::open(&iface, &SocketCanOptions::default()).unwrap();
    let frames = [
        Frame::data(CanId::Standard(0x200), &[0x0D, 0xAC, 0x5A]).unwrap(),
        Frame::data(CanId::Extended(0x18FF_0100), &[1, 2, 3, 4, 5, 6, 7, 8]).unwrap(),
        Frame::remote(CanId::Standard(0x123), 2).unwrap(),
    ];
    for f in &frames {
        a.send(f).unwrap();
    }
    let deadline = Instant::now() + Duration::from_secs(5);
    let mut got = Vec::new();
    while got.len() < frames.len() && Instant::now() < deadline {
        match b.recv().unwrap() {
            Some(tf) => got.push(tf),
            None => std::thread::sleep(Duration::from_millis(1)),
        }
    }
    let only: Vec<Frame> = got.iter().map(|t| t.frame).collect();
    assert_eq!(only, frames);
    // Kernel timestamps: microseconds since the epoch, within a minute of now.
    let now = petrel_can_bridge::clock::Clock::now_us(&petrel_can_bridge::SystemClock);
    assert!(got.iter().all(|t| t.time_us.abs_diff(now) < 60_000_000));
    // An error frame cannot be sent; a vcan reports no controller state.
    assert!(a.send(&Frame::error(0x40, [0; 8]).unwrap()).is_err());
    assert!(a.wait_fd().is_some());
    let _ = a.state();
}
