//! `petrel gen` as a user meets it: prototypes of the UAV's programs generated, built with
//! cargo (offline, on the repository's programs SDK), flown against a real `petrel play`, and
//! regenerated after the interface changed without losing the handlers written into them.
//!
//! The prototypes build into `target/prototypes` (shared by every run and every prototype, so
//! that the SDK and iceoryx2 are compiled once), not into the test's temporary directory.

use petrel_tests::{petrel, repo, unique_vehicle, Player, Processes, TempProject, Workdir};
use std::path::Path;
use std::process::{Command, Stdio};

fn uav() -> std::path::PathBuf {
    repo().join("missions/uav")
}

/// `cargo ARGS` on the prototype in `dir`, offline, in the shared target directory.
fn cargo(dir: &Path, args: &[&str]) -> std::process::Output {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    Command::new(cargo)
        .args(args)
        .arg("--offline")
        .arg("--manifest-path")
        .arg(dir.join("Cargo.toml"))
        .env("CARGO_TARGET_DIR", repo().join("target/prototypes"))
        .env("PETREL", petrel_tests::petrel_bin())
        .output()
        .expect("cargo runs")
}

fn gen(project: &Path, programs: &[&str], out: &Path, extra: &[&str]) -> std::process::Output {
    let mut args = vec!["gen".to_string(), project.display().to_string()];
    for p in programs {
        args.push("--program".into());
        args.push(p.to_string());
    }
    args.push("-o".into());
    args.push(out.display().to_string());
    args.extend(extra.iter().map(|s| s.to_string()));
    let refs: Vec<&str> = args.iter().map(String::as_str).collect();
    petrel(&refs)
}

