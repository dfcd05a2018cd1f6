//! `petrel monitor` on Redermor (22 nets), as an operator sees it in Chromium at 1600 x 1000:
//! one live flight (`petrel up missions/redermor`: the player, the data server with the
//! simulator, PLN, NAV, EVT) watched by two monitors, then its journal replayed. One flight
//! serves every check (about 75 s in all, most of it the flight):
//!
//! - live: a net opened by its address draws its labels at least 10 px high; the follow mode
//!   shows the net of the latest step; the map's track grows; an event the player refuses
//!   shows the player's reason within a second; screenshots of the overview, a net and the map
//!   go to target/monitor-shots/ (docs/img holds the ones taken once);
//! - replay: the same net by its address, readable; the log follows the slider; the map's
//!   track grows with the slider; the follow mode shows the net of the frame's step.

use petrel_tests::web::{browser_available, Browser, Monitor};
use petrel_tests::{forget_vehicle, petrel_bin, repo, unique_vehicle, TempProject};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The net the checks open: the mission's phases, a wide net with a global place.
const NET: &str = "MISSION/MISSION_PHASES";

/// `petrel up` of a copy of missions/redermor, killed (and its vehicle's files removed) if the
/// test ends before it.
struct Flight {
    child: Child,
    vehicle: String,
    project: TempProject,
}

impl Flight {
    fn start() -> Flight {
        let sim = repo().join("missions/redermor/sim");
        let project = TempProject::copy(&repo().join("missions/redermor"), |_, text| {
            text.replace("{project}/sim/", &format!("{}/", sim.display()))
        });
        let vehicle = unique_vehicle("monrdm");
        let child = Command::new(petrel_bin())
            .arg("up")
            .arg(project.path())
            .args(["--vehicle", &vehicle, "--logs"])
            .arg(project.path().join("logs"))
            .args(["--timeout", "300"])
            .env("RUST_LOG", "warn")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("petrel up runs");
        Flight {
            child,
            vehicle,
            project,
        }
    }

    fn logs(&self) -> PathBuf {
        self.project.path().join("logs")
    }

    /// Waits for the end of the mission (petrel up stops everything then).
    fn wait(&mut self) -> std::process::ExitStatus {
        self.child.wait().expect("petrel up ends")
    }
}

impl Drop for Flight {
    fn drop(&mut self) {
        if matches!(self.child.try_wait(), Ok(None)) {
            let _ = Command::new("kill")
                .args(["-TERM", &self.child.id().to_string()])
                .status();
            let _ = self.child.wait();
        }
        forget_vehicle(&self.vehicle);
    }
}

/// The same project with one more event, which the player's version does not declare: what a
/// monitor started on another version of the project (before a `petrel reload`) would send.
fn project_with_an_extra_event(dir: &Path) -> TempProject {
    TempProject::copy(dir, |name, text| {
        if name == "petrel.toml" {
            text.replace(
                "[events]\n",
                "[events]\nabort_inspection = { category = \"mission\", description = \"a later version's event\" }\n",
            )
        } else {
            text
        }
    })
}

/// The heights (px) of the labels of the drawing that are inside the canvas.
fn label_heights(b: &Browser) -> Vec<f64> {
    let v = b.eval(
        "const c = document.getElementById('canvas').getBoundingClientRect();
         return Array.from(document.querySelectorAll('#canvas svg text'))
           .filter(t => t.textContent.trim() !== '')
           .map(t => t.getBoundingClientRect())
           .filter(r => r.width > 0 && r.right > c.left && r.left < c.right && r.bottom > c.top && r.top < c.bottom)
           .map(r => r.height)",
    );
    v.as_array()
        .map(|a| a.iter().filter_map(Value::as_f64).collect())
        .unwrap_or_default()
}

/// Opens `url` and waits until the page shows net `net` (its view by address).
fn open_net(b: &Browser, url: &str, net: &str) {
    b.open(url);
    b.wait_ready();
    let shown = b.wait_for(
        30.0,
        "return document.body.dataset.view + ' ' + document.body.dataset.net",
        |v| v.as_str() == Some(&format!("net {net}")),
    );
    assert_eq!(shown, format!("net {net}"), "{url}");
}

