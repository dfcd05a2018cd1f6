//! `petrel monitor` as a user sees it: real `petrel play`, `petrel send` and `petrel monitor`
//! processes, and a real headless Chromium reading the page's DOM after its JavaScript ran.
//! Each test uses its own vehicle; every process and file goes with the test.

use petrel_tests::web::{browser_available, http, status_places, strings, Browser, Monitor};
use petrel_tests::{petrel, repo, unique_vehicle, Player};
use serde_json::Value;

fn uav() -> std::path::PathBuf {
    repo().join("missions/uav")
}

fn sorted(mut v: Vec<String>) -> Vec<String> {
    v.sort();
    v
}

/// Sends `event` with `petrel send` and checks that the player took it.
fn send(player: &Player, event: &str) {
    let o = player.send(event, 1);
    assert!(
        o.status.success(),
        "petrel send {event}: {}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
}

/// Waits until the page shows exactly `want` marked; returns what it shows.
fn wait_marked(b: &Browser, want: &[&str]) -> Vec<String> {
    let want = sorted(want.iter().map(|s| s.to_string()).collect());
    let js = "return Array.from(document.querySelectorAll('g.node.place.marked')).map(n => n.dataset.name).sort()";
    strings(&b.wait_for(30.0, js, |v| strings(v) == want))
}

#[test]
fn the_page_shows_the_marking_change_as_events_are_sent() {
    if !browser_available() {
        return;
    }
    let vehicle = unique_vehicle("monlive");
    let player = Player::start(&uav(), &vehicle);
    let dir = uav().display().to_string();
    let monitor = Monitor::start(&[&dir, "--vehicle", &vehicle]);
    let b = Browser::start();
    b.open(&monitor.url("/"));
    b.wait_ready();
    let start = ["EVENTS.watching", "MISSION.ready", "global.on_ground"];
    assert_eq!(wait_marked(&b, &start), start);
    // Every net of the project is drawn, active ones not greyed.
    let clusters = b.eval(
        "return Array.from(document.querySelectorAll('g.cluster')).map(g => g.dataset.net + (g.classList.contains('inactive') ? ':inactive' : ':active')).sort()",
    );
    assert_eq!(strings(&clusters), ["EVENTS:active", "MISSION:active"]);

    send(&player, "start_mission");
    assert_eq!(
        wait_marked(&b, &["EVENTS.watching", "MISSION.rolling"]),
        ["EVENTS.watching", "MISSION.rolling"]
    );
    send(&player, "rotation_speed");
    let flying = ["EVENTS.watching", "MISSION.taking_off", "global.in_flight"];
    assert_eq!(wait_marked(&b, &flying), flying);

    // The event log has both steps, with their category, transitions and calls.
    let log = b.eval(
        "return Array.from(document.querySelectorAll('#log tbody tr')).map(r => Array.from(r.cells).map(c => c.textContent).join('|'))",
    );
    let rows = strings(&log);
    assert!(
        rows.iter()
            .any(|r| r.contains("|start_mission|nominal|MISSION.roll|call GUI.roll()")),
        "{rows:?}"
    );
    assert!(
        rows.iter()
            .any(|r| r.contains("|rotation_speed|nominal|MISSION.takeoff|call GUI.takeoff()")),
        "{rows:?}"
    );
    // The programs panel says who is there: nobody but the player here.
    let programs = b.wait_for(
        30.0,
        "return Array.from(document.querySelectorAll('#programs tr')).map(r => r.textContent).sort()",
        |v| strings(v).len() == 3,
    );
    assert_eq!(strings(&programs), ["DECabsent", "GUIabsent", "PLDabsent"]);

    // The page agrees with `petrel status`.
    let status = player.status().expect("the player answers");
    assert_eq!(b.marked(), status_places(&status));
    // All of it under the page's Content Security Policy, which blocked nothing.
    assert_eq!(
        b.eval("return window.petrelMonitor.blocked"),
        serde_json::json!([])
    );
}

#[test]
fn a_monitor_opened_late_shows_the_marking_of_petrel_status() {
    if !browser_available() {
        return;
    }
    let vehicle = unique_vehicle("monlate");
    let player = Player::start(&uav(), &vehicle);
    let dir = uav().display().to_string();
    // A first monitor from the start, a second once the mission is under way.
    let early = Monitor::start(&[&dir, "--vehicle", &vehicle]);
    for e in [
        "start_mission",
        "rotation_speed",
        "airborne",
        "payload_failure(\"camera\")",
    ] {
        send(&player, e);
    }
    let late = Monitor::start(&[&dir, "--vehicle", &vehicle]);
    let status = player.status().expect("the player answers");
    let want = status_places(&status);
    assert!(want.contains(&"EVENTS.replanning".to_string()), "{status}");
    let want_refs: Vec<&str> = want.iter().map(String::as_str).collect();
    let b = Browser::start();
    for m in [&late, &early] {
        b.open(&m.url("/"));
        b.wait_ready();
        assert_eq!(wait_marked(&b, &want_refs), want, "monitor on {}", m.addr);
        // MISSION was deactivated by the payload's loss and activated again: both active.
        let inactive = b.eval(
            "return Array.from(document.querySelectorAll('g.cluster.inactive')).map(g => g.dataset.net)",
        );
        assert_eq!(strings(&inactive), Vec::<String>::new());
    }
    // Both monitors agree with the player on the step too.
    let s1 = late.get("/api/marking").json();
    let s2 = early.get("/api/marking").json();
    assert_eq!(s1["marked"], s2["marked"]);
    assert_eq!(strings(&s1["marked"]), want);
}

#[test]
fn replay_at_time_t_shows_the_journals_marking_at_t() {
    if !browser_available() {
        return;
    }
    let vehicle = unique_vehicle("monreplay");
    let player = Player::start(&uav(), &vehicle);
    for e in [
        "start_mission",
        "rotation_speed",
        "airborne",
        "engine_failure",
    ] {
        send(&player, e);
    }
    let journal = player.journal.clone();
    let _work = player.work.clone();
    assert!(player.stop().success());
    let (entries, _) = petrel_tests::journal_json(&journal);
    let steps: Vec<f64> = entries
        .iter()
        .filter(|e| e["kind"] == "step")
        .filter_map(|e| e["time"].as_f64())
        .collect();
    assert!(steps.len() >= 4, "{entries:?}");
    let journal_arg = journal.display().to_string();
    let monitor = Monitor::start(&["--journal", &journal_arg]);
    let b = Browser::start();
    // Between the second and third steps, and after the last.
    for t in [(steps[1] + steps[2]) / 2.0, steps[steps.len() - 1] + 1.0] {
        let t_text = format!("{t:.6}");
        let o = petrel(&["replay", &journal_arg, "--until", &t_text]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let want = replay_places(&String::from_utf8_lossy(&o.stdout));
        assert!(!want.is_empty());
        b.open(&monitor.url(&format!("/?t={t_text}")));
        b.wait_ready();
        let want_refs: Vec<&str> = want.iter().map(String::as_str).collect();
        assert_eq!(wait_marked(&b, &want_refs), want, "at t = {t_text}");
    }
    // Stepping back from the end shows the step before.
    let step = |b: &Browser| b.eval("return Number(document.body.dataset.step)").as_u64();
    let last = step(&b).expect("a step");
    b.eval("document.getElementById('prev').click(); return null");
    assert_eq!(step(&b), Some(last - 1));
    // A replay has no live stream and sends nothing.
    assert_eq!(monitor.get("/api/events").status, 404);
    let r = http(
        monitor.addr,
        "POST",
        "/api/send",
        &[],
        "{\"event\": \"touchdown\"}",
    )
    .unwrap();
    assert_eq!(r.status, 403, "{}", r.body);
}

/// The marking `petrel replay --until` prints (`state at t = ...: NET{a, b} global{c}`), as the
/// drawing's place ids, sorted.
fn replay_places(text: &str) -> Vec<String> {
    let line = text
        .lines()
        .find(|l| l.starts_with("state at t = "))
        .unwrap_or_default();
    let marking = line.split_once(": ").map(|x| x.1).unwrap_or_default();
    let mut out = Vec::new();
    for part in marking.split("} ") {
        let Some((net, places)) = part.trim_end_matches('}').split_once('{') else {
            continue;
        };
        for p in places.split(", ").filter(|p| !p.is_empty()) {
            out.push(format!("{net}.{p}"));
        }
    }
    out.sort();
    out
}

/// Headers, path, body, the status expected, and what the error must say.
type BadRequest<'a> = (&'a [(&'a str, &'a str)], &'a str, &'a str, u16, &'a str);

#[test]
fn operator_actions_need_operator_mode_and_its_token() {
    let vehicle = unique_vehicle("monop");
    let player = Player::start(&uav(), &vehicle);
    let dir = uav().display().to_string();
    let body = "{\"event\": \"start_mission\"}";

    // Read-only by default.
    let ro = Monitor::start(&[&dir, "--vehicle", &vehicle]);
    let r = http(ro.addr, "POST", "/api/send", &[], body).unwrap();
    assert_eq!(r.status, 403, "{}", r.body);
    assert!(r.json()["error"].as_str().unwrap().contains("--operator"));
    assert_eq!(ro.get("/api/model").json()["operator"], false);

    let op = Monitor::start(&[&dir, "--vehicle", &vehicle, "--operator"]);
    let token = op.token.clone().expect("the token is printed");
    assert_eq!(token.len(), 32);
    let cases: [BadRequest; 6] = [
        (&[], "/api/send", body, 403, "token"),
        (
            &[("X-Petrel-Token", "0123")],
            "/api/send",
            body,
            403,
            "wrong operator token",
        ),
        (
            &[("X-Petrel-Token", &token)],
            "/api/send",
            "not json",
            400,
            "not JSON",
        ),
        (
            &[("X-Petrel-Token", &token)],
            "/api/send",
            "{\"e\": 1}",
            400,
            "no `event`",
        ),
        (
            &[("X-Petrel-Token", &token)],
            "/api/send",
            "{\"event\": \"start_mision\"}",
            400,
            "start_mision",
        ),
        (
            &[("X-Petrel-Token", &token)],
            "/api/send",
            "{\"event\": \"payload_failure(3)\"}",
            400,
            "payload_failure",
        ),
    ];
    for (headers, path, body, status, says) in cases {
        let r = http(op.addr, "POST", path, headers, body).unwrap();
        assert_eq!(r.status, status, "{body}: {}", r.body);
        let msg = r.json()["error"].as_str().unwrap_or_default().to_string();
        assert!(msg.contains(says), "{body}: {msg}");
    }
    // Nothing was sent so far.
    assert_eq!(player.status().unwrap()["stats"]["received"], 0);
    // The token in the address is refused (a form of another site could send it, and it
    // stays in the browser's history): only the header carries it.
    let r = http(
        op.addr,
        "POST",
        &format!("/api/send?token={token}"),
        &[],
        body,
    )
    .unwrap();
    assert_eq!(r.status, 403, "{}", r.body);
    assert!(
        r.json()["error"]
            .as_str()
            .unwrap()
            .contains("header X-Petrel-Token"),
        "{}",
        r.body
    );
    assert_eq!(player.status().unwrap()["stats"]["received"], 0);
    let r = http(
        op.addr,
        "POST",
        "/api/send",
        &[("X-Petrel-Token", &token)],
        body,
    )
    .unwrap();
    assert_eq!(r.status, 200, "{}", r.body);
    assert_eq!(r.json()["verdict"], "taken and on record");
    let s = player.wait_for(10.0, |s| s["marking"]["MISSION"][0] == "rolling");
    assert_eq!(s["marking"]["MISSION"][0], "rolling", "{s}");
    // A built-in event: the player's refusal and its reason, not a time-out (issue 30).
    let r = http(
        op.addr,
        "POST",
        "/api/send",
        &[("X-Petrel-Token", &token)],
        "{\"event\": \"program_lost(\\\"GUI\\\")\"}",
    )
    .unwrap();
    assert_eq!(r.status, 502, "{}", r.body);
    let v = r.json();
    assert_eq!(
        (&v["taken"], &v["refused"]),
        (&false.into(), &true.into()),
        "{v}"
    );
    let verdict = v["verdict"].as_str().unwrap_or_default();
    assert!(
        verdict.starts_with("refused by the player: `program_lost` is a built-in event"),
        "{v}"
    );
    // Unknown routes and wrong modes are JSON errors too.
    let r = op.get("/no/such/page");
    assert_eq!(r.status, 404);
    assert_eq!(r.json()["error"], "no such page: /no/such/page");
    assert_eq!(op.get("/api/replay").status, 404);
    let r = http(op.addr, "GET", "/api/send", &[], "").unwrap();
    assert_eq!(r.status, 405);
    // The monitor is still there after all that.
    assert_eq!(op.get("/api/marking").json()["synced"], Value::Bool(true));
}

/// A project of `n` nets, each with a token that `tick` moves from `a` to `b` and `tock` back;
/// the first four also share the global place `shared`.
fn many_nets(n: usize) -> petrel_tests::TempProject {
    let mut nets = String::new();
    for i in 0..n {
        let (take, give) = if i < 4 {
            (", shared", ", shared")
        } else {
            ("", "")
        };
        nets.push_str(&format!(
            "net N{i} {{\n    place a = 1\n    place b\n    transition go on tick: a{take} -> b{give} {{}}\n    transition back on tock: b -> a {{}}\n}}\n\n"
        ));
    }
    let start: Vec<String> = (0..n).map(|i| format!("\"N{i}\"")).collect();
    let manifest = format!(
        "[project]\nname = \"many\"\nfiles = [\"nets.pn\"]\nstart = [{}]\n\n[globals]\nshared = 1\n\n[events]\ntick = {{ category = \"nominal\" }}\ntock = {{ category = \"nominal\" }}\n",
        start.join(", ")
    );
    petrel_tests::TempProject::new(&[("petrel.toml", &manifest), ("nets.pn", &nets)])
}

#[test]
fn forty_nets_stay_readable_select_zoom_and_search() {
    if !browser_available() {
        return;
    }
    let project = many_nets(40);
    let vehicle = unique_vehicle("monmany");
    let player = Player::start(project.path(), &vehicle);
    let dir = project.path().display().to_string();
    let monitor = Monitor::start(&[&dir, "--vehicle", &vehicle]);
    let b = Browser::start();
    // Every net in one drawing.
    b.open(&monitor.url("/?view=all"));
    b.wait_ready();
    let mut start: Vec<String> = (0..40).map(|i| format!("N{i}.a")).collect();
    start.push("global.shared".into());
    let start = sorted(start);
    let refs: Vec<&str> = start.iter().map(String::as_str).collect();
    assert_eq!(wait_marked(&b, &refs), start);
    let clusters = b.eval("return document.querySelectorAll('g.cluster').length");
    assert_eq!(clusters, 40);
    send(&player, "tick");
    let mut after: Vec<String> = (0..40).map(|i| format!("N{i}.b")).collect();
    after.push("global.shared".into());
    let after = sorted(after);
    let refs: Vec<&str> = after.iter().map(String::as_str).collect();
    assert_eq!(wait_marked(&b, &refs), after);
    // Zoomed in, then fitted again: the view's area shrinks and comes back.
    let area = |b: &Browser| {
        b.eval("const v = document.querySelector('#canvas svg').viewBox.baseVal; return v.width * v.height")
            .as_f64()
            .unwrap_or(0.0)
    };
    let full = area(&b);
    b.eval("document.getElementById('zoomin').click(); document.getElementById('zoomin').click(); return null");
    assert!(area(&b) < full * 0.5, "{} of {full}", area(&b));
    b.eval("document.getElementById('fit').click(); return null");
    assert!((area(&b) - full).abs() < full * 1e-6);

    // A net of the list opens its own view, with its places and the global place it uses.
    b.eval("document.querySelector('#netlist li[data-net=\"N17\"]').click(); return null");
    let shown = b.wait_for(
        10.0,
        "return document.body.dataset.view + ' ' + document.body.dataset.net",
        |v| v == "net N17",
    );
    assert_eq!(shown, "net N17");
    assert_eq!(
        b.eval("return document.getElementById('selected').textContent"),
        "net N17"
    );
    assert_eq!(wait_marked(&b, &["N17.b"]), ["N17.b"]);
    assert_eq!(b.eval("return location.search"), "?net=N17");
    b.eval("document.querySelector('#netlist li[data-net=\"N2\"]').click(); return null");
    assert_eq!(
        wait_marked(&b, &["N2.b", "global.shared"]),
        ["N2.b", "global.shared"]
    );
    // The overview: a box per net, each with its state and its count of marked places.
    b.open(&monitor.url("/?view=overview"));
    b.wait_ready();
    let boxes = b.wait_for(10.0, "return Array.from(document.querySelectorAll('#canvas g.node')).filter(g => g.dataset.state === 'active').length", |v| v == 40);
    assert_eq!(boxes, 40);
    // The search finds nets, places and transitions by name; a result opens its net.
    b.eval("const f = document.getElementById('search'); f.value = 'N3'; f.dispatchEvent(new Event('input')); return null");
    let nets = b.eval("return Array.from(document.querySelectorAll('#results li')).filter(li => li.querySelector('.kind').textContent === 'net').map(li => li.dataset.net)");
    assert_eq!(strings(&nets).len(), 11, "{nets}");
    b.eval("const f = document.getElementById('search'); f.value = 'N39.t.back'; f.dispatchEvent(new Event('input')); return null");
    b.eval("document.querySelector('#results li[data-net]').click(); return null");
    let found = b.wait_for(10.0, "const g = document.querySelector('#canvas g.node.found'); return document.body.dataset.net + ' ' + (g ? g.dataset.name : '')", |v| v == "N39 N39.t.back");
    assert_eq!(found, "N39 N39.t.back");
}

#[test]
fn every_place_of_every_mission_is_in_the_drawing() {
    let mut entries: Vec<_> = std::fs::read_dir(repo().join("missions"))
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.join("petrel.toml").is_file())
        .collect();
    entries.sort();
    for mission in entries {
        let dir = mission.display().to_string();
        if !petrel(&["check", &dir]).status.success() {
            continue;
        }
        // No player: the monitor serves the drawing and waits for one.
        let vehicle = unique_vehicle("mondraw");
        let monitor = Monitor::start(&[&dir, "--vehicle", &vehicle]);
        let model = monitor.get("/api/model").json();
        let svg = monitor.get("/api/nets.svg").body;
        let titles: std::collections::BTreeSet<String> = svg
            .split("<title>")
            .skip(1)
            .filter_map(|t| t.split_once("</title>").map(|x| x.0.replace("&#45;", "-")))
            .collect();
        let mut ids = strings(&model["globals"]);
        for net in model["nets"].as_array().unwrap() {
            ids.extend(strings(&net["places"]));
            assert!(
                titles.contains(&format!("cluster_{}", net["name"].as_str().unwrap())),
                "{dir}: net {} is not drawn",
                net["name"]
            );
        }
        assert!(!ids.is_empty(), "{dir}");
        for id in &ids {
            assert!(
                titles.contains(id),
                "{dir}: place {id} is not in the drawing"
            );
        }
        // Each net alone: its own places, and the global places it uses as ports.
        for net in model["nets"].as_array().unwrap() {
            let name = net["name"].as_str().unwrap();
            let r = monitor.get(&format!("/api/net.svg?name={}", name.replace('/', "%2F")));
            assert_eq!(r.status, 200, "{dir}: net {name}: {}", r.body);
            for id in strings(&net["places"])
                .iter()
                .chain(&strings(&net["globals"]))
            {
                assert!(
                    r.body.contains(&format!("<title>{id}</title>")),
                    "{dir}: {id} not in {name}'s view"
                );
            }
        }
        assert_eq!(monitor.get("/api/net.svg?name=NOPE").status, 404);
        // The map: drawn for the projects that have a map.toml, a clear 404 for the others.
        let map = monitor.get("/api/map.svg?w=800&h=600");
        if mission.join("map.toml").is_file() {
            assert_eq!(map.status, 200, "{dir}: {}", map.body);
            assert!(
                map.body.starts_with("<svg") && map.body.contains("Legend"),
                "{dir}"
            );
            assert_ne!(model["map"], Value::Null);
        } else {
            assert_eq!(map.status, 404, "{dir}");
            assert!(map.json()["error"]
                .as_str()
                .unwrap_or_default()
                .contains("map.toml"));
        }
        drop(monitor);
        petrel_tests::forget_vehicle(&vehicle);
    }
}

#[test]
fn the_can_data_server_panel_shows_its_bus_and_signals() {
    if !browser_available() {
        return;
    }
    let auv = repo().join("missions/auv");
    let vehicle = unique_vehicle("moncan");
    let player = Player::start(&auv, &vehicle);
    let work = petrel_tests::Workdir::new();
    let bridge = petrel_tests::Processes(vec![std::process::Command::new(
        petrel_tests::vehicle_bin("auv-bridge"),
    )
    .arg(&auv)
    .args(["--vehicle", &vehicle, "--bus", "memory", "--record"])
    .arg(work.path().join("bus.log"))
    .env("RUST_LOG", "error")
    .stdout(std::process::Stdio::null())
    .spawn()
    .expect("auv-bridge starts")]);
    let dir = auv.display().to_string();
    let monitor = Monitor::start(&[&dir, "--vehicle", &vehicle]);
    let b = Browser::start();
    b.open(&monitor.url("/"));
    b.wait_ready();
    let text = b.wait_for(
        30.0,
        "return document.getElementById('bridgebox').hidden ? '' : document.getElementById('bridge').textContent",
        |v| v.as_str().is_some_and(|t| t.contains("bus ")),
    );
    assert!(text.as_str().unwrap_or_default().contains("bus "), "{text}");
    let signals = b.wait_for(
        30.0,
        "return document.querySelectorAll('#signals tr').length",
        |v| v.as_u64() > Some(0),
    );
    assert!(signals.as_u64() > Some(0), "no signal shown");
    let can = b.wait_for(
        30.0,
        "const r = document.querySelector('#programs tr[data-program=CAN] td:last-child'); return r ? r.textContent : ''",
        |v| v == "alive",
    );
    assert_eq!(can, "alive");
    drop(b);
    drop(monitor);
    assert_eq!(bridge.stop(), vec![Some(0)]);
    drop(player);
}

#[test]
fn bad_arguments_are_clear_usage_errors() {
    let work = petrel_tests::Workdir::new();
    let missing = work.path().join("no-journal-here");
    let cases: [(Vec<String>, &str); 6] = [
        (vec!["monitor".into()], "give the project directory"),
        (
            vec![
                "monitor".into(),
                "--journal".into(),
                missing.display().to_string(),
            ],
            "cannot read",
        ),
        (
            vec![
                "monitor".into(),
                uav().display().to_string(),
                "--listen".into(),
                "192.0.2.1:80".into(),
            ],
            "cannot listen on 192.0.2.1:80",
        ),
        (
            vec!["monitor".into(), work.path().display().to_string()],
            "petrel.toml",
        ),
        // The token is never written into a log: with the standard output not a terminal
        // (here a pipe), --operator needs a file of its own.
        (
            vec![
                "monitor".into(),
                uav().display().to_string(),
                "--operator".into(),
            ],
            "give --token-file FILE",
        ),
        (
            vec![
                "monitor".into(),
                uav().display().to_string(),
                "--allow-origin".into(),
                "ground-station".into(),
            ],
            "--allow-origin ground-station: an origin starts with http://",
        ),
    ];
    for (args, says) in cases {
        let refs: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = petrel(&refs);
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(says), "{args:?}: {err}");
    }
}