fn ok(o: &std::process::Output, what: &str) {
    assert!(
        o.status.success(),
        "{what}: {}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
}

/// GUI and PLD as a user writes them into the prototype: each manoeuvre answered at once.
const GUI_HANDLERS: &str = r#"
use crate::interface::{Events, Handlers};
use petrel_programs::ProgramError;

#[derive(Debug, Default)]
pub struct GuiPld {
    pub payload: Option<String>,
}

impl Handlers for GuiPld {
    fn gui_roll(&mut self, out: &mut Events<'_>) -> Result<(), ProgramError> {
        out.rotation_speed()
    }
    fn gui_takeoff(&mut self, out: &mut Events<'_>) -> Result<(), ProgramError> {
        out.airborne()
    }
    fn gui_climb(&mut self, out: &mut Events<'_>, altitude: f64) -> Result<(), ProgramError> {
        assert!(altitude > 0.0);
        out.altitude_reached()
    }
    fn gui_transit(&mut self, out: &mut Events<'_>, position: &[f64]) -> Result<(), ProgramError> {
        assert_eq!(position.len(), 3);
        out.waypoint_reached()
    }
    fn gui_approach(&mut self, out: &mut Events<'_>) -> Result<(), ProgramError> {
        out.runway_aligned()
    }
    fn gui_land(&mut self, out: &mut Events<'_>) -> Result<(), ProgramError> {
        out.touchdown()
    }
    fn pld_use_payload(&mut self, _out: &mut Events<'_>, payload: &str) -> Result<(), ProgramError> {
        self.payload = Some(payload.to_string());
        Ok(())
    }
    fn pld_stop_payload(&mut self, _out: &mut Events<'_>) -> Result<(), ProgramError> {
        self.payload = None;
        Ok(())
    }
}
"#;

/// DEC: two waypoints, then no more.
const DEC_HANDLERS: &str = r#"
use crate::interface::{Events, Handlers};
use petrel_programs::ProgramError;

#[derive(Debug, Default)]
pub struct Dec {
    given: usize,
}

impl Handlers for Dec {
    fn next_waypoint(&mut self, out: &mut Events<'_>) -> Result<(), ProgramError> {
        self.given += 1;
        match self.given {
            1 => out.waypoint(&[48.71, 2.21, 300.0], "camera"),
            2 => out.waypoint(&[48.75, 2.30, 300.0], "lidar"),
            _ => out.no_more_waypoints(),
        }
    }
    fn replan_without(&mut self, out: &mut Events<'_>, _payload: &str) -> Result<(), ProgramError> {
        out.replanned()
    }
    fn nearest_site(&mut self, out: &mut Events<'_>) -> Result<(), ProgramError> {
        out.emergency_site(&[48.6, 2.1, 150.0])
    }
}
"#;

#[test]
fn generated_prototypes_of_the_uav_programs_build_and_fly_a_nominal_flight() {
    let work = Workdir::new();
    let gui = work.path().join("gui");
    let dec = work.path().join("dec");
    ok(
        &gen(&uav(), &["GUI", "PLD"], &gui, &[]),
        "petrel gen GUI PLD",
    );
    ok(&gen(&uav(), &["DEC"], &dec, &[]), "petrel gen DEC");
    for f in [
        "Cargo.toml",
        "README.md",
        "src/main.rs",
        "src/interface.rs",
        "src/handlers.rs",
        "tests/against_player.rs",
    ] {
        assert!(gui.join(f).is_file(), "{f} is generated");
    }
    let interface = std::fs::read_to_string(gui.join("src/interface.rs")).unwrap();
    // One typed handler per function, a typed helper per event.
    assert!(interface.contains("fn gui_climb(&mut self, out: &mut Events<'_>, altitude: f64)"));
    assert!(interface.contains("fn gui_transit(&mut self, out: &mut Events<'_>, position: &[f64])"));
    assert!(
        interface.contains("fn pld_use_payload(&mut self, out: &mut Events<'_>, payload: &str)")
    );
    assert!(interface.contains("pub fn waypoint(&mut self, position: &[f64], payload: &str)"));
    // Built-in and timer events are the player's: no helper for them.
    assert!(!interface.contains("pub fn call_failed("));
    assert!(!interface.contains("pub fn dec_timeout("));

    // The user writes the handlers; the prototypes build and fly.
    std::fs::write(gui.join("src/handlers.rs"), GUI_HANDLERS).unwrap();
    std::fs::write(dec.join("src/handlers.rs"), DEC_HANDLERS).unwrap();
    ok(&cargo(&gui, &["build"]), "cargo build (GUI, PLD)");
    ok(&cargo(&dec, &["build"]), "cargo build (DEC)");
    let bin = |name: &str| repo().join("target/prototypes/debug").join(name);

    let vehicle = unique_vehicle("genfly");
    let player = Player::start(&uav(), &vehicle);
    let programs = Processes(
        [bin("gui-pld-program"), bin("dec-program")]
            .iter()
            .map(|b| {
                Command::new(b)
                    .args(["--vehicle", &vehicle])
                    .stdout(Stdio::null())
                    .spawn()
                    .expect("the prototype starts")
            })
            .collect(),
    );
    let all_alive = player.wait_for(30.0, |s| {
        ["GUI", "PLD", "DEC"]
            .iter()
            .all(|p| s["programs"][p] == "alive")
    });
    assert_eq!(all_alive["programs"]["DEC"], "alive", "{all_alive}");
    let o = player.send("start_mission", 1);
    ok(&o, "petrel send start_mission");
    let s = player.wait_for(60.0, |s| s["marking"]["MISSION"][0] == "landed");
    assert_eq!(s["marking"]["MISSION"][0], "landed", "{s}");
    assert_eq!(s["stats"]["calls_failed"], 0, "{s}");
    assert_eq!(s["stats"]["bad_messages"], 0, "{s}");
    // Both programs leave cleanly on SIGTERM.
    assert_eq!(programs.stop(), vec![Some(0), Some(0)]);
    let _ = player.stop();

    // Regenerating on the same interface keeps the handlers the user wrote.
    ok(&gen(&uav(), &["GUI", "PLD"], &gui, &[]), "petrel gen again");
    assert_eq!(
        std::fs::read_to_string(gui.join("src/handlers.rs")).unwrap(),
        GUI_HANDLERS
    );
}

#[test]
fn an_unchanged_prototype_builds_and_its_test_runs_against_petrel_play() {
    let work = Workdir::new();
    let pld = work.path().join("pld");
    ok(&gen(&uav(), &["PLD"], &pld, &[]), "petrel gen PLD");
    ok(
        &cargo(&pld, &["test"]),
        "cargo test on the unchanged prototype",
    );
}

#[test]
fn regenerating_after_an_interface_change_keeps_or_refuses_clearly() {
    let work = Workdir::new();
    let gui = work.path().join("gui");
    ok(&gen(&uav(), &["GUI", "PLD"], &gui, &[]), "petrel gen");
    std::fs::write(gui.join("src/handlers.rs"), GUI_HANDLERS).unwrap();

    // A new function: the handlers stay, the interface has it (with its default handler).
    let added = TempProject::copy(&uav(), |name, text| {
        if name == "petrel.toml" {
            text.replace("land = []", "land = []\nhover = [\"seconds: float\"]")
        } else {
            text
        }
    });
    let o = gen(added.path(), &["GUI", "PLD"], &gui, &[]);
    ok(&o, "petrel gen with a new function");
    assert!(String::from_utf8_lossy(&o.stderr).contains("GUI.hover(seconds: float)"));
    assert_eq!(
        std::fs::read_to_string(gui.join("src/handlers.rs")).unwrap(),
        GUI_HANDLERS
    );
    let interface = std::fs::read_to_string(gui.join("src/interface.rs")).unwrap();
    assert!(interface.contains("fn gui_hover(&mut self, out: &mut Events<'_>, seconds: f64)"));

    // A function the user handles changed: refused, naming it, nothing touched.
    let changed = TempProject::copy(&uav(), |name, text| {
        if name == "petrel.toml" {
            text.replace(
                "climb = [\"altitude: float\"]",
                "climb = [\"altitude: int\"]",
            )
        } else {
            text
        }
    });
    let before = std::fs::read_to_string(gui.join("src/interface.rs")).unwrap();
    let o = gen(changed.path(), &["GUI", "PLD"], &gui, &[]);
    assert_eq!(
        o.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("`GUI.climb(altitude: float)` is now `GUI.climb(altitude: int)`"),
        "{err}"
    );
    assert!(err.contains("--force"), "{err}");
    assert_eq!(
        std::fs::read_to_string(gui.join("src/interface.rs")).unwrap(),
        before
    );
    assert_eq!(
        std::fs::read_to_string(gui.join("src/handlers.rs")).unwrap(),
        GUI_HANDLERS
    );

    // With --force: a fresh handlers file, the user's kept beside it.
    ok(
        &gen(changed.path(), &["GUI", "PLD"], &gui, &["--force"]),
        "petrel gen --force",
    );
    assert_eq!(
        std::fs::read_to_string(gui.join("src/handlers.rs.bak")).unwrap(),
        GUI_HANDLERS
    );
    let fresh = std::fs::read_to_string(gui.join("src/handlers.rs")).unwrap();
    assert!(
        fresh.contains("fn gui_climb(&mut self, out: &mut Events<'_>, altitude: i64)"),
        "{fresh}"
    );

    // Bad arguments are usage errors that say what is wrong.
    let o = gen(&uav(), &["NAV"], &work.path().join("nav"), &[]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr)
        .contains("no program `NAV`; its programs are: GUI, DEC, PLD"));
}