/// Asserts that every label of the drawing on the canvas is at least 10 px high.
fn assert_readable(b: &Browser, what: &str) {
    let heights = label_heights(b);
    assert!(heights.len() >= 5, "{what}: {heights:?}");
    let least = heights.iter().copied().fold(f64::INFINITY, f64::min);
    assert!(
        least >= 10.0,
        "{what}: a label {least:.1} px high ({heights:?})"
    );
}

/// The points of the map's first track, once the map is drawn.
fn track_points(b: &Browser) -> u64 {
    b.eval(
        "const t = document.querySelector('#canvas svg [data-track=\"0\"]'); return t ? Number(t.dataset.points) : -1",
    )
    .as_i64()
    .unwrap_or(-1)
    .max(0) as u64
}

/// What the follow mode shows and what it should: the net shown, and the net of the latest
/// step's last transition (the newest row of the log, live; the current row, replay).
const FOLLOWED: &str = "const rows = Array.from(document.querySelectorAll('#log tbody tr'));
    const replay = !!document.body.dataset.time;
    let i = replay ? rows.findIndex(r => r.classList.contains('current')) : 0;
    let want = '';
    for (; i >= 0 && i < rows.length; i += replay ? -1 : 1) {
      const links = Array.from(rows[i].cells[4].querySelectorAll('a.net'));
      if (links.length) { want = links[links.length - 1].dataset.net; break; }
    }
    return [document.body.dataset.view + ' ' + document.body.dataset.net, 'net ' + want]";

fn shots() -> PathBuf {
    let dir = petrel_bin()
        .parent()
        .and_then(Path::parent)
        .expect("target/")
        .join("monitor-shots");
    std::fs::create_dir_all(&dir).expect("target/monitor-shots");
    dir
}

