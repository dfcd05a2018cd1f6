//! What the tests share: the AUV bench project, its DBC and its can.toml.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::sync::Arc;

use petrel_can_bridge::config::{check_rules, CanConfig};
use petrel_can_bridge::Dbc;
use petrel_diag::report::Diagnostics;
use petrel_diag::source::SourceMap;
use petrel_nets::compiled::CompiledProject;

pub fn data(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(path)
}

pub fn project() -> CompiledProject {
    let (_, compiled, diags) = petrel_nets::project::load_and_check(&data("auv")).unwrap();
    compiled.unwrap_or_else(|| panic!("the bench project checks: {diags:?}"))
}

pub fn dbc() -> Arc<Dbc> {
    Arc::new(Dbc::load(&data("auv/auv.dbc")).unwrap())
}

pub fn can_toml() -> String {
    std::fs::read_to_string(data("auv/can.toml")).unwrap()
}

/// Checks `text` as can.toml against the bench; the config or the rendered diagnostics.
pub fn check(text: &str) -> Result<(CanConfig, Diagnostics), (Diagnostics, String)> {
    let mut sources = SourceMap::new();
    let file = sources.add("can.toml", text);
    let mut diags = Diagnostics::new();
    match check_rules(file, text, &dbc(), &project(), &mut diags) {
        Some(c) if !diags.has_errors() => Ok((c, diags)),
        _ => {
            let rendered = diags.render_human(&sources);
            Err((diags, rendered))
        }
    }
}

/// The bench configuration.
pub fn config() -> CanConfig {
    match check(&can_toml()) {
        Ok((c, _)) => c,
        Err((_, r)) => panic!("the bench can.toml checks:\n{r}"),
    }
}

pub fn codes(d: &Diagnostics) -> Vec<&'static str> {
    d.iter().map(|d| d.code).collect()
}
