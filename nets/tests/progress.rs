//! What `petrel verify` adds to safety and dead markings (issue 13): progress (E0605), stuck
//! nets and resource cycles (E0606), starvation (W0606), the environment model (programs'
//! declared answers, internal events, one net alone), minimal traces and grouped reports. Each
//! on a small project written for it, and issue 13's three bugs rebuilt under
//! `tests/data/progress/`.

use petrel_nets::compiled::CompiledProject;
use petrel_nets::project::{from_sources, load_and_check, LoadedProject};
use petrel_nets::verify::{self, verify, Report, VerifyOptions};
use std::path::{Path, PathBuf};

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/progress")
        .join(name)
}

fn load(dir: &Path) -> (LoadedProject, CompiledProject) {
    let (loaded, c, d) = load_and_check(dir).expect("reads");
    assert!(!d.has_errors(), "{}", d.render_human(&loaded.sources));
    (loaded, c.expect("compiles"))
}

fn verified(dir: &Path) -> (LoadedProject, Report) {
    let (loaded, c) = load(dir);
    let r = verify(&c, VerifyOptions::default()).expect("verifies");
    (loaded, r)
}

fn inline(manifest: &str, nets: &str) -> CompiledProject {
    let (_, c, d, _) = from_sources(manifest, &[("a.pn", nets)]);
    assert!(!d.has_errors(), "{d:?}");
    c.expect("compiles")
}

/// The diagnostics of `r` as JSON: code, file, line, column, message of each.
fn located(loaded: &LoadedProject, d: &petrel_nets::diag::Diagnostics) -> Vec<serde_json::Value> {
    d.to_json(&loaded.sources)["diagnostics"]
        .as_array()
        .cloned()
        .unwrap_or_default()
}

fn find<'a>(list: &'a [serde_json::Value], code: &str) -> Vec<&'a serde_json::Value> {
    list.iter().filter(|d| d["code"] == code).collect()
}

// --- Issue 13, bug (a): a mission stuck behind a catastrophic event. ---

#[test]
fn a_mission_stuck_in_its_first_transit_behind_a_catastrophic_leak_cannot_finish() {
    let (loaded, r) = verified(&data("stuck_transit"));
    // What used to make it look clean: every dead marking follows the catastrophic leak.
    assert!(r.safe && !r.deadlock, "{r:#?}");
    assert!(r.dead_markings.iter().all(|d| d.after_catastrophic));
    // Progress: no end without the catastrophic event, from the start on.
    let f = r.no_progress.as_ref().expect("E0605");
    assert_eq!(f.excluded, ["catastrophic"]);
    assert_eq!(f.trace, Vec::<String>::new(), "already at start");
    assert_eq!(f.stays_in, ["MISSION{transit1}", "SAFETY{watching}"]);
    assert_eq!(f.stays_in_trace, ["start_mission", "depth_reached"]);
    assert!(!r.is_clean());
    // MISSION itself is stuck there.
    let stuck: Vec<&str> = r.stuck_nets.iter().map(|s| s.net.as_str()).collect();
    assert_eq!(stuck, ["MISSION"]);
    assert_eq!(
        r.stuck_nets[0].marking,
        ["MISSION{transit1}", "SAFETY{watching}"]
    );
    // E0605 points at the place the mission stays in, in mission.pn.
    let d = located(&loaded, &verify::diagnostics(&loaded.project, &r));
    let e = find(&d, "E0605");
    assert_eq!(e.len(), 1);
    assert!(
        e[0]["file"].as_str().unwrap().ends_with("mission.pn"),
        "{}",
        e[0]
    );
    assert_eq!(
        (e[0]["line"].as_u64(), e[0]["column"].as_u64()),
        (Some(5), Some(11))
    );
    assert_eq!(e[0]["severity"], "error");
    let e = find(&d, "E0606");
    assert_eq!(
        (e[0]["line"].as_u64(), e[0]["column"].as_u64()),
        (Some(2), Some(5))
    );
}

