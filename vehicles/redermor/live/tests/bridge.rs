//! `redermor-bridge`, Redermor's data server, refuses a simulator it cannot build with the file
//! or the option named (exit 2), once the project checks clean. (This integration test also
//! makes `cargo test --workspace` build it, which `petrel up missions/redermor` starts; the
//! live flights of `petrel-tests` fly it.)

use std::path::PathBuf;
use std::process::Command;

fn redermor() -> PathBuf {
    PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../missions/redermor"
    ))
}

fn run(args: &[&str]) -> (Option<i32>, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_redermor-bridge"))
        .arg(redermor())
        .args(["--vehicle", "rdmbridge", "--bus", "memory"])
        .args(args)
        .output()
        .expect("redermor-bridge runs");
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

#[test]
fn a_missing_mission_file_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("no-such-mission.toml");
    let (code, err) = run(&["--mission", missing.to_str().unwrap()]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("cannot make the simulated vehicle") && err.contains("no-such-mission.toml"),
        "{err}"
    );
}

#[test]
fn a_speed_that_is_not_above_0_is_refused_by_its_option() {
    let mission = redermor().join("sim/mission.toml");
    for speed in ["0", "nan", "-2"] {
        let (code, err) = run(&[
            "--mission",
            mission.to_str().unwrap(),
            &format!("--speed={speed}"),
        ]);
        assert_eq!(code, Some(2), "{speed}: {err}");
        assert!(err.contains("--speed"), "{speed}: {err}");
    }
}
