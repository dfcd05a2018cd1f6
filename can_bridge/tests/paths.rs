//! can.toml's `dbc` stays inside the project directory (issue 10, item 3).

mod common;

use common::codes;
use petrel_diag::report::Diagnostics;
use petrel_diag::source::SourceMap;

fn load(dir: &std::path::Path) -> (Diagnostics, String) {
    let mut sources = SourceMap::new();
    let mut diags = Diagnostics::new();
    let got =
        petrel_can_bridge::load_project_can(dir, &common::project(), &mut sources, &mut diags)
            .expect("can.toml reads");
    assert!(got.is_none());
    let text = diags.render_human(&sources);
    (diags, text)
}

/// Before: `dbc = "../x.dbc"` or an absolute path read whatever file it named.
#[test]
fn a_dbc_outside_the_project_is_e0711_at_the_dbc_value() {
    let outside = tempfile::tempdir().unwrap();
    std::fs::copy(common::data("auv/auv.dbc"), outside.path().join("auv.dbc")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let project = dir.path().join("p");
    std::fs::create_dir(&project).unwrap();
    std::fs::copy(common::data("auv/auv.dbc"), dir.path().join("up.dbc")).unwrap();
    let can = common::can_toml();
    for bad in [
        outside.path().join("auv.dbc").display().to_string(),
        "../up.dbc".to_string(),
    ] {
        std::fs::write(
            project.join("can.toml"),
            can.replace("dbc = \"auv.dbc\"", &format!("dbc = \"{bad}\"")),
        )
        .unwrap();
        let (diags, text) = load(&project);
        assert_eq!(codes(&diags), ["E0711"], "{text}");
        assert!(text.contains("can.toml:2:"), "{text}");
        assert!(text.contains(&bad), "{text}");
    }
}

#[cfg(unix)]
#[test]
fn a_dbc_that_is_a_link_leading_out_is_e0711() {
    let outside = tempfile::tempdir().unwrap();
    std::fs::copy(common::data("auv/auv.dbc"), outside.path().join("auv.dbc")).unwrap();
    let project = tempfile::tempdir().unwrap();
    std::fs::write(project.path().join("can.toml"), common::can_toml()).unwrap();
    std::os::unix::fs::symlink(
        outside.path().join("auv.dbc"),
        project.path().join("auv.dbc"),
    )
    .unwrap();
    let (diags, text) = load(project.path());
    assert_eq!(codes(&diags), ["E0711"], "{text}");
    assert!(text.contains("symbolic link"), "{text}");
}