#[test]
fn the_operator_sends_from_the_page_only_with_the_token() {
    if !browser_available() {
        return;
    }
    let vehicle = unique_vehicle("monform");
    let player = Player::start(&uav(), &vehicle);
    let dir = uav().display().to_string();
    let monitor = Monitor::start(&[&dir, "--vehicle", &vehicle, "--operator"]);
    let token = monitor.token.clone().expect("a token");
    let b = Browser::start();
    let submit = "document.getElementById('sendtext').value = 'start_mission'; document.getElementById('sendform').requestSubmit(); return null";
    let result = "return document.getElementById('sendresult').className + ': ' + document.getElementById('sendresult').textContent";
    // Without the token the form is there, and what it sends is refused, saying why.
    b.open(&monitor.url("/"));
    b.wait_ready();
    b.eval(submit);
    let r = b.wait_for(30.0, result, |v| {
        v.as_str().is_some_and(|s| s.starts_with("bad"))
    });
    assert!(
        r.as_str().unwrap_or_default().contains("operator token"),
        "{r}"
    );
    assert_eq!(player.status().unwrap()["stats"]["received"], 0);
    // With it (in the address's fragment, as the monitor shows it), the event goes and the
    // page shows the player's verdict and the new marking; the token is gone from the address.
    b.open(&monitor.url(&format!("/#token={token}")));
    b.wait_ready();
    let href = b.wait_for(10.0, "return location.href", |v| {
        v.as_str().is_some_and(|h| !h.contains("token"))
    });
    // (The page then says its view in the address: `/?view=all`.)
    let href = href.as_str().unwrap_or_default();
    assert!(
        href.starts_with(&monitor.url("/")) && !href.contains("token") && !href.contains('#'),
        "{href}"
    );
    b.eval(submit);
    let r = b.wait_for(30.0, result, |v| {
        v.as_str().is_some_and(|s| s.starts_with("ok"))
    });
    assert_eq!(r, "ok: start_mission: taken and on record");
    assert_eq!(
        wait_marked(&b, &["EVENTS.watching", "MISSION.rolling"]),
        ["EVENTS.watching", "MISSION.rolling"]
    );
    // A reload keeps the token for this tab, not in the address.
    b.open(&monitor.url("/"));
    b.wait_ready();
    assert_eq!(b.eval("return window.petrelMonitor.token"), token.as_str());
    // The page works under its Content Security Policy: nothing of it was blocked.
    assert_eq!(
        b.eval("return window.petrelMonitor.blocked"),
        serde_json::json!([])
    );
}

