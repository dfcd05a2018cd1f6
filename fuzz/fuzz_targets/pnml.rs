//! PNML on any bytes: the P/T reader (`petrel verify FILE.pnml`) and the project import
//! (`petrel import`), whose result is then written as text (never to disk).
#![no_main]
use libfuzzer_sys::fuzz_target;
use petrel_diag::report::Diagnostics;
use petrel_diag::source::SourceMap;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    let mut sources = SourceMap::new();
    let id = sources.add("fuzz.pnml", text.as_ref());
    let mut d = Diagnostics::new();
    let nets = petrel_nets::pnml::parse_pnml(id, &text, &mut d);
    for net in &nets {
        let opts = petrel_verify::reach::ExploreOptions {
            max_states: Some(200),
            ..Default::default()
        };
        let _ = petrel_verify::reach::explore(net, opts);
        // The stubborn-set reduction on the same net (`petrel verify FILE.pnml --deadlocks`).
        let opts = petrel_verify::reach::ExploreOptions {
            max_states: Some(200),
            deadlocks_only: true,
            ..Default::default()
        };
        let _ = petrel_verify::reach::explore(net, opts);
    }
    let mut d = Diagnostics::new();
    if let Some(p) = petrel_nets::pnml::import_pnml(id, &text, &mut d) {
        let _ = petrel_nets::manifest::format_manifest(&p.manifest);
        for f in &p.files {
            let _ = petrel_nets::fmt::format_file(f);
        }
    }
    let _ = d.render_human(&sources);
});
