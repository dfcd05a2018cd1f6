//! The cost of `petrel monitor` to the player, and the time from a step to its display.
//!
//! `cargo run --release -p petrel-tests --example bench_monitor -- [EVENTS] [ROUNDS] [EVERY_MS]
//! [BEFORE]` (after `cargo build --release --bin petrel`; docs/benchmarks.md has the figures).
//! BEFORE: another `petrel` binary (the one of main, built in a scratch copy): everything is
//! measured with both, interleaved, and the ratios after / before come from the same run.
//!
//! 1. Throughput: a 40-net project (every event moves the token of each net: 80 places change
//!    per step) and a `petrel play --no-journal`; a sender floods it with EVENTS events as fast
//!    as the player's buffer takes them, and the time until the player's heartbeat says it has
//!    processed them all gives events per second. With 0, 1 and 5 `petrel monitor` processes
//!    following the vehicle, each with one event stream (`/api/events`) read as a page would,
//!    interleaved, best of ROUNDS; ratios to 0 monitors of the same run.
//! 2. Latency: one monitor and headless Chromium on its page; 200 events, one every EVERY_MS
//!    (20 by default). For
//!    each, the time from its sending to the player's marking delta at a plain subscriber in
//!    this process (the baseline: what the player itself takes), and to the page's first frame
//!    showing the step (`window.petrelMonitor.shownAt`, the page's clock; same machine).

use petrel_ipc::{EventMsg, Participant, Role, SendError, Vehicle};
use petrel_tests::web::{http, Browser, Monitor};
use petrel_tests::{petrel_bin, unique_vehicle, TempProject};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant, SystemTime};

fn many_nets(n: usize) -> TempProject {
    let mut nets = String::new();
    for i in 0..n {
        nets.push_str(&format!(
            "net N{i} {{\n    place a = 1\n    place b\n    transition go on tick: a -> b {{}}\n    transition back on tock: b -> a {{}}\n}}\n\n"
        ));
    }
    let start: Vec<String> = (0..n).map(|i| format!("\"N{i}\"")).collect();
    let manifest = format!(
        "[project]\nname = \"many\"\nfiles = [\"nets.pn\"]\nstart = [{}]\n\n[events]\ntick = {{ category = \"nominal\" }}\ntock = {{ category = \"nominal\" }}\n",
        start.join(", ")
    );
    TempProject::new(&[("petrel.toml", &manifest), ("nets.pn", &nets)])
}

struct Play(Child, String);

impl Play {
    fn start(bin: &Path, dir: &str, vehicle: &str) -> Play {
        let child = Command::new(bin)
            .args(["play", dir, "--vehicle", vehicle, "--no-journal"])
            .env("RUST_LOG", "error")
            .stderr(Stdio::null())
            .spawn()
            .expect("petrel play starts");
        Play(child, vehicle.to_string())
    }
}

impl Drop for Play {
    fn drop(&mut self) {
        let _ = Command::new("kill")
            .args(["-TERM", &self.0.id().to_string()])
            .status();
        let _ = self.0.wait();
        petrel_tests::forget_vehicle(&self.1);
    }
}

/// The player's latest heartbeat progress (steps published).
fn progress(beats: &petrel_ipc::HeartbeatSubscriber, last: &mut u64) -> u64 {
    let _ = beats.drain(|r| {
        if let Ok(rcv) = r {
            if rcv.origin.as_str() == "player" {
                *last = rcv.msg.progress;
            }
        }
    });
    *last
}

/// Reads a monitor's event stream as a page would, until the monitor goes.
fn read_stream(addr: std::net::SocketAddr) {
    std::thread::spawn(move || {
        use std::io::Write;
        let Ok(mut s) = std::net::TcpStream::connect(addr) else {
            return;
        };
        let _ = s.write_all(format!("GET /api/events HTTP/1.1\r\nHost: {addr}\r\n\r\n").as_bytes());
        let mut buf = [0u8; 65536];
        while matches!(s.read(&mut buf), Ok(n) if n > 0) {}
    });
}

