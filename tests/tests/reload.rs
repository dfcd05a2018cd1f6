//! `petrel reload` between real processes: a UAV flight (`petrel play` with the GUI/PLD and DEC
//! programs) given a new version of its project mid-transit, a version the verifier refuses,
//! a crash of the player right after a reload, the replay of a mission across a reload, and
//! events sent while a reload is under way.

use petrel_tests::{
    petrel, repo, unique_vehicle, vehicle_bin, Player, Processes, TempProject, Workdir,
};
use std::path::Path;
use std::process::{Command, Output, Stdio};

/// Simulated seconds per second: a transit lasts 12 s, long enough to reload during one.
const SPEED: &str = "20";

fn programs(vehicle: &str) -> Processes {
    let spawn = |bin: &str, extra: &[&str]| {
        Command::new(vehicle_bin(bin))
            .args(["--vehicle", vehicle])
            .args(extra)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("a UAV program starts")
    };
    Processes(vec![
        spawn("uav-gui", &["--speed", SPEED]),
        spawn("uav-dec", &[]),
    ])
}

fn wait_programs(vehicle: &str) {
    let v = petrel_ipc::Vehicle::new(vehicle).unwrap();
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
    while std::time::Instant::now() < deadline {
        let gui = petrel_ipc::is_program_alive(&v, "GUI").unwrap_or(false);
        let dec = petrel_ipc::is_program_alive(&v, "DEC").unwrap_or(false);
        if gui && dec {
            return;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    panic!("the UAV programs did not start");
}

fn marked(s: &serde_json::Value, net: &str, place: &str) -> bool {
    s["marking"][net]
        .as_array()
        .is_some_and(|m| m.iter().any(|p| p == place))
}

/// The UAV mission with a new reaction net, BIRDS (in `start`), waiting for `bird_strike`,
/// an event the running version does not declare; `extra` goes into BIRDS.
fn uav_with_birds(extra: &str) -> TempProject {
    let p = TempProject::copy(&repo().join("missions/uav"), |name, text| {
        if name != "petrel.toml" {
            return text;
        }
        text.replace(
            "files = [\"mission.pn\", \"events.pn\"]",
            "files = [\"mission.pn\", \"events.pn\", \"birds.pn\"]",
        )
        .replace(
            "start = [\"MISSION\", \"EVENTS\"]",
            "start = [\"MISSION\", \"EVENTS\", \"BIRDS\"]",
        )
        .replace(
            "[programs.GUI]",
            "bird_strike = { category = \"mission\" }\nbird_checked = { category = \"mission\" }\ngust = { category = \"mission\" }\n\n[programs.GUI]",
        )
    });
    std::fs::write(
        p.path().join("birds.pn"),
        format!(
            "net BIRDS {{\n    place watching = 1\n    place struck\n\n    transition strike on bird_strike: watching -> struck\n    transition checked on bird_checked: struck -> watching\n{extra}}}\n"
        ),
    )
    .expect("birds.pn written");
    p
}

fn reload(player: &Player, dir: &Path, extra: &[&str]) -> Output {
    Command::new(petrel_tests::petrel_bin())
        .arg("reload")
        .arg(dir)
        .args(["--vehicle", &player.vehicle])
        .args(extra)
        .output()
        .expect("petrel reload runs")
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// A UAV flight in transit: the player (journaled in `work`) and its programs.
fn in_transit(work: &Workdir) -> (Player, Processes) {
    let vehicle = unique_vehicle("reload");
    let player = Player::start_in(work, &repo().join("missions/uav"), &vehicle, &[]);
    let programs = programs(&vehicle);
    wait_programs(&vehicle);
    let o = player.send("start_mission", 1);
    assert!(o.status.success(), "{}", text(&o));
    let s = player.wait_for(30.0, |s| marked(s, "MISSION", "transiting"));
    assert!(marked(&s, "MISSION", "transiting"), "{s}");
    (player, programs)
}

fn send_to(player: &Player, dir: &Path, event: &str) -> Output {
    Command::new(petrel_tests::petrel_bin())
        .arg("send")
        .arg(dir)
        .arg(event)
        .args(["--vehicle", &player.vehicle])
        .output()
        .expect("petrel send runs")
}

#[test]
fn a_flight_reloaded_mid_transit_takes_the_new_reaction_net_and_uses_it() {
    let work = Workdir::new();
    let (player, programs) = in_transit(&work);
    let new = uav_with_birds("");
    // A ground-station shadow, started with the first version, follows the reload.
    let shadow_log = work.path().join("shadow.log");
    // Stopped (SIGTERM) when dropped, pass or fail.
    let shadow = Command::new(petrel_tests::petrel_bin())
        .arg("play")
        .arg(repo().join("missions/uav"))
        .args(["--vehicle", &player.vehicle, "--shadow", "--run-for", "300"])
        .env("RUST_LOG", "info")
        .stderr(std::fs::File::create(&shadow_log).unwrap())
        .spawn()
        .expect("the shadow starts");
    let shadow = Processes(vec![shadow]);
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(20);
    while !std::fs::read_to_string(&shadow_log)
        .unwrap_or_default()
        .contains("shadow synchronised")
    {
        assert!(
            std::time::Instant::now() < deadline,
            "the shadow did not synchronise"
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }

    // A dry run says what would happen and swaps nothing.
    let o = reload(&player, new.path(), &["--dry-run"]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(
        text(&o).contains("dry run: the reload would be accepted"),
        "{}",
        text(&o)
    );
    assert!(
        text(&o).contains("net BIRDS: new, in start: activated with {watching}"),
        "{}",
        text(&o)
    );
    let s = player.status().expect("status");
    assert!(s["marking"]["BIRDS"].is_null(), "{s}");

    let o = reload(&player, new.path(), &[]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(
        text(&o).contains("reload accepted: version "),
        "{}",
        text(&o)
    );
    let s = player.status().expect("status");
    assert!(marked(&s, "BIRDS", "watching"), "{s}");
    // Mid-transit still: the mapping kept the mission where it was.
    assert!(marked(&s, "MISSION", "transiting"), "{s}");
    assert_eq!(s["stats"]["reloads"], 1, "{s}");
    assert_eq!(s["version"].as_str().map(str::len), Some(16), "{s}");

    // An event only the new net handles fires its transition.
    let o = send_to(&player, new.path(), "bird_strike");
    assert!(o.status.success(), "{}", text(&o));
    let s = player.wait_for(10.0, |s| marked(s, "BIRDS", "struck"));
    assert!(marked(&s, "BIRDS", "struck"), "{s}");
    // The programs saw no interruption: the flight goes on to the landing.
    let s = player.wait_for(60.0, |s| marked(s, "MISSION", "landed"));
    assert!(marked(&s, "MISSION", "landed"), "{s}");
    assert_eq!(s["stats"]["calls_failed"], 0, "{s}");
    assert_eq!(s["stats"]["bad_messages"], 0, "{s}");
    let code = shadow.stop()[0];
    let log = std::fs::read_to_string(&shadow_log).unwrap_or_default();
    assert_eq!(code, Some(0), "{log}");
    assert!(
        log.contains("1 reload followed, 0 divergence alarms"),
        "{log}"
    );
    drop(programs);
    assert!(player.stop().success());
}

#[test]
fn a_reload_that_makes_a_place_unsafe_is_refused_and_the_mission_goes_on_unchanged() {
    let work = Workdir::new();
    let (player, programs) = in_transit(&work);
    // `gust` puts a token in `in_flight`, which the aircraft in transit holds.
    let bad = uav_with_birds("    transition gust on gust: watching -> watching, in_flight\n");
    let before = player.status().expect("status");
    let o = reload(&player, bad.path(), &[]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let out = text(&o);
    assert!(
        out.contains("reload refused: the mission goes on unchanged"),
        "{out}"
    );
    assert!(
        out.contains("unsafe place: `BIRDS.gust` would put a second token in `global.in_flight`"),
        "{out}"
    );
    assert!(out.contains("from the mapped state by: gust"), "{out}");
    let o = reload(&player, bad.path(), &["--format", "json"]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).expect("json");
    assert_eq!(doc["accepted"], false, "{doc}");
    assert_eq!(doc["trace"], serde_json::json!(["gust"]), "{doc}");

    let s = player.status().expect("status");
    assert!(s["marking"]["BIRDS"].is_null(), "{s}");
    assert_eq!(s["marking"]["MISSION"], before["marking"]["MISSION"], "{s}");
    assert_eq!(s["stats"]["reloads"], 0, "{s}");
    assert!(s["version"].is_null(), "{s}");
    // The old version still runs: it does not know the new event, and the flight goes on.
    let o = send_to(&player, bad.path(), "bird_strike");
    assert!(!o.status.success(), "{}", text(&o));
    let processed = s["stats"]["processed"].as_u64().unwrap();
    let s = player.wait_for(30.0, |s| {
        s["stats"]["processed"].as_u64().unwrap_or(0) >= processed + 2
    });
    assert!(
        s["stats"]["processed"].as_u64().unwrap() >= processed + 2,
        "{s}"
    );
    drop(programs);
    assert!(player.stop().success());
}

#[test]
fn a_new_version_that_does_not_map_is_refused_with_each_reason_unless_the_mapping_says() {
    let work = Workdir::new();
    let (player, programs) = in_transit(&work);
    // `transiting` renamed `cruising`: the marked place vanishes.
    let renamed = TempProject::copy(&repo().join("missions/uav"), |name, text| {
        if name == "mission.pn" {
            text.replace("transiting", "cruising")
        } else {
            text
        }
    });
    let o = reload(&player, renamed.path(), &[]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(
        text(&o).contains("marked place `MISSION.transiting` is not in the new version"),
        "{}",
        text(&o)
    );
    let mapping = work.path().join("reload.toml");
    std::fs::write(
        &mapping,
        "[rename]\nplaces = { \"MISSION.transiting\" = \"MISSION.cruising\" }\n",
    )
    .unwrap();
    let o = reload(
        &player,
        renamed.path(),
        &["--mapping", mapping.to_str().unwrap()],
    );
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(
        text(&o).contains("MISSION.transiting -> MISSION.cruising: marked"),
        "{}",
        text(&o)
    );
    let s = player.status().expect("status");
    assert!(marked(&s, "MISSION", "cruising"), "{s}");
    // A mapping file that does not read is a usage error, with its line and column.
    std::fs::write(&mapping, "[rename]\nnets = { A = 3 }\n").unwrap();
    let o = reload(
        &player,
        renamed.path(),
        &["--mapping", mapping.to_str().unwrap()],
    );
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(
        text(&o).contains("reload.toml:2:14: invalid type"),
        "{}",
        text(&o)
    );
    drop(programs);
    assert!(player.stop().success());
}

#[test]
fn a_crash_right_after_a_reload_resumes_on_the_new_version_and_the_journal_replays_across_it() {
    let work = Workdir::new();
    let (player, programs) = in_transit(&work);
    let new = uav_with_birds("");
    let o = reload(&player, new.path(), &[]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let o = send_to(&player, new.path(), "bird_strike");
    assert!(o.status.success(), "{}", text(&o));
    let s = player.wait_for(10.0, |s| marked(s, "BIRDS", "struck"));
    assert!(marked(&s, "BIRDS", "struck"), "{s}");
    // SIGKILL, then the same command line as before, with --resume: the first version's
    // directory, as `petrel up` would restart it.
    let mut player = player;
    player.child.kill().unwrap();
    player.child.wait().unwrap();
    let vehicle = player.vehicle.clone();
    let resumed = Player::start_in(&work, &repo().join("missions/uav"), &vehicle, &["--resume"]);
    let s = resumed.status().expect("status");
    assert!(marked(&s, "BIRDS", "struck"), "{s}");
    assert!(s["version"].is_string(), "{s}");
    let o = send_to(&resumed, new.path(), "bird_checked");
    assert!(o.status.success(), "{}", text(&o));
    let s = resumed.wait_for(10.0, |s| marked(s, "BIRDS", "watching"));
    assert!(marked(&s, "BIRDS", "watching"), "{s}");
    let s = resumed.wait_for(60.0, |s| marked(s, "MISSION", "landed"));
    assert!(marked(&s, "MISSION", "landed"), "{s}");
    drop(programs);
    assert!(resumed.stop().success());
    drop(player);

    // The whole mission replays from its first version, across the reload and the resume.
    let journal = work.path().join("journal");
    let o = petrel(&[
        "replay",
        journal.to_str().unwrap(),
        "--project",
        repo().join("missions/uav").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(text(&o).contains("across 1 reload"), "{}", text(&o));
    assert!(text(&o).contains("MISSION{landed}"), "{}", text(&o));
    // The new version's files are kept beside the journal, named by their content hash.
    let kept: Vec<String> = std::fs::read_dir(&journal)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("project-"))
        .collect();
    assert_eq!(kept.len(), 1, "{kept:?}");
    assert!(journal.join(&kept[0]).join("birds.pn").is_file());
    // Given the new version, the replay starts at the reload and says so.
    let o = petrel(&[
        "replay",
        journal.to_str().unwrap(),
        "--project",
        new.path().to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(
        text(&o).contains("replaying from its last reload"),
        "{}",
        text(&o)
    );
}

#[test]
fn events_sent_while_a_reload_is_verified_are_all_accounted() {
    // No programs: a player, a stream of events, and reloads between them.
    let manifest = |extra: &str| {
        format!(
            "[project]\nname = \"acc\"\nfiles = [\"a.pn\"]\nstart = [\"A\"]\n\n[events]\nping = {{ category = \"nominal\" }}\n{extra}"
        )
    };
    let net = "net A {\n    place p = 1\n    transition t on ping: p -> p\n}\n";
    let old = TempProject::new(&[("petrel.toml", &manifest("")), ("a.pn", net)]);
    let new = TempProject::new(&[
        ("petrel.toml", &manifest("pong = { category = \"nominal\" }\n")),
        (
            "a.pn",
            "net A {\n    place p = 1\n    transition t on ping: p -> p\n    transition u on pong: p -> p\n}\n",
        ),
    ]);
    let vehicle = unique_vehicle("reloadacc");
    let player = Player::start(old.path(), &vehicle);
    // 2,000 events: fewer than the player's event buffer holds (2,048, ipc/src/port.rs), so
    // that none is refused while a verification holds the player's loop, whatever the timing.
    let sender = Command::new(petrel_tests::petrel_bin())
        .arg("send")
        .arg(old.path())
        .arg("ping")
        .args(["--vehicle", &vehicle, "--count", "2000", "--timeout", "60"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("petrel send starts");
    // Reloads back and forth while the events flow.
    let mut accepted = 0;
    for k in 0..6 {
        let dir = if k % 2 == 0 { new.path() } else { old.path() };
        let o = reload(&player, dir, &[]);
        assert_eq!(o.status.code(), Some(0), "{}", text(&o));
        // How many events were in the queue at the swap (timing decides; shown, not asserted).
        for line in text(&o).lines().filter(|l| l.contains("handed over")) {
            eprintln!("reload {k}: {}", line.trim());
        }
        accepted += 1;
    }
    let o = sender.wait_with_output().expect("petrel send ends");
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        text(&o).contains("2000 taken and on record, 0 refused"),
        "{}",
        text(&o)
    );
    let s = player.wait_for(10.0, |s| s["stats"]["processed"] == 2000);
    let st = &s["stats"];
    assert_eq!(st["reloads"], accepted, "{s}");
    let n = |k: &str| st[k].as_u64().unwrap_or(u64::MAX);
    assert_eq!(n("received"), 2000, "{s}");
    assert_eq!(
        n("received"),
        n("processed") + n("unused") + n("refused") + n("queued"),
        "{s}"
    );
    assert_eq!(n("processed"), 2000, "{s}");
    assert!(player.stop().success());
}

/// A ground station that cannot read the version the vehicle reloaded (its files are not there:
/// here a mount namespace hides them from the shadow alone) raises its alarm, follows no more
/// and exits non-zero, while the vehicle flies on with the new version. Needs root for the
/// mount namespace; says so and passes elsewhere.
#[test]
fn a_shadow_that_cannot_read_the_reloaded_version_raises_its_alarm() {
    let can_unshare = Command::new("unshare")
        .args(["-m", "true"])
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if !can_unshare {
        eprintln!(
            "skipped: `unshare -m` needs root (a mount namespace hides files from the shadow)"
        );
        return;
    }
    let work = Workdir::new();
    let (player, programs) = in_transit(&work);
    let new = uav_with_birds("");
    let shadow_log = work.path().join("shadow.log");
    // The shadow's own mount namespace has an empty tmpfs where the new version is.
    let shadow = Command::new("unshare")
        .args(["-m", "--", "sh", "-c"])
        .arg("mount -t tmpfs -o size=64k petrel-hidden \"$1\" && shift && exec \"$@\"")
        .arg("sh")
        .arg(new.path())
        .arg(petrel_tests::petrel_bin())
        .arg("play")
        .arg(repo().join("missions/uav"))
        .args(["--vehicle", &player.vehicle, "--shadow", "--run-for", "300"])
        .env("RUST_LOG", "info")
        .stderr(std::fs::File::create(&shadow_log).unwrap())
        .spawn()
        .expect("the shadow starts");
    let shadow = Processes(vec![shadow]);
    let wait_log = |needle: &str| {
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(20);
        loop {
            let log = std::fs::read_to_string(&shadow_log).unwrap_or_default();
            if log.contains(needle) {
                return log;
            }
            assert!(
                std::time::Instant::now() < deadline,
                "the shadow never said `{needle}`:\n{log}"
            );
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
    };
    wait_log("shadow synchronised");

    let o = reload(&player, new.path(), &[]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let log = wait_log("the shadow cannot follow");
    assert!(log.contains("ALARM the vehicle reloaded version "), "{log}");
    // The vehicle is not held back by its ground station: it flies the new version.
    let o = send_to(&player, new.path(), "bird_strike");
    assert!(o.status.success(), "{}", text(&o));
    let s = player.wait_for(10.0, |s| marked(s, "BIRDS", "struck"));
    assert!(marked(&s, "BIRDS", "struck"), "{s}");

    let code = shadow.stop()[0];
    let log = std::fs::read_to_string(&shadow_log).unwrap_or_default();
    assert_ne!(
        code,
        Some(0),
        "an alarm is a failure of the double check:\n{log}"
    );
    assert!(
        log.contains("0 reloads followed, 1 divergence alarm"),
        "{log}"
    );
    drop(programs);
    assert!(player.stop().success());
}