#[test]
fn counting_the_catastrophic_events_the_leak_is_an_end_again() {
    let dir = data("stuck_transit");
    let manifest = std::fs::read_to_string(dir.join("petrel.toml")).unwrap();
    let manifest = manifest.replace("[verify]\n", "[verify]\nprogress_excludes = []\n");
    let nets = |f: &str| std::fs::read_to_string(dir.join(f)).unwrap();
    let (_, c, d, _) = from_sources(
        &manifest,
        &[
            ("mission.pn", &nets("mission.pn")),
            ("safety.pn", &nets("safety.pn")),
        ],
    );
    assert!(!d.has_errors(), "{d:?}");
    let r = verify(&c.unwrap(), VerifyOptions::default()).unwrap();
    assert!(r.no_progress.is_none(), "{:?}", r.no_progress);
    assert!(r.progress_excludes.is_empty());
    // The net is still stuck: stuck nets do not depend on the categories.
    assert_eq!(r.stuck_nets.len(), 1);
}

// --- Issue 13, bug (b): a mutex leaked by a failure. ---

#[test]
fn a_mutex_leaked_by_a_shock_leaves_both_robots_waiting_for_it() {
    let (loaded, r) = verified(&data("leaked_mutex"));
    let f = r.no_progress.as_ref().expect("E0605");
    assert_eq!(f.marking, ["R1{waiting}", "R2{waiting}"]);
    assert_eq!(
        f.trace,
        ["start_mission", "granted(\"r1\")", "shock(\"r1\")"]
    );
    let stuck: Vec<&str> = r.stuck_nets.iter().map(|s| s.net.as_str()).collect();
    assert_eq!(stuck, ["R1", "R2"]);
    for s in &r.stuck_nets {
        assert_eq!(s.waits_for, ["global.mutex"]);
        // Nobody holds it: it was taken and never given back, no cycle.
        assert_eq!(s.resource_cycle, None);
    }
    // The help says what happened to the place.
    let d = verify::diagnostics(&loaded.project, &r);
    let e = d.iter().find(|d| d.code == "E0606").unwrap();
    assert!(
        e.help
            .as_deref()
            .unwrap()
            .contains("global.mutex, which nothing gives back"),
        "{:?}",
        e.help
    );
}

#[test]
fn events_that_do_not_matter_to_a_dead_marking_are_elided() {
    let (_, r) = verified(&data("leaked_mutex"));
    let dead: Vec<_> = r.dead_markings.iter().filter(|d| !d.intended).collect();
    assert_eq!(dead.len(), 3);
    // R1 went through and is done (its end): its events do not matter to R2 waiting forever.
    let d = dead
        .iter()
        .find(|d| d.marking == ["R1{done}", "R2{waiting}"])
        .expect("R2 starved after R1 went through");
    assert_eq!(
        d.trace,
        ["start_mission", "...", "granted(\"r2\")", "shock(\"r2\")"]
    );
    // The shortest trace of the first one is minimal already.
    assert_eq!(
        dead[0].trace,
        ["start_mission", "granted(\"r1\")", "shock(\"r1\")"]
    );
}

// --- Issue 13, bug (c): a lock-order deadlock beside an always-enabled net. ---

#[test]
fn a_lock_order_deadlock_beside_an_always_enabled_net_is_two_stuck_nets_and_their_cycle() {
    let (loaded, r) = verified(&data("lock_order"));
    // ALARMS can always acknowledge: no dead marking, which is how the deadlock used to hide.
    assert!(r.dead_markings.is_empty() && !r.deadlock);
    let stuck: Vec<&str> = r.stuck_nets.iter().map(|s| s.net.as_str()).collect();
    assert_eq!(stuck, ["A", "B"]);
    let a = &r.stuck_nets[0];
    assert_eq!(a.marking, ["A{has_x}", "B{has_y}", "ALARMS{ready}"]);
    assert_eq!(a.trace, ["go_a", "go_b"]);
    assert_eq!(
        a.resource_cycle.as_deref(),
        Some(
            &[
                "A waits for global.y, which B holds".to_string(),
                "B waits for global.x, which A holds".to_string(),
            ][..]
        )
    );
    assert_eq!(a.places, ["A.has_x"]);
    let d = located(&loaded, &verify::diagnostics(&loaded.project, &r));
    let e = find(&d, "E0606");
    assert_eq!(e.len(), 2);
    assert!(e[0]["message"]
        .as_str()
        .unwrap()
        .contains("a resource cycle"));
    assert_eq!(e[0]["line"].as_u64(), Some(1), "at `net A`");
    assert_eq!(e[1]["line"].as_u64(), Some(11), "at `net B`");
    assert!(!r.is_clean());
}

// --- Starvation. ---

