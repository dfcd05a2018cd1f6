//! `redermor-program` refuses what it cannot run with a clear message, before it joins a
//! vehicle. (This integration test also makes `cargo test --workspace` build the binary, which
//! the live scenarios of `petrel-tests` start through `petrel up`.)

use std::process::Command;

fn run(args: &[&str]) -> (Option<i32>, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_redermor-program"))
        .args(args)
        .output()
        .expect("redermor-program runs");
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

#[test]
fn an_unknown_role_is_refused_with_the_roles_there_are() {
    let (code, err) = run(&["--vehicle", "v", "--role", "XYZ", "--mission", "m.toml"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("'XYZ'") && err.contains("PLN, NAV, EVT"),
        "{err}"
    );
}

#[test]
fn a_missing_mission_file_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("no-such-mission.toml");
    let (code, err) = run(&[
        "--vehicle",
        "v",
        "--role",
        "PLN",
        "--mission",
        missing.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("no-such-mission.toml"), "{err}");
}
