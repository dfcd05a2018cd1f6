//! Events sized from the project, between real processes: the player records the longest
//! event of its project in the events service and a program's sender sizes its samples from
//! it. An event longer than that (a long text) still reaches the player whole, after a reload
//! whose events got longer too; a program started before the player (the service created
//! without a bound) sends 512-byte samples and works the same.

use petrel_tests::{example_bin, journal_json, petrel_bin, unique_vehicle, Player, Processes};
use petrel_tests::{TempProject, Workdir};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// A project where `go(X)` calls `ECHO.ping(X)`, and the `echo` example answers `pong(X)`;
/// `ty` is the type of X.
fn project(ty: &str) -> TempProject {
    let manifest = format!(
        "[project]\nname = \"sized\"\nfiles = [\"s.pn\"]\nstart = [\"S\"]\n\n[events]\n\
         go = {{ category = \"nominal\", params = [\"x: {ty}\"] }}\n\
         pong = {{ category = \"nominal\", params = [\"x: {ty}\"] }}\n\n\
         [programs.ECHO]\nfunctions = {{ ping = [\"x: {ty}\"] }}\n"
    );
    let net = "net S {\n    place idle = 1\n\n    transition ask on go(x): idle -> idle {\n        call ECHO.ping(x)\n    }\n    transition heard on pong(x): idle -> idle\n}\n";
    TempProject::new(&[("petrel.toml", &manifest), ("s.pn", net)])
}

fn echo(vehicle: &str) -> Processes {
    let child = Command::new(example_bin("echo"))
        .args([vehicle, "ECHO"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("the echo program starts");
    let v = petrel_ipc::Vehicle::new(vehicle).unwrap();
    let deadline = Instant::now() + Duration::from_secs(10);
    while !petrel_ipc::is_program_alive(&v, "ECHO").unwrap_or(false) {
        assert!(Instant::now() < deadline, "the echo program did not start");
        std::thread::sleep(Duration::from_millis(20));
    }
    Processes(vec![child])
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

fn send(player: &Player, dir: &std::path::Path, event: &str) {
    let o = Command::new(petrel_bin())
        .arg("send")
        .arg(dir)
        .arg(event)
        .args(["--vehicle", &player.vehicle])
        .output()
        .expect("petrel send runs");
    assert!(o.status.success(), "{}", text(&o));
}

/// Waits until the player has processed `n` events, and that none was a bad message.
fn processed(player: &Player, n: u64) {
    let s = player.wait_for(20.0, |s| s["stats"]["processed"].as_u64() >= Some(n));
    assert!(s["stats"]["processed"].as_u64() >= Some(n), "{s}");
    assert_eq!(s["stats"]["bad_messages"], 0, "{s}");
    assert_eq!(s["stats"]["refused"], 0, "{s}");
}

/// The parameters of each `pong` the journal recorded, as the journal prints them.
fn pongs(journal: &std::path::Path) -> Vec<String> {
    let (entries, o) = journal_json(journal);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    entries
        .iter()
        .filter(|e| e["kind"] == "step" && e["event"] == "pong")
        .map(|e| e["params"][0].as_str().unwrap_or_default().to_owned())
        .collect()
}

/// A text of `n` letters that says where it was cut, if it was.
fn long_text(n: usize) -> String {
    (0..n).map(|i| char::from(b'a' + (i % 26) as u8)).collect()
}

#[test]
fn a_long_event_reaches_the_player_whole_after_a_reload_made_events_longer() {
    let work = Workdir::new();
    let vehicle = unique_vehicle("sized");
    // Version 1: ints only, so the events service's bound is a few dozen bytes.
    let v1 = project("int");
    let player = Player::start_in(&work, v1.path(), &vehicle, &[]);
    let programs = echo(&vehicle);
    let v = petrel_ipc::Vehicle::new(&vehicle).unwrap();
    let me = petrel_ipc::Participant::join(&v, petrel_ipc::Role::tool("probe").unwrap()).unwrap();
    let bound = me
        .max_event_len()
        .unwrap()
        .expect("the player recorded its bound");
    assert!(bound < 64 + 1, "an int event's bound: {bound}");
    drop(me);
    send(&player, v1.path(), "go(7)");
    processed(&player, 2);

    // Version 2: texts. The service keeps version 1's bound; the program's sender outgrows it.
    let v2 = project("text");
    let o = Command::new(petrel_bin())
        .arg("reload")
        .arg(v2.path())
        .args(["--vehicle", &vehicle])
        .output()
        .expect("petrel reload runs");
    assert!(text(&o).contains("reload accepted"), "{}", text(&o));
    let long = long_text(20_000);
    send(&player, v2.path(), &format!("go(\"{long}\")"));
    processed(&player, 4);
    drop(programs);
    let journal = player.journal.clone();
    assert!(player.stop().success());
    assert_eq!(pongs(&journal), vec!["7".to_owned(), format!("\"{long}\"")]);
}

#[test]
fn a_program_started_before_the_player_keeps_the_defaults_and_works() {
    let work = Workdir::new();
    let vehicle = unique_vehicle("early");
    let p = project("text");
    // The program first: it creates the events service, with no bound.
    let programs = echo(&vehicle);
    let player = Player::start_in(&work, p.path(), &vehicle, &[]);
    let v = petrel_ipc::Vehicle::new(&vehicle).unwrap();
    let me = petrel_ipc::Participant::join(&v, petrel_ipc::Role::tool("probe").unwrap()).unwrap();
    assert_eq!(me.max_event_len().unwrap(), None);
    drop(me);
    let long = long_text(30_000);
    send(&player, p.path(), &format!("go(\"{long}\")"));
    send(&player, p.path(), "go(\"short\")");
    processed(&player, 4);
    drop(programs);
    let journal = player.journal.clone();
    assert!(player.stop().success());
    assert_eq!(
        pongs(&journal),
        vec![format!("\"{long}\""), "\"short\"".to_owned()]
    );
}