#[test]
fn a_net_the_environment_can_keep_waiting_for_a_place_others_take_is_starved() {
    let (loaded, r) = verified(&data("starvation"));
    assert_eq!(r.starvation.len(), 1, "{:#?}", r.starvation);
    let s = &r.starvation[0];
    assert_eq!(s.net, "R2");
    assert_eq!(s.transition, "R2.enter");
    assert_eq!(s.resource, "global.free");
    assert_eq!(s.loop_events, ["give", "take"]);
    // A warning: the goal stays reachable, the verification passes.
    assert!(r.no_progress.is_none());
    assert!(r.is_clean() && r.errors() == 0 && r.warnings() == 1);
    let d = located(&loaded, &verify::diagnostics(&loaded.project, &r));
    let w = find(&d, "W0606");
    assert_eq!(w[0]["severity"], "warning");
    assert_eq!(
        (w[0]["line"].as_u64(), w[0]["column"].as_u64()),
        (Some(14), Some(16))
    );
}

#[test]
fn an_arbiter_reading_a_place_waits_for_nothing() {
    // SYNC grants with a read arc: it never takes the place, so no starvation, and the UGV
    // mission verifies clean.
    let (_, r) = verified(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../missions/ugv"));
    assert!(r.starvation.is_empty(), "{:#?}", r.starvation);
}

// --- Stuck nets and declared ends. ---

const SMALL: &str = r#"
[project]
name = "s"
files = ["a.pn"]
start = ["W", "B"]

[events]
go = { category = "nominal" }
tick = { category = "nominal" }
tock = { category = "nominal" }
"#;

const PARKING: &str = "net W {
    place a = 1
    place parked
    transition park on go: a -> parked
}
net B {
    place b0 = 1
    place b1
    transition t on tick: b0 -> b1
    transition u on tock: b1 -> b0
}";

#[test]
fn a_net_that_can_never_fire_again_is_stuck_unless_that_is_its_declared_end() {
    let r = verify(&inline(SMALL, PARKING), VerifyOptions::default()).unwrap();
    // B keeps the mission alive: no dead marking, and no end declared to make progress to.
    assert!(r.dead_markings.is_empty() && r.no_progress.is_none() && !r.declares_ends);
    assert_eq!(r.stuck_nets.len(), 1);
    assert_eq!(r.stuck_nets[0].net, "W");
    assert_eq!(r.stuck_nets[0].trace, ["go"]);
    assert!(r.stuck_nets[0].waits_for.is_empty());

    let manifest = format!("{SMALL}\n[verify]\nfinal = [[\"W.parked\"]]\n");
    let r = verify(&inline(&manifest, PARKING), VerifyOptions::default()).unwrap();
    assert!(r.stuck_nets.is_empty(), "{:#?}", r.stuck_nets);
    assert!(r.is_clean());
}

#[test]
fn a_goal_unreachable_from_some_state_is_an_error_even_when_no_state_is_dead() {
    // The goal `W.parked` cannot be reached once W went the other way; B keeps moving.
    let nets = "net W {
        place a = 1
        place parked
        place lost
        transition park on go: a -> parked
        transition stray on tock: a -> lost
        transition back on tick: lost -> lost
    }
    net B {
        place b0 = 1
        place b1
        transition t on tick: b0 -> b1
        transition u on tock: b1 -> b0
    }";
    let manifest = format!("{SMALL}\n[verify]\ngoal = [[\"W.parked\"]]\n");
    let r = verify(&inline(&manifest, nets), VerifyOptions::default()).unwrap();
    assert!(r.dead_markings.is_empty());
    let f = r.no_progress.as_ref().expect("E0605");
    assert_eq!(f.trace, ["tock"]);
    assert!(
        f.marking.contains(&"W{lost}".to_string()),
        "{:?}",
        f.marking
    );
    assert!(r.declares_ends);
}

// --- The environment model. ---

const PROTOCOL: &str = r#"
[project]
name = "p"
files = ["a.pn"]
start = ["A"]

[events]
plan = { category = "nominal" }
trajectory_ready = { category = "nominal" }

[programs.PLANNER.functions]
"#;

const PLANNING: &str = "net A {
    place idle = 1
    place asking
    place flying
    place confused
    transition ask on plan: idle -> asking {
        call PLANNER.plan_trajectory()
    }
    transition ready on trajectory_ready: asking -> flying
    transition early on trajectory_ready: idle -> confused
}";

