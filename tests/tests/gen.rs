//! `petrel gen` as a user meets it: prototypes of the UAV's programs generated, built with
//! cargo (offline, on the repository's programs SDK), flown against a real `petrel play`, and
//! regenerated after the interface changed without losing the handlers written into them.
//!
//! The prototypes build into `target/prototypes` (shared by every run and every prototype, so
//! that the SDK and iceoryx2 are compiled once), not into the test's temporary directory.

use petrel_nets::model::is_identifier;
use petrel_tests::{petrel, repo, unique_vehicle, Player, Processes, TempProject, Workdir};
use std::collections::BTreeSet;
use std::fmt::Write as _;
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

/// Two programs' handlers can meet once the program is in lower case (`A.b_c` and `A_B.c`
/// both give `a_b_c`): the second in order gets `a_b_c_`. A function declared later can take
/// the handler a user wrote for another; regenerating refuses it, naming both methods, rather
/// than let the user's code answer the wrong function.
#[test]
fn regenerating_refuses_a_handler_that_would_answer_another_function() {
    let manifest = |functions: &str| {
        format!(
            "[project]\nname = \"meet\"\nfiles = [\"n.pn\"]\nstart = [\"N\"]\n\n[verify]\nfinal = [[\"N.p\"]]\n\n[programs.A.functions]\n{functions}\n[programs.A_B.functions]\nc = []\n"
        )
    };
    let net = "net N {\n    place p = 1\n}\n";
    let before = TempProject::new(&[("petrel.toml", &manifest("")), ("n.pn", net)]);
    let after = TempProject::new(&[("petrel.toml", &manifest("b_c = []\n")), ("n.pn", net)]);
    let work = Workdir::new();
    let out = work.path().join("ab");
    ok(&gen(before.path(), &["A", "A_B"], &out, &[]), "petrel gen");
    let handlers = std::fs::read_to_string(out.join("src/handlers.rs")).unwrap();
    assert!(handlers.contains("fn a_b_c(&mut self"), "{handlers}");

    let o = gen(after.path(), &["A", "A_B"], &out, &[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("`A_B.c()` is now handled by `fn a_b_c_`, no longer by `fn a_b_c`"),
        "{err}"
    );
    ok(
        &gen(after.path(), &["A", "A_B"], &out, &["--force"]),
        "petrel gen --force",
    );
    let interface = std::fs::read_to_string(out.join("src/interface.rs")).unwrap();
    assert!(
        interface.contains(
            "//! - function A_B.c: handler `a_b_c_` (another name gives the same identifier)"
        ),
        "{interface}"
    );
    ok(&cargo(&out, &["check"]), "cargo check");
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

/// The identifiers a Rust source uses: every word outside comments and literals, and the
/// names format strings take inline (`{vehicle}`); lifetimes and numbers are not names.
fn identifiers(src: &str) -> BTreeSet<String> {
    let chars: Vec<char> = src.chars().collect();
    // The word at `i` (empty if none) and where it ends.
    let word = |i: usize| {
        let end = (i..chars.len())
            .find(|&j| !(chars[j].is_ascii_alphanumeric() || chars[j] == '_'))
            .unwrap_or(chars.len());
        (chars[i..end].iter().collect::<String>(), end)
    };
    let mut out = BTreeSet::new();
    let mut i = 0;
    while i < chars.len() {
        let c = chars[i];
        if c == '/' && chars.get(i + 1) == Some(&'/') {
            i = (i..chars.len())
                .find(|&j| chars[j] == '\n')
                .unwrap_or(chars.len());
        } else if c == '"' {
            i += 1;
            while i < chars.len() && chars[i] != '"' {
                // An escape, or `{{`: two characters that name nothing.
                let skip = chars[i] == '\\' || chars[i..].starts_with(&['{', '{']);
                if chars[i] == '{' && !skip {
                    let (w, _) = word(i + 1);
                    if w.starts_with(|c: char| c.is_ascii_alphabetic() || c == '_') {
                        out.insert(w);
                    }
                }
                i += if skip { 2 } else { 1 };
            }
            i += 1;
        } else if c == '\'' {
            // A lifetime (`'a`, `'_`) or a character (`'x'`).
            let end = word(i + 1).1.max(i + 1);
            i = if chars.get(end) == Some(&'\'') {
                end + 1
            } else {
                end
            };
        } else if c.is_ascii_alphanumeric() || c == '_' {
            let (w, end) = word(i);
            if !c.is_ascii_digit() {
                out.insert(w);
            }
            i = end;
        } else {
            i += 1;
        }
    }
    out
}

/// Rust's keywords (strict, reserved, weak, of every edition), primitive types and prelude
/// names (values, types, traits, derives, macros): written here apart from the generator's
/// own lists, which this test checks.
const RUST_NAMES: &[&str] = &[
    "as",
    "break",
    "const",
    "continue",
    "crate",
    "else",
    "enum",
    "extern",
    "false",
    "fn",
    "for",
    "if",
    "impl",
    "in",
    "let",
    "loop",
    "match",
    "mod",
    "move",
    "mut",
    "pub",
    "ref",
    "return",
    "self",
    "Self",
    "static",
    "struct",
    "super",
    "trait",
    "true",
    "type",
    "unsafe",
    "use",
    "where",
    "while",
    "async",
    "await",
    "dyn",
    "abstract",
    "become",
    "box",
    "do",
    "final",
    "macro",
    "override",
    "priv",
    "typeof",
    "unsized",
    "virtual",
    "yield",
    "try",
    "gen",
    "macro_rules",
    "union",
    "raw",
    "safe",
    "auto",
    "default",
    "bool",
    "char",
    "str",
    "i8",
    "i16",
    "i32",
    "i64",
    "i128",
    "isize",
    "u8",
    "u16",
    "u32",
    "u64",
    "u128",
    "usize",
    "f32",
    "f64",
    "Some",
    "None",
    "Ok",
    "Err",
    "drop",
    "Option",
    "Result",
    "Vec",
    "String",
    "Box",
    "ToString",
    "ToOwned",
    "Clone",
    "Copy",
    "Send",
    "Sync",
    "Sized",
    "Unpin",
    "Drop",
    "Fn",
    "FnMut",
    "FnOnce",
    "AsRef",
    "AsMut",
    "Into",
    "From",
    "TryFrom",
    "TryInto",
    "FromIterator",
    "Default",
    "Debug",
    "Hash",
    "Iterator",
    "IntoIterator",
    "Extend",
    "DoubleEndedIterator",
    "ExactSizeIterator",
    "Eq",
    "PartialEq",
    "Ord",
    "PartialOrd",
    "Future",
    "IntoFuture",
    "vec",
    "println",
    "format",
    "panic",
    "assert",
    "write",
    "into",
    "try_into",
    "to_owned",
    "to_string",
    "clone",
    "fmt",
];

/// Names that meet once renamed or converted, and the cases issue 30 found.
const MEETING_NAMES: &[&str] = &[
    "_", "__", "___", "_1", "out", "out_", "out__", "x_", "tick", "tick_", "emit", "emit_", "from",
    "send_as", "Foo", "foo", "FOO", "fOO", "type", "None", "Some", "EVENTS", "RESULT", "SELF",
];

/// `ProgramError`: `PROGRAM_ERROR`, the program name whose UpperCamelCase it is.
fn screaming(camel: &str) -> String {
    let mut s = String::new();
    for (i, c) in camel.chars().enumerate() {
        if i > 0 && c.is_ascii_uppercase() {
            s.push('_');
        }
        s.push(c.to_ascii_uppercase());
    }
    s
}

/// The corpus workspace, `target/prototypes/corpus`: one test run at a time has it (a lock
/// beside it), and its sources go when the run ends (the build's artifacts stay, as any
/// prototype's do).
struct Corpus {
    dir: std::path::PathBuf,
    _lock: std::fs::File,
}

impl Corpus {
    fn take() -> Corpus {
        let dir = repo().join("target/prototypes");
        std::fs::create_dir_all(&dir).unwrap();
        let lock = std::fs::File::create(dir.join("corpus.lock")).unwrap();
        lock.lock().expect("the corpus lock");
        let corpus = dir.join("corpus");
        let _ = std::fs::remove_dir_all(&corpus);
        std::fs::create_dir_all(&corpus).unwrap();
        Corpus {
            dir: corpus,
            _lock: lock,
        }
    }
}

impl Drop for Corpus {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// Issue 30, item 6: `petrel gen` wrote crates that did not compile for names `petrel check`
/// accepts (`type`, `None`, `_`, `out` beside `out_`, events `emit` `from` `send_as`, a
/// function `tick`, programs `EVENTS` `RESULT` `SELF`). The corpus: every identifier of the
/// generated files (harvested from a prototype, so that a name the templates start to use is
/// tried at once), Rust's keywords, primitive and prelude names, and names that meet once
/// converted; each as a parameter (of a function and of an event, all of them beside each
/// other too), a function, an event, and (when its UpperCamelCase is a type's) a program. The
/// prototypes are generated into one cargo workspace and built at once, in the shared
/// prototypes target directory, with no warning.
#[test]
fn every_interface_petrel_check_accepts_gets_a_prototype_that_builds() {
    let work = Workdir::new();
    let seed = work.path().join("seed");
    ok(
        &gen(&uav(), &["GUI", "PLD"], &seed, &[]),
        "petrel gen GUI PLD",
    );
    let mut own = BTreeSet::new();
    for f in [
        "src/interface.rs",
        "src/handlers.rs",
        "src/main.rs",
        "tests/against_player.rs",
    ] {
        own.extend(identifiers(&std::fs::read_to_string(seed.join(f)).unwrap()));
    }
    for expected in [
        "out", "tick", "emit", "PROGRAMS", "Handlers", "Events", "vehicle",
    ] {
        assert!(own.contains(expected), "{expected} not harvested: {own:?}");
    }
    let names: BTreeSet<String> = own
        .iter()
        .map(String::as_str)
        .chain(RUST_NAMES.iter().copied())
        .chain(MEETING_NAMES.iter().copied())
        .filter(|n| is_identifier(n))
        .map(String::from)
        .collect();
    // Programs: each name whose UpperCamelCase is a type's, alone in its prototype.
    let mut alone: BTreeSet<String> = names
        .iter()
        .filter(|n| n.starts_with(|c: char| c.is_ascii_uppercase()))
        .filter(|n| n.contains(|c: char| c.is_ascii_lowercase()))
        .map(|n| screaming(n))
        .collect();
    alone.extend(["EVENTS", "RESULT", "SELF", "_", "_1"].map(String::from));
    // Two programs' handlers meet (`gui_roll`, `a_b_c`) in one process.
    let together = ["GUI", "gui", "A_B", "A", "type", "_X"];

    let types = ["int", "float", "bool", "text", "[float]"];
    let param = |i: usize, n: &str| format!("\"{n}: {}\"", types[i % types.len()]);
    let all: Vec<String> = names.iter().enumerate().map(|(i, n)| param(i, n)).collect();
    let mut m = String::from("[project]\nname = \"hostile\"\ndescription = \"two\\nlines\"\nfiles = [\"n.pn\"]\nstart = [\"N\"]\n\n[verify]\nfinal = [[\"N.p\"]]\n\n[events]\n");
    m.push_str("done = { category = \"nominal\", description = \"one line,\\nand another\\r\" }\n");
    for (i, n) in names.iter().enumerate() {
        let _ = writeln!(
            m,
            "{n} = {{ category = \"nominal\", params = [{}] }}",
            param(i, n)
        );
    }
    let _ = writeln!(
        m,
        "every_param = {{ category = \"nominal\", params = [{}] }}",
        all.join(", ")
    );
    m.push_str("\n[programs.NAMES.functions]\n");
    for (i, n) in names.iter().enumerate() {
        let _ = writeln!(m, "{n} = [{}]", param(i, n));
    }
    let _ = writeln!(m, "every_param = [{}]", all.join(", "));
    for p in &together {
        let _ = writeln!(m, "\n[programs.{p}.functions]\nroll = []\ntick = []\nb_c = [\"None: int\"]\nc = [\"type: text\"]");
    }
    for p in &alone {
        let _ = writeln!(
            m,
            "\n[programs.{p}.functions]\nf = {{ params = [\"self_: int\"], answers = [\"done\"] }}"
        );
    }
    let project = TempProject::new(&[
        ("petrel.toml", &m),
        ("n.pn", "net N {\n    place p = 1\n}\n"),
    ]);
    ok(
        &petrel(&["check", &project.path().display().to_string()]),
        "petrel check on the corpus",
    );

    // The prototypes, members of one workspace (their own `[workspace]` table taken out), at
    // one place in the shared target directory: every run builds the same packages, so their
    // artifacts replace the last run's instead of piling up.
    let corpus = Corpus::take();
    let generating = std::time::Instant::now();
    let mut crates: Vec<(String, Vec<&str>)> = vec![
        ("names".into(), vec!["NAMES"]),
        ("together".into(), together.to_vec()),
    ];
    crates.extend(
        alone
            .iter()
            .enumerate()
            .map(|(i, p)| (format!("p{i}"), vec![p.as_str()])),
    );
    let mut workspace = String::from("[workspace]\nresolver = \"2\"\nmembers = [\"*\"]\n");
    for (dir, programs) in &crates {
        let out = corpus.dir.join(dir);
        ok(
            &gen(project.path(), programs, &out, &[]),
            &format!("petrel gen {programs:?}"),
        );
        let toml = std::fs::read_to_string(out.join("Cargo.toml")).unwrap();
        std::fs::write(
            out.join("Cargo.toml"),
            toml.replace("\n[workspace]\n", "\n"),
        )
        .unwrap();
        std::fs::remove_file(out.join("Cargo.lock")).unwrap();
        // The dependencies build as for any prototype (so they are built once); the
        // prototypes themselves without debug information, the most of their link time.
        let package = toml
            .lines()
            .find_map(|l| l.strip_prefix("name = "))
            .unwrap();
        let _ = writeln!(
            workspace,
            "\n[profile.dev.package.{package}]\ndebug = 0\nstrip = \"debuginfo\"\nincremental = false"
        );
    }
    std::fs::write(corpus.dir.join("Cargo.toml"), workspace).unwrap();
    std::fs::copy(repo().join("Cargo.lock"), corpus.dir.join("Cargo.lock")).unwrap();
    let started = std::time::Instant::now();
    let o = cargo(
        &corpus.dir,
        &[
            "build",
            "--keep-going",
            "--workspace",
            "--bins",
            "--test",
            "against_player",
        ],
    );
    let stderr = String::from_utf8_lossy(&o.stderr);
    eprintln!(
        "the corpus: {} names, {} prototypes, generated in {:.1} s, built in {:.1} s",
        names.len(),
        crates.len(),
        (started - generating).as_secs_f64(),
        started.elapsed().as_secs_f64()
    );
    ok(&o, "cargo build of the corpus");
    let warned: Vec<&str> = stderr
        .lines()
        .filter(|l| l.starts_with("warning") && l.contains("-program"))
        .collect();
    assert!(warned.is_empty(), "{stderr}");
    // Each name that is not kept is listed with its identifier and why.
    let interface = std::fs::read_to_string(corpus.dir.join("names/src/interface.rs")).unwrap();
    for line in [
        "function NAMES.tick: handler `tick_` (a name the generated code uses)",
        "parameter `type` of NAMES.type: `r#type` (a Rust keyword)",
        "parameter `out_` of NAMES.every_param: `out__` (ends in `_`, as renamed names do)",
        "event `emit`: `emit_` (a name the generated code uses)",
    ] {
        assert!(
            interface.contains(&format!("//! - {line}\n")),
            "{line}:\n{interface}"
        );
    }
}
