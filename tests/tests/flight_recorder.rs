//! The flight recorder across processes: a mission journaled by `petrel play` replays to the
//! same markings; damage is detected; a SIGKILLed player resumes to the same final marking as
//! an uninterrupted run; a shadow raises an alarm on divergence.

use petrel_tests::{petrel_bin, repo, unique_vehicle, Player};
use std::path::Path;
use std::process::Command;

fn uav() -> std::path::PathBuf {
    repo().join("missions/uav")
}

/// The UAV events a scripted operator sends, with no programs connected (calls fail, which the
/// journal records too).
const EVENTS: [&str; 8] = [
    "start_mission",
    "rotation_speed",
    "airborne",
    "altitude_reached",
    "waypoint([48.7, 2.2, 300], \"camera\")",
    "waypoint_reached",
    "no_more_waypoints",
    "runway_aligned",
];

fn petrel(args: &[&str]) -> std::process::Output {
    Command::new(petrel_bin()).args(args).output().unwrap()
}

fn marking(s: &serde_json::Value) -> serde_json::Value {
    s["marking"].clone()
}

fn send_all(player: &Player, events: &[&str]) {
    for e in events {
        let o = player.send(e, 1);
        assert!(
            o.status.success(),
            "{e}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
}

fn replay(journal: &Path) -> std::process::Output {
    petrel(&["replay", &journal.display().to_string()])
}

#[test]
fn a_journaled_mission_replays_to_the_same_markings() {
    let vehicle = unique_vehicle("rec");
    let player = Player::start(&uav(), &vehicle);
    send_all(&player, &EVENTS);
    let live = player.wait_for(5.0, |s| s["stats"]["processed"] == 8);
    let journal = player.journal.clone();
    // The journal lives in the player's work directory: keep it past the player.
    let _work = player.work.clone();
    assert!(player.stop().success());
    let o = replay(&journal);
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("every recorded marking reproduced"), "{out}");
    // The replayed final state is the live one.
    let m = marking(&live);
    assert!(out.contains("MISSION{landing}"), "{out}\nlive: {m}");
    // `journal show` gives the steps for people and plotting tools.
    let o = petrel(&[
        "journal",
        "show",
        &journal.display().to_string(),
        "--format",
        "csv",
    ]);
    let csv = String::from_utf8_lossy(&o.stdout);
    assert!(csv.starts_with("index,time_s,kind,event"), "{csv}");
    // 8 events, and a call_failed for each of their 10 calls (no program runs): roll, takeoff,
    // climb, next_waypoint, transit + use_payload, stop_payload + next_waypoint, approach, land.
    assert_eq!(csv.lines().filter(|l| l.contains(",step,")).count(), 8 + 10);
    let o = petrel(&[
        "journal",
        "show",
        &journal.display().to_string(),
        "--format",
        "json",
    ]);
    for line in String::from_utf8_lossy(&o.stdout).lines() {
        let _: serde_json::Value = serde_json::from_str(line).expect("one JSON document a line");
    }
}

#[test]
fn a_journal_edited_by_one_byte_is_detected() {
    let vehicle = unique_vehicle("edit");
    let player = Player::start(&uav(), &vehicle);
    send_all(&player, &EVENTS[..4]);
    player.wait_for(5.0, |s| s["stats"]["processed"] == 4);
    let journal = player.journal.clone();
    // The journal lives in the player's work directory: keep it past the player.
    let _work = player.work.clone();
    assert!(player.stop().success());
    let seg = journal.join("journal-000001.pj");
    let mut bytes = std::fs::read(&seg).unwrap();
    let i = bytes.len() / 2;
    bytes[i] = bytes[i].wrapping_add(1);
    std::fs::write(&seg, &bytes).unwrap();
    let o = replay(&journal);
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("is damaged at record") && err.contains("checksum"),
        "{err}"
    );
}

#[test]
fn a_journal_cut_mid_record_drops_the_torn_record_and_resumes() {
    let vehicle = unique_vehicle("torn");
    let player = Player::start(&uav(), &vehicle);
    send_all(&player, &EVENTS[..3]);
    player.wait_for(5.0, |s| s["stats"]["processed"] == 3);
    let journal = player.journal.clone();
    let work = player.work.clone();
    assert!(player.stop().success());
    let seg = journal.join("journal-000001.pj");
    let len = std::fs::metadata(&seg).unwrap().len();
    std::fs::OpenOptions::new()
        .write(true)
        .open(&seg)
        .unwrap()
        .set_len(len - 5)
        .unwrap();
    let o = replay(&journal);
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(String::from_utf8_lossy(&o.stderr).contains("torn"));
    // The player resumes from what precedes the torn record, with a warning.
    let player = Player::start_in(&work, &uav(), &vehicle, &["--resume"]);
    let s = player.wait_for(5.0, |s| s["stats"]["resumed_steps"].as_u64() > Some(0));
    assert!(s["stats"]["resumed_steps"].as_u64() > Some(0), "{s}");
    let log_path = player.log.clone();
    assert!(player.stop().success());
    let log = std::fs::read_to_string(log_path).unwrap();
    assert!(log.contains("torn"), "{log}");
}