#[test]
fn an_answer_a_function_declares_comes_only_after_a_call_to_it() {
    let free = format!("{PROTOCOL}plan_trajectory = []\n[verify]\nfinal = [[\"A.flying\"]]\n");
    let r = verify(&inline(&free, PLANNING), VerifyOptions::default()).unwrap();
    // Without the declaration the answer may come before the question.
    assert!(!r.never_fired.contains(&"A.early".to_string()));
    assert!(r.protocols.is_empty());

    let declared = format!(
        "{PROTOCOL}plan_trajectory = {{ params = [], answers = [\"trajectory_ready\"] }}\n[verify]\nfinal = [[\"A.flying\"]]\n"
    );
    let r = verify(&inline(&declared, PLANNING), VerifyOptions::default()).unwrap();
    assert_eq!(r.never_fired, ["A.early"]);
    assert_eq!(r.protocols, ["PLANNER.plan_trajectory"]);
    let end = r.dead_markings.iter().find(|d| d.intended).expect("flying");
    assert_eq!(end.trace, ["plan", "trajectory_ready"]);
    assert!(r.is_clean(), "{r:#?}");
}

#[test]
fn an_answer_to_a_call_never_made_leaves_the_mission_stuck() {
    // `ask` forgot its call: with the answer declared, nothing answers, and the mission
    // cannot finish.
    let nets = PLANNING.replace("call PLANNER.plan_trajectory()", "");
    let declared = format!(
        "{PROTOCOL}plan_trajectory = {{ params = [], answers = [\"trajectory_ready\"] }}\n[verify]\nfinal = [[\"A.flying\"]]\n"
    );
    let r = verify(&inline(&declared, &nets), VerifyOptions::default()).unwrap();
    let f = r.no_progress.as_ref().expect("E0605");
    assert_eq!(f.stays_in, ["A{asking}"]);
    assert_eq!(f.stays_in_trace, ["plan"]);
    assert!(r.deadlock);
}

const INTERNAL: &str = r#"
[project]
name = "i"
files = ["a.pn"]
start = ["A", "B"]

[events]
go = { category = "nominal" }
ping = { category = "nominal" }
"#;

const PINGING: &str = "net A {
    place idle = 1
    place sent
    place wrong
    transition send on go: idle -> sent {
        emit ping
    }
    transition late on ping: idle -> wrong
}
net B {
    place waiting = 1
    place got
    transition got_it on ping: waiting -> got
}";

#[test]
fn an_internal_event_comes_only_after_a_net_emitted_it() {
    let r = verify(&inline(INTERNAL, PINGING), VerifyOptions::default()).unwrap();
    assert!(!r.never_fired.contains(&"A.late".to_string()));

    let manifest = INTERNAL.replace(
        "ping = { category = \"nominal\" }",
        "ping = { category = \"nominal\", internal = true }",
    );
    let r = verify(&inline(&manifest, PINGING), VerifyOptions::default()).unwrap();
    assert_eq!(r.never_fired, ["A.late"]);
    assert_eq!(r.protocols, ["ping"]);
    let end = &r.dead_markings[0];
    assert_eq!(end.marking, ["A{sent}", "B{got}"]);
    assert_eq!(end.trace, ["go", "ping"]);
}

#[test]
fn a_function_cannot_answer_with_an_internal_event() {
    let manifest = format!(
        "{}\n[programs.P.functions]\nf = {{ params = [], answers = [\"ping\"] }}\n",
        INTERNAL.replace(
            "ping = { category = \"nominal\" }",
            "ping = { category = \"nominal\", internal = true }",
        )
    );
    let (_, c, d, _) = from_sources(&manifest, &[("a.pn", PINGING)]);
    assert!(c.is_none());
    assert!(d.iter().any(|x| x.code == "E0419"), "{d:?}");
}

// --- A pending event nobody takes is dropped, in the verifier as in the player. ---

const DELEGATION: &str = r#"
[project]
name = "d"
files = ["a.pn"]
start = ["CTRL", "WORKER"]

[events]
go = { category = "nominal" }
finished = { category = "nominal" }
job = { category = "nominal", internal = true }
job_done = { category = "nominal", internal = true }

[verify]
final = [["CTRL.over"]]
"#;

/// CTRL hands a job to WORKER and waits for it to be done; WORKER takes jobs only once it
/// has finished what it was busy with. (`REPLY` is what the job's transition does.)
const WORKING: &str = "net CTRL {
    place ready = 1
    place waiting
    place over
    transition hand_over on go: ready -> waiting {
        emit job to WORKER
    }
    transition done on job_done: waiting -> over
}
net WORKER {
    place busy = 1
    place idle
    transition finish on finished: busy -> idle
    transition work on job: idle -> idle {
        REPLY
    }
}";

