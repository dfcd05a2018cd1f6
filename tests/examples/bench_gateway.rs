//! What the gateway costs (docs/benchmarks.md): the round trip of an event program -> player ->
//! program (the player's call back), with the program on another "computer" (its own iceoryx2
//! root, joined by two `petrel gateway` over zenoh on loopback) and on the player's own
//! computer; against, in the same run, zenoh's own ping-pong (put, reply, between two
//! processes) and a TCP round trip (two processes, TCP_NODELAY); the throughput of events
//! across the link (a window of events in flight, each answered by a call); and the memory of
//! the gateways beside the player's.
//!
//! ```sh
//! cargo build --release --bin petrel
//! cargo run --release -p petrel-tests --example bench_gateway -- 2000 20000
//! ```

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use petrel_programs::{Program, Value};
use zenoh::Wait;

const WINDOW: usize = 64;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    // The responders of the baselines, run as child processes of this one.
    match args.get(1).map(String::as_str) {
        Some("--zenoh-echo") => return zenoh_echo(&args[2]),
        Some("--tcp-echo") => return tcp_echo(&args[2]),
        _ => {}
    }
    let round_trips: usize = args.get(1).and_then(|a| a.parse().ok()).unwrap_or(2000);
    let flood: usize = args.get(2).and_then(|a| a.parse().ok()).unwrap_or(20000);

    let work = tempfile::Builder::new()
        .prefix("pgb")
        .tempdir_in("/tmp")
        .expect("a work directory");
    let (root_a, root_b) = (work.path().join("a"), work.path().join("b"));
    std::fs::create_dir_all(&root_a).expect("root a");
    std::fs::create_dir_all(&root_b).expect("root b");
    // This process is computer B: the programs' computer.
    std::env::set_var("PETREL_RUNTIME_DIR", &root_b);
    let project = write_project(work.path());
    let petrel = petrel_tests::petrel_bin();
    let vehicle = format!("gwb{}", std::process::id());
    let local = format!("gwl{}", std::process::id());

    // The gateways secure their link as by default: one machine, so they make the vehicle's
    // keys at their first start, here in the run's directory (removed with it).
    let state = work.path().join("state");
    let spawn = |root: &Path, args: &[&str], log: &str| -> Child {
        Command::new(&petrel)
            .env("PETREL_RUNTIME_DIR", root)
            .env(petrel_gateway::keys::STATE_DIR_ENV, &state)
            .args(args)
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(work.path().join(log)).expect("log"))
            .spawn()
            .expect("petrel starts")
    };
    let dir = project.display().to_string();
    let mut children = vec![
        spawn(
            &root_a,
            &["play", &dir, "--vehicle", &vehicle, "--no-journal"],
            "player-a.log",
        ),
        spawn(
            &root_a,
            &["gateway", &dir, "--vehicle", &vehicle, "--computer", "A"],
            "gw-a.log",
        ),
        spawn(
            &root_b,
            &["gateway", &dir, "--vehicle", &vehicle, "--computer", "B"],
            "gw-b.log",
        ),
        // The baseline: the same project, its player on this computer.
        spawn(
            &root_b,
            &["play", &dir, "--vehicle", &local, "--no-journal"],
            "player-local.log",
        ),
    ];

    let mut remote = Program::connect(&vehicle, "BENCH").expect("BENCH joins the vehicle");
    let mut near = Program::connect(&local, "BENCH").expect("BENCH joins the local vehicle");
    warm_up(&mut remote, "across the gateway");
    warm_up(&mut near, "on one computer");

    // Interleave the rounds so that the machine's load falls on both alike.
    let mut rt_remote = Vec::new();
    let mut rt_near = Vec::new();
    let rounds = 4;
    for _ in 0..rounds {
        rt_near.extend(round_trip(&mut near, round_trips / rounds));
        rt_remote.extend(round_trip(&mut remote, round_trips / rounds));
    }
    let zenoh_rt = zenoh_ping(round_trips);
    let tcp_rt = tcp_ping(round_trips);
    let tp_near = throughput(&mut near, flood);
    let tp_remote = throughput(&mut remote, flood);

    let rss = |c: &Child| memory(c.id());
    let mem = [
        ("player (A)", rss(&children[0])),
        ("gateway A", rss(&children[1])),
        ("gateway B", rss(&children[2])),
    ];

    let base = median(&mut tcp_rt.clone());
    println!("round trip, {round_trips} each (us): p50, p90, p99, max; ratio of p50 to TCP's");
    println!("| what | p50 | p90 | p99 | max | p50 / TCP |");
    println!("|---|---:|---:|---:|---:|---:|");
    for (name, mut v) in [
        ("TCP ping-pong (two processes, loopback)", tcp_rt),
        ("zenoh ping-pong (two sessions, loopback)", zenoh_rt),
        ("event -> player -> call, one computer", rt_near),
        ("event -> player -> call, across the gateways", rt_remote),
    ] {
        v.sort();
        let q = |p: f64| v[((v.len() as f64 * p) as usize).min(v.len() - 1)];
        println!(
            "| {name} | {:.0} | {:.0} | {:.0} | {:.0} | {:.1} |",
            us(q(0.5)),
            us(q(0.9)),
            us(q(0.99)),
            us(*v.last().unwrap_or(&Duration::ZERO)),
            us(q(0.5)) / us(base).max(0.001)
        );
    }
    println!();
    println!("throughput, {flood} events, {WINDOW} in flight, each answered by a call:");
    println!("| where | events/s | ratio to one computer |");
    println!("|---|---:|---:|");
    println!("| one computer | {tp_near:.0} | 1.00 |");
    println!(
        "| across the gateways | {tp_remote:.0} | {:.2} |",
        tp_remote / tp_near
    );
    println!();
    println!(
        "memory after the runs, KiB (/proc/PID/status: resident, its peak, and of it: heap and"
    );
    println!("stacks, the executable's mapped pages, shared memory):");
    println!("| process | VmRSS | VmHWM | RssAnon | RssFile | RssShmem |");
    println!("|---|---:|---:|---:|---:|---:|");
    for (name, m) in mem {
        println!(
            "| {name} | {} | {} | {} | {} | {} |",
            m[0], m[1], m[2], m[3], m[4]
        );
    }

    drop(remote);
    drop(near);
    for c in &children {
        let _ = Command::new("kill")
            .args(["-TERM", &c.id().to_string()])
            .status();
    }
    for c in &mut children {
        let _ = c.wait();
    }
}

