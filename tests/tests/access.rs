//! Who can reach a vehicle (docs/security.md): built-in events only from the player, the
//! vehicle's files private and gone with its last process, an operator group, and a hostile
//! local user who can neither inject, nor read, nor block.
//!
//! The tests with a second user run only as root (they switch users with `setpriv`); as
//! another user they say so and pass.

use petrel_ipc::{EventMsg, Participant, Role, Value, Vehicle};
use petrel_tests::{
    as_user, can_switch_users, euid, petrel_bin, repo, unique_vehicle, Player, Workdir,
};
use std::os::unix::fs::{MetadataExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

fn liveness_dir() -> PathBuf {
    repo().join("tests/data/liveness")
}

fn marked(s: &serde_json::Value, net: &str, place: &str) -> bool {
    s["marking"][net]
        .as_array()
        .is_some_and(|m| m.iter().any(|p| p == place))
}

fn text(o: &Output) -> String {
    format!(
        "exit {:?}\nstdout: {}\nstderr: {}",
        o.status.code(),
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// The session's files in /dev/shm.
fn shm_files(prefix: &str) -> Vec<PathBuf> {
    std::fs::read_dir("/dev/shm")
        .map(|d| {
            d.filter_map(Result::ok)
                .filter(|e| e.file_name().to_string_lossy().starts_with(prefix))
                .map(|e| e.path())
                .collect()
        })
        .unwrap_or_default()
}

fn journal_lines(journal: &Path) -> Vec<serde_json::Value> {
    let o = Command::new(petrel_bin())
        .args(["journal", "show"])
        .arg(journal)
        .args(["--format", "json"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    String::from_utf8_lossy(&o.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

#[test]
fn built_in_events_from_other_processes_are_refused_and_journaled() {
    let vehicle = unique_vehicle("builtin");
    let player = Player::start(&liveness_dir(), &vehicle);
    let v = Vehicle::new(&vehicle).unwrap();
    let text_of = |s: &str| Value::Text(s.into());
    let forged = [
        EventMsg::new("program_lost", vec![text_of("WORKER")]),
        EventMsg::new("call_failed", vec![text_of("WORKER"), text_of("work")]),
        EventMsg::new(
            "safety_violation",
            vec![text_of("WATCH"), text_of("gone"), text_of("lost")],
        ),
        EventMsg::new("livelock", vec![text_of("WATCH"), text_of("gone")]),
        EventMsg::new("bad_message", vec![text_of("x"), text_of("y")]),
    ];
    // An operator tool, a program, and a process that claims to be the player: the player
    // raises its built-ins itself and never receives them, so every one of these is forged.
    // (The program is not the project's WORKER, whose leaving would be a true program_lost.)
    let roles = [
        Role::tool("forger").unwrap(),
        Role::program("PLN").unwrap(),
        Role::Player,
    ];
    let mut sent = 0u64;
    for role in roles {
        let me = Participant::join(&v, role).unwrap();
        let tx = me.event_sender().unwrap();
        for msg in &forged {
            tx.send(msg).unwrap();
            sent += 1;
        }
        // Stay until the player took them (shared memory goes with its sender).
        let origin = tx.origin().to_string();
        player.wait_for(10.0, |s| {
            s["senders"][&origin]["last_seq"].as_u64() >= Some(forged.len() as u64)
        });
    }
    let s = player.wait_for(10.0, |s| s["stats"]["bad_messages"].as_u64() >= Some(sent));
    assert_eq!(s["stats"]["messages"].as_u64(), Some(sent), "{s}");
    assert_eq!(s["stats"]["bad_messages"].as_u64(), Some(sent), "{s}");
    assert!(
        marked(&s, "WATCH", "up"),
        "no forged program_lost fired: {s}"
    );
    assert!(marked(&s, "WATCH", "waiting"), "no forged call_failed: {s}");
    // The CAN data server reports the commands it could not carry out as call_failed: that
    // one built-in it may send.
    let bridge = Participant::join(&v, Role::CanBridge).unwrap();
    let tx = bridge.event_sender().unwrap();
    tx.send(&EventMsg::new(
        "call_failed",
        vec![text_of("WORKER"), text_of("work")],
    ))
    .unwrap();
    let s = player.wait_for(10.0, |s| marked(s, "WATCH", "complained"));
    assert!(marked(&s, "WATCH", "complained"), "{s}");
    assert_eq!(s["stats"]["bad_messages"].as_u64(), Some(sent), "{s}");
    drop(tx);
    drop(bridge);
    let journal = player.journal.clone();
    let _work = player.work.clone();
    assert!(player.stop().success());
    // Each forgery is on record as refused, with who sent it and why.
    let refused: Vec<_> = journal_lines(&journal)
        .into_iter()
        .filter(|l| l["kind"] == "refused")
        .collect();
    assert_eq!(refused.len() as u64, sent, "{refused:?}");
    for r in &refused {
        assert!(
            r["outcome"]
                .as_str()
                .is_some_and(|o| o.contains("built-in event: only the player raises it")),
            "{r}"
        );
    }
    for origin in ["tool/forger", "program/PLN", "player"] {
        assert_eq!(
            refused.iter().filter(|r| r["origin"] == origin).count(),
            forged.len(),
            "{origin}: {refused:?}"
        );
    }
}

#[test]
fn the_vehicles_files_are_private_and_go_with_its_last_process() {
    let vehicle = unique_vehicle("private");
    let player = Player::start(&liveness_dir(), &vehicle);
    let (prefix, dir) = {
        let v = Vehicle::new(&vehicle).unwrap();
        (v.shm_prefix().unwrap(), v.runtime_dir().unwrap())
    };
    let files = shm_files(&prefix);
    assert!(
        files
            .iter()
            .any(|f| f.to_string_lossy().ends_with(".global_mgmt")),
        "{files:?}"
    );
    for f in &files {
        let m = std::fs::symlink_metadata(f).unwrap();
        assert_eq!(m.uid(), euid(), "{}", f.display());
        assert_eq!(
            m.mode() & 0o077,
            0,
            "{} is open to others: {:o}",
            f.display(),
            m.mode()
        );
    }
    let m = std::fs::metadata(&dir).unwrap();
    assert_eq!(m.mode() & 0o7777, 0o700, "{}", dir.display());
    assert!(
        !dir.starts_with("/tmp/iceoryx2"),
        "the vehicle's directory is {}",
        dir.display()
    );
    // The player is the vehicle's last process: when it stops, nothing of the vehicle stays.
    assert!(player.stop().success());
    assert_eq!(shm_files(&prefix), Vec::<PathBuf>::new());
    assert!(!dir.exists(), "{} is still there", dir.display());
}

#[test]
fn an_operator_in_the_vehicles_group_sends_and_reads_the_status() {
    if !can_switch_users("an_operator_in_the_vehicles_group_sends_and_reads_the_status") {
        return;
    }
    let (group, operator, stranger) = (64_000u32, 64_001u32, 64_002u32);
    let vehicle = unique_vehicle("group");
    let player = Player::start_with(&liveness_dir(), &vehicle, &["--group", &group.to_string()]);
    let (prefix, dir) = {
        let v = Vehicle::new(&vehicle).unwrap();
        assert_eq!(v.shared_gid().unwrap(), Some(group));
        (v.shm_prefix().unwrap(), v.runtime_dir().unwrap())
    };
    let base = dir.parent().unwrap().to_path_buf();
    let m = std::fs::metadata(&dir).unwrap();
    assert_eq!((m.mode() & 0o7777, m.gid()), (0o2770, group));
    for f in shm_files(&prefix) {
        let m = std::fs::symlink_metadata(&f).unwrap();
        assert_eq!(m.mode() & 0o007, 0, "{} is open to others", f.display());
    }
    // The project must be readable by the operator: a copy of its own.
    let work = Workdir::new();
    let project = work.path().join("liveness");
    std::fs::create_dir(&project).unwrap();
    for f in ["petrel.toml", "watch.pn"] {
        std::fs::copy(liveness_dir().join(f), project.join(f)).unwrap();
    }
    for p in [work.path(), project.as_path()] {
        std::fs::set_permissions(p, std::fs::Permissions::from_mode(0o755)).unwrap();
    }
    let petrel = |uid: u32, groups: &[u32], args: &[&str]| {
        as_user(uid, groups, &petrel_bin())
            .args(args)
            .arg("--vehicle")
            .arg(&vehicle)
            .env(petrel_ipc::RUNTIME_DIR_ENV, &base)
            .output()
            .unwrap()
    };
    let p = project.to_str().unwrap();
    let o = petrel(operator, &[group], &["status", p, "--json"]);
    if !o.status.success() {
        let ls = Command::new("ls").arg("-laR").arg(&base).output().unwrap();
        eprintln!("{}", String::from_utf8_lossy(&ls.stdout));
    }
    assert!(o.status.success(), "{}", text(&o));
    let s: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(marked(&s, "WATCH", "up"), "{s}");
    let o = petrel(operator, &[group], &["send", p, "tick(5)"]);
    assert!(o.status.success(), "{}", text(&o));
    let s = player.wait_for(10.0, |s| s["stats"]["processed"] == 1);
    assert_eq!(s["stats"]["processed"], 1, "{s}");
    // Someone outside the group gets nothing.
    for args in [&["status", p][..], &["send", p, "tick(6)"][..]] {
        let o = petrel(stranger, &[], args);
        assert!(!o.status.success(), "{}", text(&o));
    }
    assert_eq!(player.status().unwrap()["stats"]["messages"], 1);
    assert!(player.stop().success());
    assert_eq!(shm_files(&prefix), Vec::<PathBuf>::new());
    assert!(!dir.exists(), "{} is still there", dir.display());
}

/// What the hostile child tried, and what worked.
const HOSTILE_ENV: &str = "PETREL_TEST_HOSTILE";

/// The names the hostile user squats in /dev/shm: after the session prefix (which a listing
/// shows), the name the node counter had before sessions existed, and last a link to a file of
/// the vehicle's user.
fn squat_paths(prefix: &str, vehicle: &str) -> Vec<PathBuf> {
    [
        format!("{prefix}squat.data"),
        format!("{prefix}9204dd183d1c4d8e1ff592a30766ffa6765aa8b5_node.0_10_1.global_mgmt"),
        format!(
            "petrel_{vehicle}_9204dd183d1c4d8e1ff592a30766ffa6765aa8b5_node.0_10_0.global_mgmt"
        ),
        format!("{prefix}zz_link"),
    ]
    .into_iter()
    .map(|n| Path::new("/dev/shm").join(n))
    .collect()
}

/// Removes the hostile user's squats, pass or fail.
struct Squats(Vec<PathBuf>);

impl Drop for Squats {
    fn drop(&mut self) {
        for p in &self.0 {
            let _ = std::fs::remove_file(p);
        }
    }
}

/// Runs as a child process, as another user, when PETREL_TEST_HOSTILE is set: attacks the
/// vehicle named there, whose base directory is PETREL_RUNTIME_DIR, and prints what worked.
fn main_as_hostile() -> bool {
    let Ok(spec) = std::env::var(HOSTILE_ENV) else {
        return false;
    };
    let spec: serde_json::Value = serde_json::from_str(&spec).unwrap();
    let (vehicle, prefix, dir, canary, project) = (
        spec["vehicle"].as_str().unwrap(),
        spec["prefix"].as_str().unwrap(),
        PathBuf::from(spec["dir"].as_str().unwrap()),
        spec["canary"].as_str().unwrap(),
        spec["project"].as_str().unwrap(),
    );
    let mut report = serde_json::Map::new();
    let mut note = |k: &str, v: serde_json::Value| {
        report.insert(k.into(), v);
    };
    // 1. Write into, or read, the vehicle's shared memory (what blocked `send` and `status`
    // before: a world-writable node counter).
    let files = shm_files(prefix);
    let writable = files
        .iter()
        .filter(|f| std::fs::OpenOptions::new().write(true).open(f).is_ok())
        .count();
    let readable = files
        .iter()
        .filter(|f| std::fs::File::open(f).is_ok())
        .count();
    note("shm_files", files.len().into());
    note("shm_writable", writable.into());
    note("shm_readable", readable.into());
    // 2. Look into the vehicle's directory (its services, sockets and session).
    note("dir_listable", std::fs::read_dir(&dir).is_ok().into());
    note(
        "session_readable",
        std::fs::read(dir.join("session")).is_ok().into(),
    );
    // 3. Join the vehicle, to send events or read the heartbeat.
    let joined = Vehicle::new(vehicle)
        .map_err(|e| e.to_string())
        .and_then(|v| {
            Participant::join(&v, Role::tool("evil").unwrap()).map_err(|e| e.to_string())
        });
    note("joined", joined.is_ok().into());
    if let Err(e) = &joined {
        note("join_error", e.clone().into());
    }
    drop(joined);
    // 4. The same with the command line: inject an event, read the status.
    let send = Command::new(petrel_bin())
        .args(["send", project, "tick(666)", "--vehicle", vehicle])
        .output()
        .unwrap();
    note("send_exit", send.status.code().into());
    let status = Command::new(petrel_bin())
        .args(["status", project, "--json", "--vehicle", vehicle])
        .output()
        .unwrap();
    note("status_exit", status.status.code().into());
    note("status_stdout", status.stdout.len().into());
    // 5. Block it: squat names in /dev/shm (see squat_paths), and plant a link the vehicle's
    // cleanup must not follow.
    let squats = squat_paths(prefix, vehicle);
    let (link, files) = squats.split_last().unwrap();
    let mut squatted = Vec::new();
    for path in files {
        if std::fs::write(path, [0xff; 16]).is_ok() {
            squatted.push(path.display().to_string());
        }
    }
    if std::os::unix::fs::symlink(canary, link).is_ok() {
        squatted.push(link.display().to_string());
    }
    note("squatted", squatted.into());
    // 6. Flood it: the same vehicle name from the hostile user's side is another vehicle.
    let flood = Command::new(petrel_bin())
        .args([
            "send",
            project,
            "tick(7)",
            "--count",
            "1000",
            "--vehicle",
            vehicle,
        ])
        .env_remove(petrel_ipc::RUNTIME_DIR_ENV)
        .output()
        .unwrap();
    note("flood_exit", flood.status.code().into());
    note(
        "flood_stderr",
        String::from_utf8_lossy(&flood.stderr).into_owned().into(),
    );
    println!("@@ RESULT {}", serde_json::Value::Object(report));
    true
}

#[test]
fn hostile_child() {
    // The entry point of the hostile child process (a no-op as a test).
    let _ = main_as_hostile();
}

#[test]
fn a_hostile_local_user_can_neither_inject_nor_read_nor_block_the_vehicle() {
    if !can_switch_users("a_hostile_local_user_can_neither_inject_nor_read_nor_block_the_vehicle") {
        return;
    }
    let hostile = 65_534u32; // nobody
    let vehicle = unique_vehicle("hostile");
    let player = Player::start(&liveness_dir(), &vehicle);
    let (prefix, dir) = {
        let v = Vehicle::new(&vehicle).unwrap();
        (v.shm_prefix().unwrap(), v.runtime_dir().unwrap())
    };
    let base = dir.parent().unwrap().to_path_buf();
    // A file of ours the hostile user links to: the vehicle must never follow the link.
    let work = Workdir::new();
    let project = work.path().join("liveness");
    std::fs::create_dir(&project).unwrap();
    for f in ["petrel.toml", "watch.pn"] {
        std::fs::copy(liveness_dir().join(f), project.join(f)).unwrap();
    }
    let canary = work.path().join("canary");
    std::fs::write(&canary, "canary").unwrap();
    std::fs::set_permissions(&canary, std::fs::Permissions::from_mode(0o600)).unwrap();
    for p in [work.path(), project.as_path()] {
        std::fs::set_permissions(p, std::fs::Permissions::from_mode(0o755)).unwrap();
    }
    let o = player.send("tick(1)", 1);
    assert!(o.status.success(), "{}", text(&o));
    let squats = Squats(squat_paths(&prefix, &vehicle));
    let spec = serde_json::json!({
        "vehicle": vehicle, "prefix": prefix, "dir": dir, "canary": canary,
        "project": project,
    });
    let child = as_user(hostile, &[], &std::env::current_exe().unwrap())
        .args([
            "--exact",
            "hostile_child",
            "--nocapture",
            "--test-threads=1",
        ])
        .env(HOSTILE_ENV, spec.to_string())
        .env(petrel_ipc::RUNTIME_DIR_ENV, &base)
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&child.stdout);
    let line = out
        .lines()
        .find_map(|l| l.split_once("@@ RESULT ").map(|(_, r)| r))
        .unwrap_or_else(|| panic!("the hostile child reported nothing: {}", text(&child)));
    let r: serde_json::Value = serde_json::from_str(line).unwrap();
    eprintln!("hostile user {hostile}: {r:#}");
    let squatted = r["squatted"].as_array().map_or(0, Vec::len);
    let verdict = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        // It saw the files in /dev/shm, but could neither write nor read one.
        assert!(r["shm_files"].as_u64() > Some(0), "{r}");
        assert_eq!(r["shm_writable"], 0, "{r}");
        assert_eq!(r["shm_readable"], 0, "{r}");
        assert_eq!(r["dir_listable"], false, "{r}");
        assert_eq!(r["session_readable"], false, "{r}");
        assert_eq!(r["joined"], false, "{r}");
        assert_ne!(r["send_exit"], 0, "{r}");
        assert_ne!(r["status_exit"], 0, "{r}");
        assert_eq!(r["status_stdout"], 0, "{r}");
        // Its flood went to a vehicle of its own, where no player runs.
        assert_eq!(r["flood_exit"], 1, "{r}");
        assert!(
            r["flood_stderr"]
                .as_str()
                .is_some_and(|e| e.contains("no player is running")),
            "{r}"
        );
        assert_eq!(squatted, squats.0.len(), "the squat itself failed: {r}");
        // The mission goes on: new processes join (a new node, a new sender), events are taken,
        // and nothing of the hostile user's reached the player.
        let o = player.send("tick(2)", 1);
        assert!(o.status.success(), "{}", text(&o));
        let s = player.wait_for(10.0, |s| s["stats"]["processed"] == 2);
        assert_eq!(s["stats"]["processed"], 2, "{s}");
        assert_eq!(s["stats"]["messages"], 2, "{s}");
        assert_eq!(s["stats"]["bad_messages"], 0, "{s}");
        let v = Vehicle::new(&vehicle).unwrap();
        let worker = Participant::join(&v, Role::program("WORKER").unwrap()).unwrap();
        let calls = worker.call_receiver().unwrap();
        let o = player.send("ask", 1);
        assert!(o.status.success(), "{}", text(&o));
        let deadline = Instant::now() + Duration::from_secs(10);
        let mut got = Vec::new();
        while got.is_empty() && Instant::now() < deadline {
            let _ = calls.drain(|c| got.push(c));
            std::thread::sleep(Duration::from_millis(10));
        }
        assert_eq!(got.len(), 1, "the call reached the new program");
    }));
    let stopped = player.stop();
    // The vehicle's last process removed its files, and followed no link.
    let leftover = shm_files(&prefix)
        .into_iter()
        .filter(|p| !squats.0.contains(p))
        .collect::<Vec<_>>();
    let canary_text = std::fs::read_to_string(&canary).unwrap_or_default();
    let canary_mode = std::fs::metadata(&canary).map(|m| m.mode() & 0o777).ok();
    drop(squats);
    if let Err(e) = verdict {
        std::panic::resume_unwind(e);
    }
    assert!(stopped.success());
    assert_eq!(leftover, Vec::<PathBuf>::new());
    assert!(!dir.exists(), "{} is still there", dir.display());
    assert_eq!((canary_text.as_str(), canary_mode), ("canary", Some(0o600)));
}
