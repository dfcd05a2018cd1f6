//! The 30 Model Checking Contest nets (copied in nets/tests/data/mcc, see its README) go through
//! `petrel import` then `petrel check`, as a user would run them.
//!
//! 27 become Petrel projects that check clean. Three cannot be held by safe nets, and import
//! says exactly why, element by element, writing nothing.

use petrel_nets::plural::count;
use petrel_tests::{petrel_bin, repo};
use std::process::Command;

/// Nets Petrel cannot hold, with the only code their import must report and how many times.
const REFUSED: [(&str, &str, usize); 3] = [
    // Arcs of weight 2 and 3.
    ("DrinkVendingMachine-PT-02", "E0504", 80),
    // Initial markings of 2 and 3 tokens.
    ("FMS-PT-00002", "E0505", 5),
    // Initial marking of 4 (and 2) tokens.
    ("TwoPhaseLocking-PT-nC00004vD", "E0505", 3),
];

#[test]
fn every_mcc_net_imports_or_is_refused_with_reasons() {
    let data = repo().join("nets/tests/data/mcc");
    let answers = std::fs::read_to_string(data.join("answers.csv")).unwrap();
    let out = tempfile::tempdir().unwrap();
    let mut imported = 0;
    for line in answers.lines().skip(1) {
        let cols: Vec<&str> = line.split(',').collect();
        let (model, file, places, transitions) = (cols[0], cols[1], cols[2], cols[3]);
        let dir = out.path().join(model);
        let o = Command::new(petrel_bin())
            .arg("import")
            .arg(data.join(file))
            .arg("-o")
            .arg(&dir)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        if let Some((_, code, count)) = REFUSED.iter().find(|r| r.0 == model) {
            assert_eq!(o.status.code(), Some(1), "{model} must be refused");
            assert_eq!(
                err.matches(&format!("[{code}]")).count(),
                *count,
                "{model}:\n{err}"
            );
            assert_eq!(
                err.matches("] Error").count(),
                *count,
                "only {code} for {model}"
            );
            assert!(
                err.contains(&format!("{file}:")),
                "positions name the file: {err}"
            );
            assert!(!dir.exists(), "nothing written for {model}");
            continue;
        }
        assert_eq!(o.status.code(), Some(0), "{model}: {err}");
        let msg = String::from_utf8_lossy(&o.stdout);
        let (places, transitions): (u64, u64) =
            (places.parse().unwrap(), transitions.parse().unwrap());
        assert!(
            msg.contains(&format!(
                "1 net, {}, {}",
                count(places, "place"),
                count(transitions, "transition")
            )),
            "{model}: {msg}"
        );
        // The language-level check: as missions, these nets are all immediate transitions,
        // which the verification part of `check` rightly reports (livelocks, dead markings).
        let o = Command::new(petrel_bin())
            .args(["check", "--no-verify"])
            .arg(&dir)
            .output()
            .unwrap();
        assert_eq!(
            o.status.code(),
            Some(0),
            "{model} does not check: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        imported += 1;
    }
    assert_eq!(imported, 27);
}

#[test]
fn dot_of_the_uav_mission_and_of_an_imported_net_is_valid_graphviz() {
    // Real Graphviz: scripts/test.sh installs it.
    let have_dot = Command::new("dot").arg("-V").output().is_ok();
    assert!(
        have_dot,
        "graphviz `dot` is missing: run the suite with scripts/test.sh, which installs it"
    );
    let out = tempfile::tempdir().unwrap();
    let imported = out.path().join("philo");
    let o = Command::new(petrel_bin())
        .arg("import")
        .arg(repo().join("nets/tests/data/mcc/Philosophers-PT-000005.pnml"))
        .arg("-o")
        .arg(&imported)
        .output()
        .unwrap();
    assert!(o.status.success());
    for project in [repo().join("missions/uav"), imported] {
        let dot_file = out.path().join("net.dot");
        let o = Command::new(petrel_bin())
            .arg("dot")
            .arg(&project)
            .arg("-o")
            .arg(&dot_file)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let svg = Command::new("dot")
            .arg("-Tsvg")
            .arg(&dot_file)
            .output()
            .unwrap();
        assert!(
            svg.status.success() && svg.stderr.is_empty(),
            "graphviz rejects the DOT of {}: {}",
            project.display(),
            String::from_utf8_lossy(&svg.stderr)
        );
        assert!(String::from_utf8_lossy(&svg.stdout).contains("<svg"));
    }
}