#[test]
fn an_emitted_event_no_transition_takes_is_dropped_and_the_mission_that_waited_on_it_is_stuck() {
    // `go` while WORKER is busy: the player takes `job` from its queue, finds no candidate and
    // drops it as unused (docs/semantics.md, step 5); CTRL then waits for `job_done` forever.
    // The verifier used to let `job` wait until WORKER was idle, and found nothing.
    let nets = WORKING.replace("REPLY", "emit job_done");
    let r = verify(&inline(DELEGATION, &nets), VerifyOptions::default()).unwrap();
    let f = r.no_progress.as_ref().expect("E0605");
    assert_eq!(f.stays_in, ["CTRL{waiting}", "WORKER{idle}"]);
    assert_eq!(
        f.stays_in_trace,
        ["go", "job to WORKER (unused)", "finished"]
    );
    let ctrl = r
        .stuck_nets
        .iter()
        .find(|s| s.net == "CTRL")
        .expect("CTRL stuck");
    assert_eq!(ctrl.trace, ["go", "job to WORKER (unused)"]);
    // Where it ends: a dead marking that is no declared end, reached once `job` is gone.
    let dead: Vec<&Vec<String>> = r
        .dead_markings
        .iter()
        .filter(|d| !d.intended)
        .map(|d| &d.marking)
        .collect();
    assert_eq!(
        dead,
        [&vec![
            "CTRL{waiting}".to_string(),
            "WORKER{idle}".to_string()
        ]]
    );
    assert!(r.deadlock && !r.is_clean());
    // Delivered later, the job is still taken: the verifier does not model the queue's order
    // (an over-approximation), it only no longer omits the drop.
    let end = r.dead_markings.iter().find(|d| d.intended).expect("over");
    assert_eq!(end.trace, ["go", "finished", "job to WORKER", "job_done"]);
}

#[test]
fn an_emitted_event_dropped_where_nothing_waits_on_it_is_harmless() {
    // The same delegation, but nobody waits for the job: dropping it changes nothing that
    // matters, and the project stays clean.
    let nets = WORKING
        .replace("REPLY", "")
        .replace("ready -> waiting", "ready -> over");
    let manifest = DELEGATION.replace(
        "job_done = { category = \"nominal\", internal = true }\n",
        "",
    );
    let nets = nets.replace("    transition done on job_done: waiting -> over\n", "");
    let r = verify(&inline(&manifest, &nets), VerifyOptions::default()).unwrap();
    assert!(r.is_clean(), "{r:#?}");
    assert!(r.no_progress.is_none() && r.stuck_nets.is_empty());
    // The drop is explored: the stable states are the start, `go` with the job pending
    // (WORKER busy or idle), `finished` alone, and CTRL over with the job gone (WORKER busy or
    // idle); "over, busy, job gone" is the drop, which the verifier used to leave out.
    assert_eq!(r.states, 6);
}

#[test]
fn one_net_alone_is_given_only_the_places_other_nets_change() {
    let ugv = Path::new(env!("CARGO_MANIFEST_DIR")).join("../missions/ugv");
    let (_, c) = load(&ugv);
    let alone = |net: &str| {
        verify(
            &c,
            VerifyOptions {
                only_net: Some(net.into()),
                ..Default::default()
            },
        )
        .unwrap()
    };
    // ROBOT uses no global place: the environment only finishes its children (MOVE, PASS).
    let r = alone("R1");
    assert_eq!(r.errors(), 0, "{}", verify::render_human("ugv", &r));
    assert!(r.never_fired.is_empty(), "{:?}", r.never_fired);
    let traces: Vec<&String> = r
        .dead_markings
        .iter()
        .flat_map(|d| &d.trace)
        .chain(r.stuck_nets.iter().flat_map(|s| &s.trace))
        .collect();
    assert!(
        !traces.iter().any(|t| t.contains("global.")),
        "no global place changes: {traces:?}"
    );
    // SYNC reads the bottleneck, which the passages take and give back: not stuck, not dead.
    let r = alone("SYNC");
    assert_eq!(r.errors(), 0, "{}", verify::render_human("ugv", &r));
    // A move finishing: the net's end, not a dead marking.
    let r = alone("R1/MOVE");
    assert!(r.is_clean());
    assert!(r.dead_markings.iter().all(|d| d.intended && d.net_done));
}