fn us(d: Duration) -> f64 {
    d.as_secs_f64() * 1e6
}

fn median(v: &mut [Duration]) -> Duration {
    v.sort();
    v[v.len() / 2]
}

fn write_project(dir: &Path) -> PathBuf {
    let p = dir.join("project");
    std::fs::create_dir_all(&p).expect("project");
    std::fs::write(
        p.join("petrel.toml"),
        r#"[project]
name = "gwbench"
files = ["bench.pn"]
start = ["ECHO"]

[events]
ping = { category = "nominal", params = ["n: int"] }

[programs.BENCH]
functions = { pong = ["n: int"] }
"#,
    )
    .expect("petrel.toml");
    std::fs::write(
        p.join("bench.pn"),
        "net ECHO {\n    place idle = 1\n\n    transition echo on ping(n): idle -> idle {\n        call BENCH.pong(n)\n    }\n}\n",
    )
    .expect("bench.pn");
    let port = |_| {
        TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .map(|a| a.port())
            .expect("a port")
    };
    std::fs::write(
        p.join("vehicle.toml"),
        format!(
            "[computers.A]\ngateway = \"tcp/127.0.0.1:{}\"\n[computers.B]\ngateway = \"tcp/127.0.0.1:{}\"\n\n[[process]]\nname = \"player\"\nkind = \"player\"\ncomputer = \"A\"\n\n[[process]]\nname = \"bench\"\nkind = \"program\"\nprograms = [\"BENCH\"]\ncomputer = \"B\"\nexecutable = \"true\"\n",
            port(0),
            port(1)
        ),
    )
    .expect("vehicle.toml");
    p
}

/// Sends pings until one is answered (the gateways and stand-ins are up).
fn warm_up(p: &mut Program, what: &str) {
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        assert!(Instant::now() < deadline, "no answer {what} within 60 s");
        let _ = p.emit("ping", vec![Value::Int(0)]);
        let until = Instant::now() + Duration::from_millis(500);
        while Instant::now() < until {
            if let Ok(Some(c)) = p.recv(Some(Duration::from_millis(50))) {
                if c.function == "pong" {
                    // Drain what earlier tries may still bring.
                    while let Ok(Some(_)) = p.recv(Some(Duration::from_millis(300))) {}
                    return;
                }
            }
        }
    }
}

fn round_trip(p: &mut Program, n: usize) -> Vec<Duration> {
    let mut out = Vec::with_capacity(n);
    for i in 1..=n as i64 {
        let t = Instant::now();
        p.emit("ping", vec![Value::Int(i)]).expect("emit");
        loop {
            match p.recv(Some(Duration::from_secs(10))) {
                Ok(Some(c)) if c.args.first() == Some(&Value::Int(i)) => break,
                Ok(Some(_)) => {}
                Ok(None) => panic!("no answer to ping({i}) within 10 s"),
                Err(e) => panic!("{e}"),
            }
        }
        out.push(t.elapsed());
    }
    out
}

