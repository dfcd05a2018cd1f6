//! `petrel.toml` on any text: the manifest reader, then the checker on a project with no net
//! file (every manifest-only check), and the manifest written back.
#![no_main]
use libfuzzer_sys::fuzz_target;
use petrel_diag::report::Diagnostics;
use petrel_diag::source::SourceMap;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    let mut sources = SourceMap::new();
    let id = sources.add("petrel.toml", text.as_ref());
    let mut d = Diagnostics::new();
    if let Some(m) = petrel_nets::manifest::parse_manifest(id, &text, &mut d) {
        let _ = petrel_nets::manifest::format_manifest(&m);
    }
    let _ = d.render_human(&sources);
    let (_, _, d, sources) = petrel_nets::project::from_sources(&text, &[]);
    let _ = d.render_human(&sources);
});
