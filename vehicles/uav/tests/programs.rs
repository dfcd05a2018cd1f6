//! The UAV's programs (uav-gui, uav-dec) as real processes over real iceoryx2, driven by a fake
//! player (a plain ipc participant with `Role::Player`) in the test process, or in a child
//! process of the test binary when it has to be killed.

use std::io::Read;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use petrel_ipc::{program_status, ProgramStatus, Value, Vehicle};
use petrel_tests::programs::{FakePlayer, Proc, Stream, TestVehicle};

const GUI: &str = env!("CARGO_BIN_EXE_uav-gui");
const DEC: &str = env!("CARGO_BIN_EXE_uav-dec");

fn position(values: &[Value]) -> Vec<f64> {
    match values.first() {
        Some(Value::FloatList(p)) => p.clone(),
        other => panic!("expected a position, got {other:?}"),
    }
}

fn text(values: &[Value], i: usize) -> String {
    match values.get(i) {
        Some(Value::Text(t)) => t.clone(),
        other => panic!("expected a text, got {other:?}"),
    }
}

#[test]
fn gui_answers_roll_with_rotation_speed() {
    let v = TestVehicle::new();
    let _gui = Proc::spawn(GUI, &["--vehicle", v.name()]);
    let mut player = FakePlayer::join(&v.vehicle);
    player.call("GUI", "roll", vec![]);
    // 8 simulated seconds at x600 (13 ms): no timing is asserted, machines are shared.
    let event = player.next();
    assert_eq!(event.msg.name, "rotation_speed");
    assert!(event.msg.params.is_empty());
    assert_eq!(event.origin.as_str(), "program/GUI");
    assert_eq!((event.seq, event.missed), (1, 0));
}

#[test]
fn dec_gives_the_waypoints_in_order_then_no_more() {
    let v = TestVehicle::new();
    let _dec = Proc::spawn(DEC, &["--vehicle", v.name()]);
    let mut player = FakePlayer::join(&v.vehicle);
    let mut got = Vec::new();
    for _ in 0..3 {
        player.call("DEC", "next_waypoint", vec![]);
        let params = player.expect("waypoint");
        got.push((position(&params), text(&params, 1)));
    }
    assert_eq!(
        got,
        [
            (vec![48.71, 2.21, 300.0], "camera".to_owned()),
            (vec![48.75, 2.30, 300.0], "lidar".to_owned()),
            (vec![48.80, 2.40, 300.0], "camera".to_owned()),
        ]
    );
    player.call("DEC", "next_waypoint", vec![]);
    assert!(player.expect("no_more_waypoints").is_empty());
    player.call("DEC", "nearest_site", vec![]);
    assert_eq!(
        position(&player.expect("emergency_site")),
        [48.60, 2.10, 150.0]
    );
}

#[test]
fn dec_replans_without_a_payload_and_takes_waypoint_flags() {
    let v = TestVehicle::new();
    let _dec = Proc::spawn(
        DEC,
        &[
            "--vehicle",
            v.name(),
            "--waypoint",
            "1,2,100,camera",
            "--waypoint",
            "3,4,200,lidar",
            "--waypoint",
            "5,6,300,camera",
            "--waypoint",
            "7,8,400,radar",
        ],
    );
    let mut player = FakePlayer::join(&v.vehicle);
    player.call("DEC", "next_waypoint", vec![]);
    assert_eq!(text(&player.expect("waypoint"), 1), "camera");
    player.call("DEC", "replan_without", vec![Value::Text("camera".into())]);
    player.expect("replanned");
    let mut rest = Vec::new();
    loop {
        player.call("DEC", "next_waypoint", vec![]);
        let event = player.next();
        if event.msg.name == "no_more_waypoints" {
            break;
        }
        assert_eq!(event.msg.name, "waypoint");
        rest.push((position(&event.msg.params), text(&event.msg.params, 1)));
    }
    assert_eq!(
        rest,
        [
            (vec![3.0, 4.0, 200.0], "lidar".to_owned()),
            (vec![7.0, 8.0, 400.0], "radar".to_owned()),
        ]
    );
}