fn throughput(p: &mut Program, n: usize) -> f64 {
    let start = Instant::now();
    let (mut sent, mut answered) = (0usize, 0usize);
    while answered < n {
        while sent < n && sent - answered < WINDOW {
            sent += 1;
            p.emit("ping", vec![Value::Int(sent as i64)]).expect("emit");
        }
        match p.recv(Some(Duration::from_secs(10))) {
            Ok(Some(_)) => answered += 1,
            Ok(None) => panic!("stalled at {answered} of {n} answered"),
            Err(e) => panic!("{e}"),
        }
    }
    n as f64 / start.elapsed().as_secs_f64()
}

fn memory(pid: u32) -> [u64; 5] {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap_or_default();
    let field = |name: &str| {
        status
            .lines()
            .find(|l| l.starts_with(name))
            .and_then(|l| l.split_whitespace().nth(1))
            .and_then(|v| v.parse().ok())
            .unwrap_or(0)
    };
    [
        field("VmRSS:"),
        field("VmHWM:"),
        field("RssAnon:"),
        field("RssFile:"),
        field("RssShmem:"),
    ]
}

fn zenoh_config(listen: Option<&str>, connect: Option<&str>) -> zenoh::Config {
    let doc = serde_json::json!({
        "mode": "peer",
        "listen": { "endpoints": listen.into_iter().collect::<Vec<_>>() },
        "connect": { "endpoints": connect.into_iter().collect::<Vec<_>>() },
        "scouting": { "multicast": { "enabled": false }, "gossip": { "enabled": false } },
    });
    zenoh::Config::from_json5(&doc.to_string()).expect("zenoh config")
}

/// zenoh's ping-pong responder: every put on `bench/ping` is put back on `bench/pong`.
fn zenoh_echo(endpoint: &str) {
    let session = zenoh::open(zenoh_config(Some(endpoint), None))
        .wait()
        .expect("zenoh session");
    let publisher = session
        .declare_publisher("bench/pong")
        .congestion_control(zenoh::qos::CongestionControl::Block)
        .wait()
        .expect("publisher");
    let sub = session
        .declare_subscriber("bench/ping")
        .wait()
        .expect("subscriber");
    while let Ok(sample) = sub.recv() {
        let _ = publisher
            .put(sample.payload().to_bytes().into_owned())
            .wait();
    }
}

fn zenoh_ping(n: usize) -> Vec<Duration> {
    let port = TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a port");
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let mut echo = Command::new(std::env::current_exe().expect("this program"))
        .args(["--zenoh-echo", &endpoint])
        .spawn()
        .expect("the zenoh responder starts");
    let session = zenoh::open(zenoh_config(None, Some(&endpoint)))
        .wait()
        .expect("zenoh session");
    let publisher = session
        .declare_publisher("bench/ping")
        .congestion_control(zenoh::qos::CongestionControl::Block)
        .wait()
        .expect("publisher");
    let sub = session
        .declare_subscriber("bench/pong")
        .wait()
        .expect("subscriber");
    // A payload the size of a link message carrying a small event.
    let payload = vec![7u8; 64];
    // Until the responder answers.
    loop {
        publisher.put(payload.clone()).wait().expect("put");
        if let Ok(Some(_)) = sub.recv_timeout(Duration::from_millis(200)) {
            break;
        }
    }
    while let Ok(Some(_)) = sub.recv_timeout(Duration::from_millis(300)) {}
    let mut out = Vec::with_capacity(n);
    for _ in 0..n {
        let t = Instant::now();
        publisher.put(payload.clone()).wait().expect("put");
        sub.recv().expect("pong");
        out.push(t.elapsed());
    }
    let _ = echo.kill();
    let _ = echo.wait();
    out
}

fn tcp_echo(port: &str) {
    let listener = TcpListener::bind(format!("127.0.0.1:{port}")).expect("bind");
    if let Ok((mut s, _)) = listener.accept() {
        let _ = s.set_nodelay(true);
        let mut buf = [0u8; 64];
        while s.read_exact(&mut buf).is_ok() {
            if s.write_all(&buf).is_err() {
                break;
            }
        }
    }
}

fn tcp_ping(n: usize) -> Vec<Duration> {
    let port = TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a port");
    let mut echo = Command::new(std::env::current_exe().expect("this program"))
        .args(["--tcp-echo", &port.to_string()])
        .spawn()
        .expect("the TCP responder starts");
    let mut s = loop {
        match TcpStream::connect(("127.0.0.1", port)) {
            Ok(s) => break s,
            Err(_) => std::thread::sleep(Duration::from_millis(20)),
        }
    };
    s.set_nodelay(true).expect("nodelay");
    let mut buf = [7u8; 64];
    let mut out = Vec::with_capacity(n);
    for _ in 0..n {
        let t = Instant::now();
        s.write_all(&buf).expect("write");
        s.read_exact(&mut buf).expect("read");
        out.push(t.elapsed());
    }
    drop(s);
    let _ = echo.wait();
    out
}