#[test]
fn a_damaged_journal_replays_up_to_the_damage_with_an_alarm() {
    let vehicle = unique_vehicle("mondamage");
    let player = Player::start(&uav(), &vehicle);
    for e in ["start_mission", "rotation_speed", "airborne"] {
        send(&player, e);
    }
    let journal = player.journal.clone();
    let _work = player.work.clone();
    assert!(player.stop().success());
    let segment = petrel_tests::journal_segments(&journal)
        .into_iter()
        .next()
        .expect("a segment");
    let mut bytes = std::fs::read(&segment).unwrap();
    let middle = bytes.len() / 2;
    bytes[middle] ^= 0xff;
    std::fs::write(&segment, bytes).unwrap();
    let journal_arg = journal.display().to_string();
    let monitor = Monitor::start(&[&dir_of_uav(), "--journal", &journal_arg]);
    let t = monitor.get("/api/replay").json();
    assert_eq!(t["corrupt"], true, "{t}");
    let alarms: Vec<String> = t["alarms"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|a| a["text"].as_str().map(String::from))
        .collect();
    assert!(alarms.iter().any(|a| a.contains("damaged")), "{alarms:?}");
    // The frames before the damage are there, from the start.
    let frames = t["frames"].as_array().unwrap();
    assert!(!frames.is_empty());
    assert_eq!(frames[0]["step"], 0);
}

