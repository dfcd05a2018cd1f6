//! Helpers for Petrel's cross-crate and cross-process tests.

use std::path::{Path, PathBuf};
use std::process::Command;

/// The repository root.
pub fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The `petrel` binary of this build, built first if a test run did not build it
/// (`cargo test -p petrel-tests` alone builds no binary of another package).
pub fn petrel_bin() -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    // target/<profile>/deps/<test> -> target/<profile>/petrel
    let profile_dir = exe
        .parent()
        .and_then(Path::parent)
        .expect("test binary lives in target/<profile>/deps");
    let bin = profile_dir.join("petrel");
    if !bin.exists() {
        let release = profile_dir.file_name().is_some_and(|n| n == "release");
        let mut cmd = Command::new(env!("CARGO"));
        cmd.args(["build", "-p", "petrel-player", "--bin", "petrel"]);
        if release {
            cmd.arg("--release");
        }
        let status = cmd.current_dir(repo()).status().expect("cargo runs");
        assert!(status.success(), "building petrel failed");
    }
    bin
}
