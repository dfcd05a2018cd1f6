//! The player's acknowledgement between real processes: it stays within the heartbeat's size
//! whatever the number of senders or the size of the project, and `petrel send` reports the
//! player's verdict on each event. Each test uses its own vehicle.

use petrel_tests::{repo, unique_vehicle, Player, TempProject};

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

/// Regression (issue 10, item 1): every sender ever seen grew the status in the heartbeat until
/// the heartbeat no longer fitted its service (1,024 bytes) and was dropped unseen: after about
/// ten `petrel send`s, every send said its event "may be lost" and `petrel status` found no
/// player.
#[test]
fn forty_five_sends_are_each_acknowledged_and_status_still_answers() {
    let vehicle = unique_vehicle("acks");
    let player = Player::start(&liveness_dir(), &vehicle);
    for n in 0..45 {
        let o = player.send(&format!("tick({n})"), 1);
        assert!(o.status.success(), "send {n}: {}", text(&o));
        let out = String::from_utf8_lossy(&o.stdout);
        assert!(out.contains("1 taken"), "send {n}: {}", text(&o));
    }
    let s = player
        .status()
        .expect("the player still answers `petrel status`");
    assert_eq!(s["stats"]["messages"], 45, "{s}");
    assert_eq!(s["stats"]["processed"], 45, "{s}");
    assert_eq!(s["stats"]["heartbeats_refused"], 0, "{s}");
    assert!(player.stop().success());
}

/// Regression (issue 10, item 1): the status JSON carried the whole marking in a 1,024-byte
/// heartbeat, so a project with about forty marked places never heartbeated at all.
#[test]
fn a_project_with_seventy_marked_places_heartbeats() {
    let places: String = (0..70)
        .map(|i| format!("    place marked_place_number_{i:03} = 1\n"))
        .collect();
    let net = format!(
        "net BIG {{\n{places}    transition t on tick(n): marked_place_number_000 -> marked_place_number_000\n}}\n"
    );
    let manifest = "[project]\nname = \"big\"\nfiles = [\"big.pn\"]\nstart = [\"BIG\"]\n\n[events]\ntick = { category = \"nominal\", params = [\"n: int\"] }\n";
    let project = TempProject::new(&[("petrel.toml", manifest), ("big.pn", &net)]);
    let vehicle = unique_vehicle("big");
    let player = Player::start(project.path(), &vehicle);
    let s = player.status().expect("status answers");
    let marked = s["marking"]["BIG"].as_array().map(Vec::len);
    assert_eq!(marked, Some(70), "{s}");
    let o = player.send("tick(1)", 1);
    assert!(o.status.success(), "{}", text(&o));
    assert!(player.stop().success());
}

/// Regression (issue 10, item 8): `petrel send` said "delivered" for an event the player refused
/// (unknown to the player's project), and exited 0.
#[test]
fn send_reports_the_players_refusal_and_its_reason() {
    let vehicle = unique_vehicle("refuse");
    let player = Player::start(&liveness_dir(), &vehicle);
    // The operator's copy of the project declares an event the player's does not know.
    let operator = TempProject::copy(&liveness_dir(), |name, text| {
        if name == "petrel.toml" {
            text.replace(
                "ask = { category = \"nominal\" }",
                "ask = { category = \"nominal\" }\nabort_all = { category = \"nominal\" }",
            )
        } else {
            text
        }
    });
    let o = std::process::Command::new(petrel_tests::petrel_bin())
        .arg("send")
        .arg(operator.path())
        .arg("abort_all")
        .args(["--vehicle", &vehicle])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let all = text(&o);
    assert!(
        all.contains("refused by the player") && all.contains("unknown event `abort_all`"),
        "{all}"
    );
    // A good event still is taken, with exit 0.
    let o = player.send("tick(1)", 1);
    assert!(o.status.success(), "{}", text(&o));
    let s = player.status().unwrap();
    assert_eq!(s["stats"]["bad_messages"], 1, "{s}");
    assert!(player.stop().success());
}

/// Regression (issue 30, item 4): a built-in event sent by an operator was refused and
/// journaled by the player but never acknowledged, so `petrel send` waited its whole timeout
/// and called it unacknowledged. With `--timeout 1`, only an answer of the player within that
/// second gives "refused" and the reason.
#[test]
fn send_of_a_built_in_event_is_answered_refused_with_the_reason() {
    let vehicle = unique_vehicle("builtin");
    let player = Player::start(&liveness_dir(), &vehicle);
    let t0 = std::time::Instant::now();
    let o = player.send_with("program_lost(\"GUI\")", &["--timeout", "1"]);
    eprintln!(
        "petrel send answered in {:.2} s",
        t0.elapsed().as_secs_f64()
    );
    let all = text(&o);
    assert_eq!(o.status.code(), Some(1), "{all}");
    assert!(
        all.contains("1 refused") && all.contains("0 unacknowledged"),
        "{all}"
    );
    assert!(
        all.contains(
            "refused by the player: `program_lost` is a built-in event: only the player raises it"
        ),
        "{all}"
    );
    // Counted as received and refused: the counters balance.
    let s = player.wait_for(5.0, |s| s["stats"]["refused"] == 1);
    let stat = |k: &str| s["stats"][k].as_u64().unwrap();
    assert_eq!(
        stat("received"),
        stat("processed") + stat("unused") + stat("refused") + stat("queued"),
        "{s}"
    );
    assert!(player.stop().success());
}