fn dir_of_uav() -> String {
    uav().display().to_string()
}

/// The header's connection pill says what the page hears, as the vehicle comes and goes: a
/// monitor with no player says so (never a green "connected" on the monitor's stream alone),
/// a player's heartbeats make it "player alive", a player gone makes it "player silent", and a
/// monitor gone makes it "monitor unreachable". (Issue 35: the page showed a green
/// "connected" beside "waiting for the player's first heartbeat" once the UAV flight ended.)
#[test]
fn the_connection_pill_says_whether_a_player_is_heard() {
    if !browser_available() {
        return;
    }
    let vehicle = unique_vehicle("monconn");
    let dir = uav().display().to_string();
    let monitor = Monitor::start(&[&dir, "--vehicle", &vehicle]);
    let b = Browser::start();
    b.open(&monitor.url("/"));
    b.wait_ready();
    let pill = "const c = document.getElementById('conn'); return c.dataset.state + '|' + c.className + '|' + c.textContent";
    let wait_state = |state: &str| -> String {
        let v = b.wait_for(30.0, pill, |v| {
            v.as_str()
                .is_some_and(|s| s.starts_with(&format!("{state}|")))
        });
        let s = v.as_str().unwrap_or_default().to_string();
        assert!(
            s.starts_with(&format!("{state}|")),
            "waiting for {state}: {s}"
        );
        s
    };
    let none = wait_state("no-player");
    assert!(
        !none.contains(" ok") && !none.contains("connected"),
        "{none}"
    );
    assert!(none.ends_with("monitor up, no player heard"), "{none}");

    let player = Player::start(&uav(), &vehicle);
    let alive = wait_state("player-alive");
    assert!(alive.contains("pill ok"), "{alive}");

    // The player goes (killed: no farewell): three heartbeat periods later it is silent.
    drop(player);
    let silent = wait_state("player-silent");
    assert!(
        silent.contains("pill bad") && silent.ends_with("player silent (no heartbeat)"),
        "{silent}"
    );

    // The monitor goes: the page says it lost it, and retries.
    drop(monitor);
    let lost = wait_state("monitor-lost");
    assert!(
        lost.contains("pill bad") && lost.ends_with("monitor unreachable, retrying"),
        "{lost}"
    );
    petrel_tests::forget_vehicle(&vehicle);
}
