//! `can.toml` on any text, checked against the AUV mission's project and DBC (the repository's
//! real ones, so the fuzzer reaches the rules' checks with real messages and signals).
#![no_main]
use libfuzzer_sys::fuzz_target;
use petrel_can_bridge::Dbc;
use petrel_diag::report::Diagnostics;
use petrel_diag::source::SourceMap;
use petrel_nets::compiled::CompiledProject;
use std::sync::OnceLock;

fn auv() -> &'static (CompiledProject, Dbc) {
    static AUV: OnceLock<(CompiledProject, Dbc)> = OnceLock::new();
    AUV.get_or_init(|| {
        let (_, compiled, d, _) = petrel_nets::project::from_sources(
            include_str!("../../missions/auv/petrel.toml"),
            &[
                ("phases.pn", include_str!("../../missions/auv/phases.pn")),
                ("safety.pn", include_str!("../../missions/auv/safety.pn")),
            ],
        );
        let c = compiled.unwrap_or_else(|| panic!("the AUV mission checks: {d:?}"));
        let dbc = Dbc::parse(include_str!("../../missions/auv/auv.dbc")).expect("auv.dbc reads");
        (c, dbc)
    })
}

fuzz_target!(|data: &[u8]| {
    let (project, dbc) = auv();
    let text = String::from_utf8_lossy(data);
    let mut sources = SourceMap::new();
    let id = sources.add("can.toml", text.as_ref());
    let mut d = Diagnostics::new();
    if let Some(config) = petrel_can_bridge::check_rules(id, &text, dbc, project, &mut d) {
        // A configuration that checks clean builds a core.
        let _ = petrel_can_bridge::BridgeCore::new(std::sync::Arc::new(dbc.clone()), config, 0);
    }
    let _ = d.render_human(&sources);
});
