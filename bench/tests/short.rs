//! The suite in its short mode, so that it cannot rot: every part runs (the vcan part, which
//! boots the VM, excepted: scripts/test.sh runs the vcan tests there), the report and
//! the plots are written, and every measurement succeeds. No figure is asserted.

use std::process::Command;

#[test]
fn the_short_suite_runs_every_part_and_writes_its_report() {
    let out = tempfile::tempdir().expect("tempdir");
    let doc = out.path().join("benchmarks.md");
    std::fs::write(&doc, "# Benchmarks\n\nkept\n").expect("doc");
    let svg = out.path().join("bench");
    let run = Command::new(env!("CARGO_BIN_EXE_petrel-bench"))
        .args(["run", "--short", "--no-vm", "--doc"])
        .arg(&doc)
        .arg("--svg")
        .arg(&svg)
        .output()
        .expect("petrel-bench runs");
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "petrel-bench failed:\n{stderr}");
    let text = std::fs::read_to_string(&doc).expect("report written");
    assert!(
        text.starts_with("# Benchmarks\n\nkept\n"),
        "the rest of the doc is kept"
    );
    for part in [
        "### 1. Transport",
        "| Petrel, spin |",
        "| Petrel, block |",
        "| raw iceoryx2, busy poll |",
        "| Unix socket |",
        "| TCP loopback |",
        "### 2. The vehicle path",
        "| bare echo |",
        "### 3. Under load",
        "### 4. Footprint",
        "player, UAV mission",
        "### 5. Scale",
        "| 50 |",
    ] {
        assert!(text.contains(part), "the report lacks `{part}`:\n{text}");
    }
    assert!(!text.contains("failed:"), "a measurement failed:\n{text}");
    for plot in ["transport.svg", "vehicle.svg", "load.svg", "scale.svg"] {
        let body = std::fs::read_to_string(svg.join(plot)).expect("plot written");
        assert!(body.contains("<svg") && body.contains("</svg>"), "{plot}");
    }
    // Written twice, the section is replaced, not appended.
    let again = Command::new(env!("CARGO_BIN_EXE_petrel-bench"))
        .args(["run", "--short", "--only", "footprint", "--doc"])
        .arg(&doc)
        .output()
        .expect("petrel-bench runs");
    assert!(
        again.status.success(),
        "{}",
        String::from_utf8_lossy(&again.stderr)
    );
    let text = std::fs::read_to_string(&doc).expect("report written");
    assert_eq!(text.matches("latency-suite:begin").count(), 1);
}
