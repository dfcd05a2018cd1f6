//! The flight recorder against bad journals and misuse, through the real binaries: crafted
//! records with valid checksums, a zero-filled tail (power loss), two players on one journal
//! directory, segments spliced from other missions, and a timer across a SIGKILL.

use petrel_tests::{
    ended_cleanly, journal_json, journal_record, journal_segments, petrel, petrel_bin, repo,
    unique_vehicle, Player, TempProject, Workdir,
};
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

fn liveness_dir() -> std::path::PathBuf {
    repo().join("tests/data/liveness")
}

fn text(o: &std::process::Output) -> String {
    format!(
        "exit {:?}\nstdout: {}\nstderr: {}",
        o.status.code(),
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// A player of the liveness project that took `ticks` events and was stopped; its work
/// directory (which holds the journal) is returned with the journal's path.
fn recorded_mission(tag: &str, ticks: u64) -> (Workdir, std::path::PathBuf, String) {
    let vehicle = unique_vehicle(tag);
    let player = Player::start(&liveness_dir(), &vehicle);
    for n in 0..ticks {
        let o = player.send(&format!("tick({n})"), 1);
        assert!(o.status.success(), "{}", text(&o));
    }
    let work = player.work.clone();
    let journal = player.journal.clone();
    assert!(player.stop().success());
    (work, journal, vehicle)
}

fn append(file: &Path, bytes: &[u8]) {
    use std::io::Write;
    let mut f = std::fs::OpenOptions::new().append(true).open(file).unwrap();
    f.write_all(bytes).unwrap();
}

/// `petrel play --resume` on `journal`, for at most `secs` seconds.
fn resume(journal: &Path, vehicle: &str, secs: &str) -> std::process::Output {
    Command::new(petrel_bin())
        .arg("play")
        .arg(liveness_dir())
        .args(["--vehicle", vehicle, "--resume", "--run-for", secs])
        .arg("--journal")
        .arg(journal)
        .output()
        .unwrap()
}

/// Regression (issue 10, item 4): a record with a valid checksum whose body claims a vector of
/// 2^61 elements panicked ("capacity overflow"), one claiming a string of 2^40 bytes aborted on
/// allocation, in `replay`, `journal show` and `play --resume`. Each now refuses the journal,
/// naming the record.
#[test]
fn crafted_records_with_huge_lengths_are_refused_cleanly_everywhere() {
    // Entry::Start { time: 0, state: a vector of 2^61 words }.
    let mut huge_vec = vec![1u8, 0, 253];
    huge_vec.extend_from_slice(&(1u64 << 61).to_le_bytes());
    // Entry::Submit { time: 0, event: a string of 2^40 bytes, ... }.
    let mut huge_text = vec![3u8, 0, 253];
    huge_text.extend_from_slice(&(1u64 << 40).to_le_bytes());
    huge_text.extend_from_slice(b"abc");
    for (what, body) in [("vector", huge_vec), ("string", huge_text)] {
        let (_work, journal, vehicle) = recorded_mission("craft", 2);
        let last = journal_segments(&journal).pop().unwrap();
        append(&last, &journal_record(&body));
        let (_, show) = journal_json(&journal);
        let replay = petrel(&["replay", &journal.display().to_string()]);
        let resumed = resume(&journal, &vehicle, "2");
        for (cmd, o) in [
            ("journal show", &show),
            ("replay", &replay),
            ("play --resume", &resumed),
        ] {
            assert!(ended_cleanly(o), "{what}, {cmd}: {}", text(o));
            assert_ne!(o.status.code(), Some(0), "{what}, {cmd}: {}", text(o));
            let err = String::from_utf8_lossy(&o.stderr);
            assert!(
                err.contains("record") && !err.contains("panicked"),
                "{what}, {cmd}: {}",
                text(o)
            );
        }
        petrel_tests::forget_vehicle(&vehicle);
    }
}

/// Regression (issue 10, item 4): a run of zero bytes at the end of the last segment (what a
/// power loss leaves when the file's length reached the disk but not its data) was called
/// damage, and `--resume` refused. It is a torn tail: dropped with a warning, and cut off, so
/// the journal still replays as a whole after the resumed run.
#[test]
fn a_zero_filled_tail_is_a_torn_tail_and_the_mission_resumes() {
    let vehicle = unique_vehicle("zeros");
    let player = Player::start(&liveness_dir(), &vehicle);
    for n in 0..3 {
        let o = player.send(&format!("tick({n})"), 1);
        assert!(o.status.success(), "{}", text(&o));
    }
    let work = player.work.clone();
    let journal = player.journal.clone();
    assert!(player.stop().success());
    let last = journal_segments(&journal).pop().unwrap();
    append(&last, &[0u8; 4096]);
    let o = petrel(&["replay", &journal.display().to_string()]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("zero"),
        "{}",
        text(&o)
    );
    let player = Player::start_in(&work, &liveness_dir(), &vehicle, &["--resume"]);
    let s = player.wait_for(5.0, |s| s["stats"]["resumed_steps"].as_u64() > Some(0));
    assert_eq!(s["stats"]["resumed_steps"], 3, "{s}");
    let o = player.send("tick(9)", 1);
    assert!(o.status.success(), "{}", text(&o));
    let log = player.log.clone();
    assert!(player.stop().success());
    let log = std::fs::read_to_string(log).unwrap();
    assert!(log.contains("zero"), "{log}");
    // The zeros were cut off: the first segment is no longer the last, and nothing reads as
    // damage.
    let o = petrel(&["replay", &journal.display().to_string()]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("4 steps"),
        "{}",
        text(&o)
    );
}

/// Regression (issue 10, item 7): two players could write into one journal directory, and a
/// resume then restored the other vehicle's state.
#[test]
fn one_journal_directory_holds_one_vehicle() {
    let work = Workdir::new();
    let a = unique_vehicle("owner");
    let b = unique_vehicle("intruder");
    let mut first = Player::start_in(&work, &liveness_dir(), &a, &[]);
    let journal = first.journal.clone();
    let o = first.send("tick(1)", 1);
    assert!(o.status.success(), "{}", text(&o));
    let play_b = |extra: &[&str]| {
        Command::new(petrel_bin())
            .arg("play")
            .arg(liveness_dir())
            .args(["--vehicle", &b, "--run-for", "3"])
            .arg("--journal")
            .arg(&journal)
            .args(extra)
            .output()
            .unwrap()
    };
    // While the first player writes, a second one is refused, naming the owner.
    let o = play_b(&[]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains(&a) && err.contains(&first.child.id().to_string()),
        "{}",
        text(&o)
    );
    // The owner dies without cleaning up: its lock is stale. Another vehicle still may not
    // write there, nor resume from it.
    first.child.kill().unwrap();
    first.child.wait().unwrap();
    for extra in [&[][..], &["--resume"][..]] {
        let o = play_b(extra);
        assert_eq!(o.status.code(), Some(2), "{extra:?}: {}", text(&o));
        assert!(
            String::from_utf8_lossy(&o.stderr).contains(&a),
            "{extra:?}: {}",
            text(&o)
        );
    }
    drop(first);
    petrel_tests::forget_vehicle(&b);
    // The owner itself resumes, taking its stale lock over with a warning.
    let again = Player::start_in(&work, &liveness_dir(), &a, &["--resume"]);
    let log = again.log.clone();
    let s = again.wait_for(5.0, |s| s["stats"]["resumed_steps"].as_u64() > Some(0));
    assert_eq!(s["stats"]["resumed_steps"], 1, "{s}");
    assert!(again.stop().success());
    let log = std::fs::read_to_string(log).unwrap();
    assert!(log.contains("stale"), "{log}");
}

/// Regression (issue 10, item 7): a replay of segments spliced from other missions (another
/// vehicle; the same vehicle's earlier mission, time going backwards) said "every recorded
/// marking reproduced".
#[test]
fn spliced_segments_are_reported_as_errors() {
    let (_wa, a, _) = recorded_mission("splicea", 3);
    let (_wb, b, _) = recorded_mission("spliceb", 2);
    // Another vehicle's segment after ours.
    let other = journal_segments(&b).pop().unwrap();
    std::fs::copy(&other, a.join("journal-000002.pj")).unwrap();
    let o = petrel(&["replay", &a.display().to_string()]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("vehicle"), "{}", text(&o));
    // Our own first segment again: the same header, time going backwards.
    let own = journal_segments(&a)[0].clone();
    std::fs::copy(&own, a.join("journal-000002.pj")).unwrap();
    let o = petrel(&["replay", &a.display().to_string()]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("backwards"), "{}", text(&o));
}

/// Regression (issue 10, item 10): mission time paused while the player was down, so a 4 s
/// timer fired 4 s after the resume however long the player had been dead. Mission time is
/// wall-clock time since the mission started: a deadline that passed while the player was down
/// expires at once on resume, and the journal says so (replay reproduces it).
#[test]
fn a_timer_fires_at_its_wall_clock_deadline_across_a_sigkill() {
    let manifest = "[project]\nname = \"timers\"\nfiles = [\"t.pn\"]\nstart = [\"T\"]\n\n[events]\ngo = { category = \"nominal\" }\nlate = { category = \"mission\" }\n\n[timers]\ndeadline = { event = \"late\" }\n";
    let net = "net T {\n    place idle = 1\n    place armed\n    place fired\n\n    transition arm on go: idle -> armed {\n        start deadline after 4s\n    }\n    transition ring on late: armed -> fired\n}\n";
    let project = TempProject::new(&[("petrel.toml", manifest), ("t.pn", net)]);
    let vehicle = unique_vehicle("timer");
    let mut player = Player::start(project.path(), &vehicle);
    let o = player.send("go", 1);
    assert!(o.status.success(), "{}", text(&o));
    // The timer started before the acknowledgement: its deadline is at most 4 s from now.
    let acknowledged = Instant::now();
    player.child.kill().unwrap(); // SIGKILL
    player.child.wait().unwrap();
    let work = player.work.clone();
    let journal = player.journal.clone();
    drop(player);
    // Stay down past the deadline (a wait, not a measurement).
    while acknowledged.elapsed() < Duration::from_millis(4500) {
        std::thread::sleep(Duration::from_millis(50));
    }
    let player = Player::start_in(&work, project.path(), &vehicle, &["--resume"]);
    let s = player.wait_for(10.0, |s| s["marking"]["T"] == serde_json::json!(["fired"]));
    assert_eq!(s["marking"]["T"], serde_json::json!(["fired"]), "{s}");
    assert!(player.stop().success());
    let (entries, o) = journal_json(&journal);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let resume = entries
        .iter()
        .position(|e| e["kind"] == "resume")
        .expect("a resume entry");
    let resumed_at = entries[resume]["time"].as_f64().unwrap();
    let go = entries
        .iter()
        .find(|e| e["kind"] == "step" && e["event"] == "go")
        .expect("the go step");
    let deadline = go["time"].as_f64().unwrap() + 4.0;
    assert!(
        resumed_at >= deadline,
        "mission time went on while the player was down: resumed at {resumed_at} s, deadline {deadline} s"
    );
    let late = entries[resume..]
        .iter()
        .find(|e| e["kind"] == "step" && e["event"] == "late")
        .expect("the timer's step after the resume");
    assert_eq!(
        late["time"].as_f64(),
        Some(resumed_at),
        "the overdue timer expired at the resume"
    );
    let o = petrel(&["replay", &journal.display().to_string()]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
}

/// The journal's crash guarantee with its mapped window (issue 17): records are copied into a
/// shared mapping of the segment instead of written, so a SIGKILL leaves them in the page cache
/// and the segment ending in the window's reserved zeros. Every event `petrel send` saw
/// acknowledged is on record after the kill, `--resume` goes on from the last record, and the
/// whole journal replays.
#[test]
fn every_acknowledged_event_survives_a_sigkill_of_the_player() {
    let vehicle = unique_vehicle("mapkill");
    let mut player = Player::start(&liveness_dir(), &vehicle);
    let sent: Vec<i64> = (0..25).collect();
    for n in &sent {
        let o = player.send(&format!("tick({n})"), 1);
        // Exit 0: taken and on record (acknowledged after the journal's flush).
        assert!(o.status.success(), "tick({n}): {}", text(&o));
    }
    player.child.kill().unwrap(); // SIGKILL: no drop, no cut of the window's zeros
    player.child.wait().unwrap();
    let work = player.work.clone();
    let journal = player.journal.clone();
    drop(player);
    // The records went through the window: the segment ends in its reserved zeros (a write
    // through the file would have ended at the last record).
    let last = journal_segments(&journal).pop().unwrap();
    let bytes = std::fs::read(&last).unwrap();
    let zeros = bytes.iter().rev().take_while(|&&b| b == 0).count();
    assert!(
        zeros >= 4096,
        "{} bytes, {zeros} zeros at the end",
        bytes.len()
    );
    let ticks = |entries: &[serde_json::Value]| -> Vec<i64> {
        entries
            .iter()
            .filter(|e| e["kind"] == "submit" && e["event"] == "tick")
            .filter_map(|e| e["params"][0].as_str()?.parse().ok())
            .collect()
    };
    let (entries, o) = journal_json(&journal);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert_eq!(ticks(&entries), sent, "{}", text(&o));
    // Resumed, the player cuts the zeros off and goes on from the last record.
    let player = Player::start_in(&work, &liveness_dir(), &vehicle, &["--resume"]);
    let s = player.wait_for(5.0, |s| s["stats"]["resumed_steps"].as_u64() > Some(0));
    assert_eq!(s["stats"]["resumed_steps"], sent.len() as u64, "{s}");
    let o = player.send("tick(100)", 1);
    assert!(o.status.success(), "{}", text(&o));
    assert!(player.stop().success());
    let (entries, o) = journal_json(&journal);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let mut all = sent.clone();
    all.push(100);
    assert_eq!(ticks(&entries), all, "{}", text(&o));
    // Stopped in good order, the player cut its window's zeros off: nothing torn is left.
    assert!(
        !String::from_utf8_lossy(&o.stderr).contains("torn"),
        "{}",
        text(&o)
    );
    let o = petrel(&["replay", &journal.display().to_string()]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(
        String::from_utf8_lossy(&o.stdout).contains(&format!("{} steps", all.len())),
        "{}",
        text(&o)
    );
}