#[test]
fn sigkill_then_resume_ends_in_the_marking_of_an_uninterrupted_run() {
    // The uninterrupted run.
    let straight = unique_vehicle("straight");
    let player = Player::start(&uav(), &straight);
    send_all(&player, &EVENTS);
    let reference = player.wait_for(5.0, |s| s["stats"]["processed"] == 8);
    assert!(player.stop().success());

    // The same events, with a SIGKILL in the middle.
    let vehicle = unique_vehicle("crash");
    let mut player = Player::start(&uav(), &vehicle);
    send_all(&player, &EVENTS[..4]);
    player.wait_for(5.0, |s| s["stats"]["processed"] == 4);
    player.child.kill().unwrap(); // SIGKILL
    player.child.wait().unwrap();
    let journal = player.journal.clone();
    let work = player.work.clone();
    drop(player);
    let player = Player::start_in(&work, &uav(), &vehicle, &["--resume"]);
    let s = player.status().unwrap();
    assert_eq!(
        s["stats"]["resumed_steps"], 8,
        "4 events and their 4 call_failed: {s}"
    );
    assert_eq!(
        marking(&s)["MISSION"],
        serde_json::json!(["asking_waypoint"]),
        "{s}"
    );
    send_all(&player, &EVENTS[4..]);
    let end = player.wait_for(5.0, |s| s["stats"]["processed"] == 4);
    assert_eq!(
        marking(&end),
        marking(&reference),
        "resumed {end}\nstraight {reference}"
    );
    assert!(player.stop().success());
    // The journal, with its crash and its resumption, replays to the same markings.
    let o = replay(&journal);
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
}

#[test]
fn a_shadow_follows_the_vehicle_and_raises_an_alarm_on_divergence() {
    let vehicle = unique_vehicle("shadow");
    let player = Player::start(&uav(), &vehicle);
    // A ground station whose MISSION net skips the climb phase.
    let dir = tempfile::tempdir().unwrap();
    for f in ["petrel.toml", "mission.pn", "events.pn"] {
        let text = std::fs::read_to_string(uav().join(f)).unwrap();
        let text = text.replace(
            "transition climb on airborne: taking_off -> climbing {",
            "transition climb on airborne: taking_off -> asking_waypoint {",
        );
        std::fs::write(dir.path().join(f), text).unwrap();
    }
    // A shadow's standard error, read as it comes: the test waits on what it says, not on
    // time (each shadow stops on SIGTERM; --run-for only bounds a test gone wrong).
    struct Shadow {
        child: std::process::Child,
        lines: std::sync::mpsc::Receiver<String>,
        text: std::sync::Arc<std::sync::Mutex<String>>,
    }
    impl Shadow {
        fn wait_for(&self, what: &str) -> bool {
            let deadline = std::time::Instant::now() + std::time::Duration::from_secs(30);
            while std::time::Instant::now() < deadline {
                if self.text.lock().unwrap().contains(what) {
                    return true;
                }
                let _ = self
                    .lines
                    .recv_timeout(std::time::Duration::from_millis(100));
            }
            false
        }
        fn stop(mut self) -> (Option<i32>, String) {
            let _ = Command::new("kill")
                .args(["-TERM", &self.child.id().to_string()])
                .status();
            let status = self.child.wait().unwrap();
            // The reader ends with the process's standard error.
            while self.lines.recv().is_ok() {}
            let text = self.text.lock().unwrap().clone();
            (status.code(), text)
        }
    }
    let spawn_shadow = |project: &Path| {
        let mut child = Command::new(petrel_bin())
            .arg("play")
            .arg(project)
            .args(["--vehicle", &vehicle, "--shadow", "--run-for", "120"])
            // Its "synchronised" line is an info log.
            .env("RUST_LOG", "info")
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let stderr = child.stderr.take().unwrap();
        let (tx, lines) = std::sync::mpsc::channel();
        let text = std::sync::Arc::new(std::sync::Mutex::new(String::new()));
        let sink = text.clone();
        std::thread::spawn(move || {
            use std::io::BufRead;
            for line in std::io::BufReader::new(stderr)
                .lines()
                .map_while(Result::ok)
            {
                sink.lock().unwrap().push_str(&format!("{line}\n"));
                let _ = tx.send(line);
            }
        });
        Shadow { child, lines, text }
    };
    let same = spawn_shadow(&uav());
    let different = spawn_shadow(dir.path());
    // Both follow the vehicle before it moves.
    for shadow in [&same, &different] {
        assert!(
            shadow.wait_for("shadow synchronised"),
            "{}",
            shadow.text.lock().unwrap()
        );
    }
    send_all(&player, &EVENTS[..4]);
    different.wait_for("ALARM step");
    let (same_code, same_err) = same.stop();
    let (diff_code, diff_err) = different.stop();
    assert_eq!(same_code, Some(0), "{same_err}");
    assert!(same_err.contains("0 divergence alarm"), "{same_err}");
    assert_eq!(diff_code, Some(1), "{diff_err}");
    assert!(
        diff_err.contains("ALARM step")
            && diff_err.contains("(event airborne)")
            && diff_err.contains("only in the vehicle: [MISSION.climbing]"),
        "{diff_err}"
    );
    assert!(player.stop().success());
}