#[test]
fn malformed_calls_are_logged_and_the_program_carries_on() {
    let v = TestVehicle::new();
    let mut gui = Proc::spawn(GUI, &["--vehicle", v.name()]);
    let mut player = FakePlayer::join(&v.vehicle);
    // Wrong argument type.
    player.call("GUI", "climb", vec![Value::Text("high".into())]);
    let line = gui.wait_for(Stream::Err, "climb");
    assert!(
        line.contains("call GUI.climb: argument 0 should be a float, found a text"),
        "{line}"
    );
    assert!(line.contains("the call is ignored"), "{line}");
    // Wrong number of arguments, unknown function, and a body that does not decode.
    player.call("GUI", "roll", vec![Value::Int(1)]);
    let line = gui.wait_for(Stream::Err, "GUI.roll");
    assert!(
        line.contains("the function takes no argument, the call has 1 argument"),
        "{line}"
    );
    player.call("PLD", "dance", vec![]);
    let line = gui.wait_for(Stream::Err, "dance");
    assert!(line.contains("PLD has no function `dance`"), "{line}");
    player
        .sender("GUI")
        .send_encoded(&[0xFB, 0xFF, 0xFF, 0xFF])
        .expect("garbage sent");
    let line = gui.wait_for(Stream::Err, "refused");
    assert!(
        line.contains("a call to GUI was refused and skipped"),
        "{line}"
    );
    // None of it was answered, and the program goes on.
    player.expect_silence(Duration::from_millis(100));
    player.call("GUI", "climb", vec![Value::Int(60)]);
    assert!(player.expect("altitude_reached").is_empty());
    player.call("GUI", "roll", vec![]);
    player.expect("rotation_speed");
}

#[test]
fn events_emitted_without_a_player_are_delivered_when_one_joins() {
    let v = TestVehicle::new();
    // x20: rotation_speed comes 0.4 s after roll.
    let _gui = Proc::spawn(GUI, &["--vehicle", v.name(), "--speed", "20"]);
    let mut first = FakePlayer::join(&v.vehicle);
    first.call("GUI", "takeoff", vec![]);
    let airborne = first.next();
    assert_eq!((airborne.msg.name.as_str(), airborne.seq), ("airborne", 1));
    first.call("GUI", "roll", vec![]);
    drop(first); // the player stops in good order before the answer
    std::thread::sleep(Duration::from_millis(800));
    let mut second = FakePlayer::join(&v.vehicle);
    let late = second.next();
    assert_eq!(late.msg.name, "rotation_speed");
    // The new player's account of GUI starts afresh: no false gap.
    assert_eq!((late.seq, late.missed), (1, 0));
    second.expect_silence(Duration::from_millis(100));
    // The call receiver works with the new player.
    second.call("GUI", "takeoff", vec![]);
    let airborne = second.next();
    assert_eq!((airborne.msg.name.as_str(), airborne.seq), ("airborne", 2));
}

// ---------------------------------------------------------------------------------------------
// A player process killed with SIGKILL: the test binary runs itself again as the player.

const CHILD_ENV: &str = "PETREL_PROGRAMS_CHILD_PLAYER";

/// Runs as the killed player when `PETREL_PROGRAMS_CHILD_PLAYER` names the vehicle; otherwise
/// does nothing.
#[test]
fn child_player() {
    let Ok(name) = std::env::var(CHILD_ENV) else {
        return;
    };
    let vehicle = Vehicle::new(&name).expect("vehicle");
    let mut player = FakePlayer::join(&vehicle);
    player.call("GUI", "takeoff", vec![]);
    player.expect("airborne");
    player.call("GUI", "roll", vec![]);
    println!("@@ CALLED");
    // Wait to be killed.
    let _ = std::io::stdin().read_to_end(&mut Vec::new());
}

#[test]
fn a_killed_player_is_replaced_and_no_event_is_lost() {
    let v = TestVehicle::new();
    let _gui = Proc::spawn(GUI, &["--vehicle", v.name(), "--speed", "20"]);
    let mut old = Command::new(std::env::current_exe().expect("test binary"))
        .args([
            "--exact",
            "child_player",
            "--nocapture",
            "--test-threads=1",
            "-q",
        ])
        .env(CHILD_ENV, v.name())
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .expect("spawn the player");
    let mut out = String::new();
    let mut stdout = old.stdout.take().expect("stdout");
    let mut byte = [0u8; 1];
    while !out.contains("@@ CALLED") {
        let n = stdout.read(&mut byte).expect("read the player");
        assert!(n == 1, "the player ended early: {out}");
        out.push(byte[0] as char);
    }
    old.kill().expect("SIGKILL"); // no chance to clean up
    old.wait().expect("wait");
    // rotation_speed is emitted while the dead player's port is still there (0.4 s after
    // roll); the new player comes later, cleans up and joins.
    std::thread::sleep(Duration::from_millis(700));
    let mut new = FakePlayer::join(&v.vehicle);
    let late = new.next();
    assert_eq!(late.msg.name, "rotation_speed");
    assert_eq!((late.seq, late.missed), (1, 0));
    new.expect_silence(Duration::from_millis(100));
    new.call("GUI", "takeoff", vec![]);
    let airborne = new.next();
    assert_eq!((airborne.msg.name.as_str(), airborne.seq), ("airborne", 2));
}