/// CPU seconds (user and system) process `pid` has used so far (`/proc/PID/stat`).
fn cpu_seconds(pid: u32) -> f64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
    // Fields after the command (which may hold spaces) in parentheses.
    let rest = stat.rsplit_once(')').map(|x| x.1).unwrap_or_default();
    let f: Vec<f64> = rest
        .split_whitespace()
        .filter_map(|x| x.parse().ok())
        .collect();
    // utime and stime are fields 14 and 15 of the whole line: 11 and 12 after the state.
    let ticks = f.get(10).copied().unwrap_or(0.0) + f.get(11).copied().unwrap_or(0.0);
    ticks / 100.0
}

/// Events per second, the player's CPU microseconds per event, and the monitors' (all of them).
fn throughput(bin: &Path, dir: &str, monitors: usize, events: u64) -> (f64, f64, f64) {
    let vehicle = unique_vehicle("benchmon");
    let _player = Play::start(bin, dir, &vehicle);
    let v = Vehicle::new(&vehicle).unwrap();
    let me = Participant::join(&v, Role::tool("bench").unwrap()).unwrap();
    let _ = &_player;
    let beats = me.heartbeat_subscriber().unwrap();
    let mut last = 0;
    let deadline = Instant::now() + Duration::from_secs(20);
    while progress(&beats, &mut last) == 0 {
        assert!(Instant::now() < deadline, "the player did not start");
        std::thread::sleep(Duration::from_millis(10));
    }
    let mons: Vec<Monitor> = (0..monitors)
        .map(|_| Monitor::start_with(bin, &[dir, "--vehicle", &vehicle]))
        .collect();
    for m in &mons {
        while m.get("/api/marking").json()["synced"] != true {
            std::thread::sleep(Duration::from_millis(20));
        }
        read_stream(m.addr);
    }
    let tx = me.event_sender().unwrap();
    let msgs = [EventMsg::new("tick", vec![]), EventMsg::new("tock", vec![])];
    let start_steps = progress(&beats, &mut last);
    let player_pid = _player.0.id();
    let cpu0 = cpu_seconds(player_pid);
    let mons_cpu0: f64 = mons.iter().map(|m| cpu_seconds(m.pid())).sum();
    let t0 = Instant::now();
    for i in 0..events {
        loop {
            match tx.send(&msgs[(i % 2) as usize]) {
                Ok(_) => break,
                Err(e) if e.is_refusal() => std::thread::yield_now(),
                Err(SendError::NoReceiver { .. }) => panic!("the player is gone"),
                Err(e) => panic!("{e}"),
            }
        }
    }
    while progress(&beats, &mut last) < start_steps + events {
        std::thread::sleep(Duration::from_millis(1));
    }
    let rate = events as f64 / t0.elapsed().as_secs_f64();
    let player_us = (cpu_seconds(player_pid) - cpu0) * 1e6 / events as f64;
    let mons_cpu: f64 = mons.iter().map(|m| cpu_seconds(m.pid())).sum::<f64>() - mons_cpu0;
    drop(mons);
    (rate, player_us, mons_cpu * 1e6 / events as f64)
}

fn epoch_ms() -> f64 {
    SystemTime::now()
        .duration_since(SystemTime::UNIX_EPOCH)
        .map(|d| d.as_secs_f64() * 1e3)
        .unwrap_or(0.0)
}

fn percentile(v: &mut [f64], p: f64) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[((v.len() - 1) as f64 * p).round() as usize]
}

/// The four times of each of `events` steps (see the module's doc), the page opened at `page`.
type Latencies = (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>);

