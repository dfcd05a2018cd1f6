//! A full disk under the flight recorder, for real: the journal on a 64 KiB tmpfs (this test
//! needs root to mount it, and says so and passes where it is not root), the player and
//! `petrel send` as processes.

use petrel_tests::{
    journal_json, petrel, repo, unique_vehicle, Player, TempProject, Tmpfs, Workdir,
};

fn text(o: &std::process::Output) -> String {
    format!(
        "exit {:?}\nstdout: {}\nstderr: {}",
        o.status.code(),
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// The origin `petrel send` says it sent as (`tool/sendPID`).
fn origin(o: &std::process::Output) -> String {
    let out = String::from_utf8_lossy(&o.stdout);
    let start = out.find("tool/send").expect("send names its origin");
    out[start..]
        .split(|c: char| !(c.is_ascii_alphanumeric() || c == '/' || c == '_'))
        .next()
        .unwrap_or_default()
        .to_string()
}

/// The liveness project, with a net that follows the flight recorder's state.
fn project() -> TempProject {
    TempProject::copy(&repo().join("tests/data/liveness"), |name, text| {
        if name == "watch.pn" {
            text.replace(
                "    transition gone on",
                "    place recording = 1\n    place unrecorded\n    transition degraded on recorder_failed(reason): recording -> unrecorded\n    transition restored on recorder_restored: unrecorded -> recording\n    transition gone on",
            )
        } else {
            text
        }
    })
}

fn watch_has(s: &serde_json::Value, place: &str) -> bool {
    s["marking"]["WATCH"]
        .as_array()
        .is_some_and(|m| m.iter().any(|p| p == place))
}

/// Regression (issue 10, item 2): with the journal on a full disk, every event was still
/// acknowledged (ERROR lines in the log, nothing in `petrel status`), and once the disk had room
/// again the journal was "damaged at record 528" and `--resume` refused. Now: what cannot be
/// recorded is not acknowledged (`petrel send` says so and fails), the nets get
/// `recorder_failed`, status shows the recorder failing, the mission goes on, the recorder
/// catches up when space returns, the journal resumes and replays, and every event a send
/// reported safe is in it.
#[test]
fn a_full_disk_loses_nothing_acknowledged() {
    let work = Workdir::new();
    let Some(disk) = Tmpfs::mount(&work.path().join("disk"), 64) else {
        return;
    };
    let journal = disk.path().join("journal");
    let project = project();
    let vehicle = unique_vehicle("full");
    let mut player = Player::start_journaled(&work, project.path(), &vehicle, &journal, &[]);

    // Fill the disk, 100 events a send; every send that exits 0 says its events are safe.
    let mut safe: Vec<(String, usize)> = Vec::new();
    let mut failed = None;
    for _ in 0..60 {
        let o = player.send_with("tick(1)", &["--count", "100", "--timeout", "1"]);
        if o.status.success() {
            safe.push((origin(&o), 100));
        } else {
            failed = Some(o);
            break;
        }
    }
    let o = failed.expect("6,000 events fill a 64 KiB journal");
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(text(&o).contains("not on record"), "{}", text(&o));
    assert!(!safe.is_empty(), "the disk had room for a few events");

    // The recorder's state is in the status, and the nets know.
    let s = player.wait_for(10.0, |s| {
        s["recorder"]["state"] == "failing" && watch_has(s, "unrecorded")
    });
    assert_eq!(s["recorder"]["state"], "failing", "{s}");
    assert!(
        watch_has(&s, "unrecorded"),
        "recorder_failed reached the nets: {s}"
    );
    // The mission goes on: events are still processed, though not acknowledged.
    let processed = s["stats"]["processed"].as_u64().unwrap();
    let o = player.send_with("tick(2)", &["--count", "5", "--timeout", "1"]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let s = player.wait_for(10.0, |s| {
        s["stats"]["processed"].as_u64() >= Some(processed + 5)
    });
    assert!(
        s["stats"]["processed"].as_u64() >= Some(processed + 5),
        "{s}"
    );
    let st = &s["stats"];
    let sum = ["processed", "unused", "refused", "queued"]
        .iter()
        .map(|k| st[k].as_u64().unwrap())
        .sum::<u64>();
    assert_eq!(st["received"].as_u64(), Some(sum), "{s}");

    // Space comes back: the recorder catches up, says so, and acknowledges again.
    disk.resize(4096);
    let s = player.wait_for(10.0, |s| {
        s["recorder"]["state"] == "ok" && watch_has(s, "recording")
    });
    assert_eq!(s["recorder"]["state"], "ok", "{s}");
    assert!(
        watch_has(&s, "recording"),
        "recorder_restored reached the nets: {s}"
    );
    let o = player.send_with("tick(3)", &["--count", "5"]);
    assert!(o.status.success(), "{}", text(&o));
    safe.push((origin(&o), 5));
    let log = player.log_text();
    let errors = log.lines().filter(|l| l.contains("ERROR")).count();
    assert!(
        errors <= 5,
        "{errors} ERROR lines: the log is flooded\n{log}"
    );

    // A crash, then a resume from the journal: it is whole.
    player.child.kill().unwrap(); // SIGKILL
    player.child.wait().unwrap();
    drop(player);
    let player = Player::start_journaled(&work, project.path(), &vehicle, &journal, &["--resume"]);
    let s = player.wait_for(10.0, |s| s["stats"]["resumed_steps"].as_u64() > Some(0));
    assert!(s["stats"]["resumed_steps"].as_u64() > Some(0), "{s}");
    assert!(player.stop().success());

    // Nothing acknowledged is missing from the journal, and it replays.
    let (entries, o) = journal_json(&journal);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    for (origin, n) in &safe {
        let prefix = format!("{origin}#");
        let found = entries
            .iter()
            .filter(|e| e["kind"] == "submit")
            .filter(|e| e["origin"].as_str().is_some_and(|o| o.starts_with(&prefix)))
            .count();
        assert_eq!(
            found, *n,
            "events of {origin} acknowledged but not in the journal"
        );
    }
    let o = petrel(&["replay", &journal.display().to_string()]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
}

/// Past its backlog in memory, a failing recorder drops records (counted, unacknowledged:
/// `petrel send` says they are not on record) and, once it can write again, goes on from a
/// checkpoint of the state: the journal replays across the gap and the mission resumes.
#[test]
fn past_its_backlog_the_recorder_drops_records_and_goes_on_from_a_checkpoint() {
    let work = Workdir::new();
    let Some(disk) = Tmpfs::mount(&work.path().join("disk"), 64) else {
        return;
    };
    let journal = disk.path().join("journal");
    let project = project();
    let vehicle = unique_vehicle("drop");
    let mut player = Player::start_journaled(
        &work,
        project.path(),
        &vehicle,
        &journal,
        &["--journal-backlog-mb", "0.02"],
    );
    let mut dropping = None;
    for _ in 0..60 {
        let _ = player.send_with("tick(1)", &["--count", "200", "--timeout", "1"]);
        let s = player.status().unwrap_or_default();
        if s["recorder"]["state"] == "dropping" {
            dropping = Some(s);
            break;
        }
    }
    let s = dropping.expect("the recorder went past its backlog");
    assert!(s["recorder"]["lost_entries"].as_u64() > Some(0), "{s}");
    let o = player.send_with("tick(2)", &["--count", "5", "--timeout", "1"]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(
        text(&o).contains("5 taken but not on record"),
        "{}",
        text(&o)
    );

    disk.resize(4096);
    let s = player.wait_for(10.0, |s| {
        s["recorder"]["state"] == "ok" && watch_has(s, "recording")
    });
    assert_eq!(s["recorder"]["state"], "ok", "{s}");
    let o = player.send_with("tick(3)", &["--count", "5"]);
    assert!(o.status.success(), "{}", text(&o));
    let live = player.status().unwrap();
    player.child.kill().unwrap(); // SIGKILL
    player.child.wait().unwrap();
    drop(player);

    let o = petrel(&["replay", &journal.display().to_string()]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("dropped"),
        "{}",
        text(&o)
    );
    let player = Player::start_journaled(&work, project.path(), &vehicle, &journal, &["--resume"]);
    let s = player.wait_for(10.0, |s| s["stats"]["resumed_steps"].as_u64() > Some(0));
    assert_eq!(s["marking"], live["marking"], "resumed {s}\nlive {live}");
    assert!(player.stop().success());
}