#[test]
fn every_program_of_every_mission_gets_a_prototype_that_compiles() {
    let work = Workdir::new();
    let mut done = Vec::new();
    let mut entries: Vec<_> = std::fs::read_dir(repo().join("missions"))
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.join("petrel.toml").is_file())
        .collect();
    entries.sort();
    for mission in entries {
        let o = petrel(&["check", &mission.display().to_string()]);
        if !o.status.success() {
            continue;
        }
        let manifest = std::fs::read_to_string(mission.join("petrel.toml")).unwrap();
        for line in manifest.lines() {
            let Some(program) = line
                .strip_prefix("[programs.")
                .and_then(|l| l.strip_suffix(']'))
                .filter(|p| !p.contains('.'))
            else {
                continue;
            };
            let name = mission.file_name().unwrap().to_string_lossy().to_string();
            let out = work.path().join(format!("{name}-{program}"));
            ok(
                &gen(&mission, &[program], &out, &[]),
                &format!("petrel gen {name} {program}"),
            );
            ok(
                &cargo(&out, &["check"]),
                &format!("cargo check {name} {program}"),
            );
            done.push(format!("{name}/{program}"));
        }
    }
    for must in ["uav/GUI", "uav/DEC", "uav/PLD"] {
        assert!(done.contains(&must.to_string()), "{done:?}");
    }
}