// --- Reports. ---

#[test]
fn many_findings_of_one_kind_are_grouped_with_a_count_and_all_lists_them() {
    let nets = "net A {
        place a = 1
        place d1
        place d2
        place d3
        place d4
        place d5
        transition t1 on e1: a -> d1
        transition t2 on e2: a -> d2
        transition t3 on e3: a -> d3
        transition t4 on e4: a -> d4
        transition t5 on e5: a -> d5
    }";
    let mut manifest =
        String::from("[project]\nname = \"g\"\nfiles = [\"a.pn\"]\nstart = [\"A\"]\n\n[events]\n");
    for k in 1..=5 {
        manifest.push_str(&format!("e{k} = {{ category = \"nominal\" }}\n"));
    }
    let (project, c, d, _) = from_sources(&manifest, &[("a.pn", nets)]);
    assert!(!d.has_errors());
    let r = verify(&c.unwrap(), VerifyOptions::default()).unwrap();
    assert_eq!(r.errors(), 5);
    let grouped = verify::diagnostics(&project, &r);
    let e: Vec<_> = grouped.iter().filter(|d| d.code == "E0602").collect();
    assert_eq!(e.len(), 1);
    assert!(
        e[0].message.starts_with("5 dead markings; the first"),
        "{}",
        e[0].message
    );
    assert!(e[0].span.is_some(), "at the dead marking's place");
    let all = verify::diagnostics_all(&project, &r);
    assert_eq!(all.iter().filter(|d| d.code == "E0602").count(), 5);

    let summary = verify::render_summary("g", &r, false);
    assert!(
        summary.contains("... and 2 more dead markings (--all lists them)"),
        "{summary}"
    );
    assert_eq!(summary.matches("error[E0602]").count(), 3, "{summary}");
    let summary = verify::render_summary("g", &r, true);
    assert_eq!(summary.matches("error[E0602]").count(), 5, "{summary}");
    assert!(
        summary.ends_with("result: 5 errors, 0 warnings\n"),
        "{summary}"
    );
}

#[test]
fn ends_after_a_catastrophic_event_are_one_line_unless_all_are_asked_for() {
    let (_, r) = verified(&data("stuck_transit"));
    let summary = verify::render_summary("stuck_transit", &r, false);
    assert!(
        summary.contains(
            "  3 end(s) after a catastrophic event (the mission is over there; --all lists them)"
        ),
        "{summary}"
    );
    let all = verify::render_summary("stuck_transit", &r, true);
    assert_eq!(
        all.matches("end after a catastrophic event:").count(),
        3,
        "{all}"
    );
}

#[test]
fn the_report_never_claims_a_place_holds_two_tokens() {
    // A firing that would put a second token is refused: the report says so, and says that
    // no marking holds two.
    let manifest = "[project]\nname = \"u\"\nfiles = [\"a.pn\"]\nstart = [\"A\"]\n\n[globals]\ng = 0\n\n[events]\ngo = { category = \"nominal\" }\nback = { category = \"nominal\" }\n";
    let nets = "net A {
        place a = 1
        place b
        transition t on go: a -> b, g
        transition u on back: b -> a
    }";
    let r = verify(&inline(manifest, nets), VerifyOptions::default()).unwrap();
    assert!(!r.safe);
    assert_eq!(r.max_tokens_in_place, 1);
    let text = verify::render_human("u", &r);
    assert!(text.contains("no place ever holds two tokens"), "{text}");
    assert!(!text.contains("tokens in a place: 2"), "{text}");
    // The refused firing changes nothing: it is no loop.
    assert!(
        r.event_loops.iter().all(|l| l.events != ["go"]),
        "{:?}",
        r.event_loops
    );
}

#[test]
fn every_mission_of_the_repository_verifies_without_error() {
    // Every directory of missions/, so a new mission is checked the day it lands.
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../missions");
    let mut missions: Vec<String> = std::fs::read_dir(&root)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|m| root.join(m).join("petrel.toml").is_file())
        .collect();
    missions.sort();
    assert!(missions.len() >= 4, "{missions:?}");
    for m in missions.iter().map(String::as_str) {
        let dir = root.join(m);
        let (_, r) = verified(&dir);
        assert_eq!(r.errors(), 0, "{m}: {}", verify::render_human(m, &r));
        assert!(r.declares_ends, "{m} declares its ends");
        assert!(r.starvation.is_empty(), "{m}: {:?}", r.starvation);
    }
}
