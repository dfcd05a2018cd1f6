//! A vehicle on two computers joined by `petrel gateway` (docs/gateway.md). Each "computer" is
//! its own iceoryx2 root (`PETREL_RUNTIME_DIR`: its own directory and shared-memory prefix), so
//! the two halves see nothing of each other but through zenoh on loopback.
//!
//! The project (tests/data/relay) is the same as on one computer: the player calls ECHO and
//! waits for its `pong`; nothing in it or in the program knows there are two computers.
//!
//! The link is secured as by default (mutual TLS with the vehicle's keys): the computers of a
//! test share one state directory in its work directory (one machine: the gateways make the
//! keys at their first start), except where a test gives each its own and distributes keys
//! made by `petrel keys`, as for a real vehicle.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use petrel_tests::{
    example_bin, journal_json, petrel_bin, repo, unique_vehicle, Processes, Workdir,
};

mod computers;

use computers::{
    distribute_keys, free_port, last_json, logs, rogue, rogue_report, verdict, Cable, Computer,
    Stopped,
};

/// tests/data/relay with a vehicle file: the player on A, ECHO on B.
fn project(work: &Workdir) -> PathBuf {
    let dir = work.path().join("relay");
    std::fs::create_dir_all(&dir).expect("project dir");
    for f in ["petrel.toml", "relay.pn"] {
        std::fs::copy(repo().join("tests/data/relay").join(f), dir.join(f)).expect("copy");
    }
    let vehicle = format!(
        r#"[computers.A]
gateway = "tcp/127.0.0.1:{}"
[computers.B]
gateway = "tcp/127.0.0.1:{}"

[link]
detection = "3s"
lost_event = "link_lost"
restored_event = "link_restored"

[[process]]
name = "player"
kind = "player"
computer = "A"

[[process]]
name = "echo"
kind = "program"
programs = ["ECHO"]
computer = "B"
executable = "{{target}}/examples/echo"
args = ["{{vehicle}}", "ECHO"]
"#,
        free_port(),
        free_port()
    );
    std::fs::write(dir.join("vehicle.toml"), vehicle).expect("vehicle.toml");
    dir
}

fn place(s: &serde_json::Value, net: &str, place: &str) -> bool {
    s["marking"][net]
        .as_array()
        .is_some_and(|a| a.iter().any(|p| p == place))
}

fn counts<'a>(s: &'a serde_json::Value, computer: &str, kind: &str) -> &'a serde_json::Value {
    &s["gateways"][computer]["counters"]["kinds"][kind]
}

/// Times A's gateway lost B.
fn losses_of(s: &serde_json::Value) -> u64 {
    s["gateways"]["A"]["peers"]["B"]["losses"]
        .as_u64()
        .unwrap_or(0)
}

/// Every link message of a kind a gateway heard is accounted for.
fn accounted(c: &serde_json::Value) -> bool {
    let n = |k: &str| c[k].as_u64().unwrap_or(0);
    n("from_link") == n("delivered") + n("refused") + n("not_mine") + n("unheard") + n("discarded")
}

#[test]
fn a_program_on_another_computer_answers_and_a_lost_computer_is_an_event() {
    let work = Workdir::new();
    let dir = project(&work);
    let vehicle = unique_vehicle("relay");
    let (a, b) = (Computer::new(&work, "A"), Computer::new(&work, "B"));
    let journal = work.path().join("journal");
    let player = a.spawn(
        &petrel_bin(),
        &[
            "play",
            &dir.display().to_string(),
            "--vehicle",
            &vehicle,
            "--journal",
            &journal.display().to_string(),
        ],
        "player",
    );
    let mut procs = Processes(vec![player]);
    procs.0.push(a.gateway(&dir, &vehicle, "gw-a"));
    procs.0.push(b.gateway(&dir, &vehicle, "gw-b"));
    procs
        .0
        .push(b.spawn(&example_bin("echo"), &[&vehicle, "ECHO"], "echo"));

    // ECHO lives on B, yet the player's computer sees it alive (the gateway's stand-in).
    a.wait_for(&dir, &vehicle, "ECHO alive on A", |s| {
        s["programs"]["ECHO"] == "alive"
    });
    // B has no player, yet its `petrel status` shows the player's (the heartbeat crossed).
    let on_b = b.wait_for(&dir, &vehicle, "the player's status on B", |s| {
        place(s, "RELAY", "ready")
    });
    assert_eq!(on_b["project"], "relay", "{on_b}");

    a.send(&dir, &vehicle, "start_mission");
    let s = a.wait_for(&dir, &vehicle, "the pong back", |s| {
        place(s, "RELAY", "ready") && counts(s, "A", "event")["delivered"] == 1
    });
    assert_eq!(s["stats"]["calls_sent"], 1, "{s}");
    assert_eq!(counts(&s, "A", "call")["to_link"], 1, "{s}");
    assert_eq!(counts(&s, "A", "event")["delivered"], 1, "{s}");

    // SIGKILL B's gateway mid-mission: A raises link_lost(B) within the bound and ECHO becomes
    // program_lost for the nets.
    // (A loaded machine may have starved a gateway past the bound before: count from here.)
    let losses = losses_of(&s);
    let mut gw_b = procs.0.remove(2);
    gw_b.kill().expect("SIGKILL");
    gw_b.wait().expect("reaped");
    let s = a.wait_for(&dir, &vehicle, "B lost", |s| {
        losses_of(s) > losses && place(s, "LINK", "down") && place(s, "PROGS", "gone")
    });
    assert_eq!(s["gateways"]["A"]["peers"]["B"]["state"], "lost", "{s}");

    // B's gateway back: link_restored(B), ECHO alive again, and it answers again.
    procs.0.push(b.gateway(&dir, &vehicle, "gw-b2"));
    a.wait_for(&dir, &vehicle, "B back", |s| {
        place(s, "LINK", "up") && s["programs"]["ECHO"] == "alive"
    });
    // This time from B, as a ground station would: the player's verdict comes back to
    // `petrel send` there, by its own sender id (the gateways translate the acknowledgement).
    let verdict = b.send(&dir, &vehicle, "start_mission");
    assert!(verdict.contains("1 taken and on record"), "{verdict}");
    let s = a.wait_for(&dir, &vehicle, "the second pong", |s| {
        // pong, start_mission from B, pong
        place(s, "RELAY", "ready") && counts(s, "A", "event")["delivered"] == 3
    });
    let peer = &s["gateways"]["A"]["peers"]["B"];
    let (lost, restored) = (peer["losses"].as_u64(), peer["restorations"].as_u64());
    for kind in ["event", "call", "beacon", "heartbeat", "marking"] {
        assert!(accounted(counts(&s, "A", kind)), "{kind}: {s}");
    }
    assert_eq!(s["gateways"]["A"]["peers"]["B"]["missing"], 0, "{s}");
    assert_eq!(s["gateways"]["A"]["peers"]["B"]["restarts"], 1, "{s}");
    let on_b = b.wait_for(&dir, &vehicle, "B's counters", |s| {
        counts(s, "B", "call")["delivered"] == 1
    });
    for kind in ["event", "call", "beacon", "heartbeat", "marking"] {
        assert!(accounted(counts(&on_b, "B", kind)), "{kind}: {on_b}");
    }
    // The second gateway put two events on the link (the operator's and ECHO's), and A
    // delivered three in all.
    assert_eq!(counts(&on_b, "B", "event")["to_link"], 2, "{on_b}");

    let codes = procs.stop();
    assert!(
        codes.iter().all(|c| *c == Some(0)),
        "{codes:?}: {}",
        logs(work.path())
    );
    // The journal: the pongs came from program/ECHO (the stand-in sends as the program), and
    // the link's loss and return are on record.
    let (entries, _) = journal_json(&journal);
    let submitted = |name: &str| {
        entries
            .iter()
            .filter(|e| e["kind"] == "submit" && e["event"] == name)
            .collect::<Vec<_>>()
    };
    let pongs = submitted("pong");
    assert_eq!(pongs.len(), 2, "{entries:?}");
    assert!(pongs.iter().all(|e| e["origin"]
        .as_str()
        .unwrap_or("")
        .starts_with("program/ECHO#")));
    // One link event per loss and return the gateway counted (one, but for a loaded machine
    // starving a gateway past the bound).
    assert_eq!(
        Some(submitted("link_lost").len() as u64),
        lost,
        "{entries:?}"
    );
    assert_eq!(submitted("link_lost")[0]["params"][0], "\"B\"");
    assert_eq!(
        Some(submitted("link_restored").len() as u64),
        restored,
        "{entries:?}"
    );
}