fn latency(bin: &Path, dir: &str, events: u64, every: Duration, page: &str) -> Latencies {
    let vehicle = unique_vehicle("benchlat");
    let _player = Play::start(bin, dir, &vehicle);
    let v = Vehicle::new(&vehicle).unwrap();
    let me = Participant::join(&v, Role::tool("benchlat").unwrap()).unwrap();
    let deltas = me.marking_subscriber().unwrap();
    let beats = me.heartbeat_subscriber().unwrap();
    let mut last = 0;
    while progress(&beats, &mut last) == 0 {
        std::thread::sleep(Duration::from_millis(10));
    }
    let monitor = Monitor::start_with(bin, &[dir, "--vehicle", &vehicle]);
    // A plain event-stream client beside the page: when each step leaves the monitor.
    let streamed = std::sync::Arc::new(std::sync::Mutex::new(std::collections::HashMap::new()));
    {
        let (addr, streamed) = (monitor.addr, streamed.clone());
        std::thread::spawn(move || {
            use std::io::{BufRead, Write};
            let Ok(mut s) = std::net::TcpStream::connect(addr) else {
                return;
            };
            let _ =
                s.write_all(format!("GET /api/events HTTP/1.1\r\nHost: {addr}\r\n\r\n").as_bytes());
            for line in std::io::BufReader::new(s).lines() {
                let Ok(line) = line else { break };
                if let Some(rest) = line.split_once("{\"type\":\"step\",\"step\":").map(|x| x.1) {
                    let n: String = rest.chars().take_while(char::is_ascii_digit).collect();
                    if let Ok(n) = n.parse::<u64>() {
                        if let Ok(mut m) = streamed.lock() {
                            m.insert(n, epoch_ms());
                        }
                    }
                }
            }
        });
    }
    let b = Browser::start();
    b.open(&monitor.url(page));
    b.wait_ready();
    b.wait_for(30.0, "return document.body.dataset.synced", |v| v == "true");
    let first = b
        .eval("return Number(document.body.dataset.step)")
        .as_u64()
        .unwrap_or(1);
    let tx = me.event_sender().unwrap();
    let msgs = [EventMsg::new("tick", vec![]), EventMsg::new("tock", vec![])];
    let mut sent_at = Vec::new();
    let mut player = Vec::new();
    for i in 0..events {
        let step = first + i;
        let t = epoch_ms();
        tx.send(&msgs[(i % 2) as usize]).expect("sent");
        sent_at.push((step, t));
        // The baseline: the player's delta for this step at a plain subscriber.
        let mut seen = None;
        while seen.is_none() {
            let _ = deltas.drain(|r| {
                if let Ok(rcv) = r {
                    if rcv.msg.step == step {
                        seen = Some(epoch_ms());
                    }
                }
            });
            if seen.is_none() {
                std::thread::yield_now();
            }
        }
        player.push(seen.unwrap_or(t) - t);
        std::thread::sleep(every);
    }
    let last_step = first + events - 1;
    b.wait_for(
        30.0,
        &format!("return window.petrelMonitor.shownAt[{last_step}] || 0"),
        |v| v.as_f64().is_some_and(|x| x > 0.0),
    );
    let shown = b.eval("return window.petrelMonitor.shownAt");
    let arrived = b.eval("return window.petrelMonitor.arrivedAt");
    let since = |m: &serde_json::Value| -> Vec<f64> {
        sent_at
            .iter()
            .filter_map(|(step, t)| m[step.to_string()].as_f64().map(|s| s - t))
            .collect()
    };
    let _ = http(monitor.addr, "GET", "/api/marking", &[], "");
    let streamed: Vec<f64> = {
        let m = streamed.lock().map(|m| m.clone()).unwrap_or_default();
        sent_at
            .iter()
            .filter_map(|(step, t)| m.get(step).map(|s| s - t))
            .collect()
    };
    (player, streamed, since(&arrived), since(&shown))
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let events: u64 = args.first().and_then(|a| a.parse().ok()).unwrap_or(200_000);
    let rounds: usize = args.get(1).and_then(|a| a.parse().ok()).unwrap_or(3);
    let every_ms: u64 = args.get(2).and_then(|a| a.parse().ok()).unwrap_or(20);
    let mut bins: Vec<(&str, PathBuf)> = vec![("after", petrel_bin())];
    if let Some(before) = args.get(3) {
        bins.insert(0, ("before", PathBuf::from(before)));
    }
    let project = many_nets(40);
    let dir = project.path().display().to_string();
    for (what, bin) in &bins {
        println!("{what}: {}", bin.display());
    }
    let counts = [0usize, 1, 5];
    // Per binary: best rate, least player CPU, least monitors' CPU, for each count.
    let mut best = vec![[0f64; 3]; bins.len()];
    let mut cpu = vec![[f64::MAX; 3]; bins.len()];
    let mut mon_cpu = vec![[f64::MAX; 3]; bins.len()];
    for round in 0..rounds {
        if events == 0 {
            break;
        }
        for (k, &m) in counts.iter().enumerate() {
            for (b, (what, bin)) in bins.iter().enumerate() {
                let (r, us, mus) = throughput(bin, &dir, m, events);
                println!("round {round}: {what}: {m} monitor(s): {r:.0} events/s, player {us:.1} us CPU/event, monitors {mus:.1} us CPU/event");
                best[b][k] = best[b][k].max(r);
                cpu[b][k] = cpu[b][k].min(us);
                mon_cpu[b][k] = mon_cpu[b][k].min(mus);
            }
        }
    }
    if events > 0 {
        println!("\n| petrel | monitors | events/s (best of {rounds}) | ratio to none | player CPU us/event (least) | ratio to none | monitors' CPU us/event | events/s after / before |\n|---|---:|---:|---:|---:|---:|---:|---:|");
        for (b, (what, _)) in bins.iter().enumerate() {
            for (k, &m) in counts.iter().enumerate() {
                let versus = if bins.len() == 2 {
                    format!("{:.2}", best[bins.len() - 1][k] / best[0][k])
                } else {
                    "-".into()
                };
                println!(
                    "| {what} | {m} | {:.0} | {:.2} | {:.1} | {:.2} | {:.1} | {versus} |",
                    best[b][k],
                    best[b][k] / best[b][0],
                    cpu[b][k],
                    cpu[b][k] / cpu[b][0],
                    mon_cpu[b][k]
                );
            }
        }
    }
    if !petrel_tests::web::browser_available() {
        return;
    }
    // The page as each opens it, and the new page's whole drawing too (the old one's view).
    let mut pages: Vec<(String, &Path, &str)> = Vec::new();
    for (what, bin) in &bins {
        pages.push((format!("{what}, page /"), bin.as_path(), "/"));
    }
    pages.push((
        "after, page /?view=all".into(),
        bins[bins.len() - 1].1.as_path(),
        "/?view=all",
    ));
    println!("\n200 events, one every {every_ms} ms; from sending an event to (ms):");
    println!("\n| petrel | what | p50 | p90 | p99 | max |\n|---|---|---:|---:|---:|---:|");
    for (what, bin, page) in pages {
        let (mut player, mut streamed, mut arrived, mut shown) =
            latency(bin, &dir, 200, Duration::from_millis(every_ms), page);
        for (step, v) in [
            ("the player's delta (a plain subscriber)", &mut player),
            ("its arrival at a plain event-stream client", &mut streamed),
            ("its arrival in the page", &mut arrived),
            ("its display in the page (next frame)", &mut shown),
        ] {
            if v.is_empty() {
                continue;
            }
            println!(
                "| {what} | {step} | {:.1} | {:.1} | {:.1} | {:.1} |",
                percentile(v, 0.5),
                percentile(v, 0.9),
                percentile(v, 0.99),
                percentile(v, 1.0)
            );
        }
        println!(
            "| {what} | steps seen by the page | {} of 200 | | | |",
            shown.len()
        );
    }
}
