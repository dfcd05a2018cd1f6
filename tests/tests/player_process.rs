//! The player as a process on real iceoryx2: bad messages, floods with accounting, dead
//! programs, absent programs, clean stops. Each test uses its own vehicle.

use petrel_ipc::{EventMsg, Participant, Role, Value, Vehicle};
use petrel_tests::{repo, unique_vehicle, Player};
use std::time::{Duration, Instant};

fn liveness_dir() -> std::path::PathBuf {
    repo().join("tests/data/liveness")
}

/// Runs as a child process when PETREL_TEST_PROGRAM is set: joins the vehicle as program
/// WORKER and sleeps until killed.
fn main_as_program() -> bool {
    let Ok(vehicle) = std::env::var("PETREL_TEST_PROGRAM") else {
        return false;
    };
    let v = Vehicle::new(&vehicle).unwrap();
    let me = Participant::join(&v, Role::program("WORKER").unwrap()).unwrap();
    let _calls = me.call_receiver().unwrap();
    println!("ready");
    loop {
        std::thread::sleep(Duration::from_secs(1));
    }
}

#[test]
fn program_child() {
    // The entry point of the child process (a no-op as a test).
    if main_as_program() {
        unreachable!();
    }
}

#[test]
fn malformed_messages_are_refused_and_the_player_goes_on() {
    let vehicle = unique_vehicle("bad");
    let player = Player::start(&liveness_dir(), &vehicle);
    let v = Vehicle::new(&vehicle).unwrap();
    let me = Participant::join(&v, Role::tool("garbage").unwrap()).unwrap();
    let tx = me.event_sender().unwrap();
    // Undecodable bytes, an unknown event, a wrong parameter type, a wrong count.
    tx.send_encoded(&[0xff, 0xfe, 0xfd, 0x00, 0x13]).unwrap();
    tx.send(&EventMsg::new("no_such_event", vec![])).unwrap();
    tx.send(&EventMsg::new("tick", vec![Value::Text("one".into())]))
        .unwrap();
    tx.send(&EventMsg::new("tick", vec![])).unwrap();
    // Then a good one: it is processed.
    let last = tx
        .send(&EventMsg::new("tick", vec![Value::Int(1)]))
        .unwrap();
    let s = player.wait_for(5.0, |s| {
        s["senders"]["tool/garbage"]["last_seq"].as_u64() >= Some(last.seq)
    });
    assert_eq!(s["stats"]["messages"], 5, "{s}");
    assert_eq!(s["stats"]["bad_messages"], 4, "{s}");
    // Each bad message became a bad_message event (unused by this project), and the tick fired.
    assert_eq!(s["stats"]["processed"], 1, "{s}");
    assert_eq!(s["stats"]["unused"], 4, "{s}");
    drop(tx);
    drop(me);
    assert!(player.stop().success());
}

#[test]
fn a_flood_from_two_processes_is_fully_accounted() {
    let vehicle = unique_vehicle("flood");
    let player = Player::start(&liveness_dir(), &vehicle);
    let spawn = || {
        std::process::Command::new(petrel_tests::petrel_bin())
            .arg("send")
            .arg(liveness_dir())
            .arg("tick(7)")
            .args(["--vehicle", &vehicle, "--count", "50000"])
            .output()
    };
    let (a, b) = std::thread::scope(|s| {
        let a = s.spawn(spawn);
        let b = s.spawn(spawn);
        (a.join().unwrap().unwrap(), b.join().unwrap().unwrap())
    });
    let parse = |o: &std::process::Output| {
        let text = String::from_utf8_lossy(&o.stdout).to_string();
        let n = |word: &str| {
            text.split(&format!(" {word}"))
                .next()
                .and_then(|t| t.rsplit(' ').next())
                .and_then(|v| v.trim_end_matches(',').parse::<u64>().ok())
                .unwrap_or_else(|| panic!("no `{word}` in {text}"))
        };
        (n("delivered"), n("refused"))
    };
    let (da, ra) = parse(&a);
    let (db, rb) = parse(&b);
    assert_eq!(da + ra, 50_000);
    assert_eq!(db + rb, 50_000);
    let s = player.wait_for(10.0, |s| s["stats"]["messages"].as_u64() == Some(da + db));
    let st = &s["stats"];
    let messages = st["messages"].as_u64().unwrap();
    // sent = delivered + refused at the sender; delivered = taken by the player; and in the
    // engine, received = processed + unused + refused + queued.
    assert_eq!(messages, da + db, "{s}");
    let received = st["received"].as_u64().unwrap();
    let sum = st["processed"].as_u64().unwrap()
        + st["unused"].as_u64().unwrap()
        + st["refused"].as_u64().unwrap()
        + st["queued"].as_u64().unwrap();
    assert_eq!(received, sum, "{s}");
    assert_eq!(
        received, messages,
        "every delivered tick entered the engine: {s}"
    );
    eprintln!("flood: {da}+{db} delivered, {ra}+{rb} refused by full buffers");
    assert!(player.stop().success());
}