#[test]
fn a_link_event_must_be_a_communication_event_of_the_project() {
    let work = Workdir::new();
    let dir = project(&work);
    let text = std::fs::read_to_string(dir.join("vehicle.toml")).expect("vehicle.toml");
    std::fs::write(
        dir.join("vehicle.toml"),
        text.replace("lost_event = \"link_lost\"", "lost_event = \"pong\""),
    )
    .expect("vehicle.toml");
    let o = petrel_tests::petrel(&["check", &dir.display().to_string()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("E0812") && err.contains("communication"),
        "{err}"
    );
    // The gateway refuses to start on it, saying why.
    let o = petrel_tests::petrel(&["gateway", &dir.display().to_string(), "--computer", "A"]);
    assert_eq!(
        o.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
}

/// The link is secured by default. With computers not all on this machine, `petrel check`
/// says this machine has no keys and how to make them, and a gateway without its keys refuses
/// to start, saying the same; `petrel keys` makes them, and `petrel check` then says where.
/// The lab bench's opt-out (`[link] security = "none"`) is warned of by `petrel check` and by
/// the gateway as it starts.
#[test]
fn the_link_is_secured_by_default_and_its_opt_out_is_loud() {
    let work = Workdir::new();
    let dir = project(&work);
    let vehicle = unique_vehicle("keys");
    let file = std::fs::read_to_string(dir.join("vehicle.toml")).expect("vehicle.toml");
    let far = format!(
        "[vehicle]\nname = \"{vehicle}\"\n{}",
        file.replace("tcp/127.0.0.1:", "tcp/10.255.255.1:")
    );
    std::fs::write(dir.join("vehicle.toml"), &far).expect("vehicle.toml");
    let a = Computer::new(&work, "A");
    let run = |args: &[&str]| {
        let o = a
            .command(&petrel_bin())
            .args(args)
            .output()
            .expect("petrel runs");
        let text = |b: &[u8]| String::from_utf8_lossy(b).into_owned();
        (o.status.code(), text(&o.stdout), text(&o.stderr))
    };
    let d = dir.display().to_string();
    let (_, _, err) = run(&["check", &d, "--no-verify"]);
    assert!(
        err.contains("W0803") && err.contains("petrel keys"),
        "{err}"
    );
    let (code, _, err) = run(&["gateway", &d, "--computer", "A"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("no usable keys") && err.contains("petrel keys"),
        "{err}"
    );
    let (code, said, err) = run(&["keys", &d]);
    assert_eq!(code, Some(0), "{err}");
    assert!(
        said.contains("A.key") && said.contains("keep it off the vehicle"),
        "{said}"
    );
    let (code, said, err) = run(&["check", &d, "--no-verify"]);
    assert_eq!(code, Some(0), "{err}");
    assert!(
        said.contains("link: mutual TLS, keys of A, B in") && !err.contains("W08"),
        "{said}{err}"
    );

    // The opt-out.
    std::fs::write(
        dir.join("vehicle.toml"),
        far.replace("[link]\n", "[link]\nsecurity = \"none\"\n"),
    )
    .expect("vehicle.toml");
    let (code, said, err) = run(&["check", &d, "--no-verify"]);
    assert_eq!(code, Some(0), "{err}");
    let warning = "neither encrypted nor authenticated";
    assert!(
        err.contains("W0802") && err.contains(warning) && said.contains("NOT SECURED"),
        "{said}{err}"
    );
    let listen = format!("tcp/127.0.0.1:{}", free_port());
    let connect = format!("tcp/127.0.0.1:{}", free_port());
    let gateway = a.spawn(
        &petrel_bin(),
        &[
            "gateway",
            &d,
            "--computer",
            "A",
            "--listen",
            &listen,
            "--connect",
            &connect,
        ],
        "gw-open",
    );
    let gateway = Processes(vec![gateway]);
    let deadline = Instant::now() + Duration::from_secs(60);
    let log = loop {
        let log = std::fs::read_to_string(work.path().join("gw-open.log")).unwrap_or_default();
        if log.contains("up, link key") || Instant::now() > deadline {
            break log;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    assert!(
        log.contains(&format!(
            "WARNING: the link between the vehicle's computers is {warning}"
        )),
        "{log}"
    );
    assert_eq!(gateway.stop(), vec![Some(0)], "{log}");
}

/// tests/data/relay with ECHO and the player on A, a ground station G, and the gateways
/// authenticating each other with `password` (the credentials file of the copy).
fn ground_project(work: &Workdir, name: &str, ports: (u16, u16), password: &str) -> PathBuf {
    let dir = work.path().join(name);
    std::fs::create_dir_all(&dir).expect("project dir");
    for f in ["petrel.toml", "relay.pn"] {
        std::fs::copy(repo().join("tests/data/relay").join(f), dir.join(f)).expect("copy");
    }
    let vehicle = format!(
        r#"[computers.A]
gateway = "tcp/127.0.0.1:{}"
[computers.G]
gateway = "tcp/127.0.0.1:{}"

[link]
user = "petrel"
credentials = "link.txt"

[[process]]
name = "player"
kind = "player"
computer = "A"

[[process]]
name = "echo"
kind = "program"
programs = ["ECHO"]
computer = "A"
executable = "{{target}}/examples/echo"
args = ["{{vehicle}}", "ECHO"]
"#,
        ports.0, ports.1
    );
    std::fs::write(dir.join("vehicle.toml"), vehicle).expect("vehicle.toml");
    std::fs::write(dir.join("link.txt"), format!("petrel:{password}\n")).expect("link.txt");
    dir
}

#[test]
fn only_an_authenticated_ground_station_sends_events_and_its_shadow_follows() {
    let work = Workdir::new();
    let ports = (free_port(), free_port());
    let dir = ground_project(&work, "vehicle", ports, "s3cret");
    let impostor = ground_project(&work, "impostor", ports, "guessed");
    let vehicle = unique_vehicle("ground");
    let (a, g) = (Computer::new(&work, "A"), Computer::new(&work, "G"));
    let journal = work.path().join("journal");
    let mut procs = Processes(vec![a.spawn(
        &petrel_bin(),
        &[
            "play",
            &dir.display().to_string(),
            "--vehicle",
            &vehicle,
            "--journal",
            &journal.display().to_string(),
        ],
        "player",
    )]);
    // zenoh logs a refused password at debug level.
    let log = |ext: &str| std::fs::File::create(work.path().join(format!("gw-a.{ext}")));
    procs.0.push(
        a.command(&petrel_bin())
            .env(
                "RUST_LOG",
                "info,zenoh_transport::unicast::establishment=debug",
            )
            .arg("gateway")
            .arg(&dir)
            .args(["--vehicle", &vehicle, "--computer", "A"])
            .stdout(log("out").expect("log"))
            .stderr(log("log").expect("log"))
            .spawn()
            .expect("the gateway starts"),
    );
    procs
        .0
        .push(a.spawn(&example_bin("echo"), &[&vehicle, "ECHO"], "echo"));

    // A ground station with the vehicle's keys but the wrong password: the vehicle's gateway
    // refuses its session (its log says so), so it never hears the player, and what it is sent
    // goes nowhere.
    let mut bad = Processes(vec![g.gateway(&impostor, &vehicle, "gw-impostor")]);
    let deadline = Instant::now() + Duration::from_secs(60);
    while !std::fs::read_to_string(work.path().join("gw-a.log"))
        .unwrap_or_default()
        .contains("OpenSyn")
    {
        assert!(
            Instant::now() < deadline,
            "no refused handshake: {}",
            logs(work.path())
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let o = g
        .command(&petrel_bin())
        .arg("send")
        .arg(&dir)
        .args(["start_mission", "--vehicle", &vehicle, "--timeout", "1"])
        .output()
        .expect("petrel send runs");
    assert!(
        !o.status.success(),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
    let bad_gateway = bad.0.remove(0);
    let _ = Command::new("kill")
        .args(["-TERM", &bad_gateway.id().to_string()])
        .status();
    let out = bad_gateway.wait_with_output().expect("the impostor stops");
    let counters: serde_json::Value = serde_json::from_slice(
        &std::fs::read(work.path().join("gw-impostor.out")).unwrap_or_default(),
    )
    .unwrap_or_default();
    assert_eq!(out.status.code(), Some(0));
    assert_eq!(counters["peers"]["A"]["state"], "unknown", "{counters}");
    let s = a.wait_for(&dir, &vehicle, "the player's status", |s| {
        s["stats"].is_object()
    });
    assert_eq!(s["stats"]["received"], 0, "nothing reached the player: {s}");

    // The ground station with the vehicle's credentials: its shadow follows the player, and
    // the operator's event there reaches the player and comes back acknowledged.
    procs.0.push(g.gateway(&dir, &vehicle, "gw-g"));
    g.wait_for(&dir, &vehicle, "the player's status on G", |s| {
        place(s, "RELAY", "ready")
    });
    let shadow_log = work.path().join("shadow.log");
    let shadow = g
        .command(&petrel_bin())
        .arg("play")
        .arg(&dir)
        .args(["--vehicle", &vehicle, "--shadow"])
        .stderr(std::fs::File::create(&shadow_log).expect("log"))
        .spawn()
        .expect("the shadow starts");
    let shadow = Processes(vec![shadow]);
    let deadline = Instant::now() + Duration::from_secs(60);
    while !std::fs::read_to_string(&shadow_log)
        .unwrap_or_default()
        .contains("shadow synchronised")
    {
        assert!(
            Instant::now() < deadline,
            "the shadow did not synchronise: {}",
            logs(work.path())
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let verdict = g.send(&dir, &vehicle, "start_mission");
    assert!(verdict.contains("1 taken and on record"), "{verdict}");
    a.wait_for(&dir, &vehicle, "the pong", |s| {
        place(s, "RELAY", "ready") && s["stats"]["processed"] == 2
    });
    // The shadow saw both steps (the operator's event and ECHO's answer), and no divergence.
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        let s = g.status(&dir, &vehicle).unwrap_or_default();
        if s["stats"]["processed"] == 2 || Instant::now() > deadline {
            break;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    assert_eq!(shadow.stop(), vec![Some(0)]);
    let log = std::fs::read_to_string(&shadow_log).unwrap_or_default();
    assert!(
        log.contains("2 vehicle steps followed") && log.contains("0 divergence alarms"),
        "{log}"
    );
    let codes = procs.stop();
    assert!(
        codes.iter().all(|c| *c == Some(0)),
        "{codes:?}: {}",
        logs(work.path())
    );
}

/// missions/ugv copied, with free ports for its three computers' gateways when `free_ports`
/// (on this host's loopback; in a network namespace of its own, its file runs as shipped).
fn ugv_project(work: &Workdir, free_ports: bool) -> PathBuf {
    let dir = work.path().join("ugv");
    std::fs::create_dir_all(&dir).expect("project dir");
    for f in ["petrel.toml", "robot.pn", "sync.pn", "vehicle.toml"] {
        let text = std::fs::read_to_string(repo().join("missions/ugv").join(f)).expect("read");
        let text = ["7447", "7448", "7449"]
            .iter()
            .filter(|_| free_ports)
            .fold(text, |t, p| {
                t.replace(
                    &format!("127.0.0.1:{p}"),
                    &format!("127.0.0.1:{}", free_port()),
                )
            });
        std::fs::write(dir.join(f), text).expect("write");
    }
    dir
}

/// The `gateway` endpoints of a project's vehicle.toml, in file order.
fn endpoints(dir: &Path) -> Vec<String> {
    std::fs::read_to_string(dir.join("vehicle.toml"))
        .expect("vehicle.toml")
        .lines()
        .filter_map(|l| l.strip_prefix("gateway = \""))
        .map(|l| l.trim_end_matches('"').to_owned())
        .collect()
}

/// The paper's UGV pair live (section 3.3): the supervision on one computer, each robot's
/// movement program on its own; both robots reach the bottleneck together, and the journal
/// shows them in it one at a time.
///
/// The link as shipped (`missions/ugv/vehicle.toml`, nothing added: the gateways make the
/// vehicle's keys at their first start, every computer being on this machine), attacked while
/// the mission runs, in a network namespace of its own where one can be made (the file's
/// loopback ports are then the namespace's): a stranger's zenoh peer, in plain TCP and in QUIC
/// with a CA of its own, reaches no gateway, hears nothing and gets nothing in; a peer with
/// robot2's keys (a computer of the vehicle) may not speak for robot1, and its claim to be
/// robot2 is refused, as is a second `petrel gateway` for robot2: the first link goes on with
/// no restart, and the journal holds the operator's `start_mission` and nothing forged.
#[test]
fn the_ugv_pair_on_three_computers_passes_the_bottleneck_one_at_a_time() {
    let work = Workdir::new();
    let ns = Cable::new();
    let dir = ugv_project(&work, ns.is_none());
    let vehicle = unique_vehicle("ugv");
    let names = ["supervision", "robot1", "robot2"];
    let [mut s, mut r1, mut r2, mut stranger, mut second] =
        [names[0], names[1], names[2], "stranger", names[2]].map(|n| Computer::new(&work, n));
    for c in [&mut s, &mut r1, &mut r2, &mut stranger, &mut second] {
        c.netns = ns.as_ref().map(|n| n.ns[0].clone());
    }
    stranger.state = work.path().join("stranger");
    let journal = work.path().join("journal");
    let ugv = petrel_tests::vehicle_bin("ugv");
    let mut procs = Processes(vec![s.spawn(
        &petrel_bin(),
        &[
            "play",
            &dir.display().to_string(),
            "--vehicle",
            &vehicle,
            "--journal",
            &journal.display().to_string(),
        ],
        "player",
    )]);
    procs.0.push(s.gateway(&dir, &vehicle, "gw-s"));
    procs
        .0
        .push(s.spawn(&ugv, &["planner", &vehicle], "planner"));
    procs.0.push(r1.gateway(&dir, &vehicle, "gw-r1"));
    procs
        .0
        .push(r1.spawn(&ugv, &["moves", &vehicle, "r1", "MOVES_R1"], "moves-r1"));
    procs.0.push(r2.gateway(&dir, &vehicle, "gw-r2"));
    procs
        .0
        .push(r2.spawn(&ugv, &["moves", &vehicle, "r2", "MOVES_R2"], "moves-r2"));
    s.wait_for(&dir, &vehicle, "both robots' programs alive", |st| {
        ["PLANNER", "MOVES_R1", "MOVES_R2"]
            .iter()
            .all(|p| st["programs"][p] == "alive")
    });

    // The attacks, while the mission runs. A stranger's keys: a CA of its own, certificates
    // with the vehicle's computer names.
    let foreign = stranger.state.join("keys").join(&vehicle);
    petrel_gateway::keys::make(&foreign, &vehicle, &names.map(String::from)).expect("keys");
    let plain = endpoints(&dir);
    let quic: Vec<String> = plain.iter().map(|e| e.replace("tcp/", "quic/")).collect();
    let forge = [
        "--claim",
        "robot1",
        "--claim",
        "supervision",
        "--claim",
        "robot2",
        "--event",
        "emergency_stop",
        "--call",
        "MOVES_R1.stop",
    ];
    let foreign_keys = foreign.display().to_string();
    let mut with_keys = forge.to_vec();
    with_keys.extend(["--keys", &foreign_keys, "--as", "robot1"]);
    let stolen = s.state.join("keys").join(&vehicle).display().to_string();
    let mut insider = forge.to_vec();
    insider.extend(["--keys", &stolen, "--as", "robot2"]);
    let rogues = [
        rogue(&stranger, &vehicle, "3", &plain, &forge, "rogue-plain"),
        rogue(&stranger, &vehicle, "3", &quic, &with_keys, "rogue-quic"),
        rogue(
            &stranger,
            &vehicle,
            "3",
            &quic[..1],
            &insider,
            "rogue-insider",
        ),
    ];
    // A second gateway for robot2 (on a port of its own): refused by the others, it gives up.
    let port = format!("tcp/127.0.0.1:{}", free_port());
    let second_gw = second.spawn(
        &petrel_bin(),
        &[
            "gateway",
            &dir.display().to_string(),
            "--vehicle",
            &vehicle,
            "--computer",
            "robot2",
            "--listen",
            &port,
        ],
        "gw-second",
    );

    s.send(&dir, &vehicle, "start_mission");
    let st = s.wait_for(&dir, &vehicle, "both robots done", |st| {
        place(st, "R1", "done") && place(st, "R2", "done")
    });
    assert_eq!(st["stats"]["calls_failed"], 0, "{st}");
    // Each robot's gateway delivered its own robot's calls and left the other's (it hears
    // every computer); the robots' events are the supervision's alone.
    let on_r1 = r1.wait_for(&dir, &vehicle, "robot1's counters", |x| {
        counts(x, "robot1", "call")["delivered"]
            .as_u64()
            .unwrap_or(0)
            > 0
    });
    let calls = counts(&on_r1, "robot1", "call");
    let events = counts(&on_r1, "robot1", "event");
    assert!(
        calls["not_mine"].as_u64().unwrap_or(0) > 0 && accounted(calls),
        "{on_r1}"
    );
    assert!(events["delivered"] == 0 && accounted(events), "{on_r1}");

    // The strangers reached no gateway and heard nothing; the insider reached the gateway it
    // connected to and heard its computer's traffic (the control: this rogue does get in).
    let [plain, quic, insider] = rogues;
    for (rogue, log) in [(plain, "rogue-plain"), (quic, "rogue-quic")] {
        let r = rogue_report(&work, rogue, log);
        assert_eq!(
            (r["peers"].as_u64(), r["received"].as_u64()),
            (Some(0), Some(0)),
            "{log}: {r}"
        );
        assert!(r["puts"].as_u64() > Some(0), "{log}: {r}");
    }
    let r = rogue_report(&work, insider, "rogue-insider");
    assert!(r["peers"] == 1 && r["received"].as_u64() > Some(0), "{r}");
    // The second gateway of robot2 gave up, saying why.
    let out = second_gw
        .wait_with_output()
        .expect("the second gateway ends");
    let log = std::fs::read_to_string(work.path().join("gw-second.log")).unwrap_or_default();
    assert_eq!(out.status.code(), Some(2), "{log}");
    assert!(
        log.contains("follows another gateway of computer `robot2`"),
        "{log}"
    );
    // The supervision refused the second gateways of robot2 (the insider's and the second
    // `petrel gateway`), and robot2's first link went on: no restart, no loss (so no stand-in
    // left: no program lost).
    let st = s.wait_for(&dir, &vehicle, "the supervision's counters", |x| {
        x["gateways"]["supervision"].is_object()
    });
    let gw = &st["gateways"]["supervision"];
    assert!(
        gw["counters"]["claims_refused"]["robot2"].as_u64() > Some(0),
        "{gw}"
    );
    for peer in ["robot1", "robot2"] {
        let p = &gw["peers"][peer];
        let seen = (
            p["restarts"].as_u64(),
            p["losses"].as_u64(),
            p["state"].as_str(),
        );
        assert_eq!(seen, (Some(0), Some(0), Some("up")), "{peer}: {gw}");
    }
    assert!(
        std::fs::read_to_string(work.path().join("gw-s.log"))
            .unwrap_or_default()
            .contains("a second gateway claims computer `robot2`"),
        "{}",
        logs(work.path())
    );
    let codes = procs.stop();
    assert!(
        codes.iter().all(|c| *c == Some(0)),
        "{codes:?}: {}",
        logs(work.path())
    );

    // The trace: each robot entered the bottleneck once, never while the other was in it
    // (from `enter`, which takes it, to `out`, which gives it back); nothing forged is on
    // record: one `start_mission` (the operator's), no `emergency_stop`.
    let (entries, _) = journal_json(&journal);
    let submitted = |name: &str| {
        entries
            .iter()
            .filter(|e| e["kind"] == "submit" && e["event"] == name)
            .count()
    };
    assert_eq!(
        [submitted("start_mission"), submitted("emergency_stop")],
        [1, 0],
        "{entries:?}"
    );
    let mut inside = [false, false];
    let mut entered = [0, 0];
    let mut both_waited = false;
    for e in entries.iter().filter(|e| e["kind"] == "step") {
        for t in e["fired"].as_array().into_iter().flatten() {
            let t = t.as_str().unwrap_or("");
            for (i, r) in ["R1", "R2"].iter().enumerate() {
                if t == format!("{r}/PASS.enter") {
                    assert!(!inside[1 - i], "both in the bottleneck at {e}");
                    inside[i] = true;
                    entered[i] += 1;
                }
                if t == format!("{r}/PASS.out") {
                    inside[i] = false;
                }
                // The robot asked for the bottleneck again after the other left: it had to
                // wait for it.
                if t == format!("{r}/PASS.again") {
                    both_waited = true;
                }
            }
        }
    }
    assert_eq!(entered, [1, 1], "{entries:?}");
    assert!(
        both_waited,
        "the robots never met at the bottleneck: {entries:?}"
    );
}

/// The link out for longer than zenoh's lease (10 s), twice on one set-up: the cable between
/// the computers cut for 15 s, then B's gateway stopped (SIGSTOP) for 12 s, with a call of the
/// player's to ECHO in flight each time and operator events sent on B. Nothing goes silently:
/// the calls are given up past the link's retention bound (10 s here) and the nets get
/// `call_failed` (ECHO never gets them, not even after the stopped gateway runs again); the
/// event sent as the cable went is refused to its sender with the reason; those
/// sent later arrive in order, after `link_restored("B")`; the journal and the counters say so.
/// Each computer has only its own keys (made by `petrel keys`), and a stranger on B's side of
/// the cable gets no session with A's gateway.
#[test]
fn past_the_lease_every_call_and_event_is_delivered_in_order_or_failed_to_its_sender() {
    let Some(cable) = Cable::new() else {
        return;
    };
    let work = Workdir::new();
    let dir = project(&work);
    let text = std::fs::read_to_string(dir.join("vehicle.toml")).expect("vehicle.toml");
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    let mut n = 0;
    for l in lines.iter_mut() {
        if l.starts_with("gateway = ") {
            *l = format!("gateway = \"tcp/{}:7447\"", cable.addrs[n]);
            n += 1;
        }
        if l.starts_with("detection = ") {
            l.push_str("\nretention = \"10s\"");
        }
    }
    std::fs::write(dir.join("vehicle.toml"), lines.join("\n")).expect("vehicle.toml");
    let vehicle = unique_vehicle("outage");
    let (mut a, mut b) = (Computer::new(&work, "A"), Computer::new(&work, "B"));
    a.netns = Some(cable.ns[0].clone());
    b.netns = Some(cable.ns[1].clone());
    // Each computer has only its own keys, as on a real vehicle.
    distribute_keys(&work, &dir, &vehicle, [&mut a, &mut b]);
    let journal = work.path().join("journal");
    let mut procs = Processes(vec![a.spawn(
        &petrel_bin(),
        &[
            "play",
            &dir.display().to_string(),
            "--vehicle",
            &vehicle,
            "--journal",
            &journal.display().to_string(),
        ],
        "player",
    )]);
    procs.0.push(a.gateway(&dir, &vehicle, "gw-a"));
    procs.0.push(b.gateway(&dir, &vehicle, "gw-b"));
    procs
        .0
        .push(b.spawn(&example_bin("echo"), &[&vehicle, "ECHO"], "echo"));
    a.wait_for(&dir, &vehicle, "ECHO alive on A", |s| {
        s["programs"]["ECHO"] == "alive"
    });
    // A stranger on B's side of the cable, at A's address: no session, nothing heard.
    let stranger = rogue(
        &b,
        &vehicle,
        "2",
        &endpoints(&dir)[..1],
        &["--claim", "B", "--event", "start_mission"],
        "rogue",
    );
    a.send(&dir, &vehicle, "start_mission");
    let s = a.wait_for(&dir, &vehicle, "the pong back", |s| {
        place(s, "RELAY", "ready") && counts(s, "A", "event")["delivered"] == 1
    });
    let r = rogue_report(&work, stranger, "rogue");
    assert_eq!(
        (r["peers"].as_u64(), r["received"].as_u64()),
        (Some(0), Some(0)),
        "{r}"
    );
    let started = Instant::now();

    // 1. The cable cut for 15 s. Within the detection bound (3 s), the player calls ECHO and
    // an operator sends note(1) on B: both in flight when the link goes.
    let losses = losses_of(&s);
    cable.set(false);
    let cut = Instant::now();
    a.send(&dir, &vehicle, "start_mission");
    let note1 = b.send_waiting(&dir, &vehicle, "note(1)");
    a.wait_for(&dir, &vehicle, "B lost and the call given up", |s| {
        losses_of(s) > losses
            && place(s, "PROGS", "gone")
            && counts(s, "A", "call")["given_up"] == 1
            && place(s, "RELAY", "ready")
    });
    // Past the retention bound: note(1) was given up too, and its sender told why.
    let (code, out) = verdict(note1);
    assert_eq!(code, Some(1), "{out}");
    assert!(
        out.contains("0 taken and on record, 1 refused")
            && out.contains("not acknowledged by the gateway of computer `A` within 10 s"),
        "{out}"
    );
    // Later in the cut: notes that wait in B's gateway, within the bound when the link returns.
    let note2 = b.send_waiting(&dir, &vehicle, "note(2)");
    std::thread::sleep(Duration::from_millis(300));
    let note3 = b.send_waiting(&dir, &vehicle, "note(3)");
    std::thread::sleep(Duration::from_secs(15).saturating_sub(cut.elapsed()));
    cable.set(true);
    for send in [note2, note3] {
        let (code, out) = verdict(send);
        assert_eq!(code, Some(0), "{out}");
        assert!(out.contains("1 taken and on record"), "{out}");
    }
    a.wait_for(&dir, &vehicle, "B back after the cut", |s| {
        place(s, "LINK", "up") && s["programs"]["ECHO"] == "alive"
    });

    // 2. B's gateway stopped for 12 s, with the player's call to ECHO sent to it (zenoh drops
    // it when its lease ends; a copy that waited in a buffer would be too late to be taken:
    // gateway/tests/carried.rs), and note(4) waiting in its events buffer.
    let losses = losses_of(&a.status(&dir, &vehicle).unwrap_or_default());
    let stopped = Stopped::new(procs.0[2].id());
    let stop = Instant::now();
    a.send(&dir, &vehicle, "start_mission");
    let note4 = b.send_waiting(&dir, &vehicle, "note(4)");
    a.wait_for(&dir, &vehicle, "B lost and the second call given up", |s| {
        losses_of(s) > losses
            && counts(s, "A", "call")["given_up"] == 2
            && place(s, "RELAY", "ready")
    });
    std::thread::sleep(Duration::from_secs(12).saturating_sub(stop.elapsed()));
    drop(stopped);
    let (code, out) = verdict(note4);
    assert_eq!(code, Some(0), "{out}");
    assert!(out.contains("1 taken and on record"), "{out}");
    a.wait_for(&dir, &vehicle, "B back after the stop", |s| {
        place(s, "LINK", "up") && s["programs"]["ECHO"] == "alive"
    });
    // The link carries calls again: ECHO answers.
    a.send(&dir, &vehicle, "start_mission");
    let s = a.wait_for(&dir, &vehicle, "the last pong", |s| {
        // the pongs, and notes 2, 3 and 4
        place(s, "RELAY", "ready") && counts(s, "A", "event")["delivered"] == 5
    });
    eprintln!(
        "both outages and their recovery took {:?}",
        started.elapsed()
    );
    let calls = counts(&s, "A", "call");
    assert_eq!(
        (calls["given_up"].as_u64(), calls["carried"].as_u64()),
        (Some(2), Some(2)),
        "{s}"
    );
    assert_eq!(s["gateways"]["A"]["peers"]["B"]["buffered"], 0, "{s}");
    for kind in ["event", "call", "beacon", "heartbeat", "marking", "ack"] {
        assert!(accounted(counts(&s, "A", kind)), "{kind}: {s}");
    }
    let on_b = b.wait_for(&dir, &vehicle, "B's counters", |x| {
        x["gateways"]["B"]["peers"]["A"]["buffered"] == 0
    });
    let events = counts(&on_b, "B", "event");
    assert_eq!(events["given_up"], 1, "{on_b}");
    for kind in ["event", "call", "beacon", "heartbeat", "marking", "ack"] {
        assert!(accounted(counts(&on_b, "B", kind)), "{kind}: {on_b}");
    }
    let codes = procs.stop();
    assert!(
        codes.iter().all(|c| *c == Some(0)),
        "{codes:?}: {}",
        logs(work.path())
    );
    // ECHO got two calls (before and after the outages), never the given-up ones.
    let echo = std::fs::read_to_string(work.path().join("echo.out")).unwrap_or_default();
    assert_eq!(echo.matches("ping(").count(), 2, "{echo}");

    // The journal: each outage is link_lost(B), program_lost(ECHO), the gateway's call_failed,
    // link_restored(B), then B's notes; notes 2, 3, 4 in order, note 1 never.
    let (entries, _) = journal_json(&journal);
    let steps: Vec<String> = entries
        .iter()
        .filter(|e| e["kind"] == "submit")
        .map(|e| {
            let name = e["event"].as_str().unwrap_or("");
            match name {
                "note" => format!("note {}", e["params"][0].as_str().unwrap_or("")),
                "call_failed"
                    if e["origin"]
                        .as_str()
                        .is_some_and(|o| o.starts_with("tool/gw-A")) =>
                {
                    "call_failed by gw-A".to_owned()
                }
                _ => name.to_owned(),
            }
        })
        .filter(|n| n != "start_mission")
        .collect();
    let pos = |what: &str, nth: usize| {
        steps
            .iter()
            .enumerate()
            .filter(|(_, s)| *s == what)
            .nth(nth)
            .map(|(i, _)| i)
            .unwrap_or_else(|| panic!("no {what} #{nth} in {steps:?}"))
    };
    let notes: Vec<&String> = steps.iter().filter(|s| s.starts_with("note")).collect();
    assert_eq!(notes, ["note 2", "note 3", "note 4"], "{steps:?}");
    assert_eq!(
        steps.iter().filter(|s| *s == "pong").count(),
        2,
        "{steps:?}"
    );
    // (A loaded machine may have starved a gateway past the bound once more: the outages are
    // the last two losses.)
    let lost = steps.iter().filter(|s| *s == "link_lost").count();
    assert!(lost >= 2, "{steps:?}");
    for (outage, first_note) in [(lost - 2, "note 2"), (lost - 1, "note 4")] {
        let (down, failed, up) = (
            pos("link_lost", outage),
            pos("call_failed by gw-A", outage + 2 - lost),
            pos("link_restored", outage),
        );
        assert!(down < failed && failed < up, "{steps:?}");
        assert!(
            up < pos(first_note, 0),
            "the nets saw {first_note} before B was back: {steps:?}"
        );
    }
}

/// missions/redermor copied with `vehicle` (a vehicle file of it) as its vehicle.toml, free
/// ports for the gateways, and the simulator's files read from the repository.
fn redermor_project(vehicle: &str) -> petrel_tests::TempProject {
    let sim = repo().join("missions/redermor/sim");
    let file = std::fs::read_to_string(repo().join("missions/redermor").join(vehicle))
        .expect("the vehicle file");
    let file = ["7457", "7458", "7459"].iter().fold(file, |t, p| {
        t.replace(
            &format!("127.0.0.1:{p}"),
            &format!("127.0.0.1:{}", free_port()),
        )
    });
    petrel_tests::TempProject::copy(&repo().join("missions/redermor"), move |name, text| {
        let text = match name {
            "vehicle.toml" => file.clone(),
            // The data server's stale-depth rule counts in wall-clock time (1 s): on a loaded
            // 2-core machine a stalled simulator trips it and the nominal flight aborts, in one
            // computer's run as in two. This test is about the link, not that rule: both runs
            // get the same, looser bound.
            "can.toml" => text.replace(r#"timeout = "1s""#, r#"timeout = "30s""#),
            _ => text,
        };
        text.replace("{project}/sim/", &format!("{}/", sim.display()))
    })
}

/// A journal's steps as this test compares them, up to the one that completes the mission
/// (fires `MISSION.completed`): the event, the transitions it fired, and the actions without
/// their arguments (`call PLN.itinerary`, `activate NET`, `emit area_reached`). Arguments carry
/// the vehicle's position, which differs between any two live runs (the simulator runs on the
/// wall clock); what comes after the completion is the vehicle stopping (programs lost in
/// the order they stop).
fn mission_steps(journal: &Path) -> Vec<String> {
    let (docs, o) = journal_json(journal);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let strings = |v: &serde_json::Value| -> Vec<String> {
        v.as_array()
            .into_iter()
            .flatten()
            .map(|x| x.as_str().unwrap_or("").to_owned())
            .collect()
    };
    let mut steps = Vec::new();
    for d in docs.iter().filter(|d| d["kind"] == "step") {
        let fired = strings(&d["fired"]);
        let actions: Vec<String> = strings(&d["actions"])
            .iter()
            .map(|a| a.split('(').next().unwrap_or("").trim_end().to_owned())
            .collect();
        steps.push(format!(
            "{} | {} | {}",
            d["event"].as_str().unwrap_or(""),
            fired.join(", "),
            actions.join(", ")
        ));
        if fired.iter().any(|t| t == "MISSION.completed") {
            return steps;
        }
    }
    panic!("the mission never completed: {steps:#?}");
}

/// `petrel monitor` on `computer`, listening on a free port of loopback: its address.
fn monitor_on(computer: &Computer, project: &Path, vehicle: &str) -> (Child, std::net::SocketAddr) {
    use std::io::BufRead;
    let mut child = computer
        .command(&petrel_bin())
        .arg("monitor")
        .arg(project)
        .args(["--vehicle", vehicle, "--listen", "127.0.0.1:0"])
        .stdout(Stdio::piped())
        .stderr(
            std::fs::File::create(computer.work.join("monitor.log")).expect("the monitor's log"),
        )
        .spawn()
        .expect("petrel monitor starts");
    let out = child.stdout.take().expect("its standard output");
    let mut lines = std::io::BufReader::new(out).lines();
    let addr = lines.by_ref().map_while(Result::ok).find_map(|l| {
        l.strip_prefix("petrel monitor: listening on http://")
            .and_then(|a| a.trim_end_matches('/').parse().ok())
    });
    std::thread::spawn(move || for _ in lines {});
    let Some(addr) = addr else {
        let _ = child.kill();
        let _ = child.wait();
        panic!("petrel monitor did not start: {}", logs(&computer.work));
    };
    (child, addr)
}

/// Redermor (issue 16's test): the supervision (the player and the CAN data server with its
/// simulator) on oa1, the programs PLN, NAV (GDD, GUI, IDC) and EVT on oa2, a ground station
/// with only its gateway, each computer brought up by `petrel up --computer`. NAV reads the
/// data server's signals and commands the thrusters through it across the link. The nominal
/// scenario gives the same journal steps as on one computer (see [`mission_steps`]) and
/// reaches the same final marking; the ground station's `petrel monitor` follows the player's
/// marking step by step; every counter accounts for every message.
#[test]
fn redermor_on_two_computers_flies_the_nominal_scenario_as_on_one() {
    // One computer: vehicle.toml as it is.
    let one = redermor_project("vehicle.toml");
    let logs_one = one.path().join("logs");
    let vehicle = unique_vehicle("rdm1");
    let o = Command::new(petrel_bin())
        .arg("up")
        .arg(one.path())
        .args(["--vehicle", &vehicle, "--logs"])
        .arg(&logs_one)
        .args(["--timeout", "400"])
        .output()
        .expect("petrel up runs");
    petrel_tests::forget_vehicle(&vehicle);
    assert!(
        o.status.success(),
        "petrel up on one computer:\n{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    let steps_one = mission_steps(&logs_one.join("journal"));

    // Two computers and a ground station.
    let work = Workdir::new();
    let two = redermor_project("vehicle-two.toml");
    let dir = two.path().to_path_buf();
    let vehicle = unique_vehicle("rdm2");
    let (a, b, g) = (
        Computer::new(&work, "oa1"),
        Computer::new(&work, "oa2"),
        Computer::new(&work, "ground"),
    );
    let up = |c: &Computer| {
        let logs = work.path().join(format!("run-{}", c.name));
        let child = c.spawn(
            &petrel_bin(),
            &[
                "up",
                &dir.display().to_string(),
                "--vehicle",
                &vehicle,
                "--computer",
                c.name,
                "--logs",
                &logs.display().to_string(),
                "--timeout",
                "400",
            ],
            &format!("up-{}", c.name),
        );
        (child, logs)
    };
    let (up_a, logs_a) = up(&a);
    let (up_b, logs_b) = up(&b);
    let (up_g, logs_g) = up(&g);
    let mut ups = Processes(vec![up_a, up_b, up_g]);
    // The player on oa1 hears every program of oa2 through its stand-ins.
    a.wait_for(&dir, &vehicle, "oa2's programs alive on oa1", |s| {
        ["PLN", "GDD", "GUI", "IDC", "EVT"]
            .iter()
            .all(|p| s["programs"][p] == "alive")
    });
    let (monitor, addr) = monitor_on(&g, &dir, &vehicle);
    let monitor = Processes(vec![monitor]);
    let marked = || -> Option<Vec<String>> {
        let r = petrel_tests::web::http(addr, "GET", "/api/marking", &[], "").ok()?;
        let v = r.json();
        (v["synced"] == true).then(|| {
            v["marked"]
                .as_array()
                .into_iter()
                .flatten()
                .filter_map(|p| p.as_str().map(str::to_owned))
                .collect()
        })
    };
    let deadline = Instant::now() + Duration::from_secs(60);
    let first = loop {
        if let Some(m) = marked() {
            break m;
        }
        assert!(
            Instant::now() < deadline,
            "the ground's monitor never synchronised: {}",
            logs(work.path())
        );
        std::thread::sleep(Duration::from_millis(50));
    };
    assert!(
        first.iter().any(|p| p == "MISSION.stop") && !first.iter().any(|p| p == "global.flown"),
        "{first:?}"
    );
    a.send(&dir, &vehicle, "start_mission");
    // The ground's monitor follows the marking on oa1 as the mission goes, to its end.
    let mut seen = vec![first];
    let deadline = Instant::now() + Duration::from_secs(400);
    while !seen
        .last()
        .is_some_and(|m| m.iter().any(|p| p == "global.flown"))
    {
        assert!(
            Instant::now() < deadline,
            "the ground's monitor never showed the end: {seen:?}\n{}",
            logs(work.path())
        );
        if let Some(m) = marked() {
            if seen.last() != Some(&m) {
                seen.push(m);
            }
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    assert!(seen.len() >= 5, "the monitor saw few markings: {seen:?}");
    assert_eq!(monitor.stop(), vec![Some(0)]);
    // Each computer's `petrel up` sees the mission's end (oa2's and the ground's through the
    // mirrored player) and stops.
    let deadline = Instant::now() + Duration::from_secs(120);
    while ups.0.iter_mut().any(|c| matches!(c.try_wait(), Ok(None))) {
        assert!(
            Instant::now() < deadline,
            "a computer's petrel up did not stop: {}",
            logs(work.path())
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    let codes: Vec<Option<i32>> = ups
        .0
        .iter_mut()
        .map(|c| c.wait().ok().and_then(|s| s.code()))
        .collect();
    ups.0.clear();
    assert_eq!(codes, [Some(0); 3], "{}", logs(work.path()));
    let up_a = std::fs::read_to_string(work.path().join("up-oa1.log")).unwrap_or_default()
        + &std::fs::read_to_string(work.path().join("up-oa1.out")).unwrap_or_default();
    assert!(
        up_a.contains("the mission reached its final marking"),
        "{up_a}"
    );

    let steps_two = mission_steps(&logs_a.join("journal"));
    assert_eq!(
        steps_two,
        steps_one,
        "the journal steps differ from one computer's:\n{}",
        logs(work.path())
    );

    // Every message each gateway heard is accounted for, none missing; the data server's
    // signals reached oa2 (NAV and EVT read them there) and NAV's thruster commands reached
    // the data server on oa1.
    let counters = |logs: &Path, name: &str| last_json(&logs.join(format!("{name}.log")));
    let (ca, cb, cg) = (
        counters(&logs_a, "gateway-1"),
        counters(&logs_b, "gateway-2"),
        counters(&logs_g, "gateway-g"),
    );
    for c in [&ca, &cb, &cg] {
        for (kind, k) in c["counters"]["kinds"].as_object().into_iter().flatten() {
            assert!(accounted(k), "{kind}: {c}");
        }
        for (peer, p) in c["peers"].as_object().into_iter().flatten() {
            assert_eq!(p["missing"], 0, "{peer}: {c}");
        }
    }
    let n = |c: &serde_json::Value, kind: &str, what: &str| {
        c["counters"]["kinds"][kind][what].as_u64().unwrap_or(0)
    };
    assert!(n(&ca, "signals", "to_link") > 0, "{ca}");
    assert!(n(&cb, "signals", "delivered") > 0, "{cb}");
    assert_eq!(n(&cb, "signals", "refused"), 0, "{cb}");
    // On the ground, the monitor reads them (its vehicle panel); before it started, nobody
    // did: heard, not lost (`unheard`).
    assert!(n(&cg, "signals", "delivered") > 0, "{cg}");
    assert_eq!(n(&cg, "signals", "refused"), 0, "{cg}");
    assert!(
        n(&cb, "call", "to_link") > 0 && n(&ca, "call", "delivered") > 0,
        "{ca}\n{cb}"
    );
    assert!(n(&ca, "event", "delivered") > 0, "{ca}");
    assert_eq!(n(&ca, "event", "refused"), 0, "{ca}");
}
