//! Paths read from files stay inside their directory (issue 10, item 3): PNML net file paths,
//! the manifest's `files`, and what `project::write` and `project::write_net_file` accept.

use petrel_diag::report::Diagnostics;
use petrel_diag::source::SourceMap;
use petrel_nets::pnml::{export_pnml, import_pnml};
use petrel_nets::project;
use std::path::Path;

fn uav_pnml() -> String {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../missions/uav");
    let loaded = project::load(&dir).expect("the UAV reads");
    export_pnml(&loaded.project)
}

/// Before: `petrel import` wrote a `<netfile path>` that was absolute or had `..` wherever it
/// said, over an existing file, without `--force`.
#[test]
fn pnml_net_file_paths_outside_the_project_are_e0508_at_their_line() {
    for bad in ["../victim.pn", "/tmp/victim.pn", "nets/../../victim.pn"] {
        let text = uav_pnml().replace("\"mission.pn\"", &format!("\"{bad}\""));
        let mut sources = SourceMap::new();
        let id = sources.add("uav.pnml", text.as_str());
        let mut d = Diagnostics::new();
        let imported = import_pnml(id, &text, &mut d);
        let found: Vec<_> = d.iter().filter(|d| d.code == "E0508").collect();
        // The manifest's `<file>` and the `<netfile>` both name it.
        assert_eq!(found.len(), 2, "{bad}: {}", d.render_human(&sources));
        assert!(found[0].message.contains(bad), "{}", found[0].message);
        let lines: Vec<_> = found
            .iter()
            .map(|f| {
                sources
                    .get(id)
                    .line_col(f.span.unwrap().start as usize)
                    .line
            })
            .collect();
        // At the lines that hold the crafted path, wherever the export put them.
        let expected: Vec<_> = text
            .lines()
            .enumerate()
            .filter(|(_, l)| l.contains(&format!("\"{bad}\"")))
            .map(|(i, _)| i + 1)
            .collect();
        assert_eq!(lines, expected, "{bad}");
        // Even handed to `write` regardless, it writes nothing.
        assert!(imported.is_none(), "{bad}: nothing to write");
    }
}

/// `project::write`, the one writer of a project, refuses a path that leaves its directory
/// even when no reader caught it.
#[test]
fn write_refuses_net_file_paths_outside_its_directory() {
    let text = uav_pnml();
    let mut d = Diagnostics::new();
    let mut sources = SourceMap::new();
    let id = sources.add("uav.pnml", text.as_str());
    let clean = import_pnml(id, &text, &mut d).expect("the UAV imports");
    for bad in ["../victim.pn", "/tmp/victim.pn", ""] {
        let mut p = clean.clone();
        p.files[0].path = bad.to_string();
        let out = tempfile::tempdir().unwrap();
        let dest = out.path().join("project");
        let e = project::write(&dest, &p).expect_err("refused");
        assert_eq!(e.kind(), std::io::ErrorKind::InvalidInput);
        assert!(!dest.exists(), "nothing written");
        assert!(!out.path().join("victim.pn").exists());
    }
}

fn project_dir(files: &str) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("petrel.toml"),
        format!(
            "[project]\nname = \"t\"\nfiles = [{files}]\nstart = [\"A\"]\n\n[events]\ngo = {{ category = \"nominal\" }}\n"
        ),
    )
    .unwrap();
    dir
}

/// Before: `petrel fmt` rewrote manifest-listed files outside the project directory.
#[test]
fn manifest_files_outside_the_project_are_e0107_and_never_read() {
    let outside = tempfile::tempdir().unwrap();
    let victim = outside.path().join("victim.pn");
    std::fs::write(&victim, "net A {\nplace p = 1\n}\n").unwrap();
    for bad in [
        format!("\"{}\"", victim.display()),
        "\"../victim.pn\"".to_string(),
    ] {
        let dir = project_dir(&bad);
        let loaded = project::load(dir.path()).unwrap();
        let codes: Vec<_> = loaded.diagnostics.iter().map(|d| d.code).collect();
        assert_eq!(codes, ["E0109"], "{bad}");
        let rendered = loaded.diagnostics.render_human(&loaded.sources);
        assert!(rendered.contains("petrel.toml:3:"), "{rendered}");
        assert!(loaded.project.files.is_empty(), "nothing read");
    }
}

#[cfg(unix)]
#[test]
fn a_net_file_that_is_a_link_leading_out_is_e0107_and_not_rewritten() {
    let outside = tempfile::tempdir().unwrap();
    let victim = outside.path().join("victim.pn");
    let original = "net A {\nplace   p = 1\n}\n";
    std::fs::write(&victim, original).unwrap();
    let dir = project_dir("\"a.pn\"");
    std::os::unix::fs::symlink(&victim, dir.path().join("a.pn")).unwrap();
    let loaded = project::load(dir.path()).unwrap();
    let d: Vec<_> = loaded.diagnostics.iter().collect();
    assert_eq!(d.len(), 1);
    assert_eq!(d[0].code, "E0109");
    assert!(d[0].message.contains("symbolic link"), "{}", d[0].message);
    assert!(loaded.project.files.is_empty());
    // And the writer refuses it too.
    let e = project::write_net_file(dir.path(), "a.pn", "x").expect_err("refused");
    assert_eq!(e.kind(), std::io::ErrorKind::InvalidInput);
    assert_eq!(std::fs::read_to_string(&victim).unwrap(), original);
}
