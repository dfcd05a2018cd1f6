//! A zero-time cascade in a real player (docs/semantics.md, "Zero-time cascades"): a net that
//! emits its own event is stopped at the bound, `livelock` is raised and handled, `petrel status`
//! answers, the mission goes on, the counters balance, and the journal replays; the verifier
//! and `petrel run` say the same of the project.

use petrel_tests::{petrel, unique_vehicle, Player, TempProject};
use std::time::Instant;

const MANIFEST: &str = r#"
[project]
name = "loop"
files = ["nets.pn"]
start = ["MONITOR", "SAFE", "MISSION"]

[events]
start_mission = { category = "nominal", description = "operator: start" }
health_check = { category = "nominal", description = "meant to be a timer's event" }
waypoint = { category = "nominal", params = ["n: int"], description = "the mission goes on" }
"#;

/// `health_check`'s transition emits `health_check` again: a timer forgotten.
const NETS: &str = "
net MONITOR {
    place idle = 1
    place watching
    transition begin on start_mission: idle -> watching { emit health_check }
    transition check on health_check: watching -> watching { emit health_check }
}

net SAFE {
    place ok = 1
    place alarmed
    transition alarm on livelock(net, transition): ok -> alarmed
    transition again on livelock(net, transition): alarmed -> alarmed
}

net MISSION {
    place leg1 = 1
    place leg2
    transition next on waypoint(n): leg1 -> leg2
}
";

fn project() -> TempProject {
    TempProject::new(&[("petrel.toml", MANIFEST), ("nets.pn", NETS)])
}

fn text(o: &std::process::Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

#[test]
fn verify_and_check_name_the_loop_and_run_ends_at_the_bound() {
    let p = project();
    let dir = p.path().display().to_string();
    for command in ["verify", "check"] {
        let o = petrel(&[command, &dir]);
        assert_eq!(o.status.code(), Some(1), "{command}: {}", text(&o));
        let out = text(&o);
        assert!(out.contains("E0608"), "{command}: {out}");
        assert!(
            out.contains("health_check → health_check → ... (each turn fires MONITOR.check)"),
            "{command}: {out}"
        );
    }
    let script = p.path().join("loop.script");
    std::fs::write(
        &script,
        "0 start_mission\n5 waypoint(1)\nexpect MISSION.leg2\n",
    )
    .unwrap();
    let started = Instant::now();
    let o = petrel(&["run", &dir, "--script", &script.display().to_string()]);
    let took = started.elapsed();
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    let steps: Vec<serde_json::Value> = stdout
        .lines()
        .map(|l| serde_json::from_str(l).expect("a JSON line"))
        .collect();
    let stopped: Vec<&serde_json::Value> = steps
        .iter()
        .filter(|s| !s["cascade_stopped"].is_null())
        .collect();
    assert_eq!(stopped.len(), 1);
    assert_eq!(stopped[0]["cascade_stopped"]["steps"], 10_000);
    assert_eq!(stopped[0]["cascade_stopped"]["dropped"], 1);
    assert_eq!(stopped[0]["time"], 0.0);
    // start, start_mission, 10,000 health_checks, livelock, waypoint.
    assert_eq!(steps.len(), 10_004);
    let last = &steps[steps.len() - 1];
    assert_eq!(last["event"], "waypoint");
    assert_eq!(last["marking"]["SAFE"][0], "alarmed");
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(
        stderr.contains("warning: at 0.0 s, events produced at one instant did not settle: the cascade was stopped after 10000 steps, 1 produced event(s) dropped"),
        "{stderr}"
    );
    eprintln!("petrel run: {} steps in {took:?}", steps.len());
}

#[test]
fn the_live_player_stops_the_loop_raises_livelock_and_goes_on() {
    let p = project();
    let vehicle = unique_vehicle("cascade");
    let player = Player::start(p.path(), &vehicle);
    let sent = Instant::now();
    let o = player.send("start_mission", 1);
    assert!(o.status.success(), "{}", text(&o));
    // The player answers its status while the mission goes on: the safety net took livelock.
    let s = player.wait_for(20.0, |s| s["marking"]["SAFE"][0] == "alarmed");
    let took = sent.elapsed();
    assert_eq!(s["marking"]["SAFE"][0], "alarmed", "{s}");
    let st = &s["stats"];
    let n = |k: &str| st[k].as_u64().unwrap_or_else(|| panic!("{k} in {s}"));
    assert_eq!(
        n("received"),
        n("processed") + n("unused") + n("refused") + n("queued"),
        "{s}"
    );
    // The health_check still queued at the bound was dropped, counted as refused.
    assert_eq!(n("refused"), 1, "{s}");
    assert!(n("processed") >= 10_001, "{s}");
    // Then the mission goes on: an event from outside is processed as usual.
    let o = player.send("waypoint(1)", 1);
    assert!(o.status.success(), "{}", text(&o));
    let s = player.wait_for(5.0, |s| s["marking"]["MISSION"][0] == "leg2");
    assert_eq!(s["marking"]["MISSION"][0], "leg2", "{s}");
    let log = player.log_text();
    assert!(log.contains("cascade stopped"), "{log}");
    eprintln!("the player stopped the cascade and answered its status {took:?} after the send");
    let journal = player.journal.clone();
    let _work = player.work.clone();
    assert!(player.stop().success());
    // The journal replays: the stop is the engine's, step for step.
    let o = petrel(&["replay", &journal.display().to_string()]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("every recorded marking reproduced"),
        "{}",
        text(&o)
    );
}
