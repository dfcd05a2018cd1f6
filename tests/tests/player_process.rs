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

/// Runs as a child process when PETREL_TEST_JOINING is set: joins the vehicle as program
/// WORKER, its node only (`node`), and connects its calls receiver once a line comes on its
/// standard input (`receiving`); then prints the first call (`call ...`), or `no call` after
/// 10 s. A program is joining for as long as it likes.
fn main_as_joining_program() -> bool {
    let Ok(vehicle) = std::env::var("PETREL_TEST_JOINING") else {
        return false;
    };
    let v = Vehicle::new(&vehicle).unwrap();
    let me = Participant::join(&v, Role::program("WORKER").unwrap()).unwrap();
    println!("node");
    let mut line = String::new();
    std::io::stdin().read_line(&mut line).unwrap();
    let calls = me.call_receiver().unwrap();
    println!("receiving");
    let deadline = Instant::now() + Duration::from_secs(10);
    while Instant::now() < deadline {
        if let Ok(Some(call)) = calls.try_recv() {
            println!("call {}", call.msg.function);
            return true;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    println!("no call");
    true
}

#[test]
fn program_child() {
    // The entry point of the child processes (a no-op as a test).
    let _ = main_as_program() || main_as_joining_program();
}

/// The joining program, as a child process, once its node lives.
struct Joining {
    child: std::process::Child,
    out: std::io::BufReader<std::process::ChildStdout>,
}

impl Joining {
    fn start(vehicle: &str) -> Joining {
        let mut child = std::process::Command::new(std::env::current_exe().unwrap())
            .args([
                "--exact",
                "program_child",
                "--nocapture",
                "--test-threads",
                "1",
            ])
            .env("PETREL_TEST_JOINING", vehicle)
            .stdin(std::process::Stdio::piped())
            .stdout(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let out = std::io::BufReader::new(child.stdout.take().unwrap());
        let mut joining = Joining { child, out };
        joining.expect("node");
        joining
    }

    /// Reads lines until one starts with `what`; returns it.
    fn expect(&mut self, what: &str) -> String {
        let mut line = String::new();
        loop {
            line.clear();
            std::io::BufRead::read_line(&mut self.out, &mut line).unwrap();
            assert!(
                !line.is_empty(),
                "the joining program ended before `{what}`"
            );
            // The test harness may have written on the same line first.
            if let Some(at) = line.find(what).or_else(|| line.find("no call")) {
                return line[at..].trim().to_string();
            }
        }
    }

    /// Lets it connect its calls receiver.
    fn receive(&mut self) {
        use std::io::Write;
        let stdin = self.child.stdin.as_mut().unwrap();
        stdin.write_all(b"go\n").unwrap();
        stdin.flush().unwrap();
        self.expect("receiving");
    }
}

impl Drop for Joining {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Regression (issue 30, item 1): a call to a program whose node lives but whose calls
/// receiver is not connected yet found no receiver and became `call_failed` at once. It is
/// held, and delivered once the receiver connects.
#[test]
fn a_call_to_a_joining_program_is_held_until_it_receives() {
    let vehicle = unique_vehicle("held");
    let player = Player::start(&liveness_dir(), &vehicle);
    let mut program = Joining::start(&vehicle);
    // `ask` calls WORKER.work(1): no receiver yet, the node lives.
    assert!(player.send("ask", 1).status.success());
    let s = player.wait_for(5.0, |s| s["stats"]["calls_held"] == 1);
    assert_eq!(
        (&s["stats"]["calls_held"], &s["stats"]["calls_failed"]),
        (&1.into(), &0.into()),
        "{s}"
    );
    program.receive();
    assert_eq!(program.expect("call"), "call work");
    let s = player.wait_for(5.0, |s| s["stats"]["calls_sent"] == 1);
    assert_eq!(
        (&s["stats"]["calls_sent"], &s["stats"]["calls_failed"]),
        (&1.into(), &0.into()),
        "{s}"
    );
    // No call_failed (the child ends after the call: a program_lost may follow).
    assert!(
        !s["marking"]["WATCH"].to_string().contains("complained"),
        "{s}"
    );
    assert!(player.log_text().contains("held call delivered"));
    drop(program);
    assert!(player.stop().success());
}

/// A program whose process lives but never receives its calls: the held call becomes
/// `call_failed` once its bound has passed, with the reason in the log.
#[test]
fn a_call_held_past_its_bound_becomes_call_failed_with_the_reason() {
    let vehicle = unique_vehicle("heldout");
    let player = Player::start(&liveness_dir(), &vehicle);
    let program = Joining::start(&vehicle);
    assert!(player.send("ask", 1).status.success());
    let s = player.wait_for(10.0, |s| s["stats"]["calls_failed"] == 1);
    assert_eq!(
        (&s["stats"]["calls_held"], &s["stats"]["calls_failed"]),
        (&1.into(), &1.into()),
        "{s}"
    );
    // The net heard it: `undelivered` fired on call_failed(p, f).
    let s = player.wait_for(5.0, |s| {
        s["marking"]["WATCH"]
            .as_array()
            .is_some_and(|m| m.iter().any(|p| p == "complained"))
    });
    assert!(
        s["marking"]["WATCH"].to_string().contains("complained"),
        "{s}"
    );
    let log = player.log_text();
    assert!(
        log.contains("without receiving its calls (the bound of a held call)"),
        "{log}"
    );
    drop(program);
    assert!(player.stop().success());
}

/// Regression (issue 30, item 3): a program that left in good order (`Program::close`, or a
/// `Program` dropped) was recorded as `program_lost`. It says it leaves, and the player records
/// a stop: no `program_lost` for the nets, a `stopped` entry in the journal, INFO in the log.
#[test]
fn a_program_that_leaves_in_good_order_is_a_stop_not_a_loss() {
    let vehicle = unique_vehicle("stop");
    let player = Player::start(&liveness_dir(), &vehicle);
    let v = Vehicle::new(&vehicle).unwrap();
    let config = petrel_programs::ProgramConfig {
        handle_signals: false,
        ..petrel_programs::ProgramConfig::default()
    };
    let log_has = |text: &str, n: usize| {
        let deadline = Instant::now() + Duration::from_secs(5);
        while player.log_text().matches(text).count() < n && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(20));
        }
        player.log_text().matches(text).count() >= n
    };
    // Closed, then dropped without close: both leave in good order.
    for close in [true, false] {
        let program = petrel_programs::Program::connect_with(&v, &["WORKER"], config).unwrap();
        // The player sees it ready (it receives its calls) before it goes.
        let n = if close { 1 } else { 2 };
        assert!(log_has("status=Alive", n), "{}", player.log_text());
        if close {
            program.close(Duration::from_secs(5)).unwrap();
        } else {
            drop(program);
        }
        assert!(
            log_has("program stopped in good order", n),
            "{}",
            player.log_text()
        );
    }
    let s = player.status().unwrap();
    assert_eq!(
        s["marking"]["WATCH"],
        serde_json::json!(["up", "waiting"]),
        "{s}"
    );
    assert!(!player.log_text().contains("program lost"));
    // The journal's directory goes with the last holder of the player's work directory.
    let (journal, _work) = (player.journal.clone(), player.work.clone());
    assert!(player.stop().success());
    let (entries, o) = petrel_tests::journal_json(&journal);
    assert!(o.status.success(), "{o:?}");
    let stopped: Vec<_> = entries.iter().filter(|e| e["kind"] == "stopped").collect();
    assert_eq!(stopped.len(), 2, "{entries:?}");
    assert_eq!(stopped[0]["origin"], "program/WORKER");
    assert!(
        !entries.iter().any(|e| e["event"] == "program_lost"),
        "{entries:?}"
    );
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
    // Every tick reached the player, then the program's leave (its going is a stop, not a
    // program_lost).
    let s = player.wait_for(5.0, |s| s["stats"]["messages"].as_u64() >= Some(51));
    assert_eq!(s["stats"]["messages"], 51, "{s}");
    let w = &s["senders"]["program/WORKER"];
    assert_eq!(
        (&w["last_seq"], &w["missing"], &w["taken"]),
        (&51.into(), &0.into(), &51.into()),
        "{s}"
    );
    assert!(player.stop().success());
}

#[test]
fn sigterm_stops_the_player_cleanly_whatever_its_wait_strategy() {
    // A spinning player never sleeps in iceoryx2's WaitSet, where signals used to be caught: a
    // SIGTERM killed it (status 143) and left its node in shared memory.
    for wait in ["spin", "spin-then-block:200", "block"] {
        let vehicle = unique_vehicle(&format!("term{}", wait.len()));
        let player = Player::start_with(&repo().join("missions/uav"), &vehicle, &["--wait", wait]);
        let v = Vehicle::new(&vehicle).unwrap();
        assert!(
            !petrel_ipc::list_nodes(&v).unwrap().is_empty(),
            "the player's node"
        );
        let mut player = player;
        let pid = player.child.id().to_string();
        let log = player.log.clone();
        let _ = std::process::Command::new("kill")
            .args(["-TERM", &pid])
            .status();
        // Waited here, so that the guard's drop (which cleans up, pass or fail) finds it gone.
        let status = player.child.wait().unwrap();
        let text = std::fs::read_to_string(&log).unwrap_or_default();
        assert!(status.success(), "--wait {wait}: {status}; log:\n{text}");
        let left = petrel_ipc::list_nodes(&v).unwrap();
        assert!(
            left.is_empty(),
            "--wait {wait}: nodes left behind: {left:?}"
        );
    }
}
