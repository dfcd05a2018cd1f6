//! The net language's lexer and parser on any text, then the formatter on what was read, and
//! the diagnostics rendered both ways: none of it may panic.
#![no_main]
use libfuzzer_sys::fuzz_target;
use petrel_diag::report::Diagnostics;
use petrel_diag::source::SourceMap;

/// Rendering (ariadne, JSON) costs more than parsing under the fuzzer's instrumentation: it
/// runs on the inputs up to this size, where its cases are found; longer inputs exercise the
/// parser at full speed (the size of long reports is the business of nets/tests/diagnostics.rs).
const RENDER_UP_TO: usize = 4096;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    let mut sources = SourceMap::new();
    let id = sources.add("fuzz.pn", text.as_ref());
    let mut d = Diagnostics::new();
    let file = petrel_nets::syntax::parse_file(id, "fuzz.pn", &text, &mut d);
    let _ = petrel_nets::fmt::format_file(&file);
    if data.len() <= RENDER_UP_TO {
        let _ = d.render_human(&sources);
        let _ = d.to_json(&sources);
    }
});