#[test]
fn a_killed_program_becomes_program_lost_within_a_bounded_time() {
    let vehicle = unique_vehicle("kill");
    let player = Player::start(&liveness_dir(), &vehicle);
    let mut program = std::process::Command::new(std::env::current_exe().unwrap())
        .args(["--exact", "program_child", "--nocapture"])
        .env("PETREL_TEST_PROGRAM", &vehicle)
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Wait until the program is up (it prints `ready`).
    let mut out = std::io::BufReader::new(program.stdout.take().unwrap());
    let mut line = String::new();
    while !line.contains("ready") {
        line.clear();
        std::io::BufRead::read_line(&mut out, &mut line).unwrap();
        assert!(!line.is_empty(), "the program child ended early");
    }
    // Its calls are delivered: `ask` calls WORKER.work and nothing fails.
    let o = player.send("ask", 1);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = player.wait_for(5.0, |s| s["stats"]["calls_sent"] == 1);
    assert_eq!(s["stats"]["calls_sent"], 1, "{s}");

    let killed = Instant::now();
    program.kill().unwrap(); // SIGKILL
    program.wait().unwrap();
    let s = player.wait_for(5.0, |s| {
        s["marking"]["WATCH"]
            .as_array()
            .is_some_and(|m| m.iter().any(|p| p == "lost"))
    });
    let elapsed = killed.elapsed();
    assert!(
        s["marking"]["WATCH"]
            .as_array()
            .unwrap()
            .iter()
            .any(|p| p == "lost"),
        "program_lost never came: {s}"
    );
    eprintln!(
        "program_lost observed {:.0} ms after SIGKILL (status polling included)",
        elapsed.as_secs_f64() * 1e3
    );
    assert!(
        elapsed < Duration::from_secs(2),
        "program_lost took {elapsed:?}"
    );
    assert!(player.stop().success());
}

#[test]
fn a_call_to_an_absent_program_becomes_call_failed() {
    let vehicle = unique_vehicle("absent");
    let player = Player::start(&liveness_dir(), &vehicle);
    let o = player.send("ask", 1);
    assert!(o.status.success());
    let s = player.wait_for(5.0, |s| s["stats"]["calls_failed"] == 1);
    assert_eq!(s["stats"]["calls_failed"], 1, "{s}");
    let watch = s["marking"]["WATCH"].as_array().unwrap();
    assert!(
        watch.iter().any(|p| p == "complained"),
        "call_failed reached the net: {s}"
    );
    assert!(player.stop().success());
}

#[test]
fn send_without_a_player_says_so() {
    let vehicle = unique_vehicle("none");
    let o = std::process::Command::new(petrel_tests::petrel_bin())
        .arg("send")
        .arg(liveness_dir())
        .arg("ask")
        .args(["--vehicle", &vehicle])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("no player is running"));
    let _ = petrel_ipc::remove_vehicle_files(&Vehicle::new(&vehicle).unwrap());
}

#[test]
fn a_program_leaves_only_once_the_player_acknowledged_its_last_event() {
    let vehicle = unique_vehicle("ack");
    let player = Player::start(&liveness_dir(), &vehicle);
    let v = Vehicle::new(&vehicle).unwrap();
    let config = petrel_programs::ProgramConfig {
        handle_signals: false,
        ..petrel_programs::ProgramConfig::default()
    };
    let mut program = petrel_programs::Program::connect_with(&v, &["WORKER"], config).unwrap();
    let deadline = Instant::now() + Duration::from_secs(10);
    while !program.player_present().unwrap() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(10));
    }
    for n in 0..50 {
        program.emit("tick", vec![Value::Int(n)]).unwrap();
    }
    // Leaves at once: the player may not have taken the last ticks yet; close waits for its
    // heartbeat to say so, as shared memory goes with the program's process.
    let stats = program.close(Duration::from_secs(5)).unwrap();
    assert_eq!((stats.emitted, stats.delivered, stats.queued), (50, 50, 0));
    assert!(!stats.unacknowledged, "{stats:?}");
    // Every tick reached the player (the program's leaving is a program_lost besides).
    let s = player.wait_for(5.0, |s| s["stats"]["messages"].as_u64() >= Some(50));
    assert_eq!(s["stats"]["messages"], 50, "{s}");
    let w = &s["senders"]["program/WORKER"];
    assert_eq!(
        (&w["last_seq"], &w["missing"]),
        (&50.into(), &0.into()),
        "{s}"
    );
    assert!(player.stop().success());
}