// ---------------------------------------------------------------------------------------------

#[test]
fn injected_failures() {
    let v = TestVehicle::new();
    let _gui = Proc::spawn(
        GUI,
        &[
            "--vehicle",
            v.name(),
            "--fail-payload-after",
            "1",
            "--failing-payload",
            "lidar",
            "--engine-failure-after",
            "2",
        ],
    );
    let mut player = FakePlayer::join(&v.vehicle);
    player.call(
        "GUI",
        "transit",
        vec![Value::FloatList(vec![1.0, 2.0, 300.0])],
    );
    let failure = player.next();
    assert_eq!(failure.msg.name, "payload_failure");
    assert_eq!(failure.msg.params, [Value::Text("lidar".into())]);
    assert_eq!(failure.origin.as_str(), "program/PLD");
    player.expect("waypoint_reached");
    player.call(
        "GUI",
        "transit",
        vec![Value::FloatList(vec![3.0, 4.0, 300.0])],
    );
    assert_eq!(player.next().msg.name, "engine_failure");
    // The engine is lost: the transit does not end. A diversion does.
    player.expect_silence(Duration::from_millis(400));
    player.call(
        "GUI",
        "transit",
        vec![Value::FloatList(vec![5.0, 6.0, 150.0])],
    );
    player.expect("waypoint_reached");
}

/// The nominal flight of `missions/uav`, the fake player doing what the MISSION net does, with
/// GUI and PLD in one process and DEC in another, at the default speed.
#[test]
fn a_nominal_flight_across_three_processes() {
    let v = TestVehicle::new();
    let mut gui = Proc::spawn(GUI, &["--vehicle", v.name(), "--exit-after-land"]);
    let mut dec = Proc::spawn(DEC, &["--vehicle", v.name(), "--idle-exit", "1"]);
    let mut player = FakePlayer::join(&v.vehicle);
    let start = Instant::now();
    let mut events = Vec::new();
    player.call("GUI", "roll", vec![]);
    loop {
        let event = player.next();
        events.push(event.msg.name.clone());
        match event.msg.name.as_str() {
            "rotation_speed" => player.call("GUI", "takeoff", vec![]),
            "airborne" => player.call("GUI", "climb", vec![Value::Int(300)]),
            "altitude_reached" => player.call("DEC", "next_waypoint", vec![]),
            "waypoint" => {
                player.call("GUI", "transit", vec![event.msg.params[0].clone()]);
                player.call("PLD", "use_payload", vec![event.msg.params[1].clone()]);
            }
            "waypoint_reached" => {
                player.call("PLD", "stop_payload", vec![]);
                player.call("DEC", "next_waypoint", vec![]);
            }
            "no_more_waypoints" => player.call("GUI", "approach", vec![]),
            "runway_aligned" => player.call("GUI", "land", vec![]),
            "touchdown" => break,
            other => panic!("unexpected event {other}"),
        }
    }
    let flight = start.elapsed();
    assert_eq!(
        events,
        [
            "rotation_speed",
            "airborne",
            "altitude_reached",
            "waypoint",
            "waypoint_reached",
            "waypoint",
            "waypoint_reached",
            "waypoint",
            "waypoint_reached",
            "no_more_waypoints",
            "runway_aligned",
            "touchdown",
        ]
    );
    assert!(
        flight > Duration::from_millis(1000) && flight < Duration::from_secs(5),
        "the flight took {flight:?}"
    );
    assert!(gui.wait_exit().success());
    assert!(dec.wait_exit().success());
    gui.wait_for(Stream::Out, "PLD uses the lidar");
    gui.wait_for(Stream::Out, "undelivered");
    dec.wait_for(Stream::Out, "no call for 1.0 s");
    assert_eq!(
        program_status(&v.vehicle, "GUI").unwrap(),
        ProgramStatus::Absent
    );
}

#[test]
fn sigterm_stops_a_program_in_good_order() {
    let v = TestVehicle::new();
    let mut dec = Proc::spawn(DEC, &["--vehicle", v.name()]);
    dec.wait_for(Stream::Out, "DEC ready");
    assert_eq!(
        program_status(&v.vehicle, "DEC").unwrap(),
        ProgramStatus::Alive
    );
    dec.terminate();
    let status = dec.wait_exit();
    assert!(status.success(), "{status}");
    dec.wait_for(Stream::Out, "termination requested");
    // It left the vehicle: no dead node for the player to clean.
    assert_eq!(
        program_status(&v.vehicle, "DEC").unwrap(),
        ProgramStatus::Absent
    );
}