#[test]
fn redermor_live_then_replayed_in_a_1600_by_1000_window() {
    if !browser_available() {
        return;
    }
    let started = Instant::now();
    let mut flight = Flight::start();
    let dir = flight.project.path().display().to_string();
    let other = project_with_an_extra_event(flight.project.path());
    let other_dir = other.path().display().to_string();
    let monitor = Monitor::start(&[&dir, "--vehicle", &flight.vehicle]);
    let operator = Monitor::start(&[&other_dir, "--vehicle", &flight.vehicle, "--operator"]);
    // The mission under way: the planner answered, the vehicle transits.
    let deadline = Instant::now() + Duration::from_secs(60);
    while monitor.get("/api/marking").json()["step"].as_u64() < Some(8) {
        assert!(Instant::now() < deadline, "the mission did not start");
        std::thread::sleep(Duration::from_millis(100));
    }
    let b = Browser::start_sized(1600, 1000);

    // A net by its address: its own drawing, labels readable.
    open_net(&b, &monitor.url(&format!("/?net={NET}")), NET);
    assert_readable(&b, "live, net by address");
    // The global place it uses is a port in its frame, coloured with the marking.
    let ports = b.eval("return Array.from(document.querySelectorAll('#canvas g.place.port')).map(g => g.dataset.name)");
    assert!(
        ports
            .as_array()
            .is_some_and(|p| p.iter().any(|n| n == "global.thrusters_on")),
        "{ports}"
    );
    b.screenshot(&shots().join("redermor-net.png"));

    // The overview: every net, each with its state; then the follow mode.
    b.open(&monitor.url("/?view=overview&follow=1"));
    b.wait_ready();
    let states = b.eval(
        "return Array.from(document.querySelectorAll('#netlist li')).map(li => li.dataset.state)",
    );
    let states = states.as_array().cloned().unwrap_or_default();
    assert_eq!(states.len(), 22);
    assert!(
        states.iter().any(|s| s == "active") && states.iter().any(|s| s == "inactive"),
        "{states:?}"
    );
    let followed = b.wait_for(20.0, FOLLOWED, |v| v[0] == v[1] && v[1] != "net ");
    assert_eq!(
        followed[0], followed[1],
        "live: the follow mode shows the net of the latest step"
    );

    b.open(&monitor.url("/?view=overview"));
    b.wait_ready();
    b.screenshot(&shots().join("redermor-overview.png"));

    // The map: the vehicle's track grows as it flies.
    b.open(&monitor.url("/?view=map"));
    b.wait_ready();
    let first = b.wait_for(20.0, "return document.body.dataset.map || ''", |v| v != "");
    assert_ne!(first, "", "the map was not drawn");
    let before = track_points(&b);
    let grown = b.wait_for(
        20.0,
        "const t = document.querySelector('#canvas svg [data-track=\"0\"]'); return t ? Number(t.dataset.points) : 0",
        |v| v.as_u64() > Some(before + 10),
    );
    assert!(
        grown.as_u64() > Some(before + 10),
        "the track did not grow: {before} then {grown}"
    );
    b.screenshot(&shots().join("redermor-map.png"));

    // An event the player refuses: its reason on the page within a second, not a time-out.
    let token = operator.token.clone().expect("a token");
    b.open(&operator.url(&format!("/#token={token}")));
    b.wait_ready();
    b.eval("document.getElementById('sendtext').value = 'abort_inspection'; document.getElementById('sendform').requestSubmit(); return null");
    let verdict = b.wait_for(
        10.0,
        "const r = document.getElementById('sendresult'); return [r.dataset.verdict || '', r.textContent, Number(r.dataset.ms || -1)]",
        |v| v[0] == "refused" || v[0] == "error" || v[0] == "taken",
    );
    assert_eq!(verdict[0], "refused", "{verdict}");
    assert!(
        verdict[1]
            .as_str()
            .unwrap_or_default()
            .contains("unknown event `abort_inspection`"),
        "{verdict}"
    );
    let ms = verdict[2].as_f64().unwrap_or(f64::MAX);
    assert!(ms < 1000.0, "the verdict took {ms} ms");
    assert_eq!(
        b.eval("return window.petrelMonitor.blocked"),
        serde_json::json!([])
    );

    // The end of the mission, then its journal replayed (the bus recording beside it).
    let status = flight.wait();
    assert!(status.success(), "petrel up: {status}");
    drop((monitor, operator));
    let journal = flight.logs().join("journal");
    let replay = Monitor::start(&["--journal", &journal.display().to_string()]);
    let timeline = replay.get("/api/replay").json();
    let frames = timeline["frames"].as_array().cloned().unwrap_or_default();
    assert!(frames.len() > 30, "{} frames", frames.len());
    let time = |i: usize| frames[i]["time"].as_f64().unwrap_or(0.0);
    let (early, late) = (time(frames.len() / 4), time(frames.len() - 2));

    open_net(&b, &replay.url(&format!("/?net={NET}&t={late}")), NET);
    assert_readable(&b, "replay, net by address");

    // The log follows the slider: the current step's row is in the log's view, wherever the
    // slider goes.
    for t in [late, early, late] {
        b.eval(&format!(
            "const s = document.getElementById('slider'); s.value = {t}; s.dispatchEvent(new Event('input')); return null"
        ));
        let seen = b.eval(
            "const w = document.getElementById('logwrap').getBoundingClientRect();
             const r = document.querySelector('#log tr.current');
             if (!r) return 'no current row';
             const b = r.getBoundingClientRect();
             return b.top >= w.top - 1 && b.bottom <= w.bottom + 1 ? 'in view' : 'out of view: ' + b.top + '..' + b.bottom + ' in ' + w.top + '..' + w.bottom",
        );
        assert_eq!(seen, "in view", "at t = {t}");
    }

    // The follow mode in replay: the net of the frame's step.
    b.open(&replay.url(&format!("/?view=overview&follow=1&t={late}")));
    b.wait_ready();
    let followed = b.wait_for(10.0, FOLLOWED, |v| v[0] == v[1] && v[1] != "net ");
    assert_eq!(
        followed[0], followed[1],
        "replay: the follow mode shows the net of the step"
    );

    // The map in replay: the track as it was at the slider's time.
    let mut points = Vec::new();
    for t in [early, late] {
        b.open(&replay.url(&format!("/?view=map&t={t}")));
        b.wait_ready();
        b.wait_for(20.0, "return document.body.dataset.map || ''", |v| v != "");
        points.push(track_points(&b));
    }
    assert!(
        points[0] > 0 && points[1] > points[0],
        "track at {early} s and {late} s: {points:?}"
    );
    eprintln!(
        "Redermor live and replay in the browser: {:.0} s",
        started.elapsed().as_secs_f64()
    );
}
